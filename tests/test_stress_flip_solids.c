/* SPDX-License-Identifier: MIT */
#define _POSIX_C_SOURCE 200809L
/* FLIP stress cases one step beyond the validated scenes (issue "Stable and
 * conservative one step beyond the tested scenes", items 2 and 5): a sphere
 * collider lowered into a pool and moved through it (fractional solid faces,
 * Batty, Bertails & Bridson 2007), a still sphere, and the volume of a drop
 * falling into a pool and of a dam break with reseeding on.
 *
 * The water level is measured on the grid, as flip_pressure sees the surface:
 * in every column the height of the top zero crossing of flip_phi (linear
 * between cell centres), averaged over the columns. With no air trapped under
 * the surface this mean is (water volume + submerged solid volume) / tank
 * area, the geometric expectation the tests compare with. */
#include "test.h"

#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "eddy.h"
#include "flip_pool.h"

static double now_ms(void)
{
	struct timespec t;
	clock_gettime(CLOCK_MONOTONIC, &t);
	return t.tv_sec * 1e3 + t.tv_nsec / 1e6;
}

static bool step_frames(eddy_world *w, int frames)
{
	for (int f = 0; f < frames; ++f) {
		eddy_status st = eddy_world_step_frame(w);
		if (st != EDDY_OK) {
			test_fail(__FILE__, __LINE__, "step: %s", eddy_world_error(w));
			return false;
		}
	}
	return true;
}

/* ---- the moving sphere -------------------------------------------------------
 * Tank 0.2 x 0.3 x 0.125 m, pool 0.15 m deep, dx = 1.25 cm (8 particles per
 * cell, ~15k particles); a 4 cm sphere starts with its centre 0.22 m up,
 * is lowered at 0.28 m/s to 0.08 m (fully submerged, top 3 cm under the
 * surface), then oscillates along x with amplitude 5 cm at 2 Hz (peak speed
 * 0.63 m/s, the case) and stops; the water settles. */
enum { MOVE_STILL, MOVE_LOWER, MOVE_LOWER_OSCILLATE };

typedef struct sphere_motion {
	int kind;
	eddy_system_id sphere;
	double t_lower, t_osc; /* s, end of the lowering, end of the oscillation */
} sphere_motion;

static const double SPH_R = 0.04, SPH_X = 0.1, SPH_Z = 0.06, SPH_Y0 = 0.22, SPH_Y1 = 0.08, OSC_A = 0.05,
					OSC_W = 4 * 3.14159265358979; /* rad/s: 2 Hz */

static eddy_vec3 sphere_offset(const sphere_motion *m, double t)
{
	if (m->kind == MOVE_STILL)
		return (eddy_vec3){0, 0, 0};
	const double drop = SPH_Y1 - SPH_Y0;
	const double dy = t < m->t_lower ? drop * t / m->t_lower : drop;
	double dx = 0;
	if (m->kind == MOVE_LOWER_OSCILLATE && t > m->t_lower) {
		const double tau = (t < m->t_osc ? t : m->t_osc) - m->t_lower;
		dx = OSC_A * sin(OSC_W * tau);
	}
	return (eddy_vec3){(float)dx, (float)dy, 0};
}

static eddy_status move_sphere(eddy_world *w, const eddy_step_context *ctx, void *user)
{
	const sphere_motion *m = user;
	return eddy_collider_set_offset(w, m->sphere, sphere_offset(m, ctx->time + ctx->dt));
}

typedef struct sphere_result {
	double level, expected, worst_inside; /* m, m, worst signed distance / dx */
	size_t n0, n1;
	double ms;
	uint64_t hash;
	float *y; /* n1 heights at the end (caller frees) */
} sphere_result;

static int sphere_threads = 1;
/* false: the host sets the offset before the pipeline (a custom system
 * first); true: after flip_advect, just before the collider, as a scene's
 * offset function does (eddy_lua.c): the case */
static bool sphere_late = false;

static void run_sphere(int kind, bool reseed, eddy_flip_solver solver, double seconds, sphere_result *res)
{
	const double h = 0.0125, depth = 0.15;
	const eddy_vec3 lo = {0, 0, 0}, hi = {0.2f, 0.3f, 0.125f};
	sphere_motion m = {kind, EDDY_NULL_SYSTEM, 0.5, 0.5 + 1.5};
	eddy_world_def wd = eddy_default_world_def();
	wd.bounds_min = lo;
	wd.bounds_max = hi;
	wd.cell_size = h;
	wd.cfl = 1;
	wd.dt_max = 1.0 / 60;
	wd.fps = 30;
	eddy_world *w = eddy_create_world(&wd, NULL, 0);
	CHECK(w != NULL);
	if (!w)
		return;
	CHECK(eddy_world_set_threads(w, sphere_threads) == EDDY_OK);
	eddy_custom_system_def cs = eddy_default_custom_system_def();
	cs.name = "mover";
	cs.step = move_sphere;
	cs.user = &m;
	if (!sphere_late)
		CHECK(eddy_system_valid(w, eddy_add_custom_system(w, &cs)));
	flip_defs fd = flip_default_defs();
	fd.pressure.solver = solver;
	CHECK(flip_add_pipeline(w, &fd));
	if (sphere_late)
		CHECK(eddy_system_valid(w, eddy_add_custom_system(w, &cs)));
	eddy_collide_sphere_def sp = eddy_default_collide_sphere_def();
	const double yc = kind == MOVE_STILL ? SPH_Y1 : SPH_Y0;
	sp.center = (eddy_vec3){(float)SPH_X, (float)yc, (float)SPH_Z};
	sp.radius = (float)SPH_R;
	m.sphere = eddy_add_collide_sphere(w, &sp);
	CHECK(eddy_system_valid(w, m.sphere));
	if (reseed) {
		eddy_flip_reseed_def rs = eddy_default_flip_reseed_def();
		CHECK(eddy_system_valid(w, eddy_add_flip_reseed(w, &rs)));
	}
	if (kind == MOVE_STILL) {
		/* the pool around the sphere, filled to the level the sphere raises */
		const double lev = depth + 4.0 / 3 * 3.14159265358979 * SPH_R * SPH_R * SPH_R / (0.2 * 0.125);
		const int nx = (int)lround(0.2 / h * 2), ny = (int)lround(lev / h * 2), nz = (int)lround(0.125 / h * 2);
		eddy_vec3 *q = malloc((size_t)nx * ny * nz * sizeof *q);
		size_t n = 0;
		for (int k = 0; k < nz; ++k)
			for (int j = 0; j < ny; ++j)
				for (int i = 0; i < nx; ++i) {
					const eddy_vec3 pt = {(float)((i + 0.5) * h / 2), (float)((j + 0.5) * h / 2),
					                      (float)((k + 0.5) * h / 2)};
					const double dxp = pt.x - SPH_X, dyp = pt.y - SPH_Y1, dzp = pt.z - SPH_Z;
					if (sqrt(dxp * dxp + dyp * dyp + dzp * dzp) >= SPH_R)
						q[n++] = pt;
				}
		CHECK(eddy_world_add_particles(w, n, q, NULL) == EDDY_OK);
		free(q);
	} else {
		CHECK(pool_fill(w, h, lo, (eddy_vec3){0.2f, (float)depth, 0.125f}));
	}
	res->n0 = eddy_world_particle_count(w);
	res->worst_inside = 0;
	const double t0 = now_ms();
	const int frames = (int)lround(seconds * wd.fps);
	int f = 0;
	for (; f < frames; ++f) {
		if (!step_frames(w, 1))
			break;
		/* no particle inside the solid */
		const eddy_vec3 off = sphere_offset(&m, eddy_world_time(w));
		size_t n;
		const float *x = eddy_world_channel(w, "x", &n), *y = eddy_world_channel(w, "y", NULL),
					*z = eddy_world_channel(w, "z", NULL);
		for (size_t i = 0; i < n; ++i) {
			const double dxp = x[i] - (SPH_X + off.x), dyp = y[i] - (yc + off.y), dzp = z[i] - (SPH_Z + off.z);
			const double sd = (sqrt(dxp * dxp + dyp * dyp + dzp * dzp) - SPH_R) / h;
			res->worst_inside = sd < res->worst_inside ? sd : res->worst_inside;
		}
	}
	res->ms = now_ms() - t0;
	CHECK(f == frames);
	res->level = pool_mean_level(w);
	/* pool plus submerged sphere over the tank area (the still sphere's pool
	 * was filled to that level around it) */
	res->expected = depth + 4.0 / 3 * 3.14159265358979 * SPH_R * SPH_R * SPH_R / (0.2 * 0.125);
	res->n1 = eddy_world_particle_count(w);
	res->hash = eddy_world_state_hash(w);
	res->y = malloc(res->n1 * sizeof *res->y + 1);
	memcpy(res->y, eddy_world_channel(w, "y", NULL), res->n1 * sizeof *res->y);
	eddy_frame_stats fs;
	eddy_world_frame_stats(w, &fs);
	CHECK(fs.nonfinite == 0);
	eddy_destroy_world(w);
}

/* (a) Lowered, then moved back and forth at up to 0.63 m/s for 1.5 s, then
 * 1 s to settle. The level must end within 3% of the expectation: the
 * surface still carries waves after 1 s (their mean over the columns is zero
 * to first order) and the grid places the surface to a fraction of a cell
 * (dx = 1.25 cm is 8% of the depth; the level is its mean over 160 columns,
 * which the still pool below resolves to ~1%). No particle may be inside the
 * solid by more than 0.1 dx at any frame (the collider projects them out at
 * every step; 0.1 dx leaves room for the float round-off of the projection). */
static void sphere_lowered_and_oscillated_keeps_level(void)
{
	for (int late = 0; late < 2; ++late) {
		sphere_result r;
		sphere_late = late;
		run_sphere(MOVE_LOWER_OSCILLATE, true, EDDY_FLIP_PCG, 3.0, &r);
		sphere_late = false;
		const double err = (r.level - r.expected) / r.expected;
		printf("    sphere lowered + oscillated (0.63 m/s, 1.5 s), offset set %s, reseed on: level %.4f m, expected "
		       "%.4f m (%+.2f%%); particles %zu -> %zu; deepest particle %.3f dx inside; %.1f s\n",
		       late ? "after advect (offset function)" : "first", r.level, r.expected, 100 * err, r.n0, r.n1,
		       -r.worst_inside, r.ms / 1000);
		CHECK(fabs(err) <= 0.03);
		CHECK(r.worst_inside > -0.1);
		free(r.y);
	}
}

/* (a') Lowered only (no oscillation): the issue measured -6% here. */
static void sphere_lowered_keeps_level(void)
{
	sphere_result r;
	run_sphere(MOVE_LOWER, true, EDDY_FLIP_PCG, 1.5, &r);
	const double err = (r.level - r.expected) / r.expected;
	printf("    sphere lowered, reseed on: level %.4f m, expected %.4f m (%+.2f%%); particles %zu -> %zu; "
	       "deepest particle %.3f dx inside; %.1f s\n",
	       r.level, r.expected, 100 * err, r.n0, r.n1, -r.worst_inside, r.ms / 1000);
	CHECK(fabs(err) <= 0.03);
	CHECK(r.worst_inside > -0.1);
	free(r.y);
}

/* (b) A still sphere in a pool at rest: the level stays where it was filled. */
static void still_sphere_keeps_level(void)
{
	sphere_result r;
	run_sphere(MOVE_STILL, true, EDDY_FLIP_PCG, 1.5, &r);
	const double err = (r.level - r.expected) / r.expected;
	printf("    still sphere, reseed on: level %.4f m, expected %.4f m (%+.2f%%); particles %zu -> %zu; %.1f s\n",
	       r.level, r.expected, 100 * err, r.n0, r.n1, r.ms / 1000);
	CHECK(fabs(err) <= 0.02);
	CHECK(r.worst_inside > -0.1);
	free(r.y);
}

/* PCG and CHOLMOD solve the same weighted system: over 0.6 s of the sphere
 * going down (cut cells, solid flux, volume correction all active) the
 * particles end where the other solver put them, to round-off amplified by
 * the flow (PCG stops at 1e-6 relative residual: bound 0.01 dx). */
static void solvers_agree_with_moving_sphere(void)
{
	sphere_result p, c;
	run_sphere(MOVE_LOWER, false, EDDY_FLIP_PCG, 0.6, &p);
	run_sphere(MOVE_LOWER, false, EDDY_FLIP_CHOLMOD, 0.6, &c);
	CHECK(p.n1 == c.n1);
	double worst = 0;
	for (size_t i = 0; i < p.n1 && p.n1 == c.n1; ++i)
		worst = fmax(worst, fabs((double)p.y[i] - (double)c.y[i]));
	printf("    moving sphere, PCG vs CHOLMOD after 0.6 s: max |y_pcg - y_cholmod| = %.3g dx, levels %.5f / %.5f m\n",
	       worst / 0.0125, p.level, c.level);
	CHECK(worst <= 0.01 * 0.0125);
	free(p.y);
	free(c.y);
}

/* Determinism: the same state hash with 1 and 2 threads, solids moving. */
static void threads_agree_with_moving_sphere(void)
{
	sphere_result a, b;
	sphere_threads = 1;
	run_sphere(MOVE_LOWER_OSCILLATE, true, EDDY_FLIP_PCG, 0.7, &a);
	sphere_threads = 2;
	run_sphere(MOVE_LOWER_OSCILLATE, true, EDDY_FLIP_PCG, 0.7, &b);
	sphere_threads = 1;
	CHECK(a.hash == b.hash);
	free(a.y);
	free(b.y);
}

/* ---- volume with reseeding: a drop into a pool, a dam break ----------------- */

typedef struct volume_result {
	double worst, final; /* max |V - V0| / V0 over the frames, and at the end */
	size_t n0, n1;
	double ms;
} volume_result;

/* The standard pipeline in a closed tank (the domain's sides), reseeding on;
 * a box collider as the tank when tank_collider (the solids' code path). */
static eddy_world *volume_world(double h, eddy_vec3 hi, bool reseed)
{
	eddy_world_def wd = eddy_default_world_def();
	wd.bounds_max = hi;
	wd.cell_size = h;
	wd.cfl = 1;
	wd.dt_max = 1.0 / 60;
	wd.fps = 30;
	eddy_world *w = eddy_create_world(&wd, NULL, 0);
	CHECK(w != NULL);
	if (!w)
		return NULL;
	const flip_defs fd = flip_default_defs();
	CHECK(flip_add_pipeline(w, &fd));
	if (reseed) {
		eddy_flip_reseed_def rs = eddy_default_flip_reseed_def();
		CHECK(eddy_system_valid(w, eddy_add_flip_reseed(w, &rs)));
	}
	return w;
}

static void run_volume(eddy_world *w, double v0, int frames, volume_result *r)
{
	r->n0 = eddy_world_particle_count(w);
	r->worst = 0;
	const double t0 = now_ms();
	int f = 0;
	for (; f < frames; ++f) {
		if (!step_frames(w, 1))
			break;
		eddy_frame_stats fs;
		eddy_world_frame_stats(w, &fs);
		r->final = (fs.volume - v0) / v0;
		r->worst = fmax(r->worst, fabs(r->final));
	}
	r->ms = now_ms() - t0;
	CHECK(f == frames);
	r->n1 = eddy_world_particle_count(w);
}

/* A 5 cm cube of water falls 10 cm into a 8 cm pool (tank 0.2 x 0.3 x 0.1 m,
 * dx = 1.25 cm), 2 s. */
static void drop_into_pool_volume(void)
{
	const double h = 0.0125;
	for (int rs = 0; rs < 2; ++rs) {
		eddy_world *w = volume_world(h, (eddy_vec3){0.2f, 0.3f, 0.1f}, rs == 1);
		if (!w)
			return;
		CHECK(pool_fill(w, h, (eddy_vec3){0, 0, 0}, (eddy_vec3){0.2f, 0.08f, 0.1f}));
		CHECK(pool_fill(w, h, (eddy_vec3){0.075f, 0.175f, 0.025f}, (eddy_vec3){0.125f, 0.225f, 0.075f}));
		volume_result r;
		run_volume(w, 0.2 * 0.08 * 0.1 + 0.05 * 0.05 * 0.05, 60, &r);
		printf("    drop into pool, reseed %s: max |V - V0| / V0 = %.2f%%, at 2 s %+.2f%%; particles %zu -> %zu "
		       "(%+.1f%%); %.1f s\n",
		       rs ? "on" : "off", 100 * r.worst, 100 * r.final, r.n0, r.n1,
		       100.0 * ((double)r.n1 - (double)r.n0) / (double)r.n0, r.ms / 1000);
		/* settled (2 s): the grid volume is the marker's, which places the
		 * surface to about half a cell: 0.5 dx over the final depth
		 * (8.6 cm) is 7.2%. While it splashes the marker counts spray cells
		 * whole (the max above reaches 13% with reseeding off too), so only
		 * the end is checked. Reseeding moves particles and never deletes
		 * them. */
		CHECK(fabs(r.final) <= 0.5 * h / (0.08 + 0.05 * 0.05 * 0.05 / (0.2 * 0.1)));
		CHECK(r.n1 == r.n0);
		eddy_destroy_world(w);
	}
}

/* Martin & Moyce's column (a = 5 cm, 2a high) in a 4a x 2.5a tank, dx = a/8,
 * 1.5 s (several reflections off the far wall). */
static void dam_break_volume(void)
{
	const double a = 0.05, h = a / 8;
	for (int rs = 0; rs < 2; ++rs) {
		eddy_world *w = volume_world(h, (eddy_vec3){(float)(4 * a), (float)(2.5 * a), (float)(4 * h)}, rs == 1);
		if (!w)
			return;
		CHECK(pool_fill(w, h, (eddy_vec3){0, 0, 0}, (eddy_vec3){(float)a, (float)(2 * a), (float)(4 * h)}));
		volume_result r;
		run_volume(w, a * 2 * a * 4 * h, 45, &r);
		printf(
			"    dam break, reseed %s: max |V - V0| / V0 = %.2f%%, at 1.5 s %+.2f%%; particles %zu -> %zu (%+.1f%%); "
			"%.1f s\n",
			rs ? "on" : "off", 100 * r.worst, 100 * r.final, r.n0, r.n1,
			100.0 * ((double)r.n1 - (double)r.n0) / (double)r.n0, r.ms / 1000);
		/* at 1.5 s the water still sloshes in a layer a/2 = 2.5 cm deep (4
		 * cells): half a cell of surface placement is 12.5%. Reseeding moves
		 * particles and never deletes them (flip_reseed; the volume's own
		 * bounds are tests/test_stress_flip_volume.c's). */
		CHECK(fabs(r.final) <= 0.5 * h / (a / 2));
		CHECK(r.n1 == r.n0);
		eddy_destroy_world(w);
	}
}

/* flip_boundary keeps the solid faces while no collider moves (a tank
 * recomputes nothing); a solid that stood still for several steps and then
 * jumps must be seen where it is at once: the cell at the sphere's new
 * centre typed solid, the one at its old centre not. */
static void still_solid_moved_is_seen_at_once(void)
{
	const double h = 0.0125;
	eddy_world_def wd = eddy_default_world_def();
	wd.bounds_max = (eddy_vec3){0.2f, 0.3f, 0.125f};
	wd.cell_size = h;
	wd.fps = 30;
	eddy_world *w = eddy_create_world(&wd, NULL, 0);
	CHECK(w != NULL);
	if (!w)
		return;
	const flip_defs fd = flip_default_defs();
	CHECK(flip_add_pipeline(w, &fd));
	eddy_collide_sphere_def sp = eddy_default_collide_sphere_def();
	sp.center = (eddy_vec3){0.1f, 0.22f, 0.06f};
	sp.radius = 0.04f;
	const eddy_system_id sphere = eddy_add_collide_sphere(w, &sp);
	CHECK(eddy_system_valid(w, sphere));
	CHECK(pool_fill(w, h, (eddy_vec3){0, 0, 0}, (eddy_vec3){0.2f, 0.1f, 0.125f}));
	if (!step_frames(w, 3))
		return;
	CHECK(eddy_collider_set_offset(w, sphere, (eddy_vec3){0, -0.08f, 0}) == EDDY_OK);
	if (!step_frames(w, 1))
		return;
	const uint8_t *type = eddy_world_channel_u8(w, "cell_type", NULL);
	const int nx = 16, ny = 24;
	const size_t at_new = (size_t)8 + nx * ((size_t)11 + ny * 4), at_old = (size_t)8 + nx * ((size_t)17 + ny * 4);
	printf("    sphere moved 8 cm after 3 still frames: cell type at its new centre %d, at its old %d (solid %d)\n",
	       type[at_new], type[at_old], EDDY_CELL_SOLID);
	CHECK(type[at_new] == EDDY_CELL_SOLID);
	CHECK(type[at_old] != EDDY_CELL_SOLID);
	eddy_destroy_world(w);
}

void suite_stress_flip_solids(void)
{
	RUN(still_solid_moved_is_seen_at_once);
	RUN(still_sphere_keeps_level);
	RUN(sphere_lowered_keeps_level);
	RUN(sphere_lowered_and_oscillated_keeps_level);
	RUN(solvers_agree_with_moving_sphere);
	RUN(threads_agree_with_moving_sphere);
	RUN(drop_into_pool_volume);
	RUN(dam_break_volume);
}
