-- SPDX-License-Identifier: MIT
-- outflow: water leaving the world through its open sides (escape =
-- "remove", no tank), with any fluid method.
--
--   case = "flight": a 0.1 m block flies at (vx, vy, vz) with no gravity
--   through a box that ends a little past it; with nothing to push it, it
--   must leave at its own speed and be removed, every particle.
--   case = "jet": a 2 m/s jet from a nozzle crosses the box and leaves
--   through the far side, falling; the count must level off, nothing piling
--   up at the side.
--   case = "spill": a column 0.1 x 0.2 m collapses along a channel whose far
--   end, the world's +x side, is open: the water pours out over it.
--   case = "closed": the column in a closed tank (the world's box): escape
--   (param, default "remove") must change nothing there.
--
-- Per frame: n (particles), vx vy vz (their mean velocity, m/s; 0 with none
-- left), piled (particles within one spacing of an open side moving slower
-- than half the start speed, sqrt(2 g 0.2) for the column: water held by a
-- wall that should not be there).
--
--   build/eddy run tests/scenes/outflow.lua --set method=flip --stats - --quiet
--
-- Params: method, case, spacing (m), vx vy vz (m/s), duration (s), escape, solver.

local eddy = require "eddy"

local case = eddy.param("case", "flight")
local h = eddy.param("spacing", 0.01)
-- spill: a channel that reaches past the world's +x side, which stays open
-- closed: the same column in a closed tank (the world's box), where open
-- sides must change nothing: the tank covers them
local tank = false
if case == "spill" then tank = { min = { 0, 0, 0 }, max = { 0.6, 0.3, 0.1 } } end
if case == "closed" then tank = nil end -- the world's box
local solver = eddy.param("solver", "pcg") -- the grid methods' pressure solve
local fluid = eddy.fluid { method = eddy.param("method", "flip"), resolution = h, tank = tank,
                           flip = { solver = solver }, pic = { solver = solver }, apic = { solver = solver } }
local speed, world, B
if case == "flight" then
	local V = { eddy.param("vx", 1.0), eddy.param("vy", 0.5), eddy.param("vz", 0.25) }
	speed = math.sqrt(V[1] ^ 2 + V[2] ^ 2 + V[3] ^ 2)
	-- the block starts 0.05 m from the +x side; it is gone after (0.05 + 0.1) / vx
	B = { 0.25, 0.3, 0.3 }
	world = fluid:world { bounds = { {0, 0, 0}, B }, gravity = {0, 0, 0}, fps = 50,
	                      duration = eddy.param("duration", 0.3), escape = "remove" }
	world:add(eddy.emit_box { min = {0.1, 0.1, 0.1}, max = {0.2, 0.2, 0.2}, spacing = h, velocity = V })
elseif case == "jet" then
	speed = 2.0
	B = { 0.3, 0.2, 0.1 }
	world = fluid:world { bounds = { {0, 0, 0}, B }, fps = 30,
	                      duration = eddy.param("duration", 1.0), escape = "remove" }
	world:add(eddy.emit_nozzle { center = {0.02, 0.1, 0.05}, radius = 0.01, direction = {1, 0.5, 0},
	                             speed = speed, spacing = h })
elseif case == "spill" or case == "closed" then
	-- a column 0.1 m wide and 0.2 m tall at the closed end of a channel whose
	-- far end (x = 0.4) is open: the tank reaches past it, so nothing closes
	-- that side
	speed = math.sqrt(2 * 9.81 * 0.2)
	B = { 0.4, 0.3, 0.1 }
	world = fluid:world { bounds = { {0, 0, 0}, B }, fps = 30, duration = eddy.param("duration", 1.0),
	                      escape = eddy.param("escape", "remove") }
	world:add(eddy.emit_box { min = {0, 0, 0}, max = {0.1, 0.2, 0.1}, spacing = h })
else
	error("outflow: case must be \"flight\", \"jet\", \"spill\" or \"closed\" (got " .. tostring(case) .. ")")
end
world:add(fluid)

world:on_frame(function(w)
	local x, y, z = w:channel("x"), w:channel("y"), w:channel("z")
	local vx, vy, vz = w:channel("vx"), w:channel("vy"), w:channel("vz")
	local n = #x
	local sx, sy, sz, piled = 0, 0, 0, 0
	for i = 1, n do
		sx, sy, sz = sx + vx[i], sy + vy[i], sz + vz[i]
		local s = math.sqrt(vx[i] ^ 2 + vy[i] ^ 2 + vz[i] ^ 2)
		local near = x[i] > B[1] - h -- the spill's one open side
		if case ~= "spill" then
			near = near or x[i] < h or y[i] < h or z[i] < h or y[i] > B[2] - h or z[i] > B[3] - h
		end
		if near and s < 0.5 * speed then piled = piled + 1 end
	end
	local k = n > 0 and 1 / n or 0
	return { n = n, vx = sx * k, vy = sy * k, vz = sz * k, piled = piled }
end)

return world
