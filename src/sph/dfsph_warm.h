/* SPDX-License-Identifier: MIT */
/* sph_dfsph's hydrostatic cold start (dfsph_warm.c): a first guess of the
 * velocity solve's k for water that starts at rest with no k of its own. */
#ifndef EDDY_DFSPH_WARM_H
#define EDDY_DFSPH_WARM_H

#include "sph.h"

/* When every k[0 .. n) is 0 (no state: the first step, or water wholly
 * without pressure), writes into k the hydrostatic estimate of the rows
 * that rest on a wall (dfsph_warm.c) and returns how many got one; k is the
 * velocity solve's warm-start column (m^5/(kg s^2)). Leaves k as it is and
 * returns 0 otherwise. Serial, in row and cell order. */
long eddy__dfsph_hydrostatic_start(eddy_world *w, const sph_shared *sh, long n, float *k);

#endif
