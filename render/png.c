/* SPDX-License-Identifier: MIT */
/* PNG writing with libpng (Debian's libpng-dev), tuned for speed: zlib level 1
 * with the run-length strategy (Z_RLE) and the "up" filter on every row. A
 * rendered frame is mostly runs (background, flat-shaded sprite interiors,
 * rows repeating the row above), which RLE over "up" residuals catches at a
 * fraction of the cost of a full deflate search. Measured on a 960x540 frame
 * of the pour scene (CPU ms per frame, file size; tests/bench_render.c,
 * `make bench-render`, prints the current figures): stb_image_write at its
 * default level 8 about 50 ms and 184 kB, libpng up + Z_RLE about 7 ms and
 * 157 kB. The encoded bytes go through eddy_file, so a failed write leaves no
 * PNG; libpng's own errors (out of memory) come back through its longjmp. */
#include "render.h"

#include <errno.h>
#include <png.h>
#include <setjmp.h>
#include <zlib.h>

static void put(png_structp p, png_bytep data, size_t size) { eddy_file_write(png_get_io_ptr(p), data, size); }

static void flush(png_structp p) { (void)p; }

/* libpng reports through these; eddy reports the failure itself */
static void on_error(png_structp p, png_const_charp msg)
{
	(void)msg;
	png_longjmp(p, 1);
}

static void on_warning(png_structp p, png_const_charp msg)
{
	(void)p;
	(void)msg;
}

static int encode(eddy_file *f, int width, int height, const uint8_t *rgb)
{
	png_structp p = png_create_write_struct(PNG_LIBPNG_VER_STRING, NULL, on_error, on_warning);
	png_infop info = p ? png_create_info_struct(p) : NULL;
	if (!p || !info) {
		png_destroy_write_struct(p ? &p : NULL, NULL);
		return ENOMEM;
	}
	/* volatile: read after the longjmp */
	volatile int err = ENOMEM;
	if (setjmp(png_jmpbuf(p)) == 0) {
		png_set_write_fn(p, f, put, flush);
		png_set_IHDR(p, info, (png_uint_32)width, (png_uint_32)height, 8, PNG_COLOR_TYPE_RGB, PNG_INTERLACE_NONE,
		             PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
		png_set_compression_level(p, 1);
		png_set_compression_strategy(p, Z_RLE);
		png_set_filter(p, PNG_FILTER_TYPE_BASE, PNG_FILTER_UP);
		png_write_info(p, info);
		for (int y = 0; y < height; ++y)
			png_write_row(p, rgb + (size_t)y * (size_t)width * 3);
		png_write_end(p, info);
		err = 0;
	}
	png_destroy_write_struct(&p, &info);
	return err;
}

int eddy_write_png(const char *path, int width, int height, const uint8_t *rgb)
{
	eddy_file f;
	if (eddy_file_begin(&f, path) != 0)
		return f.err;
	/* libpng reports only its own failures (an allocation); write errors are f's */
	int err = encode(&f, width, height, rgb);
	if (err && !f.err)
		f.err = err;
	if (f.err) {
		err = f.err;
		eddy_file_abort(&f);
		return err;
	}
	return eddy_file_finish(&f);
}
