-- SPDX-License-Identifier: MIT
-- Hydrostatic tank, SPH: what stiffness (speed of sound) costs. The density
-- error of weakly compressible SPH is about g H / k; a stiffer fluid needs a
-- smaller acoustic time step (dt ~ h / sqrt(k)). error = mean over frames of
-- density_err_avg (mean |rho - rho0| / rho0), after the first 0.1 s.
--
--   build/eddy study scenes/studies/hydrostatic_sph.lua      (about a minute)

return study {
	name = "hydrostatic_sph",
	title = "Hydrostatic tank, SPH: density error vs stiffness",
	reference = { analytic = "rho = rho0 (p = rho0 g d); the stats' density_err_avg is |rho - rho0| / rho0" },
	metric = { kind = "mean", field = "density_err_avg", from = 0.1, label = "mean density error |rho - rho0| / rho0" },
	extra = { pressure_err = "mean", density_err_max = "max" },
	duration = 0.5, quick_duration = 0.2,
	methods = {
		method { name = "SPH", scene = "scenes/hydrostatic.lua",
		         sweep = { stiffness = { 50, 100, 200, 400, 800, 1600 } },
		         quick = { stiffness = { 100, 400 } } },
	},
}
