/* SPDX-License-Identifier: MIT */
/* SPH (Mueller 2003) validation: kernels against their analytic integrals and
 * lattice sums, then whole scenes against physics (hydrostatic tank, dam
 * break vs Martin & Moyce, oscillating drop vs Rayleigh) and the hard cases
 * of docs/validation.md section C. Sizes are small so the suite runs in seconds;
 * every test prints the figure it checks. */
#include "test.h"

#include <stdlib.h>
#include <string.h>

#include "eddy.h"

#ifndef M_PI
#define M_PI 3.14159265358979323846
#endif

/* ---- kernels ------------------------------------------------------------ */

/* 4 pi int_0^h W(r) r^2 dr by the midpoint rule (fine enough for the 1/r
 * singularity of the viscosity kernel, whose r^2 W is finite). */
static double kernel_integral(eddy_sph_kernel k, double h)
{
	const int n = 200000;
	double s = 0, dr = h / n;
	for (int i = 0; i < n; ++i) {
		double r = (i + 0.5) * dr;
		s += eddy_sph_kernel_value(k, r, h) * r * r;
	}
	return 4 * M_PI * s * dr;
}

static void kernels_integrate_to_one(void)
{
	const double hs[] = {0.02, 1.0, 3.5};
	for (int i = 0; i < 3; ++i) {
		CHECK_NEAR(kernel_integral(EDDY_SPH_POLY6, hs[i]), 1.0, 1e-6);
		CHECK_NEAR(kernel_integral(EDDY_SPH_SPIKY, hs[i]), 1.0, 1e-6);
		CHECK_NEAR(kernel_integral(EDDY_SPH_VISCOSITY, hs[i]), 1.0, 1e-5);
	}
	/* compact support, and the constants the literature copies wrong (65 pi) */
	CHECK(eddy_sph_kernel_value(EDDY_SPH_POLY6, 1.0, 1.0) == 0);
	CHECK(eddy_sph_kernel_value(EDDY_SPH_SPIKY, 1.2, 1.0) == 0);
	CHECK_NEAR(eddy_sph_kernel_value(EDDY_SPH_POLY6, 0, 1.0), 315.0 / (64 * M_PI), 1e-12);
	CHECK_NEAR(eddy_sph_kernel_value(EDDY_SPH_SPIKY, 0, 1.0), 15.0 / M_PI, 1e-12);
	CHECK_NEAR(eddy_sph_kernel_laplacian(EDDY_SPH_VISCOSITY, 0, 1.0), 45.0 / M_PI, 1e-12);
}

/* The derivative and Laplacian agree with finite differences of the value. */
static void kernel_derivatives_match_finite_differences(void)
{
	const double h = 0.5, e = 1e-6;
	const eddy_sph_kernel ks[] = {EDDY_SPH_POLY6, EDDY_SPH_SPIKY, EDDY_SPH_VISCOSITY};
	for (int k = 0; k < 3; ++k)
		for (double r = 0.05; r < h - 0.01; r += 0.04) {
			double fd = (eddy_sph_kernel_value(ks[k], r + e, h) - eddy_sph_kernel_value(ks[k], r - e, h)) / (2 * e);
			double an = eddy_sph_kernel_derivative(ks[k], r, h);
			CHECKF(fabs(fd - an) <= 1e-5 * (fabs(an) + 1), "kernel %d r %g: dW/dr %g vs fd %g", k, r, an, fd);
			/* Laplacian = (1/r^2) d/dr (r^2 dW/dr) */
			double g1 = (r + e) * (r + e) * eddy_sph_kernel_derivative(ks[k], r + e, h);
			double g0 = (r - e) * (r - e) * eddy_sph_kernel_derivative(ks[k], r - e, h);
			double lfd = (g1 - g0) / (2 * e) / (r * r), lan = eddy_sph_kernel_laplacian(ks[k], r, h);
			CHECKF(fabs(lfd - lan) <= 1e-4 * (fabs(lan) + 1), "kernel %d r %g: lap %g vs fd %g", k, r, lan, lfd);
		}
}

/* Lattice facts (docs/validation.md A): sum V W at h = 1.5, 2, 2.5, 3 spacings, the
 * spiky kernel's 24% excess, and sum V (x_j - x_i) (x) grad W = -I with the
 * gradient taken with respect to x_j (+I with respect to x_i, as here). */
static void lattice_sums(void)
{
	const double dx = 0.01, V = dx * dx * dx;
	CHECK_NEAR(V * eddy_sph_lattice_sum(EDDY_SPH_POLY6, dx, 1.5 * dx), 0.949, 0.001);
	CHECK_NEAR(V * eddy_sph_lattice_sum(EDDY_SPH_POLY6, dx, 2.0 * dx), 1.0098, 0.0005);
	CHECK_NEAR(V * eddy_sph_lattice_sum(EDDY_SPH_POLY6, dx, 2.5 * dx), 0.995, 0.001);
	CHECK_NEAR(V * eddy_sph_lattice_sum(EDDY_SPH_POLY6, dx, 3.0 * dx), 1.002, 0.001);
	CHECK_NEAR(V * eddy_sph_lattice_sum(EDDY_SPH_SPIKY, dx, 2.0 * dx), 1.236, 0.001);
	/* the gradient's first moment: 1 in the continuum, short on coarse
	 * lattices (sph_pressure divides by it), closer to 1 as h / dx grows */
	CHECK_NEAR(eddy_sph_lattice_gradient_moment(EDDY_SPH_SPIKY, dx, 2.0 * dx), 0.9563, 0.0005);
	CHECK_NEAR(eddy_sph_lattice_gradient_moment(EDDY_SPH_POLY6, dx, 2.0 * dx), 1.0649, 0.0005);
	CHECK_NEAR(eddy_sph_lattice_gradient_moment(EDDY_SPH_SPIKY, dx, 6.0 * dx), 1.0, 0.005);
	/* gradient consistency: the xx entry (1 exactly in the continuum) and the
	 * off-diagonal xy entry (0 by symmetry) on an interior lattice point */
	const eddy_sph_kernel ks[] = {EDDY_SPH_POLY6, EDDY_SPH_SPIKY};
	for (int k = 0; k < 2; ++k) {
		const double h = 3 * dx;
		double xx = 0, xy = 0;
		for (int i = -3; i <= 3; ++i)
			for (int j = -3; j <= 3; ++j)
				for (int l = -3; l <= 3; ++l) {
					double rx = i * dx, ry = j * dx, rz = l * dx, r = sqrt(rx * rx + ry * ry + rz * rz);
					if (r == 0)
						continue;
					/* grad_i W(x_i - x_j) with x_j - x_i = (rx, ry, rz) */
					double dw = eddy_sph_kernel_derivative(ks[k], r, h);
					double gx = dw * -rx / r, gy = dw * -ry / r;
					xx += V * rx * gx;
					xy += V * rx * gy;
					(void)gy;
				}
		printf("    lattice gradient tensor, kernel %d at h = 3 dx: xx = %.4f, xy = %.1e\n", k, xx, xy);
		CHECK_NEAR(xx, 1.0, 0.02);
		CHECK_NEAR(xy, 0.0, 1e-9);
	}
}

/* ---- scenes ------------------------------------------------------------- */

typedef struct sph_setup {
	float dx;             /* m, particle spacing (h = 2 dx) */
	eddy_vec3 lo, hi;     /* m, tank (and world bounds) */
	eddy_vec3 fmin, fmax; /* m, fluid block */
	float k;              /* m^2/s^2, stiffness */
	float mu;             /* Pa s */
	float sigma;          /* N/m, < 0: no surface tension system */
	float gravity;        /* m/s^2 downwards, the world's vector */
	bool gravity_system;  /* a gravity system applies it (false: weightless whatever the vector) */
	bool walls;           /* boundary particles on the tank */
	int threads;
	double cfl;
	double fps;                      /* frames per second */
	const eddy_sph_dfsph_def *dfsph; /* the implicit solve in place of sph_pressure, or NULL */
	eddy_sph_density_mode density;   /* sph_density's: summation or continuity */
	eddy_emit_shape shape;           /* the fluid block, or the ellipsoid inscribed in it */
	float artificial;                /* 1, sph_viscosity's Monaghan alpha */
} sph_setup;

static sph_setup default_setup(void)
{
	sph_setup s;
	s.dx = 0.01f;
	s.lo = (eddy_vec3){0, 0, 0};
	s.hi = (eddy_vec3){0.1f, 0.2f, 0.1f};
	s.fmin = s.lo;
	s.fmax = (eddy_vec3){0.1f, 0.1f, 0.1f};
	s.k = 200;
	s.mu = 0.05f;
	s.sigma = -1;
	s.gravity = 9.81f;
	s.gravity_system = true;
	s.walls = true;
	s.threads = 1;
	s.cfl = 0.4;
	s.fps = 100;
	s.dfsph = NULL;
	s.density = EDDY_SPH_DENSITY_SUMMATION;
	s.shape = EDDY_EMIT_BLOCK;
	s.artificial = eddy_default_sph_viscosity_def().artificial;
	return s;
}

/* The scene of a setup: WCSPH (sph_pressure before the other forces) or,
 * with s->dfsph, the implicit solve after gravity and viscosity and before
 * integrate. */
static eddy_world *sph_world(const sph_setup *s, eddy_system_id *density)
{
	eddy_world_def d = eddy_default_world_def();
	d.bounds_min = s->lo;
	d.bounds_max = s->hi;
	d.gravity = (eddy_vec3){0, -s->gravity, 0};
	d.threads = s->threads;
	d.cfl = s->cfl;
	d.fps = s->fps;
	eddy_world *w = eddy_create_world(&d, NULL, 0);
	eddy_emit_box_def b = eddy_default_emit_box_def();
	b.min = s->fmin;
	b.max = s->fmax;
	b.spacing = s->dx;
	b.shape = s->shape;
	CHECK(eddy_system_valid(w, eddy_add_emit_box(w, &b)));
	eddy_sph_density_def de = eddy_default_sph_density_def();
	de.spacing = s->dx;
	de.radius = 2 * s->dx;
	de.stiffness = s->k;
	de.density = s->density;
	eddy_system_id id = eddy_add_sph_density(w, &de);
	CHECKF(eddy_system_valid(w, id), "%s", eddy_world_error(w));
	if (density)
		*density = id;
	eddy_gravity_def g = eddy_default_gravity_def();
	if (s->dfsph) {
		if (s->gravity_system)
			CHECK(eddy_system_valid(w, eddy_add_gravity(w, &g)));
	} else {
		eddy_sph_pressure_def pr = eddy_default_sph_pressure_def();
		CHECK(eddy_system_valid(w, eddy_add_sph_pressure(w, &pr)));
	}
	eddy_sph_viscosity_def vi = eddy_default_sph_viscosity_def();
	vi.viscosity = s->mu;
	vi.artificial = s->artificial;
	CHECK(eddy_system_valid(w, eddy_add_sph_viscosity(w, &vi)));
	if (s->sigma >= 0) {
		eddy_sph_surface_tension_def st = eddy_default_sph_surface_tension_def();
		st.tension = s->sigma;
		CHECK(eddy_system_valid(w, eddy_add_sph_surface_tension(w, &st)));
	}
	if (s->dfsph)
		CHECKF(eddy_system_valid(w, eddy_add_sph_dfsph(w, s->dfsph)), "%s", eddy_world_error(w));
	if (s->walls) {
		eddy_sph_boundary_box_def bb = eddy_default_sph_boundary_box_def();
		bb.min = s->lo;
		bb.max = s->hi;
		bb.spacing = s->dx;
		CHECK(eddy_system_valid(w, eddy_add_sph_boundary_box(w, &bb)));
	}
	if (!s->dfsph && s->gravity_system)
		eddy_add_gravity(w, &g);
	eddy_integrate_def it = eddy_default_integrate_def();
	eddy_add_integrate(w, &it);
	eddy_collide_box_def bx = eddy_default_collide_box_def();
	bx.min = s->lo;
	bx.max = s->hi;
	eddy_add_collide_box(w, &bx);
	return w;
}

/* A block falling into a 20 x 10 x 4 cm tank: the splash the determinism
 * and SIMD tests hash. */
static sph_setup splash_setup(void)
{
	sph_setup s = default_setup();
	s.hi = (eddy_vec3){0.2f, 0.1f, 0.04f};
	s.fmax = (eddy_vec3){0.06f, 0.08f, 0.04f};
	return s;
}

/* The state hash after some frames of the setup on 1 and on 2 threads. */
static void hashes_on_one_and_two_threads(sph_setup s, int frames, uint64_t hash[2])
{
	for (int t = 0; t < 2; ++t) {
		s.threads = t + 1;
		eddy_world *w = sph_world(&s, NULL);
		for (int f = 0; f < frames; ++f)
			CHECK(eddy_world_step_frame(w) == EDDY_OK);
		hash[t] = eddy_world_state_hash(w);
		eddy_destroy_world(w);
	}
}

/* Writes the scene text to name in the suite's folder and runs `eddy check`
 * on it, its output (stderr included) in out: the exit status. The file is
 * removed after. */
static int check_scene(const char *name, const char *text, char *out, size_t cap)
{
	char path[512], cmd[1200];
	snprintf(path, sizeof path, "%s/%s", test_out_dir(), name);
	FILE *f = fopen(path, "w");
	CHECK(f != NULL);
	if (!f) {
		snprintf(out, cap, "cannot write %s", path);
		return -1;
	}
	fputs(text, f);
	fclose(f);
	snprintf(cmd, sizeof cmd, "%s/eddy check %s", test_build_dir(), path);
	const int code = test_sh(cmd, out, cap);
	remove(path);
	return code;
}

/* Runs a 8 frames and b 4, saves b to name in the suite's folder, loads
 * that into c and runs it 4 more: c must end bit-identical to a. Destroys
 * the three. */
static void check_resume_bit_identical(eddy_world *a, eddy_world *b, eddy_world *c, const char *name)
{
	for (int f = 0; f < 8; ++f)
		CHECK(eddy_world_step_frame(a) == EDDY_OK);
	for (int f = 0; f < 4; ++f)
		CHECK(eddy_world_step_frame(b) == EDDY_OK);
	char path[512];
	snprintf(path, sizeof path, "%s/%s", test_out_dir(), name);
	CHECK(eddy_world_save(b, path, 3) == EDDY_OK);
	CHECKF(eddy_world_load(c, path, 3) == EDDY_OK, "%s", eddy_world_error(c));
	for (int f = 0; f < 4; ++f)
		CHECK(eddy_world_step_frame(c) == EDDY_OK);
	CHECK(eddy_world_state_hash(c) == eddy_world_state_hash(a));
	remove(path);
	eddy_destroy_world(a);
	eddy_destroy_world(b);
	eddy_destroy_world(c);
}

static int cmp_float(const void *a, const void *b)
{
	const float u = *(const float *)a, v = *(const float *)b;
	return (u > v) - (u < v);
}

static double max_speed(const eddy_world *w)
{
	size_t n;
	const float *vx = eddy_world_channel(w, "vx", &n), *vy = eddy_world_channel(w, "vy", NULL),
				*vz = eddy_world_channel(w, "vz", NULL);
	double m = 0;
	for (size_t i = 0; i < n; ++i)
		m = fmax(m, sqrt((double)vx[i] * vx[i] + (double)vy[i] * vy[i] + (double)vz[i] * vz[i]));
	return m;
}

/* Hydrostatic tank (C.2, C.3): a 10^3 block settles for 0.5 s in a tank with
 * boundary particles, then p - rho0 g d is averaged over 0.6 s (every step:
 * frames at 100 Hz would alias the column's ringing at c / 4H = 35 Hz), for
 * the particles more than h from walls, floor and surface, by layers one
 * spacing thick and over all of them. The depth d of a particle is that of
 * the fluid above it at rest density, m N_above / (rho0 A), so rho0 g d is
 * the weight above per unit area: no surface position to guess (the top
 * particles splash), and a column that compresses still has its true
 * hydrostatic pressure as the reference.
 * The bound from k: p = k (rho - rho0) needs the fluid compressed by up to
 * g H / k, vertically only, and both lattice calibrations (the mass for the
 * density sum, the spiky gradient's moment for the pressure force) hold for
 * the undeformed lattice: each is off by up to g H / k, so the column's mean
 * pressure may be off the weight above by 2 (g H / k) rho0 g H. The mean
 * error is held to that plus three standard errors of its own measurement
 * (from six 0.1 s blocks): the particles never stop rearranging out of the
 * initial cubic lattice (rms speed ~0.04 sqrt(gH)), and that motion is the
 * noise. Measured: +0.62% +- 0.26% against 0.97% + 0.78%; without the
 * gradient calibration +3.7%. Found on the way: the mean error stays at
 * +0.6 to +0.9% for k = 100 to 800, so what is left is not compressibility
 * but the particles' disorder, and at k = 800 this bound would not hold.
 * Single layers scatter more (one layer at +3%): held to 5%.
 * The bottom layer's density is rho0 (1 + g H / k) (C.3). */
static void hydrostatic_tank_with(eddy_sph_density_mode mode)
{
	sph_setup s = default_setup();
	s.density = mode;
	eddy_system_id density;
	eddy_world *w = sph_world(&s, &density);
	CHECKF(eddy_world_advance(w, 0.5) == EDDY_OK, "%s", eddy_world_error(w));
	size_t n = eddy_world_particle_count(w);
	/* the table is reordered every step: average per layer, not per particle */
	/* every step, not every frame: frames (100 Hz) would alias the column's
	 * ringing (c / 4H = 35 Hz) into the mean */
	enum { LAYERS = 10, BLOCKS = 6 };
	const double t0 = eddy_world_time(w), span = 0.6;
	int samples = 0;
	double lsum[LAYERS] = {0}, lcount[LAYERS] = {0}, bsum[BLOCKS] = {0}, bcount[BLOCKS] = {0};
	double dsum = 0, dcount = 0, top_sum = 0, v2sum = 0, vcount = 0, xmin = 1, xmax = 0, ymin = 1;
	const double rho0 = 1000, g = 9.81, h = 2 * s.dx, H = s.fmax.y; /* rho0 g H: the scale of the errors */
	const double m = eddy_sph_particle_mass(w, density), area = (double)(s.hi.x - s.lo.x) * (s.hi.z - s.lo.z);
	float *sorted = malloc(n * sizeof *sorted);
	while (eddy_world_time(w) < t0 + span) {
		CHECKF(eddy_world_step(w) == EDDY_OK, "%s", eddy_world_error(w));
		const int blk = (int)fmin(BLOCKS - 1, (eddy_world_time(w) - t0) / span * BLOCKS);
		samples++;
		const float *x = eddy_world_channel(w, "x", &n), *y = eddy_world_channel(w, "y", NULL),
					*z = eddy_world_channel(w, "z", NULL), *p = eddy_world_channel(w, "pressure", NULL),
					*rho = eddy_world_channel(w, "density", NULL), *vx = eddy_world_channel(w, "vx", NULL),
					*vy = eddy_world_channel(w, "vy", NULL), *vz = eddy_world_channel(w, "vz", NULL);
		double top = 0;
		for (size_t i = 0; i < n; ++i) {
			top = fmax(top, y[i]);
			sorted[i] = y[i];
		}
		qsort(sorted, n, sizeof *sorted, cmp_float);
		for (size_t i = 0; i < n; ++i) {
			xmin = fmin(xmin, fmin(x[i], z[i]));
			xmax = fmax(xmax, fmax(x[i], z[i]));
			ymin = fmin(ymin, y[i]);
			v2sum += (double)vx[i] * vx[i] + (double)vy[i] * vy[i] + (double)vz[i] * vz[i];
			vcount++;
			size_t lo = 0, hi = n; /* particles at or below y[i] */
			while (lo < hi) {
				const size_t mid = (lo + hi) / 2;
				if (sorted[mid] <= y[i])
					lo = mid + 1;
				else
					hi = mid;
			}
			const double d = m * ((double)(n - lo) + 0.5) / (rho0 * area), e = (p[i] - rho0 * g * d) / (rho0 * g * H);
			const int layer = (int)(y[i] / s.dx);
			if (d > h && y[i] > h && x[i] > h && x[i] < s.hi.x - h && z[i] > h && z[i] < s.hi.z - h && layer < LAYERS) {
				lsum[layer] += e;
				lcount[layer]++;
				bsum[blk] += e;
				bcount[blk]++;
			}
			if (y[i] < s.dx) {
				dsum += rho[i];
				dcount++;
			}
		}
		top_sum += top;
	}
	double worst = 0, mean = 0, var = 0, total = 0;
	int used = 0;
	for (int l = 0; l < LAYERS; ++l)
		if (lcount[l] > 10.0 * samples) { /* a layer the interior fills, not a stray particle */
			worst = fmax(worst, fabs(lsum[l] / lcount[l]));
			used++;
		}
	for (int b = 0; b < BLOCKS; ++b) {
		mean += bsum[b];
		total += bcount[b];
	}
	mean /= total;
	for (int b = 0; b < BLOCKS; ++b)
		var += pow(bsum[b] / bcount[b] - mean, 2) / (BLOCKS - 1);
	const double se = sqrt(var / BLOCKS), surface = top_sum / samples + s.dx / 2;
	const double gH_k = g * surface / s.k, rho_bottom = dsum / dcount / rho0, vrms = sqrt(v2sum / vcount);
	printf(
		"    hydrostatic (%s density): mean (p - rho0 g d) / (rho0 g H) %+.4f +- %.4f (bound 2 gH/k = %.4f), worst of "
		"%d layers "
		"%.4f, "
		"bottom rho/rho0 %.4f (1 + gH/k = %.4f), closest to walls x/z %.4f / %.4f y %.4f m, rms speed %.3f sqrt(gH)\n",
		mode == EDDY_SPH_DENSITY_CONTINUITY ? "continuity" : "summation", mean, se, 2 * gH_k, used, worst, rho_bottom,
		1 + gH_k, xmin, s.hi.x - xmax, ymin, vrms / sqrt(g * H));
	free(sorted);
	CHECK(used >= 5);
	/* continuity: the density is rho0 where nothing compresses it, so the
	 * pressure carries rho0 a spacing^3 where the weight above is m a
	 * spacing^3 (1 - m / (rho0 dx^3) = 0.98% less at h = 2 dx: the mass is
	 * calibrated for the summation): allowed on top (measured +2.1%, +1.8%
	 * with the particles started at rho0 rather than hydrostatic) */
	const double mass_gap = mode == EDDY_SPH_DENSITY_CONTINUITY ? 1 - m / (rho0 * pow(s.dx, 3)) : 0;
	CHECK(fabs(mean) <= 2 * gH_k + 3 * se + mass_gap);
	CHECK(se < gH_k); /* the measurement itself must be able to tell */
	CHECK(worst < 0.05);
	CHECK_NEAR(rho_bottom, 1 + gH_k, gH_k);
	/* no wall gap: the lattice sits half a spacing from each wall; a gap of
	 * half a spacing more would show as a distance above one spacing */
	CHECK(xmin < s.dx && s.hi.x - xmax < s.dx && ymin < s.dx);
	CHECK(vrms < 0.1 * sqrt(g * H));
	eddy_destroy_world(w);
}

static void hydrostatic_tank(void) { hydrostatic_tank_with(EDDY_SPH_DENSITY_SUMMATION); }

/* The same tank with the density carried by the continuity equation and
 * delta-SPH diffusion (sph_density's density = continuity), to the same
 * bounds. */
static void hydrostatic_tank_continuity(void) { hydrostatic_tank_with(EDDY_SPH_DENSITY_CONTINUITY); }

/* C.8: a block at rest, without gravity, in free space and in a tank. With
 * the mass calibrated on the lattice every particle starts at rho0 (the
 * surface below it, clamped to p = 0), so nothing moves; with the naive mass
 * (rho0 spacing^3) the interior starts 1% over rho0 and the layer under the
 * surface is kicked outwards at once. */
static void resting_block_stays_at_rest(void)
{
	for (int c = 0; c < 4; ++c) {
		const int walls = c % 2;
		sph_setup s = default_setup();
		/* c = 2, 3: the continuity density (new particles start at rho0) */
		s.density = c >= 2 ? EDDY_SPH_DENSITY_CONTINUITY : EDDY_SPH_DENSITY_SUMMATION;
		s.gravity = 0;
		s.walls = walls;
		s.hi = (eddy_vec3){0.2f, 0.2f, 0.2f};
		s.fmin = walls ? s.lo : (eddy_vec3){0.05f, 0.05f, 0.05f};
		s.fmax = walls ? (eddy_vec3){0.2f, 0.1f, 0.2f} : (eddy_vec3){0.15f, 0.15f, 0.15f};
		eddy_system_id dens;
		eddy_world *w = sph_world(&s, &dens);
		const double m = eddy_sph_particle_mass(w, dens), naive = 1000.0 * s.dx * s.dx * s.dx;
		CHECK_NEAR(naive / m, 1.0098, 0.0005);
		for (int i = 0; i < 20; ++i)
			CHECK(eddy_world_step(w) == EDDY_OK);
		eddy_frame_stats st;
		CHECK(eddy_world_step_frame(w) == EDDY_OK);
		eddy_world_frame_stats(w, &st);
		const double v = max_speed(w);
		printf(
			"    resting block (%s density, walls %d): max speed %.2e m/s after %lld steps, density error max %.2e\n",
			s.density == EDDY_SPH_DENSITY_CONTINUITY ? "continuity" : "summation", walls, v,
			(long long)eddy_world_steps(w), st.density_err_max);
		/* the naive mass gives about k * 0.0098 rho0 over one layer: ~ 0.1 m/s here */
		CHECK(v < 1e-4);
		eddy_destroy_world(w);
	}
}

/* A pipeline with no gravity system is weightless whatever the world's
 * gravity vector says (its default is -9.81 along y): the walls' pressure
 * must hold no weight the water does not have. Before, the walls' terms
 * read the world's vector: a 10 cm block at rest in a closed 20 cm tank
 * rose towards the lid (DFSPH: its mean height 0.050 -> 0.107 m in 0.5 s,
 * 1.16 m/s; WCSPH 0.078 m). Held: at rest to 1e-4 m/s, its mean height to
 * 1e-5 m. */
static void no_gravity_system_no_weight(void)
{
	const eddy_sph_dfsph_def df = eddy_default_sph_dfsph_def();
	for (int dfsph = 0; dfsph < 2; ++dfsph) {
		sph_setup s = default_setup(); /* the world's vector -9.81 along y */
		s.gravity_system = false;
		s.dfsph = dfsph ? &df : NULL;
		s.fps = 30;
		eddy_world *w = sph_world(&s, NULL);
		double y0 = NAN, y = NAN, vmax = 0;
		for (int f = 0; f < 15; ++f) {
			CHECKF(eddy_world_step_frame(w) == EDDY_OK, "%s", eddy_world_error(w));
			size_t n;
			const float *py = eddy_world_channel(w, "y", &n);
			double sy = 0;
			for (size_t i = 0; i < n; ++i)
				sy += py[i];
			y = sy / (double)n;
			y0 = f == 0 ? y : y0;
			vmax = fmax(vmax, max_speed(w));
		}
		printf("    %s, no gravity system: mean height %.5f -> %.5f m, largest speed %.2e m/s\n",
		       dfsph ? "dfsph" : "wcsph", y0, y, vmax);
		CHECK(fabs(y - y0) <= 1e-5);
		CHECK(vmax <= 1e-4);
		eddy_destroy_world(w);
	}
}

static double min_pair_distance(const eddy_world *w)
{
	size_t n;
	const float *x = eddy_world_channel(w, "x", &n), *y = eddy_world_channel(w, "y", NULL),
				*z = eddy_world_channel(w, "z", NULL);
	double m2 = INFINITY;
	for (size_t i = 0; i < n; ++i)
		for (size_t j = i + 1; j < n; ++j) {
			const double dx = x[i] - x[j], dy = y[i] - y[j], dz = z[i] - z[j];
			m2 = fmin(m2, dx * dx + dy * dy + dz * dz);
		}
	return sqrt(m2);
}

static bool all_finite(const eddy_world *w)
{
	const char *cols[] = {"x", "y", "z", "vx", "vy", "vz", "density", "pressure"};
	for (int c = 0; c < 8; ++c) {
		size_t n;
		const float *v = eddy_world_channel(w, cols[c], &n);
		for (size_t i = 0; v && i < n; ++i)
			if (!isfinite(v[i]))
				return false;
	}
	return true;
}

static eddy_status no_step(eddy_world *w, const eddy_step_context *ctx, void *user)
{
	(void)w;
	(void)ctx;
	(void)user;
	return EDDY_OK;
}

/* sph_density keeps the table in grid-cell order (cells of h/2 from the world
 * bounds minus h, z slowest) and the reorder moves every particle column with
 * it, a custom one included: particles added in reverse lattice order carry a
 * tag made from their position, and after a step each row's tag still
 * matches its position. */
static void table_is_kept_in_cell_order(void)
{
	eddy_world_def d = eddy_default_world_def();
	d.gravity = (eddy_vec3){0, 0, 0};
	eddy_world *w = eddy_create_world(&d, NULL, 0);
	CHECK(eddy_world_declare_column(w, "tag", EDDY_DOMAIN_PARTICLE, EDDY_F32, EDDY_STATE, "") >= 0);
	eddy_custom_system_def cs = eddy_default_custom_system_def();
	const char *writes[] = {"tag"};
	cs.name = "tagger";
	cs.writes = writes;
	cs.write_count = 1;
	cs.step = no_step;
	CHECK(eddy_system_valid(w, eddy_add_custom_system(w, &cs)));
	eddy_sph_density_def de = eddy_default_sph_density_def();
	eddy_add_sph_density(w, &de);
	enum { N = 10 };
	eddy_vec3 pts[N * N * N];
	for (int k = 0; k < N * N * N; ++k) {
		const int q = N * N * N - 1 - k; /* reverse order: z fastest descending */
		pts[k] = (eddy_vec3){0.3f + 0.01f * (float)(q % N), 0.3f + 0.01f * (float)(q / N % N),
		                     0.3f + 0.01f * (float)(q / (N * N))};
	}
	CHECK(eddy_world_add_particles(w, N * N * N, pts, NULL) == EDDY_OK);
	size_t n;
	float *tag = eddy_world_channel_mut(w, "tag", &n);
	const float *x = eddy_world_channel(w, "x", NULL), *y = eddy_world_channel(w, "y", NULL),
				*z = eddy_world_channel(w, "z", NULL);
	for (size_t i = 0; i < n; ++i)
		tag[i] = x[i] + 10 * y[i] + 100 * z[i];
	CHECK(eddy_world_step(w) == EDDY_OK);
	tag = eddy_world_channel_mut(w, "tag", &n);
	x = eddy_world_channel(w, "x", NULL);
	y = eddy_world_channel(w, "y", NULL);
	z = eddy_world_channel(w, "z", NULL);
	const double h = de.radius, inv = 2 / h, o = -h; /* bounds start at 0 */
	const long gx = (long)ceil(1 * inv) + 4, gy = gx;
	long prev = -1;
	int unsorted = 0, mismatched = 0;
	for (size_t i = 0; i < n; ++i) {
		const long c = ((long)((z[i] - o) * inv) * gy + (long)((y[i] - o) * inv)) * gx + (long)((x[i] - o) * inv);
		unsorted += c < prev;
		prev = c;
		mismatched += fabsf(tag[i] - (x[i] + 10 * y[i] + 100 * z[i])) > 1e-4f;
	}
	CHECK(n == N * N * N);
	CHECK(unsorted == 0);
	CHECK(mismatched == 0);
	CHECK(x[0] < 0.301f && y[0] < 0.301f && z[0] < 0.301f); /* the first row is the lowest corner now */
	eddy_destroy_world(w);
}

/* Each SPH system reports its explicit limit (C.4, C.15) and the stats name
 * the active one: acoustic h / (c + |v|), viscous h^2 / (15 nu), each times
 * the CFL number 0.4, the viscous one from the first step on (the emitter
 * adds its particles within it). (The capillary limit scales like the force
 * limit of the surface particles it accelerates, which binds first here.) */
static void time_step_limits_are_reported(void)
{
	const double h = 0.02, cfl = 0.4;
	for (int which = 0; which < 2; ++which) {
		sph_setup s = default_setup();
		s.gravity = 0;
		s.mu = which == 1 ? 200.0f : 1e-3f;
		eddy_world *w = sph_world(&s, NULL);
		const double expect = which == 0 ? cfl * h / sqrt(s.k) : cfl * h * h / (15 * (s.mu / 1000.0));
		CHECK(eddy_world_step(w) == EDDY_OK); /* emits at rest */
		if (which == 1) /* bounded before any particle existed */
			CHECKF(eddy_world_time(w) <= expect * 1.001, "first step %.3e s, limit %.3e s", eddy_world_time(w),
			       expect);
		CHECK(eddy_world_step(w) == EDDY_OK);
		CHECK(eddy_world_step_frame(w) == EDDY_OK);
		CHECK(eddy_world_step_frame(w) == EDDY_OK);
		eddy_frame_stats st;
		eddy_world_frame_stats(w, &st);
		const char *name = which == 0 ? "sph_pressure: acoustic" : "sph_viscosity: viscous";
		printf("    limit %s: dt %.3e s (expected %.3e)\n", st.dt_limit, st.dt_max, expect);
		CHECK_HAS(st.dt_limit, name);
		CHECK(st.dt_max <= expect * 1.001 && st.dt_max > expect * 0.9);
		eddy_destroy_world(w);
	}
}

/* Both equations of state on a block packed 2% closer than the lattice the
 * mass is calibrated on (interior density about 1.06 rho0): each interior
 * particle's pressure is the EOS of its own density, and the surface
 * particles' negative pressure is clamped to 0 (C.1). */
static void equations_of_state(void)
{
	for (int tait = 0; tait < 2; ++tait) {
		eddy_world_def d = eddy_default_world_def();
		d.gravity = (eddy_vec3){0, 0, 0};
		eddy_world *w = eddy_create_world(&d, NULL, 0);
		eddy_emit_box_def b = eddy_default_emit_box_def();
		b.min = (eddy_vec3){0.3f, 0.3f, 0.3f};
		b.max = (eddy_vec3){0.398f, 0.398f, 0.398f};
		b.spacing = 0.0098f;
		eddy_add_emit_box(w, &b);
		eddy_sph_density_def de = eddy_default_sph_density_def();
		de.eos = tait ? EDDY_SPH_EOS_TAIT : EDDY_SPH_EOS_LINEAR;
		de.stiffness = 400;
		eddy_add_sph_density(w, &de);
		CHECK(eddy_world_step(w) == EDDY_OK);
		size_t n;
		const float *rho = eddy_world_channel(w, "density", &n), *p = eddy_world_channel(w, "pressure", NULL);
		double rho_max = 0, worst = 0;
		int clamped = 0;
		for (size_t i = 0; i < n; ++i) {
			const double r = rho[i] / 1000.0;
			const double expect = tait ? 400.0 * 1000.0 / 7.0 * (pow(r, 7) - 1) : 400.0 * (rho[i] - 1000.0);
			worst = fmax(worst, fabs(p[i] - fmax(expect, 0)) / (400.0 * 1000.0));
			clamped += expect < 0 && p[i] == 0;
			rho_max = fmax(rho_max, rho[i]);
		}
		printf("    %s EOS: max density %.1f, worst |p - EOS| / (k rho0) %.1e, %d surface particles clamped to p = 0\n",
		       tait ? "Tait" : "linear", rho_max, worst, clamped);
		/* the interior sums the packed lattice with the calibrated mass */
		CHECK_NEAR(rho_max,
		           1000.0 * eddy_sph_lattice_sum(EDDY_SPH_POLY6, 0.0098, 0.02) /
		               eddy_sph_lattice_sum(EDDY_SPH_POLY6, 0.01, 0.02),
		           0.05);
		CHECK(worst < 1e-5);
		CHECK(clamped > 100);
		eddy_destroy_world(w);
	}
}

/* C.6: a particle dropped exactly onto another inside a resting block. The
 * gradient has no direction at r = 0; skipping the pair (the usual r > 0
 * guard) leaves them stuck together forever, dividing by r gives NaN. */
static void coincident_particles_separate(void)
{
	sph_setup s = default_setup();
	s.gravity = 0;
	s.hi = (eddy_vec3){0.1f, 0.1f, 0.1f};
	eddy_world *w = sph_world(&s, NULL);
	CHECK(eddy_world_step(w) == EDDY_OK); /* emits the block */
	const eddy_vec3 p = {0.045f, 0.045f, 0.045f};
	CHECK(min_pair_distance(w) > 0.9 * s.dx);
	CHECK(eddy_world_add_particles(w, 1, &p, NULL) == EDDY_OK);
	CHECK(min_pair_distance(w) < 1e-6);
	for (int i = 0; i < 200; ++i)
		CHECKF(eddy_world_step(w) == EDDY_OK, "%s", eddy_world_error(w));
	const double d = min_pair_distance(w);
	printf("    coincident pair: closest pair %.3f spacings apart after 200 steps\n", d / s.dx);
	CHECK(all_finite(w));
	CHECK(d > 0.3 * s.dx);
	eddy_destroy_world(w);
}

/* C.4: a stiff fluid (c = 100 m/s, 50 x the flow speed) collapsing in a
 * tank. With dt from the acoustic limit it stays in the density band
 * [0.7, 1.3] rho0 (the fluid's side; surface particles are light) with a
 * full neighbourhood; with the step 5 x too long (CFL 2) it does not. */
static void high_stiffness_stays_bounded(void)
{
	for (int bad = 0; bad < 2; ++bad) {
		sph_setup s = splash_setup();
		s.k = 10000;
		s.cfl = bad ? 2.0 : 0.4;
		eddy_world *w = sph_world(&s, NULL);
		eddy_status st = EDDY_OK;
		double rho_max = 0, v_max = 0, nbr_mean = 0;
		for (int f = 0; f < 12 && st == EDDY_OK; ++f) {
			st = eddy_world_step_frame(w);
			if (st != EDDY_OK)
				break;
			size_t n;
			const float *rho = eddy_world_channel(w, "density", &n), *nb = eddy_world_channel(w, "neighbors", NULL);
			double sum = 0;
			for (size_t i = 0; i < n; ++i) {
				rho_max = fmax(rho_max, rho[i]);
				sum += nb[i];
			}
			nbr_mean = sum / (double)n;
			v_max = fmax(v_max, max_speed(w));
		}
		const bool ok = st == EDDY_OK && rho_max < 1300 && all_finite(w) && nbr_mean > 15 && v_max < 3;
		printf("    stiff fluid, CFL %.1f: %s, max density %.0f, mean neighbours %.1f, max speed %.2f m/s, dt %.2e s\n",
		       s.cfl, st == EDDY_OK ? "ran" : eddy_world_error(w), rho_max, nbr_mean, v_max, eddy_world_last_dt(w));
		CHECK(ok == !bad);
		eddy_destroy_world(w);
	}
}

/* C.5: a jet at 4 m/s against a plate 0.1 spacing thick, both as boundary
 * particles and as a collider. Per step a particle moves 0.4 spacings, four
 * times the plate: the collider alone would let it pass between two
 * steps; the boundary particles' pressure stops the jet before the plate. */
static void jet_does_not_tunnel_thin_plate(void)
{
	eddy_world_def d = eddy_default_world_def();
	d.bounds_max = (eddy_vec3){0.3f, 0.2f, 0.2f};
	d.gravity = (eddy_vec3){0, 0, 0};
	d.fps = 100;
	eddy_world *w = eddy_create_world(&d, NULL, 0);
	const float dx = 0.01f, plate = 0.2f;
	eddy_emit_nozzle_def nz = eddy_default_emit_nozzle_def();
	nz.center = (eddy_vec3){0.04f, 0.1f, 0.1f};
	nz.radius = 0.03f;
	nz.direction = (eddy_vec3){1, 0, 0};
	nz.speed = 4;
	nz.spacing = dx;
	nz.max_particles = 1500;
	CHECK(eddy_system_valid(w, eddy_add_emit_nozzle(w, &nz)));
	eddy_sph_density_def de = eddy_default_sph_density_def();
	de.spacing = dx;
	de.radius = 2 * dx;
	de.stiffness = 1600; /* c = 40 m/s, 10 x the jet */
	eddy_add_sph_density(w, &de);
	eddy_sph_pressure_def pr = eddy_default_sph_pressure_def();
	eddy_add_sph_pressure(w, &pr);
	eddy_sph_viscosity_def vi = eddy_default_sph_viscosity_def();
	eddy_add_sph_viscosity(w, &vi);
	eddy_sph_boundary_box_def bb = eddy_default_sph_boundary_box_def();
	bb.min = (eddy_vec3){plate, 0, 0};
	bb.max = (eddy_vec3){plate + 0.1f * dx, 0.2f, 0.2f};
	bb.spacing = dx;
	eddy_add_sph_boundary_box(w, &bb);
	eddy_integrate_def it = eddy_default_integrate_def();
	eddy_add_integrate(w, &it);
	eddy_collide_box_def cb = eddy_default_collide_box_def();
	cb.min = bb.min;
	cb.max = bb.max;
	cb.inside = false;
	eddy_add_collide_box(w, &cb);
	eddy_collide_box_def tank = eddy_default_collide_box_def();
	tank.max = d.bounds_max;
	eddy_add_collide_box(w, &tank);
	size_t beyond = 0, n = 0;
	for (int f = 0; f < 30; ++f) {
		CHECKF(eddy_world_step_frame(w) == EDDY_OK, "%s", eddy_world_error(w));
		const float *x = eddy_world_channel(w, "x", &n);
		for (size_t i = 0; i < n; ++i)
			beyond += x[i] > plate;
	}
	eddy_frame_stats st;
	eddy_world_frame_stats(w, &st);
	printf("    jet at a plate 0.1 spacing thick: %zu particles, %zu frames x particles beyond it, leaked %zu\n", n,
	       beyond, st.leaked);
	CHECK(n == 1500);
	CHECK(beyond == 0 && st.leaked == 0);
	eddy_destroy_world(w);
}

/* Results are identical for 1 and 2 threads: every particle gathers its own
 * sums in a fixed neighbour order, and the cell sort is stable. */
static void deterministic_across_threads(void)
{
	uint64_t hash[2];
	sph_setup s = splash_setup();
	s.sigma = 0.0728f;
	hashes_on_one_and_two_threads(s, 5, hash);
	printf("    state hash 1 thread %016llx, 2 threads %016llx\n", (unsigned long long)hash[0],
	       (unsigned long long)hash[1]);
	CHECK(hash[0] == hash[1]);
}

/* Surface-tension columns exist only while the system is in the pipeline;
 * removing it frees them. The neighbour count column comes with sph_density. */
static void surface_tension_columns_only_when_added(void)
{
	sph_setup s = default_setup();
	eddy_world *w = sph_world(&s, NULL);
	CHECK(eddy_world_channel(w, "color_nx", NULL) == NULL);
	CHECK(eddy_world_channel(w, "curvature", NULL) == NULL);
	CHECK(eddy_world_channel(w, "neighbors", NULL) != NULL);
	eddy_sph_surface_tension_def st = eddy_default_sph_surface_tension_def();
	eddy_system_id id = eddy_add_sph_surface_tension(w, &st);
	CHECK(eddy_system_valid(w, id));
	CHECK(eddy_world_channel(w, "color_nx", NULL) != NULL && eddy_world_channel(w, "curvature", NULL) != NULL);
	CHECK(eddy_world_remove_system(w, id) == EDDY_OK);
	CHECK(eddy_world_channel(w, "color_nx", NULL) == NULL);
	eddy_destroy_world(w);
	/* and an SPH system without sph_density before it is an order error that names the fix */
	eddy_world_def d = eddy_default_world_def();
	w = eddy_create_world(&d, NULL, 0);
	eddy_sph_pressure_def pr = eddy_default_sph_pressure_def();
	CHECK(!eddy_system_valid(w, eddy_add_sph_pressure(w, &pr)));
	CHECK_HAS(eddy_world_error(w), "add sph_density before it");
	eddy_destroy_world(w);
}

/* C.16: an SPH pipeline with no particles steps; all particles leaving the
 * domain (escape = remove) leaves an empty, working world; bad defs are
 * refused with the field named. */
static void empty_and_emptying_scenes(void)
{
	sph_setup s = default_setup();
	eddy_world_def d = eddy_default_world_def();
	eddy_world *w = eddy_create_world(&d, NULL, 0);
	eddy_sph_density_def de = eddy_default_sph_density_def();
	eddy_add_sph_density(w, &de);
	eddy_sph_pressure_def pr = eddy_default_sph_pressure_def();
	eddy_add_sph_pressure(w, &pr);
	CHECK(eddy_world_step_frame(w) == EDDY_OK);
	CHECK(eddy_world_particle_count(w) == 0);
	de.radius = 0;
	CHECK(!eddy_system_valid(w, eddy_add_sph_density(w, &de)));
	CHECK_HAS(eddy_world_error(w), "sph_density: 'radius' must be > 0");
	de = eddy_default_sph_density_def();
	de.radius = 10 * de.spacing;
	CHECK(!eddy_system_valid(w, eddy_add_sph_density(w, &de)));
	CHECK_HAS(eddy_world_error(w), "'radius' must be between 1 and 5 times 'spacing'");
	eddy_destroy_world(w);

	d.escape = EDDY_ESCAPE_REMOVE;
	d.bounds_max = (eddy_vec3){0.1f, 0.1f, 0.1f};
	w = eddy_create_world(&d, NULL, 0);
	eddy_emit_box_def b = eddy_default_emit_box_def();
	b.max = (eddy_vec3){0.1f, 0.05f, 0.1f};
	b.spacing = s.dx;
	eddy_add_emit_box(w, &b);
	de = eddy_default_sph_density_def();
	eddy_add_sph_density(w, &de);
	eddy_add_sph_pressure(w, &pr);
	eddy_gravity_def g = eddy_default_gravity_def();
	eddy_add_gravity(w, &g);
	eddy_integrate_def it = eddy_default_integrate_def();
	eddy_add_integrate(w, &it);
	CHECKF(eddy_world_advance(w, 0.5) == EDDY_OK, "%s", eddy_world_error(w));
	CHECK(eddy_world_particle_count(w) == 0);
	CHECK(eddy_world_step_frame(w) == EDDY_OK);
	eddy_destroy_world(w);
}

/* ---- the oscillating drop ------------------------------------------------ */

/* A drop of radius R in zero gravity, stretched along x by (1 + eps) at equal
 * volume, on the simple cubic lattice; surface tension pulls it back and it
 * rings in Rayleigh's l = 2 mode, omega^2 = 8 sigma / (rho R^3). The period
 * is read from the zero crossings of <x^2> - <y^2> about the centre of mass.
 * Returns the measured omega (NAN if fewer than 3 crossings). */
/* A drop of radius 1 cm, per_radius spacings, stretched along x by 1 + eps
 * (volume kept), in zero gravity, run for seconds (0: until eight zero crossings, at most 4.2 Rayleigh periods);
 * returns omega from the zero crossings of <x^2> - <y^2> (NAN with fewer
 * than three) and the closest pair seen, in spacings. */
static double drop_omega(int per_radius, double eps, double seconds, double *omega_theory, double *min_gap)
{
	const double R = 0.01, rho0 = 1000, sigma = 0.0728, dx = R / per_radius;
	eddy_world_def d = eddy_default_world_def();
	d.bounds_min = (eddy_vec3){-0.03f, -0.03f, -0.03f};
	d.bounds_max = (eddy_vec3){0.03f, 0.03f, 0.03f};
	d.gravity = (eddy_vec3){0, 0, 0};
	d.fps = 400;
	if (getenv("TG_DTMAX"))
		d.dt_max = atof(getenv("TG_DTMAX"));
	eddy_world *w = eddy_create_world(&d, NULL, 0);
	eddy_sph_density_def de = eddy_default_sph_density_def();
	de.spacing = (float)dx;
	de.radius = (float)(2 * dx);
	de.stiffness = 40; /* c = 6.3 m/s: the Laplace pressure 2 sigma / R compresses 0.04% */
	eddy_add_sph_density(w, &de);
	eddy_sph_pressure_def pr = eddy_default_sph_pressure_def();
	eddy_add_sph_pressure(w, &pr);
	eddy_sph_viscosity_def vi = eddy_default_sph_viscosity_def();
	/* Monaghan's alpha also keeps the surface layer's pairs (p clamped at 0,
	 * so nothing else pushes them apart) from closing in: the resting drop's
	 * closest pair was 0.46 spacings at alpha 0.05, 0.55 at 0.1 */
	vi.artificial = 0.1f;
	eddy_add_sph_viscosity(w, &vi);
	eddy_sph_surface_tension_def st = eddy_default_sph_surface_tension_def();
	st.tension = (float)sigma;
	eddy_add_sph_surface_tension(w, &st);
	eddy_integrate_def it = eddy_default_integrate_def();
	eddy_add_integrate(w, &it);
	const double ax = R * (1 + eps), ayz = R / sqrt(1 + eps);
	eddy_emit_box_def drop = eddy_default_emit_box_def();
	drop.min = (eddy_vec3){(float)-ax, (float)-ayz, (float)-ayz};
	drop.max = (eddy_vec3){(float)ax, (float)ayz, (float)ayz};
	drop.spacing = (float)dx;
	drop.shape = EDDY_EMIT_ELLIPSOID;
	CHECK(eddy_system_valid(w, eddy_add_emit_box(w, &drop)));
	*omega_theory = sqrt(8 * sigma / (rho0 * R * R * R));
	const double period = 2 * M_PI / *omega_theory;
	enum {
		CROSSINGS = 8
	}; /* three and a half periods: chaos in the particle motion moves
	    * single crossings by a few percent of a period */
	double prev = 0, crossings[CROSSINGS];
	int nc = 0;
	*min_gap = INFINITY;
	const int frames = (int)((seconds > 0 ? seconds : 4.2 * period) * d.fps);
	for (int f = 0; f < frames && (nc < CROSSINGS || seconds > 0); ++f) {
		if (eddy_world_step_frame(w) != EDDY_OK) {
			CHECKF(false, "%s", eddy_world_error(w));
			break;
		}
		size_t n;
		const float *x = eddy_world_channel(w, "x", &n), *y = eddy_world_channel(w, "y", NULL);
		double cx = 0, cy = 0, qx = 0, qy = 0;
		for (size_t i = 0; i < n; ++i) {
			cx += x[i];
			cy += y[i];
		}
		cx /= (double)n;
		cy /= (double)n;
		for (size_t i = 0; i < n; ++i) {
			qx += (x[i] - cx) * (x[i] - cx);
			qy += (y[i] - cy) * (y[i] - cy);
		}
		const double q = (qx - qy) / (double)n, t = eddy_world_time(w);
		if (f > 0 && (q > 0) != (prev > 0) && nc < CROSSINGS)
			crossings[nc++] = t - 1 / d.fps * q / (q - prev); /* linear interpolation */
		prev = q;
		if (f % 10 == 0)
			*min_gap = fmin(*min_gap, min_pair_distance(w) / dx);
	}
	eddy_destroy_world(w);
	if (nc < 3)
		return NAN;
	/* crossings are half a period apart */
	return M_PI * (nc - 1) / (crossings[nc - 1] - crossings[0]);
}

/* Rayleigh within (1 - 1.5 dx / R)^(-3/2) - 1 (27% at 8 spacings per
 * radius): omega^2 ~ sigma / R^3, and the colour field's force acts on the
 * particles from half a spacing to a spacing and a half inside the surface
 * (resting_drop_holds_laplace_pressure), so the drop rings as one up to
 * that much smaller would; measured +15.0%, at 12 spacings per radius +7.3%
 * (long_sph). Before the free-surface share (sph_surface_tension) -9.4%,
 * the force too weak by a third at every resolution. And (C.1) the drop
 * keeps its particles apart: with
 * negative pressure allowed, surface tension plus p < 0 pulls them into
 * clumps (and the paper's -lap c / |n| curvature squeezes the surface layer:
 * 0.07 spacings here). Measured: the closest pair dips to 0.51 spacings
 * while the drop rings at 20% strain (0.42-0.44 before the free-surface
 * share), so the bound here is 0.4; the drop at rest (the next test) is
 * held to docs/validation.md's 0.5. */
static void droplet_oscillates_at_rayleigh_frequency(void)
{
	double theory, gap;
	const double omega = drop_omega(8, 0.2, 0, &theory, &gap);
	printf("    drop R = 8 spacings: omega %.2f rad/s, Rayleigh %.2f rad/s, error %.1f%%, closest pair %.2f spacings\n",
	       omega, theory, 100 * (omega / theory - 1), gap);
	CHECK(isfinite(omega));
	CHECK(fabs(omega / theory - 1) <= pow(1 - 1.5 / 8, -1.5) - 1);
	CHECK(gap >= 0.4);
}

/* Laplace: a round drop at rest holds 2 sigma / R inside (tests the
 * colour field's free-surface share, sph_surface_tension's header). R from
 * the drop's volume, the particle count times a spacing cubed; the mean
 * pressure within R / 2 of the centre from 0.1 s to 0.3 s (the acoustic
 * ringing of the start averaged out). Held to 1.5 dx / R (18.75% at 8
 * spacings per radius), the diffuse interface's first-order error: the
 * force acts on the particles whose centres lie from half a spacing to a
 * spacing and a half inside the surface, where a sphere's curvature is that
 * much larger. Measured: WCSPH +15.0%, DFSPH +1.1% (at 12 spacings per
 * radius +7.9% and -2.0%); before the share, 0.62-0.68 of Laplace at 8 and
 * 16 spacings per radius alike (WCSPH 9.4-10.5 Pa, DFSPH 8.9-9.5, against
 * 14.5). */
static void resting_drop_holds_laplace_pressure(void)
{
	static const char *const methods[] = {"wcsph", "dfsph"};
	const double sigma = 0.0728, R = 0.01, dx = 0.00125;
	for (size_t m = 0; m < 2; ++m) {
		char cmd[512], *out = malloc(1 << 16);
		if (!out)
			return;
		snprintf(cmd, sizeof cmd,
		         "%s/eddy run scenes/droplet.lua --set method=%s --set stretch=0 --set render=false --duration 0.3 "
		         "--stats - --quiet --out %s/laplace 2>&1",
		         test_build_dir(), methods[m], test_out_dir());
		const int st = test_sh(cmd, out, 1 << 16);
		double sum = 0, n = NAN;
		int frames = 0;
		for (char *line = out; line && *line;) {
			char *next = strchr(line, '\n');
			if (next)
				*next++ = '\0';
			const double t = test_json_number(line, "time"), p = test_json_number(line, "p_inside");
			if (isfinite(t) && isfinite(p) && t > 0.1 - 1e-9) {
				sum += p;
				frames++;
				n = test_json_number(line, "particles");
			}
			line = next;
		}
		const double rv = cbrt(3 * n * dx * dx * dx / (4 * M_PI)), laplace = 2 * sigma / rv, p = sum / frames;
		printf("    %s drop at rest, R = 8 spacings: pressure inside %.2f Pa, Laplace 2 sigma / R %.2f Pa (%+.1f%%)\n",
		       methods[m], p, laplace, 100 * (p / laplace - 1));
		if (st != 0)
			printf("    exit %d: %.300s\n", st, out);
		CHECK(st == 0 && frames > 10);
		CHECKF(fabs(p / laplace - 1) <= 1.5 * dx / R, "%s: %.2f Pa inside against Laplace's %.2f", methods[m], p,
		       laplace);
		free(out);
	}
}

/* A threshold above the outermost layer's |n| h (1.06 at h = 2 spacings)
 * leaves a flat surface no particle with a normal, and the force's share
 * of the jump 0: the first step stops naming the field, not a division by
 * zero's infinite force. */
static void surface_tension_threshold_past_the_surface_is_an_error(void)
{
	const double dx = 0.00125;
	eddy_world_def d = eddy_default_world_def();
	d.gravity = (eddy_vec3){0, 0, 0};
	d.bounds_min = (eddy_vec3){0, 0, 0};
	d.bounds_max = (eddy_vec3){0.02f, 0.02f, 0.02f};
	eddy_world *w = eddy_create_world(&d, NULL, 0);
	eddy_sph_density_def de = eddy_default_sph_density_def();
	de.spacing = (float)dx;
	de.radius = (float)(2 * dx);
	eddy_add_sph_density(w, &de);
	eddy_sph_pressure_def pr = eddy_default_sph_pressure_def();
	eddy_add_sph_pressure(w, &pr);
	eddy_sph_surface_tension_def st = eddy_default_sph_surface_tension_def();
	st.threshold = 1.2f;
	CHECK(eddy_system_valid(w, eddy_add_sph_surface_tension(w, &st)));
	eddy_integrate_def it = eddy_default_integrate_def();
	eddy_add_integrate(w, &it);
	eddy_emit_box_def drop = eddy_default_emit_box_def();
	drop.min = (eddy_vec3){0.005f, 0.005f, 0.005f};
	drop.max = (eddy_vec3){0.015f, 0.015f, 0.015f};
	drop.spacing = (float)dx;
	CHECK(eddy_system_valid(w, eddy_add_emit_box(w, &drop)));
	CHECK(eddy_world_step(w) != EDDY_OK);
	const char *msg = eddy_world_error(w);
	printf("    %s\n", msg);
	CHECK(strstr(msg, "sph_surface_tension") && strstr(msg, "'threshold' 1.2"));
	eddy_destroy_world(w);
}

/* C.1 as docs/validation.md states it: a round drop at rest (surface tension on,
 * negative pressure clamped) keeps every pair at least half a spacing apart. */
static void resting_drop_keeps_pairs_apart(void)
{
	double theory, gap;
	drop_omega(8, 0, 0.25, &theory, &gap);
	printf("    resting drop R = 8 spacings: closest pair %.2f spacings over 0.25 s\n", gap);
	CHECK(gap >= 0.5);
}

/* ---- the dam break against Martin & Moyce (1952) -------------------------- */

typedef struct curve {
	double T[256], Z[256];
	int n;
} curve;

/* Rows "T,Z" of a Martin & Moyce CSV (comments and the header skipped). */
static bool read_reference(const char *path, curve *c)
{
	FILE *f = fopen(path, "r");
	c->n = 0;
	if (!f)
		return false;
	char line[256];
	while (fgets(line, sizeof line, f) && c->n < 256) {
		double t, z;
		if (line[0] != '#' && sscanf(line, "%lf,%lf", &t, &z) == 2) {
			c->T[c->n] = t;
			c->Z[c->n] = z;
			c->n++;
		}
	}
	fclose(f);
	return c->n > 1;
}

static double curve_at(const curve *c, double T)
{
	for (int i = 1; i < c->n; ++i)
		if (T >= c->T[i - 1] && T <= c->T[i])
			return c->Z[i - 1] + (c->Z[i] - c->Z[i - 1]) * (T - c->T[i - 1]) / (c->T[i] - c->T[i - 1]);
	return NAN;
}

/* Runs a scene with the eddy command; each stats line gives (T, Z)-like
 * pairs of the two named fields. Returns the number of lines. */
static int run_scene(const char *scene, const char *sets, const char *kx, const char *ky, curve *out, char *last,
                     size_t last_size)
{
	char cmd[1024];
	snprintf(cmd, sizeof cmd, "%s/eddy run %s %s --stats - --quiet --out %s/run 2>&1", test_build_dir(), scene, sets,
	         test_out_dir());
	FILE *p = popen(cmd, "r");
	out->n = 0;
	if (!p)
		return 0;
	static char line[16384];
	int lines = 0;
	while (fgets(line, sizeof line, p)) {
		lines++;
		if (last)
			snprintf(last, last_size, "%s", line);
		if (out->n < 256 && kx) {
			out->T[out->n] = test_json_number(line, kx);
			out->Z[out->n] = test_json_number(line, ky);
			out->n++;
		}
	}
	int st = pclose(p);
	CHECKF(st == 0, "%s exited with %d: %s", cmd, st, last ? last : "");
	return lines;
}

/* The shipped droplet scene rings with DFSPH as with WCSPH. DFSPH's
 * Monaghan term is alpha c h with its fixed c = 20 m/s: at the WCSPH
 * setting's alpha 0.1 (c = 6.3 m/s there) the drop crept back to round
 * without a single zero crossing in 1.1 s; the scene now gives DFSPH its own
 * 0.01. Held, as the WCSPH drop above, to Rayleigh's omega within (1 -
 * 1.5 dx / R)^(-3/2) - 1 over up to eight crossings, at least six of them
 * (measured: 8, +10.2%; WCSPH's scene 8, +19.7%, printed; before the
 * colour field's free-surface share -9.3% and -14.1%). */
static void droplet_scene_rings_with_dfsph(void)
{
	const double theory = sqrt(8 * 0.0728 / (1000 * 1e-6)); /* R = 1 cm */
	static const char *const methods[] = {"dfsph", "wcsph"};
	for (size_t m = 0; m < 2; ++m) {
		char sets[128];
		snprintf(sets, sizeof sets, "--set method=%s --set render=false --duration 1.1", methods[m]);
		curve c;
		run_scene("scenes/droplet.lua", sets, "time", "q", &c, NULL, 0);
		double cross[8];
		int nc = 0;
		for (int k = 1; k < c.n && nc < 8; ++k)
			if ((c.Z[k] > 0) != (c.Z[k - 1] > 0))
				cross[nc++] = c.T[k - 1] + (c.T[k] - c.T[k - 1]) * c.Z[k - 1] / (c.Z[k - 1] - c.Z[k]);
		const double omega = nc >= 3 ? M_PI * (nc - 1) / (cross[nc - 1] - cross[0]) : NAN;
		printf("    %s: %d zero crossings in 1.1 s, omega %.2f rad/s against Rayleigh's %.2f (%+.1f%%)\n", methods[m], nc,
		       omega, theory, 100 * (omega / theory - 1));
		if (m == 0) {
			CHECKF(nc >= 6, "dfsph: the drop crossed round %d times in 1.1 s: it does not ring", nc);
			CHECKF(fabs(omega / theory - 1) <= pow(1 - 1.5 / 8, -1.5) - 1, "dfsph: omega %.2f against Rayleigh's %.2f",
			       omega, theory);
		}
	}
}

/* |Z_sim - Z_exp| / Z_exp <= 10% for T in [1, 3] against both data sets,
 * after the best time shift of at most 0.2 (docs/validation.md A: the gate
 * opened in finite time, so the experiment starts late). a/12 resolution. */
static void dam_break_matches_martin_moyce(void)
{
	curve ref[2], sim;
	CHECK(read_reference("data/martin_moyce_1952_a2.25in.csv", &ref[0]));
	CHECK(read_reference("data/martin_moyce_1952_a1.125in.csv", &ref[1]));
	char last[16384] = "";
	run_scene("scenes/dam_break.lua", "--set spacing=0.008333 --set fps=100", "T", "Z", &sim, last, sizeof last);
	CHECK(sim.n > 20);
	if (sim.n <= 20 || ref[0].n < 2 || ref[1].n < 2)
		return;
	double best = INFINITY, best_shift = 0, noshift = 0;
	for (int k = -20; k <= 20; ++k) {
		const double shift = 0.01 * k;
		double worst = 0;
		for (int r = 0; r < 2; ++r)
			for (double T = 1.0; T <= 3.0 + 1e-9; T += 0.05) {
				const double ze = curve_at(&ref[r], T), zs = curve_at(&sim, T - shift);
				if (isfinite(ze) && isfinite(zs))
					worst = fmax(worst, fabs(zs - ze) / ze);
			}
		if (k == 0)
			noshift = worst;
		if (worst < best) {
			best = worst;
			best_shift = shift;
		}
	}
	printf("    dam break a/12: worst |Z_sim - Z_exp| / Z_exp over T in [1, 3] = %.3f after a shift of %.2f in T "
	       "(%.3f unshifted); Z_sim(1, 2, 3) = %.3f %.3f %.3f\n",
	       best, best_shift, noshift, curve_at(&sim, 1.0), curve_at(&sim, 2.0), curve_at(&sim, 3.0));
	CHECK(best <= 0.10);
	CHECK(test_json_number(last, "leaked") == 0 && test_json_number(last, "nonfinite") == 0);
}

/* scenes/dam_break.lua at column base a (spacing a/20, frames at T steps
 * of 1/sqrt(...) so every a has its frames at the same T): Z, T and the
 * mean compression per frame; false if it did not run. */
typedef struct scaled_dam {
	double T[64], Z[64], compression[64];
	int n;
	char last[16384];
} scaled_dam;

static bool run_scaled_dam(double a, const char *extra, scaled_dam *d)
{
	char cmd[1024];
	snprintf(cmd, sizeof cmd,
	         "%s/eddy run scenes/dam_break.lua --set a=%.17g --set spacing=%.17g --set fps=%.17g --set render=false "
	         "%s --stats - --quiet --out %s/scaled_dam 2>&1",
	         test_build_dir(), a, a / 20, 100 / sqrt(a / 0.1), extra, test_out_dir());
	FILE *p = popen(cmd, "r");
	d->n = 0;
	if (!p)
		return false;
	static char line[16384];
	while (fgets(line, sizeof line, p)) {
		snprintf(d->last, sizeof d->last, "%s", line);
		if (d->n < 64) {
			d->T[d->n] = test_json_number(line, "T");
			d->Z[d->n] = test_json_number(line, "Z");
			d->compression[d->n] = test_json_number(line, "density_compression_avg");
			d->n++;
		}
	}
	const int st = pclose(p);
	CHECKF(st == 0, "%s exited with %d: %s", cmd, st, d->last);
	return st == 0;
}

/* One step beyond the a = 0.1 m dam break: the same scene at a = 5 m and
 * at 1 cm, as a user scales it. Under Froude scaling (lengths x L, times
 * and speeds x sqrt(L)) Z(T) is the same at every a when the speed of
 * sound grows as sqrt(a) too, as the scene's unset stiffness does (c = 10 x
 * the column's fall speed). Water's viscosity breaks the similarity only
 * weakly (Re = sqrt(2 g a) a / nu is 4,400 at 1 cm).
 * - Z over the surge (T >= 1) within 2% of the 0.1 m column's at both,
 *   five times the gaps measured (0.4%).
 * - 5 m: the mean compression under 1% (Mach 0.1 compresses by about
 *   M^2 = 1%; measured 0.3%). With c fixed at 20 m/s the 5 m column ran at
 *   Mach 0.8: 11% compression, its front 2.8% behind; run so (stiffness
 *   400), sph_pressure raises a run-time warning once the mean passes 3%,
 *   and the three scales at the chosen c raise none.
 * - 1 cm (0.5 mm spacing) runs: the walls' pressure sums are of order h^6
 *   and their inverse overflowed a float, stopping the run with an
 *   infinite density within 0.3 ms; and its column has all 20 x 40 x 4
 *   particles (the float box read 39.99999725 spacings tall and lost a
 *   layer, 3% off Z). */
static void dam_break_is_the_same_at_every_scale(void)
{
	static scaled_dam base, big, small, soft;
	const bool ran = run_scaled_dam(0.1, "", &base) && run_scaled_dam(5, "", &big) &&
	                 run_scaled_dam(0.01, "", &small) && run_scaled_dam(5, "--set stiffness=400", &soft);
	CHECK(ran && base.n > 20 && big.n == base.n && small.n == base.n);
	if (!ran || base.n <= 20 || big.n != base.n || small.n != base.n)
		return;
	double worst[2] = {0, 0}, squeeze = 0;
	for (int i = 0; i < base.n; ++i) {
		const scaled_dam *d[2] = {&big, &small};
		for (int k = 0; k < 2; ++k) {
			const double e = fabs(d[k]->Z[i] - base.Z[i]) / base.Z[i];
			if (base.T[i] >= 1) /* the surge, as Martin & Moyce's data: before it the front is the column's foot */
				worst[k] = e <= worst[k] ? worst[k] : e; /* NaN too */
			CHECK(fabs(d[k]->T[i] - base.T[i]) < 1e-3);
		}
		squeeze = big.compression[i] <= squeeze ? squeeze : big.compression[i];
	}
	printf("    dam break (a/20, WCSPH) against a = 0.1 m: a = 5 m worst |dZ| / Z %.4f, mean compression up to %.4f; "
	       "a = 1 cm worst |dZ| / Z %.4f; Z at the end %.3f, %.3f, %.3f\n",
	       worst[0], squeeze, worst[1], big.Z[big.n - 1], base.Z[base.n - 1], small.Z[small.n - 1]);
	CHECK(worst[0] <= 0.02);
	CHECK(squeeze <= 0.01);
	CHECK(worst[1] <= 0.02);
	const scaled_dam *all[3] = {&base, &big, &small};
	for (int k = 0; k < 3; ++k) {
		CHECK(test_json_number(all[k]->last, "leaked") == 0 && test_json_number(all[k]->last, "nonfinite") == 0);
		CHECK(test_json_number(all[k]->last, "particles") == 3200);
		CHECK(test_json_number(all[k]->last, "warnings") == 0); /* nothing to say at the chosen c */
	}
	/* the 5 m column at the old fixed c = 20 m/s compresses 4.7% on average
	 * by its third frame: sph_pressure says so at run time */
	double soft_squeeze = 0;
	for (int i = 0; i < soft.n; ++i)
		soft_squeeze = soft.compression[i] <= soft_squeeze ? soft_squeeze : soft.compression[i];
	printf("    a = 5 m at stiffness 400 (c = 20 m/s): mean compression up to %.4f, %g run-time warnings\n",
	       soft_squeeze, test_json_number(soft.last, "warnings"));
	CHECK(soft_squeeze > 0.03 && test_json_number(soft.last, "warnings") == 1);
}

/* The speed of sound sph_density chooses when stiffness is unset: beside
 * sph_pressure 10 x sqrt(v0^2 + 2 |g| H) over the emitters (H from the
 * highest point each emits to the world's lowest corner along gravity), in
 * whatever order the systems are added, fixed once the world steps; 20 m/s
 * without sph_pressure or without any such speed; an explicit stiffness is
 * kept and, when too soft for WCSPH, warned about. */
static void collect_text(eddy_check_level level, const char *message, void *user)
{
	(void)level;
	char *t = user;
	const size_t n = strlen(t);
	snprintf(t + n, 4096 - n, "%s\n", message);
}

static void sound_speed_follows_the_scene(void)
{
	const double g = 9.81;
	for (int order = 0; order < 2; ++order) {
		eddy_world_def d = eddy_default_world_def();
		d.bounds_min = (eddy_vec3){0, -1, 0};
		d.bounds_max = (eddy_vec3){1, 9, 1};
		d.gravity = (eddy_vec3){0, (float)-g, 0};
		eddy_world *w = eddy_create_world(&d, NULL, 0);
		eddy_sph_density_def sd = eddy_default_sph_density_def();
		sd.spacing = 0.05f, sd.radius = 0.1f;
		eddy_emit_box_def b = eddy_default_emit_box_def();
		b.spacing = 0.05f;
		b.min = (eddy_vec3){0.1f, 7, 0.1f};
		b.max = (eddy_vec3){0.3f, 8, 0.3f};
		b.velocity = (eddy_vec3){3, 0, 4};
		eddy_system_id dens = EDDY_NULL_SYSTEM;
		const eddy_sph_pressure_def sp = eddy_default_sph_pressure_def();
		double no_eos = 0;
		if (order == 0) {
			dens = eddy_add_sph_density(w, &sd);
			eddy_add_emit_box(w, &b);
			no_eos = eddy_sph_sound_speed(w, dens); /* a pressure solve's c: the fixed 20 m/s */
			CHECK(eddy_world_remove_system(w, eddy_world_system_at(w, 1)) == EDDY_OK);
			eddy_add_sph_pressure(w, &sp);
		}
		eddy_system_id box = eddy_add_emit_box(w, &b);
		const double before_gravity = eddy_sph_sound_speed(w, dens);
		eddy_add_gravity(w, &(eddy_gravity_def){.scale = 1});
		if (order == 1) {
			dens = eddy_add_sph_density(w, &sd);
			eddy_add_sph_pressure(w, &sp);
		}
		const double want = 10 * sqrt(25 + 2 * g * 9);
		const double c = eddy_sph_sound_speed(w, dens);
		printf("    order %d: c %.4f m/s, want %.4f (before gravity %.4f)\n", order, c, want, before_gravity);
		CHECK(fabs(c - want) <= 1e-4 * want);
		if (order == 0) {
			CHECK(fabs(before_gravity - 50) <= 1e-4); /* 10 x the start speed alone */
			CHECK(fabs(no_eos - 20) <= 1e-5);
		}
		/* a nozzle jetting faster from higher up takes over */
		eddy_emit_nozzle_def nz = eddy_default_emit_nozzle_def();
		nz.center = (eddy_vec3){0.5f, 8.5f, 0.5f};
		nz.radius = 0.05f;
		nz.speed = 20;
		nz.spacing = 0.05f;
		nz.duration = 0.1;
		eddy_system_id noz = eddy_add_emit_nozzle(w, &nz);
		const double want2 = 10 * sqrt(400 + 2 * g * 9.55);
		CHECK(fabs(eddy_sph_sound_speed(w, dens) - want2) <= 1e-4 * want2);
		/* removing both emitters leaves the floor */
		CHECK(eddy_world_remove_system(w, noz) == EDDY_OK && eddy_world_remove_system(w, box) == EDDY_OK);
		CHECK(fabs(eddy_sph_sound_speed(w, dens) - 20) <= 1e-5);
		eddy_add_emit_box(w, &b);
		CHECK(fabs(eddy_sph_sound_speed(w, dens) - want) <= 1e-4 * want);
		/* fixed once the world steps: a later emitter changes nothing */
		const eddy_integrate_def id = eddy_default_integrate_def();
		eddy_add_integrate(w, &id);
		CHECK(eddy_world_step(w) == EDDY_OK);
		eddy_add_emit_nozzle(w, &nz);
		CHECK(fabs(eddy_sph_sound_speed(w, dens) - want) <= 1e-4 * want);
		/* an sph_density added now takes its c from the pipeline it joins */
		if (order == 0) {
			const eddy_system_id late = eddy_add_sph_density(w, &sd);
			CHECK(fabs(eddy_sph_sound_speed(w, late) - want2) <= 1e-4 * want2);
		}
		eddy_destroy_world(w);
	}
	/* water in a closed tank falls to the tank's floor, not the world's:
	 * a tank [0, 1]^3 in a world from -5 m, water up to 0.5 m in it, c from
	 * a 0.5 m fall; a block above the tank, outside it, from the world's */
	for (int above = 0; above < 2; ++above) {
		eddy_world_def d = eddy_default_world_def();
		d.bounds_min = (eddy_vec3){-1, -5, -1};
		d.bounds_max = (eddy_vec3){2, 5, 2};
		eddy_world *w = eddy_create_world(&d, NULL, 0);
		eddy_sph_density_def sd = eddy_default_sph_density_def();
		sd.spacing = 0.05f, sd.radius = 0.1f;
		const eddy_system_id dens = eddy_add_sph_density(w, &sd);
		eddy_add_sph_pressure(w, &(eddy_sph_pressure_def){.scale = 1});
		eddy_add_gravity(w, &(eddy_gravity_def){.scale = 1});
		eddy_sph_boundary_box_def bb = eddy_default_sph_boundary_box_def();
		bb.spacing = 0.05f; /* [0, 1]^3 */
		eddy_add_sph_boundary_box(w, &bb);
		eddy_emit_box_def b = eddy_default_emit_box_def();
		b.spacing = 0.05f;
		b.min = (eddy_vec3){0, above ? 2.0f : 0.0f, 0};
		b.max = (eddy_vec3){1, above ? 2.5f : 0.5f, 1};
		eddy_add_emit_box(w, &b);
		const double want = above ? 10 * sqrt(2 * g * 7.5) : 10 * sqrt(2 * g * 0.5);
		CHECKF(fabs(eddy_sph_sound_speed(w, dens) - want) <= 1e-4 * want, "above %d: c %g, want %g", above,
		       (double)eddy_sph_sound_speed(w, dens), want);
		eddy_destroy_world(w);
	}
	/* a resumed run of a scene whose c came from it (the splash: a 8 cm
	 * fall, c = 12.5 m/s) continues bit-identically: the scene is built
	 * before the state is loaded, so c is chosen the same way */
	{
		sph_setup st = splash_setup();
		st.k = 0;
		check_resume_bit_identical(sph_world(&st, NULL), sph_world(&st, NULL), sph_world(&st, NULL), "auto_sound.eddy");
	}
	/* a kernel too small for single precision is refused at add, naming
	 * the smallest radius (poly6's gradient overflows near 67 um; a 40 um
	 * kernel stopped with an infinite density at step 0); 0.1 mm runs (the
	 * dam break at a = 1 mm) */
	{
		eddy_world_def d = eddy_default_world_def();
		eddy_world *w = eddy_create_world(&d, NULL, 0);
		eddy_sph_density_def sd = eddy_default_sph_density_def();
		sd.spacing = 2e-5f, sd.radius = 4e-5f;
		CHECK(!eddy_system_valid(w, eddy_add_sph_density(w, &sd)));
		CHECK_HAS(eddy_world_error(w), "sph_density: 'radius' 4e-05 m is below 6.7e-05 m");
		sd.spacing = 5e-5f, sd.radius = 1e-4f;
		CHECK(eddy_system_valid(w, eddy_add_sph_density(w, &sd)));
		eddy_destroy_world(w);
	}
	/* an explicit stiffness stays, and too soft for a weakly compressible
	 * run the preflight says so, with the stiffness that would do */
	for (int soft = 0; soft < 2; ++soft) {
		eddy_world_def d = eddy_default_world_def();
		d.bounds_min = (eddy_vec3){0, 0, 0};
		d.bounds_max = (eddy_vec3){1, 2, 1};
		d.gravity = (eddy_vec3){0, (float)-g, 0};
		eddy_world *w = eddy_create_world(&d, NULL, 0);
		eddy_emit_box_def b = eddy_default_emit_box_def();
		b.spacing = 0.05f;
		b.min = (eddy_vec3){0, 0, 0};
		b.max = (eddy_vec3){0.2f, 1.8f, 0.2f};
		eddy_add_emit_box(w, &b);
		eddy_sph_density_def sd = eddy_default_sph_density_def();
		sd.spacing = 0.05f, sd.radius = 0.1f;
		sd.stiffness = soft ? 400 : 1e4f;
		eddy_system_id dens = eddy_add_sph_density(w, &sd);
		eddy_add_sph_pressure(w, &(eddy_sph_pressure_def){.scale = 1});
		eddy_add_gravity(w, &(eddy_gravity_def){.scale = 1});
		CHECK(fabs(eddy_sph_sound_speed(w, dens) - sqrt(sd.stiffness)) <= 1e-3);
		char text[4096] = "";
		eddy_world_check(w, collect_text, text);
		const bool warned = strstr(text, "makes the speed of sound 20 m/s") != NULL;
		printf("    stiffness %g over a 1.8 m fall: %s\n", (double)sd.stiffness, warned ? "warned" : "no warning");
		CHECK(warned == (soft == 1));
		CHECK(!soft || strstr(text, "stiffness >= 3532") != NULL); /* 100 x 2 g 1.8 */
		eddy_destroy_world(w);
	}
}

/* The SPH scenes run through the eddy command and report their fields. */
static void scenes_run_and_report(void)
{
	curve c;
	char last[16384] = "";
	run_scene("scenes/hydrostatic.lua", "--frames 2", NULL, NULL, &c, last, sizeof last);
	CHECK_HAS(last, "\"pressure_err\":");
	CHECK(test_json_number(last, "bottom_density_expected") > 1.0);
	run_scene("scenes/pour.lua", "--frames 3", NULL, NULL, &c, last, sizeof last);
	CHECK(test_json_number(last, "particles") > 0 && test_json_number(last, "leaked") == 0);
	run_scene("scenes/droplet.lua", "--frames 1 --set spacing=0.0025", NULL, NULL, &c, last, sizeof last);
	CHECK_HAS(last, "\"q\":");
	CHECK_HAS(last, "sph_surface_tension");
}

static void sph_dfsph_suite(void); /* dfsph helper */
static void verlet_lists_match_brute_force(void);
static void neighbour_lists_grow_past_their_first_size(void);
static void neighbour_lists_span_many_rows(void);
static void neighbour_cells_hold_many_rows(void);
static void neighbour_cells_skip_empty_stretches(void);

/* ---- the continuity density (sph_density's density = continuity) ---- */

/* The rate's velocity term: a block in free space (no gravity, no walls)
 * given the velocity v = -a (x - c) after its first step compresses at
 * d rho / dt = 3 a rho; one step later the particles more than h inside the
 * block's faces read rho0 (1 + 3 a dt) to 1% of the change (the sum is
 * calibrated by the spiky gradient's lattice moment, as the pressure force:
 * uncalibrated it falls 5.3% short). The block's surface layers read less
 * (their sums are truncated), which is what the diffusion spreads. */
static void continuity_rate_of_uniform_compression(void)
{
	sph_setup s = default_setup();
	s.gravity = 0;
	s.walls = false;
	s.density = EDDY_SPH_DENSITY_CONTINUITY;
	s.hi = (eddy_vec3){0.2f, 0.2f, 0.2f};
	s.fmin = (eddy_vec3){0.05f, 0.05f, 0.05f};
	s.fmax = (eddy_vec3){0.15f, 0.15f, 0.15f};
	eddy_world *w = sph_world(&s, NULL);
	CHECK(eddy_world_step(w) == EDDY_OK);
	size_t n;
	const float *x = eddy_world_channel(w, "x", &n), *y = eddy_world_channel(w, "y", NULL),
				*z = eddy_world_channel(w, "z", NULL);
	float *vx = eddy_world_channel_mut(w, "vx", NULL), *vy = eddy_world_channel_mut(w, "vy", NULL),
		  *vz = eddy_world_channel_mut(w, "vz", NULL);
	const double a = 0.5, c = 0.1; /* 1/s, m */
	for (size_t i = 0; i < n; ++i) {
		vx[i] = (float)(-a * (x[i] - c));
		vy[i] = (float)(-a * (y[i] - c));
		vz[i] = (float)(-a * (z[i] - c));
	}
	const double dt = eddy_world_last_dt(w);
	CHECK(eddy_world_step(w) == EDDY_OK);
	x = eddy_world_channel(w, "x", &n);
	y = eddy_world_channel(w, "y", NULL);
	z = eddy_world_channel(w, "z", NULL);
	const float *rho = eddy_world_channel(w, "density", NULL);
	const double want = 3 * a * dt * 1000, h = 2 * s.dx;
	double worst = 0;
	int inside = 0;
	for (size_t i = 0; i < n; ++i)
		if (fabs(x[i] - c) < 0.05 - h && fabs(y[i] - c) < 0.05 - h && fabs(z[i] - c) < 0.05 - h) {
			worst = fmax(worst, fabs((rho[i] - 1000) / want - 1));
			inside++;
		}
	printf("    continuity: uniform compression 3a = %.1f 1/s over dt %.3g s: interior (%d particles) d rho within "
	       "%.2f%% of 3 a rho0 dt = %.4f kg/m^3\n",
	       3 * a, dt, inside, 100 * worst, want);
	CHECK(inside >= 100);
	CHECK(worst < 0.01);
	eddy_destroy_world(w);
}

/* The diffusion's hydrostatic part (Fourtakas et al. 2019): a column at
 * rest carrying the hydrostatic densities rho0 (1 + g d / c^2), d the
 * depth below its top layer, keeps them through a step: every particle's
 * density, the surface's and the floor's (where the kernel is truncated)
 * included, changes by less than 1e-3 of rho0 g H / c^2. Without the
 * hydrostatic part the diffusion would move the truncated rows towards
 * their neighbours' mean (a rate of order delta h c rho0 g / c^2 / h). The
 * step that carries them is one with the velocities zeroed; the densities
 * set before it ride along in a custom column through the table's reorder. */
static void continuity_keeps_hydrostatic_densities(void)
{
	sph_setup s = default_setup();
	s.density = EDDY_SPH_DENSITY_CONTINUITY;
	eddy_world *w = sph_world(&s, NULL);
	const eddy_column_id tag = eddy_world_declare_column(w, "tag", EDDY_DOMAIN_PARTICLE, EDDY_F32, EDDY_STATE, "");
	CHECK(tag >= 0);
	/* a custom column is allocated only for a system that uses it */
	const char *const reads[] = {"tag"};
	eddy_custom_system_def cs = eddy_default_custom_system_def();
	cs.name = "tag_keeper";
	cs.reads = reads;
	cs.read_count = 1;
	cs.step = no_step;
	CHECKF(eddy_system_valid(w, eddy_add_custom_system(w, &cs)), "%s", eddy_world_error(w));
	for (int k = 0; k < 3; ++k)
		CHECK(eddy_world_step(w) == EDDY_OK);
	size_t n;
	const float *y = eddy_world_channel(w, "y", &n);
	float *carried = eddy_world_channel_mut(w, "sph_rho", NULL), *t = eddy_world_channel_mut(w, "tag", NULL);
	float *vx = eddy_world_channel_mut(w, "vx", NULL), *vy = eddy_world_channel_mut(w, "vy", NULL),
		  *vz = eddy_world_channel_mut(w, "vz", NULL);
	CHECK(carried && t);
	if (!carried || !t) {
		eddy_destroy_world(w);
		return;
	}
	double top = 0;
	for (size_t i = 0; i < n; ++i)
		top = fmax(top, y[i]);
	const double g = 9.81, c2 = s.k, scale = 1000 * g * top / c2;
	for (size_t i = 0; i < n; ++i) {
		carried[i] = t[i] = (float)(1000 * (1 + g * (top - y[i]) / c2));
		vx[i] = vy[i] = vz[i] = 0;
	}
	CHECK(eddy_world_step(w) == EDDY_OK);
	const float *rho = eddy_world_channel(w, "density", &n);
	t = eddy_world_channel_mut(w, "tag", NULL);
	double worst = 0;
	for (size_t i = 0; i < n; ++i)
		worst = fmax(worst, fabs(rho[i] - t[i]) / scale);
	printf(
		"    continuity: hydrostatic densities (rho0 g H / c^2 = %.2f kg/m^3) kept through a step at rest to %.2e of "
		"that\n",
		scale, worst);
	CHECK(worst < 1e-3);
	eddy_destroy_world(w);
}

/* The new fields' bad values are one-line errors naming them, from C and
 * from a scene; continuity without sph_pressure (beside sph_dfsph) is a
 * preflight error. */
static void continuity_rejects_bad_input(void)
{
	eddy_world_def d = eddy_default_world_def();
	eddy_world *w = eddy_create_world(&d, NULL, 0);
	eddy_sph_density_def de = eddy_default_sph_density_def();
	de.diffusion = 1.5f;
	CHECK(!eddy_system_valid(w, eddy_add_sph_density(w, &de)));
	CHECK_HAS(eddy_world_error(w), "sph_density: 'diffusion'");
	de = eddy_default_sph_density_def();
	de.density = (eddy_sph_density_mode)7;
	CHECK(!eddy_system_valid(w, eddy_add_sph_density(w, &de)));
	CHECK_HAS(eddy_world_error(w), "sph_density: 'density' must be summation or continuity");
	/* the carried density's column taken by the host for something else */
	CHECK(eddy_world_declare_column(w, "sph_rho", EDDY_DOMAIN_PARTICLE, EDDY_U8, EDDY_STATE, "") >= 0);
	de = eddy_default_sph_density_def();
	de.density = EDDY_SPH_DENSITY_CONTINUITY;
	CHECK(!eddy_system_valid(w, eddy_add_sph_density(w, &de)));
	CHECK_HAS(eddy_world_error(w), "keeps the density in the column 'sph_rho'");
	eddy_destroy_world(w);

	char out[4096];
	CHECK(check_scene("continuity_bad.lua",
	                  "local eddy = require 'eddy'\nlocal world = eddy.world{}\n"
	                  "world:add(eddy.sph_density{ density = 'continuity', diffusion = -0.1 })\nreturn world\n",
	                  out, sizeof out) != 0);
	CHECK_HAS(out, "continuity_bad.lua:3: sph_density: 'diffusion'");
	CHECK(check_scene("continuity_bad.lua",
	                  "local eddy = require 'eddy'\nlocal world = eddy.world{}\n"
	                  "world:add(eddy.emit_box{ min = {0, 0, 0}, max = {0.1, 0.1, 0.1}, spacing = 0.01 })\n"
	                  "world:add(eddy.sph_density{ density = 'continuity' })\nworld:add(eddy.gravity{})\n"
	                  "world:add(eddy.sph_dfsph{})\nworld:add(eddy.integrate{})\nreturn world\n",
	                  out, sizeof out) != 0);
	CHECK_HAS(out, "'density' = continuity needs sph_pressure");
	/* the explicit diffusion's stability: cfl x diffusion x 22.8 <= 2 at
	 * h = 2 spacings (sph_density's diffusion_eigenvalue), so at cfl 1
	 * delta 0.1 is refused and 0.08 runs */
	for (int k = 0; k < 2; ++k) {
		char text[512];
		snprintf(text, sizeof text,
		         "local eddy = require 'eddy'\nlocal world = eddy.world{ cfl = 1 }\n"
		         "world:add(eddy.emit_box{ min = {0, 0, 0}, max = {0.1, 0.1, 0.1}, spacing = 0.01 })\n"
		         "world:add(eddy.sph_density{ density = 'continuity', diffusion = %s })\n"
		         "world:add(eddy.sph_pressure{})\nworld:add(eddy.integrate{})\nreturn world\n",
		         k == 0 ? "0.1" : "0.08");
		const int code = check_scene("continuity_bad.lua", text, out, sizeof out);
		if (k == 0) {
			CHECK(code != 0);
			CHECK_HAS(out, "'diffusion' 0.1 at the world's cfl 1 makes the explicit density diffusion unstable");
			CHECK_HAS(out, "use diffusion <= 0.0876 or cfl <= 0.876");
		} else
			CHECKF(code == 0, "%s", out);
	}
}

/* With the continuity density: the same state on 1 and 2 threads (the
 * splash), and a run resumed from a checkpoint (which carries the density
 * column sph_rho) bit-identical to the straight one. */
static void continuity_deterministic_and_resumable(void)
{
	uint64_t hash[2];
	sph_setup s = splash_setup();
	s.density = EDDY_SPH_DENSITY_CONTINUITY;
	hashes_on_one_and_two_threads(s, 10, hash);
	printf("    continuity state hash 1 thread %016llx, 2 threads %016llx\n", (unsigned long long)hash[0],
	       (unsigned long long)hash[1]);
	CHECK(hash[0] == hash[1]);

	s.fps = 50;
	check_resume_bit_identical(sph_world(&s, NULL), sph_world(&s, NULL), sph_world(&s, NULL), "continuity_ckpt.eddy");
}

/* ---- settling (world.c, settle) ------------------------------------------ */

/* A free 6 x 6 x 6 block moving at 0.3 m/s with no gravity, WCSPH, one
 * particle pushed half a spacing toward its neighbour (the squeeze an
 * off-lattice solid leaves beside its boundary particles). With
 * settle_steps the start is relaxed before the first step: the block
 * leaves with the velocity it was given (momentum kept: the settling
 * moves positions only) and without the equation of state's kick; a plain
 * lattice takes no settling step. Returns the largest speed relative to
 * the block after one frame, or NAN. */
static double settle_block(int settle_steps, bool squeeze, double *mean_vx, double *steps)
{
	eddy_world_def d = eddy_default_world_def();
	d.gravity = (eddy_vec3){0, 0, 0};
	d.settle_steps = settle_steps;
	char err[256];
	eddy_world *w = eddy_create_world(&d, err, sizeof err);
	CHECKF(w != NULL, "create_world: %s", err);
	if (!w)
		return NAN;
	const float s = 0.01f;
	eddy_vec3 pos[216], vel[216];
	for (int i = 0; i < 216; ++i) {
		pos[i] = (eddy_vec3){0.45f + s * (float)(i % 6), 0.45f + s * (float)(i / 6 % 6), 0.45f + s * (float)(i / 36)};
		vel[i] = (eddy_vec3){0.3f, 0, 0};
	}
	if (squeeze)
		pos[14].x += 0.5f * s; /* an inner particle, half a spacing from particle 15 */
	eddy_sph_density_def dd = eddy_default_sph_density_def();
	dd.radius = 2 * s;
	dd.spacing = s;
	dd.stiffness = 400;
	eddy_add_sph_density(w, &dd);
	eddy_sph_pressure_def pd = eddy_default_sph_pressure_def();
	eddy_add_sph_pressure(w, &pd);
	eddy_integrate_def it = eddy_default_integrate_def();
	eddy_add_integrate(w, &it);
	CHECK(eddy_world_add_particles(w, 216, pos, vel) == EDDY_OK);
	double vrel = NAN;
	eddy_frame_stats fs;
	if (eddy_world_step_frame(w) == EDDY_OK && eddy_world_frame_stats(w, &fs) == EDDY_OK) {
		size_t n;
		const float *vx = eddy_world_channel(w, "vx", &n), *vy = eddy_world_channel(w, "vy", NULL),
					*vz = eddy_world_channel(w, "vz", NULL);
		double sum = 0;
		vrel = 0;
		for (size_t i = 0; i < n; ++i) {
			sum += vx[i];
			const double dx = vx[i] - 0.3, r = sqrt(dx * dx + vy[i] * vy[i] + vz[i] * vz[i]);
			vrel = r > vrel ? r : vrel;
		}
		*mean_vx = sum / (double)n;
		*steps = -1;
		for (int k = 0; k < fs.extra_count; ++k)
			if (strcmp(fs.extra[k].name, "settle_steps") == 0)
				*steps = fs.extra[k].value;
	} else
		printf("    %s\n", eddy_world_error(w));
	eddy_destroy_world(w);
	return vrel;
}

static void settling_relaxes_a_squeezed_start(void)
{
	double m0, m1, m2, st0, st1, st2;
	const double kick = settle_block(0, true, &m0, &st0), settled = settle_block(200, true, &m1, &st1),
				 plain = settle_block(200, false, &m2, &st2);
	printf("    squeezed block, largest speed relative to it after a frame: %.4f m/s unsettled, %.4f settled (%g "
	       "steps); plain lattice %.2g (%g steps); mean vx %.6f %.6f %.6f\n",
	       kick, settled, st1, plain, st2, m0, m1, m2);
	CHECK(st0 == -1); /* off: nothing published */
	CHECK(st1 > 0 && st1 < 200);
	CHECK(st2 == 0);
	CHECK(settled < 0.2 * kick);
	CHECK(plain < 1e-3);
	CHECK_NEAR(m1, 0.3, 1e-5);
	CHECK_NEAR(m2, 0.3, 1e-6);

	/* out of range, and without the force it settles with */
	char err[256];
	eddy_world_def d = eddy_default_world_def();
	d.settle_steps = -1;
	CHECK(eddy_create_world(&d, err, sizeof err) == NULL);
	CHECK_HAS(err, "world: 'settle_steps' must be in [0, 1000000] (got -1)");
	d.settle_steps = 10;
	eddy_world *w = eddy_create_world(&d, err, sizeof err);
	eddy_emit_box_def b = eddy_default_emit_box_def();
	eddy_add_emit_box(w, &b);
	eddy_sph_density_def dd = eddy_default_sph_density_def();
	eddy_add_sph_density(w, &dd);
	eddy_sph_dfsph_def df = eddy_default_sph_dfsph_def();
	eddy_add_sph_dfsph(w, &df);
	eddy_integrate_def it = eddy_default_integrate_def();
	eddy_add_integrate(w, &it);
	CHECK(eddy_world_check(w, NULL, NULL) >= 1);
	CHECK(eddy_world_step(w) == EDDY_ERR_INVALID);
	CHECK_HAS(eddy_world_error(w), "world: 'settle_steps' needs sph_pressure (WCSPH)");
	CHECK(eddy_world_particle_count(w) == 0);
	CHECK(eddy_world_step(w) == EDDY_ERR_INVALID); /* not skipped when asked again */
	CHECK(eddy_world_steps(w) == 0);
	eddy_destroy_world(w);
}

void suite_sph(void)
{
	RUN(kernels_integrate_to_one);
	RUN(settling_relaxes_a_squeezed_start);
	RUN(kernel_derivatives_match_finite_differences);
	RUN(lattice_sums);
	RUN(resting_block_stays_at_rest);
	RUN(hydrostatic_tank);
	RUN(hydrostatic_tank_continuity);
	RUN(continuity_rate_of_uniform_compression);
	RUN(continuity_keeps_hydrostatic_densities);
	RUN(continuity_rejects_bad_input);
	RUN(continuity_deterministic_and_resumable);
	RUN(table_is_kept_in_cell_order);
	RUN(equations_of_state);
	RUN(time_step_limits_are_reported);
	RUN(coincident_particles_separate);
	RUN(high_stiffness_stays_bounded);
	RUN(jet_does_not_tunnel_thin_plate);
	RUN(deterministic_across_threads);
	RUN(surface_tension_columns_only_when_added);
	RUN(empty_and_emptying_scenes);
	RUN(dam_break_matches_martin_moyce);
	RUN(dam_break_is_the_same_at_every_scale);
	RUN(sound_speed_follows_the_scene);
	RUN(droplet_oscillates_at_rayleigh_frequency);
	RUN(droplet_scene_rings_with_dfsph);
	RUN(no_gravity_system_no_weight);
	RUN(resting_drop_keeps_pairs_apart);
	RUN(resting_drop_holds_laplace_pressure);
	RUN(surface_tension_threshold_past_the_surface_is_an_error);
	RUN(scenes_run_and_report);
	RUN(verlet_lists_match_brute_force);
	RUN(neighbour_lists_grow_past_their_first_size);
	RUN(neighbour_lists_span_many_rows);
	RUN(neighbour_cells_hold_many_rows);
	RUN(neighbour_cells_skip_empty_stretches);
	sph_dfsph_suite(); /* dfsph helper */
}

/* The drop's l = 2 frequency converges on Rayleigh's as the spacing shrinks
 * (long: the 12-per-radius drop is 7,200 particles over four periods). */
static void droplet_frequency_converges(void)
{
	double theory, gap;
	const double coarse = drop_omega(8, 0.2, 0, &theory, &gap) / theory - 1;
	const double fine = drop_omega(12, 0.2, 0, &theory, &gap) / theory - 1;
	printf("    drop frequency against Rayleigh: 8 spacings per radius %+.1f%%, 12 %+.1f%%\n", 100 * coarse,
	       100 * fine);
	CHECK(isfinite(coarse) && isfinite(fine));
	CHECK(fabs(fine) < fabs(coarse));
	CHECK(fabs(fine) <= pow(1 - 1.5 / 12, -1.5) - 1); /* the first-order bound above */
}

void suite_long_sph(void)
{
	RUN(droplet_frequency_converges);
}

/* ---- dfsph helper ---- */
/* sph_dfsph, the implicit pressure solve (divergence-free SPH): hydrostatics,
 * the dam break, bad input, determinism and convergence. */

/* A scene of sph_setup with sph_dfsph in place of sph_pressure. */
static eddy_world *dfsph_world(sph_setup s, const eddy_sph_dfsph_def *df, double fps)
{
	s.dfsph = df;
	s.fps = fps;
	return sph_world(&s, NULL);
}

/* Mean compression max(rho - rho0, 0) / rho0 over the particles, from the
 * density column: what the solve controls (the free surface is under-dense
 * and stays so), and what the stats report as density_compression_avg. */
static double dfsph_compression(const eddy_world *w)
{
	size_t n;
	const float *rho = eddy_world_channel(w, "density", &n);
	double s = 0;
	for (size_t i = 0; i < n; ++i)
		s += fmax((double)rho[i] - 1000.0, 0) / 1000.0;
	return n ? s / (double)n : 0;
}

static double dfsph_stat(const eddy_frame_stats *st, const char *name)
{
	for (int k = 0; k < st->extra_count; ++k)
		if (strcmp(st->extra[k].name, name) == 0)
			return st->extra[k].value;
	return NAN;
}

/* Hydrostatic tank with the implicit solve: the 10^3 block of the WCSPH test
 * settles for 0.5 s, then 0.2 s are averaged. The solve stops each step at a
 * mean predicted compression of max_density_error; the prediction is first
 * order in the step and uses the spiky gradient for the poly6 density, so
 * the density it reaches differs by a fraction of that: the mean compression
 * must stay within three times the tolerance (measured about once). There is
 * no stiffness in the pressure: the layer means away from walls and surface
 * must give rho0 g d to 10% of rho0 g H (measured 3-6%, depending on
 * rounding; the WCSPH test allows 20%), and the fluid must be at rest (rms
 * speed under 5% of sqrt(g H), measured 1-2%; WCSPH: 10%). */
static void dfsph_hydrostatic_tank(void)
{
	sph_setup s = default_setup();
	eddy_sph_dfsph_def df = eddy_default_sph_dfsph_def();
	df.max_density_error = 0.001f;
	eddy_world *w = dfsph_world(s, &df, 100);
	CHECKF(eddy_world_advance(w, 0.5) == EDDY_OK, "%s", eddy_world_error(w));
	enum { BINS = 10 };
	double psum[BINS] = {0}, pcount[BINS] = {0}, top_sum = 0, v2sum = 0, vcount = 0, comp = 0, err_avg = 0, iters = 0;
	const double rho0 = 1000, g = 9.81, h = 2 * s.dx;
	const int frames = 20;
	for (int f = 0; f < frames; ++f) {
		CHECKF(eddy_world_step_frame(w) == EDDY_OK, "%s", eddy_world_error(w));
		size_t n;
		const float *x = eddy_world_channel(w, "x", &n), *y = eddy_world_channel(w, "y", NULL),
					*z = eddy_world_channel(w, "z", NULL), *p = eddy_world_channel(w, "pressure", NULL),
					*vx = eddy_world_channel(w, "vx", NULL), *vy = eddy_world_channel(w, "vy", NULL),
					*vz = eddy_world_channel(w, "vz", NULL);
		double top = 0;
		for (size_t i = 0; i < n; ++i) {
			top = fmax(top, y[i]);
			v2sum += (double)vx[i] * vx[i] + (double)vy[i] * vy[i] + (double)vz[i] * vz[i];
			vcount++;
			const int bin = (int)(y[i] / s.dx);
			if (bin >= 0 && bin < BINS && x[i] > h && x[i] < s.hi.x - h && z[i] > h && z[i] < s.hi.z - h) {
				psum[bin] += p[i];
				pcount[bin]++;
			}
		}
		top_sum += top;
		eddy_frame_stats st;
		eddy_world_frame_stats(w, &st);
		/* the stat is the mean over the particles of this frame */
		CHECK_NEAR(st.density_compression_avg, dfsph_compression(w), 1e-7);
		comp = fmax(comp, st.density_compression_avg);
		err_avg = fmax(err_avg, st.density_err_avg);
		iters += dfsph_stat(&st, "iterations") / frames;
		CHECK(dfsph_stat(&st, "unconverged") == 0);
	}
	const double surface = top_sum / frames + s.dx / 2, H = surface;
	double err = 0;
	int used = 0;
	for (int b = 0; b < BINS; ++b) {
		const double yc = (b + 0.5) * s.dx, d = surface - yc;
		if (!(pcount[b] > 0) || d < h || yc < h)
			continue;
		err = fmax(err, fabs(psum[b] / pcount[b] - rho0 * g * d) / (rho0 * g * H));
		used++;
	}
	const double vrms = sqrt(v2sum / vcount);
	printf("    dfsph hydrostatic: pressure_err %.4f over %d depths, mean compression %.5f (tolerance %.4f), "
	       "density_err_avg %.4f, %.1f iterations per step, rms speed %.3f m/s = %.3f sqrt(gH)\n",
	       err, used, comp, (double)df.max_density_error, err_avg, iters, vrms, vrms / sqrt(g * H));
	CHECK(used >= 4);
	CHECK(err < 0.1);
	CHECK(comp <= 3 * df.max_density_error);
	CHECK(vrms < 0.05 * sqrt(g * H));
	eddy_destroy_world(w);
}

/* The dam break of dam_break_matches_martin_moyce with the implicit solve:
 * |Z_sim - Z_exp| / Z_exp <= 10% for T in [1, 3] after a shift <= 0.2. */
static void dfsph_dam_break_matches_martin_moyce(void)
{
	curve ref[2], sim;
	CHECK(read_reference("data/martin_moyce_1952_a2.25in.csv", &ref[0]));
	CHECK(read_reference("data/martin_moyce_1952_a1.125in.csv", &ref[1]));
	char last[16384] = "";
	run_scene("scenes/dam_break.lua", "--set spacing=0.008333 --set fps=100 --set method=dfsph --set cfl=0.8", "T", "Z",
	          &sim, last, sizeof last);
	CHECK(sim.n > 20);
	if (sim.n <= 20 || ref[0].n < 2 || ref[1].n < 2)
		return;
	double best = INFINITY, best_shift = 0;
	for (int k = -20; k <= 20; ++k) {
		const double shift = 0.01 * k;
		double worst = 0;
		for (int r = 0; r < 2; ++r)
			for (double T = 1.0; T <= 3.0 + 1e-9; T += 0.05) {
				const double ze = curve_at(&ref[r], T), zs = curve_at(&sim, T - shift);
				if (isfinite(ze) && isfinite(zs))
					worst = fmax(worst, fabs(zs - ze) / ze);
			}
		if (worst < best) {
			best = worst;
			best_shift = shift;
		}
	}
	printf("    dfsph dam break a/12: worst |Z_sim - Z_exp| / Z_exp over T in [1, 3] = %.3f after a shift of %.2f; "
	       "Z_sim(1, 2, 3) = %.3f %.3f %.3f\n",
	       best, best_shift, curve_at(&sim, 1.0), curve_at(&sim, 2.0), curve_at(&sim, 3.0));
	CHECK(best <= 0.10);
	CHECK(test_json_number(last, "leaked") == 0 && test_json_number(last, "nonfinite") == 0);
	CHECK_HAS(last, "\"solver\":\"dfsph\"");
}

/* Out-of-range fields are rejected with the field's name, from C and from a
 * scene (file and line); sph_pressure and sph_dfsph together are an error. */
static void dfsph_rejects_bad_input(void)
{
	eddy_world_def d = eddy_default_world_def();
	eddy_world *w = eddy_create_world(&d, NULL, 0);
	eddy_sph_dfsph_def df = eddy_default_sph_dfsph_def();
	df.max_density_error = -0.001f;
	CHECK(!eddy_system_valid(w, eddy_add_sph_dfsph(w, &df)));
	CHECK_HAS(eddy_world_error(w), "sph_dfsph: 'max_density_error' must be > 0");
	df = eddy_default_sph_dfsph_def();
	df.max_density_error = NAN;
	CHECK(!eddy_system_valid(w, eddy_add_sph_dfsph(w, &df)));
	CHECK_HAS(eddy_world_error(w), "'max_density_error'");
	df = eddy_default_sph_dfsph_def();
	df.max_iterations = 0;
	CHECK(!eddy_system_valid(w, eddy_add_sph_dfsph(w, &df)));
	CHECK_HAS(eddy_world_error(w), "'max_iterations' must be between 2 and 10000 (got 0)");
	df = eddy_default_sph_dfsph_def();
	df.max_divergence_error = 2;
	CHECK(!eddy_system_valid(w, eddy_add_sph_dfsph(w, &df)));
	CHECK_HAS(eddy_world_error(w), "'max_divergence_error'");
	CHECK(!eddy_system_valid(w, eddy_add_sph_dfsph(w, NULL)));
	eddy_destroy_world(w);

	/* sph_pressure beside it is refused when added, naming both systems,
	 * and the pipeline stays as it was */
	sph_setup s = default_setup();
	df = eddy_default_sph_dfsph_def();
	w = dfsph_world(s, &df, 100);
	const int before = eddy_world_system_count(w);
	eddy_sph_pressure_def pr = eddy_default_sph_pressure_def();
	CHECK(!eddy_system_valid(w, eddy_add_sph_pressure(w, &pr)));
	CHECK_HAS(eddy_world_error(w), "sph_dfsph and sph_pressure cannot share a pipeline");
	CHECK_HAS(eddy_world_error(w), "remove one of them");
	CHECK(eddy_world_system_count(w) == before);
	CHECK(eddy_world_step(w) == EDDY_OK);
	eddy_destroy_world(w);

	char out[4096];
	CHECK(check_scene("dfsph_bad.lua",
	                  "local eddy = require 'eddy'\nlocal world = eddy.world{}\n"
	                  "world:add(eddy.sph_dfsph{ max_density_error = -0.01 })\nreturn world\n",
	                  out, sizeof out) != 0);
	CHECK_HAS(out, "dfsph_bad.lua:3: sph_dfsph: 'max_density_error' must be > 0 (got -0.01)");
	CHECK(check_scene("dfsph_bad.lua",
	                  "local eddy = require 'eddy'\nlocal world = eddy.world{}\n"
	                  "world:add(eddy.sph_dfsph{ max_density_eror = 0.01 })\nreturn world\n",
	                  out, sizeof out) != 0);
	CHECK_HAS(out, "dfsph_bad.lua:3: sph_dfsph: unknown field 'max_density_eror'");
}

/* Same state hash on 1 and 2 threads: every particle writes only its own
 * values and the mean errors are summed serially. */
static void dfsph_deterministic_across_threads(void)
{
	uint64_t hash[2];
	sph_setup s = splash_setup();
	s.cfl = 0.8;
	const eddy_sph_dfsph_def df = eddy_default_sph_dfsph_def();
	s.dfsph = &df;
	hashes_on_one_and_two_threads(s, 30, hash);
	printf("    dfsph state hash 1 thread %016llx, 2 threads %016llx\n", (unsigned long long)hash[0],
	       (unsigned long long)hash[1]);
	CHECK(hash[0] == hash[1]);
}

/* The SSE and AVX2 paths give the same bits (the AVX2 one is chosen at run
 * time; EDDY_NO_AVX2 forces SSE): a WCSPH splash with surface tension (grid
 * search and Verlet filter, pressure, viscosity) and a DFSPH drop (the
 * search without a skin and the solver's passes), hashed on both paths. On
 * a CPU without AVX2 both runs take the SSE path and the test says so. */
static void simd_paths_give_the_same_bits(void)
{
	char *saved = test_env_save("EDDY_NO_AVX2");
	const eddy_sph_dfsph_def df = eddy_default_sph_dfsph_def();
	for (int k = 0; k < 2; ++k) {
		sph_setup s = splash_setup();
		if (k == 0) {
			s.sigma = 0.0728f;
		} else {
			s.cfl = 0.8;
			s.dfsph = &df;
		}
		uint64_t hash[2];
		for (int path = 0; path < 2; ++path) {
			test_env_set("EDDY_NO_AVX2", path == 0 ? NULL : "1");
			eddy_world *w = sph_world(&s, NULL);
			for (int f = 0; f < (k == 0 ? 8 : 20); ++f)
				CHECK(eddy_world_step_frame(w) == EDDY_OK);
			hash[path] = eddy_world_state_hash(w);
			eddy_destroy_world(w);
		}
		printf("    %s: state hash %016llx (%s), %016llx (SSE)\n", k == 0 ? "wcsph" : "dfsph",
		       (unsigned long long)hash[0], __builtin_cpu_supports("avx2") ? "AVX2" : "no AVX2 here: SSE",
		       (unsigned long long)hash[1]);
		CHECK(hash[0] == hash[1]);
	}
	test_env_restore("EDDY_NO_AVX2", saved);
}

/* A block dropped from 3 cm into a tank, at CFL 0.8 with no acoustic limit:
 * every step converges (no step hits max_iterations), the published residual
 * stays within the tolerance, and the measured mean compression within twice
 * it. The time step is set by the flow, so it is far above WCSPH's. */
static void dfsph_drop_converges(void)
{
	sph_setup s = default_setup();
	s.fmin = (eddy_vec3){0.0f, 0.03f, 0.0f};
	s.fmax = (eddy_vec3){0.06f, 0.09f, 0.1f};
	s.mu = 1e-3f;
	s.cfl = 0.8;
	eddy_sph_dfsph_def df = eddy_default_sph_dfsph_def();
	eddy_world *w = dfsph_world(s, &df, 30);
	double comp = 0, resid = 0, dt_min = INFINITY, iters = 0;
	int64_t steps = 0;
	const int frames = 12;
	for (int f = 0; f < frames; ++f) {
		CHECKF(eddy_world_step_frame(w) == EDDY_OK, "%s", eddy_world_error(w));
		eddy_frame_stats st;
		eddy_world_frame_stats(w, &st);
		CHECK(dfsph_stat(&st, "unconverged") == 0);
		CHECK(st.leaked == 0 && st.nonfinite == 0);
		resid = fmax(resid, dfsph_stat(&st, "residual"));
		iters += dfsph_stat(&st, "iterations") * (double)st.steps;
		steps += st.steps;
		dt_min = fmin(dt_min, st.dt_min);
		comp = fmax(comp, st.density_compression_avg);
	}
	printf("    dfsph drop: %lld steps in %.2f s (dt >= %.2g s), %.1f iterations per step, residual <= %.5f, "
	       "mean compression <= %.5f (tolerance %.4f)\n",
	       (long long)steps, frames / 30.0, dt_min, iters / (double)steps, resid, comp, (double)df.max_density_error);
	CHECK(resid <= df.max_density_error);
	CHECK(comp <= 2 * df.max_density_error);
	CHECK(dt_min > 5e-4); /* WCSPH at k = 200 would need 3e-4 s */
	eddy_destroy_world(w);
}

/* The same drop with the density solve held to 2 iterations and a mean
 * tolerance of 0.05: the impact leaves particles predicted over 10%
 * compressed (DFSPH_MAX_COMPRESSION, the solve's other stopping rule) while
 * the mean stays within its tolerance. Such a step is short of converging
 * and must count in unconverged, frame by frame, exactly when the frame's
 * residual_max is over the bound (a step ends over it only at the cap).
 * Counting only the mean, unconverged read 0 through the impact (2 of the
 * 12 frames over the bound, at CFL 1, the pour's). The first such step
 * raises one run-time warning naming the step and the particle. */
static void dfsph_capped_compression_counts_as_unconverged(void)
{
	sph_setup s = default_setup();
	s.fmin = (eddy_vec3){0.0f, 0.03f, 0.0f};
	s.fmax = (eddy_vec3){0.06f, 0.09f, 0.1f};
	s.mu = 1e-3f;
	s.cfl = 1.0;
	eddy_sph_dfsph_def df = eddy_default_sph_dfsph_def();
	df.max_density_error = 0.05f;
	df.max_iterations = 2;
	eddy_world *w = dfsph_world(s, &df, 30);
	int over = 0, counted = 0, agree = 0;
	const int frames = 12;
	for (int f = 0; f < frames; ++f) {
		CHECKF(eddy_world_step_frame(w) == EDDY_OK, "%s", eddy_world_error(w));
		eddy_frame_stats st;
		eddy_world_frame_stats(w, &st);
		const bool short_of = dfsph_stat(&st, "residual_max") > 0.1 || dfsph_stat(&st, "residual") > 0.05;
		const bool unconverged = dfsph_stat(&st, "unconverged") > 0;
		over += short_of;
		counted += unconverged;
		agree += short_of == unconverged;
		/* and says so at run time, once: a warning from the first such step on */
		CHECKF(eddy_world_warning_count(w) == (counted > 0), "frame %d: %d warnings after %d unconverged frames", f + 1,
		       eddy_world_warning_count(w), counted);
	}
	printf("    dfsph drop, density solve capped at 2: %d of %d frames over a stopping rule, %d counted unconverged\n",
	       over, frames, counted);
	CHECK(over > 0);
	CHECK(agree == frames);
	CHECK_HAS(eddy_world_warning(w, 0), "sph_dfsph: the density solve stopped at its cap (max_iterations = 2) at step");
	CHECK_HAS(eddy_world_warning(w, 0), "particle");
	eddy_destroy_world(w);
}

/* A drop at rest in zero gravity with sph_dfsph (alpha 0.1, c 20 m/s: the
 * droplet scene's DFSPH), with and without surface tension, at CFL 1 (the
 * pour's) and at 0.4: nothing moves it but round-off
 * and, with tension, its own rounding-off, so after 0.3 s every particle
 * must be within 1.5 R of the centre of mass and slower than 0.1 m/s (the
 * capillary speed sqrt(sigma / (rho R)) is 0.085 m/s). Monaghan's viscosity
 * stepped past its explicit limit (about h / (alpha c)) blew it apart from
 * round-off: at rest nothing else bounded DFSPH's step (sph_viscosity's
 * limit now does). Without that limit the four cases here end with
 * particles 5.2-5.9 R out at 0.5-2.4 m/s; with it 0.95-0.99 R, under
 * 0.005 m/s. */
static void dfsph_drop_at_rest_holds_together(void)
{
	const double R = 0.01;
	const eddy_sph_dfsph_def df = eddy_default_sph_dfsph_def();
	for (int c = 0; c < 4; ++c) {
		sph_setup s = default_setup();
		s.dx = (float)(R / 8);
		s.lo = (eddy_vec3){-0.03f, -0.03f, -0.03f};
		s.hi = (eddy_vec3){0.03f, 0.03f, 0.03f};
		s.fmin = (eddy_vec3){(float)-R, (float)-R, (float)-R};
		s.fmax = (eddy_vec3){(float)R, (float)R, (float)R};
		s.shape = EDDY_EMIT_ELLIPSOID;
		s.k = 400; /* c = 20 m/s */
		s.mu = 1e-3f;
		s.artificial = 0.1f;
		s.sigma = c & 1 ? 0.0728f : -1;
		s.gravity = 0;
		s.walls = false;
		s.cfl = c & 2 ? 0.4 : 1.0;
		eddy_world *w = dfsph_world(s, &df, 200);
		bool ok = true;
		for (int f = 0; f < 60 && ok; ++f)
			ok = eddy_world_step_frame(w) == EDDY_OK;
		CHECKF(ok, "%s", eddy_world_error(w));
		size_t n = 0;
		const float *x = eddy_world_channel(w, "x", &n), *y = eddy_world_channel(w, "y", NULL),
					*z = eddy_world_channel(w, "z", NULL), *vx = eddy_world_channel(w, "vx", NULL),
					*vy = eddy_world_channel(w, "vy", NULL), *vz = eddy_world_channel(w, "vz", NULL);
		double cx = 0, cy = 0, cz = 0, rmax = 0, vmax = 0;
		for (size_t i = 0; i < n; ++i)
			cx += x[i], cy += y[i], cz += z[i];
		cx /= (double)n, cy /= (double)n, cz /= (double)n;
		for (size_t i = 0; i < n; ++i) {
			rmax = fmax(rmax, sqrt((x[i] - cx) * (x[i] - cx) + (y[i] - cy) * (y[i] - cy) + (z[i] - cz) * (z[i] - cz)));
			vmax = fmax(vmax, sqrt((double)vx[i] * vx[i] + (double)vy[i] * vy[i] + (double)vz[i] * vz[i]));
		}
		eddy_frame_stats st;
		eddy_world_frame_stats(w, &st);
		printf("    dfsph drop at rest, %s tension, CFL %.1f: %zu particles, farthest %.2f R, fastest %.4f m/s, "
		       "%d steps in the last frame (%s)\n",
		       s.sigma >= 0 ? "with" : "no", s.cfl, n, rmax / R, vmax, (int)st.steps, st.dt_limit);
		CHECK(n > 2000 && rmax <= 1.5 * R && vmax <= 0.1);
		eddy_destroy_world(w);
	}
}

/* A viscous blob (mu = 50 Pa s, 5 cm, 5 mm spacing) dropped 5 cm onto the
 * floor lands and stops: no particle may be faster than the fall from the
 * blob's top to the floor allows, sqrt(2 g 0.1 m) = 1.40 m/s, and the
 * energy never rises above its start (viscosity only takes energy). The
 * explicit viscous step must hold that at WCSPH's CFL number (eddy.fluid's
 * 0.4), at sph_dfsph's (0.5) and, one step beyond, at 1. Before its limit
 * was h^2 / (15 nu) (sph_viscosity's VISC_LIMIT) it was 0.3125 h^2 / nu
 * times the CFL number, past the term's stability: sph_dfsph's blob reached
 * 17 m/s in free fall from round-off, WCSPH's particles jittered at 3.6 m/s
 * on the floor. */
static void viscous_blob_lands_at_rest(void)
{
	const eddy_sph_dfsph_def df = eddy_default_sph_dfsph_def();
	const double cfls[] = {0.4, 0.5, 1.0};
	for (int c = 0; c < 3; ++c) {
		sph_setup s = default_setup();
		s.dx = 0.005f;
		s.hi = (eddy_vec3){0.2f, 0.15f, 0.2f};
		s.fmin = (eddy_vec3){0.075f, 0.05f, 0.075f};
		s.fmax = (eddy_vec3){0.125f, 0.1f, 0.125f};
		s.mu = 50;
		s.k = 400;
		s.cfl = cfls[c];
		eddy_world *w = c == 0 ? (s.fps = 30, sph_world(&s, NULL)) : dfsph_world(s, &df, 30);
		double vmax = 0, e0 = NAN, rise = 0, vlast = NAN;
		bool ok = true;
		for (int f = 0; f < 9 && ok; ++f) {
			ok = eddy_world_step_frame(w) == EDDY_OK;
			eddy_frame_stats st;
			eddy_world_frame_stats(w, &st);
			vmax = fmax(vmax, st.max_speed);
			vlast = st.max_speed;
			const double e = st.kinetic_energy + st.potential_energy;
			e0 = f == 0 ? e : e0;
			rise = fmax(rise, (e - e0) / e0);
		}
		CHECKF(ok, "%s", eddy_world_error(w));
		printf("    viscous blob, %s at CFL %.1f: fastest %.3f m/s over 0.3 s (bound 1.40), %.3f m/s at "
		       "0.3 s, energy rise %.2e of its first frame's, %zu particles\n",
		       c == 0 ? "WCSPH" : "DFSPH", s.cfl, vmax, vlast, rise, eddy_world_particle_count(w));
		CHECK(vmax <= sqrt(2 * 9.81 * 0.1));
		CHECK(rise <= 1e-3);
		eddy_destroy_world(w);
	}
}

/* sph_dfsph's state across steps (its warm starts' columns) is in the
 * checkpoint, so a run resumed from one is bit-identical to one that never
 * stopped. */
static void dfsph_resume_is_bit_identical(void)
{
	sph_setup s = default_setup();
	s.fmin = (eddy_vec3){0.0f, 0.03f, 0.0f};
	s.fmax = (eddy_vec3){0.06f, 0.09f, 0.1f};
	s.cfl = 1.0;
	eddy_sph_dfsph_def df = eddy_default_sph_dfsph_def();
	check_resume_bit_identical(dfsph_world(s, &df, 30), dfsph_world(s, &df, 30), dfsph_world(s, &df, 30),
	                           "dfsph_ckpt.eddy");
}

static void sph_dfsph_suite(void)
{
	RUN(dfsph_hydrostatic_tank);
	RUN(dfsph_dam_break_matches_martin_moyce);
	RUN(dfsph_rejects_bad_input);
	RUN(dfsph_deterministic_across_threads);
	RUN(simd_paths_give_the_same_bits);
	RUN(dfsph_drop_converges);
	RUN(dfsph_capped_compression_counts_as_unconverged);
	RUN(dfsph_drop_at_rest_holds_together);
	RUN(viscous_blob_lands_at_rest);
	RUN(dfsph_resume_is_bit_identical);
}

/* ---- speed helper ---- */

/* sph_density reuses a Verlet list (pairs within h (1 + skin)) between grid
 * searches and filters it every step: the neighbour counts must be exactly
 * those of an all-pairs test and the densities those of an all-pairs sum,
 * through falling, splashing, removed and added particles (a removal and an
 * addition in the same step keep the count). */
typedef struct verlet_check {
	float h, mass;
	int steps, count_mismatch;
	double worst_rel;
} verlet_check;

static eddy_status verlet_check_step(eddy_world *w, const eddy_step_context *ctx, void *user)
{
	(void)ctx;
	verlet_check *vc = user;
	size_t n;
	const float *x = eddy_world_channel(w, "x", &n), *y = eddy_world_channel(w, "y", NULL),
				*z = eddy_world_channel(w, "z", NULL), *rho = eddy_world_channel(w, "density", NULL),
				*nc = eddy_world_channel(w, "neighbors", NULL);
	const float h2 = vc->h * vc->h;
	const double poly6 = 315.0 / (64.0 * M_PI * pow(vc->h, 9));
	for (size_t i = 0; i < n; ++i) {
		int cnt = 0;
		double sum = (double)h2 * h2 * h2;
		for (size_t j = 0; j < n; ++j) {
			const float rx = x[i] - x[j], ry = y[i] - y[j], rz = z[i] - z[j];
			const float d = h2 - (rx * rx + ry * ry + rz * rz);
			if (d > 0 && j != i) {
				cnt++;
				sum += (double)d * d * d;
			}
		}
		vc->count_mismatch += (float)cnt != nc[i];
		const double want = vc->mass * poly6 * sum;
		vc->worst_rel = fmax(vc->worst_rel, fabs(rho[i] - want) / want);
	}
	vc->steps++;
	return EDDY_OK;
}

/* Adds a test's check: a custom system reading the count named columns,
 * stepping with step on user. */
static void add_check(eddy_world *w, const char *name, const char *const *reads, int count, eddy_step_fn step,
                      void *user)
{
	eddy_custom_system_def cs = eddy_default_custom_system_def();
	cs.name = name;
	cs.reads = reads;
	cs.read_count = count;
	cs.step = step;
	cs.user = user;
	CHECK(eddy_system_valid(w, eddy_add_custom_system(w, &cs)));
}

/* The brute-force check as a custom system after sph_density. */
static void add_verlet_check(eddy_world *w, verlet_check *vc)
{
	static const char *const reads[] = {"x", "y", "z", "density", "neighbors"};
	add_check(w, "verlet_check", reads, 5, verlet_check_step, vc);
}

/* One run of verlet_lists_match_brute_force; returns its state hash. */
static uint64_t verlet_run_brute_force(bool verlet_list)
{
	const char *what = verlet_list ? "Verlet list" : "search at h";
	eddy_world_def d = eddy_default_world_def();
	d.bounds_max = (eddy_vec3){0.3f, 0.3f, 0.3f};
	d.threads = 2;
	d.fps = 200;
	eddy_world *w = eddy_create_world(&d, NULL, 0);
	eddy_emit_box_def b = eddy_default_emit_box_def();
	b.min = (eddy_vec3){0.05f, 0.12f, 0.05f};
	b.max = (eddy_vec3){0.15f, 0.22f, 0.15f};
	b.spacing = 0.01f;
	eddy_add_emit_box(w, &b);
	eddy_sph_density_def de = eddy_default_sph_density_def();
	de.verlet_list = verlet_list;
	const eddy_system_id dens = eddy_add_sph_density(w, &de);
	verlet_check vc = {de.radius, 0, 0, 0, 0};
	add_verlet_check(w, &vc);
	eddy_sph_pressure_def pr = eddy_default_sph_pressure_def();
	eddy_add_sph_pressure(w, &pr);
	eddy_sph_viscosity_def vi = eddy_default_sph_viscosity_def();
	eddy_add_sph_viscosity(w, &vi);
	eddy_gravity_def g = eddy_default_gravity_def();
	eddy_add_gravity(w, &g);
	eddy_integrate_def it = eddy_default_integrate_def();
	eddy_add_integrate(w, &it);
	eddy_collide_box_def bx = eddy_default_collide_box_def();
	bx.max = d.bounds_max;
	bx.sph_walls = false; /* a container only: the check sums fluid pairs */
	eddy_add_collide_box(w, &bx);
	vc.mass = eddy_sph_particle_mass(w, dens);
	for (int f = 0; f < 40; ++f) {
		CHECK(eddy_world_step_frame(w) == EDDY_OK);
		if (f == 20) { /* a removal and an addition between two steps: n unchanged */
			const eddy_vec3 p = {0.25f, 0.05f, 0.25f};
			CHECK(eddy_world_remove_particle(w, 7) == EDDY_OK);
			CHECK(eddy_world_add_particles(w, 1, &p, NULL) == EDDY_OK);
		}
		if (f == 30) { /* n changes */
			const eddy_vec3 p[2] = {{0.2f, 0.2f, 0.2f}, {0.205f, 0.2f, 0.2f}};
			CHECK(eddy_world_add_particles(w, 2, p, NULL) == EDDY_OK);
		}
	}
	printf("    %s, %d steps: %d neighbour counts differ from all pairs, worst density error %.1e\n", what, vc.steps,
	       vc.count_mismatch, vc.worst_rel);
	CHECK(vc.steps > 100);
	CHECK(vc.count_mismatch == 0);
	CHECK(vc.worst_rel < 1e-5);
	const uint64_t hash = eddy_world_state_hash(w);
	eddy_destroy_world(w);
	return hash;
}

/* The same run with the Verlet list and without it (verlet_list = false:
 * the grid search at h every step, writing the exact lists itself): both
 * must match all pairs, and give the same bits. */
static void verlet_lists_match_brute_force(void)
{
	const uint64_t with = verlet_run_brute_force(true), without = verlet_run_brute_force(false);
	printf("    state hash %016llx (Verlet list), %016llx (search at h)\n", (unsigned long long)with,
	       (unsigned long long)without);
	CHECK(with == without);
}

/* The neighbour lists take only what they hold (src/sph/neighbors.c): their
 * arrays start at a guess (64 candidates, 40 neighbours a particle) and are
 * enlarged, the pass rerun, when the lists do not fit. A support of 4 and 5
 * spacings (about 350 and 600 neighbours, far past the guess) must still
 * give every particle exactly its all-pairs count and density, on two
 * threads, through the expansion that moves the Verlet list's rows; and
 * sph_pressure, which reads the lists, must still conserve momentum: its
 * pair forces are equal and opposite, so sum_i a_i = 0 up to float
 * rounding (a list read from the wrong place breaks the symmetry). */
typedef struct momentum_check {
	double worst; /* |sum a| / sum |a| */
	int forced;   /* steps with any force */
	float most;   /* neighbours of any particle */
} momentum_check;

static eddy_status momentum_check_step(eddy_world *w, const eddy_step_context *ctx, void *user)
{
	(void)ctx;
	momentum_check *mc = user;
	size_t n;
	const float *ax = eddy_world_channel(w, "ax", &n), *ay = eddy_world_channel(w, "ay", NULL),
				*az = eddy_world_channel(w, "az", NULL), *nc = eddy_world_channel(w, "neighbors", NULL);
	double s[3] = {0, 0, 0}, mag = 0;
	for (size_t i = 0; i < n; ++i) {
		mc->most = nc[i] > mc->most ? nc[i] : mc->most;
		s[0] += ax[i], s[1] += ay[i], s[2] += az[i];
		mag += sqrt((double)ax[i] * ax[i] + (double)ay[i] * ay[i] + (double)az[i] * az[i]);
	}
	mc->forced += mag > 0;
	if (mag > 0)
		mc->worst = fmax(mc->worst, sqrt(s[0] * s[0] + s[1] * s[1] + s[2] * s[2]) / mag);
	return EDDY_OK;
}

static void neighbour_lists_grow_past_their_first_size(void)
{
	const float ratios[] = {4.0f, 5.0f}; /* 5: the most sph_density takes */
	for (int r = 0; r < 2; ++r) {
		eddy_world_def d = eddy_default_world_def();
		d.bounds_max = (eddy_vec3){0.3f, 0.3f, 0.3f};
		d.threads = 2;
		d.fps = 200;
		d.gravity = (eddy_vec3){0, 0, 0};
		eddy_world *w = eddy_create_world(&d, NULL, 0);
		eddy_emit_box_def b = eddy_default_emit_box_def();
		b.min = (eddy_vec3){0.1f, 0.1f, 0.1f};
		b.max = (eddy_vec3){0.18f, 0.18f, 0.18f};
		b.spacing = 0.009f; /* packed 1.37 x denser than sph_density's spacing: pressure everywhere */
		b.jitter = 0.2f;    /* no lattice symmetry to hide a wrong pair */
		eddy_add_emit_box(w, &b);
		eddy_sph_density_def de = eddy_default_sph_density_def();
		de.spacing = 0.01f;
		de.radius = ratios[r] * de.spacing;
		const eddy_system_id dens = eddy_add_sph_density(w, &de);
		verlet_check vc = {de.radius, 0, 0, 0, 0};
		momentum_check mc = {0};
		add_verlet_check(w, &vc);
		eddy_gravity_def g = eddy_default_gravity_def();
		eddy_add_gravity(w, &g);
		eddy_sph_pressure_def pr = eddy_default_sph_pressure_def();
		eddy_add_sph_pressure(w, &pr);
		static const char *const mreads[] = {"ax", "ay", "az", "neighbors"};
		add_check(w, "momentum_check", mreads, 4, momentum_check_step, &mc);
		eddy_integrate_def it = eddy_default_integrate_def();
		eddy_add_integrate(w, &it);
		vc.mass = eddy_sph_particle_mass(w, dens);
		for (int f = 0; f < 3; ++f)
			CHECK(eddy_world_step_frame(w) == EDDY_OK);
		const float most = mc.most;
		printf("    support %.0f spacings: %d steps, up to %.0f neighbours, %d counts differ from all pairs, worst "
		       "density error %.1e, |sum a| / sum |a| up to %.1e over %d steps with forces\n",
		       (double)ratios[r], vc.steps, (double)most, vc.count_mismatch, vc.worst_rel, mc.worst, mc.forced);
		CHECK(most > 64); /* past the arrays' first guess */
		CHECK(vc.steps >= 3);
		CHECK(vc.count_mismatch == 0);
		CHECK(vc.worst_rel < 1e-5); /* float sums in another order than the double reference */
		CHECK(mc.forced > 0);
		CHECK(mc.worst < 1e-4); /* float rounding of a sum over ~500 particles' forces */
		eddy_destroy_world(w);
	}
}

/* The Verlet candidates and the exact lists are stored as 16-bit numbers in
 * groups of eight (src/sph/sph.h), whole where a group spans more than 65535
 * rows or starts 65535 or more after the previous group. Here a particle A
 * has neighbours C and D1..D7 beside it in its rows of cells and one, B, in
 * the next layer of cells, with a sheet of 300 x 300 particles in A's layer
 * (out of reach) between them in cell order: A's second group {B} starts
 * over 90000 rows after its first, {C, D}; B's groups and C's, which mix
 * the two layers, span as many. The ten must see exactly their all-pairs
 * neighbours, at the search and in the steps that reuse its list; and
 * sph_viscosity, which reads the exact lists, must give equal and opposite
 * pair forces as B and C move towards the others (the sheet at rest feels
 * none): sum_i a_i = 0 up to float rounding, which a row read wrongly from
 * a wide group would break. */
enum { SPAN_PROBES = 10 };
typedef struct span_check {
	float h;
	eddy_vec3 probe[SPAN_PROBES]; /* A, B, C, then the seven D */
	int steps, mismatch, found, a_count;
} span_check;

static eddy_status span_check_step(eddy_world *w, const eddy_step_context *ctx, void *user)
{
	(void)ctx;
	span_check *sc = user;
	size_t n;
	const float *x = eddy_world_channel(w, "x", &n), *y = eddy_world_channel(w, "y", NULL),
				*z = eddy_world_channel(w, "z", NULL), *nc = eddy_world_channel(w, "neighbors", NULL);
	const float h2 = sc->h * sc->h;
	for (int p = 0; p < SPAN_PROBES; ++p)
		for (size_t i = 0; i < n; ++i) {
			if (x[i] != sc->probe[p].x || y[i] != sc->probe[p].y || z[i] != sc->probe[p].z)
				continue;
			int cnt = 0;
			for (size_t j = 0; j < n; ++j) {
				const float rx = x[i] - x[j], ry = y[i] - y[j], rz = z[i] - z[j];
				cnt += j != i && h2 - (rx * rx + ry * ry + rz * rz) > 0;
			}
			sc->found++;
			sc->mismatch += (float)cnt != nc[i];
			sc->a_count = p == 0 ? cnt : sc->a_count;
		}
	sc->steps++;
	return EDDY_OK;
}

static void neighbour_lists_span_many_rows(void)
{
	eddy_world_def d = eddy_default_world_def();
	d.bounds_max = (eddy_vec3){3.2f, 3.4f, 0.3f};
	d.threads = 2;
	d.fps = 100;
	d.gravity = (eddy_vec3){0, 0, 0};
	eddy_world *w = eddy_create_world(&d, NULL, 0);
	const float s = 0.01f, h = 0.02f;
	/* A, C a row apart in x, B above A by a layer of cells (h/2), the seven
	 * D beside A and C in their layer; the sheet in A's layer from 3h
	 * further along y */
	span_check sc = {h, {{0.1f, 0.1f, 0.1f}, {0.1f, 0.1f, 0.1f + 0.6f * h}, {0.1f + 0.6f * h, 0.1f, 0.1f}}, 0, 0, 0, 0};
	for (int k = 0; k < 7; ++k)
		sc.probe[3 + k] = (eddy_vec3){0.094f + 0.003f * (float)k, 0.103f, 0.1f};
	enum { SIDE = 300 };
	eddy_vec3 *pos = malloc((SIDE * SIDE + SPAN_PROBES) * sizeof *pos);
	CHECK(pos != NULL);
	for (int k = 0; k < SIDE * SIDE; ++k)
		pos[k] = (eddy_vec3){0.1f + s * (float)(k % SIDE), 0.1f + 3 * h + s * (float)(k / SIDE), 0.1f};
	eddy_vec3 *vel = calloc(SIDE * SIDE + SPAN_PROBES, sizeof *vel);
	CHECK(vel != NULL);
	for (int p = 0; p < SPAN_PROBES; ++p)
		pos[SIDE * SIDE + p] = sc.probe[p];
	vel[SIDE * SIDE + 1] = (eddy_vec3){0, 0, -0.05f}; /* B down onto A */
	vel[SIDE * SIDE + 2] = (eddy_vec3){-0.05f, 0, 0}; /* C along x onto A */
	eddy_sph_density_def de = eddy_default_sph_density_def();
	de.spacing = s;
	de.radius = h;
	eddy_add_sph_density(w, &de);
	eddy_sph_viscosity_def vi = eddy_default_sph_viscosity_def();
	eddy_add_sph_viscosity(w, &vi);
	momentum_check mc = {0};
	static const char *const mreads[] = {"ax", "ay", "az", "neighbors"};
	add_check(w, "momentum_check", mreads, 4, momentum_check_step, &mc);
	static const char *const reads[] = {"x", "y", "z", "neighbors"};
	add_check(w, "span_check", reads, 4, span_check_step, &sc);
	/* no integrate: the particles stay where they are, with their velocities */
	CHECK(eddy_world_add_particles(w, SIDE * SIDE + SPAN_PROBES, pos, vel) == EDDY_OK);
	free(pos);
	free(vel);
	for (int f = 0; f < 3; ++f)
		CHECK(eddy_world_step_frame(w) == EDDY_OK);
	printf(
		"    %d steps, %d probes found (A with %d neighbours), %d counts differ from all pairs; viscous forces in %d "
		"steps, |sum a| / sum |a| up to %.1e\n",
		sc.steps, sc.found, sc.a_count, sc.mismatch, mc.forced, mc.worst);
	CHECK(sc.steps >= 3);
	CHECK(sc.found == SPAN_PROBES * sc.steps);
	CHECK(sc.a_count == 9); /* two groups */
	CHECK(sc.mismatch == 0);
	CHECK(mc.forced == sc.steps);
	CHECK(mc.worst < 1e-6); /* a few pairs' forces */
	eddy_destroy_world(w);
}

/* The cell grid stores each cell's first row as a 16-bit offset from its
 * row of cells' first (src/sph/grid.c), every cell's whole while a row of
 * cells holds more than 65535 particles. Here 70,000 particles fill one row
 * of cells: a bar a cell across (4 x 4 particles) and 11 m long, added in
 * cell order (the first step finds it in order) or against it (the first
 * step sorts it: the two ways of making the cells' starts), and falling
 * along its length (searched again as it moves). Every particle must see
 * exactly its all-pairs neighbours, about 240 each. */
typedef struct bar_check {
	float h;
	int steps, mismatch;
	float most;
	const float *x; /* for the sort by x */
} bar_check;

static bar_check *bar_sorting;
static int bar_cmp_x(const void *a, const void *b)
{
	const float xa = bar_sorting->x[*(const uint32_t *)a], xb = bar_sorting->x[*(const uint32_t *)b];
	return (xa > xb) - (xa < xb);
}

/* Every particle's all-pairs count, from the particles sorted by x: only
 * those within h along x can be closer than h. */
static eddy_status bar_check_step(eddy_world *w, const eddy_step_context *ctx, void *user)
{
	(void)ctx;
	bar_check *bc = user;
	size_t n;
	const float *x = eddy_world_channel(w, "x", &n), *y = eddy_world_channel(w, "y", NULL),
				*z = eddy_world_channel(w, "z", NULL), *nc = eddy_world_channel(w, "neighbors", NULL);
	uint32_t *by_x = malloc(n * sizeof *by_x);
	CHECK(by_x != NULL);
	for (size_t i = 0; i < n; ++i)
		by_x[i] = (uint32_t)i;
	bc->x = x;
	bar_sorting = bc;
	qsort(by_x, n, sizeof *by_x, bar_cmp_x);
	const float h2 = bc->h * bc->h;
	for (size_t a = 0, lo = 0; a < n; ++a) {
		const uint32_t i = by_x[a];
		while (x[by_x[lo]] < x[i] - bc->h)
			lo++;
		int cnt = 0;
		for (size_t k = lo; k < n && x[by_x[k]] <= x[i] + bc->h; ++k) {
			const uint32_t j = by_x[k];
			const float rx = x[i] - x[j], ry = y[i] - y[j], rz = z[i] - z[j];
			cnt += j != i && h2 - (rx * rx + ry * ry + rz * rz) > 0;
		}
		bc->mismatch += (float)cnt != nc[i];
		bc->most = (float)cnt > bc->most ? (float)cnt : bc->most;
	}
	free(by_x);
	bc->steps++;
	return EDDY_OK;
}

/* The cell table keeps offsets only over the runs of occupied cells of a
 * row (grid.c): slabs of particles across x, the gaps between them from 1
 * to 12 empty cells (runs merge across gaps of up to 6), tumbling under an
 * oblique gravity so that the table is re-sorted most steps and found in
 * order on others: every count must be the all-pairs one. */
/* sph_density (spacing, radius h), the bar_check after it, gravity and
 * integrate: the pipeline of the neighbour-cell tests below. */
static void add_bar_pipeline(eddy_world *w, float spacing, float h, bar_check *bc)
{
	eddy_sph_density_def de = eddy_default_sph_density_def();
	de.spacing = spacing;
	de.radius = h;
	eddy_add_sph_density(w, &de);
	static const char *const reads[] = {"x", "y", "z", "neighbors"};
	add_check(w, "bar_check", reads, 4, bar_check_step, bc);
	eddy_gravity_def g = eddy_default_gravity_def();
	eddy_add_gravity(w, &g);
	eddy_integrate_def it = eddy_default_integrate_def();
	eddy_add_integrate(w, &it);
}

static void neighbour_cells_skip_empty_stretches(void)
{
	eddy_world_def d = eddy_default_world_def();
	d.bounds_max = (eddy_vec3){1.4f, 0.16f, 0.16f};
	d.threads = 2;
	d.fps = 100;
	d.gravity = (eddy_vec3){3, -9.81f, 2};
	eddy_world *w = eddy_create_world(&d, NULL, 0);
	const float h = 0.02f, cell = h / 2;
	enum { N = 6000 };
	eddy_vec3 *pos = malloc(N * sizeof *pos);
	CHECK(pos != NULL);
	uint32_t seed = 12345;
	float slab[13][2]; /* [x0, x1) of each slab: 3 cells wide, then a gap of k cells */
	float at = 0.05f;
	for (int k = 0; k < 13; ++k) {
		slab[k][0] = at;
		slab[k][1] = at + 3 * cell;
		at = slab[k][1] + (float)(k % 12 + 1) * cell;
	}
	for (int k = 0; k < N; ++k) {
		float r[3];
		for (int a = 0; a < 3; ++a) {
			seed = seed * 1664525u + 1013904223u;
			r[a] = (float)(seed >> 8) / 16777216.0f;
		}
		const float *sl = slab[k % 13];
		pos[k] = (eddy_vec3){sl[0] + r[0] * (sl[1] - sl[0]), 0.02f + 0.12f * r[1], 0.02f + 0.12f * r[2]};
	}
	bar_check bc = {h, 0, 0, 0, NULL};
	add_bar_pipeline(w, 0.008f, h, &bc);
	eddy_collide_box_def bx = eddy_default_collide_box_def();
	bx.max = d.bounds_max;
	bx.sph_walls = false; /* a container only: the check sums fluid pairs */
	eddy_add_collide_box(w, &bx);
	CHECK(eddy_world_add_particles(w, N, pos, NULL) == EDDY_OK);
	free(pos);
	for (int f = 0; f < 4; ++f)
		CHECK(eddy_world_step_frame(w) == EDDY_OK);
	printf("    %d particles in 13 slabs, gaps of 1 to 12 cells: %d steps, up to %.0f neighbours, %d counts differ "
	       "from all pairs\n",
	       N, bc.steps, (double)bc.most, bc.mismatch);
	CHECK(bc.steps >= 4);
	CHECK(bc.most > 20);
	CHECK(bc.mismatch == 0);
	eddy_destroy_world(w);
}

static void neighbour_cells_hold_many_rows(void)
{
	for (int reversed = 0; reversed < 2; ++reversed) {
		eddy_world_def d = eddy_default_world_def();
		d.bounds_max = (eddy_vec3){11.2f, 0.3f, 0.3f};
		d.threads = 2;
		d.fps = 100;
		d.gravity = (eddy_vec3){20, 0, 0}; /* along the bar */
		eddy_world *w = eddy_create_world(&d, NULL, 0);
		/* cells of h/2, just under 4 spacings: 4 x 4 particles across one; h
		 * not a lattice distance (one of 8 spacings would make the count a
		 * coin toss of rounding) */
		const float s = 0.0025f, h = 0.0199f;
		enum { ALONG = 4375, N = ALONG * 16 };
		eddy_vec3 *pos = malloc(N * sizeof *pos);
		CHECK(pos != NULL);
		for (int k = 0; k < N; ++k) {
			const int q = reversed ? N - 1 - k : k, a = q / 16, b = q % 16;
			/* the cells start at bounds_min - h: y, z in 0.10125 .. 0.10875 stay in cell 12 */
			pos[k] = (eddy_vec3){0.05f + s * (float)a, 0.10125f + s * (float)(b % 4), 0.10125f + s * (float)(b / 4)};
		}
		bar_check bc = {h, 0, 0, 0, NULL};
		/* radius 4 spacings (sph_density's limit is 5); the bar is packed twice as dense */
		add_bar_pipeline(w, 2 * s, h, &bc);
		CHECK(eddy_world_add_particles(w, N, pos, NULL) == EDDY_OK);
		free(pos);
		for (int f = 0; f < 3; ++f)
			CHECK(eddy_world_step_frame(w) == EDDY_OK);
		printf("    %d particles in one row of cells, added %s cell order: %d steps, up to %.0f neighbours, %d counts "
		       "differ from all pairs\n",
		       N, reversed ? "against" : "in", bc.steps, (double)bc.most, bc.mismatch);
		CHECK(bc.steps >= 3);
		CHECK(bc.most > 200);
		CHECK(bc.mismatch == 0);
		eddy_destroy_world(w);
	}
}
