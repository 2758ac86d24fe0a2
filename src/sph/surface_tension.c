/* SPDX-License-Identifier: MIT */
/* sph_surface_tension: colour-field surface tension (Mueller 2003, sec. 3.3,
 * the continuum surface force of Morris 2000).
 *
 * Reads: x y z density. Writes: color_nx color_ny color_nz curvature ax ay az.
 *   n_i      = sum_j m / rho_j grad W_poly6(r_ij)   (gradient of the colour
 *              field c = 1 in the fluid; points into the fluid)
 *   kappa_i  = -div(n / |n|)_i = -sum_j m / rho_j (n^_j - n^_i) . grad W_poly6(r_ij)
 *              over the neighbours with a normal on i's side (n_j . n_i > 0),
 *              times sum_all V W / sum_those V W
 *   a_i     += (sigma / s) kappa_i n_i / rho_i   only where |n_i| > threshold / h:
 *   inside the fluid n is noise and dividing by |n| would amplify it (C.15).
 *   s = the colour field's share of a free surface's jump: CSF's force
 *   integrates sigma kappa |grad c| across an interface, and |grad c| to the
 *   jump of c, 1 where both sides hold particles (Morris' two fluids), but a
 *   free surface's air holds none: its particles see c fall from 1 to about
 *   1/2 at the outermost layer, and the force they carry per unit area is s
 *   sigma kappa, s = 0.645 at h = 2 spacings and threshold 0.5 (kernels.c,
 *   from the lattice, the threshold and the summation density). Without the
 *   division a drop at rest held 0.62-0.68 of Laplace's 2 sigma / R inside
 *   at 8 and 16 spacings per radius, and its l = 2 frequency stayed 9-16%
 *   under Rayleigh's at every resolution; with it both converge, at first
 *   order in the spacing (WCSPH's Laplace +15%, +8%, +1% at 8, 12, 16
 *   spacings per radius: tests/test_sph.c). s sums |n|: below the
 *   default threshold the colour field's second layer has a normal pointing
 *   out of the water (the outer layer's low summation density makes c
 *   overshoot 1 just inside), and there kappa, the divergence of that
 *   layer's own unit normals (hence the side test above: across the sheets
 *   the flip of n^ read as curvature on a flat surface, a drop at
 *   threshold 0.2 held +114% of Laplace), flips with n, so kappa n points in.
 * Why not the paper's kappa = -lap c / |n|: lap c of a particle colour field
 * is of order 1/h^2 across a flat surface too, with a sign change inside the
 * surface layer, so the paper's force squeezes the surface layer into clumps
 * and overestimates the curvature by about R/h (the drop test showed both);
 * the divergence of the unit normal is zero on a flat surface.
 * The columns exist only while this system is in the pipeline.
 * Time-step limit (capillary): dt <= 2.5 sqrt(rho0 dx^3 / (2 pi sigma / s)) with
 * dx = h/2; with the default CFL 0.4 that is the usual sqrt(rho dx^3/(2 pi sigma)).
 * Source: Mueller, Charypar & Gross 2003; Brackbill, Kothe & Zemach 1992;
 * Morris, "Simulating surface tension with SPH", IJNMF 2000. */
#include "sph.h"
#include "systems.h"

#include <stdlib.h>

static const int st_reads[] = {COL_X_, COL_Y_, COL_Z_, COL_DENSITY, -1};
static const int st_writes[] = {COL_SPH_NX, COL_SPH_NY, COL_SPH_NZ, COL_SPH_CURVATURE, COL_AX, COL_AY, COL_AZ, -1};
static const int st_hint_writes[] = {COL_SPH_NX, COL_SPH_NY, COL_SPH_NZ, COL_SPH_CURVATURE, -1};

eddy_sph_surface_tension_def eddy_default_sph_surface_tension_def(void)
{
	return (eddy_sph_surface_tension_def){.tension = 0.0728f /* water-air at 20 C */, .threshold = 0.5f};
}

typedef struct tension {
	eddy_sph_surface_tension_def def;
	double share; /* eddy__sph_surface_share for the SPH it follows; 0 until its first step */
} tension;

/* sigma / s (header), N/m; 0 when the threshold leaves a flat surface no
 * particle with a normal (s = 0: step reports it) */
static float effective_tension(tension *t, const sph_shared *sh)
{
	if (!(t->share > 0))
		t->share = eddy__sph_surface_share(sh->spacing, sh->h, t->def.threshold);
	return t->share > 0 ? (float)(t->def.tension / t->share) : 0.0f;
}

static eddy_status step(eddy_world *w, eddy_system *s, const eddy_step_context *ctx)
{
	tension *t = s->data;
	const eddy_sph_surface_tension_def *def = &t->def;
	const sph_shared *sh = eddy__sph_find(w, s); /* never NULL: the pipeline checks .requires */
	const sph_neighbors *nb = &sh->nb;
	const float *x = eddy__col(w, COL_X_), *y = eddy__col(w, COL_Y_), *z = eddy__col(w, COL_Z_);
	const float *pq = sh->pq; /* (x y z 1/rho) per row: 1/rho_j is pq[4 j + 3] */
	float *nx = eddy__col(w, COL_SPH_NX), *ny = eddy__col(w, COL_SPH_NY), *nz = eddy__col(w, COL_SPH_NZ);
	float *curv = eddy__col(w, COL_SPH_CURVATURE);
	float *ax = eddy__col(w, COL_AX), *ay = eddy__col(w, COL_AY), *az = eddy__col(w, COL_AZ);
	const sph_kernel_consts kc = sh->k;
	const float m = sh->mass, sigma = effective_tension(t, sh), thr = def->threshold / sh->h;
	if (!(t->share > 0))
		return eddy__fail(w, EDDY_ERR_INVALID,
		                  "sph_surface_tension: 'threshold' %g leaves the particles of a flat surface no normal (|n| "
		                  "h of its outermost layer is under it at h = %g spacings): lower it",
		                  (double)def->threshold, (double)(sh->h / sh->spacing));
	const long n = sph_rows(w, sh);
	/* pass 1: the colour-field gradient n */
#pragma omp parallel for num_threads(ctx->threads) schedule(static)
	for (long i = 0; i < n; ++i) {
		const float xi = x[i], yi = y[i], zi = z[i];
		sph_groups list = sph_nbr_groups(nb, i);
		const uint32_t cnt = nb->count[i];
		float gx = 0, gy = 0, gz = 0;
		uint32_t l[8];
		for (uint32_t q = 0; q < cnt; ++q) {
			if (q % 8 == 0)
				sph_group_rows(&list, l);
			const uint32_t j = l[q % 8];
			const float rx = xi - x[j], ry = yi - y[j], rz = zi - z[j];
			const float d = kc.h2 - (rx * rx + ry * ry + rz * rz);
			const float g = d * d * pq[4 * (size_t)j + 3];
			gx += g * rx;
			gy += g * ry;
			gz += g * rz;
		}
		const float c = m * kc.poly6_grad;
		nx[i] = c * gx;
		ny[i] = c * gy;
		nz[i] = c * gz;
	}
	/* pass 2: curvature -div(n/|n|) over the neighbours that have a normal,
	 * scaled up by the share of the kernel they fill (Morris 2000), and the
	 * force sigma kappa n / rho where |n| is above the threshold */
#pragma omp parallel for num_threads(ctx->threads) schedule(static)
	for (long i = 0; i < n; ++i) {
		const float li = sqrtf(nx[i] * nx[i] + ny[i] * ny[i] + nz[i] * nz[i]);
		if (!(li > thr))
			continue; /* interior: n is noise, and dividing by |n| would amplify it */
		const float ux = nx[i] / li, uy = ny[i] / li, uz = nz[i] / li;
		const float xi = x[i], yi = y[i], zi = z[i];
		sph_groups list = sph_nbr_groups(nb, i);
		const uint32_t cnt = nb->count[i];
		/* sum V W over all neighbours (i itself included), over those with a normal */
		float div = 0, w_all = kc.h2 * kc.h2 * kc.h2 * pq[4 * (size_t)i + 3], w_normal = w_all;
		uint32_t l[8];
		for (uint32_t q = 0; q < cnt; ++q) {
			if (q % 8 == 0)
				sph_group_rows(&list, l);
			const uint32_t j = l[q % 8];
			const float rx = xi - x[j], ry = yi - y[j], rz = zi - z[j];
			const float d = kc.h2 - (rx * rx + ry * ry + rz * rz);
			const float vw = d * d * d * pq[4 * (size_t)j + 3];
			w_all += vw;
			const float lj = sqrtf(nx[j] * nx[j] + ny[j] * ny[j] + nz[j] * nz[j]);
			/* a neighbour whose normal faces away from i's is another sheet
			 * of the colour field (below) or the far side of a thin film:
			 * its difference would read as curvature on a flat surface */
			if (!(lj > thr) || nx[j] * ux + ny[j] * uy + nz[j] * uz <= 0)
				continue;
			w_normal += vw;
			/* (n_j/|n_j| - n_i/|n_i|) . grad_i W, grad_i W = poly6_grad d^2 r_vec */
			const float dot = (nx[j] / lj - ux) * rx + (ny[j] / lj - uy) * ry + (nz[j] / lj - uz) * rz;
			div += dot * d * d * pq[4 * (size_t)j + 3];
		}
		const float kappa = -m * kc.poly6_grad * div * (w_all / w_normal);
		curv[i] = kappa;
		const float c = sigma * kappa * pq[4 * (size_t)i + 3];
		ax[i] += c * nx[i];
		ay[i] += c * ny[i];
		az[i] += c * nz[i];
	}
	return EDDY_OK;
}

static double limit(eddy_world *w, eddy_system *s, const char **reason)
{
	tension *t = s->data;
	const sph_shared *sh = eddy__sph_find(w, s);
	*reason = "capillary";
	if (!(t->def.tension > 0) || !(effective_tension(t, sh) > 0))
		return INFINITY;
	const double dx = 0.5 * sh->h;
	return 2.5 * sqrt(sh->rho0 * dx * dx * dx / (2 * M_PI * effective_tension(t, sh)));
}

const eddy_system_vtable eddy__kind_sph_surface_tension = {
	.name = "sph_surface_tension",
	.requires = EDDY_CAP_SPH_NEIGHBORS,
	.step = step,
	.limit = limit,
	/* ax ay az are every force's: order hints for them name gravity alone */
	.default_writes = st_hint_writes,
};

eddy_system_id eddy_add_sph_surface_tension(eddy_world *w, const eddy_sph_surface_tension_def *def)
{
	const char *sys = "sph_surface_tension";
	if (!eddy__add_args(w, def, sys) || !eddy__check_nonneg(w, sys, "tension", def->tension) ||
	    !eddy__check_nonneg(w, sys, "threshold", def->threshold))
		return EDDY_NULL_SYSTEM;
	tension *t = malloc(sizeof *t);
	if (t)
		*t = (tension){.def = *def, .share = 0};
	return eddy__add_system(w, &eddy__kind_sph_surface_tension, t, st_reads, st_writes);
}
