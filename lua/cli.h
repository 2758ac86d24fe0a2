/* SPDX-License-Identifier: MIT */
/* The eddy command's parts (lua/main.c, lua/cli_*.c): options, one-line
 * failures, stats lines and the run loop. Only the command links these; the
 * Lua module (eddy.so) does not. */
#ifndef EDDY_CLI_H
#define EDDY_CLI_H

#include <lua.h>

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>

#include "eddy.h"

/* Exit status: 0 success, 1 the scene or the run failed, 2 bad usage. */
enum { CLI_EXIT_RUN = 1, CLI_EXIT_USAGE = 2 };

/* The most frames one run may ask for, by --frames or a duration. */
enum { CLI_MAX_FRAMES = 100000000 };

typedef struct cli_options {
	const char *command; /* run, plan or check */
	const char *scene;
	int frames;      /* -1: from the duration */
	double duration; /* < 0: the scene's */
	const char *out;
	int threads;               /* 0: the scene's */
	const char *stats;         /* "-": stdout */
	const char *video;         /* the rendered frames through ffmpeg */
	const char *export_format; /* --export ply|vtk|vtp, NULL: none */
	bool quiet, dot, safe;
	int checkpoint_every; /* 0: none */
	int keep_checkpoints; /* the newest N stay after each save; 0: all */
	const char *resume;   /* a run's --out or its checkpoints folder */
	uint64_t fingerprint; /* scene text and --set values, for checkpoints */
	char outdir[1024];    /* --out or out/<scene> */
} cli_options;

/* Prints "eddy: " and the message as one line on stderr; returns code. */
int cli_fail(int code, const char *fmt, ...)
#if defined(__GNUC__)
	__attribute__((format(printf, 2, 3)))
#endif
	;

/* The first line of msg in buf: failures are one line. */
const char *cli_first_line(const char *msg, char *buf, size_t cap);

/* mkdir -p; 0 or -1 with errno set. */
int cli_make_dirs(const char *path);
/* The folders above the file at path (mkdir -p of its dirname). */
int cli_make_parent_dirs(const char *path);

/* FNV-1a over data, continuing from h. */
uint64_t cli_fnv(uint64_t h, const void *data, size_t n);

/* Parses argv into o; --set values go to L (eddy.param). Returns 0 to go
 * on, -1 when a help or version text was printed (exit 0), or the exit
 * status of a usage error (already reported). */
int cli_parse(int argc, char **argv, cli_options *o, lua_State *L);

/* eddy run: the loaded world is at world_idx. Returns the exit status. */
int cli_run(lua_State *L, const cli_options *o, int world_idx);

/* ---- stats lines (lua/cli_stats.c) ---- */

/* One stats line; fields_idx is the on_frame table (or nil). Returns NULL or
 * the name of an on_frame field that shadows a field of eddy. Write errors
 * are left in f's error indicator for cli_stats_flush. */
const char *cli_write_stats(FILE *f, const eddy_frame_stats *s, lua_State *L, int fields_idx);

/* Flushes f; 0 when every write since the last call reached the file,
 * otherwise the errno of the failure (EPIPE: the reader went away). */
int cli_stats_flush(FILE *f);

/* Opens the stats file for a run starting at frame first (> 0: a resume).
 * On resume the lines of frames 1..first are kept and later ones dropped;
 * a file missing some of them is refused, as a gap in the record would be.
 * Returns 0 with *out set, or the exit status of a reported failure. */
int cli_open_stats(const cli_options *o, int first, FILE **out);

/* The stats extra named name, or NULL. */
const eddy_stat_value *cli_find_extra(const eddy_frame_stats *s, const char *name);

#endif
