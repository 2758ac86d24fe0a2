/* SPDX-License-Identifier: MIT */
/* The coarse level of sph_dfsph's conjugate gradients (dfsph_coarse.c):
 * a two-level additive preconditioner z = D'^-1 r + P B P^T r / s, with P
 * the particles' cells, B a multigrid V-cycle on the cells' Poisson
 * operator and s its scale, A's Rayleigh quotient on the correction. */
#ifndef EDDY_DFSPH_COARSE_H
#define EDDY_DFSPH_COARSE_H

#include "sph.h"

typedef struct dfsph_coarse dfsph_coarse;

/* The levels for the active set (mask[i] = 1) of rows 0 .. n - 1 of sh's
 * lists, in the arena (per step); NULL when out of memory or no row is
 * active (then the solve runs on D'^-1 alone). Its loops and those of the
 * calls below run on up to threads threads, with the same bits for any
 * count. */
dfsph_coarse *eddy__dfsph_coarse_build(eddy_arena *a, const sph_shared *sh, long n, const uint8_t *mask, int threads);

/* y = P B P^T r on the active rows (0 elsewhere) and its coarse vector
 * e = B P^T r; returns e . L e (L the level-0 cell operator): the
 * denominator of the Rayleigh quotient s = y . (A/dt) y / e . L e. */
double eddy__dfsph_coarse_unit(dfsph_coarse *c, const float *r, float *y);

/* Sets s (the caller measured y . (A/dt) y); a scale that is not positive
 * and finite turns the coarse part off. */
void eddy__dfsph_coarse_set_scale(dfsph_coarse *c, double s);

/* z = dsym r + P B P^T r / s (0 off the active set); returns r . z summed
 * per 16384 rows in row order, then the chunks' sums in order. */
double eddy__dfsph_coarse_apply(dfsph_coarse *c, const float *r, const float *dsym, float *z);

#endif
