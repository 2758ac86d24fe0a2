/* SPDX-License-Identifier: MIT */
#define _POSIX_C_SOURCE 200809L
/* Benchmarks (not part of make test): nanoseconds per particle per step of
 * each core system, for several particle counts and thread counts, as JSON.
 * Each figure is the median of repeated runs, since machines are shared. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "eddy.h"
#include "bench_util.h"

/* A block of n particles (approximately) bouncing in a tank around a ball. */
static eddy_world *scene(int n, int threads)
{
	eddy_world_def d = eddy_default_world_def();
	d.threads = threads;
	d.dt_max = 1e-3;
	d.check_finite = getenv("NOCHECK") == NULL;
	d.fps = 1000; /* one step per frame: the frame machinery is part of the cost */
	eddy_world *w = eddy_create_world(&d, NULL, 0);
	const float side = 0.6f;
	eddy_emit_box_def b = eddy_default_emit_box_def();
	b.min = (eddy_vec3){0.2f, 0.3f, 0.2f};
	b.max = (eddy_vec3){0.2f + side, 0.3f + side, 0.2f + side};
	b.spacing = side / cbrtf((float)n);
	b.jitter = 0.2f;
	eddy_add_emit_box(w, &b);
	eddy_gravity_def g = eddy_default_gravity_def();
	eddy_add_gravity(w, &g);
	eddy_integrate_def it = eddy_default_integrate_def();
	eddy_add_integrate(w, &it);
	eddy_collide_sphere_def s = eddy_default_collide_sphere_def();
	s.center = (eddy_vec3){0.5f, 0.2f, 0.5f};
	eddy_add_collide_sphere(w, &s);
	eddy_collide_box_def bx = eddy_default_collide_box_def();
	eddy_add_collide_box(w, &bx);
	return w;
}

int main(int argc, char **argv)
{
	const char *path = argc > 1 ? argv[1] : "build/bench.json";
	FILE *f = fopen(path, "w");
	if (!f) {
		fprintf(stderr, "bench: cannot write %s\n", path);
		return 1;
	}
	const int counts[] = {10000, 100000, 1000000};
	const int threads[] = {1, 2};
	enum { REPS = 5, STEPS = 20 };
	fprintf(f, "{\"benchmark\":\"core systems\",\"unit\":\"ns per particle per step\",\"results\":[");
	int first = 1;
	for (size_t c = 0; c < sizeof counts / sizeof counts[0]; ++c)
		for (size_t t = 0; t < sizeof threads / sizeof threads[0]; ++t) {
			eddy_world *w = scene(counts[c], threads[t]);
			eddy_world_step_frame(w); /* emits */
			const size_t n = eddy_world_particle_count(w);
			const int ns = eddy_world_system_count(w);
			double per_sys[16][REPS], total[REPS];
			for (int r = 0; r < REPS; ++r) {
				double before[16];
				for (int k = 0; k < ns; ++k) {
					eddy_system_info info;
					eddy_world_system_info(w, eddy_world_system_at(w, k), &info);
					before[k] = info.profile_ms;
				}
				double a = now_ms();
				for (int s = 0; s < STEPS; ++s)
					eddy_world_step_frame(w);
				total[r] = (now_ms() - a) * 1e6 / ((double)n * STEPS);
				for (int k = 0; k < ns; ++k) {
					eddy_system_info info;
					eddy_world_system_info(w, eddy_world_system_at(w, k), &info);
					per_sys[k][r] = (info.profile_ms - before[k]) * 1e6 / ((double)n * STEPS);
				}
			}
			qsort(total, REPS, sizeof total[0], cmp_double);
			fprintf(f, "%s\n {\"particles\":%zu,\"threads\":%d,\"step_ns\":%.2f,\"systems\":{", first ? "" : ",", n,
			        threads[t], total[REPS / 2]);
			first = 0;
			printf("%8zu particles, %d thread%s: %7.2f ns/particle/step (", n, threads[t], threads[t] > 1 ? "s" : " ",
			       total[REPS / 2]);
			for (int k = 0; k < ns; ++k) {
				eddy_system_info info;
				eddy_world_system_info(w, eddy_world_system_at(w, k), &info);
				qsort(per_sys[k], REPS, sizeof per_sys[k][0], cmp_double);
				fprintf(f, "%s\"%s\":%.2f", k ? "," : "", info.label, per_sys[k][REPS / 2]);
				printf("%s%s %.2f", k ? ", " : "", info.label, per_sys[k][REPS / 2]);
			}
			fprintf(f, "}}");
			printf(")\n");
			eddy_destroy_world(w);
		}
	fprintf(f, "\n]}\n");
	fclose(f);
	printf("bench: wrote %s\n", path);
	return 0;
}
