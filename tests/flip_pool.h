/* SPDX-License-Identifier: MIT */
/* Shared by the FLIP tests and benchmarks: the pipeline in eddy.fluid's
 * order, water placed on the engine's seeding lattice, and the free-surface
 * level as flip_pressure sees it. */
#ifndef EDDY_FLIP_POOL_H
#define EDDY_FLIP_POOL_H

#include <math.h>
#include <stdbool.h>
#include <stdlib.h>

#include "eddy.h"

/* The defs of the FLIP pipeline, gravity to flip_advect; a test sets what it
 * varies in flip_default_defs()'s. */
typedef struct flip_defs {
	eddy_gravity_def gravity;
	eddy_flip_p2g_def p2g;
	eddy_flip_boundary_def boundary;
	eddy_flip_surface_def surface;
	eddy_flip_pressure_def pressure;
	eddy_flip_extrapolate_def extrapolate;
	eddy_flip_g2p_def g2p;
	eddy_flip_advect_def advect;
} flip_defs;

static inline flip_defs flip_default_defs(void)
{
	return (flip_defs){eddy_default_gravity_def(),       eddy_default_flip_p2g_def(),
	                   eddy_default_flip_boundary_def(), eddy_default_flip_surface_def(),
	                   eddy_default_flip_pressure_def(), eddy_default_flip_extrapolate_def(),
	                   eddy_default_flip_g2p_def(),      eddy_default_flip_advect_def()};
}

/* Adds the pipeline in eddy.fluid's order (colliders and flip_reseed go
 * after it). False if the world refused a system (its error says why). */
static inline bool flip_add_pipeline(eddy_world *w, const flip_defs *d)
{
	return eddy_system_valid(w, eddy_add_gravity(w, &d->gravity)) &&
	       eddy_system_valid(w, eddy_add_flip_p2g(w, &d->p2g)) &&
	       eddy_system_valid(w, eddy_add_flip_boundary(w, &d->boundary)) &&
	       eddy_system_valid(w, eddy_add_flip_surface(w, &d->surface)) &&
	       eddy_system_valid(w, eddy_add_flip_pressure(w, &d->pressure)) &&
	       eddy_system_valid(w, eddy_add_flip_extrapolate(w, &d->extrapolate)) &&
	       eddy_system_valid(w, eddy_add_flip_g2p(w, &d->g2p)) &&
	       eddy_system_valid(w, eddy_add_flip_advect(w, &d->advect));
}

/* 2 x 2 x 2 particles per cell of size h over [lo, hi] (cell aligned), at
 * rest. False if the particles could not be allocated or added. */
static inline bool pool_fill(eddy_world *w, double h, eddy_vec3 lo, eddy_vec3 hi)
{
	const int nx = (int)lround((hi.x - lo.x) / h * 2), ny = (int)lround((hi.y - lo.y) / h * 2),
			  nz = (int)lround((hi.z - lo.z) / h * 2);
	const size_t n = (size_t)nx * ny * nz;
	eddy_vec3 *p = malloc(n * sizeof *p);
	if (!p)
		return false;
	size_t q = 0;
	for (int k = 0; k < nz; ++k)
		for (int j = 0; j < ny; ++j)
			for (int i = 0; i < nx; ++i, ++q)
				p[q] = (eddy_vec3){(float)(lo.x + (i + 0.5) * h / 2), (float)(lo.y + (j + 0.5) * h / 2),
				                   (float)(lo.z + (k + 0.5) * h / 2)};
	const bool ok = eddy_world_add_particles(w, n, p, NULL) == EDDY_OK;
	free(p);
	return ok;
}

/* Mean height (m) of the free surface over the columns: in each column the
 * top crossing of flip_phi from < 0 to >= 0, linear between cell centres,
 * measured from the tank floor at y = 0. With no air trapped under the
 * surface this is (water volume + submerged solid volume) / tank area. NaN
 * when the world has no flip_phi. */
static inline double pool_mean_level(eddy_world *w)
{
	const eddy_grid_info g = eddy_world_grid(w);
	const float *phi = eddy_world_channel(w, "flip_phi", NULL);
	if (!phi)
		return NAN;
	double sum = 0;
	for (int k = 0; k < g.nz; ++k)
		for (int i = 0; i < g.nx; ++i) {
			double lev = 0;
			for (int j = g.ny - 1; j >= 0; --j) {
				const float p = phi[i + (size_t)g.nx * ((size_t)j + (size_t)g.ny * k)];
				if (p < 0) {
					const float pa = j + 1 < g.ny ? phi[i + (size_t)g.nx * ((size_t)(j + 1) + (size_t)g.ny * k)] : 1.0f;
					lev = (j + 0.5 + (double)p / ((double)p - (double)pa)) * g.cell_size;
					break;
				}
			}
			sum += lev;
		}
	return sum / ((double)g.nx * g.nz);
}

#endif
