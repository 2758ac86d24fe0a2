/* SPDX-License-Identifier: MIT */
#define _POSIX_C_SOURCE 200809L
/* `eddy study` end to end: the quick sweeps of the shipped dam-break and
 * convergence studies (every run finishes, errors are finite, the CSV has
 * its columns, the finer run of each method has the lower error, the chart
 * is a PNG), and study files with mistakes fail with one line naming the
 * file and line. The studies run the same build's eddy as child processes,
 * so under make asan the children are sanitised too. */
#include "test.h"

#include <stdlib.h>
#include <string.h>
#include <sys/wait.h>

enum { MAX_ROWS = 32, MAX_COLS = 64, CELL = 64 };

typedef struct csv {
	int rows, cols;
	char head[MAX_COLS][CELL];
	char cell[MAX_ROWS][MAX_COLS][CELL];
} csv;

/* The study's CSV has no quoted fields with commas in the shipped studies. */
static bool read_csv(const char *path, csv *c)
{
	FILE *f = fopen(path, "r");
	if (!f)
		return false;
	memset(c, 0, sizeof *c);
	char line[8192];
	int r = -1;
	while (fgets(line, sizeof line, f) && r < MAX_ROWS) {
		line[strcspn(line, "\r\n")] = '\0';
		int col = 0;
		/* by hand, not strtok: empty fields count */
		char *p = line;
		for (;;) {
			char *comma = strchr(p, ',');
			size_t n = comma ? (size_t)(comma - p) : strlen(p);
			if (col < MAX_COLS) {
				char *dst = r < 0 ? c->head[col] : c->cell[r][col];
				snprintf(dst, CELL, "%.*s", (int)n, p);
			}
			col++;
			if (!comma)
				break;
			p = comma + 1;
		}
		if (r < 0)
			c->cols = col;
		else
			CHECKF(col == c->cols, "%s row %d has %d fields, header %d", path, r + 1, col, c->cols);
		r++;
	}
	fclose(f);
	c->rows = r < 0 ? 0 : r;
	return true;
}

static int column(const csv *c, const char *name)
{
	for (int i = 0; i < c->cols && i < MAX_COLS; ++i)
		if (strcmp(c->head[i], name) == 0)
			return i;
	return -1;
}

static double num(const csv *c, int row, int col)
{
	if (col < 0 || !c->cell[row][col][0])
		return NAN;
	return strtod(c->cell[row][col], NULL);
}

static bool run_quick(const char *study, const char *out, csv *c)
{
	char cmd[1024], buf[8192];
	snprintf(cmd, sizeof cmd, "rm -rf %s && %s/eddy study scenes/studies/%s.lua --quick --out %s", out,
	         test_build_dir(), study, out);
	int code = test_sh(cmd, buf, sizeof buf);
	CHECKF(code == 0, "%s exited %d:\n%s", cmd, code, buf);
	char path[512];
	snprintf(path, sizeof path, "%s/%s.csv", out, study);
	bool ok = read_csv(path, c);
	CHECKF(ok, "no CSV at %s", path);
	return code == 0 && ok;
}

/* Every row finished, has a finite error and positive wall time and steps;
 * the columns of the issue are there; at least one run is on the Pareto
 * front. */
static void check_common(const csv *c, const char *name)
{
	static const char *const cols[] = {"study",  "method",    "resolution", "error",  "wall_s", "steps",
	                                   "frames", "particles", "peak_mb",    "status", "pareto"};
	for (size_t i = 0; i < sizeof cols / sizeof cols[0]; ++i)
		CHECKF(column(c, cols[i]) >= 0, "%s.csv has no column '%s'", name, cols[i]);
	bool per_system = false;
	for (int i = 0; i < c->cols; ++i)
		per_system |= strncmp(c->head[i], "sys_", 4) == 0;
	CHECKF(per_system, "%s.csv has no per-system time columns", name);
	int pareto = 0;
	for (int r = 0; r < c->rows; ++r) {
		CHECKF(num(c, r, column(c, "status")) == 0, "%s row %d: status %s", name, r + 1,
		       c->cell[r][column(c, "status")]);
		CHECKF(num(c, r, column(c, "wall_s")) > 0, "%s row %d: wall_s", name, r + 1);
		CHECKF(num(c, r, column(c, "steps")) > 0, "%s row %d: steps", name, r + 1);
		CHECKF(num(c, r, column(c, "peak_mb")) > 1, "%s row %d: peak_mb", name, r + 1);
		pareto += num(c, r, column(c, "pareto")) == 1;
	}
	CHECKF(pareto >= 1, "%s: no run on the Pareto front", name);
}

/* In each method, the run with the smallest resolution has a lower error
 * than the one with the largest; rows without an error (a finest-run
 * reference) are skipped. */
static void check_finer_is_better(const csv *c, const char *name, int methods_expected)
{
	int res = column(c, "resolution"), err = column(c, "error"), meth = column(c, "method");
	int methods = 0;
	for (int r = 0; r < c->rows; ++r) {
		bool first = true;
		for (int q = 0; q < r; ++q)
			first &= strcmp(c->cell[q][meth], c->cell[r][meth]) != 0;
		if (!first)
			continue;
		methods++;
		double coarse_h = -1, coarse_e = NAN, fine_h = 1e30, fine_e = NAN;
		for (int q = 0; q < c->rows; ++q) {
			double h = num(c, q, res), e = num(c, q, err);
			if (strcmp(c->cell[q][meth], c->cell[r][meth]) != 0 || !isfinite(e))
				continue;
			if (h > coarse_h)
				coarse_h = h, coarse_e = e;
			if (h < fine_h)
				fine_h = h, fine_e = e;
		}
		printf("    %s %s: error %.4g at %g, %.4g at %g\n", name, c->cell[r][meth], coarse_e, coarse_h, fine_e, fine_h);
		CHECKF(fine_h < coarse_h, "%s %s: fewer than two runs with an error", name, c->cell[r][meth]);
		CHECKF(fine_e < coarse_e, "%s %s: finer run (%g) error %g not below coarser (%g) %g", name, c->cell[r][meth],
		       fine_h, fine_e, coarse_h, coarse_e);
	}
	CHECK(methods == methods_expected);
}

static void quick_dam_break_study(void)
{
	csv *c = malloc(sizeof *c);
	char out[256];
	snprintf(out, sizeof out, "%s/study_test/dam_break", test_build_dir());
	if (run_quick("dam_break", out, c)) {
		char png[512], buf[256];
		CHECK(c->rows == 4);
		check_common(c, "dam_break");
		/* against the experiment every error is finite and the finer SPH run is
		 * closer once the experiment's clock is shifted for the gate's opening
		 * (error_shifted: 0.018 at a/5, 0.010 at a/10; unshifted 0.099 and
		 * 0.193, where a/5's column started squeezed and ran ahead, 0.43,
		 * its mean compression over the run 0.149, before WCSPH settled its
		 * start); FLIP's front leads the
		 * experiment at every resolution (see README), so its two errors are
		 * only bounded */
		int err = column(c, "error"), shifted = column(c, "error_shifted");
		for (int r = 0; r < c->rows; ++r) {
			CHECKF(isfinite(num(c, r, err)) && num(c, r, err) < 0.6, "row %d error %s", r + 1, c->cell[r][err]);
			CHECKF(num(c, r, shifted) <= num(c, r, err), "row %d: shifted error above unshifted", r + 1);
		}
		CHECKF(num(c, 1, shifted) < num(c, 0, shifted), "SPH a/10 error %g not below a/5 %g (shifted)",
		       num(c, 1, shifted), num(c, 0, shifted));
		/* the runs timed physics alone: no frame was rendered */
		char cmd[600];
		snprintf(cmd, sizeof cmd, "cat %s/runs/*.jsonl | grep -c '\"image\"'", out);
		test_sh(cmd, buf, sizeof buf);
		CHECKF(atoi(buf) == 0, "%d stats lines of the study's runs carry a rendered image", atoi(buf));
		snprintf(png, sizeof png, "command -v gnuplot >/dev/null && head -c 8 %s/dam_break.png | od -An -c", out);
		if (test_sh("command -v gnuplot", buf, sizeof buf) == 0) {
			test_sh(png, buf, sizeof buf);
			CHECK_HAS(buf, "P   N   G");
		}
	}
	free(c);
}

static void quick_convergence_study(void)
{
	csv *c = malloc(sizeof *c);
	char out[256];
	snprintf(out, sizeof out, "%s/study_test/convergence", test_build_dir());
	if (run_quick("convergence", out, c)) {
		CHECK(c->rows == 6);
		check_common(c, "convergence");
		check_finer_is_better(c, "convergence", 2);
		/* the finest run of each method is the reference: no error of its own,
		 * and the middle run carries an observed order */
		int order = column(c, "order"), ok = 0;
		for (int r = 0; r < c->rows; ++r)
			ok += isfinite(num(c, r, order)) && num(c, r, order) > 0.5;
		CHECKF(ok == 2, "%d runs with an observed order > 0.5, expected 2", ok);
	}
	free(c);
}

static void write_file(const char *path, const char *src)
{
	FILE *f = fopen(path, "w");
	if (f) {
		fputs(src, f);
		fclose(f);
	}
}

/* A fresh folder study_test/<name> (its path in dir) holding wave.lua (its
 * path in scene): q = 0.4 + cos(omega t) every frame for 1.7 s; with
 * --set broken=1 the scene fails, as a scene error. */
static void wave_scene(const char *name, char *dir, size_t dcap, char *scene, size_t scap)
{
	char cmd[1024], buf[4096];
	snprintf(dir, dcap, "%s/study_test/%s", test_build_dir(), name);
	snprintf(cmd, sizeof cmd, "rm -rf %s && mkdir -p %s", dir, dir);
	test_sh(cmd, buf, sizeof buf);
	snprintf(scene, scap, "%s/wave.lua", dir);
	write_file(scene, "local eddy = require 'eddy'\n"
	                  "local omega = tonumber(eddy.param('omega', 7))\n"
	                  "eddy.param('render', 'false') -- the study sets it\n"
	                  "if eddy.param('broken', 0) == 1 then error('wave: broken on purpose') end\n"
	                  "local w = eddy.world { fps = 100, duration = 1.7 }\n"
	                  "w:on_frame(function(w) return { q = 0.4 + math.cos(omega * w:time()) } end)\n"
	                  "return w\n");
}

/* The frequency metric counts whole periods: a field riding on an offset,
 * q = 0.4 + cos(omega t), has half periods alternating 0.74 and 1.26 of
 * pi / omega, and over 1.7 s at omega 7 and 7.5 rad/s it crosses zero 4
 * times: three half periods, which read omega 9.6% high (7.67 rad/s) when
 * all were counted. Whole periods give omega to the sampling's rounding. */
static void frequency_metric_counts_whole_periods(void)
{
	char dir[256], scene[320], file[320], out[320], cmd[1200], buf[4096];
	wave_scene("freq", dir, sizeof dir, scene, sizeof scene);
	snprintf(file, sizeof file, "%s/freq.lua", dir);
	snprintf(buf, sizeof buf,
	         "return study {\n name = 'freq', title = 'q',\n"
	         " reference = { analytic = function(p) return tonumber(p.omega) end },\n"
	         " metric = { kind = 'frequency', field = 'q', label = 'e' },\n duration = 1.7,\n"
	         " methods = { method { name = 'A', scene = '%s', resolution = 'omega',\n"
	         "  sweep = { omega = { 7, 7.5 } } } },\n}\n",
	         scene);
	write_file(file, buf);
	snprintf(out, sizeof out, "%s/out", dir);
	snprintf(cmd, sizeof cmd, "%s/eddy study %s --out %s", test_build_dir(), file, out);
	int code = test_sh(cmd, buf, sizeof buf);
	CHECKF(code == 0, "%s exited %d:\n%s", cmd, code, buf);
	csv *c = malloc(sizeof *c);
	char path[400];
	snprintf(path, sizeof path, "%s/freq.csv", out);
	if (c && read_csv(path, c)) {
		const int err = column(c, "error");
		CHECK(c->rows == 2);
		for (int r = 0; r < c->rows; ++r) {
			printf("    q = 0.4 + cos(omega t), run %d: frequency error %s\n", r + 1, c->cell[r][err]);
			CHECKF(num(c, r, err) < 0.002, "row %d error %s", r + 1, c->cell[r][err]);
		}
	} else
		CHECKF(false, "no CSV at %s", path);
	free(c);
}

/* A method whose every run fails has no points: its chart block is not
 * written, so the next method's points are gnuplot's index 0 under their own
 * title. An empty block is not counted by gnuplot's index, so writing one
 * handed the failed method's title to the next method's points. */
static void study_chart_skips_a_method_with_no_run(void)
{
	char dir[256], scene[320], file[320], out[320], cmd[1200], buf[4096];
	wave_scene("skip", dir, sizeof dir, scene, sizeof scene);
	snprintf(file, sizeof file, "%s/skip.lua", dir);
	snprintf(buf, sizeof buf,
	         "return study {\n name = 'skip', title = 'q',\n"
	         " reference = { analytic = function(p) return tonumber(p.omega) end },\n"
	         " metric = { kind = 'frequency', field = 'q', label = 'e' },\n duration = 1.7,\n"
	         " methods = {\n"
	         "  method { name = 'Broken', scene = '%s', resolution = 'omega', set = { broken = 1 },\n"
	         "   sweep = { omega = { 7, 7.5 } } },\n"
	         "  method { name = 'A', scene = '%s', resolution = 'omega', sweep = { omega = { 7, 7.5 } } },\n"
	         " },\n}\n",
	         scene, scene);
	write_file(file, buf);
	snprintf(out, sizeof out, "%s/out", dir);
	snprintf(cmd, sizeof cmd, "%s/eddy study %s --out %s", test_build_dir(), file, out);
	const int code = test_sh(cmd, buf, sizeof buf);
	CHECKF(code == 1, "exit %d, expected 1 (a method's runs failed):\n%s", code, buf);
	CHECK_HAS(buf, "4 runs, 2 failed");
	char path[400];
	snprintf(path, sizeof path, "%s/skip.gp", out);
	CHECKF(test_file_has(path, "index 0 using 1:2 with linespoints pt 6 ps 1.5 lw 2 title \"A\""),
	       "%s: A's points are not index 0", path);
	CHECKF(!test_file_has(path, "title \"Broken\""), "%s: the failed method has a series", path);
}

/* Mistakes in a study file: one line, the file and the line of the mistake. */
static void bad_study_files(void)
{
	char dir[256], path[320], cmd[1024], buf[4096];
	snprintf(dir, sizeof dir, "%s/study_test", test_build_dir());
	snprintf(cmd, sizeof cmd, "mkdir -p %s", dir);
	test_sh(cmd, buf, sizeof buf);
	snprintf(path, sizeof path, "%s/bad.lua", dir);
	static const struct {
		const char *src, *expect;
	} cases[] = {
		{"return study {\n name = 'x', reference = { finest = true },\n metric = { kind = 'mean', field = 'q' },\n"
	     " methods = {\n  method { name = 'A', scene = 's.lua', sweeep = {} },\n },\n}\n",
	     "bad.lua:5: method: unknown field 'sweeep'"},
		{"return study {\n name = 3, reference = { finest = true },\n metric = { kind = 'mean', field = 'q' },\n"
	     " methods = {},\n}\n",
	     "bad.lua:2: study: 'name' must be a string (got number)"},
		{"return study {\n name = 'x', reference = { finest = true },\n metric = { kind = 'median', field = 'q' },\n"
	     " methods = { method { name = 'A', scene = 's.lua' } },\n}\n",
	     "bad.lua:3: study: metric kind 'median' is not one of"},
		{"local m = method { name = 'A', scene = 's.lua',\n sweep = { spacing = 0.01 } }\n",
	     "bad.lua:2: method 'A': sweep 'spacing' must be a non-empty list"},
		{"return 42\n", "must return study { ... }"},
		{"return study {\n name = 'x', reference = { finest = true },\n metric = { kind = 'mean', field = 'q' },\n"
	     " methods = {\n  method { name = 'A',\n   scene = 'scenes/nope.lua' },\n },\n}\n",
	     "bad.lua:6: method 'A': scene 'scenes/nope.lua' not found"},
	};
	for (size_t i = 0; i < sizeof cases / sizeof cases[0]; ++i) {
		write_file(path, cases[i].src);
		snprintf(cmd, sizeof cmd, "%s/eddy study %s --out %s/bad_out", test_build_dir(), path, dir);
		int code = test_sh(cmd, buf, sizeof buf);
		CHECKF(code == 1, "case %zu: exit %d", i, code);
		CHECK_HAS(buf, cases[i].expect);
		CHECKF(strchr(buf, '\n') == buf + strlen(buf) - 1, "case %zu: not one line: %s", i, buf);
	}
	snprintf(cmd, sizeof cmd, "%s/eddy study", test_build_dir());
	CHECK(test_sh(cmd, buf, sizeof buf) == 2);
	CHECK_HAS(buf, "study needs a study file");
	snprintf(cmd, sizeof cmd, "%s/eddy study --help", test_build_dir());
	CHECK(test_sh(cmd, buf, sizeof buf) == 0);
	CHECK_HAS(buf, "--quick");
	snprintf(cmd, sizeof cmd, "%s/eddy study x.lua --fast", test_build_dir());
	CHECK(test_sh(cmd, buf, sizeof buf) == 2);
	CHECK_HAS(buf, "unknown option '--fast'");
}

/* A command whose Lua driver is not where it looks (a copy of the binary
 * outside the tree) says so in one line, not Lua's list of searched paths. */
static void missing_driver_is_one_line(void)
{
	const char *b = test_build_dir();
	char cmd[1024], buf[4096];
	snprintf(cmd, sizeof cmd,
	         "rm -rf %s/t_lonely && mkdir -p %s/t_lonely/a/b && cp %s/eddy %s/t_lonely/a/b/eddy && "
	         "%s/t_lonely/a/b/eddy study scenes/studies/dam_break.lua --quick",
	         b, b, b, b, b);
	CHECK(test_sh(cmd, buf, sizeof buf) == 1);
	CHECK_HAS(buf, "eddy: study: its Lua driver eddy/study.lua is not installed (looked in ");
	CHECKF(strchr(buf, '\n') == buf + strlen(buf) - 1, "not one line: %s", buf);
	/* options take their value either way; flags take none */
	snprintf(cmd, sizeof cmd, "%s/eddy study --out=%s/t_lonely/o", b, b);
	CHECK(test_sh(cmd, buf, sizeof buf) == 2);
	CHECK_HAS(buf, "eddy: study needs a study file");
	snprintf(cmd, sizeof cmd, "%s/eddy study x.lua --quick=yes", b);
	CHECK(test_sh(cmd, buf, sizeof buf) == 2);
	CHECK_HAS(buf, "eddy: study: option '--quick' takes no value");
	snprintf(cmd, sizeof cmd, "%s/eddy study --help", b);
	CHECK(test_sh(cmd, buf, sizeof buf) == 0);
	CHECK_HAS(buf, "--safe");
}

void suite_study(void)
{
	RUN(frequency_metric_counts_whole_periods);
	RUN(study_chart_skips_a_method_with_no_run);
	RUN(bad_study_files);
	RUN(missing_driver_is_one_line);
	RUN(quick_dam_break_study);
	RUN(quick_convergence_study);
}
