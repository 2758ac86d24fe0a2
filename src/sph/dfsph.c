/* SPDX-License-Identifier: MIT */
/* sph_dfsph: implicit SPH pressure, the divergence-free SPH of Bender &
 * Koschier, in place of sph_pressure: each step solves for the pressure that
 * keeps the rest density; dt is limited by the flow, not by a speed of sound.
 *
 * Reads: x y z vx vy vz density ax ay az, sph_density's lists. Writes:
 * pressure, ax ay az (accumulated: it runs after the other forces, before
 * integrate), and with shift > 0 x y z; with the divergence solver also its
 * state columns dfsph_k dfsph_kd, the solves' warm starts (below).
 *
 * With G_ij = m grad W_spiky(x_i - x_j) (the poly6 gradient vanishes at r = 0
 * and lets a tank at rest cluster), S_i = sum_j G_ij, boundary particles of
 * mass m_b = V_b rho0 (Akinci et al.), B_i = sum_b m_b grad W(x_i - x_b),
 * k_i = p_i / rho_i^2, and bdiv_i the moving colliders' part (sph.h):
 *   Drho_i/Dt = sum_j (v_i - v_j) . G_ij + v_i . B_i - bdiv_i
 *   a_i^p     = -sum_j (k_i + k_j) G_ij - 2 k_i B_i + h_i
 *   h_i       = -(1/rho_i) sum_b (g . (x_b - x_i)) m_b grad W(x_i - x_b)
 * The boundary particles mirror the pressure (p_b = p_i: with one k_i a wall
 * could not hold a particle whose neighbourhood is full, where S_i + B_i ~ 0)
 * plus Adami et al.'s hydrostatic part p_b - p_i = rho_i g . (x_b - x_i), h_i.
 * Walls do not pull. A particle with no pressure (with the divergence
 * solver: its k of the last step, the warm starts' sum, <= 0; without it:
 * rho_i <= rho0, as the cold solve makes pressure only from compression)
 * whose v + dt a points away from its walls (cosine with -B_i above
 * DFSPH_LEAVE) is leaving them: its walls' p_b is held at >= 0 (h_i from
 * the walls below its level only: p_i = 0) and it takes no part in the
 * velocity solve, whose equality would otherwise hold it to the wall with a
 * k < 0 mirrored onto the wall. Before, water released under a lid fell at
 * 0.75 of free fall over 0.1 s (the cold solve 0.92), in zero gravity a
 * block leaving a lid at 0.5 m/s was pulled back to 0.58 of it, and a dam
 * break's splash hung from its tank's lid for seconds
 * (tests/test_stress_sph_solids.c). Along a wall (cosine under DFSPH_LEAVE)
 * or under pressure a particle stays held as before: the still columns
 * start with k = 0 everywhere, and their side walls must carry them. A
 * particle whose walls move away from it (bdiv_i > 0: colliders) leaves them
 * whenever its rate towards them is negative, whatever its pressure: a wall
 * cannot pull water after it, and its own pressure, not the wall, must make
 * it follow (a paddle pulled back at 3 m/s from a pool dragged its face
 * along: the front 0.06 m out at 50 ms where the released column's reaches
 * 0.19; tests/test_physics.c).
 * A step sets v* = v + dt (a + h), solves for k by corrections that move v*
 * by dt a^p of a change of k, adds (v* - (v + dt a)) / dt to a and writes
 * p_i = k_i rho_i^2 / grad_cal (k summed over the solves; see sph_pressure).
 *
 * The divergence solver (the default) runs the paper's two solves,
 *   velocity:  R_i(v*) = 0,   density:  rho_i + dt R_i(v*) = rho0,
 *   R_i(v) = sum_j (v_i - v_j) . G_ij + 2 (v_i . B_i - bdiv_i),
 * the wall counted twice as in the force, so that a change of k moves the
 * predicted density by -(A k)_i, A = dt^2 grad^T grad symmetric positive
 * semi-definite with diagonal dt^2 D'_i, D'_i = |S_i + 2 B_i|^2 + sum_j
 * |G_ij|^2 (on the true rate A is not symmetric, and Jacobi sweeps can
 * diverge in a deep column). Each solve starts from its k of the last step
 * (with hydrostatic_start, when no particle has one, the velocity solve from
 * the pressure of water released at rest: dfsph_warm.c; the density solve's
 * k is then about 0), the velocity solve's less the density solve's last
 * change of k: the density solve's correction of a step leaves the velocity
 * field a divergence -A (its change of k) that the next velocity solve, its
 * tolerance some hundred times tighter, must take back, and that change is
 * known. Started from its own k alone, most of the velocity solve's work in
 * a settling block was that (the warm start's mean error 10-15 times the
 * tolerance against about 1.6 with the density solve's change left out).
 * Then the solve runs conjugate gradients (divergence_cg), then relaxed
 * Jacobi sweeps (Ihmsen et al.) on the residual res_i (the velocity solve's
 * R_i where rho_i >= DFSPH_SURFACE rho0, else 0; the density solve's
 * predicted rho_i - rho0),
 *   k_i <- k_i + omega res_i / (dt^n D'_i),   omega = DFSPH_OMEGA,
 * n = 1 for the velocity solve, 2 for the density one. The density solve is
 * projected (k_i >= 0, its error |res_i| where k_i > 0, else max(res_i,
 * 0)): it removes compression and never pulls. The velocity solve is an
 * equality on its particles, k of either sign, its error |res_i|: a
 * particle below DFSPH_SURFACE rho0 (the free surface's outermost) takes
 * no part, so the surface is not pulled apart from the bulk's side. With
 * k >= 0 there too, a deep column's solve stalled: near the floor its k has
 * a particle-scale roughness as large as k itself, each projection of the
 * negatives (thousands a step) raised the mean error 5-35x, and the
 * conjugate gradients began again (a 215-layer column: 97.5 velocity
 * iterations a step against 29 as an equality; a 1M block's first two
 * steps 387 against 66; README, Measurements). max_divergence_error must be well below
 * max_density_error, or the water compresses by it every step. A solve stops
 * once the mean error / rho0 (the velocity solve's |R_i| dt, the density
 * solve's predicted compression) is at most its tolerance times
 * depth_scale^2, after at least DFSPH_SMOOTH sweeps (velocity) or one
 * iteration (density), or at its cap: the paper's average errors (2017, Alg.
 * 2-3), tightened with the depth D because a mean residual eps leaves the
 * column-wide mode an error of eps (D / h)^2; the density solve also not
 * before every particle's predicted compression is at most
 * DFSPH_MAX_COMPRESSION (a mean over a jet's many under-dense particles
 * hides the few where it lands). The velocity solve's
 * conjugate gradients stop, in addition, only once the column-scale error
 * is small: the signed residual averaged over cubes of a few h
 * (block_error), where the particle-scale part, which dominates the mean
 * |R_i|, averages out and a smooth error keeps its size (a smooth error has
 * a small residual next to a rough one of the same size, and what a coarse
 * grid sees of it is the restricted residual: Briggs, Henson & McCormick),
 * its root mean square at most DFSPH_BLOCK_TOL max_divergence_error
 * depth_scale. Its depth rule: a residual rate beta (dt / rho0) coherent
 * over a column D deep moves its top at beta D / dt, and with the gravity
 * limit's dt that is beta (D / h) / (0.4 cfl) sqrt(g D), so beta ~ h / D
 * holds the column to the same fraction of sqrt(g D) at any depth. With
 * the warm start above and the mean alone, the conjugate gradients often
 * did not run at all (the warm start within tolerance, two sweeps), and
 * still water 20 layers deep moved at 0.043 sqrt(g D) (README): a cluster
 * of a few particles near the floor, the layers' mean vertical speed below
 * 1e-4 of it, so the rule is a bound on errors at the scale of a few h as
 * much as on the whole column's; what it bought is measured, not derived.
 * Tighter rules do not bring a deep column to
 * rest sooner: what moves it then is its particle arrangement relaxing
 * under the pressure force, which the shift takes over.
 *
 * Without it the density solve runs alone, cold, with the paper's sweeps that
 * only add pressure, on the true wall rate and D_i = (S_i + 2 B_i) . (S_i +
 * B_i) + sum_j |G_ij|^2, until the mean compression is at most
 * max_density_error (cheaper; it holds still water some 10 layers deep):
 *   k_i += max(beta (rho_i - rho0) + dt Drho_i/Dt, 0) / (dt^2 D_i)
 * The paper's beta = 1 removes in one step the compression a particle
 * already has, which leaves it moving at about (rho_i / rho0 - 1) h / dt:
 * the smaller the step, the faster the particles it throws where a jet
 * lands or a lattice settles. Here that part is a soft constraint (Catto,
 * "Soft constraints", 2011; Box2D's soft step): beta = dt / (dt + tau), the
 * error reduction of a spring and damper whose damping over stiffness is
 * tau, so the velocity is about (rho_i / rho0 - 1) h / (dt + tau), bounded
 * as dt shrinks, while the flow into the particle (dt Drho_i/Dt) is still
 * removed whole. tau = DFSPH_SOFT_TIME sqrt(h / |g|), gravity's time over
 * the kernel radius (0 without gravity: the paper's rule). The sweeps'
 * error is the residual over beta, so the compression carried from step to
 * step settles at about the tolerance, as with beta = 1.
 *
 * Particle shifting (shift > 0, 0.02 by default; Xu et al. 2009, Lind et
 * al. 2012): after the solves a particle moves by dr_i = -shift h^2 grad C_i,
 * grad C_i = sum_j (m / rho_j) grad W_ij the gradient of the particle
 * concentration (the spiky gradient of G_ij; Lind's Fickian shift with D =
 * shift h^2 a step), its velocity kept, so no momentum is made. A uniform
 * pressure pushes a particle by about -2 k rho0 grad C: at depth, where k is
 * large, the emitted simple cubic lattice is unstable under the spiky
 * gradient and relaxed in bursts of kinetic energy; the shift moves the
 * particles down the same gradient at no speed, and the arrangement settles
 * before the pressure throws it. With the depth-scaled step (dt ~ 1 /
 * sqrt(depth)) both rates scale alike, so one coefficient serves every
 * depth. The volumes m / rho_j (Lind's) make grad C vanish to first order in
 * a smoothly compressed fluid, so the shift does not follow the solves'
 * residual compression. Only a particle whose kernel sum, and all its
 * neighbours', is at least DFSPH_SHIFT_SURFACE rho0 shifts: at the free
 * surface the truncated neighbourhood reads as a gradient outwards (Lind
 * et al. shift only tangentially there). With a wall within h a particle
 * shifts along the wall only: grad C_i takes the walls' volumes too
 * (sum_b V_b grad W(x_i - x_b) = B_i / rho0), and its part along each
 * wall normal is removed (the normals: wall_normals, one beside a face,
 * two at an edge, three at a corner; a box's walls only: beside a
 * collider's particles nothing shifts, see shift). Along the wall the force is -2 k_i
 * (S_i + B_i) for a uniform k, the gradient of that concentration, so the
 * shift again moves the particle where the pressure would push it, at no
 * speed; without the walls' volumes the along-wall part fought the wall
 * lattice (still water 10-40 layers read up to 0.052 sqrt(gD), against
 * 0.018 with them). Across the wall the force's balance (the wall counted
 * twice, h_i) is not grad C = 0, so a shift across it fights the solve
 * every step (with the whole grad C it damped the slosh by 20-40%); and
 * with no shift beside a wall a bottom-layer particle over a wall particle
 * of the floor slid along it as from an unstable equilibrium (20 layers,
 * cfl 0.4, 0.031 sqrt(gD) at 2.7 s). Lind's Taylor correction of the
 * velocity is left out: it makes momentum, and did not change the slosh's
 * damping within its resolution.
 * The volume: as grad C_i ~ S_i / rho_i and the kernel sums' total changes
 * by 2 sum_i dr_i . S_i to first order, a shift is close to a descent on
 * sum_i rho_i: it lowers the kernel sums, and where the solves do not push
 * them back (the density solve's k >= 0: fluid below rho0) the arrangement
 * keeps the lower sum.
 * Over seconds that is an arrangement's sum more than a volume (a still
 * pool 15 layers deep read 0.2% less mean density at the same level), but
 * it never stops: a pool at rest 10 layers deep rose 1.8% in 40 s and 3.9%
 * in 150 s, still rising, its energy with it, and faster per second at
 * finer spacing (the shift is per step). So a particle shifts only while
 * its kernel sum is at least DFSPH_SHIFT_FLOOR rho0: the thinning stops
 * there (that pool +0.9% at 40 s, then level: +0.91% at 60 s; 5 mm, 10
 * and 20 layers, +0.89% and +0.69%). A floor of 0.995 held it to +0.3%
 * but the 5 mm slosh's period read -3.24%, past its 3% (-2.88% at 0.99,
 * -2.85% without a floor). Held at max_density_error (1e-3), the bulk of still
 * water, which sits 0.2-0.3% under rho0, hardly shifted: at 40 layers 9%
 * of the particles a step instead of 48%, and the column's last speed rose
 * from 0.010 to 0.018 sqrt(gD) (cfl 0.4).
 *
 * The pairs: in a small fluid the gradient pass stores each pair's row and
 * G_ij in groups of eight (16 B a pair, some 470 B a particle), which the
 * sweeps stream; beyond DFSPH_STORE_BYTES nothing is stored per pair and
 * each pass over the pairs (every sweep, correction and operator product)
 * recomputes G_ij from the positions sph_density saw (sph_shared's pq, one
 * 16-byte gather per neighbour) and the packed exact lists, read in groups
 * of eight. Either way the last group is padded with the particle itself
 * (r = 0 gives G = 0: exact zeros in every sum, no scalar tail, no mask),
 * and as the positions do not change during the solves both ways give the
 * same bits. Stored pairs that outgrow the cache are streamed from memory
 * by every sweep; recomputed, a pair costs a gather, a square root and a
 * division and reads 2 B of list.
 *
 * Published per frame: solver = "dfsph", iterations and divergence_iterations
 * (the solves' mean per step), residual (largest final mean density error of
 * a step), residual_max (... of one particle, / rho0), unconverged (steps in
 * which a solve stopped at its cap above its tolerance). Limits on dt (times
 * the CFL number): h / max|v| and DFSPH_GRAVITY_LIMIT sqrt(h / |g|), the
 * latter with the divergence solver times sqrt(depth_scale).
 *
 * Sources: Bender & Koschier, "Divergence-free smoothed particle
 * hydrodynamics", SCA 2015 (eqs. 8-9, 12, Alg. 1-3, warm start), and TVCG
 * 2017; Hestenes & Stiefel 1952 and Saad 2003 (Alg. 9.1: CG); Ihmsen et al.,
 * "Implicit incompressible SPH", TVCG 2014; Akinci et al., SIGGRAPH 2012;
 * Adami, Hu & Adams, JCP 2012 (eq. 27); Briggs, Henson & McCormick, "A
 * multigrid tutorial", SIAM 2000 (ch. 2-3: smooth error and its residual);
 * Golub & Van Loan, "Matrix computations" (sec. 8.5: the Jacobi method);
 * Xu, Stansby & Laurence, JCP 228,
 * 2009, and Lind, Xu, Stansby & Rogers, JCP 231, 2012 (particle shifting). */
#include "dfsph_coarse.h"
#include "dfsph_warm.h"
#include "simd.h"
#include "sph.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* The relaxation of the symmetric operator's Jacobi sweeps: the largest eigenvalue of
 * D'^-1 A is near 4 (full neighbourhoods plus the doubled wall), so sweeps
 * with omega above 0.5 can grow. */
#define DFSPH_OMEGA 0.5f

/* A particle leaves its walls (wall_sums) when v + dt a points away from
 * them, its cosine with -B_i above this: along a wall (a side wall under
 * gravity, at rest) it stays held. */
#define DFSPH_LEAVE 0.1f

/* The most bytes of stored pairs (dfsph_group, 16 bytes a pair, about 470
 * a particle): some 35k particles. Measured on one thread against storing
 * every pair: recomputing G_ij in every pass takes 1.7x the step's time at
 * 5k particles, 0.87-1.24x at 30k (loaded host) and 0.75-0.91x at 100k,
 * where the stored pairs no longer fit the cache; at 1M it saves 510 bytes
 * a particle. */
#define DFSPH_STORE_BYTES (16u << 20)

typedef struct dfsph_vec4 {
	float x, y, z, w;
} dfsph_vec4;

/* Eight pairs of one particle, as the gradient pass found them: the rows
 * (the last group's padding the particle itself) and G_ij by component. */
typedef struct dfsph_group {
	uint32_t j[8];
	float gx[8], gy[8], gz[8];
} dfsph_group;

/* A step's inputs and scratch (the arrays in the world's arena, n each). */
typedef struct dfsph_work {
	long n;
	float dt;   /* s */
	float beta; /* the cold density solve's share of the compression already there it removes (header) */
	int threads;
	void (*block)(const void *pass, long i0, long cnt); /* the passes on the chosen SIMD back-end */
	const sph_shared *sh;
	const float *rho;             /* kg/m^3, the density column */
	eddy_vec3 gravity;            /* m/s^2 */
	const float *bdiv;            /* the moving walls' part of the rate (sph.h); NULL while none moves
	                               * and in the operator's product, which is linear */
	const float *kprev[2];        /* the divergence solver's warm starts (their sum about the last
	                               * step's k); NULL without them */
	const float *vel[3], *acc[3]; /* v and a before the solve (wall_sums); NULL in the probe */
	/* B_i, and w = 1 / D_i (0 where D_i is negligible) for the paper's
	 * sweeps; the divergence solver, which does not use D_i, keeps there
	 * from its velocity solve on 1 where rho_i >= DFSPH_SURFACE rho0, else 0
	 * (the velocity solve's particles) */
	dfsph_vec4 *b;
	dfsph_vec4 *v; /* v*_i (w unused: a neighbour's velocity is one quad) */
	/* One array, three lives (the peak is the solves'): from the gradient
	 * pass until v* is set, the walls' hydrostatic push h_i (m/s^2); in the
	 * conjugate gradients the velocity change of a direction, -dt grad p;
	 * after the solves, with the shift, grad C_i = sum_j G_ij / rho_j (1/m)
	 * and w = max_j 1 / rho_j */
	dfsph_vec4 *u;
	float *dsym; /* 1 / D'_i, the symmetric operator's diagonal (0 likewise) */
	float *k;    /* the k_i a correction applies */
	float *ksum; /* the sum of k_i over the corrections: the current solve's k (with its warm start) */
	float *err;  /* per particle: the error the sweep measured, or R_i(v) */
	/* the conjugate gradients' (divergence_cg) */
	float *p;                /* the search direction (a change of k): k's array, which the sweeps
	                          * use only between the calls */
	float *r;                /* the residual on the active set */
	uint8_t *mask;           /* 1 on the active set, else 0 */
	struct dfsph_sums *part; /* per DFSPH_SUM_CHUNK rows: the conjugate gradients' and sweeps' partial sums */
	/* with few pairs (DFSPH_STORE_BYTES): the pairs in groups of eight,
	 * particle i's from gs + goff[i]; NULL: every pass reads the lists and
	 * recomputes G_ij */
	struct dfsph_group *gs;
	uint32_t *goff;
	eddy_arena *coarse;  /* non-NULL: the CG adds the coarse level (dfsph_coarse.c) in this arena */
	double coarse_scale; /* its scale s, measured at the step's first solve */
	/* the blocks of the column-scale error (block_error): cubes of side 1 / binv
	 * from borg, bdim of them along each axis, their sums of r and counts */
	float borg[3], binv;
	int bdim[3];
	double *bsum;
	float *bcnt;
} dfsph_work;

/* A pass over all particles: gradients, rate or correct below. */
enum dfsph_pass_kind { PASS_GRADIENTS, PASS_RATE, PASS_SWEEP, PASS_CORRECT, PASS_CONCENTRATION };
typedef struct dfsph_pass {
	dfsph_work *wk;
	enum dfsph_pass_kind kind;
	bool divergence; /* the velocity (divergence-free) solve's sweep, else the density one's */
	bool projected;  /* relaxed Jacobi on the symmetric operator, the density solve's
	                  * projected to k >= 0 (the divergence solver, and every
	                  * PASS_RATE), else the paper's sweeps */
	bool from_zero;  /* PASS_CORRECT: v* taken as 0 (not read), as the operator's product wants */
	bool reuse;      /* PASS_SWEEP: err holds R_i(v*) already (a PASS_RATE on this v*, which a
	                  * projected sweep's R_i equals): the pairs are not read again */
} dfsph_pass;
SIMD_DECLARE(void, dfsph_block, (const void *pass, long i0, long cnt));

/* ---- the passes, compiled once per SIMD back-end ---------------------------- */
/* Each particle writes only its own results, and its sums end in simd.h's
 * lane order: the same bits on every back-end and for any thread count. */

/* Eight particles' floats p[0 .. m) in lanes 0 .. m - 1, and back (m < 8:
 * the last particles of a block; the other lanes are 0 and not stored). */
static inline sf8 load8(const float *p, long m)
{
	if (m == 8)
		return sf8_load(p);
	float l[8];
	for (long k = 0; k < 8; ++k)
		l[k] = k < m ? p[k] : 0.0f;
	return sf8_load(l);
}

static inline void store8(float *p, sf8 a, long m)
{
	float l[8];
	sf8_store(m == 8 ? p : l, a);
	if (m < 8)
		memcpy(p, l, (size_t)m * sizeof *l);
}

/* Eight particles' quads p[0 .. m) by component: lane k of c0 .. c3 holds
 * p[k].x .. p[k].w; and back. */
static inline void load_quads8(const dfsph_vec4 *p, long m, sf8 *c0, sf8 *c1, sf8 *c2, sf8 *c3)
{
	dfsph_vec4 l[8];
	if (m < 8) {
		for (long k = 0; k < 8; ++k)
			l[k] = k < m ? p[k] : (dfsph_vec4){0, 0, 0, 0};
		p = l;
	}
	sf8_load_quads((const float *)p, c0, c1, c2, c3);
}

static inline void store_quads8(dfsph_vec4 *p, long m, sf8 c0, sf8 c1, sf8 c2, sf8 c3)
{
	dfsph_vec4 l[8];
	/* the whole quads, not &p->x: the stores cover eight of them (GCC checks the object) */
	sf8_store_quads(m == 8 ? (float *)p : (float *)l, c0, c1, c2, c3);
	if (m < 8)
		memcpy(p, l, (size_t)m * sizeof *l);
}

/* Per particle of eight, the sum of its four partial sums (sf8_fold4's, the
 * eight particles' quads from t): the order of sf8_sum. */
static inline sf8 sum8(const float *t, long m)
{
	sf8 f0, f1, f2, f3;
	load_quads8((const dfsph_vec4 *)t, m, &f0, &f1, &f2, &f3);
	return sf8_add(sf8_add(f0, f1), sf8_add(f2, f3));
}

/* Particle i's wall sums: B_i (out[0..2][q]) and sum_b (g . (x_b - x_i)) m_b
 * grad W(x_i - x_b) (out[3..5][q]), each in four partial sums (neighbour q
 * onto sum q mod 4, the last four padded and masked out) ended as sph_sum4
 * ends them: a particle at a wall has too few boundary neighbours for eight.
 * In a step (not the probe), a particle leaving its walls with no pressure
 * (header: the last step's k <= 0, or rho_i <= rho0 for the cold solve; v +
 * dt a moving away from them: DFSPH_LEAVE) is marked in wk->mask for the
 * velocity solve, and its walls' pressure p_b = p_i + rho_i g . (x_b - x_i)
 * held at >= 0. */
static void wall_sums(const dfsph_work *wk, long i, float out[6][SPH_BLOCK], long q)
{
	const sph_shared *sh = wk->sh;
	const sph_neighbors *nb = &sh->nb;
	const float *pi = sh->pq + 4 * i, eps2 = 1e-6f * sh->k.h2;
	const eddy_vec3 g = wk->gravity;
	const uint32_t *blist = sph_bnbrs(nb, i), bcnt = nb->bcount[i];
	const bool warm = wk->kprev[0] != NULL, free_walls = wk->vel[0] != NULL;
	/* no pressure: the last step's k (warm), else no compression for the cold
	 * solve, which makes pressure only from it; only such a particle can
	 * leave its walls, so only its sums of the walls below are kept */
	const bool unpressed = free_walls && (warm ? wk->kprev[0][i] + wk->kprev[1][i] <= 0 : wk->rho[i] <= sh->rho0);
	/* walls moving away from it (their part of the rate, -bdiv_i, < 0): it
	 * leaves them whatever its pressure once its own motion does not keep
	 * up, since they cannot pull it after them (a paddle pulled back at 3
	 * m/s from a pool dragged the water at its face along, the front
	 * following it instead of falling) */
	const bool retreat = free_walls && wk->bdiv && wk->bdiv[i] > 0;
	float s[9][4] = {{0}};
	for (uint32_t p = 0; p < bcnt; p += 4)
		for (uint32_t l = 0; l < 4; ++l) {
			const uint32_t b = blist[p + l < bcnt ? p + l : bcnt - 1];
			const float rx = pi[0] - nb->bx[b], ry = pi[1] - nb->by[b], rz = pi[2] - nb->bz[b];
			const float r2 = rx * rx + ry * ry + rz * rz;
			const float mb = nb->bvol[b] * sh->rho0; /* Akinci: the wall at rest density */
			const float r = sqrtf(r2), hr = sh->k.h - r;
			const bool ok = p + l < bcnt && r2 > eps2 && hr > 0;
			const float c = ok ? mb * sh->k.spiky_grad * hr * hr / r : 0.0f; /* + 0 leaves a sum as it is */
			s[0][l] += c * rx;
			s[1][l] += c * ry;
			s[2][l] += c * rz;
			const float gd = -(g.x * rx + g.y * ry + g.z * rz), gh = gd * c; /* g . (x_b - x_i) */
			s[3][l] += gh * rx;
			s[4][l] += gh * ry;
			s[5][l] += gh * rz;
			if (unpressed || retreat) { /* the walls above p_i's level left out (p_i = 0 here) */
				const float gp = (gd > 0 ? gd : 0.0f) * c;
				s[6][l] += gp * rx;
				s[7][l] += gp * ry;
				s[8][l] += gp * rz;
			}
		}
	for (int k = 0; k < 6; ++k)
		out[k][q] = sph_sum4(s[k]);
	if (!unpressed && !retreat)
		return; /* gradients set its mask 0 */
	const float bx = out[0][q], by = out[1][q], bz = out[2][q];
	const float ux = wk->vel[0][i] + wk->dt * wk->acc[0][i], uy = wk->vel[1][i] + wk->dt * wk->acc[1][i],
				uz = wk->vel[2][i] + wk->dt * wk->acc[2][i];
	const float rate = ux * bx + uy * by + uz * bz - (wk->bdiv ? wk->bdiv[i] : 0.0f); /* > 0: towards them */
	const float b2 = bx * bx + by * by + bz * bz, u2 = ux * ux + uy * uy + uz * uz;
	const bool leaving = rate < 0 && (retreat || rate * rate > DFSPH_LEAVE * DFSPH_LEAVE * b2 * u2);
	wk->mask[i] = leaving;
	if (leaving)
		for (int k = 3; k < 6; ++k)
			out[k][q] = sph_sum4(s[k + 3]);
}

/* The spiky gradient's constants for the pair passes, in registers. */
typedef struct dfsph_kern {
	sf8 h, eps2, mg, one, zero;
} dfsph_kern;

static inline dfsph_kern kern(const sph_shared *sh)
{
	return (dfsph_kern){sf8_set1(sh->k.h), sf8_set1(1e-6f * sh->k.h2), sf8_set1(sh->mass * sh->k.spiky_grad),
	                    sf8_set1(1.0f), sf8_zero()};
}

/* The rows of particle i's neighbours p .. p + 7 (of its c), the next group
 * of its packed list (read in order from p = 0), into pad; the last group's
 * padding (copies of its last row) replaced by i itself, whose r = 0 makes
 * G = 0 (exact zeros in every sum: no scalar tail, no mask). The lists are
 * read only here. */
static inline const uint32_t *group_rows(sph_groups *list, uint32_t c, uint32_t p, uint32_t i, uint32_t pad[8])
{
	sph_group_rows(list, pad);
	if (c - p < 8)
		for (uint32_t l = 0; l < 8; ++l) /* a blend, no branch per lane */
			pad[l] = l < c - p ? pad[l] : i;
	return pad;
}

/* f_ij of G_ij = f_ij (x_i - x_j) for the eight rows j, f = m spiky_grad (h -
 * r)^2 / r (0 for a pair closer than 1e-3 h, at r >= h: the list's margin,
 * and the padding), and x_i - x_j in rx ry rz; pi holds x_i twice. The
 * sweeps recompute it from the positions sph_density saw (pq), which do not
 * change during the solves: every pass gets the same bits. */
static inline sf8 pair_f(const dfsph_kern *kc, sf8 pi, const float *pq, const uint32_t *j, sf8 *rx, sf8 *ry, sf8 *rz)
{
	sf8 rw;
	sf8_sub_gather_quads(pi, pq, j, rx, ry, rz, &rw);
	const sf8 r2 = sf8_add(sf8_add(sf8_mul(*rx, *rx), sf8_mul(*ry, *ry)), sf8_mul(*rz, *rz));
	const sf8 r = sf8_sqrt(r2), hr = sf8_sub(kc->h, r);
	const sf8 ok = sf8_and(sf8_gt(r2, kc->eps2), sf8_gt(hr, kc->zero));
	/* r is at least sqrt(eps2) where ok; elsewhere divide by 1 */
	return sf8_and(ok, sf8_div(sf8_mul(sf8_mul(kc->mg, hr), hr), sf8_select(ok, r, kc->one)));
}

/* G_ij by component for the group of rows j. */
static inline void pair_grad(const dfsph_kern *kc, sf8 pi, const float *pq, const uint32_t *j, sf8 *gx, sf8 *gy,
                             sf8 *gz)
{
	sf8 rx, ry, rz;
	const sf8 f = pair_f(kc, pi, pq, j, &rx, &ry, &rz);
	*gx = sf8_mul(f, rx);
	*gy = sf8_mul(f, ry);
	*gz = sf8_mul(f, rz);
}

/* The gradient pass: per particle S_i, sum_j |G_ij|^2 (G_ij = 0 for a pair
 * closer than 1e-3 h or at r >= h: pair_f), the walls' sums, h_i, 1 / D_i
 * and 1 / D'_i (0 where D is negligible, below dmin). */
static void gradients(const dfsph_work *wk, long i0, long cnt)
{
	const sph_shared *sh = wk->sh;
	const sph_neighbors *nb = &sh->nb;
	const dfsph_kern kc = kern(sh);
	const float dref = sh->mass * sh->k.spiky_grad * sh->k.h2; /* |G|'s scale */
	const sf8 one = sf8_set1(1.0f), two = sf8_set1(2.0f), zero = sf8_zero(), dmin = sf8_set1(1e-6f * dref * dref),
			  minus = sf8_set1(-0.0f);
	float t[4][SPH_BLOCK][4], w[6][SPH_BLOCK] = {{0}};
	for (long q = 0; q < cnt; ++q) {
		const long i = i0 + q;
		sph_groups list = sph_nbr_groups(nb, i);
		const uint32_t c = nb->count[i];
		const sf8 pi = sf8_load_quad2(sh->pq + 4 * i);
		sf8 sx = zero, sy = zero, sz = zero, s2 = zero;
		uint32_t pad[8];
		for (uint32_t p = 0; p < c; p += 8) {
			const uint32_t *j = group_rows(&list, c, p, (uint32_t)i, pad);
			sf8 rx, ry, rz; /* x_i - x_j */
			const sf8 f = pair_f(&kc, pi, sh->pq, j, &rx, &ry, &rz);
			const sf8 gx = sf8_mul(f, rx), gy = sf8_mul(f, ry), gz = sf8_mul(f, rz);
			if (wk->gs) {
				dfsph_group *g = wk->gs + wk->goff[i] + p / 8;
				memcpy(g->j, j, sizeof g->j);
				sf8_store(g->gx, gx);
				sf8_store(g->gy, gy);
				sf8_store(g->gz, gz);
			}
			sx = sf8_add(sx, gx);
			sy = sf8_add(sy, gy);
			sz = sf8_add(sz, gz);
			s2 = sf8_add(s2, sf8_add(sf8_add(sf8_mul(gx, gx), sf8_mul(gy, gy)), sf8_mul(gz, gz)));
		}
		sf8_fold4(sx, t[0][q]);
		sf8_fold4(sy, t[1][q]);
		sf8_fold4(sz, t[2][q]);
		sf8_fold4(s2, t[3][q]);
		wk->mask[i] = 0;   /* wall_sums marks those leaving their walls */
		if (nb->bcount[i]) /* most particles are away from the walls */
			wall_sums(wk, i, w, q);
	}
	for (long q = 0; q < cnt; q += 8) {
		const long i = i0 + q, m = cnt - q < 8 ? cnt - q : 8;
		const sf8 sx = sum8(t[0][q], m), sy = sum8(t[1][q], m), sz = sum8(t[2][q], m), s2 = sum8(t[3][q], m);
		const sf8 bx = load8(w[0] + q, m), by = load8(w[1] + q, m), bz = load8(w[2] + q, m);
		sf8 x, y, z, ir; /* ir = 1 / rho_i */
		load_quads8((const dfsph_vec4 *)sh->pq + i, m, &x, &y, &z, &ir);
		store_quads8(wk->u + i, m, sf8_mul(sf8_xor(minus, load8(w[3] + q, m)), ir), /* h_i */
		             sf8_mul(sf8_xor(minus, load8(w[4] + q, m)), ir), sf8_mul(sf8_xor(minus, load8(w[5] + q, m)), ir),
		             zero);
		const sf8 ex = sf8_add(sx, sf8_mul(two, bx)), ey = sf8_add(sy, sf8_mul(two, by)),
				  ez = sf8_add(sz, sf8_mul(two, bz));
		/* D_i = (S + 2B) . (S + B) + sum |G|^2 */
		const sf8 d = sf8_add(
			sf8_add(sf8_add(sf8_mul(ex, sf8_add(sx, bx)), sf8_mul(ey, sf8_add(sy, by))), sf8_mul(ez, sf8_add(sz, bz))),
			s2);
		store_quads8(wk->b + i, m, bx, by, bz, sf8_and(sf8_gt(d, dmin), sf8_div(one, d)));
		/* D'_i = |S + 2B|^2 + sum |G|^2 */
		const sf8 ds = sf8_add(sf8_add(sf8_add(sf8_mul(ex, ex), sf8_mul(ey, ey)), sf8_mul(ez, ez)), s2);
		store8(wk->dsym + i, sf8_and(sf8_gt(ds, dmin), sf8_div(one, ds)), m);
	}
}

/* The shift's pass, after the solves: grad C_i = sum_j G_ij V_j / m over the
 * fluid (shift adds the walls' part, B_i / rho0) and max_j V_j / m, into u
 * (free again). */
static void concentration(const dfsph_work *wk, long i0, long cnt)
{
	const sph_shared *sh = wk->sh;
	const sph_neighbors *nb = &sh->nb;
	const dfsph_kern kc = kern(sh);
	float t[3][SPH_BLOCK][4], vmax[SPH_BLOCK];
	for (long q = 0; q < cnt; ++q) {
		const long i = i0 + q;
		sph_groups list = sph_nbr_groups(nb, i);
		const uint32_t c = nb->count[i];
		const sf8 pi = sf8_load_quad2(sh->pq + 4 * i);
		sf8 cx = kc.zero, cy = kc.zero, cz = kc.zero, mv = kc.zero;
		uint32_t pad[8];
		for (uint32_t p = 0; p < c; p += 8) {
			sf8 gx, gy, gz;
			const uint32_t *j;
			if (wk->gs) { /* the stored pairs (as rate: the same G_ij) */
				const dfsph_group *g = wk->gs + wk->goff[i] + p / 8;
				j = g->j;
				gx = sf8_load(g->gx);
				gy = sf8_load(g->gy);
				gz = sf8_load(g->gz);
			} else {
				j = group_rows(&list, c, p, (uint32_t)i, pad);
				pair_grad(&kc, pi, sh->pq, j, &gx, &gy, &gz);
			}
			const sf8 vj = sf8_gather4(sh->pq + 3, j); /* V_j / m = 1 / rho_j */
			cx = sf8_add(cx, sf8_mul(gx, vj));
			cy = sf8_add(cy, sf8_mul(gy, vj));
			cz = sf8_add(cz, sf8_mul(gz, vj));
			mv = sf8_max(mv, vj);
		}
		float l[8];
		sf8_store(l, mv);
		vmax[q] = l[0];
		for (int k = 1; k < 8; ++k)
			vmax[q] = l[k] > vmax[q] ? l[k] : vmax[q];
		sf8_fold4(cx, t[0][q]);
		sf8_fold4(cy, t[1][q]);
		sf8_fold4(cz, t[2][q]);
	}
	for (long q = 0; q < cnt; q += 8) {
		const long i = i0 + q, m = cnt - q < 8 ? cnt - q : 8;
		store_quads8(wk->u + i, m, sum8(t[0][q], m), sum8(t[1][q], m), sum8(t[2][q], m), load8(vmax + q, m));
	}
}

/* The rate pass: R_i(v) (or Drho_i/Dt), and for a sweep its error and change of k. */
static void rate(const dfsph_pass *ps, long i0, long cnt)
{
	const dfsph_work *wk = ps->wk;
	const sph_shared *sh = wk->sh;
	const dfsph_kern kc = kern(sh);
	const float *v = &wk->v->x;
	float t[SPH_BLOCK][4];
	for (long q = 0; q < cnt && !ps->reuse; ++q) {
		const long i = i0 + q;
		const sf8 vi = sf8_load_quad2(v + 4 * i);
		sf8 sx = sf8_zero(), sy = sx, sz = sx;
		if (wk->gs) { /* the stored pairs (one loop each way: the same sums in the same order) */
			for (const dfsph_group *g = wk->gs + wk->goff[i], *ge = wk->gs + wk->goff[i + 1]; g < ge; ++g) {
				sf8 dx, dy, dz, dw; /* v_i - v_j */
				sf8_sub_gather_quads(vi, v, g->j, &dx, &dy, &dz, &dw);
				sx = sf8_add(sx, sf8_mul(dx, sf8_load(g->gx)));
				sy = sf8_add(sy, sf8_mul(dy, sf8_load(g->gy)));
				sz = sf8_add(sz, sf8_mul(dz, sf8_load(g->gz)));
			}
		} else {
			sph_groups list = sph_nbr_groups(&sh->nb, i);
			const uint32_t c = sh->nb.count[i];
			const sf8 pi = sf8_load_quad2(sh->pq + 4 * i);
			uint32_t pad[8];
			for (uint32_t p = 0; p < c; p += 8) {
				const uint32_t *j = group_rows(&list, c, p, (uint32_t)i, pad);
				sf8 gx, gy, gz, dx, dy, dz, dw; /* G_ij, v_i - v_j */
				pair_grad(&kc, pi, sh->pq, j, &gx, &gy, &gz);
				sf8_sub_gather_quads(vi, v, j, &dx, &dy, &dz, &dw);
				sx = sf8_add(sx, sf8_mul(dx, gx));
				sy = sf8_add(sy, sf8_mul(dy, gy));
				sz = sf8_add(sz, sf8_mul(dz, gz));
			}
		}
		sf8_fold4(sf8_add(sf8_add(sx, sy), sz), t[q]);
	}
	const float inv1 = ps->divergence ? 1.0f / wk->dt : 1.0f / (wk->dt * wk->dt);
	const sf8 zero = sf8_zero(), dt = sf8_set1(wk->dt), inv = sf8_set1(inv1), rho0 = sf8_set1(wk->sh->rho0),
			  omega = sf8_set1(DFSPH_OMEGA), minus = sf8_set1(-0.0f), beta = sf8_set1(wk->beta),
			  ibeta = sf8_set1(1.0f / wk->beta);
	const bool soft = wk->beta < 1; /* else the paper's expression, bit for bit */
	for (long q = 0; q < cnt; q += 8) {
		const long i = i0 + q, m = cnt - q < 8 ? cnt - q : 8;
		sf8 vx, vy, vz, vw, bx, by, bz, bw;
		load_quads8(wk->v + i, m, &vx, &vy, &vz, &vw);
		load_quads8(wk->b + i, m, &bx, &by, &bz, &bw);
		sf8 r;
		if (ps->reuse)
			r = load8(wk->err + i, m);
		else {
			sf8 vb = sf8_add(sf8_add(sf8_mul(vx, bx), sf8_mul(vy, by)), sf8_mul(vz, bz));
			if (wk->bdiv)
				vb = sf8_sub(vb, load8(wk->bdiv + i, m));
			/* the wall counted twice, as its force, on the symmetric operator */
			r = sf8_add(sum8(t[q], m), ps->projected ? sf8_add(vb, vb) : vb);
		}
		if (ps->kind == PASS_RATE) {
			store8(wk->err + i, r, m);
			continue;
		}
		const sf8 res = ps->divergence ? sf8_mul(r, bw) /* bw: the velocity solve's particles */
		                : soft         ? sf8_add(sf8_mul(beta, sf8_sub(load8(wk->rho + i, m), rho0)), sf8_mul(dt, r))
		                               : sf8_sub(sf8_add(load8(wk->rho + i, m), sf8_mul(dt, r)), rho0);
		sf8 e = sf8_max(res, zero); /* the compression */
		if (ps->projected) {
			/* k_i += omega res_i / (dt^n D'_i), the density solve's then at
			 * least 0 (header); correct applies the change */
			const sf8 ks = load8(wk->ksum + i, m);
			sf8 kn = sf8_add(ks, sf8_mul(sf8_mul(sf8_mul(res, omega), inv), load8(wk->dsym + i, m)));
			if (!ps->divergence)
				kn = sf8_max(kn, zero);
			store8(wk->k + i, sf8_sub(kn, ks), m);
			/* |res| under pressure (the density solve) or anywhere (the velocity
			 * solve, where res is 0 off its particles): too much pressure counts
			 * as too little */
			e = ps->divergence ? sf8_andnot(minus, res) : sf8_select(sf8_gt(kn, zero), sf8_andnot(minus, res), e);
		} else { /* the paper's sweeps: only compression adds pressure */
			store8(wk->k + i, sf8_mul(sf8_mul(e, inv), bw), m);
		}
		store8(wk->err + i, ps->divergence ? sf8_mul(e, dt) : sf8_mul(e, ibeta), m);
	}
}

/* The correction: v*_i -= dt (sum_j (k_i + k_j) G_ij + 2 k_i B_i), and k_i
 * added to its sum; from_zero (the operator's product): u_i = 0 - dt (...),
 * no sum. */
static void correct(const dfsph_work *wk, long i0, long cnt, bool from_zero)
{
	const sph_shared *sh = wk->sh;
	const dfsph_kern kc = kern(sh);
	const float *k = wk->k;
	float t[3][SPH_BLOCK][4];
	for (long q = 0; q < cnt; ++q) {
		const long i = i0 + q;
		const sf8 ki = sf8_set1(k[i]);
		sf8 sx = sf8_zero(), sy = sx, sz = sx;
		if (wk->gs) { /* the stored pairs (as rate) */
			for (const dfsph_group *g = wk->gs + wk->goff[i], *ge = wk->gs + wk->goff[i + 1]; g < ge; ++g) {
				const sf8 kk = sf8_add(ki, sf8_gather(k, g->j));
				sx = sf8_add(sx, sf8_mul(kk, sf8_load(g->gx)));
				sy = sf8_add(sy, sf8_mul(kk, sf8_load(g->gy)));
				sz = sf8_add(sz, sf8_mul(kk, sf8_load(g->gz)));
			}
		} else {
			sph_groups list = sph_nbr_groups(&sh->nb, i);
			const uint32_t c = sh->nb.count[i];
			const sf8 pi = sf8_load_quad2(sh->pq + 4 * i);
			uint32_t pad[8];
			for (uint32_t p = 0; p < c; p += 8) {
				const uint32_t *j = group_rows(&list, c, p, (uint32_t)i, pad);
				sf8 gx, gy, gz;
				pair_grad(&kc, pi, sh->pq, j, &gx, &gy, &gz);
				const sf8 kk = sf8_add(ki, sf8_gather(k, j));
				sx = sf8_add(sx, sf8_mul(kk, gx));
				sy = sf8_add(sy, sf8_mul(kk, gy));
				sz = sf8_add(sz, sf8_mul(kk, gz));
			}
		}
		sf8_fold4(sx, t[0][q]);
		sf8_fold4(sy, t[1][q]);
		sf8_fold4(sz, t[2][q]);
	}
	const sf8 dt = sf8_set1(wk->dt), two = sf8_set1(2.0f);
	for (long q = 0; q < cnt; q += 8) {
		const long i = i0 + q, m = cnt - q < 8 ? cnt - q : 8;
		sf8 vx = sf8_zero(), vy = vx, vz = vx, vw = vx, bx, by, bz, bw;
		if (!from_zero) /* 0 - x: the bits a zeroed v* would give */
			load_quads8(wk->v + i, m, &vx, &vy, &vz, &vw);
		load_quads8(wk->b + i, m, &bx, &by, &bz, &bw);
		const sf8 ki = load8(wk->k + i, m), kb = sf8_mul(two, ki); /* the boundary particles mirror k_i */
		vx = sf8_sub(vx, sf8_mul(dt, sf8_add(sf8_mul(kb, bx), sum8(t[0][q], m))));
		vy = sf8_sub(vy, sf8_mul(dt, sf8_add(sf8_mul(kb, by), sum8(t[1][q], m))));
		vz = sf8_sub(vz, sf8_mul(dt, sf8_add(sf8_mul(kb, bz), sum8(t[2][q], m))));
		store_quads8(wk->v + i, m, vx, vy, vz, vw);
		if (!from_zero)
			store8(wk->ksum + i, sf8_add(load8(wk->ksum + i, m), ki), m);
	}
}

void SIMD_NAME(dfsph_block)(const void *pass, long i0, long cnt)
{
	const dfsph_pass *ps = pass;
	if (ps->kind == PASS_GRADIENTS)
		gradients(ps->wk, i0, cnt);
	else if (ps->kind == PASS_CONCENTRATION)
		concentration(ps->wk, i0, cnt);
	else if (ps->kind == PASS_CORRECT)
		correct(ps->wk, i0, cnt, ps->from_zero);
	else
		rate(ps, i0, cnt);
}

#ifndef EDDY_SIMD_VARIANT
/* ---- the system: solves, step, limits, registration ---------------------------- */
#include "systems.h"

/* The gravity limit (header): gravity compresses the fluid by g dt^2 a step,
 * which the solve's first-order prediction must absorb, or a tank at rest
 * rings up (the velocity limit covers transient forces). */
#define DFSPH_GRAVITY_LIMIT 0.18

/* The density solve stops only once, besides its mean, no particle's
 * predicted density error (its compression; with the divergence solver
 * also the expansion of a particle under pressure) is above this. The
 * mean alone is diluted in a
 * free-surface flow: in a jet most particles are under-dense, their error
 * 0, so a tolerance of 1% on the mean let the few particles where the jet
 * lands end a step predicted 30-90% compressed (the pour at 3.5 mm, 100k
 * particles: residual_max 0.3-0.9 a frame), and at 0.83 s one was thrown
 * at 389 m/s and the run stopped. With the bound it runs (largest speed 3.1
 * m/s); at 1 cm the pour's density sweeps go from 3.97 to 4.37 a step,
 * its CPU time unchanged (fewer steps). */
#define DFSPH_MAX_COMPRESSION 0.1
/* The cold density solve removes the compression the particles already
 * have over a time of about tau = DFSPH_SOFT_TIME sqrt(h / |g|) (header):
 * measured on the pour (README, Stress cases) */
#define DFSPH_SOFT_TIME 0.03

/* A step fails above this final mean density error, or above this
 * predicted density error at one particle (the particles overlap). */
#define DFSPH_FAIL_ERROR 0.05
#define DFSPH_FAIL_PARTICLE 1.0

/* The velocity solve warm-starts: stopped at its cap it hands the rest on to
 * the next step; stopped there above DFSPH_FAIL_CAPPED_ERROR times the
 * tolerance DFSPH_FAIL_CAPPED steps in a row, it is not catching up. */
#define DFSPH_FAIL_CAPPED_ERROR 2.0
#define DFSPH_FAIL_CAPPED 3

/* The least sweeps of the velocity solve: they damp the particle-scale error
 * its conjugate gradients leave, which jitters particles at a still surface. */
#define DFSPH_SMOOTH 2

/* The velocity solve's column-scale error (block_error): the residual's
 * mean over cubes of side DFSPH_BLOCK_H h (some 500 particles at h = 2
 * spacings, whose particle-scale error averages down some 20x), its root
 * mean square at most DFSPH_BLOCK_TOL max_divergence_error depth_scale
 * (header); larger cubes while there would be more than DFSPH_BLOCKS_MAX
 * (water flying far). */
#define DFSPH_BLOCK_H 4.0
#define DFSPH_BLOCK_TOL 0.1
#define DFSPH_BLOCKS_MAX 65536

/* The velocity solve leaves out a particle whose kernel sum (walls
 * included) is below DFSPH_SURFACE rho0: the outermost particles of a free
 * surface (every other particle of water at rest is within 5% of rho0), so
 * water a solid stirred apart is not held expanded. Higher leaves out enough
 * of the surface to let still water jitter; lower lets a dropped block
 * compress at impact beyond the density tolerance. */
#define DFSPH_SURFACE 0.8f

/* kernel radii: the depth beyond which the tolerances tighten (depth_scale) */
#define DFSPH_DEPTH_REF 5.0

/* Shifting moves only particles whose kernel sum, and their neighbours',
 * is at least this times rho0 (header): in water at rest every particle but
 * the free surface's outermost is within 5% of rho0 (see DFSPH_SURFACE). */
#define DFSPH_SHIFT_SURFACE 0.95f
/* nor one thinned below this fraction of rho0 (header: the shift's descent
 * on the kernel sums, which the density solve does not push back) */
#define DFSPH_SHIFT_FLOOR 0.99f

typedef struct sph_dfsph {
	eddy_sph_dfsph_def def;
	/* the state columns dfsph_k, dfsph_kd: the two solves' warm starts (or -1): the
	 * velocity solve's k less the density solve's change of k, and the density solve's k */
	int kcol[2];
	int capped; /* steps in a row whose velocity solve ended capped (DFSPH_FAIL_CAPPED) */
	/* statistics of the current frame */
	int frame;
	int64_t steps, sweeps, div_sweeps, unconverged;
	double residual, worst;
} sph_dfsph;

eddy_sph_dfsph_def eddy_default_sph_dfsph_def(void)
{
	return (eddy_sph_dfsph_def){.max_density_error = 0.005f,
	                            .max_iterations = 100,
	                            .divergence_solver = true,
	                            .max_divergence_error = 5e-5f,
	                            .max_divergence_iterations = 1000,
	                            .coarse_grid = false,
	                            .shift = 0.02f,
	                            .hydrostatic_start = false};
}

/* A pass's rows go to the threads in chunks of DFSPH_CHUNK_BLOCKS blocks or
 * fewer, taken in turn as each thread finishes one (dynamic): sph_block_pass's
 * equal shares finish at the pace of the slower core, and on a shared host
 * one core can run at half the other's speed for seconds (measured on a
 * 2-vCPU virtual machine: a register-only AVX2 multiply-add loop took
 * 0.52-1.26 s of CPU time on either core, 0.59 s on one while 1.23 s on the
 * other when run on both at once, a latency-bound division loop a steady
 * 0.46 s: likely the host's other threads on the cores' hyperthread siblings; the
 * 1-thread DFSPH figure of tests/bench_scale.c at 1M is 3.3k or 5.1k ns).
 * The chunks start at multiples of SPH_BLOCK, as one thread's blocks do, and
 * each particle's results depend on neither: the same bits for any thread
 * count and any order the chunks are taken in. */
#define DFSPH_CHUNK_BLOCKS 16

/* The plain loops over the rows that run once a solve or a step (its set-up and
 * finish, a solve's warm start and sum) use the threads above this many
 * rows: below it, waking the team costs more than the loop. */
#define DFSPH_LOOP_PAR 65536

/* The solves' sums over the rows (the conjugate gradients' dot products and
 * residuals, the sweeps' mean error) are taken in chunks of DFSPH_SUM_CHUNK
 * rows, each summed in row order, then the chunks' sums in chunk order: the
 * same bits for any thread count (a fluid of one chunk gets the plain
 * serial sum's). The chunks, and the vector updates fused with them, run on
 * the threads above DFSPH_CG_PAR rows: serial, they are some 7% of a
 * 1-thread step at 1M (perf), which bounds two threads at 1.86x; but each
 * such loop adds a join per iteration, and on a host whose cores are shared
 * a join waits for the other thread to be scheduled again (at 97k, with a
 * busy loop pinned beside the second thread, threading them took 1.5x the
 * time). Above DFSPH_CG_PAR a loop streams tens of megabytes, long enough
 * that a join is small beside it. */
#define DFSPH_SUM_CHUNK 16384
#define DFSPH_CG_PAR (1L << 18)

typedef struct dfsph_sums {
	double a, b;
} dfsph_sums;

static long sum_chunks(long n) { return (n + DFSPH_SUM_CHUNK - 1) / DFSPH_SUM_CHUNK; }
static long chunk_end(long c, long n) { return (c + 1) * DFSPH_SUM_CHUNK < n ? (c + 1) * DFSPH_SUM_CHUNK : n; }
static int cg_threads(const dfsph_work *wk) { return wk->n > DFSPH_CG_PAR ? wk->threads : 1; }

/* The chunks' partial sums part[0 .. nc), added in chunk order. */
static dfsph_sums sums_total(const dfsph_sums *part, long nc)
{
	dfsph_sums t = {0, 0};
	for (long c = 0; c < nc; ++c) {
		t.a += part[c].a;
		t.b += part[c].b;
	}
	return t;
}

static int loop_threads(long n, int threads) { return n > DFSPH_LOOP_PAR ? threads : 1; }

static void pass_run(dfsph_work *wk, const dfsph_pass *ps)
{
	const long n = wk->n, blocks = (n + SPH_BLOCK - 1) / SPH_BLOCK;
	const int threads = wk->threads;
	if (threads <= 1) {
		for (long i0 = 0; i0 < n; i0 += SPH_BLOCK)
			wk->block(ps, i0, n - i0 < SPH_BLOCK ? n - i0 : SPH_BLOCK);
		return;
	}
	/* about 8 chunks a thread at least: a small fluid still splits */
	long per = blocks / (8L * threads);
	per = per < 1 ? 1 : per > DFSPH_CHUNK_BLOCKS ? DFSPH_CHUNK_BLOCKS : per;
	const long chunk = per * SPH_BLOCK, chunks = (n + chunk - 1) / chunk;
#pragma omp parallel for num_threads(threads) schedule(dynamic, 1)
	for (long c = 0; c < chunks; ++c)
		for (long i0 = c * chunk, hi = i0 + chunk < n ? i0 + chunk : n; i0 < hi; i0 += SPH_BLOCK)
			wk->block(ps, i0, hi - i0 < SPH_BLOCK ? hi - i0 : SPH_BLOCK);
}

static void pass(dfsph_work *wk, enum dfsph_pass_kind kind, bool divergence, bool projected)
{
	const dfsph_pass ps = {wk, kind, divergence, projected, false, false};
	pass_run(wk, &ps);
}

/* err = R(u) of u = -dt grad p from zero, without the moving walls' part:
 * A p up to the factor -dt (the passes run on borrowed arrays meanwhile). */
static void operator_product(dfsph_work *wk)
{
	const dfsph_work keep = *wk;
	wk->v = wk->u;
	wk->k = wk->p; /* the same array (dfsph_work) */
	wk->bdiv = NULL;
	/* u = 0 - dt (...): no memset; ksum left as it is */
	const dfsph_pass ps = {wk, PASS_CORRECT, true, true, true, false};
	pass_run(wk, &ps);
	pass(wk, PASS_RATE, true, true);
	*wk = keep;
}

/* sum_i p_i mask_i err_i, err the operator's product on p (chunked as
 * DFSPH_SUM_CHUNK says). */
static double product_sum(const dfsph_work *wk)
{
	const long n = wk->n, nc = sum_chunks(n);
	const int nt = cg_threads(wk);
#pragma omp parallel for num_threads(nt) if (nt > 1) schedule(dynamic, 1)
	for (long c = 0; c < nc; ++c) {
		double s = 0;
		for (long i = c * DFSPH_SUM_CHUNK, e = chunk_end(c, n); i < e; ++i)
			s += (double)wk->p[i] * ((float)wk->mask[i] * wk->err[i]);
		wk->part[c] = (dfsph_sums){s, 0};
	}
	return sums_total(wk->part, nc).a;
}

/* The column-scale error of a residual r (0 off the active set): r summed
 * over the blocks, S_c over n_c active rows each, and the root mean square
 * of the block means weighted by their rows, sqrt(sum_c S_c^2 / n_c / N),
 * times dt / rho0. Serial, in row then block order. */
static double block_error(const dfsph_work *wk, const float *r)
{
	if (!wk->bsum)
		return 0;
	const size_t cells = (size_t)wk->bdim[0] * wk->bdim[1] * wk->bdim[2];
	memset(wk->bsum, 0, cells * sizeof *wk->bsum);
	memset(wk->bcnt, 0, cells * sizeof *wk->bcnt);
	const float *pq = wk->sh->pq;
	for (long i = 0; i < wk->n; ++i) {
		if (!wk->mask[i])
			continue;
		size_t c = 0;
		for (int d = 2; d >= 0; --d) {
			/* clamped in float (a non-finite position to block 0) before the conversion */
			const float q = (pq[4 * i + d] - wk->borg[d]) * wk->binv, top = (float)(wk->bdim[d] - 1);
			c = c * (size_t)wk->bdim[d] + (size_t)(q >= top ? top : q >= 0 ? q : 0);
		}
		wk->bsum[c] += r[i];
		wk->bcnt[c] += 1.0f;
	}
	double s2 = 0, cnt = 0;
	for (size_t c = 0; c < cells; ++c)
		if (wk->bcnt[c] > 0) {
			s2 += wk->bsum[c] * wk->bsum[c] / wk->bcnt[c];
			cnt += wk->bcnt[c];
		}
	return cnt > 0 ? sqrt(s2 / cnt) * wk->dt / wk->sh->rho0 : 0;
}

/* Whether the conjugate gradients go on: the mean error (*residual) above
 * tol, or else the column-scale error above btol. That error (a serial pass
 * over the rows) is measured only once the mean is within tol, as only then
 * does it decide; *berr is NAN while not measured on the current r. */
static bool cg_more(const dfsph_work *wk, double residual, double tol, double btol, double *berr)
{
	*berr = NAN;
	if (residual > tol)
		return true;
	*berr = btol > 0 ? block_error(wk, wk->r) : 0;
	return *berr > btol;
}

/* The solves' bulk: Jacobi-preconditioned conjugate gradients on A k = R(v*)
 * over the velocity solve's particles (b.w > 0), or for the density solve
 * over the particles that hold pressure (k_i > 0) or compress (R_i > 0),
 * where its unilateral constraint is an equality; the density solve's right
 * side is the rate that brings rho_i to rho0 in a step. It stops once the
 * mean |r_i| dt / rho0 is at most tol and the column-scale error at most
 * btol (cg_more; btol 0: the mean alone), or a direction has no positive
 * curvature; the density solve then projects (k_i < 0 back to 0), and the
 * sweeps after it settle the particles that left or entered its set. Its sums are chunked
 * (DFSPH_SUM_CHUNK): the same bits for any thread count. *fresh: err still
 * holds R(v*) of its first pass (no iteration, nothing projected), which
 * the sweep after it then reads instead of the pairs (the same bits). */
static int divergence_cg(dfsph_work *wk, int cap, bool density, double tol, double btol, double *residual, double *berr,
                         bool *fresh)
{
	const long n = wk->n;
	const float dt = wk->dt, rho0 = wk->sh->rho0;
	const double scale = (double)dt / ((double)rho0 * (double)n);
	pass(wk, PASS_RATE, true, true);
	*fresh = true; /* err = R(v*) until a product or the projection */
	const long nc = sum_chunks(n);
	const int nt = cg_threads(wk);
#pragma omp parallel for num_threads(nt) if (nt > 1) schedule(dynamic, 1)
	for (long c = 0; c < nc; ++c) {
		double rz = 0, esum = 0;
		for (long i = c * DFSPH_SUM_CHUNK, e = chunk_end(c, n); i < e; ++i) {
			const float res = density ? wk->err[i] + (wk->rho[i] - rho0) / dt : wk->err[i];
			const bool on = density ? wk->ksum[i] > 0 || res > 0 : wk->b[i].w > 0;
			wk->mask[i] = on;
			wk->r[i] = on ? res : 0.0f;
			wk->p[i] = wk->dsym[i] * wk->r[i];
			rz += (double)wk->r[i] * wk->p[i];
			esum += fabsf(wk->r[i]);
		}
		wk->part[c] = (dfsph_sums){rz, esum};
	}
	const dfsph_sums s0 = sums_total(wk->part, nc);
	double rz = s0.a;
	*residual = s0.b * scale;
	bool more = cg_more(wk, *residual, tol, btol, berr);
	/* the levels live until the call returns: each call rebuilds them for its active set */
	const eddy_arena_mark mark = wk->coarse ? eddy__arena_mark(wk->coarse) : (eddy_arena_mark){0};
	dfsph_coarse *cg = wk->coarse && more ? eddy__dfsph_coarse_build(wk->coarse, wk->sh, n, wk->mask, nt) : NULL;
	if (cg && !(wk->coarse_scale > 0)) { /* s = y . (A/dt) y / e . L e on y = p (dfsph_coarse.h) */
		const double ele = eddy__dfsph_coarse_unit(cg, wk->r, wk->p);
		operator_product(wk);
		*fresh = false;
		wk->coarse_scale = -product_sum(wk) / (double)dt / ele;
	}
	if (cg) {
		eddy__dfsph_coarse_set_scale(cg, wk->coarse_scale);
		rz = eddy__dfsph_coarse_apply(cg, wk->r, wk->dsym, wk->p);
	}
	int it = 0;
	while (more && it < cap && rz > 0) {
		operator_product(wk);
		*fresh = false;
		const double pq = -product_sum(wk);
		if (!(pq > 0))
			break;
		const float alpha = (float)(rz / pq);
#pragma omp parallel for num_threads(nt) if (nt > 1) schedule(dynamic, 1)
		for (long c = 0; c < nc; ++c) {
			double rz1 = 0, esum = 0;
			for (long i = c * DFSPH_SUM_CHUNK, e = chunk_end(c, n); i < e; ++i) {
				wk->v[i].x += alpha * wk->u[i].x;
				wk->v[i].y += alpha * wk->u[i].y;
				wk->v[i].z += alpha * wk->u[i].z;
				wk->ksum[i] += alpha * wk->p[i];
				wk->r[i] += alpha * ((float)wk->mask[i] * wk->err[i]);
				rz1 += (double)wk->r[i] * (wk->dsym[i] * wk->r[i]);
				esum += fabsf(wk->r[i]);
			}
			wk->part[c] = (dfsph_sums){rz1, esum};
		}
		const dfsph_sums s1 = sums_total(wk->part, nc);
		double rz1 = s1.a;
		++it;
		*residual = s1.b * scale;
		more = cg_more(wk, *residual, tol, btol, berr);
		/* z = D'^-1 r + its part, in err (free until the next product) */
		const bool coarse = cg && more && it < cap;
		if (coarse)
			rz1 = eddy__dfsph_coarse_apply(cg, wk->r, wk->dsym, wk->err);
		const float beta = (float)(rz1 / rz);
		rz = rz1;
#pragma omp parallel for num_threads(nt) if (nt > 1) schedule(static)
		for (long i = 0; i < n; ++i)
			wk->p[i] = (coarse ? wk->err[i] : wk->dsym[i] * wk->r[i]) + beta * wk->p[i];
	}
	if (isnan(*berr)) /* the caller's stopping test reads it (solve) */
		*berr = btol > 0 ? block_error(wk, wk->r) : 0;
	/* the density solve's projection: k_i < 0 back to 0, as one correction */
	bool neg = false;
	if (density) {
#pragma omp parallel for num_threads(nt) if (nt > 1) schedule(static) reduction(|| : neg)
		for (long i = 0; i < n; ++i) {
			wk->k[i] = wk->ksum[i] < 0 ? -wk->ksum[i] : 0.0f;
			neg = neg || wk->ksum[i] < 0;
		}
	}
	if (neg)
		pass(wk, PASS_CORRECT, true, true);
	*fresh = *fresh && !neg;
	if (wk->coarse)
		eddy__arena_release(wk->coarse, mark);
	return it;
}

/* DFSPH_DEPTH_REF h / H in a fluid deeper than that, else 1; H is the fluid's
 * extent along gravity (the depth at rest, more while parts of it fly). The
 * column-wide mode's eigenvalue falls relative to the diagonal as (h / H)^2,
 * so a mean residual eps leaves it an error of eps (H / h)^2: the tolerances
 * times its square hold the column to the same fraction at any depth. The
 * gravity limit takes its root (dt ~ h / sqrt(|g| H): the prediction's error
 * grows with the hydrostatic pressure it moves). */
static double depth_scale(eddy_world *w, float h, int threads)
{
	const float *x = eddy__col(w, COL_X_), *y = eddy__col(w, COL_Y_), *z = eddy__col(w, COL_Z_);
	const eddy_vec3 g = eddy__gravity(w);
	const double g1 = sqrt((double)g.x * g.x + (double)g.y * g.y + (double)g.z * g.z);
	if (!(g1 > 0) || !x || !y || !z || w->n == 0)
		return 1;
	double lo = INFINITY, hi = -INFINITY; /* exact: the same for any order */
	const long n = (long)w->n;
	const int nt = loop_threads(n, threads);
#pragma omp parallel for num_threads(nt) if (nt > 1) schedule(static) reduction(min : lo) reduction(max : hi)
	for (long i = 0; i < n; ++i) {
		const double e = ((double)g.x * x[i] + (double)g.y * y[i] + (double)g.z * z[i]) / g1;
		lo = e < lo ? e : lo;
		hi = e > hi ? e : hi;
	}
	const double ref = DFSPH_DEPTH_REF * (double)h, depth = hi - lo;
	return depth > ref ? ref / depth : 1;
}

/* The index of the largest of e[0 .. n) (the first of equals). */
static long argmax(const float *e, long n)
{
	long m = 0;
	for (long i = 0; i < n; ++i)
		m = e[i] > e[m] ? i : m;
	return m;
}

/* The velocity (divergence) or the density solve, adding its k to kp. With
 * the divergence solver it warm-starts from its state column (written back
 * at the end): sweeps could not rebuild each step the pressure that holds up
 * the water above (their error in the column-wide mode falls by 1 - c / N^2 a
 * sweep for N layers, conjugate gradients' by 1 - c / N). It stops once the
 * mean error / rho0 (*residual; the velocity solve's times dt) is at most tol
 * after at least DFSPH_SMOOTH sweeps (velocity) or one iteration (density),
 * or at the cap (*iterations counts both kinds). */
static eddy_status solve(eddy_world *w, eddy_system *sys, dfsph_work *wk, const eddy_step_context *ctx, bool divergence,
                         double tol, double btol, int *iterations, double *residual)
{
	sph_dfsph *sd = sys->data;
	const long n = wk->n;
	const float rho0 = wk->sh->rho0;
	const bool projected = sd->def.divergence_solver;
	float *col = projected ? eddy__col(w, sd->kcol[divergence ? 0 : 1]) : NULL;
	const int nt = loop_threads(n, wk->threads);
	memset(wk->ksum, 0, (size_t)n * sizeof *wk->ksum);
	if (projected) {
#pragma omp parallel for num_threads(nt) if (nt > 1) schedule(static)
		for (long i = 0; i < n; ++i) {
			if (divergence) { /* b.w: the velocity solve's particles (dfsph_work) */
				/* not one leaving its walls with no pressure (wall_sums' mark):
				 * held to them it would hang from a lid (header) */
				wk->b[i].w = wk->rho[i] >= DFSPH_SURFACE * rho0 && !wk->mask[i] ? 1.0f : 0.0f;
			}
			/* the velocity solve's k of either sign on its particles, the density solve's k >= 0 */
			wk->k[i] = divergence ? (wk->b[i].w > 0 ? col[i] : 0.0f) : (col[i] > 0 ? col[i] : 0.0f);
		}
		pass(wk, PASS_CORRECT, divergence, true);
	}
	const int cap = divergence ? sd->def.max_divergence_iterations : sd->def.max_iterations;
	int it = 0, sweeps = 0;
	for (;;) {
		bool fresh = false;
		double berr = 0;
		if (projected)
			it += divergence_cg(wk, cap - it, !divergence, tol, btol, residual, &berr, &fresh);
		const dfsph_pass sweep = {wk, PASS_SWEEP, divergence, projected, false, fresh};
		pass_run(wk, &sweep);
		const long nc = sum_chunks(n);
		const int ct = cg_threads(wk);
#pragma omp parallel for num_threads(ct) if (ct > 1) schedule(dynamic, 1)
		for (long c = 0; c < nc; ++c) {
			double sum = 0;
			float mx = 0;
			for (long i = c * DFSPH_SUM_CHUNK, e = chunk_end(c, n); i < e; ++i) {
				sum += wk->err[i];
				mx = wk->err[i] > mx ? wk->err[i] : mx;
			}
			wk->part[c] = (dfsph_sums){sum, mx};
		}
		*residual = sums_total(wk->part, nc).a / (double)n / rho0;
		double worst = 0; /* the density solve's largest predicted compression / rho0 */
		for (long c = 0; c < nc; ++c)
			worst = wk->part[c].b > worst ? wk->part[c].b : worst;
		worst /= rho0;
		const bool enough = divergence ? sweeps >= DFSPH_SMOOTH : it >= 1;
		if ((enough && *residual <= tol && berr <= btol && (divergence || worst <= DFSPH_MAX_COMPRESSION)) || it >= cap)
			break;
		pass(wk, PASS_CORRECT, divergence, projected);
		++it;
		++sweeps;
	}
	*iterations = it;
	if (divergence)
		sd->capped = it >= cap && *residual > DFSPH_FAIL_CAPPED_ERROR * tol ? sd->capped + 1 : 0;
	if (divergence && sd->capped >= DFSPH_FAIL_CAPPED) {
		const long wi = argmax(wk->err, n);
		return eddy__fail(w, EDDY_ERR_NUMERIC,
		                  "%s: the velocity solve did not converge at step %lld: mean error %.3g after %d "
		                  "iterations in %d steps in a row (max_divergence_error %g), worst at particle %ld "
		                  "(%.3g); the water may be too deep for it: raise max_divergence_iterations or lower "
		                  "the world's cfl",
		                  sys->label, (long long)ctx->step, *residual, it, sd->capped,
		                  (double)sd->def.max_divergence_error, wi, wk->err[wi] / rho0);
	}
	if (divergence) /* the density solve's k goes to its column in finish */
		memcpy(col, wk->ksum, (size_t)n * sizeof *col);
	return EDDY_OK;
}

/* The step's scratch in the world's arena for rows 0 .. n - 1 of sph_density's
 * lists, and the gradient pass on them; false when out of memory. */
static bool prepare(eddy_world *w, dfsph_work *wk, const sph_shared *sh, long n, float dt, int threads, bool free_walls,
                    const float *kv, const float *kd)
{
	const size_t un = (size_t)n;
	*wk = (dfsph_work){.n = n, .dt = dt, .threads = threads, .sh = sh, .bdiv = sh->nb.bdiv, .kprev = {kv, kd}};
	wk->beta = 1;
	wk->block = SIMD_PICK(dfsph_block);
	wk->rho = eddy__col(w, COL_DENSITY);
	wk->gravity = eddy__gravity(w);
	for (int d = 0; d < 3; ++d) { /* the step's (free walls), not the probe's */
		wk->vel[d] = free_walls ? eddy__col(w, COL_VX + d) : NULL;
		wk->acc[d] = free_walls ? eddy__col(w, COL_AX + d) : NULL;
	}
	dfsph_vec4 **quads[] = {&wk->b, &wk->v, &wk->u};
	float **floats[] = {&wk->dsym, &wk->k, &wk->ksum, &wk->err, &wk->r};
	bool ok = true;
	for (size_t a = 0; a < sizeof quads / sizeof *quads; ++a)
		ok = ok && (*quads[a] = eddy__arena_alloc(&w->arena, un * sizeof(dfsph_vec4)));
	for (size_t a = 0; a < sizeof floats / sizeof *floats; ++a)
		ok = ok && (*floats[a] = eddy__arena_alloc(&w->arena, un * sizeof(float)));
	ok = ok && (wk->mask = eddy__arena_alloc(&w->arena, un));
	ok = ok && (wk->part = eddy__arena_alloc(&w->arena, (size_t)sum_chunks(n) * sizeof *wk->part));
	if (!ok)
		return false;
	wk->p = wk->k;
	/* G_ij stored only while they fit DFSPH_STORE_BYTES: a sweep then streams
	 * them; beyond, they would fall out of cache and reading them back costs
	 * more than a square root, a division and a position gather per pair */
	uint64_t groups = 0;
	const int nt = loop_threads(n, threads);
#pragma omp parallel for num_threads(nt) if (nt > 1) schedule(static) reduction(+ : groups)
	for (long i = 0; i < n; ++i)
		groups += (sh->nb.count[i] + 7) / 8;
	if (groups * sizeof(dfsph_group) <= DFSPH_STORE_BYTES) {
		wk->goff = eddy__arena_alloc(&w->arena, (un + 1) * sizeof *wk->goff);
		wk->gs = eddy__arena_alloc(&w->arena, (size_t)groups * sizeof *wk->gs + 1);
		if (!wk->goff || !wk->gs)
			return false;
		wk->goff[0] = 0;
		for (long i = 0; i < n; ++i)
			wk->goff[i + 1] = wk->goff[i] + (sh->nb.count[i] + 7) / 8;
	}
	pass(wk, PASS_GRADIENTS, false, false);
	return true;
}

/* a += (v* - (v + dt a)) / dt, p = M kp rho^2 (kp the sum of the solves' k:
 * the velocity solve's from its column, the density solve's still in ksum)
 * and the frame's statistics;
 * fails on a non-finite result or when the density solve lost the fluid. */
static eddy_status finish(eddy_world *w, const eddy_system *sys, const dfsph_work *wk, const eddy_step_context *ctx,
                          int it, double residual, int div_it, double div_residual)
{
	sph_dfsph *sd = sys->data;
	const float dt = wk->dt, inv_dt = 1.0f / dt;
	const float *vx = eddy__col(w, COL_VX), *vy = eddy__col(w, COL_VY), *vz = eddy__col(w, COL_VZ);
	float *ax = eddy__col(w, COL_AX), *ay = eddy__col(w, COL_AY), *az = eddy__col(w, COL_AZ);
	float *p = eddy__col(w, COL_PRESSURE);
	float *kdiv = sd->def.divergence_solver ? eddy__col(w, sd->kcol[0]) : NULL;
	float *kden = sd->def.divergence_solver ? eddy__col(w, sd->kcol[1]) : NULL;
	long bad = wk->n; /* the first non-finite row, n for none */
	const int nt = loop_threads(wk->n, wk->threads);
#pragma omp parallel for num_threads(nt) if (nt > 1) schedule(static) reduction(min : bad)
	for (long i = 0; i < wk->n; ++i) {
		ax[i] += (wk->v[i].x - (vx[i] + dt * ax[i])) * inv_dt;
		ay[i] += (wk->v[i].y - (vy[i] + dt * ay[i])) * inv_dt;
		az[i] += (wk->v[i].z - (vz[i] + dt * az[i])) * inv_dt;
		const float kd = kdiv ? kdiv[i] : 0.0f, kp = (0.0f + kd) + wk->ksum[i];
		p[i] = kp * wk->rho[i] * wk->rho[i] / wk->sh->grad_cal;
		if (kden) { /* the warm starts (header): the velocity solve's less the density solve's change */
			kdiv[i] = kd - (wk->ksum[i] - kden[i]);
			kden[i] = wk->ksum[i];
		}
		if (i < bad && !(isfinite(ax[i]) && isfinite(ay[i]) && isfinite(az[i]) && isfinite(p[i])))
			bad = i;
	}
	if (bad < wk->n)
		return eddy__fail(
			w, EDDY_ERR_NUMERIC,
			"%s: non-finite pressure acceleration at step %lld, particle %ld (density %g kg/m^3, %u neighbours)",
			sys->label, (long long)ctx->step, bad, (double)wk->rho[bad], wk->sh->nb.count[bad]);
	/* the particle the solve left furthest off (the last sweep's errors) */
	const long worst = argmax(wk->err, wk->n);
	const double worst_err = wk->err[worst] / wk->sh->rho0;
	if (sd->frame != w->frame) {
		sd->frame = w->frame;
		sd->steps = sd->sweeps = sd->div_sweeps = sd->unconverged = 0;
		sd->residual = sd->worst = 0;
	}
	sd->steps++;
	sd->sweeps += it;
	sd->div_sweeps += div_it;
	/* a step whose density solve hit its cap short of either stopping rule
	 * (the mean, or one particle's compression: DFSPH_MAX_COMPRESSION) */
	const bool density_short = residual > sd->def.max_density_error || worst_err > DFSPH_MAX_COMPRESSION;
	const bool density_capped = it >= sd->def.max_iterations && density_short;
	const bool divergence_capped =
		div_it >= sd->def.max_divergence_iterations && div_residual > sd->def.max_divergence_error;
	sd->unconverged += density_capped || divergence_capped;
	if (density_capped || divergence_capped) {
		char key[sizeof sys->label + 16];
		snprintf(key, sizeof key, "%s:%s", sys->label, density_capped ? "density" : "divergence");
		if (density_capped)
			eddy__warn(w, key,
			           "%s: the density solve stopped at its cap (max_iterations = %d) at step %lld: mean density "
			           "error %.3g (max_density_error %g), particle %ld off by %.3g; the run goes on less "
			           "incompressible (the stats' unconverged counts such steps): lower the world's cfl or raise "
			           "max_iterations",
			           sys->label, sd->def.max_iterations, (long long)ctx->step, residual,
			           (double)sd->def.max_density_error, worst, worst_err);
		else
			eddy__warn(w, key,
			           "%s: the divergence solve stopped at its cap (max_divergence_iterations = %d) at step %lld: "
			           "mean divergence error %.3g (max_divergence_error %g); the run goes on (the stats' "
			           "unconverged counts such steps): lower the world's cfl or raise max_divergence_iterations",
			           sys->label, sd->def.max_divergence_iterations, (long long)ctx->step, div_residual,
			           (double)sd->def.max_divergence_error);
	}
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
		                  "(max_density_error %g), particle %ld at (%g, %g, %g) m off by %.3g; lower the "
		                  "world's cfl or raise max_iterations",
		                  sys->label, (long long)ctx->step, residual, it, (double)sd->def.max_density_error, worst,
		                  (double)eddy__col(w, COL_X_)[worst], (double)eddy__col(w, COL_Y_)[worst],
		                  (double)eddy__col(w, COL_Z_)[worst], worst_err);
	return EDDY_OK;
}

/* The walls' normals at particle i, for the shift: the eigenvectors of the
 * wall tensor T_i = sum_b V_b |grad W(x_i - x_b)| e_b e_b^T (e_b the unit
 * vector from x_b to x_i) whose eigenvalue is at least half the largest.
 * Beside one flat wall of the box's lattice T has its normal's eigenvalue
 * 4x its two tangential ones; at an edge the two normals' are 0.8 of each
 * other and the edge's 0.37 of the largest; at a corner the three are
 * within 0.75 of each other: the half splits the normals from the
 * directions along the walls (tabled with the lattice at dx / 2 from the
 * walls; a particle farther off sees fewer wall particles, nearer the
 * normal). Cyclic Jacobi rotations on the 3 x 3 (Golub & Van Loan 8.5),
 * a fixed number of sweeps: the same bits on every thread. Returns how
 * many normals it wrote into n (0: no wall within h). */
static int wall_normals(const sph_shared *sh, long i, float n[3][3])
{
	const sph_neighbors *nb = &sh->nb;
	const float *pi = sh->pq + 4 * i, eps2 = 1e-6f * sh->k.h2;
	const uint32_t *blist = sph_bnbrs(nb, i), bcnt = nb->bcount[i];
	double a[3][3] = {{0}}, v[3][3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
	for (uint32_t p = 0; p < bcnt; ++p) {
		const uint32_t b = blist[p];
		const double r[3] = {pi[0] - nb->bx[b], pi[1] - nb->by[b], pi[2] - nb->bz[b]};
		const double r2 = r[0] * r[0] + r[1] * r[1] + r[2] * r[2], d = sqrt(r2), hr = sh->k.h - d;
		if (!(r2 > eps2) || !(hr > 0))
			continue;
		const double wgt = nb->bvol[b] * hr * hr / r2; /* |grad W| / r^2 up to the constant, for e e^T = r r^T */
		for (int x = 0; x < 3; ++x)
			for (int y = 0; y < 3; ++y)
				a[x][y] += wgt * r[x] * r[y];
	}
	for (int sweep = 0; sweep < 8; ++sweep)
		for (int p = 0; p < 2; ++p)
			for (int q = p + 1; q < 3; ++q) {
				if (fabs(a[p][q]) <= 1e-12 * (fabs(a[p][p]) + fabs(a[q][q])))
					continue;
				const double th = (a[q][q] - a[p][p]) / (2 * a[p][q]);
				const double t = (th >= 0 ? 1 : -1) / (fabs(th) + sqrt(th * th + 1)), c = 1 / sqrt(t * t + 1),
							 sn = t * c;
				for (int k = 0; k < 3; ++k) { /* A <- A J */
					const double kp = a[k][p], kq = a[k][q];
					a[k][p] = c * kp - sn * kq;
					a[k][q] = sn * kp + c * kq;
				}
				for (int k = 0; k < 3; ++k) { /* A <- J^T A */
					const double pk = a[p][k], qk = a[q][k];
					a[p][k] = c * pk - sn * qk;
					a[q][k] = sn * pk + c * qk;
				}
				for (int k = 0; k < 3; ++k) { /* V <- V J: the columns are the eigenvectors */
					const double kp = v[k][p], kq = v[k][q];
					v[k][p] = c * kp - sn * kq;
					v[k][q] = sn * kp + c * kq;
				}
			}
	const double top = fmax(a[0][0], fmax(a[1][1], a[2][2]));
	int m = 0;
	for (int e = 0; e < 3 && top > 0; ++e)
		if (a[e][e] >= 0.5 * top) {
			for (int k = 0; k < 3; ++k)
				n[m][k] = (float)v[k][e];
			m++;
		}
	return m;
}

/* Particle shifting (header): x_i -= shift h^2 grad C_i where particle i and
 * all its neighbours have a kernel sum of at least DFSPH_SHIFT_SURFACE rho0,
 * its own at least DFSPH_SHIFT_FLOOR rho0;
 * beside a wall only the part of it along the wall (wall_normals' normals
 * projected out), the velocities kept. Each particle moves by its own grad
 * C, made before any moved: the same for any thread count. */
static void shift(eddy_world *w, const sph_dfsph *sd, const dfsph_work *wk)
{
	const float full = DFSPH_SHIFT_SURFACE * wk->sh->rho0, d = sd->def.shift * wk->sh->h * wk->sh->h;
	const float floor_rho = DFSPH_SHIFT_FLOOR * wk->sh->rho0;
	const float irho0 = 1.0f / wk->sh->rho0;
	float *x = eddy__col(w, COL_X_), *y = eddy__col(w, COL_Y_), *z = eddy__col(w, COL_Z_);
	const int nt = loop_threads(wk->n, wk->threads);
#pragma omp parallel for num_threads(nt) if (nt > 1) schedule(static)
	for (long i = 0; i < wk->n; ++i) {
		const dfsph_vec4 c = wk->u[i];
		/* c.w * full <= 1: no neighbour below full (c.w is 1 / the least rho_j) */
		if (!(wk->rho[i] >= full && c.w * full <= 1.0f) || !(wk->rho[i] >= floor_rho))
			continue;
		float s[3] = {c.x, c.y, c.z};
		const sph_neighbors *nb = &wk->sh->nb;
		if (nb->bcount[i]) {
			/* beside a collider's particles (after the boxes' n_static) no
			 * shift at all: their sampling of a mesh or a sphere gives the
			 * tensor no clean normals, and a shift pushed water into a mesh
			 * cup's wall (test_mesh's cup at 3 mm). The boundary list is
			 * ascending, so its last entry says whether it holds one. */
			if (sph_bnbrs(nb, i)[nb->bcount[i] - 1] >= nb->bnd.n_static)
				continue;
			/* the walls' volumes too, as the force counts them (B_i / rho0 =
			 * sum_b V_b grad W(x_i - x_b)), then only the part along the walls */
			s[0] += wk->b[i].x * irho0;
			s[1] += wk->b[i].y * irho0;
			s[2] += wk->b[i].z * irho0;
			float n[3][3];
			const int m = wall_normals(wk->sh, i, n);
			for (int e = 0; e < m; ++e) {
				const float sn = s[0] * n[e][0] + s[1] * n[e][1] + s[2] * n[e][2];
				for (int k = 0; k < 3; ++k)
					s[k] -= sn * n[e][k];
			}
		}
		x[i] -= d * s[0];
		y[i] -= d * s[1];
		z[i] -= d * s[2];
	}
}

/* The blocks of block_error over the rows' bounding box: cubes of side
 * DFSPH_BLOCK_H h, larger while there would be more than DFSPH_BLOCKS_MAX
 * of them (a particle flying far). */
static bool blocks(eddy_world *w, dfsph_work *wk)
{
	float lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
	const float *pq = wk->sh->pq;
	for (long i = 0; i < wk->n; ++i)
		for (int d = 0; d < 3; ++d) {
			lo[d] = pq[4 * i + d] < lo[d] ? pq[4 * i + d] : lo[d];
			hi[d] = pq[4 * i + d] > hi[d] ? pq[4 * i + d] : hi[d];
		}
	for (int d = 0; d < 3; ++d)
		if (!(hi[d] - lo[d] < INFINITY)) /* no finite position, or a span that overflows: one block */
			lo[d] = hi[d] = 0;
	double side = DFSPH_BLOCK_H * wk->sh->h, cells;
	for (;;) {
		cells = 1;
		for (int d = 0; d < 3; ++d)
			cells *= floor((double)(hi[d] - lo[d]) / side) + 1;
		if (cells <= DFSPH_BLOCKS_MAX)
			break;
		side *= 2;
	}
	for (int d = 0; d < 3; ++d) {
		wk->borg[d] = lo[d];
		wk->bdim[d] = (int)(floor((double)(hi[d] - lo[d]) / side) + 1);
	}
	wk->binv = (float)(1 / side);
	wk->bsum = eddy__arena_alloc(&w->arena, (size_t)cells * sizeof *wk->bsum);
	wk->bcnt = eddy__arena_alloc(&w->arena, (size_t)cells * sizeof *wk->bcnt);
	return wk->bsum && wk->bcnt;
}

static eddy_status step(eddy_world *w, eddy_system *sys, const eddy_step_context *ctx)
{
	sph_dfsph *sd = sys->data;
	const sph_shared *sh = eddy__sph_find(w, sys);
	if (!sh)
		return eddy__fail(w, EDDY_ERR_ORDER, "%s: needs sph_density before it (it builds the neighbour lists)",
		                  sys->label);
	const long n = sph_rows(w, sh);
	const float dt = (float)ctx->dt;
	if (n == 0 || !(dt > 0))
		return EDDY_OK;
	if ((uint64_t)n > (uint64_t)UINT32_MAX) /* the lists and the padding hold rows in 32 bits */
		return eddy__fail(w, EDDY_ERR_INVALID, "%s: too many particles (%ld)", sys->label, n);
	/* the velocity solve's warm start when there is none (dfsph_warm.c), its
	 * scratch released before the step's */
	if (sd->def.divergence_solver && sd->def.hydrostatic_start)
		eddy__dfsph_hydrostatic_start(w, sh, n, eddy__col(w, sd->kcol[0]));
	dfsph_work wk;
	const bool warm = sd->def.divergence_solver;
	if (!prepare(w, &wk, sh, n, dt, ctx->threads, true, warm ? eddy__col(w, sd->kcol[0]) : NULL,
	             warm ? eddy__col(w, sd->kcol[1]) : NULL))
		return eddy__fail(w, EDDY_ERR_NOMEM, "%s: out of scratch memory for %ld particles", sys->label, n);
	if (!sd->def.divergence_solver) { /* the cold solve's soft correction (header) */
		const eddy_vec3 g = eddy__gravity(w);
		const double g2 = (double)g.x * g.x + (double)g.y * g.y + (double)g.z * g.z;
		if (g2 > 0) {
			const double tau = DFSPH_SOFT_TIME * sqrt(sh->h / sqrt(g2));
			wk.beta = (float)(dt / (dt + tau));
		}
	}
	const float *vx = eddy__col(w, COL_VX), *vy = eddy__col(w, COL_VY), *vz = eddy__col(w, COL_VZ);
	const float *ax = eddy__col(w, COL_AX), *ay = eddy__col(w, COL_AY), *az = eddy__col(w, COL_AZ);
	const int nt = loop_threads(n, wk.threads);
#pragma omp parallel for num_threads(nt) if (nt > 1) schedule(static)
	for (long i = 0; i < n; ++i)
		wk.v[i] = (dfsph_vec4){vx[i] + dt * (ax[i] + wk.u[i].x), vy[i] + dt * (ay[i] + wk.u[i].y),
		                       vz[i] + dt * (az[i] + wk.u[i].z), 0}; /* u: h_i until now */
	const double scale = sd->def.divergence_solver ? depth_scale(w, sh->h, ctx->threads) : 1;
	wk.coarse = sd->def.coarse_grid && scale < 1 ? &w->arena : NULL;
	int it, div_it = 0;
	double residual, div_residual = 0;
	if (sd->def.divergence_solver) {
		const double dtol = sd->def.max_divergence_error * scale * scale;
		const double btol = DFSPH_BLOCK_TOL * sd->def.max_divergence_error * scale;
		if (!blocks(w, &wk))
			return eddy__fail(w, EDDY_ERR_NOMEM, "%s: out of scratch memory for %ld particles", sys->label, n);
		const eddy_status st = solve(w, sys, &wk, ctx, true, dtol, btol, &div_it, &div_residual);
		if (st != EDDY_OK)
			return st;
	}
	/* the density solve: its mean alone (its column-wide error is the bottom pressure, which the tests hold) */
	solve(w, sys, &wk, ctx, false, sd->def.max_density_error * scale * scale, 0, &it, &residual);
	const eddy_status st = finish(w, sys, &wk, ctx, it, residual, div_it, div_residual);
	if (st == EDDY_OK && sd->def.shift > 0) {
		pass(&wk, PASS_CONCENTRATION, false, false);
		shift(w, sd, &wk);
	}
	return st;
}

/* For tests/test_sph_reference.c, after a step of w, on the last lists and
 * the back-end SIMD_PICK gives now, per particle: inv_d = 1 / D_i, inv_dsym
 * = 1 / D'_i, rate = R_i(v) of the velocity columns (the wall counted twice),
 * acc[3 i ..] = -(sum_j (k_i + k_j) G_ij + 2 k_i B_i) for k_i = k[i]. */
eddy_status eddy__dfsph_probe(eddy_world *w, const float *k, float *inv_d, float *inv_dsym, float *rate, float *acc);
eddy_status eddy__dfsph_probe(eddy_world *w, const float *k, float *inv_d, float *inv_dsym, float *rate, float *acc)
{
	const sph_shared *sh = eddy__sph_find(w, NULL);
	if (!sh)
		return EDDY_ERR_ORDER;
	const long n = sph_rows(w, sh);
	dfsph_work wk;
	if (!prepare(w, &wk, sh, n, 1.0f, 1, false, NULL, NULL))
		return EDDY_ERR_NOMEM;
	memcpy(wk.p, k, (size_t)n * sizeof *k);
	operator_product(&wk); /* the conjugate gradients' A p: u = -dt (...) for k = p, dt = 1 */
	const float *vx = eddy__col(w, COL_VX), *vy = eddy__col(w, COL_VY), *vz = eddy__col(w, COL_VZ);
	for (long i = 0; i < n; ++i)
		wk.v[i] = (dfsph_vec4){vx[i], vy[i], vz[i], 0};
	wk.err = rate;
	pass(&wk, PASS_RATE, true, true);
	for (long i = 0; i < n; ++i) {
		inv_d[i] = wk.b[i].w;
		inv_dsym[i] = wk.dsym[i];
		acc[3 * i] = wk.u[i].x;
		acc[3 * i + 1] = wk.u[i].y;
		acc[3 * i + 2] = wk.u[i].z;
	}
	return EDDY_OK;
}

static double limit(eddy_world *w, eddy_system *s, const char **reason)
{
	const sph_shared *sh = eddy__sph_find(w, s);
	*reason = "velocity";
	if (!sh)
		return INFINITY;
	const float v2 = eddy__max_norm2(w, COL_VX, COL_VY, COL_VZ);
	const double lv = v2 > 0 ? (double)sh->h / sqrt((double)v2) : INFINITY;
	const eddy_vec3 g = eddy__gravity(w);
	const double g1 = sqrt((double)g.x * g.x + (double)g.y * g.y + (double)g.z * g.z);
	double la = g1 > 0 ? DFSPH_GRAVITY_LIMIT * sqrt((double)sh->h / g1) : INFINITY;
	if (((const sph_dfsph *)s->data)->def.divergence_solver)
		la *= sqrt(depth_scale(w, sh->h, w->def.threads));
	*reason = la < lv ? "gravity" : "velocity";
	return la < lv ? la : lv;
}

static const int no_hint_writes[] = {-1};

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
	if (!eddy__add_args(w, def, sys) || !eddy__check_positive(w, sys, "max_density_error", def->max_density_error) ||
	    !eddy__check_range(w, sys, "max_density_error", def->max_density_error, 0, 0.1) ||
	    !eddy__check_positive(w, sys, "max_divergence_error", def->max_divergence_error) ||
	    !eddy__check_range(w, sys, "max_divergence_error", def->max_divergence_error, 0, 1) ||
	    !eddy__check_range(w, sys, "shift", def->shift, 0, 0.1))
		return EDDY_NULL_SYSTEM;
	const bool it_bad = def->max_iterations < 2 || def->max_iterations > 10000;
	if (it_bad || def->max_divergence_iterations < 1 || def->max_divergence_iterations > 10000)
		return eddy__fail(w, EDDY_ERR_INVALID, "%s: '%s' must be between %d and 10000 (got %d)", sys,
		                  it_bad ? "max_iterations" : "max_divergence_iterations", it_bad ? 2 : 1,
		                  it_bad ? def->max_iterations : def->max_divergence_iterations),
		       EDDY_NULL_SYSTEM;
	sph_dfsph *sd = calloc(1, sizeof *sd);
	if (!sd)
		return eddy__fail(w, EDDY_ERR_NOMEM, "%s: out of memory", sys), EDDY_NULL_SYSTEM;
	sd->def = *def;
	sd->frame = -1;
	sd->kcol[0] = sd->kcol[1] = -1;
	/* the warm starts' state columns, shared by the sph_dfsph systems of a
	 * world (each writes its own fluid's rows) */
	const char *names[2] = {"dfsph_k", "dfsph_kd"};
	for (int c = 0; c < 2 && def->divergence_solver; ++c) {
		sd->kcol[c] = eddy_world_find_column(w, names[c]);
		if (sd->kcol[c] < 0)
			sd->kcol[c] =
				eddy_world_declare_column(w, names[c], EDDY_DOMAIN_PARTICLE, EDDY_F32, EDDY_STATE, "m^5/(kg s^2)");
		if (sd->kcol[c] < 0) {
			free(sd);
			return EDDY_NULL_SYSTEM;
		}
	}
	/* without the divergence solver the lists end at kcol[0] = -1 */
	const int reads[] = {COL_X_, COL_Y_, COL_Z_, COL_VX,      COL_VY,      COL_VZ, COL_DENSITY,
	                     COL_AX, COL_AY, COL_AZ, sd->kcol[0], sd->kcol[1], -1};
	/* the warm starts' columns, then with the shift the positions; the list
	 * ends at the first -1 */
	int writes[] = {COL_PRESSURE, COL_AX, COL_AY, COL_AZ, -1, -1, -1, -1, -1, -1}, nw = 4;
	for (int c = 0; c < 2 && def->divergence_solver; ++c)
		writes[nw++] = sd->kcol[c];
	if (def->shift > 0) {
		writes[nw++] = COL_X_;
		writes[nw++] = COL_Y_;
		writes[nw++] = COL_Z_;
	}
	return eddy__add_system(w, &eddy__kind_sph_dfsph, sd, reads, writes);
}
#endif /* EDDY_SIMD_VARIANT */
