-- SPDX-License-Identifier: MIT
-- Oscillating drop (SPH, colour-field surface tension): the error of the l = 2
-- frequency against Rayleigh's omega^2 = 8 sigma / (rho R^3) as the particles
-- per diameter grow. The drop (scenes/droplet.lua) starts as an ellipsoid
-- stretched 1.2 times along x with the volume of the sphere of radius
-- R = 1 cm it rings about. omega is read from the zero crossings of the
-- quadrupole moment q over 1 s (about 4 periods).
--
--   build/eddy study scenes/studies/droplet.lua      (about 2 minutes)

local sigma, rho, R = 0.0728, 1000, 0.01

return study {
	name = "droplet",
	title = "Oscillating drop: l = 2 frequency vs Rayleigh",
	reference = { analytic = function() return math.sqrt(8 * sigma / (rho * R ^ 3)) end },
	metric = { kind = "frequency", field = "q", label = "|omega / omega_Rayleigh - 1|" },
	set = { radius = R, tension = sigma },
	duration = 1.0, quick_duration = 0.6,
	methods = {
		-- spacing R/4, R/6, R/8: 8, 12 and 16 particles per diameter
		method { name = "SPH", scene = "scenes/droplet.lua", resolution = "spacing",
		         sweep = { spacing = { R / 4, R / 6, R / 8 } },
		         quick = { spacing = { R / 4, R / 5 } } },
	},
}
