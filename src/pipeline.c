/* SPDX-License-Identifier: MIT */
/* The pipeline: systems in the order the scene added them, each with the
 * columns it reads and writes.
 *
 * Validation rule: a derived column (cleared every step) may be read only after
 * an earlier system in the same step wrote it; otherwise the reader would see
 * zeros. The error names the systems that could fix it. State columns carry
 * over between steps, so any order is valid for them. Adding a system acquires
 * its columns; removing it releases them; nothing else allocates columns. */
#include "core.h"
#include "systems.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* Every built-in kind, for the "add X before it" hint. */
static const eddy_system_vtable *const kinds[] = {
#define EDDY_KIND_PTR(ident) &eddy__kind_##ident,
	EDDY_BUILTIN_SYSTEMS(EDDY_KIND_PTR)
#undef EDDY_KIND_PTR
};

const eddy_system *eddy__system_peek(const eddy_world *w, eddy_system_id id)
{
	if (!w || id.index >= w->slot_count)
		return NULL;
	const eddy_system *s = &w->slots[id.index];
	if (!s->live || s->generation != id.generation)
		return NULL;
	return s;
}

eddy_system *eddy__system_get(eddy_world *w, eddy_system_id id)
{
	return eddy__system_peek(w, id) ? &w->slots[id.index] : NULL;
}

bool eddy_system_valid(const eddy_world *w, eddy_system_id id) { return eddy__system_peek(w, id) != NULL; }

void eddy__system_free(eddy_world *w, eddy_system *s)
{
	(void)w;
	if (s->vt && s->vt->destroy)
		s->vt->destroy(s);
	free(s->data);
	s->data = NULL;
	s->live = false;
}

/* Names of the built-in kinds that write column col, as "a, b or c". */
static void writers_hint(const eddy_world *w, int col, char *buf, size_t cap)
{
	const char *names[16];
	int n = 0;
	for (size_t k = 0; k < sizeof kinds / sizeof kinds[0] && n < 16; ++k)
		for (int j = 0; kinds[k]->default_writes && kinds[k]->default_writes[j] >= 0; ++j)
			if (kinds[k]->default_writes[j] == col) {
				names[n++] = kinds[k]->name;
				break;
			}
	if (n == 0) {
		snprintf(buf, cap, "add a system that writes '%s' before it", w->columns[col].name);
		return;
	}
	size_t len = (size_t)snprintf(buf, cap, "add %s", names[0]);
	for (int i = 1; i < n && len < cap; ++i)
		len += (size_t)snprintf(buf + len, cap - len, "%s%s", i == n - 1 ? " or " : ", ", names[i]);
	if (len < cap)
		snprintf(buf + len, cap - len, " before it");
}

/* What each capability is, for the errors (in bit order). */
static const char *const capability_names[] = {
	"SPH neighbour lists",      "the SPH equation-of-state force", "SPH wall particles",    "a collider",
	"the MAC grid velocities",  "the grid's solid faces",          "the FLIP free surface", "gravity",
	"the grid fluid's density",
};

/* The built-in kinds that provide cap, as "a, b or c". */
static void providers_hint(uint32_t cap, char *buf, size_t cap_len)
{
	size_t len = 0;
	int n = 0, total = 0;
	for (size_t k = 0; k < sizeof kinds / sizeof kinds[0]; ++k)
		total += (kinds[k]->provides & cap) != 0;
	for (size_t k = 0; k < sizeof kinds / sizeof kinds[0] && len < cap_len; ++k)
		if (kinds[k]->provides & cap) {
			const char *sep = n == 0 ? "" : n == total - 1 ? " or " : ", ";
			len += (size_t)snprintf(buf + len, cap_len - len, "%s%s", sep, kinds[k]->name);
			n++;
		}
	if (n == 0)
		snprintf(buf, cap_len, "a system that provides it");
}

static const char *capability_name(uint32_t bit)
{
	int i = 0;
	while (i < 31 && !(bit & (1u << i)))
		++i;
	return i < (int)(sizeof capability_names / sizeof capability_names[0]) ? capability_names[i] : "a capability";
}

/* The couplings of the system at position pos: every capability it requires
 * provided before it, and no capability it excludes provided anywhere else
 * in the pipeline (or the other way round). */
static eddy_status check_couplings(eddy_world *w, int pos)
{
	const eddy_system *s = &w->slots[w->order[pos]];
	for (uint32_t bit = 1; bit && bit <= s->vt->requires; bit <<= 1) {
		if (!(s->vt->requires & bit))
			continue;
		bool found = false;
		for (int k = 0; k < pos && !found; ++k)
			found = (w->slots[w->order[k]].vt->provides & bit) != 0;
		if (!found) {
			char hint[160];
			providers_hint(bit, hint, sizeof hint);
			return eddy__fail(w, EDDY_ERR_ORDER, "%s needs %s from an earlier system: add %s before it", s->label,
			                  capability_name(bit), hint);
		}
	}
	for (int k = 0; k < w->order_count + (pos == w->order_count); ++k) {
		const eddy_system *o = &w->slots[w->order[k]];
		if (k == pos)
			continue;
		const eddy_system *excluder = (s->vt->excludes & o->vt->provides) ? s : o, *other = excluder == s ? o : s;
		const uint32_t clash = excluder->vt->excludes & other->vt->provides;
		if (clash)
			return eddy__fail(w, EDDY_ERR_ORDER,
			                  "%s and %s cannot share a pipeline (%s excludes %s); remove one of them from the scene",
			                  excluder->label, other->label, excluder->label, capability_name(clash & (0u - clash)));
	}
	return EDDY_OK;
}

/* Checks the system at pipeline position pos against the systems before it. */
static eddy_status validate_at(eddy_world *w, int pos)
{
	const eddy_system *s = &w->slots[w->order[pos]];
	for (int r = 0; r < s->read_count; ++r) {
		int col = s->reads[r];
		if (w->columns[col].lifetime != EDDY_DERIVED)
			continue;
		bool written = false;
		for (int k = 0; k < pos && !written; ++k) {
			const eddy_system *e = &w->slots[w->order[k]];
			for (int j = 0; j < e->write_count && !written; ++j)
				written = e->writes[j] == col;
		}
		if (!written) {
			char hint[256];
			writers_hint(w, col, hint, sizeof hint);
			return eddy__fail(w, EDDY_ERR_ORDER, "%s reads '%s' but no earlier system writes it: %s", s->label,
			                  w->columns[col].name, hint);
		}
	}
	return check_couplings(w, pos);
}

eddy_system_iter eddy__systems(const eddy_world *w, uint32_t caps) { return (eddy_system_iter){w, 0, caps}; }

const eddy_system *eddy__systems_next(eddy_system_iter *it)
{
	while (it->pos < it->w->order_count) {
		const eddy_system *s = &it->w->slots[it->w->order[it->pos++]];
		if (!it->caps || (s->vt->provides & it->caps))
			return s;
	}
	return NULL;
}

const eddy_system *eddy__provider(const eddy_world *w, const eddy_system *s, uint32_t cap)
{
	const eddy_system *found = NULL, *o;
	for (eddy_system_iter it = eddy__systems(w, cap); (o = eddy__systems_next(&it)) && o != s;)
		found = o;
	return found;
}

void *eddy__provided(const eddy_world *w, const eddy_system *s, uint32_t cap)
{
	const eddy_system *p = eddy__provider(w, s, cap);
	return p && p->vt->shared ? p->vt->shared(p, cap) : NULL;
}

/* A list's length up to its -1; past EDDY_MAX_IO it stops looking (the add
 * then fails with the limit), so a list missing its -1 is caught, not read
 * without end. */
static int column_list_length(const int *cols)
{
	int n = 0;
	while (cols && n <= EDDY_MAX_IO && cols[n] >= 0)
		++n;
	return n;
}

static void make_label(eddy_world *w, eddy_system *s)
{
	int same = 0;
	for (int k = 0; k < w->order_count; ++k)
		same += strcmp(w->slots[w->order[k]].name, s->name) == 0;
	char name[EDDY_NAME_MAX];
	memcpy(name, s->name, sizeof name);
	if (same == 0)
		snprintf(s->label, sizeof s->label, "%s", name);
	else
		snprintf(s->label, sizeof s->label, "%s#%d", name, same + 1);
}

/* Settings derived from the pipeline (vtable rederive) follow it until the
 * world has stepped, and then stay as they were; a system added later
 * derives its own once, from the pipeline it joins (added, non-NULL). */
static void rederive(eddy_world *w, eddy_system *added)
{
	if (w->step != 0) {
		if (added && added->vt->rederive)
			added->vt->rederive(w, added);
		return;
	}
	for (int k = 0; k < w->order_count; ++k) {
		eddy_system *s = &w->slots[w->order[k]];
		if (s->vt->rederive)
			s->vt->rederive(w, s);
	}
}

/* A collider added where the water already is (between steps, by a host or
 * a scene that advanced its world): nothing can move the particles inside
 * its solid out but its push, all of it in its first step, which SPH
 * answers with a burst (a 3 cm sphere added in a DFSPH pool: 19 m/s and 17x
 * the pool's energy in the next frame; FLIP's volume correction absorbs it).
 * Emitters fill around a solid that is there first, so the warning says
 * to add it before the water, or to move it in. */
static void warn_particles_inside(eddy_world *w, const eddy_system *s)
{
	const float *x = eddy__col(w, COL_X_), *y = eddy__col(w, COL_Y_), *z = eddy__col(w, COL_Z_);
	if (!x || !y || !z)
		return;
	size_t inside = 0, first = 0;
	for (size_t i = 0; i < w->n; ++i)
		if (s->vt->distance(s, (eddy_vec3){x[i], y[i], z[i]}) < 0 && inside++ == 0)
			first = i;
	if (inside == 0)
		return;
	char key[sizeof s->label + 16];
	snprintf(key, sizeof key, "added-inside:%s", s->label);
	eddy__warn(w, key,
	           "%s: added at step %lld (t = %.6g s) with %zu particles inside its solid (particle %zu at (%g, %g, %g)): "
	           "its first step pushes them all out, which SPH answers with a burst; add it before the water (emitters "
	           "fill around a solid that is there) or move it in from outside",
	           s->label, (long long)w->step, w->time, inside, first, (double)x[first], (double)y[first],
	           (double)z[first]);
}

static eddy_system_id add_system_named(eddy_world *w, const eddy_system_vtable *vt, const char *name, void *data,
                                       const int *reads, int read_count, const int *writes, int write_count)
{
	if (eddy__refuse_busy(w, "adding a system")) {
		free(data);
		return EDDY_NULL_SYSTEM;
	}
	int slot = -1;
	for (int i = 0; i < w->slot_count; ++i)
		if (!w->slots[i].live) {
			slot = i;
			break;
		}
	if (slot < 0) {
		if (w->slot_count == EDDY_MAX_SYSTEMS) {
			free(data);
			eddy__fail(w, EDDY_ERR_INVALID, "%s: the pipeline is full (%d systems)", name, EDDY_MAX_SYSTEMS);
			return EDDY_NULL_SYSTEM;
		}
		slot = w->slot_count++;
	}
	if (read_count > EDDY_MAX_IO || write_count > EDDY_MAX_IO) {
		free(data);
		eddy__fail(w, EDDY_ERR_INVALID, "%s: a system may read and write at most %d columns each", name, EDDY_MAX_IO);
		return EDDY_NULL_SYSTEM;
	}
	eddy_system *s = &w->slots[slot];
	uint16_t gen = (uint16_t)(s->generation + 1);
	if (gen == 0)
		gen = 1; /* generation 0 is reserved for EDDY_NULL_SYSTEM */
	memset(s, 0, sizeof *s);
	s->generation = gen;
	s->vt = vt;
	s->data = data;
	snprintf(s->name, sizeof s->name, "%s", name);
	make_label(w, s);
	s->read_count = read_count;
	s->write_count = write_count;
	for (int i = 0; i < read_count; ++i) {
		s->reads[i] = reads[i];
		s->read_names[i] = w->columns[reads[i]].name;
	}
	for (int i = 0; i < write_count; ++i) {
		s->writes[i] = writes[i];
		s->write_names[i] = w->columns[writes[i]].name;
	}

	w->order[w->order_count] = slot;
	eddy_status st = validate_at(w, w->order_count);
	int acquired_r = 0, acquired_w = 0;
	for (; st == EDDY_OK && acquired_r < read_count; ++acquired_r)
		st = eddy__column_acquire(w, reads[acquired_r]);
	if (st != EDDY_OK && acquired_r > 0)
		acquired_r--; /* the failed acquire undid itself */
	for (; st == EDDY_OK && acquired_w < write_count; ++acquired_w)
		st = eddy__column_acquire(w, writes[acquired_w]);
	if (st != EDDY_OK && acquired_w > 0)
		acquired_w--;
	if (st != EDDY_OK) {
		for (int i = 0; i < acquired_r; ++i)
			eddy__column_release(w, reads[i]);
		for (int i = 0; i < acquired_w; ++i)
			eddy__column_release(w, writes[i]);
		s->vt = NULL; /* destroy is for systems that ran their create */
		eddy__system_free(w, s);
		return EDDY_NULL_SYSTEM;
	}
	s->live = true;
	w->order_count++;
	rederive(w, s);
	if (vt->distance && w->n > 0)
		warn_particles_inside(w, s);
	return (eddy_system_id){(uint16_t)slot, gen};
}

eddy_system_id eddy__add_system(eddy_world *w, const eddy_system_vtable *vt, void *data, const int *reads,
                                const int *writes)
{
	const int read_count = column_list_length(reads), write_count = column_list_length(writes);
	if (!w) {
		free(data);
		return EDDY_NULL_SYSTEM;
	}
	if (!data) {
		eddy__fail(w, EDDY_ERR_NOMEM, "%s: out of memory", vt->name);
		return EDDY_NULL_SYSTEM;
	}
	return add_system_named(w, vt, vt->name, data, reads, read_count, writes, write_count);
}

eddy_status eddy_world_remove_system(eddy_world *w, eddy_system_id id)
{
	if (!w)
		return EDDY_ERR_INVALID;
	if (eddy__refuse_busy(w, "eddy_world_remove_system"))
		return EDDY_ERR_INVALID;
	eddy_system *s = eddy__system_get(w, id);
	if (!s)
		return eddy__fail(w, EDDY_ERR_STALE, "remove_system: stale or invalid system handle");
	int pos = 0;
	while (w->order[pos] != id.index)
		++pos;
	/* Refuse if a later system depends on what this one writes. */
	memmove(&w->order[pos], &w->order[pos + 1], (size_t)(w->order_count - pos - 1) * sizeof w->order[0]);
	w->order_count--;
	for (int k = pos; k < w->order_count; ++k) {
		if (validate_at(w, k) != EDDY_OK) {
			char msg[EDDY_ERROR_MAX];
			snprintf(msg, sizeof msg, "%s", w->error);
			memmove(&w->order[pos + 1], &w->order[pos], (size_t)(w->order_count - pos) * sizeof w->order[0]);
			w->order[pos] = id.index;
			w->order_count++;
			return eddy__fail(w, EDDY_ERR_ORDER, "cannot remove %s: %s", s->label, msg);
		}
	}
	for (int i = 0; i < s->read_count; ++i)
		eddy__column_release(w, s->reads[i]);
	for (int i = 0; i < s->write_count; ++i)
		eddy__column_release(w, s->writes[i]);
	eddy__system_free(w, s);
	rederive(w, NULL);
	return EDDY_OK;
}

int eddy_world_system_count(const eddy_world *w) { return w ? w->order_count : 0; }

eddy_system_id eddy_world_system_at(const eddy_world *w, int i)
{
	if (!w || i < 0 || i >= w->order_count)
		return EDDY_NULL_SYSTEM;
	int slot = w->order[i];
	return (eddy_system_id){(uint16_t)slot, w->slots[slot].generation};
}

eddy_status eddy_system_set_group(eddy_world *w, eddy_system_id id, const char *group)
{
	if (!w)
		return EDDY_ERR_INVALID;
	eddy_system *s = eddy__system_get(w, id);
	if (!s)
		return eddy__fail(w, EDDY_ERR_STALE, "eddy_system_set_group: no such system");
	group = group ? group : "";
	const size_t n = strlen(group);
	if (n >= sizeof s->group)
		return eddy__fail(w, EDDY_ERR_INVALID, "%s: a group's text must be under %zu bytes (got %zu)", s->label,
		                  sizeof s->group, n);
	/* plans print it as text and inside Graphviz's quoted labels */
	for (size_t i = 0; i < n; ++i)
		if ((unsigned char)group[i] < 0x20 || group[i] == '"' || group[i] == '\\')
			return eddy__fail(w, EDDY_ERR_INVALID, "%s: a group's text may not hold control characters, '\"' or '\\'",
			                  s->label);
	memcpy(s->group, group, n + 1);
	return EDDY_OK;
}

eddy_status eddy_world_system_info(const eddy_world *w, eddy_system_id id, eddy_system_info *out)
{
	if (!w || !out)
		return EDDY_ERR_INVALID;
	const eddy_system *s = eddy__system_peek(w, id);
	if (!s)
		return EDDY_ERR_STALE;
	out->name = s->name;
	out->label = s->label;
	out->group = s->group;
	out->reads = s->read_names;
	out->read_count = s->read_count;
	out->writes = s->write_names;
	out->write_count = s->write_count;
	out->profile_ms = s->ms_total;
	out->calls = s->calls;
	out->expected_particles = s->vt->expected_particles ? s->vt->expected_particles(w, s) : 0;
	return EDDY_OK;
}

/* ---- custom systems ------------------------------------------------------ */

typedef struct custom_data {
	eddy_custom_system_def def;
} custom_data;

static eddy_status custom_step(eddy_world *w, eddy_system *s, const eddy_step_context *ctx)
{
	custom_data *d = s->data;
	return d->def.step(w, ctx, d->def.user);
}

static eddy_status custom_frame(eddy_world *w, eddy_system *s, int frame)
{
	custom_data *d = s->data;
	return d->def.frame(w, frame, d->def.user);
}

static double custom_limit(eddy_world *w, eddy_system *s, const char **reason)
{
	custom_data *d = s->data;
	return d->def.limit(w, d->def.user, reason);
}

static eddy_status custom_sync(eddy_world *w, eddy_system *s)
{
	custom_data *d = s->data;
	return d->def.sync ? d->def.sync(w, d->def.user) : EDDY_OK;
}

static void custom_destroy(eddy_system *s)
{
	custom_data *d = s->data;
	if (d->def.destroy)
		d->def.destroy(d->def.user);
}

/* One vtable per feature set, so the world skips the hooks a custom system lacks
 * (a frame-only system is not timed as a step). Index: step + 2*frame + 4*limit. */
#define CUSTOM_KIND(st, f, l)                                                                                      \
	{                                                                                                              \
		.name = "custom", .step = (st), .frame = (f), .limit = (l), .destroy = custom_destroy, .sync = custom_sync \
	}
static const eddy_system_vtable custom_kinds[8] = {
	CUSTOM_KIND(NULL, NULL, NULL),
	CUSTOM_KIND(custom_step, NULL, NULL),
	CUSTOM_KIND(NULL, custom_frame, NULL),
	CUSTOM_KIND(custom_step, custom_frame, NULL),
	CUSTOM_KIND(NULL, NULL, custom_limit),
	CUSTOM_KIND(custom_step, NULL, custom_limit),
	CUSTOM_KIND(NULL, custom_frame, custom_limit),
	CUSTOM_KIND(custom_step, custom_frame, custom_limit),
};
#undef CUSTOM_KIND

void *eddy_world_custom_user(const eddy_world *w, eddy_system_id id, eddy_frame_fn frame)
{
	const eddy_system *s = w ? eddy__system_peek(w, id) : NULL;
	if (!s || !frame || s->vt->frame != custom_frame)
		return NULL;
	const custom_data *d = s->data;
	return d->def.frame == frame ? d->def.user : NULL;
}

eddy_custom_system_def eddy_default_custom_system_def(void)
{
	eddy_custom_system_def d;
	memset(&d, 0, sizeof d);
	d.name = "custom";
	return d;
}

static bool resolve_names(eddy_world *w, const char *sys, const char *const *names, int count, int *ids)
{
	if (count < 0 || count > EDDY_MAX_IO || (count > 0 && !names)) {
		eddy__fail(w, EDDY_ERR_INVALID, "%s: column lists must hold 0 to %d names", sys, EDDY_MAX_IO);
		return false;
	}
	for (int i = 0; i < count; ++i) {
		ids[i] = eddy_world_find_column(w, names[i]);
		if (ids[i] < 0) {
			eddy__fail(w, EDDY_ERR_INVALID, "%s: unknown column '%s' (declare it with eddy_world_declare_column)", sys,
			           names[i] ? names[i] : "(null)");
			return false;
		}
	}
	return true;
}

eddy_system_id eddy_add_custom_system(eddy_world *w, const eddy_custom_system_def *def)
{
	if (!eddy__add_args(w, def, "custom_system"))
		return EDDY_NULL_SYSTEM;
	const char *name = def->name ? def->name : "";
	if (!name[0] || strlen(name) >= EDDY_NAME_MAX) {
		eddy__fail(w, EDDY_ERR_INVALID, "custom system: 'name' must be 1 to %d characters", EDDY_NAME_MAX - 1);
		return EDDY_NULL_SYSTEM;
	}
	if (!def->step && !def->frame) {
		eddy__fail(w, EDDY_ERR_INVALID, "%s: needs a step or a frame callback", name);
		return EDDY_NULL_SYSTEM;
	}
	int reads[EDDY_MAX_IO], writes[EDDY_MAX_IO];
	if (!resolve_names(w, name, def->reads, def->read_count, reads) ||
	    !resolve_names(w, name, def->writes, def->write_count, writes))
		return EDDY_NULL_SYSTEM;
	custom_data *d = calloc(1, sizeof *d);
	if (!d) {
		eddy__fail(w, EDDY_ERR_NOMEM, "%s: out of memory", name);
		return EDDY_NULL_SYSTEM;
	}
	d->def = *def;
	const eddy_system_vtable *vt = &custom_kinds[(def->step ? 1 : 0) + (def->frame ? 2 : 0) + (def->limit ? 4 : 0)];
	return add_system_named(w, vt, name, d, reads, def->read_count, writes, def->write_count);
}

/* ---- plan ---------------------------------------------------------------- */

typedef struct sbuf {
	char *buf;
	size_t cap, len;
} sbuf;

static void sb_printf(sbuf *b, const char *fmt, ...)
#if defined(__GNUC__)
	__attribute__((format(printf, 2, 3)))
#endif
	;
static void sb_printf(sbuf *b, const char *fmt, ...)
{
	va_list ap;
	va_start(ap, fmt);
	char *dst = b->len < b->cap ? b->buf + b->len : NULL;
	size_t room = b->len < b->cap ? b->cap - b->len : 0;
	int n = vsnprintf(dst, room, fmt, ap);
	va_end(ap);
	if (n > 0)
		b->len += (size_t)n;
}

static const char *domain_name(eddy_domain d)
{
	static const char *names[] = {"particle", "cell", "face_x", "face_y", "face_z"};
	return names[d];
}

static void human_bytes(double b, char *out, size_t cap)
{
	if (b < 1024)
		snprintf(out, cap, "%.0f B", b);
	else if (b < 1024 * 1024)
		snprintf(out, cap, "%.1f KiB", b / 1024);
	else if (b < 1024.0 * 1024 * 1024)
		snprintf(out, cap, "%.1f MiB", b / (1024 * 1024));
	else
		snprintf(out, cap, "%.2f GiB", b / (1024.0 * 1024 * 1024));
}

size_t eddy_world_plan(const eddy_world *w, char *buf, size_t cap)
{
	if (!buf)
		cap = 0;
	sbuf b = {buf, cap, 0};
	if (cap)
		buf[0] = '\0';
	if (!w)
		return 0;
	sb_printf(&b, "pipeline: %d system%s, run in this order every step\n", w->order_count,
	          w->order_count == 1 ? "" : "s");
	int64_t expected = 0;
	bool unbounded = false;
	for (int k = 0; k < w->order_count; ++k) {
		const eddy_system *s = &w->slots[w->order[k]];
		const char *prev_group = k ? w->slots[w->order[k - 1]].group : "";
		if (s->group[0] && strcmp(s->group, prev_group) != 0)
			sb_printf(&b, "      group %s:\n", s->group);
		sb_printf(&b, "  %2d  %-20s", k + 1, s->label);
		if (s->read_count) {
			sb_printf(&b, " reads");
			for (int i = 0; i < s->read_count; ++i)
				sb_printf(&b, " %s", s->read_names[i]);
			sb_printf(&b, ";");
		}
		if (s->write_count) {
			sb_printf(&b, " writes");
			for (int i = 0; i < s->write_count; ++i)
				sb_printf(&b, " %s", s->write_names[i]);
		}
		if (!s->read_count && !s->write_count)
			sb_printf(&b, " (no columns)");
		if (!s->vt->step && s->vt->frame)
			sb_printf(&b, " [at frame times]");
		sb_printf(&b, "\n");
		if (s->vt->expected_particles) {
			int64_t e = s->vt->expected_particles(w, s);
			if (e < 0)
				unbounded = true;
			else
				expected += e;
		}
	}
	size_t total = 0, per_particle = 0;
	int allocated = 0;
	for (int c = 0; c < w->column_count; ++c) {
		eddy_column_info info;
		eddy_world_column_info(w, c, &info);
		if (!info.allocated)
			continue;
		allocated++;
		total += info.bytes;
		if (info.domain == EDDY_DOMAIN_PARTICLE)
			per_particle += info.type == EDDY_U8 ? 1 : 4;
	}
	sb_printf(&b, "particles: %zu now", w->n);
	if (unbounded)
		sb_printf(&b, ", emitters without an end (memory grows with the run)");
	else if (expected)
		sb_printf(&b, ", %lld more from emitters", (long long)expected);
	sb_printf(&b, "; %zu bytes per particle\n", per_particle);
	char hb[32], he[32];
	human_bytes((double)total, hb, sizeof hb);
	human_bytes((double)((size_t)expected + w->n) * (double)per_particle, he, sizeof he);
	if (expected && !unbounded)
		sb_printf(&b, "columns: %d allocated, %s now, %s of particle columns once the emitters are done\n", allocated,
		          hb, he);
	else
		sb_printf(&b, "columns: %d allocated, %s now\n", allocated, hb);
	for (int c = 0; c < w->column_count; ++c) {
		eddy_column_info info;
		eddy_world_column_info(w, c, &info);
		if (!info.allocated)
			continue;
		human_bytes((double)info.bytes, hb, sizeof hb);
		sb_printf(&b, "  %-14s %-8s %-3s %-7s %-7s %10s\n", info.name, domain_name(info.domain),
		          info.type == EDDY_U8 ? "u8" : "f32", info.lifetime == EDDY_STATE ? "state" : "derived",
		          info.unit[0] ? info.unit : "1", hb);
	}
	if (w->grid_allocated)
		sb_printf(&b, "grid: %d x %d x %d cells of %g m\n", w->nx, w->ny, w->nz, w->def.cell_size);
	else
		sb_printf(&b, "grid: none (no system uses a grid column)\n");
	sb_printf(&b, "not allocated:");
	int none = 1;
	for (int c = 0; c < w->column_count; ++c)
		if (!w->columns[c].data) {
			sb_printf(&b, " %s", w->columns[c].name);
			none = 0;
		}
	sb_printf(&b, "%s\n", none ? " (nothing)" : "");
	return b.len;
}

/* The system that feeds column col to the reader at position pos: within the
 * step (previous_step false), the nearest earlier writer; across steps (true,
 * state columns only), the last writer at or after the reader, whose values
 * the reader sees in the next step. -1 if there is none. */
static int producer_of(const eddy_world *w, int col, int pos, bool previous_step)
{
	if (previous_step && w->columns[col].lifetime != EDDY_STATE)
		return -1;
	/* across steps, only the first reader is drawn: later ones get the values
	 * through the systems in between */
	for (int k = 0; previous_step && k < pos; ++k) {
		const eddy_system *e = &w->slots[w->order[k]];
		for (int j = 0; j < e->read_count; ++j)
			if (e->reads[j] == col)
				return -1;
	}
	const int from = previous_step ? w->order_count - 1 : pos - 1, to = previous_step ? pos : 0;
	for (int k = from; k >= to; --k) {
		const eddy_system *e = &w->slots[w->order[k]];
		for (int j = 0; j < e->write_count; ++j)
			if (e->writes[j] == col)
				return k;
	}
	return -1;
}

size_t eddy_world_plan_dot(const eddy_world *w, char *buf, size_t cap)
{
	if (!buf)
		cap = 0;
	sbuf b = {buf, cap, 0};
	if (cap)
		buf[0] = '\0';
	if (!w)
		return 0;
	sb_printf(&b, "digraph eddy {\n  rankdir=LR;\n  node [shape=box, style=\"rounded,filled\", fillcolor=\"#eef4fb\", "
	              "fontname=\"Helvetica\"];\n");
	sb_printf(&b, "  edge [fontname=\"Helvetica\", fontsize=10];\n");
	for (int k = 0; k < w->order_count; ++k) {
		const eddy_system *s = &w->slots[w->order[k]];
		if (s->group[0])
			sb_printf(&b, "  s%d [label=\"%d. %s\\n(%s)\"];\n", k, k + 1, s->label, s->group);
		else
			sb_printf(&b, "  s%d [label=\"%d. %s\"];\n", k, k + 1, s->label);
	}
	/* One edge per (producer, reader, same-or-previous step), labelled with columns. */
	for (int r = 0; r < w->order_count; ++r) {
		const eddy_system *s = &w->slots[w->order[r]];
		for (int p = 0; p < w->order_count; ++p) {
			for (int prev = 0; prev < 2; ++prev) {
				char label[256];
				size_t len = 0;
				label[0] = '\0';
				for (int i = 0; i < s->read_count; ++i) {
					if (producer_of(w, s->reads[i], r, prev == 1) == p && len < sizeof label)
						len +=
							(size_t)snprintf(label + len, sizeof label - len, "%s%s", len ? " " : "", s->read_names[i]);
				}
				if (len)
					sb_printf(&b, "  s%d -> s%d [label=\"%s\"%s];\n", p, r, label,
					          prev ? ", style=dashed, color=\"#888888\"" : "");
			}
		}
	}
	sb_printf(&b,
	          "  label=\"eddy pipeline: solid edges carry columns within a step, dashed ones into the next step\";\n");
	sb_printf(&b, "  fontname=\"Helvetica\";\n}\n");
	return b.len;
}

/* ---- def checks ---------------------------------------------------------- */

bool eddy__check_finite(eddy_world *w, const char *sys, const char *field, double v)
{
	if (isfinite(v))
		return true;
	eddy__fail(w, EDDY_ERR_INVALID, "%s: '%s' must be finite (got %g)", sys, field, v);
	return false;
}

bool eddy__check_positive(eddy_world *w, const char *sys, const char *field, double v)
{
	if (v > 0 && isfinite(v))
		return true;
	eddy__fail(w, EDDY_ERR_INVALID, "%s: '%s' must be > 0 (got %g)", sys, field, v);
	return false;
}

bool eddy__check_nonneg(eddy_world *w, const char *sys, const char *field, double v)
{
	if (v >= 0 && isfinite(v))
		return true;
	eddy__fail(w, EDDY_ERR_INVALID, "%s: '%s' must be >= 0 (got %g)", sys, field, v);
	return false;
}

bool eddy__check_range(eddy_world *w, const char *sys, const char *field, double v, double lo, double hi)
{
	if (v >= lo && v <= hi)
		return true;
	eddy__fail(w, EDDY_ERR_INVALID, "%s: '%s' must be in [%g, %g] (got %g)", sys, field, lo, hi, v);
	return false;
}

bool eddy__check_vec3(eddy_world *w, const char *sys, const char *field, eddy_vec3 v)
{
	if (isfinite(v.x) && isfinite(v.y) && isfinite(v.z))
		return true;
	eddy__fail(w, EDDY_ERR_INVALID, "%s: '%s' must be finite (got {%g, %g, %g})", sys, field, (double)v.x, (double)v.y,
	           (double)v.z);
	return false;
}

bool eddy__check_box(eddy_world *w, const char *sys, eddy_vec3 lo, eddy_vec3 hi)
{
	if (!eddy__check_vec3(w, sys, "min", lo) || !eddy__check_vec3(w, sys, "max", hi))
		return false;
	if (hi.x > lo.x && hi.y > lo.y && hi.z > lo.z)
		return true;
	eddy__fail(w, EDDY_ERR_INVALID,
	           "%s: 'max' must exceed 'min' on every axis (got min {%g, %g, %g}, max {%g, %g, %g})", sys, (double)lo.x,
	           (double)lo.y, (double)lo.z, (double)hi.x, (double)hi.y, (double)hi.z);
	return false;
}

bool eddy__check_unit(eddy_world *w, const char *sys, const char *field, eddy_vec3 *v)
{
	if (!eddy__check_vec3(w, sys, field, *v))
		return false;
	double len = sqrt((double)v->x * v->x + (double)v->y * v->y + (double)v->z * v->z);
	if (!(len > 1e-12)) {
		eddy__fail(w, EDDY_ERR_INVALID, "%s: '%s' must be a non-zero vector", sys, field);
		return false;
	}
	v->x = (float)(v->x / len);
	v->y = (float)(v->y / len);
	v->z = (float)(v->z / len);
	return true;
}
