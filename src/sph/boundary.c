/* SPDX-License-Identifier: MIT */
/* Boundary particles for the neighbour search: the walls of every
 * sph_boundary_box and the colliders, as frozen fluid (Akinci, Ihmsen,
 * Akinci, Solenthaler & Teschner, "Versatile rigid-fluid coupling for
 * incompressible SPH", SIGGRAPH 2012).
 *
 * Reads: the pipeline's boundary systems and colliders. Writes: sph_neighbors'
 * bx by bz bvol bp bdiv and its private sph_boundary.
 *
 * The boxes' particles are static: gathered and cell-sorted once, and again
 * only when the set of boundary systems (the signature) changes. The
 * colliders' are made once in the def pose (each collider file samples its
 * own, see sph.h) and moved every step:
 *   translating:  x_b = x_b0 + offset (a plane's patch only along its normal),
 *                 v_b = (offset - offset seen last step) / time since
 *                 (as sys_flip_boundary.c takes it);
 *   rotating:     x_b = pivot + offset + R (x_b0 - pivot),
 *                 v_b = v + omega x (x_b - pivot - offset), omega from the
 *                 orientation seen last step over the time since.
 * A moved set's displacement since the last Verlet search (for a rotating
 * one bounded by the pivot's move plus its reach times the angle turned)
 * counts in the search's displacement test like a particle's. Each search
 * cell-sorts every boundary particle anew (order) and sorts each fluid
 * particle's boundary hits by index, so the lists and sums do not depend on
 * when the search ran; the seen poses are sph_density's checkpointed state,
 * so a resumed run stays bit-identical. bdiv, the density change rate the
 * moving walls add (Akinci et al. 2012, eq. 6 with the wall's velocity), is
 * made here for sph_dfsph. */
#include "neighbors.h"
#include "systems.h"

#include <stdlib.h>
#include <string.h>

/* Which boundary systems there are: every sph_boundary_box and every
 * collider (a collider without particles changes nothing but this). */
static uint64_t boundary_signature(const eddy_world *w)
{
	uint64_t sig = 0x9E3779B97F4A7C15ull;
	const eddy_system *o;
	for (eddy_system_iter it = eddy__systems(w, EDDY_CAP_SPH_WALLS | EDDY_CAP_COLLIDER); (o = eddy__systems_next(&it));)
		sig = (sig ^ ((uint64_t)(o - w->slots) << 16 | o->generation)) * 0x100000001b3ull;
	return sig;
}

void sph_boundary_free(sph_neighbors *nb)
{
	free(nb->bx); /* by, bz, bvol in the same block */
	free(nb->bp); /* rho and seen in the same block */
	free(nb->bdiv);
	free(nb->bnd.x0); /* y0 z0 vx vy vz order in the same block */
	free(nb->bnd.col);
	nb->bx = nb->by = nb->bz = nb->bvol = nb->bp = nb->bdiv = NULL;
	nb->nbound = 0;
	memset(&nb->bnd, 0, sizeof nb->bnd);
}

static bool nonzero(eddy_vec3 a) { return a.x != 0 || a.y != 0 || a.z != 0; }

static bool differ(eddy_vec3 a, eddy_vec3 b) { return a.x != b.x || a.y != b.y || a.z != b.z; }

/* Every collider's particles where their collider is now, and their
 * velocities (once per time). Returns the largest squared displacement of
 * any of them since the search: a bound for a rotating set. */
float sph_boundary_move(const eddy_world *w, sph_neighbors *nb)
{
	sph_boundary *bd = &nb->bnd;
	float moved2 = 0;
	for (int c = 0; c < bd->ncol; ++c) {
		struct sph_collider_set *cs = &bd->col[c];
		struct sph_collider_seen *sn = &bd->seen[c];
		const eddy_collider_motion *m = &((const eddy_collider_base *)w->slots[cs->slot].data)->motion;
		const eddy_vec3 off = m->offset, rot = m->rotation, n = cs->normal;
		/* placed by the whole pose also while a past rotation is still undone */
		const bool rotating = eddy__motion_rotates(m) || nonzero(eddy__v3(sn->rx, sn->ry, sn->rz)) ||
		                      nonzero(cs->rot) || nonzero(cs->rot_at_search);
		const bool plane = !rotating && nonzero(n); /* only the offset along the normal moves the patch */
		const float along = off.x * n.x + off.y * n.y + off.z * n.z;
		const eddy_vec3 d = plane ? eddy__v3(along * n.x, along * n.y, along * n.z) : off;
		if (differ(d, cs->disp) || differ(rot, cs->rot)) {
			const eddy_collider_pose pose = eddy__collider_pose(m);
			for (size_t b = cs->first; b < cs->first + cs->count; ++b) {
				const eddy_vec3 q0 = eddy__v3(bd->x0[b], bd->y0[b], bd->z0[b]);
				const eddy_vec3 q = rotating ? eddy__pose_to_world(&pose, q0) : eddy__add3(q0, d);
				nb->bx[b] = q.x, nb->by[b] = q.y, nb->bz[b] = q.z;
			}
			cs->disp = d;
			cs->rot = rot;
		}
		if (sn->have == 0 || w->time != sn->time) {
			eddy_collider_velocity mv = {{0, 0, 0}, {0, 0, 0}, eddy__add3(m->pivot, off)};
			const bool since = sn->have != 0 && w->time > sn->time;
			if (since && rotating)
				mv = eddy__collider_motion_since(m, eddy__v3(sn->x, sn->y, sn->z), eddy__v3(sn->rx, sn->ry, sn->rz),
				                                 w->time - sn->time);
			else if (since) {
				const float inv = (float)(1.0 / (w->time - sn->time));
				mv.v = eddy__v3((off.x - sn->x) * inv, (off.y - sn->y) * inv, (off.z - sn->z) * inv);
				const float vn = mv.v.x * n.x + mv.v.y * n.y + mv.v.z * n.z;
				mv.v = plane ? eddy__v3(vn * n.x, vn * n.y, vn * n.z) : mv.v;
			}
			for (size_t b = cs->first; b < cs->first + cs->count; ++b) {
				const eddy_vec3 v =
					rotating ? eddy__rigid_velocity(&mv, eddy__v3(nb->bx[b], nb->by[b], nb->bz[b])) : mv.v;
				bd->vx[b] = v.x, bd->vy[b] = v.y, bd->vz[b] = v.z;
			}
			*sn = (struct sph_collider_seen){off.x, off.y, off.z, 1, rot.x, rot.y, rot.z, 0, w->time};
		}
		const float ex = d.x - cs->at_search.x, ey = d.y - cs->at_search.y, ez = d.z - cs->at_search.z;
		float m2 = ex * ex + ey * ey + ez * ez;
		if (rotating) {
			const eddy_vec3 om = eddy__rotation_rate(cs->rot_at_search, rot, 1.0);
			const float m1 = sqrtf(m2) + cs->reach * sqrtf(om.x * om.x + om.y * om.y + om.z * om.z);
			m2 = m1 * m1;
		}
		moved2 = m2 > moved2 ? m2 : moved2;
	}
	return moved2;
}

/* The cell order of every boundary particle now, for a search (with
 * collider particles only: the static ones are stored in cell order). */
eddy_status sph_boundary_sort(eddy_world *w, sph_neighbors *nb)
{
	sph_boundary *bd = &nb->bnd;
	if (!bd->order)
		return EDDY_OK;
	const size_t total = nb->nbound;
	const eddy_arena_mark mark = eddy__arena_mark(&w->arena); /* key: the sort's own */
	uint32_t *key = eddy__arena_alloc(&w->arena, (total ? total : 1) * sizeof *key);
	if (!key)
		return eddy__fail(w, EDDY_ERR_NOMEM, "sph_density: out of scratch memory for %zu boundary particles", total);
	for (size_t i = 0; i < total; ++i)
		key[i] = sph_cell_at(&nb->grid, nb->bx[i], nb->by[i], nb->bz[i]);
	const bool sorted = sph_counting_sort(key, total, &nb->grid, &nb->grid.bound_start, bd->order);
	eddy__arena_release(&w->arena, mark);
	if (!sorted)
		return eddy__fail(w, EDDY_ERR_NOMEM, "sph_density: out of memory for the neighbour cells");
	for (int c = 0; c < bd->ncol; ++c) {
		bd->col[c].at_search = bd->col[c].disp;
		bd->col[c].rot_at_search = bd->col[c].rot;
	}
	return EDDY_OK;
}

/* The arrays for total particles, ncol collider sets among them:
 * bx by bz bvol in one block, bp rho and the seen poses in another
 * (sph_density's checkpointed state: after 2 total floats the records are
 * 8-byte aligned, since with colliders alloc = total), x0 .. order in a
 * third (velocities 0: the static particles' stay so). */
static bool boundary_alloc(sph_neighbors *nb, size_t total, size_t ncol)
{
	sph_boundary *bd = &nb->bnd;
	const size_t alloc = total ? total : 1;
	bd->state_size = 2 * total * sizeof *nb->bp + ncol * sizeof *bd->seen;
	nb->bp = calloc(1, 2 * alloc * sizeof *nb->bp + ncol * sizeof *bd->seen);
	if (!nb->bp)
		return false;
	bd->rho = nb->bp + alloc;
	bd->seen = ncol ? (struct sph_collider_seen *)(void *)(nb->bp + 2 * alloc) : NULL;
	void *block = NULL, *moving_block = NULL;
	size_t have = 0, moving_have = 0;
	void **stat[] = {(void **)&nb->bx, (void **)&nb->by, (void **)&nb->bz, (void **)&nb->bvol};
	if (!sph_grow_block(&block, &have, alloc, stat, 4))
		return false;
	if (!ncol)
		return true;
	void **moving[] = {(void **)&bd->x0, (void **)&bd->y0, (void **)&bd->z0,   (void **)&bd->vx,
	                   (void **)&bd->vy, (void **)&bd->vz, (void **)&bd->order};
	bd->col = calloc(ncol, sizeof *bd->col);
	if (!bd->col || !sph_grow_block(&moving_block, &moving_have, alloc, moving, 7))
		return false;
	memset(bd->vx, 0, 3 * moving_have * sizeof *bd->vx);
	return true;
}

/* The particles into the arrays: the boundary boxes' through x (6 nstat
 * entries), cell-sorted into [0, nstat); the colliders' after them in
 * pipeline order, each set in its collider's def pose. */
static eddy_status boundary_place(eddy_world *w, sph_shared *sh, float spacing, size_t nstat, float *x)
{
	sph_neighbors *nb = &sh->nb;
	sph_boundary *bd = &nb->bnd;
	const size_t alloc = nstat ? nstat : 1;
	/* x y z vol as floats, key order as indices */
	float *y = x + alloc, *z = y + alloc, *v = z + alloc;
	uint32_t *key = (uint32_t *)(void *)(v + alloc), *order = key + alloc;
	size_t at_stat = 0, at = nstat;
	eddy_vec3 normal;
	const eddy_system *o;
	for (eddy_system_iter it = eddy__systems(w, EDDY_CAP_SPH_WALLS | EDDY_CAP_COLLIDER);
	     (o = eddy__systems_next(&it));) {
		if (o->vt->provides & EDDY_CAP_SPH_WALLS) {
			at_stat += eddy__sph_boundary_box_points(o, sh->h, x + at_stat, y + at_stat, z + at_stat, v + at_stat);
			continue;
		}
		const size_t want = eddy__sph_collider_points(w, o, spacing, sh->h, NULL, NULL, NULL, NULL, &normal);
		if (!want)
			continue;
		if (eddy__sph_collider_points(w, o, spacing, sh->h, bd->x0 + at, bd->y0 + at, bd->z0 + at, nb->bvol + at,
		                              &normal) != want)
			return eddy__fail(w, EDDY_ERR_NOMEM, "sph_density: out of memory for the boundary particles of %s",
			                  o->label);
		struct sph_collider_set *cs = &bd->col[bd->ncol++];
		*cs = (struct sph_collider_set){.slot = (int)(o - w->slots), .first = at, .count = want, .normal = normal};
		cs->disp = eddy__v3(NAN, NAN, NAN); /* placed by sph_boundary_move */
		const eddy_vec3 pv = ((const eddy_collider_base *)o->data)->motion.pivot;
		for (; at < cs->first + want; ++at) {
			const float dx = bd->x0[at] - pv.x, dy = bd->y0[at] - pv.y, dz = bd->z0[at] - pv.z;
			cs->reach = fmaxf(cs->reach, sqrtf(dx * dx + dy * dy + dz * dz));
		}
	}
	for (size_t i = 0; i < nstat; ++i)
		key[i] = sph_cell_at(&nb->grid, x[i], y[i], z[i]);
	if (!sph_counting_sort(key, nstat, &nb->grid, &nb->grid.bound_start, order))
		return eddy__fail(w, EDDY_ERR_NOMEM, "sph_density: out of memory for the neighbour cells");
	for (size_t i = 0; i < nstat; ++i) {
		nb->bx[i] = x[order[i]];
		nb->by[i] = y[order[i]];
		nb->bz[i] = z[order[i]];
		nb->bvol[i] = v[order[i]];
	}
	return EDDY_OK;
}

/* boundary_place with its scratch in pages of its own, not the arena: made
 * once, in the first step, it would add its 24 bytes a boundary particle to
 * that step's arena blocks, the peak's moment. */
static eddy_status boundary_fill(eddy_world *w, sph_shared *sh, float spacing, size_t nstat)
{
	float *x = eddy__pages_alloc(6 * (nstat ? nstat : 1) * sizeof *x);
	if (!x)
		return eddy__fail(w, EDDY_ERR_NOMEM, "sph_density: out of memory for %zu boundary particles", nstat);
	const eddy_status st = boundary_place(w, sh, spacing, nstat, x);
	eddy__pages_free(x);
	return st;
}

/* The boundary particles of the pipeline's boundary systems, made again
 * only when they change. */
eddy_status sph_boundary_build(eddy_world *w, sph_shared *sh)
{
	sph_neighbors *nb = &sh->nb;
	const uint64_t sig = boundary_signature(w);
	if (sig == nb->bnd.sig && nb->bx)
		return EDDY_OK;
	/* the fluid spacing: that of the sph_density that owns sh */
	float spacing = sh->h / 2;
	const eddy_system *o;
	for (eddy_system_iter it = eddy__systems(w, EDDY_CAP_SPH_NEIGHBORS); (o = eddy__systems_next(&it));)
		if (o->vt->shared(o, EDDY_CAP_SPH_NEIGHBORS) == sh && eddy__sph_density_def(o))
			spacing = eddy__sph_density_def(o)->spacing;
	size_t nstat = 0, ncolp = 0, ncol = 0;
	eddy_vec3 normal;
	for (eddy_system_iter it = eddy__systems(w, EDDY_CAP_SPH_WALLS | EDDY_CAP_COLLIDER);
	     (o = eddy__systems_next(&it));) {
		if (o->vt->provides & EDDY_CAP_SPH_WALLS) {
			nstat += eddy__sph_boundary_box_points(o, sh->h, NULL, NULL, NULL, NULL);
			continue;
		}
		const size_t c = eddy__sph_collider_points(w, o, spacing, sh->h, NULL, NULL, NULL, NULL, &normal);
		ncolp += c;
		ncol += c > 0;
	}
	/* a plane's patch spans the world bounds: 5e7 particles is about 2 GB */
	if ((double)ncolp > 5e7)
		return eddy__fail(w, EDDY_ERR_NOMEM,
		                  "sph_density: the colliders need %.0f boundary particles (at most 5e7); shrink the world "
		                  "bounds or the colliders, or use a larger spacing",
		                  (double)ncolp);
	const size_t total = nstat + ncolp;
	sph_boundary_free(nb);
	nb->bnd.n_static = nstat;
	const eddy_status st =
		boundary_alloc(nb, total, ncol)
			? boundary_fill(w, sh, spacing, nstat)
			: eddy__fail(w, EDDY_ERR_NOMEM, "sph_density: out of memory for %zu boundary particles", total);
	if (st != EDDY_OK) {
		sph_boundary_free(nb);
		return st;
	}
	for (size_t i = 0; i < total; ++i)
		nb->bnd.rho[i] = sh->rho0;
	nb->nbound = total;
	if (nb->bnd.ncol) {
		sph_boundary_move(w, nb);
		for (size_t i = 0; i < total; ++i)
			nb->bnd.order[i] = (uint32_t)i; /* the first search sorts them */
	}
	nb->bnd.sig = sig;
	return EDDY_OK;
}

eddy_status eddy__sph_boundary_ready(eddy_world *w, sph_shared *sh)
{
	eddy_status st = sph_grid_init(w, &sh->nb.grid, sh->h);
	return st == EDDY_OK ? sph_boundary_build(w, sh) : st;
}

/* nb->bdiv: sum_b V_b rho0 v_b . grad W_spiky(x_i - x_b) per row, with
 * sph_dfsph's kernel gradient and cut-offs; NULL while no wall moves.
 * Only the walls' velocity along their normal counts: v_b is replaced by
 * (v_b . n_i) n_i, n_i the gradient of b's collider's signed distance at
 * x_i (its normal there; the direction of the boundary particles' own sum
 * carries the same lattice error). Over a continuous wall the sum is the
 * surface integral of W (v . n) (a rigid motion has no divergence), so a
 * wall sliding along itself changes no density; its lattice, passing under
 * a particle, gave the sum a part along the normal, and a floor sliding at
 * 5 m/s under a pool lifted it (its energy +4.4% in 0.3 s at 1 cm:
 * tests/test_physics.c, floor_sliding_under_a_pool_does_no_work). */
eddy_status sph_boundary_divergence(eddy_world *w, sph_shared *sh, int threads)
{
	sph_neighbors *nb = &sh->nb;
	const sph_boundary *bd = &nb->bnd;
	bool moving = false;
	for (size_t b = bd->n_static; b < nb->nbound && !moving; ++b)
		moving = bd->vx[b] != 0 || bd->vy[b] != 0 || bd->vz[b] != 0;
	if (!moving || !sh->pq) {
		free(nb->bdiv);
		nb->bdiv = NULL;
		nb->bnd.div_alloc = 0;
		return EDDY_OK;
	}
	const size_t n = nb->n;
	if (!sph_grow((void **)&nb->bdiv, &nb->bnd.div_alloc, n, sizeof *nb->bdiv))
		return eddy__fail(w, EDDY_ERR_NOMEM, "sph_density: out of memory for %zu particles", n);
	const float h = sh->k.h, eps2 = 1e-6f * sh->k.h2, c0 = sh->rho0 * sh->k.spiky_grad;
	const float *p4 = sh->pq;
	const long ln = (long)n;
#pragma omp parallel for num_threads(threads) schedule(static)
	for (long i = 0; i < ln; ++i) {
		const uint32_t *bl = sph_bnbrs(nb, i);
		const eddy_vec3 pi = {p4[4 * i], p4[4 * i + 1], p4[4 * i + 2]};
		float u = 0;
		int cur = -1; /* the collider whose normal n holds */
		float nx = 0, ny = 0, nz = 0;
		for (uint32_t q = 0; q < nb->bcount[i]; ++q) {
			const uint32_t b = bl[q];
			if (b < bd->n_static)
				continue; /* at rest */
			const float rx = pi.x - nb->bx[b], ry = pi.y - nb->by[b], rz = pi.z - nb->bz[b];
			const float r2 = rx * rx + ry * ry + rz * rz, r = sqrtf(r2), hr = h - r;
			if (!(r2 > eps2 && hr > 0))
				continue;
			int c = cur;
			if (c < 0 || b < bd->col[c].first || b >= bd->col[c].first + bd->col[c].count)
				for (c = 0; c < bd->ncol; ++c)
					if (b >= bd->col[c].first && b < bd->col[c].first + bd->col[c].count)
						break;
			if (c >= bd->ncol)
				continue;
			if (c != cur) { /* the collider's distance gradient at i: its normal there */
				const eddy_system *col = &w->slots[bd->col[c].slot];
				const float e = 0.25f * h;
				float g[3];
				for (int a = 0; a < 3; ++a) {
					eddy_vec3 hi = pi, lo = pi;
					(&hi.x)[a] += e, (&lo.x)[a] -= e;
					g[a] = col->vt->distance(col, hi) - col->vt->distance(col, lo);
				}
				const float len = sqrtf(g[0] * g[0] + g[1] * g[1] + g[2] * g[2]);
				nx = len > 0 ? g[0] / len : 0, ny = len > 0 ? g[1] / len : 0, nz = len > 0 ? g[2] / len : 0;
				cur = c;
			}
			const float vn = nx * bd->vx[b] + ny * bd->vy[b] + nz * bd->vz[b];
			const float c0r = nb->bvol[b] * c0 * hr * hr / r;
			u += c0r * vn * (rx * nx + ry * ny + rz * nz);
		}
		nb->bdiv[i] = u;
	}
	return EDDY_OK;
}
