/* SPDX-License-Identifier: MIT */
#define _POSIX_C_SOURCE 200809L
/* Runs every suite and ends with the summary line "N passed, N failed". */
#include "test.h"

#include <stdarg.h>
#include <stdbool.h>
#include <stdlib.h>
#include <string.h>
#include <sys/wait.h>
#include <time.h>

static int failures_in_test;
static int passed, failed;

void test_fail(const char *file, int line, const char *fmt, ...)
{
	va_list ap;
	va_start(ap, fmt);
	fprintf(stdout, "    %s:%d: ", file, line);
	vfprintf(stdout, fmt, ap);
	fputc('\n', stdout);
	va_end(ap);
	failures_in_test++;
}

void test_run(const char *name, void (*fn)(void))
{
	/* EDDY_TEST=substring: only the tests whose name contains it (iterating on one test) */
	const char *want = getenv("EDDY_TEST");
	if (want && *want && !strstr(name, want))
		return;
	struct timespec a, b;
	failures_in_test = 0;
	clock_gettime(CLOCK_MONOTONIC, &a);
	fn();
	clock_gettime(CLOCK_MONOTONIC, &b);
	double ms = (double)(b.tv_sec - a.tv_sec) * 1e3 + (double)(b.tv_nsec - a.tv_nsec) * 1e-6;
	if (failures_in_test) {
		failed++;
		printf("FAIL  %s (%.0f ms)\n", name, ms);
	} else {
		passed++;
		printf("ok    %s (%.0f ms)\n", name, ms);
	}
	fflush(stdout);
}

int test_sh(const char *cmd, char *out, size_t cap)
{
	char full[4096];
	snprintf(full, sizeof full, "%s 2>&1", cmd);
	FILE *p = popen(full, "r");
	if (!p)
		return -1;
	size_t n = fread(out, 1, cap - 1, p);
	out[n] = '\0';
	int st = pclose(p);
	return WIFEXITED(st) ? WEXITSTATUS(st) : -1;
}

double test_json_number(const char *line, const char *key)
{
	char pat[64];
	snprintf(pat, sizeof pat, "\"%s\":", key);
	const char *p = strstr(line, pat);
	if (!p)
		return NAN;
	p += strlen(pat);
	char *end;
	const double v = strtod(p, &end);
	return end == p ? NAN : v;
}

const char *test_build_dir(void)
{
	const char *b = getenv("EDDY_BUILD");
	return b && b[0] ? b : "build";
}

int main(int argc, char **argv)
{
	/* build/tests/run: every suite but the long ones; run NAME: one suite;
	 * run long: the long suites (make test-long). */
	const char *only = argc > 1 ? argv[1] : NULL;
	static const struct {
		const char *name;
		void (*fn)(void);
		bool long_running; /* minutes, not seconds: make test-long, which CI also runs */
	} suites[] = {
		{"core", suite_core, false},
		{"physics", suite_physics, false},
		{"lua", suite_lua, false},
		{"cli", suite_cli, false},
		{"reliability", suite_reliability, false},
		{"fuzz", suite_fuzz, false},
		{"package", suite_package, false},
		{"sph", suite_sph, false},
		{"sph_reference", suite_sph_reference, false},
		{"flip", suite_flip, false},
		{"flip_solvers", suite_flip_solvers, false},
		{"render", suite_render, false},
		{"surface", suite_surface, false},
		{"study", suite_study, false},
		{"compare", suite_compare, false},
		/* stress: scenes one step beyond the validated ones (scenes/stress/) */
		{"stress_flip_flight", suite_stress_flip_flight, false},
		{"stress_flip_solids", suite_stress_flip_solids, false},
		{"stress_sph_solids", suite_stress_sph_solids, false},
		{"long_sph_solids", suite_long_sph_solids, true},
		{"stress_slosh", suite_stress_slosh, false},
		{"long_slosh", suite_long_slosh, true},
		{"stress_dfsph", suite_stress_dfsph, false},
		{"long_dfsph", suite_long_dfsph, true},
		{"dfsph_coarse", suite_dfsph_coarse, false},
		{"dfsph_warm", suite_dfsph_warm, false},
		{"stress_energy", suite_stress_energy, false},
		{"mesh", suite_mesh, false},
		{"long_mesh", suite_long_mesh, true},
		{"rotate", suite_rotate, false},
		{"long_rotate", suite_long_rotate, true},
		{"stress_flip_volume", suite_stress_flip_volume, false},
		{"long_flip_volume", suite_long_flip_volume, true},
		{"stress_wcsph", suite_stress_wcsph, false},
		{"long_stress_wcsph", suite_long_stress_wcsph, true},
	};
	const bool want_long = only && strcmp(only, "long") == 0;
	int ran = 0;
	for (size_t i = 0; i < sizeof suites / sizeof suites[0]; ++i) {
		const bool named = only && strcmp(only, suites[i].name) == 0;
		if (want_long ? !suites[i].long_running : only ? !named : suites[i].long_running)
			continue;
		printf("# %s\n", suites[i].name);
		suites[i].fn();
		ran++;
	}
	if (only && !ran && !want_long) {
		fprintf(stderr, "run: no suite named '%s'\n", only);
		return 2;
	}
	printf("%d passed, %d failed\n", passed, failed);
	return failed ? 1 : 0;
}
