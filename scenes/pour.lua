-- SPDX-License-Identifier: MIT
-- pour (SPH): the scene of Mueller, Charypar & Gross 2003 - water poured
-- into a box, 5625 particles in all. A round jet falls from a nozzle near
-- the top into a box whose walls are boundary particles.
--
--   build/eddy run scenes/pour.lua --stats out/pour/stats.jsonl
--   build/eddy run scenes/pour.lua --set solver=wcsph                 (the paper's weakly compressible SPH)
--   build/eddy run scenes/pour.lua --set solver=wcsph --set stiffness=900   (stiffer: smaller density error)
--
-- solver = "dfsph" (default) solves the pressure implicitly (sph_dfsph), so
-- the time step follows the flow speed instead of the speed of sound;
-- "wcsph" uses the equation of state p = k (rho - rho0) (sph_pressure).
-- Measured on one thread (tests/bench_sph.c, `make bench`; README): dfsph at
-- CFL 1 runs the whole 4 s at 1.4 simulated s per wall s (about 1.1 in the
-- busiest half second, the pool with the jet still falling in), WCSPH
-- (k = 400) at 0.19. The mean compression (density_compression_avg, what the
-- solve controls) peaks at 1.3-2.3%; the mean density error, dominated by the
-- under-dense jet and spray, at 4-7% while the pool fills, and is 1.3% once
-- it settles.
-- The divergence solve is off here: at CFL <= 1 it changed neither errors nor
-- stability and cost 10% (it does help at CFL 1.2: --set divergence=true).

local eddy = require "eddy"

local dx = eddy.param("spacing", 0.01)          -- m
local solver = eddy.param("solver", "dfsph")    -- "dfsph" or "wcsph"
local stiffness = eddy.param("stiffness", 400)  -- m^2/s^2 (wcsph): c = 20 m/s, about 6 x the impact speed
local tolerance = eddy.param("tolerance", 0.01) -- 1 (dfsph): mean predicted compression the solve stops at
local count = eddy.param("particles", 5625)
local L, H = 0.2, 0.3                           -- m, box side and height
if solver ~= "dfsph" and solver ~= "wcsph" then
	error("pour: solver must be \"dfsph\" or \"wcsph\" (got " .. tostring(solver) .. ")")
end
local dfsph = solver == "dfsph"

local world = eddy.world {
	bounds = { {0, 0, 0}, {L, H, L} },
	gravity = {0, -9.81, 0}, fps = 30, duration = 4.0,
	cfl = eddy.param("cfl", dfsph and 1.0 or 0.4), dt_max = eddy.param("dt_max", 1 / 120),
}
world:add(eddy.emit_nozzle { center = {L / 2, H - 0.04, L / 2}, radius = 0.03, direction = {0, -1, 0},
                             speed = 1.0, spacing = dx, max_particles = count })
world:add(eddy.sph_density { radius = 2 * dx, spacing = dx, rest_density = 1000, stiffness = stiffness })
if dfsph then
	-- the pressure solve comes after the other forces, before integrate
	world:add(eddy.gravity {})
	world:add(eddy.sph_viscosity { viscosity = 1e-3, artificial = eddy.param("alpha", 0.05) })
	world:add(eddy.sph_dfsph { max_density_error = tolerance, divergence_solver = eddy.param("divergence", false) })
else
	world:add(eddy.sph_pressure {})
	world:add(eddy.sph_viscosity { viscosity = 1e-3, artificial = 0.05 })
	world:add(eddy.gravity {})
end
world:add(eddy.sph_boundary_box { min = {0, 0, 0}, max = {L, H, L}, spacing = dx })
world:add(eddy.integrate {})
world:add(eddy.collide_box { min = {0, 0, 0}, max = {L, H, L}, inside = true })

require("eddy.view").render(eddy, world, "pour", { radius = 0.6 * dx })

return world
