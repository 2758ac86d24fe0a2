/* SPDX-License-Identifier: MIT */
/* export_particles: writes the particles to one file per frame, for Blender,
 * Houdini, ParaView and MeshLab. A frame-only custom system.
 *
 * Reads: x y z and the listed channels (vx vy vz for "speed"); with channels
 * "all", every particle float column allocated at the frame (found then, so
 * it reads only x y z up front). Writes: files, each whole or not at all
 * (eddy_file: a temporary file renamed into place).
 *
 * PLY (binary_little_endian 1.0): one `vertex` element with a float property
 * per channel, x y z first, so every PLY reader sees a point cloud.
 * VTK (legacy "# vtk DataFile Version 3.0", BINARY, big-endian as that format
 * requires): POLYDATA with POINTS, one VERTICES cell per point (so ParaView
 * draws them without a Glyph filter) and the channels as one POINT_DATA
 * FIELD with a float array each.
 * VTP (VTK XML PolyData 1.0, little-endian, header_type UInt64, every array
 * in one raw AppendedData block): Points, one Verts cell per point, the frame
 * time as FieldData TimeValue, the channels as PointData Float32 arrays, where
 * a channel triple <p>x <p>y <p>z becomes one 3-component array (vx vy vz:
 * "velocity", ax ay az: "acceleration", others <p> without a trailing '_').
 * Next to the frames, a ParaView collection <stem>.pvd lists every frame file
 * written so far with its simulated time, rewritten whole each frame.
 *
 * Channel names are written with every character outside [A-Za-z0-9_.+-]
 * replaced by '_', so no name can break a PLY header or an XML attribute. */
#define _POSIX_C_SOURCE 200809L
#include "render.h"

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#define MAX_CHANNELS 20 /* names incl. x y z; with vx vy vz the reads stay within the core's 24 */
#define NAME_CAP 64     /* a written channel name, sanitised, plus a NUL */

/* A VTP point-data array: one channel, or a triple <p>x <p>y <p>z. */
typedef struct vtp_array {
	char name[NAME_CAP];
	int k; /* components, 1 or 3 */
	const float *col[3];
} vtp_array;

typedef struct pvd_entry {
	int frame;
	double time; /* s */
} pvd_entry;

typedef struct exporter {
	eddy_export_particles_def def;
	bool all;                     /* channels "all": every allocated particle float column */
	char names[MAX_CHANNELS][32]; /* explicit channels: x y z, then the chosen ones */
	int count;
	float *speed; /* the derived "speed" channel, cap floats */
	size_t cap;
	unsigned char *buf; /* file-order bytes of one chunk, grown as needed */
	size_t buf_cap;
	bool need_speed;     /* "speed" is a channel */
	const char **fnames; /* this frame's channels (x y z first) and their values */
	const float **fcols;
	struct vtp_array *arrays; /* VTP: the channels grouped, and which are taken */
	bool *used;
	int fcap; /* entries of each of the four above */
	/* VTP only: the collection file and the frames it lists, in frame order */
	char pvd[1024];
	size_t pvd_dir_len; /* bytes of the frame paths' folder prefix the .pvd shares */
	pvd_entry *entries;
	size_t entry_count, entry_cap;
	bool pvd_read; /* the collection on disk was taken over (see pvd_take_over) */
} exporter;

eddy_export_particles_def eddy_default_export_particles_def(void)
{
	eddy_export_particles_def d;
	memset(&d, 0, sizeof d);
	d.format = EDDY_EXPORT_PLY;
	strcpy(d.channels, "all");
	strcpy(d.path, "particles_%04d.ply");
	d.every = 1;
	return d;
}

static void put_le32(unsigned char *p, uint32_t v)
{
	p[0] = (unsigned char)v, p[1] = (unsigned char)(v >> 8), p[2] = (unsigned char)(v >> 16),
	p[3] = (unsigned char)(v >> 24);
}
static void put_le64(unsigned char *p, uint64_t v)
{
	put_le32(p, (uint32_t)v);
	put_le32(p + 4, (uint32_t)(v >> 32));
}
static void put_be32(unsigned char *p, uint32_t v)
{
	p[0] = (unsigned char)(v >> 24), p[1] = (unsigned char)(v >> 16), p[2] = (unsigned char)(v >> 8),
	p[3] = (unsigned char)v;
}
static uint32_t float_bits(float f)
{
	uint32_t u;
	memcpy(&u, &f, sizeof u);
	return u;
}

static void safe_name(const char *in, char out[NAME_CAP])
{
	size_t k = 0;
	for (; in[k] && k + 1 < NAME_CAP; ++k) {
		const char c = in[k];
		const bool ok = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '_' ||
		                c == '.' || c == '+' || c == '-';
		out[k] = ok ? c : '_';
	}
	out[k] = '\0';
}

/* Values go through the buffer CHUNK particles at a time: one fwrite per
 * chunk, and the buffer's size does not grow with the particle count. */
#define CHUNK 65536

static bool reserve(exporter *e, size_t n, int channels)
{
	if (e->need_speed && n > e->cap) {
		size_t cap = n + n / 4;
		float *s = realloc(e->speed, cap * sizeof *s);
		if (!s)
			return false;
		e->speed = s;
		e->cap = cap;
	}
	/* the widest chunk: every channel interleaved (PLY), or 8-byte cells */
	const size_t row = (size_t)(channels > 2 ? channels : 2) * 4;
	if (CHUNK * row > e->buf_cap) {
		unsigned char *b = realloc(e->buf, CHUNK * row);
		if (!b)
			return false;
		e->buf = b;
		e->buf_cap = CHUNK * row;
	}
	if (channels > e->fcap) {
		const size_t m = (size_t)channels;
		const char **nm = realloc(e->fnames, m * sizeof *nm);
		if (nm)
			e->fnames = nm;
		const float **cl = realloc(e->fcols, m * sizeof *cl);
		if (cl)
			e->fcols = cl;
		vtp_array *ar = realloc(e->arrays, m * sizeof *ar);
		if (ar)
			e->arrays = ar;
		bool *us = realloc(e->used, m * sizeof *us);
		if (us)
			e->used = us;
		if (!nm || !cl || !ar || !us)
			return false;
		e->fcap = channels;
	}
	return true;
}

/* k columns interleaved per particle, little- or big-endian floats. */
static void put_columns(exporter *e, eddy_file *f, const float *const *cols, int k, size_t n, bool big_endian)
{
	for (size_t first = 0; first < n && !f->err; first += CHUNK) {
		const size_t m = n - first < CHUNK ? n - first : CHUNK;
		unsigned char *p = e->buf;
		for (size_t i = first; i < first + m; ++i)
			for (int c = 0; c < k; ++c, p += 4) {
				const uint32_t u = float_bits(cols[c][i]);
				big_endian ? put_be32(p, u) : put_le32(p, u);
			}
		eddy_file_write(f, e->buf, (size_t)(p - e->buf));
	}
}

static void write_ply(exporter *e, eddy_file *f, size_t n, int nc, int frame, double t)
{
	eddy_file_printf(f,
	                 "ply\nformat binary_little_endian 1.0\ncomment eddy frame %d time %.17g s\nelement vertex %zu\n",
	                 frame, t, n);
	for (int c = 0; c < nc; ++c) {
		char name[NAME_CAP];
		safe_name(e->fnames[c], name);
		eddy_file_printf(f, "property float %s\n", name);
	}
	eddy_file_printf(f, "end_header\n");
	put_columns(e, f, e->fcols, nc, n, false);
}

static void write_vtk(exporter *e, eddy_file *f, size_t n, int nc, int frame, double t)
{
	eddy_file_printf(
		f, "# vtk DataFile Version 3.0\neddy frame %d time %.17g s\nBINARY\nDATASET POLYDATA\nPOINTS %zu float\n",
		frame, t, n);
	put_columns(e, f, e->fcols, 3, n, true);
	eddy_file_printf(f, "\nVERTICES %zu %zu\n", n, 2 * n);
	for (size_t first = 0; first < n && !f->err; first += CHUNK) {
		const size_t m = n - first < CHUNK ? n - first : CHUNK;
		unsigned char *p = e->buf;
		for (size_t i = first; i < first + m; ++i, p += 8) {
			put_be32(p, 1);
			put_be32(p + 4, (uint32_t)i);
		}
		eddy_file_write(f, e->buf, (size_t)(p - e->buf));
	}
	/* a FIELD, not SCALARS: VTK's legacy reader keeps only the first
	 * SCALARS of a dataset unless asked, but every array of a FIELD */
	eddy_file_printf(f, "\nPOINT_DATA %zu\n", n);
	if (nc > 3)
		eddy_file_printf(f, "FIELD channels %d\n", nc - 3);
	for (int c = 3; c < nc; ++c) {
		char name[NAME_CAP];
		safe_name(e->fnames[c], name);
		eddy_file_printf(f, "%s 1 %zu float\n", name, n);
		put_columns(e, f, &e->fcols[c], 1, n, true);
		eddy_file_printf(f, "\n");
	}
}

/* Groups this frame's channels (after x y z) into e->arrays (nc entries
 * are room enough: groups only shrink the list); returns the count. */
static int vtp_arrays(exporter *e, int nc)
{
	int count = 0;
	bool *used = e->used;
	vtp_array *arrays = e->arrays;
	memset(used, 0, (size_t)nc * sizeof *used);
	for (int c = 3; c < nc; ++c) {
		if (used[c])
			continue;
		const char *s = e->fnames[c];
		const size_t len = strlen(s);
		vtp_array *a = &arrays[count++];
		a->k = 1;
		a->col[0] = e->fcols[c];
		safe_name(s, a->name);
		if (len < 2 || len >= NAME_CAP || s[len - 1] != 'x')
			continue;
		int yz[2] = {-1, -1};
		for (int d = 3; d < nc; ++d)
			for (int q = 0; q < 2; ++q)
				if (!used[d] && d != c && strlen(e->fnames[d]) == len && strncmp(e->fnames[d], s, len - 1) == 0 &&
				    e->fnames[d][len - 1] == "yz"[q])
					yz[q] = d;
		if (yz[0] < 0 || yz[1] < 0)
			continue;
		used[c] = used[yz[0]] = used[yz[1]] = true;
		a->k = 3;
		a->col[1] = e->fcols[yz[0]];
		a->col[2] = e->fcols[yz[1]];
		char prefix[NAME_CAP];
		memcpy(prefix, s, len - 1);
		prefix[len - 1] = '\0';
		size_t pl = len - 1;
		while (pl > 1 && prefix[pl - 1] == '_')
			prefix[--pl] = '\0';
		safe_name(strcmp(prefix, "v") == 0 ? "velocity" : strcmp(prefix, "a") == 0 ? "acceleration" : prefix, a->name);
	}
	return count;
}

static void write_vtp(exporter *e, eddy_file *f, size_t n, int nc, int frame, double t)
{
	const int na = vtp_arrays(e, nc);
	const vtp_array *arrays = e->arrays;
	/* vtkIdType is 64-bit, but VTK reads 32-bit cells too: half the bytes */
	const bool wide = n > (size_t)INT32_MAX;
	const size_t isz = wide ? 8 : 4;
	const char *itype = wide ? "Int64" : "Int32";
	eddy_file_printf(
		f,
		"<?xml version=\"1.0\"?>\n"
		"<VTKFile type=\"PolyData\" version=\"1.0\" byte_order=\"LittleEndian\" header_type=\"UInt64\">\n"
		"  <PolyData>\n"
		"    <FieldData>\n"
		"      <DataArray type=\"Float64\" Name=\"TimeValue\" NumberOfTuples=\"1\" format=\"ascii\">%.17g</DataArray>\n"
		"      <DataArray type=\"Int32\" Name=\"Frame\" NumberOfTuples=\"1\" format=\"ascii\">%d</DataArray>\n"
		"    </FieldData>\n"
		"    <Piece NumberOfPoints=\"%zu\" NumberOfVerts=\"%zu\" NumberOfLines=\"0\" NumberOfStrips=\"0\" "
		"NumberOfPolys=\"0\">\n",
		t, frame, n, n);
	bool velocity = false;
	for (int a = 0; a < na; ++a)
		velocity = velocity || (arrays[a].k == 3 && strcmp(arrays[a].name, "velocity") == 0);
	eddy_file_printf(f, velocity ? "      <PointData Vectors=\"velocity\">\n" : "      <PointData>\n");
	/* offsets count from the byte after '_'; each block is a UInt64 byte
	 * count, then the bytes */
	uint64_t off = 0;
	for (int a = 0; a < na; ++a) {
		eddy_file_printf(
			f,
			"        <DataArray type=\"Float32\" Name=\"%s\" NumberOfComponents=\"%d\" format=\"appended\" "
			"offset=\"%llu\"/>\n",
			arrays[a].name, arrays[a].k, (unsigned long long)off);
		off += 8 + (uint64_t)n * 4 * (uint64_t)arrays[a].k;
	}
	eddy_file_printf(f,
	                 "      </PointData>\n      <Points>\n"
	                 "        <DataArray type=\"Float32\" Name=\"Points\" NumberOfComponents=\"3\" format=\"appended\" "
	                 "offset=\"%llu\"/>\n      </Points>\n      <Verts>\n",
	                 (unsigned long long)off);
	off += 8 + (uint64_t)n * 12;
	eddy_file_printf(f, "        <DataArray type=\"%s\" Name=\"connectivity\" format=\"appended\" offset=\"%llu\"/>\n",
	                 itype, (unsigned long long)off);
	off += 8 + (uint64_t)n * isz;
	eddy_file_printf(f,
	                 "        <DataArray type=\"%s\" Name=\"offsets\" format=\"appended\" offset=\"%llu\"/>\n"
	                 "      </Verts>\n    </Piece>\n  </PolyData>\n  <AppendedData encoding=\"raw\">\n   _",
	                 itype, (unsigned long long)off);
	unsigned char head[8];
	for (int a = 0; a < na; ++a) {
		put_le64(head, (uint64_t)n * 4 * (uint64_t)arrays[a].k);
		eddy_file_write(f, head, 8);
		put_columns(e, f, arrays[a].col, arrays[a].k, n, false);
	}
	put_le64(head, (uint64_t)n * 12);
	eddy_file_write(f, head, 8);
	put_columns(e, f, e->fcols, 3, n, false);
	/* connectivity 0 .. n-1, then offsets 1 .. n: one vertex per cell */
	for (int pass = 0; pass < 2; ++pass) {
		put_le64(head, (uint64_t)n * isz);
		eddy_file_write(f, head, 8);
		for (size_t first = 0; first < n && !f->err; first += CHUNK) {
			const size_t m = n - first < CHUNK ? n - first : CHUNK;
			unsigned char *p = e->buf;
			for (size_t i = first; i < first + m; ++i, p += isz) {
				const uint64_t v = (uint64_t)i + (uint64_t)pass;
				wide ? put_le64(p, v) : put_le32(p, (uint32_t)v);
			}
			eddy_file_write(f, e->buf, (size_t)(p - e->buf));
		}
	}
	eddy_file_printf(f, "\n  </AppendedData>\n</VTKFile>\n");
}

static eddy_status pvd_add(eddy_world *w, exporter *e, int frame, double t)
{
	if (e->entry_count == e->entry_cap) {
		size_t cap = e->entry_cap ? 2 * e->entry_cap : 64;
		pvd_entry *p = realloc(e->entries, cap * sizeof *p);
		if (!p)
			return eddy_world_fail(w, EDDY_ERR_NOMEM, "out of memory for the collection '%s'", e->pvd);
		e->entries = p;
		e->entry_cap = cap;
	}
	e->entries[e->entry_count++] = (pvd_entry){frame, t};
	return EDDY_OK;
}

/* A frame path relative to the .pvd, XML-escaped as the collection stores it. */
static int pvd_file_attr(const exporter *e, int frame, char *out, size_t cap)
{
	char path[1024];
	if (eddy_frame_path(e->def.path, frame, path, sizeof path) != 0)
		return -1;
	size_t n = 0;
	for (const char *c = path + e->pvd_dir_len; *c; ++c) {
		const char *rep = *c == '&' ? "&amp;" : *c == '<' ? "&lt;" : *c == '>' ? "&gt;" : *c == '"' ? "&quot;" : NULL;
		size_t k = rep ? strlen(rep) : 1;
		if (n + k + 1 > cap)
			return -1;
		memcpy(out + n, rep ? rep : c, k);
		n += k;
	}
	out[n] = '\0';
	return 0;
}

/* A world resumed from a checkpoint in a new process starts its exporter at
 * the checkpoint's frame: the frames before it are on disk from the earlier
 * process, listed in the collection it left. Those of its entries whose file
 * still exists and whose frame comes before this one are kept, with their
 * times; anything unreadable is simply not taken over. */
static eddy_status pvd_take_over(eddy_world *w, exporter *e, int frame)
{
	e->pvd_read = true;
	if (frame <= 1)
		return EDDY_OK;
	FILE *f = fopen(e->pvd, "rb");
	if (!f)
		return EDDY_OK;
	char *text = NULL;
	long size = fseek(f, 0, SEEK_END) == 0 ? ftell(f) : -1;
	if (size > 0 && size < (64L << 20) && fseek(f, 0, SEEK_SET) == 0 && (text = malloc((size_t)size + 1)) &&
	    fread(text, 1, (size_t)size, f) == (size_t)size)
		text[size] = '\0';
	else {
		free(text);
		text = NULL;
	}
	fclose(f);
	eddy_status st = EDDY_OK;
	for (int k = 0; text && k < frame && st == EDDY_OK; ++k) {
		char attr[1100], needle[1120], path[1024];
		if (pvd_file_attr(e, k, attr, sizeof attr) != 0 || eddy_frame_path(e->def.path, k, path, sizeof path) != 0)
			break;
		snprintf(needle, sizeof needle, "file=\"%s\"", attr);
		const char *hit = strstr(text, needle);
		if (!hit || access(path, F_OK) != 0)
			continue;
		const char *line = hit;
		while (line > text && line[-1] != '\n')
			--line;
		const char *ts = strstr(line, "timestep=\"");
		if (!ts || ts > hit)
			continue;
		double t = strtod(ts + 10, NULL);
		if (isfinite(t))
			st = pvd_add(w, e, k, t);
	}
	free(text);
	return st;
}

/* Records the frame and rewrites the collection. A frame at or before one
 * already listed (a world loaded from a checkpoint and run again) replaces
 * that entry and every later one, so the list follows the files on disk. */
static eddy_status write_pvd(eddy_world *w, exporter *e, int frame, double t)
{
	eddy_status st = e->pvd_read ? EDDY_OK : pvd_take_over(w, e, frame);
	while (e->entry_count > 0 && e->entries[e->entry_count - 1].frame >= frame)
		--e->entry_count;
	if (st == EDDY_OK)
		st = pvd_add(w, e, frame, t);
	if (st != EDDY_OK)
		return st;
	eddy_file f;
	if (eddy_file_begin(&f, e->pvd) != 0)
		return eddy_world_fail(w, EDDY_ERR_IO, "cannot write '%s': %s", e->pvd, strerror(f.err));
	eddy_file_printf(
		&f, "<?xml version=\"1.0\"?>\n<VTKFile type=\"Collection\" version=\"0.1\" byte_order=\"LittleEndian\">\n"
			"  <Collection>\n");
	for (size_t i = 0; i < e->entry_count && !f.err; ++i) {
		/* frame paths share the .pvd's folder prefix; the rest is relative
		 * to it */
		char attr[1100];
		if (pvd_file_attr(e, e->entries[i].frame, attr, sizeof attr) != 0) {
			eddy_file_abort(&f);
			return eddy_world_fail(w, EDDY_ERR_IO, "the export path for frame %d is too long", e->entries[i].frame);
		}
		eddy_file_printf(&f, "    <DataSet timestep=\"%.17g\" group=\"\" part=\"0\" file=\"%s\"/>\n",
		                 e->entries[i].time, attr);
	}
	eddy_file_printf(&f, "  </Collection>\n</VTKFile>\n");
	if (eddy_file_finish(&f) != 0)
		return eddy_world_fail(w, EDDY_ERR_IO, "cannot write '%s': %s", e->pvd, strerror(f.err));
	return EDDY_OK;
}

/* This frame's channels into e->fnames / e->fcols (x y z first), their
 * count into *count. */
static eddy_status frame_channels(eddy_world *w, exporter *e, size_t n, int *count)
{
	const int most = e->all ? eddy_world_column_count(w) + 3 : e->count;
	if (!reserve(e, n, most))
		return eddy_world_fail(w, EDDY_ERR_NOMEM, "out of memory exporting %zu particles", n);
	int nc = 0;
	if (!e->all) {
		for (int c = 0; c < e->count; ++c)
			e->fnames[nc++] = e->names[c];
	} else {
		e->fnames[nc++] = "x", e->fnames[nc++] = "y", e->fnames[nc++] = "z";
		for (int id = 0; id < most - 3; ++id) {
			eddy_column_info info;
			if (eddy_world_column_info(w, id, &info) != EDDY_OK || !info.allocated ||
			    info.domain != EDDY_DOMAIN_PARTICLE || info.type != EDDY_F32 || !strcmp(info.name, "x") ||
			    !strcmp(info.name, "y") || !strcmp(info.name, "z"))
				continue;
			e->fnames[nc++] = info.name;
		}
	}
	for (int c = 0; c < nc; ++c) {
		e->fcols[c] = NULL;
		/* no particles: no values to read (an empty column may have no memory) */
		if (n > 0 && !(e->fcols[c] = eddy_particle_values(w, e->fnames[c], e->speed, n)))
			return eddy_world_fail(w, EDDY_ERR_INVALID, "channel '%s' is not available", e->fnames[c]);
	}
	*count = nc;
	return EDDY_OK;
}

static eddy_status write_frame(eddy_world *w, int frame, void *user)
{
	exporter *e = user;
	if (frame % e->def.every != 0)
		return EDDY_OK;
	const size_t n = eddy_world_particle_count(w);
	int nc = 0;
	const eddy_status st = frame_channels(w, e, n, &nc);
	if (st != EDDY_OK)
		return st;
	char path[1024];
	if (eddy_frame_path(e->def.path, frame, path, sizeof path) != 0)
		return eddy_world_fail(w, EDDY_ERR_IO, "the export path for frame %d is too long", frame);
	eddy_file f;
	if (eddy_file_begin(&f, path) != 0)
		return eddy_world_fail(w, EDDY_ERR_IO, "cannot write '%s': %s", path, strerror(f.err));
	const double t = eddy_world_time(w);
	switch (e->def.format) {
	case EDDY_EXPORT_PLY:
		write_ply(e, &f, n, nc, frame, t);
		break;
	case EDDY_EXPORT_VTK:
		write_vtk(e, &f, n, nc, frame, t);
		break;
	case EDDY_EXPORT_VTP:
		write_vtp(e, &f, n, nc, frame, t);
		break;
	}
	if (eddy_file_finish(&f) != 0)
		return eddy_world_fail(w, EDDY_ERR_IO, "cannot write '%s': %s", path, strerror(f.err));
	/* after the frame's file, so the collection never lists a missing file */
	return e->def.format == EDDY_EXPORT_VTP ? write_pvd(w, e, frame, t) : EDDY_OK;
}

static void destroy(void *user)
{
	exporter *e = user;
	free(e->speed);
	free(e->buf);
	free(e->fnames);
	free(e->fcols);
	free(e->arrays);
	free(e->used);
	free(e->entries);
	free(e);
}

/* The collection's name from the path pattern: the text before the frame's
 * conversion, '%%' unescaped; its folder is the .pvd's folder, and the part
 * after the folder, without trailing '_', '-', '.' or ' ', its stem
 * ("particles" when nothing is left): out/p_%04d.vtp gives out/p.pvd, whose
 * entries read p_0001.vtp ... Returns false if the name does not fit. */
static bool pvd_path(exporter *e)
{
	char prefix[1024];
	size_t k = 0;
	for (const char *c = e->def.path; *c && k + 1 < sizeof prefix; ++c) {
		if (c[0] == '%' && c[1] == '%') {
			prefix[k++] = '%';
			++c;
		} else if (c[0] == '%') {
			break;
		} else {
			prefix[k++] = *c;
		}
	}
	prefix[k] = '\0';
	const char *slash = strrchr(prefix, '/');
	e->pvd_dir_len = slash ? (size_t)(slash - prefix) + 1 : 0;
	while (k > e->pvd_dir_len && strchr("_-. ", prefix[k - 1]))
		prefix[--k] = '\0';
	const char *stem = k > e->pvd_dir_len ? prefix + e->pvd_dir_len : "particles";
	int n = snprintf(e->pvd, sizeof e->pvd, "%.*s%s.pvd", (int)e->pvd_dir_len, prefix, stem);
	return n > 0 && (size_t)n < sizeof e->pvd;
}

eddy_system_id eddy_add_export_particles(eddy_world *w, const eddy_export_particles_def *def)
{
	const char *sys = "export_particles";
	if (!w)
		return EDDY_NULL_SYSTEM;
	if (!def)
		return eddy_world_fail(w, EDDY_ERR_INVALID, "%s: def is NULL", sys), EDDY_NULL_SYSTEM;
	if (def->format != EDDY_EXPORT_PLY && def->format != EDDY_EXPORT_VTK && def->format != EDDY_EXPORT_VTP)
		return eddy_world_fail(w, EDDY_ERR_INVALID, "%s: 'format' must be ply, vtk or vtp (got %d)", sys,
		                       (int)def->format),
		       EDDY_NULL_SYSTEM;
	if (def->every < 1)
		return eddy_world_fail(w, EDDY_ERR_INVALID, "%s: 'every' must be >= 1 frame (got %d)", sys, def->every),
		       EDDY_NULL_SYSTEM;
	if (!memchr(def->path, '\0', sizeof def->path) || !memchr(def->channels, '\0', sizeof def->channels))
		return eddy_world_fail(w, EDDY_ERR_INVALID, "%s: 'path' and 'channels' must be NUL-terminated", sys),
		       EDDY_NULL_SYSTEM;
	const char *why = eddy_check_frame_pattern(def->path);
	if (why)
		return eddy_world_fail(w, EDDY_ERR_INVALID, "%s: 'path' %s (got \"%s\")", sys, why, def->path),
		       EDDY_NULL_SYSTEM;
	exporter *e = calloc(1, sizeof *e);
	if (!e)
		return eddy_world_fail(w, EDDY_ERR_NOMEM, "%s: out of memory", sys), EDDY_NULL_SYSTEM;
	e->def = *def;
	if (def->format == EDDY_EXPORT_VTP && !pvd_path(e)) {
		destroy(e);
		return eddy_world_fail(w, EDDY_ERR_INVALID, "%s: 'path' is too long for its .pvd collection", sys),
		       EDDY_NULL_SYSTEM;
	}
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
		if (strcmp(name, "all") == 0) {
			e->all = true;
			continue;
		}
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
			need_v = e->need_speed = true;
		} else {
			eddy_column_id id = eddy_world_find_column(w, name);
			eddy_column_info info;
			if (id < 0 || eddy_world_column_info(w, id, &info) != EDDY_OK || info.domain != EDDY_DOMAIN_PARTICLE ||
			    info.type != EDDY_F32) {
				destroy(e);
				return eddy_world_fail(
						   w, EDDY_ERR_INVALID,
						   "%s: 'channels': '%s' is not a per-particle number column (or \"speed\" or \"all\")", sys,
						   name),
				       EDDY_NULL_SYSTEM;
			}
		}
		strcpy(e->names[e->count++], name);
	}
	if (e->all && e->count > 3) {
		destroy(e);
		return eddy_world_fail(w, EDDY_ERR_INVALID,
		                       "%s: 'channels': \"all\" stands alone (it already holds every column)", sys),
		       EDDY_NULL_SYSTEM;
	}
	/* the reads: every named column once, plus vx vy vz for speed; "all"
	 * reads what the other systems keep allocated, so only x y z here */
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
