-- SPDX-License-Identifier: MIT
-- slide (tests/test_physics.c): a pool 9 cm deep on a collider floor 1 cm
-- thick, longer than the tank, that slides along x at `v` m/s from t = 0,
-- with any method. A free-slip floor moving along itself does the water no
-- work: its energy stays at its start and it is not dragged along. Per
-- frame: drag (m/s, the water's mean x velocity).
local eddy = require "eddy"
local s = eddy.param("spacing", 0.005)
local v = eddy.param("v", 5.0)
local fluid = eddy.fluid { method = eddy.param("method", "dfsph"), resolution = s }
local world = fluid:world { bounds = { {0, 0, 0}, {0.6, 0.3, 0.05} }, fps = 100,
                            duration = eddy.param("duration", 0.3) }
world:add(eddy.emit_box { min = {0, 0.01, 0}, max = {0.6, 0.1, 0.05}, spacing = s })
world:add(fluid)
world:add(eddy.collide_box { min = {-5, 0, -0.01}, max = {5.6, 0.01, 0.06}, inside = false,
                             offset = function(t) return { v * t, 0, 0 } end })
world:on_frame(function(w)
	local vx = w:channel("vx")
	local sum = 0
	for i = 1, #vx do sum = sum + vx[i] end
	return { drag = sum / #vx }
end)
return world
