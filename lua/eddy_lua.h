/* The Lua binding's surface for hosts in lua/ (the eddy command, tests). */
#ifndef EDDY_LUA_H
#define EDDY_LUA_H

#include <lua.h>

#include "eddy.h"

/* luaopen_eddy: `require "eddy"`. */
int luaopen_eddy(lua_State *L);

/* The world in the userdata at idx, or NULL if idx holds no (open) world. */
eddy_world *eddy_lua_toworld(lua_State *L, int idx);

/* --set values for eddy.param(); call before running a scene. */
void eddy_lua_set_param(lua_State *L, const char *key, const char *value);
/* Pushes a table {key = true} of the --set keys the scene never read. */
void eddy_lua_push_unused_params(lua_State *L);
/* The output directory for eddy.out_dir() (--out). */
void eddy_lua_set_out_dir(lua_State *L, const char *dir);

/* Pushes the table merged from this frame's on_frame returns (or nil) and
 * clears it for the next frame. */
void eddy_lua_take_frame_fields(lua_State *L, int world_idx);

#endif
