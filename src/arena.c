/* SPDX-License-Identifier: MIT */
/* Per-step scratch: a chain of blocks handed out by bumping a pointer. A new
 * block is sized to the request (at least a quarter of what is in use, so a
 * run of small requests does not chain many), not doubled: the chain's
 * untouched slack would count in the peak resident memory at a million
 * particles. Reset leaves one block of the last step's peak use, so after the
 * first step a scene settles on one block and a step allocates nothing from
 * the system. */
#include "core.h"

#include <stdlib.h>

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
		eddy_arena_block *nb = malloc(sizeof *nb + size);
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
		free(b);
		b = n;
	}
	a->head = malloc(sizeof *a->head + peak);
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
		free(b);
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
		free(rest);
		rest = n;
	}
	b->next = rest;
	b->used = 0;
	if (rest)
		rest->used = m.used;
}
