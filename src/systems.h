/* SPDX-License-Identifier: MIT */
/* The built-in system kinds. Each lives in its own sys_*.c file and defines
 * eddy__kind_<name>; this list lets the pipeline name the systems that would
 * fix an order error. */
#ifndef EDDY_SYSTEMS_H
#define EDDY_SYSTEMS_H

#include "core.h"

#define EDDY_BUILTIN_SYSTEMS(X) \
	X(emit_box)                 \
	X(emit_nozzle)              \
	X(gravity)                  \
	X(integrate)                \
	X(collide_box)              \
	X(collide_sphere)           \
	X(collide_plane)            \
	/* meshes (mesh.c) */       \
	X(collide_mesh)             \
	X(emit_mesh)                \
	X(emit_particles)           \
	/* SPH */                   \
	X(sph_density)              \
	X(sph_pressure)             \
	X(sph_viscosity)            \
	X(sph_surface_tension)      \
	X(sph_boundary_box)         \
	X(sph_dfsph)                \
                                \
	/* FLIP */                  \
	X(flip_p2g)                 \
	X(flip_boundary)            \
	X(flip_surface)             \
	X(flip_pressure)            \
	X(flip_extrapolate)         \
	X(flip_g2p)                 \
	X(flip_advect)              \
	X(flip_reseed)              \
                                \
	/* end */

#define EDDY_KIND_DECL(ident) extern const eddy_system_vtable eddy__kind_##ident;
EDDY_BUILTIN_SYSTEMS(EDDY_KIND_DECL)
#undef EDDY_KIND_DECL

#endif
