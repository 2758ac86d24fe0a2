/* SPDX-License-Identifier: MIT */
/* The SPH folder's shared header: kernel constants, the neighbour data
 * sph_density builds each step for the later SPH passes, their helpers.
 *   grid.c search.c neighbors.c  cells, grid search, Verlet list (neighbors.h)
 *   boundary.c boundary_box.c    boundary particles of walls and colliders
 *   kernels.c                    the kernels and their lattice sums
 *   density.c pressure.c viscosity.c surface_tension.c dfsph.c: the systems
 *   dfsph_coarse.c               dfsph.c's coarse level (multigrid on cells)
 * A new pair pass (XSPH, say) is one new file plus the registry:
 *   1. src/sph/xsph.c: under #ifndef EDDY_SIMD_VARIANT its def, add
 *      function and step; outside it, the pair loop once against
 *      ../simd.h as SIMD_NAME(xsph_pair_sums) over sph_shared's lists and
 *      quads, picked with SIMD_PICK and run with sph_block_pass (below).
 *      The Makefile builds an AVX2 variant of any file including simd.h.
 *   2. the registry: its vtable in systems.h, def and add function in
 *      eddy.h, Lua binding; .requires = EDDY_CAP_SPH_NEIGHBORS. */
#ifndef EDDY_SPH_H
#define EDDY_SPH_H

#include "core.h"
#include "simd.h"

#ifndef M_PI
#define M_PI 3.14159265358979323846
#endif

/* Kernel constants for support h (3D, Mueller 2003; sph_density sets them). */
typedef struct sph_kernel_consts {
	float h, h2;
	float poly6;      /* 315/(64 pi h^9) */
	float poly6_grad; /* -6 * poly6: grad W = poly6_grad (h^2-r^2)^2 r_vec */
	float spiky_grad; /* -45/(pi h^6): dW/dr = spiky_grad (h-r)^2 */
	float visc_lap;   /* 45/(pi h^6): lap W = visc_lap (h-r) */
} sph_kernel_consts;

/* Neighbour lists, made by sph_density every step (neighbors.c): particle
 * i's fluid neighbours (itself excluded, r < h exactly, ascending index),
 * count[i] of them, are packed in groups of eight from sph_nbr_groups(nb, i)
 * (read with sph_group_next, below); its boundary neighbours (r < h,
 * ascending) are sph_bnbrs(nb, i)[0 .. bcount[i]), indexing the boundary
 * arrays. Valid for the step that made them (the particle table is then in
 * grid-cell order). The sub-structs are private to the search's files
 * (neighbors.h); the passes read only the lists and the boundary arrays. */

/* Lists of varying length packed in one array (the exact lists, the Verlet
 * candidates): list k starts at data[first[k]] and holds its count of
 * entries (the fluid ones packed in groups: sph_group_next, below; first
 * and the sizes in 4-byte words), with first and the counts beside the
 * owner's other per-row arrays. A pass hands out the array in chunks
 * (sph_list_room in neighbors.h) from the front, so
 * only what the lists hold (and a chunk's tail per chunk) is ever written:
 * the pages of data beyond that stay untouched, not resident. Where each
 * list lands depends on the threads' timing; what it holds does not. */
typedef struct sph_lists {
	uint32_t *data;
	size_t alloc; /* entries of data */
	size_t used;  /* entries handed out by the last pass */
} sph_lists;

/* Where each cell's entries start in a table in cell order (grid.c). Per
 * row of cells along x: its first entry (32 bits), and its runs of cells
 * holding entries (two such cells at most SPH_CELL_GAP empty ones apart
 * share a run), each cell of a run with its start as a 16-bit offset from
 * the row's: 2 bytes an occupied cell, nothing for the empty stretches (the
 * grid spans the world bounds: most of its cells are empty, and a row
 * crossing a box's walls holds two short runs). While some row of cells
 * holds more than 65535 entries, every cell's start whole instead (wide, 4
 * bytes a cell). Read with sph_cell_start (neighbors.h). */
typedef struct sph_cell_run {
	uint32_t x0, x1; /* the run's cells [x0, x1) along its row; x0 and x1 - 1 hold entries */
	uint32_t at;     /* off[at + x - x0]: cell x's start less its row's */
} sph_cell_run;
typedef struct sph_cell_starts {
	uint32_t *base;   /* rows of cells + 1: the first entry of each row; the last the table's size */
	uint32_t *run_at; /* rows of cells + 1: row r's runs are run[run_at[r] .. run_at[r + 1]) */
	sph_cell_run *run;
	uint16_t *off;
	size_t run_alloc, off_alloc; /* entries of run and off */
	uint32_t *wide;              /* cells + 1: cell c's first entry; NULL while the offsets hold */
} sph_cell_starts;

/* The cell grid (grid.c) */
typedef struct sph_grid {
	float ox, oy, oz;            /* m, the low corner of cell 0 */
	float inv_cell;              /* 1/m, 1 / the cell size */
	int gx, gy, gz;              /* cells along each axis, x fastest */
	sph_cell_starts fluid_start; /* the rows of each cell, the table in cell order */
	sph_cell_starts bound_start; /* the same over the boundary particles in cell order */
} sph_grid;

/* The Verlet list (neighbors.c): the pairs closer than h (1 + skin) at the
 * last search, in the rows of that time ("build slots"), reused while no
 * particle has moved more than half the skin since. It changes how fast the
 * exact lists are made, never what they hold. */
typedef struct sph_verlet {
	size_t n;                   /* particles at the last search; 0: none since the table was empty */
	sph_lists cand, bcand;      /* slot s's candidates, ascending: fluid (build slots) and boundary */
	uint32_t *first, *bfirst;   /* per slot: where its lists start in cand, bcand */
	uint32_t *count, *bcount;   /* per slot */
	uint32_t longest;           /* the most candidates of any slot, fluid or boundary */
	float *x, *y, *z;           /* m, each slot's position at the search */
	uint32_t *slot_of, *row_of; /* build slot of each row, row of each build slot */
	uint64_t boundary_sig;      /* the boundary systems at the search */
	float skin;         /* 1, of h (SPH_SKIN in neighbors.h); 0: the search wrote the exact lists, no candidates */
	int age;            /* steps since the search */
	bool rows_moved;    /* a permutation since the search: row_of is not the identity */
	bool count_changed; /* the search was forced by a new particle count */
} sph_verlet;

/* The boundary particles' private part (boundary.c): those of every
 * sph_boundary_box first (static, cell-sorted, n_static of them), then
 * those of the colliders, moving with them. */
typedef struct sph_boundary {
	size_t n_static;
	float *rho;   /* kg/m^3, EOS density for bp; in bp's block */
	uint64_t sig; /* the boundary systems the arrays were built from */
	/* with collider particles (nbound > n_static), else NULL: */
	uint32_t *order;     /* boundary indices in cell order at the last search */
	float *x0, *y0, *z0; /* m, collider particles in their collider's def pose */
	float *vx, *vy, *vz; /* m/s, each particle's velocity this step (0 for the static ones) */
	size_t div_alloc;    /* bdiv's */
	int ncol;
	struct sph_collider_set {
		int slot;                /* pipeline slot of the collider */
		size_t first, count;     /* its particles */
		eddy_vec3 normal;        /* a plane's: only the offset along it moves them; 0 otherwise */
		eddy_vec3 disp;          /* m, their displacement from the def pose now */
		eddy_vec3 at_search;     /* m, ... at the last Verlet search */
		eddy_vec3 rot;           /* degrees, the collider's rotation they were placed with */
		eddy_vec3 rot_at_search; /* degrees, ... at the last Verlet search */
		float reach;             /* m, the farthest particle from the collider's pivot (bounds a rotation's sweep) */
	} * col;
	/* per collider, the pose seen at the previous step (velocity = its
	 * change over the time since); with bp and rho the checkpointed block
	 * of sph_density (state_size bytes from bp) */
	struct sph_collider_seen {
		float x, y, z, have;      /* m; have = 1 once seen (floats: no padding in a checkpoint) */
		float rx, ry, rz, unused; /* degrees, the rotation seen */
		double time;              /* s */
	} * seen;
	size_t state_size;
} sph_boundary;

typedef struct sph_neighbors {
	/* the exact lists (read them with sph_nbr_groups and sph_bnbrs) */
	size_t n;
	sph_lists nbr, bnbr;
	uint32_t *first, *bfirst; /* per row: where its lists start in nbr, bnbr */
	uint32_t *count, *bcount; /* per row: their lengths */
	/* m (h^6 + sum_j (h^2 - r^2)^3) over the particle and its fluid
	 * neighbours, plus sum_b V_b rho_b (h^2 - r^2)^3 over the boundary ones
	 * (m: sph_shared's mass), made with the lists: the density over poly6.
	 * Not an array of its own: the density column (derived, so free until
	 * sph_density writes it), which sph_density then scales in place */
	float *ksum;
	/* the boundary particles, nbound of them */
	size_t nbound;
	float *bx, *by, *bz, *bvol; /* m, m^3 (the volume each stands for) */
	float *bp;                  /* Pa, extrapolated from the fluid each step */
	/* 1/s, sum_b V_b rho0 (v_b . n) n . grad W_spiky(x_i - x_b) per fluid
	 * row, n b's collider's normal at x_i (boundary.c): the rate of density
	 * change the moving walls add (sph_dfsph subtracts it from v_i . B_i);
	 * NULL while every wall is at rest */
	float *bdiv;

	/* private: the per-row arrays' block, its size in rows */
	void *rows;
	size_t rows_alloc;
	sph_grid grid;
	sph_verlet verlet;
	sph_boundary bnd;
} sph_neighbors;

/* The part of sigma kappa the colour field's force carries across a free
 * surface, from the lattice (kernels.c; sph_surface_tension divides by it). */
double eddy__sph_surface_share(double spacing, double h, double threshold);

/* What sph_density shares with the SPH systems after it. */
typedef struct sph_shared {
	float h, mass, rho0;
	float spacing;  /* m, the lattice the mass is calibrated on */
	float grad_cal; /* 1 / the pressure force's lattice moment: see sph_pressure */
	float c;        /* m/s, speed of sound sqrt(k) */
	bool verlet;    /* keep a Verlet list (the def's verlet_list); false: search at h every step */
	sph_kernel_consts k;
	sph_neighbors nb;
	/* (x, y, z, 1/rho) per particle this step (arena), as sph_density saw
	 * them: the force passes load a neighbour's four with one 16-byte load */
	float *pq;
} sph_shared;

/* The def of sph_density system s (its EOS, for the stats' compression
 * energy), or NULL if s is not one. */
const eddy_sph_density_def *eddy__sph_density_def(const eddy_system *s);

/* The sph_density system nearest before system s in the pipeline, or NULL. */
sph_shared *eddy__sph_find(eddy_world *w, const eddy_system *s);

/* Builds the boundary particles (once per set of boundary systems: boundary.c). */
eddy_status eddy__sph_boundary_ready(eddy_world *w, sph_shared *sh);

/* Builds the lists for the current particle table, reordering it by cell. */
eddy_status eddy__sph_neighbors_build(eddy_world *w, sph_shared *sh, int threads);
void eddy__sph_neighbors_free(sph_neighbors *nb);

/* An sph_boundary_box's particles (boundary.c gathers them); with x == NULL
 * only counts. h sets how many layers the shell has. */
size_t eddy__sph_boundary_box_points(const eddy_system *s, float h, float *x, float *y, float *z, float *vol);
/* The def of sph_boundary_box s, or NULL if s is not one. */
const eddy_sph_boundary_box_def *eddy__sph_boundary_box_def(const eddy_system *s);
/* s is an sph_boundary_box over exactly [min, max]. */
bool eddy__sph_boundary_box_covers(const eddy_system *s, eddy_vec3 min, eddy_vec3 max);

/* A collider's boundary particles (Akinci et al. 2012) for a fluid of the
 * given spacing and support h, in the collider's def pose (offset 0): a
 * shell ceil(h / spacing) layers deep on the solid side of its surface.
 * With x == NULL only counts. *normal gets the direction along which the
 * offset moves them (a plane: its normal, the sampled patch staying put in
 * the plane) or 0 (they move with the whole offset). Colliders that get
 * none: a tank box (its walls are an sph_boundary_box's), a block box that
 * an sph_boundary_box already samples (the same min and max), and any
 * collider whose kind has no sph_points (only the built-in four have).
 * Implemented beside each collider (sys_collide_*.c, the vtable's
 * sph_points), called through collider_shape.c. */
size_t eddy__sph_collider_points(const eddy_world *w, const eddy_system *s, float spacing, float h, float *x, float *y,
                                 float *z, float *vol, eddy_vec3 *normal);

/* A list of fluid rows (ascending) packed in groups of eight, the last
 * padded with copies of its last row: one word, the first row; then each
 * group as eight 16-bit numbers (four words): the group's first row less the
 * previous group's first (the list's first row for the first group), then
 * its other seven rows less its first. A group whose numbers do not fit (a
 * step of 65535 rows or more between two groups' firsts, a span over 65535
 * in one: rare, the rows of a group lie within a few layers of cells) is the
 * marker SPH_GROUP_WIDE in place of the first number, then its eight rows
 * whole (twelve words). A neighbour takes 2 bytes and a list 4 more, where
 * a list of 4-byte rows took 4 a neighbour. sph_pack_groups (neighbors.h)
 * writes them, for the exact lists and the Verlet candidates. */
#define SPH_GROUP_WIDE 0xFFFFu
#define SPH_GROUP_WORDS_MAX 12

/* The most words a list of cnt rows takes. */
static inline uint32_t sph_packed_words_max(uint32_t cnt) { return cnt ? 1 + (cnt + 7) / 8 * SPH_GROUP_WORDS_MAX : 0; }

/* A reader of a packed list: its next group and the first row of the last. */
typedef struct sph_groups {
	const uint32_t *w;
	uint32_t first;
} sph_groups;

/* The reader of the packed list at p (of at least one row; the arrays
 * holding lists have a word to spare at their end, so p may also be an
 * empty list's, then never read on). */
static inline sph_groups sph_groups_at(const uint32_t *p) { return (sph_groups){p + 1, p[0]}; }

/* The next group into l[0..8) (16-bit numbers: simd.h's widen and add).
 * The wide form is rare: its branch is predicted. */
static inline void sph_group_next(sph_groups *g, uint32_t l[8])
{
	uint16_t step;
	memcpy(&step, g->w, sizeof step);
	if (__builtin_expect(step == SPH_GROUP_WIDE, 0)) {
		memcpy(l, g->w + 4, 8 * sizeof *l);
		g->first = l[0];
		g->w += SPH_GROUP_WORDS_MAX;
		return;
	}
	g->first += step;
	simd_widen16_add(g->first, g->w, l);
	l[0] = g->first; /* its number was the step */
	g->w += 4;
}

/* The same for a group whose rows are then used one by one (as indices of
 * scalar loads, as the passes' gathers do): the numbers taken apart in
 * general registers, no vector store for the loads to wait on (a vector
 * store's lanes read back one by one cost the passes about 10% on the AMD
 * host at hand); sph_group_next where the group is loaded as a vector. */
static inline void sph_group_rows(sph_groups *g, uint32_t l[8])
{
	uint64_t lo, hi;
	memcpy(&lo, g->w, sizeof lo);
	memcpy(&hi, g->w + 2, sizeof hi);
	if (__builtin_expect((lo & 0xFFFFu) == SPH_GROUP_WIDE, 0)) {
		memcpy(l, g->w + 4, 8 * sizeof *l);
		g->first = l[0];
		g->w += SPH_GROUP_WORDS_MAX;
		return;
	}
	const uint32_t f = g->first + (uint32_t)(lo & 0xFFFFu);
	g->first = f;
	l[0] = f;
	l[1] = f + (uint32_t)(lo >> 16 & 0xFFFFu);
	l[2] = f + (uint32_t)(lo >> 32 & 0xFFFFu);
	l[3] = f + (uint32_t)(lo >> 48);
	l[4] = f + (uint32_t)(hi & 0xFFFFu);
	l[5] = f + (uint32_t)(hi >> 16 & 0xFFFFu);
	l[6] = f + (uint32_t)(hi >> 32 & 0xFFFFu);
	l[7] = f + (uint32_t)(hi >> 48);
	g->w += 4;
}

/* Past the next group, unread. */
static inline void sph_group_skip(sph_groups *g)
{
	uint16_t step;
	memcpy(&step, g->w, sizeof step);
	if (step == SPH_GROUP_WIDE) {
		g->first = g->w[4];
		g->w += SPH_GROUP_WORDS_MAX;
	} else {
		g->first += step;
		g->w += 4;
	}
}

/* Row i's fluid neighbours (count[i] of them, (count[i] + 7) / 8 groups) and
 * its boundary neighbours (bcount[i] of them). */
static inline sph_groups sph_nbr_groups(const sph_neighbors *nb, long i)
{
	return sph_groups_at(nb->nbr.data + nb->first[i]);
}
static inline const uint32_t *sph_bnbrs(const sph_neighbors *nb, long i) { return nb->bnbr.data + nb->bfirst[i]; }

/* The rows the lists cover: a system after sph_density may have added
 * particles (they have no lists this step) or removed some. */
static inline long sph_rows(const eddy_world *w, const sph_shared *sh)
{
	return sh->nb.n < w->n ? (long)sh->nb.n : (long)w->n;
}

/* The force passes run block(args, i0, cnt) over rows [0, n) in blocks of
 * SPH_BLOCK: first the SIMD sums over the block's fluid pairs, then a plain
 * loop finishing its particles (finished right after its groups, a
 * particle's totals would wait behind the often mispredicted exit of the
 * group loop). A block that copies *args to a local keeps the constants in
 * registers: its stores cannot alias the copy. On threads, the blocks go
 * out in chunks of at most SPH_CHUNK_BLOCKS (about 8 a thread in a small
 * pass), taken in turn as each thread finishes one: equal shares would
 * finish at the pace of the slower core, and on a shared host one core can
 * run at half the other's speed for seconds (dfsph.c, which hands out its
 * passes the same way). A particle's result depends on neither blocks nor
 * threads: the same bits on any thread count, in any order the chunks are
 * taken in. */
#define SPH_BLOCK 64
#define SPH_CHUNK_BLOCKS 16
static inline void sph_block_pass(long n, int threads, void (*block)(const void *args, long i0, long cnt),
                                  const void *args)
{
	if (threads <= 1) { /* no team to wake */
		for (long i0 = 0; i0 < n; i0 += SPH_BLOCK)
			block(args, i0, n - i0 < SPH_BLOCK ? n - i0 : SPH_BLOCK);
		return;
	}
	long per = (n + SPH_BLOCK - 1) / SPH_BLOCK / (8L * threads);
	per = per < 1 ? 1 : per > SPH_CHUNK_BLOCKS ? SPH_CHUNK_BLOCKS : per;
	const long chunk = per * SPH_BLOCK, chunks = (n + chunk - 1) / chunk;
#pragma omp parallel for num_threads(threads) schedule(dynamic, 1)
	for (long c = 0; c < chunks; ++c)
		for (long i0 = c * chunk, hi = i0 + chunk < n ? i0 + chunk : n; i0 < hi; i0 += SPH_BLOCK)
			block(args, i0, hi - i0 < SPH_BLOCK ? hi - i0 : SPH_BLOCK);
}

/* Four partial sums stored to memory, added in sf8_sum's order (simd.h). */
static inline float sph_sum4(const float *l) { return (l[0] + l[1]) + (l[2] + l[3]); }

#endif
