/* SPDX-License-Identifier: MIT */
#define _GNU_SOURCE
/* Scale benchmark (make bench-scale; not part of make test or CI), as JSON:
 *  - a block of about N particles settling on the floor of a tank twice as
 *    wide (N = 100k, 1M, 10M) for WCSPH, DFSPH and FLIP: ns per particle per
 *    step of the whole step (median of the timed steps), on 1 and 2 threads,
 *    the 2-thread speed-up as the median of paired ratios (1- and 2-thread
 *    runs alternate, as bench_sph's do: the host's load drifts), and the peak
 *    resident memory per particle (libraries' baseline included); also the
 *    process CPU time per particle per step, the steadier figure for 1-thread
 *    runs on a loaded host (for 2 threads it counts both, and OpenMP's
 *    spinning); and the setup's two steps (emission, the first kick): their
 *    seconds, per system, and the pressure solves' iterations;
 *  - FLIP's pressure solve on the wavy pool of tests/grid_fixture.h at 64^3,
 *    128^3 and 256^3 cells: iterations and seconds per solve for PCG,
 *    HYPRE and MG on 1 and 2 threads.
 * Every configuration runs in a fresh child process (this program re-executed
 * with --child), so its peak RSS is its own. A 10M run is attempted only when
 * the 1M run's bytes per particle, times 10M, fit in MemAvailable with a
 * quarter to spare; otherwise the row says it was skipped and why.
 *
 *   bench_scale [FILE] [--sizes 100000,1000000,10000000] [--methods wcsph,dfsph,flip]
 *               [--reps 3] [--steps 4] [--grids 64,128,256] [--no-pressure]
 *   bench_scale --child METHOD N THREADS STEPS [SOLVER]   one block run, a JSON line on stdout
 *                                     (SOLVER: FLIP's pressure solver, pcg (default), hypre or mg)
 *   bench_scale --pressure GRID SOLVER THREADS     one pressure run (pcg, hypre or mg), a JSON line
 * EDDY_SCALE_COARSE=1 runs sph_dfsph with coarse_grid on, EDDY_SCALE_WARM=1
 * with hydrostatic_start on (the velocity solve's first step from the rest
 * pressure instead of k = 0). */
#include <errno.h>
#include <stdint.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include "eddy.h"
#include "bench_util.h"
#include "grid_fixture.h"

static long maxrss_kb(void)
{
	struct rusage ru;
	getrusage(RUSAGE_SELF, &ru);
	return ru.ru_maxrss;
}

/* With EDDY_SCALE_COLUMNS: the peak RSS within the next stretch of work
 * alone (Linux: writing 5 to clear_refs resets VmHWM to the current RSS),
 * so a later step's peak shows apart from the first step's. */
static void hwm_reset(void)
{
	FILE *f = fopen("/proc/self/clear_refs", "w");
	if (f) {
		fputs("5", f);
		fclose(f);
	}
}

static long hwm_kb(void)
{
	FILE *f = fopen("/proc/self/status", "r");
	char line[256];
	long kb = -1;
	while (f && fgets(line, sizeof line, f))
		if (sscanf(line, "VmHWM: %ld", &kb) == 1)
			break;
	if (f)
		fclose(f);
	return kb;
}

/* Process CPU ms (all threads): on a loaded host a 1-thread run's CPU time
 * moves far less than its wall time. */
static double cpu_ms(void)
{
	struct timespec ts;
	clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
	return (double)ts.tv_sec * 1e3 + (double)ts.tv_nsec * 1e-6;
}

static double profile_ms(eddy_world *w, const char *name)
{
	double s = 0;
	for (int k = 0; k < eddy_world_system_count(w); ++k) {
		eddy_system_info info;
		eddy_world_system_info(w, eddy_world_system_at(w, k), &info);
		if (strcmp(info.name, name) == 0)
			s += info.profile_ms;
	}
	return s;
}

static double extra_stat(const eddy_frame_stats *st, const char *name)
{
	for (int k = 0; k < st->extra_count; ++k)
		if (strcmp(st->extra[k].name, name) == 0)
			return st->extra[k].value;
	return NAN;
}

/* A switch in the environment: set, and neither empty nor "0" (so that
 * EDDY_SCALE_COARSE= or =0 turns it off, as a user would expect). */
static bool env_on(const char *name)
{
	const char *v = getenv(name);
	return v && *v && strcmp(v, "0") != 0;
}

/* FLIP pressure solver by name: "hypre", "mg", otherwise PCG */
static eddy_flip_solver solver_of(const char *name)
{
	return strcmp(name, "hypre") == 0 ? EDDY_FLIP_HYPRE : strcmp(name, "mg") == 0 ? EDDY_FLIP_MG : EDDY_FLIP_PCG;
}

/* A cube of about n particles at spacing dx = 1 cm on the floor of a tank
 * twice as wide and 1.5 times as tall, as bench_sph's block, for method
 * "wcsph", "dfsph" or "flip" (cells 2 dx wide, 8 particles each, the
 * defaults of eddy.fluid). EDDY_SCALE_LAYERS=L makes it a square slab L
 * particles deep instead: the cost of size at a fixed depth, apart from
 * DFSPH's tolerance, which tightens with the depth. */
static eddy_world *block(const char *method, long n, int threads, eddy_flip_solver solver)
{
	const bool flip = strcmp(method, "flip") == 0, dfsph = strcmp(method, "dfsph") == 0;
	const int layers = env_on("EDDY_SCALE_LAYERS") ? atoi(getenv("EDDY_SCALE_LAYERS")) : 0;
	const float dx = 0.01f,
				depth_n = layers > 1 ? (float)layers
	                      : layers   ? 1.0f
	                                 : roundf(cbrtf((float)n)),
				/* + 0.5: a whole number of spacings after floor */
		side = dx * (roundf(sqrtf((float)n / depth_n)) + 0.5f), height = dx * (depth_n + 0.5f);
	eddy_world_def d = eddy_default_world_def();
	d.bounds_max = (eddy_vec3){2 * side, 1.5f * height, 2 * side};
	d.threads = threads;
	d.fps = 1000;
	d.cfl = flip || dfsph ? 1.0 : 0.4;
	if (flip)
		d.cell_size = 2 * dx;
	eddy_world *w = eddy_create_world(&d, NULL, 0);
	if (!w)
		return NULL;
	eddy_emit_box_def b = eddy_default_emit_box_def();
	b.min = (eddy_vec3){0.5f * side, 0, 0.5f * side};
	b.max = (eddy_vec3){1.5f * side, height, 1.5f * side};
	b.spacing = dx;
	eddy_add_emit_box(w, &b);
	eddy_gravity_def g = eddy_default_gravity_def();
	if (flip) {
		eddy_add_gravity(w, &g);
		eddy_flip_p2g_def p = eddy_default_flip_p2g_def();
		eddy_add_flip_p2g(w, &p);
		eddy_flip_boundary_def bd = eddy_default_flip_boundary_def();
		eddy_add_flip_boundary(w, &bd);
		eddy_flip_surface_def sf = eddy_default_flip_surface_def();
		eddy_add_flip_surface(w, &sf);
		eddy_flip_pressure_def pr = eddy_default_flip_pressure_def();
		pr.solver = solver;
		eddy_add_flip_pressure(w, &pr);
		eddy_flip_extrapolate_def ex = eddy_default_flip_extrapolate_def();
		ex.layers = 3; /* eddy.fluid's at CFL 1 */
		eddy_add_flip_extrapolate(w, &ex);
		eddy_flip_g2p_def gp = eddy_default_flip_g2p_def();
		eddy_add_flip_g2p(w, &gp);
		eddy_flip_advect_def ad = eddy_default_flip_advect_def();
		eddy_add_flip_advect(w, &ad);
	} else {
		eddy_sph_density_def de = eddy_default_sph_density_def();
		de.spacing = dx;
		de.radius = 2 * dx;
		de.stiffness = 400;
		de.verlet_list = !env_on("EDDY_SCALE_NO_VERLET"); /* the grid search at h every step */
		eddy_add_sph_density(w, &de);
		eddy_sph_dfsph_def df = eddy_default_sph_dfsph_def();
		df.coarse_grid = env_on("EDDY_SCALE_COARSE"); /* the velocity solve's coarse level */
		df.hydrostatic_start = env_on("EDDY_SCALE_WARM");
		bench_add_sph_forces(w, dfsph ? &df : NULL);
		eddy_sph_boundary_box_def bb = eddy_default_sph_boundary_box_def();
		bb.max = d.bounds_max;
		bb.spacing = dx;
		eddy_add_sph_boundary_box(w, &bb);
		eddy_integrate_def it = eddy_default_integrate_def();
		eddy_add_integrate(w, &it);
	}
	eddy_collide_box_def bx = eddy_default_collide_box_def();
	bx.max = d.bounds_max;
	eddy_add_collide_box(w, &bx);
	return w;
}

/* One block run: 2 steps to emit and take the first kick, then `steps`
 * timed steps. Prints one JSON object. */
static int child_block(const char *method, long n, int threads, int steps, const char *solver)
{
	if (env_on("EDDY_SCALE_COLUMNS"))
		fprintf(stderr, "peak RSS before the world: %.1f MB\n", (double)maxrss_kb() / 1e3);
	eddy_world *w = block(method, n, threads, solver_of(solver));
	if (!w) {
		fprintf(stderr, "bench_scale: cannot create the world\n");
		return 1;
	}
	const double t0 = now_ms();
	double setup_iters = 0, setup_div = 0;
	for (int s = 0; s < 2; ++s) {
		if (env_on("EDDY_SCALE_COLUMNS")) /* where the peak is reached: emission, first step or later */
			fprintf(stderr, "peak RSS before step %d: %.1f MB\n", s, (double)maxrss_kb() / 1e3);
		if (eddy_world_step(w) != EDDY_OK) {
			fprintf(stderr, "bench_scale: %s %ld: %s\n", method, n, eddy_world_error(w));
			return 1;
		}
		eddy_frame_stats st;
		eddy_world_frame_stats(w, &st);
		const double it = extra_stat(&st, "iterations");
		setup_iters += isnan(it) ? 0 : it;
		const double dit = extra_stat(&st, "divergence_iterations");
		setup_div += isnan(dit) ? 0 : dit;
	}
	const double setup_s = (now_ms() - t0) / 1e3;
	const size_t np = eddy_world_particle_count(w);
	const int ns = eddy_world_system_count(w);
	double *before = calloc((size_t)ns, sizeof *before), ms[64], cpu[64], iters = 0, div_iters = 0;
	steps = steps < 1 ? 1 : steps > 64 ? 64 : steps;
	for (int k = 0; k < ns; ++k) {
		eddy_system_info info;
		eddy_world_system_info(w, eddy_world_system_at(w, k), &info);
		before[k] = info.profile_ms;
	}
	for (int s = 0; s < steps; ++s) {
		if (env_on("EDDY_SCALE_COLUMNS"))
			hwm_reset();
		const double a = now_ms(), c = cpu_ms();
		if (eddy_world_step(w) != EDDY_OK) {
			fprintf(stderr, "bench_scale: %s %ld: %s\n", method, n, eddy_world_error(w));
			return 1;
		}
		ms[s] = now_ms() - a;
		cpu[s] = cpu_ms() - c;
		if (env_on("EDDY_SCALE_COLUMNS"))
			fprintf(stderr, "peak RSS after timed step %d: %.1f MB (within the step: %.1f MB)\n", s,
			        (double)maxrss_kb() / 1e3, (double)hwm_kb() / 1e3);
		eddy_frame_stats st;
		eddy_world_frame_stats(w, &st);
		const double it = extra_stat(&st, "iterations");
		iters += isnan(it) ? 0 : it;
		const double dit = extra_stat(&st, "divergence_iterations");
		div_iters += isnan(dit) ? 0 : dit;
	}
	printf("{\"method\":\"%s\",\"solver\":\"%s\",\"particles\":%zu,\"threads\":%d,\"steps\":%d,\"ns_per_particle_"
	       "step\":%.2f,"
	       "\"cpu_ns_per_particle_step\":%.2f,\"setup_s\":%.3f,\"peak_rss_bytes\":%ld,\"iterations_per_step\":%.2f,"
	       "\"divergence_iterations_per_step\":%.2f,\"state_hash\":\"%016llx\",\"systems_ns\":{",
	       method, solver, np, threads, steps, median(ms, steps) * 1e6 / (double)np,
	       median(cpu, steps) * 1e6 / (double)np, setup_s, maxrss_kb() * 1024L, iters / steps, div_iters / steps,
	       (unsigned long long)eddy_world_state_hash(w));
	for (int k = 0; k < ns; ++k) {
		eddy_system_info info;
		eddy_world_system_info(w, eddy_world_system_at(w, k), &info);
		printf("%s\"%s\":%.2f", k ? "," : "", info.name, (info.profile_ms - before[k]) * 1e6 / ((double)np * steps));
	}
	/* where the setup's time went: each system's seconds over the two
	 * steps, and the pressure solve's iterations in them */
	printf("},\"setup_iterations\":%.2f,\"setup_divergence_iterations\":%.2f,\"setup_systems_s\":{", setup_iters,
	       setup_div);
	for (int k = 0; k < ns; ++k) {
		eddy_system_info info;
		eddy_world_system_info(w, eddy_world_system_at(w, k), &info);
		printf("%s\"%s\":%.3f", k ? "," : "", info.name, before[k] / 1e3);
	}
	printf("}}\n");
	if (env_on("EDDY_SCALE_COLUMNS")) /* where the memory is: the columns, largest first as listed */
		for (int c = 0; c < eddy_world_column_count(w); ++c) {
			eddy_column_info ci;
			if (eddy_world_column_info(w, c, &ci) == EDDY_OK && ci.bytes > 0)
				fprintf(stderr, "column %-20s %8.1f MB\n", ci.name, (double)ci.bytes / 1e6);
		}
	free(before);
	eddy_destroy_world(w);
	return 0;
}

static eddy_status wavy_setup(eddy_world *w, const eddy_step_context *ctx, void *user)
{
	(void)ctx;
	(void)user;
	fixture_random_faces(w, 99);
	fixture_wavy_pool(w);
	return EDDY_OK;
}

static eddy_world *pool(int n, int threads, eddy_flip_solver solver)
{
	eddy_world_def d = eddy_default_world_def();
	d.cell_size = 1.0 / n;
	d.threads = threads;
	d.fps = 100;
	d.dt_max = 0.01;
	eddy_world *w = eddy_create_world(&d, NULL, 0);
	static const char *const writes[] = {"u", "v", "w", "cell_type", "flip_phi"};
	eddy_custom_system_def cs = eddy_default_custom_system_def();
	cs.name = "wavy_setup";
	cs.writes = writes;
	cs.write_count = 5;
	cs.step = wavy_setup;
	eddy_add_custom_system(w, &cs);
	eddy_flip_pressure_def pr = eddy_default_flip_pressure_def();
	pr.solver = solver;
	pr.tolerance = 1e-6;
	eddy_add_flip_pressure(w, &pr);
	return w;
}

/* One pressure run: a 16^3 solve first (HYPRE starts MPI once per process),
 * then the n^3 pool solved once (n >= 256) or three times (median). */
static int child_pressure(int n, const char *solver, int threads)
{
	const eddy_flip_solver sv = solver_of(solver);
	eddy_world *warm = pool(16, threads, sv);
	eddy_world_step_frame(warm);
	eddy_destroy_world(warm);
	eddy_world *w = pool(n, threads, sv);
	const int reps = n >= 256 ? 1 : 3;
	double t[3], iters = 0;
	for (int r = 0; r < reps; ++r) {
		const double before = profile_ms(w, "flip_pressure");
		if (eddy_world_step_frame(w) != EDDY_OK) {
			fprintf(stderr, "bench_scale: pressure %d^3 %s: %s\n", n, solver, eddy_world_error(w));
			return 1;
		}
		t[r] = (profile_ms(w, "flip_pressure") - before) / 1e3;
		eddy_frame_stats st;
		eddy_world_frame_stats(w, &st);
		iters = extra_stat(&st, "iterations");
	}
	size_t nc;
	const uint8_t *type = eddy_world_channel_u8(w, "cell_type", &nc);
	long unknowns = 0;
	for (size_t c = 0; c < nc; ++c)
		unknowns += type[c] == EDDY_CELL_FLUID;
	printf("{\"grid\":%d,\"unknowns\":%ld,\"solver\":\"%s\",\"threads\":%d,\"iterations\":%.0f,\"s_per_solve\":%.4f,"
	       "\"solves\":%d,\"peak_rss_bytes\":%ld}\n",
	       n, unknowns, solver, threads, iters, median(t, reps), reps, maxrss_kb() * 1024L);
	eddy_destroy_world(w);
	return 0;
}

/* Runs this program with args in a fresh process; its stdout (one JSON line)
 * into out. Returns false if it failed. */
static bool run_child(char *const args[], char *out, size_t cap)
{
	int fd[2];
	if (pipe(fd) != 0)
		return false;
	const pid_t pid = fork();
	if (pid < 0)
		return false;
	if (pid == 0) {
		close(fd[0]);
		dup2(fd[1], 1);
		close(fd[1]);
		execv("/proc/self/exe", args);
		_exit(127);
	}
	close(fd[1]);
	size_t len = 0;
	ssize_t r;
	while ((r = read(fd[0], out + len, cap - 1 - len)) > 0 || (r < 0 && errno == EINTR))
		if (r > 0)
			len += (size_t)r;
	out[len] = 0;
	close(fd[0]);
	int status = 0;
	while (waitpid(pid, &status, 0) < 0 && errno == EINTR) {
	}
	while (len && (out[len - 1] == '\n'))
		out[--len] = 0;
	return WIFEXITED(status) && WEXITSTATUS(status) == 0 && len > 0;
}

static double json_num(const char *s, const char *key)
{
	char k[64];
	snprintf(k, sizeof k, "\"%s\":", key);
	const char *p = strstr(s, k);
	return p ? strtod(p + strlen(k), NULL) : NAN;
}

static double mem_available(void)
{
	FILE *f = fopen("/proc/meminfo", "r");
	char line[256];
	double kb = NAN;
	while (f && fgets(line, sizeof line, f))
		if (sscanf(line, "MemAvailable: %lf kB", &kb) == 1)
			break;
	if (f)
		fclose(f);
	return kb * 1024;
}

static double load1(void)
{
	FILE *f = fopen("/proc/loadavg", "r");
	double l = NAN;
	if (f) {
		if (fscanf(f, "%lf", &l) != 1)
			l = NAN;
		fclose(f);
	}
	return l;
}

static int parse_list(const char *s, long *v, int cap)
{
	int n = 0;
	while (*s && n < cap) {
		char *end;
		v[n++] = strtol(s, &end, 10);
		s = *end == ',' ? end + 1 : end;
		if (end == s && *s)
			break;
	}
	return n;
}

int main(int argc, char **argv)
{
	if ((argc == 6 || argc == 7) && strcmp(argv[1], "--child") == 0)
		return child_block(argv[2], atol(argv[3]), atoi(argv[4]), atoi(argv[5]), argc == 7 ? argv[6] : "pcg");
	if (argc == 5 && strcmp(argv[1], "--pressure") == 0)
		return child_pressure(atoi(argv[2]), argv[3], atoi(argv[4]));
	const char *path = "build/bench_scale.json";
	long sizes[8] = {100000, 1000000, 10000000}, grids[8] = {64, 128, 256};
	int nsizes = 3, ngrids = 3, reps = 3, steps = 4;
	const char *methods[3] = {"wcsph", "dfsph", "flip"};
	bool use[3] = {true, true, true}, do_pressure = true;
	for (int a = 1; a < argc; ++a) {
		if (strcmp(argv[a], "--sizes") == 0 && a + 1 < argc)
			nsizes = parse_list(argv[++a], sizes, 8);
		else if (strcmp(argv[a], "--grids") == 0 && a + 1 < argc)
			ngrids = parse_list(argv[++a], grids, 8);
		else if (strcmp(argv[a], "--reps") == 0 && a + 1 < argc)
			reps = atoi(argv[++a]);
		else if (strcmp(argv[a], "--steps") == 0 && a + 1 < argc)
			steps = atoi(argv[++a]);
		else if (strcmp(argv[a], "--no-pressure") == 0)
			do_pressure = false;
		else if (strcmp(argv[a], "--methods") == 0 && a + 1 < argc) {
			const char *m = argv[++a];
			for (int k = 0; k < 3; ++k)
				use[k] = strstr(m, methods[k]) != NULL;
		} else if (argv[a][0] != '-')
			path = argv[a];
		else {
			fprintf(stderr, "bench_scale: unknown option '%s'\n", argv[a]);
			return 2;
		}
	}
	reps = reps < 1 ? 1 : reps > 15 ? 15 : reps;
	FILE *f = fopen(path, "w");
	if (!f) {
		fprintf(stderr, "bench_scale: cannot write %s\n", path);
		return 1;
	}
	fprintf(f,
	        "{\"benchmark\":\"scale\",\"note\":\"block settling in a tank (2 warm-up steps, %d timed); ns per particle "
	        "per step of the whole step, median over the timed steps, then over %d runs per thread count; 1- and "
	        "2-thread runs alternate and the speed-up is the median of the paired ratios; peak RSS of each run's "
	        "own process over its particle count; shared 2-core machine\",\"load_start\":%.2f,\"nproc\":%ld,"
	        "\"results\":[",
	        steps, reps, load1(), sysconf(_SC_NPROCESSORS_ONLN));
	bool first = true;
	char out[8192], sn[32], st[8], ss[8];
	for (int m = 0; m < 3; ++m) {
		if (!use[m])
			continue;
		double bpp_prev = NAN;
		long n_prev = 0;
		for (int si = 0; si < nsizes; ++si) {
			const long n = sizes[si];
			/* memory: the largest measured bytes per particle so far, scaled */
			const double need = (isnan(bpp_prev) ? 1500.0 : bpp_prev) * (double)n, avail = mem_available();
			if (n > 2000000 && (isnan(bpp_prev) || need > 0.75 * avail)) {
				fprintf(
					f,
					"%s\n {\"method\":\"%s\",\"particles\":%ld,\"skipped\":\"needs about %.1f GB (%.0f B per particle "
					"at %ld), %.1f GB available\"}",
					first ? "" : ",", methods[m], n, need / 1e9, isnan(bpp_prev) ? 1500.0 : bpp_prev, n_prev,
					avail / 1e9);
				printf("%s %ld: skipped, needs about %.1f GB, %.1f GB available\n", methods[m], n, need / 1e9,
				       avail / 1e9);
				first = false;
				continue;
			}
			double ns[2][15], cpu[2][15], ratio[15], rss[2] = {0, 0}, it = NAN;
			size_t np = 0;
			int ok = 0;
			char sys2[2][4096] = {"", ""};
			for (int r = 0; r < reps; ++r) {
				bool good = true;
				for (int t = 0; t < 2 && good; ++t) {
					snprintf(sn, sizeof sn, "%ld", n);
					snprintf(st, sizeof st, "%d", t + 1);
					snprintf(ss, sizeof ss, "%d", steps);
					char *args[] = {argv[0], "--child", (char *)(uintptr_t)methods[m], sn, st, ss, NULL};
					good = run_child(args, out, sizeof out);
					if (!good)
						break;
					ns[t][ok] = json_num(out, "ns_per_particle_step");
					cpu[t][ok] = json_num(out, "cpu_ns_per_particle_step");
					rss[t] = fmax(rss[t], json_num(out, "peak_rss_bytes"));
					np = (size_t)json_num(out, "particles");
					it = json_num(out, "iterations_per_step");
					const char *sy = strstr(out, "\"systems_ns\":");
					if (sy)
						snprintf(sys2[t], sizeof sys2[t], "%s", sy);
				}
				if (!good) {
					fprintf(stderr, "bench_scale: %s %ld failed\n", methods[m], n);
					break;
				}
				ratio[ok] = ns[0][ok] / ns[1][ok];
				ok++;
				printf("  %s %zu: run %d: %.1f / %.1f ns per particle per step on 1 / 2 threads\n", methods[m], np,
				       r + 1, ns[0][ok - 1], ns[1][ok - 1]);
				fflush(stdout);
			}
			if (!ok)
				continue;
			const double l = load1();
			for (int t = 0; t < 2; ++t) {
				const double med = median(ns[t], ok), cmed = median(cpu[t], ok);
				fprintf(f,
				        "%s\n {\"method\":\"%s\",\"particles\":%zu,\"threads\":%d,\"ns_per_particle_step\":%.1f,"
				        "\"cpu_ns_per_particle_step\":%.1f,\"peak_rss_bytes_per_particle\":%.1f,\"iterations_per_"
				        "step\":%.2f,"
				        "\"runs\":%d,%s",
				        first ? "" : ",", methods[m], np, t + 1, med, cmed, rss[t] / (double)np, it, ok, sys2[t]);
				first = false;
				printf("%s %zu particles, %d thread%s: %.1f ns per particle per step (process CPU %.1f), %.0f B per "
				       "particle "
				       "peak RSS\n",
				       methods[m], np, t + 1, t ? "s" : " ", med, cmed, rss[t] / (double)np);
			}
			const double sp = median(ratio, ok);
			fprintf(f, ",\n {\"method\":\"%s\",\"particles\":%zu,\"speedup_2_threads\":%.2f,\"load\":%.2f}", methods[m],
			        np, sp, l);
			printf("%s %zu particles: speed-up on 2 threads %.2fx (median of %d paired runs; load %.2f)\n", methods[m],
			       np, sp, ok, l);
			fflush(stdout);
			bpp_prev = fmax(rss[0], rss[1]) / (double)np;
			n_prev = (long)np;
		}
	}
	for (int g = 0; g < ngrids && do_pressure; ++g)
		for (int t = 1; t <= 2; ++t)
			for (int s = 0; s < 3; ++s) {
				const char *solver = s == 0 ? "pcg" : s == 1 ? "hypre" : "mg";
				snprintf(sn, sizeof sn, "%ld", grids[g]);
				snprintf(st, sizeof st, "%d", t);
				char *args[] = {argv[0], "--pressure", sn, (char *)(uintptr_t)solver, st, NULL};
				if (!run_child(args, out, sizeof out)) {
					fprintf(stderr, "bench_scale: pressure %ld^3 %s failed\n", grids[g], solver);
					continue;
				}
				fprintf(f, "%s\n {\"kind\":\"pressure\",\"scene\":\"wavy_pool\",%s", first ? "" : ",", out + 1);
				first = false;
				printf("pressure %ld^3 wavy pool, %s, %d thread%s: %.0f iterations, %.3f s per solve\n", grids[g],
				       solver, t, t > 1 ? "s" : "", json_num(out, "iterations"), json_num(out, "s_per_solve"));
				fflush(stdout);
			}
	fprintf(f, "\n],\"load_end\":%.2f}\n", load1());
	fclose(f);
	printf("bench_scale: wrote %s\n", path);
	return 0;
}
