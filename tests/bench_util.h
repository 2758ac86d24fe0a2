/* SPDX-License-Identifier: MIT */
/* What every benchmark needs: a monotonic clock and the median of repeats
 * (the machines are shared: medians, not means, and ratios within one run). */
#ifndef EDDY_BENCH_UTIL_H
#define EDDY_BENCH_UTIL_H

#include <stdlib.h>
#include <time.h>

#include "eddy.h"

static inline double now_ms(void)
{
	struct timespec ts;
	clock_gettime(CLOCK_MONOTONIC, &ts);
	return (double)ts.tv_sec * 1e3 + (double)ts.tv_nsec * 1e-6;
}

static inline int cmp_double(const void *a, const void *b)
{
	double x = *(const double *)a, y = *(const double *)b;
	return (x > y) - (x < y);
}

/* Sorts v in place and returns its median. */
static inline double median(double *v, int n)
{
	qsort(v, (size_t)n, sizeof *v, cmp_double);
	return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

/* The SPH forces after sph_density, in the scenes' orders: with df, gravity,
 * viscosity and sph_dfsph (df's settings); without, sph_pressure, viscosity
 * and gravity (WCSPH). */
static inline void bench_add_sph_forces(eddy_world *w, const eddy_sph_dfsph_def *df)
{
	const eddy_gravity_def g = eddy_default_gravity_def();
	const eddy_sph_viscosity_def vi = eddy_default_sph_viscosity_def();
	if (df) {
		eddy_add_gravity(w, &g);
		eddy_add_sph_viscosity(w, &vi);
		eddy_add_sph_dfsph(w, df);
	} else {
		const eddy_sph_pressure_def pr = eddy_default_sph_pressure_def();
		eddy_add_sph_pressure(w, &pr);
		eddy_add_sph_viscosity(w, &vi);
		eddy_add_gravity(w, &g);
	}
}

#endif
