// OpenImageIO shim: reads textures and writes frames for the C code (see image.h). The only C++ that
// touches images; every exception is caught here and turned into -1 and a one-line message.
#include "image.h"
#include "fxc_file.h"

#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imageio.h>

#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include <unistd.h>

using OIIO::ImageInput;
using OIIO::ImageOutput;
using OIIO::ImageSpec;
using OIIO::TypeDesc;

// Text on one line: each run of line ends becomes "; " (OpenImageIO's errors may hold several lines: a
// truncated PNG gave "Read error: hit end of file\nPNG read error: ...\nPNG library error"), trailing ones go.
static std::string one_line(const std::string &text)
{
    std::string out;
    bool line_end = false;
    for (char c : text) {
        if (c == '\n' || c == '\r') {
            line_end = true;
            continue;
        }
        if (line_end && !out.empty())
            out += "; ";
        line_end = false;
        out += c;
    }
    return out;
}

static void set_msg(char *msg, size_t cap, const std::string &text)
{
    if (msg && cap)
        std::snprintf(msg, cap, "%s", one_line(text).c_str());
}

// What is written to file descriptor 2 while an image is read, held in a temporary file instead of printed.
// libpng's default error handler (OpenImageIO 2.4's PNG reader installs none) writes "libpng error: ..." with
// C's stderr, a second line beside fxcache's one-line message, which cerr_capture (std::cerr only) cannot
// hold. Reads are serialised by a mutex, as the descriptor is the process's; another thread writing to
// stderr meanwhile would be held too, and a crash inside the read loses its report to the file (the price
// of one line; reads are short).
class stderr_hold
{
  public:
    stderr_hold()
    {
        std::fflush(stderr);
        file_ = std::tmpfile();
        if (!file_)
            return;
        saved_ = dup(2);
        if (saved_ < 0 || dup2(fileno(file_), 2) < 0) {
            if (saved_ >= 0)
                close(saved_);
            saved_ = -1;
            std::fclose(file_);
            file_ = nullptr;
        }
    }
    // Puts descriptor 2 back; returns what was written (at most 1 KiB), on one line.
    std::string release()
    {
        if (!file_)
            return "";
        std::fflush(stderr);
        dup2(saved_, 2);
        close(saved_);
        char text[1024];
        std::rewind(file_);
        size_t n = std::fread(text, 1, sizeof text - 1, file_);
        std::fclose(file_);
        file_ = nullptr;
        return one_line(std::string(text, n));
    }
    ~stderr_hold()
    {
        release();
    }
    stderr_hold(const stderr_hold &) = delete;
    stderr_hold &operator=(const stderr_hold &) = delete;

  private:
    FILE *file_ = nullptr;
    int saved_ = -1;
};

static std::mutex stderr_hold_mutex;

// The sRGB transfer function, decoded to linear.
static float srgb_to_linear(float c)
{
    return c <= 0.04045f ? c / 12.92f : std::pow((c + 0.055f) / 1.055f, 2.4f);
}

// Reads the image file at path or, when data is not null, the len encoded bytes at data (path then only
// names it and its extension picks the reader).
static int read_rgb(const char *path, const void *data, size_t len, uint32_t *width, uint32_t *height,
                    float **rgb, char *msg, size_t msg_cap)
{
    try {
        OIIO::Filesystem::IOMemReader bytes(data, len);
        auto in = data ? ImageInput::open(path, nullptr, &bytes) : ImageInput::open(path);
        if (!in) {
            std::string e = OIIO::geterror();
            set_msg(msg, msg_cap, std::string(path) + ": cannot read image" + (e.empty() ? "" : ": " + e));
            return -1;
        }
        const ImageSpec &spec = in->spec();
        if (spec.width <= 0 || spec.height <= 0 || spec.nchannels <= 0 || spec.width > 65536 ||
            spec.height > 65536) {
            set_msg(msg, msg_cap, std::string(path) + ": image size out of range (1..65536 per side)");
            return -1;
        }
        size_t w = (size_t)spec.width, h = (size_t)spec.height, nc = (size_t)spec.nchannels;
        // A header may declare up to 65536 x 65536 pixels of any number of channels (an 8 KB PNG of one row
        // declared 60000 x 60000: 40 GiB as floats): beyond the machine's memory it is refused with the
        // figures before anything is allocated (a sanitizer build aborts on such an allocation).
        double need = (double)w * (double)h * (double)nc * sizeof(float);
        double memory = (double)sysconf(_SC_PHYS_PAGES) * (double)sysconf(_SC_PAGESIZE);
        char figures[160];
        std::snprintf(figures, sizeof figures, "%zu x %zu pixels of %zu channels need %.3g GiB as floats", w,
                      h, nc, need / (1u << 30));
        if (memory > 0 && need > memory) {
            char more[96];
            std::snprintf(more, sizeof more, ", more than this machine's %.3g GiB of memory",
                          memory / (1u << 30));
            set_msg(msg, msg_cap, std::string(path) + ": " + figures + more);
            return -1;
        }
        std::vector<float> pixels;
        try {
            pixels.resize(w * h * nc);
        } catch (const std::bad_alloc &) {
            set_msg(msg, msg_cap, std::string(path) + ": out of memory: " + figures);
            return -1;
        }
        if (!in->read_image(0, 0, 0, (int)nc, TypeDesc::FLOAT, pixels.data())) {
            set_msg(msg, msg_cap, std::string(path) + ": " + in->geterror());
            return -1;
        }
        // A read that succeeds may still have met an error: OpenImageIO's JPEG reader returns a truncated
        // file's image whole, libjpeg having filled what is missing with grey, and leaves only
        // "Premature end of JPEG file" in geterror(). That becomes the caller's warning (rc 0, msg set).
        std::string late = in->geterror();
        if (!late.empty())
            set_msg(msg, msg_cap,
                    std::string(path) + ": damaged or truncated image (" + late +
                        "); the reader's fill stands for what it could not read");
        bool encoded = spec.format.basetype == TypeDesc::UINT8 || spec.format.basetype == TypeDesc::UINT16;
        float *out = static_cast<float *>(std::malloc(w * h * 3 * sizeof(float)));
        if (!out) {
            set_msg(msg, msg_cap, std::string(path) + ": out of memory");
            return -1;
        }
        for (size_t i = 0; i < w * h; i++)
            for (size_t k = 0; k < 3; k++) {
                float c = pixels[i * nc + (nc >= 3 ? k : 0)];
                if (!std::isfinite(c))
                    c = 0.0f;
                out[i * 3 + k] = encoded ? srgb_to_linear(c) : c;
            }
        *width = (uint32_t)w;
        *height = (uint32_t)h;
        *rgb = out;
        return 0;
    } catch (const std::exception &e) {
        set_msg(msg, msg_cap, std::string(path) + ": " + e.what());
    } catch (...) {
        set_msg(msg, msg_cap, std::string(path) + ": unknown error reading image");
    }
    return -1;
}

// scene_image_read_rgb and scene_image_read_rgb_memory: the read with stderr held.
static int read_rgb_held(const char *path, const void *data, size_t len, uint32_t *width, uint32_t *height,
                         float **rgb, char *msg, size_t msg_cap)
{
    *rgb = nullptr;
    if (msg && msg_cap)
        msg[0] = 0;
    std::string held;
    int rc;
    try {
        std::lock_guard<std::mutex> lock(stderr_hold_mutex);
        stderr_hold hold;
        rc = read_rgb(path, data, len, width, height, rgb, msg, msg_cap);
        held = hold.release();
    } catch (...) {
        set_msg(msg, msg_cap, std::string(path) + ": cannot read image: out of memory");
        return -1;
    }
    // What the library printed joins a failure's message unless it says what the message says already
    // ("libpng error: X" beside OpenImageIO's "PNG read error: X"); after a success it is dropped (libpng's
    // warnings, such as an sRGB profile it calls incorrect).
    const std::string prefix = "libpng error: ";
    std::string said = held.compare(0, prefix.size(), prefix) == 0 ? held.substr(prefix.size()) : held;
    if (rc != 0 && !said.empty() && msg && msg_cap && !std::strstr(msg, said.c_str()))
        set_msg(msg, msg_cap, std::string(msg) + " (" + held + ")");
    return rc;
}

extern "C" int scene_image_read_rgb(const char *path, uint32_t *width, uint32_t *height, float **rgb,
                                    char *msg, size_t msg_cap)
{
    return read_rgb_held(path, nullptr, 0, width, height, rgb, msg, msg_cap);
}

extern "C" int scene_image_read_rgb_memory(const char *name, const void *data, size_t len, uint32_t *width,
                                           uint32_t *height, float **rgb, char *msg, size_t msg_cap)
{
    if (!data || len == 0) {
        set_msg(msg, msg_cap, std::string(name) + ": cannot read image: no bytes");
        *rgb = nullptr;
        return -1;
    }
    return read_rgb_held(name, data, len, width, height, rgb, msg, msg_cap);
}

// Writes one image in the given pixel type; shared by the two public writers.
static int write_image(const char *path, uint32_t width, uint32_t height, uint32_t channels, TypeDesc type,
                       const void *pixels, char *msg, size_t msg_cap)
{
    try {
        if (channels < 1 || channels > 4 || width == 0 || height == 0) {
            set_msg(msg, msg_cap, std::string(path) + ": bad image size or channel count");
            return -1;
        }
        auto out = ImageOutput::create(path);
        if (!out) {
            set_msg(msg, msg_cap,
                    std::string(path) + ": no image writer for this file name: " + OIIO::geterror());
            return -1;
        }
        // Encoded in memory where the writer can (PNG): OpenImageIO 2.4's PNG writer does not check its
        // writes, so on a full disk it left empty or truncated files and reported success.
        std::vector<unsigned char> bytes;
        OIIO::Filesystem::IOVecOutput memory(bytes);
        bool in_memory = out->supports("ioproxy") && out->set_ioproxy(&memory);
        ImageSpec spec((int)width, (int)height, (int)channels, type);
        if (!out->open(path, spec) || !out->write_image(type, pixels) || !out->close()) {
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

extern "C" int scene_image_write_u8(const char *path, uint32_t width, uint32_t height, uint32_t channels,
                                    const uint8_t *pixels, char *msg, size_t msg_cap)
{
    return write_image(path, width, height, channels, TypeDesc::UINT8, pixels, msg, msg_cap);
}

extern "C" int scene_image_write_f32(const char *path, uint32_t width, uint32_t height, uint32_t channels,
                                     const float *pixels, char *msg, size_t msg_cap)
{
    return write_image(path, width, height, channels, TypeDesc::FLOAT, pixels, msg, msg_cap);
}
