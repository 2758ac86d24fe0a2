-- SPDX-License-Identifier: MIT
-- Writes the test and scene meshes of scenes/meshes/ (closed, outward-wound
-- triangle meshes):
--   cube.obj, cube.stl  the unit cube [0, 1]^3 (12 triangles; the STL stores
--                       each triangle's corners separately, as STL does)
--   icosphere.obj       the unit sphere: an icosahedron subdivided 3 times
--                       (642 vertices, 1280 triangles, every vertex on the sphere)
--   cylinder.obj        radius 1, y from 0 to 1, axis x = z = 0, 64 sides
--   cup.obj             a cup as a closed solid of revolution (64 sides):
--                       outer radius 0.05 m, cavity radius 0.04 m, height
--                       0.1 m, floor 0.01 m thick, standing on y = 0, axis x = z = 0
--
--   lua5.4 scripts/gen_meshes.lua [folder [cup_sides]]   (default scenes/meshes, 64)
--
-- The cup has 8 triangles per side: cup_sides = 12500 gives the
-- 100,000-triangle cup the README's distance-field cost is measured on.

local dir = arg[1] or "scenes/meshes"

local function write_obj(path, comment, v, f)
	local out = assert(io.open(path, "w"))
	out:write("# ", comment, "\n# written by scripts/gen_meshes.lua\n")
	for _, p in ipairs(v) do out:write(string.format("v %.17g %.17g %.17g\n", p[1], p[2], p[3])) end
	for _, t in ipairs(f) do out:write(string.format("f %d %d %d\n", t[1], t[2], t[3])) end
	out:close()
end

local function write_stl(path, name, v, f)
	local out = assert(io.open(path, "w"))
	out:write("solid ", name, "\n")
	for _, t in ipairs(f) do
		local a, b, c = v[t[1]], v[t[2]], v[t[3]]
		local u = { b[1] - a[1], b[2] - a[2], b[3] - a[3] }
		local w = { c[1] - a[1], c[2] - a[2], c[3] - a[3] }
		local n = { u[2] * w[3] - u[3] * w[2], u[3] * w[1] - u[1] * w[3], u[1] * w[2] - u[2] * w[1] }
		local l = math.sqrt(n[1] ^ 2 + n[2] ^ 2 + n[3] ^ 2)
		out:write(string.format("facet normal %g %g %g\n outer loop\n", n[1] / l, n[2] / l, n[3] / l))
		for _, p in ipairs({ a, b, c }) do out:write(string.format("  vertex %.17g %.17g %.17g\n", p[1], p[2], p[3])) end
		out:write(" endloop\nendfacet\n")
	end
	out:write("endsolid ", name, "\n")
	out:close()
end

-- cube: corners by bits (x = 1, y = 2, z = 4); each face as two triangles, outward
local cube_v = {}
for i = 0, 7 do cube_v[#cube_v + 1] = { i & 1, (i >> 1) & 1, (i >> 2) & 1 } end
local quads = { { 0, 4, 6, 2 }, { 1, 3, 7, 5 }, { 0, 1, 5, 4 }, { 2, 6, 7, 3 }, { 0, 2, 3, 1 }, { 4, 5, 7, 6 } }
local cube_f = {}
for _, q in ipairs(quads) do
	cube_f[#cube_f + 1] = { q[1] + 1, q[2] + 1, q[3] + 1 }
	cube_f[#cube_f + 1] = { q[1] + 1, q[3] + 1, q[4] + 1 }
end
write_obj(dir .. "/cube.obj", "the unit cube [0, 1]^3", cube_v, cube_f)
write_stl(dir .. "/cube.stl", "cube", cube_v, cube_f)

-- icosphere
local t = (1 + math.sqrt(5)) / 2
local iv = { { -1, t, 0 }, { 1, t, 0 }, { -1, -t, 0 }, { 1, -t, 0 }, { 0, -1, t }, { 0, 1, t }, { 0, -1, -t }, { 0, 1, -t },
	{ t, 0, -1 }, { t, 0, 1 }, { -t, 0, -1 }, { -t, 0, 1 } }
local function unit(p)
	local l = math.sqrt(p[1] ^ 2 + p[2] ^ 2 + p[3] ^ 2)
	return { p[1] / l, p[2] / l, p[3] / l }
end
for i, p in ipairs(iv) do iv[i] = unit(p) end
local ifc = { { 1, 12, 6 }, { 1, 6, 2 }, { 1, 2, 8 }, { 1, 8, 11 }, { 1, 11, 12 }, { 2, 6, 10 }, { 6, 12, 5 }, { 12, 11, 3 },
	{ 11, 8, 7 }, { 8, 2, 9 }, { 4, 10, 5 }, { 4, 5, 3 }, { 4, 3, 7 }, { 4, 7, 9 }, { 4, 9, 10 }, { 5, 10, 6 }, { 3, 5, 12 },
	{ 7, 3, 11 }, { 9, 7, 8 }, { 10, 9, 2 } }
for _ = 1, 3 do
	local mid, nf = {}, {}
	local function m(a, b)
		local key = a < b and (a .. ":" .. b) or (b .. ":" .. a)
		if not mid[key] then
			local p, q = iv[a], iv[b]
			iv[#iv + 1] = unit({ (p[1] + q[1]) / 2, (p[2] + q[2]) / 2, (p[3] + q[3]) / 2 })
			mid[key] = #iv
		end
		return mid[key]
	end
	for _, f in ipairs(ifc) do
		local a, b, c = m(f[1], f[2]), m(f[2], f[3]), m(f[3], f[1])
		nf[#nf + 1] = { f[1], a, c }
		nf[#nf + 1] = { f[2], b, a }
		nf[#nf + 1] = { f[3], c, b }
		nf[#nf + 1] = { a, b, c }
	end
	ifc = nf
end
write_obj(dir .. "/icosphere.obj", "the unit sphere, an icosahedron subdivided 3 times", iv, ifc)

-- solids of revolution: the closed profile {r, y} (counter-clockwise) revolved
-- about the y axis in n sides; profile points on the axis become single
-- vertices (the poles)
local function revolve(profile, N)
	local cv, cf, ring = {}, {}, {}
	for i, p in ipairs(profile) do
		if p[1] == 0 then
			cv[#cv + 1] = { 0, p[2], 0 }
			ring[i] = { pole = #cv }
		else
			ring[i] = { first = #cv + 1 }
			for k = 0, N - 1 do
				local a = 2 * math.pi * k / N
				cv[#cv + 1] = { p[1] * math.cos(a), p[2], -p[1] * math.sin(a) }
			end
		end
	end
	local function at(i, k)
		local g = ring[i]
		return g.pole or g.first + (k % N)
	end
	for i = 1, #profile - 1 do
		for k = 0, N - 1 do
			local a, b, c, d = at(i, k), at(i, k + 1), at(i + 1, k + 1), at(i + 1, k)
			-- the profile runs counter-clockwise in (r, y), the angle turns from
			-- +x towards -z: a, b, c, d then faces out of the solid
			if a ~= b then cf[#cf + 1] = { a, b, c } end
			if c ~= d then cf[#cf + 1] = { a, c, d } end
		end
	end
	return cv, cf
end

local N = 64
local cv, cf = revolve({ { 0, 0 }, { 1, 0 }, { 1, 1 }, { 0, 1 } }, N)
write_obj(dir .. "/cylinder.obj", "a cylinder: radius 1, y from 0 to 1, 64 sides", cv, cf)

local R, r, H, floor_t = 0.05, 0.04, 0.1, 0.01
local cup_sides = math.tointeger(tonumber(arg[2] or "64"))
assert(cup_sides and cup_sides >= 3, "gen_meshes.lua: cup_sides must be a whole number >= 3")
cv, cf = revolve({ { 0, 0 }, { R, 0 }, { R, H }, { r, H }, { r, floor_t }, { 0, floor_t } }, cup_sides)
write_obj(dir .. "/cup.obj", string.format("a cup: outer radius %g m, cavity radius %g m, height %g m, floor %g m, %d sides",
	R, r, H, floor_t, cup_sides), cv, cf)
