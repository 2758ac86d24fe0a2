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
 * Why not llvmpipe: measured on the shared 2-core machine, a pour frame
 * (5625 spheres at 1920x1080) cost about 55 ms of CPU through llvmpipe and
 * costs about 20 here, and a 1280x720 frame of 1M particles 0.7-1.35 s
 * against 0.33 s (tests/bench_render.c); llvmpipe's vertex stage is
 * single-threaded, and this loop is one projection per particle and a few
 * multiplies per covered pixel.
 *
 * Threads: the rows are split into bands (whole supersample rows of the
 * output), and each band's thread walks every particle in order and draws
 * only its rows, so every pixel sees the particles in the same order whatever
 * the thread count: the image is bit-identical for any count. */
#define _POSIX_C_SOURCE 200809L
#include "render.h"

#include <assert.h>
#include <math.h>
#include <pthread.h>
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
	free(s->sx), free(s->sy), free(s->sz), free(s->srgb), free(s->bin);
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
	float far_key;  /* m, the far plane's distance */
	int r0, r1;     /* the buffer rows this band draws, bottom-up */
	int ss, y0, y1; /* output rows (top-down) it filters */
	uint8_t *out;
} band;

static void clear_rows(const band *b)
{
	const eddy_splat *s = b->s;
	const uint8_t bg[4] = {unorm8(b->sc->background[0]), unorm8(b->sc->background[1]), unorm8(b->sc->background[2]),
	                       255};
	uint32_t bg32;
	memcpy(&bg32, bg, 4);
	const size_t first = (size_t)b->r0 * (size_t)s->width, n = (size_t)(b->r1 - b->r0) * (size_t)s->width;
	/* restrict and a 32-bit pattern: plain stores the compiler vectorises */
	uint32_t *restrict c = (uint32_t *)(void *)(s->rgba + 4 * first);
	float *restrict d = s->depth + first;
	const float far_key = b->far_key;
	for (size_t i = 0; i < n; ++i)
		c[i] = bg32;
	for (size_t i = 0; i < n; ++i)
		d[i] = far_key;
}

static void draw_sprites(const band *b)
{
	const eddy_gl_scene *sc = b->sc;
	eddy_splat *s = b->s;
	const float *v = sc->view, *p = sc->proj;
	const float W = (float)s->width, H = (float)s->height;
	const float size_k = 2.0f * sc->radius * p[5] * (0.5f * H);
	const float *L = sc->light, *Hw = b->halfway;
	const float r = sc->radius;
	const int r0 = b->r0, r1 = b->r1, width = s->width;
	for (size_t k = 0; k < sc->count; ++k) {
		const float x = sc->x[k], y = sc->y[k], z = sc->z[k];
		const float ex = v[0] * x + v[4] * y + v[8] * z + v[12];
		const float ey = v[1] * x + v[5] * y + v[9] * z + v[13];
		const float ez = v[2] * x + v[6] * y + v[10] * z + v[14];
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
		if (j1 <= r0 || j0 >= r1)
			continue;
		const float cx = p[0] * ex + p[4] * ey + p[8] * ez + p[12];
		const float xw = (cx / cw + 1.0f) * 0.5f * W;
		int i0 = (int)ceilf(xw - half - 0.5f), i1 = (int)ceilf(xw + half - 0.5f);
		i0 = i0 < 0 ? 0 : i0;
		i1 = i1 > width ? width : i1;
		j0 = j0 < r0 ? r0 : j0;
		j1 = j1 > r1 ? r1 : j1;
		const float inv = 2.0f / size;
		const float front = -ez - r; /* the sphere's nearest distance */
		const uint8_t *c8 = sc->rgb + 4 * k;
		const float cr = c8[0] * (1.0f / 255), cg = c8[1] * (1.0f / 255), cb = c8[2] * (1.0f / 255);
		for (int j = j0; j < j1; ++j) {
			const float py = ((float)j + 0.5f - yw) * inv;
			const float py2 = py * py;
			if (py2 > 1.0f)
				continue;
			float *drow = s->depth + (size_t)j * (size_t)width;
			uint8_t *crow = s->rgba + (size_t)j * (size_t)width * 4;
			/* the whole row hidden (the common case behind a pool's front
			 * layer): one vectorised pass instead of a branch per pixel */
			int open = 0;
			for (int i = i0; i < i1; ++i)
				open |= front < drow[i];
			if (!open)
				continue;
			for (int i = i0; i < i1; ++i) {
				if (!(front < drow[i]))
					continue;
				const float px = ((float)i + 0.5f - xw) * inv;
				const float r2 = px * px + py2;
				if (r2 > 1.0f)
					continue;
				const float nz = sqrtf(1.0f - r2);
				const float key = -ez - r * nz;
				if (!(key < drow[i]))
					continue;
				drow[i] = key;
				const float dl = px * L[0] + py * L[1] + nz * L[2];
				const float diffuse = dl > 0 ? dl : 0;
				const float dh = px * Hw[0] + py * Hw[1] + nz * Hw[2];
				float sp = dh > 0 ? dh : 0;
				sp *= sp, sp *= sp, sp *= sp, sp *= sp, sp *= sp;
				const float shade = 0.32f + 0.68f * diffuse, hl = 0.28f * sp;
				uint8_t *o = crow + 4 * (size_t)i;
				o[0] = unorm8(cr * shade + hl);
				o[1] = unorm8(cg * shade + hl);
				o[2] = unorm8(cb * shade + hl);
				o[3] = 255;
			}
		}
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

static void *band_main(void *arg)
{
	band *b = arg;
	clear_rows(b);
	if (b->sc->count > 0)
		draw_sprites(b);
	draw_lines(b);
	if (b->out)
		eddy_downsample_rows(b->s->rgba, b->s->width / b->ss, b->s->height / b->ss, b->ss, b->out, b->y0, b->y1);
	return NULL;
}

/* Copies the particles into s->sx.. near to far; -1 when out of memory. */
static int sort_near_to_far(eddy_splat *s, const eddy_gl_scene *sc)
{
	const size_t n = sc->count;
	if (n > s->sorted_cap) {
		const size_t c = n + n / 4;
		float *x = realloc(s->sx, c * sizeof *x);
		if (x)
			s->sx = x;
		float *y = realloc(s->sy, c * sizeof *y);
		if (y)
			s->sy = y;
		float *z = realloc(s->sz, c * sizeof *z);
		if (z)
			s->sz = z;
		uint8_t *rgb = realloc(s->srgb, c * 4);
		if (rgb)
			s->srgb = rgb;
		uint32_t *bin = realloc(s->bin, c * sizeof *bin);
		if (bin)
			s->bin = bin;
		if (!x || !y || !z || !rgb || !bin)
			return -1;
		s->sorted_cap = c;
	}
	const float *v = sc->view;
	float lo = INFINITY, hi = -INFINITY;
	for (size_t k = 0; k < n; ++k) {
		const float d = -(v[2] * sc->x[k] + v[6] * sc->y[k] + v[10] * sc->z[k] + v[14]);
		lo = d < lo ? d : lo;
		hi = d > hi ? d : hi;
	}
	const float scale = hi > lo ? (float)(SORT_BINS - 1) / (hi - lo) : 0.0f;
	static_assert(SORT_BINS <= 65536, "bins fit the counts below");
	size_t count[SORT_BINS + 1];
	memset(count, 0, sizeof count);
	for (size_t k = 0; k < n; ++k) {
		const float d = -(v[2] * sc->x[k] + v[6] * sc->y[k] + v[10] * sc->z[k] + v[14]);
		const float f = (d - lo) * scale;
		/* NaN and out-of-range distances go last (the draw culls them) */
		const uint32_t b = f >= 0 && f <= (float)(SORT_BINS - 1) ? (uint32_t)f : SORT_BINS - 1;
		s->bin[k] = b;
		count[b + 1]++;
	}
	for (int b = 0; b < SORT_BINS; ++b)
		count[b + 1] += count[b];
	for (size_t k = 0; k < n; ++k) {
		const size_t at = count[s->bin[k]]++;
		s->sx[at] = sc->x[k], s->sy[at] = sc->y[k], s->sz[at] = sc->z[k];
		memcpy(s->srgb + 4 * at, sc->rgb + 4 * k, 4);
	}
	return 0;
}

int eddy_splat_draw(eddy_splat *s, const eddy_gl_scene *sc_in, int threads, int ss, uint8_t *out, char *err,
                    size_t cap)
{
	eddy_gl_scene sorted = *sc_in;
	const eddy_gl_scene *sc = &sorted;
	if (sc->count > 0) {
		if (sort_near_to_far(s, sc_in) != 0) {
			snprintf(err, cap, "out of memory for %zu sorted particles", sc->count);
			return -1;
		}
		sorted.x = s->sx, sorted.y = s->sy, sorted.z = s->sz, sorted.rgb = s->srgb;
	}
	if (sc->mesh_sets > 0) {
		snprintf(err, cap, "the CPU renderer draws particles and lines only, not meshes");
		return -1;
	}
	if (ss < 1 || s->width % ss || s->height % ss) {
		snprintf(err, cap, "a %dx%d buffer cannot be filtered by %d", s->width, s->height, ss);
		return -1;
	}
	const int H = s->height / ss; /* output rows */
	threads = threads < 1 ? 1 : threads > MAX_THREADS ? MAX_THREADS : threads;
	threads = threads > H ? H : threads;
	band bands[MAX_THREADS];
	const float h[3] = {sc->light[0], sc->light[1], sc->light[2] + 1.0f};
	const float hl = sqrtf(h[0] * h[0] + h[1] * h[1] + h[2] * h[2]);
	/* the far plane's distance: z_ndc = 1 */
	const float pa = sc->proj[10], pb = sc->proj[14];
	const float far_key = sc->proj[15] != 0 ? (pb - 1.0f) / pa : pb / (1.0f + pa);
	for (int t = 0; t < threads; ++t) {
		band *b = &bands[t];
		b->far_key = far_key;
		b->s = s;
		b->sc = sc;
		for (int k = 0; k < 3; ++k)
			b->halfway[k] = h[k] / hl;
		b->ss = ss;
		b->out = out;
		b->y0 = (int)((long)H * t / threads);
		b->y1 = (int)((long)H * (t + 1) / threads);
		/* output rows [y0, y1) from the top are buffer rows [H - y1, H - y0) * ss from the bottom */
		b->r0 = (H - b->y1) * ss;
		b->r1 = (H - b->y0) * ss;
	}
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
