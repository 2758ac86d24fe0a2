/* SPDX-License-Identifier: MIT */
/* flip_p2g: particles to grid (Zhu & Bridson 2005, section 4; Brackbill 1988).
 *
 * Reads: x y z vx vy vz ax ay az (apic_ux .. apic_wz if allocated). Writes: vx vy vz, u v w, u_old v_old w_old,
 * cell_type, flip_phi.
 *   v_p += a_p dt                       (body forces act on the particles, so the
 *                                        FLIP delta below carries pressure only)
 *   u_f  = sum_p W_fp v_p / sum_p W_fp  (W trilinear on each face grid; faces no
 *                                        particle reaches stay 0)
 *   u_old = u                           (pre-solve velocity for G2P's delta)
 *   faces of fluid cells with no weight: the average of known neighbours
 *   (eddy__flip_fill_fluid_faces in sys_flip_extrapolate.c), so a uniform
 *   velocity has no divergence off the grid axes too
 *   cell_type = fluid where a particle is (or within mark_radius cells of a
 *   particle's position), air elsewhere;
 *   flip_phi = 1 - 2 min(rho_c / n0, 2), rho_c = sum_p W_cp the trilinear
 *   particle count at the cell centre (flip.h's flip_particle_density) and
 *   n0 = flip_rest_count, the count the seeding put in a cell: -1 in a cell
 *   at rest density, +1 with no particle near, 1 - 2 f in between, f the
 *   cell's fill fraction (a marker field after Zhu & Bridson, smoothed later
 *   by flip_surface). With mark_radius > 0 the marker is the binary one of
 *   the particle-radius rule instead (-1 in every cell holding or within r of
 *   a particle): the thickened blob is what that option asks for, and a fill
 *   fraction inside a -1 halo would make phi non-monotone there. One particle is
 *   dx^3 / n0 of liquid and the weights W_cp sum to 1, so sum_c (1 - phi_c)/2
 *   dx^3, the volume flip_pressure publishes, is the particles' volume
 *   N dx^3 / n0 (cells above 2 n0 excepted): the surface carries exactly the
 *   liquid the particles do, where a binary marker (-1 in every cell holding
 *   a particle) counts a surface cell holding one particle as full. Values
 *   below -1 (packed cells) are kept down to -3 (f = 2) so that the blur
 *   averages the sampling noise out before the volume's clamp to [0, 1]:
 *   clamping every cell at f = 1 would cut each cell's positive noise and
 *   bias the volume low by a fraction of the noise.
 * APIC (Jiang, Schroeder, Selle, Teran & Stomakhin 2015, "The affine
 * particle-in-cell method", SIGGRAPH, eq. 9 with the trilinear B D^-1 = C of
 * section 5.3): each particle carries one vector c_a per face grid a
 * (columns apic_ux .. apic_wz, written by flip_g2p { transfer = "apic" }),
 * and the splat of component a at face f is
 *   u_f = sum_p W_fp (v_p,a + c_p,a . (x_f - x_p)) / sum_p W_fp.
 * The affine columns are read when they are allocated, which is exactly while
 * an APIC flip_g2p is in the pipeline (their only writer; the columns hold
 * state, so the order of the two systems needs no check): the choice lives
 * in one place and p2g cannot disagree with g2p. They are not in p2g's
 * declared reads, which would allocate them for every FLIP scene.
 * Cells holding a particle are always fluid, so a sheet one particle thick
 * stays on the grid (the role of the particle-radius rule r >= sqrt(3)/2 dx).
 * The splat runs on all threads in slabs of z rows, each slab summing its
 * own samples over the particles in index order (see the loop): results are
 * bit-identical on any number of threads. The sums sum W v and sum W go to
 * u v w and u_old v_old w_old themselves (both are overwritten by the
 * division and its copy), so the splat needs only a byte per face of
 * scratch (which faces a particle reached), not two floats. */
#include "flip.h"

#include <stdlib.h>
#include <string.h>

typedef struct p2g {
	eddy_flip_p2g_def def;
	/* this step's trilinear particle density and which cells hold a
	 * particle, kept for flip_pressure (eddy__flip_p2g_density) */
	float *dens;
	uint8_t *held;
	size_t cap;       /* cells allocated */
	int64_t step;     /* the world step they were computed at, -1 never */
	size_t particles; /* the particle count they were computed with */
} p2g;

static const int p2g_reads[] = {COL_X_, COL_Y_, COL_Z_, COL_VX, COL_VY, COL_VZ, COL_AX, COL_AY, COL_AZ, -1};
static const int p2g_writes[] = {COL_VX,    COL_VY,    COL_VZ,    COL_FACE_U,    COL_FACE_V,   COL_FACE_W,
                                 COL_U_OLD, COL_V_OLD, COL_W_OLD, COL_CELL_TYPE, COL_FLIP_PHI, -1};

eddy_flip_p2g_def eddy_default_flip_p2g_def(void)
{
	eddy_flip_p2g_def d;
	d.mark_radius = 0.0f;
	return d;
}

/* floor and ceil without libm calls (baseline x86-64 has no SSE4.1 round);
 * the clamp keeps the int conversion defined */
static inline int floor_int(float t)
{
	t = !(t >= -1e8f) ? -1e8f : t > 1e8f ? 1e8f : t;
	const int i = (int)t;
	return i - ((float)i > t);
}
static inline int ceil_int(float t) { return -floor_int(-t); }

/* Adds weight * val to sv and weight to sw at the 8 samples around a point
 * of one face grid. sv is the face column itself and sw the face grid's
 * u_old column (written after the splat anyway): no grid-sized scratch. */
static inline void splat(float *restrict sv, float *restrict sw, size_t sy, size_t sz, flip_axis ax, flip_axis ay,
                         flip_axis az, float val, int klo, int khi)
{
	const size_t j[2] = {(size_t)ay.i0 * sy, (size_t)ay.i1 * sy}, k[2] = {(size_t)az.i0 * sz, (size_t)az.i1 * sz};
	const float wy[2] = {1.0f - ay.w1, ay.w1}, wz[2] = {1.0f - az.w1, az.w1}, wx0 = 1.0f - ax.w1, wx1 = ax.w1;
	const int kk[2] = {az.i0, az.i1};
	for (int c = 0; c < 2; ++c)
		for (int b = 0; b < 2 && kk[c] >= klo && kk[c] < khi; ++b) {
			const size_t row = k[c] + j[b];
			const float wyz = wz[c] * wy[b], w0 = wyz * wx0, w1 = wyz * wx1;
			const size_t q0 = row + (size_t)ax.i0, q1 = row + (size_t)ax.i1;
			sv[q0] += w0 * val;
			sw[q0] += w0;
			sv[q1] += w1 * val;
			sw[q1] += w1;
		}
}

/* splat() for APIC: the value at a face is val + c . (x_f - x_p), with
 * d0 = x_f - x_p (m) at each axis's i0 sample and h the spacing (i1 is one
 * sample further; at the clamped top i1 = i0 with weight 0). */
static inline void splat_affine(float *restrict sv, float *restrict sw, size_t sy, size_t sz, flip_axis ax,
                                flip_axis ay, flip_axis az, float val, const float c[3], const float d0[3], float h,
                                int klo, int khi)
{
	const int kk[2] = {az.i0, az.i1};
	const size_t j[2] = {(size_t)ay.i0 * sy, (size_t)ay.i1 * sy}, k[2] = {(size_t)az.i0 * sz, (size_t)az.i1 * sz};
	const float wy[2] = {1.0f - ay.w1, ay.w1}, wz[2] = {1.0f - az.w1, az.w1}, wx0 = 1.0f - ax.w1, wx1 = ax.w1;
	const float ex[2] = {c[0] * d0[0], c[0] * (d0[0] + h)}, ey[2] = {c[1] * d0[1], c[1] * (d0[1] + h)},
				ez[2] = {c[2] * d0[2], c[2] * (d0[2] + h)};
	for (int cc = 0; cc < 2; ++cc)
		for (int b = 0; b < 2 && kk[cc] >= klo && kk[cc] < khi; ++b) {
			const size_t row = k[cc] + j[b];
			const float wyz = wz[cc] * wy[b], w0 = wyz * wx0, w1 = wyz * wx1, v = val + ey[b] + ez[cc];
			const size_t q0 = row + (size_t)ax.i0, q1 = row + (size_t)ax.i1;
			sv[q0] += w0 * (v + ex[0]);
			sw[q0] += w0;
			sv[q1] += w1 * (v + ex[1]);
			sw[q1] += w1;
		}
}

/* x_f - x_p (m) at the i0 sample of an axis with sample offset off (cells);
 * t is the particle's grid coordinate (cells) */
/* The particle's trilinear weights at the cell centres around it (the tent
 * of flip_particle_density in flip.h, constant extension at the sides). */
static inline void splat_density(float *restrict dens, size_t sy, size_t sz, flip_axis ax, flip_axis ay, flip_axis az,
                                 int klo, int khi)
{
	const size_t j[2] = {(size_t)ay.i0 * sy, (size_t)ay.i1 * sy}, k[2] = {(size_t)az.i0 * sz, (size_t)az.i1 * sz};
	const float wy[2] = {1.0f - ay.w1, ay.w1}, wz[2] = {1.0f - az.w1, az.w1}, wx0 = 1.0f - ax.w1, wx1 = ax.w1;
	const int kk[2] = {az.i0, az.i1};
	for (int c = 0; c < 2; ++c)
		for (int b = 0; b < 2 && kk[c] >= klo && kk[c] < khi; ++b) {
			float *row = dens + k[c] + j[b];
			const float wyz = wz[c] * wy[b];
			row[ax.i0] += wyz * wx0;
			row[ax.i1] += wyz * wx1;
		}
}

static inline float face_offset(flip_axis a, float off, float t, float h) { return ((float)a.i0 + off - t) * h; }

static eddy_status step_body(eddy_world *w, eddy_system *s, const eddy_step_context *ctx)
{
	const p2g *pg = s->data;
	const float dt = (float)ctx->dt;
	const float *x = eddy__col(w, COL_X_), *y = eddy__col(w, COL_Y_), *z = eddy__col(w, COL_Z_);
	float *vx = eddy__col(w, COL_VX), *vy = eddy__col(w, COL_VY), *vz = eddy__col(w, COL_VZ);
	const float *ax = eddy__col(w, COL_AX), *ay = eddy__col(w, COL_AY), *az = eddy__col(w, COL_AZ);
	const int nx = w->nx, ny = w->ny, nz = w->nz;
	const float inv = (float)(1.0 / w->def.cell_size);
	const eddy_vec3 o = w->def.bounds_min;
	float *face[3] = {eddy__col(w, COL_FACE_U), eddy__col(w, COL_FACE_V), eddy__col(w, COL_FACE_W)};
	float *old[3] = {eddy__col(w, COL_U_OLD), eddy__col(w, COL_V_OLD), eddy__col(w, COL_W_OLD)};
	const size_t nf[3] = {(size_t)(nx + 1) * ny * nz, (size_t)nx * (ny + 1) * nz, (size_t)nx * ny * (nz + 1)};
	uint8_t *reached[3]; /* per face: a particle's stencil weighs it (sum W > 0) */
	for (int a = 0; a < 3; ++a) {
		reached[a] = eddy__arena_alloc(&w->arena, nf[a]);
		if (!reached[a])
			return eddy__fail(w, EDDY_ERR_NOMEM, "flip_p2g: out of memory for splat weights");
	}
	const size_t nc = (size_t)nx * ny * nz;
	p2g *pm = s->data;
	pm->step = -1;
	if (pm->cap < nc) {
		free(pm->dens);
		free(pm->held);
		pm->dens = malloc(nc * sizeof *pm->dens);
		pm->held = malloc(nc);
		pm->cap = pm->dens && pm->held ? nc : 0;
		if (!pm->cap)
			return eddy__fail(w, EDDY_ERR_NOMEM, "flip_p2g: out of memory for the particle density");
	}
	float *dens = pm->dens; /* particles per cell, trilinear */
	uint8_t *held = pm->held;
	/* one pass over the particles, three face grids: the particle columns are
	 * read once per slab (below) */
	const size_t sx = (size_t)nx, sy = (size_t)ny;
	const flip_grid grid = flip_grid_of(w);
	const size_t np = w->n;
	const float *cu[9];
	for (int q = 0; q < 9; ++q)
		cu[q] = eddy__col(w, COL_APIC_UX + q);
	/* body forces first, per particle (the splat reads the result) */
	const int nt = np > 16384 ? ctx->threads : 1;
#pragma omp parallel for num_threads(nt) if (nt > 1) schedule(static)
	for (size_t i = 0; i < np; ++i) {
		vx[i] += ax[i] * dt;
		vy[i] += ay[i] * dt;
		vz[i] += az[i] * dt;
	}
	uint8_t *type = (uint8_t *)w->columns[COL_CELL_TYPE].data;
	float *phi = eddy__col(w, COL_FLIP_PHI);
	const float inv_n0 = (float)(1.0 / flip_rest_count(w));
	const float r = pg->def.mark_radius, r2 = r * r;
	const float h = (float)w->def.cell_size;
	/* The scatter in slabs of z rows: slab t owns the face and cell rows k in
	 * [klo, khi) of every grid and takes, from each particle in index order,
	 * only the weights landing there. Every sample thus sums the same
	 * particles in the same order whatever the slab count, so the grids are
	 * bit-identical on any number of threads, and no sample has two writers.
	 * A particle reaches rows floor(gz - 1/2) .. floor(gz) + 1, so a slab
	 * skips those with gz outside [klo - 1.5, khi + 1.5) (NaN and positions
	 * off the grid clamp to the slabs holding row 0 or the top row, which take
	 * all below or above; a slab is empty when nz < threads). */
#pragma omp parallel for num_threads(nt) if (nt > 1) schedule(static, 1)
	for (int t = 0; t < nt; ++t) {
		const int klo = nz * t / nt, khi = t == nt - 1 ? nz + 1 : nz * (t + 1) / nt;
		const float zlo = klo == 0 ? -INFINITY : (float)klo - 1.5f, zhi = t == nt - 1 ? INFINITY : (float)khi + 1.5f;
		size_t q0[3], q1[3];
		for (int a = 0; a < 3; ++a) {
			const size_t row = a == 0 ? (sx + 1) * sy : a == 1 ? sx * (sy + 1) : sx * sy;
			const int top = nz + (a == 2);
			q0[a] = (size_t)klo * row;
			q1[a] = (size_t)(khi < top ? khi : top) * row;
			memset(face[a] + q0[a], 0, (q1[a] - q0[a]) * sizeof *face[a]);
			memset(old[a] + q0[a], 0, (q1[a] - q0[a]) * sizeof *old[a]);
		}
		const size_t c0 = (size_t)klo * sx * sy, c1 = (size_t)(khi < nz ? khi : nz) * sx * sy;
		memset(dens + c0, 0, (c1 - c0) * sizeof *dens);
		memset(held + c0, 0, c1 - c0);
		for (size_t i = 0; i < np; ++i) {
			const float gz = (z[i] - o.z) * inv;
			if (gz < zlo || gz >= zhi)
				continue;
			const float pvx = vx[i], pvy = vy[i], pvz = vz[i];
			const flip_axes g = flip_axes_at(&grid, (eddy_vec3){x[i], y[i], z[i]});
			if (cu[0]) {
				const float tx = (x[i] - o.x) * inv, ty = (y[i] - o.y) * inv, tz = gz;
				const float cx[3] = {cu[0][i], cu[1][i], cu[2][i]}, cy[3] = {cu[3][i], cu[4][i], cu[5][i]},
							cz[3] = {cu[6][i], cu[7][i], cu[8][i]};
				const float du[3] = {face_offset(g.fx, 0.0f, tx, h), face_offset(g.cy, 0.5f, ty, h),
				                     face_offset(g.cz, 0.5f, tz, h)};
				const float dv[3] = {face_offset(g.cx, 0.5f, tx, h), face_offset(g.fy, 0.0f, ty, h),
				                     face_offset(g.cz, 0.5f, tz, h)};
				const float dw[3] = {face_offset(g.cx, 0.5f, tx, h), face_offset(g.cy, 0.5f, ty, h),
				                     face_offset(g.fz, 0.0f, tz, h)};
				splat_affine(face[0], old[0], sx + 1, (sx + 1) * sy, g.fx, g.cy, g.cz, pvx, cx, du, h, klo, khi);
				splat_affine(face[1], old[1], sx, sx * (sy + 1), g.cx, g.fy, g.cz, pvy, cy, dv, h, klo, khi);
				splat_affine(face[2], old[2], sx, sx * sy, g.cx, g.cy, g.fz, pvz, cz, dw, h, klo, khi);
			} else {
				splat(face[0], old[0], sx + 1, (sx + 1) * sy, g.fx, g.cy, g.cz, pvx, klo, khi);
				splat(face[1], old[1], sx, sx * (sy + 1), g.cx, g.fy, g.cz, pvy, klo, khi);
				splat(face[2], old[2], sx, sx * sy, g.cx, g.cy, g.fz, pvz, klo, khi);
			}
			splat_density(dens, sx, sx * sy, g.cx, g.cy, g.cz, klo, khi);
		}
		/* this slab's faces (the weighted means; u_old their copy), then its cells */
		for (int a = 0; a < 3; ++a) {
			float *f = face[a], *sw = old[a];
			uint8_t *re = reached[a];
			for (size_t q = q0[a]; q < q1[a]; ++q) {
				re[q] = sw[q] > 0;
				f[q] = sw[q] > 0 ? f[q] / sw[q] : 0.0f;
				sw[q] = f[q];
			}
		}
		/* the fill fraction of every cell from the particle density: one
		 * particle is 1 / n0 of a cell, so sum (1 - phi) / 2 over the cells
		 * is the particles' volume (up to cells above rest density, which
		 * flip_pressure's volume correction drains) */
		for (size_t c = c0; c < c1; ++c) {
			const float f = dens[c] * inv_n0;
			phi[c] = 1.0f - 2.0f * (f < 2.0f ? f : 2.0f);
			type[c] = EDDY_CELL_AIR;
		}
		for (size_t i = 0; i < np; ++i) {
			const float gz = (z[i] - o.z) * inv;
			if (gz < zlo || gz >= zhi)
				continue;
			const float gx = (x[i] - o.x) * inv, gy = (y[i] - o.y) * inv;
			const int kc = flip_cell_index(gz, nz);
			if (kc >= klo && kc < khi) {
				const size_t c = flip_cell(w, flip_cell_index(gx, nx), flip_cell_index(gy, ny), kc);
				type[c] = EDDY_CELL_FLUID;
				held[c] = 1;
				if (r > 0)
					phi[c] = -1.0f; /* the radius rule's binary marker (see the header) */
			}
			/* cells whose centre (i + 1/2) is within r of the particle; at r = 0
			 * that is at most the particle's own cell, marked above */
			if (r <= 0)
				continue;
			int i0 = ceil_int(gx - r - 0.5f), i1 = floor_int(gx + r - 0.5f);
			int j0 = ceil_int(gy - r - 0.5f), j1 = floor_int(gy + r - 0.5f);
			int k0 = ceil_int(gz - r - 0.5f), k1 = floor_int(gz + r - 0.5f);
			i0 = i0 < 0 ? 0 : i0, j0 = j0 < 0 ? 0 : j0, k0 = k0 < klo ? klo : k0;
			i1 = i1 >= nx ? nx - 1 : i1, j1 = j1 >= ny ? ny - 1 : j1, k1 = k1 >= nz ? nz - 1 : k1;
			k1 = k1 >= khi ? khi - 1 : k1;
			for (int kk = k0; kk <= k1; ++kk)
				for (int jj = j0; jj <= j1; ++jj)
					for (int ii = i0; ii <= i1; ++ii) {
						const float ddx = (float)ii + 0.5f - gx, ddy = (float)jj + 0.5f - gy,
									ddz = (float)kk + 0.5f - gz;
						if (ddx * ddx + ddy * ddy + ddz * ddz <= r2) {
							const size_t q = flip_cell(w, ii, jj, kk);
							type[q] = EDDY_CELL_FLUID;
							phi[q] = -1.0f; /* the radius marks the cell full */
						}
					}
		}
	}
	pm->step = w->step;
	pm->particles = np;
	/* faces of fluid cells no particle reached get a velocity before the
	 * solve; u_old keeps 0 there, but no particle's stencil weighs them */
	const uint8_t *const known[3] = {reached[0], reached[1], reached[2]};
	return eddy__flip_fill_fluid_faces(w, face, known);
}

static void destroy(eddy_system *s)
{
	p2g *pg = s->data;
	if (pg) {
		free(pg->dens);
		free(pg->held);
	}
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

const eddy_system_vtable eddy__kind_flip_p2g = {
	.name = "flip_p2g",
	.keeps_solids = true,
	.provides = EDDY_CAP_MAC_GRID,
	.step = step,
	.destroy = destroy,
	.default_writes = p2g_writes,
};

bool eddy__flip_p2g_density(const eddy_world *w, const eddy_system *self, const float **dens, const uint8_t **held)
{
	const p2g *pg = NULL;
	for (int q = 0; q < w->order_count; ++q) {
		const eddy_system *c = &w->slots[w->order[q]];
		if (c == self)
			break;
		if (c->vt->provides & EDDY_CAP_MAC_GRID) {
			pg = c->data;
			continue;
		}
		/* a system between p2g and the caller that moves particles
		 * invalidates them */
		for (int k = 0; pg && k < c->write_count; ++k)
			if (c->writes[k] == COL_X_ || c->writes[k] == COL_Y_ || c->writes[k] == COL_Z_)
				pg = NULL;
	}
	if (!pg || pg->step != w->step || pg->particles != w->n)
		return false;
	*dens = pg->dens;
	*held = pg->held;
	return true;
}

eddy_system_id eddy_add_flip_p2g(eddy_world *w, const eddy_flip_p2g_def *def)
{
	const char *sys = "flip_p2g";
	if (!eddy__add_args(w, def, sys))
		return EDDY_NULL_SYSTEM;
	if (!eddy__check_range(w, sys, "mark_radius", def->mark_radius, 0, 1.5))
		return EDDY_NULL_SYSTEM;
	p2g *pg = calloc(1, sizeof *pg);
	if (pg) {
		pg->def = *def;
		pg->step = -1;
	}
	return eddy__add_system(w, &eddy__kind_flip_p2g, pg, p2g_reads, p2g_writes);
}
