/* SPDX-License-Identifier: MIT */
/* The OpenVDB side of the liquid surface (surface_vdb.cpp), behind a C
 * interface: the one C++ translation unit of the library. surface.c checks
 * the def and reads the world; this builds the field, meshes it and writes
 * the level set. Nothing here throws: every failure is a return of -1 with
 * the reason in err. */
#ifndef EDDY_SURFACE_H
#define EDDY_SURFACE_H

#include <stddef.h>

#include "eddy.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef struct eddy__surface_params {
	float spacing; /* m, particle spacing; the particle volume is spacing^3 */
	float support; /* m, kernel support radius */
	float voxel;   /* m, voxel size */
	int threads;   /* TBB worker threads */
} eddy__surface_params;

/* Rasterises the colour field of the n particles (x, y, z) into a sparse
 * grid, extracts its 0.5 isosurface into mesh (buffers grown with realloc,
 * the field kept in mesh->field for eddy__surface_write_vdb). 0 or -1. */
int eddy__surface_build(const float *x, const float *y, const float *z, size_t n, const eddy__surface_params *p,
                        eddy_mesh *mesh, char *err, size_t cap);
/* Meshes the zero level of signed distances d sampled at origin + (i, j, k)
 * dx (d[(i ny + j) nz + k], dims = nx ny nz; negative inside), normals
 * pointing out (up the distance). 0 or -1. */
int eddy__surface_from_samples(const float *d, const int dims[3], const float origin[3], float dx, eddy_mesh *mesh,
                               char *err, size_t cap);
/* Writes the field of the last build as a narrow-band level set (signed
 * distance, m) named "surface" to path, whole or not at all. 0 or -1. */
int eddy__surface_write_vdb(const eddy_mesh *mesh, const char *path, char *err, size_t cap);
/* Frees what mesh->field holds (NULL is fine). */
void eddy__surface_free_field(void *field);

#ifdef __cplusplus
}
#endif
#endif
