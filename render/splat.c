/* SPDX-License-Identifier: MIT */
/* CPU point sprites and lines: render_points' frames without GL.
 *
 * Reads an eddy_gl_scene (particles, their RGBA colours, lines); writes a
 * colour and depth buffer laid out as gl_osmesa.c's (RGBA, bottom row
 * first) and, optionally, the box-filtered RGB image.
 *
 * It draws what gl_osmesa.c's sprite and line programs draw, by the GL rules
 * llvmpipe follows, so the frames look the same (tests/test_render.c compares
 * the two images pixel by pixel):
 * - a particle is a point of size S = 2 r P11 (h/2) / w_clip at its window
 *   position (xw, yw) (GL 2.1 section 3.4, point sprites: every pixel whose
 *   centre lies in the S x S square around it), dropped when its centre is in
 *   front of the near or behind the far plane;
 * - per pixel, p = 2 (centre - (xw, yw)) / S; outside the unit disc nothing;
 *   else the sphere's normal n = (p, sqrt(1 - p.p)) in eye space, the surface
 *   point's eye depth z = z_c + r n_z, tested with LESS (GL tests the window
 *   depth 0.5 (a z + b) / (-z) + 0.5, a, b the projection's z row, / 1 when
 *   orthographic: a decreasing function of z between the near and far planes,
 *   so the distance -z orders fragments the same way; the buffer keeps it,
 *   cleared to the far plane's);
 *   colour = albedo (0.32 + 0.68 max(n.l, 0)) + 0.28 max(n.h, 0)^32, clamped;
 * - a line of width w is the parallelogram its segment sweeps when moved by
 *   +-w/2 across its major axis (llvmpipe's wide lines), depth linear along
 *   it in window space, clipped to the near and far planes first.
 * Not multisampled: render_points' supersampling and box filter are the
 * anti-aliasing, as with GL.
 *
 * A fragment is first tested with the sphere's nearest point (-z_c - r): when
 * that is not nearer than what the pixel holds, no point of the sphere there
 * is, and the square root and shading are skipped (most of a pool's spheres
 * are hidden behind its front layer). For that the particles are first
 * sorted near to far by their centres' distance, in SORT_BINS bins between
 * the nearest and the farthest (a stable counting sort: O(n), and the order
 * within a bin stays the particles' own, so the image is deterministic; only
 * exact depth ties can resolve differently from GL's draw order).
 *
 * The buffer is cut into square tiles of EDDY_SPLAT_TILE output pixels.
 * Before drawing, the particles are projected once (near to far) and every
 * tile a sprite's square or a line's pixel falls in is marked used: only used
 * tiles are cleared and box-filtered, the others are filled with the
 * background in the output directly (a frame's liquid covers a fraction of
 * it). Each used tile keeps the farthest depth it holds, recomputed when a
 * sprite has drawn into it: a sprite whose nearest point is not nearer than
 * that in any tile under its square is skipped whole, without looking at its
 * pixels (the same test as per pixel, so the same image). Where the CPU has
 * AVX2 a sprite's row is shaded eight pixels at a time, with the scalar
 * path's operations in its order (no fused multiply-add), so the bits are the
 * same (tests/test_render.c checks).
 *
 * Why not llvmpipe: measured on the shared 2-core machine, a pour frame
 * (5625 spheres at 1920x1080) cost about 55 ms of CPU through llvmpipe and
 * costs about 5 here (20 before the tiles and the AVX2 path), and a 1280x720 frame of 1M particles 0.7-1.35 s
 * against 0.33 s (tests/bench_render.c); llvmpipe's vertex stage is
 * single-threaded, and this loop is one projection per particle and a few
 * multiplies per covered pixel.
 *
 * Threads: the rows are split into bands (whole tile rows of the output),
 * and each band's thread walks every sprite in order and draws only its
 * rows, so every pixel sees the particles in the same order whatever the
 * thread count: the image is bit-identical for any count. */
#define _POSIX_C_SOURCE 200809L
#include "render.h"

#include <assert.h>
#include <math.h>
#include <pthread.h>
#include <stdbool.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define MAX_THREADS 64
#define SORT_BINS 4096

int eddy_splat_init(eddy_splat *s, int width, int height)
{
	memset(s, 0, sizeof *s);
	const size_t n = (size_t)width * (size_t)height;
	s->rgba = malloc(n * 4);
	s->depth = malloc(n * sizeof *s->depth);
	if (!s->rgba || !s->depth) {
		eddy_splat_free(s);
		return -1;
	}
	s->width = width;
	s->height = height;
	return 0;
}

void eddy_splat_free(eddy_splat *s)
{
	free(s->rgba);
	free(s->depth);
	free(s->sprites), free(s->unsorted), free(s->tile_used), free(s->tile_dirty), free(s->tile_far);
	memset(s, 0, sizeof *s);
}

static uint8_t unorm8(float v)
{
	v = v < 0 ? 0 : v > 1 ? 1 : v;
	return (uint8_t)(v * 255.0f + 0.5f);
}

typedef struct band {
	eddy_splat *s;
	const eddy_gl_scene *sc;
	float halfway[3];
	float far_key;   /* m, the far plane's distance */
	int r0, r1;      /* the buffer rows this band draws, bottom-up */
	int ss, y0, y1;  /* output rows (top-down) it filters */
	int tr0, tr1;    /* its tile rows (top-down): [r0, r1) is exactly theirs */
	int ts, tiles_x; /* tile side in buffer pixels, tiles per row */
	uint64_t ts_mul; /* ceil(2^32 / ts), for tile_div */
	uint8_t *out;
	uint8_t *mark; /* draw_lines: set the tiles the lines cover instead of drawing */
	bool avx2;     /* the CPU has AVX2: draw_sprites' eight-pixel path (the same bits) */
} band;

/* Buffer rows [*lo, *hi) of tile row tr (tile rows count from the top, so
 * they line up with the output's rows and the bands). */
static void tile_rows(const band *b, int tr, int *lo, int *hi)
{
	const int H = b->s->height;
	*lo = H - (tr + 1) * b->ts;
	*lo = *lo < 0 ? 0 : *lo;
	*hi = H - tr * b->ts;
}

/* x / ts for 0 <= x < 2^16 without a division: x ceil(2^32 / ts) / 2^32 is
 * x / ts plus less than x / 2^32 < 1 / ts, so its floor is exact. */
static int tile_div(const band *b, int x) { return (int)(((uint64_t)(uint32_t)x * b->ts_mul) >> 32); }

static int tile_row_of(const band *b, int j) { return tile_div(b, b->s->height - 1 - j); }

static uint8_t bg_byte(float v) { return unorm8(v); }

/* Clears the band's used tiles to the background and the far plane (the
 * others are never drawn in, and never read). */
static void clear_tiles(const band *b)
{
	const eddy_splat *s = b->s;
	const uint8_t bg[4] = {bg_byte(b->sc->background[0]), bg_byte(b->sc->background[1]), bg_byte(b->sc->background[2]),
	                       255};
	uint32_t bg32;
	memcpy(&bg32, bg, 4);
	const float far_key = b->far_key;
	for (int tr = b->tr0; tr < b->tr1; ++tr) {
		const uint8_t *used = s->tile_used + (size_t)tr * (size_t)b->tiles_x;
		int lo, hi;
		tile_rows(b, tr, &lo, &hi);
		for (int tx = 0; tx < b->tiles_x; ++tx) {
			if (!used[tx])
				continue;
			/* a run of used tiles: one span per row */
			int end = tx + 1;
			while (end < b->tiles_x && used[end])
				++end;
			const int i0 = tx * b->ts, i1 = end * b->ts < s->width ? end * b->ts : s->width;
			for (int j = lo; j < hi; ++j) {
				const size_t first = (size_t)j * (size_t)s->width + (size_t)i0, n = (size_t)(i1 - i0);
				/* restrict and a 32-bit pattern: plain stores the compiler vectorises */
				uint32_t *restrict c = (uint32_t *)(void *)(s->rgba + 4 * first);
				float *restrict d = s->depth + first;
				for (size_t i = 0; i < n; ++i)
					c[i] = bg32;
				for (size_t i = 0; i < n; ++i)
					d[i] = far_key;
			}
			for (int t = tx; t < end; ++t) {
				s->tile_far[(size_t)tr * (size_t)b->tiles_x + (size_t)t] = far_key;
				s->tile_dirty[(size_t)tr * (size_t)b->tiles_x + (size_t)t] = 0;
			}
			tx = end - 1;
		}
	}
}

/* The farthest depth tile (tx, tr) holds, recomputed after draws into it. */
static float tile_far(const band *b, int tx, int tr)
{
	eddy_splat *s = b->s;
	const size_t t = (size_t)tr * (size_t)b->tiles_x + (size_t)tx;
	if (s->tile_dirty[t]) {
		int lo, hi;
		tile_rows(b, tr, &lo, &hi);
		const int i0 = tx * b->ts, i1 = i0 + b->ts < s->width ? i0 + b->ts : s->width;
		/* eight running maxima: a max the compiler can vectorise */
		float m[8] = {-INFINITY, -INFINITY, -INFINITY, -INFINITY, -INFINITY, -INFINITY, -INFINITY, -INFINITY};
		for (int j = lo; j < hi; ++j) {
			const float *restrict d = s->depth + (size_t)j * (size_t)s->width;
			int i = i0;
			for (; i + 8 <= i1; i += 8)
				for (int l = 0; l < 8; ++l)
					m[l] = d[i + l] > m[l] ? d[i + l] : m[l];
			for (; i < i1; ++i)
				m[0] = d[i] > m[0] ? d[i] : m[0];
		}
		for (int l = 1; l < 8; ++l)
			m[0] = m[l] > m[0] ? m[l] : m[0];
		s->tile_far[t] = m[0];
		s->tile_dirty[t] = 0;
	}
	return s->tile_far[t];
}

/* One row of one sprite: what its pixels need. */
typedef struct sprite_row {
	float *drow;         /* the row's depths */
	uint8_t *crow;       /* its RGBA pixels */
	float xw, inv;       /* px, the centre; 2 / size */
	float py, py2;       /* the row's offset from the centre, in radii, and its square */
	float front, nez, r; /* m: the sphere's nearest distance, -z of its centre, its radius */
	float L[3], Hw[3];   /* the light and halfway directions */
	float pyL1, pyH1;    /* py L[1], py Hw[1] */
	float c[3];          /* the albedo */
} sprite_row;

/* Pixels [i0, i1) of a sprite's row, one at a time; true when one was drawn. */
static bool span_scalar(const sprite_row *q, int i0, int i1)
{
	float *drow = q->drow;
	bool wrote = false;
	for (int i = i0; i < i1; ++i) {
		if (!(q->front < drow[i]))
			continue;
		const float px = ((float)i + 0.5f - q->xw) * q->inv;
		const float r2 = px * px + q->py2;
		if (r2 > 1.0f)
			continue;
		const float nz = sqrtf(1.0f - r2);
		const float key = q->nez - q->r * nz;
		if (!(key < drow[i]))
			continue;
		drow[i] = key;
		wrote = true;
		const float dl = px * q->L[0] + q->pyL1 + nz * q->L[2];
		const float diffuse = dl > 0 ? dl : 0;
		const float dh = px * q->Hw[0] + q->pyH1 + nz * q->Hw[2];
		float spec = dh > 0 ? dh : 0;
		spec *= spec, spec *= spec, spec *= spec, spec *= spec, spec *= spec;
		const float shade = 0.32f + 0.68f * diffuse, hl = 0.28f * spec;
		uint8_t *o = q->crow + 4 * (size_t)i;
		o[0] = unorm8(q->c[0] * shade + hl);
		o[1] = unorm8(q->c[1] * shade + hl);
		o[2] = unorm8(q->c[2] * shade + hl);
		o[3] = 255;
	}
	return wrote;
}

#if defined(__x86_64__)
#include <immintrin.h>

/* The same, eight pixels at a time: the same operations in the same order on
 * each lane (no fused multiply-add: AVX2 alone), so the same bits. */
__attribute__((target("avx2"))) static __m256i unorm8_avx2(__m256 v)
{
	/* v < 0 ? 0 : v > 1 ? 1 : v, then v 255 + 0.5 truncated */
	v = _mm256_min_ps(_mm256_max_ps(v, _mm256_setzero_ps()), _mm256_set1_ps(1.0f));
	return _mm256_cvttps_epi32(_mm256_add_ps(_mm256_mul_ps(v, _mm256_set1_ps(255.0f)), _mm256_set1_ps(0.5f)));
}

/* The sprite row's constants, broadcast. */
typedef struct row8 {
	__m256 front, xw, inv, py2, nez, r, L0, L2, pyL1, H0, H2, pyH1, cr, cg, cb;
} row8;

/* Eight pixels from dp and cp (only the lanes set in `lanes` when tail):
 * whether any was drawn. */
__attribute__((target("avx2"), always_inline)) static inline bool pixels8(const row8 *k, float *dp, uint8_t *cp,
                                                                          float x, bool tail, __m256i lanes)
{
	const __m256 zero = _mm256_setzero_ps(), one = _mm256_set1_ps(1.0f);
	const __m256 d = tail ? _mm256_maskload_ps(dp, lanes) : _mm256_loadu_ps(dp);
	__m256 ahead = _mm256_cmp_ps(k->front, d, _CMP_LT_OQ);
	if (tail)
		ahead = _mm256_and_ps(ahead, _mm256_castsi256_ps(lanes));
	if (!_mm256_movemask_ps(ahead))
		return false;
	const __m256 lane = _mm256_setr_ps(0.0f, 1.0f, 2.0f, 3.0f, 4.0f, 5.0f, 6.0f, 7.0f);
	const __m256 px = _mm256_mul_ps(
		_mm256_sub_ps(_mm256_add_ps(_mm256_add_ps(_mm256_set1_ps(x), lane), _mm256_set1_ps(0.5f)), k->xw), k->inv);
	const __m256 r2 = _mm256_add_ps(_mm256_mul_ps(px, px), k->py2);
	const __m256 nz = _mm256_sqrt_ps(_mm256_max_ps(_mm256_sub_ps(one, r2), zero));
	const __m256 key = _mm256_sub_ps(k->nez, _mm256_mul_ps(k->r, nz));
	const __m256 m =
		_mm256_and_ps(_mm256_and_ps(ahead, _mm256_cmp_ps(r2, one, _CMP_LE_OQ)), _mm256_cmp_ps(key, d, _CMP_LT_OQ));
	if (!_mm256_movemask_ps(m))
		return false;
	const __m256 dl = _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(px, k->L0), k->pyL1), _mm256_mul_ps(nz, k->L2));
	const __m256 dh = _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(px, k->H0), k->pyH1), _mm256_mul_ps(nz, k->H2));
	/* max(x, 0) is x > 0 ? x : 0, as the scalar code */
	const __m256 diffuse = _mm256_max_ps(dl, zero);
	__m256 spec = _mm256_max_ps(dh, zero);
	for (int e = 0; e < 5; ++e)
		spec = _mm256_mul_ps(spec, spec);
	const __m256 shade = _mm256_add_ps(_mm256_set1_ps(0.32f), _mm256_mul_ps(_mm256_set1_ps(0.68f), diffuse));
	const __m256 hl = _mm256_mul_ps(_mm256_set1_ps(0.28f), spec);
	const __m256i R = unorm8_avx2(_mm256_add_ps(_mm256_mul_ps(k->cr, shade), hl));
	const __m256i G = unorm8_avx2(_mm256_add_ps(_mm256_mul_ps(k->cg, shade), hl));
	const __m256i B = unorm8_avx2(_mm256_add_ps(_mm256_mul_ps(k->cb, shade), hl));
	const __m256i rgba =
		_mm256_or_si256(_mm256_or_si256(R, _mm256_slli_epi32(G, 8)),
	                    _mm256_or_si256(_mm256_slli_epi32(B, 16), _mm256_set1_epi32((int)0xff000000u)));
	if (tail) {
		_mm256_maskstore_ps(dp, _mm256_castps_si256(m), key);
		_mm256_maskstore_epi32((int *)(void *)cp, _mm256_castps_si256(m), rgba);
	} else {
		_mm256_storeu_ps(dp, _mm256_blendv_ps(d, key, m));
		__m256i *c = (__m256i *)(void *)cp;
		const __m256i old = _mm256_loadu_si256(c);
		_mm256_storeu_si256(
			c, _mm256_castps_si256(_mm256_blendv_ps(_mm256_castsi256_ps(old), _mm256_castsi256_ps(rgba), m)));
	}
	return true;
}

__attribute__((target("avx2"))) static bool span_avx2(const sprite_row *q, int i0, int i1)
{
	const row8 k = {_mm256_set1_ps(q->front), _mm256_set1_ps(q->xw),    _mm256_set1_ps(q->inv),
	                _mm256_set1_ps(q->py2),   _mm256_set1_ps(q->nez),   _mm256_set1_ps(q->r),
	                _mm256_set1_ps(q->L[0]),  _mm256_set1_ps(q->L[2]),  _mm256_set1_ps(q->pyL1),
	                _mm256_set1_ps(q->Hw[0]), _mm256_set1_ps(q->Hw[2]), _mm256_set1_ps(q->pyH1),
	                _mm256_set1_ps(q->c[0]),  _mm256_set1_ps(q->c[1]),  _mm256_set1_ps(q->c[2])};
	const __m256i all = _mm256_set1_epi32(-1);
	bool wrote = false;
	int i = i0;
	for (; i + 8 <= i1; i += 8)
		wrote |= pixels8(&k, q->drow + i, q->crow + 4 * (size_t)i, (float)i, false, all);
	if (i < i1) {
		/* the last 1-7 pixels: masked loads and stores, nothing past i1 touched */
		const __m256i lanes = _mm256_cmpgt_epi32(_mm256_set1_epi32(i1 - i), _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7));
		wrote |= pixels8(&k, q->drow + i, q->crow + 4 * (size_t)i, (float)i, true, lanes);
	}
	return wrote;
}
#endif

static void draw_sprites(const band *b)
{
	const eddy_gl_scene *sc = b->sc;
	eddy_splat *s = b->s;
	const float *L = sc->light, *Hw = b->halfway;
	const float r = sc->radius;
	const int r0 = b->r0, r1 = b->r1, width = s->width;
	for (size_t k = 0; k < s->sprite_count; ++k) {
		const eddy_splat_sprite *sp = &s->sprites[k];
		const float xw = sp->xw, yw = sp->yw, size = sp->size;
		const float half = 0.5f * size;
		/* pixel j is covered when yw - half <= j + 0.5 < yw + half */
		int j0 = (int)ceilf(yw - half - 0.5f), j1 = (int)ceilf(yw + half - 0.5f);
		if (j1 <= r0 || j0 >= r1)
			continue;
		int i0 = (int)ceilf(xw - half - 0.5f), i1 = (int)ceilf(xw + half - 0.5f);
		i0 = i0 < 0 ? 0 : i0;
		i1 = i1 > width ? width : i1;
		j0 = j0 < r0 ? r0 : j0;
		j1 = j1 > r1 ? r1 : j1;
		if (i0 >= i1)
			continue;
		const float front = -sp->ez - r; /* the sphere's nearest distance */
		/* when no tile under the square holds anything farther than the
		 * sphere's front, no pixel of it passes the depth test: skip it
		 * whole (most of a pool's spheres are behind its front layer). Not
		 * asked for squares under half a tile wide: finding a tile's
		 * farthest depth costs more than their pixels' own tests. */
		const int tx0 = tile_div(b, i0), tx1 = tile_div(b, i1 - 1);
		const int ty0 = tile_row_of(b, j1 - 1), ty1 = tile_row_of(b, j0);
		bool open = 2 * (i1 - i0) < b->ts;
		for (int ty = ty0; ty <= ty1 && !open; ++ty)
			for (int tx = tx0; tx <= tx1 && !open; ++tx)
				open = front < tile_far(b, tx, ty);
		if (!open)
			continue;
		sprite_row q;
		q.xw = xw, q.inv = 2.0f / size;
		q.front = front, q.nez = -sp->ez, q.r = r;
		for (int c = 0; c < 3; ++c) {
			q.L[c] = L[c], q.Hw[c] = Hw[c];
			q.c[c] = sp->rgba[c] * (1.0f / 255);
		}
		bool wrote = false;
		for (int j = j0; j < j1; ++j) {
			q.py = ((float)j + 0.5f - yw) * q.inv;
			q.py2 = q.py * q.py;
			if (q.py2 > 1.0f)
				continue;
			q.pyL1 = q.py * L[1], q.pyH1 = q.py * Hw[1];
			q.drow = s->depth + (size_t)j * (size_t)width;
			q.crow = s->rgba + (size_t)j * (size_t)width * 4;
			/* the disc's chord on this row, |i + 0.5 - xw| <= half sqrt(1 - py^2),
			 * a pixel wider each side than rounding could make it: the
			 * pixels' own test still decides, so only pixels it would turn
			 * down are left out */
			const float chord = half * sqrtf(1.0f - q.py2);
			int a = (int)floorf(xw - 0.5f - chord) - 1, e = (int)ceilf(xw - 0.5f + chord) + 2;
			a = a < i0 ? i0 : a;
			e = e > i1 ? i1 : e;
#if defined(__x86_64__)
			if (b->avx2 && e - a >= 8) { /* narrower rows: cheaper one pixel at a time */
				wrote |= span_avx2(&q, a, e);
				continue;
			}
#endif
			/* the whole row hidden: one vectorised pass instead of a branch per pixel */
			int row_open = 0;
			for (int i = a; i < e; ++i)
				row_open |= front < q.drow[i];
			if (row_open)
				wrote |= span_scalar(&q, a, e);
		}
		if (wrote)
			for (int ty = ty0; ty <= ty1; ++ty)
				for (int tx = tx0; tx <= tx1; ++tx) /* a few: no memset call */
					s->tile_dirty[(size_t)ty * (size_t)b->tiles_x + (size_t)tx] = 1;
	}
}

/* Clips the segment to -w <= z <= w (and w > 0); 0 when nothing is left. */
static int clip_near_far(float c0[4], float c1[4])
{
	for (int plane = 0; plane < 2; ++plane) {
		/* inside when d >= 0: d = w + z (near) or w - z (far) */
		const float sgn = plane == 0 ? 1.0f : -1.0f;
		const float d0 = c0[3] + sgn * c0[2], d1 = c1[3] + sgn * c1[2];
		if (d0 < 0 && d1 < 0)
			return 0;
		if (d0 < 0 || d1 < 0) {
			const float t = d0 / (d0 - d1);
			float *out = d0 < 0 ? c0 : c1;
			float m[4];
			for (int k = 0; k < 4; ++k)
				m[k] = c0[k] + t * (c1[k] - c0[k]);
			memcpy(out, m, sizeof m);
		}
	}
	return c0[3] > 0 && c1[3] > 0;
}

static void draw_lines(const band *b)
{
	const eddy_gl_scene *sc = b->sc;
	eddy_splat *s = b->s;
	const float *v = sc->view, *p = sc->proj;
	const float W = (float)s->width, H = (float)s->height;
	const float pa = p[10], pb = p[14];
	const int ortho = p[15] != 0;
	for (int set = 0; set < sc->line_sets; ++set) {
		const eddy_gl_lines *l = &sc->lines[set];
		const uint8_t col[4] = {unorm8(l->rgb[0]), unorm8(l->rgb[1]), unorm8(l->rgb[2]), 255};
		const float hw = 0.5f * l->width;
		for (size_t g = 0; g < l->segments; ++g) {
			float c[2][4];
			for (int e = 0; e < 2; ++e) {
				const float *q = l->xyz + 6 * g + 3 * e;
				float eye[4];
				for (int r = 0; r < 4; ++r)
					eye[r] = v[r] * q[0] + v[4 + r] * q[1] + v[8 + r] * q[2] + v[12 + r];
				for (int r = 0; r < 4; ++r)
					c[e][r] = p[r] * eye[0] + p[4 + r] * eye[1] + p[8 + r] * eye[2] + p[12 + r] * eye[3];
			}
			if (!clip_near_far(c[0], c[1]))
				continue;
			float wx[2], wy[2], wz[2];
			for (int e = 0; e < 2; ++e) {
				wx[e] = (c[e][0] / c[e][3] + 1.0f) * 0.5f * W;
				wy[e] = (c[e][1] / c[e][3] + 1.0f) * 0.5f * H;
				wz[e] = c[e][2] / c[e][3]; /* z_ndc, linear along the line on screen */
			}
			const float dx = wx[1] - wx[0], dy = wy[1] - wy[0];
			const int xmajor = fabsf(dx) >= fabsf(dy);
			/* u along the major axis, w across it */
			const float u0 = xmajor ? wx[0] : wy[0], u1 = xmajor ? wx[1] : wy[1];
			const float w0 = xmajor ? wy[0] : wx[0], w1 = xmajor ? wy[1] : wx[1];
			const float du = u1 - u0;
			if (du == 0)
				continue;
			const float ulo = fminf(u0, u1), uhi = fmaxf(u0, u1);
			int k0 = (int)ceilf(ulo - 0.5f), k1 = (int)ceilf(uhi - 0.5f);
			const int ulim = xmajor ? s->width : s->height;
			k0 = k0 < 0 ? 0 : k0;
			k1 = k1 > ulim ? ulim : k1;
			for (int k = k0; k < k1; ++k) {
				const float t = ((float)k + 0.5f - u0) / du;
				const float wc = w0 + t * (w1 - w0), zn = wz[0] + t * (wz[1] - wz[0]);
				/* back to the distance: z_ndc = (a z + b) / (-z), or a z + b */
				const float z = ortho ? (pb - zn) / pa : pb / (zn + pa);
				int m0 = (int)ceilf(wc - hw - 0.5f), m1 = (int)ceilf(wc + hw - 0.5f);
				const int wlo = xmajor ? b->r0 : 0, whi = xmajor ? b->r1 : s->width;
				m0 = m0 < wlo ? wlo : m0;
				m1 = m1 > whi ? whi : m1;
				for (int m = m0; m < m1; ++m) {
					const int i = xmajor ? k : m, j = xmajor ? m : k;
					if (j < b->r0 || j >= b->r1)
						continue;
					if (b->mark) {
						b->mark[(size_t)tile_row_of(b, j) * (size_t)b->tiles_x + (size_t)tile_div(b, i)] = 1;
						continue;
					}
					const size_t at = (size_t)j * (size_t)s->width + (size_t)i;
					if (!(z < s->depth[at]))
						continue;
					s->depth[at] = z;
					memcpy(s->rgba + 4 * at, col, 4);
				}
			}
		}
	}
}

/* Box-filters the band's used tiles into out and fills the others with the
 * background (what the filter gives for a tile of it: the mean of equal
 * bytes is that byte). */
static void filter_tiles(const band *b)
{
	const eddy_splat *s = b->s;
	const int W = s->width / b->ss, H = s->height / b->ss;
	const uint8_t bg[3] = {bg_byte(b->sc->background[0]), bg_byte(b->sc->background[1]), bg_byte(b->sc->background[2])};
	for (int tr = b->tr0; tr < b->tr1; ++tr) {
		const uint8_t *used = s->tile_used + (size_t)tr * (size_t)b->tiles_x;
		const int ya = tr * EDDY_SPLAT_TILE, yb = ya + EDDY_SPLAT_TILE < H ? ya + EDDY_SPLAT_TILE : H;
		for (int tx = 0; tx < b->tiles_x;) {
			int end = tx + 1;
			while (end < b->tiles_x && used[end] == used[tx])
				++end;
			const int xa = tx * EDDY_SPLAT_TILE, xb = end * EDDY_SPLAT_TILE < W ? end * EDDY_SPLAT_TILE : W;
			if (used[tx])
				eddy_downsample_block(s->rgba, W, H, b->ss, b->out, ya, yb, xa, xb);
			else
				for (int y = ya; y < yb; ++y) {
					uint8_t *o = b->out + ((size_t)y * (size_t)W + (size_t)xa) * 3;
					for (int x = xa; x < xb; ++x, o += 3)
						o[0] = bg[0], o[1] = bg[1], o[2] = bg[2];
				}
			tx = end;
		}
	}
}

static void *band_main(void *arg)
{
	band *b = arg;
	clear_tiles(b);
	draw_sprites(b);
	draw_lines(b);
	if (b->out)
		filter_tiles(b);
	return NULL;
}

/* The sort's bin of a centre at eye z ez: NaN and out-of-range distances go last. */
static uint32_t bin_of(float ez, float lo, float scale)
{
	const float f = (-ez - lo) * scale;
	return f >= 0 && f <= (float)(SORT_BINS - 1) ? (uint32_t)f : SORT_BINS - 1;
}

/* Projects the particles, marks the tiles their squares cover and sorts
 * those that reach the buffer near to far into s->sprites (room for
 * sc->count made by the caller, there and in s->unsorted): a stable counting
 * sort on SORT_BINS bins of the centres' distance between the nearest and the
 * farthest particle. */
static void project_and_sort(eddy_splat *s, const eddy_gl_scene *sc, const band *b)
{
	const float *v = sc->view, *p = sc->proj;
	const float W = (float)s->width, H = (float)s->height;
	const float size_k = 2.0f * sc->radius * p[5] * (0.5f * H);
	eddy_splat_sprite *tmp = s->unsorted;
	float lo = INFINITY, hi = -INFINITY;
	for (size_t k = 0; k < sc->count; ++k) {
		const float x = sc->x[k], y = sc->y[k], z = sc->z[k];
		const float ex = v[0] * x + v[4] * y + v[8] * z + v[12];
		const float ey = v[1] * x + v[5] * y + v[9] * z + v[13];
		const float ez = v[2] * x + v[6] * y + v[10] * z + v[14];
		/* the sort's range: every particle's distance, drawn or not */
		const float dist = -ez;
		lo = dist < lo ? dist : lo;
		hi = dist > hi ? dist : hi;
		eddy_splat_sprite *o = &tmp[k];
		o->size = 0; /* not drawn */
		const float cw = p[3] * ex + p[7] * ey + p[11] * ez + p[15];
		const float cz = p[2] * ex + p[6] * ey + p[10] * ez + p[14];
		if (!(cw > 0) || !(cz >= -cw && cz <= cw))
			continue; /* the centre is outside the near or far plane (or not a number) */
		const float cy = p[1] * ex + p[5] * ey + p[9] * ez + p[13];
		const float yw = (cy / cw + 1.0f) * 0.5f * H;
		float size = size_k / cw;
		size = size < 1.0f ? 1.0f : size;
		const float half = 0.5f * size;
		/* pixel j is covered when yw - half <= j + 0.5 < yw + half */
		int j0 = (int)ceilf(yw - half - 0.5f), j1 = (int)ceilf(yw + half - 0.5f);
		if (j1 <= 0 || j0 >= s->height)
			continue;
		const float cx = p[0] * ex + p[4] * ey + p[8] * ez + p[12];
		const float xw = (cx / cw + 1.0f) * 0.5f * W;
		int i0 = (int)ceilf(xw - half - 0.5f), i1 = (int)ceilf(xw + half - 0.5f);
		i0 = i0 < 0 ? 0 : i0;
		i1 = i1 > s->width ? s->width : i1;
		j0 = j0 < 0 ? 0 : j0;
		j1 = j1 > s->height ? s->height : j1;
		if (i0 >= i1)
			continue;
		o->xw = xw, o->yw = yw, o->size = size, o->ez = ez;
		memcpy(o->rgba, sc->rgb + 4 * k, 4);
		const int tx0 = tile_div(b, i0), tx1 = tile_div(b, i1 - 1);
		for (int ty = tile_row_of(b, j1 - 1); ty <= tile_row_of(b, j0); ++ty)
			for (int tx = tx0; tx <= tx1; ++tx) /* a few: no memset call */
				s->tile_used[(size_t)ty * (size_t)b->tiles_x + (size_t)tx] = 1;
	}
	const float scale = hi > lo ? (float)(SORT_BINS - 1) / (hi - lo) : 0.0f;
	static_assert(SORT_BINS <= 65536, "bins fit the counts below");
	size_t count[SORT_BINS + 1];
	memset(count, 0, sizeof count);
	for (size_t k = 0; k < sc->count; ++k)
		if (tmp[k].size > 0)
			count[bin_of(tmp[k].ez, lo, scale) + 1]++;
	for (int bin = 0; bin < SORT_BINS; ++bin)
		count[bin + 1] += count[bin];
	for (size_t k = 0; k < sc->count; ++k)
		if (tmp[k].size > 0)
			s->sprites[count[bin_of(tmp[k].ez, lo, scale)]++] = tmp[k];
	s->sprite_count = count[SORT_BINS];
}

/* Room for n sprites and the tiles; false when out of memory. */
static bool reserve_frame(eddy_splat *s, size_t n, size_t tiles)
{
	if (n > s->sprite_cap) {
		const size_t c = n + n / 4;
		eddy_splat_sprite *p = realloc(s->sprites, c * sizeof *p);
		if (p)
			s->sprites = p;
		eddy_splat_sprite *q = realloc(s->unsorted, c * sizeof *q);
		if (q)
			s->unsorted = q;
		if (!p || !q)
			return false;
		s->sprite_cap = c;
	}
	if (tiles > s->tile_cap) {
		uint8_t *u = realloc(s->tile_used, tiles);
		if (u)
			s->tile_used = u;
		uint8_t *d = realloc(s->tile_dirty, tiles);
		if (d)
			s->tile_dirty = d;
		float *f = realloc(s->tile_far, tiles * sizeof *f);
		if (f)
			s->tile_far = f;
		if (!u || !d || !f)
			return false;
		s->tile_cap = tiles;
	}
	return true;
}

int eddy_splat_draw(eddy_splat *s, const eddy_gl_scene *sc_in, int threads, int ss, uint8_t *out, char *err, size_t cap)
{
	const eddy_gl_scene *sc = sc_in;
	if (sc->mesh_sets > 0) {
		snprintf(err, cap, "the CPU renderer draws particles and lines only, not meshes");
		return -1;
	}
	if (ss < 1 || s->width % ss || s->height % ss) {
		snprintf(err, cap, "a %dx%d buffer cannot be filtered by %d", s->width, s->height, ss);
		return -1;
	}
	const int H = s->height / ss; /* output rows */
	const int ts = EDDY_SPLAT_TILE * ss;
	const int tiles_x = (s->width + ts - 1) / ts, tiles_y = (s->height + ts - 1) / ts;
	const size_t tiles = (size_t)tiles_x * (size_t)tiles_y;
	if (!reserve_frame(s, sc->count, tiles)) {
		snprintf(err, cap, "out of memory for %zu sprites", sc->count);
		return -1;
	}
	threads = threads < 1 ? 1 : threads > MAX_THREADS ? MAX_THREADS : threads;
	threads = threads > tiles_y ? tiles_y : threads;
	band bands[MAX_THREADS];
	const float h[3] = {sc->light[0], sc->light[1], sc->light[2] + 1.0f};
	const float hl = sqrtf(h[0] * h[0] + h[1] * h[1] + h[2] * h[2]);
	/* the far plane's distance: z_ndc = 1 */
	const float pa = sc->proj[10], pb = sc->proj[14];
	const float far_key = sc->proj[15] != 0 ? (pb - 1.0f) / pa : pb / (1.0f + pa);
	for (int t = 0; t < threads; ++t) {
		band *b = &bands[t];
		memset(b, 0, sizeof *b);
		b->far_key = far_key;
		b->s = s;
		b->sc = sc;
		for (int k = 0; k < 3; ++k)
			b->halfway[k] = h[k] / hl;
		b->ss = ss;
		b->out = out;
		b->ts = ts;
		b->ts_mul = 0xffffffffu / (uint32_t)ts + 1;
		b->tiles_x = tiles_x;
#if defined(__x86_64__)
		b->avx2 = !s->scalar && __builtin_cpu_supports("avx2");
#endif
		/* whole tile rows per band, so a tile is one thread's */
		b->tr0 = (int)((long)tiles_y * t / threads);
		b->tr1 = (int)((long)tiles_y * (t + 1) / threads);
		b->y0 = b->tr0 * EDDY_SPLAT_TILE;
		b->y1 = b->tr1 * EDDY_SPLAT_TILE < H ? b->tr1 * EDDY_SPLAT_TILE : H;
		/* output rows [y0, y1) from the top are buffer rows [H - y1, H - y0) * ss from the bottom */
		b->r0 = (H - b->y1) * ss;
		b->r1 = (H - b->y0) * ss;
	}
	/* which tiles anything is drawn in: the sprites' squares and the lines'
	 * pixels (all of them without an output image, whose caller reads the
	 * whole buffer) */
	memset(s->tile_used, out ? 0 : 1, tiles);
	s->sprite_count = 0;
	band whole = bands[0];
	whole.r0 = 0, whole.r1 = s->height;
	if (sc->count > 0)
		project_and_sort(s, sc, &whole);
	whole.mark = s->tile_used;
	draw_lines(&whole);
	pthread_t tid[MAX_THREADS];
	int started = 1;
	for (int t = 1; t < threads; ++t, ++started)
		if (pthread_create(&tid[t], NULL, band_main, &bands[t]) != 0)
			break;
	/* bands whose thread could not start are drawn here: same pixels, later */
	band_main(&bands[0]);
	for (int t = started; t < threads; ++t)
		band_main(&bands[t]);
	for (int t = 1; t < started; ++t)
		pthread_join(tid[t], NULL);
	return 0;
}
