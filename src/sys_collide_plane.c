/* SPDX-License-Identifier: MIT */
/* collide_plane: a half-space wall; particles stay on the side the normal
 * points to.
 *
 * Reads: x y z vx vy vz. Writes: x y z vx vy vz.
 * d = (p - point) . n; a particle with d < 0 moves by -d n onto the plane and
 * gets the contact response with normal n. */
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

static eddy_status step(eddy_world *w, eddy_system *s, const eddy_step_context *ctx)
{
	collide_plane *b = s->data;
	const eddy_vec3 vw = eddy__collider_step_velocity(&b->base, ctx->dt);
	const eddy_vec3 o = eddy__add3(b->def.point, b->base.motion.offset), nrm = b->def.normal;
	float *x = eddy__col(w, COL_X_), *y = eddy__col(w, COL_Y_), *z = eddy__col(w, COL_Z_);
	float *vx = eddy__col(w, COL_VX), *vy = eddy__col(w, COL_VY), *vz = eddy__col(w, COL_VZ);
	const eddy_collider_response r = b->def.response;
	const long n = (long)w->n;
#pragma omp parallel for num_threads(ctx->threads) if (n > 32768) schedule(static)
	for (long i = 0; i < n; ++i) {
		const float d = (x[i] - o.x) * nrm.x + (y[i] - o.y) * nrm.y + (z[i] - o.z) * nrm.z;
		if (d >= 0)
			continue;
		x[i] -= d * nrm.x;
		y[i] -= d * nrm.y;
		z[i] -= d * nrm.z;
		eddy__collide_response(vx, vy, vz, (size_t)i, nrm, vw, r);
	}
	return EDDY_OK;
}

static float distance(const eddy_system *s, eddy_vec3 q)
{
	const collide_plane *b = s->data;
	const eddy_vec3 o = eddy__add3(b->def.point, b->base.motion.offset), nrm = b->def.normal;
	return (q.x - o.x) * nrm.x + (q.y - o.y) * nrm.y + (q.z - o.z) * nrm.z;
}

const eddy_system_vtable eddy__kind_collide_plane = {
	.name = "collide_plane",
	.step = step,
	.state = eddy__collider_state,
	.distance = distance,
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
	}
	return eddy__add_system(w, &eddy__kind_collide_plane, b, plane_io, 6, plane_io, 6);
}

/* ---- shape, for drawing (eddy_collider_shape_of) ---- */
#include "collider_shape.h"

void eddy__shape_collide_plane(const eddy_system *s, eddy_collider_shape *out)
{
	const collide_plane *b = s->data;
	out->kind = EDDY_COLLIDER_PLANE;
	out->a = eddy__add3(b->def.point, b->base.motion.offset);
	out->b = b->def.normal;
	out->radius = 0.0f;
	out->inside = false;
}
