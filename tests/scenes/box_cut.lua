-- SPDX-License-Identifier: MIT
-- box_cut: water in a tank whose sides are not a whole number of FLIP cells
-- apart. The grid rounds the world's box up to whole cells; the walls must
-- stay where the scene put them (the box's faces, as SPH's are), not at
-- the grid's sides past them. tests/test_flip.c (box_cut) reads the mean
-- height and the largest speed every frame.
--
--   build/eddy run tests/scenes/box_cut.lua --set method=flip --stats - --quiet
--
-- Params: method (flip, pic, apic, wcsph, dfsph), spacing (m), cell (m, the
-- grid methods' cell, 2 spacings by default), L and W (m, the tank's length in x and thickness in z), column
-- (m, the width in x of the water at the start: L for a still pool, less for
-- a column that collapses), depth (m, of the water at the start), duration.

local eddy = require "eddy"

local s = eddy.param("spacing", 0.01)
local L, W = eddy.param("L", 0.41), eddy.param("W", 0.07)
local D = eddy.param("depth", 0.1)
local cell = eddy.param("cell", 2 * s)
local grid = { cell_size = cell }
local fluid = eddy.fluid { method = eddy.param("method", "flip"), resolution = s, flip = grid, pic = grid, apic = grid }
local world = fluid:world {
	bounds = { {0, 0, 0}, {L, 3 * D, W} }, gravity = {0, -9.81, 0},
	fps = 20, duration = eddy.param("duration", 1),
}
-- a quarter spacing past the last lattice cell: the count per axis is
-- floor((max - min) / spacing), which rounding must not cut short
local column = eddy.param("column", L)
local function edge(x, top) return x < top and math.min(x + s / 4, top) or top end
world:add(eddy.emit_box { min = {0, 0, 0}, max = {edge(column, L), edge(D, 3 * D), edge(W, W)}, spacing = s })
world:add(fluid)
world:on_frame(function(w)
	local y = w:channel("y")
	local sum = 0
	for i = 1, #y do sum = sum + y[i] end
	return { ybar = sum / #y }
end)
return world
