/* SPDX-License-Identifier: MIT */
/* The neighbour search's cell grid: cells of h / SPH_CELLS_PER_H over the
 * world bounds plus a margin of h, x fastest, so that once the particle
 * table is in cell order the cells along x are one contiguous stretch of
 * rows. Cells of h/2: the 5^3 cells around a particle hold 58% of the
 * candidates of the 3^3 cells of size h, and 7^3 of them cover the Verlet
 * radius h (1 + SPH_SKIN). The cell order is a stable counting sort, so it
 * is a function of the positions alone. */
#include "neighbors.h"

#include <stdlib.h>
#include <string.h>

eddy_status sph_grid_init(eddy_world *w, sph_grid *g, float h)
{
	if (g->fluid_start)
		return EDDY_OK;
	const eddy_vec3 lo = w->def.bounds_min, hi = w->def.bounds_max;
	g->ox = lo.x - h;
	g->oy = lo.y - h;
	g->oz = lo.z - h;
	g->inv_cell = SPH_CELLS_PER_H / h;
	const double gx = ceil((hi.x - lo.x) * g->inv_cell) + 2 * SPH_CELLS_PER_H,
				 gy = ceil((hi.y - lo.y) * g->inv_cell) + 2 * SPH_CELLS_PER_H,
				 gz = ceil((hi.z - lo.z) * g->inv_cell) + 2 * SPH_CELLS_PER_H;
	if (gx * gy * gz > 1.5e8)
		return eddy__fail(
			w, EDDY_ERR_NOMEM,
			"sph_density: the world bounds hold %.0f x %.0f x %.0f neighbour cells of size radius/2 = %g m; "
			"shrink the bounds or use a larger radius",
			gx, gy, gz, (double)h / SPH_CELLS_PER_H);
	g->gx = (int)gx;
	g->gy = (int)gy;
	g->gz = (int)gz;
	const size_t cells = sph_grid_cells(g);
	g->fluid_start = calloc(cells + 1, sizeof *g->fluid_start);
	g->bound_start = calloc(cells + 1, sizeof *g->bound_start);
	if (!g->fluid_start || !g->bound_start)
		return eddy__fail(w, EDDY_ERR_NOMEM, "sph_density: out of memory for %zu neighbour cells", cells);
	return EDDY_OK;
}

/* Stable counting sort of keys[0..n) (cells in [0, cells)): order[k] is the
 * k-th index in cell order, start[c] the position of cell c's first. */
void sph_counting_sort(const uint32_t *keys, size_t n, size_t cells, uint32_t *start, uint32_t *order)
{
	memset(start, 0, (cells + 1) * sizeof *start);
	for (size_t i = 0; i < n; ++i)
		start[keys[i] + 1]++;
	for (size_t c = 0; c < cells; ++c)
		start[c + 1] += start[c];
	/* start[c] as the running cursor of cell c, then shifted back a cell */
	for (size_t i = 0; i < n; ++i)
		order[start[keys[i]]++] = (uint32_t)i;
	for (size_t c = cells; c > 0; --c)
		start[c] = start[c - 1];
	start[0] = 0;
}

/* The cell offsets of keys[0..n) already in cell order (non-decreasing):
 * start[c] is the first position in cell c or after it. One pass, no
 * permutation: a table that stayed in order needs only this. */
void sph_cell_ranges(const uint32_t *keys, size_t n, size_t cells, uint32_t *start)
{
	size_t c = 0;
	for (size_t i = 0; i < n; ++i)
		while (c <= keys[i])
			start[c++] = (uint32_t)i;
	while (c <= cells)
		start[c++] = (uint32_t)n;
}

bool sph_grow(void **p, size_t *have, size_t want, size_t elem)
{
	if (want <= *have)
		return true;
	size_t cap = *have ? *have : 1024;
	while (cap < want)
		cap *= 2;
	void *q = realloc(*p, cap * elem);
	if (!q)
		return false;
	*p = q;
	*have = cap;
	return true;
}

bool sph_grow_block(void **p, size_t *have, size_t cap, void **slices[], int k)
{
	size_t entries = *have * (size_t)k;
	if (!sph_grow(p, &entries, cap * (size_t)k, 4))
		return false;
	*have = entries / (size_t)k;
	for (int a = 0; a < k; ++a)
		*slices[a] = (uint32_t *)*p + (size_t)a * *have;
	return true;
}

void sph_sort_hits(uint32_t *idx, float *d, uint32_t cnt)
{
	for (uint32_t a = 1; a < cnt; ++a) {
		const uint32_t j = idx[a];
		const float dj = d[a];
		uint32_t k = a;
		for (; k > 0 && idx[k - 1] > j; --k) {
			idx[k] = idx[k - 1];
			d[k] = d[k - 1];
		}
		idx[k] = j;
		d[k] = dj;
	}
}
