/* SPDX-License-Identifier: MIT */
/* flip_surface: the free surface as the zero crossing of a smoothed marker
 * field (Guo & Li, after Zhu & Bridson 2005: marker -1 in fluid, +1 in empty
 * cells, blurred by a 3D Gaussian so the surface is not stair-stepped).
 * flip_p2g writes the marker as 1 - 2 f, f the cell's fill fraction from the
 * particle count, so the field's liquid volume sum (1 - phi) / 2 dx^3 is the
 * particles', and the blur keeps it.
 *
 * Reads: cell_type flip_phi. Writes: flip_phi.
 *   phi <- G_sigma * phi, G separable: three 1D passes with weights
 *   exp(-d^2 / (2 sigma^2)), |d| <= ceil(2 sigma) cells, normalised to sum 1;
 *   a pass is reflected at a solid cell or the domain's side (the image of
 *   the cell d beyond a face is the cell d - 1 before it: solid cells are
 *   neither fluid nor empty, and fluid behind a wall is not near). With
 *   reflection every 1D pass is doubly stochastic on each run of non-solid
 *   cells, so the blur keeps sum (1 - phi) / 2, the liquid volume, exactly
 *   (a cut-off pass renormalised over the cells in reach would not: a layer
 *   along a wall would gain or lose volume).
 * A flat surface on a cell face stays exactly there (the blur is symmetric);
 * flip_pressure places the surface at the linear zero crossing of phi. */
#include "flip.h"

#include <stdlib.h>
#include <string.h>

typedef struct surface {
	eddy_flip_surface_def def;
} surface;

static const int surface_reads[] = {COL_CELL_TYPE, COL_FLIP_PHI, -1};
static const int surface_writes[] = {COL_FLIP_PHI, -1};

eddy_flip_surface_def eddy_default_flip_surface_def(void)
{
	eddy_flip_surface_def d;
	d.sigma = 1.0f;
	return d;
}

enum { MAX_R = 8 };

static eddy_status step_body(eddy_world *w, eddy_system *s, const eddy_step_context *ctx)
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
	/* the trilinear count leaks across a solid wall: weights a particle put
	 * on a solid cell's centre go back to the fluid side, as the domain's
	 * sides' constant extension keeps them: to its non-solid face neighbours
	 * in proportion to their own fill (a wall between a full and an empty
	 * cell took its weight from the full one); a cell a collider cuts holds
	 * its particles in its open part, so its fill is count / (n0 open) */
	flip_solid sd;
	if (!eddy__flip_solid_for(w, s, ctx->dt, &sd))
		return eddy__fail(w, EDDY_ERR_NOMEM, "flip_surface: out of memory");
	if (sd.any) {
		memcpy(tmp, phi, nc * sizeof *phi);
		for (int k = 0; k < n[2]; ++k)
			for (int j = 0; j < n[1]; ++j)
				for (int i = 0; i < n[0]; ++i) {
					const size_t c = flip_cell(w, i, j, k);
					const float f = 0.5f * (1.0f - tmp[c]);
					if (type[c] != EDDY_CELL_SOLID || !(f > 0))
						continue;
					const int pos[3] = {i, j, k};
					size_t nb[6];
					int m = 0;
					for (int a = 0; a < 3; ++a) {
						if (pos[a] > 0 && type[c - stride[a]] != EDDY_CELL_SOLID)
							nb[m++] = c - stride[a];
						if (pos[a] + 1 < n[a] && type[c + stride[a]] != EDDY_CELL_SOLID)
							nb[m++] = c + stride[a];
					}
					float sum = 0;
					for (int q = 0; q < m; ++q)
						sum += 0.5f * (1.0f - tmp[nb[q]]);
					for (int q = 0; q < m && sum > 0; ++q)
						phi[nb[q]] -= f * (1.0f - tmp[nb[q]]) / sum; /* fill + f f_q / sum */
					phi[c] = 1.0f;
				}
		/* near the box's cut (flip_grid's top) the count of a full cell is
		 * known exactly (flip_box_rest), in its cut cells and in the cells
		 * beside them whose kernel reaches past the box */
		const flip_grid g = flip_grid_of(w);
		const bool box = flip_grid_cut(&g);
		for (size_t c = 0; c < nc; ++c) {
			if (type[c] == EDDY_CELL_SOLID)
				continue;
			const float op = flip_solid_open(&sd, c);
			float full = op;
			if (box) {
				const int i = (int)(c % (size_t)n[0]), j = (int)(c / (size_t)n[0] % (size_t)n[1]),
						  k = (int)(c / ((size_t)n[0] * n[1]));
				if (flip_box_open(&g, i, j, k) <= op)
					full = flip_box_rest(&g, i, j, k);
			}
			if (!(full < 1))
				continue;
			float f = 0.5f * (1.0f - phi[c]) / (full > 0.05f ? full : 0.05f);
			f = f < 2.0f ? f : 2.0f;
			phi[c] = 1.0f - 2.0f * f;
		}
	}
	int r = (int)ceilf(2.0f * sf->def.sigma);
	r = r > MAX_R ? MAX_R : r;
	float g[MAX_R + 1];
	float gsum = 0;
	for (int d = 0; d <= r; ++d) {
		g[d] = expf(-(float)(d * d) / (2.0f * sf->def.sigma * sf->def.sigma));
		gsum += d ? 2 * g[d] : g[d];
	}
	bool any_solid = false; /* without solid cells only the domain's sides reflect */
	for (size_t c = 0; c < nc && !any_solid; ++c)
		any_solid = type[c] == EDDY_CELL_SOLID;
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
			float sum = g[0] * in[c];
			bool clear = pos - r >= 0 && pos + r < len;
			for (int d = 1; d <= r && clear && any_solid; ++d)
				clear = type[c + (size_t)d * st] != EDDY_CELL_SOLID && type[c - (size_t)d * st] != EDDY_CELL_SOLID;
			if (clear) { /* nothing to reflect at: the plain stencil */
				for (int d = 1; d <= r; ++d)
					sum += g[d] * (in[c + (size_t)d * st] + in[c - (size_t)d * st]);
				out[c] = sum / gsum;
				continue;
			}
			/* outward each way, reflected at a solid or the domain's side
			 * (fluid behind a wall is not near): the mirror image of the
			 * cell beyond a face is the cell before it */
			for (int dir = -1; dir <= 1; dir += 2) {
				int at = pos, step = dir;
				size_t q = c;
				for (int d = 1; d <= r; ++d) {
					const int next = at + step;
					if (next < 0 || next >= len || type[step > 0 ? q + st : q - st] == EDDY_CELL_SOLID) {
						step = -step; /* reflect: this sample is the cell itself */
					} else {
						at = next;
						q = step > 0 ? q + st : q - st;
					}
					sum += g[d] * in[q];
				}
			}
			out[c] = sum / gsum;
		}
		float *t = src;
		src = dst;
		dst = t;
	}
	/* three passes end in tmp */
	memcpy(phi, src, nc * sizeof *phi);
	return EDDY_OK;
}

/* The scratch is this step's own: released on return, so the pipeline's
 * peak is the largest system's scratch, not their sum. */
static eddy_status step(eddy_world *w, eddy_system *s, const eddy_step_context *ctx)
{
	const eddy_arena_mark m = eddy__arena_mark(&w->arena);
	const eddy_status st = step_body(w, s, ctx);
	eddy__arena_release(&w->arena, m);
	return st;
}

const eddy_system_vtable eddy__kind_flip_surface = {
	.name = "flip_surface",
	.keeps_solids = true,
	.provides = EDDY_CAP_FREE_SURFACE,
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
	surface *sf = calloc(1, sizeof *sf);
	if (sf)
		sf->def = *def;
	return eddy__add_system(w, &eddy__kind_flip_surface, sf, surface_reads, surface_writes);
}
