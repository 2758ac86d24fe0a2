/* SPH neighbour search: a uniform grid of cell size h/2 over the world bounds
 * (plus a margin of h for the boundary particles behind the walls).
 *
 * Each step: the cell (size h/2, so 5^3 cells cover the support with fewer
 * candidates than 3^3 cells of size h) of every particle, a counting sort by cell (stable, so
 * the order is deterministic), the whole particle table permuted into cell
 * order (eddy__permute_particles) so that the passes over neighbours stream
 * memory, then per particle the 125 cells around it (with x fastest, the five
 * cells along x are one contiguous run of rows, so 25 runs) filtered by
 * r^2 < h^2. The density's kernel sums are accumulated on the way, since
 * r^2 is at hand. The lists are stored with a fixed stride per particle; when a
 * particle has more neighbours than the stride (compressed fluid), the stride
 * grows to the largest count and the lists are built again. Every particle
 * writes only its own list, so the lists are identical for any thread count.
 *
 * Boundary particles (sph_boundary_box systems) are static: they are gathered
 * and cell-sorted once, and again only when the set of boundary systems
 * changes. */
#include "sph.h"
#include "systems.h"

#include <stdlib.h>
#include <string.h>
#ifdef __SSE2__
#include <emmintrin.h>
#endif

void eddy__sph_neighbors_free(sph_neighbors *nb)
{
	free(nb->nbr);
	free(nb->count);
	free(nb->wsum);
	free(nb->bwsum);
	free(nb->bnbr);
	free(nb->bcount);
	free(nb->cell_start);
	free(nb->cell_of);
	free(nb->bx);
	free(nb->by);
	free(nb->bz);
	free(nb->bvol);
	free(nb->bp); /* brho lives in the same block */
	free(nb->bcell_start);
	memset(nb, 0, sizeof *nb);
}

sph_shared *eddy__sph_find(eddy_world *w, const eddy_system *s)
{
	sph_shared *found = NULL;
	for (int k = 0; k < w->order_count; ++k) {
		eddy_system *o = &w->slots[w->order[k]];
		if (o == s)
			break;
		if (o->vt == &eddy__kind_sph_density)
			found = o->data;
	}
	return found;
}

static inline int clampi(int v, int lo, int hi) { return v < lo ? lo : v > hi ? hi : v; }

static inline uint32_t cell_index(const sph_neighbors *nb, float x, float y, float z)
{
	const int cx = clampi((int)((x - nb->ox) * nb->inv), 0, nb->gx - 1);
	const int cy = clampi((int)((y - nb->oy) * nb->inv), 0, nb->gy - 1);
	const int cz = clampi((int)((z - nb->oz) * nb->inv), 0, nb->gz - 1);
	return (uint32_t)((cz * nb->gy + cy) * nb->gx + cx);
}

static eddy_status grid_setup(eddy_world *w, sph_neighbors *nb, float h)
{
	if (nb->cell_start)
		return EDDY_OK;
	const eddy_vec3 lo = w->def.bounds_min, hi = w->def.bounds_max;
	nb->ox = lo.x - h;
	nb->oy = lo.y - h;
	nb->oz = lo.z - h;
	nb->inv = SPH_CELLS_PER_H / h;
	const double gx = ceil((hi.x - lo.x) * nb->inv) + 2 * SPH_CELLS_PER_H,
	             gy = ceil((hi.y - lo.y) * nb->inv) + 2 * SPH_CELLS_PER_H,
	             gz = ceil((hi.z - lo.z) * nb->inv) + 2 * SPH_CELLS_PER_H;
	if (gx * gy * gz > 1.5e8)
		return eddy__fail(w, EDDY_ERR_NOMEM,
		                  "sph_density: the world bounds hold %.0f x %.0f x %.0f neighbour cells of size radius/2 = %g m; "
		                  "shrink the bounds or use a larger radius",
		                  gx, gy, gz, (double)h / SPH_CELLS_PER_H);
	nb->gx = (int)gx;
	nb->gy = (int)gy;
	nb->gz = (int)gz;
	const size_t cells = (size_t)nb->gx * (size_t)nb->gy * (size_t)nb->gz;
	nb->cell_start = calloc(cells + 1, sizeof *nb->cell_start);
	nb->bcell_start = calloc(cells + 1, sizeof *nb->bcell_start);
	if (!nb->cell_start || !nb->bcell_start)
		return eddy__fail(w, EDDY_ERR_NOMEM, "sph_density: out of memory for %zu neighbour cells", cells);
	return EDDY_OK;
}

/* Counting sort of keys[0..n) into order (stable); start gets cells+1 offsets. */
static void counting_sort(const uint32_t *keys, size_t n, size_t cells, uint32_t *start, uint32_t *order)
{
	memset(start, 0, (cells + 1) * sizeof *start);
	for (size_t i = 0; i < n; ++i)
		start[keys[i] + 1]++;
	for (size_t c = 0; c < cells; ++c)
		start[c + 1] += start[c];
	/* order[pos] = i, using start as the running cursor, then shift back */
	for (size_t i = 0; i < n; ++i)
		order[start[keys[i]]++] = (uint32_t)i;
	for (size_t c = cells; c > 0; --c)
		start[c] = start[c - 1];
	start[0] = 0;
}

static uint64_t boundary_signature(const eddy_world *w)
{
	uint64_t sig = 0x9E3779B97F4A7C15ull;
	for (int k = 0; k < w->order_count; ++k) {
		const eddy_system *o = &w->slots[w->order[k]];
		if (o->vt == &eddy__kind_sph_boundary_box)
			sig = (sig ^ ((uint64_t)w->order[k] << 16 | o->generation)) * 0x100000001b3ull;
	}
	return sig;
}

static eddy_status boundary_build(eddy_world *w, sph_shared *sh)
{
	sph_neighbors *nb = &sh->nb;
	const uint64_t sig = boundary_signature(w);
	if (sig == nb->bsig && nb->bx)
		return EDDY_OK;
	size_t total = 0;
	for (int k = 0; k < w->order_count; ++k) {
		const eddy_system *o = &w->slots[w->order[k]];
		if (o->vt == &eddy__kind_sph_boundary_box)
			total += eddy__sph_boundary_box_points(o, sh->h, NULL, NULL, NULL, NULL);
	}
	const size_t alloc = total ? total : 1;
	float *x = malloc(alloc * sizeof *x), *y = malloc(alloc * sizeof *y), *z = malloc(alloc * sizeof *z),
	      *v = malloc(alloc * sizeof *v);
	uint32_t *key = calloc(alloc, sizeof *key), *order = calloc(alloc, sizeof *order);
	free(nb->bx);
	free(nb->by);
	free(nb->bz);
	free(nb->bvol);
	free(nb->bp); /* brho lives in the same block */
	/* one block, bp then brho: it is sph_density's checkpointed state */
	nb->bp = calloc(2 * alloc, sizeof *nb->bp);
	nb->brho = nb->bp ? nb->bp + alloc : NULL;
	nb->bx = malloc(alloc * sizeof *nb->bx);
	nb->by = malloc(alloc * sizeof *nb->by);
	nb->bz = malloc(alloc * sizeof *nb->bz);
	nb->bvol = malloc(alloc * sizeof *nb->bvol);
	eddy_status st = EDDY_OK;
	if (!x || !y || !z || !v || !key || !order || !nb->bx || !nb->by || !nb->bz || !nb->bvol || !nb->bp || !nb->brho) {
		st = eddy__fail(w, EDDY_ERR_NOMEM, "sph_density: out of memory for %zu boundary particles", total);
		goto done;
	}
	size_t at = 0;
	for (int k = 0; k < w->order_count; ++k) {
		const eddy_system *o = &w->slots[w->order[k]];
		if (o->vt == &eddy__kind_sph_boundary_box)
			at += eddy__sph_boundary_box_points(o, sh->h, x + at, y + at, z + at, v + at);
	}
	for (size_t i = 0; i < total; ++i)
		key[i] = cell_index(nb, x[i], y[i], z[i]);
	const size_t cells = (size_t)nb->gx * (size_t)nb->gy * (size_t)nb->gz;
	counting_sort(key, total, cells, nb->bcell_start, order);
	for (size_t i = 0; i < total; ++i) {
		nb->bx[i] = x[order[i]];
		nb->by[i] = y[order[i]];
		nb->bz[i] = z[order[i]];
		nb->bvol[i] = v[order[i]];
		nb->brho[i] = sh->rho0;
	}
	nb->nb = total;
	nb->bsig = sig;
done:
	free(x);
	free(y);
	free(z);
	free(v);
	free(key);
	free(order);
	return st;
}

static bool grow(void **p, size_t *have, size_t want, size_t elem)
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

/* One pass of list building with the current strides; returns the largest
 * fluid and boundary counts seen (a count above the stride means: rebuild). */
static void fill_lists(eddy_world *w, sph_neighbors *nb, const sph_kernel_consts *kc, int threads, uint32_t *max_f,
                       uint32_t *max_b)
{
	const float *x = eddy__col(w, COL_X_), *y = eddy__col(w, COL_Y_), *z = eddy__col(w, COL_Z_);
	const long n = (long)w->n;
	const int gx = nb->gx, gy = nb->gy, gz = nb->gz, R = SPH_CELLS_PER_H;
	const size_t cap = nb->cap, bcap = nb->bcap;
	const float h2 = kc->h2;
	uint32_t mf = 0, mb = 0;
#pragma omp parallel for num_threads(threads) schedule(static) reduction(max : mf, mb)
	for (long i = 0; i < n; ++i) {
		const uint32_t c = nb->cell_of[i];
		const int cx = (int)(c % (uint32_t)gx), cy = (int)(c / (uint32_t)gx % (uint32_t)gy),
		          cz = (int)(c / ((uint32_t)gx * (uint32_t)gy));
		const int x0 = cx >= R ? cx - R : 0, x1 = cx < gx - R ? cx + R : gx - 1;
		const float xi = x[i], yi = y[i], zi = z[i];
#ifdef __SSE2__
		const __m128 vxi = _mm_set1_ps(xi), vyi = _mm_set1_ps(yi), vzi = _mm_set1_ps(zi), vh2 = _mm_set1_ps(h2);
#endif
		uint32_t *list = nb->nbr + (size_t)i * cap, *blist = nb->bnbr + (size_t)i * bcap;
		uint32_t cnt = 0, bcnt = 0;
		float ws = 0, bws = 0;
		for (int dz = -R; dz <= R; ++dz) {
			const int zz = cz + dz;
			if (zz < 0 || zz >= gz)
				continue;
			for (int dy = -R; dy <= R; ++dy) {
				const int yy = cy + dy;
				if (yy < 0 || yy >= gy)
					continue;
				const size_t row = ((size_t)zz * (size_t)gy + (size_t)yy) * (size_t)gx;
				const uint32_t a = nb->cell_start[row + (size_t)x0], e = nb->cell_start[row + (size_t)x1 + 1];
				uint32_t j = a;
#ifdef __SSE2__
				/* four candidates at a time: the distance tests are most of
				 * the search. The lanes do the scalar loop's operations in
				 * the same order (no FMA), and hits are taken in order, so
				 * lists and sums are bit for bit those of the scalar loop. */
				for (; j + 4 <= e; j += 4) {
					const __m128 rx = _mm_sub_ps(vxi, _mm_loadu_ps(x + j)), ry = _mm_sub_ps(vyi, _mm_loadu_ps(y + j)),
					             rz = _mm_sub_ps(vzi, _mm_loadu_ps(z + j));
					const __m128 r2 = _mm_add_ps(_mm_add_ps(_mm_mul_ps(rx, rx), _mm_mul_ps(ry, ry)), _mm_mul_ps(rz, rz));
					const __m128 d4 = _mm_sub_ps(vh2, r2);
					unsigned hit = (unsigned)_mm_movemask_ps(_mm_cmpgt_ps(d4, _mm_setzero_ps()));
					if ((uint32_t)i - j < 4)
						hit &= ~(1u << ((uint32_t)i - j)); /* not itself */
					if (!hit)
						continue;
					float dv[4];
					_mm_storeu_ps(dv, d4);
					for (unsigned q = 0; q < 4; ++q)
						if (hit >> q & 1) {
							if (cnt < cap)
								list[cnt] = j + q;
							cnt++;
							ws += dv[q] * dv[q] * dv[q];
						}
				}
#endif
				for (; j < e; ++j) {
					const float rx = xi - x[j], ry = yi - y[j], rz = zi - z[j];
					const float d = h2 - (rx * rx + ry * ry + rz * rz);
					if (d > 0 && j != (uint32_t)i) {
						if (cnt < cap)
							list[cnt] = j;
						cnt++;
						ws += d * d * d;
					}
				}
				const uint32_t ba = nb->bcell_start[row + (size_t)x0], be = nb->bcell_start[row + (size_t)x1 + 1];
				for (uint32_t jb = ba; jb < be; ++jb) {
					const float rx = xi - nb->bx[jb], ry = yi - nb->by[jb], rz = zi - nb->bz[jb];
					const float d = h2 - (rx * rx + ry * ry + rz * rz);
					if (d > 0) {
						if (bcnt < bcap)
							blist[bcnt] = jb;
						bcnt++;
						bws += nb->bvol[jb] * nb->brho[jb] * d * d * d;
					}
				}
			}
		}
		nb->count[i] = cnt;
		nb->bcount[i] = bcnt;
		nb->wsum[i] = ws;
		nb->bwsum[i] = bws;
		mf = cnt > mf ? cnt : mf;
		mb = bcnt > mb ? bcnt : mb;
	}
	*max_f = mf;
	*max_b = mb;
}

eddy_status eddy__sph_boundary_ready(eddy_world *w, sph_shared *sh)
{
	eddy_status st = grid_setup(w, &sh->nb, sh->h);
	return st == EDDY_OK ? boundary_build(w, sh) : st;
}

eddy_status eddy__sph_neighbors_build(eddy_world *w, sph_shared *sh, int threads)
{
	sph_neighbors *nb = &sh->nb;
	eddy_status st = grid_setup(w, nb, sh->h);
	if (st != EDDY_OK)
		return st;
	st = boundary_build(w, sh);
	if (st != EDDY_OK)
		return st;
	const size_t n = w->n;
	nb->n = n;
	if (n == 0)
		return EDDY_OK;
	if (!nb->cap) {
		nb->cap = 48;
		nb->bcap = 16;
	}
	size_t had = nb->n_alloc;
	if (!grow((void **)&nb->cell_of, &had, n, sizeof *nb->cell_of))
		return eddy__fail(w, EDDY_ERR_NOMEM, "sph_density: out of memory for %zu particles", n);
	had = nb->n_alloc;
	if (!grow((void **)&nb->count, &had, n, sizeof *nb->count))
		return eddy__fail(w, EDDY_ERR_NOMEM, "sph_density: out of memory for %zu particles", n);
	had = nb->n_alloc;
	if (!grow((void **)&nb->bcount, &had, n, sizeof *nb->bcount))
		return eddy__fail(w, EDDY_ERR_NOMEM, "sph_density: out of memory for %zu particles", n);
	had = nb->n_alloc;
	if (!grow((void **)&nb->wsum, &had, n, sizeof *nb->wsum))
		return eddy__fail(w, EDDY_ERR_NOMEM, "sph_density: out of memory for %zu particles", n);
	had = nb->n_alloc;
	if (!grow((void **)&nb->bwsum, &had, n, sizeof *nb->bwsum))
		return eddy__fail(w, EDDY_ERR_NOMEM, "sph_density: out of memory for %zu particles", n);
	nb->n_alloc = had;

	/* cell order */
	float *x = eddy__col(w, COL_X_), *y = eddy__col(w, COL_Y_), *z = eddy__col(w, COL_Z_);
	uint32_t *key = eddy__arena_alloc(&w->arena, n * sizeof *key);
	uint32_t *order = eddy__arena_alloc(&w->arena, n * sizeof *order);
	void *scratch = eddy__arena_alloc(&w->arena, n * sizeof(float));
	if (!key || !order || !scratch)
		return eddy__fail(w, EDDY_ERR_NOMEM, "sph_density: out of scratch memory for %zu particles", n);
	for (size_t i = 0; i < n; ++i)
		key[i] = cell_index(nb, x[i], y[i], z[i]);
	const size_t cells = (size_t)nb->gx * (size_t)nb->gy * (size_t)nb->gz;
	counting_sort(key, n, cells, nb->cell_start, order);
	eddy__permute_particles(w, order, scratch);
	for (size_t i = 0; i < n; ++i)
		nb->cell_of[i] = key[order[i]];

	for (;;) {
		size_t want = n * nb->cap, have = nb->cap_alloc;
		if (!grow((void **)&nb->nbr, &have, want, sizeof *nb->nbr))
			return eddy__fail(w, EDDY_ERR_NOMEM, "sph_density: out of memory for neighbour lists (%zu x %zu)", n, nb->cap);
		nb->cap_alloc = have;
		want = n * nb->bcap;
		have = nb->bcap_alloc;
		if (!grow((void **)&nb->bnbr, &have, want, sizeof *nb->bnbr))
			return eddy__fail(w, EDDY_ERR_NOMEM, "sph_density: out of memory for neighbour lists (%zu x %zu)", n, nb->bcap);
		nb->bcap_alloc = have;
		uint32_t mf, mb;
		fill_lists(w, nb, &sh->k, threads, &mf, &mb);
		if (mf <= nb->cap && mb <= nb->bcap)
			break;
		/* a particle had more neighbours than the stride: widen and redo */
		if (mf > nb->cap)
			nb->cap = (mf + 15) / 16 * 16;
		if (mb > nb->bcap)
			nb->bcap = (mb + 15) / 16 * 16;
	}
	return EDDY_OK;
}
