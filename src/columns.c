/* SPDX-License-Identifier: MIT */
/* Column storage: the particle table (one array per channel, swap-remove,
 * doubling growth) and the MAC grid (cell and face arrays).
 *
 * A column's memory exists exactly while its user count is above zero; the
 * pipeline raises and lowers the counts as systems come and go. The grid's
 * dimensions come from the world bounds and cell_size and are fixed once the
 * first grid column is in use. */
#define _POSIX_C_SOURCE 200809L
#include "core.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

static const struct {
	const char *name;
	eddy_domain domain;
	eddy_type type;
	eddy_lifetime lifetime;
	const char *unit;
} builtin[COL_BUILTIN_COUNT] = {
#define EDDY_COL_ROW(ident, nm, dom, ty, life, un) {nm, dom, ty, life, un},
	EDDY_COMPONENTS(EDDY_COL_ROW)
#undef EDDY_COL_ROW
};

void eddy__columns_init(eddy_world *w)
{
	for (int i = 0; i < COL_BUILTIN_COUNT; ++i) {
		eddy_column *c = &w->columns[i];
		snprintf(c->name, sizeof c->name, "%s", builtin[i].name);
		snprintf(c->unit, sizeof c->unit, "%s", builtin[i].unit);
		c->domain = builtin[i].domain;
		c->type = builtin[i].type;
		c->lifetime = builtin[i].lifetime;
	}
	w->column_count = COL_BUILTIN_COUNT;
}

void eddy__columns_free(eddy_world *w)
{
	for (int i = 0; i < w->column_count; ++i) {
		free(w->columns[i].data);
		w->columns[i].data = NULL;
	}
}

static size_t elem_size(eddy_type t) { return t == EDDY_U8 ? 1 : sizeof(float); }

size_t eddy__column_elems(const eddy_world *w, const eddy_column *c)
{
	const size_t nx = (size_t)w->nx, ny = (size_t)w->ny, nz = (size_t)w->nz;
	switch (c->domain) {
	case EDDY_DOMAIN_PARTICLE:
		return w->n;
	case EDDY_DOMAIN_CELL:
		return nx * ny * nz;
	case EDDY_DOMAIN_FACE_X:
		return (nx + 1) * ny * nz;
	case EDDY_DOMAIN_FACE_Y:
		return nx * (ny + 1) * nz;
	case EDDY_DOMAIN_FACE_Z:
		return nx * ny * (nz + 1);
	}
	return 0;
}

static size_t column_capacity(const eddy_world *w, const eddy_column *c)
{
	return c->domain == EDDY_DOMAIN_PARTICLE ? w->capacity : eddy__column_elems(w, c);
}

size_t eddy__column_bytes(const eddy_world *w, const eddy_column *c)
{
	return eddy__column_elems(w, c) * elem_size(c->type);
}

static eddy_status grid_setup(eddy_world *w, const eddy_column *c)
{
	if (w->grid_allocated)
		return EDDY_OK;
	const double h = w->def.cell_size;
	if (!(h > 0))
		return eddy__fail(w, EDDY_ERR_INVALID,
		                  "column '%s' lives on the MAC grid, but the world has no grid: set world 'cell_size' > 0 m",
		                  c->name);
	const eddy_vec3 lo = w->def.bounds_min, hi = w->def.bounds_max;
	/* bounds are floats: 0.55f / 0.00625 is 88.000002 cells, which must not
	 * round up to a sliver cell past the wall (FLIP puts its walls at the
	 * grid's sides), hence a tolerance well above float rounding */
	const double nx = ceil((hi.x - lo.x) / h - 1e-4), ny = ceil((hi.y - lo.y) / h - 1e-4),
				 nz = ceil((hi.z - lo.z) / h - 1e-4);
	if (nx * ny * nz > 2e9)
		return eddy__fail(w, EDDY_ERR_NOMEM, "grid of %.0f x %.0f x %.0f cells is too large; use a larger cell_size",
		                  nx, ny, nz);
	w->nx = nx < 1 ? 1 : (int)nx;
	w->ny = ny < 1 ? 1 : (int)ny;
	w->nz = nz < 1 ? 1 : (int)nz;
	w->grid_allocated = true;
	return EDDY_OK;
}

static bool grid_in_use(const eddy_world *w)
{
	for (int i = 0; i < w->column_count; ++i)
		if (w->columns[i].domain != EDDY_DOMAIN_PARTICLE && w->columns[i].data)
			return true;
	return false;
}

eddy_status eddy__column_acquire(eddy_world *w, int id)
{
	eddy_column *c = &w->columns[id];
	if (c->users++ > 0)
		return EDDY_OK;
	if (c->domain != EDDY_DOMAIN_PARTICLE) {
		eddy_status st = grid_setup(w, c);
		if (st != EDDY_OK) {
			c->users--;
			return st;
		}
	}
	size_t cap = column_capacity(w, c);
	if (c->domain != EDDY_DOMAIN_PARTICLE) {
		/* calloc of a huge grid succeeds lazily and the process dies when the
		 * solver first touches it: refuse what cannot fit instead */
		double grid_bytes = (double)cap * (double)elem_size(c->type);
		for (int i = 0; i < w->column_count; ++i)
			if (w->columns[i].data && w->columns[i].domain != EDDY_DOMAIN_PARTICLE)
				grid_bytes += (double)eddy__column_bytes(w, &w->columns[i]);
		long pages = sysconf(_SC_PHYS_PAGES), page = sysconf(_SC_PAGE_SIZE);
		double phys = pages > 0 && page > 0 ? (double)pages * (double)page : 0;
		if (phys > 0 && grid_bytes > 0.8 * phys) {
			c->users--;
			if (!grid_in_use(w)) {
				w->grid_allocated = false;
				w->nx = w->ny = w->nz = 0;
			}
			return eddy__fail(
				w, EDDY_ERR_NOMEM,
				"the %d x %d x %d grid needs %.1f GB for its columns, more than 80%% of this machine's %.1f GB; "
				"use a larger cell_size",
				w->nx, w->ny, w->nz, grid_bytes / 1e9, phys / 1e9);
		}
	}
	/* calloc(0) may return NULL; keep a real block so "allocated" stays visible. */
	c->data = calloc(cap ? cap : 1, elem_size(c->type));
	if (!c->data) {
		c->users--;
		return eddy__fail(w, EDDY_ERR_NOMEM, "out of memory for column '%s' (%zu elements)", c->name, cap);
	}
	return EDDY_OK;
}

void eddy__column_release(eddy_world *w, int id)
{
	eddy_column *c = &w->columns[id];
	if (c->users <= 0 || --c->users > 0)
		return;
	free(c->data);
	c->data = NULL;
	if (!grid_in_use(w)) {
		w->grid_allocated = false;
		w->nx = w->ny = w->nz = 0;
	}
}

eddy_status eddy__reserve_particles(eddy_world *w, size_t count)
{
	if (count <= w->capacity)
		return EDDY_OK;
	size_t cap = w->capacity ? w->capacity : 256;
	while (cap < count) {
		if (cap > SIZE_MAX / 2 / sizeof(float))
			return eddy__fail(w, EDDY_ERR_NOMEM, "particle table cannot hold %zu particles", count);
		cap *= 2;
	}
	/* Refuse what cannot fit: with overcommit a huge realloc succeeds and the
	 * process is killed later, when the memory is first touched. */
	size_t per_particle = 0;
	for (int i = 0; i < w->column_count; ++i)
		if (w->columns[i].data && w->columns[i].domain == EDDY_DOMAIN_PARTICLE)
			per_particle += elem_size(w->columns[i].type);
	long pages = sysconf(_SC_PHYS_PAGES), page = sysconf(_SC_PAGE_SIZE);
	double phys = pages > 0 && page > 0 ? (double)pages * (double)page : 0;
	if (phys > 0 && (double)cap * (double)per_particle > 0.8 * phys)
		return eddy__fail(w, EDDY_ERR_NOMEM,
		                  "%zu particles need %.1f GB of particle columns, more than 80%% of this machine's %.1f GB; "
		                  "use a larger spacing",
		                  count, (double)cap * (double)per_particle / 1e9, phys / 1e9);
	for (int i = 0; i < w->column_count; ++i) {
		eddy_column *c = &w->columns[i];
		if (!c->data || c->domain != EDDY_DOMAIN_PARTICLE)
			continue;
		size_t es = elem_size(c->type);
		void *p = realloc(c->data, cap * es);
		if (!p)
			return eddy__fail(w, EDDY_ERR_NOMEM, "out of memory growing the particle table to %zu particles", cap);
		memset((char *)p + w->capacity * es, 0, (cap - w->capacity) * es);
		c->data = p;
	}
	w->capacity = cap;
	return EDDY_OK;
}

eddy_status eddy__append_particles(eddy_world *w, size_t count, size_t *first)
{
	eddy_status st = eddy__reserve_particles(w, w->n + count);
	if (st != EDDY_OK)
		return st;
	for (int i = 0; i < w->column_count; ++i) {
		eddy_column *c = &w->columns[i];
		if (c->data && c->domain == EDDY_DOMAIN_PARTICLE)
			memset((char *)c->data + w->n * elem_size(c->type), 0, count * elem_size(c->type));
	}
	*first = w->n;
	w->n += count;
	return EDDY_OK;
}

void eddy__clear_derived(eddy_world *w)
{
	enum { PIECE = 1 << 18 }; /* bytes: a large column is cleared by all threads, a piece each */
	for (int i = 0; i < w->column_count; ++i) {
		eddy_column *c = &w->columns[i];
		if (!c->data || c->lifetime != EDDY_DERIVED)
			continue;
		const size_t bytes = eddy__column_bytes(w, c);
		const long pieces = (long)((bytes + PIECE - 1) / PIECE);
		const int nt = pieces > 1 ? w->def.threads : 1;
#pragma omp parallel for num_threads(nt) if (nt > 1) schedule(static)
		for (long q = 0; q < pieces; ++q) {
			const size_t at = (size_t)q * PIECE;
			memset((char *)c->data + at, 0, bytes - at < PIECE ? bytes - at : PIECE);
		}
	}
}

void eddy__permute_particles(eddy_world *w, const uint32_t *perm, void *scratch)
{
	enum { PIECE = 1 << 16 }; /* bytes: the copy back is handed out in pieces */
	const long n = (long)w->n;
	const int nt = n > EDDY_PAR_ROWS ? w->def.threads : 1;
	unsigned char *tmp = scratch;
	for (int c = 0; c < w->column_count; ++c) {
		eddy_column *col = &w->columns[c];
		if (!col->data || col->domain != EDDY_DOMAIN_PARTICLE)
			continue;
		const bool u8 = col->type == EDDY_U8; /* else 4-byte values */
		unsigned char *data = col->data;
		const size_t bytes = (size_t)n * (u8 ? 1 : 4);
		const long pieces = (long)((bytes + PIECE - 1) / PIECE);
#pragma omp parallel num_threads(nt) if (nt > 1)
		{
#pragma omp for schedule(static)
			for (long i = 0; i < n; ++i) {
				if (u8)
					tmp[i] = data[perm[i]];
				else
					memcpy(tmp + 4 * (size_t)i, data + 4 * (size_t)perm[i], 4);
			}
#pragma omp for schedule(static)
			for (long q = 0; q < pieces; ++q) {
				const size_t at = (size_t)q * PIECE;
				memcpy(data + at, tmp + at, bytes - at < PIECE ? bytes - at : PIECE);
			}
		}
	}
}

/* ---- public access ------------------------------------------------------- */

int eddy_world_column_count(const eddy_world *w) { return w ? w->column_count : 0; }

eddy_column_id eddy_world_find_column(const eddy_world *w, const char *name)
{
	if (!w || !name)
		return -1;
	for (int i = 0; i < w->column_count; ++i)
		if (strcmp(w->columns[i].name, name) == 0)
			return i;
	return -1;
}

eddy_status eddy_world_column_info(const eddy_world *w, eddy_column_id id, eddy_column_info *out)
{
	if (!w || !out || id < 0 || id >= w->column_count)
		return EDDY_ERR_INVALID;
	const eddy_column *c = &w->columns[id];
	out->name = c->name;
	out->domain = c->domain;
	out->type = c->type;
	out->lifetime = c->lifetime;
	out->unit = c->unit;
	out->allocated = c->data != NULL;
	out->bytes = c->data ? column_capacity(w, c) * elem_size(c->type) : 0;
	return EDDY_OK;
}

eddy_column_id eddy_world_declare_column(eddy_world *w, const char *name, eddy_domain domain, eddy_type type,
                                         eddy_lifetime lifetime, const char *unit)
{
	if (!w)
		return -1;
	if (!name || !name[0] || strlen(name) >= EDDY_NAME_MAX) {
		eddy__fail(w, EDDY_ERR_INVALID, "column name must be 1 to %d characters", EDDY_NAME_MAX - 1);
		return -1;
	}
	if (eddy_world_find_column(w, name) >= 0) {
		eddy__fail(w, EDDY_ERR_INVALID, "column '%s' already exists", name);
		return -1;
	}
	if (w->column_count == EDDY_MAX_COLUMNS) {
		eddy__fail(w, EDDY_ERR_INVALID, "too many columns (%d)", EDDY_MAX_COLUMNS);
		return -1;
	}
	if ((int)domain < EDDY_DOMAIN_PARTICLE || domain > EDDY_DOMAIN_FACE_Z || (type != EDDY_F32 && type != EDDY_U8) ||
	    (lifetime != EDDY_STATE && lifetime != EDDY_DERIVED)) {
		eddy__fail(w, EDDY_ERR_INVALID, "column '%s': unknown domain, type or lifetime", name);
		return -1;
	}
	eddy_column *c = &w->columns[w->column_count];
	memset(c, 0, sizeof *c);
	snprintf(c->name, sizeof c->name, "%s", name);
	snprintf(c->unit, sizeof c->unit, "%s", unit ? unit : "");
	c->domain = domain;
	c->type = type;
	c->lifetime = lifetime;
	return w->column_count++;
}

static void *channel(const eddy_world *w, const char *name, size_t *count, eddy_type type)
{
	int id = eddy_world_find_column(w, name);
	if (count)
		*count = 0;
	if (id < 0 || !w->columns[id].data || w->columns[id].type != type)
		return NULL;
	if (count)
		*count = eddy__column_elems(w, &w->columns[id]);
	return w->columns[id].data;
}

const float *eddy_world_channel(const eddy_world *w, const char *name, size_t *count)
{
	return channel(w, name, count, EDDY_F32);
}

float *eddy_world_channel_mut(eddy_world *w, const char *name, size_t *count)
{
	return channel(w, name, count, EDDY_F32);
}

const uint8_t *eddy_world_channel_u8(const eddy_world *w, const char *name, size_t *count)
{
	return channel(w, name, count, EDDY_U8);
}

size_t eddy_world_particle_count(const eddy_world *w) { return w ? w->n : 0; }

/* Acquires the particle columns first .. last (consecutive ids) for the
 * host, all or none. */
_Static_assert(COL_Y_ == COL_X_ + 1 && COL_Z_ == COL_X_ + 2 && COL_VY == COL_VX + 1 && COL_VZ == COL_VX + 2,
               "host_hold takes consecutive column ids");
static eddy_status host_hold(eddy_world *w, int first, int last)
{
	for (int id = first; id <= last; ++id) {
		eddy_status st = eddy__column_acquire(w, id);
		if (st != EDDY_OK) {
			while (--id >= first)
				eddy__column_release(w, id);
			return st;
		}
	}
	return EDDY_OK;
}

eddy_status eddy_world_add_particles(eddy_world *w, size_t count, const eddy_vec3 *pos, const eddy_vec3 *vel)
{
	if (!w || (count && !pos))
		return eddy__fail(w, EDDY_ERR_INVALID, "add_particles: positions are NULL");
	const eddy_vec3 lo = w->def.bounds_min, hi = w->def.bounds_max;
	for (size_t i = 0; i < count; ++i) {
		eddy_vec3 p = pos[i];
		if (!(p.x >= lo.x && p.x <= hi.x && p.y >= lo.y && p.y <= hi.y && p.z >= lo.z && p.z <= hi.z))
			return eddy__fail(w, EDDY_ERR_INVALID,
			                  "add_particles: particle %zu at (%g, %g, %g) is outside the world bounds", i, (double)p.x,
			                  (double)p.y, (double)p.z);
		if (vel && !(isfinite(vel[i].x) && isfinite(vel[i].y) && isfinite(vel[i].z)))
			return eddy__fail(w, EDDY_ERR_INVALID, "add_particles: velocity of particle %zu is not finite", i);
	}
	/* the columns first: a failure leaves the table as it was */
	eddy_status st = EDDY_OK;
	if (count && !w->host_positions) {
		st = host_hold(w, COL_X_, COL_Z_);
		w->host_positions = st == EDDY_OK;
	}
	if (st == EDDY_OK && count && vel && !w->host_velocities) {
		st = host_hold(w, COL_VX, COL_VZ);
		w->host_velocities = st == EDDY_OK;
	}
	size_t first;
	if (st == EDDY_OK)
		st = eddy__append_particles(w, count, &first);
	if (st != EDDY_OK)
		return st;
	float *x = eddy__col(w, COL_X_), *y = eddy__col(w, COL_Y_), *z = eddy__col(w, COL_Z_);
	float *vx = eddy__col(w, COL_VX), *vy = eddy__col(w, COL_VY), *vz = eddy__col(w, COL_VZ);
	for (size_t i = 0; i < count; ++i) {
		x[first + i] = pos[i].x;
		y[first + i] = pos[i].y;
		z[first + i] = pos[i].z;
		if (vel) {
			vx[first + i] = vel[i].x;
			vy[first + i] = vel[i].y;
			vz[first + i] = vel[i].z;
		}
	}
	return EDDY_OK;
}

eddy_status eddy_world_remove_particle(eddy_world *w, size_t i)
{
	if (!w)
		return EDDY_ERR_INVALID;
	if (i >= w->n)
		return eddy__fail(w, EDDY_ERR_INVALID, "remove_particle: index %zu out of range (%zu particles)", i, w->n);
	const size_t last = w->n - 1;
	for (int c = 0; c < w->column_count; ++c) {
		eddy_column *col = &w->columns[c];
		if (!col->data || col->domain != EDDY_DOMAIN_PARTICLE)
			continue;
		size_t es = elem_size(col->type);
		memcpy((char *)col->data + i * es, (char *)col->data + last * es, es);
	}
	w->n = last;
	return EDDY_OK;
}

eddy_grid_info eddy_world_grid(const eddy_world *w)
{
	eddy_grid_info g = {0};
	if (!w)
		return g;
	g.allocated = w->grid_allocated;
	g.nx = w->nx;
	g.ny = w->ny;
	g.nz = w->nz;
	g.cell_size = w->grid_allocated ? w->def.cell_size : 0;
	g.origin = w->def.bounds_min;
	return g;
}
