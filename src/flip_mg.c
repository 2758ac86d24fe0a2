/* SPDX-License-Identifier: MIT */
/* Multigrid-preconditioned conjugate gradient for the FLIP pressure system
 * (McAdams, Sifakis & Teran 2010, "A parallel multigrid Poisson solver for
 * fluids simulation on large grids"): CG in double precision on the rows of
 * flip_matrix (flip.h), preconditioned by one geometric V-cycle on the cell
 * grid in single precision.
 *
 * Reads: the matrix A (diagonal with the ghost-fluid 1/theta terms, links
 * weighted by open face fractions, pinned rows), cell_of (row -> cell) and
 * b. Writes: x with max|b - A x| <= tol max|b|, and the levels it keeps.
 *
 * Levels. Level 0 is A itself laid out on the cell box: per cell the
 * diagonal d (0: not an unknown), the links ox, oy, oz to the +x, +y, +z
 * neighbour (the open fraction, 0 for none) and the excess
 * e = d - sum of its links >= 0 (the air and pinned part of the diagonal).
 * Level l+1 has ceil(n/2) cells per axis; its cell I aggregates the up to
 * 2 x 2 x 2 children C(I), and its operator is the Galerkin product with
 * piecewise-constant prolongation P0, halved:
 *   A_{l+1} = 1/2 P0^T A_l P0:  link(I, J) = 1/2 sum of the child links
 *   between C(I) and C(J), e_I = 1/2 sum of the children's excess,
 *   d_I = e_I + sum of I's links.
 * It stays a 7-point stencil (a weighted graph Laplacian plus a non-negative
 * diagonal), symmetric positive definite whenever A_l is (every component
 * keeps the positive excess of its air side or pinned cell), and it sees
 * the face fractions, the solids and theta without a relabelling rule.
 * Built from the excess, not as d - internal links, so no cancellation can
 * make it indefinite. The factor 1/2: for smooth errors P^T A P with the
 * trilinear P below is 8 h^2 L_2h while P0^T A P0 is 16 h^2 L_2h (L the
 * Laplacian), so the halved aggregate approximates the Galerkin operator of
 * the transfers the cycle uses; unscaled aggregation corrects by half.
 * Transfers: P is cell-centred trilinear interpolation (weights 3/4 and 1/4
 * per axis; beyond the domain's side the nearest coarse cell takes the whole
 * weight, the Neumann wall; a coarse cell that is not an unknown holds 0, the
 * free surface), and restriction R = P^T, computed with the same per-axis
 * weights as a gather so each coarse cell is written by one thread.
 * Smoother: red-black Gauss-Seidel, NU sweeps (red then black) before the
 * coarse correction and NU in the reverse order (black then red) after it,
 * so the post-smoother is the adjoint of the pre-smoother; with R = P^T and
 * SPD coarse operators the cycle is a symmetric positive definite operator
 * M^-1 = S_bar + (I - S^T A) P M_c^-1 P^T (I - A S) (S_bar SPD because
 * Gauss-Seidel converges on an SPD matrix), so CG stays CG. The coarsest
 * level (at most COARSE_CELLS cells) is solved exactly by a dense Cholesky.
 * Single precision in the cycle halves its memory traffic; the cycle is only
 * the preconditioner (its rounding perturbs M^-1 by about 1e-7 relative,
 * which CG absorbs: a test solves to 1e-12), and CG's residual and update
 * stay in double. NU = 2 rather than 1: fewer CG iterations, so fewer of its
 * global reductions, for about the same work per solve.
 * Every level works on the box around its unknowns only (a settling block
 * may fill a sixth of its tank's grid); the arrays span the whole grid.
 *
 * Threads: the whole solve after the level build is one parallel region;
 * each stage splits its planes (or its chunks of FLIP_CHUNK rows) statically among
 * the threads and ends at a barrier only where the next stage reads what a
 * neighbouring thread wrote. A level whose box has at most PAR_CELLS cells,
 * and every level below it, is cycled by one thread while the others wait at
 * the next barrier: its work would not pay for the barriers. A red-black
 * sweep writes each cell of a colour from the other colour only; the
 * residual, restriction and prolongation write each cell once from read-only
 * inputs; CG's dot products are summed in fixed chunks of FLIP_CHUNK rows in chunk
 * order (as flip_pcg.c), each thread adding the same chunk sums in the same
 * order, and max|r| is order-free: the result is the same, bit for bit, on
 * any thread count. CG's search direction is updated inside the
 * matrix-vector product (as flip_pcg.c), r's update fills the cycle's
 * right-hand side and z's gather from the cycle computes r . z, so an
 * iteration's vector work takes three barriers. Under a load that leaves
 * a thread waiting for a core, every barrier can cost a time slice: PAR_CELLS
 * counts them as well as the work. Memory: the levels are allocated once per
 * grid size and reused; the CG vectors come from the world's arena. */
#include "flip.h"

#include <stdlib.h>
#include <string.h>

enum {
	NU = 2,            /* red-black sweeps before and after the coarse correction */
	COARSE_CELLS = 64, /* the coarsest level has at most this many cells */
	MAX_LEVELS = 24,
	PAR_CELLS = 32768, /* a level box of at most this many cells runs on one thread (same result) */
};

typedef struct mg_level {
	int nx, ny, nz;
	size_t nc;
	/* The box [lo, hi) around this solve's unknowns on this level: every
	 * loop stays in it and reads nothing outside it (cells there are not
	 * unknowns, and their entries are stale from earlier solves). */
	int lo[3], hi[3];
	float *d, *ox, *oy, *oz, *e; /* operator (see the header) */
	float *x, *b, *r;            /* solution, right-hand side, residual */
} mg_level;

struct flip_mg {
	int nx, ny, nz; /* the fine grid the levels were allocated for */
	int nlev;
	mg_level lev[MAX_LEVELS];
	float *mem;
	int *co_cell; /* coarsest: the unknowns' cells */
	double *chol; /* coarsest: dense Cholesky factor, row-major lower */
	double *co_v; /* coarsest: right-hand side and solution */
	int co_n;     /* coarsest unknowns */
};

flip_mg *eddy__flip_mg_new(void) { return calloc(1, sizeof(flip_mg)); }

void eddy__flip_mg_free(flip_mg *m)
{
	if (!m)
		return;
	free(m->mem);
	free(m->co_cell);
	free(m->chol);
	free(m->co_v);
	free(m);
}

/* Allocates the levels for an nx x ny x nz grid unless they are there. */
static bool mg_alloc(flip_mg *m, int nx, int ny, int nz)
{
	if (m->mem && m->nx == nx && m->ny == ny && m->nz == nz)
		return true;
	free(m->mem);
	free(m->co_cell);
	free(m->chol);
	free(m->co_v);
	m->mem = NULL;
	m->co_cell = NULL;
	m->chol = NULL;
	m->co_v = NULL;
	int l = 0;
	size_t total = 0;
	for (;;) {
		mg_level *L = &m->lev[l];
		L->nx = nx;
		L->ny = ny;
		L->nz = nz;
		L->nc = (size_t)nx * (size_t)ny * (size_t)nz;
		total += 8 * L->nc;
		if (L->nc <= COARSE_CELLS || l + 1 == MAX_LEVELS)
			break;
		nx = (nx + 1) / 2;
		ny = (ny + 1) / 2;
		nz = (nz + 1) / 2;
		++l;
	}
	m->nlev = l + 1;
	const size_t co = m->lev[l].nc;
	m->mem = malloc(total * sizeof *m->mem);
	m->co_cell = malloc(co * sizeof *m->co_cell);
	m->chol = malloc(co * co * sizeof *m->chol);
	m->co_v = malloc(co * sizeof *m->co_v);
	if (!m->mem || !m->co_cell || !m->chol || !m->co_v) {
		free(m->mem);
		m->mem = NULL;
		return false;
	}
	float *p = m->mem;
	for (int k = 0; k < m->nlev; ++k) {
		mg_level *L = &m->lev[k];
		float **arr[8] = {&L->d, &L->ox, &L->oy, &L->oz, &L->e, &L->x, &L->b, &L->r};
		for (int a = 0; a < 8; ++a) {
			*arr[a] = p;
			p += L->nc;
		}
	}
	m->nx = m->lev[0].nx;
	m->ny = m->lev[0].ny;
	m->nz = m->lev[0].nz;
	return true;
}

static size_t box_cells(const mg_level *L)
{
	return (size_t)(L->hi[0] - L->lo[0]) * (size_t)(L->hi[1] - L->lo[1]) * (size_t)(L->hi[2] - L->lo[2]);
}

static int level_threads(const mg_level *L, int nt) { return box_cells(L) > PAR_CELLS ? nt : 1; }

/* This thread (id of n) inside the solve's parallel region; SOLO is a
 * thread working alone (the whole team's share, no barriers). */
typedef struct team {
	int id, n;
} team;

static const team SOLO = {0, 1};

/* The thread's contiguous share [*a, *b) of [lo, hi) */
static void share(team t, int lo, int hi, int *a, int *b)
{
	const int len = hi - lo, q = len / t.n, rem = len % t.n;
	*a = lo + t.id * q + (t.id < rem ? t.id : rem);
	*b = *a + q + (t.id < rem ? 1 : 0);
}

static void team_sync(team t)
{
	if (t.n > 1) {
#pragma omp barrier
	}
}

static inline size_t cell_at(const mg_level *L, int i, int j, int k)
{
	return (size_t)i + (size_t)L->nx * ((size_t)j + (size_t)L->ny * (size_t)k);
}

/* Level 0 from A (each row writes its own cell), and its box. */
static void build_fine(mg_level *L, const flip_matrix *A, const int *cell_of, int nt)
{
	memset(L->d, 0, 5 * L->nc * sizeof *L->d); /* d, ox, oy, oz, e are consecutive */
	const int n = A->n, nx = L->nx, ny = L->ny;
	nt = n > PAR_CELLS ? nt : 1;
	int x0 = nx, y0 = ny, z0 = L->nz, x1 = 0, y1 = 0, z1 = 0;
#pragma omp parallel for num_threads(nt) if (nt > 1) schedule(static) reduction(min                         \
                                                                                : x0, y0, z0) reduction(max \
                                                                                                        : x1, y1, z1)
	for (int r = 0; r < n; ++r) {
		const int *nb = &A->nb[6 * r];
		const int c = cell_of[r], i = c % nx, j = (c / nx) % ny, k = c / (nx * ny);
		x0 = i < x0 ? i : x0;
		y0 = j < y0 ? j : y0;
		z0 = k < z0 ? k : z0;
		x1 = i + 1 > x1 ? i + 1 : x1;
		y1 = j + 1 > y1 ? j + 1 : y1;
		z1 = k + 1 > z1 ? k + 1 : z1;
		double links = 0;
		for (int d = 0; d < 6; ++d)
			if (nb[d] >= 0)
				links += flip_off(A, r, d);
		L->d[c] = (float)A->diag[r];
		L->ox[c] = nb[1] >= 0 ? (float)flip_off(A, r, 1) : 0.0f;
		L->oy[c] = nb[3] >= 0 ? (float)flip_off(A, r, 3) : 0.0f;
		L->oz[c] = nb[5] >= 0 ? (float)flip_off(A, r, 5) : 0.0f;
		const double e = A->diag[r] - links;
		L->e[c] = e > 0 ? (float)e : 0.0f;
	}
	L->lo[0] = x0;
	L->lo[1] = y0;
	L->lo[2] = z0;
	L->hi[0] = x1;
	L->hi[1] = y1;
	L->hi[2] = z1;
}

/* Level C = 1/2 P0^T F P0 (see the header) over the box of F's box's parents. */
static void build_coarse(const mg_level *F, mg_level *C, int nt)
{
	for (int a = 0; a < 3; ++a) {
		C->lo[a] = F->lo[a] / 2;
		C->hi[a] = (F->hi[a] - 1) / 2 + 1;
	}
	nt = level_threads(C, nt);
#pragma omp parallel for num_threads(nt) if (nt > 1) schedule(static)
	for (int K = C->lo[2]; K < C->hi[2]; ++K)
		for (int J = C->lo[1]; J < C->hi[1]; ++J)
			for (int I = C->lo[0]; I < C->hi[0]; ++I) {
				float e = 0, lx = 0, ly = 0, lz = 0;
				bool present = false;
				for (int k = 2 * K; k < 2 * K + 2; ++k)
					for (int j = 2 * J; j < 2 * J + 2; ++j)
						for (int i = 2 * I; i < 2 * I + 2; ++i) {
							if (i < F->lo[0] || i >= F->hi[0] || j < F->lo[1] || j >= F->hi[1] || k < F->lo[2] ||
							    k >= F->hi[2])
								continue;
							const size_t f = cell_at(F, i, j, k);
							present |= F->d[f] > 0;
							e += F->e[f];
							/* the links leaving the block on its + sides */
							if (i == 2 * I + 1)
								lx += F->ox[f];
							if (j == 2 * J + 1)
								ly += F->oy[f];
							if (k == 2 * K + 1)
								lz += F->oz[f];
						}
				const size_t c = cell_at(C, I, J, K);
				C->e[c] = 0.5f * e;
				C->ox[c] = 0.5f * lx;
				C->oy[c] = 0.5f * ly;
				C->oz[c] = 0.5f * lz;
				C->d[c] = present ? 1.0f : 0.0f; /* marked here, summed below */
			}
	const size_t sy = (size_t)C->nx, sz = sy * (size_t)C->ny;
#pragma omp parallel for num_threads(nt) if (nt > 1) schedule(static)
	for (int K = C->lo[2]; K < C->hi[2]; ++K)
		for (int J = C->lo[1]; J < C->hi[1]; ++J)
			for (int I = C->lo[0]; I < C->hi[0]; ++I) {
				const size_t c = cell_at(C, I, J, K);
				if (C->d[c] == 0)
					continue;
				float s = C->e[c] + C->ox[c] + C->oy[c] + C->oz[c];
				if (I > C->lo[0])
					s += C->ox[c - 1];
				if (J > C->lo[1])
					s += C->oy[c - sy];
				if (K > C->lo[2])
					s += C->oz[c - sz];
				C->d[c] = s > 0 ? s : 1.0f; /* s = 0 only by underflow; any positive value keeps M SPD */
			}
}

/* sum of the links times x around cell c at (i, j, k) (none leave the box) */
static inline float neighbours(const mg_level *L, const float *x, size_t c, int i, int j, int k)
{
	const size_t sy = (size_t)L->nx, sz = sy * (size_t)L->ny;
	float s = 0;
	if (i > L->lo[0])
		s += L->ox[c - 1] * x[c - 1];
	if (i + 1 < L->hi[0])
		s += L->ox[c] * x[c + 1];
	if (j > L->lo[1])
		s += L->oy[c - sy] * x[c - sy];
	if (j + 1 < L->hi[1])
		s += L->oy[c] * x[c + sy];
	if (k > L->lo[2])
		s += L->oz[c - sz] * x[c - sz];
	if (k + 1 < L->hi[2])
		s += L->oz[c] * x[c + sz];
	return s;
}

/* One Gauss-Seidel pass over the cells of colour col ((i + j + k) % 2). */
static void sweep(mg_level *L, int col, team t)
{
	int k0, k1;
	share(t, L->lo[2], L->hi[2], &k0, &k1);
	for (int k = k0; k < k1; ++k)
		for (int j = L->lo[1]; j < L->hi[1]; ++j)
			for (int i = L->lo[0] + ((col + j + k + L->lo[0]) & 1); i < L->hi[0]; i += 2) {
				const size_t c = cell_at(L, i, j, k);
				if (L->d[c] > 0)
					L->x[c] = (L->b[c] + neighbours(L, L->x, c, i, j, k)) / L->d[c];
			}
	team_sync(t);
}

/* r = b - A x (0 off the unknowns) */
static void residual(mg_level *L, team t)
{
	int k0, k1;
	share(t, L->lo[2], L->hi[2], &k0, &k1);
	for (int k = k0; k < k1; ++k)
		for (int j = L->lo[1]; j < L->hi[1]; ++j)
			for (int i = L->lo[0]; i < L->hi[0]; ++i) {
				const size_t c = cell_at(L, i, j, k);
				L->r[c] = L->d[c] > 0 ? L->b[c] - L->d[c] * L->x[c] + neighbours(L, L->x, c, i, j, k) : 0.0f;
			}
	team_sync(t);
}

/* x = 0 on the thread's share of the box */
static void zero_box(mg_level *L, float *x, team t)
{
	int k0, k1;
	share(t, L->lo[2], L->hi[2], &k0, &k1);
	for (int k = k0; k < k1; ++k)
		for (int j = L->lo[1]; j < L->hi[1]; ++j)
			memset(x + cell_at(L, L->lo[0], j, k), 0, (size_t)(L->hi[0] - L->lo[0]) * sizeof *x);
}

/* Interpolation along one axis: fine cell i takes 3/4 of coarse cell a and
 * 1/4 of b. Past the domain's side b = a (a takes the whole weight, the
 * Neumann wall); a b outside the coarse box is not an unknown (value 0), so
 * its weight is dropped. */
typedef struct axis_map {
	int a, b;
	float wb;
} axis_map;

static inline axis_map map_axis(int i, int n, int lo, int hi)
{
	const int I = i >> 1, J = (i & 1) ? I + 1 : I - 1;
	axis_map m = {I, J, 0.25f};
	if (J < 0 || J >= n)
		m.b = I;
	else if (J < lo || J >= hi) {
		m.b = I;
		m.wb = 0;
	}
	return m;
}

/* The fine cells 2I-1 .. 2I+2 of coarse cell I on an axis of nf fine and n
 * coarse cells and their weights in P (map_axis's, so R is P^T): 1/4, 3/4,
 * 3/4, 1/4, where a neighbour past the domain's side gives its 1/4 to I;
 * 0 for a fine cell past the side or outside the fine box [lo, hi) (not an
 * unknown: its residual is 0). */
static inline void axis_gather(int I, int nf, int n, int lo, int hi, float wt[4])
{
	wt[0] = I > 0 ? 0.25f : 0.0f;
	wt[1] = I > 0 ? 0.75f : 1.0f;
	wt[2] = 2 * I + 1 >= nf ? 0.0f : I + 1 < n ? 0.75f : 1.0f;
	wt[3] = 2 * I + 2 < nf ? 0.25f : 0.0f;
	for (int t = 0; t < 4; ++t)
		if (2 * I - 1 + t < lo || 2 * I - 1 + t >= hi)
			wt[t] = 0;
}

/* C->b = P^T F->r, as a gather over the fine cells each coarse cell feeds,
 * and C->x = 0 (the cycle's start on C) */
static void restrict_residual(const mg_level *F, mg_level *C, team t)
{
	int k0, k1;
	share(t, C->lo[2], C->hi[2], &k0, &k1);
	for (int K = k0; K < k1; ++K) {
		float wz[4];
		axis_gather(K, F->nz, C->nz, F->lo[2], F->hi[2], wz);
		for (int J = C->lo[1]; J < C->hi[1]; ++J) {
			float wy[4];
			axis_gather(J, F->ny, C->ny, F->lo[1], F->hi[1], wy);
			for (int I = C->lo[0]; I < C->hi[0]; ++I) {
				const size_t cc = cell_at(C, I, J, K);
				C->x[cc] = 0;
				if (C->d[cc] == 0) {
					C->b[cc] = 0;
					continue;
				}
				float wx[4];
				axis_gather(I, F->nx, C->nx, F->lo[0], F->hi[0], wx);
				float s = 0;
				for (int a = 0; a < 4; ++a) {
					if (wz[a] == 0)
						continue;
					for (int b = 0; b < 4; ++b) {
						if (wy[b] == 0)
							continue;
						float sr = 0;
						for (int c = 0; c < 4; ++c)
							if (wx[c] != 0)
								sr += wx[c] * F->r[cell_at(F, 2 * I - 1 + c, 2 * J - 1 + b, 2 * K - 1 + a)];
						s += wz[a] * wy[b] * sr;
					}
				}
				C->b[cc] = s;
			}
		}
	}
	team_sync(t);
}

/* F->x += P C->x on F's unknowns */
static void prolong_add(mg_level *F, const mg_level *C, team t)
{
	int k0, k1;
	share(t, F->lo[2], F->hi[2], &k0, &k1);
	for (int k = k0; k < k1; ++k)
		for (int j = F->lo[1]; j < F->hi[1]; ++j) {
			const axis_map mz = map_axis(k, C->nz, C->lo[2], C->hi[2]);
			const axis_map my = map_axis(j, C->ny, C->lo[1], C->hi[1]);
			const float *xaa = C->x + cell_at(C, 0, my.a, mz.a), *xba = C->x + cell_at(C, 0, my.b, mz.a);
			const float *xab = C->x + cell_at(C, 0, my.a, mz.b), *xbb = C->x + cell_at(C, 0, my.b, mz.b);
			for (int i = F->lo[0]; i < F->hi[0]; ++i) {
				const size_t c = cell_at(F, i, j, k);
				if (F->d[c] == 0)
					continue;
				const axis_map mx = map_axis(i, C->nx, C->lo[0], C->hi[0]);
				const float raa = 0.75f * xaa[mx.a] + mx.wb * xaa[mx.b];
				const float rba = 0.75f * xba[mx.a] + mx.wb * xba[mx.b];
				const float rab = 0.75f * xab[mx.a] + mx.wb * xab[mx.b];
				const float rbb = 0.75f * xbb[mx.a] + mx.wb * xbb[mx.b];
				F->x[c] += 0.75f * (0.75f * raa + my.wb * rba) + mz.wb * (0.75f * rab + my.wb * rbb);
			}
		}
	team_sync(t);
}

/* The coarsest level's dense Cholesky factor; false if it is not positive
 * definite (it is whenever A is). */
static bool coarse_factor(flip_mg *m)
{
	const mg_level *L = &m->lev[m->nlev - 1];
	const int nx = L->nx, ny = L->ny;
	int n = 0;
	for (int k = L->lo[2]; k < L->hi[2]; ++k)
		for (int j = L->lo[1]; j < L->hi[1]; ++j)
			for (int i = L->lo[0]; i < L->hi[0]; ++i)
				if (L->d[cell_at(L, i, j, k)] > 0)
					m->co_cell[n++] = (int)cell_at(L, i, j, k);
	m->co_n = n;
	double *a = m->chol;
	memset(a, 0, (size_t)n * (size_t)n * sizeof *a);
	for (int p = 0; p < n; ++p) {
		const int c = m->co_cell[p];
		a[(size_t)p * n + p] = L->d[c];
		/* lower triangle: the links to earlier cells (-x, -y, -z) */
		const int i = c % nx, j = (c / nx) % ny, k = c / (nx * ny);
		for (int q = 0; q < p; ++q) {
			const int o = m->co_cell[q];
			double v = 0;
			if (i > 0 && o == c - 1)
				v = L->ox[o];
			else if (j > 0 && o == c - nx)
				v = L->oy[o];
			else if (k > 0 && o == c - nx * ny)
				v = L->oz[o];
			a[(size_t)p * n + q] = -v;
		}
	}
	for (int p = 0; p < n; ++p) {
		for (int q = 0; q <= p; ++q) {
			double s = a[(size_t)p * n + q];
			for (int t = 0; t < q; ++t)
				s -= a[(size_t)p * n + t] * a[(size_t)q * n + t];
			if (q == p) {
				if (!(s > 0))
					return false;
				a[(size_t)p * n + p] = sqrt(s);
			} else {
				a[(size_t)p * n + q] = s / a[(size_t)q * n + q];
			}
		}
	}
	return true;
}

static void coarse_solve(flip_mg *m)
{
	mg_level *L = &m->lev[m->nlev - 1];
	const int n = m->co_n;
	const double *a = m->chol;
	double *v = m->co_v;
	for (int p = 0; p < n; ++p) {
		double s = L->b[m->co_cell[p]];
		for (int t = 0; t < p; ++t)
			s -= a[(size_t)p * n + t] * v[t];
		v[p] = s / a[(size_t)p * n + p];
	}
	for (int p = n; p-- > 0;) {
		double s = v[p];
		for (int t = p + 1; t < n; ++t)
			s -= a[(size_t)t * n + p] * v[t];
		v[p] = s / a[(size_t)p * n + p];
	}
	zero_box(L, L->x, SOLO);
	for (int p = 0; p < n; ++p)
		L->x[m->co_cell[p]] = (float)v[p];
}

/* x_l = V-cycle applied to b_l, x_l = 0 on entry (the caller zeroes it) */
static void vcycle(flip_mg *m, int l, team t)
{
	if (l == m->nlev - 1) {
		if (t.id == 0)
			coarse_solve(m);
		team_sync(t);
		return;
	}
	mg_level *L = &m->lev[l], *C = &m->lev[l + 1];
	if (t.n > 1 && box_cells(L) <= PAR_CELLS) {
		if (t.id == 0)
			vcycle(m, l, SOLO);
		team_sync(t);
		return;
	}
	for (int s = 0; s < NU; ++s) {
		sweep(L, 0, t);
		sweep(L, 1, t);
	}
	residual(L, t);
	restrict_residual(L, C, t);
	vcycle(m, l + 1, t);
	prolong_add(L, C, t);
	for (int s = 0; s < NU; ++s) {
		sweep(L, 1, t);
		sweep(L, 0, t);
	}
}

static double max_chunks(const double *part, int nch)
{
	double m = 0;
	for (int c = 0; c < nch; ++c)
		m = part[c] > m ? part[c] : m;
	return m;
}

/* the end of chunk c of n rows (it starts at c FLIP_CHUNK) */
static int chunk_end(int c, int n) { return (c + 1) * FLIP_CHUNK < n ? (c + 1) * FLIP_CHUNK : n; }

eddy_status eddy__flip_mg_solve(eddy_world *w, flip_mg *m, const flip_matrix *A, const int *cell_of, const double *b,
                                double *x, double tol, int max_it, int *it, double *res, bool *converged)
{
	const int n = A->n;
	memset(x, 0, (size_t)n * sizeof *x);
	*it = 0;
	*res = 0;
	*converged = true;
	double bmax = 0;
	for (int i = 0; i < n; ++i)
		bmax = fabs(b[i]) > bmax ? fabs(b[i]) : bmax;
	if (n == 0 || bmax == 0)
		return EDDY_OK;
	const int nt = w->def.threads > 1 ? w->def.threads : 1;
	const int nch = (n + FLIP_CHUNK - 1) / FLIP_CHUNK;
	if (!mg_alloc(m, w->nx, w->ny, w->nz))
		return eddy__fail(w, EDDY_ERR_NOMEM, "flip_pressure: out of memory for the multigrid levels (%dx%dx%d cells)",
		                  w->nx, w->ny, w->nz);
	double *mem = eddy__arena_alloc(&w->arena, (5 * (size_t)n + 3 * (size_t)nch) * sizeof *mem);
	if (!mem)
		return eddy__fail(w, EDDY_ERR_NOMEM, "flip_pressure: out of memory for %d unknowns", n);
	double *r = mem, *z = mem + n, *s = mem + 2 * (size_t)n, *s_old = mem + 3 * (size_t)n, *q = mem + 4 * (size_t)n;
	/* chunk sums of s . q, of r . z and the chunk maxima of |r|: separate, so
	 * no thread overwrites one that another is still adding up */
	double *part_sq = mem + 5 * (size_t)n, *part_rz = part_sq + nch, *part_max = part_rz + nch;

	build_fine(&m->lev[0], A, cell_of, nt);
	for (int l = 1; l < m->nlev; ++l)
		build_coarse(&m->lev[l - 1], &m->lev[l], nt);
	if (!coarse_factor(m))
		return eddy__fail(w, EDDY_ERR_SOLVER,
		                  "flip_pressure: multigrid coarse matrix not positive definite (%d unknowns)", n);

	mg_level *L0 = &m->lev[0];
	int iters = 0;
	double resid = 0;
	bool conv = false;
	const int ntr = n > 4 * FLIP_CHUNK ? nt : 1; /* a small solve does not pay for a team */
#pragma omp parallel num_threads(ntr) if (ntr > 1)
	{
		const team t = {TEAM_RANK, TEAM_SIZE};
		int c0, c1; /* the thread's chunks */
		share(t, 0, nch, &c0, &c1);
		/* Level 0's x stays 0 off the unknowns (no stage writes there); on
		 * them it is zeroed with each new right-hand side. */
		zero_box(L0, L0->x, t);
		team_sync(t);
		for (int c = c0; c < c1; ++c)
			for (int i = c * FLIP_CHUNK; i < chunk_end(c, n); ++i) {
				r[i] = b[i];
				L0->b[cell_of[i]] = (float)r[i];
				L0->x[cell_of[i]] = 0;
			}
		team_sync(t);
		double rho = 0, beta = 0;
		double *sk = s, *sk_old = s_old; /* swapped by every thread alike */
		for (int k = 0; k <= max_it; ++k) {
			if (k > 0) {
				for (int c = c0; c < c1; ++c) {
					const int c_hi = chunk_end(c, n);
					/* the first direction is z: s_old = z, beta = 0 */
					part_sq[c] = eddy__flip_matvec_dot(A, z, k == 1 ? z : sk_old, k == 1 ? 0.0 : beta, sk, q,
					                                   c * FLIP_CHUNK, c_hi);
				}
				team_sync(t);
				const double sq = eddy__flip_sum_chunks(part_sq, nch);
				if (t.id == 0)
					iters = k;
				if (!(sq > 0)) { /* breakdown: A is not positive definite on s */
					if (t.id == 0) {
						double rmax = 0;
						for (int i = 0; i < n; ++i)
							rmax = fabs(r[i]) > rmax ? fabs(r[i]) : rmax;
						resid = rmax / bmax;
					}
					break;
				}
				const double alpha = rho / sq;
				for (int c = c0; c < c1; ++c) {
					const int c_hi = chunk_end(c, n);
					double rmax = 0;
					for (int i = c * FLIP_CHUNK; i < c_hi; ++i) {
						x[i] += alpha * sk[i];
						r[i] -= alpha * q[i];
						rmax = fabs(r[i]) > rmax ? fabs(r[i]) : rmax;
						L0->b[cell_of[i]] = (float)r[i];
						L0->x[cell_of[i]] = 0;
					}
					part_max[c] = rmax;
				}
				team_sync(t);
				const double rk = max_chunks(part_max, nch) / bmax;
				if (t.id == 0)
					resid = rk;
				if (rk <= tol) {
					if (t.id == 0)
						conv = true;
					break;
				}
				if (k == max_it)
					break;
			}
			vcycle(m, 0, t);
			for (int c = c0; c < c1; ++c) {
				const int c_hi = chunk_end(c, n);
				double rz = 0;
				for (int i = c * FLIP_CHUNK; i < c_hi; ++i) {
					z[i] = (double)L0->x[cell_of[i]];
					rz += r[i] * z[i];
				}
				part_rz[c] = rz;
			}
			team_sync(t);
			const double rho_new = eddy__flip_sum_chunks(part_rz, nch);
			beta = k > 0 ? rho_new / rho : 0;
			rho = rho_new;
			double *tmp = sk_old; /* this s is the next iteration's s_old */
			sk_old = sk;
			sk = tmp;
		}
	}
	*it = iters;
	*res = resid;
	*converged = conv;
	return EDDY_OK;
}
