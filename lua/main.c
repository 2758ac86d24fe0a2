/* The eddy command: run, plan and check Lua scenes.
 *
 *   eddy run SCENE.lua [--frames N] [--duration S] [--out DIR] [--threads N]
 *                      [--set K=V ...] [--stats FILE] [--quiet] [--video FILE]
 *                      [--checkpoint-every N] [--resume DIR]
 *   eddy plan SCENE.lua [--dot] [--set K=V ...]
 *   eddy check SCENE.lua [--set K=V ...]
 *   eddy study STUDY.lua [--out DIR] [--quick]   (lua/study.c)
 *
 * Exit status: 0 success, 1 the scene or the run failed, 2 bad usage. Every
 * failure is one line on stderr starting with "eddy: ". */
#define _POSIX_C_SOURCE 200809L
#define _DEFAULT_SOURCE /* strdup, open_memstream, DIR */
#include "eddy_lua.h"

#include <lauxlib.h>
#include <lualib.h>

#include <dirent.h>
#include <errno.h>
#include <math.h>
#include <signal.h>
#include <sys/stat.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include "eddy.h"
#include "study.h" /* eddy study: lua/study.c */

enum { EXIT_RUN = 1, EXIT_USAGE = 2 };

typedef struct options {
	const char *command;
	const char *scene;
	int frames;          /* -1: from the scene's duration */
	double duration;     /* < 0: the scene's */
	const char *out;
	int threads;         /* 0: the scene's */
	const char *stats;
	const char *video;   /* --video FILE: the rendered frames through ffmpeg */
	bool quiet, dot;
	int checkpoint_every; /* 0: none */
	const char *resume;   /* checkpoint directory to continue from */
	uint64_t fingerprint; /* scene file and --set values, for checkpoints */
	char outdir[1024];    /* --out or out/<scene> */
} options;

static const char usage_text[] =
	"usage: eddy <command> SCENE.lua [options]\n"
	"\n"
	"commands:\n"
	"  run    simulate the scene; write its frames and, with --stats, one JSON object per frame\n"
	"  plan   print the validated pipeline: systems in order, columns and their bytes\n"
	"  check  preflight: time-step limits, particles starting in colliders, memory\n"
	"  study  accuracy against wall time over a sweep: eddy study STUDY.lua [--out DIR] [--quick]\n"
	"         (see eddy study --help)\n"
	"\n"
	"options:\n"
	"  --frames N      frames to simulate (default: the scene's duration times fps)\n"
	"  --duration S    seconds to simulate instead\n"
	"  --out DIR       where the scene writes its output (default out/<scene>)\n"
	"  --threads N     worker threads (default: the scene's, usually 1)\n"
	"  --set K=V       a scene parameter read with eddy.param(K, default); repeatable\n"
	"  --stats FILE    per-frame statistics as JSON lines ('-' for stdout)\n"
	"  --quiet         no progress bar and no summary\n"
	"  --checkpoint-every N  (run) save the full state every N frames in OUT/checkpoints\n"
	"  --resume DIR    (run) continue from the newest valid checkpoint in DIR\n"
	"  --video FILE    (run) also pipe the rendered frames to ffmpeg, making FILE (e.g. out.mp4)\n"
	"  --dot           (plan) print the pipeline as a Graphviz graph\n"
	"  -h, --help      this help\n"
	"  --version       the version\n";

static int fail(int code, const char *fmt, ...)
#if defined(__GNUC__)
	__attribute__((format(printf, 2, 3)))
#endif
	;
static int fail(int code, const char *fmt, ...)
{
	va_list ap;
	va_start(ap, fmt);
	fputs("eddy: ", stderr);
	vfprintf(stderr, fmt, ap);
	fputc('\n', stderr);
	va_end(ap);
	return code;
}

/* Only the first line of a message: errors are one line. */
static const char *first_line(const char *msg, char *buf, size_t cap)
{
	snprintf(buf, cap, "%s", msg ? msg : "(no message)");
	buf[strcspn(buf, "\n")] = '\0';
	return buf;
}

static uint64_t fnv(uint64_t h, const void *data, size_t n)
{
	const unsigned char *p = data;
	for (size_t i = 0; i < n; ++i) {
		h ^= p[i];
		h *= 0x100000001b3ull;
	}
	return h;
}

static bool parse_int(const char *s, int lo, int hi, int *out)
{
	char *end;
	errno = 0;
	long v = strtol(s, &end, 10);
	if (errno || end == s || *end || v < lo || v > hi)
		return false;
	*out = (int)v;
	return true;
}

static int parse_args(int argc, char **argv, options *o, lua_State *L)
{
	memset(o, 0, sizeof *o);
	o->frames = -1;
	o->duration = -1;
	for (int i = 1; i < argc; ++i) {
		const char *a = argv[i];
		const char *next = i + 1 < argc ? argv[i + 1] : NULL;
		if (strcmp(a, "-h") == 0 || strcmp(a, "--help") == 0) {
			fputs(usage_text, stdout);
			exit(0);
		} else if (strcmp(a, "--version") == 0) {
			printf("eddy %s\n", EDDY_VERSION_STRING);
			exit(0);
		} else if (strcmp(a, "--quiet") == 0) {
			o->quiet = true;
		} else if (strcmp(a, "--dot") == 0) {
			o->dot = true;
		} else if (strcmp(a, "--frames") == 0 || strcmp(a, "--duration") == 0 || strcmp(a, "--out") == 0 ||
		           strcmp(a, "--threads") == 0 || strcmp(a, "--set") == 0 || strcmp(a, "--stats") == 0 ||
		           strcmp(a, "--checkpoint-every") == 0 || strcmp(a, "--resume") == 0 || strcmp(a, "--video") == 0) {
			if (!next)
				return fail(EXIT_USAGE, "%s needs a value (see eddy --help)", a);
			++i;
			if (strcmp(a, "--frames") == 0) {
				if (!parse_int(next, 0, 100000000, &o->frames))
					return fail(EXIT_USAGE, "--frames must be an integer >= 0 (got '%s')", next);
			} else if (strcmp(a, "--duration") == 0) {
				char *end;
				o->duration = strtod(next, &end);
				if (end == next || *end || !(o->duration >= 0) || !isfinite(o->duration))
					return fail(EXIT_USAGE, "--duration must be a number of seconds >= 0 (got '%s')", next);
			} else if (strcmp(a, "--out") == 0) {
				o->out = next;
			} else if (strcmp(a, "--threads") == 0) {
				if (!parse_int(next, 1, 256, &o->threads))
					return fail(EXIT_USAGE, "--threads must be an integer in [1, 256] (got '%s')", next);
			} else if (strcmp(a, "--stats") == 0) {
				o->stats = next;
			} else if (strcmp(a, "--checkpoint-every") == 0) {
				if (!parse_int(next, 1, 100000000, &o->checkpoint_every))
					return fail(EXIT_USAGE, "--checkpoint-every must be an integer >= 1 (got '%s')", next);
			} else if (strcmp(a, "--resume") == 0) {
				o->resume = next;
			} else if (strcmp(a, "--video") == 0) {
				o->video = next;
			} else {
				const char *eq = strchr(next, '=');
				if (!eq || eq == next)
					return fail(EXIT_USAGE, "--set expects KEY=VALUE (got '%s')", next);
				char key[128];
				snprintf(key, sizeof key, "%.*s", (int)(eq - next), next);
				eddy_lua_set_param(L, key, eq + 1);
				o->fingerprint += fnv(0xcbf29ce484222325ull, next, strlen(next)); /* order-free */
			}
		} else if (a[0] == '-' && a[1] != '\0') {
			return fail(EXIT_USAGE, "unknown option '%s' (see eddy --help)", a);
		} else if (!o->command) {
			o->command = a;
		} else if (!o->scene) {
			o->scene = a;
		} else {
			return fail(EXIT_USAGE, "unexpected argument '%s' (see eddy --help)", a);
		}
	}
	if (!o->command) {
		fputs(usage_text, stderr);
		return EXIT_USAGE;
	}
	if (strcmp(o->command, "run") != 0 && strcmp(o->command, "plan") != 0 && strcmp(o->command, "check") != 0)
		return fail(EXIT_USAGE, "unknown command '%s': use run, plan or check (see eddy --help)", o->command);
	if (!o->scene)
		return fail(EXIT_USAGE, "%s needs a scene file, e.g. eddy %s scenes/bounce.lua", o->command, o->command);
	return 0;
}

/* The scene's name without directory and extension, for out/<scene>. */
static void scene_name(const char *path, char *out, size_t cap)
{
	const char *base = strrchr(path, '/');
	base = base ? base + 1 : path;
	size_t n = strcspn(base, ".");
	snprintf(out, cap, "%.*s", (int)n, base);
}

/* Runs the scene file; leaves the returned world on the stack. */
static int load_scene(lua_State *L, options *o)
{
	luaL_openlibs(L); /* "eddy" is already in package.loaded (see main) */
	/* scenes may require helpers beside them, and eddy's own Lua helpers
	 * (require "eddy.dam_break") from lua/ of the source tree the command was
	 * built in (build/eddy -> lua/) or of an installed prefix (bin/eddy ->
	 * share/eddy/lua/) */
	const char *slash = strrchr(o->scene, '/');
	int dirlen = slash ? (int)(slash - o->scene) : 1;
	const char *dir = slash ? o->scene : ".";
	char exe[2048] = "";
	ssize_t len = readlink("/proc/self/exe", exe, sizeof exe - 1);
	exe[len > 0 ? len : 0] = '\0';
	char *cut = strrchr(exe, '/');
	if (cut)
		*cut = '\0'; /* the directory holding the command */
	lua_getglobal(L, "package");
	char path[8192];
	lua_getfield(L, -1, "path");
	snprintf(path, sizeof path, "%.*s/?.lua;%s/../lua/?.lua;%s/../../lua/?.lua;%s/../share/eddy/lua/?.lua;%s", dirlen,
	         dir, exe, exe, exe, lua_tostring(L, -1));
	lua_pop(L, 1);
	lua_pushstring(L, path);
	lua_setfield(L, -2, "path");
	lua_pop(L, 1);

	char name[256];
	scene_name(o->scene, name, sizeof name);
	if (o->out)
		snprintf(o->outdir, sizeof o->outdir, "%s", o->out);
	else
		snprintf(o->outdir, sizeof o->outdir, "out/%s", name);
	eddy_lua_set_out_dir(L, o->outdir);

	char buf[1024];
	int rc = luaL_loadfile(L, o->scene);
	if (rc == LUA_ERRFILE)
		return fail(EXIT_RUN, "cannot read scene '%s': %s", o->scene, strerror(errno ? errno : ENOENT));
	if (rc != LUA_OK)
		return fail(EXIT_RUN, "%s", first_line(lua_tostring(L, -1), buf, sizeof buf));
	/* a checkpoint belongs to this scene text with these --set values */
	FILE *sf = fopen(o->scene, "rb");
	if (sf) {
		char chunk[4096];
		size_t k;
		while ((k = fread(chunk, 1, sizeof chunk, sf)) > 0)
			o->fingerprint = fnv(o->fingerprint ^ 0x9e3779b97f4a7c15ull, chunk, k);
		fclose(sf);
	}
	if (lua_pcall(L, 0, 1, 0) != LUA_OK)
		return fail(EXIT_RUN, "%s", first_line(lua_tostring(L, -1), buf, sizeof buf));
	if (!eddy_lua_toworld(L, -1))
		return fail(EXIT_RUN, "%s: the scene must return a world (got %s); end it with 'return world'", o->scene,
		            luaL_typename(L, -1));
	/* a --set the scene never read is almost always a typo */
	eddy_lua_push_unused_params(L);
	lua_pushnil(L);
	if (lua_next(L, -2)) {
		const char *key = lua_tostring(L, -2);
		return fail(EXIT_USAGE, "--set %s: %s has no parameter '%s' (it reads parameters with eddy.param)", key,
		            o->scene, key);
	}
	lua_pop(L, 1);
	return 0;
}

/* ---- JSON ------------------------------------------------------------------ */

static void json_string(FILE *f, const char *s)
{
	fputc('"', f);
	for (; *s; ++s) {
		unsigned char c = (unsigned char)*s;
		if (c == '"' || c == '\\')
			fprintf(f, "\\%c", c);
		else if (c == '\n')
			fputs("\\n", f);
		else if (c < 0x20)
			fprintf(f, "\\u%04x", c);
		else
			fputc(c, f);
	}
	fputc('"', f);
}

static void json_number(FILE *f, double v)
{
	if (!isfinite(v))
		fputs("null", f);
	else if (v == floor(v) && fabs(v) < 1e15)
		fprintf(f, "%.0f", v);
	else
		fprintf(f, "%.9g", v);
}

static int cmp_str(const void *a, const void *b) { return strcmp(*(const char *const *)a, *(const char *const *)b); }

/* A Lua value as JSON: tables with keys 1..n are arrays, others objects with
 * sorted string keys (so lines are reproducible). */
static void json_lua(FILE *f, lua_State *L, int idx, int depth)
{
	idx = lua_absindex(L, idx);
	switch (lua_type(L, idx)) {
	case LUA_TNUMBER:
		if (lua_isinteger(L, idx))
			fprintf(f, "%lld", (long long)lua_tointeger(L, idx));
		else
			json_number(f, lua_tonumber(L, idx));
		return;
	case LUA_TBOOLEAN: fputs(lua_toboolean(L, idx) ? "true" : "false", f); return;
	case LUA_TSTRING: json_string(f, lua_tostring(L, idx)); return;
	case LUA_TTABLE: break;
	default: fputs("null", f); return;
	}
	if (depth > 16) {
		fputs("null", f);
		return;
	}
	lua_Unsigned n = lua_rawlen(L, idx);
	size_t keys = 0;
	lua_pushnil(L);
	while (lua_next(L, idx)) {
		keys++;
		lua_pop(L, 1);
	}
	if (n > 0 && keys == n) {
		fputc('[', f);
		for (lua_Unsigned i = 1; i <= n; ++i) {
			if (i > 1)
				fputc(',', f);
			lua_rawgeti(L, idx, (lua_Integer)i);
			json_lua(f, L, -1, depth + 1);
			lua_pop(L, 1);
		}
		fputc(']', f);
		return;
	}
	const char **names = calloc(keys ? keys : 1, sizeof *names);
	size_t k = 0;
	lua_pushnil(L);
	while (lua_next(L, idx) && names) {
		if (lua_type(L, -2) == LUA_TSTRING)
			names[k++] = lua_tostring(L, -2); /* the key stays alive in the table */
		lua_pop(L, 1);
	}
	if (names)
		qsort(names, k, sizeof *names, cmp_str);
	fputc('{', f);
	for (size_t i = 0; i < k; ++i) {
		if (i)
			fputc(',', f);
		json_string(f, names[i]);
		fputc(':', f);
		lua_getfield(L, idx, names[i]);
		json_lua(f, L, -1, depth + 1);
		lua_pop(L, 1);
	}
	fputc('}', f);
	free(names);
}

static const char *const contract_fields[] = {
	"frame", "time", "steps", "dt_min", "dt_max", "dt_limit", "particles", "max_speed", "cfl", "density_err_avg",
	"density_err_max", "density_compression_avg", "volume", "leaked", "nonfinite", "solver", "iterations", "residual", "divergence", "wall_ms",
	"state_hash", "systems", NULL,
};

static bool is_contract_field(const char *name)
{
	for (int i = 0; contract_fields[i]; ++i)
		if (strcmp(contract_fields[i], name) == 0)
			return true;
	return false;
}

static const eddy_stat_value *find_extra(const eddy_frame_stats *s, const char *name)
{
	for (int i = 0; i < s->extra_count; ++i)
		if (strcmp(s->extra[i].name, name) == 0)
			return &s->extra[i];
	return NULL;
}

static void json_extra(FILE *f, const eddy_stat_value *v)
{
	if (!v)
		fputs("null", f);
	else if (v->text)
		json_string(f, v->text);
	else
		json_number(f, v->value);
}

/* One stats line. fields_idx: the on_frame table (or nil). Returns 0 or an
 * error message for a scene field that shadows a contract field. */
static const char *write_stats(FILE *f, const eddy_frame_stats *s, lua_State *L, int fields_idx)
{
	fprintf(f, "{\"frame\":%d,\"time\":", s->frame);
	json_number(f, s->time);
	fprintf(f, ",\"steps\":%lld,\"dt_min\":", (long long)s->steps);
	json_number(f, s->dt_min);
	fputs(",\"dt_max\":", f);
	json_number(f, s->dt_max);
	fputs(",\"dt_limit\":", f);
	json_string(f, s->dt_limit);
	fprintf(f, ",\"particles\":%zu,\"max_speed\":", s->particles);
	json_number(f, s->max_speed);
	fputs(",\"cfl\":", f);
	json_number(f, s->cfl);
	fputs(",\"density_err_avg\":", f);
	json_number(f, s->density_err_avg);
	fputs(",\"density_err_max\":", f);
	json_number(f, s->density_err_max);
	fputs(",\"density_compression_avg\":", f);
	json_number(f, s->density_compression_avg);
	fputs(",\"volume\":", f);
	json_number(f, s->volume);
	fprintf(f, ",\"leaked\":%zu,\"nonfinite\":%zu", s->leaked, s->nonfinite);
	static const char *const solver_fields[] = {"solver", "iterations", "residual", "divergence"};
	for (int i = 0; i < 4; ++i) {
		fprintf(f, ",\"%s\":", solver_fields[i]);
		json_extra(f, find_extra(s, solver_fields[i]));
	}
	fputs(",\"wall_ms\":", f);
	json_number(f, s->wall_ms);
	fprintf(f, ",\"state_hash\":\"%016llx\",\"systems\":{", (unsigned long long)s->state_hash);
	for (int i = 0; i < s->system_count; ++i) {
		if (i)
			fputc(',', f);
		json_string(f, s->system_names[i]);
		fputc(':', f);
		json_number(f, round(s->system_ms[i] * 1e4) / 1e4);
	}
	fputc('}', f);
	for (int i = 0; i < s->extra_count; ++i) {
		if (is_contract_field(s->extra[i].name))
			continue;
		fputc(',', f);
		json_string(f, s->extra[i].name);
		fputc(':', f);
		json_extra(f, &s->extra[i]);
	}
	const char *clash = NULL;
	if (lua_istable(L, fields_idx)) {
		/* sorted, so lines are reproducible */
		lua_newtable(L);
		int keys = lua_gettop(L);
		lua_Integer n = 0;
		lua_pushnil(L);
		while (lua_next(L, fields_idx)) {
			lua_pop(L, 1);
			const char *k = lua_tostring(L, -1);
			if (is_contract_field(k)) {
				clash = k;
				continue;
			}
			lua_pushvalue(L, -1);
			lua_rawseti(L, keys, ++n);
		}
		lua_getglobal(L, "table");
		lua_getfield(L, -1, "sort");
		lua_pushvalue(L, keys);
		lua_call(L, 1, 0);
		lua_pop(L, 1);
		for (lua_Integer i = 1; i <= n; ++i) {
			lua_rawgeti(L, keys, i);
			const char *k = lua_tostring(L, -1);
			fputc(',', f);
			json_string(f, k);
			fputc(':', f);
			lua_rawget(L, fields_idx);
			json_lua(f, L, -1, 0);
			lua_pop(L, 1);
		}
		lua_pop(L, 1);
	}
	fputs("}\n", f);
	return clash;
}

/* ---- commands ------------------------------------------------------------- */

static void progress(int frame, int frames, double sim_t, double wall_s, int64_t steps)
{
	const int width = 30;
	int fill = frames ? frame * width / frames : width;
	char bar[64];
	for (int i = 0; i < width; ++i)
		bar[i] = i < fill ? '#' : '.';
	bar[width] = '\0';
	double rate = wall_s > 0 ? (double)steps / wall_s : 0;
	double eta = frame > 0 ? wall_s / frame * (frames - frame) : 0;
	fprintf(stderr, "\r[%s] frame %d/%d  t = %.3f s  %.0f steps/s  ETA %.0f s   ", bar, frame, frames, sim_t, rate, eta);
	fflush(stderr);
}

static double now_s(void)
{
	struct timespec ts;
	clock_gettime(CLOCK_MONOTONIC, &ts);
	return (double)ts.tv_sec + (double)ts.tv_nsec * 1e-9;
}

/* Set by SIGINT/SIGTERM; the run stops after the frame in progress. */
static volatile sig_atomic_t stop_signal;

static void on_signal(int sig) { stop_signal = sig; }

static int make_dirs(const char *path)
{
	char p[1024];
	snprintf(p, sizeof p, "%s", path);
	for (char *s = p + 1; *s; ++s) {
		if (*s != '/')
			continue;
		*s = '\0';
		if (mkdir(p, 0755) != 0 && errno != EEXIST)
			return -1;
		*s = '/';
	}
	return mkdir(p, 0755) != 0 && errno != EEXIST ? -1 : 0;
}

static int checkpoint(eddy_world *w, const options *o, const char *dir)
{
	char path[2048];
	if (make_dirs(dir) != 0)
		return fail(EXIT_RUN, "cannot create checkpoint directory '%s': %s", dir, strerror(errno));
	snprintf(path, sizeof path, "%s/frame-%06d.eddy", dir, eddy_world_frame(w));
	if (eddy_world_save(w, path, o->fingerprint) != EDDY_OK)
		return fail(EXIT_RUN, "%s", eddy_world_error(w));
	return 0;
}

static int cmp_desc(const void *a, const void *b) { return -strcmp(*(char *const *)a, *(char *const *)b); }

/* Loads the newest checkpoint in dir that is intact and of this scene; older
 * ones stand in for rejected ones, each rejection said on stderr. */
static int resume(eddy_world *w, const options *o)
{
	DIR *d = opendir(o->resume);
	if (!d)
		return fail(EXIT_RUN, "--resume %s: cannot open: %s", o->resume, strerror(errno));
	char *names[4096];
	int n = 0;
	struct dirent *e;
	while ((e = readdir(d)) && n < 4096) {
		size_t len = strlen(e->d_name);
		if (strncmp(e->d_name, "frame-", 6) == 0 && len > 5 && strcmp(e->d_name + len - 5, ".eddy") == 0)
			names[n++] = strdup(e->d_name);
	}
	closedir(d);
	qsort(names, (size_t)n, sizeof names[0], cmp_desc); /* zero-padded: newest first */
	int code = -1; /* none loaded yet */
	for (int i = 0; i < n; ++i) {
		char path[2048];
		snprintf(path, sizeof path, "%s/%s", o->resume, names[i]);
		if (code < 0 && names[i]) {
			if (eddy_world_load(w, path, o->fingerprint) == EDDY_OK) {
				code = 0;
				if (!o->quiet)
					fprintf(stderr, "eddy: resuming from %s (frame %d, t = %.6g s)\n", path, eddy_world_frame(w),
					        eddy_world_time(w));
			} else {
				fprintf(stderr, "eddy: warning: %s; trying an older one\n", eddy_world_error(w));
			}
		}
		free(names[i]);
	}
	if (code < 0)
		return fail(EXIT_RUN, "--resume %s: no valid checkpoint of this scene (frame-NNNNNN.eddy)", o->resume);
	return 0;
}

/* On resume, keep the stats lines of the frames up to the checkpoint and drop
 * those a crashed run wrote after it, so each frame appears once. */
static FILE *open_stats(const options *o, int keep_frames)
{
	if (strcmp(o->stats, "-") == 0)
		return stdout;
	if (!o->resume)
		return fopen(o->stats, "w");
	FILE *in = fopen(o->stats, "r");
	char *kept = NULL;
	size_t kept_len = 0;
	if (in) {
		FILE *mem = open_memstream(&kept, &kept_len);
		char line[65536];
		while (mem && fgets(line, sizeof line, in)) {
			int frame;
			if (sscanf(line, "{\"frame\":%d", &frame) == 1 && frame <= keep_frames)
				fputs(line, mem);
		}
		if (mem)
			fclose(mem);
		fclose(in);
	}
	FILE *f = fopen(o->stats, "w");
	if (f && kept)
		fwrite(kept, 1, kept_len, f);
	free(kept);
	return f;
}

static void run_check_report(eddy_check_level level, const char *message, void *user)
{
	const bool *quiet = user;
	if (level == EDDY_CHECK_ERROR || (level == EDDY_CHECK_WARNING && !*quiet))
		fprintf(stderr, "eddy: %s: %s\n", level == EDDY_CHECK_ERROR ? "error" : "warning", message);
}

/* ---- --video: the frames the scene renders, piped to ffmpeg -------------- */

/* Whether an executable named name is on PATH. */
static bool on_path(const char *name)
{
	const char *path = getenv("PATH");
	if (!path)
		return false;
	char buf[4096];
	while (*path) {
		size_t n = strcspn(path, ":");
		snprintf(buf, sizeof buf, "%.*s/%s", (int)(n ? n : 1), n ? path : ".", name);
		if (access(buf, X_OK) == 0)
			return true;
		path += n;
		if (*path == ':')
			++path;
	}
	return false;
}

/* s in single quotes for sh, with ' written as '\'' */
static void shell_quote(const char *s, char *out, size_t cap)
{
	size_t k = 0;
	if (cap < 3) {
		out[0] = '\0';
		return;
	}
	out[k++] = '\'';
	for (; *s && k + 6 < cap; ++s) {
		if (*s == '\'') {
			memcpy(out + k, "'\\''", 4);
			k += 4;
		} else {
			out[k++] = *s;
		}
	}
	out[k++] = '\'';
	out[k] = '\0';
}

/* ffmpeg's messages go to log (a temporary file), so a failure is still one
 * line from eddy, quoting ffmpeg's first line. */
static FILE *open_video(const char *file, double fps, const char *log)
{
	char q[2048], ql[1024], cmd[4096];
	shell_quote(file, q, sizeof q);
	shell_quote(log, ql, sizeof ql);
	const char *ext = strrchr(file, '.');
	/* yuv420p: what players expect of H.264 files; even sizes for its chroma */
	const bool h264 = ext && (strcmp(ext, ".mp4") == 0 || strcmp(ext, ".mov") == 0 || strcmp(ext, ".mkv") == 0);
	snprintf(cmd, sizeof cmd,
	         "ffmpeg -hide_banner -loglevel error -y -f image2pipe -c:v png -framerate %g -i - %s %s 2>%s", fps,
	         h264 ? "-pix_fmt yuv420p -vf 'pad=ceil(iw/2)*2:ceil(ih/2)*2'" : "", q, ql);
	return popen(cmd, "w");
}

/* Copies the PNG file at path into the ffmpeg pipe. */
static bool send_frame(FILE *pipe, const char *path)
{
	FILE *f = fopen(path, "rb");
	if (!f)
		return false;
	char buf[65536];
	size_t n;
	bool ok = true;
	while (ok && (n = fread(buf, 1, sizeof buf, f)) > 0)
		ok = fwrite(buf, 1, n, pipe) == n;
	fclose(f);
	return ok;
}

static int cmd_run(lua_State *L, const options *o, int world_idx)
{
	eddy_world *w = eddy_lua_toworld(L, world_idx);
	const eddy_world_def *def = eddy_world_get_def(w);
	if (o->threads && eddy_world_set_threads(w, o->threads) != EDDY_OK)
		return fail(EXIT_USAGE, "%s", eddy_world_error(w));
	double duration = o->duration >= 0 ? o->duration : def->duration;
	int frames = o->frames >= 0 ? o->frames : (int)ceil(duration * def->fps - 1e-9);
	char ckpt_dir[1100];
	snprintf(ckpt_dir, sizeof ckpt_dir, "%s/checkpoints", o->outdir);
	if (o->resume) {
		int code = resume(w, o);
		if (code)
			return code;
	}
	const int first = eddy_world_frame(w);
	/* the preflight of eddy check: a scene that cannot work (one that would
	 * not fit in memory, say) is refused before it allocates anything */
	if (first == 0) {
		bool quiet = o->quiet;
		int errors = eddy_world_check(w, run_check_report, &quiet);
		if (errors)
			return fail(EXIT_RUN, "%s: not run: %d problem%s found by the preflight check (above)", o->scene, errors,
			            errors == 1 ? "" : "s");
	}

	FILE *stats = NULL;
	if (o->stats && !(stats = open_stats(o, first)))
		return fail(EXIT_RUN, "cannot write stats file '%s': %s", o->stats, strerror(errno));
	struct sigaction sa;
	memset(&sa, 0, sizeof sa);
	sa.sa_handler = on_signal;
	/* a second signal ends the process at once; interrupted writes restart, so
	 * no frame file is left half written */
	sa.sa_flags = (int)(SA_RESETHAND | SA_RESTART);
	sigaction(SIGINT, &sa, NULL);
	sigaction(SIGTERM, &sa, NULL);

	FILE *video = NULL;
	int video_frames = 0;
	char video_log[64] = "";
	if (o->video) {
		if (!on_path("ffmpeg")) {
			if (stats && stats != stdout)
				fclose(stats);
			return fail(EXIT_RUN, "--video %s: ffmpeg is not installed (not found on PATH); install it (Debian: "
			                      "apt-get install ffmpeg) or leave out --video (PNG frames need no ffmpeg)", o->video);
		}
		signal(SIGPIPE, SIG_IGN); /* a failing ffmpeg is reported, not fatal */
		snprintf(video_log, sizeof video_log, "/tmp/eddy-ffmpeg-XXXXXX");
		int fd = mkstemp(video_log);
		if (fd >= 0)
			close(fd);
		else
			snprintf(video_log, sizeof video_log, "/dev/null");
		video = open_video(o->video, def->fps, video_log);
		if (!video) {
			if (stats && stats != stdout)
				fclose(stats);
			return fail(EXIT_RUN, "--video %s: cannot start ffmpeg: %s", o->video, strerror(errno));
		}
	}
	const bool bar = !o->quiet && isatty(STDERR_FILENO);
	const double t0 = now_s();
	int code = 0;
	char buf[1024];
	for (int i = first; i < frames && code == 0; ++i) {
		if (eddy_world_step_frame(w) != EDDY_OK) {
			if (bar)
				fputc('\n', stderr);
			code = fail(EXIT_RUN, "%s", first_line(eddy_world_error(w), buf, sizeof buf));
			break;
		}
		eddy_lua_take_frame_fields(L, world_idx);
		if (stats) {
			eddy_frame_stats s;
			eddy_world_frame_stats(w, &s);
			const char *clash = write_stats(stats, &s, L, lua_gettop(L));
			fflush(stats);
			if (clash)
				code = fail(EXIT_RUN, "on_frame returned '%s', which is a stats field of eddy; give it another name", clash);
		}
		lua_pop(L, 1);
		if (code == 0 && o->checkpoint_every && (i + 1) % o->checkpoint_every == 0)
			code = checkpoint(w, o, ckpt_dir);
		if (video) {
			/* the renderer publishes each image's path in the frame stats */
			eddy_frame_stats s;
			eddy_world_frame_stats(w, &s);
			const eddy_stat_value *img = find_extra(&s, "image");
			if (img && img->text) {
				if (!send_frame(video, img->text)) {
					/* stats texts hold 63 characters: a longer path arrives cut short */
					if (strlen(img->text) >= 63)
						code = fail(EXIT_RUN, "--video %s: the frame path '%s...' is too long to pass on (63 "
						                      "characters at most); use a shorter --out or image path", o->video, img->text);
					else
						code = fail(EXIT_RUN, "--video %s: cannot pass frame '%s' to ffmpeg: %s", o->video, img->text,
						            strerror(errno));
					break;
				}
				video_frames++;
			}
		}
		if (bar)
			progress(i + 1, frames, eddy_world_time(w), now_s() - t0, eddy_world_steps(w));
		if (code == 0 && stop_signal && i + 1 < frames) {
			if (bar)
				fputc('\n', stderr);
			code = checkpoint(w, o, ckpt_dir);
			if (code == 0)
				code = fail(128 + stop_signal,
				            "interrupted after frame %d (t = %.6g s); resume with: eddy run %s --resume %s (and the same options)",
				            i + 1, eddy_world_time(w), o->scene, ckpt_dir);
		}
	}
	if (bar && code == 0)
		fputc('\n', stderr);
	if (stats && stats != stdout && fclose(stats) != 0 && code == 0)
		code = fail(EXIT_RUN, "cannot finish stats file '%s': %s", o->stats, strerror(errno));
	if (video) {
		int st = pclose(video);
		if (code == 0 && video_frames == 0)
			code = fail(EXIT_RUN, "--video %s: the scene rendered no frames (add eddy.render_points to it)", o->video);
		else if (code == 0 && st != 0) {
			char msg[512] = "";
			FILE *lf = fopen(video_log, "r");
			if (lf) {
				if (!fgets(msg, sizeof msg, lf))
					msg[0] = '\0';
				fclose(lf);
			}
			msg[strcspn(msg, "\n")] = '\0';
			code = fail(EXIT_RUN, "--video %s: ffmpeg failed (status %d%s%s); the PNG frames are on disk", o->video,
			            WIFEXITED(st) ? WEXITSTATUS(st) : st, msg[0] ? ": " : "", msg);
		}
		if (strcmp(video_log, "/dev/null") != 0)
			unlink(video_log);
	}
	if (code == 0 && !o->quiet)
		printf("eddy: %s: %d frames, %.3f s simulated in %.2f s wall (%lld steps, %zu particles)\n", o->scene,
		       frames - first, eddy_world_time(w), now_s() - t0, (long long)eddy_world_steps(w),
		       eddy_world_particle_count(w));
	return code;
}

static int cmd_plan(lua_State *L, const options *o, int world_idx)
{
	eddy_world *w = eddy_lua_toworld(L, world_idx);
	size_t (*fn)(const eddy_world *, char *, size_t) = o->dot ? eddy_world_plan_dot : eddy_world_plan;
	size_t n = fn(w, NULL, 0);
	char *text = malloc(n + 1);
	if (!text)
		return fail(EXIT_RUN, "out of memory");
	fn(w, text, n + 1);
	fputs(text, stdout);
	free(text);
	return 0;
}

static void check_report(eddy_check_level level, const char *message, void *user)
{
	(void)user;
	static const char *const tags[] = {"ok     ", "warning", "error  "};
	printf("%s  %s\n", tags[level], message);
}

static int cmd_check(lua_State *L, const options *o, int world_idx)
{
	eddy_world *w = eddy_lua_toworld(L, world_idx);
	printf("%s: the pipeline is valid (%d systems)\n", o->scene, eddy_world_system_count(w));
	int errors = eddy_world_check(w, check_report, NULL);
	if (errors)
		return fail(EXIT_RUN, "%s: %d problem%s found by check", o->scene, errors, errors == 1 ? "" : "s");
	return 0;
}

int main(int argc, char **argv)
{
	/* eddy study has its own arguments and runs scenes as child processes */
	if (argc > 1 && strcmp(argv[1], "study") == 0)
		return eddy_study_main(argc, argv);
	lua_State *L = luaL_newstate();
	if (!L)
		return fail(EXIT_RUN, "cannot create a Lua state (out of memory)");
	/* the registry tables for --set must exist before parsing */
	luaL_requiref(L, "eddy", luaopen_eddy, 0);
	lua_pop(L, 1);
	options o;
	int code = parse_args(argc, argv, &o, L);
	if (code == 0)
		code = load_scene(L, &o);
	if (code == 0) {
		int world_idx = lua_gettop(L);
		if (strcmp(o.command, "run") == 0)
			code = cmd_run(L, &o, world_idx);
		else if (strcmp(o.command, "plan") == 0)
			code = cmd_plan(L, &o, world_idx);
		else
			code = cmd_check(L, &o, world_idx);
	}
	fflush(stdout);
	lua_close(L);
	return code;
}
