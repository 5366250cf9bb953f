/* PNG files for the viewer client through OpenImageIO, behind a C interface (the shim is view_image.cpp, the
 * client's only C++). It writes the way scene/image_oiio.cpp does (one ImageOutput, an 8-bit RGB ImageSpec,
 * OpenImageIO's default PNG settings), so the same pixels give the same file from the server and from the
 * client. Every exception stays inside the shim. */
#ifndef FXC_VIEW_IMAGE_H
#define FXC_VIEW_IMAGE_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/* Writes width*height*3 bytes of sRGB (top row first) to path as an 8-bit RGB PNG (the format follows the
 * file name's extension, as scene_image_write_u8 does). Returns 0, or -1 with one line naming the file in msg
 * (msg_cap bytes, may be NULL). */
int view_image_write_png(const char *path, uint32_t width, uint32_t height, const uint8_t *rgb, char *msg,
                         size_t msg_cap);

#ifdef __cplusplus
}
#endif
#endif
