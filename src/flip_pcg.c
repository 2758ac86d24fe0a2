/* SPDX-License-Identifier: MIT */
/* MIC(0)-preconditioned conjugate gradient for the FLIP pressure system
 * (Bridson, "Fluid Simulation for Computer Graphics", 2nd ed., ch. 5.4:
 * modified incomplete Cholesky with tau = 0.97 and the safety factor
 * sigma = 0.25). Every scalar is double: single-precision dot products stall
 * the iteration on large grids (docs/validation.md, hard case 14). Off-diagonal
 * entries are -a with a the open fraction of the face (flip.h), so the
 * factorisation uses Bridson's general form, not the unit-coefficient one.
 * Threads: the matrix-vector product and the vector updates run on all
 * threads (each row written by one); a dot product is summed in fixed chunks
 * of FLIP_CHUNK rows, the chunk sums added in chunk order, so it is the same on
 * any number of threads; max|r| is order-free. The MIC(0) factorisation and
 * its two triangular solves are sequential by nature (row i needs the rows
 * before it) and stay serial. The result does not depend on the thread count. */
#include "flip.h"

#include <string.h>

enum { NX_M, NX_P, NY_M, NY_P, NZ_M, NZ_P };

/* Each kernel is written once with W (weighted) a compile-time constant and
 * instantiated twice: the unit-coefficient system (no solids) keeps the
 * branch-free loops it had before face weights. */
#define OFF(A, i, d) (W ? (A)->off[6 * (i) + (d)] : 1.0)
#if defined(__GNUC__)
#define KERNEL static inline __attribute__((always_inline))
#else
#define KERNEL static inline
#endif

KERNEL void mic0_w(const flip_matrix *A, double *precon, const bool W)
{
	const double tau = 0.97, sigma = 0.25;
	/* for a lower neighbour across side d: its two upper links other than this one */
	static const int other[6][2] = {{NY_P, NZ_P}, {0, 0}, {NX_P, NZ_P}, {0, 0}, {NX_P, NY_P}, {0, 0}};
	for (int i = 0; i < A->n; ++i) {
		const int *nb = &A->nb[6 * i];
		double e = A->diag[i];
		for (int d = 0; d < 6; d += 2) {
			const int q = nb[d];
			if (q < 0)
				continue;
			/* Bridson's MIC(0) with entries -a: (a_qi p_q)^2 + tau a_qi (a_q,o1 + a_q,o2) p_q^2 */
			const int *nq = &A->nb[6 * q];
			const double a = OFF(A, i, d);
			const double o = (nq[other[d][0]] >= 0 ? OFF(A, q, other[d][0]) : 0.0) +
			                 (nq[other[d][1]] >= 0 ? OFF(A, q, other[d][1]) : 0.0);
			e -= precon[q] * precon[q] * (a * a + tau * a * o);
		}
		if (e < sigma * A->diag[i])
			e = A->diag[i];
		precon[i] = 1.0 / sqrt(e);
	}
}

KERNEL void apply_w(const flip_matrix *A, const double *precon, const double *r, double *y, double *z, const bool W)
{
	for (int i = 0; i < A->n; ++i) {
		const int *nb = &A->nb[6 * i];
		double t = r[i];
		for (int d = 0; d < 6; d += 2)
			if (nb[d] >= 0)
				t += OFF(A, i, d) * precon[nb[d]] * y[nb[d]];
		y[i] = t * precon[i];
	}
	for (int i = A->n; i-- > 0;) {
		const int *nb = &A->nb[6 * i];
		double t = 0;
		for (int d = 1; d < 6; d += 2)
			if (nb[d] >= 0)
				t += OFF(A, i, d) * z[nb[d]];
		z[i] = (y[i] + precon[i] * t) * precon[i];
	}
}

/* Over the rows [lo, hi): s = z + beta s_old (the search direction's update,
 * fused in so that an iteration opens two parallel regions, not four: each
 * row's neighbours are recomputed from z and s_old, read-only here, with the
 * same operations, so the values are those of a separate update), q = A s;
 * returns the chunk's s . q. */
KERNEL double matvec_dot_w(const flip_matrix *A, const double *z, const double *s_old, double beta, double *s,
                           double *q, int lo, int hi, const bool W)
{
	double sq = 0;
	for (int i = lo; i < hi; ++i) {
		const int *nb = &A->nb[6 * i];
		const double si = z[i] + beta * s_old[i];
		double t = A->diag[i] * si;
		for (int d = 0; d < 6; ++d)
			if (nb[d] >= 0)
				t -= OFF(A, i, d) * (z[nb[d]] + beta * s_old[nb[d]]);
		s[i] = si;
		q[i] = t;
		sq += si * t;
	}
	return sq;
}

/* Threads for n rows: one below a size where a parallel region costs more
 * than it saves (the results are the same either way). */
static int pcg_threads(const eddy_world *w, int n) { return n > 4 * FLIP_CHUNK ? w->def.threads : 1; }

double eddy__flip_matvec_dot(const flip_matrix *A, const double *z, const double *s_old, double beta, double *s,
                             double *q, int lo, int hi)
{
	return A->off ? matvec_dot_w(A, z, s_old, beta, s, q, lo, hi, true)
	              : matvec_dot_w(A, z, s_old, beta, s, q, lo, hi, false);
}

double eddy__flip_sum_chunks(const double *part, int nch)
{
	double s = 0;
	for (int c = 0; c < nch; ++c)
		s += part[c];
	return s;
}

/* s = z + beta s_old, q = A s; returns s . q (chunked, see the header) */
static double matvec_dot(const flip_matrix *A, const double *z, const double *s_old, double beta, double *s, double *q,
                         double *part, int nt)
{
	const int n = A->n, nch = (n + FLIP_CHUNK - 1) / FLIP_CHUNK;
#pragma omp parallel for num_threads(nt) if (nt > 1) schedule(static)
	for (int c = 0; c < nch; ++c) {
		const int lo = c * FLIP_CHUNK, hi = lo + FLIP_CHUNK < n ? lo + FLIP_CHUNK : n;
		part[c] = eddy__flip_matvec_dot(A, z, s_old, beta, s, q, lo, hi);
	}
	return eddy__flip_sum_chunks(part, nch);
}

static void mic0(const flip_matrix *A, double *precon)
{
	if (A->off)
		mic0_w(A, precon, true);
	else
		mic0_w(A, precon, false);
}

static void apply(const flip_matrix *A, const double *precon, const double *r, double *y, double *z)
{
	if (A->off)
		apply_w(A, precon, r, y, z, true);
	else
		apply_w(A, precon, r, y, z, false);
}

static double dot(const double *a, const double *b, int n, double *part, int nt)
{
	const int nch = (n + FLIP_CHUNK - 1) / FLIP_CHUNK;
#pragma omp parallel for num_threads(nt) if (nt > 1) schedule(static)
	for (int c = 0; c < nch; ++c) {
		const int lo = c * FLIP_CHUNK, hi = lo + FLIP_CHUNK < n ? lo + FLIP_CHUNK : n;
		double s = 0;
		for (int i = lo; i < hi; ++i)
			s += a[i] * b[i];
		part[c] = s;
	}
	return eddy__flip_sum_chunks(part, nch);
}

static double maxabs(const double *a, int n)
{
	double m = 0;
	for (int i = 0; i < n; ++i)
		m = fabs(a[i]) > m ? fabs(a[i]) : m;
	return m;
}

bool eddy__flip_pcg(eddy_world *w, const flip_matrix *A, const double *b, double *x, double tol, int max_it, int *it,
                    double *res)
{
	const int n = A->n;
	memset(x, 0, (size_t)n * sizeof *x);
	*it = 0;
	*res = 0;
	const double bmax = maxabs(b, n);
	if (n == 0 || bmax == 0)
		return true;
	const int nt = pcg_threads(w, n), nch = (n + FLIP_CHUNK - 1) / FLIP_CHUNK;
	double *mem = eddy__arena_alloc(&w->arena, (6 * (size_t)n + (size_t)nch) * sizeof *mem);
	if (!mem)
		return false;
	double *part = mem + 6 * (size_t)n; /* chunk sums */
	double *precon = mem, *r = mem + n, *y = mem + 2 * (size_t)n, *z = mem + 3 * (size_t)n;
	double *s = mem + 4 * (size_t)n, *s_old = mem + 5 * (size_t)n;
	mic0(A, precon);
	memcpy(r, b, (size_t)n * sizeof *r);
	apply(A, precon, r, y, z);
	/* r . z next to the serial apply: chunked all the same, on one thread
	 * (too short to pay for a parallel region) */
	double rho = dot(r, z, n, part, 1), beta = 0;
	const double *prev = z; /* s_old of the first iteration: s = z + 0 z = z */
	for (int k = 1; k <= max_it; ++k) {
		const double sq = matvec_dot(A, z, prev, beta, s, y, part, nt); /* y doubles as q = A s */
		if (!(sq > 0)) {                                                /* breakdown: A is not positive definite on s */
			*it = k;
			*res = maxabs(r, n) / bmax;
			return false;
		}
		const double alpha = rho / sq;
		double rmax = 0;
#pragma omp parallel for num_threads(nt) if (nt > 1) schedule(static) reduction(max : rmax)
		for (int i = 0; i < n; ++i) {
			x[i] += alpha * s[i];
			r[i] -= alpha * y[i];
			rmax = fabs(r[i]) > rmax ? fabs(r[i]) : rmax;
		}
		*it = k;
		*res = rmax / bmax;
		if (*res <= tol)
			return true;
		apply(A, precon, r, y, z);
		const double rho_new = dot(r, z, n, part, 1);
		beta = rho_new / rho;
		rho = rho_new;
		double *t = s_old; /* this s is the next iteration's s_old */
		s_old = s;
		s = t;
		prev = s_old;
	}
	return false;
}
