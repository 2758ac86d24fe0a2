/* SPDX-License-Identifier: MIT */
/* A collapsing column in a closed tank (scenes/dam_break.lua) must not make
 * energy: the total (kinetic + potential, plus WCSPH's compression energy)
 * may only fall as viscosity and the transfers dissipate it. Held to 1% of
 * the potential energy released so far: the explicit time integration and
 * the compression energy's lattice bias are well under that for a method
 * that conserves energy, and a solver that injects energy (pressure that
 * overshoots, walls that push) shows up at once. Run at a/20, where DFSPH
 * fails (issue "Stable and conservative one step beyond the tested scenes":
 * its gain grows with resolution), which is printed, not asserted. */
#define _POSIX_C_SOURCE 200809L
#include "test.h"

#include <stdlib.h>
#include <string.h>

/* The number after "key": in a stats line, or NAN. */
static double field(const char *line, const char *key)
{
	char pat[64];
	snprintf(pat, sizeof pat, "\"%s\":", key);
	const char *p = strstr(line, pat);
	return p ? strtod(p + strlen(pat), NULL) : NAN;
}

/* Largest rise of the total energy above its start and the potential energy
 * released (start minus lowest), J, over a run of the dam break. */
static bool energy_rise(const char *method, const char *spacing, double *rise, double *released)
{
	char cmd[512];
	snprintf(cmd, sizeof cmd,
	         "%s/eddy run scenes/dam_break.lua --set method=%s --set spacing=%s --set render=false --quiet --stats -",
	         test_build_dir(), method, spacing);
	FILE *f = popen(cmd, "r");
	if (!f)
		return false;
	char line[8192];
	double e0 = NAN, p0 = NAN, pmin = INFINITY;
	*rise = 0;
	int frames = 0;
	while (fgets(line, sizeof line, f)) {
		const double e = field(line, "energy"), p = field(line, "potential_energy");
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
	static const char *const methods[] = {"wcsph", "flip", "pic", "apic", "dfsph"};
	for (size_t i = 0; i < sizeof methods / sizeof methods[0]; ++i) {
		double rise, released;
		const bool ran = energy_rise(methods[i], "0.005", &rise, &released);
		CHECKF(ran, "%s: the dam break did not run to its end with energy stats", methods[i]);
		const double frac = released > 0 ? rise / released : INFINITY;
		printf("    %s: energy rise %.3f%% of the %.3f J released%s\n", methods[i], 100 * frac, released,
		       strcmp(methods[i], "dfsph") == 0 ? " (open: not asserted)" : "");
		if (ran && strcmp(methods[i], "dfsph") != 0)
			CHECKF(released > 0.1 && frac <= 0.01, "%s: energy rose by %.2f%% of the released %.3f J", methods[i],
			       100 * frac, released);
	}
}

/* WCSPH one resolution coarser too, a/10 (issue 13 reported a 1.8% gain
 * there; measured 0.000% on this scene both before and after the
 * hydrostatic start and the lag-free wall density), held to the same 1%. */
static void wcsph_collapse_makes_no_energy_at_a_10(void)
{
	double rise, released;
	const bool ran = energy_rise("wcsph", "0.01", &rise, &released);
	CHECKF(ran, "wcsph a/10: the dam break did not run to its end with energy stats");
	const double frac = released > 0 ? rise / released : INFINITY;
	printf("    wcsph a/10: energy rise %.3f%% of the %.3f J released\n", 100 * frac, released);
	CHECKF(released > 0.1 && frac <= 0.01, "wcsph a/10: energy rose by %.2f%% of the released %.3f J", 100 * frac,
	       released);
}

void suite_stress_energy(void)
{
	RUN(collapse_makes_no_energy);
	RUN(wcsph_collapse_makes_no_energy_at_a_10);
}
