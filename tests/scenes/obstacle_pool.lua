-- SPDX-License-Identifier: MIT
-- obstacle_pool (tests/test_physics.c): a pool 0.4 x 0.15 x 0.2 m emitted as
-- one emit_box around an obstacle standing in it, with any method: solid =
-- "sphere" (4 cm, off the lattice), "mesh" (the same sphere as the
-- icosphere mesh), "box" (turned 30 degrees about y), "none". The emitter leaves out the points inside the solid, so the pool
-- starts still around it. Per frame: vmax (m/s), n (particles), inside
-- (particles inside the obstacle).
local eddy = require "eddy"
local fluid = eddy.fluid { method = eddy.param("method", "dfsph"), resolution = 0.01 }
local world = fluid:world { bounds = { {0, 0, 0}, {0.4, 0.3, 0.2} }, gravity = {0, -9.81, 0}, fps = 30,
                            duration = eddy.param("duration", 0.3) }
world:add(eddy.emit_box { min = {0, 0, 0}, max = {0.4, 0.15, 0.2}, spacing = fluid.spacing })
world:add(fluid)
local solid = eddy.param("solid", "sphere")
local c, r = {0.103, 0.078, 0.097}, 0.04
local half = {0.03, 0.05, 0.04}
local cos30, sin30 = math.cos(math.rad(30)), math.sin(math.rad(30))
if solid == "sphere" then
	world:add(eddy.collide_sphere { center = c, radius = r })
elseif solid == "mesh" then
	world:add(eddy.collide_mesh { path = "scenes/meshes/icosphere.obj", scale = {r, r, r}, translate = c })
elseif solid == "box" then
	world:add(eddy.collide_box { min = {c[1] - half[1], c[2] - half[2], c[3] - half[3]},
	                             max = {c[1] + half[1], c[2] + half[2], c[3] + half[3]},
	                             rotation = {0, 30, 0}, inside = false })
end
-- whether p lies inside the obstacle (the box turned about its centre)
local function inside(x, y, z)
	local dx, dy, dz = x - c[1], y - c[2], z - c[3]
	if solid == "sphere" then return dx * dx + dy * dy + dz * dz < r * r end
	-- the icosphere's faces lie up to 0.0045 r inside the sphere
	if solid == "mesh" then return dx * dx + dy * dy + dz * dz < (0.995 * r) ^ 2 end
	if solid == "box" then
		-- into the box's frame: the inverse of the 30 degree turn about y
		local bx, bz = cos30 * dx - sin30 * dz, sin30 * dx + cos30 * dz
		return math.abs(bx) < half[1] and math.abs(dy) < half[2] and math.abs(bz) < half[3]
	end
	return false
end
world:on_frame(function(w)
	local x, y, z = w:channel("x"), w:channel("y"), w:channel("z")
	local vx, vy, vz = w:channel("vx"), w:channel("vy"), w:channel("vz")
	local vmax, n_in = 0, 0
	for i = 1, #vx do
		local v = vx[i] ^ 2 + vy[i] ^ 2 + vz[i] ^ 2
		if v > vmax then vmax = v end
		if inside(x[i], y[i], z[i]) then n_in = n_in + 1 end
	end
	return { vmax = math.sqrt(vmax), n = #vx, inside = n_in }
end)
return world
