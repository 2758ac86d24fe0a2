/* SPDX-License-Identifier: MIT */
/* A plain test runner: TEST functions register in suites, CHECK records a
 * failure (file, line, message) and carries on, so one run lists every broken
 * assertion. The runner prints "N passed, N failed". */
#ifndef EDDY_TEST_H
#define EDDY_TEST_H

#include <math.h>
#include <stdbool.h>
#include <stdio.h>

void test_fail(const char *file, int line, const char *fmt, ...)
#if defined(__GNUC__)
	__attribute__((format(printf, 3, 4)))
#endif
	;
void test_run(const char *name, void (*fn)(void));
/* Runs a shell command with stderr merged into stdout, captured in out;
 * returns its exit status (-1 if it did not exit). */
int test_sh(const char *cmd, char *out, size_t cap);
/* Directory of the build under test (build/ or build/asan/). */
const char *test_build_dir(void);
/* The running suite's own folder for what it writes, BUILD/t/SUITE (made
 * before the suite starts): suites run at once never share one. */
const char *test_out_dir(void);
/* True when the file's first megabyte holds needle (false when it cannot be
 * read). */
bool test_file_has(const char *path, const char *needle);
/* The number after "key": in a JSON line such as a stats line; NAN when
 * the key is absent or its value is not a number (null). */
double test_json_number(const char *line, const char *key);
/* element index (from 0) of the number array at key; NAN if absent */
double test_json_array_number(const char *line, const char *key, int index);
/* An environment switch (EDDY_NO_AVX2, say) changed for a test
 * and put back after it: test_env_save copies its value (NULL: unset),
 * test_env_set sets it (value NULL: unsets), test_env_restore puts the saved
 * value back and frees the copy. */
char *test_env_save(const char *name);
void test_env_set(const char *name, const char *value);
void test_env_restore(const char *name, char *saved);

#define CHECK(cond)                                     \
	do {                                                \
		if (!(cond))                                    \
			test_fail(__FILE__, __LINE__, "%s", #cond); \
	} while (0)

#define CHECKF(cond, ...)                               \
	do {                                                \
		if (!(cond))                                    \
			test_fail(__FILE__, __LINE__, __VA_ARGS__); \
	} while (0)

#define CHECK_NEAR(a, b, tol)                                                                               \
	do {                                                                                                    \
		double a_ = (double)(a), b_ = (double)(b), t_ = (double)(tol);                                      \
		if (!(fabs(a_ - b_) <= t_))                                                                         \
			test_fail(__FILE__, __LINE__, "%s = %.9g, expected %s = %.9g within %.3g", #a, a_, #b, b_, t_); \
	} while (0)

/* Substring check with the haystack shown on failure. */
#define CHECK_HAS(hay, needle)                                                                     \
	do {                                                                                           \
		const char *h_ = (hay);                                                                    \
		if (!h_ || !strstr(h_, (needle)))                                                          \
			test_fail(__FILE__, __LINE__, "expected \"%s\" in: %s", (needle), h_ ? h_ : "(null)"); \
	} while (0)

#define RUN(fn) test_run(#fn, fn)

void suite_core(void);
void suite_physics(void);
void suite_lua(void);
void suite_cli(void);
void suite_reliability(void);
void suite_fuzz(void);
void suite_package(void);
/* SPH suites */
void suite_sph(void);
void suite_long_sph(void); /* the drop's frequency at two resolutions */
void suite_sph_reference(void); /* the SPH passes against a double-precision O(n^2) reference */

/* FLIP suites */
void suite_flip(void);
void suite_flip_solvers(void);
void suite_stress_flip_flight(void);
void suite_outflow(void); /* open sides: water leaving the world, every method */
void suite_box_cut(void); /* FLIP's walls at the world's box when it is not a whole number of cells */
void suite_stress_flip_solids(void);
void suite_stress_sph_solids(void);
void suite_long_sph_solids(void);

/* renderer suites */
void suite_render(void);
void suite_surface(void); /* liquid surface meshes and render_surface */

/* accuracy/time study (eddy study) */
void suite_study(void);
void suite_compare(void); /* eddy compare */

/* stress scenes (scenes/stress/) */
void suite_stress_slosh(void);
void suite_long_slosh(void); /* minutes: make test-long */

void suite_stress_dfsph(void);
void suite_long_dfsph(void);
void suite_dfsph_coarse(void); /* sph_dfsph's coarse level (dfsph_coarse.c) */
void suite_dfsph_warm(void);   /* sph_dfsph's hydrostatic cold start (dfsph_warm.c) */

/* meshes and particle files (issue 16) */
void suite_mesh(void);
void suite_long_mesh(void); /* minutes: make test-long */
void suite_rotate(void);    /* rotating colliders (issue 16) */
void suite_long_rotate(void);
void suite_stress_energy(void);
void suite_stress_flip_volume(void);
void suite_long_flip_volume(void); /* minutes: make test-long */
void suite_stress_wcsph(void);
void suite_long_stress_wcsph(void);

#endif
