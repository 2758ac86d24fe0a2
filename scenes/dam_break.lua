-- SPDX-License-Identifier: MIT
-- dam_break: Martin & Moyce's collapsing column, a x 2a against the back wall
-- of a tank 5.5 a long, in a thin slab with free-slip walls (2D-like flow),
-- with any fluid method. Reports Z = front / a and T = t sqrt(2 g / a) every
-- frame, to compare with data/martin_moyce_1952_*.csv.
--
--   build/eddy run scenes/dam_break.lua --stats out/dam/stats.jsonl           (WCSPH)
--   build/eddy run scenes/dam_break.lua --set method=dfsph
--   build/eddy run scenes/dam_break.lua --set method=flip --set solver=cholmod
--   build/eddy compare scenes/dam_break.lua --methods wcsph,dfsph,flip
--
-- `spacing` is the particle spacing of every method (FLIP's cells are two
-- spacings wide, 8 particles each). SPH walls are boundary particles so the
-- fluid neither sticks to nor gaps from them; FLIP's are the grid's sides.

local eddy = require "eddy"
local dam = require "eddy.dam_break"

local a = eddy.param("a", 0.1)                  -- m, column base
local solver = eddy.param("solver", "pcg")      -- FLIP's pressure solve: "pcg", "mg", "cholmod" or "hypre"
local fluid = eddy.fluid {
	method = eddy.param("method", "wcsph"),     -- wcsph, dfsph, flip, pic or apic
	resolution = eddy.param("spacing", a / 20), -- m
	-- stiffness 0: sph_density chooses c = 10 x the column's fall speed sqrt(2 g 2a), at least 20 m/s (20 at
	-- a = 0.1), so the flow is the same at every a (Froude-similar)
	wcsph = { stiffness = eddy.param("stiffness", 0), artificial = eddy.param("alpha", 0.05) },
	dfsph = { tolerance = eddy.param("tolerance", 0.001), artificial = eddy.param("alpha", 0.05) },
	flip = { solver = solver, tolerance = eddy.param("tolerance", 1e-6), flip_ratio = eddy.param("flip_ratio", 0.95),
	         reseed = eddy.param("reseed", false) },
	pic = { solver = solver, tolerance = eddy.param("tolerance", 1e-6) },
	apic = { solver = solver, tolerance = eddy.param("tolerance", 1e-6) },
}

local world, geo = dam.world(eddy, fluid, { a = a, fps = eddy.param("fps", 200), cfl = eddy.param("cfl", fluid.cfl) })
world:add(eddy.emit_box { min = geo.column_min, max = geo.column_max, spacing = fluid.spacing })
world:add(fluid)
dam.report(world, geo)
dam.render(eddy, world, geo, "dam_break")

return world
