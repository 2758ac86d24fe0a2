-- SPDX-License-Identifier: MIT
-- flip_volume (FLIP stress case, docs/validation.md hard case 13): the liquid
-- volume of a FLIP run with and without flip_reseed, in two flows that churn
-- the particles: Martin & Moyce's dam break (eddy.dam_break, column a x 2a,
-- run on past the wall impact) and a cube of water dropped into a pool.
-- flip_pressure publishes the grid's liquid volume (`volume`, m^3) every
-- frame and the frame stats carry the particle count; this scene adds V0,
-- the volume emitted, so a reader compares the two.
--
--   build/eddy run scenes/stress/flip_volume.lua --set case=dam --set reseed=true
--   build/eddy run scenes/stress/flip_volume.lua --set case=drop --set spacing=0.003125
--
-- Params: case ("dam" or "drop"), reseed (bool), spacing (m, particle
-- spacing; cells are two spacings wide), duration (s), method (flip, pic or
-- apic), solver ("pcg" or "cholmod").

local eddy = require "eddy"

local case = eddy.param("case", "dam")
local reseed = eddy.param("reseed", false)
local method = eddy.param("method", "flip")
local settings = { solver = eddy.param("solver", "pcg"), reseed = reseed }
local fluid = eddy.fluid { method = method, resolution = eddy.param("spacing", 0.0025), [method] = settings }
local h = fluid.cell_size

local world, v0, hi
if case == "dam" then
	local dam = require "eddy.dam_break"
	local a = 0.1
	local geo
	world, geo = dam.world(eddy, fluid, { a = a, fps = 30, duration = eddy.param("duration", 2.0) })
	world:add(eddy.emit_box { min = geo.column_min, max = geo.column_max, spacing = fluid.spacing })
	v0 = a * 2 * a * geo.tank_max[3]
	hi = geo.tank_max
elseif case == "drop" then
	-- tank 0.2 x 0.3 x 0.1 m, pool 7.5 cm deep, a 5 cm cube from 17.5 cm (cell
	-- aligned for cells of 2.5, 1.25 and 0.625 cm, as tests/test_stress_flip_volume.c)
	world = fluid:world {
		bounds = { {0, 0, 0}, {0.2, 0.3, 0.1} }, gravity = {0, -9.81, 0},
		fps = 30, duration = eddy.param("duration", 2.0), cfl = 1.0,
	}
	world:add(eddy.emit_box { min = {0, 0, 0}, max = {0.2, 0.075, 0.1}, spacing = fluid.spacing })
	world:add(eddy.emit_box { min = {0.075, 0.175, 0.025}, max = {0.125, 0.225, 0.075}, spacing = fluid.spacing })
	v0 = 0.2 * 0.075 * 0.1 + 0.05 ^ 3
	hi = {0.2, 0.3, 0.1}
else
	error("flip_volume: 'case' must be \"dam\" or \"drop\" (got " .. tostring(case) .. ")")
end
world:add(fluid)

-- level: the mean over columns one cell wide (along x, the slab's z
-- included) of the highest particle plus half a spacing, the surface the
-- particles themselves draw; with a single-valued surface it is V / area.
-- level0 = V0 / area, where a settled run ends.
local lo = {0, 0, 0}
local nbin = math.floor((hi[1] - lo[1]) / h + 0.5)
local area = (hi[1] - lo[1]) * (hi[3] - lo[3])
world:on_frame(function(w)
	local x, y = w:channel("x"), w:channel("y")
	local top = {}
	for b = 1, nbin do top[b] = lo[2] end
	for i = 1, #x do
		local b = math.floor((x[i] - lo[1]) / h) + 1
		b = b < 1 and 1 or b > nbin and nbin or b
		if y[i] > top[b] then top[b] = y[i] end
	end
	local sum = 0
	for b = 1, nbin do sum = sum + top[b] + fluid.spacing / 2 - lo[2] end
	return { V0 = v0, cell = h, level = sum / nbin, level0 = v0 / area }
end)

return world
