/* SPDX-License-Identifier: MIT */
/* surface_mesh: the liquid surface written as a mesh file per frame, for
 * Blender, Houdini, MeshLab and ParaView. A frame-only custom system.
 *
 * Reads: x y z. Writes: at every `every`-th frame time, eddy_world_surface
 * (the 1/2 level of the particles' colour field, src/surface_vdb.cpp) to
 * path + ".ply" (binary little-endian), ".obj" and/or ".vdb" (an OpenVDB
 * level set), each whole or not at all (a temporary file renamed into
 * place). The mesh buffers are made at the first frame and reused. Publishes
 * surface_ms (the meshing, ms), surface_vertices and surface_triangles.
 *
 * Meshed once per frame: with a render_surface of the same spacing, support
 * and voxel in the world, whichever runs first meshes and the other takes its
 * mesh (eddy_surface_of_frame; the state is stamped by frame, step count,
 * time and particle count, which no frame hook changes), and surface_ms is
 * published by the one that meshed. */
#define _POSIX_C_SOURCE 200809L
#include "render.h"

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

static const char *const mesh_ext[] = {"ply", "obj", "vdb"}; /* eddy_mesh_format order */

typedef struct surface_writer {
	eddy_surface_cache cache; /* first: eddy_surface_of_frame reads it from either system */
	eddy_surface_mesh_def def;
	bool want[3]; /* by eddy_mesh_format */
} surface_writer;

eddy_surface_mesh_def eddy_default_surface_mesh_def(void)
{
	eddy_surface_mesh_def d;
	memset(&d, 0, sizeof d);
	const eddy_surface_def s = eddy_default_surface_def();
	d.spacing = s.spacing;
	d.support = s.support;
	d.voxel = s.voxel;
	strcpy(d.format, "ply");
	strcpy(d.path, "surface_%04d");
	d.every = 1;
	return d;
}

const char *eddy_check_surface_fields(float spacing, float support, float voxel, char *buf, size_t cap)
{
	if (!(spacing > 0) || !isfinite(spacing))
		snprintf(buf, cap, "'spacing' must be > 0 m (got %g)", (double)spacing);
	else if (!(support >= 1 && support <= 4))
		snprintf(buf, cap, "'support' must be in [1, 4] spacings (got %g)", (double)support);
	else if (!(voxel >= 0.1f && voxel <= 1))
		snprintf(buf, cap, "'voxel' must be in [0.1, 1] spacings (got %g)", (double)voxel);
	else
		return NULL;
	return buf;
}

double eddy_now_ms(void)
{
	struct timespec ts;
	clock_gettime(CLOCK_MONOTONIC, &ts);
	return (double)ts.tv_sec * 1e3 + (double)ts.tv_nsec * 1e-6;
}

static bool same_state(const eddy_surface_cache *c, const eddy_world *w, int frame)
{
	return c->valid && c->frame == frame && c->steps == eddy_world_steps(w) && c->time == eddy_world_time(w) &&
	       c->particles == eddy_world_particle_count(w);
}

eddy_status eddy_surface_of_frame(eddy_world *w, eddy_surface_cache *c, int frame, const eddy_mesh **out, double *ms)
{
	const int systems = eddy_world_system_count(w);
	for (int i = 0; i < systems; ++i) {
		const eddy_system_id id = eddy_world_system_at(w, i);
		eddy_surface_cache *o = eddy_world_custom_user(w, id, eddy_surface_mesh_frame);
		if (!o)
			o = eddy_world_custom_user(w, id, eddy_render_surface_frame);
		if (!o || o == c || !same_state(o, w, frame) || o->def.spacing != c->def.spacing ||
		    o->def.support != c->def.support || o->def.voxel != c->def.voxel)
			continue;
		*out = &o->mesh;
		*ms = -1;
		return EDDY_OK;
	}
	const double t0 = eddy_now_ms();
	c->valid = false;
	eddy_status st = eddy_world_surface(w, &c->def, &c->mesh);
	if (st != EDDY_OK)
		return st;
	*ms = eddy_now_ms() - t0;
	c->valid = true;
	c->frame = frame;
	c->steps = eddy_world_steps(w);
	c->time = eddy_world_time(w);
	c->particles = eddy_world_particle_count(w);
	*out = &c->mesh;
	return EDDY_OK;
}

eddy_status eddy_surface_mesh_frame(eddy_world *w, int frame, void *user)
{
	surface_writer *s = user;
	if (frame % s->def.every != 0)
		return EDDY_OK;
	const eddy_mesh *mesh = NULL;
	double ms = 0;
	eddy_status st = eddy_surface_of_frame(w, &s->cache, frame, &mesh, &ms);
	if (st != EDDY_OK)
		return st;
	char stem[1024], path[1100];
	if (eddy_frame_path(s->def.path, frame, stem, sizeof stem) != 0)
		return eddy_world_fail(w, EDDY_ERR_IO, "surface_mesh: the path for frame %d is too long", frame);
	for (int f = 0; f < 3; ++f) {
		if (!s->want[f])
			continue;
		snprintf(path, sizeof path, "%s.%s", stem, mesh_ext[f]);
		if (eddy_make_parent_dirs(path) != 0)
			return eddy_world_fail(w, EDDY_ERR_IO, "surface_mesh: cannot create the folder of '%s': %s", path,
			                       strerror(errno));
		st = eddy_world_write_mesh(w, mesh, (eddy_mesh_format)f, path);
		if (st != EDDY_OK)
			return st;
	}
	if (ms >= 0)
		eddy_world_publish(w, "surface_ms", ms);
	eddy_world_publish(w, "surface_vertices", (double)mesh->vertex_count);
	eddy_world_publish(w, "surface_triangles", (double)mesh->triangle_count);
	return EDDY_OK;
}

static void destroy(void *user)
{
	surface_writer *s = user;
	eddy_mesh_free(&s->cache.mesh);
	free(s);
}

#define BAD(...) (eddy_world_fail(w, EDDY_ERR_INVALID, __VA_ARGS__), EDDY_NULL_SYSTEM)

eddy_system_id eddy_add_surface_mesh(eddy_world *w, const eddy_surface_mesh_def *def)
{
	const char *sys = "surface_mesh";
	if (!w)
		return EDDY_NULL_SYSTEM;
	if (!def)
		return BAD("%s: def is NULL", sys);
	char why[160];
	if (eddy_check_surface_fields(def->spacing, def->support, def->voxel, why, sizeof why))
		return BAD("%s: %s", sys, why);
	if (def->every < 1)
		return BAD("%s: 'every' must be >= 1 frame (got %d)", sys, def->every);
	if (!memchr(def->path, '\0', sizeof def->path) || !memchr(def->format, '\0', sizeof def->format))
		return BAD("%s: 'path' and 'format' must be NUL-terminated", sys);
	const char *bad = eddy_check_frame_pattern(def->path);
	if (bad)
		return BAD("%s: 'path' %s (got \"%s\")", sys, bad, def->path);
	bool want[3] = {false, false, false}, any = false;
	for (const char *p = def->format; *p;) {
		size_t len = strcspn(p, " ,\t");
		if (len == 0) {
			++p;
			continue;
		}
		int f = -1;
		for (int k = 0; k < 3; ++k)
			if (strlen(mesh_ext[k]) == len && strncmp(p, mesh_ext[k], len) == 0)
				f = k;
		if (f < 0)
			return BAD("%s: 'format' must list ply, obj and/or vdb (got '%.*s')", sys, (int)len, p);
		want[f] = any = true;
		p += len;
	}
	if (!any)
		return BAD("%s: 'format' must list ply, obj and/or vdb (got \"%s\")", sys, def->format);
	surface_writer *s = calloc(1, sizeof *s);
	if (!s)
		return eddy_world_fail(w, EDDY_ERR_NOMEM, "%s: out of memory", sys), EDDY_NULL_SYSTEM;
	s->def = *def;
	s->cache.def = (eddy_surface_def){def->spacing, def->support, def->voxel};
	memcpy(s->want, want, sizeof want);
	const char *reads[3] = {"x", "y", "z"};
	eddy_custom_system_def cd = eddy_default_custom_system_def();
	cd.name = sys;
	cd.reads = reads;
	cd.read_count = 3;
	cd.frame = eddy_surface_mesh_frame;
	cd.destroy = destroy;
	cd.user = s;
	eddy_system_id id = eddy_add_custom_system(w, &cd);
	if (!eddy_system_valid(w, id))
		destroy(s);
	return id;
}
