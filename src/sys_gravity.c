/* SPDX-License-Identifier: MIT */
/* gravity: the world's gravity as a body acceleration.
 *
 * Reads: nothing. Writes: ax ay az (accumulated; the world clears them each step).
 * a += scale * g. */
#include "systems.h"

#include <stdlib.h>

typedef struct gravity {
	eddy_gravity_def def;
} gravity;

static const int gravity_writes[] = {COL_AX, COL_AY, COL_AZ, -1};

eddy_gravity_def eddy_default_gravity_def(void)
{
	eddy_gravity_def d;
	d.scale = 1.0f;
	return d;
}

static eddy_status step(eddy_world *w, eddy_system *s, const eddy_step_context *ctx)
{
	const gravity *g = s->data;
	const float gx = w->def.gravity.x * g->def.scale, gy = w->def.gravity.y * g->def.scale,
				gz = w->def.gravity.z * g->def.scale;
	float *ax = eddy__col(w, COL_AX), *ay = eddy__col(w, COL_AY), *az = eddy__col(w, COL_AZ);
	const long n = (long)w->n;
	const int nt = n > EDDY_PAR_ROWS ? ctx->threads : 1;
#pragma omp parallel for num_threads(nt) if (nt > 1) schedule(static)
	for (long i = 0; i < n; ++i) {
		ax[i] += gx;
		ay[i] += gy;
		az[i] += gz;
	}
	return EDDY_OK;
}

void eddy__gravity_sum(const eddy_world *w, double g[3])
{
	g[0] = g[1] = g[2] = 0;
	if (w->settling) /* the settling steps relax the arrangement alone (world.c) */
		return;
	const eddy_system *o;
	for (eddy_system_iter it = eddy__systems(w, EDDY_CAP_GRAVITY); (o = eddy__systems_next(&it));) {
		const double sc = ((const gravity *)o->data)->def.scale;
		g[0] += sc * w->def.gravity.x, g[1] += sc * w->def.gravity.y, g[2] += sc * w->def.gravity.z;
	}
}

eddy_vec3 eddy__gravity(const eddy_world *w)
{
	double g[3];
	eddy__gravity_sum(w, g);
	return eddy__v3((float)g[0], (float)g[1], (float)g[2]);
}

static void *shared(const eddy_system *s, uint32_t cap)
{
	return cap == EDDY_CAP_GRAVITY ? &((gravity *)s->data)->def : NULL;
}

const eddy_system_vtable eddy__kind_gravity = {
	.name = "gravity",
	.keeps_solids = true,
	.provides = EDDY_CAP_GRAVITY,
	.shared = shared,
	.step = step,
	.default_writes = gravity_writes,
};

eddy_system_id eddy_add_gravity(eddy_world *w, const eddy_gravity_def *def)
{
	const char *sys = "gravity";
	if (!eddy__add_args(w, def, sys))
		return EDDY_NULL_SYSTEM;
	if (!eddy__check_finite(w, sys, "scale", def->scale))
		return EDDY_NULL_SYSTEM;
	gravity *g = malloc(sizeof *g);
	if (g)
		g->def = *def;
	return eddy__add_system(w, &eddy__kind_gravity, g, NULL, gravity_writes);
}
