/* SPDX-License-Identifier: MIT */
/* What the colliders share: moving them, their wall velocity, and the
 * restitution/friction check. The contact response itself is inline in core.h. */
#include "systems.h"

bool eddy__is_collider(const eddy_system *s) { return s && s->vt && s->vt->distance != NULL; }

bool eddy__check_response(eddy_world *w, const char *sys, eddy_collider_response r)
{
	return eddy__check_range(w, sys, "restitution", r.restitution, 0, 1) &&
	       eddy__check_nonneg(w, sys, "friction", r.friction);
}

void *eddy__collider_state(eddy_world *w, eddy_system *s, size_t *size)
{
	(void)w;
	eddy_collider_base *b = s->data;
	*size = sizeof b->motion;
	return &b->motion;
}

eddy_vec3 eddy__collider_step_velocity(eddy_collider_base *b, double dt)
{
	const eddy_collider_motion m = b->motion;
	const float inv = dt > 0 ? (float)(1.0 / dt) : 0.0f;
	b->motion.last_offset = m.offset;
	b->motion.stepped = true;
	return (eddy_vec3){(m.offset.x - m.last_offset.x) * inv, (m.offset.y - m.last_offset.y) * inv,
	                   (m.offset.z - m.last_offset.z) * inv};
}

/* The collider behind id, or NULL; errors go to err (NULL for const callers). */
static const eddy_system *collider(const eddy_world *w, eddy_system_id id, const char *what, eddy_world *err)
{
	const eddy_system *s = eddy__system_peek(w, id);
	if (!s) {
		eddy__fail(err, EDDY_ERR_STALE, "%s: stale or invalid system handle", what);
		return NULL;
	}
	if (!eddy__is_collider(s)) {
		eddy__fail(err, EDDY_ERR_INVALID, "%s: %s is not a collider", what, s->label);
		return NULL;
	}
	return s;
}

eddy_status eddy_collider_set_offset(eddy_world *w, eddy_system_id id, eddy_vec3 offset)
{
	if (!w)
		return EDDY_ERR_INVALID;
	if (!collider(w, id, "collider_set_offset", w))
		return eddy_system_valid(w, id) ? EDDY_ERR_INVALID : EDDY_ERR_STALE;
	eddy_system *s = eddy__system_get(w, id);
	if (!eddy__check_vec3(w, s->label, "offset", offset))
		return EDDY_ERR_INVALID;
	eddy_collider_motion *m = &((eddy_collider_base *)s->data)->motion;
	m->offset = offset;
	if (!m->stepped)
		m->last_offset = offset; /* placing it before it ever ran is not motion */
	return EDDY_OK;
}

eddy_status eddy_collider_get_offset(const eddy_world *w, eddy_system_id id, eddy_vec3 *offset)
{
	if (!w || !offset)
		return EDDY_ERR_INVALID;
	const eddy_system *s = collider(w, id, "collider_get_offset", NULL);
	if (!s)
		return eddy_system_valid(w, id) ? EDDY_ERR_INVALID : EDDY_ERR_STALE;
	*offset = ((const eddy_collider_base *)s->data)->motion.offset;
	return EDDY_OK;
}

eddy_status eddy_collider_distance(const eddy_world *w, eddy_system_id id, eddy_vec3 p, float *dist)
{
	if (!w || !dist)
		return EDDY_ERR_INVALID;
	const eddy_system *s = collider(w, id, "collider_distance", NULL);
	if (!s)
		return eddy_system_valid(w, id) ? EDDY_ERR_INVALID : EDDY_ERR_STALE;
	*dist = s->vt->distance(s, p);
	return EDDY_OK;
}
