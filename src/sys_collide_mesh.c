/* SPDX-License-Identifier: MIT */
/* collide_mesh: a triangle mesh from a file as a solid (inside = false) or as
 * a closed tank the fluid stays in (inside = true).
 *
 * Reads: x y z vx vy vz. Writes: x y z vx vy vz.
 * The mesh is loaded, checked and turned into a signed distance field phi
 * once, when the system is added (mesh.c): phi < 0 in the mesh, trilinear
 * between nodes. The collider's distance is phi(p - offset), negated for a
 * tank. Meshes have thin walls (a cup's is a few particles thick), which a
 * particle can cross, or pass more than half through, in one step; so a
 * particle that moved more than a quarter cell this step (relative to the
 * collider) has its path x - v dt -> x walked half a cell at a time, and
 * if it entered the solid it goes back to where it entered (bisection) and
 * on along the surface there by the rest of the path less its part into the
 * solid (slide, below). Otherwise, a particle with distance d < 0 stays
 * where it is. It then
 * moves along n = grad d / |grad d| (central differences half a cell wide)
 * by (2e-3 cells - d) / |grad d|, a Newton step to d = 2e-3 cells (so
 * rounding cannot leave it inside; |grad d| is under 1 in a crease),
 * repeated up to four times where the field bends, then on along n in steps
 * doubling up to a cell where the field is flat along it (still inside after that, in a crease
 * where the steps bounce between two faces, it goes back to where its path
 * entered the solid, when the path started outside), and gets the contact response (core.h)
 * with normal n and the collider's velocity. x - v dt is exactly the last
 * position after integrate (v the velocity it moved with) and close to it
 * after flip_advect. A rotating mesh does the same in its own frame (x_b =
 * pivot + R^T (x - pivot - offset)), the path's start taken in the pose of
 * the last step, the normal turned back by R, and the wall velocity
 * v + omega x (x - pivot - offset). The field is the only state besides the motion; a
 * scene without collide_mesh allocates none of it. */
#include "mesh.h"
#include "sph/sph.h"
#include "systems.h"

#include <stdlib.h>
#include <string.h>

/* The least slope a push divides by: where the field is nearly flat (a
 * ridge of the distance, between two faces) a step is at most 4x the
 * distance. */
#define MESH_MIN_SLOPE 0.25f

typedef struct collide_mesh {
	eddy_collider_base base; /* first: shared offset handling */
	eddy_collide_mesh_def def;
	eddy_sdf sdf;
	double volume; /* m^3 */
	float depth;   /* m, the deepest node inside the solid: half its thickest part */
	float field[]; /* the distance grid's values (sdf.d) */
} collide_mesh;

static const int mesh_io[] = {COL_X_, COL_Y_, COL_Z_, COL_VX, COL_VY, COL_VZ, -1};

eddy_collide_mesh_def eddy_default_collide_mesh_def(void)
{
	eddy_collide_mesh_def d;
	memset(&d, 0, sizeof d);
	d.scale = eddy__v3(1, 1, 1);
	d.inside = false;
	d.open = false;
	d.cell_size = 0;
	return d;
}

static float sdistance(const collide_mesh *b, eddy_vec3 q)
{
	if (eddy__motion_rotates(&b->base.motion)) {
		const eddy_collider_pose pose = eddy__collider_pose(&b->base.motion);
		const float d = eddy__sdf_value(&b->sdf, eddy__pose_to_body(&pose, q));
		return b->def.inside ? -d : d;
	}
	const eddy_vec3 o = b->base.motion.offset;
	const float d = eddy__sdf_value(&b->sdf, eddy__v3(q.x - o.x, q.y - o.y, q.z - o.z));
	return b->def.inside ? -d : d;
}

static float distance(const eddy_system *s, eddy_vec3 q) { return sdistance(s->data, q); }

/* Unit normal out of the solid at q, (0, 1, 0) where the field is flat;
 * with slope, also the field's slope along it (1 on a face, under 1 in a
 * crease: 0.71 in a right-angled one). */
static eddy_vec3 normal(const collide_mesh *b, eddy_vec3 q, float *slope)
{
	const float e = 0.5f * (float)b->sdf.h;
	eddy_vec3 g = {sdistance(b, eddy__v3(q.x + e, q.y, q.z)) - sdistance(b, eddy__v3(q.x - e, q.y, q.z)),
	               sdistance(b, eddy__v3(q.x, q.y + e, q.z)) - sdistance(b, eddy__v3(q.x, q.y - e, q.z)),
	               sdistance(b, eddy__v3(q.x, q.y, q.z + e)) - sdistance(b, eddy__v3(q.x, q.y, q.z - e))};
	const float len = sqrtf(g.x * g.x + g.y * g.y + g.z * g.z);
	if (slope)
		*slope = len / (2 * e);
	if (!(len > 0))
		return eddy__v3(0, 1, 0);
	return eddy__v3(g.x / len, g.y / len, g.z / len);
}

/* Field value in the collider's own frame (no offset). */
static float body_distance(const collide_mesh *b, eddy_vec3 q)
{
	const float d = eddy__sdf_value(&b->sdf, q);
	return b->def.inside ? -d : d;
}

/* Where the segment a -> c (collider frame) first enters the solid, when a
 * is outside: samples half a cell apart, then bisection; false if it never
 * does. */
static bool first_entry(const collide_mesh *b, eddy_vec3 a, eddy_vec3 c, eddy_vec3 *hit)
{
	if (!(body_distance(b, a) >= 0))
		return false;
	const eddy_vec3 dv = {c.x - a.x, c.y - a.y, c.z - a.z};
	const float len = sqrtf(dv.x * dv.x + dv.y * dv.y + dv.z * dv.z);
	const int n = (int)fminf(ceilf(len / (0.5f * (float)b->sdf.h)), 256.0f);
	float t0 = 0;
	for (int k = 1; k <= n; ++k) {
		float t1 = (float)k / (float)n;
		if (body_distance(b, eddy__v3(a.x + t1 * dv.x, a.y + t1 * dv.y, a.z + t1 * dv.z)) < 0) {
			for (int it = 0; it < 24; ++it) {
				const float tm = 0.5f * (t0 + t1);
				if (body_distance(b, eddy__v3(a.x + tm * dv.x, a.y + tm * dv.y, a.z + tm * dv.z)) < 0)
					t1 = tm;
				else
					t0 = tm;
			}
			*hit = eddy__v3(a.x + t0 * dv.x, a.y + t0 * dv.y, a.z + t0 * dv.z);
			return true;
		}
		t0 = t1;
	}
	return false;
}

/* Unit normal out of the solid at body-frame q, (0, 1, 0) where flat; with
 * slope, as normal. */
static eddy_vec3 body_normal(const collide_mesh *b, eddy_vec3 q, float *slope)
{
	const float e = 0.5f * (float)b->sdf.h;
	eddy_vec3 g = {body_distance(b, eddy__v3(q.x + e, q.y, q.z)) - body_distance(b, eddy__v3(q.x - e, q.y, q.z)),
	               body_distance(b, eddy__v3(q.x, q.y + e, q.z)) - body_distance(b, eddy__v3(q.x, q.y - e, q.z)),
	               body_distance(b, eddy__v3(q.x, q.y, q.z + e)) - body_distance(b, eddy__v3(q.x, q.y, q.z - e))};
	const float len = sqrtf(g.x * g.x + g.y * g.y + g.z * g.z);
	if (slope)
		*slope = len / (2 * e);
	if (!(len > 0))
		return eddy__v3(0, 1, 0);
	return eddy__v3(g.x / len, g.y / len, g.z / len);
}

/* Pushes body-frame point q, at field value *d, out of the solid along the
 * field's normal to *d >= hair where it can; returns the last normal (q's
 * own when it needs no push). Up to four Newton steps on d (in a crease the
 * field rises slower than the distance moved: the distance alone left a particle that began
 * the step in the cup's inner corner, with no entry point to go back to,
 * 1e-6 m in the solid after four), then, where the field is flat along n
 * (trilinear values of a crease have no slope along its bisector at a node
 * near it: the cube's edge held particles 0.2 mm in after the four), on
 * along n in steps doubling up to a field cell. off: the normal taken at q
 * + off in the world (a collider that only translates), else in the body
 * frame; the same field either way, the world's as step has always read it. */
static eddy_vec3 push_out(const collide_mesh *b, eddy_vec3 *q, float *d, float hair, const eddy_vec3 *off)
{
	float slope;
	eddy_vec3 nrm = off ? normal(b, eddy__add3(*q, *off), &slope) : body_normal(b, *q, &slope);
	for (int it = 0; it < 4 && *d < hair; ++it) {
		if (it > 0)
			nrm = off ? normal(b, eddy__add3(*q, *off), &slope) : body_normal(b, *q, &slope);
		const float k = (2 * hair - *d) / eddy__maxf(slope, MESH_MIN_SLOPE);
		*q = eddy__v3(q->x + nrm.x * k, q->y + nrm.y * k, q->z + nrm.z * k);
		*d = body_distance(b, *q);
	}
	for (float k = 2 * hair - *d; *d < hair && k <= (float)b->sdf.h; k *= 2) {
		*q = eddy__v3(q->x + nrm.x * k, q->y + nrm.y * k, q->z + nrm.z * k);
		*d = body_distance(b, *q);
	}
	return nrm;
}

/* Where a path that entered the solid at hit (body frame, the path ending
 * at c) goes: on from hit along the surface by the rest of its length less
 * the rest's part into the solid (the normal at hit), as a particle pressed
 * against a face slides along it. Stopping at hit instead held such a
 * particle still while its speed along the face grew (a particle on a mesh
 * ramp under gravity: every step's path starts on the face and dips in).
 * A slide that ends inside by at most walk (the field's bend over it) is
 * left to push_out, as a slow particle is; deeper (a corner, where it runs
 * into a second face) it ends where it enters, or at hit. */
static eddy_vec3 slide(const collide_mesh *b, eddy_vec3 hit, eddy_vec3 c, float walk)
{
	const eddy_vec3 n = body_normal(b, hit, NULL);
	eddy_vec3 r = {c.x - hit.x, c.y - hit.y, c.z - hit.z};
	const float rn = r.x * n.x + r.y * n.y + r.z * n.z;
	if (rn < 0)
		r = eddy__v3(r.x - rn * n.x, r.y - rn * n.y, r.z - rn * n.z);
	const eddy_vec3 q = eddy__add3(hit, r);
	if (!(body_distance(b, q) < -walk))
		return q;
	eddy_vec3 hit2;
	return first_entry(b, hit, q, &hit2) ? hit2 : hit;
}

/* A rotating mesh: as step below, in the mesh's own frame. The path starts
 * at x - v dt seen in the pose of the collider's last step and ends at x in
 * the current pose, so a wall sweeping over a particle is caught as a
 * particle crossing it. */
static void step_rotated(eddy_world *w, collide_mesh *b, const eddy_collider_motion *then,
                         const eddy_collider_velocity *mv, double dt_step, int threads)
{
	const eddy_collider_pose pose = eddy__collider_pose(&b->base.motion), pose0 = eddy__collider_pose(then);
	float *x = eddy__col(w, COL_X_), *y = eddy__col(w, COL_Y_), *z = eddy__col(w, COL_Z_);
	float *vx = eddy__col(w, COL_VX), *vy = eddy__col(w, COL_VY), *vz = eddy__col(w, COL_VZ);
	const eddy_collider_response r = b->def.response;
	const float hair = 1e-3f * (float)b->sdf.h, dt = (float)dt_step, walk = 0.25f * (float)b->sdf.h;
	const long n = (long)w->n;
#pragma omp parallel for num_threads(threads) if (n > 8192) schedule(static)
	for (long i = 0; i < n; ++i) {
		const eddy_vec3 pw = eddy__off_walls(w, eddy__v3(x[i], y[i], z[i]), hair); /* core.h */
		const eddy_vec3 c = eddy__pose_to_body(&pose, pw);
		const eddy_vec3 c0 =
			eddy__pose_to_body(&pose0, eddy__v3(pw.x - vx[i] * dt, pw.y - vy[i] * dt, pw.z - vz[i] * dt));
		const eddy_vec3 dp = {c.x - c0.x, c.y - c0.y, c.z - c0.z};
		float d = body_distance(b, c);
		const float len2 = dp.x * dp.x + dp.y * dp.y + dp.z * dp.z;
		const bool fast = len2 > walk * walk;
		if (!(d < 0) && (!fast || d * d > 3 * len2))
			continue;
		eddy_vec3 q = c, hit;
		if (fast && first_entry(b, c0, c, &hit))
			q = slide(b, hit, c, walk), d = body_distance(b, q);
		else if (!(d < 0))
			continue;
		eddy_vec3 nrm = push_out(b, &q, &d, hair, NULL);
		if (d < 0 && first_entry(b, c0, c, &hit))
			q = hit; /* in a crease the steps did not get out: where the path entered */
		/* out of the mesh through the world's wall (core.h): where the path
		 * entered the mesh instead, else the nearest point inside */
		if (eddy__outside_box(w, eddy__pose_to_world(&pose, q)) && first_entry(b, c0, c, &hit) &&
		    !eddy__outside_box(w, eddy__pose_to_world(&pose, hit)))
			q = hit, nrm = body_normal(b, q, NULL);
		eddy__collide_rotated_in(w, x, y, z, vx, vy, vz, (size_t)i, &pose, mv, q, nrm, r);
	}
}

static eddy_status step(eddy_world *w, eddy_system *s, const eddy_step_context *ctx)
{
	collide_mesh *b = s->data;
	if (eddy__motion_rotates(&b->base.motion)) {
		eddy_collider_motion then = b->base.motion;
		then.offset = then.last_offset, then.rotation = then.last_rotation;
		const eddy_collider_velocity mv = eddy__collider_step_motion(&b->base, ctx->dt, 1.0 / w->def.fps);
		step_rotated(w, b, &then, &mv, ctx->dt, ctx->threads);
		return EDDY_OK;
	}
	const eddy_vec3 vw = eddy__collider_step_velocity(&b->base, ctx->dt, 1.0 / w->def.fps);
	const eddy_vec3 off = b->base.motion.offset;
	float *x = eddy__col(w, COL_X_), *y = eddy__col(w, COL_Y_), *z = eddy__col(w, COL_Z_);
	float *vx = eddy__col(w, COL_VX), *vy = eddy__col(w, COL_VY), *vz = eddy__col(w, COL_VZ);
	const eddy_collider_response r = b->def.response;
	const float hair = 1e-3f * (float)b->sdf.h, dt = (float)ctx->dt, walk = 0.25f * (float)b->sdf.h;
	const long n = (long)w->n;
#pragma omp parallel for num_threads(ctx->threads) if (n > 8192) schedule(static)
	for (long i = 0; i < n; ++i) {
		/* this step's path in the collider's frame: from where the particle
		 * was (x - v dt, the collider then at off - vw dt) to where it is */
		const eddy_vec3 pw = eddy__off_walls(w, eddy__v3(x[i], y[i], z[i]), hair); /* core.h */
		const eddy_vec3 c = {pw.x - off.x, pw.y - off.y, pw.z - off.z};
		const eddy_vec3 dp = {(vx[i] - vw.x) * dt, (vy[i] - vw.y) * dt, (vz[i] - vw.z) * dt};
		float d = body_distance(b, c);
		const float len2 = dp.x * dp.x + dp.y * dp.y + dp.z * dp.z;
		const bool fast = len2 > walk * walk;
		/* trilinear values of a distance change by at most sqrt 3 times the
		 * distance moved: a path ending further out never touched the solid */
		if (!(d < 0) && (!fast || d * d > 3 * len2))
			continue;
		eddy_vec3 q = c, hit;
		/* a path that entered the solid (or crossed a wall thinner than it)
		 * ends where it entered: projection to the nearest surface would put
		 * a particle that went more than half through on the far side */
		if (fast && first_entry(b, eddy__v3(c.x - dp.x, c.y - dp.y, c.z - dp.z), c, &hit))
			q = slide(b, hit, c, walk), d = body_distance(b, q);
		else if (!(d < 0))
			continue;
		eddy_vec3 nrm = push_out(b, &q, &d, hair, &off);
		const eddy_vec3 c0 = {c.x - dp.x, c.y - dp.y, c.z - dp.z};
		if (d < 0 && first_entry(b, c0, c, &hit))
			q = hit; /* in a crease the steps did not get out: where the path entered */
		eddy_vec3 p = eddy__add3(q, off);
		if (eddy__outside_box(w, p)) {
			/* out of the mesh through the world's wall (core.h): where the
			 * path entered the mesh instead, else the nearest point inside */
			if (first_entry(b, c0, c, &hit) && !eddy__outside_box(w, eddy__add3(hit, off)))
				p = eddy__add3(hit, off), nrm = normal(b, p, NULL);
			else
				p = eddy__into_box(w, p);
		}
		x[i] = p.x, y[i] = p.y, z[i] = p.z;
		eddy__collide_response(vx, vy, vz, (size_t)i, nrm, vw, r);
	}
	return EDDY_OK;
}

/* Preflight: FLIP types a cell solid by its centre and weights faces by
 * their open area, so a solid nowhere two grid cells thick has cells that
 * straddle it, and the grid's velocity can carry particles through. */
static int check(eddy_world *w, const eddy_system *s, eddy_check_fn report, void *user)
{
	const collide_mesh *b = s->data;
	const double h = w->def.cell_size;
	if (h > 0 && !b->def.inside && 2 * b->depth < 2 * h)
		eddy__report(report, user, EDDY_CHECK_WARNING,
		             "%s: %s is nowhere thicker than %.2g m, %.2g grid cells: FLIP can carry particles through "
		             "walls under two cells thick; use cell_size <= %.2g m or thicker walls",
		             s->label, b->def.path, 2.0 * b->depth, 2.0 * b->depth / h, (double)b->depth);
	return 0;
}

static void shape(const eddy_system *s, eddy_collider_shape *out);
static size_t sph_points(const eddy_world *w, const eddy_system *s, float spacing, float h, float *x, float *y,
                         float *z, float *vol, eddy_vec3 *normal);

const eddy_system_vtable eddy__kind_collide_mesh = {
	.name = "collide_mesh",
	.check = check,
	.step = step,
	.state = eddy__collider_state,
	.limit = eddy__collider_limit,
	.provides = EDDY_CAP_COLLIDER,
	.distance = distance,
	.shape = shape,
	.sph_points = sph_points,
	.default_writes = mesh_io,
};

static bool check_pose(eddy_world *w, const char *sys, eddy_vec3 scale, eddy_vec3 rotate, eddy_vec3 translate)
{
	if (!eddy__check_vec3(w, sys, "scale", scale) || !eddy__check_vec3(w, sys, "rotate", rotate) ||
	    !eddy__check_vec3(w, sys, "translate", translate))
		return false;
	if (!(scale.x > 0 && scale.y > 0 && scale.z > 0)) {
		eddy__fail(w, EDDY_ERR_INVALID, "%s: 'scale' must be > 0 on every axis (got {%g, %g, %g})", sys,
		           (double)scale.x, (double)scale.y, (double)scale.z);
		return false;
	}
	return true;
}

bool eddy__mesh_from_def(eddy_world *w, const char *sys, const char *path, eddy_vec3 scale, eddy_vec3 rotate,
                         eddy_vec3 translate, eddy_trimesh *m)
{
	if (!memchr(path, '\0', 512) || !path[0]) {
		eddy__fail(w, EDDY_ERR_INVALID, "%s: 'path' must name a mesh file", sys);
		return false;
	}
	if (!check_pose(w, sys, scale, rotate, translate))
		return false;
	char err[EDDY_ERROR_MAX - 64];
	if (!eddy__mesh_load(m, path, (eddy_mesh_pose){scale, rotate, translate}, err, sizeof err)) {
		eddy__fail(w, EDDY_ERR_IO, "%s: %s", sys, err);
		return false;
	}
	return true;
}

eddy_system_id eddy_add_collide_mesh(eddy_world *w, const eddy_collide_mesh_def *def)
{
	const char *sys = "collide_mesh";
	if (!eddy__add_args(w, def, sys))
		return EDDY_NULL_SYSTEM;
	if (!eddy__check_nonneg(w, sys, "cell_size", def->cell_size) || !eddy__check_response(w, sys, def->response))
		return EDDY_NULL_SYSTEM;
	eddy_trimesh m;
	if (!eddy__mesh_from_def(w, sys, def->path, def->scale, def->rotate, def->translate, &m))
		return EDDY_NULL_SYSTEM;
	char err[EDDY_ERROR_MAX - 64];
	if (!def->open && !eddy__mesh_closed(&m)) {
		eddy__mesh_describe_open(&m, def->path, err, sizeof err);
		eddy__mesh_free(&m);
		eddy__fail(w, EDDY_ERR_INVALID, "%s: %s", sys, err);
		return EDDY_NULL_SYSTEM;
	}
	/* the grid: explicit, or fine enough for the mesh and for the fluid */
	const double ext = fmax(m.hi[0] - m.lo[0], fmax(m.hi[1] - m.lo[1], m.hi[2] - m.lo[2]));
	double h = def->cell_size;
	const int margin = 3;
	if (h <= 0) {
		h = ext / 64;
		if (w->def.cell_size > 0)
			h = fmin(h, 0.5 * w->def.cell_size);
		if (w->length_scale > 0)
			h = fmin(h, 0.5 * w->length_scale);
		/* at most 2^24 nodes (64 MB): coarser for a mesh far larger than the fluid's scale */
		for (;;) {
			double nodes = 1;
			for (int a = 0; a < 3; ++a)
				nodes *= ceil((m.hi[a] - m.lo[a]) / h) + 2 * margin + 1;
			if (nodes <= (double)(1 << 24))
				break;
			h *= 1.25;
		}
	}
	eddy_sdf sdf;
	const size_t nodes = eddy__sdf_plan(&sdf, &m, h, margin);
	if (nodes == 0) {
		eddy__mesh_free(&m);
		eddy__fail(w, EDDY_ERR_INVALID,
		           "%s: %s: a distance grid of %d x %d x %d nodes is more than eddy builds (2^26); use a larger "
		           "cell_size",
		           sys, def->path, sdf.n[0], sdf.n[1], sdf.n[2]);
		return EDDY_NULL_SYSTEM;
	}
	/* one block with the field, so every path that frees the data frees it */
	collide_mesh *b = malloc(sizeof *b + nodes * sizeof(float));
	if (!b) {
		eddy__mesh_free(&m);
		return eddy__fail(w, EDDY_ERR_NOMEM, "%s: out of memory for %zu distance nodes", sys, nodes), EDDY_NULL_SYSTEM;
	}
	memset(b, 0, sizeof *b);
	b->def = *def;
	b->volume = m.volume;
	b->sdf = sdf;
	b->sdf.d = b->field;
	const bool ok = eddy__sdf_fill(&b->sdf, &m, def->open, w->def.threads);
	eddy__mesh_free(&m);
	if (!ok) {
		free(b);
		return eddy__fail(w, EDDY_ERR_NOMEM, "%s: out of memory building the distance field", sys), EDDY_NULL_SYSTEM;
	}
	for (size_t q = 0; q < nodes; ++q)
		b->depth = fmaxf(b->depth, -b->field[q]);
	eddy__collider_init_pivot(&b->base, def->translate);
	eddy_system_id id = eddy__add_system(w, &eddy__kind_collide_mesh, b, mesh_io, mesh_io);
	return id;
}

/* ---- shape, for drawing (eddy_collider_shape_of) ----
 * The distance grid's box (the mesh's box plus the grid's margin), with the
 * offset; a drawer turns it by rotation about pivot and loads the mesh file
 * for the triangles. */

static void shape(const eddy_system *s, eddy_collider_shape *out)
{
	const collide_mesh *b = s->data;
	const eddy_vec3 o = b->base.motion.offset;
	out->kind = EDDY_COLLIDER_MESH;
	out->a = eddy__v3((float)b->sdf.origin[0] + o.x, (float)b->sdf.origin[1] + o.y, (float)b->sdf.origin[2] + o.z);
	out->b = eddy__v3((float)(b->sdf.origin[0] + (b->sdf.n[0] - 1) * b->sdf.h) + o.x,
	                  (float)(b->sdf.origin[1] + (b->sdf.n[1] - 1) * b->sdf.h) + o.y,
	                  (float)(b->sdf.origin[2] + (b->sdf.n[2] - 1) * b->sdf.h) + o.z);
	out->radius = 0.0f;
	out->inside = b->def.inside;
	out->rotation = b->base.motion.rotation;
	out->pivot = eddy__add3(b->base.motion.pivot, o);
}

/* ---- boundary particles, for SPH (src/sph/neighbors.c) ----
 * Akinci et al. 2012 on the mesh, laid out as a block box lays out its own:
 * the points of a cubic lattice of the fluid's spacing s (over the distance
 * grid's box grown by the shell, at min + (i + 1/2) s) that lie on the solid
 * side of the surface within L = ceil(h / s) spacings of it, depth -d in
 * [0, L s) (a hair deeper: below) with d the collider's signed distance in
 * its def pose: a shell as thick as
 * the kernel support (a wall thinner than that is sampled whole), so a fluid
 * particle at the surface sees a full neighbourhood. Each stands for the
 * lattice cell, V_b = 1 / sum_lattice W, the volume sph_boundary_box gives
 * its own: where the fluid continues the lattice, the boundary and fluid
 * sums together are a full lattice's. Each point then moves along the
 * field's normal onto the layer at depth (j + 1/2) s it falls in, j = 0 ..
 * L - 1, as the sphere's and box's layers lie: left on the lattice, points
 * a hair under the surface would sit closer to the fluid than any wall
 * particle of theirs and kick it (the cup's water then threw dozens of
 * particles over the rim). A layer keeps the lattice's s^-2 points per unit
 * area on average. A tank mesh (inside = true) gets its shell outside the
 * mesh. */
static size_t sph_points(const eddy_world *w, const eddy_system *s, float spacing, float h, float *x, float *y,
                         float *z, float *vol, eddy_vec3 *normal)
{
	(void)w;
	(void)normal;
	const collide_mesh *b = s->data;
	const int L = (int)ceil(h / spacing - 1e-4);
	const double sp = spacing, grow = (L + 1) * sp;
	double lo[3];
	long n[3];
	for (int a = 0; a < 3; ++a) {
		lo[a] = b->sdf.origin[a] - grow;
		const double ext = (b->sdf.n[a] - 1) * b->sdf.h + 2 * grow;
		n[a] = (long)ceil(ext / sp);
	}
	const float v = (float)(1.0 / eddy_sph_lattice_sum(EDDY_SPH_POLY6, spacing, h)), shell = (float)(L * sp);
	/* depths are taken a hair deeper, so that a lattice plane lying on a
	 * face (a mesh at multiples of the spacing: the lattice and the
	 * distance grid both start from its box) falls in the first layer
	 * whatever the rounding of d: taken as outside, it emptied the first
	 * layer and pushed the others a spacing deeper (the cup's floor held
	 * its water a spacing low, where the collider caught it) */
	const float tau = 1e-3f * (float)sp;
	size_t k = 0;
	for (long iz = 0; iz < n[2]; ++iz)
		for (long iy = 0; iy < n[1]; ++iy)
			for (long ix = 0; ix < n[0]; ++ix) {
				const eddy_vec3 q = {(float)(lo[0] + (ix + 0.5) * sp), (float)(lo[1] + (iy + 0.5) * sp),
				                     (float)(lo[2] + (iz + 0.5) * sp)};
				const float d = body_distance(b, q), depth = tau - d;
				if (!(depth > 0 && depth < shell))
					continue;
				if (x) {
					/* onto the layer at depth (j + 1/2) s it falls in (one
					 * step along the field's normal) */
					const float target = -((float)floor(depth / sp) + 0.5f) * (float)sp;
					const eddy_vec3 nrm = body_normal(b, q, NULL);
					x[k] = q.x + nrm.x * (target - d), y[k] = q.y + nrm.y * (target - d),
					z[k] = q.z + nrm.z * (target - d);
					vol[k] = v;
				}
				k++;
			}
	return k;
}
