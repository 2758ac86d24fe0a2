-- SPDX-License-Identifier: MIT
-- pour_flip: the paper's pour scene with FLIP — a jet of 5625 particles
-- poured into a box, splashing and settling.
--
--   build/eddy run scenes/pour_flip.lua --stats out/pour_flip.jsonl
--   build/eddy run scenes/pour_flip.lua --set solver=cholmod

local eddy = require "eddy"

local dx = eddy.param("cell_size", 0.025)      -- m, MAC grid spacing
local solver = eddy.param("solver", "pcg")

local world = eddy.world {
	bounds = { {0, 0, 0}, {0.5, 0.5, 0.5} },
	gravity = {0, -9.81, 0},
	fps = 30, duration = 3.0, cfl = 2.0, dt_max = 1 / 60,
	cell_size = dx,
}

-- nozzle rate = speed * pi r^2 / spacing^3 (about 2200/s): 5625 particles by t = 2.6 s
world:add(eddy.emit_nozzle { center = {0.25, 0.45, 0.25}, radius = 0.03, direction = {0, -1, 0},
                             speed = 1.5, spacing = dx / 2, max_particles = 5625 })
world:add(eddy.gravity {})
world:add(eddy.flip_p2g {})
world:add(eddy.flip_boundary {})
world:add(eddy.flip_surface {})
world:add(eddy.flip_pressure { solver = solver })
world:add(eddy.flip_extrapolate { layers = 4 }) -- CFL 2 + 2
world:add(eddy.flip_g2p {})
world:add(eddy.flip_advect {})

require("eddy.view").render(eddy, world, "pour_flip")

return world
