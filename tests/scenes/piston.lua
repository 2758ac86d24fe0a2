-- SPDX-License-Identifier: MIT
-- piston (tests/test_physics.c): a paddle 1 cm thick spanning a tank 5 cm
-- wide and standing on its floor is pushed into a pool 0.1 m deep at `v`
-- m/s (the offset v min(t - start, T): it starts and stops at full
-- speed, as a scene written in a hurry moves a solid), with any method.
-- The motion starts at `start` (s). With keyed = true the host moves it
-- instead, as a program driving eddy does: each frame sets the pose for the
-- next frame time, the same motion when `start` is at least a frame (the
-- first frame's pose is never keyed). Per frame: nfast, the particles
-- faster than twice the paddle.
local eddy = require "eddy"
local s = 0.005
local v = eddy.param("v", 3.0)
local T = eddy.param("T", 0.02)
local keyed = eddy.param("keyed", false)
local start = eddy.param("start", 0.0)
local fps = 100
local function offset(t) return { v * math.max(0, math.min(t - start, T)), 0, 0 } end
local fluid = eddy.fluid { method = eddy.param("method", "dfsph"), resolution = s }
local world = fluid:world { bounds = { {0, 0, 0}, {0.5, 0.4, 0.05} }, fps = fps,
                            duration = eddy.param("duration", 0.03) }
world:add(eddy.emit_box { min = {0.03, 0, 0}, max = {0.5, 0.1, 0.05}, spacing = s })
world:add(fluid)
local paddle = world:add(eddy.collide_box { min = {0.015, 0, -0.01}, max = {0.025, 0.2, 0.06}, inside = false,
                             offset = not keyed and offset or nil })
world:on_frame(function(w)
	if keyed then paddle:set_offset(offset(w:time() + 1 / fps)) end
	local vx, vy, vz = w:channel("vx"), w:channel("vy"), w:channel("vz")
	local fast = 0
	for i = 1, #vx do
		if vx[i] * vx[i] + vy[i] * vy[i] + vz[i] * vz[i] > 4 * v * v then fast = fast + 1 end
	end
	return { nfast = fast }
end)
return world
