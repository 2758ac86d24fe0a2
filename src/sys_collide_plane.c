/* SPDX-License-Identifier: MIT */
/* collide_plane: a half-space wall; particles stay on the side the normal
 * points to.
 *
 * Reads: x y z vx vy vz. Writes: x y z vx vy vz.
 * d = (p - point) . n; a particle with d < 0 moves by -d n onto the plane and
 * gets the contact response with normal n. A rotating plane has its point
 * and normal turned about the pivot (by default the point) and the wall
 * velocity v + omega x (x - pivot - offset) at the contact; its SPH patch
 * then turns with it whole.
 * With SPH the plane also carries boundary particles that move with it
 * (sph_points below; Akinci et al., "Versatile rigid-fluid
 * coupling for incompressible SPH", SIGGRAPH 2012); the projection here is
 * the last guard. */
#include "sph/sph.h"
#include "systems.h"

#include <stdlib.h>

typedef struct collide_plane {
	eddy_collider_base base;
	eddy_collide_plane_def def;
} collide_plane;

static const int plane_io[] = {COL_X_, COL_Y_, COL_Z_, COL_VX, COL_VY, COL_VZ, -1};

eddy_collide_plane_def eddy_default_collide_plane_def(void)
{
	eddy_collide_plane_def d;
	d.point = eddy__v3(0, 0, 0);
	d.normal = eddy__v3(0, 1, 0);
	d.response.restitution = 0.0f;
	d.response.friction = 0.0f;
	return d;
}

/* The plane's point and normal in the world now. */
static void plane_now(const collide_plane *b, eddy_vec3 *o, eddy_vec3 *nrm)
{
	if (!eddy__motion_rotates(&b->base.motion)) {
		*o = eddy__add3(b->def.point, b->base.motion.offset);
		*nrm = b->def.normal;
		return;
	}
	const eddy_collider_pose pose = eddy__collider_pose(&b->base.motion);
	*o = eddy__pose_to_world(&pose, b->def.point);
	*nrm = eddy__mat_mul(pose.r, b->def.normal);
}

static eddy_status step(eddy_world *w, eddy_system *s, const eddy_step_context *ctx)
{
	collide_plane *b = s->data;
	/* a rotating plane: its point and normal turn about the pivot, and the
	 * surface moves with v + omega x (x - pivot - offset) */
	const bool rot = eddy__motion_rotates(&b->base.motion);
	eddy_collider_velocity mv = {{0, 0, 0}, {0, 0, 0}, {0, 0, 0}};
	eddy_vec3 vw = {0, 0, 0};
	if (rot)
		mv = eddy__collider_step_motion(&b->base, ctx->dt, 1.0 / w->def.fps);
	else
		vw = eddy__collider_step_velocity(&b->base, ctx->dt, 1.0 / w->def.fps);
	eddy_vec3 o, nrm;
	plane_now(b, &o, &nrm);
	float *x = eddy__col(w, COL_X_), *y = eddy__col(w, COL_Y_), *z = eddy__col(w, COL_Z_);
	float *vx = eddy__col(w, COL_VX), *vy = eddy__col(w, COL_VY), *vz = eddy__col(w, COL_VZ);
	const eddy_collider_response r = b->def.response;
	const long n = (long)w->n;
#pragma omp parallel for num_threads(ctx->threads) if (n > 32768) schedule(static)
	for (long i = 0; i < n; ++i) {
		const float d = (x[i] - o.x) * nrm.x + (y[i] - o.y) * nrm.y + (z[i] - o.z) * nrm.z;
		if (d >= 0)
			continue;
		eddy_vec3 q = eddy__v3(x[i] - d * nrm.x, y[i] - d * nrm.y, z[i] - d * nrm.z);
		/* not out through the world's wall (core.h) but to the crease
		 * between them, by alternate projections (each round closes the
		 * gap by cos^2 of the crease's angle), clamped */
		for (int it = 0; it < 8 && eddy__outside_box(w, q); ++it) {
			q = eddy__into_box(w, q);
			const float e = (q.x - o.x) * nrm.x + (q.y - o.y) * nrm.y + (q.z - o.z) * nrm.z;
			if (e >= 0)
				break;
			q = eddy__v3(q.x - e * nrm.x, q.y - e * nrm.y, q.z - e * nrm.z);
		}
		q = eddy__into_box(w, q);
		x[i] = q.x, y[i] = q.y, z[i] = q.z;
		eddy__collide_response(vx, vy, vz, (size_t)i, nrm,
		                       rot ? eddy__rigid_velocity(&mv, eddy__v3(x[i], y[i], z[i])) : vw, r);
	}
	return EDDY_OK;
}

static float distance(const eddy_system *s, eddy_vec3 q)
{
	const collide_plane *b = s->data;
	eddy_vec3 o, nrm;
	plane_now(b, &o, &nrm);
	return (q.x - o.x) * nrm.x + (q.y - o.y) * nrm.y + (q.z - o.z) * nrm.z;
}

static void shape(const eddy_system *s, eddy_collider_shape *out);
static size_t sph_points(const eddy_world *w, const eddy_system *s, float spacing, float h, float *x, float *y,
                         float *z, float *vol, eddy_vec3 *normal);

const eddy_system_vtable eddy__kind_collide_plane = {
	.name = "collide_plane",
	.step = step,
	.state = eddy__collider_state,
	.limit = eddy__collider_limit,
	.provides = EDDY_CAP_COLLIDER,
	.distance = distance,
	.shape = shape,
	.sph_points = sph_points,
	.default_writes = plane_io,
};

eddy_system_id eddy_add_collide_plane(eddy_world *w, const eddy_collide_plane_def *def)
{
	const char *sys = "collide_plane";
	if (!eddy__add_args(w, def, sys))
		return EDDY_NULL_SYSTEM;
	eddy_vec3 nrm = def->normal;
	if (!eddy__check_vec3(w, sys, "point", def->point) || !eddy__check_unit(w, sys, "normal", &nrm) ||
	    !eddy__check_response(w, sys, def->response))
		return EDDY_NULL_SYSTEM;
	collide_plane *b = calloc(1, sizeof *b);
	if (b) {
		b->def = *def;
		b->def.normal = nrm;
		eddy__collider_init_pivot(&b->base, def->point);
	}
	return eddy__add_system(w, &eddy__kind_collide_plane, b, plane_io, plane_io);
}

/* ---- shape, for drawing (eddy_collider_shape_of) ---- */

static void shape(const eddy_system *s, eddy_collider_shape *out)
{
	const collide_plane *b = s->data;
	out->kind = EDDY_COLLIDER_PLANE;
	plane_now(b, &out->a, &out->b);
	out->radius = 0.0f;
	out->inside = false;
	out->rotation = b->base.motion.rotation;
	out->pivot = eddy__add3(b->base.motion.pivot, b->base.motion.offset);
}

/* ---- boundary particles, for SPH (src/sph/neighbors.c) ----
 * Akinci et al. 2012, laid out as sph_boundary_box lays out its walls: L =
 * ceil(h / s) layers behind the plane at depths (k + 1/2) s, each a square
 * lattice of spacing s in the plane, covering the world bounds' shadow on
 * the plane plus h. The patch stays where it is in the plane and moves only
 * along the normal (a plane sliding along itself is the same plane), so it
 * covers the bounds whatever the offset. On a lattice continued by the fluid
 * each particle stands for V_b = 1 / sum_lattice W, the lattice cell. */
static void plane_basis(eddy_vec3 n, eddy_vec3 *t1, eddy_vec3 *t2)
{
	/* the axis least along n, crossed with n */
	const float ax = fabsf(n.x), ay = fabsf(n.y), az = fabsf(n.z);
	eddy_vec3 a = ax <= ay && ax <= az ? eddy__v3(1, 0, 0) : ay <= az ? eddy__v3(0, 1, 0) : eddy__v3(0, 0, 1);
	eddy_vec3 u = {a.y * n.z - a.z * n.y, a.z * n.x - a.x * n.z, a.x * n.y - a.y * n.x};
	const float l = sqrtf(u.x * u.x + u.y * u.y + u.z * u.z);
	u = eddy__v3(u.x / l, u.y / l, u.z / l);
	*t1 = u;
	*t2 = eddy__v3(n.y * u.z - n.z * u.y, n.z * u.x - n.x * u.z, n.x * u.y - n.y * u.x);
}

static size_t sph_points(const eddy_world *w, const eddy_system *s, float spacing, float h, float *x, float *y,
                         float *z, float *vol, eddy_vec3 *normal)
{
	const collide_plane *b = s->data;
	const eddy_vec3 n = b->def.normal, o = b->def.point;
	eddy_vec3 t1, t2;
	plane_basis(n, &t1, &t2);
	const eddy_vec3 lo = w->def.bounds_min, hi = w->def.bounds_max;
	double u0 = INFINITY, u1 = -INFINITY, v0 = INFINITY, v1 = -INFINITY;
	for (int c = 0; c < 8; ++c) {
		const eddy_vec3 q = {c & 1 ? hi.x : lo.x, c & 2 ? hi.y : lo.y, c & 4 ? hi.z : lo.z};
		const double u = (q.x - o.x) * t1.x + (q.y - o.y) * t1.y + (q.z - o.z) * t1.z,
					 v = (q.x - o.x) * t2.x + (q.y - o.y) * t2.y + (q.z - o.z) * t2.z;
		u0 = fmin(u0, u), u1 = fmax(u1, u), v0 = fmin(v0, v), v1 = fmax(v1, v);
	}
	const double sp = spacing;
	const long nu = (long)ceil((u1 - u0 + 2 * h) / sp), nv = (long)ceil((v1 - v0 + 2 * h) / sp);
	const int L = (int)ceil(h / spacing - 1e-4);
	*normal = n;
	if (!x)
		return (size_t)nu * (size_t)nv * (size_t)L;
	const float v = (float)(1.0 / eddy_sph_lattice_sum(EDDY_SPH_POLY6, sp, h));
	size_t k = 0;
	for (int l = 0; l < L; ++l)
		for (long j = 0; j < nv; ++j)
			for (long i = 0; i < nu; ++i, ++k) {
				const double du = u0 - h + (i + 0.5) * sp, dv = v0 - h + (j + 0.5) * sp, dn = -(l + 0.5) * sp;
				x[k] = (float)(o.x + du * t1.x + dv * t2.x + dn * n.x);
				y[k] = (float)(o.y + du * t1.y + dv * t2.y + dn * n.y);
				z[k] = (float)(o.z + du * t1.z + dv * t2.z + dn * n.z);
				vol[k] = v;
			}
	return k;
}
