#define _POSIX_C_SOURCE 200809L
/* The renderer and the particle exports: particles land on the pixels the
 * camera projects them to, nearer spheres hide farther ones whatever the draw
 * order, the colour map is applied, the background shows where nothing is
 * drawn; PNGs read back (stb_image) with a pinned hash; a GL context failure
 * is a clear eddy_status, not a crash; PLY and VTK files parse back to the
 * values written; the Lua binding and the eddy command's --video. */
#include "test.h"

#include <lauxlib.h>
#include <lualib.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/wait.h>

#include "eddy.h"
#include "eddy_lua.h"

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

static const unsigned char *pixel(const image *im, int x, int y) { return im->px + ((size_t)y * (size_t)im->w + (size_t)x) * 3; }

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
 * pixels, whose hash is pinned (Debian 12's Mesa 22.3 llvmpipe). */
#define PINNED_IMAGE_HASH 0x29d388e13771a6bdull

static uint64_t fixed_scene_hash(const char *name)
{
	eddy_world *w = make_world();
	if (!w)
		return 0;
	eddy_vec3 p[512], v[512];
	for (int i = 0; i < 512; ++i) {
		p[i] = (eddy_vec3){0.1f + 0.1f * (float)(i % 8), 0.1f + 0.1f * (float)((i / 8) % 8), 0.1f + 0.1f * (float)(i / 64)};
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

static void png_round_trip_and_pinned_hash(void)
{
	uint64_t a = fixed_scene_hash("hash_a_%d.png"), b = fixed_scene_hash("hash_b_%d.png");
	CHECK(a != 0);
	CHECKF(a == b, "the same scene rendered twice differs: %016llx vs %016llx", (unsigned long long)a,
	       (unsigned long long)b);
	CHECKF(a == PINNED_IMAGE_HASH, "image hash %016llx, pinned %016llx (a different Mesa may round differently)",
	       (unsigned long long)a, (unsigned long long)PINNED_IMAGE_HASH);
}

/* No GL context: the frame returns EDDY_ERR_EXTERNAL and says why; the world
 * stays usable and is destroyed cleanly. EDDY_RENDER_FAIL_CONTEXT forces the
 * failure through the same path as a failing OSMesaCreateContextAttribs. */
static void no_gl_context_is_a_clear_error(void)
{
	setenv("EDDY_RENDER_FAIL_CONTEXT", "1", 1);
	eddy_world *w = make_world();
	if (w) {
		const eddy_vec3 p = {0.5f, 0.5f, 0.5f};
		eddy_render_points_def d = base_def("nogl_%d.png");
		eddy_system_id id = eddy_add_render_points(w, &d);
		add_particles(w, 1, &p, NULL);
		CHECK(eddy_system_valid(w, id));
		eddy_status st = eddy_world_step_frame(w);
		CHECK(st == EDDY_ERR_EXTERNAL);
		CHECK_HAS(eddy_world_error(w), "render_points");
		CHECK_HAS(eddy_world_error(w), "cannot create an OpenGL context with OSMesa");
		CHECK(eddy_world_remove_system(w, id) == EDDY_OK);
		CHECK(eddy_world_step_frame(w) == EDDY_OK);
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
static const eddy_vec3 exp_pos[NP] = {{0.1f, 0.2f, 0.3f}, {0.9f, 0.8f, 0.7f}, {0.5f, 0.5f, 0.5f}, {0.25f, 0.125f, 0.0625f}, {1e-3f, 0.999f, 0.33f}};
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
	CHECK(sscanf(line(&p, end, buf, sizeof buf), "VERTICES %ld %ld", &cells, &size) == 2 && cells == NP && size == 2 * NP);
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
	         "w:advance(4 / 30)\n"
	         "local ok, err = pcall(eddy.render_points, { colour_by = 'speed' })\n"
	         "assert(not ok and err:find(\"unknown field 'colour_by'\"), err)\n"
	         "ok, err = pcall(eddy.export_particles, { channels = {'vx', 3} })\n"
	         "assert(not ok and err:find('must be a list of strings'), err)\n"
	         "ok, err = pcall(eddy.render_points, { projection = 'fisheye' })\n"
	         "assert(not ok and err:find('perspective'), err)\n"
	         "return w\n");
	int rc = luaL_dostring(L, chunk);
	CHECKF(rc == LUA_OK, "lua: %s", rc == LUA_OK ? "" : lua_tostring(L, -1));
	static const char *const files[] = {"f_02.png", "f_04.png", "p_01.vtk", "p_04.vtk"};
	for (int i = 0; i < 4; ++i) {
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
	snprintf(cmd, sizeof cmd, "rm -rf %s/t_render/cli && %s/eddy run scenes/bounce.lua --frames 2 --out %s/t_render/cli --quiet",
	         b, b, b);
	CHECKF(test_sh(cmd, out, sizeof out) == 0, "%s", out);
	snprintf(path, sizeof path, "%s/t_render/cli/frame_0002.png", b);
	int iw = 0, ih = 0, comp;
	unsigned char *px = stbi_load(path, &iw, &ih, &comp, 3);
	CHECKF(px && iw == 960 && ih == 540, "bounce frame %s (%dx%d)", path, iw, ih);
	stbi_image_free(px);

	snprintf(cmd, sizeof cmd, "PATH=/nonexistent %s/eddy run scenes/bounce.lua --frames 1 --out %s/t_render/cli --video %s/t_render/v.mp4",
	         b, b, b);
	CHECK(test_sh(cmd, out, sizeof out) == 1);
	CHECK_HAS(out, "ffmpeg is not installed");
	CHECK(strchr(out, '\n') == strrchr(out, '\n')); /* one line */

	snprintf(cmd, sizeof cmd,
	         "mkdir -p %s/t_render/fakebin && printf '#!/bin/sh\\ncat > \"$EDDY_FAKE_FFMPEG\"\\n' > %s/t_render/fakebin/ffmpeg && "
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

	snprintf(cmd, sizeof cmd, "EDDY_RENDER_FAIL_CONTEXT=1 %s/eddy run scenes/bounce.lua --frames 1 --out %s/t_render/cli --quiet",
	         b, b);
	CHECK(test_sh(cmd, out, sizeof out) == 1);
	CHECK_HAS(out, "eddy: render_points: frame 1: ");
	CHECK_HAS(out, "cannot create an OpenGL context with OSMesa");
}

void suite_render(void)
{
	char dir[512];
	snprintf(dir, sizeof dir, "%s/t_render", test_build_dir());
	mkdir(dir, 0777);
	RUN(particle_lands_on_its_projected_pixel);
	RUN(nearer_spheres_occlude_farther_ones);
	RUN(colour_map_is_applied);
	RUN(background_where_nothing_is_drawn);
	RUN(png_round_trip_and_pinned_hash);
	RUN(no_gl_context_is_a_clear_error);
	RUN(unwritable_path_is_an_io_error);
	RUN(bad_defs_are_rejected);
	RUN(ply_parses_back);
	RUN(vtk_parses_back);
	RUN(lua_scene_renders_and_exports);
	RUN(command_renders_and_pipes_video);
}
