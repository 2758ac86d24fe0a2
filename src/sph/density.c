/* SPDX-License-Identifier: MIT */
/* sph_density: neighbour search, density and equation of state.
 *
 * Reads: x y z (density = continuity: also vx vy vz sph_rho). Writes:
 * density pressure neighbors (continuity: also sph_rho), and reorders the
 * particle table into grid-cell order (neighbors.c, which also makes the
 * kernel sums below with the lists). Shares sph_shared (sph.h) with the
 * later SPH systems.
 * density = summation (the default):
 *   rho_i = m sum_j W_poly6(x_i - x_j) + sum_b V_b rho_b W_poly6(x_i - x_b)
 *   (j over fluid particles including i itself, b over boundary particles)
 * density = continuity (weakly compressible SPH with sph_pressure only): the
 * density is state, the column sph_rho, advanced each step by
 *   d rho_i/dt = rho_i sum_j V_j (v_i - v_j) . grad W_ij
 *              + rho_i sum_b V_b (v_i - v_b) . grad W_ib
 *              + delta h c sum_j V_j psi_ij . grad W_ij,
 *   psi_ij = 2 (rho_j - rho_i - rho0 g . (x_j - x_i) / c^2) (x_j - x_i) / (r^2 + 0.01 h^2)
 * (V_j = m / rho_j, W the spiky kernel, the sums calibrated by its lattice
 * moment as sph_pressure's force; v_b a moving collider's). The last term
 * is delta-SPH's density diffusion (Molteni & Colagrossi 2009; Antuono,
 * Colagrossi & Marrone 2010), less its hydrostatic part (Fourtakas et al.
 * 2019, linearised: rho0 g dz / c^2 is the EOS's density step of a
 * hydrostatic pressure step): it damps the acoustic noise and leaves a
 * column at rest with its hydrostatic densities. h is the support radius
 * (2 spacings, the smoothing length of the delta-SPH papers' Wendland kernels
 * of support 2h at h/dx = 1-2), so delta = 0.1 is theirs. A free-surface
 * particle keeps its density (no truncated kernel sum reading low); the walls
 * enter through their volumes only (their densities are not iterated, see
 * below). New particles start hydrostatic (hydrostatic_start, below). The
 * explicit diffusion is stable while cfl delta h^2 lambda <= 2 (lambda its
 * largest eigenvalue on the lattice, diffusion_eigenvalue below): delta 0.1
 * at h = 2 spacings up to cfl 0.88; check() and step refuse beyond.
 * Source: Molteni & Colagrossi, "A simple procedure to improve the pressure
 * evaluation in hydrodynamic context using the SPH", CPC 180 (2009);
 * Antuono, Colagrossi, Marrone & Molteni, "Free-surface flows solved by
 * means of SPH schemes with numerical diffusive terms", CPC 181 (2010);
 * Fourtakas, Dominguez, Vacondio & Rogers, "Local uniform stencil (LUST)
 * boundary condition for arbitrary 3-D boundaries in parallel smoothed
 * particle hydrodynamics (SPH) models", Computers & Fluids 190 (2019).
 *   linear EOS: p_i = k (rho_i - rho0)                      (Mueller 2003, eq. 12)
 *   Tait EOS:   p_i = (k rho0 / gamma) ((rho_i/rho0)^gamma - 1)
 *   p_i >= 0: negative pressure pulls particles into clumps (tensile
 *   instability, docs/validation.md C.1), and a free surface's truncated
 *   kernel sum reads low. Tension kept only where a particle has a full
 *   neighbourhood, floored at as little as 0.03% of k rho0, with or without
 *   Monaghan's artificial pressure or Sun et al.'s p_j - p_i form for a
 *   particle in tension, makes an inviscid column thrown onto a wall gain
 *   energy (stress_wcsph's budget). So fluid a solid stirs apart stays
 *   expanded while it is stirred and closes under gravity afterwards.
 * Boundary particles carry the pressure extrapolated from the fluid near
 * them with the hydrostatic correction (Adami, Hu & Adams 2012, eq. 27),
 *   p_b = max(0, sum_f (p_f + rho_f g . (x_b - x_f)) W_bf / sum_f W_bf),
 * and the density rho_b the EOS gives for it. Frozen at rho0 (plain Akinci
 * et al. 2012) the walls would leave the fluid beside them less compressed
 * than the fluid away from them, and it would sink along them in a steady
 * circulation.
 * m = rho0 / sum_lattice W_poly6 over a simple cubic lattice of the given
 * spacing: a block at rest starts at rho0 exactly, not 1% above it at h = 2
 * spacings (C.8). The self term keeps rho > 0 for a lone particle (C.6).
 * No time-step limit: the acoustic one is sph_pressure's, the force that
 * carries sound at c = sqrt(k); a pressure solve (sph_dfsph) has none.
 * Source: Mueller, Charypar & Gross, "Particle-Based Fluid Simulation for
 * Interactive Applications", SCA 2003; Akinci et al., "Versatile rigid-fluid
 * coupling for incompressible SPH", SIGGRAPH 2012 (boundary term); tension:
 * Monaghan, "SPH without a tensile instability", JCP 159 (2000); Sun et al.,
 * "The delta-plus-SPH model", CMAME 315 (2017). */
#include "sph.h"
#include "systems.h"

#include <float.h>
#include <stdlib.h>
#include <string.h>

typedef struct sph_density {
	sph_shared sh;
	eddy_sph_density_def def;
	uint32_t *wall_slot; /* per wall, WALL_NONE between steps (walls_make) */
	size_t wall_slots;
	int carried;         /* continuity: the state column holding each particle's density between steps */
	float diffusion_eig; /* continuity: 1/m^2, the diffusion's largest eigenvalue on the lattice over delta h c */
	bool auto_sound;     /* the def's stiffness was 0: c from the scene (rederive) */
	double reach_speed;  /* m/s, the fastest the scene's water can get by itself (rederive) */
	double reach_fall;   /* m, the fall in that speed */
} sph_density;

static const int density_reads[] = {COL_X_, COL_Y_, COL_Z_, -1};
static const int density_writes[] = {COL_DENSITY, COL_PRESSURE, COL_SPH_NEIGHBORS, -1};
#define CARRIED_NAME "sph_rho" /* the continuity density's state column */

eddy_sph_density_def eddy_default_sph_density_def(void)
{
	return (eddy_sph_density_def){.radius = 0.02f,
	                              .spacing = 0.01f,
	                              .rest_density = 1000.0f,
	                              .stiffness = 0.0f, /* from the scene */
	                              .eos = EDDY_SPH_EOS_LINEAR,
	                              .tait_gamma = 7.0f,
	                              .density = EDDY_SPH_DENSITY_SUMMATION,
	                              .diffusion = 0.1f,
	                              .verlet_list = true};
}

/* The EOS: pressure of a density (clamped at 0) and density of a pressure. */
static float eos_pressure(const sph_density *sd, float rho)
{
	const float rho0 = sd->sh.rho0, k = sd->def.stiffness, gamma = sd->def.tait_gamma;
	const float p =
		sd->def.eos == EDDY_SPH_EOS_TAIT ? k * rho0 / gamma * (powf(rho / rho0, gamma) - 1.0f) : k * (rho - rho0);
	return p > 0 ? p : 0;
}

/* The EOS's constants, copied where a loop's float stores would otherwise
 * make the compiler reload them every iteration. */
typedef struct eos_consts {
	eddy_sph_eos eos;
	float rho0, k, gamma;
} eos_consts;

static eos_consts eos_of(const sph_density *sd)
{
	return (eos_consts){sd->def.eos, sd->sh.rho0, sd->def.stiffness, sd->def.tait_gamma};
}

static inline float eos_rho(eos_consts e, float p)
{
	return e.eos == EDDY_SPH_EOS_TAIT ? e.rho0 * powf(p / (e.k * e.rho0 / e.gamma) + 1.0f, 1.0f / e.gamma)
	                                  : e.rho0 + p / e.k;
}

static float eos_density(const sph_density *sd, float p) { return eos_rho(eos_of(sd), p); }

/* The wall densities enter the fluid's density sums, which set the pressure
 * the walls copy: a loop. Closed with the previous step's wall densities (as
 * the neighbour search summed them) it is a one-step-lagged positive feedback
 * that pumps energy into the fluid at the walls (a still column never comes
 * to rest). With the EOS pressure (sph_pressure) it is iterated within the
 * step: the fluid near the walls takes their new densities, sum_b V_b
 * (rho_b new - rho_b old) W_poly6, and the walls are extrapolated again,
 * WALL_PASSES_MAX times or until no wall density changes by more than
 * WALL_TOL of the first pass's change; each pass shrinks the error by the
 * walls' share of a kernel sum (1/4 at a flat wall, 1/2 at a corner). With
 * sph_dfsph iterated walls pump energy in instead: it keeps the lag.
 * Only the walls with fluid near them (act) and the fluid rows with walls
 * near them take part, through the pairs in the fluid's list order; every
 * other wall is at p = 0 and its EOS density. A wall's sums run over its
 * fluid rows in ascending order, whichever thread adds them. */
#define WALL_PASSES_MAX 3
#define WALL_TOL 1e-3f
#define WALL_NONE UINT32_MAX

/* The wall-fluid pairs of one step, in the fluid's list order: row
 * rows[r]'s are [fstart[r], fstart[r + 1]). */
typedef struct walls {
	long nact, nrows;
	uint32_t *act;    /* the walls with fluid near them, numbered in the order the rows first name them */
	uint32_t *rows;   /* the fluid rows with walls near them, ascending */
	uint32_t *fstart; /* nrows + 1 */
	uint32_t *slot;   /* per pair: its wall's place in act */
	float *wgt;       /* per pair: (h^2 - r^2)^3 */
	float *grav;      /* per pair: g . (x_b - x_f) */
	/* per act entry: */
	float *sp;     /* sum of W (p_f + rho_f g . (x_b - x_f)) */
	float *inv_sw; /* 1 / sum of W (0: none) */
	float *old;    /* the wall density the fluid sums hold */
	float *dv;     /* V_b times the change of that density */
	float *vol;    /* V_b */
	float *pb;     /* the wall pressure, stored to the wall once the passes end */
} walls;

static void *scratch(eddy_world *w, size_t count, size_t size, bool *ok)
{
	void *p = eddy__arena_alloc(&w->arena, (count ? count : 1) * size);
	*ok = *ok && p;
	return p;
}

/* The pairs, their walls numbered through sd->wall_slot (WALL_NONE for
 * every wall between steps), so nothing here is proportional to the walls
 * without fluid near them; the weights in parallel over the rows. */
static bool walls_make(eddy_world *w, sph_density *sd, int threads, walls *wl)
{
	const sph_neighbors *nb = &sd->sh.nb;
	const size_t n = w->n, nbound = nb->nbound;
	bool ok = true;
	*wl = (walls){0};
	if (sd->wall_slots < nbound) {
		uint32_t *s = realloc(sd->wall_slot, nbound * sizeof *s);
		if (!s)
			return false;
		for (size_t b = sd->wall_slots; b < nbound; ++b)
			s[b] = WALL_NONE;
		sd->wall_slot = s;
		sd->wall_slots = nbound;
	}
	size_t pairs = 0;
	for (size_t i = 0; i < n; ++i)
		pairs += nb->bcount[i];
	wl->act = scratch(w, nbound, sizeof *wl->act, &ok);
	wl->rows = scratch(w, n, sizeof *wl->rows, &ok);
	wl->fstart = scratch(w, n + 1, sizeof *wl->fstart, &ok);
	wl->slot = scratch(w, pairs, sizeof *wl->slot, &ok);
	wl->wgt = scratch(w, pairs, sizeof *wl->wgt, &ok);
	wl->grav = scratch(w, pairs, sizeof *wl->grav, &ok);
	if (!ok)
		return false;
	uint32_t *slot = sd->wall_slot, f = 0;
	long nact = 0, nrows = 0;
	for (size_t i = 0; i < n; ++i) {
		const uint32_t *bl = sph_bnbrs(nb, i);
		if (nb->bcount[i]) {
			wl->fstart[nrows] = f;
			wl->rows[nrows++] = (uint32_t)i;
		}
		for (uint32_t q = 0; q < nb->bcount[i]; ++q, ++f) {
			if (slot[bl[q]] == WALL_NONE) {
				slot[bl[q]] = (uint32_t)nact;
				wl->act[nact++] = bl[q];
			}
			wl->slot[f] = slot[bl[q]];
		}
	}
	wl->fstart[nrows] = f;
	wl->nact = nact;
	wl->nrows = nrows;
	for (long a = 0; a < nact; ++a)
		slot[wl->act[a]] = WALL_NONE;
	wl->sp = scratch(w, (size_t)nact, sizeof *wl->sp, &ok);
	wl->inv_sw = scratch(w, (size_t)nact, sizeof *wl->inv_sw, &ok);
	wl->old = scratch(w, (size_t)nact, sizeof *wl->old, &ok);
	wl->dv = scratch(w, (size_t)nact, sizeof *wl->dv, &ok);
	wl->vol = scratch(w, (size_t)nact, sizeof *wl->vol, &ok);
	wl->pb = scratch(w, (size_t)nact, sizeof *wl->pb, &ok);
	if (!ok)
		return false;
	const eddy_vec3 g = eddy__gravity(w); /* the gravity systems' (none while the world settles its start) */
	const float h2 = sd->sh.k.h2;
#pragma omp parallel for num_threads(threads) schedule(static)
	for (long r = 0; r < nrows; ++r) {
		const uint32_t i = wl->rows[r], *bl = sph_bnbrs(nb, i);
		const float *xi = sd->sh.pq + 4 * i; /* x_f y_f z_f */
		for (uint32_t k = wl->fstart[r], q = 0; k < wl->fstart[r + 1]; ++k, ++q) {
			const uint32_t b = bl[q];
			const float rx = nb->bx[b] - xi[0], ry = nb->by[b] - xi[1], rz = nb->bz[b] - xi[2];
			const float d = h2 - (rx * rx + ry * ry + rz * rz);
			wl->wgt[k] = d * d * d;
			wl->grav[k] = g.x * rx + g.y * ry + g.z * rz;
		}
	}
	for (long a = 0; a < nact; ++a) {
		wl->old[a] = nb->bnd.rho[wl->act[a]];
		wl->vol[a] = nb->bvol[wl->act[a]];
	}
	return true;
}

/* The sums of walls [lo, hi) of act over the pairs in the fluid's order
 * (all: every wall is in the range), with sum W into sw when given. */
static inline void walls_sum_range(const walls *wl, const float *rho, const float *p, uint32_t lo, uint32_t hi,
                                   bool all, float *restrict sw)
{
	const uint32_t *restrict slot = wl->slot;
	const float *restrict wgt = wl->wgt, *restrict grav = wl->grav;
	float *restrict sp = wl->sp;
	for (uint32_t a = lo; a < hi; ++a) {
		sp[a] = 0;
		if (sw)
			sw[a] = 0;
	}
	for (long r = 0; r < wl->nrows; ++r) {
		const uint32_t i = wl->rows[r];
		const float pi = p[i], ri = rho[i];
		for (uint32_t k = wl->fstart[r], end = wl->fstart[r + 1]; k < end; ++k) {
			const uint32_t a = slot[k];
			if (!all && a - lo >= hi - lo)
				continue;
			sp[a] += wgt[k] * (pi + ri * grav[k]);
			if (sw)
				sw[a] += wgt[k];
		}
	}
}

/* The walls' sums from the fluid, sp (and on the first pass sum W, in
 * inv_sw): each thread takes the walls of an equal share of act, so every
 * wall's terms are added in ascending rows. */
static void walls_sum(const walls *wl, const float *rho, const float *p, bool first, int threads)
{
	if (threads == 1) {
		if (first)
			walls_sum_range(wl, rho, p, 0, (uint32_t)wl->nact, true, wl->inv_sw);
		else
			walls_sum_range(wl, rho, p, 0, (uint32_t)wl->nact, true, NULL);
		return;
	}
#pragma omp parallel for num_threads(threads) schedule(static)
	for (int th = 0; th < threads; ++th)
		walls_sum_range(wl, rho, p, (uint32_t)(wl->nact * th / threads), (uint32_t)(wl->nact * (th + 1) / threads),
		                false, first ? wl->inv_sw : NULL);
}

/* Each wall's pressure from its sums,
 *   p_b = max(0, sum_f (p_f + rho_f g . (x_b - x_f)) W_bf / sum_f W_bf),
 * and its EOS density, in pb and old (boundary_pressure puts them on the walls
 * once the passes end: a pass reads and writes act's order only); the
 * first pass divides by sum W and keeps its inverse, the later ones
 * multiply by that. Returns the largest change of a wall density since the
 * fluid's sums took it, and stores the changes times V_b in dv (the
 * fluid's next correction). */
static float walls_set(const sph_density *sd, const walls *wl, bool first, int threads)
{
	const eos_consts e = eos_of(sd);
	float *restrict sp = wl->sp, *restrict inv_sw = wl->inv_sw, *restrict old = wl->old, *restrict dv = wl->dv,
					*restrict pbs = wl->pb;
	const float *restrict vol = wl->vol;
	const long nact = wl->nact;
	float change = 0;
#pragma omp parallel for num_threads(threads) schedule(static) reduction(max : change)
	for (long a = 0; a < nact; ++a) {
		float s;
		if (first) {
			/* sum W is of order h^6 (1e-18 at h = 1 mm): a wall the fluid
			 * reaches only at the kernel's very edge can sum below
			 * 1 / FLT_MAX, and its inverse was infinite (a dam break at
			 * 0.5 mm spacing stopped with an infinite density). Its weight
			 * in every fluid sum is as small: it is left at p = 0. */
			const float sw = inv_sw[a];
			const bool held = sw > 0 && 1.0f / sw <= FLT_MAX;
			s = held ? sp[a] / sw : 0.0f;
			inv_sw[a] = held ? 1.0f / sw : 0.0f;
		} else
			s = sp[a] * inv_sw[a];
		const float pb = s > 0 ? s : 0.0f, r = eos_rho(e, pb), d = r - old[a];
		pbs[a] = pb;
		old[a] = r;
		dv[a] = vol[a] * d;
		change = fabsf(d) > change ? fabsf(d) : change;
	}
	return change;
}

/* Row i's density r and what follows: 1/rho in its quad, the pressure. */
static inline void set_density(sph_density *sd, float *rho, float *p, long i, float r)
{
	rho[i] = r;
	sd->sh.pq[4 * i + 3] = 1.0f / r;
	p[i] = eos_pressure(sd, r);
}

/* The walls' pressure and density: those with fluid near them extrapolated
 * from it, the rest at p = 0; when iterating, each later pass moves the
 * fluid near the walls to the walls' new densities and extrapolates those
 * walls again. */
static eddy_status boundary_pressure(eddy_world *w, sph_density *sd, int threads)
{
	sph_neighbors *nb = &sd->sh.nb;
	const long nbound = (long)nb->nbound;
	if (w->n == 0 || nbound == 0)
		return EDDY_OK;
	/* continuity: the walls' densities are not in the fluid's */
	const bool iterate =
		eddy__provider(w, NULL, EDDY_CAP_SPH_EOS_FORCE) != NULL && sd->def.density != EDDY_SPH_DENSITY_CONTINUITY;
	walls wl;
	const eddy_arena_mark mark = eddy__arena_mark(&w->arena); /* wl's arrays: this pass's own */
	if (!walls_make(w, sd, threads, &wl))
		return eddy__fail(w, EDDY_ERR_NOMEM, "sph_density: out of scratch memory for %ld boundary particles", nbound);
	float *rho = eddy__col(w, COL_DENSITY), *p = eddy__col(w, COL_PRESSURE);
	const float rho_free = eos_density(sd, 0); /* a wall with no fluid near it */
	for (long b = 0; b < nbound; ++b) {
		nb->bp[b] = 0;
		nb->bnd.rho[b] = rho_free;
	}
	walls_sum(&wl, rho, p, true, threads);
	float change = walls_set(sd, &wl, true, threads);
	const float first = change; /* the lag */
	for (int pass = 1; iterate && pass <= WALL_PASSES_MAX; ++pass) {
		if (pass > 1 && !(change > WALL_TOL * first))
			break;
		/* in locals: set_density's stores would reload them from wl */
		const uint32_t *restrict fstart = wl.fstart, *restrict slot = wl.slot, *restrict rows = wl.rows;
		const float *restrict dv = wl.dv, *restrict wgt = wl.wgt;
		const long nrows = wl.nrows;
#pragma omp parallel for num_threads(threads) schedule(static)
		for (long r = 0; r < nrows; ++r) {
			float dr = 0;
			for (uint32_t k = fstart[r]; k < fstart[r + 1]; ++k)
				dr += dv[slot[k]] * wgt[k];
			if (dr != 0) {
				const uint32_t i = rows[r];
				set_density(sd, rho, p, i, rho[i] + sd->sh.k.poly6 * dr);
			}
		}
		walls_sum(&wl, rho, p, false, threads);
		change = walls_set(sd, &wl, false, threads);
	}
	for (long a = 0; a < wl.nact; ++a) {
		nb->bp[wl.act[a]] = wl.pb[a];
		nb->bnd.rho[wl.act[a]] = wl.old[a];
	}
	eddy__arena_release(&w->arena, mark);
	return EDDY_OK;
}

/* The continuity density's rate for rows [0, n), from the carried
 * densities rho (1/rho in pq) and the velocities:
 *   d rho_i/dt = rho_i [sum_j V_j (v_i - v_j) + sum_b V_b (v_i - v_b)] . grad W_ib
 *              + delta h c sum_j V_j psi_ij . grad W_ij,
 *   psi_ij . grad W_ij = 2 (rho_j - rho_i - rho0 g . (x_j - x_i) / c^2) r |W'(r)| / (r^2 + 0.01 h^2)
 * V_j = m / rho_j, W' the spiky kernel's, the sums calibrated by grad_cal
 * as sph_pressure's force. */
static void continuity_rate(eddy_world *w, const sph_density *sd, const float *rho, float *rate, long n, int threads)
{
	const sph_shared *sh = &sd->sh;
	const sph_neighbors *nb = &sh->nb;
	const sph_boundary *bd = &nb->bnd;
	const float *vx = eddy__col(w, COL_VX), *vy = eddy__col(w, COL_VY), *vz = eddy__col(w, COL_VZ);
	const float *pq = sh->pq;
	const float h = sh->k.h, eps2 = 1e-6f * sh->k.h2, eta2 = 0.01f * sh->k.h2;
	/* |W'(r)| = -spiky_grad (h - r)^2; the sums' constant factors */
	const float dw = -sh->k.spiky_grad * sh->grad_cal, m = sh->mass;
	const float diff = sd->def.diffusion * h * sh->c * 2.0f;
	const eddy_vec3 g = eddy__gravity(w);
	const float gc = sh->rho0 / (sh->c * sh->c); /* rho0 g . dx / c^2: the hydrostatic density difference */
	const float gx = g.x * gc, gy = g.y * gc, gz = g.z * gc;
	const bool moving = bd->vx != NULL;
#pragma omp parallel for num_threads(threads) schedule(static)
	for (long i = 0; i < n; ++i) {
		const float xi = pq[4 * i], yi = pq[4 * i + 1], zi = pq[4 * i + 2], ri = rho[i];
		const float ui = vx[i], vi = vy[i], wi = vz[i];
		float div = 0, dif = 0; /* sum V_j (v_i - v_j) . grad W; sum V_j psi . grad W */
		sph_groups list = sph_nbr_groups(nb, i);
		uint32_t l[8];
		for (uint32_t q = 0; q < nb->count[i]; ++q) {
			if (q % 8 == 0)
				sph_group_rows(&list, l);
			const uint32_t j = l[q % 8];
			const float rx = xi - pq[4 * (size_t)j], ry = yi - pq[4 * (size_t)j + 1], rz = zi - pq[4 * (size_t)j + 2];
			const float r2 = rx * rx + ry * ry + rz * rz;
			if (!(r2 > eps2))
				continue;                                                      /* no direction */
			const float r = sqrtf(r2), hr = h - r, vj = pq[4 * (size_t)j + 3]; /* 1/rho_j */
			/* grad_i W = -|W'| r_vec / r: (v_i - v_j) . grad_i W = -|W'| (v_i - v_j) . r_vec / r */
			const float a = hr * hr * vj;
			div -= a * ((ui - vx[j]) * rx + (vi - vy[j]) * ry + (wi - vz[j]) * rz) / r;
			/* x_j - x_i = -r_vec */
			const float hyd = -(gx * rx + gy * ry + gz * rz);
			dif += a * (rho[j] - ri - hyd) * r / (r2 + eta2);
		}
		float bdiv = 0;
		const uint32_t *bl = sph_bnbrs(nb, i);
		for (uint32_t q = 0; q < nb->bcount[i]; ++q) {
			const uint32_t b = bl[q];
			const float rx = xi - nb->bx[b], ry = yi - nb->by[b], rz = zi - nb->bz[b];
			const float r2 = rx * rx + ry * ry + rz * rz;
			if (!(r2 > eps2))
				continue;
			const float r = sqrtf(r2), hr = h - r;
			float ux = ui, uy = vi, uz = wi;
			if (moving && b >= bd->n_static) {
				ux -= bd->vx[b];
				uy -= bd->vy[b];
				uz -= bd->vz[b];
			}
			bdiv -= nb->bvol[b] * hr * hr * (ux * rx + uy * ry + uz * rz) / r;
		}
		rate[i] = dw * (ri * (m * div + bdiv) + diff * m * dif);
	}
}

/* The starting densities of the rows new this step (carried value 0):
 * hydrostatic below the highest new particle of their vertical column,
 *   rho = rho_EOS(m / spacing^3 |g| (top - height + spacing / 2)),
 * columns h wide across gravity, so a block emitted at rest starts in
 * equilibrium rather than falling by g D / c^2 and ringing in its acoustic
 * mode; a new particle with none above it (a nozzle's front, no gravity)
 * starts at rho0. Particles emitted under older fluid take no account of
 * it. The new rows are few after the first step: sorted by column, ties by
 * row, for the same result on any thread count. */
typedef struct newrow {
	int64_t key;
	uint32_t row;
	float height;
} newrow;

static int newrow_cmp(const void *a, const void *b)
{
	const newrow *u = a, *v = b;
	if (u->key != v->key)
		return u->key < v->key ? -1 : 1;
	return (u->row > v->row) - (u->row < v->row);
}

static bool hydrostatic_start(eddy_world *w, const sph_density *sd, float *carried, long n)
{
	long count = 0;
	for (long i = 0; i < n; ++i)
		count += !(carried[i] > 0);
	if (count == 0)
		return true;
	const float rho0 = sd->sh.rho0;
	const eddy_vec3 g = eddy__gravity(w);
	const double gn = sqrt((double)g.x * g.x + (double)g.y * g.y + (double)g.z * g.z);
	if (!(gn > 0)) { /* no gravity: rho0 */
		for (long i = 0; i < n; ++i)
			carried[i] = carried[i] > 0 ? carried[i] : rho0;
		return true;
	}
	newrow *nr = eddy__arena_alloc(&w->arena, (size_t)count * sizeof *nr);
	if (!nr)
		return false;
	/* up = -g / |g|; e1, e2 across it */
	const double ux = -g.x / gn, uy = -g.y / gn, uz = -g.z / gn;
	double ax = fabs(ux) < 0.9 ? 1 : 0, ay = fabs(ux) < 0.9 ? 0 : 1, az = 0; /* not along up */
	double e1x = ay * uz - az * uy, e1y = az * ux - ax * uz, e1z = ax * uy - ay * ux;
	const double l1 = sqrt(e1x * e1x + e1y * e1y + e1z * e1z);
	e1x /= l1, e1y /= l1, e1z /= l1;
	const double e2x = uy * e1z - uz * e1y, e2y = uz * e1x - ux * e1z, e2z = ux * e1y - uy * e1x;
	const float *x = eddy__col(w, COL_X_), *y = eddy__col(w, COL_Y_), *z = eddy__col(w, COL_Z_);
	const double inv = 1.0 / sd->sh.h;
	/* the weight above per unit area and depth: the lattice's m / spacing^3, 1% under rho0 at h = 2 spacings */
	const float sp = sd->def.spacing, lattice_rho = sd->sh.mass / (sp * sp * sp);
	long k = 0;
	for (long i = 0; i < n; ++i)
		if (!(carried[i] > 0)) {
			/* clamped (a far or non-finite position shares an end column) so the key's casts are defined */
			const double a = fmax(-1e6, fmin(1e6, floor((e1x * x[i] + e1y * y[i] + e1z * z[i]) * inv))),
						 b = fmax(-1e6, fmin(1e6, floor((e2x * x[i] + e2y * y[i] + e2z * z[i]) * inv)));
			nr[k++] =
				(newrow){(int64_t)a * 4194304 + (int64_t)b, (uint32_t)i, (float)(ux * x[i] + uy * y[i] + uz * z[i])};
		}
	qsort(nr, (size_t)count, sizeof *nr, newrow_cmp);
	for (long a = 0; a < count;) {
		long b = a;
		float top = nr[a].height;
		for (; b < count && nr[b].key == nr[a].key; ++b)
			top = nr[b].height > top ? nr[b].height : top;
		for (long q = a; q < b; ++q) {
			const float depth = top - nr[q].height + 0.5f * sd->def.spacing;
			carried[nr[q].row] = eos_density(sd, lattice_rho * (float)gn * depth);
		}
		a = b;
	}
	return true;
}

/* The explicit diffusion's stability. On the lattice the diffusion's
 * operator, sum_j V_j 2 (f_j - f_i) F_ij (F_ij = |W'| r / (r^2 + 0.01 h^2)
 * calibrated), has its largest eigenvalue on the checkerboard mode,
 *   lambda = V grad_cal sum_j 2 F_ij (1 - (-1)^(a+b+c))   (lattice offsets a b c),
 * 5.71 / spacing^2 at h = 2 spacings; Euler steps of the diffusion alone
 * stay bounded while dt delta h c lambda <= 2, and the acoustic step is at
 * most cfl h / c: so while cfl delta h^2 lambda <= 2 (delta 0.1, h = 2
 * spacings: cfl up to 0.88). Measured (10 layers of still water, cfl 0.5):
 * delta 0.17 (1.94) holds, 0.19 (2.17) blows up. */
static double diffusion_eigenvalue(double dx, double h, double vol, double grad_cal)
{
	const int reach = (int)ceil(h / dx);
	const double k = 45.0 / (M_PI * pow(h, 6)), eta2 = 0.01 * h * h;
	double sum = 0;
	for (int a = -reach; a <= reach; ++a)
		for (int b = -reach; b <= reach; ++b)
			for (int c = -reach; c <= reach; ++c) {
				const double r = dx * sqrt((double)(a * a + b * b + c * c));
				if (r > 0 && r < h && (a + b + c) % 2 != 0) /* 1 - (-1)^(a+b+c): 2 or 0 */
					sum += 2 * 2 * k * (h - r) * (h - r) * r / (r * r + eta2);
			}
	return vol * grad_cal * sum;
}

/* cfl delta h^2 lambda (above): the continuity's diffusion is stable while <= 2. */
static double diffusion_number(const eddy_world *w, const sph_density *sd)
{
	return w->def.cfl * sd->def.diffusion * sd->sh.k.h2 * sd->diffusion_eig;
}

/* The continuity density: each row's carried density (hydrostatic_start's
 * for a new particle, whose carried value is 0) advanced over the last step by the
 * rate at the positions and velocities that step ended with (as the
 * integrator moved x with the new v), then stored back and in the density
 * column. */
static eddy_status continuity(eddy_world *w, sph_density *sd, int threads)
{
	const long n = (long)w->n;
	float *carried = eddy__col(w, sd->carried), *rho = eddy__col(w, COL_DENSITY), *p = eddy__col(w, COL_PRESSURE);
	const eddy_arena_mark mark = eddy__arena_mark(&w->arena); /* rate and the new rows': this pass's own */
	float *rate = eddy__arena_alloc(&w->arena, (w->n ? w->n : 1) * sizeof *rate);
	if (!rate)
		return eddy__fail(w, EDDY_ERR_NOMEM, "sph_density: out of scratch memory for %zu particles", w->n);
	const float dt = (float)w->last_dt;
	const float least = sd->sh.mass * sd->sh.k.poly6 * sd->sh.k.h2 * sd->sh.k.h2 * sd->sh.k.h2;
	if (!hydrostatic_start(w, sd, carried, n))
		return eddy__fail(w, EDDY_ERR_NOMEM, "sph_density: out of scratch memory for %zu particles", w->n);
#pragma omp parallel for num_threads(threads) schedule(static)
	for (long i = 0; i < n; ++i) {
		const float r = carried[i];
		rho[i] = r;
		sd->sh.pq[4 * i + 3] = 1.0f / r;
	}
	continuity_rate(w, sd, rho, rate, n, threads);
#pragma omp parallel for num_threads(threads) schedule(static)
	for (long i = 0; i < n; ++i) {
		float r = rho[i] + dt * rate[i];
		/* kept above m W(0), the summation's least (a lone particle's): 1/rho stays finite */
		r = r > least ? r : least;
		carried[i] = r;
		set_density(sd, rho, p, i, r);
	}
	eddy__arena_release(&w->arena, mark);
	return EDDY_OK;
}

static eddy_status step(eddy_world *w, eddy_system *s, const eddy_step_context *ctx)
{
	sph_density *sd = s->data;
	sph_shared *sh = &sd->sh;
	eddy_status st = eddy__sph_neighbors_build(w, sh, ctx->threads);
	if (st != EDDY_OK)
		return st;
	const sph_neighbors *nb = &sh->nb;
	float *rho = eddy__col(w, COL_DENSITY), *p = eddy__col(w, COL_PRESSURE), *ncount = eddy__col(w, COL_SPH_NEIGHBORS);
	const sph_kernel_consts kc = sh->k;
	const long n = (long)w->n;
	if (sd->def.density == EDDY_SPH_DENSITY_CONTINUITY && n > 0) {
		if (!eddy__provider(w, NULL, EDDY_CAP_SPH_EOS_FORCE)) /* check() says so before a run */
			return eddy__fail(w, EDDY_ERR_INVALID,
			                  "sph_density: 'density' = continuity needs sph_pressure; with sph_dfsph use "
			                  "density = summation");
		if (diffusion_number(w, sd) > 2)
			return eddy__fail(w, EDDY_ERR_INVALID,
			                  "sph_density: 'diffusion' %g at the world's cfl %g is unstable (cfl x diffusion x "
			                  "%.3g = %.3g, must be <= 2)",
			                  (double)sd->def.diffusion, w->def.cfl, sd->sh.k.h2 * sd->diffusion_eig,
			                  diffusion_number(w, sd));
		for (long i = 0; i < n; ++i)
			ncount[i] = (float)(nb->count[i] + nb->bcount[i]);
		st = continuity(w, sd, ctx->threads);
		return st == EDDY_OK ? boundary_pressure(w, sd, ctx->threads) : st;
	}
#pragma omp parallel for num_threads(ctx->threads) schedule(static)
	for (long i = 0; i < n; ++i) {
		/* the kernel sums were made with the neighbour lists */
		set_density(sd, rho, p, i, kc.poly6 * nb->ksum[i]);
		ncount[i] = (float)(nb->count[i] + nb->bcount[i]);
	}
	return boundary_pressure(w, sd, ctx->threads);
}

static void destroy(eddy_system *s)
{
	sph_density *sd = s->data;
	if (sd) {
		eddy__sph_neighbors_free(&sd->sh.nb);
		free(sd->wall_slot);
	}
}

/* Checkpointed state: the boundary particles' pressure and density, which the
 * next step's density sum reads before this step's extrapolation replaces
 * them (a lag of one step), and the collider offsets the moving boundary
 * particles' velocities are taken against. The continuity density is a
 * state column (sph_rho), which the checkpoint carries with the others. */
static void *state(eddy_world *w, eddy_system *s, size_t *size)
{
	sph_density *sd = s->data;
	*size = 0;
	if (eddy__sph_boundary_ready(w, &sd->sh) != EDDY_OK || !sd->sh.nb.bp)
		return NULL;
	*size = sd->sh.nb.bnd.state_size; /* bp, rho and the colliders' seen offsets (sph.h) */
	return sd->sh.nb.bp;
}

/* The automatic speed of sound (stiffness 0): ten times the fastest speed
 * the water can reach by the scene's own means, so the Mach number stays
 * under 0.1 and the density within about 1% of rho0 (Monaghan 1994: the
 * density error goes as M^2). That speed is an emitter's start speed and
 * its fall from the highest point it emits to the world's lowest corner
 * along gravity (or the floor of a closed sph_boundary_box holding that
 * point), v = sqrt(v0^2 + 2 |g| H): in a pool that is the top of the
 * water to the floor, an overestimate by about sqrt(2) of the wave speed
 * sqrt(g D), which costs time, never accuracy. A collider the host moves
 * and particles it adds itself are not foreseen: such a scene sets
 * stiffness. With c proportional to sqrt(length) and h to the length,
 * WCSPH's flow is Froude-similar: the same dam break at 1 cm, 0.1 m and
 * 5 m. A fixed c is not: 20 m/s, the old default, left the 5 m column at
 * Mach 0.8 and made a 1 mm one take 9x the steps with a 14% density error.
 * A scene with no speed of its own (no gravity, emitters at rest) takes
 * SOUND_IDLE, and so does one without sph_pressure: the rule is about
 * compression, and sph_dfsph's solve has none; there c only scales
 * Monaghan's alpha c h, whose alpha its stress cases were measured with
 * at 20 m/s (a c from the scene made DFSPH's dam break Froude-similar too,
 * but moved its slosh's damping: README, Measurements). */
#define SOUND_IDLE 20.0 /* m/s */
#define SOUND_MACH 10.0

/* The lowest point of a box along up, as a height along up. */
static double lowest(eddy_vec3 lo, eddy_vec3 hi, eddy_vec3 up)
{
	return (up.x > 0 ? lo.x : hi.x) * (double)up.x + (up.y > 0 ? lo.y : hi.y) * (double)up.y +
	       (up.z > 0 ? lo.z : hi.z) * (double)up.z;
}

/* p in the box [lo, hi], its faces included to a part in 1e5 of the box's
 * size (an emitter's corner sits on the tank's walls). */
static bool inside(eddy_vec3 lo, eddy_vec3 hi, eddy_vec3 p)
{
	const float tol = 1e-5f * fmaxf(hi.x - lo.x, fmaxf(hi.y - lo.y, hi.z - lo.z));
	return p.x >= lo.x - tol && p.x <= hi.x + tol && p.y >= lo.y - tol && p.y <= hi.y + tol && p.z >= lo.z - tol &&
	       p.z <= hi.z + tol;
}

static double scene_reach(const eddy_world *w, double *fall)
{
	double g[3];
	eddy__gravity_sum(w, g);
	const eddy_system *o;
	const double gn = sqrt(g[0] * g[0] + g[1] * g[1] + g[2] * g[2]);
	const eddy_vec3 up =
		gn > 0 ? eddy__v3((float)(-g[0] / gn), (float)(-g[1] / gn), (float)(-g[2] / gn)) : eddy__v3(0, 1, 0);
	const double world_low = lowest(w->def.bounds_min, w->def.bounds_max, up);
	double v2 = 0;
	*fall = 0;
	for (eddy_system_iter it = eddy__systems(w, 0); (o = eddy__systems_next(&it));) {
		if (!o->vt->reach)
			continue;
		eddy_vec3 p;
		double speed;
		o->vt->reach(o, up, &p, &speed);
		/* the world's floor, or the floor of a closed sph_boundary_box
		 * holding the point (the water cannot leave it) */
		double low = world_low;
		const eddy_system *b;
		for (eddy_system_iter jt = eddy__systems(w, EDDY_CAP_SPH_WALLS); (b = eddy__systems_next(&jt));) {
			const eddy_sph_boundary_box_def *bd = eddy__sph_boundary_box_def(b);
			if (bd && inside(bd->min, bd->max, p))
				low = fmax(low, lowest(bd->min, bd->max, up));
		}
		const double top = (double)p.x * up.x + (double)p.y * up.y + (double)p.z * up.z;
		const double H = top > low ? top - low : 0, e = speed * speed + 2 * gn * H;
		if (e > v2)
			v2 = e, *fall = H;
	}
	return sqrt(v2);
}

static void rederive(eddy_world *w, eddy_system *s)
{
	sph_density *sd = s->data;
	sd->reach_speed = scene_reach(w, &sd->reach_fall);
	if (!sd->auto_sound)
		return;
	const bool eos = eddy__provider(w, NULL, EDDY_CAP_SPH_EOS_FORCE) != NULL;
	const double c = eos && sd->reach_speed > 0 ? SOUND_MACH * sd->reach_speed : SOUND_IDLE;
	sd->def.stiffness = (float)(c * c);
	sd->sh.c = sqrtf(sd->def.stiffness);
}

/* Preflight: every emitter on the lattice the mass is calibrated on, and
 * h / spacing in [1.2, 4] (an error below, a warning above; the messages
 * give the reasons). */
static int check(eddy_world *w, const eddy_system *s, eddy_check_fn report, void *user)
{
	const sph_density *sd = s->data;
	const double dx = sd->def.spacing, h = sd->def.radius;
	int errors = 0;
	const eddy_system *e;
	for (eddy_system_iter it = eddy__systems(w, 0); (e = eddy__systems_next(&it));) {
		if (!e->vt->spacing)
			continue;
		const double de = e->vt->spacing(e);
		if (fabs(de / dx - 1) <= 1e-3)
			continue;
		const double start = pow(dx / de, 3);
		eddy__report(report, user, EDDY_CHECK_ERROR,
		             "%s: 'spacing' is %g m but %s emits at spacing %g m: the particle mass is calibrated on %g m, "
		             "so the fluid starts at %.2f x rest density and %s; set %s's spacing = %g (and radius = %g)",
		             s->label, dx, e->label, de, dx, start, start < 1 ? "collapses" : "blows apart", s->label, de,
		             2 * de);
		errors++;
	}
	if (sd->def.density == EDDY_SPH_DENSITY_CONTINUITY && !eddy__provider(w, NULL, EDDY_CAP_SPH_EOS_FORCE)) {
		eddy__report(report, user, EDDY_CHECK_ERROR,
		             "%s: 'density' = continuity needs sph_pressure (weakly compressible SPH); a pressure solve "
		             "(sph_dfsph) corrects the summation density itself: use density = summation",
		             s->label);
		errors++;
	}
	if (sd->def.density == EDDY_SPH_DENSITY_CONTINUITY && diffusion_number(w, sd) > 2) {
		const double per = sd->sh.k.h2 * sd->diffusion_eig;
		eddy__report(report, user, EDDY_CHECK_ERROR,
		             "%s: 'diffusion' %g at the world's cfl %g makes the explicit density diffusion unstable "
		             "(cfl x diffusion x %.3g = %.3g, must be <= 2); use diffusion <= %.3g or cfl <= %.3g",
		             s->label, (double)sd->def.diffusion, w->def.cfl, per, diffusion_number(w, sd),
		             2 / (w->def.cfl * per), 2 / (sd->def.diffusion * per));
		errors++;
	}
	const double c = sd->sh.c, v = sd->reach_speed;
	const bool eos = eddy__provider(w, NULL, EDDY_CAP_SPH_EOS_FORCE) != NULL;
	if (sd->auto_sound && eos)
		eddy__report(report, user, EDDY_CHECK_INFO,
		             v > 0 ? "%s: speed of sound %.3g m/s (stiffness %.4g m^2/s^2): 10 x %.3g m/s, the fastest the "
		                     "water gets by itself (its start speed and a fall of %.3g m)"
		                   : "%s: speed of sound %.3g m/s (stiffness %.4g m^2/s^2): the scene gives its water no "
		                     "speed (%.3g m/s: no gravity, emitters at rest; fall %.3g m), so the fixed default; set "
		                     "stiffness = (10 x the speed you expect)^2",
		             s->label, c, c * c, v, sd->reach_fall);
	else if (!sd->auto_sound && c < 0.5 * SOUND_MACH * v && eos)
		eddy__report(report, user, EDDY_CHECK_WARNING,
		             "%s: 'stiffness' %g m^2/s^2 makes the speed of sound %.3g m/s, but the water reaches about "
		             "%.3g m/s by itself (its start speed and a fall of %.3g m): at Mach %.2f it compresses (the "
		             "density error grows as Mach squared, about 1%% at 0.1); use stiffness >= %.4g (10 x that "
		             "speed), or leave it unset to have it chosen",
		             s->label, (double)sd->def.stiffness, c, v, sd->reach_fall, v / c, SOUND_MACH * SOUND_MACH * v * v);
	if (h / dx < 1.2) {
		eddy__report(report, user, EDDY_CHECK_ERROR,
		             "%s: 'radius' %g m is %.2f x 'spacing' %g m, below 1.2: the nearest neighbours barely reach "
		             "into the kernel and the pressure cannot hold the fluid; use radius = 2 x spacing = %g m",
		             s->label, h, h / dx, dx, 2 * dx);
		errors++;
	} else if (h / dx > 4) {
		eddy__report(report, user, EDDY_CHECK_WARNING,
		             "%s: 'radius' %g m is %.2f x 'spacing' %g m, above 4: about %.0f neighbours per particle for "
		             "no accuracy; radius = 2 x spacing = %g m is usual",
		             s->label, h, h / dx, dx, 4.19 * pow(h / dx, 3), 2 * dx);
	}
	return errors;
}

static void *shared(const eddy_system *s, uint32_t cap)
{
	return cap == EDDY_CAP_SPH_NEIGHBORS ? &((sph_density *)s->data)->sh : NULL;
}

const eddy_system_vtable eddy__kind_sph_density = {
	.name = "sph_density",
	.settles = true,
	.provides = EDDY_CAP_SPH_NEIGHBORS,
	.shared = shared,
	.step = step,
	.state = state,
	.destroy = destroy,
	.default_writes = density_writes,
	.check = check,
	.rederive = rederive,
};

float eddy_sph_sound_speed(const eddy_world *w, eddy_system_id id)
{
	const eddy_system *s = eddy__system_peek(w, id);
	return eddy__sph_density_def(s) ? ((const sph_density *)s->data)->sh.c : 0;
}

float eddy_sph_particle_mass(const eddy_world *w, eddy_system_id id)
{
	const eddy_system *s = eddy__system_peek(w, id);
	return eddy__sph_density_def(s) ? ((const sph_density *)s->data)->sh.mass : 0;
}

const eddy_sph_density_def *eddy__sph_density_def(const eddy_system *s)
{
	return s && s->vt == &eddy__kind_sph_density ? &((const sph_density *)s->data)->def : NULL;
}

eddy_system_id eddy_add_sph_density(eddy_world *w, const eddy_sph_density_def *def)
{
	const char *sys = "sph_density";
	if (!eddy__add_args(w, def, sys) || !eddy__check_positive(w, sys, "spacing", def->spacing) ||
	    !eddy__check_positive(w, sys, "radius", def->radius) ||
	    !eddy__check_positive(w, sys, "rest_density", def->rest_density) ||
	    !eddy__check_nonneg(w, sys, "stiffness", def->stiffness) ||
	    !eddy__check_range(w, sys, "tait_gamma", def->tait_gamma, 1, 20))
		return EDDY_NULL_SYSTEM;
	if (!(def->radius > def->spacing && def->radius <= 5 * def->spacing))
		return eddy__fail(w, EDDY_ERR_INVALID,
		                  "%s: 'radius' must be between 1 and 5 times 'spacing' (got radius = %g m, spacing = %g m; "
		                  "2 x spacing is usual)",
		                  sys, (double)def->radius, (double)def->spacing),
		       EDDY_NULL_SYSTEM;
	/* the kernel constants in float: poly6's gradient, 6 x 315 / (64 pi h^9),
	 * is the largest and overflows below about 67 um */
	const double h_min = pow(6 * 315.0 / (64.0 * M_PI * FLT_MAX), 1.0 / 9);
	if (def->radius < h_min)
		return eddy__fail(w, EDDY_ERR_INVALID,
		                  "%s: 'radius' %g m is below %.2g m, the smallest kernel whose constants (of order 1/h^9) "
		                  "fit in single precision; use spacing >= %.2g m, or FLIP, which has no such limit",
		                  sys, (double)def->radius, h_min, h_min / 2),
		       EDDY_NULL_SYSTEM;
	if (def->eos != EDDY_SPH_EOS_LINEAR && def->eos != EDDY_SPH_EOS_TAIT)
		return eddy__fail(w, EDDY_ERR_INVALID, "%s: 'eos' must be linear or tait", sys), EDDY_NULL_SYSTEM;
	if (def->density != EDDY_SPH_DENSITY_SUMMATION && def->density != EDDY_SPH_DENSITY_CONTINUITY)
		return eddy__fail(w, EDDY_ERR_INVALID, "%s: 'density' must be summation or continuity", sys), EDDY_NULL_SYSTEM;
	if (!eddy__check_range(w, sys, "diffusion", def->diffusion, 0, 1))
		return EDDY_NULL_SYSTEM;
	int carried = -1;
	if (def->density == EDDY_SPH_DENSITY_CONTINUITY) {
		carried = eddy_world_find_column(w, CARRIED_NAME);
		eddy_column_info ci;
		if (carried >= 0 && eddy_world_column_info(w, carried, &ci) == EDDY_OK &&
		    (ci.domain != EDDY_DOMAIN_PARTICLE || ci.type != EDDY_F32 || ci.lifetime != EDDY_STATE))
			return eddy__fail(w, EDDY_ERR_INVALID,
			                  "%s: density = continuity keeps the density in the column '%s', which the host "
			                  "declared otherwise (it must be a per-particle f32 state column)",
			                  sys, CARRIED_NAME),
			       EDDY_NULL_SYSTEM;
		if (carried < 0)
			carried = eddy_world_declare_column(w, CARRIED_NAME, EDDY_DOMAIN_PARTICLE, EDDY_F32, EDDY_STATE, "kg/m^3");
		if (carried < 0)
			return EDDY_NULL_SYSTEM;
	}
	sph_density *sd = calloc(1, sizeof *sd);
	if (!sd)
		return eddy__fail(w, EDDY_ERR_NOMEM, "%s: out of memory", sys), EDDY_NULL_SYSTEM;
	sd->def = *def;
	sd->auto_sound = def->stiffness == 0;
	if (sd->auto_sound) /* until rederive sees the scene, which the add below calls */
		sd->def.stiffness = (float)(SOUND_IDLE * SOUND_IDLE);
	sd->carried = carried;
	sd->sh.h = def->radius;
	sd->sh.rho0 = def->rest_density;
	sd->sh.c = sqrtf(sd->def.stiffness);
	sd->sh.verlet = def->verlet_list;
	const double h = def->radius, h6 = h * h * h * h * h * h, h9 = h6 * h * h * h;
	sd->sh.k = (sph_kernel_consts){.h = def->radius,
	                               .h2 = def->radius * def->radius,
	                               .poly6 = (float)(315.0 / (64.0 * M_PI * h9)),
	                               .poly6_grad = (float)(-6.0 * 315.0 / (64.0 * M_PI * h9)),
	                               .spiky_grad = (float)(-45.0 / (M_PI * h6)),
	                               .visc_lap = (float)(45.0 / (M_PI * h6))};
	const double lattice = eddy_sph_lattice_sum(EDDY_SPH_POLY6, def->spacing, def->radius);
	sd->sh.mass = (float)(def->rest_density / lattice);
	sd->sh.spacing = def->spacing;
	/* the force sums m grad W, and m = rho0 / sum_lattice W is not rho0
	 * spacing^3: the moment the force sees is the lattice moment times
	 * m / (rho0 spacing^3) (0.956 / 1.010 = 0.947 at h = 2 spacings) */
	const double vol = (double)def->spacing * def->spacing * def->spacing;
	sd->sh.grad_cal =
		(float)(lattice * vol / eddy_sph_lattice_gradient_moment(EDDY_SPH_SPIKY, def->spacing, def->radius));
	sd->diffusion_eig =
		(float)diffusion_eigenvalue(def->spacing, def->radius, sd->sh.mass / def->rest_density, sd->sh.grad_cal);
	const int cont_reads[] = {COL_X_, COL_Y_, COL_Z_, COL_VX, COL_VY, COL_VZ, carried, -1};
	const int cont_writes[] = {COL_DENSITY, COL_PRESSURE, COL_SPH_NEIGHBORS, carried, -1};
	const bool cont = carried >= 0;
	eddy_system_id id = eddy__add_system(w, &eddy__kind_sph_density, sd, cont ? cont_reads : density_reads,
	                                     cont ? cont_writes : density_writes);
	if (eddy_system_valid(w, id))
		eddy_world_set_rest_density(w, def->rest_density);
	return id;
}
