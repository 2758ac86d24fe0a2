-- Oscillating drop (SPH, colour-field surface tension): the error of the l = 2
-- frequency against Rayleigh's omega^2 = 8 sigma / (rho R^3) as the particles
-- per diameter grow. The drop (scenes/droplet.lua) starts as a block 2.6 r x
-- 2r x 2r, r = 1 cm, and rings about the sphere of the same volume,
-- R = (10.4 * 3 / (4 pi))^(1/3) r. omega is read from the zero crossings of
-- the quadrupole moment q over 1 s (about 2.5 periods).
--
--   build/eddy study scenes/studies/droplet.lua      (about 2 minutes)

local sigma, rho, r = 0.0728, 1000, 0.01

return study {
	name = "droplet",
	title = "Oscillating drop: l = 2 frequency vs Rayleigh",
	reference = { analytic = function()
		local R = (10.4 * 3 / (4 * math.pi)) ^ (1 / 3) * r
		return math.sqrt(8 * sigma / (rho * R ^ 3))
	end },
	metric = { kind = "frequency", field = "q", label = "|omega / omega_Rayleigh - 1|" },
	set = { radius = r, tension = sigma },
	duration = 1.0, quick_duration = 0.6,
	methods = {
		-- spacing r/4, r/6, r/8: 8, 12 and 16 particles per diameter
		method { name = "SPH", scene = "scenes/droplet.lua", resolution = "spacing",
		         sweep = { spacing = { r / 4, r / 6, r / 8 } },
		         quick = { spacing = { r / 4, r / 5 } } },
	},
}
