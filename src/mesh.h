/* SPDX-License-Identifier: MIT */
/* Triangle meshes from files (assimp's C API) and their signed distance field,
 * for collide_mesh and emit_mesh (mesh.c). Not installed. */
#ifndef EDDY_MESH_H
#define EDDY_MESH_H

#include "core.h"

/* A triangle soup welded on exact positions, in world coordinates (scale,
 * rotation and translation applied), outward-facing when it is closed. */
typedef struct eddy_trimesh {
	int nv, nt;
	double (*v)[3]; /* m */
	int (*t)[3];
	double lo[3], hi[3]; /* m, bounding box */
	/* topology, from eddy__mesh_load: edges used by one triangle only,
	 * by more than two, and by two with the same direction (inconsistent
	 * winding); all zero for a closed, consistently oriented surface */
	int open_edges, nonmanifold_edges, flipped_edges;
	double volume; /* m^3, enclosed (by the divergence theorem, after orienting outward) */
} eddy_trimesh;

/* The pose a file's mesh is placed in: x' = R (scale * x) + translate, R the
 * rotation by |rotate| degrees about rotate / |rotate|. */
typedef struct eddy_mesh_pose {
	eddy_vec3 scale;     /* 1, each > 0 */
	eddy_vec3 rotate;    /* degrees, rotation vector */
	eddy_vec3 translate; /* m */
} eddy_mesh_pose;

/* Loads every triangle of every mesh in the file, placed by pose, welds
 * equal positions and finds the topology. A closed mesh wound inward is
 * turned outward. False with one line in err ("<path>: <why>") on failure. */
bool eddy__mesh_load(eddy_trimesh *m, const char *path, eddy_mesh_pose pose, char *err, size_t cap);
void eddy__mesh_free(eddy_trimesh *m);
bool eddy__mesh_closed(const eddy_trimesh *m);
/* The one-line reason a mesh is not closed, naming path; "" if it is. */
void eddy__mesh_describe_open(const eddy_trimesh *m, const char *path, char *err, size_t cap);

/* Inside flags of the samples origin + (i, j, k) h, i < n[0] fastest: 1 where
 * the winding number along +x is non-zero (exact for a closed mesh: ray
 * crossings with a consistent tie rule on shared edges). With vote (open
 * meshes) a sample is inside when at least four of the six axis-aligned
 * rays through it say so. False when scratch memory is short. */
bool eddy__mesh_inside(const eddy_trimesh *m, const double origin[3], double h, const int n[3], bool vote,
                       uint8_t *inside);

/* For the systems: checks a def's path and pose, loads the mesh; false
 * with the world error "<sys>: <path>: <why>" (sys_collide_mesh.c). */
bool eddy__mesh_from_def(eddy_world *w, const char *sys, const char *path, eddy_vec3 scale, eddy_vec3 rotate,
                         eddy_vec3 translate, eddy_trimesh *m);

/* A signed distance field on a node grid, < 0 inside the mesh. */
typedef struct eddy_sdf {
	double origin[3]; /* m, node (0, 0, 0) */
	double h;         /* m, node spacing */
	int n[3];         /* nodes per axis */
	float *d;         /* m, n[0] n[1] n[2] values, x fastest */
} eddy_sdf;

/* Sizes the field for m with `margin` cells around its box and node
 * spacing h; returns the node count, 0 when above 2^26. */
size_t eddy__sdf_plan(eddy_sdf *s, const eddy_trimesh *m, double h, int margin);
/* Fills s->d (allocated by the caller, eddy__sdf_plan's count): exact
 * point-triangle distances within two cells of every triangle's box, then
 * fast sweeping of each node's closest triangle (Batty's SDFGen); sign from
 * eddy__mesh_inside. The band is filled on `threads` threads with the same
 * result on any count. False when scratch memory is short. */
bool eddy__sdf_fill(eddy_sdf *s, const eddy_trimesh *m, bool vote, int threads);
/* Trilinear value at p; outside the grid, the value at the nearest grid
 * point plus the distance to it (outside the mesh there, so still a
 * distance bound with the right sign). */
float eddy__sdf_value(const eddy_sdf *s, eddy_vec3 p);

/* Exact distance from p to triangle t of m (Ericson, Real-Time Collision
 * Detection, 5.1.5). */
double eddy__mesh_triangle_distance(const eddy_trimesh *m, int t, const double p[3]);

#endif
