/* sph_surface_tension: colour-field surface tension (Mueller 2003, sec. 3.3,
 * the continuum surface force of Morris 2000).
 *
 * Reads: x y z density. Writes: color_nx color_ny color_nz curvature ax ay az.
 *   c_i      = sum_j m / rho_j W_poly6(r_ij)            (colour field, 1 inside)
 *   n_i      = sum_j m / rho_j grad W_poly6(r_ij)       (points into the fluid)
 *   lap c_i  = sum_j m / rho_j lap W_poly6(r_ij)        (j includes i itself)
 *   kappa_i  = -lap c_i / |n_i|
 *   a_i     += sigma kappa_i n_i / rho_i   only where |n_i| > threshold / h:
 *   inside the fluid n is noise and dividing by |n| would amplify it (C.15).
 * The columns exist only while this system is in the pipeline.
 * Time-step limit (capillary): dt <= 2.5 sqrt(rho0 dx^3 / (2 pi sigma)) with
 * dx = h/2; with the default CFL 0.4 that is the usual sqrt(rho dx^3/(2 pi sigma)).
 * Source: Mueller, Charypar & Gross 2003; Brackbill, Kothe & Zemach 1992. */
#include "sph.h"
#include "systems.h"

#include <stdlib.h>

typedef struct sph_surface_tension {
	eddy_sph_surface_tension_def def;
} sph_surface_tension;

static const int st_reads[] = {COL_X_, COL_Y_, COL_Z_, COL_DENSITY};
static const int st_writes[] = {COL_SPH_NX, COL_SPH_NY, COL_SPH_NZ, COL_SPH_CURVATURE, COL_AX, COL_AY, COL_AZ, -1};
static const int st_hint_writes[] = {COL_SPH_NX, COL_SPH_NY, COL_SPH_NZ, COL_SPH_CURVATURE, -1};

eddy_sph_surface_tension_def eddy_default_sph_surface_tension_def(void)
{
	eddy_sph_surface_tension_def d;
	d.tension = 0.0728f; /* water-air at 20 C */
	d.threshold = 0.5f;
	return d;
}

static eddy_status step(eddy_world *w, eddy_system *s, const eddy_step_context *ctx)
{
	const sph_surface_tension *st = s->data;
	sph_shared *sh = eddy__sph_find(w, s);
	if (!sh)
		return eddy__fail(w, EDDY_ERR_ORDER, "%s: needs sph_density before it (it builds the neighbour lists)", s->label);
	const sph_neighbors *nb = &sh->nb;
	const float *x = eddy__col(w, COL_X_), *y = eddy__col(w, COL_Y_), *z = eddy__col(w, COL_Z_);
	const float *rho = eddy__col(w, COL_DENSITY);
	float *nx = eddy__col(w, COL_SPH_NX), *ny = eddy__col(w, COL_SPH_NY), *nz = eddy__col(w, COL_SPH_NZ);
	float *curv = eddy__col(w, COL_SPH_CURVATURE);
	float *ax = eddy__col(w, COL_AX), *ay = eddy__col(w, COL_AY), *az = eddy__col(w, COL_AZ);
	const sph_kernel_consts kc = sh->k;
	const float m = sh->mass, sigma = st->def.tension, thr = st->def.threshold / sh->h;
	const long n = nb->n < w->n ? (long)nb->n : (long)w->n;
#pragma omp parallel for num_threads(ctx->threads) schedule(static)
	for (long i = 0; i < n; ++i) {
		const float xi = x[i], yi = y[i], zi = z[i];
		const uint32_t *list = nb->nbr + (size_t)i * nb->cap;
		const uint32_t cnt = nb->count[i];
		/* self term of the Laplacian: -6 (h^2)(3 h^2) in units of poly6 */
		float gx = 0, gy = 0, gz = 0, lap = -18.0f * kc.h2 * kc.h2 / rho[i];
		for (uint32_t q = 0; q < cnt; ++q) {
			const uint32_t j = list[q];
			const float rx = xi - x[j], ry = yi - y[j], rz = zi - z[j];
			const float r2 = rx * rx + ry * ry + rz * rz, d = kc.h2 - r2, vj = 1.0f / rho[j];
			const float gcoef = -6.0f * d * d * vj;
			gx += gcoef * rx;
			gy += gcoef * ry;
			gz += gcoef * rz;
			lap += -6.0f * d * (3.0f * kc.h2 - 7.0f * r2) * vj;
		}
		gx *= m * kc.poly6;
		gy *= m * kc.poly6;
		gz *= m * kc.poly6;
		lap *= m * kc.poly6;
		nx[i] = gx;
		ny[i] = gy;
		nz[i] = gz;
		const float len = sqrtf(gx * gx + gy * gy + gz * gz);
		if (len > thr) {
			const float kappa = -lap / len;
			curv[i] = kappa;
			const float c = sigma * kappa / rho[i];
			ax[i] += c * gx;
			ay[i] += c * gy;
			az[i] += c * gz;
		}
	}
	return EDDY_OK;
}

static double limit(eddy_world *w, eddy_system *s, const char **reason)
{
	const sph_surface_tension *st = s->data;
	const sph_shared *sh = eddy__sph_find(w, s);
	*reason = "capillary";
	if (!sh || !(st->def.tension > 0))
		return INFINITY;
	const double dx = 0.5 * sh->h;
	return 2.5 * sqrt(sh->rho0 * dx * dx * dx / (2 * M_PI * st->def.tension));
}

const eddy_system_vtable eddy__kind_sph_surface_tension = {
	.name = "sph_surface_tension",
	.step = step,
	.limit = limit,
	/* ax ay az are every force's: order hints for them name gravity alone */
	.default_writes = st_hint_writes,
};

eddy_system_id eddy_add_sph_surface_tension(eddy_world *w, const eddy_sph_surface_tension_def *def)
{
	const char *sys = "sph_surface_tension";
	if (!def)
		return eddy__fail(w, EDDY_ERR_INVALID, "%s: def is NULL", sys), EDDY_NULL_SYSTEM;
	if (!eddy__check_nonneg(w, sys, "tension", def->tension) || !eddy__check_finite(w, sys, "tension", def->tension) ||
	    !eddy__check_nonneg(w, sys, "threshold", def->threshold) ||
	    !eddy__check_finite(w, sys, "threshold", def->threshold))
		return EDDY_NULL_SYSTEM;
	sph_surface_tension *st = malloc(sizeof *st);
	if (st)
		st->def = *def;
	return eddy__add_system(w, &eddy__kind_sph_surface_tension, st, st_reads, 4, st_writes, 7);
}
