/* export_particles: writes the particles to one file per frame, for Blender,
 * Houdini, ParaView and MeshLab. A frame-only custom system.
 *
 * Reads: x y z and the listed channels (vx vy vz for "speed"). Writes: files.
 *
 * PLY (binary_little_endian 1.0): one `vertex` element with a float property
 * per channel, x y z first, so every PLY reader sees a point cloud.
 * VTK (legacy "# vtk DataFile Version 3.0", BINARY, big-endian as that format
 * requires): POLYDATA with POINTS, one VERTICES cell per point (so ParaView
 * draws them without a Glyph filter) and the channels as one POINT_DATA
 * FIELD with a float array each. */
#define _POSIX_C_SOURCE 200809L
#include "render.h"

#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define MAX_CHANNELS 20 /* names incl. x y z; with vx vy vz the reads stay within the core's 24 */

typedef struct exporter {
	eddy_export_particles_def def;
	char names[MAX_CHANNELS][32]; /* x y z, then the chosen channels */
	int count;
	float *scratch[MAX_CHANNELS]; /* derived channels (speed) */
	size_t cap;
	unsigned char *row;           /* one file-order buffer, grown as needed */
	size_t row_cap;
} exporter;

eddy_export_particles_def eddy_default_export_particles_def(void)
{
	eddy_export_particles_def d;
	memset(&d, 0, sizeof d);
	d.format = EDDY_EXPORT_PLY;
	strcpy(d.channels, "vx vy vz");
	strcpy(d.path, "particles_%04d.ply");
	d.every = 1;
	return d;
}

static void put_le32(unsigned char *p, uint32_t v)
{
	p[0] = (unsigned char)v, p[1] = (unsigned char)(v >> 8), p[2] = (unsigned char)(v >> 16), p[3] = (unsigned char)(v >> 24);
}
static void put_be32(unsigned char *p, uint32_t v)
{
	p[0] = (unsigned char)(v >> 24), p[1] = (unsigned char)(v >> 16), p[2] = (unsigned char)(v >> 8), p[3] = (unsigned char)v;
}
static uint32_t float_bits(float f)
{
	uint32_t u;
	memcpy(&u, &f, sizeof u);
	return u;
}

static bool reserve(exporter *e, size_t n, size_t row_bytes)
{
	if (n > e->cap) {
		size_t cap = n + n / 4;
		for (int c = 0; c < e->count; ++c)
			if (strcmp(e->names[c], "speed") == 0) {
				float *s = realloc(e->scratch[c], cap * sizeof *s);
				if (!s)
					return false;
				e->scratch[c] = s;
			}
		e->cap = cap;
	}
	if (row_bytes > e->row_cap) {
		unsigned char *r = realloc(e->row, row_bytes);
		if (!r)
			return false;
		e->row = r;
		e->row_cap = row_bytes;
	}
	return true;
}

/* Writes count floats (or, for VTK vertices, the cells) through a buffer of
 * at most 64 Ki values per fwrite. */
#define CHUNK 65536

static eddy_status write_frame(eddy_world *w, int frame, void *user)
{
	exporter *e = user;
	if (frame % e->def.every != 0)
		return EDDY_OK;
	const size_t n = eddy_world_particle_count(w);
	const bool ply = e->def.format == EDDY_EXPORT_PLY;
	const size_t nc = (size_t)e->count;
	if (!reserve(e, n, ply ? CHUNK * nc * 4 : CHUNK * 8))
		return eddy_world_fail(w, EDDY_ERR_NOMEM, "out of memory exporting %zu particles", n);
	const float *col[MAX_CHANNELS] = {NULL};
	for (size_t c = 0; c < nc && n > 0; ++c) {
		col[c] = eddy_particle_values(w, e->names[c], e->scratch[c], n);
		if (!col[c])
			return eddy_world_fail(w, EDDY_ERR_INVALID, "channel '%s' is not available", e->names[c]);
	}
	char path[1024];
	if (eddy_frame_path(e->def.path, frame, path, sizeof path) != 0)
		return eddy_world_fail(w, EDDY_ERR_IO, "the export path for frame %d is too long", frame);
	if (eddy_make_parent_dirs(path) != 0)
		return eddy_world_fail(w, EDDY_ERR_IO, "cannot create the directory of '%s': %s", path, strerror(errno));
	FILE *f = fopen(path, "wb");
	if (!f)
		return eddy_world_fail(w, EDDY_ERR_IO, "cannot write '%s': %s", path, strerror(errno));
	bool ok = true;
	const double t = eddy_world_time(w);
	if (ply) {
		ok = fprintf(f, "ply\nformat binary_little_endian 1.0\ncomment eddy frame %d time %.9g s\nelement vertex %zu\n",
		             frame, t, n) > 0;
		for (size_t c = 0; c < nc && ok; ++c)
			ok = fprintf(f, "property float %s\n", e->names[c]) > 0;
		ok = ok && fputs("end_header\n", f) >= 0;
		for (size_t first = 0; first < n && ok; first += CHUNK) {
			size_t m = n - first < CHUNK ? n - first : CHUNK;
			unsigned char *p = e->row;
			for (size_t i = first; i < first + m; ++i)
				for (size_t c = 0; c < nc; ++c, p += 4)
					put_le32(p, float_bits(col[c][i]));
			ok = fwrite(e->row, 1, (size_t)(p - e->row), f) == (size_t)(p - e->row);
		}
	} else {
		ok = fprintf(f, "# vtk DataFile Version 3.0\neddy frame %d time %.9g s\nBINARY\nDATASET POLYDATA\nPOINTS %zu float\n",
		             frame, t, n) > 0;
		for (size_t first = 0; first < n && ok; first += CHUNK) {
			size_t m = n - first < CHUNK ? n - first : CHUNK;
			unsigned char *p = e->row;
			for (size_t i = first; i < first + m; ++i)
				for (size_t c = 0; c < 3; ++c, p += 4)
					put_be32(p, float_bits(col[c][i]));
			ok = fwrite(e->row, 1, (size_t)(p - e->row), f) == (size_t)(p - e->row);
		}
		ok = ok && fprintf(f, "\nVERTICES %zu %zu\n", n, 2 * n) > 0;
		for (size_t first = 0; first < n && ok; first += CHUNK) {
			size_t m = n - first < CHUNK ? n - first : CHUNK;
			unsigned char *p = e->row;
			for (size_t i = first; i < first + m; ++i, p += 8) {
				put_be32(p, 1);
				put_be32(p + 4, (uint32_t)i);
			}
			ok = fwrite(e->row, 1, (size_t)(p - e->row), f) == (size_t)(p - e->row);
		}
		/* a FIELD, not SCALARS: VTK's legacy reader keeps only the first
		 * SCALARS of a dataset unless asked, but every array of a FIELD */
		ok = ok && fprintf(f, "\nPOINT_DATA %zu\n", n) > 0;
		if (nc > 3)
			ok = ok && fprintf(f, "FIELD channels %zu\n", nc - 3) > 0;
		for (size_t c = 3; c < nc && ok; ++c) {
			ok = fprintf(f, "%s 1 %zu float\n", e->names[c], n) > 0;
			for (size_t first = 0; first < n && ok; first += CHUNK) {
				size_t m = n - first < CHUNK ? n - first : CHUNK;
				unsigned char *p = e->row;
				for (size_t i = first; i < first + m; ++i, p += 4)
					put_be32(p, float_bits(col[c][i]));
				ok = fwrite(e->row, 1, (size_t)(p - e->row), f) == (size_t)(p - e->row);
			}
			ok = ok && fputc('\n', f) != EOF;
		}
	}
	int err = ok ? 0 : errno;
	if (fclose(f) != 0 && ok) {
		ok = false;
		err = errno;
	}
	if (!ok)
		return eddy_world_fail(w, EDDY_ERR_IO, "cannot write '%s': %s", path, err ? strerror(err) : "write failed");
	return EDDY_OK;
}

static void destroy(void *user)
{
	exporter *e = user;
	for (int c = 0; c < MAX_CHANNELS; ++c)
		free(e->scratch[c]);
	free(e->row);
	free(e);
}

eddy_system_id eddy_add_export_particles(eddy_world *w, const eddy_export_particles_def *def)
{
	const char *sys = "export_particles";
	if (!w)
		return EDDY_NULL_SYSTEM;
	if (!def)
		return eddy_world_fail(w, EDDY_ERR_INVALID, "%s: def is NULL", sys), EDDY_NULL_SYSTEM;
	if (def->format != EDDY_EXPORT_PLY && def->format != EDDY_EXPORT_VTK)
		return eddy_world_fail(w, EDDY_ERR_INVALID, "%s: 'format' must be ply or vtk", sys), EDDY_NULL_SYSTEM;
	if (def->every < 1)
		return eddy_world_fail(w, EDDY_ERR_INVALID, "%s: 'every' must be >= 1 frame (got %d)", sys, def->every),
		       EDDY_NULL_SYSTEM;
	if (!memchr(def->path, '\0', sizeof def->path) || !memchr(def->channels, '\0', sizeof def->channels))
		return eddy_world_fail(w, EDDY_ERR_INVALID, "%s: 'path' and 'channels' must be NUL-terminated", sys),
		       EDDY_NULL_SYSTEM;
	const char *why = eddy_check_frame_pattern(def->path);
	if (why)
		return eddy_world_fail(w, EDDY_ERR_INVALID, "%s: 'path' %s (got \"%s\")", sys, why, def->path), EDDY_NULL_SYSTEM;
	exporter *e = calloc(1, sizeof *e);
	if (!e)
		return eddy_world_fail(w, EDDY_ERR_NOMEM, "%s: out of memory", sys), EDDY_NULL_SYSTEM;
	e->def = *def;
	strcpy(e->names[0], "x"), strcpy(e->names[1], "y"), strcpy(e->names[2], "z");
	e->count = 3;
	const char *reads[MAX_CHANNELS + 3];
	int nreads = 0;
	bool need_v = false;
	for (const char *p = def->channels; *p;) {
		size_t len = strcspn(p, " ,\t");
		if (len == 0) {
			++p;
			continue;
		}
		char name[32];
		if (len >= sizeof name) {
			destroy(e);
			return eddy_world_fail(w, EDDY_ERR_INVALID, "%s: channel name '%.*s' is too long", sys, (int)len, p),
			       EDDY_NULL_SYSTEM;
		}
		memcpy(name, p, len);
		name[len] = '\0';
		p += len;
		bool dup = false;
		for (int c = 0; c < e->count; ++c)
			dup = dup || strcmp(e->names[c], name) == 0;
		if (dup)
			continue; /* x y z are always there; a repeat adds nothing */
		if (e->count == MAX_CHANNELS) {
			destroy(e);
			return eddy_world_fail(w, EDDY_ERR_INVALID, "%s: at most %d channels besides x y z", sys, MAX_CHANNELS - 3),
			       EDDY_NULL_SYSTEM;
		}
		if (strcmp(name, "speed") == 0) {
			need_v = true;
		} else {
			eddy_column_id id = eddy_world_find_column(w, name);
			eddy_column_info info;
			if (id < 0 || eddy_world_column_info(w, id, &info) != EDDY_OK || info.domain != EDDY_DOMAIN_PARTICLE ||
			    info.type != EDDY_F32) {
				destroy(e);
				return eddy_world_fail(w, EDDY_ERR_INVALID,
				                       "%s: 'channels': '%s' is not a per-particle number column (or \"speed\")", sys, name),
				       EDDY_NULL_SYSTEM;
			}
		}
		strcpy(e->names[e->count++], name);
	}
	/* the reads: every named column once, plus vx vy vz for speed */
	for (int c = 0; c < e->count; ++c)
		if (strcmp(e->names[c], "speed") != 0)
			reads[nreads++] = e->names[c];
	if (need_v) {
		static const char *const v[3] = {"vx", "vy", "vz"};
		for (int k = 0; k < 3; ++k) {
			bool have = false;
			for (int i = 0; i < nreads; ++i)
				have = have || strcmp(reads[i], v[k]) == 0;
			if (!have)
				reads[nreads++] = v[k];
		}
	}
	eddy_custom_system_def cd = eddy_default_custom_system_def();
	cd.name = sys;
	cd.reads = reads;
	cd.read_count = nreads;
	cd.frame = write_frame;
	cd.destroy = destroy;
	cd.user = e;
	eddy_system_id id = eddy_add_custom_system(w, &cd);
	if (!eddy_system_valid(w, id))
		destroy(e);
	return id;
}
