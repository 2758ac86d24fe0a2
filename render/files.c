/* SPDX-License-Identifier: MIT */
/* Helpers for the renderer and the exporters: frame path patterns, parent
 * directories, particle values by channel name, and files written through a
 * temporary name so a reader never sees a partial one. */
#define _POSIX_C_SOURCE 200809L
#include "render.h"

#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <stdarg.h>
#include <stdatomic.h>
#include <stdio.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

const char *eddy_check_frame_pattern(const char *p)
{
	int conversions = 0;
	if (!p[0])
		return "must not be empty";
	for (const char *c = p; *c; ++c) {
		if (*c != '%')
			continue;
		if (c[1] == '%') {
			++c;
			continue;
		}
		++c;
		while (*c == '0' || *c == '-' || *c == '+' || *c == ' ')
			++c;
		int digits = 0;
		while (*c >= '0' && *c <= '9' && digits < 3)
			++c, ++digits;
		if (*c != 'd' && *c != 'i' && *c != 'u')
			return "may hold only an integer conversion for the frame (%d, %04d, %i or %u; %% for a percent sign)";
		++conversions;
	}
	if (conversions != 1)
		return "must hold exactly one integer conversion for the frame, e.g. \"frame_%04d.png\"";
	return NULL;
}

int eddy_frame_path(const char *pattern, int frame, char *out, size_t cap)
{
	/* the pattern was checked: one integer conversion, so this is safe */
#if defined(__GNUC__)
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wformat-nonliteral"
#endif
	int n = snprintf(out, cap, pattern, frame);
#if defined(__GNUC__)
#pragma GCC diagnostic pop
#endif
	return n < 0 || (size_t)n >= cap ? -1 : 0;
}

int eddy_make_parent_dirs(const char *path)
{
	char buf[1024];
	if (strlen(path) >= sizeof buf) {
		errno = ENAMETOOLONG;
		return -1;
	}
	strcpy(buf, path);
	char *slash = strrchr(buf, '/');
	if (!slash)
		return 0;
	*slash = '\0';
	for (char *p = buf + 1; *p; ++p) {
		if (*p != '/')
			continue;
		*p = '\0';
		if (mkdir(buf, 0777) != 0 && errno != EEXIST)
			return -1;
		*p = '/';
	}
	if (buf[0] && mkdir(buf, 0777) != 0 && errno != EEXIST)
		return -1;
	return 0;
}

const float *eddy_particle_values(const eddy_world *w, const char *name, float *scratch, size_t count)
{
	size_t n = 0;
	if (strcmp(name, "speed") == 0) {
		const float *vx = eddy_world_channel(w, "vx", &n), *vy = eddy_world_channel(w, "vy", &n),
					*vz = eddy_world_channel(w, "vz", &n);
		if (!vx || !vy || !vz)
			return NULL;
		for (size_t i = 0; i < count; ++i)
			scratch[i] = sqrtf(vx[i] * vx[i] + vy[i] * vy[i] + vz[i] * vz[i]);
		return scratch;
	}
	const float *v = eddy_world_channel(w, name, &n);
	return v && n == count ? v : NULL;
}

/* ---- files written whole or not at all ---- */

int eddy_file_begin(eddy_file *o, const char *path)
{
	memset(o, 0, sizeof *o);
	o->path = path;
	if (eddy_make_parent_dirs(path) != 0)
		return o->err = errno ? errno : EIO;
	/* a hidden name in the final file's folder: rename() within one file
	 * system is atomic, and file-series readers never list it */
	const char *slash = strrchr(path, '/');
	const int dir_len = slash ? (int)(slash - path) + 1 : 0;
	/* frame hooks on the stepping thread and renderers' writer threads all
	 * take names from it */
	static atomic_uint counter;
	for (int attempt = 0; attempt < 100; ++attempt) {
		int n = snprintf(o->tmp, sizeof o->tmp, "%.*s.%s.%ld-%u.tmp", dir_len, path, path + dir_len, (long)getpid(),
		                 atomic_fetch_add(&counter, 1u));
		if (n < 0 || (size_t)n >= sizeof o->tmp)
			return o->err = ENAMETOOLONG;
		/* O_EXCL: never write through a file (or link) someone else made */
		int fd = open(o->tmp, O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0666);
		if (fd < 0 && errno == EEXIST)
			continue;
		if (fd < 0)
			return o->err = errno;
		o->f = fdopen(fd, "wb");
		if (!o->f) {
			o->err = errno;
			close(fd);
			unlink(o->tmp);
			return o->err;
		}
		return 0;
	}
	return o->err = EEXIST;
}

void eddy_file_write(eddy_file *o, const void *p, size_t n)
{
	if (o->err || n == 0)
		return;
	errno = 0;
	if (fwrite(p, 1, n, o->f) != n)
		o->err = errno ? errno : EIO;
}

void eddy_file_printf(eddy_file *o, const char *fmt, ...)
{
	if (o->err)
		return;
	va_list ap;
	va_start(ap, fmt);
	errno = 0;
	int n = vfprintf(o->f, fmt, ap);
	va_end(ap);
	if (n < 0)
		o->err = errno ? errno : EIO;
}

int eddy_file_finish(eddy_file *o)
{
	if (!o->f)
		return o->err ? o->err : EINVAL;
	if (!o->err && fflush(o->f) != 0)
		o->err = errno ? errno : EIO;
	/* fclose always releases the stream, whatever it returns */
	if (fclose(o->f) != 0 && !o->err)
		o->err = errno ? errno : EIO;
	o->f = NULL;
	if (!o->err && rename(o->tmp, o->path) != 0)
		o->err = errno ? errno : EIO;
	if (o->err)
		unlink(o->tmp);
	return o->err;
}

void eddy_file_abort(eddy_file *o)
{
	if (!o->f)
		return;
	fclose(o->f);
	o->f = NULL;
	unlink(o->tmp);
}
