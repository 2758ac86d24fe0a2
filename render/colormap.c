/* SPDX-License-Identifier: MIT */
/* Colour maps: piecewise-linear in sRGB between 11 evenly spaced samples.
 * viridis and plasma are the matplotlib maps by van der Walt and Smith (2015),
 * sampled at t = 0, 0.1, ..., 1 from their published values; 11 samples keep
 * the interpolation error below what 8-bit output shows on a smooth field. */
#include "render.h"

#include <math.h>

static const uint8_t viridis[11][3] = {
	{68, 1, 84},    {72, 36, 117},  {65, 68, 135},  {53, 95, 141},  {42, 120, 142}, {33, 145, 140},
	{34, 168, 132}, {68, 191, 112}, {122, 209, 81}, {189, 223, 38}, {253, 231, 37},
};

static const uint8_t plasma[11][3] = {
	{13, 8, 135},   {65, 4, 157},   {106, 0, 168},  {143, 13, 164}, {177, 42, 144}, {204, 71, 120},
	{225, 100, 98}, {242, 132, 75}, {252, 166, 54}, {252, 206, 37}, {240, 249, 33},
};

void eddy_colormap_rgb(eddy_colormap map, float t, uint8_t rgb[3])
{
	if (!(t > 0.0f))
		t = 0.0f; /* NaN too */
	if (t > 1.0f)
		t = 1.0f;
	if (map == EDDY_COLORMAP_GRAY) {
		uint8_t v = (uint8_t)lrintf(t * 255.0f);
		rgb[0] = rgb[1] = rgb[2] = v;
		return;
	}
	const uint8_t(*tab)[3] = map == EDDY_COLORMAP_PLASMA ? plasma : viridis;
	float f = t * 10.0f;
	int i = (int)f;
	if (i > 9)
		i = 9;
	float u = f - (float)i;
	for (int c = 0; c < 3; ++c)
		rgb[c] = (uint8_t)lrintf((float)tab[i][c] + u * (float)(tab[i + 1][c] - tab[i][c]));
}
