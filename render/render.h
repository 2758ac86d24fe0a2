/* SPDX-License-Identifier: MIT */
/* Internals shared by the renderer's files. render/ sees only eddy.h: these
 * are its own pieces (GL context, colour maps, PNG writing, file helpers). */
#ifndef EDDY_RENDER_H
#define EDDY_RENDER_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>

#include "eddy.h"

/* ---- the GL context (gl_osmesa.c, the one file that includes OSMesa) ---- */

typedef struct eddy_gl eddy_gl;

/* A line segment list: 6 floats (two world points, m) per segment. */
typedef struct eddy_gl_lines {
	const float *xyz;
	size_t segments;
	float rgb[3]; /* 1 */
	float width;  /* px */
} eddy_gl_lines;

/* A triangle mesh lit per pixel (Phong, plus a Schlick Fresnel rim of
 * `fresnel` strength: 0 for matte grey, about 1 for water). Vertices and
 * normals 3 floats each; with cull_back only faces wound counter-clockwise
 * towards the camera are drawn. */
typedef struct eddy_gl_mesh {
	const float *xyz;    /* m */
	const float *normal; /* 1, unit */
	const uint32_t *tri; /* 3 per triangle */
	size_t triangles;
	float rgb[3];   /* 1, albedo */
	float specular; /* 1, highlight strength */
	float fresnel;  /* 1, rim strength */
	int cull_back;
} eddy_gl_mesh;

typedef struct eddy_gl_scene {
	float view[16], proj[16]; /* column-major, world to eye and eye to clip */
	float background[3];      /* 1, RGB */
	float light[3];           /* 1, unit direction to the light in eye space */
	float radius;             /* m */
	size_t count;             /* particles */
	const float *x, *y, *z;   /* m, positions, count each */
	const uint8_t *rgb;       /* colours, RGBA bytes per particle */
	const eddy_gl_lines *lines;
	int line_sets;
	const eddy_gl_mesh *meshes; /* depth-tested with the particles and lines */
	int mesh_sets;
} eddy_gl_scene;

/* NULL with the reason in err when no context can be made. */
eddy_gl *eddy_gl_create(int width, int height, char *err, size_t cap);
void eddy_gl_destroy(eddy_gl *g);
/* Draws the scene; returns 0 or -1 with the reason in err. The pixels are RGBA,
 * bottom row first, width*height*4 bytes, valid until the next draw. */
int eddy_gl_draw(eddy_gl *g, const eddy_gl_scene *s, char *err, size_t cap);
const uint8_t *eddy_gl_pixels(const eddy_gl *g);

/* ---- the camera and the frame around the scene (view.c), shared by
 * render_points and render_surface ---- */

static inline eddy_vec3 eddy_v3_sub(eddy_vec3 a, eddy_vec3 b) { return (eddy_vec3){a.x - b.x, a.y - b.y, a.z - b.z}; }
static inline eddy_vec3 eddy_v3_add(eddy_vec3 a, eddy_vec3 b) { return (eddy_vec3){a.x + b.x, a.y + b.y, a.z + b.z}; }
static inline eddy_vec3 eddy_v3_scale(eddy_vec3 a, float s) { return (eddy_vec3){a.x * s, a.y * s, a.z * s}; }
static inline float eddy_v3_dot(eddy_vec3 a, eddy_vec3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
static inline eddy_vec3 eddy_v3_cross(eddy_vec3 a, eddy_vec3 b)
{
	return (eddy_vec3){a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
float eddy_v3_len(eddy_vec3 a);
eddy_vec3 eddy_v3_norm(eddy_vec3 a); /* a / |a|, or a when zero */

/* What a camera is asked for: the fields render_points and render_surface share. */
typedef struct eddy_view_def {
	int width, height;         /* px, [1, 8192] */
	int supersample;           /* 1, [1, 4]; width and height times it <= 16384 */
	eddy_vec3 eye, target, up; /* m; eye == target frames the world's bounds */
	float fov;                 /* degrees, vertical */
	eddy_projection projection;
	float ortho_height; /* m, 0 = fit the bounds */
	float eye_pad;      /* m, extra distance of an automatic eye from the bounds */
	float depth_pad;    /* m, how far drawn things reach out of the bounds (near and far planes) */
} eddy_view_def;

typedef struct eddy_camera {
	eddy_vec3 eye, fwd, side, up; /* orthonormal frame */
	float view[16], proj[16];     /* column-major, world to eye and eye to clip */
} eddy_camera;

/* NULL when the image size, supersample, eye, target, up, fov, projection
 * and ortho_height are in range, else what is wrong (in buf, without the
 * system's name). */
const char *eddy_view_check(const eddy_view_def *d, char *buf, size_t cap);
/* The look-at view and the perspective or orthographic projection, near and
 * far planes fitted to the world's bounds. */
void eddy_camera_make(const eddy_view_def *d, const eddy_world_def *wd, eddy_camera *c);
/* The key light: a unit direction in eye space, from the upper left, in front. */
void eddy_key_light(float light[3]);
/* The 12 edges of a box, 6 floats each. */
void eddy_box_edges(float *out, eddy_vec3 lo, eddy_vec3 hi);
/* Turns n points (3 floats each) by a rotation vector in degrees about pivot
 * (a collider shape's rotation); a direction turns with pivot 0. */
void eddy_rotate_points(float *xyz, size_t n, eddy_vec3 rotation, eddy_vec3 pivot);
/* Box-filters RGBA rows (bottom row first, W*s by H*s) down to RGB (top row
 * first, W by H), output rows [y0, y1) only. */
void eddy_downsample_rows(const uint8_t *rgba, int W, int H, int s, uint8_t *out, int y0, int y1);
/* The same for output columns [x0, x1) of rows [y0, y1) only. */
void eddy_downsample_block(const uint8_t *rgba, int W, int H, int s, uint8_t *out, int y0, int y1, int x0, int x1);
/* 1 when the colour components are all in [0, 1]. */
int eddy_color_ok(eddy_vec3 c);

/* ---- CPU point sprites and lines (splat.c) ---- */

/* The side of splat.c's square tiles, output pixels. */
#define EDDY_SPLAT_TILE 8

/* A particle as splat.c draws it, projected once per frame. */
typedef struct eddy_splat_sprite {
	float xw, yw; /* px, the centre's window position */
	float size;   /* px, the point size, >= 1 */
	float ez;     /* m, the centre's eye-space z (negative in front of the eye) */
	uint8_t rgba[4];
} eddy_splat_sprite;

/* A colour and depth buffer drawn on the CPU: render_points' sprites shaded
 * exactly as gl_osmesa.c's sprite shader does, and its lines, without GL.
 * The rows are split into `threads` bands, each drawn by its own thread
 * through every particle in order, so the image does not depend on the
 * thread count. */
typedef struct eddy_splat {
	int width, height; /* px */
	uint8_t *rgba;     /* bottom row first, as eddy_gl_pixels */
	float *depth;      /* distance along the view axis, m: the depth test's key */
	/* the particles that reach the buffer, projected once per frame and
	 * sorted near to far (unsorted: in the particles' order, culled ones
	 * with size 0); reused between frames */
	eddy_splat_sprite *sprites, *unsorted;
	size_t sprite_count, sprite_cap;
	/* square tiles of EDDY_SPLAT_TILE output pixels (times the supersample):
	 * whether anything is drawn in each, and the farthest depth it holds
	 * (valid unless dirty) */
	uint8_t *tile_used, *tile_dirty;
	float *tile_far;
	size_t tile_cap;
	bool scalar; /* draw one pixel at a time even where AVX2 is there (the tests compare the two) */
} eddy_splat;

/* 0, or -1 when out of memory. */
int eddy_splat_init(eddy_splat *s, int width, int height);
void eddy_splat_free(eddy_splat *s);
/* Draws the scene's particles and lines (meshes are GL's alone: mesh_sets
 * must be 0) and, with out != NULL, box-filters by ss into out (RGB, top row
 * first, width/ss by height/ss); then only the tiles anything was drawn in
 * hold this frame's pixels in rgba and depth, while with out == NULL all of
 * them do. 0, or -1 with the reason in err. */
int eddy_splat_draw(eddy_splat *s, const eddy_gl_scene *scene, int threads, int ss, uint8_t *out, char *err,
                    size_t cap);

/* ---- colour maps (colormap.c) ---- */

/* RGB bytes of t in [0, 1] (clamped; NaN gives the bottom colour). */
void eddy_colormap_rgb(eddy_colormap map, float t, uint8_t rgb[3]);

/* ---- files (files.c) ---- */

/* Checks a path pattern: exactly one integer conversion (%d, %05d, %i, %u),
 * '%%' allowed. Returns NULL or what is wrong. */
const char *eddy_check_frame_pattern(const char *pattern);
/* Formats the pattern for a frame into out; -1 if it does not fit. */
int eddy_frame_path(const char *pattern, int frame, char *out, size_t cap);
/* Creates the parent directories of path (like mkdir -p); 0 or -1 (errno). */
int eddy_make_parent_dirs(const char *path);
/* Writes RGB rows (top row first) as PNG, whole or not at all (eddy_file);
 * 0 or an errno value. (png.c: libpng, fast settings) */
int eddy_write_png(const char *path, int width, int height, const uint8_t *rgb);

/* A file written whole or not at all: the bytes go to a hidden temporary file
 * in the final file's folder (".NAME.PID-N.tmp"), every write, the flush and
 * the close are checked, and only when all succeeded is it renamed over the
 * final name; on any failure the temporary file is removed and the final name
 * keeps whatever it held before. (Not fsync'ed: a power loss may still lose
 * the newest file, but never leaves a short one under the final name from a
 * failed write.) Usage: begin; write/printf (no-ops once one failed); finish
 * (or abort). err holds the first failure's errno. */
typedef struct eddy_file {
	FILE *f;
	const char *path; /* the final name: the caller's string, alive until finish */
	char tmp[1100];
	int err; /* errno of the first failure, 0 while all succeeded */
} eddy_file;

/* Creates the parent folders and the temporary file; 0 or an errno value. */
int eddy_file_begin(eddy_file *o, const char *path);
void eddy_file_write(eddy_file *o, const void *p, size_t n);
void eddy_file_printf(eddy_file *o, const char *fmt, ...)
#if defined(__GNUC__)
	__attribute__((format(printf, 2, 3)))
#endif
	;
/* Flushes, closes, and renames into place; 0 or the first failure's errno
 * (then the temporary file is gone). */
int eddy_file_finish(eddy_file *o);
/* Closes and removes the temporary file (for failures found by the caller). */
void eddy_file_abort(eddy_file *o);

/* Particle values by channel name: "speed" is computed into scratch (count
 * floats), other names are columns. NULL if the channel is missing. */
const float *eddy_particle_values(const eddy_world *w, const char *name, float *scratch, size_t count);

/* ---- the liquid surface (surface_mesh.c) ---- */

/* A surface system's mesh and the state it was meshed from. surface_mesh's
 * and render_surface's user data start with one, so a frame's surface is
 * meshed once when both are in a world with the same fields. */
typedef struct eddy_surface_cache {
	eddy_surface_def def;
	eddy_mesh mesh;
	bool valid; /* mesh is of the state stamped below */
	int frame;
	int64_t steps;
	double time; /* s */
	size_t particles;
} eddy_surface_cache;

/* The surface of w's current state: another surface system's mesh when one
 * meshed this very state with the same def this frame, else c's own, meshed
 * now. *ms is the meshing time, ms, or -1 when the mesh was shared. */
eddy_status eddy_surface_of_frame(eddy_world *w, eddy_surface_cache *c, int frame, const eddy_mesh **out, double *ms);
/* The systems' frame hooks, by which eddy_surface_of_frame finds their data. */
eddy_status eddy_surface_mesh_frame(eddy_world *w, int frame, void *user);
eddy_status eddy_render_surface_frame(eddy_world *w, int frame, void *user);

/* NULL when spacing, support and voxel are in range, else what is wrong (in buf). */
const char *eddy_check_surface_fields(float spacing, float support, float voxel, char *buf, size_t cap);
/* Monotonic clock, ms. */
double eddy_now_ms(void);

#endif
