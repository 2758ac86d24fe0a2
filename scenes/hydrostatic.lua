-- SPDX-License-Identifier: MIT
-- hydrostatic: a block of water at rest in a closed tank, with any fluid
-- method. Reports pressure_err = max |p - rho0 g d| / (rho0 g H) over layers
-- one spacing (SPH) or one cell (grid methods) thick, for the particles more
-- than a kernel radius or a cell from the walls, floor and surface.
-- SPH: a particle's depth d is that of the fluid above it at rest density,
-- m N_above / (rho0 A), so rho0 g d is the weight above it per unit area (no
-- surface position to guess), and the bottom layer's density is compared with
-- rho0 (1 + g H / k). Weakly compressible SPH keeps ringing at c / 4H after
-- gravity switches on, so single frames scatter; tests/test_sph.c averages
-- every step over 0.6 s.
-- FLIP, PIC, APIC: the pressure solve alone holds the column up; the surface
-- stays on the cell face at the block's top (H is a whole number of cells),
-- where the ghost-fluid pressure is exact, so d = H - y of the particle's cell
-- centre and the error measures the solver (CHOLMOD exact, PCG its tolerance).
--
--   build/eddy run scenes/hydrostatic.lua --stats out/hydro/stats.jsonl
--   build/eddy run scenes/hydrostatic.lua --set method=dfsph
--   build/eddy run scenes/hydrostatic.lua --set method=flip --set solver=cholmod --set spacing=0.003125

local eddy = require "eddy"

local H = eddy.param("depth", 0.1)              -- m, water depth
local W = eddy.param("width", H)                -- m, tank width (x and z)
local solver = eddy.param("solver", "pcg")      -- grid methods: "pcg", "mg", "cholmod" or "hypre"
-- dfsph: mean compression (default 0.001); grid methods: PCG's residual (1e-6)
local tolerance = eddy.param("tolerance", 0)
if tolerance <= 0 then tolerance = nil end
local rho0, g = 1000, 9.81
-- m^2/s^2 (wcsph): g H / k = 0.49% at any depth (200 at the default 0.1 m;
-- a fixed 200 compressed a 2 m column by 10%)
local stiffness = eddy.param("stiffness", 2000 * H)
local grid = { solver = solver, tolerance = tolerance or 1e-6 }
local fluid = eddy.fluid {
	method = eddy.param("method", "wcsph"),     -- wcsph, dfsph, flip, pic or apic
	resolution = eddy.param("spacing", 0.01),   -- m
	rest_density = rho0,
	wcsph = { stiffness = stiffness },
	dfsph = { tolerance = tolerance or 0.001, divergence = eddy.param("divergence", true),
	          artificial = eddy.param("alpha", 0.05) },
	flip = grid, pic = grid, apic = grid,
}
local cell = fluid.cell_size

local world = fluid:world {
	bounds = { {0, 0, 0}, {W, 2 * H, W} },
	gravity = {0, -g, 0}, fps = 30, duration = 1.0, cfl = eddy.param("cfl", cell and 1.0 or 0.4),
	dt_max = eddy.param("dt_max", 0.01),
}
world:add(eddy.emit_box { min = {0, 0, 0}, max = {W, H, W}, spacing = fluid.spacing })
local systems = world:add(fluid)

-- pressure_err: the largest error of a layer's mean; pressure_err_particle:
-- the largest single-particle error (SPH: the particle noise of k d(rho)).
world:on_frame(function(w)
	local x, y, z = w:channel("x"), w:channel("y"), w:channel("z")
	local vx, vy, vz = w:channel("vx"), w:channel("vy"), w:channel("vz")
	local n, v2 = #y, 0
	for i = 1, n do v2 = v2 + vx[i] ^ 2 + vy[i] ^ 2 + vz[i] ^ 2 end
	local pressure, depth, H0, margin, layer_of
	if cell then
		local p = w:channel("cell_pressure")
		local nx, ny = math.floor(W / cell + 0.5), math.floor(2 * H / cell + 0.5)
		local function index(i) return math.floor(x[i] / cell), math.floor(y[i] / cell), math.floor(z[i] / cell) end
		pressure = function(i)
			local a, b, c = index(i)
			return p[1 + a + nx * (b + ny * c)]
		end
		depth = function(i) local _, b = index(i) return H - (b + 0.5) * cell end
		H0, margin = H, cell
		layer_of = function(i) local _, b = index(i) return b end
	else
		local p = w:channel("pressure")
		local order = {}
		for i = 1, n do order[i] = y[i] end
		table.sort(order)
		local below = {} -- y -> particles at or below it (ties share the count)
		for k = 1, n do below[order[k]] = k end
		local depth_of = systems.sph_density:mass() / (rho0 * W * W) -- m of depth per particle above
		pressure = function(i) return p[i] end
		depth = function(i) return (n - below[y[i]] + 0.5) * depth_of end
		H0, margin = n * depth_of, 2 * fluid.spacing
		layer_of = function(i) return math.floor(y[i] / fluid.spacing) end
	end
	local err_p, sum, count = 0, {}, {}
	for i = 1, n do
		local d = depth(i)
		if d > margin and y[i] > margin and x[i] > margin and x[i] < W - margin and z[i] > margin and z[i] < W - margin then
			local e = (pressure(i) - rho0 * g * d) / (rho0 * g * H0)
			if math.abs(e) > err_p then err_p = math.abs(e) end
			local layer = layer_of(i)
			sum[layer] = (sum[layer] or 0) + e
			count[layer] = (count[layer] or 0) + 1
		end
	end
	local err = 0
	for layer, s in pairs(sum) do
		if math.abs(s / count[layer]) > err then err = math.abs(s / count[layer]) end
	end
	local fields = { pressure_err = err, pressure_err_particle = err_p, rms_speed = math.sqrt(v2 / math.max(n, 1)) }
	if not cell then
		local rho, bottom, nb = w:channel("density"), 0, 0
		for i = 1, n do
			if y[i] < fluid.spacing then bottom, nb = bottom + rho[i], nb + 1 end
		end
		fields.bottom_density_ratio = bottom / math.max(nb, 1) / rho0
		fields.bottom_density_expected = 1 + g * H0 / stiffness
	end
	return fields
end)

require("eddy.view").render(eddy, world, "hydrostatic")

return world
