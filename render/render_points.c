/* SPDX-License-Identifier: MIT */
/* render_points: the headless particle renderer, a frame-only custom system.
 *
 * Reads: x y z, plus vx vy vz (color_by = "speed") or the color_by column.
 * Writes: nothing; a PNG per rendered frame, and the frame stats values
 * render_ms (GL draw), png_ms (encoding and writing) and image (the path).
 *
 * At every `every`-th frame time: colour each particle (colour map of its
 * value, t = (v - min) / (max - min), range fixed or the frame's own), build
 * the camera (look-at view; perspective or orthographic projection with near
 * and far planes fitted to the world's bounds), draw the spheres and outlines
 * at supersample times the size, box-filter down and write the PNG. The GL
 * context is made at the first frame, so plans and checks never need one. */
#define _POSIX_C_SOURCE 200809L
#include "render.h"

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#define CIRCLE_SEGMENTS 96
#define PI_F 3.14159265358979f

typedef struct renderer {
	eddy_render_points_def def;
	eddy_gl *gl;
	float *values;    /* scratch for derived channels (speed) */
	uint8_t *rgb;     /* per-particle colours, RGBA (4-byte aligned fetches are llvmpipe's fast path) */
	size_t cap;       /* particles the scratch holds */
	uint8_t *image;   /* the final RGB image, top row first */
	float *lines;     /* outline segments, 6 floats each */
	size_t line_cap;  /* segments */
} renderer;

eddy_render_points_def eddy_default_render_points_def(void)
{
	eddy_render_points_def d;
	memset(&d, 0, sizeof d);
	d.width = 960;
	d.height = 540;
	d.supersample = 2;
	d.eye = (eddy_vec3){0, 0, 0};
	d.target = (eddy_vec3){0, 0, 0};
	d.up = (eddy_vec3){0, 1, 0};
	d.fov = 40.0f;
	d.projection = EDDY_PROJECTION_PERSPECTIVE;
	d.ortho_height = 0.0f;
	d.background = (eddy_vec3){0.11f, 0.12f, 0.14f};
	d.radius = 0.01f;
	strcpy(d.color_by, "speed");
	d.color = (eddy_vec3){0.2f, 0.45f, 0.85f};
	d.colormap = EDDY_COLORMAP_VIRIDIS;
	d.value_min = NAN;
	d.value_max = NAN;
	d.outline_domain = true;
	d.outline_colliders = true;
	d.outline_color = (eddy_vec3){0.6f, 0.62f, 0.66f};
	strcpy(d.path, "frame_%04d.png");
	d.every = 1;
	return d;
}

/* ---- small vector and matrix helpers (column-major 4x4) ---- */

static eddy_vec3 sub3(eddy_vec3 a, eddy_vec3 b) { return (eddy_vec3){a.x - b.x, a.y - b.y, a.z - b.z}; }
static eddy_vec3 add3(eddy_vec3 a, eddy_vec3 b) { return (eddy_vec3){a.x + b.x, a.y + b.y, a.z + b.z}; }
static eddy_vec3 scale3(eddy_vec3 a, float s) { return (eddy_vec3){a.x * s, a.y * s, a.z * s}; }
static float dot3(eddy_vec3 a, eddy_vec3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
static float len3(eddy_vec3 a) { return sqrtf(dot3(a, a)); }
static eddy_vec3 cross3(eddy_vec3 a, eddy_vec3 b)
{
	return (eddy_vec3){a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
static eddy_vec3 norm3(eddy_vec3 a)
{
	float l = len3(a);
	return l > 0 ? scale3(a, 1.0f / l) : a;
}

typedef struct camera {
	eddy_vec3 eye, fwd, side, up; /* orthonormal frame */
	float view[16], proj[16];
} camera;

static bool finite3(eddy_vec3 v) { return isfinite(v.x) && isfinite(v.y) && isfinite(v.z); }
static bool color_ok(eddy_vec3 c)
{
	return c.x >= 0 && c.x <= 1 && c.y >= 0 && c.y <= 1 && c.z >= 0 && c.z <= 1;
}

/* The camera the def asks for; eye == target frames the world's bounds from
 * the front, a little right and above, so a scene needs no camera to look right. */
static void make_camera(const eddy_render_points_def *d, const eddy_world_def *wd, camera *c)
{
	const eddy_vec3 lo = wd->bounds_min, hi = wd->bounds_max;
	const eddy_vec3 center = scale3(add3(lo, hi), 0.5f);
	const float R = 0.5f * len3(sub3(hi, lo));
	const float aspect = (float)d->width / (float)d->height;
	const float half_fov = 0.5f * d->fov * (PI_F / 180.0f);
	eddy_vec3 eye = d->eye, target = d->target;
	const bool automatic = eye.x == target.x && eye.y == target.y && eye.z == target.z;
	if (automatic) {
		/* back off along a fixed direction until every corner of the bounds is
		 * inside the frustum: corner q (from the centre) at depth D + q.f needs
		 * |q.s| <= (D + q.f) tan(half width angle), the same for q.u vertically */
		target = center;
		const eddy_vec3 back = norm3((eddy_vec3){0.42f, 0.38f, 1.0f});
		const eddy_vec3 f = scale3(back, -1.0f), sd = norm3(cross3(f, d->up)), u = cross3(sd, f);
		const float tv = tanf(half_fov), th = tv * aspect;
		float D = 0;
		for (int k = 0; k < 8; ++k) {
			eddy_vec3 q = sub3((eddy_vec3){(k & 1) ? hi.x : lo.x, (k & 2) ? hi.y : lo.y, (k & 4) ? hi.z : lo.z}, center);
			float qf = dot3(q, f), need_s = fabsf(dot3(q, sd)) / th - qf, need_u = fabsf(dot3(q, u)) / tv - qf;
			D = need_s > D ? need_s : D;
			D = need_u > D ? need_u : D;
		}
		eye = add3(center, scale3(back, 1.06f * D + 2.0f * d->radius));
	}
	c->eye = eye;
	c->fwd = norm3(sub3(target, eye));
	c->side = norm3(cross3(c->fwd, d->up));
	c->up = cross3(c->side, c->fwd);
	float *v = c->view;
	memset(v, 0, 16 * sizeof *v);
	v[0] = c->side.x, v[4] = c->side.y, v[8] = c->side.z, v[12] = -dot3(c->side, eye);
	v[1] = c->up.x, v[5] = c->up.y, v[9] = c->up.z, v[13] = -dot3(c->up, eye);
	v[2] = -c->fwd.x, v[6] = -c->fwd.y, v[10] = -c->fwd.z, v[14] = dot3(c->fwd, eye);
	v[15] = 1;
	/* near and far planes around the bounds (particles live inside them) */
	float dmin = INFINITY, dmax = -INFINITY, smax = 0, umax = 0;
	for (int k = 0; k < 8; ++k) {
		eddy_vec3 p = {(k & 1) ? hi.x : lo.x, (k & 2) ? hi.y : lo.y, (k & 4) ? hi.z : lo.z};
		eddy_vec3 q = sub3(p, eye);
		float depth = dot3(q, c->fwd);
		dmin = depth < dmin ? depth : dmin;
		dmax = depth > dmax ? depth : dmax;
		float s = fabsf(dot3(sub3(p, target), c->side)), u = fabsf(dot3(sub3(p, target), c->up));
		smax = s > smax ? s : smax;
		umax = u > umax ? u : umax;
	}
	const float margin = 0.05f * (dmax - dmin) + 2.0f * d->radius + 1e-3f * R;
	float farp = dmax + margin, nearp = dmin - margin;
	float *p = c->proj;
	memset(p, 0, 16 * sizeof *p);
	if (d->projection == EDDY_PROJECTION_ORTHOGRAPHIC) {
		float hh = 0.5f * d->ortho_height;
		if (!(hh > 0))
			hh = 1.05f * (umax > smax / aspect ? umax : smax / aspect);
		p[0] = 1.0f / (hh * aspect);
		p[5] = 1.0f / hh;
		p[10] = -2.0f / (farp - nearp);
		p[14] = -(farp + nearp) / (farp - nearp);
		p[15] = 1;
	} else {
		if (nearp < 1e-3f * farp)
			nearp = 1e-3f * farp; /* the camera is inside the bounds */
		const float f = 1.0f / tanf(half_fov);
		p[0] = f / aspect;
		p[5] = f;
		p[10] = (farp + nearp) / (nearp - farp);
		p[11] = -1;
		p[14] = 2 * farp * nearp / (nearp - farp);
	}
}

/* ---- outlines ---- */

static bool reserve_lines(renderer *r, size_t segments)
{
	if (segments <= r->line_cap)
		return true;
	float *l = realloc(r->lines, segments * 6 * sizeof *l);
	if (!l)
		return false;
	r->lines = l;
	r->line_cap = segments;
	return true;
}

static void box_edges(float *out, eddy_vec3 lo, eddy_vec3 hi)
{
	/* corner k has x from bit 0, y from bit 1, z from bit 2; an edge flips one bit */
	int e = 0;
	for (int k = 0; k < 8; ++k)
		for (int bit = 1; bit < 8; bit <<= 1) {
			if (k & bit)
				continue;
			int k2 = k | bit;
			float *o = out + 6 * e++;
			o[0] = (k & 1) ? hi.x : lo.x, o[1] = (k & 2) ? hi.y : lo.y, o[2] = (k & 4) ? hi.z : lo.z;
			o[3] = (k2 & 1) ? hi.x : lo.x, o[4] = (k2 & 2) ? hi.y : lo.y, o[5] = (k2 & 4) ? hi.z : lo.z;
		}
}

/* The sphere's silhouette: the circle where the cone from the eye touches it
 * (centre c - (r^2/d) u, radius r sqrt(1 - r^2/d^2)); a plain great circle
 * facing the camera for orthographic views. */
static int sphere_silhouette(float *out, eddy_vec3 c, float rad, const camera *cam, bool ortho)
{
	eddy_vec3 u = cam->fwd, center = c;
	float rr = rad;
	if (!ortho) {
		eddy_vec3 to = sub3(c, cam->eye);
		float d = len3(to);
		if (d <= rad)
			return 0; /* the eye is inside the sphere */
		u = scale3(to, 1.0f / d);
		center = sub3(c, scale3(u, rad * rad / d));
		rr = rad * sqrtf(1.0f - rad * rad / (d * d));
	}
	eddy_vec3 a = norm3(cross3(u, fabsf(u.y) < 0.9f ? (eddy_vec3){0, 1, 0} : (eddy_vec3){1, 0, 0}));
	eddy_vec3 b = cross3(u, a);
	for (int i = 0; i < CIRCLE_SEGMENTS; ++i) {
		float t0 = (2.0f * PI_F) * (float)i / CIRCLE_SEGMENTS, t1 = (2.0f * PI_F) * (float)(i + 1) / CIRCLE_SEGMENTS;
		eddy_vec3 p0 = add3(center, add3(scale3(a, rr * cosf(t0)), scale3(b, rr * sinf(t0))));
		eddy_vec3 p1 = add3(center, add3(scale3(a, rr * cosf(t1)), scale3(b, rr * sinf(t1))));
		float *o = out + 6 * i;
		o[0] = p0.x, o[1] = p0.y, o[2] = p0.z, o[3] = p1.x, o[4] = p1.y, o[5] = p1.z;
	}
	return CIRCLE_SEGMENTS;
}

/* Fills r->lines; returns the segment count or -1 when out of memory. */
static long build_outlines(renderer *r, eddy_world *w, const camera *cam)
{
	const eddy_render_points_def *d = &r->def;
	size_t n = 0;
	if (d->outline_domain) {
		if (!reserve_lines(r, 12))
			return -1;
		const eddy_world_def *wd = eddy_world_get_def(w);
		box_edges(r->lines, wd->bounds_min, wd->bounds_max);
		n = 12;
	}
	if (!d->outline_colliders)
		return (long)n;
	const int systems = eddy_world_system_count(w);
	for (int i = 0; i < systems; ++i) {
		eddy_collider_shape shape;
		if (eddy_collider_shape_of(w, eddy_world_system_at(w, i), &shape) != EDDY_OK)
			continue; /* not a collider */
		if (!reserve_lines(r, n + CIRCLE_SEGMENTS))
			return -1;
		if (shape.kind == EDDY_COLLIDER_BOX)
			box_edges(r->lines + 6 * n, shape.a, shape.b), n += 12;
		else if (shape.kind == EDDY_COLLIDER_SPHERE)
			n += (size_t)sphere_silhouette(r->lines + 6 * n, shape.a, shape.radius, cam,
			                               d->projection == EDDY_PROJECTION_ORTHOGRAPHIC);
		/* planes are unbounded and other shapes undescribed: no outline */
	}
	return (long)n;
}

/* ---- the frame ---- */

static double now_ms(void)
{
	struct timespec ts;
	clock_gettime(CLOCK_MONOTONIC, &ts);
	return (double)ts.tv_sec * 1e3 + (double)ts.tv_nsec * 1e-6;
}

static bool reserve_particles(renderer *r, size_t n)
{
	if (n <= r->cap)
		return true;
	size_t cap = n + n / 4;
	float *v = realloc(r->values, cap * sizeof *v);
	if (v)
		r->values = v;
	uint8_t *c = realloc(r->rgb, cap * 4);
	if (c)
		r->rgb = c;
	if (!v || !c)
		return false;
	r->cap = cap;
	return true;
}

static eddy_status colour_particles(renderer *r, eddy_world *w, size_t n)
{
	const eddy_render_points_def *d = &r->def;
	if (!d->color_by[0]) {
		const uint8_t c[4] = {(uint8_t)lrintf(d->color.x * 255), (uint8_t)lrintf(d->color.y * 255),
		                      (uint8_t)lrintf(d->color.z * 255), 255};
		for (size_t i = 0; i < n; ++i)
			memcpy(r->rgb + 4 * i, c, 4);
		return EDDY_OK;
	}
	const float *v = eddy_particle_values(w, d->color_by, r->values, n);
	if (!v)
		return eddy_world_fail(w, EDDY_ERR_INVALID, "color_by '%s' is not available", d->color_by);
	float lo = d->value_min, hi = d->value_max;
	if (isnan(lo) || isnan(hi)) {
		float mn = INFINITY, mx = -INFINITY;
		for (size_t i = 0; i < n; ++i)
			if (isfinite(v[i])) {
				mn = v[i] < mn ? v[i] : mn;
				mx = v[i] > mx ? v[i] : mx;
			}
		if (isnan(lo))
			lo = isfinite(mn) ? mn : 0;
		if (isnan(hi))
			hi = isfinite(mx) ? mx : 1;
	}
	/* a uniform field gets the bottom colour instead of a division by zero */
	const float inv = hi > lo ? 1.0f / (hi - lo) : 0.0f;
	for (size_t i = 0; i < n; ++i) {
		eddy_colormap_rgb(d->colormap, (v[i] - lo) * inv, r->rgb + 4 * i);
		r->rgb[4 * i + 3] = 255;
	}
	return EDDY_OK;
}

static void downsample(const uint8_t *rgba, int W, int H, int s, uint8_t *out)
{
	const int sw = W * s, sh = H * s, area = s * s;
	for (int y = 0; y < H; ++y)
		for (int x = 0; x < W; ++x) {
			unsigned sum[3] = {0, 0, 0};
			for (int j = 0; j < s; ++j) {
				/* GL rows run bottom-up, PNG rows top-down */
				const uint8_t *row = rgba + (size_t)(sh - 1 - (y * s + j)) * (size_t)sw * 4;
				for (int i = 0; i < s; ++i)
					for (int c = 0; c < 3; ++c)
						sum[c] += row[(size_t)(x * s + i) * 4 + (size_t)c];
			}
			uint8_t *o = out + ((size_t)y * (size_t)W + (size_t)x) * 3;
			for (int c = 0; c < 3; ++c)
				o[c] = (uint8_t)((sum[c] + (unsigned)area / 2) / (unsigned)area);
		}
}

static eddy_status render_frame(eddy_world *w, int frame, void *user)
{
	renderer *r = user;
	const eddy_render_points_def *d = &r->def;
	if (frame % d->every != 0)
		return EDDY_OK;
	const int s = d->supersample;
	char err[512];
	if (!r->gl) {
		r->gl = eddy_gl_create(d->width * s, d->height * s, err, sizeof err);
		if (!r->gl)
			return eddy_world_fail(w, EDDY_ERR_EXTERNAL, "%s", err);
	}
	size_t n = eddy_world_particle_count(w), cnt = 0;
	const float *x = NULL, *y = NULL, *z = NULL;
	if (n > 0) {
		x = eddy_world_channel(w, "x", &cnt);
		y = eddy_world_channel(w, "y", &cnt);
		z = eddy_world_channel(w, "z", &cnt);
		if (!x || !y || !z)
			return eddy_world_fail(w, EDDY_ERR_INVALID, "the positions x y z are not allocated");
		if (!reserve_particles(r, n))
			return eddy_world_fail(w, EDDY_ERR_NOMEM, "out of memory for %zu particle colours", n);
		eddy_status st = colour_particles(r, w, n);
		if (st != EDDY_OK)
			return st;
	}
	camera cam;
	make_camera(d, eddy_world_get_def(w), &cam);
	long segments = build_outlines(r, w, &cam);
	if (segments < 0)
		return eddy_world_fail(w, EDDY_ERR_NOMEM, "out of memory for outlines");
	eddy_gl_lines lines = {r->lines, (size_t)segments, {d->outline_color.x, d->outline_color.y, d->outline_color.z},
	                       1.5f * (float)s};
	eddy_gl_scene scene;
	memset(&scene, 0, sizeof scene);
	memcpy(scene.view, cam.view, sizeof scene.view);
	memcpy(scene.proj, cam.proj, sizeof scene.proj);
	scene.background[0] = d->background.x, scene.background[1] = d->background.y, scene.background[2] = d->background.z;
	/* key light from the upper left, in front of the camera */
	const float lx = -0.38f, ly = 0.62f, lz = 0.69f, ll = sqrtf(lx * lx + ly * ly + lz * lz);
	scene.light[0] = lx / ll, scene.light[1] = ly / ll, scene.light[2] = lz / ll;
	scene.radius = d->radius;
	scene.count = n;
	scene.x = x, scene.y = y, scene.z = z;
	scene.rgb = r->rgb;
	scene.lines = &lines;
	scene.line_sets = segments > 0 ? 1 : 0;

	const double t0 = now_ms();
	if (eddy_gl_draw(r->gl, &scene, err, sizeof err) != 0)
		return eddy_world_fail(w, EDDY_ERR_EXTERNAL, "%s", err);
	const double t1 = now_ms();
	if (!r->image) {
		r->image = malloc((size_t)d->width * (size_t)d->height * 3);
		if (!r->image)
			return eddy_world_fail(w, EDDY_ERR_NOMEM, "out of memory for a %dx%d image", d->width, d->height);
	}
	downsample(eddy_gl_pixels(r->gl), d->width, d->height, s, r->image);
	char path[1024];
	if (eddy_frame_path(d->path, frame, path, sizeof path) != 0)
		return eddy_world_fail(w, EDDY_ERR_IO, "the image path for frame %d is too long", frame);
	/* creates the folders too; a failure leaves no file under path */
	const int werr = eddy_write_png(path, d->width, d->height, r->image);
	if (werr != 0)
		return eddy_world_fail(w, EDDY_ERR_IO, "cannot write '%s': %s", path, strerror(werr));
	const double t2 = now_ms();
	eddy_world_publish(w, "render_ms", t1 - t0);
	eddy_world_publish(w, "png_ms", t2 - t1);
	eddy_world_publish_text(w, "image", path);
	return EDDY_OK;
}

static void destroy(void *user)
{
	renderer *r = user;
	eddy_gl_destroy(r->gl);
	free(r->values);
	free(r->rgb);
	free(r->image);
	free(r->lines);
	free(r);
}

/* "<system>: '<field>' must be ..." like the built-in systems. */
#define BAD(...) (eddy_world_fail(w, EDDY_ERR_INVALID, __VA_ARGS__), EDDY_NULL_SYSTEM)

eddy_system_id eddy_add_render_points(eddy_world *w, const eddy_render_points_def *def)
{
	const char *sys = "render_points";
	if (!w)
		return EDDY_NULL_SYSTEM;
	if (!def)
		return BAD("%s: def is NULL", sys);
	const eddy_render_points_def *d = def;
	if (d->width < 1 || d->width > 8192)
		return BAD("%s: 'width' must be in [1, 8192] px (got %d)", sys, d->width);
	if (d->height < 1 || d->height > 8192)
		return BAD("%s: 'height' must be in [1, 8192] px (got %d)", sys, d->height);
	if (d->supersample < 1 || d->supersample > 4)
		return BAD("%s: 'supersample' must be in [1, 4] (got %d)", sys, d->supersample);
	if ((long)d->width * d->supersample > 16384 || (long)d->height * d->supersample > 16384)
		return BAD("%s: 'width' and 'height' times 'supersample' must be <= 16384 px", sys);
	if (!finite3(d->eye) || !finite3(d->target) || !finite3(d->up))
		return BAD("%s: 'eye', 'target' and 'up' must be finite", sys);
	if (!(d->fov > 0 && d->fov < 180))
		return BAD("%s: 'fov' must be in (0, 180) degrees (got %g)", sys, (double)d->fov);
	if (d->projection != EDDY_PROJECTION_PERSPECTIVE && d->projection != EDDY_PROJECTION_ORTHOGRAPHIC)
		return BAD("%s: 'projection' must be perspective or orthographic", sys);
	if (!(d->ortho_height >= 0) || !isfinite(d->ortho_height))
		return BAD("%s: 'ortho_height' must be >= 0 m (got %g)", sys, (double)d->ortho_height);
	if (!(d->radius > 0) || !isfinite(d->radius))
		return BAD("%s: 'radius' must be > 0 m (got %g)", sys, (double)d->radius);
	if (!color_ok(d->background))
		return BAD("%s: 'background' must be an RGB colour with components in [0, 1]", sys);
	if (!color_ok(d->color))
		return BAD("%s: 'color' must be an RGB colour with components in [0, 1]", sys);
	if (!color_ok(d->outline_color))
		return BAD("%s: 'outline_color' must be an RGB colour with components in [0, 1]", sys);
	if ((unsigned)d->colormap > EDDY_COLORMAP_GRAY)
		return BAD("%s: 'colormap' must be viridis, plasma or gray", sys);
	if (isinf(d->value_min) || isinf(d->value_max) || (d->value_min >= d->value_max))
		return BAD("%s: 'value_min' must be below 'value_max' (got %g and %g); NaN means automatic", sys,
		           (double)d->value_min, (double)d->value_max);
	if (d->every < 1)
		return BAD("%s: 'every' must be >= 1 frame (got %d)", sys, d->every);
	if (!memchr(d->path, '\0', sizeof d->path) || !memchr(d->color_by, '\0', sizeof d->color_by))
		return BAD("%s: 'path' and 'color_by' must be NUL-terminated", sys);
	const char *why = eddy_check_frame_pattern(d->path);
	if (why)
		return BAD("%s: 'path' %s (got \"%s\")", sys, why, d->path);
	if (d->eye.x != d->target.x || d->eye.y != d->target.y || d->eye.z != d->target.z) {
		eddy_vec3 f = norm3(sub3(d->target, d->eye));
		if (len3(cross3(f, norm3(d->up))) < 1e-4f)
			return BAD("%s: 'up' must not be parallel to the view direction (eye to target)", sys);
	} else if (len3(d->up) == 0) {
		return BAD("%s: 'up' must not be zero", sys);
	}

	/* the columns it reads, so the plan shows them and they are allocated */
	const char *reads[6] = {"x", "y", "z", "vx", "vy", "vz"};
	int nreads = 3;
	const char *by = strcmp(d->color_by, "none") == 0 ? "" : d->color_by;
	if (strcmp(by, "speed") == 0) {
		nreads = 6;
	} else if (by[0]) {
		eddy_column_id id = eddy_world_find_column(w, by);
		eddy_column_info info;
		if (id < 0 || eddy_world_column_info(w, id, &info) != EDDY_OK)
			return BAD("%s: 'color_by' must be \"speed\", \"\" (constant 'color') or a particle column (no column "
			           "named '%s')", sys, by);
		if (info.domain != EDDY_DOMAIN_PARTICLE || info.type != EDDY_F32)
			return BAD("%s: 'color_by' column '%s' is not a per-particle number column", sys, by);
		if (strcmp(by, "x") && strcmp(by, "y") && strcmp(by, "z"))
			reads[nreads++] = by;
	}
	renderer *r = calloc(1, sizeof *r);
	if (!r) {
		eddy_world_fail(w, EDDY_ERR_NOMEM, "%s: out of memory", sys);
		return EDDY_NULL_SYSTEM;
	}
	r->def = *d;
	if (!by[0])
		r->def.color_by[0] = '\0';
	eddy_custom_system_def cd = eddy_default_custom_system_def();
	cd.name = sys;
	cd.reads = reads;
	cd.read_count = nreads;
	cd.frame = render_frame;
	cd.destroy = destroy;
	cd.user = r;
	eddy_system_id id = eddy_add_custom_system(w, &cd);
	if (!eddy_system_valid(w, id))
		destroy(r);
	return id;
}
