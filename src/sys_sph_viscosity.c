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
#ifdef __SSE2__
#include <emmintrin.h>
#endif

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
	/* each neighbour's eight inputs as two 16-byte quads, (x y z 1/rho) and
	 * (vx vy vz rho): a pair then costs two loads and a transpose instead of
	 * eight scattered loads, which were most of the pass */
	float *pk = eddy__arena_alloc(&w->arena, (size_t)(n ? n : 1) * 8 * sizeof *pk);
	if (!pk)
		return eddy__fail(w, EDDY_ERR_NOMEM, "%s: out of scratch memory for %ld particles", s->label, n);
#pragma omp parallel for num_threads(ctx->threads) schedule(static)
	for (long i = 0; i < n; ++i) {
		float *o = pk + 8 * i;
		o[0] = x[i];
		o[1] = y[i];
		o[2] = z[i];
		o[3] = inv_rho[i];
		o[4] = vx[i];
		o[5] = vy[i];
		o[6] = vz[i];
		o[7] = rho[i];
	}
#pragma omp parallel for num_threads(ctx->threads) schedule(static)
	for (long i = 0; i < n; ++i) {
		const float *pi = pk + 8 * i;
		const float xi = pi[0], yi = pi[1], zi = pi[2], ui = pi[4], vi = pi[5], wi = pi[6], rhoi = pi[7];
		const uint32_t *list = nb->nbr + (size_t)i * nb->cap;
		const uint32_t cnt = nb->count[i];
		float fx = 0, fy = 0, fz = 0, gx = 0, gy = 0, gz = 0;
		uint32_t q = 0;
#ifdef __SSE2__
		/* four neighbours at a time, with four partial sums per component
		 * added up at the end: a fixed order, the same for any thread count */
		const __m128 vxi = _mm_set1_ps(xi), vyi = _mm_set1_ps(yi), vzi = _mm_set1_ps(zi), vui = _mm_set1_ps(ui),
		             vvi = _mm_set1_ps(vi), vwi = _mm_set1_ps(wi), vh = _mm_set1_ps(kc.h), veps = _mm_set1_ps(eps),
		             vrmin = _mm_set1_ps(rmin), vrhoi = _mm_set1_ps(rhoi), zero = _mm_setzero_ps();
		__m128 sfx = zero, sfy = zero, sfz = zero, sgx = zero, sgy = zero, sgz = zero;
		for (; q + 4 <= cnt; q += 4) {
			const float *p0 = pk + 8 * (size_t)list[q], *p1 = pk + 8 * (size_t)list[q + 1],
			            *p2 = pk + 8 * (size_t)list[q + 2], *p3 = pk + 8 * (size_t)list[q + 3];
			__m128 px = _mm_loadu_ps(p0), py = _mm_loadu_ps(p1), pz = _mm_loadu_ps(p2), pir = _mm_loadu_ps(p3);
			_MM_TRANSPOSE4_PS(px, py, pz, pir);
			__m128 pu = _mm_loadu_ps(p0 + 4), pv = _mm_loadu_ps(p1 + 4), pw = _mm_loadu_ps(p2 + 4), prho = _mm_loadu_ps(p3 + 4);
			_MM_TRANSPOSE4_PS(pu, pv, pw, prho);
			const __m128 rx = _mm_sub_ps(vxi, px), ry = _mm_sub_ps(vyi, py), rz = _mm_sub_ps(vzi, pz);
			const __m128 r2 = _mm_add_ps(_mm_add_ps(_mm_mul_ps(rx, rx), _mm_mul_ps(ry, ry)), _mm_mul_ps(rz, rz));
			const __m128 r = _mm_sqrt_ps(r2), hr = _mm_sub_ps(vh, r);
			const __m128 ux = _mm_sub_ps(vui, pu), uy = _mm_sub_ps(vvi, pv), uz = _mm_sub_ps(vwi, pw);
			const __m128 c = _mm_mul_ps(hr, pir);
			sfx = _mm_sub_ps(sfx, _mm_mul_ps(c, ux));
			sfy = _mm_sub_ps(sfy, _mm_mul_ps(c, uy));
			sfz = _mm_sub_ps(sfz, _mm_mul_ps(c, uz));
			const __m128 vr = _mm_add_ps(_mm_add_ps(_mm_mul_ps(ux, rx), _mm_mul_ps(uy, ry)), _mm_mul_ps(uz, rz));
			const __m128 app = _mm_and_ps(_mm_cmplt_ps(vr, zero), _mm_sub_ps(zero, vr)), rs = _mm_max_ps(r, vrmin);
			const __m128 a = _mm_div_ps(_mm_mul_ps(_mm_mul_ps(app, hr), hr),
			                            _mm_mul_ps(_mm_mul_ps(_mm_add_ps(r2, veps), _mm_add_ps(vrhoi, prho)), rs));
			sgx = _mm_add_ps(sgx, _mm_mul_ps(a, rx));
			sgy = _mm_add_ps(sgy, _mm_mul_ps(a, ry));
			sgz = _mm_add_ps(sgz, _mm_mul_ps(a, rz));
		}
		fx = sph_hsum4(sfx);
		fy = sph_hsum4(sfy);
		fz = sph_hsum4(sfz);
		gx = sph_hsum4(sgx);
		gy = sph_hsum4(sgy);
		gz = sph_hsum4(sgz);
#endif
		for (; q < cnt; ++q) {
			const float *pj = pk + 8 * (size_t)list[q];
			const float rx = xi - pj[0], ry = yi - pj[1], rz = zi - pj[2];
			const float r2 = rx * rx + ry * ry + rz * rz, r = sqrtf(r2);
			const float ux = ui - pj[4], uy = vi - pj[5], uz = wi - pj[6];
			const float c = (kc.h - r) * pj[3];
			fx -= c * ux;
			fy -= c * uy;
			fz -= c * uz;
			/* approaching pairs only (vr < 0), pushed apart along r_hat;
			 * branch-free, since the sign of vr is a coin toss per pair */
			const float vr = ux * rx + uy * ry + uz * rz, hr = kc.h - r;
			/* ternaries, not fmaxf: without -ffinite-math-only fmaxf is a libm call */
			const float app = vr < 0 ? -vr : 0.0f, rs = r > rmin ? r : rmin;
			const float a = app * hr * hr / ((r2 + eps) * (rhoi + pj[7]) * rs);
			gx += a * rx;
			gy += a * ry;
			gz += a * rz;
		}
		const float k = coef * pi[3];
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
