/* sph_pressure: the symmetric pressure force with the spiky kernel's gradient
 * (Mueller 2003, eq. 10, without its factor 1/2; see below); boundary
 * particles enter the same sum with the pressure sph_density extrapolated onto
 * them (Adami et al. 2012).
 *
 * Reads: x y z density pressure. Writes: ax ay az (accumulated).
 *   a_i -= scale * [ sum_j m (p_i + p_j) / (rho_i rho_j) grad W_spiky(x_i - x_j)
 *                  + sum_b V_b (p_i + p_b) / rho_i grad W_spiky(x_i - x_b) ]
 *   grad W_spiky(r_vec) = -45/(pi h^6) (h - r)^2 r_vec / r
 * Why not the paper's (p_i + p_j) / 2: in the interior sum_j V_j grad W = 0,
 * so sum_j V_j (p_i + p_j)/2 grad W = grad p / 2. The paper's force is half
 * the pressure gradient; a resting column then compresses twice as much as
 * g H / k says and sound travels at sqrt(k/2). The form here is the same
 * symmetric (momentum-conserving) pair force, doubled, so it reproduces
 * grad p and c = sqrt(k) (tested by the hydrostatic tank).
 * The force is divided by the moment it has on the particle lattice,
 * (m / rho0) sum_j x_j^2 |dW/dr| / r_j = 0.947 at h = 2 spacings (the spiky
 * lattice moment 0.956, eddy_sph_lattice_gradient_moment, times the
 * calibrated m over rho0 spacing^3): uncorrected, the force of a linear
 * pressure field falls 5.3% short of grad p and a resting column carries that
 * much more pressure (the hydrostatic test saw +3.7%, now +0.6%). The same
 * correction sph_density makes for the mass.
 * Pairs closer than 1e-3 h take a fixed antisymmetric direction (sph.h): the
 * gradient has no direction at r = 0, and skipping them would leave
 * coincident particles stuck together (VALIDATION.md C.6).
 * Positions and 1/rho come from sph_density's (x y z 1/rho) quads (sh->pq).
 * The fluid pairs go eight at a time (AVX2 when the CPU has it, else SSE as
 * two halves doing the same per lane), with per-lane partial sums added in a
 * fixed order: the same bits for any thread count and either path.
 * Time-step limits, the smaller reported: acoustic, dt <= h / (c + max|v|),
 * c = sqrt(k) from sph_density's stiffness (the world's CFL number is the
 * Courant factor lambda, 0.25-0.4); force, dt <= 0.625 sqrt(h / max|a|),
 * max|a| from the last step (with the default CFL 0.4 the usual
 * 0.25 sqrt(h/|a|)).
 * Source: Mueller, Charypar & Gross 2003; Adami, Hu & Adams, "A generalized
 * wall boundary condition for SPH", JCP 2012. */
#include "sph.h"
#include "systems.h"

#include <stdlib.h>

typedef struct sph_pressure {
	eddy_sph_pressure_def def;
} sph_pressure;

static const int pressure_reads[] = {COL_X_, COL_Y_, COL_Z_, COL_DENSITY, COL_PRESSURE};
static const int pressure_writes[] = {COL_AX, COL_AY, COL_AZ, -1};
static const int no_hint_writes[] = {-1};

eddy_sph_pressure_def eddy_default_sph_pressure_def(void)
{
	eddy_sph_pressure_def d;
	d.scale = 1.0f;
	return d;
}

/* The fluid pairs of one particle, eight neighbours at a time (the last
 * group padded with copies of the last neighbour, masked out); returns how
 * many it did, all unless a group has a coincident pair: the scalar loop
 * takes it from there. f gets the sums of (p_i + p_j) / rho_j (h - r)^2
 * r_vec / r: the 1/r normalises r_vec. */
typedef struct pair_args {
	const float *pk, *p; /* (x y z 1/rho) quads; pressures */
	float h, eps2;
} pair_args;

/* The neighbours of group q, padded; lanes past the count are masked. */
static inline void group_rows(const uint32_t *list, uint32_t cnt, uint32_t q, uint32_t l[8])
{
	for (uint32_t k = 0; k < 8; ++k)
		l[k] = list[q + k < cnt ? q + k : cnt - 1];
}

#ifdef __SSE2__
static uint32_t pairs_sse(const pair_args *a, const uint32_t *list, uint32_t cnt, float xi, float yi, float zi,
                          float pi_, float f[3])
{
	const __m128 vxi = _mm_set1_ps(xi), vyi = _mm_set1_ps(yi), vzi = _mm_set1_ps(zi), vpi = _mm_set1_ps(pi_),
	             vh = _mm_set1_ps(a->h), veps2 = _mm_set1_ps(a->eps2);
	__m128 sx[2] = {_mm_setzero_ps(), _mm_setzero_ps()}, sy[2] = {sx[0], sx[0]}, sz[2] = {sx[0], sx[0]};
	uint32_t q = 0;
	for (; q < cnt; q += 8) {
		uint32_t l[8];
		group_rows(list, cnt, q, l);
		const __m128i left = _mm_set1_epi32((int)(cnt - q));
		__m128 rx[2], ry[2], rz[2], ir[2], r2[2], in[2];
		for (int k = 0; k < 2; ++k) {
			const uint32_t *lk = l + 4 * k;
			__m128 px = _mm_loadu_ps(a->pk + 4 * (size_t)lk[0]), py = _mm_loadu_ps(a->pk + 4 * (size_t)lk[1]),
			       pz = _mm_loadu_ps(a->pk + 4 * (size_t)lk[2]), pw = _mm_loadu_ps(a->pk + 4 * (size_t)lk[3]);
			_MM_TRANSPOSE4_PS(px, py, pz, pw);
			rx[k] = _mm_sub_ps(vxi, px);
			ry[k] = _mm_sub_ps(vyi, py);
			rz[k] = _mm_sub_ps(vzi, pz);
			ir[k] = pw;
			r2[k] = _mm_add_ps(_mm_add_ps(_mm_mul_ps(rx[k], rx[k]), _mm_mul_ps(ry[k], ry[k])), _mm_mul_ps(rz[k], rz[k]));
			in[k] = _mm_castsi128_ps(_mm_cmpgt_epi32(left, _mm_setr_epi32(4 * k, 4 * k + 1, 4 * k + 2, 4 * k + 3)));
		}
		if ((_mm_movemask_ps(_mm_cmpgt_ps(r2[0], veps2)) & _mm_movemask_ps(_mm_cmpgt_ps(r2[1], veps2))) != 15)
			break;
		for (int k = 0; k < 2; ++k) {
			const uint32_t *lk = l + 4 * k;
			const __m128 r = _mm_sqrt_ps(r2[k]), hr = _mm_sub_ps(vh, r);
			const __m128 pj = _mm_setr_ps(a->p[lk[0]], a->p[lk[1]], a->p[lk[2]], a->p[lk[3]]);
			const __m128 c = _mm_and_ps(
				in[k], _mm_div_ps(_mm_mul_ps(_mm_mul_ps(_mm_mul_ps(_mm_add_ps(vpi, pj), ir[k]), hr), hr), r));
			sx[k] = _mm_add_ps(sx[k], _mm_mul_ps(c, rx[k]));
			sy[k] = _mm_add_ps(sy[k], _mm_mul_ps(c, ry[k]));
			sz[k] = _mm_add_ps(sz[k], _mm_mul_ps(c, rz[k]));
		}
	}
	f[0] = sph_hsum4(_mm_add_ps(sx[0], sx[1]));
	f[1] = sph_hsum4(_mm_add_ps(sy[0], sy[1]));
	f[2] = sph_hsum4(_mm_add_ps(sz[0], sz[1]));
	return q < cnt ? q : cnt;
}
#endif

#ifdef SPH_AVX2
__attribute__((target("avx2"))) static uint32_t pairs_avx2(const pair_args *a, const uint32_t *list, uint32_t cnt,
                                                           float xi, float yi, float zi, float pi_, float f[3])
{
	const __m256 vxi = _mm256_set1_ps(xi), vyi = _mm256_set1_ps(yi), vzi = _mm256_set1_ps(zi),
	             vpi = _mm256_set1_ps(pi_), vh = _mm256_set1_ps(a->h), veps2 = _mm256_set1_ps(a->eps2);
	const __m256i lane = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
	__m256 sx = _mm256_setzero_ps(), sy = sx, sz = sx;
	uint32_t q = 0;
	for (; q < cnt; q += 8) {
		uint32_t l[8];
		group_rows(list, cnt, q, l);
		const float *const quad[8] = {a->pk + 4 * (size_t)l[0], a->pk + 4 * (size_t)l[1], a->pk + 4 * (size_t)l[2],
		                              a->pk + 4 * (size_t)l[3], a->pk + 4 * (size_t)l[4], a->pk + 4 * (size_t)l[5],
		                              a->pk + 4 * (size_t)l[6], a->pk + 4 * (size_t)l[7]};
		__m256 px, py, pz, ir;
		sph_transpose8(quad, &px, &py, &pz, &ir);
		const __m256 rx = _mm256_sub_ps(vxi, px), ry = _mm256_sub_ps(vyi, py), rz = _mm256_sub_ps(vzi, pz);
		const __m256 r2 =
			_mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(rx, rx), _mm256_mul_ps(ry, ry)), _mm256_mul_ps(rz, rz));
		if (_mm256_movemask_ps(_mm256_cmp_ps(r2, veps2, _CMP_GT_OQ)) != 255)
			break;
		const __m256 in = _mm256_castsi256_ps(_mm256_cmpgt_epi32(_mm256_set1_epi32((int)(cnt - q)), lane));
		const __m256 r = _mm256_sqrt_ps(r2), hr = _mm256_sub_ps(vh, r);
		const __m256 pj = _mm256_setr_ps(a->p[l[0]], a->p[l[1]], a->p[l[2]], a->p[l[3]], a->p[l[4]], a->p[l[5]],
		                                 a->p[l[6]], a->p[l[7]]);
		const __m256 c = _mm256_and_ps(
			in, _mm256_div_ps(_mm256_mul_ps(_mm256_mul_ps(_mm256_mul_ps(_mm256_add_ps(vpi, pj), ir), hr), hr), r));
		sx = _mm256_add_ps(sx, _mm256_mul_ps(c, rx));
		sy = _mm256_add_ps(sy, _mm256_mul_ps(c, ry));
		sz = _mm256_add_ps(sz, _mm256_mul_ps(c, rz));
	}
	f[0] = sph_hsum8(sx);
	f[1] = sph_hsum8(sy);
	f[2] = sph_hsum8(sz);
	return q < cnt ? q : cnt;
}
#endif

static eddy_status step(eddy_world *w, eddy_system *s, const eddy_step_context *ctx)
{
	const sph_pressure *sp = s->data;
	sph_shared *sh = eddy__sph_find(w, s);
	if (!sh)
		return eddy__fail(w, EDDY_ERR_ORDER, "%s: needs sph_density before it (it builds the neighbour lists)", s->label);
	const sph_neighbors *nb = &sh->nb;
	const float *p = eddy__col(w, COL_PRESSURE), *inv_rho = sh->inv_rho;
	float *ax = eddy__col(w, COL_AX), *ay = eddy__col(w, COL_AY), *az = eddy__col(w, COL_AZ);
	const sph_kernel_consts kc = sh->k;
	const float m = sh->mass, scale = sp->def.scale, eps2 = 1e-6f * kc.h2;
	const long n = nb->n < w->n ? (long)nb->n : (long)w->n;
	/* each neighbour's position and 1/rho as one 16-byte quad (sph_density
	 * made them): a group of neighbours then costs a load each and a
	 * transpose instead of four scattered loads each */
	const float *pk = sh->pq;
#ifdef __SSE2__
	const pair_args pa = {pk, p, kc.h, eps2};
#endif
#ifdef SPH_AVX2
	const bool avx2 = sph_use_avx2();
#endif
#pragma omp parallel for num_threads(ctx->threads) schedule(static)
	for (long i = 0; i < n; ++i) {
		const float xi = pk[4 * i], yi = pk[4 * i + 1], zi = pk[4 * i + 2];
		/* rho >= m W(0) > 0 (the self term), so 1/rho is finite */
		const float iri = inv_rho[i], pi_ = p[i];
		const uint32_t *list = nb->nbr + (size_t)i * nb->cap;
		const uint32_t cnt = nb->count[i];
		float fx = 0, fy = 0, fz = 0;
		uint32_t q = 0;
#ifdef __SSE2__
		/* partial sums added up at the end: a fixed order, the same for any
		 * thread count and either path */
		float f[3];
#ifdef SPH_AVX2
		if (avx2)
			q = pairs_avx2(&pa, list, cnt, xi, yi, zi, pi_, f);
		else
#endif
			q = pairs_sse(&pa, list, cnt, xi, yi, zi, pi_, f);
		fx = f[0];
		fy = f[1];
		fz = f[2];
#endif
		for (; q < cnt; ++q) {
			const uint32_t j = list[q];
			float rx = xi - pk[4 * (size_t)j], ry = yi - pk[4 * (size_t)j + 1], rz = zi - pk[4 * (size_t)j + 2];
			const float r2 = rx * rx + ry * ry + rz * rz;
			float r;
			if (r2 > eps2) {
				r = sqrtf(r2);
				const float inv = 1.0f / r;
				rx *= inv;
				ry *= inv;
				rz *= inv;
			} else {
				r = 0;
				sph_coincident_dir((size_t)i, j, &rx, &ry, &rz);
			}
			const float hr = kc.h - r;
			/* (p_i + p_j)/(rho_i rho_j) times |dW/dr|; the force pushes i away from j */
			const float c = (pi_ + p[j]) * inv_rho[j] * hr * hr;
			fx += c * rx;
			fy += c * ry;
			fz += c * rz;
		}
		const uint32_t *blist = nb->bnbr + (size_t)i * nb->bcap;
		const uint32_t bcnt = nb->bcount[i];
		float bx = 0, by = 0, bz = 0;
		for (uint32_t qb = 0; qb < bcnt; ++qb) {
			const uint32_t b = blist[qb];
			float rx = xi - nb->bx[b], ry = yi - nb->by[b], rz = zi - nb->bz[b];
			const float r2 = rx * rx + ry * ry + rz * rz;
			if (!(r2 > eps2))
				continue; /* on the wall surface: the collider handles it */
			const float r = sqrtf(r2), inv = 1.0f / r, hr = kc.h - r;
			/* m_b (p_i + p_b) / (rho_i rho_b) with m_b = V_b rho_b */
			const float c = nb->bvol[b] * (pi_ + nb->bp[b]) * hr * hr * inv;
			bx += c * rx;
			by += c * ry;
			bz += c * rz;
		}
		/* -grad W = +45/(pi h^6) (h-r)^2 r_hat, so the signs above are already "away" */
		const float g = -kc.spiky_grad * sh->grad_cal * scale;
		const float bcoef = 1.0f;
		ax[i] += g * iri * (m * fx + bcoef * bx);
		ay[i] += g * iri * (m * fy + bcoef * by);
		az[i] += g * iri * (m * fz + bcoef * bz);
	}
	return EDDY_OK;
}

/* The largest |(u, v, w)| over the particles, 0 without the columns. */
static double max_norm(eddy_world *w, int cu, int cv, int cw)
{
	const float *u = eddy__col(w, cu), *v = eddy__col(w, cv), *q = eddy__col(w, cw);
	float m2 = 0;
	if (u && v && q)
		for (size_t i = 0; i < w->n; ++i) {
			const float s2 = u[i] * u[i] + v[i] * v[i] + q[i] * q[i];
			m2 = s2 > m2 ? s2 : m2;
		}
	return sqrt((double)m2);
}

static double limit(eddy_world *w, eddy_system *s, const char **reason)
{
	const sph_shared *sh = eddy__sph_find(w, s);
	*reason = "acoustic";
	if (!sh)
		return INFINITY;
	const double acoustic = sh->h / (sh->c + max_norm(w, COL_VX, COL_VY, COL_VZ)), a = max_norm(w, COL_AX, COL_AY, COL_AZ);
	const double force = a > 0 ? 0.625 * sqrt(sh->h / a) : INFINITY;
	if (force < acoustic)
		*reason = "force";
	return force < acoustic ? force : acoustic;
}

const eddy_system_vtable eddy__kind_sph_pressure = {
	.name = "sph_pressure",
	.step = step,
	.limit = limit,
	/* ax ay az are every force's: order hints for them name gravity alone */
	.default_writes = no_hint_writes,
};

eddy_system_id eddy_add_sph_pressure(eddy_world *w, const eddy_sph_pressure_def *def)
{
	const char *sys = "sph_pressure";
	if (!def)
		return eddy__fail(w, EDDY_ERR_INVALID, "%s: def is NULL", sys), EDDY_NULL_SYSTEM;
	if (!eddy__check_positive(w, sys, "scale", def->scale))
		return EDDY_NULL_SYSTEM;
	sph_pressure *sp = malloc(sizeof *sp);
	if (sp)
		sp->def = *def;
	return eddy__add_system(w, &eddy__kind_sph_pressure, sp, pressure_reads, 5, pressure_writes, 3);
}
