/* Writing a whole file, every step checked: the image shims (scene/image_oiio.cpp, the viewer's
 * view_image.cpp) encode in memory, then write through this, so a full disk or a vanished folder is an error
 * naming the file and never an empty or truncated file left behind. Links nothing but libc. */
#ifndef FXC_COMMON_FILE_H
#define FXC_COMMON_FILE_H

#include <stdbool.h>
#include <stddef.h>

#ifdef __cplusplus
extern "C" {
#endif

/* Writes len bytes to path (created or truncated). A full disk shows at fwrite, fflush or fclose; a file that
 * could not be written whole is removed (fxc_remove_partial). Returns false with "PATH: cannot write: REASON" in msg (cap bytes,
 * may be NULL). */
bool fxc_write_whole_file(const char *path, const void *bytes, size_t len, char *msg, size_t cap);

/* Removes what a failed write left at path: a regular file, or a link (whatever it points to stays). Anything
 * else is left alone: a device, a pipe or a socket the user named (`--summary /dev/full` run as root removed
 * the device node, and the next write made it a regular file). */
void fxc_remove_partial(const char *path);

#ifdef __cplusplus
}
#endif

#endif
