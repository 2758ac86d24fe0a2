-- SPDX-License-Identifier: MIT
-- cut_lid: a block of water rising at U into the lid of a closed tank, no
-- gravity, spreading along the lid. The lid is the world's box, at H: with
-- cells of `cell` m it lies on a cell face (H a whole number of cells) or
-- cuts the grid's last row. The sheet along the lid must run at the same
-- speed either way: tests/test_box_cut.c (jet_along_a_cut_lid) reads the
-- stats' max_speed.
--
--   build/eddy run tests/scenes/cut_lid.lua --set method=flip --set H=0.194 --stats - --quiet
--
-- Params: method (flip, pic, apic), spacing (m), cell (m), H (m), U (m/s), duration (s).

local eddy = require "eddy"

local s = eddy.param("spacing", 0.005)
local grid = { cell_size = eddy.param("cell", 2 * s) }
local fluid = eddy.fluid { method = eddy.param("method", "flip"), resolution = s, flip = grid, pic = grid, apic = grid }
local L, W = 0.2, 0.04
local world = fluid:world {
	bounds = { {0, 0, 0}, {L, eddy.param("H", 0.2), W} }, gravity = {0, 0, 0},
	fps = 200, duration = eddy.param("duration", 0.15),
}
world:add(eddy.emit_box { min = {0.05, 0.05, 0}, max = {0.15, 0.1, W}, spacing = s,
                          velocity = {0, eddy.param("U", 2.0), 0} })
world:add(fluid)
return world
