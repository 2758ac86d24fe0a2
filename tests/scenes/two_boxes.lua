-- SPDX-License-Identifier: MIT
-- two_boxes (tests/test_physics.c): a pool 0.4 x 0.1 x 0.1 m built from two
-- emit_box blocks that overlap by 0.1 m (the second shifted by `off` m off
-- the first's lattice), or from one block (one = true), with any method.
-- The emitters add water only where there is none, so both make the same
-- still pool. Per frame: vmax (m/s), n (particles).
local eddy = require "eddy"
local fluid = eddy.fluid { method = eddy.param("method", "dfsph"), resolution = 0.01 }
local world = fluid:world { bounds = { {0, 0, 0}, {0.4, 0.3, 0.1} }, gravity = {0, -9.81, 0}, fps = 30,
                            duration = eddy.param("duration", 0.3) }
local off = eddy.param("off", 0)
if eddy.param("one", "false") == "true" then
	world:add(eddy.emit_box { min = {0, 0, 0}, max = {0.4, 0.1, 0.1}, spacing = fluid.spacing })
else
	world:add(eddy.emit_box { min = {0, 0, 0}, max = {0.25, 0.1, 0.1}, spacing = fluid.spacing })
	world:add(eddy.emit_box { min = {0.15 + off, 0, 0}, max = {0.4, 0.1, 0.1}, spacing = fluid.spacing })
end
world:add(fluid)
world:on_frame(function(w)
	local vx, vy, vz = w:channel("vx"), w:channel("vy"), w:channel("vz")
	local vmax = 0
	for i = 1, #vx do
		local v = vx[i] ^ 2 + vy[i] ^ 2 + vz[i] ^ 2
		if v > vmax then vmax = v end
	end
	return { vmax = math.sqrt(vmax), n = #vx }
end)
return world
