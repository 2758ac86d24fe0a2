/* SPDX-License-Identifier: MIT */
#define _POSIX_C_SOURCE 200809L
/* The Lua binding, run in an embedded state: errors name the scene file and
 * line, the system, the field and what is allowed; the API does what the
 * scene asks. */
#include "test.h"

#include <lauxlib.h>
#include <lualib.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "bind.h"
#include "eddy_lua.h"

static lua_State *new_state(void)
{
	lua_State *L = luaL_newstate();
	luaL_openlibs(L);
	luaL_requiref(L, "eddy", luaopen_eddy, 0);
	lua_pop(L, 1);
	return L;
}

/* Runs src as the chunk "@scenes/t.lua"; returns NULL on success or the error
 * message (valid until the state is closed). */
static const char *run(lua_State *L, const char *src)
{
	if (luaL_loadbuffer(L, src, strlen(src), "@scenes/t.lua") != LUA_OK || lua_pcall(L, 0, 1, 0) != LUA_OK)
		return lua_tostring(L, -1);
	return NULL;
}

static const char *run_fresh(const char *src, char *buf, size_t cap)
{
	lua_State *L = new_state();
	const char *err = run(L, src);
	snprintf(buf, cap, "%s", err ? err : "");
	lua_close(L);
	return err ? buf : NULL;
}

#define HEAD "local eddy = require 'eddy'\nlocal world = eddy.world{}\n"

static void unknown_field_names_file_line_and_fix(void)
{
	char buf[512];
	const char *e = run_fresh(HEAD "world:add(eddy.emit_box{ spacin = 0.01 })\n", buf, sizeof buf);
	CHECK_HAS(e, "scenes/t.lua:3: emit_box: unknown field 'spacin' (did you mean 'spacing'?");
	CHECK_HAS(e, "fields: min, max, spacing, jitter, velocity, start, shape)");
	e = run_fresh("local eddy = require 'eddy'\nlocal w = eddy.world{ bounds = {{0,0,0},{1,1,1}}, fsp = 3 }\n", buf,
	              sizeof buf);
	CHECK_HAS(e, "scenes/t.lua:2: world: unknown field 'fsp' (did you mean 'fps'?");
}

static void wrong_type_and_range(void)
{
	char buf[512];
	const char *e = run_fresh(HEAD "world:add(eddy.emit_box{ spacing = 'fine' })\n", buf, sizeof buf);
	CHECK_HAS(e, "scenes/t.lua:3: emit_box: 'spacing' must be a number (got string)");
	e = run_fresh(HEAD "world:add(eddy.emit_box{ min = {0, 0} })\n", buf, sizeof buf);
	CHECK_HAS(e, "scenes/t.lua:3: emit_box: 'min' must be a table of 3 numbers {x, y, z}");
	e = run_fresh(HEAD "\nworld:add(eddy.emit_box{ spacing = -0.01 })\n", buf, sizeof buf);
	CHECK_HAS(e, "scenes/t.lua:4: emit_box: 'spacing' must be > 0 (got -0.01)");
	e = run_fresh(HEAD "world:add(eddy.collide_box{ inside = 1 })\n", buf, sizeof buf);
	CHECK_HAS(e, "scenes/t.lua:3: collide_box: 'inside' must be true or false (got number)");
	e = run_fresh("local eddy = require 'eddy'\nlocal w = eddy.world{ escape = 'bounce' }\n", buf, sizeof buf);
	CHECK_HAS(e, "scenes/t.lua:2: world: 'escape' must be \"error\" or \"remove\" (got bounce)");
	e = run_fresh("local eddy = require 'eddy'\nlocal w = eddy.world{ cfl = 0 }\n", buf, sizeof buf);
	CHECK_HAS(e, "scenes/t.lua:2: world: 'cfl' must be in (0, 10] (got 0)");
	e = run_fresh("local eddy = require 'eddy'\nlocal w = eddy.world{ settle_steps = -1 }\n", buf, sizeof buf);
	CHECK_HAS(e, "scenes/t.lua:2: world: 'settle_steps' must be in [0, 1000000] (got -1)");
	e = run_fresh(HEAD "world:add(eddy.emit_nozzle{ max_particles = 1.5 })\n", buf, sizeof buf);
	CHECK_HAS(e, "emit_nozzle: 'max_particles' must be an integer");
	e = run_fresh(HEAD "world:add({})\n", buf, sizeof buf);
	CHECK_HAS(e, "scenes/t.lua:3: add: expects a system made by eddy.<system>{...}");
}

static void order_error_in_lua(void)
{
	char buf[512];
	const char *e = run_fresh(HEAD "world:add(eddy.emit_box{})\nworld:add(eddy.integrate{})\n", buf, sizeof buf);
	CHECK_HAS(e, "scenes/t.lua:4: integrate reads 'ax' but no earlier system writes it: add gravity before it");
}

static void stale_handle_in_lua(void)
{
	char buf[512];
	const char *e = run_fresh(HEAD "local s = world:add(eddy.collide_sphere{})\nworld:remove(s)\n"
	                               "assert(not s:valid())\ns:set_offset{0, 0.1, 0}\n",
	                          buf, sizeof buf);
	CHECK_HAS(e, "scenes/t.lua:6: stale system handle");
}

/* h:mass() gives sph_density's calibrated particle mass, rho0 / sum_lattice
 * W (0.99 rho0 dx^3 at h = 2 dx), and names the system that has none. */
static void sph_mass_from_the_handle(void)
{
	char buf[512];
	const char *e = run_fresh(HEAD "local d = world:add(eddy.sph_density{ spacing = 0.01, radius = 0.02 })\n"
	                               "local m = d:mass()\n"
	                               "assert(math.abs(m - 1000 * 0.01^3 / 1.0097752) < 1e-8, m)\n"
	                               "world:add(eddy.gravity{}):mass()\n",
	                          buf, sizeof buf);
	CHECK_HAS(e, "scenes/t.lua:6: gravity has no particle mass (only sph_density calibrates one)");
}

static void world_api_and_channels(void)
{
	lua_State *L = new_state();
	const char *e = run(L, HEAD "world:add(eddy.emit_box{ min = {0.1,0.1,0.1}, max = {0.2,0.3,0.2}, spacing = 0.05 })\n"
	                            "world:add(eddy.gravity{})\n"
	                            "world:add(eddy.integrate{})\n"
	                            "world:add(eddy.collide_box{})\n"
	                            "world:advance(0.1)\n"
	                            "local y = world:channel('y')\n"
	                            "assert(#y == world:count() and #y == 16, 'count ' .. #y)\n"
	                            "assert(y[1] > 0 and y[1] < 0.3 and y[0] == nil and y[17] == nil)\n"
	                            "local n = 0; for i, v in ipairs(y) do n = i end\n"
	                            "assert(n == 16, 'ipairs ' .. n)\n"
	                            "assert(math.abs(world:time() - 0.1) < 1e-12 and world:frame() == 3)\n"
	                            "assert(world:step() > 0)\n"
	                            "assert(world:plan():find('collide_box', 1, true))\n"
	                            "assert(world:plan{dot = true}:find('digraph', 1, true))\n"
	                            "local ok, err = pcall(world.channel, world, 'density')\n"
	                            "assert(not ok and err:find('not allocated', 1, true), err)\n"
	                            "assert(#world:warnings() == 0 and world:stats().warnings == 0)\n"
	                            "return world:stats()\n");
	CHECKF(e == NULL, "%s", e);
	if (!e) {
		lua_getfield(L, -1, "particles");
		CHECK(lua_tointeger(L, -1) == 16);
		lua_getfield(L, -2, "state_hash");
		CHECK(lua_tostring(L, -1) && strlen(lua_tostring(L, -1)) == 16);
	}
	lua_close(L);
}

/* world:warnings() lists the run-time warnings, and world:stats() counts them. */
static void warnings_from_lua(void)
{
	lua_State *L = new_state();
	const char *e = run(L, HEAD "world:add(eddy.emit_box{ min = {0.1,0.5,0.1}, max = {0.2,0.6,0.2}, spacing = 0.05 })\n"
	                            "world:add(eddy.gravity{})\n"
	                            "world:add(eddy.integrate{ max_speed = 0.5 })\n"
	                            "world:advance(0.2)\n"
	                            "local ws = world:warnings()\n"
	                            "assert(#ws == 1 and world:stats().warnings == 1, #ws)\n"
	                            "assert(ws[1]:find('max_speed = 0.5 m/s at step', 1, true), ws[1])\n"
	                            "return world\n");
	CHECKF(e == NULL, "%s", e);
	lua_close(L);
}

static void on_frame_fields_merge(void)
{
	lua_State *L = new_state();
	const char *e = run(L, HEAD "world:add(eddy.emit_box{ min = {0.1,0.1,0.1}, max = {0.2,0.2,0.2}, spacing = 0.05 })\n"
	                            "world:on_frame(function(w, f) return { a = f } end)\n"
	                            "world:on_frame(function(w, f) return { b = w:count() } end)\n"
	                            "return world\n");
	CHECKF(e == NULL, "%s", e);
	eddy_world *w = eddy_lua_toworld(L, -1);
	CHECK(w != NULL);
	if (w) {
		CHECK(eddy_world_step_frame(w) == EDDY_OK);
		CHECK(eddy_world_step_frame(w) == EDDY_OK);
		eddy_lua_take_frame_fields(L, -1);
		CHECK(lua_istable(L, -1));
		lua_getfield(L, -1, "a");
		CHECK(lua_tointeger(L, -1) == 2);
		lua_getfield(L, -2, "b");
		CHECK(lua_tointeger(L, -1) == 8);
		lua_pop(L, 3);
		eddy_lua_take_frame_fields(L, -1);
		CHECK(lua_isnil(L, -1)); /* taken: cleared for the next frame */
		lua_pop(L, 1);
	}
	lua_close(L);

	char buf[512];
	e = run_fresh(HEAD "world:on_frame(function(w, f) local x = nil; return x.y end)\nworld:advance(0.1)\n", buf,
	              sizeof buf);
	CHECK_HAS(e, "on_frame: scenes/t.lua:3: attempt to index");
	e = run_fresh(HEAD "world:on_frame(function(w, f) return 42 end)\nworld:advance(0.1)\n", buf, sizeof buf);
	CHECK_HAS(e, "on_frame: must return a table of stats fields or nothing (got number)");
	e = run_fresh(HEAD "world:on_frame(function(w, f) w:advance(1) end)\nworld:advance(0.1)\n", buf, sizeof buf);
	CHECK_HAS(e, "scenes/t.lua:3: world:advance() cannot be called from inside on_frame");
}

/* Runs src (which returns its world) and steps one frame from C, as the eddy
 * command does; returns the frame's status, the world error in err. */
static eddy_status step_frame_from_c(const char *src, char *err, size_t cap, double *time, int *frame)
{
	lua_State *L = new_state();
	const char *e = run(L, src);
	eddy_world *w = e ? NULL : eddy_lua_toworld(L, -1);
	CHECKF(w != NULL, "%s", e ? e : "the scene returned no world");
	eddy_status st = w ? eddy_world_step_frame(w) : EDDY_ERR_INVALID;
	snprintf(err, cap, "%s", w && st != EDDY_OK ? eddy_world_error(w) : "");
	*time = w ? eddy_world_time(w) : -1;
	*frame = w ? eddy_world_frame(w) : -1;
	lua_close(L);
	return st;
}

/* A world's own callbacks may not step it, add to it, remove from it or close
 * it, whoever steps the world (Lua or the host in C): the step in progress
 * holds its systems and columns. The refused call leaves time and frame as
 * they were; the error names the call and the callback at the scene's line. */
static void callbacks_cannot_reenter_their_world(void)
{
	char err[512];
	double t;
	int frame;
	eddy_status st =
		step_frame_from_c(HEAD "world:add(eddy.emit_box{ min = {0.1,0.1,0.1}, max = {0.2,0.2,0.2}, spacing = 0.05 })\n"
	                           "world:on_frame(function(w, f) w:advance(1) end)\n"
	                           "return world\n",
	                      err, sizeof err, &t, &frame);
	CHECK(st == EDDY_ERR_EXTERNAL);
	CHECK_HAS(err, "on_frame: scenes/t.lua:4: world:advance() cannot be called from inside on_frame");
	CHECKF(frame <= 1 && t <= 1.0 / 30 + 1e-9, "frame %d, t %g: the refused advance ran", frame, t);

	/* every refused call, caught: the frame completes as if none was made */
	st = step_frame_from_c(
		HEAD
		"local g = world:add(eddy.gravity{})\n"
		"world:on_frame(function(w, f)\n"
		"  local t, n = w:time(), w:frame()\n"
		"  local calls = {\n"
		"    {'advance', function() w:advance(1) end}, {'step', function() w:step() end},\n"
		"    {'add', function() w:add(eddy.integrate{}) end}, {'remove', function() w:remove(g) end},\n"
		"    {'on_frame', function() w:on_frame(print) end}, {'close', function() w:close() end},\n"
		"    {'close', function() local c <close> = w end},\n"
		"    {'close', function() getmetatable(w).__gc(w) end},\n"
		"  }\n"
		"  for _, c in ipairs(calls) do\n"
		"    local ok, e = pcall(c[2])\n"
		"    assert(not ok and e:find('world:' .. c[1] .. '() cannot be called from inside on_frame', 1, true), e)\n"
		"  end\n"
		"  assert(w:time() == t and w:frame() == n and g:valid())\n"
		"end)\n"
		"return world\n",
		err, sizeof err, &t, &frame);
	CHECKF(st == EDDY_OK, "%s", err);
	CHECK(frame == 1);
	CHECK_NEAR(t, 1.0 / 30, 1e-9);

	/* an animated offset function, during a step and when the collider is added */
	st = step_frame_from_c(HEAD "world:add(eddy.collide_sphere{ offset = function(t)\n"
	                            "  if t > 0 then world:step() end\n"
	                            "  return {0, 0, 0} end })\n"
	                            "return world\n",
	                       err, sizeof err, &t, &frame);
	CHECK(st == EDDY_ERR_EXTERNAL);
	CHECK_HAS(err, "scenes/t.lua:4: world:step() cannot be called from inside an offset function");
	char buf[512];
	const char *e =
		run_fresh(HEAD "world:add(eddy.collide_sphere{ offset = function(t) world:close(); return {0, 0, 0} end })\n",
	              buf, sizeof buf);
	CHECK_HAS(e, "scenes/t.lua:3: world:close() cannot be called from inside an offset function");
}

static void params_convert_to_the_default_type(void)
{
	lua_State *L = new_state();
	eddy_lua_set_param(L, "spacing", "0.05");
	eddy_lua_set_param(L, "solver", "pcg");
	eddy_lua_set_param(L, "fast", "true");
	eddy_lua_set_param(L, "typo", "1");
	const char *e = run(L, "local eddy = require 'eddy'\n"
	                       "assert(eddy.param('spacing', 0.02) == 0.05)\n"
	                       "assert(eddy.param('solver', 'cholmod') == 'pcg')\n"
	                       "assert(eddy.param('fast', false) == true)\n"
	                       "assert(eddy.param('absent', 7) == 7)\n");
	CHECKF(e == NULL, "%s", e);
	eddy_lua_push_unused_params(L);
	lua_getfield(L, -1, "typo");
	CHECK(lua_toboolean(L, -1));
	lua_getfield(L, -2, "spacing");
	CHECK(!lua_toboolean(L, -1));
	lua_close(L);

	L = new_state();
	eddy_lua_set_param(L, "spacing", "fine");
	e = run(L, "local eddy = require 'eddy'\nlocal h = eddy.param('spacing', 0.02)\n");
	CHECK_HAS(e, "scenes/t.lua:2: --set spacing=fine: 'spacing' must be a number");
	lua_close(L);
}

/* An animated offset moves the collider each step and shows in the plan. */
static void animated_collider(void)
{
	lua_State *L = new_state();
	const char *e =
		run(L, HEAD "local s = world:add(eddy.collide_sphere{ center = {0.5,0.5,0.5}, radius = 0.1,\n"
	                "  offset = function(t) return {t, 0, 0} end })\n"
	                "world:advance(0.2)\n"
	                "local o = s:offset()\n"
	                "assert(math.abs(o[1] - 0.2) < 1e-6, 'offset ' .. o[1])\n"
	                "assert(world:plan():find('animate', 1, true))\n"
	                "local ok, err = pcall(eddy.collide_plane, { offset = function() end, normal = 3 })\n"
	                "assert(not ok and err:find(\"'normal' must be a table of 3 numbers\", 1, true), err)\n");
	CHECKF(e == NULL, "%s", e);
	lua_close(L);
	char buf[512];
	e = run_fresh(HEAD "world:add(eddy.collide_sphere{ offset = function(t) return {t} end })\n", buf, sizeof buf);
	CHECK_HAS(e, "scenes/t.lua:3: collide_sphere: 'offset (returned by the function)' must be a table of 3 numbers");
}

/* eddy.fluid{}: the group expands into each method's systems in its order,
 * tagged with the group (plans show it), and it steps; fields that do not
 * apply to the method, unknown fields and methods are errors at the scene's
 * line. */
static const char *run_group(const char *src, char *buf, size_t cap)
{
	lua_State *L = new_state();
	lua_getglobal(L, "package");
	lua_pushliteral(L, "lua/?.lua");
	lua_setfield(L, -2, "path");
	lua_pop(L, 1);
	const char *err = run(L, src);
	snprintf(buf, cap, "%s", err ? err : lua_tostring(L, -1));
	lua_close(L);
	return buf;
}

/* eddy.fluid passes sph_density's density, diffusion and verlet_list on:
 * the continuity density shows in the plan as its state column sph_rho,
 * for WCSPH only (the wcsph table is not applied to DFSPH), and a bad
 * verlet_list reaches sph_density's own check. */
static void fluid_group_passes_sph_density_fields(void)
{
	static const char *const fmt = "local eddy = require 'eddy'\n"
								   "local fluid = eddy.fluid { method = '%s', resolution = 0.02, verlet_list = %s,\n"
								   "  wcsph = { density = 'continuity', diffusion = 0.08 } }\n"
								   "local world = fluid:world { bounds = { {0, 0, 0}, {0.3, 0.3, 0.1} } }\n"
								   "world:add(fluid)\n"
								   "return world:plan()\n";
	char src[1024], buf[4096];
	snprintf(src, sizeof src, fmt, "wcsph", "false");
	CHECK_HAS(run_group(src, buf, sizeof buf), "sph_rho");
	snprintf(src, sizeof src, fmt, "dfsph", "false");
	const char *out = run_group(src, buf, sizeof buf);
	CHECKF(strstr(out, "sph_density") && !strstr(out, "sph_rho"), "%s", out);
	snprintf(src, sizeof src, fmt, "wcsph", "3");
	CHECK_HAS(run_group(src, buf, sizeof buf), "sph_density: 'verlet_list' must be true or false");
}

static void fluid_group_expands_per_method(void)
{
	static const struct {
		const char *method, *systems;
	} cases[] = {
		{"wcsph", "sph_density sph_pressure sph_viscosity gravity sph_boundary_box integrate collide_box|"},
		{"dfsph", "sph_density gravity sph_viscosity sph_dfsph sph_boundary_box integrate collide_box|"},
		{"flip", "gravity flip_p2g flip_boundary flip_surface flip_pressure flip_extrapolate flip_g2p flip_advect|"},
		{"pic", "gravity flip_p2g flip_boundary flip_surface flip_pressure flip_extrapolate flip_g2p flip_advect|"},
	};
	char src[1024], buf[4096];
	for (size_t c = 0; c < sizeof cases / sizeof cases[0]; ++c) {
		snprintf(
			src, sizeof src,
			"local eddy = require 'eddy'\n"
			"local fluid = eddy.fluid { method = '%s', resolution = 0.02 }\n"
			"local world = fluid:world { bounds = { {0, 0, 0}, {0.3, 0.3, 0.1} }, fps = 30, duration = 0.1 }\n"
			"world:add(eddy.emit_box { min = {0, 0, 0}, max = {0.1, 0.1, 0.1}, spacing = fluid.spacing })\n"
			"local h = world:add(fluid)\n"
			"world:advance(1 / 30)\n"
			"local names = {}\n"
			"for i, s in ipairs(h) do names[i] = s:name():gsub('#%%d+', '') end\n"
			"local st = world:stats()\n"
			"assert(type(st.energy) == 'number' and st.kinetic_energy >= 0 and #st.momentum == 3, 'energy stats')\n"
			"return table.concat(names, ' ') .. '|' .. h[1]:group() .. '|' .. world:plan() .. '|' .. world:count()\n",
			cases[c].method);
		const char *out = run_group(src, buf, sizeof buf);
		CHECKF(strncmp(out, cases[c].systems, strlen(cases[c].systems)) == 0, "%s: %s", cases[c].method, out);
		char group[128];
		snprintf(group, sizeof group, "|fluid{method = %s, resolution = 0.02 m}|", cases[c].method);
		CHECK_HAS(out, group);
		snprintf(group, sizeof group, "      group fluid{method = %s, resolution = 0.02 m}:\n", cases[c].method);
		CHECK_HAS(out, group);
		CHECK_HAS(out, "|125");
	}
	static const struct {
		const char *fields, *error;
	} bad[] = {
		{"method = 'flip', resolution = 0.02, stiffness = 100",
	     "scenes/t.lua:2: eddy.fluid: 'stiffness' does not apply to method 'flip' (it applies to wcsph; fields for "
	     "flip: cell_size, flip_ratio,"},
		{"method = 'sph', resolution = 0.02", "scenes/t.lua:2: eddy.fluid: 'method' must be one of wcsph, dfsph, flip, "
	                                          "pic, apic (got sph)"},
		{"method = 'dfsph', resolution = 0.02, tolerence = 0.01",
	     "scenes/t.lua:2: eddy.fluid: unknown field 'tolerence'"},
		{"method = 'flip', resolution = 0.02, wcsph = { stiffness = 100 }, flip = { stiffness = 1 }",
	     "scenes/t.lua:2: eddy.fluid: 'stiffness' in flip = {...} does not apply to method 'flip'"},
		{"method = 'wcsph', resolution = -1", "scenes/t.lua:2: eddy.fluid: 'resolution' (m, the particle spacing) must "
	                                          "be a number > 0 (got -1)"},
		{"method = 'dfsph', resolution = 0.02, tolerance = -1",
	     "scenes/t.lua:4: eddy.fluid: sph_dfsph: 'max_density_error' must be > 0 (got -1)"},
	};
	for (size_t c = 0; c < sizeof bad / sizeof bad[0]; ++c) {
		snprintf(src, sizeof src,
		         "local eddy = require 'eddy'\nlocal fluid = eddy.fluid { %s }\n"
		         "local world = fluid:world { bounds = { {0, 0, 0}, {0.3, 0.3, 0.1} } }\nworld:add(fluid)\n",
		         bad[c].fields);
		CHECK_HAS(run_group(src, buf, sizeof buf), bad[c].error);
	}
	/* SPH needs the tank: a world made without fluid:world and no tank field */
	CHECK_HAS(
		run_group("local eddy = require 'eddy'\nlocal fluid = eddy.fluid { method = 'wcsph', resolution = 0.02 }\n"
	              "local world = eddy.world {}\nworld:add(fluid)\n",
	              buf, sizeof buf),
		"scenes/t.lua:4: eddy.fluid: an SPH method needs the tank's walls");
}

static void every_field_rejects_nan_and_inf(void);

/* A state as eddy run --safe makes it: eddy's Lua helpers on package.path,
 * a C module reachable on package.cpath until the sandbox removes it, and the
 * output directory in the global OUT. */
static lua_State *new_safe_state(const char *out)
{
	lua_State *L = new_state();
	char cpath[1024];
	snprintf(cpath, sizeof cpath, "%s/?.so", test_build_dir());
	lua_getglobal(L, "package");
	lua_pushliteral(L, "lua/?.lua");
	lua_setfield(L, -2, "path");
	lua_pushstring(L, cpath);
	lua_setfield(L, -2, "cpath");
	lua_pop(L, 1);
	eddy_lua_set_out_dir(L, out);
	int rc = eddy_lua_sandbox(L, out);
	CHECKF(rc == LUA_OK, "%s", lua_tostring(L, -1));
	lua_pushstring(L, out);
	lua_setglobal(L, "OUT");
	return L;
}

/* Under eddy_lua_sandbox a scene cannot run commands, write outside its
 * output directory, load native code or bytecode or reach the debug library;
 * each refusal is a Lua error (or load's nil and message) that says why. */
static void safe_mode_refuses_escapes(void)
{
	char out[] = "/tmp/eddy_safe_XXXXXX";
	CHECK(mkdtemp(out) != NULL);
	static const struct {
		const char *code, *want;
	} refused[] = {
		{"os.execute('true')", "scenes/t.lua:1: os.execute is not available in safe mode (--safe)"},
		{"os.remove(OUT .. '/x')", "os.remove is not available in safe mode"},
		{"os.rename('a', 'b')", "os.rename is not available in safe mode"},
		{"os.exit(3)", "os.exit is not available in safe mode"},
		{"io.popen('ls')", "io.popen is not available in safe mode"},
		{"io.tmpfile()", "io.tmpfile is not available in safe mode"},
		{"io.open('/tmp/x', 'w')", "io.open: cannot write '/tmp/x': files are written only under the output directory"},
		{"io.open('/tmp/x', 'r+')", "io.open: cannot write '/tmp/x'"},
		{"io.open(OUT .. '/../x', 'w')", "a path with a '..' component is not written in safe mode"},
		{"io.open(OUT .. '/a/../../x', 'a')", "a path with a '..' component"},
		{"io.open(OUT, 'w')", "only under the output directory"},
		{"io.open(OUT .. 'x/y', 'w')", "only under the output directory"},
		{"io.open('x.txt', 'w')", "only under the output directory"},
		{"io.output('/tmp/x')", "io.output: cannot write '/tmp/x'"},
		{"package.loadlib('/lib/x.so', 'f')", "package.loadlib is not available in safe mode"},
		{"package.loaded.eddy = nil; local ok, err = pcall(require, 'eddy'); package.loaded.eddy = eddy; error(err)",
	     "C modules (package.cpath) are not loaded in safe mode"},
		{"package.cpath = '/usr/lib/?.so'; require 'nosuchmodule'", "C modules (package.cpath) are not loaded"},
		{"assert(load(string.dump(function() end)))",
	     "load: binary chunks (string.dump) cannot be loaded in safe mode"},
		{"assert(load(string.dump(function() end), 'x', 'b'))", "binary chunks (string.dump) cannot be loaded"},
		{"local s = string.dump(function() end); assert(load(function() local r = s; s = nil; return r end))",
	     "attempt to load a binary chunk (mode is 't')"},
		{"local f = assert(io.open(OUT .. '/dumped.lua', 'wb')); f:write(string.dump(function() end)); f:close()\n"
	     "assert(loadfile(OUT .. '/dumped.lua', 'b'))",
	     "/dumped.lua: a binary (precompiled) chunk: eddy loads Lua source only"},
		{"dofile(OUT .. '/dumped.lua')", "/dumped.lua: a binary (precompiled) chunk"},
		{"package.path = OUT .. '/?.lua'; require 'dumped'", "error loading module 'dumped' from file"},
		{"debug.getinfo(1)", "global 'debug'"},
		{"require 'debug'", "module 'debug' not found"},
		{"local w = eddy.world{}; w:add(eddy.render_points{ path = '/tmp/f_%04d.png' })",
	     "render_points: cannot write '/tmp/f_%04d.png'"},
		{"local w = eddy.world{}; w:add(eddy.export_particles{ path = OUT .. '/../p_%04d.ply' })",
	     "export_particles: cannot write"},
		{"eddy.load_scene('scenes/bounce.lua', { safe = false })",
	     "load_scene: safe = false is not available in safe mode"},
		{"eddy.load_scene('scenes/bounce.lua', { out = '/tmp' })",
	     "load_scene: 'out' must be the output directory or below it"},
		{"eddy.load_scene('scenes/bounce.lua', { out = OUT .. '/../x' })",
	     "load_scene: 'out' must be the output directory"},
	};
	lua_State *L = new_safe_state(out);
	for (size_t i = 0; i < sizeof refused / sizeof refused[0]; ++i) {
		char src[1024];
		snprintf(src, sizeof src, "local eddy = require 'eddy'; %s", refused[i].code);
		int top = lua_gettop(L);
		const char *e = run(L, src);
		CHECKF(e && strstr(e, refused[i].want), "%s: expected \"%s\", got: %s", refused[i].code, refused[i].want,
		       e ? e : "no error");
		lua_settop(L, top);
	}
	/* a symbolic link in the output directory that leads out of it */
	char link[512];
	snprintf(link, sizeof link, "%s/away", out);
	CHECK(symlink("/tmp", link) == 0);
	const char *e = run(L, "io.open(OUT .. '/away/x', 'w')");
	CHECK_HAS(e, "a symbolic link leads out of it");
	unlink(link);
	lua_close(L);
	char cmd[600], buf[256];
	snprintf(cmd, sizeof cmd, "rm -rf '%s'", out);
	test_sh(cmd, buf, sizeof buf);
}

static void write_file(const char *path, const char *text, size_t len)
{
	FILE *f = fopen(path, "wb");
	CHECK(f != NULL);
	if (f) {
		fwrite(text, 1, len, f);
		fclose(f);
	}
}

/* eddy.load_scene, from a state with every library (the stock interpreter's):
 * the scene runs text-only in fresh sandboxed globals, with the refusals of
 * eddy_lua_sandbox, and returns what it returns; the host's globals and
 * libraries are untouched. */
static void load_scene_runs_a_scene_sandboxed(void)
{
	char out[] = "/tmp/eddy_safe_XXXXXX";
	CHECK(mkdtemp(out) != NULL);
	char path[600], luac[600], cmd[2048], buf[512];
	snprintf(path, sizeof path, "%s/escape.lua", out);
	const char *escape = "X_LEAKED = true\nlocal ok, e = pcall(os.execute, 'true')\n"
						 "assert(not ok and e:find('os.execute is not available in safe mode', 1, true), e)\n"
						 "ok, e = pcall(io.open, '/tmp/x', 'w')\n"
						 "assert(not ok and e:find('only under the output directory', 1, true), e)\n"
						 "assert(io.open(eddy_out .. '/ok.txt', 'w')):close()\n"
						 "assert(debug == nil and package.loadlib ~= nil and not pcall(package.loadlib, 'x', 'y'))\n"
						 "assert(not load(string.dump(function() end)))\n"
						 "local eddy = require 'eddy'\n"
						 "assert(eddy.out_dir() == eddy_out)\n"
						 "return eddy.world{}, 42, function() return eddy.world{} end,\n"
						 "  function() return eddy.load_scene('scenes/bounce.lua', { safe = false }) end\n";
	/* the out option is the scene's eddy.out_dir() */
	char scene[2048];
	snprintf(scene, sizeof scene, "local eddy_out = require('eddy').out_dir()\n%s", escape);
	write_file(path, scene, strlen(scene));
	lua_State *L = new_state();
	lua_pushstring(L, path);
	lua_setglobal(L, "SCENE");
	lua_pushstring(L, out);
	lua_setglobal(L, "OUT");
	const char *e = run(L, "local eddy = require 'eddy'\n"
	                       "local w, n, make_world, unsafe = eddy.load_scene(SCENE, { safe = true, out = OUT })\n"
	                       "assert(eddy.world and tostring(w):find('eddy world', 1, true) and n == 42)\n"
	                       /* the scene's functions stay sandboxed after it returned */
	                       "local w2 = make_world()\n"
	                       "local ok, err = pcall(w2.add, w2, eddy.render_points{ path = '/tmp/f_%04d.png' })\n"
	                       "assert(not ok and err:find('render_points: cannot write', 1, true), err)\n"
	                       "ok, err = pcall(unsafe)\n"
	                       "assert(not ok and err:find('safe = false is not available in safe mode', 1, true), err)\n"
	                       "assert(X_LEAKED == nil and type(os.execute) == 'function' and debug ~= nil)\n"
	                       "assert(io.open(OUT .. '/ok.txt')):close()\n"
	                       "ok, err = pcall(eddy.load_scene, SCENE, { sfae = true })\n"
	                       "assert(not ok and err:find(\"unknown option 'sfae'\", 1, true), err)\n"
	                       "w = eddy.load_scene('scenes/bounce.lua', { out = OUT })\n"
	                       "w:advance(0.05)\n"
	                       "assert(w:frame() == 1)\n"
	                       "return true\n");
	CHECKF(e == NULL, "%s", e);
	/* a precompiled scene is refused, not undumped */
	snprintf(luac, sizeof luac, "%s/bounce.luac", out);
	snprintf(cmd, sizeof cmd, "cp tests/fuzz/regressions/luac_corrupt_segv_a.bin '%s'", luac);
	CHECK(test_sh(cmd, buf, sizeof buf) == 0);
	lua_pushstring(L, luac);
	lua_setglobal(L, "SCENE");
	e = run(L, "local eddy = require 'eddy'\nreturn eddy.load_scene(SCENE, { safe = false })\n");
	CHECK_HAS(e, "/bounce.luac: a binary (precompiled) chunk: eddy loads Lua source only");
	lua_close(L);
	snprintf(cmd, sizeof cmd, "rm -rf '%s'", out);
	test_sh(cmd, buf, sizeof buf);
}

/* What a scene needs still works under the sandbox: writing under the output
 * directory, reading anywhere, the kept os functions, text chunks, eddy's Lua
 * helpers, and a whole scene (bounce) that loads and steps. */
static void safe_mode_keeps_what_scenes_use(void)
{
	char out[] = "/tmp/eddy_safe_XXXXXX";
	CHECK(mkdtemp(out) != NULL);
	lua_State *L = new_safe_state(out);
	const char *e = run(L, "local f = assert(io.open(OUT .. '/ok.txt', 'w')); f:write('ok'); f:close()\n"
	                       "assert(io.open(OUT .. '/./ok.txt', 'a')):close()\n"
	                       "assert(io.open(OUT .. '//ok.txt', 'rb')):close()\n"
	                       "assert(assert(io.open(OUT .. '/ok.txt')):read('a') == 'ok')\n"
	                       "assert(io.open('scenes/bounce.lua'):read('a'):find('require \"eddy\"', 1, true))\n"
	                       "local n = 0; for _ in io.lines('scenes/bounce.lua') do n = n + 1 end; assert(n > 10)\n"
	                       "assert(os.time() and os.clock() and os.date('%Y') and os.difftime(2, 1) == 1)\n"
	                       "assert(os.getenv('EDDY_NO_SUCH_VARIABLE') == nil)\n"
	                       "assert(load('return 1 + 1')() == 2 and load('return x', 'c', 't', { x = 3 })() == 3)\n"
	                       "local dam = require 'eddy.dam_break'\n"
	                       "assert(type(dam) == 'table' and package.loaded['eddy.dam_break'] == dam)\n"
	                       "assert(require 'string' == string)\n"
	                       "local world = dofile('scenes/bounce.lua')\n"
	                       "world:advance(0.1)\n"
	                       "assert(world:frame() == 3 and world:count() > 0)\n"
	                       "return world\n");
	CHECKF(e == NULL, "%s", e);
	lua_close(L);
	char cmd[600], buf[256];
	snprintf(cmd, sizeof cmd, "ls '%s'", out);
	CHECK(test_sh(cmd, buf, sizeof buf) == 0);
	CHECK_HAS(buf, "ok.txt");
	CHECK_HAS(buf, "frame_0003.png"); /* bounce renders into eddy.out_dir() */
	snprintf(cmd, sizeof cmd, "rm -rf '%s'", out);
	test_sh(cmd, buf, sizeof buf);
}

/* Misuse through the API (handles of other worlds, views of closed worlds,
 * metamethods that close the world mid-call, out-of-range numbers) is a Lua
 * error or a harmless value, never a crash. */
static void arguments_that_once_crashed(void)
{
	char buf[512];
	const char *e = run_fresh(HEAD "local other = eddy.world{}\nlocal g = other:add(eddy.gravity{})\n"
	                               "world:add(eddy.gravity{})\nworld:remove(g)\n",
	                          buf, sizeof buf);
	CHECK_HAS(e, "scenes/t.lua:6: remove: the handle belongs to another world");
	e = run_fresh(HEAD "local opts = setmetatable({}, { __index = function() world:close() end })\n"
	                   "world:plan(opts)\n",
	              buf, sizeof buf);
	CHECK_HAS(e, "scenes/t.lua:4: world is closed");
	e = run_fresh(HEAD "world:add(eddy.emit_box{ min = {0.1,0.1,0.1}, max = {0.2,0.2,0.2}, spacing = 0.05 })\n"
	                   "world:add(eddy.gravity{}); world:add(eddy.integrate{})\n"
	                   "world:step()\n"
	                   "local y = world:channel('y')\n"
	                   "assert(#y == 8 and y[1] and y[math.maxinteger] == nil and y[math.mininteger] == nil)\n"
	                   "assert(y[1.5] == nil and y.x == nil and y[0/0] == nil)\n"
	                   "world:close()\n"
	                   "assert(#y == 0 and y[1] == nil and tostring(world) == 'eddy world (closed)')\n"
	                   "world:close()\n"
	                   "local ok, err = pcall(world.time, world)\n"
	                   "assert(not ok and err:find('world is closed', 1, true), err)\n"
	                   "ok, err = pcall(world.channel, eddy.world{}, string.rep('y', 100))\n"
	                   "assert(not ok and err:find('no column named', 1, true), err)\n"
	                   "local w2 = eddy.world{}\n"
	                   "ok, err = pcall(w2.advance, w2, 1e300)\n"
	                   "assert(not ok and err:find('past the last frame a world counts', 1, true), err)\n"
	                   "assert(w2:frame() == 0 and w2:time() == 0)\n"
	                   "ok, err = pcall(world.add, eddy.gravity{}, eddy.gravity{})\n"
	                   "assert(not ok and err:find('eddy.world expected', 1, true), err)\n",
	              buf, sizeof buf);
	CHECKF(e == NULL, "%s", e);
	/* a float field beyond the float range is infinite, and rejected as such */
	e = run_fresh(HEAD "world:add(eddy.emit_box{ spacing = 1e300 })\n", buf, sizeof buf);
	CHECK_HAS(e, "'spacing' must be");
	e = run_fresh(HEAD "world:add(eddy.emit_box{ min = {0, -1e300, 0} })\n", buf, sizeof buf);
	CHECK_HAS(e, "'min'");
}

/* --threads reaches a world when the scene creates it (eddy_lua_set_threads
 * before the scene runs), so what the scene builds while adding systems (a
 * mesh collider's distance field) runs on those threads; 0 leaves the
 * scene's own choice. */
static void threads_override_applies_at_creation(void)
{
	lua_State *L = new_state();
	eddy_lua_set_threads(L, 2);
	CHECK(run(L, "local eddy = require 'eddy'\nreturn eddy.world{ threads = 1 }\n") == NULL);
	const eddy_world *w = eddy_lua_toworld(L, -1);
	CHECK(w != NULL && eddy_world_get_def(w)->threads == 2);
	lua_pop(L, 1);
	eddy_lua_set_threads(L, 0);
	CHECK(run(L, "local eddy = require 'eddy'\nreturn eddy.world{ threads = 1 }\n") == NULL);
	w = eddy_lua_toworld(L, -1);
	CHECK(w != NULL && eddy_world_get_def(w)->threads == 1);
	lua_close(L);
}

void suite_lua(void)
{
	RUN(unknown_field_names_file_line_and_fix);
	RUN(threads_override_applies_at_creation);
	RUN(wrong_type_and_range);
	RUN(order_error_in_lua);
	RUN(stale_handle_in_lua);
	RUN(sph_mass_from_the_handle);
	RUN(world_api_and_channels);
	RUN(warnings_from_lua);
	RUN(on_frame_fields_merge);
	RUN(callbacks_cannot_reenter_their_world);
	RUN(arguments_that_once_crashed);
	RUN(params_convert_to_the_default_type);
	RUN(animated_collider);
	RUN(every_field_rejects_nan_and_inf);
	RUN(fluid_group_expands_per_method);
	RUN(fluid_group_passes_sph_density_fields);
	RUN(safe_mode_refuses_escapes);
	RUN(safe_mode_keeps_what_scenes_use);
	RUN(load_scene_runs_a_scene_sandboxed);
}

/* Every number a scene can give, for every def, rejects NaN, and infinity
 * unless infinity means "no limit" there; the error names the field. */
static int nan_inf_sweep(const eddy_lua_kind *k, bool is_world)
{
	/* where infinity means "no limit", and NaN "automatic" (documented in eddy.h) */
	static const char *const inf_ok[] = {"emit_nozzle.duration", "integrate.max_speed", NULL};
	static const char *const nan_ok[] = {"render_points.value_min", "render_points.value_max", NULL};
	static const char *const bad[] = {"0/0", "1/0", "-1/0"};
	int checked = 0;
	for (const eddy_lua_field *f = k->fields; f->name; ++f) {
		if (f->type != EDDY_LUA_FLOAT && f->type != EDDY_LUA_DOUBLE && f->type != EDDY_LUA_VEC3 &&
		    f->type != EDDY_LUA_BOUNDS && f->type != EDDY_LUA_OFFSET)
			continue;
		for (int b = 0; b < 3; ++b) {
			char v[96], src[512], qual[96], buf[512];
			if (f->type == EDDY_LUA_FLOAT || f->type == EDDY_LUA_DOUBLE)
				snprintf(v, sizeof v, "%s", bad[b]);
			else if (f->type == EDDY_LUA_BOUNDS)
				snprintf(v, sizeof v, "{{0, 0, 0}, {1, %s, 1}}", bad[b]);
			else
				snprintf(v, sizeof v, "{0.5, %s, 0.5}", bad[b]);
			snprintf(qual, sizeof qual, "%s.%s", k->name, f->name);
			bool allowed = false;
			for (int i = 0; inf_ok[i]; ++i)
				allowed |= b == 1 && strcmp(inf_ok[i], qual) == 0;
			for (int i = 0; nan_ok[i]; ++i)
				allowed |= b == 0 && strcmp(nan_ok[i], qual) == 0;
			if (is_world)
				snprintf(src, sizeof src, "local eddy = require 'eddy'\nlocal w = eddy.world{ %s = %s }\n", f->name, v);
			else /* gravity first, so systems that read the acceleration are in order */
				snprintf(src, sizeof src, HEAD "world:add(eddy.gravity{})\nworld:add(eddy.%s{ %s = %s })\n", k->name,
				         f->name, v);
			const char *e = run_fresh(src, buf, sizeof buf);
			if (allowed) {
				CHECKF(e == NULL, "%s = %s should be accepted: %s", qual, bad[b], e);
			} else {
				char want[64];
				snprintf(want, sizeof want, "'%s'", f->name);
				CHECKF(e && strstr(e, want), "%s = %s: expected an error naming %s, got: %s", qual, bad[b], want,
				       e ? e : "no error");
			}
			++checked;
		}
	}
	return checked;
}

static void every_field_rejects_nan_and_inf(void)
{
	int checked = nan_inf_sweep(&eddy_lua_world_kind, true);
	const eddy_lua_kind *const lists[] = {eddy_lua_core_kinds, eddy_lua_sph_kinds, eddy_lua_flip_kinds,
	                                      eddy_lua_render_kinds};
	for (size_t l = 0; l < sizeof lists / sizeof lists[0]; ++l)
		for (const eddy_lua_kind *k = lists[l]; k->name; ++k)
			checked += nan_inf_sweep(k, false);
	CHECK(checked > 150);
}
