/* SPDX-License-Identifier: MIT */
/* Lua descriptions of the world def and the core systems' defs. */
#include "bind.h"

#define RESPONSE_FIELDS(T)                                                                                           \
	{"restitution", EDDY_LUA_FLOAT, offsetof(T, response) + offsetof(eddy_collider_response, restitution), NULL, 0}, \
		{"friction", EDDY_LUA_FLOAT, offsetof(T, response) + offsetof(eddy_collider_response, friction), NULL, 0},   \
		{"offset", EDDY_LUA_OFFSET, 0, NULL, 0}, {"rotation", EDDY_LUA_ROTATION, 0, NULL, 0},                        \
	{                                                                                                                \
		"pivot", EDDY_LUA_PIVOT, 0, NULL, 0                                                                          \
	}

static const char *const escape_choices[] = {"error", "remove", NULL};

static const eddy_lua_field world_fields[] = {
	{"bounds", EDDY_LUA_BOUNDS, offsetof(eddy_world_def, bounds_min), NULL, 0},
	EDDY_LUA_FIELD(eddy_world_def, gravity, EDDY_LUA_VEC3),
	EDDY_LUA_FIELD(eddy_world_def, fps, EDDY_LUA_DOUBLE),
	EDDY_LUA_FIELD(eddy_world_def, duration, EDDY_LUA_DOUBLE),
	EDDY_LUA_FIELD(eddy_world_def, cfl, EDDY_LUA_DOUBLE),
	EDDY_LUA_FIELD(eddy_world_def, dt_max, EDDY_LUA_DOUBLE),
	EDDY_LUA_FIELD(eddy_world_def, dt_min, EDDY_LUA_DOUBLE),
	EDDY_LUA_FIELD(eddy_world_def, max_steps_per_frame, EDDY_LUA_INT),
	EDDY_LUA_FIELD(eddy_world_def, cell_size, EDDY_LUA_DOUBLE),
	EDDY_LUA_FIELD(eddy_world_def, seed, EDDY_LUA_U64),
	EDDY_LUA_FIELD(eddy_world_def, threads, EDDY_LUA_INT),
	EDDY_LUA_ENUM_FIELD(eddy_world_def, escape, escape_choices),
	EDDY_LUA_FIELD(eddy_world_def, check_finite, EDDY_LUA_BOOL),
	EDDY_LUA_FIELD(eddy_world_def, settle_steps, EDDY_LUA_INT),
	EDDY_LUA_END,
};
static const char *const shape_choices[] = {"block", "ellipsoid", NULL};
static const eddy_lua_field emit_box_fields[] = {
	EDDY_LUA_FIELD(eddy_emit_box_def, min, EDDY_LUA_VEC3),
	EDDY_LUA_FIELD(eddy_emit_box_def, max, EDDY_LUA_VEC3),
	EDDY_LUA_FIELD(eddy_emit_box_def, spacing, EDDY_LUA_FLOAT),
	EDDY_LUA_FIELD(eddy_emit_box_def, jitter, EDDY_LUA_FLOAT),
	EDDY_LUA_FIELD(eddy_emit_box_def, velocity, EDDY_LUA_VEC3),
	EDDY_LUA_FIELD(eddy_emit_box_def, start, EDDY_LUA_DOUBLE),
	EDDY_LUA_ENUM_FIELD(eddy_emit_box_def, shape, shape_choices),
	EDDY_LUA_END,
};
static const eddy_lua_field emit_nozzle_fields[] = {
	EDDY_LUA_FIELD(eddy_emit_nozzle_def, center, EDDY_LUA_VEC3),
	EDDY_LUA_FIELD(eddy_emit_nozzle_def, radius, EDDY_LUA_FLOAT),
	EDDY_LUA_FIELD(eddy_emit_nozzle_def, direction, EDDY_LUA_VEC3),
	EDDY_LUA_FIELD(eddy_emit_nozzle_def, speed, EDDY_LUA_FLOAT),
	EDDY_LUA_FIELD(eddy_emit_nozzle_def, spacing, EDDY_LUA_FLOAT),
	EDDY_LUA_FIELD(eddy_emit_nozzle_def, start, EDDY_LUA_DOUBLE),
	EDDY_LUA_FIELD(eddy_emit_nozzle_def, duration, EDDY_LUA_DOUBLE),
	EDDY_LUA_FIELD(eddy_emit_nozzle_def, max_particles, EDDY_LUA_INT64),
	EDDY_LUA_END,
};
static const eddy_lua_field gravity_fields[] = {EDDY_LUA_FIELD(eddy_gravity_def, scale, EDDY_LUA_FLOAT), EDDY_LUA_END};
static const eddy_lua_field integrate_fields[] = {EDDY_LUA_FIELD(eddy_integrate_def, max_speed, EDDY_LUA_FLOAT),
                                                  EDDY_LUA_END};
static const eddy_lua_field collide_box_fields[] = {
	EDDY_LUA_FIELD(eddy_collide_box_def, min, EDDY_LUA_VEC3),
	EDDY_LUA_FIELD(eddy_collide_box_def, max, EDDY_LUA_VEC3),
	EDDY_LUA_FIELD(eddy_collide_box_def, inside, EDDY_LUA_BOOL),
	EDDY_LUA_FIELD(eddy_collide_box_def, sph_walls, EDDY_LUA_BOOL),
	RESPONSE_FIELDS(eddy_collide_box_def),
	EDDY_LUA_END,
};
static const eddy_lua_field collide_sphere_fields[] = {
	EDDY_LUA_FIELD(eddy_collide_sphere_def, center, EDDY_LUA_VEC3),
	EDDY_LUA_FIELD(eddy_collide_sphere_def, radius, EDDY_LUA_FLOAT),
	EDDY_LUA_FIELD(eddy_collide_sphere_def, inside, EDDY_LUA_BOOL),
	RESPONSE_FIELDS(eddy_collide_sphere_def),
	EDDY_LUA_END,
};
static const eddy_lua_field collide_plane_fields[] = {
	EDDY_LUA_FIELD(eddy_collide_plane_def, point, EDDY_LUA_VEC3),
	EDDY_LUA_FIELD(eddy_collide_plane_def, normal, EDDY_LUA_VEC3),
	RESPONSE_FIELDS(eddy_collide_plane_def),
	EDDY_LUA_END,
};

EDDY_LUA_KIND_FUNCS(emit_box)
EDDY_LUA_KIND_FUNCS(emit_nozzle)
EDDY_LUA_KIND_FUNCS(gravity)
EDDY_LUA_KIND_FUNCS(integrate)
EDDY_LUA_KIND_FUNCS(collide_box)
EDDY_LUA_KIND_FUNCS(collide_sphere)
EDDY_LUA_KIND_FUNCS(collide_plane)

static void world_defaults(void *d) { *(eddy_world_def *)d = eddy_default_world_def(); }

const eddy_lua_kind eddy_lua_world_kind = {"world", sizeof(eddy_world_def), world_defaults, NULL, world_fields};

const eddy_lua_kind eddy_lua_core_kinds[] = {
	EDDY_LUA_KIND(emit_box),    EDDY_LUA_KIND(emit_nozzle),    EDDY_LUA_KIND(gravity),       EDDY_LUA_KIND(integrate),
	EDDY_LUA_KIND(collide_box), EDDY_LUA_KIND(collide_sphere), EDDY_LUA_KIND(collide_plane), EDDY_LUA_KIND_END,
};
