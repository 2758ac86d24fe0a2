-- SPDX-License-Identifier: MIT
-- splash: a block of water collapses in a tank and runs into a ball, in full
-- 3D, with FLIP (MAC grid, PCG pressure, ghost-fluid free surface). The
-- default scene of `make run`: it renders into out/splash/frame_NNNN.png.
--
--   build/eddy run scenes/splash.lua --set cell_size=0.025 --video out/splash.mp4

local eddy = require "eddy"

local dx = eddy.param("cell_size", 1 / 32)        -- m, grid spacing
local solver = eddy.param("solver", "pcg")        -- "pcg" or "cholmod"
local L, H, W = 1.0, 0.6, 0.5                     -- m, tank

local world = eddy.world {
	bounds = { {0, 0, 0}, {L, H, W} },
	gravity = {0, -9.81, 0},
	fps = 30, duration = 3.0, cfl = 2.0,
	cell_size = dx,
}

-- 2 x 2 x 2 particles per cell
world:add(eddy.emit_box { min = {0, 0, 0}, max = {0.35, 0.5, W}, spacing = dx / 2, jitter = 0.25 })
world:add(eddy.gravity {})
world:add(eddy.flip_p2g {})
world:add(eddy.flip_boundary {})
world:add(eddy.collide_sphere { center = {0.7, 0.1, 0.25}, radius = 0.1 })
world:add(eddy.flip_surface {})
world:add(eddy.flip_pressure { solver = solver })
world:add(eddy.flip_extrapolate {})
world:add(eddy.flip_g2p { flip_ratio = 0.95 })
world:add(eddy.flip_advect {})
world:add(eddy.flip_reseed {})

world:add(eddy.render_points {
	width = 960, height = 540,
	eye = {0.55, 0.95, 1.75}, target = {0.5, 0.18, 0.25},
	radius = dx * 0.45,
	color_by = "speed", colormap = "viridis", value_min = 0, value_max = 2.5,
	path = eddy.out_dir("out/splash") .. "/frame_%04d.png",
})

return world
