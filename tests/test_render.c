/* SPDX-License-Identifier: MIT */
#define _POSIX_C_SOURCE 200809L
/* The renderer and the particle exports: particles land on the pixels the
 * camera projects them to, nearer spheres hide farther ones whatever the draw
 * order, the colour map is applied, the background shows where nothing is
 * drawn; PNGs read back (stb_image) with a pinned hash; a GL context failure
 * is a clear eddy_status, not a crash; PLY, VTK and VTP files parse back to
 * the values written (VTP and its .pvd through VTK's own Python reader); a
 * write that fails leaves neither a partial file nor a temporary one; NULL
 * worlds and defs are refused; the Lua binding and the eddy command's --video;
 * frames written in the background match those written at once, arrive whole
 * and in order, and a failed one is still its frame's error. */
#include "test.h"

#include <dirent.h>
#include <errno.h>
#include <lauxlib.h>
#include <lualib.h>
#include <signal.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include "eddy.h"
#include "eddy_lua.h"
#include "../render/render.h" /* the CPU splatter and the GL context, compared */

#include <png.h> /* libpng reads render/png.c's files back, checksums checked */

#define STB_IMAGE_IMPLEMENTATION
#define STBI_ONLY_PNG
#include <stb/stb_image.h>

/* ---- helpers ---- */

static eddy_world *make_world(void)
{
	eddy_world_def wd = eddy_default_world_def(); /* bounds (0,0,0)-(1,1,1) */
	char err[256];
	eddy_world *w = eddy_create_world(&wd, err, sizeof err);
	CHECKF(w != NULL, "create world: %s", err);
	return w;
}

/* The file a path pattern gives for a frame (the patterns here are ours). */
static void frame_file(char *buf, size_t cap, const char *pattern, int frame)
{
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wformat-nonliteral"
	snprintf(buf, cap, pattern, frame);
#pragma GCC diagnostic pop
}

static void out_path(char *buf, size_t cap, const char *name)
{
	snprintf(buf, cap, "%s/t_render/%s", test_build_dir(), name);
}

/* A camera looking down -z at the unit box's centre, orthographic, 1 m tall,
 * constant red spheres, black background, no outlines. */
static eddy_render_points_def base_def(const char *name)
{
	eddy_render_points_def d = eddy_default_render_points_def();
	d.width = d.height = 101;
	d.supersample = 1;
	d.eye = (eddy_vec3){0.5f, 0.5f, 3.0f};
	d.target = (eddy_vec3){0.5f, 0.5f, 0.5f};
	d.projection = EDDY_PROJECTION_ORTHOGRAPHIC;
	d.ortho_height = 1.0f;
	d.background = (eddy_vec3){0, 0, 0};
	d.radius = 0.05f;
	d.color_by[0] = '\0';
	d.color = (eddy_vec3){1, 0, 0};
	d.outline_domain = d.outline_colliders = false;
	out_path(d.path, sizeof d.path, name);
	return d;
}

typedef struct image {
	int w, h;
	unsigned char *px; /* RGB, top row first */
} image;

static void add_particles(eddy_world *w, size_t n, const eddy_vec3 *p, const eddy_vec3 *v);

/* Renders one frame of w with d and particles p (added after the renderer:
 * columns no system uses yet are not kept) and reads frame 1's PNG back. */
static image render_once(eddy_world *w, const eddy_render_points_def *d, size_t n, const eddy_vec3 *p)
{
	image im = {0, 0, NULL};
	eddy_system_id id = eddy_add_render_points(w, d);
	CHECKF(eddy_system_valid(w, id), "add_render_points: %s", eddy_world_error(w));
	add_particles(w, n, p, NULL);
	eddy_status st = eddy_world_step_frame(w);
	CHECKF(st == EDDY_OK, "step_frame: %s", eddy_world_error(w));
	if (st != EDDY_OK)
		return im;
	char path[600];
	frame_file(path, sizeof path, d->path, 1);
	int comp = 0;
	im.px = stbi_load(path, &im.w, &im.h, &comp, 3);
	CHECKF(im.px != NULL, "cannot read back %s", path);
	CHECK(comp == 3);
	return im;
}

static const unsigned char *pixel(const image *im, int x, int y)
{
	return im->px + ((size_t)y * (size_t)im->w + (size_t)x) * 3;
}

static void add_particles(eddy_world *w, size_t n, const eddy_vec3 *p, const eddy_vec3 *v)
{
	eddy_status st = eddy_world_add_particles(w, n, p, v);
	CHECKF(st == EDDY_OK, "add_particles: %s", eddy_world_error(w));
}

/* ---- tests ---- */

/* Orthographic: world (x, y) maps to column (x - 0.5) * 101 + 50.5 and row
 * (0.5 - y) * 101 + 50.5; the particle's colour is there and nowhere near
 * the mirrored point. Perspective: the pinhole projection of the same camera. */
static void particle_lands_on_its_projected_pixel(void)
{
	eddy_world *w = make_world();
	if (!w)
		return;
	const eddy_vec3 p = {0.25f, 0.75f, 0.5f};
	eddy_render_points_def d = base_def("ortho_%d.png");
	image im = render_once(w, &d, 1, &p);
	if (im.px) {
		CHECK(im.w == 101 && im.h == 101);
		const int cx = (int)((p.x - 0.5f) * 101 + 50.5f), cy = (int)((0.5f - p.y) * 101 + 50.5f);
		const unsigned char *c = pixel(&im, cx, cy);
		CHECKF(c[0] > 150 && c[1] < 40 && c[2] < 40, "ortho centre pixel (%d,%d) = %d %d %d", cx, cy, c[0], c[1], c[2]);
		/* 0.05 m radius = 5 px: 3 px away is still the sphere, 7 px away is not */
		CHECK(pixel(&im, cx + 3, cy)[0] > 60);
		CHECK(pixel(&im, cx + 7, cy)[0] == 0);
		const unsigned char *m = pixel(&im, 100 - cx, 100 - cy);
		CHECK(m[0] == 0 && m[1] == 0 && m[2] == 0);
	}
	stbi_image_free(im.px);
	eddy_destroy_world(w);

	w = make_world();
	if (!w)
		return;
	const eddy_vec3 q = {0.7f, 0.6f, 0.5f};
	d = base_def("persp_%d.png");
	d.projection = EDDY_PROJECTION_PERSPECTIVE;
	d.eye = (eddy_vec3){0.5f, 0.5f, 2.5f};
	d.fov = 40.0f;
	d.radius = 0.02f;
	im = render_once(w, &d, 1, &q);
	if (im.px) {
		const double t = tan(20.0 * 3.14159265358979 / 180.0), depth = 2.0;
		const double xn = (q.x - 0.5) / depth / t, yn = (q.y - 0.5) / depth / t;
		const int cx = (int)((xn + 1) / 2 * 101), cy = (int)((1 - yn) / 2 * 101);
		const unsigned char *c = pixel(&im, cx, cy);
		CHECKF(c[0] > 150 && c[1] < 40, "perspective pixel (%d,%d) = %d %d %d", cx, cy, c[0], c[1], c[2]);
		CHECK(pixel(&im, cx + 6, cy)[0] == 0 && pixel(&im, cx, cy + 6)[0] == 0);
	}
	stbi_image_free(im.px);
	eddy_destroy_world(w);
}

/* Two spheres on one line of sight, coloured by vx through the gray map: the
 * nearer (white, vx = 1) covers the centre whichever is drawn first; where
 * they overlap partly, each shows where its surface is nearer. */
static void nearer_spheres_occlude_farther_ones(void)
{
	for (int order = 0; order < 2; ++order) {
		eddy_world *w = make_world();
		if (!w)
			return;
		const eddy_vec3 near_p = {0.5f, 0.5f, 0.6f}, far_p = {0.5f, 0.5f, 0.4f};
		const eddy_vec3 near_v = {1, 0, 0}, far_v = {0, 0, 0};
		eddy_vec3 p[2] = {order ? far_p : near_p, order ? near_p : far_p};
		eddy_vec3 v[2] = {order ? far_v : near_v, order ? near_v : far_v};
		/* the renderer reads vx, so the column must exist before particles arrive */
		eddy_render_points_def d = base_def(order ? "occ_b_%d.png" : "occ_a_%d.png");
		strcpy(d.color_by, "vx");
		d.colormap = EDDY_COLORMAP_GRAY;
		d.value_min = 0, d.value_max = 1;
		d.background = (eddy_vec3){0, 0, 1};
		eddy_system_id id = eddy_add_render_points(w, &d);
		CHECKF(eddy_system_valid(w, id), "%s", eddy_world_error(w));
		add_particles(w, 2, p, v);
		CHECK(eddy_world_step_frame(w) == EDDY_OK);
		char path[600];
		frame_file(path, sizeof path, d.path, 1);
		int iw, ih, comp;
		unsigned char *px = stbi_load(path, &iw, &ih, &comp, 3);
		CHECK(px != NULL);
		if (px) {
			const unsigned char *c = px + (50 * 101 + 50) * 3;
			CHECKF(c[0] > 150 && c[1] > 150 && c[2] > 150, "order %d: centre = %d %d %d (the far sphere shows)", order,
			       c[0], c[1], c[2]);
			stbi_image_free(px);
		}
		eddy_destroy_world(w);
	}
	/* intersecting spheres need per-fragment depth, not one depth per sprite:
	 * A (white) at z = 0.50 and B (black) at x + 0.04, z = 0.49, both r = 0.05.
	 * Column 52 (x = 0.5198): A's surface z = 0.546 beats B's 0.536; column 54
	 * (x = 0.5396): B's 0.540 beats A's 0.531, though B's centre is farther. */
	eddy_world *w = make_world();
	if (!w)
		return;
	const eddy_vec3 p[2] = {{0.50f, 0.5f, 0.50f}, {0.54f, 0.5f, 0.49f}};
	const eddy_vec3 v[2] = {{1, 0, 0}, {0, 0, 0}};
	eddy_render_points_def d = base_def("occ_c_%d.png");
	strcpy(d.color_by, "vx");
	d.colormap = EDDY_COLORMAP_GRAY;
	d.value_min = 0, d.value_max = 1;
	d.background = (eddy_vec3){0, 0, 1};
	CHECK(eddy_system_valid(w, eddy_add_render_points(w, &d)));
	add_particles(w, 2, p, v);
	CHECK(eddy_world_step_frame(w) == EDDY_OK);
	char path[600];
	frame_file(path, sizeof path, d.path, 1);
	int iw, ih, comp;
	unsigned char *px = stbi_load(path, &iw, &ih, &comp, 3);
	CHECK(px != NULL);
	if (px) {
		const unsigned char *a = px + (50 * 101 + 52) * 3, *b = px + (50 * 101 + 54) * 3;
		CHECKF(a[0] > 150 && a[2] > 150, "column 52 should show A (white): %d %d %d", a[0], a[1], a[2]);
		CHECKF(b[0] < 40 && b[2] < 40, "column 54 should show B (black): %d %d %d", b[0], b[1], b[2]);
		stbi_image_free(px);
	}
	eddy_destroy_world(w);
}

/* Values 0, 0.5 and 1 through viridis give its bottom, middle and top colours
 * (times the same shading, measured on a white sphere). */
static void colour_map_is_applied(void)
{
	eddy_world *w = make_world();
	if (!w)
		return;
	const eddy_vec3 p[4] = {{0.2f, 0.5f, 0.5f}, {0.5f, 0.5f, 0.5f}, {0.8f, 0.5f, 0.5f}, {0.5f, 0.2f, 0.5f}};
	const eddy_vec3 v[4] = {{0, 0, 0}, {0.5f, 0, 0}, {1, 0, 0}, {0.25f, 0, 0}};
	eddy_render_points_def d = base_def("cmap_%d.png");
	strcpy(d.color_by, "vx");
	d.colormap = EDDY_COLORMAP_VIRIDIS; /* automatic range: 0 .. 1 from the data */
	d.value_min = NAN;
	d.value_max = NAN;
	eddy_system_valid(w, eddy_add_render_points(w, &d));
	add_particles(w, 4, p, v);
	CHECK(eddy_world_step_frame(w) == EDDY_OK);
	char path[600];
	frame_file(path, sizeof path, d.path, 1);
	image im = {0, 0, NULL};
	int comp;
	im.px = stbi_load(path, &im.w, &im.h, &comp, 3);
	eddy_destroy_world(w);

	/* the shading factor at a sphere's centre, from a white sphere */
	w = make_world();
	const eddy_vec3 c = {0.5f, 0.5f, 0.5f};
	eddy_render_points_def wd = base_def("white_%d.png");
	wd.color = (eddy_vec3){1, 1, 1};
	image white = render_once(w, &wd, 1, &c);
	eddy_destroy_world(w);
	if (!im.px || !white.px) {
		CHECK(!"images missing");
		stbi_image_free(im.px);
		stbi_image_free(white.px);
		return;
	}
	const double k = pixel(&white, 50, 50)[0] / 255.0;
	CHECKF(k > 0.6 && k < 1.0, "shading factor at a sphere's centre %.3f", k);
	static const int expect[3][3] = {{68, 1, 84}, {33, 145, 140}, {253, 231, 37}}; /* viridis 0, 0.5, 1 */
	const int cols[3] = {20, 50, 80};
	for (int i = 0; i < 3; ++i) {
		const unsigned char *px = pixel(&im, cols[i], 50);
		for (int ch = 0; ch < 3; ++ch)
			CHECKF(fabs(px[ch] - k * expect[i][ch]) <= 10, "value %.1f channel %d: %d, expected %.0f", i * 0.5, ch,
			       px[ch], k * expect[i][ch]);
	}
	stbi_image_free(im.px);
	stbi_image_free(white.px);
}

/* Where nothing is drawn the background colour is exact; with outlines on,
 * the domain's edges show in the outline colour. */
static void background_where_nothing_is_drawn(void)
{
	eddy_world *w = make_world();
	if (!w)
		return;
	const eddy_vec3 p = {0.5f, 0.5f, 0.5f};
	eddy_render_points_def d = base_def("bg_%d.png");
	d.background = (eddy_vec3){0.2f, 0.4f, 0.6f};
	d.ortho_height = 1.2f; /* so the domain's edges are inside the picture */
	d.outline_domain = true;
	d.outline_color = (eddy_vec3){1, 1, 1};
	image im = render_once(w, &d, 1, &p);
	if (im.px) {
		const int corners[4][2] = {{0, 0}, {100, 0}, {0, 100}, {100, 100}};
		for (int i = 0; i < 4; ++i) {
			const unsigned char *c = pixel(&im, corners[i][0], corners[i][1]);
			CHECKF(c[0] == 51 && c[1] == 102 && c[2] == 153, "corner %d = %d %d %d", i, c[0], c[1], c[2]);
		}
		/* the box's left edge x = 0 sits at column (0 - 0.5) / 1.2 * 101 + 50.5 = 8.4 */
		int white = 0;
		for (int x = 6; x <= 11; ++x)
			white += pixel(&im, x, 50)[0] > 200;
		CHECKF(white >= 1, "no outline near column 8");
	}
	stbi_image_free(im.px);
	eddy_destroy_world(w);
}

static uint64_t fnv1a(const unsigned char *p, size_t n)
{
	uint64_t h = 1469598103934665603ull;
	for (size_t i = 0; i < n; ++i)
		h = (h ^ p[i]) * 1099511628211ull;
	return h;
}

/* A fixed scene, drawn twice by two renderers: the PNGs decode to the same
 * pixels, whose hash is pinned (render/splat.c, single-precision floats with
 * the compiler's default contraction on x86-64). */
#define PINNED_IMAGE_HASH 0xa7a12bf7f6c5d402ull

static uint64_t fixed_scene_hash(const char *name)
{
	eddy_world *w = make_world();
	if (!w)
		return 0;
	eddy_vec3 p[512], v[512];
	for (int i = 0; i < 512; ++i) {
		p[i] = (eddy_vec3){0.1f + 0.1f * (float)(i % 8), 0.1f + 0.1f * (float)((i / 8) % 8),
		                   0.1f + 0.1f * (float)(i / 64)};
		v[i] = (eddy_vec3){(float)(i % 7) * 0.1f, (float)(i % 5) * -0.2f, 0.0f};
	}
	eddy_render_points_def d = eddy_default_render_points_def();
	d.width = 160;
	d.height = 90;
	d.radius = 0.04f;
	out_path(d.path, sizeof d.path, name);
	eddy_collide_sphere_def sphere = eddy_default_collide_sphere_def();
	sphere.radius = 0.2f;
	eddy_system_valid(w, eddy_add_collide_sphere(w, &sphere));
	eddy_system_id id = eddy_add_render_points(w, &d);
	CHECKF(eddy_system_valid(w, id), "%s", eddy_world_error(w));
	add_particles(w, 512, p, v);
	CHECK(eddy_world_step_frame(w) == EDDY_OK);
	char path[600];
	frame_file(path, sizeof path, d.path, 1);
	image im = {0, 0, NULL};
	int comp;
	im.px = stbi_load(path, &im.w, &im.h, &comp, 3);
	uint64_t h = 0;
	if (im.px) {
		CHECK(im.w == 160 && im.h == 90);
		h = fnv1a(im.px, (size_t)im.w * (size_t)im.h * 3);
	}
	stbi_image_free(im.px);
	eddy_destroy_world(w);
	return h;
}

/* render/png.c's own deflate: images with runs of equal rows at the top, in
 * the middle and at the bottom, of 7 to 23 rows, in widths whose rows end a
 * run of copies in each way (3 w - 1 zero bytes after a row's first: 2, 5,
 * 257, 260, 518, 899), and one row of 75024 bytes shuffled with Fibonacci
 * frequencies (symbol k F(k + 2) times, k < 22: Huffman would give codes 21 bits
 * long, so the 15-bit limit is exercised, and more tokens than one block
 * holds), read back by libpng (which checks every CRC, the code's
 * completeness and the zlib Adler-32) and by stb_image, give the bytes
 * written. */
static void png_writer_round_trips(void)
{
	const int widths[6] = {1, 2, 86, 87, 173, 300};
	enum { H = 64 };
	for (int wi = 0; wi < 6; ++wi) {
		const int w = widths[wi];
		uint8_t *rgb = malloc((size_t)w * H * 3);
		if (!rgb)
			return;
		uint64_t r = 7 + (uint64_t)wi;
		for (int y = 0; y < H; ++y) {
			uint8_t *row = rgb + (size_t)y * (size_t)w * 3;
			/* rows 1-9 repeat the row above (a run of 9), 21-27 (7, through
			 * zlib), 31-38 (8), 41-63 (23, to the end); the rest is noise */
			const bool repeat = (y > 0 && y <= 9) || (y > 20 && y <= 27) || (y > 30 && y <= 38) || y > 40;
			if (repeat) {
				memcpy(row, row - (size_t)w * 3, (size_t)w * 3);
				continue;
			}
			for (int i = 0; i < w * 3; ++i) {
				r = r * 6364136223846793005ull + 1442695040888963407ull;
				row[i] = (uint8_t)(r >> 56);
			}
		}
		char path[600];
		char name[64];
		snprintf(name, sizeof name, "png_w%d.png", w);
		out_path(path, sizeof path, name);
		CHECK(eddy_write_png(path, w, H, rgb) == 0);
		png_image im;
		memset(&im, 0, sizeof im);
		im.version = PNG_IMAGE_VERSION;
		uint8_t *back = malloc((size_t)w * H * 3);
		CHECKF(png_image_begin_read_from_file(&im, path) != 0, "libpng cannot read %s: %s", path, im.message);
		if (back && im.width == (png_uint_32)w && im.height == H) {
			im.format = PNG_FORMAT_RGB;
			CHECKF(png_image_finish_read(&im, NULL, back, 0, NULL) != 0, "libpng: %s: %s", path, im.message);
			CHECKF(memcmp(back, rgb, (size_t)w * H * 3) == 0, "width %d: libpng reads other pixels back", w);
		} else {
			CHECKF(0, "width %d: libpng reads %ux%u", w, (unsigned)im.width, (unsigned)im.height);
			png_image_free(&im);
		}
		int sw = 0, sh = 0, comp = 0;
		uint8_t *st = stbi_load(path, &sw, &sh, &comp, 3);
		CHECKF(st && sw == w && sh == H && memcmp(st, rgb, (size_t)w * H * 3) == 0,
		       "width %d: stb_image reads other pixels", w);
		stbi_image_free(st);
		free(back);
		free(rgb);
	}
	/* the skewed row */
	enum { FW = 25008 };
	uint8_t *row = malloc(3 * FW), *back = malloc(3 * FW);
	if (!row || !back) {
		free(row), free(back);
		return;
	}
	size_t at = 0;
	uint32_t f0 = 1, f1 = 1; /* F(1), F(2) */
	for (int k = 0; k < 22; ++k) {
		for (uint32_t c = 0; c < f1; ++c)
			row[at++] = (uint8_t)(7 * k);
		const uint32_t f2 = f0 + f1;
		f0 = f1, f1 = f2;
	}
	row[at++] = 255; /* 75023 bytes so far */
	CHECK(at == 3 * FW);
	uint64_t r = 5;
	for (size_t i = 3 * FW - 1; i > 0; --i) {
		r = r * 6364136223846793005ull + 1442695040888963407ull;
		const size_t j = (size_t)(r >> 33) % (i + 1);
		const uint8_t t = row[i];
		row[i] = row[j], row[j] = t;
	}
	char path[600];
	out_path(path, sizeof path, "png_skewed.png");
	CHECK(eddy_write_png(path, FW, 1, row) == 0);
	png_image im;
	memset(&im, 0, sizeof im);
	im.version = PNG_IMAGE_VERSION;
	CHECKF(png_image_begin_read_from_file(&im, path) != 0, "libpng cannot read %s: %s", path, im.message);
	im.format = PNG_FORMAT_RGB;
	CHECKF(im.width == FW && png_image_finish_read(&im, NULL, back, 0, NULL) != 0, "libpng: %s: %s", path, im.message);
	CHECK(memcmp(back, row, 3 * FW) == 0);
	free(row), free(back);
}

static void png_round_trip_and_pinned_hash(void)
{
	uint64_t a = fixed_scene_hash("hash_a_%d.png"), b = fixed_scene_hash("hash_b_%d.png");
	CHECK(a != 0);
	CHECKF(a == b, "the same scene rendered twice differs: %016llx vs %016llx", (unsigned long long)a,
	       (unsigned long long)b);
	CHECKF(a == PINNED_IMAGE_HASH, "image hash %016llx, pinned %016llx (another compiler may round differently)",
	       (unsigned long long)a, (unsigned long long)PINNED_IMAGE_HASH);
}

/* No GL context (render_surface draws through OSMesa; render_points no
 * longer needs one): the frame returns EDDY_ERR_EXTERNAL and says why; the
 * world stays usable and is destroyed cleanly. EDDY_RENDER_FAIL_CONTEXT
 * forces the failure through the same path as a failing
 * OSMesaCreateContextAttribs, and render_points still draws under it. */
static void no_gl_context_is_a_clear_error(void)
{
	setenv("EDDY_RENDER_FAIL_CONTEXT", "1", 1);
	eddy_world *w = make_world();
	if (w) {
		const eddy_vec3 p = {0.5f, 0.5f, 0.5f};
		eddy_render_surface_def d = eddy_default_render_surface_def();
		out_path(d.path, sizeof d.path, "nogl_%d.png");
		eddy_system_id id = eddy_add_render_surface(w, &d);
		eddy_render_points_def pd = base_def("nogl_points_%d.png");
		CHECK(eddy_system_valid(w, eddy_add_render_points(w, &pd)));
		add_particles(w, 1, &p, NULL);
		CHECK(eddy_system_valid(w, id));
		eddy_status st = eddy_world_step_frame(w);
		CHECK(st == EDDY_ERR_EXTERNAL);
		CHECK_HAS(eddy_world_error(w), "render_surface");
		CHECK_HAS(eddy_world_error(w), "cannot create an OpenGL context with OSMesa");
		CHECK(eddy_world_remove_system(w, id) == EDDY_OK);
		CHECK(eddy_world_step_frame(w) == EDDY_OK);
		char path[600];
		frame_file(path, sizeof path, pd.path, 2);
		struct stat sb;
		CHECKF(stat(path, &sb) == 0, "render_points wrote no %s without GL", path);
		eddy_destroy_world(w);
	}
	unsetenv("EDDY_RENDER_FAIL_CONTEXT");
}

/* An image that cannot be written is EDDY_ERR_IO naming the path. */
static void unwritable_path_is_an_io_error(void)
{
	eddy_world *w = make_world();
	if (!w)
		return;
	eddy_render_points_def d = base_def("x_%d.png");
	strcpy(d.path, "/proc/eddy-no-such-dir/frame_%d.png");
	CHECK(eddy_system_valid(w, eddy_add_render_points(w, &d)));
	CHECK(eddy_world_step_frame(w) == EDDY_ERR_IO);
	CHECK_HAS(eddy_world_error(w), "/proc/eddy-no-such-dir/frame_1.png");
	eddy_destroy_world(w);
}

static void bad_defs_are_rejected(void)
{
	eddy_world *w = make_world();
	if (!w)
		return;
	eddy_render_points_def d = base_def("bad_%d.png");
	strcpy(d.path, "frame.png");
	CHECK(!eddy_system_valid(w, eddy_add_render_points(w, &d)));
	CHECK_HAS(eddy_world_error(w), "render_points: 'path' must hold exactly one integer conversion");
	d = base_def("bad_%d.png");
	strcpy(d.color_by, "temperature");
	CHECK(!eddy_system_valid(w, eddy_add_render_points(w, &d)));
	CHECK_HAS(eddy_world_error(w), "no column named 'temperature'");
	d = base_def("bad_%d.png");
	d.radius = 0;
	CHECK(!eddy_system_valid(w, eddy_add_render_points(w, &d)));
	CHECK_HAS(eddy_world_error(w), "'radius' must be > 0 m");
	d = base_def("bad_%d.png");
	d.up = (eddy_vec3){0, 0, 1};
	CHECK(!eddy_system_valid(w, eddy_add_render_points(w, &d)));
	CHECK_HAS(eddy_world_error(w), "'up' must not be parallel");
	/* density exists but nothing writes it: the pipeline names the fix */
	d = base_def("bad_%d.png");
	strcpy(d.color_by, "density");
	CHECK(!eddy_system_valid(w, eddy_add_render_points(w, &d)));
	CHECK_HAS(eddy_world_error(w), "density");
	eddy_export_particles_def e = eddy_default_export_particles_def();
	strcpy(e.channels, "vx nonsense");
	CHECK(!eddy_system_valid(w, eddy_add_export_particles(w, &e)));
	CHECK_HAS(eddy_world_error(w), "'nonsense' is not a per-particle number column");
	eddy_destroy_world(w);
}

/* ---- exports ---- */

static float le_float(const unsigned char *p)
{
	uint32_t u = (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24;
	float f;
	memcpy(&f, &u, 4);
	return f;
}
static uint32_t be_u32(const unsigned char *p)
{
	return (uint32_t)p[0] << 24 | (uint32_t)p[1] << 16 | (uint32_t)p[2] << 8 | (uint32_t)p[3];
}
static float be_float(const unsigned char *p)
{
	uint32_t u = be_u32(p);
	float f;
	memcpy(&f, &u, 4);
	return f;
}

static unsigned char *slurp(const char *path, size_t *n)
{
	FILE *f = fopen(path, "rb");
	if (!f)
		return NULL;
	fseek(f, 0, SEEK_END);
	long len = ftell(f);
	fseek(f, 0, SEEK_SET);
	unsigned char *b = malloc((size_t)len + 1);
	*n = fread(b, 1, (size_t)len, f);
	b[*n] = 0;
	fclose(f);
	return b;
}

/* Reads one text line at *p (up to '\n'), advancing past it. */
static const char *line(const unsigned char **p, const unsigned char *end, char *buf, size_t cap)
{
	size_t k = 0;
	while (*p < end && **p != '\n' && k + 1 < cap)
		buf[k++] = (char)*(*p)++;
	buf[k] = '\0';
	if (*p < end)
		++*p;
	return buf;
}

enum { NP = 5 };
static const eddy_vec3 exp_pos[NP] = {
	{0.1f, 0.2f, 0.3f}, {0.9f, 0.8f, 0.7f}, {0.5f, 0.5f, 0.5f}, {0.25f, 0.125f, 0.0625f}, {1e-3f, 0.999f, 0.33f}};
static const eddy_vec3 exp_vel[NP] = {{1, 2, 2}, {-3, 0, 4}, {0, 0, 0}, {0.5f, -0.25f, 1e-3f}, {-7.5f, 3.25f, 0}};

static eddy_world *export_world(eddy_export_format format, const char *name)
{
	eddy_world *w = make_world();
	if (!w)
		return NULL;
	eddy_export_particles_def e = eddy_default_export_particles_def();
	e.format = format;
	strcpy(e.channels, "vx, vy vz speed");
	out_path(e.path, sizeof e.path, name);
	CHECKF(eddy_system_valid(w, eddy_add_export_particles(w, &e)), "%s", eddy_world_error(w));
	add_particles(w, NP, exp_pos, exp_vel);
	CHECK(eddy_world_step_frame(w) == EDDY_OK);
	return w;
}

static float expected(int i, int c)
{
	const eddy_vec3 p = exp_pos[i], v = exp_vel[i];
	const float vals[7] = {p.x, p.y, p.z, v.x, v.y, v.z, sqrtf(v.x * v.x + v.y * v.y + v.z * v.z)};
	return vals[c];
}

static void ply_parses_back(void)
{
	eddy_world *w = export_world(EDDY_EXPORT_PLY, "p_%03d.ply");
	eddy_destroy_world(w);
	char path[600];
	out_path(path, sizeof path, "p_001.ply");
	size_t n;
	unsigned char *b = slurp(path, &n);
	CHECKF(b != NULL, "no %s", path);
	if (!b)
		return;
	const unsigned char *p = b, *end = b + n;
	char buf[256];
	CHECK(strcmp(line(&p, end, buf, sizeof buf), "ply") == 0);
	CHECK(strcmp(line(&p, end, buf, sizeof buf), "format binary_little_endian 1.0") == 0);
	static const char *const props[7] = {"x", "y", "z", "vx", "vy", "vz", "speed"};
	int prop = 0;
	long vertices = -1;
	for (;;) {
		line(&p, end, buf, sizeof buf);
		if (strcmp(buf, "end_header") == 0 || p >= end)
			break;
		if (strncmp(buf, "comment", 7) == 0)
			continue;
		if (sscanf(buf, "element vertex %ld", &vertices) == 1)
			continue;
		char name[64];
		if (sscanf(buf, "property float %63s", name) == 1) {
			CHECKF(prop < 7 && strcmp(name, props[prop]) == 0, "property %d is %s", prop, name);
			prop++;
			continue;
		}
		CHECKF(0, "unexpected header line: %s", buf);
	}
	CHECK(vertices == NP);
	CHECK(prop == 7);
	CHECK((size_t)(end - p) == (size_t)NP * 7 * 4);
	if ((size_t)(end - p) == (size_t)NP * 7 * 4)
		for (int i = 0; i < NP; ++i)
			for (int c = 0; c < 7; ++c)
				CHECK_NEAR(le_float(p + (i * 7 + c) * 4), expected(i, c), 1e-6);
	free(b);
}

static void vtk_parses_back(void)
{
	eddy_world *w = export_world(EDDY_EXPORT_VTK, "v_%03d.vtk");
	eddy_destroy_world(w);
	char path[600];
	out_path(path, sizeof path, "v_001.vtk");
	size_t n;
	unsigned char *b = slurp(path, &n);
	CHECKF(b != NULL, "no %s", path);
	if (!b)
		return;
	const unsigned char *p = b, *end = b + n;
	char buf[256];
	CHECK(strcmp(line(&p, end, buf, sizeof buf), "# vtk DataFile Version 3.0") == 0);
	CHECK(strlen(line(&p, end, buf, sizeof buf)) < 256); /* the title line */
	CHECK(strcmp(line(&p, end, buf, sizeof buf), "BINARY") == 0);
	CHECK(strcmp(line(&p, end, buf, sizeof buf), "DATASET POLYDATA") == 0);
	long count = 0;
	CHECK(sscanf(line(&p, end, buf, sizeof buf), "POINTS %ld float", &count) == 1 && count == NP);
	if (count != NP || end - p < NP * 12) {
		free(b);
		return;
	}
	for (int i = 0; i < NP; ++i)
		for (int c = 0; c < 3; ++c)
			CHECK_NEAR(be_float(p + (i * 3 + c) * 4), expected(i, c), 1e-6);
	p += NP * 12;
	line(&p, end, buf, sizeof buf); /* the newline after the binary block */
	long cells = 0, size = 0;
	CHECK(sscanf(line(&p, end, buf, sizeof buf), "VERTICES %ld %ld", &cells, &size) == 2 && cells == NP &&
	      size == 2 * NP);
	for (int i = 0; i < NP && p + 8 <= end; ++i, p += 8)
		CHECK(be_u32(p) == 1 && be_u32(p + 4) == (uint32_t)i);
	line(&p, end, buf, sizeof buf);
	CHECK(sscanf(line(&p, end, buf, sizeof buf), "POINT_DATA %ld", &count) == 1 && count == NP);
	long arrays = 0;
	CHECK(sscanf(line(&p, end, buf, sizeof buf), "FIELD channels %ld", &arrays) == 1 && arrays == 4);
	static const char *const names[4] = {"vx", "vy", "vz", "speed"};
	for (int c = 0; c < 4; ++c) {
		char name[64] = "";
		long comps = 0, tuples = 0;
		CHECK(sscanf(line(&p, end, buf, sizeof buf), "%63s %ld %ld float", name, &comps, &tuples) == 3 && comps == 1 &&
		      tuples == NP);
		CHECKF(strcmp(name, names[c]) == 0, "array %d named %s", c, name);
		if (end - p < NP * 4)
			break;
		for (int i = 0; i < NP; ++i)
			CHECK_NEAR(be_float(p + i * 4), expected(i, 3 + c), 1e-6);
		p += NP * 4;
		line(&p, end, buf, sizeof buf);
	}
	CHECK(p == end);
	free(b);
}

/* ---- round trips through strict and real readers ---- */

/* A grid of n particles inside the unit box with small, distinct velocities
 * (whole binary fractions are avoided so a conversion would show). */
static void grid_particles(eddy_world *w, int n)
{
	eddy_vec3 *p = malloc((size_t)n * sizeof *p), *v = malloc((size_t)n * sizeof *v);
	if (!p || !v) {
		CHECK(!"out of memory");
		free(p), free(v);
		return;
	}
	for (int i = 0; i < n; ++i) {
		p[i] = (eddy_vec3){0.2f + 0.05f * (float)(i % 12), 0.4f + 0.05f * (float)((i / 12) % 12),
		                   0.2f + 0.05f * (float)(i / 144)};
		v[i] = (eddy_vec3){0.1f * sinf((float)i), 0.07f * cosf(1.3f * (float)i), 0.05f * sinf(0.7f * (float)i + 1)};
	}
	add_particles(w, (size_t)n, p, v);
	free(p), free(v);
}

/* gravity, integrate and a tank: the velocities change and ax ay az exist */
static void add_motion(eddy_world *w)
{
	eddy_gravity_def g = eddy_default_gravity_def();
	eddy_integrate_def in = eddy_default_integrate_def();
	eddy_collide_box_def box = eddy_default_collide_box_def();
	CHECKF(eddy_system_valid(w, eddy_add_gravity(w, &g)), "%s", eddy_world_error(w));
	CHECKF(eddy_system_valid(w, eddy_add_integrate(w, &in)), "%s", eddy_world_error(w));
	CHECKF(eddy_system_valid(w, eddy_add_collide_box(w, &box)), "%s", eddy_world_error(w));
}

/* The default export ("all" channels) of a moving scene, read back with a
 * strict PLY parser: the header is exactly what PLY allows for a binary
 * little-endian point cloud, and every property's 4 bytes per particle are
 * the world's column bit for bit (x y z first, then vx vy vz among them). */
static void ply_round_trip_is_bit_exact(void)
{
	eddy_world *w = make_world();
	if (!w)
		return;
	add_motion(w);
	eddy_export_particles_def e = eddy_default_export_particles_def();
	CHECK(strcmp(e.channels, "all") == 0 && e.format == EDDY_EXPORT_PLY);
	out_path(e.path, sizeof e.path, "rt_%03d.ply");
	CHECKF(eddy_system_valid(w, eddy_add_export_particles(w, &e)), "%s", eddy_world_error(w));
	enum { N = 300 };
	grid_particles(w, N);
	CHECK(eddy_world_step_frame(w) == EDDY_OK);
	CHECK(eddy_world_step_frame(w) == EDDY_OK);
	char path[600];
	out_path(path, sizeof path, "rt_002.ply");
	size_t n = 0;
	unsigned char *b = slurp(path, &n);
	CHECKF(b != NULL, "no %s", path);
	if (!b) {
		eddy_destroy_world(w);
		return;
	}
	const unsigned char *p = b, *end = b + n;
	char buf[256], names[32][64];
	int props = 0;
	long vertices = -1;
	CHECK(strcmp(line(&p, end, buf, sizeof buf), "ply") == 0);
	CHECK(strcmp(line(&p, end, buf, sizeof buf), "format binary_little_endian 1.0") == 0);
	bool ended = false;
	while (p < end && !ended) {
		line(&p, end, buf, sizeof buf);
		char name[64], extra[8];
		long count;
		if (strcmp(buf, "end_header") == 0) {
			ended = true;
		} else if (strncmp(buf, "comment ", 8) == 0) {
			continue;
		} else if (sscanf(buf, "element vertex %ld%7s", &count, extra) == 1) {
			CHECKF(vertices < 0 && props == 0, "a second element or one after properties: %s", buf);
			vertices = count;
		} else if (sscanf(buf, "property float %63s%7s", name, extra) == 1) {
			CHECKF(vertices >= 0 && props < 32, "property before the element: %s", buf);
			if (props < 32)
				strcpy(names[props++], name);
		} else {
			CHECKF(0, "not a header line eddy writes: \"%s\"", buf);
		}
	}
	CHECK(ended);
	CHECKF(vertices == N, "element vertex %ld, expected %d", vertices, N);
	CHECK(props >= 6 && !strcmp(names[0], "x") && !strcmp(names[1], "y") && !strcmp(names[2], "z"));
	bool seen_v[3] = {false, false, false};
	for (int c = 0; c < props; ++c)
		for (int k = 0; k < 3; ++k)
			seen_v[k] = seen_v[k] || !strcmp(names[c], (const char *[]){"vx", "vy", "vz"}[k]);
	CHECKF(seen_v[0] && seen_v[1] && seen_v[2], "vx vy vz missing from the default (\"all\") export");
	CHECKF((size_t)(end - p) == (size_t)N * (size_t)props * 4, "body %zu bytes, expected %zu", (size_t)(end - p),
	       (size_t)N * (size_t)props * 4);
	if ((size_t)(end - p) == (size_t)N * (size_t)props * 4) {
		int mismatches = 0;
		for (int c = 0; c < props; ++c) {
			size_t cnt = 0;
			const float *col = eddy_world_channel(w, names[c], &cnt);
			CHECKF(col && cnt == N, "property %s is not a column of the world", names[c]);
			for (size_t i = 0; col && cnt == N && i < N; ++i) {
				const float got = le_float(p + (i * (size_t)props + (size_t)c) * 4);
				mismatches += memcmp(&got, &col[i], 4) != 0;
			}
		}
		CHECKF(mismatches == 0, "%d values differ from the world's bits", mismatches);
	}
	free(b);
	eddy_destroy_world(w);
}

/* The Python that has VTK: $EDDY_PYTHON, Debian's /usr/bin/python3 (where
 * python3-vtk9 installs it, even when another python3 comes first on PATH),
 * then python3. NULL if none imports vtk. */
static const char *python_with_vtk(void)
{
	const char *env = getenv("EDDY_PYTHON");
	const char *const cand[3] = {env && env[0] ? env : NULL, "/usr/bin/python3", "python3"};
	for (int i = 0; i < 3; ++i) {
		char cmd[700], out[256];
		if (!cand[i])
			continue;
		snprintf(cmd, sizeof cmd, "%s -c 'import vtk' </dev/null", cand[i]);
		if (test_sh(cmd, out, sizeof out) == 0)
			return cand[i];
	}
	return NULL;
}

/* VTK's own reader on eddy's .vtp frames, and the .pvd parsed strictly:
 * every listed frame exists, has the particle count, a vertex cell per
 * point, TimeValue equal to the .pvd's timestep equal to eddy's time, a
 * 3-component "velocity"; the last frame's points and velocities are the
 * world's floats exactly. Missing VTK fails: the set-up installs it. */
static const char vtp_check_py[] =
	"import os, sys\n"
	"import xml.etree.ElementTree as ET\n"
	"import vtk\n"
	"d = sys.argv[1]\n"
	"def fail(m):\n"
	"    print('FAIL: ' + m); sys.exit(1)\n"
	"lines = open(os.path.join(d, 'expect.txt')).read().split('\\n')\n"
	"n = int(lines[0]); times = [float(t) for t in lines[1].split()]; arrays = sorted(lines[2].split())\n"
	"rows = [[float.fromhex(v) for v in l.split()] for l in lines[3:3 + n]]\n"
	"root = ET.parse(os.path.join(d, 'p.pvd')).getroot()\n"
	"if root.tag != 'VTKFile' or root.get('type') != 'Collection': fail('pvd root %s %s' % (root.tag, root.attrib))\n"
	"if len(root) != 1 or root[0].tag != 'Collection': fail('pvd must hold one Collection')\n"
	"sets = list(root[0])\n"
	"if len(sets) != len(times): fail('pvd lists %d frames, eddy wrote %d' % (len(sets), len(times)))\n"
	"for k, (ds, t) in enumerate(zip(sets, times)):\n"
	"    f = ds.get('file')\n"
	"    if ds.tag != 'DataSet' or f != 'p_%04d.vtp' % (k + 1): fail('entry %d: %s %s' % (k, ds.tag, ds.attrib))\n"
	"    if float(ds.get('timestep')) != t: fail('entry %d: timestep %s, eddy time %r' % (k, ds.get('timestep'), t))\n"
	"    r = vtk.vtkXMLPolyDataReader(); r.SetFileName(os.path.join(d, f)); r.Update()\n"
	"    if r.GetErrorCode() != 0: fail('%s: reader error %d' % (f, r.GetErrorCode()))\n"
	"    o = r.GetOutput()\n"
	"    if o.GetNumberOfPoints() != n or o.GetNumberOfVerts() != n or o.GetNumberOfCells() != n:\n"
	"        fail('%s: %d points, %d verts, expected %d' % (f, o.GetNumberOfPoints(), o.GetNumberOfVerts(), n))\n"
	"    tv = o.GetFieldData().GetArray('TimeValue')\n"
	"    if tv is None or tv.GetValue(0) != t: fail('%s: TimeValue %r, expected %r' % (f, tv and tv.GetValue(0), t))\n"
	"    pd = o.GetPointData()\n"
	"    names = sorted(pd.GetArrayName(i) for i in range(pd.GetNumberOfArrays()))\n"
	"    if names != arrays: fail('%s: point data %s, expected %s' % (f, names, arrays))\n"
	"    v = pd.GetArray('velocity')\n"
	"    if v.GetNumberOfComponents() != 3 or v.GetNumberOfTuples() != n: fail('velocity is not %d 3-vectors' % n)\n"
	"for i, row in enumerate(rows):\n"
	"    if list(o.GetPoint(i)) != row[0:3]: fail('point %d: %s, eddy %s' % (i, o.GetPoint(i), row[0:3]))\n"
	"    if list(v.GetTuple3(i)) != row[3:6]: fail('velocity %d: %s, eddy %s' % (i, v.GetTuple3(i), row[3:6]))\n"
	"print('ok %d points, %d frames' % (n, len(times)))\n";

static void vtp_reads_back_with_vtk(void)
{
	const char *py = python_with_vtk();
	CHECKF(py != NULL, "python3 with VTK is not importable (tried $EDDY_PYTHON, /usr/bin/python3, python3): run the "
	                   "test set-up (scripts/deps.sh), which installs python3-vtk9");
	char dir[300], cmd[2048], out[4096];
	snprintf(dir, sizeof dir, "%s/t_render/vtp", test_build_dir());
	snprintf(cmd, sizeof cmd, "rm -rf %s", dir);
	test_sh(cmd, out, sizeof out);
	eddy_world *w = make_world();
	if (!w)
		return;
	add_motion(w);
	eddy_export_particles_def e = eddy_default_export_particles_def();
	e.format = EDDY_EXPORT_VTP;
	snprintf(e.path, sizeof e.path, "%s/p_%%04d.vtp", dir);
	CHECKF(eddy_system_valid(w, eddy_add_export_particles(w, &e)), "%s", eddy_world_error(w));
	enum { N = 200, FRAMES = 3 };
	grid_particles(w, N);
	double t[FRAMES];
	for (int f = 0; f < FRAMES; ++f) {
		CHECKF(eddy_world_step_frame(w) == EDDY_OK, "%s", eddy_world_error(w));
		t[f] = eddy_world_time(w);
	}
	char path[700];
	snprintf(path, sizeof path, "%s/expect.txt", dir);
	FILE *f = fopen(path, "w");
	CHECK(f != NULL);
	size_t cnt = 0;
	const char *const col[6] = {"x", "y", "z", "vx", "vy", "vz"};
	const float *c[6];
	for (int k = 0; k < 6; ++k) {
		c[k] = eddy_world_channel(w, col[k], &cnt);
		CHECK(c[k] && cnt == N);
	}
	if (f && c[0] && c[1] && c[2] && c[3] && c[4] && c[5] && cnt == N) {
		fprintf(f, "%d\n", N);
		for (int k = 0; k < FRAMES; ++k)
			fprintf(f, "%.17g ", t[k]);
		/* the arrays "all" gives here: vx vy vz and ax ay az, grouped */
		fprintf(f, "\nvelocity acceleration\n");
		for (size_t i = 0; i < N; ++i)
			for (int k = 0; k < 6; ++k)
				fprintf(f, "%a%c", (double)c[k][i], k == 5 ? '\n' : ' ');
	}
	if (f)
		CHECK(fclose(f) == 0);
	eddy_destroy_world(w);
	if (!py)
		return;
	snprintf(path, sizeof path, "%s/t_render/vtp_check.py", test_build_dir());
	f = fopen(path, "w");
	CHECK(f && fputs(vtp_check_py, f) >= 0);
	if (f)
		CHECK(fclose(f) == 0);
	snprintf(cmd, sizeof cmd, "%s %s %s", py, path, dir);
	const int rc = test_sh(cmd, out, sizeof out);
	CHECKF(rc == 0 && strncmp(out, "ok ", 3) == 0, "VTK's reader on %s (exit %d): %s", dir, rc, out);
}

/* A world resumed from a checkpoint in a new exporter keeps the frames the
 * first one wrote in the collection: frames 1-2 from the first world, 3 from
 * the resumed one, with the first world's times. */
static eddy_world *vtp_world(const char *dir)
{
	eddy_world *w = make_world();
	if (!w)
		return NULL;
	add_motion(w);
	eddy_export_particles_def e = eddy_default_export_particles_def();
	e.format = EDDY_EXPORT_VTP;
	snprintf(e.path, sizeof e.path, "%s/p_%%04d.vtp", dir);
	CHECKF(eddy_system_valid(w, eddy_add_export_particles(w, &e)), "%s", eddy_world_error(w));
	grid_particles(w, 50);
	return w;
}

static void vtp_collection_survives_a_resume(void)
{
	char dir[300], cmd[700], out[4096], ckpt[400];
	snprintf(dir, sizeof dir, "%s/t_render/vtp_resume", test_build_dir());
	snprintf(cmd, sizeof cmd, "rm -rf %s && mkdir -p %s", dir, dir);
	test_sh(cmd, out, sizeof out);
	snprintf(ckpt, sizeof ckpt, "%s/frame2.eddy", dir);
	eddy_world *a = vtp_world(dir);
	if (!a)
		return;
	double t[3] = {0};
	for (int f = 0; f < 3; ++f) {
		CHECKF(eddy_world_step_frame(a) == EDDY_OK, "%s", eddy_world_error(a));
		t[f] = eddy_world_time(a);
		if (f == 1)
			CHECKF(eddy_world_save(a, ckpt, 7) == EDDY_OK, "%s", eddy_world_error(a));
	}
	eddy_destroy_world(a);
	eddy_world *b = vtp_world(dir);
	if (!b)
		return;
	CHECKF(eddy_world_load(b, ckpt, 7) == EDDY_OK, "%s", eddy_world_error(b));
	CHECKF(eddy_world_step_frame(b) == EDDY_OK, "%s", eddy_world_error(b));
	CHECK(eddy_world_frame(b) == 3);
	eddy_destroy_world(b);
	snprintf(cmd, sizeof cmd, "grep -o 'timestep=\"[^\"]*\".*file=\"[^\"]*\"' %s/p.pvd", dir);
	CHECK(test_sh(cmd, out, sizeof out) == 0);
	char want[200];
	for (int f = 0; f < 3; ++f) {
		snprintf(want, sizeof want, "timestep=\"%.17g\" group=\"\" part=\"0\" file=\"p_%04d.vtp\"", t[f], f + 1);
		CHECK_HAS(out, want);
	}
	int lines = 0;
	for (const char *c = out; *c; ++c)
		lines += *c == '\n';
	CHECKF(lines == 3, "%d entries: %s", lines, out);
}

/* The names in a folder besides . and .., space-separated ("" if none). */
static void list_dir(const char *dir, char *out, size_t cap)
{
	out[0] = '\0';
	DIR *d = opendir(dir);
	if (!d)
		return;
	for (struct dirent *ent; (ent = readdir(d));) {
		if (!strcmp(ent->d_name, ".") || !strcmp(ent->d_name, ".."))
			continue;
		size_t len = strlen(out);
		snprintf(out + len, cap - len, "%s%s", len ? " " : "", ent->d_name);
	}
	closedir(d);
}

/* Whether a failed frame left dir clean and named its file; what is wrong
 * is appended to why. */
static void expect_clean_failure(eddy_world *w, eddy_status st, const char *dir, const char *file, char *why,
                                 size_t cap)
{
	char ls[1024];
	size_t len = strlen(why);
	if (st != EDDY_ERR_IO)
		len += (size_t)snprintf(why + len, cap - len, "[%s: status %s, not io] ", file, eddy_status_name(st));
	if (len < cap && !strstr(eddy_world_error(w), file))
		len += (size_t)snprintf(why + len, cap - len, "[message '%s' does not name %s] ", eddy_world_error(w), file);
	if (len < cap && !strstr(eddy_world_error(w), strerror(EFBIG)))
		len +=
			(size_t)snprintf(why + len, cap - len, "[message '%s' lacks '%s'] ", eddy_world_error(w), strerror(EFBIG));
	list_dir(dir, ls, sizeof ls);
	if (len < cap && ls[0])
		snprintf(why + len, cap - len, "[%s: left behind in %s: %s] ", file, dir, ls);
}

/* Files larger than RLIMIT_FSIZE cannot be written (EFBIG once SIGXFSZ is
 * ignored), on any file system and without root. In a forked child, so the
 * limit never touches the runner: every format's frame fails with
 * EDDY_ERR_IO naming the file and the reason, and the folder is left empty
 * (no short file under the final name, no temporary file, no .pvd). */
static void failed_export_leaves_no_file(void)
{
	static const struct {
		eddy_export_format format;
		const char *name;
	} formats[3] = {{EDDY_EXPORT_PLY, "ply"}, {EDDY_EXPORT_VTK, "vtk"}, {EDDY_EXPORT_VTP, "vtp"}};
	const char *b = test_build_dir();
	char cmd[1024], out[256];
	snprintf(cmd, sizeof cmd,
	         "rm -rf %s/t_render/full && mkdir -p %s/t_render/full/ply %s/t_render/full/vtk %s/t_render/full/vtp", b, b,
	         b, b);
	CHECK(test_sh(cmd, out, sizeof out) == 0);
	int fds[2];
	CHECK(pipe(fds) == 0);
	fflush(stdout), fflush(stderr);
	pid_t pid = fork();
	CHECK(pid >= 0);
	if (pid == 0) {
		close(fds[0]);
		char why[4096] = "";
		struct rlimit rl;
		signal(SIGXFSZ, SIG_IGN);
		if (getrlimit(RLIMIT_FSIZE, &rl) != 0 || (rl.rlim_cur = 4096, setrlimit(RLIMIT_FSIZE, &rl)) != 0)
			snprintf(why, sizeof why, "setrlimit: %s", strerror(errno));
		for (int i = 0; i < 3 && !why[0]; ++i) {
			eddy_world_def wd = eddy_default_world_def();
			eddy_world *w = eddy_create_world(&wd, NULL, 0);
			if (!w)
				break;
			eddy_export_particles_def e = eddy_default_export_particles_def();
			e.format = formats[i].format;
			char dir[300], file[400];
			snprintf(dir, sizeof dir, "%s/t_render/full/%s", b, formats[i].name);
			snprintf(e.path, sizeof e.path, "%s/f_%%d.%s", dir, formats[i].name);
			snprintf(file, sizeof file, "%s/f_1.%s", dir, formats[i].name);
			if (!eddy_system_valid(w, eddy_add_export_particles(w, &e))) {
				snprintf(why, sizeof why, "add: %s", eddy_world_error(w));
			} else {
				eddy_vec3 p[1000]; /* 12 kB of positions alone: past the 4 kB limit */
				for (int k = 0; k < 1000; ++k)
					p[k] = (eddy_vec3){0.001f * (float)k, 0.5f, 0.5f};
				if (eddy_world_add_particles(w, 1000, p, NULL) != EDDY_OK)
					snprintf(why, sizeof why, "add particles: %s", eddy_world_error(w));
				else
					expect_clean_failure(w, eddy_world_step_frame(w), dir, file, why, sizeof why);
			}
			eddy_destroy_world(w);
		}
		ssize_t put = write(fds[1], why, strlen(why));
		_exit(put == (ssize_t)strlen(why) ? 0 : 1);
	}
	close(fds[1]);
	char why[4096];
	size_t got = 0;
	for (ssize_t r; got + 1 < sizeof why && (r = read(fds[0], why + got, sizeof why - 1 - got)) > 0;)
		got += (size_t)r;
	why[got] = '\0';
	close(fds[0]);
	int status = 0;
	CHECK(waitpid(pid, &status, 0) == pid);
	CHECKF(WIFEXITED(status) && WEXITSTATUS(status) == 0, "the child did not finish (status %d)", status);
	CHECKF(got == 0, "%s", why);
}

/* A PNG that cannot be written whole is EDDY_ERR_IO naming it and leaves
 * nothing. In this process, not a forked child (a child of a process that
 * has run llvmpipe's threads cannot safely make a GL context): frame 1 is
 * drawn normally, so Mesa has compiled (and cached) its shaders, then frame
 * 2 runs under a 64-byte RLIMIT_FSIZE, restored right after. */
static void failed_png_leaves_no_file(void)
{
	const char *b = test_build_dir();
	char cmd[1024], out[256], dir[300], file[400], why[2048] = "";
	snprintf(dir, sizeof dir, "%s/t_render/fullpng", b);
	snprintf(cmd, sizeof cmd, "rm -rf %s", dir);
	test_sh(cmd, out, sizeof out);
	eddy_world *w = make_world();
	if (!w)
		return;
	const eddy_vec3 p = {0.5f, 0.5f, 0.5f};
	eddy_render_points_def d = base_def("unused_%d.png");
	snprintf(d.path, sizeof d.path, "%s/f_%%d.png", dir);
	CHECK(eddy_system_valid(w, eddy_add_render_points(w, &d)));
	add_particles(w, 1, &p, NULL);
	CHECK(eddy_world_step_frame(w) == EDDY_OK);
	snprintf(file, sizeof file, "%s/f_1.png", dir);
	CHECKF(unlink(file) == 0, "frame 1 was not written: %s", file);
	struct rlimit old, lim;
	CHECK(getrlimit(RLIMIT_FSIZE, &old) == 0);
	lim = old;
	lim.rlim_cur = 64;
	fflush(stdout), fflush(stderr); /* nothing of ours may be written under the limit */
	void (*handler)(int) = signal(SIGXFSZ, SIG_IGN);
	const bool limited = setrlimit(RLIMIT_FSIZE, &lim) == 0;
	const eddy_status st = eddy_world_step_frame(w);
	const bool restored = setrlimit(RLIMIT_FSIZE, &old) == 0;
	signal(SIGXFSZ, handler);
	CHECK(limited && restored);
	snprintf(file, sizeof file, "%s/f_2.png", dir);
	expect_clean_failure(w, st, dir, file, why, sizeof why);
	CHECKF(why[0] == '\0', "%s", why);
	eddy_destroy_world(w);
}

/* ---- frames written in the background (eddy_world_set_background_output) ---- */

/* Whether two PNG files decode to the same pixels; what differs goes to why. */
static bool same_pixels(const char *a, const char *b, char *why, size_t cap)
{
	int wa = 0, ha = 0, wb = 0, hb = 0, c;
	unsigned char *pa = stbi_load(a, &wa, &ha, &c, 3), *pb = stbi_load(b, &wb, &hb, &c, 3);
	bool same = pa && pb && wa == wb && ha == hb && memcmp(pa, pb, (size_t)wa * (size_t)ha * 3) == 0;
	if (!same)
		snprintf(why, cap, "%s (%s, %dx%d) and %s (%s, %dx%d) differ", a, pa ? "read" : "unreadable", wa, ha, b,
		         pb ? "read" : "unreadable", wb, hb);
	stbi_image_free(pa);
	stbi_image_free(pb);
	return same;
}

/* A falling, spreading cloud drawn at every frame by two worlds, one writing
 * in the background, one not: the background world's frames are copies taken
 * at the frame (the particles move on while the writer draws), so every
 * frame is identical pixel for pixel; the files exist once eddy_world_sync
 * returns, and the stats carry each frame's image path. */
static void background_frames_match_synchronous_ones(void)
{
	enum { FRAMES = 8, N = 400 };
	char why[1400] = "";
	for (int bg = 0; bg < 2; ++bg) {
		eddy_world *w = make_world();
		if (!w)
			return;
		eddy_render_points_def d = base_def(bg ? "bg_%d.png" : "fg_%d.png");
		d.width = 160, d.height = 120, d.supersample = 2;
		d.projection = EDDY_PROJECTION_PERSPECTIVE;
		d.eye = d.target; /* framed automatically */
		strcpy(d.color_by, "speed");
		d.outline_domain = true;
		CHECK(eddy_system_valid(w, eddy_add_render_points(w, &d)));
		eddy_gravity_def g = eddy_default_gravity_def();
		CHECK(eddy_system_valid(w, eddy_add_gravity(w, &g)));
		eddy_integrate_def in = eddy_default_integrate_def();
		CHECK(eddy_system_valid(w, eddy_add_integrate(w, &in)));
		eddy_vec3 p[N], v[N];
		for (int i = 0; i < N; ++i) {
			p[i] = (eddy_vec3){0.3f + 0.02f * (float)(i % 20), 0.9f, 0.3f + 0.02f * (float)(i / 20)};
			v[i] = (eddy_vec3){0.2f * (float)(i % 7) - 0.6f, 0.2f * (float)(i % 5), 0.3f * (float)(i % 3) - 0.3f};
		}
		add_particles(w, N, p, v);
		CHECK(eddy_world_set_background_output(w, bg) == EDDY_OK);
		CHECK(eddy_world_background_output(w) == (bool)bg);
		for (int f = 1; f <= FRAMES; ++f) {
			CHECKF(eddy_world_step_frame(w) == EDDY_OK, "frame %d: %s", f, eddy_world_error(w));
			eddy_frame_stats st;
			eddy_world_frame_stats(w, &st);
			char path[600];
			frame_file(path, sizeof path, d.path, f);
			bool named = false;
			for (int k = 0; k < st.extra_count; ++k)
				named |= strcmp(st.extra[k].name, "image") == 0 && st.extra[k].text && !strcmp(st.extra[k].text, path);
			CHECKF(named, "frame %d's stats do not name %s", f, path);
		}
		CHECKF(eddy_world_sync(w) == EDDY_OK, "sync: %s", eddy_world_error(w));
		eddy_destroy_world(w);
	}
	for (int f = 1; f <= FRAMES && !why[0]; ++f) {
		char a[600], b[600];
		out_path(a, sizeof a, "fg_%d.png");
		out_path(b, sizeof b, "bg_%d.png");
		char fa[600], fb[600];
		frame_file(fa, sizeof fa, a, f);
		frame_file(fb, sizeof fb, b, f);
		same_pixels(fa, fb, why, sizeof why);
	}
	CHECKF(why[0] == '\0', "%s", why);
}

/* In the background a failed write is still the failed frame's error: with
 * writes limited to 64 bytes (RLIMIT_FSIZE, as in failed_png_leaves_no_file)
 * frame 2 is queued, and eddy_world_sync returns EDDY_ERR_IO naming frame 2
 * and its file, leaving neither it nor a temporary file; the failure is
 * returned once, and frame 3 is written again once writes are allowed. */
static void background_write_failure_names_its_frame(void)
{
	const char *b = test_build_dir();
	char cmd[1024], out[256], dir[300], file[400], why[2048] = "";
	snprintf(dir, sizeof dir, "%s/t_render/bgfull", b);
	snprintf(cmd, sizeof cmd, "rm -rf %s", dir);
	test_sh(cmd, out, sizeof out);
	eddy_world *w = make_world();
	if (!w)
		return;
	const eddy_vec3 p = {0.5f, 0.5f, 0.5f};
	eddy_render_points_def d = base_def("unused_%d.png");
	snprintf(d.path, sizeof d.path, "%s/f_%%d.png", dir);
	CHECK(eddy_system_valid(w, eddy_add_render_points(w, &d)));
	add_particles(w, 1, &p, NULL);
	CHECK(eddy_world_set_background_output(w, true) == EDDY_OK);
	CHECK(eddy_world_step_frame(w) == EDDY_OK);
	CHECK(eddy_world_sync(w) == EDDY_OK);
	snprintf(file, sizeof file, "%s/f_1.png", dir);
	CHECKF(unlink(file) == 0, "frame 1 was not written: %s", file);
	struct rlimit old, lim;
	CHECK(getrlimit(RLIMIT_FSIZE, &old) == 0);
	lim = old;
	lim.rlim_cur = 64;
	fflush(stdout), fflush(stderr);
	void (*handler)(int) = signal(SIGXFSZ, SIG_IGN);
	const bool limited = setrlimit(RLIMIT_FSIZE, &lim) == 0;
	const eddy_status stepped = eddy_world_step_frame(w);
	const eddy_status synced = eddy_world_sync(w);
	const bool restored = setrlimit(RLIMIT_FSIZE, &old) == 0;
	signal(SIGXFSZ, handler);
	CHECK(limited && restored);
	CHECKF(stepped == EDDY_OK, "frame 2's step waited for its write: %s", eddy_world_error(w));
	snprintf(file, sizeof file, "%s/f_2.png", dir);
	expect_clean_failure(w, synced, dir, file, why, sizeof why);
	CHECKF(why[0] == '\0', "%s", why);
	CHECK_HAS(eddy_world_error(w), "render_points: frame 2: cannot write");
	CHECK(eddy_world_sync(w) == EDDY_OK); /* returned once */
	CHECKF(eddy_world_step_frame(w) == EDDY_OK, "frame 3: %s", eddy_world_error(w));
	CHECK(eddy_world_sync(w) == EDDY_OK);
	snprintf(file, sizeof file, "%s/f_3.png", dir);
	struct stat sb;
	CHECKF(stat(file, &sb) == 0, "frame 3 was not written: %s", file);
	eddy_destroy_world(w);
}

/* eddy run writes frames in the background (EDDY_SYNC_FRAMES=1: not): the
 * bounce scene (particles, a moving sphere's outline) gives the same pixels
 * either way, every frame is there, written in frame order (modification
 * times never go backwards); a run resumed from a checkpoint gives the same
 * frames as one that was not stopped; a write that fails (RLIMIT_FSIZE from
 * the shell, SIGXFSZ ignored) stops the run with status 1 and one line
 * naming the frame and its file. */
static void command_frames_in_the_background(void)
{
	enum { FRAMES = 6 };
	const char *b = test_build_dir();
	char cmd[2048], out[4096], why[1400] = "";
	snprintf(cmd, sizeof cmd,
	         "rm -rf %s/t_render/bgrun && "
	         "EDDY_SYNC_FRAMES=1 %s/eddy run scenes/bounce.lua --frames %d --out %s/t_render/bgrun/sync --quiet && "
	         "%s/eddy run scenes/bounce.lua --frames %d --out %s/t_render/bgrun/async --quiet --threads 1 && "
	         "%s/eddy run scenes/bounce.lua --frames 3 --out %s/t_render/bgrun/resumed --quiet --checkpoint-every 3 && "
	         "%s/eddy run scenes/bounce.lua --frames %d --out %s/t_render/bgrun/resumed --quiet "
	         "--resume %s/t_render/bgrun/resumed",
	         b, b, FRAMES, b, b, FRAMES, b, b, b, b, FRAMES, b, b);
	CHECKF(test_sh(cmd, out, sizeof out) == 0, "%s", out);
	struct timespec last = {0, 0};
	for (int f = 1; f <= FRAMES && !why[0]; ++f) {
		char a[600], s[600], r[600];
		snprintf(s, sizeof s, "%s/t_render/bgrun/sync/frame_%04d.png", b, f);
		snprintf(a, sizeof a, "%s/t_render/bgrun/async/frame_%04d.png", b, f);
		snprintf(r, sizeof r, "%s/t_render/bgrun/resumed/frame_%04d.png", b, f);
		if (same_pixels(s, a, why, sizeof why))
			same_pixels(s, r, why, sizeof why);
		struct stat st;
		if (!why[0] && stat(a, &st) == 0) {
			if (st.st_mtim.tv_sec < last.tv_sec ||
			    (st.st_mtim.tv_sec == last.tv_sec && st.st_mtim.tv_nsec < last.tv_nsec))
				snprintf(why, sizeof why, "%s was written before frame %d", a, f - 1);
			last = st.st_mtim;
		}
	}
	CHECKF(why[0] == '\0', "%s", why);

	snprintf(cmd, sizeof cmd,
	         "trap '' XFSZ; ulimit -f 8; %s/eddy run scenes/bounce.lua --frames 3 --out %s/t_render/bgrun/full --quiet",
	         b, b);
	CHECK(test_sh(cmd, out, sizeof out) == 1);
	CHECK_HAS(out, "eddy: render_points: frame 1: cannot write '");
	CHECK_HAS(out, "t_render/bgrun/full/frame_0001.png': ");
	CHECK_HAS(out, strerror(EFBIG));
	CHECK(strchr(out, '\n') == strrchr(out, '\n')); /* one line */
	char ls[1024], dir[400];
	snprintf(dir, sizeof dir, "%s/t_render/bgrun/full", b);
	list_dir(dir, ls, sizeof ls);
	CHECKF(strcmp(ls, ".eddy.lock") == 0, "left in %s: %s", dir, ls);
}

/* NULL world or def: an invalid id and no crash (with a world, the error
 * says which); an unknown format, "all" mixed with names. */
static void null_world_or_def_is_an_invalid_id(void)
{
	eddy_render_points_def d = eddy_default_render_points_def();
	eddy_export_particles_def e = eddy_default_export_particles_def();
	CHECK(!eddy_system_valid(NULL, eddy_add_render_points(NULL, &d)));
	CHECK(!eddy_system_valid(NULL, eddy_add_export_particles(NULL, &e)));
	CHECK(!eddy_system_valid(NULL, eddy_add_render_points(NULL, NULL)));
	CHECK(!eddy_system_valid(NULL, eddy_add_export_particles(NULL, NULL)));
	eddy_world *w = make_world();
	if (!w)
		return;
	eddy_system_id id = eddy_add_render_points(w, NULL);
	CHECK(!eddy_system_valid(w, id) && id.index == 0 && id.generation == 0);
	CHECK_HAS(eddy_world_error(w), "render_points: def is NULL");
	id = eddy_add_export_particles(w, NULL);
	CHECK(!eddy_system_valid(w, id) && id.index == 0 && id.generation == 0);
	CHECK_HAS(eddy_world_error(w), "export_particles: def is NULL");
	e.format = (eddy_export_format)7;
	CHECK(!eddy_system_valid(w, eddy_add_export_particles(w, &e)));
	CHECK_HAS(eddy_world_error(w), "'format' must be ply, vtk or vtp");
	e = eddy_default_export_particles_def();
	strcpy(e.channels, "all vx");
	CHECK(!eddy_system_valid(w, eddy_add_export_particles(w, &e)));
	CHECK_HAS(eddy_world_error(w), "\"all\" stands alone");
	CHECK(eddy_world_system_count(w) == 0);
	eddy_destroy_world(w);
}

/* ---- Lua and the command ---- */

static void lua_scene_renders_and_exports(void)
{
	lua_State *L = luaL_newstate();
	luaL_openlibs(L);
	luaL_requiref(L, "eddy", luaopen_eddy, 0);
	lua_pop(L, 1);
	char dir[512], chunk[2048];
	snprintf(dir, sizeof dir, "%s/t_render/lua", test_build_dir());
	eddy_lua_set_out_dir(L, dir);
	snprintf(chunk, sizeof chunk,
	         "local eddy = require 'eddy'\n"
	         "local w = eddy.world{}\n"
	         "w:add(eddy.emit_box{ min = {0.3,0.3,0.3}, max = {0.7,0.7,0.7}, spacing = 0.05 })\n"
	         "w:add(eddy.gravity{})\nw:add(eddy.integrate{})\nw:add(eddy.collide_box{})\n"
	         "w:add(eddy.render_points{ width = 64, height = 48, colormap = 'plasma', radius = 0.02,\n"
	         "                          path = eddy.out_dir('x') .. '/f_%%02d.png', every = 2 })\n"
	         "w:add(eddy.export_particles{ format = 'vtk', channels = {'vy', 'speed'},\n"
	         "                             path = eddy.out_dir('x') .. '/p_%%02d.vtk' })\n"
	         "w:add(eddy.export_particles{ format = 'vtp', path = eddy.out_dir('x') .. '/q_%%02d.vtp' })\n"
	         "w:advance(4 / 30)\n"
	         "local ok, err = pcall(eddy.render_points, { colour_by = 'speed' })\n"
	         "assert(not ok and err:find(\"unknown field 'colour_by'\"), err)\n"
	         "ok, err = pcall(eddy.export_particles, { channels = {'vx', 3} })\n"
	         "assert(not ok and err:find('must be a list of strings'), err)\n"
	         "ok, err = pcall(eddy.export_particles, { format = 'obj' })\n"
	         "assert(not ok and err:find('\\'format\\' must be \"ply\", \"vtk\" or \"vtp\" (got obj)', 1, true), err)\n"
	         "ok, err = pcall(eddy.render_points, { projection = 'fisheye' })\n"
	         "assert(not ok and err:find('perspective'), err)\n"
	         "return w\n");
	int rc = luaL_dostring(L, chunk);
	CHECKF(rc == LUA_OK, "lua: %s", rc == LUA_OK ? "" : lua_tostring(L, -1));
	static const char *const files[] = {"f_02.png", "f_04.png", "p_01.vtk", "p_04.vtk", "q_04.vtp", "q.pvd"};
	for (int i = 0; i < 6; ++i) {
		char path[700];
		snprintf(path, sizeof path, "%s/%s", dir, files[i]);
		struct stat st;
		CHECKF(stat(path, &st) == 0 && st.st_size > 0, "missing %s", path);
	}
	char path[700];
	snprintf(path, sizeof path, "%s/f_01.png", dir);
	struct stat st;
	CHECKF(stat(path, &st) != 0, "every = 2 rendered frame 1");
	lua_close(L);
}

/* bounce renders into --out; --video says when ffmpeg is missing and pipes
 * PNG frames to it when present (here a stand-in that keeps what it gets);
 * a GL failure is one line and exit status 1. */
static void command_renders_and_pipes_video(void)
{
	const char *b = test_build_dir();
	char cmd[2048], out[4096], path[600];
	snprintf(cmd, sizeof cmd,
	         "rm -rf %s/t_render/cli && %s/eddy run scenes/bounce.lua --frames 2 --out %s/t_render/cli --quiet", b, b,
	         b);
	CHECKF(test_sh(cmd, out, sizeof out) == 0, "%s", out);
	snprintf(path, sizeof path, "%s/t_render/cli/frame_0002.png", b);
	int iw = 0, ih = 0, comp;
	unsigned char *px = stbi_load(path, &iw, &ih, &comp, 3);
	CHECKF(px && iw == 960 && ih == 540, "bounce frame %s (%dx%d)", path, iw, ih);
	stbi_image_free(px);

	snprintf(
		cmd, sizeof cmd,
		"PATH=/nonexistent %s/eddy run scenes/bounce.lua --frames 1 --out %s/t_render/cli --video %s/t_render/v.mp4", b,
		b, b);
	CHECK(test_sh(cmd, out, sizeof out) == 1);
	CHECK_HAS(out, "ffmpeg is not installed");
	CHECK(strchr(out, '\n') == strrchr(out, '\n')); /* one line */

	snprintf(cmd, sizeof cmd,
	         "mkdir -p %s/t_render/fakebin && printf '#!/bin/sh\\ncat > \"$EDDY_FAKE_FFMPEG\"\\n' > "
	         "%s/t_render/fakebin/ffmpeg && "
	         "chmod +x %s/t_render/fakebin/ffmpeg && EDDY_FAKE_FFMPEG=%s/t_render/piped PATH=%s/t_render/fakebin:$PATH "
	         "%s/eddy run scenes/bounce.lua --frames 3 --out %s/t_render/cli --video %s/t_render/v.mp4 --quiet",
	         b, b, b, b, b, b, b, b);
	CHECKF(test_sh(cmd, out, sizeof out) == 0, "%s", out);
	snprintf(path, sizeof path, "%s/t_render/piped", b);
	size_t n = 0;
	unsigned char *data = slurp(path, &n);
	CHECK(data != NULL);
	if (data) {
		int pngs = 0;
		for (size_t i = 0; i + 8 <= n; ++i)
			pngs += memcmp(data + i, "\x89PNG\r\n\x1a\n", 8) == 0;
		CHECKF(pngs == 3, "ffmpeg got %d PNGs, expected 3", pngs);
		free(data);
	}

	snprintf(cmd, sizeof cmd,
	         "EDDY_RENDER_FAIL_CONTEXT=1 %s/eddy run scenes/surface.lua --frames 1 --set points=false --out "
	         "%s/t_render/cli_surface --quiet",
	         b, b);
	CHECK(test_sh(cmd, out, sizeof out) == 1);
	CHECK_HAS(out, "eddy: render_surface");
	CHECK_HAS(out, "cannot create an OpenGL context with OSMesa");
}

/* ---- the CPU splatter against llvmpipe ---- */

typedef struct diff_stats {
	double mean;  /* mean |difference| over all channels, of 255 */
	double over8; /* fraction of pixels with a channel off by more than 8 */
	int max;
} diff_stats;

static diff_stats compare_rgb(const uint8_t *a, const uint8_t *b, size_t pixels)
{
	diff_stats d = {0, 0, 0};
	size_t over = 0;
	double sum = 0;
	for (size_t i = 0; i < pixels; ++i) {
		int worst = 0;
		for (int c = 0; c < 3; ++c) {
			const int e = abs((int)a[3 * i + c] - (int)b[3 * i + c]);
			sum += e;
			worst = e > worst ? e : worst;
		}
		over += worst > 8;
		d.max = worst > d.max ? worst : d.max;
	}
	d.mean = sum / (3.0 * (double)pixels);
	d.over8 = (double)over / (double)pixels;
	return d;
}

/* A dense, overlapping cloud of coloured spheres with a box outline and a
 * few lines through it, as render_points draws it, once through llvmpipe
 * (gl_osmesa.c's sprite and line shaders) and once through the CPU splatter
 * (render/splat.c), box-filtered by 2. The images agree within the
 * rasterisers' rounding: at most 0.05 grey levels on average and at most
 * 0.2% of the pixels off by more than 8 levels (measured 0.004-0.007 and
 * 0.013-0.018%: pixels whose centre falls on a sprite's or line's edge, and
 * where two spheres' depths tie within the 24-bit depth buffer's step). The
 * same images one pixel apart differ by 8 levels on average and in 20% of the
 * pixels, so a flipped axis, a wrong shading term or a sphere a pixel too
 * large fails; measured figures are printed. Perspective and orthographic, and the splatter on 1
 * and 3 threads, and its one-pixel-at-a-time path (the AVX2 one draws eight),
 * give the same bytes. */
static void splat_matches_gl(void)
{
	enum { W = 240, H = 160, S = 2, N = 3000 };
	char err[256];
	eddy_gl *gl = eddy_gl_create(W * S, H * S, err, sizeof err);
	CHECKF(gl != NULL, "%s", err);
	eddy_splat sp;
	CHECK(eddy_splat_init(&sp, W * S, H * S) == 0);
	float *x = malloc(N * sizeof *x), *y = malloc(N * sizeof *y), *z = malloc(N * sizeof *z);
	uint8_t *rgb = malloc(4 * N), *a = malloc(W * H * 3), *b = malloc(W * H * 3), *c = malloc(W * H * 3);
	if (!gl || !x || !y || !z || !rgb || !a || !b || !c)
		goto done;
	uint64_t r = 99;
	for (int i = 0; i < N; ++i) {
		float u[4];
		for (int k = 0; k < 4; ++k) {
			r = r * 6364136223846793005ull + 1442695040888963407ull;
			u[k] = (float)(r >> 40) / (float)(1 << 24);
		}
		x[i] = u[0], y[i] = 0.6f * u[1], z[i] = u[2];
		eddy_colormap_rgb(EDDY_COLORMAP_VIRIDIS, u[3], rgb + 4 * i);
		rgb[4 * i + 3] = 255;
	}
	float lines[15 * 6];
	eddy_box_edges(lines, (eddy_vec3){0, 0, 0}, (eddy_vec3){1, 1, 1});
	const float extra[3][6] = {
		{0, 0.3f, 0.5f, 1, 0.35f, 0.4f}, {0.2f, 0, 0.2f, 0.25f, 1, 0.8f}, {0.5f, 0.5f, -2, 0.5f, 0.5f, 3}};
	memcpy(lines + 12 * 6, extra, sizeof extra);
	eddy_world_def wd = eddy_default_world_def();
	for (int ortho = 0; ortho < 2; ++ortho) {
		eddy_view_def vd = {
			W,         H,         S,     {0, 0, 0},
			{0, 0, 0}, {0, 1, 0}, 40.0f, ortho ? EDDY_PROJECTION_ORTHOGRAPHIC : EDDY_PROJECTION_PERSPECTIVE,
			0.0f,      0.024f,    0.024f};
		eddy_camera cam;
		eddy_camera_make(&vd, &wd, &cam);
		eddy_gl_lines ls = {lines, 15, {0.6f, 0.62f, 0.66f}, 1.5f * S};
		eddy_gl_scene sc;
		memset(&sc, 0, sizeof sc);
		memcpy(sc.view, cam.view, sizeof sc.view);
		memcpy(sc.proj, cam.proj, sizeof sc.proj);
		sc.background[0] = 0.11f, sc.background[1] = 0.12f, sc.background[2] = 0.14f;
		eddy_key_light(sc.light);
		sc.radius = 0.012f;
		sc.count = N;
		sc.x = x, sc.y = y, sc.z = z;
		sc.rgb = rgb;
		sc.lines = &ls;
		sc.line_sets = 1;
		CHECKF(eddy_gl_draw(gl, &sc, err, sizeof err) == 0, "%s", err);
		eddy_downsample_rows(eddy_gl_pixels(gl), W, H, S, a, 0, H);
		CHECKF(eddy_splat_draw(&sp, &sc, 1, S, b, err, sizeof err) == 0, "%s", err);
		CHECKF(eddy_splat_draw(&sp, &sc, 3, S, c, err, sizeof err) == 0, "%s", err);
		CHECK(memcmp(b, c, W * H * 3) == 0);
		/* one pixel at a time: the same bytes as eight at a time */
		sp.scalar = true;
		CHECKF(eddy_splat_draw(&sp, &sc, 2, S, c, err, sizeof err) == 0, "%s", err);
		sp.scalar = false;
		CHECK(memcmp(b, c, W * H * 3) == 0);
		const diff_stats d = compare_rgb(a, b, (size_t)W * H);
		printf("    %s: mean |diff| %.3f levels, %.3f%% of pixels off by > 8, max %d\n",
		       ortho ? "orthographic" : "perspective", d.mean, 100 * d.over8, d.max);
		CHECKF(d.mean <= 0.05 && d.over8 <= 0.002, "%s: mean %.3f, %.3f%% over 8", ortho ? "ortho" : "persp", d.mean,
		       100 * d.over8);
		/* the same scene one pixel off tells the test apart from a blur */
		if (!ortho) {
			const diff_stats shifted = compare_rgb(a + 3, b, (size_t)W * H - 1);
			printf("    shifted by a pixel: mean %.3f, %.3f%% over 8\n", shifted.mean, 100 * shifted.over8);
			CHECK(shifted.mean > 2 * d.mean && shifted.over8 > 2 * d.over8);
		}
	}
done:
	free(x), free(y), free(z), free(rgb), free(a), free(b), free(c);
	eddy_splat_free(&sp);
	eddy_gl_destroy(gl);
}

/* A collider's rotation (degrees about an axis through its pivot) turns its
 * drawn outline and mesh: 90 degrees about z takes pivot + (1, 0, 0) to
 * pivot + (0, 1, 0), 120 degrees about (1, 1, 1) cycles the axes, and a zero
 * rotation leaves points where they are. */
static void collider_rotation_turns_drawn_points(void)
{
	float p[9] = {2, 1, 1, 1, 0, 0, 0, 1, 0};
	eddy_rotate_points(p, 1, (eddy_vec3){0, 0, 90}, (eddy_vec3){1, 1, 1});
	CHECK_NEAR(p[0], 1, 1e-6);
	CHECK_NEAR(p[1], 2, 1e-6);
	CHECK_NEAR(p[2], 1, 1e-6);
	const float d = 120.0f / sqrtf(3.0f);
	eddy_rotate_points(p + 3, 2, (eddy_vec3){d, d, d}, (eddy_vec3){0, 0, 0});
	CHECK_NEAR(p[3], 0, 1e-6);
	CHECK_NEAR(p[4], 1, 1e-6);
	CHECK_NEAR(p[5], 0, 1e-6);
	CHECK_NEAR(p[6], 0, 1e-6);
	CHECK_NEAR(p[7], 0, 1e-6);
	CHECK_NEAR(p[8], 1, 1e-6);
	float q[3] = {0.25f, -3, 7};
	eddy_rotate_points(q, 1, (eddy_vec3){0, 0, 0}, (eddy_vec3){5, 5, 5});
	CHECK(q[0] == 0.25f && q[1] == -3 && q[2] == 7);
}

void suite_render(void)
{
	char dir[512];
	snprintf(dir, sizeof dir, "%s/t_render", test_build_dir());
	mkdir(dir, 0777);
	RUN(splat_matches_gl);
	RUN(collider_rotation_turns_drawn_points);
	RUN(particle_lands_on_its_projected_pixel);
	RUN(nearer_spheres_occlude_farther_ones);
	RUN(colour_map_is_applied);
	RUN(background_where_nothing_is_drawn);
	RUN(png_round_trip_and_pinned_hash);
	RUN(png_writer_round_trips);
	RUN(no_gl_context_is_a_clear_error);
	RUN(unwritable_path_is_an_io_error);
	RUN(bad_defs_are_rejected);
	RUN(ply_parses_back);
	RUN(vtk_parses_back);
	RUN(ply_round_trip_is_bit_exact);
	RUN(vtp_reads_back_with_vtk);
	RUN(vtp_collection_survives_a_resume);
	RUN(failed_export_leaves_no_file);
	RUN(failed_png_leaves_no_file);
	RUN(null_world_or_def_is_an_invalid_id);
	RUN(lua_scene_renders_and_exports);
	RUN(command_renders_and_pipes_video);
	RUN(background_frames_match_synchronous_ones);
	RUN(background_write_failure_names_its_frame);
	RUN(command_frames_in_the_background);
}
