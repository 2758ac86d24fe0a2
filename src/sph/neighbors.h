/* SPDX-License-Identifier: MIT */
/* Internals of the neighbour search, shared by grid.c, boundary.c,
 * search.c and neighbors.c (each says its part in its header comment). The
 * SPH passes read the lists through sph.h only. */
#ifndef EDDY_SPH_NEIGHBORS_H
#define EDDY_SPH_NEIGHBORS_H

#include "sph.h"

/* Verlet skin as a fraction of h: larger means rarer searches but more
 * candidates to filter every step ((1 + skin)^3 of the exact list's). It is
 * sized from the motion per step seen at the last search, so that a list
 * lasts SPH_SKIN_LIFE steps (a fluid at rest filters few more candidates
 * than it keeps), within [SPH_SKIN_MIN, SPH_SKIN]; 0 when even SPH_SKIN
 * would not last SPH_SKIN_MIN_LIFE steps. */
#define SPH_SKIN 0.2f
#define SPH_SKIN_MIN 0.05f
#define SPH_SKIN_LIFE 8
#define SPH_SKIN_MIN_LIFE 3
#define SPH_CELLS_PER_H 2
#define SPH_VERLET_CELLS 3 /* cells of h/2 the Verlet radius spans: ceil(2 (1 + SPH_SKIN)) */

/* ---- grid.c ---- */
eddy_status sph_grid_init(eddy_world *w, sph_grid *g, float h);
void sph_counting_sort(const uint32_t *keys, size_t n, size_t cells, uint32_t *start, uint32_t *order);
void sph_cell_ranges(const uint32_t *keys, size_t n, size_t cells, uint32_t *start);

static inline size_t sph_grid_cells(const sph_grid *g) { return (size_t)g->gx * (size_t)g->gy * (size_t)g->gz; }

static inline int sph_clampi(int v, int lo, int hi) { return v < lo ? lo : v > hi ? hi : v; }

/* The cell of a point; points outside the grid go to its border cells. */
static inline uint32_t sph_cell_at(const sph_grid *g, float x, float y, float z)
{
	const int cx = sph_clampi((int)((x - g->ox) * g->inv_cell), 0, g->gx - 1);
	const int cy = sph_clampi((int)((y - g->oy) * g->inv_cell), 0, g->gy - 1);
	const int cz = sph_clampi((int)((z - g->oz) * g->inv_cell), 0, g->gz - 1);
	return (uint32_t)((cz * g->gy + cy) * g->gx + cx);
}

/* Grows *p (elem bytes each) to hold want, doubling; *have is in elements. */
bool sph_grow(void **p, size_t *have, size_t want, size_t elem);
/* Points the k arrays *slices[0..k) at consecutive stretches of cap 4-byte
 * entries in one block *p, grown to hold them; *have is in entries of one
 * array. What the arrays held is not kept. */
bool sph_grow_block(void **p, size_t *have, size_t cap, void **slices[], int k);

/* Sorts idx (and d with it) ascending: insertion, for lists that are in
 * order or nearly. */
void sph_sort_hits(uint32_t *idx, float *d, uint32_t cnt);

/* ---- boundary.c ---- */
eddy_status sph_boundary_build(eddy_world *w, sph_shared *sh);
void sph_boundary_free(sph_neighbors *nb);
float sph_boundary_move(const eddy_world *w, sph_neighbors *nb);
eddy_status sph_boundary_sort(eddy_world *w, sph_neighbors *nb);
eddy_status sph_boundary_divergence(eddy_world *w, sph_shared *sh, int threads);

/* ---- search.c ---- */
/* The lists a search writes: the Verlet candidates (r2max = (h (1 + skin))^2)
 * or, with exact, the exact lists and kernel sums (r2max = h^2). */
typedef struct sph_search_out {
	bool exact;
	float r2max;
	size_t stride, bstride;
	uint32_t *list, *count, *blist, *bcount;
} sph_search_out;
/* Returns false when out of memory; *max_f, *max_b: the largest counts
 * seen (above the strides: widen and search again). */
bool sph_search(eddy_world *w, sph_neighbors *nb, const sph_search_out *out, int threads, uint32_t *max_f,
                uint32_t *max_b);

/* ---- the kernel sums (search.c in exact mode, neighbors.c's filter) ---- */
/* sum_k d_k^3 in one fixed order: four partial sums over the whole quads,
 * (0 + 1) + (2 + 3), then the tail. Every path that makes a particle's list
 * sums this way, so they give the same bits. */
static inline float sph_cube_sum(const float *d, uint32_t cnt)
{
	float a[4] = {0, 0, 0, 0};
	uint32_t q = 0;
	for (; q + 4 <= cnt; q += 4)
		for (int k = 0; k < 4; ++k)
			a[k] += d[q + k] * d[q + k] * d[q + k];
	float s = (a[0] + a[1]) + (a[2] + a[3]);
	for (; q < cnt; ++q)
		s += d[q] * d[q] * d[q];
	return s;
}

#endif
