/* SPDX-License-Identifier: MIT */
/* collide_box: an axis-aligned box, as a tank (inside = true: particles stay
 * in it) or as a solid block (inside = false: particles stay out of it).
 *
 * Reads: x y z vx vy vz. Writes: x y z vx vy vz.
 * Tank: each coordinate is clamped to [min, max] (+ offset); a clamped axis
 * gets the contact response with that wall's inward normal. Block: a particle
 * inside is moved to the nearest face and responds with its outward normal.
 * The response (core.h) works on velocity relative to the moving wall.
 * A rotated box (eddy_collider_set_rotation) does the same in its own frame:
 * x_b = pivot + R^T (x - pivot - offset), the normal turned back by R and
 * the wall velocity v + omega x (x - pivot - offset) at the contact point.
 * With SPH a block also carries boundary particles that move with it
 * (sph_points below; Akinci et al., "Versatile rigid-fluid
 * coupling for incompressible SPH", SIGGRAPH 2012); a tank's walls are an
 * sph_boundary_box's. The clamping here is the last guard. */
#include "sph/sph.h"
#include "systems.h"

#include <float.h>
#include <stdlib.h>

typedef struct collide_box {
	eddy_collider_base base; /* first: shared offset handling */
	eddy_collide_box_def def;
} collide_box;

static const int box_io[] = {COL_X_, COL_Y_, COL_Z_, COL_VX, COL_VY, COL_VZ, -1};

eddy_collide_box_def eddy_default_collide_box_def(void)
{
	eddy_collide_box_def d;
	d.min = eddy__v3(0, 0, 0);
	d.max = eddy__v3(1, 1, 1);
	d.inside = true;
	d.response.restitution = 0.0f;
	d.response.friction = 0.0f;
	d.sph_walls = true;
	return d;
}

static void bounds(const collide_box *b, eddy_vec3 *lo, eddy_vec3 *hi)
{
	*lo = eddy__add3(b->def.min, b->base.motion.offset);
	*hi = eddy__add3(b->def.max, b->base.motion.offset);
}

/* A rotated box: each particle in the box's own frame (the def pose), the
 * same clamp or push there, back to the world with the normal rotated and
 * the wall velocity of the surface point it ends at. */
static void step_rotated(eddy_world *w, collide_box *b, const eddy_collider_velocity *mv, int threads)
{
	const eddy_collider_pose pose = eddy__collider_pose(&b->base.motion);
	const float l[3] = {b->def.min.x, b->def.min.y, b->def.min.z}, h[3] = {b->def.max.x, b->def.max.y, b->def.max.z};
	float *x = eddy__col(w, COL_X_), *y = eddy__col(w, COL_Y_), *z = eddy__col(w, COL_Z_);
	float *vx = eddy__col(w, COL_VX), *vy = eddy__col(w, COL_VY), *vz = eddy__col(w, COL_VZ);
	const eddy_collider_response r = b->def.response;
	const bool tank = b->def.inside;
	const long n = (long)w->n;
	/* the round trip's error: a few float ulps of the coordinates it adds */
	const eddy_vec3 wl = w->def.bounds_min, wh = w->def.bounds_max;
	const float reach =
		eddy__maxf(eddy__maxf(fabsf(wl.x), fabsf(wh.x)),
	               eddy__maxf(eddy__maxf(fabsf(wl.y), fabsf(wh.y)), eddy__maxf(fabsf(wl.z), fabsf(wh.z))));
	const float slack = 64.0f * FLT_EPSILON * (reach + (h[0] - l[0]) + (h[1] - l[1]) + (h[2] - l[2]));
#pragma omp parallel for num_threads(threads) if (n > 32768) schedule(static)
	for (long i = 0; i < n; ++i) {
		const eddy_vec3 qb = eddy__pose_to_body(&pose, eddy__v3(x[i], y[i], z[i]));
		float q[3] = {qb.x, qb.y, qb.z};
		if (tank) {
			bool pushed = false;
			for (int a = 0; a < 3; ++a) {
				if (q[a] >= l[a] && q[a] <= h[a])
					continue;
				eddy_vec3 nrm = {0, 0, 0};
				float *c = a == 0 ? &nrm.x : a == 1 ? &nrm.y : &nrm.z;
				*c = q[a] < l[a] ? 1.0f : -1.0f;
				q[a] = q[a] < l[a] ? l[a] : h[a];
				/* a turned tank's wall can lie past the world's: in the box (core.h) */
				eddy__collide_rotated_in(w, x, y, z, vx, vy, vz, (size_t)i, &pose, mv, eddy__v3(q[0], q[1], q[2]), nrm,
				                         r);
				pushed = true;
			}
			/* Where a wall of the turned tank lies on the world's (a tank the
			 * world's size rocked about the axis along that wall), a particle
			 * a hair past both reads inside the tank after the round trip
			 * through its frame. Within that rounding it is put on the wall;
			 * farther out it is the tank's inside past the world, an error
			 * of the scene that check_bounds reports. */
			if (!pushed) {
				const eddy_vec3 at = eddy__v3(x[i], y[i], z[i]), in = eddy__into_box(w, at);
				if (fabsf(in.x - at.x) + fabsf(in.y - at.y) + fabsf(in.z - at.z) <= slack)
					x[i] = in.x, y[i] = in.y, z[i] = in.z;
			}
			continue;
		}
		int best = -1;
		float depth = INFINITY, sign = 0;
		for (int a = 0; a < 3; ++a) {
			if (!(q[a] > l[a] && q[a] < h[a])) {
				best = -1;
				break;
			}
			if (q[a] - l[a] < depth)
				depth = q[a] - l[a], best = a, sign = -1;
			if (h[a] - q[a] < depth)
				depth = h[a] - q[a], best = a, sign = 1;
		}
		if (best < 0)
			continue;
		eddy_vec3 nrm = {0, 0, 0};
		float *c = best == 0 ? &nrm.x : best == 1 ? &nrm.y : &nrm.z;
		*c = sign;
		q[best] = sign > 0 ? h[best] : l[best];
		/* not out through the world's wall (core.h) */
		eddy__collide_rotated_in(w, x, y, z, vx, vy, vz, (size_t)i, &pose, mv, eddy__v3(q[0], q[1], q[2]), nrm, r);
	}
}

static eddy_status step(eddy_world *w, eddy_system *s, const eddy_step_context *ctx)
{
	collide_box *b = s->data;
	if (eddy__motion_rotates(&b->base.motion)) {
		const eddy_collider_velocity mv = eddy__collider_step_motion(&b->base, ctx->dt, 1.0 / w->def.fps);
		step_rotated(w, b, &mv, ctx->threads);
		return EDDY_OK;
	}
	const eddy_vec3 vw = eddy__collider_step_velocity(&b->base, ctx->dt, 1.0 / w->def.fps);
	eddy_vec3 lo, hi;
	bounds(b, &lo, &hi);
	const float l[3] = {lo.x, lo.y, lo.z}, h[3] = {hi.x, hi.y, hi.z};
	float *p[3] = {eddy__col(w, COL_X_), eddy__col(w, COL_Y_), eddy__col(w, COL_Z_)};
	float *vx = eddy__col(w, COL_VX), *vy = eddy__col(w, COL_VY), *vz = eddy__col(w, COL_VZ);
	const eddy_collider_response r = b->def.response;
	const long n = (long)w->n;
	if (b->def.inside) {
#pragma omp parallel for num_threads(ctx->threads) if (n > 32768) schedule(static)
		for (long i = 0; i < n; ++i) {
			for (int a = 0; a < 3; ++a) {
				float q = p[a][i];
				if (q >= l[a] && q <= h[a])
					continue;
				eddy_vec3 nrm = {0, 0, 0};
				float *c = a == 0 ? &nrm.x : a == 1 ? &nrm.y : &nrm.z;
				*c = q < l[a] ? 1.0f : -1.0f;
				p[a][i] = q < l[a] ? l[a] : h[a];
				eddy__collide_response(vx, vy, vz, (size_t)i, nrm, vw, r);
			}
		}
		return EDDY_OK;
	}
	/* a face on or beyond the world's wall is no way out (core.h: it would
	 * leave the particle in the crease between them, or outside), unless no
	 * face is one */
	const eddy_vec3 wl = w->def.bounds_min, wh = w->def.bounds_max;
	const bool lo_ok[3] = {l[0] > wl.x, l[1] > wl.y, l[2] > wl.z}, hi_ok[3] = {h[0] < wh.x, h[1] < wh.y, h[2] < wh.z};
	const bool any_ok = lo_ok[0] || lo_ok[1] || lo_ok[2] || hi_ok[0] || hi_ok[1] || hi_ok[2];
#pragma omp parallel for num_threads(ctx->threads) if (n > 32768) schedule(static)
	for (long i = 0; i < n; ++i) {
		int best = -1;
		float depth = INFINITY, sign = 0;
		for (int a = 0; a < 3; ++a) {
			const float q = p[a][i];
			/* a face on the world's wall is closed: a particle on the
			 * floor under a block is in it, not in a gap under it */
			if (!((lo_ok[a] ? q > l[a] : q >= l[a]) && (hi_ok[a] ? q < h[a] : q <= h[a]))) {
				best = -1;
				break;
			}
			if (q - l[a] < depth && (lo_ok[a] || !any_ok)) {
				depth = q - l[a];
				best = a;
				sign = -1;
			}
			if (h[a] - q < depth && (hi_ok[a] || !any_ok)) {
				depth = h[a] - q;
				best = a;
				sign = 1;
			}
		}
		if (best < 0)
			continue;
		eddy_vec3 nrm = {0, 0, 0};
		float *c = best == 0 ? &nrm.x : best == 1 ? &nrm.y : &nrm.z;
		*c = sign;
		p[best][i] = sign > 0 ? h[best] : l[best];
		eddy__collide_response(vx, vy, vz, (size_t)i, nrm, vw, r);
	}
	return EDDY_OK;
}

static float distance(const eddy_system *s, eddy_vec3 q)
{
	const collide_box *b = s->data;
	eddy_vec3 lo, hi;
	if (eddy__motion_rotates(&b->base.motion)) {
		const eddy_collider_pose pose = eddy__collider_pose(&b->base.motion);
		q = eddy__pose_to_body(&pose, q);
		lo = b->def.min, hi = b->def.max;
	} else {
		bounds(b, &lo, &hi);
	}
	/* distance to the box surface, negative inside the box */
	const float dx = eddy__maxf(lo.x - q.x, q.x - hi.x), dy = eddy__maxf(lo.y - q.y, q.y - hi.y),
				dz = eddy__maxf(lo.z - q.z, q.z - hi.z);
	const float ox = eddy__maxf(dx, 0), oy = eddy__maxf(dy, 0), oz = eddy__maxf(dz, 0);
	const float box_sd = sqrtf(ox * ox + oy * oy + oz * oz) + eddy__minf(eddy__maxf(dx, eddy__maxf(dy, dz)), 0);
	/* a tank's solid is everything outside the box */
	return b->def.inside ? -box_sd : box_sd;
}

static void shape(const eddy_system *s, eddy_collider_shape *out);
static size_t sph_points(const eddy_world *w, const eddy_system *s, float spacing, float h, float *x, float *y,
                         float *z, float *vol, eddy_vec3 *normal);

const eddy_system_vtable eddy__kind_collide_box = {
	.name = "collide_box",
	.step = step,
	.state = eddy__collider_state,
	.limit = eddy__collider_limit,
	.provides = EDDY_CAP_COLLIDER,
	.distance = distance,
	.shape = shape,
	.sph_points = sph_points,
	.default_writes = box_io,
};

eddy_system_id eddy_add_collide_box(eddy_world *w, const eddy_collide_box_def *def)
{
	const char *sys = "collide_box";
	if (!eddy__add_args(w, def, sys))
		return EDDY_NULL_SYSTEM;
	if (!eddy__check_box(w, sys, def->min, def->max) || !eddy__check_response(w, sys, def->response))
		return EDDY_NULL_SYSTEM;
	collide_box *b = calloc(1, sizeof *b);
	if (b) {
		b->def = *def;
		eddy__collider_init_pivot(&b->base, eddy__v3(0.5f * (def->min.x + def->max.x), 0.5f * (def->min.y + def->max.y),
		                                             0.5f * (def->min.z + def->max.z)));
	}
	return eddy__add_system(w, &eddy__kind_collide_box, b, box_io, box_io);
}

/* ---- shape, for drawing (eddy_collider_shape_of) ---- */

static void shape(const eddy_system *s, eddy_collider_shape *out)
{
	const collide_box *b = s->data;
	out->kind = EDDY_COLLIDER_BOX;
	bounds(b, &out->a, &out->b);
	out->radius = 0.0f;
	out->inside = b->def.inside;
	out->rotation = b->base.motion.rotation;
	out->pivot = eddy__add3(b->base.motion.pivot, b->base.motion.offset);
}

/* ---- boundary particles, for SPH (src/sph/neighbors.c) ----
 * A block (inside = false): the lattice inside it, min + (i + 1/2) s_a on
 * each axis (s_a the spacing adjusted to a whole number of cells, at least
 * one), keeping the points within L = ceil(h / s) layers of a face: a shell
 * as thick as the kernel support, each point standing for the lattice cell
 * V_b = 1 / sum_lattice W, as sph_boundary_box does (Akinci et al. 2012).
 * A tank (inside = true): the lattice continued L layers out through its
 * walls, the points outside it (sph_boundary_box's layout), so a tank that
 * moves or turns carries its walls with it. Neither gets any where an
 * sph_boundary_box already samples the box (the same min and max: eddy.fluid's
 * tank, a thin plate), nor with sph_walls = false. */
static size_t sph_points(const eddy_world *w, const eddy_system *s, float spacing, float h, float *x, float *y,
                         float *z, float *vol, eddy_vec3 *normal)
{
	(void)normal;
	const collide_box *b = s->data;
	if (!b->def.sph_walls)
		return 0;
	const eddy_system *o;
	for (eddy_system_iter it = eddy__systems(w, EDDY_CAP_SPH_WALLS); (o = eddy__systems_next(&it));)
		if (eddy__sph_boundary_box_covers(o, b->def.min, b->def.max))
			return 0;
	const float lo[3] = {b->def.min.x, b->def.min.y, b->def.min.z}, hi[3] = {b->def.max.x, b->def.max.y, b->def.max.z};
	long n[3];
	double sp[3];
	for (int a = 0; a < 3; ++a) {
		n[a] = (long)fmax(1.0, round((hi[a] - lo[a]) / spacing));
		sp[a] = (hi[a] - lo[a]) / (double)n[a];
	}
	const long L = (long)ceil(h / spacing - 1e-4);
	const float v = (float)(1.0 / eddy_sph_lattice_sum(EDDY_SPH_POLY6, spacing, h));
	/* the lattice over [a, e) on each axis, less the rows' middles [c, f):
	 * a block's points within L layers inside its faces, a tank's the
	 * lattice continued L layers out through its walls (sph_boundary_box's
	 * layout), carried by the tank as it moves and turns */
	const bool tank = b->def.inside;
	long a[3], e[3], c[3], f[3];
	for (int ax = 0; ax < 3; ++ax) {
		a[ax] = tank ? -L : 0, e[ax] = tank ? n[ax] + L : n[ax];
		c[ax] = tank ? 0 : L, f[ax] = tank ? n[ax] : n[ax] - L;
	}
	size_t k = 0;
	for (long iz = a[2]; iz < e[2]; ++iz)
		for (long iy = a[1]; iy < e[1]; ++iy) {
			/* a row through the middle keeps only its ends */
			const bool through = iy >= c[1] && iy < f[1] && iz >= c[2] && iz < f[2];
			for (long ix = a[0]; ix < e[0]; ++ix) {
				if (through && ix == c[0] && f[0] > c[0])
					ix = f[0];
				if (x) {
					x[k] = (float)(lo[0] + (ix + 0.5) * sp[0]);
					y[k] = (float)(lo[1] + (iy + 0.5) * sp[1]);
					z[k] = (float)(lo[2] + (iz + 0.5) * sp[2]);
					vol[k] = v;
				}
				k++;
			}
		}
	return k;
}
