-- SPDX-License-Identifier: MIT
-- glide (tests/test_physics.c): a layer of water 3 cm thick gliding at
-- 1.5 m/s along a floor, with any method. floor = "domain" (the world's
-- side), "box" (a collide_box whose top is at y0), "mesh" (cube.obj as that
-- box). tilt (degrees) turns gravity towards +x, speed (m/s) is the start.
-- The floor is free-slip, so the mean velocity along it is speed + g sin(tilt) t.
-- Per frame: vx (mean, m/s), want (that velocity, m/s), n.
local eddy = require "eddy"
local sp = eddy.param("spacing", 0.01)
local fluid = eddy.fluid { method = eddy.param("method", "flip"), resolution = sp }
local tilt, speed = math.rad(eddy.param("tilt", 0)), eddy.param("speed", 1.5)
local g = 9.81
local world = fluid:world { bounds = { {0, 0, 0}, {1.2, 0.3, 0.2} },
                            gravity = {g * math.sin(tilt), -g * math.cos(tilt), 0}, fps = 30, duration = 0.3 }
local floor = eddy.param("floor", "box")
local y0 = floor == "domain" and 0 or eddy.param("y0", 0.1)
world:add(eddy.emit_box { min = {0.05, y0, 0.04}, max = {0.15, y0 + 0.03, 0.16}, spacing = sp,
                          velocity = {speed, 0, 0} })
world:add(fluid)
if floor == "box" then
	world:add(eddy.collide_box { min = {-0.1, -0.1, -0.1}, max = {1.3, y0, 0.3}, inside = false })
elseif floor == "mesh" then
	world:add(eddy.collide_mesh { path = "scenes/meshes/cube.obj", scale = {1.4, y0 + 0.1, 0.4},
	                              translate = {-0.1, -0.1, -0.1} })
end
world:on_frame(function(w)
	local vx = w:channel("vx")
	local m = 0
	for i = 1, #vx do m = m + vx[i] end
	return { vx = m / #vx, want = speed + g * math.sin(tilt) * w:time(), n = #vx }
end)
return world
