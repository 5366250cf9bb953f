// OpenImageIO shim of the viewer client: writes received frames as PNG for the C code (see view_image.h).
// The same calls as scene/image_oiio.cpp's writer, so identical pixels give identical files; every exception
// is caught here and turned into -1 and a one-line message.
#include "view_image.h"

#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imageio.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

using OIIO::ImageOutput;
using OIIO::ImageSpec;
using OIIO::TypeDesc;

static void set_msg(char *msg, size_t cap, const std::string &text)
{
    if (msg && cap)
        std::snprintf(msg, cap, "%s", text.c_str());
}

// Writes bytes to path, checking every step (a full disk shows at fwrite, fflush or fclose); a file that
// could not be written whole is removed rather than left truncated. Returns false with the reason in msg.
static bool write_whole_file(const char *path, const std::vector<unsigned char> &bytes, char *msg, size_t cap)
{
    FILE *file = std::fopen(path, "wb");
    if (!file) {
        set_msg(msg, cap, std::string(path) + ": cannot write: " + std::strerror(errno));
        return false;
    }
    bool ok = std::fwrite(bytes.data(), 1, bytes.size(), file) == bytes.size() && std::fflush(file) == 0;
    int saved = errno;
    if (std::fclose(file) != 0 && ok) {
        ok = false;
        saved = errno;
    }
    if (!ok) {
        std::remove(path);
        set_msg(msg, cap, std::string(path) + ": cannot write: " + std::strerror(saved));
    }
    return ok;
}

extern "C" int view_image_write_png(const char *path, uint32_t width, uint32_t height, const uint8_t *rgb,
                                    char *msg, size_t msg_cap)
{
    try {
        if (width == 0 || height == 0) {
            set_msg(msg, msg_cap, std::string(path) + ": bad image size");
            return -1;
        }
        auto out = ImageOutput::create(path);
        if (!out) {
            set_msg(msg, msg_cap,
                    std::string(path) + ": no image writer for this file name: " + OIIO::geterror());
            return -1;
        }
        // Encoded in memory (scene/image_oiio.cpp says why), then written whole or not at all.
        std::vector<unsigned char> bytes;
        OIIO::Filesystem::IOVecOutput memory(bytes);
        bool in_memory = out->supports("ioproxy") && out->set_ioproxy(&memory);
        ImageSpec spec((int)width, (int)height, 3, TypeDesc::UINT8);
        if (!out->open(path, spec) || !out->write_image(TypeDesc::UINT8, rgb) || !out->close()) {
            set_msg(msg, msg_cap, std::string(path) + ": " + out->geterror());
            return -1;
        }
        if (in_memory && !write_whole_file(path, bytes, msg, msg_cap))
            return -1;
        return 0;
    } catch (const std::exception &e) {
        set_msg(msg, msg_cap, std::string(path) + ": " + e.what());
    } catch (...) {
        set_msg(msg, msg_cap, std::string(path) + ": unknown error writing image");
    }
    return -1;
}
