-- SPDX-License-Identifier: MIT
-- eddy.fluid{...}: a node group that expands into one method's systems, in
-- the order that method needs, with defaults derived from one resolution.
-- It is plain Lua over the systems of the module: anything it does a scene
-- can do by hand, and `eddy plan` shows what it expanded into.
--
--   local fluid = eddy.fluid { method = eddy.param("method", "dfsph"), resolution = 0.01 }
--   local world = fluid:world { bounds = { {0, 0, 0}, {1, 0.5, 0.2} }, fps = 30, duration = 2 }
--   world:add(eddy.emit_box { min = {0, 0, 0}, max = {0.3, 0.3, 0.2}, spacing = fluid.spacing })
--   world:add(fluid)           -- the method's systems, the tank's walls
--   world:add(eddy.collide_sphere { ... })   -- colliders after the group
--
-- Methods and what they expand into (h = resolution, the particle spacing):
--   wcsph  sph_density (radius 2h) sph_pressure sph_viscosity [sph_surface_tension]
--          gravity sph_boundary_box integrate collide_box
--   dfsph  sph_density gravity sph_viscosity [sph_surface_tension] sph_dfsph
--          sph_boundary_box integrate collide_box
--   flip, pic, apic
--          gravity flip_p2g flip_boundary flip_surface flip_pressure
--          flip_extrapolate flip_g2p flip_advect [flip_reseed if reseed = true],
--          on a MAC grid of
--          cells 2h wide (8 particles per cell); pic is flip_ratio 0, apic the
--          affine transfer; the tank is the world's box unless `tank` says
--          otherwise (then a collide_box keeps the fluid in it)
-- The world's CFL number, grid and (wcsph) settle_steps come from the group
-- through fluid:world{}.
-- tank = {min = {x, y, z}, max = {x, y, z}}, or the two corners as bounds
-- takes them (default: the world's box, when made by fluid:world{})
-- gives SPH its boundary particles and collider; tank = false gives none.
-- FLIP's grid sides are walls with the default tank only: with tank = false
-- or a tank of its own, water reaching a side leaves the world (outflow).
-- A field that does not apply to the chosen method is an error naming it:
-- a FLIP run ignoring 'stiffness' would silently be another experiment.
-- Settings for one method only go in a table named after it, so one scene
-- carries each method's tuning and runs with any of them:
--   eddy.fluid { method = m, resolution = h,
--                wcsph = { stiffness = 400 }, dfsph = { tolerance = 1e-3 },
--                flip = { solver = "pcg", flip_ratio = 0.95 } }
-- Each such table is checked against its own method whichever is chosen,
-- and the chosen method's table overrides the fields beside it.

local M = {}

local METHODS = { "wcsph", "dfsph", "flip", "pic", "apic" }
local SPH = { wcsph = true, dfsph = true }
local METHOD_TABLE = { wcsph = true, dfsph = true, flip = true, pic = true, apic = true }

-- field -> the methods it applies to (nil: all)
local FIELDS = {
	method = false, resolution = false, rest_density = false, tank = false,
	wcsph = false, dfsph = false, flip = false, pic = false, apic = false,
	viscosity = { "wcsph", "dfsph" },       -- Pa s, dynamic
	artificial = { "wcsph", "dfsph" },      -- 1, Monaghan's alpha
	surface_tension = { "wcsph", "dfsph" }, -- N/m
	stiffness = { "wcsph" },                -- m^2/s^2, c^2; unset or 0: from the scene (10 x its fall speed)
	density = { "wcsph" },                  -- sph_density's "summation" (default) or "continuity"
	diffusion = { "wcsph" },                -- 1, delta-SPH's delta with density = "continuity"
	verlet_list = { "wcsph", "dfsph" },     -- false: a search every step, less memory, more time
	tolerance = { "dfsph", "flip", "pic", "apic" },
	divergence = { "dfsph" },
	shift = { "dfsph" },                    -- 1, sph_dfsph's particle shifting
	solver = { "flip", "pic", "apic" },
	flip_ratio = { "flip" },
	reseed = { "flip", "pic", "apic" },
	cell_size = { "flip", "pic", "apic" },
}

-- the world's CFL number per method: the explicit acoustic limit binds
-- WCSPH; the grid methods take about one cell a step. DFSPH's is that at
-- which still water is at rest (scenes/stress/still_water.lua, 10-200
-- layers, is tested at 0.3-0.55): at 1.0 its gravity limit, 0.18 sqrt(h/g)
-- (sph_dfsph), let 10, 20 and 40 layers burst at 0.39, 0.31 and 1.25 m/s
local CFL = { wcsph = 0.4, dfsph = 0.5, flip = 1.0, pic = 1.0, apic = 1.0 }

-- WCSPH's settling before the first step (the world's settle_steps, at most
-- this many): water emitted squeezed against an off-lattice solid relaxes
-- instead of starting with the equation of state's kick (tests/scenes/
-- obstacle_pool.lua: 81 steps for the turned box, none for a plain tank)
local SETTLE_STEPS = 500

-- level: 4 from new() and expand() themselves (the scene's line, past the C
-- function that called them), 5 from a helper they call
local function fail(msg, level) error("eddy.fluid: " .. msg, level or 4) end

local function sorted_keys(t)
	local k = {}
	for name in pairs(t) do k[#k + 1] = name end
	table.sort(k, function(a, b) return tostring(a) < tostring(b) end) -- a stray list entry is a number
	return k
end

local function applies(field, method)
	local where = FIELDS[field]
	if not where then return true end
	for _, m in ipairs(where) do if m == method then return true end end
	return false
end

local function fields_of(method)
	local list = {}
	for _, name in ipairs(sorted_keys(FIELDS)) do
		if applies(name, method) and not METHOD_TABLE[name] then list[#list + 1] = name end
	end
	return table.concat(list, ", ")
end

local Group = {}
Group.__index = Group

function M.new(def)
	if type(def) ~= "table" then fail("expects a table of fields, e.g. eddy.fluid { method = \"flip\", resolution = 0.01 }") end
	local method = def.method
	local known = false
	for _, m in ipairs(METHODS) do known = known or m == method end
	if not known then
		fail(string.format("'method' must be one of %s (got %s)", table.concat(METHODS, ", "), tostring(method)))
	end
	local function check(t, m, where)
		for _, name in ipairs(sorted_keys(t)) do
			if FIELDS[name] == nil or (where and (name == "method" or name == "resolution" or METHOD_TABLE[name])) then
				fail(string.format("unknown field '%s'%s (fields for %s: %s)", tostring(name), where or "", m, fields_of(m)), 5)
			elseif not applies(name, m) then
				fail(string.format("'%s'%s does not apply to method '%s' (it applies to %s; fields for %s: %s)", name,
				                   where or "", m, table.concat(FIELDS[name], ", "), m, fields_of(m)), 5)
			end
		end
	end
	check(def, method)
	local merged = {}
	for k, v in pairs(def) do if not METHOD_TABLE[k] then merged[k] = v end end
	for _, m in ipairs(METHODS) do
		if def[m] ~= nil then
			if type(def[m]) ~= "table" then fail(string.format("'%s' must be a table of %s's settings", m, m)) end
			check(def[m], m, " in " .. m .. " = {...}")
		end
	end
	for k, v in pairs(def[method] or {}) do merged[k] = v end
	def = merged
	local h = def.resolution
	if type(h) ~= "number" or not (h > 0) then
		fail(string.format("'resolution' (m, the particle spacing) must be a number > 0 (got %s)", tostring(h)))
	end
	-- tank: {min = {x, y, z}, max = {x, y, z}}, or two corners as the
	-- world's bounds take them; a table of any other shape would otherwise
	-- reach collide_box without min and max, a unit box of its defaults
	local tank = def.tank
	if tank ~= nil and tank ~= false then
		local function corner(c)
			return type(c) == "table" and #c == 3 and type(c[1]) == "number" and type(c[2]) == "number"
				and type(c[3]) == "number"
		end
		if type(tank) == "table" and tank.min == nil and tank.max == nil and #tank == 2 then
			tank = { min = tank[1], max = tank[2] }
		end
		local extra = false
		if type(tank) == "table" then
			for k in pairs(tank) do extra = extra or (k ~= "min" and k ~= "max") end
		end
		if type(tank) ~= "table" or extra or not corner(tank.min) or not corner(tank.max) then
			fail("'tank' must be {min = {x, y, z}, max = {x, y, z}} (m; or the two corners, as bounds takes them), "
			     .. "false for no walls, or left out for the world's box (got "
			     .. (type(tank) == "table" and "a table of another shape" or tostring(tank)) .. ")")
		end
		for a = 1, 3 do
			if not (tank.min[a] < tank.max[a]) then
				fail(string.format("'tank' must have min < max on every axis (axis %d: %g, %g)", a, tank.min[a],
				                   tank.max[a]))
			end
		end
		def.tank = tank
	end
	local g = setmetatable({ def = def, method = method, spacing = h, radius = 2 * h, cfl = CFL[method] }, Group)
	if not SPH[method] then g.cell_size = def.cell_size or 2 * h end
	return g
end

-- fluid:world{...}: eddy.world with the method's grid, CFL number and (WCSPH)
-- settling filled in where the def leaves them out; remembers the bounds for
-- the tank.
function Group:world(wdef)
	local d = {}
	for k, v in pairs(wdef or {}) do d[k] = v end
	if d.cfl == nil then d.cfl = self.cfl end
	if d.settle_steps == nil and self.method == "wcsph" then d.settle_steps = SETTLE_STEPS end
	if self.cell_size and d.cell_size == nil then d.cell_size = self.cell_size end
	self.bounds, self.cfl = d.bounds, d.cfl
	local eddy = require "eddy"
	local ok, world = pcall(eddy.world, d)
	if not ok then error((tostring(world):gsub("^[^:]*:%d+: ", "")), 2) end
	return world
end

function Group:label()
	return string.format("fluid{method = %s, resolution = %g m}", self.method, self.spacing)
end

-- world:add(group) calls this: adds the systems and returns their handles in
-- a table (by name; sph_density's handle has :mass()).
function Group:expand(world)
	local eddy = require "eddy"
	local d, h, m = self.def, self.spacing, self.method
	-- tank = false: no walls of the group's own (a drop in free space)
	local tank = d.tank
	if tank == nil and self.bounds then tank = { min = self.bounds[1], max = self.bounds[2] } end
	local handles = {}
	local function add(name, sdef)
		local ok, sys = pcall(function() return world:add(eddy[name](sdef)) end)
		if not ok then fail((tostring(sys):gsub("^[^:]*:%d+: ", "")), 5) end
		sys:set_group(self:label())
		handles[name] = sys
		handles[#handles + 1] = sys
	end
	local function opt(t) -- drop nil fields so the system's defaults apply
		local r = {}
		for k, v in pairs(t) do r[k] = v end
		return r
	end
	if SPH[m] then
		if tank == nil then
			fail("an SPH method needs the tank's walls: create the world with fluid:world{...}, give tank = {min = ..., "
			     .. "max = ...}, or tank = false for none")
		end
		add("sph_density", { radius = 2 * h, spacing = h, rest_density = d.rest_density or 1000,
		                     stiffness = d.stiffness, density = d.density, diffusion = d.diffusion,
		                     verlet_list = d.verlet_list })
		local visc = opt { viscosity = d.viscosity or 1e-3, artificial = d.artificial or 0.05 }
		if m == "wcsph" then
			add("sph_pressure", {})
			add("sph_viscosity", visc)
			if d.surface_tension then add("sph_surface_tension", { tension = d.surface_tension }) end
			add("gravity", {})
		else
			-- the pressure solve after every other force, before integrate
			add("gravity", {})
			add("sph_viscosity", visc)
			if d.surface_tension then add("sph_surface_tension", { tension = d.surface_tension }) end
			add("sph_dfsph", opt { max_density_error = d.tolerance, divergence_solver = d.divergence,
			                       shift = d.shift })
		end
		if tank then add("sph_boundary_box", { min = tank.min, max = tank.max, spacing = h }) end
		add("integrate", {})
		if tank then add("collide_box", { min = tank.min, max = tank.max, inside = true }) end
	else
		add("gravity", {})
		add("flip_p2g", {})
		-- the domain's sides are the tank's walls only for the default tank
		-- (the world's box, as SPH's): with tank = false, or a tank of its
		-- own, water reaching a side leaves the world there
		add("flip_boundary", { open_sides = d.tank ~= nil })
		add("flip_surface", {})
		add("flip_pressure", opt { solver = d.solver, tolerance = d.tolerance, density = d.rest_density })
		-- RK2 at CFL C samples up to C + 1 cells beyond the surface
		add("flip_extrapolate", { layers = math.max(2, math.ceil((self.cfl or 1) + 2)) })
		local g2p = { flip_ratio = m == "pic" and 0 or d.flip_ratio }
		if m == "apic" then g2p = { transfer = "apic" } end
		add("flip_g2p", opt(g2p))
		add("flip_advect", {})
		-- reseeding only on request: it moves particles from packed cells
		-- into holes inside the liquid and keeps their count, so the volume
		-- is kept either way (the FLIP pour ends within 0.1% of its
		-- particles' volume with it and without)
		if d.reseed then add("flip_reseed", {}) end
		if d.tank then add("collide_box", { min = d.tank.min, max = d.tank.max, inside = true }) end
	end
	return handles
end

return M
