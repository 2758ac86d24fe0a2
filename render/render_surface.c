/* SPDX-License-Identifier: MIT */
/* render_surface: the liquid drawn as a shaded surface, not as balls. A
 * frame-only custom system, render_points' sibling.
 *
 * Reads: x y z. Writes: nothing; a PNG per rendered frame, and the frame
 * stats values surface_ms (meshing), render_ms (GL draw) and image (path).
 *
 * At every `every`-th frame time: eddy_world_surface (the 1/2 level of the
 * particles' colour field, closed, with the field's gradient as per-vertex
 * normals), box and sphere colliders tessellated into triangles whose
 * normals face the liquid's side (a tank's walls inward, a ball's outward),
 * any other collider (a mesh) as the zero level of its signed distance
 * (eddy_collider_mesh),
 * and drawn with back faces culled, so the near walls of a tank never hide
 * the liquid; the domain's edges as lines. The camera is render_points'
 * (eye == target frames the world's bounds). Drawn at supersample times the
 * size by gl_osmesa.c (per-pixel Phong with a Fresnel rim for the water,
 * plain Phong for the colliders), box-filtered down, written as PNG. */
#define _POSIX_C_SOURCE 200809L
#include "render.h"

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define PI_F 3.14159265358979f
#define SPHERE_RINGS 24 /* latitude bands of a sphere collider */
#define SPHERE_SEGS 48  /* longitude segments */

typedef struct surface_renderer {
	eddy_surface_cache cache; /* first: the liquid, reused every frame, or shared with a surface_mesh */
	eddy_render_surface_def def;
	eddy_gl *gl;
	float *cxyz, *cnormal; /* colliders' vertices and normals */
	uint32_t *ctri;
	size_t cv_cap, ct_cap; /* vertices, triangles */
	uint8_t *image;        /* RGB, top row first */
	eddy_mesh other;       /* scratch: a collider of no described shape, meshed from its distance */
} surface_renderer;

eddy_render_surface_def eddy_default_render_surface_def(void)
{
	eddy_render_surface_def d;
	memset(&d, 0, sizeof d);
	d.width = 960;
	d.height = 540;
	d.supersample = 2;
	d.up = (eddy_vec3){0, 1, 0};
	d.fov = 40.0f;
	d.projection = EDDY_PROJECTION_PERSPECTIVE;
	d.background = (eddy_vec3){0.11f, 0.12f, 0.14f};
	const eddy_surface_def s = eddy_default_surface_def();
	d.spacing = s.spacing;
	d.support = s.support;
	d.voxel = s.voxel;
	d.color = (eddy_vec3){0.10f, 0.36f, 0.62f};
	d.draw_colliders = true;
	d.collider_color = (eddy_vec3){0.55f, 0.56f, 0.58f};
	d.outline_domain = true;
	d.outline_color = (eddy_vec3){0.6f, 0.62f, 0.66f};
	strcpy(d.path, "surface_%04d.png");
	d.every = 1;
	return d;
}

static eddy_view_def view_def(const eddy_render_surface_def *d)
{
	/* the surface reaches about a support radius past the particles */
	return (eddy_view_def){d->width,
	                       d->height,
	                       d->supersample,
	                       d->eye,
	                       d->target,
	                       d->up,
	                       d->fov,
	                       d->projection,
	                       d->ortho_height,
	                       2.0f * d->spacing,
	                       4.0f * d->support * d->spacing};
}

/* ---- colliders as triangles ---- */

static bool reserve_colliders(surface_renderer *r, size_t verts, size_t tris)
{
	if (verts > r->cv_cap) {
		size_t c = verts + verts / 2;
		float *a = realloc(r->cxyz, 3 * c * sizeof *a);
		if (a)
			r->cxyz = a;
		float *b = realloc(r->cnormal, 3 * c * sizeof *b);
		if (b)
			r->cnormal = b;
		if (!a || !b)
			return false;
		r->cv_cap = c;
	}
	if (tris > r->ct_cap) {
		size_t c = tris + tris / 2;
		uint32_t *t = realloc(r->ctri, 3 * c * sizeof *t);
		if (!t)
			return false;
		r->ctri = t;
		r->ct_cap = c;
	}
	return true;
}

static void put_vertex(surface_renderer *r, size_t v, eddy_vec3 p, eddy_vec3 n)
{
	float *o = r->cxyz + 3 * v, *m = r->cnormal + 3 * v;
	o[0] = p.x, o[1] = p.y, o[2] = p.z;
	m[0] = n.x, m[1] = n.y, m[2] = n.z;
}

/* Triangle (a, b, c) wound counter-clockwise seen from where normal n points. */
static void put_tri(surface_renderer *r, size_t t, uint32_t a, uint32_t b, uint32_t c, bool flip)
{
	uint32_t *o = r->ctri + 3 * t;
	o[0] = a, o[1] = flip ? c : b, o[2] = flip ? b : c;
}

/* Box: 6 faces of 4 own vertices (flat normals). sign +1: normals out. */
static void box_mesh(surface_renderer *r, size_t *nv, size_t *nt, eddy_vec3 lo, eddy_vec3 hi, float sign)
{
	for (int axis = 0; axis < 3; ++axis)
		for (int side = 0; side < 2; ++side) {
			/* face at axis = lo or hi; u, v the other two axes (right-handed: u x v = +axis) */
			const int u = (axis + 1) % 3, w = (axis + 2) % 3;
			eddy_vec3 n = {0, 0, 0};
			float *nc = axis == 0 ? &n.x : axis == 1 ? &n.y : &n.z;
			*nc = (side ? 1.0f : -1.0f) * sign;
			const size_t base = *nv;
			for (int k = 0; k < 4; ++k) {
				const int bu = (k == 1 || k == 2), bw = (k >= 2);
				float c[3];
				const float l[3] = {lo.x, lo.y, lo.z}, h[3] = {hi.x, hi.y, hi.z};
				c[axis] = side ? h[axis] : l[axis];
				c[u] = bu ? h[u] : l[u];
				c[w] = bw ? h[w] : l[w];
				put_vertex(r, (*nv)++, (eddy_vec3){c[0], c[1], c[2]}, n);
			}
			/* corners 0 (lo,lo) 1 (hi,lo) 2 (hi,hi) 3 (lo,hi) in (u, w): counter-clockwise about +axis */
			const bool flip = *nc < 0;
			put_tri(r, (*nt)++, (uint32_t)base, (uint32_t)base + 1, (uint32_t)base + 2, flip);
			put_tri(r, (*nt)++, (uint32_t)base, (uint32_t)base + 2, (uint32_t)base + 3, flip);
		}
}

static void sphere_mesh(surface_renderer *r, size_t *nv, size_t *nt, eddy_vec3 c, float rad, float sign)
{
	const size_t base = *nv;
	for (int i = 0; i <= SPHERE_RINGS; ++i) {
		const float th = PI_F * (float)i / SPHERE_RINGS;
		for (int j = 0; j <= SPHERE_SEGS; ++j) {
			const float ph = 2.0f * PI_F * (float)j / SPHERE_SEGS;
			const eddy_vec3 d = {sinf(th) * cosf(ph), cosf(th), sinf(th) * sinf(ph)};
			put_vertex(r, (*nv)++, eddy_v3_add(c, eddy_v3_scale(d, rad)), eddy_v3_scale(d, sign));
		}
	}
	const uint32_t row = SPHERE_SEGS + 1;
	for (uint32_t i = 0; i < SPHERE_RINGS; ++i)
		for (uint32_t j = 0; j < SPHERE_SEGS; ++j) {
			const uint32_t a = (uint32_t)base + i * row + j, b = a + row, c2 = b + 1, d = a + 1;
			/* (a, d, c2) is counter-clockwise seen from outside with y up and phi towards +z */
			put_tri(r, (*nt)++, a, d, c2, sign < 0);
			put_tri(r, (*nt)++, a, c2, b, sign < 0);
		}
}

/* Fills the collider arrays; the triangle count, or -1 when out of memory. */
static long build_colliders(surface_renderer *r, eddy_world *w)
{
	size_t nv = 0, nt = 0;
	const int systems = eddy_world_system_count(w);
	for (int i = 0; i < systems; ++i) {
		eddy_collider_shape shape;
		if (eddy_collider_shape_of(w, eddy_world_system_at(w, i), &shape) != EDDY_OK)
			continue;
		const float sign = shape.inside ? -1.0f : 1.0f;
		if (shape.kind != EDDY_COLLIDER_BOX && shape.kind != EDDY_COLLIDER_SPHERE &&
		    shape.kind != EDDY_COLLIDER_PLANE) {
			/* any other kind (a mesh collider): the zero level of its distance,
			 * whose normals already face the liquid; one that cannot be meshed
			 * is left out rather than failing the frame */
			if (eddy_collider_mesh(w, eddy_world_system_at(w, i), 0.0f, &r->other) != EDDY_OK)
				continue;
			const eddy_mesh *m = &r->other;
			if (m->vertex_count > UINT32_MAX - nv ||
			    !reserve_colliders(r, nv + m->vertex_count, nt + m->triangle_count))
				return -1;
			memcpy(r->cxyz + 3 * nv, m->xyz, 3 * m->vertex_count * sizeof *m->xyz);
			memcpy(r->cnormal + 3 * nv, m->normal, 3 * m->vertex_count * sizeof *m->normal);
			for (size_t t = 0; t < 3 * m->triangle_count; ++t)
				r->ctri[3 * nt + t] = (uint32_t)nv + m->tri[t];
			nv += m->vertex_count;
			nt += m->triangle_count;
			continue;
		}
		const size_t sv = (SPHERE_RINGS + 1) * (SPHERE_SEGS + 1), st = 2 * SPHERE_RINGS * SPHERE_SEGS;
		if (!reserve_colliders(r, nv + sv, nt + st))
			return -1;
		if (shape.kind == EDDY_COLLIDER_BOX) {
			const size_t first = nv;
			box_mesh(r, &nv, &nt, shape.a, shape.b, sign);
			eddy_rotate_points(r->cxyz + 3 * first, nv - first, shape.rotation, shape.pivot);
			eddy_rotate_points(r->cnormal + 3 * first, nv - first, shape.rotation, (eddy_vec3){0, 0, 0});
		} else if (shape.kind == EDDY_COLLIDER_SPHERE)
			sphere_mesh(r, &nv, &nt, shape.a, shape.radius, sign);
		/* planes are unbounded: not drawn */
	}
	return (long)nt;
}

/* ---- the frame ---- */

eddy_status eddy_render_surface_frame(eddy_world *w, int frame, void *user)
{
	surface_renderer *r = user;
	const eddy_render_surface_def *d = &r->def;
	if (frame % d->every != 0)
		return EDDY_OK;
	const int s = d->supersample;
	char err[512];
	if (!r->gl) {
		r->gl = eddy_gl_create(d->width * s, d->height * s, err, sizeof err);
		if (!r->gl)
			return eddy_world_fail(w, EDDY_ERR_EXTERNAL, "%s", err);
	}
	const eddy_mesh *mesh = NULL;
	double mesh_ms = 0;
	eddy_status st = eddy_surface_of_frame(w, &r->cache, frame, &mesh, &mesh_ms);
	if (st != EDDY_OK)
		return st;
	const double t1 = eddy_now_ms();
	long ctris = d->draw_colliders ? build_colliders(r, w) : 0;
	if (ctris < 0)
		return eddy_world_fail(w, EDDY_ERR_NOMEM, "render_surface: out of memory for the colliders' meshes");

	float edges[12 * 6];
	const eddy_world_def *wd = eddy_world_get_def(w);
	eddy_box_edges(edges, wd->bounds_min, wd->bounds_max);
	eddy_gl_lines lines = {edges, 12, {d->outline_color.x, d->outline_color.y, d->outline_color.z}, 1.5f * (float)s};
	eddy_gl_mesh meshes[2];
	memset(meshes, 0, sizeof meshes);
	meshes[0] = (eddy_gl_mesh){
		mesh->xyz, mesh->normal, mesh->tri, mesh->triangle_count, {d->color.x, d->color.y, d->color.z}, 0.6f, 1.0f, 0};
	meshes[1] = (eddy_gl_mesh){
		r->cxyz, r->cnormal, r->ctri, (size_t)ctris, {d->collider_color.x, d->collider_color.y, d->collider_color.z},
		0.1f,    0.0f,       1};
	eddy_gl_scene scene;
	memset(&scene, 0, sizeof scene);
	eddy_camera cam;
	const eddy_view_def vd = view_def(d);
	eddy_camera_make(&vd, wd, &cam);
	memcpy(scene.view, cam.view, sizeof scene.view);
	memcpy(scene.proj, cam.proj, sizeof scene.proj);
	scene.background[0] = d->background.x, scene.background[1] = d->background.y, scene.background[2] = d->background.z;
	eddy_key_light(scene.light);
	scene.radius = d->spacing;
	scene.lines = &lines;
	scene.line_sets = d->outline_domain ? 1 : 0;
	scene.meshes = meshes;
	scene.mesh_sets = 2;
	if (eddy_gl_draw(r->gl, &scene, err, sizeof err) != 0)
		return eddy_world_fail(w, EDDY_ERR_EXTERNAL, "render_surface: %s", err);
	const double t2 = eddy_now_ms();
	if (!r->image) {
		r->image = malloc((size_t)d->width * (size_t)d->height * 3);
		if (!r->image)
			return eddy_world_fail(w, EDDY_ERR_NOMEM, "out of memory for a %dx%d image", d->width, d->height);
	}
	eddy_downsample_rows(eddy_gl_pixels(r->gl), d->width, d->height, s, r->image, 0, d->height);
	char path[1024];
	if (eddy_frame_path(d->path, frame, path, sizeof path) != 0)
		return eddy_world_fail(w, EDDY_ERR_IO, "render_surface: the image path for frame %d is too long", frame);
	const int werr = eddy_write_png(path, d->width, d->height, r->image);
	if (werr != 0)
		return eddy_world_fail(w, EDDY_ERR_IO, "render_surface: cannot write '%s': %s", path, strerror(werr));
	if (mesh_ms >= 0)
		eddy_world_publish(w, "surface_ms", mesh_ms);
	eddy_world_publish(w, "render_ms", t2 - t1);
	eddy_world_publish_text(w, "image", path);
	return EDDY_OK;
}

static void destroy(void *user)
{
	surface_renderer *r = user;
	eddy_gl_destroy(r->gl);
	eddy_mesh_free(&r->cache.mesh);
	eddy_mesh_free(&r->other);
	free(r->cxyz);
	free(r->cnormal);
	free(r->ctri);
	free(r->image);
	free(r);
}

#define BAD(...) (eddy_world_fail(w, EDDY_ERR_INVALID, __VA_ARGS__), EDDY_NULL_SYSTEM)

eddy_system_id eddy_add_render_surface(eddy_world *w, const eddy_render_surface_def *def)
{
	const char *sys = "render_surface";
	if (!w)
		return EDDY_NULL_SYSTEM;
	if (!def)
		return BAD("%s: def is NULL", sys);
	const eddy_render_surface_def *d = def;
	char why[160];
	const eddy_view_def vd = view_def(d);
	if (eddy_view_check(&vd, why, sizeof why))
		return BAD("%s: %s", sys, why);
	if (eddy_check_surface_fields(d->spacing, d->support, d->voxel, why, sizeof why))
		return BAD("%s: %s", sys, why);
	if (!eddy_color_ok(d->background) || !eddy_color_ok(d->color) || !eddy_color_ok(d->collider_color) ||
	    !eddy_color_ok(d->outline_color))
		return BAD("%s: 'background', 'color', 'collider_color' and 'outline_color' must be RGB colours with "
		           "components in [0, 1]",
		           sys);
	if (d->every < 1)
		return BAD("%s: 'every' must be >= 1 frame (got %d)", sys, d->every);
	if (!memchr(d->path, '\0', sizeof d->path))
		return BAD("%s: 'path' must be NUL-terminated", sys);
	const char *bad = eddy_check_frame_pattern(d->path);
	if (bad)
		return BAD("%s: 'path' %s (got \"%s\")", sys, bad, d->path);
	surface_renderer *r = calloc(1, sizeof *r);
	if (!r)
		return eddy_world_fail(w, EDDY_ERR_NOMEM, "%s: out of memory", sys), EDDY_NULL_SYSTEM;
	r->def = *d;
	r->cache.def = (eddy_surface_def){d->spacing, d->support, d->voxel};
	const char *reads[3] = {"x", "y", "z"};
	eddy_custom_system_def cd = eddy_default_custom_system_def();
	cd.name = sys;
	cd.reads = reads;
	cd.read_count = 3;
	cd.frame = eddy_render_surface_frame;
	cd.destroy = destroy;
	cd.user = r;
	eddy_system_id id = eddy_add_custom_system(w, &cd);
	if (!eddy_system_valid(w, id))
		destroy(r);
	return id;
}
