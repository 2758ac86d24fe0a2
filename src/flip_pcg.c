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
 * its two triangular solves are sequential by nature: row i needs its lower
 * neighbours (-x, -y, -z) done first, and the back substitution its upper
 * ones. They run as a pipeline over the grid's planes instead: each z-plane's
 * rows are cut into one band per thread at the same y for every plane (the
 * bands hold about equal rows), and thread t does plane p of its band once
 * thread t - 1 has done plane p (a row's -y neighbour may lie in band t - 1;
 * its -x and -z neighbours are in its own band), so t - 1 runs ahead by a
 * plane or more; the back substitution runs the other way. Every row is
 * computed with the same operations in the same order as in the serial sweep,
 * so the preconditioner gives the same bits on any thread count. A wait is a
 * spin on the neighbour's plane counter that yields its core after a while
 * (on a shared machine the neighbour may be waiting for one). The result does
 * not depend on the thread count. */
#include "flip.h"

#include <sched.h>
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

/* Row i of the MIC(0) factorisation: its lower neighbours' precon first. */
KERNEL void mic0_row(const flip_matrix *A, double *precon, int i, const bool W)
{
	const double tau = 0.97, sigma = 0.25;
	/* for a lower neighbour across side d: its two upper links other than this one */
	static const int other[6][2] = {{NY_P, NZ_P}, {0, 0}, {NX_P, NZ_P}, {0, 0}, {NX_P, NY_P}, {0, 0}};
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

/* Row i of the forward substitution (its lower neighbours' y first). */
KERNEL void forward_row(const flip_matrix *A, const double *precon, const double *r, double *y, int i, const bool W)
{
	const int *nb = &A->nb[6 * i];
	double t = r[i];
	for (int d = 0; d < 6; d += 2)
		if (nb[d] >= 0)
			t += OFF(A, i, d) * precon[nb[d]] * y[nb[d]];
	y[i] = t * precon[i];
}

/* Row i of the back substitution (its upper neighbours' z first). */
KERNEL void backward_row(const flip_matrix *A, const double *precon, const double *y, double *z, int i, const bool W)
{
	const int *nb = &A->nb[6 * i];
	double t = 0;
	for (int d = 1; d < 6; d += 2)
		if (nb[d] >= 0)
			t += OFF(A, i, d) * z[nb[d]];
	z[i] = (y[i] + precon[i] * t) * precon[i];
}

/* The sweeps' pipeline (see the header): the rows of plane p in band t are
 * [at[p * nt + t], at[p * nt + t + 1]), planes counted from the lowest
 * holding a row; done[t * PAD] counts the planes band t has finished (the
 * forward sweep's, then the back substitution's on top). */
enum { PAD = 16 }; /* ints between two bands' counters: one cache line */
typedef struct pipeline {
	int nt, np;
	const int *at;
	int *done;
} pipeline;

typedef enum sweep_kind { SWEEP_MIC0, SWEEP_FORWARD, SWEEP_BACKWARD } sweep_kind;

/* Rows [lo, hi) of one sweep, in its order (the back substitution's downwards). */
KERNEL void band_rows(const flip_matrix *A, double *precon, const double *r, double *y, double *z, int lo, int hi,
                      sweep_kind what, const bool W)
{
	if (what == SWEEP_MIC0)
		for (int i = lo; i < hi; ++i)
			mic0_row(A, precon, i, W);
	else if (what == SWEEP_FORWARD)
		for (int i = lo; i < hi; ++i)
			forward_row(A, precon, r, y, i, W);
	else
		for (int i = hi; i-- > lo;)
			backward_row(A, precon, y, z, i, W);
}

static void wait_for(const int *counter, int want)
{
	for (int spins = 0;; ++spins) {
		if (__atomic_load_n(counter, __ATOMIC_ACQUIRE) >= want)
			return;
		if (spins >= 256)
			sched_yield();
	}
}

static void publish(int *counter, int value) { __atomic_store_n(counter, value, __ATOMIC_RELEASE); }

/* Thread t's part of a sweep: MIC(0) and the forward substitution over the
 * planes upwards, the back substitution downwards, its counter going from
 * base to base + np. */
static void sweep(const pipeline *P, int t, const flip_matrix *A, double *precon, const double *r, double *y, double *z,
                  sweep_kind what, int base)
{
	const int nt = P->nt, np = P->np;
	const bool up = what != SWEEP_BACKWARD;
	const int from = up ? t - 1 : t + 1; /* the band this one waits for */
	for (int k = 0; k < np; ++k) {
		const int p = up ? k : np - 1 - k;
		if (from >= 0 && from < nt)
			wait_for(&P->done[from * PAD], base + k + 1);
		const int lo = P->at[p * nt + t], hi = P->at[p * nt + t + 1];
		if (A->off)
			band_rows(A, precon, r, y, z, lo, hi, what, true);
		else
			band_rows(A, precon, r, y, z, lo, hi, what, false);
		if (nt > 1)
			publish(&P->done[t * PAD], base + k + 1);
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

/* A sweep over all rows in the serial order, on the calling thread. */
static void sweep_serial(const flip_matrix *A, double *precon, const double *r, double *y, double *z, sweep_kind what)
{
	if (A->off)
		band_rows(A, precon, r, y, z, 0, A->n, what, true);
	else
		band_rows(A, precon, r, y, z, 0, A->n, what, false);
}

/* The bands of the pipeline for nt threads over A's rows (cell_of: each
 * row's cell, ascending; the grid nx by ny cells a plane); NULL from the
 * arena: out of memory. A single band (nt 1) is the serial order. */
static bool pipeline_make(eddy_world *w, const int *cell_of, int n, int nt, pipeline *P)
{
	const int nx = w->nx, ny = w->ny;
	const int z0 = cell_of[0] / (nx * ny), np = cell_of[n - 1] / (nx * ny) - z0 + 1;
	int *count = eddy__arena_alloc(&w->arena, (size_t)ny * sizeof *count + 8);
	int *cut = eddy__arena_alloc(&w->arena, ((size_t)nt + 1) * sizeof *cut);
	int *at = eddy__arena_alloc(&w->arena, ((size_t)np * nt + 1) * sizeof *at);
	int *done = eddy__arena_alloc(&w->arena, (size_t)nt * PAD * sizeof *done);
	if (!count || !cut || !at || !done)
		return false;
	/* band t holds the rows with cut[t] <= y < cut[t + 1], about n / nt of them */
	memset(count, 0, (size_t)ny * sizeof *count);
	for (int r = 0; r < n; ++r)
		count[(cell_of[r] / nx) % ny]++;
	cut[0] = 0;
	for (int t = 1, y = 0, below = 0; t < nt; ++t) {
		while (y < ny && (long)below * nt < (long)t * n)
			below += count[y++];
		cut[t] = y;
	}
	cut[nt] = ny;
	/* at[key]: the first row of key = plane * nt + band (rows in cell order
	 * come in ascending keys); a key with no rows starts where the next does */
	for (int k = 0; k <= np * nt; ++k)
		at[k] = -1;
	at[np * nt] = n;
	for (int r = 0, band = 0, last = -1; r < n; ++r) {
		const int y = (cell_of[r] / nx) % ny, key0 = (cell_of[r] / (nx * ny) - z0) * nt;
		band = 0;
		while (y >= cut[band + 1])
			band++;
		const int key = key0 + band;
		if (key != last)
			at[key] = r;
		last = key;
	}
	for (int k = np * nt; k-- > 0;)
		if (at[k] < 0)
			at[k] = at[k + 1];
	memset(done, 0, (size_t)nt * PAD * sizeof *done);
	*P = (pipeline){nt, np, at, done};
	return true;
}

/* precon = MIC(0) of A, on P's threads */
static void mic0(const flip_matrix *A, double *precon, const pipeline *P)
{
	const int nt = P->nt;
	for (int t = 0; t < nt; ++t)
		P->done[t * PAD] = 0;
#pragma omp parallel num_threads(nt) if (nt > 1)
	{
		if (TEAM_SIZE == nt)
			sweep(P, TEAM_RANK, A, precon, NULL, NULL, NULL, SWEEP_MIC0, 0);
		else if (TEAM_RANK == 0) /* fewer threads than bands: the serial order */
			sweep_serial(A, precon, NULL, NULL, NULL, SWEEP_MIC0);
	}
}

/* z = M^-1 r (y: scratch), then r . z (chunked, see the header), on P's
 * threads */
static double apply_dot(const flip_matrix *A, double *precon, const double *r, double *y, double *z, double *part,
                        const pipeline *P)
{
	const int nt = P->nt, n = A->n, nch = (n + FLIP_CHUNK - 1) / FLIP_CHUNK;
	for (int t = 0; t < nt; ++t)
		P->done[t * PAD] = 0;
#pragma omp parallel num_threads(nt) if (nt > 1)
	{
		if (TEAM_SIZE == nt) {
			const int t = TEAM_RANK;
			sweep(P, t, A, precon, r, y, z, SWEEP_FORWARD, 0);
			sweep(P, t, A, precon, r, y, z, SWEEP_BACKWARD, P->np);
		} else if (TEAM_RANK == 0) {
			sweep_serial(A, precon, r, y, z, SWEEP_FORWARD);
			sweep_serial(A, precon, r, y, z, SWEEP_BACKWARD);
		}
#pragma omp barrier
#pragma omp for schedule(static)
		for (int c = 0; c < nch; ++c) {
			const int lo = c * FLIP_CHUNK, hi = lo + FLIP_CHUNK < n ? lo + FLIP_CHUNK : n;
			double s = 0;
			for (int i = lo; i < hi; ++i)
				s += r[i] * z[i];
			part[c] = s;
		}
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

bool eddy__flip_pcg(eddy_world *w, const flip_matrix *A, const int *cell_of, const double *b, double *x, double tol,
                    int max_it, int *it, double *res)
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
	pipeline P;
	if (!pipeline_make(w, cell_of, n, nt, &P))
		return false;
	mic0(A, precon, &P);
	memcpy(r, b, (size_t)n * sizeof *r);
	double rho = apply_dot(A, precon, r, y, z, part, &P), beta = 0;
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
		const double rho_new = apply_dot(A, precon, r, y, z, part, &P);
		beta = rho_new / rho;
		rho = rho_new;
		double *t = s_old; /* this s is the next iteration's s_old */
		s_old = s;
		s = t;
		prev = s_old;
	}
	return false;
}
