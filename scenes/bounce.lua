-- SPDX-License-Identifier: MIT
-- bounce: a block of particles falls into a box and splashes around a sphere
-- that sweeps back and forth through the tank. No fluid forces: this scene
-- shows the engine core (emitter, gravity, integrator, colliders, a moving
-- collider animated from Lua) and is the default scene of `make run`.
--
--   build/eddy run scenes/bounce.lua --set spacing=0.01 --stats out/bounce/stats.jsonl
--   (PNG frames go to out/bounce/frame_0001.png ...; --out DIR moves them)

local eddy = require "eddy"

local h = eddy.param("spacing", 0.02)          -- m, particle spacing
local restitution = eddy.param("restitution", 0.5)

local world = eddy.world {
	bounds = { {0, 0, 0}, {1, 1, 0.5} },
	gravity = {0, -9.81, 0},
	fps = 30, duration = 3.0, cfl = 0.5,
}

world:add(eddy.emit_box { min = {0.05, 0.45, 0.05}, max = {0.45, 0.95, 0.45}, spacing = h, jitter = 0.1 })
world:add(eddy.gravity {})
world:add(eddy.integrate {})
-- the sphere sweeps along x; its offset is a function of time, so the
-- engine knows its velocity and it pushes the particles it meets
world:add(eddy.collide_sphere {
	center = {0.5, 0.15, 0.25}, radius = 0.12, restitution = restitution,
	offset = function(t) return { 0.3 * math.sin(2.0 * t), 0, 0 } end,
})
world:add(eddy.collide_box { min = {0, 0, 0}, max = {1, 1, 0.5}, inside = true,
                             restitution = restitution, friction = 0.1 })

-- frames: spheres coloured by speed, into out/bounce/ (or --out DIR)
world:add(eddy.render_points {
	width = 960, height = 540, radius = 0.55 * h,
	color_by = "speed", colormap = "viridis", value_min = 0, value_max = 3,
	path = eddy.out_dir("out/bounce") .. "/frame_%04d.png",
})

world:on_frame(function(w, frame)
	-- the height of the highest particle, as a scene-defined stats field
	local y, top = w:channel("y"), 0
	for i = 1, #y do if y[i] > top then top = y[i] end end
	return { top = top }
end)

return world
