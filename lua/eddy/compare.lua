-- SPDX-License-Identifier: MIT
-- The driver behind `eddy compare SCENE.lua [--methods a,b] [--set K=V ...]
-- [--out DIR] [--quick] [--field NAME] [--safe]` (arguments: lua/compare.c).
--
-- The scene is run once per method, one after another, each as a child
--   eddy run SCENE --set method=M [--set K=V ...] --out DIR/runs/M
--            --stats DIR/runs/M/stats.jsonl [--frames 6] [--safe]
-- (spawn, lua/compare.c: wall time and peak memory through wait4, as for
-- eddy study), so no run disturbs another's time or memory. From the stats
-- lines and the frames each run rendered, it writes into DIR:
--   frame_NNNN.png     the methods side by side (one panel each, stamped with
--                      the method, the simulated time and the ms of the frame;
--                      a failed method's panel says why)
--   compare.mp4        the same frames, when ffmpeg is on PATH
--   compare.csv        one row per method
--   compare.md         the same as Markdown tables, and each method's warnings
--                      (the preflight's and the run's: a solve at its cap, a
--                      nozzle held back, ...) from its run.log
--   compare_FIELD.png  a stats field against simulated time, one line per method
--   compare_cost.png   wall time per simulated second, per method
-- A failed method is a row with its reason; the others still run. Returns
-- the exit status: 0 when every method ran and every file was written, 1
-- otherwise.

local M = {}

local json_decode = require("eddy.study").json_decode

-- stats fields eddy writes itself; of these only the measurements below are
-- compared. Fields systems publish that are not measurements are left out.
local CONTRACT = {
	frame = true, time = true, steps = true, dt_min = true, dt_max = true, dt_limit = true, particles = true,
	max_speed = true, cfl = true, density_err_avg = true, density_err_max = true, density_compression_avg = true,
	volume = true, leaked = true, nonfinite = true, solver = true, iterations = true, residual = true,
	divergence = true, wall_ms = true, state_hash = true, systems = true,
	render_ms = true, png_ms = true, image = true, pinned = true, analyses = true,
}
local MEASURED = { "density_err_avg", "density_err_max", "volume", "max_speed" }
-- systems that draw or write files rather than simulate
local OUTPUT_SYSTEMS = { render_points = true, export_particles = true, on_frame = true }

local function exists(path)
	local f = io.open(path, "rb")
	if f then f:close() return true end
	return false
end

local function shell_quote(p) return "'" .. p:gsub("'", "'\\''") .. "'" end

local function mkdir_p(dir)
	local ok = os.execute("mkdir -p " .. shell_quote(dir))
	if not (ok == true or ok == 0) then error("compare: cannot create folder '" .. dir .. "'", 0) end
end

-- One line on stderr, after whatever stdout holds (so the lines keep their order).
local function note(msg)
	io.stdout:flush()
	io.stderr:write("eddy: compare: ", msg, "\n")
end

local function on_path(name)
	local ok = os.execute("command -v " .. name .. " >/dev/null 2>&1")
	return ok == true or ok == 0
end

local function fmt(v, f)
	if v == nil then return "" end
	if type(v) == "number" then
		if v ~= v then return "" end
		if math.type(v) == "integer" then return tostring(v) end
		return string.format(f or "%.6g", v)
	end
	return tostring(v)
end

local function csv_field(v)
	local s = fmt(v)
	if s:find('[,"\n]') then s = '"' .. s:gsub('"', '""') .. '"' end
	return s
end

local function md_cell(v, f)
	return (fmt(v, f):gsub("|", "\\|"))
end

-- The stats lines, and the order of the systems as the first line lists them
-- (the decoded table has none).
local function read_stats(path)
	local frames, order = {}, {}
	local f = io.open(path, "r")
	if not f then return frames, order end
	for line in f:lines() do
		local v = json_decode(line)
		if type(v) == "table" then
			frames[#frames + 1] = v
			if #order == 0 then
				local sys = line:match('"systems":(%b{})')
				for name in (sys or ""):gmatch('"([^"]+)":') do order[#order + 1] = name end
			end
		end
	end
	f:close()
	return frames, order
end

-- The child's warnings: its "eddy: warning: " lines, in order.
local function warnings_of(log)
	local list = {}
	local f = io.open(log, "r")
	if f then
		for line in f:lines() do
			local text = line:match("^eddy: warning: (.*)")
			if text then list[#list + 1] = text end
		end
		f:close()
	end
	return list
end

-- The child's one-line error: its first "eddy: " line that is not a warning,
-- else its first line, else the exit status.
local function failure_reason(log, code)
	local first
	local f = io.open(log, "r")
	if f then
		for line in f:lines() do
			if line:match("^eddy: ") and not line:match("^eddy: warning: ") then first = line:sub(7) break end
			if not first and line:match("%S") then first = line end
		end
		f:close()
	end
	if first then return first end
	if code == 127 then return "the eddy command could not be started" end
	if code > 128 then return "killed by signal " .. (code - 128) end
	return "exit status " .. code
end

-- The image of a stats line: its `image` path when that file is there; stats
-- texts hold 63 characters, so a longer path arrives cut short and the frame
-- is then found by its number among the run's PNG files.
local function frame_image(ctx, run, f)
	if type(f.image) ~= "string" then return nil end
	if exists(f.image) then return f.image end
	if not run.listing then run.listing = ctx.listdir(run.dir) or {} end
	local number = tonumber(f.image:match("(%d+)%.png$")) or f.frame
	for _, name in ipairs(run.listing) do
		local n = name:match("(%d+)%.png$")
		if n and tonumber(n) == number then return run.dir .. "/" .. name end
	end
	return nil
end

local function run_method(ctx, method)
	local dir = ctx.out .. "/runs/" .. method
	mkdir_p(dir)
	local stats, log = dir .. "/stats.jsonl", dir .. "/run.log"
	os.remove(stats)
	local argv = { ctx.exe, "run", ctx.scene, "--set", "method=" .. method }
	for _, kv in ipairs(ctx.set) do
		argv[#argv + 1] = "--set"
		argv[#argv + 1] = kv
	end
	-- not --quiet: the child's warnings go to its run.log (its stderr is no
	-- terminal, so no progress bar) and into compare.md
	for _, a in ipairs({ "--out", dir, "--stats", stats }) do argv[#argv + 1] = a end
	if ctx.quick then
		argv[#argv + 1] = "--frames"
		argv[#argv + 1] = "6"
	end
	if ctx.safe then argv[#argv + 1] = "--safe" end
	if ctx.threads > 0 then
		argv[#argv + 1] = "--threads"
		argv[#argv + 1] = tostring(ctx.threads)
	end
	io.stdout:write(string.format("%-10s", method))
	io.stdout:flush()
	local code, wall, rss, signal = ctx.spawn(argv, log)
	local frames, order = read_stats(stats)
	local r = { method = method, dir = dir, code = code, wall_s = wall, peak_mb = rss / 1024, frames = frames,
	            nframes = #frames, sys_order = order, systems = {}, steps = 0, images = {}, measure = {} }
	if code ~= 0 then r.reason = failure_reason(log, code) end
	r.warnings = warnings_of(log)
	-- Ctrl-C or SIGTERM: the child stopped after its frame (status 128 + the
	-- signal); no further method runs
	if (signal or 0) ~= 0 or code == 130 or code == 143 then
		r.interrupted = (signal or 0) ~= 0 and signal or code - 128
	end
	local dt_min, dt_max
	for _, f in ipairs(frames) do
		r.steps = r.steps + (tonumber(f.steps) or 0)
		if type(f.dt_min) == "number" then dt_min = math.min(dt_min or math.huge, f.dt_min) end
		if type(f.dt_max) == "number" then dt_max = math.max(dt_max or -math.huge, f.dt_max) end
		if type(f.particles) == "number" then r.particles = f.particles end
		if type(f.time) == "number" then r.sim_time = f.time end
		if type(f.systems) == "table" then
			for name, ms in pairs(f.systems) do
				if type(ms) == "number" then r.systems[name] = (r.systems[name] or 0) + ms end
			end
		end
		local img = frame_image(ctx, r, f)
		if img and type(f.frame) == "number" then
			r.images[f.frame] = { path = img, time = f.time, wall_ms = f.wall_ms }
			r.rendered = (r.rendered or 0) + 1
		end
		-- measurements: the contract's, and every other number (the scene's own)
		for k, v in pairs(f) do
			if type(v) == "number" and (not CONTRACT[k] or ctx.measured_set[k]) then
				local m = r.measure[k] or {}
				m.last_frame, m.worst = f.frame, math.max(m.worst or 0, math.abs(v))
				r.measure[k] = m
			end
		end
	end
	-- the value at the end is the last frame's (nil when it has none)
	local last = frames[#frames]
	for k, m in pairs(r.measure) do
		m.final = last and type(last[k]) == "number" and last[k] or nil
	end
	r.dt_min, r.dt_max = dt_min, dt_max
	if r.steps > 0 and r.sim_time then r.dt_mean = r.sim_time / r.steps end
	local physics = 0
	for name, ms in pairs(r.systems) do
		if not OUTPUT_SYSTEMS[name] then physics = physics + ms end
	end
	r.physics_ms = physics
	io.stdout:flush()
	if code == 0 then
		io.stdout:write(string.format("  %.2f s, %d frames, %d steps, %.0f MB\n", wall, #frames, r.steps, r.peak_mb))
	else
		io.stdout:write(string.format("  FAILED (status %d): %s\n", code, r.reason))
	end
	return r
end

-- ---- tables ----------------------------------------------------------------------

local function status_text(r)
	return r.code == 0 and "ok" or ("failed: " .. r.reason)
end

local function keys_of(runs)
	local sys, sys_seen = {}, {}
	for _, r in ipairs(runs) do
		for _, name in ipairs(r.sys_order) do
			if not sys_seen[name] then sys_seen[name] = true sys[#sys + 1] = name end
		end
		local rest = {}
		for name in pairs(r.systems) do
			if not sys_seen[name] then rest[#rest + 1] = name end
		end
		table.sort(rest)
		for _, name in ipairs(rest) do sys_seen[name] = true sys[#sys + 1] = name end
	end
	local fields, seen = {}, {}
	for _, k in ipairs(MEASURED) do
		for _, r in ipairs(runs) do
			if r.measure[k] and not seen[k] then seen[k] = true fields[#fields + 1] = k end
		end
	end
	local extra = {}
	for _, r in ipairs(runs) do
		for k in pairs(r.measure) do
			if not seen[k] then seen[k] = true extra[#extra + 1] = k end
		end
	end
	table.sort(extra)
	for _, k in ipairs(extra) do fields[#fields + 1] = k end
	return sys, fields
end

local function write_csv(path, runs, sys, fields)
	local f = assert(io.open(path, "w"))
	local head = { "method", "status", "exit_code", "wall_s", "frames", "sim_time_s", "steps", "dt_mean_s", "dt_min_s",
	               "dt_max_s", "peak_mb", "particles", "physics_ms" }
	for _, k in ipairs(sys) do head[#head + 1] = "sys_" .. k .. "_ms" end
	for _, k in ipairs(fields) do
		head[#head + 1] = k .. "_end"
		head[#head + 1] = k .. "_worst"
	end
	f:write(table.concat(head, ","), "\n")
	for _, r in ipairs(runs) do
		local row = { r.method, status_text(r), r.code, r.wall_s, r.nframes, r.sim_time, r.steps, r.dt_mean, r.dt_min,
		              r.dt_max, r.peak_mb, r.particles, r.physics_ms }
		local line = {}
		for i = 1, 13 do line[i] = csv_field(row[i]) end
		for _, k in ipairs(sys) do line[#line + 1] = csv_field(r.systems[k]) end
		for _, k in ipairs(fields) do
			local m = r.measure[k]
			line[#line + 1] = csv_field(m and m.final)
			line[#line + 1] = csv_field(m and m.worst)
		end
		f:write(table.concat(line, ","), "\n")
	end
	assert(f:close())
end

local function write_md(path, ctx, runs, sys, fields)
	local f = assert(io.open(path, "w"))
	local out = {}
	local function w(...) for _, s in ipairs({ ... }) do out[#out + 1] = s end end
	w("# eddy compare: ", ctx.scene, "\n\n")
	w(string.format("Methods %s%s; one child `eddy run` each, one after another. ", table.concat(ctx.methods, ", "),
		#ctx.set > 0 and (" with `--set " .. table.concat(ctx.set, " --set ") .. "`") or ""))
	w(ctx.quick and "Quick: 6 frames each.\n\n" or "\n\n")
	w("| method | status | wall (s) | frames | simulated (s) | steps | mean dt (ms) | min dt (ms) | max dt (ms) | ",
	  "peak memory (MB) | particles | systems (ms) | physics (ms) |\n")
	w("|---|---|---|---|---|---|---|---|---|---|---|---|---|\n")
	for _, r in ipairs(runs) do
		local total = 0
		for _, ms in pairs(r.systems) do total = total + ms end
		w("| ", md_cell(r.method), " | ", md_cell(status_text(r)), " | ", md_cell(r.wall_s, "%.2f"), " | ",
		  md_cell(r.nframes), " | ", md_cell(r.sim_time, "%.4g"), " | ", md_cell(r.steps), " | ",
		  md_cell(r.dt_mean and r.dt_mean * 1000, "%.3g"), " | ", md_cell(r.dt_min and r.dt_min * 1000, "%.3g"), " | ",
		  md_cell(r.dt_max and r.dt_max * 1000, "%.3g"), " | ", md_cell(r.peak_mb, "%.1f"), " | ",
		  md_cell(r.particles), " | ", md_cell(total, "%.1f"), " | ", md_cell(r.physics_ms, "%.1f"), " |\n")
	end
	w("\nTimes are summed over the frames' stats lines; physics leaves out render_points, export_particles and ",
	  "on_frame. Wall time and peak memory are the child process's (wait4).\n")
	local function header(first)
		w("| ", first)
		for _, r in ipairs(runs) do w(" | ", md_cell(r.method)) end
		w(" |\n|---")
		for _ = 1, #runs do w("|---") end
		w("|\n")
	end
	if #sys > 0 then
		w("\n## Time per system (ms, summed over frames)\n\n")
		header("system")
		for _, k in ipairs(sys) do
			w("| ", md_cell(k))
			for _, r in ipairs(runs) do w(" | ", md_cell(r.systems[k], "%.2f")) end
			w(" |\n")
		end
	end
	if #fields > 0 then
		w("\n## Measurements: at the end / worst (largest |value| over frames)\n\n")
		header("field")
		for _, k in ipairs(fields) do
			w("| ", md_cell(k))
			for _, r in ipairs(runs) do
				local m = r.measure[k]
				w(" | ", m and (md_cell(m.final, "%.4g") .. " / " .. md_cell(m.worst, "%.4g")) or "")
			end
			w(" |\n")
		end
	end
	local any = false
	for _, r in ipairs(runs) do any = any or #r.warnings > 0 end
	if any then
		w("\n## Warnings (each run's, from its run.log)\n\n")
		for _, r in ipairs(runs) do
			for _, text in ipairs(r.warnings) do w("- ", md_cell(r.method), ": ", md_cell(text), "\n") end
		end
	end
	f:write(table.concat(out))
	assert(f:close())
end

-- ---- side-by-side frames and the video ------------------------------------------

local function caption(r, shot)
	if shot then
		return string.format("%s\nt = %.3f s\n%s ms/frame", r.method, tonumber(shot.time) or 0,
			type(shot.wall_ms) == "number" and string.format("%.1f", shot.wall_ms) or "?")
	end
	if r.code ~= 0 then return r.method .. "\nfailed: " .. r.reason end
	if not r.rendered then return r.method .. "\nfailed: rendered no frames (the scene has no render_points)" end
	return r.method .. "\nno frame rendered here"
end

-- Returns the frame paths written (in order) and the fps of the scene.
local function write_panels(ctx, runs)
	for _, name in ipairs(ctx.listdir(ctx.out) or {}) do
		if name:match("^frame_%d+%.png$") then os.remove(ctx.out .. "/" .. name) end
	end
	local numbers, seen = {}, {}
	for _, r in ipairs(runs) do
		for n in pairs(r.images) do
			if not seen[n] then seen[n] = true numbers[#numbers + 1] = n end
		end
	end
	table.sort(numbers)
	local written, w, h = {}, nil, nil
	for _, n in ipairs(numbers) do
		local images, captions = {}, {}
		for i, r in ipairs(runs) do
			local shot = r.images[n]
			images[i] = shot and shot.path or false
			captions[i] = caption(r, shot)
		end
		local path = string.format("%s/frame_%04d.png", ctx.out, n)
		local pw, ph = ctx.compose(path, images, captions, w or 0, h or 0)
		if not pw then error("compare: " .. ph, 0) end
		w, h = pw, ph
		written[#written + 1] = path
	end
	local fps
	for _, r in ipairs(runs) do
		local f = r.frames[1]
		if not fps and f and type(f.time) == "number" and f.time > 0 and type(f.frame) == "number" then
			fps = f.frame / f.time
		end
	end
	return written, fps or 30, w and (w * #runs) or 0, h or 0
end

-- The frames piped to ffmpeg, as eddy run --video does (lua/cli_run.c).
local function write_video(ctx, frames, fps)
	local mp4, log = ctx.out .. "/compare.mp4", ctx.out .. "/ffmpeg.log"
	local cmd = string.format("ffmpeg -hide_banner -loglevel error -y -f image2pipe -c:v png -framerate %g -i - "
		.. "-pix_fmt yuv420p -vf 'pad=ceil(iw/2)*2:ceil(ih/2)*2' %s 2>%s", fps, shell_quote(mp4), shell_quote(log))
	local pipe = io.popen(cmd, "w")
	if not pipe then return false, "cannot start ffmpeg" end
	local ok = true
	for _, path in ipairs(frames) do
		local f = io.open(path, "rb")
		if not f then ok = false break end
		local bytes = f:read("a")
		f:close()
		if not pipe:write(bytes) then ok = false break end
	end
	local closed, _, status = pipe:close()
	if ok and closed then return mp4 end
	local l = io.open(log, "r")
	local msg = l and l:read("l") or nil
	if l then l:close() end
	return false, string.format("ffmpeg failed (status %s%s); the PNG frames are on disk", tostring(status),
		msg and (": " .. msg) or "")
end

-- ---- charts ------------------------------------------------------------------------

local function gnuplot(ctx, gp_text, name)
	local gp = ctx.out .. "/" .. name .. ".gp"
	local f = assert(io.open(gp, "w"))
	f:write(gp_text)
	f:close()
	-- each chart its own log: a later chart's run would empty a shared one
	local log = ctx.out .. "/" .. name .. ".log"
	local ok = os.execute("gnuplot " .. shell_quote(gp) .. " 2>" .. shell_quote(log))
	return ok == true or ok == 0, log
end

local function chart_field(ctx, runs)
	local field = ctx.field
	local png = ctx.out .. "/compare_" .. field .. ".png"
	local dat = ctx.out .. "/compare_" .. field .. ".dat"
	local f = assert(io.open(dat, "w"))
	-- one block per method with points: gnuplot's index counts only blocks
	-- holding data, so an empty one (a method that failed before its first
	-- frame) would hand its index to the next method's points
	local used = {}
	for i, r in ipairs(runs) do
		local rows = {}
		for _, s in ipairs(r.frames) do
			if type(s.time) == "number" and type(s[field]) == "number" then
				rows[#rows + 1] = string.format("%.9g %.9g\n", s.time, s[field])
			end
		end
		if #rows > 0 then
			f:write("# ", r.method, "\n", table.concat(rows), "\n\n")
			used[#used + 1] = string.format("%q index %d using 1:2 with linespoints lw 2 pt %d title %q", dat,
				#used, 5 + 2 * (i - 1), r.method .. (r.code ~= 0 and " (failed)" or ""))
		end
	end
	f:close()
	if #used == 0 then
		return nil, "no method's stats carry a number for '" .. field .. "', no chart of it"
	end
	local gp = table.concat({
		"set terminal pngcairo size 900,550 font 'sans,11'",
		"set output " .. string.format("%q", png),
		"set termoption noenhanced", "set grid", "set key outside right top",
		"set title " .. string.format("%q", field .. ": " .. ctx.scene),
		"set xlabel 'simulated time (s)'",
		"set ylabel " .. string.format("%q", field),
		"plot " .. table.concat(used, ", \\\n     "), "" }, "\n")
	local ok, log = gnuplot(ctx, gp, "compare_" .. field)
	if not ok then return nil, "gnuplot failed (see " .. log .. ")", true end
	return png
end

local function chart_cost(ctx, runs)
	local png, dat = ctx.out .. "/compare_cost.png", ctx.out .. "/compare_cost.dat"
	local f = assert(io.open(dat, "w"))
	f:write("# method, wall s per simulated s (process), systems without output per simulated s\n")
	local n = 0
	for _, r in ipairs(runs) do
		if r.sim_time and r.sim_time > 0 then
			f:write(string.format("%q %.6g %.6g\n", r.method .. (r.code ~= 0 and " (failed)" or ""),
				r.wall_s / r.sim_time, r.physics_ms / 1000 / r.sim_time))
			n = n + 1
		end
	end
	f:close()
	if n == 0 then return nil, "no method simulated any time, no cost chart" end
	local gp = table.concat({
		"set terminal pngcairo size 700,450 font 'sans,11'",
		"set output " .. string.format("%q", png),
		"set termoption noenhanced", "set grid ytics", "set key top left",
		"set title " .. string.format("%q", "cost: " .. ctx.scene .. (ctx.quick and " (quick)" or "")),
		"set ylabel 'wall time per simulated second (s/s)'",
		"set yrange [0:*]",
		"set style data histograms", "set style histogram clustered gap 1", "set style fill solid 0.8 border -1",
		"set boxwidth 0.9",
		string.format("plot %q using 2:xtic(1) title 'whole run (process wall time)', '' using 3 title 'systems, without rendering'", dat),
		"" }, "\n")
	local ok, log = gnuplot(ctx, gp, "compare_cost")
	if not ok then return nil, "gnuplot failed (see " .. log .. ")", true end
	return png
end

-- ---- entry point -------------------------------------------------------------------

-- args: scene, methods, set, out, quick, field, safe, threads, exe, spawn, listdir,
-- compose (lua/compare.c). Returns the exit status.
function M.main(args)
	if not exists(args.scene) then error("compare: cannot read scene '" .. args.scene .. "'", 0) end
	local name = args.scene:match("([^/]*)$"):match("^[^.]*")
	local ctx = { scene = args.scene, methods = args.methods, set = args.set, quick = args.quick, safe = args.safe,
	              threads = args.threads or 0,
	              field = args.field, exe = args.exe, spawn = args.spawn, listdir = args.listdir,
	              compose = args.compose, out = args.out or ("out/compare_" .. name), measured_set = {} }
	for _, k in ipairs(MEASURED) do ctx.measured_set[k] = true end
	mkdir_p(ctx.out .. "/runs")

	local runs, failed, problems = {}, 0, 0
	local interrupted
	for _, method in ipairs(ctx.methods) do
		if interrupted then
			-- a row all the same, so the tables list every method asked for
			runs[#runs + 1] = { method = method, dir = ctx.out .. "/runs/" .. method, code = -1,
			                    reason = "not run (interrupted)", wall_s = 0, peak_mb = nil, frames = {}, nframes = 0,
			                    sys_order = {}, systems = {}, steps = 0, images = {}, measure = {}, physics_ms = 0 }
			failed = failed + 1
		else
			local r = run_method(ctx, method)
			runs[#runs + 1] = r
			if r.code ~= 0 then failed = failed + 1 end
			interrupted = r.interrupted
		end
	end
	local sys, fields = keys_of(runs)
	local csv, md = ctx.out .. "/compare.csv", ctx.out .. "/compare.md"
	write_csv(csv, runs, sys, fields)
	write_md(md, ctx, runs, sys, fields)
	local wrote = { csv, md }

	local frames, fps, fw, fh = write_panels(ctx, runs)
	if #frames == 0 then
		note("no method rendered a frame, no side-by-side frames (add eddy.render_points to the scene)")
	else
		wrote[#wrote + 1] = string.format("%d side-by-side frames (%d x %d px) %s/frame_NNNN.png", #frames, fw, fh, ctx.out)
		if not on_path("ffmpeg") then
			note("ffmpeg not found, no compare.mp4 (apt-get install ffmpeg)")
		else
			local mp4, err = write_video(ctx, frames, fps)
			if mp4 then
				wrote[#wrote + 1] = mp4
			else
				note("compare.mp4: " .. err)
				problems = problems + 1
			end
		end
	end

	local any_frame = false
	for _, r in ipairs(runs) do any_frame = any_frame or r.nframes > 0 end
	if not any_frame then
		note("no method ran a frame, no charts")
	elseif not on_path("gnuplot") then
		note("gnuplot not found, no charts (apt-get install gnuplot-nox)")
	else
		for _, chart in ipairs({ chart_field, chart_cost }) do
			local png, err, fatal = chart(ctx, runs)
			if png then
				wrote[#wrote + 1] = png
			else
				note(err)
				if fatal then problems = problems + 1 end
			end
		end
	end
	print(string.format("%d method%s, %d failed; wrote %s", #runs, #runs == 1 and "" or "s", failed,
		table.concat(wrote, ", ")))
	if interrupted then
		note(string.format("interrupted by signal %d; the tables hold the methods run so far", interrupted))
		return 128 + interrupted
	end
	return (failed > 0 or problems > 0) and 1 or 0
end

return M
