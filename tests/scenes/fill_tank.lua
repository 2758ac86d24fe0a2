-- SPDX-License-Identifier: MIT
-- fill_tank (tests/test_physics.c): a nozzle pours into a closed tank
-- 0.06 x 0.08 x 0.04 m (12 x 16 x 8 spacings of 5 mm: 1,536 particles at the
-- lattice's density) for longer than the tank takes to fill, with any
-- method. The nozzle (1 cm radius, 2,513 particles a second at 1 m/s) sits
-- 1 cm under the lid, pointing down (`dir` = "down") or along x ("side").
-- Once the water reaches the opening the nozzle must hold its points back
-- (published as emit_nozzle_held) instead of stacking particles into the
-- full tank.
local eddy = require "eddy"
local s = 0.005
local fluid = eddy.fluid { method = eddy.param("method", "dfsph"), resolution = s }
local world = fluid:world { bounds = { {0, 0, 0}, {0.06, 0.08, 0.04} }, gravity = {0, -9.81, 0}, fps = 30,
                            duration = eddy.param("duration", 1.5) }
local side = eddy.param("dir", "down") == "side"
world:add(eddy.emit_nozzle { center = side and {0.012, 0.06, 0.02} or {0.03, 0.07, 0.02}, radius = 0.01,
                             direction = side and {1, 0, 0} or {0, -1, 0}, speed = eddy.param("speed", 1.0),
                             spacing = s })
world:add(fluid)
return world
