/* SPDX-License-Identifier: MIT */
/* The component table: every column the engine knows, declared once.
 * X(ident, name, domain, type, lifetime, unit)
 *
 * A column is allocated only while some system in the pipeline reads or writes
 * it. Derived columns are cleared at the start of every step, so force systems
 * accumulate into them and nothing reads a stale value from the last step.
 * Custom columns are appended at run time with eddy_world_declare_column(). */
#ifndef EDDY_COMPONENTS_H
#define EDDY_COMPONENTS_H

#define EDDY_COMPONENTS(X)                                                             \
	/* particle state */                                                               \
	X(X_, "x", EDDY_DOMAIN_PARTICLE, EDDY_F32, EDDY_STATE, "m")                        \
	X(Y_, "y", EDDY_DOMAIN_PARTICLE, EDDY_F32, EDDY_STATE, "m")                        \
	X(Z_, "z", EDDY_DOMAIN_PARTICLE, EDDY_F32, EDDY_STATE, "m")                        \
	X(VX, "vx", EDDY_DOMAIN_PARTICLE, EDDY_F32, EDDY_STATE, "m/s")                     \
	X(VY, "vy", EDDY_DOMAIN_PARTICLE, EDDY_F32, EDDY_STATE, "m/s")                     \
	X(VZ, "vz", EDDY_DOMAIN_PARTICLE, EDDY_F32, EDDY_STATE, "m/s")                     \
	/* particle, recomputed each step */                                               \
	X(AX, "ax", EDDY_DOMAIN_PARTICLE, EDDY_F32, EDDY_DERIVED, "m/s^2")                 \
	X(AY, "ay", EDDY_DOMAIN_PARTICLE, EDDY_F32, EDDY_DERIVED, "m/s^2")                 \
	X(AZ, "az", EDDY_DOMAIN_PARTICLE, EDDY_F32, EDDY_DERIVED, "m/s^2")                 \
	X(DENSITY, "density", EDDY_DOMAIN_PARTICLE, EDDY_F32, EDDY_DERIVED, "kg/m^3")      \
	X(PRESSURE, "pressure", EDDY_DOMAIN_PARTICLE, EDDY_F32, EDDY_DERIVED, "Pa")        \
	/* SPH columns */                                                                  \
	X(SPH_NEIGHBORS, "neighbors", EDDY_DOMAIN_PARTICLE, EDDY_F32, EDDY_DERIVED, "")    \
	X(SPH_NX, "color_nx", EDDY_DOMAIN_PARTICLE, EDDY_F32, EDDY_DERIVED, "1/m")         \
	X(SPH_NY, "color_ny", EDDY_DOMAIN_PARTICLE, EDDY_F32, EDDY_DERIVED, "1/m")         \
	X(SPH_NZ, "color_nz", EDDY_DOMAIN_PARTICLE, EDDY_F32, EDDY_DERIVED, "1/m")         \
	X(SPH_CURVATURE, "curvature", EDDY_DOMAIN_PARTICLE, EDDY_F32, EDDY_DERIVED, "1/m") \
                                                                                       \
	/* FLIP particle columns: APIC's affine velocity, one vector c_a per face          \
	 * grid a (x-faces carry u: apic_ux apic_uy apic_uz = grad u at the                \
	 * particle, and so on); allocated only by flip_g2p { transfer = "apic" } */       \
	X(APIC_UX, "apic_ux", EDDY_DOMAIN_PARTICLE, EDDY_F32, EDDY_STATE, "1/s")           \
	X(APIC_UY, "apic_uy", EDDY_DOMAIN_PARTICLE, EDDY_F32, EDDY_STATE, "1/s")           \
	X(APIC_UZ, "apic_uz", EDDY_DOMAIN_PARTICLE, EDDY_F32, EDDY_STATE, "1/s")           \
	X(APIC_VX, "apic_vx", EDDY_DOMAIN_PARTICLE, EDDY_F32, EDDY_STATE, "1/s")           \
	X(APIC_VY, "apic_vy", EDDY_DOMAIN_PARTICLE, EDDY_F32, EDDY_STATE, "1/s")           \
	X(APIC_VZ, "apic_vz", EDDY_DOMAIN_PARTICLE, EDDY_F32, EDDY_STATE, "1/s")           \
	X(APIC_WX, "apic_wx", EDDY_DOMAIN_PARTICLE, EDDY_F32, EDDY_STATE, "1/s")           \
	X(APIC_WY, "apic_wy", EDDY_DOMAIN_PARTICLE, EDDY_F32, EDDY_STATE, "1/s")           \
	X(APIC_WZ, "apic_wz", EDDY_DOMAIN_PARTICLE, EDDY_F32, EDDY_STATE, "1/s")           \
                                                                                       \
	/* MAC grid */                                                                     \
	X(CELL_TYPE, "cell_type", EDDY_DOMAIN_CELL, EDDY_U8, EDDY_DERIVED, "")             \
	X(CELL_PRESSURE, "cell_pressure", EDDY_DOMAIN_CELL, EDDY_F32, EDDY_DERIVED, "Pa")  \
	X(FACE_U, "u", EDDY_DOMAIN_FACE_X, EDDY_F32, EDDY_DERIVED, "m/s")                  \
	X(FACE_V, "v", EDDY_DOMAIN_FACE_Y, EDDY_F32, EDDY_DERIVED, "m/s")                  \
	X(FACE_W, "w", EDDY_DOMAIN_FACE_Z, EDDY_F32, EDDY_DERIVED, "m/s")                  \
	/* FLIP grid columns */                                                            \
	X(U_OLD, "u_old", EDDY_DOMAIN_FACE_X, EDDY_F32, EDDY_DERIVED, "m/s")               \
	X(V_OLD, "v_old", EDDY_DOMAIN_FACE_Y, EDDY_F32, EDDY_DERIVED, "m/s")               \
	X(W_OLD, "w_old", EDDY_DOMAIN_FACE_Z, EDDY_F32, EDDY_DERIVED, "m/s")               \
	X(FLIP_PHI, "flip_phi", EDDY_DOMAIN_CELL, EDDY_F32, EDDY_DERIVED, "")              \
                                                                                       \
	/* renderer columns */

enum eddy_builtin_column {
#define EDDY_COL_ENUM(ident, name, domain, type, lifetime, unit) COL_##ident,
	EDDY_COMPONENTS(EDDY_COL_ENUM)
#undef EDDY_COL_ENUM
		COL_BUILTIN_COUNT
};

#endif
