/* SPDX-License-Identifier: MIT */
/* Side-by-side panels for eddy compare: PNG frames read back with stb_image,
 * captions rasterised from stb_easy_font's quads, the row written through
 * eddy_write_png (png.c: stb_image_write, a temporary file renamed into place).
 * Both stb headers are Debian's libstb-dev; stb_image's implementation is
 * STATIC here, so its symbols stay private to this file. */
#include "render.h"

#include <errno.h>
#include <stdlib.h>
#include <string.h>

#if defined(__GNUC__)
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wshadow"
#pragma GCC diagnostic ignored "-Wcast-qual"
#pragma GCC diagnostic ignored "-Wunused-function"
#pragma GCC diagnostic ignored "-Wsign-compare"
#pragma GCC diagnostic ignored "-Wmissing-prototypes"
#pragma GCC diagnostic ignored "-Wstrict-prototypes"
#pragma GCC diagnostic ignored "-Wpedantic"
#pragma GCC diagnostic ignored "-Wdouble-promotion"
#pragma GCC diagnostic ignored "-Wimplicit-fallthrough"
#pragma GCC diagnostic ignored "-Wundef"
#endif
#define STB_IMAGE_IMPLEMENTATION
#define STB_IMAGE_STATIC
#define STBI_ONLY_PNG
#define STBI_NO_HDR
#define STBI_NO_LINEAR
#include <stb/stb_image.h>
#include <stb/stb_easy_font.h>
#if defined(__GNUC__)
#pragma GCC diagnostic pop
/* stb_image declares functions that STBI_ONLY_PNG leaves undefined and
 * stb_easy_font has helpers this file does not call; GCC says so at the end
 * of the file, after the pop above */
#pragma GCC diagnostic ignored "-Wunused-function"
#endif

/* text into a 256-byte line buffer, cut if longer */
static void copy_line(char dst[256], const char *text)
{
	size_t n = strlen(text);
	n = n < 255 ? n : 255;
	memcpy(dst, text, n);
	dst[n] = '\0';
}

enum { DEFAULT_W = 320, DEFAULT_H = 240, MAX_SIDE = 16384 };

typedef struct canvas {
	uint8_t *rgb;
	int w, h;
} canvas;

/* A filled rectangle [x0, x1) x [y0, y1), clipped to the panel's columns
 * [clip0, clip1); alpha 255 is opaque. */
static void fill(canvas *c, int x0, int y0, int x1, int y1, int clip0, int clip1, const uint8_t rgb[3], int alpha)
{
	if (x0 < clip0)
		x0 = clip0;
	if (x1 > clip1)
		x1 = clip1;
	if (y0 < 0)
		y0 = 0;
	if (y1 > c->h)
		y1 = c->h;
	for (int y = y0; y < y1; ++y)
		for (int x = x0; x < x1; ++x) {
			uint8_t *p = c->rgb + ((size_t)y * (size_t)c->w + (size_t)x) * 3;
			for (int k = 0; k < 3; ++k)
				p[k] = (uint8_t)((p[k] * (255 - alpha) + rgb[k] * alpha) / 255);
		}
}

/* One line of text at (x, y) px, scale px per font unit, white. */
static void draw_text(canvas *c, int x, int y, int scale, const char *text, int clip0, int clip1)
{
	static char vbuf[96 * 1024]; /* about 270 bytes a character: 350 characters */
	char line[256];
	copy_line(line, text);
	int quads = stb_easy_font_print(0, 0, line, NULL, vbuf, (int)sizeof vbuf);
	static const uint8_t white[3] = {255, 255, 255};
	for (int q = 0; q < quads; ++q) {
		float v[4][4]; /* x, y, z, colour: 16 bytes a vertex */
		memcpy(v, vbuf + q * 64, sizeof v);
		float xa = v[0][0], xb = v[0][0], ya = v[0][1], yb = v[0][1];
		for (int k = 1; k < 4; ++k) {
			xa = v[k][0] < xa ? v[k][0] : xa;
			xb = v[k][0] > xb ? v[k][0] : xb;
			ya = v[k][1] < ya ? v[k][1] : ya;
			yb = v[k][1] > yb ? v[k][1] : yb;
		}
		fill(c, x + (int)(xa * (float)scale), y + (int)(ya * (float)scale), x + (int)(xb * (float)scale),
		     y + (int)(yb * (float)scale), clip0, clip1, white, 255);
	}
}

static int text_width(const char *text)
{
	char line[256];
	copy_line(line, text);
	return stb_easy_font_width(line);
}

/* The caption's lines, wrapped at spaces to width font units, into lines[]
 * (each up to 255 characters). Returns the number of lines. */
static int wrap(const char *caption, int width, char lines[][256], int max_lines)
{
	int n = 0;
	const char *p = caption;
	while (*p && n < max_lines) {
		size_t len = strcspn(p, "\n");
		char src[256];
		snprintf(src, sizeof src, "%.*s", (int)(len < 255 ? len : 255), p);
		p += len + (p[len] == '\n');
		/* greedy: as many words as fit, a word longer than the width on its own */
		char *s = src;
		do {
			char cur[256] = "";
			size_t used = 0;
			while (*s) {
				size_t w = strcspn(s, " ");
				/* trial = cur, a space, the word (each under 256 bytes) */
				char trial[520];
				size_t t = used;
				memcpy(trial, cur, used);
				if (used)
					trial[t++] = ' ';
				memcpy(trial + t, s, w);
				trial[t + w] = '\0';
				if (used && text_width(trial) > width)
					break;
				if (!used && text_width(trial) > width) {
					/* a word wider than the panel: as many characters as fit */
					size_t k = w > 1 ? w - 1 : 1;
					for (; k > 1; --k) {
						trial[k] = '\0';
						if (text_width(trial) <= width)
							break;
					}
					memcpy(cur, s, k);
					cur[k] = '\0';
					s += k;
					break;
				}
				copy_line(cur, trial);
				used = strlen(cur);
				s += w;
				while (*s == ' ')
					++s;
			}
			copy_line(lines[n++], cur);
		} while (*s && n < max_lines);
	}
	return n;
}

/* The caption over the top-left corner of the panel at column x0. */
static void caption(canvas *c, int x0, int pw, const char *text)
{
	const int scale = pw >= 1200 ? 3 : pw >= 480 ? 2 : 1;
	const int margin = 3 * scale, line_h = 10 * scale;
	char lines[12][256];
	int n = wrap(text, (pw - 2 * margin) / scale, lines, 12);
	int widest = 0;
	for (int i = 0; i < n; ++i) {
		int w = text_width(lines[i]) * scale;
		widest = w > widest ? w : widest;
	}
	static const uint8_t shade[3] = {0, 0, 0};
	fill(c, x0, 0, x0 + widest + 2 * margin, n * line_h + 2 * margin, x0, x0 + pw, shade, 160);
	for (int i = 0; i < n; ++i)
		draw_text(c, x0 + margin, margin + i * line_h + scale, scale, lines[i], x0, x0 + pw);
}

int eddy_compose_panels(const char *path, int panels, const char *const *images, const char *const *captions,
                        int panel_w, int panel_h, int *out_w, int *out_h, char *err, size_t cap)
{
	if (panels < 1 || panels > 64 || panel_w < 0 || panel_h < 0 || panel_w > MAX_SIDE || panel_h > MAX_SIDE) {
		snprintf(err, cap, "compose: %d panels of %d x %d px: out of range", panels, panel_w, panel_h);
		return -1;
	}
	uint8_t **pix = calloc((size_t)panels, sizeof *pix);
	int *iw = calloc((size_t)panels, sizeof *iw), *ih = calloc((size_t)panels, sizeof *ih);
	const char **why = calloc((size_t)panels, sizeof *why);
	int rc = -1;
	canvas c = {NULL, 0, 0};
	if (!pix || !iw || !ih || !why) {
		snprintf(err, cap, "compose: out of memory");
		goto done;
	}
	int maxw = 0, maxh = 0;
	for (int i = 0; i < panels; ++i) {
		if (!images || !images[i] || !images[i][0])
			continue;
		int comp;
		pix[i] = stbi_load(images[i], &iw[i], &ih[i], &comp, 3);
		if (!pix[i]) {
			why[i] = stbi_failure_reason();
			continue;
		}
		maxw = iw[i] > maxw ? iw[i] : maxw;
		maxh = ih[i] > maxh ? ih[i] : maxh;
	}
	const int pw = panel_w ? panel_w : maxw ? (maxw < MAX_SIDE ? maxw : MAX_SIDE) : DEFAULT_W;
	const int ph = panel_h ? panel_h : maxh ? (maxh < MAX_SIDE ? maxh : MAX_SIDE) : DEFAULT_H;
	c.w = pw * panels;
	c.h = ph;
	c.rgb = calloc((size_t)c.w * (size_t)c.h, 3);
	if (!c.rgb) {
		snprintf(err, cap, "compose: out of memory for %d x %d px", c.w, c.h);
		goto done;
	}
	static const uint8_t background[3] = {40, 40, 48}, border[3] = {128, 128, 128};
	for (int i = 0; i < panels; ++i) {
		const int x0 = i * pw;
		fill(&c, x0, 0, x0 + pw, ph, x0, x0 + pw, background, 255);
		if (pix[i]) {
			/* centred; cropped when larger than the panel */
			const int dx = (pw - iw[i]) / 2, dy = (ph - ih[i]) / 2;
			for (int y = 0; y < ih[i]; ++y) {
				const int ty = y + dy;
				if (ty < 0 || ty >= ph)
					continue;
				for (int x = 0; x < iw[i]; ++x) {
					const int tx = x + dx;
					if (tx < 0 || tx >= pw)
						continue;
					memcpy(c.rgb + ((size_t)ty * (size_t)c.w + (size_t)(x0 + tx)) * 3,
					       pix[i] + ((size_t)y * (size_t)iw[i] + (size_t)x) * 3, 3);
				}
			}
		}
		if (i > 0)
			fill(&c, x0, 0, x0 + 1, ph, x0, x0 + pw, border, 255);
		char text[1024];
		snprintf(text, sizeof text, "%s%s%s%s", captions && captions[i] ? captions[i] : "",
		         why[i] ? "\ncannot read image: " : "", why[i] ? why[i] : "", "");
		caption(&c, x0, pw, text);
	}
	int e = eddy_write_png(path, c.w, c.h, c.rgb);
	if (e) {
		snprintf(err, cap, "cannot write '%s': %s", path, strerror(e));
		goto done;
	}
	if (out_w)
		*out_w = pw;
	if (out_h)
		*out_h = ph;
	rc = 0;
done:
	if (pix)
		for (int i = 0; i < panels; ++i)
			stbi_image_free(pix[i]);
	free(pix);
	free(iw);
	free(ih);
	free(why);
	free(c.rgb);
	return rc;
}
