/* SPDX-License-Identifier: MIT */
/* flip_pressure: pressure projection with a ghost-fluid free surface and
 * fractional solid faces (Zhu & Bridson 2005; Enright, Nguyen, Gibou & Fedkiw
 * 2003 for the ghost-fluid boundary; Batty, Bertails & Bridson 2007, "A fast
 * variational framework for accurate solid-fluid coupling", for the solid
 * faces; Bridson's book, ch. 5).
 *
 * Reads: cell_type flip_phi u v w x y z. Writes: u v w cell_pressure.
 * Unknown q = p dt / (rho dx) per fluid cell; w_f the open fraction of face f
 * and V_f the normal velocity of the solid covering it (flip.h, recomputed
 * from the colliders as flip_boundary did); D_i = sum over the faces of i of
 * +-(w_f u_f + (1 - w_f) V_f), the net outflow of fluid and solid together.
 *   (A q)_i = sum over the 6 sides of i:  unknown j: w_f (q_i - q_j)
 *                                         air j:     w_f q_i / theta_ij
 *                                         open domain side:  w_f q_i (air at theta 1)
 *                                         solid / closed domain side: nothing
 *   A q = -D + dx s_i   (s_i: the volume correction below, 0 elsewhere)
 *   u_f -= q_right - q_left on every open face (w_f > 0) with an unknown on
 *   a side, an air side taking the ghost value q_i (1 - 1/theta_ij), so the
 *   face sees exactly the theta the matrix used and the update zeroes the
 *   weighted divergence; closed faces keep the solid's velocity.
 *   theta_ij = phi_i / (phi_i - phi_j), the linear zero crossing of the
 *   smoothed marker between the cell centres, clamped to [theta_min, 1].
 * Unknowns: fluid cells, and cells a solid cuts that have an open face to a
 * fluid cell and none to an uncut air cell (liquid up to the solid, not
 * surface): the pressure lives in every cell holding fluid, so a moving
 * solid's cells do not jump in and out of the system (binary cells lost 6-44%
 * of the water around a moving sphere). A solid-typed cell out of the system
 * (all solid, or cut and on the free surface) is no unknown: its face to an
 * unknown is a given flux w_f u_f + (1 - w_f) V_f, the water's own through
 * the open part, and keeps u_f. Made a wall (w_f = 0, u_f = V_f) it blocked
 * the cut row along a floor whose top lies in a cell's upper half at both
 * ends of the water, and the pressure braked that row: a layer gliding at
 * 1.5 m/s over such a floor slowed to 0.35 m/s in 0.3 s.
 * Volume correction (after Losasso, Talton, Kwatra & Fedkiw 2008, "Two-way
 * coupled SPH and particle level set fluid simulation", and Kugelstadt et al.
 * 2019, "Implicit density projection for volume conserving liquids", which
 * both drive the particle density back to rest through the pressure solve):
 * FLIP's particles are its volume (flip_p2g's marker counts dx^3 / n0 per
 * particle, n0 = flip_rest_count), but a discretely divergence-free grid
 * velocity does not keep them evenly spread: advection and the colliders'
 * projection pack them in places and thin them in others. With rho_i the
 * trilinear particle count at the centre of fluid cell i (not cut by a
 * solid), e_i = rho_i / n0 - 1 adds the source
 *   s_i = VC_RATE clamp(e_i, -VC_CLAMP, VC_CLAMP) / T,
 *   T = max(dt, cfl dx / (|v|max + sqrt(|g| dx)))
 * where e_i > 0 in any such cell (a partly filled cell cannot be above rest
 * density, so an excess is packing wherever it is), and where e_i < 0 only in
 * deep cells: neither the cell nor a face neighbour has an air side, and all
 * 27 cells of the kernel's reach hold a particle (cells beyond the domain's
 * side do not count: the density extends constantly there; nor do the box's
 * cut cells below). Near the
 * surface a low count is a partly filled cell, not a thinned one; a cell
 * marked fluid without particles (mark_radius) or a blob's edge is not
 * liquid at rest density either. Cells a solid cuts, and cells with a face
 * to a cut or solid-typed cell, get no source either way: their open part is
 * known to a cell only and the kernel reaches into the solid. The world's
 * box cutting the grid's last cells (flip_grid's top) is the exception: there
 * the count of water at rest is known exactly (flip_box_rest), and e_i is
 * taken against it in the cut cells (a quarter cell open or more) and in
 * the cells beside them; left out, the water packed there (a collapse in a
 * tank 7.5 cells thick lost 5.7% of its marker volume). A cut cell
 * expects a few particles (2.25 in a quarter cell), so one holding none is
 * sampling, not the liquid's edge, and does not keep its neighbours from
 * being deep: held to hold one, a quarter cell that emptied stayed empty and
 * its neighbours' deficits went uncorrected (a collapse in a tank 7.25 cells
 * thick settled 4.1% high). A packed cell
 * expands and a thinned one contracts by their whole error per step
 * (VC_RATE 1, the implicit density projection's target), moving particles
 * rather than creating or deleting them, so with flip_reseed relocating
 * instead of deleting (sys_flip_reseed.c) the particle count, and with it the
 * volume, is conserved. The clamp keeps a splash or a pile-up from turning
 * into a burst of velocity. T: removing an error e in one step moves the
 * particles at about e dx / dt, a fixed fraction of the flow's speed while
 * dt is flip_advect's CFL step, but more wherever dt is held below it (by
 * the frame, dt_max or another system's limit): the 20 m dam break (cells 2
 * m, its 5 ms frames one step each, its CFL step some 70 ms) reached 101
 * m/s against its 28 m/s fall and gained 54% energy, the 100 m one 1,120
 * m/s and 10x (0.1 m: none). So the error is removed over the step the
 * flow's own CFL limit allows (the same as flip_advect's limit, with the
 * world's cfl), dt where that binds: 20 m 28.9 m/s, 100 m 59.0 m/s, no
 * energy gained (tests/test_flip.c). Without gravity and at rest T is
 * infinite: nothing is corrected (nothing packs).
 * A fluid component with no air side (closed box, sealed pocket, one walled-in
 * cell) makes A singular: its right-hand side is made zero-mean and its first
 * cell pinned (q = 0, links to it dropped), which solves the singular system
 * exactly because its rows sum to zero.
 * Walls do not pull where air can follow the water (after Chentanez &
 * Mueller 2011, "A multigrid fluid pressure solver handling separating
 * solid boundary conditions", here as one active-set round): after the
 * solve, a cell with q < 0 (suction) beside a wall (a domain side, a face
 * a solid closes or cuts, a solid cell) whose side leads to air outside the
 * surface (phi > 0) or to a cell already let go is let go: q = 0 there (its
 * row an identity, as a pinned row) and the rest solved again for the
 * correction, in SEPARATE_ROUNDS rounds a step (a cell let go early in a
 * round's sweep opens its neighbours later in it: a lid's row of cells goes
 * in one); then its wall faces
 * that the water leaves take the velocity of the cell's opposite face, so
 * that flip_g2p, interpolating towards the wall, does not hold the particles
 * beside it (flip_extrapolate does the same for the walls of air cells).
 * Before, a block of water released under a lid fell at 0.79 of free fall
 * over 0.1 s, one leaving a lid in zero gravity kept 0.67 of its speed and
 * a dam break's splash hung from its tank's lid (tests/test_flip.c). Water held
 * by suction without air in reach (a closed box, a hole the particles left
 * inside the liquid) keeps its tension, as water does. Such a cell's
 * divergence (the gap opening at the wall) is left out of the published
 * divergence; "released" counts the cells let go in the step, and
 * "iterations" counts the rounds' solves too.
 * Solvers: MIC(0)-PCG (flip_pcg.c), CG with a HYPRE PFMG multigrid
 * preconditioner (flip_hypre.c, iterations flat in grid size) or supernodal
 * CHOLMOD (flip_cholmod.c), or CG with eddy's own threaded geometric
 * multigrid preconditioner (flip_mg.c, McAdams et al. 2010), all with the
 * weighted off-diagonals -w_f.
 * Every solve is checked: a non-converged PCG, HYPRE or MG solve, a CHOLMOD
 * status other than OK or a relative residual max|b - A q| / max|b| above
 * tolerance (CHOLMOD: 1e-8) is an error and the velocities are left as they
 * were.
 * Published: solver, iterations, residual, divergence = max_i |D_i| dt / dx
 * after projection, volume = dx^3 sum clamp((1 - phi) / 2, 0, 1) open_i (m^3;
 * open_i the cell's open volume fraction), density_error_max/min (the largest
 * and smallest rho_i / n0 - 1 over the corrected cells). */
#include "flip.h"

#include <stdlib.h>
#include <string.h>

/* volume correction: fraction of the density error removed per step, and the
 * largest error acted on (beyond it a cell is a splash or a pile-up the source
 * should not turn into a burst of velocity) */
#define VC_RATE 1.0
#define VC_CLAMP 0.5
/* outside the deep liquid only an excess above this counts as packing: a
 * cell's sampling noise (8 particles under the tent kernel) is about +-0.1,
 * and expanding the positive half of it with no contraction of the negative
 * half would inflate a shallow layer */
#define VC_PACKED 0.2
/* the least open part of a cell the box's cut leaves that the correction
 * takes: a slice under it holds a particle or two */
#define VC_CUT_MIN 0.25f
/* rounds of letting go of walls in a step (header), each a solve more: the
 * FLIP pour took 1.07x the CPU time with one, 1.14x with three (medians of
 * 7 pairs), and every lid and shelf case let go in the first */
#define SEPARATE_ROUNDS 1

typedef struct pressure {
	eddy_flip_pressure_def def;
	flip_cholmod *chol;
	flip_mg *mg;
	int64_t analyses; /* CHOLMOD symbolic analyses so far */
} pressure;

static const int pressure_reads[] = {COL_CELL_TYPE, COL_FLIP_PHI, COL_FACE_U, COL_FACE_V, COL_FACE_W,
                                     COL_X_,        COL_Y_,       COL_Z_,     -1};
static const int pressure_writes[] = {COL_FACE_U, COL_FACE_V, COL_FACE_W, COL_CELL_PRESSURE, -1};

eddy_flip_pressure_def eddy_default_flip_pressure_def(void)
{
	eddy_flip_pressure_def d;
	d.solver = EDDY_FLIP_PCG;
	d.density = 1000.0f;
	d.tolerance = 1e-6;
	d.max_iterations = 1000;
	d.theta_min = 0.01f;
	return d;
}

/* per eddy_flip_solver: the published name and the one in messages */
static const char *const solver_name[] = {"pcg", "cholmod", "hypre", "mg"};
static const char *const solver_label[] = {"PCG", "CHOLMOD", "HYPRE PFMG-PCG", "MG-PCG"};

/* Fraction of the way from fluid centre i to air centre j where phi = 0. */
static double theta(float pi, float pj, double tmin)
{
	double t;
	if (pj <= 0)
		t = 1; /* the blurred field says fluid up to j: surface at j */
	else if (pi >= 0)
		t = tmin; /* a thin sheet blurred positive: surface at i */
	else
		t = (double)pi / ((double)pi - (double)pj);
	return t < tmin ? tmin : t > 1 ? 1 : t;
}

typedef struct grid_ctx {
	int nx, ny, nz;
	const uint8_t *type;
	const float *phi;
	const float *face[3];
	const int *row; /* cell -> row or -1 */
} grid_ctx;

/* Cell across side d (0 -x, 1 +x, 2 -y, 3 +y, 4 -z, 5 +z) of (i, j, k), or -1
 * beyond the domain; the face between them in *f (index in face grid d/2). */
static long across(const eddy_world *w, int i, int j, int k, int d, size_t *f)
{
	const int a = d >> 1, plus = d & 1;
	int c[3] = {i, j, k};
	const int n[3] = {w->nx, w->ny, w->nz};
	int fc[3] = {i, j, k};
	fc[a] += plus;
	*f = a == 0   ? flip_fu(w, fc[0], fc[1], fc[2])
	     : a == 1 ? flip_fv(w, fc[0], fc[1], fc[2])
	              : flip_fw(w, fc[0], fc[1], fc[2]);
	c[a] += plus ? 1 : -1;
	if (c[a] < 0 || c[a] >= n[a])
		return -1;
	return (long)flip_cell(w, c[0], c[1], c[2]);
}

/* Cell c has a side on a wall (the domain's side, a face the solid closes
 * or partly covers, or a solid cell out of the system) and air can reach
 * it: a side on air outside the liquid's surface (phi > 0: not a hole the
 * particles left inside the liquid, which the blurred marker calls liquid)
 * or on a cell already let go of its walls. */
static bool at_wall(const eddy_world *w, const flip_solid *sd, const uint8_t *type, const float *phi, const int *row,
                    const uint8_t *free_row, size_t c)
{
	bool air = false;
	const int nx = w->nx, ny = w->ny;
	const int i = (int)(c % (size_t)nx), j = (int)(c / (size_t)nx % (size_t)ny), k = (int)(c / ((size_t)nx * ny));
	bool wall = false;
	for (int d = 0; d < 6; ++d) {
		size_t f;
		const long o = across(w, i, j, k, d, &f);
		const int ax = d >> 1;
		int fc[3] = {i, j, k};
		fc[ax] += d & 1;
		if (o < 0) { /* a domain side: a wall, or air where open and uncovered */
			const float wf = flip_face_weight(w, sd, ax, f, fc[0], fc[1], fc[2]);
			wall = wall || wf < 1;
			air = air || wf > 0;
			continue;
		}
		wall = wall || flip_face_weight(w, sd, ax, f, fc[0], fc[1], fc[2]) < 1 ||
		       (row[o] < 0 && type[o] == EDDY_CELL_SOLID);
		air = air || (row[o] >= 0 && free_row[row[o]]) || (row[o] < 0 && type[o] == EDDY_CELL_AIR && phi[o] > 0);
	}
	return wall && air;
}

/* (b - A q)_r */
static inline double row_residual(const flip_matrix *A, const double *b, const double *q, int r)
{
	const int *nb = &A->nb[6 * r];
	double t = b[r] - A->diag[r] * q[r];
	for (int d = 0; d < 6; ++d)
		if (nb[d] >= 0)
			t += flip_off(A, r, d) * q[nb[d]];
	return t;
}

/* A q = b to max|r| <= tol max|b| by the chosen solver (*iterations,
 * *residual: its own account; the caller measures the residual). */
static eddy_status solve_system(eddy_world *w, pressure *ps, const eddy_step_context *ctx, const flip_matrix *pA,
                                const int *cell_of, const double *b, double *q, double tol, int *iterations_out,
                                double *residual_out)
{
	const flip_matrix A = *pA;
	const int n = A.n;
	int iterations = 0;
	double residual = 0;
	if (ps->def.solver == EDDY_FLIP_PCG) {
		const bool ok = eddy__flip_pcg(w, &A, cell_of, b, q, tol, ps->def.max_iterations, &iterations, &residual);
		if (!ok)
			return eddy__fail(w, EDDY_ERR_SOLVER,
			                  "flip_pressure: PCG did not converge: relative residual %.3g after %d iterations "
			                  "(tolerance %.3g, %d unknowns); raise max_iterations or use solver = \"cholmod\"",
			                  residual, iterations, tol, n);
	} else if (ps->def.solver == EDDY_FLIP_HYPRE) {
		bool converged = false;
		const eddy_status st = eddy__flip_hypre_solve(w, &A, cell_of, b, q, tol, ps->def.max_iterations, &iterations,
		                                              &residual, &converged);
		if (st != EDDY_OK)
			return st;
		if (!converged)
			return eddy__fail(
				w, EDDY_ERR_SOLVER,
				"flip_pressure: HYPRE PFMG-PCG did not converge at step %lld: relative residual %.3g after "
				"%d iterations (tolerance %.3g, %d unknowns); raise max_iterations or use solver = "
				"\"cholmod\"",
				(long long)ctx->step, residual, iterations, tol, n);
	} else if (ps->def.solver == EDDY_FLIP_MG) {
		/* created at the first solve, as CHOLMOD below */
		if (!ps->mg && !(ps->mg = eddy__flip_mg_new()))
			return eddy__fail(w, EDDY_ERR_NOMEM, "flip_pressure: out of memory");
		bool converged = false;
		const eddy_status st = eddy__flip_mg_solve(w, ps->mg, &A, cell_of, b, q, tol, ps->def.max_iterations,
		                                           &iterations, &residual, &converged);
		if (st != EDDY_OK)
			return st;
		if (!converged)
			return eddy__fail(w, EDDY_ERR_SOLVER,
			                  "flip_pressure: MG-PCG did not converge at step %lld: relative residual %.3g after %d "
			                  "iterations (tolerance %.3g, %d unknowns); raise max_iterations or use solver = "
			                  "\"cholmod\"",
			                  (long long)ctx->step, residual, iterations, tol, n);
	} else {
		/* created at the first solve, not in add: a failed add frees the
		 * system's data without its destroy hook */
		if (!ps->chol && !(ps->chol = eddy__flip_cholmod_new()))
			return eddy__fail(w, EDDY_ERR_NOMEM, "flip_pressure: CHOLMOD could not start");
		bool re = false;
		eddy_status st = eddy__flip_cholmod_solve(w, ps->chol, &A, b, q, &re);
		if (st != EDDY_OK)
			return st;
		ps->analyses += re;
		iterations = 1;
	}
	*iterations_out = iterations;
	*residual_out = residual;
	return EDDY_OK;
}

static eddy_status step_body(eddy_world *w, eddy_system *s, const eddy_step_context *ctx)
{
	pressure *ps = s->data;
	const int nx = w->nx, ny = w->ny, nz = w->nz;
	const size_t nc = (size_t)nx * ny * nz;
	const uint8_t *type = (const uint8_t *)w->columns[COL_CELL_TYPE].data;
	const float *phi = eddy__col(w, COL_FLIP_PHI);
	float *face[3] = {eddy__col(w, COL_FACE_U), eddy__col(w, COL_FACE_V), eddy__col(w, COL_FACE_W)};
	float *pcell = eddy__col(w, COL_CELL_PRESSURE);
	const double h = w->def.cell_size, tmin = ps->def.theta_min;

	flip_solid sd;
	if (!eddy__flip_solid_for(w, s, ctx->dt, &sd))
		return eddy__fail(w, EDDY_ERR_NOMEM, "flip_pressure: out of memory");
	int *row = eddy__arena_alloc(&w->arena, nc * sizeof *row);
	int *slab_rows = eddy__arena_alloc(&w->arena, (size_t)nz * sizeof *slab_rows);
	double *slab_vol = eddy__arena_alloc(&w->arena, (size_t)nz * sizeof *slab_vol);
	if (!row || !slab_rows || !slab_vol)
		return eddy__fail(w, EDDY_ERR_NOMEM, "flip_pressure: out of memory");
	/* The unknowns and the liquid volume, slab by slab (on all threads): row
	 * marks an unknown with 0 here, and each slab's count and volume are
	 * its own, summed below in slab order, so neither depends on the thread
	 * count. */
	const int nt = nc > 65536 ? ctx->threads : 1;
#pragma omp parallel for num_threads(nt) if (nt > 1) schedule(static)
	for (int k = 0; k < nz; ++k) {
		int cnt = 0;
		double vk = 0;
		for (int j = 0; j < ny; ++j)
			for (int i = 0; i < nx; ++i) {
				const size_t c = flip_cell(w, i, j, k);
				bool unknown = type[c] == EDDY_CELL_FLUID;
				if (sd.any && !unknown && flip_solid_open(&sd, c) < 1) {
					/* A cell the solid cuts that holds no particle (they sit
					 * in the open part of the cells next door), or whose
					 * centre is in the solid (typed solid): it is liquid up
					 * to the solid when an open face leads to a fluid cell
					 * and none to a plain air cell (one the solid does not
					 * cut, or outside the marker's surface, phi > 0: then it
					 * is on the free surface; at a corner of the box's cut
					 * every neighbour is cut, and the pool's surface rose a
					 * cell there). As air inside the
					 * pool it would be a p = 0 sink draining the water into
					 * the solid; as a wall it would jump in and out of the
					 * system as the solid moves. */
					bool wet = false, dry = false;
					for (int d = 0; d < 6; ++d) {
						size_t f;
						const long o = across(w, i, j, k, d, &f);
						const int ax = d >> 1;
						int fc[3] = {i, j, k};
						fc[ax] += d & 1;
						if (flip_face_weight(w, &sd, ax, f, fc[0], fc[1], fc[2]) == 0)
							continue;
						if (o < 0) { /* an open domain side: air beyond */
							dry = true;
							continue;
						}
						wet |= type[o] == EDDY_CELL_FLUID;
						dry |= type[o] == EDDY_CELL_AIR && (flip_solid_open(&sd, o) >= 1 || phi[o] > 0);
					}
					unknown = wet && !dry;
				}
				row[c] = unknown ? 0 : -1;
				cnt += unknown;
				if (unknown && type[c] == EDDY_CELL_SOLID) {
					vk += flip_solid_open(&sd, c); /* no marker there: full of liquid up to the solid */
				} else if (type[c] != EDDY_CELL_SOLID) {
					const double f = 0.5 * (1.0 - (double)phi[c]);
					vk += (f < 0 ? 0 : f > 1 ? 1 : f) * (sd.any ? (double)flip_solid_open(&sd, c) : 1.0);
				}
			}
		slab_rows[k] = cnt;
		slab_vol[k] = vk;
	}
	int n = 0;
	double vol = 0;
	for (int k = 0; k < nz; ++k) {
		const int first = n;
		n += slab_rows[k];
		slab_rows[k] = first;
		vol += slab_vol[k];
	}
	/* rows numbered in cell order, as the solvers' orderings assume */
#pragma omp parallel for num_threads(nt) if (nt > 1) schedule(static)
	for (int k = 0; k < nz; ++k) {
		int r = slab_rows[k];
		for (size_t c = flip_cell(w, 0, 0, k), e = c + (size_t)nx * ny; c < e; ++c)
			if (row[c] == 0)
				row[c] = r++;
	}
	vol *= h * h * h;
	flip_matrix A = {n, NULL, NULL, NULL};
	A.diag = eddy__arena_alloc(&w->arena, (size_t)n * sizeof *A.diag + 8);
	A.nb = eddy__arena_alloc(&w->arena, 6 * (size_t)n * sizeof *A.nb + 8);
	if (sd.any)
		A.off = eddy__arena_alloc(&w->arena, 6 * (size_t)n * sizeof *A.off + 8);
	double *b = eddy__arena_alloc(&w->arena, (size_t)n * sizeof *b + 8);
	double *q = eddy__arena_alloc(&w->arena, (size_t)n * sizeof *q + 8);
	int *cell_of = eddy__arena_alloc(&w->arena, (size_t)n * sizeof *cell_of + 8);
	int *comp = eddy__arena_alloc(&w->arena, (size_t)n * sizeof *comp + 8);
	int *stack = eddy__arena_alloc(&w->arena, (size_t)n * sizeof *stack + 8);
	uint8_t *has_air = eddy__arena_alloc(&w->arena, (size_t)n + 8);
	uint8_t *open_of = eddy__arena_alloc(&w->arena, (size_t)n + 8);  /* per component root: it has air */
	uint8_t *free_row = eddy__arena_alloc(&w->arena, (size_t)n + 8); /* let go of its walls: q = 0 */
	if (!A.diag || !A.nb || !b || !q || !cell_of || !comp || !stack || !has_air || !open_of || !free_row ||
	    (sd.any && !A.off))
		return eddy__fail(w, EDDY_ERR_NOMEM, "flip_pressure: out of memory for %d unknowns", n);

#pragma omp parallel for num_threads(nt) if (nt > 1) schedule(static)
	/* assemble: diagonal, links weighted by the open fraction w_f, and the
	 * right-hand side -D with D = sum_f +-(w_f u_f + (1 - w_f) u_solid,f).
	 * Each row is written by one thread from read-only inputs, so this and
	 * the loops below marked "on all threads" give the same values on any
	 * thread count (the max reductions are order-free). */
	for (int k = 0; k < nz; ++k)
		for (int j = 0; j < ny; ++j)
			for (int i = 0; i < nx; ++i) {
				const size_t c = flip_cell(w, i, j, k);
				const int r = row[c];
				if (r < 0)
					continue;
				cell_of[r] = (int)c;
				double diag = 0, div = 0;
				has_air[r] = 0;
				for (int d = 0; d < 6; ++d) {
					size_t f;
					const long o = across(w, i, j, k, d, &f);
					const int ax = d >> 1;
					int fc[3] = {i, j, k};
					fc[ax] += d & 1;
					double wf = flip_face_weight(w, &sd, ax, f, fc[0], fc[1], fc[2]);
					/* a solid cell out of the system (cut, at the surface, or
					 * all solid): no link, its face a given flux, the water's
					 * own through the open part (held as it is, below) */
					double flux = (double)face[ax][f];
					if (sd.any)
						flux = wf * flux + (1.0 - wf) * (double)flip_solid_vel(&sd, ax, f);
					div += (d & 1) ? flux : -flux;
					int link = -1;
					if (o < 0 && wf > 0) {
						/* an open domain side: air beyond, p = 0 at the
						 * centre of the cell past it (theta 1) */
						diag += wf;
						has_air[r] = 1;
					} else if (o >= 0 && wf > 0) {
						if (row[o] >= 0) {
							diag += wf;
							link = row[o];
						} else if (type[o] == EDDY_CELL_AIR) {
							diag += wf / theta(phi[c], phi[o], tmin);
							has_air[r] = 1;
						}
					}
					A.nb[6 * r + d] = link;
					if (A.off)
						A.off[6 * r + d] = link >= 0 ? wf : 0.0;
				}
				A.diag[r] = diag;
				b[r] = -div;
			}

	/* volume correction: a divergence source where the particles are packed
	 * or thinned (see the header) */
	double dens_max = 0, dens_min = INFINITY;
	int corrected = 0;
	/* the time the correction takes (header): the step, or the flow's own
	 * step, flip_advect's CFL limit, where that is longer */
	const double vc_time = fmax(ctx->dt, w->def.cfl * eddy__flip_advect_time(w));
	{
		const float *dens;
		const uint8_t *held;
		if (!eddy__flip_p2g_density(w, s, &dens, &held)) {
			/* no p2g result valid for these particles: measure here */
			float *d = eddy__arena_alloc(&w->arena, nc * sizeof *d);
			uint8_t *hc = eddy__arena_alloc(&w->arena, nc);
			if (!d || !hc)
				return eddy__fail(w, EDDY_ERR_NOMEM, "flip_pressure: out of memory");
			const float *px = eddy__col(w, COL_X_), *py = eddy__col(w, COL_Y_), *pz = eddy__col(w, COL_Z_);
			flip_particle_density(w, px, py, pz, d, ctx->threads);
			memset(hc, 0, nc);
			const flip_grid g = flip_grid_of(w);
			for (size_t p = 0; p < w->n; ++p)
				hc[flip_cell(w, flip_cell_index((px[p] - g.o.x) * g.inv, nx),
				             flip_cell_index((py[p] - g.o.y) * g.inv, ny),
				             flip_cell_index((pz[p] - g.o.z) * g.inv, nz))] = 1;
			dens = d;
			held = hc;
		}
		const double n0 = flip_rest_count(w);
		const flip_grid bg = flip_grid_of(w);
		/* each row its own source; the extremes and the count are order-free */
#pragma omp parallel for num_threads(nt) if (nt > 1) schedule(static) reduction(max : dens_max) \
	reduction(min : dens_min) reduction(+ : corrected)
		for (int r = 0; r < n; ++r) {
			const int c = cell_of[r];
			const int i = c % nx, j = (c / nx) % ny, k = c / (nx * ny);
			if (type[c] != EDDY_CELL_FLUID)
				continue;
			/* near the box's cut (flip_grid's top) the count at rest is known
			 * (flip_box_rest); a collider's cut cells, and slices of the
			 * box's under a quarter cell (a particle or two), are left */
			const float op = sd.any ? flip_solid_open(&sd, c) : 1.0f;
			if (op < 1 && !(flip_box_open(&bg, i, j, k) <= op && op >= VC_CUT_MIN))
				continue;
			double e = (double)dens[c] / (n0 * (double)flip_box_rest(&bg, i, j, k)) - 1.0;
			if (has_air[r] && e <= VC_PACKED)
				continue; /* not deep, not packed: no source, whatever the neighbours */
			/* next to a solid the kernel reaches into it; deep: no air side
			 * on the cell or a face neighbour, a particle in all 27 cells of
			 * the kernel's reach (see the header) */
			bool deep = !has_air[r], walled = false;
			for (int d = 0; d < 6; ++d) {
				const int o = A.nb[6 * r + d];
				size_t f;
				if (o >= 0) {
					const int co = cell_of[o];
					const float oo = sd.any ? flip_solid_open(&sd, (size_t)co) : 1.0f;
					walled |= oo < 1 && !(flip_box_open(&bg, co % nx, (co / nx) % ny, co / (nx * ny)) <= oo);
					deep &= !has_air[o];
				} else if (across(w, i, j, k, d, &f) >= 0) {
					walled |= type[across(w, i, j, k, d, &f)] == EDDY_CELL_SOLID;
					deep = false; /* air */
				}
			}
			if (walled || (!deep && e <= VC_PACKED))
				continue;
			/* the kernel's reach: all 27 cells around hold particles (those
			 * beyond the domain's sides and the box's cut cells excepted:
			 * see the header) */
			if (deep && e <= 0) {
				const int i0 = i > 0 ? -1 : 0, i1 = i + 1 < nx ? 1 : 0, j0 = j > 0 ? -1 : 0, j1 = j + 1 < ny ? 1 : 0,
						  k0 = k > 0 ? -1 : 0, k1 = k + 1 < nz ? 1 : 0;
				const long sy = nx, sz = (long)nx * ny;
				for (int dk = k0; dk <= k1 && deep; ++dk)
					for (int dj = j0; dj <= j1 && deep; ++dj)
						for (int di = i0; di <= i1 && deep; ++di) {
							const float cut = flip_box_open(&bg, i + di, j + dj, k + dk);
							deep = held[c + di + dj * sy + dk * sz] != 0 || (cut < 1.0f && cut >= VC_CUT_MIN);
						}
			}
			if (walled || (!deep && e <= VC_PACKED))
				continue;
			dens_max = e > dens_max ? e : dens_max;
			dens_min = e < dens_min ? e : dens_min;
			e = e > VC_CLAMP ? VC_CLAMP : e < -VC_CLAMP ? -VC_CLAMP : e;
			b[r] += VC_RATE * e * h / vc_time; /* + dx s_i, s_i = rate e / T */
			corrected++;
		}
	}

	/* connected components; those without an air side are singular */
	for (int r = 0; r < n; ++r) {
		comp[r] = -1;
		free_row[r] = 0;
	}
	int pinned = 0;
	for (int r0 = 0; r0 < n; ++r0) {
		if (comp[r0] >= 0)
			continue;
		int top = 0, members = 0;
		bool open = false;
		double sum = 0;
		stack[top++] = r0;
		comp[r0] = r0;
		while (top > 0) {
			const int r = stack[--top];
			members++;
			sum += b[r];
			for (int d = 0; d < 6; ++d) {
				const int o = A.nb[6 * r + d];
				if (o >= 0 && comp[o] < 0) {
					comp[o] = r0;
					stack[top++] = o;
				}
			}
			open |= has_air[r] != 0;
		}
		open_of[r0] = open;
		if (open)
			continue;
		/* zero-mean right-hand side, then pin the component's first row */
		const double mean = sum / members;
		for (int r = r0; r < n; ++r)
			if (comp[r] == r0)
				b[r] -= mean;
		for (int d = 0; d < 6; ++d) {
			const int o = A.nb[6 * r0 + d];
			if (o >= 0)
				A.nb[6 * o + (d ^ 1)] = -1;
			A.nb[6 * r0 + d] = -1;
		}
		A.diag[r0] = 1;
		b[r0] = 0;
		pinned++;
	}

	/* solve, then let go of the walls where the water leaves them (header) */
	int iterations = 0, released = 0;
	double residual = 0;
	double b0max = 0;
	for (int r = 0; r < n; ++r)
		b0max = fabs(b[r]) > b0max ? fabs(b[r]) : b0max;
	eddy_status st = solve_system(w, ps, ctx, &A, cell_of, b, q, ps->def.tolerance, &iterations, &residual);
	if (st != EDDY_OK)
		return st;
	for (int round = 0; round < SEPARATE_ROUNDS; ++round) {
		int more = 0;
		/* swept until no cell is added: a cell let go opens the suction
		 * cells along the wall beside it whatever the sweep's order (rows
		 * run up from the floor, so one sweep opened a wall leaving water
		 * one cell a step down from the surface, and a paddle pulled back
		 * dragged the column below with it meanwhile) */
		for (int added = 1; added;) {
			added = 0;
			for (int r = 0; r < n; ++r) {
				if (!(q[r] < 0) || !open_of[comp[r]] || free_row[r] ||
				    !at_wall(w, &sd, type, phi, row, free_row, cell_of[r]))
					continue;
				/* q_r = 0: as the pinning, the neighbours keep their diagonal */
				for (int d = 0; d < 6; ++d) {
					const int o = A.nb[6 * r + d];
					if (o >= 0)
						A.nb[6 * o + (d ^ 1)] = -1;
					A.nb[6 * r + d] = -1;
				}
				free_row[r] = 1;
				A.diag[r] = 1;
				b[r] = 0;
				added++;
			}
			more += added;
		}
		if (more == 0)
			break;
		released += more;
		/* the change is local: solve for the correction of q, to the same
		 * absolute residual (tol max|b|) */
		double *res = eddy__arena_alloc(&w->arena, (size_t)n * sizeof *res + 8);
		double *dq = eddy__arena_alloc(&w->arena, (size_t)n * sizeof *dq + 8);
		if (!res || !dq)
			return eddy__fail(w, EDDY_ERR_NOMEM, "flip_pressure: out of memory for %d unknowns", n);
		for (int r = 0; r < n; ++r)
			q[r] = free_row[r] ? 0.0 : q[r];
		/* the residual of q: on all threads, each row its own, the maxima order-free */
		double rmax = 0, bmax = 0;
#pragma omp parallel for num_threads(nt) if (nt > 1) schedule(static) reduction(max : rmax, bmax)
		for (int r = 0; r < n; ++r) {
			const double t = row_residual(&A, b, q, r);
			res[r] = t;
			rmax = fabs(t) > rmax ? fabs(t) : rmax;
			bmax = fabs(b[r]) > bmax ? fabs(b[r]) : bmax;
		}
		/* the residual allowed: the solve's tolerance of the first solve's
		 * max|b| (as the check below: letting go empties rows of b) */
		const double tol = ps->def.solver == EDDY_FLIP_CHOLMOD ? 1e-10 : ps->def.tolerance; /* its check: 1e-8 */
		const double target = tol * (bmax > b0max ? bmax : b0max);
		if (!(rmax > target))
			continue;
		int it2 = 0;
		double res2 = 0;
		st = solve_system(w, ps, ctx, &A, cell_of, res, dq, target / rmax, &it2, &res2);
		if (st != EDDY_OK)
			return st;
#pragma omp parallel for num_threads(nt) if (nt > 1) schedule(static)
		for (int r = 0; r < n; ++r)
			q[r] += dq[r];
		iterations += it2;
	}
	/* the residual, measured rather than trusted */
	double rmax = 0, bmax = 0;
	bool finite = true;
#pragma omp parallel for num_threads(nt) if (nt > 1) schedule(static) reduction(max : rmax, bmax) reduction(&& : finite)
	for (int r = 0; r < n; ++r) {
		const double t = row_residual(&A, b, q, r);
		finite = finite && isfinite(q[r]);
		rmax = fabs(t) > rmax ? fabs(t) : rmax;
		bmax = fabs(b[r]) > bmax ? fabs(b[r]) : bmax;
	}
	bmax = bmax > b0max ? bmax : b0max;
	residual = bmax > 0 ? rmax / bmax : rmax;
	const double allowed = ps->def.solver == EDDY_FLIP_CHOLMOD ? 1e-8 : ps->def.tolerance * 1.0001;
	if (!finite || !(residual <= allowed))
		return eddy__fail(
			w, EDDY_ERR_SOLVER,
			"flip_pressure: %s solution rejected at step %lld: relative residual %.3g > %.3g (%d unknowns, %s)",
			solver_label[ps->def.solver], (long long)ctx->step, residual, allowed, n,
			finite ? "finite" : "non-finite values");

	/* velocity update on faces with fluid on a side and no solid */
	const double pscale = ps->def.density * h / ctx->dt;
#pragma omp parallel for num_threads(nt) if (nt > 1) schedule(static)
	for (size_t c = 0; c < nc; ++c)
		pcell[c] = row[c] >= 0 ? (float)(q[row[c]] * pscale) : 0.0f;
	for (int a = 0; a < 3; ++a) {
		const int fx = nx + (a == 0), fy = ny + (a == 1), fz = nz + (a == 2);
		float *f = face[a];
		/* on all threads: each face written once */
#pragma omp parallel for num_threads(nt) if (nt > 1) schedule(static)
		for (int k = 0; k < fz; ++k)
			for (int j = 0; j < fy; ++j)
				for (int i = 0; i < fx; ++i) {
					const int hi[3] = {i, j, k};
					int lo[3] = {i, j, k};
					lo[a]--;
					const int na = a == 0 ? nx : a == 1 ? ny : nz;
					const size_t fi = a == 0 ? flip_fu(w, i, j, k) : a == 1 ? flip_fv(w, i, j, k) : flip_fw(w, i, j, k);
					/* closed faces keep the solid velocity flip_boundary set;
					 * a solid cell has only closed faces; a domain side is
					 * closed unless open (flip_boundary's open_sides) */
					if (flip_face_weight(w, &sd, a, fi, i, j, k) == 0)
						continue;
					if (lo[a] < 0 || hi[a] >= na) {
						/* an open side: the ghost pressure of air at theta 1 is 0 */
						const int r = lo[a] < 0 ? row[flip_cell(w, hi[0], hi[1], hi[2])]
						                        : row[flip_cell(w, lo[0], lo[1], lo[2])];
						if (r >= 0)
							f[fi] = (float)((double)f[fi] - (lo[a] < 0 ? q[r] : -q[r]));
						continue;
					}
					const size_t cl = flip_cell(w, lo[0], lo[1], lo[2]), ch = flip_cell(w, hi[0], hi[1], hi[2]);
					const int rl = row[cl], rh = row[ch];
					if (rl < 0 && rh < 0)
						continue;
					/* as in the matrix: a side that is not an unknown is air
					 * (ghost pressure) or a solid cell (a given flux: no update) */
					if ((rl < 0 && type[cl] != EDDY_CELL_AIR) || (rh < 0 && type[ch] != EDDY_CELL_AIR))
						continue;
					double ql, qh;
					if (rl >= 0 && rh >= 0) {
						ql = q[rl];
						qh = q[rh];
					} else if (rl >= 0) {
						ql = q[rl];
						qh = ql * (1.0 - 1.0 / theta(phi[cl], phi[ch], tmin));
					} else {
						qh = q[rh];
						ql = qh * (1.0 - 1.0 / theta(phi[ch], phi[cl], tmin));
					}
					f[fi] = (float)((double)f[fi] - (qh - ql));
				}
	}
	/* walls the water leaves: a closed face (or a domain side) of a liquid
	 * cell whose opposite face, open, carries the water away from the wall
	 * faster than the wall moves takes that face's velocity, so that the
	 * particles beside the wall, which flip_g2p interpolates towards it, are
	 * not held back by the wall's (header). Serial: few cells touch a wall
	 * and each face is written by the one cell it faces. */
	for (int r = 0; r < n; ++r) {
		if (!free_row[r])
			continue;
		const int c = cell_of[r];
		const int ci[3] = {c % nx, (c / nx) % ny, c / (nx * ny)};
		for (int d = 0; d < 6; ++d) {
			size_t f, fo;
			const long o = across(w, ci[0], ci[1], ci[2], d, &f);
			const int ax = d >> 1;
			int fc[3] = {ci[0], ci[1], ci[2]};
			fc[ax] += d & 1;
			const bool wall = flip_face_weight(w, &sd, ax, f, fc[0], fc[1], fc[2]) == 0 ||
			                  (o >= 0 && row[o] < 0 && type[o] == EDDY_CELL_SOLID);
			if (!wall)
				continue;
			const long oo = across(w, ci[0], ci[1], ci[2], d ^ 1, &fo);
			int gc[3] = {ci[0], ci[1], ci[2]};
			gc[ax] += (d ^ 1) & 1;
			if (flip_face_weight(w, &sd, ax, fo, gc[0], gc[1], gc[2]) < 1 ||
			    (oo >= 0 && row[oo] < 0 && type[oo] == EDDY_CELL_SOLID))
				continue; /* walled on both sides along this axis */
			const float vw = o < 0 ? 0.0f : flip_solid_vel(&sd, ax, f), vo = face[ax][fo];
			/* away from the wall: against the wall's outward side d */
			if ((d & 1) ? vo < vw : vo > vw)
				face[ax][f] = vo;
		}
	}

	/* divergence left over, as volume change per step */
	double dmax = 0;
#pragma omp parallel for num_threads(nt) if (nt > 1) schedule(static) reduction(max : dmax)
	for (int r = 0; r < n; ++r) {
		if (free_row[r])
			continue; /* let go of its walls: its divergence is the gap opening */
		const int c = cell_of[r];
		const int i = c % nx, j = (c / nx) % ny, k = c / (nx * ny);
		double div = 0;
		for (int d = 0; d < 6; ++d) {
			size_t f;
			(void)across(w, i, j, k, d, &f);
			const int ax = d >> 1;
			double flux = (double)face[ax][f];
			if (sd.any) {
				int fc[3] = {i, j, k};
				fc[ax] += d & 1;
				const double wf = flip_face_weight(w, &sd, ax, f, fc[0], fc[1], fc[2]);
				flux = wf * flux + (1.0 - wf) * (double)flip_solid_vel(&sd, ax, f);
			}
			div += (d & 1) ? flux : -flux;
		}
		dmax = fabs(div) > dmax ? fabs(div) : dmax;
	}
	eddy_world_publish_text(w, "solver", solver_name[ps->def.solver]);
	eddy_world_publish(w, "iterations", iterations);
	eddy_world_publish(w, "residual", residual);
	eddy_world_publish(w, "divergence", dmax / h * ctx->dt);
	eddy_world_publish(w, "volume", vol);
	eddy_world_publish(w, "pinned", pinned);
	eddy_world_publish(w, "released", released);
	eddy_world_publish(w, "density_error_max", dens_max);
	eddy_world_publish(w, "density_error_min", corrected ? dens_min : 0.0);
	eddy_world_publish(w, "analyses", (double)ps->analyses);
	return EDDY_OK;
}

static void destroy(eddy_system *s)
{
	pressure *ps = s->data;
	if (ps) {
		eddy__flip_cholmod_free(ps->chol);
		eddy__flip_mg_free(ps->mg);
	}
}

/* The scratch is this step's own: released on return, so the pipeline's
 * peak is the largest system's scratch, not their sum. */
static eddy_status step(eddy_world *w, eddy_system *s, const eddy_step_context *ctx)
{
	const eddy_arena_mark m = eddy__arena_mark(&w->arena);
	const eddy_status st = step_body(w, s, ctx);
	eddy__arena_release(&w->arena, m);
	return st;
}

static void *shared(const eddy_system *s, uint32_t cap)
{
	return cap == EDDY_CAP_GRID_DENSITY ? &((pressure *)s->data)->def : NULL;
}

const eddy_system_vtable eddy__kind_flip_pressure = {
	.name = "flip_pressure",
	.keeps_solids = true,
	.provides = EDDY_CAP_GRID_DENSITY,
	.shared = shared,
	.step = step,
	.destroy = destroy,
	.default_writes = pressure_writes,
};

eddy_system_id eddy_add_flip_pressure(eddy_world *w, const eddy_flip_pressure_def *def)
{
	const char *sys = "flip_pressure";
	if (!eddy__add_args(w, def, sys))
		return EDDY_NULL_SYSTEM;
	if (def->solver != EDDY_FLIP_PCG && def->solver != EDDY_FLIP_CHOLMOD && def->solver != EDDY_FLIP_HYPRE &&
	    def->solver != EDDY_FLIP_MG) {
		eddy__fail(w, EDDY_ERR_INVALID, "%s: 'solver' must be \"pcg\", \"cholmod\", \"hypre\" or \"mg\" (got %d)", sys,
		           (int)def->solver);
		return EDDY_NULL_SYSTEM;
	}
	if (!eddy__check_positive(w, sys, "density", def->density) || !eddy__check_finite(w, sys, "density", def->density))
		return EDDY_NULL_SYSTEM;
	if (!(def->tolerance > 0 && def->tolerance < 1)) {
		eddy__fail(w, EDDY_ERR_INVALID, "%s: 'tolerance' must be in (0, 1) (got %g)", sys, def->tolerance);
		return EDDY_NULL_SYSTEM;
	}
	if (def->max_iterations < 1) {
		eddy__fail(w, EDDY_ERR_INVALID, "%s: 'max_iterations' must be >= 1 (got %d)", sys, def->max_iterations);
		return EDDY_NULL_SYSTEM;
	}
	if (!eddy__check_range(w, sys, "theta_min", def->theta_min, 1e-4, 0.5))
		return EDDY_NULL_SYSTEM;
	pressure *ps = calloc(1, sizeof *ps);
	if (ps)
		ps->def = *def;
	return eddy__add_system(w, &eddy__kind_flip_pressure, ps, pressure_reads, pressure_writes);
}
