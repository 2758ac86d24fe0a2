/* SPDX-License-Identifier: MIT */
#define _POSIX_C_SOURCE 200809L
/* FLIP's volume with and without reseeding (eddy issue 13 item 5,
 * docs/validation.md hard case 13): a cube of water dropped into a pool and
 * Martin & Moyce's dam break (scenes/dam_break.lua --set method=flip), each
 * with flip_reseed off and on, at the tested grid and one step beyond
 * (coarser and finer grids, a longer run: suite long_flip_volume).
 *
 * What is measured:
 *   V, flip_pressure's published liquid volume, sum clamp((1 - phi)/2, 0, 1)
 *     dx^3 over the cells, against V0, the volume emitted. flip_p2g's marker
 *     phi is 1 - 2 f with f the fill fraction from the particle count, so V
 *     is what the particles carry (dx^3 / 8 each) as the surface sees it;
 *   N, the particle count: flip_reseed moves particles and never creates or
 *     deletes them, so N is exact by construction and is checked exactly;
 *   the settled pool's level, the mean height of phi's zero crossing over
 *     the columns (as tests/test_stress_flip_solids.c measures it), an
 *     independent check: packed particles (density above rest, which V
 *     partly hides under its clamp) would lower it, thinned ones raise it.
 * Tolerances:
 *   |V - V0| / V0 <= 3% at every frame. A binary marker (-1 in every cell
 *     holding a particle) counts each surface cell whole, an error of order
 *     half a cell over the depth (7% for this pool, 12.5% for the dam break's
 *     layer) that grows as the flow thins into more surface cells. The fill
 *     fraction has no such term; what is left is the volume in cells packed
 *     beyond the blur's reach of the clamp, which flip_pressure's volume
 *     correction drains within steps, and the blur's renormalisation at the
 *     walls: a few tenths of a percent at rest, about 1% in the dam break's
 *     wall impact (measured); 3% leaves room for a harsher splash.
 *   settled level within 0.15 dx of (pool + cube) / tank area: the surface
 *     is a zero crossing of a field sampled at the cell centres, and 0.15 dx
 *     is 2% of the 12-cell pool's depth at the tested grid. */
#include "test.h"

#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "eddy.h"
#include "flip_pool.h"

static double now_s(void)
{
	struct timespec t;
	clock_gettime(CLOCK_MONOTONIC, &t);
	return (double)t.tv_sec + 1e-9 * (double)t.tv_nsec;
}

/* ---- a drop into a pool (C API) ------------------------------------------- */

typedef struct drop_result {
	double worst, final, level, level_expected;
	size_t n0, n1;
	double wall_s;
	bool ok;
} drop_result;

/* Tank 0.2 x 0.3 x 0.1 m, pool 7.5 cm deep, a 5 cm cube whose bottom is
 * 10 cm above the pool (cell aligned for dx = 2.5, 1.25 and 0.625 cm); the
 * standard FLIP pipeline of eddy.fluid, closed by the domain's sides. */
static drop_result drop_into_pool(double h, bool reseed, double seconds)
{
	drop_result r;
	memset(&r, 0, sizeof r);
	eddy_world_def wd = eddy_default_world_def();
	wd.bounds_max = (eddy_vec3){0.2f, 0.3f, 0.1f};
	wd.cell_size = h;
	wd.cfl = 1;
	wd.dt_max = 1.0 / 60;
	wd.fps = 30;
	eddy_world *w = eddy_create_world(&wd, NULL, 0);
	CHECK(w != NULL);
	if (!w)
		return r;
	flip_defs fd = flip_default_defs();
	fd.extrapolate.layers = 3; /* eddy.fluid's: CFL 1 + 2 */
	CHECK(flip_add_pipeline(w, &fd));
	if (reseed) {
		eddy_flip_reseed_def rs = eddy_default_flip_reseed_def();
		CHECK(eddy_system_valid(w, eddy_add_flip_reseed(w, &rs)));
	}
	const double pool = 0.075, cube = 0.05, area = 0.2 * 0.1;
	CHECK(pool_fill(w, h, (eddy_vec3){0, 0, 0}, (eddy_vec3){0.2f, (float)pool, 0.1f}));
	CHECK(pool_fill(w, h, (eddy_vec3){0.075f, 0.175f, 0.025f}, (eddy_vec3){0.125f, 0.225f, 0.075f}));
	const double v0 = area * pool + cube * cube * cube;
	r.level_expected = v0 / area;
	r.n0 = eddy_world_particle_count(w);
	const int frames = (int)lround(seconds * 30);
	const double t0 = now_s();
	int f = 0;
	for (; f < frames; ++f) {
		if (eddy_world_step_frame(w) != EDDY_OK) {
			test_fail(__FILE__, __LINE__, "drop h = %g, reseed %d: %s", h, reseed, eddy_world_error(w));
			break;
		}
		eddy_frame_stats fs;
		eddy_world_frame_stats(w, &fs);
		r.final = (fs.volume - v0) / v0;
		r.worst = fmax(r.worst, fabs(r.final));
	}
	r.wall_s = now_s() - t0;
	r.ok = f == frames;
	r.n1 = eddy_world_particle_count(w);
	r.level = pool_mean_level(w);
	eddy_destroy_world(w);
	printf("    drop into pool, dx %.4g m, reseed %-3s %.0f s: max |V - V0| / V0 %.2f%%, at the end %+.2f%%; level "
	       "%.5f m, expected %.5f m (%+.3f dx); particles %zu -> %zu; %.1f s\n",
	       h, reseed ? "on," : "off,", seconds, 100 * r.worst, 100 * r.final, r.level, r.level_expected,
	       (r.level - r.level_expected) / h, r.n0, r.n1, r.wall_s);
	return r;
}

static void check_drop(const drop_result *r, double h)
{
	CHECK(r->ok);
	CHECK(r->worst <= 0.03);
	CHECK(r->n1 == r->n0); /* reseeding moves particles, never creates or deletes them */
	CHECK(fabs(r->level - r->level_expected) <= 0.15 * h);
}

/* dx = 1.25 cm (a pool 6 cells deep, a cube 4 cells wide: 6656 particles),
 * 2 s: the splash settles. */
static void drop_into_pool_keeps_volume(void)
{
	for (int rs = 0; rs < 2; ++rs) {
		const drop_result r = drop_into_pool(0.0125, rs == 1, 2.0);
		check_drop(&r, 0.0125);
	}
}

/* One step beyond, coarser: dx = 2.5 cm, the pool 3 cells deep and the cube
 * 2 cells wide (a surface cell is a third of the depth; 832 particles). */
static void drop_into_pool_coarse(void)
{
	for (int rs = 0; rs < 2; ++rs) {
		const drop_result r = drop_into_pool(0.025, rs == 1, 2.0);
		check_drop(&r, 0.025);
	}
}

/* One step beyond, finer and longer: dx = 6.25 mm (53k particles), 4 s. */
static void drop_into_pool_fine_long(void)
{
	for (int rs = 0; rs < 2; ++rs) {
		const drop_result r = drop_into_pool(0.00625, rs == 1, 4.0);
		check_drop(&r, 0.00625);
	}
}

/* ---- the dam break (scenes/dam_break.lua through the CLI) ----------------- */

typedef struct dam_result {
	double worst, final;
	double n0, n1;
	int frames;
	double wall_s;
} dam_result;

/* scenes/dam_break.lua --set method=flip (a = 0.1 m, the tank 5.5 a long, a
 * slab 4 cells thick, cells two spacings wide), at 30 fps for `seconds`. */
static dam_result dam_break(const char *spacing, bool reseed, double seconds)
{
	dam_result r = {0, 0, NAN, NAN, 0, 0};
	char out[256], cmd[4096], buf[8192];
	snprintf(out, sizeof out, "%s/stress_flip_volume/dam_%s_%d_%g", test_build_dir(), spacing, reseed, seconds);
	snprintf(cmd, sizeof cmd,
	         "rm -rf %s && mkdir -p %s && %s/eddy run scenes/dam_break.lua --quiet --set render=false "
	         "--set method=flip --set spacing=%s --set reseed=%s --set fps=30 --duration %g --out %s "
	         "--stats %s/stats.jsonl",
	         out, out, test_build_dir(), spacing, reseed ? "true" : "false", seconds, out, out);
	const double t0 = now_s();
	const int code = test_sh(cmd, buf, sizeof buf);
	r.wall_s = now_s() - t0;
	CHECKF(code == 0, "%s exited %d:\n%s", cmd, code, buf);
	char path[600];
	snprintf(path, sizeof path, "%s/stats.jsonl", out);
	FILE *f = fopen(path, "r");
	CHECKF(f != NULL, "no stats at %s", path);
	if (!f)
		return r;
	/* V0 = a x 2a x the slab's width (4 cells of 2 spacings) */
	const double a = 0.1, v0 = a * 2 * a * 4 * 2 * atof(spacing);
	static char line[65536];
	while (fgets(line, sizeof line, f)) {
		const double v = test_json_number(line, "volume"), n = test_json_number(line, "particles");
		CHECKF(isfinite(v) && isfinite(n), "frame %d: no volume or particle count", r.frames + 1);
		if (r.frames++ == 0)
			r.n0 = n;
		r.n1 = n;
		r.final = (v - v0) / v0;
		r.worst = fmax(r.worst, fabs(r.final));
	}
	fclose(f);
	printf("    dam break, spacing %s m, reseed %-3s %g s: max |V - V0| / V0 %.2f%%, at the end %+.2f%%; particles "
	       "%.0f -> %.0f; %.1f s\n",
	       spacing, reseed ? "on," : "off,", seconds, 100 * r.worst, 100 * r.final, r.n0, r.n1, r.wall_s);
	return r;
}

static void check_dam(const dam_result *r, double seconds)
{
	CHECK(r->frames == (int)lround(seconds * 30));
	CHECK(r->worst <= 0.03);
	CHECK(r->n1 == r->n0);
}

/* spacing 5 mm (6400 particles, cells 1 cm), 1 s: the surge runs the tank
 * (5.5 a) in about 0.35 s, climbs the far wall and falls back, the most
 * violent phase of the run. */
static void dam_break_keeps_volume(void)
{
	for (int rs = 0; rs < 2; ++rs) {
		const dam_result r = dam_break("0.005", rs == 1, 1.0);
		check_dam(&r, 1.0);
	}
}

/* One step beyond: the 25600-particle dam break (spacing 2.5 mm) for
 * 2 s, and the 5 mm one for 6 s (the water sloshing in a layer 2a/5.5 deep,
 * under 4 cells). */
static void dam_break_fine_and_long(void)
{
	for (int rs = 0; rs < 2; ++rs) {
		const dam_result r = dam_break("0.0025", rs == 1, 2.0);
		check_dam(&r, 2.0);
	}
	for (int rs = 0; rs < 2; ++rs) {
		const dam_result r = dam_break("0.005", rs == 1, 6.0);
		check_dam(&r, 6.0);
	}
}

void suite_stress_flip_volume(void)
{
	RUN(drop_into_pool_keeps_volume);
	RUN(drop_into_pool_coarse);
	RUN(dam_break_keeps_volume);
}

void suite_long_flip_volume(void)
{
	RUN(drop_into_pool_fine_long);
	RUN(dam_break_fine_and_long);
}
