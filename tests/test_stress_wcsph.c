/* SPDX-License-Identifier: MIT */
/* Stress tests of weakly compressible SPH (sph_pressure) one step beyond the
 * validated scenes: still water 10, 20 and 40 layers deep in a closed box
 * (scenes/stress/still_water.lua --set solver=wcsph), run through the command
 * line with per-frame stats, at the scene's defaults (stiffness k = 100 g D,
 * Monaghan alpha 0.05, water's viscosity).
 *
 * The scale the bounds come from: with k = 100 g D the Mach number of
 * gravity-wave speeds is M = sqrt(g D) / c = 0.1, and a column that is not in
 * equilibrium rings in its acoustic mode (period 4 D / c) at speeds up to
 * M sqrt(g D) = 0.1 sqrt(g D). "At rest" is held to 0.06 sqrt(g D) from 2 s
 * on, under that scale (measured 0.029, 0.039, 0.046 at 10, 20, 40 layers; before the
 * walls' density was iterated within the step, 0.52 and 0.57: the one-step
 * lag pumped the column up to half the gravity-wave speed). The bottom
 * pressure is the weight above, averaged over the frames from 2 s on, within
 * 5% ("a few %": measured +2.1%, +3.4%, +3.0% at 10, 20, 40 layers; the
 * pressure force's lattice calibration leaves +0.6% in the hydrostatic tank,
 * and a mean of 30 frames a second keeps a residue of the ringing below,
 * whose amplitude is up to 0.35 rho0 g D).
 *
 * The bottom pressure still rings around that mean, in the column's
 * fundamental acoustic mode (period 4 D / c = 0.064 s at 20 layers, measured
 * 0.066 s): max - min of the frames in [2, 2.5) and [2.5, 3] s, relative to
 * rho0 g D, is 0.34 then 0.10 at 10 layers (it dies out by 5 s), 0.74 then
 * 0.45 at 20 and 0.63 then 0.57 at 40 (at 20 and 40 it beats between 0.2
 * and 0.8 to 6 s without decaying). It is printed per half second, not
 * asserted (open, README "WCSPH still water rings"). The column starts at
 * rho0 and settles by g D / k, which excites the mode at about rho0 g D, but
 * the mode is also fed: started hydrostatically compressed, 20 layers ring
 * at 0.2 and grow to 0.45 by 2-3 s, 10 layers from 0.35 to 1.8. From the
 * cold start the ringing grows with alpha (at 20 layers 0.46 then 0.11 by
 * 4 s at alpha 0.02, about 1.7 at 0.2): the artificial term is one-sided at a wall, and the walls' pressure force,
 * not the gradient of an energy, need not return the work it does on the
 * layer beside the wall as dissipation. Nothing else would damp a wave that
 * long (Monaghan's term acts like nu ~ alpha c h / 10: a damping ratio near
 * 1e-3 at alpha 0.05, where decaying to 5% within 2 s needs 0.012 at 10
 * layers and 0.023 at 40).
 *
 * These figures are one sample of a chaotic motion, not a margin: the same
 * runs at cfl 0.48 and 0.52 (the scene's is 0.5) read vmax 0.075 and 0.163
 * at 10 layers, 0.066 and 0.061 at 20, 0.085 and 0.082 at 40 (whose bottom
 * p mean reads 1.051 at 0.48), against the 0.06 held here, and the ringing
 * 0.05-1.26 rho0 g D; at cfl 0.25 and 0.3, 0.019 and 0.030 at 10
 * layers but 0.068 and 0.091 at 20 (so not a time-step error). A change
 * near 1e-3 of the walls' density (WALL_TOL 1e-3 -> 5e-4 in sph_density)
 * moves 10 layers from 0.029 to 0.018 and 20 from 0.041 to 0.060. A change
 * to the walls or the pressure therefore has to be judged over such a
 * spread (several cfl values, depths), not by one run passing. 100 layers
 * (depth 1.25) at cfl 0.5: 14 particles thrown (from 0.23 s on), vmax 0.14
 * from 2 s, bottom p mean 1.023, ringing 0.71 then 0.73 (not run here: it
 * fails the bounds; issue 13).
 *
 * Where the energy comes from (scenes/stress/wcsph_energy.lua, viscosity and
 * alpha 0, energy_budget_* below): not the integrator (the same rise at cfl
 * 0.5, 0.25 and 0.125), but two terms that are not the gradient of an
 * energy. The bulk pair (poly6 density, spiky-gradient force): two free
 * blocks meeting at +-0.2 m/s gain 104% of their energy; with the density
 * and the force from one kernel, the force the exact gradient of
 * sum m e(rho) (Wendland C2, p_i/rho_i^2 + p_j/rho_j^2), they keep it to
 * 0.08%. The walls' extrapolated pressure (Adami's p_b, iterated or not):
 * with that consistent bulk pair and the walls a fixed rho0 term in the
 * density sum (Akinci 2012, force -p_i/rho_i^2 sum V_b rho0 grad W) the
 * inviscid 20-layer column keeps its energy (-3e-4 J of 3.04 J over 2 s at
 * cfl 0.25) but its bottom layer holds twice the hydrostatic pressure (the
 * wall term's one-sided p_i/rho_i^2: bottom p 2.15 at 10 layers); with
 * Adami's p_b in the wall pair it blows up again, from the bottom corners.
 * (Scalar experiments on branch energy12-wendland-experiment, E12_WEND=1
 * and 2.)
 *
 * Tried next (issue 13, branch wall13-experiment, measured at d9c8d9f + that
 * branch): the cubic spline (M4, support h) for the density and the force,
 * whose lattice gradient moment over its lattice sum is 1.02 at h = 2 spacings
 * (Wendland C2 0.95, poly6 1.05), so the force needs no calibration and stays
 * the exact gradient; and each wall particle b an energy rho0 V_b S_b
 * e(rho^_b), rho^_b = m sum_f W_bf (1 + g . (x_b - x_f) / k) / S_b, S_b = 1 -
 * sum_b' V_b' W_bb' (the fluid's share of the partition of unity at b: 0.15 at
 * a flat wall's first layer). The weight S_b is needed: weighted rho0 V_b
 * alone (the first proposal) the wall's pair term is p^_b / S_b, 6.7 times the
 * mirror of the fluid's. Still water then comes to rest: vmax from 2 s 0.009,
 * 0.020, 0.031, 0.044 sqrt(g D) at 10, 20, 40, 100 layers (cfl 0.5, scalar
 * loops at d12ad5b; the branch's SIMD sums round differently and read 0.021,
 * 0.022, 0.026 at 10-40 layers, bottom p 1.005, 1.027, 1.019), 0.008-0.031 at
 * cfl 0.25, 0.48, 0.52 for 10-40 layers (0.035, 0.027 at 100 layers at 0.48,
 * 0.52), nothing thrown, bottom p 1.00-1.03, ringing 0.008, 0.08, 0.35, 0.38
 * then 0.001, 0.02, 0.27, 0.25 rho0 g D; the inviscid 20-layer column keeps
 * its energy (at most +0.17% of E0 = 3.03 J over 2 s at cfl 0.5, +0.13% at
 * 0.25). Not taken, because the wall reads the fluid's density from the tail
 * of the kernel divided by S_b, 1/S_b times as sensitive to the fluid-wall gap
 * as a fluid particle is to its neighbours: the column thrown onto the floor
 * gains 4.1% at cfl 0.5 (0.4% at 0.45, 0.2% at 0.4, none at 0.25: a time-step
 * error, the wall mode stiffer than the bulk's), the Martin & Moyce column at
 * a/5 (0.02 m, a slab 4 particles thick) is thrown apart at the start (4.2 m/s
 * by 5 ms against 0.8 m/s now; the quick study's error 2.77 against its bound
 * 0.6), and, with no wall involved, the oscillating drop rings 16-20% below
 * Rayleigh (five runs) against 9.4% now, past its 15% bound: the same with
 * poly6's exact gradient or the (p_i + p_j) / (rho_i rho_j) pair on the
 * cubic's gradient, so the suspect is the smooth kernels' gradient (spiky's
 * does not vanish at r = 0) under the colour-field tension, not the pair form.
 * A flatter kernel in the wall term ((1 - q^2)^2) cuts the impact's gain to
 * 0.7% but lets the bottom pressure fall to 0.79. The slosh (5 mm, 3 s) reads
 * a period 6.4% short and a damping ratio of 0.074 (now 3.9% and 0.056). What
 * remains: a wall energy whose pressure follows the fluid's pressure (as
 * Adami's average does) rather than the gap, or a time-step limit for the wall
 * mode; and a pair that keeps the drop.
 *
 * Free-slip walls (issue 13, branch slip14-experiment, at 01680a5; 10 layers,
 * vmax from 2 s at cfl 0.48/0.50/0.52, against 0.075/0.029/0.163 now). The
 * walls' force along their normals only: 2.74/0.69/0.98, and a tank 0.4 m
 * wide reads 2.03 (0.040 with today's walls), so the hold is not a narrow
 * column's. Nor is it the wall lattice's corrugation: the normal force from
 * tangentially averaged wall sheets (per layer 2 pi z (h - z)^3 / 3 V_b / A)
 * reads 3.01/0.98/0.86, walls sampled at half the spacing (corrugation of
 * their density 5e-5) 0.71/0.46/0.66. Keeping along the wall the pressure's
 * difference, V_b (p_b - p_i) grad_t W, and dropping 2 p_i sum V_b grad_t W
 * (zero on a smooth wall, the wall lattice's pockets otherwise) gives the
 * aligned still lattice today's forces and the slosh its period (10 mm:
 * +0.03%, zeta 0.040, against -5.6% and 0.113 now; 5 mm: -2.6%, 0.031), but
 * still water reads 0.15/0.70/0.70, 0.15 at 20 layers and throws 162
 * particles at 40; with Monaghan's alpha 0.2 or 0.5, 0.11-0.13 at every cfl;
 * keeping a quarter or half of the 2 p_i term, 0.48-0.57 or 0.15-1.02.
 * Particle shifting (Lind et al. 2012, dr = -D h^2 grad C each step, D
 * 0.002-0.1, interior only as sph_dfsph's or also along the walls) holds none
 * of these (0.2-3). The fastest particles sit at the side walls near the free
 * surface, 0.1-0.3 spacing from the face, or in the vertical edges: where the
 * pressure, and with it the walls' push p_i + p_b, is near 0. A wall
 * background pressure p_w = rho0 |g| h added to the normal term settles
 * them: the ringing falls to 0.003-0.03 rho0 g D at 10 and 20 layers
 * (vmax 0.063/0.042/0.028 and 0.076/0.050/0.044, bottom p 0.95 and 0.97, the
 * floor holding the bottom layer up), but 40 layers read 0.11/0.31/0.11 (with
 * shifting D = 0.02 0.068/0.080/0.066, 100 layers 3.1, while 10 and 20 layers
 * rise to 0.14-0.17 and 0.08-0.10: a shift moves particles out of the
 * pressure's balance, which a weakly compressible fluid answers with sound,
 * where sph_dfsph's solve absorbs it) and the slosh period
 * goes back to -3.9% at 10 mm (p_w / 2: -3.1%; as a floor max(p_i + p_b,
 * p_w): -2.0% but still water 0.10; only beyond the still lattice's wall
 * sum: 0.19-0.23). Whatever holds the fluid at the side walls near the
 * surface stiffens the slosh there.
 *
 * Particle shifting with today's walls (issue 13, branch wshift16-experiment,
 * at c8b0844; sph_dfsph's rule: x_i -= shift h^2 grad C_i where i and its
 * neighbours have kernel sums >= 0.95 rho0 and no wall is within h; vmax
 * from 2 s at cfl 0.45/0.48/0.50/0.52/0.55). Shift 0 (now): 0.043/0.075/
 * 0.029/0.163/0.083 at 10 layers, 0.060/0.066/0.041/0.061/0.048 at 20,
 * 0.063/0.085/0.047/0.082/0.188 at 40. Shift 0.02: 0.19/0.17/0.16/0.79/0.18,
 * 0.12/0.14/0.11/0.10/0.10, 0.068/0.088/0.078/0.087/0.081; shift 0.01 and
 * 0.05 alike (10 layers 0.15-0.19, 20 layers 0.11-0.15, 40 layers 0.065-0.14),
 * 0.005 0.10-0.12 at 10 layers. The spread over the step becomes a steady
 * motion at the free surface (the fastest particle at 0.8-1.0 D; at 10
 * layers 10x the kinetic energy; at cfl 0.25 0.17 against 0.019, 20 layers
 * 0.12 against 0.068). 100 layers: nothing thrown (14 without)
 * but 0.12 sqrt(g D). A gate at 0.99 rho0, a weight ramping from the gate
 * over 0.03 rho0, or shifting beside the walls (their volumes in grad C):
 * 0.10-0.63 at 10 layers. Slosh with shift 0.02: 10 mm -3.4%, zeta 0.076;
 * 5 mm -4.6%, 0.063 (now -5.6%, 0.113 and -3.9%, 0.056). Not taken (README,
 * "WCSPH still water's pass depends on the exact step"). */
#include "test.h"

#include <stdlib.h>
#include <string.h>

/* Figures of a still-water run from t_settle on (thrown and failures over
 * the whole run). */
typedef struct still_water {
	int status, frames;
	double vmax_ratio, bp_min, bp_max, bp_mean; /* from t_settle */
	double half_min[2], half_max[2];            /* over [t_settle, +0.5 s) and from t_settle + 0.5 s */
	double thrown, leaked, nonfinite;           /* the whole run */
} still_water;

static still_water run_still_water_scene(const char *scene, const char *sets, double t_settle)
{
	still_water r = {0, 0, 0, INFINITY, -INFINITY, 0, {INFINITY, INFINITY}, {-INFINITY, -INFINITY}, 0, 0, 0};
	int settled = 0;
	enum { CAP = 1 << 20 };
	char *out = malloc(CAP), cmd[1024];
	if (!out) {
		r.status = -1;
		return r;
	}
	snprintf(cmd, sizeof cmd,
	         "%s/eddy run %s --set solver=wcsph %s --stats - --quiet --threads 1 --out %s/stress_still_water_wcsph",
	         test_build_dir(), scene, sets, test_build_dir());
	r.status = test_sh(cmd, out, CAP);
	for (char *line = out; line && *line;) {
		char *next = strchr(line, '\n');
		if (next)
			*next++ = '\0';
		const double t = test_json_number(line, "time");
		if (isfinite(t)) {
			r.frames++;
			r.thrown = fmax(r.thrown, test_json_number(line, "thrown"));
			r.leaked = fmax(r.leaked, test_json_number(line, "leaked"));
			r.nonfinite = fmax(r.nonfinite, test_json_number(line, "nonfinite"));
			if (t >= t_settle - 1e-9) {
				const double bp = test_json_number(line, "bottom_p_ratio");
				r.vmax_ratio = fmax(r.vmax_ratio, test_json_number(line, "vmax_ratio"));
				r.bp_min = fmin(r.bp_min, bp);
				r.bp_max = fmax(r.bp_max, bp);
				r.bp_mean += bp;
				settled++;
				const int half = t >= t_settle + 0.5 - 1e-9;
				r.half_min[half] = fmin(r.half_min[half], bp);
				r.half_max[half] = fmax(r.half_max[half], bp);
			}
		}
		line = next;
	}
	r.bp_mean = settled ? r.bp_mean / settled : NAN;
	if (r.status != 0)
		printf("    eddy run %s: exit %d: %.300s\n", sets, r.status, out);
	free(out);
	return r;
}

static still_water run_still_water(const char *sets, double t_settle)
{
	return run_still_water_scene("scenes/stress/still_water.lua", sets, t_settle);
}

/* The same scene with sph_density's density = continuity (through
 * tests/scenes/continuity.lua, which sets it on the scene's sph_density). */
static still_water run_still_water_continuity(const char *sets, double t_settle)
{
	return run_still_water_scene("tests/scenes/continuity.lua --set scene=scenes/stress/still_water.lua", sets,
	                             t_settle);
}

/* One depth, 3 s, judged from 2 s on. */
static void still_water_at_rest(const char *depth, int layers)
{
	char sets[128];
	snprintf(sets, sizeof sets, "--set depth=%s --set duration=3", depth);
	const still_water r = run_still_water(sets, 2.0);
	printf(
		"    WCSPH still water %d layers, t >= 2 s: vmax <= %.4f sqrt(g H) (held to 0.06), bottom p mean %.3f x rho0 "
		"g H (held to 0.95-1.05), range %.3f-%.3f, ringing (max - min) %.3f then %.3f per half second (open: not "
		"asserted), thrown %g\n",
		layers, r.vmax_ratio, r.bp_mean, r.bp_min, r.bp_max, r.half_max[0] - r.half_min[0],
		r.half_max[1] - r.half_min[1], r.thrown);
	CHECK(r.status == 0);
	CHECK(r.frames == 90);
	CHECK(r.thrown == 0);
	CHECK(r.leaked == 0 && r.nonfinite == 0);
	CHECK(r.vmax_ratio < 0.06);
	CHECK(fabs(r.bp_mean - 1) < 0.05);
}

/* 10 layers at cfl 0.45, 0.48, 0.52 and 0.55 besides the scene's 0.5:
 * the step spread (header). Held at each: nothing thrown and the mean
 * bottom pressure within 5% of the weight above (measured 1.007-1.021);
 * the max speed is printed, not asserted (0.043, 0.075, 0.163, 0.083
 * against 0.06: open, README). */
static void still_water_10_layers_step_spread(void)
{
	static const char *const cfl[] = {"0.45", "0.48", "0.52", "0.55"};
	for (int c = 0; c < 4; ++c) {
		char sets[128];
		snprintf(sets, sizeof sets, "--set depth=0.125 --set duration=3 --set cfl=%s", cfl[c]);
		const still_water r = run_still_water(sets, 2.0);
		printf("    WCSPH still water 10 layers, cfl %s, t >= 2 s: vmax %.4f sqrt(g H) (open: not asserted), bottom p "
		       "mean %.3f x rho0 g H (held to 0.95-1.05), thrown %g\n",
		       cfl[c], r.vmax_ratio, r.bp_mean, r.thrown);
		CHECK(r.status == 0);
		CHECK(r.frames == 90);
		CHECK(r.thrown == 0);
		CHECK(r.leaked == 0 && r.nonfinite == 0);
		CHECK(fabs(r.bp_mean - 1) < 0.05);
	}
}

/* 10 layers (0.125 m, 640 particles): a few seconds. */
static void still_water_10_layers_at_rest(void) { still_water_at_rest("0.125", 10); }

/* 20 layers (0.25 m, 1280 particles) and 40 (0.5 m, 2560): long. */
static void still_water_20_layers_at_rest(void) { still_water_at_rest("0.25", 20); }

static void still_water_40_layers_at_rest(void) { still_water_at_rest("0.5", 40); }

/* The energy (kinetic + potential + compression, the frame stats') of a
 * wcsph_energy.lua case, inviscid: its first frame's, the largest rise above
 * that up to t_end and at the last frame. */
typedef struct energy_run {
	int status, frames;
	double e0, rise, last, vmax;
} energy_run;

static energy_run run_energy(const char *sets, double t_end)
{
	energy_run r = {0, 0, NAN, -INFINITY, NAN, 0};
	enum { CAP = 1 << 20 };
	char *out = malloc(CAP), cmd[1024];
	if (!out) {
		r.status = -1;
		return r;
	}
	snprintf(cmd, sizeof cmd,
	         "%s/eddy run scenes/stress/wcsph_energy.lua %s --stats - --quiet --threads 1 --out %s/stress_wcsph_energy",
	         test_build_dir(), sets, test_build_dir());
	r.status = test_sh(cmd, out, CAP);
	for (char *line = out; line && *line;) {
		char *next = strchr(line, '\n');
		if (next)
			*next++ = '\0';
		const double t = test_json_number(line, "time"), e = test_json_number(line, "energy");
		if (isfinite(t) && t <= t_end + 1e-9) {
			if (r.frames++ == 0)
				r.e0 = e;
			r.rise = fmax(r.rise, e - r.e0);
			r.last = e;
			r.vmax = fmax(r.vmax, test_json_number(line, "vmax"));
		}
		line = next;
	}
	if (r.status != 0)
		printf("    eddy run %s: exit %d: %.300s\n", sets, r.status, out);
	free(out);
	return r;
}

/* WCSPH's energy budget with the viscosity and Monaghan's alpha at 0: a
 * conservative force integrated by symplectic Euler keeps the energy to
 * O(dt^2), with no secular rise. Held: the column thrown onto the floor at
 * 0.2 m/s (case walls: it meets the floor at 0.125 s and leaves it by
 * 0.3 s) gains nothing: the energy never rises above its first frame's by
 * more than 1% of it (measured +0.03%; the contact loses 1.6%, through the
 * collider). The check can fail: with the walls' pressure taken equal to
 * the fluid's (p_b = p_i in sph_pressure's wall term) the same impact gains
 * 0.1 J (2 x E0) by 0.2 s and 8.8 J by 0.5 s. Printed, not asserted (open, issue 13; measured at
 * 5eb19ff, cfl 0.5): the same column meeting the lid at 0.6 s gains 90 x
 * its energy by 1 s and the fastest particle reaches 5.8 m/s; two free
 * blocks meeting at +-0.2 m/s (no walls) gain 104% of their energy, the
 * same at cfl 0.25, so not the integrator; the still column (gravity,
 * case column, E0 3.04 J) gains 9 J by 1 s at cfl 0.5 and 0.25 alike, with
 * or without the walls' iteration. */
static void energy_budget_floor(void)
{
	const energy_run fl = run_energy("--set case=walls --set duration=0.5", 0.5);
	printf("    WCSPH inviscid column thrown onto the floor at 0.2 m/s, t <= 0.5 s: E0 %.4g J, largest rise %+.3g "
	       "(held to 1%% of E0), last %+.3g\n",
	       fl.e0, fl.rise / fl.e0, (fl.last - fl.e0) / fl.e0);
	CHECK(fl.status == 0);
	CHECK(fl.frames == 15);
	CHECK(fl.rise < 0.01 * fl.e0);
}

/* The open part of the budget (above): slow, as the runs blow up and the
 * force limit shortens the step. */
static void energy_budget_open(void)
{
	const energy_run lid = run_energy("--set case=walls --set duration=1", 1.0);
	const energy_run bl = run_energy("--set case=blocks --set duration=1", 1.0);
	const energy_run col = run_energy("--set case=column --set duration=1", 1.0);
	const energy_run col4 = run_energy("--set case=column --set duration=1 --set cfl=0.25", 1.0);
	printf("    open (not asserted): energy rise by 1 s relative to E0: column meeting the lid %+.3g (vmax %.3g m/s), "
	       "two free blocks %+.3g, still column with gravity %+.3g at cfl 0.5, %+.3g at 0.25 (vmax %.3g, %.3g m/s)\n",
	       (lid.last - lid.e0) / lid.e0, lid.vmax, (bl.last - bl.e0) / bl.e0, (col.last - col.e0) / col.e0,
	       (col4.last - col4.e0) / col4.e0, col.vmax, col4.vmax);
	CHECK(lid.status == 0 && bl.status == 0 && col.status == 0 && col4.status == 0);
}

/* The continuity density (sph_density's density = continuity: delta-SPH
 * with the hydrostatic part of the diffusion taken out, particles started
 * hydrostatic; README "Stress cases"): still water over the step spread,
 * 3 s, judged from 2 s on. Held, as the summation is: vmax under
 * 0.06 sqrt(g D) and nothing thrown, which the summation fails at 10 layers
 * and cfl 0.48 and 0.52 (0.075, 0.163), at 40 layers and 0.55 (0.188) and
 * at 100 layers (14 thrown, 0.14); the bottom pressure mean within 5% plus
 * the mass's calibration gap (1 - m / (rho0 dx^3) = 0.98%: the continuity
 * density is rho0 where nothing compresses it, so the pressure carries
 * rho0 a spacing^3 where the weight is m; test_sph's hydrostatic tank
 * allows the same): measured 1.041-1.052. At 10 and 20 layers the ringing
 * of the bottom pressure over the last half second is held to 0.1 rho0 g D
 * (measured 0.001-0.017; the summation's 0.10-0.57); at 40 and 100 layers
 * it is printed (0.12-0.19: the diffusion, nu ~ delta h c, damps the
 * fundamental acoustic mode at a rate falling as 1 / D, and a shift of the
 * lattice in the first 0.2 s excites it), open. */
static void still_water_continuity(const char *depth, int layers, const char *const *cfl, int ncfl)
{
	const double mass_gap = 1 - 1 / 1.0098; /* the lattice's sum V W_poly6 at h = 2 dx (test_sph's lattice_sums) */
	for (int c = 0; c < ncfl; ++c) {
		char sets[128];
		snprintf(sets, sizeof sets, "--set depth=%s --set duration=3 --set cfl=%s", depth, cfl[c]);
		const still_water r = run_still_water_continuity(sets, 2.0);
		const double ring = r.half_max[1] - r.half_min[1];
		printf("    WCSPH continuity still water %d layers, cfl %s, t >= 2 s: vmax %.4f sqrt(g H) (held to 0.06), "
		       "bottom p mean %.3f x rho0 g H (held to %.3f), ringing %.3f then %.3f%s, thrown %g\n",
		       layers, cfl[c], r.vmax_ratio, r.bp_mean, 1.05 + mass_gap, r.half_max[0] - r.half_min[0], ring,
		       layers <= 20 ? " (the last held to 0.1)" : " (open: not asserted)", r.thrown);
		CHECK(r.status == 0);
		CHECK(r.frames == 90);
		CHECK(r.thrown == 0);
		CHECK(r.leaked == 0 && r.nonfinite == 0);
		CHECK(r.vmax_ratio < 0.06);
		CHECK(fabs(r.bp_mean - 1) < 0.05 + mass_gap);
		if (layers <= 20)
			CHECK(ring < 0.1);
	}
}

static const char *const spread[] = {"0.45", "0.48", "0.5", "0.52", "0.55"};

/* 10 layers, the five steps: a few seconds. */
static void still_water_continuity_10_layers(void) { still_water_continuity("0.125", 10, spread, 5); }

/* 20 and 40 layers at the five steps, 100 (depth 1.25, 6400 particles) at
 * 0.48, 0.5 and 0.52: long. */
static void still_water_continuity_20_layers(void) { still_water_continuity("0.25", 20, spread, 5); }
static void still_water_continuity_40_layers(void) { still_water_continuity("0.5", 40, spread, 5); }
static void still_water_continuity_100_layers(void) { still_water_continuity("1.25", 100, spread + 1, 3); }

void suite_stress_wcsph(void)
{
	RUN(still_water_10_layers_at_rest);
	RUN(still_water_10_layers_step_spread);
	RUN(still_water_continuity_10_layers);
	RUN(energy_budget_floor);
}

void suite_long_stress_wcsph(void)
{
	RUN(still_water_20_layers_at_rest);
	RUN(still_water_40_layers_at_rest);
	RUN(still_water_continuity_20_layers);
	RUN(still_water_continuity_40_layers);
	RUN(still_water_continuity_100_layers);
	RUN(energy_budget_open);
}
