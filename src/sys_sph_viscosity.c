/* sph_viscosity: viscous force from the Laplacian of the viscosity kernel
 * (Mueller 2003, eq. 14, with the symmetric velocity difference).
 *
 * Reads: x y z vx vy vz density. Writes: ax ay az (accumulated).
 *   a_i += (mu / rho_i) sum_j m (v_j - v_i) / rho_j lap W_visc(r_ij)
 *   lap W_visc(r) = 45/(pi h^6) (h - r)  (positive everywhere, so the term
 *   only ever damps relative motion)
 *   a_i -= sum_j m Pi_ij grad W_spiky(r_ij), for approaching pairs only
 *   (v_ij . x_ij < 0): Pi_ij = -alpha c h (v_ij . x_ij) / ((r^2 + 0.01 h^2) rho_ij),
 *   rho_ij the mean density (Monaghan 1992): it damps the acoustic noise of
 *   weakly compressible SPH near walls and the free surface, which a
 *   physical viscosity small enough not to slow the flow cannot.
 * Boundary particles add no viscous force: walls are free-slip, as the
 * dam-break validation wants.
 * Time-step limit (viscous): dt <= 0.3125 h^2 / nu, nu = mu / rho0; with the
 * default CFL 0.4 that is the usual 0.125 h^2/nu.
 * Source: Mueller, Charypar & Gross 2003; Monaghan, "Smoothed particle
 * hydrodynamics", ARAA 1992. */
#include "sph.h"
#include "systems.h"

#include <stdlib.h>

typedef struct sph_viscosity {
	eddy_sph_viscosity_def def;
} sph_viscosity;

static const int viscosity_reads[] = {COL_X_, COL_Y_, COL_Z_, COL_VX, COL_VY, COL_VZ, COL_DENSITY};
static const int viscosity_writes[] = {COL_AX, COL_AY, COL_AZ, -1};
static const int no_hint_writes[] = {-1};

eddy_sph_viscosity_def eddy_default_sph_viscosity_def(void)
{
	eddy_sph_viscosity_def d;
	d.viscosity = 1e-3f; /* water at 20 C */
	d.artificial = 0.05f;
	return d;
}

static eddy_status step(eddy_world *w, eddy_system *s, const eddy_step_context *ctx)
{
	const sph_viscosity *sv = s->data;
	sph_shared *sh = eddy__sph_find(w, s);
	if (!sh)
		return eddy__fail(w, EDDY_ERR_ORDER, "%s: needs sph_density before it (it builds the neighbour lists)", s->label);
	const sph_neighbors *nb = &sh->nb;
	const float *x = eddy__col(w, COL_X_), *y = eddy__col(w, COL_Y_), *z = eddy__col(w, COL_Z_);
	const float *vx = eddy__col(w, COL_VX), *vy = eddy__col(w, COL_VY), *vz = eddy__col(w, COL_VZ);
	const float *rho = eddy__col(w, COL_DENSITY), *inv_rho = sh->inv_rho;
	float *ax = eddy__col(w, COL_AX), *ay = eddy__col(w, COL_AY), *az = eddy__col(w, COL_AZ);
	const sph_kernel_consts kc = sh->k;
	const float coef = sv->def.viscosity * sh->mass * kc.visc_lap;
	/* -m Pi grad W = m alpha c h vr / ((r^2 + eps) rho_ij) spiky_grad (h-r)^2 r_hat */
	/* 2 x: the mean density (rho_i + rho_j) / 2 is folded into the pair term */
	const float acoef = 2.0f * sh->mass * sv->def.artificial * sh->c * kc.h * -kc.spiky_grad, eps = 0.01f * kc.h2,
	            rmin = 1e-3f * kc.h;
	const long n = nb->n < w->n ? (long)nb->n : (long)w->n;
#pragma omp parallel for num_threads(ctx->threads) schedule(static)
	for (long i = 0; i < n; ++i) {
		const float xi = x[i], yi = y[i], zi = z[i], ui = vx[i], vi = vy[i], wi = vz[i];
		const uint32_t *list = nb->nbr + (size_t)i * nb->cap;
		const uint32_t cnt = nb->count[i];
		float fx = 0, fy = 0, fz = 0, gx = 0, gy = 0, gz = 0;
		for (uint32_t q = 0; q < cnt; ++q) {
			const uint32_t j = list[q];
			const float rx = xi - x[j], ry = yi - y[j], rz = zi - z[j];
			const float r2 = rx * rx + ry * ry + rz * rz, r = sqrtf(r2);
			const float ux = ui - vx[j], uy = vi - vy[j], uz = wi - vz[j];
			const float c = (kc.h - r) * inv_rho[j];
			fx -= c * ux;
			fy -= c * uy;
			fz -= c * uz;
			/* approaching pairs only (vr < 0), pushed apart along r_hat;
			 * branch-free, since the sign of vr is a coin toss per pair */
			const float vr = ux * rx + uy * ry + uz * rz, hr = kc.h - r;
			/* ternaries, not fmaxf: without -ffinite-math-only fmaxf is a libm call */
			const float app = vr < 0 ? -vr : 0.0f, rs = r > rmin ? r : rmin;
			const float a = app * hr * hr / ((r2 + eps) * (rho[i] + rho[j]) * rs);
			gx += a * rx;
			gy += a * ry;
			gz += a * rz;
		}
		const float k = coef * inv_rho[i];
		ax[i] += k * fx + acoef * gx;
		ay[i] += k * fy + acoef * gy;
		az[i] += k * fz + acoef * gz;
	}
	return EDDY_OK;
}

static double limit(eddy_world *w, eddy_system *s, const char **reason)
{
	const sph_viscosity *sv = s->data;
	const sph_shared *sh = eddy__sph_find(w, s);
	*reason = "viscous";
	if (!sh || !(sv->def.viscosity > 0))
		return INFINITY;
	const double nu = sv->def.viscosity / sh->rho0;
	return 0.3125 * (double)sh->h * sh->h / nu;
}

const eddy_system_vtable eddy__kind_sph_viscosity = {
	.name = "sph_viscosity",
	.step = step,
	.limit = limit,
	/* ax ay az are every force's: order hints for them name gravity alone */
	.default_writes = no_hint_writes,
};

eddy_system_id eddy_add_sph_viscosity(eddy_world *w, const eddy_sph_viscosity_def *def)
{
	const char *sys = "sph_viscosity";
	if (!def)
		return eddy__fail(w, EDDY_ERR_INVALID, "%s: def is NULL", sys), EDDY_NULL_SYSTEM;
	if (!eddy__check_nonneg(w, sys, "viscosity", def->viscosity) || !eddy__check_finite(w, sys, "viscosity", def->viscosity) ||
	    !eddy__check_range(w, sys, "artificial", def->artificial, 0, 2))
		return EDDY_NULL_SYSTEM;
	sph_viscosity *sv = malloc(sizeof *sv);
	if (sv)
		sv->def = *def;
	return eddy__add_system(w, &eddy__kind_sph_viscosity, sv, viscosity_reads, 7, viscosity_writes, 3);
}
