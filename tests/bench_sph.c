/* SPDX-License-Identifier: MIT */
#define _POSIX_C_SOURCE 200809L
/* SPH benchmarks (make bench; not part of make test), as JSON:
 *  - ns per particle per step of sph_density (neighbour search included),
 *    sph_pressure and sph_viscosity, for 5k / 30k / 100k particles at
 *    h = 2 spacings, on 1 and 2 threads: a block settling in a tank, one
 *    world per thread count, measured in turns so that the speed-up is a
 *    median of paired ratios; then the same blocks with sph_dfsph (rows
 *    "solver":"dfsph": sph_density, sph_viscosity and sph_dfsph);
 *  - the pour scene of scenes/pour.lua (5625 particles, one thread) with
 *    the implicit solve (sph_dfsph, the scene's default) and with WCSPH:
 *    simulated seconds per wall second, the density error, the mean
 *    compression and the solver's iterations per step (one run each).
 * Options after the output file: --no-pour (the blocks only),
 * --wcsph-blocks or --dfsph-blocks (one solver's blocks only), --pour-only.
 * Every figure is the median of repeated runs: the machine is shared, and a
 * neighbour's job shows up as outliers. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "eddy.h"
#include "bench_util.h"

/* A cube of about n particles on the lattice, resting on the floor of a tank
 * twice as wide, with gravity: the neighbourhoods of a real fluid. A block
 * this calm seldom moves a particle by half the Verlet skin, so this times
 * mostly the filtered-list path (src/sph/neighbors.c); a dam break runs the grid
 * search every few steps. dfsph: sph_dfsph at its defaults (both solves)
 * after gravity and viscosity, instead of sph_pressure with k = 400. */
static eddy_world *block(int n, int threads, bool dfsph)
{
	const float dx = 0.01f,
				side = dx * (roundf(cbrtf((float)n)) + 0.5f); /* + 0.5: a whole number of spacings after floor */
	eddy_world_def d = eddy_default_world_def();
	d.bounds_max = (eddy_vec3){2 * side, 1.5f * side, 2 * side};
	d.threads = threads;
	d.fps = 1000;
	eddy_world *w = eddy_create_world(&d, NULL, 0);
	eddy_emit_box_def b = eddy_default_emit_box_def();
	b.min = (eddy_vec3){0.5f * side, 0, 0.5f * side};
	b.max = (eddy_vec3){1.5f * side, side, 1.5f * side};
	b.spacing = dx;
	eddy_add_emit_box(w, &b);
	eddy_sph_density_def de = eddy_default_sph_density_def();
	de.spacing = dx;
	de.radius = 2 * dx;
	de.stiffness = 400;
	eddy_add_sph_density(w, &de);
	const eddy_sph_dfsph_def df = eddy_default_sph_dfsph_def();
	bench_add_sph_forces(w, dfsph ? &df : NULL);
	eddy_integrate_def it = eddy_default_integrate_def();
	eddy_add_integrate(w, &it);
	eddy_collide_box_def bx = eddy_default_collide_box_def();
	bx.max = d.bounds_max;
	bx.sph_walls = false; /* the block's benchmark has kept a bare tank: its figures compare across builds */
	eddy_add_collide_box(w, &bx);
	return w;
}

/* scenes/pour.lua in C (the benchmark links the engine only): solver
 * "dfsph" (sph_dfsph after gravity and viscosity, CFL 1, no divergence
 * solve: the scene's default) or "wcsph" (sph_pressure with stiffness k,
 * CFL 0.4). */
static eddy_world *pour(const char *solver, float stiffness)
{
	const bool dfsph = strcmp(solver, "dfsph") == 0;
	const float dx = 0.01f, L = 0.2f, H = 0.3f;
	eddy_world_def d = eddy_default_world_def();
	d.bounds_max = (eddy_vec3){L, H, L};
	d.fps = 30;
	d.cfl = dfsph ? 1.0 : 0.4;
	d.threads = 1;
	eddy_world *w = eddy_create_world(&d, NULL, 0);
	eddy_emit_nozzle_def nz = eddy_default_emit_nozzle_def();
	nz.center = (eddy_vec3){L / 2, H - 0.04f, L / 2};
	nz.radius = 0.03f;
	nz.direction = (eddy_vec3){0, -1, 0};
	nz.speed = 1;
	nz.spacing = dx;
	nz.max_particles = 5625;
	eddy_add_emit_nozzle(w, &nz);
	eddy_sph_density_def de = eddy_default_sph_density_def();
	de.spacing = dx;
	de.radius = 2 * dx;
	de.stiffness = stiffness;
	eddy_add_sph_density(w, &de);
	eddy_sph_dfsph_def df = eddy_default_sph_dfsph_def();
	df.max_density_error = 0.01f; /* the scene's: the mean compression stays under 2% */
	df.divergence_solver = false;
	bench_add_sph_forces(w, dfsph ? &df : NULL);
	eddy_sph_boundary_box_def bb = eddy_default_sph_boundary_box_def();
	bb.max = d.bounds_max;
	bb.spacing = dx;
	eddy_add_sph_boundary_box(w, &bb);
	eddy_integrate_def it = eddy_default_integrate_def();
	eddy_add_integrate(w, &it);
	eddy_collide_box_def bx = eddy_default_collide_box_def();
	bx.max = d.bounds_max;
	eddy_add_collide_box(w, &bx);
	return w;
}

static double extra_stat(const eddy_frame_stats *st, const char *name)
{
	for (int k = 0; k < st->extra_count; ++k)
		if (strcmp(st->extra[k].name, name) == 0)
			return st->extra[k].value;
	return 0;
}

/* Pours of the scene's 4 s (the jet ends at 2.0 s) on one thread, reps
 * times: the runs are identical but for the clock, so the rates are the
 * medians and the rest is the last run's; one JSON row. Rates: over the
 * whole scene; over the first 2.5 s; from the frame the last particle is in
 * to 2.5 s (the pool at its busiest). The errors and counts are over the
 * first 2.5 s. Returns false on a failed step. */
static bool pour_row(FILE *f, bool first, const char *solver, float stiffness, int reps)
{
	double rates[9], rates_full[9], rates_scene[9];
	reps = reps < 1 ? 1 : reps > 9 ? 9 : reps;
	for (int r = 0; r < reps; ++r) {
		eddy_world *w = pour(solver, stiffness);
		const double a = now_ms();
		double err_avg_full = 0, err_max_full = 0, comp_full = 0, full_start = 0, full_sim = 0, sweeps = 0,
			   div_sweeps = 0;
		double wall = 0, wall_full = 0, sim_full = 0;
		int full_frames = 0;
		int64_t steps = 0;
		while (eddy_world_time(w) < 4.0 - 1e-9) {
			if (eddy_world_step_frame(w) != EDDY_OK) {
				fprintf(stderr, "bench_sph: pour (%s): %s\n", solver, eddy_world_error(w));
				eddy_destroy_world(w);
				return false;
			}
			if (eddy_world_time(w) > 2.5 + 1e-9)
				continue; /* the rest of the scene is timed only */
			eddy_frame_stats st;
			eddy_world_frame_stats(w, &st);
			if (eddy_world_time(w) > 2.5 - 1e-9) {
				wall = (now_ms() - a) / 1e3;
				wall_full = (now_ms() - full_start) / 1e3;
				sim_full = eddy_world_time(w) - full_sim;
			}
			steps += st.steps;
			sweeps += extra_stat(&st, "iterations") * (double)st.steps;
			div_sweeps += extra_stat(&st, "divergence_iterations") * (double)st.steps;
			if (st.particles == 5625) {
				if (!full_frames) {
					full_start = now_ms();
					full_sim = eddy_world_time(w);
				}
				full_frames++;
				err_avg_full = fmax(err_avg_full, st.density_err_avg);
				err_max_full = fmax(err_max_full, st.density_err_max);
				comp_full = fmax(comp_full, st.density_compression_avg);
			}
		}
		rates_scene[r] = eddy_world_time(w) / ((now_ms() - a) / 1e3);
		rates[r] = 2.5 / wall;
		rates_full[r] = sim_full / wall_full;
		if (r + 1 < reps) {
			eddy_destroy_world(w);
			continue;
		}
		qsort(rates, (size_t)reps, sizeof rates[0], cmp_double);
		qsort(rates_full, (size_t)reps, sizeof rates_full[0], cmp_double);
		qsort(rates_scene, (size_t)reps, sizeof rates_scene[0], cmp_double);
		const double rate = rates[reps / 2], rate_full = rates_full[reps / 2], rate_scene = rates_scene[reps / 2];
		printf(
			"pour %s (5625 particles, %s, 1 thread, median of %d): %.3f simulated s per wall s over the scene's 4 s, "
			"%.3f over the first 2.5 s, %.3f with all particles in; "
			"%lld steps (mean dt %.2g s); density error avg %.4f (max over frames with all particles in), max %.3f "
			"(surface particles), mean compression %.5f; %.2f iterations per step (+ %.2f divergence)\n",
			solver, strcmp(solver, "dfsph") == 0 ? "tolerance 0.01" : "k = 400", reps, rate_scene, rate, rate_full,
			(long long)steps, 2.5 / (double)steps, err_avg_full, err_max_full, comp_full, sweeps / (double)steps,
			div_sweeps / (double)steps);
		fprintf(f,
		        "%s\n {\"scene\":\"pour\",\"solver\":\"%s\",\"particles\":5625,\"stiffness\":%.0f,\"threads\":1,"
		        "\"sim_s_per_wall_s_scene\":%.4f,\"sim_s_per_wall_s\":%.4f,\"sim_s_per_wall_s_full\":%.4f,"
		        "\"steps\":%lld,\"density_err_avg\":%.4f,"
		        "\"density_err_max\":%.4f,\"compression_avg\":%.5f,\"iterations_per_step\":%.3f,"
		        "\"divergence_iterations_per_step\":%.3f}",
		        first ? "" : ",", solver, (double)stiffness, rate_scene, rate, rate_full, (long long)steps,
		        err_avg_full, err_max_full, comp_full, sweeps / (double)steps, div_sweeps / (double)steps);
		eddy_destroy_world(w);
	}
	return true;
}

enum { REPS = 9, STEPS = 5 };

/* The profile time (ms) of each system named in names[0..3) so far. */
static void profile_ms(eddy_world *w, const char *const names[3], double ms[3])
{
	for (int k = 0; k < eddy_world_system_count(w); ++k) {
		eddy_system_info info;
		eddy_world_system_info(w, eddy_world_system_at(w, k), &info);
		for (int q = 0; q < 3; ++q)
			if (strcmp(info.name, names[q]) == 0)
				ms[q] = info.profile_ms;
	}
}

/* The block rows of one solver: for each size, the same block on 1 and on 2
 * threads, measured in turns (the host's load drifts over seconds, so a
 * ratio of runs made minutes apart measures the host as much as the code).
 * *first: no row written yet. False if a step failed. */
static bool block_rows(FILE *f, bool *first, bool dfsph)
{
	const int counts[] = {5000, 30000, 100000};
	const char *const wcsph_names[3] = {"sph_density", "sph_pressure", "sph_viscosity"};
	const char *const dfsph_names[3] = {"sph_density", "sph_viscosity", "sph_dfsph"};
	const char *const *names = dfsph ? dfsph_names : wcsph_names;
	const char *solver = dfsph ? "dfsph" : "wcsph";
	for (size_t c = 0; c < 3; ++c) {
		eddy_world *w[2] = {block(counts[c], 1, dfsph), block(counts[c], 2, dfsph)};
		for (int t = 0; t < 2; ++t)
			for (int s = 0; s < 3; ++s)
				eddy_world_step_frame(w[t]); /* emit, then settle the first kick */
		const size_t n = eddy_world_particle_count(w[0]);
		double per[2][3][REPS], sum[2][REPS], ratio[REPS];
		for (int r = 0; r < REPS; ++r) {
			for (int t = 0; t < 2; ++t) {
				double before[3] = {0}, after[3] = {0};
				profile_ms(w[t], names, before);
				for (int s = 0; s < STEPS; ++s)
					if (eddy_world_step(w[t]) != EDDY_OK) {
						fprintf(stderr, "bench_sph: %s\n", eddy_world_error(w[t]));
						return false;
					}
				profile_ms(w[t], names, after);
				sum[t][r] = 0;
				for (int q = 0; q < 3; ++q) {
					per[t][q][r] = (after[q] - before[q]) * 1e6 / ((double)n * STEPS);
					sum[t][r] += per[t][q][r];
				}
			}
			ratio[r] = sum[0][r] / sum[1][r];
		}
		qsort(ratio, REPS, sizeof ratio[0], cmp_double);
		for (int t = 0; t < 2; ++t) {
			qsort(sum[t], REPS, sizeof sum[t][0], cmp_double);
			for (int q = 0; q < 3; ++q)
				qsort(per[t][q], REPS, sizeof per[t][q][0], cmp_double);
			/* WCSPH's rows keep the key they always had */
			fprintf(f, "%s\n {\"solver\":\"%s\",\"particles\":%zu,\"threads\":%d,\"%s\":%.1f,\"systems\":{",
			        *first ? "" : ",", solver, n, t + 1, dfsph ? "sph_ns" : "density_pressure_viscosity_ns",
			        sum[t][REPS / 2]);
			*first = false;
			printf("%s %7zu particles, %d thread%s: %7.1f ns/particle/step (", solver, n, t + 1, t ? "s" : " ",
			       sum[t][REPS / 2]);
			for (int q = 0; q < 3; ++q) {
				fprintf(f, "%s\"%s\":%.1f", q ? "," : "", names[q], per[t][q][REPS / 2]);
				printf("%s%s %.1f", q ? ", " : "", names[q], per[t][q][REPS / 2]);
			}
			fprintf(f, "}}");
			if (t == 1) {
				fprintf(f, ",\n {\"solver\":\"%s\",\"particles\":%zu,\"speedup_2_threads\":%.2f}", solver, n,
				        ratio[REPS / 2]);
				printf("; speed-up %.2fx, median of paired runs", ratio[REPS / 2]);
			}
			printf(")\n");
		}
		eddy_destroy_world(w[0]);
		eddy_destroy_world(w[1]);
	}
	return true;
}

int main(int argc, char **argv)
{
	const char *path = argc > 1 ? argv[1] : "build/bench_sph.json";
	FILE *f = fopen(path, "w");
	if (!f) {
		fprintf(stderr, "bench_sph: cannot write %s\n", path);
		return 1;
	}
	fprintf(f,
	        "{\"benchmark\":\"sph\",\"unit\":\"ns per particle per step\",\"note\":\"medians of %d runs of %d steps, "
	        "1 and 2 threads alternating; the speed-up is the median of the paired ratios; shared 2-core machine\","
	        "\"results\":[",
	        REPS, STEPS);
	const char *opt = argc > 2 ? argv[2] : "";
	const bool pour_only = strcmp(opt, "--pour-only") == 0;
	bool first = true;
	if (!pour_only && strcmp(opt, "--dfsph-blocks") != 0 && !block_rows(f, &first, false))
		return 1;
	if (!pour_only && strcmp(opt, "--wcsph-blocks") != 0 && !block_rows(f, &first, true))
		return 1;
	if (strcmp(opt, "--no-pour") == 0 || strcmp(opt, "--wcsph-blocks") == 0 || strcmp(opt, "--dfsph-blocks") == 0) {
		fprintf(f, "\n]}\n");
		fclose(f);
		return 0;
	}
	/* the pour: the implicit solve (the scene's default), then WCSPH */
	if (!pour_row(f, first, "dfsph", 400, 5) || !pour_row(f, false, "wcsph", 400, 1))
		return 1;
	fprintf(f, "\n]}\n");
	fclose(f);
	printf("bench_sph: wrote %s\n", path);
	return 0;
}
