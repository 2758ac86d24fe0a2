-- SPDX-License-Identifier: MIT
-- The dam-break setup of scenes/dam_break.lua, which runs with any fluid
-- method, and of the studies that sweep it.
--
-- Martin & Moyce (1952): a column of square base a and height 2a stands against
-- the back wall (x = 0) of a tank; the gate opens at t = 0. The surge front z
-- (from the back wall) is reported as Z = z / a against T = t * sqrt(2 g / a).
-- A thin slab in z (free-slip walls) stands in for 2D flow; the tank is 5.5 a
-- long so the front runs free until T = 3 (Z(3) is about 3.7).
--
--   local dam = require "eddy.dam_break"
--   local fluid = eddy.fluid { method = "flip", resolution = 0.005 }
--   local world, geo = dam.world(eddy, fluid, { a = 0.1 })
--   world:add(eddy.emit_box { min = geo.column_min, max = geo.column_max, spacing = geo.spacing })
--   world:add(fluid)
--   dam.report(world, geo)

local M = {}

-- The tank and the column for a fluid group (eddy.fluid{}): the world comes
-- from the group, so it carries the method's grid and CFL number, and the
-- group takes the tank's walls from it. The slab is 4 particle spacings
-- thick for SPH and 4 cells for a grid method. Fields of p: a (m), fps,
-- duration (s; default T = 3.2), cfl (default the method's), g (m/s^2).
function M.world(eddy, fluid, p)
	local a = assert(p.a, "dam_break: 'a' (column base, m) is required")
	local h = fluid.spacing
	local g = p.g or 9.81
	local W = 4 * (fluid.cell_size or h)
	local L, H = 5.5 * a, 2.5 * a
	local t_ref = math.sqrt(a / (2 * g)) -- t = T * t_ref
	local world = fluid:world {
		bounds = { {0, 0, 0}, {L, H, W} },
		gravity = {0, -g, 0},
		fps = p.fps or 200,
		duration = p.duration or 3.2 * t_ref,
		cfl = p.cfl,
	}
	return world, {
		a = a, spacing = h, g = g, t_ref = t_ref,
		tank_min = {0, 0, 0}, tank_max = {L, H, W},
		column_min = {0, 0, 0}, column_max = {a, 2 * a, W},
	}
end

function M.front(world, geo)
	local x, y = world:channel("x"), world:channel("y")
	local front, floor = 0, geo.a / 4
	for i = 1, #x do
		local xi = x[i]
		if xi > front and y[i] < floor then front = xi end
	end
	return front + geo.spacing / 2
end

-- Adds Z and T to every frame's stats.
function M.report(world, geo)
	world:on_frame(function(w)
		return { Z = M.front(w, geo) / geo.a, T = w:time() / geo.t_ref }
	end)
end

-- Renders the thin slab from the front, orthographic, into out/<name>/.
function M.render(eddy, world, geo, name)
	local a = geo.a
	local L, H = geo.tank_max[1], geo.tank_max[2]
	local W = geo.tank_max[3]
	return require("eddy.view").render(eddy, world, name, {
		width = 1056, height = 480, projection = "orthographic", ortho_height = 1.1 * H,
		eye = {L / 2, H / 2, W + 10 * a}, target = {L / 2, H / 2, W / 2},
		radius = 0.6 * geo.spacing, value_min = 0, value_max = 1.5 * math.sqrt(2 * geo.g * a),
	})
end

-- Reads a Martin & Moyce CSV (# comments, a "T,Z" header, then rows) into
-- { {T = ..., Z = ...}, ... } sorted by T.
function M.read_reference(path)
	local rows = {}
	for line in assert(io.open(path)):lines() do
		local T, Z = line:match("^%s*([%d%.eE+-]+)%s*,%s*([%d%.eE+-]+)")
		if T then rows[#rows + 1] = { T = tonumber(T), Z = tonumber(Z) } end
	end
	table.sort(rows, function(p, q) return p.T < q.T end)
	return rows
end

-- Linear interpolation of Z at T in a sorted reference (nil outside it).
function M.interpolate(rows, T)
	for i = 2, #rows do
		local p, q = rows[i - 1], rows[i]
		if T >= p.T and T <= q.T then
			return p.Z + (q.Z - p.Z) * (T - p.T) / (q.T - p.T)
		end
	end
	return nil
end

return M
