/* SPDX-License-Identifier: MIT */
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
 * (AVX2 when the CPU has it, else SSE as two halves doing the same per lane;
 * EDDY_NO_AVX2 forces SSE), a particle's last group masked, with per-lane
 * partial sums added in a fixed order: the same bits for any thread count
 * and either path. The particles go in blocks of 64, the sums over the
 * block's groups first, then a loop adding the totals to ax ay az.
 * Source: Mueller, Charypar & Gross 2003; Monaghan, "Smoothed particle
 * hydrodynamics", ARAA 1992. */
#include "sph.h"
#include "systems.h"

#include <stdlib.h>

typedef struct sph_viscosity {
	eddy_sph_viscosity_def def;
} sph_viscosity;

static const int viscosity_reads[] = {COL_X_, COL_Y_, COL_Z_, COL_VX, COL_VY, COL_VZ, COL_DENSITY, -1};
static const int viscosity_writes[] = {COL_AX, COL_AY, COL_AZ, -1};
static const int no_hint_writes[] = {-1};

eddy_sph_viscosity_def eddy_default_sph_viscosity_def(void)
{
	eddy_sph_viscosity_def d;
	d.viscosity = 1e-3f; /* water at 20 C */
	d.artificial = 0.05f;
	return d;
}

/* The pass goes in blocks of particles: first the sums over the pairs of the
 * block (pair_sums), then a loop adding each particle's totals to ax ay az.
 * Finishing each particle right after its groups put the adds of its six
 * totals behind every (often mispredicted) exit of the loop over its groups;
 * the particles of the second loop are independent (as in sph_dfsph). */
#define VISC_BLOCK 64
#define VISC_T 24 /* floats of the sums per particle: 4 lanes of each of six */

/* What the pair sums read. Per particle they give -sum (h - r) / rho_j
 * (v_i - v_j) (components 0-2) and the artificial viscosity's sum of
 * max(0, -v_ij . r_vec) (h - r)^2 / ((r^2 + eps) (rho_i + rho_j)
 * max(r, rmin)) r_vec (3-5). */
typedef struct pair_args {
	const sph_neighbors *nb;
	const float *pq, *pv; /* (x y z 1/rho) and (vx vy vz -rho) per particle */
	float h, eps, rmin;
} pair_args;

/* The sums over the pairs of particles i0 .. i0 + cnt - 1, eight neighbours
 * at a time, each particle's as four lanes per component (lane l holding
 * lanes l and l + 4 of the groups) at t + VISC_T q. */
typedef void pair_sums_fn(const pair_args *a, long i0, long cnt, float *t);

#ifdef __SSE2__
/* One group (neighbours l[0..7]) as two halves, with the same operations
 * per lane as the AVX2 path. The differences are taken on the quads before
 * the transpose: qp = (x_i y_i z_i 0) minus (x_j y_j z_j 1/rho_j) gives
 * r_vec and -1/rho_j, qv = (v_i rho_i) minus (v_j -rho_j) gives v_ij and
 * rho_i + rho_j (a - (-b) is a + b, bit for bit): the same results per
 * lane, but i's inputs take two registers, not seven, and fewer of the six
 * sums spill to the stack (the pass some 5-10% faster). The -1/rho_j makes
 * c the negative of (h - r) / rho_j, added instead of subtracted. Whole
 * groups (masked false) need no mask: the compiler drops it where the
 * argument is constant. */
static inline void group_sse(const pair_args *a, const uint32_t *l, bool masked, uint32_t left, __m128 qp, __m128 qv,
                             __m128 s[6][2])
{
	const __m128 vh = _mm_set1_ps(a->h), veps = _mm_set1_ps(a->eps), vrmin = _mm_set1_ps(a->rmin),
	             zero = _mm_setzero_ps();
	for (int k = 0; k < 2; ++k) {
		const size_t o0 = 4 * (size_t)l[4 * k], o1 = 4 * (size_t)l[4 * k + 1], o2 = 4 * (size_t)l[4 * k + 2],
		             o3 = 4 * (size_t)l[4 * k + 3];
		__m128 rx = _mm_sub_ps(qp, _mm_loadu_ps(a->pq + o0)), ry = _mm_sub_ps(qp, _mm_loadu_ps(a->pq + o1)),
		       rz = _mm_sub_ps(qp, _mm_loadu_ps(a->pq + o2)), nir = _mm_sub_ps(qp, _mm_loadu_ps(a->pq + o3));
		_MM_TRANSPOSE4_PS(rx, ry, rz, nir);
		__m128 ux = _mm_sub_ps(qv, _mm_loadu_ps(a->pv + o0)), uy = _mm_sub_ps(qv, _mm_loadu_ps(a->pv + o1)),
		       uz = _mm_sub_ps(qv, _mm_loadu_ps(a->pv + o2)), rho2 = _mm_sub_ps(qv, _mm_loadu_ps(a->pv + o3));
		_MM_TRANSPOSE4_PS(ux, uy, uz, rho2);
		const __m128 r2 = _mm_add_ps(_mm_add_ps(_mm_mul_ps(rx, rx), _mm_mul_ps(ry, ry)), _mm_mul_ps(rz, rz));
		const __m128 r = _mm_sqrt_ps(r2), hr = _mm_sub_ps(vh, r);
		const __m128 in = masked ? _mm_castsi128_ps(_mm_cmpgt_epi32(_mm_set1_epi32((int)left),
		                                                            _mm_setr_epi32(4 * k, 4 * k + 1, 4 * k + 2, 4 * k + 3)))
		                         : zero;
		__m128 c = _mm_mul_ps(hr, nir);
		if (masked)
			c = _mm_and_ps(in, c);
		s[0][k] = _mm_add_ps(s[0][k], _mm_mul_ps(c, ux));
		s[1][k] = _mm_add_ps(s[1][k], _mm_mul_ps(c, uy));
		s[2][k] = _mm_add_ps(s[2][k], _mm_mul_ps(c, uz));
		const __m128 vr = _mm_add_ps(_mm_add_ps(_mm_mul_ps(ux, rx), _mm_mul_ps(uy, ry)), _mm_mul_ps(uz, rz));
		__m128 neg = _mm_cmplt_ps(vr, zero);
		if (masked)
			neg = _mm_and_ps(in, neg);
		const __m128 app = _mm_and_ps(neg, _mm_sub_ps(zero, vr));
		const __m128 g = _mm_div_ps(_mm_mul_ps(_mm_mul_ps(app, hr), hr),
		                            _mm_mul_ps(_mm_mul_ps(_mm_add_ps(r2, veps), rho2), _mm_max_ps(r, vrmin)));
		s[3][k] = _mm_add_ps(s[3][k], _mm_mul_ps(g, rx));
		s[4][k] = _mm_add_ps(s[4][k], _mm_mul_ps(g, ry));
		s[5][k] = _mm_add_ps(s[5][k], _mm_mul_ps(g, rz));
	}
}

/* (x_i y_i z_i 0) and (v_i rho_i) from i's quads */
static inline void own_quads(const float *pi, const float *vel, __m128 *qp, __m128 *qv)
{
	*qp = _mm_and_ps(_mm_loadu_ps(pi), _mm_castsi128_ps(_mm_setr_epi32(-1, -1, -1, 0)));
	*qv = _mm_xor_ps(_mm_loadu_ps(vel), _mm_setr_ps(0.0f, 0.0f, 0.0f, -0.0f));
}

static void pair_sums_sse(const pair_args *a, long i0, long cnt, float *t)
{
	const sph_neighbors *nb = a->nb;
	for (long b = 0; b < cnt; ++b) {
		const long i = i0 + b;
		const uint32_t *list = nb->nbr + (size_t)i * nb->cap, c = nb->count[i];
		__m128 qp, qv;
		own_quads(a->pq + 4 * i, a->pv + 4 * i, &qp, &qv);
		__m128 s[6][2];
		for (int k = 0; k < 6; ++k)
			s[k][0] = s[k][1] = _mm_setzero_ps();
		uint32_t q = 0;
		for (; q + 8 <= c; q += 8)
			group_sse(a, list + q, false, 8, qp, qv, s);
		if (q < c) {
			uint32_t l[8];
			sph_group_rows(list, c, q, l);
			group_sse(a, l, true, c - q, qp, qv, s);
		}
		for (int k = 0; k < 6; ++k)
			_mm_storeu_ps(t + VISC_T * b + 4 * k, _mm_add_ps(s[k][0], s[k][1]));
	}
}
#else
/* Without SSE, pair by pair: the totals in lane 0, the other lanes 0. */
static void pair_sums_scalar(const pair_args *a, long i0, long cnt, float *t)
{
	const sph_neighbors *nb = a->nb;
	for (long b = 0; b < cnt; ++b) {
		const long i = i0 + b;
		const uint32_t *list = nb->nbr + (size_t)i * nb->cap, cnt_i = nb->count[i];
		const float *pi = a->pq + 4 * i, *vel = a->pv + 4 * i;
		float f[6] = {0, 0, 0, 0, 0, 0};
		for (uint32_t q = 0; q < cnt_i; ++q) {
			const float *pj = a->pq + 4 * (size_t)list[q], *vj = a->pv + 4 * (size_t)list[q];
			const float rx = pi[0] - pj[0], ry = pi[1] - pj[1], rz = pi[2] - pj[2];
			const float r2 = rx * rx + ry * ry + rz * rz, r = sqrtf(r2), hr = a->h - r;
			const float ux = vel[0] - vj[0], uy = vel[1] - vj[1], uz = vel[2] - vj[2];
			const float c = hr * pj[3];
			f[0] -= c * ux;
			f[1] -= c * uy;
			f[2] -= c * uz;
			/* approaching pairs only (vr < 0), pushed apart along r_hat */
			const float vr = ux * rx + uy * ry + uz * rz;
			const float app = vr < 0 ? -vr : 0.0f, rs = r > a->rmin ? r : a->rmin;
			/* pv holds -rho */
			const float g = app * hr * hr / ((r2 + a->eps) * (-vel[3] - vj[3]) * rs);
			f[3] += g * rx;
			f[4] += g * ry;
			f[5] += g * rz;
		}
		for (int k = 0; k < 6; ++k) {
			float *l = t + VISC_T * b + 4 * k;
			l[0] = f[k];
			l[1] = l[2] = l[3] = 0;
		}
	}
}
#endif

#ifdef SPH_AVX2
/* Quads a[0..7] subtracted from q (lanes 0-3 from a[0..3], 4-7 from
 * a[4..7]) and transposed, as the SSE path's four subtractions and
 * _MM_TRANSPOSE4_PS per half. */
__attribute__((target("avx2"))) static inline void sub_transpose8(__m256 q, const float *const a[8], __m256 *c0,
                                                                  __m256 *c1, __m256 *c2, __m256 *c3)
{
	const __m256 v0 = _mm256_sub_ps(
		             q, _mm256_insertf128_ps(_mm256_castps128_ps256(_mm_loadu_ps(a[0])), _mm_loadu_ps(a[4]), 1)),
	             v1 = _mm256_sub_ps(
		             q, _mm256_insertf128_ps(_mm256_castps128_ps256(_mm_loadu_ps(a[1])), _mm_loadu_ps(a[5]), 1)),
	             v2 = _mm256_sub_ps(
		             q, _mm256_insertf128_ps(_mm256_castps128_ps256(_mm_loadu_ps(a[2])), _mm_loadu_ps(a[6]), 1)),
	             v3 = _mm256_sub_ps(
		             q, _mm256_insertf128_ps(_mm256_castps128_ps256(_mm_loadu_ps(a[3])), _mm_loadu_ps(a[7]), 1));
	const __m256 t0 = _mm256_unpacklo_ps(v0, v1), t1 = _mm256_unpacklo_ps(v2, v3), t2 = _mm256_unpackhi_ps(v0, v1),
	             t3 = _mm256_unpackhi_ps(v2, v3);
	*c0 = _mm256_shuffle_ps(t0, t1, _MM_SHUFFLE(1, 0, 1, 0));
	*c1 = _mm256_shuffle_ps(t0, t1, _MM_SHUFFLE(3, 2, 3, 2));
	*c2 = _mm256_shuffle_ps(t2, t3, _MM_SHUFFLE(1, 0, 1, 0));
	*c3 = _mm256_shuffle_ps(t2, t3, _MM_SHUFFLE(3, 2, 3, 2));
}

__attribute__((target("avx2"))) static inline void group_avx2(const pair_args *a, const uint32_t *l, bool masked,
                                                              uint32_t left, __m256 qp, __m256 qv, __m256 s[6])
{
	const __m256 vh = _mm256_set1_ps(a->h), veps = _mm256_set1_ps(a->eps), vrmin = _mm256_set1_ps(a->rmin),
	             zero = _mm256_setzero_ps();
	const float *const qa[8] = {a->pq + 4 * (size_t)l[0], a->pq + 4 * (size_t)l[1], a->pq + 4 * (size_t)l[2],
	                            a->pq + 4 * (size_t)l[3], a->pq + 4 * (size_t)l[4], a->pq + 4 * (size_t)l[5],
	                            a->pq + 4 * (size_t)l[6], a->pq + 4 * (size_t)l[7]};
	const float *const qb[8] = {a->pv + 4 * (size_t)l[0], a->pv + 4 * (size_t)l[1], a->pv + 4 * (size_t)l[2],
	                            a->pv + 4 * (size_t)l[3], a->pv + 4 * (size_t)l[4], a->pv + 4 * (size_t)l[5],
	                            a->pv + 4 * (size_t)l[6], a->pv + 4 * (size_t)l[7]};
	__m256 rx, ry, rz, nir, ux, uy, uz, rho2;
	sub_transpose8(qp, qa, &rx, &ry, &rz, &nir);
	sub_transpose8(qv, qb, &ux, &uy, &uz, &rho2);
	const __m256 r2 = _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(rx, rx), _mm256_mul_ps(ry, ry)), _mm256_mul_ps(rz, rz));
	const __m256 r = _mm256_sqrt_ps(r2), hr = _mm256_sub_ps(vh, r);
	const __m256 in = masked ? _mm256_castsi256_ps(_mm256_cmpgt_epi32(_mm256_set1_epi32((int)left),
	                                                                  _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7)))
	                         : zero;
	__m256 c = _mm256_mul_ps(hr, nir);
	if (masked)
		c = _mm256_and_ps(in, c);
	s[0] = _mm256_add_ps(s[0], _mm256_mul_ps(c, ux));
	s[1] = _mm256_add_ps(s[1], _mm256_mul_ps(c, uy));
	s[2] = _mm256_add_ps(s[2], _mm256_mul_ps(c, uz));
	const __m256 vr = _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(ux, rx), _mm256_mul_ps(uy, ry)), _mm256_mul_ps(uz, rz));
	__m256 neg = _mm256_cmp_ps(vr, zero, _CMP_LT_OQ);
	if (masked)
		neg = _mm256_and_ps(in, neg);
	const __m256 app = _mm256_and_ps(neg, _mm256_sub_ps(zero, vr));
	const __m256 g = _mm256_div_ps(_mm256_mul_ps(_mm256_mul_ps(app, hr), hr),
	                               _mm256_mul_ps(_mm256_mul_ps(_mm256_add_ps(r2, veps), rho2), _mm256_max_ps(r, vrmin)));
	s[3] = _mm256_add_ps(s[3], _mm256_mul_ps(g, rx));
	s[4] = _mm256_add_ps(s[4], _mm256_mul_ps(g, ry));
	s[5] = _mm256_add_ps(s[5], _mm256_mul_ps(g, rz));
}

__attribute__((target("avx2"))) static void pair_sums_avx2(const pair_args *a, long i0, long cnt, float *t)
{
	const sph_neighbors *nb = a->nb;
	for (long b = 0; b < cnt; ++b) {
		const long i = i0 + b;
		const uint32_t *list = nb->nbr + (size_t)i * nb->cap, c = nb->count[i];
		__m128 qp4, qv4;
		own_quads(a->pq + 4 * i, a->pv + 4 * i, &qp4, &qv4);
		const __m256 qp = _mm256_set_m128(qp4, qp4), qv = _mm256_set_m128(qv4, qv4);
		__m256 s[6];
		for (int k = 0; k < 6; ++k)
			s[k] = _mm256_setzero_ps();
		uint32_t q = 0;
		for (; q + 8 <= c; q += 8)
			group_avx2(a, list + q, false, 8, qp, qv, s);
		if (q < c) {
			uint32_t l[8];
			sph_group_rows(list, c, q, l);
			group_avx2(a, l, true, c - q, qp, qv, s);
		}
		/* lanes l and l + 4 added, as the SSE path adds its halves */
		for (int k = 0; k < 6; ++k)
			_mm_storeu_ps(t + VISC_T * b + 4 * k,
			              _mm_add_ps(_mm256_castps256_ps128(s[k]), _mm256_extractf128_ps(s[k], 1)));
	}
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
	 * sph_density and (vx vy vz -rho) made here: a group of neighbours then
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
		pv[4 * i + 3] = -rho[i]; /* negated: see group_sse */
	}
	const pair_args pa = {nb, pq, pv, kc.h, eps, rmin};
#ifdef SPH_AVX2
	pair_sums_fn *sums = sph_use_avx2() ? pair_sums_avx2 : pair_sums_sse;
#elif defined(__SSE2__)
	pair_sums_fn *sums = pair_sums_sse;
#else
	pair_sums_fn *sums = pair_sums_scalar;
#endif
	const int threads = ctx->threads;
	/* the threads take equal shares in order; a particle's result does not
	 * depend on the blocks, so it is the same for any thread count */
#pragma omp parallel for num_threads(threads) schedule(static)
	for (int th = 0; th < threads; ++th) {
		float t[VISC_BLOCK * VISC_T];
		for (long i0 = n * th / threads, hi = n * (th + 1) / threads; i0 < hi; i0 += VISC_BLOCK) {
			const long cnt = hi - i0 < VISC_BLOCK ? hi - i0 : VISC_BLOCK;
			sums(&pa, i0, cnt, t);
			for (long b = 0; b < cnt; ++b) {
				const long i = i0 + b;
				const float *tb = t + VISC_T * b;
				const float k = coef * pq[4 * i + 3];
				ax[i] += k * sph_sum4(tb) + acoef * sph_sum4(tb + 12);
				ay[i] += k * sph_sum4(tb + 4) + acoef * sph_sum4(tb + 16);
				az[i] += k * sph_sum4(tb + 8) + acoef * sph_sum4(tb + 20);
			}
		}
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
	.requires = EDDY_CAP_SPH_NEIGHBORS,
	.step = step,
	.limit = limit,
	/* ax ay az are every force's: order hints for them name gravity alone */
	.default_writes = no_hint_writes,
};

eddy_system_id eddy_add_sph_viscosity(eddy_world *w, const eddy_sph_viscosity_def *def)
{
	const char *sys = "sph_viscosity";
	if (!eddy__add_args(w, def, sys))
		return EDDY_NULL_SYSTEM;
	if (!eddy__check_nonneg(w, sys, "viscosity", def->viscosity) || !eddy__check_finite(w, sys, "viscosity", def->viscosity) ||
	    !eddy__check_range(w, sys, "artificial", def->artificial, 0, 2))
		return EDDY_NULL_SYSTEM;
	sph_viscosity *sv = malloc(sizeof *sv);
	if (sv)
		sv->def = *def;
	return eddy__add_system(w, &eddy__kind_sph_viscosity, sv, viscosity_reads, viscosity_writes);
}
