/* SPDX-License-Identifier: MIT */
/* Child runs for the commands that sweep scenes (lua/spawn.c). */
#ifndef EDDY_SPAWN_H
#define EDDY_SPAWN_H

#include <lua.h>

/* spawn(argv, log_path) -> exit_code, wall_s, maxrss_kb, signal
 * argv[1] is the program; its stdout and stderr go to log_path. A program
 * that cannot start exits with 127 (as a shell's would); a child killed by a
 * signal gives 128 + the signal. signal is the SIGINT or SIGTERM this process
 * received while the child ran (0: none): Ctrl-C reaches the child too, which
 * finishes its frame, and the driver stops running further configurations. */
int eddy_cli_spawn(lua_State *L);

#define EDDY_CLI_PATH_MAX 2048

/* A Lua state for a command's driver (lua/eddy/<command>.lua): the standard
 * libraries, and package.path reaching the helpers of the source tree
 * (build/eddy, build/asan/eddy) or of an installed prefix (bin/eddy ->
 * share/lua/5.4). exe receives this executable's path (the children run the
 * same build), dir its folder (for messages). NULL, said on stderr, when out
 * of memory. */
lua_State *eddy_cli_driver_state(char exe[EDDY_CLI_PATH_MAX], char dir[EDDY_CLI_PATH_MAX]);

/* Message handler for the driver's pcall: the driver's errors are already
 * "file:line: message", so no traceback is added. */
int eddy_cli_error_message(lua_State *L);

/* Pushes the driver's argument table with what every driver gets: exe (the
 * binary its runs use) and spawn; the command adds its own options. */
void eddy_cli_push_driver_args(lua_State *L, const char *exe);

#endif
