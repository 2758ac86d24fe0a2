-- SPDX-License-Identifier: MIT
-- pour: the scene of Mueller, Charypar & Gross 2003 - water poured into a
-- box, 5625 particles in all, with any fluid method. A round jet falls from a
-- nozzle near the top into a box 0.2 x 0.3 x 0.2 m.
--
--   build/eddy run scenes/pour.lua --stats out/pour/stats.jsonl        (DFSPH)
--   build/eddy run scenes/pour.lua --set method=wcsph                 (the paper's weakly compressible SPH)
--   build/eddy run scenes/pour.lua --set method=wcsph --set stiffness=900   (stiffer: smaller density error)
--   build/eddy run scenes/pour.lua --set method=flip                  (the paper's FLIP)
--   build/eddy compare scenes/pour.lua --methods wcsph,dfsph,flip
--
-- dfsph (default) solves the pressure implicitly (sph_dfsph), so the time
-- step follows the flow speed instead of the speed of sound; wcsph uses the
-- equation of state p = k (rho - rho0) (sph_pressure); flip, pic and apic
-- project on a MAC grid of cells two spacings wide.
-- Measured on one thread (tests/bench_sph.c, `make bench`; README): dfsph at
-- CFL 1 runs the whole 4 s at 1.4 simulated s per wall s (about 1.1 in the
-- busiest half second, the pool with the jet still falling in), WCSPH
-- (k = 400) at 0.19. The mean compression (density_compression_avg, what the
-- solve controls) peaks at 1.3-2.3%; the mean density error, dominated by the
-- under-dense jet and spray, at 4-7% while the pool fills, and is 1.3% once
-- it settles.
-- DFSPH's divergence solve is off here: at CFL <= 1 it changed neither errors
-- nor stability and cost 10% (it does help at CFL 1.2: --set divergence=true).

local eddy = require "eddy"

local L, H = 0.2, 0.3                           -- m, box side and height
local solver = eddy.param("solver", "pcg")      -- FLIP's pressure solve: "pcg", "mg", "cholmod" or "hypre"
local fluid = eddy.fluid {
	method = eddy.param("method", "dfsph"),     -- wcsph, dfsph, flip, pic or apic
	resolution = eddy.param("spacing", 0.01),   -- m
	-- c = 20 m/s, about 6 x the impact speed
	wcsph = { stiffness = eddy.param("stiffness", 400) },
	-- mean predicted compression the solve stops at
	dfsph = { tolerance = eddy.param("tolerance", 0.01), artificial = eddy.param("alpha", 0.05),
	          divergence = eddy.param("divergence", false),
	          shift = tonumber(eddy.param("shift", nil)) }, -- unset: sph_dfsph's default particle shifting
	flip = { solver = solver }, pic = { solver = solver }, apic = { solver = solver },
}

local world = fluid:world {
	bounds = { {0, 0, 0}, {L, H, L} },
	gravity = {0, -9.81, 0}, fps = 30, duration = 4.0,
	-- DFSPH's cold solve (divergence = false) at 1.0, not eddy.fluid's 0.5:
	-- its shallow pool is at rest at either, the splash as fast (README,
	-- Stress cases), and the larger step costs half as much
	cfl = eddy.param("cfl", fluid.method == "dfsph" and 1.0 or fluid.cfl), dt_max = eddy.param("dt_max", 1 / 120),
}
world:add(eddy.emit_nozzle { center = {L / 2, H - 0.04, L / 2}, radius = 0.03, direction = {0, -1, 0},
                             speed = 1.0, spacing = fluid.spacing, max_particles = eddy.param("particles", 5625) })
world:add(fluid)

require("eddy.view").render(eddy, world, "pour", { radius = 0.6 * fluid.spacing })

return world
