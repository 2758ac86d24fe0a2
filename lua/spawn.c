/* SPDX-License-Identifier: MIT */
/* spawn(argv, log_path) for the drivers of `eddy study` and `eddy compare`:
 * one configuration as a child process (`eddy run ...`, this very binary),
 * its wall time and peak resident memory through wait4's rusage. Each run is
 * a separate process so that one run's memory peak, allocator state or crash
 * cannot leak into the next one's figures. */
#define _POSIX_C_SOURCE 200809L
#define _DEFAULT_SOURCE /* wait4, siginfo_t */
#include "spawn.h"

#include <lauxlib.h>
#include <lualib.h>

#include <errno.h>
#include <fcntl.h>
#include <signal.h>
#include <stdbool.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>
#include <sys/resource.h>
#include <sys/time.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

static double now_s(void)
{
	struct timespec t;
	clock_gettime(CLOCK_MONOTONIC, &t);
	return (double)t.tv_sec + 1e-9 * (double)t.tv_nsec;
}

/* SIGINT or SIGTERM while a child runs: Ctrl-C reaches the child too (the
 * terminal signals the whole process group), and the child finishes its frame
 * and exits with 128 + the signal; this process only remembers it, stops
 * running methods and writes what it has. A signal sent to this process
 * alone (kill PID: SI_USER) is passed on to the child. */
static volatile sig_atomic_t stop_signal;
static volatile pid_t running_child;

static void on_signal(int sig, siginfo_t *info, void *context)
{
	(void)context;
	stop_signal = sig;
	if (info && info->si_code == SI_USER && running_child > 0 && info->si_pid != running_child)
		kill(running_child, sig);
}

static void catch_signals(bool on, struct sigaction old[2])
{
	static const int sigs[2] = {SIGINT, SIGTERM};
	for (int i = 0; i < 2; ++i) {
		if (on) {
			struct sigaction sa;
			memset(&sa, 0, sizeof sa);
			sa.sa_sigaction = on_signal;
			sa.sa_flags = SA_SIGINFO | SA_RESTART;
			sigemptyset(&sa.sa_mask);
			sigaction(sigs[i], &sa, &old[i]);
		} else {
			sigaction(sigs[i], &old[i], NULL);
		}
	}
}

int eddy_cli_spawn(lua_State *L)
{
	luaL_checktype(L, 1, LUA_TTABLE);
	const char *log = luaL_checkstring(L, 2);
	lua_Integer n = luaL_len(L, 1);
	if (n < 1 || n > 4096)
		return luaL_error(L, "spawn: argv must hold 1 to 4096 strings");
	char **argv = lua_newuserdatauv(L, sizeof(char *) * (size_t)(n + 1), 0);
	for (lua_Integer i = 1; i <= n; ++i) {
		lua_geti(L, 1, i);
		const char *s = lua_tostring(L, -1);
		if (!s)
			return luaL_error(L, "spawn: argv[%d] is not a string", (int)i);
		argv[i - 1] = (char *)(uintptr_t)s; /* the table keeps it alive */
		lua_pop(L, 1);
	}
	argv[n] = NULL;
	int fd = open(log, O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
	if (fd < 0)
		return luaL_error(L, "spawn: cannot write '%s': %s", log, strerror(errno));
	fflush(NULL);
	struct sigaction old[2];
	catch_signals(true, old);
	double t0 = now_s();
	pid_t pid = fork();
	if (pid < 0) {
		catch_signals(false, old);
		close(fd);
		return luaL_error(L, "spawn: fork failed: %s", strerror(errno));
	}
	if (pid == 0) {
		catch_signals(false, old); /* the child handles its own (eddy run) */
		dup2(fd, 1);
		dup2(fd, 2);
		execv(argv[0], argv);
		_exit(127);
	}
	running_child = pid;
	close(fd);
	int status = 0;
	struct rusage ru;
	memset(&ru, 0, sizeof ru);
	while (wait4(pid, &status, 0, &ru) < 0) {
		if (errno != EINTR) {
			running_child = 0;
			catch_signals(false, old);
			return luaL_error(L, "spawn: wait4 failed: %s", strerror(errno));
		}
	}
	running_child = 0;
	catch_signals(false, old);
	double wall = now_s() - t0;
	int code = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + (WIFSIGNALED(status) ? WTERMSIG(status) : 0);
	lua_pushinteger(L, code);
	lua_pushnumber(L, wall);
	lua_pushinteger(L, (lua_Integer)ru.ru_maxrss); /* KiB on Linux */
	lua_pushinteger(L, stop_signal);
	return 4;
}

lua_State *eddy_cli_driver_state(char exe[EDDY_CLI_PATH_MAX], char dir[EDDY_CLI_PATH_MAX])
{
	ssize_t len = readlink("/proc/self/exe", exe, EDDY_CLI_PATH_MAX - 1);
	exe[len > 0 ? (size_t)len : 0] = '\0';
	snprintf(dir, EDDY_CLI_PATH_MAX, "%s", exe);
	char *cut = strrchr(dir, '/');
	if (cut)
		*cut = '\0';
	lua_State *L = luaL_newstate();
	if (!L) {
		fputs("eddy: cannot create a Lua state (out of memory)\n", stderr);
		return NULL;
	}
	luaL_openlibs(L);
	lua_getglobal(L, "package");
	lua_getfield(L, -1, "path");
	lua_pushfstring(L, "%s/../lua/?.lua;%s/../../lua/?.lua;%s/../share/lua/5.4/?.lua;%s", dir, dir, dir,
	                lua_tostring(L, -1));
	lua_setfield(L, -3, "path");
	lua_pop(L, 2);
	return L;
}

int eddy_cli_error_message(lua_State *L)
{
	const char *msg = lua_tostring(L, 1);
	lua_pushstring(L, msg ? msg : "(error object is not a string)");
	return 1;
}

void eddy_cli_push_driver_args(lua_State *L, const char *exe)
{
	lua_newtable(L);
	lua_pushstring(L, exe);
	lua_setfield(L, -2, "exe");
	lua_pushcfunction(L, eddy_cli_spawn);
	lua_setfield(L, -2, "spawn");
}
