/* SPDX-License-Identifier: MIT */
/* Shape descriptions of the built-in colliders, for eddy_collider_shape_of()
 * (collider_shape.c): each collider file describes its own private data. */
#ifndef EDDY_COLLIDER_SHAPE_H
#define EDDY_COLLIDER_SHAPE_H

#include "core.h"

void eddy__shape_collide_box(const eddy_system *s, eddy_collider_shape *out);
void eddy__shape_collide_sphere(const eddy_system *s, eddy_collider_shape *out);
void eddy__shape_collide_plane(const eddy_system *s, eddy_collider_shape *out);
void eddy__shape_collide_mesh(const eddy_system *s, eddy_collider_shape *out);

#endif
