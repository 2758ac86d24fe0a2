/* SPDX-License-Identifier: MIT */
#define _POSIX_C_SOURCE 200809L
/* FLIP pressure solvers against each other (eddy issue 17): the multigrid-
 * preconditioned CGs (solver = "hypre", src/flip_hypre.c, and solver = "mg",
 * src/flip_mg.c) against CHOLMOD on
 * the systems the pressure solve builds (free surface with ghost-fluid
 * diagonals, a closed box whose singular component is pinned, fractional
 * faces cut by colliders), its iteration count over grid sizes, its result
 * on one and two threads, and its failure message. The validations that also
 * run with it (analytic Poisson, closed box, tank, dam break against Martin &
 * Moyce, the scene on the command line) are in tests/test_flip.c. */
#include "test.h"

#include <stdlib.h>
#include <string.h>

#include "eddy.h"
#include "flip_pool.h"
#include "grid_fixture.h"

static double stat(const eddy_frame_stats *fs, const char *name)
{
	for (int k = 0; k < fs->extra_count; ++k)
		if (strcmp(fs->extra[k].name, name) == 0)
			return fs->extra[k].value;
	return NAN;
}

/* ---- one step of the full pipeline, solver against solver ------------------ */

typedef enum pool_case { POOL_SLOPED, POOL_CLOSED, POOL_SOLIDS } pool_case;

static uint64_t lcg(uint64_t *s)
{
	*s = *s * 6364136223846793005ull + 1442695040888963407ull;
	return *s >> 40;
}

/* A unit-wide tank at dx = 1/16: a surface sloped in x and z (thetas of every
 * size), the tank full (no air: singular, pinned), or a pool with a sphere and
 * a tilted plane cutting faces. Particles 2 x 2 x 2 per cell with random
 * velocities up to 0.25 m/s, so there is divergence to remove. */
static eddy_world *pool(pool_case pc, eddy_flip_solver solver, double tol, int threads)
{
	const double h = 1.0 / 16;
	eddy_world_def d = eddy_default_world_def();
	d.bounds_max = (eddy_vec3){1, pc == POOL_CLOSED ? 0.5f : 1, 0.5f};
	d.cell_size = h;
	d.fps = 100;
	d.dt_max = 0.01; /* one step per frame: the first frame is one solve of a known state */
	d.threads = threads;
	eddy_world *w = eddy_create_world(&d, NULL, 0);
	flip_defs fd = flip_default_defs();
	fd.pressure.solver = solver;
	fd.pressure.tolerance = tol;
	CHECK(flip_add_pipeline(w, &fd));
	if (pc == POOL_SOLIDS) {
		eddy_collide_sphere_def sp = eddy_default_collide_sphere_def();
		sp.center = (eddy_vec3){0.43f, 0.37f, 0.26f};
		sp.radius = 0.17f;
		CHECK(eddy_system_valid(w, eddy_add_collide_sphere(w, &sp)));
		eddy_collide_plane_def pl = eddy_default_collide_plane_def();
		pl.point = (eddy_vec3){0, 0.11f, 0};
		pl.normal = (eddy_vec3){0.3f, 1, 0.2f};
		CHECK(eddy_system_valid(w, eddy_add_collide_plane(w, &pl)));
	}
	const int m = 32; /* particles per metre per axis: 2 per cell */
	eddy_vec3 *pos = malloc((size_t)m * m * m / 2 * sizeof *pos), *vel = malloc((size_t)m * m * m / 2 * sizeof *vel);
	size_t n = 0;
	uint64_t seed = 42;
	for (int k = 0; k < m / 2; ++k)
		for (int j = 0; j < m; ++j)
			for (int i = 0; i < m; ++i) {
				const double x = (i + 0.5) / m, y = (j + 0.5) / m, z = (k + 0.5) / m;
				const double top = pc == POOL_CLOSED ? 0.5 : pc == POOL_SLOPED ? 0.3 + 0.25 * x + 0.1 * z : 0.55;
				if (y > top)
					continue;
				if (pc == POOL_SOLIDS) { /* not inside the sphere or below the plane */
					const double dx = x - 0.43, dy = y - 0.37, dz = z - 0.26;
					if (dx * dx + dy * dy + dz * dz < 0.17 * 0.17 || 0.3 * x + (y - 0.11) + 0.2 * z < 0)
						continue;
				}
				pos[n] = (eddy_vec3){(float)x, (float)y, (float)z};
				vel[n].x = (float)(0.5 * ((double)lcg(&seed) / (1 << 24) - 0.5));
				vel[n].y = (float)(0.5 * ((double)lcg(&seed) / (1 << 24) - 0.5));
				vel[n].z = (float)(0.5 * ((double)lcg(&seed) / (1 << 24) - 0.5));
				n++;
			}
	CHECK(eddy_world_add_particles(w, n, pos, vel) == EDDY_OK);
	free(pos);
	free(vel);
	return w;
}

/* On each case, the HYPRE (or MG) pressures after one step against CHOLMOD's:
 * max |p - p_cholmod| <= 20 tol max |p_cholmod|, the bound the PCG
 * meets against CHOLMOD in test_flip.c (the stop is on max|r| / max|b| = tol;
 * the error is A^-1 r, a smooth field some 10 tol at these sizes, and
 * cell_pressure is a float, 6e-8 relative). Also: the published residual is
 * within tol, the singular case pinned one component, and the colliders cut
 * faces (the divergence after projection within tol of the flux scale). */
static void agrees_with_cholmod(eddy_flip_solver solver)
{
	static const char *const names[3] = {"sloped surface", "closed box (pinned)",
	                                     "sphere and plane (fractional faces)"};
	const double tol = 1e-6;
	for (int pc = 0; pc < 3; ++pc) {
		eddy_world *c = pool((pool_case)pc, EDDY_FLIP_CHOLMOD, tol, 1);
		eddy_world *hy = pool((pool_case)pc, solver, tol, 1);
		const eddy_status sc = eddy_world_step_frame(c), sh = eddy_world_step_frame(hy);
		CHECKF(sc == EDDY_OK, "cholmod: %s", eddy_world_error(c));
		CHECKF(sh == EDDY_OK, "%s: %s", solver == EDDY_FLIP_MG ? "mg" : "hypre", eddy_world_error(hy));
		if (sc == EDDY_OK && sh == EDDY_OK) {
			size_t n, n2;
			const float *pcm = eddy_world_channel(c, "cell_pressure", &n);
			const float *phy = eddy_world_channel(hy, "cell_pressure", &n2);
			CHECK(n == n2);
			double dmax = 0, pmax = 0;
			for (size_t i = 0; i < n && i < n2; ++i) {
				dmax = fmax(dmax, fabs((double)pcm[i] - phy[i]));
				pmax = fmax(pmax, fabs((double)pcm[i]));
			}
			eddy_frame_stats fc, fh;
			eddy_world_frame_stats(c, &fc);
			eddy_world_frame_stats(hy, &fh);
			printf("    %s, %s: |p - p_cholmod| / max|p| = %.3g (max |p| %.4g Pa), %g iterations, residual %.3g, "
			       "pinned %g, divergence %.3g (cholmod %.3g)\n",
			       solver == EDDY_FLIP_MG ? "mg" : "hypre", names[pc], dmax / pmax, pmax, stat(&fh, "iterations"),
			       stat(&fh, "residual"), stat(&fh, "pinned"), stat(&fh, "divergence"), stat(&fc, "divergence"));
			CHECK(pmax > 0);
			CHECK(dmax <= 20 * tol * pmax);
			CHECK(stat(&fh, "residual") <= tol);
			CHECK(stat(&fh, "iterations") >= 1);
			CHECK(stat(&fh, "pinned") == (pc == POOL_CLOSED ? 1 : 0));
			CHECK(stat(&fh, "pinned") == stat(&fc, "pinned"));
			/* the velocity update leaves the residual as the weighted
			 * divergence: max |D| <= tol max |b|, and |b| <= 6 faces x
			 * (0.25 m/s + g dt) = 2.1 m/s, so the published max |D| dt / dx
			 * <= tol x 2.1 x 0.16 = 0.34 tol */
			CHECK(stat(&fh, "divergence") <= 0.34 * tol);
		}
		eddy_destroy_world(c);
		eddy_destroy_world(hy);
	}
}

static void hypre_agrees_with_cholmod(void) { agrees_with_cholmod(EDDY_FLIP_HYPRE); }
static void mg_agrees_with_cholmod(void) { agrees_with_cholmod(EDDY_FLIP_MG); }

/* ---- iterations against grid size -------------------------------------------- */

/* A grid-only pool with a wavy surface and a drop (fixture_wavy_pool) and
 * random face velocities. */
static eddy_status wavy_setup(eddy_world *w, const eddy_step_context *ctx, void *user)
{
	(void)ctx;
	(void)user;
	fixture_random_faces(w, 99);
	fixture_wavy_pool(w);
	return EDDY_OK;
}

static double wavy_iterations(int n, eddy_flip_solver solver, double *ms)
{
	eddy_world_def d = eddy_default_world_def();
	d.cell_size = 1.0 / n;
	d.fps = 100;
	d.dt_max = 0.01;
	eddy_world *w = eddy_create_world(&d, NULL, 0);
	static const char *const writes[] = {"u", "v", "w", "cell_type", "flip_phi"};
	eddy_custom_system_def cs = eddy_default_custom_system_def();
	cs.name = "wavy_setup";
	cs.writes = writes;
	cs.write_count = 5;
	cs.step = wavy_setup;
	CHECK(eddy_system_valid(w, eddy_add_custom_system(w, &cs)));
	eddy_flip_pressure_def pr = eddy_default_flip_pressure_def();
	pr.solver = solver;
	pr.tolerance = 1e-6;
	CHECK(eddy_system_valid(w, eddy_add_flip_pressure(w, &pr)));
	double it = NAN;
	*ms = NAN;
	if (eddy_world_step_frame(w) == EDDY_OK) {
		eddy_frame_stats fs;
		eddy_world_frame_stats(w, &fs);
		it = stat(&fs, "iterations");
		CHECK(stat(&fs, "residual") <= 1e-6);
		for (int k = 0; k < eddy_world_system_count(w); ++k) {
			eddy_system_info info;
			eddy_world_system_info(w, eddy_world_system_at(w, k), &info);
			if (strcmp(info.name, "flip_pressure") == 0)
				*ms = info.profile_ms;
		}
	} else {
		test_fail(__FILE__, __LINE__, "%d^3: %s", n, eddy_world_error(w));
	}
	eddy_destroy_world(w);
	return it;
}

/* The multigrid preconditioner's point: iterations do not grow with the grid.
 * Each doubling may cost at most 30% more iterations (PFMG-PCG took 6, 7, 8
 * at 16^3, 32^3, 64^3 on this pool and 7 at 128^3, the bench's sweep: one
 * iteration more is the integer step at these counts, 17%); MIC(0)-PCG's
 * count grows with the grid's width (18, 25, 44 here: 1.4x and 1.8x per
 * doubling), which the same bound rejects, as the last check confirms. */
static void hypre_iterations_flat_in_grid_size(void)
{
	const int sizes[3] = {16, 32, 64};
	double ith[3], itp[3], msh[3], msp[3];
	for (int k = 0; k < 3; ++k) {
		ith[k] = wavy_iterations(sizes[k], EDDY_FLIP_HYPRE, &msh[k]);
		itp[k] = wavy_iterations(sizes[k], EDDY_FLIP_PCG, &msp[k]);
		printf("    wavy pool %d^3: hypre %g iterations (%.1f ms), pcg %g iterations (%.1f ms)\n", sizes[k], ith[k],
		       msh[k], itp[k], msp[k]);
	}
	for (int k = 1; k < 3; ++k) {
		CHECKF(ith[k] <= 1.3 * ith[k - 1], "hypre: %g iterations at %d^3 after %g at %d^3", ith[k], sizes[k],
		       ith[k - 1], sizes[k - 1]);
		CHECK(ith[k] < itp[k]);
	}
	/* the contrast the bound is about: the same pool does make PCG's count grow */
	CHECKF(itp[2] > 1.3 * itp[1], "pcg: %g iterations at 64^3, %g at 32^3", itp[2], itp[1]);
}

/* The multigrid preconditioner of flip_mg.c: iterations at 64^3 within 1.5x
 * of those at 32^3 (issue 17's target; MIC(0)-PCG's grow 1.8x there, see
 * above), and the same at 96^3 against 32^3 one step beyond. */
static void mg_iterations_flat_in_grid_size(void)
{
	const int sizes[3] = {32, 64, 96};
	double it[3], ms[3];
	for (int k = 0; k < 3; ++k) {
		it[k] = wavy_iterations(sizes[k], EDDY_FLIP_MG, &ms[k]);
		printf("    wavy pool %d^3: mg %g iterations (%.1f ms)\n", sizes[k], it[k], ms[k]);
	}
	for (int k = 1; k < 3; ++k)
		CHECKF(it[k] <= 1.5 * it[0], "mg: %g iterations at %d^3 after %g at %d^3", it[k], sizes[k], it[0], sizes[0]);
}

/* The V-cycle runs in single precision inside double-precision CG: its
 * rounding perturbs the preconditioner by about 1e-7 relative, which must not
 * stall CG short of tolerances far below that. On the pool with a sphere and
 * a plane (fractional faces) at 1e-10, and one step beyond at 1e-12: the
 * published residual (measured by flip_pressure, not trusted) within each. */
static void mg_reaches_tight_tolerance(void)
{
	const double tols[2] = {1e-10, 1e-12};
	for (int k = 0; k < 2; ++k) {
		eddy_world *w = pool(POOL_SOLIDS, EDDY_FLIP_MG, tols[k], 1);
		const bool ok = eddy_world_step_frame(w) == EDDY_OK;
		CHECKF(ok, "tolerance %g: %s", tols[k], eddy_world_error(w));
		if (ok) {
			eddy_frame_stats fs;
			eddy_world_frame_stats(w, &fs);
			printf("    tolerance %g: %g iterations, residual %.3g\n", tols[k], stat(&fs, "iterations"),
			       stat(&fs, "residual"));
			CHECK(stat(&fs, "residual") <= tols[k]);
		}
		eddy_destroy_world(w);
	}
}

/* ---- determinism and failure ----------------------------------------------------- */

/* The same run on 1 and 2 threads gives the same state: the solve is serial,
 * and the systems around it keep their own guarantee (test_flip.c). Five
 * steps, so the pressures feed back into the particles and the next solve. */
static void hypre_same_result_on_one_and_two_threads(void)
{
	uint64_t hash[2] = {0, 1};
	for (int t = 0; t < 2; ++t) {
		eddy_world *w = pool(POOL_SLOPED, EDDY_FLIP_HYPRE, 1e-6, t + 1);
		bool ok = true;
		for (int f = 0; f < 5 && ok; ++f)
			ok = eddy_world_step_frame(w) == EDDY_OK;
		CHECKF(ok, "%s", eddy_world_error(w));
		if (ok)
			hash[t] = eddy_world_state_hash(w);
		eddy_destroy_world(w);
	}
	CHECK(hash[0] == hash[1]);
}

/* PCG on threads: past 16384 rows (4 chunks of flip_pcg.c's 4096) the
 * matrix-vector product, the updates and the chunked dot products run on
 * all threads, and the MIC(0) factorisation and its triangular solves as a
 * pipeline of one band of rows per thread. The wavy pool at 34^3 has about
 * 19k unknowns. The chunk sums are added in chunk order and every row of the
 * sweeps is computed as in the serial order, so the solve must give the same
 * pressures, bit for bit, on 1, 2 and 3 threads (3 bands: a middle one waits
 * on both sides; on this 2-core machine oversubscribed, so a band's wait
 * must yield) and on a second 2-thread run (a race or an order that followed
 * the threads would show up as a different hash); and it must still
 * converge to the tolerance. */
static void same_result_on_one_and_two_threads(eddy_flip_solver solver)
{
	static const int threads[4] = {1, 2, 2, 3};
	uint64_t hash[4] = {0, 1, 2, 3};
	double unknowns = 0;
	for (int run = 0; run < 4; ++run) {
		eddy_world_def d = eddy_default_world_def();
		d.cell_size = 1.0 / 34;
		d.threads = threads[run];
		eddy_world *w = eddy_create_world(&d, NULL, 0);
		static const char *const writes[] = {"u", "v", "w", "cell_type", "flip_phi"};
		eddy_custom_system_def cs = eddy_default_custom_system_def();
		cs.name = "wavy_setup";
		cs.writes = writes;
		cs.write_count = 5;
		cs.step = wavy_setup;
		eddy_add_custom_system(w, &cs);
		eddy_flip_pressure_def pr = eddy_default_flip_pressure_def();
		pr.solver = solver;
		pr.tolerance = 1e-6;
		CHECK(eddy_system_valid(w, eddy_add_flip_pressure(w, &pr)));
		const bool ok = eddy_world_step_frame(w) == EDDY_OK;
		CHECKF(ok, "%s", eddy_world_error(w));
		eddy_frame_stats fs;
		eddy_world_frame_stats(w, &fs);
		CHECKF(stat(&fs, "residual") <= 1e-6, "residual %g", stat(&fs, "residual"));
		size_t nc;
		const uint8_t *type = eddy_world_channel_u8(w, "cell_type", &nc);
		unknowns = 0;
		for (size_t c = 0; c < nc; ++c)
			unknowns += type[c] == EDDY_CELL_FLUID;
		if (ok)
			hash[run] = eddy_world_state_hash(w);
		eddy_destroy_world(w);
	}
	CHECKF(unknowns > 16384, "%g unknowns: too few for the threaded path", unknowns);
	CHECK(hash[0] == hash[1] && hash[1] == hash[2] && hash[2] == hash[3]);
}

static void pcg_same_result_on_one_and_two_threads(void) { same_result_on_one_and_two_threads(EDDY_FLIP_PCG); }
/* MG-PCG: the same on its multigrid levels (flip_mg.c; levels of more than
 * 32768 cells and CG vectors of more than 16384 rows run on all threads):
 * red-black sweeps, transfers and residuals write each cell once. */
static void mg_same_result_on_one_and_two_threads(void) { same_result_on_one_and_two_threads(EDDY_FLIP_MG); }

/* Not converging is an error naming the system, the solver and the step. */
static void failure_is_an_error(eddy_flip_solver solver, const char *message)
{
	eddy_world_def d = eddy_default_world_def();
	d.cell_size = 1.0 / 16;
	eddy_world *w = eddy_create_world(&d, NULL, 0);
	static const char *const writes[] = {"u", "v", "w", "cell_type", "flip_phi"};
	eddy_custom_system_def cs = eddy_default_custom_system_def();
	cs.name = "wavy_setup";
	cs.writes = writes;
	cs.write_count = 5;
	cs.step = wavy_setup;
	eddy_add_custom_system(w, &cs);
	eddy_flip_pressure_def pr = eddy_default_flip_pressure_def();
	pr.solver = solver;
	pr.tolerance = 1e-12;
	pr.max_iterations = 2;
	CHECK(eddy_system_valid(w, eddy_add_flip_pressure(w, &pr)));
	CHECK(eddy_world_step(w) == EDDY_ERR_SOLVER);
	CHECK_HAS(eddy_world_error(w), message);
	CHECK_HAS(eddy_world_error(w), "after 2 iterations");
	eddy_destroy_world(w);
}

static void hypre_failure_is_an_error(void)
{
	failure_is_an_error(EDDY_FLIP_HYPRE, "flip_pressure: HYPRE PFMG-PCG did not converge at step 0");
}
static void mg_failure_is_an_error(void)
{
	failure_is_an_error(EDDY_FLIP_MG, "flip_pressure: MG-PCG did not converge at step 0");
}

void suite_flip_solvers(void)
{
	RUN(hypre_agrees_with_cholmod);
	RUN(hypre_iterations_flat_in_grid_size);
	RUN(hypre_same_result_on_one_and_two_threads);
	RUN(pcg_same_result_on_one_and_two_threads);
	RUN(hypre_failure_is_an_error);
	RUN(mg_agrees_with_cholmod);
	RUN(mg_iterations_flat_in_grid_size);
	RUN(mg_reaches_tight_tolerance);
	RUN(mg_same_result_on_one_and_two_threads);
	RUN(mg_failure_is_an_error);
}
