/* SPDX-License-Identifier: MIT */
/* Multigrid-preconditioned CG for the FLIP pressure system, with HYPRE's
 * PFMG (Ashby & Falgout 1996, "A parallel multigrid preconditioned conjugate
 * gradient algorithm for groundwater flow simulations"; the same structure as
 * McAdams, Sifakis & Teran 2010, "A parallel multigrid Poisson solver for
 * fluids simulation on large grids": CG on the fluid unknowns, one V-cycle as
 * the preconditioner). The only file that includes HYPRE or MPI headers.
 *
 * The CG loop is eddy's own (as flip_pcg.c, with one PFMG V(2,2)-cycle in
 * place of MIC(0)): it stops on the same criterion as the other solvers,
 * max|r| <= tol max|b|, which HYPRE's own PCG (2-norm or preconditioned norm)
 * cannot express. The preconditioner works on HYPRE's Struct interface over
 * the bounding box of the unknowns: a 7-point symmetric stencil with the
 * matrix's weighted links (-w_f), zero links to every cell that is not an
 * unknown, and an identity row for each such cell. Those rows are decoupled
 * (zero in both directions), so the box matrix is symmetric positive definite
 * and its fluid block is exactly A; the right-hand side is zero there, so the
 * V-cycle's output there is ignored. PFMG: semicoarsening, two sweeps of
 * symmetric red-black Gauss-Seidel before and after (red then black before,
 * black then red after: a symmetric preconditioner, as CG needs),
 * non-Galerkin 7-point coarse operators (RAP type 1).
 *
 * Why PFMG on the box and not BoomerAMG on the fluid unknowns (IJ interface),
 * measured on a pool with a wavy free surface (ghost-fluid diagonals with
 * theta down to 0.01) and a drop above it (tests/grid_fixture.h), tolerance
 * 1e-6, HYPRE 2.26 (Debian), one rank: PFMG-PCG took 10, 10, 10 iterations at
 * 32^3, 64^3, 128^3 (16k, 131k, 1.05M unknowns) with V(1,1) cycles;
 * BoomerAMG-PCG (HMIS, ext+i, l1-Jacobi) 8, 10, 12, with a setup alone 5 to 6
 * times the whole PFMG solve (11 s at 128^3). Galerkin coarse operators (RAP
 * type 0) took the same iterations with a 5x costlier setup (27-point coarse
 * stencils); weighted Jacobi 14 iterations and 20% more time; V(2,2) 7
 * iterations at every size and 10-15% less time at 128^3 than V(1,1). The
 * air cells in the box cost one identity row each (about as many again as the
 * unknowns for a half-full tank). Against MIC(0)-PCG on that pool (process
 * CPU time per flip_pressure step, make bench-flip's sweep): 1.3x slower at
 * 32^3 (setup and a V-cycle cost more than 18 MIC(0) iterations save),
 * 1.2x faster at 64^3 (8 iterations against 44), 1.8x at 128^3 (7 against
 * 81); the gap grows with n, as PCG's work grows by about 16 per doubling
 * and this solve's by 8. HYPRE is kept over an own MGPCG because it is as
 * fast from 64^3 up, and the distributed solve will need it.
 *
 * Debian's HYPRE is built without OpenMP: the V-cycle runs on one thread, and
 * so does the CG around it (a few percent of the work; threading it left the
 * idle OpenMP workers spinning through every V-cycle, which cost more CPU and
 * wall time than it saved on a shared machine). The result is therefore the
 * same bit for bit for every thread count; threads come with the distributed
 * solve (MPI ranks) or a HYPRE built with OpenMP.
 * MPI: HYPRE needs MPI_COMM_WORLD. If the host has not initialised MPI, the
 * first solve does (MPI_Init_thread, serialized: one solve at a time talks
 * to HYPRE) and finalises it at exit (glibc runs a shared library's atexit
 * handlers when it is unloaded, so also then). MPI cannot be initialised
 * twice in a process: after a finalisation, by the host or by an unloaded
 * copy of eddy, a HYPRE solve is an error, not an abort. One rank: the
 * distributed solve is a later issue, and every call here takes the
 * communicator so it can grow into it.
 *
 * Loading: libHYPRE and libmpi are opened (dlopen) by the first HYPRE solve,
 * not linked. Linked, they came with some 40 more shared libraries into every
 * process that uses eddy (start-up 90 ms against 30), and libsuperlu_dist,
 * which HYPRE needs, sets mallopt(M_MMAP_MAX, 0) when it loads: from then on
 * malloc never returns a large block to the system, in the host's program
 * too. Only the headers are needed to build; the libraries' sonames come
 * from the build (EDDY_HYPRE_SONAME, EDDY_MPI_SONAME in the Makefile). libmpi
 * is opened first and RTLD_GLOBAL, as Open MPI's plugins resolve its symbols
 * from the global scope. Neither is ever closed (MPI cannot start twice). */
#include "flip.h"

#include <dlfcn.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <mpi.h>
#include <HYPRE.h>
#include <HYPRE_struct_ls.h>

/* Under LeakSanitizer (make asan), what MPI allocates while it starts and
 * stops is its process-wide state, not eddy's leaks: much of it is made in
 * plugins Open MPI unloads again, where no suppression can name it. */
#if defined(__SANITIZE_ADDRESS__)
#define EDDY_LSAN 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define EDDY_LSAN 1
#endif
#endif
#ifdef EDDY_LSAN
#include <sanitizer/lsan_interface.h>
#define LSAN_OFF() __lsan_disable()
#define LSAN_ON() __lsan_enable()
#else
#define LSAN_OFF() ((void)0)
#define LSAN_ON() ((void)0)
#endif

#ifndef EDDY_HYPRE_SONAME
#define EDDY_HYPRE_SONAME "libHYPRE.so"
#endif
#ifndef EDDY_MPI_SONAME
#define EDDY_MPI_SONAME "libmpi.so"
#endif

/* The functions used here, looked up in the opened libraries; each field has
 * the type of the header's declaration of its name. */
#define EDDY_MPI_FUNCS(X) \
	X(MPI_Initialized) X(MPI_Finalized) X(MPI_Init_thread) X(MPI_Finalize) X(MPI_Comm_set_errhandler)
#define EDDY_HYPRE_FUNCS(X)                \
	X(HYPRE_Init)                          \
	X(HYPRE_Finalize)                      \
	X(HYPRE_ClearAllErrors)                \
	X(HYPRE_StructGridCreate)              \
	X(HYPRE_StructGridSetExtents)          \
	X(HYPRE_StructGridAssemble)            \
	X(HYPRE_StructGridDestroy)             \
	X(HYPRE_StructStencilCreate)           \
	X(HYPRE_StructStencilSetElement)       \
	X(HYPRE_StructStencilDestroy)          \
	X(HYPRE_StructMatrixCreate)            \
	X(HYPRE_StructMatrixSetSymmetric)      \
	X(HYPRE_StructMatrixInitialize)        \
	X(HYPRE_StructMatrixSetBoxValues)      \
	X(HYPRE_StructMatrixAssemble)          \
	X(HYPRE_StructMatrixDestroy)           \
	X(HYPRE_StructVectorCreate)            \
	X(HYPRE_StructVectorInitialize)        \
	X(HYPRE_StructVectorSetConstantValues) \
	X(HYPRE_StructVectorSetBoxValues)      \
	X(HYPRE_StructVectorGetBoxValues)      \
	X(HYPRE_StructVectorAssemble)          \
	X(HYPRE_StructVectorDestroy)           \
	X(HYPRE_StructPFMGCreate)              \
	X(HYPRE_StructPFMGSetMaxIter)          \
	X(HYPRE_StructPFMGSetTol)              \
	X(HYPRE_StructPFMGSetZeroGuess)        \
	X(HYPRE_StructPFMGSetRelaxType)        \
	X(HYPRE_StructPFMGSetRAPType)          \
	X(HYPRE_StructPFMGSetNumPreRelax)      \
	X(HYPRE_StructPFMGSetNumPostRelax)     \
	X(HYPRE_StructPFMGSetSkipRelax)        \
	X(HYPRE_StructPFMGSetLogging)          \
	X(HYPRE_StructPFMGSetup)               \
	X(HYPRE_StructPFMGSolve)               \
	X(HYPRE_StructPFMGDestroy)
#define EDDY_FIELD(name) __typeof__(&name) name;
typedef struct hypre_lib {
	EDDY_MPI_FUNCS(EDDY_FIELD)
	EDDY_HYPRE_FUNCS(EDDY_FIELD)
	MPI_Comm comm_world;
	MPI_Errhandler errors_return;
} hypre_lib;
#undef EDDY_FIELD

/* MPI and HYPRE are process-wide libraries: initialising them is the one
 * process-wide step, done once whichever world asks first; HYPRE keeps a
 * process-wide error flag, so solves from worlds on different threads take
 * turns (MPI_THREAD_SERIALIZED). */
static pthread_once_t init_once = PTHREAD_ONCE_INIT;
static const char *init_error; /* set once inside init_once, read after it */
static char init_message[512]; /* init_error's text when it names a library */
static hypre_lib lib;          /* set once inside init_once, read after it */
static pthread_mutex_t solve_lock = PTHREAD_MUTEX_INITIALIZER;

static void finalize_mpi(void)
{
	int finalised = 0;
	lib.MPI_Finalized(&finalised);
	if (!finalised) {
		LSAN_OFF();
		lib.HYPRE_Finalize();
		lib.MPI_Finalize();
		LSAN_ON();
	}
}

/* Opens a library and looks up its functions; false with init_error set. */
static bool open_library(const char *soname, int mode, void **handle)
{
	*handle = dlopen(soname, mode);
	if (!*handle) {
		const char *why = dlerror();
		snprintf(init_message, sizeof init_message,
		         "cannot load %s (%s); Debian's libhypre-dev and libopenmpi-dev provide it", soname,
		         why ? why : "not found");
		init_error = init_message;
	}
	return *handle != NULL;
}

static bool find_symbol(void *handle, const char *soname, const char *name, void **at)
{
	dlerror();
	*at = dlsym(handle, name);
	if (!*at) {
		snprintf(init_message, sizeof init_message, "%s has no symbol %s", soname, name);
		init_error = init_message;
	}
	return *at != NULL;
}

static bool load_libraries(void)
{
	void *mpi = NULL, *hypre = NULL;
	LSAN_OFF();
	const bool opened = open_library(EDDY_MPI_SONAME, RTLD_NOW | RTLD_GLOBAL, &mpi) &&
	                    open_library(EDDY_HYPRE_SONAME, RTLD_NOW, &hypre);
	LSAN_ON();
	if (!opened)
		return false;
	/* a data pointer to a function pointer through memcpy: ISO C has no cast between them */
	void *at = NULL;
#define EDDY_FIND(lib_handle, soname, name)           \
	if (!find_symbol(lib_handle, soname, #name, &at)) \
		return false;                                 \
	memcpy(&lib.name, &at, sizeof lib.name);
#define EDDY_FIND_MPI(name) EDDY_FIND(mpi, EDDY_MPI_SONAME, name)
#define EDDY_FIND_HYPRE(name) EDDY_FIND(hypre, EDDY_HYPRE_SONAME, name)
	EDDY_MPI_FUNCS(EDDY_FIND_MPI)
	EDDY_HYPRE_FUNCS(EDDY_FIND_HYPRE)
#undef EDDY_FIND_HYPRE
#undef EDDY_FIND_MPI
#undef EDDY_FIND
#ifdef OPEN_MPI
	/* Open MPI's predefined handles are the addresses of its globals */
	if (!find_symbol(mpi, EDDY_MPI_SONAME, "ompi_mpi_comm_world", &at))
		return false;
	lib.comm_world = (MPI_Comm)at;
	if (!find_symbol(mpi, EDDY_MPI_SONAME, "ompi_mpi_errors_return", &at))
		return false;
	lib.errors_return = (MPI_Errhandler)at;
#else
	lib.comm_world = MPI_COMM_WORLD;
	lib.errors_return = MPI_ERRORS_RETURN;
#endif
	return true;
}

static void init_libraries(void)
{
	if (!load_libraries())
		return;
	int initialised = 0, finalised = 0;
	lib.MPI_Finalized(&finalised);
	if (finalised) {
		init_error = "MPI was finalised by the host before the first HYPRE solve";
		return;
	}
	lib.MPI_Initialized(&initialised);
	if (!initialised) {
		int provided = 0;
		LSAN_OFF();
		const int st = lib.MPI_Init_thread(NULL, NULL, MPI_THREAD_SERIALIZED, &provided);
		LSAN_ON();
		if (st != MPI_SUCCESS) {
			init_error = "MPI_Init_thread failed";
			return;
		}
		/* ours: report MPI errors as codes rather than aborting the host,
		 * and finalise at exit (or when this library is unloaded), as
		 * mpirun expects of every rank */
		lib.MPI_Comm_set_errhandler(lib.comm_world, lib.errors_return);
		atexit(finalize_mpi);
	}
	LSAN_OFF();
	if (lib.HYPRE_Init() != 0)
		init_error = "HYPRE_Init failed";
	LSAN_ON();
}

static double dot(const double *a, const double *b, int n)
{
	double s = 0;
	for (int i = 0; i < n; ++i)
		s += a[i] * b[i];
	return s;
}

static double maxabs(const double *a, int n)
{
	double m = 0;
	for (int i = 0; i < n; ++i)
		m = fabs(a[i]) > m ? fabs(a[i]) : m;
	return m;
}

static void matvec(const flip_matrix *A, const double *s, double *q)
{
	for (int i = 0; i < A->n; ++i) {
		const int *nb = &A->nb[6 * i];
		double t = A->diag[i] * s[i];
		for (int d = 0; d < 6; ++d)
			if (nb[d] >= 0)
				t -= flip_off(A, i, d) * s[nb[d]];
		q[i] = t;
	}
}

/* The HYPRE objects of one solve. */
typedef struct hyp {
	HYPRE_StructGrid grid;
	HYPRE_StructStencil stencil;
	HYPRE_StructMatrix mat;
	HYPRE_StructVector rv, zv;
	HYPRE_StructSolver pfmg;
	int lo[3], hi[3];
} hyp;

static void hyp_free(hyp *H)
{
	if (H->pfmg)
		lib.HYPRE_StructPFMGDestroy(H->pfmg);
	if (H->rv)
		lib.HYPRE_StructVectorDestroy(H->rv);
	if (H->zv)
		lib.HYPRE_StructVectorDestroy(H->zv);
	if (H->mat)
		lib.HYPRE_StructMatrixDestroy(H->mat);
	if (H->stencil)
		lib.HYPRE_StructStencilDestroy(H->stencil);
	if (H->grid)
		lib.HYPRE_StructGridDestroy(H->grid);
	lib.HYPRE_ClearAllErrors();
}

/* z = one PFMG V-cycle applied to r (box-ordered arrays rb, zb; rb is zero
 * off the unknowns, where only the caller's first clearing writes). */
static bool precondition(hyp *H, const double *r, double *z, const int *bidx, int n, double *rb, double *zb)
{
	for (int i = 0; i < n; ++i)
		rb[bidx[i]] = r[i];
	int e = lib.HYPRE_StructVectorSetBoxValues(H->rv, H->lo, H->hi, rb);
	e |= lib.HYPRE_StructVectorSetConstantValues(H->zv, 0.0);
	e |= lib.HYPRE_StructPFMGSolve(H->pfmg, H->mat, H->rv, H->zv);
	e |= lib.HYPRE_StructVectorGetBoxValues(H->zv, H->lo, H->hi, zb);
	for (int i = 0; i < n; ++i)
		z[i] = zb[bidx[i]];
	return e == 0;
}

static eddy_status solve(eddy_world *w, const flip_matrix *A, const int *cell_of, const double *b, double *x,
                         double tol, int max_it, int *it, double *res, bool *converged)
{
	const int n = A->n;
	memset(x, 0, (size_t)n * sizeof *x);
	*it = 0;
	*res = 0;
	*converged = true;
	const double bmax = maxabs(b, n);
	if (n == 0 || bmax == 0)
		return EDDY_OK;
	/* the bounding box of the unknowns, and each row's place in it */
	const int nx = w->nx, ny = w->ny;
	int lo[3] = {w->nx, w->ny, w->nz}, hi[3] = {-1, -1, -1};
	for (int r = 0; r < n; ++r) {
		const int c = cell_of[r];
		const int p[3] = {c % nx, (c / nx) % ny, c / (nx * ny)};
		for (int a = 0; a < 3; ++a) {
			lo[a] = p[a] < lo[a] ? p[a] : lo[a];
			hi[a] = p[a] > hi[a] ? p[a] : hi[a];
		}
	}
	const int bx = hi[0] - lo[0] + 1, by = hi[1] - lo[1] + 1, bz = hi[2] - lo[2] + 1;
	const size_t nbox = (size_t)bx * (size_t)by * (size_t)bz;
	double *vals = eddy__arena_alloc(&w->arena, 4 * nbox * sizeof *vals + 8);
	double *rb = eddy__arena_alloc(&w->arena, nbox * sizeof *rb + 8);
	double *zb = eddy__arena_alloc(&w->arena, nbox * sizeof *zb + 8);
	int *bidx = eddy__arena_alloc(&w->arena, (size_t)n * sizeof *bidx + 8);
	double *mem = eddy__arena_alloc(&w->arena, 4 * (size_t)n * sizeof *mem + 8);
	if (!vals || !rb || !zb || !bidx || !mem)
		return eddy__fail(w, EDDY_ERR_NOMEM, "flip_pressure: out of memory for the HYPRE box (%zu cells)", nbox);
	double *r = mem, *z = mem + n, *s = mem + 2 * (size_t)n, *y = mem + 3 * (size_t)n;

	/* box matrix, symmetric storage: centre, -x, -y, -z; identity rows off the unknowns */
	for (size_t q = 0; q < nbox; ++q) {
		vals[4 * q] = 1;
		vals[4 * q + 1] = vals[4 * q + 2] = vals[4 * q + 3] = 0;
	}
	for (int rr = 0; rr < n; ++rr) {
		const int c = cell_of[rr];
		const int i = c % nx - lo[0], j = (c / nx) % ny - lo[1], k = c / (nx * ny) - lo[2];
		const size_t q = (size_t)i + (size_t)bx * ((size_t)j + (size_t)by * (size_t)k);
		bidx[rr] = (int)q;
		const int *nb = &A->nb[6 * rr];
		vals[4 * q] = A->diag[rr];
		vals[4 * q + 1] = nb[0] >= 0 ? -flip_off(A, rr, 0) : 0.0;
		vals[4 * q + 2] = nb[2] >= 0 ? -flip_off(A, rr, 2) : 0.0;
		vals[4 * q + 3] = nb[4] >= 0 ? -flip_off(A, rr, 4) : 0.0;
	}

	hyp H;
	memset(&H, 0, sizeof H);
	for (int a = 0; a < 3; ++a) {
		H.lo[a] = lo[a];
		H.hi[a] = hi[a];
	}
	int offsets[4][3] = {{0, 0, 0}, {-1, 0, 0}, {0, -1, 0}, {0, 0, -1}};
	int entries[4] = {0, 1, 2, 3};
	int e = lib.HYPRE_StructGridCreate(lib.comm_world, 3, &H.grid);
	e |= lib.HYPRE_StructGridSetExtents(H.grid, H.lo, H.hi);
	e |= lib.HYPRE_StructGridAssemble(H.grid);
	e |= lib.HYPRE_StructStencilCreate(3, 4, &H.stencil);
	for (int k = 0; k < 4; ++k)
		e |= lib.HYPRE_StructStencilSetElement(H.stencil, k, offsets[k]);
	e |= lib.HYPRE_StructMatrixCreate(lib.comm_world, H.grid, H.stencil, &H.mat);
	e |= lib.HYPRE_StructMatrixSetSymmetric(H.mat, 1);
	e |= lib.HYPRE_StructMatrixInitialize(H.mat);
	e |= lib.HYPRE_StructMatrixSetBoxValues(H.mat, H.lo, H.hi, 4, entries, vals);
	e |= lib.HYPRE_StructMatrixAssemble(H.mat);
	e |= lib.HYPRE_StructVectorCreate(lib.comm_world, H.grid, &H.rv);
	e |= lib.HYPRE_StructVectorCreate(lib.comm_world, H.grid, &H.zv);
	e |= lib.HYPRE_StructVectorInitialize(H.rv);
	e |= lib.HYPRE_StructVectorInitialize(H.zv);
	e |= lib.HYPRE_StructVectorSetConstantValues(H.rv, 0.0);
	e |= lib.HYPRE_StructVectorSetConstantValues(H.zv, 0.0);
	e |= lib.HYPRE_StructVectorAssemble(H.rv);
	e |= lib.HYPRE_StructVectorAssemble(H.zv);
	e |= lib.HYPRE_StructPFMGCreate(lib.comm_world, &H.pfmg);
	e |= lib.HYPRE_StructPFMGSetMaxIter(H.pfmg, 1);
	e |= lib.HYPRE_StructPFMGSetTol(H.pfmg, 0.0);
	e |= lib.HYPRE_StructPFMGSetZeroGuess(H.pfmg);
	e |= lib.HYPRE_StructPFMGSetRelaxType(H.pfmg, 2); /* symmetric red-black Gauss-Seidel */
	e |= lib.HYPRE_StructPFMGSetRAPType(H.pfmg, 1);   /* non-Galerkin 7-point coarse operators */
	e |= lib.HYPRE_StructPFMGSetNumPreRelax(H.pfmg, 2);
	e |= lib.HYPRE_StructPFMGSetNumPostRelax(H.pfmg, 2);
	e |= lib.HYPRE_StructPFMGSetSkipRelax(H.pfmg, 1);
	e |= lib.HYPRE_StructPFMGSetLogging(H.pfmg, 0);
	e |= lib.HYPRE_StructPFMGSetup(H.pfmg, H.mat, H.rv, H.zv);
	if (e) {
		hyp_free(&H);
		return eddy__fail(w, EDDY_ERR_SOLVER,
		                  "flip_pressure: HYPRE PFMG setup failed (error %d, %d unknowns, box %dx%dx%d)", e, n, bx, by,
		                  bz);
	}

	/* CG, as flip_pcg.c */
	memcpy(r, b, (size_t)n * sizeof *r);
	memset(rb, 0, nbox * sizeof *rb);
	bool ok = precondition(&H, r, z, bidx, n, rb, zb);
	memcpy(s, z, (size_t)n * sizeof *s);
	double rho = dot(r, z, n);
	*converged = false;
	for (int k = 1; k <= max_it && ok; ++k) {
		matvec(A, s, y);
		const double sq = dot(s, y, n);
		*it = k;
		if (!(sq > 0)) { /* breakdown: A is not positive definite on s */
			*res = maxabs(r, n) / bmax;
			break;
		}
		const double alpha = rho / sq;
		for (int i = 0; i < n; ++i) {
			x[i] += alpha * s[i];
			r[i] -= alpha * y[i];
		}
		*res = maxabs(r, n) / bmax;
		if (*res <= tol) {
			*converged = true;
			break;
		}
		ok = precondition(&H, r, z, bidx, n, rb, zb);
		const double rho_new = dot(r, z, n);
		const double beta = rho_new / rho;
		rho = rho_new;
		for (int i = 0; i < n; ++i)
			s[i] = z[i] + beta * s[i];
	}
	hyp_free(&H);
	if (!ok)
		return eddy__fail(w, EDDY_ERR_SOLVER, "flip_pressure: HYPRE PFMG V-cycle failed (%d unknowns)", n);
	return EDDY_OK;
}

eddy_status eddy__flip_hypre_solve(eddy_world *w, const flip_matrix *A, const int *cell_of, const double *b, double *x,
                                   double tol, int max_it, int *it, double *res, bool *converged)
{
	pthread_once(&init_once, init_libraries);
	if (init_error) {
		memset(x, 0, (size_t)A->n * sizeof *x);
		*it = 0;
		*res = 0;
		*converged = false;
		return eddy__fail(w, EDDY_ERR_SOLVER, "flip_pressure: HYPRE unavailable: %s", init_error);
	}
	pthread_mutex_lock(&solve_lock);
	const eddy_status st = solve(w, A, cell_of, b, x, tol, max_it, it, res, converged);
	pthread_mutex_unlock(&solve_lock);
	return st;
}
