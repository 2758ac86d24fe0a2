-- SPDX-License-Identifier: MIT
-- Sloshing: mode-1 standing wave in a 0.4 m tank, 0.1 m deep, from a tilted
-- surface 10 mm high at the walls (scenes/stress/slosh.lua). error = |omega /
-- omega_theory - 1| from the zero crossings of the wall's mode-1 elevation
-- eta, omega_theory^2 = g k tanh(k d), k = pi / L (7.108 rad/s, T = 0.884 s);
-- the signed period error is omega_ref / omega - 1 from the CSV's omega
-- columns. zeta is the damping ratio: the mean over the run's half cycles of
-- the log decrement of eta's peaks, delta / sqrt(pi^2 + delta^2), which for
-- an inviscid method is its numerical dissipation (water's viscosity alone
-- gives ~1e-4). Methods: WCSPH (k = 100 g d), DFSPH, FLIP 0.95, PIC and APIC;
-- FLIP's cell is two particle spacings. 3 s = 3.4 periods, 6 peaks.
--
--   build/eddy study scenes/studies/sloshing.lua            (about 10 minutes; WCSPH is 8 of them)
--   build/eddy study scenes/studies/sloshing.lua --quick    (under a minute, without WCSPH)

local pi, g, L, d = math.pi, 9.81, 0.4, 0.1
local k = pi / L

local fine = { 0.005, 0.004, 0.003125, 0.0025 }
local coarse = { 0.005, 0.003125 }

return study {
	name = "sloshing",
	title = "Mode-1 sloshing: period error vs wall time (damping ratio in the CSV's zeta)",
	reference = { analytic = function(params) return math.sqrt(g * k * math.tanh(k * d)) end },
	metric = { kind = "frequency", field = "eta", label = "|omega / omega_theory - 1|" },
	extra = { zeta = "mean" },
	duration = 3.0, quick_duration = 2.0,
	methods = {
		method { name = "WCSPH", scene = "scenes/stress/slosh.lua", resolution = "spacing",
		         sweep = { method = { "wcsph" }, spacing = { 0.005, 0.004 } },
		         quick = false }, -- 3.5 minutes at 5 mm: 8000 acoustic steps
		method { name = "DFSPH", scene = "scenes/stress/slosh.lua", resolution = "spacing",
		         sweep = { method = { "dfsph" }, spacing = { 0.005, 0.004 } },
		         quick = { method = { "dfsph" }, spacing = { 0.005 } } },
		method { name = "FLIP 0.95", scene = "scenes/stress/slosh.lua", resolution = "spacing",
		         sweep = { method = { "flip" }, spacing = fine }, quick = { method = { "flip" }, spacing = coarse } },
		method { name = "PIC", scene = "scenes/stress/slosh.lua", resolution = "spacing",
		         sweep = { method = { "pic" }, spacing = fine }, quick = { method = { "pic" }, spacing = coarse } },
		method { name = "APIC", scene = "scenes/stress/slosh.lua", resolution = "spacing",
		         sweep = { method = { "apic" }, spacing = fine }, quick = { method = { "apic" }, spacing = coarse } },
	},
}
