/* SPDX-License-Identifier: MIT */
/* PNG writing: RGB, 8 bits, every row "up"-filtered, the deflate stream
 * (RFC 1951) made here by run-length matching with dynamic Huffman codes,
 * in the zlib wrapper (RFC 1950) and the PNG chunks (PNG specification, 2nd
 * edition, ISO/IEC 15948); zlib computes the checksums.
 *
 * A rendered frame is mostly runs: the background, flat-shaded sprite
 * interiors, rows repeating the row above, which the up filter turns into
 * zeros. The matcher is zlib's Z_RLE strategy (a run of the previous byte,
 * 3 to 258 long, is a copy from distance 1; anything else a literal), but a
 * run is measured eight bytes at a time, so the background costs almost
 * nothing. Each block of up to BLOCK_TOKENS tokens gets its own Huffman code
 * (lengths limited to 15 bits, the code-length code to 7), as zlib's blocks
 * do, so the files come out about as large as zlib's Z_RLE at level 1.
 *
 * Measured on a pour-sized frame (960x540; CPU ms per frame and bytes,
 * `make bench-render` prints the current figures under "encoders"): zlib at
 * level 1 with Z_RLE through libpng about 8 ms and 197 kB, this writer about
 * 4 ms and 200 kB.
 *
 * The bytes go through eddy_file, so a failed write leaves no PNG. */
#include "render.h"

#include <errno.h>
#include <stdlib.h>
#include <string.h>
#include <zlib.h>

#define BLOCK_TOKENS 65536
#define LITLEN 286 /* literal/length symbols: 0-255, end of block 256, lengths 257-285 */
#define MAX_BITS 15
#define CL_SYMBOLS 19
#define CL_MAX_BITS 7

typedef struct bits {
	uint8_t *p; /* room checked by the caller */
	uint64_t acc;
	int n;
} bits;

static void put(bits *b, uint32_t v, int n)
{
	b->acc |= (uint64_t)v << b->n;
	b->n += n;
	if (b->n >= 32) {
		const uint32_t w = (uint32_t)b->acc;
		b->p[0] = (uint8_t)w, b->p[1] = (uint8_t)(w >> 8), b->p[2] = (uint8_t)(w >> 16), b->p[3] = (uint8_t)(w >> 24);
		b->p += 4;
		b->acc >>= 32;
		b->n -= 32;
	}
}

/* The remaining bits, padded with zeros to a byte. */
static void flush_bits(bits *b)
{
	while (b->n > 0) {
		*b->p++ = (uint8_t)b->acc;
		b->acc >>= 8;
		b->n -= 8;
	}
	b->n = 0;
	b->acc = 0;
}

static const short len_base[29] = {3,  4,  5,  6,  7,  8,  9,  10, 11,  13,  15,  17,  19,  23, 27,
                                   31, 35, 43, 51, 59, 67, 83, 99, 115, 131, 163, 195, 227, 258};
static const unsigned char len_extra[29] = {0, 0, 0, 0, 0, 0, 0, 0, 1, 1, 1, 1, 2, 2, 2,
                                            2, 3, 3, 3, 3, 4, 4, 4, 4, 5, 5, 5, 5, 0};

/* Huffman code lengths for freq[0..n) (0 for unused symbols), none longer
 * than max_bits, the code complete (Kraft sum exactly 1: inflate rejects
 * incomplete codes). At least two symbols must be used. */
static void code_lengths(const uint32_t *freq, int n, int max_bits, uint8_t *len)
{
	/* Huffman's construction on the used symbols, sorted by frequency (two
	 * queues: leaves in order, internal nodes made in order) */
	int sym[LITLEN];
	uint64_t w[2 * LITLEN];
	int parent[2 * LITLEN];
	int m = 0;
	for (int i = 0; i < n; ++i) {
		len[i] = 0;
		if (freq[i])
			sym[m++] = i;
	}
	/* insertion sort by frequency (n <= 286), ties by symbol: deterministic */
	for (int i = 1; i < m; ++i) {
		const int s = sym[i];
		int j = i;
		while (j > 0 && freq[sym[j - 1]] > freq[s])
			sym[j] = sym[j - 1], --j;
		sym[j] = s;
	}
	for (int i = 0; i < m; ++i)
		w[i] = freq[sym[i]];
	int leaf = 0, node = m, made = m;
	for (int k = 0; k < m - 1; ++k) {
		int pick[2];
		for (int t = 0; t < 2; ++t) {
			if (leaf < m && (node >= made || w[leaf] <= w[node]))
				pick[t] = leaf++;
			else
				pick[t] = node++;
		}
		w[made] = w[pick[0]] + w[pick[1]];
		parent[pick[0]] = parent[pick[1]] = made;
		++made;
	}
	/* depths: the root is made - 1; parents come after their children */
	int depth[2 * LITLEN];
	depth[made - 1] = 0;
	for (int i = made - 2; i >= 0; --i)
		depth[i] = depth[parent[i]] + 1;
	for (int i = 0; i < m; ++i)
		len[sym[i]] = (uint8_t)depth[i];
	/* limit: clamp, then lengthen the longest codes under the limit until
	 * the Kraft sum fits, then shorten codes while it stays <= 1 */
	int64_t kraft = 0;
	const int64_t one = (int64_t)1 << max_bits;
	for (int i = 0; i < n; ++i)
		if (len[i]) {
			len[i] = len[i] > max_bits ? (uint8_t)max_bits : len[i];
			kraft += (int64_t)1 << (max_bits - len[i]);
		}
	while (kraft > one) {
		/* the least frequent symbol under the limit gets a bit longer */
		int best = -1;
		for (int i = 0; i < m; ++i) {
			const int s = sym[i];
			if (len[s] < max_bits) {
				best = s;
				break;
			}
		}
		kraft -= (int64_t)1 << (max_bits - len[best] - 1);
		len[best]++;
	}
	while (kraft < one) {
		/* the most frequent symbol whose shortening still fits */
		int done = 1;
		for (int i = m - 1; i >= 0; --i) {
			const int s = sym[i];
			if (len[s] > 1 && kraft + ((int64_t)1 << (max_bits - len[s])) <= one) {
				kraft += (int64_t)1 << (max_bits - len[s]);
				len[s]--;
				done = 0;
				break;
			}
		}
		if (done)
			break;
	}
	if (kraft != one) {
		/* not reached in practice; a flat code is always complete: every
		 * used symbol ceil(log2 m) bits, then 2^L - m of them one shorter */
		int L = 1;
		while ((1 << L) < m)
			++L;
		for (int i = 0; i < m; ++i)
			len[sym[i]] = (uint8_t)(i < (1 << L) - m ? L - 1 : L);
	}
}

/* Canonical codes for lengths (RFC 1951 3.2.2), bit-reversed for put(). */
static void canonical(const uint8_t *len, int n, uint16_t *code)
{
	int count[MAX_BITS + 1] = {0};
	for (int i = 0; i < n; ++i)
		count[len[i]]++;
	count[0] = 0;
	int next[MAX_BITS + 2];
	int c = 0;
	for (int b = 1; b <= MAX_BITS; ++b) {
		c = (c + count[b - 1]) << 1;
		next[b] = c;
	}
	for (int i = 0; i < n; ++i) {
		if (!len[i])
			continue;
		const unsigned v = (unsigned)next[len[i]]++;
		unsigned r = 0;
		for (int k = 0; k < len[i]; ++k)
			r |= ((v >> k) & 1u) << (len[i] - 1 - k);
		code[i] = (uint16_t)r;
	}
}

/* Makes sure at least two symbols are used (a complete code needs two). */
static void two_used(uint32_t *freq, int n)
{
	int used = 0;
	for (int i = 0; i < n && used < 2; ++i)
		used += freq[i] != 0;
	for (int i = 0; used < 2 && i < n; ++i)
		if (!freq[i])
			freq[i] = 1, ++used;
}

/* One block of tokens (a literal byte v < 256, or a copy of v - 256 bytes
 * from distance 1), with its dynamic Huffman codes. */
static void put_block(bits *b, const uint16_t *tok, size_t n, bool last)
{
	uint32_t freq[LITLEN] = {0};
	for (size_t i = 0; i < n; ++i) {
		const int t = tok[i];
		if (t < 256)
			freq[t]++;
		else {
			int k = 28;
			while (len_base[k] > t - 256)
				--k;
			freq[257 + k]++;
		}
	}
	freq[256] = 1;
	two_used(freq, LITLEN);
	uint8_t len[LITLEN + 2];
	uint16_t code[LITLEN + 2];
	code_lengths(freq, LITLEN, MAX_BITS, len);
	canonical(len, LITLEN, code);
	int hlit = LITLEN;
	while (hlit > 257 && len[hlit - 1] == 0)
		--hlit;
	/* two distance codes of one bit: code 0 (distance 1) and an unused 1, so the code is complete */
	len[hlit] = 1, len[hlit + 1] = 1;
	/* the code lengths, run-length coded (16: repeat 3-6, 17: 3-10 zeros, 18: 11-138 zeros) */
	uint8_t cl[LITLEN + 2], cl_extra[LITLEN + 2];
	int ncl = 0;
	const int total = hlit + 2;
	for (int i = 0; i < total;) {
		int r = 1;
		while (i + r < total && len[i + r] == len[i])
			++r;
		if (len[i] == 0 && r >= 3) {
			const int k = r > 138 ? 138 : r;
			cl[ncl] = k >= 11 ? 18 : 17;
			cl_extra[ncl++] = (uint8_t)(k >= 11 ? k - 11 : k - 3);
			i += k;
		} else if (len[i] != 0 && r >= 4) {
			cl[ncl] = len[i], cl_extra[ncl++] = 0;
			const int k = r - 1 > 6 ? 6 : r - 1;
			cl[ncl] = 16, cl_extra[ncl++] = (uint8_t)(k - 3);
			i += 1 + k;
		} else {
			cl[ncl] = len[i], cl_extra[ncl++] = 0;
			++i;
		}
	}
	uint32_t cfreq[CL_SYMBOLS] = {0};
	for (int i = 0; i < ncl; ++i)
		cfreq[cl[i]]++;
	two_used(cfreq, CL_SYMBOLS);
	uint8_t clen[CL_SYMBOLS];
	uint16_t ccode[CL_SYMBOLS];
	code_lengths(cfreq, CL_SYMBOLS, CL_MAX_BITS, clen);
	canonical(clen, CL_SYMBOLS, ccode);
	static const uint8_t order[CL_SYMBOLS] = {16, 17, 18, 0, 8, 7, 9, 6, 10, 5, 11, 4, 12, 3, 13, 2, 14, 1, 15};
	int hclen = CL_SYMBOLS;
	while (hclen > 4 && clen[order[hclen - 1]] == 0)
		--hclen;
	put(b, last ? 1 : 0, 1);
	put(b, 2, 2); /* dynamic Huffman codes */
	put(b, (uint32_t)(hlit - 257), 5);
	put(b, 1, 5); /* HDIST: 2 distance codes */
	put(b, (uint32_t)(hclen - 4), 4);
	for (int i = 0; i < hclen; ++i)
		put(b, clen[order[i]], 3);
	for (int i = 0; i < ncl; ++i) {
		put(b, ccode[cl[i]], clen[cl[i]]);
		if (cl[i] == 16)
			put(b, cl_extra[i], 2);
		else if (cl[i] == 17)
			put(b, cl_extra[i], 3);
		else if (cl[i] == 18)
			put(b, cl_extra[i], 7);
	}
	/* the tokens; a copy's distance is code 0 of one bit: a 0 */
	for (size_t i = 0; i < n; ++i) {
		const int t = tok[i];
		if (t < 256) {
			put(b, code[t], len[t]);
			continue;
		}
		const int l = t - 256;
		int k = 28;
		while (len_base[k] > l)
			--k;
		put(b, code[257 + k], len[257 + k]);
		if (len_extra[k])
			put(b, (uint32_t)(l - len_base[k]), len_extra[k]);
		put(b, 0, 1);
	}
	put(b, code[256], len[256]);
}

/* The length of the run of byte c from p, at most max. */
static size_t run_of(const uint8_t *p, uint8_t c, size_t max)
{
	const uint64_t pat = 0x0101010101010101ull * c;
	size_t r = 0;
	while (r + 8 <= max) {
		uint64_t w;
		memcpy(&w, p + r, 8);
		const uint64_t x = w ^ pat;
		if (x) /* little-endian: the first differing byte is the lowest set one */
			return r + (size_t)(__builtin_ctzll(x) >> 3);
		r += 8;
	}
	while (r < max && p[r] == c)
		++r;
	return r;
}

/* The zlib stream (header, deflate blocks, Adler-32) of data[0..n) into out,
 * which holds 2 n + 1024 bytes and 320 per block; returns its length. */
static size_t deflate_rle(const uint8_t *data, size_t n, uint16_t *tok, uint8_t *out)
{
	bits b = {out, 0, 0};
	put(&b, 0x78, 8); /* deflate, 32 KiB window */
	put(&b, 0x01, 8); /* fastest; (0x78 * 256 + 0x01) % 31 == 0 */
	size_t p = 0;
	do {
		size_t t = 0;
		while (p < n && t < BLOCK_TOKENS) {
			if (p > 0) {
				const size_t max = n - p < 258 ? n - p : 258;
				const size_t r = run_of(data + p, data[p - 1], max);
				if (r >= 3) {
					tok[t++] = (uint16_t)(256 + r);
					p += r;
					continue;
				}
			}
			tok[t++] = data[p++];
		}
		put_block(&b, tok, t, p >= n);
	} while (p < n);
	flush_bits(&b);
	/* crc32 and adler32 take uInt lengths */
	uLong adler = adler32(0, NULL, 0);
	for (size_t done = 0; done < n;) {
		const size_t part = n - done > (1u << 30) ? (1u << 30) : n - done;
		adler = adler32(adler, data + done, (uInt)part);
		done += part;
	}
	const uint32_t a = (uint32_t)adler;
	b.p[0] = (uint8_t)(a >> 24), b.p[1] = (uint8_t)(a >> 16), b.p[2] = (uint8_t)(a >> 8), b.p[3] = (uint8_t)a;
	b.p += 4;
	return (size_t)(b.p - out);
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
	for (size_t done = 0; done < n;) {
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

static int encode(eddy_file *f, int width, int height, const uint8_t *rgb)
{
	static const uint8_t signature[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
	const size_t stride = (size_t)width * 3, n = (stride + 1) * (size_t)height;
	/* a literal costs at most 15 bits, a copy of >= 3 bytes at most
	 * 15 + 5 + 1, a block header under 320 bytes */
	const size_t cap = 2 * n + 1024 + (n / BLOCK_TOKENS + 1) * 320;
	uint8_t *filtered = malloc(n), *out = malloc(cap);
	uint16_t *tok = malloc(BLOCK_TOKENS * sizeof *tok);
	if (!filtered || !out || !tok) {
		free(filtered), free(out), free(tok);
		return ENOMEM;
	}
	/* up: each row less the row above (the first row's is itself) */
	for (int y = 0; y < height; ++y) {
		uint8_t *restrict o = filtered + (size_t)y * (stride + 1);
		const uint8_t *restrict cur = rgb + (size_t)y * stride;
		o[0] = 2;
		if (y == 0)
			memcpy(o + 1, cur, stride);
		else {
			const uint8_t *restrict up = cur - stride;
			for (size_t i = 0; i < stride; ++i)
				o[1 + i] = (uint8_t)(cur[i] - up[i]);
		}
	}
	const size_t zn = deflate_rle(filtered, n, tok, out);
	uint8_t ihdr[13];
	be32(ihdr, (uint32_t)width);
	be32(ihdr + 4, (uint32_t)height);
	ihdr[8] = 8;  /* bits per sample */
	ihdr[9] = 2;  /* RGB */
	ihdr[10] = 0; /* deflate */
	ihdr[11] = 0; /* adaptive filtering (each row says its filter) */
	ihdr[12] = 0; /* not interlaced */
	eddy_file_write(f, signature, sizeof signature);
	write_chunk(f, "IHDR", ihdr, sizeof ihdr);
	write_chunk(f, "IDAT", out, zn);
	write_chunk(f, "IEND", NULL, 0);
	free(filtered), free(out), free(tok);
	return 0;
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
