/* SPDX-License-Identifier: MIT */
/* emit_nozzle: a continuous round jet ("pouring water into a box").
 *
 * Reads: nothing. Writes: x y z vx vy vz.
 * The opening is a disc of the given radius normal to the direction. Every
 * time the jet has advanced one spacing (speed * t), a disc of particles on a
 * square lattice of that spacing leaves the nozzle with velocity
 * speed * direction, placed where it is at the end of the step after the
 * integrator moved it; so the jet has the lattice density and the rate is speed * pi r^2 / h^3.
 * The pour runs over [start, start + duration] and stops early at
 * max_particles (the last disc is cut to hit the total exactly).
 * A disc's point that water or a collider's solid already fills (a particle
 * closer than 0.8 spacings, NOZZLE_CLEARANCE) is held back, not emitted: a
 * closed tank filled up to the opening stops taking water instead of having
 * particles stacked into it (tests/scenes/fill_tank.lua, a 6 x 8 x 4 cm tank
 * poured into for 1.5 s: DFSPH's step collapsed at 0.63 s, FLIP packed 2.5x
 * the particles the tank holds, WCSPH compressed 148%). So an opening under
 * the water line adds only what the flow in front of it makes room for: the
 * nozzle is a spout, not a pump (a submerged inlet that pushes its rate into
 * still water needs a pipe wall behind the opening, which the nozzle does
 * not model). The points held back in a frame are published as
 * "<label>_held", and the first hold-back raises a run-time warning.
 * Time-step limit (emission): dt <= spacing / speed. */
#include "systems.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* A disc's point is held back when a particle lies closer than this many
 * spacings: a free jet's last disc is a spacing downstream, water at rest
 * around the opening leaves no hole that wide. */
#define NOZZLE_CLEARANCE 0.8f

typedef struct emit_nozzle {
	eddy_emit_nozzle_def def;
	eddy_vec3 u, v;       /* unit vectors spanning the opening */
	int disc;             /* particles per disc */
	int half;             /* lattice extent: offsets in [-half, half] */
	struct nozzle_state { /* what a checkpoint saves */
		double travelled; /* m the jet moved since the last disc left */
		int64_t emitted;
		bool started;
	} run;
	int held_frame; /* the frame `held` counts in */
	int64_t held;   /* points held back this frame (occupied) */
} emit_nozzle;

static const int nozzle_writes[] = {COL_X_, COL_Y_, COL_Z_, COL_VX, COL_VY, COL_VZ, -1};

eddy_emit_nozzle_def eddy_default_emit_nozzle_def(void)
{
	eddy_emit_nozzle_def d = {0};
	d.center = eddy__v3(0.5f, 0.9f, 0.5f);
	d.radius = 0.03f;
	d.direction = eddy__v3(0, -1, 0);
	d.speed = 1.0f;
	d.spacing = 0.01f;
	d.start = 0;
	d.duration = INFINITY;
	d.max_particles = 0;
	return d;
}

static bool in_disc(const emit_nozzle *e, int i, int j)
{
	const double r = e->def.radius / e->def.spacing;
	return (double)i * i + (double)j * j <= r * r + 1e-9;
}

/* Writes the disc's points (at most cap); returns the number of points. */
static int disc_points(const emit_nozzle *e, double downstream, eddy_vec3 *out, int cap)
{
	const eddy_emit_nozzle_def *d = &e->def;
	int k = 0;
	for (int j = -e->half; j <= e->half; ++j)
		for (int i = -e->half; i <= e->half; ++i) {
			if (!in_disc(e, i, j))
				continue;
			if (k < cap) {
				const float a = (float)i * d->spacing, b = (float)j * d->spacing, c = (float)downstream;
				out[k] = (eddy_vec3){d->center.x + a * e->u.x + b * e->v.x + c * d->direction.x,
				                     d->center.y + a * e->u.y + b * e->v.y + c * d->direction.y,
				                     d->center.z + a * e->u.z + b * e->v.z + c * d->direction.z};
			}
			++k;
		}
	return k;
}

static eddy_status emit_disc(eddy_world *w, eddy_system *s, emit_nozzle *e, double downstream)
{
	int count = e->disc;
	if (e->def.max_particles > 0 && e->run.emitted + count > e->def.max_particles)
		count = (int)(e->def.max_particles - e->run.emitted);
	if (count <= 0)
		return EDDY_OK;
	eddy_vec3 *pts = eddy__arena_alloc(&w->arena, (size_t)e->disc * sizeof *pts);
	uint8_t *occupied = eddy__arena_alloc(&w->arena, (size_t)e->disc);
	if (!pts || !occupied)
		return eddy__fail(w, EDDY_ERR_NOMEM, "%s: out of scratch memory", s->label);
	disc_points(e, downstream, pts, e->disc);
	if (!eddy__emit_needs_check(w))
		memset(occupied, 0, (size_t)e->disc);
	else if (!eddy__emit_occupied(w, pts, (size_t)e->disc, e->def.spacing, NOZZLE_CLEARANCE * e->def.spacing, occupied))
		return eddy__fail(w, EDDY_ERR_NOMEM, "%s: out of scratch memory", s->label);
	/* the first `count` free points, in the disc's order */
	int kept = 0, held = 0;
	for (int k = 0; k < e->disc && kept < count; ++k) {
		if (occupied[k])
			held++;
		else
			pts[kept++] = pts[k];
	}
	if (eddy_world_frame(w) != e->held_frame) {
		e->held_frame = eddy_world_frame(w);
		e->held = 0;
	}
	e->held += held;
	if (held > 0) {
		char key[sizeof s->label + 8];
		snprintf(key, sizeof key, "%s:held", s->label);
		eddy__warn(w, key,
		           "%s: water at its opening at step %lld (t = %.6g s): %d of %d points held back; the nozzle adds "
		           "only what the flow in front of it makes room for (a splash back, a tank full up to the opening, "
		           "an opening under the water line); the stats' %s_held counts them per frame",
		           s->label, (long long)w->step, w->time, held, e->disc, s->label);
	}
	char name[sizeof s->label + 8];
	snprintf(name, sizeof name, "%s_held", s->label);
	eddy_world_publish(w, name, (double)e->held);
	if (kept == 0)
		return EDDY_OK;
	size_t first;
	eddy_status st = eddy__append_particles(w, (size_t)kept, &first);
	if (st != EDDY_OK)
		return st;
	float *x = eddy__col(w, COL_X_), *y = eddy__col(w, COL_Y_), *z = eddy__col(w, COL_Z_);
	float *vx = eddy__col(w, COL_VX), *vy = eddy__col(w, COL_VY), *vz = eddy__col(w, COL_VZ);
	const eddy_vec3 lo = w->def.bounds_min, hi = w->def.bounds_max;
	const eddy_vec3 vel = {e->def.direction.x * e->def.speed, e->def.direction.y * e->def.speed,
	                       e->def.direction.z * e->def.speed};
	for (int k = 0; k < kept; ++k) {
		const size_t i = first + (size_t)k;
		x[i] = fminf(fmaxf(pts[k].x, lo.x), hi.x);
		y[i] = fminf(fmaxf(pts[k].y, lo.y), hi.y);
		z[i] = fminf(fmaxf(pts[k].z, lo.z), hi.z);
		vx[i] = vel.x;
		vy[i] = vel.y;
		vz[i] = vel.z;
	}
	e->run.emitted += kept;
	return EDDY_OK;
}

static eddy_status step(eddy_world *w, eddy_system *s, const eddy_step_context *ctx)
{
	emit_nozzle *e = s->data;
	const double t0 = fmax(ctx->time, e->def.start);
	const double t1 = fmin(ctx->time + ctx->dt, e->def.start + e->def.duration);
	if (t1 <= t0 || (e->def.max_particles > 0 && e->run.emitted >= e->def.max_particles))
		return EDDY_OK;
	if (!e->run.started) {
		e->run.started = true;
		e->run.travelled = e->def.spacing; /* the first disc leaves as the pour starts */
	}
	e->run.travelled += e->def.speed * (t1 - t0);
	/* integrate moves every particle by speed * dt after this; a disc that
	 * left at t_k must end the step speed * (t + dt - t_k) downstream, so it
	 * starts that much minus speed * dt, i.e. up to one step inside the pipe */
	const double lead = e->def.speed * (t1 - ctx->time);
	while (e->run.travelled >= e->def.spacing) {
		e->run.travelled -= e->def.spacing;
		eddy_status st = emit_disc(w, s, e, e->run.travelled - lead);
		if (st != EDDY_OK)
			return st;
	}
	return EDDY_OK;
}

/* The jet moves one spacing per disc: dt <= spacing / speed keeps it to about
 * one disc per step at CFL 1, and bounds the discs a single step can emit. */
static double limit(eddy_world *w, eddy_system *s, const char **reason)
{
	const emit_nozzle *e = s->data;
	*reason = "emission";
	const bool over = eddy_world_time(w) >= e->def.start + e->def.duration ||
	                  (e->def.max_particles > 0 && e->run.emitted >= e->def.max_particles);
	return over ? INFINITY : e->def.spacing / e->def.speed;
}

static int64_t expected(const eddy_world *w, const eddy_system *s)
{
	(void)w;
	const emit_nozzle *e = s->data;
	int64_t by_time = -1;
	if (isfinite(e->def.duration))
		by_time = ((int64_t)floor(e->def.duration * e->def.speed / e->def.spacing) + 1) * e->disc;
	if (e->def.max_particles > 0 && (by_time < 0 || e->def.max_particles < by_time))
		by_time = e->def.max_particles;
	return by_time < 0 ? -1 : by_time - e->run.emitted;
}

static size_t sample(const eddy_world *w, const eddy_system *s, eddy_vec3 *out, size_t cap)
{
	(void)w;
	const emit_nozzle *e = s->data;
	if (!out)
		return (size_t)e->disc;
	int n = disc_points(e, 0, out, (int)(cap < (size_t)e->disc ? cap : (size_t)e->disc));
	return (size_t)n < cap ? (size_t)n : cap;
}

static void *state(eddy_world *w, eddy_system *s, size_t *size)
{
	(void)w;
	emit_nozzle *e = s->data;
	*size = sizeof e->run;
	return &e->run;
}

static int check(eddy_world *w, const eddy_system *s, eddy_check_fn report, void *user)
{
	const emit_nozzle *e = s->data;
	eddy__check_emitter_start(w, s, e->def.start, report, user);
	/* an opening under a spacing across holds only its centre: the jet is a
	 * single file of particles, which no fluid method resolves (SPH stacks it
	 * into a chain the pressure cannot spread: the pour at 8-15 cm spacing
	 * stopped with DFSPH's solve failing) */
	if (e->disc == 1)
		eddy__report(report, user, EDDY_CHECK_WARNING,
		             "%s: the opening (radius %g m) holds one particle at spacing %g m: the jet is a single file of "
		             "particles, not a fluid; use radius >= %g m or spacing <= %g m",
		             s->label, (double)e->def.radius, (double)e->def.spacing, (double)e->def.spacing,
		             (double)e->def.radius);
	return 0;
}

static float spacing(const eddy_system *s) { return ((const emit_nozzle *)s->data)->def.spacing; }

/* The opening's highest point, and the jet's speed. */
static void reach(const eddy_system *s, eddy_vec3 up, eddy_vec3 *top, double *speed)
{
	const emit_nozzle *e = s->data;
	const eddy_vec3 c = e->def.center;
	const float r = e->def.radius;
	*top = eddy__v3(c.x + r * up.x, c.y + r * up.y, c.z + r * up.z);
	*speed = e->def.speed;
}

const eddy_system_vtable eddy__kind_emit_nozzle = {
	.name = "emit_nozzle",
	.state = state,
	.step = step,
	.limit = limit,
	.expected_particles = expected,
	.sample = sample,
	.spacing = spacing,
	.reach = reach,
	.check = check,
	.default_writes = nozzle_writes,
};

eddy_system_id eddy_add_emit_nozzle(eddy_world *w, const eddy_emit_nozzle_def *def)
{
	const char *sys = "emit_nozzle";
	if (!eddy__add_args(w, def, sys))
		return EDDY_NULL_SYSTEM;
	eddy_vec3 dir = def->direction;
	if (!eddy__check_vec3(w, sys, "center", def->center) || !eddy__check_positive(w, sys, "radius", def->radius) ||
	    !eddy__check_unit(w, sys, "direction", &dir) || !eddy__check_positive(w, sys, "speed", def->speed) ||
	    !eddy__check_positive(w, sys, "spacing", def->spacing) || !eddy__check_nonneg(w, sys, "start", def->start) ||
	    !eddy__check_finite(w, sys, "start", def->start))
		return EDDY_NULL_SYSTEM;
	if (!(def->duration > 0)) {
		eddy__fail(w, EDDY_ERR_INVALID, "%s: 'duration' must be > 0 s, or infinite for no end (got %g)", sys,
		           def->duration);
		return EDDY_NULL_SYSTEM;
	}
	if (def->max_particles < 0) {
		eddy__fail(w, EDDY_ERR_INVALID, "%s: 'max_particles' must be >= 0, 0 for no limit (got %lld)", sys,
		           (long long)def->max_particles);
		return EDDY_NULL_SYSTEM;
	}
	if (def->radius / def->spacing > 1000) {
		eddy__fail(w, EDDY_ERR_INVALID, "%s: 'radius' must be at most 1000 spacings (got %g m at spacing %g m)", sys,
		           (double)def->radius, (double)def->spacing);
		return EDDY_NULL_SYSTEM;
	}
	const eddy_vec3 lo = w->def.bounds_min, hi = w->def.bounds_max, c = def->center;
	const float r = def->radius;
	if (c.x - r < lo.x || c.y - r < lo.y || c.z - r < lo.z || c.x + r > hi.x || c.y + r > hi.y || c.z + r > hi.z) {
		eddy__fail(w, EDDY_ERR_INVALID,
		           "%s: the opening (centre {%g, %g, %g}, radius %g m) must lie inside the world bounds", sys,
		           (double)c.x, (double)c.y, (double)c.z, (double)r);
		return EDDY_NULL_SYSTEM;
	}
	emit_nozzle *e = calloc(1, sizeof *e);
	if (!e)
		return eddy__fail(w, EDDY_ERR_NOMEM, "%s: out of memory", sys), EDDY_NULL_SYSTEM;
	e->def = *def;
	e->def.direction = dir;
	/* u: any unit vector normal to dir; v completes the frame */
	eddy_vec3 a = fabsf(dir.x) < 0.9f ? eddy__v3(1, 0, 0) : eddy__v3(0, 1, 0);
	eddy_vec3 u = {dir.y * a.z - dir.z * a.y, dir.z * a.x - dir.x * a.z, dir.x * a.y - dir.y * a.x};
	eddy__check_unit(w, sys, "direction", &u);
	e->u = u;
	e->v = (eddy_vec3){dir.y * u.z - dir.z * u.y, dir.z * u.x - dir.x * u.z, dir.x * u.y - dir.y * u.x};
	e->half = (int)eddy__count_floor(0, def->radius, def->spacing);
	e->disc = disc_points(e, 0, NULL, 0);
	eddy_system_id id = eddy__add_system(w, &eddy__kind_emit_nozzle, e, NULL, nozzle_writes);
	if (eddy_system_valid(w, id))
		eddy__note_length_scale(w, def->spacing);
	return id;
}
