/* SPDX-License-Identifier: MIT */
/* Internals of the neighbour search, shared by grid.c, boundary.c,
 * search.c and neighbors.c (each says its part in its header comment). The
 * SPH passes read the lists through sph.h only. */
#ifndef EDDY_SPH_NEIGHBORS_H
#define EDDY_SPH_NEIGHBORS_H

#include "sph.h"

#include <string.h>

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
void sph_grid_free(sph_grid *g);
/* Stable counting sort of keys[0..n) (cells of g): order[k] is the k-th
 * index in cell order, *start where each cell's begin in it. False when out
 * of memory (for the wide form). */
bool sph_counting_sort(const uint32_t *keys, size_t n, const sph_grid *g, sph_cell_starts *start, uint32_t *order);
/* *start for keys[0..n) already in cell order (non-decreasing): one pass, no
 * permutation (a table that stayed in order needs only this). False when
 * out of memory. */
bool sph_cell_ranges(const uint32_t *keys, size_t n, const sph_grid *g, sph_cell_starts *start);

static inline size_t sph_grid_cells(const sph_grid *g) { return (size_t)g->gx * (size_t)g->gy * (size_t)g->gz; }

/* A grid of at most this many cells keeps one 32-bit start per cell (the
 * wide form, 256 KB at most a grid) rather than the runs: a lookup is then
 * one load where the runs take a walk of the row's, and a sparse flow (a
 * jet, a splash) has few particles in each search block, so its search is
 * mostly such lookups (5 per row of cells around a block). */
#define SPH_WIDE_CELLS (1u << 16)

/* Empty cells between two of a row's occupied ones that still share a run
 * (sph_cell_starts, sph.h): a run's own record costs six offsets. */
#define SPH_CELL_GAP 6

/* The first entry of cell x (0 <= x <= gx: gx gives the row's end) of row
 * of cells row (y + gy z): in a run, its offset; before one (its cells are
 * empty), the run's first cell's; after the last, the next row's start. A
 * row holds a few runs (one across a fluid, two across a box's walls). */
static inline uint32_t sph_cell_start(const sph_grid *g, const sph_cell_starts *s, size_t row, int x)
{
	if (s->wide)
		return s->wide[row * (size_t)g->gx + (size_t)x];
	const uint32_t ux = (uint32_t)x;
	for (uint32_t k = s->run_at[row], e = s->run_at[row + 1]; k < e; ++k) {
		const sph_cell_run *r = &s->run[k];
		if (ux < r->x1)
			return s->base[row] + s->off[r->at + (ux > r->x0 ? ux - r->x0 : 0)];
	}
	return s->base[row + 1];
}

/* The first entries of cells xa <= xb of row of cells row (as
 * sph_cell_start), in one walk of the row's runs. */
static inline void sph_cell_start2(const sph_grid *g, const sph_cell_starts *s, size_t row, int xa, int xb, uint32_t *a,
                                   uint32_t *b)
{
	if (s->wide) {
		*a = s->wide[row * (size_t)g->gx + (size_t)xa];
		*b = s->wide[row * (size_t)g->gx + (size_t)xb];
		return;
	}
	const uint32_t ua = (uint32_t)xa, ub = (uint32_t)xb, e = s->run_at[row + 1], end = s->base[row + 1];
	uint32_t k = s->run_at[row];
	while (k < e && ua >= s->run[k].x1)
		++k;
	*a = k < e ? s->base[row] + s->off[s->run[k].at + (ua > s->run[k].x0 ? ua - s->run[k].x0 : 0)] : end;
	while (k < e && ub >= s->run[k].x1)
		++k;
	*b = k < e ? s->base[row] + s->off[s->run[k].at + (ub > s->run[k].x0 ? ub - s->run[k].x0 : 0)] : end;
}

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

/* ---- sph_lists (sph.h): room for one list at a time ---- */
#define SPH_LIST_CHUNK 4096 /* entries a cursor takes from the array at a time */
#define SPH_LIST_CURSORS 16 /* the most cursors a thread uses on one array (search.c's SEARCH_ROWS) */

/* One thread's part of a pass over a sph_lists. */
typedef struct sph_cursor {
	size_t at, end;   /* the thread's chunk of the array: [at, end) */
	uint64_t total;   /* entries of the lists it asked room for */
	uint32_t longest; /* the longest of them */
	bool full;        /* the array ran out: the pass must run again on a larger one */
} sph_cursor;

/* Room for up to most entries at the cursor, or NULL once the array is
 * full; the list written there is then ended by sph_list_commit. A chunk
 * is taken whole, so two threads never share one; the tail of a chunk too
 * short for a list is left unused. */
static inline uint32_t *sph_list_claim(sph_lists *l, sph_cursor *c, uint32_t most)
{
	if (c->end - c->at < most) {
		if (c->full)
			return NULL;
		const size_t take = most > SPH_LIST_CHUNK ? most : SPH_LIST_CHUNK;
		size_t at;
#pragma omp atomic capture
		{
			at = l->used;
			l->used += take;
		}
		if (at + take > l->alloc) {
			c->full = true;
			c->at = c->end = 0;
			return NULL;
		}
		c->at = at;
		c->end = at + take;
	}
	return c->full ? NULL : l->data + c->at;
}

/* The list of cnt entries written at the claimed room: its start in the
 * array (*first; 0 once the array is full, when it was not written). */
static inline void sph_list_commit(sph_cursor *c, uint32_t cnt, uint32_t *first)
{
	c->total += cnt;
	c->longest = cnt > c->longest ? cnt : c->longest;
	*first = c->full ? 0 : (uint32_t)c->at;
	c->at += c->full ? 0 : cnt;
}

/* Room for a list of cnt entries, committed: the pointer to write it to,
 * NULL once the array is full. */
static inline uint32_t *sph_list_room(sph_lists *l, sph_cursor *c, uint32_t cnt, uint32_t *first)
{
	uint32_t *p = sph_list_claim(l, c, cnt);
	sph_list_commit(c, cnt, first);
	return p;
}

/* The cursors of a pass's threads, merged: total summed, longest the
 * largest, full or-ed. */
static inline void sph_cursor_merge(sph_cursor *into, const sph_cursor *c)
{
	into->total += c->total;
	into->longest = c->longest > into->longest ? c->longest : into->longest;
	into->full = into->full || c->full;
}

/* ---- the packed groups of the fluid lists (sph.h): search.c and the
 * filter write them, the passes read them with sph_group_next ---- */
/* Packs cnt ascending rows c[0 .. cnt) to out (room for
 * sph_packed_words_max(cnt) words); returns the words written. The last
 * group's padding is written to c[cnt .. cnt + 7) first: c needs room for
 * it. */
static inline uint32_t sph_pack_groups(uint32_t *c, uint32_t cnt, uint32_t *out)
{
	if (cnt == 0)
		return 0;
	for (uint32_t k = 0; k < 7; ++k)
		c[cnt + k] = c[cnt - 1];
	uint32_t *w = out, prev = c[0];
	*w++ = prev;
	for (uint32_t q = 0; q < cnt; q += 8) {
		const uint32_t *g = c + q;
		const uint32_t step = g[0] - prev;
		if (step < SPH_GROUP_WIDE && g[7] - g[0] <= 0xFFFFu) {
			simd_narrow16_sub(g, g[0], w);
			const uint16_t s16 = (uint16_t)step;
			memcpy(w, &s16, sizeof s16); /* in place of the first's 0 */
			w += 4;
		} else {
			const uint16_t mark[8] = {SPH_GROUP_WIDE, 0, 0, 0, 0, 0, 0, 0};
			memcpy(w, mark, sizeof mark);
			memcpy(w + 4, g, 8 * sizeof *g);
			w += SPH_GROUP_WORDS_MAX;
		}
		prev = g[0];
	}
	return (uint32_t)(w - out);
}

/* ---- search.c ---- */
/* The lists a search writes: the Verlet candidates (r2max = (h (1 + skin))^2;
 * the fluid ones in packed groups, above) or, with exact, the exact lists
 * and kernel sums (r2max = h^2). */
typedef struct sph_search_out {
	bool exact;
	float r2max;
	float mass, self; /* exact: the kernel sum's m and h^6 (sph_kernel_sum) */
	sph_lists *list, *blist;
	uint32_t *first, *count, *bfirst, *bcount;
} sph_search_out;
/* Returns false when out of memory; *fluid, *bound: the passes' cursors
 * merged (full: run again on larger lists). */
bool sph_search(eddy_world *w, sph_neighbors *nb, const sph_search_out *out, int threads, sph_cursor *fluid,
                sph_cursor *bound);

/* ---- the kernel sums (search.c in exact mode, neighbors.c's filter) ---- */
/* sum_k d_k^3 in one fixed order: four partial sums over the whole quads,
 * (0 + 1) + (2 + 3), then the tail. Every path that makes a particle's list
 * sums this way, so they give the same bits. */
static inline float sph_cube_sum(const float *d, uint32_t cnt)
{
	/* the four partial sums in lanes 0-3 (a quad loaded into both halves;
	 * the upper one is not read): the same operations per lane as four
	 * scalar sums */
	sf8 acc = sf8_zero();
	uint32_t q = 0;
	for (; q + 4 <= cnt; q += 4) {
		const sf8 v = sf8_load_quad2(d + q);
		acc = sf8_add(acc, sf8_mul(sf8_mul(v, v), v));
	}
	float a[8];
	sf8_store(a, acc);
	float s = (a[0] + a[1]) + (a[2] + a[3]);
	for (; q < cnt; ++q)
		s += d[q] * d[q] * d[q];
	return s;
}

/* The kernel sum of a particle whose fluid neighbours' (h^2 - r^2)^3 sum to
 * ws and boundary ones' V_b rho_b (h^2 - r^2)^3 to bws (sph_neighbors'
 * ksum): one expression, so the search and the filter give the same bits. */
static inline float sph_kernel_sum(float mass, float self, float ws, float bws) { return mass * (self + ws) + bws; }

#endif
