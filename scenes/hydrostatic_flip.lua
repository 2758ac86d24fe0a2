-- SPDX-License-Identifier: MIT
-- hydrostatic_flip: a tank of water at rest, FLIP. The pressure solve alone
-- holds the column up, so the hydrostatic error measures the solver: CHOLMOD
-- is exact, PCG stops at its tolerance. The water depth is a whole number of
-- cells, so the free surface sits on a cell boundary and the ghost-fluid
-- pressure is exact there.
--
-- Reports pressure_err = max |p - rho g (H - y)| / (rho g H) over the fluid
-- cells below the surface cell and off the walls (cell-centred pressure).
--
--   build/eddy run scenes/hydrostatic_flip.lua --set solver=cholmod --stats out/hf.jsonl
--   build/eddy run scenes/hydrostatic_flip.lua --set solver=pcg --set tolerance=1e-3

local eddy = require "eddy"

local dx = eddy.param("cell_size", 0.01)        -- m
local cells = eddy.param("depth_cells", 16)     -- water depth in cells
local solver = eddy.param("solver", "pcg")      -- "pcg" or "cholmod"
local tolerance = eddy.param("tolerance", 1e-6) -- PCG relative residual
local rho, g = 1000, 9.81
local H, W = cells * dx, cells * dx
local nx, ny, nz = cells, 2 * cells, cells

local world = eddy.world {
	bounds = { {0, 0, 0}, {W, 2 * H, W} },
	gravity = {0, -g, 0}, fps = 30, duration = 1.0, cfl = 1.0, cell_size = dx,
}
world:add(eddy.emit_box { min = {0, 0, 0}, max = {W, H, W}, spacing = dx / 2 })
world:add(eddy.gravity {})
world:add(eddy.flip_p2g {})
world:add(eddy.flip_boundary {})
world:add(eddy.flip_surface {})
world:add(eddy.flip_pressure { solver = solver, tolerance = tolerance, density = rho })
world:add(eddy.flip_extrapolate {})
world:add(eddy.flip_g2p { flip_ratio = 0.95 })
world:add(eddy.flip_advect {})

world:on_frame(function(w)
	local p = w:channel("cell_pressure")
	local err = 0
	for k = 1, nz - 2 do
		for j = 0, cells - 2 do
			for i = 1, nx - 2 do
				local y = (j + 0.5) * dx
				local e = math.abs(p[1 + i + nx * (j + ny * k)] - rho * g * (H - y)) / (rho * g * H)
				if e > err then err = e end
			end
		end
	end
	return { pressure_err = err }
end)

require("eddy.view").render(eddy, world, "hydrostatic_flip")

return world
