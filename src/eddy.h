/* SPDX-License-Identifier: MIT */
/* eddy — a headless fluid engine.
 *
 * This is the one public header. A host creates a world from a def, adds systems
 * (each from its own def), and steps the world; the systems it added are the only
 * physics that runs, and the columns they use are the only memory allocated.
 *
 * Conventions: every def is filled by its eddy_default_*_def() function, the only
 * place a default lives; SI units on every field; handles carry a generation so a
 * stale one is detected. Functions that can fail return an eddy_status and leave
 * a one-line message in eddy_world_error(). The library never exits or aborts on
 * user input.
 *
 * NULL arguments: every function checks its pointers. A NULL world, def,
 * name, path or out-pointer makes a status function return EDDY_ERR_INVALID
 * (with a message in eddy_world_error(w) when w is not NULL), an eddy_add_*
 * return EDDY_NULL_SYSTEM, a getter return a neutral value: 0 for counts and
 * hashes, NaN for times (eddy_world_time, frame_time, last_dt), NULL for
 * pointers, < 0 for column ids, EDDY_NULL_SYSTEM for handles; functions
 * returning void do nothing. Pointers documented as optional (vel, err, a
 * plan's buf with cap 0, a channel's count) may be NULL.
 *
 * Re-entrancy: while the world runs systems' and hosts' code (custom step,
 * frame and limit callbacks, the renderer), that code may read the world but
 * not step it, load a checkpoint or change its pipeline: eddy_world_step,
 * step_frame, advance, load, set_threads, remove_system and every eddy_add_*
 * called from a callback return EDDY_ERR_INVALID (or EDDY_NULL_SYSTEM) with
 * "<function> called from inside a frame callback" (or step, limit callback).
 * Adding and removing particles and moving colliders stay allowed.
 * eddy_destroy_world called from a callback does nothing (the world is in use).
 */
#ifndef EDDY_H
#define EDDY_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

#define EDDY_VERSION_MAJOR 0
#define EDDY_VERSION_MINOR 2
#define EDDY_VERSION_PATCH 0
#define EDDY_VERSION_STRING "0.2.0"

/* EDDY_API marks the public functions: the library is built with hidden
 * visibility, so libeddy.so exports these and nothing else. */
#if defined(__GNUC__) || defined(__clang__)
#define EDDY_API __attribute__((visibility("default")))
#else
#define EDDY_API
#endif

/* ---- status ------------------------------------------------------------ */

typedef enum eddy_status {
	EDDY_OK = 0,
	EDDY_ERR_INVALID, /* a def field or argument is out of range */
	EDDY_ERR_ORDER,   /* the pipeline reads a column before anything writes it */
	EDDY_ERR_STALE,   /* a handle refers to something that no longer exists */
	EDDY_ERR_NOMEM,   /* an allocation failed or would not fit */
	EDDY_ERR_IO,      /* a file could not be read or written */
	EDDY_ERR_NUMERIC, /* a non-finite value, an escaped particle, a collapsed step */
	EDDY_ERR_SOLVER,  /* a linear solve failed */
	EDDY_ERR_EXTERNAL /* a host callback or an external library reported failure */
} eddy_status;

EDDY_API const char *eddy_status_name(eddy_status s);

/* ---- small value types ------------------------------------------------- */

typedef struct eddy_vec3 {
	float x, y, z;
} eddy_vec3;

typedef struct eddy_world eddy_world;

/* A system in a world's pipeline. index is the slot, generation changes when the
 * slot is reused, so a handle kept past eddy_world_remove_system() is rejected. */
typedef struct eddy_system_id {
	uint16_t index;
	uint16_t generation;
} eddy_system_id;

#define EDDY_NULL_SYSTEM ((eddy_system_id){0, 0})

/* ---- world ------------------------------------------------------------- */

typedef enum eddy_escape_policy {
	EDDY_ESCAPE_ERROR = 0, /* a particle leaving the bounds stops the run */
	EDDY_ESCAPE_REMOVE     /* particles leaving the bounds are removed (e.g. open outflow) */
} eddy_escape_policy;

typedef struct eddy_world_def {
	eddy_vec3 bounds_min;      /* m, lower corner of the domain */
	eddy_vec3 bounds_max;      /* m, upper corner of the domain */
	eddy_vec3 gravity;         /* m/s^2, applied by the gravity system */
	double fps;                /* 1/s, frames per simulated second */
	double duration;           /* s, default length of a run */
	double cfl;                /* 1, multiplies every time-step limit systems report */
	double dt_max;             /* s, upper bound on the step */
	double dt_min;             /* s, a step limit below this stops the run */
	int max_steps_per_frame;   /* 1, a frame needing more steps stops the run */
	double cell_size;          /* m, MAC grid spacing; 0 = no grid may be used */
	uint64_t seed;             /* 1, seed of the world's random stream (jitter) */
	int threads;               /* 1, worker threads for systems that parallelise */
	eddy_escape_policy escape; /* what a particle leaving the bounds means */
	bool check_finite;         /* scan written columns after each system */
	int settle_steps;          /* 1, 0 (off) to 1e6: before the first step, at most this many descent steps
	                              of the SPH pressure force (no gravity, no time) on what is there at time 0,
	                              until no particle would move 5e-4 h; needs sph_pressure. Published as the
	                              first frame's stat settle_steps */
} eddy_world_def;

EDDY_API eddy_world_def eddy_default_world_def(void);

/* NULL only when def is invalid or memory is short; the reason is written to
 * err (if err_size > 0). */
EDDY_API eddy_world *eddy_create_world(const eddy_world_def *def, char *err, size_t err_size);
EDDY_API void eddy_destroy_world(eddy_world *w);

/* The last error message of this world ("" if none). */
EDDY_API const char *eddy_world_error(const eddy_world *w);
/* Sets the world's error message (printf style) and returns status; for custom
 * systems that fail. */
EDDY_API eddy_status eddy_world_fail(eddy_world *w, eddy_status status, const char *fmt, ...)
#if defined(__GNUC__)
	__attribute__((format(printf, 3, 4)))
#endif
	;

EDDY_API const eddy_world_def *eddy_world_get_def(const eddy_world *w);
EDDY_API eddy_status eddy_world_set_threads(eddy_world *w, int threads);

EDDY_API double eddy_world_time(const eddy_world *w);       /* s */
EDDY_API double eddy_world_frame_time(const eddy_world *w); /* s, 1/fps */
EDDY_API int eddy_world_frame(const eddy_world *w);         /* frames completed */
EDDY_API int64_t eddy_world_steps(const eddy_world *w);     /* steps taken */
EDDY_API double eddy_world_last_dt(const eddy_world *w);    /* s, 0 before the first step */
/* m, the length the CFL limits use: the smallest emitter spacing (0 before
 * any emitter); a moving collider's surface moves at most cfl times it a step */
EDDY_API double eddy_world_length_scale(const eddy_world *w);

/* One adaptive step, never past the next frame time. */
EDDY_API eddy_status eddy_world_step(eddy_world *w);
/* Steps up to the next frame time, then runs the frame hooks. */
EDDY_API eddy_status eddy_world_step_frame(eddy_world *w);
/* Advances by seconds (frame hooks run at every frame time crossed). */
EDDY_API eddy_status eddy_world_advance(eddy_world *w, double seconds);

/* Frame output in the background. Off (the default), every file a frame hook
 * writes (render_points' PNG) is complete when the step that ran the hook
 * returns, and a failed write is that call's status. On, the hook copies what
 * the frame needs and a thread of the system's own draws and writes it while
 * the next frames step: at most 2 frames wait per renderer, and the stepping
 * blocks while they do. Files are still written whole, in frame order; a
 * failed write is returned, naming the frame and its file, by the next
 * stepping call or by eddy_world_sync. eddy_world_save and eddy_world_load
 * sync first, so a checkpoint never gets ahead of the frames on disk.
 * Destroying the world (or removing the system) still writes the frames in
 * flight but cannot report their failures: sync first to learn of them. The
 * background threads are not counted in eddy_world_set_threads. */
EDDY_API eddy_status eddy_world_set_background_output(eddy_world *w, bool on);
EDDY_API bool eddy_world_background_output(const eddy_world *w);
/* Waits until every frame handed to the background is on disk (or failed);
 * returns EDDY_OK or the first failure not yet returned, with its message. */
EDDY_API eddy_status eddy_world_sync(eddy_world *w);

/* ---- columns ----------------------------------------------------------- */

typedef enum eddy_domain {
	EDDY_DOMAIN_PARTICLE = 0, /* one value per particle */
	EDDY_DOMAIN_CELL,         /* one value per grid cell, nx*ny*nz */
	EDDY_DOMAIN_FACE_X,       /* one value per x-face, (nx+1)*ny*nz */
	EDDY_DOMAIN_FACE_Y,       /* one value per y-face, nx*(ny+1)*nz */
	EDDY_DOMAIN_FACE_Z        /* one value per z-face, nx*ny*(nz+1) */
} eddy_domain;

typedef enum eddy_type { EDDY_F32 = 0, EDDY_U8 } eddy_type;

typedef enum eddy_lifetime {
	EDDY_STATE = 0, /* persists across steps; part of the state hash */
	EDDY_DERIVED    /* cleared at the start of each step, then recomputed */
} eddy_lifetime;

typedef int eddy_column_id; /* < 0 means "no such column" */

typedef struct eddy_column_info {
	const char *name;
	eddy_domain domain;
	eddy_type type;
	eddy_lifetime lifetime;
	const char *unit; /* SI unit, "" for dimensionless */
	bool allocated;   /* some system in the pipeline uses it */
	size_t bytes;     /* bytes currently allocated */
} eddy_column_info;

EDDY_API int eddy_world_column_count(const eddy_world *w);
EDDY_API eddy_column_id eddy_world_find_column(const eddy_world *w, const char *name);
EDDY_API eddy_status eddy_world_column_info(const eddy_world *w, eddy_column_id id, eddy_column_info *out);
/* Declares a new column for custom systems (e.g. "temperature"). Returns its id,
 * or < 0 with the world error set if the name is taken or invalid. */
EDDY_API eddy_column_id eddy_world_declare_column(eddy_world *w, const char *name, eddy_domain domain, eddy_type type,
                                                  eddy_lifetime lifetime, const char *unit);

/* Read access by name: NULL if the column is unknown or not allocated. *count gets
 * the number of elements (particles, cells or faces). */
EDDY_API const float *eddy_world_channel(const eddy_world *w, const char *name, size_t *count);
/* Writable access for custom systems and hosts (same rules). */
EDDY_API float *eddy_world_channel_mut(eddy_world *w, const char *name, size_t *count);
EDDY_API const uint8_t *eddy_world_channel_u8(const eddy_world *w, const char *name, size_t *count);

EDDY_API size_t eddy_world_particle_count(const eddy_world *w);

/* Appends count particles; each allocated particle column is zero-filled except
 * positions and velocities taken from the arrays (vel may be NULL). From the
 * first call on the world keeps x y z (and vx vy vz once given) for the host,
 * even before or without a system that uses them. Positions outside the bounds
 * are rejected. */
EDDY_API eddy_status eddy_world_add_particles(eddy_world *w, size_t count, const eddy_vec3 *pos, const eddy_vec3 *vel);
/* Swap-remove: the last particle moves into slot i. Iterate backwards. */
EDDY_API eddy_status eddy_world_remove_particle(eddy_world *w, size_t i);

typedef struct eddy_grid_info {
	bool allocated;
	int nx, ny, nz;   /* cells along each axis */
	double cell_size; /* m */
	eddy_vec3 origin; /* m, corner of cell (0,0,0) */
} eddy_grid_info;

EDDY_API eddy_grid_info eddy_world_grid(const eddy_world *w);

/* A 64-bit hash of the state columns, particle count and clock: equal states
 * give equal hashes, so determinism and resume can be checked. Not a
 * checksum of a file: FNV-1a over the count, clock and column names, each
 * column's bytes hashed in 64 KB chunks on the world's threads (8-byte
 * words, multiply and xor-shift) and folded in order, so the value does not
 * depend on the thread count. */
EDDY_API uint64_t eddy_world_state_hash(const eddy_world *w);

/* ---- pipeline ---------------------------------------------------------- */

typedef struct eddy_step_context {
	double dt;    /* s, this step's size */
	double time;  /* s, time at the start of the step */
	int64_t step; /* index of this step, from 0 */
	int threads;  /* worker threads the system may use */
} eddy_step_context;

typedef struct eddy_system_info {
	const char *name;  /* the system kind, e.g. "emit_box" */
	const char *label; /* kind plus slot, e.g. "emit_box#1" */
	const char *const *reads;
	int read_count;
	const char *const *writes;
	int write_count;
	double profile_ms;          /* total wall time spent in step, ms */
	int64_t calls;              /* steps run */
	int64_t expected_particles; /* emitters: particles it will create, -1 unbounded, 0 others */
	const char *group;          /* the node group that added it ("" if none), see eddy_system_set_group */
} eddy_system_info;

EDDY_API int eddy_world_system_count(const eddy_world *w);
/* i-th system in pipeline order. */
EDDY_API eddy_system_id eddy_world_system_at(const eddy_world *w, int i);
EDDY_API eddy_status eddy_world_system_info(const eddy_world *w, eddy_system_id id, eddy_system_info *out);
EDDY_API bool eddy_system_valid(const eddy_world *w, eddy_system_id id);
EDDY_API eddy_status eddy_world_remove_system(eddy_world *w, eddy_system_id id);
/* Node groups: a host that adds several systems as one unit (Lua's
 * eddy.fluid{}, say) tags each with the group's text, e.g.
 * "fluid{method = flip, resolution = 0.01 m}"; plans show the systems under
 * it. The tag is a label only: the systems run and validate as any others.
 * NULL or "" clears it; text longer than 95 bytes is an error. */
EDDY_API eddy_status eddy_system_set_group(eddy_world *w, eddy_system_id id, const char *group);

/* The validated pipeline as text (systems in order, reads/writes, columns and
 * bytes) or as a Graphviz digraph. Returns the length that the full text needs,
 * like snprintf; buf may be NULL when cap is 0. */
EDDY_API size_t eddy_world_plan(const eddy_world *w, char *buf, size_t cap);
EDDY_API size_t eddy_world_plan_dot(const eddy_world *w, char *buf, size_t cap);

/* ---- custom systems: the public door for hosts and the renderer -------- */

typedef eddy_status (*eddy_step_fn)(eddy_world *w, const eddy_step_context *ctx, void *user);
typedef eddy_status (*eddy_frame_fn)(eddy_world *w, int frame, void *user);
/* Largest stable step (s) before the world's CFL factor; write a short reason. */
typedef double (*eddy_limit_fn)(eddy_world *w, void *user, const char **reason);

typedef struct eddy_custom_system_def {
	const char *name;         /* shown in plans and errors; copied */
	const char *const *reads; /* column names the step reads */
	int read_count;
	const char *const *writes; /* column names the step writes */
	int write_count;
	eddy_step_fn step;           /* may be NULL for a frame-only system */
	eddy_frame_fn frame;         /* called at each frame time; may be NULL */
	eddy_limit_fn limit;         /* may be NULL */
	void (*destroy)(void *user); /* called when the system is removed */
	void *user;
	/* may be NULL; for systems whose frame hook leaves work running
	 * (eddy_world_set_background_output): waits for it and returns its first
	 * failure not yet returned (eddy_world_sync) */
	eddy_status (*sync)(eddy_world *w, void *user);
} eddy_custom_system_def;

EDDY_API eddy_custom_system_def eddy_default_custom_system_def(void);
EDDY_API eddy_system_id eddy_add_custom_system(eddy_world *w, const eddy_custom_system_def *def);
/* The user pointer of custom system id when its frame hook is `frame` (so a
 * caller gets only pointers whose type it knows), else NULL. Systems that
 * share work within a frame find each other with it (render/: the surface
 * mesh, meshed once for surface_mesh and render_surface). */
EDDY_API void *eddy_world_custom_user(const eddy_world *w, eddy_system_id id, eddy_frame_fn frame);

/* ---- built-in systems --------------------------------------------------- *
 * Each eddy_add_* returns EDDY_NULL_SYSTEM on failure with the reason in
 * eddy_world_error(): "<system>: '<field>' must be <what is allowed> (got <v>)".
 */

/* What emit_box fills: the whole box, or the ellipsoid inscribed in it (a
 * drop: centre (min + max) / 2, semi-axes (max - min) / 2). */
typedef enum eddy_emit_shape { EDDY_EMIT_BLOCK = 0, EDDY_EMIT_ELLIPSOID } eddy_emit_shape;

/* emit_box: a block (or the ellipsoid inscribed in it) of particles on a
 * cubic lattice, once, at time `start`. The one-shot emitters (emit_box,
 * emit_mesh, emit_particles) limit the step that emits moving particles to
 * cfl spacing / speed, as the advection limit does from the next step on:
 * the limits are taken before a step's systems add their particles.
 * emit_box and emit_mesh add water only where there is none: a lattice point
 * within spacing / 2 of a particle already in the world on every axis is
 * left out, so boxes that overlap each other or a pool make one body of
 * water (emit_particles places every particle it reads). */
typedef struct eddy_emit_box_def {
	eddy_vec3 min;         /* m, lower corner of the block */
	eddy_vec3 max;         /* m, upper corner of the block */
	float spacing;         /* m, lattice spacing; > 0 */
	float jitter;          /* 1, random offset as a fraction of spacing, [0, 0.5] */
	eddy_vec3 velocity;    /* m/s, initial velocity */
	double start;          /* s, emission time */
	eddy_emit_shape shape; /* block (default) or the inscribed ellipsoid */
} eddy_emit_box_def;
EDDY_API eddy_emit_box_def eddy_default_emit_box_def(void);
EDDY_API eddy_system_id eddy_add_emit_box(eddy_world *w, const eddy_emit_box_def *def);

/* emit_nozzle: a continuous round jet. Discs of particles on a square lattice
 * leave the nozzle every spacing/speed seconds, so the jet has the lattice
 * density; rate = speed * pi r^2 / spacing^3 particles per second. */
typedef struct eddy_emit_nozzle_def {
	eddy_vec3 center;      /* m, centre of the nozzle opening */
	float radius;          /* m, > 0 */
	eddy_vec3 direction;   /* 1, jet direction (normalised on add) */
	float speed;           /* m/s, > 0 */
	float spacing;         /* m, > 0 */
	double start;          /* s, time the pour begins */
	double duration;       /* s, length of the pour; infinity = no end */
	int64_t max_particles; /* 1, stop after this many; 0 = no limit */
} eddy_emit_nozzle_def;
EDDY_API eddy_emit_nozzle_def eddy_default_emit_nozzle_def(void);
EDDY_API eddy_system_id eddy_add_emit_nozzle(eddy_world *w, const eddy_emit_nozzle_def *def);

/* gravity: adds the world's gravity times scale to the particle acceleration. */
typedef struct eddy_gravity_def {
	float scale; /* 1, multiplies eddy_world_def.gravity */
} eddy_gravity_def;
EDDY_API eddy_gravity_def eddy_default_gravity_def(void);
EDDY_API eddy_system_id eddy_add_gravity(eddy_world *w, const eddy_gravity_def *def);

/* integrate: symplectic Euler, v += a dt, x += v dt. Reports the advection limit
 * dt <= length / max_speed, length being the smallest emitter spacing. */
typedef struct eddy_integrate_def {
	float max_speed; /* m/s, speeds are clamped to this (a safety valve); > 0 */
} eddy_integrate_def;
EDDY_API eddy_integrate_def eddy_default_integrate_def(void);
EDDY_API eddy_system_id eddy_add_integrate(eddy_world *w, const eddy_integrate_def *def);

/* Shared by the colliders: a particle found in the solid is projected to its
 * surface; its velocity relative to the collider loses the inward normal part,
 * which comes back as restitution times the impact speed, and its tangential
 * part loses friction times the normal speed change (Coulomb), never reversing. */
typedef struct eddy_collider_response {
	float restitution; /* 1, [0, 1] */
	float friction;    /* 1, >= 0 */
} eddy_collider_response;

/* collide_box: an axis-aligned box; inside = the particles live inside it (a
 * tank), otherwise the box is a solid block they stay out of. */
typedef struct eddy_collide_box_def {
	eddy_vec3 min; /* m */
	eddy_vec3 max; /* m */
	bool inside;   /* particles are kept inside (true) or outside (false) */
	eddy_collider_response response;
	bool sph_walls; /* with SPH, boundary particles that move with the box: a block's
	                   inside its faces, a tank's outside its walls (default true);
	                   none where an sph_boundary_box samples the same box; false:
	                   the box only clamps */
} eddy_collide_box_def;
EDDY_API eddy_collide_box_def eddy_default_collide_box_def(void);
EDDY_API eddy_system_id eddy_add_collide_box(eddy_world *w, const eddy_collide_box_def *def);

/* collide_sphere: a solid ball (inside = false) or a spherical bowl (inside = true). */
typedef struct eddy_collide_sphere_def {
	eddy_vec3 center; /* m */
	float radius;     /* m, > 0 */
	bool inside;
	eddy_collider_response response;
} eddy_collide_sphere_def;
EDDY_API eddy_collide_sphere_def eddy_default_collide_sphere_def(void);
EDDY_API eddy_system_id eddy_add_collide_sphere(eddy_world *w, const eddy_collide_sphere_def *def);

/* collide_plane: a half-space; particles stay on the side the normal points to. */
typedef struct eddy_collide_plane_def {
	eddy_vec3 point;  /* m, a point on the plane */
	eddy_vec3 normal; /* 1, normalised on add */
	eddy_collider_response response;
} eddy_collide_plane_def;
EDDY_API eddy_collide_plane_def eddy_default_collide_plane_def(void);
EDDY_API eddy_system_id eddy_add_collide_plane(eddy_world *w, const eddy_collide_plane_def *def);

/* Meshes from files (mesh.c, through assimp: OBJ, STL, PLY, glTF, FBX and
 * the other formats it reads). A mesh is placed by scale, then rotate, then
 * translate: x' = R (scale * x) + translate. Relative paths are taken from
 * the current directory. A file that cannot be used is a one-line error
 * naming it and why. */

/* collide_mesh: a triangle mesh as a solid the particles stay out of
 * (inside = false: a cup, a rock, a sphere), or as a closed tank the fluid
 * stays inside (inside = true: everything outside the mesh is solid). Its
 * signed distance field is built once when added (exact near the surface,
 * trilinear between nodes); particles in the solid are projected out along
 * its gradient and get the contact response; flip_boundary and flip_advect
 * see it as any collider. Moves with eddy_collider_set_offset. The mesh must
 * be closed (every edge in two triangles, consistently wound) unless open =
 * true, which decides inside by six rays' vote. */
typedef struct eddy_collide_mesh_def {
	char path[512];      /* the mesh file */
	eddy_vec3 scale;     /* 1, per axis; each > 0 */
	eddy_vec3 rotate;    /* degrees, rotation vector: |rotate| degrees about rotate / |rotate| */
	eddy_vec3 translate; /* m */
	float cell_size;     /* m, distance grid spacing; 0 = auto: the finest of the mesh's longest side / 64,
	                        half the world's cell_size and half the spacing of emitters added before it */
	bool inside;         /* particles are kept inside (true) or outside (false) the mesh */
	bool open;           /* accept a mesh that is not closed */
	eddy_collider_response response;
} eddy_collide_mesh_def;
EDDY_API eddy_collide_mesh_def eddy_default_collide_mesh_def(void);
EDDY_API eddy_system_id eddy_add_collide_mesh(eddy_world *w, const eddy_collide_mesh_def *def);

/* emit_mesh: fills a closed mesh with particles on a cubic lattice, once, at
 * time `start`: the lattice points min + (i + 1/2) spacing (min the mesh's
 * box corner) that lie inside, as emit_box places them. The mesh's box must
 * lie in the world's bounds. */
typedef struct eddy_emit_mesh_def {
	char path[512];      /* the mesh file (closed) */
	eddy_vec3 scale;     /* 1, per axis; each > 0 */
	eddy_vec3 rotate;    /* degrees, rotation vector */
	eddy_vec3 translate; /* m */
	float spacing;       /* m, lattice spacing; > 0 */
	float jitter;        /* 1, random offset as a fraction of spacing, [0, 0.5] */
	eddy_vec3 velocity;  /* m/s, initial velocity */
	double start;        /* s, emission time */
} eddy_emit_mesh_def;
EDDY_API eddy_emit_mesh_def eddy_default_emit_mesh_def(void);
EDDY_API eddy_system_id eddy_add_emit_mesh(eddy_world *w, const eddy_emit_mesh_def *def);

/* emit_particles: the particles of a PLY file (ascii, binary_little_endian
 * or binary_big_endian; a `vertex` element with x y z and optionally vx vy
 * vz, as export_particles writes them), once, at time `start`. Particles
 * without vx vy vz take `velocity`. Every particle must lie in the world's
 * bounds. */
typedef struct eddy_emit_particles_def {
	char path[512];     /* the PLY file */
	float spacing;      /* m, the spacing the particles sample the fluid at (the advection limit's length,
	                       SPH's mass calibration); > 0 */
	eddy_vec3 velocity; /* m/s, for particles the file gives no velocity */
	double start;       /* s, emission time */
} eddy_emit_particles_def;
EDDY_API eddy_emit_particles_def eddy_default_emit_particles_def(void);
EDDY_API eddy_system_id eddy_add_emit_particles(eddy_world *w, const eddy_emit_particles_def *def);

/* Moves a collider by an offset from its def pose. The collider moves there
 * at a constant velocity over the steps up to when the pose is due, and
 * particles meet that velocity:
 *   - set in a frame hook (a scene's on_frame): the pose at the next frame
 *     time;
 *   - set between the world's stepping calls: at the end of the next call
 *     (eddy_world_step: its one step, as setting it before every step
 *     does; eddy_world_step_frame: the frame; eddy_world_advance: its
 *     seconds);
 *   - set by a step callback (a custom system's step, Lua's animated
 *     `offset = function(t)`): at the end of that step.
 * Before the collider's first step this only places it. The getter returns the
 * pose last set; eddy_collider_shape_of and eddy_collider_distance the
 * collider where it is. A moving collider limits the time step as the
 * fluid's advection does: its surface moves at most cfl times the world's
 * length scale (the smallest emitter spacing) a step, at |v| + |omega| r
 * (r the farthest its surface reaches from the pivot within the world's
 * box), v and omega those of its last step or of the glide ahead, so that
 * a thin solid moving fast does not step over the water it meets. */
EDDY_API eddy_status eddy_collider_set_offset(eddy_world *w, eddy_system_id id, eddy_vec3 offset);
EDDY_API eddy_status eddy_collider_get_offset(const eddy_world *w, eddy_system_id id, eddy_vec3 *offset);
/* Rotates a collider about its pivot: axis_angle is a rotation vector in
 * degrees (|axis_angle| degrees about axis_angle / |axis_angle|, the unit of
 * collide_mesh's `rotate`), the orientation relative to the def pose, finite
 * and at most 1e6 degrees long. The pose is x = pivot + offset + R (q - pivot)
 * for a point q of the def pose. It is reached when the offset would be
 * (above), the rotation vector moving linearly to it over the steps between:
 * about a fixed axis a uniform turn, half a turn or more between two poses
 * included. The angular velocity of a step is the rotation from the
 * orientation at the collider's last step to this one over dt, and particles
 * meet the surface's velocity v + omega x (x - pivot - offset). Before the
 * collider's first step this only places it. */
EDDY_API eddy_status eddy_collider_set_rotation(eddy_world *w, eddy_system_id id, eddy_vec3 axis_angle);
EDDY_API eddy_status eddy_collider_get_rotation(const eddy_world *w, eddy_system_id id, eddy_vec3 *axis_angle);
/* The point the collider rotates about, in its def pose (m): by default the
 * box's centre, the sphere's centre, the plane's point, the mesh's translate. */
EDDY_API eddy_status eddy_collider_set_pivot(eddy_world *w, eddy_system_id id, eddy_vec3 pivot);
EDDY_API eddy_status eddy_collider_get_pivot(const eddy_world *w, eddy_system_id id, eddy_vec3 *pivot);
/* Signed distance from p to the collider's solid (< 0 inside the solid). */
EDDY_API eddy_status eddy_collider_distance(const eddy_world *w, eddy_system_id id, eddy_vec3 p, float *dist);

/* ---- per-frame statistics ---------------------------------------------- */

#define EDDY_MAX_STAT_SYSTEMS 64
#define EDDY_MAX_EXTRA_STATS 16

typedef struct eddy_stat_value {
	const char *name; /* e.g. "iterations" */
	double value;     /* NAN when text is used */
	const char *text; /* NULL for a number */
} eddy_stat_value;

typedef struct eddy_frame_stats {
	int frame;             /* frames completed */
	double time;           /* s */
	int64_t steps;         /* steps in this frame */
	double dt_min, dt_max; /* s, over this frame's steps */
	const char *dt_limit;  /* what limited the last step, e.g. "integrate: advection" */
	size_t particles;
	double max_speed;               /* m/s */
	double cfl;                     /* 1, max_speed * dt / length; NAN without a length */
	double density_err_avg;         /* 1, |rho - rho0| / rho0; NAN without a density */
	double density_err_max;         /* 1 */
	double density_compression_avg; /* 1, mean of max(rho - rho0, 0) / rho0: the part of
	                                 * the density error a pressure solve controls (the free
	                                 * surface's under-density is the rest); NAN without a density */
	double volume;                  /* m^3, fluid volume on the grid; NAN without a grid */
	size_t leaked;                  /* particles outside the bounds or inside a collider */
	size_t nonfinite;               /* non-finite values in particle state columns */
	double wall_ms;                 /* ms of wall time this frame */
	uint64_t state_hash;
	int system_count;
	const char *system_names[EDDY_MAX_STAT_SYSTEMS]; /* labels, pipeline order */
	double system_ms[EDDY_MAX_STAT_SYSTEMS];         /* ms this frame */
	int extra_count;                                 /* values systems published this frame */
	eddy_stat_value extra[EDDY_MAX_EXTRA_STATS];
	/* Energy and momentum (appended: the fields above keep their places).
	 * All NAN without a particle mass: sph_density's calibrated mass, or for
	 * FLIP flip_pressure's density times spacing^3 of the emitters (all at
	 * one spacing; flip_reseed adds and removes particles, so FLIP's totals
	 * move with the count as well as with the flow). */
	double particle_mass;      /* kg */
	double kinetic_energy;     /* J, sum m |v|^2 / 2 */
	double potential_energy;   /* J, -sum m g . (x - bounds_min), g the gravity systems apply (0 without) */
	double compression_energy; /* J, WCSPH's stored elastic energy (sph_pressure in the pipeline); else NAN */
	double energy;             /* J, kinetic + potential (+ compression where it applies) */
	double momentum[3];        /* kg m/s, sum m v */
	int warnings;              /* run-time warnings raised so far (eddy_world_warning_count) */
} eddy_frame_stats;

/* Statistics of the frame completed last (call after eddy_world_step_frame). */
EDDY_API eddy_status eddy_world_frame_stats(eddy_world *w, eddy_frame_stats *out);

/* Run-time warnings. A system that cannot do all a scene asks of it but can
 * go on (a nozzle whose opening water fills, a solve stopped at its cap, a
 * speed clamped, a particle removed at the bounds) says so once per cause,
 * naming the step and, where one is to blame, the particle; the run goes
 * on. Kept in the order raised: the first EDDY_MAX_WARNINGS - 1, then one
 * saying later ones are not kept. Not saved in checkpoints (a resumed run
 * raises a cause again). */
#define EDDY_MAX_WARNINGS 32
EDDY_API int eddy_world_warning_count(const eddy_world *w);
/* The index-th warning kept, or NULL outside [0, eddy_world_warning_count). */
EDDY_API const char *eddy_world_warning(const eddy_world *w, int index);

/* Systems publish a frame value (solver iterations, residual, ...); a name
 * published twice in a frame keeps the last value. */
EDDY_API void eddy_world_publish(eddy_world *w, const char *name, double value);
EDDY_API void eddy_world_publish_text(eddy_world *w, const char *name, const char *text);

/* Rest density the world compares densities against (set by density systems). */
EDDY_API void eddy_world_set_rest_density(eddy_world *w, float rho0);

/* ---- checkpoints ------------------------------------------------------- */

/* Writes the world's full state (all allocated columns, clock, random stream,
 * the systems' own state) to path atomically: a temporary file, fsync, rename.
 * fingerprint is mixed with the pipeline's own, so a checkpoint loads only into
 * the same scene with the same parameters (the eddy command passes a hash of
 * the scene file and its --set values). */
EDDY_API eddy_status eddy_world_save(eddy_world *w, const char *path, uint64_t fingerprint);
/* Restores what eddy_world_save wrote into a world built by the same scene.
 * A truncated, corrupted, foreign or other-version file is rejected with
 * EDDY_ERR_IO and a message saying which, and the world is left unchanged;
 * so is one whose checksum holds but whose clock or counts no run of this
 * world reaches (a negative frame, a frame off time * fps, a non-finite time
 * or dt, ...): the message names the file and the field. */
EDDY_API eddy_status eddy_world_load(eddy_world *w, const char *path, uint64_t fingerprint);

/* ---- preflight --------------------------------------------------------- */

typedef enum eddy_check_level { EDDY_CHECK_INFO, EDDY_CHECK_WARNING, EDDY_CHECK_ERROR } eddy_check_level;
typedef void (*eddy_check_fn)(eddy_check_level level, const char *message, void *user);

/* Reports time-step limits, particles starting inside colliders and a memory
 * estimate, and scene mistakes that would run but give a wrong answer (an
 * emitter spacing other than the one sph_density calibrates its mass on, a
 * first frame longer than the run, ...); returns the number of
 * EDDY_CHECK_ERROR findings. report may be NULL to only count; a NULL world
 * counts as one error. */
EDDY_API int eddy_world_check(eddy_world *w, eddy_check_fn report, void *user);

/* ---- SPH (src/sph/) ------------------------------------------------- */

/* SPH after Mueller, Charypar & Gross 2003, with the fixes docs/validation.md lists.
 * sph_density builds the neighbour lists (uniform grid, cells of radius/2) once
 * per step and keeps the particle table in cell order; the later SPH systems
 * reuse those lists, so they must come after it (they read 'density'). */

/* The three kernels of the paper (3D), for hosts and tests. */
typedef enum eddy_sph_kernel {
	EDDY_SPH_POLY6 = 0, /* 315/(64 pi h^9) (h^2 - r^2)^3: density, colour field */
	EDDY_SPH_SPIKY,     /* 15/(pi h^6) (h - r)^3: pressure gradient */
	EDDY_SPH_VISCOSITY  /* 15/(2 pi h^3) (-r^3/2h^3 + r^2/h^2 + h/2r - 1): viscosity Laplacian */
} eddy_sph_kernel;
/* W(r, h) in 1/m^3, dW/dr in 1/m^4, Laplacian in 1/m^5; 0 for r >= h. */
EDDY_API double eddy_sph_kernel_value(eddy_sph_kernel k, double r, double h);
EDDY_API double eddy_sph_kernel_derivative(eddy_sph_kernel k, double r, double h);
EDDY_API double eddy_sph_kernel_laplacian(eddy_sph_kernel k, double r, double h);
/* Sum of W over a simple cubic lattice of the given spacing around a lattice
 * point (itself included), 1/m^3: the calibrated particle mass is rho0 / sum.
 * This and the moment below return 0 for spacing or h <= 0 and NaN for
 * h > 100 spacings. */
EDDY_API double eddy_sph_lattice_sum(eddy_sph_kernel k, double spacing, double h);
/* First moment of the kernel gradient over the same lattice (the point itself
 * excluded), sum_j spacing^3 x_j^2 |dW/dr|(r_j) / r_j, dimensionless: 1 in
 * the continuum, so that the SPH gradient of a linear field is exact; 0.956
 * for spiky at h = 2 spacings. With the calibrated mass in place of
 * rho0 spacing^3 the pressure force sees 0.947, and sph_pressure divides by it. */
EDDY_API double eddy_sph_lattice_gradient_moment(eddy_sph_kernel k, double spacing, double h);

typedef enum eddy_sph_eos {
	EDDY_SPH_EOS_LINEAR = 0, /* p = k (rho - rho0), the paper's */
	EDDY_SPH_EOS_TAIT        /* p = (k rho0 / gamma) ((rho/rho0)^gamma - 1) */
} eddy_sph_eos;

/* How sph_density makes the density. */
typedef enum eddy_sph_density_mode {
	EDDY_SPH_DENSITY_SUMMATION = 0, /* rho_i = sum_j m W_ij each step (Mueller 2003) */
	EDDY_SPH_DENSITY_CONTINUITY     /* d rho_i / dt from the velocities, with delta-SPH diffusion (sph_pressure only) */
} eddy_sph_density_mode;

/* sph_density: neighbour search, poly6 density, equation of state. */
typedef struct eddy_sph_density_def {
	float radius;                  /* m, kernel support h; > spacing */
	float spacing;                 /* m, particle spacing the mass is calibrated on; > 0 */
	float rest_density;            /* kg/m^3, rho0; > 0 */
	float stiffness;               /* m^2/s^2, k = c^2 (speed of sound squared); >= 0. 0 (the default):
	                                  with sph_pressure from the scene, c = 10 x the fastest speed its
	                                  water reaches by itself (emitters' speed and their fall to the
	                                  world's floor, or their sph_boundary_box's), fixed at the first step;
	                                  otherwise, or with no such speed, 20 m/s (eddy_sph_sound_speed) */
	eddy_sph_eos eos;              /* equation of state: linear (the paper's) or Tait */
	float tait_gamma;              /* 1, exponent of the Tait EOS; >= 1 */
	eddy_sph_density_mode density; /* summation (default) or continuity */
	float diffusion;               /* 1, delta-SPH's delta for continuity; [0, 1], 0.1 usual */
	/* keep a Verlet list (default true): the pairs within 1.2 h, reused
	 * while no particle has moved half that margin, so a step searches
	 * about 50 candidates a particle instead of the cell grid's 240; false:
	 * the grid search at h every step. The same pairs and results either
	 * way; off, a step at 100k-1M particles takes about 1.3x the time with
	 * WCSPH and some 40% less memory (README, Scale) */
	bool verlet_list;
} eddy_sph_density_def;
EDDY_API eddy_sph_density_def eddy_default_sph_density_def(void);
EDDY_API eddy_system_id eddy_add_sph_density(eddy_world *w, const eddy_sph_density_def *def);
/* The particle mass sph_density calibrated (kg), 0 if id is not one. */
EDDY_API float eddy_sph_particle_mass(const eddy_world *w, eddy_system_id id);
/* The speed of sound sqrt(stiffness) sph_density uses (m/s; the one chosen
 * from the scene when the def's stiffness is 0), 0 if id is not one. */
EDDY_API float eddy_sph_sound_speed(const eddy_world *w, eddy_system_id id);

/* sph_pressure: symmetric spiky-gradient pressure force. */
typedef struct eddy_sph_pressure_def {
	float scale; /* 1, multiplies the force (1 = the paper's); > 0 */
} eddy_sph_pressure_def;
EDDY_API eddy_sph_pressure_def eddy_default_sph_pressure_def(void);
EDDY_API eddy_system_id eddy_add_sph_pressure(eddy_world *w, const eddy_sph_pressure_def *def);

/* sph_viscosity: viscosity-kernel Laplacian of the velocity, plus Monaghan's
 * artificial viscosity on approaching pairs, which damps the acoustic noise of
 * weakly compressible SPH that a physical viscosity too small to slow the flow
 * cannot. */
typedef struct eddy_sph_viscosity_def {
	float viscosity;  /* Pa s, dynamic viscosity mu; >= 0 */
	float artificial; /* 1, Monaghan's alpha (0.01-0.1 usual); >= 0 */
} eddy_sph_viscosity_def;
EDDY_API eddy_sph_viscosity_def eddy_default_sph_viscosity_def(void);
EDDY_API eddy_system_id eddy_add_sph_viscosity(eddy_world *w, const eddy_sph_viscosity_def *def);

/* sph_surface_tension: colour-field (CSF) surface tension where |n| h >
 * threshold (n = grad c, h the kernel radius), scaled so that a free
 * surface carries the whole sigma kappa (a drop at rest holds Laplace's
 * 2 sigma / R). */
typedef struct eddy_sph_surface_tension_def {
	float tension;   /* N/m, sigma; >= 0 */
	float threshold; /* 1, |grad c| h below this gets no force; >= 0, and under a flat surface's outermost
	                    layer's (1.06 at h = 2 spacings; the first step says so), well under on a curved one */
} eddy_sph_surface_tension_def;
EDDY_API eddy_sph_surface_tension_def eddy_default_sph_surface_tension_def(void);
EDDY_API eddy_system_id eddy_add_sph_surface_tension(eddy_world *w, const eddy_sph_surface_tension_def *def);

/* sph_boundary_box: the six faces of a box sampled with boundary particles
 * (Akinci et al. 2012) that sph_density and sph_pressure see as fluid at rest,
 * so particles at walls have full neighbourhoods: no sticking, no gap. Keep a
 * collide_box with the same bounds as the hard limit. */
typedef struct eddy_sph_boundary_box_def {
	eddy_vec3 min; /* m */
	eddy_vec3 max; /* m */
	float spacing; /* m, spacing of the boundary particles; > 0 (about the fluid's) */
} eddy_sph_boundary_box_def;
EDDY_API eddy_sph_boundary_box_def eddy_default_sph_boundary_box_def(void);
EDDY_API eddy_system_id eddy_add_sph_boundary_box(eddy_world *w, const eddy_sph_boundary_box_def *def);

/* sph_dfsph: implicit pressure, divergence-free SPH (Bender & Koschier 2015),
 * in place of sph_pressure. Put it after the other forces (gravity,
 * sph_viscosity, sph_surface_tension) and before integrate: it predicts the
 * velocities those forces give, solves for the pressure that keeps the density
 * at rest density, adds the pressure acceleration and writes the pressure (Pa)
 * to the 'pressure' column. The time step is then limited by the flow speed
 * (h / max|v|, and 0.18 sqrt(h / |g|), times the CFL number; CFL <= 1), not by
 * sph_density's speed of sound. With divergence_solver both solves start from
 * each particle's pressure of the last step (state columns dfsph_k, dfsph_kd)
 * and run conjugate gradients, their tolerances and the gravity limit
 * tightened in water deeper than 5 kernel radii: what holds deep water
 * still. Publishes solver, iterations, residual,
 * residual_max, divergence_iterations and unconverged (steps whose solve
 * reached its cap short of a stopping rule) in the frame stats. */
typedef struct eddy_sph_dfsph_def {
	float max_density_error;       /* 1, mean density error rho/rho0 - 1 the solve
	                                  stops at (compression only without the divergence
	                                  solver), and not before no particle is predicted
	                                  over 10% compressed; > 0 and <= 0.1 (0.001-0.01
	                                  usual) */
	int max_iterations;            /* 1, cap on constant-density sweeps per step; 2 to 10000 */
	bool divergence_solver;        /* also make the velocity divergence-free each step
	                                  (default; off: a cheaper cold solve that holds
	                                  shallow water only) */
	float max_divergence_error;    /* 1, mean |Drho/Dt| dt / rho0 the velocity solve
	                                  leaves per step (default 5e-5); > 0 and <= 1 */
	int max_divergence_iterations; /* 1, cap on divergence sweeps per step; 1 to 10000 */
	bool coarse_grid;              /* with divergence_solver, in water deeper than 5 kernel
	                                  radii: precondition the conjugate gradients with a
	                                  multigrid cycle on a grid of h-sized cells too, for
	                                  fewer iterations (same tolerances either way; off by
	                                  default: Jacobi alone, as with it still columns of
	                                  20-40 layers settle with faster particles, and the
	                                  velocity solve, an equality, no longer needs it: README) */
	float shift;                   /* 1, particle shifting: each step a particle away from
	                                  the free surface and the walls moves by -shift h^2
	                                  grad C (C the particle concentration, h the kernel
	                                  radius), its velocity kept: what lets deep water's
	                                  particle lattice settle without bursts; 0 to 0.1
	                                  (default 0.02; 0: off) */
	bool hydrostatic_start;        /* with divergence_solver: when no particle has a pressure
	                                  yet (the first step), start the velocity solve of water
	                                  resting on a wall from the hydrostatic pressure of its
	                                  depth instead of 0 (default off: the velocity solve builds
	                                  that pressure itself in a few tens of iterations, a
	                                  100-layer tank's first frame 95 against 87 with it; the
	                                  solved pressure is the same to the tolerances) */
} eddy_sph_dfsph_def;
EDDY_API eddy_sph_dfsph_def eddy_default_sph_dfsph_def(void);
EDDY_API eddy_system_id eddy_add_sph_dfsph(eddy_world *w, const eddy_sph_dfsph_def *def);

/* ---- FLIP (sys_flip_*.c) ------------------------------------------------ */

/* FLIP on the world's MAC grid (cell_size > 0). A step reads, in pipeline order:
 *   gravity, flip_p2g, flip_boundary, flip_surface, flip_pressure,
 *   flip_extrapolate, flip_g2p, flip_advect[, flip_reseed]
 * Cell types in the "cell_type" column: */
enum { EDDY_CELL_AIR = 0, EDDY_CELL_FLUID = 1, EDDY_CELL_SOLID = 2 };

/* flip_p2g: particle accelerations applied (v += a dt), then a trilinear splat
 * of particle velocity onto the three face grids (normalised weights), cells
 * holding a particle marked fluid, the marker field flip_phi (-1 fluid, +1
 * empty) and the pre-solve velocity (u_old, v_old, w_old) for the FLIP delta.
 * With an APIC flip_g2p in the pipeline (its affine columns allocated) the
 * splat carries each particle's affine velocity: v_a + c_a . (x_f - x_p). */
typedef struct eddy_flip_p2g_def {
	float mark_radius; /* 1, in cells: a cell whose centre lies within this of a particle is fluid
	                      too (the cell holding it always is); [0, 1.5] */
} eddy_flip_p2g_def;
EDDY_API eddy_flip_p2g_def eddy_default_flip_p2g_def(void);
EDDY_API eddy_system_id eddy_add_flip_p2g(eddy_world *w, const eddy_flip_p2g_def *def);

/* flip_boundary: the domain's sides and every collider in the pipeline become
 * solid; faces touching a solid cell carry the solid's normal velocity. */
typedef struct eddy_flip_boundary_def {
	float margin;    /* m, cells whose centre is closer than this to a collider's solid are solid; >= 0 */
	bool open_sides; /* false: the domain's sides are still walls; true: outflow (air beyond them, p = 0),
	                  * closed only where a collider covers them, and water crossing them leaves the world
	                  * (removed with escape = EDDY_ESCAPE_REMOVE, else an error) */
} eddy_flip_boundary_def;
EDDY_API eddy_flip_boundary_def eddy_default_flip_boundary_def(void);
EDDY_API eddy_system_id eddy_add_flip_boundary(eddy_world *w, const eddy_flip_boundary_def *def);

/* flip_surface: the marker field smoothed by a 3D Gaussian (separable, solid
 * cells excluded); flip_pressure finds the surface at its zero crossing. */
typedef struct eddy_flip_surface_def {
	float sigma; /* 1, Gaussian standard deviation in cells; (0, 4] */
} eddy_flip_surface_def;
EDDY_API eddy_flip_surface_def eddy_default_flip_surface_def(void);
EDDY_API eddy_system_id eddy_add_flip_surface(eddy_world *w, const eddy_flip_surface_def *def);

typedef enum eddy_flip_solver {
	EDDY_FLIP_PCG = 0, /* MIC(0)-preconditioned conjugate gradient, double precision */
	EDDY_FLIP_CHOLMOD, /* supernodal sparse Cholesky (CHOLMOD), the exact reference */
	EDDY_FLIP_HYPRE,   /* CG preconditioned by a HYPRE PFMG multigrid V-cycle: iterations
	                      flat in grid size; initialises MPI if the host has not */
	EDDY_FLIP_MG       /* CG preconditioned by eddy's own geometric multigrid V-cycle
	                      (McAdams et al. 2010): iterations flat in grid size, on all threads */
} eddy_flip_solver;

/* flip_pressure: the pressure Poisson equation over fluid cells with
 * ghost-fluid free-surface conditions, then the velocity update. Publishes
 * solver, iterations, residual, divergence (max |div u| dt after projection)
 * and volume. */
typedef struct eddy_flip_pressure_def {
	eddy_flip_solver solver;
	float density;      /* kg/m^3, > 0 */
	double tolerance;   /* 1, PCG, HYPRE and MG stop at max|r| <= tolerance * max|b|; (0, 1) */
	int max_iterations; /* 1, PCG, HYPRE and MG cap; failure to converge is an error; >= 1 */
	float theta_min;    /* 1, lower clamp of the ghost-fluid fraction; [1e-4, 0.5] */
} eddy_flip_pressure_def;
EDDY_API eddy_flip_pressure_def eddy_default_flip_pressure_def(void);
EDDY_API eddy_system_id eddy_add_flip_pressure(eddy_world *w, const eddy_flip_pressure_def *def);

/* flip_extrapolate: face velocities copied outward from faces next to fluid
 * into the air, layer by layer; faces inside a solid likewise, then with the
 * solid's velocity across its surface (free slip along it). */
typedef struct eddy_flip_extrapolate_def {
	int layers; /* 1, layers of faces filled; at least the CFL number + 1; [1, 64] */
} eddy_flip_extrapolate_def;
EDDY_API eddy_flip_extrapolate_def eddy_default_flip_extrapolate_def(void);
EDDY_API eddy_system_id eddy_add_flip_extrapolate(eddy_world *w, const eddy_flip_extrapolate_def *def);

/* flip_g2p: the grid's velocity back to the particles.
 *   flip: v = r (v + interp(u - u_old)) + (1 - r) interp(u), r = flip_ratio
 *   pic:  v = interp(u)                     (flip with r = 0)
 *   apic: v = interp(u), c_a = grad interp(u_a) per face grid a (Jiang et al.
 *         2015); flip_p2g then splats v_a + c_a . (x_f - x_p). Only apic
 *         allocates the nine affine columns (apic_ux .. apic_wz). */
typedef enum eddy_flip_transfer {
	EDDY_FLIP_TRANSFER_FLIP = 0, /* FLIP/PIC blend by flip_ratio (the default) */
	EDDY_FLIP_TRANSFER_PIC,      /* pure PIC; flip_ratio is not used */
	EDDY_FLIP_TRANSFER_APIC      /* affine PIC; flip_ratio is not used */
} eddy_flip_transfer;
typedef struct eddy_flip_g2p_def {
	float flip_ratio;            /* 1, 0.95, 1 = pure FLIP, 0 = pure PIC; [0, 1]; transfer flip only */
	eddy_flip_transfer transfer; /* flip */
} eddy_flip_g2p_def;
EDDY_API eddy_flip_g2p_def eddy_default_flip_g2p_def(void);
EDDY_API eddy_system_id eddy_add_flip_g2p(eddy_world *w, const eddy_flip_g2p_def *def);

/* flip_advect: midpoint (RK2) through the grid velocity; particles that end in
 * a solid (domain sides, colliders) are projected out. Limit dt <= dx / v. */
typedef struct eddy_flip_advect_def {
	float wall_gap; /* 1, in cells: projected particles stop this far from a solid; [0, 0.5] */
} eddy_flip_advect_def;
EDDY_API eddy_flip_advect_def eddy_default_flip_advect_def(void);
EDDY_API eddy_system_id eddy_add_flip_advect(eddy_world *w, const eddy_flip_advect_def *def);

/* flip_reseed: keeps min..max particles in each fluid cell (new ones take the
 * grid velocity, surplus ones are removed). */
typedef struct eddy_flip_reseed_def {
	int min_per_cell; /* 1, >= 1 */
	int max_per_cell; /* 1, > min_per_cell */
} eddy_flip_reseed_def;
EDDY_API eddy_flip_reseed_def eddy_default_flip_reseed_def(void);
EDDY_API eddy_system_id eddy_add_flip_reseed(eddy_world *w, const eddy_flip_reseed_def *def);

/* ---- renderer and particle exports (render/) ----------------------------- */

/* render_points: draws the particles as lit spheres (OSMesa point sprites, no
 * GPU or display needed) and writes a PNG at every `every`-th frame time. It
 * reads x y z and the columns color_by needs; it never runs per substep. The GL
 * context is created at the first frame: a failure there is the frame's
 * eddy_status (EDDY_ERR_EXTERNAL) with the reason in eddy_world_error(). */
typedef enum eddy_projection { EDDY_PROJECTION_PERSPECTIVE = 0, EDDY_PROJECTION_ORTHOGRAPHIC } eddy_projection;

typedef enum eddy_colormap {
	EDDY_COLORMAP_VIRIDIS = 0, /* perceptually uniform, dark blue to yellow */
	EDDY_COLORMAP_PLASMA,      /* perceptually uniform, dark blue to orange-yellow */
	EDDY_COLORMAP_GRAY         /* black to white */
} eddy_colormap;

typedef struct eddy_render_points_def {
	int width, height;          /* px, image size, [1, 8192] */
	int supersample;            /* 1, samples per pixel along each axis (box-filtered), [1, 4] */
	eddy_vec3 eye;              /* m, camera position; eye == target frames the world's bounds */
	eddy_vec3 target;           /* m, the point the camera looks at */
	eddy_vec3 up;               /* 1, the camera's up direction (not parallel to the view) */
	float fov;                  /* degrees, vertical field of view (perspective), (0, 180) */
	eddy_projection projection; /* perspective (uses fov) or orthographic (uses ortho_height) */
	float ortho_height;         /* m, visible height (orthographic); 0 = fit the bounds */
	eddy_vec3 background;       /* 1, RGB in [0, 1] */
	float radius;               /* m, particle radius in world units, > 0 */
	char color_by[32];          /* "speed" (m/s, derived), a particle column name (its unit), or "" for `color` */
	eddy_vec3 color;            /* 1, RGB in [0, 1] when color_by is "" */
	eddy_colormap colormap;     /* maps color_by's value range to colours */
	float value_min;            /* unit of color_by, bottom of the colour map; NaN = the frame's minimum */
	float value_max;            /* unit of color_by, top of the colour map; NaN = the frame's maximum */
	bool outline_domain;        /* draw the edges of the world's bounds (lines 1.5 px wide) */
	bool outline_colliders;     /* draw box colliders' edges and spheres' silhouettes (planes: none) */
	eddy_vec3 outline_color;    /* 1, RGB in [0, 1] */
	char path[512];             /* printf pattern with one integer conversion (the frame), e.g. "out/f_%04d.png" */
	int every;                  /* frames, render every N-th frame, >= 1 */
} eddy_render_points_def;

EDDY_API eddy_render_points_def eddy_default_render_points_def(void);
EDDY_API eddy_system_id eddy_add_render_points(eddy_world *w, const eddy_render_points_def *def);

/* export_particles: writes the chosen particle channels to one file per frame:
 * binary little-endian PLY (vertex elements, float properties), legacy VTK
 * (binary big-endian POLYDATA with one vertex per point, the channels as point
 * data) or VTK XML PolyData .vtp (one vertex cell per point, the channels as
 * point data, <p>x <p>y <p>z triples as one 3-component array, vx vy vz as
 * "velocity"; plus a <stem>.pvd collection listing every frame file with its
 * time, e.g. out/p_%04d.vtp gives out/p.pvd). Positions x y z are always
 * written; channels lists the others. Every file is written to a temporary
 * name and renamed into place only when every write succeeded: a failure is
 * the frame's EDDY_ERR_IO naming the file, and leaves no partial file. */
typedef enum eddy_export_format {
	EDDY_EXPORT_PLY = 0, /* .ply, binary little-endian */
	EDDY_EXPORT_VTK,     /* .vtk, legacy 3.0 binary POLYDATA */
	EDDY_EXPORT_VTP      /* .vtp per frame plus a .pvd collection (ParaView, VTK's XML readers) */
} eddy_export_format;

typedef struct eddy_export_particles_def {
	eddy_export_format format; /* EDDY_EXPORT_PLY (default), EDDY_EXPORT_VTP, or EDDY_EXPORT_VTK */
	char channels[256];        /* "all" (default: every allocated particle float column at each frame), or particle
	                            * columns besides x y z, separated by spaces or commas; "speed" is derived */
	char path[512];            /* printf pattern with one integer conversion (the frame) */
	int every;                 /* frames, export every N-th frame, >= 1 */
} eddy_export_particles_def;

EDDY_API eddy_export_particles_def eddy_default_export_particles_def(void);
EDDY_API eddy_system_id eddy_add_export_particles(eddy_world *w, const eddy_export_particles_def *def);

/* What a collider is, for drawing it: kind, pose (offset included) and size. */
typedef enum eddy_collider_kind {
	EDDY_COLLIDER_BOX = 0,
	EDDY_COLLIDER_SPHERE,
	EDDY_COLLIDER_PLANE,
	EDDY_COLLIDER_OTHER, /* a collider whose shape has no description */
	EDDY_COLLIDER_MESH   /* a collide_mesh: a, b its distance grid's box (eddy_collider_mesh draws it) */
} eddy_collider_kind;

typedef struct eddy_collider_shape {
	eddy_collider_kind kind; /* which of the fields below apply */
	eddy_vec3 a;             /* m, box min, sphere centre or a point on the plane (before the rotation) */
	eddy_vec3 b;             /* m, box max; 1, the plane's unit normal (rotation applied) */
	float radius;            /* m, sphere radius */
	bool inside;             /* particles live inside the box or sphere (a tank or bowl) */
	eddy_vec3 rotation;      /* degrees, rotation vector turning a box or mesh about `pivot` (0: none) */
	eddy_vec3 pivot;         /* m, the centre of that rotation, offset applied */
} eddy_collider_shape;

/* The collider's current shape (its offset applied; a box's corners a, b are
 * before `rotation` about `pivot`, a sphere's centre and a plane's point and
 * normal after it). */
EDDY_API eddy_status eddy_collider_shape_of(const eddy_world *w, eddy_system_id id, eddy_collider_shape *out);

/* ---- the liquid surface (src/surface.c, OpenVDB) ------------------------ *
 * The isosurface c = 1/2 of the particles' colour field
 *   c(x) = sum_j spacing^3 W(|x - x_j|, support * spacing)
 * (cubic spline kernel): the volume fraction, 1 inside resting fluid, 0 away
 * from it, 1/2 halfway between the outer particles and the next layer out.
 * Works on any particles (SPH, or FLIP's with spacing = cell_size / 2 for 8
 * per cell). The mesh is closed (every edge shared by two triangles). */
typedef struct eddy_surface_def {
	float spacing; /* m, the particles' rest spacing (each stands for spacing^3 of liquid); > 0 */
	float support; /* 1, kernel support radius in spacings; [1, 4] */
	float voxel;   /* 1, voxel size in spacings; [0.1, 1] */
} eddy_surface_def;
EDDY_API eddy_surface_def eddy_default_surface_def(void);

/* A triangle mesh; start from {0} and reuse it frame after frame (its
 * buffers grow as needed), then eddy_mesh_free. */
typedef struct eddy_mesh {
	size_t vertex_count, triangle_count;
	float *xyz;    /* m, 3 per vertex */
	float *normal; /* 1, 3 per vertex: the field's outward unit normal */
	uint32_t *tri; /* 3 vertex indices per triangle, counter-clockwise seen from outside */
	size_t vertex_cap, normal_cap, triangle_cap; /* floats / indices allocated */
	void *field;                                 /* the field it came from (for eddy_mesh_write_vdb) */
} eddy_mesh;

/* Meshes the world's particles now (x y z). No particles: an empty mesh. */
EDDY_API eddy_status eddy_world_surface(eddy_world *w, const eddy_surface_def *def, eddy_mesh *mesh);
/* A drawable mesh of any collider: the zero level of its signed distance
 * (eddy_collider_distance) sampled every `cell` m over the world's bounds
 * (cell <= 0: the bounds' longest side / 64; at most 256 samples a side),
 * meshed like the surface, normals out of the solid, closed where the solid
 * leaves the bounds. For colliders eddy_collider_shape_of gives no
 * primitive for (EDDY_COLLIDER_MESH, EDDY_COLLIDER_OTHER); both renderers
 * draw them so. */
EDDY_API eddy_status eddy_collider_mesh(eddy_world *w, eddy_system_id id, float cell, eddy_mesh *out);
/* Writes the mesh, whole or not at all, as binary little-endian PLY (vertex
 * x y z nx ny nz floats, face uchar/uint index lists), Wavefront OBJ (v, vn,
 * f a//a b//b c//c) or OpenVDB (.vdb: the field's 1/2 level as a narrow-band
 * level set grid "surface", signed distance in m, which Blender and Houdini
 * read). Failures are EDDY_ERR_IO naming the file. */
typedef enum eddy_mesh_format { EDDY_MESH_PLY = 0, EDDY_MESH_OBJ, EDDY_MESH_VDB } eddy_mesh_format;
EDDY_API eddy_status eddy_world_write_mesh(eddy_world *w, const eddy_mesh *mesh, eddy_mesh_format format,
                                           const char *path);
EDDY_API void eddy_mesh_free(eddy_mesh *mesh);

/* surface_mesh: at every `every`-th frame time, the surface of the particles
 * written to path (a printf pattern with one integer conversion, the frame,
 * and no extension) plus ".ply", ".obj" and/or ".vdb", e.g.
 * out/surface_0001.ply. A frame-only system; reads x y z. Publishes
 * surface_ms (meshing), surface_vertices and surface_triangles. */
typedef struct eddy_surface_mesh_def {
	float spacing;   /* m, as eddy_surface_def; > 0 */
	float support;   /* 1, as eddy_surface_def; [1, 4] */
	float voxel;     /* 1, as eddy_surface_def; [0.1, 1] */
	char format[32]; /* "ply", "obj", "vdb", or several separated by spaces or commas */
	char path[512];  /* printf pattern with one integer conversion (the frame), no extension */
	int every;       /* frames, write every N-th frame, >= 1 */
} eddy_surface_mesh_def;
EDDY_API eddy_surface_mesh_def eddy_default_surface_mesh_def(void);
EDDY_API eddy_system_id eddy_add_surface_mesh(eddy_world *w, const eddy_surface_mesh_def *def);

/* render_surface: the liquid surface drawn shaded (OSMesa, Phong with a
 * Fresnel rim: a simple water material), the colliders as grey meshes (box
 * and sphere colliders; a tank's walls are seen from inside, so the near
 * ones never hide the liquid), the domain's edges as lines; a PNG every
 * `every`-th frame. The camera fields mean what they mean in render_points.
 * Publishes render_ms, surface_ms and image. */
typedef struct eddy_render_surface_def {
	int width, height; /* px, image size, [1, 8192] */
	int supersample;   /* 1, samples per pixel along each axis, [1, 4] */
	eddy_vec3 eye;     /* m, camera position; eye == target frames the world's bounds */
	eddy_vec3 target;  /* m */
	eddy_vec3 up;      /* 1 */
	float fov;         /* degrees, (0, 180) */
	eddy_projection projection;
	float ortho_height;       /* m, 0 = fit the bounds */
	eddy_vec3 background;     /* 1, RGB in [0, 1] */
	float spacing;            /* m, as eddy_surface_def; > 0 */
	float support;            /* 1, as eddy_surface_def; [1, 4] */
	float voxel;              /* 1, as eddy_surface_def; [0.1, 1] */
	eddy_vec3 color;          /* 1, the water's RGB in [0, 1] */
	bool draw_colliders;      /* box and sphere colliders as meshes */
	eddy_vec3 collider_color; /* 1, RGB in [0, 1] */
	bool outline_domain;      /* the world's bounds as lines */
	eddy_vec3 outline_color;  /* 1, RGB in [0, 1] */
	char path[512];           /* printf pattern with one integer conversion (the frame), e.g. "out/s_%04d.png" */
	int every;                /* frames, >= 1 */
} eddy_render_surface_def;
EDDY_API eddy_render_surface_def eddy_default_render_surface_def(void);
EDDY_API eddy_system_id eddy_add_render_surface(eddy_world *w, const eddy_render_surface_def *def);

/* Side-by-side panels (render/compose.c, for eddy compare): the PNG files
 * images[0..panels-1] (NULL or "" for a panel with text only) in one row, each
 * captioned top-left with captions[i] (lines separated by '\n', wrapped to the
 * panel), written as one RGB PNG at path, whole or not at all (a temporary
 * file renamed into place). panel_w and panel_h are each panel's size in px;
 * 0 takes the largest image's (320 x 240 when none can be read). An image of
 * another size is centred, and cropped if larger; one that cannot be read
 * gets the reason in its caption. The panel size used goes to *out_w and
 * *out_h (either may be NULL). Returns 0, or -1 with the reason in err. */
EDDY_API int eddy_compose_panels(const char *path, int panels, const char *const *images, const char *const *captions,
                                 int panel_w, int panel_h, int *out_w, int *out_h, char *err, size_t cap);

#ifdef __cplusplus
}
#endif
#endif
