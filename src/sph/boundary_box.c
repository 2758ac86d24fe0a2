/* SPDX-License-Identifier: MIT */
/* sph_boundary_box: the walls of a box as frozen fluid (boundary particles,
 * after Akinci et al. 2012). It has no step of its own: sph_density gathers
 * the particles of every sph_boundary_box in the pipeline into its neighbour
 * search and adds them to the density sum; sph_pressure mirrors the fluid
 * particle's pressure onto them. A fluid particle at a wall so sees a full
 * neighbourhood: it is neither sucked onto the wall nor held a gap away from
 * it, as plain clamping with a deficient density does (docs/validation.md C.2).
 *
 * Reads: nothing. Writes: nothing.
 * Layout: the fluid lattice continued through the walls. Points sit at
 * min + (i + 1/2) s_a on each axis (s_a = the spacing adjusted so a whole
 * number of cells spans the box), for i from -L to N_a + L - 1 with
 * L = ceil(h / spacing) layers, keeping only the points outside the box:
 * a shell as thick as the kernel support. A side thinner than half a spacing
 * has no inner cells: its layers start from its centre plane, so a thin
 * plate is a solid wall of 2L layers that a jet cannot pass. Each boundary particle stands for
 * the volume V_b = 1 / sum_lattice W of a lattice cell, so a fluid lattice at
 * rest flush with the wall sums to exactly rho0 up to the wall, with no
 * per-particle normalisation (Akinci's single layer with V_b = 1 / sum_k W_bk
 * over-weights particles closer than a spacing; the full shell does not). */
#include "sph.h"
#include "systems.h"

#include <stdlib.h>

typedef struct sph_boundary_box {
	eddy_sph_boundary_box_def def;
	int n[3];    /* lattice cells inside the box along each axis (0: thinner than a spacing) */
	float sp[3]; /* m, adjusted spacing along each axis */
	float o[3];  /* m, lattice origin: min, or the centre of a thin side */
} sph_boundary_box;

eddy_sph_boundary_box_def eddy_default_sph_boundary_box_def(void)
{
	eddy_sph_boundary_box_def d;
	d.min = eddy__v3(0, 0, 0);
	d.max = eddy__v3(1, 1, 1);
	d.spacing = 0.01f;
	return d;
}

size_t eddy__sph_boundary_box_points(const eddy_system *s, float h, float *x, float *y, float *z, float *vol)
{
	const sph_boundary_box *b = s->data;
	const int L = (int)ceil(h / b->def.spacing - 1e-4);
	const float v = (float)(1.0 / eddy_sph_lattice_sum(EDDY_SPH_POLY6, b->def.spacing, h));
	size_t k = 0;
	for (int iz = -L; iz < b->n[2] + L; ++iz)
		for (int iy = -L; iy < b->n[1] + L; ++iy)
			for (int ix = -L; ix < b->n[0] + L; ++ix) {
				if (ix >= 0 && ix < b->n[0] && iy >= 0 && iy < b->n[1] && iz >= 0 && iz < b->n[2])
					continue; /* inside the box: fluid's place */
				if (x) {
					x[k] = b->o[0] + ((float)ix + 0.5f) * b->sp[0];
					y[k] = b->o[1] + ((float)iy + 0.5f) * b->sp[1];
					z[k] = b->o[2] + ((float)iz + 0.5f) * b->sp[2];
					vol[k] = v;
				}
				k++;
			}
	return k;
}

const eddy_sph_boundary_box_def *eddy__sph_boundary_box_def(const eddy_system *s)
{
	return s && s->vt == &eddy__kind_sph_boundary_box ? &((const sph_boundary_box *)s->data)->def : NULL;
}

bool eddy__sph_boundary_box_covers(const eddy_system *s, eddy_vec3 min, eddy_vec3 max)
{
	if (!s || s->vt != &eddy__kind_sph_boundary_box)
		return false;
	const eddy_sph_boundary_box_def *d = &((const sph_boundary_box *)s->data)->def;
	return d->min.x == min.x && d->min.y == min.y && d->min.z == min.z && d->max.x == max.x && d->max.y == max.y &&
	       d->max.z == max.z;
}

const eddy_system_vtable eddy__kind_sph_boundary_box = {
	.name = "sph_boundary_box",
	.provides = EDDY_CAP_SPH_WALLS,
};

eddy_system_id eddy_add_sph_boundary_box(eddy_world *w, const eddy_sph_boundary_box_def *def)
{
	const char *sys = "sph_boundary_box";
	if (!eddy__add_args(w, def, sys))
		return EDDY_NULL_SYSTEM;
	if (!eddy__check_box(w, sys, def->min, def->max) || !eddy__check_positive(w, sys, "spacing", def->spacing))
		return EDDY_NULL_SYSTEM;
	const float ext[3] = {def->max.x - def->min.x, def->max.y - def->min.y, def->max.z - def->min.z};
	const float lo[3] = {def->min.x, def->min.y, def->min.z};
	/* a side thinner than a spacing (a thin plate) gets no inner cells:
	 * the layers of both faces meet at its centre */
	double cells[3], total = 1, inner = 1;
	for (int a = 0; a < 3; ++a) {
		cells[a] = round(ext[a] / def->spacing);
		if (cells[a] > 1e6)
			return eddy__fail(w, EDDY_ERR_NOMEM,
			                  "%s: the box is more than a million spacings long; use a larger spacing", sys),
			       EDDY_NULL_SYSTEM;
		total *= cells[a] + 10;
		inner *= cells[a];
	}
	if (total - inner > 2e9)
		return eddy__fail(w, EDDY_ERR_NOMEM, "%s: the box needs too many boundary particles; use a larger spacing",
		                  sys),
		       EDDY_NULL_SYSTEM;
	sph_boundary_box *b = calloc(1, sizeof *b);
	if (!b)
		return eddy__fail(w, EDDY_ERR_NOMEM, "%s: out of memory", sys), EDDY_NULL_SYSTEM;
	b->def = *def;
	for (int a = 0; a < 3; ++a) {
		b->n[a] = (int)cells[a];
		b->sp[a] = cells[a] > 0 ? (float)(ext[a] / cells[a]) : def->spacing;
		b->o[a] = cells[a] > 0 ? lo[a] : lo[a] + 0.5f * ext[a];
	}
	return eddy__add_system(w, &eddy__kind_sph_boundary_box, b, NULL, NULL);
}
