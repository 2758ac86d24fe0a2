/* SPDX-License-Identifier: MIT */
#define _POSIX_C_SOURCE 200809L
/* FLIP benchmarks (make bench; not part of make test), as JSON:
 *  - transfers and advection: ns per particle per step of flip_p2g, flip_g2p
 *    and flip_advect, a box half full at 8 particles per cell, 1 and 2 threads;
 *  - pressure: seconds per solve on n^3 half full (n = 32, 64) for PCG at
 *    1e-2 / 1e-5 / 1e-8 and CHOLMOD (first solve = analyse + factor + solve,
 *    repeat = factor + solve with the analysis reused), 1 and 2 threads;
 *  - the pour scene (5625 particles) on one thread: simulated s per wall s;
 *  - pressure sweep: PCG against HYPRE's PFMG-PCG (solver = "hypre") and
 *    eddy's multigrid-preconditioned CG (solver = "mg") on a pool with a
 *    wavy surface at 32^3, 64^3, 128^3: iterations and s per solve
 *    ("bench_flip FILE sweep" runs only this).
 * Every figure is the median of repeats: the machine is shared and noisy. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "eddy.h"
#include "flip_pool.h"
#include "grid_fixture.h"
#include "bench_util.h"

static double profile_ms(eddy_world *w, const char *name)
{
	for (int k = 0; k < eddy_world_system_count(w); ++k) {
		eddy_system_info info;
		eddy_world_system_info(w, eddy_world_system_at(w, k), &info);
		if (strcmp(info.name, name) == 0)
			return info.profile_ms;
	}
	return NAN;
}

static void add_pipeline(eddy_world *w, eddy_flip_solver solver, double tol)
{
	flip_defs fd = flip_default_defs();
	fd.pressure.solver = solver;
	fd.pressure.tolerance = tol;
	if (!flip_add_pipeline(w, &fd))
		fprintf(stderr, "bench_flip: %s\n", eddy_world_error(w));
}

/* n^3 unit box, the lower half filled at 2 x 2 x 2 particles per cell, in
 * cell order (as a sorted particle table would be). */
static eddy_world *half_box(int n, int threads, eddy_flip_solver solver, double tol)
{
	eddy_world_def d = eddy_default_world_def();
	d.cell_size = 1.0 / n;
	d.threads = threads;
	d.fps = 1000;
	d.dt_max = 1e-3; /* one step per frame, a calm flow */
	d.check_finite = false;
	eddy_world *w = eddy_create_world(&d, NULL, 0);
	add_pipeline(w, solver, tol);
	const int m = 2 * n;
	const size_t count = (size_t)m * (size_t)(m / 2) * (size_t)m;
	eddy_vec3 *p = malloc(count * sizeof *p);
	size_t q = 0;
	const float h = 0.5f / n;
	for (int ck = 0; ck < n; ++ck)
		for (int cj = 0; cj < n / 2; ++cj)
			for (int ci = 0; ci < n; ++ci)
				for (int s = 0; s < 8; ++s)
					p[q++] = (eddy_vec3){(2 * ci + (s & 1) + 0.5f) * h, (2 * cj + ((s >> 1) & 1) + 0.5f) * h,
					                     (2 * ck + (s >> 2) + 0.5f) * h};
	eddy_world_add_particles(w, count, p, NULL);
	free(p);
	return w;
}

static void transfers(FILE *f, bool *first)
{
	enum { REPS = 5, STEPS = 4 };
	const int threads[] = {1, 2};
	const char *sys[] = {"flip_p2g", "flip_g2p", "flip_advect"};
	for (int t = 0; t < 2; ++t) {
		eddy_world *w = half_box(32, threads[t], EDDY_FLIP_PCG, 1e-5);
		eddy_world_step_frame(w);
		const double n = (double)eddy_world_particle_count(w);
		double per[3][REPS], sum[REPS];
		for (int r = 0; r < REPS; ++r) {
			double before[3];
			for (int k = 0; k < 3; ++k)
				before[k] = profile_ms(w, sys[k]);
			for (int s = 0; s < STEPS; ++s)
				eddy_world_step_frame(w);
			sum[r] = 0;
			for (int k = 0; k < 3; ++k) {
				per[k][r] = (profile_ms(w, sys[k]) - before[k]) * 1e6 / (n * STEPS);
				sum[r] += per[k][r];
			}
		}
		const double total = median(sum, REPS);
		fprintf(f, "%s\n {\"kind\":\"transfers\",\"grid\":32,\"particles\":%.0f,\"threads\":%d,\"ns_per_particle\":{",
		        *first ? "" : ",", n, threads[t]);
		printf("transfers 32^3 half full, %.0f particles, %d thread%s:", n, threads[t], threads[t] > 1 ? "s" : "");
		for (int k = 0; k < 3; ++k) {
			const double m = median(per[k], REPS);
			fprintf(f, "\"%s\":%.1f,", sys[k], m);
			printf(" %s %.1f", sys[k], m);
		}
		fprintf(f, "\"sum\":%.1f}}", total);
		printf(", sum %.1f ns/particle/step (target <= 150 on one thread)\n", total);
		*first = false;
		eddy_destroy_world(w);
	}
}

/* A grid-only pressure world: a custom system writes the fluid mask (lower
 * half fluid) and a pseudo-random velocity field, then flip_pressure solves. */
static eddy_status setup(eddy_world *w, const eddy_step_context *ctx, void *user)
{
	(void)ctx;
	(void)user;
	const eddy_grid_info g = eddy_world_grid(w);
	size_t nc;
	float *phi = eddy_world_channel_mut(w, "flip_phi", &nc);
	uint8_t *type = (uint8_t *)(uintptr_t)eddy_world_channel_u8(w, "cell_type", NULL);
	fixture_random_faces(w, 99);
	for (size_t c = 0; c < nc; ++c) {
		const int j = (int)(c / (size_t)g.nx % (size_t)g.ny);
		const bool fluid = j < g.ny / 2;
		type[c] = fluid ? EDDY_CELL_FLUID : EDDY_CELL_AIR;
		phi[c] = fluid ? -1.0f : 1.0f;
	}
	return EDDY_OK;
}

static void pressure(FILE *f, bool *first)
{
	const int sizes[] = {32, 64};
	const struct {
		eddy_flip_solver solver;
		double tol;
	} runs[] = {{EDDY_FLIP_PCG, 1e-2}, {EDDY_FLIP_PCG, 1e-5}, {EDDY_FLIP_PCG, 1e-8}, {EDDY_FLIP_CHOLMOD, 0}};
	for (int si = 0; si < 2; ++si)
		for (int ri = 0; ri < 4; ++ri)
			for (int threads = 1; threads <= 2; ++threads) {
				const int n = sizes[si];
				const bool chol = runs[ri].solver == EDDY_FLIP_CHOLMOD;
				const int reps = chol ? 3 : 5;
				eddy_world_def d = eddy_default_world_def();
				d.cell_size = 1.0 / n;
				d.threads = threads;
				d.fps = 100;
				d.dt_max = 0.01;
				eddy_world *w = eddy_create_world(&d, NULL, 0);
				static const char *const writes[] = {"u", "v", "w", "cell_type", "flip_phi"};
				eddy_custom_system_def cs = eddy_default_custom_system_def();
				cs.name = "setup";
				cs.writes = writes;
				cs.write_count = 5;
				cs.step = setup;
				eddy_add_custom_system(w, &cs);
				eddy_flip_pressure_def pr = eddy_default_flip_pressure_def();
				pr.solver = runs[ri].solver;
				pr.tolerance = chol ? 1e-6 : runs[ri].tol;
				eddy_add_flip_pressure(w, &pr);
				double t[5], first_ms = NAN, iters = 0;
				bool ok = true;
				for (int r = 0; r < reps && ok; ++r) {
					const double before = profile_ms(w, "flip_pressure");
					ok = eddy_world_step_frame(w) == EDDY_OK;
					t[r] = (profile_ms(w, "flip_pressure") - before) / 1e3;
					if (r == 0)
						first_ms = t[r];
					eddy_frame_stats fs;
					eddy_world_frame_stats(w, &fs);
					for (int k = 0; k < fs.extra_count; ++k)
						if (strcmp(fs.extra[k].name, "iterations") == 0)
							iters = fs.extra[k].value;
				}
				if (!ok) {
					printf("pressure %d^3: %s\n", n, eddy_world_error(w));
					eddy_destroy_world(w);
					continue;
				}
				/* CHOLMOD: the first solve analyses; the others reuse it */
				const double s = chol ? median(t + 1, reps - 1) : median(t, reps);
				fprintf(f,
				        "%s\n "
				        "{\"kind\":\"pressure\",\"grid\":%d,\"unknowns\":%d,\"solver\":\"%s\",\"tolerance\":%g,"
				        "\"threads\":%d,"
				        "\"iterations\":%.0f,\"s_per_solve\":%.4f",
				        *first ? "" : ",", n, n * n * n / 2, chol ? "cholmod" : "pcg", chol ? 0.0 : runs[ri].tol,
				        threads, iters, s);
				if (chol)
					fprintf(f, ",\"s_first_solve_with_analysis\":%.4f", first_ms);
				fprintf(f, "}");
				*first = false;
				printf("pressure %d^3 half full (%d unknowns), %s", n, n * n * n / 2, chol ? "cholmod" : "pcg");
				if (!chol)
					printf("(%g), %.0f iterations", runs[ri].tol, iters);
				printf(", %d thread%s: %.4f s per solve", threads, threads > 1 ? "s" : "", s);
				if (chol)
					printf(" (first, with analysis: %.4f s)", first_ms);
				printf("\n");
				eddy_destroy_world(w);
			}
}

/* Grid-size sweep (eddy issue 17): the pool with a wavy surface and a drop
 * (fixture_wavy_pool, about half the box liquid) at n^3, n = 32, 64, 128,
 * solved by MIC(0)-PCG, HYPRE's PFMG-preconditioned CG and flip_mg.c's
 * multigrid-preconditioned CG to 1e-6, on 1 and 2 threads: iterations and
 * seconds per flip_pressure step (assembly, solve, velocity update), the
 * median of the repeats; and the process CPU time per frame (the solve plus
 * the setup system's fill, the same for every solver), the steadier figure
 * on a shared machine. */
/* Process CPU seconds: on a shared machine a one-thread run's CPU time moves
 * far less than its wall time (it counts all threads: compare 1-thread rows). */
static double cpu_s(void)
{
	struct timespec ts;
	clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
	return (double)ts.tv_sec + (double)ts.tv_nsec * 1e-9;
}

static eddy_status wavy_setup(eddy_world *w, const eddy_step_context *ctx, void *user)
{
	(void)ctx;
	(void)user;
	fixture_random_faces(w, 99);
	fixture_wavy_pool(w);
	return EDDY_OK;
}

static void pressure_sweep(FILE *f, bool *first)
{
	const int sizes[] = {32, 64, 128};
	const eddy_flip_solver solvers[] = {EDDY_FLIP_PCG, EDDY_FLIP_HYPRE, EDDY_FLIP_MG};
	const char *const names[] = {"pcg", "hypre", "mg"};
	for (int si = 0; si < 3; ++si)
		for (int threads = 1; threads <= 2; ++threads)
			for (int sv = 0; sv < 3; ++sv) {
				const int n = sizes[si], reps = n >= 128 ? 3 : 5;
				eddy_world_def d = eddy_default_world_def();
				d.cell_size = 1.0 / n;
				d.threads = threads;
				d.fps = 100;
				d.dt_max = 0.01;
				eddy_world *w = eddy_create_world(&d, NULL, 0);
				static const char *const writes[] = {"u", "v", "w", "cell_type", "flip_phi"};
				eddy_custom_system_def cs = eddy_default_custom_system_def();
				cs.name = "wavy_setup";
				cs.writes = writes;
				cs.write_count = 5;
				cs.step = wavy_setup;
				eddy_add_custom_system(w, &cs);
				eddy_flip_pressure_def pr = eddy_default_flip_pressure_def();
				pr.solver = solvers[sv];
				pr.tolerance = 1e-6;
				eddy_add_flip_pressure(w, &pr);
				/* one solve first: HYPRE's first initialises MPI (once per process) */
				bool ok = eddy_world_step_frame(w) == EDDY_OK;
				double t[5], cpu[5], iters = 0;
				for (int r = 0; r < reps && ok; ++r) {
					const double before = profile_ms(w, "flip_pressure"), c0 = cpu_s();
					ok = eddy_world_step_frame(w) == EDDY_OK;
					cpu[r] = cpu_s() - c0;
					t[r] = (profile_ms(w, "flip_pressure") - before) / 1e3;
					eddy_frame_stats fs;
					eddy_world_frame_stats(w, &fs);
					for (int k = 0; k < fs.extra_count; ++k)
						if (strcmp(fs.extra[k].name, "iterations") == 0)
							iters = fs.extra[k].value;
				}
				if (!ok) {
					printf("pressure sweep %d^3 %s: %s\n", n, names[sv], eddy_world_error(w));
					eddy_destroy_world(w);
					continue;
				}
				size_t nc;
				const uint8_t *type = eddy_world_channel_u8(w, "cell_type", &nc);
				int unknowns = 0;
				for (size_t c = 0; c < nc; ++c)
					unknowns += type[c] == EDDY_CELL_FLUID;
				const double sec = median(t, reps), csec = median(cpu, reps);
				fprintf(f,
				        "%s\n "
				        "{\"kind\":\"pressure_sweep\",\"scene\":\"wavy_pool\",\"grid\":%d,\"unknowns\":%d,\"solver\":"
				        "\"%s\","
				        "\"tolerance\":1e-06,\"threads\":%d,\"iterations\":%.0f,\"s_per_solve\":%.4f,\"cpu_s_per_"
				        "frame\":%.4f}",
				        *first ? "" : ",", n, unknowns, names[sv], threads, iters, sec, csec);
				*first = false;
				printf("pressure sweep, wavy pool %d^3 (%d unknowns), %s(1e-6), %d thread%s: %.0f iterations, %.4f s "
				       "per solve "
				       "(process CPU per frame %.4f s)\n",
				       n, unknowns, names[sv], threads, threads > 1 ? "s" : "", iters, sec, csec);
				fflush(stdout);
				eddy_destroy_world(w);
			}
}

/* the FLIP pour (the paper's jet into a 0.5 m box) in C: the bench links only libeddy. */
static void pour(FILE *f, bool *first)
{
	enum { REPS = 3 };
	double rate[REPS];
	size_t particles = 0;
	for (int r = 0; r < REPS; ++r) {
		eddy_world_def d = eddy_default_world_def();
		d.bounds_max = (eddy_vec3){0.5f, 0.5f, 0.5f};
		d.cell_size = 0.025;
		d.fps = 30;
		d.cfl = 2;
		d.dt_max = 1.0 / 60;
		eddy_world *w = eddy_create_world(&d, NULL, 0);
		eddy_emit_nozzle_def nz = eddy_default_emit_nozzle_def();
		nz.center = (eddy_vec3){0.25f, 0.45f, 0.25f};
		nz.radius = 0.03f;
		nz.direction = (eddy_vec3){0, -1, 0};
		nz.speed = 1.5f;
		nz.spacing = 0.0125f;
		nz.max_particles = 5625;
		eddy_add_emit_nozzle(w, &nz);
		add_pipeline(w, EDDY_FLIP_PCG, 1e-6);
		const double a = now_ms();
		eddy_status st = eddy_world_advance(w, 3.0);
		rate[r] = st == EDDY_OK ? 3.0 / ((now_ms() - a) / 1e3) : 0;
		particles = eddy_world_particle_count(w);
		eddy_destroy_world(w);
	}
	const double m = median(rate, REPS);
	fprintf(f, "%s\n {\"kind\":\"pour\",\"particles\":%zu,\"threads\":1,\"sim_s_per_wall_s\":%.2f}", *first ? "" : ",",
	        particles, m);
	*first = false;
	printf("pour scene, %zu particles, 1 thread: %.2f simulated s per wall s (target >= 5)\n", particles, m);
}

/* Which BLAS CHOLMOD got: Debian's alternatives decide at load time, and the
 * reference BLAS makes the factorisation about 7x slower. */
static const char *blas_in_use(void)
{
	FILE *m = fopen("/proc/self/maps", "r");
	if (!m)
		return "unknown";
	char line[512];
	const char *found = "reference or other";
	while (fgets(line, sizeof line, m))
		if (strstr(line, "openblas")) {
			found = "openblas";
			break;
		}
	fclose(m);
	return found;
}

int main(int argc, char **argv)
{
	const char *path = argc > 1 ? argv[1] : "build/bench_flip.json";
	/* bench_flip FILE sweep: only the pressure grid-size sweep */
	const bool sweep_only = argc > 2 && strcmp(argv[2], "sweep") == 0;
	FILE *f = fopen(path, "w");
	if (!f) {
		fprintf(stderr, "bench_flip: cannot write %s\n", path);
		return 1;
	}
	bool first = true;
	const char *blas = blas_in_use();
	printf("BLAS behind CHOLMOD: %s\n", blas);
	fprintf(f, "{\"benchmark\":\"flip\",\"note\":\"medians; shared, noisy machine\",\"blas\":\"%s\",\"results\":[",
	        blas);
	if (!sweep_only) {
		transfers(f, &first);
		pour(f, &first);
		pressure(f, &first);
	}
	pressure_sweep(f, &first);
	fprintf(f, "\n]}\n");
	fclose(f);
	printf("bench_flip: wrote %s\n", path);
	return 0;
}
