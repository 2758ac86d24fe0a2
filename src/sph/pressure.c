/* SPDX-License-Identifier: MIT */
/* sph_pressure: the symmetric pressure force with the spiky kernel's gradient
 * (Mueller 2003, eq. 10, without its factor 1/2; see below); boundary
 * particles enter the same sum with the pressure sph_density extrapolated onto
 * them (Adami et al. 2012).
 *
 * Reads: x y z density pressure. Writes: ax ay az (accumulated).
 *   a_i -= scale * [ sum_j m (p_i + p_j) / (rho_i rho_j) grad W_spiky(x_i - x_j)
 *                  + sum_b V_b (p_i + p_b) / rho_i grad W_spiky(x_i - x_b) ]
 *   grad W_spiky(r_vec) = -45/(pi h^6) (h - r)^2 r_vec / r
 * Why not the paper's (p_i + p_j) / 2: in the interior sum_j V_j grad W = 0,
 * so sum_j V_j (p_i + p_j)/2 grad W = grad p / 2. The paper's force is half
 * the pressure gradient; a resting column then compresses twice as much as
 * g H / k says and sound travels at sqrt(k/2). The form here is the same
 * symmetric (momentum-conserving) pair force, doubled, so it reproduces
 * grad p and c = sqrt(k) (tested by the hydrostatic tank).
 * The force is divided by the moment it has on the particle lattice,
 * (m / rho0) sum_j x_j^2 |dW/dr| / r_j = 0.947 at h = 2 spacings (the spiky
 * lattice moment 0.956, eddy_sph_lattice_gradient_moment, times the
 * calibrated m over rho0 spacing^3): uncorrected, the force of a linear
 * pressure field falls 5.3% short of grad p and a resting column carries that
 * much more pressure (the hydrostatic test saw +3.7%, now +0.6%). The same
 * correction sph_density makes for the mass.
 * Pairs closer than 1e-3 h take a fixed antisymmetric direction (sph.h): the
 * gradient has no direction at r = 0, and skipping them would leave
 * coincident particles stuck together (docs/validation.md C.6).
 * Positions and 1/rho come from sph_density's (x y z 1/rho) quads (sh->pq).
 * The fluid pairs go eight at a time, written once against simd.h (AVX2
 * when the CPU has it, else SSE or scalar doing the same per lane;
 * EDDY_NO_AVX2 forces the base path), a particle's last group masked, with
 * per-lane partial sums added in a fixed order: the same bits for any thread
 * count and any back-end. The particles go in blocks
 * of 64, the sums over the block's groups first, then a loop finishing its
 * particles (the walls, ax ay az). A group with a coincident pair ends the
 * vector sums of its particle; the finish loop takes the rest pair by pair.
 * Time-step limits, the smaller reported: acoustic, dt <= h / (c + max|v|),
 * c = sqrt(k) from sph_density's stiffness (the world's CFL number is the
 * Courant factor lambda, 0.25-0.4); force, dt <= 0.625 sqrt(h / max|a|),
 * max|a| from the last step (with the default CFL 0.4 the usual
 * 0.25 sqrt(h/|a|)).
 * Source: Mueller, Charypar & Gross 2003; Adami, Hu & Adams, "A generalized
 * wall boundary condition for SPH", JCP 2012. */
#include "simd.h"
#include "sph.h"
#include "systems.h"

#include <stdlib.h>

/* The pass goes in blocks of particles: first the sums over the fluid pairs
 * of the block (pressure_pair_sums), then a loop that finishes its particles (the
 * walls, the rare coincident pairs, ax ay az). Finishing each particle right
 * after its groups put the adds of its totals behind every (often
 * mispredicted) exit of the loop over its groups; the particles of the second
 * loop are independent of each other (as in sph_dfsph). */
#define PRESSURE_BLOCK 64
#define PRESSURE_T 12 /* floats of the sums per particle: 4 lanes of x, y, z */

/* What the pair sums read. They sum (p_i + p_j) / rho_j (h - r)^2 r_vec / r
 * over the pairs: the 1/r normalises r_vec. */
typedef struct pair_args {
	const sph_neighbors *nb;
	const float *pk, *p; /* (x y z 1/rho) quads; pressures */
	float h, eps2;
} pair_args;

/* The sums over the fluid pairs of particles i0 .. i0 + cnt - 1, eight
 * neighbours at a time, each particle's as four lanes per component (lane l
 * holding lanes l and l + 4 of the groups) at t + PRESSURE_T q, and in
 * done[q] how many of its pairs they cover: all, unless a group has a
 * coincident pair, from which on the finish loop takes the pairs one by one. */
typedef void pair_sums_fn(const pair_args *a, long i0, long cnt, float *t, uint32_t *done);
SIMD_DECLARE(void, pressure_pair_sums, (const pair_args *a, long i0, long cnt, float *t, uint32_t *done));

/* One group (neighbours l[0..7]; with masked, only the first left count);
 * false, summing nothing, if a pair is coincident (r^2 <= eps2: no
 * direction to divide by). Whole groups (masked false) need no mask: the
 * compiler drops it where the argument is constant. */
static inline bool group(const pair_args *a, const uint32_t *l, bool masked, uint32_t left, sf8 xi, sf8 yi, sf8 zi,
                         sf8 p_i, sf8 *sx, sf8 *sy, sf8 *sz)
{
	sf8 px, py, pz, ir;
	sf8_gather_quads(a->pk, l, &px, &py, &pz, &ir);
	const sf8 rx = sf8_sub(xi, px), ry = sf8_sub(yi, py), rz = sf8_sub(zi, pz);
	const sf8 r2 = sf8_add(sf8_add(sf8_mul(rx, rx), sf8_mul(ry, ry)), sf8_mul(rz, rz));
	if (sf8_mask_bits(sf8_gt(r2, sf8_set1(a->eps2))) != 255)
		return false;
	const sf8 r = sf8_sqrt(r2), hr = sf8_sub(sf8_set1(a->h), r);
	const sf8 pj = sf8_gather(a->p, l);
	sf8 c = sf8_div(sf8_mul(sf8_mul(sf8_mul(sf8_add(p_i, pj), ir), hr), hr), r);
	if (masked)
		c = sf8_and(c, sf8_lanes_below(left));
	*sx = sf8_add(*sx, sf8_mul(c, rx));
	*sy = sf8_add(*sy, sf8_mul(c, ry));
	*sz = sf8_add(*sz, sf8_mul(c, rz));
	return true;
}

void SIMD_NAME(pressure_pair_sums)(const pair_args *a, long i0, long cnt, float *t, uint32_t *done)
{
	const sph_neighbors *nb = a->nb;
	for (long b = 0; b < cnt; ++b) {
		const long i = i0 + b;
		const uint32_t *list = nb->nbr + (size_t)i * nb->cap, c = nb->count[i];
		const float *pi = a->pk + 4 * i;
		const sf8 xi = sf8_set1(pi[0]), yi = sf8_set1(pi[1]), zi = sf8_set1(pi[2]), p_i = sf8_set1(a->p[i]);
		sf8 sx = sf8_zero(), sy = sx, sz = sx;
		uint32_t q = 0;
		for (; q + 8 <= c; q += 8)
			if (!group(a, list + q, false, 8, xi, yi, zi, p_i, &sx, &sy, &sz))
				break;
		if (q + 8 > c && q < c) {
			uint32_t l[8];
			sph_group_rows(list, c, q, l);
			if (group(a, l, true, c - q, xi, yi, zi, p_i, &sx, &sy, &sz))
				q = c;
		}
		float *tb = t + PRESSURE_T * b;
		sf8_fold4(sx, tb);
		sf8_fold4(sy, tb + 4);
		sf8_fold4(sz, tb + 8);
		done[b] = q < c ? q : c;
	}
}

#ifndef EDDY_SIMD_VARIANT
typedef struct sph_pressure {
	eddy_sph_pressure_def def;
} sph_pressure;

static const int pressure_reads[] = {COL_X_, COL_Y_, COL_Z_, COL_DENSITY, COL_PRESSURE, -1};
static const int pressure_writes[] = {COL_AX, COL_AY, COL_AZ, -1};
static const int no_hint_writes[] = {-1};

eddy_sph_pressure_def eddy_default_sph_pressure_def(void)
{
	eddy_sph_pressure_def d;
	d.scale = 1.0f;
	return d;
}

/* The finish loop of a block: the pairs the sums left (coincident ones, one
 * by one), the walls, and ax ay az. */
typedef struct finish_args {
	const sph_neighbors *nb;
	const float *pk, *p, *inv_rho;
	float *ax, *ay, *az;
	float h, eps2, m, g; /* g: -spiky_grad grad_cal scale */
} finish_args;

static void finish(const finish_args *fa, long i0, long cnt, const float *t, const uint32_t *done)
{
	/* a copy the stores below cannot alias: the constants stay in registers */
	const finish_args a = *fa;
	const sph_neighbors *nb = a.nb;
	for (long b = 0; b < cnt; ++b) {
		const long i = i0 + b;
		const float *tb = t + PRESSURE_T * b;
		const float xi = a.pk[4 * i], yi = a.pk[4 * i + 1], zi = a.pk[4 * i + 2];
		/* rho >= m W(0) > 0 (the self term), so 1/rho is finite */
		const float iri = a.inv_rho[i], pi_ = a.p[i];
		float fx = sph_sum4(tb), fy = sph_sum4(tb + 4), fz = sph_sum4(tb + 8);
		const uint32_t *list = nb->nbr + (size_t)i * nb->cap;
		for (uint32_t q = done[b], cnt_i = nb->count[i]; q < cnt_i; ++q) {
			const uint32_t j = list[q];
			float rx = xi - a.pk[4 * (size_t)j], ry = yi - a.pk[4 * (size_t)j + 1], rz = zi - a.pk[4 * (size_t)j + 2];
			const float r2 = rx * rx + ry * ry + rz * rz;
			float r;
			if (r2 > a.eps2) {
				r = sqrtf(r2);
				const float inv = 1.0f / r;
				rx *= inv;
				ry *= inv;
				rz *= inv;
			} else {
				r = 0;
				sph_coincident_dir((size_t)i, j, &rx, &ry, &rz);
			}
			const float hr = a.h - r;
			/* (p_i + p_j)/(rho_i rho_j) times |dW/dr|; the force pushes i away from j */
			const float c = (pi_ + a.p[j]) * a.inv_rho[j] * hr * hr;
			fx += c * rx;
			fy += c * ry;
			fz += c * rz;
		}
		const uint32_t *blist = nb->bnbr + (size_t)i * nb->bcap;
		const uint32_t bcnt = nb->bcount[i];
		float bx = 0, by = 0, bz = 0;
		for (uint32_t qb = 0; qb < bcnt; ++qb) {
			const uint32_t bj = blist[qb];
			float rx = xi - nb->bx[bj], ry = yi - nb->by[bj], rz = zi - nb->bz[bj];
			const float r2 = rx * rx + ry * ry + rz * rz;
			if (!(r2 > a.eps2))
				continue; /* on the wall surface: the collider handles it */
			const float r = sqrtf(r2), inv = 1.0f / r, hr = a.h - r;
			/* m_b (p_i + p_b) / (rho_i rho_b) with m_b = V_b rho_b */
			const float c = nb->bvol[bj] * (pi_ + nb->bp[bj]) * hr * hr * inv;
			bx += c * rx;
			by += c * ry;
			bz += c * rz;
		}
		a.ax[i] += a.g * iri * (a.m * fx + bx);
		a.ay[i] += a.g * iri * (a.m * fy + by);
		a.az[i] += a.g * iri * (a.m * fz + bz);
	}
}

static eddy_status step(eddy_world *w, eddy_system *s, const eddy_step_context *ctx)
{
	const sph_pressure *sp = s->data;
	sph_shared *sh = eddy__sph_find(w, s);
	if (!sh)
		return eddy__fail(w, EDDY_ERR_ORDER, "%s: needs sph_density before it (it builds the neighbour lists)",
		                  s->label);
	const sph_neighbors *nb = &sh->nb;
	const sph_kernel_consts kc = sh->k;
	const float eps2 = 1e-6f * kc.h2;
	const long n = nb->n < w->n ? (long)nb->n : (long)w->n;
	/* each neighbour's position and 1/rho as one 16-byte quad (sph_density
	 * made them): a group of neighbours then costs a load each and a
	 * transpose instead of four scattered loads each */
	const pair_args pa = {nb, sh->pq, eddy__col(w, COL_PRESSURE), kc.h, eps2};
	/* -grad W = +45/(pi h^6) (h-r)^2 r_hat, so the signs of the sums are already "away" */
	const finish_args fa = {nb,
	                        sh->pq,
	                        pa.p,
	                        sh->inv_rho,
	                        eddy__col(w, COL_AX),
	                        eddy__col(w, COL_AY),
	                        eddy__col(w, COL_AZ),
	                        kc.h,
	                        eps2,
	                        sh->mass,
	                        -kc.spiky_grad * sh->grad_cal * sp->def.scale};
	pair_sums_fn *sums = SIMD_PICK(pressure_pair_sums);
	const int threads = ctx->threads;
	/* the threads take equal shares in order; a particle's result does not
	 * depend on the blocks, so it is the same for any thread count */
#pragma omp parallel for num_threads(threads) schedule(static)
	for (int th = 0; th < threads; ++th) {
		float t[PRESSURE_BLOCK * PRESSURE_T];
		uint32_t done[PRESSURE_BLOCK];
		for (long i0 = n * th / threads, hi = n * (th + 1) / threads; i0 < hi; i0 += PRESSURE_BLOCK) {
			const long cnt = hi - i0 < PRESSURE_BLOCK ? hi - i0 : PRESSURE_BLOCK;
			sums(&pa, i0, cnt, t, done);
			finish(&fa, i0, cnt, t, done);
		}
	}
	return EDDY_OK;
}

/* The largest |(u, v, w)| over the particles, 0 without the columns. */
static double max_norm(eddy_world *w, int cu, int cv, int cw)
{
	const float *u = eddy__col(w, cu), *v = eddy__col(w, cv), *q = eddy__col(w, cw);
	float m2 = 0;
	if (u && v && q)
		for (size_t i = 0; i < w->n; ++i) {
			const float s2 = u[i] * u[i] + v[i] * v[i] + q[i] * q[i];
			m2 = s2 > m2 ? s2 : m2;
		}
	return sqrt((double)m2);
}

static double limit(eddy_world *w, eddy_system *s, const char **reason)
{
	const sph_shared *sh = eddy__sph_find(w, s);
	*reason = "acoustic";
	if (!sh)
		return INFINITY;
	const double acoustic = sh->h / (sh->c + max_norm(w, COL_VX, COL_VY, COL_VZ)),
				 a = max_norm(w, COL_AX, COL_AY, COL_AZ);
	const double force = a > 0 ? 0.625 * sqrt(sh->h / a) : INFINITY;
	if (force < acoustic)
		*reason = "force";
	return force < acoustic ? force : acoustic;
}

const eddy_system_vtable eddy__kind_sph_pressure = {
	.name = "sph_pressure",
	.provides = EDDY_CAP_SPH_EOS_FORCE,
	.requires = EDDY_CAP_SPH_NEIGHBORS,
	.step = step,
	.limit = limit,
	/* ax ay az are every force's: order hints for them name gravity alone */
	.default_writes = no_hint_writes,
};

eddy_system_id eddy_add_sph_pressure(eddy_world *w, const eddy_sph_pressure_def *def)
{
	const char *sys = "sph_pressure";
	if (!eddy__add_args(w, def, sys))
		return EDDY_NULL_SYSTEM;
	if (!eddy__check_positive(w, sys, "scale", def->scale))
		return EDDY_NULL_SYSTEM;
	sph_pressure *sp = malloc(sizeof *sp);
	if (sp)
		sp->def = *def;
	return eddy__add_system(w, &eddy__kind_sph_pressure, sp, pressure_reads, pressure_writes);
}
#endif
