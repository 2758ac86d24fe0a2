/* SPDX-License-Identifier: MIT */
/* collide_sphere: a solid ball (inside = false) or a spherical bowl that
 * particles stay inside (inside = true).
 *
 * Reads: x y z vx vy vz. Writes: x y z vx vy vz.
 * A particle on the solid side is projected radially onto the sphere and gets
 * the contact response with the normal pointing out of the solid. A particle
 * exactly at the centre of a ball leaves along +y. */
#include "systems.h"

#include <stdlib.h>

typedef struct collide_sphere {
	eddy_collider_base base;
	eddy_collide_sphere_def def;
} collide_sphere;

static const int sphere_io[] = {COL_X_, COL_Y_, COL_Z_, COL_VX, COL_VY, COL_VZ, -1};

eddy_collide_sphere_def eddy_default_collide_sphere_def(void)
{
	eddy_collide_sphere_def d;
	d.center = eddy__v3(0.5f, 0.5f, 0.5f);
	d.radius = 0.1f;
	d.inside = false;
	d.response.restitution = 0.0f;
	d.response.friction = 0.0f;
	return d;
}

static eddy_status step(eddy_world *w, eddy_system *s, const eddy_step_context *ctx)
{
	collide_sphere *b = s->data;
	const eddy_vec3 vw = eddy__collider_step_velocity(&b->base, ctx->dt);
	const eddy_vec3 c = eddy__add3(b->def.center, b->base.motion.offset);
	const float rad = b->def.radius;
	const bool bowl = b->def.inside;
	float *x = eddy__col(w, COL_X_), *y = eddy__col(w, COL_Y_), *z = eddy__col(w, COL_Z_);
	float *vx = eddy__col(w, COL_VX), *vy = eddy__col(w, COL_VY), *vz = eddy__col(w, COL_VZ);
	const eddy_collider_response r = b->def.response;
	const long n = (long)w->n;
#pragma omp parallel for num_threads(ctx->threads) if (n > 32768) schedule(static)
	for (long i = 0; i < n; ++i) {
		const float dx = x[i] - c.x, dy = y[i] - c.y, dz = z[i] - c.z;
		const float d2 = dx * dx + dy * dy + dz * dz;
		if (bowl ? d2 <= rad * rad : d2 >= rad * rad)
			continue;
		const float d = sqrtf(d2);
		eddy_vec3 u = d > 0 ? eddy__v3(dx / d, dy / d, dz / d) : eddy__v3(0, 1, 0);
		x[i] = c.x + u.x * rad;
		y[i] = c.y + u.y * rad;
		z[i] = c.z + u.z * rad;
		const eddy_vec3 nrm = bowl ? eddy__v3(-u.x, -u.y, -u.z) : u;
		eddy__collide_response(vx, vy, vz, (size_t)i, nrm, vw, r);
	}
	return EDDY_OK;
}

static float distance(const eddy_system *s, eddy_vec3 q)
{
	const collide_sphere *b = s->data;
	const eddy_vec3 c = eddy__add3(b->def.center, b->base.motion.offset);
	const float dx = q.x - c.x, dy = q.y - c.y, dz = q.z - c.z;
	const float d = sqrtf(dx * dx + dy * dy + dz * dz) - b->def.radius;
	return b->def.inside ? -d : d;
}

const eddy_system_vtable eddy__kind_collide_sphere = {
	.name = "collide_sphere",
	.step = step,
	.state = eddy__collider_state,
	.distance = distance,
	.default_writes = sphere_io,
};

eddy_system_id eddy_add_collide_sphere(eddy_world *w, const eddy_collide_sphere_def *def)
{
	const char *sys = "collide_sphere";
	if (!eddy__add_args(w, def, sys))
		return EDDY_NULL_SYSTEM;
	if (!eddy__check_vec3(w, sys, "center", def->center) || !eddy__check_positive(w, sys, "radius", def->radius) ||
	    !eddy__check_response(w, sys, def->response))
		return EDDY_NULL_SYSTEM;
	collide_sphere *b = calloc(1, sizeof *b);
	if (b)
		b->def = *def;
	return eddy__add_system(w, &eddy__kind_collide_sphere, b, sphere_io, 6, sphere_io, 6);
}

/* ---- shape, for drawing (eddy_collider_shape_of) ---- */
#include "collider_shape.h"

void eddy__shape_collide_sphere(const eddy_system *s, eddy_collider_shape *out)
{
	const collide_sphere *b = s->data;
	out->kind = EDDY_COLLIDER_SPHERE;
	out->a = eddy__add3(b->def.center, b->base.motion.offset);
	out->b = eddy__v3(0, 0, 0);
	out->radius = b->def.radius;
	out->inside = b->def.inside;
}
