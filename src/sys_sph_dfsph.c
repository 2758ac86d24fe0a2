/* sph_dfsph: implicit (incompressible) SPH pressure, the divergence-free SPH
 * of Bender & Koschier (SCA 2015, TVCG 2017). It replaces sph_pressure: the
 * pressure is solved for each step so the fluid keeps its rest density, and
 * the time step is limited by the flow speed, not by a speed of sound.
 *
 * Reads: x y z vx vy vz density ax ay az. Writes: pressure ax ay az
 * (accumulated). Runs after the non-pressure forces (gravity, sph_viscosity,
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
 *   Drho_i/Dt = sum_j (v_i - v_j) . G_ij + v_i . B_i
 *   a_i^p     = -sum_j (k_i + k_j) G_ij - 2 k_i B_i + h_i
 * The boundary particles mirror the particle's pressure (p_b = p_i, so the
 * wall term counts twice: with a single k_i the wall could not hold a
 * particle whose neighbourhood is full, as sum_j G_ij + B_i ~ 0 there), plus
 * Adami et al.'s (2012) hydrostatic part p_b - p_i = rho_i g . (x_b - x_i):
 *   h_i = -(1/rho_i) sum_b (g . (x_b - x_i)) m_b grad W(x_i - x_b)
 * (up, away from a floor),
 * known before the solve and added to the forces; without it the fluid
 * beside the walls lacks support and circulates.
 * A change k_i alone moves Drho_i/Dt by -dt k_i D_i, with
 *   D_i = (S_i + 2 B_i) . (S_i + B_i) + sum_j |G_ij|^2,   S_i = sum_j G_ij
 * (the paper's rho_i / alpha_i with the mirrored wall), so each Jacobi sweep
 * sets, from the current predicted velocities v*,
 *   constant density:  k_i = max(rho_i + dt Drho_i/Dt - rho0, 0) / (dt^2 D_i)
 *   divergence-free:   k_i = max(Drho_i/Dt, 0) / (dt D_i)
 * and moves v*_i by dt a_i^p(k). The divergence solver runs first, on the
 * velocity at the start of the step (positions are new, velocities not yet
 * consistent with them); then v* = v + dt (a + h) and the constant-density
 * solver runs until the mean predicted compression max(rho*_i - rho0, 0) / rho0
 * is at most max_density_error (at least one sweep). Only
 * compression is corrected: the free surface has too few neighbours to reach
 * rho0 and must not be pulled together. (Tried and dropped: the paper's warm
 * start from last step's k, which with sweeps that only add pressure pushed
 * the free surface apart (mean density error 2% -> 4.5% in the pour), and a
 * projected Jacobi that could take pressure back, which diverged.)
 * The result, a^p = (v* - (v + dt a)) / dt, is added to ax ay az. The pressure
 * column gets p_i = M k_i rho_i^2, k_i summed over both solvers, M the
 * force's lattice moment (1 / grad_cal, see sph_pressure): the force of a
 * linear field is M grad p / rho, so this is the pressure in Pa (M = 0.947
 * at h = 2 spacings).
 * Sums over neighbours run in list order and per particle, and the mean
 * errors are summed serially in row order, so the result does not depend on
 * the thread count.
 *
 * Published per frame: solver = "dfsph", iterations (mean constant-density
 * sweeps per step), residual (largest final mean density error of a step),
 * divergence_iterations (mean), unconverged (steps that hit max_iterations).
 * A step whose final mean density error is above 5% fails: the time step is
 * far too long for the solver.
 * Time-step limits (the world multiplies them by its CFL number): velocity,
 * dt <= h / max|v|; gravity, dt <= 0.18 sqrt(h / |g|) (see below). There is
 * no acoustic limit: that is sph_pressure's, which a scene with this lacks.
 * Source: Bender & Koschier, "Divergence-free smoothed particle hydrodynamics",
 * SCA 2015 (eqs. 8-9, 12, Alg. 2-3); Akinci et al., "Versatile rigid-fluid
 * coupling for incompressible SPH", SIGGRAPH 2012; Adami, Hu & Adams, "A
 * generalized wall boundary condition for SPH", JCP 2012 (eq. 27). */
#include "sph.h"
#include "systems.h"

#include <stdlib.h>
#include <string.h>
#ifdef __SSE2__
#include <emmintrin.h>
#endif

typedef struct sph_dfsph {
	eddy_sph_dfsph_def def;
	/* statistics of the current frame */
	int frame;
	int64_t steps, sweeps, div_sweeps, unconverged;
	double residual;
} sph_dfsph;

static const int dfsph_reads[] = {COL_X_, COL_Y_, COL_Z_, COL_VX, COL_VY, COL_VZ, COL_DENSITY, COL_AX, COL_AY, COL_AZ};
static const int dfsph_writes[] = {COL_PRESSURE, COL_AX, COL_AY, COL_AZ};
static const int no_hint_writes[] = {-1};

/* dt <= DFSPH_GRAVITY_LIMIT sqrt(h / |g|) (times the CFL number): gravity
 * compresses the fluid by g dt^2 each step, which the first-order prediction
 * of the solve must absorb; a tank at rest rings up from dt = 0.19 sqrt(h / g)
 * on (h = 2 cm, dt 8.5 ms) and stays quiet below it. Transient forces
 * (viscosity, impacts) do not need it: the velocity limit covers them. */
#define DFSPH_GRAVITY_LIMIT 0.18

/* above this final mean density error a step fails instead of going on */
#define DFSPH_FAIL_ERROR 0.05

/* constant-density sweeps a step makes at least (the paper: 2; 1 gives the
 * same errors in the pour, tank and drop and saves 10% of the solve) */
#define DFSPH_MIN_SWEEPS 1

eddy_sph_dfsph_def eddy_default_sph_dfsph_def(void)
{
	eddy_sph_dfsph_def d;
	d.max_density_error = 0.005f;
	d.max_iterations = 100;
	d.divergence_solver = true;
	d.max_divergence_error = 0.01f;
	d.max_divergence_iterations = 100;
	return d;
}

/* The solver's per-step scratch, all in the world's arena. Four floats per
 * entry, so a neighbour's velocity and k come in one load (the sweeps are
 * gathers over the neighbour lists). */
typedef struct dfsph_f4 {
	float x, y, z, w;
} dfsph_f4;


typedef struct dfsph_work {
	long n;
	const uint32_t *count;
	size_t *off;   /* particle i's pairs are off[i] .. off[i] + count[i]: packed, so
	                * a sweep streams through them (sph_density's lists have a
	                * fixed stride) */
	uint32_t *nbr; /* the neighbour of each pair */
	float *gx, *gy, *gz; /* G_ij of each pair, by component: four pairs are one load */
	dfsph_f4 *b;   /* B_i, and w = 1 / D_i (0 where D_i is negligible) */
	dfsph_f4 *v;   /* v*_i, and w = this sweep's k_i */
	dfsph_f4 *h;   /* the walls' hydrostatic push h_i (m/s^2), and w = rho_i */
	float *ksum;   /* the sum of k_i over the sweeps */
	float *err;    /* per particle: the error the sweep measured */
} dfsph_work;

static void gradients(const sph_shared *sh, const float *x, const float *y, const float *z, const float *rho,
                      eddy_vec3 grav, dfsph_work *wk, int threads)
{
	const sph_neighbors *nb = &sh->nb;
	const sph_kernel_consts kc = sh->k;
	const float m = sh->mass, rho0 = sh->rho0, eps2 = 1e-6f * kc.h2;
	const float dref = m * kc.spiky_grad * kc.h2, dmin = 1e-6f * dref * dref; /* |G| scale */
	const long n = wk->n;
	const size_t cap = nb->cap;
#pragma omp parallel for num_threads(threads) schedule(static)
	for (long i = 0; i < n; ++i) {
		const float xi = x[i], yi = y[i], zi = z[i];
		const uint32_t *list = nb->nbr + (size_t)i * cap;
		const size_t o = wk->off[i];
		uint32_t *packed = wk->nbr + o;
		float *gxo = wk->gx + o, *gyo = wk->gy + o, *gzo = wk->gz + o;
		const uint32_t cnt = nb->count[i];
		const float mg = m * kc.spiky_grad;
		float sx = 0, sy = 0, sz = 0, s2 = 0;
		uint32_t q = 0;
#ifdef __SSE2__
		/* four pairs at a time (the square root and division are most of
		 * the pass); lanes add in a fixed order, so any thread count gives
		 * the same sums */
		__m128 vsx = _mm_setzero_ps(), vsy = vsx, vsz = vsx, vs2 = vsx;
		const __m128 vxi = _mm_set1_ps(xi), vyi = _mm_set1_ps(yi), vzi = _mm_set1_ps(zi), vh = _mm_set1_ps(kc.h),
		             veps2 = _mm_set1_ps(eps2), vmg = _mm_set1_ps(mg), zero = _mm_setzero_ps();
		for (; q + 4 <= cnt; q += 4) {
			const uint32_t j0 = list[q], j1 = list[q + 1], j2 = list[q + 2], j3 = list[q + 3];
			const __m128 rx = _mm_sub_ps(vxi, _mm_setr_ps(x[j0], x[j1], x[j2], x[j3])),
			             ry = _mm_sub_ps(vyi, _mm_setr_ps(y[j0], y[j1], y[j2], y[j3])),
			             rz = _mm_sub_ps(vzi, _mm_setr_ps(z[j0], z[j1], z[j2], z[j3]));
			const __m128 r2 = _mm_add_ps(_mm_add_ps(_mm_mul_ps(rx, rx), _mm_mul_ps(ry, ry)), _mm_mul_ps(rz, rz));
			const __m128 r = _mm_sqrt_ps(r2), hr = _mm_sub_ps(vh, r);
			const __m128 ok = _mm_and_ps(_mm_cmpgt_ps(r2, veps2), _mm_cmpgt_ps(hr, zero));
			/* r is at least sqrt(eps2) where ok; elsewhere divide by 1 */
			const __m128 rs = _mm_or_ps(_mm_and_ps(ok, r), _mm_andnot_ps(ok, _mm_set1_ps(1.0f)));
			const __m128 c = _mm_and_ps(ok, _mm_div_ps(_mm_mul_ps(_mm_mul_ps(vmg, hr), hr), rs));
			const __m128 gx = _mm_mul_ps(c, rx), gy = _mm_mul_ps(c, ry), gz = _mm_mul_ps(c, rz);
			_mm_storeu_si128((__m128i *)(packed + q), _mm_loadu_si128((const __m128i *)(list + q)));
			_mm_storeu_ps(gxo + q, gx);
			_mm_storeu_ps(gyo + q, gy);
			_mm_storeu_ps(gzo + q, gz);
			vsx = _mm_add_ps(vsx, gx);
			vsy = _mm_add_ps(vsy, gy);
			vsz = _mm_add_ps(vsz, gz);
			vs2 = _mm_add_ps(vs2, _mm_add_ps(_mm_add_ps(_mm_mul_ps(gx, gx), _mm_mul_ps(gy, gy)), _mm_mul_ps(gz, gz)));
		}
		float l4[4];
		_mm_storeu_ps(l4, vsx);
		sx = (l4[0] + l4[1]) + (l4[2] + l4[3]);
		_mm_storeu_ps(l4, vsy);
		sy = (l4[0] + l4[1]) + (l4[2] + l4[3]);
		_mm_storeu_ps(l4, vsz);
		sz = (l4[0] + l4[1]) + (l4[2] + l4[3]);
		_mm_storeu_ps(l4, vs2);
		s2 = (l4[0] + l4[1]) + (l4[2] + l4[3]);
#endif
		for (; q < cnt; ++q) {
			const uint32_t j = list[q];
			const float rx = xi - x[j], ry = yi - y[j], rz = zi - z[j];
			const float r2 = rx * rx + ry * ry + rz * rz;
			const float r = sqrtf(r2), hr = kc.h - r;
			const float c = r2 > eps2 && hr > 0 ? mg * hr * hr / r : 0.0f;
			/* the gradient's factor is < 0: G_ij points from i towards j */
			const float gx = c * rx, gy = c * ry, gz = c * rz;
			packed[q] = j;
			gxo[q] = gx;
			gyo[q] = gy;
			gzo[q] = gz;
			sx += gx;
			sy += gy;
			sz += gz;
			s2 += gx * gx + gy * gy + gz * gz;
		}
		const uint32_t *blist = nb->bnbr + (size_t)i * nb->bcap;
		const uint32_t bcnt = nb->bcount[i];
		float bx = 0, by = 0, bz = 0, hx = 0, hy = 0, hz = 0;
		for (uint32_t qb = 0; qb < bcnt; ++qb) {
			const uint32_t b = blist[qb];
			const float rx = xi - nb->bx[b], ry = yi - nb->by[b], rz = zi - nb->bz[b];
			const float r2 = rx * rx + ry * ry + rz * rz;
			const float mb = nb->bvol[b] * rho0; /* Akinci: the wall at rest density */
			const float r = sqrtf(r2), hr = kc.h - r;
			const float c = r2 > eps2 && hr > 0 ? mb * kc.spiky_grad * hr * hr / r : 0.0f;
			bx += c * rx;
			by += c * ry;
			bz += c * rz;
			/* g . (x_b - x_i) */
			const float gh = -(grav.x * rx + grav.y * ry + grav.z * rz) * c;
			hx += gh * rx;
			hy += gh * ry;
			hz += gh * rz;
		}
		const float ir = 1.0f / rho[i];
		wk->h[i] = (dfsph_f4){-hx * ir, -hy * ir, -hz * ir, rho[i]};
		/* (S + 2B) . (S + B) + sum |G|^2, S = sum_j G_ij: the boundary term of
		 * the acceleration counts twice (pressure mirroring) */
		const float d = (sx + 2 * bx) * (sx + bx) + (sy + 2 * by) * (sy + by) + (sz + 2 * bz) * (sz + bz) + s2;
		wk->b[i] = (dfsph_f4){bx, by, bz, d > dmin ? 1.0f / d : 0.0f};
	}
}

/* Drho_i/Dt from the predicted velocities. */
static inline float density_rate(const dfsph_work *wk, long i)
{
	const size_t o = wk->off[i];
	const uint32_t *list = wk->nbr + o;
	const float *gx = wk->gx + o, *gy = wk->gy + o, *gz = wk->gz + o;
	const dfsph_f4 vi = wk->v[i], bi = wk->b[i];
	const uint32_t cnt = wk->count[i];
	float sx = 0, sy = 0, sz = 0;
	uint32_t q = 0;
#ifdef __SSE2__
	/* four neighbours' (v, k) are four loads and a transpose */
	__m128 ax = _mm_setzero_ps(), ay = ax, az = ax;
	for (; q + 4 <= cnt; q += 4) {
		__m128 a = _mm_loadu_ps(&wk->v[list[q]].x), b = _mm_loadu_ps(&wk->v[list[q + 1]].x),
		       c = _mm_loadu_ps(&wk->v[list[q + 2]].x), d = _mm_loadu_ps(&wk->v[list[q + 3]].x);
		_MM_TRANSPOSE4_PS(a, b, c, d); /* a = vx, b = vy, c = vz of the four */
		ax = _mm_add_ps(ax, _mm_mul_ps(_mm_sub_ps(_mm_set1_ps(vi.x), a), _mm_loadu_ps(gx + q)));
		ay = _mm_add_ps(ay, _mm_mul_ps(_mm_sub_ps(_mm_set1_ps(vi.y), b), _mm_loadu_ps(gy + q)));
		az = _mm_add_ps(az, _mm_mul_ps(_mm_sub_ps(_mm_set1_ps(vi.z), c), _mm_loadu_ps(gz + q)));
	}
	float l4[4];
	_mm_storeu_ps(l4, _mm_add_ps(_mm_add_ps(ax, ay), az));
	sx = (l4[0] + l4[1]) + (l4[2] + l4[3]);
#endif
	for (; q < cnt; ++q) {
		const dfsph_f4 vj = wk->v[list[q]];
		sx += (vi.x - vj.x) * gx[q];
		sy += (vi.y - vj.y) * gy[q];
		sz += (vi.z - vj.z) * gz[q];
	}
	return (sx + sy + sz) + (vi.x * bi.x + vi.y * bi.y + vi.z * bi.z);
}

/* v*_i -= dt (sum_j (k_i + k_j) G_ij + 2 k_i B_i); k in v[].w. Writes only
 * its own particle's x y z (others read w), and adds k_i to its sum. */
static void correct(dfsph_work *wk, float dt, int threads)
{
	const long n = wk->n;
#pragma omp parallel for num_threads(threads) schedule(static)
	for (long i = 0; i < n; ++i) {
		const size_t o = wk->off[i];
		const uint32_t *list = wk->nbr + o;
		const float *gx = wk->gx + o, *gy = wk->gy + o, *gz = wk->gz + o;
		const dfsph_f4 bi = wk->b[i];
		const float ki = wk->v[i].w;
		const uint32_t cnt = wk->count[i];
		const float kb = 2 * ki; /* the boundary particles mirror k_i */
		float ax = kb * bi.x, ay = kb * bi.y, az = kb * bi.z;
		uint32_t q = 0;
#ifdef __SSE2__
		__m128 sx = _mm_setzero_ps(), sy = sx, sz = sx;
		const __m128 vki = _mm_set1_ps(ki);
		for (; q + 4 <= cnt; q += 4) {
			const __m128 c = _mm_add_ps(vki, _mm_setr_ps(wk->v[list[q]].w, wk->v[list[q + 1]].w,
			                                             wk->v[list[q + 2]].w, wk->v[list[q + 3]].w));
			sx = _mm_add_ps(sx, _mm_mul_ps(c, _mm_loadu_ps(gx + q)));
			sy = _mm_add_ps(sy, _mm_mul_ps(c, _mm_loadu_ps(gy + q)));
			sz = _mm_add_ps(sz, _mm_mul_ps(c, _mm_loadu_ps(gz + q)));
		}
		float l4[4];
		_mm_storeu_ps(l4, sx);
		ax += (l4[0] + l4[1]) + (l4[2] + l4[3]);
		_mm_storeu_ps(l4, sy);
		ay += (l4[0] + l4[1]) + (l4[2] + l4[3]);
		_mm_storeu_ps(l4, sz);
		az += (l4[0] + l4[1]) + (l4[2] + l4[3]);
#endif
		for (; q < cnt; ++q) {
			const float c = ki + wk->v[list[q]].w;
			ax += c * gx[q];
			ay += c * gy[q];
			az += c * gz[q];
		}
		wk->v[i].x -= dt * ax;
		wk->v[i].y -= dt * ay;
		wk->v[i].z -= dt * az;
		wk->ksum[i] += ki;
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

/* Divergence-free solve: sweeps until mean max(Drho/Dt, 0) dt / rho0 <= tol. */
static int divergence_solve(dfsph_work *wk, const sph_dfsph *sd, float rho0, float dt, int threads)
{
	const long n = wk->n;
	const float inv_dt = 1.0f / dt;
	int it = 0;
	for (;;) {
#pragma omp parallel for num_threads(threads) schedule(static)
		for (long i = 0; i < n; ++i) {
			float r = density_rate(wk, i);
			r = r > 0 ? r : 0;
			wk->err[i] = r * dt;
			wk->v[i].w = r * inv_dt * wk->b[i].w;
		}
		const double e = mean_of(wk->err, n) / rho0;
		if ((it >= 1 && e <= sd->def.max_divergence_error) || it >= sd->def.max_divergence_iterations)
			break;
		correct(wk, dt, threads);
		++it;
	}
	return it;
}

/* Constant-density solve: sweeps until mean max(rho* - rho0, 0) / rho0 <= tol. */
static int density_solve(dfsph_work *wk, const sph_dfsph *sd, float rho0, float dt, int threads, double *residual)
{
	const long n = wk->n;
	const float inv_dt2 = 1.0f / (dt * dt);
	int it = 0;
	for (;;) {
#pragma omp parallel for num_threads(threads) schedule(static)
		for (long i = 0; i < n; ++i) {
			float e = wk->h[i].w + dt * density_rate(wk, i) - rho0;
			e = e > 0 ? e : 0;
			wk->err[i] = e;
			wk->v[i].w = e * inv_dt2 * wk->b[i].w;
		}
		*residual = mean_of(wk->err, n) / rho0;
		if ((it >= DFSPH_MIN_SWEEPS && *residual <= sd->def.max_density_error) || it >= sd->def.max_iterations)
			break;
		correct(wk, dt, threads);
		++it;
	}
	return it;
}

/* A scene uses one pressure system: sph_pressure's force on top of the solve
 * would be counted twice. */
static bool has_sph_pressure(const eddy_world *w)
{
	for (int k = 0; k < w->order_count; ++k)
		if (w->slots[w->order[k]].vt == &eddy__kind_sph_pressure)
			return true;
	return false;
}

static eddy_status step(eddy_world *w, eddy_system *s, const eddy_step_context *ctx)
{
	sph_dfsph *sd = s->data;
	sph_shared *sh = eddy__sph_find(w, s);
	if (!sh)
		return eddy__fail(w, EDDY_ERR_ORDER, "%s: needs sph_density before it (it builds the neighbour lists)", s->label);
	if (has_sph_pressure(w))
		return eddy__fail(w, EDDY_ERR_ORDER, "%s: replaces sph_pressure; remove one of them from the scene", s->label);
	if (sd->frame != w->frame) {
		sd->frame = w->frame;
		sd->steps = sd->sweeps = sd->div_sweeps = sd->unconverged = 0;
		sd->residual = 0;
	}
	const sph_neighbors *nb = &sh->nb;
	const long n = nb->n < w->n ? (long)nb->n : (long)w->n;
	const float *x = eddy__col(w, COL_X_), *y = eddy__col(w, COL_Y_), *z = eddy__col(w, COL_Z_);
	const float *vx = eddy__col(w, COL_VX), *vy = eddy__col(w, COL_VY), *vz = eddy__col(w, COL_VZ);
	const float *rho = eddy__col(w, COL_DENSITY);
	float *p = eddy__col(w, COL_PRESSURE);
	float *ax = eddy__col(w, COL_AX), *ay = eddy__col(w, COL_AY), *az = eddy__col(w, COL_AZ);
	const float dt = (float)ctx->dt, rho0 = sh->rho0;
	if (n == 0 || !(dt > 0))
		return EDDY_OK;

	dfsph_work wk;
	wk.n = n;
	wk.count = nb->count;
	const size_t un = (size_t)n;
	wk.off = eddy__arena_alloc(&w->arena, (un + 1) * sizeof *wk.off);
	if (!wk.off)
		return eddy__fail(w, EDDY_ERR_NOMEM, "%s: out of scratch memory for %ld particles", s->label, n);
	wk.off[0] = 0;
	for (long i = 0; i < n; ++i)
		wk.off[i + 1] = wk.off[i] + nb->count[i];
	const size_t pairs = wk.off[n] ? wk.off[n] : 1;
	wk.nbr = eddy__arena_alloc(&w->arena, pairs * sizeof *wk.nbr);
	wk.gx = eddy__arena_alloc(&w->arena, 3 * pairs * sizeof *wk.gx);
	wk.gy = wk.gx ? wk.gx + pairs : NULL;
	wk.gz = wk.gx ? wk.gy + pairs : NULL;
	dfsph_f4 *block = eddy__arena_alloc(&w->arena, 3 * un * sizeof(dfsph_f4) + 2 * un * sizeof(float));
	if (!wk.nbr || !wk.gx || !block)
		return eddy__fail(w, EDDY_ERR_NOMEM, "%s: out of scratch memory for %ld particles", s->label, n);
	wk.b = block;
	wk.v = wk.b + un;
	wk.h = wk.v + un;
	wk.ksum = (float *)(wk.h + un);
	wk.err = wk.ksum + un;

	gradients(sh, x, y, z, rho, w->def.gravity, &wk, ctx->threads);
	memset(wk.ksum, 0, un * sizeof *wk.ksum);

	int div_it = 0;
	if (sd->def.divergence_solver) {
		for (long i = 0; i < n; ++i)
			wk.v[i] = (dfsph_f4){vx[i], vy[i], vz[i], 0};
		div_it = divergence_solve(&wk, sd, rho0, dt, ctx->threads);
	} else {
		for (long i = 0; i < n; ++i)
			wk.v[i] = (dfsph_f4){vx[i], vy[i], vz[i], 0};
	}
	/* v* = v (divergence-free) + dt (a + h) */
	for (long i = 0; i < n; ++i) {
		wk.v[i].x += dt * (ax[i] + wk.h[i].x);
		wk.v[i].y += dt * (ay[i] + wk.h[i].y);
		wk.v[i].z += dt * (az[i] + wk.h[i].z);
	}

	double residual = 0;
	const int it = density_solve(&wk, sd, rho0, dt, ctx->threads, &residual);

	/* a += (v* - (v + dt a)) / dt; p = k rho^2 */
	const float inv_dt = 1.0f / dt;
	long bad = -1;
	for (long i = 0; i < n; ++i) {
		const float ux = (wk.v[i].x - (vx[i] + dt * ax[i])) * inv_dt, uy = (wk.v[i].y - (vy[i] + dt * ay[i])) * inv_dt,
		            uz = (wk.v[i].z - (vz[i] + dt * az[i])) * inv_dt;
		ax[i] += ux;
		ay[i] += uy;
		az[i] += uz;
		p[i] = wk.ksum[i] * wk.h[i].w * wk.h[i].w / sh->grad_cal;
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
	sd->unconverged += it >= sd->def.max_iterations && residual > sd->def.max_density_error;
	sd->residual = residual > sd->residual ? residual : sd->residual;
	eddy_world_publish_text(w, "solver", "dfsph");
	eddy_world_publish(w, "iterations", (double)sd->sweeps / (double)sd->steps);
	eddy_world_publish(w, "residual", sd->residual);
	if (sd->def.divergence_solver)
		eddy_world_publish(w, "divergence_iterations", (double)sd->div_sweeps / (double)sd->steps);
	eddy_world_publish(w, "unconverged", (double)sd->unconverged);
	if (!(residual <= DFSPH_FAIL_ERROR))
		return eddy__fail(w, EDDY_ERR_NUMERIC,
		                  "%s: did not converge at step %lld: mean density error %.3g after %d iterations "
		                  "(max_density_error %g); lower the world's cfl or raise max_iterations",
		                  s->label, (long long)ctx->step, residual, it, (double)sd->def.max_density_error);
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
	const double la = g1 > 0 ? DFSPH_GRAVITY_LIMIT * sqrt((double)sh->h / g1) : INFINITY;
	if (la < lv)
		*reason = "gravity";
	return la < lv ? la : lv;
}

const eddy_system_vtable eddy__kind_sph_dfsph = {
	.name = "sph_dfsph",
	.step = step,
	.limit = limit,
	/* ax ay az are every force's: order hints for them name gravity alone */
	.default_writes = no_hint_writes,
};

eddy_system_id eddy_add_sph_dfsph(eddy_world *w, const eddy_sph_dfsph_def *def)
{
	const char *sys = "sph_dfsph";
	if (!def)
		return eddy__fail(w, EDDY_ERR_INVALID, "%s: def is NULL", sys), EDDY_NULL_SYSTEM;
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
	return eddy__add_system(w, &eddy__kind_sph_dfsph, sd, dfsph_reads, 10, dfsph_writes, 4);
}
