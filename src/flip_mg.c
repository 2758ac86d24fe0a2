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
 * the preconditioner, and CG's residual and update stay in double.
 *
 * Threads: every stage runs on all threads. A red-black sweep writes each cell
 * of a colour from the other colour only; the residual, restriction and
 * prolongation write each cell once from read-only inputs; CG's dot products
 * are summed in fixed chunks of CHUNK rows in chunk order (as flip_pcg.c) and
 * max|r| is order-free: the result is the same, bit for bit, on any thread
 * count. Memory: the levels are allocated once per grid size and reused; the
 * CG vectors come from the world's arena. */
#include "flip.h"

#include <stdlib.h>
#include <string.h>

enum {
	NU = 2,            /* red-black sweeps before and after the coarse correction */
	COARSE_CELLS = 64, /* the coarsest level has at most this many cells */
	MAX_LEVELS = 24,
	CHUNK = 4096,      /* rows per chunk of a dot product */
	PAR_CELLS = 32768, /* a level below this runs on one thread (same result) */
};

typedef struct mg_level {
	int nx, ny, nz;
	size_t nc;
	float *d, *ox, *oy, *oz, *e; /* operator (see the header) */
	float *x, *b, *r;            /* solution, right-hand side, residual */
} mg_level;

struct flip_mg {
	int nx, ny, nz; /* the fine grid the levels were allocated for */
	int nlev;
	mg_level lev[MAX_LEVELS];
	float *mem;
	int *co_cell;  /* coarsest: the unknowns' cells */
	double *chol;  /* coarsest: dense Cholesky factor, row-major lower */
	double *co_v;  /* coarsest: right-hand side and solution */
	int co_n;      /* coarsest unknowns */
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

static int level_threads(const mg_level *L, int nt) { return L->nc > PAR_CELLS ? nt : 1; }

/* Level 0 from A (each row writes its own cell). */
static void build_fine(mg_level *L, const flip_matrix *A, const int *cell_of, int nt)
{
	memset(L->d, 0, 5 * L->nc * sizeof *L->d); /* d, ox, oy, oz, e are consecutive */
	const int n = A->n;
	nt = n > PAR_CELLS ? nt : 1;
#pragma omp parallel for num_threads(nt) if (nt > 1) schedule(static)
	for (int r = 0; r < n; ++r) {
		const int *nb = &A->nb[6 * r];
		const size_t c = (size_t)cell_of[r];
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
}

/* Level C = 1/2 P0^T F P0 (see the header). */
static void build_coarse(const mg_level *F, mg_level *C, int nt)
{
	const int fx = F->nx, fy = F->ny, fz = F->nz, cx = C->nx, cy = C->ny, cz = C->nz;
	const size_t fsy = (size_t)fx, fsz = (size_t)fx * fy;
	nt = level_threads(F, nt);
#pragma omp parallel for num_threads(nt) if (nt > 1) schedule(static)
	for (int K = 0; K < cz; ++K)
		for (int J = 0; J < cy; ++J)
			for (int I = 0; I < cx; ++I) {
				const size_t cc = (size_t)I + (size_t)cx * ((size_t)J + (size_t)cy * (size_t)K);
				float e = 0, lx = 0, ly = 0, lz = 0;
				bool present = false;
				for (int k = 2 * K; k < 2 * K + 2 && k < fz; ++k)
					for (int j = 2 * J; j < 2 * J + 2 && j < fy; ++j)
						for (int i = 2 * I; i < 2 * I + 2 && i < fx; ++i) {
							const size_t f = (size_t)i + fsy * (size_t)j + fsz * (size_t)k;
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
				C->e[cc] = 0.5f * e;
				C->ox[cc] = 0.5f * lx;
				C->oy[cc] = 0.5f * ly;
				C->oz[cc] = 0.5f * lz;
				C->d[cc] = present ? 1.0f : 0.0f; /* marked here, summed below */
			}
	const size_t sy = (size_t)cx, sz = (size_t)cx * cy;
	nt = level_threads(C, nt);
#pragma omp parallel for num_threads(nt) if (nt > 1) schedule(static)
	for (int K = 0; K < cz; ++K)
		for (int J = 0; J < cy; ++J)
			for (int I = 0; I < cx; ++I) {
				const size_t c = (size_t)I + sy * (size_t)J + sz * (size_t)K;
				if (C->d[c] == 0)
					continue;
				float s = C->e[c] + C->ox[c] + C->oy[c] + C->oz[c];
				if (I > 0)
					s += C->ox[c - 1];
				if (J > 0)
					s += C->oy[c - sy];
				if (K > 0)
					s += C->oz[c - sz];
				C->d[c] = s > 0 ? s : 1.0f; /* s = 0 only by underflow; any positive value keeps M SPD */
			}
}

/* sum of a's links times x around cell c at (i, j, k) */
static inline float neighbours(const mg_level *L, const float *x, size_t c, int i, int j, int k)
{
	const size_t sy = (size_t)L->nx, sz = sy * (size_t)L->ny;
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

/* One Gauss-Seidel pass over the cells of colour col ((i + j + k) % 2). */
static void sweep(mg_level *L, int col, int nt)
{
	const int nx = L->nx, ny = L->ny, nz = L->nz;
	nt = level_threads(L, nt);
#pragma omp parallel for num_threads(nt) if (nt > 1) schedule(static)
	for (int k = 0; k < nz; ++k)
		for (int j = 0; j < ny; ++j) {
			const size_t row = (size_t)nx * ((size_t)j + (size_t)ny * (size_t)k);
			for (int i = (col + j + k) & 1; i < nx; i += 2) {
				const size_t c = row + (size_t)i;
				if (L->d[c] > 0)
					L->x[c] = (L->b[c] + neighbours(L, L->x, c, i, j, k)) / L->d[c];
			}
		}
}

/* r = b - A x (0 off the unknowns) */
static void residual(mg_level *L, int nt)
{
	const int nx = L->nx, ny = L->ny, nz = L->nz;
	nt = level_threads(L, nt);
#pragma omp parallel for num_threads(nt) if (nt > 1) schedule(static)
	for (int k = 0; k < nz; ++k)
		for (int j = 0; j < ny; ++j) {
			const size_t row = (size_t)nx * ((size_t)j + (size_t)ny * (size_t)k);
			for (int i = 0; i < nx; ++i) {
				const size_t c = row + (size_t)i;
				L->r[c] = L->d[c] > 0 ? L->b[c] - L->d[c] * L->x[c] + neighbours(L, L->x, c, i, j, k) : 0.0f;
			}
		}
}

/* Fine cell i of an axis maps to coarse cells a (weight 3/4) and b (1/4);
 * b = a past the domain's side, giving a the whole weight. */
static inline void axis_map(int i, int n, int *a, int *b)
{
	const int I = i >> 1, J = (i & 1) ? I + 1 : I - 1;
	*a = I;
	*b = J < 0 || J >= n ? I : J;
}

/* weight of coarse cell I in fine cell i's interpolation */
static inline float axis_weight(int i, int n, int I)
{
	int a, b;
	axis_map(i, n, &a, &b);
	return (a == I ? 0.75f : 0.0f) + (b == I ? 0.25f : 0.0f);
}

/* C->b = P^T F->r, as a gather over the fine cells each coarse cell feeds */
static void restrict_residual(const mg_level *F, mg_level *C, int nt)
{
	const int fx = F->nx, fy = F->ny, fz = F->nz, cx = C->nx, cy = C->ny, cz = C->nz;
	nt = level_threads(F, nt);
#pragma omp parallel for num_threads(nt) if (nt > 1) schedule(static)
	for (int K = 0; K < cz; ++K)
		for (int J = 0; J < cy; ++J)
			for (int I = 0; I < cx; ++I) {
				const size_t cc = (size_t)I + (size_t)cx * ((size_t)J + (size_t)cy * (size_t)K);
				if (C->d[cc] == 0) {
					C->b[cc] = 0;
					continue;
				}
				float s = 0;
				for (int k = 2 * K - 1; k <= 2 * K + 2; ++k) {
					if (k < 0 || k >= fz)
						continue;
					const float wz = axis_weight(k, cz, K);
					if (wz == 0)
						continue;
					for (int j = 2 * J - 1; j <= 2 * J + 2; ++j) {
						if (j < 0 || j >= fy)
							continue;
						const float wy = axis_weight(j, cy, J);
						if (wy == 0)
							continue;
						const size_t frow = (size_t)fx * ((size_t)j + (size_t)fy * (size_t)k);
						float sr = 0;
						for (int i = 2 * I - 1; i <= 2 * I + 2; ++i)
							if (i >= 0 && i < fx)
								sr += axis_weight(i, cx, I) * F->r[frow + (size_t)i];
						s += wz * wy * sr;
					}
				}
				C->b[cc] = s;
			}
}

/* F->x += P C->x on F's unknowns (C->x is 0 off C's unknowns) */
static void prolong_add(mg_level *F, const mg_level *C, int nt)
{
	const int fx = F->nx, fy = F->ny, fz = F->nz, cx = C->nx, cy = C->ny, cz = C->nz;
	const size_t sy = (size_t)cx, sz = (size_t)cx * cy;
	nt = level_threads(F, nt);
#pragma omp parallel for num_threads(nt) if (nt > 1) schedule(static)
	for (int k = 0; k < fz; ++k)
		for (int j = 0; j < fy; ++j) {
			int ka, kb, ja, jb;
			axis_map(k, cz, &ka, &kb);
			axis_map(j, cy, &ja, &jb);
			const size_t r00 = (size_t)ja * sy + (size_t)ka * sz, r01 = (size_t)jb * sy + (size_t)ka * sz;
			const size_t r10 = (size_t)ja * sy + (size_t)kb * sz, r11 = (size_t)jb * sy + (size_t)kb * sz;
			const size_t row = (size_t)fx * ((size_t)j + (size_t)fy * (size_t)k);
			for (int i = 0; i < fx; ++i) {
				const size_t c = row + (size_t)i;
				if (F->d[c] == 0)
					continue;
				int ia, ib;
				axis_map(i, cx, &ia, &ib);
				const float *x = C->x;
				const float a00 = 0.75f * x[r00 + ia] + 0.25f * x[r00 + ib];
				const float a01 = 0.75f * x[r01 + ia] + 0.25f * x[r01 + ib];
				const float a10 = 0.75f * x[r10 + ia] + 0.25f * x[r10 + ib];
				const float a11 = 0.75f * x[r11 + ia] + 0.25f * x[r11 + ib];
				F->x[c] += 0.75f * (0.75f * a00 + 0.25f * a01) + 0.25f * (0.75f * a10 + 0.25f * a11);
			}
		}
}

/* The coarsest level's dense Cholesky factor; false if it is not positive
 * definite (it is whenever A is). */
static bool coarse_factor(flip_mg *m)
{
	const mg_level *L = &m->lev[m->nlev - 1];
	const int nx = L->nx, ny = L->ny;
	int n = 0;
	for (size_t c = 0; c < L->nc; ++c)
		if (L->d[c] > 0)
			m->co_cell[n++] = (int)c;
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
	memset(L->x, 0, L->nc * sizeof *L->x);
	for (int p = 0; p < n; ++p)
		L->x[m->co_cell[p]] = (float)v[p];
}

/* x_l = V-cycle applied to b_l */
static void vcycle(flip_mg *m, int l, int nt)
{
	if (l == m->nlev - 1) {
		coarse_solve(m);
		return;
	}
	mg_level *L = &m->lev[l], *C = &m->lev[l + 1];
	memset(L->x, 0, L->nc * sizeof *L->x);
	for (int s = 0; s < NU; ++s) {
		sweep(L, 0, nt);
		sweep(L, 1, nt);
	}
	residual(L, nt);
	restrict_residual(L, C, nt);
	vcycle(m, l + 1, nt);
	prolong_add(L, C, nt);
	for (int s = 0; s < NU; ++s) {
		sweep(L, 1, nt);
		sweep(L, 0, nt);
	}
}

/* z = M^-1 r on the rows */
static void precondition(flip_mg *m, const int *cell_of, int n, const double *r, double *z, int nt)
{
	mg_level *L = &m->lev[0];
	const int t = n > PAR_CELLS ? nt : 1;
	/* b is 0 off the unknowns from build_fine's caller; rows overwrite theirs */
#pragma omp parallel for num_threads(t) if (t > 1) schedule(static)
	for (int i = 0; i < n; ++i)
		L->b[cell_of[i]] = (float)r[i];
	vcycle(m, 0, nt);
#pragma omp parallel for num_threads(t) if (t > 1) schedule(static)
	for (int i = 0; i < n; ++i)
		z[i] = (double)L->x[cell_of[i]];
}

static double sum_chunks(const double *part, int nch)
{
	double s = 0;
	for (int c = 0; c < nch; ++c)
		s += part[c];
	return s;
}

static double dot(const double *a, const double *b, int n, double *part, int nt)
{
	const int nch = (n + CHUNK - 1) / CHUNK;
#pragma omp parallel for num_threads(nt) if (nt > 1) schedule(static)
	for (int c = 0; c < nch; ++c) {
		const int lo = c * CHUNK, hi = lo + CHUNK < n ? lo + CHUNK : n;
		double s = 0;
		for (int i = lo; i < hi; ++i)
			s += a[i] * b[i];
		part[c] = s;
	}
	return sum_chunks(part, nch);
}

/* q = A s; returns s . q (chunked) */
static double matvec_dot(const flip_matrix *A, const double *s, double *q, double *part, int nt)
{
	const int n = A->n, nch = (n + CHUNK - 1) / CHUNK;
#pragma omp parallel for num_threads(nt) if (nt > 1) schedule(static)
	for (int c = 0; c < nch; ++c) {
		const int lo = c * CHUNK, hi = lo + CHUNK < n ? lo + CHUNK : n;
		double sq = 0;
		for (int i = lo; i < hi; ++i) {
			const int *nb = &A->nb[6 * i];
			double t = A->diag[i] * s[i];
			for (int d = 0; d < 6; ++d)
				if (nb[d] >= 0)
					t -= flip_off(A, i, d) * s[nb[d]];
			q[i] = t;
			sq += s[i] * t;
		}
		part[c] = sq;
	}
	return sum_chunks(part, nch);
}

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
	const int ntv = n > 4 * CHUNK ? nt : 1, nch = (n + CHUNK - 1) / CHUNK;
	if (!mg_alloc(m, w->nx, w->ny, w->nz))
		return eddy__fail(w, EDDY_ERR_NOMEM, "flip_pressure: out of memory for the multigrid levels (%dx%dx%d cells)",
		                  w->nx, w->ny, w->nz);
	double *mem = eddy__arena_alloc(&w->arena, (4 * (size_t)n + (size_t)nch) * sizeof *mem);
	if (!mem)
		return eddy__fail(w, EDDY_ERR_NOMEM, "flip_pressure: out of memory for %d unknowns", n);
	double *r = mem, *z = mem + n, *s = mem + 2 * (size_t)n, *q = mem + 3 * (size_t)n, *part = mem + 4 * (size_t)n;

	build_fine(&m->lev[0], A, cell_of, nt);
	memset(m->lev[0].b, 0, m->lev[0].nc * sizeof *m->lev[0].b);
	for (int l = 1; l < m->nlev; ++l)
		build_coarse(&m->lev[l - 1], &m->lev[l], nt);
	if (!coarse_factor(m))
		return eddy__fail(w, EDDY_ERR_SOLVER,
		                  "flip_pressure: multigrid coarse matrix not positive definite (%d unknowns)", n);

	memcpy(r, b, (size_t)n * sizeof *r);
	precondition(m, cell_of, n, r, z, nt);
	memcpy(s, z, (size_t)n * sizeof *s);
	double rho = dot(r, z, n, part, ntv);
	for (int k = 1; k <= max_it; ++k) {
		const double sq = matvec_dot(A, s, q, part, ntv);
		*it = k;
		if (!(sq > 0)) { /* breakdown: A is not positive definite on s */
			double rmax = 0;
			for (int i = 0; i < n; ++i)
				rmax = fabs(r[i]) > rmax ? fabs(r[i]) : rmax;
			*res = rmax / bmax;
			*converged = false;
			return EDDY_OK;
		}
		const double alpha = rho / sq;
		double rmax = 0;
#pragma omp parallel for num_threads(ntv) if (ntv > 1) schedule(static) reduction(max : rmax)
		for (int i = 0; i < n; ++i) {
			x[i] += alpha * s[i];
			r[i] -= alpha * q[i];
			rmax = fabs(r[i]) > rmax ? fabs(r[i]) : rmax;
		}
		*res = rmax / bmax;
		if (*res <= tol)
			return EDDY_OK;
		precondition(m, cell_of, n, r, z, nt);
		const double rho_new = dot(r, z, n, part, ntv);
		const double beta = rho_new / rho;
		rho = rho_new;
#pragma omp parallel for num_threads(ntv) if (ntv > 1) schedule(static)
		for (int i = 0; i < n; ++i)
			s[i] = z[i] + beta * s[i];
	}
	*converged = false;
	return EDDY_OK;
}
