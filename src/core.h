/* SPDX-License-Identifier: MIT */
/* Internal structures shared by the engine's source files. Not installed: hosts
 * see only eddy.h. */
#ifndef EDDY_CORE_H
#define EDDY_CORE_H

#include "eddy.h"
#include "components.h"

#include <float.h>
#include <math.h>
#include <stdarg.h>

#define EDDY_MAX_COLUMNS 128
#define EDDY_MAX_SYSTEMS 256
#define EDDY_MAX_IO 24
#define EDDY_NAME_MAX 32
#define EDDY_GROUP_MAX 96 /* a node group's text, as eddy_system_set_group takes it */
#define EDDY_ERROR_MAX 512

typedef struct eddy_system eddy_system;

/* What a kind offers the systems after it and asks of the ones before it.
 * A kind lists them in its vtable (provides, requires, excludes); the
 * pipeline checks them when a system is added or removed, so a scene that
 * cannot work fails at the line that built it, naming both systems. Systems
 * find each other through these (eddy__provider, eddy__systems), never by
 * comparing kinds. */
typedef enum eddy_capability {
	EDDY_CAP_SPH_NEIGHBORS = 1u << 0, /* sph_density: neighbour lists, densities, boundary particles (sph_shared) */
	EDDY_CAP_SPH_EOS_FORCE = 1u << 1, /* sph_pressure: the force from the equation of state's pressure */
	EDDY_CAP_SPH_WALLS = 1u << 2,     /* boundary particles on fixed walls (sph_boundary_box) */
	EDDY_CAP_COLLIDER = 1u << 3,      /* a solid with a signed distance (vtable distance) */
	EDDY_CAP_MAC_GRID = 1u << 4,      /* flip_p2g: particle velocities on the staggered grid */
	EDDY_CAP_SOLID_FACES = 1u << 5,   /* flip_boundary: the grid's solid cells and face velocities */
	EDDY_CAP_FREE_SURFACE = 1u << 6,  /* flip_surface: the liquid's level set */
	EDDY_CAP_GRAVITY = 1u << 7,       /* gravity: shares its eddy_gravity_def */
	EDDY_CAP_GRID_DENSITY = 1u << 8,  /* flip_pressure: shares its eddy_flip_pressure_def (the fluid's density) */
} eddy_capability;

/* What a system kind can do. step is required except for frame-only systems. */
typedef struct eddy_system_vtable {
	const char *name;
	/* couplings (bits of eddy_capability, see above): what the kind
	 * provides; what an earlier system must provide; what no other system
	 * in the pipeline may provide */
	uint32_t provides, requires, excludes;
	/* the block a provider shares for capability cap (e.g. sph_shared for
	 * EDDY_CAP_SPH_NEIGHBORS), or NULL */
	void *(*shared)(const eddy_system *s, uint32_t cap);
	eddy_status (*step)(eddy_world *w, eddy_system *s, const eddy_step_context *ctx);
	eddy_status (*frame)(eddy_world *w, eddy_system *s, int frame);
	double (*limit)(eddy_world *w, eddy_system *s, const char **reason);
	void (*destroy)(eddy_system *s);
	/* emitters: particles the system will create over a run, -1 if unbounded */
	int64_t (*expected_particles)(const eddy_world *w, const eddy_system *s);
	/* emitters: positions of the first emission, for preflight; returns the count
	 * written (up to cap) */
	size_t (*sample)(const eddy_world *w, const eddy_system *s, eddy_vec3 *out, size_t cap);
	/* emitters: the lattice spacing they emit at (m), for the preflight */
	float (*spacing)(const eddy_system *s);
	/* emitters: the highest point along the unit vector up of what they
	 * emit (m; a bound: a block's corner) and the fastest speed they give a
	 * particle (m/s), for sph_density's automatic speed of sound */
	void (*reach)(const eddy_system *s, eddy_vec3 up, eddy_vec3 *top, double *speed);
	/* derives settings from the rest of the pipeline (sph_density's
	 * automatic speed of sound); called on every live system after each
	 * add and remove until the world's first step, so the order systems are
	 * added in does not matter and the settings are fixed while it runs
	 * (a system added after that derives its own once, when added) */
	void (*rederive)(eddy_world *w, eddy_system *s);
	/* the kind's own preflight findings (eddy_world_check), one line each;
	 * returns the number of EDDY_CHECK_ERROR findings it reported */
	int (*check)(eddy_world *w, const eddy_system *s, eddy_check_fn report, void *user);
	/* never moves a solid nor changes what a solid covers: FLIP's solid
	 * faces made before it still hold after it (eddy__flip_solid_for) */
	bool keeps_solids;
	/* takes part in the settling steps before the first step (world.c,
	 * settle): the SPH density (with the walls' particles) and pressure
	 * force; everything else (gravity, viscosity, colliders, integrate,
	 * emitters after time 0's emission, custom systems) sits them out */
	bool settles;
	/* colliders: signed distance to the solid, < 0 inside it */
	float (*distance)(const eddy_system *s, eddy_vec3 p);
	/* colliders: pose and size, for hosts that draw them (eddy_collider_shape_of) */
	void (*shape)(const eddy_system *s, eddy_collider_shape *out);
	/* colliders: SPH boundary particles (sph/sph.h, eddy__sph_collider_points) */
	size_t (*sph_points)(const eddy_world *w, const eddy_system *s, float spacing, float h, float *x, float *y,
	                     float *z, float *vol, eddy_vec3 *normal);
	/* columns the kind writes, ending in -1; names the fix in order errors */
	const int *default_writes;
	/* the system's mutable state as one plain block, saved and restored
	 * byte for byte by checkpoints; NULL for stateless systems. It may build
	 * what the block lives in (the same way for the same scene), so a world
	 * that has not stepped yet can take a saved state. */
	void *(*state)(eddy_world *w, eddy_system *s, size_t *size);
	/* output systems: waits for frame work left running in the background
	 * (eddy_world_sync); EDDY_OK or its first failure */
	eddy_status (*sync)(eddy_world *w, eddy_system *s);
} eddy_system_vtable;

struct eddy_system {
	const eddy_system_vtable *vt;
	char label[EDDY_NAME_MAX + 8];
	char name[EDDY_NAME_MAX];
	char group[EDDY_GROUP_MAX]; /* the node group that added it, "" if none (plans show it) */
	uint16_t generation;
	bool live;
	int reads[EDDY_MAX_IO], read_count;
	int writes[EDDY_MAX_IO], write_count;
	const char *read_names[EDDY_MAX_IO];
	const char *write_names[EDDY_MAX_IO];
	double ms_total, ms_frame;
	int64_t calls;
	void *data; /* the system's def and private state, owned */
};

typedef struct eddy_column {
	char name[EDDY_NAME_MAX];
	char unit[16];
	eddy_domain domain;
	eddy_type type;
	eddy_lifetime lifetime;
	int users;  /* systems in the pipeline that read or write it */
	void *data; /* NULL unless users > 0 */
} eddy_column;

/* A bump allocator reset at the start of every step: scratch that lives for one
 * step costs no free() and cannot leak. Grows by chaining blocks. */
typedef struct eddy_arena_block eddy_arena_block;
typedef struct eddy_arena {
	eddy_arena_block *head;
	size_t high_water;
	size_t step_peak; /* most in use at once since the last reset */
} eddy_arena;

void *eddy__arena_alloc(eddy_arena *a, size_t bytes);
/* A large block of its own pages from the system (arena.c), its contents
 * undefined; freed with eddy__pages_free, which returns the pages to the
 * system. The pages stay unresident until written. */
void *eddy__pages_alloc(size_t bytes);
void eddy__pages_free(void *p);
void eddy__arena_reset(eddy_arena *a);
void eddy__arena_free(eddy_arena *a);
/* A point in the arena to return to: a system whose scratch dies with its own
 * step releases it there, so the step's peak is the largest system's scratch
 * rather than the sum over the pipeline (what is allocated before the mark
 * stays valid). */
typedef struct eddy_arena_mark {
	eddy_arena_block *head;
	size_t used;
} eddy_arena_mark;
eddy_arena_mark eddy__arena_mark(const eddy_arena *a);
void eddy__arena_release(eddy_arena *a, eddy_arena_mark m);

typedef struct eddy_extra_stat {
	char name[EDDY_NAME_MAX];
	double value;
	char text[64];
	bool is_text;
} eddy_extra_stat;

struct eddy_world {
	eddy_world_def def;
	char error[EDDY_ERROR_MAX];
	/* Non-NULL while a step, advance or check runs systems' or hosts' code:
	 * names what runs (eddy__busy_step, eddy__busy_frame, ...). Calls that
	 * would change the clock or the pipeline under that code are refused;
	 * a collider pose set under a step is that step's, under the frame
	 * hooks the next frame time's (collider.c). */
	const char *busy;
	double call_end;        /* s, the end of the stepping call that runs (-INFINITY: eddy_world_step's one step) */
	bool background_output; /* eddy_world_set_background_output */

	/* clock */
	double time;
	int frame;
	int64_t step;
	double last_dt;
	const char *last_limit; /* static string or a system label */
	char last_limit_buf[96];

	/* columns */
	eddy_column columns[EDDY_MAX_COLUMNS];
	int column_count;
	size_t n, capacity; /* particles */
	/* eddy_world_add_particles holds x y z (and vx vy vz once it was given
	 * velocities) as one more user, so that what the host gave is kept even
	 * before, or without, a system that uses them */
	bool host_positions, host_velocities;

	/* MAC grid, present while some grid column is in use */
	int nx, ny, nz;
	bool grid_allocated;

	/* pipeline: slots hold systems, order lists live slots in step order */
	eddy_system slots[EDDY_MAX_SYSTEMS];
	int slot_count;
	int order[EDDY_MAX_SYSTEMS];
	int order_count;

	eddy_arena arena;
	uint64_t rng;
	float length_scale; /* m, smallest emitter spacing; 0 if none */
	float rest_density; /* kg/m^3, 0 if no density system */
	bool settling;      /* the settling steps run (gravity reads as zero) */
	bool settled;       /* they ran to the end, or there were none to run */

	/* run-time warnings (eddy__warn): once per key, the first EDDY_MAX_WARNINGS - 1
	 * kept and then one saying so */
	struct eddy_warning {
		char key[EDDY_NAME_MAX + 24];
		char text[512];
	} warnings[EDDY_MAX_WARNINGS];
	int warning_count;

	/* per-frame accumulators, and the snapshot of the last completed frame */
	int64_t frame_steps;
	double frame_dt_min, frame_dt_max;
	double frame_wall_ms;
	eddy_extra_stat extras[EDDY_MAX_EXTRA_STATS];
	int extra_count;
	struct {
		int64_t steps;
		double dt_min, dt_max, wall_ms;
		double system_ms[EDDY_MAX_STAT_SYSTEMS];
		eddy_extra_stat extras[EDDY_MAX_EXTRA_STATS];
		int extra_count;
		const char *dt_limit;
	} last_frame;
};

/* errors */
eddy_status eddy__fail(eddy_world *w, eddy_status s, const char *fmt, ...)
#if defined(__GNUC__)
	__attribute__((format(printf, 3, 4)))
#endif
	;

/* Raises a run-time warning (eddy_world_warning) once per key: a second
 * call with a key already raised does nothing. The key names the system
 * and the cause ("<label>:held"). Called from a system's step or frame,
 * never from inside a parallel loop. */
void eddy__warn(eddy_world *w, const char *key, const char *fmt, ...)
#if defined(__GNUC__)
	__attribute__((format(printf, 3, 4)))
#endif
	;

/* Refuses a call that changes the clock or the pipeline while w->busy: sets
 * the error ("<fn> called from inside <what>") and returns true. */
bool eddy__refuse_busy(eddy_world *w, const char *fn);
/* The checks every eddy_add_* starts with: a world, a def, and no step
 * running. False with the world error set (when there is a world). */
bool eddy__add_args(eddy_world *w, const void *def, const char *sys);

/* columns (columns.c) */
void eddy__columns_init(eddy_world *w);
void eddy__columns_free(eddy_world *w);
/* A per-row loop over more rows than this runs on the world's threads:
 * below it, waking the team costs more than the loop. */
#define EDDY_PAR_ROWS 65536
/* The largest u^2 + v^2 + w^2 over the particle rows of columns cu cv cw
 * (0 when one is not allocated; a row with a non-finite value is passed
 * over), on the world's threads above EDDY_PAR_ROWS rows: the step limits'
 * largest speed or acceleration. A maximum, so the same on any thread
 * count. */
float eddy__max_norm2(eddy_world *w, int cu, int cv, int cw);
/* Reorders every allocated particle column so row i takes old row perm[i]
 * (on the world's threads: a gather, the same bits); scratch holds n
 * floats. SPH keeps the table in grid-cell order with it. */
void eddy__permute_particles(eddy_world *w, const uint32_t *perm, void *scratch);
size_t eddy__column_elems(const eddy_world *w, const eddy_column *c);
size_t eddy__column_bytes(const eddy_world *w, const eddy_column *c);
eddy_status eddy__column_acquire(eddy_world *w, int id);
void eddy__column_release(eddy_world *w, int id);
eddy_status eddy__reserve_particles(eddy_world *w, size_t count);
/* Appends count zero-filled rows; returns the index of the first. */
eddy_status eddy__append_particles(eddy_world *w, size_t count, size_t *first);
void eddy__clear_derived(eddy_world *w);
/* Starts a fresh frame's statistics. */
void eddy__frame_reset(eddy_world *w);

/* w->busy while the systems of a step run, and while the frame hooks run */
extern const char eddy__busy_step[], eddy__busy_frame[];
static inline float *eddy__col(eddy_world *w, int id) { return (float *)w->columns[id].data; }
/* s, the time of the frame the world steps toward */
/* m/s^2, the acceleration the pipeline's gravity systems add up to (each
 * the world's gravity times its scale; 0 without any): sys_gravity.c */
void eddy__gravity_sum(const eddy_world *w, double g[3]);
/* The same as a vector (m/s^2): what the SPH passes' hydrostatic terms take
 * as g, so a pipeline without gravity (or with it scaled, or settling its
 * start) has walls that hold no weight the water does not have. */
eddy_vec3 eddy__gravity(const eddy_world *w);

static inline double eddy__next_frame_time(const eddy_world *w) { return (double)(w->frame + 1) / w->def.fps; }
static inline float eddy__clamp_to(float v, float lo, float hi) { return v < lo ? lo : v > hi ? hi : v; }
/* The world's box is solid outside: a collider's push out of its own solid
 * must not leave it. Where a collider stands on the box's floor or cuts a
 * wall (a cup on the floor), the push along the collider's own normal can
 * cross the box's wall in the crease between them, and the run would stop
 * with the particle outside the domain. Each collider checks its pushes
 * with eddy__outside_box, takes another way out where it has one (the
 * mesh: where the particle's path entered it; the box: its nearest face
 * inside the world) and clamps with eddy__into_box last. */
static inline bool eddy__outside_box(const eddy_world *w, eddy_vec3 p)
{
	const eddy_vec3 lo = w->def.bounds_min, hi = w->def.bounds_max;
	return !(p.x >= lo.x && p.x <= hi.x && p.y >= lo.y && p.y <= hi.y && p.z >= lo.z && p.z <= hi.z);
}
/* p with each coordinate within e of one of the world's walls moved e
 * inside: where a collider stands on the floor, a particle on the floor
 * (where a tank leaves it) under the collider's edge reads its distance
 * there, not the 0 of the face it shares with the floor, so it is pushed
 * out rather than left in the gap between them. */
static inline eddy_vec3 eddy__off_walls(const eddy_world *w, eddy_vec3 p, float e)
{
	const eddy_vec3 lo = w->def.bounds_min, hi = w->def.bounds_max;
	const float q[3] = {p.x, p.y, p.z}, l[3] = {lo.x, lo.y, lo.z}, h[3] = {hi.x, hi.y, hi.z};
	float r[3];
	for (int a = 0; a < 3; ++a)
		r[a] = eddy__clamp_to(q[a], l[a] + e, h[a] - e);
	return (eddy_vec3){r[0], r[1], r[2]};
}
/* The nearest point of the world's box to p. */
static inline eddy_vec3 eddy__into_box(const eddy_world *w, eddy_vec3 p)
{
	const eddy_vec3 lo = w->def.bounds_min, hi = w->def.bounds_max;
	return (eddy_vec3){eddy__clamp_to(p.x, lo.x, hi.x), eddy__clamp_to(p.y, lo.y, hi.y),
	                   eddy__clamp_to(p.z, lo.z, hi.z)};
}

/* systems (pipeline.c) */
eddy_system *eddy__system_get(eddy_world *w, eddy_system_id id);
const eddy_system *eddy__system_peek(const eddy_world *w, eddy_system_id id);
/* Adds a system of kind vt; data is the system's heap block (taken over, freed
 * on failure too). reads and writes are column lists ending in -1 (NULL for
 * none), so no count is ever typed beside a list. */
eddy_system_id eddy__add_system(eddy_world *w, const eddy_system_vtable *vt, void *data, const int *reads,
                                const int *writes);
void eddy__system_free(eddy_world *w, eddy_system *s);

/* The pipeline in step order, optionally only the systems that provide any
 * of caps (0: all):
 *   for (eddy_system_iter it = eddy__systems(w, caps); (s = eddy__systems_next(&it));) */
typedef struct eddy_system_iter {
	const eddy_world *w;
	int pos;
	uint32_t caps;
} eddy_system_iter;
eddy_system_iter eddy__systems(const eddy_world *w, uint32_t caps);
const eddy_system *eddy__systems_next(eddy_system_iter *it);
/* The pipeline position of the system the last eddy__systems_next gave, for
 * data kept per position. */
static inline int eddy__systems_position(const eddy_system_iter *it) { return it->pos - 1; }
/* The nearest system before s (any position when s is NULL: the last one)
 * that provides cap, or NULL. */
const eddy_system *eddy__provider(const eddy_world *w, const eddy_system *s, uint32_t cap);
/* What that provider shares for cap (vtable shared), or NULL. */
void *eddy__provided(const eddy_world *w, const eddy_system *s, uint32_t cap);

/* FNV-1a over bytes, for the state hash and the checkpoint checksums: start
 * from EDDY__FNV_BASIS and feed the pieces in order. */
#define EDDY__FNV_BASIS 0xcbf29ce484222325ull
static inline uint64_t eddy__fnv1a(uint64_t h, const void *data, size_t n)
{
	const unsigned char *p = data;
	for (size_t i = 0; i < n; ++i) {
		h ^= p[i];
		h *= 0x100000001b3ull;
	}
	return h;
}

/* random numbers: splitmix64, deterministic per world seed */
static inline uint64_t eddy__rand_u64(uint64_t *state)
{
	uint64_t z = (*state += 0x9E3779B97F4A7C15ull);
	z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
	z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
	return z ^ (z >> 31);
}
static inline double eddy__rand01(uint64_t *state)
{
	return (double)(eddy__rand_u64(state) >> 11) * (1.0 / 9007199254740992.0);
}

/* def validation: each returns false and sets the world error when the field is
 * out of range; messages read "<system>: '<field>' must be <allowed> (got <v>)". */
bool eddy__check_positive(eddy_world *w, const char *sys, const char *field, double v);
bool eddy__check_nonneg(eddy_world *w, const char *sys, const char *field, double v);
bool eddy__check_range(eddy_world *w, const char *sys, const char *field, double v, double lo, double hi);
bool eddy__check_finite(eddy_world *w, const char *sys, const char *field, double v);
bool eddy__check_vec3(eddy_world *w, const char *sys, const char *field, eddy_vec3 v);
bool eddy__check_box(eddy_world *w, const char *sys, eddy_vec3 lo, eddy_vec3 hi);
bool eddy__check_unit(eddy_world *w, const char *sys, const char *field, eddy_vec3 *v);

void eddy__note_length_scale(eddy_world *w, float h);
/* One preflight finding, printf style (eddy_world_check and the kinds' check). */
void eddy__report(eddy_check_fn report, void *user, eddy_check_level level, const char *fmt, ...)
#if defined(__GNUC__)
	__attribute__((format(printf, 4, 5)))
#endif
	;
double eddy__now_ms(void);
/* Preflight of an emitter: one starting when the run is over emits nothing.
 * A warning, as eddy run --duration may run longer than the scene's duration. */
void eddy__check_emitter_start(const eddy_world *w, const eddy_system *s, double start, eddy_check_fn report,
                               void *user);
/* The time-step limit of a one-shot emitter whose particles leave at up to
 * speed (m/s): the limits are taken before the step's systems add their
 * particles, so the step that emits them must move them at most spacing
 * (times the CFL number), as the advection limit does from the next step
 * on; otherwise infinite. */
double eddy__emission_limit(const eddy_world *w, bool done, double start, double spacing, double speed,
                            const char **reason);
/* The points pts[0 .. np) a one-shot emitter of the given spacing would add
 * where water or a solid already is: occupied[k] = 1 when a particle of the
 * world lies within spacing / 2 of pts[k] on every axis (its lattice cell,
 * faces included, holds the point) or pts[k] lies inside a collider's solid
 * (its signed distance < 0), else 0. An emitter adds water only where there
 * is none: two boxes that overlap make one pool, not a doubly dense block
 * that bursts, and a box around an obstacle fills around it rather than
 * leaving the collider to push the water inside it out in one step (a pool
 * around a 4 cm sphere burst at 15 m/s, WCSPH). The solids' test on the
 * world's threads, the water's serially, in the world's arena (released on
 * return); false when out of memory. clearance > 0 (at most spacing) tests
 * the distance instead: occupied when a particle lies closer than
 * clearance (emit_nozzle, whose discs meet moving water off any lattice). */
bool eddy__emit_occupied(eddy_world *w, const eddy_vec3 *pts, size_t np, float spacing, float clearance,
                         uint8_t *occupied);
/* Whether an emitter must ask eddy__emit_occupied: the world has particles
 * or colliders. */
bool eddy__emit_needs_check(const eddy_world *w);

/* collider helpers (collider.c) */
/* The collider's pose: a point q of the def pose is at
 *   x = pivot + offset + R(rotation) (q - pivot)
 * with R the rotation by |rotation| degrees about rotation / |rotation| (the
 * unit of collide_mesh's static `rotate`). The pivot is in the def pose:
 * each kind sets its centre when added (box centre, sphere centre, plane
 * point, mesh translate), eddy_collider_set_pivot another. A collider whose
 * rotation and last rotation are zero takes the translating code paths
 * unchanged (the same bits as before rotation existed). */
typedef struct eddy_collider_motion {
	eddy_vec3 offset;        /* m, current displacement from the def pose */
	eddy_vec3 last_offset;   /* m, displacement at the collider's last step */
	eddy_vec3 rotation;      /* degrees, axis-angle about the pivot, now */
	eddy_vec3 last_rotation; /* degrees, ... at the collider's last step */
	eddy_vec3 pivot;         /* m, the centre of rotation in the def pose */
	/* The pose last set (eddy_collider_set_offset, set_rotation): a pose set
	 * between the world's stepping calls is reached at the end of the next
	 * call, one set in a frame hook at the next frame time, each step moving
	 * offset and rotation toward it by its dt over the time left
	 * (eddy__collider_glide). Equal to offset and rotation when not gliding. */
	eddy_vec3 goal_offset;   /* m */
	eddy_vec3 goal_rotation; /* degrees */
	float stepped;    /* 1 once it has run: from now on offsets are motion (a float: no padding in a checkpoint) */
	float speed;      /* m/s, |v| of the pivot over the collider's last step */
	float spin;       /* rad/s, |omega| over that step */
	/* speed and spin eased over about an eighth of a frame (each step moves
	 * them toward the step's by min(1, dt / that time)): what the water
	 * beside the collider has been driven at, for the limit on a glide's
	 * start (eddy__collider_limit) */
	float speed_eased; /* m/s */
	float spin_eased;  /* rad/s */
	float unused;      /* 0: the struct without padding in a checkpoint */
	double goal_time;  /* s, when the goal is reached; 0 not gliding; NaN the end of the next stepping call */
} eddy_collider_motion;

/* A rotation as a row-major 3x3 matrix, and the rigid transform of a pose. */
typedef struct eddy_collider_pose {
	float r[9];       /* def pose -> world, row-major */
	eddy_vec3 pivot;  /* m, in the def pose */
	eddy_vec3 center; /* m, the pivot in the world: pivot + offset */
	bool rotated;     /* r is not the identity */
} eddy_collider_pose;

/* A rigid motion over one step: the velocity at x is v + omega x (x - center). */
typedef struct eddy_collider_velocity {
	eddy_vec3 v;      /* m/s, the pivot's */
	eddy_vec3 omega;  /* rad/s */
	eddy_vec3 center; /* m */
} eddy_collider_velocity;

/* Rotation matrix of a rotation vector in degrees (Rodrigues). */
void eddy__rotation_matrix(eddy_vec3 rotvec_deg, float r[9]);
/* The angular velocity (rad/s) taking orientation `from` to `to` (rotation
 * vectors in degrees) over dt: the rotation vector of R(to) R(from)^T / dt,
 * the shorter way round; 0 for dt <= 0. */
eddy_vec3 eddy__rotation_rate(eddy_vec3 from_deg, eddy_vec3 to_deg, double dt);
eddy_collider_pose eddy__collider_pose(const eddy_collider_motion *m);
/* Before a step from time t of dt ending at end (the stepping call's end
 * time call_end, -INFINITY for eddy_world_step's one step): moves a gliding
 * collider dt / (goal_time - t) of the way to its goal pose, linearly in
 * offset and in the rotation vector (for a fixed axis a uniform rotation,
 * half a turn and more between two poses included), landing on the goal's
 * exact values in the step that reaches goal_time. */
void eddy__collider_glide(eddy_collider_motion *m, double t, double dt, double end, double call_end, double eps);
/* Every collider's time-step limit (vtable limit): its surface moves at
 * most the world's length scale a step (the advection limit's rule for
 * the fluid), at the speed of its last step or of the glide ahead. */
double eddy__collider_limit(eddy_world *w, eddy_system *s, const char **reason);
static inline bool eddy__motion_rotates(const eddy_collider_motion *m)
{
	return m->rotation.x != 0 || m->rotation.y != 0 || m->rotation.z != 0 || m->last_rotation.x != 0 ||
	       m->last_rotation.y != 0 || m->last_rotation.z != 0;
}
static inline eddy_vec3 eddy__mat_mul(const float r[9], eddy_vec3 v)
{
	return (eddy_vec3){r[0] * v.x + r[1] * v.y + r[2] * v.z, r[3] * v.x + r[4] * v.y + r[5] * v.z,
	                   r[6] * v.x + r[7] * v.y + r[8] * v.z};
}
static inline eddy_vec3 eddy__mat_tmul(const float r[9], eddy_vec3 v)
{
	return (eddy_vec3){r[0] * v.x + r[3] * v.y + r[6] * v.z, r[1] * v.x + r[4] * v.y + r[7] * v.z,
	                   r[2] * v.x + r[5] * v.y + r[8] * v.z};
}
/* World point -> def pose, and back. */
static inline eddy_vec3 eddy__pose_to_body(const eddy_collider_pose *p, eddy_vec3 x)
{
	const eddy_vec3 d = eddy__mat_tmul(p->r, (eddy_vec3){x.x - p->center.x, x.y - p->center.y, x.z - p->center.z});
	return (eddy_vec3){p->pivot.x + d.x, p->pivot.y + d.y, p->pivot.z + d.z};
}
static inline eddy_vec3 eddy__pose_to_world(const eddy_collider_pose *p, eddy_vec3 q)
{
	const eddy_vec3 d = eddy__mat_mul(p->r, (eddy_vec3){q.x - p->pivot.x, q.y - p->pivot.y, q.z - p->pivot.z});
	return (eddy_vec3){p->center.x + d.x, p->center.y + d.y, p->center.z + d.z};
}
/* The velocity of the solid's point at x. */
static inline eddy_vec3 eddy__rigid_velocity(const eddy_collider_velocity *m, eddy_vec3 x)
{
	const float rx = x.x - m->center.x, ry = x.y - m->center.y, rz = x.z - m->center.z;
	return (eddy_vec3){m->v.x + m->omega.y * rz - m->omega.z * ry, m->v.y + m->omega.z * rx - m->omega.x * rz,
	                   m->v.z + m->omega.x * ry - m->omega.y * rx};
}

/* Every collider's data block starts with this, so offset setting is shared. */
typedef struct eddy_collider_base {
	eddy_collider_motion motion;
	eddy_collider_response response;
} eddy_collider_base;

bool eddy__is_collider(const eddy_system *s);
bool eddy__check_response(eddy_world *w, const char *sys, eddy_collider_response r);
/* Projects particle i to p_surface and applies the velocity response against
 * the surface normal n (unit, pointing out of the solid) and wall velocity vw. */
static inline void eddy__collide_response(float *vx, float *vy, float *vz, size_t i, eddy_vec3 n, eddy_vec3 vw,
                                          eddy_collider_response r)
{
	float rx = vx[i] - vw.x, ry = vy[i] - vw.y, rz = vz[i] - vw.z;
	float vn = rx * n.x + ry * n.y + rz * n.z;
	if (vn >= 0.0f)
		return; /* already separating */
	float tx = rx - vn * n.x, ty = ry - vn * n.y, tz = rz - vn * n.z;
	float vt = sqrtf(tx * tx + ty * ty + tz * tz);
	float dvn = (1.0f + r.restitution) * -vn;
	float keep = 1.0f;
	if (vt > 0.0f) {
		keep = 1.0f - r.friction * dvn / vt;
		if (keep < 0.0f)
			keep = 0.0f;
	}
	float vn_new = -r.restitution * vn;
	vx[i] = vw.x + tx * keep + vn_new * n.x;
	vy[i] = vw.y + ty * keep + vn_new * n.y;
	vz[i] = vw.z + tz * keep + vn_new * n.z;
}

/* A collider's checkpointed state: its motion. */
void *eddy__collider_state(eddy_world *w, eddy_system *s, size_t *size);

/* Wall velocity of a collider over a step of dt, then marks the offset as
 * used (frame: the world's frame time, s, which sets the easing). */
eddy_vec3 eddy__collider_step_velocity(eddy_collider_base *b, double dt, double frame);
/* The rigid motion over a step of dt (offset and rotation against those of
 * the last step), then marks both as used. */
eddy_collider_velocity eddy__collider_step_motion(eddy_collider_base *b, double dt, double frame);
/* The motion between a remembered pose (offset, rotation) and the current
 * one over dt, for systems that keep their own memory (flip_boundary, SPH's
 * boundary particles). */
eddy_collider_velocity eddy__collider_motion_since(const eddy_collider_motion *m, eddy_vec3 offset_then,
                                                   eddy_vec3 rotation_then, double dt);
/* Sets a newly added collider's pivot (its kind's centre); a pivot given
 * with eddy_collider_set_pivot later replaces it. */
static inline void eddy__collider_init_pivot(eddy_collider_base *b, eddy_vec3 pivot) { b->motion.pivot = pivot; }
/* Contact of particle i found at body-frame point q_body (moved there), with
 * body-frame normal n_body, on a rotated collider: writes the world position
 * and applies the response against the surface's velocity there. */
static inline void eddy__collide_rotated(float *x, float *y, float *z, float *vx, float *vy, float *vz, size_t i,
                                         const eddy_collider_pose *p, const eddy_collider_velocity *mv,
                                         eddy_vec3 q_body, eddy_vec3 n_body, eddy_collider_response r)
{
	const eddy_vec3 xw = eddy__pose_to_world(p, q_body);
	x[i] = xw.x, y[i] = xw.y, z[i] = xw.z;
	eddy__collide_response(vx, vy, vz, i, eddy__mat_mul(p->r, n_body), eddy__rigid_velocity(mv, xw), r);
}
/* The same, the point clamped into the world's box (eddy__into_box, above)
 * in world coordinates and written as clamped: a clamp in the body frame
 * comes back a rounding outside. */
static inline void eddy__collide_rotated_in(const eddy_world *w, float *x, float *y, float *z, float *vx, float *vy,
                                            float *vz, size_t i, const eddy_collider_pose *p,
                                            const eddy_collider_velocity *mv, eddy_vec3 q_body, eddy_vec3 n_body,
                                            eddy_collider_response r)
{
	const eddy_vec3 xw = eddy__into_box(w, eddy__pose_to_world(p, q_body));
	x[i] = xw.x, y[i] = xw.y, z[i] = xw.z;
	eddy__collide_response(vx, vy, vz, i, eddy__mat_mul(p->r, n_body), eddy__rigid_velocity(mv, xw), r);
}

/* floor and ceil of the spacings h in the side [lo, hi], all three given
 * as floats: each float is rounded by up to FLT_EPSILON / 2 of itself, so
 * a side of exactly k spacings comes out k off by up to
 * (|lo| + |hi| + k h) FLT_EPSILON / (2 h), and a count that close to an
 * integer is that integer (twice that, for room). A 0.04 m side at 1 mm
 * read 39.99999725 spacings, and one from 10 m to 10.04 m 39.99996: a
 * fixed 1e-6 of tolerance lost a layer, 5% of a dam break's water. */
static inline double eddy__count_tolerance(double lo, double hi, double h)
{
	return 1e-6 + FLT_EPSILON * (fabs(lo) + fabs(hi) + fabs(hi - lo)) / h;
}
static inline double eddy__count_floor(double lo, double hi, double h)
{
	return floor((hi - lo) / h + eddy__count_tolerance(lo, hi, h));
}
static inline double eddy__count_ceil(double lo, double hi, double h)
{
	return ceil((hi - lo) / h - eddy__count_tolerance(lo, hi, h));
}

static inline eddy_vec3 eddy__v3(float x, float y, float z) { return (eddy_vec3){x, y, z}; }
static inline eddy_vec3 eddy__add3(eddy_vec3 a, eddy_vec3 b) { return (eddy_vec3){a.x + b.x, a.y + b.y, a.z + b.z}; }
static inline float eddy__norm3(eddy_vec3 v) { return sqrtf(v.x * v.x + v.y * v.y + v.z * v.z); }

/* max and min of finite floats in one instruction: fmaxf and fminf must
 * treat NaN specially, so without -ffinite-math-only they are calls */
static inline float eddy__maxf(float a, float b) { return a > b ? a : b; }
static inline float eddy__minf(float a, float b) { return a < b ? a : b; }

#endif
