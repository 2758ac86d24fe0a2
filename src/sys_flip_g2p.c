/* SPDX-License-Identifier: MIT */
/* flip_g2p: grid to particles, FLIP blended with PIC (Brackbill 1988; Zhu &
 * Bridson 2005, section 4: FLIP adds the grid's change, PIC takes the grid
 * value; PIC is stable but smooths the flow like a strong viscosity, FLIP
 * keeps detail but is noisy, docs/validation.md hard case 11).
 *
 * Reads: x y z vx vy vz u v w u_old v_old w_old. Writes: vx vy vz.
 *   v_flip = v_p + I(u - u_old),  v_pic = I(u),  I trilinear on each face grid
 *   v_p = r v_flip + (1 - r) v_pic,  r = flip_ratio. */
#include "flip.h"

#include <stdlib.h>

typedef struct g2p {
	eddy_flip_g2p_def def;
} g2p;

static const int g2p_reads[] = {COL_X_,     COL_Y_,     COL_Z_,     COL_VX,    COL_VY,    COL_VZ,
                                COL_FACE_U, COL_FACE_V, COL_FACE_W, COL_U_OLD, COL_V_OLD, COL_W_OLD};
static const int g2p_writes[] = {COL_VX, COL_VY, COL_VZ, -1};

eddy_flip_g2p_def eddy_default_flip_g2p_def(void)
{
	eddy_flip_g2p_def d;
	d.flip_ratio = 0.95f;
	return d;
}

static eddy_status step(eddy_world *w, eddy_system *s, const eddy_step_context *ctx)
{
	const float r = ((const g2p *)s->data)->def.flip_ratio;
	const float *x = eddy__col(w, COL_X_), *y = eddy__col(w, COL_Y_), *z = eddy__col(w, COL_Z_);
	float *vel[3] = {eddy__col(w, COL_VX), eddy__col(w, COL_VY), eddy__col(w, COL_VZ)};
	const float *now[3] = {eddy__col(w, COL_FACE_U), eddy__col(w, COL_FACE_V), eddy__col(w, COL_FACE_W)};
	const float *old[3] = {eddy__col(w, COL_U_OLD), eddy__col(w, COL_V_OLD), eddy__col(w, COL_W_OLD)};
	const long n = (long)w->n;
	const flip_grid grid = flip_grid_of(w);
#pragma omp parallel for num_threads(ctx->threads) if (n > 16384) schedule(static)
	for (long i = 0; i < n; ++i) {
		/* interpolation is linear: I(u - u_old) = I(u) - I(u_old) */
		const flip_axes ax = flip_axes_at(&grid, (eddy_vec3){x[i], y[i], z[i]});
		const eddy_vec3 pic = flip_velocity_axes(&grid, now[0], now[1], now[2], &ax);
		const eddy_vec3 before = flip_velocity_axes(&grid, old[0], old[1], old[2], &ax);
		vel[0][i] = r * (vel[0][i] + pic.x - before.x) + (1.0f - r) * pic.x;
		vel[1][i] = r * (vel[1][i] + pic.y - before.y) + (1.0f - r) * pic.y;
		vel[2][i] = r * (vel[2][i] + pic.z - before.z) + (1.0f - r) * pic.z;
	}
	return EDDY_OK;
}

const eddy_system_vtable eddy__kind_flip_g2p = {
	.name = "flip_g2p",
	.step = step,
	.default_writes = g2p_writes,
};

eddy_system_id eddy_add_flip_g2p(eddy_world *w, const eddy_flip_g2p_def *def)
{
	const char *sys = "flip_g2p";
	if (!eddy__add_args(w, def, sys))
		return EDDY_NULL_SYSTEM;
	if (!eddy__check_range(w, sys, "flip_ratio", def->flip_ratio, 0, 1))
		return EDDY_NULL_SYSTEM;
	g2p *g = malloc(sizeof *g);
	if (g)
		g->def = *def;
	return eddy__add_system(w, &eddy__kind_flip_g2p, g, g2p_reads, 12, g2p_writes, 3);
}
