-- SPDX-License-Identifier: MIT
-- sph_solid_sphere: the SPH version of flip_solid_sphere.lua. A 4 cm sphere
-- lowered into a 15 cm pool, then moved back and forth through it at up to
-- 0.63 m/s for 1.5 s and left 1.5 s to settle (issue "Stable and
-- conservative one step beyond the tested scenes", item 2). The sphere
-- collider carries boundary particles (Akinci et al. 2012,
-- src/sph/neighbors.c) that move with it, so the fluid
-- beside it has a full neighbourhood; the level should end at (fluid volume +
-- sphere volume) / tank area = 0.1612 m at the default spacing.
-- tests/test_stress_sph_solids.c runs the same case.
--
--   build/eddy run scenes/stress/sph_solid_sphere.lua --stats out/sph_solid_sphere.jsonl
--   build/eddy run scenes/stress/sph_solid_sphere.lua --set solver=wcsph --set radius=0.05
--
-- Per frame: level (m, the mean over columns two spacings square of the
-- highest particle with another within two spacings below it, plus half a
-- spacing: the surface of a fluid at rest on the lattice), expected (m, the
-- geometric level for the part of the sphere under that level) and
-- level_error (level / expected - 1).
-- Params: solver ("dfsph" or "wcsph"), spacing (m), radius (m, of the
-- sphere), speed (m/s, peak of the oscillation, amplitude 5 cm), shift
-- (sph_dfsph's particle shifting; unset: its default).

local eddy = require "eddy"

local dx = eddy.param("spacing", 0.01)         -- m
local solver = eddy.param("solver", "dfsph")   -- "dfsph" (sph_dfsph) or "wcsph" (sph_pressure)
local r = eddy.param("radius", 0.04)           -- m, sphere radius
local A = 0.05                                 -- m, oscillation amplitude
local omega = eddy.param("speed", 0.2 * math.pi) / A  -- rad/s: peak speed A omega
local W, H, D, depth = 0.2, 0.3, 0.12, 0.15    -- m: tank and pool
local y0, y1 = 0.22, 0.08                      -- m: start and working height of the centre
local t_lower, t_osc = 0.5, 1.5                -- s: lowering, then oscillation
local rho0, g = 1000, 9.81

local world = eddy.world {
	bounds = { {0, 0, 0}, {W, H, D} }, gravity = {0, -g, 0},
	fps = 30, duration = 3.5, cfl = solver == "dfsph" and 0.5 or 0.4,
}
world:add(eddy.emit_box { min = {0, 0, 0}, max = {W, depth, D}, spacing = dx })
-- WCSPH: k = 100 g D, compressed by g D / k = 1% at the floor
world:add(eddy.sph_density { radius = 2 * dx, spacing = dx, rest_density = rho0,
                            stiffness = 100 * g * depth })
if solver == "dfsph" then
	world:add(eddy.gravity {})
	world:add(eddy.sph_viscosity { viscosity = 1e-3, artificial = 0.05 })
	-- params arrive as strings; unset: sph_dfsph's default shift
	world:add(eddy.sph_dfsph { shift = tonumber(eddy.param("shift", nil)) })
else
	world:add(eddy.sph_pressure {})
	world:add(eddy.sph_viscosity { viscosity = 1e-3, artificial = 0.05 })
	world:add(eddy.gravity {})
end
world:add(eddy.sph_boundary_box { min = {0, 0, 0}, max = {W, H, D}, spacing = dx })
world:add(eddy.integrate {})
world:add(eddy.collide_box { min = {0, 0, 0}, max = {W, H, D}, inside = true })
-- the offset is evaluated just before the collider, for the end of the step;
-- sph_density sees it at the next step, where the sphere's boundary particles
-- move to it
local function offset(t)
	local dy = (t < t_lower) and (y1 - y0) * t / t_lower or (y1 - y0)
	local dxo = 0
	if t > t_lower then
		dxo = A * math.sin(omega * (math.min(t, t_lower + t_osc) - t_lower))
	end
	return { dxo, dy, 0 }
end
world:add(eddy.collide_sphere { center = {W / 2, y0, D / 2}, radius = r, offset = offset })

world:on_frame(function(w)
	local x, y, z = w:channel("x"), w:channel("y"), w:channel("z")
	local n, cs = #y, 2 * dx
	local nx, nz = math.floor(W / cs + 1e-6), math.floor(D / cs + 1e-6)
	local cols = {}
	for i = 1, n do
		local a = math.min(math.floor(x[i] / cs), nx - 1)
		local b = math.min(math.floor(z[i] / cs), nz - 1)
		local k = a * nz + b + 1
		local c = cols[k]
		if not c then c = {}; cols[k] = c end
		c[#c + 1] = y[i]
	end
	local sum, count = 0, 0
	for _, c in pairs(cols) do
		table.sort(c)
		local top = #c
		while top > 1 and c[top] - c[top - 1] > 2 * dx do top = top - 1 end
		sum, count = sum + c[top] + dx / 2, count + 1
	end
	local level = sum / math.max(count, 1)
	-- the part of the sphere below the level (a spherical cap)
	local cy = y0 + offset(w:time())[2]
	local hcap = math.max(0, math.min(2 * r, level - (cy - r)))
	local vsub = math.pi * hcap * hcap * (3 * r - hcap) / 3
	local expected = (n * dx ^ 3 + vsub) / (W * D)
	return { level = level, expected = expected, level_error = level / expected - 1 }
end)

return world
