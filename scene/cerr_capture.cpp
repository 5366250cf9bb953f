/* std::cerr held in a string while Assimp imports: see cerr_capture.h. Nothing here throws past the C
 * interface (allocation uses nothrow new; the stream writes cannot throw with exceptions off). */
#include "cerr_capture.h"

#include <iostream>
#include <new>
#include <sstream>
#include <string>

struct scene_cerr_capture {
    std::ostringstream held;
    std::streambuf *previous = nullptr;
};

extern "C" scene_cerr_capture *scene_cerr_capture_begin(void)
{
    scene_cerr_capture *c = new (std::nothrow) scene_cerr_capture;
    if (c)
        c->previous = std::cerr.rdbuf(c->held.rdbuf());
    return c;
}

extern "C" void scene_cerr_capture_end(scene_cerr_capture *c, char *text, size_t cap)
{
    if (cap > 0)
        text[0] = 0;
    if (!c)
        return;
    std::cerr.rdbuf(c->previous);
    std::string written;
    try {
        written = c->held.str();
    } catch (...) {
        written.clear();
    }
    size_t n = 0;
    bool line_end = false;
    for (char ch : written) {
        if (n + 3 >= cap)
            break;
        if (ch == '\n' || ch == '\r') {
            line_end = n > 0;
            continue;
        }
        if (line_end) {
            text[n++] = ';';
            text[n++] = ' ';
            line_end = false;
        }
        text[n++] = ch >= 32 && ch < 127 ? ch : '?';
    }
    if (cap > 0)
        text[n] = 0;
    delete c;
}
