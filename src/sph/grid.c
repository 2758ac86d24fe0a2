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
 * as 32 bits and, over the runs of occupied cells only, each cell's as a
 * 16-bit offset from it (sph_cell_starts, sph.h): some 2 bytes an occupied
 * cell, where one offset per cell of the whole grid took 26 bytes a
 * particle for a block in a tank twice its width (two grids, fluid and
 * boundary). All 32-bit per cell while some row of cells holds more than
 * 65535, and in a grid of at most SPH_WIDE_CELLS cells (neighbors.h: a
 * lookup is then one load). The sort goes by rows of cells, then along
 * each row, so it never holds a count per cell of the whole grid either. */
#include "neighbors.h"

#include <stdlib.h>
#include <string.h>

static bool starts_alloc(sph_cell_starts *s, size_t rows)
{
	*s = (sph_cell_starts){0};
	s->base = calloc(rows + 1, sizeof *s->base);
	s->run_at = calloc(rows + 1, sizeof *s->run_at);
	return s->base && s->run_at;
}

static void starts_free(sph_cell_starts *s)
{
	free(s->base);
	free(s->run_at);
	eddy__pages_free(s->run);
	eddy__pages_free(s->off);
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
	if (!starts_alloc(&g->fluid_start, rows) || !starts_alloc(&g->bound_start, rows)) {
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

/* The row of cells of cell c: c / gx, by a multiplication (the sort takes
 * it for every key) made exact by one correction either way. */
static inline uint32_t row_of_cell(uint32_t c, uint32_t gx, double inv_gx)
{
	uint32_t r = (uint32_t)((double)c * inv_gx);
	r -= r * gx > c;
	r += (r + 1) * gx <= c;
	return r;
}

/* Room for the runs and offsets of n entries: at most one run and
 * 1 + SPH_CELL_GAP offsets an entry, and an offset a cell (what is not
 * written stays unresident: eddy__pages_alloc). What they held is not kept. */
static bool starts_room(sph_cell_starts *s, size_t n, size_t cells)
{
	const size_t runs = n + 1, offs = n * (1 + SPH_CELL_GAP) < cells ? n * (1 + SPH_CELL_GAP) + 1 : cells + 1;
	if (runs > s->run_alloc) {
		eddy__pages_free(s->run);
		s->run = eddy__pages_alloc(runs * sizeof *s->run);
		s->run_alloc = s->run ? runs : 0;
	}
	if (offs > s->off_alloc) {
		eddy__pages_free(s->off);
		s->off = eddy__pages_alloc(offs * sizeof *s->off);
		s->off_alloc = s->off ? offs : 0;
	}
	return s->run && s->off;
}

/* Row r's runs from its cells' counts cnt[xlo .. xhi] (both occupied),
 * appended at *nrun and *noff; cnt[x] becomes cell x's start less the
 * row's (the sort's cursor). */
static void row_runs(sph_cell_starts *s, uint32_t *cnt, uint32_t xlo, uint32_t xhi, size_t *nrun, size_t *noff)
{
	uint32_t rel = 0;
	for (uint32_t x = xlo; x <= xhi;) {
		sph_cell_run *run = &s->run[(*nrun)++];
		run->x0 = x;
		run->at = (uint32_t)*noff;
		uint32_t last = x; /* the run's last occupied cell so far */
		for (; x <= xhi && x - last <= SPH_CELL_GAP; ++x) {
			const uint32_t c = cnt[x];
			last = c ? x : last;
			s->off[(*noff)++] = (uint16_t)rel;
			cnt[x] = rel;
			rel += c;
		}
		*noff -= x - 1 - last; /* the gap's empty cells at its end */
		run->x1 = last + 1;
		while (x <= xhi && cnt[x] == 0) /* to the next occupied cell (counts: not yet rewritten) */
			++x;
	}
}

/* The wide form's stable counting sort: a count per cell of the grid. */
static bool counting_sort_wide(const uint32_t *keys, size_t n, size_t cells, sph_cell_starts *start, uint32_t *order)
{
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

bool sph_counting_sort(const uint32_t *keys, size_t n, const sph_grid *g, sph_cell_starts *start, uint32_t *order)
{
	const size_t gx = (size_t)g->gx, cells = sph_grid_cells(g), rows = cells / gx;
	if (cells <= SPH_WIDE_CELLS)
		return counting_sort_wide(keys, n, cells, start, order);
	const double inv_gx = 1.0 / (double)gx;
	uint32_t *base = start->base, *cur = start->run_at; /* run_at: the rows' cursors, until the runs */
	/* the rows' counts, then their starts */
	memset(base, 0, (rows + 1) * sizeof *base);
	for (size_t i = 0; i < n; ++i)
		base[row_of_cell(keys[i], (uint32_t)gx, inv_gx) + 1]++;
	bool fits = true;
	for (size_t r = 0; r < rows; ++r) {
		fits = fits && base[r + 1] <= 0xFFFFu;
		base[r + 1] += base[r];
	}
	uint32_t *cnt = fits ? malloc(gx * sizeof *cnt) : NULL, *row = NULL;
	if (fits && cnt && starts_room(start, n, cells)) {
		/* by rows (stable), then each row's entries by cell (stable) */
		memcpy(cur, base, rows * sizeof *cur);
		for (size_t i = 0; i < n; ++i)
			order[cur[row_of_cell(keys[i], (uint32_t)gx, inv_gx)]++] = (uint32_t)i;
		uint32_t longest = 0;
		for (size_t r = 0; r < rows; ++r)
			longest = base[r + 1] - base[r] > longest ? base[r + 1] - base[r] : longest;
		row = malloc((longest ? longest : 1) * sizeof *row);
	}
	if (fits && row) {
		size_t nrun = 0, noff = 0;
		for (size_t r = 0; r < rows; ++r) {
			start->run_at[r] = (uint32_t)nrun;
			const uint32_t b = base[r], len = base[r + 1] - b, c0 = (uint32_t)(r * gx);
			if (len == 0)
				continue;
			memcpy(row, order + b, len * sizeof *row);
			uint32_t xlo = (uint32_t)gx, xhi = 0;
			for (uint32_t k = 0; k < len; ++k) {
				const uint32_t x = keys[row[k]] - c0;
				xlo = x < xlo ? x : xlo;
				xhi = x > xhi ? x : xhi;
			}
			memset(cnt + xlo, 0, (xhi - xlo + 1) * sizeof *cnt);
			for (uint32_t k = 0; k < len; ++k)
				cnt[keys[row[k]] - c0]++;
			row_runs(start, cnt, xlo, xhi, &nrun, &noff);
			for (uint32_t k = 0; k < len; ++k)
				order[b + cnt[keys[row[k]] - c0]++] = row[k];
		}
		start->run_at[rows] = (uint32_t)nrun;
		free(cnt);
		free(row);
		starts_narrow(start);
		return true;
	}
	free(cnt);
	free(row);
	if (fits) /* out of memory */
		return false;
	return counting_sort_wide(keys, n, cells, start, order);
}

/* The wide form of keys[0..n) in cell order: each cell's first entry. */
static bool cell_ranges_wide(const uint32_t *keys, size_t n, size_t cells, sph_cell_starts *start)
{
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

bool sph_cell_ranges(const uint32_t *keys, size_t n, const sph_grid *g, sph_cell_starts *start)
{
	const size_t gx = (size_t)g->gx, cells = sph_grid_cells(g), rows = cells / gx;
	if (cells <= SPH_WIDE_CELLS)
		return cell_ranges_wide(keys, n, cells, start);
	uint32_t *base = start->base;
	uint32_t *cnt = malloc(gx * sizeof *cnt);
	bool fits = cnt && starts_room(start, n, cells);
	if (!fits) {
		free(cnt);
		return false;
	}
	/* a row of cells with no particle (most of them: the grid spans the
	 * bounds) has no runs */
	size_t i = 0, nrun = 0, noff = 0;
	for (size_t r = 0; r < rows && fits; ++r) {
		const uint32_t c0 = (uint32_t)(r * gx), c1 = (uint32_t)(c0 + gx);
		base[r] = (uint32_t)i;
		start->run_at[r] = (uint32_t)nrun;
		if (i == n || keys[i] >= c1)
			continue;
		size_t j = i;
		while (j < n && keys[j] < c1)
			++j;
		fits = j - i <= 0xFFFFu;
		const uint32_t xlo = keys[i] - c0, xhi = keys[j - 1] - c0;
		memset(cnt + xlo, 0, (xhi - xlo + 1) * sizeof *cnt);
		for (size_t k = i; k < j; ++k)
			cnt[keys[k] - c0]++;
		if (fits)
			row_runs(start, cnt, xlo, xhi, &nrun, &noff);
		i = j;
	}
	free(cnt);
	base[rows] = (uint32_t)n; /* a row's end is the next row's start */
	start->run_at[rows] = (uint32_t)nrun;
	if (fits) {
		starts_narrow(start);
		return true;
	}
	return cell_ranges_wide(keys, n, cells, start);
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
