/* Image files through OpenImageIO, behind a C interface (the shim is scene/image_oiio.cpp, the only C++
 * that reads or writes images). Every exception stays inside the shim; failures come back as -1 with one
 * line naming the file. */
#ifndef FXC_SCENE_IMAGE_H
#define FXC_SCENE_IMAGE_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/* Reads any image OpenImageIO reads as linear RGB floats (8- and 16-bit files are taken as sRGB and
 * decoded; float files as linear; grey is replicated; alpha dropped). On success *rgb is malloc'd
 * (width*height*3, top row first) and owned by the caller. Returns 0, or -1 with msg filled. A file the
 * reader returns despite an error (a truncated JPEG: libjpeg fills the missing part with grey) returns 0 with
 * msg a one-line warning naming the file; msg is "" after a clean read. */
int scene_image_read_rgb(const char *path, uint32_t *width, uint32_t *height, float **rgb, char *msg,
                         size_t msg_cap);

/* The same from len encoded bytes in memory (an image embedded in a GLB or FBX file): name says where they
 * came from in messages, and its extension (".png", ".jpg", ...) picks the reader. */
int scene_image_read_rgb_memory(const char *name, const void *data, size_t len, uint32_t *width,
                                uint32_t *height, float **rgb, char *msg, size_t msg_cap);

/* Writes 8-bit pixels (channels 1..4, top row first) to path; the format follows the extension (PNG,
 * JPEG, ...). Returns 0, or -1 with msg filled. */
int scene_image_write_u8(const char *path, uint32_t width, uint32_t height, uint32_t channels,
                         const uint8_t *pixels, char *msg, size_t msg_cap);

/* Writes float pixels (linear, e.g. to OpenEXR). Returns 0, or -1 with msg filled. */
int scene_image_write_f32(const char *path, uint32_t width, uint32_t height, uint32_t channels,
                          const float *pixels, char *msg, size_t msg_cap);

#ifdef __cplusplus
}
#endif
#endif
