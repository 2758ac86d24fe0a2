/* SPDX-License-Identifier: MIT */
/* surface_mesh: the liquid surface written as a mesh file per frame, for
 * Blender, Houdini, MeshLab and ParaView. A frame-only custom system.
 *
 * Reads: x y z. Writes: at every `every`-th frame time, eddy_world_surface
 * (the 1/2 level of the particles' colour field, src/surface_vdb.cpp) to
 * path + ".ply" (binary little-endian), ".obj" and/or ".vdb" (an OpenVDB
 * level set), each whole or not at all (a temporary file renamed into
 * place). The mesh buffers are made at the first frame and reused. Publishes
 * surface_ms (the meshing, ms), surface_vertices and surface_triangles. */
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
	eddy_surface_mesh_def def;
	bool want[3]; /* by eddy_mesh_format */
	eddy_mesh mesh;
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

static eddy_status write_frame(eddy_world *w, int frame, void *user)
{
	surface_writer *s = user;
	if (frame % s->def.every != 0)
		return EDDY_OK;
	const eddy_surface_def sd = {s->def.spacing, s->def.support, s->def.voxel};
	const double t0 = eddy_now_ms();
	eddy_status st = eddy_world_surface(w, &sd, &s->mesh);
	if (st != EDDY_OK)
		return st;
	const double t1 = eddy_now_ms();
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
		st = eddy_world_write_mesh(w, &s->mesh, (eddy_mesh_format)f, path);
		if (st != EDDY_OK)
			return st;
	}
	eddy_world_publish(w, "surface_ms", t1 - t0);
	eddy_world_publish(w, "surface_vertices", (double)s->mesh.vertex_count);
	eddy_world_publish(w, "surface_triangles", (double)s->mesh.triangle_count);
	return EDDY_OK;
}

static void destroy(void *user)
{
	surface_writer *s = user;
	eddy_mesh_free(&s->mesh);
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
	memcpy(s->want, want, sizeof want);
	const char *reads[3] = {"x", "y", "z"};
	eddy_custom_system_def cd = eddy_default_custom_system_def();
	cd.name = sys;
	cd.reads = reads;
	cd.read_count = 3;
	cd.frame = write_frame;
	cd.destroy = destroy;
	cd.user = s;
	eddy_system_id id = eddy_add_custom_system(w, &cd);
	if (!eddy_system_valid(w, id))
		destroy(s);
	return id;
}
