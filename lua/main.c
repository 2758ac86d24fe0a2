/* SPDX-License-Identifier: MIT */
/* The eddy command: run, plan and check Lua scenes; study (lua/study.c).
 *
 *   eddy run SCENE.lua [--frames N] [--duration S] [--out DIR] [--threads N]
 *                      [--set K=V ...] [--stats FILE] [--quiet] [--safe]
 *                      [--video FILE] [--export ply|vtk|vtp]
 *                      [--checkpoint-every N] [--keep-checkpoints N] [--resume DIR]
 *   eddy plan SCENE.lua [--dot] [--set K=V ...] [--safe]
 *   eddy check SCENE.lua [--set K=V ...] [--safe]
 *   eddy study STUDY.lua [--out DIR] [--quick] [--safe]
 *   eddy compare SCENE.lua [--methods M1,M2,...] [--set K=V ...] [--out DIR]
 *                          [--quick] [--field NAME] [--safe]
 *
 * Arguments: lua/cli_args.c; the run loop: lua/cli_run.c; stats lines:
 * lua/cli_stats.c; the manual: docs/eddy.1.
 *
 * Exit status: 0 success, 1 the scene or the run failed, 2 bad usage. Every
 * failure is one line on stderr starting with "eddy: ". */
#define _POSIX_C_SOURCE 200809L
#include "cli.h"

#include <lauxlib.h>
#include <lualib.h>

#include <errno.h>
#include <poll.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "eddy_lua.h"
#include "study.h"   /* eddy study: lua/study.c */
#include "compare.h" /* eddy compare: lua/compare.c */

/* The scene's name without directory and extension, for out/<scene>. */
static void scene_name(const char *path, char *out, size_t cap)
{
	const char *base = strrchr(path, '/');
	base = base ? base + 1 : path;
	size_t n = strcspn(base, ".");
	snprintf(out, cap, "%.*s", (int)n, base);
}

/* package.path: scenes may require helpers beside them, and eddy's own Lua
 * helpers (require "eddy.dam_break") from lua/ of the source tree the command
 * was built in (build/eddy -> lua/) or of an installed prefix (bin/eddy ->
 * share/lua/5.4/). */
static void set_package_path(lua_State *L, const char *scene)
{
	const char *slash = strrchr(scene, '/');
	int dirlen = slash ? (int)(slash - scene) : 1;
	const char *dir = slash ? scene : ".";
	char exe[2048] = "";
	ssize_t len = readlink("/proc/self/exe", exe, sizeof exe - 1);
	exe[len > 0 ? len : 0] = '\0';
	char *cut = strrchr(exe, '/');
	if (cut)
		*cut = '\0'; /* the directory holding the command */
	lua_getglobal(L, "package");
	char path[8192];
	lua_getfield(L, -1, "path");
	snprintf(path, sizeof path, "%.*s/?.lua;%s/../lua/?.lua;%s/../../lua/?.lua;%s/../share/lua/5.4/?.lua;%s", dirlen,
	         dir, exe, exe, exe, lua_tostring(L, -1));
	lua_pop(L, 1);
	lua_pushstring(L, path);
	lua_setfield(L, -2, "path");
	lua_pop(L, 1);
}

/* The scene's chunk on the stack, as text only: a precompiled chunk is
 * refused, since Lua does not verify bytecode and bad bytecode can crash the
 * process. The fingerprint covers the scene text (and the --set values). */
static int load_chunk(lua_State *L, cli_options *o)
{
	char buf[1024];
	errno = 0;
	int rc = luaL_loadfilex(L, o->scene, "t");
	if (rc == LUA_ERRFILE)
		return cli_fail(CLI_EXIT_RUN, "cannot read scene '%s': %s", o->scene, strerror(errno ? errno : ENOENT));
	if (rc != LUA_OK && strstr(lua_tostring(L, -1), "binary chunk"))
		return cli_fail(CLI_EXIT_RUN, "%s: a precompiled (binary) chunk; scenes are loaded as Lua text only", o->scene);
	if (rc != LUA_OK)
		return cli_fail(CLI_EXIT_RUN, "%s", cli_first_line(lua_tostring(L, -1), buf, sizeof buf));
	/* a checkpoint belongs to this scene text with these --set values */
	FILE *sf = fopen(o->scene, "rb");
	if (sf) {
		char chunk[4096];
		size_t k;
		while ((k = fread(chunk, 1, sizeof chunk, sf)) > 0)
			o->fingerprint = cli_fnv(o->fingerprint ^ 0x9e3779b97f4a7c15ull, chunk, k);
		fclose(sf);
	}
	return 0;
}

/* Runs the scene file; leaves the returned world on the stack. */
static int load_scene(lua_State *L, cli_options *o)
{
	luaL_openlibs(L); /* "eddy" is already in package.loaded (see main) */
	set_package_path(L, o->scene);
	char name[256];
	scene_name(o->scene, name, sizeof name);
	if (o->out)
		snprintf(o->outdir, sizeof o->outdir, "%s", o->out);
	else
		snprintf(o->outdir, sizeof o->outdir, "out/%s", name);
	eddy_lua_set_out_dir(L, o->outdir);
	eddy_lua_set_threads(L, o->threads);

	char buf[1024];
	if (o->safe && eddy_lua_sandbox(L, o->outdir) != 0)
		return cli_fail(CLI_EXIT_RUN, "--safe: %s", cli_first_line(lua_tostring(L, -1), buf, sizeof buf));
	int code = load_chunk(L, o);
	if (code)
		return code;
	if (lua_pcall(L, 0, 1, 0) != LUA_OK)
		return cli_fail(CLI_EXIT_RUN, "%s", cli_first_line(lua_tostring(L, -1), buf, sizeof buf));
	if (!eddy_lua_toworld(L, -1))
		return cli_fail(CLI_EXIT_RUN, "%s: the scene must return a world (got %s); end it with 'return world'",
		                o->scene, luaL_typename(L, -1));
	/* a --set the scene never read is almost always a typo */
	eddy_lua_push_unused_params(L);
	lua_pushnil(L);
	if (lua_next(L, -2)) {
		const char *key = lua_tostring(L, -2);
		return cli_fail(CLI_EXIT_USAGE, "--set %s: %s has no parameter '%s' (it reads parameters with eddy.param)", key,
		                o->scene, key);
	}
	lua_pop(L, 1);
	return 0;
}

static int cmd_plan(lua_State *L, const cli_options *o, int world_idx)
{
	eddy_world *w = eddy_lua_toworld(L, world_idx);
	size_t (*fn)(const eddy_world *, char *, size_t) = o->dot ? eddy_world_plan_dot : eddy_world_plan;
	size_t n = fn(w, NULL, 0);
	char *text = malloc(n + 1);
	if (!text)
		return cli_fail(CLI_EXIT_RUN, "out of memory");
	fn(w, text, n + 1);
	fputs(text, stdout);
	free(text);
	return 0;
}

static void check_report(eddy_check_level level, const char *message, void *user)
{
	(void)user;
	static const char *const tags[] = {"ok     ", "warning", "error  "};
	printf("%s  %s\n", tags[level], message);
}

static int cmd_check(lua_State *L, const cli_options *o, int world_idx)
{
	eddy_world *w = eddy_lua_toworld(L, world_idx);
	printf("%s: the pipeline is valid (%d systems)\n", o->scene, eddy_world_system_count(w));
	int errors = eddy_world_check(w, check_report, NULL);
	if (errors)
		return cli_fail(CLI_EXIT_RUN, "%s: %d problem%s found by check", o->scene, errors, errors == 1 ? "" : "s");
	return 0;
}

/* Whatever went to stdout reached it. A reader that went away (EPIPE:
 * `eddy plan s.lua | head -1`) is not a failure: it has what it wanted. */
static int finish_stdout(int code)
{
	errno = 0;
	if (fflush(stdout) == 0 && !ferror(stdout))
		return code;
	int err = errno;
	/* a write that failed inside an earlier printf left only the error
	 * indicator; a pipe without a reader polls as POLLERR */
	struct pollfd pfd = {.fd = STDOUT_FILENO, .events = POLLOUT};
	if (!err && poll(&pfd, 1, 0) == 1 && (pfd.revents & POLLERR))
		err = EPIPE;
	if (!err)
		err = EIO;
	if (err == EPIPE || code != 0)
		return code;
	return cli_fail(CLI_EXIT_RUN, "cannot write to standard output: %s", strerror(err));
}

int main(int argc, char **argv)
{
	/* writes to a closed pipe fail with EPIPE, reported or taken as the
	 * reader's wish to stop, instead of killing the process without a word */
	signal(SIGPIPE, SIG_IGN);
	/* eddy study has its own arguments and runs scenes as child processes */
	if (argc > 1 && strcmp(argv[1], "study") == 0)
		return finish_stdout(eddy_study_main(argc, argv));
	/* so has eddy compare: one child eddy run per method */
	if (argc > 1 && strcmp(argv[1], "compare") == 0)
		return finish_stdout(eddy_compare_main(argc, argv));
	lua_State *L = luaL_newstate();
	if (!L)
		return cli_fail(CLI_EXIT_RUN, "cannot create a Lua state (out of memory)");
	/* the registry tables for --set must exist before parsing */
	luaL_requiref(L, "eddy", luaopen_eddy, 0);
	lua_pop(L, 1);
	cli_options o;
	int code = cli_parse(argc, argv, &o, L);
	if (code == 0)
		code = load_scene(L, &o);
	if (code == 0) {
		int world_idx = lua_gettop(L);
		if (strcmp(o.command, "run") == 0)
			code = cli_run(L, &o, world_idx);
		else if (strcmp(o.command, "plan") == 0)
			code = cmd_plan(L, &o, world_idx);
		else
			code = cmd_check(L, &o, world_idx);
	}
	lua_close(L);
	return finish_stdout(code < 0 ? 0 : code);
}
