/* SPDX-License-Identifier: MIT */
/* The coarse level of sph_dfsph's conjugate gradients: a two-level additive
 * preconditioner under which their iteration count grows far slower with
 * the water's depth than under Jacobi's alone.
 *
 * Reads: the rows' positions (sph_shared pq), the boundary particles'
 * positions, the active set (mask) and the residual r. Writes: z.
 *
 * Jacobi's D'^-1 alone removes the particle-scale error quickly, but the
 * smooth, column-wide error falls by only 1 - c/N an iteration for N layers
 * (its eigenvalue is (h/D)^2 of the diagonal). The coarse part handles it
 * on a grid of cells of side h (8 particles each at spacing h/2):
 *   z = D'^-1 r + P B P^T r / s
 * P maps a cell value to the active particles in the cell (piecewise
 * constant; P^T r sums the residuals per cell, the exact transpose), B is
 * one multigrid V-cycle on the 7-point Poisson operator L of the cells
 * holding an active particle: unit links between two such cells, Dirichlet 0
 * at an empty cell (the free surface, +1 on the diagonal per face), Neumann
 * at a cell holding boundary particles only (the walls mirror the pressure,
 * so no face term). A = dt^2 grad^T grad acts on smooth pressures as a
 * Laplacian, so P^T (A/dt) P ~ s L on smooth vectors; s is A's Rayleigh
 * quotient on the correction itself, y . (A/dt) y / e . L e with e = B P^T r
 * and y = P e (the caller measures y . (A/dt) y with one operator product
 * at a step's first solve), so it includes the kernel's, the lattice's and the staircase's
 * factors without a formula for each.
 *
 * SPD: B = S_bar + (I - S^T L) P0 B_c P0^T (I - L S) with red-black
 * Gauss-Seidel pre-sweeps (red then black) and their adjoint post-sweeps
 * (black then red), restriction the exact transpose of the prolongation and
 * on the coarsest level the same sweeps without a correction: symmetric
 * positive semi-definite (positive definite where every component of fluid
 * cells touches an empty cell); D'^-1 is positive, so z is an SPD
 * preconditioner and CG stays CG: the solve converges to the same tolerance
 * under the same stopping rule, only in fewer iterations.
 * Levels (after McAdams, Sifakis & Teran 2010 and flip_mg.c): level l+1
 * aggregates 2 x 2 x 2 cells of level l (2 x 1 x 1 or 2 x 2 x 1 where an
 * axis is down to two cells: a narrow column still coarsens along its
 * depth), down to COARSEST_CELLS, its operator half the Galerkin
 * product with piecewise-constant P0 (links: half the sum of the child links
 * crossing between two aggregates; the Dirichlet excess: half the children's;
 * the diagonal: excess plus links), a 7-point stencil that stays SPD; the
 * halving matches the Galerkin operator of smooth transfers (flip_mg.c).
 *
 * Cells of side h: A's symbol falls below a Laplacian's at wavelengths of
 * a few h (the kernel smooths the gradient), so a finer grid's Poisson
 * operator would correct those wavelengths wrongly, and a coarser grid
 * leaves more of the smooth error to Jacobi. That mismatch is also why the
 * count still grows slowly with the depth (tests/test_dfsph_coarse.c).
 *
 * Threads: every cell's and every row's result is computed by one loop
 * iteration from values no other iteration of that loop writes (a
 * red-black sweep's cells read only the other colour; the restriction and
 * the Galerkin product gather each aggregate's children in cell order, P^T r
 * each cell's rows in row order, the order a serial scatter adds them in),
 * and the sums are taken per row of cells or per SUM_CHUNK rows, then in
 * order: the same bits for any thread count. The caller's threads run the
 * rows' loops (it passes 1 below its own threshold) and the loops of a
 * level of PAR_CELLS cells or more; smaller levels run serially, where a
 * join would cost more than the sweep. Its cost per iteration: one pass
 * over the rows and one V-cycle over n/8 cells, next to the operator
 * product's two passes over some 30 neighbours per row.
 *
 * Sources: McAdams, Sifakis & Teran, SCA 2010 (the V-cycle as a CG
 * preconditioner); Nicolaides, SINUM 1987, and Tang et al., J. Sci. Comput.
 * 2009 (two-level deflation and additive coarse corrections); Vanek, Mandel
 * & Brezina 1996 (aggregation); Bender & Koschier, TVCG 2017 (the solve). */
#include "dfsph_coarse.h"

#include <string.h>

/* V-cycle red-black sweep pairs before and after each coarse correction,
 * the coarsest level's sweep pairs, the coarsest level's size. */
#define NU 2
#define NU_COARSEST 16
#define COARSEST_CELLS 512
#define MAX_LEVELS 24
/* A level's loops use the threads from this many cells (a sweep then
 * updates 2^14 or more): below it, the few coarse levels' loops are short
 * beside a join (not measured separately; at 1M only level 0, some 130k
 * cells, and level 1 reach it). */
#define PAR_CELLS (1 << 15)
/* The rows' sums are taken in chunks of this many rows (sph_dfsph's
 * DFSPH_SUM_CHUNK): a fluid of one chunk gets the plain serial sum's bits. */
#define SUM_CHUNK 16384

typedef struct level {
	int nx, ny, nz;
	int fx, fy, fz; /* 2: the next level halves this axis; 1: keeps it */
	size_t cells;
	float *d;            /* the diagonal; 0: not an unknown */
	float *e;            /* the Dirichlet excess: d minus the links */
	float *ox, *oy, *oz; /* the link to the +x, +y, +z neighbour (0: none) */
	float *x, *b, *r;
} level;

struct dfsph_coarse {
	long n;
	int threads;            /* for the rows' loops and the levels of PAR_CELLS cells or more */
	uint32_t *cell;         /* each row's level-0 cell, UINT32_MAX off the active set */
	uint32_t *first, *rows; /* level 0's cell c holds rows[first[c] .. first[c + 1]), in row order */
	double *part;           /* partial sums: one per row of cells of level 0 or per SUM_CHUNK rows */
	int nlev;
	level L[MAX_LEVELS];
	double inv_s; /* 1 / s; 0: the coarse part is off */
};

static float *zalloc(eddy_arena *a, size_t cnt)
{
	float *p = eddy__arena_alloc(a, (cnt ? cnt : 1) * sizeof *p);
	if (p)
		memset(p, 0, (cnt ? cnt : 1) * sizeof *p);
	return p;
}

static bool level_alloc(eddy_arena *a, level *L, int nx, int ny, int nz)
{
	L->nx = nx, L->ny = ny, L->nz = nz;
	L->cells = (size_t)nx * ny * nz;
	float **arr[] = {&L->d, &L->e, &L->ox, &L->oy, &L->oz, &L->x, &L->b, &L->r};
	for (size_t k = 0; k < sizeof arr / sizeof *arr; ++k)
		if (!(*arr[k] = zalloc(a, L->cells)))
			return false;
	return true;
}

/* The sum of link x over the cell's six neighbours (the links to outside the
 * box are 0 and never read). */
static inline float neighbours(const level *L, const float *x, size_t c, int i, int j, int k)
{
	const size_t sy = (size_t)L->nx, sz = (size_t)L->nx * L->ny;
	float s = 0;
	if (i > 0)
		s += L->ox[c - 1] * x[c - 1];
	if (i + 1 < L->nx)
		s += L->ox[c] * x[c + 1];
	if (j > 0)
		s += L->oy[c - sy] * x[c - sy];
	if (j + 1 < L->ny)
		s += L->oy[c] * x[c + sy];
	if (k > 0)
		s += L->oz[c - sz] * x[c - sz];
	if (k + 1 < L->nz)
		s += L->oz[c] * x[c + sz];
	return s;
}

/* The threads for a level's loops: cs->threads (the caller's, 1 below its
 * row threshold) on a level of PAR_CELLS cells or more, else 1. */
static int level_threads(const dfsph_coarse *cs, const level *L) { return L->cells >= PAR_CELLS ? cs->threads : 1; }

/* One Gauss-Seidel sweep over the cells of colour col ((i + j + k) % 2): a
 * cell reads only the other colour's, so the rows of cells may run in any
 * order, on any thread. */
static void sweep(level *L, int col, int nt)
{
#pragma omp parallel for num_threads(nt) if (nt > 1) schedule(static) collapse(2)
	for (int k = 0; k < L->nz; ++k)
		for (int j = 0; j < L->ny; ++j) {
			const size_t row = ((size_t)k * L->ny + j) * L->nx;
			for (int i = (col + j + k) & 1; i < L->nx; i += 2) {
				const size_t c = row + i;
				if (L->d[c] > 0)
					L->x[c] = (L->b[c] + neighbours(L, L->x, c, i, j, k)) / L->d[c];
			}
		}
}

/* r = b - L x; with part (ny nz entries), returns x . (L x), summed per row
 * of cells, then the rows' sums in order (the same bits for any thread
 * count). */
static double residual(level *L, double *part, int nt)
{
#pragma omp parallel for num_threads(nt) if (nt > 1) schedule(static) collapse(2)
	for (int k = 0; k < L->nz; ++k)
		for (int j = 0; j < L->ny; ++j) {
			double xlx = 0;
			for (int i = 0; i < L->nx; ++i) {
				const size_t c = ((size_t)k * L->ny + j) * L->nx + i;
				if (!(L->d[c] > 0)) {
					L->r[c] = 0;
					continue;
				}
				const float lx = L->d[c] * L->x[c] - neighbours(L, L->x, c, i, j, k);
				L->r[c] = L->b[c] - lx;
				xlx += (double)L->x[c] * lx;
			}
			if (part)
				part[(size_t)k * L->ny + j] = xlx;
		}
	double xlx = 0;
	for (size_t q = 0; part && q < (size_t)L->ny * L->nz; ++q)
		xlx += part[q];
	return xlx;
}

/* The fine cell (i, j, k)'s aggregate on the next level C. */
static inline size_t parent(const level *F, const level *C, int i, int j, int k)
{
	return ((size_t)(k / F->fz) * C->ny + j / F->fy) * C->nx + i / F->fx;
}

/* Loops over the children of C's cell (I, J, K) on level F in cell order
 * (k, then j, then i), the order the fine cells' serial loop reaches them:
 * a sum gathered over them has the bits of that loop's scatter. */
#define FOR_CHILDREN(F, I, J, K, i, j, k)                                        \
	for (int k = (K) * (F)->fz; k < ((K) + 1) * (F)->fz && k < (F)->nz; ++k)     \
		for (int j = (J) * (F)->fy; j < ((J) + 1) * (F)->fy && j < (F)->ny; ++j) \
			for (int i = (I) * (F)->fx; i < ((I) + 1) * (F)->fx && i < (F)->nx; ++i)

/* Level l + 1 from level l: half the Galerkin product with the aggregation,
 * gathered per aggregate. */
static void build_coarse(const level *F, level *C, int nt)
{
#pragma omp parallel for num_threads(nt) if (nt > 1) schedule(static) collapse(2)
	for (int K = 0; K < C->nz; ++K)
		for (int J = 0; J < C->ny; ++J)
			for (int I = 0; I < C->nx; ++I) {
				float d = 0, e = 0, ox = 0, oy = 0, oz = 0;
				FOR_CHILDREN(F, I, J, K, i, j, k)
				{
					const size_t c = ((size_t)k * F->ny + j) * F->nx + i;
					if (!(F->d[c] > 0))
						continue;
					d = 1; /* an unknown; its value below */
					e += 0.5f * F->e[c];
					/* a link leaving the aggregate on the + side */
					if (F->fx == 1 || (i & 1))
						ox += 0.5f * F->ox[c];
					if (F->fy == 1 || (j & 1))
						oy += 0.5f * F->oy[c];
					if (F->fz == 1 || (k & 1))
						oz += 0.5f * F->oz[c];
				}
				const size_t c = ((size_t)K * C->ny + J) * C->nx + I;
				C->d[c] = d, C->e[c] = e, C->ox[c] = ox, C->oy[c] = oy, C->oz[c] = oz;
			}
	const size_t sy = (size_t)C->nx, sz = (size_t)C->nx * C->ny;
#pragma omp parallel for num_threads(nt) if (nt > 1) schedule(static) collapse(2)
	for (int k = 0; k < C->nz; ++k)
		for (int j = 0; j < C->ny; ++j)
			for (int i = 0; i < C->nx; ++i) {
				const size_t c = ((size_t)k * C->ny + j) * C->nx + i;
				if (!(C->d[c] > 0))
					continue;
				float s = C->e[c] + C->ox[c] + C->oy[c] + C->oz[c];
				s += i > 0 ? C->ox[c - 1] : 0;
				s += j > 0 ? C->oy[c - sy] : 0;
				s += k > 0 ? C->oz[c - sz] : 0;
				C->d[c] = s > 0 ? s : 0; /* an isolated cell with no link and no excess: not an unknown */
			}
}

/* C.b = the sum of F.r over each aggregate (P0^T r, gathered). */
static void restrict_residual(const level *F, level *C, int nt)
{
#pragma omp parallel for num_threads(nt) if (nt > 1) schedule(static) collapse(2)
	for (int K = 0; K < C->nz; ++K)
		for (int J = 0; J < C->ny; ++J)
			for (int I = 0; I < C->nx; ++I) {
				float s = 0;
				FOR_CHILDREN(F, I, J, K, i, j, k)
				{
					const size_t c = ((size_t)k * F->ny + j) * F->nx + i;
					if (F->d[c] > 0)
						s += F->r[c];
				}
				C->b[((size_t)K * C->ny + J) * C->nx + I] = s;
			}
}

/* F.x += P0 C.x on F's unknowns. */
static void prolong_correction(level *F, const level *C, int nt)
{
#pragma omp parallel for num_threads(nt) if (nt > 1) schedule(static) collapse(2)
	for (int k = 0; k < F->nz; ++k)
		for (int j = 0; j < F->ny; ++j)
			for (int i = 0; i < F->nx; ++i) {
				const size_t c = ((size_t)k * F->ny + j) * F->nx + i;
				if (F->d[c] > 0)
					F->x[c] += C->x[parent(F, C, i, j, k)];
			}
}

/* x = B_l b on level l (x from zero). */
static void vcycle(dfsph_coarse *cs, int l)
{
	level *L = &cs->L[l];
	const int nt = level_threads(cs, L);
	memset(L->x, 0, L->cells * sizeof *L->x);
	const bool last = l + 1 == cs->nlev;
	const int nu = last ? NU_COARSEST : NU;
	for (int s = 0; s < nu; ++s) {
		sweep(L, 0, nt);
		sweep(L, 1, nt);
	}
	if (!last) {
		level *C = &cs->L[l + 1];
		residual(L, NULL, nt);
		restrict_residual(L, C, nt);
		vcycle(cs, l + 1);
		prolong_correction(L, C, nt);
	}
	for (int s = 0; s < nu; ++s) {
		sweep(L, 1, nt);
		sweep(L, 0, nt);
	}
}

/* The walls: solid[c] = 1 for the cells of the grid (origin org, cells of
 * side 1 / inv) that hold boundary particles. */
static void mark_walls(const sph_neighbors *nb, const float org[3], const int dim[3], float inv, uint8_t *solid)
{
	for (size_t b = 0; b < nb->nbound; ++b) {
		const float p[3] = {nb->bx[b], nb->by[b], nb->bz[b]};
		int ix[3];
		bool in = true;
		for (int d = 0; d < 3; ++d) {
			const float q = floorf((p[d] - org[d]) * inv);
			in = in && q >= 0 && q < (float)dim[d];
			ix[d] = in ? (int)q : 0;
		}
		if (in)
			solid[((size_t)ix[2] * dim[1] + ix[1]) * dim[0] + ix[0]] = 1;
	}
}

/* Level 0's operator on the cells L0->d marks (d = 1 on entry, the diagonal
 * on return): unit links between unknowns, +1 per face to an empty cell (not
 * a wall's). */
static void level0_operator(level *L0, const int dim[3], const uint8_t *solid, int nt)
{
	const size_t sy = (size_t)dim[0], sz = (size_t)dim[0] * dim[1];
#pragma omp parallel for num_threads(nt) if (nt > 1) schedule(static) collapse(2)
	for (int k = 1; k < dim[2] - 1; ++k)
		for (int j = 1; j < dim[1] - 1; ++j)
			for (int i = 1; i + 1 < dim[0]; ++i) {
				const size_t c = ((size_t)k * dim[1] + j) * dim[0] + i;
				if (!(L0->d[c] > 0))
					continue;
				const size_t nbr[6] = {c - 1, c + 1, c - sy, c + sy, c - sz, c + sz};
				float e = 0; /* faces to empty cells */
				for (int f = 0; f < 6; ++f)
					e += !(L0->d[nbr[f]] > 0) && !solid[nbr[f]] ? 1.0f : 0.0f;
				L0->ox[c] = L0->d[c + 1] > 0 ? 1.0f : 0.0f;
				L0->oy[c] = L0->d[c + sy] > 0 ? 1.0f : 0.0f;
				L0->oz[c] = L0->d[c + sz] > 0 ? 1.0f : 0.0f;
				L0->e[c] = e;
			}
	/* the diagonal once every link is known (d still marks the unknowns; a
	 * cell's d is written only by its own iteration, its neighbours' links
	 * only read) */
	const long cells = (long)L0->cells;
#pragma omp parallel for num_threads(nt) if (nt > 1) schedule(static)
	for (long c = 0; c < cells; ++c)
		if (L0->d[c] > 0) {
			const float s =
				L0->e[c] + L0->ox[c] + L0->oy[c] + L0->oz[c] + L0->ox[c - 1] + L0->oy[c - sy] + L0->oz[c - sz];
			L0->d[c] = s > 0 ? s : 0;
		}
}

/* The rows' chunks for the sums over them. */
static long row_chunks(long n) { return (n + SUM_CHUNK - 1) / SUM_CHUNK; }

dfsph_coarse *eddy__dfsph_coarse_build(eddy_arena *a, const sph_shared *sh, long n, const uint8_t *mask, int threads)
{
	const float H = sh->h, inv = 1.0f / H;
	const int nt = threads > 1 ? threads : 1;
	/* min and max are exact: the same box for any thread count */
	float lx = INFINITY, ly = INFINITY, lz = INFINITY, hx = -INFINITY, hy = -INFINITY, hz = -INFINITY;
	long active = 0;
#pragma omp parallel for num_threads(nt) if (nt > 1) schedule(static) reduction(+ : active) \
	reduction(min : lx, ly, lz) reduction(max : hx, hy, hz)
	for (long i = 0; i < n; ++i) {
		if (!(mask[i] > 0))
			continue;
		++active;
		const float *q = sh->pq + 4 * i;
		lx = q[0] < lx ? q[0] : lx, ly = q[1] < ly ? q[1] : ly, lz = q[2] < lz ? q[2] : lz;
		hx = q[0] > hx ? q[0] : hx, hy = q[1] > hy ? q[1] : hy, hz = q[2] > hz ? q[2] : hz;
	}
	if (active == 0)
		return NULL;
	const float lo[3] = {lx, ly, lz}, hi[3] = {hx, hy, hz};
	dfsph_coarse *cs = eddy__arena_alloc(a, sizeof *cs);
	if (!cs)
		return NULL;
	*cs = (dfsph_coarse){.n = n, .threads = nt};
	/* one cell of margin around the active rows: their cells' neighbours */
	int dim[3];
	float org[3];
	for (int d = 0; d < 3; ++d) {
		org[d] = lo[d] - H;
		const double cells = floor((double)(hi[d] - org[d]) * inv) + 2;
		if (!(cells < 1 << 20)) /* a flying particle far away: no grid that size */
			return NULL;
		dim[d] = (int)cells;
	}
	level *L0 = &cs->L[0];
	if (!level_alloc(a, L0, dim[0], dim[1], dim[2]) || L0->cells >= UINT32_MAX)
		return NULL;
	const size_t nparts =
		(size_t)dim[1] * dim[2] > (size_t)row_chunks(n) ? (size_t)dim[1] * dim[2] : (size_t)row_chunks(n);
	cs->cell = eddy__arena_alloc(a, (size_t)n * sizeof *cs->cell);
	cs->rows = eddy__arena_alloc(a, (size_t)active * sizeof *cs->rows);
	cs->first = eddy__arena_alloc(a, (L0->cells + 1) * sizeof *cs->first);
	cs->part = eddy__arena_alloc(a, nparts * sizeof *cs->part);
	uint8_t *solid = eddy__arena_alloc(a, L0->cells);
	if (!cs->cell || !cs->rows || !cs->first || !cs->part || !solid)
		return NULL;
	memset(solid, 0, L0->cells);
	memset(cs->first, 0, (L0->cells + 1) * sizeof *cs->first);
	/* each active row's cell (clamped off the margin) */
#pragma omp parallel for num_threads(nt) if (nt > 1) schedule(static)
	for (long i = 0; i < n; ++i) {
		cs->cell[i] = UINT32_MAX;
		if (!(mask[i] > 0))
			continue;
		int ix[3];
		for (int d = 0; d < 3; ++d) {
			const int q = (int)((sh->pq[4 * i + d] - org[d]) * inv);
			ix[d] = q < 1 ? 1 : q > dim[d] - 2 ? dim[d] - 2 : q;
		}
		cs->cell[i] = (uint32_t)(((size_t)ix[2] * dim[1] + ix[1]) * dim[0] + ix[0]);
	}
	/* the cells' lists of rows, in row order (a counting sort); the cells
	 * holding one hold the unknowns (d = 1 marks them here) */
	for (long i = 0; i < n; ++i)
		if (cs->cell[i] != UINT32_MAX)
			cs->first[cs->cell[i] + 1]++;
	for (size_t c = 0; c < L0->cells; ++c) {
		L0->d[c] = cs->first[c + 1] > 0 ? 1.0f : 0.0f;
		cs->first[c + 1] += cs->first[c];
	}
	for (long i = 0; i < n; ++i) /* first[c] runs over c's slots, ending at its end: c + 1's start */
		if (cs->cell[i] != UINT32_MAX)
			cs->rows[cs->first[cs->cell[i]]++] = (uint32_t)i;
	for (size_t c = L0->cells; c > 0; --c)
		cs->first[c] = cs->first[c - 1];
	cs->first[0] = 0;
	mark_walls(&sh->nb, org, dim, inv, solid);
	level0_operator(L0, dim, solid, level_threads(cs, L0));
	cs->nlev = 1;
	while (cs->nlev < MAX_LEVELS) {
		level *F = &cs->L[cs->nlev - 1];
		/* an axis of one or two cells stays (a narrow column coarsens along its depth) */
		F->fx = F->nx > 2 ? 2 : 1, F->fy = F->ny > 2 ? 2 : 1, F->fz = F->nz > 2 ? 2 : 1;
		if (F->cells <= COARSEST_CELLS)
			break;
		level *C = &cs->L[cs->nlev];
		if (!level_alloc(a, C, (F->nx + F->fx - 1) / F->fx, (F->ny + F->fy - 1) / F->fy, (F->nz + F->fz - 1) / F->fz))
			return NULL;
		build_coarse(F, C, level_threads(cs, F));
		cs->nlev++;
	}
	return cs;
}

/* (P x)_i: row i's cell's value, 0 off the active set */
static inline float prolong_at(const dfsph_coarse *cs, long i, const float *x)
{
	return cs->cell[i] == UINT32_MAX ? 0.0f : x[cs->cell[i]];
}

/* The level-0 right side P^T r, each cell's rows summed in row order, and
 * the cycle: L0.x = B P^T r. */
static void coarse_solve(dfsph_coarse *cs, const float *r)
{
	level *L0 = &cs->L[0];
	const long cells = (long)L0->cells;
	const int nt = cs->threads;
#pragma omp parallel for num_threads(nt) if (nt > 1) schedule(static)
	for (long c = 0; c < cells; ++c) {
		float s = 0;
		for (uint32_t q = cs->first[c]; q < cs->first[c + 1]; ++q)
			s += r[cs->rows[q]];
		L0->b[c] = s;
	}
	vcycle(cs, 0);
}

double eddy__dfsph_coarse_unit(dfsph_coarse *cs, const float *r, float *y)
{
	coarse_solve(cs, r);
	level *L0 = &cs->L[0];
	const long n = cs->n;
	const int nt = cs->threads;
#pragma omp parallel for num_threads(nt) if (nt > 1) schedule(static)
	for (long i = 0; i < n; ++i)
		y[i] = prolong_at(cs, i, L0->x);
	return residual(L0, cs->part, level_threads(cs, L0));
}

void eddy__dfsph_coarse_set_scale(dfsph_coarse *cs, double s) { cs->inv_s = s > 0 && isfinite(s) ? 1 / s : 0; }

double eddy__dfsph_coarse_apply(dfsph_coarse *cs, const float *r, const float *dsym, float *z)
{
	const bool on = cs->inv_s > 0;
	if (on)
		coarse_solve(cs, r);
	const float *x = cs->L[0].x, inv_s = (float)cs->inv_s;
	const long n = cs->n, nc = row_chunks(n);
	const int nt = cs->threads;
#pragma omp parallel for num_threads(nt) if (nt > 1) schedule(static)
	for (long c = 0; c < nc; ++c) {
		double rz = 0;
		for (long i = c * SUM_CHUNK, e = (c + 1) * SUM_CHUNK < n ? (c + 1) * SUM_CHUNK : n; i < e; ++i) {
			z[i] = dsym[i] * r[i] + (on ? inv_s * prolong_at(cs, i, x) : 0.0f);
			rz += (double)r[i] * z[i];
		}
		cs->part[c] = rz;
	}
	double rz = 0;
	for (long c = 0; c < nc; ++c)
		rz += cs->part[c];
	return rz;
}
