/* SPDX-License-Identifier: MIT */
/* A collapsing column in a closed tank (scenes/dam_break.lua) must not make
 * energy: the total (kinetic + potential, plus WCSPH's compression energy)
 * may only fall as viscosity and the transfers dissipate it. Held to 1% of
 * the potential energy released so far: the explicit time integration and
 * the compression energy's lattice bias are well under that for a method
 * that conserves energy, and a solver that injects energy (pressure that
 * overshoots, walls that push) shows up at once. Run at a/20 for every
 * method, and for DFSPH at a/10 too: its gain grew with resolution (issue
 * "Stable and conservative one step beyond the tested scenes"; 20% of the
 * released energy at a/20 with the cold solve), so it is held at two. */
#define _POSIX_C_SOURCE 200809L
#include "test.h"

#include <stdlib.h>
#include <string.h>

/* Largest rise of the total energy above its start and the potential energy
 * released (start minus lowest), J, over a run of the dam break. */
static bool energy_rise(const char *method, double spacing, double *rise, double *released)
{
	char cmd[512];
	snprintf(cmd, sizeof cmd,
	         "%s/eddy run scenes/dam_break.lua --set method=%s --set spacing=%g --set render=false --quiet --stats - "
	         "--out %s/run",
	         test_build_dir(), method, spacing, test_out_dir());
	FILE *f = popen(cmd, "r");
	if (!f)
		return false;
	char line[8192];
	double e0 = NAN, p0 = NAN, pmin = INFINITY;
	*rise = 0;
	int frames = 0;
	while (fgets(line, sizeof line, f)) {
		const double e = test_json_number(line, "energy"), p = test_json_number(line, "potential_energy");
		if (!isfinite(e) || !isfinite(p))
			continue;
		if (!frames++)
			e0 = e, p0 = p;
		if (e - e0 > *rise)
			*rise = e - e0;
		if (p < pmin)
			pmin = p;
	}
	const int st = pclose(f);
	*released = p0 - pmin;
	return st == 0 && frames > 40;
}

static void collapse_makes_no_energy(void)
{
	/* every method at a/20 (a = 0.1 m); DFSPH and WCSPH also at a/10 (issue
	 * 13 reported a 1.8% WCSPH gain there) */
	static const struct {
		const char *method;
		double spacing;
	} runs[] = {{"wcsph", 0.005}, {"flip", 0.005},  {"pic", 0.005}, {"apic", 0.005},
	            {"dfsph", 0.01},  {"dfsph", 0.005}, {"wcsph", 0.01}};
	for (size_t i = 0; i < sizeof runs / sizeof runs[0]; ++i) {
		double rise, released;
		const bool ran = energy_rise(runs[i].method, runs[i].spacing, &rise, &released);
		CHECKF(ran, "%s: the dam break did not run to its end with energy stats", runs[i].method);
		const double frac = released > 0 ? rise / released : INFINITY;
		printf("    %s a/%.0f: energy rise %.3f%% of the %.3f J released\n", runs[i].method, 0.1 / runs[i].spacing,
		       100 * frac, released);
		if (ran)
			CHECKF(released > 0.1 && frac <= 0.01, "%s a/%.0f: energy rose by %.2f%% of the released %.3f J",
			       runs[i].method, 0.1 / runs[i].spacing, 100 * frac, released);
	}
}

void suite_stress_energy(void) { RUN(collapse_makes_no_energy); }
