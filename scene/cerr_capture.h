/* What C++ libraries write to std::cerr while fxcache calls them, held instead of printed (the shim is
 * scene/cerr_capture.cpp). Assimp's bundled OpenDDL parser (OpenGEX) writes its complaints straight to
 * std::cerr, which put a second line beside fxcache's one-line error; the import runs between begin and end
 * and what was written becomes part of that line. Only std::cerr is redirected, not the file descriptor, so
 * a crash report or a sanitizer report still reaches the terminal. */
#ifndef FXC_SCENE_CERR_CAPTURE_H
#define FXC_SCENE_CERR_CAPTURE_H

#include <stddef.h>

#ifdef __cplusplus
extern "C" {
#endif

typedef struct scene_cerr_capture scene_cerr_capture;

/* Starts holding what is written to std::cerr. Returns NULL (and holds nothing) when out of memory. */
scene_cerr_capture *scene_cerr_capture_begin(void);

/* Puts std::cerr back and frees c; text gets what was written as one line (line ends become "; ",
 * non-printable bytes '?', at most cap - 1 bytes), "" when nothing was. c may be NULL. */
void scene_cerr_capture_end(scene_cerr_capture *c, char *text, size_t cap);

#ifdef __cplusplus
}
#endif
#endif
