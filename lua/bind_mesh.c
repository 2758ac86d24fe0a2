/* SPDX-License-Identifier: MIT */
/* Lua descriptions of the mesh and particle-file systems' defs (mesh.c,
 * sys_collide_mesh.c, sys_emit_mesh.c, sys_emit_particles.c). */
#include "bind.h"

#define INPUT_PATH(T)                                                                \
	{                                                                                \
		"path", EDDY_LUA_INPUT_PATH, offsetof(T, path), NULL, sizeof(((T *)0)->path) \
	}

static const eddy_lua_field collide_mesh_fields[] = {
	INPUT_PATH(eddy_collide_mesh_def),
	EDDY_LUA_FIELD(eddy_collide_mesh_def, scale, EDDY_LUA_VEC3),
	EDDY_LUA_FIELD(eddy_collide_mesh_def, rotate, EDDY_LUA_VEC3),
	EDDY_LUA_FIELD(eddy_collide_mesh_def, translate, EDDY_LUA_VEC3),
	EDDY_LUA_FIELD(eddy_collide_mesh_def, cell_size, EDDY_LUA_FLOAT),
	EDDY_LUA_FIELD(eddy_collide_mesh_def, inside, EDDY_LUA_BOOL),
	EDDY_LUA_FIELD(eddy_collide_mesh_def, open, EDDY_LUA_BOOL),
	{"restitution", EDDY_LUA_FLOAT,
     offsetof(eddy_collide_mesh_def, response) + offsetof(eddy_collider_response, restitution), NULL, 0},
	{"friction", EDDY_LUA_FLOAT, offsetof(eddy_collide_mesh_def, response) + offsetof(eddy_collider_response, friction),
     NULL, 0},
	{"offset", EDDY_LUA_OFFSET, 0, NULL, 0},
	{"rotation", EDDY_LUA_ROTATION, 0, NULL, 0},
	{"pivot", EDDY_LUA_PIVOT, 0, NULL, 0},
	EDDY_LUA_END,
};
static const eddy_lua_field emit_mesh_fields[] = {
	INPUT_PATH(eddy_emit_mesh_def),
	EDDY_LUA_FIELD(eddy_emit_mesh_def, scale, EDDY_LUA_VEC3),
	EDDY_LUA_FIELD(eddy_emit_mesh_def, rotate, EDDY_LUA_VEC3),
	EDDY_LUA_FIELD(eddy_emit_mesh_def, translate, EDDY_LUA_VEC3),
	EDDY_LUA_FIELD(eddy_emit_mesh_def, spacing, EDDY_LUA_FLOAT),
	EDDY_LUA_FIELD(eddy_emit_mesh_def, jitter, EDDY_LUA_FLOAT),
	EDDY_LUA_FIELD(eddy_emit_mesh_def, velocity, EDDY_LUA_VEC3),
	EDDY_LUA_FIELD(eddy_emit_mesh_def, start, EDDY_LUA_DOUBLE),
	EDDY_LUA_END,
};
static const eddy_lua_field emit_particles_fields[] = {
	INPUT_PATH(eddy_emit_particles_def),
	EDDY_LUA_FIELD(eddy_emit_particles_def, spacing, EDDY_LUA_FLOAT),
	EDDY_LUA_FIELD(eddy_emit_particles_def, velocity, EDDY_LUA_VEC3),
	EDDY_LUA_FIELD(eddy_emit_particles_def, start, EDDY_LUA_DOUBLE),
	EDDY_LUA_END,
};

EDDY_LUA_KIND_FUNCS(collide_mesh)
EDDY_LUA_KIND_FUNCS(emit_mesh)
EDDY_LUA_KIND_FUNCS(emit_particles)

const eddy_lua_kind eddy_lua_mesh_kinds[] = {
	EDDY_LUA_KIND(collide_mesh),
	EDDY_LUA_KIND(emit_mesh),
	EDDY_LUA_KIND(emit_particles),
	EDDY_LUA_KIND_END,
};
