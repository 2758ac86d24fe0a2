/* SPDX-License-Identifier: MIT */
/* The stats lines of eddy run (JSON, one object per frame) and the stats
 * file: every write checked, and on resume the record kept free of gaps. */
#define _POSIX_C_SOURCE 200809L /* open_memstream */
#include "cli.h"

#include <errno.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

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
	case LUA_TBOOLEAN:
		fputs(lua_toboolean(L, idx) ? "true" : "false", f);
		return;
	case LUA_TSTRING:
		json_string(f, lua_tostring(L, idx));
		return;
	case LUA_TTABLE:
		break;
	default:
		fputs("null", f);
		return;
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
	"frame",
	"time",
	"steps",
	"dt_min",
	"dt_max",
	"dt_limit",
	"particles",
	"max_speed",
	"cfl",
	"density_err_avg",
	"density_err_max",
	"density_compression_avg",
	"volume",
	"leaked",
	"nonfinite",
	"solver",
	"iterations",
	"residual",
	"divergence",
	"wall_ms",
	"state_hash",
	"systems",
	"kinetic_energy",
	"potential_energy",
	"compression_energy",
	"energy",
	"momentum",
	"warnings",
	NULL,
};

static bool is_contract_field(const char *name)
{
	for (int i = 0; contract_fields[i]; ++i)
		if (strcmp(contract_fields[i], name) == 0)
			return true;
	return false;
}

const eddy_stat_value *cli_find_extra(const eddy_frame_stats *s, const char *name)
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

const char *cli_write_stats(FILE *f, const eddy_frame_stats *s, lua_State *L, int fields_idx)
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
		json_extra(f, cli_find_extra(s, solver_fields[i]));
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
	/* appended to the contract: J, J, J, J and kg m/s, null without a particle
	 * mass; compression_energy null without sph_pressure's equation of state */
	fputs(",\"kinetic_energy\":", f);
	json_number(f, s->kinetic_energy);
	fputs(",\"potential_energy\":", f);
	json_number(f, s->potential_energy);
	fputs(",\"compression_energy\":", f);
	json_number(f, s->compression_energy);
	fputs(",\"energy\":", f);
	json_number(f, s->energy);
	fputs(",\"momentum\":", f);
	if (isfinite(s->momentum[0]) && isfinite(s->momentum[1]) && isfinite(s->momentum[2])) {
		fputc('[', f);
		for (int i = 0; i < 3; ++i) {
			if (i)
				fputc(',', f);
			json_number(f, s->momentum[i]);
		}
		fputc(']', f);
	} else {
		fputs("null", f);
	}
	fprintf(f, ",\"warnings\":%d", s->warnings); /* appended: run-time warnings so far */
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

/* ---- the stats file --------------------------------------------------------- */

int cli_stats_flush(FILE *f)
{
	/* the error indicator is sticky: a failed fputc or fprintf anywhere in
	 * the line (or a buffer flush inside one) is still seen here */
	errno = 0;
	if (fflush(f) == 0 && !ferror(f))
		return 0;
	return errno ? errno : EIO;
}

/* The lines of path for frames 1..keep into *kept (malloc'd), their count in
 * *lines. Returns 0, ENOENT for no file, or another errno. */
static int read_kept_lines(const char *path, int keep, char **kept, size_t *kept_len, int *lines)
{
	*kept = NULL;
	*kept_len = 0;
	*lines = 0;
	FILE *in = fopen(path, "r");
	if (!in)
		return errno;
	FILE *mem = open_memstream(kept, kept_len);
	if (!mem) {
		fclose(in);
		return errno;
	}
	char line[65536];
	while (fgets(line, sizeof line, in)) {
		int frame;
		if (sscanf(line, "{\"frame\":%d", &frame) == 1 && frame >= 1 && frame <= keep) {
			fputs(line, mem);
			++*lines;
		}
	}
	int err = ferror(in) ? (errno ? errno : EIO) : 0;
	fclose(in);
	if (fclose(mem) != 0 && !err)
		err = ENOMEM;
	return err;
}

/* path rewritten to hold text alone: a temp file beside it, then rename, so a
 * failure leaves the old file whole. */
static int replace_file(const char *path, const char *text, size_t len)
{
	char tmp[1100];
	snprintf(tmp, sizeof tmp, "%s.eddy-tmp", path);
	FILE *f = fopen(tmp, "w");
	if (!f)
		return errno;
	fwrite(text, 1, len, f);
	int err = cli_stats_flush(f);
	if (fclose(f) != 0 && !err)
		err = errno ? errno : EIO;
	if (!err && rename(tmp, path) != 0)
		err = errno;
	if (err)
		remove(tmp);
	return err;
}

/* A resumed run continues the record of frames 1..first: later lines (from
 * after the checkpoint) are dropped; missing ones are an error, since the
 * file would have a gap. No file at all starts a new one. */
static int open_resumed_stats(const cli_options *o, int first, FILE **out)
{
	char *kept;
	size_t kept_len;
	int lines, err = read_kept_lines(o->stats, first, &kept, &kept_len, &lines);
	if (err == ENOENT) {
		free(kept);
		*out = fopen(o->stats, "w");
		return *out ? 0 : cli_fail(CLI_EXIT_RUN, "cannot write stats file '%s': %s", o->stats, strerror(errno));
	}
	if (err) {
		free(kept);
		return cli_fail(CLI_EXIT_RUN, "cannot read stats file '%s': %s", o->stats, strerror(err));
	}
	if (lines < first) {
		free(kept);
		return cli_fail(CLI_EXIT_RUN,
		                "--resume: stats file '%s' has %d lines for the %d frames up to the checkpoint (frame %d); "
		                "lines are missing, so it cannot be continued (move it away or choose another --stats)",
		                o->stats, lines, first, first);
	}
	err = replace_file(o->stats, kept ? kept : "", kept_len);
	free(kept);
	if (err)
		return cli_fail(CLI_EXIT_RUN, "cannot write stats file '%s': %s", o->stats, strerror(err));
	*out = fopen(o->stats, "a");
	return *out ? 0 : cli_fail(CLI_EXIT_RUN, "cannot write stats file '%s': %s", o->stats, strerror(errno));
}

int cli_open_stats(const cli_options *o, int first, FILE **out)
{
	*out = NULL;
	if (strcmp(o->stats, "-") == 0) {
		*out = stdout;
		return 0;
	}
	if (cli_make_parent_dirs(o->stats) != 0)
		return cli_fail(CLI_EXIT_RUN, "cannot write stats file '%s': cannot create its folder: %s", o->stats,
		                strerror(errno));
	if (o->resume && first > 0)
		return open_resumed_stats(o, first, out);
	*out = fopen(o->stats, "w");
	return *out ? 0 : cli_fail(CLI_EXIT_RUN, "cannot write stats file '%s': %s", o->stats, strerror(errno));
}
