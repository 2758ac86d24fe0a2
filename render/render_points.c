/* SPDX-License-Identifier: MIT */
/* render_points: the headless particle renderer, a frame-only custom system.
 *
 * Reads: x y z, plus vx vy vz (color_by = "speed") or the color_by column.
 * Writes: nothing; a PNG per rendered frame, and the frame stats values
 * render_ms (colouring, drawing and the box filter), png_ms (encoding and
 * writing) and image (the path).
 *
 * At every `every`-th frame time the frame hook copies what the frame needs:
 * positions, the colour values, the camera (render/view.c: look-at view;
 * perspective or orthographic projection with near and far planes fitted to
 * the world's bounds), the outlines and the world's thread count. A writer
 * thread of the renderer's own then colours each particle (colour map of its
 * value, t = (v - min) / (max - min), range fixed or the frame's own), draws
 * the spheres and outlines at supersample times the size on the CPU
 * (render/splat.c, the same pixels as the GL sprite shader of gl_osmesa.c,
 * in as many row bands as the world has threads), box-filters down and writes
 * the PNG (render/png.c). The buffers are made on that thread at the first
 * rendered frame, so plans and checks never need them.
 *
 * With the world's background output off the hook waits for its frame, so
 * the PNG is on disk when the step returns and a failure is that frame's
 * status. On, the hook returns once the copy is queued (at most JOBS frames
 * wait; the hook blocks while they do) and the drawing overlaps the next
 * frames' steps; a failure is returned by the next hook or by
 * eddy_world_sync, naming its frame. render_ms and png_ms are then the
 * newest finished frame's, published once each. */
#define _POSIX_C_SOURCE 200809L
#include "render.h"

#include <errno.h>
#include <math.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#define CIRCLE_SEGMENTS 96
#define PI_F 3.14159265358979f

/* Outline segments, 6 floats (two world points, m) each. */
typedef struct line_buf {
	float *xyz;
	size_t cap; /* segments */
} line_buf;

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

static eddy_view_def view_def(const eddy_render_points_def *d)
{
	/* a sphere reaches a radius out of the bounds; the eye keeps two away */
	return (eddy_view_def){d->width, d->height,     d->supersample,  d->eye,           d->target,       d->up,
	                       d->fov,   d->projection, d->ortho_height, 2.0f * d->radius, 2.0f * d->radius};
}

/* ---- outlines ---- */

static bool reserve_lines(line_buf *b, size_t segments)
{
	if (segments <= b->cap)
		return true;
	float *l = realloc(b->xyz, segments * 6 * sizeof *l);
	if (!l)
		return false;
	b->xyz = l;
	b->cap = segments;
	return true;
}

/* The sphere's silhouette: the circle where the cone from the eye touches it
 * (centre c - (r^2/d) u, radius r sqrt(1 - r^2/d^2)); a plain great circle
 * facing the camera for orthographic views. */
static int sphere_silhouette(float *out, eddy_vec3 c, float rad, const eddy_camera *cam, bool ortho)
{
	eddy_vec3 u = cam->fwd, center = c;
	float rr = rad;
	if (!ortho) {
		eddy_vec3 to = eddy_v3_sub(c, cam->eye);
		float d = eddy_v3_len(to);
		if (d <= rad)
			return 0; /* the eye is inside the sphere */
		u = eddy_v3_scale(to, 1.0f / d);
		center = eddy_v3_sub(c, eddy_v3_scale(u, rad * rad / d));
		rr = rad * sqrtf(1.0f - rad * rad / (d * d));
	}
	eddy_vec3 a = eddy_v3_norm(eddy_v3_cross(u, fabsf(u.y) < 0.9f ? (eddy_vec3){0, 1, 0} : (eddy_vec3){1, 0, 0}));
	eddy_vec3 b = eddy_v3_cross(u, a);
	for (int i = 0; i < CIRCLE_SEGMENTS; ++i) {
		float t0 = (2.0f * PI_F) * (float)i / CIRCLE_SEGMENTS, t1 = (2.0f * PI_F) * (float)(i + 1) / CIRCLE_SEGMENTS;
		eddy_vec3 p0 =
			eddy_v3_add(center, eddy_v3_add(eddy_v3_scale(a, rr * cosf(t0)), eddy_v3_scale(b, rr * sinf(t0))));
		eddy_vec3 p1 =
			eddy_v3_add(center, eddy_v3_add(eddy_v3_scale(a, rr * cosf(t1)), eddy_v3_scale(b, rr * sinf(t1))));
		float *o = out + 6 * i;
		o[0] = p0.x, o[1] = p0.y, o[2] = p0.z, o[3] = p1.x, o[4] = p1.y, o[5] = p1.z;
	}
	return CIRCLE_SEGMENTS;
}

/* Fills b; returns the segment count or -1 when out of memory. */
static long build_outlines(line_buf *b, const eddy_render_points_def *d, eddy_world *w, const eddy_camera *cam)
{
	size_t n = 0;
	if (d->outline_domain) {
		if (!reserve_lines(b, 12))
			return -1;
		const eddy_world_def *wd = eddy_world_get_def(w);
		eddy_box_edges(b->xyz, wd->bounds_min, wd->bounds_max);
		n = 12;
	}
	if (!d->outline_colliders)
		return (long)n;
	const int systems = eddy_world_system_count(w);
	for (int i = 0; i < systems; ++i) {
		eddy_collider_shape shape;
		if (eddy_collider_shape_of(w, eddy_world_system_at(w, i), &shape) != EDDY_OK)
			continue; /* not a collider */
		if (!reserve_lines(b, n + CIRCLE_SEGMENTS))
			return -1;
		if (shape.kind == EDDY_COLLIDER_BOX) {
			eddy_box_edges(b->xyz + 6 * n, shape.a, shape.b);
			eddy_rotate_points(b->xyz + 6 * n, 24, shape.rotation, shape.pivot);
			n += 12;
		} else if (shape.kind == EDDY_COLLIDER_SPHERE)
			n += (size_t)sphere_silhouette(b->xyz + 6 * n, shape.a, shape.radius, cam,
			                               d->projection == EDDY_PROJECTION_ORTHOGRAPHIC);
		else if (shape.kind != EDDY_COLLIDER_PLANE) {
			/* any other kind (a mesh collider): the box around the zero level
			 * of its distance, sampled coarsely (1/32 of the bounds); one that
			 * cannot be meshed gets no outline rather than failing the frame */
			eddy_mesh m = {0};
			const eddy_world_def *wd = eddy_world_get_def(w);
			const eddy_vec3 ext = eddy_v3_sub(wd->bounds_max, wd->bounds_min);
			const float cell = fmaxf(ext.x, fmaxf(ext.y, ext.z)) / 32;
			if (eddy_collider_mesh(w, eddy_world_system_at(w, i), cell, &m) == EDDY_OK && m.vertex_count > 0) {
				eddy_vec3 lo = {INFINITY, INFINITY, INFINITY}, hi = {-INFINITY, -INFINITY, -INFINITY};
				for (size_t v = 0; v < m.vertex_count; ++v) {
					const float *q = m.xyz + 3 * v;
					lo = (eddy_vec3){fminf(lo.x, q[0]), fminf(lo.y, q[1]), fminf(lo.z, q[2])};
					hi = (eddy_vec3){fmaxf(hi.x, q[0]), fmaxf(hi.y, q[1]), fmaxf(hi.z, q[2])};
				}
				eddy_box_edges(b->xyz + 6 * n, lo, hi), n += 12;
			}
			eddy_mesh_free(&m);
		}
		/* planes are unbounded: no outline */
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

/* Grows a buffer to hold n elements of size bytes; false when out of memory
 * (the old buffer stays). */
static bool reserve(void **p, size_t *cap, size_t n, size_t size)
{
	if (n <= *cap)
		return true;
	size_t c = n + n / 4;
	void *q = realloc(*p, c * size);
	if (!q)
		return false;
	*p = q;
	*cap = c;
	return true;
}

/* Colours from the snapshot's values (NULL: the constant colour), RGBA. */
static void colour_particles(const eddy_render_points_def *d, const float *v, size_t n, uint8_t *rgb)
{
	if (!v) {
		const uint8_t c[4] = {(uint8_t)lrintf(d->color.x * 255), (uint8_t)lrintf(d->color.y * 255),
		                      (uint8_t)lrintf(d->color.z * 255), 255};
		for (size_t i = 0; i < n; ++i)
			memcpy(rgb + 4 * i, c, 4);
		return;
	}
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
		eddy_colormap_rgb(d->colormap, (v[i] - lo) * inv, rgb + 4 * i);
		rgb[4 * i + 3] = 255;
	}
}

/* ---- the writer thread -------------------------------------------------------
 *
 * Frames are drawn and written on a thread of the renderer's own, which alone
 * creates and uses the GL context. The frame hook (the stepping thread) fills
 * a job with copies of what the frame needs (positions, colour values, camera,
 * outlines, the path) and queues it; with background output off it then waits
 * for that job, so the files are on disk when the step returns; on, it
 * returns at once and the job is drawn while the next frames step. The queue
 * holds JOBS jobs; the hook waits for a free one, so a slow disk slows the
 * run instead of filling memory. Jobs are done in order, so files appear in
 * frame order. A failed job's message is kept until the hook or the sync
 * returns it (one failure is returned once; later frames go on being written).
 *
 * Locking: mu guards head, queued, busy-state and the result fields; a job
 * between head and head + queued belongs to the writer, the others to the
 * stepping thread. */

#define JOBS 2

typedef struct job {
	int frame;
	char path[1024];
	size_t count, count_cap;
	float *x, *y, *z; /* m, copies of the positions */
	float *values;    /* color_by's values, or NULL for the constant colour */
	size_t values_cap;
	line_buf lines;
	size_t segments;
	float view[16], proj[16];
	int threads; /* the world's thread count: the drawing's bands */
	bool has_values;
} job;

typedef struct renderer {
	eddy_render_points_def def;
	/* the stepping thread's */
	eddy_system_id id; /* this system, for its label */
	bool started;      /* the writer thread runs */
	float *speed;      /* scratch for the speed of the newest job */
	size_t speed_cap;
	int published; /* the newest frame whose times went into the stats */
	/* shared, under mu */
	pthread_t thread;
	pthread_mutex_t mu;
	pthread_cond_t cv;
	job jobs[JOBS];
	int head, queued; /* jobs[head .. head + queued) wait or are being drawn */
	bool quit;
	int ready;                /* 0 while the buffers are being made, 1 made, -1 failed (msg holds why) */
	eddy_status failed;       /* a failure not yet returned, EDDY_OK if none */
	int failed_frame;         /* its frame */
	char msg[512];            /* its reason (or the buffers', ready < 0) */
	int done;                 /* the newest frame written */
	double render_ms, png_ms; /* its times */
	/* the writer thread's */
	eddy_splat splat; /* the supersampled colour and depth buffers */
	uint8_t *rgb;     /* per-particle colours, RGBA */
	size_t rgb_cap;
	uint8_t *image; /* the final RGB image, top row first */
} renderer;

/* Draws and writes one job; 0, or -1 with the status in st and the reason in err. */
static int draw_job(renderer *r, const job *j, double *render_ms, double *png_ms, eddy_status *st, char *err,
                    size_t cap)
{
	const eddy_render_points_def *d = &r->def;
	const int s = d->supersample;
	char why[512];
	const double t0 = now_ms();
	if (j->count > 0) {
		if (!reserve((void **)&r->rgb, &r->rgb_cap, j->count, 4)) {
			*st = EDDY_ERR_NOMEM;
			snprintf(err, cap, "out of memory for %zu particle colours", j->count);
			return -1;
		}
		colour_particles(d, j->has_values ? j->values : NULL, j->count, r->rgb);
	}
	eddy_gl_lines lines = {
		j->lines.xyz, j->segments, {d->outline_color.x, d->outline_color.y, d->outline_color.z}, 1.5f * (float)s};
	eddy_gl_scene scene;
	memset(&scene, 0, sizeof scene);
	memcpy(scene.view, j->view, sizeof scene.view);
	memcpy(scene.proj, j->proj, sizeof scene.proj);
	scene.background[0] = d->background.x, scene.background[1] = d->background.y, scene.background[2] = d->background.z;
	eddy_key_light(scene.light);
	scene.radius = d->radius;
	scene.count = j->count;
	scene.x = j->x, scene.y = j->y, scene.z = j->z;
	scene.rgb = r->rgb;
	scene.lines = &lines;
	scene.line_sets = j->segments > 0 ? 1 : 0;

	if (eddy_splat_draw(&r->splat, &scene, j->threads, s, r->image, why, sizeof why) != 0) {
		*st = EDDY_ERR_INVALID;
		snprintf(err, cap, "%s", why);
		return -1;
	}
	const double t1 = now_ms();
	/* creates the folders too; a failure leaves no file under path */
	const int werr = eddy_write_png(j->path, d->width, d->height, r->image);
	if (werr != 0) {
		*st = EDDY_ERR_IO;
		snprintf(err, cap, "cannot write '%s': %s", j->path, strerror(werr));
		return -1;
	}
	*render_ms = t1 - t0;
	*png_ms = now_ms() - t1;
	return 0;
}

static void *writer_main(void *arg)
{
	renderer *r = arg;
	const int s = r->def.supersample;
	char err[512];
	const int W = r->def.width, H = r->def.height;
	bool ok = eddy_splat_init(&r->splat, W * s, H * s) == 0;
	r->image = ok ? malloc((size_t)W * (size_t)H * 3) : NULL;
	ok = ok && r->image;
	pthread_mutex_lock(&r->mu);
	r->ready = ok ? 1 : -1;
	if (!ok)
		snprintf(r->msg, sizeof r->msg, "out of memory for a %dx%d image (supersample %d)", W, H, s);
	pthread_cond_broadcast(&r->cv);
	for (;;) {
		while (r->queued == 0 && !r->quit)
			pthread_cond_wait(&r->cv, &r->mu);
		if (r->queued == 0)
			break; /* quit with nothing left to write */
		const job *j = &r->jobs[r->head];
		pthread_mutex_unlock(&r->mu);
		double render_ms = 0, png_ms = 0;
		eddy_status st = EDDY_OK;
		int rc = -1;
		if (ok)
			rc = draw_job(r, j, &render_ms, &png_ms, &st, err, sizeof err);
		else
			st = EDDY_ERR_NOMEM, snprintf(err, sizeof err, "%s", r->msg);
		pthread_mutex_lock(&r->mu);
		if (rc == 0) {
			r->done = j->frame;
			r->render_ms = render_ms;
			r->png_ms = png_ms;
		} else if (r->failed == EDDY_OK) {
			r->failed = st;
			r->failed_frame = j->frame;
			snprintf(r->msg, sizeof r->msg, "%s", err);
		}
		r->head = (r->head + 1) % JOBS;
		r->queued--;
		pthread_cond_broadcast(&r->cv);
	}
	pthread_mutex_unlock(&r->mu);
	return NULL;
}

/* Returns a failure the writer kept, once; call with mu held. */
static eddy_status take_failure(renderer *r, eddy_world *w)
{
	eddy_status st = r->failed;
	if (st == EDDY_OK)
		return EDDY_OK;
	r->failed = EDDY_OK;
	/* the message names the failed frame, which may be earlier than the
	 * world's, and starts with the label, so the world adds no other */
	char msg[512];
	snprintf(msg, sizeof msg, "%s", r->msg);
	const int frame = r->failed_frame;
	pthread_mutex_unlock(&r->mu);
	eddy_system_info info;
	const char *label = eddy_world_system_info(w, r->id, &info) == EDDY_OK ? info.label : "render_points";
	eddy_world_fail(w, st, "%s: frame %d: %s", label, frame, msg);
	pthread_mutex_lock(&r->mu);
	return st;
}

/* Starts the writer and waits for its GL context: a context that cannot be
 * made is the first rendered frame's failure, as it always was. */
static eddy_status start_writer(renderer *r, eddy_world *w)
{
	if (pthread_create(&r->thread, NULL, writer_main, r) != 0)
		return eddy_world_fail(w, EDDY_ERR_NOMEM, "cannot start the frame writer thread");
	r->started = true;
	pthread_mutex_lock(&r->mu);
	while (r->ready == 0)
		pthread_cond_wait(&r->cv, &r->mu);
	pthread_mutex_unlock(&r->mu);
	return EDDY_OK;
}

/* Fills a job with copies of what the frame needs (the stepping thread). */
static eddy_status fill_job(renderer *r, eddy_world *w, job *j, int frame)
{
	const eddy_render_points_def *d = &r->def;
	j->frame = frame;
	if (eddy_frame_path(d->path, frame, j->path, sizeof j->path) != 0)
		return eddy_world_fail(w, EDDY_ERR_IO, "the image path for frame %d is too long", frame);
	const size_t n = eddy_world_particle_count(w);
	size_t cnt = 0;
	j->count = n;
	j->has_values = false;
	if (n > 0) {
		const float *x = eddy_world_channel(w, "x", &cnt), *y = eddy_world_channel(w, "y", &cnt),
					*z = eddy_world_channel(w, "z", &cnt);
		if (!x || !y || !z)
			return eddy_world_fail(w, EDDY_ERR_INVALID, "the positions x y z are not allocated");
		size_t cap = j->count_cap;
		bool ok = reserve((void **)&j->x, &cap, n, sizeof(float));
		cap = j->count_cap;
		ok = ok && reserve((void **)&j->y, &cap, n, sizeof(float));
		cap = j->count_cap;
		ok = ok && reserve((void **)&j->z, &cap, n, sizeof(float));
		if (!ok)
			return eddy_world_fail(w, EDDY_ERR_NOMEM, "out of memory for %zu particle positions", n);
		j->count_cap = cap;
		memcpy(j->x, x, n * sizeof(float));
		memcpy(j->y, y, n * sizeof(float));
		memcpy(j->z, z, n * sizeof(float));
		if (d->color_by[0]) {
			if (!reserve((void **)&r->speed, &r->speed_cap, n, sizeof(float)) ||
			    !reserve((void **)&j->values, &j->values_cap, n, sizeof(float)))
				return eddy_world_fail(w, EDDY_ERR_NOMEM, "out of memory for %zu particle values", n);
			const float *v = eddy_particle_values(w, d->color_by, r->speed, n);
			if (!v)
				return eddy_world_fail(w, EDDY_ERR_INVALID, "color_by '%s' is not available", d->color_by);
			memcpy(j->values, v, n * sizeof(float));
			j->has_values = true;
		}
	}
	eddy_camera cam;
	const eddy_view_def vd = view_def(d);
	eddy_camera_make(&vd, eddy_world_get_def(w), &cam);
	j->threads = eddy_world_get_def(w)->threads;
	memcpy(j->view, cam.view, sizeof j->view);
	memcpy(j->proj, cam.proj, sizeof j->proj);
	long segments = build_outlines(&j->lines, d, w, &cam);
	if (segments < 0)
		return eddy_world_fail(w, EDDY_ERR_NOMEM, "out of memory for outlines");
	j->segments = (size_t)segments;
	return EDDY_OK;
}

/* The newest finished frame's times into the stats, once per frame drawn;
 * call with mu held. */
static void publish_times(renderer *r, eddy_world *w)
{
	if (r->done <= r->published)
		return;
	r->published = r->done;
	eddy_world_publish(w, "render_ms", r->render_ms);
	eddy_world_publish(w, "png_ms", r->png_ms);
}

static eddy_status render_frame(eddy_world *w, int frame, void *user)
{
	renderer *r = user;
	const eddy_render_points_def *d = &r->def;
	pthread_mutex_lock(&r->mu);
	eddy_status st = take_failure(r, w);
	pthread_mutex_unlock(&r->mu);
	if (st != EDDY_OK || frame % d->every != 0)
		return st;
	if (!r->started && (st = start_writer(r, w)) != EDDY_OK)
		return st;
	pthread_mutex_lock(&r->mu);
	if (r->ready < 0) {
		/* no buffers: every rendered frame fails as the first did */
		char msg[512];
		snprintf(msg, sizeof msg, "%s", r->msg);
		pthread_mutex_unlock(&r->mu);
		return eddy_world_fail(w, EDDY_ERR_NOMEM, "%s", msg);
	}
	/* a free job: the writer is at most JOBS frames behind */
	while (r->queued == JOBS)
		pthread_cond_wait(&r->cv, &r->mu);
	job *j = &r->jobs[(r->head + r->queued) % JOBS];
	pthread_mutex_unlock(&r->mu);
	/* the job is outside the queue: the writer does not touch it */
	if ((st = fill_job(r, w, j, frame)) != EDDY_OK)
		return st;
	eddy_world_publish_text(w, "image", j->path);
	pthread_mutex_lock(&r->mu);
	r->queued++;
	pthread_cond_broadcast(&r->cv);
	if (!eddy_world_background_output(w)) {
		/* this frame's files are on disk when the step returns */
		while (r->queued > 0)
			pthread_cond_wait(&r->cv, &r->mu);
		st = take_failure(r, w);
	}
	if (st == EDDY_OK)
		publish_times(r, w);
	pthread_mutex_unlock(&r->mu);
	return st;
}

static eddy_status sync_frames(eddy_world *w, void *user)
{
	renderer *r = user;
	pthread_mutex_lock(&r->mu);
	while (r->queued > 0)
		pthread_cond_wait(&r->cv, &r->mu);
	eddy_status st = take_failure(r, w);
	pthread_mutex_unlock(&r->mu);
	return st;
}

static void destroy(void *user)
{
	renderer *r = user;
	if (r->started) {
		/* the queued frames are written (whole) before the thread ends */
		pthread_mutex_lock(&r->mu);
		r->quit = true;
		pthread_cond_broadcast(&r->cv);
		pthread_mutex_unlock(&r->mu);
		pthread_join(r->thread, NULL);
	}
	pthread_cond_destroy(&r->cv);
	pthread_mutex_destroy(&r->mu);
	for (int k = 0; k < JOBS; ++k) {
		job *j = &r->jobs[k];
		free(j->x), free(j->y), free(j->z), free(j->values), free(j->lines.xyz);
	}
	free(r->speed);
	eddy_splat_free(&r->splat);
	free(r->rgb);
	free(r->image);
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
	char why_view[160];
	const eddy_view_def vd = view_def(d);
	if (eddy_view_check(&vd, why_view, sizeof why_view))
		return BAD("%s: %s", sys, why_view);
	if (!(d->radius > 0) || !isfinite(d->radius))
		return BAD("%s: 'radius' must be > 0 m (got %g)", sys, (double)d->radius);
	if (!eddy_color_ok(d->background))
		return BAD("%s: 'background' must be an RGB colour with components in [0, 1]", sys);
	if (!eddy_color_ok(d->color))
		return BAD("%s: 'color' must be an RGB colour with components in [0, 1]", sys);
	if (!eddy_color_ok(d->outline_color))
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
			           "named '%s')",
			           sys, by);
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
	if (pthread_mutex_init(&r->mu, NULL) != 0 || pthread_cond_init(&r->cv, NULL) != 0) {
		free(r);
		eddy_world_fail(w, EDDY_ERR_NOMEM, "%s: cannot make the frame writer's lock", sys);
		return EDDY_NULL_SYSTEM;
	}
	eddy_custom_system_def cd = eddy_default_custom_system_def();
	cd.name = sys;
	cd.reads = reads;
	cd.read_count = nreads;
	cd.frame = render_frame;
	cd.destroy = destroy;
	cd.sync = sync_frames;
	cd.user = r;
	eddy_system_id id = eddy_add_custom_system(w, &cd);
	if (!eddy_system_valid(w, id))
		destroy(r);
	else
		r->id = id;
	return id;
}
