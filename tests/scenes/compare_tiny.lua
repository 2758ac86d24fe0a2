-- SPDX-License-Identifier: MIT
-- compare_tiny: a small block of water falling into a small tank, for the
-- test of `eddy compare` (tests/test_compare.c). The method is a parameter:
-- "wcsph" (weakly compressible SPH, as scenes/hydrostatic.lua) or "flip" (the
-- FLIP systems in the order lua/eddy/fluid.lua uses); "broken" fails on
-- purpose, as a scene error for one method. Frames are 160 x 120.
--
--   build/eddy compare tests/scenes/compare_tiny.lua --methods wcsph,flip,broken --quick

local eddy = require "eddy"

local method = eddy.param("method", "wcsph")
local dx = eddy.param("spacing", 0.01) -- m, particle spacing (FLIP cells are 2 spacings)
local W = 0.1                             -- m, tank width (x and z)

if method == "broken" then
	error("compare_tiny: method 'broken' fails on purpose (the test of a failing method)")
end
if method ~= "wcsph" and method ~= "flip" then
	error("compare_tiny: unknown method '" .. method .. "' (this scene has wcsph and flip)")
end

local world = eddy.world {
	bounds = { {0, 0, 0}, {W, W, W} }, gravity = {0, -9.81, 0}, fps = 30, duration = 0.4,
	cfl = method == "flip" and 1.0 or 0.4, dt_max = 0.01, cell_size = method == "flip" and 2 * dx or 0,
}
world:add(eddy.emit_box { min = {0, 0, 0}, max = {0.5 * W, 0.6 * W, W}, spacing = dx })
if method == "wcsph" then
	world:add(eddy.sph_density { radius = 2 * dx, spacing = dx, rest_density = 1000, stiffness = 200 })
	world:add(eddy.sph_pressure {})
	world:add(eddy.sph_viscosity { viscosity = 1e-3, artificial = 0.05 })
	world:add(eddy.gravity {})
	world:add(eddy.integrate {})
	world:add(eddy.collide_box { min = {0, 0, 0}, max = {W, W, W}, inside = true })
else
	world:add(eddy.gravity {})
	world:add(eddy.flip_p2g {})
	world:add(eddy.flip_boundary {})
	world:add(eddy.flip_surface {})
	world:add(eddy.flip_pressure { solver = "pcg" })
	world:add(eddy.flip_extrapolate {})
	world:add(eddy.flip_g2p { flip_ratio = 0.95 })
	world:add(eddy.flip_advect {})
end

-- a field of the scene's own, so compare has a non-contract measurement
world:on_frame(function(w)
	local y, top = w:channel("y"), 0
	for i = 1, #y do top = math.max(top, y[i]) end
	return { top = top }
end)

world:add(eddy.render_points {
	width = 160, height = 120, radius = 0.5 * dx, color_by = "speed", value_min = 0, value_max = 1,
	path = eddy.out_dir("out/compare_tiny") .. "/frame_%04d.png",
})

return world
