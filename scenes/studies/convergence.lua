-- SPDX-License-Identifier: MIT
-- Convergence: the dam-break front Z(T), T in [1, 3], against each method's
-- finest run (docs/validation.md's protocol: halve the spacing at fixed CFL and
-- read the observed order p = log2(E(dx) / E(dx/2)) from the CSV's `order`).
-- The experiment cannot serve here: both methods converge to a front that
-- leads Martin & Moyce's (see scenes/studies/dam_break.lua).
--
--   build/eddy study scenes/studies/convergence.lua     (about 2 minutes)
--
-- SPH spacing a/5 .. a/40 (reference a/40); FLIP cells a/4 .. a/32 (reference
-- a/32), particle spacing half a cell.

return study {
	name = "convergence",
	title = "Convergence of the dam-break front (vs each method's finest run)",
	reference = { finest = true },
	metric = { kind = "mean_abs", x = "T", y = "Z", from = 1, to = 3, label = "mean |Z - Z_finest|, T in [1, 3]" },
	methods = {
		method { name = "SPH", scene = "scenes/dam_break.lua", resolution = "spacing",
		         sweep = { spacing = { 0.02, 0.01, 0.005, 0.0025 } },
		         quick = { spacing = { 0.04, 0.02, 0.01 } } },
		method { name = "FLIP", scene = "scenes/dam_break.lua", resolution = "spacing", set = { method = "flip" },
		         sweep = { spacing = { 0.0125, 0.00625, 0.003125, 0.0015625 } },
		         quick = { spacing = { 0.025, 0.0125, 0.00625 } } },
	},
}
