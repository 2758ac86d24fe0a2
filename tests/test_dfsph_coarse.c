/* SPDX-License-Identifier: MIT */
/* sph_dfsph's coarse level (src/sph/dfsph_coarse.c): the conjugate
 * gradients of its solves with the two-level preconditioner reach the same
 * tolerance as with Jacobi alone, in fewer iterations, on a deep column
 * started cold (the whole hydrostatic pressure to build in one step, the
 * case whose iteration count grows with the depth). Iteration counts are
 * deterministic: the assertions are on them, never on time. */
#include "test.h"

#include "eddy.h"

#include <stdint.h>
#include <string.h>

/* A column side x side particles wide and layers deep at spacing 1 cm
 * (h = 2 cm) in a closed tank of boundary particles, at rest; warm: the
 * velocity solve starts from the hydrostatic pressure (hydrostatic_start),
 * else cold. */
static eddy_world *column(int side, int layers, bool coarse, bool warm)
{
	const float dx = 0.01f, W = side * dx, D = layers * dx;
	eddy_world_def d = eddy_default_world_def();
	d.bounds_max = (eddy_vec3){W, 1.5f * D, W};
	d.threads = 1;
	d.fps = 1000;
	d.cfl = 0.5;
	eddy_world *w = eddy_create_world(&d, NULL, 0);
	if (!w)
		return NULL;
	eddy_emit_box_def b = eddy_default_emit_box_def();
	b.max = (eddy_vec3){W, D, W};
	b.spacing = dx;
	eddy_add_emit_box(w, &b);
	eddy_sph_density_def de = eddy_default_sph_density_def();
	de.spacing = dx;
	de.radius = 2 * dx;
	eddy_add_sph_density(w, &de);
	eddy_gravity_def g = eddy_default_gravity_def();
	eddy_add_gravity(w, &g);
	eddy_sph_dfsph_def df = eddy_default_sph_dfsph_def();
	df.coarse_grid = coarse;
	df.hydrostatic_start = warm; /* cold: the whole pressure to build, the coarse level's case */
	eddy_add_sph_dfsph(w, &df);
	eddy_sph_boundary_box_def bb = eddy_default_sph_boundary_box_def();
	bb.max = d.bounds_max;
	bb.spacing = dx;
	eddy_add_sph_boundary_box(w, &bb);
	eddy_integrate_def it = eddy_default_integrate_def();
	eddy_add_integrate(w, &it);
	return w;
}

static double stat(const eddy_frame_stats *st, const char *name)
{
	for (int k = 0; k < st->extra_count; ++k)
		if (strcmp(st->extra[k].name, name) == 0)
			return st->extra[k].value;
	return NAN;
}

typedef struct frame_run {
	double div_it, it, residual, unconverged, p_bottom;
} frame_run;

/* The first frame (the cold start) of a column: its solves' figures and the
 * bottom layer's mean pressure. */
static frame_run first_frame(int side, int layers, bool coarse)
{
	frame_run r = {NAN, NAN, NAN, NAN, NAN};
	eddy_world *w = column(side, layers, coarse, false);
	CHECK(w != NULL);
	if (!w)
		return r;
	const eddy_status st = eddy_world_step_frame(w);
	CHECKF(st == EDDY_OK, "step: %s", eddy_world_error(w));
	eddy_frame_stats fs;
	eddy_world_frame_stats(w, &fs);
	r.div_it = stat(&fs, "divergence_iterations");
	r.it = stat(&fs, "iterations");
	r.residual = stat(&fs, "residual");
	r.unconverged = stat(&fs, "unconverged");
	size_t n = 0;
	const float *y = eddy_world_channel(w, "y", &n), *p = eddy_world_channel(w, "pressure", &n);
	double sum = 0;
	long nb = 0;
	for (size_t i = 0; y && p && i < n; ++i)
		if (y[i] < 0.01f)
			sum += p[i], ++nb;
	r.p_bottom = nb ? sum / nb : NAN;
	eddy_destroy_world(w);
	return r;
}

/* A column 6 x 6 particles wide, 160 layers (1.6 m) deep, from rest: the
 * first frame (two steps) builds the whole hydrostatic pressure. Both paths
 * must reach their tolerance (no step capped: unconverged 0) and leave the
 * same bottom pressure: each is the hydrostatic rho0 g (H - dx/2) within
 * 3% (the bottom layer reads a few % off at every depth, its neighbourhood
 * half wall: tests/test_stress_dfsph.c's BP_BAND is 5%), and the two agree
 * within 0.5%: both stop at the same mean residual, which leaves the
 * column-wide mode an error of about max_divergence_error (D/h)^2
 * depth_scale^2 = 5e-5 * 25 ~ 1e-3 of it (measured 0.1%). The coarse path
 * must take at most 65% of Jacobi's iterations (measured 180 against 334,
 * 0.54), and one step beyond, at 320 layers, at most 55% (341 against 738,
 * 0.46) and a smaller share than at 160: the saving grows with the depth,
 * Jacobi's count growing linearly (the column-wide error falls by 1 - c/N
 * an iteration), the coarse level's with the log of the tightened
 * tolerance and the active set's growth. */
static void deep_column_reaches_the_same_state_in_fewer_iterations(void)
{
	const int layers[2] = {160, 320};
	const double ratio[2] = {0.65, 0.55};
	double share[2] = {NAN, NAN};
	for (int c = 0; c < 2; ++c) {
		const frame_run a = first_frame(6, layers[c], false), b = first_frame(6, layers[c], true);
		const double H = layers[c] * 0.01, p_hyd = 1000 * 9.81 * (H - 0.005);
		printf("    %d layers: divergence iterations %.0f (Jacobi) %.0f (coarse), bottom pressure / hydrostatic "
		       "%.4f %.4f\n",
		       layers[c], a.div_it, b.div_it, a.p_bottom / p_hyd, b.p_bottom / p_hyd);
		CHECK(a.unconverged == 0 && b.unconverged == 0);
		CHECK_NEAR(a.p_bottom / p_hyd, 1, 0.03);
		CHECK_NEAR(b.p_bottom / p_hyd, 1, 0.03);
		CHECK_NEAR(b.p_bottom / a.p_bottom, 1, 0.005);
		CHECKF(b.div_it <= ratio[c] * a.div_it, "%d layers: %.0f iterations with the coarse level, %.0f without",
		       layers[c], b.div_it, a.div_it);
		share[c] = b.div_it / a.div_it;
	}
	CHECK(share[1] < share[0]);
}

/* Below DFSPH_CG_PAR rows the coarse level runs serially: 1 and 2 threads
 * give the same bits (the state hash after two frames of a 40-layer
 * column). */
static void coarse_level_is_deterministic_across_threads(void)
{
	uint64_t hash[2] = {0, 1};
	for (int t = 0; t < 2; ++t) {
		eddy_world *w = column(8, 40, true, false);
		CHECK(w != NULL);
		if (!w)
			return;
		eddy_world_set_threads(w, t + 1);
		for (int f = 0; f < 2; ++f)
			CHECKF(eddy_world_step_frame(w) == EDDY_OK, "step: %s", eddy_world_error(w));
		hash[t] = eddy_world_state_hash(w);
		eddy_destroy_world(w);
	}
	CHECK(hash[0] == hash[1]);
}

/* The threaded path: a pool 150 x 150 particles wide and 12 layers (6 h)
 * deep, 270,000 particles, above sph_dfsph's DFSPH_CG_PAR (2^18 rows), so
 * the coarse level's loops over the rows and over level 0 (77 x 10 x 77
 * cells, above PAR_CELLS) run on the threads; its coarser levels stay
 * serial. The first frame (one step, cold) at 1 and 2 threads: the same
 * state hash; and the coarse level ran: fewer velocity iterations than
 * Jacobi's alone (measured 16 against 29) and another hash. About 2 s of
 * CPU a run. */
static void threaded_coarse_level_gives_the_same_bits(void)
{
	uint64_t hash[3] = {0, 1, 2};
	double div_it[3] = {NAN, NAN, NAN};
	for (int t = 0; t < 3; ++t) { /* coarse at 1 and 2 threads, Jacobi alone at 1 */
		eddy_world *w = column(150, 12, t < 2, false);
		CHECK(w != NULL);
		if (!w)
			return;
		eddy_world_set_threads(w, t == 1 ? 2 : 1);
		CHECKF(eddy_world_step_frame(w) == EDDY_OK, "step: %s", eddy_world_error(w));
		eddy_frame_stats fs;
		eddy_world_frame_stats(w, &fs);
		div_it[t] = stat(&fs, "divergence_iterations");
		hash[t] = eddy_world_state_hash(w);
		eddy_destroy_world(w);
	}
	printf("    270k particles: hash %016llx (1 thread) %016llx (2), velocity iterations %.0f; Jacobi alone %.0f "
	       "(hash %016llx)\n",
	       (unsigned long long)hash[0], (unsigned long long)hash[1], div_it[0], div_it[2], (unsigned long long)hash[2]);
	CHECK(hash[0] == hash[1]);
	CHECK(div_it[0] == div_it[1]);
	CHECK(div_it[0] < div_it[2] && hash[0] != hash[2]);
}

/* Shallow water (5 kernel radii or less): the coarse level stays off and
 * the run is the same, bit for bit, as without it. */
static void shallow_water_is_unchanged(void)
{
	uint64_t hash[2] = {0, 1};
	for (int c = 0; c < 2; ++c) {
		eddy_world *w = column(8, 9, c == 1, false); /* 9 cm deep, h = 2 cm */
		CHECK(w != NULL);
		if (!w)
			return;
		for (int f = 0; f < 2; ++f)
			CHECKF(eddy_world_step_frame(w) == EDDY_OK, "step: %s", eddy_world_error(w));
		hash[c] = eddy_world_state_hash(w);
		eddy_destroy_world(w);
	}
	CHECK(hash[0] == hash[1]);
}

void suite_dfsph_coarse(void)
{
	RUN(deep_column_reaches_the_same_state_in_fewer_iterations);
	RUN(coarse_level_is_deterministic_across_threads);
	RUN(threaded_coarse_level_gives_the_same_bits);
	RUN(shallow_water_is_unchanged);
}
