-- SPDX-License-Identifier: MIT
-- dam_break_flip: Martin & Moyce's dam break with FLIP (Zhu & Bridson 2005).
-- The tank, column and front reporting (Z, T) are lua/eddy/dam_break.lua,
-- shared with the SPH scene; only the method systems differ.
--
--   build/eddy run scenes/dam_break_flip.lua --set solver=cholmod --stats out/dam_flip.jsonl
--   build/eddy run scenes/dam_break_flip.lua --set solver=pcg --set cell_size=0.00625

local eddy = require "eddy"
local dam = require "eddy.dam_break"

local a = eddy.param("a", 0.1)                  -- m, column base (height 2a)
local dx = eddy.param("cell_size", a / 16)      -- m, MAC grid spacing
local solver = eddy.param("solver", "pcg")      -- "pcg" or "cholmod"
local tolerance = eddy.param("tolerance", 1e-6) -- PCG relative residual
local flip_ratio = eddy.param("flip_ratio", 0.95)

-- 2 x 2 x 2 particles per cell
local world, geo = dam.world(eddy, { a = a, spacing = dx / 2, thickness = 4 * dx,
                                     cell_size = dx, cfl = eddy.param("cfl", 1.0) })

world:add(eddy.emit_box { min = geo.column_min, max = geo.column_max, spacing = geo.spacing })
world:add(eddy.gravity {})
world:add(eddy.flip_p2g {})
world:add(eddy.flip_boundary {})
world:add(eddy.flip_surface {})
world:add(eddy.flip_pressure { solver = solver, tolerance = tolerance })
world:add(eddy.flip_extrapolate {})
world:add(eddy.flip_g2p { flip_ratio = flip_ratio })
world:add(eddy.flip_advect {})
world:add(eddy.flip_reseed {})
dam.report(world, geo)
dam.render(eddy, world, geo, "dam_break_flip")

return world
