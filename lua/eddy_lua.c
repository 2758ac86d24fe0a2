/* SPDX-License-Identifier: MIT */
/* The Lua binding: `local eddy = require "eddy"`.
 *
 * Every def starts from the C default function, so defaults live only in C;
 * this file knows each def's field names and types (to reject unknown fields
 * and wrong types where the scene wrote them), and the C add functions judge
 * ranges. Errors are raised with luaL_error so they carry the scene's file and
 * line.
 *
 * Userdata: eddy.world (owns an eddy_world), eddy.def (a filled def not yet
 * added), eddy.system (a handle: world + id), eddy.channel (a live view of a
 * column). Host callbacks (on_frame, animated collider offsets) are custom
 * systems, so they show in the plan like any other system. */
#define _XOPEN_SOURCE 700 /* getcwd, lstat, realpath: safe mode's path checks */
#include "eddy_lua.h"
#include "bind.h"

#include <lauxlib.h>
#include <lualib.h>

#include <float.h>
#include <limits.h>
#include <math.h>
#include <stddef.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#define WORLD_MT "eddy.world"
#define DEF_MT "eddy.def"
#define SYSTEM_MT "eddy.system"
#define CHANNEL_MT "eddy.channel"
#define PARAMS_KEY "eddy.params"
#define PARAMS_USED_KEY "eddy.params_used"
#define WORLDS_KEY "eddy.worlds" /* weak: eddy_world* -> its userdata */
#define OUT_DIR_KEY "eddy.out_dir"
#define THREADS_KEY "eddy.threads"

/* Every list of kinds the module exposes; each ends with EDDY_LUA_KIND_END. */
static const eddy_lua_kind *const kind_lists[] = {
	eddy_lua_core_kinds,
	/* more kind lists go here, one line per area */

	/* SPH */
	eddy_lua_sph_kinds,

	/* FLIP */
	eddy_lua_flip_kinds,

	/* renderer */
	eddy_lua_render_kinds,

	/* meshes and particle files */
	eddy_lua_mesh_kinds,
};

/* ---- reading fields ------------------------------------------------------ */

static size_t edit_distance(const char *a, const char *b)
{
	size_t la = strlen(a), lb = strlen(b);
	if (la > 31 || lb > 31)
		return 99;
	size_t d[32][32];
	for (size_t i = 0; i <= la; ++i)
		d[i][0] = i;
	for (size_t j = 0; j <= lb; ++j)
		d[0][j] = j;
	for (size_t i = 1; i <= la; ++i)
		for (size_t j = 1; j <= lb; ++j) {
			size_t sub = d[i - 1][j - 1] + (a[i - 1] != b[j - 1]);
			size_t del = d[i - 1][j] + 1, ins = d[i][j - 1] + 1;
			d[i][j] = sub < del ? (sub < ins ? sub : ins) : (del < ins ? del : ins);
		}
	return d[la][lb];
}

static int unknown_field(lua_State *L, const eddy_lua_kind *k, const char *name)
{
	luaL_Buffer b;
	luaL_buffinit(L, &b);
	const char *best = NULL;
	size_t best_d = 3;
	for (const eddy_lua_field *f = k->fields; f->name; ++f) {
		luaL_addstring(&b, f == k->fields ? "" : ", ");
		luaL_addstring(&b, f->name);
		size_t dist = edit_distance(name, f->name);
		if (dist < best_d) {
			best_d = dist;
			best = f->name;
		}
	}
	luaL_pushresult(&b);
	if (best)
		return luaL_error(L, "%s: unknown field '%s' (did you mean '%s'? fields: %s)", k->name, name, best,
		                  lua_tostring(L, -1));
	return luaL_error(L, "%s: unknown field '%s' (fields: %s)", k->name, name, lua_tostring(L, -1));
}

static double number_field(lua_State *L, const eddy_lua_kind *k, const char *name, int idx, const char *what)
{
	if (lua_type(L, idx) != LUA_TNUMBER)
		return luaL_error(L, "%s: '%s' must be %s (got %s)", k->name, name, what, luaL_typename(L, idx));
	return lua_tonumber(L, idx);
}

/* A double as a float; beyond the float range it is the infinity of its sign
 * (a C conversion out of range is undefined), which the add functions reject. */
static float to_float(double d)
{
	if (d > FLT_MAX)
		return INFINITY;
	if (d < -FLT_MAX)
		return -INFINITY;
	return (float)d;
}

static eddy_vec3 vec3_field(lua_State *L, const eddy_lua_kind *k, const char *name, int idx)
{
	idx = lua_absindex(L, idx);
	if (!lua_istable(L, idx) || lua_rawlen(L, idx) != 3)
		luaL_error(L, "%s: '%s' must be a table of 3 numbers {x, y, z} (got %s)", k->name, name,
		           lua_istable(L, idx) ? "a table of another length" : luaL_typename(L, idx));
	float v[3];
	for (int i = 0; i < 3; ++i) {
		lua_rawgeti(L, idx, i + 1);
		if (lua_type(L, -1) != LUA_TNUMBER)
			luaL_error(L, "%s: '%s' must be a table of 3 numbers {x, y, z} (element %d is %s)", k->name, name, i + 1,
			           luaL_typename(L, -1));
		v[i] = to_float(lua_tonumber(L, -1));
		lua_pop(L, 1);
	}
	return (eddy_vec3){v[0], v[1], v[2]};
}

static lua_Integer integer_field(lua_State *L, const eddy_lua_kind *k, const char *name, int idx, lua_Integer lo,
                                 lua_Integer hi)
{
	int ok = 0;
	lua_Integer v = lua_tointegerx(L, idx, &ok);
	if (!ok || v < lo || v > hi)
		return luaL_error(L, "%s: '%s' must be an integer in [%I, %I] (got %s)", k->name, name, lo, hi,
		                  lua_type(L, idx) == LUA_TNUMBER ? lua_tostring(L, idx) : luaL_typename(L, idx));
	return v;
}

typedef struct lua_def {
	const eddy_lua_kind *k;
	bool has_offset; /* a constant offset in `offset` */
	eddy_vec3 offset;
	bool has_rotation;  /* a constant rotation in `rotation` */
	eddy_vec3 rotation; /* degrees, axis-angle */
	bool has_pivot;
	eddy_vec3 pivot;
	/* an offset function, if any, is the userdata's user value 1; a
	 * rotation function user value 2 */
	/* k->def_size bytes: the C def. Lua aligns userdata to 8 bytes, not to
	 * max_align_t; defs hold nothing wider than double, int64 or pointers. */
	union {
		double d;
		int64_t i;
		void *p;
	} def[];
} lua_def;

/* Fills d from the table at idx; an `offset` function is left on user value 1
 * of the def userdata at ud (0 when reading a world def). */
static void read_fields(lua_State *L, const eddy_lua_kind *k, int idx, void *def, lua_def *ld, int ud)
{
	idx = lua_absindex(L, idx);
	luaL_checktype(L, idx, LUA_TTABLE);
	char *base = (char *)def;
	lua_pushnil(L);
	while (lua_next(L, idx)) {
		if (lua_type(L, -2) != LUA_TSTRING)
			luaL_error(L, "%s: fields must be named (found a %s key)", k->name, luaL_typename(L, -2));
		const char *name = lua_tostring(L, -2);
		const eddy_lua_field *f = k->fields;
		while (f->name && strcmp(f->name, name) != 0)
			++f;
		if (!f->name)
			unknown_field(L, k, name);
		void *p = base + f->offset;
		switch (f->type) {
		case EDDY_LUA_FLOAT:
			*(float *)p = to_float(number_field(L, k, name, -1, "a number"));
			break;
		case EDDY_LUA_DOUBLE:
			*(double *)p = number_field(L, k, name, -1, "a number");
			break;
		case EDDY_LUA_INT:
			*(int *)p = (int)integer_field(L, k, name, -1, -1000000000, 1000000000);
			break;
		case EDDY_LUA_INT64:
			*(int64_t *)p = (int64_t)integer_field(L, k, name, -1, 0, LUA_MAXINTEGER);
			break;
		case EDDY_LUA_U64:
			*(uint64_t *)p = (uint64_t)integer_field(L, k, name, -1, 0, LUA_MAXINTEGER);
			break;
		case EDDY_LUA_BOOL:
			if (!lua_isboolean(L, -1))
				luaL_error(L, "%s: '%s' must be true or false (got %s)", k->name, name, luaL_typename(L, -1));
			*(bool *)p = lua_toboolean(L, -1);
			break;
		case EDDY_LUA_VEC3:
			*(eddy_vec3 *)p = vec3_field(L, k, name, -1);
			break;
		case EDDY_LUA_BOUNDS: {
			if (!lua_istable(L, -1) || lua_rawlen(L, -1) != 2)
				luaL_error(L, "%s: '%s' must be {{xmin, ymin, zmin}, {xmax, ymax, zmax}} (got %s)", k->name, name,
				           luaL_typename(L, -1));
			lua_rawgeti(L, -1, 1);
			((eddy_vec3 *)p)[0] = vec3_field(L, k, name, -1);
			lua_rawgeti(L, -2, 2);
			((eddy_vec3 *)p)[1] = vec3_field(L, k, name, -1);
			lua_pop(L, 2);
			break;
		}
		case EDDY_LUA_ENUM: {
			const char *s = lua_type(L, -1) == LUA_TSTRING ? lua_tostring(L, -1) : NULL;
			int i = 0;
			while (s && f->choices[i] && strcmp(f->choices[i], s) != 0)
				++i;
			if (!s || !f->choices[i]) {
				luaL_Buffer b;
				luaL_buffinit(L, &b);
				for (int j = 0; f->choices[j]; ++j) {
					luaL_addstring(&b, j ? (f->choices[j + 1] ? ", \"" : " or \"") : "\"");
					luaL_addstring(&b, f->choices[j]);
					luaL_addstring(&b, "\"");
				}
				luaL_pushresult(&b);
				luaL_error(L, "%s: '%s' must be %s (got %s)", k->name, name, lua_tostring(L, -1),
				           s ? s : luaL_typename(L, -2));
			}
			*(int *)p = i;
			break;
		}
		case EDDY_LUA_STRING:
		case EDDY_LUA_INPUT_PATH: {
			size_t len = 0;
			const char *s = lua_type(L, -1) == LUA_TSTRING ? lua_tolstring(L, -1, &len) : NULL;
			if (!s)
				luaL_error(L, "%s: '%s' must be a string (got %s)", k->name, name, luaL_typename(L, -1));
			if (len >= f->size || strlen(s) != len)
				luaL_error(L, "%s: '%s' must be a string of at most %d bytes without NUL", k->name, name,
				           (int)f->size - 1);
			memcpy(p, s, len + 1);
			break;
		}
		case EDDY_LUA_STRING_LIST: {
			/* {"a", "b"} (or "a b") -> "a b": C defs hold lists as one string */
			const int t = lua_absindex(L, -1);
			const bool is_table = lua_istable(L, t);
			if (!is_table && lua_type(L, t) != LUA_TSTRING)
				luaL_error(L, "%s: '%s' must be a list of strings, e.g. {\"vx\", \"vy\"} (got %s)", k->name, name,
				           luaL_typename(L, t));
			const lua_Integer n = is_table ? (lua_Integer)lua_rawlen(L, t) : 0;
			for (lua_Integer i = 1; i <= n; ++i) {
				if (lua_rawgeti(L, t, i) != LUA_TSTRING)
					luaL_error(L, "%s: '%s' must be a list of strings (element %d is %s)", k->name, name, (int)i,
					           luaL_typename(L, -1));
				lua_pop(L, 1);
			}
			luaL_Buffer b;
			luaL_buffinit(L, &b);
			if (!is_table) {
				lua_pushvalue(L, t);
				luaL_addvalue(&b);
			}
			for (lua_Integer i = 1; i <= n; ++i) {
				if (i > 1)
					luaL_addchar(&b, ' ');
				lua_rawgeti(L, t, i);
				luaL_addvalue(&b);
			}
			luaL_pushresult(&b);
			size_t len;
			const char *s = lua_tolstring(L, -1, &len);
			if (len >= f->size || strlen(s) != len)
				luaL_error(L, "%s: '%s' must join to at most %d bytes without NUL", k->name, name, (int)f->size - 1);
			memcpy(p, s, len + 1);
			lua_pop(L, 1);
			break;
		}
		case EDDY_LUA_OFFSET:
			if (!ld)
				luaL_error(L, "%s: '%s' is not allowed here", k->name, name);
			if (lua_isfunction(L, -1)) {
				lua_pushvalue(L, -1);
				lua_setiuservalue(L, ud, 1);
			} else {
				ld->offset = vec3_field(L, k, name, -1);
				ld->has_offset = true;
			}
			break;
		case EDDY_LUA_ROTATION:
			if (!ld)
				luaL_error(L, "%s: '%s' is not allowed here", k->name, name);
			if (lua_isfunction(L, -1)) {
				lua_pushvalue(L, -1);
				lua_setiuservalue(L, ud, 2);
			} else {
				ld->rotation = vec3_field(L, k, name, -1);
				ld->has_rotation = true;
			}
			break;
		case EDDY_LUA_PIVOT:
			if (!ld)
				luaL_error(L, "%s: '%s' is not allowed here", k->name, name);
			ld->pivot = vec3_field(L, k, name, -1);
			ld->has_pivot = true;
			break;
		}
		lua_pop(L, 1);
	}
}

/* eddy.<system>{...}: a def for world:add, checked for names and types here. */
static int l_make_def(lua_State *L)
{
	const eddy_lua_kind *k = lua_touserdata(L, lua_upvalueindex(1));
	if (lua_isnoneornil(L, 1))
		lua_newtable(L);
	lua_settop(L, 1);
	if (!lua_istable(L, 1))
		return luaL_error(L, "%s: expects a table of fields, e.g. eddy.%s{...} (got %s)", k->name, k->name,
		                  luaL_typename(L, 1));
	lua_def *ld = lua_newuserdatauv(L, sizeof *ld + k->def_size, 2);
	memset(ld, 0, sizeof *ld + k->def_size);
	ld->k = k;
	k->defaults(ld->def);
	luaL_setmetatable(L, DEF_MT);
	read_fields(L, k, 1, ld->def, ld, 2);
	return 1;
}

/* ---- the world userdata -------------------------------------------------- */

typedef struct lua_world {
	eddy_world *w;
	lua_State *L; /* main thread, for callbacks */
	int busy;     /* inside a step started from Lua */
	/* While one of the world's callbacks runs, what it is ("on_frame", "an
	 * offset function"), else NULL. The world is mid-step then, whoever
	 * stepped it (Lua or the host in C): the step holds its systems and
	 * columns, so the world may not be stepped, changed or closed. */
	const char *inside;
} lua_world;

eddy_world *eddy_lua_toworld(lua_State *L, int idx)
{
	lua_world *lw = luaL_testudata(L, idx, WORLD_MT);
	return lw ? lw->w : NULL;
}

static lua_world *check_world(lua_State *L, int idx)
{
	lua_world *lw = luaL_checkudata(L, idx, WORLD_MT);
	if (!lw->w)
		luaL_error(L, "world is closed");
	return lw;
}

/* The world at idx for a call that steps, changes or closes it (world:<method>). */
static lua_world *check_idle_world(lua_State *L, int idx, const char *method)
{
	lua_world *lw = luaL_checkudata(L, idx, WORLD_MT);
	if (lw->inside)
		luaL_error(L, "world:%s() cannot be called from inside %s", method, lw->inside);
	if (lw->busy)
		luaL_error(L, "world:%s() cannot be called while the world is stepping", method);
	if (!lw->w)
		luaL_error(L, "world is closed");
	return lw;
}

/* Pushes the userdata of world w (from the weak registry map). */
static void push_world(lua_State *L, const eddy_world *w)
{
	lua_getfield(L, LUA_REGISTRYINDEX, WORLDS_KEY);
	lua_rawgetp(L, -1, w);
	lua_remove(L, -2);
}

static int l_world(lua_State *L)
{
	if (lua_isnoneornil(L, 1))
		lua_newtable(L);
	lua_settop(L, 1);
	if (!lua_istable(L, 1))
		return luaL_error(L, "world: expects a table of fields, e.g. eddy.world{bounds = ...} (got %s)",
		                  luaL_typename(L, 1));
	eddy_world_def def;
	eddy_lua_world_kind.defaults(&def);
	read_fields(L, &eddy_lua_world_kind, 1, &def, NULL, 0);
	if (lua_getfield(L, LUA_REGISTRYINDEX, THREADS_KEY) == LUA_TNUMBER)
		def.threads = (int)lua_tointeger(L, -1);
	lua_pop(L, 1);
	lua_world *lw = lua_newuserdatauv(L, sizeof *lw, 1);
	memset(lw, 0, sizeof *lw);
	luaL_setmetatable(L, WORLD_MT);
	char err[256];
	lw->w = eddy_create_world(&def, err, sizeof err);
	if (!lw->w)
		return luaL_error(L, "%s", err);
	/* LUA_RIDX_MAINTHREAD: callbacks run on the main thread even if the world
	 * was made inside a coroutine. */
	lua_rawgeti(L, LUA_REGISTRYINDEX, LUA_RIDX_MAINTHREAD);
	lw->L = lua_tothread(L, -1);
	lua_pop(L, 1);
	lua_newtable(L); /* user value: frame fields, callbacks, safe mode */
	/* eddy.world of a sandbox carries {out = its output directory} */
	if (lua_type(L, lua_upvalueindex(1)) == LUA_TTABLE) {
		lua_pushvalue(L, lua_upvalueindex(1));
		lua_setfield(L, -2, "safe");
	}
	lua_setiuservalue(L, -2, 1);
	lua_getfield(L, LUA_REGISTRYINDEX, WORLDS_KEY);
	lua_pushvalue(L, -2);
	lua_rawsetp(L, -2, lw->w);
	lua_pop(L, 1);
	return 1;
}

/* __gc, and world:close() / __close once the world is idle. A collected world
 * is never mid-step (a step holds it on the stack); a scene calling __gc
 * itself gets close's check. */
static int l_world_gc(lua_State *L)
{
	lua_world *lw = luaL_checkudata(L, 1, WORLD_MT);
	if (lw->inside || lw->busy)
		check_idle_world(L, 1, "close");
	if (lw->w) {
		eddy_destroy_world(lw->w);
		lw->w = NULL;
	}
	return 0;
}

/* Runs a host callback with a traceback-free error message; on error returns
 * EDDY_ERR_EXTERNAL with the Lua message in the world error. */
static eddy_status call_lua(lua_State *L, eddy_world *w, int nargs, int nresults, const char *what)
{
	if (lua_pcall(L, nargs, nresults, 0) == LUA_OK)
		return EDDY_OK;
	const char *msg = lua_tostring(L, -1);
	eddy_world_fail(w, EDDY_ERR_EXTERNAL, "%s: %s", what, msg ? msg : "(error object is not a string)");
	lua_pop(L, 1);
	return EDDY_ERR_EXTERNAL;
}

typedef struct callback {
	lua_State *L;
	lua_world *owner;      /* outlives the callback: its __gc destroys the world */
	int fn;                /* registry reference */
	eddy_system_id target; /* animate: the collider */
	bool rotation;         /* animate: the function gives the rotation (else the offset) */
	double placed;         /* animate: s, when the function first placed the collider (at rest before) */
	char what[64];
} callback;

static void callback_destroy(void *user)
{
	callback *cb = user;
	luaL_unref(cb->L, LUA_REGISTRYINDEX, cb->fn);
	free(cb);
}

/* on_frame: fn(world, frame) may return a table of stats fields. */
static eddy_status on_frame_hook(eddy_world *w, int frame, void *user)
{
	callback *cb = user;
	lua_State *L = cb->L;
	int top = lua_gettop(L);
	lua_rawgeti(L, LUA_REGISTRYINDEX, cb->fn);
	push_world(L, w);
	lua_pushinteger(L, frame);
	const char *outer = cb->owner->inside;
	cb->owner->inside = "on_frame";
	eddy_status st = call_lua(L, w, 2, 1, "on_frame");
	cb->owner->inside = outer;
	if (st != EDDY_OK) {
		lua_settop(L, top);
		return st;
	}
	if (lua_istable(L, -1)) {
		/* merge into the world's frame fields */
		push_world(L, w);
		lua_getiuservalue(L, -1, 1);
		lua_getfield(L, -1, "frame_fields");
		if (!lua_istable(L, -1)) {
			lua_pop(L, 1);
			lua_newtable(L);
			lua_pushvalue(L, -1);
			lua_setfield(L, -3, "frame_fields");
		}
		int dst = lua_gettop(L);
		lua_pushnil(L);
		while (lua_next(L, top + 1)) {
			if (lua_type(L, -2) != LUA_TSTRING) {
				lua_settop(L, top);
				return eddy_world_fail(w, EDDY_ERR_EXTERNAL, "on_frame: the returned table must have string keys");
			}
			lua_pushvalue(L, -2);
			lua_insert(L, -2);
			lua_rawset(L, dst);
		}
	} else if (!lua_isnil(L, -1)) {
		const char *tn = luaL_typename(L, -1);
		lua_settop(L, top);
		return eddy_world_fail(w, EDDY_ERR_EXTERNAL,
		                       "on_frame: must return a table of stats fields or nothing (got %s)", tn);
	}
	lua_settop(L, top);
	return EDDY_OK;
}

/* animate: the pose fn(t) gives, as doubles (false: not three numbers). */
static bool animate_eval(callback *cb, double t, double v[3])
{
	lua_State *L = cb->L;
	const int top = lua_gettop(L);
	lua_rawgeti(L, LUA_REGISTRYINDEX, cb->fn);
	lua_pushnumber(L, t);
	const char *outer = cb->owner->inside;
	cb->owner->inside = cb->rotation ? "a rotation function" : "an offset function";
	const int rc = lua_pcall(L, 1, 1, 0);
	cb->owner->inside = outer;
	bool ok = rc == LUA_OK && lua_istable(L, -1) && lua_rawlen(L, -1) == 3;
	for (int i = 0; ok && i < 3; ++i) {
		lua_rawgeti(L, -1, i + 1);
		ok = lua_type(L, -1) == LUA_TNUMBER && isfinite(lua_tonumber(L, -1));
		v[i] = lua_tonumber(L, -1);
		lua_pop(L, 1);
	}
	lua_settop(L, top);
	return ok;
}

/* How far a rotating collider's surface reaches from its pivot: a box's
 * farthest corner, a sphere's far side; a plane or mesh: the world's box.
 * A pose change d over dt then moves the surface at |d| / dt for an offset,
 * |d| (degrees) / dt times that reach for a rotation. */
static double animate_reach(callback *cb, eddy_world *w)
{
	eddy_collider_shape sh;
	const eddy_world_def *wd = eddy_world_get_def(w);
	eddy_vec3 lo = wd->bounds_min, hi = wd->bounds_max, c = {0, 0, 0};
	double extra = 0;
	if (eddy_collider_shape_of(w, cb->target, &sh) == EDDY_OK) {
		c = sh.pivot;
		if (sh.kind == EDDY_COLLIDER_BOX)
			lo = sh.a, hi = sh.b;
		else if (sh.kind == EDDY_COLLIDER_SPHERE)
			lo = hi = sh.a, extra = sh.radius;
	}
	double r = 0;
	for (int k = 0; k < 8; ++k) {
		const double x = (k & 1 ? hi.x : lo.x) - c.x, y = (k & 2 ? hi.y : lo.y) - c.y, z = (k & 4 ? hi.z : lo.z) - c.z;
		r = fmax(r, sqrt(x * x + y * y + z * z));
	}
	return r + extra;
}

static double norm3d(const double d[3]) { return sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]); }

/* animate's time-step limit. The collider limits the step by its last
 * step's speed, which a motion that starts or speeds up suddenly outruns:
 * a paddle whose offset is v t from t = 0 took a first step of 2.9 ms
 * (DFSPH) or 6.7 ms (FLIP) at 3 m/s, jumping 2-4 particle spacings into the
 * water, which burst at 25-30 m/s. So the function is sampled a frame
 * ahead (ANIMATE_SAMPLES intervals from now), and the step is held
 * - to the length scale L over the fastest the surface moves there (times
 *   the world's cfl), as the collider's own limit does with its last
 *   step's speed;
 * - to ANIMATE_JERK L over the largest change of that speed from the
 *   interval before now (at rest before the function first placed it),
 *   whatever the cfl: SPH's walls see a step's motion one step late, so a
 *   wall that starts at 3 m/s compresses the water in front by that speed
 *   times the step before any pressure answers it (DFSPH at cfl 0.5: a
 *   half-spacing start, 3,500 particles over 6 m/s within 4 ms).
 * It reads only the clock and the function: a resumed run steps as the
 * uninterrupted one. */
#define ANIMATE_SAMPLES 8
#define ANIMATE_JERK 0.25
static double animate_limit(eddy_world *w, void *user, const char **reason)
{
	callback *cb = user;
	const double L = eddy_world_length_scale(w), t = eddy_world_time(w), frame = eddy_world_frame_time(w);
	const double cfl = eddy_world_get_def(w)->cfl;
	if (!(L > 0) || !(frame > 0) || !(cfl > 0))
		return INFINITY;
	/* a frame ahead in fixed intervals: intervals shrinking toward the frame's
	 * end would chase a jump there (a pose that teleports) down to dt_min */
	const double dt = frame / ANIMATE_SAMPLES;
	double now[3], before[3] = {0, 0, 0};
	if (!animate_eval(cb, t, now))
		return INFINITY;        /* the step's own call reports it */
	if (t - dt >= cb->placed) { /* the motion over the interval before now */
		double b[3];
		if (!animate_eval(cb, t - dt, b))
			return INFINITY;
		for (int i = 0; i < 3; ++i)
			before[i] = now[i] - b[i];
	}
	/* m per unit of pose change and second: 1 for an offset, the reach in
	 * radians for a rotation */
	const double scale = (cb->rotation ? animate_reach(cb, w) * (M_PI / 180.0) : 1.0) / dt;
	double prev[3] = {now[0], now[1], now[2]}, speed = 0, jerk = 0;
	for (int k = 1; k <= ANIMATE_SAMPLES; ++k) {
		double v[3];
		if (!animate_eval(cb, t + k * dt, v))
			return INFINITY;
		const double d[3] = {v[0] - prev[0], v[1] - prev[1], v[2] - prev[2]};
		const double change[3] = {d[0] - before[0], d[1] - before[1], d[2] - before[2]};
		speed = fmax(speed, norm3d(d) * scale);
		jerk = fmax(jerk, norm3d(change) * scale);
		memcpy(prev, v, sizeof prev);
	}
	const double by_speed = speed > 0 ? L / speed : INFINITY;
	const double by_jerk = jerk > 0 ? ANIMATE_JERK * L / jerk / cfl : INFINITY;
	*reason = by_jerk < by_speed ? "moving wall starting" : "moving wall ahead";
	return fmin(by_speed, by_jerk);
}

/* animate: offset = fn(t) at the end of each step, before the collider runs. */
static eddy_status animate_step(eddy_world *w, const eddy_step_context *ctx, void *user)
{
	callback *cb = user;
	lua_State *L = cb->L;
	int top = lua_gettop(L);
	lua_rawgeti(L, LUA_REGISTRYINDEX, cb->fn);
	lua_pushnumber(L, ctx->time + ctx->dt);
	const char *outer = cb->owner->inside;
	cb->owner->inside = cb->rotation ? "a rotation function" : "an offset function";
	eddy_status st = call_lua(L, w, 1, 1, cb->what);
	cb->owner->inside = outer;
	if (st != EDDY_OK)
		return st;
	float v[3];
	bool ok = lua_istable(L, -1) && lua_rawlen(L, -1) == 3;
	for (int i = 0; ok && i < 3; ++i) {
		lua_rawgeti(L, -1, i + 1);
		ok = lua_type(L, -1) == LUA_TNUMBER;
		v[i] = to_float(lua_tonumber(L, -1));
		lua_pop(L, 1);
	}
	lua_settop(L, top);
	if (!ok && cb->rotation)
		return eddy_world_fail(w, EDDY_ERR_EXTERNAL,
		                       "%s: the rotation function must return an axis-angle {x, y, z} in degrees", cb->what);
	if (!ok)
		return eddy_world_fail(w, EDDY_ERR_EXTERNAL, "%s: the offset function must return {x, y, z}", cb->what);
	if (cb->rotation)
		return eddy_collider_set_rotation(w, cb->target, (eddy_vec3){v[0], v[1], v[2]});
	return eddy_collider_set_offset(w, cb->target, (eddy_vec3){v[0], v[1], v[2]});
}

typedef struct lua_system {
	eddy_system_id id;
	/* user value 1: the world userdata, kept alive by the handle */
} lua_system;

static void push_system(lua_State *L, int world_idx, eddy_system_id id)
{
	world_idx = lua_absindex(L, world_idx);
	lua_system *ls = lua_newuserdatauv(L, sizeof *ls, 1);
	ls->id = id;
	luaL_setmetatable(L, SYSTEM_MT);
	lua_pushvalue(L, world_idx);
	lua_setiuservalue(L, -2, 1);
}

static void check_writable(lua_State *L, const char *fn, const char *path, const char *dir);

/* A world made in safe mode writes files (render_points, export_particles:
 * their `path`) only where the scene itself may. */
static void check_safe_paths(lua_State *L, int world_idx, const lua_def *ld)
{
	lua_getiuservalue(L, world_idx, 1);
	if (lua_getfield(L, -1, "safe") == LUA_TTABLE) {
		lua_getfield(L, -1, "out");
		for (const eddy_lua_field *f = ld->k->fields; f->name; ++f)
			if (f->type == EDDY_LUA_STRING && strcmp(f->name, "path") == 0)
				check_writable(L, ld->k->name, (const char *)ld->def + f->offset, lua_tostring(L, -1));
		lua_pop(L, 1);
	}
	lua_pop(L, 2);
}

static int l_world_add(lua_State *L)
{
	lua_world *lw = check_idle_world(L, 1, "add");
	/* a node group (eddy.fluid{...}): plain Lua that adds its systems */
	if (lua_istable(L, 2) && lua_getfield(L, 2, "expand") == LUA_TFUNCTION) {
		lua_pushvalue(L, 2);
		lua_pushvalue(L, 1);
		lua_call(L, 2, 1);
		return 1;
	}
	lua_def *ld = luaL_testudata(L, 2, DEF_MT);
	if (!ld)
		return luaL_error(L,
		                  "add: expects a system made by eddy.<system>{...} or a group such as eddy.fluid{...}, e.g. "
		                  "world:add(eddy.gravity{}) (got %s)",
		                  luaL_typename(L, 2));
	check_safe_paths(L, 1, ld);
	eddy_world *w = lw->w;
	/* animators (offset, rotation): each must run before its collider, so
	 * they go in first */
	callback *cb[2] = {NULL, NULL};
	eddy_system_id anim[2] = {EDDY_NULL_SYSTEM, EDDY_NULL_SYSTEM};
	for (int u = 0; u < 2; ++u) {
		lua_getiuservalue(L, 2, u + 1);
		if (lua_isfunction(L, -1)) {
			cb[u] = calloc(1, sizeof *cb[u]);
			if (!cb[u]) {
				if (u)
					eddy_world_remove_system(w, anim[0]);
				return luaL_error(L, "add: out of memory");
			}
			cb[u]->L = lw->L;
			cb[u]->owner = lw;
			cb[u]->rotation = u == 1;
			lua_pushvalue(L, -1);
			cb[u]->fn = luaL_ref(L, LUA_REGISTRYINDEX);
			snprintf(cb[u]->what, sizeof cb[u]->what, "animate %s %s", ld->k->name, u ? "rotation" : "offset");
			eddy_custom_system_def cd = eddy_default_custom_system_def();
			cd.name = "animate";
			cd.step = animate_step;
			cd.limit = animate_limit;
			cd.destroy = callback_destroy;
			cd.user = cb[u];
			anim[u] = eddy_add_custom_system(w, &cd);
			if (!eddy_system_valid(w, anim[u])) {
				callback_destroy(cb[u]);
				if (u && cb[0])
					eddy_world_remove_system(w, anim[0]);
				return luaL_error(L, "%s", eddy_world_error(w));
			}
		}
		lua_pop(L, 1);
	}
	eddy_system_id id = ld->k->add(w, ld->def);
	if (!eddy_system_valid(w, id)) {
		for (int u = 0; u < 2; ++u)
			if (cb[u])
				eddy_world_remove_system(w, anim[u]);
		return luaL_error(L, "%s", eddy_world_error(w));
	}
	if (ld->has_pivot && eddy_collider_set_pivot(w, id, ld->pivot) != EDDY_OK)
		return luaL_error(L, "%s", eddy_world_error(w));
	for (int u = 0; u < 2; ++u) {
		if (cb[u]) {
			cb[u]->target = id;
			cb[u]->placed = eddy_world_time(w);
			/* place the collider where the function puts it at t = now */
			lua_getiuservalue(L, 2, u + 1);
			lua_pushnumber(L, eddy_world_time(w));
			lw->inside = u ? "a rotation function" : "an offset function";
			int rc = lua_pcall(L, 1, 1, 0);
			lw->inside = NULL;
			if (rc != LUA_OK)
				return lua_error(L);
			eddy_vec3 v = vec3_field(
				L, ld->k, u ? "rotation (returned by the function)" : "offset (returned by the function)", -1);
			lua_pop(L, 1);
			if ((u ? eddy_collider_set_rotation(w, id, v) : eddy_collider_set_offset(w, id, v)) != EDDY_OK)
				return luaL_error(L, "%s", eddy_world_error(w));
		} else if (u == 0 && ld->has_offset && eddy_collider_set_offset(w, id, ld->offset) != EDDY_OK) {
			return luaL_error(L, "%s", eddy_world_error(w));
		} else if (u == 1 && ld->has_rotation && eddy_collider_set_rotation(w, id, ld->rotation) != EDDY_OK) {
			return luaL_error(L, "%s", eddy_world_error(w));
		}
	}
	push_system(L, 1, id);
	return 1;
}

static int l_world_on_frame(lua_State *L)
{
	lua_world *lw = check_idle_world(L, 1, "on_frame");
	luaL_checktype(L, 2, LUA_TFUNCTION);
	callback *cb = calloc(1, sizeof *cb);
	if (!cb)
		return luaL_error(L, "on_frame: out of memory");
	cb->L = lw->L;
	cb->owner = lw;
	lua_pushvalue(L, 2);
	cb->fn = luaL_ref(L, LUA_REGISTRYINDEX);
	eddy_custom_system_def cd = eddy_default_custom_system_def();
	cd.name = "on_frame";
	cd.frame = on_frame_hook;
	cd.destroy = callback_destroy;
	cd.user = cb;
	eddy_system_id id = eddy_add_custom_system(lw->w, &cd);
	if (!eddy_system_valid(lw->w, id)) {
		callback_destroy(cb);
		return luaL_error(L, "%s", eddy_world_error(lw->w));
	}
	push_system(L, 1, id);
	return 1;
}

static int stepping(lua_State *L, lua_world *lw, eddy_status (*fn)(eddy_world *, double), double arg)
{
	lw->busy = 1;
	eddy_status st = fn(lw->w, arg);
	lw->busy = 0;
	if (st != EDDY_OK)
		return luaL_error(L, "%s", eddy_world_error(lw->w));
	return 0;
}

static eddy_status step_once(eddy_world *w, double unused)
{
	(void)unused;
	return eddy_world_step(w);
}

static int l_world_advance(lua_State *L)
{
	lua_world *lw = check_idle_world(L, 1, "advance");
	double s = luaL_checknumber(L, 2);
	if (!(s >= 0 && isfinite(s)))
		return luaL_error(L, "advance: 'seconds' must be >= 0 and finite (got %f)", s);
	/* frames are counted in an int */
	const double frames = s / eddy_world_frame_time(lw->w);
	if (!(frames <= (double)INT_MAX - eddy_world_frame(lw->w)))
		return luaL_error(L, "advance: %f s is %f frames, past the last frame a world counts (%d)", s, frames, INT_MAX);
	stepping(L, lw, eddy_world_advance, s);
	lua_settop(L, 1);
	return 1;
}

static int l_world_step(lua_State *L)
{
	lua_world *lw = check_idle_world(L, 1, "step");
	stepping(L, lw, step_once, 0);
	lua_pushnumber(L, eddy_world_last_dt(lw->w));
	return 1;
}

static int l_world_time(lua_State *L)
{
	lua_pushnumber(L, eddy_world_time(check_world(L, 1)->w));
	return 1;
}

static int l_world_frame(lua_State *L)
{
	lua_pushinteger(L, eddy_world_frame(check_world(L, 1)->w));
	return 1;
}

static int l_world_steps(lua_State *L)
{
	lua_pushinteger(L, (lua_Integer)eddy_world_steps(check_world(L, 1)->w));
	return 1;
}

static int l_world_count(lua_State *L)
{
	lua_pushinteger(L, (lua_Integer)eddy_world_particle_count(check_world(L, 1)->w));
	return 1;
}

static int push_text(lua_State *L, size_t (*fn)(const eddy_world *, char *, size_t), const eddy_world *w)
{
	size_t n = fn(w, NULL, 0);
	char *buf = malloc(n + 1);
	if (!buf)
		return luaL_error(L, "out of memory");
	fn(w, buf, n + 1);
	lua_pushlstring(L, buf, n);
	free(buf);
	return 1;
}

/* world:plan() -> text; world:plan{dot = true} -> Graphviz */
static int l_world_plan(lua_State *L)
{
	check_world(L, 1);
	bool dot = false;
	if (lua_istable(L, 2)) {
		lua_getfield(L, 2, "dot"); /* may run an __index that closes the world */
		dot = lua_toboolean(L, -1);
		lua_pop(L, 1);
	}
	return push_text(L, dot ? eddy_world_plan_dot : eddy_world_plan, check_world(L, 1)->w);
}

static int l_world_remove(lua_State *L)
{
	lua_world *lw = check_idle_world(L, 1, "remove");
	lua_system *ls = luaL_checkudata(L, 2, SYSTEM_MT);
	/* ids are per world: another world's handle could name a system here */
	lua_getiuservalue(L, 2, 1);
	bool mine = lua_touserdata(L, -1) == lw;
	lua_pop(L, 1);
	if (!mine)
		return luaL_error(L, "remove: the handle belongs to another world");
	if (eddy_world_remove_system(lw->w, ls->id) != EDDY_OK)
		return luaL_error(L, "%s", eddy_world_error(lw->w));
	return 0;
}

static int l_world_gravity(lua_State *L)
{
	const eddy_world_def *d = eddy_world_get_def(check_world(L, 1)->w);
	lua_createtable(L, 3, 0);
	lua_pushnumber(L, d->gravity.x);
	lua_rawseti(L, -2, 1);
	lua_pushnumber(L, d->gravity.y);
	lua_rawseti(L, -2, 2);
	lua_pushnumber(L, d->gravity.z);
	lua_rawseti(L, -2, 3);
	return 1;
}

/* world:stats(): the last completed frame's statistics as a table. */
static int l_world_stats(lua_State *L)
{
	lua_world *lw = check_world(L, 1);
	eddy_frame_stats s;
	eddy_world_frame_stats(lw->w, &s);
	lua_newtable(L);
	lua_pushinteger(L, s.frame);
	lua_setfield(L, -2, "frame");
	lua_pushnumber(L, s.time);
	lua_setfield(L, -2, "time");
	lua_pushinteger(L, (lua_Integer)s.steps);
	lua_setfield(L, -2, "steps");
	lua_pushnumber(L, s.dt_min);
	lua_setfield(L, -2, "dt_min");
	lua_pushnumber(L, s.dt_max);
	lua_setfield(L, -2, "dt_max");
	lua_pushstring(L, s.dt_limit);
	lua_setfield(L, -2, "dt_limit");
	lua_pushinteger(L, (lua_Integer)s.particles);
	lua_setfield(L, -2, "particles");
	lua_pushnumber(L, s.max_speed);
	lua_setfield(L, -2, "max_speed");
	lua_pushinteger(L, (lua_Integer)s.leaked);
	lua_setfield(L, -2, "leaked");
	lua_pushinteger(L, (lua_Integer)s.nonfinite);
	lua_setfield(L, -2, "nonfinite");
	lua_pushinteger(L, s.warnings);
	lua_setfield(L, -2, "warnings");
	char hash[24];
	snprintf(hash, sizeof hash, "%016llx", (unsigned long long)s.state_hash);
	lua_pushstring(L, hash);
	lua_setfield(L, -2, "state_hash");
	/* energy and momentum: nil without a particle mass (see eddy_frame_stats) */
	const struct {
		const char *name;
		double v;
	} energies[] = {{"particle_mass", s.particle_mass},
	                {"kinetic_energy", s.kinetic_energy},
	                {"potential_energy", s.potential_energy},
	                {"compression_energy", s.compression_energy},
	                {"energy", s.energy}};
	for (size_t i = 0; i < sizeof energies / sizeof energies[0]; ++i)
		if (isfinite(energies[i].v)) {
			lua_pushnumber(L, energies[i].v);
			lua_setfield(L, -2, energies[i].name);
		}
	if (isfinite(s.momentum[0])) {
		lua_createtable(L, 3, 0);
		for (int a = 0; a < 3; ++a) {
			lua_pushnumber(L, s.momentum[a]);
			lua_rawseti(L, -2, a + 1);
		}
		lua_setfield(L, -2, "momentum");
	}
	return 1;
}

/* world:warnings(): the run-time warnings raised so far, oldest first. */
static int l_world_warnings(lua_State *L)
{
	lua_world *lw = check_world(L, 1);
	const int n = eddy_world_warning_count(lw->w);
	lua_createtable(L, n, 0);
	for (int k = 0; k < n; ++k) {
		lua_pushstring(L, eddy_world_warning(lw->w, k));
		lua_rawseti(L, -2, k + 1);
	}
	return 1;
}

static int l_world_close(lua_State *L)
{
	lua_world *lw = luaL_checkudata(L, 1, WORLD_MT);
	if (lw->inside || lw->busy)
		check_idle_world(L, 1, "close");
	return l_world_gc(L);
}

/* ---- channels ------------------------------------------------------------ */

typedef struct lua_channel {
	char name[32];
	/* user value 1: the world userdata */
} lua_channel;

static const float *channel_data(lua_State *L, int idx, size_t *n)
{
	lua_channel *c = luaL_checkudata(L, idx, CHANNEL_MT);
	lua_getiuservalue(L, idx, 1);
	eddy_world *w = eddy_lua_toworld(L, -1);
	lua_pop(L, 1);
	*n = 0;
	return w ? eddy_world_channel(w, c->name, n) : NULL;
}

static int l_channel_len(lua_State *L)
{
	size_t n;
	channel_data(L, 1, &n);
	lua_pushinteger(L, (lua_Integer)n);
	return 1;
}

static int l_channel_index(lua_State *L)
{
	size_t n;
	const float *v = channel_data(L, 1, &n);
	lua_Integer i = lua_tointeger(L, 2);
	if (!v || i < 1 || (size_t)i > n)
		lua_pushnil(L);
	else
		lua_pushnumber(L, v[i - 1]);
	return 1;
}

static int l_world_channel(lua_State *L)
{
	lua_world *lw = check_world(L, 1);
	const char *name = luaL_checkstring(L, 2);
	eddy_column_id id = eddy_world_find_column(lw->w, name);
	if (id < 0 || strlen(name) >= sizeof((lua_channel *)0)->name)
		return luaL_error(L, "channel: no column named '%s'", name);
	eddy_column_info info;
	eddy_world_column_info(lw->w, id, &info);
	if (!info.allocated)
		return luaL_error(L, "channel: column '%s' is not allocated: no system in this scene reads or writes it", name);
	if (info.type != EDDY_F32)
		return luaL_error(L, "channel: column '%s' holds bytes, not numbers", name);
	lua_channel *c = lua_newuserdatauv(L, sizeof *c, 1);
	snprintf(c->name, sizeof c->name, "%s", name);
	luaL_setmetatable(L, CHANNEL_MT);
	lua_pushvalue(L, 1);
	lua_setiuservalue(L, -2, 1);
	return 1;
}

/* ---- system handles ------------------------------------------------------ */

static eddy_world *system_world(lua_State *L, int idx, lua_system **out)
{
	*out = luaL_checkudata(L, idx, SYSTEM_MT);
	lua_getiuservalue(L, idx, 1);
	eddy_world *w = eddy_lua_toworld(L, -1);
	lua_pop(L, 1);
	if (!w)
		luaL_error(L, "system handle: its world is closed");
	return w;
}

static int l_system_valid(lua_State *L)
{
	lua_system *ls;
	eddy_world *w = system_world(L, 1, &ls);
	lua_pushboolean(L, eddy_system_valid(w, ls->id));
	return 1;
}

static int l_system_name(lua_State *L)
{
	lua_system *ls;
	eddy_world *w = system_world(L, 1, &ls);
	eddy_system_info info;
	if (eddy_world_system_info(w, ls->id, &info) != EDDY_OK)
		return luaL_error(L, "stale system handle: the system was removed from the world");
	lua_pushstring(L, info.label);
	return 1;
}

/* h:set_group(text): tags the system with the node group that added it
 * (plans show it); h:group() reads it back. */
static int l_system_set_group(lua_State *L)
{
	lua_system *ls;
	eddy_world *w = system_world(L, 1, &ls);
	if (eddy_system_set_group(w, ls->id, luaL_optstring(L, 2, "")) != EDDY_OK)
		return luaL_error(L, "%s", eddy_world_error(w));
	return 0;
}

static int l_system_group(lua_State *L)
{
	lua_system *ls;
	eddy_world *w = system_world(L, 1, &ls);
	eddy_system_info info;
	if (eddy_world_system_info(w, ls->id, &info) != EDDY_OK)
		return luaL_error(L, "stale system handle: the system was removed from the world");
	lua_pushstring(L, info.group);
	return 1;
}

/* h:mass(): the particle mass an sph_density calibrated (kg); an error for
 * other systems, which have none. */
static int l_system_mass(lua_State *L)
{
	lua_system *ls;
	eddy_world *w = system_world(L, 1, &ls);
	eddy_system_info info;
	if (eddy_world_system_info(w, ls->id, &info) != EDDY_OK)
		return luaL_error(L, "stale system handle: the system was removed from the world");
	const float m = eddy_sph_particle_mass(w, ls->id);
	if (!(m > 0))
		return luaL_error(L, "%s has no particle mass (only sph_density calibrates one)", info.label);
	lua_pushnumber(L, m);
	return 1;
}

/* A collider's pose vector (offset or rotation) from Lua, and back. */
typedef eddy_status (*pose_set_fn)(eddy_world *, eddy_system_id, eddy_vec3);
typedef eddy_status (*pose_get_fn)(const eddy_world *, eddy_system_id, eddy_vec3 *);

static int set_pose(lua_State *L, const char *method, const char *field, pose_set_fn set)
{
	lua_system *ls;
	eddy_world *w = system_world(L, 1, &ls);
	const eddy_lua_kind k = {method, 0, NULL, NULL, NULL};
	eddy_vec3 v = vec3_field(L, &k, field, 2);
	if (!eddy_system_valid(w, ls->id))
		return luaL_error(L, "stale system handle: the system was removed from the world");
	if (set(w, ls->id, v) != EDDY_OK)
		return luaL_error(L, "%s", eddy_world_error(w));
	return 0;
}

static int get_pose(lua_State *L, const char *field, pose_get_fn get)
{
	lua_system *ls;
	eddy_world *w = system_world(L, 1, &ls);
	eddy_vec3 v;
	if (!eddy_system_valid(w, ls->id))
		return luaL_error(L, "stale system handle: the system was removed from the world");
	if (get(w, ls->id, &v) != EDDY_OK)
		return luaL_error(L, "%s: this system is not a collider", field);
	lua_createtable(L, 3, 0);
	lua_pushnumber(L, v.x);
	lua_rawseti(L, -2, 1);
	lua_pushnumber(L, v.y);
	lua_rawseti(L, -2, 2);
	lua_pushnumber(L, v.z);
	lua_rawseti(L, -2, 3);
	return 1;
}

static int l_system_set_offset(lua_State *L) { return set_pose(L, "set_offset", "offset", eddy_collider_set_offset); }
static int l_system_offset(lua_State *L) { return get_pose(L, "offset", eddy_collider_get_offset); }
static int l_system_set_rotation(lua_State *L)
{
	return set_pose(L, "set_rotation", "rotation", eddy_collider_set_rotation);
}
static int l_system_rotation(lua_State *L) { return get_pose(L, "rotation", eddy_collider_get_rotation); }

/* ---- safe mode ------------------------------------------------------------
 *
 * A safe scene can compute, read files, write files under the output
 * directory and require Lua modules; it cannot run commands, write elsewhere,
 * load native code or bytecode (Lua does not verify bytecode: a crafted chunk
 * corrupts memory), or reach the debug library. What it cannot use is
 * replaced by a function raising "<name> is not available in safe mode", so a
 * scene learns why at the line that tried. */

#define SAFE_MODE "safe mode (--safe)"

static int l_refused(lua_State *L)
{
	return luaL_error(L, "%s is not available in " SAFE_MODE, lua_tostring(L, lua_upvalueindex(1)));
}

static void set_refused(lua_State *L, int t, const char *lib, const char *name)
{
	lua_pushfstring(L, "%s.%s", lib, name);
	lua_pushcclosure(L, l_refused, 1);
	lua_setfield(L, t, name);
}

/* Writes into out (cap bytes) the absolute form of path with "." components
 * and repeated slashes dropped; false if it has a ".." component (refused
 * rather than resolved: with symbolic links, ".." is not lexical) or does not
 * fit. */
static bool absolute_path(const char *path, char *out, size_t cap)
{
	size_t n = 0;
	if (path[0] != '/') {
		if (!getcwd(out, cap))
			return false;
		n = strlen(out);
		if (n == 1)
			n = 0; /* the root: its components follow a single '/' */
	}
	for (const char *p = path; *p;) {
		while (*p == '/')
			++p;
		size_t len = strcspn(p, "/");
		if (len == 2 && p[0] == '.' && p[1] == '.')
			return false;
		if (len && !(len == 1 && p[0] == '.')) {
			if (n + 1 + len + 1 > cap)
				return false;
			out[n++] = '/';
			memcpy(out + n, p, len);
			n += len;
		}
		p += len;
	}
	if (n == 0 || (n == 1 && out[0] == '/')) {
		if (cap < 2)
			return false;
		n = 0;
		out[n++] = '/';
	}
	out[n] = '\0';
	return true;
}

static bool below(const char *path, const char *dir)
{
	size_t n = strlen(dir);
	if (n == 1 && dir[0] == '/')
		return path[0] == '/' && path[1] != '\0';
	return strncmp(path, dir, n) == 0 && path[n] == '/' && path[n + 1] != '\0';
}

/* Whether dir names path or a directory above it, lexically and with symbolic
 * links resolved (where both exist). */
static bool within(const char *path, const char *dir)
{
	char *buf = malloc(2 * 8192);
	if (!buf)
		return false;
	bool ok = absolute_path(path, buf, 8192) && absolute_path(dir, buf + 8192, 8192) &&
	          (strcmp(buf, buf + 8192) == 0 || below(buf, buf + 8192));
	free(buf);
	char *rp = ok ? realpath(path, NULL) : NULL, *rd = ok ? realpath(dir, NULL) : NULL;
	if (rp && rd)
		ok = strcmp(rp, rd) == 0 || below(rp, rd);
	free(rp);
	free(rd);
	return ok;
}

/* Raises an error unless path may be opened for writing in safe mode: a file
 * strictly below dir (the output directory; NULL for none), with no ".."
 * component, whose directory is below dir or dir itself also with symbolic
 * links resolved, and which is not itself a symbolic link. */
static void check_writable(lua_State *L, const char *fn, const char *path, const char *dir)
{
	if (!dir)
		luaL_error(L, "%s: cannot write '%s': " SAFE_MODE " has no output directory to write in", fn, path);
	enum { CAP = 8192 };
	char *buf = malloc(2 * CAP);
	if (!buf)
		luaL_error(L, "%s: out of memory", fn);
	char *abs_path = buf, *abs_dir = buf + CAP;
	const char *why = NULL;
	if (!absolute_path(path, abs_path, CAP))
		why = "a path with a '..' component is not written in " SAFE_MODE;
	else if (!absolute_path(dir, abs_dir, CAP) || !below(abs_path, abs_dir))
		why = "files are written only under the output directory in " SAFE_MODE;
	else {
		struct stat st;
		char *slash = strrchr(abs_path, '/');
		*slash = '\0';
		char *real_parent = realpath(abs_path[0] ? abs_path : "/", NULL);
		*slash = '/';
		char *real_dir = realpath(abs_dir, NULL);
		if (lstat(abs_path, &st) == 0 && S_ISLNK(st.st_mode))
			why = "a symbolic link is not written through in " SAFE_MODE;
		/* a parent that does not exist fails the open by itself */
		else if (real_parent && (!real_dir || (strcmp(real_parent, real_dir) != 0 && !below(real_parent, real_dir))))
			why =
				"files are written only under the output directory in " SAFE_MODE " (a symbolic link leads out of it)";
		free(real_parent);
		free(real_dir);
	}
	free(buf);
	if (why)
		luaL_error(L, "%s: cannot write '%s': %s ('%s')", fn, path, why, dir);
}

/* io.open(name, mode): any file for reading ("r", "rb"); other modes only
 * under the output directory. Upvalues: io.open, the output directory. */
static int l_safe_open(lua_State *L)
{
	const char *path = luaL_checkstring(L, 1);
	const char *mode = luaL_optstring(L, 2, "r");
	if (mode[0] != 'r' || strchr(mode, '+'))
		check_writable(L, "io.open", path, lua_tostring(L, lua_upvalueindex(2)));
	lua_settop(L, 2);
	lua_pushvalue(L, lua_upvalueindex(1));
	lua_insert(L, 1);
	lua_call(L, 2, LUA_MULTRET);
	return lua_gettop(L);
}

/* io.output(name) opens name for writing: the same rule as io.open. */
static int l_safe_output(lua_State *L)
{
	if (lua_type(L, 1) == LUA_TSTRING)
		check_writable(L, "io.output", lua_tostring(L, 1), lua_tostring(L, lua_upvalueindex(2)));
	int n = lua_gettop(L);
	lua_pushvalue(L, lua_upvalueindex(1));
	lua_insert(L, 1);
	lua_call(L, n, LUA_MULTRET);
	return lua_gettop(L);
}

/* luaL_loadfilex in text mode, with a message naming the file when it holds
 * a binary chunk (Lua's says only "attempt to load a binary chunk"). */
static int load_text_file(lua_State *L, const char *name)
{
	int rc = luaL_loadfilex(L, name, "t");
	const char *msg = rc == LUA_OK ? NULL : lua_tostring(L, -1);
	if (msg && strstr(msg, "attempt to load a binary chunk")) {
		lua_pop(L, 1);
		lua_pushfstring(L, "%s: a binary (precompiled) chunk: eddy loads Lua source only", name ? name : "stdin");
	}
	return rc;
}

/* The environment a chunk gets when the caller names none: upvalue 2 (the
 * sandbox's globals), or the argument at idx when given. */
static void set_chunk_env(lua_State *L, int nargs, int idx)
{
	if (nargs >= idx)
		lua_pushvalue(L, idx);
	else
		lua_pushvalue(L, lua_upvalueindex(2));
	if (!lua_setupvalue(L, -2, 1))
		lua_pop(L, 1);
}

/* load(chunk, name, mode, env) with mode forced to "t". Upvalues: load, the
 * sandbox's globals. */
static int l_safe_load(lua_State *L)
{
	int n = lua_gettop(L);
	luaL_checkany(L, 1);
	lua_settop(L, 4);
	if (lua_type(L, 1) == LUA_TSTRING && lua_tostring(L, 1)[0] == LUA_SIGNATURE[0]) {
		luaL_pushfail(L);
		lua_pushliteral(L, "load: binary chunks (string.dump) cannot be loaded in " SAFE_MODE);
		return 2;
	}
	lua_pushvalue(L, lua_upvalueindex(1));
	lua_pushvalue(L, 1);
	lua_pushvalue(L, 2);
	lua_pushliteral(L, "t");
	if (n >= 4)
		lua_pushvalue(L, 4);
	else
		lua_pushvalue(L, lua_upvalueindex(2));
	lua_call(L, 4, 2);
	if (lua_isnil(L, -2))
		return 2;
	lua_pop(L, 1);
	return 1;
}

/* loadfile(name, mode, env), text only. Upvalues: unused, the globals. */
static int l_safe_loadfile(lua_State *L)
{
	int n = lua_gettop(L);
	const char *name = luaL_optstring(L, 1, NULL);
	if (load_text_file(L, name) != LUA_OK) {
		luaL_pushfail(L);
		lua_insert(L, -2);
		return 2;
	}
	set_chunk_env(L, n, 3);
	return 1;
}

/* dofile(name), text only. */
static int l_safe_dofile(lua_State *L)
{
	const char *name = luaL_optstring(L, 1, NULL);
	lua_settop(L, 1);
	if (load_text_file(L, name) != LUA_OK)
		return lua_error(L);
	set_chunk_env(L, 0, 1);
	lua_call(L, 0, LUA_MULTRET);
	return lua_gettop(L) - 1;
}

/* package.searchers[1]: package.preload[name]. Upvalue 1: package. */
static int l_search_preload(lua_State *L)
{
	const char *name = luaL_checkstring(L, 1);
	lua_getfield(L, lua_upvalueindex(1), "preload");
	if (!lua_istable(L, -1) || lua_getfield(L, -1, name) == LUA_TNIL) {
		lua_pushfstring(L, "no field package.preload['%s']", name);
		return 1;
	}
	lua_pushliteral(L, ":preload:");
	return 2;
}

/* package.searchers[2]: a Lua file on package.path, loaded as text with the
 * sandbox's globals. Upvalues: package, the globals. */
static int l_search_text(lua_State *L)
{
	const char *name = luaL_checkstring(L, 1);
	lua_settop(L, 1);
	lua_getfield(L, lua_upvalueindex(1), "path");
	const char *path = lua_tostring(L, -1);
	if (!path)
		return luaL_error(L, "'package.path' must be a string");
	const char *file = luaL_gsub(L, name, ".", "/");
	lua_pushliteral(L, ""); /* the files tried */
	for (const char *p = path; *p;) {
		size_t len = strcspn(p, ";");
		if (len) {
			lua_pushlstring(L, p, len);
			const char *fn = luaL_gsub(L, lua_tostring(L, -1), "?", file);
			lua_remove(L, -2);
			FILE *f = fopen(fn, "r");
			if (f) {
				fclose(f);
				if (load_text_file(L, fn) != LUA_OK)
					return luaL_error(L, "error loading module '%s' from file '%s':\n\t%s", name, fn,
					                  lua_tostring(L, -1));
				set_chunk_env(L, 0, 1);
				lua_pushvalue(L, -2);
				return 2;
			}
			lua_pushfstring(L, "%sno file '%s'", lua_rawlen(L, -2) ? "\n\t" : "", fn);
			lua_remove(L, -2);
			lua_concat(L, 2);
		}
		p += len + (p[len] == ';');
	}
	return 1;
}

static int l_search_native(lua_State *L)
{
	lua_pushliteral(L, "C modules (package.cpath) are not loaded in " SAFE_MODE);
	return 1;
}

/* require(name) over package.loaded and package.searchers of upvalue 1. */
static int l_safe_require(lua_State *L)
{
	const char *name = luaL_checkstring(L, 1);
	lua_settop(L, 1);
	if (lua_getfield(L, lua_upvalueindex(1), "loaded") != LUA_TTABLE) /* 2 */
		return luaL_error(L, "'package.loaded' must be a table");
	if (lua_getfield(L, 2, name) != LUA_TNIL && lua_toboolean(L, -1))
		return 1;
	lua_pop(L, 1);
	if (lua_getfield(L, lua_upvalueindex(1), "searchers") != LUA_TTABLE) /* 3 */
		return luaL_error(L, "'package.searchers' must be a table");
	lua_pushliteral(L, ""); /* 4: why each searcher found nothing */
	for (int i = 1;; ++i) {
		if (lua_rawgeti(L, 3, i) == LUA_TNIL)
			return luaL_error(L, "module '%s' not found:%s", name, lua_tostring(L, 4));
		lua_pushstring(L, name);
		lua_call(L, 1, 2); /* 5, 6 */
		if (lua_isfunction(L, 5))
			break;
		if (lua_isstring(L, 5)) {
			lua_pop(L, 1);
			lua_pushliteral(L, "\n\t");
			lua_insert(L, 5);
			lua_concat(L, 3);
		} else {
			lua_pop(L, 2);
		}
	}
	lua_remove(L, 4); /* 4: loader, 5: its data */
	lua_pushvalue(L, 4);
	lua_pushvalue(L, 1);
	lua_pushvalue(L, 5);
	lua_call(L, 2, 1);
	if (!lua_isnil(L, -1))
		lua_setfield(L, 2, name);
	else
		lua_pop(L, 1);
	if (lua_getfield(L, 2, name) == LUA_TNIL) {
		lua_pop(L, 1);
		lua_pushboolean(L, 1);
		lua_pushvalue(L, -1);
		lua_setfield(L, 2, name);
	}
	lua_pushvalue(L, 5);
	return 2;
}

static int l_load_scene(lua_State *L);

/* Makes the globals env, with its os, io and package tables and the eddy
 * module in package.loaded, safe; out (a string, or nil for none) is where
 * files may be written. */
static void make_safe(lua_State *L, int env, int os, int io, int pkg, int out)
{
	static const char *const os_kept[] = {"time", "clock", "date", "getenv", "difftime", NULL};
	lua_pushnil(L);
	while (lua_next(L, os)) {
		lua_pop(L, 1);
		bool kept = lua_type(L, -1) != LUA_TSTRING;
		for (int i = 0; !kept && os_kept[i]; ++i)
			kept = strcmp(lua_tostring(L, -1), os_kept[i]) == 0;
		if (!kept)
			set_refused(L, os, "os", lua_tostring(L, -1)); /* an existing field: next stays valid */
	}

	lua_getfield(L, io, "open");
	lua_pushvalue(L, out);
	lua_pushcclosure(L, l_safe_open, 2);
	lua_setfield(L, io, "open");
	lua_getfield(L, io, "output");
	lua_pushvalue(L, out);
	lua_pushcclosure(L, l_safe_output, 2);
	lua_setfield(L, io, "output");
	set_refused(L, io, "io", "popen");
	set_refused(L, io, "io", "tmpfile");

	set_refused(L, pkg, "package", "loadlib");
	lua_pushliteral(L, "");
	lua_setfield(L, pkg, "cpath");
	lua_createtable(L, 3, 0);
	lua_pushvalue(L, pkg);
	lua_pushcclosure(L, l_search_preload, 1);
	lua_rawseti(L, -2, 1);
	lua_pushvalue(L, pkg);
	lua_pushvalue(L, env);
	lua_pushcclosure(L, l_search_text, 2);
	lua_rawseti(L, -2, 2);
	lua_pushcfunction(L, l_search_native);
	lua_rawseti(L, -2, 3);
	lua_setfield(L, pkg, "searchers");
	lua_getfield(L, pkg, "loaded");
	if (lua_istable(L, -1)) {
		lua_pushnil(L);
		lua_setfield(L, -2, "debug");
		/* the sandbox's eddy: worlds that write files only under out, and
		 * load_scene only into sandboxes as narrow (as a closure may call
		 * them after the scene has returned, the limit is in the functions,
		 * not in a flag set while the scene runs) */
		if (lua_getfield(L, -1, "eddy") == LUA_TTABLE) {
			lua_createtable(L, 0, 1);
			lua_pushvalue(L, out);
			lua_setfield(L, -2, "out");
			lua_pushvalue(L, -1);
			lua_pushcclosure(L, l_world, 1);
			lua_setfield(L, -3, "world");
			lua_pushcclosure(L, l_load_scene, 1);
			lua_setfield(L, -2, "load_scene");
		}
		lua_pop(L, 1);
	}
	lua_pop(L, 1);

	lua_pushvalue(L, pkg);
	lua_pushcclosure(L, l_safe_require, 1);
	lua_setfield(L, env, "require");
	lua_getfield(L, env, "load");
	lua_pushvalue(L, env);
	lua_pushcclosure(L, l_safe_load, 2);
	lua_setfield(L, env, "load");
	lua_pushnil(L);
	lua_pushvalue(L, env);
	lua_pushcclosure(L, l_safe_loadfile, 2);
	lua_setfield(L, env, "loadfile");
	lua_pushnil(L);
	lua_pushvalue(L, env);
	lua_pushcclosure(L, l_safe_dofile, 2);
	lua_setfield(L, env, "dofile");
	lua_pushnil(L);
	lua_setfield(L, env, "debug");
}

/* Pushes the standard library `name` as loaded in this state (a table). */
static void push_loaded(lua_State *L, const char *name)
{
	luaL_getsubtable(L, LUA_REGISTRYINDEX, LUA_LOADED_TABLE);
	if (lua_getfield(L, -1, name) != LUA_TTABLE)
		luaL_error(L, "safe mode needs the standard library '%s' (luaL_openlibs)", name);
	lua_remove(L, -2);
}

static int sandbox_in_place(lua_State *L)
{
	const int out = 1;
	lua_pushglobaltable(L);
	push_loaded(L, "os");
	push_loaded(L, "io");
	push_loaded(L, "package");
	make_safe(L, out + 1, out + 2, out + 3, out + 4, out);
	return 0;
}

int eddy_lua_sandbox(lua_State *L, const char *out_dir)
{
	lua_pushcfunction(L, sandbox_in_place);
	if (out_dir)
		lua_pushstring(L, out_dir);
	else
		lua_pushnil(L);
	return lua_pcall(L, 1, 0, 0);
}

/* Pushes a shallow copy of the table on top, in place of it. */
static void copy_table(lua_State *L)
{
	lua_newtable(L);
	lua_pushnil(L);
	while (lua_next(L, -3)) {
		lua_pushvalue(L, -2);
		lua_insert(L, -2);
		lua_rawset(L, -4);
	}
	lua_remove(L, -2);
}

/* eddy.load_scene(path [, {safe = true, out = dir}]): runs the scene file
 * (text only) in fresh globals and returns what it returns. safe (default
 * true) gives those globals only what eddy run --safe gives a scene, writing
 * under out (default eddy.out_dir()); out also becomes eddy.out_dir(). With
 * safe = false the fresh globals fall back to this state's. */
static int l_load_scene(lua_State *L)
{
	const char *path = luaL_checkstring(L, 1);
	bool safe = true;
	/* called from a sandbox: upvalue 1 is {out = its output directory} */
	const bool sandboxed = lua_type(L, lua_upvalueindex(1)) == LUA_TTABLE;
	lua_settop(L, 2);
	lua_pushnil(L); /* 3: the output directory */
	if (!lua_isnil(L, 2)) {
		luaL_checktype(L, 2, LUA_TTABLE);
		lua_pushnil(L);
		while (lua_next(L, 2)) {
			lua_pop(L, 1);
			const char *k = lua_type(L, -1) == LUA_TSTRING ? lua_tostring(L, -1) : "";
			if (strcmp(k, "safe") != 0 && strcmp(k, "out") != 0)
				return luaL_error(L, "load_scene: unknown option '%s' (options: safe, out)",
				                  luaL_tolstring(L, -1, NULL));
		}
		if (lua_getfield(L, 2, "safe") != LUA_TNIL) {
			if (!lua_isboolean(L, -1))
				return luaL_error(L, "load_scene: 'safe' must be true or false (got %s)", luaL_typename(L, -1));
			safe = lua_toboolean(L, -1);
			if (sandboxed && !safe)
				return luaL_error(L, "load_scene: safe = false is not available in " SAFE_MODE);
		}
		lua_pop(L, 1);
		if (lua_getfield(L, 2, "out") != LUA_TNIL) {
			if (lua_type(L, -1) != LUA_TSTRING)
				return luaL_error(L, "load_scene: 'out' must be a directory name (got %s)", luaL_typename(L, -1));
			if (sandboxed) {
				lua_getfield(L, lua_upvalueindex(1), "out");
				const char *dir = lua_tostring(L, -1);
				if (!dir || !within(lua_tostring(L, -2), dir))
					return luaL_error(L, "load_scene: 'out' must be the output directory or below it in " SAFE_MODE);
				lua_pop(L, 1);
			}
			lua_pushvalue(L, -1);
			lua_setfield(L, LUA_REGISTRYINDEX, OUT_DIR_KEY); /* the scene's eddy.out_dir() */
			lua_replace(L, 3);
		} else {
			lua_pop(L, 1);
		}
	}
	if (lua_isnil(L, 3)) {
		if (sandboxed)
			lua_getfield(L, lua_upvalueindex(1), "out");
		else
			lua_getfield(L, LUA_REGISTRYINDEX, OUT_DIR_KEY);
		lua_replace(L, 3);
	}
	lua_remove(L, 2); /* 2: the output directory (or nil) */
	lua_newtable(L);  /* 3: the scene's globals */
	if (!safe) {
		lua_createtable(L, 0, 1);
		lua_pushglobaltable(L);
		lua_setfield(L, -2, "__index");
		lua_setmetatable(L, 3);
	} else {
		static const char *const base[] = {
			"assert",   "collectgarbage", "error",  "getmetatable", "ipairs",   "next",   "pairs",        "pcall",
			"print",    "rawequal",       "rawget", "rawlen",       "rawset",   "select", "setmetatable", "tonumber",
			"tostring", "type",           "xpcall", "warn",         "_VERSION", NULL};
		static const char *const libs[] = {"string", "math", "table", "utf8", "coroutine", "os", "io", NULL};
		push_loaded(L, "_G");
		for (int i = 0; base[i]; ++i) {
			lua_getfield(L, -1, base[i]);
			lua_setfield(L, 3, base[i]);
		}
		lua_pop(L, 1);
		lua_newtable(L); /* 4: package.loaded */
		for (int i = 0; libs[i]; ++i) {
			push_loaded(L, libs[i]);
			copy_table(L);
			lua_pushvalue(L, -1);
			lua_setfield(L, 3, libs[i]);
			lua_setfield(L, 4, libs[i]);
		}
		push_loaded(L, "eddy");
		copy_table(L); /* make_safe replaces its world and load_scene */
		lua_setfield(L, 4, "eddy");
		lua_pushvalue(L, 3);
		lua_setfield(L, 3, "_G");
		lua_pushvalue(L, 3);
		lua_setfield(L, 4, "_G");
		push_loaded(L, "package"); /* 5: the host's, for path, config, searchpath */
		lua_newtable(L);           /* 6 */
		static const char *const pkg_fields[] = {"path", "config", "searchpath", NULL};
		for (int i = 0; pkg_fields[i]; ++i) {
			lua_getfield(L, 5, pkg_fields[i]);
			lua_setfield(L, 6, pkg_fields[i]);
		}
		lua_newtable(L);
		lua_setfield(L, 6, "preload");
		lua_pushvalue(L, 4);
		lua_setfield(L, 6, "loaded");
		lua_pushvalue(L, 6);
		lua_setfield(L, 3, "package");
		lua_pushvalue(L, 6);
		lua_setfield(L, 4, "package");
		lua_getfield(L, 3, "os"); /* 7 */
		lua_getfield(L, 3, "io"); /* 8 */
		push_loaded(L, "_G");
		lua_getfield(L, -1, "load");
		lua_setfield(L, 3, "load"); /* make_safe wraps it */
		lua_pop(L, 1);
		make_safe(L, 3, 7, 8, 6, 2);
		lua_settop(L, 3);
	}
	if (load_text_file(L, path) != LUA_OK)
		return lua_error(L);
	lua_pushvalue(L, 3);
	lua_setupvalue(L, -2, 1);
	lua_call(L, 0, LUA_MULTRET);
	return lua_gettop(L) - 3;
}

/* ---- module functions ---------------------------------------------------- */

void eddy_lua_set_param(lua_State *L, const char *key, const char *value)
{
	lua_getfield(L, LUA_REGISTRYINDEX, PARAMS_KEY);
	lua_pushstring(L, value);
	lua_setfield(L, -2, key);
	lua_pop(L, 1);
}

void eddy_lua_push_unused_params(lua_State *L)
{
	lua_newtable(L);
	int out = lua_gettop(L);
	lua_getfield(L, LUA_REGISTRYINDEX, PARAMS_KEY);
	lua_getfield(L, LUA_REGISTRYINDEX, PARAMS_USED_KEY);
	lua_pushnil(L);
	while (lua_next(L, -3)) {
		lua_pop(L, 1);
		lua_pushvalue(L, -1);
		lua_rawget(L, -3);
		bool used = lua_toboolean(L, -1);
		lua_pop(L, 1);
		if (!used) {
			lua_pushvalue(L, -1);
			lua_pushboolean(L, 1);
			lua_rawset(L, out);
		}
	}
	lua_pop(L, 2);
}

void eddy_lua_set_out_dir(lua_State *L, const char *dir)
{
	lua_pushstring(L, dir);
	lua_setfield(L, LUA_REGISTRYINDEX, OUT_DIR_KEY);
}

void eddy_lua_set_threads(lua_State *L, int threads)
{
	if (threads > 0)
		lua_pushinteger(L, threads);
	else
		lua_pushnil(L);
	lua_setfield(L, LUA_REGISTRYINDEX, THREADS_KEY);
}

void eddy_lua_take_frame_fields(lua_State *L, int world_idx)
{
	world_idx = lua_absindex(L, world_idx);
	lua_getiuservalue(L, world_idx, 1);
	lua_getfield(L, -1, "frame_fields");
	lua_pushnil(L);
	lua_setfield(L, -3, "frame_fields");
	lua_remove(L, -2);
}

/* eddy.param(name, default): the --set value converted to default's type. */
static int l_param(lua_State *L)
{
	const char *name = luaL_checkstring(L, 1);
	if (lua_isnone(L, 2))
		return luaL_error(L, "param: '%s' needs a default value, e.g. eddy.param(\"%s\", 0.02)", name, name);
	lua_getfield(L, LUA_REGISTRYINDEX, PARAMS_USED_KEY);
	lua_pushboolean(L, 1);
	lua_setfield(L, -2, name);
	lua_pop(L, 1);
	lua_getfield(L, LUA_REGISTRYINDEX, PARAMS_KEY);
	lua_getfield(L, -1, name);
	if (lua_isnil(L, -1)) {
		lua_pushvalue(L, 2);
		return 1;
	}
	const char *v = lua_tostring(L, -1);
	switch (lua_type(L, 2)) {
	case LUA_TNUMBER:
		if (!lua_stringtonumber(L, v))
			return luaL_error(L, "--set %s=%s: '%s' must be a number", name, v, name);
		return 1;
	case LUA_TBOOLEAN:
		if (strcmp(v, "true") == 0 || strcmp(v, "1") == 0)
			lua_pushboolean(L, 1);
		else if (strcmp(v, "false") == 0 || strcmp(v, "0") == 0)
			lua_pushboolean(L, 0);
		else
			return luaL_error(L, "--set %s=%s: '%s' must be true or false", name, v, name);
		return 1;
	default:
		return 1; /* strings (and nil defaults) take the text as given */
	}
}

/* eddy.fluid{...}: the fluid node group of lua/eddy/fluid.lua (plain Lua
 * over the systems here), loaded on first use through require. */
static int l_fluid(lua_State *L)
{
	lua_settop(L, 1);
	lua_getglobal(L, "require");
	lua_pushliteral(L, "eddy.fluid");
	lua_call(L, 1, 1);
	lua_getfield(L, -1, "new");
	lua_pushvalue(L, 1);
	lua_call(L, 1, 1);
	return 1;
}

/* eddy.out_dir(default): the --out directory, or default. */
static int l_out_dir(lua_State *L)
{
	lua_getfield(L, LUA_REGISTRYINDEX, OUT_DIR_KEY);
	if (lua_isnil(L, -1))
		lua_pushvalue(L, 1);
	return 1;
}

static const luaL_Reg world_methods[] = {
	{"add", l_world_add},           {"advance", l_world_advance},
	{"step", l_world_step},         {"time", l_world_time},
	{"frame", l_world_frame},       {"steps", l_world_steps},
	{"count", l_world_count},       {"channel", l_world_channel},
	{"plan", l_world_plan},         {"on_frame", l_world_on_frame},
	{"remove", l_world_remove},     {"stats", l_world_stats},
	{"gravity", l_world_gravity},   {"close", l_world_close},
	{"warnings", l_world_warnings}, {NULL, NULL},
};

static const luaL_Reg system_methods[] = {
	{"valid", l_system_valid},       {"name", l_system_name},
	{"mass", l_system_mass},         {"set_offset", l_system_set_offset},
	{"offset", l_system_offset},     {"set_rotation", l_system_set_rotation},
	{"rotation", l_system_rotation}, {"set_group", l_system_set_group},
	{"group", l_system_group},       {NULL, NULL},
};

static int l_def_tostring(lua_State *L)
{
	lua_def *ld = luaL_checkudata(L, 1, DEF_MT);
	lua_pushfstring(L, "eddy.%s def", ld->k->name);
	return 1;
}

static int l_world_tostring(lua_State *L)
{
	lua_world *lw = luaL_checkudata(L, 1, WORLD_MT);
	if (!lw->w)
		lua_pushliteral(L, "eddy world (closed)");
	else
		lua_pushfstring(L, "eddy world (%d systems, %d particles, t = %f s)", eddy_world_system_count(lw->w),
		                (int)eddy_world_particle_count(lw->w), eddy_world_time(lw->w));
	return 1;
}

static void new_metatable(lua_State *L, const char *name, const luaL_Reg *methods)
{
	luaL_newmetatable(L, name);
	if (methods) {
		lua_newtable(L);
		luaL_setfuncs(L, methods, 0);
		lua_setfield(L, -2, "__index");
	}
}

int luaopen_eddy(lua_State *L)
{
	new_metatable(L, WORLD_MT, world_methods);
	lua_pushcfunction(L, l_world_gc);
	lua_setfield(L, -2, "__gc");
	lua_pushcfunction(L, l_world_close);
	lua_setfield(L, -2, "__close");
	lua_pushcfunction(L, l_world_tostring);
	lua_setfield(L, -2, "__tostring");
	lua_pop(L, 1);

	new_metatable(L, DEF_MT, NULL);
	lua_pushcfunction(L, l_def_tostring);
	lua_setfield(L, -2, "__tostring");
	lua_pop(L, 1);

	new_metatable(L, SYSTEM_MT, system_methods);
	lua_pop(L, 1);

	new_metatable(L, CHANNEL_MT, NULL);
	lua_pushcfunction(L, l_channel_len);
	lua_setfield(L, -2, "__len");
	lua_pushcfunction(L, l_channel_index);
	lua_setfield(L, -2, "__index");
	lua_pop(L, 1);

	/* registry tables: params (--set), params read, worlds by pointer (weak) */
	if (lua_getfield(L, LUA_REGISTRYINDEX, PARAMS_KEY) != LUA_TTABLE) {
		lua_newtable(L);
		lua_setfield(L, LUA_REGISTRYINDEX, PARAMS_KEY);
		lua_newtable(L);
		lua_setfield(L, LUA_REGISTRYINDEX, PARAMS_USED_KEY);
	}
	lua_pop(L, 1);
	lua_newtable(L);
	lua_newtable(L);
	lua_pushliteral(L, "v");
	lua_setfield(L, -2, "__mode");
	lua_setmetatable(L, -2);
	lua_setfield(L, LUA_REGISTRYINDEX, WORLDS_KEY);

	lua_newtable(L);
	lua_pushcfunction(L, l_world);
	lua_setfield(L, -2, "world");
	lua_pushcfunction(L, l_param);
	lua_setfield(L, -2, "param");
	lua_pushcfunction(L, l_out_dir);
	lua_setfield(L, -2, "out_dir");
	lua_pushcfunction(L, l_load_scene);
	lua_setfield(L, -2, "load_scene");
	lua_pushcfunction(L, l_fluid);
	lua_setfield(L, -2, "fluid");
	for (size_t l = 0; l < sizeof kind_lists / sizeof kind_lists[0]; ++l)
		for (const eddy_lua_kind *k = kind_lists[l]; k->name; ++k) {
			lua_pushlightuserdata(L, (void *)(uintptr_t)k);
			lua_pushcclosure(L, l_make_def, 1);
			lua_setfield(L, -2, k->name);
		}
	lua_pushliteral(L, EDDY_VERSION_STRING);
	lua_setfield(L, -2, "version");
	return 1;
}
