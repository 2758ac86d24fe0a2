/* SPDX-License-Identifier: MIT */
#define _POSIX_C_SOURCE 200809L
/* Fuzzing scene loading and stepping.
 *
 * The input bytes choose a scene: world fields, then systems from the Lua
 * module with fields of random names, types and values (NaN, infinities,
 * huge, negative, wrong types, unknown names, functions where vectors go).
 * The scene is written as Lua source and run through the binding, as a user's
 * scene would be; if it yields a world, the world is stepped a little. Errors
 * are expected; crashes, sanitizer reports and hangs are bugs.
 *
 * An input that starts with Lua's binary-chunk signature (ESC "Lua") is
 * instead handed to the loader as it is, the way a precompiled scene file
 * would be: eddy loads text only, so it must be refused with an error, never
 * undumped (Lua does not verify bytecode; a corrupted chunk crashes it).
 *
 * Built two ways: with clang -fsanitize=fuzzer (make fuzz) it is a libFuzzer
 * target; in the test runner, eddy_fuzz_one() replays the files under
 * tests/fuzz/ (seeds, and every input that ever found a bug) on each make test. */
#include <lauxlib.h>
#include <lualib.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "eddy.h"
#include "eddy_lua.h"

/* Scenes are text: eddy never loads binary chunks. */
#define LOAD_MODE "t"

typedef struct input {
	const uint8_t *p;
	size_t n;
} input;

static unsigned take(input *in, unsigned range)
{
	if (in->n == 0 || range == 0)
		return 0;
	unsigned v = *in->p++;
	in->n--;
	return v % range;
}

/* A number as Lua source: mostly plausible, often hostile. */
static void number(input *in, char *out, size_t cap)
{
	static const char *const special[] = {"0",    "-1",    "1",  "0.5",  "1e-9", "1e9", "0/0",     "1/0",
	                                      "-1/0", "1e300", "-5", "0.01", "0.1",  "2",   "-1e-300", "3"};
	unsigned k = take(in, 24);
	if (k < 16)
		snprintf(out, cap, "%s", special[k]);
	else
		snprintf(out, cap, "%g", (double)(take(in, 256) + 256 * take(in, 256)) / 4096.0 - 2.0);
}

/* A field value of a random type. */
static void value(input *in, char *out, size_t cap)
{
	char a[32], b[32], c[32];
	switch (take(in, 8)) {
	case 0:
	case 1:
	case 2:
		number(in, out, cap);
		break;
	case 3:
	case 4:
		number(in, a, sizeof a);
		number(in, b, sizeof b);
		number(in, c, sizeof c);
		snprintf(out, cap, "{%s, %s, %s}", a, b, c);
		break;
	case 5:
		snprintf(out, cap, "%s", take(in, 2) ? "true" : "false");
		break;
	case 6: {
		static const char *const strs[] = {"'error'",
		                                   "'remove'",
		                                   "'cholmod'",
		                                   "'pcg'",
		                                   "{}",
		                                   "{1, 2}",
		                                   "{{0,0,0},{1,1,1}}",
		                                   "function(t) return {t, 0, 0} end",
		                                   "function(t) return nil end",
		                                   "function(t) error('boom') end"};
		snprintf(out, cap, "%s", strs[take(in, sizeof strs / sizeof strs[0])]);
		break;
	}
	default:
		number(in, a, sizeof a);
		snprintf(out, cap, "%s", a);
	}
}

static const char *const systems[] = {"emit_box",       "emit_nozzle",      "gravity",  "integrate",     "collide_box",
                                      "collide_sphere", "collide_plane",    "flip_p2g", "flip_boundary", "flip_surface",
                                      "flip_pressure",  "flip_extrapolate", "flip_g2p", "flip_advect",   "flip_reseed"};
static const char *const fields[] = {
	"min",         "max",         "spacing",    "jitter",   "velocity",      "start",       "center",
	"radius",      "direction",   "speed",      "duration", "max_particles", "scale",       "max_speed",
	"inside",      "restitution", "friction",   "offset",   "point",         "normal",      "typo",
	"mark_radius", "margin",      "sigma",      "solver",   "density",       "tolerance",   "max_iterations",
	"theta_min",   "layers",      "flip_ratio", "wall_gap", "min_per_cell",  "max_per_cell"};
static const char *const world_fields[] = {"bounds", "gravity", "fps",          "cfl",       "dt_max",  "dt_min",
                                           "seed",   "escape",  "check_finite", "cell_size", "duration"};

static lua_State *new_state(void)
{
	lua_State *L = luaL_newstate();
	if (!L)
		return NULL;
	luaL_openlibs(L);
	luaL_requiref(L, "eddy", luaopen_eddy, 0);
	lua_pop(L, 1);
	return L;
}

/* A binary chunk given as a scene: loading it in text mode must fail. */
static int load_as_given(const uint8_t *data, size_t size)
{
	lua_State *L = new_state();
	if (!L)
		return 0;
	if (luaL_loadbufferx(L, (const char *)data, size, "=fuzz", LOAD_MODE) == LUA_OK) {
		fprintf(stderr, "fuzz: a binary chunk was accepted by the text-only loader\n");
		abort();
	}
	lua_close(L);
	return 0;
}

/* Runs one input; returns 0 (libFuzzer's convention). */
int eddy_fuzz_one(const uint8_t *data, size_t size);
int eddy_fuzz_one(const uint8_t *data, size_t size)
{
	if (size >= 4 && memcmp(data, LUA_SIGNATURE, 4) == 0)
		return load_as_given(data, size);
	input in = {data, size};
	char src[8192], v[160];
	size_t len = 0;
#define EMIT(...)                                                    \
	do {                                                             \
		int k_ = snprintf(src + len, sizeof src - len, __VA_ARGS__); \
		if (k_ > 0 && (size_t)k_ < sizeof src - len)                 \
			len += (size_t)k_;                                       \
	} while (0)
	/* a step budget keeps hostile time steps from running for hours */
	EMIT("local eddy = require 'eddy'\nlocal w = eddy.world{ max_steps_per_frame = 300, escape = 'remove', "
	     "cell_size = 0.1");
	for (unsigned i = 0, nf = take(&in, 4); i < nf; ++i) {
		value(&in, v, sizeof v);
		EMIT(", %s = %s", world_fields[take(&in, sizeof world_fields / sizeof world_fields[0])], v);
	}
	EMIT(" }\n");
	for (unsigned s = 0, ns = take(&in, 9); s < ns; ++s) {
		EMIT("w:add(eddy.%s{", systems[take(&in, sizeof systems / sizeof systems[0])]);
		for (unsigned i = 0, nf = take(&in, 5); i < nf; ++i) {
			value(&in, v, sizeof v);
			EMIT("%s%s = %s", i ? ", " : "", fields[take(&in, sizeof fields / sizeof fields[0])], v);
		}
		EMIT("})\n");
	}
	if (take(&in, 4) == 0)
		EMIT("w:on_frame(function(w, f) local y = w:channel('y'); return { n = #y, first = y[1] } end)\n");
	EMIT("return w\n");
#undef EMIT

	lua_State *L = new_state();
	if (!L)
		return 0;
	if (luaL_loadbufferx(L, src, len, "=fuzz", LOAD_MODE) == LUA_OK && lua_pcall(L, 0, 1, 0) == LUA_OK) {
		eddy_world *w = eddy_lua_toworld(L, -1);
		/* step only scenes of a size a fuzzer can afford */
		int64_t expected = 0;
		for (int i = 0; w && i < eddy_world_system_count(w); ++i) {
			eddy_system_info info;
			if (eddy_world_system_info(w, eddy_world_system_at(w, i), &info) == EDDY_OK)
				expected += info.expected_particles < 0 ? 0 : info.expected_particles;
		}
		eddy_grid_info g = w ? eddy_world_grid(w) : (eddy_grid_info){0};
		if (w && expected <= 20000 && (double)g.nx * g.ny * g.nz <= 1e6) {
			char plan[64];
			eddy_world_plan(w, plan, sizeof plan);
			for (int step = 0; step < 200; ++step) {
				if (eddy_world_step(w) != EDDY_OK || eddy_world_particle_count(w) > 50000)
					break;
			}
			eddy_frame_stats st;
			eddy_world_frame_stats(w, &st);
		}
	}
	lua_close(L);
	return 0;
}

#ifdef EDDY_LIBFUZZER
int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);
int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) { return eddy_fuzz_one(data, size); }
#endif
