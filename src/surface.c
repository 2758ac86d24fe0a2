/* SPDX-License-Identifier: MIT */
/* The liquid surface as a triangle mesh: the public door to surface_vdb.cpp
 * (OpenVDB) and the mesh files.
 *
 * eddy_world_surface reads x y z and meshes the 1/2 level of the particles'
 * colour field (the field, the kernel and why this level: surface_vdb.cpp).
 * eddy_world_write_mesh writes the mesh as binary PLY or OBJ, or its field as
 * an OpenVDB level set; every file goes to a hidden temporary name beside the
 * final one and is renamed into place only when every write, the flush and
 * the close succeeded, so a failure leaves no partial file. Nothing here is
 * allocated unless a host or a system asks for a surface. */
#define _POSIX_C_SOURCE 200809L
#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "core.h"
#include "surface.h"

eddy_surface_def eddy_default_surface_def(void)
{
	eddy_surface_def d;
	memset(&d, 0, sizeof d);
	d.spacing = 0.01f;
	d.support = 2.0f;
	d.voxel = 0.5f;
	return d;
}

static eddy_status check_def(eddy_world *w, const char *sys, float spacing, float support, float voxel)
{
	if (!(spacing > 0) || !isfinite(spacing))
		return eddy__fail(w, EDDY_ERR_INVALID, "%s: 'spacing' must be > 0 m (got %g)", sys, (double)spacing);
	if (!(support >= 1 && support <= 4))
		return eddy__fail(w, EDDY_ERR_INVALID, "%s: 'support' must be in [1, 4] spacings (got %g)", sys,
		                  (double)support);
	if (!(voxel >= 0.1f && voxel <= 1))
		return eddy__fail(w, EDDY_ERR_INVALID, "%s: 'voxel' must be in [0.1, 1] spacings (got %g)", sys, (double)voxel);
	return EDDY_OK;
}

eddy_status eddy_world_surface(eddy_world *w, const eddy_surface_def *def, eddy_mesh *mesh)
{
	if (!w)
		return EDDY_ERR_INVALID;
	if (!def || !mesh)
		return eddy__fail(w, EDDY_ERR_INVALID, "eddy_world_surface: def and mesh must not be NULL");
	eddy_status st = check_def(w, "surface", def->spacing, def->support, def->voxel);
	if (st != EDDY_OK)
		return st;
	const size_t n = eddy_world_particle_count(w);
	size_t cnt = 0;
	const float *x = NULL, *y = NULL, *z = NULL;
	if (n > 0) {
		x = eddy_world_channel(w, "x", &cnt);
		y = eddy_world_channel(w, "y", &cnt);
		z = eddy_world_channel(w, "z", &cnt);
		if (!x || !y || !z)
			return eddy__fail(w, EDDY_ERR_INVALID, "surface: the positions x y z are not allocated");
	}
	const float s = def->spacing;
	const eddy__surface_params p = {s, def->support * s, def->voxel * s, eddy_world_get_def(w)->threads};
	char err[512];
	if (eddy__surface_build(x, y, z, n, &p, mesh, err, sizeof err) != 0)
		return eddy__fail(w, strstr(err, "memory") ? EDDY_ERR_NOMEM : EDDY_ERR_EXTERNAL, "surface: %s", err);
	return EDDY_OK;
}

eddy_status eddy_collider_mesh(eddy_world *w, eddy_system_id id, float cell, eddy_mesh *out)
{
	if (!w)
		return EDDY_ERR_INVALID;
	if (!out || !isfinite(cell))
		return eddy__fail(w, EDDY_ERR_INVALID, "eddy_collider_mesh: out must not be NULL and cell finite");
	float d0 = 0;
	eddy_status st = eddy_collider_distance(w, id, (eddy_vec3){0, 0, 0}, &d0);
	if (st != EDDY_OK)
		return st;
	const eddy_world_def *wd = eddy_world_get_def(w);
	const float ext[3] = {wd->bounds_max.x - wd->bounds_min.x, wd->bounds_max.y - wd->bounds_min.y,
	                      wd->bounds_max.z - wd->bounds_min.z};
	const float longest = fmaxf(ext[0], fmaxf(ext[1], ext[2]));
	const float dx = fmaxf(cell > 0 ? cell : longest / 64, longest / 255);
	/* one cell of margin each side, so a solid inside the bounds is closed */
	const float origin[3] = {wd->bounds_min.x - dx, wd->bounds_min.y - dx, wd->bounds_min.z - dx};
	int dims[3];
	for (int c = 0; c < 3; ++c)
		dims[c] = (int)ceilf(ext[c] / dx) + 3;
	const size_t n = (size_t)dims[0] * (size_t)dims[1] * (size_t)dims[2];
	float *d = malloc(n * sizeof *d);
	if (!d)
		return eddy__fail(w, EDDY_ERR_NOMEM, "eddy_collider_mesh: out of memory for %zu samples", n);
	for (int i = 0; i < dims[0]; ++i)
		for (int j = 0; j < dims[1]; ++j)
			for (int k = 0; k < dims[2]; ++k) {
				const eddy_vec3 p = {origin[0] + (float)i * dx, origin[1] + (float)j * dx, origin[2] + (float)k * dx};
				float v = 0;
				eddy_collider_distance(w, id, p, &v);
				d[((size_t)i * (size_t)dims[1] + (size_t)j) * (size_t)dims[2] + (size_t)k] = isfinite(v) ? v : 3 * dx;
			}
	char err[512];
	const int rc = eddy__surface_from_samples(d, dims, origin, dx, out, err, sizeof err);
	free(d);
	if (rc != 0)
		return eddy__fail(w, strstr(err, "memory") ? EDDY_ERR_NOMEM : EDDY_ERR_EXTERNAL, "collider mesh: %s", err);
	return EDDY_OK;
}

void eddy_mesh_free(eddy_mesh *mesh)
{
	if (!mesh)
		return;
	free(mesh->xyz);
	free(mesh->normal);
	free(mesh->tri);
	eddy__surface_free_field(mesh->field);
	memset(mesh, 0, sizeof *mesh);
}

/* ---- files ---- */

typedef struct out_file {
	FILE *f;
	char tmp[1200];
	int err; /* errno of the first failure */
} out_file;

static int out_begin(out_file *o, const char *path)
{
	memset(o, 0, sizeof *o);
	const char *slash = strrchr(path, '/');
	const int dir = slash ? (int)(slash - path + 1) : 0;
	for (int attempt = 0; attempt < 100; ++attempt) {
		if (snprintf(o->tmp, sizeof o->tmp, "%.*s.%s.%ld-m%d.tmp", dir, path, path + dir, (long)getpid(), attempt) >=
		    (int)sizeof o->tmp)
			return ENAMETOOLONG;
		/* O_EXCL: never write through a file (or link) someone else made */
		int fd = open(o->tmp, O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0666);
		if (fd < 0 && errno == EEXIST)
			continue;
		if (fd < 0)
			return errno;
		o->f = fdopen(fd, "wb");
		if (!o->f) {
			int e = errno;
			close(fd);
			unlink(o->tmp);
			return e;
		}
		return 0;
	}
	return EEXIST;
}

static void out_write(out_file *o, const void *p, size_t n)
{
	if (!o->err && fwrite(p, 1, n, o->f) != n)
		o->err = errno ? errno : EIO;
}

static int out_finish(out_file *o, const char *path)
{
	if (fflush(o->f) != 0 && !o->err)
		o->err = errno ? errno : EIO;
	if (fclose(o->f) != 0 && !o->err)
		o->err = errno ? errno : EIO;
	if (!o->err && rename(o->tmp, path) != 0)
		o->err = errno;
	if (o->err)
		remove(o->tmp);
	return o->err;
}

static void put_u32(unsigned char *b, uint32_t v)
{
	b[0] = (unsigned char)v, b[1] = (unsigned char)(v >> 8), b[2] = (unsigned char)(v >> 16),
	b[3] = (unsigned char)(v >> 24);
}

static void put_f32(unsigned char *b, float f)
{
	uint32_t v;
	memcpy(&v, &f, 4);
	put_u32(b, v);
}

/* Binary little-endian PLY, written in chunks so no file-sized buffer is needed. */
static void write_ply(out_file *o, const eddy_mesh *m)
{
	char head[512];
	int len = snprintf(head, sizeof head,
	                   "ply\nformat binary_little_endian 1.0\ncomment eddy liquid surface\n"
	                   "element vertex %zu\nproperty float x\nproperty float y\nproperty float z\n"
	                   "property float nx\nproperty float ny\nproperty float nz\n"
	                   "element face %zu\nproperty list uchar uint vertex_indices\nend_header\n",
	                   m->vertex_count, m->triangle_count);
	out_write(o, head, (size_t)len);
	unsigned char buf[4096];
	size_t k = 0;
	for (size_t v = 0; v < m->vertex_count; ++v) {
		for (int c = 0; c < 3; ++c)
			put_f32(buf + k + 4 * (size_t)c, m->xyz[3 * v + (size_t)c]);
		for (int c = 0; c < 3; ++c)
			put_f32(buf + k + 12 + 4 * (size_t)c, m->normal[3 * v + (size_t)c]);
		k += 24;
		if (k + 24 > sizeof buf)
			out_write(o, buf, k), k = 0;
	}
	for (size_t t = 0; t < m->triangle_count; ++t) {
		buf[k] = 3;
		for (int c = 0; c < 3; ++c)
			put_u32(buf + k + 1 + 4 * (size_t)c, m->tri[3 * t + (size_t)c]);
		k += 13;
		if (k + 13 > sizeof buf)
			out_write(o, buf, k), k = 0;
	}
	out_write(o, buf, k);
}

static void write_obj(out_file *o, const eddy_mesh *m)
{
	if (!o->err &&
	    fprintf(o->f, "# eddy liquid surface: %zu vertices, %zu triangles\n", m->vertex_count, m->triangle_count) < 0)
		o->err = errno ? errno : EIO;
	/* %.9g: floats survive the text round trip exactly */
	for (size_t v = 0; v < m->vertex_count && !o->err; ++v) {
		const float *p = m->xyz + 3 * v;
		if (fprintf(o->f, "v %.9g %.9g %.9g\n", (double)p[0], (double)p[1], (double)p[2]) < 0)
			o->err = errno ? errno : EIO;
	}
	for (size_t v = 0; v < m->vertex_count && !o->err; ++v) {
		const float *p = m->normal + 3 * v;
		if (fprintf(o->f, "vn %.6g %.6g %.6g\n", (double)p[0], (double)p[1], (double)p[2]) < 0)
			o->err = errno ? errno : EIO;
	}
	for (size_t t = 0; t < m->triangle_count && !o->err; ++t) {
		const uint32_t *q = m->tri + 3 * t; /* OBJ counts from 1 */
		if (fprintf(o->f, "f %u//%u %u//%u %u//%u\n", q[0] + 1, q[0] + 1, q[1] + 1, q[1] + 1, q[2] + 1, q[2] + 1) < 0)
			o->err = errno ? errno : EIO;
	}
}

eddy_status eddy_world_write_mesh(eddy_world *w, const eddy_mesh *mesh, eddy_mesh_format format, const char *path)
{
	if (!w)
		return EDDY_ERR_INVALID;
	if (!mesh || !path || !path[0])
		return eddy__fail(w, EDDY_ERR_INVALID, "eddy_world_write_mesh: mesh and path must not be NULL or empty");
	if ((mesh->vertex_count && (!mesh->xyz || !mesh->normal)) || (mesh->triangle_count && !mesh->tri))
		return eddy__fail(w, EDDY_ERR_INVALID, "eddy_world_write_mesh: the mesh has counts but no arrays");
	if (format == EDDY_MESH_VDB) {
		char err[1400];
		if (eddy__surface_write_vdb(mesh, path, err, sizeof err) != 0)
			return eddy__fail(w, EDDY_ERR_IO, "surface: %s", err);
		return EDDY_OK;
	}
	if (format != EDDY_MESH_PLY && format != EDDY_MESH_OBJ)
		return eddy__fail(w, EDDY_ERR_INVALID, "eddy_world_write_mesh: 'format' must be ply, obj or vdb (got %d)",
		                  (int)format);
	out_file o;
	int e = out_begin(&o, path);
	if (e)
		return eddy__fail(w, EDDY_ERR_IO, "surface: cannot write '%s': %s", path, strerror(e));
	if (format == EDDY_MESH_PLY)
		write_ply(&o, mesh);
	else
		write_obj(&o, mesh);
	e = out_finish(&o, path);
	if (e)
		return eddy__fail(w, EDDY_ERR_IO, "surface: cannot write '%s': %s", path, strerror(e));
	return EDDY_OK;
}
