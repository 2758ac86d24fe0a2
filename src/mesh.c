/* SPDX-License-Identifier: MIT */
/* Triangle meshes read through assimp's C API (OBJ, STL, PLY, glTF, FBX, ...)
 * and their signed distance fields, for collide_mesh and emit_mesh.
 *
 * Loading: aiImportFile with Triangulate (polygons to triangles),
 * JoinIdenticalVertices, PreTransformVertices (the file's node transforms
 * baked in, so a glTF or FBX scene lands where its author put it) and
 * SortByPType (points and lines split off and ignored). Every triangle of
 * every mesh is placed by the pose, then vertices at equal positions are
 * welded, across meshes too: formats such as STL store each triangle's
 * corners separately, and OBJ splits a vertex that carries two normals.
 *
 * Topology: a closed surface has every edge in exactly two triangles, once
 * in each direction (consistent winding). Anything else is counted and
 * reported, so a user learns why a mesh has no well-defined inside.
 *
 * Inside/outside: the winding number along grid-aligned rays. For each
 * triangle, the rows whose (y, z) line passes through its projection get a
 * signed crossing at the x where the line meets it (sign: the x component
 * of the triangle's normal). A row passing exactly through a shared edge
 * or vertex must count exactly one of the triangles there: the 2D
 * point-in-triangle test breaks ties of zero signed area by a fixed order of
 * coordinates, the same for both triangles of an edge (Batty's SDFGen,
 * after Edelsbrunner & Muecke's simulation of simplicity). A prefix sum along
 * each row gives the winding number of every sample. Why rays rather than
 * angle-weighted pseudo-normals (Baerentzen & Aanaes 2005): the pseudo-normal
 * gives the right sign only from the true nearest feature, which the fast
 * sweep below finds exactly near the surface but not always far from it;
 * the ray count is exact for a closed mesh at every sample and costs one
 * pass over the triangles. For an open mesh (accepted only on request) no
 * single ray is right, so six rays (+-x, +-y, +-z) vote and four make a
 * sample inside: a hole smaller than the mesh's silhouette from most sides
 * changes one or two votes, not the answer.
 *
 * Distance: exact point-triangle distances (Ericson 2005, 5.1.5) at the
 * nodes within two cells of each triangle's box, then fast sweeping
 * (Zhao 2005) that offers each node its neighbours' closest triangles, as
 * in Batty's SDFGen: exact near the surface, an upper bound that is nearly
 * always exact further out. Lookup is trilinear. */
#include "mesh.h"

#include <assimp/cimport.h>
#include <assimp/postprocess.h>
#include <assimp/scene.h>

#include <float.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* ---- loading -------------------------------------------------------------- */

static void rotation(eddy_vec3 r, double R[3][3])
{
	const double ang = sqrt((double)r.x * r.x + (double)r.y * r.y + (double)r.z * r.z);
	const double rad = ang * 3.14159265358979323846 / 180.0;
	double k[3] = {0, 0, 0};
	if (ang > 0)
		k[0] = r.x / ang, k[1] = r.y / ang, k[2] = r.z / ang;
	const double c = cos(rad), s = sin(rad), t = 1 - c;
	R[0][0] = c + k[0] * k[0] * t;
	R[0][1] = k[0] * k[1] * t - k[2] * s;
	R[0][2] = k[0] * k[2] * t + k[1] * s;
	R[1][0] = k[1] * k[0] * t + k[2] * s;
	R[1][1] = c + k[1] * k[1] * t;
	R[1][2] = k[1] * k[2] * t - k[0] * s;
	R[2][0] = k[2] * k[0] * t - k[1] * s;
	R[2][1] = k[2] * k[1] * t + k[0] * s;
	R[2][2] = c + k[2] * k[2] * t;
}

typedef struct vkey {
	double p[3];
	int i;
} vkey;

static int cmp_vkey(const void *a, const void *b)
{
	const vkey *x = a, *y = b;
	for (int c = 0; c < 3; ++c)
		if (x->p[c] != y->p[c])
			return x->p[c] < y->p[c] ? -1 : 1;
	return (x->i > y->i) - (x->i < y->i);
}

typedef struct ekey {
	int a, b;    /* a < b */
	int forward; /* 1 when the triangle runs a -> b */
} ekey;

static int cmp_ekey(const void *p, const void *q)
{
	const ekey *x = p, *y = q;
	if (x->a != y->a)
		return x->a < y->a ? -1 : 1;
	return (x->b > y->b) - (x->b < y->b);
}

/* Counts open, non-manifold and inconsistently wound edges. */
static bool topology(eddy_trimesh *m)
{
	const size_t ne = 3 * (size_t)m->nt;
	ekey *e = malloc(ne * sizeof *e);
	if (!e)
		return false;
	for (int t = 0; t < m->nt; ++t)
		for (int k = 0; k < 3; ++k) {
			const int a = m->t[t][k], b = m->t[t][(k + 1) % 3];
			e[3 * (size_t)t + (size_t)k] = (ekey){a < b ? a : b, a < b ? b : a, a < b};
		}
	qsort(e, ne, sizeof *e, cmp_ekey);
	m->open_edges = m->nonmanifold_edges = m->flipped_edges = 0;
	for (size_t i = 0; i < ne;) {
		size_t j = i;
		int fwd = 0;
		while (j < ne && e[j].a == e[i].a && e[j].b == e[i].b)
			fwd += e[j++].forward;
		const size_t uses = j - i;
		if (uses == 1)
			m->open_edges++;
		else if (uses > 2)
			m->nonmanifold_edges++;
		else if (fwd != 1)
			m->flipped_edges++;
		i = j;
	}
	free(e);
	return true;
}

static double signed_volume(const eddy_trimesh *m)
{
	double v = 0;
	for (int t = 0; t < m->nt; ++t) {
		const double *a = m->v[m->t[t][0]], *b = m->v[m->t[t][1]], *c = m->v[m->t[t][2]];
		v += a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0]) +
		     a[2] * (b[0] * c[1] - b[1] * c[0]);
	}
	return v / 6.0;
}

bool eddy__mesh_closed(const eddy_trimesh *m)
{
	return m->open_edges == 0 && m->nonmanifold_edges == 0 && m->flipped_edges == 0;
}

void eddy__mesh_describe_open(const eddy_trimesh *m, const char *path, char *err, size_t cap)
{
	if (eddy__mesh_closed(m)) {
		if (cap)
			err[0] = '\0';
		return;
	}
	snprintf(err, cap,
	         "%s: the mesh is not a closed surface (%d open edges, %d edges in more than two triangles, %d edges "
	         "whose triangles are wound inconsistently), so it has no well-defined inside; close it, or set "
	         "open = true to decide inside by a vote of six rays",
	         path, m->open_edges, m->nonmanifold_edges, m->flipped_edges);
}

void eddy__mesh_free(eddy_trimesh *m)
{
	if (!m)
		return;
	free(m->v);
	free(m->t);
	memset(m, 0, sizeof *m);
}

bool eddy__mesh_load(eddy_trimesh *m, const char *path, eddy_mesh_pose pose, char *err, size_t cap)
{
	memset(m, 0, sizeof *m);
	const struct aiScene *sc = aiImportFile(path, aiProcess_Triangulate | aiProcess_JoinIdenticalVertices |
	                                                  aiProcess_PreTransformVertices | aiProcess_SortByPType);
	if (!sc) {
		const char *why = aiGetErrorString();
		snprintf(err, cap, "%s: cannot read the mesh: %s", path, why && why[0] ? why : "unknown reason");
		return false;
	}
	size_t nv = 0, nt = 0;
	for (unsigned k = 0; k < sc->mNumMeshes; ++k) {
		const struct aiMesh *me = sc->mMeshes[k];
		nv += me->mNumVertices;
		for (unsigned f = 0; f < me->mNumFaces; ++f)
			nt += me->mFaces[f].mNumIndices == 3;
	}
	if (nt == 0) {
		aiReleaseImport(sc);
		snprintf(err, cap, "%s: the file holds no triangles", path);
		return false;
	}
	if (nv > (size_t)1 << 28 || nt > (size_t)1 << 28) {
		aiReleaseImport(sc);
		snprintf(err, cap, "%s: %zu triangles is more than eddy takes", path, nt);
		return false;
	}
	double R[3][3];
	rotation(pose.rotate, R);
	const double sc3[3] = {pose.scale.x, pose.scale.y, pose.scale.z},
				 tr[3] = {pose.translate.x, pose.translate.y, pose.translate.z};
	vkey *keys = malloc(nv * sizeof *keys);
	int *tri = malloc(3 * nt * sizeof *tri), *id = malloc(nv * sizeof *id);
	m->v = malloc(nv * sizeof *m->v);
	if (!keys || !tri || !id || !m->v) {
		free(keys), free(tri), free(id);
		eddy__mesh_free(m);
		aiReleaseImport(sc);
		snprintf(err, cap, "%s: out of memory for %zu vertices", path, nv);
		return false;
	}
	size_t base = 0, q = 0;
	for (unsigned k = 0; k < sc->mNumMeshes; ++k) {
		const struct aiMesh *me = sc->mMeshes[k];
		for (unsigned i = 0; i < me->mNumVertices; ++i) {
			const double s[3] = {sc3[0] * me->mVertices[i].x, sc3[1] * me->mVertices[i].y, sc3[2] * me->mVertices[i].z};
			vkey *kk = &keys[base + i];
			for (int a = 0; a < 3; ++a)
				kk->p[a] = R[a][0] * s[0] + R[a][1] * s[1] + R[a][2] * s[2] + tr[a];
			kk->i = (int)(base + i);
		}
		for (unsigned f = 0; f < me->mNumFaces; ++f)
			if (me->mFaces[f].mNumIndices == 3)
				for (int c = 0; c < 3; ++c)
					tri[q++] = (int)(base + me->mFaces[f].mIndices[c]);
		base += me->mNumVertices;
	}
	aiReleaseImport(sc);
	for (size_t i = 0; i < nv; ++i)
		if (!isfinite(keys[i].p[0]) || !isfinite(keys[i].p[1]) || !isfinite(keys[i].p[2])) {
			snprintf(err, cap, "%s: vertex %zu is not finite", path, i);
			free(keys), free(tri), free(id);
			eddy__mesh_free(m);
			return false;
		}
	/* weld: equal positions become one vertex */
	qsort(keys, nv, sizeof *keys, cmp_vkey);
	int count = 0;
	for (size_t i = 0; i < nv; ++i) {
		if (i == 0 || keys[i].p[0] != keys[i - 1].p[0] || keys[i].p[1] != keys[i - 1].p[1] ||
		    keys[i].p[2] != keys[i - 1].p[2]) {
			memcpy(m->v[count], keys[i].p, sizeof m->v[count]);
			count++;
		}
		id[keys[i].i] = count - 1;
	}
	m->nv = count;
	m->t = malloc(nt * sizeof *m->t);
	if (!m->t) {
		free(keys), free(tri), free(id);
		eddy__mesh_free(m);
		snprintf(err, cap, "%s: out of memory for %zu triangles", path, nt);
		return false;
	}
	/* triangles with two equal corners have no area and no inside */
	int kept = 0;
	for (size_t t = 0; t < nt; ++t) {
		const int a = id[tri[3 * t]], b = id[tri[3 * t + 1]], c = id[tri[3 * t + 2]];
		if (a == b || b == c || a == c)
			continue;
		m->t[kept][0] = a, m->t[kept][1] = b, m->t[kept][2] = c;
		kept++;
	}
	m->nt = kept;
	free(keys), free(tri), free(id);
	if (m->nt == 0) {
		eddy__mesh_free(m);
		snprintf(err, cap, "%s: every triangle is degenerate (two equal corners)", path);
		return false;
	}
	for (int a = 0; a < 3; ++a)
		m->lo[a] = DBL_MAX, m->hi[a] = -DBL_MAX;
	for (int i = 0; i < m->nv; ++i)
		for (int a = 0; a < 3; ++a) {
			m->lo[a] = fmin(m->lo[a], m->v[i][a]);
			m->hi[a] = fmax(m->hi[a], m->v[i][a]);
		}
	if (!topology(m)) {
		eddy__mesh_free(m);
		snprintf(err, cap, "%s: out of memory for the edges", path);
		return false;
	}
	m->volume = signed_volume(m);
	if (eddy__mesh_closed(m) && m->volume < 0) {
		/* wound inward: turn it outward */
		for (int t = 0; t < m->nt; ++t) {
			const int s = m->t[t][1];
			m->t[t][1] = m->t[t][2];
			m->t[t][2] = s;
		}
		m->volume = -m->volume;
	}
	const double ext = fmax(m->hi[0] - m->lo[0], fmax(m->hi[1] - m->lo[1], m->hi[2] - m->lo[2]));
	if (!(ext > 0)) {
		eddy__mesh_free(m);
		snprintf(err, cap, "%s: the mesh has no extent (every vertex at one point)", path);
		return false;
	}
	return true;
}

/* ---- inside: winding numbers along rays --------------------------------- */

/* Sign of y1 x2 - x1 y2, ties broken by a fixed order of the coordinates so
 * the two triangles of an edge never both (or neither) claim a point on it
 * (SDFGen). *area gets the value. 0 only for two equal points. */
static int orientation(double x1, double y1, double x2, double y2, double *area)
{
	*area = y1 * x2 - x1 * y2;
	if (*area > 0)
		return 1;
	if (*area < 0)
		return -1;
	if (y2 > y1)
		return 1;
	if (y2 < y1)
		return -1;
	if (x1 > x2)
		return 1;
	if (x1 < x2)
		return -1;
	return 0;
}

/* Whether (x0, y0) lies in the 2D triangle; its barycentric weights in w and
 * the common orientation sign in *sign. */
static bool point_in_triangle_2d(double x0, double y0, double x1, double y1, double x2, double y2, double x3, double y3,
                                 double w[3], int *sign)
{
	x1 -= x0, x2 -= x0, x3 -= x0;
	y1 -= y0, y2 -= y0, y3 -= y0;
	const int sa = orientation(x2, y2, x3, y3, &w[0]);
	if (sa == 0)
		return false;
	if (orientation(x3, y3, x1, y1, &w[1]) != sa)
		return false;
	if (orientation(x1, y1, x2, y2, &w[2]) != sa)
		return false;
	const double sum = w[0] + w[1] + w[2];
	if (sum == 0)
		return false; /* the triangle is edge-on to the ray */
	w[0] /= sum, w[1] /= sum, w[2] /= sum;
	*sign = sa;
	return true;
}

/* Winding numbers of the samples along axis a: from the low end into wlo,
 * from the high end into whi (either may be NULL), indexed x fastest. */
static bool winding_axis(const eddy_trimesh *m, const double origin[3], double h, const int n[3], int a, int *wlo,
                         int *whi)
{
	const int b = (a + 1) % 3, c = (a + 2) % 3, na = n[a], nb = n[b], nc = n[c];
	const size_t rows = (size_t)nb * (size_t)nc;
	int *diff = calloc(rows * (size_t)(na + 1), sizeof *diff), *total = calloc(rows, sizeof *total);
	if (!diff || !total) {
		free(diff), free(total);
		return false;
	}
	for (int t = 0; t < m->nt; ++t) {
		const double *P[3] = {m->v[m->t[t][0]], m->v[m->t[t][1]], m->v[m->t[t][2]]};
		const double blo = fmin(P[0][b], fmin(P[1][b], P[2][b])), bhi = fmax(P[0][b], fmax(P[1][b], P[2][b]));
		const double clo = fmin(P[0][c], fmin(P[1][c], P[2][c])), chi = fmax(P[0][c], fmax(P[1][c], P[2][c]));
		const int j0 = (int)fmax(0, ceil((blo - origin[b]) / h)), j1 = (int)fmin(nb - 1, floor((bhi - origin[b]) / h));
		const int k0 = (int)fmax(0, ceil((clo - origin[c]) / h)), k1 = (int)fmin(nc - 1, floor((chi - origin[c]) / h));
		for (int k = k0; k <= k1; ++k)
			for (int j = j0; j <= j1; ++j) {
				const double yb = origin[b] + j * h, zc = origin[c] + k * h;
				double w[3];
				int sa;
				if (!point_in_triangle_2d(yb, zc, P[0][b], P[0][c], P[1][b], P[1][c], P[2][b], P[2][c], w, &sa))
					continue;
				/* orientation() has the opposite sign of the cross product, so
				 * -sa is the sign of the normal's a component */
				const int s = -sa;
				const double xa = w[0] * P[0][a] + w[1] * P[1][a] + w[2] * P[2][a];
				double g = floor((xa - origin[a]) / h) + 1; /* first sample strictly past the crossing */
				g = g < 0 ? 0 : g > na ? na : g;
				const size_t row = (size_t)j + (size_t)nb * (size_t)k;
				diff[row * (size_t)(na + 1) + (size_t)g] -= s;
				total[row] += s;
			}
	}
	for (int k = 0; k < nc; ++k)
		for (int j = 0; j < nb; ++j) {
			const size_t row = (size_t)j + (size_t)nb * (size_t)k;
			int acc = 0;
			for (int i = 0; i < na; ++i) {
				acc += diff[row * (size_t)(na + 1) + (size_t)i];
				int idx[3];
				idx[a] = i, idx[b] = j, idx[c] = k;
				const size_t q = (size_t)idx[0] + (size_t)n[0] * ((size_t)idx[1] + (size_t)n[1] * (size_t)idx[2]);
				if (wlo)
					wlo[q] = acc;
				if (whi)
					whi[q] = total[row] + acc;
			}
		}
	free(diff), free(total);
	return true;
}

bool eddy__mesh_inside(const eddy_trimesh *m, const double origin[3], double h, const int n[3], bool vote,
                       uint8_t *inside)
{
	const size_t N = (size_t)n[0] * (size_t)n[1] * (size_t)n[2];
	int *wlo = malloc(N * sizeof *wlo), *whi = vote ? malloc(N * sizeof *whi) : NULL;
	memset(inside, 0, N);
	if (!wlo || (vote && !whi)) {
		free(wlo), free(whi);
		return false;
	}
	bool ok = true;
	if (!vote) {
		ok = winding_axis(m, origin, h, n, 0, wlo, NULL);
		for (size_t q = 0; ok && q < N; ++q)
			inside[q] = wlo[q] != 0;
	} else {
		for (int a = 0; ok && a < 3; ++a) {
			ok = winding_axis(m, origin, h, n, a, wlo, whi);
			for (size_t q = 0; ok && q < N; ++q)
				inside[q] = (uint8_t)(inside[q] + (wlo[q] != 0) + (whi[q] != 0));
		}
		for (size_t q = 0; q < N; ++q)
			inside[q] = inside[q] >= 4;
	}
	free(wlo), free(whi);
	return ok;
}

/* ---- distance ------------------------------------------------------------- */

static double dot3(const double *a, const double *b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }

double eddy__mesh_triangle_distance(const eddy_trimesh *m, int t, const double p[3])
{
	const double *a = m->v[m->t[t][0]], *b = m->v[m->t[t][1]], *c = m->v[m->t[t][2]];
	double ab[3], ac[3], ap[3], q[3];
	for (int i = 0; i < 3; ++i)
		ab[i] = b[i] - a[i], ac[i] = c[i] - a[i], ap[i] = p[i] - a[i];
	const double d1 = dot3(ab, ap), d2 = dot3(ac, ap);
	if (d1 <= 0 && d2 <= 0) {
		memcpy(q, a, sizeof q);
		goto done;
	}
	double bp[3];
	for (int i = 0; i < 3; ++i)
		bp[i] = p[i] - b[i];
	const double d3 = dot3(ab, bp), d4 = dot3(ac, bp);
	if (d3 >= 0 && d4 <= d3) {
		memcpy(q, b, sizeof q);
		goto done;
	}
	const double vc = d1 * d4 - d3 * d2;
	if (vc <= 0 && d1 >= 0 && d3 <= 0) {
		const double v = d1 / (d1 - d3);
		for (int i = 0; i < 3; ++i)
			q[i] = a[i] + v * ab[i];
		goto done;
	}
	double cp[3];
	for (int i = 0; i < 3; ++i)
		cp[i] = p[i] - c[i];
	const double d5 = dot3(ab, cp), d6 = dot3(ac, cp);
	if (d6 >= 0 && d5 <= d6) {
		memcpy(q, c, sizeof q);
		goto done;
	}
	const double vb = d5 * d2 - d1 * d6;
	if (vb <= 0 && d2 >= 0 && d6 <= 0) {
		const double w = d2 / (d2 - d6);
		for (int i = 0; i < 3; ++i)
			q[i] = a[i] + w * ac[i];
		goto done;
	}
	const double va = d3 * d6 - d5 * d4;
	if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) {
		const double w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
		for (int i = 0; i < 3; ++i)
			q[i] = b[i] + w * (c[i] - b[i]);
		goto done;
	}
	{
		const double den = 1.0 / (va + vb + vc), v = vb * den, w = vc * den;
		for (int i = 0; i < 3; ++i)
			q[i] = a[i] + ab[i] * v + ac[i] * w;
	}
done:;
	const double dx = p[0] - q[0], dy = p[1] - q[1], dz = p[2] - q[2];
	return sqrt(dx * dx + dy * dy + dz * dz);
}

/* One sweep direction: each node tries the closest triangles of its seven
 * upwind neighbours (the octant the sweep comes from, as SDFGen). */
static void sweep(const eddy_trimesh *m, eddy_sdf *s, int *tri, int di, int dj, int dk)
{
	const int nx = s->n[0], ny = s->n[1], nz = s->n[2];
	const int i0 = di > 0 ? 1 : nx - 2, i1 = di > 0 ? nx : -1;
	const int j0 = dj > 0 ? 1 : ny - 2, j1 = dj > 0 ? ny : -1;
	const int k0 = dk > 0 ? 1 : nz - 2, k1 = dk > 0 ? nz : -1;
	const long sx = di, sy = (long)dj * nx, sz = (long)dk * nx * ny;
	const long back[7] = {sx, sy, sz, sx + sy, sx + sz, sy + sz, sx + sy + sz};
	for (int k = k0; k != k1; k += dk)
		for (int j = j0; j != j1; j += dj)
			for (int i = i0; i != i1; i += di) {
				const long q = (long)i + (long)nx * ((long)j + (long)ny * (long)k);
				const double p[3] = {s->origin[0] + i * s->h, s->origin[1] + j * s->h, s->origin[2] + k * s->h};
				for (int e = 0; e < 7; ++e) {
					const int t = tri[q - back[e]];
					if (t < 0 || t == tri[q])
						continue;
					const double d = eddy__mesh_triangle_distance(m, t, p);
					if (d < s->d[q]) {
						s->d[q] = (float)d;
						tri[q] = t;
					}
				}
			}
}

size_t eddy__sdf_plan(eddy_sdf *s, const eddy_trimesh *m, double h, int margin)
{
	memset(s, 0, sizeof *s);
	s->h = h;
	double N = 1;
	for (int a = 0; a < 3; ++a) {
		s->n[a] = (int)ceil((m->hi[a] - m->lo[a]) / h - 1e-9) + 2 * margin + 1;
		s->origin[a] = m->lo[a] - margin * h;
		N *= s->n[a];
	}
	return N > (double)(1 << 26) ? 0 : (size_t)N;
}

bool eddy__sdf_fill(eddy_sdf *s, const eddy_trimesh *m, bool vote, int threads)
{
	const double h = s->h;
	const size_t n = (size_t)s->n[0] * (size_t)s->n[1] * (size_t)s->n[2];
	int *tri = malloc(n * sizeof *tri);
	uint8_t *in = malloc(n);
	if (!tri || !in) {
		free(tri), free(in);
		return false;
	}
	for (size_t q = 0; q < n; ++q)
		s->d[q] = FLT_MAX, tri[q] = -1;
	const int band = 2;
	const int nx = s->n[0], ny = s->n[1];
	/* The narrow band in z slabs, one thread a slab: every slab visits the
	 * triangles in index order, so a node keeps the first of its nearest
	 * triangles whatever the thread count. */
	const int nslab = threads > 1 ? 4 * threads : 1;
#pragma omp parallel for num_threads(threads) if (threads > 1) schedule(dynamic, 1)
	for (int slab = 0; slab < nslab; ++slab) {
		const int k0 = (int)((long)s->n[2] * slab / nslab), k1 = (int)((long)s->n[2] * (slab + 1) / nslab) - 1;
		for (int t = 0; t < m->nt; ++t) {
			int lo[3], hi[3];
			for (int a = 0; a < 3; ++a) {
				const double *P0 = m->v[m->t[t][0]], *P1 = m->v[m->t[t][1]], *P2 = m->v[m->t[t][2]];
				const double tlo = fmin(P0[a], fmin(P1[a], P2[a])), thi = fmax(P0[a], fmax(P1[a], P2[a]));
				lo[a] = (int)fmax(0, floor((tlo - s->origin[a]) / h) - band);
				hi[a] = (int)fmin(s->n[a] - 1, ceil((thi - s->origin[a]) / h) + band);
			}
			lo[2] = lo[2] > k0 ? lo[2] : k0;
			hi[2] = hi[2] < k1 ? hi[2] : k1;
			for (int k = lo[2]; k <= hi[2]; ++k)
				for (int j = lo[1]; j <= hi[1]; ++j)
					for (int i = lo[0]; i <= hi[0]; ++i) {
						const size_t q = (size_t)i + (size_t)nx * ((size_t)j + (size_t)ny * (size_t)k);
						const double p[3] = {s->origin[0] + i * h, s->origin[1] + j * h, s->origin[2] + k * h};
						const double d = eddy__mesh_triangle_distance(m, t, p);
						if (d < s->d[q]) {
							s->d[q] = (float)d;
							tri[q] = t;
						}
					}
		}
	}
	for (int pass = 0; pass < 2; ++pass)
		for (int dir = 0; dir < 8; ++dir)
			sweep(m, s, tri, dir & 1 ? -1 : 1, dir & 2 ? -1 : 1, dir & 4 ? -1 : 1);
	const bool ok = eddy__mesh_inside(m, s->origin, h, s->n, vote, in);
	for (size_t q = 0; q < n; ++q)
		if (in[q])
			s->d[q] = -s->d[q];
	free(tri), free(in);
	return ok;
}

float eddy__sdf_value(const eddy_sdf *s, eddy_vec3 p)
{
	const double g[3] = {(p.x - s->origin[0]) / s->h, (p.y - s->origin[1]) / s->h, (p.z - s->origin[2]) / s->h};
	double out2 = 0, f[3];
	int i[3];
	for (int a = 0; a < 3; ++a) {
		const double top = s->n[a] - 1;
		double c = g[a];
		if (!(c >= 0)) /* NaN lands here too */
			out2 += c < 0 ? c * c : 0, c = 0;
		else if (c > top)
			out2 += (c - top) * (c - top), c = top;
		int k = (int)c;
		if (k > s->n[a] - 2)
			k = s->n[a] - 2;
		i[a] = k;
		f[a] = c - k;
	}
	const size_t nx = (size_t)s->n[0], nxy = nx * (size_t)s->n[1];
	const float *d = s->d + (size_t)i[0] + nx * (size_t)i[1] + nxy * (size_t)i[2];
	const double c00 = d[0] + f[0] * (d[1] - d[0]), c10 = d[nx] + f[0] * (d[nx + 1] - d[nx]);
	const double c01 = d[nxy] + f[0] * (d[nxy + 1] - d[nxy]),
				 c11 = d[nxy + nx] + f[0] * (d[nxy + nx + 1] - d[nxy + nx]);
	const double c0 = c00 + f[1] * (c10 - c00), c1 = c01 + f[1] * (c11 - c01);
	return (float)(c0 + f[2] * (c1 - c0) + sqrt(out2) * s->h);
}
