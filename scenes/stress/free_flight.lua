-- SPDX-License-Identifier: MIT
-- free_flight (FLIP stress case): a blob of water, a cube or a sphere of
-- size L, flies through an empty box with a uniform velocity, off the grid
-- axes by default, with no gravity (or with it: gravity=1). A uniform field
-- is divergence free and has no pressure, so FLIP must carry it exactly: the
-- momentum, the shape and the pressure solve's zero work show whether the
-- scheme is Galilean invariant off the axes (the issue "Stable and
-- conservative one step beyond the tested scenes", item 3).
-- Per frame: p_err (|P - P0| / |P0|, P the mean particle velocity, P0 the
-- first frame's; with gravity P0 + g t), shape (max over particles of the
-- displacement relative to the centre of mass, against the initial one, / L;
-- -1 if the count changed), pz_rel (P_z / P0_z - 1), acom (y acceleration
-- of the centre of mass from the last three frames, m/s^2; the CFL step
-- varies with gravity, which adds g/2 d(dt)/dt), n (particles).
--
--   build/eddy run scenes/stress/free_flight.lua --stats - --quiet
--   build/eddy run scenes/stress/free_flight.lua --set shape=ellipsoid --set vx=0.3 --set vy=-1 --set vz=0.7
--
-- Params: cell_size (m), L (m), shape ("block" or "ellipsoid"), vx vy vz
-- (m/s), spacing (m, default cell_size / 2), jitter (spacings), gravity (0 or
-- 1: scale of g), mark_radius (cells), sigma (flip_surface's), reseed (0/1),
-- cfl, dt_max (s), offset (cells: the blob's start off the grid lines), solver,
-- flip_ratio, duration (s).

local eddy = require "eddy"

local h = eddy.param("cell_size", 0.0125)       -- m
local L = eddy.param("L", 0.1)                  -- m, blob size
local shape = eddy.param("shape", "block")      -- "block" or "ellipsoid"
local V = { eddy.param("vx", 1.0), eddy.param("vy", 0.5), eddy.param("vz", 0.25) }
local sp = eddy.param("spacing", h / 2)
local gs = eddy.param("gravity", 0)
local g = 9.81 * gs
local T = eddy.param("duration", 0.5)
-- the box holds the flight with 2 L to spare on every side
local lo, hi = {}, {}
local start = {}
for a = 1, 3 do
	local travel = V[a] * T
	local s0 = 2 * L + math.max(0, -travel) + (a == 2 and 0.5 * g * T * T or 0)
	lo[a], start[a] = 0, s0
	hi[a] = s0 + L + math.max(0, travel) + 2 * L
end

local world = eddy.world {
	bounds = { lo, hi }, gravity = {0, -g, 0},
	fps = 50, duration = T, cfl = eddy.param("cfl", 1.0), dt_max = eddy.param("dt_max", 0.01),
	cell_size = h,
}
local offset = eddy.param("offset", 0.37) -- cells: the blob starts off the grid lines
local min, max = {}, {}
for a = 1, 3 do
	min[a] = start[a] + offset * h
	max[a] = min[a] + L
end
world:add(eddy.emit_box { min = min, max = max, spacing = sp, shape = shape,
                          jitter = eddy.param("jitter", 0), velocity = V })
world:add(eddy.gravity {})
world:add(eddy.flip_p2g { mark_radius = eddy.param("mark_radius", 0) })
world:add(eddy.flip_boundary {})
world:add(eddy.flip_surface { sigma = eddy.param("sigma", 1.0) })
world:add(eddy.flip_pressure { solver = eddy.param("solver", "pcg") })
world:add(eddy.flip_extrapolate {})
world:add(eddy.flip_g2p { flip_ratio = eddy.param("flip_ratio", 0.95) })
world:add(eddy.flip_advect {})
if tonumber(eddy.param("reseed", 1)) ~= 0 then world:add(eddy.flip_reseed {}) end

local P0, rel0, hist = nil, nil, {}
world:on_frame(function(w)
	local x, y, z = w:channel("x"), w:channel("y"), w:channel("z")
	local vx, vy, vz = w:channel("vx"), w:channel("vy"), w:channel("vz")
	local n = #x
	if n == 0 then return { n = 0 } end
	local c, P = {0, 0, 0}, {0, 0, 0}
	for i = 1, n do
		c[1], c[2], c[3] = c[1] + x[i], c[2] + y[i], c[3] + z[i]
		P[1], P[2], P[3] = P[1] + vx[i], P[2] + vy[i], P[3] + vz[i]
	end
	for a = 1, 3 do c[a], P[a] = c[a] / n, P[a] / n end -- per particle (equal masses)
	local t = w:time()
	if not P0 then
		P0 = { P[1], P[2] + g * t, P[3] }
		rel0 = {}
		for i = 1, n do rel0[i] = { x[i] - c[1], y[i] - c[2], z[i] - c[3] } end
	end
	local e = math.sqrt((P[1] - P0[1]) ^ 2 + (P[2] - (P0[2] - g * t)) ^ 2 + (P[3] - P0[3]) ^ 2)
	local p0 = math.sqrt(P0[1] ^ 2 + P0[2] ^ 2 + P0[3] ^ 2)
	local shape_err = -1
	if #rel0 == n then
		shape_err = 0
		for i = 1, n do
			local d = math.sqrt((x[i] - c[1] - rel0[i][1]) ^ 2 + (y[i] - c[2] - rel0[i][2]) ^ 2 +
			                    (z[i] - c[3] - rel0[i][3]) ^ 2) / L
			if d > shape_err then shape_err = d end
		end
	end
	hist[#hist + 1] = { t, c[2] }
	local acom = 0
	if #hist >= 3 then
		local a, b, d = hist[#hist - 2], hist[#hist - 1], hist[#hist]
		local dt = d[1] - b[1]
		acom = (d[2] - 2 * b[2] + a[2]) / (dt * dt)
	end
	return { n = n, p_err = e / p0, pz_rel = P[3] / P0[3] - 1, shape = shape_err, acom = acom }
end)

return world
