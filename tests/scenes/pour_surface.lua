-- SPDX-License-Identifier: MIT
-- The pour (scenes/pour.lua) with its liquid surface meshed every frame
-- (surface_mesh, binary PLY). tests/bench_render.c (make bench-render) runs
-- it to set the mesher's time per frame (surface_ms) beside the
-- simulation's own (issue 16: meshing should cost less than stepping).
local eddy = require "eddy"
local world = dofile("scenes/pour.lua")
world:add(eddy.surface_mesh { spacing = eddy.param("spacing", 0.01), support = eddy.param("support", 2),
                              format = "ply", path = eddy.out_dir("out/pour_surface") .. "/surface_%04d" })
return world
