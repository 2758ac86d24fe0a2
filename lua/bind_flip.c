/* SPDX-License-Identifier: MIT */
/* Lua descriptions of the FLIP systems' defs (sys_flip_*.c). */
#include "bind.h"

static const char *const solver_choices[] = {"pcg", "cholmod", "hypre", "mg", NULL};
static const char *const transfer_choices[] = {"flip", "pic", "apic", NULL};

static const eddy_lua_field flip_p2g_fields[] = {
	EDDY_LUA_FIELD(eddy_flip_p2g_def, mark_radius, EDDY_LUA_FLOAT),
	EDDY_LUA_END,
};
static const eddy_lua_field flip_boundary_fields[] = {
	EDDY_LUA_FIELD(eddy_flip_boundary_def, margin, EDDY_LUA_FLOAT),
	EDDY_LUA_FIELD(eddy_flip_boundary_def, open_sides, EDDY_LUA_BOOL),
	EDDY_LUA_END,
};
static const eddy_lua_field flip_surface_fields[] = {
	EDDY_LUA_FIELD(eddy_flip_surface_def, sigma, EDDY_LUA_FLOAT),
	EDDY_LUA_END,
};
static const eddy_lua_field flip_pressure_fields[] = {
	EDDY_LUA_ENUM_FIELD(eddy_flip_pressure_def, solver, solver_choices),
	EDDY_LUA_FIELD(eddy_flip_pressure_def, density, EDDY_LUA_FLOAT),
	EDDY_LUA_FIELD(eddy_flip_pressure_def, tolerance, EDDY_LUA_DOUBLE),
	EDDY_LUA_FIELD(eddy_flip_pressure_def, max_iterations, EDDY_LUA_INT),
	EDDY_LUA_FIELD(eddy_flip_pressure_def, theta_min, EDDY_LUA_FLOAT),
	EDDY_LUA_END,
};
static const eddy_lua_field flip_extrapolate_fields[] = {
	EDDY_LUA_FIELD(eddy_flip_extrapolate_def, layers, EDDY_LUA_INT),
	EDDY_LUA_END,
};
static const eddy_lua_field flip_g2p_fields[] = {
	EDDY_LUA_FIELD(eddy_flip_g2p_def, flip_ratio, EDDY_LUA_FLOAT),
	EDDY_LUA_ENUM_FIELD(eddy_flip_g2p_def, transfer, transfer_choices),
	EDDY_LUA_END,
};
static const eddy_lua_field flip_advect_fields[] = {
	EDDY_LUA_FIELD(eddy_flip_advect_def, wall_gap, EDDY_LUA_FLOAT),
	EDDY_LUA_END,
};
static const eddy_lua_field flip_reseed_fields[] = {
	EDDY_LUA_FIELD(eddy_flip_reseed_def, min_per_cell, EDDY_LUA_INT),
	EDDY_LUA_FIELD(eddy_flip_reseed_def, max_per_cell, EDDY_LUA_INT),
	EDDY_LUA_END,
};

EDDY_LUA_KIND_FUNCS(flip_p2g)
EDDY_LUA_KIND_FUNCS(flip_boundary)
EDDY_LUA_KIND_FUNCS(flip_surface)
EDDY_LUA_KIND_FUNCS(flip_pressure)
EDDY_LUA_KIND_FUNCS(flip_extrapolate)
EDDY_LUA_KIND_FUNCS(flip_g2p)
EDDY_LUA_KIND_FUNCS(flip_advect)
EDDY_LUA_KIND_FUNCS(flip_reseed)

const eddy_lua_kind eddy_lua_flip_kinds[] = {
	EDDY_LUA_KIND(flip_p2g),      EDDY_LUA_KIND(flip_boundary),    EDDY_LUA_KIND(flip_surface),
	EDDY_LUA_KIND(flip_pressure), EDDY_LUA_KIND(flip_extrapolate), EDDY_LUA_KIND(flip_g2p),
	EDDY_LUA_KIND(flip_advect),   EDDY_LUA_KIND(flip_reseed),      EDDY_LUA_KIND_END,
};
