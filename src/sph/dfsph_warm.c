/* SPDX-License-Identifier: MIT */
/* sph_dfsph's hydrostatic cold start: the velocity solve's first guess for
 * water that starts at rest and has no k of its own yet.
 *
 * Reads: the rows' positions (sph_shared pq) and velocities, the neighbour
 * grid's cells (neighbors.h: fluid_start), the boundary neighbour
 * counts, gravity. Writes: the velocity solve's warm-start column k.
 *
 * Why: each solve starts from its k of the last step (Bender & Koschier's
 * warm start). A block emitted at rest has none, and the velocity solve
 * must build its pressure from k = 0; the column-wide error falls by only
 * 1 - c/N a conjugate-gradient iteration for N layers, so the two first
 * steps took 69 iterations at 46 layers (bench_scale's block), 330 at 100,
 * and a closed tank 100 layers deep stopped at the 1000-iteration cap.
 * Started near the answer, the solve has mostly the particle-scale error
 * of the estimate to remove. The estimate is only the start: the converged
 * k is the solve's, to its tolerance.
 *
 * The estimate: the pressure of incompressible water released at rest, the
 * solution of the Laplace equation with p = 0 on the free surfaces, the
 * normal gradient rho0 g . n on the walls, for a box-shaped body of water
 * (separation of variables): H deep on a floor, along each horizontal axis
 * either walled at both ends (the mode k = 0: no change along it), free at
 * both ends L apart, or free at one and walled at the other (its mirror
 * image: free at both ends 2L apart), with xi the distance from a free end:
 *   p / (rho0 |g_a|) = sum_{j,l odd} c_j c_l sin(k_j xi_u) sin(k_l xi_v)
 *                      sinh(K eta) / (K cosh(K H)),
 *   k_j = j pi / L_u, c_j = 4 / (j pi), K^2 = k_j^2 + k_l^2,
 * eta the depth below the surface; a tank walled all round gives the
 * hydrostatic p = rho0 |g| eta, a free-standing block (a dam break, the
 * benchmark's settling block) much less near its free sides. sph_dfsph's k
 * is grad_cal p / rho^2 (its force has no lattice factor; it reports k
 * rho^2 / grad_cal), taken at rho0:
 *   k_i = grad_cal p_i / rho0^2.
 * The surface and the free sides lie half a spacing s = (m / rho0)^(1/3)
 * beyond the outermost particles' centres, the floor half a spacing below
 * the lowest. Measured on the emitted lattice: the converged k of a
 * 40-layer column in a closed tank fits 1.039e-2 (d + 0.0048) m^5/(kg s^2)
 * for s = 1 cm (grad_cal |g| / rho0 = 1.039e-2), the top layer 5.2e-5
 * against 5.0e-5; in a free 30-layer cube the estimate is within 3-5% of
 * the solve's converged k (tolerance 1e-9) along the centre column and
 * 5-25% low at the bottom edge. An oblique gravity takes its dominant axis
 * a and that component g_a: exact for a surface at rest (perpendicular to
 * g, dp/dx_a = rho0 g_a), an estimate otherwise.
 *
 * The shape: on the neighbour grid's cells (h/2), along each axis a line of
 * cells holds runs, stretches of occupied cells with no gap of RUN_GAP or
 * more empty ones. Along gravity, from the top down: a run's surface is its
 * top cell's highest particle and its depth H reaches its bottom cell's
 * lowest; it gets an estimate only if it rests on a wall (a particle of its
 * bottom cell has a boundary neighbour at least s/2 below it, within 35
 * degrees of straight below: sph_boundary_box or a collider's particles,
 * not the foot of a side wall) and none of its particles falls faster than sqrt(|g| h) (a fall
 * of h/2): water in free fall, or a jet, has no hydrostatic pressure, and a
 * vertical jet's run is as long as the jet. Across gravity: an end of a run
 * is walled if one of its end cell's particles has a boundary neighbour at
 * least s/2 beyond it and not below it (the floor under a free side's
 * bottom particle is a spacing below). Each particle takes the box its
 * three runs span: exact for boxes, an estimate for other shapes.
 *
 * When: only when every k of the rows is 0: there is no state (the first
 * step, a resumed checkpoint of one; the k column is state, so a resumed
 * run decides as the original did), or all the water is without pressure.
 * Not per particle whose k is 0: the free surface's outermost particles
 * carry k = 0 at rest, and an emitter's new particles (a pour's jet) fall
 * with about 0 pressure; once any k is positive the warm start of the last
 * step is the better guess. The density solve keeps its own warm start: at
 * rest its k is about 0 (the velocity solve carries the pressure; measured:
 * 1e-7 of it, 40 layers). Without the divergence solver there are no warm
 * starts at all (sph_dfsph's cold density solve).
 *
 * Where it does not pay: a free-standing block at a large step (CFL 0.5 at
 * 100 frames/s, the tolerance tight next to dt^2 g) whose converged k has
 * a lattice-scale pattern of inactive particles (k = 0): warm-started, all
 * its particles are in the conjugate gradients' active set, which then
 * takes longer to find them (36-47 layer cubes: 151-363 iterations against
 * 117-206 cold; 50 layers 43 against 178). At 1 ms steps (bench_scale) and
 * in closed tanks it pays at every size measured.
 *
 * Everything is serial, in row and cell order: the same bits for any
 * thread count. Cost, once: three walks over the cells of the particles'
 * box, and per particle the series' terms with K (H - eta) <= 12, at most
 * SIDE_MODES^2 (near the floor), a few elsewhere. While every k is 0 and
 * no particle touches a wall (water in free fall) each step pays one or
 * two passes over the rows and no walk.
 *
 * Sources: Bender & Koschier, SCA 2015 (the warm start); the initial
 * pressure of a released body of water as a Laplace problem with p = 0 on
 * its free surface: Penney & Thornhill, Phil. Trans. R. Soc. A 244, 1952
 * (the dam break's initial motion), solved here by separation of variables
 * in a box. */
#include "dfsph_warm.h"

#include "neighbors.h"

#include <math.h>

/* Empty cells (of h/2) in a row that end a run: one empty cell is a
 * lattice's jitter across a cell face, two (h) a gap in the water. */
#define RUN_GAP 2

/* The most modes per horizontal axis of a block's pressure (block_depth). */
#define SIDE_MODES 24

typedef struct warm_walk {
	const sph_neighbors *nb;
	const sph_grid *g; /* the cells' row ranges: cell_lo, cell_hi */
	const float *pq;   /* (x y z 1/rho) quads */
	long n;
	float s;          /* m, the particle spacing */
	int lo[3], hi[3]; /* the occupied cells' box (inclusive), per axis */
	size_t stride[3];
} warm_walk;

/* The first row of cell c and the row after its last (the table in cell order). */
static inline uint32_t cell_lo(const sph_grid *g, size_t c)
{
	return sph_cell_start(g, &g->fluid_start, c / (size_t)g->gx, (int)(c % (size_t)g->gx));
}

static inline uint32_t cell_hi(const sph_grid *g, size_t c)
{
	return sph_cell_start(g, &g->fluid_start, c / (size_t)g->gx, (int)(c % (size_t)g->gx) + 1);
}

/* A run of occupied cells along axis b of the line through cell base: from
 * layer l (occupied) on, in steps dl, until RUN_GAP empty cells or the
 * occupied box's end; returns its last occupied layer. */
static int run_end(const warm_walk *ww, size_t base, int b, int l, int dl)
{
	int last = l;
	for (int m = l, gap = 0; m >= ww->lo[b] && m <= ww->hi[b] && gap < RUN_GAP; m += dl) {
		const size_t c = base + (size_t)m * ww->stride[b];
		if (cell_lo(ww->g, c) == cell_hi(ww->g, c))
			++gap;
		else
			gap = 0, last = m;
	}
	return last;
}

/* Whether a particle of cell c has a boundary neighbour beyond it along
 * axis b in direction dir (at least s/2 further): along gravity (b = a) one
 * within 35 degrees of straight below (a floor, not a side wall's foot);
 * across gravity one not below it (the floor under a free side's bottom
 * particle is a spacing below it, a side wall beside it). */
static bool walled(const warm_walk *ww, size_t c, int b, float dir, int a, float up)
{
	const sph_neighbors *nb = ww->nb;
	const float *bp[3] = {nb->bx, nb->by, nb->bz};
	for (uint32_t i = cell_lo(ww->g, c), iend = cell_hi(ww->g, c); i < iend && (long)i < ww->n; ++i) {
		const uint32_t *bl = sph_bnbrs(nb, i);
		const float *pi = ww->pq + 4 * (size_t)i;
		for (uint32_t q = 0; q < nb->bcount[i]; ++q) {
			float d[3];
			for (int e = 0; e < 3; ++e)
				d[e] = bp[e][bl[q]] - pi[e];
			const float across = d[0] * d[0] + d[1] * d[1] + d[2] * d[2] - d[b] * d[b];
			/* along gravity: more below than beside (not a side wall's foot) */
			const bool placed = b == a ? 2 * across < d[a] * d[a] : d[a] * up >= -0.5f * ww->s;
			if (d[b] * dir >= 0.5f * ww->s && placed)
				return true;
		}
	}
	return false;
}

/* The pressure (/ rho0 |g|, m) at depth eta in a block H deep on a floor,
 * at xi[b] from its free end along each horizontal axis b, the axis's
 * half-wavelength span L[b] (header; L[b] = 0: walled at both ends):
 *   sum_{j,l odd} c_j c_l sin(k_j xi_u) sin(k_l xi_v) sinh(K eta) / (K cosh(K H)),
 *   k_j = j pi / L_u, c_j = 4 / (j pi), K^2 = k_j^2 + k_l^2,
 * a walled-walled axis contributing the one term k = 0, c = 1, sin -> 1
 * (both walled: eta, the hydrostatic depth). Terms with K (H - eta) above
 * 12 (e^-12) are left out, and modes above SIDE_MODES per axis. */
static float block_depth(float eta, float H, const float xi[2], const float L[2])
{
	double k[2][SIDE_MODES], ph[2][SIDE_MODES];
	int nm[2];
	const double gap = (double)H - (double)eta;
	for (int b = 0; b < 2; ++b) {
		if (!(L[b] > 0)) {
			k[b][0] = 0, ph[b][0] = 1, nm[b] = 1;
			continue;
		}
		nm[b] = 0;
		for (int m = 0; m < SIDE_MODES; ++m) {
			const int j = 2 * m + 1;
			k[b][m] = j * M_PI / (double)L[b];
			if (m > 0 && k[b][m] * gap > 12)
				break;
			ph[b][m] = 4.0 / (j * M_PI) * sin(k[b][m] * (double)xi[b]);
			nm[b] = m + 1;
		}
	}
	double sum = 0;
	for (int m = 0; m < nm[0]; ++m)
		for (int q = 0; q < nm[1]; ++q) {
			const double K = sqrt(k[0][m] * k[0][m] + k[1][q] * k[1][q]);
			if (K * gap > 12 && (m > 0 || q > 0))
				break;
			/* sinh(K eta) / (K cosh(K H)) without overflow; eta at K -> 0 */
			const double f = K * H < 1e-6 ? (double)eta
			                              : (exp(-K * gap) - exp(-K * ((double)H + eta))) / (K * (1 + exp(-2 * K * H)));
			sum += ph[0][m] * ph[1][q] * f;
		}
	return sum > 0 ? (float)sum : 0.0f;
}

long eddy__dfsph_hydrostatic_start(eddy_world *w, const sph_shared *sh, long n, float *k)
{
	const sph_neighbors *nb = &sh->nb;
	const sph_grid *gr = &nb->grid;
	const eddy_vec3 g = eddy__gravity(w);
	const float ga[3] = {g.x, g.y, g.z};
	int a = 0;
	for (int c = 1; c < 3; ++c)
		a = fabsf(ga[c]) > fabsf(ga[a]) ? c : a;
	/* no boundary particles: nothing rests on a wall */
	if (n <= 0 || !(fabsf(ga[a]) > 0) || nb->nbound == 0 || !sh->pq || !gr->fluid_start.base)
		return 0;
	for (long i = 0; i < n; ++i)
		if (k[i] != 0)
			return 0;
	/* The rows are in cell order this step; the cells' ranges must cover
	 * them (sph_density refreshes them whenever there are boundary
	 * particles): if not, no estimate rather than a wrong one. */
	int clo[3] = {gr->gx, gr->gy, gr->gz}, chi[3] = {-1, -1, -1}; /* the occupied cells' box */
	bool touch = false;                                           /* some particle has a boundary neighbour */
	for (long i = 0; i < n; ++i) {
		const float *p = sh->pq + 4 * i;
		const uint32_t c = sph_cell_at(gr, p[0], p[1], p[2]);
		if (!(cell_lo(gr, c) <= (uint32_t)i && (uint32_t)i < cell_hi(gr, c)))
			return 0;
		const int ci[3] = {(int)(c % (uint32_t)gr->gx), (int)(c / (uint32_t)gr->gx % (uint32_t)gr->gy),
		                   (int)(c / ((uint32_t)gr->gx * (uint32_t)gr->gy))};
		for (int e = 0; e < 3; ++e) {
			clo[e] = ci[e] < clo[e] ? ci[e] : clo[e];
			chi[e] = ci[e] > chi[e] ? ci[e] : chi[e];
		}
		touch = touch || nb->bcount[i] > 0;
	}
	if (!touch) /* nothing rests on a wall: water in free fall, every step of it */
		return 0;
	const int vcol[3] = {COL_VX, COL_VY, COL_VZ};
	const float *vel = eddy__col(w, vcol[a]);
	const eddy_arena_mark mark = eddy__arena_mark(&w->arena);
	float *eta = eddy__arena_alloc(&w->arena, (size_t)n * sizeof *eta),
		  *depth = eddy__arena_alloc(&w->arena, (size_t)n * sizeof *depth),
		  *xi = eddy__arena_alloc(&w->arena, 4 * (size_t)n * sizeof *xi), *span = xi + 2 * (size_t)n;
	if (!vel || !eta || !depth || !xi) {
		eddy__arena_release(&w->arena, mark);
		return 0;
	}
	const warm_walk ww = {.nb = nb,
	                      .g = gr,
	                      .pq = sh->pq,
	                      .n = n,
	                      .s = cbrtf(sh->mass / sh->rho0),
	                      .lo = {clo[0], clo[1], clo[2]},
	                      .hi = {chi[0], chi[1], chi[2]},
	                      .stride = {1, (size_t)gr->gx, (size_t)gr->gx * (size_t)gr->gy}};
	const float up = ga[a] < 0 ? 1.0f : -1.0f; /* the height is up x_a */
	const float g1 = sqrtf(g.x * g.x + g.y * g.y + g.z * g.z);
	const float vrest = sqrtf(g1 * sh->h); /* the fastest fall that still counts as rest */
	for (long i = 0; i < n; ++i)
		eta[i] = -1, xi[2 * i] = xi[2 * i + 1] = span[2 * i] = span[2 * i + 1] = 0;
	/* along gravity: per run from the top down, its surface, its depth and
	 * whether it rests on a wall */
	{
		const int u = (a + 1) % 3, v = (a + 2) % 3;
		const int top = up > 0 ? chi[a] : clo[a], dl = up > 0 ? -1 : 1;
		for (int iv = clo[v]; iv <= chi[v]; ++iv)
			for (int iu = clo[u]; iu <= chi[u]; ++iu) {
				const size_t base = (size_t)iu * ww.stride[u] + (size_t)iv * ww.stride[v];
				for (int l = top; l >= clo[a] && l <= chi[a];) {
					const size_t c0 = base + (size_t)l * ww.stride[a];
					if (cell_lo(gr, c0) == cell_hi(gr, c0)) {
						l += dl;
						continue;
					}
					const int last = run_end(&ww, base, a, l, dl);
					const size_t cb = base + (size_t)last * ww.stride[a];
					float surf = -INFINITY, bottom = INFINITY;
					bool rest = true;
					for (int m = l; m != last + dl; m += dl) {
						const size_t c = base + (size_t)m * ww.stride[a];
						for (uint32_t i = cell_lo(gr, c), iend = cell_hi(gr, c); i < iend && (long)i < n; ++i) {
							const float hgt = up * ww.pq[4 * (size_t)i + a];
							surf = m == l ? fmaxf(surf, hgt) : surf;
							bottom = c == cb ? fminf(bottom, hgt) : bottom;
							rest = rest && -up * vel[i] <= vrest; /* the speed along g */
						}
					}
					const bool wall = walled(&ww, cb, a, -up, a, up); /* a floor under its bottom */
					for (int m = l; wall && rest && m != last + dl; m += dl) {
						const size_t c = base + (size_t)m * ww.stride[a];
						for (uint32_t i = cell_lo(gr, c), iend = cell_hi(gr, c); i < iend && (long)i < n; ++i) {
							eta[i] = fmaxf(surf - up * ww.pq[4 * (size_t)i + a], 0.0f) + 0.5f * ww.s;
							depth[i] = surf - bottom + ww.s;
						}
					}
					l = last + dl;
				}
			}
	}
	/* across gravity, along each other axis b: per run, its ends (free or
	 * against a wall) and extent: a particle's distance from the free end
	 * and the modes' span (the run's length, twice it with one end walled) */
	for (int sb = 0; sb < 2; ++sb) {
		const int b = (a + 1 + sb) % 3, u = (b + 1) % 3, v = (b + 2) % 3;
		for (int iv = clo[v]; iv <= chi[v]; ++iv)
			for (int iu = clo[u]; iu <= chi[u]; ++iu) {
				const size_t base = (size_t)iu * ww.stride[u] + (size_t)iv * ww.stride[v];
				for (int l = clo[b]; l <= chi[b];) {
					const size_t c0 = base + (size_t)l * ww.stride[b];
					if (cell_lo(gr, c0) == cell_hi(gr, c0)) {
						++l;
						continue;
					}
					const int last = run_end(&ww, base, b, l, 1);
					const size_t cl = base + (size_t)last * ww.stride[b];
					float lo = INFINITY, hi = -INFINITY;
					for (uint32_t i = cell_lo(gr, c0), iend = cell_hi(gr, c0); i < iend && (long)i < n; ++i)
						lo = fminf(lo, ww.pq[4 * (size_t)i + b]);
					for (uint32_t i = cell_lo(gr, cl), iend = cell_hi(gr, cl); i < iend && (long)i < n; ++i)
						hi = fmaxf(hi, ww.pq[4 * (size_t)i + b]);
					const bool free_lo = !walled(&ww, c0, b, -1.0f, a, up), free_hi = !walled(&ww, cl, b, 1.0f, a, up);
					const float len = hi - lo + ww.s, span_b = free_lo && free_hi ? len : 2 * len;
					for (int m = l; m <= last && (free_lo || free_hi); ++m) {
						const size_t c = base + (size_t)m * ww.stride[b];
						for (uint32_t i = cell_lo(gr, c), iend = cell_hi(gr, c); i < iend && (long)i < n; ++i) {
							const float x = ww.pq[4 * (size_t)i + b];
							xi[2 * i + sb] = (free_lo ? x - lo : hi - x) + 0.5f * ww.s;
							span[2 * i + sb] = span_b;
						}
					}
					l = last + 1;
				}
			}
	}
	const float coef = sh->grad_cal * fabsf(ga[a]) / sh->rho0;
	long done = 0;
	for (long i = 0; i < n; ++i)
		if (eta[i] >= 0) {
			k[i] = coef * block_depth(eta[i], depth[i], xi + 2 * i, span + 2 * i);
			++done;
		}
	eddy__arena_release(&w->arena, mark);
	return done;
}
