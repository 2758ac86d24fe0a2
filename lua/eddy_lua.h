/* SPDX-License-Identifier: MIT */
/* The Lua binding's surface for hosts in lua/ (the eddy command, tests). */
#ifndef EDDY_LUA_H
#define EDDY_LUA_H

#include <lua.h>

#include "eddy.h"

/* luaopen_eddy: `require "eddy"`. */
EDDY_API int luaopen_eddy(lua_State *L);

/* The world in the userdata at idx, or NULL if idx holds no (open) world. */
eddy_world *eddy_lua_toworld(lua_State *L, int idx);

/* --set values for eddy.param(); call before running a scene. */
void eddy_lua_set_param(lua_State *L, const char *key, const char *value);
/* Pushes a table {key = true} of the --set keys the scene never read. */
void eddy_lua_push_unused_params(lua_State *L);
/* The output directory for eddy.out_dir() (--out). */
void eddy_lua_set_out_dir(lua_State *L, const char *dir);
/* Worker threads for every world eddy.world{} creates from now on, whatever
 * the scene asks (--threads; 0: the scene's). Set before the scene runs, so
 * the work done while it builds its pipeline (a mesh's distance field) has
 * them too. */
void eddy_lua_set_threads(lua_State *L, int threads);

/* Safe mode (eddy run --safe). Call after luaL_openlibs, with "eddy" in
 * package.loaded, before loading the scene. Afterwards Lua code in L cannot:
 * run commands or change files through os (os.time, os.clock, os.date,
 * os.getenv and os.difftime remain); open files for writing except strictly
 * under out_dir (NULL: nowhere), and never through a path with a ".."
 * component or a symbolic link leading out of out_dir (io.open and
 * io.output; io.popen and io.tmpfile are refused; reading is unrestricted);
 * load native code (package.loadlib, the C searchers, package.cpath); load
 * binary chunks (load, loadfile, dofile and require load text only); use the
 * debug library (removed). require keeps finding Lua modules on
 * package.path, package.preload and package.loaded. A refused function raises
 * "<name> is not available in safe mode (--safe)". Returns LUA_OK, or an error
 * status with the message pushed (e.g. a standard library was not opened). */
int eddy_lua_sandbox(lua_State *L, const char *out_dir);

/* Pushes the table merged from this frame's on_frame returns (or nil) and
 * clears it for the next frame. */
void eddy_lua_take_frame_fields(lua_State *L, int world_idx);

#endif
