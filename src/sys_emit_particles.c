/* SPDX-License-Identifier: MIT */
/* emit_particles: the particles of a PLY file, emitted once.
 *
 * Reads: nothing. Writes: x y z vx vy vz.
 * The file is read when the system is added: the header (format ascii,
 * binary_little_endian or binary_big_endian 1.0; elements with scalar and
 * list properties of any PLY type), then the rows of the `vertex` element
 * (elements before it are skipped). x y z are required; vx vy vz are taken
 * when all three are there (export_particles writes them under these
 * names), else every particle gets the def's velocity. Other properties
 * (density, pressure, ...) are read past. Values are converted to float, so
 * a file export_particles wrote comes back bit for bit. Any problem is one
 * line naming the file and what is wrong (the header line, or the vertex
 * and property). The spacing is the world's length scale, as an
 * emitter's. */
#include "systems.h"

#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

typedef struct emit_particles {
	eddy_emit_particles_def def;
	bool done;
	size_t count;
	float speed;  /* m/s, the fastest particle's */
	float data[]; /* x y z vx vy vz, count each */
} emit_particles;

static const int ep_writes[] = {COL_X_, COL_Y_, COL_Z_, COL_VX, COL_VY, COL_VZ, -1};

eddy_emit_particles_def eddy_default_emit_particles_def(void)
{
	eddy_emit_particles_def d;
	memset(&d, 0, sizeof d);
	d.spacing = 0.01f;
	return d;
}

static eddy_status step(eddy_world *w, eddy_system *s, const eddy_step_context *ctx)
{
	emit_particles *e = s->data;
	if (e->done || ctx->time + 1e-12 < e->def.start)
		return EDDY_OK;
	e->done = true;
	size_t first;
	eddy_status st = eddy__append_particles(w, e->count, &first);
	if (st != EDDY_OK)
		return st;
	const int cols[6] = {COL_X_, COL_Y_, COL_Z_, COL_VX, COL_VY, COL_VZ};
	for (int c = 0; c < 6; ++c)
		memcpy(eddy__col(w, cols[c]) + first, e->data + (size_t)c * e->count, e->count * sizeof(float));
	return EDDY_OK;
}

static int64_t expected(const eddy_world *w, const eddy_system *s)
{
	(void)w;
	const emit_particles *e = s->data;
	return e->done ? 0 : (int64_t)e->count;
}

static size_t sample(const eddy_world *w, const eddy_system *s, eddy_vec3 *out, size_t cap)
{
	(void)w;
	const emit_particles *e = s->data;
	if (!out)
		return e->count;
	size_t k = 0;
	for (; k < e->count && k < cap; ++k)
		out[k] = eddy__v3(e->data[k], e->data[e->count + k], e->data[2 * e->count + k]);
	return k;
}

static void *state(eddy_world *w, eddy_system *s, size_t *size)
{
	(void)w;
	emit_particles *e = s->data;
	*size = sizeof e->done;
	return &e->done;
}

static int check(eddy_world *w, const eddy_system *s, eddy_check_fn report, void *user)
{
	eddy__check_emitter_start(w, s, ((const emit_particles *)s->data)->def.start, report, user);
	return 0;
}

static float spacing(const eddy_system *s) { return ((const emit_particles *)s->data)->def.spacing; }

static double limit(eddy_world *w, eddy_system *s, const char **reason)
{
	const emit_particles *e = s->data;
	return eddy__emission_limit(w, e->done, e->def.start, e->def.spacing, e->speed, reason);
}

/* The file's highest particle and its fastest. */
static void reach(const eddy_system *s, eddy_vec3 up, eddy_vec3 *top, double *speed)
{
	const emit_particles *e = s->data;
	double best = -INFINITY;
	*top = eddy__v3(0, 0, 0);
	for (size_t k = 0; k < e->count; ++k) {
		const eddy_vec3 p = eddy__v3(e->data[k], e->data[e->count + k], e->data[2 * e->count + k]);
		const double t = (double)p.x * up.x + (double)p.y * up.y + (double)p.z * up.z;
		if (t > best)
			best = t, *top = p;
	}
	*speed = e->speed;
}

const eddy_system_vtable eddy__kind_emit_particles = {
	.name = "emit_particles",
	.state = state,
	.step = step,
	.limit = limit,
	.expected_particles = expected,
	.sample = sample,
	.spacing = spacing,
	.reach = reach,
	.check = check,
	.default_writes = ep_writes,
};

/* ---- PLY ------------------------------------------------------------------ */

enum { PLY_ASCII, PLY_LE, PLY_BE };
enum { MAX_ELEMS = 16, MAX_PROPS = 64 };

typedef struct ply_prop {
	char name[32];
	int type;      /* index into type_names / 2 */
	int list_type; /* -1 for a scalar */
} ply_prop;

typedef struct ply_elem {
	char name[32];
	size_t count;
	int nprops;
	ply_prop props[MAX_PROPS];
} ply_elem;

static const char *const type_names[] = {"char", "int8",  "uchar", "uint8",  "short", "int16",   "ushort", "uint16",
                                         "int",  "int32", "uint",  "uint32", "float", "float32", "double", "float64"};
static const int type_size[] = {1, 1, 2, 2, 4, 4, 4, 8};

static int type_of(const char *s)
{
	for (int i = 0; i < 16; ++i)
		if (strcmp(s, type_names[i]) == 0)
			return i / 2;
	return -1;
}

/* One binary value of type t at p, as a double. */
static double binary_value(const unsigned char *p, int t, bool big)
{
	unsigned char b[8];
	const int n = type_size[t];
	for (int i = 0; i < n; ++i)
		b[i] = big ? p[n - 1 - i] : p[i];
	uint64_t u = 0;
	for (int i = n - 1; i >= 0; --i)
		u = u << 8 | b[i];
	switch (t) {
	case 0:
		return (double)(int8_t)u;
	case 1:
		return (double)(uint8_t)u;
	case 2:
		return (double)(int16_t)u;
	case 3:
		return (double)(uint16_t)u;
	case 4:
		return (double)(int32_t)u;
	case 5:
		return (double)(uint32_t)u;
	case 6: {
		uint32_t v = (uint32_t)u;
		float f;
		memcpy(&f, &v, sizeof f);
		return f;
	}
	default: {
		double d;
		memcpy(&d, &u, sizeof d);
		return d;
	}
	}
}

typedef struct reader {
	const char *path;
	const unsigned char *buf;
	size_t len, pos;
	char *err;
	size_t cap;
} reader;

/* The next value of type t (binary) or token (ascii) as a double. */
static bool next_value(reader *r, int format, int t, double *out, const char *what, size_t row)
{
	if (format == PLY_ASCII) {
		while (r->pos < r->len &&
		       (r->buf[r->pos] == ' ' || r->buf[r->pos] == '\t' || r->buf[r->pos] == '\n' || r->buf[r->pos] == '\r'))
			r->pos++;
		if (r->pos >= r->len) {
			snprintf(r->err, r->cap, "%s: the data ends at row %zu of '%s'", r->path, row, what);
			return false;
		}
		char tok[64];
		size_t k = 0;
		while (r->pos < r->len && !strchr(" \t\r\n", r->buf[r->pos]) && k + 1 < sizeof tok)
			tok[k++] = (char)r->buf[r->pos++];
		tok[k] = '\0';
		char *end;
		errno = 0;
		*out = strtod(tok, &end);
		if (end == tok || *end) {
			snprintf(r->err, r->cap, "%s: row %zu of '%s': '%s' is not a number", r->path, row, what, tok);
			return false;
		}
		return true;
	}
	const size_t n = (size_t)type_size[t];
	if (r->len - r->pos < n) {
		snprintf(r->err, r->cap, "%s: the data ends at row %zu of '%s'", r->path, row, what);
		return false;
	}
	*out = binary_value(r->buf + r->pos, t, format == PLY_BE);
	r->pos += n;
	return true;
}

/* Reads the file's vertices into a new emit_particles block (NULL on error). */
static emit_particles *read_ply(const char *path, eddy_vec3 vdef, char *err, size_t cap)
{
	FILE *f = fopen(path, "rb");
	if (!f) {
		snprintf(err, cap, "%s: cannot open: %s", path, strerror(errno));
		return NULL;
	}
	unsigned char *buf = NULL;
	size_t len = 0, got;
	for (;;) {
		unsigned char *nb = realloc(buf, len + 65536);
		if (!nb) {
			free(buf);
			fclose(f);
			snprintf(err, cap, "%s: out of memory reading it", path);
			return NULL;
		}
		buf = nb;
		got = fread(buf + len, 1, 65536, f);
		len += got;
		if (got < 65536)
			break;
	}
	const bool rerr = ferror(f);
	fclose(f);
	emit_particles *e = NULL;
	reader r = {path, buf, len, 0, err, cap};
	if (rerr) {
		snprintf(err, cap, "%s: read error", path);
		goto out;
	}
	/* the header, line by line */
	ply_elem elems[MAX_ELEMS];
	int nelem = 0, format = -1, line_no = 0;
	bool ended = false;
	while (r.pos < len && !ended) {
		size_t end = r.pos;
		while (end < len && buf[end] != '\n')
			end++;
		char line[256];
		size_t ll = end - r.pos < sizeof line - 1 ? end - r.pos : sizeof line - 1;
		memcpy(line, buf + r.pos, ll);
		line[ll] = '\0';
		if (ll && line[ll - 1] == '\r')
			line[ll - 1] = '\0';
		r.pos = end < len ? end + 1 : end;
		line_no++;
		char w0[32] = "", w1[32] = "", w2[32] = "", w3[32] = "", w4[32] = "";
		const int nw = sscanf(line, "%31s %31s %31s %31s %31s", w0, w1, w2, w3, w4);
		if (line_no == 1) {
			if (strcmp(w0, "ply") != 0) {
				snprintf(err, cap, "%s: not a PLY file (the first line is not 'ply')", path);
				goto out;
			}
			continue;
		}
		if (nw <= 0 || strcmp(w0, "comment") == 0 || strcmp(w0, "obj_info") == 0)
			continue;
		if (strcmp(w0, "end_header") == 0) {
			ended = true;
		} else if (strcmp(w0, "format") == 0) {
			format = strcmp(w1, "ascii") == 0                  ? PLY_ASCII
			         : strcmp(w1, "binary_little_endian") == 0 ? PLY_LE
			         : strcmp(w1, "binary_big_endian") == 0    ? PLY_BE
			                                                   : -1;
			if (format < 0 || strcmp(w2, "1.0") != 0) {
				snprintf(err, cap,
				         "%s: header line %d: unknown format '%s %s' (ascii, binary_little_endian or "
				         "binary_big_endian 1.0)",
				         path, line_no, w1, w2);
				goto out;
			}
		} else if (strcmp(w0, "element") == 0) {
			char *endp;
			errno = 0;
			const unsigned long long c = strtoull(w2, &endp, 10);
			if (nw != 3 || endp == w2 || *endp || errno || w2[0] == '-') {
				snprintf(err, cap, "%s: header line %d: 'element' needs a name and a count", path, line_no);
				goto out;
			}
			if (nelem == MAX_ELEMS) {
				snprintf(err, cap, "%s: header line %d: more than %d elements", path, line_no, MAX_ELEMS);
				goto out;
			}
			ply_elem *el = &elems[nelem++];
			memset(el, 0, sizeof *el);
			snprintf(el->name, sizeof el->name, "%s", w1);
			el->count = (size_t)c;
			if (c > ((size_t)1 << 31)) {
				snprintf(err, cap, "%s: header line %d: %llu %s is more than eddy can hold", path, line_no, c, w1);
				goto out;
			}
		} else if (strcmp(w0, "property") == 0) {
			if (nelem == 0) {
				snprintf(err, cap, "%s: header line %d: a property before any element", path, line_no);
				goto out;
			}
			ply_elem *el = &elems[nelem - 1];
			if (el->nprops == MAX_PROPS) {
				snprintf(err, cap, "%s: header line %d: more than %d properties", path, line_no, MAX_PROPS);
				goto out;
			}
			ply_prop *p = &el->props[el->nprops++];
			const bool list = strcmp(w1, "list") == 0;
			p->list_type = list ? type_of(w2) : -1;
			p->type = type_of(list ? w3 : w1);
			snprintf(p->name, sizeof p->name, "%s", list ? w4 : w2);
			if (p->type < 0 || (list && p->list_type < 0) || nw != (list ? 5 : 3)) {
				snprintf(err, cap,
				         "%s: header line %d: cannot read '%s' (property <type> <name>, or property list "
				         "<count type> <type> <name>)",
				         path, line_no, line);
				goto out;
			}
		} else {
			snprintf(err, cap, "%s: header line %d: unknown keyword '%s'", path, line_no, w0);
			goto out;
		}
	}
	if (!ended) {
		snprintf(err, cap, "%s: the header has no 'end_header' line", path);
		goto out;
	}
	if (format < 0) {
		snprintf(err, cap, "%s: the header has no 'format' line", path);
		goto out;
	}
	int ve = -1;
	for (int i = 0; i < nelem && ve < 0; ++i)
		if (strcmp(elems[i].name, "vertex") == 0)
			ve = i;
	if (ve < 0) {
		snprintf(err, cap, "%s: no 'vertex' element", path);
		goto out;
	}
	const ply_elem *V = &elems[ve];
	const char *names[6] = {"x", "y", "z", "vx", "vy", "vz"};
	int col[6];
	for (int c = 0; c < 6; ++c) {
		col[c] = -1;
		for (int p = 0; p < V->nprops; ++p)
			if (strcmp(V->props[p].name, names[c]) == 0 && V->props[p].list_type < 0)
				col[c] = p;
	}
	for (int c = 0; c < 3; ++c)
		if (col[c] < 0) {
			snprintf(err, cap, "%s: the vertex element has no scalar property '%s'", path, names[c]);
			goto out;
		}
	const int nvel = (col[3] >= 0) + (col[4] >= 0) + (col[5] >= 0);
	if (nvel != 0 && nvel != 3) {
		snprintf(err, cap, "%s: the vertex element has %d of the velocity properties vx vy vz; give all three or none",
		         path, nvel);
		goto out;
	}
	if (V->count == 0) {
		snprintf(err, cap, "%s: the file holds no particles (element vertex 0)", path);
		goto out;
	}
	/* elements before the vertices: read past */
	for (int i = 0; i < ve; ++i)
		for (size_t row = 0; row < elems[i].count; ++row)
			for (int p = 0; p < elems[i].nprops; ++p) {
				const ply_prop *pp = &elems[i].props[p];
				double v, cnt = 1;
				if (pp->list_type >= 0 && !next_value(&r, format, pp->list_type, &cnt, elems[i].name, row))
					goto out;
				if (!(cnt >= 0 && cnt <= 1e6)) {
					snprintf(err, cap, "%s: row %zu of '%.31s': a list of %g entries", path, row, elems[i].name, cnt);
					goto out;
				}
				for (int k = 0; k < (int)cnt; ++k)
					if (!next_value(&r, format, pp->type, &v, elems[i].name, row))
						goto out;
			}
	const size_t n = V->count;
	e = calloc(1, sizeof *e + 6 * n * sizeof(float));
	if (!e) {
		snprintf(err, cap, "%s: out of memory for %zu particles", path, n);
		goto out;
	}
	e->count = n;
	for (size_t row = 0; row < n; ++row) {
		float val[6] = {0, 0, 0, vdef.x, vdef.y, vdef.z};
		for (int p = 0; p < V->nprops; ++p) {
			const ply_prop *pp = &V->props[p];
			double v, cnt = 1;
			if (pp->list_type >= 0 && !next_value(&r, format, pp->list_type, &cnt, "vertex", row))
				goto fail;
			if (!(cnt >= 0 && cnt <= 1e6)) {
				snprintf(err, cap, "%s: vertex %zu: a list of %g entries", path, row, cnt);
				goto fail;
			}
			for (int k = 0; k < (int)cnt; ++k) {
				if (!next_value(&r, format, pp->type, &v, "vertex", row))
					goto fail;
				for (int c = 0; c < 6; ++c)
					if (col[c] == p) {
						if (!isfinite(v)) {
							snprintf(err, cap, "%s: vertex %zu: '%s' is not finite", path, row, names[c]);
							goto fail;
						}
						val[c] = (float)v;
					}
			}
		}
		for (int c = 0; c < 6; ++c)
			e->data[(size_t)c * n + row] = val[c];
	}
	goto out;
fail:
	free(e);
	e = NULL;
out:
	free(buf);
	return e;
}

eddy_system_id eddy_add_emit_particles(eddy_world *w, const eddy_emit_particles_def *def)
{
	const char *sys = "emit_particles";
	if (!eddy__add_args(w, def, sys))
		return EDDY_NULL_SYSTEM;
	if (!eddy__check_positive(w, sys, "spacing", def->spacing) ||
	    !eddy__check_vec3(w, sys, "velocity", def->velocity) || !eddy__check_nonneg(w, sys, "start", def->start))
		return EDDY_NULL_SYSTEM;
	if (!memchr(def->path, '\0', sizeof def->path) || !def->path[0])
		return eddy__fail(w, EDDY_ERR_INVALID, "%s: 'path' must name a PLY file", sys), EDDY_NULL_SYSTEM;
	char err[EDDY_ERROR_MAX - 64];
	emit_particles *e = read_ply(def->path, def->velocity, err, sizeof err);
	if (!e)
		return eddy__fail(w, EDDY_ERR_IO, "%s: %s", sys, err), EDDY_NULL_SYSTEM;
	e->def = *def;
	const eddy_vec3 lo = w->def.bounds_min, hi = w->def.bounds_max;
	const size_t n = e->count;
	e->speed = 0;
	for (size_t i = 0; i < n; ++i) {
		const float x = e->data[i], y = e->data[n + i], z = e->data[2 * n + i];
		const float s = eddy__norm3((eddy_vec3){e->data[3 * n + i], e->data[4 * n + i], e->data[5 * n + i]});
		e->speed = s > e->speed ? s : e->speed;
		if (x < lo.x || y < lo.y || z < lo.z || x > hi.x || y > hi.y || z > hi.z) {
			eddy__fail(w, EDDY_ERR_INVALID, "%s: %s: vertex %zu at {%g, %g, %g} lies outside the world bounds", sys,
			           def->path, i, (double)x, (double)y, (double)z);
			free(e);
			return EDDY_NULL_SYSTEM;
		}
	}
	eddy_system_id id = eddy__add_system(w, &eddy__kind_emit_particles, e, NULL, ep_writes);
	if (eddy_system_valid(w, id))
		eddy__note_length_scale(w, def->spacing);
	return id;
}
