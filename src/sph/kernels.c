/* SPDX-License-Identifier: MIT */
/* The SPH kernels of Mueller, Charypar & Gross 2003 (3D) as public functions
 * of r, for hosts and tests; the systems use their constants (sph.h).
 *   poly6      W = 315/(64 pi h^9) (h^2 - r^2)^3
 *   spiky      W = 15/(pi h^6) (h - r)^3,          dW/dr = -45/(pi h^6) (h - r)^2
 *   viscosity  W = 15/(2 pi h^3) (-r^3/(2h^3) + r^2/h^2 + h/(2r) - 1),
 *              lap W = 45/(pi h^6) (h - r)
 * All are zero for r >= h and integrate to 1 over the ball of radius h. */
#include "sph.h"

/* W (order 0), dW/dr (1) or lap W (2) of kernel k. */
static double kernel(eddy_sph_kernel k, int order, double r, double h)
{
	if (!(h > 0) || !(r >= 0) || r >= h)
		return 0;
	const double h3 = h * h * h, h6 = h3 * h3, d = h * h - r * r;
	switch (3 * (int)k + order) {
	case 3 * EDDY_SPH_POLY6:
		return 315.0 / (64.0 * M_PI * h6 * h3) * d * d * d;
	case 3 * EDDY_SPH_POLY6 + 1:
		return -6.0 * 315.0 / (64.0 * M_PI * h6 * h3) * d * d * r;
	case 3 * EDDY_SPH_POLY6 + 2:
		return -6.0 * 315.0 / (64.0 * M_PI * h6 * h3) * d * (3 * h * h - 7 * r * r);
	case 3 * EDDY_SPH_SPIKY:
		return 15.0 / (M_PI * h6) * (h - r) * (h - r) * (h - r);
	case 3 * EDDY_SPH_SPIKY + 1:
		return -45.0 / (M_PI * h6) * (h - r) * (h - r);
	case 3 * EDDY_SPH_SPIKY + 2: /* (1/r^2) d/dr (r^2 dW/dr) */
		return r == 0 ? -INFINITY : -90.0 / (M_PI * h6) * (h - r) * (h - 2 * r) / r;
	case 3 * EDDY_SPH_VISCOSITY: /* an integrable 1/r singularity at 0 */
		return r == 0 ? INFINITY
		              : 15.0 / (2.0 * M_PI * h3) * (-r * r * r / (2 * h3) + r * r / (h * h) + h / (2 * r) - 1);
	case 3 * EDDY_SPH_VISCOSITY + 1:
		return r == 0 ? -INFINITY
		              : 15.0 / (2.0 * M_PI * h3) * (-3 * r * r / (2 * h3) + 2 * r / (h * h) - h / (2 * r * r));
	case 3 * EDDY_SPH_VISCOSITY + 2:
		return 45.0 / (M_PI * h6) * (h - r);
	}
	return 0;
}

double eddy_sph_kernel_value(eddy_sph_kernel k, double r, double h) { return kernel(k, 0, r, h); }

double eddy_sph_kernel_derivative(eddy_sph_kernel k, double r, double h) { return kernel(k, 1, r, h); }

double eddy_sph_kernel_laplacian(eddy_sph_kernel k, double r, double h) { return kernel(k, 2, r, h); }

/* Over the simple cubic lattice of the given spacing: the sum of W, or with
 * moment its gradient moment -sum V x^2 (dW/dr) / r (the point itself, which
 * has no direction, left out; so is the viscosity kernel's singular self
 * term from the sum). */
static double lattice(eddy_sph_kernel k, double spacing, double h, bool moment)
{
	if (!(spacing > 0) || !(h > 0))
		return 0;
	if (!(h / spacing <= 100))
		return NAN; /* (2 h / spacing)^3 terms: a mistaken argument must not hang the host */
	const int m = (int)ceil(h / spacing);
	const double vol = spacing * spacing * spacing;
	double sum = 0;
	for (int i = -m; i <= m; ++i)
		for (int j = -m; j <= m; ++j)
			for (int l = -m; l <= m; ++l) {
				const double r = spacing * sqrt((double)(i * i + j * j + l * l)), xi = spacing * i;
				if (moment && r > 0)
					sum -= vol * xi * xi * kernel(k, 1, r, h) / r;
				else if (!moment && !(k == EDDY_SPH_VISCOSITY && r == 0))
					sum += kernel(k, 0, r, h);
			}
	return sum;
}

double eddy_sph_lattice_sum(eddy_sph_kernel k, double spacing, double h) { return lattice(k, spacing, h, false); }

double eddy_sph_lattice_gradient_moment(eddy_sph_kernel k, double spacing, double h)
{
	return lattice(k, spacing, h, true);
}

/* The colour field's part of a free surface's jump (sph_surface_tension):
 * over the half-space z < 0 filled with the simple cubic lattice, layers at
 * z = -(k + 1/2) spacing, with the summation density rho_k = m sum W (m =
 * 1 / the full lattice's sum, rho0 = 1) and n_k = sum_j (m / rho_j) grad W
 * (poly6), sum_k (m / rho_k) / spacing^2 |n_k| over the layers with
 * |n_k| > threshold / h: the force a column of the surface's particles
 * carries per unit area over sigma kappa. A two-sided interface's colour
 * jump would give 1; the air side holds no particles. |n_k|, not its
 * component: where n_k points out of the water kappa n_k still points in
 * (surface_tension.c). 0 when no layer reaches the threshold. */
double eddy__sph_surface_share(double spacing, double h, double threshold)
{
	if (!(spacing > 0) || !(h > 0) || !(h / spacing <= 100))
		return NAN;
	/* layers 0 .. 2r + 1 can have a normal (a layer deeper than r has the
	 * whole lattice within h but its neighbours' densities vary up to 2r);
	 * their neighbours' densities reach layer 3r + 1, each over its own h */
	const int r = (int)ceil(h / spacing), normals = 2 * r + 2, layers = 3 * r + 2;
	const double m = 1.0 / lattice(EDDY_SPH_POLY6, spacing, h, false);
	double rho[3 * 100 + 2];
	for (int k = 0; k < layers; ++k) {
		double sum = 0;
		for (int l = k > r ? k - r : 0; l <= k + r; ++l)
			for (int i = -r; i <= r; ++i)
				for (int j = -r; j <= r; ++j) {
					const double dz = spacing * (l - k);
					sum += kernel(EDDY_SPH_POLY6, 0, sqrt(spacing * spacing * (i * i + j * j) + dz * dz), h);
				}
		rho[k] = m * sum;
	}
	double share = 0;
	for (int k = 0; k < normals; ++k) {
		double n = 0; /* along -z, into the water */
		for (int l = k > r ? k - r : 0; l <= k + r; ++l)
			for (int i = -r; i <= r; ++i)
				for (int j = -r; j <= r; ++j) {
					/* x_k - x_l along z is spacing (l - k); grad W = W'(d) (x_k - x_l) / d */
					const double dz = spacing * (l - k), d = sqrt(spacing * spacing * (i * i + j * j) + dz * dz);
					if (d > 0)
						n -= m / rho[l] * kernel(EDDY_SPH_POLY6, 1, d, h) * dz / d;
				}
		if (fabs(n) > threshold / h)
			share += m / rho[k] / (spacing * spacing) * fabs(n);
	}
	return share;
}
