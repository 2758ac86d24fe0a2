-- SPDX-License-Identifier: MIT
-- surface: a small 3D dam break around a ball, shown as liquid rather than
-- balls. Every frame the particles' surface (the 1/2 level of their colour
-- field, meshed by OpenVDB) is written as binary PLY and OBJ (and .vdb with
-- --set vdb=true) and drawn shaded by render_surface; render_points' sphere
-- frames are kept beside them for comparison (--set points=false drops them).
--
--   build/eddy run scenes/surface.lua                      (DFSPH, ~9k particles)
--   build/eddy run scenes/surface.lua --set method=flip
--   build/eddy run scenes/surface.lua --set vdb=true --out out/surface_vdb
--
-- Output in out/surface/ (or --out): surface_NNNN.ply/.obj[/.vdb] (Blender:
-- File > Import; Houdini reads the .vdb as a level set), liquid_NNNN.png
-- (render_surface) and frame_NNNN.png (render_points).

local eddy = require "eddy"

local L, H, W = 0.6, 0.4, 0.3                   -- m, tank
local fluid = eddy.fluid {
	method = eddy.param("method", "dfsph"),     -- wcsph, dfsph, flip, pic or apic
	resolution = eddy.param("spacing", 0.0125), -- m
	-- WCSPH's stiffness from the scene (sph_density: c = 10 x the fall speed;
	-- a fixed 200 compressed 1% where the column hits the ball, 0.24% now)
	dfsph = { artificial = 0.05 }, wcsph = { artificial = 0.05 },
}

local world = fluid:world {
	bounds = { {0, 0, 0}, {L, H, W} },
	gravity = {0, -9.81, 0},
	fps = 30, duration = eddy.param("duration", 1.5),
}

world:add(eddy.emit_box { min = {0, 0, 0}, max = {0.2, 0.3, W}, spacing = fluid.spacing,
                          jitter = fluid.cell_size and 0.25 or 0 })
world:add(fluid)
world:add(eddy.collide_sphere { center = {0.42, 0.06, 0.15}, radius = 0.06 })

-- The colour field's kernel spans `support` spacings. SPH keeps its
-- particles near the rest spacing, so 2 (its own kernel's) gives a smooth
-- surface; FLIP's particles bunch along the flow with gaps between, so their
-- field needs a wider kernel to be as smooth.
local support = eddy.param("support", fluid.cell_size and 4 or 2)
local out = eddy.out_dir("out/surface")
local formats = { "ply", "obj" }
if eddy.param("vdb", false) then formats[#formats + 1] = "vdb" end
world:add(eddy.surface_mesh { spacing = fluid.spacing, support = support, format = formats, path = out .. "/surface_%04d" })

local camera = { eye = {0.95, 0.55, 0.85}, target = {0.3, 0.08, 0.15} }
world:add(eddy.render_surface { spacing = fluid.spacing, support = support, eye = camera.eye, target = camera.target,
                                path = out .. "/liquid_%04d.png" })
if eddy.param("points", true) then
	require("eddy.view").render(eddy, world, "surface", {
		eye = camera.eye, target = camera.target, radius = 0.9 * fluid.spacing,
		value_min = 0, value_max = 2.0,
	})
end

return world
