/* SPDX-License-Identifier: MIT */
/* The SIMD vocabulary of the SPH pair passes: sf8, eight float lanes, and
 * the operations the passes need, with three back-ends that give the same
 * bits lane for lane:
 *   AVX2    (the file is compiled with -mavx2 -mbmi2): sf8 is an __m256;
 *   SSE     (__SSE2__, EDDY_SIMD_SCALAR not defined): two __m128, lo = lanes
 *           0-3 and hi = lanes 4-7, every operation done on both halves;
 *   scalar  (anything else): float l[8], every operation a plain loop over
 *           the lanes, no intrinsics.
 * Every operation is one IEEE operation per lane (no FMA: -std=c11 keeps
 * -ffp-contract=off), so a pass written once gives the same results on all
 * three. Masks are sf8 values whose lanes are all ones or zero, as the
 * SSE/AVX compares give. Sums over lanes end in one fixed order (sf8_fold4,
 * sf8_sum) for the same reason.
 *
 * The operations: sf8_zero, set1(a), load(p) and store(p, a) (unaligned);
 * add sub mul div sqrt, max min (as maxps/minps: b when unordered); the
 * ordered compares lt gt le ge; and or xor, andnot(m, a) = ~m & a,
 * select(m, a, b) (a where m, else b); and these:
 *   sf8_lanes_below(n)       mask of the lanes k < n (n may be >= 8)
 *   sf8_quad_lanes_below(n)  mask of the lanes k with k mod 4 < n
 *   sf8_mask_bits(m)         bit k = lane k's sign bit (movemask)
 *   sf8_gather(base, idx)    lane k = base[idx[k]]; sf8_gather4 lane k = base[4 idx[k]]
 *   sf8_load_quad2(p)        the quad p[0..3] in lanes 0-3 and again in 4-7
 *   sf8_gather_quads(base, idx, c0..c3)
 *                            the quads at base + 4 idx[k] (such as sph_shared's
 *                            pq) transposed: cj lane k = base[4 idx[k] + j]
 *   sf8_sub_gather_quads(q, base, idx, c0..c3)
 *                            the same, each quad subtracted from q (made by
 *                            sf8_load_quad2) first: cj lane k = qj - base[4
 *                            idx[k] + j], the particle's own quad in one
 *                            register instead of four broadcasts
 *   sf8_load_quads(p, c0..c3)
 *                            eight consecutive quads transposed: cj lane k =
 *                            p[4 k + j]; sf8_store_quads(p, c0..c3) the inverse
 *   sf8_fold4(a, out)        out[l] = lane l + lane l + 4
 *   sf8_sum(a)               (f0 + f1) + (f2 + f3) of the fold
 *   sf8_pack(m, a, idx, out, out_idx)  see below
 * and one on indices, not lanes of an sf8:
 *   simd_widen16_add(b, o, idx)  idx[k] = b + o[k] for eight 16-bit o[k]
 *                            (16 bytes at o, unaligned): one 16-bit load,
 *                            widened, added (the SPH lists' packed groups)
 *   simd_narrow16_sub(idx, b, o)  its inverse: o[k] = the low 16 bits of
 *                            idx[k] - b
 *
 * One pass, several back-ends: a source file that includes this header
 * is compiled normally (SSE, or scalar in a SIMD=scalar build) and, on x86
 * unless SIMD=scalar, once more with -mavx2 -mbmi2 -DEDDY_SIMD_VARIANT
 * (the Makefile finds such files by the include), which compiles only its
 * kernels (the system glue is under #ifndef EDDY_SIMD_VARIANT). A kernel the
 * glue calls is named SIMD_NAME(x) (x_avx2 in the variant, x_base
 * otherwise; extern, so x carries the file's prefix), declared with
 * SIMD_DECLARE(ret, x, (params)) and picked at run time with SIMD_PICK(x),
 * which gives x_base unless the Makefile built the variant
 * (EDDY_SIMD_HAVE_AVX2). */
#ifndef EDDY_SIMD_H
#define EDDY_SIMD_H

#include <stdbool.h>
#include <math.h>
#include <stdint.h>
#include <string.h>

#if defined(__AVX2__)
#define SIMD_AVX2 1
#include <immintrin.h>
#elif defined(__SSE2__) && !defined(EDDY_SIMD_SCALAR)
#define SIMD_SSE 1
#include <emmintrin.h>
#else
#define SIMD_SCALAR 1
#endif

#ifdef EDDY_SIMD_VARIANT
#define SIMD_NAME(x) x##_avx2
#else
#define SIMD_NAME(x) x##_base
#endif
/* Both names' prototypes: params in parentheses, e.g.
 * SIMD_DECLARE(void, pair_sums, (const pair_args *a, long i0, long cnt)); */
#define SIMD_DECLARE(ret, x, params) \
	ret x##_base params;             \
	ret x##_avx2 params

#if defined(EDDY_SIMD_HAVE_AVX2) && !defined(EDDY_SIMD_VARIANT) && !defined(EDDY_SIMD_SCALAR) && defined(__GNUC__) && \
	(defined(__x86_64__) || defined(__i386__))
#include <stdlib.h>
/* The CPU has AVX2 and BMI2 (every AVX2 CPU from Haswell and Zen on has
 * both) and EDDY_NO_AVX2 is unset or empty. EDDY_NO_AVX2=1 takes the base
 * path on such a machine: the test that both give the same bits, and a way
 * around a suspect CPU. */
static inline bool simd_use_avx2(void)
{
	const char *off = getenv("EDDY_NO_AVX2");
	return __builtin_cpu_supports("avx2") && __builtin_cpu_supports("bmi2") && !(off && *off);
}
#define SIMD_PICK(x) (simd_use_avx2() ? x##_avx2 : x##_base)
#else
#define SIMD_PICK(x) x##_base
#endif

/* The two-operand operations whose intrinsics are named _mm_<op>_ps and
 * _mm256_<op>_ps. */
#define SIMD_NAMED_OPS_(X) X(add) X(sub) X(mul) X(div) X(max) X(min) X(and) X(or) X(xor) X(andnot)

/* Each back-end defines, besides the operations above, simd_quad_pair_(base,
 * a, b) (the quad at base + 4 a in lanes 0-3, at base + 4 b in 4-7), its
 * store simd_store_quad_pair_(base, a, b, v), and simd_transpose_(v0..v3,
 * c0..c3) (cj lane k = v(k mod 4) lane 4 (k / 4) + j: two 4x4 transposes side
 * by side, pure moves), on which the quad operations are built once below. */

/* ---- AVX2 ---------------------------------------------------------------- */
#ifdef SIMD_AVX2

typedef __m256 sf8;

#define SIMD_AVX2_OP_(op) \
	static inline sf8 sf8_##op(sf8 a, sf8 b) { return _mm256_##op##_ps(a, b); }
SIMD_NAMED_OPS_(SIMD_AVX2_OP_)
static inline sf8 sf8_lt(sf8 a, sf8 b) { return _mm256_cmp_ps(a, b, _CMP_LT_OQ); }
static inline sf8 sf8_gt(sf8 a, sf8 b) { return _mm256_cmp_ps(a, b, _CMP_GT_OQ); }
static inline sf8 sf8_le(sf8 a, sf8 b) { return _mm256_cmp_ps(a, b, _CMP_LE_OQ); }
static inline sf8 sf8_ge(sf8 a, sf8 b) { return _mm256_cmp_ps(a, b, _CMP_GE_OQ); }
static inline sf8 sf8_set1(float a) { return _mm256_set1_ps(a); }
static inline sf8 sf8_load(const float *p) { return _mm256_loadu_ps(p); }
static inline void sf8_store(float *p, sf8 a) { _mm256_storeu_ps(p, a); }
static inline sf8 sf8_sqrt(sf8 a) { return _mm256_sqrt_ps(a); }
static inline sf8 sf8_select(sf8 m, sf8 a, sf8 b) { return _mm256_blendv_ps(b, a, m); }
/* unsigned n > k as a signed compare of both with the sign bit flipped (no
 * clamp, no branch) */
static inline sf8 sf8_lanes_below(uint32_t n)
{
	const __m256i f = _mm256_set1_epi32(INT32_MIN);
	return _mm256_castsi256_ps(_mm256_cmpgt_epi32(_mm256_xor_si256(_mm256_set1_epi32((int32_t)n), f),
	                                              _mm256_xor_si256(_mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7), f)));
}
static inline int sf8_mask_bits(sf8 m) { return _mm256_movemask_ps(m); }
/* eight scalar loads: vgatherdps is slower on the CPUs at hand */
static inline sf8 sf8_gather(const float *base, const uint32_t idx[8])
{
	return _mm256_setr_ps(base[idx[0]], base[idx[1]], base[idx[2]], base[idx[3]], base[idx[4]], base[idx[5]],
	                      base[idx[6]], base[idx[7]]);
}
static inline void sf8_fold4(sf8 a, float out[4])
{
	_mm_storeu_ps(out, _mm_add_ps(_mm256_castps256_ps128(a), _mm256_extractf128_ps(a, 1)));
}
static inline void simd_widen16_add(uint32_t b, const void *o, uint32_t idx[8])
{
	const __m256i w = _mm256_cvtepu16_epi32(_mm_loadu_si128((const __m128i *)o));
	_mm256_storeu_si256((__m256i *)(void *)idx, _mm256_add_epi32(w, _mm256_set1_epi32((int32_t)b)));
}
static inline void simd_narrow16_sub(const uint32_t idx[8], uint32_t b, void *o)
{
	const __m256i d =
		_mm256_sub_epi32(_mm256_loadu_si256((const __m256i *)(const void *)idx), _mm256_set1_epi32((int32_t)b));
	/* each 32-bit lane's low half to the low 8 bytes of its 128-bit lane, then the two together */
	const __m256i lows = _mm256_setr_epi8(0, 1, 4, 5, 8, 9, 12, 13, -1, -1, -1, -1, -1, -1, -1, -1, 0, 1, 4, 5, 8, 9,
	                                      12, 13, -1, -1, -1, -1, -1, -1, -1, -1);
	const __m256i p = _mm256_permute4x64_epi64(_mm256_shuffle_epi8(d, lows), _MM_SHUFFLE(3, 1, 2, 0));
	_mm_storeu_si128((__m128i *)o, _mm256_castsi256_si128(p));
}
static inline sf8 simd_quad_pair_(const float *base, uint32_t a, uint32_t b)
{
	return _mm256_insertf128_ps(_mm256_castps128_ps256(_mm_loadu_ps(base + 4 * (size_t)a)),
	                            _mm_loadu_ps(base + 4 * (size_t)b), 1);
}
static inline void simd_store_quad_pair_(float *base, uint32_t a, uint32_t b, sf8 v)
{
	_mm_storeu_ps(base + 4 * (size_t)a, _mm256_castps256_ps128(v));
	_mm_storeu_ps(base + 4 * (size_t)b, _mm256_extractf128_ps(v, 1));
}
static inline void simd_transpose_(sf8 v0, sf8 v1, sf8 v2, sf8 v3, sf8 *c0, sf8 *c1, sf8 *c2, sf8 *c3)
{
	const __m256 t0 = _mm256_unpacklo_ps(v0, v1), t1 = _mm256_unpacklo_ps(v2, v3), t2 = _mm256_unpackhi_ps(v0, v1),
				 t3 = _mm256_unpackhi_ps(v2, v3);
	*c0 = _mm256_shuffle_ps(t0, t1, _MM_SHUFFLE(1, 0, 1, 0));
	*c1 = _mm256_shuffle_ps(t0, t1, _MM_SHUFFLE(3, 2, 3, 2));
	*c2 = _mm256_shuffle_ps(t2, t3, _MM_SHUFFLE(1, 0, 1, 0));
	*c3 = _mm256_shuffle_ps(t2, t3, _MM_SHUFFLE(3, 2, 3, 2));
}

/* ---- SSE: two halves ------------------------------------------------------ */
#elif defined(SIMD_SSE)

typedef struct sf8 {
	__m128 lo, hi;
} sf8;

static inline sf8 simd_halves_(__m128 lo, __m128 hi) { return (sf8){lo, hi}; }
#define SIMD_SSE_OP_(op, stem) \
	static inline sf8 sf8_##op(sf8 a, sf8 b) { return simd_halves_(stem(a.lo, b.lo), stem(a.hi, b.hi)); }
#define SIMD_SSE_NAMED_OP_(op) SIMD_SSE_OP_(op, _mm_##op##_ps)
SIMD_NAMED_OPS_(SIMD_SSE_NAMED_OP_)
SIMD_SSE_OP_(lt, _mm_cmplt_ps)
SIMD_SSE_OP_(gt, _mm_cmpgt_ps)
SIMD_SSE_OP_(le, _mm_cmple_ps)
SIMD_SSE_OP_(ge, _mm_cmpge_ps)
static inline sf8 sf8_set1(float a) { return simd_halves_(_mm_set1_ps(a), _mm_set1_ps(a)); }
static inline sf8 sf8_load(const float *p) { return simd_halves_(_mm_loadu_ps(p), _mm_loadu_ps(p + 4)); }
static inline void sf8_store(float *p, sf8 a)
{
	_mm_storeu_ps(p, a.lo);
	_mm_storeu_ps(p + 4, a.hi);
}
static inline sf8 sf8_sqrt(sf8 a) { return simd_halves_(_mm_sqrt_ps(a.lo), _mm_sqrt_ps(a.hi)); }
static inline sf8 sf8_lanes_below(uint32_t n)
{
	const __m128i f = _mm_set1_epi32(INT32_MIN), c = _mm_xor_si128(_mm_set1_epi32((int32_t)n), f);
	return simd_halves_(_mm_castsi128_ps(_mm_cmpgt_epi32(c, _mm_xor_si128(_mm_setr_epi32(0, 1, 2, 3), f))),
	                    _mm_castsi128_ps(_mm_cmpgt_epi32(c, _mm_xor_si128(_mm_setr_epi32(4, 5, 6, 7), f))));
}
static inline int sf8_mask_bits(sf8 m) { return _mm_movemask_ps(m.lo) | _mm_movemask_ps(m.hi) << 4; }
static inline sf8 sf8_gather(const float *base, const uint32_t idx[8])
{
	return simd_halves_(_mm_setr_ps(base[idx[0]], base[idx[1]], base[idx[2]], base[idx[3]]),
	                    _mm_setr_ps(base[idx[4]], base[idx[5]], base[idx[6]], base[idx[7]]));
}
static inline void sf8_fold4(sf8 a, float out[4]) { _mm_storeu_ps(out, _mm_add_ps(a.lo, a.hi)); }
static inline void simd_widen16_add(uint32_t b, const void *o, uint32_t idx[8])
{
	const __m128i v = _mm_loadu_si128((const __m128i *)o), zero = _mm_setzero_si128(), vb = _mm_set1_epi32((int32_t)b);
	_mm_storeu_si128((__m128i *)(void *)idx, _mm_add_epi32(_mm_unpacklo_epi16(v, zero), vb));
	_mm_storeu_si128((__m128i *)(void *)(idx + 4), _mm_add_epi32(_mm_unpackhi_epi16(v, zero), vb));
}
static inline void simd_narrow16_sub(const uint32_t idx[8], uint32_t b, void *o)
{
	const __m128i vb = _mm_set1_epi32((int32_t)b);
	__m128i lo = _mm_sub_epi32(_mm_loadu_si128((const __m128i *)(const void *)idx), vb);
	__m128i hi = _mm_sub_epi32(_mm_loadu_si128((const __m128i *)(const void *)(idx + 4)), vb);
	/* the low halves sign-extended, so that the saturating pack keeps them as they are */
	lo = _mm_srai_epi32(_mm_slli_epi32(lo, 16), 16);
	hi = _mm_srai_epi32(_mm_slli_epi32(hi, 16), 16);
	_mm_storeu_si128((__m128i *)o, _mm_packs_epi32(lo, hi));
}
static inline sf8 simd_quad_pair_(const float *base, uint32_t a, uint32_t b)
{
	return simd_halves_(_mm_loadu_ps(base + 4 * (size_t)a), _mm_loadu_ps(base + 4 * (size_t)b));
}
static inline void simd_store_quad_pair_(float *base, uint32_t a, uint32_t b, sf8 v)
{
	_mm_storeu_ps(base + 4 * (size_t)a, v.lo);
	_mm_storeu_ps(base + 4 * (size_t)b, v.hi);
}
static inline void simd_transpose_(sf8 v0, sf8 v1, sf8 v2, sf8 v3, sf8 *c0, sf8 *c1, sf8 *c2, sf8 *c3)
{
	_MM_TRANSPOSE4_PS(v0.lo, v1.lo, v2.lo, v3.lo);
	_MM_TRANSPOSE4_PS(v0.hi, v1.hi, v2.hi, v3.hi);
	*c0 = v0;
	*c1 = v1;
	*c2 = v2;
	*c3 = v3;
}

/* ---- scalar: plain loops over the lanes ----------------------------------- */
#else

typedef union sf8 {
	float l[8];
	uint32_t u[8]; /* the same lanes as bits: a mask lane is ~0u (a quiet NaN as a float) or 0 */
} sf8;

/* r's lanes (l as floats, u as bits) from a's and b's lanes k */
#define SIMD_SCALAR_OP_(name, lanes, expr)     \
	static inline sf8 sf8_##name(sf8 a, sf8 b) \
	{                                          \
		sf8 r;                                 \
		for (int k = 0; k < 8; ++k)            \
			r.lanes[k] = (expr);               \
		return r;                              \
	}

SIMD_SCALAR_OP_(add, l, a.l[k] + b.l[k])
SIMD_SCALAR_OP_(sub, l, a.l[k] - b.l[k])
SIMD_SCALAR_OP_(mul, l, a.l[k] * b.l[k])
SIMD_SCALAR_OP_(div, l, a.l[k] / b.l[k])
/* as maxps/minps: the second operand unless the first is strictly greater
 * (smaller), so b when either is NaN or both are zeros */
SIMD_SCALAR_OP_(max, l, a.l[k] > b.l[k] ? a.l[k] : b.l[k])
SIMD_SCALAR_OP_(min, l, a.l[k] < b.l[k] ? a.l[k] : b.l[k])
SIMD_SCALAR_OP_(lt, u, a.l[k] < b.l[k] ? ~0u : 0u)
SIMD_SCALAR_OP_(gt, u, a.l[k] > b.l[k] ? ~0u : 0u)
SIMD_SCALAR_OP_(le, u, a.l[k] <= b.l[k] ? ~0u : 0u)
SIMD_SCALAR_OP_(ge, u, a.l[k] >= b.l[k] ? ~0u : 0u)
SIMD_SCALAR_OP_(and, u, a.u[k] & b.u[k])
SIMD_SCALAR_OP_(or, u, a.u[k] | b.u[k])
SIMD_SCALAR_OP_(xor, u, a.u[k] ^ b.u[k])
SIMD_SCALAR_OP_(andnot, u, ~a.u[k] & b.u[k])
static inline sf8 sf8_set1(float a)
{
	sf8 r;
	for (int k = 0; k < 8; ++k)
		r.l[k] = a;
	return r;
}
static inline sf8 sf8_load(const float *p)
{
	sf8 r;
	memcpy(r.l, p, sizeof r.l);
	return r;
}
static inline void sf8_store(float *p, sf8 a) { memcpy(p, a.l, sizeof a.l); }
static inline sf8 sf8_sqrt(sf8 a)
{
	for (int k = 0; k < 8; ++k)
		a.l[k] = sqrtf(a.l[k]);
	return a;
}
static inline sf8 sf8_lanes_below(uint32_t n)
{
	sf8 r;
	for (uint32_t k = 0; k < 8; ++k)
		r.u[k] = k < n ? ~0u : 0u;
	return r;
}
static inline int sf8_mask_bits(sf8 m)
{
	int bits = 0;
	for (int k = 0; k < 8; ++k)
		bits |= (int)(m.u[k] >> 31) << k;
	return bits;
}
static inline sf8 sf8_gather(const float *base, const uint32_t idx[8])
{
	sf8 r;
	for (int k = 0; k < 8; ++k)
		r.l[k] = base[idx[k]];
	return r;
}
static inline void sf8_fold4(sf8 a, float out[4])
{
	for (int k = 0; k < 4; ++k)
		out[k] = a.l[k] + a.l[k + 4];
}
static inline void simd_widen16_add(uint32_t b, const void *o, uint32_t idx[8])
{
	uint16_t h[8];
	memcpy(h, o, sizeof h);
	for (int k = 0; k < 8; ++k)
		idx[k] = b + h[k];
}
static inline void simd_narrow16_sub(const uint32_t idx[8], uint32_t b, void *o)
{
	uint16_t h[8];
	for (int k = 0; k < 8; ++k)
		h[k] = (uint16_t)(idx[k] - b);
	memcpy(o, h, sizeof h);
}
static inline sf8 simd_quad_pair_(const float *base, uint32_t a, uint32_t b)
{
	sf8 r;
	memcpy(r.l, base + 4 * (size_t)a, 4 * sizeof(float));
	memcpy(r.l + 4, base + 4 * (size_t)b, 4 * sizeof(float));
	return r;
}
static inline void simd_store_quad_pair_(float *base, uint32_t a, uint32_t b, sf8 v)
{
	memcpy(base + 4 * (size_t)a, v.l, 4 * sizeof(float));
	memcpy(base + 4 * (size_t)b, v.l + 4, 4 * sizeof(float));
}
static inline void simd_transpose_(sf8 v0, sf8 v1, sf8 v2, sf8 v3, sf8 *c0, sf8 *c1, sf8 *c2, sf8 *c3)
{
	const sf8 v[4] = {v0, v1, v2, v3};
	sf8 *c[4] = {c0, c1, c2, c3};
	for (int j = 0; j < 4; ++j)
		for (int k = 0; k < 8; ++k)
			c[j]->l[k] = v[k & 3].l[(k & 4) + j];
}
#endif

/* ---- written once on the back-ends' operations ----------------------------- */

static inline sf8 sf8_zero(void) { return sf8_set1(0.0f); }

#ifndef SIMD_AVX2
static inline sf8 sf8_select(sf8 m, sf8 a, sf8 b) { return sf8_or(sf8_and(m, a), sf8_andnot(m, b)); }
#endif

static inline sf8 sf8_load_quad2(const float *p) { return simd_quad_pair_(p, 0, 0); }

static inline sf8 sf8_quad_lanes_below(int n)
{
	uint32_t bits[4];
	float quad[4];
	for (int k = 0; k < 4; ++k)
		bits[k] = k < n ? ~0u : 0u;
	memcpy(quad, bits, sizeof quad);
	return sf8_load_quad2(quad);
}

/* lane k = base[4 idx[k]] (idx[k] < 2^30): one member of each quad, such as pq's 1/rho (base = pq + 3) */
static inline sf8 sf8_gather4(const float *base, const uint32_t idx[8])
{
	uint32_t q[8];
	for (int k = 0; k < 8; ++k)
		q[k] = 4 * idx[k];
	return sf8_gather(base, q);
}

static inline void sf8_gather_quads(const float *base, const uint32_t idx[8], sf8 *c0, sf8 *c1, sf8 *c2, sf8 *c3)
{
	simd_transpose_(simd_quad_pair_(base, idx[0], idx[4]), simd_quad_pair_(base, idx[1], idx[5]),
	                simd_quad_pair_(base, idx[2], idx[6]), simd_quad_pair_(base, idx[3], idx[7]), c0, c1, c2, c3);
}

static inline void sf8_sub_gather_quads(sf8 q, const float *base, const uint32_t idx[8], sf8 *c0, sf8 *c1, sf8 *c2,
                                        sf8 *c3)
{
	simd_transpose_(sf8_sub(q, simd_quad_pair_(base, idx[0], idx[4])),
	                sf8_sub(q, simd_quad_pair_(base, idx[1], idx[5])),
	                sf8_sub(q, simd_quad_pair_(base, idx[2], idx[6])),
	                sf8_sub(q, simd_quad_pair_(base, idx[3], idx[7])), c0, c1, c2, c3);
}

static inline void sf8_load_quads(const float *p, sf8 *c0, sf8 *c1, sf8 *c2, sf8 *c3)
{
	simd_transpose_(simd_quad_pair_(p, 0, 4), simd_quad_pair_(p, 1, 5), simd_quad_pair_(p, 2, 6),
	                simd_quad_pair_(p, 3, 7), c0, c1, c2, c3);
}

/* the transpose is its own inverse */
static inline void sf8_store_quads(float *p, sf8 c0, sf8 c1, sf8 c2, sf8 c3)
{
	sf8 v0, v1, v2, v3;
	simd_transpose_(c0, c1, c2, c3, &v0, &v1, &v2, &v3);
	simd_store_quad_pair_(p, 0, 4, v0);
	simd_store_quad_pair_(p, 1, 5, v1);
	simd_store_quad_pair_(p, 2, 6, v2);
	simd_store_quad_pair_(p, 3, 7, v3);
}

static inline float sf8_sum(sf8 a)
{
	float f[4];
	sf8_fold4(a, f);
	return (f[0] + f[1]) + (f[2] + f[3]);
}

/* The lanes of a, and the same entries of idx[0..7], where mask m is set,
 * packed to the front of out and out_idx in lane order; all eight entries
 * of each may be written (the callers leave room). Returns how many.
 * Branch-free: which lanes are set is a coin toss in the neighbour search,
 * and a mispredicted branch costs more than writing every lane. AVX2 packs
 * with a permutation made from the mask (pdep/pext), the others write each
 * lane and move the count past the set ones: the same entries either way. */
#ifdef SIMD_AVX2
static inline uint32_t sf8_pack(sf8 m, sf8 a, const uint32_t idx[8], float *out, uint32_t *out_idx)
{
	const unsigned bits = (unsigned)_mm256_movemask_ps(m);
	const uint64_t keep = _pdep_u64(bits, 0x0101010101010101ull) * 0xFF; /* a byte of ones per lane kept */
	const __m256i perm = _mm256_cvtepu8_epi32(_mm_cvtsi64_si128((long long)_pext_u64(0x0706050403020100ull, keep)));
	_mm256_storeu_si256((__m256i *)(void *)out_idx,
	                    _mm256_permutevar8x32_epi32(_mm256_loadu_si256((const __m256i *)(const void *)idx), perm));
	_mm256_storeu_ps(out, _mm256_permutevar8x32_ps(a, perm));
	return (uint32_t)__builtin_popcount(bits);
}
#else
static inline uint32_t sf8_pack(sf8 m, sf8 a, const uint32_t idx[8], float *out, uint32_t *out_idx)
{
	const unsigned bits = (unsigned)sf8_mask_bits(m);
	float l[8];
	sf8_store(l, a);
	uint32_t cnt = 0;
	for (unsigned k = 0; k < 8; ++k) {
		out_idx[cnt] = idx[k];
		out[cnt] = l[k];
		cnt += bits >> k & 1;
	}
	return cnt;
}
#endif

#endif
