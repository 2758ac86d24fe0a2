/* SPDX-License-Identifier: MIT */
/* SPH neighbour lists, made by sph_density every step: a Verlet list over
 * the cell grid, filtered into the exact lists and kernel sums.
 *
 * Reads: x y z, the boundary particles (boundary.c). Writes: the particle
 * table's order, sph_neighbors' lists and sums, sph_shared's pq.
 *
 * Every step the table is put in cell order (a stable counting sort, skipped
 * while in order), so the neighbour passes stream memory and the particle
 * order is a function of the positions.
 *
 * The grid search (search.c), the costly part, runs only when the Verlet
 * list is stale. Its hits, the pairs with r < h (1 + skin), are kept in the
 * rows of that time ("build slots"), followed through later permutations by
 * slot_of / row_of. The list holds while every particle is within skin/2 of
 * where it was at the search (a pair closer than h now was closer than
 * h + skin then); a new particle count or set of boundary systems, or
 * collider particles moved beyond skin/2, force a search. With a skin of 0
 * the search is at h and writes the exact lists and sums itself.
 *
 * Every step each particle's candidates are filtered by r^2 < h^2 into its
 * exact list, sorted by row, and summed in that order: the same bits
 * whenever the last search ran, so a resumed run is bit-identical without
 * checkpointing the Verlet list. Each particle writes only its own lists:
 * the same for any thread count. Every list takes only its own length in
 * its array (sph_lists, sph.h), so a particle away from the walls takes no
 * room for boundary neighbours; an array too small for a pass's lists is
 * enlarged and the pass run again (rare: the arrays only grow, and their
 * unused end costs address space, not memory). */
#include "neighbors.h"
#include "simd.h"
#include "systems.h"

#include <stdlib.h>
#include <string.h>

/* What the filter reads and writes. */
typedef struct filter_ctx {
	sph_neighbors *nb;
	const float *p4;        /* (x y z -) per row */
	const uint32_t *row_of; /* the row of each build slot; NULL: the rows are the slots */
	float h2;
	float mass, self; /* the kernel sum's (sph_kernel_sum) */
	long n;
	uint32_t longest; /* the most candidates any slot has, fluid or boundary */
} filter_ctx;

/* ---- the kernel (also compiled as the AVX2 variant) ---- */

/* Build slot b's fluid candidates (vc of them, packed from cand) with
 * r^2 < h^2, as rows, into jl and their h^2 - r^2 into dv, in candidate
 * order; returns how many. The last group's padding is masked. */
static inline uint32_t filter_fluid(const filter_ctx *f, const uint32_t *packed, uint32_t vc, const float *pi,
                                    uint32_t *jl, float *dv)
{
	sph_groups cand = sph_groups_at(packed);
	const sf8 vx = sf8_set1(pi[0]), vy = sf8_set1(pi[1]), vz = sf8_set1(pi[2]), vh2 = sf8_set1(f->h2),
			  zero = sf8_zero();
	const uint32_t *row_of = f->row_of;
	const float *p4 = f->p4; /* in locals: sf8_pack's stores may alias f */
	uint32_t cnt = 0;
	for (uint32_t q = 0; q < vc; q += 8) {
		/* unpacked in vector-wide operations where the group is 16-bit,
		 * so the packing's vector load of j is forwarded from them */
		uint32_t j[8];
		sph_group_next(&cand, j);
		if (row_of)
			for (uint32_t k = 0; k < 8; ++k)
				j[k] = row_of[j[k]];
		const bool last = q + 8 > vc;
		sf8 px, py, pz, pw;
		sf8_gather_quads(p4, j, &px, &py, &pz, &pw);
		const sf8 rx = sf8_sub(vx, px), ry = sf8_sub(vy, py), rz = sf8_sub(vz, pz);
		const sf8 d = sf8_sub(vh2, sf8_add(sf8_add(sf8_mul(rx, rx), sf8_mul(ry, ry)), sf8_mul(rz, rz)));
		sf8 in = sf8_gt(d, zero);
		if (last)
			in = sf8_and(in, sf8_lanes_below(vc - q));
		cnt += sf8_pack(in, d, j, dv + cnt, jl + cnt);
	}
	return cnt;
}

/* Row i's boundary list from its build slot's candidates (in index order:
 * filtering keeps it), written to the room for all of them (to scratch
 * once the array is full); returns their sum (V_b rho_b (h^2 - r^2)^3). */
static inline float filter_boundary(const filter_ctx *f, long i, uint32_t b, uint32_t *scratch, sph_cursor *cur)
{
	sph_neighbors *nb = f->nb;
	const uint32_t vbc = nb->verlet.bcount[b];
	if (vbc == 0) { /* most particles, away from the walls */
		nb->bfirst[i] = nb->bcount[i] = 0;
		return 0;
	}
	const uint32_t *bcand = nb->verlet.bcand.data + nb->verlet.bfirst[b];
	uint32_t *hits = sph_list_claim(&nb->bnbr, cur, vbc);
	hits = hits ? hits : scratch;
	const float *pi = f->p4 + 4 * i;
	uint32_t bcnt = 0;
	float bws = 0;
	for (uint32_t q = 0; q < vbc; ++q) {
		const uint32_t jb = bcand[q];
		const float rx = pi[0] - nb->bx[jb], ry = pi[1] - nb->by[jb], rz = pi[2] - nb->bz[jb];
		const float d = f->h2 - (rx * rx + ry * ry + rz * rz);
		if (d > 0) {
			hits[bcnt++] = jb;
			bws += nb->bvol[jb] * nb->bnd.rho[jb] * d * d * d;
		}
	}
	sph_list_commit(cur, bcnt, &nb->bfirst[i]);
	nb->bcount[i] = bcnt;
	return bws;
}

SIMD_DECLARE(bool, neighbors_filter, (const filter_ctx *f, int threads, sph_cursor *fluid, sph_cursor *bound));

/* The exact lists and kernel sums from the Verlet list. False when out of
 * memory; *fluid, *bound: the threads' cursors merged (as sph_search). */
bool SIMD_NAME(neighbors_filter)(const filter_ctx *f, int threads, sph_cursor *fluid, sph_cursor *bound)
{
	sph_neighbors *nb = f->nb;
	const size_t longest = f->longest;
	bool ok = true;
	nb->nbr.used = nb->bnbr.used = 0;
	*fluid = *bound = (sph_cursor){0};
#pragma omp parallel num_threads(threads) reduction(&& : ok)
	{
		/* a particle's hits before they are packed (+ 8: sf8_pack writes
		 * whole groups), and its boundary list once that array is full */
		uint32_t *jl = malloc((longest + 8) * sizeof *jl);
		float *dv = malloc((longest + 8) * sizeof *dv);
		sph_cursor cf = {0}, cb = {0};
		ok = jl && dv;
		/* in chunks taken as threads come free, not equal shares: a row's
		 * list and sums are its own, and the lists go where each thread's
		 * claims put them (as sph_search's), so only the layout depends on
		 * the order; equal shares wait for the slower core (dfsph.c) */
#pragma omp for schedule(dynamic, 512)
		for (long i = 0; i < f->n; ++i) {
			if (!ok)
				continue;
			const uint32_t b = nb->verlet.slot_of[i], vc = nb->verlet.count[b];
			const uint32_t cnt = filter_fluid(f, nb->verlet.cand.data + nb->verlet.first[b], vc, f->p4 + 4 * i, jl, dv);
			/* after a permutation since the search (else the candidates are
			 * in ascending rows, and so are their hits), sorted by row: they
			 * are unless a particle changed cell, and then nearly */
			uint32_t descents = 0; /* over the whole list, no early exit: the loop vectorises */
			for (uint32_t a = 1; f->row_of && a < cnt; ++a)
				descents += jl[a - 1] > jl[a];
			if (descents)
				sph_sort_hits(jl, dv, cnt);
			const float ws = sph_cube_sum(dv, cnt);
			/* packed into the list's room (the most words it can take); only
			 * counted once the array is full */
			const uint32_t most = sph_packed_words_max(cnt);
			uint32_t *list = sph_list_claim(&nb->nbr, &cf, most);
			sph_list_commit(&cf, list ? sph_pack_groups(jl, cnt, list) : most, &nb->first[i]);
			nb->count[i] = cnt;
			nb->ksum[i] = sph_kernel_sum(f->mass, f->self, ws, filter_boundary(f, i, b, jl, &cb));
		}
		free(jl);
		free(dv);
#pragma omp critical
		{
			sph_cursor_merge(fluid, &cf);
			sph_cursor_merge(bound, &cb);
		}
	}
	return ok;
}

#ifndef EDDY_SIMD_VARIANT

void eddy__sph_neighbors_free(sph_neighbors *nb)
{
	free(nb->rows);
	eddy__pages_free(nb->nbr.data);
	eddy__pages_free(nb->bnbr.data);
	eddy__pages_free(nb->verlet.cand.data);
	eddy__pages_free(nb->verlet.bcand.data);
	sph_grid_free(&nb->grid);
	sph_boundary_free(nb);
	memset(nb, 0, sizeof *nb);
}

sph_shared *eddy__sph_find(eddy_world *w, const eddy_system *s) { return eddy__provided(w, s, EDDY_CAP_SPH_NEIGHBORS); }

/* The per-step scratch of the cell-order pass. */
typedef struct row_pass {
	uint32_t *key;   /* the cell of each row before the sort */
	uint32_t *order; /* the sort's permutation */
	void *scratch;   /* a float or index per row */
	float *p4;       /* (x y z 0) per row, in the final order */
	bool verlet;     /* the Verlet list is for this count and boundary set: measure the displacement */
	float moved2;    /* m^2, the largest squared displacement from the build slots */
} row_pass;

/* Row i's quad (x y z 0: sph_density puts 1/rho in the fourth) and, with a
 * Verlet list, its squared distance from its build slot's position. */
static inline float row_quad(const float *x, const float *y, const float *z, const row_pass *rp, const sph_verlet *v,
                             long i)
{
	float *q = rp->p4 + 4 * i;
	q[0] = x[i], q[1] = y[i], q[2] = z[i], q[3] = 0;
	if (!rp->verlet)
		return 0;
	const uint32_t b = v->slot_of[i];
	const float dx = x[i] - v->x[b], dy = y[i] - v->y[b], dz = z[i] - v->z[b];
	return dx * dx + dy * dy + dz * dz;
}

/* The table into cell order, the Verlet slots followed through the
 * permutation, the quads and the displacements; returns 1 if the table was
 * in order already, 0 if it was sorted, -1 when out of memory. In order,
 * the first pass is all (a step of a fluid at rest: a parallel region costs
 * a thread wake-up) and grid.fluid_start, which the sort makes, is left to
 * the caller. */
static int cell_order(eddy_world *w, sph_neighbors *nb, row_pass *rp, int threads)
{
	const float *x = eddy__col(w, COL_X_), *y = eddy__col(w, COL_Y_), *z = eddy__col(w, COL_Z_);
	sph_verlet *v = &nb->verlet;
	const long n = (long)w->n;
	int sorted = 1;
	float d2max = 0;
#pragma omp parallel for num_threads(threads) schedule(static) reduction(&& : sorted) reduction(max : d2max)
	for (long i = 0; i < n; ++i) {
		const uint32_t k = sph_cell_at(&nb->grid, x[i], y[i], z[i]);
		rp->key[i] = k;
		sorted = sorted && (i == 0 || sph_cell_at(&nb->grid, x[i - 1], y[i - 1], z[i - 1]) <= k);
		const float d2 = row_quad(x, y, z, rp, v, i);
		d2max = d2 > d2max ? d2 : d2max;
	}
	rp->moved2 = d2max;
	if (sorted)
		return 1;
	if (!sph_counting_sort(rp->key, w->n, &nb->grid, &nb->grid.fluid_start, rp->order))
		return -1;
	eddy__permute_particles(w, rp->order, rp->scratch);
	if (rp->verlet) {
		uint32_t *slot = rp->scratch;
#pragma omp parallel for num_threads(threads) schedule(static)
		for (long i = 0; i < n; ++i)
			slot[i] = v->slot_of[rp->order[i]];
		memcpy(v->slot_of, slot, w->n * sizeof *slot);
		v->rows_moved = true;
	}
	/* the quads in the new order; the displacements are the same set */
	x = eddy__col(w, COL_X_), y = eddy__col(w, COL_Y_), z = eddy__col(w, COL_Z_);
#pragma omp parallel for num_threads(threads) schedule(static)
	for (long i = 0; i < n; ++i) {
		if (rp->verlet)
			v->row_of[v->slot_of[i]] = (uint32_t)i;
		row_quad(x, y, z, rp, v, i);
	}
	return 0;
}

/* l with room for want entries at least; what it held is not kept (no
 * copy: a fresh block's pages stay untouched until a list is written, and
 * the old block's go back to the system: eddy__pages_alloc). */
static bool lists_reserve(sph_lists *l, size_t want)
{
	if (want <= l->alloc)
		return true;
	eddy__pages_free(l->data);
	/* + 1: an empty list at the very end may still have its first word
	 * loaded (sph_groups_at), never used */
	l->data = eddy__pages_alloc((want + 1) * sizeof *l->data);
	l->alloc = l->data ? want : 0;
	return l->data != NULL;
}

/* The room a pass that wanted total entries (and found l too small) gets
 * next: the total with room for the chunks' unused tails, at least twice
 * what l had (so that a rerun cannot fail the same way forever). */
static size_t lists_regrow(const sph_lists *l, uint64_t total, int threads)
{
	const uint64_t want = total + total / 8 + (uint64_t)(SPH_LIST_CURSORS * threads + 1) * SPH_LIST_CHUNK;
	return (size_t)(want > 2 * (uint64_t)l->alloc ? want : 2 * (uint64_t)l->alloc);
}

/* The Verlet candidates (candidates) or the exact lists: the search, or the
 * filter of the candidates kept, rerun on larger arrays until every list
 * fits. The arrays start at an estimate of per_row entries per particle. */
static eddy_status fill_lists(eddy_world *w, sph_shared *sh, const float *p4, bool candidates, int threads)
{
	sph_neighbors *nb = &sh->nb;
	sph_verlet *v = &nb->verlet;
	const size_t n = w->n;
	/* 1e-4 over: the filter's exact test (r < h, another operation order)
	 * must find every pair it would keep among the candidates */
	const float hs = sh->h * (1.0f + v->skin + 1e-4f), r2max = candidates ? hs * hs : sh->k.h2;
	sph_lists *list = candidates ? &v->cand : &nb->nbr, *blist = candidates ? &v->bcand : &nb->bnbr;
	const sph_search_out out = {!candidates,
	                            r2max,
	                            sh->mass,
	                            sh->k.h2 * sh->k.h2 * sh->k.h2,
	                            list,
	                            blist,
	                            candidates ? v->first : nb->first,
	                            candidates ? v->count : nb->count,
	                            candidates ? v->bfirst : nb->bfirst,
	                            candidates ? v->bcount : nb->bcount};
	const filter_ctx f = {nb,       p4,        v->rows_moved ? v->row_of : NULL,
	                      sh->k.h2, sh->mass,  sh->k.h2 * sh->k.h2 * sh->k.h2,
	                      (long)n,  v->longest};
	/* a first guess (a fluid at rest has about 30 neighbours, 50 candidates) */
	size_t want = n * (candidates ? 64 : 40), bwant = n * 8 + SPH_LIST_CHUNK * (size_t)(SPH_LIST_CURSORS * threads + 1);
	for (;;) {
		if (want > UINT32_MAX || bwant > UINT32_MAX || !lists_reserve(list, want) || !lists_reserve(blist, bwant))
			return eddy__fail(w, EDDY_ERR_NOMEM, "sph_density: out of memory for neighbour lists (%zu + %zu entries)",
			                  want, bwant);
		sph_cursor fc, bc;
		const bool ok = !candidates && v->skin > 0 ? SIMD_PICK(neighbors_filter)(&f, threads, &fc, &bc)
		                                           : sph_search(w, nb, &out, threads, &fc, &bc);
		if (!ok)
			return eddy__fail(w, EDDY_ERR_NOMEM, "sph_density: out of scratch memory for the neighbour lists");
		if (candidates) { /* fc.longest counts packed words */
			uint32_t longest = bc.longest;
			for (size_t i = 0; i < n; ++i)
				longest = v->count[i] > longest ? v->count[i] : longest;
			v->longest = longest;
		}
		if (!fc.full && !bc.full)
			return EDDY_OK;
		want = fc.full ? lists_regrow(list, fc.total, threads) : want;
		bwant = bc.full ? lists_regrow(blist, bc.total, threads) : bwant;
	}
}

/* A new Verlet list: search (with a skin) and remember the positions, to
 * size the next skin and to test the displacements against. */
static eddy_status verlet_rebuild(eddy_world *w, sph_shared *sh, const row_pass *rp, int threads)
{
	sph_neighbors *nb = &sh->nb;
	sph_verlet *v = &nb->verlet;
	const size_t n = w->n;
	eddy_status st = sph_boundary_sort(w, nb);
	if (st != EDDY_OK)
		return st;
	/* a skin (sized as neighbors.h says) pays only if the list outlives a
	 * few steps: when particles move a good part of it per step (DFSPH's
	 * steps are ten times WCSPH's) or the count changes every step (an
	 * emitter), it only adds candidates to a search made every step anyway;
	 * then the search is at h until the motion per step, seen against the
	 * last search, would let a skin last */
	const bool count_changed = v->n != 0 && v->n != n;
	const bool off = !sh->verlet;
	const bool emitting = count_changed && v->count_changed && v->age <= 1;
	const float step_move = rp->verlet ? sqrtf(rp->moved2) / (float)v->age : 0.0f;
	const bool fast = rp->verlet && step_move * SPH_SKIN_MIN_LIFE > 0.5f * SPH_SKIN * sh->h;
	const float sized = 2.0f * SPH_SKIN_LIFE * step_move / sh->h;
	v->count_changed = count_changed;
	v->skin = off || emitting || fast ? 0.0f : !rp->verlet ? SPH_SKIN : fminf(SPH_SKIN, fmaxf(SPH_SKIN_MIN, sized));
	if (v->skin > 0 && (st = fill_lists(w, sh, rp->p4, true, threads)) != EDDY_OK)
		return st;
	v->n = n;
	v->boundary_sig = nb->bnd.sig;
	v->rows_moved = false;
	v->age = 0;
	if (off) /* no Verlet per-row arrays */
		return EDDY_OK;
	memcpy(v->x, eddy__col(w, COL_X_), n * sizeof *v->x);
	memcpy(v->y, eddy__col(w, COL_Y_), n * sizeof *v->y);
	memcpy(v->z, eddy__col(w, COL_Z_), n * sizeof *v->z);
	for (size_t i = 0; i < n; ++i)
		v->slot_of[i] = v->row_of[i] = (uint32_t)i;
	return EDDY_OK;
}

/* Builds the lists for the current particle table, reordering it by cell. */
eddy_status eddy__sph_neighbors_build(eddy_world *w, sph_shared *sh, int threads)
{
	sph_neighbors *nb = &sh->nb;
	sph_verlet *v = &nb->verlet;
	eddy_status st = eddy__sph_boundary_ready(w, sh);
	if (st != EDDY_OK)
		return st;
	/* the collider particles where the colliders are now; how far they are
	 * from where the last search saw them counts as a particle's motion */
	const float bmove2 = nb->bnd.ncol ? sph_boundary_move(w, nb) : 0.0f;
	const size_t n = w->n;
	nb->n = n;
	sh->pq = NULL;
	if (n == 0) {
		v->n = 0;
		return EDDY_OK;
	}
	const bool off = !sh->verlet;
	row_pass rp = {.verlet = !off && v->n == n && v->boundary_sig == nb->bnd.sig};
	rp.p4 = eddy__arena_alloc(&w->arena, 4 * n * sizeof *rp.p4);
	if (!rp.p4)
		return eddy__fail(w, EDDY_ERR_NOMEM, "sph_density: out of scratch memory for %zu particles", n);
	/* every per-row array to n rows; what they held is not kept: a new count
	 * forces a search, which needs none of it */
	void **arrays[] = {(void **)&nb->first, (void **)&nb->count, (void **)&nb->bfirst, (void **)&nb->bcount,
	                   (void **)&v->first,  (void **)&v->count,  (void **)&v->bfirst,  (void **)&v->bcount,
	                   (void **)&v->x,      (void **)&v->y,      (void **)&v->z,       (void **)&v->slot_of,
	                   (void **)&v->row_of};
	const int narrays = off ? 4 : (int)(sizeof arrays / sizeof arrays[0]); /* off: the exact lists' only */
	if (!sph_grow_block(&nb->rows, &nb->rows_alloc, n, arrays, narrays))
		return eddy__fail(w, EDDY_ERR_NOMEM, "sph_density: out of memory for %zu particles", n);
	/* key and order in per-row arrays of the last step's exact lists: this
	 * step's are written after their last use (the cell ranges, before any
	 * search); the permutation's scratch in p4, whose quads are rewritten
	 * after it (cell_order): the arena is spared 12 bytes a row */
	rp.key = nb->first;
	rp.order = nb->count;
	rp.scratch = rp.p4;
	nb->ksum = eddy__col(w, COL_DENSITY);
	v->age++;
	const int in_order = cell_order(w, nb, &rp, threads);
	if (in_order < 0)
		return eddy__fail(w, EDDY_ERR_NOMEM, "sph_density: out of memory for the neighbour cells");
	rp.moved2 = bmove2 > rp.moved2 ? bmove2 : rp.moved2;
	/* valid while every particle is within skin/2 of its build slot's
	 * position (0.49: float rounding); false for NaN too */
	const float half = 0.49f * v->skin * sh->h;
	const bool valid = rp.verlet && v->skin > 0 && rp.moved2 < half * half;
	/* the search and the boundary pressure walk cells */
	if (in_order && (!valid || nb->nbound > 0))
		if (!sph_cell_ranges(rp.key, n, &nb->grid, &nb->grid.fluid_start))
			return eddy__fail(w, EDDY_ERR_NOMEM, "sph_density: out of memory for the neighbour cells");
	if (!valid && (st = verlet_rebuild(w, sh, &rp, threads)) != EDDY_OK)
		return st;
	sh->pq = rp.p4;
	st = fill_lists(w, sh, rp.p4, false, threads);
	return st == EDDY_OK ? sph_boundary_divergence(w, sh, threads) : st;
}

#endif
