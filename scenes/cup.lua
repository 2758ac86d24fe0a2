-- SPDX-License-Identifier: MIT
-- cup: water poured into a cup read from a mesh file (scenes/meshes/cup.obj,
-- written by scripts/gen_meshes.lua: a 64-sided cup, cavity radius 4 cm,
-- walls and floor 1 cm thick, 10 cm tall), with any fluid method.
--
--   build/eddy run scenes/cup.lua                        (FLIP)
--   build/eddy run scenes/cup.lua --set method=dfsph     (DFSPH; --set spacing=0.003 for a quicker run)
--   build/eddy run scenes/cup.lua --set mesh=my_cup.stl  (any mesh assimp reads, closed)
--
-- Output in out/cup/ (or --out): frame_NNNN.png (sprites coloured by speed)
-- and liquid_NNNN.png (render_surface: the liquid's surface and the cup).
--
-- The cup is an eddy.collide_mesh: a signed distance field built from the
-- mesh when the scene loads (exact near the surface), which FLIP's boundary
-- sees as solid cells with fractional faces and which keeps SPH particles
-- out. Paths are taken from the current directory (run from the checkout).
-- FLIP needs walls at least two of its cells thick (cells are two spacings
-- wide: spacing <= 2.5 mm for these 1 cm walls); thinner walls let the
-- grid's velocity carry particles through. With SPH the mesh carries
-- boundary particles (Akinci 2012), so the water meets the walls with a full
-- neighbourhood (see README, Meshes).

local eddy = require "eddy"

local fluid = eddy.fluid {
	method = eddy.param("method", "flip"),      -- wcsph, dfsph, flip, pic or apic
	resolution = eddy.param("spacing", 0.0025), -- m
}

local world = fluid:world {
	bounds = { {0, 0, 0}, {0.14, 0.2, 0.14} },
	gravity = {0, -9.81, 0}, fps = 30, duration = eddy.param("duration", 3.0),
	cfl = fluid.cfl, dt_max = 1 / 120,
}
-- a jet 3 cm wide from 18 cm up; half the cavity's volume (2.3e-4 m^3)
local spacing = fluid.spacing
world:add(eddy.emit_nozzle { center = {0.07, 0.18, 0.07}, radius = 0.015, direction = {0, -1, 0},
                             speed = 1.0, spacing = spacing,
                             max_particles = math.floor(0.5 * math.pi * 0.04^2 * 0.09 / spacing^3) })
world:add(fluid)
world:add(eddy.collide_mesh { path = eddy.param("mesh", "scenes/meshes/cup.obj"), translate = {0.07, 0, 0.07} })

local eye, target = {0.07, 0.25, 0.3}, {0.07, 0.06, 0.07}
require("eddy.view").render(eddy, world, "cup", { radius = 0.6 * spacing, eye = eye, target = target })
-- the liquid's surface, shaded, with the cup drawn as the zero level of its
-- distance field (liquid_NNNN.png beside the sprite frames); --set surface=false skips it
if eddy.param("render", true) and eddy.param("surface", true) then
	world:add(eddy.render_surface { spacing = spacing, support = fluid.cell_size and 4 or 2, eye = eye, target = target,
	                                path = eddy.out_dir("out/cup") .. "/liquid_%04d.png" })
end

return world
