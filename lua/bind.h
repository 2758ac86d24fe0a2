/* SPDX-License-Identifier: MIT */
/* How the Lua binding describes a def: its fields (name, type, offset) and
 * the C functions that fill its defaults and add it to a world. Each area of
 * the engine lists its kinds in its own bind_*.c file; eddy_lua.c reads the
 * lists, checks field names and types where the scene wrote them, and leaves
 * ranges to the C add functions. */
#ifndef EDDY_BIND_H
#define EDDY_BIND_H

#include <stddef.h>

#include "eddy.h"

typedef enum eddy_lua_field_type {
	EDDY_LUA_FLOAT,       /* float */
	EDDY_LUA_DOUBLE,      /* double */
	EDDY_LUA_INT,         /* int */
	EDDY_LUA_INT64,       /* int64_t, >= 0 */
	EDDY_LUA_U64,         /* uint64_t */
	EDDY_LUA_BOOL,        /* bool */
	EDDY_LUA_VEC3,        /* eddy_vec3 from {x, y, z} */
	EDDY_LUA_BOUNDS,      /* two eddy_vec3 (min, max) from {{...}, {...}} */
	EDDY_LUA_ENUM,        /* int from one of the strings in choices (index) */
	EDDY_LUA_STRING,      /* char[size] from a string */
	EDDY_LUA_STRING_LIST, /* char[size]: a table of strings (or one string), joined by spaces */
	EDDY_LUA_OFFSET,      /* collider offset: a vector or a function of time */
	EDDY_LUA_ROTATION,    /* collider rotation: an axis-angle vector (degrees) or a function of time */
	EDDY_LUA_PIVOT,       /* collider pivot: a vector (eddy_collider_set_pivot) */
	EDDY_LUA_INPUT_PATH   /* char[size] from a string: a file the system reads (safe mode
	                         reads anywhere, and checks only EDDY_LUA_STRING paths as outputs) */
} eddy_lua_field_type;

typedef struct eddy_lua_field {
	const char *name;
	eddy_lua_field_type type;
	size_t offset;
	const char *const *choices; /* EDDY_LUA_ENUM: NULL-terminated */
	size_t size;                /* EDDY_LUA_STRING: bytes of the char array */
} eddy_lua_field;

typedef struct eddy_lua_kind {
	const char *name; /* eddy.<name>{...} */
	size_t def_size;
	void (*defaults)(void *def);
	eddy_system_id (*add)(eddy_world *w, const void *def); /* NULL for the world */
	const eddy_lua_field *fields;                          /* ends with a NULL name */
} eddy_lua_kind;

#define EDDY_LUA_FIELD(T, f, type)        \
	{                                     \
#f, type, offsetof(T, f), NULL, 0 \
	}
#define EDDY_LUA_ENUM_FIELD(T, f, choices)            \
	{                                                 \
#f, EDDY_LUA_ENUM, offsetof(T, f), choices, 0 \
	}
#define EDDY_LUA_STRING_FIELD(T, f)                                    \
	{                                                                  \
#f, EDDY_LUA_STRING, offsetof(T, f), NULL, sizeof(((T *)0)->f) \
	}
#define EDDY_LUA_END                     \
	{                                    \
		NULL, EDDY_LUA_FLOAT, 0, NULL, 0 \
	}

/* Wrappers with the generic signatures for eddy_default_<k>_def and eddy_add_<k>. */
#define EDDY_LUA_KIND_FUNCS(k)                                                             \
	static void k##_defaults(void *d) { *(eddy_##k##_def *)d = eddy_default_##k##_def(); } \
	static eddy_system_id k##_add(eddy_world *w, const void *d) { return eddy_add_##k(w, (const eddy_##k##_def *)d); }
#define EDDY_LUA_KIND(k)                                              \
	{                                                                 \
#k, sizeof(eddy_##k##_def), k##_defaults, k##_add, k##_fields \
	}
#define EDDY_LUA_KIND_END         \
	{                             \
		NULL, 0, NULL, NULL, NULL \
	}

/* The kind lists, each ending with EDDY_LUA_KIND_END. */
extern const eddy_lua_kind eddy_lua_core_kinds[];
/* more lists: add them here and in kind_lists[] of eddy_lua.c */

/* SPH: eddy_lua_sph_kinds (bind_sph.c) */
extern const eddy_lua_kind eddy_lua_sph_kinds[];

/* FLIP: eddy_lua_flip_kinds (bind_flip.c) */
extern const eddy_lua_kind eddy_lua_flip_kinds[];

/* renderer: eddy_lua_render_kinds (bind_render.c) */
extern const eddy_lua_kind eddy_lua_render_kinds[];

/* meshes and particle files: eddy_lua_mesh_kinds (bind_mesh.c) */
extern const eddy_lua_kind eddy_lua_mesh_kinds[];

extern const eddy_lua_kind eddy_lua_world_kind;

#endif
