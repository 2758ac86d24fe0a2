/* SPDX-License-Identifier: MIT */
/* SPH neighbour lists: a Verlet list over a uniform grid, filtered every
 * step into exact lists.
 *
 * Every step: the cell (size h/2) of every particle, and unless the table is
 * still in cell order (a fluid at rest), a counting sort by cell (stable, so
 * the order is deterministic) and the whole particle table permuted into
 * cell order (eddy__permute_particles), so the passes over neighbours stream
 * memory.
 *
 * The grid search, the costly part, runs only when the Verlet list is stale.
 * It works on blocks of 4 x 2 x 2 cells: the runs of cells around a block
 * (with x fastest, the cells along x are one contiguous run of rows) are
 * gathered once into one buffer, in cell order, and each particle of the
 * block tests the whole buffer, eight at a time, packing its hits without a
 * branch (see SEARCH_BX). The hits are r^2 < h_s^2, h_s = h (1 + skin), in
 * the rows of that time ("build slots"); the permutations of later steps are
 * followed with slot_of / now_of. The list stays valid while every particle
 * is within skin/2 of where it was at the search: then a pair closer than h
 * now was closer than h + skin then. A change in the particle count or in
 * the boundary systems also forces a search. Any row may hold any particle
 * (a swap-remove, a loaded checkpoint): the argument is about positions, so
 * the displacement test covers that as well. With a skin of 0 (a list that
 * would not outlive a few steps, see below) the search is at h itself and
 * writes the exact lists and kernel sums directly, with the filter's tests,
 * order and sums, so it gives the same bits as a search plus a filter.
 *
 * Every step each particle's Verlet candidates are filtered by r^2 < h^2 into
 * its exact list, sorted by index, and the density's kernel sums are made
 * from it in that order. Since the particle order is a function of the
 * positions alone (a stable sort of the table each step), the exact lists
 * and sums are the same whenever the last search ran: a resumed run is
 * bit-identical without checkpointing the Verlet list.
 *
 * Both lists are stored with a fixed stride per particle (the Verlet one
 * wider); when a particle has more entries than a stride (compressed fluid),
 * the stride grows and that pass runs again. Every particle writes only its
 * own lists, so they are identical for any thread count. The filter has an
 * AVX2 path (chosen at run time) giving the same lists as the SSE one.
 *
 * Boundary particles: those of the sph_boundary_box systems are static:
 * gathered and cell-sorted once, and again only when the set of boundary
 * systems changes. Those of the colliders (sphere, plane, block box: Akinci,
 * Ihmsen, Akinci, Solenthaler & Teschner, "Versatile rigid-fluid coupling for
 * incompressible SPH", SIGGRAPH 2012; each collider file samples its own,
 * see sph.h) follow them after, made once in the collider's def pose and
 * moved every step by its offset (a plane's patch only along its normal),
 * with the velocity (offset - offset seen at the last step) / time since,
 * as sys_flip_boundary.c takes it. A rotating collider's particles are
 * placed by its whole pose, pivot + offset + R (x_b0 - pivot), and carry
 * the point velocity v + omega x (x_b - pivot - offset), omega the rotation
 * from the orientation seen at the last step over the time since; their
 * Verlet displacement is bounded by the pivot's move plus the set's reach
 * from the pivot times the angle turned. Their motion since the last search
 * counts in the Verlet displacement test like a particle's; at each search
 * every boundary particle is cell-sorted anew (border), and each particle's
 * boundary hits are sorted by index, so the lists and sums are the same
 * whenever the search ran (a resumed run stays bit-identical; the seen
 * offsets are sph_density's checkpointed state). bdiv, the density change
 * the moving walls add, is made here for sph_dfsph. sph_density's wall
 * pressure (Adami et al. 2012, eq. 27) leaves out the wall's acceleration.
 * A scene with no collider particles takes the static path unchanged. */
#include "sph.h"
#include "systems.h"

#include <stdlib.h>
#include <string.h>
#ifdef __SSE2__
#include <emmintrin.h>
#endif

static void boundary_free(sph_neighbors *nb);

void eddy__sph_neighbors_free(sph_neighbors *nb)
{
	free(nb->nbr);
	free(nb->count);
	free(nb->wsum);
	free(nb->bwsum);
	free(nb->bnbr);
	free(nb->bcount);
	free(nb->cell_start);
	free(nb->cell_of);
	free(nb->vnbr);
	free(nb->vcount);
	free(nb->vbnbr);
	free(nb->vbcount);
	free(nb->vx);
	free(nb->vy);
	free(nb->vz);
	free(nb->slot_of);
	free(nb->now_of);
	boundary_free(nb);
	free(nb->bdiv);
	free(nb->bcell_start);
	memset(nb, 0, sizeof *nb);
}

sph_shared *eddy__sph_find(eddy_world *w, const eddy_system *s)
{
	return eddy__provided(w, s, EDDY_CAP_SPH_NEIGHBORS);
}

static inline int clampi(int v, int lo, int hi) { return v < lo ? lo : v > hi ? hi : v; }

static inline uint32_t cell_index(const sph_neighbors *nb, float x, float y, float z)
{
	const int cx = clampi((int)((x - nb->ox) * nb->inv), 0, nb->gx - 1);
	const int cy = clampi((int)((y - nb->oy) * nb->inv), 0, nb->gy - 1);
	const int cz = clampi((int)((z - nb->oz) * nb->inv), 0, nb->gz - 1);
	return (uint32_t)((cz * nb->gy + cy) * nb->gx + cx);
}

static eddy_status grid_setup(eddy_world *w, sph_neighbors *nb, float h)
{
	if (nb->cell_start)
		return EDDY_OK;
	const eddy_vec3 lo = w->def.bounds_min, hi = w->def.bounds_max;
	nb->ox = lo.x - h;
	nb->oy = lo.y - h;
	nb->oz = lo.z - h;
	nb->inv = SPH_CELLS_PER_H / h;
	const double gx = ceil((hi.x - lo.x) * nb->inv) + 2 * SPH_CELLS_PER_H,
	             gy = ceil((hi.y - lo.y) * nb->inv) + 2 * SPH_CELLS_PER_H,
	             gz = ceil((hi.z - lo.z) * nb->inv) + 2 * SPH_CELLS_PER_H;
	if (gx * gy * gz > 1.5e8)
		return eddy__fail(w, EDDY_ERR_NOMEM,
		                  "sph_density: the world bounds hold %.0f x %.0f x %.0f neighbour cells of size radius/2 = %g m; "
		                  "shrink the bounds or use a larger radius",
		                  gx, gy, gz, (double)h / SPH_CELLS_PER_H);
	nb->gx = (int)gx;
	nb->gy = (int)gy;
	nb->gz = (int)gz;
	const size_t cells = (size_t)nb->gx * (size_t)nb->gy * (size_t)nb->gz;
	nb->cell_start = calloc(cells + 1, sizeof *nb->cell_start);
	nb->bcell_start = calloc(cells + 1, sizeof *nb->bcell_start);
	if (!nb->cell_start || !nb->bcell_start)
		return eddy__fail(w, EDDY_ERR_NOMEM, "sph_density: out of memory for %zu neighbour cells", cells);
	return EDDY_OK;
}

/* Counting sort of keys[0..n) into order (stable); start gets cells+1 offsets. */
static void counting_sort(const uint32_t *keys, size_t n, size_t cells, uint32_t *start, uint32_t *order)
{
	memset(start, 0, (cells + 1) * sizeof *start);
	for (size_t i = 0; i < n; ++i)
		start[keys[i] + 1]++;
	for (size_t c = 0; c < cells; ++c)
		start[c + 1] += start[c];
	/* order[pos] = i, using start as the running cursor, then shift back */
	for (size_t i = 0; i < n; ++i)
		order[start[keys[i]]++] = (uint32_t)i;
	for (size_t c = cells; c > 0; --c)
		start[c] = start[c - 1];
	start[0] = 0;
}

/* The cell offsets of a table already in cell order (keys non-decreasing):
 * start[c] is the first row in cell c or after it. */
static void cell_ranges(const uint32_t *key, size_t n, size_t cells, uint32_t *start)
{
	size_t c = 0;
	for (size_t i = 0; i < n; ++i)
		while (c <= key[i])
			start[c++] = (uint32_t)i;
	while (c <= cells)
		start[c++] = (uint32_t)n;
}

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

/* The fluid spacing: that of the sph_density that owns sh. */
static float fluid_spacing(const eddy_world *w, const sph_shared *sh)
{
	const eddy_system *o;
	for (eddy_system_iter it = eddy__systems(w, EDDY_CAP_SPH_NEIGHBORS); (o = eddy__systems_next(&it));)
		if (o->vt->shared(o, EDDY_CAP_SPH_NEIGHBORS) == sh && eddy__sph_density_def(o))
			return eddy__sph_density_def(o)->spacing;
	return sh->h / 2;
}

static void boundary_free(sph_neighbors *nb)
{
	free(nb->bx);
	free(nb->by);
	free(nb->bz);
	free(nb->bvol);
	free(nb->bp); /* brho and seen live in the same block */
	free(nb->border);
	free(nb->blx); /* bly, blz in the same block */
	free(nb->bvx); /* bvy, bvz in the same block */
	free(nb->col);
	nb->bx = nb->by = nb->bz = nb->bvol = nb->bp = nb->brho = NULL;
	nb->blx = nb->bly = nb->blz = nb->bvx = nb->bvy = nb->bvz = NULL;
	nb->border = NULL;
	nb->col = NULL;
	nb->seen = NULL;
	nb->bstate_size = 0;
	nb->ncol = 0;
	nb->nb = nb->nbs = 0;
}

/* The collider particles where their colliders are now (a displacement
 * changed: positions; the time moved on: velocities, the offset's change
 * over the time since it was last seen, as sys_flip_boundary.c takes it).
 * Returns the largest squared displacement since the last search. */
/* A rotating collider's particles (or one that rotated since it was last
 * seen): x_b = pivot + offset + R (x_b0 - pivot), whole (a plane's patch
 * turns with it too), with the rigid velocity v + omega x (x_b - pivot -
 * offset), v and omega from the pose seen at the last step. Returns the
 * bound on any particle's displacement since the search: the pivot's move
 * plus the reach times the angle turned. */
static float boundary_move_rotating(const eddy_world *w, sph_neighbors *nb, int c)
{
	struct sph_collider_set *cs = &nb->col[c];
	const eddy_collider_motion *m = &((const eddy_collider_base *)w->slots[cs->slot].data)->motion;
	const eddy_vec3 off = m->offset, rot = m->rotation;
	if (off.x != cs->disp.x || off.y != cs->disp.y || off.z != cs->disp.z || rot.x != cs->rot.x ||
	    rot.y != cs->rot.y || rot.z != cs->rot.z) {
		const eddy_collider_pose pose = eddy__collider_pose(m);
		for (size_t b = cs->first; b < cs->first + cs->count; ++b) {
			const eddy_vec3 q = eddy__pose_to_world(&pose, eddy__v3(nb->blx[b], nb->bly[b], nb->blz[b]));
			nb->bx[b] = q.x, nb->by[b] = q.y, nb->bz[b] = q.z;
		}
		cs->disp = off;
		cs->rot = rot;
	}
	struct sph_collider_seen *sn = &nb->seen[c];
	if (sn->have == 0 || w->time != sn->time) {
		eddy_collider_velocity mv = {{0, 0, 0}, {0, 0, 0}, eddy__add3(m->pivot, off)};
		if (sn->have != 0 && w->time > sn->time)
			mv = eddy__collider_motion_since(m, eddy__v3(sn->x, sn->y, sn->z), eddy__v3(sn->rx, sn->ry, sn->rz),
			                                 w->time - sn->time);
		for (size_t b = cs->first; b < cs->first + cs->count; ++b) {
			const eddy_vec3 v = eddy__rigid_velocity(&mv, eddy__v3(nb->bx[b], nb->by[b], nb->bz[b]));
			nb->bvx[b] = v.x, nb->bvy[b] = v.y, nb->bvz[b] = v.z;
		}
		*sn = (struct sph_collider_seen){off.x, off.y, off.z, 1, rot.x, rot.y, rot.z, 0, w->time};
	}
	const eddy_vec3 om = eddy__rotation_rate(cs->rot_at_search, rot, 1.0);
	const float ex = off.x - cs->at_search.x, ey = off.y - cs->at_search.y, ez = off.z - cs->at_search.z;
	const float ang = sqrtf(om.x * om.x + om.y * om.y + om.z * om.z);
	const float m1 = sqrtf(ex * ex + ey * ey + ez * ez) + cs->reach * ang;
	return m1 * m1;
}

static float boundary_move(const eddy_world *w, sph_neighbors *nb)
{
	float moved2 = 0;
	for (int c = 0; c < nb->ncol; ++c) {
		struct sph_collider_set *cs = &nb->col[c];
		const eddy_system *o = &w->slots[cs->slot];
		const struct sph_collider_seen *sn0 = &nb->seen[c];
		if (eddy__motion_rotates(&((const eddy_collider_base *)o->data)->motion) || sn0->rx != 0 || sn0->ry != 0 ||
		    sn0->rz != 0 || cs->rot.x != 0 || cs->rot.y != 0 || cs->rot.z != 0 || cs->rot_at_search.x != 0 ||
		    cs->rot_at_search.y != 0 || cs->rot_at_search.z != 0) {
			const float m2 = boundary_move_rotating(w, nb, c);
			moved2 = m2 > moved2 ? m2 : moved2;
			continue;
		}
		const eddy_vec3 off = ((const eddy_collider_base *)o->data)->motion.offset, n = cs->normal;
		const bool plane = n.x != 0 || n.y != 0 || n.z != 0;
		const float along = off.x * n.x + off.y * n.y + off.z * n.z;
		const eddy_vec3 d = plane ? eddy__v3(along * n.x, along * n.y, along * n.z) : off;
		if (d.x != cs->disp.x || d.y != cs->disp.y || d.z != cs->disp.z) {
			for (size_t b = cs->first; b < cs->first + cs->count; ++b) {
				nb->bx[b] = nb->blx[b] + d.x;
				nb->by[b] = nb->bly[b] + d.y;
				nb->bz[b] = nb->blz[b] + d.z;
			}
			cs->disp = d;
		}
		struct sph_collider_seen *sn = &nb->seen[c];
		if (sn->have == 0 || w->time != sn->time) {
			eddy_vec3 v = {0, 0, 0};
			if (sn->have != 0 && w->time > sn->time) {
				const float inv = (float)(1.0 / (w->time - sn->time));
				v = eddy__v3((off.x - sn->x) * inv, (off.y - sn->y) * inv, (off.z - sn->z) * inv);
				if (plane) {
					const float vn = v.x * n.x + v.y * n.y + v.z * n.z;
					v = eddy__v3(vn * n.x, vn * n.y, vn * n.z);
				}
			}
			for (size_t b = cs->first; b < cs->first + cs->count; ++b) {
				nb->bvx[b] = v.x;
				nb->bvy[b] = v.y;
				nb->bvz[b] = v.z;
			}
			*sn = (struct sph_collider_seen){off.x, off.y, off.z, 1, 0, 0, 0, 0, w->time};
		}
		const float ex = d.x - cs->at_search.x, ey = d.y - cs->at_search.y, ez = d.z - cs->at_search.z;
		const float m2 = ex * ex + ey * ey + ez * ez;
		moved2 = m2 > moved2 ? m2 : moved2;
	}
	return moved2;
}

/* The cell order of every boundary particle now (with collider particles
 * only: the static ones are stored in cell order), for the search. */
static eddy_status boundary_sort(eddy_world *w, sph_neighbors *nb)
{
	if (!nb->border)
		return EDDY_OK;
	const size_t total = nb->nb, cells = (size_t)nb->gx * (size_t)nb->gy * (size_t)nb->gz;
	uint32_t *key = eddy__arena_alloc(&w->arena, (total ? total : 1) * sizeof *key);
	if (!key)
		return eddy__fail(w, EDDY_ERR_NOMEM, "sph_density: out of scratch memory for %zu boundary particles", total);
	for (size_t i = 0; i < total; ++i)
		key[i] = cell_index(nb, nb->bx[i], nb->by[i], nb->bz[i]);
	counting_sort(key, total, cells, nb->bcell_start, nb->border);
	for (int c = 0; c < nb->ncol; ++c) {
		nb->col[c].at_search = nb->col[c].disp;
		nb->col[c].rot_at_search = nb->col[c].rot;
	}
	return EDDY_OK;
}

static eddy_status boundary_build(eddy_world *w, sph_shared *sh)
{
	sph_neighbors *nb = &sh->nb;
	const uint64_t sig = boundary_signature(w);
	if (sig == nb->bsig && nb->bx)
		return EDDY_OK;
	const float spacing = fluid_spacing(w, sh);
	size_t total = 0, ncol = 0, tcol = 0;
	eddy_vec3 normal;
	const eddy_system *o;
	for (eddy_system_iter it = eddy__systems(w, EDDY_CAP_SPH_WALLS | EDDY_CAP_COLLIDER); (o = eddy__systems_next(&it));) {
		if (o->vt->provides & EDDY_CAP_SPH_WALLS)
			total += eddy__sph_boundary_box_points(o, sh->h, NULL, NULL, NULL, NULL);
		else {
			const size_t c = eddy__sph_collider_points(w, o, spacing, sh->h, NULL, NULL, NULL, NULL, &normal);
			tcol += c;
			ncol += c > 0;
		}
	}
	/* a plane's patch spans the world bounds: 5e7 particles is about 2 GB */
	if ((double)tcol > 5e7)
		return eddy__fail(w, EDDY_ERR_NOMEM,
		                  "sph_density: the colliders need %.0f boundary particles (at most 5e7); shrink the world "
		                  "bounds or the colliders, or use a larger spacing",
		                  (double)tcol);
	const size_t nstat = total;
	total += tcol;
	const size_t alloc = total ? total : 1;
	float *x = malloc(alloc * sizeof *x), *y = malloc(alloc * sizeof *y), *z = malloc(alloc * sizeof *z),
	      *v = malloc(alloc * sizeof *v);
	uint32_t *key = calloc(alloc, sizeof *key), *order = calloc(alloc, sizeof *order);
	boundary_free(nb);
	/* one block, bp, brho, then each collider's seen offset: it is
	 * sph_density's checkpointed state (after 2 total floats the records
	 * are 8-byte aligned; with colliders, alloc = total) */
	nb->bstate_size = 2 * total * sizeof *nb->bp + ncol * sizeof *nb->seen;
	nb->bp = calloc(1, 2 * alloc * sizeof *nb->bp + ncol * sizeof *nb->seen);
	nb->brho = nb->bp ? nb->bp + alloc : NULL;
	nb->seen = nb->bp && ncol ? (struct sph_collider_seen *)(void *)(nb->bp + 2 * alloc) : NULL;
	/* positions padded by three for the search's groups of four */
	nb->bx = malloc((alloc + 3) * sizeof *nb->bx);
	nb->by = malloc((alloc + 3) * sizeof *nb->by);
	nb->bz = malloc((alloc + 3) * sizeof *nb->bz);
	nb->bvol = malloc(alloc * sizeof *nb->bvol);
	bool ok = x && y && z && v && key && order && nb->bx && nb->by && nb->bz && nb->bvol && nb->bp && nb->brho;
	if (ok && ncol) {
		nb->border = malloc(alloc * sizeof *nb->border);
		nb->blx = malloc(3 * alloc * sizeof *nb->blx);
		nb->bvx = calloc(3 * alloc, sizeof *nb->bvx);
		nb->col = calloc(ncol, sizeof *nb->col);
		ok = nb->border && nb->blx && nb->bvx && nb->col;
		if (ok) {
			nb->bly = nb->blx + alloc;
			nb->blz = nb->bly + alloc;
			nb->bvy = nb->bvx + alloc;
			nb->bvz = nb->bvy + alloc;
		}
	}
	eddy_status st = EDDY_OK;
	if (!ok) {
		st = eddy__fail(w, EDDY_ERR_NOMEM, "sph_density: out of memory for %zu boundary particles", total);
		boundary_free(nb);
		goto done;
	}
	size_t at = 0;
	for (eddy_system_iter it = eddy__systems(w, EDDY_CAP_SPH_WALLS); (o = eddy__systems_next(&it));)
		at += eddy__sph_boundary_box_points(o, sh->h, x + at, y + at, z + at, v + at);
	for (size_t i = 0; i < nstat; ++i)
		key[i] = cell_index(nb, x[i], y[i], z[i]);
	const size_t cells = (size_t)nb->gx * (size_t)nb->gy * (size_t)nb->gz;
	counting_sort(key, nstat, cells, nb->bcell_start, order);
	for (size_t i = total; i < total + 3; ++i)
		nb->bx[i] = nb->by[i] = nb->bz[i] = 0; /* read, always masked */
	for (size_t i = 0; i < nstat; ++i) {
		nb->bx[i] = x[order[i]];
		nb->by[i] = y[order[i]];
		nb->bz[i] = z[order[i]];
		nb->bvol[i] = v[order[i]];
	}
	/* the colliders' particles after them, in the order they are made */
	at = nstat;
	for (eddy_system_iter it = eddy__systems(w, EDDY_CAP_COLLIDER); ncol && (o = eddy__systems_next(&it));) {
		const size_t want = eddy__sph_collider_points(w, o, spacing, sh->h, NULL, NULL, NULL, NULL, &normal);
		if (!want)
			continue;
		const size_t got =
			eddy__sph_collider_points(w, o, spacing, sh->h, nb->blx + at, nb->bly + at, nb->blz + at, nb->bvol + at, &normal);
		if (got != want) {
			st = eddy__fail(w, EDDY_ERR_NOMEM, "sph_density: out of memory for the boundary particles of %s", o->label);
			boundary_free(nb);
			goto done;
		}
		struct sph_collider_set *cs = &nb->col[nb->ncol++];
		cs->slot = (int)(o - w->slots);
		cs->first = at;
		cs->count = got;
		cs->normal = normal;
		cs->disp = eddy__v3(NAN, NAN, NAN); /* placed by boundary_move */
		const eddy_vec3 pv = ((const eddy_collider_base *)o->data)->motion.pivot;
		for (size_t b = at; b < at + got; ++b) {
			const float dx = nb->blx[b] - pv.x, dy = nb->bly[b] - pv.y, dz = nb->blz[b] - pv.z;
			cs->reach = fmaxf(cs->reach, sqrtf(dx * dx + dy * dy + dz * dz));
		}
		at += got;
	}
	for (size_t i = 0; i < total; ++i)
		nb->brho[i] = sh->rho0;
	nb->nb = total;
	nb->nbs = nstat;
	if (nb->ncol) {
		boundary_move(w, nb);
		for (size_t i = 0; i < total; ++i)
			nb->border[i] = (uint32_t)i; /* the first search sorts them */
	}
	nb->bsig = sig;
done:
	free(x);
	free(y);
	free(z);
	free(v);
	free(key);
	free(order);
	return st;
}

static bool grow(void **p, size_t *have, size_t want, size_t elem)
{
	if (want <= *have)
		return true;
	size_t cap = *have ? *have : 1024;
	while (cap < want)
		cap *= 2;
	void *q = realloc(*p, cap * elem);
	if (!q)
		return false;
	*p = q;
	*have = cap;
	return true;
}

/* The search works on blocks of cells: the particles of a block (about 16 in
 * a fluid at cells of h/2) share their candidates, the runs of cells around
 * the block, gathered once into a contiguous buffer. Each particle then
 * tests the whole buffer in one loop of groups of four (eight with AVX2) and
 * packs the hits without branches. Looping over the runs per particle
 * instead cost a lookup and a masked, mispredicted tail per run, which with
 * about one particle per cell was most of the search; gathering per run of
 * four cells along x (4 x 1 x 1) took the pour's search from 41% to 31% of
 * its time, and 4 x 2 x 2 (a sixteenth of the gathering per particle, for
 * 288 candidates instead of 200) to about 21%. */
#define SEARCH_BX 4
#define SEARCH_BY 2
#define SEARCH_BZ 2

static int cmp_u32(const void *a, const void *b)
{
	const uint32_t x = *(const uint32_t *)a, y = *(const uint32_t *)b;
	return (x > y) - (x < y);
}

/* one thread's buffers: a block's candidates (padded by eight far-away
 * points, so groups never need a tail) and one particle's hits */
typedef struct search_buf {
	size_t cap;
	float *x, *y, *z, *d;
	uint32_t *j, *hit;
} search_buf;

static void search_buf_free(search_buf *b)
{
	free(b->x);
	free(b->y);
	free(b->z);
	free(b->d);
	free(b->j);
	free(b->hit);
	memset(b, 0, sizeof *b);
}

static bool search_buf_grow(search_buf *b, size_t want)
{
	want += 8;
	if (want <= b->cap)
		return true;
	size_t cap = b->cap ? b->cap : 256;
	while (cap < want)
		cap *= 2;
	search_buf_free(b);
	b->x = malloc(cap * sizeof *b->x);
	b->y = malloc(cap * sizeof *b->y);
	b->z = malloc(cap * sizeof *b->z);
	b->d = malloc(cap * sizeof *b->d);
	b->j = malloc(cap * sizeof *b->j);
	b->hit = malloc(cap * sizeof *b->hit);
	b->cap = cap;
	return b->x && b->y && b->z && b->d && b->j && b->hit;
}

/* The candidates c[q0..q1) with r2max - r^2 > 0, in order, into hit/d;
 * returns how many. The last group reads past q1 (the buffer is padded by
 * eight) and is masked to q1. The same operations as filter(), so the same
 * (r2max - r^2) bits. */
static uint32_t hits_sse(const search_buf *c, uint32_t q0, uint32_t q1, float xi, float yi, float zi, float r2max,
                         uint32_t *hit, float *dv)
{
	uint32_t cnt = 0, q = q0;
#ifdef __SSE2__
	const __m128 vxi = _mm_set1_ps(xi), vyi = _mm_set1_ps(yi), vzi = _mm_set1_ps(zi), vh2 = _mm_set1_ps(r2max);
	for (; q < q1; q += 4) {
		const __m128 rx = _mm_sub_ps(vxi, _mm_loadu_ps(c->x + q)), ry = _mm_sub_ps(vyi, _mm_loadu_ps(c->y + q)),
		             rz = _mm_sub_ps(vzi, _mm_loadu_ps(c->z + q));
		const __m128 d =
			_mm_sub_ps(vh2, _mm_add_ps(_mm_add_ps(_mm_mul_ps(rx, rx), _mm_mul_ps(ry, ry)), _mm_mul_ps(rz, rz)));
		unsigned in = (unsigned)_mm_movemask_ps(_mm_cmpgt_ps(d, _mm_setzero_ps()));
		if (q1 - q < 4)
			in &= (1u << (q1 - q)) - 1;
		float dd[4];
		_mm_storeu_ps(dd, d);
		for (unsigned k = 0; k < 4; ++k) {
			hit[cnt] = c->j[q + k];
			dv[cnt] = dd[k];
			cnt += in >> k & 1;
		}
	}
#endif
	for (; q < q1; ++q) {
		const float rx = xi - c->x[q], ry = yi - c->y[q], rz = zi - c->z[q];
		const float d = r2max - (rx * rx + ry * ry + rz * rz);
		hit[cnt] = c->j[q];
		dv[cnt] = d;
		cnt += d > 0;
	}
	return cnt;
}

#ifdef SPH_AVX2
/* hits_sse with eight lanes, packed with a permutation made from the mask
 * (pdep/pext) and stored eight at a time: the same hits in the same order. */
__attribute__((target("avx2,bmi2"))) static uint32_t hits_avx2(const search_buf *c, uint32_t q0, uint32_t q1, float xi,
                                                               float yi, float zi, float r2max, uint32_t *hit,
                                                               float *dv)
{
	const __m256 vxi = _mm256_set1_ps(xi), vyi = _mm256_set1_ps(yi), vzi = _mm256_set1_ps(zi),
	             vh2 = _mm256_set1_ps(r2max);
	const float *cx = c->x, *cy = c->y, *cz = c->z;
	const uint32_t *cj = c->j;
	uint32_t cnt = 0;
	/* no test for a group without hits: which groups hit is a coin toss,
	 * and storing nothing costs less than a mispredicted branch */
	for (uint32_t q = q0; q < q1; q += 8) {
		const __m256 rx = _mm256_sub_ps(vxi, _mm256_loadu_ps(cx + q)), ry = _mm256_sub_ps(vyi, _mm256_loadu_ps(cy + q)),
		             rz = _mm256_sub_ps(vzi, _mm256_loadu_ps(cz + q));
		const __m256 d = _mm256_sub_ps(
			vh2, _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(rx, rx), _mm256_mul_ps(ry, ry)), _mm256_mul_ps(rz, rz)));
		unsigned in = (unsigned)_mm256_movemask_ps(_mm256_cmp_ps(d, _mm256_setzero_ps(), _CMP_GT_OQ));
		if (q1 - q < 8)
			in &= (1u << (q1 - q)) - 1;
		const uint64_t keep = _pdep_u64(in, 0x0101010101010101ull) * 0xFF;
		const __m256i perm =
			_mm256_cvtepu8_epi32(_mm_cvtsi64_si128((long long)_pext_u64(0x0706050403020100ull, keep)));
		_mm256_storeu_si256((__m256i *)(hit + cnt),
		                    _mm256_permutevar8x32_epi32(_mm256_loadu_si256((const __m256i *)(cj + q)), perm));
		_mm256_storeu_ps(dv + cnt, _mm256_permutevar8x32_ps(d, perm));
		cnt += (uint32_t)__builtin_popcount(in);
	}
	return cnt;
}
#endif

/* sum_k d_k^3 in a fixed order, four partial sums then (0+1)+(2+3), the
 * tail after: every path that makes a particle's list (the filter, the
 * exact search) sums this way, so they give the same bits. */
static inline float cube_sum(const float *d, uint32_t cnt)
{
	uint32_t q = 0;
	float ws = 0;
#ifdef __SSE2__
	__m128 acc = _mm_setzero_ps();
	for (; q + 4 <= cnt; q += 4) {
		const __m128 v = _mm_loadu_ps(d + q);
		acc = _mm_add_ps(acc, _mm_mul_ps(_mm_mul_ps(v, v), v));
	}
	ws = sph_hsum4(acc);
#else
	float a[4] = {0, 0, 0, 0};
	for (; q + 4 <= cnt; q += 4)
		for (int k = 0; k < 4; ++k)
			a[k] += d[q + k] * d[q + k] * d[q + k];
	ws = (a[0] + a[1]) + (a[2] + a[3]);
#endif
	for (; q < cnt; ++q)
		ws += d[q] * d[q] * d[q];
	return ws;
}

/* Sorts hits (and their d) by index: insertion, a particle has a few
 * dozen boundary neighbours at most, nearly in order. */
static void sort_hits(uint32_t *hit, float *d, uint32_t cnt)
{
	for (uint32_t a = 1; a < cnt; ++a) {
		const uint32_t j = hit[a];
		const float dj = d[a];
		uint32_t k = a;
		for (; k > 0 && hit[k - 1] > j; --k) {
			hit[k] = hit[k - 1];
			d[k] = d[k - 1];
		}
		hit[k] = j;
		d[k] = dj;
	}
}

/* The grid search. Verlet mode (exact false): the pairs closer than
 * sqrt(r2max) into the Verlet list with the current strides. Exact mode (a
 * skin of 0, r2max = h^2): straight into the exact lists and kernel sums,
 * which the filter would make from such a list (same tests, same order,
 * same sums), so the filter is skipped. Returns the largest fluid and
 * boundary counts seen (a count above the stride means: search again).
 * The table is in cell order and the runs are gathered in cell order, so
 * the hits come in ascending row order. */
static bool search(eddy_world *w, sph_neighbors *nb, float r2max, bool exact, int threads, uint32_t *max_f,
                   uint32_t *max_b)
{
	const float *x = eddy__col(w, COL_X_), *y = eddy__col(w, COL_Y_), *z = eddy__col(w, COL_Z_);
	const size_t n = w->n;
	const int gx = nb->gx, gy = nb->gy, gz = nb->gz, R = exact ? SPH_CELLS_PER_H : SPH_VERLET_CELLS;
	const size_t cap = exact ? nb->cap : nb->vcap, bcap = exact ? nb->bcap : nb->vbcap;
	uint32_t *const lists = exact ? nb->nbr : nb->vnbr, *const blists = exact ? nb->bnbr : nb->vbnbr;
	uint32_t *const counts = exact ? nb->count : nb->vcount, *const bcounts = exact ? nb->bcount : nb->vbcount;
	/* with moving (collider) boundary particles the cells hold them out of
	 * index order: each particle's hits are sorted by index, so that the
	 * lists, and the sums over them, do not depend on when the search ran */
	const uint32_t *const border = nb->border;
	/* how many cells along x a run at cell offsets (dy, dz) needs: a cell k
	 * cells away is at least (k - 1) cells of h/2 from the particle, so the
	 * corners of the block are beyond the radius; -1: none */
	int reach[SPH_VERLET_CELLS + 1][SPH_VERLET_CELLS + 1];
	const double rs2 = 1.001 * (double)r2max * (double)nb->inv * (double)nb->inv; /* in cells^2, 0.1% for rounding */
	for (int a = 0; a <= R; ++a)
		for (int b = 0; b <= R; ++b) {
			const double ey = a > 0 ? a - 1 : 0, ez = b > 0 ? b - 1 : 0, rem = rs2 - ey * ey - ez * ez;
			int k = -1;
			if (rem > 0) /* x offsets k with (k - 1)^2 < rem */
				for (k = 0; k < R && (double)k * k < rem; ++k)
					;
			reach[a][b] = k;
		}
	/* the blocks that hold particles, as ids in block order: one per
	 * stretch of rows in one row of cells and one block, then unique */
	const int nbx = (gx + SEARCH_BX - 1) / SEARCH_BX, nby = (gy + SEARCH_BY - 1) / SEARCH_BY;
	uint32_t *ids = eddy__arena_alloc(&w->arena, (n + 1) * sizeof *ids);
	if (!ids)
		return false;
	long blocks = 0;
	uint32_t prev = UINT32_MAX;
	for (size_t i = 0; i < n; ++i) {
		const uint32_t c = nb->cell_of[i], cx = c % (uint32_t)gx, cy = c / (uint32_t)gx % (uint32_t)gy,
		               cz = c / ((uint32_t)gx * (uint32_t)gy);
		const uint32_t id = (cz / SEARCH_BZ * (uint32_t)nby + cy / SEARCH_BY) * (uint32_t)nbx + cx / SEARCH_BX;
		if (id != prev)
			ids[blocks++] = id;
		prev = id;
	}
	qsort(ids, (size_t)blocks, sizeof *ids, cmp_u32);
	long unique = 0;
	for (long k = 0; k < blocks; ++k)
		if (k == 0 || ids[k] != ids[unique - 1])
			ids[unique++] = ids[k];
	blocks = unique;
#ifdef SPH_AVX2
	const bool avx2 = sph_use_avx2();
#endif
	uint32_t mf = 0, mb = 0;
	bool ok = true;
#pragma omp parallel num_threads(threads) reduction(max : mf, mb) reduction(&& : ok)
	{
		search_buf fb = {0}, bb = {0};
#pragma omp for schedule(dynamic, 8)
		for (long k = 0; k < blocks; ++k) {
			if (!ok)
				continue;
			const int bxi = (int)(ids[k] % (uint32_t)nbx), byi = (int)(ids[k] / (uint32_t)nbx % (uint32_t)nby),
			          bzi = (int)(ids[k] / ((uint32_t)nbx * (uint32_t)nby));
			const int bx0 = bxi * SEARCH_BX, bx1 = bx0 + SEARCH_BX - 1 < gx ? bx0 + SEARCH_BX - 1 : gx - 1;
			const int by0 = byi * SEARCH_BY, by1 = by0 + SEARCH_BY - 1 < gy ? by0 + SEARCH_BY - 1 : gy - 1;
			const int bz0 = bzi * SEARCH_BZ, bz1 = bz0 + SEARCH_BZ - 1 < gz ? bz0 + SEARCH_BZ - 1 : gz - 1;
			/* the runs, in cell order: fluid rows [0], [1], boundary [2], [3], the
			 * first cell of the block's own particles in it [4], its z layer [5] */
			uint32_t run[(2 * SPH_VERLET_CELLS + SEARCH_BY) * (2 * SPH_VERLET_CELLS + SEARCH_BZ)][6];
			int runs = 0;
			size_t nf = 0, nbd = 0;
			for (int zz = bz0 - R; zz <= bz1 + R; ++zz) {
				if (zz < 0 || zz >= gz)
					continue;
				const int ez = zz < bz0 ? bz0 - zz : zz > bz1 ? zz - bz1 : 0;
				for (int yy = by0 - R; yy <= by1 + R; ++yy) {
					const int ey = yy < by0 ? by0 - yy : yy > by1 ? yy - by1 : 0, ext = reach[ey][ez];
					if (yy < 0 || yy >= gy || ext < 0)
						continue;
					const int x0 = bx0 >= ext ? bx0 - ext : 0, x1 = bx1 < gx - ext ? bx1 + ext : gx - 1;
					const size_t row = ((size_t)zz * (size_t)gy + (size_t)yy) * (size_t)gx;
					uint32_t *r = run[runs++];
					r[0] = nb->cell_start[row + (size_t)x0];
					r[1] = nb->cell_start[row + (size_t)x1 + 1];
					r[2] = nb->bcell_start[row + (size_t)x0];
					r[3] = nb->bcell_start[row + (size_t)x1 + 1];
					/* the block's own particles in this row: a stretch of the run */
					r[4] = ey == 0 && ez == 0 ? (uint32_t)(row + (size_t)bx0) : UINT32_MAX;
					r[5] = (uint32_t)(zz - (bz0 - R)); /* its layer */
					nf += r[1] - r[0];
					nbd += r[3] - r[2];
				}
			}
			if (!search_buf_grow(&fb, nf) || !search_buf_grow(&bb, nbd)) {
				ok = false;
				continue;
			}
			/* the buffers' offsets at each run and at each layer of cells
			 * in z: a particle needs only the 2R + 1 layers around its own,
			 * one stretch of the buffer (the block spans 2R + SEARCH_BZ) */
			uint32_t nc = 0, nbc = 0, at[(2 * SPH_VERLET_CELLS + SEARCH_BY) * (2 * SPH_VERLET_CELLS + SEARCH_BZ)];
			uint32_t zf[2 * SPH_VERLET_CELLS + SEARCH_BZ + 1], zb[2 * SPH_VERLET_CELLS + SEARCH_BZ + 1];
			int layer = 0;
			for (int r = 0; r < runs; ++r) {
				for (; layer <= (int)run[r][5]; ++layer) {
					zf[layer] = nc;
					zb[layer] = nbc;
				}
				at[r] = nc;
				for (uint32_t j = run[r][0]; j < run[r][1]; ++j, ++nc) {
					fb.x[nc] = x[j];
					fb.y[nc] = y[j];
					fb.z[nc] = z[j];
					fb.j[nc] = j;
				}
				for (uint32_t j = run[r][2]; j < run[r][3]; ++j, ++nbc) {
					const uint32_t jb = border ? border[j] : j;
					bb.x[nbc] = nb->bx[jb];
					bb.y[nbc] = nb->by[jb];
					bb.z[nbc] = nb->bz[jb];
					bb.j[nbc] = jb;
				}
			}
			for (; layer <= 2 * R + bz1 - bz0 + 1; ++layer) {
				zf[layer] = nc;
				zb[layer] = nbc;
			}
			/* a group of eight may start anywhere: eight points past the end
			 * (masked; far away all the same) */
			for (uint32_t q = nc; q < nc + 8; ++q) {
				fb.x[q] = fb.y[q] = fb.z[q] = 1e30f;
				fb.j[q] = 0;
			}
			for (uint32_t q = nbc; q < nbc + 8; ++q) {
				bb.x[q] = bb.y[q] = bb.z[q] = 1e30f;
				bb.j[q] = 0;
			}
			for (int r = 0; r < runs; ++r) {
				if (run[r][4] == UINT32_MAX)
					continue;
				const uint32_t pa = nb->cell_start[run[r][4]], pe = nb->cell_start[run[r][4] + (uint32_t)(bx1 - bx0) + 1];
			for (uint32_t i = pa; i < pe; ++i) {
				const float xi = x[i], yi = y[i], zi = z[i];
				/* not itself: its own entry is moved far away for its turn */
				const uint32_t s = at[r] + (i - run[r][0]);
				fb.x[s] = 1e30f;
				uint32_t cnt, bcnt;
				const uint32_t l0 = run[r][5] - (uint32_t)R, l1 = run[r][5] + (uint32_t)R + 1;
#ifdef SPH_AVX2
				if (avx2) {
					cnt = hits_avx2(&fb, zf[l0], zf[l1], xi, yi, zi, r2max, fb.hit, fb.d);
					bcnt = hits_avx2(&bb, zb[l0], zb[l1], xi, yi, zi, r2max, bb.hit, bb.d);
				} else
#endif
				{
					cnt = hits_sse(&fb, zf[l0], zf[l1], xi, yi, zi, r2max, fb.hit, fb.d);
					bcnt = hits_sse(&bb, zb[l0], zb[l1], xi, yi, zi, r2max, bb.hit, bb.d);
				}
				fb.x[s] = xi;
				if (border)
					sort_hits(bb.hit, bb.d, bcnt);
				if (cnt <= cap)
					memcpy(lists + (size_t)i * cap, fb.hit, cnt * sizeof *fb.hit);
				if (bcnt <= bcap)
					memcpy(blists + (size_t)i * bcap, bb.hit, bcnt * sizeof *bb.hit);
				counts[i] = cnt;
				bcounts[i] = bcnt;
				if (exact) {
					nb->wsum[i] = cube_sum(fb.d, cnt);
					float bws = 0;
					for (uint32_t q = 0; q < bcnt; ++q) {
						const uint32_t jb = bb.hit[q];
						const float d = bb.d[q];
						bws += nb->bvol[jb] * nb->brho[jb] * d * d * d;
					}
					nb->bwsum[i] = bws;
				}
				mf = cnt > mf ? cnt : mf;
				mb = bcnt > mb ? bcnt : mb;
			}
			}
		}
		search_buf_free(&fb);
		search_buf_free(&bb);
	}
	*max_f = mf;
	*max_b = mb;
	return ok;
}

#ifdef SPH_AVX2
/* The AVX2 path of filter() for the candidates of one row, eight a group:
 * the candidates in (r^2 < h^2) are packed to the front of the group with a
 * permutation made from the mask (pdep/pext), stored eight at a time. The
 * same candidates in the same order as the SSE path, so the same lists. */
__attribute__((target("avx2,bmi2"))) static uint32_t filter_avx2(const uint32_t *cand, uint32_t vc,
                                                                 const uint32_t *now_of, const float *p4, float xi,
                                                                 float yi, float zi, float h2, uint32_t *jl,
                                                                 float *dv, uint32_t *done)
{
	const __m256 vxi = _mm256_set1_ps(xi), vyi = _mm256_set1_ps(yi), vzi = _mm256_set1_ps(zi), vh2 = _mm256_set1_ps(h2);
	const __m256i lane = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
	uint32_t cnt = 0, q = 0;
	/* the last group is padded with copies of the last candidate, masked */
	for (; q < vc; q += 8) {
		uint32_t j[8];
		__m256i jv;
		if (q + 8 <= vc && !now_of) {
			for (uint32_t k = 0; k < 8; ++k)
				j[k] = cand[q + k];
			jv = _mm256_loadu_si256((const __m256i *)(cand + q));
		} else {
			for (uint32_t k = 0; k < 8; ++k) {
				const uint32_t c = cand[q + k < vc ? q + k : vc - 1];
				j[k] = now_of ? now_of[c] : c;
			}
			jv = _mm256_setr_epi32((int)j[0], (int)j[1], (int)j[2], (int)j[3], (int)j[4], (int)j[5], (int)j[6],
			                       (int)j[7]);
		}
		const float *const quad[8] = {p4 + 4 * (size_t)j[0], p4 + 4 * (size_t)j[1], p4 + 4 * (size_t)j[2],
		                              p4 + 4 * (size_t)j[3], p4 + 4 * (size_t)j[4], p4 + 4 * (size_t)j[5],
		                              p4 + 4 * (size_t)j[6], p4 + 4 * (size_t)j[7]};
		__m256 px, py, pz, pw;
		sph_transpose8(quad, &px, &py, &pz, &pw);
		const __m256 rx = _mm256_sub_ps(vxi, px), ry = _mm256_sub_ps(vyi, py), rz = _mm256_sub_ps(vzi, pz);
		const __m256 d = _mm256_sub_ps(
			vh2, _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(rx, rx), _mm256_mul_ps(ry, ry)), _mm256_mul_ps(rz, rz)));
		const __m256 real = _mm256_castsi256_ps(_mm256_cmpgt_epi32(_mm256_set1_epi32((int)(vc - q)), lane));
		const unsigned in =
			(unsigned)_mm256_movemask_ps(_mm256_and_ps(real, _mm256_cmp_ps(d, _mm256_setzero_ps(), _CMP_GT_OQ)));
		/* lane numbers of the ones in, packed: a byte per lane */
		const uint64_t keep = _pdep_u64(in, 0x0101010101010101ull) * 0xFF;
		const __m256i perm =
			_mm256_cvtepu8_epi32(_mm_cvtsi64_si128((long long)_pext_u64(0x0706050403020100ull, keep)));
		_mm256_storeu_si256((__m256i *)(jl + cnt), _mm256_permutevar8x32_epi32(jv, perm));
		_mm256_storeu_ps(dv + cnt, _mm256_permutevar8x32_ps(d, perm));
		cnt += (uint32_t)__builtin_popcount(in);
	}
	*done = vc;
	return cnt;
}
#endif

/* The exact lists and kernel sums from the Verlet list: candidates mapped to
 * the rows they are in now, r^2 < h^2 kept, sorted by row, summed in that
 * order. p4 holds (x, y, z, -) per row. */
static bool filter(const sph_neighbors *nb, const float *p4, float h2, long n, int threads, uint32_t *max_f,
                   uint32_t *max_b)
{
	const size_t vcap = nb->vcap, vbcap = nb->vbcap, cap = nb->cap, bcap = nb->bcap;
	/* the row a build slot is in now; the same while no permutation moved a
	 * particle since the search (a loop-invariant test, hoisted) */
	const uint32_t *now_of = nb->vsame ? NULL : nb->now_of;
#define ROW(slot) (now_of ? now_of[slot] : (slot))
#ifdef SPH_AVX2
	const bool avx2 = sph_use_avx2();
#endif
	uint32_t mf = 0, mb = 0;
	bool ok = true;
#pragma omp parallel num_threads(threads) reduction(max : mf, mb) reduction(&& : ok)
	{
	/* a particle's hits, sorted here and then written once, whole, which
	 * the memory system streams; + 8: whole groups are stored */
	uint32_t *jl = malloc((vcap + 8) * sizeof *jl);
	float *dv = malloc((vcap + 8) * sizeof *dv);
	ok = jl && dv;
#pragma omp for schedule(static)
	for (long i = 0; i < n; ++i) {
		if (!ok)
			continue;
		const uint32_t b = nb->slot_of[i];
		const uint32_t *cand = nb->vnbr + (size_t)b * vcap;
		const uint32_t vc = nb->vcount[b];
		uint32_t *list = nb->nbr + (size_t)i * cap;
		const float xi = p4[4 * i], yi = p4[4 * i + 1], zi = p4[4 * i + 2];
		uint32_t cnt = 0;
		float ws = 0;
		{
			uint32_t q = 0;
			/* branch-free (whether a candidate is in is a coin toss): every
			 * candidate is written, and the count moves past the ones in */
#ifdef SPH_AVX2
			if (avx2)
				cnt = filter_avx2(cand, vc, now_of, p4, xi, yi, zi, h2, jl, dv, &q);
#endif
#ifdef __SSE2__
			const __m128 vxi = _mm_set1_ps(xi), vyi = _mm_set1_ps(yi), vzi = _mm_set1_ps(zi), vh2 = _mm_set1_ps(h2);
			for (; q + 4 <= vc; q += 4) {
				const uint32_t j0 = ROW(cand[q]), j1 = ROW(cand[q + 1]), j2 = ROW(cand[q + 2]), j3 = ROW(cand[q + 3]);
				__m128 px = _mm_loadu_ps(p4 + 4 * (size_t)j0), py = _mm_loadu_ps(p4 + 4 * (size_t)j1),
				       pz = _mm_loadu_ps(p4 + 4 * (size_t)j2), pw = _mm_loadu_ps(p4 + 4 * (size_t)j3);
				_MM_TRANSPOSE4_PS(px, py, pz, pw);
				const __m128 rx = _mm_sub_ps(vxi, px), ry = _mm_sub_ps(vyi, py), rz = _mm_sub_ps(vzi, pz);
				const __m128 d = _mm_sub_ps(
					vh2, _mm_add_ps(_mm_add_ps(_mm_mul_ps(rx, rx), _mm_mul_ps(ry, ry)), _mm_mul_ps(rz, rz)));
				const unsigned in = (unsigned)_mm_movemask_ps(_mm_cmpgt_ps(d, _mm_setzero_ps()));
				float dd[4];
				_mm_storeu_ps(dd, d);
				jl[cnt] = j0;
				dv[cnt] = dd[0];
				cnt += in & 1;
				jl[cnt] = j1;
				dv[cnt] = dd[1];
				cnt += in >> 1 & 1;
				jl[cnt] = j2;
				dv[cnt] = dd[2];
				cnt += in >> 2 & 1;
				jl[cnt] = j3;
				dv[cnt] = dd[3];
				cnt += in >> 3;
			}
#endif
			for (; q < vc; ++q) {
				const uint32_t j = ROW(cand[q]);
				const float *pj = p4 + 4 * (size_t)j;
				const float rx = xi - pj[0], ry = yi - pj[1], rz = zi - pj[2];
				const float d = h2 - (rx * rx + ry * ry + rz * rz);
				jl[cnt] = j;
				dv[cnt] = d;
				cnt += d > 0;
			}
			/* sorted already unless a particle changed cell since the search,
			 * and then nearly: check four at a time, insertion-sort if not */
			uint32_t a = 1;
#ifdef __SSE2__
			const __m128i flip = _mm_set1_epi32(INT32_MIN); /* unsigned order by a signed compare */
			for (; a + 4 <= cnt; a += 4) {
				const __m128i prev = _mm_xor_si128(_mm_loadu_si128((const __m128i *)(jl + a - 1)), flip),
				              cur = _mm_xor_si128(_mm_loadu_si128((const __m128i *)(jl + a)), flip);
				if (_mm_movemask_epi8(_mm_cmpgt_epi32(prev, cur)))
					break;
			}
#endif
			for (; a < cnt; ++a) {
				const uint32_t j = jl[a];
				if (jl[a - 1] < j)
					continue;
				const float d = dv[a];
				uint32_t k = a;
				for (; k > 0 && jl[k - 1] > j; --k) {
					jl[k] = jl[k - 1];
					dv[k] = dv[k - 1];
				}
				jl[k] = j;
				dv[k] = d;
			}
			ws = cube_sum(dv, cnt);
			if (cnt <= cap) {
				/* whole quads (cap is a multiple of 8): short rows, where a
				 * memcpy call costs more than the copy */
				q = 0;
#ifdef __SSE2__
				for (; q < cnt; q += 4)
					_mm_storeu_si128((__m128i *)(list + q), _mm_loadu_si128((const __m128i *)(jl + q)));
#endif
				for (; q < cnt; ++q)
					list[q] = jl[q];
			}
		}
		nb->count[i] = cnt;
		nb->wsum[i] = ws;

		/* the boundary candidates are in index order (the search sorted
		 * them), and filtering keeps it */
		const uint32_t *bcand = nb->vbnbr + (size_t)b * vbcap;
		const uint32_t vbc = nb->vbcount[b];
		uint32_t *blist = nb->bnbr + (size_t)i * bcap;
		uint32_t bcnt = 0;
		float bws = 0;
		for (uint32_t q = 0; q < vbc; ++q) {
			const uint32_t jb = bcand[q];
			const float rx = xi - nb->bx[jb], ry = yi - nb->by[jb], rz = zi - nb->bz[jb];
			const float d = h2 - (rx * rx + ry * ry + rz * rz);
			if (d > 0) {
				if (bcnt < bcap)
					blist[bcnt] = jb;
				bcnt++;
				bws += nb->bvol[jb] * nb->brho[jb] * d * d * d;
			}
		}
		nb->bcount[i] = bcnt;
		nb->bwsum[i] = bws;
		mf = cnt > mf ? cnt : mf;
		mb = bcnt > mb ? bcnt : mb;
	}
	free(jl);
	free(dv);
	}
	*max_f = mf;
	*max_b = mb;
	return ok;
#undef ROW
}

eddy_status eddy__sph_boundary_ready(eddy_world *w, sph_shared *sh)
{
	eddy_status st = grid_setup(w, &sh->nb, sh->h);
	return st == EDDY_OK ? boundary_build(w, sh) : st;
}

/* nb->bdiv: sum_b V_b rho0 v_b . grad W_spiky(x_i - x_b) per row, the
 * density change rate the moving walls add (Akinci et al. 2012, eq. 6 with
 * the wall's velocity; sph_dfsph's Drho/Dt), with sph_dfsph's kernel
 * gradient and cut-offs; NULL while no wall moves. */
static eddy_status boundary_divergence(eddy_world *w, sph_shared *sh, int threads)
{
	sph_neighbors *nb = &sh->nb;
	bool moving = false;
	for (size_t b = nb->nbs; b < nb->nb && !moving; ++b)
		moving = nb->bvx[b] != 0 || nb->bvy[b] != 0 || nb->bvz[b] != 0;
	if (!moving || !sh->pq) {
		free(nb->bdiv);
		nb->bdiv = NULL;
		nb->bdiv_alloc = 0;
		return EDDY_OK;
	}
	const size_t n = nb->n;
	if (!grow((void **)&nb->bdiv, &nb->bdiv_alloc, n, sizeof *nb->bdiv))
		return eddy__fail(w, EDDY_ERR_NOMEM, "sph_density: out of memory for %zu particles", n);
	const float h = sh->k.h, eps2 = 1e-6f * sh->k.h2, c0 = sh->rho0 * sh->k.spiky_grad;
	const float *p4 = sh->pq;
	const long ln = (long)n;
#pragma omp parallel for num_threads(threads) schedule(static)
	for (long i = 0; i < ln; ++i) {
		const uint32_t *bl = nb->bnbr + (size_t)i * nb->bcap;
		float u = 0;
		for (uint32_t q = 0; q < nb->bcount[i]; ++q) {
			const uint32_t b = bl[q];
			if (b < nb->nbs)
				continue; /* at rest */
			const float rx = p4[4 * i] - nb->bx[b], ry = p4[4 * i + 1] - nb->by[b], rz = p4[4 * i + 2] - nb->bz[b];
			const float r2 = rx * rx + ry * ry + rz * rz, r = sqrtf(r2), hr = h - r;
			if (!(r2 > eps2 && hr > 0))
				continue;
			const float c = nb->bvol[b] * c0 * hr * hr / r;
			u += c * (rx * nb->bvx[b] + ry * nb->bvy[b] + rz * nb->bvz[b]);
		}
		nb->bdiv[i] = u;
	}
	return EDDY_OK;
}

/* Grows every per-particle array to n. */
static bool grow_rows(sph_neighbors *nb, size_t n)
{
	void **arrays[] = {(void **)&nb->cell_of, (void **)&nb->count, (void **)&nb->bcount, (void **)&nb->wsum,
	                   (void **)&nb->bwsum,   (void **)&nb->vcount, (void **)&nb->vbcount, (void **)&nb->vx,
	                   (void **)&nb->vy,      (void **)&nb->vz,     (void **)&nb->slot_of, (void **)&nb->now_of};
	size_t had = nb->n_alloc;
	for (size_t a = 0; a < sizeof arrays / sizeof arrays[0]; ++a) {
		had = nb->n_alloc;
		if (!grow(arrays[a], &had, n, 4)) /* every one is 4 bytes a row */
			return false;
	}
	nb->n_alloc = had;
	return true;
}

eddy_status eddy__sph_neighbors_build(eddy_world *w, sph_shared *sh, int threads)
{
	sph_neighbors *nb = &sh->nb;
	eddy_status st = grid_setup(w, nb, sh->h);
	if (st != EDDY_OK)
		return st;
	st = boundary_build(w, sh);
	if (st != EDDY_OK)
		return st;
	/* the collider particles where the colliders are now; how far they are
	 * from where the last search saw them counts as a particle's motion */
	const float bmove2 = nb->ncol ? boundary_move(w, nb) : 0.0f;
	const size_t n = w->n;
	nb->n = n;
	sh->pq = NULL;
	if (n == 0) {
		nb->vvalid = false;
		return EDDY_OK;
	}
	if (!nb->vcap) {
		nb->vcap = 80;
		nb->vbcap = 32;
	}
	if (!grow_rows(nb, n))
		return eddy__fail(w, EDDY_ERR_NOMEM, "sph_density: out of memory for %zu particles", n);

	/* cell order */
	float *x = eddy__col(w, COL_X_), *y = eddy__col(w, COL_Y_), *z = eddy__col(w, COL_Z_);
	uint32_t *key = eddy__arena_alloc(&w->arena, n * sizeof *key);
	uint32_t *order = eddy__arena_alloc(&w->arena, n * sizeof *order);
	void *scratch = eddy__arena_alloc(&w->arena, n * sizeof(float));
	float *p4 = eddy__arena_alloc(&w->arena, 4 * n * sizeof *p4);
	if (!key || !order || !scratch || !p4)
		return eddy__fail(w, EDDY_ERR_NOMEM, "sph_density: out of scratch memory for %zu particles", n);
	const long ln = (long)n;
	/* a fluid at rest keeps its order from step to step: then the counting
	 * sort (over every cell of the world) and the copying are skipped, and
	 * the cell ranges are made only if something needs them. One pass does
	 * what such a step needs (a parallel region costs a thread wake-up): the
	 * cells, the order check, the (x y z -) quads and, if the Verlet list
	 * may still be good, how far the particles are from their build slots. */
	const bool prevalid = nb->vvalid && nb->vn == n && nb->vbsig == nb->bsig;
	const float half = 0.49f * nb->skin * sh->h; /* 0.49: float rounding */
	nb->age++;
	const float lim2 = half * half;
	int sorted = 1;
	float d2max = 0;
#pragma omp parallel for num_threads(threads) schedule(static) reduction(&& : sorted) reduction(max : d2max)
	for (long i = 0; i < ln; ++i) {
		const uint32_t k = cell_index(nb, x[i], y[i], z[i]);
		key[i] = nb->cell_of[i] = k;
		sorted = sorted && (i == 0 || cell_index(nb, x[i - 1], y[i - 1], z[i - 1]) <= k);
		p4[4 * i] = x[i];
		p4[4 * i + 1] = y[i];
		p4[4 * i + 2] = z[i];
		p4[4 * i + 3] = 0; /* sph_density puts 1/rho here */
		if (prevalid) {
			const uint32_t b = nb->slot_of[i];
			const float dx = x[i] - nb->vx[b], dy = y[i] - nb->vy[b], dz = z[i] - nb->vz[b];
			const float d2 = dx * dx + dy * dy + dz * dz;
			d2max = d2 > d2max ? d2 : d2max;
		}
	}
	const size_t cells = (size_t)nb->gx * (size_t)nb->gy * (size_t)nb->gz;
	const bool same = sorted;
	bool ranges = false; /* nb->cell_start matches the table */
	if (!same) {
		counting_sort(key, n, cells, nb->cell_start, order);
		eddy__permute_particles(w, order, scratch);
		ranges = true;
		/* follow the rows through the permutation */
		if (prevalid) {
			uint32_t *slot = scratch;
#pragma omp parallel for num_threads(threads) schedule(static)
			for (long i = 0; i < ln; ++i)
				slot[i] = nb->slot_of[order[i]];
			memcpy(nb->slot_of, slot, n * sizeof *slot);
			nb->vsame = false;
		}
		d2max = 0;
#pragma omp parallel for num_threads(threads) schedule(static) reduction(max : d2max)
		for (long i = 0; i < ln; ++i) {
			nb->cell_of[i] = key[order[i]];
			p4[4 * i] = x[i];
			p4[4 * i + 1] = y[i];
			p4[4 * i + 2] = z[i];
			p4[4 * i + 3] = 0;
			if (prevalid) {
				const uint32_t b = nb->slot_of[i];
				nb->now_of[b] = (uint32_t)i;
				const float dx = x[i] - nb->vx[b], dy = y[i] - nb->vy[b], dz = z[i] - nb->vz[b];
				const float d2 = dx * dx + dy * dy + dz * dz;
				d2max = d2 > d2max ? d2 : d2max;
			}
		}
	}
	/* the Verlet list is good while every particle is within skin/2 of its
	 * build slot's position */
	d2max = bmove2 > d2max ? bmove2 : d2max;
	bool valid = prevalid && nb->vlist && d2max < lim2; /* false for NaN too */
	/* the search and the boundary pressure walk cells */
	if (!ranges && (!valid || nb->nb > 0)) {
		cell_ranges(key, n, cells, nb->cell_start);
		ranges = true;
	}
	if (!valid) {
		st = boundary_sort(w, nb);
		if (st != EDDY_OK)
			return st;
		/* The skin pays only if the list outlives a few steps: when particles
		 * move a good part of the skin per step (DFSPH's steps are ten times
		 * WCSPH's) or the count changes every step (an emitter), a skin only
		 * adds candidates (1.7x at 0.2 h) to a search made every step anyway.
		 * Then the list is searched at h itself until the motion per step,
		 * seen against the last search, would let a skin last. Otherwise
		 * the skin is sized for SPH_SKIN_LIFE steps of that motion: a fluid
		 * at rest filters (1.05)^3 of its exact lists' pairs, not (1.2)^3. */
		const bool emitting = !prevalid && nb->vvalid && nb->vn != n && nb->count_changed && nb->age <= 1;
		const float step_move = prevalid ? sqrtf(d2max) / (float)nb->age : 0.0f;
		const bool fast = prevalid && step_move * SPH_SKIN_MIN_LIFE > 0.5f * SPH_SKIN * sh->h;
		const float sized = 2.0f * SPH_SKIN_LIFE * step_move / sh->h;
		nb->count_changed = nb->vvalid && nb->vn != n;
		nb->skin = emitting || fast ? 0.0f
		           : !prevalid      ? SPH_SKIN
		                            : fminf(SPH_SKIN, fmaxf(SPH_SKIN_MIN, sized));
		if (nb->skin > 0) {
			/* 1e-4 over: the filter's exact test (r < h, other operation
			 * order) must find every pair it would keep among the candidates */
			const float hs = sh->h * (1.0f + nb->skin + 1e-4f), hs2 = hs * hs;
			for (;;) {
				size_t want = n * nb->vcap, have = nb->vcap_alloc;
				if (!grow((void **)&nb->vnbr, &have, want, sizeof *nb->vnbr))
					return eddy__fail(w, EDDY_ERR_NOMEM, "sph_density: out of memory for neighbour lists (%zu x %zu)",
					                  n, nb->vcap);
				nb->vcap_alloc = have;
				want = n * nb->vbcap;
				have = nb->vbcap_alloc;
				if (!grow((void **)&nb->vbnbr, &have, want, sizeof *nb->vbnbr))
					return eddy__fail(w, EDDY_ERR_NOMEM, "sph_density: out of memory for neighbour lists (%zu x %zu)",
					                  n, nb->vbcap);
				nb->vbcap_alloc = have;
				uint32_t mf, mb;
				if (!search(w, nb, hs2, false, threads, &mf, &mb))
					return eddy__fail(w, EDDY_ERR_NOMEM, "sph_density: out of scratch memory for the neighbour search");
				if (mf <= nb->vcap && mb <= nb->vbcap)
					break;
				/* a particle had more candidates than the stride: widen and redo */
				if (mf > nb->vcap)
					nb->vcap = (mf + 15) / 16 * 16;
				if (mb > nb->vbcap)
					nb->vbcap = (mb + 15) / 16 * 16;
			}
		}
		memcpy(nb->vx, x, n * sizeof *x);
		memcpy(nb->vy, y, n * sizeof *y);
		memcpy(nb->vz, z, n * sizeof *z);
		for (size_t i = 0; i < n; ++i)
			nb->slot_of[i] = nb->now_of[i] = (uint32_t)i;
		nb->vn = n;
		nb->vbsig = nb->bsig;
		/* without a skin only the positions are kept (to size the next
		 * skin): the search below writes the exact lists directly */
		nb->vvalid = true;
		nb->vlist = nb->skin > 0;
		nb->vsame = true;
		nb->age = 0;
		nb->searches++;
	}

	sh->pq = p4;
	/* the exact lists, with their own (tighter) strides */
	const bool direct = !nb->vlist;
	if (!nb->cap) {
		nb->cap = 32;
		nb->bcap = 16;
	}
	for (;;) {
		size_t want = n * nb->cap, have = nb->cap_alloc;
		if (!grow((void **)&nb->nbr, &have, want, sizeof *nb->nbr))
			return eddy__fail(w, EDDY_ERR_NOMEM, "sph_density: out of memory for neighbour lists (%zu x %zu)", n, nb->cap);
		nb->cap_alloc = have;
		want = n * nb->bcap;
		have = nb->bcap_alloc;
		if (!grow((void **)&nb->bnbr, &have, want, sizeof *nb->bnbr))
			return eddy__fail(w, EDDY_ERR_NOMEM, "sph_density: out of memory for neighbour lists (%zu x %zu)", n, nb->bcap);
		nb->bcap_alloc = have;
		uint32_t mf, mb;
		const bool ok = direct ? search(w, nb, sh->k.h2, true, threads, &mf, &mb)
		                       : filter(nb, p4, sh->k.h2, (long)n, threads, &mf, &mb);
		if (!ok)
			return eddy__fail(w, EDDY_ERR_NOMEM, "sph_density: out of scratch memory for the neighbour lists");
		if (mf <= nb->cap && mb <= nb->bcap)
			break;
		/* more neighbours than the stride (compressed fluid): widen, with
		 * room to spare so that this stays rare, and redo */
		if (mf > nb->cap)
			nb->cap = (mf + 7) / 8 * 8 + 8;
		if (mb > nb->bcap)
			nb->bcap = (mb + 7) / 8 * 8 + 8;
	}
	return boundary_divergence(w, sh, threads);
}
