/* SPDX-License-Identifier: MIT */
/* eddy_collider_shape_of: what a collider looks like, for hosts that draw it
 * (the renderer's outlines). Signed distance alone cannot give edges cheaply,
 * so each built-in collider describes its own pose and size. Also the
 * dispatch to the colliders' SPH boundary particles (eddy__sph_collider_points). */
#include "core.h"

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
	if (s->vt->shape)
		s->vt->shape(s, out);
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
	return s->vt->sph_points ? s->vt->sph_points(w, s, spacing, h, x, y, z, vol, normal) : 0;
}
