/* SPDX-License-Identifier: MIT */
/* sph_dfsph: implicit (incompressible) SPH pressure, the divergence-free SPH
 * of Bender & Koschier (SCA 2015, TVCG 2017). It replaces sph_pressure: the
 * pressure is solved for each step so the fluid keeps its rest density, and
 * the time step is limited by the flow speed, not by a speed of sound.
 *
 * Reads: x y z vx vy vz density ax ay az, and with the divergence solver
 * dfsph_k dfsph_kd (state columns it declares: each solve's k of the last
 * step). Writes: pressure ax ay az (accumulated), dfsph_k dfsph_kd. Runs after the non-pressure forces (gravity, sph_viscosity,
 * sph_surface_tension) and before integrate, whose v += dt a then gives the
 * corrected velocity. It uses sph_density's neighbour lists.
 *
 * Kernel: the density is sph_density's (poly6, the 'density' column the
 * stats report) and G_ij = m grad W_spiky(x_i - x_j), the gradient and mass
 * sph_pressure uses; boundary particles (Akinci et al. 2012) have mass
 * m_b = V_b rho0. The spiky gradient stays repulsive as particles close in:
 * with the poly6 gradient (exact for the poly6 density, but zero at r = 0) a
 * tank at rest kept churning at 0.1 m/s as particles clustered. A spiky
 * density of its own (exact for the spiky gradient) made the solve consistent
 * but left the poly6 column 1% under rho0 in a tank at rest (mean
 * |rho - rho0| 1.4% against 0.15% now) at no gain in iterations.
 * With B_i = sum_b m_b grad W(x_i - x_b) and the pressure written as
 * k_i = p_i / rho_i^2:
 *   Drho_i/Dt = sum_j (v_i - v_j) . G_ij + v_i . B_i - sum_b m_b v_b . grad W(x_i - x_b)
 * (the last term: boundary particles of moving colliders, neighbors.c's
 * bdiv; 0 for walls at rest)
 *   a_i^p     = -sum_j (k_i + k_j) G_ij - 2 k_i B_i + h_i
 * The boundary particles mirror the particle's pressure (p_b = p_i, so the
 * wall term counts twice: with a single k_i the wall could not hold a
 * particle whose neighbourhood is full, as sum_j G_ij + B_i ~ 0 there), plus
 * Adami et al.'s (2012) hydrostatic part p_b - p_i = rho_i g . (x_b - x_i):
 *   h_i = -(1/rho_i) sum_b (g . (x_b - x_i)) m_b grad W(x_i - x_b)
 * (up, away from a floor),
 * known before the solve and added to the forces; without it the fluid
 * beside the walls lacks support and circulates.
 * Each step first sets v* = v + dt (a + h), the velocity the non-pressure
 * forces give, then solves for k on it, by sweeps that each set k from the
 * current v* and move v* by dt a^p of the change.
 *
 * With the divergence solver (the default) there are two solves, the
 * paper's pair (Alg. 1) folded into one step, both on the symmetric
 * operator, warm-started and projected:
 *   velocity (divergence-free) solve:  Drho_i/Dt(v*) = 0
 *   density solve:                     rho_i + dt Drho_i/Dt(v*) = rho0
 * In both the rate counts the wall as the force does,
 *   R_i(v) = sum_j (v_i - v_j) . G_ij + 2 v_i . B_i,
 * so that a change of k moves the predicted density by -(A k)_i with
 * A = dt^2 grad^T grad symmetric positive semi-definite, of diagonal
 * dt^2 D'_i,   D'_i = |S_i + 2 B_i|^2 + sum_j |G_ij|^2,   S_i = sum_j G_ij.
 * (The true wall rate is v_i . B_i: counted twice, the solve over-predicts
 * compression at a wall and is only stiffer there; at rest the constraint
 * is the same. With the true rate, Jacobi sweeps run to a tight tolerance
 * diverged in a 40-layer column.) Each sweep is a projected, relaxed Jacobi
 * step on the residual res_i (Drho_i/Dt, or the predicted rho_i - rho0):
 *   k_i <- max(k_i + omega res_i / (dt^n D'_i), 0),   omega = DFSPH_OMEGA,
 * n = 1 for the velocity solve, 2 for the density one (Ihmsen et al.'s
 * relaxed Jacobi, with the projection of unilateral pressure: a particle
 * may lose pressure it no longer needs but never goes below 0, so the free
 * surface is not pulled together). Each solve starts from its own k of the
 * last step (the state columns DFSPH_K_COLUMN and DFSPH_KD_COLUMN, which
 * move with the particles and are checkpointed), applied as one
 * correction: the velocity solve's k is the pressure that carries the
 * weight of the water above (it balances gravity over a step whatever dt
 * is), the density solve's the one that holds the compression the velocity
 * solve leaves. Cold, each step had to rebuild the hydrostatic pressure from
 * the compression it allowed, which Jacobi sweeps cannot do through deep
 * water (their error in the column-wide mode falls by about 1 - c / N^2 a
 * sweep for N layers): a 40-layer column rang and threw water to the lid.
 * Each solve first runs Jacobi-preconditioned conjugate gradients on the
 * particles that hold pressure or are compressing (divergence_cg: they
 * reduce the column-wide mode about N times faster than the sweeps), then
 * the projected sweeps above settle the particles that entered or left that
 * set; the velocity solve makes at least DFSPH_SMOOTH of them, which damp
 * the particle-scale error the Krylov solve leaves. In the velocity solve a
 * particle whose kernel sum is below DFSPH_SURFACE rho0 (the outermost
 * layer of a free surface) holds no pressure (k = 0 and no constraint: a
 * Dirichlet surface, as SPlisHSPlasH's DFSPH leaves out particles with few
 * neighbours), so water a moving solid stirred apart below it is not held
 * at its expanded density; the density solve still covers every particle.
 * A sweep's error is |res_i| where k_i > 0 (too much pressure counts, as
 * too little) and max(res_i, 0) where k_i = 0, averaged over all particles:
 * the velocity solve stops once that times dt / rho0 is at most
 * max_divergence_error (the density change per step it leaves: it must be
 * well below max_density_error, or the water compresses by it every step),
 * the density solve once it is at most max_density_error, both scaled by
 * (DFSPH_DEPTH_REF h / H)^2 in a fluid H deep along gravity beyond
 * DFSPH_DEPTH_REF kernel radii (divergence_tolerance: the mean residual of
 * the column-wide mode shrinks so against its error).
 *
 * Without the divergence solver the density solve runs alone, cold, with
 * the paper's sweeps that only add pressure, on the true wall rate and
 * D_i = (S_i + 2 B_i) . (S_i + B_i) + sum_j |G_ij|^2:
 *   k_i += max(rho_i + dt Drho_i/Dt - rho0, 0) / (dt^2 D_i)
 * until the mean predicted compression is at most max_density_error. It is
 * the cheaper choice for shallow, splashing scenes (scenes/pour.lua), and
 * does not hold still water much deeper than 10 layers (at 40 it blows up).
 *
 * The result, a^p = (v* - (v + dt a)) / dt, is added to ax ay az. The pressure
 * column gets p_i = M k_i rho_i^2, k_i summed over both solves, M the
 * force's lattice moment (1 / grad_cal, see sph_pressure): the force of a
 * linear field is M grad p / rho, so this is the pressure in Pa (M = 0.947
 * at h = 2 spacings).
 * The pairs are packed once a step into groups of eight (the neighbours and
 * G_ij by component, a particle's last group padded with G = 0), which the
 * sweeps stream; positions come from sph_density's (x y z 1/rho) quads. The
 * sums over a particle's groups go eight lanes at a time, with AVX2 when the
 * CPU has it, else SSE doing each group as two halves with the same
 * operations per lane, and end in a fixed order (lane l + 4 onto lane l,
 * then sph_hsum4's); each particle writes only its own results, and the mean
 * errors are summed serially in row order. So the result is the same, bit
 * for bit, on either path and for any thread count. EDDY_NO_AVX2 (set and
 * not empty when the system is added) makes it take the SSE path, to compare
 * the two.
 *
 * Published per frame: solver = "dfsph", iterations (mean constant-density
 * sweeps per step), residual (largest final mean density error of a step),
 * residual_max (largest final error of one particle, / rho0),
 * divergence_iterations (mean), unconverged (steps in which a solve hit its
 * cap above its tolerance). A step whose final mean density error is above
 * DFSPH_FAIL_ERROR, or one particle's above DFSPH_FAIL_PARTICLE, fails
 * naming the step and the particle: the solve has lost the fluid (a time
 * step far too long, or water deeper than the solver holds).
 * Time-step limits (the world multiplies them by its CFL number): velocity,
 * dt <= h / max|v|; gravity, dt <= 0.18 sqrt(h / |g|) (see below), and with
 * the divergence solver in a fluid H deep beyond DFSPH_DEPTH_REF h, that
 * times sqrt(DFSPH_DEPTH_REF h / H), i.e. dt ~ h / sqrt(|g| H): the first-
 * order prediction's error in a step grows with the hydrostatic pressure
 * p ~ rho0 |g| H it moves (a 60-layer column rang at the shallow limit and
 * held at half of it). There is
 * no acoustic limit: that is sph_pressure's, which a scene with this lacks.
 * Source: Bender & Koschier, "Divergence-free smoothed particle hydrodynamics",
 * SCA 2015 (eqs. 8-9, 12, Alg. 1-3, warm start), and "Divergence-free SPH
 * for incompressible and viscous fluids", TVCG 2017; Hestenes & Stiefel,
 * "Methods of conjugate gradients for solving linear systems", J. Res. NBS
 * 1952, and Saad, "Iterative methods for sparse linear systems", 2003 (Alg.
 * 9.1, preconditioned CG); Ihmsen et al.,
 * "Implicit incompressible SPH", TVCG 2014 (relaxed Jacobi); Akinci et al., "Versatile rigid-fluid
 * coupling for incompressible SPH", SIGGRAPH 2012; Adami, Hu & Adams, "A
 * generalized wall boundary condition for SPH", JCP 2012 (eq. 27). */
#include "sph.h"
#include "systems.h"

#include <stdlib.h>
#include <string.h>

typedef struct sph_dfsph {
	eddy_sph_dfsph_def def;
	/* statistics of the current frame */
	int frame;
	int64_t steps, sweeps, div_sweeps, unconverged;
	double residual, worst;
	bool avx2; /* the passes' AVX2 path (else SSE, the same bits) */
	int kcol;  /* the state column DFSPH_K_COLUMN */
	int kdcol; /* the state column DFSPH_KD_COLUMN */
	int capped; /* consecutive steps whose velocity solve stopped at its cap
	             * above DFSPH_FAIL_CAPPED_ERROR times its tolerance */
} sph_dfsph;

static const int dfsph_reads[] = {COL_X_, COL_Y_, COL_Z_, COL_VX, COL_VY, COL_VZ, COL_DENSITY, COL_AX, COL_AY, COL_AZ, -1};
static const int dfsph_writes[] = {COL_PRESSURE, COL_AX, COL_AY, COL_AZ, -1};
static const int no_hint_writes[] = {-1};

/* dt <= DFSPH_GRAVITY_LIMIT sqrt(h / |g|) (times the CFL number): gravity
 * compresses the fluid by g dt^2 each step, which the first-order prediction
 * of the solve must absorb; a tank at rest rings up from dt = 0.19 sqrt(h / g)
 * on (h = 2 cm, dt 8.5 ms) and stays quiet below it. Transient forces
 * (viscosity, impacts) do not need it: the velocity limit covers them. */
#define DFSPH_GRAVITY_LIMIT 0.18

/* above this final mean density error a step fails instead of going on */
#define DFSPH_FAIL_ERROR 0.05

/* above this predicted density error at one particle a step fails: the
 * particles overlap (the pour's largest is 0.42) */
#define DFSPH_FAIL_PARTICLE 1.0

/* The velocity solve warm-starts, so a step stopped at its cap hands the
 * rest on to the next (a 40-layer column at rest: once, in its first step,
 * at 1.8 times the tolerance). Stopped at the cap above DFSPH_FAIL_CAPPED_ERROR
 * times the tolerance in DFSPH_FAIL_CAPPED steps in a row, it is not
 * catching up, and the step fails (an 80-layer column: steps 0-2 at 2.5-3.6
 * times, before it threw water to the lid at step 26). */
#define DFSPH_FAIL_CAPPED_ERROR 2.0
#define DFSPH_FAIL_CAPPED 3

/* projected Jacobi sweeps the velocity solve makes after its conjugate
 * gradients: they damp the particle-scale part of the error, which the
 * Krylov solve leaves (with none, single particles at the surface of still
 * water kept jittering at a few % of sqrt(g H)) */
#define DFSPH_SMOOTH 2

/* the velocity solve leaves out a particle whose kernel sum (its density,
 * walls included) is below DFSPH_SURFACE rho0: the outermost particles of a
 * free surface (0.75-0.9 rho0 in water at rest, every other particle
 * 0.95-1.05). Held there too, the velocity solve keeps water a moving solid
 * has stirred apart at its expanded density (0.972 rho0: a lowered block
 * stood 2.6% high); leaving out every particle up to 0.95 rho0 let still
 * water's surface jitter at 4-8% of sqrt(g H), up to 0.875 let a dropped
 * block compress 1.6% at impact (three times the density solve's
 * tolerance). At 0.8 still water rests under 0.5% of sqrt(g H) at 10-20
 * layers and 1.1% at 40, a dropped block compresses 0.46%, and the lowered
 * block stands 1.3% high. */
#define DFSPH_SURFACE 0.8f

/* the depth (in kernel radii) up to which the velocity solve stops at its
 * requested tolerance; deeper, the tolerance falls with the square of the
 * depth (divergence_tolerance) */
#define DFSPH_DEPTH_REF 5.0

/* constant-density sweeps a step makes at least (the paper: 2; 1 gives the
 * same errors in the pour, tank and drop and saves 10% of the solve) */
#define DFSPH_MIN_SWEEPS 1

/* the relaxation of both solves' projected Jacobi sweeps (with the divergence
 * solver): the largest eigenvalue of D'^-1 A is near 4 here (full
 * neighbourhoods plus the doubled wall), so sweeps with omega above 0.5 can
 * grow; a 40-layer column diverged at 0.66 and at 0.8 */
#define DFSPH_OMEGA 0.5f

/* the particle state column with each particle's k of the velocity solve,
 * its warm start in the next step */
#define DFSPH_K_COLUMN "dfsph_k"
#define DFSPH_KD_COLUMN "dfsph_kd"

eddy_sph_dfsph_def eddy_default_sph_dfsph_def(void)
{
	eddy_sph_dfsph_def d;
	d.max_density_error = 0.005f;
	d.max_iterations = 100;
	d.divergence_solver = true;
	d.max_divergence_error = 5e-5f;
	d.max_divergence_iterations = 1000;
	return d;
}

/* The solver's per-step scratch, all in the world's arena. */
typedef struct dfsph_f4 {
	float x, y, z, w;
} dfsph_f4;

#ifdef __SSE2__
/* Four consecutive particles' quads as four vectors of their x, y, z, w. */
static inline void load4(const dfsph_f4 *p, __m128 *x, __m128 *y, __m128 *z, __m128 *w)
{
	__m128 a = _mm_loadu_ps(&p[0].x), b = _mm_loadu_ps(&p[1].x), c = _mm_loadu_ps(&p[2].x), d = _mm_loadu_ps(&p[3].x);
	_MM_TRANSPOSE4_PS(a, b, c, d);
	*x = a;
	*y = b;
	*z = c;
	*w = d;
}
#endif

/* Eight pairs of one particle: the neighbours and G_ij by component. A
 * particle's pairs are whole groups, the last one padded with the particle
 * itself and G = 0 (exact zeros in every sum), so the sweeps stream through
 * one array with neither a scalar tail nor a mask, and a group is what one
 * AVX2 register or two SSE ones hold. */
typedef struct dfsph_group {
	uint32_t j2[8]; /* 2 j: address modes of scale 8 and 2 then reach the 16-byte
	                 * v[j] and pq[j] and the 4-byte k[j] without a shift */
	float gx[8], gy[8], gz[8];
} dfsph_group;

/* v[j] or pq[j] (four floats), and k[j], of 2 j */
static inline const float *quad_of(const float *base, uint32_t j2)
{
	return base + 2 * (size_t)j2;
}

static inline float k_of(const float *k, uint32_t j2)
{
	return *(const float *)((const char *)k + 2 * (size_t)j2);
}

/* What the gradient pass reads. */
typedef struct grad_args {
	const sph_neighbors *nb;
	const float *pq;  /* (x y z 1/rho) quads of sph_density */
	const float *rho;
	float h, eps2;
	float mg;         /* m spiky_grad: G_ij = mg (h - r)^2 / r r_vec */
	float rho0, spiky_grad;
	float gx, gy, gz; /* gravity */
	float dmin;       /* D_i below this is negligible */
} grad_args;

struct dfsph_work;
/* A pass's sums over the groups of particles i0 .. i0 + cnt - 1, written
 * as four lanes each (lane l holding lanes l and l + 4 of the groups) to
 * t: the part of a pass that has an SSE and an AVX2 path. */
typedef void sums_fn(struct dfsph_work *wk, long i0, long cnt, float *t);

typedef struct dfsph_work {
	long n;
	size_t *goff;   /* particle i's groups are goff[i] .. goff[i + 1] */
	dfsph_group *g;
	dfsph_f4 *b;    /* B_i, and w = 1 / D_i (0 where D_i is negligible) */
	float *dsym;    /* 1 / D'_i, the diagonal of the symmetric operator (0 likewise) */
	dfsph_f4 *v;    /* v*_i (w unused: a neighbour's velocity is one 16-byte load) */
	dfsph_f4 *h;    /* the walls' hydrostatic push h_i (m/s^2), and w = rho_i */
	float *k;       /* the k_i a correction applies, apart from v: correct
	                 * gathers it from 4 bytes a particle (22 KB in the pour,
	                 * within L1) */
	float *ksum;    /* the sum of k_i over the sweeps: the current solve's k
	                 * (with its warm start) */
	float *kp;      /* the pressure's k_i: the sum over both solves */
	float *err;     /* per particle: the error the sweep measured */
	float *full;    /* 1 where rho_i >= DFSPH_SURFACE rho0, else 0: the
	                 * velocity solve's particles (divergence solver only) */
	const grad_args *ga;
	uint32_t *owner; /* the particle of each group (the AVX2 gradient pass) */
	sums_fn *grads, *rate, *correct; /* the path's sums (AVX2 or SSE) */
} dfsph_work;

/* What a sweep needs beside the work arrays. */
typedef struct sweep_args {
	float dt, inv_dt, inv_dt2, rho0;
	bool divergence; /* the divergence-free solve, else the constant-density one */
	bool projected;  /* the velocity solve: projected relaxed Jacobi on the
	                  * symmetric operator (else sweeps that add pressure) */
	int rate_only;   /* RATE_SIGNED or RATE_LINEAR: the rate pass only writes
	                  * R_i(v) to err (the conjugate gradient's products) */
} sweep_args;

/* sweep_args.rate_only: R_i(v) with the moving walls' part (the residual),
 * or without it (the linear operator's product) */
enum { RATE_SWEEP = 0, RATE_SIGNED = 1, RATE_LINEAR = 2 };

/* The passes go in blocks of particles: first the sums over the groups
 * (sums_fn), then the rest for the block. Finishing each particle right
 * after its groups put a long chain of dependent adds and multiplies behind
 * every (often mispredicted) exit of the loop over its groups; the
 * particles of the second loop are independent, and the passes took 10%
 * less time. */
#define DFSPH_BLOCK 64

/* floats of t per particle */
#define GRAD_T 16 /* sum G_ij by component, sum |G_ij|^2 */
#define RATE_T 4  /* sum (v_i - v_j) . G_ij */
#define CORR_T 12 /* sum (k_i + k_j) G_ij by component */

/* The neighbours of group q, padded with i itself, as 2 j. */
static inline void group_rows_self(const uint32_t *list, uint32_t cnt, uint32_t q, uint32_t i, uint32_t l2[8])
{
	for (uint32_t k = 0; k < 8; ++k)
		l2[k] = 2 * (q + k < cnt ? list[q + k] : i);
}

/* The gradient pass's sums: each particle's groups from its list, with
 * G_ij = 0 for a pair closer than sqrt(eps2) (no direction), at r >= h
 * (the list's margin) and for the padding. */
#ifdef __SSE2__
static void grads_sse(struct dfsph_work *wk, long i0, long cnt, float *t)
{
	const grad_args *a = wk->ga;
	const sph_neighbors *nb = a->nb;
	const __m128 vh = _mm_set1_ps(a->h), veps2 = _mm_set1_ps(a->eps2), vmg = _mm_set1_ps(a->mg),
	             one = _mm_set1_ps(1.0f), zero = _mm_setzero_ps();
	for (long q = 0; q < cnt; ++q) {
		const long i = i0 + q;
		const uint32_t *list = nb->nbr + (size_t)i * nb->cap, c = nb->count[i];
		const float *pi = a->pq + 4 * i;
		const __m128 vxi = _mm_set1_ps(pi[0]), vyi = _mm_set1_ps(pi[1]), vzi = _mm_set1_ps(pi[2]);
		__m128 sx[2] = {zero, zero}, sy[2] = {zero, zero}, sz[2] = {zero, zero}, s2[2] = {zero, zero};
		dfsph_group *g = wk->g + wk->goff[i];
		for (uint32_t p = 0; p < c; p += 8, ++g) {
			if (p + 8 <= c) {
				const __m128i l0 = _mm_loadu_si128((const __m128i *)(list + p)),
				              l1 = _mm_loadu_si128((const __m128i *)(list + p + 4));
				_mm_storeu_si128((__m128i *)g->j2, _mm_add_epi32(l0, l0));
				_mm_storeu_si128((__m128i *)(g->j2 + 4), _mm_add_epi32(l1, l1));
			} else {
				group_rows_self(list, c, p, (uint32_t)i, g->j2);
			}
			for (int k = 0; k < 2; ++k) {
				const uint32_t *l = g->j2 + 4 * k;
				__m128 px = _mm_loadu_ps(quad_of(a->pq, l[0])), py = _mm_loadu_ps(quad_of(a->pq, l[1])),
				       pz = _mm_loadu_ps(quad_of(a->pq, l[2])), pw = _mm_loadu_ps(quad_of(a->pq, l[3]));
				_MM_TRANSPOSE4_PS(px, py, pz, pw);
				const __m128 rx = _mm_sub_ps(vxi, px), ry = _mm_sub_ps(vyi, py), rz = _mm_sub_ps(vzi, pz);
				const __m128 r2 =
					_mm_add_ps(_mm_add_ps(_mm_mul_ps(rx, rx), _mm_mul_ps(ry, ry)), _mm_mul_ps(rz, rz));
				const __m128 r = _mm_sqrt_ps(r2), hr = _mm_sub_ps(vh, r);
				const __m128 ok = _mm_and_ps(_mm_cmpgt_ps(r2, veps2), _mm_cmpgt_ps(hr, zero));
				/* r is at least sqrt(eps2) where ok; elsewhere divide by 1 */
				const __m128 rs = _mm_or_ps(_mm_and_ps(ok, r), _mm_andnot_ps(ok, one));
				const __m128 f = _mm_and_ps(ok, _mm_div_ps(_mm_mul_ps(_mm_mul_ps(vmg, hr), hr), rs));
				const __m128 gx = _mm_mul_ps(f, rx), gy = _mm_mul_ps(f, ry), gz = _mm_mul_ps(f, rz);
				_mm_storeu_ps(g->gx + 4 * k, gx);
				_mm_storeu_ps(g->gy + 4 * k, gy);
				_mm_storeu_ps(g->gz + 4 * k, gz);
				sx[k] = _mm_add_ps(sx[k], gx);
				sy[k] = _mm_add_ps(sy[k], gy);
				sz[k] = _mm_add_ps(sz[k], gz);
				s2[k] = _mm_add_ps(
					s2[k], _mm_add_ps(_mm_add_ps(_mm_mul_ps(gx, gx), _mm_mul_ps(gy, gy)), _mm_mul_ps(gz, gz)));
			}
		}
		float *ti = t + GRAD_T * q;
		_mm_storeu_ps(ti, _mm_add_ps(sx[0], sx[1]));
		_mm_storeu_ps(ti + 4, _mm_add_ps(sy[0], sy[1]));
		_mm_storeu_ps(ti + 8, _mm_add_ps(sz[0], sz[1]));
		_mm_storeu_ps(ti + 12, _mm_add_ps(s2[0], s2[1]));
	}
}

static void rate_sse(struct dfsph_work *wk, long i0, long cnt, float *t)
{
	const float *vf = &wk->v->x;
	for (long q = 0; q < cnt; ++q) {
		const float *vi = vf + 4 * (i0 + q);
		const __m128 vix = _mm_set1_ps(vi[0]), viy = _mm_set1_ps(vi[1]), viz = _mm_set1_ps(vi[2]);
		__m128 sx[2] = {_mm_setzero_ps(), _mm_setzero_ps()}, sy[2] = {sx[0], sx[0]}, sz[2] = {sx[0], sx[0]};
		for (const dfsph_group *g = wk->g + wk->goff[i0 + q], *ge = wk->g + wk->goff[i0 + q + 1]; g < ge; ++g)
			for (int k = 0; k < 2; ++k) {
				const uint32_t *l = g->j2 + 4 * k;
				/* four neighbours' velocities are four loads and a transpose */
				__m128 vx = _mm_loadu_ps(quad_of(vf, l[0])), vy = _mm_loadu_ps(quad_of(vf, l[1])),
				       vz = _mm_loadu_ps(quad_of(vf, l[2])), vw = _mm_loadu_ps(quad_of(vf, l[3]));
				_MM_TRANSPOSE4_PS(vx, vy, vz, vw);
				sx[k] = _mm_add_ps(sx[k], _mm_mul_ps(_mm_sub_ps(vix, vx), _mm_loadu_ps(g->gx + 4 * k)));
				sy[k] = _mm_add_ps(sy[k], _mm_mul_ps(_mm_sub_ps(viy, vy), _mm_loadu_ps(g->gy + 4 * k)));
				sz[k] = _mm_add_ps(sz[k], _mm_mul_ps(_mm_sub_ps(viz, vz), _mm_loadu_ps(g->gz + 4 * k)));
			}
		_mm_storeu_ps(t + RATE_T * q, _mm_add_ps(_mm_add_ps(_mm_add_ps(sx[0], sy[0]), sz[0]),
		                                         _mm_add_ps(_mm_add_ps(sx[1], sy[1]), sz[1])));
	}
}

static void correct_sse(struct dfsph_work *wk, long i0, long cnt, float *t)
{
	const float *k = wk->k;
	for (long q = 0; q < cnt; ++q) {
		const __m128 vki = _mm_set1_ps(k[i0 + q]);
		__m128 sx[2] = {_mm_setzero_ps(), _mm_setzero_ps()}, sy[2] = {sx[0], sx[0]}, sz[2] = {sx[0], sx[0]};
		for (const dfsph_group *g = wk->g + wk->goff[i0 + q], *ge = wk->g + wk->goff[i0 + q + 1]; g < ge; ++g)
			for (int h = 0; h < 2; ++h) {
				const uint32_t *l = g->j2 + 4 * h;
				const __m128 c =
					_mm_add_ps(vki, _mm_setr_ps(k_of(k, l[0]), k_of(k, l[1]), k_of(k, l[2]), k_of(k, l[3])));
				sx[h] = _mm_add_ps(sx[h], _mm_mul_ps(c, _mm_loadu_ps(g->gx + 4 * h)));
				sy[h] = _mm_add_ps(sy[h], _mm_mul_ps(c, _mm_loadu_ps(g->gy + 4 * h)));
				sz[h] = _mm_add_ps(sz[h], _mm_mul_ps(c, _mm_loadu_ps(g->gz + 4 * h)));
			}
		float *ti = t + CORR_T * q;
		_mm_storeu_ps(ti, _mm_add_ps(sx[0], sx[1]));
		_mm_storeu_ps(ti + 4, _mm_add_ps(sy[0], sy[1]));
		_mm_storeu_ps(ti + 8, _mm_add_ps(sz[0], sz[1]));
	}
}
#else
/* Without SSE the vector paths' lanes one by one, folded as they fold. */
static void fold(const float s[8], float *t)
{
	for (int l = 0; l < 4; ++l)
		t[l] = s[l] + s[l + 4];
}

static void grads_scalar(struct dfsph_work *wk, long i0, long cnt, float *t)
{
	const grad_args *a = wk->ga;
	const sph_neighbors *nb = a->nb;
	for (long q = 0; q < cnt; ++q) {
		const long i = i0 + q;
		const uint32_t *list = nb->nbr + (size_t)i * nb->cap, c = nb->count[i];
		const float *pi = a->pq + 4 * i;
		float sx[8] = {0}, sy[8] = {0}, sz[8] = {0}, s2[8] = {0};
		dfsph_group *g = wk->g + wk->goff[i];
		for (uint32_t p = 0; p < c; p += 8, ++g) {
			group_rows_self(list, c, p, (uint32_t)i, g->j2);
			for (int l = 0; l < 8; ++l) {
				const float *pj = quad_of(a->pq, g->j2[l]);
				const float rx = pi[0] - pj[0], ry = pi[1] - pj[1], rz = pi[2] - pj[2];
				const float r2 = rx * rx + ry * ry + rz * rz;
				const float r = sqrtf(r2), hr = a->h - r;
				const float f = r2 > a->eps2 && hr > 0 ? a->mg * hr * hr / r : 0.0f;
				g->gx[l] = f * rx;
				g->gy[l] = f * ry;
				g->gz[l] = f * rz;
				sx[l] += g->gx[l];
				sy[l] += g->gy[l];
				sz[l] += g->gz[l];
				s2[l] += g->gx[l] * g->gx[l] + g->gy[l] * g->gy[l] + g->gz[l] * g->gz[l];
			}
		}
		float *ti = t + GRAD_T * q;
		fold(sx, ti);
		fold(sy, ti + 4);
		fold(sz, ti + 8);
		fold(s2, ti + 12);
	}
}

static void rate_scalar(struct dfsph_work *wk, long i0, long cnt, float *t)
{
	const float *vf = &wk->v->x;
	for (long q = 0; q < cnt; ++q) {
		const float *vi = vf + 4 * (i0 + q);
		float sx[8] = {0}, sy[8] = {0}, sz[8] = {0}, s[8];
		for (const dfsph_group *g = wk->g + wk->goff[i0 + q], *ge = wk->g + wk->goff[i0 + q + 1]; g < ge; ++g)
			for (int l = 0; l < 8; ++l) {
				const float *vj = quad_of(vf, g->j2[l]);
				sx[l] += (vi[0] - vj[0]) * g->gx[l];
				sy[l] += (vi[1] - vj[1]) * g->gy[l];
				sz[l] += (vi[2] - vj[2]) * g->gz[l];
			}
		for (int l = 0; l < 8; ++l)
			s[l] = (sx[l] + sy[l]) + sz[l];
		fold(s, t + RATE_T * q);
	}
}

static void correct_scalar(struct dfsph_work *wk, long i0, long cnt, float *t)
{
	const float *k = wk->k;
	for (long q = 0; q < cnt; ++q) {
		const float ki = k[i0 + q];
		float sx[8] = {0}, sy[8] = {0}, sz[8] = {0};
		for (const dfsph_group *g = wk->g + wk->goff[i0 + q], *ge = wk->g + wk->goff[i0 + q + 1]; g < ge; ++g)
			for (int l = 0; l < 8; ++l) {
				const float c = ki + k_of(k, g->j2[l]);
				sx[l] += c * g->gx[l];
				sy[l] += c * g->gy[l];
				sz[l] += c * g->gz[l];
			}
		float *ti = t + CORR_T * q;
		fold(sx, ti);
		fold(sy, ti + 4);
		fold(sz, ti + 8);
	}
}
#endif

#ifdef SPH_AVX2
/* lanes l and l + 4 added, as the SSE path adds its halves */
__attribute__((target("avx2"))) static inline __m128 fold8(__m256 v)
{
	return _mm_add_ps(_mm256_castps256_ps128(v), _mm256_extractf128_ps(v, 1));
}

__attribute__((target("avx2"))) static void grads_avx2(struct dfsph_work *wk, long i0, long cnt, float *t)
{
	const grad_args *a = wk->ga;
	const sph_neighbors *nb = a->nb;
	const __m256i lane = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
	for (long q = 0; q < cnt; ++q) {
		const long i = i0 + q;
		const uint32_t *list = nb->nbr + (size_t)i * nb->cap, c = nb->count[i];
		dfsph_group *g = wk->g + wk->goff[i];
		uint32_t p = 0;
		for (; p + 8 <= c; p += 8, ++g) {
			const __m256i l = _mm256_loadu_si256((const __m256i *)(list + p));
			_mm256_storeu_si256((__m256i *)g->j2, _mm256_add_epi32(l, l));
		}
		if (p < c) { /* the last group: lanes past the count (not read) get i */
			const __m256i in = _mm256_cmpgt_epi32(_mm256_set1_epi32((int)(c - p)), lane);
			const __m256i l = _mm256_blendv_epi8(_mm256_set1_epi32((int)i),
			                                     _mm256_maskload_epi32((const int *)(list + p), in), in);
			_mm256_storeu_si256((__m256i *)g->j2, _mm256_add_epi32(l, l));
		}
	}
	/* the block's groups in one loop: the square roots and divisions of
	 * several particles overlap */
	const __m256 vh = _mm256_set1_ps(a->h), veps2 = _mm256_set1_ps(a->eps2), vmg = _mm256_set1_ps(a->mg),
	             one = _mm256_set1_ps(1.0f), zero = _mm256_setzero_ps();
	for (size_t gi = wk->goff[i0], ge = wk->goff[i0 + cnt]; gi < ge; ++gi) {
		dfsph_group *g = wk->g + gi;
		const float *pi = a->pq + 4 * (size_t)wk->owner[gi];
		const __m256 vxi = _mm256_broadcast_ss(pi), vyi = _mm256_broadcast_ss(pi + 1), vzi = _mm256_broadcast_ss(pi + 2);
		const uint32_t *l = g->j2;
		const float *const quad[8] = {quad_of(a->pq, l[0]), quad_of(a->pq, l[1]), quad_of(a->pq, l[2]),
		                              quad_of(a->pq, l[3]), quad_of(a->pq, l[4]), quad_of(a->pq, l[5]),
		                              quad_of(a->pq, l[6]), quad_of(a->pq, l[7])};
		__m256 px, py, pz, pw;
		sph_transpose8(quad, &px, &py, &pz, &pw);
		const __m256 rx = _mm256_sub_ps(vxi, px), ry = _mm256_sub_ps(vyi, py), rz = _mm256_sub_ps(vzi, pz);
		const __m256 r2 =
			_mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(rx, rx), _mm256_mul_ps(ry, ry)), _mm256_mul_ps(rz, rz));
		const __m256 r = _mm256_sqrt_ps(r2), hr = _mm256_sub_ps(vh, r);
		const __m256 ok = _mm256_and_ps(_mm256_cmp_ps(r2, veps2, _CMP_GT_OQ), _mm256_cmp_ps(hr, zero, _CMP_GT_OQ));
		const __m256 rs = _mm256_blendv_ps(one, r, ok);
		const __m256 f = _mm256_and_ps(ok, _mm256_div_ps(_mm256_mul_ps(_mm256_mul_ps(vmg, hr), hr), rs));
		_mm256_storeu_ps(g->gx, _mm256_mul_ps(f, rx));
		_mm256_storeu_ps(g->gy, _mm256_mul_ps(f, ry));
		_mm256_storeu_ps(g->gz, _mm256_mul_ps(f, rz));
	}
	for (long q = 0; q < cnt; ++q) {
		__m256 sx = zero, sy = zero, sz = zero, s2 = zero;
		for (const dfsph_group *g = wk->g + wk->goff[i0 + q], *ge = wk->g + wk->goff[i0 + q + 1]; g < ge; ++g) {
			const __m256 gx = _mm256_loadu_ps(g->gx), gy = _mm256_loadu_ps(g->gy), gz = _mm256_loadu_ps(g->gz);
			sx = _mm256_add_ps(sx, gx);
			sy = _mm256_add_ps(sy, gy);
			sz = _mm256_add_ps(sz, gz);
			s2 = _mm256_add_ps(s2, _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(gx, gx), _mm256_mul_ps(gy, gy)),
			                                     _mm256_mul_ps(gz, gz)));
		}
		float *ti = t + GRAD_T * q;
		_mm_storeu_ps(ti, fold8(sx));
		_mm_storeu_ps(ti + 4, fold8(sy));
		_mm_storeu_ps(ti + 8, fold8(sz));
		_mm_storeu_ps(ti + 12, fold8(s2));
	}
}

__attribute__((target("avx2"))) static void rate_avx2(struct dfsph_work *wk, long i0, long cnt, float *t)
{
	const float *vf = &wk->v->x;
	for (long q = 0; q < cnt; ++q) {
		const float *vi = vf + 4 * (i0 + q);
		const __m256 vix = _mm256_set1_ps(vi[0]), viy = _mm256_set1_ps(vi[1]), viz = _mm256_set1_ps(vi[2]);
		__m256 sx = _mm256_setzero_ps(), sy = sx, sz = sx;
		for (const dfsph_group *g = wk->g + wk->goff[i0 + q], *ge = wk->g + wk->goff[i0 + q + 1]; g < ge; ++g) {
			const uint32_t *l = g->j2;
			const float *const quad[8] = {quad_of(vf, l[0]), quad_of(vf, l[1]), quad_of(vf, l[2]), quad_of(vf, l[3]),
			                              quad_of(vf, l[4]), quad_of(vf, l[5]), quad_of(vf, l[6]), quad_of(vf, l[7])};
			__m256 vx, vy, vz, vw;
			sph_transpose8(quad, &vx, &vy, &vz, &vw);
			sx = _mm256_add_ps(sx, _mm256_mul_ps(_mm256_sub_ps(vix, vx), _mm256_loadu_ps(g->gx)));
			sy = _mm256_add_ps(sy, _mm256_mul_ps(_mm256_sub_ps(viy, vy), _mm256_loadu_ps(g->gy)));
			sz = _mm256_add_ps(sz, _mm256_mul_ps(_mm256_sub_ps(viz, vz), _mm256_loadu_ps(g->gz)));
		}
		_mm_storeu_ps(t + RATE_T * q, fold8(_mm256_add_ps(_mm256_add_ps(sx, sy), sz)));
	}
}

__attribute__((target("avx2"))) static void correct_avx2(struct dfsph_work *wk, long i0, long cnt, float *t)
{
	const float *k = wk->k;
	for (long q = 0; q < cnt; ++q) {
		const __m256 vki = _mm256_set1_ps(k[i0 + q]);
		__m256 sx = _mm256_setzero_ps(), sy = sx, sz = sx;
		for (const dfsph_group *g = wk->g + wk->goff[i0 + q], *ge = wk->g + wk->goff[i0 + q + 1]; g < ge; ++g) {
			/* eight scalar loads: faster here than vgatherdps */
			const uint32_t *l = g->j2;
			const __m256 kj = _mm256_setr_ps(k_of(k, l[0]), k_of(k, l[1]), k_of(k, l[2]), k_of(k, l[3]),
			                                 k_of(k, l[4]), k_of(k, l[5]), k_of(k, l[6]), k_of(k, l[7]));
			const __m256 c = _mm256_add_ps(vki, kj);
			sx = _mm256_add_ps(sx, _mm256_mul_ps(c, _mm256_loadu_ps(g->gx)));
			sy = _mm256_add_ps(sy, _mm256_mul_ps(c, _mm256_loadu_ps(g->gy)));
			sz = _mm256_add_ps(sz, _mm256_mul_ps(c, _mm256_loadu_ps(g->gz)));
		}
		float *ti = t + CORR_T * q;
		_mm_storeu_ps(ti, fold8(sx));
		_mm_storeu_ps(ti + 4, fold8(sy));
		_mm_storeu_ps(ti + 8, fold8(sz));
	}
}
#endif

/* The wall sums of particle i: B_i (out[0..2]) and the hydrostatic sum
 * sum_b (g . (x_b - x_i)) m_b grad W(x_i - x_b) (out[3..5]). Four boundary
 * particles at a time (the last four padded with copies of the last one,
 * masked out), the same code for either path: most particles have none and
 * those at a wall a few, a small part of the pass. */
static void wall_sums(const grad_args *a, long i, float out[6])
{
	const sph_neighbors *nb = a->nb;
	const float *pi = a->pq + 4 * i;
	const uint32_t *blist = nb->bnbr + (size_t)i * nb->bcap;
	const uint32_t bcnt = nb->bcount[i];
#ifdef __SSE2__
	const __m128 vxi = _mm_set1_ps(pi[0]), vyi = _mm_set1_ps(pi[1]), vzi = _mm_set1_ps(pi[2]), vh = _mm_set1_ps(a->h),
	             veps2 = _mm_set1_ps(a->eps2), vrho0 = _mm_set1_ps(a->rho0), vsg = _mm_set1_ps(a->spiky_grad),
	             vgx = _mm_set1_ps(a->gx), vgy = _mm_set1_ps(a->gy), vgz = _mm_set1_ps(a->gz),
	             one = _mm_set1_ps(1.0f), zero = _mm_setzero_ps(), sign = _mm_set1_ps(-0.0f);
	__m128 s[6] = {zero, zero, zero, zero, zero, zero};
	for (uint32_t q = 0; q < bcnt; q += 4) {
		uint32_t l[4];
		for (uint32_t k = 0; k < 4; ++k)
			l[k] = blist[q + k < bcnt ? q + k : bcnt - 1];
		const __m128 in = _mm_castsi128_ps(_mm_cmpgt_epi32(_mm_set1_epi32((int)(bcnt - q)), _mm_setr_epi32(0, 1, 2, 3)));
		const __m128 rx = _mm_sub_ps(vxi, _mm_setr_ps(nb->bx[l[0]], nb->bx[l[1]], nb->bx[l[2]], nb->bx[l[3]])),
		             ry = _mm_sub_ps(vyi, _mm_setr_ps(nb->by[l[0]], nb->by[l[1]], nb->by[l[2]], nb->by[l[3]])),
		             rz = _mm_sub_ps(vzi, _mm_setr_ps(nb->bz[l[0]], nb->bz[l[1]], nb->bz[l[2]], nb->bz[l[3]]));
		/* Akinci: the wall at rest density */
		const __m128 mb =
			_mm_mul_ps(_mm_setr_ps(nb->bvol[l[0]], nb->bvol[l[1]], nb->bvol[l[2]], nb->bvol[l[3]]), vrho0);
		const __m128 r2 = _mm_add_ps(_mm_add_ps(_mm_mul_ps(rx, rx), _mm_mul_ps(ry, ry)), _mm_mul_ps(rz, rz));
		const __m128 r = _mm_sqrt_ps(r2), hr = _mm_sub_ps(vh, r);
		const __m128 ok = _mm_and_ps(in, _mm_and_ps(_mm_cmpgt_ps(r2, veps2), _mm_cmpgt_ps(hr, zero)));
		const __m128 rs = _mm_or_ps(_mm_and_ps(ok, r), _mm_andnot_ps(ok, one));
		const __m128 c = _mm_and_ps(ok, _mm_div_ps(_mm_mul_ps(_mm_mul_ps(_mm_mul_ps(mb, vsg), hr), hr), rs));
		s[0] = _mm_add_ps(s[0], _mm_mul_ps(c, rx));
		s[1] = _mm_add_ps(s[1], _mm_mul_ps(c, ry));
		s[2] = _mm_add_ps(s[2], _mm_mul_ps(c, rz));
		/* g . (x_b - x_i) */
		const __m128 gh = _mm_mul_ps(
			_mm_xor_ps(sign, _mm_add_ps(_mm_add_ps(_mm_mul_ps(vgx, rx), _mm_mul_ps(vgy, ry)), _mm_mul_ps(vgz, rz))), c);
		s[3] = _mm_add_ps(s[3], _mm_mul_ps(gh, rx));
		s[4] = _mm_add_ps(s[4], _mm_mul_ps(gh, ry));
		s[5] = _mm_add_ps(s[5], _mm_mul_ps(gh, rz));
	}
	for (int k = 0; k < 6; ++k)
		out[k] = sph_hsum4(s[k]);
#else
	float s[6][4] = {{0}};
	for (uint32_t q = 0; q < bcnt; ++q) {
		const uint32_t b = blist[q], l = q % 4;
		const float rx = pi[0] - nb->bx[b], ry = pi[1] - nb->by[b], rz = pi[2] - nb->bz[b];
		const float r2 = rx * rx + ry * ry + rz * rz;
		const float mb = nb->bvol[b] * a->rho0;
		const float r = sqrtf(r2), hr = a->h - r;
		const float c = r2 > a->eps2 && hr > 0 ? mb * a->spiky_grad * hr * hr / r : 0.0f;
		s[0][l] += c * rx;
		s[1][l] += c * ry;
		s[2][l] += c * rz;
		const float gh = -(a->gx * rx + a->gy * ry + a->gz * rz) * c;
		s[3][l] += gh * rx;
		s[4][l] += gh * ry;
		s[5][l] += gh * rz;
	}
	for (int k = 0; k < 6; ++k)
		out[k] = sph_sum4(s[k]);
#endif
}

/* The gradient pass's second loop: the walls' sums, h_i and 1 / D_i. */
static void grads_finish(dfsph_work *wk, long i0, long cnt, const float *t)
{
	/* a copy the stores below cannot alias: the constants stay in registers */
	const grad_args a = *wk->ga;
	for (long q = 0; q < cnt; ++q) {
		const long i = i0 + q;
		const float *ti = t + GRAD_T * q;
		const float sx = sph_sum4(ti), sy = sph_sum4(ti + 4), sz = sph_sum4(ti + 8), s2 = sph_sum4(ti + 12);
		float w[6] = {0, 0, 0, 0, 0, 0};
		if (a.nb->bcount[i]) /* most particles are away from the walls */
			wall_sums(&a, i, w);
		const float bx = w[0], by = w[1], bz = w[2];
		const float ir = a.pq[4 * i + 3]; /* 1 / rho_i */
		wk->h[i] = (dfsph_f4){-w[3] * ir, -w[4] * ir, -w[5] * ir, a.rho[i]};
		/* (S + 2B) . (S + B) + sum |G|^2, S = sum_j G_ij: the boundary term of
		 * the acceleration counts twice (pressure mirroring) */
		const float d = (sx + 2 * bx) * (sx + bx) + (sy + 2 * by) * (sy + by) + (sz + 2 * bz) * (sz + bz) + s2;
		wk->b[i] = (dfsph_f4){bx, by, bz, d > a.dmin ? 1.0f / d : 0.0f};
		if (wk->dsym) { /* the symmetric operator's: |S + 2B|^2 + sum |G|^2 */
			const float ds =
				(sx + 2 * bx) * (sx + 2 * bx) + (sy + 2 * by) * (sy + 2 * by) + (sz + 2 * bz) * (sz + 2 * bz) + s2;
			wk->dsym[i] = ds > a.dmin ? 1.0f / ds : 0.0f;
		}
	}
}

/* max(e, 0), 0 for NaN: without the explicit maxss the compiler made a
 * branch of it, mispredicted for about every other particle */
static inline float positive(float e)
{
#ifdef __SSE2__
	return _mm_cvtss_f32(_mm_max_ss(_mm_set_ss(e), _mm_setzero_ps()));
#else
	return e > 0 ? e : 0;
#endif
}

/* rate's second loop: Drho_i/Dt, the sweep's error and k_i. Four particles
 * at a time where SSE is (the scalar loop does the same per particle). */
static void rate_finish(dfsph_work *wk, const sweep_args *a, long i0, long cnt, const float *t)
{
	const float *bdiv = wk->ga->nb->bdiv; /* NULL while no wall moves */
	if (a->rate_only) {
		/* R_i(v) = sum_j (v_i - v_j) . G_ij + 2 (v_i . B_i - bdiv_i), the wall
		 * counted as in the projected sweeps */
		for (long q = 0; q < cnt; ++q) {
			const long i = i0 + q;
			const dfsph_f4 vi = wk->v[i], bi = wk->b[i];
			const float vb = (vi.x * bi.x + vi.y * bi.y + vi.z * bi.z) -
			                 (bdiv && a->rate_only == RATE_SIGNED ? bdiv[i] : 0.0f);
			wk->err[i] = sph_sum4(t + RATE_T * q) + (vb + vb);
		}
		return;
	}
	long q = 0;
#ifdef __SSE2__
	const __m128 vdt = _mm_set1_ps(a->dt), vrho0 = _mm_set1_ps(a->rho0), zero = _mm_setzero_ps(),
	             vinv = _mm_set1_ps(a->divergence ? a->inv_dt : a->inv_dt2), vom = _mm_set1_ps(DFSPH_OMEGA);
	for (; q + 4 <= cnt; q += 4) {
		const long i = i0 + q;
		__m128 s0 = _mm_loadu_ps(t + RATE_T * q), s1 = _mm_loadu_ps(t + RATE_T * (q + 1)),
		       s2 = _mm_loadu_ps(t + RATE_T * (q + 2)), s3 = _mm_loadu_ps(t + RATE_T * (q + 3));
		_MM_TRANSPOSE4_PS(s0, s1, s2, s3);
		__m128 vx, vy, vz, vw, bx, by, bz, bw;
		load4(wk->v + i, &vx, &vy, &vz, &vw);
		load4(wk->b + i, &bx, &by, &bz, &bw);
		/* the wall's part (v_i - v_b) . B_i: bdiv holds the moving walls'
		 * v_b part (sph.h), NULL while no wall moves */
		__m128 vb = _mm_add_ps(_mm_add_ps(_mm_mul_ps(vx, bx), _mm_mul_ps(vy, by)), _mm_mul_ps(vz, bz));
		if (bdiv)
			vb = _mm_sub_ps(vb, _mm_loadu_ps(bdiv + i));
		__m128 e;
		if (a->projected) {
			/* the wall's rate counted twice, as its force: the symmetric operator */
			const __m128 r = _mm_add_ps(_mm_add_ps(_mm_add_ps(s0, s1), _mm_add_ps(s2, s3)), _mm_add_ps(vb, vb));
			const __m128 res =
				a->divergence ? _mm_mul_ps(r, _mm_loadu_ps(wk->full + i))
				              : _mm_sub_ps(_mm_add_ps(_mm_setr_ps(wk->h[i].w, wk->h[i + 1].w, wk->h[i + 2].w, wk->h[i + 3].w),
				                                      _mm_mul_ps(vdt, r)),
				                           vrho0);
			/* k_i = max(k_i + omega res_i / (dt^n D'_i), 0); correct applies the change */
			const __m128 ks = _mm_loadu_ps(wk->ksum + i);
			const __m128 kn = _mm_max_ps(
				_mm_add_ps(ks, _mm_mul_ps(_mm_mul_ps(_mm_mul_ps(res, vom), vinv), _mm_loadu_ps(wk->dsym + i))), zero);
			_mm_storeu_ps(wk->k + i, _mm_sub_ps(kn, ks));
			/* |res| under pressure, the compression max(res, 0) without */
			const __m128 on = _mm_cmpgt_ps(kn, zero);
			e = _mm_or_ps(_mm_and_ps(on, _mm_andnot_ps(_mm_set1_ps(-0.0f), res)), _mm_andnot_ps(on, _mm_max_ps(res, zero)));
			if (a->divergence)
				e = _mm_mul_ps(e, vdt);
		} else if (a->divergence) {
			const __m128 r = _mm_add_ps(_mm_add_ps(_mm_add_ps(s0, s1), _mm_add_ps(s2, s3)), vb);
			const __m128 d = _mm_max_ps(r, zero);
			e = _mm_mul_ps(d, vdt);
			_mm_storeu_ps(wk->k + i, _mm_mul_ps(_mm_mul_ps(d, vinv), bw));
		} else {
			const __m128 r = _mm_add_ps(_mm_add_ps(_mm_add_ps(s0, s1), _mm_add_ps(s2, s3)), vb);
			const __m128 rho = _mm_setr_ps(wk->h[i].w, wk->h[i + 1].w, wk->h[i + 2].w, wk->h[i + 3].w);
			e = _mm_max_ps(_mm_sub_ps(_mm_add_ps(rho, _mm_mul_ps(vdt, r)), vrho0), zero);
			_mm_storeu_ps(wk->k + i, _mm_mul_ps(_mm_mul_ps(e, vinv), bw));
		}
		_mm_storeu_ps(wk->err + i, e);
	}
#endif
	for (; q < cnt; ++q) {
		const long i = i0 + q;
		const dfsph_f4 vi = wk->v[i], bi = wk->b[i];
		const float vb = (vi.x * bi.x + vi.y * bi.y + vi.z * bi.z) - (bdiv ? bdiv[i] : 0.0f);
		if (a->projected) {
			const float r = sph_sum4(t + RATE_T * q) + (vb + vb);
			const float res = a->divergence ? r * wk->full[i] : (wk->h[i].w + a->dt * r) - a->rho0;
			const float ks = wk->ksum[i];
			const float kn = positive(ks + ((res * DFSPH_OMEGA) * (a->divergence ? a->inv_dt : a->inv_dt2)) * wk->dsym[i]);
			wk->k[i] = kn - ks;
			const float e = kn > 0 ? fabsf(res) : positive(res);
			wk->err[i] = a->divergence ? e * a->dt : e;
			continue;
		}
		const float r = sph_sum4(t + RATE_T * q) + vb;
		if (a->divergence) {
			const float d = positive(r);
			wk->err[i] = d * a->dt;
			wk->k[i] = d * a->inv_dt * bi.w;
		} else {
			const float e = positive(wk->h[i].w + a->dt * r - a->rho0);
			wk->err[i] = e;
			wk->k[i] = e * a->inv_dt2 * bi.w;
		}
	}
}

/* correct's second loop: v*_i -= dt (sum_j (k_i + k_j) G_ij + 2 k_i B_i),
 * and k_i added to its sum. Four particles at a time where SSE is. */
static void correct_finish(dfsph_work *wk, const sweep_args *a, long i0, long cnt, const float *t)
{
	long q = 0;
#ifdef __SSE2__
	const __m128 vdt = _mm_set1_ps(a->dt), two = _mm_set1_ps(2.0f);
	for (; q + 4 <= cnt; q += 4) {
		const long i = i0 + q;
		const float *t0 = t + CORR_T * q, *t1 = t0 + CORR_T, *t2 = t1 + CORR_T, *t3 = t2 + CORR_T;
		__m128 f[3];
		for (int c = 0; c < 3; ++c) {
			__m128 l0 = _mm_loadu_ps(t0 + 4 * c), l1 = _mm_loadu_ps(t1 + 4 * c), l2 = _mm_loadu_ps(t2 + 4 * c),
			       l3 = _mm_loadu_ps(t3 + 4 * c);
			_MM_TRANSPOSE4_PS(l0, l1, l2, l3);
			f[c] = _mm_add_ps(_mm_add_ps(l0, l1), _mm_add_ps(l2, l3));
		}
		__m128 vx, vy, vz, vw, bx, by, bz, bw;
		load4(wk->v + i, &vx, &vy, &vz, &vw);
		load4(wk->b + i, &bx, &by, &bz, &bw);
		const __m128 ki = _mm_loadu_ps(wk->k + i), kb = _mm_mul_ps(two, ki); /* the boundary particles mirror k_i */
		vx = _mm_sub_ps(vx, _mm_mul_ps(vdt, _mm_add_ps(_mm_mul_ps(kb, bx), f[0])));
		vy = _mm_sub_ps(vy, _mm_mul_ps(vdt, _mm_add_ps(_mm_mul_ps(kb, by), f[1])));
		vz = _mm_sub_ps(vz, _mm_mul_ps(vdt, _mm_add_ps(_mm_mul_ps(kb, bz), f[2])));
		_MM_TRANSPOSE4_PS(vx, vy, vz, vw);
		_mm_storeu_ps(&wk->v[i].x, vx);
		_mm_storeu_ps(&wk->v[i + 1].x, vy);
		_mm_storeu_ps(&wk->v[i + 2].x, vz);
		_mm_storeu_ps(&wk->v[i + 3].x, vw);
		_mm_storeu_ps(wk->ksum + i, _mm_add_ps(_mm_loadu_ps(wk->ksum + i), ki));
	}
#endif
	for (; q < cnt; ++q) {
		const long i = i0 + q;
		const float *ti = t + CORR_T * q;
		const dfsph_f4 bi = wk->b[i];
		const float ki = wk->k[i], kb = 2 * ki; /* the boundary particles mirror k_i */
		wk->v[i].x -= a->dt * (kb * bi.x + sph_sum4(ti));
		wk->v[i].y -= a->dt * (kb * bi.y + sph_sum4(ti + 4));
		wk->v[i].z -= a->dt * (kb * bi.z + sph_sum4(ti + 8));
		wk->ksum[i] += ki;
	}
}

enum pass_kind { PASS_GRADIENTS, PASS_RATE, PASS_CORRECT };

/* A pass over all particles, the threads taking equal shares in order.
 * Each particle writes only its own values (rate its err and k, correct its
 * velocity: the others read k) from inputs no other particle of the pass
 * changes, so the result is the same for any thread count. (Tried: fusing a
 * correction with the next rates, rating a particle as soon as its
 * neighbours were corrected while its groups were in cache; the same bits,
 * but no faster: the passes are not bound by streaming the groups.) */
static void pass(dfsph_work *wk, enum pass_kind kind, const sweep_args *a, int threads)
{
	sums_fn *sums = kind == PASS_GRADIENTS ? wk->grads : kind == PASS_RATE ? wk->rate : wk->correct;
	const long n = wk->n;
#pragma omp parallel for num_threads(threads) schedule(static)
	for (int th = 0; th < threads; ++th) {
		float t[DFSPH_BLOCK * GRAD_T];
		for (long i0 = n * th / threads, hi = n * (th + 1) / threads; i0 < hi; i0 += DFSPH_BLOCK) {
			const long cnt = hi - i0 < DFSPH_BLOCK ? hi - i0 : DFSPH_BLOCK;
			sums(wk, i0, cnt, t);
			if (kind == PASS_GRADIENTS)
				grads_finish(wk, i0, cnt, t);
			else if (kind == PASS_RATE)
				rate_finish(wk, a, i0, cnt, t);
			else
				correct_finish(wk, a, i0, cnt, t);
		}
	}
}

/* Serial sum in row order: the same for any thread count. */
static double mean_of(const float *e, long n)
{
	double s = 0;
	for (long i = 0; i < n; ++i)
		s += e[i];
	return n > 0 ? s / (double)n : 0;
}

/* The conjugate gradient's vectors (see divergence_cg). */
typedef struct dfsph_cg {
	dfsph_f4 *u;    /* the velocity change of a direction: -dt grad p */
	float *p;       /* the search direction (a change of k) */
	float *r;       /* the residual on the active set */
	float *mask;    /* 1 on the active set, else 0 */
	float *scratch; /* the correct pass's sum of k, not kept */
} dfsph_cg;

/* The velocity solve's bulk: Jacobi-preconditioned conjugate gradients
 * (Hestenes & Stiefel 1952; Saad, "Iterative methods for sparse linear
 * systems", 2003, Alg. 9.1) on A k = R(v*), A = dt grad^T grad the
 * symmetric operator of the projected sweeps, restricted to the particles
 * that hold pressure (k_i > 0 from the warm start) or are compressing
 * (R_i > 0): there the unilateral constraint is an equality. Jacobi sweeps
 * shrink the column-wide error mode of N layers by about 1 - c / N^2 a
 * sweep, conjugate gradients by about 1 - c / N, so a deep column converges
 * in a number of products that grows with the depth, not its square. A
 * product A p is one correct pass onto a zero velocity (u = -dt grad p) and
 * one rate pass of u. The iteration stops when the mean |r_i| dt / rho0 is
 * at most max_divergence_error (the projected sweeps' measure) or when a
 * direction has no positive curvature. The particles whose k ends below 0
 * are then set to 0 (the projection), and the projected sweeps that follow
 * settle what the fixed set got wrong: particles that left or entered it.
 * Every sum is serial in row order: the same bits for any thread count. */
static int divergence_cg(dfsph_work *wk, dfsph_cg *cg, float rho0, float dt, int threads, int cap, bool density,
                         double tol, double *residual)
{
	const long n = wk->n;
	const sweep_args as = {dt, 1.0f / dt, 1.0f / (dt * dt), rho0, true, true, RATE_SIGNED};
	const sweep_args al = {dt, 1.0f / dt, 1.0f / (dt * dt), rho0, true, true, RATE_LINEAR};
	const double scale = (double)dt / ((double)rho0 * (double)n);
	pass(wk, PASS_RATE, &as, threads);
	double rz = 0, esum = 0;
	for (long i = 0; i < n; ++i) {
		/* the density solve: the rate that brings rho_i to rho0 in a step */
		const float res = density ? wk->err[i] + (wk->h[i].w - rho0) / dt : wk->err[i];
		const bool on = (density || wk->full[i] > 0) && (wk->ksum[i] > 0 || res > 0);
		cg->mask[i] = on ? 1.0f : 0.0f;
		cg->r[i] = on ? res : 0.0f;
		cg->p[i] = wk->dsym[i] * cg->r[i];
		rz += (double)cg->r[i] * cg->p[i];
		esum += fabsf(cg->r[i]);
	}
	*residual = esum * scale;
	int it = 0;
	dfsph_f4 *const v = wk->v;
	float *const k = wk->k, *const ksum = wk->ksum;
	while (*residual > tol && it < cap && rz > 0) {
		/* err = R(u), u = -dt grad p: the passes read and write wk's arrays */
		memset(cg->u, 0, (size_t)n * sizeof *cg->u);
		wk->v = cg->u;
		wk->k = cg->p;
		wk->ksum = cg->scratch;
		pass(wk, PASS_CORRECT, &as, threads);
		pass(wk, PASS_RATE, &al, threads);
		wk->v = v;
		wk->k = k;
		wk->ksum = ksum;
		double pq = 0;
		for (long i = 0; i < n; ++i)
			pq -= (double)cg->p[i] * (cg->mask[i] * wk->err[i]);
		if (!(pq > 0))
			break;
		const float alpha = (float)(rz / pq);
		double rz1 = 0;
		esum = 0;
		for (long i = 0; i < n; ++i) {
			v[i].x += alpha * cg->u[i].x;
			v[i].y += alpha * cg->u[i].y;
			v[i].z += alpha * cg->u[i].z;
			ksum[i] += alpha * cg->p[i];
			cg->r[i] += alpha * (cg->mask[i] * wk->err[i]);
			rz1 += (double)cg->r[i] * (wk->dsym[i] * cg->r[i]);
			esum += fabsf(cg->r[i]);
		}
		++it;
		*residual = esum * scale;
		const float beta = (float)(rz1 / rz);
		rz = rz1;
		for (long i = 0; i < n; ++i)
			cg->p[i] = wk->dsym[i] * cg->r[i] + beta * cg->p[i];
	}
	/* the projection: k_i < 0 back to 0, as one correction */
	bool neg = false;
	for (long i = 0; i < n; ++i) {
		k[i] = ksum[i] < 0 ? -ksum[i] : 0.0f;
		neg |= ksum[i] < 0;
	}
	if (neg)
		pass(wk, PASS_CORRECT, &as, threads);
	return it;
}

/* The velocity solve's stopping tolerance in water `depth` deep (m, the
 * hydrostatic head of the last step's largest pressure) for a kernel radius
 * h: the requested one down to DFSPH_DEPTH_REF h, and below that scaled by
 * (DFSPH_DEPTH_REF h / depth)^2. The operator's smallest eigenvalue, that of
 * the column-wide mode, falls relative to its diagonal as (h / depth)^2, so
 * a mean residual eps leaves that mode an error of eps (depth / h)^2: with
 * the tolerance scaled so, the pressure that carries the column is held to
 * the same fraction at any depth. */
static double divergence_tolerance(double tol, float h, double depth)
{
	const double ref = DFSPH_DEPTH_REF * (double)h;
	return depth > ref ? tol * (ref / depth) * (ref / depth) : tol;
}

/* The fluid's extent along gravity (m): the depth of water at rest, more
 * (so the solve is stricter) while parts of it fly or splash; 0 without
 * gravity. */
static double fluid_depth(eddy_world *w, eddy_vec3 g)
{
	const float *x = eddy__col(w, COL_X_), *y = eddy__col(w, COL_Y_), *z = eddy__col(w, COL_Z_);
	const double g1 = sqrt((double)g.x * g.x + (double)g.y * g.y + (double)g.z * g.z);
	if (!(g1 > 0) || !x || !y || !z || w->n == 0)
		return 0;
	double lo = INFINITY, hi = -INFINITY;
	for (size_t i = 0; i < w->n; ++i) {
		const double e = ((double)g.x * x[i] + (double)g.y * y[i] + (double)g.z * z[i]) / g1;
		lo = e < lo ? e : lo;
		hi = e > hi ? e : hi;
	}
	return hi - lo;
}

/* The velocity solve (divergence-free, on v*): projected sweeps until the
 * mean error (see rate_finish) times dt / rho0 is at most tol. */
static int divergence_solve(dfsph_work *wk, dfsph_cg *cg, const sph_dfsph *sd, float rho0, float dt, int threads,
                            double tol, double *residual)
{
	const sweep_args a = {dt, 1.0f / dt, 1.0f / (dt * dt), rho0, true, true, RATE_SWEEP};
	int it = 0, sweeps = 0;
	for (;;) {
		it += divergence_cg(wk, cg, rho0, dt, threads, sd->def.max_divergence_iterations - it, false, tol, residual);
		pass(wk, PASS_RATE, &a, threads);
		*residual = mean_of(wk->err, wk->n) / rho0;
		if ((sweeps >= DFSPH_SMOOTH && *residual <= tol) || it >= sd->def.max_divergence_iterations)
			break;
		pass(wk, PASS_CORRECT, &a, threads);
		++it;
		++sweeps;
	}
	return it;
}

/* Constant-density solve: sweeps until mean max(rho* - rho0, 0) / rho0 <= tol. */
static int density_solve(dfsph_work *wk, dfsph_cg *cg, const sph_dfsph *sd, float rho0, float dt, int threads,
                         double tol, double *residual)
{
	const sweep_args a = {dt, 1.0f / dt, 1.0f / (dt * dt), rho0, false, sd->def.divergence_solver, RATE_SWEEP};
	int it = 0;
	for (;;) {
		if (cg)
			it += divergence_cg(wk, cg, rho0, dt, threads, sd->def.max_iterations - it, true, tol, residual);
		pass(wk, PASS_RATE, &a, threads);
		*residual = mean_of(wk->err, wk->n) / rho0;
		if ((it >= DFSPH_MIN_SWEEPS && *residual <= tol) || it >= sd->def.max_iterations)
			break;
		pass(wk, PASS_CORRECT, &a, threads);
		++it;
	}
	return it;
}

static eddy_status step(eddy_world *w, eddy_system *s, const eddy_step_context *ctx)
{
	sph_dfsph *sd = s->data;
	sph_shared *sh = eddy__sph_find(w, s);
	if (!sh)
		return eddy__fail(w, EDDY_ERR_ORDER, "%s: needs sph_density before it (it builds the neighbour lists)", s->label);
	if (sd->frame != w->frame) {
		sd->frame = w->frame;
		sd->steps = sd->sweeps = sd->div_sweeps = sd->unconverged = 0;
		sd->residual = sd->worst = 0;
	}
	const sph_neighbors *nb = &sh->nb;
	const long n = nb->n < w->n ? (long)nb->n : (long)w->n;
	const float *vx = eddy__col(w, COL_VX), *vy = eddy__col(w, COL_VY), *vz = eddy__col(w, COL_VZ);
	const float *rho = eddy__col(w, COL_DENSITY);
	float *p = eddy__col(w, COL_PRESSURE);
	float *ax = eddy__col(w, COL_AX), *ay = eddy__col(w, COL_AY), *az = eddy__col(w, COL_AZ);
	const float dt = (float)ctx->dt, rho0 = sh->rho0;
	if (n == 0 || !(dt > 0))
		return EDDY_OK;
	if ((uint64_t)n > (uint64_t)INT32_MAX) /* the groups hold 2 j in 32 bits */
		return eddy__fail(w, EDDY_ERR_INVALID, "%s: too many particles (%ld)", s->label, n);

	dfsph_work wk;
	wk.n = n;
#if defined(SPH_AVX2)
	wk.grads = sd->avx2 ? grads_avx2 : grads_sse;
	wk.rate = sd->avx2 ? rate_avx2 : rate_sse;
	wk.correct = sd->avx2 ? correct_avx2 : correct_sse;
#elif defined(__SSE2__)
	wk.grads = grads_sse;
	wk.rate = rate_sse;
	wk.correct = correct_sse;
#else
	wk.grads = grads_scalar;
	wk.rate = rate_scalar;
	wk.correct = correct_scalar;
#endif
	const size_t un = (size_t)n;
	wk.goff = eddy__arena_alloc(&w->arena, (un + 1) * sizeof *wk.goff);
	if (!wk.goff)
		return eddy__fail(w, EDDY_ERR_NOMEM, "%s: out of scratch memory for %ld particles", s->label, n);
	wk.goff[0] = 0;
	for (long i = 0; i < n; ++i)
		wk.goff[i + 1] = wk.goff[i] + (nb->count[i] + 7) / 8;
	wk.g = eddy__arena_alloc(&w->arena, (wk.goff[n] ? wk.goff[n] : 1) * sizeof *wk.g);
	wk.owner = eddy__arena_alloc(&w->arena, (wk.goff[n] ? wk.goff[n] : 1) * sizeof *wk.owner);
	dfsph_f4 *block = eddy__arena_alloc(&w->arena, 3 * un * sizeof(dfsph_f4) + 5 * un * sizeof(float));
	if (!wk.g || !wk.owner || !block)
		return eddy__fail(w, EDDY_ERR_NOMEM, "%s: out of scratch memory for %ld particles", s->label, n);
	wk.b = block;
	wk.v = wk.b + un;
	wk.h = wk.v + un;
	wk.k = (float *)(wk.h + un);
	wk.ksum = wk.k + un;
	wk.err = wk.ksum + un;
	wk.kp = wk.err + un;
	wk.dsym = sd->def.divergence_solver ? wk.kp + un : NULL;
	dfsph_cg cg = {NULL, NULL, NULL, NULL, NULL};
	if (sd->def.divergence_solver) {
		cg.u = eddy__arena_alloc(&w->arena, un * sizeof(dfsph_f4) + 5 * un * sizeof(float));
		if (!cg.u)
			return eddy__fail(w, EDDY_ERR_NOMEM, "%s: out of scratch memory for %ld particles", s->label, n);
		cg.p = (float *)(cg.u + un);
		cg.r = cg.p + un;
		cg.mask = cg.r + un;
		cg.scratch = cg.mask + un;
		wk.full = cg.scratch + un;
	} else {
		wk.full = NULL;
	}
	for (long i = 0; i < n; ++i)
		for (size_t gi = wk.goff[i]; gi < wk.goff[i + 1]; ++gi)
			wk.owner[gi] = (uint32_t)i;

	const sph_kernel_consts kc = sh->k;
	const float dref = sh->mass * kc.spiky_grad * kc.h2; /* |G| scale */
	const eddy_vec3 g = w->def.gravity;
	const grad_args ga = {nb,  sh->pq, rho, kc.h, 1e-6f * kc.h2, sh->mass * kc.spiky_grad, rho0, kc.spiky_grad,
	                      g.x, g.y,    g.z, 1e-6f * dref * dref};
	wk.ga = &ga;
	pass(&wk, PASS_GRADIENTS, NULL, ctx->threads);
	memset(wk.ksum, 0, un * sizeof *wk.ksum);

	/* v* = v + dt (a + h) */
	for (long i = 0; i < n; ++i)
		wk.v[i] = (dfsph_f4){vx[i] + dt * (ax[i] + wk.h[i].x), vy[i] + dt * (ay[i] + wk.h[i].y),
		                     vz[i] + dt * (az[i] + wk.h[i].z), 0};
	int div_it = 0;
	double div_residual = 0, dtol = sd->def.max_divergence_error, ddtol = sd->def.max_density_error;
	if (sd->def.divergence_solver) {
		/* the velocity solve, from last step's k (a correction with it) */
		float *kcol = eddy__col(w, sd->kcol);
		for (long i = 0; i < n; ++i) {
			wk.full[i] = rho[i] >= DFSPH_SURFACE * rho0 ? 1.0f : 0.0f;
			wk.k[i] = kcol[i] > 0 && wk.full[i] > 0 ? kcol[i] : 0.0f;
		}
		const double depth = fluid_depth(w, g);
		dtol = divergence_tolerance(sd->def.max_divergence_error, kc.h, depth);
		ddtol = divergence_tolerance(sd->def.max_density_error, kc.h, depth);
		const sweep_args wa = {dt, 1.0f / dt, 1.0f / (dt * dt), rho0, true, true, RATE_SWEEP};
		pass(&wk, PASS_CORRECT, &wa, ctx->threads);
		div_it = divergence_solve(&wk, &cg, sd, rho0, dt, ctx->threads, dtol, &div_residual);
		const bool capped = div_it >= sd->def.max_divergence_iterations &&
		                    div_residual > DFSPH_FAIL_CAPPED_ERROR * dtol;
		sd->capped = capped ? sd->capped + 1 : 0;
		if (sd->capped >= DFSPH_FAIL_CAPPED) {
			long wi = 0;
			for (long i = 0; i < n; ++i)
				wi = wk.err[i] > wk.err[wi] ? i : wi;
			return eddy__fail(w, EDDY_ERR_NUMERIC,
			                  "%s: the velocity solve did not converge at step %lld: mean error %.3g after %d "
			                  "iterations in %d steps in a row (max_divergence_error %g), worst at particle %ld "
			                  "(%.3g); the water may be too deep for it: raise max_divergence_iterations or lower "
			                  "the world's cfl",
			                  s->label, (long long)ctx->step, div_residual, div_it, sd->capped,
			                  (double)sd->def.max_divergence_error, wi, wk.err[wi] / rho0);
		}
		memcpy(kcol, wk.ksum, un * sizeof *kcol);
		memcpy(wk.kp, wk.ksum, un * sizeof *wk.kp);
		memset(wk.ksum, 0, un * sizeof *wk.ksum);
	} else {
		memset(wk.kp, 0, un * sizeof *wk.kp);
	}
	float *kdcol = sd->def.divergence_solver ? eddy__col(w, sd->kdcol) : NULL;
	if (kdcol) {
		/* the density solve, from last step's k likewise */
		for (long i = 0; i < n; ++i)
			wk.k[i] = kdcol[i] > 0 ? kdcol[i] : 0.0f;
		const sweep_args wa = {dt, 1.0f / dt, 1.0f / (dt * dt), rho0, false, true, RATE_SWEEP};
		pass(&wk, PASS_CORRECT, &wa, ctx->threads);
	}

	double residual = 0;
	const int it = density_solve(&wk, sd->def.divergence_solver ? &cg : NULL, sd, rho0, dt, ctx->threads, ddtol, &residual);
	/* the particle the solve left furthest off (the last sweep's errors) */
	long worst = 0;
	for (long i = 0; i < n; ++i) {
		wk.kp[i] += wk.ksum[i];
		worst = wk.err[i] > wk.err[worst] ? i : worst;
	}
	const double worst_err = wk.err[worst] / rho0;
	if (kdcol)
		memcpy(kdcol, wk.ksum, un * sizeof *kdcol);

	/* a += (v* - (v + dt a)) / dt; p = k rho^2 */
	const float inv_dt = 1.0f / dt;
	long bad = -1;
	for (long i = 0; i < n; ++i) {
		const float ux = (wk.v[i].x - (vx[i] + dt * ax[i])) * inv_dt, uy = (wk.v[i].y - (vy[i] + dt * ay[i])) * inv_dt,
		            uz = (wk.v[i].z - (vz[i] + dt * az[i])) * inv_dt;
		ax[i] += ux;
		ay[i] += uy;
		az[i] += uz;
		p[i] = wk.kp[i] * wk.h[i].w * wk.h[i].w / sh->grad_cal;
		if (bad < 0 && !(isfinite(ux) && isfinite(uy) && isfinite(uz) && isfinite(p[i])))
			bad = i;
	}
	if (bad >= 0)
		return eddy__fail(w, EDDY_ERR_NUMERIC,
		                  "%s: non-finite pressure acceleration at step %lld, particle %ld (density %g kg/m^3, %u neighbours)",
		                  s->label, (long long)ctx->step, bad, (double)rho[bad], nb->count[bad]);

	sd->steps++;
	sd->sweeps += it;
	sd->div_sweeps += div_it;
	sd->unconverged += (it >= sd->def.max_iterations && residual > sd->def.max_density_error) ||
	                   (div_it >= sd->def.max_divergence_iterations && div_residual > sd->def.max_divergence_error);
	sd->residual = residual > sd->residual ? residual : sd->residual;
	sd->worst = worst_err > sd->worst ? worst_err : sd->worst;
	eddy_world_publish_text(w, "solver", "dfsph");
	eddy_world_publish(w, "iterations", (double)sd->sweeps / (double)sd->steps);
	eddy_world_publish(w, "residual", sd->residual);
	if (sd->def.divergence_solver)
		eddy_world_publish(w, "divergence_iterations", (double)sd->div_sweeps / (double)sd->steps);
	eddy_world_publish(w, "unconverged", (double)sd->unconverged);
	eddy_world_publish(w, "residual_max", sd->worst);
	if (!(residual <= DFSPH_FAIL_ERROR) || !(worst_err <= DFSPH_FAIL_PARTICLE))
		return eddy__fail(w, EDDY_ERR_NUMERIC,
		                  "%s: did not converge at step %lld: mean density error %.3g after %d iterations "
		                  "(max_density_error %g), particle %ld off by %.3g; lower the world's cfl or raise "
		                  "max_iterations",
		                  s->label, (long long)ctx->step, residual, it, (double)sd->def.max_density_error, worst,
		                  worst_err);
	return EDDY_OK;
}

static double limit(eddy_world *w, eddy_system *s, const char **reason)
{
	const sph_shared *sh = eddy__sph_find(w, s);
	*reason = "velocity";
	const float *vx = eddy__col(w, COL_VX), *vy = eddy__col(w, COL_VY), *vz = eddy__col(w, COL_VZ);
	if (!sh || !vx || !vy || !vz)
		return INFINITY;
	float v2 = 0;
	for (size_t i = 0; i < w->n; ++i) {
		const float q = vx[i] * vx[i] + vy[i] * vy[i] + vz[i] * vz[i];
		v2 = q > v2 ? q : v2;
	}
	const double lv = v2 > 0 ? (double)sh->h / sqrt((double)v2) : INFINITY;
	const eddy_vec3 g = w->def.gravity;
	const double g1 = sqrt((double)g.x * g.x + (double)g.y * g.y + (double)g.z * g.z);
	double la = g1 > 0 ? DFSPH_GRAVITY_LIMIT * sqrt((double)sh->h / g1) : INFINITY;
	const sph_dfsph *sd = s->data;
	if (g1 > 0 && sd->def.divergence_solver) {
		/* deeper than DFSPH_DEPTH_REF h: dt <= (that) sqrt(DFSPH_DEPTH_REF h / H) */
		const double H = fluid_depth(w, g), ref = DFSPH_DEPTH_REF * (double)sh->h;
		if (H > ref)
			la *= sqrt(ref / H);
	}
	if (la < lv)
		*reason = "gravity";
	return la < lv ? la : lv;
}

const eddy_system_vtable eddy__kind_sph_dfsph = {
	.name = "sph_dfsph",
	.requires = EDDY_CAP_SPH_NEIGHBORS,
	/* the implicit solve replaces that force: both would count the pressure twice */
	.excludes = EDDY_CAP_SPH_EOS_FORCE,
	.step = step,
	.limit = limit,
	/* ax ay az are every force's: order hints for them name gravity alone */
	.default_writes = no_hint_writes,
};

eddy_system_id eddy_add_sph_dfsph(eddy_world *w, const eddy_sph_dfsph_def *def)
{
	const char *sys = "sph_dfsph";
	if (!eddy__add_args(w, def, sys))
		return EDDY_NULL_SYSTEM;
	if (!eddy__check_positive(w, sys, "max_density_error", def->max_density_error) ||
	    !eddy__check_range(w, sys, "max_density_error", def->max_density_error, 0, 0.1) ||
	    !eddy__check_positive(w, sys, "max_divergence_error", def->max_divergence_error) ||
	    !eddy__check_range(w, sys, "max_divergence_error", def->max_divergence_error, 0, 1))
		return EDDY_NULL_SYSTEM;
	if (def->max_iterations < 2 || def->max_iterations > 10000) {
		eddy__fail(w, EDDY_ERR_INVALID, "%s: 'max_iterations' must be between 2 and 10000 (got %d)", sys,
		           def->max_iterations);
		return EDDY_NULL_SYSTEM;
	}
	if (def->max_divergence_iterations < 1 || def->max_divergence_iterations > 10000) {
		eddy__fail(w, EDDY_ERR_INVALID, "%s: 'max_divergence_iterations' must be between 1 and 10000 (got %d)", sys,
		           def->max_divergence_iterations);
		return EDDY_NULL_SYSTEM;
	}
	sph_dfsph *sd = calloc(1, sizeof *sd);
	if (!sd)
		return eddy__fail(w, EDDY_ERR_NOMEM, "%s: out of memory", sys), EDDY_NULL_SYSTEM;
	sd->def = *def;
	sd->frame = -1;
#ifdef SPH_AVX2
	sd->avx2 = sph_use_avx2();
#endif
	if (!def->divergence_solver) /* the warm starts are the velocity solve's */
		return eddy__add_system(w, &eddy__kind_sph_dfsph, sd, dfsph_reads, dfsph_writes);
	/* the warm starts' state columns (shared by the sph_dfsph systems of a
	 * world: each writes its own fluid's rows) */
	const char *names[2] = {DFSPH_K_COLUMN, DFSPH_KD_COLUMN};
	int *cols[2] = {&sd->kcol, &sd->kdcol};
	for (int c = 0; c < 2; ++c) {
		*cols[c] = eddy_world_find_column(w, names[c]);
		if (*cols[c] < 0)
			*cols[c] = eddy_world_declare_column(w, names[c], EDDY_DOMAIN_PARTICLE, EDDY_F32, EDDY_STATE, "m^5/(kg s^2)");
		if (*cols[c] < 0) {
			free(sd);
			return EDDY_NULL_SYSTEM;
		}
	}
	/* the lists above plus the two state columns, -1 moved to the end */
	const int nr = (int)(sizeof dfsph_reads / sizeof dfsph_reads[0]) - 1,
	          nw = (int)(sizeof dfsph_writes / sizeof dfsph_writes[0]) - 1;
	int reads[sizeof dfsph_reads / sizeof dfsph_reads[0] + 2], writes[sizeof dfsph_writes / sizeof dfsph_writes[0] + 2];
	memcpy(reads, dfsph_reads, sizeof dfsph_reads);
	memcpy(writes, dfsph_writes, sizeof dfsph_writes);
	reads[nr] = writes[nw] = sd->kcol;
	reads[nr + 1] = writes[nw + 1] = sd->kdcol;
	reads[nr + 2] = writes[nw + 2] = -1;
	return eddy__add_system(w, &eddy__kind_sph_dfsph, sd, reads, writes);
}
