/* SPDX-License-Identifier: MIT */
/* Shared by the FLIP tests and benchmarks: a reproducible velocity field on
 * the three face grids, uniform in [-0.5, 0.5) m/s from a 64-bit LCG, so a
 * pressure solve has real divergence to remove. */
#ifndef EDDY_GRID_FIXTURE_H
#define EDDY_GRID_FIXTURE_H

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

#endif
