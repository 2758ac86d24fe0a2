/* SPDX-License-Identifier: MIT */
#define _POSIX_C_SOURCE 200809L
#define _DEFAULT_SOURCE /* getloadavg */
/* Renderer benchmark (make bench-render, part of make bench): milliseconds per
 * rendered frame at 1280x720 for 10k, 100k, 1M and 10M particles, and at the
 * pour scene's 960x540 (supersample 2) for its 5625, with the world on 1 and
 * 2 threads (render_points draws in as many row bands), as JSON. Then the
 * PNG encoders on the pour-sized frame: CPU ms per encode (median of 15) and
 * bytes for stb_image_write at its default level, libpng at its defaults
 * (level 6, adaptive filters), libpng at level 1 with Z_RLE and the up
 * filter in memory, and render/png.c (those settings, to a file as
 * render_points writes it).
 *
 * Then the surface mesher on the pour (tests/scenes/pour_surface.lua through
 * the eddy command beside this program, 1 thread, no images): the medians
 * over its 120 frames of surface_ms and of the simulation's own time per
 * frame (the frame's wall_ms less the surface_mesh system's), and their
 * ratio (issue 16's target: below 1).
 *
 * Then what frames cost the pour itself (issue 17's target: within 1.3x):
 * `eddy run scenes/pour.lua --threads 1` with frames and without, in turns,
 * wall and CPU time (pour_frames in the JSON; not with --quick).
 *
 *   bench_render OUT.json            everything, JSON to OUT.json
 *   bench_render --quick             the pour-sized and 1M frames only, to stdout
 *   bench_render --encoders          the encoders only (on the frame a full run left), to stdout
 *   bench_render --pour              the pour's turns only, to stdout
 *
 * A frame is the whole render_points frame hook: colouring by speed, the
 * drawing and box filter (draw_ms), the PNG encoding and writing (png_ms);
 * cpu_ms is the process CPU time of the frame, all threads. Medians over
 * repeated frames; the first * frame (context and shader set-up) is reported apart. */
#include <math.h>
#include <stdbool.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <sys/resource.h>
#include <sys/stat.h>

#include <png.h>
#include <zlib.h>

#define STB_IMAGE_IMPLEMENTATION
#define STBI_ONLY_PNG
#include <stb/stb_image.h>
#define STB_IMAGE_WRITE_IMPLEMENTATION
#define STB_IMAGE_WRITE_STATIC
#include <stb/stb_image_write.h>

#include "eddy.h"
#include "bench_util.h"
#include "../render/render.h" /* eddy_write_png */

/* CPU time of the whole process (all llvmpipe threads): on a shared machine
 * it moves less with other people's load than wall time does. */
static double cpu_ms(void)
{
	struct timespec ts;
	clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
	return (double)ts.tv_sec * 1e3 + (double)ts.tv_nsec * 1e-6;
}

static double extra(const eddy_frame_stats *s, const char *name)
{
	for (int i = 0; i < s->extra_count; ++i)
		if (strcmp(s->extra[i].name, name) == 0)
			return s->extra[i].value;
	return NAN;
}

/* n particles filling the lower half of the unit box (a resting pool, the
 * common case), jittered, with random velocities to colour by speed. */
static int run(FILE *json, bool *first_row, int n, int width, int height, int supersample, int threads)
{
	eddy_world_def wd = eddy_default_world_def();
	wd.threads = threads;
	char err[256];
	eddy_world *w = eddy_create_world(&wd, err, sizeof err);
	if (!w) {
		fprintf(stderr, "bench_render: %s\n", err);
		return 1;
	}
	eddy_render_points_def d = eddy_default_render_points_def();
	d.width = width;
	d.height = height;
	d.supersample = supersample;
	const float spacing = cbrtf(0.5f / (float)n);
	d.radius = 0.6f * spacing;
	snprintf(d.path, sizeof d.path, "build/bench_render/frame_%dx%d_%d_%%d.png", width, height, n);
	if (!eddy_system_valid(w, eddy_add_render_points(w, &d))) {
		fprintf(stderr, "bench_render: %s\n", eddy_world_error(w));
		return 1;
	}
	eddy_vec3 *p = malloc((size_t)n * sizeof *p), *v = malloc((size_t)n * sizeof *v);
	uint64_t s = 12345;
	for (int i = 0; i < n; ++i) {
		float r[6];
		for (int k = 0; k < 6; ++k) {
			s = s * 6364136223846793005ull + 1442695040888963407ull;
			r[k] = (float)(s >> 40) / (float)(1 << 24);
		}
		p[i] = (eddy_vec3){r[0], 0.5f * r[1], r[2]};
		v[i] = (eddy_vec3){r[3] - 0.5f, r[4] - 0.5f, r[5] - 0.5f};
	}
	eddy_world_add_particles(w, (size_t)n, p, v);
	free(p);
	free(v);
	const int frames = n >= 10000000 ? 3 : n >= 1000000 ? 5 : 9;
	double frame_ms[16], gl_ms[16], png_ms[16], cpu[16], first = 0;
	for (int f = 0; f <= frames; ++f) {
		const double c0 = cpu_ms();
		eddy_status st_frame = eddy_world_step_frame(w);
		const double c1 = cpu_ms();
		if (st_frame != EDDY_OK) {
			fprintf(stderr, "bench_render: %s\n", eddy_world_error(w));
			return 1;
		}
		eddy_frame_stats st;
		eddy_world_frame_stats(w, &st);
		double ms = NAN;
		for (int k = 0; k < st.system_count; ++k)
			if (strncmp(st.system_names[k], "render_points", 13) == 0)
				ms = st.system_ms[k];
		if (f == 0) {
			first = ms;
			continue;
		}
		frame_ms[f - 1] = ms;
		cpu[f - 1] = c1 - c0;
		gl_ms[f - 1] = extra(&st, "render_ms");
		png_ms[f - 1] = extra(&st, "png_ms");
	}
	char line[512];
	snprintf(line, sizeof line,
	         "{\"particles\":%d,\"width\":%d,\"height\":%d,\"supersample\":%d,\"threads\":%d,\"frames\":%d,"
	         "\"frame_ms_median\":%.1f,\"draw_ms_median\":%.1f,\"png_ms_median\":%.1f,\"cpu_ms_median\":%.1f,"
	         "\"first_frame_ms\":%.1f}",
	         n, width, height, supersample, threads, frames, median(frame_ms, frames), median(gl_ms, frames),
	         median(png_ms, frames), median(cpu, frames), first);
	printf("%s\n", line);
	fflush(stdout);
	if (json)
		fprintf(json, "%s\n  %s", *first_row ? "" : ",", line);
	*first_row = false;
	eddy_destroy_world(w);
	return 0;
}

/* ---- PNG encoders on one frame ---- */

static double thread_cpu_ms(void)
{
	struct timespec ts;
	clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
	return (double)ts.tv_sec * 1e3 + (double)ts.tv_nsec * 1e-6;
}

typedef struct membuf {
	unsigned char *p;
	size_t n, cap;
} membuf;

static void membuf_put(membuf *b, const void *data, size_t n)
{
	if (b->n + n > b->cap) {
		size_t cap = 2 * (b->n + n);
		unsigned char *p = realloc(b->p, cap);
		if (!p)
			abort(); /* a benchmark: no recovery */
		b->p = p, b->cap = cap;
	}
	memcpy(b->p + b->n, data, n);
	b->n += n;
}

static void stb_put(void *ctx, void *data, int n) { membuf_put(ctx, data, (size_t)n); }
static void png_put(png_structp p, png_bytep data, size_t n) { membuf_put(png_get_io_ptr(p), data, n); }
static void png_flush_none(png_structp p) { (void)p; }

/* fast: render/png.c's settings; otherwise libpng's defaults. Returns bytes. */
static size_t libpng_encode(const unsigned char *rgb, int w, int h, bool fast)
{
	membuf b = {NULL, 0, 0};
	png_structp p = png_create_write_struct(PNG_LIBPNG_VER_STRING, NULL, NULL, NULL);
	png_infop info = png_create_info_struct(p);
	if (setjmp(png_jmpbuf(p)))
		abort();
	png_set_write_fn(p, &b, png_put, png_flush_none);
	png_set_IHDR(p, info, (png_uint_32)w, (png_uint_32)h, 8, PNG_COLOR_TYPE_RGB, PNG_INTERLACE_NONE,
	             PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
	if (fast) {
		png_set_compression_level(p, 1);
		png_set_compression_strategy(p, Z_RLE);
		png_set_filter(p, PNG_FILTER_TYPE_BASE, PNG_FILTER_UP);
	}
	png_write_info(p, info);
	for (int y = 0; y < h; ++y)
		png_write_row(p, rgb + (size_t)y * (size_t)w * 3);
	png_write_end(p, info);
	png_destroy_write_struct(&p, &info);
	free(b.p);
	return b.n;
}

static size_t stb_encode(const unsigned char *rgb, int w, int h)
{
	membuf b = {NULL, 0, 0};
	stbi_write_png_to_func(stb_put, &b, w, h, 3, rgb, w * 3);
	free(b.p);
	return b.n;
}

static int encoders(FILE *f, const char *frame)
{
	int w = 0, h = 0, comp = 0;
	unsigned char *rgb = stbi_load(frame, &w, &h, &comp, 3);
	if (!rgb) {
		fprintf(stderr, "bench_render: cannot read %s back\n", frame);
		return 1;
	}
	const char *names[4] = {"stb_image_write level 8", "libpng defaults (level 6, adaptive filters)",
	                        "libpng level 1, Z_RLE, up", "eddy (render/png.c: libpng level 1, Z_RLE, up, to a file)"};
	enum { REPS = 15 };
	for (int e = 0; e < 4; ++e) {
		double ms[REPS];
		size_t bytes = 0;
		for (int r = 0; r < REPS; ++r) {
			const double t0 = thread_cpu_ms();
			if (e == 3) {
				/* eddy's writer, to a file as render_points writes it */
				const char *path = "build/bench_render/encoder.png";
				struct stat st;
				if (eddy_write_png(path, w, h, rgb) != 0 || stat(path, &st) != 0) {
					fprintf(stderr, "bench_render: cannot write %s\n", path);
					return 1;
				}
				bytes = (size_t)st.st_size;
			} else
				bytes = e == 0 ? stb_encode(rgb, w, h) : libpng_encode(rgb, w, h, e == 2);
			ms[r] = thread_cpu_ms() - t0;
		}
		char line[256];
		snprintf(line, sizeof line,
		         "{\"encoder\":\"%s\",\"width\":%d,\"height\":%d,\"cpu_ms_median\":%.2f,\"bytes\":%zu}", names[e], w, h,
		         median(ms, REPS), bytes);
		if (f)
			fprintf(f, "%s\n  %s", e ? "," : "", line);
		printf("%s\n", line);
	}
	stbi_image_free(rgb);
	return 0;
}

/* The number after "key": in a JSON line, NAN if absent. */
static double json_number(const char *line, const char *key)
{
	char pat[64];
	snprintf(pat, sizeof pat, "\"%s\":", key);
	const char *p = strstr(line, pat);
	return p ? strtod(p + strlen(pat), NULL) : NAN;
}

/* The eddy command beside this program (build/tests/.. -> build/eddy). */
static void eddy_beside(const char *argv0, char *eddy, size_t cap)
{
	snprintf(eddy, cap, "%s", argv0);
	char *slash = strrchr(eddy, '/');
	if (slash)
		*slash = '\0'; /* build/tests */
	slash = strrchr(eddy, '/');
	snprintf(slash ? slash + 1 : eddy, cap - (size_t)(slash ? slash + 1 - eddy : 0), "eddy");
	if (!slash)
		snprintf(eddy, cap, "build/eddy");
}

static double children_cpu_ms(void)
{
	struct rusage ru;
	getrusage(RUSAGE_CHILDREN, &ru);
	return (double)(ru.ru_utime.tv_sec + ru.ru_stime.tv_sec) * 1e3 +
	       (double)(ru.ru_utime.tv_usec + ru.ru_stime.tv_usec) * 1e-3;
}

/* What frames cost the pour (issue 17's target: within 1.3x): `eddy run
 * scenes/pour.lua --threads 1` with its frames and with --set render=false,
 * in turns (which goes first alternates), wall and CPU time of each run
 * (children's rusage), medians over TURNS pairs and of the pairs' ratios,
 * with the load average before and after. */
static int pour_frames_cost(FILE *json, const char *argv0)
{
	enum { TURNS = 5 };
	char eddy[1024], cmd[2][2400];
	eddy_beside(argv0, eddy, sizeof eddy);
	snprintf(cmd[0], sizeof cmd[0],
	         "'%s' run scenes/pour.lua --threads 1 --set render=false --quiet "
	         "--out build/bench_render/pour >/dev/null",
	         eddy);
	snprintf(cmd[1], sizeof cmd[1],
	         "'%s' run scenes/pour.lua --threads 1 --quiet --out build/bench_render/pour "
	         ">/dev/null",
	         eddy);
	double load0[3] = {0, 0, 0}, load1[3] = {0, 0, 0};
	getloadavg(load0, 3);
	double wall[2][TURNS], cpu[2][TURNS], rwall[TURNS], rcpu[TURNS];
	for (int t = 0; t < TURNS; ++t) {
		for (int k = 0; k < 2; ++k) {
			const int which = t % 2 ? 1 - k : k;
			const double w0 = now_ms(), c0 = children_cpu_ms();
			if (system(cmd[which]) != 0) {
				fprintf(stderr, "bench_render: %s failed\n", cmd[which]);
				return 1;
			}
			wall[which][t] = now_ms() - w0;
			cpu[which][t] = children_cpu_ms() - c0;
		}
		rwall[t] = wall[1][t] / wall[0][t];
		rcpu[t] = cpu[1][t] / cpu[0][t];
	}
	getloadavg(load1, 3);
	char out[768];
	snprintf(out, sizeof out,
	         "{\"scene\":\"scenes/pour.lua\",\"threads\":1,\"turns\":%d,\"wall_s_no_frames\":%.2f,"
	         "\"wall_s_frames\":%.2f,\"cpu_s_no_frames\":%.2f,\"cpu_s_frames\":%.2f,\"wall_ratio\":%.2f,"
	         "\"cpu_ratio\":%.2f,\"load_before\":%.1f,\"load_after\":%.1f}",
	         TURNS, median(wall[0], TURNS) / 1e3, median(wall[1], TURNS) / 1e3, median(cpu[0], TURNS) / 1e3,
	         median(cpu[1], TURNS) / 1e3, median(rwall, TURNS), median(rcpu, TURNS), load0[0], load1[0]);
	printf("%s\n", out);
	if (json)
		fprintf(json, "\n  %s", out);
	return 0;
}

/* The pour with surface_mesh: medians of the mesher's and the simulation's
 * ms per frame. */
static int surface_vs_step(FILE *json, const char *argv0)
{
	char eddy[1024], cmd[2400];
	eddy_beside(argv0, eddy, sizeof eddy);
	snprintf(cmd, sizeof cmd,
	         "'%s' run tests/scenes/pour_surface.lua --threads 1 --set render=false --quiet "
	         "--out build/bench_render/pour_surface --stats -",
	         eddy);
	FILE *p = popen(cmd, "r");
	if (!p) {
		perror("popen");
		return 1;
	}
	static double mesh[4096], sim[4096];
	int n = 0;
	static char line[1 << 16];
	while (fgets(line, sizeof line, p) && n < 4096) {
		const double m = json_number(line, "surface_ms"), wall = json_number(line, "wall_ms"),
					 sys = json_number(line, "surface_mesh");
		if (isnan(m) || isnan(wall) || isnan(sys))
			continue;
		mesh[n] = m;
		sim[n] = wall - sys;
		++n;
	}
	if (pclose(p) != 0 || n == 0) {
		fprintf(stderr, "bench_render: %s failed\n", cmd);
		return 1;
	}
	const double mm = median(mesh, n), sm = median(sim, n);
	char out[512];
	snprintf(out, sizeof out,
	         "{\"scene\":\"tests/scenes/pour_surface.lua\",\"threads\":1,\"frames\":%d,\"surface_ms_median\":%.1f,"
	         "\"step_ms_median\":%.1f,\"surface_over_step\":%.2f}",
	         n, mm, sm, mm / sm);
	printf("%s\n", out);
	if (json)
		fprintf(json, "\n  %s", out);
	return 0;
}

int main(int argc, char **argv)
{
	/* one part alone, to stdout: the encoders on the newest pour-sized frame, or the pour's turns */
	if (argc >= 2 && strcmp(argv[1], "--encoders") == 0)
		return encoders(NULL, "build/bench_render/frame_960x540_5625_9.png");
	if (argc >= 2 && strcmp(argv[1], "--pour") == 0)
		return pour_frames_cost(NULL, argv[0]);
	const bool quick = argc >= 2 && strcmp(argv[1], "--quick") == 0;
	const char *out = argc >= 2 && !quick ? argv[1] : "build/bench_render.json";
	FILE *f = quick ? NULL : fopen(out, "w");
	if (!quick && !f) {
		perror(out);
		return 1;
	}
	if (f)
		fprintf(f, "{\"benchmark\":\"render_points\",\"unit\":\"ms per frame (median)\",\"results\":[");
	bool first = true;
	const int sizes[4] = {10000, 100000, 1000000, 10000000};
	for (int t = 1; t <= 2; ++t) {
		/* the pour scene's frames: 5625 particles, 960x540, supersample 2 */
		if (run(f, &first, 5625, 960, 540, 2, t) != 0)
			return 1;
		for (int i = quick ? 2 : 0; i < (quick ? 3 : 4); ++i)
			if (run(f, &first, sizes[i], 1280, 720, 1, t) != 0)
				return 1;
		/* the default supersample 2 (an internal 2560x1440) at 1M */
		if (!quick && run(f, &first, 1000000, 1280, 720, 2, t) != 0)
			return 1;
	}
	if (quick)
		return 0;
	fprintf(f, "\n],\"encoders\":[");
	if (encoders(f, "build/bench_render/frame_960x540_5625_9.png") != 0)
		return 1;
	fprintf(f, "\n],\"surface\":[");
	if (surface_vs_step(f, argv[0]) != 0)
		return 1;
	fprintf(f, "\n],\"pour_frames\":[");
	if (pour_frames_cost(f, argv[0]) != 0)
		return 1;
	fprintf(f, "\n]}\n");
	fclose(f);
	printf("bench_render: results in %s\n", out);
	return 0;
}
