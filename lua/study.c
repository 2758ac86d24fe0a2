/* SPDX-License-Identifier: MIT */
/* `eddy study STUDY.lua [--out DIR] [--quick]`: the accuracy/time study.
 *
 * The sweep, the error metrics, the CSV and the chart are Lua
 * (lua/eddy/study.lua). C adds what Lua cannot do: run one configuration as a
 * child process (`eddy run ...`, this very binary) and measure its wall time
 * and peak resident memory through wait4's rusage. Each run is a separate
 * process so that one run's memory peak, allocator state or crash cannot leak
 * into the next one's figures. Every failure is one line on stderr. */
#define _POSIX_C_SOURCE 200809L
#define _DEFAULT_SOURCE /* wait4 */
#define _GNU_SOURCE     /* getopt_long */
#include "spawn.h"
#include "study.h"

#include <lauxlib.h>
#include <lualib.h>

#include <errno.h>
#include <fcntl.h>
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

static const char study_usage[] = "usage: eddy study STUDY.lua [--out DIR] [--quick] [--safe]\n"
								  "\n"
								  "Runs every configuration the study file sweeps (each as `eddy run SCENE\n"
								  "--set render=false`, one process per run), measures its error against the\n"
								  "study's reference, its wall time, per-system time, steps and peak memory,\n"
								  "and writes into DIR (default out/study_<name>):\n"
								  "  <name>.csv   one row per run\n"
								  "  <name>.png   error against wall time, log-log, one series per method,\n"
								  "               Pareto front marked (needs gnuplot: apt-get install gnuplot-nox)\n"
								  "\n"
								  "options:\n"
								  "  --out DIR   output directory\n"
								  "  --quick     the study's reduced sweep (under a minute)\n"
								  "  --safe      run every scene with eddy run --safe (sandboxed)\n"
								  "  -h, --help  this help\n"
								  "\n"
								  "Shipped studies: scenes/studies/*.lua (the format is described in\n"
								  "lua/eddy/study.lua).\n";

static const struct option study_options[] = {
	{"out", required_argument, NULL, 'o'},
	{"quick", no_argument, NULL, 'q'},
	{"safe", no_argument, NULL, 's'},
	{"help", no_argument, NULL, 'h'},
	{NULL, 0, NULL, 0},
};

typedef struct study_args {
	const char *file, *out;
	bool quick, safe, help;
} study_args;

/* getopt_long over argv[1..] ("study" stands in for the program name), so
 * --out DIR and --out=DIR both work. Returns 0 or the exit status of a
 * reported usage error. */
static int parse_study_args(int argc, char **argv, study_args *a)
{
	memset(a, 0, sizeof *a);
	opterr = 0; /* its messages are not one line starting "eddy: " */
	optind = 1;
	int opt;
	while ((opt = getopt_long(argc - 1, argv + 1, ":h", study_options, NULL)) != -1) {
		const char *arg = argv[optind]; /* argv + 1's optind - 1 */
		if (opt == 'o')
			a->out = optarg;
		else if (opt == 'q')
			a->quick = true;
		else if (opt == 's')
			a->safe = true;
		else if (opt == 'h')
			a->help = true;
		else if (opt == ':')
			return fprintf(stderr, "eddy: --out needs a value (see eddy study --help)\n"), 2;
		else if (optopt == 'q' || optopt == 's' || optopt == 'h')
			return fprintf(stderr, "eddy: study: option '%.*s' takes no value\n", (int)strcspn(arg, "="), arg), 2;
		else
			return fprintf(stderr, "eddy: study: unknown option '%.*s' (see eddy study --help)\n",
			               (int)strcspn(arg, "="), arg),
			       2;
	}
	for (int i = optind + 1; i < argc; ++i) {
		if (a->file)
			return fprintf(stderr, "eddy: study: unexpected argument '%s' (see eddy study --help)\n", argv[i]), 2;
		a->file = argv[i];
	}
	return 0;
}

/* The first line of msg (failures are one line); the module search's
 * "module not found" list says where it looked, so it gets a sentence. */
static void report(const char *msg, const char *exe_dir)
{
	char buf[1024];
	snprintf(buf, sizeof buf, "%s", msg ? msg : "(error object is not a string)");
	buf[strcspn(buf, "\n")] = '\0';
	if (strncmp(buf, "module 'eddy.study' not found", 29) == 0)
		fprintf(stderr,
		        "eddy: study: its Lua driver eddy/study.lua is not installed (looked in %s/../lua, "
		        "%s/../../lua and %s/../share/lua/5.4)\n",
		        exe_dir, exe_dir, exe_dir);
	else
		fprintf(stderr, "eddy: %s\n", buf);
}

int eddy_study_main(int argc, char **argv)
{
	study_args a;
	int usage = parse_study_args(argc, argv, &a);
	if (usage)
		return usage;
	if (a.help) {
		fputs(study_usage, stdout);
		return 0;
	}
	if (!a.file) {
		fputs("eddy: study needs a study file, e.g. eddy study scenes/studies/dam_break.lua\n", stderr);
		return 2;
	}
	char exe[EDDY_CLI_PATH_MAX], dir[EDDY_CLI_PATH_MAX];
	lua_State *L = eddy_cli_driver_state(exe, dir);
	if (!L)
		return 1;

	int code = 1;
	lua_pushcfunction(L, eddy_cli_error_message);
	int handler = lua_gettop(L);
	lua_getglobal(L, "require");
	lua_pushstring(L, "eddy.study");
	if (lua_pcall(L, 1, 1, handler) != LUA_OK) {
		report(lua_tostring(L, -1), dir);
		goto done;
	}
	lua_getfield(L, -1, "main");
	eddy_cli_push_driver_args(L, exe);
	lua_pushstring(L, a.file);
	lua_setfield(L, -2, "file");
	if (a.out) {
		lua_pushstring(L, a.out);
		lua_setfield(L, -2, "out");
	}
	lua_pushboolean(L, a.quick);
	lua_setfield(L, -2, "quick");
	lua_pushboolean(L, a.safe);
	lua_setfield(L, -2, "safe");
	if (lua_pcall(L, 1, 1, handler) != LUA_OK) {
		report(lua_tostring(L, -1), dir); /* the driver's are "file:line: message" */
		goto done;
	}
	code = (int)lua_tointeger(L, -1);
done:
	lua_close(L);
	return code;
}
