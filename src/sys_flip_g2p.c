/* flip_g2p: grid to particles, FLIP blended with PIC (Brackbill 1988; Zhu &
 * Bridson 2005, section 4: FLIP adds the grid's change, PIC takes the grid
 * value; PIC is stable but smooths the flow like a strong viscosity, FLIP
 * keeps detail but is noisy, VALIDATION.md hard case 11).
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
	const float inv = (float)(1.0 / w->def.cell_size);
	const eddy_vec3 o = w->def.bounds_min;
	const long n = (long)w->n;
#pragma omp parallel for num_threads(ctx->threads) if (n > 16384) schedule(static)
	for (long i = 0; i < n; ++i) {
		const float gx = (x[i] - o.x) * inv, gy = (y[i] - o.y) * inv, gz = (z[i] - o.z) * inv;
		flip_stencil st;
		for (int a = 0; a < 3; ++a) {
			flip_stencil_at(w, a, gx, gy, gz, &st);
			float pic = 0, delta = 0;
			for (int q = 0; q < 8; ++q) {
				const float un = now[a][st.idx[q]];
				pic += st.wt[q] * un;
				delta += st.wt[q] * (un - old[a][st.idx[q]]);
			}
			vel[a][i] = r * (vel[a][i] + delta) + (1.0f - r) * pic;
		}
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
	if (!def)
		return eddy__fail(w, EDDY_ERR_INVALID, "%s: def is NULL", sys), EDDY_NULL_SYSTEM;
	if (!eddy__check_range(w, sys, "flip_ratio", def->flip_ratio, 0, 1))
		return EDDY_NULL_SYSTEM;
	g2p *g = malloc(sizeof *g);
	if (g)
		g->def = *def;
	return eddy__add_system(w, &eddy__kind_flip_g2p, g, g2p_reads, 12, g2p_writes, 3);
}
