/* SPDX-License-Identifier: MIT */
/* flip_extrapolate: velocity extrapolation into the air (Bridson's book,
 * ch. 4.6; without it particles near the surface interpolate the zeros of
 * faces no particle reached and stall: docs/validation.md hard case 12).
 *
 * Reads: cell_type u v w, the solids' velocities (flip_boundary's, lent) and
 * their distances (the colliders'). Writes: u v w.
 *   Known faces: a fluid or solid cell on a side, or on the domain's sides,
 *   except a face wholly inside a solid that holds its velocity.
 *   Layer l = 1..layers: every unknown face with known neighbours (6-connected
 *   in its own face grid) takes their average and becomes known. A layer is
 *   a vectorised sweep of the grid's flag bytes on all threads (see
 *   extrapolate_grid): the same result on any thread count.
 * Faces wholly inside a solid are filled as air is, then take the solid's
 * normal velocity (closed_faces: free slip along solids, Bridson's book,
 * ch. 5: "extrapolate, then replace the normal component") where the water
 * moves into the solid, and keep the water's where it moves away from it
 * (a solid cannot pull); cut faces keep flip_pressure's values. A domain
 * side beside an air cell is extrapolated too, then
 * kept only where it carries water away from the side (else 0): a particle
 * beside a fluid cell that left the side (flip_pressure) interpolates it,
 * and held at 0 it would hold the particle back. Open sides
 * (flip_boundary's open_sides) keep the extrapolated velocity either way,
 * except where a collider closes them. RK2 advection at CFL number C samples up to C + 1 cells
 * beyond the fluid: layers should be at least that. */
#include "flip.h"

#include <math.h>
#include <stddef.h>
#include <stdlib.h>
#include <string.h>

typedef struct extrapolate {
	eddy_flip_extrapolate_def def;
} extrapolate;

static const int extrap_reads[] = {COL_CELL_TYPE, COL_FACE_U, COL_FACE_V, COL_FACE_W, -1};
static const int extrap_writes[] = {COL_FACE_U, COL_FACE_V, COL_FACE_W, -1};

eddy_flip_extrapolate_def eddy_default_flip_extrapolate_def(void)
{
	eddy_flip_extrapolate_def d;
	d.layers = 6;
	return d;
}

enum { UNKNOWN = 255 }; /* layers are at most 64 */

/* (i, j, k) of face f. The divisions dominate the fill's rounds, and a
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

/* Face f's value from its neighbours known before layer l (flag < l), in
 * the order -x, +x, -y, +y, -z, +z; false when it has none. Summed in
 * double: equal neighbours give exactly their value (in float, (v + v + v)
 * / 3 need not be v), so a uniform field extrapolates to itself and G2P's
 * FLIP delta stays exactly 0. */
static inline bool face_average(const float *u, const uint8_t *layer, const int m[3], const size_t st[3],
                                const int c[3], size_t f, int l, float *out)
{
	double sum = 0;
	int cnt = 0;
	for (int d = 0; d < 3; ++d) {
		if (c[d] > 0 && layer[f - st[d]] < l) {
			sum += (double)u[f - st[d]];
			cnt++;
		}
		if (c[d] + 1 < m[d] && layer[f + st[d]] < l) {
			sum += (double)u[f + st[d]];
			cnt++;
		}
	}
	if (cnt)
		*out = (float)(sum / cnt);
	return cnt > 0;
}

/* One face grid: m faces per axis (strides st), layer flags (0 known,
 * UNKNOWN), hit: a byte per face. Layer l: every unknown face with a
 * neighbour known before it (flag < l) takes their average and flag l.
 * A pass reads flags and known values and writes only the values of this
 * layer's faces (unknown until the pass ends, so no one reads them) and
 * their hit bytes; the flags are set in a second pass. Both run on all
 * threads in z slabs, each face one thread's: the same result on any thread
 * count (and as the serial frontier sweep this replaces: its layer l was the
 * unknown faces next to layer l - 1, the same set, averaged in the same
 * neighbour order). A row inside the grid is tested branch-free, which the
 * compiler vectorises: a sweep costs about a byte load per face and
 * neighbour, and no frontier list (16 bytes per face) is kept. */
static void extrapolate_grid(float *u, uint8_t *restrict layer, uint8_t *restrict hit, const int m[3],
                             const size_t st[3], int layers, int nt)
{
	for (int l = 1; l <= layers; ++l) {
		long filled = 0;
		const uint8_t lb = (uint8_t)l;
#pragma omp parallel for num_threads(nt) if (nt > 1) schedule(static) reduction(+ : filled)
		for (int k = 0; k < m[2]; ++k)
			for (int j = 0; j < m[1]; ++j) {
				const size_t row = st[1] * (size_t)j + st[2] * (size_t)k;
				uint8_t *restrict h = hit + row;
				const uint8_t *L = layer + row;
				const bool inner = j > 0 && j + 1 < m[1] && k > 0 && k + 1 < m[2] && m[0] > 2;
				if (inner) {
					/* interior of the row: all six neighbours exist; signed
					 * strides, as L[i - sy] lies before the row's start */
					const ptrdiff_t sy = (ptrdiff_t)st[1], sz = (ptrdiff_t)st[2];
					for (int i = 1; i < m[0] - 1; ++i)
						h[i] = (uint8_t)((L[i] == UNKNOWN) & ((L[i - 1] < lb) | (L[i + 1] < lb) | (L[i - sy] < lb) |
						                                      (L[i + sy] < lb) | (L[i - sz] < lb) | (L[i + sz] < lb)));
					for (int i = 0; i < m[0]; i += m[0] - 1) { /* the row's two ends */
						const int c[3] = {i, j, k};
						float v;
						h[i] = L[i] == UNKNOWN && face_average(u, layer, m, st, c, row + (size_t)i, l, &v);
					}
				} else {
					for (int i = 0; i < m[0]; ++i) {
						const int c[3] = {i, j, k};
						float v;
						h[i] = L[i] == UNKNOWN && face_average(u, layer, m, st, c, row + (size_t)i, l, &v);
					}
				}
				for (int i = 0; i < m[0]; ++i)
					if (h[i]) {
						const int c[3] = {i, j, k};
						float v = 0;
						face_average(u, layer, m, st, c, row + (size_t)i, l, &v);
						u[row + (size_t)i] = v;
						filled++;
					}
			}
		if (filled == 0)
			break;
		const long nf = (long)(st[2] * (size_t)m[2]);
#pragma omp parallel for num_threads(nt) if (nt > 1) schedule(static)
		for (long f = 0; f < nf; ++f)
			layer[f] = hit[f] ? lb : layer[f];
	}
}

/* ---- before the solve: faces of fluid cells no particle reached ----------
 * (eddy__flip_fill_fluid_faces, called by flip_p2g; declared in flip.h)
 *
 * A fluid cell is one holding a particle (or within mark_radius of one), but
 * the trilinear splat gives a face weight only if some particle's stencil
 * reaches it with weight > 0. A particle exactly on a grid plane (frac = 0,
 * which float positions hit more often than one would think: a blob moving
 * at 0.7 m/s with dt = 0.01 s and dx = 0.0125 m puts a whole layer on one) gives
 * its cell's far face no weight; a cell marked by mark_radius may have no
 * reached face at all. Such a face stays 0, so a uniform velocity V shows a
 * divergence D = |V_a| dx in that cell, the solve answers it with a real
 * pressure, and the momentum, the shape and the PCG's zero work are lost
 * (whether a flight meets a plane depends on its velocity, step and offset;
 * measured: max |D| = 0.79 |V| before, round-off after). Velocity is known
 * only where particles reached, and unknown
 * velocities are extrapolated from known ones (Bridson, "Fluid Simulation for
 * Computer Graphics", 2nd ed.: the transfer's "valid" flags and the
 * extrapolation of the water chapter; Zhu & Bridson 2005, section 4); the
 * pressure solve needs the faces of fluid cells, so those are extrapolated
 * here, before it, and the air beyond after it (flip_extrapolate).
 *   Needed: faces with weight 0 and a fluid cell on a side (domain sides
 *   excluded: flip_boundary sets them).
 *   Round l = 1, 2, ...: every needed face with a face known before the
 *   round among its 6 neighbours in its own face grid takes their average
 *   and becomes known; until none is left or a round fills none.
 * Every needed face is reached: a fluid cell's own particle reaches one of
 * its two faces on each axis (trilinear weights (1 - f, f), the row weight is
 * >= 1/2), the other is its neighbour along the axis; mark_radius cells lie in
 * a ball around a particle, whose lattice cells are face-connected to the
 * particle's cell, so their faces chain to it through needed faces.
 * The average is summed in double: equal neighbours give exactly their value,
 * so the filled faces add no round-off of their own (a uniform field's D is
 * then only the round-off of flip_p2g's float weighted means, ~1e-6 |V|). */
eddy_status eddy__flip_fill_fluid_faces(eddy_world *w, float *const face[3], const uint8_t *const reached[3])
{
	const int n[3] = {w->nx, w->ny, w->nz};
	const uint8_t *type = (const uint8_t *)w->columns[COL_CELL_TYPE].data;
	for (int a = 0; a < 3; ++a) {
		int m[3];
		size_t st[3];
		for (int d = 0; d < 3; ++d)
			m[d] = n[d] + (d == a);
		st[0] = 1;
		st[1] = (size_t)m[0];
		st[2] = (size_t)m[0] * (size_t)m[1];
		const size_t cst = a == 0 ? 1 : a == 1 ? (size_t)n[0] : (size_t)n[0] * (size_t)n[1];
		float *u = face[a];
		const uint8_t *wt = reached[a];
		/* needed faces: interior, weight 0, a fluid cell on a side. Face
		 * (i, j, k) of grid a lies between cell (i, j, k) and the one below
		 * it on axis a, so a scan over cells with c[a] >= 1 visits each
		 * interior face once, in increasing face index; it reads the cell
		 * types first (bytes, mostly air) and the weight only next to fluid */
		size_t nneed = 0, cap = 0;
		size_t *need = NULL;
		for (int pass = 0; pass < 2; ++pass) {
			for (int k = a == 2; k < n[2]; ++k)
				for (int j = a == 1; j < n[1]; ++j)
					for (int i = a == 0; i < n[0]; ++i) {
						const size_t cl = flip_cell(w, i, j, k);
						if (type[cl] != EDDY_CELL_FLUID && type[cl - cst] != EDDY_CELL_FLUID)
							continue;
						const size_t f = (size_t)i + st[1] * (size_t)j + st[2] * (size_t)k;
						if (wt[f])
							continue;
						if (pass)
							need[nneed] = f;
						nneed++;
					}
			if (pass || nneed == 0)
				break;
			/* second pass stores them: the count is usually 0, so no
			 * grid-sized list is allocated in the common case */
			cap = nneed;
			need = eddy__arena_alloc(&w->arena, cap * (sizeof *need + sizeof(float) + sizeof(int)) + 8);
			if (!need)
				return eddy__fail(w, EDDY_ERR_NOMEM, "flip_p2g: out of memory for the face fill");
			nneed = 0;
		}
		if (nneed == 0)
			continue;
		float *val = (float *)(need + cap);
		int *done = (int *)(val + cap); /* round that filled a needed face, 0 not yet */
		memset(done, 0, cap * sizeof *done);
		/* known: weight > 0, or a needed face filled in an earlier round;
		 * needed faces are found in the sorted list by bisection (few) */
		size_t left = nneed;
		for (int round = 1; left > 0; ++round) {
			size_t filled = 0;
			for (size_t q = 0; q < nneed; ++q) {
				if (done[q])
					continue;
				const size_t f = need[q];
				size_t c[3];
				face_coords(f, st, m[1], st[2] * (size_t)m[2] <= UINT32_MAX, c);
				double sum = 0;
				int cnt = 0;
				for (int d = 0; d < 3; ++d)
					for (int sgn = -1; sgn <= 1; sgn += 2) {
						if (sgn < 0 ? c[d] == 0 : c[d] + 1 >= (size_t)m[d])
							continue;
						const size_t g = sgn < 0 ? f - st[d] : f + st[d];
						bool known = wt[g] != 0;
						if (!known) {
							size_t lo = 0, hi = nneed; /* need[] is increasing */
							while (lo < hi) {
								const size_t mid = lo + (hi - lo) / 2;
								if (need[mid] < g)
									lo = mid + 1;
								else
									hi = mid;
							}
							known = lo < nneed && need[lo] == g && done[lo] && done[lo] < round;
						}
						if (known) {
							sum += (double)u[g];
							cnt++;
						}
					}
				if (cnt) {
					val[q] = (float)(sum / cnt);
					done[q] = round;
					filled++;
				}
			}
			if (filled == 0)
				break; /* cannot happen (see above); such faces keep their 0 */
			for (size_t q = 0; q < nneed; ++q)
				if (done[q] == round)
					u[need[q]] = val[q];
			left -= filled;
		}
	}
	return EDDY_OK;
}

/* Layers of closed faces closed_faces corrects: a particle's stencil (G2P,
 * RK2 advection at CFL up to 1) reaches faces a cell into a solid, so the
 * second layer and on are the water's velocity as filled. Each corrected
 * face queries the colliders' distances six times. */
#define CLOSED_REACH 2

/* near[c] = 1 where a fluid cell lies within NEAR_CELLS cells of cell c
 * along every axis (a box dilation, one axis at a time): the faces a
 * particle's stencil can read, a particle in a cut cell typed solid
 * included. tmp: scratch of the same size. */
#define NEAR_CELLS 2
static void near_fluid_cells(const eddy_world *w, const uint8_t *type, uint8_t *near, uint8_t *tmp, int nt)
{
	const int n[3] = {w->nx, w->ny, w->nz};
	const size_t st[3] = {1, (size_t)n[0], (size_t)n[0] * (size_t)n[1]};
	const long nc = (long)n[0] * n[1] * n[2];
#pragma omp parallel for num_threads(nt) if (nt > 1) schedule(static)
	for (long c = 0; c < nc; ++c)
		near[c] = type[c] == EDDY_CELL_FLUID;
	for (int a = 0; a < 3; ++a) {
		uint8_t *src = a % 2 ? tmp : near, *dst = a % 2 ? near : tmp;
#pragma omp parallel for num_threads(nt) if (nt > 1) schedule(static)
		for (long c = 0; c < nc; ++c) {
			const int i = (int)((size_t)c / st[a] % (size_t)n[a]);
			uint8_t v = 0;
			for (int d = -NEAR_CELLS; d <= NEAR_CELLS && !v; ++d)
				if (i + d >= 0 && i + d < n[a])
					v = src[(size_t)((long)c + (long)d * (long)st[a])];
			dst[c] = v;
		}
	}
	memcpy(near, tmp, (size_t)nc); /* three passes ended in tmp */
}

/* m, the solids' signed distance at p: the least over the colliders col[0 .. nc - 1] */
static float solid_distance(const eddy_system *const *col, int nc, eddy_vec3 p)
{
	float best = INFINITY;
	for (int q = 0; q < nc; ++q) {
		const float d = col[q]->vt->distance(col[q], p);
		best = d < best ? d : best;
	}
	return best;
}

/* A closed face (all in a solid) that this step filled from the water
 * beside it keeps the water's velocity along the solid's surface and takes
 * the solid's across it: with e the face's velocity vector (its own
 * component, the other two averaged from the four faces of each other grid
 * around it), V the solid's (flip_boundary's normal velocities, likewise)
 * and n the solids' distance gradient at the face, its component becomes
 * e_a - ((e - V) . n) n_a: free slip along a wall, the wall's velocity
 * across it. The water's velocity alone there (n ignored) let a stirring
 * paddle's faces push less; the solid's alone made every wall drag. Where
 * (e - V) . n > 0 the water leaves the solid faster than its surface
 * follows, and a solid cannot pull: the face keeps e. Taking V there, the
 * faces inside a gate lifted along a pool's face held, beside its lower
 * edge (where n is that edge's), the gate's speed upward, and the water
 * within half a cell of the gate, interpolating them, was carried up. A
 * face of a fluid cell is the exception: the pressure solve held it at V
 * (and gave the water's velocity to those air could follow). A
 * closed face flip_pressure gave the water's velocity (water leaving a wall
 * with air in reach) is not filled: it keeps that. Values
 * are computed from the filled fields into out[a] and written after, so
 * the result does not depend on the order. */
static void closed_faces(const eddy_world *w, const uint8_t *type, const uint8_t *near, const flip_solid *sd,
                         float *const face[3], uint8_t *const layer[3], size_t st[3][3], int m[3][3], int layers,
                         float *const out[3], int nt)
{
	const int n[3] = {w->nx, w->ny, w->nz};
	const double h = w->def.cell_size;
	const eddy_system *col[EDDY_MAX_SYSTEMS];
	int nc = 0;
	eddy_system_iter it = eddy__systems(w, EDDY_CAP_COLLIDER);
	for (const eddy_system *c; (c = eddy__systems_next(&it));)
		col[nc++] = c;
	const double org[3] = {w->def.bounds_min.x, w->def.bounds_min.y, w->def.bounds_min.z};
	const int reach = layers < CLOSED_REACH ? layers : CLOSED_REACH;
	for (int a = 0; a < 3; ++a) {
		const uint8_t *la = layer[a];
		float *oa = out[a];
		const int ma[3] = {m[a][0], m[a][1], m[a][2]};
		const size_t sa[3] = {st[a][0], st[a][1], st[a][2]};
#pragma omp parallel for num_threads(nt) if (nt > 1) schedule(static)
		for (int k = 0; k < ma[2]; ++k)
			for (int j = 0; j < ma[1]; ++j)
				for (int i = 0; i < ma[0]; ++i) {
					const size_t f = (size_t)i + sa[1] * (size_t)j + sa[2] * (size_t)k;
					const int c[3] = {i, j, k};
					oa[f] = face[a][f];
					if (la[f] == 0 || la[f] > reach || c[a] == 0 || c[a] == n[a] || flip_solid_wt(sd, a, f) != 0 ||
					    !(near[flip_cell(w, c[0] - (a == 0), c[1] - (a == 1), c[2] - (a == 2))] |
					      (c[a] < n[a] ? near[flip_cell(w, c[0], c[1], c[2])] : 0)))
						continue;
					const bool fluid_side =
						type[flip_cell(w, c[0] - (a == 0), c[1] - (a == 1), c[2] - (a == 2))] == EDDY_CELL_FLUID ||
						type[flip_cell(w, c[0], c[1], c[2])] == EDDY_CELL_FLUID;
					double e[3], v[3];
					e[a] = face[a][f];
					v[a] = flip_solid_vel(sd, a, f);
					for (int b = 0; b < 3; ++b) {
						if (b == a)
							continue;
						double se = 0, sv = 0;
						for (int da = -1; da <= 0; ++da)
							for (int db = 0; db <= 1; ++db) {
								int g[3] = {i, j, k};
								g[a] += da;
								g[b] += db;
								const size_t fb = (size_t)g[0] + st[b][1] * (size_t)g[1] + st[b][2] * (size_t)g[2];
								se += face[b][fb];
								sv += flip_solid_vel(sd, b, fb);
							}
						e[b] = 0.25 * se, v[b] = 0.25 * sv;
					}
					/* the face's centre and the distance's gradient there */
					double p[3];
					for (int d = 0; d < 3; ++d)
						p[d] = org[d] + ((double)c[d] + (d == a ? 0.0 : 0.5)) * h;
					double g[3], len2 = 0;
					for (int d = 0; d < 3; ++d) {
						double q1[3] = {p[0], p[1], p[2]}, q0[3] = {p[0], p[1], p[2]};
						q1[d] += 0.5 * h, q0[d] -= 0.5 * h;
						g[d] = (double)solid_distance(col, nc, (eddy_vec3){(float)q1[0], (float)q1[1], (float)q1[2]}) -
						       (double)solid_distance(col, nc, (eddy_vec3){(float)q0[0], (float)q0[1], (float)q0[2]});
						len2 += g[d] * g[d];
					}
					if (!(len2 > 0) || !isfinite(len2))
						continue;
					const double inv = 1.0 / sqrt(len2);
					double dn = 0;
					for (int d = 0; d < 3; ++d)
						dn += (e[d] - v[d]) * g[d] * inv;
					if (dn > 0 && !fluid_side)
						continue; /* separating: the water's own velocity */
					oa[f] = (float)(e[a] - dn * g[a] * inv);
				}
	}
	for (int a = 0; a < 3; ++a) {
		const size_t nf = st[a][2] * (size_t)m[a][2];
		memcpy(face[a], out[a], nf * sizeof *face[a]);
	}
}

static eddy_status step_body(eddy_world *w, eddy_system *s, const eddy_step_context *ctx)
{
	const extrapolate *ex = s->data;
	const int n[3] = {w->nx, w->ny, w->nz};
	const uint8_t *type = (const uint8_t *)w->columns[COL_CELL_TYPE].data;
	float *face[3] = {eddy__col(w, COL_FACE_U), eddy__col(w, COL_FACE_V), eddy__col(w, COL_FACE_W)};
	int m[3][3];
	size_t st[3][3];
	uint8_t *layer[3], *hit = NULL;
	size_t nfmax = 0;
	const size_t ncell = (size_t)n[0] * n[1] * n[2];
	const int nt = ncell > 32768 ? ctx->threads : 1;
	/* the solid velocities of this step (flip_boundary's, lent) */
	flip_solid sd;
	if (!eddy__flip_solid_for(w, s, ctx->dt, &sd))
		return eddy__fail(w, EDDY_ERR_NOMEM, "flip_extrapolate: out of memory");
	const bool solids = sd.any, open_sides = sd.open_sides;
	for (int a = 0; a < 3; ++a) {
		for (int d = 0; d < 3; ++d)
			m[a][d] = n[d] + (d == a);
		st[a][0] = 1;
		st[a][1] = (size_t)m[a][0];
		st[a][2] = (size_t)m[a][0] * (size_t)m[a][1];
		const size_t nf = st[a][2] * (size_t)m[a][2];
		layer[a] = eddy__arena_alloc(&w->arena, nf);
		nfmax = nf > nfmax ? nf : nfmax;
		if (!layer[a])
			return eddy__fail(w, EDDY_ERR_NOMEM, "flip_extrapolate: out of memory");
		uint8_t *la = layer[a];
		const int ma[3] = {m[a][0], m[a][1], m[a][2]};
		const size_t sa[3] = {st[a][0], st[a][1], st[a][2]};
#pragma omp parallel for num_threads(nt) if (nt > 1) schedule(static)
		for (int k = 0; k < ma[2]; ++k)
			for (int j = 0; j < ma[1]; ++j)
				for (int i = 0; i < ma[0]; ++i) {
					const int c[3] = {i, j, k};
					const size_t f = (size_t)i + sa[1] * (size_t)j + sa[2] * (size_t)k;
					/* a domain side is known beside fluid, extrapolated beside
					 * air and then held (below) */
					bool known = (c[a] == 0 || c[a] == n[a]) &&
					             type[flip_cell(w, c[0] - (c[a] == n[a] && a == 0), c[1] - (c[a] == n[a] && a == 1),
					                            c[2] - (c[a] == n[a] && a == 2))] != EDDY_CELL_AIR;
					if (!known && c[a] > 0 && c[a] < n[a]) {
						int lo[3] = {i, j, k};
						lo[a]--;
						const uint8_t tl = type[flip_cell(w, lo[0], lo[1], lo[2])], th = type[flip_cell(w, i, j, k)];
						/* a solid cell's face to air: extrapolated, then held (below) */
						known = (tl != EDDY_CELL_AIR || th != EDDY_CELL_AIR) &&
						        !(solids && ((tl == EDDY_CELL_SOLID && th == EDDY_CELL_AIR) ||
						                     (th == EDDY_CELL_SOLID && tl == EDDY_CELL_AIR)));
						/* a closed face (all in the solid) holding the solid's
						 * velocity: filled from the water beside it (closed_faces) */
						if (known && solids && flip_solid_wt(&sd, a, f) == 0 && face[a][f] == flip_solid_vel(&sd, a, f))
							known = false;
					}
					la[f] = known ? 0 : UNKNOWN;
				}
	}
	hit = eddy__arena_alloc(&w->arena, nfmax);
	if (!hit)
		return eddy__fail(w, EDDY_ERR_NOMEM, "flip_extrapolate: out of memory");
	for (int a = 0; a < 3; ++a)
		extrapolate_grid(face[a], layer[a], hit, m[a], st[a], ex->def.layers, nt);
	if (solids) {
		float *out[3];
		for (int a = 0; a < 3; ++a) {
			out[a] = eddy__arena_alloc(&w->arena, st[a][2] * (size_t)m[a][2] * sizeof *out[a]);
			if (!out[a])
				return eddy__fail(w, EDDY_ERR_NOMEM, "flip_extrapolate: out of memory");
		}
		const size_t ncell3 = (size_t)n[0] * n[1] * n[2];
		uint8_t *near = eddy__arena_alloc(&w->arena, ncell3), *tmp = eddy__arena_alloc(&w->arena, ncell3);
		if (!near || !tmp)
			return eddy__fail(w, EDDY_ERR_NOMEM, "flip_extrapolate: out of memory");
		near_fluid_cells(w, type, near, tmp, nt);
		closed_faces(w, type, near, &sd, face, layer, st, m, ex->def.layers, out, nt);
	}
	for (int a = 0; a < 3; ++a) {
		/* the domain's sides beside air: the water's velocity where it
		 * leaves the side, the side's 0 where it would go through (header) */
		float *u = face[a];
		const uint8_t *la = layer[a];
		const int ma[3] = {m[a][0], m[a][1], m[a][2]};
		const size_t sa[3] = {st[a][0], st[a][1], st[a][2]};
		const int b1 = (a + 1) % 3, b2 = (a + 2) % 3;
		if (solids) /* a solid cell's faces to air likewise, against the solid's velocity */
#pragma omp parallel for num_threads(nt) if (nt > 1) schedule(static)
			for (int k = 0; k < ma[2]; ++k)
				for (int j = 0; j < ma[1]; ++j)
					for (int i = 0; i < ma[0]; ++i) {
						const int c[3] = {i, j, k};
						if (c[a] == 0 || c[a] == n[a])
							continue;
						int lo[3] = {i, j, k};
						lo[a]--;
						const uint8_t tl = type[flip_cell(w, lo[0], lo[1], lo[2])], th = type[flip_cell(w, i, j, k)];
						const bool solid_lo = tl == EDDY_CELL_SOLID && th == EDDY_CELL_AIR,
								   solid_hi = th == EDDY_CELL_SOLID && tl == EDDY_CELL_AIR;
						if (!solid_lo && !solid_hi)
							continue;
						const size_t f = (size_t)i + sa[1] * (size_t)j + sa[2] * (size_t)k;
						const float vs = flip_solid_vel(&sd, a, f);
						if (la[f] == UNKNOWN || (solid_lo ? u[f] < vs : u[f] > vs))
							u[f] = vs;
					}
		for (int side = 0; side < 2; ++side)
			for (int q2 = 0; q2 < ma[b2]; ++q2)
				for (int q1 = 0; q1 < ma[b1]; ++q1) {
					int c[3];
					c[a] = side ? n[a] : 0;
					c[b1] = q1;
					c[b2] = q2;
					const size_t f = (size_t)c[0] + sa[1] * (size_t)c[1] + sa[2] * (size_t)c[2];
					if (la[f] == 0)
						continue; /* beside fluid or solid: flip_boundary's, flip_pressure's */
					if (open_sides && flip_solid_wt(&sd, a, f) > 0)
						continue; /* an open side: no wall, the extrapolated velocity */
					if (la[f] == UNKNOWN || (side ? u[f] > 0 : u[f] < 0))
						u[f] = 0;
				}
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

const eddy_system_vtable eddy__kind_flip_extrapolate = {
	.name = "flip_extrapolate",
	.keeps_solids = true,
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
	return eddy__add_system(w, &eddy__kind_flip_extrapolate, ex, extrap_reads, extrap_writes);
}
