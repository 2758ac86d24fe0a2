/* SPDX-License-Identifier: MIT */
/* integrate: symplectic (semi-implicit) Euler.
 *
 * Reads: ax ay az x y z vx vy vz. Writes: x y z vx vy vz.
 *   v(n+1) = v(n) + a dt,   x(n+1) = x(n) + v(n+1) dt
 * From rest under constant g this gives y_n = y_0 - g dt^2 n(n+1)/2 exactly.
 * Speeds above max_speed are scaled down to it (a safety valve, off at the
 * default of infinity).
 * Time-step limit (advection): dt <= L / max|v|, L the smallest emitter
 * spacing; the world multiplies it by the CFL number. */
#include "systems.h"

#include <stdio.h>
#include <stdlib.h>

typedef struct integrate {
	eddy_integrate_def def;
} integrate;

static const int integrate_reads[] = {COL_AX, COL_AY, COL_AZ, COL_X_, COL_Y_, COL_Z_, COL_VX, COL_VY, COL_VZ, -1};
static const int integrate_writes[] = {COL_X_, COL_Y_, COL_Z_, COL_VX, COL_VY, COL_VZ, -1};

eddy_integrate_def eddy_default_integrate_def(void)
{
	eddy_integrate_def d;
	d.max_speed = INFINITY;
	return d;
}

static eddy_status step(eddy_world *w, eddy_system *s, const eddy_step_context *ctx)
{
	const integrate *it = s->data;
	const float dt = (float)ctx->dt, vmax = it->def.max_speed;
	const float *ax = eddy__col(w, COL_AX), *ay = eddy__col(w, COL_AY), *az = eddy__col(w, COL_AZ);
	float *x = eddy__col(w, COL_X_), *y = eddy__col(w, COL_Y_), *z = eddy__col(w, COL_Z_);
	float *vx = eddy__col(w, COL_VX), *vy = eddy__col(w, COL_VY), *vz = eddy__col(w, COL_VZ);
	const long n = (long)w->n;
	const bool clamp = isfinite(vmax);
	long first = n; /* the first particle clamped */
#pragma omp parallel for num_threads(ctx->threads) if (n > 32768) schedule(static) reduction(min : first)
	for (long i = 0; i < n; ++i) {
		float ux = vx[i] + ax[i] * dt, uy = vy[i] + ay[i] * dt, uz = vz[i] + az[i] * dt;
		if (clamp) {
			const float sp = sqrtf(ux * ux + uy * uy + uz * uz);
			if (sp > vmax) {
				first = i < first ? i : first;
				const float k = vmax / sp;
				ux *= k;
				uy *= k;
				uz *= k;
			}
		}
		vx[i] = ux;
		vy[i] = uy;
		vz[i] = uz;
		x[i] += ux * dt;
		y[i] += uy * dt;
		z[i] += uz * dt;
	}
	if (first < n) {
		char key[sizeof s->label + 8];
		snprintf(key, sizeof key, "%s:clamp", s->label);
		eddy__warn(w, key,
		           "%s: particle %ld reached more than max_speed = %g m/s at step %lld (t = %.6g s) and was slowed to "
		           "it; later clamps are silent: the run is no longer the scene's physics where it clamps",
		           s->label, first, (double)vmax, (long long)ctx->step, ctx->time);
	}
	return EDDY_OK;
}

static double limit(eddy_world *w, eddy_system *s, const char **reason)
{
	(void)s;
	*reason = "advection";
	if (w->length_scale <= 0)
		return INFINITY;
	const float v2 = eddy__max_norm2(w, COL_VX, COL_VY, COL_VZ);
	return v2 > 0 ? w->length_scale / sqrt((double)v2) : INFINITY;
}

const eddy_system_vtable eddy__kind_integrate = {
	.name = "integrate",
	.step = step,
	.limit = limit,
	.default_writes = integrate_writes,
};

eddy_system_id eddy_add_integrate(eddy_world *w, const eddy_integrate_def *def)
{
	const char *sys = "integrate";
	if (!eddy__add_args(w, def, sys))
		return EDDY_NULL_SYSTEM;
	if (!(def->max_speed > 0)) {
		eddy__fail(w, EDDY_ERR_INVALID, "%s: 'max_speed' must be > 0 m/s (got %g)", sys, (double)def->max_speed);
		return EDDY_NULL_SYSTEM;
	}
	integrate *it = malloc(sizeof *it);
	if (it)
		it->def = *def;
	return eddy__add_system(w, &eddy__kind_integrate, it, integrate_reads, integrate_writes);
}
