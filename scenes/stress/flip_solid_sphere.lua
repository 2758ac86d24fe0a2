-- SPDX-License-Identifier: MIT
-- flip_solid_sphere: a 4 cm sphere lowered into a 15 cm pool, then moved
-- back and forth through it at up to 0.63 m/s for 1.5 s (issue "Stable and
-- conservative one step beyond the tested scenes", item 2). The level should
-- end at (pool volume + sphere volume) / tank area = 0.1607 m; flip_pressure
-- weights the faces the sphere cuts (Batty, Bertails & Bridson 2007) and
-- publishes "volume". tests/test_stress_flip_solids.c runs the same case.
--
--   build/eddy run scenes/stress/flip_solid_sphere.lua --stats out/flip_solid_sphere.jsonl
--   build/eddy run scenes/stress/flip_solid_sphere.lua --set solver=cholmod --set reseed=0

local eddy = require "eddy"

local dx = eddy.param("cell_size", 0.0125)   -- m
local solver = eddy.param("solver", "pcg")    -- "pcg" or "cholmod"
local reseed = eddy.param("reseed", 1)        -- 1: flip_reseed on
local W, H, D, depth = 0.2, 0.3, 0.125, 0.15  -- m: tank and pool
local r, y0, y1 = 0.04, 0.22, 0.08            -- m: radius, start and working height of the centre
local t_lower, t_osc = 0.5, 1.5               -- s: lowering, then oscillation
local A, omega = 0.05, 4 * math.pi            -- m, rad/s: peak speed A omega = 0.63 m/s

local world = eddy.world {
	bounds = { {0, 0, 0}, {W, H, D} },
	gravity = {0, -9.81, 0},
	cell_size = dx, fps = 30, duration = 3.0, cfl = 1.0, dt_max = 1 / 60,
}

world:add(eddy.emit_box { min = {0, 0, 0}, max = {W, depth, D}, spacing = dx / 2 })
world:add(eddy.gravity {})
world:add(eddy.flip_p2g {})
world:add(eddy.flip_boundary {})
world:add(eddy.flip_surface {})
world:add(eddy.flip_pressure { solver = solver })
world:add(eddy.flip_extrapolate {})
world:add(eddy.flip_g2p {})
world:add(eddy.flip_advect {})
-- after flip_advect: the colliders keep particles out, flip_boundary reads
-- their offset for this step against the last one (their velocity)
world:add(eddy.collide_sphere {
	center = {W / 2, y0, D / 2}, radius = r,
	offset = function(t)
		local dy = (t < t_lower) and (y1 - y0) * t / t_lower or (y1 - y0)
		local dxo = 0
		if t > t_lower then
			dxo = A * math.sin(omega * (math.min(t, t_lower + t_osc) - t_lower))
		end
		return { dxo, dy, 0 }
	end,
})
if reseed ~= 0 then
	world:add(eddy.flip_reseed {})
end

return world
