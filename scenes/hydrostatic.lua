-- SPDX-License-Identifier: MIT
-- hydrostatic (SPH): a block of water at rest in a closed tank with boundary
-- particles. Reports pressure_err = max |p - rho0 g d| / (rho0 g H) over
-- layers one spacing thick, for the particles more than h from the walls,
-- floor and surface, and the bottom layer's density against rho0 (1 + g H / k).
-- A particle's depth d is that of the fluid above it at rest density,
-- m N_above / (rho0 A), so rho0 g d is the weight above it per unit area: no
-- surface position to guess. Weakly compressible SPH keeps ringing at c / 4H
-- after gravity switches on, so single frames scatter; tests/test_sph.c
-- averages every step over 0.6 s.
--
--   build/eddy run scenes/hydrostatic.lua --stats out/hydro/stats.jsonl

local eddy = require "eddy"

local dx = eddy.param("spacing", 0.01)          -- m
local H = eddy.param("depth", 0.1)              -- m, water depth
local W = eddy.param("width", 0.1)              -- m, tank width (x and z)
local stiffness = eddy.param("stiffness", 200)  -- m^2/s^2: g H / k = 0.5%
local solver = eddy.param("solver", "wcsph")   -- "wcsph" (sph_pressure) or "dfsph" (implicit)
local rho0, g, h = 1000, 9.81, 2 * dx

local world = eddy.world {
	bounds = { {0, 0, 0}, {W, 2 * H, W} },
	gravity = {0, -g, 0}, fps = 30, duration = 1.0, cfl = eddy.param("cfl", 0.4), dt_max = eddy.param("dt_max", 0.01),
}
world:add(eddy.emit_box { min = {0, 0, 0}, max = {W, H, W}, spacing = dx })
local density = world:add(eddy.sph_density { radius = h, spacing = dx, rest_density = rho0, stiffness = stiffness })
if solver == "dfsph" then
	world:add(eddy.gravity {})
	world:add(eddy.sph_viscosity { viscosity = 1e-3, artificial = eddy.param("alpha", 0.05) })
	world:add(eddy.sph_dfsph { max_density_error = eddy.param("tolerance", 0.001), divergence_solver = eddy.param("divergence", true) })
else
	world:add(eddy.sph_pressure {})
	world:add(eddy.sph_viscosity { viscosity = 1e-3, artificial = 0.05 })
	world:add(eddy.gravity {})
end
world:add(eddy.sph_boundary_box { min = {0, 0, 0}, max = {W, 2 * H, W}, spacing = dx })
world:add(eddy.integrate {})
world:add(eddy.collide_box { min = {0, 0, 0}, max = {W, 2 * H, W}, inside = true })

-- pressure_err: the largest error of a layer's mean (layers one spacing
-- thick); pressure_err_particle: the largest single-particle error, which
-- carries the particle noise of k d(rho).
world:on_frame(function(w)
	local x, y, z, p, rho = w:channel("x"), w:channel("y"), w:channel("z"), w:channel("pressure"), w:channel("density")
	local vx, vy, vz = w:channel("vx"), w:channel("vy"), w:channel("vz")
	local n, v2 = #y, 0
	local order = {}
	for i = 1, n do
		order[i] = y[i]
		v2 = v2 + vx[i] ^ 2 + vy[i] ^ 2 + vz[i] ^ 2
	end
	table.sort(order)
	local below = {} -- y -> particles at or below it (ties share the count)
	for k = 1, n do below[order[k]] = k end
	local m = density:mass()
	local depth_of = m / (rho0 * W * W) -- m of depth per particle above
	local H0 = n * depth_of
	local err_p, bottom, nb = 0, 0, 0
	local sum, count = {}, {}
	for i = 1, n do
		local d = (n - below[y[i]] + 0.5) * depth_of
		if d > h and y[i] > h and x[i] > h and x[i] < W - h and z[i] > h and z[i] < W - h then
			local e = (p[i] - rho0 * g * d) / (rho0 * g * H0)
			if math.abs(e) > err_p then err_p = math.abs(e) end
			local layer = math.floor(y[i] / dx)
			sum[layer] = (sum[layer] or 0) + e
			count[layer] = (count[layer] or 0) + 1
		end
		if y[i] < dx then bottom, nb = bottom + rho[i], nb + 1 end
	end
	local err = 0
	for layer, s in pairs(sum) do
		if math.abs(s / count[layer]) > err then err = math.abs(s / count[layer]) end
	end
	return { pressure_err = err, pressure_err_particle = err_p, rms_speed = math.sqrt(v2 / math.max(n, 1)),
	         bottom_density_ratio = bottom / math.max(nb, 1) / rho0,
	         bottom_density_expected = 1 + g * H0 / stiffness }
end)

require("eddy.view").render(eddy, world, "hydrostatic")

return world
