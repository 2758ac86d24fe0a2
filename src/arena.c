/* SPDX-License-Identifier: MIT */
/* Per-step scratch: a chain of blocks handed out by bumping a pointer. A new
 * block is sized to the request (at least a quarter of what is in use, so a
 * run of small requests does not chain many), not doubled: the chain's
 * untouched slack would count in the peak resident memory at a million
 * particles. Reset leaves one block of the last step's peak use, so after the
 * first step a scene settles on one block and a step allocates nothing from
 * the system. The blocks come from eddy__pages_alloc (below), so the ones
 * a reset drops go back to the system.
 *
 * eddy__pages_alloc: large blocks mapped from the system directly, so that
 * freeing one returns its memory whatever malloc's settings. A library in
 * the process may turn malloc's own mapping of large blocks off (HYPRE
 * loads libsuperlu_dist, whose initialiser sets M_MMAP_MAX to 0): then
 * every large block freed stays resident in the heap, and the arena's
 * first-step chain alone left some 50 bytes a particle resident at a
 * million particles. Under AddressSanitizer they come from malloc, which
 * it checks. */
#define _DEFAULT_SOURCE /* MAP_ANONYMOUS */
#include "core.h"

#include <stdlib.h>

#if defined(__has_feature)
#if __has_feature(address_sanitizer)
#define EDDY_PAGES_MALLOC 1
#endif
#endif
#if defined(__SANITIZE_ADDRESS__) || !defined(__unix__)
#define EDDY_PAGES_MALLOC 1
#endif

#ifndef EDDY_PAGES_MALLOC
#include <sys/mman.h>

/* The mapping's size, in front of the block (64 bytes: the block stays
 * aligned for any vector load). */
#define PAGES_HEAD 64

void *eddy__pages_alloc(size_t bytes)
{
	if (bytes > SIZE_MAX - PAGES_HEAD)
		return NULL;
	const size_t size = bytes + PAGES_HEAD;
	void *m = mmap(NULL, size, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
	if (m == MAP_FAILED)
		return NULL;
	*(size_t *)m = size;
	return (unsigned char *)m + PAGES_HEAD;
}

void eddy__pages_free(void *p)
{
	if (!p)
		return;
	unsigned char *m = (unsigned char *)p - PAGES_HEAD;
	munmap(m, *(size_t *)(void *)m);
}
#else
void *eddy__pages_alloc(size_t bytes) { return malloc(bytes ? bytes : 1); }
void eddy__pages_free(void *p) { free(p); }
#endif

struct eddy_arena_block {
	eddy_arena_block *next;
	size_t size, used;
	_Alignas(16) unsigned char mem[];
};

void *eddy__arena_alloc(eddy_arena *a, size_t bytes)
{
	bytes = (bytes + 15) & ~(size_t)15;
	eddy_arena_block *b = a->head;
	if (!b || b->size - b->used < bytes) {
		size_t used = 0;
		for (eddy_arena_block *q = b; q; q = q->next)
			used += q->used;
		size_t size = bytes > used / 4 ? bytes : used / 4;
		size = size < 64 * 1024 ? 64 * 1024 : (size + 65535) & ~(size_t)65535;
		eddy_arena_block *nb = eddy__pages_alloc(sizeof *nb + size);
		if (!nb)
			return NULL;
		nb->next = b;
		nb->size = size;
		nb->used = 0;
		a->head = b = nb;
	}
	void *p = b->mem + b->used;
	b->used += bytes;
	size_t total = 0;
	for (eddy_arena_block *q = a->head; q; q = q->next)
		total += q->used;
	if (total > a->high_water)
		a->high_water = total;
	if (total > a->step_peak)
		a->step_peak = total;
	return p;
}

void eddy__arena_reset(eddy_arena *a)
{
	eddy_arena_block *b = a->head;
	const size_t peak = (a->step_peak + 65535) & ~(size_t)65535;
	a->step_peak = 0;
	if (!b)
		return;
	if (!b->next && b->size >= peak) {
		b->used = 0;
		return;
	}
	/* several blocks: one of the peak's size instead (if that fails, the
	 * next request allocates as it can) */
	while (b) {
		eddy_arena_block *n = b->next;
		eddy__pages_free(b);
		b = n;
	}
	a->head = eddy__pages_alloc(sizeof *a->head + peak);
	if (a->head) {
		a->head->next = NULL;
		a->head->size = peak;
		a->head->used = 0;
	}
}

void eddy__arena_free(eddy_arena *a)
{
	eddy_arena_block *b = a->head;
	while (b) {
		eddy_arena_block *n = b->next;
		eddy__pages_free(b);
		b = n;
	}
	a->head = NULL;
}

/* Blocks are only ever added in front of the marked one until the release,
 * which therefore finds it in the chain. */
eddy_arena_mark eddy__arena_mark(const eddy_arena *a)
{
	eddy_arena_mark m = {a->head, a->head ? a->head->used : 0};
	return m;
}

void eddy__arena_release(eddy_arena *a, eddy_arena_mark m)
{
	eddy_arena_block *b = a->head;
	if (!b)
		return;
	if (b == m.head) {
		b->used = m.used;
		return;
	}
	/* blocks chained since the mark: keep the newest (it was sized for
	 * this system's requests) empty in front of the marked one, free those
	 * between */
	eddy_arena_block *rest = b->next;
	while (rest && rest != m.head) {
		eddy_arena_block *n = rest->next;
		eddy__pages_free(rest);
		rest = n;
	}
	b->next = rest;
	b->used = 0;
	if (rest)
		rest->used = m.used;
}
