/* SPDX-License-Identifier: MIT */
/* Checkpoints: the whole state of a world in one file, written atomically and
 * read back only when it is intact and belongs to the same scene.
 *
 * Layout (native byte order; the version changes with the layout):
 *   header   "EDDYCKPT", u32 version, u32 0, u64 fingerprint, u64 payload bytes,
 *            u64 FNV-1a of the payload
 *   payload  clock (time, frame, step, last dt), random state, length scale,
 *            rest density, particle count; every allocated column (name,
 *            domain, type, bytes, data); every system's state block (label,
 *            bytes, data)
 * Derived columns are saved too, although the next step recomputes them:
 * time-step limits read the last step's values (SPH's force limit reads the
 * accelerations), and a resumed run must pick the same steps to be
 * bit-identical.
 * Loading parses and checks everything before it changes the world, so a bad
 * file leaves the world as it was. */
#define _POSIX_C_SOURCE 200809L
#include "core.h"

#include <errno.h>
#include <math.h>
#include <fcntl.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#define CKPT_MAGIC "EDDYCKPT"
#define CKPT_VERSION 3u
#define HEADER_BYTES 40

/* The pipeline's own fingerprint: what must match for a state to make sense.
 * Thread count is left out: a run may resume on another machine. */
static uint64_t pipeline_fingerprint(const eddy_world *w, uint64_t host)
{
	const eddy_world_def *d = &w->def;
	uint64_t h = eddy__fnv1a(EDDY__FNV_BASIS, &host, sizeof host);
	h = eddy__fnv1a(h, &d->bounds_min, sizeof d->bounds_min);
	h = eddy__fnv1a(h, &d->bounds_max, sizeof d->bounds_max);
	h = eddy__fnv1a(h, &d->gravity, sizeof d->gravity);
	h = eddy__fnv1a(h, &d->fps, sizeof d->fps);
	h = eddy__fnv1a(h, &d->cfl, sizeof d->cfl);
	h = eddy__fnv1a(h, &d->dt_max, sizeof d->dt_max);
	h = eddy__fnv1a(h, &d->cell_size, sizeof d->cell_size);
	h = eddy__fnv1a(h, &d->seed, sizeof d->seed);
	for (int k = 0; k < w->order_count; ++k) {
		const eddy_system *s = &w->slots[w->order[k]];
		h = eddy__fnv1a(h, s->label, strlen(s->label) + 1);
	}
	for (int c = 0; c < w->column_count; ++c)
		if (w->columns[c].data)
			h = eddy__fnv1a(h, w->columns[c].name, strlen(w->columns[c].name) + 1);
	return h;
}

typedef struct buf {
	unsigned char *p;
	size_t len, cap;
	bool failed;
} buf;

static void put(buf *b, const void *data, size_t n)
{
	if (b->failed)
		return;
	if (b->len + n > b->cap) {
		size_t cap = b->cap ? b->cap : 4096;
		while (cap < b->len + n)
			cap *= 2;
		unsigned char *p = realloc(b->p, cap);
		if (!p) {
			b->failed = true;
			return;
		}
		b->p = p;
		b->cap = cap;
	}
	memcpy(b->p + b->len, data, n);
	b->len += n;
}

#define PUT(b, v) put((b), &(v), sizeof(v))

static void put_name(buf *b, const char *name)
{
	char field[EDDY_NAME_MAX + 8] = {0};
	snprintf(field, sizeof field, "%s", name);
	put(b, field, sizeof field);
}

static eddy_status write_all(eddy_world *w, int fd, const void *data, size_t n, const char *path)
{
	const unsigned char *p = data;
	while (n > 0) {
		ssize_t k = write(fd, p, n);
		if (k < 0 && errno == EINTR)
			continue;
		if (k <= 0)
			return eddy__fail(w, EDDY_ERR_IO, "checkpoint: cannot write '%s': %s", path, strerror(errno));
		p += k;
		n -= (size_t)k;
	}
	return EDDY_OK;
}

eddy_status eddy_world_save(eddy_world *w, const char *path, uint64_t fingerprint)
{
	if (!w || !path)
		return eddy__fail(w, EDDY_ERR_INVALID, "checkpoint: world or path is NULL");
	/* the frames before this one are on disk before the state that follows them */
	eddy_status synced = eddy_world_sync(w);
	if (synced != EDDY_OK)
		return synced;
	buf b = {0};
	PUT(&b, w->time);
	PUT(&b, w->frame);
	PUT(&b, w->step);
	PUT(&b, w->last_dt);
	PUT(&b, w->rng);
	PUT(&b, w->length_scale);
	PUT(&b, w->rest_density);
	uint64_t n = w->n;
	PUT(&b, n);
	uint32_t ncols = 0;
	for (int c = 0; c < w->column_count; ++c)
		ncols += w->columns[c].data != NULL;
	PUT(&b, ncols);
	for (int c = 0; c < w->column_count; ++c) {
		const eddy_column *col = &w->columns[c];
		if (!col->data)
			continue;
		put_name(&b, col->name);
		uint8_t dom = (uint8_t)col->domain, type = (uint8_t)col->type;
		PUT(&b, dom);
		PUT(&b, type);
		uint64_t bytes = eddy__column_bytes(w, col);
		PUT(&b, bytes);
		put(&b, col->data, bytes);
	}
	uint32_t nsys = (uint32_t)w->order_count;
	PUT(&b, nsys);
	for (int k = 0; k < w->order_count; ++k) {
		eddy_system *s = &w->slots[w->order[k]];
		size_t size = 0;
		void *st = s->vt->state ? s->vt->state(w, s, &size) : NULL;
		put_name(&b, s->label);
		uint64_t sz = st ? size : 0;
		PUT(&b, sz);
		if (st)
			put(&b, st, size);
	}
	if (b.failed) {
		free(b.p);
		return eddy__fail(w, EDDY_ERR_NOMEM, "checkpoint: out of memory");
	}

	unsigned char header[HEADER_BYTES] = {0};
	const uint32_t version = CKPT_VERSION;
	const uint64_t fp = pipeline_fingerprint(w, fingerprint), size = b.len,
				   sum = eddy__fnv1a(EDDY__FNV_BASIS, b.p, b.len);
	memcpy(header, CKPT_MAGIC, 8);
	memcpy(header + 8, &version, 4);
	memcpy(header + 16, &fp, 8);
	memcpy(header + 24, &size, 8);
	memcpy(header + 32, &sum, 8);

	/* temp file beside the target, fsync, rename: a crash leaves either the
	 * old file or the new one, never half of one */
	char tmp[4096];
	if (snprintf(tmp, sizeof tmp, "%s.tmp", path) >= (int)sizeof tmp) {
		free(b.p);
		return eddy__fail(w, EDDY_ERR_INVALID, "checkpoint: path too long");
	}
	int fd = open(tmp, O_WRONLY | O_CREAT | O_TRUNC, 0644);
	if (fd < 0) {
		free(b.p);
		return eddy__fail(w, EDDY_ERR_IO, "checkpoint: cannot create '%s': %s", tmp, strerror(errno));
	}
	eddy_status st = write_all(w, fd, header, sizeof header, tmp);
	if (st == EDDY_OK)
		st = write_all(w, fd, b.p, b.len, tmp);
	free(b.p);
	if (st == EDDY_OK && fsync(fd) != 0)
		st = eddy__fail(w, EDDY_ERR_IO, "checkpoint: cannot sync '%s': %s", tmp, strerror(errno));
	if (close(fd) != 0 && st == EDDY_OK)
		st = eddy__fail(w, EDDY_ERR_IO, "checkpoint: cannot close '%s': %s", tmp, strerror(errno));
	if (st == EDDY_OK && rename(tmp, path) != 0)
		st = eddy__fail(w, EDDY_ERR_IO, "checkpoint: cannot rename '%s' to '%s': %s", tmp, path, strerror(errno));
	if (st != EDDY_OK) {
		unlink(tmp);
		return st;
	}
	/* the rename itself is durable once the directory is synced */
	char dir[4096];
	snprintf(dir, sizeof dir, "%s", path);
	char *slash = strrchr(dir, '/');
	if (slash)
		*slash = '\0';
	int dfd = open(slash ? dir : ".", O_RDONLY);
	if (dfd >= 0) {
		fsync(dfd);
		close(dfd);
	}
	return EDDY_OK;
}

typedef struct reader {
	const unsigned char *p, *end;
	bool short_read;
} reader;

static void get(reader *r, void *out, size_t n)
{
	if ((size_t)(r->end - r->p) < n) {
		r->short_read = true;
		memset(out, 0, n);
		return;
	}
	memcpy(out, r->p, n);
	r->p += n;
}

#define GET(r, v) get((r), &(v), sizeof(v))

static const unsigned char *skip(reader *r, size_t n)
{
	if ((size_t)(r->end - r->p) < n) {
		r->short_read = true;
		return NULL;
	}
	const unsigned char *p = r->p;
	r->p += n;
	return p;
}

/* The clock and counts of a checkpoint, checked against what a run of this
 * world can reach: a file whose checksum holds may still have been crafted,
 * and a negative frame or a NaN time would run on and fail far from the cause. */
static eddy_status check_clock(eddy_world *w, const char *path, double time, int frame, int64_t step, double last_dt,
                               float length_scale, float rest_density, uint64_t n, uint32_t ncols)
{
	const double fps = w->def.fps;
	const char *bad = NULL;
	char why[160];
	if (!(isfinite(time) && time >= 0)) {
		bad = "time";
		snprintf(why, sizeof why, "%g s, must be finite and >= 0", time);
	} else if (frame < 0 || frame >= INT32_MAX - 1) {
		bad = "frame";
		snprintf(why, sizeof why, "%d, must be in [0, %d)", frame, INT32_MAX - 1);
	} else if (!(time * fps >= frame - 1e-6 * (frame + 1.0) && time * fps <= frame + 1 + 1e-6 * (frame + 1.0))) {
		/* frame k ends at k / fps and the clock lands on it exactly; between
		 * frames the time lies in [frame / fps, (frame + 1) / fps] */
		bad = "frame";
		snprintf(why, sizeof why, "%d, inconsistent with time %.9g s at %g fps (frame %.0f expected)", frame, time, fps,
		         floor(time * fps + 1e-6));
	} else if (step < frame) {
		bad = "step";
		snprintf(why, sizeof why, "%lld, fewer than the %d frames (every frame takes a step)", (long long)step, frame);
	} else if (!(isfinite(last_dt) && last_dt >= 0 && last_dt <= w->def.dt_max * (1 + 1e-9))) {
		bad = "last_dt";
		snprintf(why, sizeof why, "%g s, must be in [0, dt_max = %g s]", last_dt, w->def.dt_max);
	} else if (step > 0 && !(last_dt > 0)) {
		bad = "last_dt";
		snprintf(why, sizeof why, "%g s after %lld steps, must be > 0", last_dt, (long long)step);
	} else if (!(isfinite(length_scale) && length_scale >= 0)) {
		bad = "length_scale";
		snprintf(why, sizeof why, "%g m, must be finite and >= 0", (double)length_scale);
	} else if (!(isfinite(rest_density) && rest_density >= 0)) {
		bad = "rest_density";
		snprintf(why, sizeof why, "%g kg/m^3, must be finite and >= 0", (double)rest_density);
	} else if (n > ((uint64_t)1 << 40)) {
		bad = "particles";
		snprintf(why, sizeof why, "%llu, more than 2^40", (unsigned long long)n);
	} else {
		uint32_t have = 0;
		for (int c = 0; c < w->column_count; ++c)
			have += w->columns[c].data != NULL;
		if (ncols != have) {
			bad = "columns";
			snprintf(why, sizeof why, "%u, the world has %u allocated", ncols, have);
		}
	}
	if (!bad)
		return EDDY_OK;
	return eddy__fail(w, EDDY_ERR_IO, "checkpoint '%s': field '%s' is %s (crafted or corrupted)", path, bad, why);
}

eddy_status eddy_world_load(eddy_world *w, const char *path, uint64_t fingerprint)
{
	if (!w || !path)
		return eddy__fail(w, EDDY_ERR_INVALID, "checkpoint: world or path is NULL");
	if (eddy__refuse_busy(w, "eddy_world_load"))
		return EDDY_ERR_INVALID;
	/* frames of the timeline being left are written before it is replaced */
	eddy_status synced = eddy_world_sync(w);
	if (synced != EDDY_OK)
		return synced;
	FILE *f = fopen(path, "rb");
	if (!f)
		return eddy__fail(w, EDDY_ERR_IO, "checkpoint '%s': cannot open: %s", path, strerror(errno));
	unsigned char header[HEADER_BYTES];
	if (fread(header, 1, sizeof header, f) != sizeof header || memcmp(header, CKPT_MAGIC, 8) != 0) {
		fclose(f);
		return eddy__fail(w, EDDY_ERR_IO, "checkpoint '%s': not an eddy checkpoint (or truncated header)", path);
	}
	uint32_t version;
	uint64_t fp, size, sum;
	memcpy(&version, header + 8, 4);
	memcpy(&fp, header + 16, 8);
	memcpy(&size, header + 24, 8);
	memcpy(&sum, header + 32, 8);
	if (version != CKPT_VERSION) {
		fclose(f);
		return eddy__fail(w, EDDY_ERR_IO, "checkpoint '%s': version %u, this eddy reads version %u", path, version,
		                  CKPT_VERSION);
	}
	if (fp != pipeline_fingerprint(w, fingerprint)) {
		fclose(f);
		return eddy__fail(w, EDDY_ERR_IO,
		                  "checkpoint '%s': written by another scene or other parameters (fingerprint differs)", path);
	}
	unsigned char *payload = size < ((uint64_t)1 << 40) ? malloc(size ? size : 1) : NULL;
	if (!payload) {
		fclose(f);
		return eddy__fail(w, EDDY_ERR_IO, "checkpoint '%s': implausible size %llu", path, (unsigned long long)size);
	}
	size_t got = fread(payload, 1, size, f);
	int extra = fgetc(f);
	fclose(f);
	if (got != size || extra != EOF) {
		free(payload);
		return eddy__fail(w, EDDY_ERR_IO, "checkpoint '%s': truncated (%zu of %llu payload bytes)%s", path, got,
		                  (unsigned long long)size, extra != EOF ? " or followed by garbage" : "");
	}
	if (eddy__fnv1a(EDDY__FNV_BASIS, payload, size) != sum) {
		free(payload);
		return eddy__fail(w, EDDY_ERR_IO, "checkpoint '%s': checksum mismatch (corrupted)", path);
	}

	/* parse and check everything first */
	reader r = {payload, payload + size, false};
	double time, last_dt;
	int frame;
	int64_t step;
	uint64_t rng, n;
	float length_scale, rest_density;
	GET(&r, time);
	GET(&r, frame);
	GET(&r, step);
	GET(&r, last_dt);
	GET(&r, rng);
	GET(&r, length_scale);
	GET(&r, rest_density);
	GET(&r, n);
	uint32_t ncols;
	GET(&r, ncols);
	eddy_status st = r.short_read
	                     ? eddy__fail(w, EDDY_ERR_IO, "checkpoint '%s': malformed payload", path)
	                     : check_clock(w, path, time, frame, step, last_dt, length_scale, rest_density, n, ncols);
	struct {
		int id;
		const unsigned char *data;
		uint64_t bytes;
	} cols[EDDY_MAX_COLUMNS];
	bool seen[EDDY_MAX_COLUMNS] = {false};
	for (uint32_t i = 0; st == EDDY_OK && i < ncols; ++i) {
		char name[EDDY_NAME_MAX + 8];
		uint8_t dom, type;
		uint64_t bytes;
		get(&r, name, sizeof name);
		name[sizeof name - 1] = '\0';
		GET(&r, dom);
		GET(&r, type);
		GET(&r, bytes);
		const unsigned char *data = skip(&r, bytes);
		int id = eddy_world_find_column(w, name);
		if (r.short_read)
			break;
		const eddy_column *c = id >= 0 ? &w->columns[id] : NULL;
		size_t es = type == EDDY_U8 ? 1 : 4;
		uint64_t expect = c && c->domain == EDDY_DOMAIN_PARTICLE ? n * es : c ? eddy__column_bytes(w, c) : 0;
		if (!c || !c->data || c->domain != dom || c->type != type || bytes != expect || seen[id])
			st = eddy__fail(w, EDDY_ERR_IO, "checkpoint '%s': column '%s' does not fit this world", path, name);
		else
			seen[id] = true;
		cols[i].id = id;
		cols[i].data = data;
		cols[i].bytes = bytes;
	}
	uint32_t nsys = 0;
	GET(&r, nsys);
	if (st == EDDY_OK && !r.short_read && nsys != (uint32_t)w->order_count)
		st = eddy__fail(w, EDDY_ERR_IO, "checkpoint '%s': %u systems, the scene has %d", path, nsys, w->order_count);
	const unsigned char *sys_data[EDDY_MAX_SYSTEMS];
	for (uint32_t k = 0; st == EDDY_OK && !r.short_read && k < nsys; ++k) {
		char label[EDDY_NAME_MAX + 8];
		uint64_t sz;
		get(&r, label, sizeof label);
		label[sizeof label - 1] = '\0';
		GET(&r, sz);
		sys_data[k] = skip(&r, sz);
		eddy_system *s = &w->slots[w->order[k]];
		size_t have = 0;
		if (s->vt->state)
			s->vt->state(w, s, &have);
		if (!r.short_read && strcmp(label, s->label) != 0)
			st = eddy__fail(w, EDDY_ERR_IO, "checkpoint '%s': system %u is %s, the scene has %s", path, k + 1, label,
			                s->label);
		else if (!r.short_read && sz != have)
			st = eddy__fail(w, EDDY_ERR_IO,
			                "checkpoint '%s': system %u (%s) holds %llu bytes of state, this build's %zu: written by "
			                "another version of eddy",
			                path, k + 1, label, (unsigned long long)sz, have);
	}
	if (st == EDDY_OK && (r.short_read || r.p != r.end))
		st = eddy__fail(w, EDDY_ERR_IO, "checkpoint '%s': malformed payload", path);
	if (st == EDDY_OK)
		st = eddy__reserve_particles(w, (size_t)n);
	if (st != EDDY_OK) {
		free(payload);
		return st;
	}

	/* apply */
	w->time = time;
	w->frame = frame;
	w->step = step;
	w->last_dt = last_dt;
	w->rng = rng;
	w->length_scale = length_scale;
	w->rest_density = rest_density;
	w->n = (size_t)n;
	for (uint32_t i = 0; i < ncols; ++i)
		memcpy(w->columns[cols[i].id].data, cols[i].data, cols[i].bytes);
	for (uint32_t k = 0; k < nsys; ++k) {
		eddy_system *s = &w->slots[w->order[k]];
		size_t have = 0;
		void *dst = s->vt->state ? s->vt->state(w, s, &have) : NULL;
		if (dst && have)
			memcpy(dst, sys_data[k], have);
	}
	eddy__frame_reset(w);
	free(payload);
	return EDDY_OK;
}
