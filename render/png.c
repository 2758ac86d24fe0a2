/* SPDX-License-Identifier: MIT */
/* PNG writing: RGB, 8 bits, every row "up"-filtered, compressed by zlib at
 * level 1 with the run-length strategy (Z_RLE), the PNG container (PNG
 * specification, 2nd edition, ISO/IEC 15948) and the zlib wrapper (RFC 1950)
 * written here.
 *
 * A rendered frame is mostly runs: the background, flat-shaded sprite
 * interiors, rows repeating the row above, which the up filter turns into
 * zeros and RLE over them catches at a fraction of a full deflate search.
 * A run of whole rows equal to the row above (the background over and under
 * the liquid) is not passed through zlib at all: zlib's stream is ended with
 * a full flush (its history dropped, so it never refers back past it), the
 * run is written as one fixed-Huffman deflate block (RFC 1951 section 3.2.6:
 * per row its filter byte and a zero as literals, then copies of distance 1),
 * an empty stored block brings the stream back to a byte boundary and zlib
 * goes on. The zlib checksum (Adler-32) of such a row is two additions.
 *
 * Measured on real pour frames (960x540; CPU ms per frame and bytes,
 * `make bench-render` prints the current figures under "encoders"): libpng
 * with the same settings about 7 ms, this writer about 4, the files within a
 * few per cent of each other.
 *
 * The bytes go through eddy_file, so a failed write leaves no PNG. */
#include "render.h"

#include <errno.h>
#include <stdlib.h>
#include <string.h>
#include <zlib.h>

/* Runs of equal rows shorter than this go through zlib: a full flush costs
 * zlib a new block header, some tens of bytes. */
#define MIN_RUN 8

#define ADLER_MOD 65521u

typedef struct out_buf {
	uint8_t *p;
	size_t n, cap;
	uint64_t bits; /* bits not yet whole bytes, least significant first */
	int nbits;
} out_buf;

static int reserve(out_buf *o, size_t more)
{
	if (o->n + more <= o->cap)
		return 0;
	size_t cap = 2 * o->cap + more;
	uint8_t *p = realloc(o->p, cap);
	if (!p)
		return ENOMEM;
	o->p = p;
	o->cap = cap;
	return 0;
}

/* n <= 32 bits of v, least significant first (deflate's bit order); the
 * caller reserved room. */
static void put_bits(out_buf *o, uint32_t v, int n)
{
	o->bits |= (uint64_t)v << o->nbits;
	o->nbits += n;
	while (o->nbits >= 8) {
		o->p[o->n++] = (uint8_t)o->bits;
		o->bits >>= 8;
		o->nbits -= 8;
	}
}

/* A Huffman code of len bits: deflate sends its most significant bit first. */
static void put_code(out_buf *o, uint32_t code, int len)
{
	uint32_t r = 0;
	for (int i = 0; i < len; ++i)
		r |= ((code >> i) & 1u) << (len - 1 - i);
	put_bits(o, r, len);
}

/* The fixed literal/length code (RFC 1951 3.2.6). */
static void put_symbol(out_buf *o, int sym)
{
	if (sym < 144)
		put_code(o, 0x30u + (uint32_t)sym, 8);
	else if (sym < 256)
		put_code(o, 0x190u + (uint32_t)(sym - 144), 9);
	else if (sym < 280)
		put_code(o, (uint32_t)(sym - 256), 7);
	else
		put_code(o, 0xc0u + (uint32_t)(sym - 280), 8);
}

/* A copy of len (3..258) bytes from distance 1. */
static void put_copy1(out_buf *o, int len)
{
	static const short base[29] = {3,  4,  5,  6,  7,  8,  9,  10, 11,  13,  15,  17,  19,  23, 27,
	                               31, 35, 43, 51, 59, 67, 83, 99, 115, 131, 163, 195, 227, 258};
	static const unsigned char extra[29] = {0, 0, 0, 0, 0, 0, 0, 0, 1, 1, 1, 1, 2, 2, 2,
	                                        2, 3, 3, 3, 3, 4, 4, 4, 4, 5, 5, 5, 5, 0};
	int k = 28;
	while (base[k] > len)
		--k;
	put_symbol(o, 257 + k);
	if (extra[k])
		put_bits(o, (uint32_t)(len - base[k]), extra[k]);
	put_code(o, 0, 5); /* distance code 0: distance 1 */
}

/* rows rows of `filter` followed by `zeros` zero bytes, as one fixed-Huffman
 * block and an empty stored block (back on a byte boundary). */
static int put_run(out_buf *o, int rows, int filter, int zeros)
{
	/* per row at most 2 literals, a copy per 258 bytes and a remainder; 4 bytes each is ample */
	const size_t per_row = 4u * (size_t)(4 + zeros / 258);
	int err = reserve(o, (size_t)rows * per_row + 16);
	if (err)
		return err;
	put_bits(o, 0, 1); /* not the last block */
	put_bits(o, 1, 2); /* fixed Huffman codes */
	for (int r = 0; r < rows; ++r) {
		put_symbol(o, filter);
		int left = zeros;
		if (left > 0) {
			put_symbol(o, 0);
			--left;
		}
		while (left > 0) {
			if (left < 3) {
				put_symbol(o, 0);
				--left;
				continue;
			}
			/* leave no remainder of 1 or 2 behind a full copy */
			int len = left <= 258 ? left : left - 258 < 3 ? left - 3 : 258;
			put_copy1(o, len);
			left -= len;
		}
	}
	put_symbol(o, 256); /* end of block */
	put_bits(o, 0, 3);  /* a stored block, not the last */
	if (o->nbits > 0)
		put_bits(o, 0, 8 - o->nbits);
	const uint8_t stored[4] = {0, 0, 0xff, 0xff}; /* LEN 0, NLEN */
	memcpy(o->p + o->n, stored, 4);
	o->n += 4;
	return 0;
}

/* Runs deflate over its input with flush, growing o as needed. */
static int run_deflate(z_stream *z, out_buf *o, int flush)
{
	for (;;) {
		if (o->cap - o->n < 4096 && reserve(o, 65536) != 0)
			return ENOMEM;
		z->next_out = o->p + o->n;
		z->avail_out = (uInt)(o->cap - o->n);
		const int rc = deflate(z, flush);
		o->n = o->cap - z->avail_out;
		if (rc == Z_STREAM_END)
			return 0;
		if (rc != Z_OK && rc != Z_BUF_ERROR)
			return EIO;
		/* done when the input is used up and deflate had output room left */
		if (z->avail_in == 0 && z->avail_out > 0)
			return 0;
	}
}

/* Adler-32 of a row of filter byte f and n zero bytes. */
static uint32_t adler_blank_row(uint32_t adler, int f, int n)
{
	uint64_t a = adler & 0xffffu, b = adler >> 16;
	a = (a + (uint64_t)f) % ADLER_MOD;
	b = (b + a) % ADLER_MOD;
	b = (b + (uint64_t)n % ADLER_MOD * a) % ADLER_MOD;
	return (uint32_t)(b << 16 | a);
}

static void be32(uint8_t *p, uint32_t v)
{
	p[0] = (uint8_t)(v >> 24), p[1] = (uint8_t)(v >> 16), p[2] = (uint8_t)(v >> 8), p[3] = (uint8_t)v;
}

static void write_chunk(eddy_file *f, const char type[4], const uint8_t *data, size_t n)
{
	uint8_t head[8];
	be32(head, (uint32_t)n);
	memcpy(head + 4, type, 4);
	uLong crc = crc32(0, (const Bytef *)type, 4);
	size_t done = 0;
	while (done < n) { /* crc32 takes a uInt length */
		const size_t part = n - done > (1u << 30) ? (1u << 30) : n - done;
		crc = crc32(crc, data + done, (uInt)part);
		done += part;
	}
	uint8_t tail[4];
	be32(tail, (uint32_t)crc);
	eddy_file_write(f, head, 8);
	if (n > 0)
		eddy_file_write(f, data, n);
	eddy_file_write(f, tail, 4);
}

/* The zlib stream of the filtered rows into o; 0 or an errno value. */
static int compress_rows(out_buf *o, int width, int height, const uint8_t *rgb, uint32_t *adler_out)
{
	const size_t stride = (size_t)width * 3;
	uint8_t *row = malloc(stride + 1);
	z_stream z;
	memset(&z, 0, sizeof z);
	if (!row || deflateInit2(&z, 1, Z_DEFLATED, -15, 8, Z_RLE) != Z_OK) {
		free(row);
		return ENOMEM;
	}
	int err = reserve(o, deflateBound(&z, (uLong)((stride + 1) * (size_t)height)) / 2 + 64);
	uint32_t adler = 1;
	if (!err) {
		o->p[o->n++] = 0x78; /* deflate, 32 KiB window */
		o->p[o->n++] = 0x01; /* fastest level; (0x78 * 256 + 0x01) % 31 == 0 */
	}
	int run = 0; /* rows equal to the one above, not yet written */
	for (int y = 0; y <= height && !err; ++y) {
		const uint8_t *cur = rgb + (size_t)y * stride;
		const int same = y > 0 && y < height && memcmp(cur, cur - stride, stride) == 0;
		if (same) {
			++run;
			continue;
		}
		if (run >= MIN_RUN) {
			/* zlib's block ends and its history goes: nothing after refers into the run */
			err = run_deflate(&z, o, Z_FULL_FLUSH);
			if (!err)
				err = put_run(o, run, 2, (int)stride);
			for (int r = 0; r < run && !err; ++r)
				adler = adler_blank_row(adler, 2, (int)stride);
			run = 0;
		}
		while (run > 0 && !err) { /* a short run: through zlib like any row */
			row[0] = 2;
			memset(row + 1, 0, stride);
			adler = (uint32_t)adler32(adler, row, (uInt)(stride + 1));
			z.next_in = row;
			z.avail_in = (uInt)(stride + 1);
			err = run_deflate(&z, o, Z_NO_FLUSH);
			--run;
		}
		if (y == height || err)
			break;
		/* up: the difference to the row above (the first row's is itself) */
		row[0] = 2;
		if (y == 0)
			memcpy(row + 1, cur, stride);
		else {
			const uint8_t *restrict up = cur - stride;
			uint8_t *restrict f = row + 1;
			for (size_t i = 0; i < stride; ++i)
				f[i] = (uint8_t)(cur[i] - up[i]);
		}
		adler = (uint32_t)adler32(adler, row, (uInt)(stride + 1));
		z.next_in = row;
		z.avail_in = (uInt)(stride + 1);
		err = run_deflate(&z, o, Z_NO_FLUSH);
	}
	if (!err)
		err = run_deflate(&z, o, Z_FINISH);
	deflateEnd(&z);
	free(row);
	*adler_out = adler;
	return err;
}

static int encode(eddy_file *f, int width, int height, const uint8_t *rgb)
{
	static const uint8_t signature[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
	uint8_t ihdr[13];
	be32(ihdr, (uint32_t)width);
	be32(ihdr + 4, (uint32_t)height);
	ihdr[8] = 8;  /* bits per sample */
	ihdr[9] = 2;  /* RGB */
	ihdr[10] = 0; /* deflate */
	ihdr[11] = 0; /* adaptive filtering (each row says its filter) */
	ihdr[12] = 0; /* not interlaced */
	out_buf o = {NULL, 0, 0, 0, 0};
	uint32_t adler = 1;
	int err = compress_rows(&o, width, height, rgb, &adler);
	if (!err)
		err = reserve(&o, 4);
	if (!err) {
		be32(o.p + o.n, adler);
		o.n += 4;
		eddy_file_write(f, signature, sizeof signature);
		write_chunk(f, "IHDR", ihdr, sizeof ihdr);
		write_chunk(f, "IDAT", o.p, o.n);
		write_chunk(f, "IEND", NULL, 0);
	}
	free(o.p);
	return err;
}

int eddy_write_png(const char *path, int width, int height, const uint8_t *rgb)
{
	if (width < 1 || height < 1)
		return EINVAL;
	eddy_file f;
	if (eddy_file_begin(&f, path) != 0)
		return f.err;
	/* encoding fails only for memory; write errors are f's */
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
