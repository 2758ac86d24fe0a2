/* SPDX-License-Identifier: MIT */
/* sph_pressure: the symmetric pressure force with the spiky kernel's gradient
 * (Mueller 2003, eq. 10, without its factor 1/2); boundary particles enter
 * the sum with the pressure sph_density extrapolated onto them (Adami et al.
 * 2012).
 *
 * Reads: x y z density pressure. Writes: ax ay az (accumulated).
 *   a_i -= scale * [ sum_j m (p_i + p_j) / (rho_i rho_j) grad W_spiky(x_i - x_j)
 *                  + sum_b V_b (p_i + p_b) / rho_i grad W_spiky(x_i - x_b) ]
 *   grad W_spiky(r_vec) = -45/(pi h^6) (h - r)^2 r_vec / r
 * Why not the paper's (p_i + p_j) / 2: in the interior sum_j V_j grad W = 0,
 * so that force is grad p / 2; a resting column would compress twice as
 * much as g H / k says and sound travel at sqrt(k/2). Doubled, the same
 * symmetric (momentum-conserving) pair force gives grad p and c = sqrt(k)
 * (the hydrostatic tank tests it).
 * The force is divided by its moment on the particle lattice (sh->grad_cal,
 * 0.947 at h = 2 spacings: see sph_density's add function); uncorrected,
 * the force of a linear pressure field falls 5.3% short of grad p.
 * Pairs closer than 1e-3 h take a fixed antisymmetric direction: skipping
 * them would leave coincident particles stuck together (docs/validation.md
 * C.6). A group with such a pair ends the vector sums of its particle; the
 * finish loop takes the rest pair by pair, and the walls.
 * Time-step limits, the smaller reported: acoustic, dt <= h / (c + max|v|)
 * (the world's CFL number is the Courant factor, 0.25-0.4); force,
 * dt <= 0.625 sqrt(h / max|a|), max|a| from the last step (with the default
 * CFL 0.4 the usual 0.25 sqrt(h/|a|)).
 * A mean compression over 3% at a frame raises a run-time warning (frame).
 * Source: Mueller, Charypar & Gross 2003; Adami, Hu & Adams, "A generalized
 * wall boundary condition for SPH", JCP 2012. */
#include "simd.h"
#include "sph.h"
#include "systems.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>

#define PRESSURE_T 12 /* floats of the pair sums per particle: 4 lanes of x, y, z */

/* What a block of the pass reads and writes. The pair sums are of
 * (p_i + p_j) / rho_j (h - r)^2 r_vec / r: the 1/r normalises r_vec. */
typedef struct pressure_args {
	const sph_neighbors *nb;
	const float *pq, *p; /* (x y z 1/rho) quads; pressures */
	float *ax, *ay, *az;
	float h, eps2, m, g; /* g: -spiky_grad grad_cal scale */
	void (*pair_sums)(const struct pressure_args *a, long i0, long cnt, float *t, uint32_t *done);
} pressure_args;

/* The sums over the fluid pairs of particles i0 .. i0 + cnt - 1 (sph.h's
 * block pass), each particle's as four lanes per component at t +
 * PRESSURE_T q, and in done[q] how many of its pairs they cover: all, unless
 * a group has a coincident pair. */
SIMD_DECLARE(void, pressure_pair_sums, (const pressure_args *a, long i0, long cnt, float *t, uint32_t *done));

/* One group (neighbours l[0..7]; with masked, only the first left count);
 * false, summing nothing, if a pair is coincident (r^2 <= eps2: no
 * direction to divide by). Whole groups (masked false) need no mask: the
 * compiler drops it where the argument is constant. */
static inline bool group(const pressure_args *a, const uint32_t *l, bool masked, uint32_t left, sf8 xi, sf8 yi, sf8 zi,
                         sf8 p_i, sf8 *sx, sf8 *sy, sf8 *sz)
{
	sf8 px, py, pz, ir;
	sf8_gather_quads(a->pq, l, &px, &py, &pz, &ir);
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

void SIMD_NAME(pressure_pair_sums)(const pressure_args *a, long i0, long cnt, float *t, uint32_t *done)
{
	const sph_neighbors *nb = a->nb;
	for (long b = 0; b < cnt; ++b) {
		const long i = i0 + b;
		sph_groups list = sph_nbr_groups(nb, i);
		const uint32_t c = nb->count[i];
		const float *pi = a->pq + 4 * i;
		const sf8 xi = sf8_set1(pi[0]), yi = sf8_set1(pi[1]), zi = sf8_set1(pi[2]), p_i = sf8_set1(a->p[i]);
		sf8 sx = sf8_zero(), sy = sx, sz = sx;
		uint32_t q = 0, l[8];
		for (; q + 8 <= c; q += 8) {
			sph_group_rows(&list, l);
			if (!group(a, l, false, 8, xi, yi, zi, p_i, &sx, &sy, &sz))
				break;
		}
		if (q + 8 > c && q < c) { /* the last group, padded with its last neighbour */
			sph_group_rows(&list, l);
			if (group(a, l, true, c - q, xi, yi, zi, p_i, &sx, &sy, &sz))
				q = c;
		}
		float *tb = t + PRESSURE_T * b;
		sf8_fold4(sx, tb);
		sf8_fold4(sy, tb + 4);
		sf8_fold4(sz, tb + 8);
		done[b] = q;
	}
}

#ifndef EDDY_SIMD_VARIANT
static const int pressure_reads[] = {COL_X_, COL_Y_, COL_Z_, COL_DENSITY, COL_PRESSURE, -1};
static const int pressure_writes[] = {COL_AX, COL_AY, COL_AZ, -1};

eddy_sph_pressure_def eddy_default_sph_pressure_def(void) { return (eddy_sph_pressure_def){.scale = 1.0f}; }

/* A block: the pair sums, then the pairs they left (coincident ones, one
 * by one), the walls, and ax ay az. */
static void pressure_block(const void *arg, long i0, long cnt)
{
	const pressure_args a = *(const pressure_args *)arg;
	const sph_neighbors *nb = a.nb;
	float t[SPH_BLOCK * PRESSURE_T];
	uint32_t done[SPH_BLOCK];
	a.pair_sums(&a, i0, cnt, t, done);
	for (long b = 0; b < cnt; ++b) {
		const long i = i0 + b;
		const float *tb = t + PRESSURE_T * b;
		const float xi = a.pq[4 * i], yi = a.pq[4 * i + 1], zi = a.pq[4 * i + 2];
		const float pi_ = a.p[i];
		float fx = sph_sum4(tb), fy = sph_sum4(tb + 4), fz = sph_sum4(tb + 8);
		/* from group done[b] / 8 (the sums stop at a group's start) */
		sph_groups list = sph_nbr_groups(nb, i);
		const uint32_t cnt_i = nb->count[i];
		for (uint32_t q = 0; q < done[b] && done[b] < cnt_i; q += 8)
			sph_group_skip(&list);
		uint32_t l[8];
		for (uint32_t q = done[b]; q < cnt_i; ++q) {
			if (q % 8 == 0)
				sph_group_rows(&list, l);
			const uint32_t j = l[q % 8];
			float rx = xi - a.pq[4 * (size_t)j], ry = yi - a.pq[4 * (size_t)j + 1], rz = zi - a.pq[4 * (size_t)j + 2];
			const float r2 = rx * rx + ry * ry + rz * rz;
			float r;
			if (r2 > a.eps2) {
				r = sqrtf(r2);
				const float inv = 1.0f / r;
				rx *= inv;
				ry *= inv;
				rz *= inv;
			} else { /* no direction at r = 0: a fixed one, not along a wall axis, opposite for (j, i) */
				const float sign = (uint32_t)i < j ? 1.0f : -1.0f;
				r = 0;
				rx = sign * 0.80178373f; /* (3, 2, 1) / sqrt(14) */
				ry = sign * 0.53452248f;
				rz = sign * 0.26726124f;
			}
			const float hr = a.h - r;
			/* (p_i + p_j)/(rho_i rho_j) times |dW/dr|; the force pushes i away from j */
			const float c = (pi_ + a.p[j]) * a.pq[4 * (size_t)j + 3] * hr * hr;
			fx += c * rx;
			fy += c * ry;
			fz += c * rz;
		}
		const uint32_t *blist = sph_bnbrs(nb, i);
		float bx = 0, by = 0, bz = 0;
		for (uint32_t qb = 0; qb < nb->bcount[i]; ++qb) {
			const uint32_t bj = blist[qb];
			const float rx = xi - nb->bx[bj], ry = yi - nb->by[bj], rz = zi - nb->bz[bj];
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
		/* rho >= m W(0) > 0 (the self term), so 1/rho is finite */
		const float gi = a.g * a.pq[4 * i + 3];
		a.ax[i] += gi * (a.m * fx + bx);
		a.ay[i] += gi * (a.m * fy + by);
		a.az[i] += gi * (a.m * fz + bz);
	}
}

static eddy_status step(eddy_world *w, eddy_system *s, const eddy_step_context *ctx)
{
	const eddy_sph_pressure_def *def = s->data;
	const sph_shared *sh = eddy__sph_find(w, s); /* never NULL: the pipeline checks .requires */
	const sph_kernel_consts kc = sh->k;
	/* -grad W = +45/(pi h^6) (h-r)^2 r_hat, so the signs of the sums are already "away" */
	const pressure_args a = {.nb = &sh->nb,
	                         .pq = sh->pq,
	                         .p = eddy__col(w, COL_PRESSURE),
	                         .ax = eddy__col(w, COL_AX),
	                         .ay = eddy__col(w, COL_AY),
	                         .az = eddy__col(w, COL_AZ),
	                         .h = kc.h,
	                         .eps2 = 1e-6f * kc.h2,
	                         .m = sh->mass,
	                         .g = -kc.spiky_grad * sh->grad_cal * def->scale,
	                         .pair_sums = SIMD_PICK(pressure_pair_sums)};
	sph_block_pass(sph_rows(w, sh), ctx->threads, pressure_block, &a);
	return EDDY_OK;
}

static double limit(eddy_world *w, eddy_system *s, const char **reason)
{
	const sph_shared *sh = eddy__sph_find(w, s);
	const double acoustic = sh->h / (sh->c + sqrt((double)eddy__max_norm2(w, COL_VX, COL_VY, COL_VZ)));
	const double a = sqrt((double)eddy__max_norm2(w, COL_AX, COL_AY, COL_AZ)),
				 force = a > 0 ? 0.625 * sqrt(sh->h / a) : INFINITY;
	*reason = force < acoustic ? "force" : "acoustic";
	return force < acoustic ? force : acoustic;
}

/* Once a frame, the water's mean compression (mean of max(rho - rho0, 0) /
 * rho0, the stats' density_compression_avg). The speed of sound is chosen
 * for about 1% (Mach 0.1: compression goes as Mach^2); a mean over 3% means
 * the flow outruns it (a collider the host moves faster than the scene's
 * own speeds, particles the host adds, a stiffness set too low), and a
 * run-time warning says so, naming the fastest particle and the stiffness
 * its speed wants. The state is not touched. */
#define PRESSURE_WARN_COMPRESSION 0.03
static eddy_status frame(eddy_world *w, eddy_system *s, int f)
{
	const sph_shared *sh = eddy__sph_find(w, s);
	const float *rho = eddy__col(w, COL_DENSITY);
	const long n = (long)w->n;
	if (!sh || !rho || n == 0 || !(sh->rho0 > 0))
		return EDDY_OK;
	const float rho0 = sh->rho0;
	double over = 0;
#pragma omp parallel for num_threads(w->def.threads) if (n > 65536) schedule(static) reduction(+ : over)
	for (long i = 0; i < n; ++i)
		over += rho[i] > rho0 ? (double)(rho[i] - rho0) : 0.0;
	const double mean = over / ((double)n * rho0);
	if (!(mean > PRESSURE_WARN_COMPRESSION))
		return EDDY_OK;
	const float *vx = eddy__col(w, COL_VX), *vy = eddy__col(w, COL_VY), *vz = eddy__col(w, COL_VZ);
	long fast = 0;
	double v2 = -1;
	for (long i = 0; i < n; ++i) {
		const double e = (double)vx[i] * vx[i] + (double)vy[i] * vy[i] + (double)vz[i] * vz[i];
		if (e > v2)
			v2 = e, fast = i;
	}
	const double v = sqrt(v2), c = sh->c;
	char key[sizeof s->label + 12];
	snprintf(key, sizeof key, "%s:compressed", s->label);
	eddy__warn(w, key,
	           "%s: the water is compressed %.1f%% on average at frame %d (t = %.6g s), over %g%%: the speed of sound "
	           "c = %.3g m/s (sph_density's stiffness %.4g m^2/s^2) is too low for this flow, whose fastest particle "
	           "(%ld) moves at %.3g m/s; the compression grows as (speed / c)^2: set stiffness to about (10 x %.3g)^2 "
	           "= %.4g m^2/s^2",
	           s->label, 100 * mean, f, w->time, 100 * PRESSURE_WARN_COMPRESSION, c, c * c, fast, v, v, 100 * v * v);
	return EDDY_OK;
}

/* ax ay az are every force's: no default_writes, so order hints for them
 * name gravity alone */
const eddy_system_vtable eddy__kind_sph_pressure = {
	.name = "sph_pressure",
	.settles = true,
	.provides = EDDY_CAP_SPH_EOS_FORCE,
	.requires = EDDY_CAP_SPH_NEIGHBORS,
	.step = step,
	.frame = frame,
	.limit = limit,
};

eddy_system_id eddy_add_sph_pressure(eddy_world *w, const eddy_sph_pressure_def *def)
{
	const char *sys = "sph_pressure";
	if (!eddy__add_args(w, def, sys) || !eddy__check_positive(w, sys, "scale", def->scale))
		return EDDY_NULL_SYSTEM;
	eddy_sph_pressure_def *copy = malloc(sizeof *copy);
	if (copy)
		*copy = *def;
	return eddy__add_system(w, &eddy__kind_sph_pressure, copy, pressure_reads, pressure_writes);
}
#endif
