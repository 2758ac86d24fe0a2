/* SPDX-License-Identifier: MIT */
/* Per-step scratch: a chain of blocks handed out by bumping a pointer. Reset
 * keeps the largest block and drops the rest, so after the first steps a scene
 * settles on one block and a step allocates nothing from the system. */
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
		size_t size = b ? b->size * 2 : 64 * 1024;
		while (size < bytes)
			size *= 2;
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
	return p;
}

void eddy__arena_reset(eddy_arena *a)
{
	eddy_arena_block *b = a->head;
	if (!b)
		return;
	/* the head is the newest and largest block */
	eddy_arena_block *rest = b->next;
	while (rest) {
		eddy_arena_block *n = rest->next;
		free(rest);
		rest = n;
	}
	b->next = NULL;
	b->used = 0;
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
	/* blocks chained since the mark: keep the newest (the largest) empty in
	 * front of the marked one, free those between */
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
