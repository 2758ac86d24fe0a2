/* SPDX-License-Identifier: MIT */
#define _POSIX_C_SOURCE 200809L
/* Stress: mode-1 sloshing (scenes/stress/slosh.lua) and the energy and
 * momentum the frame stats report.
 *
 * The slosh period must be within 3% of linear theory, omega^2 = g k
 * tanh(k d) (Lamb 1932, art. 227); the damping ratio (log decrement of the
 * wall elevation's peaks) is printed, and APIC's must not exceed FLIP 0.95's
 * by more than the measurement's scatter (see slosh_flip_apic). The fast
 * suite runs FLIP and APIC at the spacing where the period first comes
 * within 1% (3.125 mm, 8 particles per 6.25 mm cell, one cell thick); the
 * long suite runs all five methods (make test-long, suite_long_slosh). */
#include "test.h"

#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "eddy.h"

/* ---- the slosh scene ---------------------------------------------------- */

typedef struct slosh_result {
	double period_err, damping, peaks, wall_s;
	bool ok;
} slosh_result;

static slosh_result run_slosh(const char *method, const char *spacing, const char *thickness, double duration)
{
	slosh_result r = {NAN, NAN, NAN, NAN, false};
	char out[256], cmd[4096], buf[8192];
	snprintf(out, sizeof out, "%s/stress_slosh/%s_%s", test_build_dir(), method, spacing);
	snprintf(cmd, sizeof cmd,
	         "rm -rf %s && mkdir -p %s && %s/eddy run scenes/stress/slosh.lua --quiet --set render=false "
	         "--set method=%s --set spacing=%s --set thickness=%s --duration %g --out %s --stats %s/stats.jsonl",
	         out, out, test_build_dir(), method, spacing, thickness, duration, out, out);
	struct timespec t0, t1;
	clock_gettime(CLOCK_MONOTONIC, &t0);
	const int code = test_sh(cmd, buf, sizeof buf);
	clock_gettime(CLOCK_MONOTONIC, &t1);
	CHECKF(code == 0, "%s exited %d:\n%s", cmd, code, buf);
	r.wall_s = (double)(t1.tv_sec - t0.tv_sec) + 1e-9 * (double)(t1.tv_nsec - t0.tv_nsec);
	char path[600];
	snprintf(path, sizeof path, "%s/stats.jsonl", out);
	FILE *f = fopen(path, "r");
	CHECKF(f != NULL, "no stats at %s", path);
	if (!f)
		return r;
	static char line[65536], last[65536];
	last[0] = '\0';
	while (fgets(line, sizeof line, f))
		memcpy(last, line, sizeof last);
	fclose(f);
	r.period_err = test_json_number(last, "period_err");
	r.damping = test_json_number(last, "damping_ratio");
	r.peaks = test_json_number(last, "peaks");
	r.ok = code == 0;
	return r;
}

/* FLIP 0.95 and APIC at 3.125 mm, 3 s (3.4 periods, 6 peaks): the period
 * within 3% (measured: +0.2% for both); the damping ratios printed. The
 * measured ratios are small (0.000 to 0.005 FLIP, 0.005 to 0.007 APIC
 * since flip_p2g's marker is the particles' fill fraction; 0.04 each with a
 * binary marker, whose surface moved by whole cells): the damping comes from
 * the free surface's capture on the grid and the staircase start more than
 * from the transfer, so what is asserted is that FLIP does not gain
 * amplitude and APIC is not materially more dissipative than FLIP: within
 * 20% (the scatter between runs of different thickness) plus 0.006, twice
 * the resolution of zeta here (eta is read from the top particles, whose
 * heights step by particle layers: an error of a few % of A per peak over 5
 * half cycles is about 0.003 in zeta), not that it is less. On the
 * Taylor-Green vortex, where the transfer is all there is, APIC's effective
 * viscosity is below FLIP 0.95's (tests/test_flip.c). */
static void slosh_flip_apic(void)
{
	const slosh_result flip = run_slosh("flip", "0.003125", "2", 3.0);
	const slosh_result apic = run_slosh("apic", "0.003125", "2", 3.0);
	printf("    slosh L = 0.4 m, d = 0.1 m, A = 10 mm, spacing 3.125 mm, 3 s: period error FLIP %+.2f%%, APIC "
	       "%+.2f%%; damping ratio FLIP %.4f, APIC %.4f; wall %.1f s, %.1f s\n",
	       100 * flip.period_err, 100 * apic.period_err, flip.damping, apic.damping, flip.wall_s, apic.wall_s);
	CHECK(flip.ok && apic.ok);
	CHECK(flip.peaks >= 4 && apic.peaks >= 4);
	CHECK(fabs(flip.period_err) <= 0.03);
	CHECK(fabs(apic.period_err) <= 0.03);
	CHECK(flip.damping > -0.003 && flip.damping < 0.1); /* no growth beyond the resolution */
	CHECK(apic.damping > -0.003 && apic.damping <= 1.2 * fmax(flip.damping, 0) + 0.006);
}

/* APIC's g2p runs in parallel above 16384 particles (25600 here) and its
 * p2g is a serial scatter: the same bits for 1 and 2 threads. */
static void apic_thread_count_independent(void)
{
	char hash[2][32] = {"", ""};
	for (int t = 0; t < 2; ++t) {
		char out[256], cmd[1024], buf[4096];
		snprintf(out, sizeof out, "%s/stress_slosh/apic_threads%d", test_build_dir(), t + 1);
		snprintf(cmd, sizeof cmd,
		         "rm -rf %s && %s/eddy run scenes/stress/slosh.lua --quiet --set render=false --set method=apic "
		         "--set spacing=0.0025 --threads %d --frames 4 --out %s --stats - | tail -n 1",
		         out, test_build_dir(), t + 1, out);
		const int code = test_sh(cmd, buf, sizeof buf);
		CHECKF(code == 0, "%s exited %d:\n%s", cmd, code, buf);
		const char *h = strstr(buf, "\"state_hash\":\"");
		CHECKF(h != NULL, "no state_hash in: %s", buf);
		if (h)
			snprintf(hash[t], sizeof hash[t], "%.16s", h + 14);
		CHECK(strstr(buf, "\"particles\":25600") != NULL);
	}
	CHECKF(hash[0][0] && strcmp(hash[0], hash[1]) == 0, "1 thread %s, 2 threads %s", hash[0], hash[1]);
}

/* ---- energy and momentum in the frame stats ------------------------------ */

static eddy_world *world_with(double cell_size)
{
	eddy_world_def d = eddy_default_world_def();
	d.bounds_min = (eddy_vec3){-0.5f, -0.25f, 0};
	d.bounds_max = (eddy_vec3){0.5f, 0.75f, 0.2f};
	d.cell_size = cell_size;
	d.fps = 30;
	char err[256];
	eddy_world *w = eddy_create_world(&d, err, sizeof err);
	CHECKF(w != NULL, "create: %s", err);
	return w;
}

/* Sums over the particles as the stats define them, for comparison. */
static void sums(eddy_world *w, double gy, double lo_y, double *ke, double *pe, double p[3])
{
	size_t n;
	const float *y = eddy_world_channel(w, "y", &n);
	const float *vx = eddy_world_channel(w, "vx", NULL), *vy = eddy_world_channel(w, "vy", NULL),
				*vz = eddy_world_channel(w, "vz", NULL);
	*ke = *pe = p[0] = p[1] = p[2] = 0;
	for (size_t i = 0; i < n; ++i) {
		*ke += 0.5 * ((double)vx[i] * vx[i] + (double)vy[i] * vy[i] + (double)vz[i] * vz[i]);
		*pe -= gy * ((double)y[i] - lo_y);
		p[0] += vx[i], p[1] += vy[i], p[2] += vz[i];
	}
}

/* FLIP: m = flip_pressure's density (non-default here) times the emitter's
 * spacing cubed; the potential uses the gravity system's scale and the
 * bounds' minimum; PIC keeps the momentum of a free block exactly. */
static void energy_stats_flip(void)
{
	eddy_world *w = world_with(0.05);
	eddy_emit_box_def b = eddy_default_emit_box_def();
	b.min = (eddy_vec3){-0.2f, 0, 0};
	b.max = (eddy_vec3){0.2f, 0.2f, 0.2f};
	b.spacing = 0.025f;
	b.velocity = (eddy_vec3){0.5f, 0, 0};
	eddy_add_emit_box(w, &b);
	eddy_gravity_def g = eddy_default_gravity_def();
	g.scale = 0.5f;
	eddy_add_gravity(w, &g);
	eddy_flip_p2g_def p2g = eddy_default_flip_p2g_def();
	eddy_add_flip_p2g(w, &p2g);
	eddy_flip_boundary_def bd = eddy_default_flip_boundary_def();
	eddy_add_flip_boundary(w, &bd);
	eddy_flip_surface_def sf = eddy_default_flip_surface_def();
	eddy_add_flip_surface(w, &sf);
	eddy_flip_pressure_def pr = eddy_default_flip_pressure_def();
	pr.density = 500;
	eddy_add_flip_pressure(w, &pr);
	eddy_flip_extrapolate_def ex = eddy_default_flip_extrapolate_def();
	eddy_add_flip_extrapolate(w, &ex);
	eddy_flip_g2p_def gp = eddy_default_flip_g2p_def();
	gp.transfer = EDDY_FLIP_TRANSFER_APIC;
	eddy_add_flip_g2p(w, &gp);
	eddy_flip_advect_def ad = eddy_default_flip_advect_def();
	eddy_add_flip_advect(w, &ad);
	CHECK(eddy_world_step_frame(w) == EDDY_OK);
	eddy_frame_stats fs;
	eddy_world_frame_stats(w, &fs);
	const double m = 500 * 0.025 * 0.025 * 0.025;
	CHECK_NEAR(fs.particle_mass, m, 1e-6 * m); /* the spacing is a float */
	double ke, pe, p[3];
	sums(w, 0.5 * -9.81, -0.25, &ke, &pe, p);
	CHECK_NEAR(fs.kinetic_energy, m * ke, 1e-6 * m * ke);
	CHECK_NEAR(fs.potential_energy, m * pe, 1e-5 * m * pe);
	CHECK(pe > 0);
	CHECK_NEAR(fs.momentum[0], m * p[0], 1e-6 * fabs(m * p[0]));
	CHECK_NEAR(fs.momentum[1], m * p[1], 1e-6 * fabs(m * p[1]));
	CHECK(isnan(fs.compression_energy));
	CHECK_NEAR(fs.energy, fs.kinetic_energy + fs.potential_energy, 1e-12);
	eddy_destroy_world(w);

	/* particles added without an emitter: no spacing, so no mass, no values */
	w = world_with(0.05);
	eddy_add_flip_p2g(w, &p2g);
	eddy_add_flip_boundary(w, &bd);
	eddy_add_flip_surface(w, &sf);
	eddy_add_flip_pressure(w, &pr);
	eddy_add_flip_extrapolate(w, &ex);
	eddy_add_flip_g2p(w, &gp);
	eddy_add_flip_advect(w, &ad);
	const eddy_vec3 pos = {0, 0, 0.1f}, vel = {1, 0, 0};
	CHECK(eddy_world_add_particles(w, 1, &pos, &vel) == EDDY_OK);
	CHECK(eddy_world_step_frame(w) == EDDY_OK);
	eddy_world_frame_stats(w, &fs);
	CHECK(isnan(fs.particle_mass) && isnan(fs.kinetic_energy) && isnan(fs.energy) && isnan(fs.momentum[0]));
	eddy_destroy_world(w);
}

/* WCSPH: the calibrated mass, and a compression energy that is >= 0, 0 for
 * a particle at or below rho0, and is the EOS integral for the linear EOS. */
static void energy_stats_wcsph(void)
{
	eddy_world *w = world_with(0);
	eddy_emit_box_def b = eddy_default_emit_box_def();
	b.min = (eddy_vec3){-0.1f, -0.25f, 0};
	b.max = (eddy_vec3){0.1f, 0, 0.2f};
	b.spacing = 0.02f;
	eddy_add_emit_box(w, &b);
	eddy_sph_density_def sd = eddy_default_sph_density_def();
	sd.spacing = 0.02f;
	sd.radius = 0.04f;
	eddy_system_id dens = eddy_add_sph_density(w, &sd);
	eddy_sph_pressure_def sp = eddy_default_sph_pressure_def();
	eddy_add_sph_pressure(w, &sp);
	eddy_gravity_def g = eddy_default_gravity_def();
	eddy_add_gravity(w, &g);
	eddy_integrate_def it = eddy_default_integrate_def();
	eddy_add_integrate(w, &it);
	eddy_collide_box_def cb = eddy_default_collide_box_def();
	cb.min = (eddy_vec3){-0.5f, -0.25f, 0};
	cb.max = (eddy_vec3){0.5f, 0.75f, 0.2f};
	cb.inside = true;
	eddy_add_collide_box(w, &cb);
	for (int f = 0; f < 3; ++f)
		CHECK(eddy_world_step_frame(w) == EDDY_OK);
	eddy_frame_stats fs;
	eddy_world_frame_stats(w, &fs);
	const double m = eddy_sph_particle_mass(w, dens);
	CHECK_NEAR(fs.particle_mass, m, 1e-6 * m);
	size_t n;
	const float *rho = eddy_world_channel(w, "density", &n);
	double ce = 0;
	const double c = eddy_sph_sound_speed(w, dens), k = c * c; /* the stiffness chosen from the scene */
	const double r0 = sd.rest_density;
	for (size_t i = 0; i < n; ++i) {
		const double r = rho[i];
		if (r > r0)
			ce += m * k * (log(r / r0) + r0 / r - 1);
	}
	CHECK(fs.compression_energy >= 0);
	CHECK_NEAR(fs.compression_energy, ce, 1e-6 * (ce + 1e-12));
	CHECK_NEAR(fs.energy, fs.kinetic_energy + fs.potential_energy + fs.compression_energy, 1e-9);
	printf("    WCSPH block after 0.1 s: kinetic %.4g J, potential %.4g J, compression %.4g J\n", fs.kinetic_energy,
	       fs.potential_energy, fs.compression_energy);
	eddy_destroy_world(w);
}

/* Long: the five methods (make test-long, about 5 minutes). FLIP 0.95, PIC
 * and APIC at 2.5 mm (5 mm cells, 20 cells deep), WCSPH and
 * DFSPH at 5 mm (WCSPH alone is 3-4 minutes there: 8000 acoustic steps).
 * Measured (this test, the period from the second zero crossing on over
 * whole periods, 3 s): period error FLIP +0.07%, PIC +0.27%, APIC -0.61%,
 * WCSPH -3.40%, DFSPH -2.90% (5 mm) and -2.29% (10 mm); counting the odd
 * half period at the end, as the scene did before 2026-11-28: FLIP
 * +0.04%, PIC +0.47%, APIC -0.47%, WCSPH -3.87%, DFSPH -2.62%. Earlier
 * (scenes/studies/sloshing.lua, from the first crossing): FLIP +1.1%,
 * PIC +1.9%, APIC +0.9%, WCSPH -1.1%. Damping ratio (this test): FLIP
 * -0.0009, PIC 0.0036, APIC 0.0040, WCSPH 0.056. DFSPH runs at 10 mm too (10 layers deep) and is held
 * to what the issue asks of it: its damping must not grow as the spacing
 * halves (it did: -0.024 with a +4.3% period error, the slosh gaining
 * energy) and must be positive, each within 0.003 (zeta's resolution here,
 * see slosh_flip_apic), and the 5 mm period within 3%. Measured with the
 * conjugate-gradient solves (src/sph/dfsph.c): zeta 0.0423 at 10 mm and
 * 0.0393 at 5 mm without particle shifting; with shift = 0.02 (sph_dfsph's
 * default, which these runs use; the walls' neighbours shifted along the
 * walls only) 0.0456 and 0.0374, period error -2.0% and -2.5%. Shifting is
 * a diffusion of the particle positions and can damp the wave (shifting
 * across the walls too read 0.050-0.057 and 0.055): each zeta is held to 1.2 times its value without
 * shifting, the 20% that the scatter of zeta over cfl 0.36-0.44 at 10 mm
 * (0.042-0.048 without shifting) leaves room for. */
static void slosh_all_methods(void)
{
	const slosh_result flip = run_slosh("flip", "0.0025", "4", 3.0);
	const slosh_result pic = run_slosh("pic", "0.0025", "4", 3.0);
	const slosh_result apic = run_slosh("apic", "0.0025", "4", 3.0);
	const slosh_result wcsph = run_slosh("wcsph", "0.005", "4", 3.0);
	const slosh_result dfsph = run_slosh("dfsph", "0.005", "4", 3.0);
	const slosh_result dfsph10 = run_slosh("dfsph", "0.01", "4", 3.0);
	const slosh_result wcsph_thick = run_slosh("wcsph", "0.01", "16", 3.0);
	const struct {
		const char *name;
		const slosh_result *r;
	} rows[] = {{"FLIP 0.95 2.5 mm", &flip},
	            {"PIC 2.5 mm", &pic},
	            {"APIC 2.5 mm", &apic},
	            {"WCSPH 5 mm", &wcsph},
	            {"DFSPH 5 mm", &dfsph},
	            {"DFSPH 10 mm", &dfsph10},
	            {"WCSPH 10 mm, 16 thick", &wcsph_thick}};
	for (size_t i = 0; i < sizeof rows / sizeof rows[0]; ++i)
		printf("    slosh %-22s period error %+6.2f%%, damping ratio %.4f, %.0f peaks, wall %.1f s\n", rows[i].name,
		       100 * rows[i].r->period_err, rows[i].r->damping, rows[i].r->peaks, rows[i].r->wall_s);
	CHECK(flip.ok && pic.ok && apic.ok && wcsph.ok && dfsph.ok && dfsph10.ok && wcsph_thick.ok);
	CHECK(fabs(dfsph.period_err) <= 0.03);
	CHECK(dfsph10.damping > -0.003 && dfsph.damping > -0.003);
	CHECK(dfsph.damping <= dfsph10.damping + 0.003);
	CHECK(dfsph.damping < 1.2 * 0.0393 && dfsph10.damping < 1.2 * 0.0423);
	CHECK(fabs(flip.period_err) <= 0.03);
	CHECK(fabs(pic.period_err) <= 0.03);
	CHECK(fabs(apic.period_err) <= 0.03);
	/* WCSPH at 5 mm reads -3.9% from the second crossing on: short of the
	 * 3% the other methods meet, and of issue 13's target (open). The cause,
	 * measured (2.2-3 s runs): the walls' pressure force along the wall.
	 * Neither the amplitude (-3.9% at 5 mm), the resolution (about -4% at
	 * 10 mm spacing, a damped-sine fit) nor c (k x 4: -3.6%) moves it; the
	 * tank twice as thick (8 spacings, not 4) halves it (-2.0%): it goes
	 * with the wall area per volume. A wall particle's force has a part
	 * along the wall, which holds the fluid lattice beside it in the wall
	 * lattice's pockets: a shear stiffness that raises the frequency and,
	 * slipping, damps. With the box walls' force taken along their normals
	 * only, the period is +0.4% at 5 mm (+0.6% at 10 mm) and zeta 0.010
	 * (0.024), but still water loses the hold the walls gave its lattice:
	 * 10 layers ring up to 0.69 sqrt(g D). 5% holds the period where it is,
	 * so a change that moves the wave further from linear theory fails.
	 * Linear theory's wave is two-dimensional (no side walls): in a tank
	 * thick enough that the side walls do not reach every particle the
	 * WCSPH wave has the period, as the grid methods': 16 spacings thick,
	 * -0.46% at 10 mm over whole periods (10 particles per depth, held to
	 * the 3% here; -1.63% counting the odd half period at the end, as the
	 * scene did before) and -0.46% at 5 mm (odd count); 8 thick, -2.37% at
	 * 5 mm. So the thin tank's -3.4% (whole periods; -3.9% odd) is the side
	 * walls' stiffness (README, Stress cases), a limit for water in a
	 * channel a few spacings wide, not the wave's. */
	CHECK(fabs(wcsph.period_err) <= 0.05);
	CHECK(fabs(wcsph_thick.period_err) <= 0.03);
	/* The grid methods conserve the wave's volume since the fill-fraction
	 * marker (flip_p2g): all three measure a damping ratio within a few
	 * resolutions (about 0.003, the fast test's) of water's 0.001, PIC no
	 * longer clearly above APIC. None may grow, and none may damp like the
	 * SPH methods (0.03-0.06). */
	CHECK(flip.damping > -0.003 && flip.damping < 0.01);
	CHECK(pic.damping > -0.003 && pic.damping < 0.01);
	CHECK(apic.damping > -0.003 && apic.damping < 0.01);
}

void suite_long_slosh(void) { RUN(slosh_all_methods); }

void suite_stress_slosh(void)
{
	RUN(energy_stats_flip);
	RUN(energy_stats_wcsph);
	RUN(apic_thread_count_independent);
	RUN(slosh_flip_apic);
}
