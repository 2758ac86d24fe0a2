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
static bool energy_rise(const char *method, double *rise, double *released)
{
	char cmd[512];
	snprintf(cmd, sizeof cmd,
	         "%s/eddy run scenes/dam_break.lua --set method=%s --set spacing=0.005 --set render=false --quiet --stats -",
	         test_build_dir(), method);
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
		const bool ran = energy_rise(methods[i], &rise, &released);
		CHECKF(ran, "%s: the dam break did not run to its end with energy stats", methods[i]);
		const double frac = released > 0 ? rise / released : INFINITY;
		printf("    %s: energy rise %.3f%% of the %.3f J released%s\n", methods[i], 100 * frac, released,
		       strcmp(methods[i], "dfsph") == 0 ? " (open: not asserted)" : "");
		if (ran && strcmp(methods[i], "dfsph") != 0)
			CHECKF(released > 0.1 && frac <= 0.01, "%s: energy rose by %.2f%% of the released %.3f J", methods[i],
			       100 * frac, released);
	}
}

void suite_stress_energy(void)
{
	RUN(collapse_makes_no_energy);
}
