-- SPDX-License-Identifier: MIT
-- paddle: a thin paddle turning about the vertical stirs a tank (issue 16,
-- rotating colliders; tests/test_rotate.c asserts the same case). The paddle
-- is an eddy.collide_box whose `rotation` is a function of time returning an
-- axis-angle vector in degrees (|v| degrees about v / |v|), turned about the
-- box's centre (or `pivot`); particles meet the surface's velocity
-- v + omega x (x - pivot), in SPH's boundary particles and projection and in
-- FLIP's solid faces alike.
--
--   build/eddy run scenes/paddle.lua                         (DFSPH)
--   build/eddy run scenes/paddle.lua --set method=flip
--   build/eddy run scenes/paddle.lua --set turns=2 --set tilt=30  (faster, an oblique axis)
--   build/eddy run scenes/paddle.lua --set surface=true      (render_surface frames too)
--
-- Output in out/paddle/ (or --out): frame_NNNN.png (render_points, coloured
-- by speed) and, with surface=true, liquid_NNNN.png.

local eddy = require "eddy"

local W, H, D, depth = 0.2, 0.25, 0.2, 0.1       -- m: tank and pool
local fluid = eddy.fluid {
	method = eddy.param("method", "dfsph"),      -- wcsph, dfsph, flip, pic or apic
	resolution = eddy.param("spacing", 0.005),   -- m
	dfsph = { artificial = 0.05 }, wcsph = { stiffness = 100 * 9.81 * depth, artificial = 0.05 },
}
local turns = eddy.param("turns", 1.0)           -- turns per second
local tilt = math.rad(eddy.param("tilt", 0))     -- the axis from the vertical toward +z

local world = fluid:world {
	bounds = { {0, 0, 0}, {W, H, D} },
	gravity = {0, -9.81, 0},
	fps = 30, duration = eddy.param("duration", 3.0),
}

-- the paddle at rest: 14 x 16 x 2.5 cm about (0.1, 0.1, 0.1); the pool is
-- emitted around it (four boxes), so no particle starts inside
local hx, hy, hz = 0.07, 0.08, 0.0125
if tilt ~= 0 then hx, hy = 0.06, 0.05 end         -- smaller: its tilted sweep stays off the walls
local c = { 0.1, tilt ~= 0 and 0.09 or 0.1, 0.1 }
local s = fluid.spacing
local function snap(v) return math.floor(v / s + 0.5) * s end
local z0, z1, x0, x1 = snap(c[3] - hz), snap(c[3] + hz), snap(c[1] - hx), snap(c[1] + hx)
for _, b in ipairs {
	{ {0, 0, 0}, {W, depth, z0} }, { {0, 0, z1}, {W, depth, D} },
	{ {0, 0, z0}, {x0, depth, z1} }, { {x1, 0, z0}, {W, depth, z1} },
} do
	world:add(eddy.emit_box { min = b[1], max = b[2], spacing = s })
end
world:add(fluid)

local axis = { 0, math.cos(tilt), math.sin(tilt) }
world:add(eddy.collide_box {
	min = { c[1] - hx, c[2] - hy, c[3] - hz }, max = { c[1] + hx, c[2] + hy, c[3] + hz }, inside = false,
	rotation = function(t)
		local deg = 360 * turns * t
		return { axis[1] * deg, axis[2] * deg, axis[3] * deg }
	end,
})

local eye, target = {0.45, 0.35, 0.5}, {0.1, 0.05, 0.1}
require("eddy.view").render(eddy, world, "paddle", { radius = 0.6 * s, eye = eye, target = target })
if eddy.param("surface", false) then
	world:add(eddy.render_surface { spacing = s, support = fluid.cell_size and 4 or 2, eye = eye, target = target,
	                                path = eddy.out_dir("out/paddle") .. "/liquid_%04d.png" })
end

return world
