/* SPDX-License-Identifier: MIT */
/* What the colliders share: moving and rotating them (a pose set in a frame
 * hook reached over the frame's steps), their wall velocity
 * (v + omega x (x - pivot), omega from consecutive orientations over the
 * step), and the restitution/friction check. The contact response itself is inline in core.h. */
#include "systems.h"

bool eddy__is_collider(const eddy_system *s) { return s && s->vt && s->vt->distance != NULL; }

bool eddy__check_response(eddy_world *w, const char *sys, eddy_collider_response r)
{
	return eddy__check_range(w, sys, "restitution", r.restitution, 0, 1) &&
	       eddy__check_nonneg(w, sys, "friction", r.friction);
}

/* A glide that starts, stops or changes its pace moves the surface at most
 * COLLIDER_JERK length scales a step beyond the speed it was driven at,
 * whatever the cfl: SPH's walls see a step's motion one step late, so a wall
 * that starts at 3 m/s compresses the water in front by that speed times the
 * step before any pressure answers it. "Driven at" is the speed eased over
 * COLLIDER_EASE of a frame, the interval over which the Lua animate system
 * measures a function's change of speed (lua/eddy_lua.c: ANIMATE_JERK,
 * ANIMATE_SAMPLES): against the last step's speed alone, one short step
 * would do and the next would jump to the full pace. A paddle the host keyed
 * from rest to 3 m/s at a frame (set_offset in on_frame,
 * tests/scenes/piston.lua with keyed = true): DFSPH threw a quarter of a 0.1
 * m pool past 6 m/s, up to 28 m/s; with the last step's speed 14 m/s. */
#define COLLIDER_JERK 0.25
#define COLLIDER_EASE 0.125

void *eddy__collider_state(eddy_world *w, eddy_system *s, size_t *size)
{
	(void)w;
	eddy_collider_base *b = s->data;
	*size = sizeof b->motion;
	return &b->motion;
}

/* The eased speed and spin after a step of dt (eddy_collider_motion). */
static void ease(eddy_collider_motion *m, double dt, double frame)
{
	const double k = frame > 0 ? fmin(1.0, dt / (COLLIDER_EASE * frame)) : 1.0;
	m->speed_eased = (float)(m->speed_eased + (m->speed - (double)m->speed_eased) * k);
	m->spin_eased = (float)(m->spin_eased + (m->spin - (double)m->spin_eased) * k);
}

eddy_vec3 eddy__collider_step_velocity(eddy_collider_base *b, double dt, double frame)
{
	const eddy_collider_motion m = b->motion;
	const float inv = dt > 0 ? (float)(1.0 / dt) : 0.0f;
	b->motion.last_offset = m.offset;
	b->motion.last_rotation = m.rotation;
	b->motion.stepped = 1;
	const eddy_vec3 v = {(m.offset.x - m.last_offset.x) * inv, (m.offset.y - m.last_offset.y) * inv,
	                     (m.offset.z - m.last_offset.z) * inv};
	b->motion.speed = eddy__norm3(v);
	b->motion.spin = 0;
	ease(&b->motion, dt, frame);
	return v;
}

/* ---- rotation ----
 * Rotation vectors in degrees become unit quaternions (double) for the
 * relative rotation between two orientations, and a float matrix for
 * transforming points. */
#ifndef M_PI
#define M_PI 3.14159265358979323846
#endif

static void quat_of(eddy_vec3 rv, double q[4])
{
	const double ang = sqrt((double)rv.x * rv.x + (double)rv.y * rv.y + (double)rv.z * rv.z) * (M_PI / 180.0);
	if (!(ang > 0)) {
		q[0] = 1, q[1] = q[2] = q[3] = 0;
		return;
	}
	const double s = sin(0.5 * ang) / (ang * (180.0 / M_PI));
	q[0] = cos(0.5 * ang), q[1] = rv.x * s, q[2] = rv.y * s, q[3] = rv.z * s;
}

void eddy__rotation_matrix(eddy_vec3 rv, float r[9])
{
	double q[4];
	quat_of(rv, q);
	const double w = q[0], x = q[1], y = q[2], z = q[3];
	r[0] = (float)(1 - 2 * (y * y + z * z)), r[1] = (float)(2 * (x * y - w * z)), r[2] = (float)(2 * (x * z + w * y));
	r[3] = (float)(2 * (x * y + w * z)), r[4] = (float)(1 - 2 * (x * x + z * z)), r[5] = (float)(2 * (y * z - w * x));
	r[6] = (float)(2 * (x * z - w * y)), r[7] = (float)(2 * (y * z + w * x)), r[8] = (float)(1 - 2 * (x * x + y * y));
}

eddy_vec3 eddy__rotation_rate(eddy_vec3 from, eddy_vec3 to, double dt)
{
	if (!(dt > 0) || (from.x == to.x && from.y == to.y && from.z == to.z))
		return (eddy_vec3){0, 0, 0};
	double a[4], b[4];
	quat_of(to, a);
	quat_of(from, b);
	/* q = a * conj(b) */
	double q[4] = {
		a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + a[3] * b[3], -a[0] * b[1] + a[1] * b[0] - a[2] * b[3] + a[3] * b[2],
		-a[0] * b[2] + a[1] * b[3] + a[2] * b[0] - a[3] * b[1], -a[0] * b[3] - a[1] * b[2] + a[2] * b[1] + a[3] * b[0]};
	if (q[0] < 0)
		for (int k = 0; k < 4; ++k)
			q[k] = -q[k];
	const double sn = sqrt(q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
	if (!(sn > 0))
		return (eddy_vec3){0, 0, 0};
	const double ang = 2 * atan2(sn, q[0]), k = ang / (sn * dt);
	return (eddy_vec3){(float)(q[1] * k), (float)(q[2] * k), (float)(q[3] * k)};
}

eddy_collider_pose eddy__collider_pose(const eddy_collider_motion *m)
{
	eddy_collider_pose p;
	eddy__rotation_matrix(m->rotation, p.r);
	p.pivot = m->pivot;
	p.center = eddy__add3(m->pivot, m->offset);
	p.rotated = m->rotation.x != 0 || m->rotation.y != 0 || m->rotation.z != 0;
	return p;
}

eddy_collider_velocity eddy__collider_motion_since(const eddy_collider_motion *m, eddy_vec3 off0, eddy_vec3 rot0,
                                                   double dt)
{
	const double inv = dt > 0 ? 1.0 / dt : 0.0;
	eddy_collider_velocity v;
	v.v = (eddy_vec3){(float)((m->offset.x - off0.x) * inv), (float)((m->offset.y - off0.y) * inv),
	                  (float)((m->offset.z - off0.z) * inv)};
	v.omega = eddy__rotation_rate(rot0, m->rotation, dt);
	v.center = eddy__add3(m->pivot, m->offset);
	return v;
}

eddy_collider_velocity eddy__collider_step_motion(eddy_collider_base *b, double dt, double frame)
{
	const eddy_collider_velocity v =
		eddy__collider_motion_since(&b->motion, b->motion.last_offset, b->motion.last_rotation, dt);
	b->motion.last_offset = b->motion.offset;
	b->motion.last_rotation = b->motion.rotation;
	b->motion.stepped = 1;
	b->motion.speed = eddy__norm3(v.v);
	b->motion.spin = eddy__norm3(v.omega);
	ease(&b->motion, dt, frame);
	return v;
}

/* The farthest the collider's surface where particles can be lies from its
 * pivot: its shape's farthest point, within the world's box. */
static double reach(const eddy_world *w, const eddy_system *s, eddy_vec3 pivot)
{
	const eddy_vec3 lo = w->def.bounds_min, hi = w->def.bounds_max;
	double box = 0;
	for (int c = 0; c < 8; ++c) {
		const double dx = (c & 1 ? hi.x : lo.x) - pivot.x, dy = (c & 2 ? hi.y : lo.y) - pivot.y,
					 dz = (c & 4 ? hi.z : lo.z) - pivot.z;
		box = fmax(box, sqrt(dx * dx + dy * dy + dz * dz));
	}
	if (!s->vt->shape)
		return box;
	eddy_collider_shape sh = {0};
	s->vt->shape(s, &sh);
	double r = box;
	if (sh.kind == EDDY_COLLIDER_SPHERE)
		r = eddy__norm3((eddy_vec3){sh.a.x - pivot.x, sh.a.y - pivot.y, sh.a.z - pivot.z}) + (double)sh.radius;
	else if (sh.kind == EDDY_COLLIDER_BOX || sh.kind == EDDY_COLLIDER_MESH) {
		r = 0;
		for (int c = 0; c < 8; ++c)
			r = fmax(r,
			         eddy__norm3((eddy_vec3){(c & 1 ? sh.b.x : sh.a.x) - pivot.x, (c & 2 ? sh.b.y : sh.a.y) - pivot.y,
			                                 (c & 4 ? sh.b.z : sh.a.z) - pivot.z}));
	}
	return fmin(r, box);
}

double eddy__collider_limit(eddy_world *w, eddy_system *s, const char **reason)
{
	*reason = "moving wall";
	const eddy_collider_motion *m = &((const eddy_collider_base *)s->data)->motion;
	if (w->length_scale <= 0 || !m->stepped)
		return INFINITY;
	double v = m->speed, om = m->spin, pace = 0, spin = 0;
	const double due = isnan(m->goal_time) ? w->call_end : m->goal_time;
	const bool gliding = m->goal_time != 0 && due > w->time;
	if (gliding) { /* the glide's pace over the time left */
		const double left = due - w->time;
		const eddy_vec3 dof = {m->goal_offset.x - m->offset.x, m->goal_offset.y - m->offset.y,
		                       m->goal_offset.z - m->offset.z},
						dr = {m->goal_rotation.x - m->rotation.x, m->goal_rotation.y - m->rotation.y,
		                      m->goal_rotation.z - m->rotation.z};
		pace = eddy__norm3(dof) / left;
		spin = eddy__norm3(dr) * (M_PI / 180.0) / left;
		v = fmax(v, pace);
		om = fmax(om, spin);
	}
	if (!(v > 0) && !(om > 0))
		return INFINITY;
	const eddy_vec3 pivot = eddy__add3(m->pivot, m->offset);
	const double r = om > 0 ? reach(w, s, pivot) : 0;
	const double surface = v + om * r;
	double l = surface > 0 ? w->length_scale / surface : INFINITY;
	/* the glide's surface speed against the one it was driven at (a start, a stop) */
	const double jerk = gliding ? fabs((pace + spin * r) - ((double)m->speed_eased + (double)m->spin_eased * r)) : 0;
	if (jerk > 0 && COLLIDER_JERK * w->length_scale / jerk / w->def.cfl < l) {
		l = COLLIDER_JERK * w->length_scale / jerk / w->def.cfl;
		*reason = "moving wall starting";
	}
	return l;
}

static float lerpf(float a, float b, double t) { return (float)(a + (b - (double)a) * t); }

void eddy__collider_glide(eddy_collider_motion *m, double t, double dt, double end, double call_end, double eps)
{
	if (m->goal_time == 0)
		return;
	if (isnan(m->goal_time))
		m->goal_time = call_end;
	if (m->goal_time <= end + eps) {
		m->offset = m->goal_offset;
		m->rotation = m->goal_rotation;
		m->goal_time = 0;
		return;
	}
	const double frac = dt / (m->goal_time - t);
	const eddy_vec3 o = m->offset, go = m->goal_offset, r = m->rotation, gr = m->goal_rotation;
	m->offset = (eddy_vec3){lerpf(o.x, go.x, frac), lerpf(o.y, go.y, frac), lerpf(o.z, go.z, frac)};
	m->rotation = (eddy_vec3){lerpf(r.x, gr.x, frac), lerpf(r.y, gr.y, frac), lerpf(r.z, gr.z, frac)};
}

/* A pose set now: placed before the collider's first step and by a step's
 * own callbacks (the animated offset: the pose at this step's end), else
 * the goal of a glide. */
static bool set_as_goal(eddy_world *w, eddy_collider_motion *m)
{
	if (!m->stepped || w->busy == eddy__busy_step)
		return false;
	m->goal_time = w->busy == eddy__busy_frame ? eddy__next_frame_time(w) : NAN;
	return true;
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
	m->goal_offset = offset;
	if (set_as_goal(w, m))
		return EDDY_OK;
	m->offset = offset;
	if (!m->stepped)
		m->last_offset = offset; /* placing it before it ever ran is not motion */
	return EDDY_OK;
}

/* The collider behind id for a setter, with the world error set otherwise. */
static eddy_collider_motion *motion_for_set(eddy_world *w, eddy_system_id id, const char *fn, const char *field,
                                            eddy_vec3 v)
{
	if (!w)
		return NULL;
	if (!collider(w, id, fn, w))
		return NULL;
	eddy_system *s = eddy__system_get(w, id);
	if (!eddy__check_vec3(w, s->label, field, v))
		return NULL;
	return &((eddy_collider_base *)s->data)->motion;
}

eddy_status eddy_collider_set_rotation(eddy_world *w, eddy_system_id id, eddy_vec3 axis_angle)
{
	eddy_collider_motion *m = motion_for_set(w, id, "collider_set_rotation", "rotation", axis_angle);
	if (!m)
		return w && !eddy_system_valid(w, id) ? EDDY_ERR_STALE : EDDY_ERR_INVALID;
	/* beyond 1e6 degrees a float angle has lost whole degrees */
	const double deg2 =
		(double)axis_angle.x * axis_angle.x + (double)axis_angle.y * axis_angle.y + (double)axis_angle.z * axis_angle.z;
	if (!(deg2 <= 1e12)) {
		eddy__fail(w, EDDY_ERR_INVALID,
		           "%s: 'rotation' must be an axis-angle vector in degrees of length at most 1e6 (got {%g, %g, %g})",
		           eddy__system_get(w, id)->label, (double)axis_angle.x, (double)axis_angle.y, (double)axis_angle.z);
		return EDDY_ERR_INVALID;
	}
	m->goal_rotation = axis_angle;
	if (set_as_goal(w, m))
		return EDDY_OK;
	m->rotation = axis_angle;
	if (!m->stepped)
		m->last_rotation = axis_angle; /* placing it before it ever ran is not motion */
	return EDDY_OK;
}

eddy_status eddy_collider_get_rotation(const eddy_world *w, eddy_system_id id, eddy_vec3 *axis_angle)
{
	if (!w || !axis_angle)
		return EDDY_ERR_INVALID;
	const eddy_system *s = collider(w, id, "collider_get_rotation", NULL);
	if (!s)
		return eddy_system_valid(w, id) ? EDDY_ERR_INVALID : EDDY_ERR_STALE;
	*axis_angle = ((const eddy_collider_base *)s->data)->motion.goal_rotation;
	return EDDY_OK;
}

eddy_status eddy_collider_set_pivot(eddy_world *w, eddy_system_id id, eddy_vec3 pivot)
{
	eddy_collider_motion *m = motion_for_set(w, id, "collider_set_pivot", "pivot", pivot);
	if (!m)
		return w && !eddy_system_valid(w, id) ? EDDY_ERR_STALE : EDDY_ERR_INVALID;
	m->pivot = pivot;
	return EDDY_OK;
}

eddy_status eddy_collider_get_pivot(const eddy_world *w, eddy_system_id id, eddy_vec3 *pivot)
{
	if (!w || !pivot)
		return EDDY_ERR_INVALID;
	const eddy_system *s = collider(w, id, "collider_get_pivot", NULL);
	if (!s)
		return eddy_system_valid(w, id) ? EDDY_ERR_INVALID : EDDY_ERR_STALE;
	*pivot = ((const eddy_collider_base *)s->data)->motion.pivot;
	return EDDY_OK;
}

eddy_status eddy_collider_get_offset(const eddy_world *w, eddy_system_id id, eddy_vec3 *offset)
{
	if (!w || !offset)
		return EDDY_ERR_INVALID;
	const eddy_system *s = collider(w, id, "collider_get_offset", NULL);
	if (!s)
		return eddy_system_valid(w, id) ? EDDY_ERR_INVALID : EDDY_ERR_STALE;
	*offset = ((const eddy_collider_base *)s->data)->motion.goal_offset;
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
