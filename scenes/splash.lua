-- SPDX-License-Identifier: MIT
-- splash: a block of water released against a sphere in a tank, any fluid
-- method (FLIP by default: `make run`'s scene, about 20 s). The frames show
-- the wave running over the sphere and splashing off the far wall.
--
--   build/eddy run scenes/splash.lua --stats out/splash/stats.jsonl
--   build/eddy run scenes/splash.lua --set solver=cholmod
--   build/eddy run scenes/splash.lua --set method=dfsph --set spacing=0.02

local eddy = require "eddy"

local L, H, W = 1.0, 0.6, 0.5                     -- m, tank
local solver = eddy.param("solver", "pcg")        -- grid methods: "pcg", "mg", "cholmod" or "hypre"
local fluid = eddy.fluid {
	method = eddy.param("method", "flip"),        -- wcsph, dfsph, flip, pic or apic
	resolution = eddy.param("spacing", 1 / 64),   -- m: FLIP cells of 1/32 m
	flip = { solver = solver, flip_ratio = 0.95 }, pic = { solver = solver }, apic = { solver = solver },
}

local world = fluid:world {
	bounds = { {0, 0, 0}, {L, H, W} },
	gravity = {0, -9.81, 0},
	fps = 30, duration = 3.0, cfl = eddy.param("cfl", fluid.cell_size and 2.0 or fluid.cfl),
}

world:add(eddy.emit_box { min = {0, 0, 0}, max = {0.35, 0.5, W}, spacing = fluid.spacing,
                          jitter = fluid.cell_size and 0.25 or 0 })
world:add(fluid)
world:add(eddy.collide_sphere { center = {0.7, 0.1, 0.25}, radius = 0.1 })

require("eddy.view").render(eddy, world, "splash", {
	eye = {0.55, 0.95, 1.75}, target = {0.5, 0.18, 0.25},
	radius = fluid.spacing * 0.9, value_min = 0, value_max = 2.5,
})

return world
