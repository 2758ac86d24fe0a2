/* SPDX-License-Identifier: MIT */
/* The view both renderers share (render_points, render_surface): the camera
 * (look-at view; perspective or orthographic projection with near and far
 * planes fitted to the world's bounds), its checks, the key light, the
 * domain's box edges and the supersample box filter.
 *
 * An automatic camera (eye == target) looks at the bounds' centre from a fixed
 * direction, front, a little right and above, backed off until every corner
 * of the bounds is inside the frustum: a corner q (from the centre) at depth
 * D + q.f needs |q.s| <= (D + q.f) tan(half width angle), and the same for
 * q.u vertically. The near and far planes enclose the bounds' corners with a
 * margin of 5% of the depth range plus depth_pad (what is drawn can reach out
 * of the bounds by a particle radius or a surface's support). */
#include "render.h"

#include <math.h>
#include <string.h>

#define PI_F 3.14159265358979f

float eddy_v3_len(eddy_vec3 a) { return sqrtf(eddy_v3_dot(a, a)); }

eddy_vec3 eddy_v3_norm(eddy_vec3 a)
{
	float l = eddy_v3_len(a);
	return l > 0 ? eddy_v3_scale(a, 1.0f / l) : a;
}

static int finite3(eddy_vec3 v) { return isfinite(v.x) && isfinite(v.y) && isfinite(v.z); }

int eddy_color_ok(eddy_vec3 c) { return c.x >= 0 && c.x <= 1 && c.y >= 0 && c.y <= 1 && c.z >= 0 && c.z <= 1; }

const char *eddy_view_check(const eddy_view_def *d, char *buf, size_t cap)
{
	if (d->width < 1 || d->width > 8192)
		snprintf(buf, cap, "'width' must be in [1, 8192] px (got %d)", d->width);
	else if (d->height < 1 || d->height > 8192)
		snprintf(buf, cap, "'height' must be in [1, 8192] px (got %d)", d->height);
	else if (d->supersample < 1 || d->supersample > 4)
		snprintf(buf, cap, "'supersample' must be in [1, 4] (got %d)", d->supersample);
	else if ((long)d->width * d->supersample > 16384 || (long)d->height * d->supersample > 16384)
		snprintf(buf, cap, "'width' and 'height' times 'supersample' must be <= 16384 px");
	else if (!finite3(d->eye) || !finite3(d->target) || !finite3(d->up))
		snprintf(buf, cap, "'eye', 'target' and 'up' must be finite");
	else if (!(d->fov > 0 && d->fov < 180))
		snprintf(buf, cap, "'fov' must be in (0, 180) degrees (got %g)", (double)d->fov);
	else if (d->projection != EDDY_PROJECTION_PERSPECTIVE && d->projection != EDDY_PROJECTION_ORTHOGRAPHIC)
		snprintf(buf, cap, "'projection' must be perspective or orthographic");
	else if (!(d->ortho_height >= 0) || !isfinite(d->ortho_height))
		snprintf(buf, cap, "'ortho_height' must be >= 0 m (got %g)", (double)d->ortho_height);
	else if (d->eye.x != d->target.x || d->eye.y != d->target.y || d->eye.z != d->target.z) {
		eddy_vec3 f = eddy_v3_norm(eddy_v3_sub(d->target, d->eye));
		if (eddy_v3_len(eddy_v3_cross(f, eddy_v3_norm(d->up))) >= 1e-4f)
			return NULL;
		snprintf(buf, cap, "'up' must not be parallel to the view direction (eye to target)");
	} else if (eddy_v3_len(d->up) == 0)
		snprintf(buf, cap, "'up' must not be zero");
	else
		return NULL;
	return buf;
}

static eddy_vec3 corner(eddy_vec3 lo, eddy_vec3 hi, int k)
{
	return (eddy_vec3){(k & 1) ? hi.x : lo.x, (k & 2) ? hi.y : lo.y, (k & 4) ? hi.z : lo.z};
}

void eddy_camera_make(const eddy_view_def *d, const eddy_world_def *wd, eddy_camera *c)
{
	const eddy_vec3 lo = wd->bounds_min, hi = wd->bounds_max;
	const eddy_vec3 center = eddy_v3_scale(eddy_v3_add(lo, hi), 0.5f);
	const float R = 0.5f * eddy_v3_len(eddy_v3_sub(hi, lo));
	const float aspect = (float)d->width / (float)d->height;
	const float half_fov = 0.5f * d->fov * (PI_F / 180.0f);
	eddy_vec3 eye = d->eye, target = d->target;
	if (eye.x == target.x && eye.y == target.y && eye.z == target.z) {
		target = center;
		const eddy_vec3 back = eddy_v3_norm((eddy_vec3){0.42f, 0.38f, 1.0f});
		const eddy_vec3 f = eddy_v3_scale(back, -1.0f), sd = eddy_v3_norm(eddy_v3_cross(f, d->up)),
						u = eddy_v3_cross(sd, f);
		const float tv = tanf(half_fov), th = tv * aspect;
		float D = 0;
		for (int k = 0; k < 8; ++k) {
			eddy_vec3 q = eddy_v3_sub(corner(lo, hi, k), center);
			float qf = eddy_v3_dot(q, f), need_s = fabsf(eddy_v3_dot(q, sd)) / th - qf,
				  need_u = fabsf(eddy_v3_dot(q, u)) / tv - qf;
			D = need_s > D ? need_s : D;
			D = need_u > D ? need_u : D;
		}
		eye = eddy_v3_add(center, eddy_v3_scale(back, 1.06f * D + d->eye_pad));
	}
	c->eye = eye;
	c->fwd = eddy_v3_norm(eddy_v3_sub(target, eye));
	c->side = eddy_v3_norm(eddy_v3_cross(c->fwd, d->up));
	c->up = eddy_v3_cross(c->side, c->fwd);
	float *v = c->view;
	memset(v, 0, 16 * sizeof *v);
	v[0] = c->side.x, v[4] = c->side.y, v[8] = c->side.z, v[12] = -eddy_v3_dot(c->side, eye);
	v[1] = c->up.x, v[5] = c->up.y, v[9] = c->up.z, v[13] = -eddy_v3_dot(c->up, eye);
	v[2] = -c->fwd.x, v[6] = -c->fwd.y, v[10] = -c->fwd.z, v[14] = eddy_v3_dot(c->fwd, eye);
	v[15] = 1;
	float dmin = INFINITY, dmax = -INFINITY, smax = 0, umax = 0;
	for (int k = 0; k < 8; ++k) {
		const eddy_vec3 p = corner(lo, hi, k);
		const float depth = eddy_v3_dot(eddy_v3_sub(p, eye), c->fwd);
		dmin = depth < dmin ? depth : dmin;
		dmax = depth > dmax ? depth : dmax;
		const float s = fabsf(eddy_v3_dot(eddy_v3_sub(p, target), c->side)),
					u = fabsf(eddy_v3_dot(eddy_v3_sub(p, target), c->up));
		smax = s > smax ? s : smax;
		umax = u > umax ? u : umax;
	}
	const float margin = 0.05f * (dmax - dmin) + d->depth_pad + 1e-3f * R;
	float farp = dmax + margin, nearp = dmin - margin;
	float *p = c->proj;
	memset(p, 0, 16 * sizeof *p);
	if (d->projection == EDDY_PROJECTION_ORTHOGRAPHIC) {
		float hh = 0.5f * d->ortho_height;
		if (!(hh > 0))
			hh = 1.05f * (umax > smax / aspect ? umax : smax / aspect);
		p[0] = 1.0f / (hh * aspect);
		p[5] = 1.0f / hh;
		p[10] = -2.0f / (farp - nearp);
		p[14] = -(farp + nearp) / (farp - nearp);
		p[15] = 1;
	} else {
		if (nearp < 1e-3f * farp)
			nearp = 1e-3f * farp; /* the camera is inside the bounds */
		const float f = 1.0f / tanf(half_fov);
		p[0] = f / aspect;
		p[5] = f;
		p[10] = (farp + nearp) / (nearp - farp);
		p[11] = -1;
		p[14] = 2 * farp * nearp / (nearp - farp);
	}
}

void eddy_key_light(float light[3])
{
	const float lx = -0.38f, ly = 0.62f, lz = 0.69f, ll = sqrtf(lx * lx + ly * ly + lz * lz);
	light[0] = lx / ll, light[1] = ly / ll, light[2] = lz / ll;
}

void eddy_box_edges(float *out, eddy_vec3 lo, eddy_vec3 hi)
{
	/* corner k has x from bit 0, y from bit 1, z from bit 2; an edge flips one bit */
	int e = 0;
	for (int k = 0; k < 8; ++k)
		for (int bit = 1; bit < 8; bit <<= 1) {
			if (k & bit)
				continue;
			const eddy_vec3 a = corner(lo, hi, k), b = corner(lo, hi, k | bit);
			float *o = out + 6 * e++;
			o[0] = a.x, o[1] = a.y, o[2] = a.z, o[3] = b.x, o[4] = b.y, o[5] = b.z;
		}
}

void eddy_rotate_points(float *xyz, size_t n, eddy_vec3 rotation, eddy_vec3 pivot)
{
	/* Rodrigues: R v = v cos t + (k x v) sin t + k (k . v)(1 - cos t), with k
	 * the unit axis and t the angle (the rotation vector is in degrees) */
	const double len =
		sqrt((double)rotation.x * rotation.x + (double)rotation.y * rotation.y + (double)rotation.z * rotation.z);
	if (!(len > 0))
		return;
	const double kx = rotation.x / len, ky = rotation.y / len, kz = rotation.z / len;
	const double t = len * 3.14159265358979323846 / 180, c = cos(t), sn = sin(t);
	for (size_t i = 0; i < n; ++i) {
		float *p = xyz + 3 * i;
		const double vx = p[0] - pivot.x, vy = p[1] - pivot.y, vz = p[2] - pivot.z;
		const double kv = kx * vx + ky * vy + kz * vz;
		p[0] = (float)(pivot.x + vx * c + (ky * vz - kz * vy) * sn + kx * kv * (1 - c));
		p[1] = (float)(pivot.y + vy * c + (kz * vx - kx * vz) * sn + ky * kv * (1 - c));
		p[2] = (float)(pivot.z + vz * c + (kx * vy - ky * vx) * sn + kz * kv * (1 - c));
	}
}

void eddy_downsample_rows(const uint8_t *rgba, int W, int H, int s, uint8_t *out, int y0, int y1)
{
	eddy_downsample_block(rgba, W, H, s, out, y0, y1, 0, W);
}

void eddy_downsample_block(const uint8_t *rgba, int W, int H, int s, uint8_t *out, int y0, int y1, int x0, int x1)
{
	const int sw = W * s, sh = H * s;
	const unsigned area = (unsigned)(s * s);
	for (int y = y0; y < y1; ++y) {
		uint8_t *o = out + (size_t)y * (size_t)W * 3;
		if (s == 1) {
			const uint8_t *row = rgba + (size_t)(sh - 1 - y) * (size_t)sw * 4; /* GL rows bottom-up */
			for (int x = x0; x < x1; ++x)
				o[3 * x] = row[4 * x], o[3 * x + 1] = row[4 * x + 1], o[3 * x + 2] = row[4 * x + 2];
			continue;
		}
		if (s == 2) {
			/* the default supersample: two rows, two pixels each */
			const uint8_t *r0 = rgba + (size_t)(sh - 1 - 2 * y) * (size_t)sw * 4, *r1 = r0 - (size_t)sw * 4;
			r0 += 8 * (size_t)x0, r1 += 8 * (size_t)x0;
			for (int x = x0; x < x1; ++x, r0 += 8, r1 += 8)
				for (int c = 0; c < 3; ++c)
					o[3 * x + c] = (uint8_t)((unsigned)(r0[c] + r0[4 + c] + r1[c] + r1[4 + c] + 2) / 4);
			continue;
		}
		for (int x = x0; x < x1; ++x) {
			unsigned sum[3] = {0, 0, 0};
			for (int j = 0; j < s; ++j) {
				const uint8_t *row = rgba + (size_t)(sh - 1 - (y * s + j)) * (size_t)sw * 4;
				for (int i = 0; i < s; ++i)
					for (int c = 0; c < 3; ++c)
						sum[c] += row[(size_t)(x * s + i) * 4 + (size_t)c];
			}
			for (int c = 0; c < 3; ++c)
				o[3 * x + c] = (uint8_t)((sum[c] + area / 2) / area);
		}
	}
}
