/* SPDX-License-Identifier: MIT */
/* PNG writing: the one file that holds stb_image_write's implementation
 * (Debian's libstb-dev header). STATIC keeps its symbols private to this file;
 * its tuning globals are never written, so they stay at their defaults. The
 * encoded bytes go through eddy_file, so a failed write leaves no PNG. */
#define STB_IMAGE_WRITE_IMPLEMENTATION
#define STB_IMAGE_WRITE_STATIC
#include <stb/stb_image_write.h>

#include "render.h"

#include <errno.h>

static void put(void *context, void *data, int size)
{
	eddy_file_write(context, data, size > 0 ? (size_t)size : 0);
}

int eddy_write_png(const char *path, int width, int height, const uint8_t *rgb)
{
	eddy_file f;
	if (eddy_file_begin(&f, path) != 0)
		return f.err;
	/* stb reports only its own failure (an allocation); write errors are f's */
	if (!stbi_write_png_to_func(put, &f, width, height, 3, rgb, width * 3) && !f.err)
		f.err = ENOMEM;
	if (f.err) {
		int err = f.err;
		eddy_file_abort(&f);
		return err;
	}
	return eddy_file_finish(&f);
}
