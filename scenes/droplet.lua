-- SPDX-License-Identifier: MIT
-- droplet (SPH): a drop in zero gravity relaxing under surface tension. It
-- starts as an ellipsoid stretched along x (by 1 + stretch, its volume that
-- of the round drop of radius R), rounds off and rings in its l = 2 mode,
-- whose frequency Rayleigh gives as omega^2 = 8 sigma / (rho R^3) (24 rad/s
-- for R = 1 cm). Reports the quadrupole moment q = <x^2> - <y^2> (m^2) about
-- the centre of mass each frame; tests/test_sph.c measures omega from it.
--
--   build/eddy run scenes/droplet.lua --stats out/drop/stats.jsonl

local eddy = require "eddy"

local dx = eddy.param("spacing", 0.00125)      -- m: 16 spacings across
local sigma = eddy.param("tension", 0.0728)    -- N/m, water-air
local R = eddy.param("radius", 0.01)            -- m, radius of the round drop
local stretch = eddy.param("stretch", 0.2)      -- 1, x semi-axis R (1 + stretch)
local ax, ayz = R * (1 + stretch), R / math.sqrt(1 + stretch)
local world = eddy.world {
	bounds = { {-0.03, -0.03, -0.03}, {0.03, 0.03, 0.03} },
	gravity = {0, 0, 0}, fps = 200, duration = 0.6, cfl = 0.4,
}
world:add(eddy.emit_box { min = {-ax, -ayz, -ayz}, max = {ax, ayz, ayz}, spacing = dx, shape = "ellipsoid" })
world:add(eddy.sph_density { radius = 2 * dx, spacing = dx, rest_density = 1000, stiffness = 40 })
world:add(eddy.sph_pressure {})
-- alpha 0.1: also keeps the surface layer's pairs apart (docs/validation.md C.1)
world:add(eddy.sph_viscosity { viscosity = 1e-3, artificial = 0.1 })
world:add(eddy.sph_surface_tension { tension = sigma, threshold = 0.5 })
world:add(eddy.integrate {})
world:add(eddy.collide_box { min = {-0.03, -0.03, -0.03}, max = {0.03, 0.03, 0.03}, inside = true })

world:on_frame(function(w)
	local x, y = w:channel("x"), w:channel("y")
	local n, cx, cy = #x, 0, 0
	for i = 1, n do cx, cy = cx + x[i], cy + y[i] end
	cx, cy = cx / n, cy / n
	local q = 0
	for i = 1, n do q = q + (x[i] - cx) ^ 2 - (y[i] - cy) ^ 2 end
	return { q = q / n }
end)

require("eddy.view").render(eddy, world, "droplet")

return world
