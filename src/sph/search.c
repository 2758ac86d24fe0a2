/* SPDX-License-Identifier: MIT */
/* The grid search: every pair closer than sqrt(r2max), fluid-fluid and
 * fluid-boundary, into the Verlet list or (exact mode) straight into the
 * exact lists and kernel sums.
 *
 * It works on blocks of SEARCH_BX x SEARCH_BY x SEARCH_BZ cells (about 64
 * particles in a fluid at cells of h/2), whose particles share their
 * candidates: the runs of cells around the block (x fastest: one row of
 * cells along x is one stretch of table rows) are gathered once, in cell
 * order, into one buffer. Each particle of the block then tests the stretch
 * of the buffer within its own z layers, eight at a time, and packs its hits
 * without a branch. So a particle's fluid hits come in ascending row order;
 * its boundary hits are sorted by index when collider particles make the
 * cells' boundary order differ from the index order.
 *
 * Each particle's lists go to the room its thread's cursor for its row of
 * cells hands out (sph_lists, sph.h), the fluid ones (exact or candidates)
 * packed in groups (sph.h).
 *
 * The same tests, in the same operation order, as neighbors.c's filter, and
 * the sums in sph_cube_sum's order: an exact-mode search gives the same bits
 * as a Verlet search followed by the filter. */
#include "neighbors.h"
#include "simd.h"

#include <stdlib.h>
#include <string.h>

/* 4 x 2 x 8 cells: of the shapes tried (4x2x2 before; 2x1x8, 2x2x4, 4x1x4,
 * 4x1x8, 8x2x2, 8x1x4, 4x2x4, 4x1x16, 4x2x16, 4x4x8), the fewest
 * instructions in both a dense block and the sparse pour: deeper blocks
 * share each row of cells' lookups and gather among more particles, while a
 * particle's stretch (its own z layers) stays 5 x 6 x 8 cells (README,
 * Measurements) */
#define SEARCH_BX 4
#define SEARCH_BY 2
#define SEARCH_BZ 8
/* the most runs around a block and the most z layers searched for it */
#define SEARCH_RUNS ((2 * SPH_VERLET_CELLS + SEARCH_BY) * (2 * SPH_VERLET_CELLS + SEARCH_BZ))
#define SEARCH_LAYERS (2 * SPH_VERLET_CELLS + SEARCH_BZ)
#define FAR 1e30f /* a coordinate no particle is near: padding, and a particle's own entry on its turn */

/* What every block reads. */
typedef struct search_ctx {
	const sph_neighbors *nb;
	const sph_search_out *out;
	const float *x, *y, *z;
	uint32_t n;                  /* fluid rows */
	const uint32_t *bound_order; /* the boundary particles in cell order (NULL: they are stored in it) */
	int R;                       /* cells searched beyond the block's on each side */
	/* reach[a][b]: the cells along x a run at cell offsets (a, b) in (y, z)
	 * from the block needs on each side, -1 for none */
	int reach[SPH_VERLET_CELLS + 1][SPH_VERLET_CELLS + 1];
	int blocks_x, blocks_y;
} search_ctx;

/* One thread's buffers: a block's gathered candidates (padded by eight
 * FAR points, so groups of eight need no tail) and one particle's hits;
 * and its cursors in the lists it writes, one per row of cells of a block
 * (y, z; x fastest): the rows of one row of cells are consecutive in the
 * table, and so, written through one cursor, are their lists across the
 * blocks along x, the order in which the filter and the passes read them. */
#define SEARCH_ROWS (SEARCH_BY * SEARCH_BZ)
_Static_assert(SEARCH_ROWS <= SPH_LIST_CURSORS, "sph_list's room for the chunks' tails counts on it");
typedef struct search_buf {
	void *block; /* holds the six arrays */
	size_t cap;
	float *x, *y, *z, *d;
	uint32_t *j, *hit;
	sph_cursor out[SEARCH_ROWS];
} search_buf;

/* One row of cells along x around a block. */
typedef struct cell_run {
	uint32_t fluid_begin, fluid_end; /* rows */
	uint32_t bound_begin, bound_end; /* positions in the boundary cell order */
	uint32_t own_begin, own_end;     /* the rows of the block's own particles in it (none: equal) */
	uint32_t layer;                  /* the row's z layer, 0 = the lowest searched */
	uint32_t own_row;                /* with own rows: which of the block's rows of cells, y + SEARCH_BY z */
	uint32_t fluid_at;               /* the buffer offset of its rows */
} cell_run;

/* A block's runs and where they land in the buffers. */
typedef struct block_runs {
	int x0, x1, y0, y1, z0, z1; /* the block's cells, inclusive */
	int count;
	cell_run run[SEARCH_RUNS];
	uint32_t nf, nbd;                                                        /* fluid and boundary candidates */
	uint32_t fluid_layer[SEARCH_LAYERS + 1], bound_layer[SEARCH_LAYERS + 1]; /* buffer offset of each z layer */
} block_runs;

static bool search_buf_grow(search_buf *b, size_t want)
{
	void **slices[] = {(void **)&b->x, (void **)&b->y, (void **)&b->z,
	                   (void **)&b->d, (void **)&b->j, (void **)&b->hit};
	return sph_grow_block(&b->block, &b->cap, want + 8, slices, 6);
}

/* The runs of cells around block id, in cell order, with their row ranges
 * and their buffer offsets, and the offset of each z layer: a particle
 * needs only the 2R + 1 layers around its own, one stretch of the buffer. */
static void block_find_runs(const search_ctx *c, uint32_t id, block_runs *br)
{
	const sph_grid *g = &c->nb->grid;
	const int R = c->R, bxi = (int)(id % (uint32_t)c->blocks_x),
			  byi = (int)(id / (uint32_t)c->blocks_x % (uint32_t)c->blocks_y),
			  bzi = (int)(id / ((uint32_t)c->blocks_x * (uint32_t)c->blocks_y));
	br->x0 = bxi * SEARCH_BX, br->x1 = br->x0 + SEARCH_BX - 1 < g->gx ? br->x0 + SEARCH_BX - 1 : g->gx - 1;
	br->y0 = byi * SEARCH_BY, br->y1 = br->y0 + SEARCH_BY - 1 < g->gy ? br->y0 + SEARCH_BY - 1 : g->gy - 1;
	br->z0 = bzi * SEARCH_BZ, br->z1 = br->z0 + SEARCH_BZ - 1 < g->gz ? br->z0 + SEARCH_BZ - 1 : g->gz - 1;
	br->count = 0;
	br->nf = br->nbd = 0;
	for (int zz = br->z0 - R;; ++zz) {
		const uint32_t layer = (uint32_t)(zz - (br->z0 - R));
		br->fluid_layer[layer] = br->nf;
		br->bound_layer[layer] = br->nbd;
		if (zz > br->z1 + R)
			break;
		if (zz < 0 || zz >= g->gz)
			continue;
		const int ez = zz < br->z0 ? br->z0 - zz : zz > br->z1 ? zz - br->z1 : 0;
		for (int yy = br->y0 - R; yy <= br->y1 + R; ++yy) {
			const int ey = yy < br->y0 ? br->y0 - yy : yy > br->y1 ? yy - br->y1 : 0, ext = c->reach[ey][ez];
			if (yy < 0 || yy >= g->gy || ext < 0)
				continue;
			const int x0 = br->x0 >= ext ? br->x0 - ext : 0, x1 = br->x1 < g->gx - ext ? br->x1 + ext : g->gx - 1;
			const size_t row = (size_t)zz * (size_t)g->gy + (size_t)yy;
			uint32_t fb, fe, bb, be;
			sph_cell_start2(g, &g->fluid_start, row, x0, x1 + 1, &fb, &fe);
			sph_cell_start2(g, &g->bound_start, row, x0, x1 + 1, &bb, &be);
			if (fb == fe && bb == be)
				continue; /* nothing in it, and so none of the block's own (most rows around a jet's blocks) */
			cell_run *r = &br->run[br->count++];
			r->fluid_begin = fb;
			r->fluid_end = fe;
			r->bound_begin = bb;
			r->bound_end = be;
			const bool own = ey == 0 && ez == 0;
			r->own_begin = r->own_end = 0;
			if (own)
				sph_cell_start2(g, &g->fluid_start, row, br->x0, br->x1 + 1, &r->own_begin, &r->own_end);
			r->own_row = own ? (uint32_t)((yy - br->y0) + SEARCH_BY * (zz - br->z0)) : 0;
			r->layer = layer;
			r->fluid_at = br->nf;
			br->nf += r->fluid_end - r->fluid_begin;
			br->nbd += r->bound_end - r->bound_begin;
		}
	}
}

/* Candidates [begin, end) of one run into b from at (order: their
 * indices, NULL for the identity); returns the end. */
static uint32_t gather_run(search_buf *b, uint32_t at, const float *x, const float *y, const float *z,
                           const uint32_t *order, uint32_t begin, uint32_t end)
{
	for (uint32_t q = begin; q < end; ++q, ++at) {
		const uint32_t j = order ? order[q] : q;
		b->x[at] = x[j];
		b->y[at] = y[j];
		b->z[at] = z[j];
		b->j[at] = j;
	}
	return at;
}

/* Fluid rows [begin, end) (stored in cell order: one stretch of the
 * columns) into b from at; returns the end. Eight at a time while that
 * stays inside the table's rows (n): up to seven entries past the end are
 * written, into room the next run or the FAR padding overwrites. */
static uint32_t gather_fluid(search_buf *b, uint32_t at, const float *x, const float *y, const float *z, uint32_t begin,
                             uint32_t end, uint32_t n)
{
	float *bx = b->x + at, *by = b->y + at, *bz = b->z + at;
	uint32_t *bj = b->j + at;
	static const uint16_t iota[8] = {0, 1, 2, 3, 4, 5, 6, 7};
	const uint32_t len = end - begin, len8 = (len + 7) & ~7u;
	if (len >= 3 && begin + len8 <= n) /* shorter: the copies cost less than a group */
		for (uint32_t q = 0; q < len8; q += 8) {
			sf8_store(bx + q, sf8_load(x + begin + q));
			sf8_store(by + q, sf8_load(y + begin + q));
			sf8_store(bz + q, sf8_load(z + begin + q));
			simd_widen16_add(begin + q, iota, bj + q);
		}
	else
		for (uint32_t q = 0; q < len; ++q) {
			bx[q] = x[begin + q];
			by[q] = y[begin + q];
			bz[q] = z[begin + q];
			bj[q] = begin + q;
		}
	return at + len;
}

/* The runs' candidates into the buffers, then eight FAR points. */
static void block_gather(const search_ctx *c, const block_runs *br, search_buf *fb, search_buf *bb)
{
	const sph_neighbors *nb = c->nb;
	uint32_t nf = 0, nbd = 0;
	for (int r = 0; r < br->count; ++r) {
		const cell_run *run = &br->run[r];
		nf = gather_fluid(fb, nf, c->x, c->y, c->z, run->fluid_begin, run->fluid_end, c->n);
		nbd = gather_run(bb, nbd, nb->bx, nb->by, nb->bz, c->bound_order, run->bound_begin, run->bound_end);
	}
	for (uint32_t q = 0; q < 8; ++q) {
		fb->x[nf + q] = fb->y[nf + q] = fb->z[nf + q] = FAR;
		fb->j[nf + q] = 0;
		bb->x[nbd + q] = bb->y[nbd + q] = bb->z[nbd + q] = FAR;
		bb->j[nbd + q] = 0;
	}
}

/* ---- the kernel (also compiled as the AVX2 variant) ---- */

/* One group of eight candidates from q: those with r2max - r^2 > 0 (and,
 * tail, among the first left) packed to hit and dv; returns how many. */
static inline uint32_t hit_group(const float *bx, const float *by, const float *bz, const uint32_t *bj, uint32_t q,
                                 sf8 vx, sf8 vy, sf8 vz, sf8 vr2, bool tail, uint32_t left, float *dv, uint32_t *hit)
{
	const sf8 rx = sf8_sub(vx, sf8_load(bx + q)), ry = sf8_sub(vy, sf8_load(by + q)),
			  rz = sf8_sub(vz, sf8_load(bz + q));
	const sf8 d = sf8_sub(vr2, sf8_add(sf8_add(sf8_mul(rx, rx), sf8_mul(ry, ry)), sf8_mul(rz, rz)));
	sf8 in = sf8_gt(d, sf8_zero());
	if (tail)
		in = sf8_and(in, sf8_lanes_below(left));
	return sf8_pack(in, d, bj + q, dv, hit);
}

/* The candidates b[q0..q1) with r2max - r^2 > 0, in order, into b->hit and
 * b->d; returns how many. The whole groups first, then the last one, which
 * reads past q1 (into the padding) and is masked to q1. The arrays are held
 * in locals: sf8_pack's stores may alias anything, and would reload them
 * from b every group. */
__attribute__((noinline)) static uint32_t hits(const search_buf *b, uint32_t q0, uint32_t q1, float xi, float yi,
                                               float zi, float r2max)
{
	const float *bx = b->x, *by = b->y, *bz = b->z;
	const uint32_t *bj = b->j;
	uint32_t *hit = b->hit;
	float *dv = b->d;
	const sf8 vx = sf8_set1(xi), vy = sf8_set1(yi), vz = sf8_set1(zi), vr2 = sf8_set1(r2max);
	/* the output pointers advance, no count beside them: one register
	 * fewer, and the loop keeps every array in a register */
	const uint32_t whole = q0 + ((q1 - q0) & ~7u);
	uint32_t q = q0;
	for (; q < whole; q += 8) {
		const uint32_t k = hit_group(bx, by, bz, bj, q, vx, vy, vz, vr2, false, 8, dv, hit);
		hit += k;
		dv += k;
	}
	if (q < q1) {
		const uint32_t k = hit_group(bx, by, bz, bj, q, vx, vy, vz, vr2, true, q1 - q, dv, hit);
		hit += k;
	}
	return (uint32_t)(hit - b->hit);
}

/* Particle i of run r: its hits into its lists (and, exact, its sums). */
static void search_particle(const search_ctx *c, const block_runs *br, int r, uint32_t i, search_buf *fb,
                            search_buf *bb)
{
	const sph_search_out *o = c->out;
	const cell_run *run = &br->run[r];
	const float xi = c->x[i], yi = c->y[i], zi = c->z[i];
	/* not itself: its own entry is moved away for its turn */
	const uint32_t self = run->fluid_at + (i - run->fluid_begin);
	fb->x[self] = FAR;
	const uint32_t l0 = run->layer - (uint32_t)c->R, l1 = run->layer + (uint32_t)c->R + 1;
	const uint32_t cnt = hits(fb, br->fluid_layer[l0], br->fluid_layer[l1], xi, yi, zi, o->r2max);
	const uint32_t bcnt = hits(bb, br->bound_layer[l0], br->bound_layer[l1], xi, yi, zi, o->r2max);
	fb->x[self] = xi;
	if (c->bound_order)
		sph_sort_hits(bb->hit, bb->d, bcnt);
	sph_cursor *cur = &fb->out[run->own_row];
	const uint32_t most = sph_packed_words_max(cnt); /* packed (sph.h), exact or not */
	uint32_t *list = sph_list_claim(o->list, cur, most);
	sph_list_commit(cur, list ? sph_pack_groups(fb->hit, cnt, list) : most, &o->first[i]);
	uint32_t *blist = sph_list_room(o->blist, &bb->out[run->own_row], bcnt, &o->bfirst[i]);
	if (blist)
		memcpy(blist, bb->hit, bcnt * sizeof *bb->hit);
	o->count[i] = cnt;
	o->bcount[i] = bcnt;
	if (o->exact) {
		const float ws = sph_cube_sum(fb->d, cnt);
		float bws = 0; /* in list order, as the filter sums */
		for (uint32_t q = 0; q < bcnt; ++q)
			bws += c->nb->bvol[bb->hit[q]] * c->nb->bnd.rho[bb->hit[q]] * bb->d[q] * bb->d[q] * bb->d[q];
		c->nb->ksum[i] = sph_kernel_sum(o->mass, o->self, ws, bws);
	}
}

SIMD_DECLARE(bool, search_block, (const search_ctx *c, uint32_t id, search_buf *fb, search_buf *bb));

/* Block id: gather its candidates, search for each of its particles.
 * False when out of memory. */
bool SIMD_NAME(search_block)(const search_ctx *c, uint32_t id, search_buf *fb, search_buf *bb)
{
	block_runs br;
	block_find_runs(c, id, &br);
	if (!search_buf_grow(fb, br.nf) || !search_buf_grow(bb, br.nbd))
		return false;
	block_gather(c, &br, fb, bb);
	for (int r = 0; r < br.count; ++r)
		for (uint32_t i = br.run[r].own_begin; i < br.run[r].own_end; ++i)
			search_particle(c, &br, r, i, fb, bb);
	return true;
}

#ifndef EDDY_SIMD_VARIANT

bool sph_search(eddy_world *w, sph_neighbors *nb, const sph_search_out *out, int threads, sph_cursor *fluid,
                sph_cursor *bound)
{
	search_ctx c = {
		.nb = nb, .out = out, .bound_order = nb->bnd.order, .R = out->exact ? SPH_CELLS_PER_H : SPH_VERLET_CELLS};
	c.n = (uint32_t)w->n;
	c.x = eddy__col(w, COL_X_), c.y = eddy__col(w, COL_Y_), c.z = eddy__col(w, COL_Z_);
	c.blocks_x = (nb->grid.gx + SEARCH_BX - 1) / SEARCH_BX;
	c.blocks_y = (nb->grid.gy + SEARCH_BY - 1) / SEARCH_BY;
	/* reach[a][b]: a cell k cells away is at least (k - 1) cells of h/2 from
	 * the particle, so the block's far corners are skipped */
	const double rs2 = 1.001 * (double)out->r2max * (double)nb->grid.inv_cell *
	                   (double)nb->grid.inv_cell; /* in cells^2, 0.1% for rounding */
	for (int a = 0; a <= c.R; ++a)
		for (int b = 0; b <= c.R; ++b) {
			const double ey = a > 0 ? a - 1 : 0, ez = b > 0 ? b - 1 : 0, rem = rs2 - ey * ey - ez * ez;
			int k = -1;
			if (rem > 0) /* x offsets k with (k - 1)^2 < rem */
				for (k = 0; k < c.R && (double)k * k < rem; ++k)
					;
			c.reach[a][b] = k;
		}
	/* the blocks that hold particles, ascending: marked in a bit per block,
	 * then read off in order (no sort) */
	const uint32_t gx = (uint32_t)nb->grid.gx, gy = (uint32_t)nb->grid.gy;
	const size_t blocks_z = (size_t)(nb->grid.gz + SEARCH_BZ - 1) / SEARCH_BZ,
				 words = ((size_t)c.blocks_x * (size_t)c.blocks_y * blocks_z + 63) / 64;
	const eddy_arena_mark am = eddy__arena_mark(&w->arena); /* ids and mark: the search's own */
	uint32_t *ids = eddy__arena_alloc(&w->arena, (w->n + 1) * sizeof *ids);
	uint64_t *mark = eddy__arena_alloc(&w->arena, words * sizeof *mark);
	if (!ids || !mark)
		return false;
	memset(mark, 0, words * sizeof *mark);
	/* on the threads: a bit set is the same whoever sets it; the rows are in
	 * cell order, so a thread's next row is mostly in the block it marked last */
	const long n = (long)w->n;
#pragma omp parallel num_threads(n > EDDY_PAR_ROWS ? threads : 1) if (n > EDDY_PAR_ROWS && threads > 1)
	{
		uint32_t last = UINT32_MAX;
#pragma omp for schedule(static)
		for (long i = 0; i < n; ++i) {
			const uint32_t cell = sph_cell_at(&nb->grid, c.x[i], c.y[i], c.z[i]); /* as the cell order's pass found */
			const uint32_t cx = cell % gx, cy = cell / gx % gy, cz = cell / (gx * gy);
			const uint32_t id =
				(cz / SEARCH_BZ * (uint32_t)c.blocks_y + cy / SEARCH_BY) * (uint32_t)c.blocks_x + cx / SEARCH_BX;
			if (id != last) {
#pragma omp atomic update
				mark[id / 64] |= 1ull << (id % 64);
				last = id;
			}
		}
	}
	long blocks = 0;
	for (size_t k = 0; k < words; ++k)
		for (uint64_t m = mark[k]; m; m &= m - 1)
			ids[blocks++] = (uint32_t)(k * 64 + (size_t)__builtin_ctzll(m));
	bool (*const block)(const search_ctx *, uint32_t, search_buf *, search_buf *) = SIMD_PICK(search_block);
	bool ok = true;
	out->list->used = out->blist->used = 0;
	*fluid = *bound = (sph_cursor){0};
#pragma omp parallel num_threads(threads) reduction(&& : ok)
	{
		search_buf fb = {0}, bb = {0};
#pragma omp for schedule(dynamic, 2) /* 128 cells a chunk, as with blocks of 16 in chunks of 8 */
		for (long k = 0; k < blocks; ++k)
			ok = ok && block(&c, ids[k], &fb, &bb);
		free(fb.block);
		free(bb.block);
#pragma omp critical
		for (int k = 0; k < SEARCH_ROWS; ++k) {
			sph_cursor_merge(fluid, &fb.out[k]);
			sph_cursor_merge(bound, &bb.out[k]);
		}
	}
	eddy__arena_release(&w->arena, am);
	return ok;
}

#endif
