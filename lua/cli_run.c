/* SPDX-License-Identifier: MIT */
/* eddy run: the frame loop with its stats lines, checkpoints, the lock on the
 * output folder, particle exports and the ffmpeg pipe.
 *
 * Frames are drawn and written in the background (eddy_world_set_background_
 * output): the renderer's thread finishes frame N while frame N + 1 steps.
 * The run syncs where it must see the files: before a checkpoint (inside
 * eddy_world_save), before passing a frame to ffmpeg, and at the end, where a
 * failed write still stops the run with status 1 and the message naming the
 * frame and its file. EDDY_SYNC_FRAMES=1 writes every frame before the next
 * one steps, as eddy did before (the tests compare the two). */
#define _POSIX_C_SOURCE 200809L
#define _DEFAULT_SOURCE /* flock, DIR */
#include "cli.h"

#include <dirent.h>
#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <signal.h>
#include <stdlib.h>
#include <string.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include "eddy_lua.h"

typedef struct run {
	lua_State *L;
	const cli_options *o;
	int world_idx;
	eddy_world *w;
	int first, frames;   /* the frames first+1 .. frames are simulated */
	char ckpt_dir[1100]; /* OUT/checkpoints: where this run saves */
	FILE *stats;         /* NULL: no --stats */
	FILE *video;         /* the ffmpeg pipe, NULL: no --video */
	int video_frames;
	char video_log[64]; /* ffmpeg's messages */
	bool bar;           /* a progress bar on stderr */
	bool reader_gone;   /* the stats reader closed its pipe: stop quietly */
	int warned;         /* run-time warnings printed so far */
	double t0;
} run;

static double now_s(void)
{
	struct timespec ts;
	clock_gettime(CLOCK_MONOTONIC, &ts);
	return (double)ts.tv_sec + (double)ts.tv_nsec * 1e-9;
}

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
	fprintf(stderr, "\r[%s] frame %d/%d  t = %.3f s  %.0f steps/s  ETA %.0f s   ", bar, frame, frames, sim_t, rate,
	        eta);
	fflush(stderr);
}

/* Set by SIGINT/SIGTERM; the run stops after the frame in progress. */
static volatile sig_atomic_t stop_signal;

static void on_signal(int sig) { stop_signal = sig; }

/* ---- the lock on the output folder -------------------------------------------- */

/* OUT/.eddy.lock, flock'd for the whole run: two runs writing the same frames
 * and checkpoints would interleave them. The descriptor stays open until the
 * process ends, which releases the lock even after a crash; the file itself
 * stays (removing it would race with a run that has just opened it). It holds
 * the owner's pid, for the message. */
static int lock_out_dir(const char *outdir)
{
	if (cli_make_dirs(outdir) != 0)
		return cli_fail(CLI_EXIT_RUN, "cannot create output folder '%s': %s", outdir, strerror(errno));
	char path[1100];
	snprintf(path, sizeof path, "%s/.eddy.lock", outdir);
	int fd = open(path, O_RDWR | O_CREAT | O_CLOEXEC, 0644);
	if (fd < 0)
		return cli_fail(CLI_EXIT_RUN, "cannot create lock file '%s': %s", path, strerror(errno));
	if (flock(fd, LOCK_EX | LOCK_NB) != 0) {
		int err = errno;
		char pid[32] = "";
		ssize_t n = err == EWOULDBLOCK ? pread(fd, pid, sizeof pid - 1, 0) : 0;
		pid[n > 0 ? n : 0] = '\0';
		pid[strcspn(pid, "\n")] = '\0';
		close(fd);
		if (err == EWOULDBLOCK)
			return cli_fail(CLI_EXIT_RUN, "%s is in use by another run (pid %s)", outdir, pid[0] ? pid : "unknown");
		return cli_fail(CLI_EXIT_RUN, "cannot lock '%s': %s", path, strerror(err));
	}
	char text[32];
	int len = snprintf(text, sizeof text, "%ld\n", (long)getpid());
	if (ftruncate(fd, 0) != 0 || pwrite(fd, text, (size_t)len, 0) != len)
		return cli_fail(CLI_EXIT_RUN, "cannot write lock file '%s': %s", path, strerror(errno));
	return 0;
}

/* ---- checkpoints ----------------------------------------------------------------- */

static bool has_suffix(const char *s, const char *suffix)
{
	size_t n = strlen(s), k = strlen(suffix);
	return n >= k && strcmp(s + n - k, suffix) == 0;
}

static int cmp_desc(const void *a, const void *b) { return -strcmp(*(char *const *)a, *(char *const *)b); }

/* The frame-NNNNNN.eddy names in dir, newest first (the numbers are
 * zero-padded, so text order is frame order); free each and the array. */
static int list_checkpoints(const char *dir, char ***names)
{
	*names = NULL;
	DIR *d = opendir(dir);
	if (!d)
		return -1;
	int n = 0, cap = 0;
	struct dirent *e;
	while ((e = readdir(d))) {
		if (strncmp(e->d_name, "frame-", 6) != 0 || !has_suffix(e->d_name, ".eddy"))
			continue;
		if (n == cap) {
			cap = cap ? 2 * cap : 64;
			char **grown = realloc(*names, sizeof **names * (size_t)cap);
			if (!grown)
				break;
			*names = grown;
		}
		char *name = strdup(e->d_name);
		if (name)
			(*names)[n++] = name;
	}
	closedir(d);
	if (n)
		qsort(*names, (size_t)n, sizeof **names, cmp_desc);
	return n;
}

static void free_names(char **names, int n)
{
	for (int i = 0; i < n; ++i)
		free(names[i]);
	free(names);
}

/* A process killed mid-write leaves its temp files: a checkpoint's
 * frame-NNNNNN.eddy.tmp (src/checkpoint.c writes it, then renames it) and a
 * frame's or export's .NAME.PID-N.tmp (render/files.c). Called with the lock
 * held, so no other run is writing one here. */
static bool is_stale_temp(const char *name)
{
	if (strncmp(name, "frame-", 6) == 0 && has_suffix(name, ".eddy.tmp"))
		return true;
	return name[0] == '.' && has_suffix(name, ".tmp");
}

static void remove_stale_temps(const char *dir)
{
	DIR *d = opendir(dir);
	if (!d)
		return;
	struct dirent *e;
	char path[2048];
	while ((e = readdir(d))) {
		if (is_stale_temp(e->d_name)) {
			snprintf(path, sizeof path, "%s/%s", dir, e->d_name);
			unlink(path);
		}
	}
	closedir(d);
}

/* The newest keep checkpoints stay (0: all). The older ones were superseded;
 * one that cannot be removed only costs disk space, so that is not fatal. */
static void prune_checkpoints(const char *dir, int keep)
{
	if (keep <= 0)
		return;
	char **names;
	int n = list_checkpoints(dir, &names);
	char path[2048];
	for (int i = keep; i < n; ++i) {
		snprintf(path, sizeof path, "%s/%s", dir, names[i]);
		unlink(path);
	}
	free_names(names, n > 0 ? n : 0);
}

static int checkpoint(run *r)
{
	char path[2048];
	if (cli_make_dirs(r->ckpt_dir) != 0)
		return cli_fail(CLI_EXIT_RUN, "cannot create checkpoint directory '%s': %s", r->ckpt_dir, strerror(errno));
	snprintf(path, sizeof path, "%s/frame-%06d.eddy", r->ckpt_dir, eddy_world_frame(r->w));
	if (eddy_world_save(r->w, path, r->o->fingerprint) != EDDY_OK)
		return cli_fail(CLI_EXIT_RUN, "%s", eddy_world_error(r->w));
	prune_checkpoints(r->ckpt_dir, r->o->keep_checkpoints);
	return 0;
}

/* --resume takes a run's output folder (its checkpoints/ inside) or the
 * checkpoints folder itself. */
static void resume_dir(const char *arg, char *out, size_t cap)
{
	struct stat st;
	snprintf(out, cap, "%s/checkpoints", arg);
	if (stat(out, &st) == 0 && S_ISDIR(st.st_mode))
		return;
	snprintf(out, cap, "%s", arg);
}

/* Loads the newest checkpoint in the folder that is intact and of this scene;
 * older ones stand in for rejected ones, each rejection said on stderr. */
static int resume(run *r)
{
	char dir[1100];
	resume_dir(r->o->resume, dir, sizeof dir);
	char **names;
	int n = list_checkpoints(dir, &names);
	if (n < 0)
		return cli_fail(CLI_EXIT_RUN, "--resume %s: cannot open: %s", dir, strerror(errno));
	bool loaded = false;
	for (int i = 0; i < n && !loaded; ++i) {
		char path[2048];
		snprintf(path, sizeof path, "%s/%s", dir, names[i]);
		if (eddy_world_load(r->w, path, r->o->fingerprint) == EDDY_OK) {
			loaded = true;
			if (!r->o->quiet)
				fprintf(stderr, "eddy: resuming from %s (frame %d, t = %.6g s)\n", path, eddy_world_frame(r->w),
				        eddy_world_time(r->w));
		} else {
			fprintf(stderr, "eddy: warning: %s; trying an older one\n", eddy_world_error(r->w));
		}
	}
	free_names(names, n);
	if (!loaded)
		return cli_fail(CLI_EXIT_RUN, "--resume %s: no valid checkpoint of this scene (frame-NNNNNN.eddy)", dir);
	return 0;
}

/* ---- --export: a particle export the scene did not ask for ------------------- */

static int add_export(run *r)
{
	const char *fmt = r->o->export_format;
	eddy_export_particles_def d = eddy_default_export_particles_def();
	if (strcmp(fmt, "ply") == 0)
		d.format = EDDY_EXPORT_PLY;
	else if (strcmp(fmt, "vtk") == 0)
		d.format = EDDY_EXPORT_VTK;
	else
		d.format = EDDY_EXPORT_VTP; /* one .vtp a frame and OUT/particles.pvd */
	/* the path is a printf pattern: a '%' of the folder is written "%%" */
	char dir[1024];
	size_t k = 0;
	for (const char *s = r->o->outdir; *s && k + 2 < sizeof dir; ++s) {
		if (*s == '%')
			dir[k++] = '%';
		dir[k++] = *s;
	}
	dir[k] = '\0';
	if (snprintf(d.path, sizeof d.path, "%s/particles_%%04d.%s", dir, fmt) >= (int)sizeof d.path)
		return cli_fail(CLI_EXIT_USAGE, "--export: the output folder '%s' is too long", r->o->outdir);
	eddy_system_id id = eddy_add_export_particles(r->w, &d);
	if (!eddy_system_valid(r->w, id))
		return cli_fail(CLI_EXIT_RUN, "--export %s: %s", fmt, eddy_world_error(r->w));
	return 0;
}

/* ---- --video: the frames the scene renders, piped to ffmpeg ------------------- */

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

static int start_video(run *r)
{
	const char *file = r->o->video;
	if (!on_path("ffmpeg"))
		return cli_fail(CLI_EXIT_RUN,
		                "--video %s: ffmpeg is not installed (not found on PATH); install it (Debian: "
		                "apt-get install ffmpeg) or leave out --video (PNG frames need no ffmpeg)",
		                file);
	snprintf(r->video_log, sizeof r->video_log, "/tmp/eddy-ffmpeg-XXXXXX");
	int fd = mkstemp(r->video_log);
	if (fd >= 0)
		close(fd);
	else
		snprintf(r->video_log, sizeof r->video_log, "/dev/null");
	r->video = open_video(file, eddy_world_get_def(r->w)->fps, r->video_log);
	if (!r->video)
		return cli_fail(CLI_EXIT_RUN, "--video %s: cannot start ffmpeg: %s", file, strerror(errno));
	return 0;
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

/* The image the renderer published in this frame's stats, into ffmpeg. */
static int video_frame(run *r)
{
	char buf[1024];
	/* the image is on disk only once the renderer's thread has written it */
	if (eddy_world_sync(r->w) != EDDY_OK)
		return cli_fail(CLI_EXIT_RUN, "%s", cli_first_line(eddy_world_error(r->w), buf, sizeof buf));
	eddy_frame_stats s;
	eddy_world_frame_stats(r->w, &s);
	const eddy_stat_value *img = cli_find_extra(&s, "image");
	if (!img || !img->text)
		return 0;
	if (send_frame(r->video, img->text)) {
		r->video_frames++;
		return 0;
	}
	/* stats texts hold 63 characters: a longer path arrives cut short */
	if (strlen(img->text) >= 63)
		return cli_fail(CLI_EXIT_RUN,
		                "--video %s: the frame path '%s...' is too long to pass on (63 characters at "
		                "most); use a shorter --out or image path",
		                r->o->video, img->text);
	return cli_fail(CLI_EXIT_RUN, "--video %s: cannot pass frame '%s' to ffmpeg: %s", r->o->video, img->text,
	                strerror(errno));
}

static int finish_video(run *r, int code)
{
	int st = pclose(r->video);
	if (code == 0 && r->video_frames == 0)
		code = cli_fail(CLI_EXIT_RUN, "--video %s: the scene rendered no frames (add eddy.render_points to it)",
		                r->o->video);
	else if (code == 0 && st != 0) {
		char msg[512] = "";
		FILE *lf = fopen(r->video_log, "r");
		if (lf) {
			if (!fgets(msg, sizeof msg, lf))
				msg[0] = '\0';
			fclose(lf);
		}
		msg[strcspn(msg, "\n")] = '\0';
		code = cli_fail(CLI_EXIT_RUN, "--video %s: ffmpeg failed (status %d%s%s); the PNG frames are on disk",
		                r->o->video, WIFEXITED(st) ? WEXITSTATUS(st) : st, msg[0] ? ": " : "", msg);
	}
	if (strcmp(r->video_log, "/dev/null") != 0)
		unlink(r->video_log);
	return code;
}

/* ---- the run --------------------------------------------------------------------- */

static void run_check_report(eddy_check_level level, const char *message, void *user)
{
	const bool *quiet = user;
	if (level == EDDY_CHECK_ERROR || (level == EDDY_CHECK_WARNING && !*quiet))
		fprintf(stderr, "eddy: %s: %s\n", level == EDDY_CHECK_ERROR ? "error" : "warning", message);
}

/* Everything before the first frame: threads, the export, the lock, the
 * checkpoint to resume from, the preflight. */
static int prepare(run *r)
{
	const cli_options *o = r->o;
	const eddy_world_def *def = eddy_world_get_def(r->w);
	if (o->threads && eddy_world_set_threads(r->w, o->threads) != EDDY_OK)
		return cli_fail(CLI_EXIT_USAGE, "%s", eddy_world_error(r->w));
	/* --threads counts the simulation's threads; a renderer's writer is its own */
	const char *sync = getenv("EDDY_SYNC_FRAMES");
	eddy_world_set_background_output(r->w, !(sync && sync[0] && strcmp(sync, "0") != 0));
	double duration = o->duration >= 0 ? o->duration : def->duration;
	/* in double first: a duration of many frames overflows an int */
	const double frames = o->frames >= 0 ? o->frames : ceil(duration * def->fps - 1e-9);
	if (!(frames <= CLI_MAX_FRAMES))
		return o->duration >= 0 ? cli_fail(CLI_EXIT_USAGE,
		                                   "--duration %g s is %.3g frames at %g fps: a run may have at most %d frames",
		                                   duration, frames, def->fps, CLI_MAX_FRAMES)
		                        : cli_fail(CLI_EXIT_RUN,
		                                   "%s: world 'duration' %g s is %.3g frames at %g fps: a run may have at "
		                                   "most %d frames",
		                                   o->scene, duration, frames, def->fps, CLI_MAX_FRAMES);
	r->frames = (int)frames;
	/* a run is whole frames: --duration below one frame would run a whole
	 * frame, many times what was asked (the scene's own duration is checked
	 * by the preflight) */
	if (o->frames < 0 && o->duration > 0) {
		const double ran = r->frames / def->fps;
		if (ran > 2 * o->duration)
			return cli_fail(CLI_EXIT_USAGE,
			                "--duration %g s is shorter than one frame of the scene (%g s at %g fps): "
			                "give at least %g s or --frames",
			                o->duration, 1 / def->fps, def->fps, 1 / def->fps);
		if (ran > 1.01 * o->duration && !o->quiet)
			fprintf(stderr, "eddy: warning: --duration %g s runs %d whole frames, %g s\n", o->duration, r->frames, ran);
	}
	snprintf(r->ckpt_dir, sizeof r->ckpt_dir, "%s/checkpoints", o->outdir);
	int code = o->export_format ? add_export(r) : 0; /* before resume: it is part of the pipeline */
	if (code == 0)
		code = lock_out_dir(o->outdir);
	if (code)
		return code;
	remove_stale_temps(r->ckpt_dir);
	remove_stale_temps(o->outdir);
	if (o->resume && (code = resume(r)) != 0)
		return code;
	r->first = eddy_world_frame(r->w);
	if (o->resume && r->first >= r->frames)
		return cli_fail(CLI_EXIT_USAGE,
		                "--resume: the checkpoint is at frame %d and the run ends at frame %d: "
		                "nothing left to run (ask for more with --frames or --duration)",
		                r->first, r->frames);
	/* the preflight of eddy check: a scene that cannot work (one that would
	 * not fit in memory, say) is refused before it allocates anything */
	if (r->first == 0) {
		bool quiet = o->quiet;
		int errors = eddy_world_check(r->w, run_check_report, &quiet);
		if (errors)
			return cli_fail(CLI_EXIT_RUN, "%s: not run: %d problem%s found by the preflight check (above)", o->scene,
			                errors, errors == 1 ? "" : "s");
	}
	return 0;
}

/* This frame's stats line. A reader that closed the pipe (EPIPE: `eddy run
 * ... --stats - | head`) stops the run quietly; any other write error fails it. */
static int stats_line(run *r)
{
	eddy_frame_stats s;
	eddy_world_frame_stats(r->w, &s);
	const char *clash = cli_write_stats(r->stats, &s, r->L, lua_gettop(r->L));
	int err = cli_stats_flush(r->stats);
	if (err == EPIPE) {
		r->reader_gone = true;
		return 0;
	}
	if (err)
		return cli_fail(CLI_EXIT_RUN, "cannot write stats file '%s': %s", r->o->stats, strerror(err));
	if (clash)
		return cli_fail(CLI_EXIT_RUN, "on_frame returned '%s', which is a stats field of eddy; give it another name",
		                clash);
	return 0;
}

/* Frame i + 1: step, stats line, checkpoint, video frame, progress. */
static int frame(run *r, int i)
{
	char buf[1024];
	const eddy_status st = eddy_world_step_frame(r->w);
	/* the frame's new run-time warnings, one line each (a warning does not
	 * stop the run; they come before an error that does) */
	for (; r->warned < eddy_world_warning_count(r->w); r->warned++)
		if (!r->o->quiet) {
			if (r->bar)
				fputc('\n', stderr);
			fprintf(stderr, "eddy: warning: %s\n", eddy_world_warning(r->w, r->warned));
		}
	if (st != EDDY_OK) {
		if (r->bar)
			fputc('\n', stderr);
		return cli_fail(CLI_EXIT_RUN, "%s", cli_first_line(eddy_world_error(r->w), buf, sizeof buf));
	}
	eddy_lua_take_frame_fields(r->L, r->world_idx);
	int code = r->stats ? stats_line(r) : 0;
	lua_pop(r->L, 1);
	if (code == 0 && r->o->checkpoint_every && (i + 1) % r->o->checkpoint_every == 0)
		code = checkpoint(r);
	if (code == 0 && r->video)
		code = video_frame(r);
	if (r->bar)
		progress(i + 1, r->frames, eddy_world_time(r->w), now_s() - r->t0, eddy_world_steps(r->w));
	if (code == 0 && stop_signal && i + 1 < r->frames) {
		if (r->bar)
			fputc('\n', stderr);
		code = checkpoint(r);
		if (code == 0)
			code = cli_fail(128 + stop_signal,
			                "interrupted after frame %d (t = %.6g s); resume with: eddy run %s --resume %s (and the "
			                "same options)",
			                i + 1, eddy_world_time(r->w), r->o->scene, r->ckpt_dir);
	}
	return code;
}

static void catch_signals(void)
{
	struct sigaction sa;
	memset(&sa, 0, sizeof sa);
	sa.sa_handler = on_signal;
	/* a second signal ends the process at once; interrupted writes restart, so
	 * no frame file is left half written */
	sa.sa_flags = (int)(SA_RESETHAND | SA_RESTART);
	sigaction(SIGINT, &sa, NULL);
	sigaction(SIGTERM, &sa, NULL);
}

static int finish(run *r, int code)
{
	/* the frames still being written: all on disk (or failed) before the end */
	char buf[1024];
	if (eddy_world_sync(r->w) != EDDY_OK && code == 0) {
		if (r->bar)
			fputc('\n', stderr);
		code = cli_fail(CLI_EXIT_RUN, "%s", cli_first_line(eddy_world_error(r->w), buf, sizeof buf));
	}
	if (r->bar && code == 0)
		fputc('\n', stderr);
	if (r->stats && r->stats != stdout) {
		int err = r->reader_gone ? 0 : cli_stats_flush(r->stats);
		if (fclose(r->stats) != 0 && !err && !r->reader_gone)
			err = errno ? errno : EIO;
		if (err && code == 0)
			code = cli_fail(CLI_EXIT_RUN, "cannot finish stats file '%s': %s", r->o->stats, strerror(err));
	}
	if (r->video)
		code = finish_video(r, code);
	if (code == 0 && !r->o->quiet && !r->reader_gone)
		printf("eddy: %s: %d frames, %.3f s simulated in %.2f s wall (%lld steps, %zu particles)\n", r->o->scene,
		       eddy_world_frame(r->w) - r->first, eddy_world_time(r->w), now_s() - r->t0,
		       (long long)eddy_world_steps(r->w), eddy_world_particle_count(r->w));
	return code;
}

int cli_run(lua_State *L, const cli_options *o, int world_idx)
{
	run r;
	memset(&r, 0, sizeof r);
	r.L = L;
	r.o = o;
	r.world_idx = world_idx;
	r.w = eddy_lua_toworld(L, world_idx);
	int code = prepare(&r);
	if (code == 0 && o->stats)
		code = cli_open_stats(o, r.first, &r.stats);
	if (code == 0 && o->video)
		code = start_video(&r);
	if (code) {
		if (r.stats && r.stats != stdout)
			fclose(r.stats);
		return code;
	}
	catch_signals();
	r.bar = !o->quiet && isatty(STDERR_FILENO);
	r.t0 = now_s();
	for (int i = r.first; i < r.frames && code == 0 && !r.reader_gone; ++i)
		code = frame(&r, i);
	return finish(&r, code);
}
