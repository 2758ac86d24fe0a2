/* SPDX-License-Identifier: MIT */
/* flip_boundary: solid cells and solid face velocities (Bridson, "Fluid
 * Simulation for Computer Graphics", ch. 5: free-slip solid walls).
 *
 * Reads: cell_type u v w. Writes: cell_type u v w.
 *   A cell is solid when its centre c has phi_s(c) < margin for some collider
 *   in the pipeline (phi_s its signed distance, < 0 inside the solid).
 *   Faces on the domain's sides: u.n = 0 (fixed walls).
 *   Faces touching a solid cell: u.n = V_s.n, V_s = (offset - last offset) / dt
 *   of that collider, so moving colliders push the fluid (free slip: only the
 *   normal component is imposed, which is all a MAC face stores).
 * The collider's velocity is read, not consumed: add the colliders after
 * flip_advect (where they also keep particles out) so this system sees the
 * offset the host set for this step against the one of the last step. */
#include "flip.h"

#include <stdlib.h>
#include <string.h>

typedef struct boundary {
	eddy_flip_boundary_def def;
} boundary;

static const int boundary_io[] = {COL_CELL_TYPE, COL_FACE_U, COL_FACE_V, COL_FACE_W, -1};

eddy_flip_boundary_def eddy_default_flip_boundary_def(void)
{
	eddy_flip_boundary_def d;
	d.margin = 0.0f;
	return d;
}

static eddy_status step(eddy_world *w, eddy_system *s, const eddy_step_context *ctx)
{
	const boundary *b = s->data;
	const int nx = w->nx, ny = w->ny, nz = w->nz;
	const double h = w->def.cell_size;
	const eddy_vec3 o = w->def.bounds_min;
	uint8_t *type = (uint8_t *)w->columns[COL_CELL_TYPE].data;
	float *u = eddy__col(w, COL_FACE_U), *v = eddy__col(w, COL_FACE_V), *wv = eddy__col(w, COL_FACE_W);
	const size_t nc = (size_t)nx * ny * nz;
	/* index + 1 of the collider owning each solid cell, 0 for none */
	uint16_t *owner = eddy__arena_alloc(&w->arena, nc * sizeof *owner);
	eddy_vec3 *vel = eddy__arena_alloc(&w->arena, (size_t)w->order_count * sizeof *vel + 1);
	if (!owner || !vel)
		return eddy__fail(w, EDDY_ERR_NOMEM, "flip_boundary: out of memory");
	memset(owner, 0, nc * sizeof *owner);
	const float inv_dt = ctx->dt > 0 ? (float)(1.0 / ctx->dt) : 0.0f;
	for (int q = 0; q < w->order_count; ++q) {
		const eddy_system *c = &w->slots[w->order[q]];
		if (!eddy__is_collider(c))
			continue;
		const eddy_collider_motion m = ((const eddy_collider_base *)c->data)->motion;
		vel[q] = (eddy_vec3){(m.offset.x - m.last_offset.x) * inv_dt, (m.offset.y - m.last_offset.y) * inv_dt,
		                     (m.offset.z - m.last_offset.z) * inv_dt};
		for (int k = 0; k < nz; ++k)
			for (int j = 0; j < ny; ++j)
				for (int i = 0; i < nx; ++i) {
					const eddy_vec3 p = {(float)(o.x + (i + 0.5) * h), (float)(o.y + (j + 0.5) * h),
					                     (float)(o.z + (k + 0.5) * h)};
					if (c->vt->distance(c, p) < b->def.margin) {
						const size_t ci = flip_cell(w, i, j, k);
						type[ci] = EDDY_CELL_SOLID;
						owner[ci] = (uint16_t)(q + 1);
					}
				}
	}
	/* faces touching a solid cell take its normal velocity; domain sides are still */
	for (int k = 0; k < nz; ++k)
		for (int j = 0; j < ny; ++j)
			for (int i = 0; i <= nx; ++i) {
				const size_t f = flip_fu(w, i, j, k);
				if (i == 0 || i == nx) {
					u[f] = 0;
					continue;
				}
				const uint16_t a = owner[flip_cell(w, i - 1, j, k)], c = owner[flip_cell(w, i, j, k)];
				if (a || c)
					u[f] = vel[(a ? a : c) - 1].x;
			}
	for (int k = 0; k < nz; ++k)
		for (int j = 0; j <= ny; ++j)
			for (int i = 0; i < nx; ++i) {
				const size_t f = flip_fv(w, i, j, k);
				if (j == 0 || j == ny) {
					v[f] = 0;
					continue;
				}
				const uint16_t a = owner[flip_cell(w, i, j - 1, k)], c = owner[flip_cell(w, i, j, k)];
				if (a || c)
					v[f] = vel[(a ? a : c) - 1].y;
			}
	for (int k = 0; k <= nz; ++k)
		for (int j = 0; j < ny; ++j)
			for (int i = 0; i < nx; ++i) {
				const size_t f = flip_fw(w, i, j, k);
				if (k == 0 || k == nz) {
					wv[f] = 0;
					continue;
				}
				const uint16_t a = owner[flip_cell(w, i, j, k - 1)], c = owner[flip_cell(w, i, j, k)];
				if (a || c)
					wv[f] = vel[(a ? a : c) - 1].z;
			}
	return EDDY_OK;
}

const eddy_system_vtable eddy__kind_flip_boundary = {
	.name = "flip_boundary",
	.step = step,
	.default_writes = boundary_io,
};

eddy_system_id eddy_add_flip_boundary(eddy_world *w, const eddy_flip_boundary_def *def)
{
	const char *sys = "flip_boundary";
	if (!eddy__add_args(w, def, sys))
		return EDDY_NULL_SYSTEM;
	if (!eddy__check_nonneg(w, sys, "margin", def->margin) || !eddy__check_finite(w, sys, "margin", def->margin))
		return EDDY_NULL_SYSTEM;
	boundary *b = malloc(sizeof *b);
	if (b)
		b->def = *def;
	return eddy__add_system(w, &eddy__kind_flip_boundary, b, boundary_io, 4, boundary_io, 4);
}
