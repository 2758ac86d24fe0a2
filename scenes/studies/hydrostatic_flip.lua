-- SPDX-License-Identifier: MIT
-- Hydrostatic tank, FLIP: CHOLMOD (exact) against MIC(0)-PCG and the
-- multigrid-preconditioned CG (HYPRE PFMG, solver = "hypre") at several
-- tolerances. error = mean over frames of pressure_err, the largest
-- |p - rho g d| / (rho g H) of the interior cells (scenes/hydrostatic.lua with method = flip, cells of 1/32 of the depth);
-- the CSV also has the largest divergence |div u| dt after projection.
--
--   build/eddy study scenes/studies/hydrostatic_flip.lua     (about a minute)

return study {
	name = "hydrostatic_flip",
	title = "Hydrostatic tank, FLIP: pressure error vs solver and tolerance",
	reference = { analytic = "p = rho g (H - y), computed by the scene as pressure_err" },
	metric = { kind = "mean", field = "pressure_err", label = "mean max |p - rho g d| / (rho g H)" },
	extra = { divergence = "max", iterations = "mean" },
	duration = 0.5, quick_duration = 0.1,
	methods = {
		method { name = "FLIP CHOLMOD", scene = "scenes/hydrostatic.lua",
		         set = { method = "flip", spacing = 0.003125 }, sweep = { solver = { "cholmod" } } },
		method { name = "FLIP PCG", scene = "scenes/hydrostatic.lua", set = { method = "flip", spacing = 0.003125 },
		         sweep = { solver = { "pcg" }, tolerance = { 1e-1, 1e-2, 1e-3, 1e-4, 1e-6, 1e-8 } },
		         quick = { solver = { "pcg" }, tolerance = { 1e-1, 1e-4 } } },
		method { name = "FLIP HYPRE", scene = "scenes/hydrostatic.lua", set = { method = "flip", spacing = 0.003125 },
		         sweep = { solver = { "hypre" }, tolerance = { 1e-1, 1e-2, 1e-3, 1e-4, 1e-6, 1e-8 } },
		         quick = { solver = { "hypre" }, tolerance = { 1e-1, 1e-4 } } },
	},
}
