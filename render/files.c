/* Helpers for the renderer and the exporters: frame path patterns, parent
 * directories, and particle values by channel name. */
#define _POSIX_C_SOURCE 200809L
#include "render.h"

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <string.h>
#include <sys/stat.h>

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
