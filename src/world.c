/* SPDX-License-Identifier: MIT */
/* The world: clock, adaptive step, frames, errors, statistics and the state hash.
 *
 * A step: pick dt = min(dt_max, cfl * min over systems of their limit), shortened
 * so steps land exactly on frame times; clear derived columns; run the systems in
 * pipeline order, timing each and scanning what it wrote for non-finite values;
 * then check that no particle left the bounds. */
#define _POSIX_C_SOURCE 200809L
#include "core.h"
#include "flip.h"
#include "sph/sph.h"
#include "systems.h"

#include <float.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

/* A scan of more values than this (non-finite check, bounds) runs on all
 * threads: below it, waking the team costs more than the pass. */
#define SCAN_PAR 65536

const char *eddy_status_name(eddy_status s)
{
	switch (s) {
	case EDDY_OK:
		return "ok";
	case EDDY_ERR_INVALID:
		return "invalid argument";
	case EDDY_ERR_ORDER:
		return "pipeline order";
	case EDDY_ERR_STALE:
		return "stale handle";
	case EDDY_ERR_NOMEM:
		return "out of memory";
	case EDDY_ERR_IO:
		return "i/o error";
	case EDDY_ERR_NUMERIC:
		return "numerical failure";
	case EDDY_ERR_SOLVER:
		return "solver failure";
	case EDDY_ERR_EXTERNAL:
		return "external failure";
	}
	return "unknown status";
}

double eddy__now_ms(void)
{
	struct timespec ts;
	clock_gettime(CLOCK_MONOTONIC, &ts);
	return (double)ts.tv_sec * 1e3 + (double)ts.tv_nsec * 1e-6;
}

static eddy_status vfail(eddy_world *w, eddy_status s, const char *fmt, va_list ap)
{
	if (w)
		vsnprintf(w->error, sizeof w->error, fmt, ap);
	return s;
}

eddy_status eddy__fail(eddy_world *w, eddy_status s, const char *fmt, ...)
{
	va_list ap;
	va_start(ap, fmt);
	vfail(w, s, fmt, ap);
	va_end(ap);
	return s;
}

eddy_status eddy_world_fail(eddy_world *w, eddy_status status, const char *fmt, ...)
{
	if (!fmt)
		return eddy__fail(w, status, "(no message)");
	va_list ap;
	va_start(ap, fmt);
	vfail(w, status, fmt, ap);
	va_end(ap);
	return status;
}

const char *eddy_world_error(const eddy_world *w) { return w ? w->error : "no world"; }

bool eddy__refuse_busy(eddy_world *w, const char *fn)
{
	if (!w->busy)
		return false;
	eddy__fail(w, EDDY_ERR_INVALID,
	           "%s called from inside %s: a callback may read the world but not step it, load it or change its "
	           "pipeline; do that after the step or frame returns",
	           fn, w->busy);
	return true;
}

bool eddy__add_args(eddy_world *w, const void *def, const char *sys)
{
	if (!w)
		return false;
	if (!def) {
		eddy__fail(w, EDDY_ERR_INVALID, "%s: def is NULL", sys);
		return false;
	}
	char fn[EDDY_NAME_MAX + 16];
	snprintf(fn, sizeof fn, "eddy_add_%s", sys);
	return !eddy__refuse_busy(w, fn);
}

eddy_world_def eddy_default_world_def(void)
{
	eddy_world_def d;
	memset(&d, 0, sizeof d);
	d.bounds_min = eddy__v3(0, 0, 0);
	d.bounds_max = eddy__v3(1, 1, 1);
	d.gravity = eddy__v3(0, -9.81f, 0);
	d.fps = 30;
	d.duration = 2;
	d.cfl = 0.4;
	d.dt_max = 1.0 / 120.0;
	d.dt_min = 1e-7;
	d.max_steps_per_frame = 100000;
	d.cell_size = 0;
	d.seed = 1;
	d.threads = 1;
	d.escape = EDDY_ESCAPE_ERROR;
	d.check_finite = true;
	return d;
}

static bool world_def_valid(const eddy_world_def *d, char *err, size_t n)
{
	const eddy_vec3 lo = d->bounds_min, hi = d->bounds_max;
	const char *bad = NULL;
	char buf[160];
	if (!(isfinite(lo.x) && isfinite(lo.y) && isfinite(lo.z) && isfinite(hi.x) && isfinite(hi.y) && isfinite(hi.z)))
		bad = "world: 'bounds' must be finite";
	else if (!(hi.x > lo.x && hi.y > lo.y && hi.z > lo.z))
		bad = "world: 'bounds' must have max > min on every axis";
	else if (!(isfinite(d->gravity.x) && isfinite(d->gravity.y) && isfinite(d->gravity.z)))
		bad = "world: 'gravity' must be finite";
	else if (!(d->fps > 0 && d->fps <= 1e6)) {
		snprintf(buf, sizeof buf, "world: 'fps' must be in (0, 1e6] (got %g)", d->fps);
		bad = buf;
	} else if (!(d->duration >= 0 && isfinite(d->duration))) {
		snprintf(buf, sizeof buf, "world: 'duration' must be >= 0 s (got %g)", d->duration);
		bad = buf;
	} else if (!(d->cfl > 0 && d->cfl <= 10)) {
		snprintf(buf, sizeof buf, "world: 'cfl' must be in (0, 10] (got %g)", d->cfl);
		bad = buf;
	} else if (!(d->dt_max > 0 && isfinite(d->dt_max))) {
		snprintf(buf, sizeof buf, "world: 'dt_max' must be > 0 s (got %g)", d->dt_max);
		bad = buf;
	} else if (!(d->dt_min > 0 && d->dt_min <= d->dt_max)) {
		snprintf(buf, sizeof buf, "world: 'dt_min' must be in (0, dt_max] (got %g)", d->dt_min);
		bad = buf;
	} else if (d->max_steps_per_frame < 1) {
		snprintf(buf, sizeof buf, "world: 'max_steps_per_frame' must be >= 1 (got %d)", d->max_steps_per_frame);
		bad = buf;
	} else if (!(d->cell_size >= 0 && isfinite(d->cell_size))) {
		snprintf(buf, sizeof buf, "world: 'cell_size' must be >= 0 m (got %g)", d->cell_size);
		bad = buf;
	} else if (d->threads < 1 || d->threads > 256) {
		snprintf(buf, sizeof buf, "world: 'threads' must be in [1, 256] (got %d)", d->threads);
		bad = buf;
	} else if (d->settle_steps < 0 || d->settle_steps > 1000000) {
		snprintf(buf, sizeof buf, "world: 'settle_steps' must be in [0, 1000000] (got %d)", d->settle_steps);
		bad = buf;
	} else if (d->escape != EDDY_ESCAPE_ERROR && d->escape != EDDY_ESCAPE_REMOVE)
		bad = "world: 'escape' must be EDDY_ESCAPE_ERROR or EDDY_ESCAPE_REMOVE";
	if (bad && err && n)
		snprintf(err, n, "%s", bad);
	return bad == NULL;
}

eddy_world *eddy_create_world(const eddy_world_def *def, char *err, size_t err_size)
{
	if (!def) {
		if (err && err_size)
			snprintf(err, err_size, "world: def is NULL");
		return NULL;
	}
	if (!world_def_valid(def, err, err_size))
		return NULL;
	eddy_world *w = calloc(1, sizeof *w);
	if (!w) {
		if (err && err_size)
			snprintf(err, err_size, "world: out of memory");
		return NULL;
	}
	w->def = *def;
	w->rng = def->seed;
	w->last_limit = "none";
	w->frame_dt_min = INFINITY;
	eddy__columns_init(w);
	return w;
}

void eddy_destroy_world(eddy_world *w)
{
	if (!w)
		return;
	/* the step running the callback still uses the world: refused (the world
	 * lives on, and its error says why) rather than freed under the step */
	if (eddy__refuse_busy(w, "eddy_destroy_world"))
		return;
	for (int i = w->order_count - 1; i >= 0; --i)
		eddy__system_free(w, &w->slots[w->order[i]]);
	eddy__columns_free(w);
	eddy__arena_free(&w->arena);
	free(w);
}

const eddy_world_def *eddy_world_get_def(const eddy_world *w) { return w ? &w->def : NULL; }

eddy_status eddy_world_set_threads(eddy_world *w, int threads)
{
	if (!w)
		return EDDY_ERR_INVALID;
	if (eddy__refuse_busy(w, "eddy_world_set_threads"))
		return EDDY_ERR_INVALID;
	if (threads < 1 || threads > 256)
		return eddy__fail(w, EDDY_ERR_INVALID, "world: 'threads' must be in [1, 256] (got %d)", threads);
	w->def.threads = threads;
	return EDDY_OK;
}

eddy_status eddy_world_set_background_output(eddy_world *w, bool on)
{
	if (!w)
		return EDDY_ERR_INVALID;
	if (eddy__refuse_busy(w, "eddy_world_set_background_output"))
		return EDDY_ERR_INVALID;
	w->background_output = on;
	return EDDY_OK;
}

bool eddy_world_background_output(const eddy_world *w) { return w && w->background_output; }

/* Every system's background work, in pipeline order; all are waited for even
 * after a failure, so nothing is still writing when this returns. */
eddy_status eddy_world_sync(eddy_world *w)
{
	if (!w)
		return EDDY_ERR_INVALID;
	eddy_status first = EDDY_OK;
	char msg[EDDY_ERROR_MAX] = "";
	for (int k = 0; k < w->order_count; ++k) {
		eddy_system *s = &w->slots[w->order[k]];
		if (!s->vt->sync)
			continue;
		eddy_status st = s->vt->sync(w, s);
		if (st != EDDY_OK && first == EDDY_OK) {
			first = st;
			snprintf(msg, sizeof msg, "%s", w->error);
		}
	}
	if (first != EDDY_OK)
		eddy__fail(w, first, "%s", msg);
	return first;
}

double eddy_world_time(const eddy_world *w) { return w ? w->time : NAN; }
double eddy_world_frame_time(const eddy_world *w) { return w ? 1.0 / w->def.fps : NAN; }
int eddy_world_frame(const eddy_world *w) { return w ? w->frame : 0; }
double eddy_world_length_scale(const eddy_world *w) { return w ? w->length_scale : 0; }
int64_t eddy_world_steps(const eddy_world *w) { return w ? w->step : 0; }
double eddy_world_last_dt(const eddy_world *w) { return w ? w->last_dt : NAN; }

void eddy__note_length_scale(eddy_world *w, float h)
{
	if (h > 0 && (w->length_scale == 0 || h < w->length_scale))
		w->length_scale = h;
}

void eddy_world_set_rest_density(eddy_world *w, float rho0)
{
	if (w && isfinite(rho0) && rho0 >= 0)
		w->rest_density = rho0;
}

/* ---- stepping ----------------------------------------------------------- */

/* The smallest limit any system reports, times the CFL factor, capped by dt_max. */
static double step_limit(eddy_world *w, const char **reason)
{
	double lim = w->def.dt_max;
	*reason = "dt_max";
	const char *was = w->busy;
	w->busy = "a time-step limit callback";
	for (int k = 0; k < w->order_count; ++k) {
		eddy_system *s = &w->slots[w->order[k]];
		if (!s->vt->limit)
			continue;
		const char *why = "limit";
		double l = s->vt->limit(w, s, &why) * w->def.cfl;
		if (l < lim) {
			lim = l;
			snprintf(w->last_limit_buf, sizeof w->last_limit_buf, "%s: %s", s->label, why);
			*reason = w->last_limit_buf;
		}
	}
	w->busy = was;
	return lim;
}

/* Whether any of v[lo, hi) is Inf or NaN (its exponent bits all set): a
 * plain loop that vectorises, where the same loop inside the parallel
 * region's reduction stays scalar. */
static uint32_t any_nonfinite(const float *v, size_t lo, size_t hi)
{
	uint32_t any = 0;
	for (size_t i = lo; i < hi; ++i) {
		uint32_t bits;
		memcpy(&bits, &v[i], sizeof bits);
		any |= (bits & 0x7f800000u) == 0x7f800000u;
	}
	return any;
}

/* First non-finite value in v[0..n), or n. An all-ones exponent marks inf and
 * NaN; OR-ing that test over the column is an integer reduction the compiler
 * vectorises (on all threads for a large column), so the scan costs about a
 * memory pass, not a branch per value; only a column that has one looks for
 * the first. */
static size_t first_nonfinite(const float *v, size_t n, int threads)
{
	const int nt = n > SCAN_PAR ? threads : 1;
	uint32_t any = 0;
	if (nt == 1)
		any = any_nonfinite(v, 0, n);
	else
#pragma omp parallel for num_threads(nt) schedule(static) reduction(| : any)
		for (int t = 0; t < nt; ++t)
			any |= any_nonfinite(v, n * (size_t)t / (size_t)nt, n * (size_t)(t + 1) / (size_t)nt);
	if (any)
		for (size_t i = 0; i < n; ++i)
			if (!isfinite(v[i]))
				return i;
	return n;
}

/* Scans the float columns system s writes; the first non-finite value names
 * the system, step and particle, or the grid cell or face (i, j, k), so a
 * grid pass that goes wrong is blamed, not the particle pass that reads it. */
static eddy_status check_written(eddy_world *w, const eddy_system *s)
{
	for (int k = 0; k < s->write_count; ++k) {
		const eddy_column *c = &w->columns[s->writes[k]];
		if (c->type != EDDY_F32 || !c->data)
			continue;
		const float *v = c->data;
		if (c->domain == EDDY_DOMAIN_PARTICLE) {
			const size_t bad = first_nonfinite(v, w->n, w->def.threads);
			if (bad < w->n)
				return eddy__fail(w, EDDY_ERR_NUMERIC,
				                  "%s: non-finite %s = %g of particle %zu at step %lld (t = %.6g s)", s->label, c->name,
				                  (double)v[bad], bad, (long long)w->step, w->time);
			continue;
		}
		const size_t n = eddy__column_elems(w, c), bad = first_nonfinite(v, n, w->def.threads);
		if (bad == n)
			continue;
		/* x fastest; a face grid has one more layer along its axis */
		const size_t nx = (size_t)w->nx + (c->domain == EDDY_DOMAIN_FACE_X),
					 ny = (size_t)w->ny + (c->domain == EDDY_DOMAIN_FACE_Y);
		const char *where = c->domain == EDDY_DOMAIN_CELL ? "cell" : "face";
		return eddy__fail(w, EDDY_ERR_NUMERIC, "%s: non-finite %s = %g at %s (%zu, %zu, %zu) at step %lld (t = %.6g s)",
		                  s->label, c->name, (double)v[bad], where, bad % nx, bad / nx % ny, bad / (nx * ny),
		                  (long long)w->step, w->time);
	}
	return EDDY_OK;
}

/* After the pipeline ran: particles outside the bounds stop the run or are
 * removed, as the world def says. */
static eddy_status check_bounds(eddy_world *w)
{
	float *x = eddy__col(w, COL_X_), *y = eddy__col(w, COL_Y_), *z = eddy__col(w, COL_Z_);
	if (!x || !y || !z)
		return EDDY_OK;
	const eddy_vec3 lo = w->def.bounds_min, hi = w->def.bounds_max;
	/* the common case, none out, on all threads; removal (which renumbers)
	 * and the error then in one serial pass */
	const size_t n = w->n;
	const int nt = n > SCAN_PAR ? w->def.threads : 1;
	int any = 0;
#pragma omp parallel for num_threads(nt) if (nt > 1) schedule(static) reduction(| : any)
	for (size_t i = 0; i < n; ++i)
		any |= !(x[i] >= lo.x && x[i] <= hi.x && y[i] >= lo.y && y[i] <= hi.y && z[i] >= lo.z && z[i] <= hi.z);
	if (!any)
		return EDDY_OK;
	for (size_t i = w->n; i-- > 0;) {
		bool out = !(x[i] >= lo.x && x[i] <= hi.x && y[i] >= lo.y && y[i] <= hi.y && z[i] >= lo.z && z[i] <= hi.z);
		if (!out)
			continue;
		if (w->def.escape == EDDY_ESCAPE_REMOVE) {
			eddy__warn(w, "world:escape",
			           "particle %zu left the domain at step %lld (t = %.6g s) at (%g, %g, %g) and was removed (escape "
			           "= \"remove\"); later ones are removed without a warning (the stats' particles counts what is "
			           "left)",
			           i, (long long)w->step, w->time, (double)x[i], (double)y[i], (double)z[i]);
			eddy_world_remove_particle(w, i);
			continue;
		}
		/* with a collider moved or turned from its def pose, the likely
		 * cause is a tank carried past the bounds: the bounds are the last
		 * wall, and a tank's inside beyond them lets particles through */
		const eddy_system *moved = NULL, *o;
		for (eddy_system_iter it = eddy__systems(w, EDDY_CAP_COLLIDER); !moved && (o = eddy__systems_next(&it));) {
			const eddy_collider_motion *m = &((const eddy_collider_base *)o->data)->motion;
			if (m->offset.x || m->offset.y || m->offset.z || m->rotation.x || m->rotation.y || m->rotation.z)
				moved = o;
		}
		char hint[256];
		if (moved)
			snprintf(hint, sizeof hint,
			         "%s is moved or turned: the bounds must hold its whole motion (a tank's inside past them lets "
			         "particles out), or set escape = \"remove\"",
			         moved->label);
		else
			snprintf(hint, sizeof hint,
			         "add collide_box{min = bounds min, max = bounds max, inside = true} or set escape = \"remove\"");
		return eddy__fail(w, EDDY_ERR_NUMERIC,
		                  "particle %zu left the domain at step %lld (t = %.6g s): (%g, %g, %g) outside "
		                  "[%g, %g]x[%g, %g]x[%g, %g]; %s",
		                  i, (long long)w->step, w->time, (double)x[i], (double)y[i], (double)z[i], (double)lo.x,
		                  (double)hi.x, (double)lo.y, (double)hi.y, (double)lo.z, (double)hi.z, hint);
	}
	return EDDY_OK;
}

const char eddy__busy_step[] = "a step callback", eddy__busy_frame[] = "a frame callback";

/* Runs one system's step as step_toward does: its time, and an error
 * message that names it. */
static eddy_status run_system(eddy_world *w, eddy_system *s, const eddy_step_context *ctx)
{
	const double a = eddy__now_ms();
	eddy_status st = s->vt->step(w, s, ctx);
	const double ms = eddy__now_ms() - a;
	s->ms_total += ms;
	s->ms_frame += ms;
	s->calls++;
	if (st != EDDY_OK) {
		if (strncmp(w->error, s->label, strlen(s->label)) != 0) {
			char msg[EDDY_ERROR_MAX];
			snprintf(msg, sizeof msg, "%s", w->error);
			eddy__fail(w, st, "%s: step %lld (t = %.6g s): %s", s->label, (long long)w->step, w->time, msg);
		}
		return st;
	}
	return w->def.check_finite ? check_written(w, s) : EDDY_OK;
}

/* The settling steps (def.settle_steps), before the first step: what the
 * emitters place at time 0 (emitted here, a step of no length) is relaxed
 * by the pipeline's own pressure force, without gravity, until no particle
 * would move SETTLE_TOL h in a step. Water that starts squeezed
 * against a solid's boundary particles (a lattice cut by an off-lattice
 * collider: a point just outside a face starts under one spacing from the
 * particles half a spacing inside it) then does not start with the
 * equation of state's answer to that squeeze, a kick of metres a second.
 * Each step is a descent step, x += a dt^2 at the acoustic step dt (a
 * gradient step on the compression energy): velocities stay as emitted,
 * time stays where it was. Only the systems marked settles run, the SPH
 * density and pressure force, and then the world moves the particles
 * (settle_move); integrate does not run. Gravity sits them out
 * (eddy__gravity_sum reads zero), so a column the scene releases, a dam
 * break, is not released here; colliders stay as placed. The pressure is
 * clamped at p >= 0, so with no compression left nothing moves: a plain
 * lattice ends as emitted, and squeezed water moves only until its density
 * is back at rho0 (the total potential energy of the obstacle pool after
 * it matches the geometry's). */
#define SETTLE_TOL 5e-4 /* of the SPH support h: a thousandth of a spacing at h = 2 spacings */
static void *first_shared(const eddy_world *w, uint32_t cap);
static const char settle_needs[] = "'settle_steps' needs sph_pressure (WCSPH) in the pipeline: sph_dfsph and "
                                   "flip_pressure answer a squeezed start in their first step's solve; set it to 0";
/* One settling step's move, x += a dt^2, unless the largest is under
 * min_move: then nothing moves, so a start that needs no settling stays
 * exactly as emitted. Returns whether it moved. */
static bool settle_move(eddy_world *w, float dt, float min_move)
{
	const float *ax = eddy__col(w, COL_AX), *ay = eddy__col(w, COL_AY), *az = eddy__col(w, COL_AZ);
	float *x = eddy__col(w, COL_X_), *y = eddy__col(w, COL_Y_), *z = eddy__col(w, COL_Z_);
	const long n = (long)w->n;
	const int nt = n > EDDY_PAR_ROWS ? w->def.threads : 1;
	const float dt2 = dt * dt;
	if (!(sqrtf(eddy__max_norm2(w, COL_AX, COL_AY, COL_AZ)) * dt2 >= min_move))
		return false;
#pragma omp parallel for num_threads(nt) if (nt > 1) schedule(static)
	for (long i = 0; i < n; ++i) {
		x[i] += ax[i] * dt2;
		y[i] += ay[i] * dt2;
		z[i] += az[i] * dt2;
	}
	return true;
}

static eddy_status settle(eddy_world *w)
{
	if (w->def.settle_steps <= 0) {
		w->settled = true;
		return EDDY_OK;
	}
	if (!eddy__provider(w, NULL, EDDY_CAP_SPH_EOS_FORCE))
		return eddy__fail(w, EDDY_ERR_INVALID, "world: %s", settle_needs);
	const double t0 = eddy__now_ms();
	w->busy = eddy__busy_step;
	const eddy_step_context at0 = {0, w->time, w->step, w->def.threads};
	for (int k = 0; k < w->order_count; ++k) {
		eddy_system *s = &w->slots[w->order[k]];
		if (s->vt->step && s->vt->expected_particles) {
			eddy_status st = run_system(w, s, &at0);
			if (st != EDDY_OK)
				return st;
		}
	}
	w->settling = true;
	const sph_shared *sh = first_shared(w, EDDY_CAP_SPH_NEIGHBORS);
	const float min_move = (float)(SETTLE_TOL * (sh ? sh->h : 0));
	eddy_status st = EDDY_OK;
	int k = 0;
	while (st == EDDY_OK) {
		const char *reason;
		const double dt = fmin(step_limit(w, &reason), 1.0 / w->def.fps);
		eddy__arena_reset(&w->arena);
		eddy__clear_derived(w);
		const eddy_step_context ctx = {dt, w->time, w->step, w->def.threads};
		for (int q = 0; q < w->order_count && st == EDDY_OK; ++q) {
			eddy_system *s = &w->slots[w->order[q]];
			if (s->vt->step && s->vt->settles)
				st = run_system(w, s, &ctx);
		}
		if (st != EDDY_OK || !settle_move(w, (float)dt, min_move))
			break;
		if (++k == w->def.settle_steps) {
			eddy__warn(w, "world:settle",
			           "world: the settling stopped at settle_steps = %d with particles still moving; it ends "
			           "once none would move %g h a step; the run starts from there",
			           k, SETTLE_TOL);
			break;
		}
		st = check_bounds(w);
	}
	w->settling = false;
	eddy__arena_reset(&w->arena);
	eddy__clear_derived(w);
	if (st == EDDY_OK)
		st = check_bounds(w);
	/* a failed settling stops the run; a step asked for after it runs the
	 * emitters' time 0 again (each emits once) and the settling anew */
	w->settled = st == EDDY_OK;
	eddy_world_publish(w, "settle_steps", k);
	w->frame_wall_ms += eddy__now_ms() - t0;
	return st;
}

/* One step toward time stop (never past it). *reached says whether it got there. */
static eddy_status step_toward(eddy_world *w, double stop, bool *reached)
{
	if (!w->settled && w->step == 0) {
		eddy_status st = settle(w);
		if (st != EDDY_OK)
			return st;
	}
	const double remaining = stop - w->time;
	const char *reason;
	double lim = step_limit(w, &reason);
	if (!(lim >= w->def.dt_min))
		return eddy__fail(w, EDDY_ERR_NUMERIC,
		                  "time step collapsed at step %lld (t = %.6g s): %s allows %.3g s, below dt_min = %.3g s",
		                  (long long)w->step, w->time, reason, lim, w->def.dt_min);
	/* Equal steps to the stop, so the last one is not a sliver. */
	/* a limit a hair under an even split (float speeds) must not add a step */
	double nsteps = ceil(remaining / lim - 1e-6);
	if (nsteps < 1)
		nsteps = 1;
	if (w->frame_steps + nsteps > (double)w->def.max_steps_per_frame)
		return eddy__fail(w, EDDY_ERR_NUMERIC,
		                  "frame %d needs more than max_steps_per_frame = %d steps: %s limits dt to %.3g s",
		                  w->frame + 1, w->def.max_steps_per_frame, reason, lim);
	const double dt = remaining / nsteps;
	w->last_limit = reason;

	const double t0 = eddy__now_ms();
	eddy__arena_reset(&w->arena);
	eddy__clear_derived(w);
	/* colliders given a pose move toward it at the pace that lands them on
	 * it when it is due */
	const double end = nsteps <= 1.0 ? stop : w->time + dt;
	const eddy_system *c;
	for (eddy_system_iter it = eddy__systems(w, EDDY_CAP_COLLIDER); (c = eddy__systems_next(&it));)
		eddy__collider_glide(&((eddy_collider_base *)c->data)->motion, w->time, dt, end, w->call_end,
		                     1e-9 / w->def.fps);
	const eddy_step_context ctx = {dt, w->time, w->step, w->def.threads};
	w->busy = eddy__busy_step;
	for (int k = 0; k < w->order_count; ++k) {
		eddy_system *s = &w->slots[w->order[k]];
		if (!s->vt->step)
			continue;
		eddy_status st = run_system(w, s, &ctx);
		if (st != EDDY_OK)
			return st;
	}
	if (nsteps <= 1.0) {
		w->time = stop; /* land exactly, so frame times do not drift */
		*reached = true;
	} else {
		w->time += dt;
		*reached = false;
	}
	w->step++;
	w->last_dt = dt;
	w->frame_steps++;
	if (dt < w->frame_dt_min)
		w->frame_dt_min = dt;
	if (dt > w->frame_dt_max)
		w->frame_dt_max = dt;
	eddy_status st = check_bounds(w);
	w->frame_wall_ms += eddy__now_ms() - t0;
	return st;
}

void eddy__frame_reset(eddy_world *w)
{
	w->frame_steps = 0;
	w->frame_dt_min = INFINITY;
	w->frame_dt_max = 0;
	w->frame_wall_ms = 0;
	w->extra_count = 0;
	for (int k = 0; k < w->order_count; ++k)
		w->slots[w->order[k]].ms_frame = 0;
}

/* At a frame time: the systems' frame hooks (renderers, host callbacks), then
 * the snapshot that eddy_world_frame_stats() reports. */
static eddy_status finish_frame(eddy_world *w)
{
	w->frame++;
	w->busy = eddy__busy_frame;
	for (int k = 0; k < w->order_count; ++k) {
		eddy_system *s = &w->slots[w->order[k]];
		if (!s->vt->frame)
			continue;
		const double a = eddy__now_ms();
		eddy_status st = s->vt->frame(w, s, w->frame);
		const double ms = eddy__now_ms() - a;
		s->ms_total += ms;
		s->ms_frame += ms;
		w->frame_wall_ms += ms;
		if (st != EDDY_OK) {
			if (strncmp(w->error, s->label, strlen(s->label)) != 0) {
				char msg[EDDY_ERROR_MAX];
				snprintf(msg, sizeof msg, "%s", w->error);
				eddy__fail(w, st, "%s: frame %d: %s", s->label, w->frame, msg);
			}
			return st;
		}
	}
	w->last_frame.steps = w->frame_steps;
	w->last_frame.dt_min = w->frame_steps ? w->frame_dt_min : 0;
	w->last_frame.dt_max = w->frame_dt_max;
	w->last_frame.wall_ms = w->frame_wall_ms;
	w->last_frame.dt_limit = w->last_limit;
	for (int k = 0; k < w->order_count && k < EDDY_MAX_STAT_SYSTEMS; ++k)
		w->last_frame.system_ms[k] = w->slots[w->order[k]].ms_frame;
	memcpy(w->last_frame.extras, w->extras, sizeof w->extras);
	w->last_frame.extra_count = w->extra_count;
	eddy__frame_reset(w);
	return EDDY_OK;
}

static eddy_status step_once(eddy_world *w)
{
	bool reached;
	eddy_status st = step_toward(w, eddy__next_frame_time(w), &reached);
	if (st == EDDY_OK && reached)
		st = finish_frame(w);
	return st;
}

/* The stepping entry points run systems' and hosts' code, which must not
 * re-enter them: w->busy is set below them and cleared when they return. */
eddy_status eddy_world_step(eddy_world *w)
{
	if (!w)
		return EDDY_ERR_INVALID;
	if (eddy__refuse_busy(w, "eddy_world_step"))
		return EDDY_ERR_INVALID;
	w->call_end = -INFINITY;
	eddy_status st = step_once(w);
	w->busy = NULL;
	return st;
}

eddy_status eddy_world_step_frame(eddy_world *w)
{
	if (!w)
		return EDDY_ERR_INVALID;
	if (eddy__refuse_busy(w, "eddy_world_step_frame"))
		return EDDY_ERR_INVALID;
	const int target = w->frame + 1;
	w->call_end = eddy__next_frame_time(w);
	eddy_status st = EDDY_OK;
	while (st == EDDY_OK && w->frame < target)
		st = step_once(w);
	w->busy = NULL;
	return st;
}

static eddy_status advance(eddy_world *w, double seconds);

eddy_status eddy_world_advance(eddy_world *w, double seconds)
{
	if (!w)
		return EDDY_ERR_INVALID;
	if (eddy__refuse_busy(w, "eddy_world_advance"))
		return EDDY_ERR_INVALID;
	eddy_status st = advance(w, seconds);
	w->busy = NULL;
	return st;
}

static eddy_status advance(eddy_world *w, double seconds)
{
	if (!(seconds >= 0 && isfinite(seconds)))
		return eddy__fail(w, EDDY_ERR_INVALID, "advance: 'seconds' must be >= 0 and finite (got %g)", seconds);
	const double end = w->time + seconds;
	const double eps = 1e-9 / w->def.fps;
	w->call_end = end;
	while (w->time < end - eps) {
		double frame_end = eddy__next_frame_time(w);
		bool reached;
		eddy_status st;
		if (frame_end <= end + eps) {
			st = step_toward(w, frame_end, &reached);
			if (st == EDDY_OK && reached)
				st = finish_frame(w);
		} else {
			st = step_toward(w, end, &reached);
		}
		if (st != EDDY_OK)
			return st;
	}
	return EDDY_OK;
}

/* ---- statistics ---------------------------------------------------------- */

void eddy_world_publish(eddy_world *w, const char *name, double value)
{
	if (!w || !name)
		return;
	int k = 0;
	while (k < w->extra_count && strcmp(w->extras[k].name, name) != 0)
		++k;
	if (k == EDDY_MAX_EXTRA_STATS)
		return;
	if (k == w->extra_count)
		w->extra_count++;
	snprintf(w->extras[k].name, sizeof w->extras[k].name, "%s", name);
	w->extras[k].value = value;
	w->extras[k].is_text = false;
}

void eddy_world_publish_text(eddy_world *w, const char *name, const char *text)
{
	if (!w || !name)
		return;
	if (!text)
		text = "";
	eddy_world_publish(w, name, NAN);
	for (int k = 0; k < w->extra_count; ++k) {
		if (strcmp(w->extras[k].name, name) == 0) {
			snprintf(w->extras[k].text, sizeof w->extras[k].text, "%s", text);
			w->extras[k].is_text = true;
		}
	}
}

void eddy__warn(eddy_world *w, const char *key, const char *fmt, ...)
{
	for (int k = 0; k < w->warning_count; ++k)
		if (strcmp(w->warnings[k].key, key) == 0)
			return;
	if (w->warning_count == EDDY_MAX_WARNINGS)
		return;
	struct eddy_warning *wn = &w->warnings[w->warning_count++];
	if (w->warning_count == EDDY_MAX_WARNINGS) { /* the last place says the list is full */
		snprintf(wn->key, sizeof wn->key, "%s", "");
		snprintf(wn->text, sizeof wn->text, "%d warnings: later ones are not kept", EDDY_MAX_WARNINGS - 1);
		return;
	}
	snprintf(wn->key, sizeof wn->key, "%s", key);
	va_list ap;
	va_start(ap, fmt);
	vsnprintf(wn->text, sizeof wn->text, fmt, ap);
	va_end(ap);
}

int eddy_world_warning_count(const eddy_world *w) { return w ? w->warning_count : 0; }

const char *eddy_world_warning(const eddy_world *w, int index)
{
	return w && index >= 0 && index < w->warning_count ? w->warnings[index].text : NULL;
}

static bool inside_any_collider(const eddy_world *w, eddy_vec3 p)
{
	for (int k = 0; k < w->order_count; ++k) {
		const eddy_system *s = &w->slots[w->order[k]];
		/* A small tolerance: projection lands on the surface up to rounding. */
		if (s->vt->distance && s->vt->distance(s, p) < -1e-5f * (w->length_scale > 0 ? w->length_scale : 1.0f))
			return true;
	}
	return false;
}

/* The mass of one particle (kg), NAN when the pipeline does not define one:
 * sph_density's calibrated mass (the first sph_density), else for FLIP
 * rho * s^3, rho flip_pressure's density and s the spacing every emitter
 * shares (FLIP has no particle mass of its own: its particles sample the
 * fluid at the emitted lattice, s^3 of water each; emitters at different
 * spacings, or particles added without an emitter, leave it undefined).
 * Built-in kinds whose def is read here keep it as their data's first member
 * (C11 6.7.2.1p15: a pointer to a struct converts to one to its first
 * member); tests/test_stress_slosh.c checks non-default values come through. */
static void *first_shared(const eddy_world *w, uint32_t cap)
{
	eddy_system_iter it = eddy__systems(w, cap);
	const eddy_system *o = eddy__systems_next(&it);
	return o && o->vt->shared ? o->vt->shared(o, cap) : NULL;
}

static double particle_mass(const eddy_world *w)
{
	const sph_shared *sh = first_shared(w, EDDY_CAP_SPH_NEIGHBORS);
	if (sh)
		return sh->mass;
	double rho = NAN, s = NAN;
	const eddy_flip_pressure_def *grid = first_shared(w, EDDY_CAP_GRID_DENSITY);
	if (grid)
		rho = grid->density;
	const eddy_system *o;
	for (eddy_system_iter it = eddy__systems(w, 0); (o = eddy__systems_next(&it));) {
		if (o->vt->spacing) {
			const double e = o->vt->spacing(o);
			if (isnan(s))
				s = e;
			else if (e != s)
				return NAN;
		}
	}
	return rho * s * s * s; /* NAN if either is missing */
}

/* The stats' sums run on all threads in fixed chunks whose sums are added in
 * chunk order: the same figures on any number of threads. At most
 * STAT_CHUNKS chunks of at least STAT_CHUNK particles (the chunking depends
 * on the particle count only). */
enum { STAT_CHUNK = 16384, STAT_CHUNKS = 256 };
static size_t stat_chunk_size(size_t n) { return n / STAT_CHUNKS + 1 > STAT_CHUNK ? n / STAT_CHUNKS + 1 : STAT_CHUNK; }

/* Energy and momentum of the particles into out (see eddy_frame_stats).
 * The compression energy is the work done compressing each particle from
 * rho0 along sph_density's equation of state, e = m int_rho0^rho p / r^2 dr
 * (the specific internal energy of a barotropic fluid, de = p / rho^2 drho),
 * with p clamped at 0 as sph_density clamps it (e = 0 for rho <= rho0):
 *   linear, p = k (rho - rho0):  e = m k (ln(rho / rho0) + rho0 / rho - 1)
 *   Tait, p = B ((rho/rho0)^gamma - 1), B = k rho0 / gamma:
 *     e = m (B / rho0) (((rho/rho0)^(gamma-1) - 1) / (gamma - 1) + rho0 / rho - 1)
 * It is the energy WCSPH's pressure force exchanges with the motion, so the
 * total is the one a conservative WCSPH would keep; sph_dfsph solves for the
 * pressure instead and has no such store (NAN there). */
static void energy_stats(const eddy_world *w, eddy_frame_stats *out)
{
	const double m = particle_mass(w);
	out->particle_mass = m;
	out->kinetic_energy = out->potential_energy = out->compression_energy = out->energy = NAN;
	out->momentum[0] = out->momentum[1] = out->momentum[2] = NAN;
	const float *x = w->columns[COL_X_].data, *y = w->columns[COL_Y_].data, *z = w->columns[COL_Z_].data;
	const float *vx = w->columns[COL_VX].data, *vy = w->columns[COL_VY].data, *vz = w->columns[COL_VZ].data;
	if (!(m > 0) || !x || !vx)
		return;
	double gv[3]; /* m/s^2, what the gravity systems add up to */
	eddy__gravity_sum(w, gv);
	const double gx = gv[0], gy = gv[1], gz = gv[2];
	const eddy_sph_density_def *eos = NULL;
	float rho0 = 0;
	bool wcsph = false;
	const eddy_system *o;
	for (eddy_system_iter it = eddy__systems(w, EDDY_CAP_SPH_NEIGHBORS); !eos && (o = eddy__systems_next(&it));) {
		eos = eddy__sph_density_def(o);
		rho0 = ((const sph_shared *)o->vt->shared(o, EDDY_CAP_SPH_NEIGHBORS))->rho0;
	}
	wcsph = eddy__provider(w, NULL, EDDY_CAP_SPH_EOS_FORCE) != NULL;
	const eddy_vec3 lo = w->def.bounds_min;
	const size_t n = w->n, csize = stat_chunk_size(n);
	const int nch = (int)((n + csize - 1) / csize), nt = nch > 1 ? w->def.threads : 1;
	double part[STAT_CHUNKS][5];
#pragma omp parallel for num_threads(nt) if (nt > 1) schedule(static)
	for (int c = 0; c < nch; ++c) {
		const size_t i0 = (size_t)c * csize, i1 = i0 + csize < n ? i0 + csize : n;
		double cke = 0, cpe = 0, cpx = 0, cpy = 0, cpz = 0;
		for (size_t i = i0; i < i1; ++i) {
			const double ux = vx[i], uy = vy[i], uz = vz[i];
			cke += ux * ux + uy * uy + uz * uz;
			cpe -= gx * ((double)x[i] - lo.x) + gy * ((double)y[i] - lo.y) + gz * ((double)z[i] - lo.z);
			cpx += ux, cpy += uy, cpz += uz;
		}
		part[c][0] = cke, part[c][1] = cpe, part[c][2] = cpx, part[c][3] = cpy, part[c][4] = cpz;
	}
	double ke = 0, pe = 0, px = 0, py = 0, pz = 0;
	for (int c = 0; c < nch; ++c)
		ke += part[c][0], pe += part[c][1], px += part[c][2], py += part[c][3], pz += part[c][4];
	out->kinetic_energy = 0.5 * m * ke;
	out->potential_energy = m * pe;
	out->momentum[0] = m * px, out->momentum[1] = m * py, out->momentum[2] = m * pz;
	out->energy = out->kinetic_energy + out->potential_energy;
	const float *rho = w->columns[COL_DENSITY].data;
	if (!wcsph || !eos || !rho || !(rho0 > 0))
		return;
	const double r0 = rho0, kk = eos->stiffness, gam = eos->tait_gamma, B = kk * r0 / gam;
	const bool tait = eos->eos == EDDY_SPH_EOS_TAIT;
#pragma omp parallel for num_threads(nt) if (nt > 1) schedule(static)
	for (int c = 0; c < nch; ++c) {
		const size_t i0 = (size_t)c * csize, i1 = i0 + csize < n ? i0 + csize : n;
		double cce = 0;
		for (size_t i = i0; i < i1; ++i) {
			const double r = rho[i];
			if (!(r > r0))
				continue;
			cce += tait ? (B / r0) * ((pow(r / r0, gam - 1) - 1) / (gam - 1) + r0 / r - 1)
			            : kk * (log(r / r0) + r0 / r - 1);
		}
		part[c][0] = cce;
	}
	double ce = 0;
	for (int c = 0; c < nch; ++c)
		ce += part[c][0];
	out->compression_energy = m * ce;
	out->energy += out->compression_energy;
}

eddy_status eddy_world_frame_stats(eddy_world *w, eddy_frame_stats *out)
{
	if (!w || !out)
		return EDDY_ERR_INVALID;
	memset(out, 0, sizeof *out);
	out->frame = w->frame;
	out->time = w->time;
	out->steps = w->last_frame.steps;
	out->dt_min = w->last_frame.dt_min;
	out->dt_max = w->last_frame.dt_max;
	out->dt_limit = w->last_frame.dt_limit ? w->last_frame.dt_limit : "none";
	out->particles = w->n;
	out->wall_ms = w->last_frame.wall_ms;

	const float *x = eddy__col(w, COL_X_), *y = eddy__col(w, COL_Y_), *z = eddy__col(w, COL_Z_);
	const float *vx = eddy__col(w, COL_VX), *vy = eddy__col(w, COL_VY), *vz = eddy__col(w, COL_VZ);
	double vmax2 = 0;
	size_t leaked = 0, nonfinite = 0;
	const eddy_vec3 lo = w->def.bounds_min, hi = w->def.bounds_max;
	/* a largest value and counts: the same on any number of threads */
	const long n = (long)w->n;
	const int nt = n > EDDY_PAR_ROWS ? w->def.threads : 1;
#pragma omp parallel for num_threads(nt) if (nt > 1) schedule(static) reduction(max : vmax2) reduction(+ : leaked)
	for (long i = 0; i < n; ++i) {
		if (vx && vy && vz) {
			double v2 = (double)vx[i] * vx[i] + (double)vy[i] * vy[i] + (double)vz[i] * vz[i];
			if (v2 > vmax2)
				vmax2 = v2;
		}
		if (x && y && z) {
			eddy_vec3 p = {x[i], y[i], z[i]};
			bool out_of_bounds =
				!(p.x >= lo.x && p.x <= hi.x && p.y >= lo.y && p.y <= hi.y && p.z >= lo.z && p.z <= hi.z);
			if (out_of_bounds || inside_any_collider(w, p))
				leaked++;
		}
	}
	for (int c = 0; c < w->column_count; ++c) {
		const eddy_column *col = &w->columns[c];
		if (!col->data || col->domain != EDDY_DOMAIN_PARTICLE || col->type != EDDY_F32 || col->lifetime != EDDY_STATE)
			continue;
		const float *v = col->data;
#pragma omp parallel for num_threads(nt) if (nt > 1) schedule(static) reduction(+ : nonfinite)
		for (long i = 0; i < n; ++i)
			nonfinite += !isfinite(v[i]);
	}
	out->max_speed = sqrt(vmax2);
	out->leaked = leaked;
	out->nonfinite = nonfinite;
	out->warnings = w->warning_count;
	out->cfl = w->length_scale > 0 ? out->max_speed * w->last_dt / w->length_scale : NAN;

	const float *rho = eddy__col(w, COL_DENSITY);
	if (rho && w->rest_density > 0 && w->n > 0) {
		const size_t csize = stat_chunk_size(w->n);
		const int nch = (int)((w->n + csize - 1) / csize), cnt = nch > 1 ? w->def.threads : 1;
		double part[STAT_CHUNKS][2], mx = 0;
#pragma omp parallel for num_threads(cnt) if (cnt > 1) schedule(static) reduction(max : mx)
		for (int c = 0; c < nch; ++c) {
			const size_t i0 = (size_t)c * csize, i1 = i0 + csize < w->n ? i0 + csize : w->n;
			double csum = 0, ccomp = 0;
			for (size_t i = i0; i < i1; ++i) {
				const double d = ((double)rho[i] - w->rest_density) / w->rest_density, e = fabs(d);
				csum += e;
				ccomp += d > 0 ? d : 0;
				mx = e > mx ? e : mx;
			}
			part[c][0] = csum, part[c][1] = ccomp;
		}
		double sum = 0, comp = 0;
		for (int c = 0; c < nch; ++c)
			sum += part[c][0], comp += part[c][1];
		out->density_err_avg = sum / (double)w->n;
		out->density_err_max = mx;
		out->density_compression_avg = comp / (double)w->n;
	} else {
		out->density_err_avg = NAN;
		out->density_err_max = NAN;
		out->density_compression_avg = NAN;
	}
	out->volume = NAN; /* a grid system publishes "volume" when a grid exists */
	energy_stats(w, out);

	out->state_hash = eddy_world_state_hash(w);
	out->system_count = w->order_count < EDDY_MAX_STAT_SYSTEMS ? w->order_count : EDDY_MAX_STAT_SYSTEMS;
	for (int k = 0; k < out->system_count; ++k) {
		out->system_names[k] = w->slots[w->order[k]].label;
		out->system_ms[k] = w->last_frame.system_ms[k];
	}
	out->extra_count = w->last_frame.extra_count;
	for (int k = 0; k < out->extra_count; ++k) {
		const eddy_extra_stat *e = &w->last_frame.extras[k];
		out->extra[k].name = e->name;
		out->extra[k].value = e->value;
		out->extra[k].text = e->is_text ? e->text : NULL;
		if (strcmp(e->name, "volume") == 0 && !e->is_text)
			out->volume = e->value;
	}
	return EDDY_OK;
}

float eddy__max_norm2(eddy_world *w, int cu, int cv, int cw)
{
	const float *u = eddy__col(w, cu), *v = eddy__col(w, cv), *q = eddy__col(w, cw);
	if (!u || !v || !q)
		return 0;
	const long n = (long)w->n;
	const int nt = n > EDDY_PAR_ROWS ? w->def.threads : 1;
	float m2 = 0;
#pragma omp parallel for num_threads(nt) if (nt > 1) schedule(static) reduction(max : m2)
	for (long i = 0; i < n; ++i) {
		const float s2 = u[i] * u[i] + v[i] * v[i] + q[i] * q[i];
		m2 = s2 > m2 ? s2 : m2;
	}
	return m2;
}

/* The state hash reads a column in chunks of HASH_CHUNK bytes, each hashed
 * on its own (on the world's threads when there are several) and their
 * hashes folded in order, so the value depends on the bytes alone, not on
 * the thread count. Within a chunk, 8-byte words: FNV-1a's xor and
 * multiply (by an odd 64-bit constant, not FNV's sparse prime, which moves
 * a word's bits mostly upwards) and a fold of the high half down, so a
 * change in any bit of a word reaches every bit of the chunk's hash; the
 * tail bytes as FNV-1a. One multiply per 8 bytes where FNV-1a took one a
 * byte: at 1M particles FNV-1a was 9% of a WCSPH step taking stats every
 * step, all on one thread. */
#define HASH_CHUNK ((size_t)1 << 16)
#define HASH_BATCH 256 /* chunks hashed per parallel loop: 16 MB */

static uint64_t hash_chunk(const unsigned char *p, size_t n)
{
	uint64_t h = EDDY__FNV_BASIS;
	size_t i = 0;
	for (; i + 8 <= n; i += 8) {
		uint64_t v;
		memcpy(&v, p + i, sizeof v);
		h = (h ^ v) * 0x9e3779b97f4a7c15ull;
		h ^= h >> 32;
	}
	return eddy__fnv1a(h, p + i, n - i);
}

static uint64_t hash_column(uint64_t h, const void *data, size_t bytes, int threads)
{
	const unsigned char *p = data;
	const size_t chunks = (bytes + HASH_CHUNK - 1) / HASH_CHUNK;
	uint64_t part[HASH_BATCH];
	for (size_t c0 = 0; c0 < chunks; c0 += HASH_BATCH) {
		const long cn = (long)(chunks - c0 < HASH_BATCH ? chunks - c0 : HASH_BATCH);
		const int nt = cn > 1 ? threads : 1;
#pragma omp parallel for num_threads(nt) if (nt > 1) schedule(static)
		for (long k = 0; k < cn; ++k) {
			const size_t at = (c0 + (size_t)k) * HASH_CHUNK;
			part[k] = hash_chunk(p + at, bytes - at < HASH_CHUNK ? bytes - at : HASH_CHUNK);
		}
		h = eddy__fnv1a(h, part, (size_t)cn * sizeof part[0]);
	}
	return h;
}

uint64_t eddy_world_state_hash(const eddy_world *w)
{
	if (!w)
		return 0;
	uint64_t h = EDDY__FNV_BASIS;
	uint64_t n = w->n;
	h = eddy__fnv1a(h, &n, sizeof n);
	h = eddy__fnv1a(h, &w->time, sizeof w->time);
	for (int c = 0; c < w->column_count; ++c) {
		const eddy_column *col = &w->columns[c];
		if (!col->data || col->lifetime != EDDY_STATE)
			continue;
		h = eddy__fnv1a(h, col->name, strlen(col->name));
		h = hash_column(h, col->data, eddy__column_bytes(w, col), w->def.threads);
	}
	return h;
}

/* ---- preflight ---------------------------------------------------------- */

void eddy__report(eddy_check_fn report, void *user, eddy_check_level level, const char *fmt, ...)
{
	char msg[512];
	va_list ap;
	va_start(ap, fmt);
	vsnprintf(msg, sizeof msg, fmt, ap);
	va_end(ap);
	report(level, msg, user);
}

double eddy__emission_limit(const eddy_world *w, bool done, double start, double spacing, double speed,
                            const char **reason)
{
	*reason = "emission";
	if (done || w->time + 1e-12 < start || !(speed > 0))
		return INFINITY;
	return spacing / speed;
}

bool eddy__emit_needs_check(const eddy_world *w)
{
	if (w->n > 0)
		return true;
	for (int k = 0; k < w->order_count; ++k)
		if (w->slots[w->order[k]].vt->distance)
			return true;
	return false;
}

/* The points inside a collider's solid (signed distance < 0): occupied.
 * Not those within a margin outside it: a lattice point just outside a
 * solid is where the water beside it is, and a gap left there is one the
 * water falls into (tests/scenes/obstacle_pool.lua, DFSPH: the largest
 * speed around a 4 cm sphere and a 6 x 10 x 8 cm box 0.09 and 0.26 m/s with
 * no margin, 0.34 and 0.71 with half a spacing). */
static void emit_solids(const eddy_world *w, const eddy_vec3 *pts, size_t np, uint8_t *occupied)
{
	/* each point's flag is written by one thread (the distances are
	 * read-only queries): the same flags on any thread count */
	const long n = (long)np;
	const int nt = n > EDDY_PAR_ROWS ? w->def.threads : 1;
	for (int k = 0; k < w->order_count; ++k) {
		const eddy_system *c = &w->slots[w->order[k]];
		if (!c->vt->distance)
			continue;
#pragma omp parallel for num_threads(nt) if (nt > 1) schedule(static)
		for (long q = 0; q < n; ++q)
			if (!occupied[q] && c->vt->distance(c, pts[q]) < 0)
				occupied[q] = 1;
	}
}

bool eddy__emit_occupied(eddy_world *w, const eddy_vec3 *pts, size_t np, float spacing, float clearance,
                         uint8_t *occupied)
{
	memset(occupied, 0, np);
	if (np == 0 || !(spacing > 0))
		return true;
	emit_solids(w, pts, np, occupied);
	if (w->n == 0)
		return true;
	/* the existing particles in the points' box (one spacing wider) bucketed
	 * in cells of one spacing: a point's particles lie in its 27 cells */
	double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
	for (size_t k = 0; k < np; ++k) {
		const double p[3] = {pts[k].x, pts[k].y, pts[k].z};
		for (int d = 0; d < 3; ++d) {
			lo[d] = p[d] < lo[d] ? p[d] : lo[d];
			hi[d] = p[d] > hi[d] ? p[d] : hi[d];
		}
	}
	size_t dim[3], cells = 1;
	for (int d = 0; d < 3; ++d) {
		lo[d] -= spacing;
		hi[d] += spacing;
		dim[d] = (size_t)((hi[d] - lo[d]) / spacing) + 1;
		cells *= dim[d];
	}
	if (cells >= UINT32_MAX || w->n >= UINT32_MAX) /* the buckets count in 32 bits */
		return false;
	const eddy_arena_mark am = eddy__arena_mark(&w->arena);
	uint32_t *start = eddy__arena_alloc(&w->arena, (cells + 1) * sizeof *start);
	uint32_t *cell_of = eddy__arena_alloc(&w->arena, w->n * sizeof *cell_of);
	if (!start || !cell_of) {
		eddy__arena_release(&w->arena, am);
		return false;
	}
	const float *x = eddy__col(w, COL_X_), *y = eddy__col(w, COL_Y_), *z = eddy__col(w, COL_Z_);
	memset(start, 0, (cells + 1) * sizeof *start);
	size_t inside = 0;
	for (size_t i = 0; i < w->n; ++i) {
		const double p[3] = {x[i], y[i], z[i]};
		size_t c = 0;
		bool in = true;
		for (int d = 2; d >= 0 && in; --d) {
			const double u = (p[d] - lo[d]) / spacing;
			in = u >= 0 && u < (double)dim[d];
			c = c * dim[d] + (in ? (size_t)u : 0);
		}
		cell_of[i] = in ? (uint32_t)c : UINT32_MAX;
		if (in) {
			start[c + 1]++;
			inside++;
		}
	}
	if (inside == 0) {
		eddy__arena_release(&w->arena, am);
		return true;
	}
	for (size_t c = 0; c < cells; ++c)
		start[c + 1] += start[c];
	uint32_t *fill = eddy__arena_alloc(&w->arena, cells * sizeof *fill);
	uint32_t *idx = eddy__arena_alloc(&w->arena, inside * sizeof *idx);
	if (!fill || !idx) {
		eddy__arena_release(&w->arena, am);
		return false;
	}
	memcpy(fill, start, cells * sizeof *fill);
	for (size_t i = 0; i < w->n; ++i)
		if (cell_of[i] != UINT32_MAX)
			idx[fill[cell_of[i]]++] = (uint32_t)i;
	/* the cube's faces included, with a hair for rounding: a point on the
	 * face two particles' cubes share (the lattices half a spacing apart)
	 * is filled */
	const double half = 0.5 * spacing * (1 + 1e-4), clear2 = (double)clearance * clearance;
	for (size_t k = 0; k < np; ++k) {
		const double p[3] = {pts[k].x, pts[k].y, pts[k].z};
		long cc[3]; /* about 1 and up: the box is a spacing wider than the points */
		for (int d = 0; d < 3; ++d)
			cc[d] = (long)((p[d] - lo[d]) / spacing);
		for (long cz = cc[2] - 1; cz <= cc[2] + 1 && !occupied[k]; ++cz)
			for (long cy = cc[1] - 1; cy <= cc[1] + 1 && !occupied[k]; ++cy)
				for (long cx = cc[0] - 1; cx <= cc[0] + 1 && !occupied[k]; ++cx) {
					if (cx < 0 || cy < 0 || cz < 0 || (size_t)cx >= dim[0] || (size_t)cy >= dim[1] ||
					    (size_t)cz >= dim[2])
						continue;
					const size_t c = ((size_t)cz * dim[1] + (size_t)cy) * dim[0] + (size_t)cx;
					for (uint32_t q = start[c]; q < start[c + 1]; ++q) {
						const uint32_t i = idx[q];
						const double dx = (double)x[i] - p[0], dy = (double)y[i] - p[1], dz = (double)z[i] - p[2];
						if (clearance > 0 ? dx * dx + dy * dy + dz * dz < clear2
						                  : fabs(dx) <= half && fabs(dy) <= half && fabs(dz) <= half) {
							occupied[k] = 1;
							break;
						}
					}
				}
	}
	eddy__arena_release(&w->arena, am);
	return true;
}

void eddy__check_emitter_start(const eddy_world *w, const eddy_system *s, double start, eddy_check_fn report,
                               void *user)
{
	const double duration = w->def.duration;
	if (duration > 0 && start >= duration)
		eddy__report(report, user, EDDY_CHECK_WARNING,
		             "%s: 'start' is %g s, not before the end of the run (duration %g s): it emits nothing; set "
		             "start < %g",
		             s->label, start, duration, duration);
}

static void count_only(eddy_check_level level, const char *message, void *user)
{
	(void)level;
	(void)message;
	(void)user;
}

int eddy_world_check(eddy_world *w, eddy_check_fn report, void *user)
{
	if (!report)
		report = count_only;
	if (!w) {
		report(EDDY_CHECK_ERROR, "world: no world to check (NULL)", user);
		return 1;
	}
	int errors = 0;
	/* memory: particle columns in use times the particles the emitters will make */
	int64_t expected = 0;
	bool unbounded = false;
	size_t per_particle = 0;
	for (int c = 0; c < w->column_count; ++c)
		if (w->columns[c].users > 0 && w->columns[c].domain == EDDY_DOMAIN_PARTICLE)
			per_particle += w->columns[c].type == EDDY_U8 ? 1 : sizeof(float);
	for (int k = 0; k < w->order_count; ++k) {
		const eddy_system *s = &w->slots[w->order[k]];
		if (!s->vt->expected_particles)
			continue;
		int64_t e = s->vt->expected_particles(w, s);
		if (e < 0)
			unbounded = true;
		else
			expected += e;
	}
	expected += (int64_t)w->n;
	double bytes = (double)expected * (double)per_particle * 2.0; /* growth doubles capacity */
	for (int c = 0; c < w->column_count; ++c)
		if (w->columns[c].users > 0 && w->columns[c].domain != EDDY_DOMAIN_PARTICLE)
			bytes += (double)eddy__column_bytes(w, &w->columns[c]);
	long pages = sysconf(_SC_PHYS_PAGES), page = sysconf(_SC_PAGE_SIZE);
	double avail = pages > 0 && page > 0 ? (double)pages * (double)page : 0;
	if (unbounded)
		eddy__report(
			report, user, EDDY_CHECK_WARNING,
			"memory: an emitter has no end (set duration or max_particles); %lld particles known, %zu bytes each",
			(long long)expected, per_particle);
	else
		eddy__report(report, user, EDDY_CHECK_INFO, "memory: %lld particles x %zu bytes, about %.1f MB in all",
		             (long long)expected, per_particle, bytes / 1e6);
	if (avail > 0 && bytes > 0.8 * avail) {
		eddy__report(report, user, EDDY_CHECK_ERROR,
		             "memory: the scene needs about %.1f GB but the machine has %.1f GB; use a coarser spacing",
		             bytes / 1e9, avail / 1e9);
		errors++;
	}

	if (w->def.settle_steps > 0 && w->step == 0 && !eddy__provider(w, NULL, EDDY_CAP_SPH_EOS_FORCE)) {
		eddy__report(report, user, EDDY_CHECK_ERROR, "world: %s", settle_needs);
		errors++;
	}

	/* frames: eddy run simulates ceil(duration * fps) whole frames, so a frame
	 * longer than the run makes the run longer than asked */
	const double fps = w->def.fps, duration = w->def.duration;
	if (duration > 0 && fps * duration < 1 - 1e-9) {
		eddy__report(report, user, EDDY_CHECK_ERROR,
		             "world: 'fps' is %g but 'duration' is %g s: the first frame (%g s) is longer than the whole run, "
		             "so a run would simulate %g s; set fps >= %g",
		             fps, duration, 1 / fps, 1 / fps, 1 / duration);
		errors++;
	} else if (duration > 0) {
		const double frames = ceil(duration * fps - 1e-9), simulated = frames / fps;
		if (simulated > duration * 1.01)
			eddy__report(report, user, EDDY_CHECK_WARNING,
			             "world: 'duration' %g s is not a whole number of frames at %g fps; a run simulates %.0f "
			             "frames = %g s",
			             duration, fps, frames, simulated);
	}

	/* the box against the emitters' lattice: a box narrower than a spacing
	 * along an axis has no room for a layer of particles (the pour at 0.5 m
	 * spacing in its 0.2 m box blew up in DFSPH's solve) */
	if (w->length_scale > 0) {
		const eddy_vec3 lo = w->def.bounds_min, hi = w->def.bounds_max;
		const double side[3] = {hi.x - lo.x, hi.y - lo.y, hi.z - lo.z};
		for (int a = 0; a < 3; ++a)
			if (side[a] < w->length_scale) {
				eddy__report(report, user, EDDY_CHECK_ERROR,
				             "world: 'bounds' are %g m along %c, less than the emitters' spacing %g m: no layer of "
				             "particles fits; use spacing <= %g m",
				             side[a], "xyz"[a], (double)w -> length_scale, side[a]);
				errors++;
				break;
			}
	}

	/* particles per cell: a grid method wants 3 to 12 (docs/validation.md §A);
	 * FLIP with less than one leaves fluid cells holding no particle, which
	 * the grid then takes for air */
	const bool flip = eddy__provider(w, NULL, EDDY_CAP_MAC_GRID) != NULL;
	if (w->grid_allocated && w->length_scale > 0) {
		const double ppc = pow(w->def.cell_size / w->length_scale, 3);
		if (flip && ppc < 1) {
			eddy__report(report, user, EDDY_CHECK_ERROR,
			             "flip_p2g: %.2f particles per cell (world cell_size %g m, emitter spacing %g m), below 1: "
			             "fluid cells would hold no particle; set spacing = cell_size / 2 = %g m",
			             ppc, w->def.cell_size, (double)w->length_scale, w->def.cell_size / 2);
			errors++;
		} else if (ppc < 3 || ppc > 12) {
			/* 8 per cell: spacing = cell_size / 2 */
			eddy__report(
				report, user, EDDY_CHECK_WARNING,
				"particles per cell: %.1f (cell_size %g m, spacing %g m); 3 to 12 keep the grid resolved, e.g. "
				"spacing = %g m",
				ppc, w->def.cell_size, (double)w->length_scale, w->def.cell_size / 2);
		} else {
			eddy__report(report, user, EDDY_CHECK_INFO, "particles per cell: %.1f", ppc);
		}
	}
	/* the box's faces inside the grid's last cells (flip.h, flip_grid's top):
	 * said, since cut cells are walls of a lower order than the grid's sides */
	if (flip && w->grid_allocated) {
		const flip_grid g = flip_grid_of(w);
		const int n[3] = {w->nx, w->ny, w->nz};
		char cut[160] = "";
		size_t len = 0;
		for (int a = 0; a < 3; ++a)
			if (g.top[a] < (float)n[a] && len < sizeof cut)
				len += (size_t)snprintf(cut + len, sizeof cut - len, "%s%c at %.2f of a cell", len ? ", " : "",
				                        "xyz"[a], (double)(g.top[a] - (float)(n[a] - 1)));
		if (len)
			eddy__report(report, user, EDDY_CHECK_INFO,
			             "grid: %d x %d x %d cells of %g m; the box is not a whole number of cells, so its faces cut "
			             "the last cells (%s): walls there are cut cells",
			             n[0], n[1], n[2], w->def.cell_size, cut);
	}

	/* FLIP counts every particle as the same volume, cell_size^3 / n0 with
	 * n0 from the finest emitter's spacing (flip_rest_count): water emitted
	 * coarser reads as a fraction of itself (a block at 1 cm beside one at
	 * 5 mm read 1/8 full and the two settled at 0.52 and 0.69 of the height they should have) */
	if (flip && w->length_scale > 0) {
		const eddy_system *fine = NULL, *e;
		for (eddy_system_iter it = eddy__systems(w, 0); (e = eddy__systems_next(&it));)
			if (e->vt->spacing && !(fine && e->vt->spacing(e) >= fine->vt->spacing(fine)))
				fine = e;
		for (eddy_system_iter it = eddy__systems(w, 0); fine && (e = eddy__systems_next(&it));) {
			if (!e->vt->spacing)
				continue;
			const double de = e->vt->spacing(e), df = fine->vt->spacing(fine);
			if (fabs(de / df - 1) <= 1e-3)
				continue;
			eddy__report(report, user, EDDY_CHECK_ERROR,
			             "flip_p2g: %s emits at spacing %g m and %s at %g m: FLIP counts every particle as the "
			             "same volume (cell_size^3 / %.3g, from the finest spacing), so %s's water would read "
			             "%.3g of its volume and collapse; emit every body at one spacing (%g m)",
			             e->label, de, fine->label, df, pow(w->def.cell_size / df, 3), e->label, pow(df / de, 3), df);
			errors++;
		}
	}

	/* one fluid, one method: the fluid systems act on every particle, so a
	 * second of a kind applies its step twice (a second eddy.fluid group in
	 * the world: two FLIP pipelines ran, gravity and the transfers twice a
	 * step, and nothing said so), and SPH's and FLIP's systems together
	 * move the same particles two ways */
	{
		static const eddy_system_vtable *const once[] = {
			&eddy__kind_sph_density,         &eddy__kind_sph_pressure,    &eddy__kind_sph_viscosity,
			&eddy__kind_sph_surface_tension, &eddy__kind_sph_dfsph,       &eddy__kind_integrate,
			&eddy__kind_flip_p2g,            &eddy__kind_flip_boundary,   &eddy__kind_flip_surface,
			&eddy__kind_flip_pressure,       &eddy__kind_flip_extrapolate, &eddy__kind_flip_g2p,
			&eddy__kind_flip_advect,         &eddy__kind_flip_reseed};
		const eddy_system *dup_first = NULL, *dup = NULL;
		int dups = 0;
		for (size_t q = 0; q < sizeof once / sizeof once[0]; ++q) {
			const eddy_system *first = NULL;
			for (int k = 0; k < w->order_count; ++k) {
				const eddy_system *s = &w->slots[w->order[k]];
				if (s->vt != once[q])
					continue;
				if (!first) {
					first = s;
					continue;
				}
				if (dups++ == 0) /* the message names the first pair */
					dup_first = first, dup = s;
				break;
			}
		}
		if (dups) {
			char more[64] = "";
			if (dups > 1)
				snprintf(more, sizeof more, " (and %d more systems repeat)", dups - 1);
			eddy__report(report, user, EDDY_CHECK_ERROR,
			             "pipeline: %s repeats %s%s: each would run twice a step on the same particles; a world holds "
			             "one fluid (one eddy.fluid group, one method)",
			             dup->label, dup_first->label, more);
			errors++;
		}
		const eddy_system *sph = eddy__provider(w, NULL, EDDY_CAP_SPH_NEIGHBORS);
		const eddy_system *grid = eddy__provider(w, NULL, EDDY_CAP_MAC_GRID);
		if (sph && grid) {
			eddy__report(report, user, EDDY_CHECK_ERROR,
			             "pipeline: %s (SPH) and %s (FLIP) in one world would move the same particles two ways; "
			             "a world runs one method",
			             sph->label, grid->label);
			errors++;
		}
	}

	/* emitted particles that nothing moves: a scene without integrate (or
	 * flip_advect) runs, and its fluid hangs in the air */
	bool emits = false, moves = false;
	for (int k = 0; k < w->order_count; ++k) {
		const eddy_system *s = &w->slots[w->order[k]];
		if (s->vt->spacing) {
			emits = true;
			continue;
		}
		for (int j = 0; j < s->write_count; ++j)
			moves = moves || s->writes[j] == COL_X_;
	}
	if (emits && !moves)
		eddy__report(report, user, EDDY_CHECK_WARNING,
		             "pipeline: no system moves the particles (none writes x after emitting); add integrate "
		             "(flip_advect for FLIP)");

	/* the kinds' own checks (SPH spacing against the emitters, ...) */
	for (int k = 0; k < w->order_count; ++k) {
		const eddy_system *s = &w->slots[w->order[k]];
		if (s->vt->check)
			errors += s->vt->check(w, s, report, user);
	}

	/* time step at the start */
	const char *reason;
	double lim = step_limit(w, &reason);
	double frame_dt = 1.0 / w->def.fps;
	eddy__report(report, user, EDDY_CHECK_INFO, "time step: %.3g s at the start, limited by %s (%.0f steps per frame)",
	             lim, reason, ceil(frame_dt / lim - 1e-9));
	if (ceil(frame_dt / lim - 1e-9) > w->def.max_steps_per_frame) {
		eddy__report(report, user, EDDY_CHECK_ERROR,
		             "time step: a frame needs %.0f steps, more than max_steps_per_frame = %d; raise it or relax %s",
		             ceil(frame_dt / lim - 1e-9), w->def.max_steps_per_frame, reason);
		errors++;
	}
	if (lim < w->def.dt_min) {
		eddy__report(report, user, EDDY_CHECK_ERROR, "time step: %s allows %.3g s, below dt_min = %.3g s", reason, lim,
		             w->def.dt_min);
		errors++;
	}

	/* a collider before the last system that moves the particles (integrate,
	 * flip_advect, sph_dfsph's shift): its push comes before they move, so
	 * they can end a step inside its solid (the stats' leaked; a DFSPH pool
	 * in a collide_sphere bowl added before the fluid: 10-56 of 1,818
	 * particles a frame, none with the bowl added after it) */
	int last_mover = -1;
	for (int k = 0; k < w->order_count; ++k) {
		const eddy_system *m = &w->slots[w->order[k]];
		/* emitters place particles, colliders are what is checked, and
		 * flip_reseed moves particles only into cells no collider cuts: it
		 * runs after the colliders by design */
		if (m->vt->sample || m->vt->distance || m->vt == &eddy__kind_flip_reseed)
			continue;
		for (int j = 0; j < m->write_count; ++j)
			if (m->writes[j] == COL_X_)
				last_mover = k;
	}
	for (int k = 0; k < last_mover; ++k) {
		const eddy_system *c = &w->slots[w->order[k]];
		if (c->vt->distance)
			eddy__report(report, user, EDDY_CHECK_WARNING,
			             "%s runs before %s, which moves the particles after its push: they can end a step inside "
			             "its solid (the stats' leaked); add it after the fluid (world:add it later)",
			             c->label, w->slots[w->order[last_mover]].label);
	}

	/* emitters whose first particles start inside a collider or outside the bounds */
	for (int k = 0; k < w->order_count; ++k) {
		const eddy_system *e = &w->slots[w->order[k]];
		if (!e->vt->sample)
			continue;
		size_t cap = e->vt->sample(w, e, NULL, 0);
		if (cap > ((size_t)1 << 20))
			cap = (size_t)1 << 20; /* a sample is enough to find overlaps */
		eddy_vec3 *pts = cap ? malloc(cap * sizeof *pts) : NULL;
		if (cap && !pts)
			continue;
		size_t np = e->vt->sample(w, e, pts, cap);
		if (np == 0) {
			eddy__report(report, user, EDDY_CHECK_ERROR,
			             "%s: emits no particles; make its region larger than its spacing", e->label);
			errors++;
		}
		for (int j = 0; j < w->order_count; ++j) {
			const eddy_system *c = &w->slots[w->order[j]];
			if (!c->vt->distance)
				continue;
			size_t inside = 0;
			for (size_t i = 0; i < np; ++i)
				inside += c->vt->distance(c, pts[i]) < 0;
			/* a tank's solid is all that lies outside it: points far off in
			 * opposite directions are both in it */
			const eddy_vec3 blo = w->def.bounds_min, bhi = w->def.bounds_max;
			const float far = 1e3f * (1 + (bhi.x - blo.x) + (bhi.y - blo.y) + (bhi.z - blo.z));
			const bool tank = inside && c->vt->distance(c, (eddy_vec3){bhi.x + far, bhi.y + far, bhi.z + far}) < 0 &&
			                  c->vt->distance(c, (eddy_vec3){blo.x - far, blo.y - far, blo.z - far}) < 0;
			if (inside && inside == np) {
				eddy__report(report, user, EDDY_CHECK_ERROR,
				             tank ? "%s: all %zu particles start outside %s, a tank (inside = true: particles stay "
				                    "in it); move the emitter into it, or set the collider's inside = false for a "
				                    "solid obstacle"
				                  : "%s: all %zu particles start inside the solid of %s; move the emitter or the "
				                    "collider (for a tank, set the collider's inside = true)",
				             e->label, np, c->label);
				errors++;
			} else if (inside && (e->vt == &eddy__kind_emit_box || e->vt == &eddy__kind_emit_mesh)) {
				eddy__report(report, user, EDDY_CHECK_WARNING,
				             tank ? "%s: %zu of %zu particles start outside %s, a tank (inside = true); they are "
				                    "left out (for a solid obstacle set its inside = false)"
				                  : "%s: %zu of %zu particles start inside %s; they are left out (the water fills "
				                    "around the solid)",
				             e->label, inside, np, c->label);
			} else if (inside) {
				eddy__report(report, user, EDDY_CHECK_WARNING,
				             "%s: %zu of %zu particles start inside %s; they will be pushed out in the first step",
				             e->label, inside, np, c->label);
			}
		}
		size_t outside = 0;
		const eddy_vec3 lo = w->def.bounds_min, hi = w->def.bounds_max;
		for (size_t i = 0; i < np; ++i) {
			eddy_vec3 p = pts[i];
			outside += !(p.x >= lo.x && p.x <= hi.x && p.y >= lo.y && p.y <= hi.y && p.z >= lo.z && p.z <= hi.z);
		}
		if (outside) {
			eddy__report(report, user, EDDY_CHECK_ERROR, "%s: %zu of %zu particles start outside the world bounds",
			             e->label, outside, np);
			errors++;
		}
		free(pts);
	}
	return errors;
}
