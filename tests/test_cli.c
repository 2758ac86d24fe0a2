/* SPDX-License-Identifier: MIT */
#define _POSIX_C_SOURCE 200809L
/* The eddy command end to end: exit codes, one-line errors, the stats
 * contract (every line parses as JSON and carries the contract's fields),
 * --set, plan, check; the stock lua5.4 interpreter loading build/eddy.so; and
 * the README's C example built against the installed header and library. */
#include "test.h"

#include <eddy.h>

#include <signal.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

static const char *eddy(void)
{
	static char path[256];
	snprintf(path, sizeof path, "%s/eddy", test_build_dir());
	return path;
}

/* "eddy run" with this suite's output folder: a run's default, out/SCENE,
 * would be shared with (and locked against) other suites running at once. */
static const char *eddy_run(void)
{
	static char cmd[256];
	snprintf(cmd, sizeof cmd, "%s/eddy run --out %s/run", test_build_dir(), test_out_dir());
	return cmd;
}

static char *slurp(const char *path)
{
	FILE *f = fopen(path, "rb");
	if (!f)
		return NULL;
	fseek(f, 0, SEEK_END);
	long n = ftell(f);
	fseek(f, 0, SEEK_SET);
	char *s = malloc((size_t)n + 1);
	size_t got = fread(s, 1, (size_t)n, f);
	s[got] = '\0';
	fclose(f);
	return s;
}

/* ---- a strict little JSON reader: enough to validate a stats line ---- */

typedef struct json {
	const char *p;
	bool ok;
	char keys[64][32]; /* top-level keys, in order */
	int nkeys;
} json;

static void ws(json *j)
{
	while (*j->p == ' ' || *j->p == '\t' || *j->p == '\n' || *j->p == '\r')
		j->p++;
}

static void value(json *j, int depth);

static void string(json *j, char *out, size_t cap)
{
	size_t n = 0;
	if (*j->p != '"') {
		j->ok = false;
		return;
	}
	j->p++;
	while (*j->p && *j->p != '"') {
		if ((unsigned char)*j->p < 0x20) {
			j->ok = false;
			return;
		}
		if (*j->p == '\\') {
			j->p++;
			if (!strchr("\"\\/bfnrtu", *j->p)) {
				j->ok = false;
				return;
			}
		}
		if (out && n + 1 < cap)
			out[n++] = *j->p;
		j->p++;
	}
	if (*j->p != '"') {
		j->ok = false;
		return;
	}
	j->p++;
	if (out)
		out[n] = '\0';
}

static void value(json *j, int depth)
{
	ws(j);
	if (!j->ok)
		return;
	if (*j->p == '{' || *j->p == '[') {
		const char close = *j->p == '{' ? '}' : ']';
		const bool obj = close == '}';
		j->p++;
		ws(j);
		if (*j->p == close) {
			j->p++;
			return;
		}
		for (;;) {
			ws(j);
			if (obj) {
				char key[32];
				string(j, key, sizeof key);
				if (depth == 0 && j->nkeys < 64)
					snprintf(j->keys[j->nkeys++], 32, "%s", key);
				ws(j);
				if (*j->p != ':') {
					j->ok = false;
					return;
				}
				j->p++;
			}
			value(j, depth + 1);
			ws(j);
			if (!j->ok)
				return;
			if (*j->p == ',') {
				j->p++;
				continue;
			}
			if (*j->p == close) {
				j->p++;
				return;
			}
			j->ok = false;
			return;
		}
	} else if (*j->p == '"') {
		string(j, NULL, 0);
	} else if (strncmp(j->p, "true", 4) == 0 || strncmp(j->p, "null", 4) == 0) {
		j->p += 4;
	} else if (strncmp(j->p, "false", 5) == 0) {
		j->p += 5;
	} else {
		char *end;
		strtod(j->p, &end);
		const char c0 = j->p[0] == '-' ? j->p[1] : j->p[0];
		if (end == j->p || !(c0 >= '0' && c0 <= '9') || (j->p[0] == '0' && j->p[1] >= '0' && j->p[1] <= '9'))
			j->ok = false;
		j->p = end;
	}
}

static bool parse_line(const char *line, json *j)
{
	memset(j, 0, sizeof *j);
	j->p = line;
	j->ok = true;
	value(j, 0);
	ws(j);
	return j->ok && *j->p == '\0' && line[0] == '{';
}

static bool has_key(const json *j, const char *k)
{
	for (int i = 0; i < j->nkeys; ++i)
		if (strcmp(j->keys[i], k) == 0)
			return true;
	return false;
}

static void json_reader_rejects_bad_json(void)
{
	json j;
	CHECK(parse_line("{\"a\":1,\"b\":[1,2,{\"c\":null}],\"d\":\"x\\\"y\"}", &j));
	CHECK(j.nkeys == 3 && has_key(&j, "d"));
	CHECK(!parse_line("{\"a\":nan}", &j));
	CHECK(!parse_line("{\"a\":1,}", &j));
	CHECK(!parse_line("{\"a\":01}", &j));
	CHECK(!parse_line("{\"a\":1} x", &j));
}

static const char *const contract[] = {
	"frame",
	"time",
	"steps",
	"dt_min",
	"dt_max",
	"particles",
	"max_speed",
	"cfl",
	"density_err_avg",
	"density_err_max",
	"density_compression_avg",
	"volume",
	"leaked",
	"nonfinite",
	"solver",
	"iterations",
	"residual",
	"divergence",
	"wall_ms",
	"state_hash",
	"systems",
	NULL,
};

static void run_writes_stats_lines(void)
{
	char cmd[1024], out[8192];
	snprintf(cmd, sizeof cmd, "%s scenes/bounce.lua --frames 3 --stats %s/t_stats.jsonl --quiet", eddy_run(),
	         test_build_dir());
	CHECK(test_sh(cmd, out, sizeof out) == 0);
	CHECKF(out[0] == '\0', "--quiet printed: %s", out);
	char path[512];
	snprintf(path, sizeof path, "%s/t_stats.jsonl", test_build_dir());
	char *text = slurp(path);
	CHECK(text != NULL);
	if (!text)
		return;
	int lines = 0;
	for (char *line = strtok(text, "\n"); line; line = strtok(NULL, "\n")) {
		++lines;
		json j;
		CHECKF(parse_line(line, &j), "line %d is not JSON: %s", lines, line);
		for (int k = 0; contract[k]; ++k)
			CHECKF(has_key(&j, contract[k]), "line %d lacks '%s'", lines, contract[k]);
		CHECK(has_key(&j, "top")); /* the scene's on_frame field */
		CHECK(test_json_number(line, "frame") == lines);
		CHECK_NEAR(test_json_number(line, "time"), lines / 30.0, 1e-8);
		CHECK(test_json_number(line, "particles") == 10000);
		CHECK(test_json_number(line, "leaked") == 0);
		CHECK(test_json_number(line, "nonfinite") == 0);
		CHECK(strstr(line, "\"integrate\":") != NULL);
	}
	CHECK(lines == 3);
	free(text);
}

/* The energy fields of a stats line: WCSPH's sum takes its compression
 * energy, which is its own field; a pressure solve has none (null). */
static void stats_energy_fields(void)
{
	char cmd[1024], out[16384];
	snprintf(cmd, sizeof cmd,
	         "%s scenes/pour.lua --set method=wcsph --set render=false --duration 0.2 --stats - --quiet | tail -1",
	         eddy_run());
	CHECK(test_sh(cmd, out, sizeof out) == 0);
	const double ke = test_json_number(out, "kinetic_energy"), pe = test_json_number(out, "potential_energy"),
				 ce = test_json_number(out, "compression_energy"), e = test_json_number(out, "energy");
	CHECKF(ce > 0 && ke > 0 && pe > 0, "WCSPH energies: %s", out);
	/* the line prints 9 significant digits */
	CHECKF(fabs(e - (ke + pe + ce)) <= 1e-8 * (fabs(ke) + fabs(pe) + ce), "energy %g against %g + %g + %g", e, ke, pe,
	       ce);
	snprintf(cmd, sizeof cmd,
	         "%s scenes/pour.lua --set method=dfsph --set render=false --duration 0.1 --stats - --quiet | tail -1",
	         eddy_run());
	CHECK(test_sh(cmd, out, sizeof out) == 0);
	CHECKF(strstr(out, "\"compression_energy\":null") != NULL, "DFSPH: %s", out);
	CHECK_NEAR(test_json_number(out, "energy"),
	           test_json_number(out, "kinetic_energy") + test_json_number(out, "potential_energy"),
	           1e-8 * test_json_number(out, "potential_energy"));
}

/* Equal runs give equal state hashes, whatever the thread count. */
static void run_is_deterministic(void)
{
	char cmd[1024], a[16384], b[16384], c[16384];
	snprintf(cmd, sizeof cmd,
	         "%s scenes/bounce.lua --frames 4 --stats - --quiet | grep -o '\"state_hash\":\"[0-9a-f]*\"'", eddy_run());
	CHECK(test_sh(cmd, a, sizeof a) == 0);
	CHECK(test_sh(cmd, b, sizeof b) == 0);
	snprintf(cmd, sizeof cmd,
	         "%s scenes/bounce.lua --frames 4 --threads 2 --stats - --quiet | grep -o '\"state_hash\":\"[0-9a-f]*\"'",
	         eddy_run());
	CHECK(test_sh(cmd, c, sizeof c) == 0);
	CHECK(strlen(a) > 40);
	CHECK(strcmp(a, b) == 0);
	CHECK(strcmp(a, c) == 0);
}

static void set_changes_the_scene(void)
{
	char cmd[2048], out[16384];
	snprintf(cmd, sizeof cmd, "%s scenes/bounce.lua --frames 1 --set spacing=0.04 --stats - --quiet", eddy_run());
	CHECK(test_sh(cmd, out, sizeof out) == 0);
	CHECK(test_json_number(out, "particles") == 10 * 12 * 10); /* a 0.4 x 0.5 x 0.4 block at 0.04 m */
	snprintf(cmd, sizeof cmd, "%s scenes/bounce.lua --frames 1 --set spcing=0.04", eddy_run());
	CHECK(test_sh(cmd, out, sizeof out) == 2);
	CHECK_HAS(out, "eddy: --set spcing: scenes/bounce.lua has no parameter 'spcing'");
	snprintf(cmd, sizeof cmd, "%s scenes/bounce.lua --frames 1 --set spacing=-1", eddy_run());
	CHECK(test_sh(cmd, out, sizeof out) == 1);
	CHECK_HAS(out, "eddy: scenes/bounce.lua:");
	CHECK_HAS(out, "emit_box: 'spacing' must be > 0 (got -1)");
	CHECK(strchr(out, '\n') == out + strlen(out) - 1); /* one line */
}

/* Failures are exactly one line. */
static bool one_line(const char *out)
{
	size_t n = strlen(out);
	return n > 0 && strchr(out, '\n') == out + n - 1;
}

static void usage_and_errors(void)
{
	char cmd[1024], out[8192];
	snprintf(cmd, sizeof cmd, "%s --version", eddy());
	CHECK(test_sh(cmd, out, sizeof out) == 0);
	CHECK_HAS(out, "eddy " EDDY_VERSION_STRING);
	snprintf(cmd, sizeof cmd, "%s --help", eddy());
	CHECK(test_sh(cmd, out, sizeof out) == 0);
	CHECK_HAS(out, "usage: eddy <command> SCENE.lua");
	snprintf(cmd, sizeof cmd, "%s scenes/bounce.lua --frobnicate", eddy_run());
	CHECK(test_sh(cmd, out, sizeof out) == 2);
	CHECK_HAS(out, "eddy: unknown option '--frobnicate'");
	snprintf(cmd, sizeof cmd, "%s scenes/bounce.lua --frames many", eddy_run());
	CHECK(test_sh(cmd, out, sizeof out) == 2);
	CHECK_HAS(out, "--frames must be an integer");
	snprintf(cmd, sizeof cmd, "%s", eddy());
	CHECK(test_sh(cmd, out, sizeof out) == 2);
	CHECK_HAS(out, "eddy: no command");
	CHECK(one_line(out));
	snprintf(cmd, sizeof cmd, "%s fly scenes/bounce.lua", eddy());
	CHECK(test_sh(cmd, out, sizeof out) == 2);
	snprintf(cmd, sizeof cmd, "%s no/such/scene.lua", eddy_run());
	CHECK(test_sh(cmd, out, sizeof out) == 1);
	CHECK_HAS(out, "eddy: cannot read scene 'no/such/scene.lua'");
	/* a folder that cannot be made (its parent is a file) */
	snprintf(cmd, sizeof cmd, "%s scenes/bounce.lua --stats /dev/null/x/s.jsonl --frames 1", eddy_run());
	CHECK(test_sh(cmd, out, sizeof out) == 1);
	CHECK_HAS(out, "eddy: cannot write stats file '/dev/null/x/s.jsonl'");
	CHECK(one_line(out));
	/* --duration under one frame (bounce runs at 30 fps) would run 30x what it asks */
	snprintf(cmd, sizeof cmd, "%s run scenes/bounce.lua --duration 0.001 --quiet --out %s/t_dur", eddy(),
	         test_build_dir());
	CHECK(test_sh(cmd, out, sizeof out) == 2);
	CHECK_HAS(out, "eddy: --duration 0.001 s is shorter than one frame");
	CHECK(one_line(out));
	/* a duration of more frames than an int holds: refused, where it ran 0
	 * frames and exited 0 (the frame count overflowed) */
	snprintf(cmd, sizeof cmd, "%s run scenes/bounce.lua --duration 1e30 --quiet --out %s/t_dur", eddy(),
	         test_build_dir());
	CHECK(test_sh(cmd, out, sizeof out) == 2);
	CHECK_HAS(out, "eddy: --duration 1e+30 s is 3e+31 frames at 30 fps: a run may have at most 100000000 frames");
	CHECK(one_line(out));
	snprintf(cmd, sizeof cmd, "%s scenes/bounce.lua --frames 100000001", eddy_run());
	CHECK(test_sh(cmd, out, sizeof out) == 2);
	CHECK_HAS(out, "--frames must be an integer in [0, 100000000] (got '100000001')");
}

static void write_scene(const char *path, const char *src)
{
	FILE *f = fopen(path, "w");
	fputs(src, f);
	fclose(f);
}

static void bad_scenes_fail_with_one_line(void)
{
	char path[256], cmd[2048], out[8192];
	snprintf(path, sizeof path, "%s/t_bad.lua", test_build_dir());
	write_scene(
		path,
		"local eddy = require 'eddy'\nlocal w = eddy.world{}\n\nw:add(eddy.emit_box{ spacin = 0.01 })\nreturn w\n");
	snprintf(cmd, sizeof cmd, "%s %s", eddy_run(), path);
	CHECK(test_sh(cmd, out, sizeof out) == 1);
	char expect[600];
	snprintf(expect, sizeof expect, "eddy: %s:4: emit_box: unknown field 'spacin' (did you mean 'spacing'?", path);
	CHECK_HAS(out, expect);

	write_scene(path, "local eddy = require 'eddy'\nlocal w = eddy.world{}\n");
	CHECK(test_sh(cmd, out, sizeof out) == 1);
	CHECK_HAS(out, "the scene must return a world (got nil)");

	write_scene(path, "local eddy = require 'eddy'\nlocal w = eddy.world{\n");
	CHECK(test_sh(cmd, out, sizeof out) == 1);
	CHECK_HAS(out, "t_bad.lua:");

	/* a scene's duration of more frames than a run may have */
	write_scene(path, "local eddy = require 'eddy'\nreturn eddy.world{ duration = 1e30 }\n");
	snprintf(cmd, sizeof cmd, "%s %s --quiet --out %s/t_dur", eddy_run(), path, test_build_dir());
	CHECK(test_sh(cmd, out, sizeof out) == 1);
	CHECK_HAS(out, "t_bad.lua: world 'duration' 1e+30 s is 3e+31 frames at 30 fps");
	CHECK(one_line(out));

	/* no tank: the block falls out of the domain and the run says where */
	write_scene(path, "local eddy = require 'eddy'\nlocal w = eddy.world{ fps = 10 }\n"
	                  "w:add(eddy.emit_box{ min = {0.4, 0.05, 0.4}, max = {0.5, 0.15, 0.5} })\n"
	                  "w:add(eddy.gravity{})\nw:add(eddy.integrate{})\nreturn w\n");
	snprintf(cmd, sizeof cmd, "%s %s --frames 10 --stats %s/t_bad.jsonl", eddy_run(), path, test_build_dir());
	CHECK(test_sh(cmd, out, sizeof out) == 1);
	CHECK_HAS(out, "eddy: particle ");
	CHECK_HAS(out, "left the domain at step");
	CHECK(strchr(out, '\n') == out + strlen(out) - 1);

	/* a tank the size of the world, rocked: its floor turns past the
	 * world's, the water follows it out, and the hint names the tank */
	write_scene(path, "local eddy = require 'eddy'\n"
	                  "local w = eddy.world{ bounds = {{0, 0, 0}, {0.4, 0.3, 0.2}}, fps = 30 }\n"
	                  "w:add(eddy.emit_box{ min = {0, 0, 0}, max = {0.4, 0.1, 0.2}, spacing = 0.01 })\n"
	                  "w:add(eddy.gravity{})\nw:add(eddy.integrate{})\n"
	                  "local tank = w:add(eddy.collide_box{ min = {0, 0, 0}, max = {0.4, 0.3, 0.2}, inside = true })\n"
	                  "w:on_frame(function() tank:set_rotation({0, 0, 8}) end)\nreturn w\n");
	snprintf(cmd, sizeof cmd, "%s %s --frames 3 --quiet --out %s/t_bad", eddy_run(), path, test_build_dir());
	CHECK(test_sh(cmd, out, sizeof out) == 1);
	CHECK_HAS(out, "left the domain at step");
	CHECK_HAS(out, "collide_box is moved or turned: the bounds must hold its whole motion");
	CHECK(one_line(out));

	/* an on_frame field may not shadow a contract field */
	write_scene(path, "local eddy = require 'eddy'\nlocal w = eddy.world{}\n"
	                  "w:on_frame(function() return { time = 1 } end)\nreturn w\n");
	snprintf(cmd, sizeof cmd, "%s %s --frames 1 --stats -", eddy_run(), path);
	CHECK(test_sh(cmd, out, sizeof out) == 1);
	CHECK_HAS(out, "on_frame returned 'time', which is a stats field of eddy");
}

/* Lines in the file at path (-1: no file). */
static int count_lines(const char *path)
{
	char *text = slurp(path);
	if (!text)
		return -1;
	int n = 0;
	for (const char *c = text; *c; ++c)
		n += *c == '\n';
	free(text);
	return n;
}

/* A stats file that cannot be written fails the run (exit 1, one line
 * naming it); a stats reader that goes away (| head -1) stops it quietly
 * with status 0 instead of SIGPIPE's silent 141. */
static void stats_write_errors_stop_the_run(void)
{
	char cmd[2048], out[8192];
	snprintf(cmd, sizeof cmd, "%s scenes/bounce.lua --frames 2 --quiet --stats /dev/full", eddy_run());
	CHECK(test_sh(cmd, out, sizeof out) == 1);
	CHECK_HAS(out, "eddy: cannot write stats file '/dev/full': No space left on device");
	CHECK(one_line(out));
	const char *b = test_build_dir();
	snprintf(cmd, sizeof cmd,
	         "(%s scenes/bounce.lua --frames 300 --quiet --stats - 2>%s/t_pipe.err; "
	         "echo $? >%s/t_pipe.rc) | head -1 >/dev/null; cat %s/t_pipe.rc %s/t_pipe.err",
	         eddy_run(), b, b, b, b);
	CHECK(test_sh(cmd, out, sizeof out) == 0);
	CHECKF(strcmp(out, "0\n") == 0, "status and stderr of the run: %s", out);
	/* the same for plan's stdout; a full disk is an error there too */
	snprintf(cmd, sizeof cmd, "{ %s plan scenes/bounce.lua >/dev/full; } 2>&1", eddy());
	CHECK(test_sh(cmd, out, sizeof out) == 1);
	CHECK_HAS(out, "eddy: cannot write to standard output: No space left on device");
	CHECK(one_line(out));
}

static void stats_creates_its_folders(void)
{
	char cmd[2048], out[8192], path[512];
	snprintf(cmd, sizeof cmd, "rm -rf %s/t_deep", test_build_dir());
	CHECK(test_sh(cmd, out, sizeof out) == 0);
	snprintf(path, sizeof path, "%s/t_deep/a/b/s.jsonl", test_build_dir());
	snprintf(cmd, sizeof cmd, "%s run scenes/bounce.lua --frames 2 --quiet --out %s/t_deep/out --stats %s", eddy(),
	         test_build_dir(), path);
	CHECKF(test_sh(cmd, out, sizeof out) == 0, "%s", out);
	CHECK(count_lines(path) == 2);
}

static void set_is_given_once_per_key(void)
{
	char cmd[1024], out[4096];
	snprintf(cmd, sizeof cmd, "%s scenes/bounce.lua --frames 1 --set spacing=0.04 --set spacing=0.05", eddy_run());
	CHECK(test_sh(cmd, out, sizeof out) == 2);
	CHECK_HAS(out, "eddy: --set spacing given twice");
	CHECK(one_line(out));
	/* distinct keys, one a prefix of the other, are fine */
	snprintf(cmd, sizeof cmd, "%s check scenes/bounce.lua --set spacing=0.04 --set spacingx=1", eddy());
	CHECK(test_sh(cmd, out, sizeof out) == 2);
	CHECK_HAS(out, "--set spacingx: scenes/bounce.lua has no parameter 'spacingx'");
}

/* getopt_long: --opt V and --opt=V alike; one-line usage errors; per-command
 * help on stdout with status 0. */
static void options_take_values_either_way(void)
{
	char cmd[1024], a[16384], b[16384];
	snprintf(cmd, sizeof cmd,
	         "%s scenes/bounce.lua --frames 2 --stats - --quiet --set spacing=0.04 "
	         "| grep -o '\"state_hash\":\"[0-9a-f]*\"'",
	         eddy_run());
	CHECK(test_sh(cmd, a, sizeof a) == 0);
	snprintf(cmd, sizeof cmd,
	         "%s --frames=2 --stats=- --quiet --set=spacing=0.04 scenes/bounce.lua "
	         "| grep -o '\"state_hash\":\"[0-9a-f]*\"'",
	         eddy_run());
	CHECK(test_sh(cmd, b, sizeof b) == 0);
	CHECK(strlen(a) > 40 && strcmp(a, b) == 0);
	static const struct {
		const char *args, *expect;
	} bad[] = {
		{"run scenes/bounce.lua --frames", "eddy: --frames needs a value"},
		{"run scenes/bounce.lua --stats", "eddy: --stats needs a value"},
		{"run scenes/bounce.lua --quiet=yes", "eddy: --quiet takes no value"},
		{"run scenes/bounce.lua --frames=x", "eddy: --frames must be an integer"},
		{"run scenes/bounce.lua --frobnicate=3", "eddy: unknown option '--frobnicate'"},
		{"run scenes/bounce.lua -z", "eddy: unknown option '-z'"},
		{"run scenes/bounce.lua --keep-checkpoints=-1", "eddy: --keep-checkpoints must be an integer >= 0"},
		{"run scenes/bounce.lua --export obj", "eddy: --export must be ply, vtk or vtp"},
		{"study --out", "eddy: --out needs a value"},
		{"study --frobnicate", "eddy: study: unknown option '--frobnicate'"},
		{NULL, NULL},
	};
	for (int i = 0; bad[i].args; ++i) {
		snprintf(cmd, sizeof cmd, "%s %s", eddy(), bad[i].args);
		CHECKF(test_sh(cmd, a, sizeof a) == 2, "%s", bad[i].args);
		CHECK_HAS(a, bad[i].expect);
		CHECKF(one_line(a), "%s: %s", bad[i].args, a);
	}
	static const struct {
		const char *command, *expect;
	} help[] = {
		{"run", "usage: eddy run SCENE.lua"},
		{"plan", "usage: eddy plan SCENE.lua"},
		{"check", "usage: eddy check SCENE.lua"},
		{"study", "usage: eddy study STUDY.lua"},
		{NULL, NULL},
	};
	for (int i = 0; help[i].command; ++i) {
		snprintf(cmd, sizeof cmd, "%s %s --help 2>/dev/null", eddy(), help[i].command);
		CHECK(test_sh(cmd, a, sizeof a) == 0);
		CHECK_HAS(a, help[i].expect);
		CHECK_HAS(a, "--help");
	}
	snprintf(cmd, sizeof cmd, "%s run --help", eddy());
	CHECK(test_sh(cmd, a, sizeof a) == 0);
	CHECK_HAS(a, "--keep-checkpoints N");
	CHECK_HAS(a, "--export FMT");
}

/* A second run on the same output folder is refused at once, naming the
 * first one's pid. */
static void output_folder_is_locked(void)
{
	char cmd[2048], out[4096], outdir[512], lock[600], errpath[600];
	snprintf(outdir, sizeof outdir, "%s/t_lock", test_build_dir());
	snprintf(lock, sizeof lock, "%s/.eddy.lock", outdir);
	snprintf(errpath, sizeof errpath, "%s/t_lock.err", test_build_dir());
	snprintf(cmd, sizeof cmd, "rm -rf %s", outdir);
	CHECK(system(cmd) == 0);
	pid_t pid = fork();
	if (pid == 0) {
		if (!freopen(errpath, "w", stderr))
			_exit(98);
		execl(eddy(), eddy(), "run", "scenes/bounce.lua", "--frames", "100000", "--set", "spacing=0.008", "--out",
		      outdir, "--quiet", (char *)NULL);
		_exit(99);
	}
	/* the lock file holds the pid once the lock is taken (a sanitizer
	 * build is slow to start) */
	char want[32];
	snprintf(want, sizeof want, "%ld\n", (long)pid);
	bool locked = false;
	for (int i = 0; i < 600 && !locked; ++i) {
		struct timespec ts = {0, 50 * 1000 * 1000};
		nanosleep(&ts, NULL);
		char *text = slurp(lock);
		locked = text && strcmp(text, want) == 0;
		free(text);
	}
	CHECK(locked);
	snprintf(cmd, sizeof cmd, "%s run scenes/bounce.lua --frames 1 --quiet --out %s", eddy(), outdir);
	CHECK(test_sh(cmd, out, sizeof out) == 1);
	char expect[700];
	snprintf(expect, sizeof expect, "eddy: %s is in use by another run (pid %ld)", outdir, (long)pid);
	CHECK_HAS(out, expect);
	CHECK(one_line(out));
	kill(pid, SIGKILL);
	int st;
	waitpid(pid, &st, 0);
	/* the lock went with the process */
	CHECK(test_sh(cmd, out, sizeof out) == 0);
}

/* --resume takes the run's --out; a resume with nothing left to run and one
 * whose stats file has lost lines are refused, the stats file untouched. */
static void resume_checks_frames_and_stats(void)
{
	const char *b = test_build_dir();
	char cmd[2048], out[8192], stats[512], shorter[512];
	snprintf(stats, sizeof stats, "%s/t_res/s.jsonl", b);
	snprintf(shorter, sizeof shorter, "%s/t_res/short.jsonl", b);
	snprintf(cmd, sizeof cmd,
	         "rm -rf %s/t_res && %s run scenes/bounce.lua --frames 10 --checkpoint-every 5 --quiet "
	         "--out %s/t_res --stats %s && head -3 %s > %s",
	         b, eddy(), b, stats, stats, shorter);
	CHECK(test_sh(cmd, out, sizeof out) == 0);
	CHECK(count_lines(stats) == 10);
	snprintf(cmd, sizeof cmd, "%s run scenes/bounce.lua --frames 8 --quiet --out %s/t_res --resume %s/t_res --stats %s",
	         eddy(), b, b, stats);
	CHECK(test_sh(cmd, out, sizeof out) == 2);
	CHECK_HAS(out, "eddy: --resume: the checkpoint is at frame 10 and the run ends at frame 8: nothing left to run");
	CHECK(one_line(out));
	CHECK(count_lines(stats) == 10);
	snprintf(cmd, sizeof cmd,
	         "%s run scenes/bounce.lua --frames 12 --quiet --out %s/t_res --resume %s/t_res --stats %s", eddy(), b, b,
	         shorter);
	CHECK(test_sh(cmd, out, sizeof out) == 1);
	CHECK_HAS(out, "short.jsonl' has 3 lines for the 10 frames up to the checkpoint");
	CHECK(one_line(out));
	CHECK(count_lines(shorter) == 3);
	/* the output folder itself, not its checkpoints/ */
	snprintf(cmd, sizeof cmd,
	         "%s run scenes/bounce.lua --frames 12 --quiet --out %s/t_res --resume %s/t_res --stats %s", eddy(), b, b,
	         stats);
	CHECK(test_sh(cmd, out, sizeof out) == 0);
	CHECK(count_lines(stats) == 12);
	char *text = slurp(stats);
	int line = 0;
	for (char *l = text ? strtok(text, "\n") : NULL; l; l = strtok(NULL, "\n"))
		CHECKF(test_json_number(l, "frame") == ++line, "line %d: %s", line, l); /* frames 1..12, once each */
	free(text);
}

/* At most --keep-checkpoints remain (default 3, 0 all); temp files a crash
 * left are removed when a run starts. */
static void checkpoints_are_pruned_and_temps_removed(void)
{
	const char *b = test_build_dir();
	char cmd[2048], out[8192];
	snprintf(cmd, sizeof cmd,
	         "rm -rf %s/t_keep && mkdir -p %s/t_keep/checkpoints && "
	         "echo junk > %s/t_keep/checkpoints/frame-000003.eddy.tmp && "
	         "echo junk > %s/t_keep/.frame_0004.png.999-1.tmp && "
	         "%s run scenes/bounce.lua --frames 10 --checkpoint-every 2 --quiet --out %s/t_keep && "
	         "ls %s/t_keep/checkpoints && ls -A %s/t_keep | grep -c tmp",
	         b, b, b, b, eddy(), b, b, b);
	test_sh(cmd, out, sizeof out);
	CHECKF(strcmp(out, "frame-000006.eddy\nframe-000008.eddy\nframe-000010.eddy\n0\n") == 0, "%s", out);
	snprintf(cmd, sizeof cmd,
	         "rm -rf %s/t_keep && %s run scenes/bounce.lua --frames 10 --checkpoint-every 2 --quiet "
	         "--keep-checkpoints 0 --out %s/t_keep && ls %s/t_keep/checkpoints | wc -l",
	         b, eddy(), b, b);
	CHECK(test_sh(cmd, out, sizeof out) == 0);
	CHECK(atoi(out) == 5);
	snprintf(cmd, sizeof cmd,
	         "echo junk > %s/t_keep/checkpoints/frame-000011.eddy.tmp && "
	         "%s run scenes/bounce.lua --frames 12 --checkpoint-every 2 --quiet --keep-checkpoints=1 --out %s/t_keep "
	         "--resume %s/t_keep && ls %s/t_keep/checkpoints",
	         b, eddy(), b, b, b);
	CHECK(test_sh(cmd, out, sizeof out) == 0);
	CHECKF(strcmp(out, "frame-000012.eddy\n") == 0, "%s", out);
}

/* Scenes are Lua text: a precompiled or corrupted binary chunk is refused in
 * one line naming the file. */
static void binary_scenes_are_refused(void)
{
	const char *b = test_build_dir();
	char cmd[2048], out[8192], expect[600];
	snprintf(cmd, sizeof cmd, "luac5.4 -o %s/t_scene.luac scenes/bounce.lua && %s %s/t_scene.luac --frames 1", b,
	         eddy_run(), b);
	CHECK(test_sh(cmd, out, sizeof out) == 1);
	snprintf(expect, sizeof expect, "eddy: %s/t_scene.luac: a precompiled (binary) chunk", b);
	CHECK_HAS(out, expect);
	CHECK(one_line(out));
	char path[512];
	snprintf(path, sizeof path, "%s/t_bad.luac", b);
	FILE *f = fopen(path, "wb");
	fwrite("\x1bLua\x54\x00\x19\x93\r\n\x1a\nrubbish\xff\xfe", 1, 21, f);
	fclose(f);
	snprintf(cmd, sizeof cmd, "%s plan %s", eddy(), path);
	CHECK(test_sh(cmd, out, sizeof out) == 1);
	CHECK_HAS(out, "t_bad.luac: a precompiled (binary) chunk");
	CHECK(one_line(out));
}

/* --export adds a particle export into OUT without editing the scene. */
static void export_adds_particle_files(void)
{
	const char *b = test_build_dir();
	char cmd[2048], out[8192];
	snprintf(
		cmd, sizeof cmd,
		"rm -rf %s/t_exp && %s run scenes/bounce.lua --frames 2 --quiet --out %s/t_exp "
		"--export ply && ls %s/t_exp | grep -c '^particles_000[12]\\.ply$' && head -c 3 %s/t_exp/particles_0002.ply",
		b, eddy(), b, b, b);
	CHECK(test_sh(cmd, out, sizeof out) == 0);
	CHECK(strcmp(out, "2\nply") == 0);
	/* vtp: a file a frame and the collection listing both */
	snprintf(cmd, sizeof cmd,
	         "rm -rf %s/t_exp && %s run scenes/bounce.lua --frames=2 --quiet --out %s/t_exp "
	         "--export=vtp && ls %s/t_exp | grep -c '^particles_000[12]\\.vtp$' && grep -c '<DataSet ' "
	         "%s/t_exp/particles.pvd",
	         b, eddy(), b, b, b);
	CHECK(test_sh(cmd, out, sizeof out) == 0);
	CHECKF(strcmp(out, "2\n2\n") == 0, "%s", out);
}

/* --safe: the scene runs without os.execute; the failure is one line with
 * the scene's line. */
static void safe_mode_refuses_os_execute(void)
{
	char path[256], cmd[1024], out[4096];
	snprintf(path, sizeof path, "%s/t_safe.lua", test_build_dir());
	write_scene(path, "local eddy = require 'eddy'\nlocal w = eddy.world{}\nos.execute('true')\nreturn w\n");
	snprintf(cmd, sizeof cmd, "%s check %s", eddy(), path);
	CHECK(test_sh(cmd, out, sizeof out) == 0);
	snprintf(cmd, sizeof cmd, "%s check --safe %s", eddy(), path);
	int rc = test_sh(cmd, out, sizeof out);
	CHECK(rc == 1);
	char expect[300];
	snprintf(expect, sizeof expect, "eddy: %s:3:", path);
	CHECK_HAS(out, expect);
	CHECK(one_line(out));
}

/* Every option the help texts name is in the manual (docs/eddy.1). */
static void manual_covers_every_option(void)
{
	char *man = slurp("docs/eddy.1");
	CHECK(man != NULL);
	if (!man)
		return;
	static const char *const helps[] = {"--help", "run --help", "plan --help", "check --help", "study --help", NULL};
	for (int h = 0; helps[h]; ++h) {
		char cmd[512], out[16384];
		snprintf(cmd, sizeof cmd, "%s %s", eddy(), helps[h]);
		CHECK(test_sh(cmd, out, sizeof out) == 0);
		for (const char *p = strstr(out, "--"); p; p = strstr(p + 2, "--")) {
			size_t n = 2;
			while ((p[n] >= 'a' && p[n] <= 'z') || p[n] == '-')
				++n;
			char name[64], troff[80];
			snprintf(name, sizeof name, "%.*s", (int)n, p);
			/* troff writes each '-' as "\-" */
			size_t k = 0;
			for (size_t i = 0; name[i] && k + 3 < sizeof troff; ++i) {
				if (name[i] == '-')
					troff[k++] = '\\';
				troff[k++] = name[i];
			}
			troff[k] = '\0';
			CHECKF(n <= 2 || strstr(man, troff), "eddy %s names %s, docs/eddy.1 does not", helps[h], name);
		}
	}
	free(man);
}

static void plan_and_check(void)
{
	char cmd[2048], out[16384];
	snprintf(cmd, sizeof cmd, "%s plan scenes/bounce.lua", eddy());
	CHECK(test_sh(cmd, out, sizeof out) == 0);
	CHECK_HAS(out, "pipeline: 8 systems"); /* bounce renders: render_points is the 8th */
	CHECK_HAS(out, "3  integrate");
	CHECK_HAS(out, "10000 more from emitters; 36 bytes per particle");
	CHECK_HAS(out, "not allocated: density pressure");
	snprintf(cmd, sizeof cmd, "%s plan scenes/bounce.lua --dot", eddy());
	CHECK(test_sh(cmd, out, sizeof out) == 0);
	CHECK(strncmp(out, "digraph eddy {", 14) == 0);
	CHECK_HAS(out, "s1 -> s2 [label=\"ax ay az\"]");
	snprintf(cmd, sizeof cmd, "%s check scenes/bounce.lua", eddy());
	CHECK(test_sh(cmd, out, sizeof out) == 0);
	CHECK_HAS(out, "memory: 10000 particles x 36 bytes");
	CHECK_HAS(out, "time step:");
	/* a block started inside the sphere is reported */
	char path[256];
	snprintf(path, sizeof path, "%s/t_check.lua", test_build_dir());
	write_scene(path, "local eddy = require 'eddy'\nlocal w = eddy.world{}\n"
	                  "w:add(eddy.emit_box{ min = {0.4,0.4,0.4}, max = {0.6,0.6,0.6}, spacing = 0.05 })\n"
	                  "w:add(eddy.collide_sphere{ center = {0.5,0.5,0.5}, radius = 0.08 })\nreturn w\n");
	snprintf(cmd, sizeof cmd, "%s check %s", eddy(), path);
	CHECK(test_sh(cmd, out, sizeof out) == 0);
	CHECK_HAS(out, "warning  emit_box: 8 of 64 particles start inside collide_sphere");
}

static void stock_lua_requires_the_module(void)
{
	char cmd[1024], out[4096];
	if (test_sh("command -v lua5.4", out, sizeof out) != 0) {
		test_fail(__FILE__, __LINE__, "lua5.4 is not installed (scripts/deps.sh installs it)");
		return;
	}
	snprintf(cmd, sizeof cmd,
	         "lua5.4 -e 'package.cpath = \"%s/?.so;\" .. package.cpath; local eddy = require \"eddy\";"
	         " local w = eddy.world{}; w:add(eddy.emit_box{}); w:add(eddy.gravity{}); w:add(eddy.integrate{});"
	         " w:add(eddy.collide_box{}); w:advance(0.5); print(eddy.version, w:count(), w:channel(\"y\")[1] < 0.01)'",
	         test_build_dir());
#if defined(__SANITIZE_ADDRESS__)
	/* the module is built with ASan; the stock interpreter is not */
	setenv("LD_PRELOAD", "libasan.so.8", 1);
	setenv("ASAN_OPTIONS", "detect_leaks=0", 1);
#endif
	int rc = test_sh(cmd, out, sizeof out);
#if defined(__SANITIZE_ADDRESS__)
	unsetenv("LD_PRELOAD");
#endif
	CHECKF(rc == 0, "lua5.4 exited %d: %s", rc, out);
	CHECK_HAS(out, EDDY_VERSION_STRING "\t1000\ttrue");
}

static void readme_c_example_builds_and_runs(void)
{
	char cmd[2048], out[16384];
	snprintf(cmd, sizeof cmd, "sh tests/readme_example.sh %s", test_build_dir());
#if defined(__SANITIZE_ADDRESS__)
	setenv("EDDY_EXAMPLE_CFLAGS", "-fsanitize=address,undefined", 1);
#endif
	int rc = test_sh(cmd, out, sizeof out);
	CHECKF(rc == 0, "readme example exited %d: %s", rc, out);
	CHECK_HAS(out, "particles: 1000");
	CHECK_HAS(out, "lowest particle above the floor: yes");
}

void suite_cli(void)
{
	RUN(json_reader_rejects_bad_json);
	RUN(run_writes_stats_lines);
	RUN(stats_energy_fields);
	RUN(run_is_deterministic);
	RUN(set_changes_the_scene);
	RUN(usage_and_errors);
	RUN(bad_scenes_fail_with_one_line);
	RUN(plan_and_check);
	RUN(stats_write_errors_stop_the_run);
	RUN(stats_creates_its_folders);
	RUN(set_is_given_once_per_key);
	RUN(options_take_values_either_way);
	RUN(output_folder_is_locked);
	RUN(resume_checks_frames_and_stats);
	RUN(checkpoints_are_pruned_and_temps_removed);
	RUN(binary_scenes_are_refused);
	RUN(export_adds_particle_files);
	RUN(safe_mode_refuses_os_execute);
	RUN(manual_covers_every_option);
	RUN(stock_lua_requires_the_module);
	RUN(readme_c_example_builds_and_runs);
}
