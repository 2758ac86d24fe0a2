-- SPDX-License-Identifier: MIT
-- Dam break, SPH against FLIP: how close the surge front comes to Martin &
-- Moyce's measurements (a = 2.25 in) for the wall time each resolution costs.
-- error = mean |Z_sim - Z_exp| over T in [1, 3] (Z = front / a, T = t sqrt(2g/a)),
-- no time shift; the CSV also has error_shifted, the best error after shifting
-- the experiment's clock by up to 0.2 in T (docs/validation.md: the gate opened in
-- finite time), and that shift.
--
--   build/eddy study scenes/studies/dam_break.lua            (about 40 s)
--   build/eddy study scenes/studies/dam_break.lua --quick    (a few seconds)
--
-- Resolutions are fractions of the column base a = 0.1 m: SPH spacing a/10,
-- a/15, a/20; FLIP cells a/8, a/12, a/16 with 2 x 2 x 2 particles per cell
-- (particle spacing a/16, a/24, a/32: the scene's `spacing` is the particle
-- spacing of every method); PIC is the same scene with method = pic.

return study {
	name = "dam_break",
	title = "Dam break vs Martin & Moyce: SPH and FLIP",
	reference = { data = "data/martin_moyce_1952_a2.25in.csv" },
	metric = { kind = "mean_abs", x = "T", y = "Z", from = 1, to = 3, shift = 0.2,
	           label = "mean |Z - Z_exp|, T in [1, 3]" },
	extra = { density_err_avg = "mean", divergence = "max" },
	methods = {
		method { name = "SPH", scene = "scenes/dam_break.lua", resolution = "spacing",
		         sweep = { spacing = { 0.01, 0.1 / 15, 0.005 } },
		         quick = { spacing = { 0.02, 0.01 } } },
		method { name = "FLIP", scene = "scenes/dam_break.lua", resolution = "spacing", set = { method = "flip" },
		         sweep = { spacing = { 0.00625, 0.1 / 24, 0.003125 } },
		         quick = { spacing = { 0.0125, 0.00625 } } },
		-- PIC: the dissipative end of the FLIP/PIC blend
		method { name = "PIC", scene = "scenes/dam_break.lua", resolution = "spacing",
		         set = { method = "pic" }, sweep = { spacing = { 0.00625, 0.1 / 24, 0.003125 } }, quick = false },
	},
}
