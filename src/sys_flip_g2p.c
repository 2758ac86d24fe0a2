/* SPDX-License-Identifier: MIT */
/* flip_g2p: grid to particles, FLIP blended with PIC (Brackbill 1988; Zhu &
 * Bridson 2005, section 4: FLIP adds the grid's change, PIC takes the grid
 * value; PIC is stable but smooths the flow like a strong viscosity, FLIP
 * keeps detail but is noisy, docs/validation.md hard case 11).
 *
 * Reads: x y z vx vy vz u v w u_old v_old w_old. Writes: vx vy vz
 * (and apic_ux .. apic_wz with transfer "apic").
 *   flip: v_flip = v_p + I(u - u_old),  v_pic = I(u),  I trilinear on each
 *         face grid; v_p = r v_flip + (1 - r) v_pic,  r = flip_ratio
 *   pic:  v_p = I(u)  (the same as flip with r = 0, bit for bit)
 *   apic: v_p = I(u),  c_p,a = sum_f grad W_fp u_a,f  for each face grid a
 *         (Jiang, Schroeder, Selle, Teran & Stomakhin 2015, "The affine
 *         particle-in-cell method", SIGGRAPH, eq. 8 and section 5.3: for
 *         multilinear weights B_p D_p^-1 equals the weights' gradient sum).
 *         flip_p2g splats v_a + c_a . (x_f - x_p) with the same weights.
 *         APIC keeps the affine (rotation and shear) part of the motion that
 *         PIC's averaging loses, without FLIP's noise. Where an axis lies
 *         outside its sample range the weights are constant (flip.h), so
 *         their gradient along that axis is 0 there.
 * Every particle is independent (a parallel loop writing only its own
 * rows): the results do not depend on the thread count. */
#include "flip.h"

#include <stdlib.h>

typedef struct g2p {
	eddy_flip_g2p_def def;
} g2p;

static const int g2p_reads[] = {COL_X_,     COL_Y_,     COL_Z_,    COL_VX,    COL_VY,    COL_VZ, COL_FACE_U,
                                COL_FACE_V, COL_FACE_W, COL_U_OLD, COL_V_OLD, COL_W_OLD, -1};
static const int g2p_writes[] = {COL_VX, COL_VY, COL_VZ, -1};
static const int apic_writes[] = {COL_VX,      COL_VY,      COL_VZ,      COL_APIC_UX, COL_APIC_UY,
                                  COL_APIC_UZ, COL_APIC_VX, COL_APIC_VY, COL_APIC_VZ, COL_APIC_WX,
                                  COL_APIC_WY, COL_APIC_WZ, -1};

eddy_flip_g2p_def eddy_default_flip_g2p_def(void)
{
	eddy_flip_g2p_def d;
	d.flip_ratio = 0.95f;
	d.transfer = EDDY_FLIP_TRANSFER_FLIP;
	return d;
}

/* The trilinear sample of face grid f (strides sy, sz) and its gradient
 * (1/s) at a point; dx, dy, dz are each axis's d w1 / d x (1/m), 0 where the
 * axis is clamped. */
static inline float sample_grad(const float *f, size_t sy, size_t sz, flip_axis ax, flip_axis ay, flip_axis az,
                                float dx, float dy, float dz, float g[3])
{
	const size_t i[2] = {(size_t)ax.i0, (size_t)ax.i1}, j[2] = {(size_t)ay.i0 * sy, (size_t)ay.i1 * sy},
				 k[2] = {(size_t)az.i0 * sz, (size_t)az.i1 * sz};
	const float wx[2] = {1.0f - ax.w1, ax.w1}, wy[2] = {1.0f - ay.w1, ay.w1}, wz[2] = {1.0f - az.w1, az.w1};
	const float gx[2] = {-dx, dx}, gy[2] = {-dy, dy}, gz[2] = {-dz, dz};
	float v = 0, sx = 0, sy2 = 0, sz2 = 0;
	for (int c = 0; c < 2; ++c)
		for (int b = 0; b < 2; ++b)
			for (int a = 0; a < 2; ++a) {
				const float u = f[k[c] + j[b] + i[a]];
				v += wx[a] * wy[b] * wz[c] * u;
				sx += gx[a] * wy[b] * wz[c] * u;
				sy2 += wx[a] * gy[b] * wz[c] * u;
				sz2 += wx[a] * wy[b] * gz[c] * u;
			}
	g[0] = sx, g[1] = sy2, g[2] = sz2;
	return v;
}

/* d w1 / d x of an axis sampled at (s + off) for s in [0, n): inv inside the
 * sample range, 0 where flip_axis_at clamps (constant extension) */
static inline float axis_slope(float t, float off, int n, float inv)
{
	const float s = t - off;
	return s >= 0.0f && s < (float)(n - 1) ? inv : 0.0f;
}

/* The same for a face grid's axis (n + 1 faces), through flip_face_coord's
 * stretch of the last cell where the box cuts it (its slope 1 / (top - last)). */
static inline float face_slope(float t, float top, int n, float inv)
{
	const float last = (float)(n - 1);
	if (top < (float)n && t > last)
		return t < top ? inv / (top - last) : 0.0f;
	return axis_slope(t, 0.0f, n + 1, inv);
}

/* The same for a centre axis, through flip_centre_coord (0 where it holds
 * the coordinate at the last centre inside the box). */
static inline float centre_slope(float t, float top, int n, float inv)
{
	return flip_centre_coord(t, top, n) != t ? 0.0f : axis_slope(t, 0.5f, n, inv);
}

static void apic_step(eddy_world *w, int threads)
{
	const float *x = eddy__col(w, COL_X_), *y = eddy__col(w, COL_Y_), *z = eddy__col(w, COL_Z_);
	float *vel[3] = {eddy__col(w, COL_VX), eddy__col(w, COL_VY), eddy__col(w, COL_VZ)};
	const float *now[3] = {eddy__col(w, COL_FACE_U), eddy__col(w, COL_FACE_V), eddy__col(w, COL_FACE_W)};
	float *c[9];
	for (int q = 0; q < 9; ++q)
		c[q] = eddy__col(w, COL_APIC_UX + q);
	const long n = (long)w->n;
	const flip_grid grid = flip_grid_of(w);
	const size_t nx = (size_t)grid.nx, ny = (size_t)grid.ny;
#pragma omp parallel for num_threads(threads) if (n > 16384) schedule(static)
	for (long i = 0; i < n; ++i) {
		const flip_axes a = flip_vel_axes_at(&grid, (eddy_vec3){x[i], y[i], z[i]});
		const float tx = (x[i] - grid.o.x) * grid.inv, ty = (y[i] - grid.o.y) * grid.inv,
					tz = (z[i] - grid.o.z) * grid.inv;
		const float sfx = face_slope(tx, grid.top[0], grid.nx, grid.inv), scx = centre_slope(tx, grid.top[0], grid.nx, grid.inv);
		const float sfy = face_slope(ty, grid.top[1], grid.ny, grid.inv), scy = centre_slope(ty, grid.top[1], grid.ny, grid.inv);
		const float sfz = face_slope(tz, grid.top[2], grid.nz, grid.inv), scz = centre_slope(tz, grid.top[2], grid.nz, grid.inv);
		float g[3];
		vel[0][i] = sample_grad(now[0], nx + 1, (nx + 1) * ny, a.fx, a.cy, a.cz, sfx, scy, scz, g);
		c[0][i] = g[0], c[1][i] = g[1], c[2][i] = g[2];
		vel[1][i] = sample_grad(now[1], nx, nx * (ny + 1), a.cx, a.fy, a.cz, scx, sfy, scz, g);
		c[3][i] = g[0], c[4][i] = g[1], c[5][i] = g[2];
		vel[2][i] = sample_grad(now[2], nx, nx * ny, a.cx, a.cy, a.fz, scx, scy, sfz, g);
		c[6][i] = g[0], c[7][i] = g[1], c[8][i] = g[2];
	}
}

static eddy_status step(eddy_world *w, eddy_system *s, const eddy_step_context *ctx)
{
	const eddy_flip_g2p_def *def = &((const g2p *)s->data)->def;
	if (def->transfer == EDDY_FLIP_TRANSFER_APIC) {
		apic_step(w, ctx->threads);
		return EDDY_OK;
	}
	/* pic is flip at r = 0: r (..) + 1 * pic adds 0 * (..), bit for bit the
	 * same as flip_ratio = 0 (unless the delta is not finite, which the
	 * world's finite check reports either way) */
	const float r = def->transfer == EDDY_FLIP_TRANSFER_PIC ? 0.0f : def->flip_ratio;
	const float *x = eddy__col(w, COL_X_), *y = eddy__col(w, COL_Y_), *z = eddy__col(w, COL_Z_);
	float *vel[3] = {eddy__col(w, COL_VX), eddy__col(w, COL_VY), eddy__col(w, COL_VZ)};
	const float *now[3] = {eddy__col(w, COL_FACE_U), eddy__col(w, COL_FACE_V), eddy__col(w, COL_FACE_W)};
	const float *old[3] = {eddy__col(w, COL_U_OLD), eddy__col(w, COL_V_OLD), eddy__col(w, COL_W_OLD)};
	const long n = (long)w->n;
	const flip_grid grid = flip_grid_of(w);
#pragma omp parallel for num_threads(ctx->threads) if (n > 16384) schedule(static)
	for (long i = 0; i < n; ++i) {
		/* interpolation is linear: I(u - u_old) = I(u) - I(u_old) */
		const flip_axes ax = flip_vel_axes_at(&grid, (eddy_vec3){x[i], y[i], z[i]});
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
	if (def->transfer != EDDY_FLIP_TRANSFER_FLIP && def->transfer != EDDY_FLIP_TRANSFER_PIC &&
	    def->transfer != EDDY_FLIP_TRANSFER_APIC) {
		eddy__fail(w, EDDY_ERR_INVALID, "%s: 'transfer' must be flip, pic or apic", sys);
		return EDDY_NULL_SYSTEM;
	}
	g2p *g = malloc(sizeof *g);
	if (g)
		g->def = *def;
	/* only apic declares (and so allocates) the affine columns */
	const bool apic = def->transfer == EDDY_FLIP_TRANSFER_APIC;
	return eddy__add_system(w, &eddy__kind_flip_g2p, g, g2p_reads, apic ? apic_writes : g2p_writes);
}
