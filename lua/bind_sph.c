/* SPDX-License-Identifier: MIT */
/* Lua descriptions of the SPH systems' defs. */
#include "bind.h"

static const char *const eos_choices[] = {"linear", "tait", NULL};
static const char *const density_choices[] = {"summation", "continuity", NULL};

static const eddy_lua_field sph_density_fields[] = {
	EDDY_LUA_FIELD(eddy_sph_density_def, radius, EDDY_LUA_FLOAT),
	EDDY_LUA_FIELD(eddy_sph_density_def, spacing, EDDY_LUA_FLOAT),
	EDDY_LUA_FIELD(eddy_sph_density_def, rest_density, EDDY_LUA_FLOAT),
	EDDY_LUA_FIELD(eddy_sph_density_def, stiffness, EDDY_LUA_FLOAT),
	EDDY_LUA_ENUM_FIELD(eddy_sph_density_def, eos, eos_choices),
	EDDY_LUA_FIELD(eddy_sph_density_def, tait_gamma, EDDY_LUA_FLOAT),
	EDDY_LUA_ENUM_FIELD(eddy_sph_density_def, density, density_choices),
	EDDY_LUA_FIELD(eddy_sph_density_def, diffusion, EDDY_LUA_FLOAT),
	EDDY_LUA_FIELD(eddy_sph_density_def, verlet_list, EDDY_LUA_BOOL),
	EDDY_LUA_END,
};
static const eddy_lua_field sph_pressure_fields[] = {
	EDDY_LUA_FIELD(eddy_sph_pressure_def, scale, EDDY_LUA_FLOAT),
	EDDY_LUA_END,
};
static const eddy_lua_field sph_viscosity_fields[] = {
	EDDY_LUA_FIELD(eddy_sph_viscosity_def, viscosity, EDDY_LUA_FLOAT),
	EDDY_LUA_FIELD(eddy_sph_viscosity_def, artificial, EDDY_LUA_FLOAT),
	EDDY_LUA_END,
};
static const eddy_lua_field sph_surface_tension_fields[] = {
	EDDY_LUA_FIELD(eddy_sph_surface_tension_def, tension, EDDY_LUA_FLOAT),
	EDDY_LUA_FIELD(eddy_sph_surface_tension_def, threshold, EDDY_LUA_FLOAT),
	EDDY_LUA_END,
};
static const eddy_lua_field sph_boundary_box_fields[] = {
	EDDY_LUA_FIELD(eddy_sph_boundary_box_def, min, EDDY_LUA_VEC3),
	EDDY_LUA_FIELD(eddy_sph_boundary_box_def, max, EDDY_LUA_VEC3),
	EDDY_LUA_FIELD(eddy_sph_boundary_box_def, spacing, EDDY_LUA_FLOAT),
	EDDY_LUA_END,
};

static const eddy_lua_field sph_dfsph_fields[] = {
	EDDY_LUA_FIELD(eddy_sph_dfsph_def, max_density_error, EDDY_LUA_FLOAT),
	EDDY_LUA_FIELD(eddy_sph_dfsph_def, max_iterations, EDDY_LUA_INT),
	EDDY_LUA_FIELD(eddy_sph_dfsph_def, divergence_solver, EDDY_LUA_BOOL),
	EDDY_LUA_FIELD(eddy_sph_dfsph_def, max_divergence_error, EDDY_LUA_FLOAT),
	EDDY_LUA_FIELD(eddy_sph_dfsph_def, max_divergence_iterations, EDDY_LUA_INT),
	EDDY_LUA_FIELD(eddy_sph_dfsph_def, coarse_grid, EDDY_LUA_BOOL),
	EDDY_LUA_FIELD(eddy_sph_dfsph_def, shift, EDDY_LUA_FLOAT),
	EDDY_LUA_FIELD(eddy_sph_dfsph_def, hydrostatic_start, EDDY_LUA_BOOL),
	EDDY_LUA_END,
};

EDDY_LUA_KIND_FUNCS(sph_density)
EDDY_LUA_KIND_FUNCS(sph_pressure)
EDDY_LUA_KIND_FUNCS(sph_viscosity)
EDDY_LUA_KIND_FUNCS(sph_surface_tension)
EDDY_LUA_KIND_FUNCS(sph_boundary_box)
EDDY_LUA_KIND_FUNCS(sph_dfsph)

const eddy_lua_kind eddy_lua_sph_kinds[] = {
	EDDY_LUA_KIND(sph_density),
	EDDY_LUA_KIND(sph_pressure),
	EDDY_LUA_KIND(sph_viscosity),
	EDDY_LUA_KIND(sph_surface_tension),
	EDDY_LUA_KIND(sph_boundary_box),
	EDDY_LUA_KIND(sph_dfsph),
	EDDY_LUA_KIND_END,
};
