/* SPDX-License-Identifier: MIT */
/* The SPH passes against a plain reference: sph_density, sph_pressure,
 * sph_viscosity and sph_dfsph's passes on a small random block of
 * particles, compared with a double-precision evaluation of the Mueller
 * kernels over all pairs, written for clarity (O(n^2), no neighbour lists,
 * no SIMD). The passes' SIMD back-ends share their lane order with each
 * other, so they cannot check one another; this reference shares nothing
 * with them but the equations of their header comments. Run on whichever back-end the build has (AVX2 or
 * SSE; SIMD=scalar: the scalar one) and again with EDDY_NO_AVX2=1.
 *
 * Sources: Mueller, Charypar & Gross 2003 (poly6 density, spiky pressure
 * gradient, viscosity Laplacian); Monaghan 1992 (artificial viscosity). */
#include "test.h"

#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "eddy.h"

#ifndef M_PI
#define M_PI 3.14159265358979323846
#endif

enum { SIDE = 7, NP = SIDE * SIDE * SIDE };

/* What the passes produced, copied by custom systems placed between them
 * (the step runs no integrator, so the positions stay put). */
typedef struct snapshot {
	size_t n;
	double x[NP], y[NP], z[NP], vx[NP], vy[NP], vz[NP], rho[NP], p[NP];
	double a[3][3][NP]; /* ax ay az after gravity (g = 0), of sph_pressure, of sph_viscosity */
	int stage;
} snapshot;

static eddy_status capture(eddy_world *w, const eddy_step_context *ctx, void *user)
{
	(void)ctx;
	snapshot *s = user;
	size_t n;
	const char *acc[3] = {"ax", "ay", "az"};
	if (s->stage == 0) {
		const char *names[8] = {"x", "y", "z", "vx", "vy", "vz", "density", "pressure"};
		double *dst[8] = {s->x, s->y, s->z, s->vx, s->vy, s->vz, s->rho, s->p};
		for (int c = 0; c < 8; ++c) {
			const float *v = eddy_world_channel(w, names[c], &n);
			if (!v || n > NP)
				return EDDY_ERR_INVALID;
			for (size_t i = 0; i < n; ++i)
				dst[c][i] = v[i];
		}
		s->n = n;
	}
	/* each pass's acceleration alone: taken, then ax ay az set back to 0
	 * for the next pass to add to */
	for (int c = 0; c < 3; ++c) {
		float *v = eddy_world_channel_mut(w, acc[c], &n);
		for (size_t i = 0; i < n; ++i) {
			s->a[s->stage][c][i] = v ? v[i] : 0.0;
			if (v)
				v[i] = 0;
		}
	}
	s->stage++;
	return EDDY_OK;
}

static void add_capture(eddy_world *w, snapshot *s, const char *name)
{
	static const char *const reads[] = {"x", "y", "z", "vx", "vy", "vz", "density", "pressure", "ax", "ay", "az"};
	eddy_custom_system_def cs = eddy_default_custom_system_def();
	cs.name = name;
	cs.reads = reads;
	cs.read_count = 11;
	cs.writes = reads + 8;
	cs.write_count = 3;
	cs.step = capture;
	cs.user = s;
	CHECKF(eddy_system_valid(w, eddy_add_custom_system(w, &cs)), "%s", eddy_world_error(w));
}

/* A jittered lattice (spacing dx, each particle moved by up to 0.3 dx per
 * axis, so no pair is closer than 0.4 dx) with random velocities up to
 * 0.5 m/s per axis: neighbour counts that are not multiples of eight, every
 * pressure from 0 (clamped) upward, approaching and receding pairs. */
static void random_block(uint32_t seed, float dx, eddy_vec3 pos[NP], eddy_vec3 vel[NP])
{
	uint32_t r = seed;
#define NEXT() (r = r * 1664525u + 1013904223u, (double)(r >> 8) / 16777216.0 - 0.5) /* [-0.5, 0.5) */
	for (int k = 0; k < NP; ++k) {
		const int i = k % SIDE, j = k / SIDE % SIDE, l = k / (SIDE * SIDE);
		pos[k].x = 0.1f + dx * (float)(i + 0.6 * NEXT());
		pos[k].y = 0.1f + dx * (float)(j + 0.6 * NEXT());
		pos[k].z = 0.1f + dx * (float)(l + 0.6 * NEXT());
		vel[k].x = (float)NEXT();
		vel[k].y = (float)NEXT();
		vel[k].z = (float)NEXT();
	}
#undef NEXT
}

typedef struct ref_case {
	float dx, h, rho0, k, mu, alpha, scale;
} ref_case;

/* A world around the random block, without gravity, with sph_density as c
 * gives it and a gravity system (g = 0) that writes ax ay az = 0 before the
 * passes add to them. */
static eddy_world *ref_world(const ref_case *c, eddy_system_id *dens)
{
	eddy_world_def d = eddy_default_world_def();
	d.bounds_max = (eddy_vec3){0.3f, 0.3f, 0.3f};
	d.gravity = (eddy_vec3){0, 0, 0};
	eddy_world *w = eddy_create_world(&d, NULL, 0);
	eddy_sph_density_def de = eddy_default_sph_density_def();
	de.spacing = c->dx;
	de.radius = c->h;
	de.rest_density = c->rho0;
	de.stiffness = c->k;
	*dens = eddy_add_sph_density(w, &de);
	eddy_gravity_def g = eddy_default_gravity_def();
	CHECK(eddy_system_valid(w, eddy_add_gravity(w, &g)));
	return w;
}

/* One step of density, pressure and viscosity on the random block. */
static void run_passes(const ref_case *c, uint32_t seed, snapshot *s, double *mass)
{
	eddy_system_id dens;
	eddy_world *w = ref_world(c, &dens);
	add_capture(w, s, "after_density");
	eddy_sph_pressure_def pr = eddy_default_sph_pressure_def();
	pr.scale = c->scale;
	CHECK(eddy_system_valid(w, eddy_add_sph_pressure(w, &pr)));
	add_capture(w, s, "after_pressure");
	eddy_sph_viscosity_def vi = eddy_default_sph_viscosity_def();
	vi.viscosity = c->mu;
	vi.artificial = c->alpha;
	CHECK(eddy_system_valid(w, eddy_add_sph_viscosity(w, &vi)));
	add_capture(w, s, "after_viscosity");
	static eddy_vec3 pos[NP], vel[NP];
	random_block(seed, c->dx, pos, vel);
	CHECK(eddy_world_add_particles(w, NP, pos, vel) == EDDY_OK);
	s->stage = 0;
	CHECKF(eddy_world_step(w) == EDDY_OK, "%s", eddy_world_error(w));
	CHECK(s->stage == 3 && s->n == NP);
	*mass = eddy_sph_particle_mass(w, dens);
	eddy_destroy_world(w);
}

/* Tolerances, from the float arithmetic of the passes (unit roundoff
 * u = 2^-24). A pair term takes about a dozen roundings (the differences of
 * neighbouring positions are exact, Sterbenz), so it is within ~12 u of its
 * exact value relative to its size, except where it is ill-conditioned: r
 * comes from a float r^2 (~3 u r off), so h - r is off by a relative
 * 3 u r / (h - r), and a term with (h - r)^k by k times that (h^2 - r^2 the
 * same with r^2 / (h^2 - r^2): poly6's cube). A sum of n terms in float,
 * in whatever order, adds at most (n - 1) u of the sum of their magnitudes
 * (first order). So particle i's result may be off by
 *   u [ (n_i + 12) sum |t| + sum |t| 3 k r / (h - r) ]
 * (cond below holds the second sum without its factor u); the test allows
 * twice that, for the constants (m, 1/rho, the kernel factors) rounded to
 * float once each. A wrong exponent, constant, sign or mask in a pass
 * changes a result by a sizeable fraction of the sum of |terms| (a single
 * extra or missing pair: one term of ~n_i, 1-10%), far beyond this. */
#define ROUNDOFF 5.9604644775390625e-08 /* 2^-24 */
static double tolerance(int n_terms, double magnitude, double cond)
{
	return 2.0 * ROUNDOFF * ((n_terms + 12) * magnitude + 1.5 * cond);
}

/* The reference, term by term as the papers write it (double precision).
 * W_poly6(r) = 315/(64 pi h^9) (h^2 - r^2)^3, grad W_spiky(r_vec) =
 * -45/(pi h^6) (h - r)^2 r_vec / r, lap W_visc(r) = 45/(pi h^6) (h - r).
 * Each result comes with the sum of its terms' magnitudes, the scale its
 * float rounding is measured against. */
typedef struct reference {
	double rho[NP];
	int pairs[NP];                 /* neighbours within h, i excluded */
	double rho_tol[NP];            /* kg/m^3 */
	double ap[3][NP], ap_tol[NP];  /* pressure acceleration and its tolerance (see tolerance()) */
	double av[3][NP], av_tol[NP];  /* viscous acceleration (both parts) */
	double ap_mag[NP], av_mag[NP]; /* sums of |terms| */
} reference;

static void evaluate_reference(const ref_case *c, const snapshot *s, double m, reference *ref)
{
	const double h = c->h, h6 = pow(h, 6), h9 = pow(h, 9);
	const double poly6 = 315.0 / (64.0 * M_PI * h9), spiky = 45.0 / (M_PI * h6), vlap = 45.0 / (M_PI * h6);
	/* the pressure force is divided by its lattice moment (sph_pressure's
	 * header): m / (rho0 dx^3) times the spiky kernel's moment */
	const double dx3 = (double)c->dx * c->dx * c->dx;
	const double grad_cal = eddy_sph_lattice_sum(EDDY_SPH_POLY6, c->dx, h) * dx3 /
	                        eddy_sph_lattice_gradient_moment(EDDY_SPH_SPIKY, c->dx, h);
	const double sound = sqrt((double)c->k), eps = 0.01 * h * h;
	const size_t n = s->n;
	for (size_t i = 0; i < n; ++i) {
		double rho = 0, cond = 0;
		int pairs = 0;
		for (size_t j = 0; j < n; ++j) {
			const double dx = s->x[i] - s->x[j], dy = s->y[i] - s->y[j], dz = s->z[i] - s->z[j];
			const double r2 = dx * dx + dy * dy + dz * dz;
			if (r2 < h * h) {
				const double t = m * poly6 * pow(h * h - r2, 3);
				rho += t;
				cond += t * 3 * r2 / (h * h - r2);
				pairs += j != i;
			}
		}
		ref->rho[i] = rho;
		ref->rho_tol[i] = tolerance(pairs, rho, cond);
	}
	for (size_t i = 0; i < n; ++i) {
		double ap[3] = {0, 0, 0}, av[3] = {0, 0, 0}, pmag = 0, vmag = 0, pcond = 0, vcond = 0;
		int pairs = 0;
		for (size_t j = 0; j < n; ++j) {
			const double rv[3] = {s->x[i] - s->x[j], s->y[i] - s->y[j], s->z[i] - s->z[j]};
			const double r = sqrt(rv[0] * rv[0] + rv[1] * rv[1] + rv[2] * rv[2]);
			if (j == i || r >= h)
				continue;
			pairs++;
			const double vij[3] = {s->vx[i] - s->vx[j], s->vy[i] - s->vy[j], s->vz[i] - s->vz[j]};
			const double vr = vij[0] * rv[0] + vij[1] * rv[1] + vij[2] * rv[2];
			/* the passes use the density they were given (sph_density's, in
			 * float); the reference density is checked on its own above */
			const double rho_i = s->rho[i], rho_j = s->rho[j];
			for (int a = 0; a < 3; ++a) {
				const double grad = -spiky * (h - r) * (h - r) * rv[a] / r;
				/* a_i -= scale grad_cal m (p_i + p_j) / (rho_i rho_j) grad W */
				const double tp = -c->scale * grad_cal * m * (s->p[i] + s->p[j]) / (rho_i * rho_j) * grad;
				/* a_i += (mu / rho_i) m (v_j - v_i) / rho_j lap W */
				double tv = c->mu / rho_i * m * -vij[a] / rho_j * vlap * (h - r);
				/* a_i -= m Pi_ij grad W for approaching pairs, Pi_ij =
				 * -alpha c h vr / ((r^2 + 0.01 h^2) (rho_i + rho_j) / 2) */
				if (vr < 0)
					tv -= m * (-c->alpha * sound * h * vr / ((r * r + eps) * 0.5 * (rho_i + rho_j))) * grad;
				ap[a] += tp;
				av[a] += tv;
				pmag += fabs(tp);
				vmag += fabs(tv);
				/* (h - r)^2 (and (h - r) in the Laplacian) */
				pcond += fabs(tp) * 2 * r / (h - r);
				vcond += fabs(tv) * 2 * r / (h - r);
			}
		}
		for (int a = 0; a < 3; ++a) {
			ref->ap[a][i] = ap[a];
			ref->av[a][i] = av[a];
		}
		ref->pairs[i] = pairs;
		ref->ap_mag[i] = pmag;
		ref->av_mag[i] = vmag;
		ref->ap_tol[i] = tolerance(pairs, pmag, pcond);
		ref->av_tol[i] = tolerance(pairs, vmag, vcond);
	}
}

static void check_against_reference(const ref_case *c, uint32_t seed, const char *label)
{
	static snapshot s;
	static reference ref;
	memset(&s, 0, sizeof s);
	double m;
	run_passes(c, seed, &s, &m);
	if (s.n != NP)
		return;
	evaluate_reference(c, &s, m, &ref);
	/* worst error over the particles, in units of each one's tolerance */
	double worst_rho = 0, worst_p = 0, worst_v = 0, mean_pmag = 0, mean_vmag = 0;
	int bad = 0;
	for (size_t i = 0; i < s.n; ++i) {
		const int nt = ref.pairs[i];
		worst_rho = fmax(worst_rho, fabs(s.rho[i] - ref.rho[i]) / ref.rho_tol[i]);
		for (int a = 0; a < 3; ++a) {
			const double gp = s.a[1][a][i], gv = s.a[2][a][i];
			CHECK(s.a[0][a][i] == 0);
			const double ep = fabs(gp - ref.ap[a][i]) / ref.ap_tol[i];
			const double ev = fabs(gv - ref.av[a][i]) / ref.av_tol[i];
			if ((ep > 1 || ev > 1) && bad++ < 5)
				printf("    particle %zu axis %d (%d pairs, p_i %g, sums of |terms| %g %g): pressure %.9g vs %.9g, "
				       "viscous %.9g vs %.9g\n",
				       i, a, nt, s.p[i], ref.ap_mag[i], ref.av_mag[i], gp, ref.ap[a][i], gv, ref.av[a][i]);
			worst_p = fmax(worst_p, ep);
			worst_v = fmax(worst_v, ev);
		}
		mean_pmag += ref.ap_mag[i] / (double)s.n;
		mean_vmag += ref.av_mag[i] / (double)s.n;
	}
	printf("    %s: %zu particles, worst error / tolerance: density %.2f, pressure %.2f, viscosity %.2f (mean sum "
	       "of |terms| %.3g and %.3g m/s^2)\n",
	       label, s.n, worst_rho, worst_p, worst_v, mean_pmag, mean_vmag);
	CHECK(worst_rho <= 1);
	CHECK(worst_p <= 1);
	CHECK(worst_v <= 1);
	/* the block exercises what it should: pressures and both viscous parts */
	CHECK(mean_pmag > 1.0 && mean_vmag > 1.0);
}

/* sph_dfsph's passes (its header's equations), run on the random block by
 * eddy__dfsph_probe (dfsph.c) after one step of sph_density, against the
 * same kind of reference: with G_ij = m grad W_spiky(x_i - x_j) and
 * S_i = sum_j G_ij, no walls (B_i = 0, so D'_i = D_i):
 *   D_i = |S_i|^2 + sum_j |G_ij|^2,   R_i(v) = sum_j (v_i - v_j) . G_ij,
 *   a_i = -sum_j (k_i + k_j) G_ij   (the correction for a given k). */
eddy_status eddy__dfsph_probe(eddy_world *w, const float *k, float *inv_d, float *inv_dsym, float *rate, float *acc);

static void check_dfsph_against_reference(const ref_case *c, uint32_t seed, const char *label)
{
	/* sph_dfsph reads the velocities (the columns the probe reads) and writes
	 * only ax ay az (after gravity's, g = 0), pressure and its warm starts */
	eddy_system_id dens;
	eddy_world *w = ref_world(c, &dens);
	eddy_sph_dfsph_def df = eddy_default_sph_dfsph_def();
	CHECKF(eddy_system_valid(w, eddy_add_sph_dfsph(w, &df)), "%s", eddy_world_error(w));
	static eddy_vec3 pos[NP], vel[NP];
	random_block(seed, c->dx, pos, vel);
	CHECK(eddy_world_add_particles(w, NP, pos, vel) == EDDY_OK);
	CHECKF(eddy_world_step(w) == EDDY_OK, "%s", eddy_world_error(w));
	/* the rows as the step left them (in cell order; no integrator moved them) */
	size_t n = 0;
	const char *names[6] = {"x", "y", "z", "vx", "vy", "vz"};
	const float *col[6];
	for (int a = 0; a < 6; ++a)
		col[a] = eddy_world_channel(w, names[a], &n);
	CHECK(n == NP && col[5]);
	if (n != NP || !col[5]) {
		eddy_destroy_world(w);
		return;
	}
	/* an irregular k, 0 for every fifth particle as for one without pressure */
	static float k[NP], inv_d[NP], inv_dsym[NP], rate[NP], acc[3 * NP];
	for (size_t i = 0; i < n; ++i)
		k[i] = i % 5 == 0 ? 0.0f : 1e-3f * (float)(1 + i * 7 % 11);
	CHECK(eddy__dfsph_probe(w, k, inv_d, inv_dsym, rate, acc) == EDDY_OK);
	const double m = eddy_sph_particle_mass(w, dens), h = c->h;
	const double spiky = -45.0 / (M_PI * pow(h, 6));
	double worst_d = 0, worst_r = 0, worst_a = 0, mean_rmag = 0;
	for (size_t i = 0; i < n; ++i) {
		double S[3] = {0, 0, 0}, s2 = 0, R = 0, a[3] = {0, 0, 0};
		double smag[3] = {0, 0, 0}, scond[3] = {0, 0, 0}, s2cond = 0, rmag = 0, rcond = 0, amag[3] = {0, 0, 0},
			   acond[3] = {0, 0, 0};
		int pairs = 0;
		for (size_t j = 0; j < n; ++j) {
			const double rv[3] = {col[0][i] - col[0][j], col[1][i] - col[1][j], col[2][i] - col[2][j]};
			const double r = sqrt(rv[0] * rv[0] + rv[1] * rv[1] + rv[2] * rv[2]);
			if (j == i || r >= h)
				continue;
			pairs++;
			/* G has (h - r)^2, |G|^2 (h - r)^4: their conditioning (see tolerance()) */
			const double kr = 2 * r / (h - r);
			for (int e = 0; e < 3; ++e) {
				const double g = m * spiky * (h - r) * (h - r) / r * rv[e];
				const double rt = (col[3 + e][i] - col[3 + e][j]) * g, at = -((double)k[i] + k[j]) * g;
				S[e] += g;
				s2 += g * g;
				R += rt;
				a[e] += at;
				smag[e] += fabs(g);
				scond[e] += fabs(g) * kr;
				s2cond += g * g * 2 * kr;
				rmag += fabs(rt);
				rcond += fabs(rt) * kr;
				amag[e] += fabs(at);
				acond[e] += fabs(at) * kr;
			}
		}
		/* D's error: sum |G|^2's, plus |S|^2's from each S_e's error
		 * (2 |S_e| dS_e + dS_e^2), plus the few roundings of the products,
		 * the sums and 1 / D (4 u D) */
		const double D = S[0] * S[0] + S[1] * S[1] + S[2] * S[2] + s2;
		double d_tol = tolerance(3 * pairs, s2, s2cond) + 4 * ROUNDOFF * D;
		for (int e = 0; e < 3; ++e) {
			const double ds = tolerance(pairs, smag[e], scond[e]);
			d_tol += 2 * fabs(S[e]) * ds + ds * ds;
		}
		worst_d = fmax(worst_d, fabs(1.0 / inv_d[i] - D) / d_tol);
		worst_d = fmax(worst_d, fabs(1.0 / inv_dsym[i] - D) / d_tol);
		worst_r = fmax(worst_r, fabs(rate[i] - R) / tolerance(3 * pairs, rmag, rcond));
		for (int e = 0; e < 3; ++e)
			worst_a = fmax(worst_a, fabs(acc[3 * i + e] - a[e]) / tolerance(pairs, amag[e], acond[e]));
		mean_rmag += rmag / (double)n;
	}
	printf("    %s: worst error / tolerance: D and D' %.2f, rate %.2f, correction %.2f (mean sum of |rate terms| "
	       "%.3g kg/(m^3 s))\n",
	       label, worst_d, worst_r, worst_a, mean_rmag);
	CHECK(worst_d <= 1);
	CHECK(worst_r <= 1);
	CHECK(worst_a <= 1);
	/* the block exercises the rate: approaching and receding pairs */
	CHECK(mean_rmag > 1.0);
	eddy_destroy_world(w);
}

/* Two cases: the default water setup (h = 2 spacings), and one step beyond
 * it, a wider support (h = 2.6 spacings: some 60% more neighbours per
 * particle and other last-group sizes) with a stiffer EOS, a larger
 * viscosity and a scaled pressure force. */
static void passes_match_double_reference(void)
{
	const ref_case water = {0.01f, 0.02f, 1000.0f, 400.0f, 1e-3f, 0.05f, 1.0f};
	const ref_case wide = {0.01f, 0.026f, 1000.0f, 2000.0f, 0.05f, 0.2f, 0.7f};
	char *saved = test_env_save("EDDY_NO_AVX2");
	for (int path = 0; path < 2; ++path) {
		test_env_set("EDDY_NO_AVX2", path == 0 ? NULL : "1");
		char label[64];
		snprintf(label, sizeof label, "h = 2 dx%s", path ? ", EDDY_NO_AVX2" : "");
		check_against_reference(&water, 12345u, label);
		snprintf(label, sizeof label, "h = 2.6 dx%s", path ? ", EDDY_NO_AVX2" : "");
		check_against_reference(&wide, 777u, label);
		snprintf(label, sizeof label, "dfsph, h = 2 dx%s", path ? ", EDDY_NO_AVX2" : "");
		check_dfsph_against_reference(&water, 12345u, label);
		snprintf(label, sizeof label, "dfsph, h = 2.6 dx%s", path ? ", EDDY_NO_AVX2" : "");
		check_dfsph_against_reference(&wide, 777u, label);
	}
	test_env_restore("EDDY_NO_AVX2", saved);
}

/* Every back-end gives the bits the passes gave before they were written
 * once against simd.h: the state after two frames of the WCSPH dam break
 * (pressure, viscosity, boundary particles) and of the droplet (surface
 * tension), pinned from main's build of that time, on the build's back-end
 * and with EDDY_NO_AVX2=1. make test SIMD=scalar runs this too, so the
 * scalar back-end is held to the same bits. The third is a DFSPH column
 * of 52,020 particles (2 threads), above the size up to which sph_dfsph
 * stores its pair gradients (DFSPH_STORE_BYTES): its passes recompute them,
 * and must give the bits the stored ones gave (pinned from main at e266694,
 * which stored them at every size; re-pinned when the velocity solve's warm
 * start and stopping rule changed the physics, and again when the velocity
 * solve became an equality (k of either sign), each from that build and the
 * same build with DFSPH_STORE_BYTES at 2 GB, which gave the same bits). All
 * three were re-pinned once more when the state hash became chunked (its
 * value, not the states: main's build gave the old pins on the same code),
 * and the column again when DFSPH's walls stopped pulling a particle that
 * leaves them (its surface beside the side walls). Re-pinned when the
 * dam break's speed of sound came from the scene (19.8 m/s, not 20) and
 * emit_box stopped losing a layer to float rounding (the 0.65 m column
 * holds 52 x 52 particles across, not 51 x 51). Re-pinned when WCSPH
 * scenes made by eddy.fluid began to settle their start (world.c, settle:
 * the dam break's column needs no settling, but its first step's sums come
 * in another order). Re-pinned when the walls' pressure took g from the
 * gravity systems (none while settling) instead of the world's def: the
 * settling's check of the column no longer leaves the walls' carried
 * density with gravity's part in it. The droplet re-pinned when the
 * surface tension took the colour field's free-surface share into account
 * (sph_surface_tension).
 * GCC on x86-64 (no FMA contraction under
 * -std=c11); another compiler or libm may round differently, and the
 * message says so. */
static void backends_give_the_pinned_bits(void)
{
	static const struct {
		const char *scene, *args, *hash;
	} pinned[] = {{"dam_break", "", "e32f936e92c6e9a6"},
	              {"droplet", "", "f4fe954f75d72fe8"},
	              {"stress/still_water", "--set width=0.65 --set depth=0.25 --threads 2", "60991acc68bb87cb"}};
	for (int k = 0; k < 3; ++k)
		for (int path = 0; path < 2; ++path) {
			char cmd[512], out[4096];
			snprintf(cmd, sizeof cmd,
			         "%s %s/eddy run scenes/%s.lua %s --frames 2 --stats - --quiet --out %s/pinned_bits | tail -1 | "
			         "grep -o '\"state_hash\":\"[0-9a-f]*\"'",
			         path ? "EDDY_NO_AVX2=1" : "env -u EDDY_NO_AVX2", test_build_dir(), pinned[k].scene, pinned[k].args,
			         test_build_dir());
			CHECK(test_sh(cmd, out, sizeof out) == 0);
			char want[64];
			snprintf(want, sizeof want, "\"state_hash\":\"%s\"", pinned[k].hash);
			printf("    %s, 2 frames%s: %s", pinned[k].scene, path ? ", EDDY_NO_AVX2" : "", out);
			CHECKF(strstr(out, want) != NULL, "%s: %s, pinned %s (another compiler or libm may round differently)",
			       pinned[k].scene, out, pinned[k].hash);
		}
}

void suite_sph_reference(void)
{
	RUN(passes_match_double_reference);
	RUN(backends_give_the_pinned_bits);
}
