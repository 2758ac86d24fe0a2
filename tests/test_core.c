/* SPDX-License-Identifier: MIT */
/* The engine core through the public API: worlds, columns, the pipeline rule,
 * handles, errors. */
#include "test.h"

#include <stdlib.h>
#include <string.h>

#include "eddy.h"

static eddy_world *make_world(void)
{
	eddy_world_def d = eddy_default_world_def();
	char err[256];
	eddy_world *w = eddy_create_world(&d, err, sizeof err);
	CHECKF(w != NULL, "create_world: %s", err);
	return w;
}

static char *plan_text(const eddy_world *w)
{
	size_t n = eddy_world_plan(w, NULL, 0);
	char *t = malloc(n + 1);
	eddy_world_plan(w, t, n + 1);
	CHECK(strlen(t) == n);
	return t;
}

static void world_def_rejects_bad_values(void)
{
	char err[256];
	eddy_world_def d = eddy_default_world_def();
	d.bounds_max.y = d.bounds_min.y;
	CHECK(eddy_create_world(&d, err, sizeof err) == NULL);
	CHECK_HAS(err, "'bounds' must have max > min");
	d = eddy_default_world_def();
	d.cfl = NAN;
	CHECK(eddy_create_world(&d, err, sizeof err) == NULL);
	CHECK_HAS(err, "world: 'cfl' must be in (0, 10]");
	d = eddy_default_world_def();
	d.fps = -1;
	CHECK(eddy_create_world(&d, err, sizeof err) == NULL);
	CHECK_HAS(err, "'fps'");
}

/* "Simulate only the effects a scene calls for": an absent system leaves its
 * columns unallocated, and the plan says so. */
static void absent_systems_allocate_nothing(void)
{
	eddy_world *w = make_world();
	size_t n = 99;
	CHECK(eddy_world_channel(w, "x", &n) == NULL);
	CHECK(n == 0);
	eddy_emit_box_def b = eddy_default_emit_box_def();
	eddy_add_emit_box(w, &b);
	eddy_gravity_def g = eddy_default_gravity_def();
	eddy_add_gravity(w, &g);
	eddy_integrate_def it = eddy_default_integrate_def();
	eddy_add_integrate(w, &it);
	CHECK(eddy_world_step(w) == EDDY_OK);
	CHECK(eddy_world_channel(w, "x", &n) != NULL);
	CHECK(n == 1000);
	CHECK(eddy_world_channel(w, "density", &n) == NULL);
	CHECK(eddy_world_channel(w, "pressure", NULL) == NULL);
	CHECK(eddy_world_channel(w, "u", NULL) == NULL);
	CHECK(!eddy_world_grid(w).allocated);
	eddy_column_info info;
	CHECK(eddy_world_column_info(w, eddy_world_find_column(w, "density"), &info) == EDDY_OK);
	CHECK(!info.allocated && info.bytes == 0);
	char *t = plan_text(w);
	const char *na = strstr(t, "not allocated:");
	CHECK(na != NULL);
	CHECK(na && strstr(na, " density") != NULL);
	/* and the allocated part of the plan does not list it */
	char *cut = strstr(t, "not allocated:");
	if (cut)
		*cut = '\0';
	CHECK(strstr(t, "density") == NULL);
	CHECK_HAS(t, "emit_box");
	free(t);
	eddy_destroy_world(w);
}

static eddy_status noop_step(eddy_world *w, const eddy_step_context *ctx, void *user)
{
	(void)w, (void)ctx, (void)user;
	return EDDY_OK;
}

static void order_errors_name_the_fix(void)
{
	eddy_world *w = make_world();
	eddy_integrate_def it = eddy_default_integrate_def();
	eddy_system_id id = eddy_add_integrate(w, &it);
	CHECK(!eddy_system_valid(w, id));
	CHECK_HAS(eddy_world_error(w), "integrate reads 'ax' but no earlier system writes it: add gravity before it");
	/* nothing was allocated by the failed add */
	CHECK(eddy_world_channel(w, "x", NULL) == NULL);
	CHECK(eddy_world_system_count(w) == 0);

	const char *reads[] = {"density"};
	eddy_custom_system_def c = eddy_default_custom_system_def();
	c.name = "my_pressure";
	c.reads = reads;
	c.read_count = 1;
	c.step = noop_step;
	id = eddy_add_custom_system(w, &c);
	CHECK(!eddy_system_valid(w, id));
	CHECK_HAS(eddy_world_error(w), "my_pressure reads 'density' but no earlier system writes it");

	const char *bogus[] = {"densty"};
	c.reads = bogus;
	CHECK(!eddy_system_valid(w, eddy_add_custom_system(w, &c)));
	CHECK_HAS(eddy_world_error(w), "unknown column 'densty'");

	/* a writer first makes the same reader valid */
	const char *writes[] = {"density"};
	eddy_custom_system_def wr = eddy_default_custom_system_def();
	wr.name = "my_density";
	wr.writes = writes;
	wr.write_count = 1;
	wr.step = noop_step;
	eddy_system_id wid = eddy_add_custom_system(w, &wr);
	CHECK(eddy_system_valid(w, wid));
	c.reads = reads;
	eddy_system_id rid = eddy_add_custom_system(w, &c);
	CHECK(eddy_system_valid(w, rid));
	CHECK(eddy_world_channel(w, "density", NULL) != NULL);
	/* removing the writer would break the reader: refused */
	CHECK(eddy_world_remove_system(w, wid) == EDDY_ERR_ORDER);
	CHECK_HAS(eddy_world_error(w), "cannot remove my_density");
	CHECK(eddy_world_remove_system(w, rid) == EDDY_OK);
	CHECK(eddy_world_remove_system(w, wid) == EDDY_OK);
	CHECK(eddy_world_channel(w, "density", NULL) == NULL);
	eddy_destroy_world(w);
}

/* Couplings are checked when a system is added (and removed), not at the
 * first step: a system that needs what an earlier system provides names it,
 * and two systems that exclude each other name both, in either order. */
static void couplings_are_checked_when_added(void)
{
	eddy_world *w = make_world();
	/* 'density' written by a custom system satisfies the column rule, but
	 * not sph_viscosity's need for neighbour lists */
	const char *writes[] = {"density"};
	eddy_custom_system_def wr = eddy_default_custom_system_def();
	wr.name = "my_density";
	wr.writes = writes;
	wr.write_count = 1;
	wr.step = noop_step;
	CHECK(eddy_system_valid(w, eddy_add_custom_system(w, &wr)));
	eddy_sph_viscosity_def vd = eddy_default_sph_viscosity_def();
	CHECK(!eddy_system_valid(w, eddy_add_sph_viscosity(w, &vd)));
	CHECK_HAS(eddy_world_error(w),
	          "sph_viscosity needs SPH neighbour lists from an earlier system: add sph_density before it");
	CHECK(eddy_world_system_count(w) == 1);

	eddy_sph_density_def dd = eddy_default_sph_density_def();
	eddy_system_id did = eddy_add_sph_density(w, &dd);
	CHECK(eddy_system_valid(w, did));
	eddy_system_id vid = eddy_add_sph_viscosity(w, &vd);
	CHECK(eddy_system_valid(w, vid));
	/* removing the provider would leave the viscosity without its lists;
	 * the custom writer still writes 'density', so only the coupling holds it */
	CHECK(eddy_world_remove_system(w, did) == EDDY_ERR_ORDER);
	CHECK_HAS(eddy_world_error(w), "cannot remove sph_density: sph_viscosity needs SPH neighbour lists");

	/* sph_pressure first, then sph_dfsph: refused naming both */
	eddy_sph_pressure_def pd = eddy_default_sph_pressure_def();
	eddy_system_id pid = eddy_add_sph_pressure(w, &pd);
	CHECK(eddy_system_valid(w, pid));
	eddy_sph_dfsph_def fd = eddy_default_sph_dfsph_def();
	CHECK(!eddy_system_valid(w, eddy_add_sph_dfsph(w, &fd)));
	CHECK_HAS(eddy_world_error(w), "sph_dfsph and sph_pressure cannot share a pipeline (sph_dfsph excludes the SPH "
	                               "equation-of-state force); remove one of them from the scene");
	/* without sph_pressure it joins */
	CHECK(eddy_world_remove_system(w, pid) == EDDY_OK);
	CHECK(eddy_system_valid(w, eddy_add_sph_dfsph(w, &fd)));
	eddy_destroy_world(w);
}

static void stale_handles_are_detected(void)
{
	eddy_world *w = make_world();
	eddy_collide_sphere_def s = eddy_default_collide_sphere_def();
	eddy_system_id a = eddy_add_collide_sphere(w, &s);
	CHECK(eddy_system_valid(w, a));
	CHECK(eddy_world_remove_system(w, a) == EDDY_OK);
	CHECK(!eddy_system_valid(w, a));
	CHECK(eddy_collider_set_offset(w, a, (eddy_vec3){0, 0, 0}) == EDDY_ERR_STALE);
	CHECK(eddy_world_remove_system(w, a) == EDDY_ERR_STALE);
	/* the slot is reused with a new generation; the old handle stays stale */
	eddy_system_id b = eddy_add_collide_sphere(w, &s);
	CHECK(b.index == a.index && b.generation != a.generation);
	CHECK(!eddy_system_valid(w, a));
	CHECK(eddy_system_valid(w, b));
	CHECK(!eddy_system_valid(w, EDDY_NULL_SYSTEM));
	eddy_destroy_world(w);
}

static void grid_exists_only_for_grid_systems(void)
{
	eddy_world *w = make_world();
	const char *reads[] = {"u"};
	eddy_custom_system_def c = eddy_default_custom_system_def();
	c.name = "grid_user";
	c.writes = reads;
	c.write_count = 1;
	c.step = noop_step;
	CHECK(!eddy_system_valid(w, eddy_add_custom_system(w, &c)));
	CHECK_HAS(eddy_world_error(w), "set world 'cell_size' > 0 m");
	eddy_destroy_world(w);

	eddy_world_def d = eddy_default_world_def();
	d.cell_size = 0.1;
	w = eddy_create_world(&d, NULL, 0);
	CHECK(!eddy_world_grid(w).allocated);
	eddy_system_id id = eddy_add_custom_system(w, &c);
	CHECK(eddy_system_valid(w, id));
	eddy_grid_info g = eddy_world_grid(w);
	CHECK(g.allocated && g.nx == 10 && g.ny == 10 && g.nz == 10);
	size_t n;
	CHECK(eddy_world_channel(w, "u", &n) != NULL);
	CHECK(n == 11 * 10 * 10);
	CHECK(eddy_world_channel(w, "cell_pressure", NULL) == NULL);
	CHECK(eddy_world_remove_system(w, id) == EDDY_OK);
	CHECK(!eddy_world_grid(w).allocated);
	CHECK(eddy_world_channel(w, "u", NULL) == NULL);
	eddy_destroy_world(w);
}

static void swap_remove_and_growth(void)
{
	eddy_world *w = make_world();
	eddy_gravity_def g = eddy_default_gravity_def();
	eddy_add_gravity(w, &g);
	eddy_integrate_def it = eddy_default_integrate_def();
	eddy_add_integrate(w, &it);
	enum { N = 1000 }; /* past the first capacity, so the table grows */
	eddy_vec3 *p = malloc(N * sizeof *p);
	for (int i = 0; i < N; ++i)
		p[i] = (eddy_vec3){0.5f, (float)i / N, 0.5f};
	CHECK(eddy_world_add_particles(w, N, p, NULL) == EDDY_OK);
	CHECK(eddy_world_particle_count(w) == N);
	const float *y = eddy_world_channel(w, "y", NULL);
	CHECK(y[0] == 0.0f && y[N - 1] == (float)(N - 1) / N);
	CHECK(eddy_world_remove_particle(w, 0) == EDDY_OK);
	y = eddy_world_channel(w, "y", NULL);
	CHECK(eddy_world_particle_count(w) == N - 1);
	CHECK(y[0] == (float)(N - 1) / N);
	CHECK(eddy_world_remove_particle(w, N) == EDDY_ERR_INVALID);
	p[0].x = 2.0f; /* outside the unit box */
	CHECK(eddy_world_add_particles(w, 1, p, NULL) == EDDY_ERR_INVALID);
	CHECK_HAS(eddy_world_error(w), "outside the world bounds");
	free(p);
	eddy_destroy_world(w);
}

/* Particles a host adds before any system uses positions or velocities
 * keep what it gave (the world holds those columns for it), and only those
 * columns: the rest are still made by the systems that use them. */
static void host_particles_keep_their_state(void)
{
	eddy_world *w = make_world();
	const eddy_vec3 p[2] = {{0.5f, 0.5f, 0.5f}, {0.25f, 0.75f, 0.5f}}, v[2] = {{1, 2, 3}, {-1, 0, 0.5f}};
	CHECK(eddy_world_add_particles(w, 2, p, v) == EDDY_OK);
	size_t n = 0;
	const float *x = eddy_world_channel(w, "x", &n), *vz = eddy_world_channel(w, "vz", NULL);
	CHECK(x && vz && n == 2);
	CHECK(x && x[1] == 0.25f && vz && vz[0] == 3.0f);
	CHECK(eddy_world_channel(w, "ax", NULL) == NULL && eddy_world_channel(w, "density", NULL) == NULL);
	eddy_gravity_def g = eddy_default_gravity_def();
	eddy_system_id gid = eddy_add_gravity(w, &g);
	eddy_integrate_def it = eddy_default_integrate_def();
	eddy_system_id iid = eddy_add_integrate(w, &it);
	CHECK(eddy_world_step(w) == EDDY_OK);
	x = eddy_world_channel(w, "x", NULL);
	const float *y = eddy_world_channel(w, "y", NULL), *vx = eddy_world_channel(w, "vx", NULL);
	CHECK(x && y && vx);
	if (x && y && vx) {
		CHECK(x[0] > 0.5f && x[1] < 0.25f);     /* moved with the velocities given */
		CHECK(vx[0] == 1.0f && vx[1] == -1.0f); /* gravity acts along y only */
		CHECK(y[1] < 0.75f);                    /* and pulls the resting one down */
	}
	/* the systems gone, the host's particles stay */
	CHECK(eddy_world_remove_system(w, iid) == EDDY_OK && eddy_world_remove_system(w, gid) == EDDY_OK);
	CHECK(eddy_world_channel(w, "x", NULL) != NULL && eddy_world_channel(w, "vx", NULL) != NULL);
	CHECK(eddy_world_channel(w, "ax", NULL) == NULL);
	eddy_destroy_world(w);
	/* positions alone hold no velocity column */
	w = make_world();
	CHECK(eddy_world_add_particles(w, 1, p, NULL) == EDDY_OK);
	CHECK(eddy_world_channel(w, "y", NULL) != NULL && eddy_world_channel(w, "vx", NULL) == NULL);
	eddy_destroy_world(w);
}

static void defs_are_range_checked(void)
{
	eddy_world *w = make_world();
	eddy_emit_box_def b = eddy_default_emit_box_def();
	b.spacing = -0.01f;
	CHECK(!eddy_system_valid(w, eddy_add_emit_box(w, &b)));
	CHECK_HAS(eddy_world_error(w), "emit_box: 'spacing' must be > 0 (got -0.01)");
	b = eddy_default_emit_box_def();
	b.max = (eddy_vec3){0.105f, 0.2f, 0.2f}; /* thinner than one spacing in x */
	b.min = (eddy_vec3){0.1f, 0.1f, 0.1f};
	CHECK(!eddy_system_valid(w, eddy_add_emit_box(w, &b)));
	CHECK_HAS(eddy_world_error(w), "emits no particles");
	b = eddy_default_emit_box_def();
	b.jitter = 0.7f;
	CHECK(!eddy_system_valid(w, eddy_add_emit_box(w, &b)));
	CHECK_HAS(eddy_world_error(w), "'jitter' must be in [0, 0.5] (got 0.7");
	eddy_collide_box_def cb = eddy_default_collide_box_def();
	cb.response.restitution = 1.5f;
	CHECK(!eddy_system_valid(w, eddy_add_collide_box(w, &cb)));
	CHECK_HAS(eddy_world_error(w), "collide_box: 'restitution' must be in [0, 1]");
	eddy_collide_plane_def pl = eddy_default_collide_plane_def();
	pl.normal = (eddy_vec3){0, 0, 0};
	CHECK(!eddy_system_valid(w, eddy_add_collide_plane(w, &pl)));
	CHECK_HAS(eddy_world_error(w), "'normal' must be a non-zero vector");
	eddy_emit_nozzle_def nz = eddy_default_emit_nozzle_def();
	nz.speed = NAN;
	CHECK(!eddy_system_valid(w, eddy_add_emit_nozzle(w, &nz)));
	CHECK_HAS(eddy_world_error(w), "emit_nozzle: 'speed' must be > 0");
	CHECK(eddy_world_system_count(w) == 0);
	eddy_destroy_world(w);
}

/* Hard case 16: a count that cannot fit in memory is an error, not a crash. */
static void huge_emitter_is_refused(void)
{
	eddy_world_def d = eddy_default_world_def();
	d.bounds_max = (eddy_vec3){10, 10, 10};
	eddy_world *w = eddy_create_world(&d, NULL, 0);
	eddy_emit_box_def b = eddy_default_emit_box_def();
	b.min = (eddy_vec3){0, 0, 0};
	b.max = (eddy_vec3){10, 10, 10};
	b.spacing = 0.01f; /* 1e9 particles, 36 GB of columns */
	CHECK(eddy_system_valid(w, eddy_add_emit_box(w, &b)));
	eddy_gravity_def g = eddy_default_gravity_def();
	eddy_add_gravity(w, &g);
	eddy_integrate_def it = eddy_default_integrate_def();
	eddy_add_integrate(w, &it);
	CHECK(eddy_world_step(w) == EDDY_ERR_NOMEM);
	CHECK_HAS(eddy_world_error(w), "use a larger spacing");
	CHECK(eddy_world_particle_count(w) == 0);
	eddy_destroy_world(w);
}

/* emit_box with shape = ellipsoid: only lattice points inside the inscribed
 * ellipsoid, on a lattice centred on it, so the drop is mirror-symmetric
 * and holds about its volume / spacing^3 points. */
/* Emitters add water only where there is none (eddy__emit_occupied): two
 * boxes that overlap make one pool of the union's count, whether their
 * lattices coincide, sit half a spacing apart or 0.3 of one; a box emitted
 * later over a pool adds only the part above it; a mesh over a box likewise,
 * and an ellipsoid inside a box adds nothing. Before, the overlap held twice
 * the particles: a 0.1 m deep pool of two boxes overlapping by 0.1 m burst
 * at 21-24 m/s (WCSPH, DFSPH) and 3 m/s (FLIP) (tests/test_physics.c runs
 * it). No two particles are then within half a spacing of each other on
 * every axis. */
static size_t emit_count(const eddy_emit_box_def *boxes, int nb, const eddy_emit_mesh_def *mesh, double *closest)
{
	eddy_world_def d = eddy_default_world_def();
	d.bounds_max = (eddy_vec3){0.4f, 0.3f, 0.1f};
	eddy_world *w = eddy_create_world(&d, NULL, 0);
	for (int k = 0; k < nb; ++k)
		CHECK(eddy_system_valid(w, eddy_add_emit_box(w, &boxes[k])));
	if (mesh)
		CHECKF(eddy_system_valid(w, eddy_add_emit_mesh(w, mesh)), "%s", eddy_world_error(w));
	for (int s = 0; s < 6; ++s) /* 6 ms: the late box's start is 5 ms */
		CHECK(eddy_world_step(w) == EDDY_OK);
	size_t n;
	const float *x = eddy_world_channel(w, "x", &n), *y = eddy_world_channel(w, "y", NULL),
				*z = eddy_world_channel(w, "z", NULL);
	*closest = INFINITY; /* the smallest largest-axis distance of a pair */
	for (size_t i = 0; i < n; ++i)
		for (size_t j = i + 1; j < n; ++j) {
			const double c = fmax(fabs(x[i] - x[j]), fmax(fabs(y[i] - y[j]), fabs(z[i] - z[j])));
			*closest = c < *closest ? c : *closest;
		}
	eddy_destroy_world(w);
	return n;
}

static void emitters_add_water_only_where_there_is_none(void)
{
	eddy_emit_box_def a = eddy_default_emit_box_def(), b = a;
	a.min = (eddy_vec3){0, 0, 0};
	a.max = (eddy_vec3){0.25f, 0.1f, 0.05f};
	b.min = (eddy_vec3){0.15f, 0, 0};
	b.max = (eddy_vec3){0.4f, 0.1f, 0.05f};
	double closest;
	eddy_emit_box_def ab[2] = {a, b};
	size_t n = emit_count(ab, 2, NULL, &closest);
	printf("    two boxes overlapping by 0.1 m, one lattice: %zu particles (the union 2000), closest %.4f m\n", n,
	       closest);
	CHECK(n == 2000);
	CHECK(closest > 0.0099);
	const float shift[2] = {0.005f, 0.003f}; /* half a spacing, and 0.3 of one */
	for (int k = 0; k < 2; ++k) {
		ab[1].min.x = 0.15f + shift[k];
		n = emit_count(ab, 2, NULL, &closest);
		printf("    the second shifted by %.3f m: %zu particles, closest %.4f m\n", shift[k], n, closest);
		CHECK(n >= 1950 && n <= 2000); /* the seam: one column of 50 more or less */
		CHECK(closest > 0.005);        /* no point within half a spacing of another on every axis */
	}
	/* a late box over a pool 5 cm deep: only its part above the pool */
	eddy_emit_box_def pool = a, late = a;
	pool.max = (eddy_vec3){0.4f, 0.05f, 0.05f};
	late.min = (eddy_vec3){0.1f, 0.02f, 0};
	late.max = (eddy_vec3){0.2f, 0.12f, 0.05f};
	late.start = 0.005;
	eddy_emit_box_def pl[2] = {pool, late};
	n = emit_count(pl, 2, NULL, &closest);
	printf("    a box emitted at 5 ms over a pool: %zu particles (pool 1000 + 7 layers above it 350)\n", n);
	CHECK(n == 1000 + 350);
	/* an ellipsoid inside a box adds nothing */
	eddy_emit_box_def el = a;
	el.min = (eddy_vec3){0.05f, 0.02f, 0.01f};
	el.max = (eddy_vec3){0.15f, 0.08f, 0.04f};
	el.shape = EDDY_EMIT_ELLIPSOID;
	eddy_emit_box_def ae[2] = {a, el};
	n = emit_count(ae, 2, NULL, &closest);
	CHECK(n == 1250);
	/* a mesh cube 0.1 m over the box's end, 0.05 m past it */
	eddy_emit_mesh_def m = eddy_default_emit_mesh_def();
	strcpy(m.path, "scenes/meshes/cube.obj");
	m.scale = (eddy_vec3){0.1f, 0.1f, 0.05f};
	m.translate = (eddy_vec3){0.2f, 0, 0};
	m.spacing = 0.01f;
	n = emit_count(&a, 1, &m, &closest);
	printf("    a mesh cube half over a box: %zu particles (1250 + 250), closest %.4f m\n", n, closest);
	CHECK(n == 1250 + 250);
	CHECK(closest > 0.0099);
}

/* Emitters leave out the points inside a collider's solid
 * (eddy__emit_occupied): a box around a sphere, a box obstacle off the
 * lattice and a mesh cube holds exactly the box's points outside them, and
 * no particle starts inside one; a tank (a box collider with inside = true,
 * whose solid is outside it) takes none. Before, every point was emitted and
 * the collider pushed the water inside it out in the first step: a pool
 * around a 4 cm sphere burst at 15 m/s (WCSPH; tests/test_physics.c runs
 * the pools). */
static void emitters_fill_around_solids(void)
{
	eddy_emit_box_def b = eddy_default_emit_box_def();
	b.max = (eddy_vec3){0.2f, 0.1f, 0.1f}; /* 2000 points at (i + 1/2) cm, 128,000 at 2.5 mm */
	/* cases 0-3 at 1 cm; 4 and 5 (the sphere and the box) at 2.5 mm on two
	 * threads, where the solids' test runs on the threads */
	size_t want_sphere = 0;
	for (int kk = 0; kk < 6; ++kk) {
		const int k = kk % 4, m = kk < 4 ? 1 : 4; /* lattice points per cm */
		b.spacing = 0.01f / (float)m;
		eddy_world_def d = eddy_default_world_def();
		d.bounds_max = (eddy_vec3){0.2f, 0.2f, 0.1f};
		d.threads = kk < 4 ? 1 : 2;
		eddy_world *w = eddy_create_world(&d, NULL, 0);
		CHECK(eddy_system_valid(w, eddy_add_emit_box(w, &b)));
		const eddy_vec3 c = {0.083f, 0.047f, 0.052f};
		const float r = 0.031f;
		const eddy_vec3 lo = {0.052f, 0.013f, 0.021f}, hi = {0.137f, 0.071f, 0.060f};
		if (k == 0) {
			eddy_collide_sphere_def s = eddy_default_collide_sphere_def();
			s.center = c;
			s.radius = r;
			CHECK(eddy_system_valid(w, eddy_add_collide_sphere(w, &s)));
		} else if (k == 1 || k == 3) {
			eddy_collide_box_def s = eddy_default_collide_box_def();
			s.min = k == 1 ? lo : d.bounds_min;
			s.max = k == 1 ? hi : d.bounds_max;
			s.inside = k == 3;
			CHECK(eddy_system_valid(w, eddy_add_collide_box(w, &s)));
		} else {
			eddy_collide_mesh_def s = eddy_default_collide_mesh_def();
			strcpy(s.path, "scenes/meshes/cube.obj"); /* the unit cube [0, 1]^3 */
			s.scale = (eddy_vec3){hi.x - lo.x, hi.y - lo.y, hi.z - lo.z};
			s.translate = lo;
			CHECKF(eddy_system_valid(w, eddy_add_collide_mesh(w, &s)), "%s", eddy_world_error(w));
		}
		CHECKF(eddy_world_step(w) == EDDY_OK, "%s", eddy_world_error(w));
		/* the lattice points outside the solid, counted here */
		size_t want = 0;
		const double sp = 0.01 / m;
		for (int i = 0; i < 20 * m; ++i)
			for (int j = 0; j < 10 * m; ++j)
				for (int l = 0; l < 10 * m; ++l) {
					const double x = sp * (i + 0.5), y = sp * (j + 0.5), z = sp * (l + 0.5);
					bool in = false;
					if (k == 0)
						in = (x - c.x) * (x - c.x) + (y - c.y) * (y - c.y) + (z - c.z) * (z - c.z) < (double)r * r;
					else if (k == 1 || k == 2)
						in = x > lo.x && x < hi.x && y > lo.y && y < hi.y && z > lo.z && z < hi.z;
					want += !in;
				}
		size_t n;
		const float *x = eddy_world_channel(w, "x", &n), *y = eddy_world_channel(w, "y", NULL),
					*z = eddy_world_channel(w, "z", NULL);
		size_t inside = 0;
		for (size_t i = 0; i < n; ++i) {
			const double px = x[i], py = y[i], pz = z[i];
			if (k == 0)
				inside += (px - c.x) * (px - c.x) + (py - c.y) * (py - c.y) + (pz - c.z) * (pz - c.z) < (double)r * r;
			else if (k == 1 || k == 2)
				inside += px > lo.x && px < hi.x && py > lo.y && py < hi.y && pz > lo.z && pz < hi.z;
		}
		static const char *const solid[] = {"a sphere", "a box", "a mesh cube", "a tank"};
		printf(
			"    a box around %s, spacing %g m: %zu particles (%zu lattice points outside the solid), %zu inside it\n",
			solid[k], sp, n, want, inside);
		CHECK(n == want);
		CHECK(inside == 0);
		CHECK(k != 3 || n == 2000);
		if (kk == 0)
			want_sphere = want;
		eddy_destroy_world(w);
	}
	/* emit_mesh likewise: a mesh cube on the box's lattice around the sphere */
	eddy_world_def d = eddy_default_world_def();
	d.bounds_max = (eddy_vec3){0.2f, 0.2f, 0.1f};
	eddy_world *w = eddy_create_world(&d, NULL, 0);
	eddy_emit_mesh_def em = eddy_default_emit_mesh_def();
	strcpy(em.path, "scenes/meshes/cube.obj");
	em.scale = (eddy_vec3){0.2f, 0.1f, 0.1f};
	em.spacing = 0.01f;
	CHECKF(eddy_system_valid(w, eddy_add_emit_mesh(w, &em)), "%s", eddy_world_error(w));
	eddy_collide_sphere_def sph = eddy_default_collide_sphere_def();
	sph.center = (eddy_vec3){0.083f, 0.047f, 0.052f};
	sph.radius = 0.031f;
	CHECK(eddy_system_valid(w, eddy_add_collide_sphere(w, &sph)));
	CHECKF(eddy_world_step(w) == EDDY_OK, "%s", eddy_world_error(w));
	size_t n;
	eddy_world_channel(w, "x", &n);
	printf("    a mesh cube around the sphere: %zu particles (the box's %zu)\n", n, want_sphere);
	CHECK(n == want_sphere);
	eddy_destroy_world(w);
}

/* A block exactly k spacings long holds k layers, for the sides and
 * spacings a user writes in decimals (taken to float as the API does),
 * from the origin and away from it: a fixed tolerance of 1e-6 spacings
 * lost a layer wherever the floats' rounding left the ratio further below
 * k (0.04 m at 1 mm read 39.99999725: a dam break at 1 cm lost 5% of its
 * water; from 10 m, 39.99996). Also a nozzle exactly k
 * spacings in radius reaches k spacings out. */
static void emitters_count_whole_spacings(void)
{
	static const double spacings[] = {0.001, 0.0005, 0.003, 0.007, 0.01, 0.025, 0.1, 0.00025};
	static const double offsets[] = {0, 10, -3.7}; /* m: far from the origin the corners round more */
	int cases = 0, wrong = 0;
	for (size_t o = 0; o < sizeof offsets / sizeof offsets[0]; ++o)
		for (size_t s = 0; s < sizeof spacings / sizeof spacings[0]; ++s)
			for (int k = 1; k <= 120; ++k) {
				const double h = spacings[s], x0 = offsets[o];
				eddy_world_def d = eddy_default_world_def();
				d.bounds_min = (eddy_vec3){(float)(x0 - h), 0, 0};
				d.bounds_max = (eddy_vec3){(float)(x0 + 130 * h), (float)(2 * h), (float)(2 * h)};
				eddy_world *w = eddy_create_world(&d, NULL, 0);
				eddy_emit_box_def b = eddy_default_emit_box_def();
				b.min = (eddy_vec3){(float)x0, 0, 0};
				b.max = (eddy_vec3){(float)(x0 + k * h), (float)h, (float)h};
				b.spacing = (float)h;
				eddy_add_emit_box(w, &b);
				CHECK(eddy_world_step(w) == EDDY_OK);
				const size_t n = eddy_world_particle_count(w);
				if (n != (size_t)k && wrong++ < 5)
					printf("    %d spacings of %g m from x = %g: %zu particles\n", k, h, x0, n);
				cases++;
				eddy_destroy_world(w);
			}
	printf("    blocks of 1-120 whole spacings at %zu spacings and %zu offsets: %d of %d counts wrong\n",
	       sizeof spacings / sizeof spacings[0], sizeof offsets / sizeof offsets[0], wrong, cases);
	CHECK(wrong == 0);
	for (int k = 1; k <= 40; ++k) {
		eddy_world_def d = eddy_default_world_def();
		eddy_world *w = eddy_create_world(&d, NULL, 0);
		eddy_emit_nozzle_def nz = eddy_default_emit_nozzle_def();
		nz.spacing = 0.0007f;
		nz.radius = (float)(k * 0.0007);
		nz.max_particles = 1000000;
		eddy_add_emit_nozzle(w, &nz);
		CHECK(eddy_world_step(w) == EDDY_OK);
		size_t n;
		const float *x = eddy_world_channel(w, "x", &n);
		double reach = 0;
		for (size_t i = 0; i < n; ++i)
			reach = fmax(reach, fabs(x[i] - nz.center.x));
		CHECKF(fabs(reach - k * 0.0007) < 1e-6, "nozzle of %d spacings reaches %g m", k, reach);
		eddy_destroy_world(w);
	}
}

static void ellipsoid_emitter(void)
{
	eddy_world_def d = eddy_default_world_def();
	d.bounds_min = (eddy_vec3){-1, -1, -1};
	d.gravity = (eddy_vec3){0, 0, 0};
	eddy_world *w = eddy_create_world(&d, NULL, 0);
	eddy_emit_box_def b = eddy_default_emit_box_def();
	const double a = 0.12, c = 0.1, e = 0.08, dx = 0.01; /* semi-axes, m */
	b.min = (eddy_vec3){(float)(0.3 - a), (float)(-0.2 - c), (float)(0.1 - e)};
	b.max = (eddy_vec3){(float)(0.3 + a), (float)(-0.2 + c), (float)(0.1 + e)};
	b.spacing = (float)dx;
	b.shape = EDDY_EMIT_ELLIPSOID;
	CHECK(eddy_system_valid(w, eddy_add_emit_box(w, &b)));
	eddy_gravity_def g = eddy_default_gravity_def();
	eddy_add_gravity(w, &g);
	eddy_integrate_def it = eddy_default_integrate_def();
	eddy_add_integrate(w, &it);
	CHECK(eddy_world_step(w) == EDDY_OK);
	size_t n;
	const float *x = eddy_world_channel(w, "x", &n), *y = eddy_world_channel(w, "y", NULL),
				*z = eddy_world_channel(w, "z", NULL);
	const double volume = 4.0 / 3.0 * 3.14159265358979 * a * c * e / (dx * dx * dx);
	printf("    ellipsoid: %zu particles, volume / spacing^3 = %.0f\n", n, volume);
	CHECK(fabs((double)n / volume - 1) < 0.03);
	double cx = 0, cy = 0, cz = 0, outside = 0;
	for (size_t i = 0; i < n; ++i) {
		const double u = (x[i] - 0.3) / a, v = (y[i] + 0.2) / c, q = (z[i] - 0.1) / e;
		outside += u * u + v * v + q * q > 1 + 1e-5;
		cx += x[i];
		cy += y[i];
		cz += z[i];
	}
	CHECK(outside == 0);
	CHECK_NEAR(cx / (double)n, 0.3, 1e-5);
	CHECK_NEAR(cy / (double)n, -0.2, 1e-5);
	CHECK_NEAR(cz / (double)n, 0.1, 1e-5);
	b.shape = (eddy_emit_shape)7;
	CHECK(!eddy_system_valid(w, eddy_add_emit_box(w, &b)));
	CHECK_HAS(eddy_world_error(w), "emit_box: 'shape' must be block or ellipsoid");
	eddy_destroy_world(w);
}

static eddy_status poison_step(eddy_world *w, const eddy_step_context *ctx, void *user)
{
	(void)user;
	if (ctx->step == 5) {
		float *vx = eddy_world_channel_mut(w, "vx", NULL);
		vx[3] = NAN;
	}
	return EDDY_OK;
}

static void nonfinite_names_system_step_particle(void)
{
	eddy_world *w = make_world();
	eddy_emit_box_def b = eddy_default_emit_box_def();
	b.min = (eddy_vec3){0.2f, 0.2f, 0.2f};
	b.max = (eddy_vec3){0.3f, 0.3f, 0.3f};
	eddy_add_emit_box(w, &b);
	const char *writes[] = {"vx"};
	eddy_custom_system_def c = eddy_default_custom_system_def();
	c.name = "poison";
	c.writes = writes;
	c.write_count = 1;
	c.step = poison_step;
	eddy_add_custom_system(w, &c);
	eddy_status st = EDDY_OK;
	for (int i = 0; i < 10 && st == EDDY_OK; ++i)
		st = eddy_world_step(w);
	CHECK(st == EDDY_ERR_NUMERIC);
	CHECK_HAS(eddy_world_error(w), "poison: non-finite vx = nan of particle 3 at step 5");
	CHECK(eddy_world_steps(w) == 5);
	eddy_destroy_world(w);
}

static eddy_status failing_step(eddy_world *w, const eddy_step_context *ctx, void *user)
{
	(void)ctx, (void)user;
	return eddy_world_fail(w, EDDY_ERR_IO, "cannot open 'x.bin'");
}

static void custom_system_errors_are_labelled(void)
{
	eddy_world *w = make_world();
	eddy_custom_system_def c = eddy_default_custom_system_def();
	c.name = "writer";
	c.step = failing_step;
	CHECK(eddy_system_valid(w, eddy_add_custom_system(w, &c)));
	CHECK(eddy_world_step(w) == EDDY_ERR_IO);
	CHECK_HAS(eddy_world_error(w), "writer: step 0 (t = 0 s): cannot open 'x.bin'");
	c.step = NULL;
	CHECK(!eddy_system_valid(w, eddy_add_custom_system(w, &c)));
	CHECK_HAS(eddy_world_error(w), "needs a step or a frame callback");
	eddy_destroy_world(w);
}

static void arena_is_plain_memory(void)
{
	/* emit_nozzle takes its disc from the arena every emission; many
	 * emissions must neither leak (asan) nor corrupt the emitted lattice. */
	eddy_world_def d = eddy_default_world_def();
	d.gravity = (eddy_vec3){0, 0, 0};
	d.escape = EDDY_ESCAPE_REMOVE;
	eddy_world *w = eddy_create_world(&d, NULL, 0);
	eddy_emit_nozzle_def nz = eddy_default_emit_nozzle_def();
	nz.center = (eddy_vec3){0.5f, 0.5f, 0.5f};
	nz.direction = (eddy_vec3){1, 0, 0};
	nz.speed = 2.0f;
	nz.radius = 0.05f;
	nz.spacing = 0.01f;
	eddy_add_emit_nozzle(w, &nz);
	eddy_gravity_def g = eddy_default_gravity_def();
	eddy_add_gravity(w, &g);
	eddy_integrate_def it = eddy_default_integrate_def();
	eddy_add_integrate(w, &it);
	CHECK(eddy_world_advance(w, 0.2) == EDDY_OK);
	size_t n;
	const float *y = eddy_world_channel(w, "y", &n);
	CHECK(n > 0);
	for (size_t i = 0; i < n; ++i)
		CHECKF(fabsf(y[i] - 0.5f) <= 0.0501f, "particle %zu at y = %g, outside the jet", i, (double)y[i]);
	eddy_destroy_world(w);
}

typedef struct findings {
	char text[2048];
	int errors;
} findings;

static void collect(eddy_check_level level, const char *message, void *user)
{
	findings *f = user;
	size_t n = strlen(f->text);
	snprintf(f->text + n, sizeof f->text - n, "%s\n", message);
	f->errors += level == EDDY_CHECK_ERROR;
}

static void preflight_findings(void)
{
	eddy_world_def d = eddy_default_world_def();
	d.cell_size = 0.1;
	eddy_world *w = eddy_create_world(&d, NULL, 0);
	eddy_emit_box_def b = eddy_default_emit_box_def(); /* spacing 0.01 */
	eddy_add_emit_box(w, &b);
	const char *writes[] = {"u"};
	eddy_custom_system_def c = eddy_default_custom_system_def();
	c.name = "grid_user";
	c.writes = writes;
	c.write_count = 1;
	c.step = noop_step;
	eddy_add_custom_system(w, &c);
	eddy_collide_sphere_def s = eddy_default_collide_sphere_def();
	s.center = (eddy_vec3){0.05f, 0.05f, 0.05f};
	s.radius = 0.02f;
	eddy_add_collide_sphere(w, &s);
	findings f = {"", 0};
	CHECK(eddy_world_check(w, collect, &f) == 0);
	CHECK_HAS(f.text, "particles per cell: 1000.0 (cell_size 0.1 m, spacing 0.01 m)");
	CHECK_HAS(f.text, "e.g. spacing = 0.05 m");
	CHECK_HAS(f.text, "emit_box: 32 of 1000 particles start inside collide_sphere; they are left out");
	CHECK_HAS(f.text, "memory: 1000 particles x 24 bytes");
	eddy_destroy_world(w);
}

static bool is_null_system(eddy_system_id id) { return id.index == 0 && id.generation == 0; }

/* Each eddy_add_* with a NULL world and with a NULL def. */
#define CHECK_ADDER(kind)                                   \
	do {                                                    \
		eddy_##kind##_def d_ = eddy_default_##kind##_def(); \
		CHECK(is_null_system(eddy_add_##kind(NULL, &d_)));  \
		CHECK(is_null_system(eddy_add_##kind(NULL, NULL))); \
		CHECK(is_null_system(eddy_add_##kind(w, NULL)));    \
		CHECK_HAS(eddy_world_error(w), "def is NULL");      \
	} while (0)

/* Every public function of eddy.h with NULL in each pointer argument: no
 * crash, and the neutral value or status eddy.h's header comment documents. */
static void null_arguments_are_refused(void)
{
	eddy_world *w = make_world();
	eddy_world_def wd = eddy_default_world_def();
	char err[64] = "untouched";
	CHECK(eddy_create_world(NULL, err, sizeof err) == NULL);
	CHECK_HAS(err, "def is NULL");
	CHECK(eddy_create_world(NULL, NULL, 16) == NULL);
	eddy_world *w2 = eddy_create_world(&wd, NULL, 16);
	CHECK(w2 != NULL);
	eddy_destroy_world(w2);
	eddy_destroy_world(NULL);
	CHECK(eddy_world_error(NULL) != NULL);
	CHECK(eddy_world_fail(NULL, EDDY_ERR_EXTERNAL, "x %d", 1) == EDDY_ERR_EXTERNAL);
	CHECK(eddy_world_fail(w, EDDY_ERR_EXTERNAL, NULL) == EDDY_ERR_EXTERNAL);
	CHECK(eddy_world_get_def(NULL) == NULL);
	CHECK(eddy_world_set_threads(NULL, 2) == EDDY_ERR_INVALID);
	CHECK(isnan(eddy_world_time(NULL)));
	CHECK(isnan(eddy_world_frame_time(NULL)));
	CHECK(eddy_world_frame(NULL) == 0);
	CHECK(eddy_world_steps(NULL) == 0);
	CHECK(isnan(eddy_world_last_dt(NULL)));
	CHECK(eddy_world_step(NULL) == EDDY_ERR_INVALID);
	CHECK(eddy_world_step_frame(NULL) == EDDY_ERR_INVALID);
	CHECK(eddy_world_advance(NULL, 0.1) == EDDY_ERR_INVALID);

	/* columns */
	eddy_column_info info;
	CHECK(eddy_world_column_count(NULL) == 0);
	CHECK(eddy_world_find_column(NULL, "x") < 0);
	CHECK(eddy_world_find_column(w, NULL) < 0);
	CHECK(eddy_world_column_info(NULL, 0, &info) == EDDY_ERR_INVALID);
	CHECK(eddy_world_column_info(w, 0, NULL) == EDDY_ERR_INVALID);
	CHECK(eddy_world_declare_column(NULL, "t", EDDY_DOMAIN_PARTICLE, EDDY_F32, EDDY_STATE, "K") < 0);
	CHECK(eddy_world_declare_column(w, NULL, EDDY_DOMAIN_PARTICLE, EDDY_F32, EDDY_STATE, "K") < 0);
	CHECK(eddy_world_declare_column(w, "t_no_unit", EDDY_DOMAIN_PARTICLE, EDDY_F32, EDDY_STATE, NULL) >= 0);
	size_t count = 7;
	CHECK(eddy_world_channel(NULL, "x", &count) == NULL && count == 0);
	CHECK(eddy_world_channel(w, NULL, &count) == NULL);
	CHECK(eddy_world_channel(w, "x", NULL) == NULL);
	CHECK(eddy_world_channel_mut(NULL, "x", &count) == NULL);
	CHECK(eddy_world_channel_mut(w, NULL, NULL) == NULL);
	CHECK(eddy_world_channel_u8(NULL, "cell_type", &count) == NULL);
	CHECK(eddy_world_channel_u8(w, NULL, NULL) == NULL);
	CHECK(eddy_world_particle_count(NULL) == 0);
	eddy_vec3 p = {0.5f, 0.5f, 0.5f};
	CHECK(eddy_world_add_particles(NULL, 1, &p, NULL) == EDDY_ERR_INVALID);
	CHECK(eddy_world_add_particles(w, 1, NULL, NULL) == EDDY_ERR_INVALID);
	CHECK(eddy_world_remove_particle(NULL, 0) == EDDY_ERR_INVALID);
	CHECK(!eddy_world_grid(NULL).allocated);
	CHECK(eddy_world_state_hash(NULL) == 0);

	/* pipeline */
	eddy_system_info si;
	CHECK(eddy_world_system_count(NULL) == 0);
	CHECK(is_null_system(eddy_world_system_at(NULL, 0)));
	CHECK(eddy_world_system_info(NULL, EDDY_NULL_SYSTEM, &si) == EDDY_ERR_INVALID);
	CHECK(eddy_world_system_info(w, EDDY_NULL_SYSTEM, NULL) == EDDY_ERR_INVALID);
	CHECK(!eddy_system_valid(NULL, EDDY_NULL_SYSTEM));
	CHECK(eddy_world_remove_system(NULL, EDDY_NULL_SYSTEM) == EDDY_ERR_INVALID);
	char plan[16] = "untouched";
	CHECK(eddy_world_plan(NULL, plan, sizeof plan) == 0 && plan[0] == '\0');
	CHECK(eddy_world_plan(w, NULL, 100) > 0);
	CHECK(eddy_world_plan_dot(NULL, plan, sizeof plan) == 0);
	CHECK(eddy_world_plan_dot(w, NULL, 100) > 0);

	/* systems */
	CHECK_ADDER(custom_system);
	eddy_custom_system_def cd = eddy_default_custom_system_def();
	cd.step = noop_step;
	cd.name = NULL;
	CHECK(is_null_system(eddy_add_custom_system(w, &cd)));
	CHECK_HAS(eddy_world_error(w), "'name'");
	cd.name = "c";
	cd.step = NULL;
	CHECK(is_null_system(eddy_add_custom_system(w, &cd)));
	CHECK_HAS(eddy_world_error(w), "needs a step or a frame callback");
	cd.step = noop_step;
	cd.read_count = 1; /* reads is NULL */
	CHECK(is_null_system(eddy_add_custom_system(w, &cd)));
	CHECK_ADDER(emit_box);
	CHECK_ADDER(emit_nozzle);
	CHECK_ADDER(gravity);
	CHECK_ADDER(integrate);
	CHECK_ADDER(collide_box);
	CHECK_ADDER(collide_sphere);
	CHECK_ADDER(collide_plane);
	CHECK_ADDER(sph_density);
	CHECK_ADDER(sph_pressure);
	CHECK_ADDER(sph_viscosity);
	CHECK_ADDER(sph_surface_tension);
	CHECK_ADDER(sph_boundary_box);
	CHECK_ADDER(sph_dfsph);
	CHECK_ADDER(flip_p2g);
	CHECK_ADDER(flip_boundary);
	CHECK_ADDER(flip_surface);
	CHECK_ADDER(flip_pressure);
	CHECK_ADDER(flip_extrapolate);
	CHECK_ADDER(flip_g2p);
	CHECK_ADDER(flip_advect);
	CHECK_ADDER(flip_reseed);
	CHECK_ADDER(render_points);
	CHECK_ADDER(export_particles);
	CHECK(eddy_sph_particle_mass(NULL, EDDY_NULL_SYSTEM) == 0);
	/* not pointers, but a mistaken lattice must not hang the host */
	CHECK(isnan(eddy_sph_lattice_sum(EDDY_SPH_POLY6, 1e-9, 1)));
	CHECK(isnan(eddy_sph_lattice_gradient_moment(EDDY_SPH_SPIKY, 1e-9, 1)));

	/* colliders */
	eddy_collide_box_def bd = eddy_default_collide_box_def();
	eddy_system_id box = eddy_add_collide_box(w, &bd);
	CHECK(eddy_system_valid(w, box));
	eddy_vec3 off;
	float dist;
	eddy_collider_shape shape;
	CHECK(eddy_collider_set_offset(NULL, box, p) == EDDY_ERR_INVALID);
	CHECK(eddy_collider_get_offset(NULL, box, &off) == EDDY_ERR_INVALID);
	CHECK(eddy_collider_get_offset(w, box, NULL) == EDDY_ERR_INVALID);
	CHECK(eddy_collider_distance(NULL, box, p, &dist) == EDDY_ERR_INVALID);
	CHECK(eddy_collider_distance(w, box, p, NULL) == EDDY_ERR_INVALID);
	CHECK(eddy_collider_shape_of(NULL, box, &shape) == EDDY_ERR_INVALID);
	CHECK(eddy_collider_shape_of(w, box, NULL) == EDDY_ERR_INVALID);

	/* statistics, checkpoints, preflight */
	eddy_frame_stats fs;
	CHECK(eddy_world_frame_stats(NULL, &fs) == EDDY_ERR_INVALID);
	CHECK(eddy_world_frame_stats(w, NULL) == EDDY_ERR_INVALID);
	eddy_world_publish(NULL, "a", 1);
	eddy_world_publish(w, NULL, 1);
	eddy_world_publish_text(NULL, "a", "b");
	eddy_world_publish_text(w, NULL, "b");
	eddy_world_publish_text(w, "a", NULL);
	eddy_world_set_rest_density(NULL, 1000);
	CHECK(eddy_world_save(NULL, "/tmp/eddy_null.ckpt", 0) == EDDY_ERR_INVALID);
	CHECK(eddy_world_save(w, NULL, 0) == EDDY_ERR_INVALID);
	CHECK(eddy_world_load(NULL, "/tmp/eddy_null.ckpt", 0) == EDDY_ERR_INVALID);
	CHECK(eddy_world_load(w, NULL, 0) == EDDY_ERR_INVALID);
	CHECK(eddy_world_check(NULL, NULL, NULL) == 1);
	CHECK(eddy_world_check(w, NULL, NULL) == 0);

	/* the world still works */
	CHECK(eddy_world_step(w) == EDDY_OK);
	eddy_destroy_world(w);
}

/* What a callback tried, and what each call returned. */
typedef struct reentry {
	eddy_status step, step_frame, advance, add, remove, load, threads;
	bool added_valid;
	char error[512];
	double time_seen;
	int calls;
	eddy_system_id self;
} reentry;

static void try_reentry(eddy_world *w, reentry *r)
{
	if (r->calls++ > 0)
		return;
	r->step = eddy_world_step(w);
	r->step_frame = eddy_world_step_frame(w);
	r->advance = eddy_world_advance(w, 0.1);
	snprintf(r->error, sizeof r->error, "%s", eddy_world_error(w));
	eddy_gravity_def g = eddy_default_gravity_def();
	r->added_valid = eddy_system_valid(w, eddy_add_gravity(w, &g));
	r->remove = eddy_world_remove_system(w, r->self);
	r->load = eddy_world_load(w, "/nonexistent/eddy.ckpt", 0);
	r->threads = eddy_world_set_threads(w, 2);
	eddy_destroy_world(w); /* refused: the step still uses the world */
	/* reading stays allowed */
	r->time_seen = eddy_world_time(w);
	eddy_frame_stats fs;
	CHECK(eddy_world_frame_stats(w, &fs) == EDDY_OK);
}

static eddy_status reenter_step(eddy_world *w, const eddy_step_context *ctx, void *user)
{
	(void)ctx;
	try_reentry(w, user);
	return EDDY_OK;
}

static eddy_status reenter_frame(eddy_world *w, int frame, void *user)
{
	(void)frame;
	try_reentry(w, user);
	return EDDY_OK;
}

static void check_reentry_refused(const reentry *r, const char *where)
{
	CHECK(r->calls > 0);
	CHECK(r->step == EDDY_ERR_INVALID);
	CHECK(r->step_frame == EDDY_ERR_INVALID);
	CHECK(r->advance == EDDY_ERR_INVALID);
	CHECK(!r->added_valid);
	CHECK(r->remove == EDDY_ERR_INVALID);
	CHECK(r->load == EDDY_ERR_INVALID);
	CHECK(r->threads == EDDY_ERR_INVALID);
	char want[128];
	snprintf(want, sizeof want, "eddy_world_advance called from inside %s", where);
	CHECK_HAS(r->error, want);
}

/* A step or frame callback that steps the world again would run frames
 * inside frames (0.3 s simulated for 0.2 asked); such calls are refused and
 * the run keeps its clock. */
static void callbacks_cannot_reenter(void)
{
	for (int frame_hook = 0; frame_hook < 2; ++frame_hook) {
		eddy_world *w = make_world();
		reentry r;
		memset(&r, 0, sizeof r);
		eddy_custom_system_def c = eddy_default_custom_system_def();
		c.name = "reenter";
		if (frame_hook)
			c.frame = reenter_frame;
		else
			c.step = reenter_step;
		c.user = &r;
		r.self = eddy_add_custom_system(w, &c);
		CHECK(eddy_system_valid(w, r.self));
		CHECK(eddy_world_advance(w, 0.2) == EDDY_OK);
		check_reentry_refused(&r, frame_hook ? "a frame callback" : "a step callback");
		CHECK_NEAR(eddy_world_time(w), 0.2, 1e-12);
		CHECK(eddy_world_frame(w) == 6);
		CHECK(eddy_world_system_count(w) == 1);
		CHECK(eddy_world_get_def(w)->threads == 1);
		/* outside a callback the same calls work again */
		CHECK(eddy_world_step_frame(w) == EDDY_OK);
		CHECK(eddy_world_frame(w) == 7);
		CHECK(eddy_world_set_threads(w, 2) == EDDY_OK);
		eddy_destroy_world(w);
	}
}

/* One emitter of the given spacing in [0.1, 0.3]^3 of a default world with
 * fps and duration, the findings of eddy_world_check in f. */
static eddy_world *spacing_world(float spacing, double fps, double duration)
{
	eddy_world_def d = eddy_default_world_def();
	d.fps = fps;
	d.duration = duration;
	eddy_world *w = eddy_create_world(&d, NULL, 0);
	eddy_emit_box_def b = eddy_default_emit_box_def();
	b.min = (eddy_vec3){0.1f, 0.1f, 0.1f};
	b.max = (eddy_vec3){0.3f, 0.3f, 0.3f};
	b.spacing = spacing;
	eddy_add_emit_box(w, &b);
	return w;
}

/* A FLIP world (cells of cell_size) with spacing_world's block at spacing,
 * a second block beside it at spacing2 unless that is 0, then gravity and
 * flip_p2g: what the preflight's FLIP checks look at. */
static eddy_world *flip_world(double cell_size, float spacing, float spacing2)
{
	eddy_world_def d = eddy_default_world_def();
	d.cell_size = cell_size;
	eddy_world *w = eddy_create_world(&d, NULL, 0);
	eddy_emit_box_def b = eddy_default_emit_box_def();
	b.min = (eddy_vec3){0.1f, 0.1f, 0.1f};
	b.max = (eddy_vec3){0.3f, 0.3f, 0.3f};
	b.spacing = spacing;
	CHECK(eddy_system_valid(w, eddy_add_emit_box(w, &b)));
	if (spacing2 > 0) {
		b.min.x += 0.4f, b.max.x += 0.4f;
		b.spacing = spacing2;
		CHECK(eddy_system_valid(w, eddy_add_emit_box(w, &b)));
	}
	eddy_gravity_def g = eddy_default_gravity_def();
	CHECK(eddy_system_valid(w, eddy_add_gravity(w, &g)));
	eddy_flip_p2g_def pg = eddy_default_flip_p2g_def();
	CHECKF(eddy_system_valid(w, eddy_add_flip_p2g(w, &pg)), "%s", eddy_world_error(w));
	return w;
}

/* A collider added where the water already is (between steps) pushes the
 * particles inside its solid out in its first step, a burst in SPH: a
 * run-time warning names it, the count and a particle; one added clear of
 * the water, or before any, says nothing. */
static void collider_added_into_water_warns(void)
{
	eddy_world *w = spacing_world(0.01f, 30, 2);
	eddy_gravity_def gr = eddy_default_gravity_def();
	CHECK(eddy_system_valid(w, eddy_add_gravity(w, &gr)));
	eddy_integrate_def it = eddy_default_integrate_def();
	CHECKF(eddy_system_valid(w, eddy_add_integrate(w, &it)), "%s", eddy_world_error(w));
	eddy_collide_sphere_def away = eddy_default_collide_sphere_def();
	away.center = (eddy_vec3){0.7f, 0.7f, 0.7f};
	away.radius = 0.1f;
	CHECK(eddy_system_valid(w, eddy_add_collide_sphere(w, &away)));
	CHECK(eddy_world_step_frame(w) == EDDY_OK);
	CHECK(eddy_world_particle_count(w) == 8000);
	CHECK(eddy_world_warning_count(w) == 0);
	eddy_collide_sphere_def in = eddy_default_collide_sphere_def();
	in.center = (eddy_vec3){0.2f, 0.2f, 0.2f};
	in.radius = 0.05f;
	CHECK(eddy_system_valid(w, eddy_add_collide_sphere(w, &in)));
	CHECK(eddy_world_warning_count(w) == 1);
	const char *msg = eddy_world_warning(w, 0);
	CHECK_HAS(msg, "collide_sphere#2: added at step 4 (t = 0.0333333 s) with 524 particles inside its solid");
	CHECK_HAS(msg, "add it before the water");
	eddy_destroy_world(w);
}

/* Scene mistakes that run without an error but give a wrong answer are
 * errors of the check (and so refused by eddy run). */
static void check_catches_scene_mistakes(void)
{
	/* sph_density left at its default spacing (0.01 m) under an emitter at 0.02 m */
	eddy_world *w = spacing_world(0.02f, 30, 2);
	eddy_sph_density_def de = eddy_default_sph_density_def();
	CHECK(eddy_system_valid(w, eddy_add_sph_density(w, &de)));
	findings f = {"", 0};
	CHECK(eddy_world_check(w, collect, &f) == 1);
	CHECK_HAS(f.text, "sph_density: 'spacing' is 0.01 m but emit_box emits at spacing 0.02 m");
	CHECK_HAS(f.text, "0.12 x rest density and collapses; set sph_density's spacing = 0.02 (and radius = 0.04)");
	eddy_destroy_world(w);

	/* the same with the spacings matched: no error */
	w = spacing_world(0.01f, 30, 2);
	CHECK(eddy_system_valid(w, eddy_add_sph_density(w, &de)));
	memset(&f, 0, sizeof f);
	CHECK(eddy_world_check(w, collect, &f) == 0);
	/* a nozzle off the lattice */
	eddy_emit_nozzle_def nz = eddy_default_emit_nozzle_def();
	nz.center = (eddy_vec3){0.5f, 0.8f, 0.5f};
	nz.spacing = 0.005f;
	nz.max_particles = 1000;
	CHECK(eddy_system_valid(w, eddy_add_emit_nozzle(w, &nz)));
	memset(&f, 0, sizeof f);
	CHECK(eddy_world_check(w, collect, &f) == 1);
	CHECK_HAS(f.text, "emit_nozzle emits at spacing 0.005 m");
	CHECK_HAS(f.text, "8.00 x rest density and blows apart");
	eddy_destroy_world(w);

	/* FLIP with two emitters at different spacings: every particle counts
	 * the same volume, from the finest spacing (a block at 1 cm beside one
	 * at 5 mm read 1/8 full and the two settled at 0.52 and 0.69 of the height they should have) */
	for (int same = 0; same < 2; ++same) {
		w = flip_world(0.02, 0.01f, same ? 0.01f : 0.005f);
		memset(&f, 0, sizeof f);
		eddy_world_check(w, collect, &f);
		if (same) {
			CHECK(strstr(f.text, "FLIP counts every particle") == NULL);
		} else {
			CHECK_HAS(f.text, "flip_p2g: emit_box emits at spacing 0.01 m and emit_box#2 at 0.005 m: FLIP counts "
			                  "every particle as the same volume (cell_size^3 / 64, from the finest spacing), so "
			                  "emit_box's water would read 0.125 of its volume");
		}
		eddy_destroy_world(w);
	}

	/* a kernel barely wider than the spacing */
	w = spacing_world(0.01f, 30, 2);
	de.radius = 0.011f;
	CHECK(eddy_system_valid(w, eddy_add_sph_density(w, &de)));
	memset(&f, 0, sizeof f);
	CHECK(eddy_world_check(w, collect, &f) == 1);
	CHECK_HAS(f.text, "sph_density: 'radius' 0.011 m is 1.10 x 'spacing' 0.01 m, below 1.2");
	eddy_destroy_world(w);

	/* a block emitted after the run, and nothing to move it */
	w = spacing_world(0.01f, 30, 2);
	eddy_emit_box_def late = eddy_default_emit_box_def();
	late.start = 2.5;
	CHECK(eddy_system_valid(w, eddy_add_emit_box(w, &late)));
	memset(&f, 0, sizeof f);
	CHECK(eddy_world_check(w, collect, &f) == 0);
	CHECK_HAS(f.text, "emit_box#2: 'start' is 2.5 s, not before the end of the run (duration 2 s): it emits nothing");
	CHECK_HAS(f.text, "pipeline: no system moves the particles");
	eddy_gravity_def gr = eddy_default_gravity_def();
	eddy_add_gravity(w, &gr);
	eddy_integrate_def it = eddy_default_integrate_def();
	CHECK(eddy_system_valid(w, eddy_add_integrate(w, &it)));
	memset(&f, 0, sizeof f);
	eddy_world_check(w, collect, &f);
	CHECK(strstr(f.text, "no system moves") == NULL);
	/* a second integrate (a second fluid group, say) steps every particle
	 * twice: an error, once however many systems repeat */
	CHECK(eddy_system_valid(w, eddy_add_integrate(w, &it)));
	CHECK(eddy_system_valid(w, eddy_add_gravity(w, &gr)));
	memset(&f, 0, sizeof f);
	CHECK(eddy_world_check(w, collect, &f) == 1);
	CHECK_HAS(f.text, "pipeline: integrate#2 repeats integrate: each would run twice a step on the same particles; a "
	                  "world holds one fluid (one eddy.fluid group, one method)");
	eddy_destroy_world(w);

	/* fps 0.5 for a 0.2 s run: one 2 s frame, 10 times the run */
	w = spacing_world(0.01f, 0.5, 0.2);
	memset(&f, 0, sizeof f);
	CHECK(eddy_world_check(w, collect, &f) == 1);
	CHECK_HAS(f.text,
	          "world: 'fps' is 0.5 but 'duration' is 0.2 s: the first frame (2 s) is longer than the whole run");
	CHECK_HAS(f.text, "set fps >= 5");
	eddy_destroy_world(w);
	w = spacing_world(0.01f, 30, 0.21);
	memset(&f, 0, sizeof f);
	CHECK(eddy_world_check(w, collect, &f) == 0);
	CHECK_HAS(f.text, "a run simulates 7 frames = 0.233333 s");
	eddy_destroy_world(w);

	/* a box thinner than the spacing, and a nozzle whose opening holds
	 * only its centre (a single file of particles) */
	eddy_world_def d = eddy_default_world_def();
	d.bounds_max = (eddy_vec3){1, 1, 0.005f};
	w = eddy_create_world(&d, NULL, 0);
	eddy_emit_nozzle_def thin = eddy_default_emit_nozzle_def();
	thin.center = (eddy_vec3){0.5f, 0.8f, 0.0025f};
	thin.radius = 0.002f;
	thin.spacing = 0.01f;
	thin.max_particles = 100;
	CHECKF(eddy_system_valid(w, eddy_add_emit_nozzle(w, &thin)), "%s", eddy_world_error(w));
	memset(&f, 0, sizeof f);
	CHECK(eddy_world_check(w, collect, &f) == 1);
	CHECK_HAS(f.text, "world: 'bounds' are 0.005 m along z, less than the emitters' spacing 0.01 m: no layer of "
	                  "particles fits; use spacing <= 0.005 m");
	CHECK_HAS(f.text, "emit_nozzle: the opening (radius 0.002 m) holds one particle at spacing 0.01 m");
	eddy_destroy_world(w);

	/* FLIP cells smaller than the particle spacing */
	w = flip_world(0.01, 0.02f, 0);
	memset(&f, 0, sizeof f);
	CHECK(eddy_world_check(w, collect, &f) == 1);
	CHECK_HAS(f.text, "flip_p2g: 0.1");
	CHECK_HAS(f.text, "particles per cell (world cell_size 0.01 m, emitter spacing 0.02 m), below 1");
	eddy_destroy_world(w);

	/* an emitter wholly inside a solid block */
	w = spacing_world(0.02f, 30, 2);
	eddy_collide_box_def cb = eddy_default_collide_box_def();
	cb.min = (eddy_vec3){0.05f, 0.05f, 0.05f};
	cb.max = (eddy_vec3){0.35f, 0.35f, 0.35f};
	cb.inside = false;
	CHECK(eddy_system_valid(w, eddy_add_collide_box(w, &cb)));
	memset(&f, 0, sizeof f);
	CHECK(eddy_world_check(w, collect, &f) == 1);
	CHECK_HAS(f.text, "emit_box: all 1000 particles start inside the solid of collide_box");
	eddy_destroy_world(w);
	/* wholly outside a tank (collide_box's default, inside = true: a plate
	 * written without inside = false): the message says which it is */
	w = spacing_world(0.02f, 30, 2);
	cb.min = (eddy_vec3){0.32f, 0.32f, 0.32f};
	cb.max = (eddy_vec3){0.38f, 0.33f, 0.38f};
	cb.inside = true;
	CHECK(eddy_system_valid(w, eddy_add_collide_box(w, &cb)));
	memset(&f, 0, sizeof f);
	CHECK(eddy_world_check(w, collect, &f) == 1);
	CHECK_HAS(f.text, "emit_box: all 1000 particles start outside collide_box, a tank (inside = true");
	CHECK_HAS(f.text, "set the collider's inside = false for a solid obstacle");
	eddy_destroy_world(w);
	/* a collider before the integrator: its push comes before the step
	 * moves the particles (they end steps inside it); after it, no word */
	for (int after = 0; after < 2; ++after) {
		w = spacing_world(0.02f, 30, 2);
		eddy_collide_sphere_def cs = eddy_default_collide_sphere_def();
		cs.center = (eddy_vec3){0.5f, 0.5f, 0.5f};
		cs.radius = 0.05f;
		eddy_gravity_def gd = eddy_default_gravity_def();
		CHECK(eddy_system_valid(w, eddy_add_gravity(w, &gd)));
		eddy_integrate_def id = eddy_default_integrate_def();
		if (after)
			CHECK(eddy_system_valid(w, eddy_add_integrate(w, &id)));
		CHECK(eddy_system_valid(w, eddy_add_collide_sphere(w, &cs)));
		if (!after)
			CHECK(eddy_system_valid(w, eddy_add_integrate(w, &id)));
		memset(&f, 0, sizeof f);
		CHECK(eddy_world_check(w, collect, &f) == 0);
		if (after)
			CHECK(strstr(f.text, "runs before") == NULL);
		else
			CHECK_HAS(f.text, "collide_sphere runs before integrate, which moves the particles after its push");
		eddy_destroy_world(w);
	}
	/* half outside a tank: left out, and said so as a tank's */
	w = spacing_world(0.02f, 30, 2);
	cb.min = (eddy_vec3){0.0f, 0.0f, 0.0f};
	cb.max = (eddy_vec3){0.2f, 0.4f, 0.4f};
	CHECK(eddy_system_valid(w, eddy_add_collide_box(w, &cb)));
	memset(&f, 0, sizeof f);
	CHECK(eddy_world_check(w, collect, &f) == 0);
	CHECK_HAS(f.text, "emit_box: 500 of 1000 particles start outside collide_box, a tank (inside = true); they are "
	                  "left out (for a solid obstacle set its inside = false)");
	eddy_destroy_world(w);
	/* and a collider box with min > max never gets that far */
	w = make_world();
	cb.min.x = 0.5f;
	cb.max.x = 0.4f;
	CHECK(!eddy_system_valid(w, eddy_add_collide_box(w, &cb)));
	CHECK_HAS(eddy_world_error(w), "collide_box: 'max' must exceed 'min' on every axis");
	eddy_destroy_world(w);
}

static eddy_status poison_face(eddy_world *w, const eddy_step_context *ctx, void *user)
{
	(void)ctx;
	(void)user;
	size_t n;
	float *u = eddy_world_channel_mut(w, "u", &n);
	eddy_grid_info g = eddy_world_grid(w);
	/* face (2, 1, 3) of the x-face grid, (nx + 1) faces along x */
	u[2 + (size_t)(g.nx + 1) * (1 + (size_t)g.ny * 3)] = NAN;
	return EDDY_OK;
}

/* A grid pass that writes a non-finite value is blamed with the face or cell,
 * not the particle pass that would read it next. */
static void nonfinite_on_the_grid_names_the_face(void)
{
	eddy_world_def d = eddy_default_world_def();
	d.cell_size = 0.1;
	eddy_world *w = eddy_create_world(&d, NULL, 0);
	const char *writes[] = {"u"};
	eddy_custom_system_def c = eddy_default_custom_system_def();
	c.name = "grid_pass";
	c.writes = writes;
	c.write_count = 1;
	c.step = poison_face;
	CHECK(eddy_system_valid(w, eddy_add_custom_system(w, &c)));
	CHECK(eddy_world_step(w) == EDDY_ERR_NUMERIC);
	CHECK_HAS(eddy_world_error(w), "grid_pass: non-finite u = nan at face (2, 1, 3) at step 0");
	eddy_destroy_world(w);
}

void suite_core(void)
{
	RUN(nonfinite_on_the_grid_names_the_face);
	RUN(check_catches_scene_mistakes);
	RUN(collider_added_into_water_warns);
	RUN(null_arguments_are_refused);
	RUN(callbacks_cannot_reenter);
	RUN(preflight_findings);
	RUN(world_def_rejects_bad_values);
	RUN(absent_systems_allocate_nothing);
	RUN(order_errors_name_the_fix);
	RUN(couplings_are_checked_when_added);
	RUN(stale_handles_are_detected);
	RUN(grid_exists_only_for_grid_systems);
	RUN(swap_remove_and_growth);
	RUN(host_particles_keep_their_state);
	RUN(defs_are_range_checked);
	RUN(huge_emitter_is_refused);
	RUN(ellipsoid_emitter);
	RUN(emitters_count_whole_spacings);
	RUN(emitters_add_water_only_where_there_is_none);
	RUN(emitters_fill_around_solids);
	RUN(nonfinite_names_system_step_particle);
	RUN(custom_system_errors_are_labelled);
	RUN(arena_is_plain_memory);
}
