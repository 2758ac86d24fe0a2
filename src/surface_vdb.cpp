/* SPDX-License-Identifier: MIT */
/* The liquid surface from particles, with OpenVDB (the library's one C++
 * translation unit; see surface.h for the C interface).
 *
 * Field: the SPH colour field (volume fraction) of the particles,
 *   c(x) = sum_j V W(|x - x_j|, R),  V = spacing^3,
 * with the cubic spline kernel of support radius R (Monaghan 1992; the
 * normalisation of SPlisHSPlasH's CubicKernel), rasterised into a sparse
 * openvdb::FloatGrid of voxel size dx, stored as -c (inside lower, as in a
 * level set). Each particle adds to the voxels within R of it; the particles
 * are split into fixed chunks, each chunk into its own grid (through a dense
 * block over the chunk's voxel box when that box is at most 8 times the
 * voxels its kernels touch: a packed pool, where the tree's accessor would
 * cost most of the meshing; else voxel by voxel into the tree), and the grids
 * summed pairwise in a fixed order (tbb::parallel_deterministic_reduce), so
 * a frame's mesh does not depend on the thread count.
 *
 * Surface: c = 1/2, extracted with openvdb::tools::volumeToMesh (adaptivity
 * 0: every voxel its own polygons; quads split into two triangles). Why the
 * half level of the colour field rather than a union of spheres
 * (openvdb::tools::ParticlesToLevelSet) or Zhu & Bridson's (2005) blended
 * spheres: the colour field of a uniform half-space of particles is exactly
 * 1/2 on the plane halfway between the outer layer and the next layer out
 * (the kernel is symmetric and sums to one), so a resting block's surface
 * encloses N spacing^3 whatever the particle arrangement, while a union of
 * spheres puts a flat face somewhere between r and sqrt(r^2 - s^2/2) beyond
 * the outer centres depending on the lattice. Curvature pulls the half level
 * in by about the kernel's variance over the radius (R^2/(10 R_sphere) here),
 * a small fraction of a spacing for drops a few spacings across. The sparse
 * grid's background is 0 (no fluid), so the isosurface never meets the grid's
 * edge and the mesh is closed.
 *
 * Normals: the field's gradient at each vertex (trilinear samples of -c half
 * a voxel either side), normalised; where the gradient vanishes, the
 * area-weighted normal of the triangles around the vertex.
 *
 * Level set (.vdb): openvdb::tools::levelSetRebuild turns the field's 1/2
 * level into a narrow-band signed distance (3 voxels each side), grid class
 * level set, named "surface", written with openvdb::io::File to a temporary
 * name and renamed into place. */
#include "surface.h"

#include <openvdb/openvdb.h>
#include <openvdb/tools/Composite.h>
#include <openvdb/tools/Dense.h>
#include <openvdb/tools/Interpolation.h>
#include <openvdb/tools/LevelSetRebuild.h>
#include <openvdb/tools/VolumeToMesh.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_reduce.h>
#include <tbb/task_arena.h>

#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <climits>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <exception>
#include <string>
#include <vector>

/* this file's own symbols stay inside the library (see the Makefile) */
#pragma GCC visibility push(hidden)

namespace
{

using openvdb::FloatGrid;

struct Field {
	FloatGrid::Ptr grid;
	float isovalue; /* -1/2 */
};

/* Most particles one grid accumulates (ranges are halved down to this);
 * fixed, so the summation order is. Large enough that a pool of thousands
 * is one dense block and needs no joining of grids. */
const size_t CHUNK = 8192;
/* Largest dense block a chunk is splatted into, voxels (64 MB of floats). */
const double DENSE_MAX = double(1 << 24);

struct Splat {
	const float *x, *y, *z;
	float dx, R, V;
	openvdb::math::Transform::Ptr xform;
	FloatGrid::Ptr grid;

	Splat(const float *x_, const float *y_, const float *z_, float dx_, float R_, float V_,
	      openvdb::math::Transform::Ptr t)
		: x(x_), y(y_), z(z_), dx(dx_), R(R_), V(V_), xform(t), grid(FloatGrid::create(0.0f))
	{
		grid->setTransform(xform);
	}
	Splat(Splat &o, tbb::split)
		: x(o.x), y(o.y), z(o.z), dx(o.dx), R(o.R), V(o.V), xform(o.xform), grid(FloatGrid::create(0.0f))
	{
		grid->setTransform(xform);
	}

	/* Adds the kernels of particles [b, e) to the voxels, through add(i, j, k, value). */
	template <typename Add> void splat(size_t b, size_t e, Add add) const
	{
		const float k = 8.0f / (float(M_PI) * R * R * R), inv_R = 1.0f / R, inv_dx = 1.0f / dx;
		for (size_t p = b; p != e; ++p) {
			const float px = x[p], py = y[p], pz = z[p];
			/* voxel (i, j, k) has its centre at (i, j, k) dx */
			const int i0 = int(std::ceil((px - R) * inv_dx)), i1 = int(std::floor((px + R) * inv_dx));
			const int j0 = int(std::ceil((py - R) * inv_dx)), j1 = int(std::floor((py + R) * inv_dx));
			const int k0 = int(std::ceil((pz - R) * inv_dx)), k1 = int(std::floor((pz + R) * inv_dx));
			for (int i = i0; i <= i1; ++i) {
				const float ex = float(i) * dx - px;
				for (int j = j0; j <= j1; ++j) {
					const float ey = float(j) * dx - py;
					const float exy = ex * ex + ey * ey;
					if (exy >= R * R)
						continue;
					for (int kk = k0; kk <= k1; ++kk) {
						const float ez = float(kk) * dx - pz;
						const float q = std::sqrt(exy + ez * ez) * inv_R;
						if (q >= 1.0f)
							continue;
						const float W = q <= 0.5f ? k * (6.0f * q * q * (q - 1.0f) + 1.0f)
						                          : k * 2.0f * (1.0f - q) * (1.0f - q) * (1.0f - q);
						add(i, j, kk, -V * W);
					}
				}
			}
		}
	}

	void operator()(const tbb::blocked_range<size_t> &r)
	{
		/* the voxel box of the range's kernels */
		const float inv_dx = 1.0f / dx;
		int lo[3] = {INT32_MAX, INT32_MAX, INT32_MAX}, hi[3] = {INT32_MIN, INT32_MIN, INT32_MIN};
		for (size_t p = r.begin(); p != r.end(); ++p) {
			const float q[3] = {x[p], y[p], z[p]};
			for (int c = 0; c < 3; ++c) {
				lo[c] = std::min(lo[c], int(std::ceil((q[c] - R) * inv_dx)));
				hi[c] = std::max(hi[c], int(std::floor((q[c] + R) * inv_dx)));
			}
		}
		const double box = double(hi[0] - lo[0] + 1) * double(hi[1] - lo[1] + 1) * double(hi[2] - lo[2] + 1);
		const double kernel = std::pow(2.0 * double(R * inv_dx) + 1.0, 3.0);
		if (grid->empty() && box > 0 && box <= DENSE_MAX && box <= 8.0 * kernel * double(r.size())) {
			/* a dense block when the particles are packed: plain adds instead of
			 * the tree's accessor, the same sums in the same order, then the
			 * nonzero voxels (every voxel a kernel reached) into the tree */
			const openvdb::CoordBBox bbox(openvdb::Coord(lo[0], lo[1], lo[2]), openvdb::Coord(hi[0], hi[1], hi[2]));
			openvdb::tools::Dense<float, openvdb::tools::LayoutZYX> dense(bbox, 0.0f);
			float *d = dense.data();
			const size_t sx = dense.xStride(), sy = dense.yStride();
			splat(r.begin(), r.end(), [&](int i, int j, int kk, float v) {
				d[size_t(i - lo[0]) * sx + size_t(j - lo[1]) * sy + size_t(kk - lo[2])] += v;
			});
			openvdb::tools::copyFromDense(dense, *grid, 0.0f);
			return;
		}
		FloatGrid::Accessor acc = grid->getAccessor();
		splat(r.begin(), r.end(), [&](int i, int j, int kk, float v) {
			acc.modifyValue(openvdb::Coord(i, j, kk), [v](float &u) { u += v; });
		});
	}

	void join(Splat &o) { openvdb::tools::compSum(*grid, *o.grid); }
};

template <typename T> bool grow(T **buf, size_t *cap, size_t n)
{
	if (n <= *cap)
		return true;
	size_t c = n + n / 4 + 16;
	void *q = std::realloc(*buf, c * sizeof(T));
	if (!q)
		return false;
	*buf = static_cast<T *>(q);
	*cap = c;
	return true;
}

void set_err(char *err, size_t cap, const char *what, const char *detail)
{
	if (cap)
		std::snprintf(err, cap, "%s%s%s", what, detail ? ": " : "", detail ? detail : "");
}

/* The mesh volumeToMesh gave (quads split in two) into mesh, with the
 * normals of the field grid (its gradient, else the faces'): 0 or -1. */
int fill_mesh(const FloatGrid &grid, float dx, const std::vector<openvdb::Vec3s> &points,
              const std::vector<openvdb::Vec3I> &tris, const std::vector<openvdb::Vec4I> &quads, eddy_mesh *mesh,
              char *err, size_t cap)
{
	const size_t nv = points.size(), nt = tris.size() + 2 * quads.size();
	if (nv > UINT32_MAX)
		return set_err(err, cap, "the surface has more than 2^32 vertices", nullptr), -1;
	if (!grow(&mesh->xyz, &mesh->vertex_cap, 3 * nv) || !grow(&mesh->normal, &mesh->normal_cap, 3 * nv) ||
	    !grow(&mesh->tri, &mesh->triangle_cap, 3 * nt))
		return set_err(err, cap, "out of memory for the surface mesh", nullptr), -1;
	for (size_t v = 0; v < nv; ++v)
		for (int c = 0; c < 3; ++c)
			mesh->xyz[3 * v + size_t(c)] = points[v][c];
	/* volumeToMesh winds polygons counter-clockwise seen from the side
	 * where the field is above the isovalue (outside here), as PLY, OBJ
	 * and GL expect; a quad (a b c d) becomes (a b c) and (a c d) */
	uint32_t *t = mesh->tri;
	for (const openvdb::Vec3I &f : tris)
		*t++ = f[0], *t++ = f[1], *t++ = f[2];
	for (const openvdb::Vec4I &f : quads) {
		*t++ = f[0], *t++ = f[1], *t++ = f[2];
		*t++ = f[0], *t++ = f[2], *t++ = f[3];
	}
	mesh->vertex_count = nv;
	mesh->triangle_count = nt;

	/* normals: the field's gradient, else the faces' */
	std::vector<float> face(3 * nv, 0.0f);
	for (size_t f = 0; f < nt; ++f) {
		const uint32_t *q = mesh->tri + 3 * f;
		const float *a = mesh->xyz + 3 * q[0], *b = mesh->xyz + 3 * q[1], *c = mesh->xyz + 3 * q[2];
		const float u[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]}, w[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
		const float nrm[3] = {u[1] * w[2] - u[2] * w[1], u[2] * w[0] - u[0] * w[2], u[0] * w[1] - u[1] * w[0]};
		for (int k = 0; k < 3; ++k)
			for (int c3 = 0; c3 < 3; ++c3)
				face[3 * q[k] + size_t(c3)] += nrm[c3];
	}
	const float h = 0.5f * dx;
	/* the sampler keeps a reference to the accessor: it must outlive it */
	const FloatGrid::ConstAccessor acc = grid.getConstAccessor();
	openvdb::tools::GridSampler<FloatGrid::ConstAccessor, openvdb::tools::BoxSampler> sampler(acc, grid.transform());
	for (size_t v = 0; v < nv; ++v) {
		const float *P = mesh->xyz + 3 * v;
		float g[3];
		for (int c = 0; c < 3; ++c) {
			openvdb::Vec3d a(P[0], P[1], P[2]), b(P[0], P[1], P[2]);
			a[c] += h, b[c] -= h;
			g[c] = float(sampler.wsSample(a) - sampler.wsSample(b));
		}
		float len = std::sqrt(g[0] * g[0] + g[1] * g[1] + g[2] * g[2]);
		if (!(len > 1e-12f)) {
			for (int c = 0; c < 3; ++c)
				g[c] = face[3 * v + size_t(c)];
			len = std::sqrt(g[0] * g[0] + g[1] * g[1] + g[2] * g[2]);
		}
		for (int c = 0; c < 3; ++c)
			mesh->normal[3 * v + size_t(c)] = len > 0 ? g[c] / len : (c == 2 ? 1.0f : 0.0f);
	}

	return 0;
}

} // namespace

extern "C" int eddy__surface_build(const float *x, const float *y, const float *z, size_t n,
                                   const eddy__surface_params *p, eddy_mesh *mesh, char *err, size_t cap)
{
	try {
		openvdb::initialize();
		const float dx = p->voxel;
		openvdb::math::Transform::Ptr xform = openvdb::math::Transform::createLinearTransform(double(dx));
		Splat splat(x, y, z, dx, p->support, p->spacing * p->spacing * p->spacing, xform);
		std::vector<openvdb::Vec3s> points;
		std::vector<openvdb::Vec3I> tris;
		std::vector<openvdb::Vec4I> quads;
		const float iso = -0.5f;
		tbb::task_arena arena(p->threads > 0 ? p->threads : 1);
		arena.execute([&] {
			if (n > 0)
				tbb::parallel_deterministic_reduce(tbb::blocked_range<size_t>(0, n, CHUNK), splat,
				                                   tbb::simple_partitioner());
			splat.grid->pruneGrid(0.0f);
			openvdb::tools::volumeToMesh(*splat.grid, points, tris, quads, double(iso), 0.0, true);
		});

		if (fill_mesh(*splat.grid, dx, points, tris, quads, mesh, err, cap) != 0)
			return -1;

		Field *fld = static_cast<Field *>(mesh->field);
		if (!fld)
			mesh->field = fld = new Field();
		fld->grid = splat.grid;
		fld->isovalue = iso;
		return 0;
	} catch (const std::bad_alloc &) {
		set_err(err, cap, "out of memory for the surface field", nullptr);
	} catch (const std::exception &e) {
		set_err(err, cap, "OpenVDB failed", e.what());
	} catch (...) {
		set_err(err, cap, "OpenVDB failed", "unknown exception");
	}
	return -1;
}

extern "C" int eddy__surface_from_samples(const float *d, const int dims[3], const float origin[3], float dx,
                                          eddy_mesh *mesh, char *err, size_t cap)
{
	try {
		openvdb::initialize();
		/* background: outside, three cells away; every sample nearer or inside
		 * is stored, so the solid's interior is never background and the
		 * surface closes where the solid leaves the sampled box */
		const float far = 3.0f * dx;
		FloatGrid::Ptr grid = FloatGrid::create(far);
		openvdb::math::Transform::Ptr xform = openvdb::math::Transform::createLinearTransform(double(dx));
		xform->postTranslate(openvdb::Vec3d(origin[0], origin[1], origin[2]));
		grid->setTransform(xform);
		FloatGrid::Accessor acc = grid->getAccessor();
		for (int i = 0; i < dims[0]; ++i)
			for (int j = 0; j < dims[1]; ++j)
				for (int k = 0; k < dims[2]; ++k) {
					const float v = d[(size_t(i) * size_t(dims[1]) + size_t(j)) * size_t(dims[2]) + size_t(k)];
					if (v < far)
						acc.setValue(openvdb::Coord(i, j, k), v);
				}
		std::vector<openvdb::Vec3s> points;
		std::vector<openvdb::Vec3I> tris;
		std::vector<openvdb::Vec4I> quads;
		openvdb::tools::volumeToMesh(*grid, points, tris, quads, 0.0, 0.0, true);
		return fill_mesh(*grid, dx, points, tris, quads, mesh, err, cap);
	} catch (const std::bad_alloc &) {
		set_err(err, cap, "out of memory for the collider's mesh", nullptr);
	} catch (const std::exception &e) {
		set_err(err, cap, "OpenVDB failed", e.what());
	} catch (...) {
		set_err(err, cap, "OpenVDB failed", "unknown exception");
	}
	return -1;
}

extern "C" int eddy__surface_write_vdb(const eddy_mesh *mesh, const char *path, char *err, size_t cap)
{
	const Field *fld = static_cast<const Field *>(mesh->field);
	if (!fld || !fld->grid)
		return set_err(err, cap, "no surface has been built yet", nullptr), -1;
	/* a hidden temporary file beside the final one, renamed into place */
	std::string final_path(path), dir, base = final_path;
	const size_t slash = final_path.rfind('/');
	if (slash != std::string::npos)
		dir = final_path.substr(0, slash + 1), base = final_path.substr(slash + 1);
	const std::string tmp = dir + "." + base + "." + std::to_string(long(getpid())) + "-vdb.tmp";
	try {
		FloatGrid::Ptr ls = openvdb::tools::levelSetRebuild(*fld->grid, fld->isovalue, 3.0f);
		ls->setGridClass(openvdb::GRID_LEVEL_SET);
		ls->setName("surface");
		openvdb::GridPtrVec grids;
		grids.push_back(ls);
		openvdb::io::File file(tmp);
		file.write(grids);
		file.close();
	} catch (const std::exception &e) {
		std::remove(tmp.c_str());
		std::string why = std::string("cannot write '") + path + "'";
		return set_err(err, cap, why.c_str(), e.what()), -1;
	} catch (...) {
		std::remove(tmp.c_str());
		return set_err(err, cap, "cannot write the .vdb file", "unknown exception"), -1;
	}
	if (std::rename(tmp.c_str(), path) != 0) {
		const int e = errno;
		std::remove(tmp.c_str());
		std::string why = std::string("cannot rename '") + tmp + "' to '" + path + "'";
		return set_err(err, cap, why.c_str(), std::strerror(e)), -1;
	}
	return 0;
}

extern "C" void eddy__surface_free_field(void *field) { delete static_cast<Field *>(field); }

#pragma GCC visibility pop
