-- SPDX-License-Identifier: MIT
-- dam_break (SPH): Martin & Moyce's collapsing column, a x 2a against the back
-- wall of a tank 5.5 a long, in a slab 4 spacings thick with free-slip walls
-- (2D-like flow). Reports Z = front / a and T = t sqrt(2 g / a) every frame,
-- to compare with data/martin_moyce_1952_*.csv.
--
--   build/eddy run scenes/dam_break.lua --set spacing=0.005 --stats out/dam/stats.jsonl
--
-- Walls are boundary particles (sph_boundary_box) so the fluid neither sticks
-- to nor gaps from them; collide_box on the same box is the hard stop.

local eddy = require "eddy"
local dam = require "eddy.dam_break"

local a = eddy.param("a", 0.1)                  -- m, column base
local h = eddy.param("spacing", a / 20)         -- m, particle spacing
local stiffness = eddy.param("stiffness", 400)  -- m^2/s^2: c = 20 m/s, 10 x the front speed
local alpha = eddy.param("alpha", 0.05)         -- Monaghan artificial viscosity
local solver = eddy.param("solver", "wcsph")    -- "wcsph" (sph_pressure) or "dfsph" (implicit, sph_dfsph)

local world, geo = dam.world(eddy, { a = a, spacing = h, fps = eddy.param("fps", 200), cfl = eddy.param("cfl", 0.4) })
world:add(eddy.emit_box { min = geo.column_min, max = geo.column_max, spacing = h })
world:add(eddy.sph_density { radius = 2 * h, spacing = h, rest_density = 1000, stiffness = stiffness })
if solver == "dfsph" then
	-- the pressure solve after the other forces, before integrate
	world:add(eddy.gravity {})
	world:add(eddy.sph_viscosity { viscosity = 1e-3, artificial = alpha })
	world:add(eddy.sph_dfsph { max_density_error = eddy.param("tolerance", 0.001) })
else
	world:add(eddy.sph_pressure {})
	world:add(eddy.sph_viscosity { viscosity = 1e-3, artificial = alpha })
	world:add(eddy.gravity {})
end
world:add(eddy.sph_boundary_box { min = geo.tank_min, max = geo.tank_max, spacing = h })
world:add(eddy.integrate {})
world:add(eddy.collide_box { min = geo.tank_min, max = geo.tank_max, inside = true })
dam.report(world, geo)
dam.render(eddy, world, geo, "dam_break")

return world
