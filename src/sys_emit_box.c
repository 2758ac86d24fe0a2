/* SPDX-License-Identifier: MIT */
/* emit_box: a block of particles on a simple cubic lattice, emitted once.
 *
 * Reads: x y z (the water already there), the colliders' solids. Writes: x y z vx vy vz.
 * Lattice points sit at min + (i + 1/2) * spacing on each axis, so a block
 * fills [min, max] with cells of size spacing; the count per axis is
 * floor((max - min) / spacing). Jitter moves each point by a uniform offset in
 * [-jitter, jitter] * spacing per axis, from the world's seeded stream.
 * With shape = ellipsoid only the lattice points inside the ellipsoid
 * inscribed in [min, max] are emitted (tested before jitter, so the count
 * does not depend on the random stream), on the lattice with a cell corner
 * at the centre, (min + max) / 2 + (i + 1/2) * spacing: the drop is then
 * mirror-symmetric about its centre on every axis, and it stands on the
 * simple cubic lattice the SPH mass calibration assumes.
 * A point water already fills (a particle within spacing / 2 of it on every
 * axis) or a collider's solid holds is left out (eddy__emit_occupied), so
 * that boxes which overlap each other or a pool make one body of water, and
 * a box around an obstacle fills around it.
 * The spacing becomes the world's length scale for the advection limit. */
#include "systems.h"

#include <stdlib.h>

typedef struct emit_box {
	eddy_emit_box_def def;
	int nx, ny, nz;
	eddy_vec3 origin; /* m, corner of the lattice's first cell */
	size_t count;     /* points emitted: nx ny nz, or those inside the ellipsoid */
	bool done;
} emit_box;

static const int box_writes[] = {COL_X_, COL_Y_, COL_Z_, COL_VX, COL_VY, COL_VZ, -1};

eddy_emit_box_def eddy_default_emit_box_def(void)
{
	eddy_emit_box_def d = {0};
	d.min = eddy__v3(0, 0, 0);
	d.max = eddy__v3(0.1f, 0.1f, 0.1f);
	d.spacing = 0.01f;
	d.jitter = 0;
	d.velocity = eddy__v3(0, 0, 0);
	d.start = 0;
	d.shape = EDDY_EMIT_BLOCK;
	return d;
}

/* Lattice points along one axis, as a double: a huge box over a tiny spacing
 * must be refused, not overflow an int. */
static double axis_count(float lo, float hi, float h)
{
	/* a box of exactly k spacings gives k, not k - 1 */
	double n = eddy__count_floor(lo, hi, h);
	return n > 0 ? n : 0;
}

/* Lattice point k of the block (x fastest), before jitter. */
static eddy_vec3 lattice_point(const emit_box *e, size_t k)
{
	const eddy_emit_box_def *d = &e->def;
	const size_t ix = k % (size_t)e->nx, iy = k / (size_t)e->nx % (size_t)e->ny,
				 iz = k / ((size_t)e->nx * (size_t)e->ny);
	return (eddy_vec3){e->origin.x + ((float)ix + 0.5f) * d->spacing, e->origin.y + ((float)iy + 0.5f) * d->spacing,
	                   e->origin.z + ((float)iz + 0.5f) * d->spacing};
}

/* Whether lattice point p is emitted: always for a block; for an ellipsoid,
 * when it lies inside (in double, so the count is the same on every host). */
static bool emitted(const eddy_emit_box_def *d, eddy_vec3 p)
{
	if (d->shape != EDDY_EMIT_ELLIPSOID)
		return true;
	const double ux = ((double)p.x - 0.5 * ((double)d->min.x + d->max.x)) / (0.5 * ((double)d->max.x - d->min.x)),
				 uy = ((double)p.y - 0.5 * ((double)d->min.y + d->max.y)) / (0.5 * ((double)d->max.y - d->min.y)),
				 uz = ((double)p.z - 0.5 * ((double)d->min.z + d->max.z)) / (0.5 * ((double)d->max.z - d->min.z));
	return ux * ux + uy * uy + uz * uz <= 1.0;
}

/* Lattice point p moved by the jitter, when rng is given. */
static eddy_vec3 jittered(const emit_box *e, eddy_vec3 p, uint64_t *rng)
{
	const eddy_emit_box_def *d = &e->def;
	if (rng && d->jitter > 0) {
		p.x += (float)((2 * eddy__rand01(rng) - 1) * d->jitter * d->spacing);
		p.y += (float)((2 * eddy__rand01(rng) - 1) * d->jitter * d->spacing);
		p.z += (float)((2 * eddy__rand01(rng) - 1) * d->jitter * d->spacing);
	}
	return p;
}

static eddy_status step(eddy_world *w, eddy_system *s, const eddy_step_context *ctx)
{
	emit_box *e = s->data;
	if (e->done || ctx->time + 1e-12 < e->def.start)
		return EDDY_OK;
	e->done = true;
	const size_t count = e->count, lattice = (size_t)e->nx * (size_t)e->ny * (size_t)e->nz;
	/* the points, and which of them water or a solid already fills (core.h;
	 * a world with neither needs neither array) */
	const bool check = eddy__emit_needs_check(w);
	eddy_vec3 *pts = check ? malloc(count * sizeof *pts + 1) : NULL;
	uint8_t *occupied = check ? malloc(count + 1) : NULL;
	bool ok = !check || (pts && occupied);
	size_t kept = check ? 0 : count;
	if (check && ok) {
		size_t k = 0;
		for (size_t q = 0; q < lattice && k < count; ++q) {
			const eddy_vec3 l = lattice_point(e, q);
			if (emitted(&e->def, l))
				pts[k++] = l;
		}
		ok = eddy__emit_occupied(w, pts, count, e->def.spacing, 0, occupied);
		for (size_t q = 0; q < count; ++q)
			kept += !occupied[q];
	}
	size_t first;
	eddy_status st = ok ? eddy__append_particles(w, kept, &first)
	                    : eddy__fail(w, EDDY_ERR_NOMEM, "%s: out of memory for %zu particles", s->label, count);
	if (st != EDDY_OK) {
		free(pts);
		free(occupied);
		return st;
	}
	float *x = eddy__col(w, COL_X_), *y = eddy__col(w, COL_Y_), *z = eddy__col(w, COL_Z_);
	float *vx = eddy__col(w, COL_VX), *vy = eddy__col(w, COL_VY), *vz = eddy__col(w, COL_VZ);
	const eddy_vec3 lo = w->def.bounds_min, hi = w->def.bounds_max;
	size_t k = 0;
	for (size_t q = 0, r = 0; q < lattice && r < count; ++q) {
		const eddy_vec3 l = lattice_point(e, q);
		if (!emitted(&e->def, l) || (check && occupied[r++]))
			continue;
		const eddy_vec3 p = jittered(e, l, &w->rng);
		/* jitter must not push a particle out of the world */
		x[first + k] = fminf(fmaxf(p.x, lo.x), hi.x);
		y[first + k] = fminf(fmaxf(p.y, lo.y), hi.y);
		z[first + k] = fminf(fmaxf(p.z, lo.z), hi.z);
		vx[first + k] = e->def.velocity.x;
		vy[first + k] = e->def.velocity.y;
		vz[first + k] = e->def.velocity.z;
		k++;
	}
	free(pts);
	free(occupied);
	return EDDY_OK;
}

static int64_t expected(const eddy_world *w, const eddy_system *s)
{
	(void)w;
	const emit_box *e = s->data;
	return e->done ? 0 : (int64_t)e->count;
}

static size_t sample(const eddy_world *w, const eddy_system *s, eddy_vec3 *out, size_t cap)
{
	(void)w;
	const emit_box *e = s->data;
	const size_t lattice = (size_t)e->nx * (size_t)e->ny * (size_t)e->nz;
	if (!out)
		return e->count;
	size_t k = 0;
	for (size_t q = 0; q < lattice && k < cap; ++q) {
		const eddy_vec3 p = lattice_point(e, q);
		if (emitted(&e->def, p))
			out[k++] = p;
	}
	return k;
}

static void *state(eddy_world *w, eddy_system *s, size_t *size)
{
	(void)w;
	emit_box *e = s->data;
	*size = sizeof e->done;
	return &e->done;
}

static int check(eddy_world *w, const eddy_system *s, eddy_check_fn report, void *user)
{
	eddy__check_emitter_start(w, s, ((const emit_box *)s->data)->def.start, report, user);
	return 0;
}

static float spacing(const eddy_system *s) { return ((const emit_box *)s->data)->def.spacing; }

static double limit(eddy_world *w, eddy_system *s, const char **reason)
{
	const emit_box *e = s->data;
	return eddy__emission_limit(w, e->done, e->def.start, e->def.spacing, eddy__norm3(e->def.velocity), reason);
}

/* The block's highest corner: the ellipsoid's top is no higher. */
static void reach(const eddy_system *s, eddy_vec3 up, eddy_vec3 *top, double *speed)
{
	const emit_box *e = s->data;
	const eddy_vec3 lo = e->def.min, hi = e->def.max;
	*top = eddy__v3(up.x > 0 ? hi.x : lo.x, up.y > 0 ? hi.y : lo.y, up.z > 0 ? hi.z : lo.z);
	*speed = eddy__norm3(e->def.velocity);
}

const eddy_system_vtable eddy__kind_emit_box = {
	.name = "emit_box",
	.state = state,
	.step = step,
	.limit = limit,
	.expected_particles = expected,
	.sample = sample,
	.spacing = spacing,
	.reach = reach,
	.check = check,
	.default_writes = box_writes,
};

eddy_system_id eddy_add_emit_box(eddy_world *w, const eddy_emit_box_def *def)
{
	const char *sys = "emit_box";
	if (!eddy__add_args(w, def, sys))
		return EDDY_NULL_SYSTEM;
	if (!eddy__check_box(w, sys, def->min, def->max) || !eddy__check_positive(w, sys, "spacing", def->spacing) ||
	    !eddy__check_range(w, sys, "jitter", def->jitter, 0, 0.5) ||
	    !eddy__check_vec3(w, sys, "velocity", def->velocity) || !eddy__check_nonneg(w, sys, "start", def->start))
		return EDDY_NULL_SYSTEM;
	if (def->shape != EDDY_EMIT_BLOCK && def->shape != EDDY_EMIT_ELLIPSOID)
		return eddy__fail(w, EDDY_ERR_INVALID, "%s: 'shape' must be block or ellipsoid", sys), EDDY_NULL_SYSTEM;
	const eddy_vec3 lo = w->def.bounds_min, hi = w->def.bounds_max;
	if (def->min.x < lo.x || def->min.y < lo.y || def->min.z < lo.z || def->max.x > hi.x || def->max.y > hi.y ||
	    def->max.z > hi.z) {
		eddy__fail(w, EDDY_ERR_INVALID, "%s: the block {%g, %g, %g}..{%g, %g, %g} must lie inside the world bounds",
		           sys, (double)def->min.x, (double)def->min.y, (double)def->min.z, (double)def->max.x,
		           (double)def->max.y, (double)def->max.z);
		return EDDY_NULL_SYSTEM;
	}
	emit_box *e = calloc(1, sizeof *e);
	if (!e)
		return eddy__fail(w, EDDY_ERR_NOMEM, "%s: out of memory", sys), EDDY_NULL_SYSTEM;
	e->def = *def;
	const double nx = axis_count(def->min.x, def->max.x, def->spacing),
				 ny = axis_count(def->min.y, def->max.y, def->spacing),
				 nz = axis_count(def->min.z, def->max.z, def->spacing), count = nx * ny * nz;
	if (count == 0) {
		free(e);
		eddy__fail(w, EDDY_ERR_INVALID,
		           "%s: the block emits no particles: every side must be at least 'spacing' = %g m long", sys,
		           (double)def->spacing);
		return EDDY_NULL_SYSTEM;
	}
	if (count > (double)(1ll << 31)) {
		free(e);
		eddy__fail(w, EDDY_ERR_NOMEM, "%s: %.3g particles is more than eddy can hold; use a larger spacing", sys,
		           count);
		return EDDY_NULL_SYSTEM;
	}
	e->nx = (int)nx;
	e->ny = (int)ny;
	e->nz = (int)nz;
	e->origin = def->min;
	e->count = (size_t)count;
	if (def->shape == EDDY_EMIT_ELLIPSOID) {
		/* an even number of cells per axis, centred on the ellipsoid (at most
		 * two more per axis than the block's; about pi/6 of them are inside) */
		const double hx = 0.5 * ((double)def->max.x - def->min.x), hy = 0.5 * ((double)def->max.y - def->min.y),
					 hz = 0.5 * ((double)def->max.z - def->min.z);
		const double cx = eddy__count_ceil(def->min.x, def->max.x, 2.0 * def->spacing),
					 cy = eddy__count_ceil(def->min.y, def->max.y, 2.0 * def->spacing),
					 cz = eddy__count_ceil(def->min.z, def->max.z, 2.0 * def->spacing);
		e->nx = 2 * (int)cx;
		e->ny = 2 * (int)cy;
		e->nz = 2 * (int)cz;
		e->origin = eddy__v3((float)(def->min.x + hx - cx * def->spacing), (float)(def->min.y + hy - cy * def->spacing),
		                     (float)(def->min.z + hz - cz * def->spacing));
		const size_t lattice = (size_t)e->nx * (size_t)e->ny * (size_t)e->nz;
		e->count = 0;
		for (size_t q = 0; q < lattice; ++q)
			e->count += emitted(def, lattice_point(e, q));
		if (e->count == 0) {
			free(e);
			eddy__fail(w, EDDY_ERR_INVALID,
			           "%s: the ellipsoid holds no lattice point: make every side at least 'spacing' = %g m long", sys,
			           (double)def->spacing);
			return EDDY_NULL_SYSTEM;
		}
	}
	eddy_system_id id = eddy__add_system(w, &eddy__kind_emit_box, e, NULL, box_writes);
	if (eddy_system_valid(w, id))
		eddy__note_length_scale(w, def->spacing);
	return id;
}
