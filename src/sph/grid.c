/* SPDX-License-Identifier: MIT */
/* The neighbour search's cell grid: cells of h / SPH_CELLS_PER_H over the
 * world bounds plus a margin of h, x fastest, so that once the particle
 * table is in cell order the cells along x are one contiguous stretch of
 * rows. Cells of h/2: the 5^3 cells around a particle hold 58% of the
 * candidates of the 3^3 cells of size h, and 7^3 of them cover the Verlet
 * radius h (1 + SPH_SKIN). The cell order is a stable counting sort, so it
 * is a function of the positions alone.
 * The grid spans the world bounds, most of its cells empty: where each
 * cell's particles start is kept per row of cells along x, the row's first
 * as 32 bits and each cell's as a 16-bit offset from it (sph_cell_starts,
 * sph.h), 2 bytes a cell instead of 4; all 32-bit while some row of cells
 * holds more than 65535 (a cell's count wraps in 16 bits, and then the
 * rows' totals fall short of n: the sort sees it and takes the wide form). */
#include "neighbors.h"

#include <stdlib.h>
#include <string.h>

static bool starts_alloc(sph_cell_starts *s, size_t cells, size_t rows)
{
	s->base = calloc(rows + 1, sizeof *s->base);
	s->off = calloc(cells ? cells : 1, sizeof *s->off);
	s->wide = NULL;
	return s->base && s->off;
}

static void starts_free(sph_cell_starts *s)
{
	free(s->base);
	free(s->off);
	free(s->wide);
	memset(s, 0, sizeof *s);
}

void sph_grid_free(sph_grid *g)
{
	starts_free(&g->fluid_start);
	starts_free(&g->bound_start);
}

eddy_status sph_grid_init(eddy_world *w, sph_grid *g, float h)
{
	if (g->fluid_start.base)
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
	const size_t cells = sph_grid_cells(g), rows = (size_t)g->gy * (size_t)g->gz;
	if (!starts_alloc(&g->fluid_start, cells, rows) || !starts_alloc(&g->bound_start, cells, rows)) {
		sph_grid_free(g);
		return eddy__fail(w, EDDY_ERR_NOMEM, "sph_density: out of memory for %zu neighbour cells", cells);
	}
	return EDDY_OK;
}

/* The wide form of s, allocated if it is not. */
static uint32_t *starts_wide(sph_cell_starts *s, size_t cells)
{
	if (!s->wide)
		s->wide = malloc((cells + 1) * sizeof *s->wide);
	return s->wide;
}

/* Back to the offsets (they held this time): the wide form's memory freed. */
static void starts_narrow(sph_cell_starts *s)
{
	free(s->wide);
	s->wide = NULL;
}

bool sph_counting_sort(const uint32_t *keys, size_t n, const sph_grid *g, sph_cell_starts *start, uint32_t *order)
{
	const size_t gx = (size_t)g->gx, cells = sph_grid_cells(g), rows = cells / gx;
	uint32_t *base = start->base;
	uint16_t *off = start->off;
	/* the counts per cell (16 bits: a cell of 65536 or more wraps, and then
	 * the rows' totals fall short of n), then their sums from each row's start */
	memset(off, 0, cells * sizeof *off);
	for (size_t i = 0; i < n; ++i)
		off[keys[i]]++;
	bool fits = true;
	uint32_t at = 0;
	for (size_t r = 0, c = 0; r < rows; ++r) {
		base[r] = at;
		uint32_t in = 0;
		for (size_t x = 0; x < gx; ++x, ++c) {
			const uint32_t k = off[c];
			off[c] = (uint16_t)in;
			in += k;
		}
		fits = fits && in <= 0xFFFFu;
		at += in;
	}
	base[rows] = at;
	if (fits && at == n) {
		/* off[c] as the running cursor of cell c, then shifted back a cell in each row */
		for (size_t i = 0; i < n; ++i) {
			const uint32_t c = keys[i];
			order[base[c / gx] + off[c]++] = (uint32_t)i;
		}
		for (size_t r = 0; r < rows; ++r) {
			uint16_t *o = off + r * gx;
			for (size_t x = gx - 1; x > 0; --x)
				o[x] = o[x - 1];
			o[0] = 0;
		}
		starts_narrow(start);
		return true;
	}
	uint32_t *s = starts_wide(start, cells);
	if (!s)
		return false;
	memset(s, 0, (cells + 1) * sizeof *s);
	for (size_t i = 0; i < n; ++i)
		s[keys[i] + 1]++;
	for (size_t c = 0; c < cells; ++c)
		s[c + 1] += s[c];
	/* s[c] as the running cursor of cell c, then shifted back a cell */
	for (size_t i = 0; i < n; ++i)
		order[s[keys[i]]++] = (uint32_t)i;
	for (size_t c = cells; c > 0; --c)
		s[c] = s[c - 1];
	s[0] = 0;
	return true;
}

bool sph_cell_ranges(const uint32_t *keys, size_t n, const sph_grid *g, sph_cell_starts *start)
{
	const size_t gx = (size_t)g->gx, cells = sph_grid_cells(g), rows = cells / gx;
	uint32_t *base = start->base;
	uint16_t *off = start->off;
	/* cell c starts at the first position i with keys[i] >= c; a row of
	 * cells with no particle (most of them: the grid spans the bounds) is
	 * all zeros */
	bool fits = true;
	size_t i = 0;
	for (size_t r = 0; r < rows; ++r) {
		const size_t c0 = r * gx;
		uint16_t *o = off + c0;
		base[r] = (uint32_t)i;
		if (i == n || keys[i] >= c0 + gx) {
			memset(o, 0, gx * sizeof *o);
			continue;
		}
		for (size_t x = 0; x < gx; ++x) {
			while (i < n && keys[i] < c0 + x)
				++i;
			o[x] = (uint16_t)(i - base[r]);
		}
		fits = fits && i - base[r] <= 0xFFFFu; /* the row's last start, its largest */
		while (i < n && keys[i] < c0 + gx)
			++i;
	}
	base[rows] = (uint32_t)n; /* a row's end is the next row's start: no offset */
	if (fits) {
		starts_narrow(start);
		return true;
	}
	uint32_t *s = starts_wide(start, cells);
	if (!s)
		return false;
	size_t c = 0;
	for (size_t k = 0; k < n; ++k)
		while (c <= keys[k])
			s[c++] = (uint32_t)k;
	while (c <= cells)
		s[c++] = (uint32_t)n;
	return true;
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
