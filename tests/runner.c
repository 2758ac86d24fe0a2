/* SPDX-License-Identifier: MIT */
#define _POSIX_C_SOURCE 200809L
/* Runs the suites and ends with the summary line "N passed, N failed".
 *
 * With one job the suites run one after the other in this process. With more
 * (-j N, EDDY_JOBS; default: the online CPUs) each suite runs as "run SUITE"
 * in a child process, forked and exec'd before this process has run anything
 * of eddy's: a fork alone is not enough, since libraries start threads when
 * they load (log4cplus, under OpenVDB, has one that a forked child then waits
 * for at exit, forever). The child's stdout and stderr go to a file of its own,
 * printed whole when the suite ends, so suites never interleave. The longest
 * suites start first (their measured seconds are in the table), so that no
 * long suite starts last. A child that dies of a signal, or exits without its
 * summary line, or exits non-zero with no failed test (a sanitizer's report
 * at exit) is a failure named after the suite.
 *
 * Each suite writes its files under test_out_dir(), BUILD/t/SUITE, so two
 * suites running at once never share an output folder (eddy run's lock on
 * its --out folder refuses a second run, and outputs read back would mix). */
#include "test.h"

#include <errno.h>
#include <fcntl.h>
#include <stdarg.h>
#include <stdbool.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

static int failures_in_test;
static int passed, failed;
static char suite_out[1024]; /* test_out_dir() of the suite running in this process */

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

bool test_file_has(const char *path, const char *needle)
{
	FILE *f = fopen(path, "rb");
	if (!f)
		return false;
	enum { CAP = 1 << 20 };
	char *text = malloc(CAP);
	const size_t n = text ? fread(text, 1, CAP - 1, f) : 0;
	fclose(f);
	if (!text)
		return false;
	text[n] = '\0';
	const bool found = strstr(text, needle) != NULL;
	free(text);
	return found;
}

/* the number at p (NAN if none) */
static double number_at(const char *p)
{
	char *end;
	const double v = strtod(p, &end);
	return end == p ? NAN : v;
}

/* where "key": followed by open starts in line, past both; NULL if absent */
static const char *after_key(const char *line, const char *key, const char *open)
{
	char pat[64];
	snprintf(pat, sizeof pat, "\"%s\":%s", key, open);
	const char *p = strstr(line, pat);
	return p ? p + strlen(pat) : NULL;
}

double test_json_number(const char *line, const char *key)
{
	const char *p = after_key(line, key, "");
	return p ? number_at(p) : NAN;
}

double test_json_array_number(const char *line, const char *key, int index)
{
	const char *p = after_key(line, key, "[");
	for (int k = 0; p && k < index; ++k) {
		p = strpbrk(p, ",]");
		p = p && *p == ',' ? p + 1 : NULL;
	}
	return p ? number_at(p) : NAN;
}

const char *test_build_dir(void)
{
	const char *b = getenv("EDDY_BUILD");
	return b && b[0] ? b : "build";
}

const char *test_out_dir(void) { return suite_out; }

char *test_env_save(const char *name)
{
	const char *v = getenv(name);
	return v ? strdup(v) : NULL;
}

void test_env_set(const char *name, const char *value)
{
	if (value)
		setenv(name, value, 1);
	else
		unsetenv(name);
}

void test_env_restore(const char *name, char *saved)
{
	test_env_set(name, saved);
	free(saved);
}

typedef struct suite {
	const char *name;
	void (*fn)(void);
	bool long_running; /* minutes, not seconds: make test-long, which CI also runs */
	/* its CPU time on the 2-core host, the start order: the closing lines
	 * of a -j 2 run (make test at load 7, make test-long at load 3-7) */
	int seconds;
} suite;

static double now_s(void)
{
	struct timespec t;
	clock_gettime(CLOCK_MONOTONIC, &t);
	return (double)t.tv_sec + 1e-9 * (double)t.tv_nsec;
}

/* mkdir -p */
static int make_dirs(const char *path)
{
	char p[1024];
	snprintf(p, sizeof p, "%s", path);
	for (char *c = p + 1;; ++c)
		if (*c == '/' || *c == '\0') {
			const char was = *c;
			*c = '\0';
			if (mkdir(p, 0755) != 0 && errno != EEXIST)
				return -1;
			if (!(*c = was))
				return 0;
		}
}

/* CPU seconds of this process and of the commands it has run and waited for */
static double cpu_s(void)
{
	struct rusage self, kids;
	getrusage(RUSAGE_SELF, &self);
	getrusage(RUSAGE_CHILDREN, &kids);
	return (double)(self.ru_utime.tv_sec + self.ru_stime.tv_sec + kids.ru_utime.tv_sec + kids.ru_stime.tv_sec) +
	       1e-6 *
	           (double)(self.ru_utime.tv_usec + self.ru_stime.tv_usec + kids.ru_utime.tv_usec + kids.ru_stime.tv_usec);
}

/* Runs one suite in this process, between the lines "# NAME" and "# NAME: N
 * passed, N failed, S s, C s CPU" (wall time and the CPU time of the suite
 * and of the commands it ran; the table's seconds are the CPU time). */
static void run_suite(const suite *s)
{
	snprintf(suite_out, sizeof suite_out, "%s/t/%s", test_build_dir(), s->name);
	if (make_dirs(suite_out) != 0)
		fprintf(stdout, "run: cannot create %s: %s\n", suite_out, strerror(errno));
	printf("# %s\n", s->name);
	fflush(stdout);
	const int p0 = passed, f0 = failed;
	const double t0 = now_s(), c0 = cpu_s();
	s->fn();
	printf("# %s: %d passed, %d failed, %.1f s, %.1f s CPU\n", s->name, passed - p0, failed - f0, now_s() - t0,
	       cpu_s() - c0);
	fflush(stdout);
}

typedef struct child {
	const suite *s;
	pid_t pid;
	FILE *log; /* the child's stdout and stderr */
} child;

static bool start_child(child *c, const suite *s, const char *self, const char *argv0)
{
	c->s = s;
	c->log = tmpfile();
	if (!c->log) {
		printf("FAIL  suite %s: no temporary file for its output: %s\n", s->name, strerror(errno));
		return false;
	}
	/* only this child writes it (its dup2 copies stay open across exec) */
	fcntl(fileno(c->log), F_SETFD, FD_CLOEXEC);
	fflush(stdout);
	fflush(stderr);
	c->pid = fork();
	if (c->pid < 0) {
		printf("FAIL  suite %s: fork: %s\n", s->name, strerror(errno));
		fclose(c->log);
		return false;
	}
	if (c->pid == 0) {
		if (dup2(fileno(c->log), STDOUT_FILENO) >= 0 && dup2(fileno(c->log), STDERR_FILENO) >= 0)
			execl(self, argv0, s->name, (char *)NULL);
		fprintf(stderr, "run: cannot start %s %s: %s\n", self, s->name, strerror(errno));
		_exit(127);
	}
	return true;
}

/* Prints the child's output whole but its summary line, whose counts it adds
 * instead, and names the suite when the child did not end cleanly. */
static void finish_child(child *c, int status)
{
	char line[4096];
	int p = 0, f = 0;
	bool summed = false, line_start = true;
	rewind(c->log);
	while (fgets(line, sizeof line, c->log)) {
		int lp, lf, end = 0;
		if (line_start && sscanf(line, "%d passed, %d failed%n", &lp, &lf, &end) == 2 && line[end] == '\n') {
			p += lp, f += lf, summed = true;
			continue;
		}
		fputs(line, stdout);
		line_start = strchr(line, '\n') != NULL; /* else a longer line goes on */
	}
	if (!line_start)
		fputc('\n', stdout); /* the child stopped mid-line */
	fclose(c->log);
	passed += p;
	failed += f;
	if (WIFSIGNALED(status)) {
		printf("FAIL  suite %s: killed by signal %d (%s)\n", c->s->name, WTERMSIG(status), strsignal(WTERMSIG(status)));
		failed++;
	} else if (!summed) {
		printf("FAIL  suite %s: exited with status %d without its summary line\n", c->s->name, WEXITSTATUS(status));
		failed++;
	} else if (WEXITSTATUS(status) != 0 && f == 0) {
		printf("FAIL  suite %s: exited with status %d, no test failed\n", c->s->name, WEXITSTATUS(status));
		failed++;
	}
	fflush(stdout);
}

/* The suites in sel, jobs at a time, longest first. */
static void run_parallel(const suite **sel, int n, int jobs, const char *self, const char *argv0)
{
	for (int i = 1; i < n; ++i) /* insertion sort, stable: equal times keep the table's order */
		for (int j = i; j > 0 && sel[j]->seconds > sel[j - 1]->seconds; --j) {
			const suite *t = sel[j];
			sel[j] = sel[j - 1];
			sel[j - 1] = t;
		}
	child *kids = calloc((size_t)jobs, sizeof *kids);
	if (!kids) {
		printf("run: out of memory\n");
		failed++;
		return;
	}
	int next = 0, running = 0;
	while (next < n || running > 0) {
		for (int k = 0; k < jobs && next < n; ++k)
			if (!kids[k].pid) {
				if (start_child(&kids[k], sel[next++], self, argv0))
					running++;
				else
					failed++;
			}
		if (!running)
			continue;
		int status;
		const pid_t pid = waitpid(-1, &status, 0);
		if (pid < 0) {
			if (errno == EINTR)
				continue;
			printf("run: waitpid: %s\n", strerror(errno));
			failed++;
			break;
		}
		for (int k = 0; k < jobs; ++k)
			if (kids[k].pid == pid) {
				finish_child(&kids[k], status);
				kids[k].pid = 0;
				running--;
			}
	}
	free(kids);
}

/* A job count from -j or EDDY_JOBS: 1 to 256, else -1. */
static int parse_jobs(const char *text)
{
	char *end;
	errno = 0;
	const long v = strtol(text, &end, 10);
	return errno || end == text || *end || v < 1 || v > 256 ? -1 : (int)v;
}

int main(int argc, char **argv)
{
	/* build/tests/run [-j N] [long | SUITE]: every suite but the long ones;
	 * long: the long suites (make test-long); SUITE: that one, in-process. */
	static const suite suites[] = {
		{"core", suite_core, false, 0},
		{"physics", suite_physics, false, 1},
		{"lua", suite_lua, false, 0},
		{"cli", suite_cli, false, 13},
		{"reliability", suite_reliability, false, 3},
		{"fuzz", suite_fuzz, false, 0},
		{"package", suite_package, false, 1},
		{"sph", suite_sph, false, 22},
		{"long_sph", suite_long_sph, true, 40},
		{"sph_reference", suite_sph_reference, false, 23},
		{"flip", suite_flip, false, 6},
		{"flip_solvers", suite_flip_solvers, false, 2},
		{"render", suite_render, false, 3},
		{"surface", suite_surface, false, 2},
		{"study", suite_study, false, 5},
		{"compare", suite_compare, false, 3},
		/* stress: scenes one step beyond the validated ones (scenes/stress/) */
		{"stress_flip_flight", suite_stress_flip_flight, false, 5},
		{"outflow", suite_outflow, false, 5},
		{"box_cut", suite_box_cut, false, 4},
		{"stress_flip_solids", suite_stress_flip_solids, false, 10},
		{"stress_sph_solids", suite_stress_sph_solids, false, 17},
		{"long_sph_solids", suite_long_sph_solids, true, 58},
		{"stress_slosh", suite_stress_slosh, false, 5},
		{"long_slosh", suite_long_slosh, true, 75},
		{"stress_dfsph", suite_stress_dfsph, false, 2},
		{"long_dfsph", suite_long_dfsph, true, 60},
		{"dfsph_coarse", suite_dfsph_coarse, false, 1},
		{"dfsph_warm", suite_dfsph_warm, false, 0},
		{"stress_energy", suite_stress_energy, false, 7},
		{"mesh", suite_mesh, false, 10},
		{"long_mesh", suite_long_mesh, true, 25},
		{"rotate", suite_rotate, false, 16},
		{"long_rotate", suite_long_rotate, true, 24},
		{"stress_flip_volume", suite_stress_flip_volume, false, 2},
		{"long_flip_volume", suite_long_flip_volume, true, 66},
		{"stress_wcsph", suite_stress_wcsph, false, 2},
		{"long_stress_wcsph", suite_long_stress_wcsph, true, 17},
	};
	enum { n_suites = sizeof suites / sizeof suites[0] };
	const char *env_jobs = getenv("EDDY_JOBS");
	int jobs = 0; /* 0: the online CPUs */
	if (env_jobs && *env_jobs && (jobs = parse_jobs(env_jobs)) < 0) {
		fprintf(stderr, "run: EDDY_JOBS must be a job count from 1 to 256 (got '%s')\n", env_jobs);
		return 2;
	}
	const char *only = NULL;
	for (int a = 1; a < argc; ++a) {
		const char *v = NULL;
		if (strcmp(argv[a], "-j") == 0 || strcmp(argv[a], "--jobs") == 0) {
			if (a + 1 >= argc) {
				fprintf(stderr, "run: %s needs a job count from 1 to 256\n", argv[a]);
				return 2;
			}
			v = argv[++a];
		} else if (strncmp(argv[a], "-j", 2) == 0)
			v = argv[a] + 2;
		else if (argv[a][0] == '-' || only) {
			fprintf(stderr, "usage: run [-j N] [long | SUITE] (got '%s')\n", argv[a]);
			return 2;
		} else
			only = argv[a];
		if (v && (jobs = parse_jobs(v)) < 0) {
			fprintf(stderr, "run: -j must be a job count from 1 to 256 (got '%s')\n", v);
			return 2;
		}
	}
	const bool want_long = only && strcmp(only, "long") == 0;
	const suite *sel[n_suites];
	int n = 0;
	for (size_t i = 0; i < n_suites; ++i) {
		const bool named = only && strcmp(only, suites[i].name) == 0;
		if (!(want_long ? !suites[i].long_running : only ? !named : suites[i].long_running))
			sel[n++] = &suites[i];
	}
	if (only && !n && !want_long) {
		fprintf(stderr, "run: no suite named '%s'\n", only);
		return 2;
	}
	if (!jobs) {
		const long cpus = sysconf(_SC_NPROCESSORS_ONLN);
		jobs = cpus > 0 ? (int)(cpus < 256 ? cpus : 256) : 1;
	}
	if (jobs > n)
		jobs = n;
	if (jobs > 1) {
		/* Suites run beside each other on cores that a two-thread test also
		 * wants; libgomp's default spin at barriers would then burn a core
		 * another suite needs. libgomp reads this when it loads: in the
		 * children, not here (results do not depend on it). */
		if (!getenv("OMP_WAIT_POLICY") && !getenv("GOMP_SPINCOUNT"))
			setenv("OMP_WAIT_POLICY", "passive", 1);
		printf("# %d suites, %d at a time\n", n, jobs);
		run_parallel(sel, n, jobs, access("/proc/self/exe", X_OK) == 0 ? "/proc/self/exe" : argv[0], argv[0]);
	} else
		for (int i = 0; i < n; ++i)
			run_suite(sel[i]);
	printf("%d passed, %d failed\n", passed, failed);
	return failed ? 1 : 0;
}
