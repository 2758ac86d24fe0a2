/* SPDX-License-Identifier: MIT */
/* flip_boundary: solid cells and solid face velocities with fractional face
 * areas (Batty, Bertails & Bridson 2007, "A fast variational framework for
 * accurate solid-fluid coupling", SIGGRAPH; Bridson, "Fluid Simulation for
 * Computer Graphics", 2nd ed., ch. 5.2 and 7.5: free-slip solid walls).
 *
 * Reads: cell_type u v w. Writes: cell_type u v w.
 *   phi_s(node) = min over the colliders of their signed distance (< 0 inside)
 *   minus margin, at every grid node; a face's open fraction w_f is the area
 *   of the face where the bilinear phi_s is positive, from its four corners
 *   (Batty's fraction_inside, exact for the linear cut of each triangle).
 *   A cell is typed solid when its centre is inside (open volume fraction
 *   clamp(1/2 + phi_s(centre) / dx, 0, 1) < 1/2): flip_extrapolate keeps its
 *   faces, flip_surface stops there. The type no longer decides the pressure
 *   unknowns: flip_pressure solves in every cut cell with an open face and
 *   weights the faces by w_f, so nothing jumps when a centre crosses the
 *   solid's surface.
 *   Faces on the domain's sides: u.n = 0 (fixed walls, w_f = 0), unless the
 *   def opens them (open_sides: outflow, air beyond at p = 0): then they
 *   are faces like any other, closed only where a collider covers them.
 *   Where the world's box ends inside the grid's last cells (an extent that
 *   is not a whole number of cells, flip_grid's top), the box's face is the
 *   wall, a still solid: a face's open fraction is the part of it inside the
 *   box, a cell's open volume likewise (exact for the box's axis-aligned
 *   planes, where the bilinear rule gives a corner column's faces 1/8 open
 *   for 1/4), each the smaller of the box's and the colliders'. So the tank
 *   is the box the scene gave, as SPH's walls are.
 *   Closed faces (w_f = 0): u.n = V_s.n, V_s = (offset - offset this system
 *   saw at its last step) / dt of the collider most inside at the face's
 *   corners (solid_velocities says why not the collider's own record);
 *   partly open faces keep the fluid velocity, and flip_pressure adds the
 *   solid's flux (1 - w_f) V_s.n with the same V_s. A rotating collider's
 *   V_s is its point velocity at the face's centre, v + omega x (x_f - c)
 *   (c its pivot in the world), omega the rotation from the orientation
 *   seen at the last step to this one over dt.
 * Why fractional: with binary cells (solid when the centre is inside) a moving
 * collider flips cells between solid and fluid, the solid region jumps by
 * whole cells and the fluid it covers or uncovers is not accounted for; the
 * particles it projects out pack, and the level drops (measured: 6% lowering
 * a 4 cm sphere into a 15 cm pool, 44% moving it back and forth).
 * Add the colliders after flip_advect (where they also keep particles out).
 * The solid faces are computed on all threads (each node, cell and face
 * written by one: the same on any thread count) in a step where the grid or
 * a collider's pose or velocity differs from the last computation (solid_key:
 * still solids, such as a tank, are computed once), kept compactly
 * (flip.h's flip_solid: only the faces and cells that are not plainly open)
 * in this system's store, and lent to flip_surface and flip_pressure after
 * it (eddy__flip_boundary_solid).
 * State: the offsets seen at the last step, per pipeline position
 * (checkpointed, so a resumed run sees the same solid velocities). */
#include "flip.h"

#include <stdlib.h>
#include <string.h>

typedef struct boundary {
	eddy_flip_boundary_def def;
	/* per pipeline position: the collider offset this system saw at its last
	 * step, and the solid velocities of the current step (see step) */
	int cap;
	struct seen_offset {
		float x, y, z;            /* m */
		float have;               /* 1 when x y z hold a collider's offset (floats only: no padding in a checkpoint) */
		float rx, ry, rz, unused; /* degrees, the collider's rotation */
	} * seen;
	eddy_vec3 *vel;
	eddy_vec3 *omega;  /* rad/s, per pipeline position, this step's (with vel) */
	eddy_vec3 *center; /* m, the pivot each omega turns about */
	int64_t vel_step;  /* the step vel belongs to, -1 for none */
	/* this step's solid faces, lent to the FLIP systems after this one */
	flip_solid sd;
	flip_solid_store store;
	int64_t sd_step; /* the step sd belongs to, -1 for none */
	/* what sd was computed from (solid_key); nkey 0: nothing yet */
	struct solid_key *key;
	int nkey, key_cap;
} boundary;

/* What the solid faces depend on besides the colliders' shapes (fixed once
 * added): the grid and margin, then per collider its slot and generation,
 * pose and this step's solid velocities. All 4-byte fields: no padding, so
 * keys compare with memcmp. */
typedef struct solid_key {
	int32_t slot, generation;
	float pose[9]; /* offset, rotation (degrees), pivot */
	float vel[9];  /* velocity, angular velocity, the pivot it turns about */
} solid_key;

static const int boundary_io[] = {COL_CELL_TYPE, COL_FACE_U, COL_FACE_V, COL_FACE_W, -1};

eddy_flip_boundary_def eddy_default_flip_boundary_def(void)
{
	eddy_flip_boundary_def d;
	d.margin = 0.0f;
	d.open_sides = false;
	return d;
}

/* Fraction of segment [a, b] where the linear phi is negative (Batty). */
static float frac1(float a, float b)
{
	if (a <= 0 && b <= 0)
		return 1;
	if (a <= 0 && b > 0)
		return a / (a - b);
	if (a > 0 && b <= 0)
		return b / (b - a);
	return 0;
}

static void cycle4(float *l)
{
	const float t = l[0];
	l[0] = l[1], l[1] = l[2], l[2] = l[3], l[3] = t;
}

/* Fraction of a square face inside the solid from its corners in cyclic order
 * (Batty's fraction_inside, from his variational pressure code). The solid
 * includes its surface (phi <= 0): a face lying on a wall is closed, as the
 * binary rule had it; Batty's strict phi < 0 would open it. */
static float frac_inside(float p0, float p1, float p2, float p3)
{
	float l[4] = {p0, p1, p2, p3};
	const int inside = (p0 <= 0) + (p1 <= 0) + (p2 <= 0) + (p3 <= 0);
	if (inside == 4)
		return 1;
	if (inside == 0)
		return 0;
	if (inside == 3) {
		while (l[0] <= 0)
			cycle4(l);
		const float s0 = 1 - frac1(l[0], l[3]), s1 = 1 - frac1(l[0], l[1]);
		return 1 - 0.5f * s0 * s1;
	}
	if (inside == 1) {
		while (l[0] > 0)
			cycle4(l);
		return 0.5f * frac1(l[0], l[3]) * frac1(l[0], l[1]);
	}
	/* two inside: adjacent, or diagonal (the centre's sign decides) */
	while (l[0] > 0 || !(l[1] <= 0 || l[2] <= 0))
		cycle4(l);
	if (l[1] <= 0)
		return 0.5f * (frac1(l[0], l[3]) + frac1(l[1], l[2]));
	if (0.25f * (l[0] + l[1] + l[2] + l[3]) <= 0) {
		const float a = 0.5f * (1 - frac1(l[0], l[3])) * (1 - frac1(l[2], l[3])) +
		                0.5f * (1 - frac1(l[0], l[1])) * (1 - frac1(l[2], l[1]));
		return 1 - a;
	}
	return 0.5f * frac1(l[0], l[1]) * frac1(l[0], l[3]) + 0.5f * frac1(l[2], l[1]) * frac1(l[2], l[3]);
}

/* Open volume fraction of a cell from phi_s at its centre: exact for a plane
 * through the cell along an axis; < 1/2 exactly when the centre is in the
 * solid (the binary rule's solid cells). */
static inline float open_of(float cphi, float h)
{
	const float op = 0.5f + cphi / h;
	return cphi < 0 ? (op < 0 ? 0 : op > 0.5f ? 0.4999f : op) : (op > 1 ? 1 : op);
}

/* Open area fraction the box leaves face c of grid a (flip_grid's top): closed
 * on or past the box's face, else its two spans' product. Exact for the
 * box's axis-aligned planes. */
static inline float box_face_open(const flip_grid *g, int a, const int c[3])
{
	if (!((float)c[a] < g->top[a]))
		return 0.0f;
	float f = 1.0f;
	for (int e = 0; e < 3; ++e)
		if (e != a)
			f *= flip_box_span(g, e, c[e]);
	return f;
}

static inline float box_cell_open(const flip_grid *g, const int c[3]) { return flip_box_open(g, c[0], c[1], c[2]); }

/* (i, j, k) of item f of a grid with rows of m0 and planes of m0 m1 items. */
static inline void grid_coords(size_t f, size_t m0, size_t m1, int c[3])
{
	const size_t row = f / m0;
	c[0] = (int)(f - row * m0);
	c[1] = (int)(row % m1);
	c[2] = (int)(row / m1);
}

/* Serial prefix over the words: rank[q] = marked items before word q; returns the total. */
static size_t rank_words(const uint64_t *mark, uint32_t *rank, size_t nwords)
{
	size_t total = 0;
	for (size_t q = 0; q < nwords; ++q) {
		rank[q] = (uint32_t)total;
		total += (size_t)__builtin_popcountll(mark[q]);
	}
	return total;
}

bool eddy__flip_solid_faces(eddy_world *w, double dt, float margin, const eddy_vec3 *velocities, flip_solid *s,
                            flip_solid_store *store)
{
	memset(s, 0, sizeof *s);
	s->open_sides = eddy__flip_open_sides(w);
	int ncol = 0;
	int colq[EDDY_MAX_SYSTEMS]; /* the colliders' pipeline positions, in order */
	eddy_system_iter it = eddy__systems(w, EDDY_CAP_COLLIDER);
	while (eddy__systems_next(&it))
		colq[ncol++] = eddy__systems_position(&it);
	const int nx = w->nx, ny = w->ny, nz = w->nz, nt = w->def.threads;
	const double h = w->def.cell_size;
	const float hf = (float)h;
	const eddy_vec3 o = w->def.bounds_min;
	/* the box's faces inside the grid's last cells (flip_grid's top) */
	const flip_grid bc = flip_grid_of(w);
	const bool box_on = flip_grid_cut(&bc);
	if (ncol == 0 && !box_on)
		return true;
	const size_t mx = (size_t)nx + 1, my = (size_t)ny + 1, mz = (size_t)nz + 1, nn = mx * my * mz;
	const size_t nf[3] = {mx * ny * nz, (size_t)nx * my * nz, (size_t)nx * ny * mz}, nc = (size_t)nx * ny * nz;
	size_t nwf[3], nwc = (nc + 63) / 64, fixed = 0;
	for (int a = 0; a < 3; ++a) {
		nwf[a] = (nf[a] + 63) / 64;
		fixed += nwf[a] * (sizeof(uint64_t) + sizeof(uint32_t));
	}
	fixed += nwc * (sizeof(uint64_t) + sizeof(uint32_t));
	const eddy_arena_mark am = eddy__arena_mark(&w->arena);
	float *phi = eddy__arena_alloc(&w->arena, nn * sizeof *phi);
	uint16_t *own = eddy__arena_alloc(&w->arena, nn * sizeof *own);
	eddy_vec3 *vel = eddy__arena_alloc(&w->arena, (size_t)w->order_count * sizeof *vel + 1);
	float *cphi = eddy__arena_alloc(&w->arena, nc * sizeof *cphi);
	/* marks and running counts, copied to the output once the counts are known */
	unsigned char *marks = eddy__arena_alloc(&w->arena, fixed);
	if (!phi || !own || !vel || !cphi || !marks)
		return false;
	uint64_t *fmark[3], *cmark;
	uint32_t *frank[3], *crank;
	{
		unsigned char *m = marks;
		for (int a = 0; a < 3; ++a) {
			fmark[a] = (uint64_t *)m, m += nwf[a] * sizeof(uint64_t);
		}
		cmark = (uint64_t *)m, m += nwc * sizeof(uint64_t);
		for (int a = 0; a < 3; ++a)
			frank[a] = (uint32_t *)m, m += nwf[a] * sizeof(uint32_t);
		crank = (uint32_t *)m;
	}
	s->any = true;
	const float inv_dt = dt > 0 ? (float)(1.0 / dt) : 0.0f;
	/* the rotating solids' angular velocities: flip_boundary's of this step
	 * with its velocities, else from each motion record; NULL while none turns */
	const eddy_vec3 *omega = NULL, *center = NULL;
	eddy_vec3 *own_omega = NULL, *own_center = NULL;
	for (int q = 0; q < w->order_count; ++q) {
		const eddy_system *c = &w->slots[w->order[q]];
		if (velocities && (c->vt->provides & EDDY_CAP_SOLID_FACES) && ((const boundary *)c->data)->vel == velocities) {
			omega = ((const boundary *)c->data)->omega, center = ((const boundary *)c->data)->center;
			break;
		}
		if (!velocities && eddy__is_collider(c) &&
		    eddy__motion_rotates(&((const eddy_collider_base *)c->data)->motion)) {
			own_omega = eddy__arena_alloc(&w->arena, (size_t)w->order_count * sizeof *own_omega + 1);
			own_center = eddy__arena_alloc(&w->arena, (size_t)w->order_count * sizeof *own_center + 1);
			if (!own_omega || !own_center)
				return false;
			for (int r = 0; r < w->order_count; ++r) {
				const eddy_system *cr = &w->slots[w->order[r]];
				own_omega[r] = own_center[r] = (eddy_vec3){0, 0, 0};
				if (!eddy__is_collider(cr))
					continue;
				const eddy_collider_motion *m = &((const eddy_collider_base *)cr->data)->motion;
				own_omega[r] = eddy__rotation_rate(m->last_rotation, m->rotation, dt);
				own_center[r] = eddy__add3(m->pivot, m->offset);
			}
			omega = own_omega, center = own_center;
			break;
		}
	}
	for (int t = 0; t < ncol; ++t) {
		const int q = colq[t];
		if (velocities) {
			vel[q] = velocities[q];
		} else {
			const eddy_collider_motion m = ((const eddy_collider_base *)w->slots[w->order[q]].data)->motion;
			vel[q] = (eddy_vec3){(m.offset.x - m.last_offset.x) * inv_dt, (m.offset.y - m.last_offset.y) * inv_dt,
			                     (m.offset.z - m.last_offset.z) * inv_dt};
		}
	}
	/* phi_s at the nodes and the cell centres: per point, the colliders in
	 * pipeline order, the first of equal distances owning it; each point
	 * written by one thread (the distances are read-only queries) */
	const int ntp = nn > 32768 ? nt : 1;
#pragma omp parallel for num_threads(ntp) if (ntp > 1) schedule(static)
	for (size_t k = 0; k < mz; ++k)
		for (size_t j = 0; j < my; ++j)
			for (size_t i = 0; i < mx; ++i) {
				const size_t g = i + mx * (j + my * k);
				const eddy_vec3 p = {(float)(o.x + (double)i * h), (float)(o.y + (double)j * h),
				                     (float)(o.z + (double)k * h)};
				float best = INFINITY;
				uint16_t who = 0;
				for (int t = 0; t < ncol; ++t) {
					const eddy_system *c = &w->slots[w->order[colq[t]]];
					const float d = c->vt->distance(c, p) - margin;
					if (d < best)
						best = d, who = (uint16_t)(colq[t] + 1);
				}
				phi[g] = best, own[g] = who;
			}
#pragma omp parallel for num_threads(ntp) if (ntp > 1) schedule(static)
	for (int k = 0; k < nz; ++k)
		for (int j = 0; j < ny; ++j)
			for (int i = 0; i < nx; ++i) {
				const eddy_vec3 p = {(float)(o.x + (i + 0.5) * h), (float)(o.y + (j + 0.5) * h),
				                     (float)(o.z + (k + 0.5) * h)};
				float best = INFINITY;
				for (int t = 0; t < ncol; ++t) {
					const eddy_system *c = &w->slots[w->order[colq[t]]];
					const float d = c->vt->distance(c, p) - margin;
					best = d < best ? d : best;
				}
				cphi[(size_t)i + (size_t)nx * ((size_t)j + (size_t)ny * (size_t)k)] = best;
			}
	/* marks: a face with a corner in or on a solid or a cell beside it whose
	 * centre is in one; a cell with open volume below 1. Word by word, each
	 * word one thread's. */
	const size_t sy = mx, sz = mx * my;
	for (int a = 0; a < 3; ++a) {
		const size_t fx = (size_t)nx + (a == 0), fy = (size_t)ny + (a == 1);
		const size_t s1 = a == 0 ? sy : 1, s2 = a == 2 ? sy : sz; /* the two in-plane node strides */
		const size_t cst = a == 0 ? 1 : a == 1 ? (size_t)nx : (size_t)nx * ny;
		const int n[3] = {nx, ny, nz};
		uint64_t *mk = fmark[a];
		const long nw = (long)nwf[a];
#pragma omp parallel for num_threads(ntp) if (ntp > 1) schedule(static)
		for (long q = 0; q < nw; ++q) {
			uint64_t word = 0;
			const size_t f0 = (size_t)q * 64, f1 = f0 + 64 < nf[a] ? f0 + 64 : nf[a];
			int c[3];
			grid_coords(f0, fx, fy, c);
			for (size_t f = f0; f < f1; ++f) {
				if (f > f0 && ++c[0] == (int)fx) { /* the next face's coordinates, no division */
					c[0] = 0;
					if (++c[1] == (int)fy)
						c[1] = 0, ++c[2];
				}
				const size_t g0 = (size_t)c[0] + sy * (size_t)c[1] + sz * (size_t)c[2];
				bool m = phi[g0] <= 0 || phi[g0 + s1] <= 0 || phi[g0 + s1 + s2] <= 0 || phi[g0 + s2] <= 0;
				if (!m) {
					const size_t ch = (size_t)c[0] + (size_t)nx * ((size_t)c[1] + (size_t)ny * (size_t)c[2]);
					m = (c[a] < n[a] && cphi[ch] < 0) || (c[a] > 0 && cphi[ch - cst] < 0);
				}
				if (!m && box_on) { /* the box cuts it or a cell beside it */
					int cb[3] = {c[0], c[1], c[2]};
					m = box_face_open(&bc, a, c) < 1 || (c[a] < n[a] && box_cell_open(&bc, c) < 1);
					cb[a] -= 1;
					m = m || (c[a] > 0 && box_cell_open(&bc, cb) < 1);
				}
				word |= (uint64_t)m << (f - f0);
			}
			mk[q] = word;
		}
	}
	{
		const long nw = (long)nwc;
#pragma omp parallel for num_threads(ntp) if (ntp > 1) schedule(static)
		for (long q = 0; q < nw; ++q) {
			uint64_t word = 0;
			const size_t c0 = (size_t)q * 64, c1 = c0 + 64 < nc ? c0 + 64 : nc;
			for (size_t c = c0; c < c1; ++c) {
				bool m = open_of(cphi[c], hf) < 1;
				if (!m && box_on) {
					int cc[3];
					grid_coords(c, (size_t)nx, (size_t)ny, cc);
					m = box_cell_open(&bc, cc) < 1;
				}
				word |= (uint64_t)m << (c - c0);
			}
			cmark[q] = word;
		}
	}
	size_t cnt[3], ccnt = rank_words(cmark, crank, nwc), vals = ccnt;
	for (int a = 0; a < 3; ++a)
		vals += 2 * (cnt[a] = rank_words(fmark[a], frank[a], nwf[a]));
	/* the output: marks and counts, then the values of the marked items */
	const size_t bytes = fixed + vals * sizeof(float);
	unsigned char *out;
	float *wtv[3], *velv[3], *openv;
	if (store) {
		if (store->cap < bytes) {
			free(store->mem);
			store->mem = malloc(bytes);
			store->cap = store->mem ? bytes : 0;
			if (!store->mem)
				return false;
		}
		out = store->mem;
	} else {
		out = eddy__arena_alloc(&w->arena, bytes);
		if (!out)
			return false;
	}
	memcpy(out, marks, fixed);
	{
		unsigned char *m = out;
		for (int a = 0; a < 3; ++a)
			fmark[a] = (uint64_t *)m, m += nwf[a] * sizeof(uint64_t);
		cmark = (uint64_t *)m, m += nwc * sizeof(uint64_t);
		for (int a = 0; a < 3; ++a)
			frank[a] = (uint32_t *)m, m += nwf[a] * sizeof(uint32_t);
		crank = (uint32_t *)m, m += nwc * sizeof(uint32_t);
		float *v = (float *)m;
		for (int a = 0; a < 3; ++a) {
			s->mark[a] = fmark[a], s->rank[a] = frank[a];
			s->wt[a] = wtv[a] = v, v += cnt[a];
			s->vel[a] = velv[a] = v, v += cnt[a];
		}
		s->cmark = cmark, s->crank = crank, s->open = openv = v;
	}
	/* the marked faces' values: corners in cyclic order in the face's plane;
	 * the covering collider is the one nearest (most inside) at a corner */
	const bool open_sides = s->open_sides;
	for (int a = 0; a < 3; ++a) {
		const size_t fx = (size_t)nx + (a == 0), fy = (size_t)ny + (a == 1);
		const size_t s1 = a == 0 ? sy : 1, s2 = a == 2 ? sy : sz;
		const int n[3] = {nx, ny, nz};
		const uint64_t *mk = fmark[a];
		const uint32_t *rk = frank[a];
		float *wt = wtv[a], *fv = velv[a];
		const long nw = (long)nwf[a];
#pragma omp parallel for num_threads(ntp) if (ntp > 1) schedule(static)
		for (long q = 0; q < nw; ++q) {
			uint64_t word = mk[q];
			size_t slot = rk[q];
			while (word) {
				const size_t f = (size_t)q * 64 + (size_t)__builtin_ctzll(word);
				word &= word - 1;
				int c[3];
				grid_coords(f, fx, fy, c);
				const int i = c[0], j = c[1], k = c[2];
				const size_t g0 = (size_t)i + sy * (size_t)j + sz * (size_t)k;
				const size_t g[4] = {g0, g0 + s1, g0 + s1 + s2, g0 + s2};
				if ((c[a] == 0 || c[a] == n[a]) && !open_sides) { /* the domain's sides: still, closed */
					wt[slot] = 0.0f;
					fv[slot++] = 0.0f;
					continue;
				}
				const float fin = frac_inside(phi[g[0]], phi[g[1]], phi[g[2]], phi[g[3]]);
				/* tiny openings are closed: a weight of 1e-6 only conditions A badly */
				float wf = 1.0f - fin;
				if (wf < 1e-3f)
					wf = 0.0f;
				float wb = box_on ? box_face_open(&bc, a, c) : 1.0f;
				wb = wb < 1e-3f ? 0.0f : wb;
				if (wb < wf) { /* the box closes more of it than the colliders: still */
					wt[slot] = wb;
					fv[slot++] = 0.0f;
					continue;
				}
				wt[slot] = wf;
				int best = 0;
				for (int e = 1; e < 4; ++e)
					if (phi[g[e]] < phi[g[best]])
						best = e;
				const uint16_t ow = own[g[best]];
				eddy_vec3 v = ow ? vel[ow - 1] : (eddy_vec3){0, 0, 0};
				if (ow && omega && (omega[ow - 1].x != 0 || omega[ow - 1].y != 0 || omega[ow - 1].z != 0)) {
					/* a turning solid: its point velocity at the face's centre */
					const eddy_collider_velocity rv = {v, omega[ow - 1], center[ow - 1]};
					const eddy_vec3 fc = {(float)(o.x + (i + 0.5 * (a != 0)) * h),
					                      (float)(o.y + (j + 0.5 * (a != 1)) * h),
					                      (float)(o.z + (k + 0.5 * (a != 2)) * h)};
					v = eddy__rigid_velocity(&rv, fc);
				}
				fv[slot++] = a == 0 ? v.x : a == 1 ? v.y : v.z;
			}
		}
	}
	{
		float *op = openv;
		const long nw = (long)nwc;
#pragma omp parallel for num_threads(ntp) if (ntp > 1) schedule(static)
		for (long q = 0; q < nw; ++q) {
			uint64_t word = cmark[q];
			size_t slot = crank[q];
			while (word) {
				const size_t c = (size_t)q * 64 + (size_t)__builtin_ctzll(word);
				word &= word - 1;
				int cc[3];
				grid_coords(c, (size_t)nx, (size_t)ny, cc);
				const float oc = open_of(cphi[c], hf), ob = box_cell_open(&bc, cc);
				op[slot++] = ob < oc ? ob : oc;
			}
		}
	}
	if (store)
		eddy__arena_release(&w->arena, am);
	return true;
}

bool eddy__flip_box_walls(const eddy_world *w)
{
	eddy_system_iter it = eddy__systems(w, EDDY_CAP_SOLID_FACES);
	const eddy_system *c = eddy__systems_next(&it);
	return c && !((const boundary *)c->data)->def.open_sides;
}

bool eddy__flip_open_sides(const eddy_world *w)
{
	eddy_system_iter it = eddy__systems(w, EDDY_CAP_SOLID_FACES);
	const eddy_system *c = eddy__systems_next(&it);
	return c && ((const boundary *)c->data)->def.open_sides;
}

bool eddy__flip_boundary_info(const eddy_world *w, float *margin, const eddy_vec3 **vel)
{
	eddy_system_iter it = eddy__systems(w, EDDY_CAP_SOLID_FACES);
	const eddy_system *c = eddy__systems_next(&it);
	if (!c)
		return false;
	const boundary *b = c->data;
	*margin = b->def.margin;
	if (vel)
		*vel = b->vel_step == w->step && b->cap == w->order_count ? b->vel : NULL;
	return true;
}

bool eddy__flip_boundary_solid(const eddy_world *w, const eddy_system *self, flip_solid *sd)
{
	int at = -1;
	for (int q = 0; q < w->order_count; ++q)
		if (&w->slots[w->order[q]] == self)
			at = q;
	for (int q = at - 1; q >= 0; --q) {
		const eddy_system *c = &w->slots[w->order[q]];
		if (c->vt->provides & EDDY_CAP_SOLID_FACES) {
			const boundary *b = c->data;
			if (b->sd_step != w->step)
				return false;
			*sd = b->sd;
			return true;
		}
		/* past a system that may move a solid, the geometry is not flip_boundary's */
		if (!c->vt->keeps_solids)
			return false;
	}
	return false;
}

bool eddy__flip_solid_for(eddy_world *w, const eddy_system *self, double dt, flip_solid *sd)
{
	memset(sd, 0, sizeof *sd);
	if (eddy__flip_boundary_solid(w, self, sd))
		return true;
	float margin = 0;
	const eddy_vec3 *svel = NULL;
	return !eddy__flip_boundary_info(w, &margin, &svel) || eddy__flip_solid_faces(w, dt, margin, svel, sd, NULL);
}

/* The solids' velocities for this step, per pipeline position. A collider's
 * own motion record (offset - last offset) is its velocity only when the
 * host set the offset before this system ran; an offset function in a scene
 * (eddy_lua.c's animate step) sets it after flip_advect, just before the
 * collider runs and marks it used, so here offset == last offset and the
 * record says "still" while the solid moves by a cell a step (the issue's
 * sphere scene lost 59% of its water that way). So this system remembers the
 * offset it saw at its last step: velocity = (offset - seen) / dt. With the
 * host setting the offset first that is (pos(t + dt) - pos(t)) / dt, exact;
 * with an offset function it is the last step's displacement, a step late,
 * while the geometry is the one at the start of the step. With no memory
 * (first step, a changed pipeline) the motion record is used. */
/* Sizes the per-position arrays for the pipeline (a changed pipeline forgets
 * what was seen). */
static bool fit(boundary *b, int n)
{
	if (b->cap == n)
		return true;
	free(b->seen);
	free(b->vel);
	free(b->omega);
	free(b->center);
	b->seen = calloc((size_t)n + 1, sizeof *b->seen);
	b->vel = calloc((size_t)n + 1, sizeof *b->vel);
	b->omega = calloc((size_t)n + 1, sizeof *b->omega);
	b->center = calloc((size_t)n + 1, sizeof *b->center);
	b->cap = n;
	if (!b->seen || !b->vel || !b->omega || !b->center) {
		b->cap = -1;
		return false;
	}
	return true;
}

static bool solid_velocities(eddy_world *w, boundary *b, const eddy_step_context *ctx)
{
	const int n = w->order_count;
	if (!fit(b, n))
		return false;
	const double inv_dt = ctx->dt > 0 ? 1.0 / ctx->dt : 0.0;
	for (int q = 0; q < n; ++q) {
		const eddy_system *c = &w->slots[w->order[q]];
		if (!eddy__is_collider(c)) {
			b->seen[q].have = 0;
			continue;
		}
		const eddy_collider_motion m = ((const eddy_collider_base *)c->data)->motion;
		const eddy_vec3 ref =
			b->seen[q].have != 0 ? (eddy_vec3){b->seen[q].x, b->seen[q].y, b->seen[q].z} : m.last_offset;
		const eddy_vec3 rref =
			b->seen[q].have != 0 ? (eddy_vec3){b->seen[q].rx, b->seen[q].ry, b->seen[q].rz} : m.last_rotation;
		b->vel[q] = (eddy_vec3){(float)((m.offset.x - ref.x) * inv_dt), (float)((m.offset.y - ref.y) * inv_dt),
		                        (float)((m.offset.z - ref.z) * inv_dt)};
		b->omega[q] = eddy__rotation_rate(rref, m.rotation, ctx->dt);
		b->center[q] = eddy__add3(m.pivot, m.offset);
		b->seen[q] =
			(struct seen_offset){m.offset.x, m.offset.y, m.offset.z, 1, m.rotation.x, m.rotation.y, m.rotation.z, 0};
	}
	b->vel_step = ctx->step;
	return true;
}

/* Writes this step's key into the first half of b->key (the second holds
 * the one sd was computed from): entry 0 the grid and margin, then one per
 * collider. Returns the entries, -1 when out of memory. */
static int solid_key_of(const eddy_world *w, boundary *b)
{
	const int want = 2 * (w->order_count + 1);
	if (b->key_cap < want) {
		solid_key *k = calloc((size_t)want, sizeof *k);
		if (!k)
			return -1;
		free(b->key);
		b->key = k;
		b->key_cap = want;
		b->nkey = 0;
	}
	solid_key *key = b->key;
	int n = 0;
	memset(&key[n], 0, sizeof key[n]);
	key[n].slot = w->nx, key[n].generation = w->ny;
	key[n].pose[0] = (float)w->nz, key[n].pose[1] = (float)w->def.cell_size;
	key[n].pose[2] = w->def.bounds_min.x, key[n].pose[3] = w->def.bounds_min.y;
	key[n].pose[4] = w->def.bounds_min.z, key[n].pose[5] = b->def.margin;
	n++;
	for (int q = 0; q < w->order_count; ++q) {
		const eddy_system *c = &w->slots[w->order[q]];
		if (!eddy__is_collider(c))
			continue;
		const eddy_collider_motion *m = &((const eddy_collider_base *)c->data)->motion;
		key[n] = (solid_key){(int32_t)w->order[q],
		                     c->generation,
		                     {m->offset.x, m->offset.y, m->offset.z, m->rotation.x, m->rotation.y, m->rotation.z,
		                      m->pivot.x, m->pivot.y, m->pivot.z},
		                     {b->vel[q].x, b->vel[q].y, b->vel[q].z, b->omega[q].x, b->omega[q].y, b->omega[q].z,
		                      b->center[q].x, b->center[q].y, b->center[q].z}};
		n++;
	}
	return n;
}

static eddy_status step(eddy_world *w, eddy_system *s, const eddy_step_context *ctx)
{
	boundary *b = s->data;
	const int nx = w->nx, ny = w->ny, nz = w->nz;
	if (!solid_velocities(w, b, ctx))
		return eddy__fail(w, EDDY_ERR_NOMEM, "flip_boundary: out of memory");
	uint8_t *type = (uint8_t *)w->columns[COL_CELL_TYPE].data;
	float *face[3] = {eddy__col(w, COL_FACE_U), eddy__col(w, COL_FACE_V), eddy__col(w, COL_FACE_W)};
	const int nkey = solid_key_of(w, b); /* resets b->nkey when the key array regrows */
	if (nkey < 0)
		return eddy__fail(w, EDDY_ERR_NOMEM, "flip_boundary: out of memory");
	/* still solids (a tank) keep the faces last computed: the same inputs
	 * give the same faces, so reusing them changes no bit */
	const bool same = b->sd_step >= 0 && nkey == b->nkey &&
	                  memcmp(b->key, b->key + b->key_cap / 2, (size_t)nkey * sizeof *b->key) == 0;
	b->sd_step = -1;
	if (!same) {
		b->nkey = 0; /* until the faces are whole */
		if (!eddy__flip_solid_faces(w, ctx->dt, b->def.margin, b->vel, &b->sd, &b->store))
			return eddy__fail(w, EDDY_ERR_NOMEM, "flip_boundary: out of memory");
		memcpy(b->key + b->key_cap / 2, b->key, (size_t)nkey * sizeof *b->key);
		b->nkey = nkey;
	}
	b->sd_step = ctx->step;
	const flip_solid sd = b->sd;
	/* closed faces take the solid's normal velocity; domain sides are still
	 * unless open (each face written once: on all threads) */
	const bool open_sides = b->def.open_sides;
	const int nt = (size_t)nx * ny * nz > 32768 ? ctx->threads : 1;
	for (int a = 0; a < 3; ++a) {
		const int fx = nx + (a == 0), fy = ny + (a == 1), fz = nz + (a == 2);
#pragma omp parallel for num_threads(nt) if (nt > 1) schedule(static)
		for (int k = 0; k < fz; ++k)
			for (int j = 0; j < fy; ++j)
				for (int i = 0; i < fx; ++i) {
					const size_t f = (size_t)i + (size_t)fx * ((size_t)j + (size_t)fy * (size_t)k);
					const int c[3] = {i, j, k}, n[3] = {nx, ny, nz};
					if ((c[a] == 0 || c[a] == n[a]) && !open_sides)
						face[a][f] = 0;
					else if (sd.any) {
						size_t q;
						if (flip_marked(sd.mark[a], sd.rank[a], f, &q) && sd.wt[a][q] == 0)
							face[a][f] = sd.vel[a][q];
					}
				}
	}
	if (!sd.any)
		return EDDY_OK;
	/* cells whose centre is in the solid (open fraction < 1/2) are typed
	 * solid, as before: flip_extrapolate keeps their faces and flip_surface
	 * stops its blur there; flip_pressure still solves for the cut ones with
	 * an open face (the type no longer means "no fluid") */
	/* not where the box's cut makes it so (flip_grid's top): a cell of the
	 * box's last row holds water or air as any cell, only smaller, and as
	 * a solid-typed cell out of the system its face to the water below it
	 * would be a given flux, so water against the box's face fell freely */
	const long nc = (long)nx * ny * nz;
	const flip_grid bc = flip_grid_of(w);
#pragma omp parallel for num_threads(nt) if (nt > 1) schedule(static)
	for (long c = 0; c < nc; ++c) {
		const float op = flip_solid_open(&sd, (size_t)c);
		if (!(op < 0.5f))
			continue;
		int cc[3];
		grid_coords((size_t)c, (size_t)nx, (size_t)ny, cc);
		if (!(box_cell_open(&bc, cc) <= op))
			type[c] = EDDY_CELL_SOLID;
	}
	return EDDY_OK;
}

static void destroy(eddy_system *s)
{
	boundary *b = s->data;
	if (!b)
		return;
	free(b->seen);
	free(b->vel);
	free(b->omega);
	free(b->center);
	free(b->store.mem);
	free(b->key);
}

static void *state(eddy_world *w, eddy_system *s, size_t *size)
{
	boundary *b = s->data;
	if (!fit(b, w->order_count)) {
		*size = 0;
		return NULL;
	}
	*size = (size_t)b->cap * sizeof *b->seen;
	return b->seen;
}

const eddy_system_vtable eddy__kind_flip_boundary = {
	.name = "flip_boundary",
	.provides = EDDY_CAP_SOLID_FACES,
	.state = state,
	.step = step,
	.destroy = destroy,
	.default_writes = boundary_io,
};

eddy_system_id eddy_add_flip_boundary(eddy_world *w, const eddy_flip_boundary_def *def)
{
	const char *sys = "flip_boundary";
	if (!eddy__add_args(w, def, sys))
		return EDDY_NULL_SYSTEM;
	if (!eddy__check_nonneg(w, sys, "margin", def->margin) || !eddy__check_finite(w, sys, "margin", def->margin))
		return EDDY_NULL_SYSTEM;
	boundary *b = calloc(1, sizeof *b);
	if (b) {
		b->def = *def;
		b->vel_step = -1;
		b->sd_step = -1;
	}
	return eddy__add_system(w, &eddy__kind_flip_boundary, b, boundary_io, boundary_io);
}
