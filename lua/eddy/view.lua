-- SPDX-License-Identifier: MIT
-- How the shipped scenes render: one call adds eddy.render_points with the
-- scene's output directory (out/<scene>, or --out), unless the run says
-- --set render=false (benchmarks and studies time the physics alone).
--
--   local view = require "eddy.view"
--   view.render(eddy, world, "pour", { radius = 0.6 * h })
--
-- opts are render_points fields; they override the defaults here.

local M = {}

function M.render(eddy, world, name, opts)
	if not eddy.param("render", true) then return nil end
	local def = {
		width = 960, height = 540,
		color_by = "speed", colormap = "viridis",
		path = eddy.out_dir("out/" .. name) .. "/frame_%04d.png",
	}
	for k, v in pairs(opts or {}) do def[k] = v end
	return world:add(eddy.render_points(def))
end

return M
