/* PNG writing: the one file that holds stb_image_write's implementation
 * (Debian's libstb-dev header). STATIC keeps its symbols private to this file;
 * its tuning globals are never written, so they stay at their defaults. */
#define STB_IMAGE_WRITE_IMPLEMENTATION
#define STB_IMAGE_WRITE_STATIC
#include <stb/stb_image_write.h>

#include "render.h"

int eddy_write_png(const char *path, int width, int height, const uint8_t *rgb)
{
	return stbi_write_png(path, width, height, 3, rgb, width * 3) ? 0 : -1;
}
