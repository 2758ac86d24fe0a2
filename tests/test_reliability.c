/* SPDX-License-Identifier: MIT */
#define _POSIX_C_SOURCE 200809L
/* Losing nothing: checkpoints continue a run bit for bit, bad checkpoints are
 * rejected with the reason, an interrupted run ends its frame cleanly and says
 * where to resume. */
#include "test.h"

#include <signal.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include "eddy.h"

/* A scene with every kind of system state: a one-shot block, a nozzle part way
 * through its pour, a moving collider, jitter from the random stream. */
static eddy_world *stateful_world(eddy_system_id *sphere)
{
	eddy_world_def d = eddy_default_world_def();
	d.seed = 42;
	eddy_world *w = eddy_create_world(&d, NULL, 0);
	eddy_emit_box_def b = eddy_default_emit_box_def();
	b.min = (eddy_vec3){0.1f, 0.5f, 0.1f};
	b.max = (eddy_vec3){0.4f, 0.8f, 0.4f};
	b.spacing = 0.03f;
	b.jitter = 0.3f;
	eddy_add_emit_box(w, &b);
	eddy_emit_nozzle_def nz = eddy_default_emit_nozzle_def();
	nz.center = (eddy_vec3){0.7f, 0.9f, 0.5f};
	nz.spacing = 0.02f;
	nz.radius = 0.04f;
	nz.speed = 0.7f;
	eddy_add_emit_nozzle(w, &nz);
	eddy_gravity_def g = eddy_default_gravity_def();
	eddy_add_gravity(w, &g);
	eddy_integrate_def it = eddy_default_integrate_def();
	eddy_add_integrate(w, &it);
	eddy_collide_sphere_def s = eddy_default_collide_sphere_def();
	s.center = (eddy_vec3){0.5f, 0.2f, 0.5f};
	s.response.restitution = 0.4f;
	*sphere = eddy_add_collide_sphere(w, &s);
	eddy_collide_box_def bx = eddy_default_collide_box_def();
	bx.response.restitution = 0.2f;
	eddy_add_collide_box(w, &bx);
	return w;
}

/* Frames with the sphere moving along a path known in advance. */
static void run_frames(eddy_world *w, eddy_system_id sphere, int frames)
{
	for (int f = 0; f < frames; ++f) {
		const double t = eddy_world_time(w) + 1.0 / 30.0;
		eddy_collider_set_offset(w, sphere, (eddy_vec3){(float)(0.2 * sin(3 * t)), 0, 0});
		CHECK(eddy_world_step_frame(w) == EDDY_OK);
	}
}

static void ckpt_path(char *out, size_t cap, const char *name) { snprintf(out, cap, "%s/%s", test_build_dir(), name); }

static void checkpoint_resume_is_bit_identical(void)
{
	eddy_system_id sa, sb;
	eddy_world *a = stateful_world(&sa);
	run_frames(a, sa, 20);
	const uint64_t straight = eddy_world_state_hash(a);

	eddy_world *b = stateful_world(&sb);
	run_frames(b, sb, 9);
	char path[512];
	ckpt_path(path, sizeof path, "t_ckpt.eddy");
	CHECK(eddy_world_save(b, path, 7) == EDDY_OK);
	run_frames(b, sb, 3); /* work after the checkpoint that a crash loses */
	eddy_destroy_world(b);

	eddy_world *c = stateful_world(&sb);
	CHECKF(eddy_world_load(c, path, 7) == EDDY_OK, "%s", eddy_world_error(c));
	CHECK(eddy_world_frame(c) == 9);
	run_frames(c, sb, 11);
	CHECK(eddy_world_frame(c) == 20);
	CHECK(eddy_world_particle_count(c) == eddy_world_particle_count(a));
	CHECK(eddy_world_state_hash(c) == straight);
	eddy_destroy_world(c);
	eddy_destroy_world(a);
}

static void corrupt_byte(const char *path, long at)
{
	FILE *f = fopen(path, "r+b");
	fseek(f, at, at < 0 ? SEEK_END : SEEK_SET);
	int c = fgetc(f);
	fseek(f, -1, SEEK_CUR);
	fputc(c ^ 0x5a, f);
	fclose(f);
}

static void bad_checkpoints_are_rejected(void)
{
	eddy_system_id s;
	eddy_world *w = stateful_world(&s);
	run_frames(w, s, 3);
	char path[512], copy[600];
	ckpt_path(path, sizeof path, "t_bad.eddy");
	CHECK(eddy_world_save(w, path, 1) == EDDY_OK);
	const uint64_t before = eddy_world_state_hash(w);
	char cmd[1400];

	/* another fingerprint: another scene or other --set values */
	CHECK(eddy_world_load(w, path, 2) == EDDY_ERR_IO);
	CHECK_HAS(eddy_world_error(w), "written by another scene or other parameters");

	snprintf(copy, sizeof copy, "%s.c", path);
	snprintf(cmd, sizeof cmd, "cp %s %s", path, copy);
	CHECK(system(cmd) == 0);
	corrupt_byte(copy, -10);
	CHECK(eddy_world_load(w, copy, 1) == EDDY_ERR_IO);
	CHECK_HAS(eddy_world_error(w), "checksum mismatch (corrupted)");

	CHECK(system(cmd) == 0);
	snprintf(cmd, sizeof cmd, "truncate -s -100 %s", copy);
	CHECK(system(cmd) == 0);
	CHECK(eddy_world_load(w, copy, 1) == EDDY_ERR_IO);
	CHECK_HAS(eddy_world_error(w), "truncated");

	snprintf(cmd, sizeof cmd, "cp %s %s", path, copy);
	CHECK(system(cmd) == 0);
	corrupt_byte(copy, 8); /* the version */
	CHECK(eddy_world_load(w, copy, 1) == EDDY_ERR_IO);
	CHECK_HAS(eddy_world_error(w), "this eddy reads version 3");

	snprintf(cmd, sizeof cmd, "printf 'hello' > %s", copy);
	CHECK(system(cmd) == 0);
	CHECK(eddy_world_load(w, copy, 1) == EDDY_ERR_IO);
	CHECK_HAS(eddy_world_error(w), "not an eddy checkpoint");

	/* every rejection left the world as it was */
	CHECK(eddy_world_state_hash(w) == before);
	CHECK(eddy_world_save(w, "/no/such/dir/x.eddy", 1) == EDDY_ERR_IO);
	CHECK_HAS(eddy_world_error(w), "cannot create '/no/such/dir/x.eddy.tmp'");
	eddy_destroy_world(w);

	/* a world with another pipeline does not take it either */
	eddy_world_def d = eddy_default_world_def();
	d.seed = 42;
	eddy_world *other = eddy_create_world(&d, NULL, 0);
	CHECK(eddy_world_load(other, path, 1) == EDDY_ERR_IO);
	eddy_destroy_world(other);
}

/* The command resumes from the newest good checkpoint, skipping a corrupted
 * one, and the resumed run ends in the same state as a straight one. */
static void cli_resume_skips_a_corrupted_checkpoint(void)
{
	const char *bin = test_build_dir();
	char cmd[2048], out[65536], a[8192], b[8192];
	snprintf(cmd, sizeof cmd,
	         "rm -rf %s/t_run && %s/eddy run scenes/bounce.lua --frames 16 --quiet --out %s/run --stats - "
	         "| tail -1 | grep -o '\"state_hash\":\"[0-9a-f]*\"'",
	         bin, bin, test_out_dir());
	CHECK(test_sh(cmd, a, sizeof a) == 0);
	snprintf(cmd, sizeof cmd, "%s/eddy run scenes/bounce.lua --frames 11 --quiet --checkpoint-every 5 --out %s/t_run",
	         bin, bin);
	CHECK(test_sh(cmd, out, sizeof out) == 0);
	char newest[512];
	snprintf(newest, sizeof newest, "%s/t_run/checkpoints/frame-000010.eddy", bin);
	corrupt_byte(newest, 100);
	snprintf(cmd, sizeof cmd,
	         "%s/eddy run scenes/bounce.lua --frames 16 --out %s/t_run --resume %s/t_run/checkpoints "
	         "--stats %s/t_run/s.jsonl",
	         bin, bin, bin, bin);
	CHECK(test_sh(cmd, out, sizeof out) == 0);
	CHECK_HAS(out, "checksum mismatch (corrupted); trying an older one");
	CHECK_HAS(out, "resuming from");
	CHECK_HAS(out, "frame-000005.eddy (frame 5");
	snprintf(cmd, sizeof cmd, "tail -1 %s/t_run/s.jsonl | grep -o '\"state_hash\":\"[0-9a-f]*\"'", bin);
	CHECK(test_sh(cmd, b, sizeof b) == 0);
	CHECK(strlen(a) > 20);
	CHECK(strcmp(a, b) == 0);
	/* --set changes the scene: its checkpoints are not taken */
	snprintf(
		cmd, sizeof cmd,
		"%s/eddy run scenes/bounce.lua --frames 16 --set restitution=0.9 --resume %s/t_run/checkpoints --out %s/run",
		bin, bin, test_out_dir());
	CHECK(test_sh(cmd, out, sizeof out) == 1);
	CHECK_HAS(out, "no valid checkpoint of this scene");
}

/* The fluid methods resume bit for bit too: a straight run and a run stopped
 * at frame 7 and resumed from its frame-6 checkpoint end in the same states. */
static void fluid_scenes_resume_bit_identical(void)
{
	static const char *const scenes[] = {
		"scenes/dam_break.lua --set method=flip --set render=false --set spacing=0.005",
		"scenes/dam_break.lua --set render=false --set spacing=0.01",
		/* a collider moved by an offset function: flip_boundary's memory of it */
		"scenes/stress/flip_solid_sphere.lua --set cell_size=0.025", NULL};
	const char *bin = test_build_dir();
	for (int i = 0; scenes[i]; ++i) {
		char cmd[2048], a[16384], b[16384], out[4096];
		snprintf(
			cmd, sizeof cmd,
			"rm -rf %s/t_fluid %s/t_fluid_b.jsonl && %s/eddy run %s --frames 10 --quiet --out %s/t_fluid/a --stats - "
			"| grep -o '\"state_hash\":\"[0-9a-f]*\"'",
			bin, bin, bin, scenes[i], bin);
		CHECK(test_sh(cmd, a, sizeof a) == 0);
		snprintf(cmd, sizeof cmd,
		         "%s/eddy run %s --frames 7 --checkpoint-every 3 --quiet --out %s/t_fluid/b "
		         "--stats %s/t_fluid_b.jsonl",
		         bin, scenes[i], bin, bin);
		CHECK(test_sh(cmd, out, sizeof out) == 0);
		snprintf(cmd, sizeof cmd,
		         "%s/eddy run %s --frames 10 --quiet --out %s/t_fluid/b --stats %s/t_fluid_b.jsonl "
		         "--resume %s/t_fluid/b/checkpoints && grep -o '\"state_hash\":\"[0-9a-f]*\"' %s/t_fluid_b.jsonl",
		         bin, scenes[i], bin, bin, bin, bin);
		CHECK(test_sh(cmd, b, sizeof b) == 0);
		CHECK(strlen(a) > 10 * 20);
		CHECKF(strcmp(a, b) == 0, "%s: resumed hashes differ", scenes[i]);
	}
}

/* SIGINT: the frame in progress finishes, its stats line is whole, a
 * checkpoint is written and the message says how to resume. */
static void interrupt_finishes_the_frame(void)
{
	char cmd[2048];
	const char *bin = test_build_dir();
	snprintf(cmd, sizeof cmd, "rm -rf %s/t_int %s/t_int.jsonl", bin, bin);
	CHECK(system(cmd) == 0);
	char exe[512], outdir[512], stats[512], errpath[512];
	snprintf(exe, sizeof exe, "%s/eddy", bin);
	snprintf(outdir, sizeof outdir, "%s/t_int", bin);
	snprintf(stats, sizeof stats, "%s/t_int.jsonl", bin);
	snprintf(errpath, sizeof errpath, "%s/t_int.err", bin);
	pid_t pid = fork();
	if (pid == 0) {
		if (!freopen(errpath, "w", stderr))
			_exit(98);
		execl(exe, exe, "run", "scenes/bounce.lua", "--frames", "100000", "--set", "spacing=0.008", "--out", outdir,
		      "--stats", stats, "--quiet", (char *)NULL);
		_exit(99);
	}
	/* interrupt once a frame is out (a sanitizer build is slow to start) */
	for (int i = 0; i < 600; ++i) {
		struct timespec ts = {0, 50 * 1000 * 1000};
		nanosleep(&ts, NULL);
		FILE *probe = fopen(stats, "r");
		int c = probe ? fgetc(probe) : EOF;
		if (probe)
			fclose(probe);
		if (c != EOF)
			break;
	}
	kill(pid, SIGINT);
	int st;
	waitpid(pid, &st, 0);
	CHECKF(WIFEXITED(st) && WEXITSTATUS(st) == 128 + SIGINT, "exit status %d", WIFEXITED(st) ? WEXITSTATUS(st) : -1);
	FILE *f = fopen(errpath, "r");
	char msg[2048] = "";
	if (f) {
		size_t n = fread(msg, 1, sizeof msg - 1, f);
		msg[n] = '\0';
		fclose(f);
	}
	CHECK_HAS(msg, "eddy: interrupted after frame ");
	CHECK_HAS(msg, "resume with: eddy run scenes/bounce.lua --resume ");
	/* every stats line is complete */
	f = fopen(stats, "r");
	CHECK(f != NULL);
	int lines = 0, whole = 0;
	char line[65536];
	while (f && fgets(line, sizeof line, f)) {
		++lines;
		size_t n = strlen(line);
		whole += n > 2 && line[0] == '{' && line[n - 2] == '}' && line[n - 1] == '\n';
	}
	if (f)
		fclose(f);
	CHECK(lines >= 1 && whole == lines);
	char ck[600];
	snprintf(ck, sizeof ck, "%s/checkpoints/frame-%06d.eddy", outdir, lines);
	CHECKF(access(ck, R_OK) == 0, "no checkpoint %s", ck);
}

/* Hard case 16: a scene too large for the machine is refused up front. */
static void run_refuses_what_cannot_fit(void)
{
	char path[512], cmd[1200], out[4096];
	snprintf(path, sizeof path, "%s/t_huge.lua", test_build_dir());
	FILE *f = fopen(path, "w");
	fputs("local eddy = require 'eddy'\nlocal w = eddy.world{ bounds = {{0,0,0},{10,10,10}} }\n"
	      "w:add(eddy.emit_box{ min = {0,0,0}, max = {10,10,10}, spacing = 0.01 })\n"
	      "w:add(eddy.gravity{})\nw:add(eddy.integrate{})\nreturn w\n",
	      f);
	fclose(f);
	snprintf(cmd, sizeof cmd, "%s/eddy run %s --frames 1 --out %s/run", test_build_dir(), path, test_out_dir());
	CHECK(test_sh(cmd, out, sizeof out) == 1);
	CHECK_HAS(out, "memory: the scene needs about");
	CHECK_HAS(out, "not run: 1 problem found by the preflight check");
}

/* Copies checkpoint src to dst with n bytes at payload offset at replaced by
 * bytes, and the checksum recomputed: a crafted file that passes the
 * integrity checks. Layout per src/checkpoint.c: a 40-byte header whose last
 * 8 bytes are the FNV-1a of the payload; the payload opens with time (f64),
 * frame (i32), step (i64), last dt (f64), random state (u64), length scale
 * (f32), rest density (f32), particle count (u64), packed. */
static void craft(const char *src, const char *dst, size_t at, const void *bytes, size_t n)
{
	FILE *f = fopen(src, "rb");
	CHECK(f != NULL);
	if (!f)
		return;
	fseek(f, 0, SEEK_END);
	long len = ftell(f);
	fseek(f, 0, SEEK_SET);
	unsigned char *data = malloc((size_t)len);
	CHECK(fread(data, 1, (size_t)len, f) == (size_t)len);
	fclose(f);
	memcpy(data + 40 + at, bytes, n);
	uint64_t h = 0xcbf29ce484222325ull;
	for (long i = 40; i < len; ++i) {
		h ^= data[i];
		h *= 0x100000001b3ull;
	}
	memcpy(data + 32, &h, 8);
	f = fopen(dst, "wb");
	CHECK(fwrite(data, 1, (size_t)len, f) == (size_t)len);
	fclose(f);
	free(data);
}

/* Red-team case: checkpoints with a valid checksum but an impossible clock
 * (frame -5 ran negative frames, frame 2^31 - 1 ran nothing, a NaN time
 * failed later in integrate) are refused, naming the file and the field. */
static void crafted_checkpoints_are_rejected(void)
{
	eddy_system_id s;
	eddy_world *w = stateful_world(&s);
	run_frames(w, s, 3);
	char path[512], copy[600];
	ckpt_path(path, sizeof path, "t_craft.eddy");
	snprintf(copy, sizeof copy, "%s.c", path);
	CHECK(eddy_world_save(w, path, 1) == EDDY_OK);
	const uint64_t before = eddy_world_state_hash(w);

	/* the crafting itself keeps a file loadable */
	double t = 0.1;
	craft(path, copy, 0, &t, sizeof t);
	CHECKF(eddy_world_load(w, copy, 1) == EDDY_OK, "%s", eddy_world_error(w));

	const struct {
		size_t at;
		int kind; /* 0 f64, 1 i32, 2 i64, 3 f32, 4 u64 */
		double value;
		const char *field;
	} cases[] = {
		{8, 1, -5, "field 'frame' is -5"},
		{8, 1, 2147483647.0, "field 'frame' is 2147483647"},
		{8, 1, 4, "field 'frame' is 4, inconsistent with time 0.1 s at 30 fps (frame 3 expected)"},
		{0, 0, NAN, "field 'time' is nan s"},
		{0, 0, -1, "field 'time' is -1 s"},
		{0, 0, 1e300, "field 'frame' is 3, inconsistent"},
		{12, 2, -1, "field 'step' is -1"},
		{20, 0, INFINITY, "field 'last_dt' is inf s"},
		{20, 0, -1e-3, "field 'last_dt'"},
		{36, 3, NAN, "field 'length_scale'"},
		{40, 3, -1000, "field 'rest_density'"},
		{44, 4, 1125899906842624.0, "field 'particles' is 1125899906842624"},
	};
	for (size_t k = 0; k < sizeof cases / sizeof cases[0]; ++k) {
		unsigned char b[8];
		size_t n = 8;
		if (cases[k].kind == 0) {
			memcpy(b, &cases[k].value, 8);
		} else if (cases[k].kind == 1) {
			int32_t v = (int32_t)cases[k].value;
			memcpy(b, &v, n = 4);
		} else if (cases[k].kind == 2) {
			int64_t v = (int64_t)cases[k].value;
			memcpy(b, &v, 8);
		} else if (cases[k].kind == 3) {
			float v = (float)cases[k].value;
			memcpy(b, &v, n = 4);
		} else {
			uint64_t v = (uint64_t)cases[k].value;
			memcpy(b, &v, 8);
		}
		craft(path, copy, cases[k].at, b, n);
		CHECKF(eddy_world_load(w, copy, 1) == EDDY_ERR_IO, "case %zu (%s) loaded", k, cases[k].field);
		CHECK_HAS(eddy_world_error(w), cases[k].field);
		CHECK_HAS(eddy_world_error(w), copy);
	}
	CHECK(eddy_world_state_hash(w) == before);
	eddy_destroy_world(w);
}

/* Red-team case: sph_density left at its default spacing (0.01 m) under an
 * emitter at 0.02 m collapsed the tank silently; eddy run's preflight now
 * refuses it, naming both systems, both spacings and the fix. */
static void run_refuses_mismatched_sph_spacing(void)
{
	char path[512], cmd[1200], out[4096];
	snprintf(path, sizeof path, "%s/t_spacing.lua", test_build_dir());
	FILE *f = fopen(path, "w");
	fputs("local eddy = require 'eddy'\nlocal w = eddy.world{ bounds = {{0,0,0},{1,1,1}} }\n"
	      "w:add(eddy.emit_box{ min = {0.1,0.1,0.1}, max = {0.3,0.3,0.3}, spacing = 0.02 })\n"
	      "w:add(eddy.sph_density{})\nw:add(eddy.gravity{})\nw:add(eddy.sph_pressure{})\n"
	      "w:add(eddy.integrate{})\nreturn w\n",
	      f);
	fclose(f);
	snprintf(cmd, sizeof cmd, "%s/eddy run %s --frames 1 --out %s/t_spacing_out", test_build_dir(), path,
	         test_build_dir());
	CHECK(test_sh(cmd, out, sizeof out) == 1);
	CHECK_HAS(out, "sph_density: 'spacing' is 0.01 m but emit_box emits at spacing 0.02 m");
	CHECK_HAS(out, "not run: 1 problem found by the preflight check");
	snprintf(cmd, sizeof cmd, "%s/eddy check %s", test_build_dir(), path);
	CHECK(test_sh(cmd, out, sizeof out) != 0);
	CHECK_HAS(out, "set sph_density's spacing = 0.02");
}

/* Two eddy.fluid groups in one world (water and oil, say) ran FLIP's whole
 * pipeline twice a step on the same particles, silently; SPH beside FLIP
 * moved them two ways. eddy run refuses both, in one line each. */
static void run_refuses_two_fluids(void)
{
	static const struct {
		const char *first, *second, *want;
	} cases[] = {
		{"flip", "flip",
	     "pipeline: flip_p2g#2 repeats flip_p2g (and 6 more systems repeat): each would run twice a step on the same "
	     "particles; a world holds one fluid (one eddy.fluid group, one method)"},
		{"dfsph", "flip", "pipeline: sph_density (SPH) and flip_p2g (FLIP) in one world would move the same particles "
	                      "two ways; a world runs one method"},
	};
	for (size_t c = 0; c < sizeof cases / sizeof cases[0]; ++c) {
		char path[512], cmd[1200], out[4096];
		snprintf(path, sizeof path, "%s/t_two_fluids.lua", test_build_dir());
		FILE *f = fopen(path, "w");
		fprintf(f,
		        "local eddy = require 'eddy'\n"
		        "local a = eddy.fluid { method = '%s', resolution = 0.01 }\n"
		        "local b = eddy.fluid { method = '%s', resolution = 0.01, rest_density = 800, tank = false }\n"
		        "local w = a:world { bounds = { {0, 0, 0}, {0.2, 0.3, 0.1} }, duration = 0.1, cell_size = 0.02 }\n"
		        "w:add(eddy.emit_box { min = {0, 0, 0}, max = {0.2, 0.1, 0.1}, spacing = 0.01 })\n"
		        "w:add(a)\nw:add(b)\nreturn w\n",
		        cases[c].first, cases[c].second);
		fclose(f);
		snprintf(cmd, sizeof cmd, "%s/eddy run %s --frames 1 --out %s/t_two_fluids_out", test_build_dir(), path,
		         test_out_dir());
		CHECK(test_sh(cmd, out, sizeof out) == 1);
		CHECK_HAS(out, cases[c].want);
		CHECK_HAS(out, "not run: 1 problem found by the preflight check");
	}
}

void suite_reliability(void)
{
	RUN(run_refuses_two_fluids);
	RUN(run_refuses_mismatched_sph_spacing);
	RUN(run_refuses_what_cannot_fit);
	RUN(checkpoint_resume_is_bit_identical);
	RUN(bad_checkpoints_are_rejected);
	RUN(crafted_checkpoints_are_rejected);
	RUN(cli_resume_skips_a_corrupted_checkpoint);
	RUN(interrupt_finishes_the_frame);
	RUN(fluid_scenes_resume_bit_identical);
}
