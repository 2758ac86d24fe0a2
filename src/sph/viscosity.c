/* SPDX-License-Identifier: MIT */
/* sph_viscosity: viscous force from the Laplacian of the viscosity kernel
 * (Mueller 2003, eq. 14, with the symmetric velocity difference).
 *
 * Reads: x y z vx vy vz density. Writes: ax ay az (accumulated).
 *   a_i += (mu / rho_i) sum_j m (v_j - v_i) / rho_j lap W_visc(r_ij)
 *   lap W_visc(r) = 45/(pi h^6) (h - r)  (positive everywhere, so the term
 *   only ever damps relative motion)
 *   a_i -= sum_j m Pi_ij grad W_spiky(r_ij), for approaching pairs only
 *   (v_ij . x_ij < 0): Pi_ij = -alpha c h (v_ij . x_ij) / ((r^2 + 0.01 h^2) rho_ij),
 *   rho_ij the mean density (Monaghan 1992): it damps the acoustic noise of
 *   weakly compressible SPH near walls and the free surface, which a
 *   physical viscosity small enough not to slow the flow cannot.
 * Boundary particles add no viscous force: walls are free-slip, as the
 * dam-break validation wants.
 * Time-step limits (viscous), both explicit diffusion: dt <= h^2 / (15 nu)
 * (VISC_LIMIT), nu = mu / rho0, and dt <= VISC_ARTIFICIAL_LIMIT h / (alpha c)
 * for Monaghan's term, a viscosity of about alpha c h / 20 (h the support
 * radius), which nothing else bounded under sph_dfsph (WCSPH's acoustic
 * limit, h / c, is the tighter one for alpha < 0.5). Both hold from the
 * first step on, before any particle exists: an emitter adds its particles
 * within that step, and the limits depend on the def alone.
 * Source: Mueller, Charypar & Gross 2003; Monaghan, "Smoothed particle
 * hydrodynamics", ARAA 1992. */
#include "simd.h"
#include "sph.h"
#include "systems.h"

#include <stdlib.h>

#define VISC_T 24 /* floats of the pair sums per particle: 4 lanes of each of six */

/* Monaghan's term is stable, stepped explicitly, up to about 0.8-1.0 h /
 * (alpha c): a drop at rest in zero gravity (scenes/droplet.lua with
 * DFSPH and no surface tension: alpha 0.1, c 20 m/s, h 2.5 mm) stays at
 * rest for 0.6 s with dt at most 1.0 ms and flies apart (2116 of 2120
 * particles beyond 1.5 R) at 1.25 ms. Under sph_dfsph nothing else bounded
 * its step at rest (no speed, no gravity: the frame's 5 ms), so the drop
 * came apart from round-off. Half the threshold, times the world's CFL. */
#define VISC_ARTIFICIAL_LIMIT 0.5

/* The viscous term's explicit step is stable while dt lambda <= 2, lambda
 * the largest eigenvalue of v -> nu sum_j V_j (v_j - v_i) lap W(r_ij). Its
 * row sum is nu sum_j V_j lap W ~ nu integral of lap W = 15 nu / h^2, and
 * Gershgorin bounds lambda by twice that; on the simple cubic lattice
 * lambda is 15.8 nu / h^2, and in a blob compressed and disordered by an
 * impact about 20 nu / h^2 (a 5 cm blob of mu = 50 Pa s, 5 mm spacing,
 * dropped 5 cm onto the floor under sph_dfsph: at rest for dt = 0.094
 * h^2 / nu, at 0.109 its particles reach 5 m/s within 0.3 s). So dt <=
 * h^2 / (15 nu) times the CFL number: inside that at any CFL number up to
 * 1. The limit this replaced, 0.3125 h^2 / nu (the textbook 0.125 h^2 / nu
 * with h the support radius, where the textbook's h is the smoothing
 * length, about half of it), let that blob reach 17 m/s at sph_dfsph's CFL
 * number 0.5 and WCSPH's particles jitter at up to 3.6 m/s at 0.4. */
#define VISC_LIMIT (1.0 / 15.0)

/* What a block of the pass reads and writes. Per particle the pair sums
 * are -sum (h - r) / rho_j (v_i - v_j) (components 0-2) and the artificial
 * viscosity's sum of max(0, -v_ij . r_vec) (h - r)^2 / ((r^2 + eps)
 * (rho_i + rho_j) max(r, rmin)) r_vec (3-5). */
typedef struct visc_args {
	const float *pq, *pv; /* (x y z 1/rho) and (vx vy vz -rho) per particle */
	const sph_neighbors *nb;
	float *ax, *ay, *az;
	float h, eps, rmin, coef, acoef;
	void (*pair_sums)(const struct visc_args *a, long i0, long cnt, float *t);
} visc_args;

/* The sums over the pairs of particles i0 .. i0 + cnt - 1 (sph.h's block
 * pass), each particle's as four lanes per component at t + VISC_T q. */
SIMD_DECLARE(void, visc_pair_sums, (const visc_args *a, long i0, long cnt, float *t));

/* One group (neighbours l[0..7]; with masked, only the first left count).
 * The differences are taken on the quads before the transpose:
 * qp = (x_i y_i z_i 0) minus (x_j y_j z_j 1/rho_j) gives r_vec and
 * -1/rho_j, qv = (v_i rho_i) minus (v_j -rho_j) gives v_ij and
 * rho_i + rho_j (a - (-b) is a + b, bit for bit), so that i's inputs take
 * two registers, not seven. The -1/rho_j makes c the negative of
 * (h - r) / rho_j, added instead of subtracted. Whole groups (masked
 * false) need no mask: the compiler drops it where the argument is
 * constant. */
static inline void group(const visc_args *a, const uint32_t *l, bool masked, uint32_t left, sf8 qp, sf8 qv, sf8 s[6])
{
	const sf8 zero = sf8_zero();
	sf8 rx, ry, rz, nir, ux, uy, uz, rho2;
	sf8_sub_gather_quads(qp, a->pq, l, &rx, &ry, &rz, &nir);
	sf8_sub_gather_quads(qv, a->pv, l, &ux, &uy, &uz, &rho2);
	const sf8 r2 = sf8_add(sf8_add(sf8_mul(rx, rx), sf8_mul(ry, ry)), sf8_mul(rz, rz));
	const sf8 r = sf8_sqrt(r2), hr = sf8_sub(sf8_set1(a->h), r);
	const sf8 in = masked ? sf8_lanes_below(left) : zero;
	sf8 c = sf8_mul(hr, nir);
	if (masked)
		c = sf8_and(in, c);
	s[0] = sf8_add(s[0], sf8_mul(c, ux));
	s[1] = sf8_add(s[1], sf8_mul(c, uy));
	s[2] = sf8_add(s[2], sf8_mul(c, uz));
	/* approaching pairs only (v_ij . r_vec < 0), pushed apart along r_vec */
	const sf8 vr = sf8_add(sf8_add(sf8_mul(ux, rx), sf8_mul(uy, ry)), sf8_mul(uz, rz));
	sf8 neg = sf8_lt(vr, zero);
	if (masked)
		neg = sf8_and(in, neg);
	const sf8 app = sf8_and(neg, sf8_sub(zero, vr));
	const sf8 g = sf8_div(sf8_mul(sf8_mul(app, hr), hr),
	                      sf8_mul(sf8_mul(sf8_add(r2, sf8_set1(a->eps)), rho2), sf8_max(r, sf8_set1(a->rmin))));
	s[3] = sf8_add(s[3], sf8_mul(g, rx));
	s[4] = sf8_add(s[4], sf8_mul(g, ry));
	s[5] = sf8_add(s[5], sf8_mul(g, rz));
}

void SIMD_NAME(visc_pair_sums)(const visc_args *a, long i0, long cnt, float *t)
{
	const sph_neighbors *nb = a->nb;
	for (long b = 0; b < cnt; ++b) {
		const long i = i0 + b;
		sph_groups list = sph_nbr_groups(nb, i);
		const uint32_t c = nb->count[i];
		/* (x_i y_i z_i 0) and (v_i rho_i) from i's quads, in registers (a
		 * quad written to memory as floats and loaded back whole would
		 * stall on store forwarding) */
		const sf8 xyz = sf8_quad_lanes_below(3);
		const sf8 qp = sf8_and(sf8_load_quad2(a->pq + 4 * i), xyz);
		const sf8 qv = sf8_xor(sf8_load_quad2(a->pv + 4 * i), sf8_andnot(xyz, sf8_set1(-0.0f)));
		sf8 s[6];
		for (int k = 0; k < 6; ++k)
			s[k] = sf8_zero();
		uint32_t q = 0, l[8];
		for (; q + 8 <= c; q += 8) {
			sph_group_rows(&list, l);
			group(a, l, false, 8, qp, qv, s);
		}
		if (q < c) { /* the last group, padded with its last neighbour */
			sph_group_rows(&list, l);
			group(a, l, true, c - q, qp, qv, s);
		}
		for (int k = 0; k < 6; ++k)
			sf8_fold4(s[k], t + VISC_T * b + 4 * k);
	}
}

#ifndef EDDY_SIMD_VARIANT
static const int viscosity_reads[] = {COL_X_, COL_Y_, COL_Z_, COL_VX, COL_VY, COL_VZ, COL_DENSITY, -1};
static const int viscosity_writes[] = {COL_AX, COL_AY, COL_AZ, -1};

eddy_sph_viscosity_def eddy_default_sph_viscosity_def(void)
{
	return (eddy_sph_viscosity_def){.viscosity = 1e-3f /* water at 20 C */, .artificial = 0.05f};
}

/* A block: the pair sums, then their totals added to ax ay az. */
static void visc_block(const void *arg, long i0, long cnt)
{
	const visc_args a = *(const visc_args *)arg;
	float t[SPH_BLOCK * VISC_T];
	a.pair_sums(&a, i0, cnt, t);
	for (long b = 0; b < cnt; ++b) {
		const long i = i0 + b;
		const float *tb = t + VISC_T * b;
		const float k = a.coef * a.pq[4 * i + 3];
		a.ax[i] += k * sph_sum4(tb) + a.acoef * sph_sum4(tb + 12);
		a.ay[i] += k * sph_sum4(tb + 4) + a.acoef * sph_sum4(tb + 16);
		a.az[i] += k * sph_sum4(tb + 8) + a.acoef * sph_sum4(tb + 20);
	}
}

static eddy_status step(eddy_world *w, eddy_system *s, const eddy_step_context *ctx)
{
	const eddy_sph_viscosity_def *def = s->data;
	const sph_shared *sh = eddy__sph_find(w, s); /* never NULL: the pipeline checks .requires */
	const float *vx = eddy__col(w, COL_VX), *vy = eddy__col(w, COL_VY), *vz = eddy__col(w, COL_VZ);
	const float *rho = eddy__col(w, COL_DENSITY);
	const sph_kernel_consts kc = sh->k;
	const long n = sph_rows(w, sh);
	/* each neighbour's eight inputs as two 16-byte quads, (x y z 1/rho) from
	 * sph_density and (vx vy vz -rho) made here: a group of neighbours then
	 * costs two loads each and two transposes instead of eight scattered
	 * loads each */
	const eddy_arena_mark mark = eddy__arena_mark(&w->arena); /* pv lives for this pass only */
	float *pv = eddy__arena_alloc(&w->arena, (size_t)(n ? n : 1) * 4 * sizeof *pv);
	if (!pv)
		return eddy__fail(w, EDDY_ERR_NOMEM, "%s: out of scratch memory for %ld particles", s->label, n);
#pragma omp parallel for num_threads(ctx->threads) schedule(static)
	for (long i = 0; i < n; ++i) {
		pv[4 * i] = vx[i];
		pv[4 * i + 1] = vy[i];
		pv[4 * i + 2] = vz[i];
		pv[4 * i + 3] = -rho[i]; /* negated: see group */
	}
	/* acoef: -m Pi grad W = m alpha c h vr / ((r^2 + eps) rho_ij) spiky_grad
	 * (h-r)^2 r_hat, times 2: the mean density (rho_i + rho_j) / 2 is folded
	 * into the pair term */
	const visc_args a = {.pq = sh->pq,
	                     .pv = pv,
	                     .nb = &sh->nb,
	                     .ax = eddy__col(w, COL_AX),
	                     .ay = eddy__col(w, COL_AY),
	                     .az = eddy__col(w, COL_AZ),
	                     .h = kc.h,
	                     .eps = 0.01f * kc.h2,
	                     .rmin = 1e-3f * kc.h,
	                     .coef = def->viscosity * sh->mass * kc.visc_lap,
	                     .acoef = 2.0f * sh->mass * def->artificial * sh->c * kc.h * -kc.spiky_grad,
	                     .pair_sums = SIMD_PICK(visc_pair_sums)};
	sph_block_pass(n, ctx->threads, visc_block, &a);
	eddy__arena_release(&w->arena, mark);
	return EDDY_OK;
}

static double limit(eddy_world *w, eddy_system *s, const char **reason)
{
	const eddy_sph_viscosity_def *def = s->data;
	const sph_shared *sh = eddy__sph_find(w, s);
	*reason = "viscous";
	double l = INFINITY;
	if (def->viscosity > 0)
		l = VISC_LIMIT * (double)sh->h * sh->h / (def->viscosity / sh->rho0);
	const double ac = (double)def->artificial * sh->c;
	if (ac > 0 && VISC_ARTIFICIAL_LIMIT * sh->h / ac < l) {
		l = VISC_ARTIFICIAL_LIMIT * sh->h / ac;
		*reason = "artificial viscosity";
	}
	return l;
}

/* ax ay az are every force's: no default_writes, so order hints for them
 * name gravity alone */
const eddy_system_vtable eddy__kind_sph_viscosity = {
	.name = "sph_viscosity",
	.requires = EDDY_CAP_SPH_NEIGHBORS,
	.step = step,
	.limit = limit,
};

eddy_system_id eddy_add_sph_viscosity(eddy_world *w, const eddy_sph_viscosity_def *def)
{
	const char *sys = "sph_viscosity";
	if (!eddy__add_args(w, def, sys) || !eddy__check_nonneg(w, sys, "viscosity", def->viscosity) ||
	    !eddy__check_range(w, sys, "artificial", def->artificial, 0, 2))
		return EDDY_NULL_SYSTEM;
	eddy_sph_viscosity_def *copy = malloc(sizeof *copy);
	if (copy)
		*copy = *def;
	return eddy__add_system(w, &eddy__kind_sph_viscosity, copy, viscosity_reads, viscosity_writes);
}
#endif
