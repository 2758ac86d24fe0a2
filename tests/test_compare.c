/* SPDX-License-Identifier: MIT */
#define _POSIX_C_SOURCE 200809L
/* `eddy compare` end to end on tests/scenes/compare_tiny.lua (a block of water
 * in a small tank, 160 x 120 frames): wcsph and flip run and a method the
 * scene rejects ("broken") fails. The side-by-side frames have one panel per
 * method, the failed one with its reason; the CSV and Markdown tables have a
 * row per method; the charts exist when gnuplot is there; the exit status is
 * 1 with a failed method and 0 without; the video goes through a stand-in
 * ffmpeg; usage errors are one line with status 2. The command runs the same
 * build's eddy as child processes, so under make asan they are sanitised too. */
#include "test.h"

#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

/* stb_image's implementation is compiled into this test binary by
 * tests/test_render.c; only the declarations here */
#include <stb/stb_image.h>

enum { MAX_ROWS = 8, MAX_COLS = 96, CELL = 256 };

typedef struct csv {
	int rows, cols;
	char head[MAX_COLS][CELL];
	char cell[MAX_ROWS][MAX_COLS][CELL];
} csv;

/* RFC 4180 fields: quoted ones may hold commas and doubled quotes. */
static bool read_csv(const char *path, csv *c)
{
	FILE *f = fopen(path, "r");
	if (!f)
		return false;
	memset(c, 0, sizeof *c);
	char line[16384];
	int r = -1;
	while (fgets(line, sizeof line, f) && r < MAX_ROWS) {
		line[strcspn(line, "\r\n")] = '\0';
		int col = 0;
		const char *p = line;
		for (;;) {
			char field[CELL];
			size_t n = 0;
			if (*p == '"') {
				for (++p; *p && !(p[0] == '"' && p[1] != '"'); ++p) {
					if (p[0] == '"')
						++p; /* a doubled quote */
					if (n + 1 < CELL)
						field[n++] = *p;
				}
				if (*p == '"')
					++p;
			} else {
				for (; *p && *p != ','; ++p)
					if (n + 1 < CELL)
						field[n++] = *p;
			}
			field[n] = '\0';
			if (col < MAX_COLS)
				memcpy(r < 0 ? c->head[col] : c->cell[r][col], field, n + 1);
			col++;
			if (*p != ',')
				break;
			++p;
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

static const char *cell(const csv *c, int row, const char *name)
{
	int col = column(c, name);
	return col < 0 ? "" : c->cell[row][col];
}

static double num(const csv *c, int row, const char *name)
{
	const char *s = cell(c, row, name);
	return s[0] ? strtod(s, NULL) : NAN;
}

static int row_of(const csv *c, const char *method)
{
	for (int r = 0; r < c->rows; ++r)
		if (strcmp(cell(c, r, "method"), method) == 0)
			return r;
	return -1;
}

static bool is_png(const char *path)
{
	unsigned char sig[8] = {0};
	FILE *f = fopen(path, "rb");
	if (!f)
		return false;
	size_t n = fread(sig, 1, sizeof sig, f);
	fclose(f);
	return n == 8 && memcmp(sig, "\x89PNG\r\n\x1a\n", 8) == 0;
}

static bool have(const char *tool)
{
	char cmd[128], buf[256];
	snprintf(cmd, sizeof cmd, "command -v %s", tool);
	return test_sh(cmd, buf, sizeof buf) == 0;
}

/* wcsph, flip and broken: exit 1 after writing everything. */
static void compare_three_methods(void)
{
	const char *b = test_build_dir();
	char out[256], cmd[1024], buf[16384], path[512];
	snprintf(out, sizeof out, "%s/t_compare", b);
	snprintf(cmd, sizeof cmd,
	         "rm -rf %s && %s/eddy compare tests/scenes/compare_tiny.lua --methods wcsph,flip,broken "
	         "--quick --out %s",
	         out, b, out);
	int code = test_sh(cmd, buf, sizeof buf);
	CHECKF(code == 1, "exit %d, expected 1 (a method failed):\n%s", code, buf);
	CHECK_HAS(buf, "3 methods, 1 failed");
	CHECK_HAS(buf, "FAILED (status 1)");
	if (!have("ffmpeg"))
		CHECK_HAS(buf, "eddy: compare: ffmpeg not found, no compare.mp4");

	/* --quick: 6 frames, each 3 panels of 160 x 120 */
	for (int frame = 1; frame <= 6; ++frame) {
		snprintf(path, sizeof path, "%s/frame_%04d.png", out, frame);
		int w = 0, h = 0, comp = 0;
		unsigned char *px = stbi_load(path, &w, &h, &comp, 3);
		CHECKF(px != NULL, "%s: cannot read", path);
		if (!px)
			continue;
		CHECKF(w == 3 * 160 && h == 120, "%s is %d x %d, expected 480 x 120", path, w, h);
		/* each panel's caption: white text at its top left; the failed
		 * method's panel is background below its text, the others drew the
		 * tank and the water */
		for (int p = 0; p < 3 && w == 480; ++p) {
			int white = 0, lit = 0;
			for (int y = 0; y < 40; ++y)
				for (int x = p * 160; x < p * 160 + 120; ++x) {
					const unsigned char *q = px + ((size_t)y * (size_t)w + (size_t)x) * 3;
					white += q[0] == 255 && q[1] == 255 && q[2] == 255;
				}
			for (int y = 80; y < 120; ++y)
				for (int x = p * 160 + 20; x < p * 160 + 140; ++x) {
					const unsigned char *q = px + ((size_t)y * (size_t)w + (size_t)x) * 3;
					lit += abs(q[0] - 40) + abs(q[1] - 40) + abs(q[2] - 48) > 30;
				}
			CHECKF(white > 20, "%s panel %d: no caption (%d white pixels)", path, p, white);
			if (p < 2)
				CHECKF(lit > 100, "%s panel %d: no frame drawn (%d pixels off the background)", path, p, lit);
			else
				CHECKF(lit == 0, "%s panel %d (broken): %d pixels off the background", path, p, lit);
		}
		stbi_image_free(px);
	}
	snprintf(path, sizeof path, "%s/frame_0007.png", out);
	struct stat st;
	CHECKF(stat(path, &st) != 0, "%s exists: more frames than --quick runs", path);

	csv *c = malloc(sizeof *c);
	snprintf(path, sizeof path, "%s/compare.csv", out);
	if (c && read_csv(path, c)) {
		CHECKF(c->rows == 3, "%d rows, expected 3", c->rows);
		static const char *const cols[] = {"method",
		                                   "status",
		                                   "exit_code",
		                                   "wall_s",
		                                   "frames",
		                                   "sim_time_s",
		                                   "steps",
		                                   "dt_mean_s",
		                                   "dt_max_s",
		                                   "peak_mb",
		                                   "particles",
		                                   "sys_sph_density_ms",
		                                   "sys_flip_pressure_ms",
		                                   "density_err_avg_end",
		                                   "density_err_avg_worst",
		                                   "volume_end",
		                                   "max_speed_end",
		                                   "max_speed_worst",
		                                   "top_end",
		                                   "top_worst"};
		for (size_t i = 0; i < sizeof cols / sizeof cols[0]; ++i)
			CHECKF(column(c, cols[i]) >= 0, "compare.csv has no column '%s'", cols[i]);
		static const char *const ok[] = {"wcsph", "flip"};
		for (int i = 0; i < 2; ++i) {
			int r = row_of(c, ok[i]);
			CHECKF(r >= 0, "no row for %s", ok[i]);
			if (r < 0)
				continue;
			CHECKF(strcmp(cell(c, r, "status"), "ok") == 0, "%s: status '%s'", ok[i], cell(c, r, "status"));
			CHECK(num(c, r, "frames") == 6);
			CHECK(num(c, r, "steps") >= 6);
			CHECK(num(c, r, "wall_s") > 0);
			CHECK(num(c, r, "peak_mb") > 1);
			CHECK(num(c, r, "particles") == 300);
			CHECK_NEAR(num(c, r, "sim_time_s"), 0.2, 1e-6);
			CHECK_NEAR(num(c, r, "dt_mean_s"), 0.2 / num(c, r, "steps"), 1e-5 * num(c, r, "dt_mean_s"));
			CHECK(num(c, r, "dt_max_s") >= num(c, r, "dt_mean_s") * (1 - 1e-6));
			CHECK(num(c, r, "max_speed_worst") >= num(c, r, "max_speed_end"));
			CHECK(num(c, r, "top_worst") > 0.03);
		}
		int wc = row_of(c, "wcsph"), fl = row_of(c, "flip");
		if (wc >= 0 && fl >= 0) {
			/* each method's own systems and measurements; the other's are empty */
			CHECK(num(c, wc, "sys_sph_density_ms") > 0 && isnan(num(c, fl, "sys_sph_density_ms")));
			CHECK(num(c, fl, "sys_flip_pressure_ms") > 0 && isnan(num(c, wc, "sys_flip_pressure_ms")));
			CHECK(num(c, wc, "density_err_avg_end") > 0 && isnan(num(c, fl, "density_err_avg_end")));
			CHECK(num(c, fl, "volume_end") > 0);
		}
		int br = row_of(c, "broken");
		CHECKF(br >= 0, "no row for broken");
		if (br >= 0) {
			CHECKF(strncmp(cell(c, br, "status"), "failed: ", 8) == 0, "broken: status '%s'", cell(c, br, "status"));
			CHECK_HAS(cell(c, br, "status"), "compare_tiny.lua:");
			CHECK_HAS(cell(c, br, "status"), "fails on purpose");
			CHECK(num(c, br, "exit_code") == 1);
			CHECK(num(c, br, "frames") == 0);
		}
	} else {
		CHECKF(false, "no CSV at %s", path);
	}
	free(c);

	snprintf(path, sizeof path, "%s/compare.md", out);
	CHECKF(test_file_has(path, "| wcsph | ok |"), "%s: no ok row for wcsph", path);
	CHECKF(test_file_has(path, "| broken | failed: "), "%s: no failed row for broken", path);
	CHECKF(test_file_has(path, "| sph_density |"), "%s: no time of sph_density", path);
	CHECKF(test_file_has(path, "| top |"), "%s: no measurement of the scene's own field", path);
	if (have("gnuplot")) {
		snprintf(path, sizeof path, "%s/compare_max_speed.png", out);
		CHECKF(is_png(path), "%s is not a PNG", path);
		snprintf(path, sizeof path, "%s/compare_cost.png", out);
		CHECKF(is_png(path), "%s is not a PNG", path);
	}
}

/* Every method runs: exit 0; --field charts a field of the scene's own; with
 * ffmpeg on PATH (a stand-in that keeps what it is fed) the panels are piped
 * to it as PNG images, as eddy run --video does. */
static void compare_all_ok_with_video(void)
{
	const char *b = test_build_dir();
	char out[256], cmd[2048], buf[16384], path[512];
	/* a folder name long enough that the runs' image paths are cut short in
	 * their stats lines (63 characters): the frames are then found by number */
	snprintf(out, sizeof out, "%s/t_compare_ok_in_a_folder_whose_name_is_longer_than_stats_texts", b);
	snprintf(cmd, sizeof cmd,
	         "rm -rf %s && mkdir -p %s/bin && printf '#!/bin/sh\\nfor a; do last=$a; done\\n"
	         "cat > \"$last\"\\n' > %s/bin/ffmpeg && chmod +x %s/bin/ffmpeg && PATH=%s/bin:$PATH %s/eddy compare "
	         "tests/scenes/compare_tiny.lua --methods=flip,wcsph --quick --field top --set spacing=0.01 --out %s",
	         out, out, out, out, out, b, out);
	int code = test_sh(cmd, buf, sizeof buf);
	CHECKF(code == 0, "exit %d, expected 0:\n%s", code, buf);
	CHECK_HAS(buf, "2 methods, 0 failed");
	snprintf(path, sizeof path, "%s/compare.mp4", out);
	CHECKF(is_png(path), "%s: the stand-in ffmpeg was not fed PNG frames", path);
	snprintf(cmd, sizeof cmd, "grep -c 'IHDR' %s", path);
	test_sh(cmd, buf, sizeof buf);
	CHECKF(atoi(buf) >= 1, "%s: %s", path, buf);
	if (have("gnuplot")) {
		snprintf(path, sizeof path, "%s/compare_top.png", out);
		CHECKF(is_png(path), "%s is not a PNG", path);
	}
	snprintf(path, sizeof path, "%s/runs/flip/stats.jsonl", out);
	CHECKF(test_file_has(path, "\"frame\":6,"), "%s: no sixth frame", path);
	CHECKF(!test_file_has(path, "frame_0001.png"), "%s: the image path was not cut short; make the folder name longer",
	       path);
	for (int frame = 1; frame <= 6; ++frame) {
		snprintf(path, sizeof path, "%s/frame_%04d.png", out, frame);
		int w = 0, h = 0, comp = 0;
		CHECKF(stbi_info(path, &w, &h, &comp) && w == 320 && h == 120, "%s: %d x %d, expected 320 x 120", path, w, h);
	}
	snprintf(path, sizeof path, "%s/compare.md", out);
	CHECKF(!test_file_has(path, "failed"), "%s: a method failed", path);
}

/* A run's warnings reach compare.md: DFSPH's nozzle pouring into the small
 * closed tank holds points back by 0.15 s (tests/scenes/fill_tank.lua), and
 * the scene's endless nozzle draws the preflight's memory warning. Before,
 * the children ran --quiet and their warnings were lost. */
static void compare_lists_warnings(void)
{
	const char *b = test_build_dir();
	char out[256], cmd[1024], buf[8192], path[512];
	snprintf(out, sizeof out, "%s/compare_warnings", test_out_dir());
	snprintf(cmd, sizeof cmd,
	         "rm -rf %s && %s/eddy compare tests/scenes/fill_tank.lua --methods dfsph --quick --out %s 2>&1", out, b,
	         out);
	int code = test_sh(cmd, buf, sizeof buf);
	CHECKF(code == 0, "exit %d, expected 0:\n%s", code, buf);
	snprintf(path, sizeof path, "%s/compare.md", out);
	CHECKF(test_file_has(path, "## Warnings"), "%s: no warnings section", path);
	CHECKF(test_file_has(path, "- dfsph: emit_nozzle: water at its opening at step"), "%s: no nozzle warning", path);
	CHECKF(test_file_has(path, "- dfsph: memory: an emitter has no end"), "%s: no preflight warning", path);
	CHECKF(test_file_has(path, "| warnings | 1 / 1 |"), "%s: no warnings count", path);
}

/* Usage errors: one line, status 2, before anything runs; --help: status 0. */
static void compare_usage_errors(void)
{
	const char *b = test_build_dir();
	static const struct {
		const char *args, *expect;
	} cases[] = {
		{"", "eddy: compare: needs a scene file"},
		{"tests/scenes/compare_tiny.lua --methods 'wc sph'", "'wc sph' is not a method name"},
		{"tests/scenes/compare_tiny.lua --methods wcsph,,flip", "--methods expects names separated by commas"},
		{"tests/scenes/compare_tiny.lua --methods flip,flip", "'flip' is given twice"},
		{"tests/scenes/compare_tiny.lua --set method=flip", "the method is chosen by --methods"},
		{"tests/scenes/compare_tiny.lua --set spacing", "--set expects KEY=VALUE"},
		{"tests/scenes/compare_tiny.lua --fast", "unknown option '--fast'"},
		{"tests/scenes/compare_tiny.lua --quick=yes", "option '--quick' takes no value"},
		{"tests/scenes/compare_tiny.lua --field", "--field needs a value"},
		{"tests/scenes/compare_tiny.lua --threads 0", "--threads must be an integer from 1 to 1024 (got '0')"},
		{"tests/scenes/compare_tiny.lua other.lua", "unexpected argument 'other.lua'"},
	};
	char cmd[1024], buf[4096];
	for (size_t i = 0; i < sizeof cases / sizeof cases[0]; ++i) {
		snprintf(cmd, sizeof cmd, "%s/eddy compare --out %s/t_compare_usage %s", b, b, cases[i].args);
		int code = test_sh(cmd, buf, sizeof buf);
		CHECKF(code == 2, "case %zu (%s): exit %d", i, cases[i].args, code);
		CHECK_HAS(buf, cases[i].expect);
		CHECKF(strchr(buf, '\n') == buf + strlen(buf) - 1, "case %zu: not one line: %s", i, buf);
	}
	snprintf(cmd, sizeof cmd, "test ! -e %s/t_compare_usage", b);
	CHECKF(test_sh(cmd, buf, sizeof buf) == 0, "a usage error created its output folder");
	snprintf(cmd, sizeof cmd, "%s/eddy compare --help", b);
	CHECK(test_sh(cmd, buf, sizeof buf) == 0);
	CHECK_HAS(buf, "usage: eddy compare SCENE.lua");
	CHECK_HAS(buf, "--frames 6");
	snprintf(cmd, sizeof cmd, "%s/eddy compare tests/scenes/no_such_scene.lua --quick --out %s/t_compare_usage", b, b);
	CHECK(test_sh(cmd, buf, sizeof buf) == 1);
	CHECK_HAS(buf, "eddy: compare: cannot read scene 'tests/scenes/no_such_scene.lua'");
}

/* A method that fails before its first frame writes no data block, and the
 * next method's points keep their own title: gnuplot's index counts only
 * blocks holding data, so an empty first block once gave flip's index 1 to
 * a file with one block (gnuplot failed, no max_speed chart), and in eddy
 * study's charts a method whose runs all failed would have handed its
 * title to the next method's points. */
static void compare_chart_skips_a_method_with_no_frame(void)
{
	const char *b = test_build_dir();
	char out[256], cmd[1024], buf[16384], path[512];
	snprintf(out, sizeof out, "%s/t_compare_skip", b);
	snprintf(cmd, sizeof cmd,
	         "rm -rf %s && %s/eddy compare tests/scenes/compare_tiny.lua --methods broken,flip --quick --out %s", out, b,
	         out);
	const int code = test_sh(cmd, buf, sizeof buf);
	CHECKF(code == 1, "exit %d, expected 1 (a method failed):\n%s", code, buf);
	CHECKF(strstr(buf, "gnuplot failed") == NULL, "%s", buf);
	snprintf(path, sizeof path, "%s/compare_max_speed.gp", out);
	CHECKF(test_file_has(path, "index 0 using 1:2 with linespoints lw 2 pt 7 title \"flip\""),
	       "%s: flip's points are not index 0", path);
	CHECKF(!test_file_has(path, "index 1"), "%s: a second block plotted", path);
	if (have("gnuplot")) {
		snprintf(path, sizeof path, "%s/compare_max_speed.png", out);
		struct stat st;
		CHECKF(stat(path, &st) == 0 && st.st_size > 1000, "%s: no chart", path);
	}
}

void suite_compare(void)
{
	RUN(compare_chart_skips_a_method_with_no_frame);
	RUN(compare_usage_errors);
	RUN(compare_three_methods);
	RUN(compare_all_ok_with_video);
	RUN(compare_lists_warnings);
}
