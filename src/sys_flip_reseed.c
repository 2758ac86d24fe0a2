/* SPDX-License-Identifier: MIT */
/* flip_reseed: keeps the particle count in fluid cells between min and max
 * per cell, against the clumping and thinning that leave FLIP's grid cells
 * under-sampled (docs/validation.md hard case 13; Zhu & Bridson keep about 8
 * per cell), without changing the number of particles: a particle is
 * dx^3 / n0 of liquid (n0 = flip_rest_count, flip.h), so creating or deleting
 * one creates or deletes volume, and reseeding moves particles instead.
 *
 * Reads: x y z cell_type u v w. Writes: x y z vx vy vz (and zeroes the APIC
 * columns of a moved particle when they exist).
 *   Spare particles: in a cell holding more than max whose trilinear density
 *   (flip.h) is also above PACKED n0 (a fluid at rest density has cells
 *   above 12 by sampling noise alone), the surplus over max, in index order.
 *   Holes: interior fluid cells (no side empty: holding no particle after
 *   advection and not solid; surface cells are partly empty by nature, and
 *   cell_type predates flip_advect, so a cell a moving blob has just left
 *   still reads fluid) with fewer than min particles, in cell order; cells a
 *   collider cuts are skipped (their open part is known to a cell only, and
 *   a particle placed in the solid would be projected out and pile up).
 *   Each hole takes spare particles, while there are any, to random
 *   positions in the cell (the world's random stream, so runs repeat), with
 *   the grid velocity there. Holes left over are closed and surpluses left
 *   over spread by flip_pressure's volume correction, which acts on the same
 *   density. Run it last, after the colliders.
 * Threads: the counts (integer, atomic) and the density (slabs, flip.h) on
 * all threads, the same on any count; choosing the spares (each cell's
 * first in index order) and the holes' random positions stay serial. */
#include "flip.h"

#include <stdlib.h>
#include <string.h>

typedef struct reseed {
	eddy_flip_reseed_def def;
} reseed;

static const int reseed_reads[] = {COL_X_, COL_Y_, COL_Z_, COL_CELL_TYPE, COL_FACE_U, COL_FACE_V, COL_FACE_W, -1};
static const int reseed_writes[] = {COL_X_, COL_Y_, COL_Z_, COL_VX, COL_VY, COL_VZ, -1};

eddy_flip_reseed_def eddy_default_flip_reseed_def(void)
{
	eddy_flip_reseed_def d;
	d.min_per_cell = 3;
	d.max_per_cell = 12;
	return d;
}

/* A cell gives particles only above this multiple of the rest count n0 in
 * trilinear density as well as above max_per_cell in count: at rest density
 * sampling noise alone puts cells above 12. */
#define PACKED 1.125

static long cell_of(const eddy_world *w, float x, float y, float z)
{
	const float inv = (float)(1.0 / w->def.cell_size);
	const eddy_vec3 o = w->def.bounds_min;
	return (long)flip_cell(w, flip_cell_index((x - o.x) * inv, w->nx), flip_cell_index((y - o.y) * inv, w->ny),
	                       flip_cell_index((z - o.z) * inv, w->nz));
}

/* A cell with no particle after advection that is not solid. */
static inline bool empty(const uint8_t *type, const int *count, size_t c)
{
	return count[c] == 0 && type[c] != EDDY_CELL_SOLID;
}

static eddy_status step_body(eddy_world *w, eddy_system *s, const eddy_step_context *ctx)
{
	const reseed *rs = s->data;
	const int nx = w->nx, ny = w->ny, nz = w->nz;
	const size_t nc = (size_t)nx * ny * nz;
	const uint8_t *type = (const uint8_t *)w->columns[COL_CELL_TYPE].data;
	int *count = eddy__arena_alloc(&w->arena, nc * sizeof *count);
	if (!count)
		return eddy__fail(w, EDDY_ERR_NOMEM, "flip_reseed: out of memory");
	memset(count, 0, nc * sizeof *count);
	{
		/* integer counts: the same whatever order the threads add in */
		const float *x = eddy__col(w, COL_X_), *y = eddy__col(w, COL_Y_), *z = eddy__col(w, COL_Z_);
		const long np = (long)w->n;
		const int nt = np > 16384 ? ctx->threads : 1;
#pragma omp parallel for num_threads(nt) if (nt > 1) schedule(static)
		for (long i = 0; i < np; ++i) {
			const long c = cell_of(w, x[i], y[i], z[i]);
#pragma omp atomic
			count[c]++;
		}
	}
	float *dens = eddy__arena_alloc(&w->arena, nc * sizeof *dens);
	size_t *spare = eddy__arena_alloc(&w->arena, (w->n + 1) * sizeof *spare);
	if (!dens || !spare)
		return eddy__fail(w, EDDY_ERR_NOMEM, "flip_reseed: out of memory");
	flip_particle_density(w, eddy__col(w, COL_X_), eddy__col(w, COL_Y_), eddy__col(w, COL_Z_), dens, ctx->threads);
	/* surplus: particles a packed cell can give (counted, not removed) */
	const double n0 = flip_rest_count(w);
	size_t nspare = 0;
	{
		const float *x = eddy__col(w, COL_X_), *y = eddy__col(w, COL_Y_), *z = eddy__col(w, COL_Z_);
		for (size_t i = 0; i < w->n; ++i) {
			const long c = cell_of(w, x[i], y[i], z[i]);
			if (count[c] > rs->def.max_per_cell && dens[c] > PACKED * n0) {
				count[c]--;
				spare[nspare++] = i;
			}
		}
	}
	if (nspare == 0)
		return EDDY_OK; /* nothing to move: holes are flip_pressure's to close */
	size_t used = 0;
	/* the solids now (after the colliders moved): a cut cell's fair share is
	 * min_per_cell times its open fraction, and no particle is placed inside */
	flip_solid sd;
	if (!eddy__flip_solid_for(w, s, ctx->dt, &sd))
		return eddy__fail(w, EDDY_ERR_NOMEM, "flip_reseed: out of memory");
	const double h = w->def.cell_size;
	const flip_grid grid = flip_grid_of(w);
	const eddy_vec3 o = w->def.bounds_min;
	for (int k = 1; k < nz - 1; ++k)
		for (int j = 1; j < ny - 1; ++j)
			for (int i = 1; i < nx - 1; ++i) {
				const size_t c = flip_cell(w, i, j, k);
				const double share = sd.any ? (double)flip_solid_open(&sd, c) : 1.0;
				if (type[c] != EDDY_CELL_FLUID || share < 1 || count[c] >= rs->def.min_per_cell)
					continue; /* cut cells are skipped: their open part is uncertain to a cell */
				const size_t sx = 1, sy = (size_t)nx, sz = (size_t)nx * ny;
				/* interior now: cell_type was marked before flip_advect moved
				 * the particles, so a cell the fluid has just left still
				 * reads fluid; a side counts as empty when it holds no
				 * particle now (and is not solid) */
				if (empty(type, count, c - sx) || empty(type, count, c + sx) || empty(type, count, c - sy) ||
				    empty(type, count, c + sy) || empty(type, count, c - sz) || empty(type, count, c + sz))
					continue;
				size_t add = (size_t)(rs->def.min_per_cell - count[c]);
				add = add < nspare - used ? add : nspare - used;
				if (add == 0)
					continue; /* no spare particle: flip_pressure's correction closes the gap */
				float *x = eddy__col(w, COL_X_), *y = eddy__col(w, COL_Y_), *z = eddy__col(w, COL_Z_);
				float *vx = eddy__col(w, COL_VX), *vy = eddy__col(w, COL_VY), *vz = eddy__col(w, COL_VZ);
				const float *u = eddy__col(w, COL_FACE_U), *v = eddy__col(w, COL_FACE_V),
							*wv = eddy__col(w, COL_FACE_W);
				for (size_t a = 0; a < add; ++a) {
					const size_t q = spare[used++];
					const eddy_vec3 p = {(float)(o.x + (i + eddy__rand01(&w->rng)) * h),
					                     (float)(o.y + (j + eddy__rand01(&w->rng)) * h),
					                     (float)(o.z + (k + eddy__rand01(&w->rng)) * h)};
					const eddy_vec3 gv = flip_velocity_at(&grid, u, v, wv, p);
					x[q] = p.x, y[q] = p.y, z[q] = p.z;
					vx[q] = gv.x, vy[q] = gv.y, vz[q] = gv.z;
					for (int m = 0; m < 9; ++m) {
						float *cm = eddy__col(w, COL_APIC_UX + m); /* NULL unless APIC's g2p runs */
						if (cm)
							cm[q] = 0; /* the affine velocity of the old place is not the new one's */
					}
				}
				count[c] += (int)add;
			}
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

const eddy_system_vtable eddy__kind_flip_reseed = {
	.name = "flip_reseed",
	.step = step,
	.default_writes = reseed_writes,
};

eddy_system_id eddy_add_flip_reseed(eddy_world *w, const eddy_flip_reseed_def *def)
{
	const char *sys = "flip_reseed";
	if (!eddy__add_args(w, def, sys))
		return EDDY_NULL_SYSTEM;
	if (def->min_per_cell < 1 || def->max_per_cell <= def->min_per_cell) {
		eddy__fail(w, EDDY_ERR_INVALID, "%s: need 1 <= 'min_per_cell' < 'max_per_cell' (got %d, %d)", sys,
		           def->min_per_cell, def->max_per_cell);
		return EDDY_NULL_SYSTEM;
	}
	reseed *rs = malloc(sizeof *rs);
	if (rs)
		rs->def = *def;
	return eddy__add_system(w, &eddy__kind_flip_reseed, rs, reseed_reads, reseed_writes);
}
