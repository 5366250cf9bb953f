// OpenImageIO shim of the viewer client: writes received frames as PNG for the C code (see view_image.h).
// The same calls as scene/image_oiio.cpp's writer, so identical pixels give identical files; every exception
// is caught here and turned into -1 and a one-line message.
#include "view_image.h"
#include "fxc_file.h"

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
        if (in_memory && !fxc_write_whole_file(path, bytes.data(), bytes.size(), msg, msg_cap))
            return -1;
        return 0;
    } catch (const std::exception &e) {
        set_msg(msg, msg_cap, std::string(path) + ": " + e.what());
    } catch (...) {
        set_msg(msg, msg_cap, std::string(path) + ": unknown error writing image");
    }
    return -1;
}
