-- SPDX-License-Identifier: MIT
-- The accuracy/time study driver behind `eddy study STUDY.lua [--out DIR] [--quick]`.
--
-- A study file is Lua. It calls two constructors, `study {}` and `method {}`,
-- and returns the study; mistakes (an unknown field, a wrong type) are errors
-- at the line of the constructor that holds them:
--
--   return study {
--     name = "dam_break",                       -- output files: <name>.csv, <name>.png
--     title = "Dam break against Martin & Moyce",
--     reference = { data = "data/martin_moyce_1952_a2.25in.csv" },
--              -- or { analytic = "what the scene's error field measures" }
--              -- or { analytic = function(params) return omega end } (metric "frequency")
--              -- or { finest = true }: each method's finest run is its reference
--     metric = { kind = "mean_abs", x = "T", y = "Z", from = 1, to = 3 },
--              -- kinds: "mean_abs" (y against the reference's y(x), x in [from, to]),
--              -- "mean" / "max" (of a stats field the scene computes, time >= from),
--              -- "frequency" (omega of a stats field from its zero crossings over
--              -- whole periods, relative error against reference.analytic(params))
--     extra = { density_err_avg = "mean", divergence = "max" },   -- more CSV columns
--     set = { a = 0.1 },                         -- --set for every run
--     duration = 0.2, quick_duration = 0.1,      -- s, optional (default: the scene's)
--     methods = {
--       method { name = "SPH", scene = "scenes/dam_break.lua", resolution = "spacing",
--                sweep = { spacing = {0.01, 0.005} }, quick = { spacing = {0.02, 0.01} } },
--     },
--   }
--
-- A method's `sweep` maps --set parameters (and "threads", which becomes
-- --threads) to lists of values; every combination is one run. `quick` is the
-- sweep for --quick (false leaves the method out of it). `resolution` names
-- the swept parameter that is a length (smaller is finer): it orders the
-- convergence columns. A method may override the study's metric, set and
-- duration.
--
-- Each run is a child process `eddy run SCENE --quiet --set render=false
-- --stats FILE ...` (see lua/study.c), so wall time and peak memory are the
-- run's own. The CSV has one row per run; the chart (gnuplot) plots error
-- against wall time, log-log, one series per method, Pareto front marked.

local M = {}

-- ---- study file constructors and their checks ------------------------------

-- Where a mistake is: "file:line: " of the field's own line when it can be
-- found after the constructor's line (Lua keeps no line per table field),
-- else of the constructor call. `return study {...}` is a tail call, which
-- leaves no caller frame: its line is then found by scanning the file.
local function locator(file, lines, line)
	return function(field)
		if not line then return file .. ": " end
		if field then
			local pat = "%f[%w_]" .. field:gsub("%W", "%%%0") .. "%s*="
			for i = line, math.min(#lines, line + 200) do
				if lines[i]:find(pat) then return file .. ":" .. i .. ": " end
			end
		end
		return file .. ":" .. line .. ": "
	end
end

-- The line of the call to the constructor that calls this (nil if unknown).
local function call_line(lines, name)
	local me = debug.getinfo(2, "t")
	if me and not me.istailcall then
		local info = debug.getinfo(3, "l")
		if info and info.currentline and info.currentline > 0 then return info.currentline end
	end
	for i, l in ipairs(lines) do
		local code = l:gsub("%-%-.*$", "")
		if code:find("%f[%w_]" .. name .. "%s*[{(]") then return i end
	end
	return nil
end

local function list_keys(schema)
	local keys = {}
	for k in pairs(schema) do keys[#keys + 1] = k end
	table.sort(keys)
	return table.concat(keys, ", ")
end

-- schema: field -> { type = "string"|"number"|"table"|"boolean"|"function"|"any", required = bool }
local function check_fields(what, t, schema, loc)
	if type(t) ~= "table" then
		error(loc() .. what .. ": expects a table (got " .. type(t) .. ")", 0)
	end
	for k, v in pairs(t) do
		local s = schema[k]
		if not s then
			error(loc(tostring(k)) .. what .. ": unknown field '" .. tostring(k) .. "' (fields: " .. list_keys(schema) .. ")", 0)
		end
		local ok = false
		for ty in s.type:gmatch("[^|]+") do
			if ty == "any" or type(v) == ty then ok = true end
		end
		if not ok then
			error(loc(k) .. what .. ": '" .. k .. "' must be a " .. s.type .. " (got " .. type(v) .. ")", 0)
		end
	end
	for k, s in pairs(schema) do
		if s.required and t[k] == nil then
			error(loc() .. what .. ": '" .. k .. "' is required", 0)
		end
	end
end

local METHOD = {
	name = { type = "string", required = true },
	scene = { type = "string", required = true },
	sweep = { type = "table" },
	quick = { type = "table|boolean" },
	resolution = { type = "string" },
	set = { type = "table" },
	metric = { type = "table|function" },
	duration = { type = "number" },
	quick_duration = { type = "number" },
}

local STUDY = {
	name = { type = "string", required = true },
	title = { type = "string" },
	reference = { type = "table", required = true },
	metric = { type = "table|function", required = true },
	extra = { type = "table" },
	set = { type = "table" },
	duration = { type = "number" },
	quick_duration = { type = "number" },
	methods = { type = "table", required = true },
	findings = { type = "string" },
}

local REFERENCE = {
	data = { type = "string" },
	analytic = { type = "string|function" },
	finest = { type = "boolean" },
	x = { type = "string" },
	y = { type = "string" },
}

local METRIC = {
	kind = { type = "string", required = true },
	x = { type = "string" },
	y = { type = "string" },
	field = { type = "string" },
	from = { type = "number" },
	to = { type = "number" },
	shift = { type = "number" },
	label = { type = "string" },
}

local KINDS = { mean_abs = true, mean = true, max = true, frequency = true }

local function check_sweep(what, sweep, loc)
	for k, values in pairs(sweep) do
		if type(k) ~= "string" then
			error(loc() .. what .. ": sweep keys are parameter names (got " .. type(k) .. ")", 0)
		end
		if type(values) ~= "table" or #values == 0 then
			error(loc(k) .. what .. ": sweep '" .. k .. "' must be a non-empty list of values", 0)
		end
		for _, v in ipairs(values) do
			if type(v) ~= "number" and type(v) ~= "string" and type(v) ~= "boolean" then
				error(loc(k) .. what .. ": sweep '" .. k .. "' holds a " .. type(v) .. "; values are numbers, strings or booleans", 0)
			end
		end
	end
end

local function check_metric(what, m, loc)
	if type(m) == "function" then return end
	check_fields(what .. " metric", m, METRIC, loc)
	if not KINDS[m.kind] then
		error(loc("kind") .. what .. ": metric kind '" .. m.kind .. "' is not one of mean_abs, mean, max, frequency", 0)
	end
	if m.kind == "mean_abs" and not (m.x and m.y) then
		error(loc("metric") .. what .. ": metric mean_abs needs x and y (stats fields)", 0)
	end
	if m.kind ~= "mean_abs" and not m.field then
		error(loc("metric") .. what .. ": metric " .. m.kind .. " needs 'field' (a stats field)", 0)
	end
end

-- The constructors a study file calls, bound to that file.
local function constructors(file)
	local lines = {}
	local f = io.open(file, "r")
	if f then
		for l in f:lines() do lines[#lines + 1] = l end
		f:close()
	end
	local function method(t)
		local loc = locator(file, lines, call_line(lines, "method"))
		check_fields("method", t, METHOD, loc)
		local what = "method '" .. t.name .. "'"
		if t.sweep then check_sweep(what, t.sweep, loc) end
		if type(t.quick) == "table" then check_sweep(what .. " quick", t.quick, loc) end
		if t.metric then check_metric(what, t.metric, loc) end
		if t.resolution and not ((t.sweep or {})[t.resolution]) then
			error(loc("resolution") .. what .. ": resolution '" .. t.resolution .. "' is not a swept parameter", 0)
		end
		return setmetatable(t, { __name = "eddy.study.method", scene_at = loc("scene") })
	end
	local function study(t)
		local loc = locator(file, lines, call_line(lines, "study"))
		check_fields("study", t, STUDY, loc)
		check_fields("study reference", t.reference, REFERENCE, loc)
		check_metric("study", t.metric, loc)
		if #t.methods == 0 then error(loc("methods") .. "study: 'methods' is empty", 0) end
		for i, m in ipairs(t.methods) do
			if getmetatable(m) == nil or getmetatable(m).__name ~= "eddy.study.method" then
				error(loc("methods") .. "study: methods[" .. i .. "] must be made with method { ... }", 0)
			end
		end
		if not t.name:match("^[%w_%-]+$") then
			error(loc("name") .. "study: 'name' must be letters, digits, '_' or '-' (it names files)", 0)
		end
		return setmetatable(t, { __name = "eddy.study" })
	end
	return study, method
end

-- ---- files and JSON ------------------------------------------------------------

local function exists(path)
	local f = io.open(path, "rb")
	if f then f:close() return true end
	return false
end

-- A path as given (from the repository root), else relative to the study
-- file's directory and its parents (so data/... resolves from
-- scenes/studies/ as well).
local function resolve(path, study_file)
	if path:sub(1, 1) == "/" or exists(path) then return path end
	local dir = study_file:match("^(.*)/[^/]*$") or "."
	for _ = 1, 4 do
		local p = dir .. "/" .. path
		if exists(p) then return p end
		dir = dir .. "/.."
	end
	return path
end

-- Minimal JSON reader for the stats lines: objects, strings, numbers, true,
-- false, null (as nil). Returns the value or nil, message.
local function json_decode(s)
	local pos = 1
	local value
	local function ws() pos = s:find("[^ \t\r\n]", pos) or #s + 1 end
	local function str()
		local out, i = {}, pos + 1
		while true do
			local c = s:sub(i, i)
			if c == "" then error("unterminated string") end
			if c == '"' then pos = i + 1 return table.concat(out) end
			if c == "\\" then
				local e = s:sub(i + 1, i + 1)
				local map = { n = "\n", t = "\t", r = "\r", b = "\b", f = "\f", ['"'] = '"', ["\\"] = "\\", ["/"] = "/" }
				if e == "u" then
					out[#out + 1] = utf8.char(tonumber(s:sub(i + 2, i + 5), 16))
					i = i + 6
				else
					out[#out + 1] = map[e] or e
					i = i + 2
				end
			else
				out[#out + 1] = c
				i = i + 1
			end
		end
	end
	function value()
		ws()
		local c = s:sub(pos, pos)
		if c == "{" then
			local t = {}
			pos = pos + 1
			ws()
			if s:sub(pos, pos) == "}" then pos = pos + 1 return t end
			while true do
				ws()
				if s:sub(pos, pos) ~= '"' then error("expected a key at " .. pos) end
				local k = str()
				ws()
				if s:sub(pos, pos) ~= ":" then error("expected ':' at " .. pos) end
				pos = pos + 1
				t[k] = value()
				ws()
				local d = s:sub(pos, pos)
				pos = pos + 1
				if d == "}" then return t end
				if d ~= "," then error("expected ',' or '}' at " .. (pos - 1)) end
			end
		elseif c == "[" then
			local t = {}
			pos = pos + 1
			ws()
			if s:sub(pos, pos) == "]" then pos = pos + 1 return t end
			while true do
				t[#t + 1] = value()
				ws()
				local d = s:sub(pos, pos)
				pos = pos + 1
				if d == "]" then return t end
				if d ~= "," then error("expected ',' or ']'") end
			end
		elseif c == '"' then
			return str()
		elseif s:sub(pos, pos + 3) == "null" then
			pos = pos + 4 return nil
		elseif s:sub(pos, pos + 3) == "true" then
			pos = pos + 4 return true
		elseif s:sub(pos, pos + 4) == "false" then
			pos = pos + 5 return false
		else
			local num = s:match("^-?%d+%.?%d*[eE]?[-+]?%d*", pos)
			if not num or num == "" then error("unexpected '" .. c .. "' at " .. pos) end
			pos = pos + #num
			return tonumber(num)
		end
	end
	local ok, v = pcall(value)
	if not ok then return nil, v end
	return v
end
M.json_decode = json_decode

local function read_stats(path)
	local frames = {}
	local f = io.open(path, "r")
	if not f then return frames end
	for line in f:lines() do
		local v = json_decode(line)
		if type(v) == "table" then frames[#frames + 1] = v end
	end
	f:close()
	return frames
end

-- "x,y" rows after '#' comments and a header; sorted by x.
local function read_data(path, study_file)
	local p = resolve(path, study_file)
	local f = io.open(p, "r")
	if not f then error(study_file .. ": reference data '" .. path .. "' not found (looked from the repository root and " .. study_file .. ")", 0) end
	local rows = {}
	for line in f:lines() do
		local x, y = line:match("^%s*([-%d%.eE+]+)%s*,%s*([-%d%.eE+]+)")
		if x and tonumber(x) and tonumber(y) then rows[#rows + 1] = { tonumber(x), tonumber(y) } end
	end
	f:close()
	table.sort(rows, function(a, b) return a[1] < b[1] end)
	if #rows < 2 then error(study_file .. ": reference data '" .. p .. "' has fewer than 2 rows", 0) end
	return rows
end

local function interpolate(rows, x)
	for i = 2, #rows do
		local a, b = rows[i - 1], rows[i]
		if x >= a[1] and x <= b[1] then
			if b[1] == a[1] then return a[2] end
			return a[2] + (b[2] - a[2]) * (x - a[1]) / (b[1] - a[1])
		end
	end
	return nil
end

-- ---- metrics ---------------------------------------------------------------

local function mean_abs(frames, rows, m, shift)
	local sum, n = 0, 0
	for _, f in ipairs(frames) do
		local x, y = f[m.x], f[m.y]
		if type(x) == "number" and type(y) == "number" and x >= (m.from or -math.huge) and x <= (m.to or math.huge) then
			local r = interpolate(rows, x + (shift or 0))
			if r then sum, n = sum + math.abs(y - r), n + 1 end
		end
	end
	return n > 0 and sum / n or 0 / 0
end

local function field_reduce(frames, field, how, from)
	local acc, n = (how == "max") and -math.huge or 0, 0
	for _, f in ipairs(frames) do
		local v = f[field]
		if type(v) == "number" and (f.time or 0) >= (from or -math.huge) then
			if how == "max" then acc = math.max(acc, v) else acc = acc + v end
			n = n + 1
		end
	end
	if n == 0 then return 0 / 0 end
	return how == "max" and acc or acc / n
end

-- omega (rad/s) of a stats field from its zero crossings (linearly
-- interpolated), which are half a period apart, over whole periods once
-- there are any (an even number of half periods: a field riding on a small
-- offset has half periods alternating short and long, and an odd count
-- keeps one more of one kind); NaN with fewer than 2. The count stops at
-- the first half period whose peak |field| is under DECAYED of the largest
-- before it: a damped mode that has rung down crosses zero with its noise
-- (a drop at 6 spacings per radius, rung down by 0.6 s, read 56% off).
local DECAYED = 0.1
local function omega_of(frames, field, from)
	local crossings, prev, prev_t = {}, nil, nil
	local peak, largest = 0, 0 -- this half period's peak |v|, the largest of the whole ones before
	for _, f in ipairs(frames) do
		local v, t = f[field], f.time
		if type(v) == "number" and type(t) == "number" and t >= (from or 0) then
			if prev and ((prev > 0 and v <= 0) or (prev < 0 and v >= 0)) and v ~= prev then
				if #crossings > 0 and peak < DECAYED * largest then break end
				if #crossings > 0 then largest = math.max(largest, peak) end
				crossings[#crossings + 1] = prev_t + (t - prev_t) * prev / (prev - v)
				peak = 0
			end
			peak = math.max(peak, math.abs(v))
			prev, prev_t = v, t
		end
	end
	if #crossings < 2 then return 0 / 0 end
	local last = #crossings
	if (last - 1) % 2 == 1 and last > 2 then last = last - 1 end
	return math.pi * (last - 1) / (crossings[last] - crossings[1])
end

-- ---- the sweep -------------------------------------------------------------

local function combinations(sweep)
	local keys = {}
	for k in pairs(sweep or {}) do keys[#keys + 1] = k end
	table.sort(keys)
	local out = { {} }
	for _, k in ipairs(keys) do
		local next_out = {}
		for _, base in ipairs(out) do
			for _, v in ipairs(sweep[k]) do
				local c = {}
				for kk, vv in pairs(base) do c[kk] = vv end
				c[k] = v
				next_out[#next_out + 1] = c
			end
		end
		out = next_out
	end
	return out, keys
end

local function fmt(v)
	if type(v) == "number" then
		if v ~= v then return "" end
		if math.type(v) == "integer" then return tostring(v) end
		return string.format("%.6g", v)
	end
	if v == nil then return "" end
	return tostring(v)
end

local function csv_field(v)
	local s = fmt(v)
	if s:find('[,"\n]') then s = '"' .. s:gsub('"', '""') .. '"' end
	return s
end

local function mkdir_p(dir)
	-- os.execute is the portable door here; the path is quoted
	os.execute("mkdir -p '" .. dir:gsub("'", "'\\''") .. "'")
end

local function run_one(ctx, s, m, params, index, quick)
	local stats = string.format("%s/runs/%s_%02d.jsonl", ctx.out, m.name:gsub("[^%w]", "_"), index)
	local log = stats:gsub("%.jsonl$", ".log")
	os.remove(stats)
	local scene = resolve(m.scene, ctx.file)
	-- wall time measures physics: the shipped scenes render (eddy.view)
	-- unless --set render=false, so a scene run by a study must read the
	-- 'render' parameter (eddy.param("render", true)); eddy run rejects a
	-- --set the scene never reads, which names the fix. Each run has its own
	-- --out (beside its stats), so it never contends for the lock of the
	-- scene's default output folder with another run of the same scene.
	local argv = { ctx.exe, "run", scene, "--quiet", "--stats", stats, "--out", (stats:gsub("%.jsonl$", "")) }
	if ctx.safe then argv[#argv + 1] = "--safe" end
	-- render = false unless the study sets it: eddy run takes each --set once
	local set = { render = false }
	for k, v in pairs(s.set or {}) do set[k] = v end
	for k, v in pairs(m.set or {}) do set[k] = v end
	for k, v in pairs(params) do set[k] = v end
	local keys = {}
	for k in pairs(set) do keys[#keys + 1] = k end
	table.sort(keys)
	for _, k in ipairs(keys) do
		if k == "threads" then
			argv[#argv + 1] = "--threads"
			argv[#argv + 1] = fmt(set[k])
		else
			argv[#argv + 1] = "--set"
			argv[#argv + 1] = k .. "=" .. fmt(set[k])
		end
	end
	local duration = quick and (m.quick_duration or s.quick_duration) or nil
	duration = duration or m.duration or s.duration
	if duration then
		argv[#argv + 1] = "--duration"
		argv[#argv + 1] = fmt(duration)
	end
	local code, wall, rss, signal = ctx.spawn(argv, log)
	if signal ~= 0 then
		-- Ctrl-C reached the run too: stop the sweep rather than time the rest
		error(string.format("study: stopped by signal %d during %s (%s)", signal, m.name, log), 0)
	end
	local frames = read_stats(stats)
	local row = { method = m.name, scene = m.scene, params = params, status = code, wall_s = wall,
	              peak_mb = rss / 1024, frames = #frames, systems = {}, set = set }
	if code ~= 0 then
		local f = io.open(log, "r")
		local msg = f and f:read("l") or ""
		if f then f:close() end
		row.message = msg
	end
	local steps, particles = 0, nil
	for _, f in ipairs(frames) do
		steps = steps + (tonumber(f.steps) or 0)
		particles = tonumber(f.particles) or particles
		if type(f.systems) == "table" then
			for name, ms in pairs(f.systems) do
				if type(ms) == "number" then row.systems[name] = (row.systems[name] or 0) + ms / 1000 end
			end
		end
	end
	row.steps, row.particles = steps, particles
	row.sim_time = frames[#frames] and frames[#frames].time or 0
	row.data = frames
	return row
end

local function compute_error(ctx, s, m, row, finest)
	local metric = m.metric or s.metric
	if type(metric) == "function" then
		return metric(row.data, ctx.reference, row.set)
	end
	if metric.kind == "mean_abs" then
		local rows = ctx.reference
		if s.reference.finest then
			if not finest or finest == row then return 0 / 0 end
			rows = {}
			for _, f in ipairs(finest.data) do
				if type(f[metric.x]) == "number" and type(f[metric.y]) == "number" then
					rows[#rows + 1] = { f[metric.x], f[metric.y] }
				end
			end
			table.sort(rows, function(a, b) return a[1] < b[1] end)
		end
		if metric.shift and not s.reference.finest then
			-- the experiment's clock may start before the simulated release (a
			-- gate opens in finite time): also the best error over shifts of
			-- the reference's x in [0, shift]
			local best, best_s = math.huge, 0
			for i = 0, 40 do
				local sh = metric.shift * i / 40
				local e = mean_abs(row.data, rows, metric, sh)
				if e < best then best, best_s = e, sh end
			end
			row.shifted = { error_shifted = best, shift = best_s }
		end
		return mean_abs(row.data, rows, metric)
	elseif metric.kind == "frequency" then
		local omega = omega_of(row.data, metric.field, metric.from)
		row.omega = omega
		local expected = s.reference.analytic(row.set)
		row.omega_ref = expected
		return math.abs(omega / expected - 1)
	else
		return field_reduce(row.data, metric.field, metric.kind, metric.from)
	end
end

local function write_csv(path, s, rows, param_keys, sys_keys, extra_keys)
	local f = assert(io.open(path, "w"))
	local head = { "study", "method", "scene" }
	for _, k in ipairs(param_keys) do head[#head + 1] = k end
	for _, k in ipairs({ "resolution", "error" }) do head[#head + 1] = k end
	for _, k in ipairs(extra_keys) do head[#head + 1] = k end
	for _, k in ipairs({ "order", "wall_s", "steps", "frames", "particles", "peak_mb", "status", "pareto" }) do
		head[#head + 1] = k
	end
	for _, k in ipairs(sys_keys) do head[#head + 1] = "sys_" .. k .. "_s" end
	f:write(table.concat(head, ","), "\n")
	for _, r in ipairs(rows) do
		local line = { csv_field(s.name), csv_field(r.method), csv_field(r.scene) }
		for _, k in ipairs(param_keys) do line[#line + 1] = csv_field(r.set[k]) end
		line[#line + 1] = csv_field(r.resolution)
		line[#line + 1] = csv_field(r.error)
		for _, k in ipairs(extra_keys) do line[#line + 1] = csv_field(r.extra[k]) end
		-- a numeric loop: order and particles may be nil, which ipairs would stop at
		local tail = { r.order, r.wall_s, r.steps, r.frames, r.particles, r.peak_mb, r.status, r.pareto and 1 or 0 }
		for i = 1, 8 do line[#line + 1] = csv_field(tail[i]) end
		for _, k in ipairs(sys_keys) do line[#line + 1] = csv_field(r.systems[k]) end
		f:write(table.concat(line, ","), "\n")
	end
	f:close()
end

local function shell_quote(p) return "'" .. p:gsub("'", "'\\''") .. "'" end

local function have_gnuplot()
	local ok = os.execute("command -v gnuplot >/dev/null 2>&1")
	return ok == true or ok == 0
end

-- error against wall time, log-log; one series per method; the Pareto front
-- (no other run is both faster and more accurate) as a line through its runs.
local function write_chart(ctx, s, rows, label)
	local png = ctx.out .. "/" .. s.name .. ".png"
	if not have_gnuplot() then
		io.stderr:write("eddy: study: gnuplot not found, no chart (apt-get install gnuplot-nox)\n")
		return nil
	end
	local methods, seen = {}, {}
	for _, r in ipairs(rows) do
		if not seen[r.method] then seen[r.method] = true methods[#methods + 1] = r.method end
	end
	local plottable = false
	for _, r in ipairs(rows) do
		plottable = plottable or (r.status == 0 and r.error == r.error and r.error > 0)
	end
	if not plottable then
		io.stderr:write("eddy: study: no run has an error to plot, no chart\n")
		return nil
	end
	local dat = ctx.out .. "/" .. s.name .. ".dat"
	local f = assert(io.open(dat, "w"))
	-- one gnuplot data block per method with points, then the front:
	-- gnuplot's index counts only blocks holding data, so an empty one (a
	-- method whose runs all failed) would hand its index, and its title,
	-- to the next method's points
	local blocks = {} -- {name, pt} per block written, in index order
	for i, name in ipairs(methods) do
		local lines = {}
		for _, r in ipairs(rows) do
			if r.method == name and r.error == r.error and r.error > 0 and r.status == 0 then
				lines[#lines + 1] = string.format("%.6g %.6g\n", r.wall_s, r.error)
			end
		end
		if #lines > 0 then
			f:write("# ", name, "\n", table.concat(lines), "\n\n")
			blocks[#blocks + 1] = { name = name, pt = 4 + 2 * (i - 1) }
		end
	end
	f:write("# Pareto front\n")
	local front = {}
	for _, r in ipairs(rows) do if r.pareto then front[#front + 1] = r end end
	table.sort(front, function(a, b) return a.wall_s < b.wall_s end)
	for _, r in ipairs(front) do f:write(string.format("%.6g %.6g\n", r.wall_s, r.error)) end
	f:close()
	local gp = ctx.out .. "/" .. s.name .. ".gp"
	f = assert(io.open(gp, "w"))
	f:write("set terminal pngcairo size 900,600 font 'sans,11'\n")
	f:write("set output ", string.format("%q", png), "\n")
	f:write("set termoption noenhanced\nset logscale xy\nset grid\nset key outside right top\n")
	f:write("set title ", string.format("%q", (s.title or s.name) .. (ctx.quick and " (quick)" or "")), "\n")
	f:write("set xlabel 'wall time per run (s)'\n")
	f:write("set ylabel ", string.format("%q", label), "\n")
	local plots = {}
	for i, b in ipairs(blocks) do
		plots[#plots + 1] = string.format("%q index %d using 1:2 with linespoints pt %d ps 1.5 lw 2 title %q",
			dat, i - 1, b.pt, b.name)
	end
	if #front > 0 then
		plots[#plots + 1] = string.format("%q index %d using 1:2 with steps dt 2 lw 1.5 lc rgb 'black' title 'Pareto front', '' index %d using 1:2 with points pt 6 ps 3 lc rgb 'black' notitle",
			dat, #blocks, #blocks)
	end
	f:write("plot ", table.concat(plots, ", \\\n     "), "\n")
	f:close()
	local log = ctx.out .. "/" .. s.name .. ".log"
	local ok = os.execute("gnuplot " .. shell_quote(gp) .. " 2>" .. shell_quote(log))
	if not (ok == true or ok == 0) then
		io.stderr:write("eddy: study: gnuplot failed (see " .. log .. ")\n")
		return nil
	end
	return png
end

-- ---- entry point -----------------------------------------------------------

-- args: file, out, quick, safe, exe, spawn. Returns the exit status.
function M.main(args)
	local study, method = constructors(args.file)
	local env = setmetatable({ study = study, method = method }, { __index = _G })
	local chunk, err = loadfile(args.file, "t", env)
	if not chunk then
		if not exists(args.file) then error("cannot read study '" .. args.file .. "'", 0) end
		error(err, 0)
	end
	local ok, s = pcall(chunk)
	if not ok then error(s, 0) end
	if getmetatable(s) == nil or getmetatable(s).__name ~= "eddy.study" then
		error(args.file .. ": the study file must return study { ... } (got " .. type(s) .. ")", 0)
	end
	local ctx = { file = args.file, exe = args.exe, spawn = args.spawn, quick = args.quick, safe = args.safe,
	              out = args.out or ("out/study_" .. s.name) }
	-- a missing scene is the study file's mistake: say so before running anything
	for _, m in ipairs(s.methods) do
		if not exists(resolve(m.scene, args.file)) then
			error(getmetatable(m).scene_at .. "method '" .. m.name .. "': scene '" .. m.scene .. "' not found", 0)
		end
	end
	mkdir_p(ctx.out .. "/runs")
	if s.reference.data then ctx.reference = read_data(s.reference.data, args.file) end
	local metric_label = (type(s.metric) == "table" and (s.metric.label or s.metric.kind .. " " .. (s.metric.field or s.metric.y))) or "error"

	local rows, param_set, param_keys = {}, {}, {}
	local failed = 0
	for _, m in ipairs(s.methods) do
		local sweep = m.sweep
		if args.quick and m.quick ~= nil then sweep = m.quick end
		if sweep then
			local combos = combinations(sweep)
			local method_rows = {}
			for i, params in ipairs(combos) do
				io.stdout:write(string.format("%-14s", m.name))
				local pk = {}
				for k in pairs(params) do pk[#pk + 1] = k end
				table.sort(pk)
				for _, k in ipairs(pk) do io.stdout:write(" ", k, "=", fmt(params[k])) end
				io.stdout:flush()
				local r = run_one(ctx, s, m, params, i, args.quick)
				r.resolution = m.resolution and tonumber(params[m.resolution]) or nil
				rows[#rows + 1] = r
				method_rows[#method_rows + 1] = r
				if r.status ~= 0 then
					failed = failed + 1
					io.stdout:write(string.format("  FAILED (status %d): %s\n", r.status, r.message or ""))
				else
					io.stdout:write(string.format("  %.2f s, %d steps, %.0f MB\n", r.wall_s, r.steps, r.peak_mb))
				end
				for k in pairs(r.set) do
					if not param_set[k] and k ~= "render" then param_set[k] = true param_keys[#param_keys + 1] = k end
				end
			end
			-- the finest run of the method (smallest resolution) is its reference when asked
			local finest
			for _, r in ipairs(method_rows) do
				if r.resolution and (not finest or r.resolution < finest.resolution) then finest = r end
			end
			for _, r in ipairs(method_rows) do
				r.error = r.status == 0 and compute_error(ctx, s, m, r, finest) or 0 / 0
				r.is_reference = s.reference.finest and r == finest
				r.extra = {}
				for k, how in pairs(s.extra or {}) do
					r.extra[k] = field_reduce(r.data, k, how, nil)
				end
			end
			-- observed order between successive resolutions (coarse to fine);
			-- not against experimental data, whose gap to the model does not
			-- vanish with resolution
			if m.resolution and not s.reference.data then
				local sorted = {}
				for _, r in ipairs(method_rows) do
					if r.resolution and r.error == r.error and r.error > 0 then sorted[#sorted + 1] = r end
				end
				table.sort(sorted, function(a, b) return a.resolution > b.resolution end)
				for i = 2, #sorted do
					local c, f = sorted[i - 1], sorted[i]
					if c.resolution ~= f.resolution then
						f.order = math.log(c.error / f.error) / math.log(c.resolution / f.resolution)
					end
				end
			end
		end
	end
	-- Pareto front over every finished run with an error
	for _, r in ipairs(rows) do
		if r.status == 0 and r.error == r.error then
			r.pareto = true
			for _, o in ipairs(rows) do
				if o ~= r and o.status == 0 and o.error == o.error and o.wall_s <= r.wall_s and o.error <= r.error
					and (o.wall_s < r.wall_s or o.error < r.error) then
					r.pareto = false
					break
				end
			end
		end
	end
	table.sort(param_keys)
	local sys_set, sys_keys = {}, {}
	for _, r in ipairs(rows) do
		for k in pairs(r.systems) do
			if not sys_set[k] then sys_set[k] = true sys_keys[#sys_keys + 1] = k end
		end
	end
	table.sort(sys_keys)
	local extra_keys = {}
	for k in pairs(s.extra or {}) do extra_keys[#extra_keys + 1] = k end
	table.sort(extra_keys)
	if type(s.metric) == "table" and s.metric.shift then
		extra_keys[#extra_keys + 1] = "error_shifted"
		extra_keys[#extra_keys + 1] = "shift"
		for _, r in ipairs(rows) do
			if r.shifted then r.extra.error_shifted, r.extra.shift = r.shifted.error_shifted, r.shifted.shift end
		end
	end
	if type(s.metric) == "table" and s.metric.kind == "frequency" then
		extra_keys[#extra_keys + 1] = "omega"
		extra_keys[#extra_keys + 1] = "omega_ref"
		for _, r in ipairs(rows) do r.extra.omega, r.extra.omega_ref = r.omega, r.omega_ref end
	end
	local csv = ctx.out .. "/" .. s.name .. ".csv"
	write_csv(csv, s, rows, param_keys, sys_keys, extra_keys)
	local png = write_chart(ctx, s, rows, metric_label)
	print(string.format("%d runs, %d failed; wrote %s%s", #rows, failed, csv, png and (" and " .. png) or ""))
	for _, r in ipairs(rows) do
		if r.order then
			print(string.format("  %s %s=%s: observed order %.2f", r.method, "resolution", fmt(r.resolution), r.order))
		end
	end
	return failed > 0 and 1 or 0
end

return M
