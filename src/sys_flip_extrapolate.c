/* flip_extrapolate: velocity extrapolation into the air (Bridson's book,
 * ch. 4.6; without it particles near the surface interpolate the zeros of
 * faces no particle reached and stall: VALIDATION.md hard case 12).
 *
 * Reads: cell_type u v w. Writes: u v w.
 *   Known faces: a fluid or solid cell on a side, or on the domain's sides.
 *   Layer l = 1..layers: every unknown face with known neighbours (6-connected
 *   in its own face grid) takes their average and becomes known.
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

static eddy_status step(eddy_world *w, eddy_system *s, const eddy_step_context *ctx)
{
	(void)ctx;
	const extrapolate *ex = s->data;
	const int n[3] = {w->nx, w->ny, w->nz};
	const uint8_t *type = (const uint8_t *)w->columns[COL_CELL_TYPE].data;
	float *face[3] = {eddy__col(w, COL_FACE_U), eddy__col(w, COL_FACE_V), eddy__col(w, COL_FACE_W)};
	for (int a = 0; a < 3; ++a) {
		int m[3] = {n[0], n[1], n[2]};
		m[a]++;
		const size_t st[3] = {1, (size_t)m[0], (size_t)m[0] * (size_t)m[1]};
		const size_t nf = st[2] * (size_t)m[2];
		uint8_t *layer = eddy__arena_alloc(&w->arena, nf);
		if (!layer)
			return eddy__fail(w, EDDY_ERR_NOMEM, "flip_extrapolate: out of memory");
		for (int k = 0; k < m[2]; ++k)
			for (int j = 0; j < m[1]; ++j)
				for (int i = 0; i < m[0]; ++i) {
					const int c[3] = {i, j, k};
					const size_t f = (size_t)i + st[1] * (size_t)j + st[2] * (size_t)k;
					uint8_t known = c[a] == 0 || c[a] == n[a];
					if (!known) {
						int lo[3] = {i, j, k};
						lo[a]--;
						const uint8_t tl = type[flip_cell(w, lo[0], lo[1], lo[2])], th = type[flip_cell(w, i, j, k)];
						known = tl != EDDY_CELL_AIR || th != EDDY_CELL_AIR;
					}
					layer[f] = known ? 0 : 255;
				}
		float *u = face[a];
		for (int l = 1; l <= ex->def.layers; ++l) {
			bool changed = false;
			for (int k = 0; k < m[2]; ++k)
				for (int j = 0; j < m[1]; ++j)
					for (int i = 0; i < m[0]; ++i) {
						const size_t f = (size_t)i + st[1] * (size_t)j + st[2] * (size_t)k;
						if (layer[f] != 255)
							continue;
						const int c[3] = {i, j, k};
						float sum = 0;
						int cnt = 0;
						for (int d = 0; d < 3; ++d) {
							if (c[d] > 0 && layer[f - st[d]] < l) {
								sum += u[f - st[d]];
								cnt++;
							}
							if (c[d] < m[d] - 1 && layer[f + st[d]] < l) {
								sum += u[f + st[d]];
								cnt++;
							}
						}
						if (cnt) {
							u[f] = sum / (float)cnt;
							layer[f] = (uint8_t)l;
							changed = true;
						}
					}
			if (!changed)
				break;
		}
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
	if (!def)
		return eddy__fail(w, EDDY_ERR_INVALID, "%s: def is NULL", sys), EDDY_NULL_SYSTEM;
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
