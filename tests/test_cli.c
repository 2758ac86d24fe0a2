#define _POSIX_C_SOURCE 200809L
/* The eddy command end to end: exit codes, one-line errors, the stats
 * contract (every line parses as JSON and carries the contract's fields),
 * --set, plan, check; the stock lua5.4 interpreter loading build/eddy.so; and
 * the README's C example built against the installed header and library. */
#include "test.h"

#include <stdlib.h>
#include <string.h>
#include <sys/wait.h>
#include <unistd.h>

static const char *eddy(void)
{
	static char path[256];
	snprintf(path, sizeof path, "%s/eddy", test_build_dir());
	return path;
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

/* The value text after "key": in line (for simple fields). */
static double field_num(const char *line, const char *key)
{
	char pat[64];
	snprintf(pat, sizeof pat, "\"%s\":", key);
	const char *p = strstr(line, pat);
	return p ? strtod(p + strlen(pat), NULL) : NAN;
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
	"frame", "time", "steps", "dt_min", "dt_max", "particles", "max_speed", "cfl", "density_err_avg",
	"density_err_max", "density_compression_avg", "volume", "leaked", "nonfinite", "solver", "iterations", "residual", "divergence",
	"wall_ms", "state_hash", "systems", NULL,
};

static void run_writes_stats_lines(void)
{
	char cmd[1024], out[8192];
	snprintf(cmd, sizeof cmd, "%s run scenes/bounce.lua --frames 3 --stats %s/t_stats.jsonl --quiet", eddy(),
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
		CHECK(field_num(line, "frame") == lines);
		CHECK_NEAR(field_num(line, "time"), lines / 30.0, 1e-8);
		CHECK(field_num(line, "particles") == 10000);
		CHECK(field_num(line, "leaked") == 0);
		CHECK(field_num(line, "nonfinite") == 0);
		CHECK(strstr(line, "\"integrate\":") != NULL);
	}
	CHECK(lines == 3);
	free(text);
}

/* Equal runs give equal state hashes, whatever the thread count. */
static void run_is_deterministic(void)
{
	char cmd[1024], a[16384], b[16384], c[16384];
	snprintf(cmd, sizeof cmd, "%s run scenes/bounce.lua --frames 4 --stats - --quiet | grep -o '\"state_hash\":\"[0-9a-f]*\"'", eddy());
	CHECK(test_sh(cmd, a, sizeof a) == 0);
	CHECK(test_sh(cmd, b, sizeof b) == 0);
	snprintf(cmd, sizeof cmd, "%s run scenes/bounce.lua --frames 4 --threads 2 --stats - --quiet | grep -o '\"state_hash\":\"[0-9a-f]*\"'", eddy());
	CHECK(test_sh(cmd, c, sizeof c) == 0);
	CHECK(strlen(a) > 40);
	CHECK(strcmp(a, b) == 0);
	CHECK(strcmp(a, c) == 0);
}

static void set_changes_the_scene(void)
{
	char cmd[2048], out[16384];
	snprintf(cmd, sizeof cmd, "%s run scenes/bounce.lua --frames 1 --set spacing=0.04 --stats - --quiet", eddy());
	CHECK(test_sh(cmd, out, sizeof out) == 0);
	CHECK(field_num(out, "particles") == 10 * 12 * 10); /* a 0.4 x 0.5 x 0.4 block at 0.04 m */
	snprintf(cmd, sizeof cmd, "%s run scenes/bounce.lua --frames 1 --set spcing=0.04", eddy());
	CHECK(test_sh(cmd, out, sizeof out) == 2);
	CHECK_HAS(out, "eddy: --set spcing: scenes/bounce.lua has no parameter 'spcing'");
	snprintf(cmd, sizeof cmd, "%s run scenes/bounce.lua --frames 1 --set spacing=-1", eddy());
	CHECK(test_sh(cmd, out, sizeof out) == 1);
	CHECK_HAS(out, "eddy: scenes/bounce.lua:");
	CHECK_HAS(out, "emit_box: 'spacing' must be > 0 (got -1)");
	CHECK(strchr(out, '\n') == out + strlen(out) - 1); /* one line */
}

static void usage_and_errors(void)
{
	char cmd[1024], out[8192];
	snprintf(cmd, sizeof cmd, "%s --version", eddy());
	CHECK(test_sh(cmd, out, sizeof out) == 0);
	CHECK_HAS(out, "eddy 0.1.0");
	snprintf(cmd, sizeof cmd, "%s --help", eddy());
	CHECK(test_sh(cmd, out, sizeof out) == 0);
	CHECK_HAS(out, "usage: eddy <command> SCENE.lua");
	snprintf(cmd, sizeof cmd, "%s run scenes/bounce.lua --frobnicate", eddy());
	CHECK(test_sh(cmd, out, sizeof out) == 2);
	CHECK_HAS(out, "eddy: unknown option '--frobnicate'");
	snprintf(cmd, sizeof cmd, "%s run scenes/bounce.lua --frames many", eddy());
	CHECK(test_sh(cmd, out, sizeof out) == 2);
	CHECK_HAS(out, "--frames must be an integer");
	snprintf(cmd, sizeof cmd, "%s fly scenes/bounce.lua", eddy());
	CHECK(test_sh(cmd, out, sizeof out) == 2);
	snprintf(cmd, sizeof cmd, "%s run no/such/scene.lua", eddy());
	CHECK(test_sh(cmd, out, sizeof out) == 1);
	CHECK_HAS(out, "eddy: cannot read scene 'no/such/scene.lua'");
	snprintf(cmd, sizeof cmd, "%s run scenes/bounce.lua --stats /no/such/dir/s.jsonl --frames 1", eddy());
	CHECK(test_sh(cmd, out, sizeof out) == 1);
	CHECK_HAS(out, "eddy: cannot write stats file '/no/such/dir/s.jsonl'");
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
	write_scene(path, "local eddy = require 'eddy'\nlocal w = eddy.world{}\n\nw:add(eddy.emit_box{ spacin = 0.01 })\nreturn w\n");
	snprintf(cmd, sizeof cmd, "%s run %s", eddy(), path);
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

	/* no tank: the block falls out of the domain and the run says where */
	write_scene(path, "local eddy = require 'eddy'\nlocal w = eddy.world{ fps = 10 }\n"
	                  "w:add(eddy.emit_box{ min = {0.4, 0.05, 0.4}, max = {0.5, 0.15, 0.5} })\n"
	                  "w:add(eddy.gravity{})\nw:add(eddy.integrate{})\nreturn w\n");
	snprintf(cmd, sizeof cmd, "%s run %s --frames 10 --stats %s/t_bad.jsonl", eddy(), path, test_build_dir());
	CHECK(test_sh(cmd, out, sizeof out) == 1);
	CHECK_HAS(out, "eddy: particle ");
	CHECK_HAS(out, "left the domain at step");
	CHECK(strchr(out, '\n') == out + strlen(out) - 1);

	/* an on_frame field may not shadow a contract field */
	write_scene(path, "local eddy = require 'eddy'\nlocal w = eddy.world{}\n"
	                  "w:on_frame(function() return { time = 1 } end)\nreturn w\n");
	snprintf(cmd, sizeof cmd, "%s run %s --frames 1 --stats -", eddy(), path);
	CHECK(test_sh(cmd, out, sizeof out) == 1);
	CHECK_HAS(out, "on_frame returned 'time', which is a stats field of eddy");
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
	CHECK_HAS(out, "0.1.0\t1000\ttrue");
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
	RUN(run_is_deterministic);
	RUN(set_changes_the_scene);
	RUN(usage_and_errors);
	RUN(bad_scenes_fail_with_one_line);
	RUN(plan_and_check);
	RUN(stock_lua_requires_the_module);
	RUN(readme_c_example_builds_and_runs);
}
