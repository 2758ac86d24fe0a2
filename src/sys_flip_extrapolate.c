/* SPDX-License-Identifier: MIT */
/* flip_extrapolate: velocity extrapolation into the air (Bridson's book,
 * ch. 4.6; without it particles near the surface interpolate the zeros of
 * faces no particle reached and stall: docs/validation.md hard case 12).
 *
 * Reads: cell_type u v w. Writes: u v w.
 *   Known faces: a fluid or solid cell on a side, or on the domain's sides.
 *   Layer l = 1..layers: every unknown face with known neighbours (6-connected
 *   in its own face grid) takes their average and becomes known. A frontier
 *   list keeps the cost to the faces filled, not the whole grid per layer.
 * Solid faces are never rewritten, so the solid velocities flip_boundary set
 * stay imposed. RK2 advection at CFL number C samples up to C + 1 cells
 * beyond the fluid: layers should be at least that. */
#include "flip.h"

#include <stdlib.h>
#include <string.h>

typedef struct extrapolate {
	eddy_flip_extrapolate_def def;
} extrapolate;

static const int extrap_reads[] = {COL_CELL_TYPE, COL_FACE_U, COL_FACE_V, COL_FACE_W};
static const int extrap_writes[] = {COL_FACE_U, COL_FACE_V, COL_FACE_W, -1};

eddy_flip_extrapolate_def eddy_default_flip_extrapolate_def(void)
{
	eddy_flip_extrapolate_def d;
	d.layers = 6;
	return d;
}

enum { UNKNOWN = 255, QUEUED = 254 };

/* (i, j, k) of face f. The divisions dominate the frontier passes, and a
 * 32-bit division is several times faster than a 64-bit one: grids of fewer
 * than 2^32 faces (all in practice) take it. */
static inline void face_coords(size_t f, const size_t st[3], int m1, bool small, size_t c[3])
{
	if (small) {
		const uint32_t g = (uint32_t)f, s1 = (uint32_t)st[1], row = g / s1;
		c[0] = g - row * s1;
		c[1] = row % (uint32_t)m1;
		c[2] = row / (uint32_t)m1;
	} else {
		c[0] = f % st[1];
		c[1] = f / st[1] % (size_t)m1;
		c[2] = f / st[2];
	}
}

/* One face grid: m faces per axis (strides st), layer flags (0 known,
 * UNKNOWN), two frontier buffers of m0 m1 m2 entries each. Only faces next to
 * the last layer are visited, so the cost follows the filled region. */
static void extrapolate_grid(float *u, uint8_t *layer, size_t *cur, size_t *next, const int m[3], const size_t st[3],
                             int layers)
{
	const bool small = st[2] * (size_t)m[2] <= UINT32_MAX;
	size_t ncur = 0;
	for (int k = 0; k < m[2]; ++k)
		for (int j = 0; j < m[1]; ++j)
			for (int i = 0; i < m[0]; ++i) {
				const size_t f = (size_t)i + st[1] * (size_t)j + st[2] * (size_t)k;
				if (layer[f] != UNKNOWN)
					continue;
				const int c[3] = {i, j, k};
				for (int d = 0; d < 3; ++d)
					if ((c[d] > 0 && layer[f - st[d]] == 0) || (c[d] < m[d] - 1 && layer[f + st[d]] == 0)) {
						layer[f] = QUEUED;
						cur[ncur++] = f;
						break;
					}
			}
	for (int l = 1; l <= layers && ncur > 0; ++l) {
		/* one pass: each frontier face's value, from faces known before this
		 * layer only (the frontier's own faces are QUEUED, not < l, until the
		 * pass is over), and its unknown neighbours queued for the next
		 * layer; the coordinates are computed once for both */
		size_t nnext = 0;
		for (size_t q = 0; q < ncur; ++q) {
			const size_t f = cur[q];
			size_t c[3];
			face_coords(f, st, m[1], small, c);
			float sum = 0;
			int cnt = 0;
			for (int d = 0; d < 3; ++d) {
				if (c[d] > 0 && layer[f - st[d]] < l) {
					sum += u[f - st[d]];
					cnt++;
				}
				if (c[d] + 1 < (size_t)m[d] && layer[f + st[d]] < l) {
					sum += u[f + st[d]];
					cnt++;
				}
			}
			u[f] = cnt ? sum / (float)cnt : u[f];
			for (int d = 0; d < 3; ++d) {
				if (c[d] > 0 && layer[f - st[d]] == UNKNOWN) {
					layer[f - st[d]] = QUEUED;
					next[nnext++] = f - st[d];
				}
				if (c[d] + 1 < (size_t)m[d] && layer[f + st[d]] == UNKNOWN) {
					layer[f + st[d]] = QUEUED;
					next[nnext++] = f + st[d];
				}
			}
		}
		for (size_t q = 0; q < ncur; ++q)
			layer[cur[q]] = (uint8_t)l;
		size_t *t = cur;
		cur = next;
		next = t;
		ncur = nnext;
	}
}

static eddy_status step(eddy_world *w, eddy_system *s, const eddy_step_context *ctx)
{
	const extrapolate *ex = s->data;
	const int n[3] = {w->nx, w->ny, w->nz};
	const uint8_t *type = (const uint8_t *)w->columns[COL_CELL_TYPE].data;
	float *face[3] = {eddy__col(w, COL_FACE_U), eddy__col(w, COL_FACE_V), eddy__col(w, COL_FACE_W)};
	int m[3][3];
	size_t st[3][3];
	uint8_t *layer[3];
	size_t *buf[3];
	for (int a = 0; a < 3; ++a) {
		for (int d = 0; d < 3; ++d)
			m[a][d] = n[d] + (d == a);
		st[a][0] = 1;
		st[a][1] = (size_t)m[a][0];
		st[a][2] = (size_t)m[a][0] * (size_t)m[a][1];
		const size_t nf = st[a][2] * (size_t)m[a][2];
		layer[a] = eddy__arena_alloc(&w->arena, nf);
		buf[a] = eddy__arena_alloc(&w->arena, 2 * nf * sizeof *buf[a]);
		if (!layer[a] || !buf[a])
			return eddy__fail(w, EDDY_ERR_NOMEM, "flip_extrapolate: out of memory");
		for (int k = 0; k < m[a][2]; ++k)
			for (int j = 0; j < m[a][1]; ++j)
				for (int i = 0; i < m[a][0]; ++i) {
					const int c[3] = {i, j, k};
					const size_t f = (size_t)i + st[a][1] * (size_t)j + st[a][2] * (size_t)k;
					bool known = c[a] == 0 || c[a] == n[a];
					if (!known) {
						int lo[3] = {i, j, k};
						lo[a]--;
						known = type[flip_cell(w, lo[0], lo[1], lo[2])] != EDDY_CELL_AIR ||
						        type[flip_cell(w, i, j, k)] != EDDY_CELL_AIR;
					}
					layer[a][f] = known ? 0 : UNKNOWN;
				}
	}
	/* the three grids are independent: one thread each, same result */
	const int nt = ctx->threads < 3 ? ctx->threads : 3;
#pragma omp parallel for num_threads(nt) schedule(static, 1)
	for (int a = 0; a < 3; ++a) {
		const size_t nf = st[a][2] * (size_t)m[a][2];
		extrapolate_grid(face[a], layer[a], buf[a], buf[a] + nf, m[a], st[a], ex->def.layers);
	}
	return EDDY_OK;
}

const eddy_system_vtable eddy__kind_flip_extrapolate = {
	.name = "flip_extrapolate",
	.step = step,
	.default_writes = extrap_writes,
};

eddy_system_id eddy_add_flip_extrapolate(eddy_world *w, const eddy_flip_extrapolate_def *def)
{
	const char *sys = "flip_extrapolate";
	if (!eddy__add_args(w, def, sys))
		return EDDY_NULL_SYSTEM;
	if (def->layers < 1 || def->layers > 64) {
		eddy__fail(w, EDDY_ERR_INVALID, "%s: 'layers' must be in [1, 64] (got %d)", sys, def->layers);
		return EDDY_NULL_SYSTEM;
	}
	/* RK2 at CFL number C samples up to C + 1 cells past the fluid */
	const int need = (int)ceil(w->def.cfl) + 1;
	if (def->layers < need) {
		eddy__fail(w, EDDY_ERR_INVALID, "%s: 'layers' must be >= %d for the world's cfl = %g (got %d)", sys, need,
		           w->def.cfl, def->layers);
		return EDDY_NULL_SYSTEM;
	}
	extrapolate *ex = malloc(sizeof *ex);
	if (ex)
		ex->def = *def;
	return eddy__add_system(w, &eddy__kind_flip_extrapolate, ex, extrap_reads, 4, extrap_writes, 3);
}
