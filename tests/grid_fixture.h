/* SPDX-License-Identifier: MIT */
/* Shared by the FLIP tests and benchmarks: a reproducible velocity field on
 * the three face grids, uniform in [-0.5, 0.5) m/s from a 64-bit LCG, so a
 * pressure solve has real divergence to remove; and a liquid domain with an
 * irregular free surface for the pressure solvers. */
#ifndef EDDY_GRID_FIXTURE_H
#define EDDY_GRID_FIXTURE_H

#include <math.h>
#include <stdint.h>

#include "eddy.h"

static inline void fixture_random_faces(eddy_world *w, uint64_t seed)
{
	const char *const names[3] = {"u", "v", "w"};
	for (int a = 0; a < 3; ++a) {
		size_t n;
		float *f = eddy_world_channel_mut(w, names[a], &n);
		for (size_t i = 0; f && i < n; ++i) {
			seed = seed * 6364136223846793005ull + 1442695040888963407ull;
			f[i] = (float)((double)(seed >> 40) / (double)(1ull << 24) - 0.5);
		}
	}
}

/* Cell types and marker of a pool in the world's box (unit lengths: the box
 * is the unit cube scaled per axis): the surface at y = 0.5 + 0.1 sin(6.3 x)
 * cos(4.1 z) + 0.05 sin(17 x + 3 z), so every ghost-fluid theta occurs along
 * it, and a drop of radius 0.08 above it (a second free-surface component).
 * The same shapes at every grid size; flip_phi in cells, as flip_surface's. */
static inline void fixture_wavy_pool(eddy_world *w)
{
	const eddy_grid_info g = eddy_world_grid(w);
	float *phi = eddy_world_channel_mut(w, "flip_phi", NULL);
	uint8_t *type = (uint8_t *)(uintptr_t)eddy_world_channel_u8(w, "cell_type", NULL);
	for (int k = 0; k < g.nz; ++k)
		for (int j = 0; j < g.ny; ++j)
			for (int i = 0; i < g.nx; ++i) {
				const double x = (i + 0.5) / g.nx, y = (j + 0.5) / g.ny, z = (k + 0.5) / g.nz;
				const double s = 0.5 + 0.1 * sin(6.3 * x) * cos(4.1 * z) + 0.05 * sin(17 * x + 3 * z);
				const double drop =
					sqrt((x - 0.5) * (x - 0.5) + (y - 0.85) * (y - 0.85) + (z - 0.5) * (z - 0.5)) - 0.08;
				const double d = drop < y - s ? drop : y - s;
				const size_t c = (size_t)i + (size_t)g.nx * ((size_t)j + (size_t)g.ny * k);
				phi[c] = (float)(d * g.ny);
				type[c] = d < 0 ? EDDY_CELL_FLUID : EDDY_CELL_AIR;
			}
}

#endif
