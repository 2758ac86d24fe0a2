-- SPDX-License-Identifier: MIT
-- retreat (tests/test_physics.c): a paddle 1 cm thick standing against the
-- face of a pool 0.1 m deep is pulled away from it at `v` m/s (dir = "x"),
-- or lifted along it (dir = "y"), from t = 0, with any method; the paddle
-- spans x0 .. x0 + thickness. A wall
-- cannot pull water after it: the face is released and falls as a dam
-- break's column does, whose front runs at most 2 sqrt(g H) (Ritter), and
-- the paddle, moving away or along the water, does it no work. Per frame:
-- front (m, the water's least x), face_vx (m/s, the mean x velocity of the
-- water within 2 cm of the paddle's start).
local eddy = require "eddy"
local s = eddy.param("spacing", 0.005)
local v = eddy.param("v", 3.0)
local dir = eddy.param("dir", "x")
local x0 = eddy.param("x0", 0.2)               -- m, the paddle's face away from the water
local thickness = eddy.param("thickness", 0.01) -- m
local face = x0 + thickness                     -- the water's face
local fluid = eddy.fluid { method = eddy.param("method", "dfsph"), resolution = s }
local world = fluid:world { bounds = { {0, 0, 0}, {0.6, 0.5, 0.05} }, fps = 100,
                            duration = eddy.param("duration", 0.1) }
world:add(eddy.emit_box { min = {face, 0, 0}, max = {0.5, 0.1, 0.05}, spacing = s })
world:add(fluid)
local function offset(t)
	local d = math.min(v * t, 0.15)
	if dir == "x" then return { -d, 0, 0 } end
	return { 0, d, 0 }
end
world:add(eddy.collide_box { min = {x0, 0, -0.01}, max = {face, 0.2, 0.06}, inside = false, sph_walls = true,
                             offset = offset })
world:on_frame(function(w)
	local x, vx = w:channel("x"), w:channel("vx")
	local front, sv, n = 1, 0, 0
	for i = 1, #x do
		if x[i] < front then front = x[i] end
		if x[i] < face + 0.02 then sv, n = sv + vx[i], n + 1 end
	end
	return { front = front, face_vx = n > 0 and sv / n or 0 }
end)
return world
