-- SPDX-License-Identifier: MIT
-- lid (stress case): a block of water touching the lid of a closed tank, or
-- the underside of a shelf, released at rest (or, without gravity, moving
-- away from the lid). In this model the space the water leaves is air at
-- p = 0, so nothing may hold it: it falls freely. Per frame: fall_ratio =
-- the block's mean velocity along g over g t (+ its start speed), 1 in free
-- fall; top_gap = how far the highest particle is below the lid, over the
-- free fall's 0.5 g t^2 (1 when the top layer left with the rest).
--
--   build/eddy run scenes/stress/lid.lua --set method=flip --stats - --quiet
--   build/eddy run scenes/stress/lid.lua --set gx=4 --set gy=-9        (gravity off the lid's normal)
--   build/eddy run scenes/stress/lid.lua --set shelf=true              (under a collider box)
--   build/eddy run scenes/stress/lid.lua --set gy=0 --set v0=0.5       (no gravity, leaving at 0.5 m/s)
--
-- Params: method (wcsph, dfsph, flip, pic, apic), spacing (m), thick (m, the
-- block's thickness), gx gy (m/s^2, gravity), v0 (m/s, start speed away from
-- the lid), shelf (true: a collider box's underside instead of the lid),
-- duration (s). Before the walls were made unable to pull (README, Stress
-- cases), DFSPH's lid held the block to 0.75 of free fall over 0.1 s and
-- FLIP's to 0.79; in zero gravity a block leaving the lid kept 0.58 (DFSPH)
-- and 0.67 (FLIP) of its speed.

local eddy = require "eddy"

local sp = eddy.param("spacing", 0.01)          -- m
local fluid = eddy.fluid { method = eddy.param("method", "dfsph"), resolution = sp }
local L, H, W = 0.2, 0.3, 0.1                   -- m, tank
local gx, gy = eddy.param("gx", 0), eddy.param("gy", -9.81)
local v0 = eddy.param("v0", 0)
local shelf = eddy.param("shelf", "false") == "true"
local top = shelf and 0.2 or H                  -- m, the wall the block touches
local world = fluid:world { bounds = { {0, 0, 0}, {L, H, W} }, gravity = {gx, gy, 0}, fps = 100,
                            duration = eddy.param("duration", 0.2) }
-- away from the side walls (they would add their own drag: not this case)
world:add(eddy.emit_box { min = {0.05, top - eddy.param("thick", 0.03), 0.03}, max = {0.15, top, 0.07},
                          spacing = fluid.spacing, velocity = {0, -v0, 0} })
world:add(fluid)
if shelf then world:add(eddy.collide_box { min = {0, top, 0}, max = {L, top + 0.04, W}, inside = false }) end

local g = math.sqrt(gx * gx + gy * gy)
local ymax0
world:on_frame(function(w)
	local y, vx, vy = w:channel("y"), w:channel("vx"), w:channel("vy")
	local n, along, ymax = #y, 0, 0
	for i = 1, n do
		along = along + (g > 0 and (vx[i] * gx + vy[i] * gy) / g or -vy[i])
		if y[i] > ymax then ymax = y[i] end
	end
	local t = w:time()
	ymax0 = ymax0 or top - sp / 2
	local uy = g > 0 and -gy / g or 1              -- the start speed's part along g
	local fall = (g > 0 and 0.5 * g * t * t * uy or 0) + v0 * t
	return { fall_ratio = along / n / (g * t + v0 * uy), top_gap = fall > 0 and (ymax0 - ymax) / fall or 0 }
end)

return world
