/* SPDX-License-Identifier: MIT */
/* Stress tests of sph_dfsph one step beyond the validated scenes: still water
 * a few tens of layers deep (scenes/stress/still_water.lua), run through the
 * command line with per-frame stats.
 *
 * The target (issue "Stable and conservative one step beyond the tested
 * scenes", item 1) is a column at rest after settling: max speed under 2% of
 * sqrt(g H), bottom pressure within 3% of the weight above, nothing thrown.
 * The solver does not reach it yet (see the figures each test prints), so
 * these tests guard what holds today: the 10-layer column stays in the box
 * and bounded, and they print the figures the target is about. */
#include "test.h"

#include <stdlib.h>
#include <string.h>

/* The number after "name": in a JSON line, or NAN. */
static double field(const char *line, const char *name)
{
	char key[64];
	snprintf(key, sizeof key, "\"%s\":", name);
	const char *p = strstr(line, key);
	return p ? strtod(p + strlen(key), NULL) : NAN;
}

/* Figures of a still-water run from t_settle on (thrown and failures over
 * the whole run). */
typedef struct still_water {
	int status, frames;
	double vmax_ratio, bp_min, bp_max; /* from t_settle */
	double thrown, leaked, nonfinite;  /* the whole run */
} still_water;

static still_water run_still_water(const char *sets, double t_settle)
{
	still_water r = {0, 0, 0, INFINITY, -INFINITY, 0, 0, 0};
	enum { CAP = 1 << 20 };
	char *out = malloc(CAP), cmd[1024];
	if (!out) {
		r.status = -1;
		return r;
	}
	snprintf(cmd, sizeof cmd,
	         "%s/eddy run scenes/stress/still_water.lua %s --stats - --quiet --threads 1 --out %s/stress_still_water",
	         test_build_dir(), sets, test_build_dir());
	r.status = test_sh(cmd, out, CAP);
	for (char *line = out; line && *line;) {
		char *next = strchr(line, '\n');
		if (next)
			*next++ = '\0';
		const double t = field(line, "time");
		if (isfinite(t)) {
			r.frames++;
			r.thrown = fmax(r.thrown, field(line, "thrown"));
			r.leaked = fmax(r.leaked, field(line, "leaked"));
			r.nonfinite = fmax(r.nonfinite, field(line, "nonfinite"));
			if (t >= t_settle - 1e-9) {
				const double bp = field(line, "bottom_p_ratio");
				r.vmax_ratio = fmax(r.vmax_ratio, field(line, "vmax_ratio"));
				r.bp_min = fmin(r.bp_min, bp);
				r.bp_max = fmax(r.bp_max, bp);
			}
		}
		line = next;
	}
	if (r.status != 0)
		printf("    eddy run %s: exit %d: %.300s\n", sets, r.status, out);
	free(out);
	return r;
}

/* 10 layers (0.125 m, 640 particles), 2 s: the run completes, nothing is
 * thrown above the surface or leaves the box, and from 1 s on the max speed
 * stays under 0.3 sqrt(g H) (measured 0.15: the column does not come to
 * rest, the target is 0.02). The bottom pressure ratio is printed (measured
 * 0.28-2.1 x rho0 g H; the target is 0.97-1.03). About 1 s. */
static void still_water_10_layers_stays_bounded(void)
{
	const still_water r = run_still_water("--set depth=0.125", 1.0);
	printf("    still water 10 layers, t >= 1 s: vmax <= %.3f sqrt(g H) (target 0.02), bottom p %.2f-%.2f x "
	       "rho0 g H (target 0.97-1.03), thrown %g\n",
	       r.vmax_ratio, r.bp_min, r.bp_max, r.thrown);
	CHECK(r.status == 0);
	CHECK(r.frames == 60);
	CHECK(r.thrown == 0);
	CHECK(r.leaked == 0 && r.nonfinite == 0);
	CHECK(r.vmax_ratio < 0.3);
}

void suite_stress_dfsph(void)
{
	RUN(still_water_10_layers_stays_bounded);
}
