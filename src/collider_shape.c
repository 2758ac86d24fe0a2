/* SPDX-License-Identifier: MIT */
/* eddy_collider_shape_of: what a collider looks like, for hosts that draw it
 * (the renderer's outlines). Signed distance alone cannot give edges cheaply,
 * so each built-in collider describes its own pose and size. Also the
 * dispatch to the colliders' SPH boundary particles (eddy__sph_collider_points). */
#include "collider_shape.h"
#include "systems.h"

#include <string.h>

eddy_status eddy_collider_shape_of(const eddy_world *w, eddy_system_id id, eddy_collider_shape *out)
{
	if (!w || !out)
		return EDDY_ERR_INVALID;
	const eddy_system *s = eddy__system_peek(w, id);
	if (!s)
		return EDDY_ERR_STALE;
	if (!eddy__is_collider(s))
		return EDDY_ERR_INVALID;
	memset(out, 0, sizeof *out);
	if (s->vt == &eddy__kind_collide_box)
		eddy__shape_collide_box(s, out);
	else if (s->vt == &eddy__kind_collide_sphere)
		eddy__shape_collide_sphere(s, out);
	else if (s->vt == &eddy__kind_collide_plane)
		eddy__shape_collide_plane(s, out);
	else if (s->vt == &eddy__kind_collide_mesh)
		eddy__shape_collide_mesh(s, out);
	else
		out->kind = EDDY_COLLIDER_OTHER;
	return EDDY_OK;
}

/* ---- SPH boundary particles of the built-in colliders (sph.h) ---- */
#include "sph/sph.h"

size_t eddy__sph_collider_points(const eddy_world *w, const eddy_system *s, float spacing, float h, float *x, float *y,
                                 float *z, float *vol, eddy_vec3 *normal)
{
	*normal = eddy__v3(0, 0, 0);
	if (s->vt == &eddy__kind_collide_sphere)
		return eddy__sph_sphere_points(s, spacing, h, x, y, z, vol);
	if (s->vt == &eddy__kind_collide_plane)
		return eddy__sph_plane_points(w, s, spacing, h, x, y, z, vol, normal);
	if (s->vt == &eddy__kind_collide_box)
		return eddy__sph_box_points(w, s, spacing, h, x, y, z, vol);
	if (s->vt == &eddy__kind_collide_mesh)
		return eddy__sph_mesh_points(s, spacing, h, x, y, z, vol);
	return 0;
}
