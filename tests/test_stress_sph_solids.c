/* SPDX-License-Identifier: MIT */
#define _POSIX_C_SOURCE 200809L
/* SPH stress cases with moving solids (issue "Stable and conservative one
 * step beyond the tested scenes", item 2, SPH part): a sphere collider
 * lowered into a pool and moved through it, a faster and larger one, and a
 * plane driven in as a piston, with WCSPH (sph_pressure) and DFSPH
 * (sph_dfsph). The colliders carry boundary particles (Akinci et al. 2012,
 * src/sph/neighbors.c) that move with them, so the fluid beside a solid has a full
 * neighbourhood: without them it packed against the sphere and the level
 * ended about 5% low.
 *
 * The level is measured on the particles: the tank is cut into columns two
 * spacings square; in each, the highest particle that has another within two
 * spacings below it (a lone splash droplet is not the surface) marks the top
 * layer, whose centre lies half a spacing under the surface of a fluid at
 * rest on the lattice; the level is the mean over the columns of that height
 * + spacing / 2. The expectation is geometric: the fluid's volume (N
 * particles of one lattice cell, spacing^3, each: the mass is calibrated so
 * that the lattice is at rest density) plus the submerged solid, over the
 * free area of the tank. scenes/stress/sph_solid_sphere.lua is the same case
 * as a scene. */
#include "test.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "eddy.h"

static double now_ms(void)
{
	struct timespec t;
	clock_gettime(CLOCK_MONOTONIC, &t);
	return t.tv_sec * 1e3 + t.tv_nsec / 1e6;
}

#define PI 3.14159265358979

/* The tank and pool (m) and the fluid spacing. */
static const double TW = 0.2, TH = 0.3, TD = 0.12, DEPTH = 0.15, SP = 0.01;

typedef enum { SOLID_SPHERE, SOLID_PISTON, SOLID_BLOCK, SOLID_NONE } solid_kind;

typedef struct solid_case {
	solid_kind kind;
	bool dfsph;
	double r;                 /* m, sphere radius, or half the block's side */
	double y0, y1, t_lower;   /* m, m, s: sphere centre start, working height, end of the lowering */
	double amp, omega, t_osc; /* m, rad/s, s: oscillation along x, from t_lower for t_osc */
	double piston_x, stroke;  /* m: piston plane (normal +x) start, and how far it is driven in */
	double seconds;
	int threads;
} solid_case;

typedef struct solid_result {
	double level, expected, worst_inside; /* m, m, deepest particle inside the solid (spacings, <= 0) */
	double rho_mean;                      /* mean density / rho0 at the end */
	size_t n;
	double ms;
	uint64_t hash;
	int bad_frames; /* frames that failed */
} solid_result;

typedef struct mover {
	const solid_case *c;
	eddy_system_id solid;
} mover;

static eddy_vec3 solid_offset(const solid_case *c, double t)
{
	if (c->kind == SOLID_PISTON) {
		/* driven in at a constant speed over t_lower, then held */
		const double s = t < c->t_lower ? c->stroke * t / c->t_lower : c->stroke;
		return (eddy_vec3){(float)s, 0, 0};
	}
	const double drop = c->y1 - c->y0;
	const double dy = t < c->t_lower ? drop * t / c->t_lower : drop;
	double dx = 0;
	if (t > c->t_lower) {
		const double tau = (t < c->t_lower + c->t_osc ? t : c->t_lower + c->t_osc) - c->t_lower;
		dx = c->amp * sin(c->omega * tau);
	}
	return (eddy_vec3){(float)dx, (float)dy, 0};
}

/* Just before the collider (as a scene's offset function): where the solid
 * is at the end of this step. */
static eddy_status move_solid(eddy_world *w, const eddy_step_context *ctx, void *user)
{
	const mover *m = user;
	return eddy_collider_set_offset(w, m->solid, solid_offset(m->c, ctx->time + ctx->dt));
}

/* Signed distance (m) of p to the solid's surface, < 0 inside. */
static double solid_distance(const solid_case *c, eddy_vec3 off, double x, double y, double z)
{
	if (c->kind == SOLID_NONE)
		return 0;
	if (c->kind == SOLID_PISTON)
		return x - (c->piston_x + off.x);
	if (c->kind == SOLID_BLOCK) {
		/* inside only: the depth to the nearest face, negative */
		const double ex = fabs(x - (TW / 2 + off.x)) - c->r, ey = fabs(y - (c->y0 + off.y)) - c->r,
					 ez = fabs(z - (TD / 2 + off.z)) - c->r;
		const double m = fmax(ex, fmax(ey, ez));
		return m < 0 ? m : 0;
	}
	const double dx = x - (TW / 2 + off.x), dy = y - (c->y0 + off.y), dz = z - (TD / 2 + off.z);
	return sqrt(dx * dx + dy * dy + dz * dz) - c->r;
}

static int cmp_float(const void *a, const void *b)
{
	const float x = *(const float *)a, y = *(const float *)b;
	return (x > y) - (x < y);
}

/* The mean surface height over the columns of [x0, TW] x [0, TD] (see the
 * header comment). */
static double mean_level(eddy_world *w, double x0)
{
	size_t n;
	const float *x = eddy_world_channel(w, "x", &n), *y = eddy_world_channel(w, "y", NULL),
				*z = eddy_world_channel(w, "z", NULL);
	const double cs = 2 * SP;
	const int nx = (int)floor((TW - x0) / cs + 1e-6), nz = (int)lround(TD / cs);
	float *col = malloc((n + 1) * sizeof *col);
	double sum = 0;
	int cols = 0;
	for (int a = 0; a < nx; ++a)
		for (int b = 0; b < nz; ++b) {
			const double xa = TW - (a + 1) * cs, za = b * cs;
			size_t m = 0;
			for (size_t i = 0; i < n; ++i)
				if (x[i] >= xa && x[i] < xa + cs && z[i] >= za && z[i] < za + cs)
					col[m++] = y[i];
			if (m == 0)
				continue;
			qsort(col, m, sizeof *col, cmp_float);
			size_t top = m - 1;
			while (top > 0 && col[top] - col[top - 1] > 2 * SP)
				top--;
			sum += col[top] + SP / 2;
			cols++;
		}
	free(col);
	return cols ? sum / cols : NAN;
}

/* The SPH pipeline after the emitters, as eddy.fluid builds it: density
 * (h = 2 spacings; stiffness for WCSPH), DFSPH (cold: without its
 * divergence solver) or WCSPH, viscosity 1e-3 Pa s and alpha 0.05, gravity,
 * the world box's wall particles, integrate and the tank. */
static void add_sph_fluid(eddy_world *w, const eddy_world_def *wd, bool dfsph, bool cold, float stiffness)
{
	eddy_sph_density_def de = eddy_default_sph_density_def();
	de.spacing = (float)SP;
	de.radius = (float)(2 * SP);
	de.stiffness = stiffness;
	CHECK(eddy_system_valid(w, eddy_add_sph_density(w, &de)));
	eddy_gravity_def g = eddy_default_gravity_def();
	eddy_sph_viscosity_def vi = eddy_default_sph_viscosity_def();
	vi.viscosity = 1e-3f;
	vi.artificial = 0.05f;
	if (dfsph) {
		eddy_add_gravity(w, &g);
		CHECK(eddy_system_valid(w, eddy_add_sph_viscosity(w, &vi)));
		eddy_sph_dfsph_def df = eddy_default_sph_dfsph_def();
		df.divergence_solver = !cold;
		CHECK(eddy_system_valid(w, eddy_add_sph_dfsph(w, &df)));
	} else {
		eddy_sph_pressure_def pr = eddy_default_sph_pressure_def();
		CHECK(eddy_system_valid(w, eddy_add_sph_pressure(w, &pr)));
		CHECK(eddy_system_valid(w, eddy_add_sph_viscosity(w, &vi)));
		eddy_add_gravity(w, &g);
	}
	eddy_sph_boundary_box_def bb = eddy_default_sph_boundary_box_def();
	bb.min = wd->bounds_min;
	bb.max = wd->bounds_max;
	bb.spacing = (float)SP;
	CHECK(eddy_system_valid(w, eddy_add_sph_boundary_box(w, &bb)));
	eddy_integrate_def it = eddy_default_integrate_def();
	eddy_add_integrate(w, &it);
	eddy_collide_box_def tank = eddy_default_collide_box_def();
	tank.min = wd->bounds_min;
	tank.max = wd->bounds_max;
	eddy_add_collide_box(w, &tank);
}

/* The world of case c; m (kept alive by the caller) moves its solid. */
static eddy_world *solid_world(const solid_case *c, mover *mp)
{
	mp->c = c;
	mp->solid = EDDY_NULL_SYSTEM;
	eddy_world_def wd = eddy_default_world_def();
	wd.bounds_min = (eddy_vec3){0, 0, 0};
	wd.bounds_max = (eddy_vec3){(float)TW, (float)TH, (float)TD};
	wd.fps = 30;
	wd.cfl = c->dfsph ? 0.5f : 0.4f;
	eddy_world *w = eddy_create_world(&wd, NULL, 0);
	CHECK(w != NULL);
	if (!w)
		return NULL;
	CHECK(eddy_world_set_threads(w, c->threads) == EDDY_OK);
	eddy_emit_box_def eb = eddy_default_emit_box_def();
	eb.min = (eddy_vec3){c->kind == SOLID_PISTON ? (float)c->piston_x : 0.0f, 0, 0};
	eb.max = (eddy_vec3){(float)TW, (float)DEPTH, (float)TD};
	eb.spacing = (float)SP;
	CHECK(eddy_system_valid(w, eddy_add_emit_box(w, &eb)));
	/* WCSPH: k = 100 g D, a column compressed by g D / k = 1% at the floor
	 * (0.5% on the mean), c = 12 m/s, 20 x the solid's top speed */
	add_sph_fluid(w, &wd, c->dfsph, false, (float)(100 * 9.81 * DEPTH));
	eddy_custom_system_def cs = eddy_default_custom_system_def();
	cs.name = "mover";
	cs.step = move_solid;
	cs.user = mp;
	if (c->kind != SOLID_NONE)
		CHECK(eddy_system_valid(w, eddy_add_custom_system(w, &cs)));
	if (c->kind == SOLID_NONE) {
		mp->solid = EDDY_NULL_SYSTEM;
	} else if (c->kind == SOLID_SPHERE) {
		eddy_collide_sphere_def sp = eddy_default_collide_sphere_def();
		sp.center = (eddy_vec3){(float)(TW / 2), (float)c->y0, (float)(TD / 2)};
		sp.radius = (float)c->r;
		mp->solid = eddy_add_collide_sphere(w, &sp);
	} else if (c->kind == SOLID_BLOCK) {
		eddy_collide_box_def bl = eddy_default_collide_box_def();
		bl.min = (eddy_vec3){(float)(TW / 2 - c->r), (float)(c->y0 - c->r), (float)(TD / 2 - c->r)};
		bl.max = (eddy_vec3){(float)(TW / 2 + c->r), (float)(c->y0 + c->r), (float)(TD / 2 + c->r)};
		bl.inside = false;
		mp->solid = eddy_add_collide_box(w, &bl);
	} else {
		eddy_collide_plane_def pl = eddy_default_collide_plane_def();
		pl.point = (eddy_vec3){(float)c->piston_x, 0, 0};
		pl.normal = (eddy_vec3){1, 0, 0};
		mp->solid = eddy_add_collide_plane(w, &pl);
	}
	CHECK(c->kind == SOLID_NONE || eddy_system_valid(w, mp->solid));
	return w;
}

static void run_solid(const solid_case *c, solid_result *res)
{
	memset(res, 0, sizeof *res);
	mover m;
	eddy_world *w = solid_world(c, &m);
	if (!w)
		return;
	const double fps = 30;
	const double t0 = now_ms();
	const int frames = (int)lround(c->seconds * fps), last = 9; /* the level: mean of the last 0.3 s */
	const double x0 = c->kind == SOLID_PISTON ? c->piston_x + c->stroke : 0;
	for (int f = 0; f < frames; ++f) {
		if (eddy_world_step_frame(w) != EDDY_OK) {
			test_fail(__FILE__, __LINE__, "step: %s", eddy_world_error(w));
			res->bad_frames++;
			break;
		}
		const eddy_vec3 off = solid_offset(c, eddy_world_time(w));
		size_t n;
		const float *x = eddy_world_channel(w, "x", &n), *y = eddy_world_channel(w, "y", NULL),
					*z = eddy_world_channel(w, "z", NULL);
		for (size_t i = 0; i < n; ++i) {
			const double sd = solid_distance(c, off, x[i], y[i], z[i]) / SP;
			res->worst_inside = sd < res->worst_inside ? sd : res->worst_inside;
		}
		if (f >= frames - last)
			res->level += mean_level(w, x0) / last;
	}
	res->ms = now_ms() - t0;
	res->n = eddy_world_particle_count(w);
	const double vol = (double)res->n * SP * SP * SP;
	if (c->kind == SOLID_NONE)
		res->expected = vol / (TW * TD);
	else if (c->kind == SOLID_PISTON)
		res->expected = vol / ((TW - x0) * TD);
	else if (c->kind == SOLID_BLOCK) /* it ends fully under */
		res->expected = (vol + 8 * c->r * c->r * c->r) / (TW * TD);
	else /* the sphere ends fully under */
		res->expected = (vol + 4.0 / 3 * PI * c->r * c->r * c->r) / (TW * TD);
	{
		size_t n;
		const float *rho = eddy_world_channel(w, "density", &n);
		double sum = 0;
		for (size_t i = 0; i < n; ++i)
			sum += rho[i];
		res->rho_mean = n ? sum / (double)n / 1000.0 : NAN;
	}
	res->hash = eddy_world_state_hash(w);
	eddy_frame_stats fs;
	eddy_world_frame_stats(w, &fs);
	CHECK(fs.nonfinite == 0 && fs.leaked == 0);
	eddy_destroy_world(w);
}

/* The case: a 4 cm sphere lowered over 0.5 s from 0.22 m to 0.08 m
 * (fully under, its top 3 cm below the surface), moved along x with
 * amplitude 5 cm at 2 Hz (peak 0.63 m/s) for 1.5 s, then left to settle:
 * 0.5 s with WCSPH, 1.5 s with DFSPH. 0.5 s after the sphere stops, the
 * waves it left still read in DFSPH's level: the 5 cm case read +2.8 to
 * +4.6% over 2.2-2.5 s at peak speeds 0.62-0.64 m/s (with or without
 * sph_dfsph's shift, chaotically), +0.7 to +1.3% over 2.7-3.0 s and +0.2 to
 * +0.6% over 3.2-3.5 s: the level is a volume only once they have settled.
 * WCSPH keeps the 2.5 s reading: at 3.5 s its 4 cm sphere at 1 m/s read
 * -2.75%, near the bound, a drift not studied here. */
static solid_case sphere_case(bool dfsph)
{
	solid_case c = {SOLID_SPHERE, dfsph, 0.04, 0.22, 0.08, 0.5, 0.05, 4 * PI, 1.5, 0, 0, dfsph ? 3.5 : 2.5, 1};
	return c;
}

static void report(const char *what, const solid_case *c, const solid_result *r)
{
	const double err = (r->level - r->expected) / r->expected;
	printf("    %s, %s: level %.4f m, expected %.4f m (%+.2f%%); %zu particles, mean density %.4f rho0; deepest %.3f "
	       "spacings inside; %.1f s\n",
	       what, c->dfsph ? "DFSPH" : "WCSPH", r->level, r->expected, 100 * err, r->n, r->rho_mean, -r->worst_inside,
	       r->ms / 1000);
}

/* Tolerances. Level: 3% of the expectation (the bound), on the
 * mean of the readings over the last 0.3 s. What it has to hold besides the
 * solid's displacement: WCSPH's compression (0.5% on the mean at k = 100 g D),
 * DFSPH's (at most its 0.5% tolerance), the waves left after the settling
 * (their mean over the 60 columns is zero to first order), and the reading of
 * a free surface in SPH: the same tank without a solid, filled on the lattice
 * and left alone, reads -2.9% (DFSPH) and -0.7% (WCSPH) after 2.5 s, -2.7%
 * and -2.2% after 1 s (the simple cubic start relaxes and the top layer,
 * short of neighbours above, settles into the one below), so the calm cases
 * (piston, block) keep less margin than the stirred ones. The sphere adds
 * 1.1 cm (7%) to the 15 cm; without its boundary particles the oscillated
 * case read -3.7% for both solvers and fails. Inside: the collider projects
 * every particle out at each step, and the boundary particles keep them
 * about half a spacing off; 0.01 spacings is float round-off of the
 * projection. */
static void check_level(const solid_result *r)
{
	CHECK(fabs(r->level - r->expected) <= 0.03 * r->expected);
	CHECK(r->worst_inside > -0.01);
	CHECK(r->bad_frames == 0);
}

static void sphere_oscillated_wcsph_keeps_level(void)
{
	const solid_case c = sphere_case(false);
	solid_result r;
	run_solid(&c, &r);
	report("4 cm sphere lowered + oscillated (0.63 m/s)", &c, &r);
	check_level(&r);
}

static void sphere_oscillated_dfsph_keeps_level(void)
{
	const solid_case c = sphere_case(true);
	solid_result r;
	run_solid(&c, &r);
	report("4 cm sphere lowered + oscillated (0.63 m/s)", &c, &r);
	check_level(&r);
}

/* One step beyond, each way: a 5 cm sphere (twice the volume, its top 2 cm
 * under) at the same 0.63 m/s, and the 4 cm sphere at 1 m/s (5 cm at
 * 3.2 Hz). Both together: larger_and_faster_sphere_keeps_level. */
static void larger_or_faster_sphere_keeps_level(void)
{
	for (int k = 0; k < 4; ++k) {
		solid_case c = sphere_case(k % 2 == 1);
		if (k < 2)
			c.r = 0.05;
		else
			c.omega = 1.0 / c.amp;
		solid_result r;
		run_solid(&c, &r);
		report(k < 2 ? "5 cm sphere lowered + oscillated (0.63 m/s)" : "4 cm sphere lowered + oscillated (1.0 m/s)", &c,
		       &r);
		check_level(&r);
	}
}

/* Both steps at once: the 5 cm sphere at 1 m/s. While it moves, WCSPH's
 * stirred fluid is expanded (the particles from 3 spacings above the floor
 * to 4 below the surface at 0.973-0.982 rho0 over 0.7-1.5 s, half of them
 * under rho0, the level 3-7% high: its pressure, clamped at 0, does not
 * pull them together); gravity does, once the sphere stops (1.001 rho0 at
 * 2.0 s, 1.007 at 2.5 s) and the level comes back to the geometry: WCSPH
 * -0.30% (mean density 0.9973 rho0), DFSPH +0.36%. */
static void larger_and_faster_sphere_keeps_level(void)
{
	for (int k = 0; k < 2; ++k) {
		solid_case c = sphere_case(k == 1);
		c.r = 0.05;
		c.omega = 1.0 / c.amp;
		solid_result r;
		run_solid(&c, &r);
		report("5 cm sphere lowered + oscillated (1.0 m/s)", &c, &r);
		check_level(&r);
	}
}

/* The calm cases are also held to the still pool: the same tank, fluid and
 * solver for the same time without a solid reads the free surface
 * L_pool - H_pool off the geometric H_pool (the settling above); the case's
 * reading minus that offset must be within tol of its expectation. The
 * piston meets 1%, a bound the solid's displacement error alone has to meet
 * (measured +0.52%). The block is held to the 3% only: lowering it
 * stirs the fluid, and sph_dfsph's pressure, clamped at 0, cannot pull the
 * expanded fluid back together (mean density 0.976 rho0 at the end, against
 * 0.984 for the piston), so it ends 1.32% high after the pool's offset
 * (+1.25% raw). */
static void check_against_pool(const solid_case *c, const solid_result *r, double tol)
{
	solid_case p = *c;
	p.kind = SOLID_NONE;
	solid_result pool;
	run_solid(&p, &pool);
	const double corrected = r->level - (pool.level - pool.expected);
	printf("      still pool %.4f m for %.4f m (%+.2f%%): the case less that offset %.4f m (%+.2f%%)\n", pool.level,
	       pool.expected, 100 * (pool.level / pool.expected - 1), corrected, 100 * (corrected / r->expected - 1));
	CHECK(fabs(corrected - r->expected) <= tol * r->expected);
}

/* A piston: a plane (normal +x) at x = 2 cm driven in by 3 cm over 0.5 s
 * (6 cm/s), then held for 1 s; the fluid, pushed into 15 of the 18 cm, rises
 * by a fifth. */
static solid_case piston_case(bool dfsph)
{
	solid_case c = {SOLID_PISTON, dfsph, 0, 0, 0, 0.5, 0, 0, 0, 0.02, 0.03, 1.5, 1};
	return c;
}

static void piston_dfsph_keeps_level(void)
{
	const solid_case c = piston_case(true);
	solid_result r;
	run_solid(&c, &r);
	report("plane piston driven 3 cm in", &c, &r);
	check_level(&r);
	check_against_pool(&c, &r, 0.01);
}

/* WCSPH's still pool rings (-2.2% at 1 s, -0.7% at 2.5 s): the level alone */
static void piston_wcsph_keeps_level(void)
{
	const solid_case c = piston_case(false);
	solid_result r;
	run_solid(&c, &r);
	report("plane piston driven 3 cm in", &c, &r);
	check_level(&r);
}

/* A block (collide_box, inside = false) 6 cm on a side, lowered like the
 * sphere to a centre height of 8 cm (top 4 cm under) and held 1 s: its
 * 216 cm^3 raise the level by 0.9 cm. */
static void block_lowered_keeps_level(void)
{
	solid_case c = sphere_case(true);
	c.kind = SOLID_BLOCK;
	c.r = 0.03;
	c.t_osc = 0;
	c.seconds = 1.5;
	solid_result r;
	run_solid(&c, &r);
	report("6 cm block lowered", &c, &r);
	check_level(&r);
	check_against_pool(&c, &r, 0.03);
}

/* Determinism with a moving solid: the same state hash on 1 and 2 threads
 * (the collider particles change cells as the sphere moves; every list is
 * sorted by index, so the sums go in the same order). */
static void threads_agree_with_moving_sphere(void)
{
	solid_case c = sphere_case(true);
	c.seconds = 0.4; /* the sphere enters the water at 0.1 s */
	solid_result a, b;
	run_solid(&c, &a);
	c.threads = 2;
	run_solid(&c, &b);
	printf("    moving sphere, DFSPH, 0.4 s: state hash 1 thread %016llx, 2 threads %016llx\n",
	       (unsigned long long)a.hash, (unsigned long long)b.hash);
	CHECK(a.hash == b.hash);
}

/* A checkpoint taken with the sphere moving resumes bit-identical: the
 * collider particles are placed from the colliders' offsets, and the offsets
 * their velocities are taken against are sph_density's checkpointed state. */
static void resume_with_moving_sphere_is_bit_identical(void)
{
	const solid_case c = sphere_case(true); /* frames 9-15: lowering, 0.28 m/s */
	mover ma, mb, mc;
	eddy_world *a = solid_world(&c, &ma), *b = solid_world(&c, &mb);
	if (!a || !b)
		return;
	for (int f = 0; f < 15; ++f)
		CHECK(eddy_world_step_frame(a) == EDDY_OK);
	for (int f = 0; f < 9; ++f)
		CHECK(eddy_world_step_frame(b) == EDDY_OK);
	char path[512];
	snprintf(path, sizeof path, "%s/t_sph_solid.eddy", test_build_dir());
	CHECKF(eddy_world_save(b, path, 3) == EDDY_OK, "%s", eddy_world_error(b));
	eddy_destroy_world(b);
	eddy_world *r = solid_world(&c, &mc);
	if (!r)
		return;
	CHECKF(eddy_world_load(r, path, 3) == EDDY_OK, "%s", eddy_world_error(r));
	for (int f = 0; f < 6; ++f)
		CHECK(eddy_world_step_frame(r) == EDDY_OK);
	printf("    moving sphere, DFSPH: hash after 15 frames straight %016llx, resumed at 9 %016llx\n",
	       (unsigned long long)eddy_world_state_hash(a), (unsigned long long)eddy_world_state_hash(r));
	CHECK(eddy_world_state_hash(a) == eddy_world_state_hash(r));
	remove(path);
	eddy_destroy_world(a);
	eddy_destroy_world(r);
}

/* Water leaving a wall it touches: a block 3 layers thick (10 x 4 cm,
 * away from the side walls) released against the lid of a closed tank, or
 * against the underside of a collider box, falls freely: in this model the
 * space it leaves is air at p = 0 (the free surface), so nothing may hold
 * it but its own compression, which is none at rest. After 0.1 s its mean
 * velocity along g is g t to within 2% (the solves' tolerances; measured
 * 1.000 at 3 decimals, WCSPH and DFSPH). Before DFSPH's walls were made
 * unable to pull (src/sph/dfsph.c: the hydrostatic wall pressure held at
 * >= 0, a particle leaving its walls with no pressure out of the velocity
 * solve), its lid held the block back: 0.75 of free fall at 0.1 s (0.77
 * with gravity off the normal, 0.75 under the collider; the cold solve,
 * divergence_solver = false, 0.92), a dam break's
 * splash hung from the lid of its tank for seconds, and in zero gravity a
 * block leaving the lid at 0.5 m/s was pulled back to 0.58 of that speed. One step beyond the lid: gravity 24 degrees
 * off the lid's normal, the underside of a collider, zero gravity with the block moving away.
 * And beside side walls, which hold nothing up either: the block against
 * one side wall (DFSPH 0.985) and, WCSPH, against three (x = 0 and both z
 * walls: 0.993). DFSPH against three reads 0.958, its cold solve 0.957:
 * its hydrostatic wall term carries a falling block beside its side walls
 * as if it were a column at rest (open: README, Stress cases). */
typedef struct lid_case {
	bool dfsph, shelf;
	bool cold;   /* DFSPH without its divergence solver */
	eddy_vec3 g; /* m/s^2 */
	double v0;   /* m/s, the block's start speed away from the lid (down) */
	int side;    /* 0: away from the side walls; 1: against the x = 0 wall; 2: and the two z walls */
} lid_case;

static double lid_fall_ratio(const lid_case *c)
{
	const double H = 0.3, top = c->shelf ? 0.2 : H, t_end = 0.1;
	eddy_world_def wd = eddy_default_world_def();
	wd.bounds_min = (eddy_vec3){0, 0, 0};
	wd.bounds_max = (eddy_vec3){0.2f, (float)H, 0.1f};
	wd.gravity = c->g;
	wd.fps = 100;
	wd.cfl = c->dfsph ? 0.5f : 0.4f;
	eddy_world *w = eddy_create_world(&wd, NULL, 0);
	CHECK(w != NULL);
	if (!w)
		return NAN;
	eddy_emit_box_def eb = eddy_default_emit_box_def();
	eb.min = (eddy_vec3){c->side ? 0 : 0.05f, (float)(top - 3 * SP), c->side == 2 ? 0 : 0.03f};
	eb.max = (eddy_vec3){c->side ? 0.1f : 0.15f, (float)top, c->side == 2 ? 0.1f : 0.07f};
	eb.spacing = (float)SP;
	eb.velocity = (eddy_vec3){0, (float)-c->v0, 0};
	CHECK(eddy_system_valid(w, eddy_add_emit_box(w, &eb)));
	add_sph_fluid(w, &wd, c->dfsph, c->cold, 400); /* WCSPH: c = 20 m/s, as scenes/pour.lua */
	if (c->shelf) {
		eddy_collide_box_def sh = eddy_default_collide_box_def();
		sh.min = (eddy_vec3){0, (float)top, 0};
		sh.max = (eddy_vec3){0.2f, (float)top + 0.04f, 0.1f};
		sh.inside = false;
		CHECK(eddy_system_valid(w, eddy_add_collide_box(w, &sh)));
	}
	const int frames = (int)lround(t_end * wd.fps);
	for (int f = 0; f < frames; ++f)
		if (eddy_world_step_frame(w) != EDDY_OK) {
			test_fail(__FILE__, __LINE__, "step: %s", eddy_world_error(w));
			eddy_destroy_world(w);
			return NAN;
		}
	/* the mean velocity along g (along -y without gravity) over g t + v0 along it */
	const double gn = sqrt((double)c->g.x * c->g.x + (double)c->g.y * c->g.y + (double)c->g.z * c->g.z);
	const double ux = gn > 0 ? c->g.x / gn : 0, uy = gn > 0 ? c->g.y / gn : -1, uz = gn > 0 ? c->g.z / gn : 0;
	size_t n;
	const float *vx = eddy_world_channel(w, "vx", &n), *vy = eddy_world_channel(w, "vy", NULL),
				*vz = eddy_world_channel(w, "vz", NULL);
	double along = 0;
	for (size_t i = 0; i < n; ++i)
		along += ux * vx[i] + uy * vy[i] + uz * vz[i];
	along /= n ? (double)n : 1;
	eddy_destroy_world(w);
	return along / (gn * t_end + c->v0 * -uy);
}

static void check_lid(const char *what, lid_case c)
{
	const double r = lid_fall_ratio(&c);
	printf("    %s, %s: mean velocity along g at 0.1 s / free fall %.4f\n",
	       c.dfsph ? (c.cold ? "dfsph cold" : "dfsph") : "wcsph", what, r);
	CHECK_NEAR(r, 1.0, 0.02);
}

static void water_leaves_a_lid(void)
{
	const eddy_vec3 down = {0, -9.81f, 0};
	check_lid("released under the lid", (lid_case){true, false, false, down, 0, 0});
	check_lid("released under the lid", (lid_case){true, false, true, down, 0, 0});
	check_lid("released under the lid", (lid_case){false, false, false, down, 0, 0});
	check_lid("gravity 24 degrees off the lid's normal", (lid_case){true, false, false, {4.0f, -9.0f, 0}, 0, 0});
	check_lid("under a collider box", (lid_case){true, true, false, down, 0, 0});
	check_lid("under a collider box", (lid_case){true, true, true, down, 0, 0});
	check_lid("no gravity, leaving the lid at 0.5 m/s", (lid_case){true, false, false, {0, 0, 0}, 0.5, 0});
	check_lid("under the lid, against a side wall", (lid_case){true, false, false, down, 0, 1});
	check_lid("under the lid, against three side walls", (lid_case){false, false, false, down, 0, 2});
}

/* make test: DFSPH (a few seconds each) */
void suite_stress_sph_solids(void)
{
	RUN(sphere_oscillated_dfsph_keeps_level);
	RUN(piston_dfsph_keeps_level);
	RUN(block_lowered_keeps_level);
	RUN(water_leaves_a_lid);
	RUN(threads_agree_with_moving_sphere);
	RUN(resume_with_moving_sphere_is_bit_identical);
}

/* make test-long: WCSPH's acoustic step makes the sphere cases ten times
 * longer (about 15 s each on one thread) */
void suite_long_sph_solids(void)
{
	RUN(sphere_oscillated_wcsph_keeps_level);
	RUN(piston_wcsph_keeps_level);
	RUN(larger_or_faster_sphere_keeps_level);
	RUN(larger_and_faster_sphere_keeps_level);
}
