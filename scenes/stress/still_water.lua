-- SPDX-License-Identifier: MIT
-- still_water (SPH stress case): a 0.1 x 0.1 m column of water at rest in a
-- closed box (boundary particles), depth a param, to see whether a pressure
-- solve holds deep water still. At rest the bottom layer's pressure is the
-- weight above it per unit area: with N particles of mass m in the area A
-- the fluid is H = N m / (rho0 A) deep, and the bottom layer's centre (one
-- spacing thick) lies dx / 2 above the floor, so p_bottom = rho0 g (H - dx / 2);
-- the layer mean of particles with y < dx is compared with it.
-- Per frame: vmax (m/s), vmax_ratio = vmax / sqrt(g H) (the speed of a wave
-- on water H deep: a still column keeps it far below 1), vmax_height (the
-- fastest particle's height above the floor / H: 1 at the surface, where a
-- solver's surface treatment would show, less in the bulk), bottom_p_ratio
-- (bottom layer mean pressure / rho0 g (H - dx / 2)), thrown (particles
-- more than 3 spacings above the surface), and the bulk beside the fastest
-- particle: v99_ratio (the 99th percentile speed / sqrt(g H): the speed
-- all but 1% of the particles stay under, blind to a burst of a few) and
-- ke_ratio (the mean kinetic energy per unit mass / g H).
--
--   build/eddy run scenes/stress/still_water.lua --set depth=0.5 --set solver=dfsph --stats - --quiet
--
-- Params: depth (m, 0.5 = 40 layers at the default spacing), spacing (m),
-- solver ("dfsph" or "wcsph"), tolerance, max_iterations, divergence_tolerance,
-- divergence_iterations, divergence, shift and coarse_grid (sph_dfsph's
-- max_density_error, max_iterations, max_divergence_error,
-- max_divergence_iterations, divergence_solver, shift and coarse_grid;
-- unset: its defaults),
-- stiffness (sph_pressure's, m^2/s^2), cfl, duration (s).
-- width (m, the column's side; 0.05 for the narrow 150-200 layer columns).
-- At sph_dfsph's defaults (tests/test_stress_dfsph.c): 10, 20 and 40 layers
-- come to rest (max speed under 2% of sqrt(g H) once settled), and so does a
-- narrow column 200 layers deep, and 100 layers (its particle shifting lets
-- the emitted lattice relax without bursts: README, Stress cases); the
-- bottom pressure reads 1.02-1.05 at every depth, 1.06 in the narrow column.

local eddy = require "eddy"

local dx = eddy.param("spacing", 0.0125)        -- m
local D = eddy.param("depth", 0.5)              -- m, water depth
local W = eddy.param("width", 0.1)              -- m, column width (x and z)
local solver = eddy.param("solver", "dfsph")    -- "dfsph" (sph_dfsph) or "wcsph" (sph_pressure)
local rho0, g = 1000, 9.81
local top = D * 1.5

local world = eddy.world {
	bounds = { {0, 0, 0}, {W, top, W} }, gravity = {0, -g, 0},
	fps = 30, duration = eddy.param("duration", 2.0), cfl = eddy.param("cfl", 0.5),
}
world:add(eddy.emit_box { min = {0, 0, 0}, max = {W, D, W}, spacing = dx })
-- WCSPH: g D / k = 1% by default (k = 100 g D)
local density = world:add(eddy.sph_density { radius = 2 * dx, spacing = dx, rest_density = rho0,
                                             stiffness = eddy.param("stiffness", 100 * g * D) })
if solver == "dfsph" then
	world:add(eddy.gravity {})
	world:add(eddy.sph_viscosity { viscosity = 1e-3, artificial = 0.05 })
	-- params arrive as strings: the solver's fields are numbers
	local div = eddy.param("divergence", nil)
	if div ~= nil then div = div ~= "false" end
	local coarse = eddy.param("coarse_grid", nil)
	if coarse ~= nil then coarse = coarse ~= "false" end
	world:add(eddy.sph_dfsph { max_density_error = tonumber(eddy.param("tolerance", nil)),
	                           max_iterations = tonumber(eddy.param("max_iterations", nil)),
	                           max_divergence_error = tonumber(eddy.param("divergence_tolerance", nil)),
	                           max_divergence_iterations = tonumber(eddy.param("divergence_iterations", nil)),
	                           divergence_solver = div,
	                           shift = tonumber(eddy.param("shift", nil)), coarse_grid = coarse })
else
	world:add(eddy.sph_pressure {})
	world:add(eddy.sph_viscosity { viscosity = 1e-3, artificial = 0.05 })
	world:add(eddy.gravity {})
end
world:add(eddy.sph_boundary_box { min = {0, 0, 0}, max = {W, top, W}, spacing = dx })
world:add(eddy.integrate {})
world:add(eddy.collide_box { min = {0, 0, 0}, max = {W, top, W}, inside = true })

world:on_frame(function(w)
	local y, p = w:channel("y"), w:channel("pressure")
	local vx, vy, vz = w:channel("vx"), w:channel("vy"), w:channel("vz")
	local n, vmax, ymax, pb, nb, thrown, v2sum, speeds = #y, 0, 0, 0, 0, 0, 0, {}
	local H = n * density:mass() / (rho0 * W * W)
	for i = 1, n do
		local v2 = vx[i] ^ 2 + vy[i] ^ 2 + vz[i] ^ 2
		local s = math.sqrt(v2)
		speeds[i], v2sum = s, v2sum + v2
		if s > vmax then vmax, ymax = s, y[i] end
		if y[i] < dx then pb, nb = pb + p[i], nb + 1 end
		if y[i] > H + 3 * dx then thrown = thrown + 1 end
	end
	table.sort(speeds)
	local v99 = n > 0 and speeds[math.max(1, math.ceil(0.99 * n))] or 0
	return { vmax = vmax, vmax_ratio = vmax / math.sqrt(g * H), vmax_height = ymax / H,
	         v99_ratio = v99 / math.sqrt(g * H), ke_ratio = 0.5 * v2sum / math.max(n, 1) / (g * H),
	         bottom_p_ratio = pb / math.max(nb, 1) / (rho0 * g * (H - dx / 2)), thrown = thrown }
end)

return world
