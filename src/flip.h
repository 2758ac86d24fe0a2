/* SPDX-License-Identifier: MIT */
/* Internals shared by the FLIP systems (sys_flip_*.c): MAC-grid indexing,
 * trilinear stencils on the staggered grids, and the linear-solver interface
 * (flip_pcg.c, flip_hypre.c, flip_cholmod.c).
 *
 * Grid layout: cell (i, j, k) spans [i, i+1] dx from the world's lower corner;
 * u lives on x-faces at (i, j+1/2, k+1/2) dx, v on y-faces, w on z-faces.
 * Cell index i + nx (j + ny k); the x-face array has nx+1 per row, etc. */
#ifndef EDDY_FLIP_H
#define EDDY_FLIP_H

#include "systems.h"

#include <string.h>

/* The calling thread's place in its OpenMP team and the team's size, for the
 * solvers' parallel regions that split work by thread (flip_pcg.c,
 * flip_mg.c). */
#ifdef _OPENMP
#include <omp.h>
#define TEAM_RANK omp_get_thread_num()
#define TEAM_SIZE omp_get_num_threads()
#else /* a build without OpenMP (the fuzzer's) runs the team of one */
#define TEAM_RANK 0
#define TEAM_SIZE 1
#endif

static inline size_t flip_cell(const eddy_world *w, int i, int j, int k)
{
	return (size_t)i + (size_t)w->nx * ((size_t)j + (size_t)w->ny * (size_t)k);
}
static inline size_t flip_fu(const eddy_world *w, int i, int j, int k)
{
	return (size_t)i + (size_t)(w->nx + 1) * ((size_t)j + (size_t)w->ny * (size_t)k);
}
static inline size_t flip_fv(const eddy_world *w, int i, int j, int k)
{
	return (size_t)i + (size_t)w->nx * ((size_t)j + (size_t)(w->ny + 1) * (size_t)k);
}
static inline size_t flip_fw(const eddy_world *w, int i, int j, int k)
{
	return (size_t)i + (size_t)w->nx * ((size_t)j + (size_t)w->ny * (size_t)k);
}

/* Index of the cell holding grid coordinate t (in cells), clamped to [0, n). */
static inline int flip_cell_index(float t, int n)
{
	if (!(t >= 0.0f))
		return 0; /* also NaN */
	if (t >= (float)n)
		return n - 1;
	const int i = (int)t;
	return i < n ? i : n - 1;
}

/* One axis of a trilinear stencil: samples at (s + off) dx for s in [0, n);
 * t is the particle coordinate in cells. Outside the sample range the nearest
 * sample takes the whole weight (constant extension), so weights stay a
 * partition of unity everywhere. */
typedef struct flip_axis {
	int i0, i1;
	float w1; /* weight of i1; i0 gets 1 - w1 */
} flip_axis;

static inline flip_axis flip_axis_at(float t, float off, int n)
{
	flip_axis a;
	const float s = t - off, top = (float)(n - 1);
	/* Clamping s to the sample range [0, n-1] first gives the constant
	 * extension (below 0: i = 0 and weight 0; from n-1 up: i = n-1, weight 0),
	 * maps NaN to the low end and keeps the int conversion defined; inside the
	 * range it is the identity, and truncation is floor since sc >= 0 (no libm
	 * call, no branches). */
	const float sc = s >= 0.0f ? (s < top ? s : top) : 0.0f;
	const int i = (int)sc;
	a.i0 = i;
	a.i1 = i + (i < n - 1);
	a.w1 = sc - (float)i;
	return a;
}

/* The stencil of a point (in cells from the grid origin) on face grid `axis`
 * (0 = u, 1 = v, 2 = w): 8 face indices and weights. */
typedef struct flip_stencil {
	size_t idx[8];
	float wt[8];
} flip_stencil;

static inline void flip_stencil_at(const eddy_world *w, int axis, float gx, float gy, float gz, flip_stencil *st)
{
	const int nx = w->nx, ny = w->ny, nz = w->nz;
	const flip_axis ax = flip_axis_at(gx, axis == 0 ? 0.0f : 0.5f, nx + (axis == 0));
	const flip_axis ay = flip_axis_at(gy, axis == 1 ? 0.0f : 0.5f, ny + (axis == 1));
	const flip_axis az = flip_axis_at(gz, axis == 2 ? 0.0f : 0.5f, nz + (axis == 2));
	const size_t sx = 1, sy = (size_t)(nx + (axis == 0)), sz = sy * (size_t)(ny + (axis == 1));
	int n = 0;
	for (int c = 0; c < 2; ++c) {
		const size_t kk = (size_t)(c ? az.i1 : az.i0) * sz;
		const float wz = c ? az.w1 : 1.0f - az.w1;
		for (int b = 0; b < 2; ++b) {
			const size_t jj = (size_t)(b ? ay.i1 : ay.i0) * sy;
			const float wy = b ? ay.w1 : 1.0f - ay.w1;
			st->idx[n] = kk + jj + (size_t)ax.i0 * sx;
			st->wt[n++] = wz * wy * (1.0f - ax.w1);
			st->idx[n] = kk + jj + (size_t)ax.i1 * sx;
			st->wt[n++] = wz * wy * ax.w1;
		}
	}
}

static inline float flip_interp(const float *f, const flip_stencil *st)
{
	float s = 0;
	for (int q = 0; q < 8; ++q)
		s += st->wt[q] * f[st->idx[q]];
	return s;
}

/* Trilinear sample of face grid f (row strides sy, sz) from its three axes. */
static inline float flip_trilinear(const float *f, size_t sy, size_t sz, flip_axis ax, flip_axis ay, flip_axis az)
{
	const size_t j0 = (size_t)ay.i0 * sy, j1 = (size_t)ay.i1 * sy, k0 = (size_t)az.i0 * sz, k1 = (size_t)az.i1 * sz;
	const size_t i0 = (size_t)ax.i0, i1 = (size_t)ax.i1;
	const float c00 = f[k0 + j0 + i0] + ax.w1 * (f[k0 + j0 + i1] - f[k0 + j0 + i0]);
	const float c01 = f[k0 + j1 + i0] + ax.w1 * (f[k0 + j1 + i1] - f[k0 + j1 + i0]);
	const float c10 = f[k1 + j0 + i0] + ax.w1 * (f[k1 + j0 + i1] - f[k1 + j0 + i0]);
	const float c11 = f[k1 + j1 + i0] + ax.w1 * (f[k1 + j1 + i1] - f[k1 + j1 + i0]);
	const float c0 = c00 + ay.w1 * (c01 - c00), c1 = c10 + ay.w1 * (c11 - c10);
	return c0 + az.w1 * (c1 - c0);
}

/* The pipeline has a flip_boundary with closed sides: only then are the
 * box's faces walls where the grid sticks out past them (flip_grid's top);
 * without one there are no solid faces, and the grid's sides are the walls
 * for every FLIP system alike. */
bool eddy__flip_box_walls(const eddy_world *w);

/* The grid's shape copied into locals: particle loops store floats, which
 * could alias the world's float fields, so reading them through the world
 * pointer would reload them for every particle. */
typedef struct flip_grid {
	int nx, ny, nz;
	float inv;   /* 1/m, 1 / cell_size */
	eddy_vec3 o; /* m, grid origin */
	/* in cells from o, per axis: where the wall is. The grid rounds the
	 * world's box up to whole cells (columns.c), so on an axis whose extent
	 * is not a whole number of cells the last cells stick out past the box,
	 * and there the box's face, not the grid's side, is the wall the scene
	 * asked for: flip_boundary cuts those cells as a still solid beyond it.
	 * The grid's side (n) on the other axes (the box's to within a
	 * thousandth of a cell, where openings count as closed), with open sides
	 * (water past the box leaves the world there) and without a
	 * flip_boundary (eddy__flip_box_walls). */
	float top[3];
} flip_grid;

static inline flip_grid flip_grid_of(const eddy_world *w)
{
	flip_grid g = {w->nx, w->ny, w->nz, (float)(1.0 / w->def.cell_size), w->def.bounds_min, {0, 0, 0}};
	const double h = w->def.cell_size;
	const double lo[3] = {g.o.x, g.o.y, g.o.z};
	const double hi[3] = {w->def.bounds_max.x, w->def.bounds_max.y, w->def.bounds_max.z};
	const int n[3] = {g.nx, g.ny, g.nz};
	bool walls = false, asked = false; /* eddy__flip_box_walls, asked once an axis sticks out */
	for (int a = 0; a < 3; ++a) {
		g.top[a] = (float)n[a];
		if (!(h > 0 && lo[a] + n[a] * h - hi[a] > 1e-3 * h))
			continue;
		if (!asked)
			walls = eddy__flip_box_walls(w), asked = true;
		if (walls)
			g.top[a] = (float)((hi[a] - lo[a]) / h);
	}
	return g;
}

/* Whether the box's faces cut the grid's last cells on any axis. */
static inline bool flip_grid_cut(const flip_grid *g)
{
	return g->top[0] < (float)g->nx || g->top[1] < (float)g->ny || g->top[2] < (float)g->nz;
}

/* The part of cell span c on axis a ([c, c + 1] in cells) inside the box:
 * 1 on the axes the box does not cut. */
static inline float flip_box_span(const flip_grid *g, int a, int c)
{
	const float t = g->top[a] - (float)c;
	return t <= 0.0f ? 0.0f : t >= 1.0f ? 1.0f : t;
}

/* The open volume fraction the box leaves cell (i, j, k) (1 where it does not cut it). */
static inline float flip_box_open(const flip_grid *g, int i, int j, int k)
{
	return flip_box_span(g, 0, i) * flip_box_span(g, 1, j) * flip_box_span(g, 2, k);
}

/* The trilinear particle count at the centre of cell (i, j, k) for water
 * at rest filling the box (flip_particle_density, constantly extended past
 * the last centre), as a fraction of the rest count: 1 away from the box's
 * cut. On an axis it cuts, with d = top - c cells from the cell's low face
 * to the box's face: (d + 1/2)^2 / 2 below d = 1/2 and d up to 1 (the cut
 * cell), 1 - (3/2 - d)^2 / 2 up to 3/2 (its neighbour, whose kernel reaches
 * past a face less than half a cell into the cut cell). */
static inline float flip_box_rest(const flip_grid *g, int i, int j, int k)
{
	const int c[3] = {i, j, k}, n[3] = {g->nx, g->ny, g->nz};
	float r = 1.0f;
	for (int a = 0; a < 3; ++a) {
		if (!(g->top[a] < (float)n[a]))
			continue;
		const float d = g->top[a] - (float)c[a];
		r *= d <= 0.0f   ? 0.0f
		     : d < 0.5f  ? 0.5f * (d + 0.5f) * (d + 0.5f)
		     : d < 1.0f  ? d
		     : d < 1.5f  ? 1.0f - 0.5f * (1.5f - d) * (1.5f - d)
		                 : 1.0f;
	}
	return r;
}

/* A face-grid coordinate t (in cells) on an axis the box cuts at top (in
 * (n - 1, n)): the stretch of [n - 1, top] over the last cell, so the
 * normal velocity goes to the closed side's 0 at the box's face, where the
 * particles stop, not a fraction of a cell past it (water against a cut
 * face was carried on into it and packed there: a collapse in a tank 7.5
 * cells thick ended 5% under its volume). The identity elsewhere. */
static inline float flip_face_coord(float t, float top, int n)
{
	const float last = (float)(n - 1);
	if (!(top < (float)n) || !(t > last))
		return t;
	const float s = last + (t - last) / (top - last);
	return s < (float)n ? s : (float)n;
}

/* A cell-centre coordinate t (in cells) for sampling a velocity on an axis
 * the box cuts at top: where the cut leaves less than half of the last
 * cell, that cell's centre, where the tangential faces are sampled, lies
 * past the box's face, outside the water, and the faces' velocity is a
 * sliver's: the pressure that stops the water entering the cut row turns
 * the row's little mass along the wall fast (a sheet along a lid cut at
 * 0.3-0.4 of a cell ran 1.6x as fast as along a lid on a face). A point
 * past the last centre inside the box takes that centre's value (constant
 * extension: a free-slip wall's zero tangential gradient). The identity
 * elsewhere; the particle density keeps the plain centres. */
static inline float flip_centre_coord(float t, float top, int n)
{
	const float inside = (float)n - 1.5f;
	return top < (float)n - 0.5f && n >= 2 && t > inside ? inside : t;
}

/* The six axis lookups of a world position (m): per axis, faces at i (f*)
 * and centres at i + 1/2 (c*); they serve all three face grids. */
typedef struct flip_axes {
	flip_axis fx, cx, fy, cy, fz, cz;
} flip_axes;

static inline flip_axes flip_axes_at(const flip_grid *g, eddy_vec3 p)
{
	const float gx = (p.x - g->o.x) * g->inv, gy = (p.y - g->o.y) * g->inv, gz = (p.z - g->o.z) * g->inv;
	flip_axes a;
	a.fx = flip_axis_at(flip_face_coord(gx, g->top[0], g->nx), 0.0f, g->nx + 1);
	a.cx = flip_axis_at(gx, 0.5f, g->nx);
	a.fy = flip_axis_at(flip_face_coord(gy, g->top[1], g->ny), 0.0f, g->ny + 1);
	a.cy = flip_axis_at(gy, 0.5f, g->ny);
	a.fz = flip_axis_at(flip_face_coord(gz, g->top[2], g->nz), 0.0f, g->nz + 1);
	a.cz = flip_axis_at(gz, 0.5f, g->nz);
	return a;
}

/* flip_axes_at for sampling velocities: the centres through
 * flip_centre_coord (the particle density keeps flip_axes_at's). */
static inline flip_axes flip_vel_axes_at(const flip_grid *g, eddy_vec3 p)
{
	const float gx = (p.x - g->o.x) * g->inv, gy = (p.y - g->o.y) * g->inv, gz = (p.z - g->o.z) * g->inv;
	flip_axes a;
	a.fx = flip_axis_at(flip_face_coord(gx, g->top[0], g->nx), 0.0f, g->nx + 1);
	a.cx = flip_axis_at(flip_centre_coord(gx, g->top[0], g->nx), 0.5f, g->nx);
	a.fy = flip_axis_at(flip_face_coord(gy, g->top[1], g->ny), 0.0f, g->ny + 1);
	a.cy = flip_axis_at(flip_centre_coord(gy, g->top[1], g->ny), 0.5f, g->ny);
	a.fz = flip_axis_at(flip_face_coord(gz, g->top[2], g->nz), 0.0f, g->nz + 1);
	a.cz = flip_axis_at(flip_centre_coord(gz, g->top[2], g->nz), 0.5f, g->nz);
	return a;
}

/* Velocity of the face grids u, v, wv at the position behind a. */
static inline eddy_vec3 flip_velocity_axes(const flip_grid *g, const float *u, const float *v, const float *wv,
                                           const flip_axes *a)
{
	const size_t nx = (size_t)g->nx, ny = (size_t)g->ny;
	eddy_vec3 r;
	r.x = flip_trilinear(u, nx + 1, (nx + 1) * ny, a->fx, a->cy, a->cz);
	r.y = flip_trilinear(v, nx, nx * (ny + 1), a->cx, a->fy, a->cz);
	r.z = flip_trilinear(wv, nx, nx * ny, a->cx, a->cy, a->fz);
	return r;
}

/* Grid velocity at a world position (m), trilinear on each face grid. */
static inline eddy_vec3 flip_velocity_at(const flip_grid *g, const float *u, const float *v, const float *wv,
                                         eddy_vec3 p)
{
	const flip_axes a = flip_vel_axes_at(g, p);
	return flip_velocity_axes(g, u, v, wv, &a);
}

/* Before the pressure solve (flip_p2g calls it once the cells are marked):
 * every interior face with a fluid cell on a side and no particle weight
 * (reached[a][f] == 0) takes the average of its known neighbours in
 * its own face grid, round by round, so the solve sees a velocity on every
 * face of every fluid cell (sys_flip_extrapolate.c, which says why). */
eddy_status eddy__flip_fill_fluid_faces(eddy_world *w, float *const face[3], const uint8_t *const reached[3]);

/* ---- fractional solid faces ----------------------------------------------
 * Batty, Bertails & Bridson 2007, "A fast variational framework for accurate
 * solid-fluid coupling": every face carries the fraction of its area open to
 * the fluid, from the colliders' signed distance at its four corners (grid
 * nodes; the union of the solids is the minimum distance), and the normal
 * velocity of the collider covering it. flip_boundary computes them once a
 * step (cell types, closed faces) and lends them to flip_surface and
 * flip_pressure after it (eddy__flip_boundary_solid); a system that cannot
 * borrow them computes its own from the same collider offsets.
 *
 * Stored compactly: almost every face and cell of a scene is plainly open
 * (weight 1, open volume 1), so only the others are kept. A face is marked
 * when a corner is in or on a solid or a cell beside it has its centre in one
 * (those faces' solid velocity is read); a cell when its open volume is
 * below 1. A marked item's slot is the count of marked items before it: a
 * running count per 64-item word plus a popcount in the word. About 0.19
 * bytes per face and cell plus 8 (4) per marked face (cell), against 8 (4)
 * for every face (cell) stored plainly: 60 MB at a million particles in a
 * tank whose walls are a collider. Unmarked: weight 1, velocity 0, open 1. */
typedef struct flip_solid {
	bool any;                /* a collider is in the pipeline or the box cuts the grid (flip_grid's top); if not, the arrays are NULL */
	bool open_sides;         /* the domain's sides are open (flip_boundary's def; eddy__flip_open_sides) */
	const uint64_t *mark[3]; /* per face grid: bit f % 64 of word f / 64, face f is marked */
	const uint32_t *rank[3]; /* per word: marked faces before it */
	const float *wt[3];      /* per marked face, in face order: open fraction in [0, 1]; 0 on the domain's closed sides */
	const float *vel[3];     /* per marked face: m/s, normal velocity of the covering collider (0 on closed sides) */
	const uint64_t *cmark;   /* cells, as the faces */
	const uint32_t *crank;
	const float *open; /* per marked cell: open volume fraction, clamp(1/2 + phi_s(centre) / dx, 0, 1) */
} flip_solid;

/* Where flip_boundary keeps its solid faces from step to step (malloc'd,
 * grown as needed): the arena is a stack, and the faces outlive the systems
 * after flip_boundary whose scratch is released above them. */
typedef struct flip_solid_store {
	void *mem;
	size_t cap; /* bytes */
} flip_solid_store;

static inline bool flip_marked(const uint64_t *mark, const uint32_t *rank, size_t f, size_t *slot)
{
	const uint64_t word = mark[f >> 6], bit = (uint64_t)1 << (f & 63);
	if (!(word & bit))
		return false;
	*slot = (size_t)rank[f >> 6] + (size_t)__builtin_popcountll(word & (bit - 1));
	return true;
}

/* Open fraction of face f of grid a as stored (1 when unmarked). */
static inline float flip_solid_wt(const flip_solid *s, int a, size_t f)
{
	size_t q;
	return s->any && flip_marked(s->mark[a], s->rank[a], f, &q) ? s->wt[a][q] : 1.0f;
}
/* m/s, the covering solid's normal velocity at face f of grid a (0 when unmarked). */
static inline float flip_solid_vel(const flip_solid *s, int a, size_t f)
{
	size_t q;
	return s->any && flip_marked(s->mark[a], s->rank[a], f, &q) ? s->vel[a][q] : 0.0f;
}
/* Open volume fraction of cell c: 1 without colliders or when unmarked. */
static inline float flip_solid_open(const flip_solid *s, size_t c)
{
	size_t q;
	return s->any && flip_marked(s->cmark, s->crank, c, &q) ? s->open[q] : 1.0f;
}

/* Fills s from the colliders (margin inflates them). The arrays go to store
 * (its scratch released from the world's arena before returning), or with
 * store NULL to the world's arena along with the scratch. velocities: per
 * pipeline position, the solids' velocities of this step (flip_boundary's),
 * or NULL for each collider's motion record. On all of the world's threads,
 * the same result on any thread count. Returns false when out of memory. */
bool eddy__flip_solid_faces(eddy_world *w, double dt, float margin, const eddy_vec3 *velocities, flip_solid *s,
                            flip_solid_store *store);
/* The pipeline's flip_boundary opens the domain's sides (its def's
 * open_sides): outflow boundaries, air beyond them at p = 0, closed only
 * where a collider covers them; particles cross them and leave the world
 * (removed, or an error, as the world's escape says). false without a
 * flip_boundary: the sides are still walls. */
bool eddy__flip_open_sides(const eddy_world *w);

/* The margin of the pipeline's flip_boundary and the solid velocities it used
 * this step (NULL if it has not run this step); false if it has none (then
 * flip_pressure sees no solids, as flip_boundary marks none). */
bool eddy__flip_boundary_info(const eddy_world *w, float *margin, const eddy_vec3 **vel);

/* The solid faces the pipeline's flip_boundary computed this step, for a
 * system after it (self): the same geometry when only FLIP grid systems and
 * gravity run between them (none of them moves a collider). false when there
 * is no such flip_boundary, it has not run this step, or another system
 * (a collider, a callback) runs between them: then compute them afresh. */
bool eddy__flip_boundary_solid(const eddy_world *w, const eddy_system *self, flip_solid *sd);

/* The solid faces for system self: flip_boundary's of this step when it can
 * lend them (above), else computed into the world's arena with its margin
 * and velocities (all zero, any = false, without a flip_boundary). false
 * when out of memory. */
bool eddy__flip_solid_for(eddy_world *w, const eddy_system *self, double dt, flip_solid *sd);

/* The trilinear particle density (flip_particle_density) and the cells
 * holding a particle (nc each) as the pipeline's flip_p2g computed them this
 * step, for a system after it (self): false when there is no such p2g, it
 * has not run this step, the particle count changed, or a system between
 * them declares a write of x, y or z. */
bool eddy__flip_p2g_density(const eddy_world *w, const eddy_system *self, const float **dens, const uint8_t **held);

/* s, flip_advect's step limit before the world's cfl: dx / (max |v_p| +
 * sqrt(|g| dx)), infinite for particles at rest without gravity
 * (sys_flip_advect.c; flip_pressure's volume correction takes it too). */
double eddy__flip_advect_time(eddy_world *w);

/* Face `axis` (i, j, k) lies on a side of the domain. */
static inline bool flip_side_face(const eddy_world *w, int axis, int i, int j, int k)
{
	const int c[3] = {i, j, k}, n[3] = {w->nx, w->ny, w->nz};
	return c[axis] == 0 || c[axis] == n[axis];
}

/* Open fraction of face `axis` (i, j, k): 1 without colliders; on the
 * domain's sides 0, or as inside where they are open (flip_solid's
 * open_sides). */
static inline float flip_face_weight(const eddy_world *w, const flip_solid *s, int axis, size_t f, int i, int j, int k)
{
	if (flip_side_face(w, axis, i, j, k) && !s->open_sides)
		return 0.0f;
	return s->any ? flip_solid_wt(s, axis, f) : 1.0f;
}

/* Particle density per cell (nc floats): every particle's trilinear weights
 * at the cell centres around it (constant extension at the domain's sides,
 * so a cell at a wall sees the full rest density). Sum = particle count.
 * On nt threads in slabs of z rows: each slab sums, over the particles in
 * index order, the weights landing in its rows (a particle reaches rows
 * floor(gz - 1/2) and one above, so a slab skips those with gz outside
 * [klo - 1.5, khi + 1.5); NaN clamps to row 0, which one slab owns): every
 * cell sums the same terms in the same order on any thread count. */
static inline void flip_particle_density(const eddy_world *w, const float *px, const float *py, const float *pz,
                                         float *dens, int nt)
{
	const flip_grid g = flip_grid_of(w);
	const size_t sy = (size_t)w->nx, sz = (size_t)w->nx * (size_t)w->ny;
	const int nz = w->nz;
	const size_t np = w->n;
	nt = np > 16384 && nt > 1 ? nt : 1;
#pragma omp parallel for num_threads(nt) if (nt > 1) schedule(static, 1)
	for (int t = 0; t < nt; ++t) {
		const int klo = nz * t / nt, khi = t == nt - 1 ? nz : nz * (t + 1) / nt;
		const float zlo = klo == 0 ? -INFINITY : (float)klo - 1.5f, zhi = t == nt - 1 ? INFINITY : (float)khi + 1.5f;
		memset(dens + (size_t)klo * sz, 0, (size_t)(khi - klo) * sz * sizeof *dens);
		for (size_t p = 0; p < np; ++p) {
			const float gz = (pz[p] - g.o.z) * g.inv;
			if (gz < zlo || gz >= zhi)
				continue;
			const flip_axes ax = flip_axes_at(&g, (eddy_vec3){px[p], py[p], pz[p]});
			const size_t i0 = (size_t)ax.cx.i0, i1 = (size_t)ax.cx.i1;
			const size_t j0 = (size_t)ax.cy.i0 * sy, j1 = (size_t)ax.cy.i1 * sy;
			const size_t k0 = (size_t)ax.cz.i0 * sz, k1 = (size_t)ax.cz.i1 * sz;
			const bool in0 = ax.cz.i0 >= klo && ax.cz.i0 < khi, in1 = ax.cz.i1 >= klo && ax.cz.i1 < khi;
			const float wx = ax.cx.w1, wy = ax.cy.w1, wz = ax.cz.w1;
			if (in0) {
				dens[k0 + j0 + i0] += (1 - wx) * (1 - wy) * (1 - wz);
				dens[k0 + j0 + i1] += wx * (1 - wy) * (1 - wz);
				dens[k0 + j1 + i0] += (1 - wx) * wy * (1 - wz);
				dens[k0 + j1 + i1] += wx * wy * (1 - wz);
			}
			if (in1) {
				dens[k1 + j0 + i0] += (1 - wx) * (1 - wy) * wz;
				dens[k1 + j0 + i1] += wx * (1 - wy) * wz;
				dens[k1 + j1 + i0] += (1 - wx) * wy * wz;
				dens[k1 + j1 + i1] += wx * wy * wz;
			}
		}
	}
}

/* Particles per cell of the engine's seeding (2 x 2 x 2, Zhu & Bridson):
 * flip_reseed's bounds and the volume correction's rest density refer to it. */
enum { FLIP_SEED_PER_CELL = 8 };

/* The rest particle count per cell n0 the volume bookkeeping refers to (p2g's
 * fill fraction, flip_pressure's volume correction, flip_reseed): the
 * emitters' lattice, (cell_size / spacing)^3, or FLIP_SEED_PER_CELL when no
 * emitter set a spacing (particles added through the API). One particle is
 * dx^3 / n0 of liquid. */
static inline double flip_rest_count(const eddy_world *w)
{
	if (w->length_scale > 0) {
		const double r = w->def.cell_size / (double)w->length_scale;
		return r * r * r;
	}
	return FLIP_SEED_PER_CELL;
}

/* ---- the Poisson system ---------------------------------------------------
 * Rows are fluid cells in cell-index order, so a row's -x, -y, -z neighbours
 * come before it (what MIC(0) and the upper-triangle CSC for CHOLMOD need).
 * nb[6*r + d] is the row across side d (0 -x, 1 +x, 2 -y, 3 +y, 4 -z, 5 +z)
 * or -1; the off-diagonal entry to it is -off[6*r + d] (the open fraction of
 * the face between them, > 0 for a link; symmetric), or -1 when off is NULL. */
typedef struct flip_matrix {
	int n;
	double *diag; /* n */
	int *nb;      /* 6 n */
	double *off;  /* 6 n, or NULL for all 1 */
} flip_matrix;

static inline double flip_off(const flip_matrix *A, int r, int d) { return A->off ? A->off[6 * r + d] : 1.0; }

/* CG's shared row kernel (flip_pcg.c, used by the PCG and MG solvers). A dot
 * product is summed in fixed chunks of FLIP_CHUNK rows, the chunk sums added
 * in chunk order, so it is the same on any number of threads. */
enum { FLIP_CHUNK = 4096 };
/* Over the rows [lo, hi): s = z + beta s_old, q = A s; returns the chunk's
 * s . q. With s_old = z and beta = 0 it gives s = z (z finite). */
double eddy__flip_matvec_dot(const flip_matrix *A, const double *z, const double *s_old, double beta, double *s,
                             double *q, int lo, int hi);
/* part[0] + ... + part[nch - 1], in that order */
double eddy__flip_sum_chunks(const double *part, int nch);

/* MIC(0)-PCG (flip_pcg.c). Solves A x = b to max|r| <= tol max|b|; x starts
 * at 0; cell_of[r] is row r's cell (ascending: the rows in cell order). Scratch comes from the world's arena. Returns
 * false if it did not converge in max_it; *it and *res (max|r| / max|b|) are always set. */
bool eddy__flip_pcg(eddy_world *w, const flip_matrix *A, const int *cell_of, const double *b, double *x, double tol,
                    int max_it, int *it, double *res);

/* PFMG-preconditioned CG (flip_hypre.c, the only file including HYPRE or
 * MPI). Solves A x = b to max|r| <= tol max|b| as eddy__flip_pcg; cell_of[r]
 * is row r's cell (the preconditioner works on the grid box around them).
 * Serial, so the result does not depend on the thread count. *converged
 * false: no convergence in max_it (EDDY_OK returned; *it, *res set). Any
 * other failure (MPI or HYPRE unavailable, out of memory) returns an error
 * with the world error set. */
eddy_status eddy__flip_hypre_solve(eddy_world *w, const flip_matrix *A, const int *cell_of, const double *b, double *x,
                                   double tol, int max_it, int *it, double *res, bool *converged);

/* Multigrid-preconditioned CG (flip_mg.c, after McAdams, Sifakis & Teran
 * 2010). One per flip_pressure system: it keeps its grid levels while the
 * grid size stays. Solves A x = b to max|r| <= tol max|b| as eddy__flip_pcg;
 * cell_of[r] is row r's cell. On all of the world's threads, the same result
 * on any thread count. *converged false: no convergence in max_it (EDDY_OK
 * returned; *it, *res set). Out of memory returns an error with the world
 * error set. */
typedef struct flip_mg flip_mg;
flip_mg *eddy__flip_mg_new(void);
void eddy__flip_mg_free(flip_mg *m);
eddy_status eddy__flip_mg_solve(eddy_world *w, flip_mg *m, const flip_matrix *A, const int *cell_of, const double *b,
                                double *x, double tol, int max_it, int *it, double *res, bool *converged);

/* CHOLMOD (flip_cholmod.c, the only file including cholmod.h). One solver
 * per flip_pressure system, keeping the symbolic analysis while the pattern
 * is unchanged. */
typedef struct flip_cholmod flip_cholmod;
flip_cholmod *eddy__flip_cholmod_new(void);
void eddy__flip_cholmod_free(flip_cholmod *c);
/* Factorises A (re-analysing only if its pattern changed) and solves A x = b.
 * On failure returns EDDY_ERR_SOLVER (or NOMEM) with the world error set. */
eddy_status eddy__flip_cholmod_solve(eddy_world *w, flip_cholmod *c, const flip_matrix *A, const double *b, double *x,
                                     bool *reanalysed);

#endif
