/* SPDX-License-Identifier: MIT */
/* emit_mesh: a closed mesh from a file filled with particles on a simple
 * cubic lattice, emitted once.
 *
 * Reads: x y z (the water already there), the colliders' solids. Writes: x y z vx vy vz.
 * Lattice points sit at min + (i + 1/2) spacing on each axis, min the
 * mesh's box corner, as emit_box places them in a box; those inside the
 * mesh are emitted. Inside is the winding number along +x rays through the
 * lattice rows (mesh.c): exact for a closed mesh, points on a face counted
 * once between the two triangles of an edge, so a mesh cube gives exactly
 * emit_box's count. The flags are found once, when added (one byte per
 * lattice point of the box); jitter as emit_box's, after the test. Points
 * water already fills or a collider's solid holds are left out, as
 * emit_box's. The spacing becomes the world's length scale. */
#include "mesh.h"
#include "systems.h"

#include <stdlib.h>
#include <string.h>

typedef struct emit_mesh {
	eddy_emit_mesh_def def;
	bool done;
	int n[3];
	double origin[3]; /* m, the first lattice point */
	size_t count;     /* points inside */
	uint8_t inside[]; /* n[0] n[1] n[2] flags, x fastest */
} emit_mesh;

static const int mesh_writes[] = {COL_X_, COL_Y_, COL_Z_, COL_VX, COL_VY, COL_VZ, -1};

eddy_emit_mesh_def eddy_default_emit_mesh_def(void)
{
	eddy_emit_mesh_def d;
	memset(&d, 0, sizeof d);
	d.scale = eddy__v3(1, 1, 1);
	d.spacing = 0.01f;
	return d;
}

static eddy_vec3 point(const emit_mesh *e, size_t q)
{
	const size_t nx = (size_t)e->n[0], ny = (size_t)e->n[1];
	const size_t i = q % nx, j = q / nx % ny, k = q / (nx * ny);
	const double h = e->def.spacing;
	return eddy__v3((float)(e->origin[0] + (double)i * h), (float)(e->origin[1] + (double)j * h),
	                (float)(e->origin[2] + (double)k * h));
}

static size_t lattice(const emit_mesh *e) { return (size_t)e->n[0] * (size_t)e->n[1] * (size_t)e->n[2]; }

static eddy_status step(eddy_world *w, eddy_system *s, const eddy_step_context *ctx)
{
	emit_mesh *e = s->data;
	if (e->done || ctx->time + 1e-12 < e->def.start)
		return EDDY_OK;
	e->done = true;
	/* the points water or a solid already fills are left out (core.h:
	 * eddy__emit_occupied; a world with neither needs neither array) */
	const bool check = eddy__emit_needs_check(w);
	eddy_vec3 *pts = check ? malloc(e->count * sizeof *pts + 1) : NULL;
	uint8_t *occupied = check ? malloc(e->count + 1) : NULL;
	bool ok = !check || (pts && occupied);
	size_t kept = check ? 0 : e->count;
	if (check && ok) {
		size_t r = 0;
		for (size_t q = 0, all = lattice(e); q < all && r < e->count; ++q)
			if (e->inside[q])
				pts[r++] = point(e, q);
		ok = eddy__emit_occupied(w, pts, e->count, e->def.spacing, 0, occupied);
		for (size_t q = 0; q < e->count; ++q)
			kept += !occupied[q];
	}
	free(pts);
	size_t first;
	eddy_status st = ok ? eddy__append_particles(w, kept, &first)
	                    : eddy__fail(w, EDDY_ERR_NOMEM, "%s: out of memory for %zu particles", s->label, e->count);
	if (st != EDDY_OK) {
		free(occupied);
		return st;
	}
	float *x = eddy__col(w, COL_X_), *y = eddy__col(w, COL_Y_), *z = eddy__col(w, COL_Z_);
	float *vx = eddy__col(w, COL_VX), *vy = eddy__col(w, COL_VY), *vz = eddy__col(w, COL_VZ);
	const eddy_vec3 lo = w->def.bounds_min, hi = w->def.bounds_max;
	const float jit = e->def.jitter * e->def.spacing;
	size_t k = first;
	for (size_t q = 0, r = 0, all = lattice(e); q < all; ++q) {
		if (!e->inside[q] || (check && occupied[r++]))
			continue;
		eddy_vec3 p = point(e, q);
		if (jit > 0) {
			p.x += (float)(2 * eddy__rand01(&w->rng) - 1) * jit;
			p.y += (float)(2 * eddy__rand01(&w->rng) - 1) * jit;
			p.z += (float)(2 * eddy__rand01(&w->rng) - 1) * jit;
		}
		x[k] = fminf(fmaxf(p.x, lo.x), hi.x);
		y[k] = fminf(fmaxf(p.y, lo.y), hi.y);
		z[k] = fminf(fmaxf(p.z, lo.z), hi.z);
		vx[k] = e->def.velocity.x, vy[k] = e->def.velocity.y, vz[k] = e->def.velocity.z;
		k++;
	}
	free(occupied);
	return EDDY_OK;
}

static int64_t expected(const eddy_world *w, const eddy_system *s)
{
	(void)w;
	const emit_mesh *e = s->data;
	return e->done ? 0 : (int64_t)e->count;
}

static size_t sample(const eddy_world *w, const eddy_system *s, eddy_vec3 *out, size_t cap)
{
	(void)w;
	const emit_mesh *e = s->data;
	if (!out)
		return e->count;
	size_t k = 0;
	for (size_t q = 0, all = lattice(e); q < all && k < cap; ++q)
		if (e->inside[q])
			out[k++] = point(e, q);
	return k;
}

static void *state(eddy_world *w, eddy_system *s, size_t *size)
{
	(void)w;
	emit_mesh *e = s->data;
	*size = sizeof e->done;
	return &e->done;
}

static int check(eddy_world *w, const eddy_system *s, eddy_check_fn report, void *user)
{
	eddy__check_emitter_start(w, s, ((const emit_mesh *)s->data)->def.start, report, user);
	return 0;
}

static float spacing(const eddy_system *s) { return ((const emit_mesh *)s->data)->def.spacing; }

static double limit(eddy_world *w, eddy_system *s, const char **reason)
{
	const emit_mesh *e = s->data;
	return eddy__emission_limit(w, e->done, e->def.start, e->def.spacing, eddy__norm3(e->def.velocity), reason);
}

/* The lattice box's highest corner. */
static void reach(const eddy_system *s, eddy_vec3 up, eddy_vec3 *top, double *speed)
{
	const emit_mesh *e = s->data;
	const double u[3] = {up.x, up.y, up.z};
	float t[3];
	for (int d = 0; d < 3; ++d)
		t[d] = (float)(e->origin[d] + (u[d] > 0 ? (double)(e->n[d] - 1) * e->def.spacing : 0));
	*top = eddy__v3(t[0], t[1], t[2]);
	*speed = eddy__norm3(e->def.velocity);
}

const eddy_system_vtable eddy__kind_emit_mesh = {
	.name = "emit_mesh",
	.state = state,
	.step = step,
	.limit = limit,
	.expected_particles = expected,
	.sample = sample,
	.spacing = spacing,
	.reach = reach,
	.check = check,
	.default_writes = mesh_writes,
};

eddy_system_id eddy_add_emit_mesh(eddy_world *w, const eddy_emit_mesh_def *def)
{
	const char *sys = "emit_mesh";
	if (!eddy__add_args(w, def, sys))
		return EDDY_NULL_SYSTEM;
	if (!eddy__check_positive(w, sys, "spacing", def->spacing) ||
	    !eddy__check_range(w, sys, "jitter", def->jitter, 0, 0.5) ||
	    !eddy__check_vec3(w, sys, "velocity", def->velocity) || !eddy__check_nonneg(w, sys, "start", def->start))
		return EDDY_NULL_SYSTEM;
	eddy_trimesh m;
	if (!eddy__mesh_from_def(w, sys, def->path, def->scale, def->rotate, def->translate, &m))
		return EDDY_NULL_SYSTEM;
	char err[EDDY_ERROR_MAX - 64];
	if (!eddy__mesh_closed(&m)) {
		eddy__mesh_describe_open(&m, def->path, err, sizeof err);
		eddy__mesh_free(&m);
		/* an emitter has no open = true: without an inside there is nothing to fill */
		eddy__fail(w, EDDY_ERR_INVALID, "%s: %.*s", sys,
		           (int)(strstr(err, "; close it") ? strstr(err, "; close it") - err : (long)strlen(err)), err);
		return EDDY_NULL_SYSTEM;
	}
	const eddy_vec3 lo = w->def.bounds_min, hi = w->def.bounds_max;
	const double blo[3] = {lo.x, lo.y, lo.z}, bhi[3] = {hi.x, hi.y, hi.z};
	for (int a = 0; a < 3; ++a)
		if (m.lo[a] < blo[a] || m.hi[a] > bhi[a]) {
			eddy__fail(w, EDDY_ERR_INVALID,
			           "%s: %s: the mesh's box {%g, %g, %g}..{%g, %g, %g} must lie inside the world bounds", sys,
			           def->path, m.lo[0], m.lo[1], m.lo[2], m.hi[0], m.hi[1], m.hi[2]);
			eddy__mesh_free(&m);
			return EDDY_NULL_SYSTEM;
		}
	int n[3];
	double origin[3], N = 1;
	for (int a = 0; a < 3; ++a) {
		/* as emit_box: a side of exactly k spacings gives k */
		const double c = eddy__count_ceil(m.lo[a], m.hi[a], def->spacing);
		n[a] = c > 0 ? (int)fmin(c, 1 << 30) : 0;
		origin[a] = m.lo[a] + 0.5 * def->spacing;
		N *= c;
	}
	/* the inside test needs 9 bytes a lattice point while it runs */
	if (N > (double)(1ll << 27)) {
		eddy__mesh_free(&m);
		eddy__fail(w, EDDY_ERR_NOMEM,
		           "%s: %s: %.3g lattice points in the mesh's box is more than eddy fills (2^27); use a "
		           "larger spacing",
		           sys, def->path, N);
		return EDDY_NULL_SYSTEM;
	}
	emit_mesh *e = calloc(1, sizeof *e + (size_t)N);
	if (!e) {
		eddy__mesh_free(&m);
		return eddy__fail(w, EDDY_ERR_NOMEM, "%s: out of memory", sys), EDDY_NULL_SYSTEM;
	}
	e->def = *def;
	memcpy(e->n, n, sizeof n);
	memcpy(e->origin, origin, sizeof origin);
	const bool ok = N == 0 || eddy__mesh_inside(&m, origin, def->spacing, n, false, e->inside);
	eddy__mesh_free(&m);
	if (!ok) {
		free(e);
		return eddy__fail(w, EDDY_ERR_NOMEM, "%s: out of memory", sys), EDDY_NULL_SYSTEM;
	}
	for (size_t q = 0; q < (size_t)N; ++q)
		e->count += e->inside[q];
	if (e->count == 0) {
		free(e);
		eddy__fail(w, EDDY_ERR_INVALID,
		           "%s: %s: the mesh holds no lattice point at spacing %g m; use a smaller spacing", sys, def->path,
		           (double)def->spacing);
		return EDDY_NULL_SYSTEM;
	}
	eddy_system_id id = eddy__add_system(w, &eddy__kind_emit_mesh, e, NULL, mesh_writes);
	if (eddy_system_valid(w, id))
		eddy__note_length_scale(w, def->spacing);
	return id;
}
