/* SPDX-License-Identifier: MIT */
/* collide_sphere: a solid ball (inside = false) or a spherical bowl that
 * particles stay inside (inside = true).
 *
 * Reads: x y z vx vy vz. Writes: x y z vx vy vz.
 * A particle on the solid side is projected radially onto the sphere and gets
 * the contact response with the normal pointing out of the solid. A particle
 * exactly at the centre of a ball leaves along +y. A rotating sphere
 * (eddy_collider_set_rotation) has its centre turned about the pivot and a
 * surface moving at v + omega x (x - pivot - offset), which the response
 * takes as the wall's velocity (a ball spinning about its centre drags
 * particles with friction > 0).
 * With SPH the sphere also carries boundary particles that move with it
 * (sph_points below; Akinci et al., "Versatile rigid-fluid
 * coupling for incompressible SPH", SIGGRAPH 2012): the fluid beside it then
 * has a full neighbourhood, and the projection here is the last guard. */
#include "sph/sph.h"
#include "systems.h"

#include <stdlib.h>

#ifndef M_PI
#define M_PI 3.14159265358979323846
#endif

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
	/* a rotating sphere: its centre turns about the pivot, and the surface
	 * moves with v + omega x (x - pivot - offset) */
	const bool rot = eddy__motion_rotates(&b->base.motion);
	const eddy_collider_pose pose = eddy__collider_pose(&b->base.motion);
	eddy_collider_velocity mv = {{0, 0, 0}, {0, 0, 0}, {0, 0, 0}};
	eddy_vec3 vw = {0, 0, 0};
	if (rot)
		mv = eddy__collider_step_motion(&b->base, ctx->dt, 1.0 / w->def.fps);
	else
		vw = eddy__collider_step_velocity(&b->base, ctx->dt, 1.0 / w->def.fps);
	const eddy_vec3 c =
		rot ? eddy__pose_to_world(&pose, b->def.center) : eddy__add3(b->def.center, b->base.motion.offset);
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
		eddy_vec3 q = eddy__v3(c.x + u.x * rad, c.y + u.y * rad, c.z + u.z * rad);
		/* a sphere cutting the world's wall: not out through it (core.h),
		 * but to the crease between them, by alternate projections (each
		 * round closes the gap by cos^2 of the crease's angle), clamped */
		for (int it = 0; it < 8 && eddy__outside_box(w, q); ++it) {
			q = eddy__into_box(w, q);
			const eddy_vec3 e = {q.x - c.x, q.y - c.y, q.z - c.z};
			const float de = sqrtf(e.x * e.x + e.y * e.y + e.z * e.z);
			if (bowl ? de <= rad : de >= rad)
				break;
			q = eddy__v3(c.x + e.x / de * rad, c.y + e.y / de * rad, c.z + e.z / de * rad);
		}
		q = eddy__into_box(w, q);
		x[i] = q.x, y[i] = q.y, z[i] = q.z;
		const eddy_vec3 nrm = bowl ? eddy__v3(-u.x, -u.y, -u.z) : u;
		eddy__collide_response(vx, vy, vz, (size_t)i, nrm,
		                       rot ? eddy__rigid_velocity(&mv, eddy__v3(x[i], y[i], z[i])) : vw, r);
	}
	return EDDY_OK;
}

/* The centre in the world: turned about the pivot when the sphere rotates. */
static eddy_vec3 center_now(const collide_sphere *b)
{
	if (!eddy__motion_rotates(&b->base.motion))
		return eddy__add3(b->def.center, b->base.motion.offset);
	const eddy_collider_pose pose = eddy__collider_pose(&b->base.motion);
	return eddy__pose_to_world(&pose, b->def.center);
}

static float distance(const eddy_system *s, eddy_vec3 q)
{
	const collide_sphere *b = s->data;
	const eddy_vec3 c = center_now(b);
	const float dx = q.x - c.x, dy = q.y - c.y, dz = q.z - c.z;
	const float d = sqrtf(dx * dx + dy * dy + dz * dz) - b->def.radius;
	return b->def.inside ? -d : d;
}

static void shape(const eddy_system *s, eddy_collider_shape *out);
static size_t sph_points(const eddy_world *w, const eddy_system *s, float spacing, float h, float *x, float *y,
                         float *z, float *vol, eddy_vec3 *normal);

const eddy_system_vtable eddy__kind_collide_sphere = {
	.name = "collide_sphere",
	.step = step,
	.state = eddy__collider_state,
	.limit = eddy__collider_limit,
	.provides = EDDY_CAP_COLLIDER,
	.distance = distance,
	.shape = shape,
	.sph_points = sph_points,
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
	if (b) {
		b->def = *def;
		eddy__collider_init_pivot(&b->base, def->center);
	}
	return eddy__add_system(w, &eddy__kind_collide_sphere, b, sphere_io, sphere_io);
}

/* ---- shape, for drawing (eddy_collider_shape_of) ---- */

static void shape(const eddy_system *s, eddy_collider_shape *out)
{
	const collide_sphere *b = s->data;
	out->kind = EDDY_COLLIDER_SPHERE;
	out->a = center_now(b);
	out->b = eddy__v3(0, 0, 0);
	out->radius = b->def.radius;
	out->rotation = b->base.motion.rotation;
	out->pivot = eddy__add3(b->base.motion.pivot, b->base.motion.offset);
	out->inside = b->def.inside;
}

/* ---- boundary particles, for SPH (src/sph/neighbors.c) ----
 * Akinci et al. 2012: the solid's surface sampled at about the fluid
 * spacing s, each particle standing for the volume V_b = 1 / sum_k W_bk.
 * Layers of radius R -+ (k + 1/2) s, k = 0 .. L - 1, L = ceil(h / s) (inward
 * for a ball, outward for a bowl): a shell as thick as the kernel support,
 * so a fluid particle at the surface sees a full neighbourhood, as at an
 * sph_boundary_box. Each layer is a Fibonacci sphere of round(4 pi r^2 / s^2)
 * points (a near-uniform spread at any radius). The sum in V_b runs over the
 * shell and its continuation by L more layers into the fluid (where a fluid
 * at rest would be): over the shell alone (Akinci's single layer) the outer
 * layer's half-empty neighbourhood would over-weight it, as
 * src/sph/boundary_box.c explains. The sum is the mean over up to 16 points
 * of the layer (the spread is uniform, so the layer shares one volume). */
static size_t fib_layer(double rk, double s, double *px, double *py, double *pz)
{
	const size_t nk = (size_t)fmax(1.0, round(4 * M_PI * rk * rk / (s * s)));
	if (px) {
		const double golden = M_PI * (3.0 - sqrt(5.0));
		for (size_t j = 0; j < nk; ++j) {
			const double zz = 1.0 - (2.0 * (double)j + 1.0) / (double)nk, rr = sqrt(fmax(0.0, 1.0 - zz * zz)),
						 ph = golden * (double)j;
			px[j] = rk * rr * cos(ph);
			py[j] = rk * zz;
			pz[j] = rk * rr * sin(ph);
		}
	}
	return nk;
}

static size_t sph_points(const eddy_world *w, const eddy_system *s, float spacing, float h, float *x, float *y,
                         float *z, float *vol, eddy_vec3 *normal)
{
	(void)w;
	(void)normal;
	const collide_sphere *b = s->data;
	const double R = b->def.radius, sp = spacing, hh = h;
	const int L = (int)ceil(h / spacing - 1e-4);
	const double dir = b->def.inside ? 1.0 : -1.0; /* toward the solid */
	/* layer k >= 0: solid (kept); k < 0: the fluid's continuation (for V_b) */
	size_t real = 0, all = 0;
	int kmax = L; /* the solid layers that fit (a small ball holds fewer) */
	for (int k = -L; k < L; ++k) {
		const double rk = R + dir * (k + 0.5) * sp;
		if (rk <= 0) {
			if (k >= 0 && k < kmax)
				kmax = k;
			continue;
		}
		const size_t nk = fib_layer(rk, sp, NULL, NULL, NULL);
		all += nk;
		if (k >= 0)
			real += nk;
	}
	if (!x)
		return real;
	double *px = malloc((all + 1) * sizeof *px), *py = malloc((all + 1) * sizeof *py),
		   *pz = malloc((all + 1) * sizeof *pz);
	size_t *start = malloc((size_t)(2 * L + 1) * sizeof *start);
	if (!px || !py || !pz || !start) {
		/* no memory for the volume sums: the lattice cell's volume instead */
		free(px), free(py), free(pz), free(start);
		px = py = pz = NULL;
		start = NULL;
	}
	size_t at = 0, out = 0;
	for (int k = -L; k < L; ++k) {
		const double rk = R + dir * (k + 0.5) * sp;
		if (start)
			start[k + L] = at;
		if (rk <= 0)
			continue;
		if (px)
			at += fib_layer(rk, sp, px + at, py + at, pz + at);
	}
	if (start)
		start[2 * L] = at;
	const double lattice_v = 1.0 / eddy_sph_lattice_sum(EDDY_SPH_POLY6, sp, hh);
	const eddy_vec3 c = b->def.center;
	for (int k = 0; k < kmax; ++k) {
		const double rk = R + dir * (k + 0.5) * sp;
		const size_t nk = fib_layer(rk, sp, NULL, NULL, NULL);
		double v = lattice_v;
		if (px) {
			/* the mean kernel sum at up to 16 points spread over the layer */
			const size_t s0 = start[k + L], probes = nk < 16 ? nk : 16;
			double sum = 0;
			for (size_t q = 0; q < probes; ++q) {
				const size_t i = s0 + (2 * q + 1) * nk / (2 * probes);
				for (size_t j = 0; j < at; ++j) {
					const double dx = px[i] - px[j], dy = py[i] - py[j], dz = pz[i] - pz[j];
					sum += eddy_sph_kernel_value(EDDY_SPH_POLY6, sqrt(dx * dx + dy * dy + dz * dz), hh);
				}
			}
			v = (double)probes / sum;
		}
		double *lx = malloc(nk * sizeof *lx), *ly = malloc(nk * sizeof *ly), *lz = malloc(nk * sizeof *lz);
		if (!lx || !ly || !lz) {
			free(lx), free(ly), free(lz);
			break; /* the caller sees fewer points than it counted */
		}
		fib_layer(rk, sp, lx, ly, lz);
		for (size_t j = 0; j < nk; ++j, ++out) {
			x[out] = (float)(c.x + lx[j]);
			y[out] = (float)(c.y + ly[j]);
			z[out] = (float)(c.z + lz[j]);
			vol[out] = (float)v;
		}
		free(lx), free(ly), free(lz);
	}
	free(px), free(py), free(pz), free(start);
	return out;
}
