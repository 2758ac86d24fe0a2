/* SPDX-License-Identifier: MIT */
/* The eddy command's arguments: getopt_long, so `--frames 3` and
 * `--frames=3` are the same, options may come before or after the scene,
 * and `eddy COMMAND --help` prints that command's options. */
#define _GNU_SOURCE /* getopt_long */
#include "cli.h"

#include <errno.h>
#include <getopt.h>
#include <math.h>
#include <stdarg.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include "eddy_lua.h"

static const char usage_text[] =
	"usage: eddy <command> SCENE.lua [options]\n"
	"\n"
	"commands:\n"
	"  run    simulate the scene; write its frames and, with --stats, one JSON object per frame\n"
	"  plan   print the validated pipeline: systems in order, columns and their bytes\n"
	"  check  preflight: time-step limits, particles starting in colliders, memory\n"
	"  study  accuracy against wall time over a sweep: eddy study STUDY.lua [--out DIR] [--quick]\n"
	"  compare one scene, several methods, side by side: eddy compare SCENE.lua\n"
	"         [--methods wcsph,dfsph,flip] [--set K=V ...] [--out DIR] [--quick] [--field NAME]\n"
	"\n"
	"eddy COMMAND --help lists the options of one command. Options take their value\n"
	"as the next argument or after '=' (--frames 3, --frames=3).\n"
	"\n"
	"options:\n"
	"  --frames N      frames to simulate (default: the scene's duration times fps)\n"
	"  --duration S    seconds to simulate instead\n"
	"  --out DIR       where the scene writes its output (default out/<scene>)\n"
	"  --threads N     worker threads (default: the scene's, usually 1); render_points\n"
	"                  draws and writes frames on one more thread, in N row bands\n"
	"  --set K=V       a scene parameter read with eddy.param(K, default); repeatable, once per K\n"
	"  --stats FILE    per-frame statistics as JSON lines ('-' for stdout)\n"
	"  --quiet         no progress bar and no summary\n"
	"  --safe          load the scene in a sandbox (no os.execute, io writes only inside --out)\n"
	"  --checkpoint-every N  (run) save the full state every N frames in OUT/checkpoints\n"
	"  --keep-checkpoints N  (run) keep the newest N checkpoints (default 3; 0 keeps all)\n"
	"  --resume DIR    (run) continue from the newest valid checkpoint in DIR (a run's --out\n"
	"                  or its checkpoints folder)\n"
	"  --export FMT    (run) also write the particles every frame into OUT: ply, vtk or vtp\n"
	"  --video FILE    (run) also pipe the rendered frames to ffmpeg, making FILE (e.g. out.mp4)\n"
	"  --dot           (plan) print the pipeline as a Graphviz graph\n"
	"  -h, --help      this help\n"
	"  --version       the version\n"
	"\n"
	"Exit status: 0 success, 1 the scene or the run failed, 2 bad usage.\n";

static const char run_usage[] =
	"usage: eddy run SCENE.lua [options]\n"
	"\n"
	"Simulates the scene: its frames (PNG, exports) go where the scene writes them,\n"
	"by default under out/<scene>. The run holds OUT/.eddy.lock: a second run on the\n"
	"same output folder is refused.\n"
	"\n"
	"options:\n"
	"  --frames N              frames to simulate (default: the scene's duration times fps)\n"
	"  --duration S            seconds to simulate instead\n"
	"  --out DIR               the output folder (default out/<scene>); eddy.out_dir() in the scene\n"
	"  --threads N             worker threads, 1 to 256 (default: the scene's); render_points\n"
	"                          draws and writes frames on a thread of its own beside them\n"
	"                          (drawing in N row bands), overlapping the next frames' steps;\n"
	"                          EDDY_SYNC_FRAMES=1 in the environment writes each frame at once\n"
	"  --set K=V               a scene parameter (eddy.param); repeatable, once per K\n"
	"  --stats FILE            one JSON object per frame ('-' for stdout); folders are created\n"
	"  --quiet                 no progress bar, no warnings and no summary\n"
	"  --safe                  load the scene in a sandbox\n"
	"  --checkpoint-every N    save the full state every N frames in OUT/checkpoints\n"
	"  --keep-checkpoints N    keep the newest N checkpoints (default 3; 0 keeps all)\n"
	"  --resume DIR            continue from the newest valid checkpoint in DIR (OUT or\n"
	"                          OUT/checkpoints); give the same scene, --set and --export\n"
	"  --export FMT            also write the particles every frame into OUT (ply, vtk, vtp)\n"
	"  --video FILE            also pipe the rendered frames to ffmpeg, making FILE\n"
	"  -h, --help              this help\n";

static const char plan_usage[] =
	"usage: eddy plan SCENE.lua [options]\n"
	"\n"
	"Prints the validated pipeline: systems in order with what they read and write,\n"
	"columns and bytes, what is not allocated.\n"
	"\n"
	"options:\n"
	"  --dot        a Graphviz graph instead (eddy plan s.lua --dot | dot -Tpng > plan.png)\n"
	"  --set K=V    a scene parameter (eddy.param); repeatable, once per K\n"
	"  --out DIR    the output folder the scene is told (eddy.out_dir())\n"
	"  --safe       load the scene in a sandbox\n"
	"  -h, --help   this help\n";

static const char check_usage[] = "usage: eddy check SCENE.lua [options]\n"
								  "\n"
								  "Preflight: the time step at the start and what limits it, particles starting\n"
								  "inside colliders or outside the bounds, the memory estimate. Exit status 1\n"
								  "when it finds an error.\n"
								  "\n"
								  "options:\n"
								  "  --set K=V    a scene parameter (eddy.param); repeatable, once per K\n"
								  "  --out DIR    the output folder the scene is told (eddy.out_dir())\n"
								  "  --safe       load the scene in a sandbox\n"
								  "  -h, --help   this help\n";

int cli_fail(int code, const char *fmt, ...)
{
	va_list ap;
	va_start(ap, fmt);
	fputs("eddy: ", stderr);
	vfprintf(stderr, fmt, ap);
	fputc('\n', stderr);
	va_end(ap);
	return code;
}

const char *cli_first_line(const char *msg, char *buf, size_t cap)
{
	snprintf(buf, cap, "%s", msg ? msg : "(no message)");
	buf[strcspn(buf, "\n")] = '\0';
	return buf;
}

int cli_make_dirs(const char *path)
{
	char p[1024];
	if (snprintf(p, sizeof p, "%s", path) >= (int)sizeof p) {
		errno = ENAMETOOLONG;
		return -1;
	}
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

int cli_make_parent_dirs(const char *path)
{
	const char *slash = strrchr(path, '/');
	if (!slash || slash == path)
		return 0;
	char dir[1024];
	if (snprintf(dir, sizeof dir, "%.*s", (int)(slash - path), path) >= (int)sizeof dir) {
		errno = ENAMETOOLONG;
		return -1;
	}
	return cli_make_dirs(dir);
}

uint64_t cli_fnv(uint64_t h, const void *data, size_t n)
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

enum {
	OPT_FRAMES = 256,
	OPT_DURATION,
	OPT_OUT,
	OPT_THREADS,
	OPT_SET,
	OPT_STATS,
	OPT_QUIET,
	OPT_DOT,
	OPT_SAFE,
	OPT_CHECKPOINT_EVERY,
	OPT_KEEP_CHECKPOINTS,
	OPT_RESUME,
	OPT_EXPORT,
	OPT_VIDEO,
	OPT_VERSION,
};

static const struct option long_options[] = {
	{"frames", required_argument, NULL, OPT_FRAMES},
	{"duration", required_argument, NULL, OPT_DURATION},
	{"out", required_argument, NULL, OPT_OUT},
	{"threads", required_argument, NULL, OPT_THREADS},
	{"set", required_argument, NULL, OPT_SET},
	{"stats", required_argument, NULL, OPT_STATS},
	{"quiet", no_argument, NULL, OPT_QUIET},
	{"dot", no_argument, NULL, OPT_DOT},
	{"safe", no_argument, NULL, OPT_SAFE},
	{"checkpoint-every", required_argument, NULL, OPT_CHECKPOINT_EVERY},
	{"keep-checkpoints", required_argument, NULL, OPT_KEEP_CHECKPOINTS},
	{"resume", required_argument, NULL, OPT_RESUME},
	{"export", required_argument, NULL, OPT_EXPORT},
	{"video", required_argument, NULL, OPT_VIDEO},
	{"help", no_argument, NULL, 'h'},
	{"version", no_argument, NULL, OPT_VERSION},
	{NULL, 0, NULL, 0},
};

/* "--name" of the option whose val is val, for messages. */
static const char *option_name(int val, char *buf, size_t cap)
{
	for (const struct option *p = long_options; p->name; ++p)
		if (p->val == val) {
			snprintf(buf, cap, "--%s", p->name);
			return buf;
		}
	snprintf(buf, cap, "-%c", val > 0 && val < 128 ? val : '?');
	return buf;
}

/* A --set K=V: each K once, since a later value silently replacing an
 * earlier one hides a mistake. seen holds the earlier K=V arguments. */
static int parse_set(const char *arg, const char **seen, int *nseen, cli_options *o, lua_State *L)
{
	const char *eq = strchr(arg, '=');
	if (!eq || eq == arg)
		return cli_fail(CLI_EXIT_USAGE, "--set expects KEY=VALUE (got '%s')", arg);
	const size_t klen = (size_t)(eq - arg);
	if (klen >= 128)
		return cli_fail(CLI_EXIT_USAGE, "--set: the key '%.40s...' is longer than 127 characters", arg);
	for (int i = 0; i < *nseen; ++i)
		if (strncmp(seen[i], arg, klen) == 0 && seen[i][klen] == '=')
			return cli_fail(CLI_EXIT_USAGE, "--set %.*s given twice ('%s' and '%s'); give each parameter once",
			                (int)klen, arg, seen[i], arg);
	seen[(*nseen)++] = arg;
	char key[128];
	snprintf(key, sizeof key, "%.*s", (int)klen, arg);
	eddy_lua_set_param(L, key, eq + 1);
	o->fingerprint += cli_fnv(0xcbf29ce484222325ull, arg, strlen(arg)); /* order-free */
	return 0;
}

/* One option with its value (NULL for flags). Returns 0 or an exit status. */
static int parse_option(int opt, const char *v, cli_options *o)
{
	char *end;
	switch (opt) {
	case OPT_FRAMES:
		if (!parse_int(v, 0, CLI_MAX_FRAMES, &o->frames))
			return cli_fail(CLI_EXIT_USAGE, "--frames must be an integer in [0, %d] (got '%s')", CLI_MAX_FRAMES, v);
		return 0;
	case OPT_DURATION:
		o->duration = strtod(v, &end);
		if (end == v || *end || !(o->duration >= 0) || !isfinite(o->duration))
			return cli_fail(CLI_EXIT_USAGE, "--duration must be a number of seconds >= 0 (got '%s')", v);
		return 0;
	case OPT_THREADS:
		if (!parse_int(v, 1, 256, &o->threads))
			return cli_fail(CLI_EXIT_USAGE, "--threads must be an integer in [1, 256] (got '%s')", v);
		return 0;
	case OPT_CHECKPOINT_EVERY:
		if (!parse_int(v, 1, 100000000, &o->checkpoint_every))
			return cli_fail(CLI_EXIT_USAGE, "--checkpoint-every must be an integer >= 1 (got '%s')", v);
		return 0;
	case OPT_KEEP_CHECKPOINTS:
		if (!parse_int(v, 0, 1000000, &o->keep_checkpoints))
			return cli_fail(CLI_EXIT_USAGE, "--keep-checkpoints must be an integer >= 0 (got '%s')", v);
		return 0;
	case OPT_EXPORT:
		if (strcmp(v, "ply") != 0 && strcmp(v, "vtk") != 0 && strcmp(v, "vtp") != 0)
			return cli_fail(CLI_EXIT_USAGE, "--export must be ply, vtk or vtp (got '%s')", v);
		o->export_format = v;
		return 0;
	case OPT_OUT:
		o->out = v;
		return 0;
	case OPT_STATS:
		o->stats = v;
		return 0;
	case OPT_RESUME:
		o->resume = v;
		return 0;
	case OPT_VIDEO:
		o->video = v;
		return 0;
	case OPT_QUIET:
		o->quiet = true;
		return 0;
	case OPT_DOT:
		o->dot = true;
		return 0;
	case OPT_SAFE:
		o->safe = true;
		return 0;
	default:
		return cli_fail(CLI_EXIT_USAGE, "internal: unhandled option %d", opt);
	}
}

/* getopt_long's complaint as one line: it printed nothing (opterr = 0). */
static int bad_option(int opt, char **argv, int argc)
{
	char name[64];
	const char *arg = optind - 1 < argc ? argv[optind - 1] : "";
	if (opt == ':')
		return cli_fail(CLI_EXIT_USAGE, "%s needs a value (see eddy --help)", option_name(optopt, name, sizeof name));
	if (optopt && optopt >= 256)
		return cli_fail(CLI_EXIT_USAGE, "%s takes no value (got '%s')", option_name(optopt, name, sizeof name), arg);
	if (optopt)
		return cli_fail(CLI_EXIT_USAGE, "unknown option '-%c' (see eddy --help)", optopt);
	return cli_fail(CLI_EXIT_USAGE, "unknown option '%.*s' (see eddy --help)", (int)strcspn(arg, "="), arg);
}

static const char *command_usage(const char *command)
{
	if (command && strcmp(command, "run") == 0)
		return run_usage;
	if (command && strcmp(command, "plan") == 0)
		return plan_usage;
	if (command && strcmp(command, "check") == 0)
		return check_usage;
	return usage_text;
}

int cli_parse(int argc, char **argv, cli_options *o, lua_State *L)
{
	memset(o, 0, sizeof *o);
	o->frames = -1;
	o->duration = -1;
	o->keep_checkpoints = 3;
	bool help = false, version = false;
	const char **seen = calloc((size_t)argc, sizeof *seen);
	int nseen = 0, code = 0, opt;
	if (!seen)
		return cli_fail(CLI_EXIT_RUN, "out of memory");
	opterr = 0; /* its messages are not one line starting "eddy: " */
	optind = 1;
	/* ':' first: a missing value is told apart from an unknown option */
	while (code == 0 && (opt = getopt_long(argc, argv, ":h", long_options, NULL)) != -1) {
		if (opt == 'h')
			help = true;
		else if (opt == OPT_VERSION)
			version = true;
		else if (opt == '?' || opt == ':')
			code = bad_option(opt, argv, argc);
		else if (opt == OPT_SET)
			code = parse_set(optarg, seen, &nseen, o, L);
		else
			code = parse_option(opt, optarg, o);
	}
	free(seen);
	if (code)
		return code;
	/* getopt_long moved the operands after the options */
	for (int i = optind; i < argc; ++i) {
		if (!o->command)
			o->command = argv[i];
		else if (!o->scene)
			o->scene = argv[i];
		else
			return cli_fail(CLI_EXIT_USAGE, "unexpected argument '%s' (see eddy --help)", argv[i]);
	}
	if (help || version) {
		if (help)
			fputs(command_usage(o->command), stdout);
		else
			printf("eddy %s\n", EDDY_VERSION_STRING);
		return -1;
	}
	if (!o->command)
		return cli_fail(CLI_EXIT_USAGE,
		                "no command: eddy run|plan|check|study|compare SCENE.lua [options] (see eddy --help)");
	if (strcmp(o->command, "run") != 0 && strcmp(o->command, "plan") != 0 && strcmp(o->command, "check") != 0)
		return cli_fail(CLI_EXIT_USAGE,
		                "unknown command '%s': use run, plan, check, study or compare (see eddy --help)", o->command);
	if (!o->scene)
		return cli_fail(CLI_EXIT_USAGE, "%s needs a scene file, e.g. eddy %s scenes/bounce.lua", o->command,
		                o->command);
	return 0;
}
