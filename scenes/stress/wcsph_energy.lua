-- SPDX-License-Identifier: MIT
-- wcsph_energy (SPH stress case): WCSPH's energy budget. With the physical
-- viscosity and Monaghan's alpha at 0 (the defaults here) the dynamics are
-- meant to be conservative and the integrator symplectic, so the frame
-- stats' `energy` (kinetic + potential + WCSPH's compression energy) should
-- stay constant to O(dt^2) with no secular growth; whatever rises beyond
-- that is work done by a term that is not the gradient of an energy.
-- Three cases, the water 0.1 x depth x 0.1 m at the still-water scene's
-- spacing and stiffness (k = 100 g D):
--   case = "blocks": no walls, no gravity, two blocks meeting head-on at
--          +-v0 (the bulk pair force and the p >= 0 clamp alone);
--   case = "walls":  boundary particles, no gravity, the column 2 spacings
--          above the floor thrown down at v0 (it meets the floor at
--          2 dx / v0, rebounds, rises and meets the lid 1.5 depth up);
--   case = "column": boundary particles and gravity, still water started
--          at rho0 (scenes/stress/still_water.lua without its viscosity).
--
--   build/eddy run scenes/stress/wcsph_energy.lua --set case=column --set cfl=0.25 --stats - --quiet
--
-- Params: case, depth (m), v0 (m/s), cfl, duration (s), viscosity (Pa s),
-- artificial (Monaghan's alpha). Per frame besides the stats: vmax (m/s),
-- vmax_height (the fastest particle's height / depth), vmax_wall (its
-- distance from the nearest side wall in spacings) and bottom_p_ratio (as
-- still_water.lua's, 0 without gravity).

local eddy = require "eddy"

local dx = 0.0125
local case = eddy.param("case", "column")
local D = eddy.param("depth", 0.25)
local W = 0.1
local v0 = eddy.param("v0", case == "column" and 0.0 or 0.2)
local rho0, g = 1000, 9.81
local walls, gravity = case ~= "blocks", case == "column"
local top = D * 1.5
local lo, hi = {0, 0, 0}, {W, top, W}
if not walls then lo, hi = {-1, -1, -1}, {1, 2, 1} end

local world = eddy.world {
	bounds = { lo, hi }, gravity = {0, gravity and -g or 0, 0},
	fps = 30, duration = eddy.param("duration", 2.0), cfl = eddy.param("cfl", 0.5),
}
if case == "blocks" then
	world:add(eddy.emit_box { min = {0, 0, 0}, max = {W, D, W}, spacing = dx, velocity = {0, v0, 0} })
	world:add(eddy.emit_box { min = {0, D + 2 * dx, 0}, max = {W, 2 * D + 2 * dx, W}, spacing = dx,
	                          velocity = {0, -v0, 0} })
else
	local y0 = gravity and 0 or 2 * dx
	world:add(eddy.emit_box { min = {0, y0, 0}, max = {W, y0 + D, W}, spacing = dx, velocity = {0, -v0, 0} })
end
world:add(eddy.sph_density { radius = 2 * dx, spacing = dx, rest_density = rho0, stiffness = 100 * g * D })
world:add(eddy.sph_pressure {})
world:add(eddy.sph_viscosity { viscosity = eddy.param("viscosity", 0.0), artificial = eddy.param("artificial", 0.0) })
if gravity then world:add(eddy.gravity {}) end
if walls then world:add(eddy.sph_boundary_box { min = lo, max = hi, spacing = dx }) end
world:add(eddy.integrate {})
if walls then world:add(eddy.collide_box { min = lo, max = hi, inside = true }) end

world:on_frame(function(w)
	local x, y, z, p = w:channel("x"), w:channel("y"), w:channel("z"), w:channel("pressure")
	local vx, vy, vz = w:channel("vx"), w:channel("vy"), w:channel("vz")
	local n, vmax, yv, dw, pb, nb = #y, 0, 0, 0, 0, 0
	for i = 1, n do
		local s = math.sqrt(vx[i] ^ 2 + vy[i] ^ 2 + vz[i] ^ 2)
		if s > vmax then vmax, yv, dw = s, y[i] / D, math.min(x[i], W - x[i], z[i], W - z[i]) / dx end
		if y[i] < dx then pb, nb = pb + p[i], nb + 1 end
	end
	return { vmax = vmax, vmax_height = yv, vmax_wall = dw,
	         bottom_p_ratio = gravity and pb / math.max(nb, 1) / (rho0 * g * (D - dx / 2)) or 0 }
end)

return world
