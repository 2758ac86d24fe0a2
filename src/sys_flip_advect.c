/* SPDX-License-Identifier: MIT */
/* flip_advect: particles move through the divergence-free grid velocity
 * (Zhu & Bridson 2005, section 4: advection through the grid field, RK2).
 *
 * Reads: x y z u v w. Writes: x y z.
 *   x_mid = x + dt/2 U(x),  x <- x + dt U(x_mid)   (U trilinear on the MAC grid)
 * Projection out of solids: coordinates are clamped to the domain shrunk by
 * wall_gap cells (not where flip_boundary opens them, open_sides: a particle
 * that flows out leaves the bounds, and the world removes it or stops, as
 * its escape says); a particle closer than that to a collider's solid (signed
 * distance phi < gap) moves along the distance gradient n (central
 * differences) by gap - phi, twice at most, so thin colliders cannot be
 * tunnelled through at the end of a step.
 * Limit: dt <= dx / (max |v_p| + sqrt(|g| dx)), the world's cfl being the CFL
 * number C (FLIP is stable well past C = 1; extrapolate C + 1 layers). The
 * sqrt(g dx) term stops a fluid starting from rest from taking a first step
 * far longer than the next. */
#include "flip.h"

#include <stdlib.h>

typedef struct advect {
	eddy_flip_advect_def def;
} advect;

static const int advect_reads[] = {COL_X_, COL_Y_, COL_Z_, COL_FACE_U, COL_FACE_V, COL_FACE_W, -1};
static const int advect_writes[] = {COL_X_, COL_Y_, COL_Z_, -1};

eddy_flip_advect_def eddy_default_flip_advect_def(void)
{
	eddy_flip_advect_def d;
	d.wall_gap = 0.01f;
	return d;
}

static eddy_vec3 push_out(const eddy_system *c, eddy_vec3 p, float gap, float eps)
{
	for (int it = 0; it < 2; ++it) {
		const float d = c->vt->distance(c, p);
		if (!(d < gap))
			return p;
		eddy_vec3 g = {
			c->vt->distance(c, eddy__v3(p.x + eps, p.y, p.z)) - c->vt->distance(c, eddy__v3(p.x - eps, p.y, p.z)),
			c->vt->distance(c, eddy__v3(p.x, p.y + eps, p.z)) - c->vt->distance(c, eddy__v3(p.x, p.y - eps, p.z)),
			c->vt->distance(c, eddy__v3(p.x, p.y, p.z + eps)) - c->vt->distance(c, eddy__v3(p.x, p.y, p.z - eps))};
		const float len = sqrtf(g.x * g.x + g.y * g.y + g.z * g.z);
		if (!(len > 0))
			return p;
		const float k = (gap - d) / len;
		p = eddy__v3(p.x + g.x * k, p.y + g.y * k, p.z + g.z * k);
	}
	return p;
}

static float clampf(float v, float lo, float hi) { return v < lo ? lo : v > hi ? hi : v; }

static eddy_status step(eddy_world *w, eddy_system *s, const eddy_step_context *ctx)
{
	const advect *ad = s->data;
	const float dt = (float)ctx->dt, h = (float)w->def.cell_size, gap = ad->def.wall_gap * h;
	float *x = eddy__col(w, COL_X_), *y = eddy__col(w, COL_Y_), *z = eddy__col(w, COL_Z_);
	const float *u = eddy__col(w, COL_FACE_U), *v = eddy__col(w, COL_FACE_V), *wv = eddy__col(w, COL_FACE_W);
	const eddy_vec3 lo = w->def.bounds_min, hi = w->def.bounds_max;
	const eddy_system *col[EDDY_MAX_SYSTEMS];
	int nc = 0;
	eddy_system_iter it = eddy__systems(w, EDDY_CAP_COLLIDER);
	for (const eddy_system *c; (c = eddy__systems_next(&it));)
		col[nc++] = c;
	const long n = (long)w->n;
	const flip_grid grid = flip_grid_of(w);
	const bool open_sides = eddy__flip_open_sides(w);
#pragma omp parallel for num_threads(ctx->threads) if (n > 16384) schedule(static)
	for (long i = 0; i < n; ++i) {
		eddy_vec3 p = {x[i], y[i], z[i]};
		const eddy_vec3 v0 = flip_velocity_at(&grid, u, v, wv, p);
		const eddy_vec3 pm = {p.x + 0.5f * dt * v0.x, p.y + 0.5f * dt * v0.y, p.z + 0.5f * dt * v0.z};
		const eddy_vec3 v1 = flip_velocity_at(&grid, u, v, wv, pm);
		p = eddy__v3(p.x + dt * v1.x, p.y + dt * v1.y, p.z + dt * v1.z);
		for (int c = 0; c < nc; ++c)
			p = push_out(col[c], p, gap, 0.01f * h);
		if (open_sides) { /* beyond the bounds the world removes it */
			x[i] = p.x, y[i] = p.y, z[i] = p.z;
			continue;
		}
		x[i] = clampf(p.x, lo.x + gap, hi.x - gap);
		y[i] = clampf(p.y, lo.y + gap, hi.y - gap);
		z[i] = clampf(p.z, lo.z + gap, hi.z - gap);
	}
	return EDDY_OK;
}

double eddy__flip_advect_time(eddy_world *w)
{
	const float v2 = eddy__max_norm2(w, COL_VX, COL_VY, COL_VZ);
	const eddy_vec3 g = w->def.gravity;
	const double h = w->def.cell_size;
	const double vmax = sqrt((double)v2) + sqrt(sqrt((double)g.x * g.x + (double)g.y * g.y + (double)g.z * g.z) * h);
	return vmax > 0 ? h / vmax : INFINITY;
}

static double limit(eddy_world *w, eddy_system *s, const char **reason)
{
	(void)s;
	*reason = "CFL";
	return eddy__flip_advect_time(w);
}

const eddy_system_vtable eddy__kind_flip_advect = {
	.name = "flip_advect",
	.step = step,
	.limit = limit,
	.default_writes = advect_writes,
};

eddy_system_id eddy_add_flip_advect(eddy_world *w, const eddy_flip_advect_def *def)
{
	const char *sys = "flip_advect";
	if (!eddy__add_args(w, def, sys))
		return EDDY_NULL_SYSTEM;
	if (!eddy__check_range(w, sys, "wall_gap", def->wall_gap, 0, 0.5))
		return EDDY_NULL_SYSTEM;
	advect *ad = malloc(sizeof *ad);
	if (ad)
		ad->def = *def;
	return eddy__add_system(w, &eddy__kind_flip_advect, ad, advect_reads, advect_writes);
}
