/* SPDX-License-Identifier: MIT */
/* Lua descriptions of the renderer's and the exporters' defs (render/):
 * eddy.render_points{...}, eddy.export_particles{...}, eddy.surface_mesh{...}
 * and eddy.render_surface{...}. */
#include "bind.h"

static const char *const projection_choices[] = {"perspective", "orthographic", NULL};
static const char *const colormap_choices[] = {"viridis", "plasma", "gray", NULL};
/* in eddy_export_format's order: the index is the enum value */
static const char *const format_choices[] = {"ply", "vtk", "vtp", NULL};

static const eddy_lua_field render_points_fields[] = {
	EDDY_LUA_FIELD(eddy_render_points_def, width, EDDY_LUA_INT),
	EDDY_LUA_FIELD(eddy_render_points_def, height, EDDY_LUA_INT),
	EDDY_LUA_FIELD(eddy_render_points_def, supersample, EDDY_LUA_INT),
	EDDY_LUA_FIELD(eddy_render_points_def, eye, EDDY_LUA_VEC3),
	EDDY_LUA_FIELD(eddy_render_points_def, target, EDDY_LUA_VEC3),
	EDDY_LUA_FIELD(eddy_render_points_def, up, EDDY_LUA_VEC3),
	EDDY_LUA_FIELD(eddy_render_points_def, fov, EDDY_LUA_FLOAT),
	EDDY_LUA_ENUM_FIELD(eddy_render_points_def, projection, projection_choices),
	EDDY_LUA_FIELD(eddy_render_points_def, ortho_height, EDDY_LUA_FLOAT),
	EDDY_LUA_FIELD(eddy_render_points_def, background, EDDY_LUA_VEC3),
	EDDY_LUA_FIELD(eddy_render_points_def, radius, EDDY_LUA_FLOAT),
	EDDY_LUA_STRING_FIELD(eddy_render_points_def, color_by),
	EDDY_LUA_FIELD(eddy_render_points_def, color, EDDY_LUA_VEC3),
	EDDY_LUA_ENUM_FIELD(eddy_render_points_def, colormap, colormap_choices),
	EDDY_LUA_FIELD(eddy_render_points_def, value_min, EDDY_LUA_FLOAT),
	EDDY_LUA_FIELD(eddy_render_points_def, value_max, EDDY_LUA_FLOAT),
	EDDY_LUA_FIELD(eddy_render_points_def, outline_domain, EDDY_LUA_BOOL),
	EDDY_LUA_FIELD(eddy_render_points_def, outline_colliders, EDDY_LUA_BOOL),
	EDDY_LUA_FIELD(eddy_render_points_def, outline_color, EDDY_LUA_VEC3),
	EDDY_LUA_STRING_FIELD(eddy_render_points_def, path),
	EDDY_LUA_FIELD(eddy_render_points_def, every, EDDY_LUA_INT),
	EDDY_LUA_END,
};

static const eddy_lua_field export_particles_fields[] = {
	EDDY_LUA_ENUM_FIELD(eddy_export_particles_def, format, format_choices),
	{"channels", EDDY_LUA_STRING_LIST, offsetof(eddy_export_particles_def, channels), NULL,
     sizeof(((eddy_export_particles_def *)0)->channels)},
	EDDY_LUA_STRING_FIELD(eddy_export_particles_def, path),
	EDDY_LUA_FIELD(eddy_export_particles_def, every, EDDY_LUA_INT),
	EDDY_LUA_END,
};

static const eddy_lua_field surface_mesh_fields[] = {
	EDDY_LUA_FIELD(eddy_surface_mesh_def, spacing, EDDY_LUA_FLOAT),
	EDDY_LUA_FIELD(eddy_surface_mesh_def, support, EDDY_LUA_FLOAT),
	EDDY_LUA_FIELD(eddy_surface_mesh_def, voxel, EDDY_LUA_FLOAT),
	{"format", EDDY_LUA_STRING_LIST, offsetof(eddy_surface_mesh_def, format), NULL,
     sizeof(((eddy_surface_mesh_def *)0)->format)},
	EDDY_LUA_STRING_FIELD(eddy_surface_mesh_def, path),
	EDDY_LUA_FIELD(eddy_surface_mesh_def, every, EDDY_LUA_INT),
	EDDY_LUA_END,
};

static const eddy_lua_field render_surface_fields[] = {
	EDDY_LUA_FIELD(eddy_render_surface_def, width, EDDY_LUA_INT),
	EDDY_LUA_FIELD(eddy_render_surface_def, height, EDDY_LUA_INT),
	EDDY_LUA_FIELD(eddy_render_surface_def, supersample, EDDY_LUA_INT),
	EDDY_LUA_FIELD(eddy_render_surface_def, eye, EDDY_LUA_VEC3),
	EDDY_LUA_FIELD(eddy_render_surface_def, target, EDDY_LUA_VEC3),
	EDDY_LUA_FIELD(eddy_render_surface_def, up, EDDY_LUA_VEC3),
	EDDY_LUA_FIELD(eddy_render_surface_def, fov, EDDY_LUA_FLOAT),
	EDDY_LUA_ENUM_FIELD(eddy_render_surface_def, projection, projection_choices),
	EDDY_LUA_FIELD(eddy_render_surface_def, ortho_height, EDDY_LUA_FLOAT),
	EDDY_LUA_FIELD(eddy_render_surface_def, background, EDDY_LUA_VEC3),
	EDDY_LUA_FIELD(eddy_render_surface_def, spacing, EDDY_LUA_FLOAT),
	EDDY_LUA_FIELD(eddy_render_surface_def, support, EDDY_LUA_FLOAT),
	EDDY_LUA_FIELD(eddy_render_surface_def, voxel, EDDY_LUA_FLOAT),
	EDDY_LUA_FIELD(eddy_render_surface_def, color, EDDY_LUA_VEC3),
	EDDY_LUA_FIELD(eddy_render_surface_def, draw_colliders, EDDY_LUA_BOOL),
	EDDY_LUA_FIELD(eddy_render_surface_def, collider_color, EDDY_LUA_VEC3),
	EDDY_LUA_FIELD(eddy_render_surface_def, outline_domain, EDDY_LUA_BOOL),
	EDDY_LUA_FIELD(eddy_render_surface_def, outline_color, EDDY_LUA_VEC3),
	EDDY_LUA_STRING_FIELD(eddy_render_surface_def, path),
	EDDY_LUA_FIELD(eddy_render_surface_def, every, EDDY_LUA_INT),
	EDDY_LUA_END,
};

EDDY_LUA_KIND_FUNCS(render_points)
EDDY_LUA_KIND_FUNCS(export_particles)
EDDY_LUA_KIND_FUNCS(surface_mesh)
EDDY_LUA_KIND_FUNCS(render_surface)

const eddy_lua_kind eddy_lua_render_kinds[] = {
	EDDY_LUA_KIND(render_points),
	EDDY_LUA_KIND(export_particles),
	EDDY_LUA_KIND(surface_mesh),
	EDDY_LUA_KIND(render_surface),
	EDDY_LUA_KIND_END,
};
