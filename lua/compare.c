/* SPDX-License-Identifier: MIT */
/* `eddy compare SCENE.lua [--methods a,b,...] [--set K=V ...] [--out DIR]
 * [--quick] [--field NAME] [--safe] [--threads N]`: one scene, several methods, side by side.
 *
 * The driver (lua/eddy/compare.lua) runs the scene once per method as a child
 * `eddy run` (this very binary), one after another, and writes the tables,
 * charts, side-by-side frames and video. C adds what Lua cannot do: the child
 * process with its wall time and peak memory (wait4, as lua/study.c does for
 * eddy study), a folder listing, and the panels (eddy_compose_panels,
 * render/compose.c). Usage errors are checked here, before anything runs. */
#define _POSIX_C_SOURCE 200809L
#define _DEFAULT_SOURCE /* wait4, DIR, siginfo_t */
#define _GNU_SOURCE     /* getopt_long */
#include "compare.h"
#include "spawn.h"

#include <lauxlib.h>
#include <lualib.h>

#include <dirent.h>
#include <errno.h>
#include <fcntl.h>
#include <signal.h>
#include <stdarg.h>
#include <getopt.h>
#include <stdbool.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <sys/time.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include "eddy.h"

static const char compare_usage[] =
	"usage: eddy compare SCENE.lua [--methods M1,M2,...] [--set K=V ...] [--out DIR]\n"
	"                    [--quick] [--field NAME] [--safe] [--threads N]\n"
	"\n"
	"Runs the scene once per method, one after another, each as a child process\n"
	"  eddy run SCENE --set method=M [--set K=V ...] --out DIR/runs/M\n"
	"           --stats DIR/runs/M/stats.jsonl --quiet [--frames 6] [--safe] [--threads N]\n"
	"(the scene reads the method with eddy.param(\"method\", ...)), and writes into\n"
	"DIR (default out/compare_<scene>):\n"
	"  frame_NNNN.png     the methods' frames side by side, each panel stamped with\n"
	"                     the method, the simulated time and the ms of that frame\n"
	"  compare.mp4        those frames as a video (when ffmpeg is on PATH)\n"
	"  compare.csv        one row per method: status, wall time, frames, steps, time\n"
	"                     step, peak memory, particles, ms per system, and each\n"
	"                     measurement of the stats at the end and at its worst\n"
	"  compare.md         the same as Markdown tables\n"
	"  compare_FIELD.png  the field against simulated time, one line per method\n"
	"  compare_cost.png   wall time per simulated second, per method (gnuplot)\n"
	"\n"
	"options:\n"
	"  --methods LIST  methods, comma-separated (default wcsph,dfsph,flip); names are\n"
	"                  letters, digits, '_' and '-'\n"
	"  --set K=V       a scene parameter for every run; repeatable, once per K\n"
	"                  (not method: that is --methods)\n"
	"  --out DIR       output folder\n"
	"  --quick         a reduced run: 6 frames each (--frames 6); the scene keeps its\n"
	"                  resolution\n"
	"  --field NAME    the stats field charted against time (default max_speed)\n"
	"  --safe          run every scene with eddy run --safe (sandboxed)\n"
	"  --threads N     worker threads of every run (default: eddy run's, all cores);\n"
	"                  --threads 1 for the single-thread figures of a paper\n"
	"  -h, --help      this help\n"
	"\n"
	"Exit status: 0 every method ran; 1 a method failed (its row says why; the\n"
	"others still run and every file is still written) or the comparison could not\n"
	"be written; 2 bad usage; 128+N stopped by signal N (Ctrl-C: the running method\n"
	"ends after its frame, no further method runs, what ran is written).\n";

/* listdir(dir) -> { names } (no "." or ".."), or nil, message */
static int l_listdir(lua_State *L)
{
	const char *dir = luaL_checkstring(L, 1);
	DIR *d = opendir(dir);
	if (!d) {
		lua_pushnil(L);
		lua_pushfstring(L, "%s: %s", dir, strerror(errno));
		return 2;
	}
	lua_newtable(L);
	lua_Integer n = 0;
	struct dirent *e;
	while ((e = readdir(d))) {
		if (strcmp(e->d_name, ".") == 0 || strcmp(e->d_name, "..") == 0)
			continue;
		lua_pushstring(L, e->d_name);
		lua_rawseti(L, -2, ++n);
	}
	closedir(d);
	return 1;
}

/* compose(path, images, captions [, w, h]) -> w, h or nil, message.
 * images[i] false or "" makes a panel of text only. */
static int l_compose(lua_State *L)
{
	const char *path = luaL_checkstring(L, 1);
	luaL_checktype(L, 2, LUA_TTABLE);
	luaL_checktype(L, 3, LUA_TTABLE);
	int w = (int)luaL_optinteger(L, 4, 0), h = (int)luaL_optinteger(L, 5, 0);
	lua_Integer n = luaL_len(L, 3);
	if (n < 1 || n > 64)
		return luaL_error(L, "compose: 1 to 64 panels (got %d)", (int)n);
	const char **images = lua_newuserdatauv(L, sizeof(char *) * (size_t)n, 0);
	const char **captions = lua_newuserdatauv(L, sizeof(char *) * (size_t)n, 0);
	for (lua_Integer i = 1; i <= n; ++i) {
		lua_geti(L, 2, i); /* the tables keep the strings alive */
		images[i - 1] = lua_type(L, -1) == LUA_TSTRING ? lua_tostring(L, -1) : NULL;
		lua_pop(L, 1);
		lua_geti(L, 3, i);
		captions[i - 1] = lua_type(L, -1) == LUA_TSTRING ? lua_tostring(L, -1) : "";
		lua_pop(L, 1);
	}
	char err[512];
	int ow = 0, oh = 0;
	if (eddy_compose_panels(path, (int)n, images, captions, w, h, &ow, &oh, err, sizeof err) != 0) {
		lua_pushnil(L);
		lua_pushstring(L, err);
		return 2;
	}
	lua_pushinteger(L, ow);
	lua_pushinteger(L, oh);
	return 2;
}

enum { OPT_METHODS = 256, OPT_SET, OPT_OUT, OPT_QUICK, OPT_FIELD, OPT_SAFE, OPT_THREADS };

static const struct option compare_options[] = {
	{"methods", required_argument, NULL, OPT_METHODS},
	{"set", required_argument, NULL, OPT_SET},
	{"out", required_argument, NULL, OPT_OUT},
	{"quick", no_argument, NULL, OPT_QUICK},
	{"field", required_argument, NULL, OPT_FIELD},
	{"safe", no_argument, NULL, OPT_SAFE},
	{"threads", required_argument, NULL, OPT_THREADS},
	{"help", no_argument, NULL, 'h'},
	{NULL, 0, NULL, 0},
};

enum { MAX_METHODS = 16, MAX_SETS = 256 };

typedef struct compare_args {
	const char *scene, *out, *field;
	int threads; /* --threads for every run, 0: eddy run's default */
	char methods_buf[1024];
	const char *methods[MAX_METHODS];
	int nmethods;
	const char *sets[MAX_SETS];
	int nsets;
	bool quick, safe, help;
} compare_args;

static int usage_error(const char *fmt, ...)
#if defined(__GNUC__)
	__attribute__((format(printf, 1, 2)))
#endif
	;

/* One line "eddy: compare: ..." on stderr; returns 2, the usage status. */
static int usage_error(const char *fmt, ...)
{
	va_list ap;
	va_start(ap, fmt);
	fputs("eddy: compare: ", stderr);
	vfprintf(stderr, fmt, ap);
	fputc('\n', stderr);
	va_end(ap);
	return 2;
}

static bool is_name(const char *s, bool dash)
{
	if (!*s)
		return false;
	for (; *s; ++s) {
		unsigned char c = (unsigned char)*s;
		if (!((c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '_' ||
		      (dash && c == '-')))
			return false;
	}
	return true;
}

/* --methods a,b,c: names of letters, digits, '_' and '-' (they name folders
 * and go into --set method=), each once. */
static int parse_methods(const char *list, compare_args *a)
{
	if (snprintf(a->methods_buf, sizeof a->methods_buf, "%s", list) >= (int)sizeof a->methods_buf)
		return usage_error("--methods: the list is too long ('%.40s...')", list);
	a->nmethods = 0;
	char *save = NULL;
	if (!list[0] || list[0] == ',' || list[strlen(list) - 1] == ',' || strstr(list, ",,"))
		return usage_error("--methods expects names separated by commas, e.g. wcsph,dfsph,flip (got '%s')", list);
	for (char *m = strtok_r(a->methods_buf, ",", &save); m; m = strtok_r(NULL, ",", &save)) {
		if (!is_name(m, true))
			return usage_error("--methods: '%s' is not a method name (letters, digits, '_' and '-' only)", m);
		for (int i = 0; i < a->nmethods; ++i)
			if (strcmp(a->methods[i], m) == 0)
				return usage_error("--methods: '%s' is given twice", m);
		if (a->nmethods == MAX_METHODS)
			return usage_error("--methods: more than 16 methods ('%s')", list);
		a->methods[a->nmethods++] = m;
	}
	return 0;
}

static int parse_set(const char *arg, compare_args *a)
{
	const char *eq = strchr(arg, '=');
	if (!eq || eq == arg)
		return usage_error("--set expects KEY=VALUE (got '%s')", arg);
	const int klen = (int)(eq - arg);
	if (klen == 6 && strncmp(arg, "method", 6) == 0)
		return usage_error("--set %s: the method is chosen by --methods (e.g. --methods %s)", arg, eq + 1);
	for (int i = 0; i < a->nsets; ++i)
		if (strncmp(a->sets[i], arg, (size_t)klen) == 0 && a->sets[i][klen] == '=')
			return usage_error("--set %.*s given twice ('%s' and '%s'); give each parameter once", klen, arg,
			                   a->sets[i], arg);
	if (a->nsets == MAX_SETS)
		return usage_error("more than 256 --set options");
	a->sets[a->nsets++] = arg;
	return 0;
}

/* "--name" of an argument "--name=value", for messages. */
static const char *option_text(const char *arg, char name[128])
{
	snprintf(name, 128, "%.*s", (int)strcspn(arg ? arg : "?", "="), arg ? arg : "?");
	return name;
}

/* getopt_long over argv[1..] ("compare" stands in for the program name). */
static int parse_compare_args(int argc, char **argv, compare_args *a)
{
	memset(a, 0, sizeof *a);
	a->field = "max_speed";
	int code = parse_methods("wcsph,dfsph,flip", a);
	opterr = 0;
	optind = 1;
	int opt;
	char name[128];
	while (code == 0 && (opt = getopt_long(argc - 1, argv + 1, ":h", compare_options, NULL)) != -1) {
		const char *arg = argv[optind]; /* argv + 1's optind - 1 */
		switch (opt) {
		case OPT_METHODS:
			code = parse_methods(optarg, a);
			break;
		case OPT_SET:
			code = parse_set(optarg, a);
			break;
		case OPT_OUT:
			if (!optarg[0])
				code = usage_error("--out must not be empty");
			a->out = optarg;
			break;
		case OPT_FIELD:
			if (!is_name(optarg, false))
				code = usage_error("--field: '%s' is not a stats field name (letters, digits and '_')", optarg);
			a->field = optarg;
			break;
		case OPT_THREADS: {
			char *end;
			const long t = strtol(optarg, &end, 10);
			if (end == optarg || *end || t < 1 || t > 1024)
				code = usage_error("--threads must be an integer from 1 to 1024 (got '%s')", optarg);
			a->threads = (int)t;
			break;
		}
		case OPT_QUICK:
			a->quick = true;
			break;
		case OPT_SAFE:
			a->safe = true;
			break;
		case 'h':
			a->help = true;
			break;
		case ':':
			code = usage_error("%s needs a value (see eddy compare --help)", option_text(arg, name));
			break;
		default:
			if (optopt == OPT_QUICK || optopt == OPT_SAFE || optopt == 'h')
				code = usage_error("option '%s' takes no value", option_text(arg, name));
			else
				code = usage_error("unknown option '%s' (see eddy compare --help)", option_text(arg, name));
		}
	}
	if (code)
		return code;
	for (int i = optind + 1; i < argc; ++i) {
		if (a->scene)
			return usage_error("unexpected argument '%s' (see eddy compare --help)", argv[i]);
		a->scene = argv[i];
	}
	return 0;
}

int eddy_compare_main(int argc, char **argv)
{
	compare_args a;
	int usage = parse_compare_args(argc, argv, &a);
	if (usage)
		return usage;
	if (a.help) {
		fputs(compare_usage, stdout);
		return 0;
	}
	if (!a.scene)
		return usage_error("needs a scene file, e.g. eddy compare scenes/dam_break.lua --methods wcsph,flip");
	char exe[EDDY_CLI_PATH_MAX], dir[EDDY_CLI_PATH_MAX];
	lua_State *L = eddy_cli_driver_state(exe, dir);
	if (!L)
		return 1;

	int code = 1;
	lua_pushcfunction(L, eddy_cli_error_message);
	int handler = lua_gettop(L);
	lua_getglobal(L, "require");
	lua_pushstring(L, "eddy.compare");
	if (lua_pcall(L, 1, 1, handler) != LUA_OK) {
		const char *msg = lua_tostring(L, -1);
		if (msg && strncmp(msg, "module 'eddy.", 13) == 0 && strstr(msg, "not found"))
			fprintf(stderr,
			        "eddy: compare: its Lua driver eddy/compare.lua (or eddy/study.lua) is not installed "
			        "(looked in %s/../lua, %s/../../lua and %s/../share/lua/5.4)\n",
			        dir, dir, dir);
		else
			fprintf(stderr, "eddy: %.*s\n", (int)strcspn(msg ? msg : "?", "\n"), msg ? msg : "?");
		goto done;
	}
	lua_getfield(L, -1, "main");
	eddy_cli_push_driver_args(L, exe);
	lua_pushstring(L, a.scene);
	lua_setfield(L, -2, "scene");
	if (a.out) {
		lua_pushstring(L, a.out);
		lua_setfield(L, -2, "out");
	}
	lua_pushstring(L, a.field);
	lua_setfield(L, -2, "field");
	lua_createtable(L, a.nmethods, 0);
	for (int i = 0; i < a.nmethods; ++i) {
		lua_pushstring(L, a.methods[i]);
		lua_rawseti(L, -2, i + 1);
	}
	lua_setfield(L, -2, "methods");
	lua_createtable(L, a.nsets, 0);
	for (int i = 0; i < a.nsets; ++i) {
		lua_pushstring(L, a.sets[i]);
		lua_rawseti(L, -2, i + 1);
	}
	lua_setfield(L, -2, "set");
	lua_pushboolean(L, a.quick);
	lua_setfield(L, -2, "quick");
	lua_pushboolean(L, a.safe);
	lua_setfield(L, -2, "safe");
	lua_pushinteger(L, a.threads);
	lua_setfield(L, -2, "threads");
	lua_pushcfunction(L, l_listdir);
	lua_setfield(L, -2, "listdir");
	lua_pushcfunction(L, l_compose);
	lua_setfield(L, -2, "compose");
	if (lua_pcall(L, 1, 1, handler) != LUA_OK) {
		const char *msg = lua_tostring(L, -1);
		fprintf(stderr, "eddy: %.*s\n", (int)strcspn(msg ? msg : "?", "\n"), msg ? msg : "?");
		goto done;
	}
	code = (int)lua_tointeger(L, -1);
done:
	lua_close(L);
	return code;
}
