/* SPDX-License-Identifier: MIT */
/* flip_surface: the free surface as the zero crossing of a smoothed marker
 * field (Guo & Li, after Zhu & Bridson 2005: marker -1 in fluid, +1 in empty
 * cells, blurred by a 3D Gaussian so the surface is not stair-stepped).
 *
 * Reads: cell_type flip_phi. Writes: flip_phi.
 *   phi <- G_sigma * phi, G separable: three 1D passes with weights
 *   exp(-d^2 / (2 sigma^2)), |d| <= ceil(2 sigma) cells, renormalised over the
 *   cells in reach; a pass stops at a solid cell or the domain's side (solid
 *   cells are neither fluid nor empty, and fluid behind a wall is not near).
 * A flat surface on a cell face stays exactly there (the blur is symmetric);
 * flip_pressure places the surface at the linear zero crossing of phi. */
#include "flip.h"

#include <stdlib.h>
#include <string.h>

typedef struct surface {
	eddy_flip_surface_def def;
} surface;

static const int surface_reads[] = {COL_CELL_TYPE, COL_FLIP_PHI};
static const int surface_writes[] = {COL_FLIP_PHI, -1};

eddy_flip_surface_def eddy_default_flip_surface_def(void)
{
	eddy_flip_surface_def d;
	d.sigma = 1.0f;
	return d;
}

enum { MAX_R = 8 };

static eddy_status step(eddy_world *w, eddy_system *s, const eddy_step_context *ctx)
{
	const surface *sf = s->data;
	const int n[3] = {w->nx, w->ny, w->nz};
	const size_t stride[3] = {1, (size_t)n[0], (size_t)n[0] * (size_t)n[1]};
	const size_t nc = (size_t)n[0] * n[1] * n[2];
	const uint8_t *type = (const uint8_t *)w->columns[COL_CELL_TYPE].data;
	float *phi = eddy__col(w, COL_FLIP_PHI);
	float *tmp = eddy__arena_alloc(&w->arena, nc * sizeof *tmp);
	if (!tmp)
		return eddy__fail(w, EDDY_ERR_NOMEM, "flip_surface: out of memory");
	int r = (int)ceilf(2.0f * sf->def.sigma);
	r = r > MAX_R ? MAX_R : r;
	float g[MAX_R + 1];
	for (int d = 0; d <= r; ++d)
		g[d] = expf(-(float)(d * d) / (2.0f * sf->def.sigma * sf->def.sigma));
	float *src = phi, *dst = tmp;
	for (int a = 0; a < 3; ++a) {
		const int len = n[a];
		const size_t st = stride[a];
		const float *in = src;
		float *out = dst;
		/* each cell's output depends on the input pass only: same result on any thread count */
#pragma omp parallel for num_threads(ctx->threads) if (nc > 32768) schedule(static)
		for (long cl = 0; cl < (long)nc; ++cl) {
			const size_t c = (size_t)cl;
			if (type[c] == EDDY_CELL_SOLID) {
				out[c] = in[c];
				continue;
			}
			const int pos = (int)((c / st) % (size_t)len);
			float sum = g[0] * in[c], wsum = g[0];
			/* outward each way, stopping at a solid: fluid behind a wall is not near */
			for (int d = 1; d <= r && pos + d < len && type[c + (size_t)d * st] != EDDY_CELL_SOLID; ++d) {
				sum += g[d] * in[c + (size_t)d * st];
				wsum += g[d];
			}
			for (int d = 1; d <= r && pos - d >= 0 && type[c - (size_t)d * st] != EDDY_CELL_SOLID; ++d) {
				sum += g[d] * in[c - (size_t)d * st];
				wsum += g[d];
			}
			out[c] = sum / wsum;
		}
		float *t = src;
		src = dst;
		dst = t;
	}
	/* three passes end in tmp */
	memcpy(phi, src, nc * sizeof *phi);
	return EDDY_OK;
}

const eddy_system_vtable eddy__kind_flip_surface = {
	.name = "flip_surface",
	.step = step,
	.default_writes = surface_writes,
};

eddy_system_id eddy_add_flip_surface(eddy_world *w, const eddy_flip_surface_def *def)
{
	const char *sys = "flip_surface";
	if (!eddy__add_args(w, def, sys))
		return EDDY_NULL_SYSTEM;
	if (!(def->sigma > 0 && def->sigma <= 4)) {
		eddy__fail(w, EDDY_ERR_INVALID, "%s: 'sigma' must be in (0, 4] cells (got %g)", sys, (double)def->sigma);
		return EDDY_NULL_SYSTEM;
	}
	surface *sf = malloc(sizeof *sf);
	if (sf)
		sf->def = *def;
	return eddy__add_system(w, &eddy__kind_flip_surface, sf, surface_reads, 2, surface_writes, 1);
}
