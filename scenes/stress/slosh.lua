-- SPDX-License-Identifier: MIT
-- slosh (stress case): mode-1 sloshing in a closed tank L = 0.4 m long,
-- water d = 0.1 m deep, thin in z (4 particle spacings), started at rest from
-- a tilted surface eta = A cos(k x), k = pi / L. Linear theory (Lamb 1932,
-- art. 227): a standing wave of frequency omega^2 = g k tanh(k d), here
-- omega = 7.11 rad/s, T = 0.884 s; an inviscid method should keep the
-- amplitude, and the damping it shows is the method's numerical dissipation
-- (water's own, nu = 1e-6 m^2/s, damps this mode by zeta ~ 1e-4).
--
-- The surface elevation is measured from the particles at the top: the
-- surface height of each bin two spacings wide (one FLIP cell) is the
-- highest particle in it plus half a spacing, and eta is the mode-1
-- amplitude of that profile, a = (2 / L) sum_b y_b cos(k x_b) dx_b (the
-- still depth drops out: sum_b cos(k x_b) = 0 over the bins' centres). eta
-- is the fundamental's elevation at the left wall; eta_wall, the top of the
-- wall's own bin minus d, is reported too, but it steps by particle layers
-- and carries the higher modes. A measure from particle counts (volume)
-- would not do: FLIP's particles do not keep a uniform density. The first
-- frame's eta differs from A: the initial surface is a staircase of whole
-- particle layers.
-- Per frame: eta (m), and as they become known, omega (rad/s, from eta's zero
-- crossings, half a period apart, from the second crossing on over whole
-- periods), period_err = T / T_theory - 1, zeta (at
-- the frame after each peak: the damping ratio from the log decrement
-- delta = ln(|a_i-1| / |a_i|) of the last two peaks of |eta|, half a period
-- apart, zeta = delta / sqrt(pi^2 + delta^2); their mean over a run is the
-- fitted one) and damping_ratio (the same from the first and the latest
-- peak: the run's fit so far). The peak of each half cycle between two zero
-- crossings is refined by a parabola through its three samples; the first
-- half cycle (from the start) is not used, since it starts at its peak.
-- A crossing counts only once the half cycle has swung out to a third of
-- the one before (below).
--
--   build/eddy run scenes/stress/slosh.lua --set method=apic --stats - --quiet
--   build/eddy run scenes/stress/slosh.lua --set method=wcsph --set spacing=0.005
--
-- Params: method (wcsph, dfsph, flip, pic, apic), spacing (m, particle
-- spacing; FLIP's cell is 2 spacings, 8 particles per cell), amplitude (m),
-- flip_ratio (method flip), solver (FLIP's pcg or cholmod), cfl, fps,
-- duration (s), render.

local eddy = require "eddy"

local method = eddy.param("method", "flip")
local s = eddy.param("spacing", 0.00625)   -- m, particle spacing
local A = eddy.param("amplitude", 0.01)    -- m (kA = 0.079: the nonlinear
                                            -- frequency shift, Tadjbakhsh & Keller 1960, is +0.16%)
local L, d = 0.4, 0.1                       -- m, tank length and still depth
local g, rho0 = 9.81, 1000
local W = eddy.param("thickness", 4) * s      -- m, thickness (z), in spacings
local H = 2 * d                             -- m, tank height
local k = math.pi / L
local omega_ref = math.sqrt(g * k * math.tanh(k * d))

local grid = { solver = eddy.param("solver", "pcg"), rest_density = rho0, reseed = true }
local fluid = eddy.fluid {
	method = method, resolution = s, rest_density = rho0,
	-- WCSPH: k = 100 g d puts the hydrostatic compression at 1% (still_water)
	wcsph = { stiffness = eddy.param("stiffness", 100 * g * d) },
	flip = { solver = grid.solver, reseed = true, flip_ratio = eddy.param("flip_ratio", 0.95) },
	pic = grid, apic = grid,
}
local flip = fluid.cell_size ~= nil

local world = fluid:world {
	bounds = { {0, 0, 0}, {L, H, W} }, gravity = {0, -g, 0},
	fps = eddy.param("fps", 60), duration = eddy.param("duration", 4.0),
	cfl = eddy.param("cfl", flip and 1.0 or 0.4),
}

-- The tilted surface: columns one spacing wide, each of the whole number of
-- layers nearest d + A cos(k x) at its centre; runs of equal height share
-- one emitter.
local ncol = math.floor(L / s + 0.5)
local function layers(i) return math.floor((d + A * math.cos(k * (i + 0.5) * s)) / s + 0.5) end
local i0 = 0
for i = 1, ncol do
	if i == ncol or layers(i) ~= layers(i0) then
		-- max a quarter spacing past the last lattice cell: the count per axis
		-- is floor((max - min) / spacing), which rounding must not cut short
		world:add(eddy.emit_box { min = {i0 * s, 0, 0}, max = {math.min((i + 0.25) * s, L), (layers(i0) + 0.25) * s, W}, spacing = s })
		i0 = i
	end
end

world:add(fluid)

local nbin = math.floor(L / (2 * s) + 0.5) -- surface bins
local bw = L / nbin                          -- m, bin width

-- the history the frame reports need
local prev_t, prev_eta           -- last frame
local crossings = {}             -- s, zero crossings of eta
local seg = nil                  -- samples of the current half cycle: { {t, eta}, ... }
local peaks = {}                 -- |eta| at the peaks of complete half cycles
local half_sign                  -- sign of eta in the current half cycle
local half_max = 0               -- m, the largest |eta| in it so far
local last_max                   -- m, the same of the half cycle before it

-- the peak of a half cycle: its largest |eta| sample, refined by the
-- parabola through it and its neighbours (samples are one frame apart)
local function seg_peak(samples)
	local best = 1
	for i = 2, #samples do
		if math.abs(samples[i][2]) > math.abs(samples[best][2]) then best = i end
	end
	local e1 = math.abs(samples[best][2])
	if best > 1 and best < #samples then
		local e0, e2 = math.abs(samples[best - 1][2]), math.abs(samples[best + 1][2])
		local a = (e0 - 2 * e1 + e2) / 2
		if a < 0 then return e1 - (e2 - e0) ^ 2 / (16 * a) end
	end
	return e1
end

local function zeta_of(delta) return delta / math.sqrt(math.pi ^ 2 + delta ^ 2) end

world:on_frame(function(w)
	local x, y = w:channel("x"), w:channel("y")
	local top = {}
	for b = 1, nbin do top[b] = 0 end
	for i = 1, #x do
		local b = math.floor(x[i] / bw) + 1
		b = b < 1 and 1 or b > nbin and nbin or b
		if y[i] > top[b] then top[b] = y[i] end
	end
	local a = 0
	for b = 1, nbin do a = a + (top[b] + s / 2) * math.cos(k * (b - 0.5) * bw) end
	local eta = 2 * a * bw / L
	local t = w:time()
	local out = { eta = eta, eta_wall = top[1] + s / 2 - d, omega_ref = omega_ref }
	-- a zero crossing ends the current half cycle only from its own sign and
	-- once it has swung out to a third of the half cycle before it: a
	-- strongly damped or coarse wave (WCSPH at 10 mm) jitters about zero by
	-- a fraction of a layer, which would otherwise count as several crossings
	half_sign = half_sign or (eta >= 0 and 1 or -1)
	local swung = not last_max or half_max >= last_max / 3
	if prev_eta and swung and prev_eta * half_sign > 0 and eta * half_sign <= 0 and eta ~= prev_eta then
		last_max, half_max, half_sign = half_max, 0, -half_sign
		crossings[#crossings + 1] = prev_t + (t - prev_t) * prev_eta / (prev_eta - eta)
		if seg then -- a complete half cycle ended
			peaks[#peaks + 1] = seg_peak(seg)
			if #peaks >= 2 then
				out.zeta = zeta_of(math.log(peaks[#peaks - 1] / peaks[#peaks]))
				out.damping_ratio = zeta_of(math.log(peaks[1] / peaks[#peaks]) / (#peaks - 1))
			end
		end
		seg = {}
	end
	if seg then seg[#seg + 1] = { t, eta } end
	half_max = math.max(half_max, math.abs(eta))
	-- the period from the second crossing on once there are four: the
	-- first quarter cycle starts from a staircase surface at rest and
	-- carries the higher modes' start-up, which shifts the first crossing;
	-- over whole periods (an even number of half periods) once there are
	-- any, since eta rides on a small offset (the settled surface's own
	-- mode-1 part) that makes its half periods alternate short and long,
	-- by up to 10% in the SPH runs: an odd count read WCSPH's 10 mm wave
	-- in a tank 16 spacings thick at -1.6% where whole periods read -2.5%
	if #crossings >= 2 then
		local c0 = #crossings >= 4 and 2 or 1
		local c1 = #crossings
		if (c1 - c0) % 2 == 1 and c1 - c0 > 1 then c1 = c1 - 1 end
		out.omega = math.pi * (c1 - c0) / (crossings[c1] - crossings[c0])
		out.period_err = omega_ref / out.omega - 1
	end
	if #peaks >= 2 then
		out.damping_ratio = out.damping_ratio or zeta_of(math.log(peaks[1] / peaks[#peaks]) / (#peaks - 1))
		out.peaks = #peaks
	end
	prev_t, prev_eta = t, eta
	return out
end)

require("eddy.view").render(eddy, world, "slosh", { radius = 0.6 * s })

return world
