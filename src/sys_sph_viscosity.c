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
 * Positions and 1/rho come from sph_density's (x y z 1/rho) quads (sh->pq,
 * the positions its lists were made from). The pairs go eight at a time
 * (AVX2 when the CPU has it, else SSE as two halves doing the same per lane),
 * with per-lane partial sums added in a fixed order: the same bits for any
 * thread count and either path.
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

/* The fluid pairs of one particle, eight neighbours at a time (the last
 * group padded with copies of the last neighbour, masked out). f[0..2] get
 * -sum (h - r) / rho_j (v_i - v_j), f[3..5] the artificial viscosity's
 * sum of max(0, -v_ij . r_vec) (h - r)^2 / ((r^2 + eps) (rho_i + rho_j)
 * max(r, rmin)) r_vec. */
typedef struct pair_args {
	const float *pq, *pv; /* (x y z 1/rho) and (vx vy vz rho) per particle */
	float h, eps, rmin;
} pair_args;

static inline void group_rows(const uint32_t *list, uint32_t cnt, uint32_t q, uint32_t l[8])
{
	for (uint32_t k = 0; k < 8; ++k)
		l[k] = list[q + k < cnt ? q + k : cnt - 1];
}

#ifdef __SSE2__
static void pairs_sse(const pair_args *a, const uint32_t *list, uint32_t cnt, const float *pi, const float *vi,
                      float f[6])
{
	const __m128 vxi = _mm_set1_ps(pi[0]), vyi = _mm_set1_ps(pi[1]), vzi = _mm_set1_ps(pi[2]),
	             vui = _mm_set1_ps(vi[0]), vvi = _mm_set1_ps(vi[1]), vwi = _mm_set1_ps(vi[2]),
	             vrhoi = _mm_set1_ps(vi[3]), vh = _mm_set1_ps(a->h), veps = _mm_set1_ps(a->eps),
	             vrmin = _mm_set1_ps(a->rmin), zero = _mm_setzero_ps();
	__m128 s[6][2];
	for (int c = 0; c < 6; ++c)
		s[c][0] = s[c][1] = zero;
	for (uint32_t q = 0; q < cnt; q += 8) {
		uint32_t l[8];
		group_rows(list, cnt, q, l);
		const __m128i left = _mm_set1_epi32((int)(cnt - q));
		for (int k = 0; k < 2; ++k) {
			const size_t o0 = 4 * (size_t)l[4 * k], o1 = 4 * (size_t)l[4 * k + 1], o2 = 4 * (size_t)l[4 * k + 2],
			             o3 = 4 * (size_t)l[4 * k + 3];
			__m128 px = _mm_loadu_ps(a->pq + o0), py = _mm_loadu_ps(a->pq + o1), pz = _mm_loadu_ps(a->pq + o2),
			       pir = _mm_loadu_ps(a->pq + o3);
			_MM_TRANSPOSE4_PS(px, py, pz, pir);
			__m128 pu = _mm_loadu_ps(a->pv + o0), pv = _mm_loadu_ps(a->pv + o1), pw = _mm_loadu_ps(a->pv + o2),
			       prho = _mm_loadu_ps(a->pv + o3);
			_MM_TRANSPOSE4_PS(pu, pv, pw, prho);
			const __m128 in =
				_mm_castsi128_ps(_mm_cmpgt_epi32(left, _mm_setr_epi32(4 * k, 4 * k + 1, 4 * k + 2, 4 * k + 3)));
			const __m128 rx = _mm_sub_ps(vxi, px), ry = _mm_sub_ps(vyi, py), rz = _mm_sub_ps(vzi, pz);
			const __m128 r2 = _mm_add_ps(_mm_add_ps(_mm_mul_ps(rx, rx), _mm_mul_ps(ry, ry)), _mm_mul_ps(rz, rz));
			const __m128 r = _mm_sqrt_ps(r2), hr = _mm_sub_ps(vh, r);
			const __m128 ux = _mm_sub_ps(vui, pu), uy = _mm_sub_ps(vvi, pv), uz = _mm_sub_ps(vwi, pw);
			const __m128 c = _mm_and_ps(in, _mm_mul_ps(hr, pir));
			s[0][k] = _mm_sub_ps(s[0][k], _mm_mul_ps(c, ux));
			s[1][k] = _mm_sub_ps(s[1][k], _mm_mul_ps(c, uy));
			s[2][k] = _mm_sub_ps(s[2][k], _mm_mul_ps(c, uz));
			const __m128 vr = _mm_add_ps(_mm_add_ps(_mm_mul_ps(ux, rx), _mm_mul_ps(uy, ry)), _mm_mul_ps(uz, rz));
			const __m128 app = _mm_and_ps(_mm_and_ps(in, _mm_cmplt_ps(vr, zero)), _mm_sub_ps(zero, vr));
			const __m128 g = _mm_div_ps(_mm_mul_ps(_mm_mul_ps(app, hr), hr),
			                            _mm_mul_ps(_mm_mul_ps(_mm_add_ps(r2, veps), _mm_add_ps(vrhoi, prho)),
			                                       _mm_max_ps(r, vrmin)));
			s[3][k] = _mm_add_ps(s[3][k], _mm_mul_ps(g, rx));
			s[4][k] = _mm_add_ps(s[4][k], _mm_mul_ps(g, ry));
			s[5][k] = _mm_add_ps(s[5][k], _mm_mul_ps(g, rz));
		}
	}
	for (int c = 0; c < 6; ++c)
		f[c] = sph_hsum4(_mm_add_ps(s[c][0], s[c][1]));
}
#endif

#ifdef SPH_AVX2
__attribute__((target("avx2"))) static void pairs_avx2(const pair_args *a, const uint32_t *list, uint32_t cnt,
                                                       const float *pi, const float *vi, float f[6])
{
	const __m256 vxi = _mm256_set1_ps(pi[0]), vyi = _mm256_set1_ps(pi[1]), vzi = _mm256_set1_ps(pi[2]),
	             vui = _mm256_set1_ps(vi[0]), vvi = _mm256_set1_ps(vi[1]), vwi = _mm256_set1_ps(vi[2]),
	             vrhoi = _mm256_set1_ps(vi[3]), vh = _mm256_set1_ps(a->h), veps = _mm256_set1_ps(a->eps),
	             vrmin = _mm256_set1_ps(a->rmin), zero = _mm256_setzero_ps();
	const __m256i lane = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
	__m256 s0 = zero, s1 = zero, s2 = zero, s3 = zero, s4 = zero, s5 = zero;
	for (uint32_t q = 0; q < cnt; q += 8) {
		uint32_t l[8];
		group_rows(list, cnt, q, l);
		const float *const qa[8] = {a->pq + 4 * (size_t)l[0], a->pq + 4 * (size_t)l[1], a->pq + 4 * (size_t)l[2],
		                            a->pq + 4 * (size_t)l[3], a->pq + 4 * (size_t)l[4], a->pq + 4 * (size_t)l[5],
		                            a->pq + 4 * (size_t)l[6], a->pq + 4 * (size_t)l[7]};
		const float *const qb[8] = {a->pv + 4 * (size_t)l[0], a->pv + 4 * (size_t)l[1], a->pv + 4 * (size_t)l[2],
		                            a->pv + 4 * (size_t)l[3], a->pv + 4 * (size_t)l[4], a->pv + 4 * (size_t)l[5],
		                            a->pv + 4 * (size_t)l[6], a->pv + 4 * (size_t)l[7]};
		__m256 px, py, pz, pir, pu, pv, pw, prho;
		sph_transpose8(qa, &px, &py, &pz, &pir);
		sph_transpose8(qb, &pu, &pv, &pw, &prho);
		const __m256 in = _mm256_castsi256_ps(_mm256_cmpgt_epi32(_mm256_set1_epi32((int)(cnt - q)), lane));
		const __m256 rx = _mm256_sub_ps(vxi, px), ry = _mm256_sub_ps(vyi, py), rz = _mm256_sub_ps(vzi, pz);
		const __m256 r2 =
			_mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(rx, rx), _mm256_mul_ps(ry, ry)), _mm256_mul_ps(rz, rz));
		const __m256 r = _mm256_sqrt_ps(r2), hr = _mm256_sub_ps(vh, r);
		const __m256 ux = _mm256_sub_ps(vui, pu), uy = _mm256_sub_ps(vvi, pv), uz = _mm256_sub_ps(vwi, pw);
		const __m256 c = _mm256_and_ps(in, _mm256_mul_ps(hr, pir));
		s0 = _mm256_sub_ps(s0, _mm256_mul_ps(c, ux));
		s1 = _mm256_sub_ps(s1, _mm256_mul_ps(c, uy));
		s2 = _mm256_sub_ps(s2, _mm256_mul_ps(c, uz));
		const __m256 vr =
			_mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(ux, rx), _mm256_mul_ps(uy, ry)), _mm256_mul_ps(uz, rz));
		const __m256 app =
			_mm256_and_ps(_mm256_and_ps(in, _mm256_cmp_ps(vr, zero, _CMP_LT_OQ)), _mm256_sub_ps(zero, vr));
		const __m256 g = _mm256_div_ps(_mm256_mul_ps(_mm256_mul_ps(app, hr), hr),
		                               _mm256_mul_ps(_mm256_mul_ps(_mm256_add_ps(r2, veps), _mm256_add_ps(vrhoi, prho)),
		                                             _mm256_max_ps(r, vrmin)));
		s3 = _mm256_add_ps(s3, _mm256_mul_ps(g, rx));
		s4 = _mm256_add_ps(s4, _mm256_mul_ps(g, ry));
		s5 = _mm256_add_ps(s5, _mm256_mul_ps(g, rz));
	}
	f[0] = sph_hsum8(s0);
	f[1] = sph_hsum8(s1);
	f[2] = sph_hsum8(s2);
	f[3] = sph_hsum8(s3);
	f[4] = sph_hsum8(s4);
	f[5] = sph_hsum8(s5);
}
#endif

static eddy_status step(eddy_world *w, eddy_system *s, const eddy_step_context *ctx)
{
	const sph_viscosity *sv = s->data;
	sph_shared *sh = eddy__sph_find(w, s);
	if (!sh)
		return eddy__fail(w, EDDY_ERR_ORDER, "%s: needs sph_density before it (it builds the neighbour lists)", s->label);
	const sph_neighbors *nb = &sh->nb;
	/* positions and 1/rho come with sph_density's quads (sh->pq) */
	const float *vx = eddy__col(w, COL_VX), *vy = eddy__col(w, COL_VY), *vz = eddy__col(w, COL_VZ);
	const float *rho = eddy__col(w, COL_DENSITY);
	float *ax = eddy__col(w, COL_AX), *ay = eddy__col(w, COL_AY), *az = eddy__col(w, COL_AZ);
	const sph_kernel_consts kc = sh->k;
	const float coef = sv->def.viscosity * sh->mass * kc.visc_lap;
	/* -m Pi grad W = m alpha c h vr / ((r^2 + eps) rho_ij) spiky_grad (h-r)^2 r_hat */
	/* 2 x: the mean density (rho_i + rho_j) / 2 is folded into the pair term */
	const float acoef = 2.0f * sh->mass * sv->def.artificial * sh->c * kc.h * -kc.spiky_grad, eps = 0.01f * kc.h2,
	            rmin = 1e-3f * kc.h;
	const long n = nb->n < w->n ? (long)nb->n : (long)w->n;
	/* each neighbour's eight inputs as two 16-byte quads, (x y z 1/rho) from
	 * sph_density and (vx vy vz rho) made here: a group of neighbours then
	 * costs two loads each and two transposes instead of eight scattered
	 * loads each, which were most of the pass */
	const float *pq = sh->pq;
	float *pv = eddy__arena_alloc(&w->arena, (size_t)(n ? n : 1) * 4 * sizeof *pv);
	if (!pv)
		return eddy__fail(w, EDDY_ERR_NOMEM, "%s: out of scratch memory for %ld particles", s->label, n);
#pragma omp parallel for num_threads(ctx->threads) schedule(static)
	for (long i = 0; i < n; ++i) {
		pv[4 * i] = vx[i];
		pv[4 * i + 1] = vy[i];
		pv[4 * i + 2] = vz[i];
		pv[4 * i + 3] = rho[i];
	}
#ifdef __SSE2__
	const pair_args pa = {pq, pv, kc.h, eps, rmin};
#endif
#ifdef SPH_AVX2
	const bool avx2 = sph_use_avx2();
#endif
#pragma omp parallel for num_threads(ctx->threads) schedule(static)
	for (long i = 0; i < n; ++i) {
		const float *pi = pq + 4 * i, *vel = pv + 4 * i;
		const float xi = pi[0], yi = pi[1], zi = pi[2], ui = vel[0], vi = vel[1], wi = vel[2], rhoi = vel[3];
		const uint32_t *list = nb->nbr + (size_t)i * nb->cap;
		const uint32_t cnt = nb->count[i];
		float fx = 0, fy = 0, fz = 0, gx = 0, gy = 0, gz = 0;
		uint32_t q = 0;
#ifdef __SSE2__
		/* partial sums added up at the end: a fixed order, the same for any
		 * thread count and either path */
		float f[6];
#ifdef SPH_AVX2
		if (avx2)
			pairs_avx2(&pa, list, cnt, pi, vel, f);
		else
#endif
			pairs_sse(&pa, list, cnt, pi, vel, f);
		fx = f[0];
		fy = f[1];
		fz = f[2];
		gx = f[3];
		gy = f[4];
		gz = f[5];
		q = cnt;
#endif
		for (; q < cnt; ++q) {
			const float *pj = pq + 4 * (size_t)list[q], *vj = pv + 4 * (size_t)list[q];
			const float rx = xi - pj[0], ry = yi - pj[1], rz = zi - pj[2];
			const float r2 = rx * rx + ry * ry + rz * rz, r = sqrtf(r2);
			const float ux = ui - vj[0], uy = vi - vj[1], uz = wi - vj[2];
			const float c = (kc.h - r) * pj[3];
			fx -= c * ux;
			fy -= c * uy;
			fz -= c * uz;
			/* approaching pairs only (vr < 0), pushed apart along r_hat;
			 * branch-free, since the sign of vr is a coin toss per pair */
			const float vr = ux * rx + uy * ry + uz * rz, hr = kc.h - r;
			/* ternaries, not fmaxf: without -ffinite-math-only fmaxf is a libm call */
			const float app = vr < 0 ? -vr : 0.0f, rs = r > rmin ? r : rmin;
			const float a = app * hr * hr / ((r2 + eps) * (rhoi + vj[3]) * rs);
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
