/* SPDX-License-Identifier: MIT */
/* CHOLMOD for the FLIP pressure system: the only file that includes
 * cholmod.h. Supernodal Cholesky (LL^T) of the symmetric positive definite
 * matrix (singular components are pinned by flip_pressure before it gets
 * here). The symbolic analysis (fill-reducing ordering, supernodes) is kept
 * and reused while the fluid-cell pattern stays the same, so a still scene
 * pays only the numeric factorisation. Each solver owns its cholmod_common:
 * no global state. */
#include "flip.h"

#include <stdlib.h>
#include <string.h>
#include <suitesparse/cholmod.h>

struct flip_cholmod {
	cholmod_common c;
	cholmod_factor *L;
	int n, nnz;
	int *colptr, *rowidx; /* the pattern L was analysed for */
};

flip_cholmod *eddy__flip_cholmod_new(void)
{
	flip_cholmod *s = calloc(1, sizeof *s);
	if (!s)
		return NULL;
	if (!cholmod_start(&s->c)) {
		free(s);
		return NULL;
	}
	s->c.supernodal = CHOLMOD_SUPERNODAL;
	s->c.print = 0;
	s->c.error_handler = NULL;
	return s;
}

void eddy__flip_cholmod_free(flip_cholmod *s)
{
	if (!s)
		return;
	if (s->L)
		cholmod_free_factor(&s->L, &s->c);
	cholmod_finish(&s->c);
	free(s->colptr);
	free(s->rowidx);
	free(s);
}

static const char *status_text(int st)
{
	switch (st) {
	case CHOLMOD_OK:
		return "ok";
	case CHOLMOD_NOT_INSTALLED:
		return "method not installed";
	case CHOLMOD_OUT_OF_MEMORY:
		return "out of memory";
	case CHOLMOD_TOO_LARGE:
		return "problem too large";
	case CHOLMOD_INVALID:
		return "invalid input";
	case CHOLMOD_GPU_PROBLEM:
		return "GPU problem";
	case CHOLMOD_NOT_POSDEF:
		return "matrix not positive definite";
	case CHOLMOD_DSMALL:
		return "tiny diagonal";
	default:
		return "unknown status";
	}
}

eddy_status eddy__flip_cholmod_solve(eddy_world *w, flip_cholmod *s, const flip_matrix *A, const double *b, double *x,
                                     bool *reanalysed)
{
	const int n = A->n;
	*reanalysed = false;
	if (n == 0)
		return EDDY_OK;
	/* upper triangle, column by column: rows -z, -y, -x (ascending), then the diagonal */
	int nnz = 0;
	for (int j = 0; j < n; ++j)
		nnz += 1 + (A->nb[6 * j + 4] >= 0) + (A->nb[6 * j + 2] >= 0) + (A->nb[6 * j + 0] >= 0);
	cholmod_sparse *M = cholmod_allocate_sparse((size_t)n, (size_t)n, (size_t)nnz, 1, 1, 1, CHOLMOD_REAL, &s->c);
	if (!M)
		return eddy__fail(w, EDDY_ERR_NOMEM, "flip_pressure: CHOLMOD cannot allocate the matrix (%d unknowns): %s", n,
		                  status_text(s->c.status));
	int *cp = M->p, *ri = M->i;
	double *val = M->x;
	int k = 0;
	static const int lower[3] = {4, 2, 0};
	for (int j = 0; j < n; ++j) {
		cp[j] = k;
		for (int d = 0; d < 3; ++d) {
			const int q = A->nb[6 * j + lower[d]];
			if (q >= 0) {
				ri[k] = q;
				val[k++] = -flip_off(A, j, lower[d]);
			}
		}
		ri[k] = j;
		val[k++] = A->diag[j];
	}
	cp[n] = k;

	const bool same = s->L && s->n == n && s->nnz == nnz && memcmp(s->colptr, cp, (size_t)(n + 1) * sizeof *cp) == 0 &&
	                  memcmp(s->rowidx, ri, (size_t)nnz * sizeof *ri) == 0;
	if (!same) {
		if (s->L)
			cholmod_free_factor(&s->L, &s->c);
		free(s->colptr);
		free(s->rowidx);
		s->colptr = malloc((size_t)(n + 1) * sizeof *cp);
		s->rowidx = malloc((size_t)nnz * sizeof *ri);
		s->n = 0;
		if (!s->colptr || !s->rowidx) {
			cholmod_free_sparse(&M, &s->c);
			return eddy__fail(w, EDDY_ERR_NOMEM, "flip_pressure: out of memory for the CHOLMOD pattern");
		}
		s->L = cholmod_analyze(M, &s->c);
		if (!s->L || s->c.status != CHOLMOD_OK) {
			const int st = s->c.status;
			cholmod_free_sparse(&M, &s->c);
			if (s->L)
				cholmod_free_factor(&s->L, &s->c);
			return eddy__fail(w, EDDY_ERR_SOLVER, "flip_pressure: CHOLMOD analysis failed (%d unknowns): %s", n,
			                  status_text(st));
		}
		memcpy(s->colptr, cp, (size_t)(n + 1) * sizeof *cp);
		memcpy(s->rowidx, ri, (size_t)nnz * sizeof *ri);
		s->n = n;
		s->nnz = nnz;
		*reanalysed = true;
	}
	const int ok = cholmod_factorize(M, s->L, &s->c);
	cholmod_free_sparse(&M, &s->c);
	if (!ok || s->c.status != CHOLMOD_OK || s->L->minor != (size_t)n) {
		const int st = s->c.status;
		const size_t minor = s->L->minor;
		cholmod_free_factor(&s->L, &s->c); /* a failed factor is not reused */
		s->n = 0;
		return eddy__fail(w, EDDY_ERR_SOLVER, "flip_pressure: CHOLMOD factorisation failed at column %zu of %d: %s",
		                  minor, n, status_text(st));
	}
	cholmod_dense *B = cholmod_allocate_dense((size_t)n, 1, (size_t)n, CHOLMOD_REAL, &s->c);
	if (!B)
		return eddy__fail(w, EDDY_ERR_NOMEM, "flip_pressure: CHOLMOD cannot allocate the right-hand side");
	memcpy(B->x, b, (size_t)n * sizeof *b);
	cholmod_dense *X = cholmod_solve(CHOLMOD_A, s->L, B, &s->c);
	cholmod_free_dense(&B, &s->c);
	if (!X || s->c.status != CHOLMOD_OK) {
		const int st = s->c.status;
		if (X)
			cholmod_free_dense(&X, &s->c);
		return eddy__fail(w, EDDY_ERR_SOLVER, "flip_pressure: CHOLMOD solve failed: %s", status_text(st));
	}
	memcpy(x, X->x, (size_t)n * sizeof *x);
	cholmod_free_dense(&X, &s->c);
	return EDDY_OK;
}
