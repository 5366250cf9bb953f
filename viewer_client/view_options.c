/* fxcache-viewer's command line (view_options.h): a table of options, one parser per kind of value, the
 * checks between options, and the --help text. Every refusal is one line naming the option and the value. */
#include "view_options.h"

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stddef.h>
#include <stdlib.h>
#include <string.h>

/* ---- values -------------------------------------------------------------------------------------------- */

/* A whole number in [lo, hi]: digits only (no sign, no spaces, no exponent). */
static bool parse_whole(const char *text, uint64_t lo, uint64_t hi, uint64_t *out)
{
    if (!text[0] || strlen(text) > 19)
        return false;
    uint64_t value = 0;
    for (const char *c = text; *c; c++) {
        if (*c < '0' || *c > '9')
            return false;
        value = value * 10 + (uint64_t)(*c - '0');
    }
    if (value < lo || value > hi)
        return false;
    *out = value;
    return true;
}

/* A finite decimal number, all of the text (strtod in the C locale; no hex, no NaN or infinity). */
static bool parse_decimal(const char *text, double *out)
{
    if (!text[0])
        return false;
    for (const char *c = text; *c; c++)
        if (!((*c >= '0' && *c <= '9') || *c == '.' || *c == '-' || *c == '+' || *c == 'e' || *c == 'E'))
            return false;
    char *end = NULL;
    errno = 0;
    double value = strtod(text, &end);
    if (*end != 0 || !isfinite(value))
        return false;
    *out = value;
    return true;
}

/* Printable ASCII (what the wire format allows in names and tokens), at most max bytes. */
static bool printable(const char *text, size_t max)
{
    size_t n = strlen(text);
    if (n > max)
        return false;
    for (size_t i = 0; i < n; i++)
        if ((unsigned char)text[i] < 0x20 || (unsigned char)text[i] > 0x7e)
            return false;
    return true;
}

bool view_options_parse_url(const char *url, view_options *o, char *err, size_t cap)
{
    static const char scheme[] = "ws://";
    if (strncmp(url, scheme, sizeof scheme - 1) != 0) {
        const char *colon = strstr(url, "://");
        if (colon)
            snprintf(err, cap,
                     "--connect %s: the scheme must be ws:// (got %.*s://; wss:// is not supported)", url,
                     (int)(colon - url < 16 ? colon - url : 16), url);
        else
            snprintf(err, cap, "--connect %s: expected ws://HOST:PORT", url);
        return false;
    }
    const char *host = url + sizeof scheme - 1, *host_end, *after;
    if (host[0] == '[') { /* an IPv6 address */
        host_end = strchr(host, ']');
        if (!host_end) {
            snprintf(err, cap, "--connect %s: an IPv6 address needs its closing ']'", url);
            return false;
        }
        host++;
        after = host_end + 1;
    } else {
        host_end = host + strcspn(host, ":/");
        after = host_end;
    }
    size_t host_len = (size_t)(host_end - host);
    if (host_len == 0 || host_len >= sizeof o->host) {
        snprintf(err, cap, "--connect %s: %s", url, host_len ? "the host name is too long" : "no host");
        return false;
    }
    for (size_t i = 0; i < host_len; i++) {
        char c = host[i];
        bool ok = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '.' ||
                  c == '-' || c == '_' || (c == ':' && host[-1] == '[');
        if (!ok) {
            snprintf(err, cap, "--connect %s: the host has a character that cannot be in a host name", url);
            return false;
        }
    }
    if (*after != ':') {
        snprintf(err, cap, "--connect %s: no port (expected ws://HOST:PORT)", url);
        return false;
    }
    const char *port = after + 1;
    size_t port_len = strcspn(port, "/");
    char port_text[8];
    uint64_t port_value = 0;
    if (port_len == 0 || port_len >= sizeof port_text) {
        snprintf(err, cap, "--connect %s: the port must be a whole number in 1..65535", url);
        return false;
    }
    memcpy(port_text, port, port_len);
    port_text[port_len] = 0;
    if (!parse_whole(port_text, 1, 65535, &port_value)) {
        snprintf(err, cap, "--connect %s: the port must be a whole number in 1..65535", url);
        return false;
    }
    const char *path = port + port_len;
    if (!*path)
        path = "/";
    if (strlen(path) >= sizeof o->path || !printable(path, sizeof o->path - 1) || strchr(path, ' ')) {
        snprintf(err, cap, "--connect %s: the path must be printable, without spaces, under %zu bytes", url,
                 sizeof o->path);
        return false;
    }
    memcpy(o->host, host, host_len);
    o->host[host_len] = 0;
    o->port = (uint16_t)port_value;
    snprintf(o->path, sizeof o->path, "%s", path);
    snprintf(o->url, sizeof o->url, "%s", url);
    return true;
}

/* ---- the options --------------------------------------------------------------------------------------- */

/* What each option does with its value (NULL for flags). Returns false with the message in err. */
typedef bool (*option_fn)(view_options *o, const char *name, const char *value, char *err, size_t cap);

#define REFUSE(...)                                                                                          \
    do {                                                                                                     \
        snprintf(err, cap, __VA_ARGS__);                                                                     \
        return false;                                                                                        \
    } while (0)

static bool option_connect(view_options *o, const char *name, const char *value, char *err, size_t cap)
{
    (void)name;
    if (strlen(value) >= sizeof o->url)
        REFUSE("--connect %.40s...: too long", value);
    return view_options_parse_url(value, o, err, cap);
}

static bool option_viewers(view_options *o, const char *name, const char *value, char *err, size_t cap)
{
    uint64_t v;
    if (!parse_whole(value, 1, VIEW_MAX_VIEWERS, &v))
        REFUSE("%s %s: must be a whole number in 1..%d", name, value, VIEW_MAX_VIEWERS);
    o->viewers = (uint32_t)v;
    return true;
}

static bool option_frames(view_options *o, const char *name, const char *value, char *err, size_t cap)
{
    uint64_t v;
    if (!parse_whole(value, 0, 1000000000u, &v))
        REFUSE("%s %s: must be a whole number in 0..1000000000 (0: no limit)", name, value);
    o->frames = (uint32_t)v;
    return true;
}

static bool option_trace(view_options *o, const char *name, const char *value, char *err, size_t cap)
{
    if (o->trace_count == VIEW_MAX_VIEWERS)
        REFUSE("%s %s: at most %d traces (one per viewer)", name, value, VIEW_MAX_VIEWERS);
    if (!value[0])
        REFUSE("%s '': needs a file name", name);
    o->traces[o->trace_count++] = value;
    return true;
}

static bool option_camera(view_options *o, const char *name, const char *value, char *err, size_t cap)
{
    if (!view_camera_kind_parse(value, &o->camera))
        REFUSE("%s %s: must be orbit or static", name, value);
    o->camera_given = true;
    return true;
}

static bool option_fps(view_options *o, const char *name, const char *value, char *err, size_t cap)
{
    double v;
    if (!parse_decimal(value, &v) || !(v > 0 && v <= 1000))
        REFUSE("%s %s: must be a number above 0, at most 1000", name, value);
    o->fps = v;
    return true;
}

static bool option_res(view_options *o, const char *name, const char *value, char *err, size_t cap)
{
    const char *x = strchr(value, 'x');
    char side[2][16];
    uint64_t v[2];
    if (!x || (size_t)(x - value) >= sizeof side[0] || strlen(x + 1) >= sizeof side[1])
        REFUSE("%s %s: expected WIDTHxHEIGHT, each 1..%d (as 640x360)", name, value, PROTO_MAX_SIDE);
    memcpy(side[0], value, (size_t)(x - value));
    side[0][x - value] = 0;
    snprintf(side[1], sizeof side[1], "%s", x + 1);
    for (int i = 0; i < 2; i++)
        if (!parse_whole(side[i], 1, PROTO_MAX_SIDE, &v[i]))
            REFUSE("%s %s: expected WIDTHxHEIGHT, each 1..%d (as 640x360)", name, value, PROTO_MAX_SIDE);
    o->width = (uint32_t)v[0];
    o->height = (uint32_t)v[1];
    o->res_given = true;
    return true;
}

static bool option_fov(view_options *o, const char *name, const char *value, char *err, size_t cap)
{
    double v;
    if (!parse_decimal(value, &v) || !(v > 0 && v < 180) || !((float)v > 0 && (float)v < 180))
        REFUSE("%s %s: must be a number of degrees strictly between 0 and 180", name, value);
    o->fov_deg = (float)v;
    return true;
}

static bool option_codec(view_options *o, const char *name, const char *value, char *err, size_t cap)
{
    proto_codec codec;
    if (!proto_codec_parse(value, &codec))
        REFUSE("%s %s: must be raw, zstd or jpeg", name, value);
    o->codec = (uint8_t)codec;
    return true;
}

static bool option_quality(view_options *o, const char *name, const char *value, char *err, size_t cap)
{
    uint64_t v;
    if (!parse_whole(value, 1, 100, &v))
        REFUSE("%s %s: must be a whole number in 1..100", name, value);
    o->quality = (uint8_t)v;
    o->quality_given = true;
    return true;
}

static bool option_depth(view_options *o, const char *name, const char *value, char *err, size_t cap)
{
    if (strcmp(value, "none") == 0)
        o->depth = PROTO_DEPTH_NONE;
    else if (strcmp(value, "16") == 0)
        o->depth = PROTO_DEPTH_HALF;
    else if (strcmp(value, "32") == 0)
        o->depth = PROTO_DEPTH_FLOAT;
    else
        REFUSE("%s %s: must be none, 16 or 32", name, value);
    o->depth_given = true;
    return true;
}

static bool option_token(view_options *o, const char *name, const char *value, char *err, size_t cap)
{
    if (!printable(value, PROTO_TOKEN_MAX))
        REFUSE("%s: the token must be at most %d printable ASCII characters", name, PROTO_TOKEN_MAX);
    snprintf(o->token, sizeof o->token, "%s", value);
    return true;
}

static bool option_name(view_options *o, const char *name, const char *value, char *err, size_t cap)
{
    /* The server sees PREFIX_i: room for "_0" at least (check_together checks the last viewer's name). */
    if (!value[0] || !printable(value, PROTO_NAME_MAX - 2))
        REFUSE("%s %s: must be 1..%d printable ASCII characters (viewers are named PREFIX_0, PREFIX_1, ...)",
               name, value, PROTO_NAME_MAX - 2);
    snprintf(o->name_prefix, sizeof o->name_prefix, "%s", value);
    return true;
}

static bool option_out(view_options *o, const char *name, const char *value, char *err, size_t cap)
{
    if (!value[0])
        REFUSE("%s '': needs a folder", name);
    o->out_dir = value;
    return true;
}

static bool option_latency(view_options *o, const char *name, const char *value, char *err, size_t cap)
{
    uint64_t v;
    if (!parse_whole(value, 0, VIEW_MAX_LATENCY_MS, &v))
        REFUSE("%s %s: must be a whole number of milliseconds in 0..%d", name, value, VIEW_MAX_LATENCY_MS);
    o->latency_ms = (uint32_t)v;
    return true;
}

static bool option_stats(view_options *o, const char *name, const char *value, char *err, size_t cap)
{
    if (!value[0])
        REFUSE("%s '': needs a file name", name);
    o->stats_path = value;
    return true;
}

static bool option_timeout(view_options *o, const char *name, const char *value, char *err, size_t cap)
{
    double v;
    if (!parse_decimal(value, &v) || !(v > 0 && v <= 86400))
        REFUSE("%s %s: must be a number of seconds above 0, at most 86400", name, value);
    o->timeout_s = v;
    return true;
}

static bool option_display_fps(view_options *o, const char *name, const char *value, char *err, size_t cap)
{
    double v;
    if (!parse_decimal(value, &v) || !(v > 0 && v <= 1000))
        REFUSE("%s %s: must be a number above 0, at most 1000", name, value);
    o->display_fps = v;
    return true;
}

static bool option_display_out(view_options *o, const char *name, const char *value, char *err, size_t cap)
{
    if (!value[0])
        REFUSE("%s '': needs a folder", name);
    o->display_out = value;
    return true;
}

static bool option_time_scale(view_options *o, const char *name, const char *value, char *err, size_t cap)
{
    double v;
    if (!parse_decimal(value, &v) || !(v >= 1 && v <= 1000))
        REFUSE("%s %s: must be a number from 1 to 1000", name, value);
    o->time_scale = v;
    return true;
}

static bool option_rc_threads(view_options *o, const char *name, const char *value, char *err, size_t cap)
{
    uint64_t v;
    if (!parse_whole(value, 1, VIEW_MAX_RC_THREADS, &v))
        REFUSE("%s %s: must be a whole number in 1..%d", name, value, VIEW_MAX_RC_THREADS);
    o->rc_threads = (uint32_t)v;
    return true;
}

static bool option_sample_budget(view_options *o, const char *name, const char *value, char *err, size_t cap)
{
    uint64_t v;
    /* The upper bound is the image's pixel count, checked with --res in check_together. */
    if (!parse_whole(value, 0, (uint64_t)PROTO_MAX_SIDE * PROTO_MAX_SIDE, &v))
        REFUSE("%s %s: must be a whole number of pixels, 0 (no sample requests) up to the image's pixels",
               name, value);
    o->sample_budget = (uint32_t)v;
    o->sample_budget_given = true;
    return true;
}

static bool option_strategy(view_options *o, const char *name, const char *value, char *err, size_t cap)
{
    proto_strategy strategy;
    if (value[0] && proto_strategy_parse(value, &strategy)) {
        o->strategy = (uint8_t)strategy;
        return true;
    }
    REFUSE("%s %s: must be basic, fan or predictive", name, value);
}

/* The flags: each sets one bool of view_options (found by its offset). */
static bool option_flag(view_options *o, const char *name, const char *value, char *err, size_t cap);

static bool option_quiet(view_options *o, const char *name, const char *value, char *err, size_t cap)
{
    (void)name, (void)value, (void)err, (void)cap;
    o->quiet = true;
    return true;
}

static const struct option_entry {
    const char *name;
    bool takes_value;
    option_fn apply;
} option_table[] = {
    {"--connect", true, option_connect},
    {"--viewers", true, option_viewers},
    {"--frames", true, option_frames},
    {"--trace", true, option_trace},
    {"--camera", true, option_camera},
    {"--fps", true, option_fps},
    {"--res", true, option_res},
    {"--fov", true, option_fov},
    {"--codec", true, option_codec},
    {"--quality", true, option_quality},
    {"--depth", true, option_depth},
    {"--token", true, option_token},
    {"--name", true, option_name},
    {"--out", true, option_out},
    {"--latency", true, option_latency},
    {"--stats", true, option_stats},
    {"--timeout", true, option_timeout},
    {"--quiet", false, option_quiet},
    {"--display-fps", true, option_display_fps},
    {"--display-out", true, option_display_out},
    {"--reproject", false, option_flag},
    {"--no-prediction", false, option_flag},
    {"--no-prefilter", false, option_flag},
    {"--no-eviction", false, option_flag},
    {"--no-tiling", false, option_flag},
    {"--rc-threads", true, option_rc_threads},
    {"--sample-budget", true, option_sample_budget},
    {"--strategy", true, option_strategy},
    {"--time-scale", true, option_time_scale},
};

static bool option_flag(view_options *o, const char *name, const char *value, char *err, size_t cap)
{
    (void)value, (void)err, (void)cap;
    static const struct {
        const char *name;
        size_t offset;
    } flags[] = {
        {"--reproject", offsetof(view_options, reproject)},
        {"--no-prediction", offsetof(view_options, no_prediction)},
        {"--no-prefilter", offsetof(view_options, no_prefilter)},
        {"--no-eviction", offsetof(view_options, no_eviction)},
        {"--no-tiling", offsetof(view_options, no_tiling)},
    };
    for (size_t k = 0; k < sizeof flags / sizeof flags[0]; k++)
        if (strcmp(name, flags[k].name) == 0) {
            *(bool *)((char *)o + flags[k].offset) = true;
            return true;
        }
    return false; /* not reached: every flag of the table is in this list */
}

/* The checks between options, once all are read. */
static bool check_together(view_options *o, bool viewers_given, char *err, size_t cap)
{
    if (o->trace_count > 1) {
        if (viewers_given && o->viewers != o->trace_count)
            REFUSE("--viewers %u: %u traces given; give one trace for all viewers or one per viewer",
                   o->viewers, o->trace_count);
        o->viewers = o->trace_count;
    }
    if (o->trace_count && o->camera_given)
        REFUSE("--camera %s: the cameras come from --trace; use one or the other",
               view_camera_kind_name(o->camera));
    if (o->trace_count && o->fps > 0)
        REFUSE("--fps %g: cameras from --trace are sent at the trace's own times", o->fps);
    if (o->quality_given && o->codec != PROTO_CODEC_JPEG)
        REFUSE("--quality %u: only --codec jpeg has a quality (the codec is %s)", o->quality,
               proto_codec_name(o->codec));
    /* The render cache's options need it; it needs depth. */
    static const struct {
        const char *name;
        size_t offset;
    } rc_only[] = {
        {"--no-prediction", offsetof(view_options, no_prediction)},
        {"--no-prefilter", offsetof(view_options, no_prefilter)},
        {"--no-eviction", offsetof(view_options, no_eviction)},
        {"--no-tiling", offsetof(view_options, no_tiling)},
        {"--sample-budget", offsetof(view_options, sample_budget_given)},
    };
    for (size_t k = 0; k < sizeof rc_only / sizeof rc_only[0]; k++)
        if (!o->reproject && *(const bool *)((const char *)o + rc_only[k].offset))
            REFUSE("%s: only with --reproject (it switches a stage of the render cache)", rc_only[k].name);
    if (!o->reproject && o->rc_threads)
        REFUSE("--rc-threads %u: only with --reproject (the render cache's threads)", o->rc_threads);
    if (!o->reproject && o->strategy == PROTO_STRATEGY_FAN)
        REFUSE("--strategy fan: only with --reproject (a wider, smaller frame is shown through the render "
               "cache)");
    if (o->reproject && o->depth_given && o->depth == PROTO_DEPTH_NONE)
        REFUSE("--depth none: --reproject needs depth (16 or 32; default 16 with --reproject)");
    if (o->reproject && !o->depth_given)
        o->depth = PROTO_DEPTH_HALF;
    if (o->sample_budget_given && o->res_given && o->sample_budget > o->width * o->height)
        REFUSE("--sample-budget %u: more than the %ux%u image's %u pixels", o->sample_budget, o->width,
               o->height, o->width * o->height);
    if (o->name_prefix[0]) {
        char longest[64];
        snprintf(longest, sizeof longest, "%s_%u", o->name_prefix, o->viewers - 1);
        if (strlen(longest) > PROTO_NAME_MAX)
            REFUSE("--name %s: the name %s is longer than %d characters", o->name_prefix, longest,
                   PROTO_NAME_MAX);
    }
    return true;
}

view_parse_result view_options_parse(int argc, char *const argv[], const char *env_token, view_options *o,
                                     char *err, size_t cap)
{
    memset(o, 0, sizeof *o);
    char scratch[32];
    if (!view_options_parse_url(VIEW_DEFAULT_URL, o, scratch, sizeof scratch))
        return VIEW_PARSE_ERROR; /* cannot happen: the default is valid */
    o->viewers = 1;
    o->camera = VIEW_CAMERA_ORBIT;
    o->width = 640;
    o->height = 360;
    o->codec = PROTO_CODEC_ZSTD;
    o->quality = 85;
    o->depth = PROTO_DEPTH_NONE;
    o->display_fps = 30;
    o->time_scale = 1;
    o->timeout_s = 60; /* the first frame of 16 viewers on Sponza took 13 s here: everything is new */
    if (env_token && !option_token(o, "FXCACHE_TOKEN", env_token, err, cap))
        return VIEW_PARSE_ERROR;
    bool viewers_given = false;
    for (int i = 1; i < argc; i++) {
        const char *arg = argv[i];
        if (strcmp(arg, "--help") == 0 || strcmp(arg, "-h") == 0)
            return VIEW_PARSE_HELP;
        /* --name=value or --name value */
        const char *equals = strncmp(arg, "--", 2) == 0 ? strchr(arg, '=') : NULL;
        size_t name_len = equals ? (size_t)(equals - arg) : strlen(arg);
        const struct option_entry *entry = NULL;
        for (size_t k = 0; k < sizeof option_table / sizeof option_table[0]; k++)
            if (strlen(option_table[k].name) == name_len && strncmp(option_table[k].name, arg, name_len) == 0)
                entry = &option_table[k];
        if (!entry) {
            if (arg[0] == '-')
                snprintf(err, cap, "%s: unknown option (fxcache-viewer --help lists them)", arg);
            else
                snprintf(err, cap, "%s: unexpected argument (options start with --; see --help)", arg);
            return VIEW_PARSE_ERROR;
        }
        const char *value = NULL;
        if (entry->takes_value) {
            if (equals) {
                value = equals + 1;
            } else if (i + 1 < argc) {
                value = argv[++i];
            } else {
                snprintf(err, cap, "%s: needs a value (see --help)", entry->name);
                return VIEW_PARSE_ERROR;
            }
        } else if (equals) {
            snprintf(err, cap, "%s: takes no value", arg);
            return VIEW_PARSE_ERROR;
        }
        if (!entry->apply(o, entry->name, value, err, cap))
            return VIEW_PARSE_ERROR;
        if (entry->apply == option_viewers)
            viewers_given = true;
    }
    return check_together(o, viewers_given, err, cap) ? VIEW_PARSE_RUN : VIEW_PARSE_ERROR;
}

const char *view_options_help(void)
{
    return "fxcache-viewer: simulated viewers of an fxcache server (fxcache serve) in one process: each one\n"
           "connects over WebSocket, says hello, sends cameras, decodes the frames it gets back, and "
           "measures\n"
           "them. All viewers share one thread and one libwebsockets context.\n"
           "\n"
           "usage: fxcache-viewer [options]\n"
           "\n"
           "  --connect ws://HOST:PORT  the server (default " VIEW_DEFAULT_URL "); ws:// only, HOST a name,\n"
           "                           an IPv4 address or [an IPv6 address], an optional /PATH after the "
           "port\n"
           "  --viewers N              simulated viewers, 1..64 (default 1, or the number of --trace files)\n"
           "  --frames N               each viewer says bye and closes after showing N frames,\n"
           "                           0..1000000000 (default 0: until interrupted, the server ends, or its\n"
           "                           trace ends)\n"
           "  --trace FILE             cameras from a viewer trace (docs/TRACE_FORMAT.md); repeat it for "
           "one\n"
           "                           trace per viewer, or give one for all. Camera lines are sent at "
           "their\n"
           "                           times after the viewer's welcome, counted from the earliest first "
           "time\n"
           "                           of all traces; a version 2 trace sets the viewer's resolution unless\n"
           "                           --res is given. The viewer ends when a frame for its last camera "
           "shows.\n"
           "  --camera orbit|static    the camera generator without --trace (default orbit): orbit circles "
           "the\n"
           "                           scene bounds' centre at the default camera's height and distance,\n"
           "                           looking at the centre, viewers spread evenly round the circle, one\n"
           "                           revolution per 240 cameras; static is the scene's default camera\n"
           "  --fps F                  generated cameras per second, above 0, at most 1000 (default: the\n"
           "                           server's fps from its welcome, at most 1000); never above the camera\n"
           "                           rate the welcome allows (a warning says so)\n"
           "  --res WxH                image size asked for, each side 1..8192 (default 640x360)\n"
           "  --fov DEG                vertical field of view, (0, 180) (default: the welcome's camera's, "
           "or\n"
           "                           each trace line's; the hello, sent before the welcome, carries "
           "--fov,\n"
           "                           else the trace's first line's, else 60)\n"
           "  --codec raw|zstd|jpeg    colour codec asked for (default zstd)\n"
           "  --quality Q              JPEG quality 1..100 (default 85; only with --codec jpeg)\n"
           "  --depth none|16|32       depth asked for: none (default), binary16 or binary32\n"
           "  --token T                access token (default: $FXCACHE_TOKEN, else none)\n"
           "  --name PREFIX            viewer names PREFIX_0, PREFIX_1, ..., PREFIX 1..29 printable ASCII\n"
           "                           characters (default: the server names them)\n"
           "  --out DIR                write every frame shown as DIR/frame_FFFF_NAME.png (FFFF the "
           "server's\n"
           "                           frame number, NAME the name from the welcome); DIR is created\n"
           "  --latency MS             simulated network delay each way, 0..10000 ms: cameras are held MS\n"
           "                           before they are sent, frames MS before they count as shown\n"
           "  --stats FILE             at the end, JSON: per viewer and in total frames, fps, latency "
           "median\n"
           "                           and 95th percentile, bytes received, bytes per frame, decode errors;\n"
           "                           per viewer the display's frames and empty pixels and, with\n"
           "                           --reproject, the render cache's (pixels by kind, points, requests\n"
           "                           sent and answered, samples, time per stage)\n"
           "  --timeout S              give up on a viewer that has no connection, no welcome, or no frame\n"
           "                           for S seconds, (0, 86400] (default 60: a first frame of many viewers\n"
           "                           on a large scene can take over 10 s)\n"
           "  --quiet                  no summary and no warnings (errors are still printed)\n"
           "  -h, --help               this text\n"
           "\n"
           "The display: each viewer runs its own display clock at --display-fps. A display frame shows, "
           "for\n"
           "the viewer's camera at that moment (its trace's cameras interpolated, or the generator between\n"
           "two of its cameras), the last frame received (default) or, with --reproject, what the render\n"
           "cache reprojects from every frame and sample received so far.\n"
           "  --display-fps F          display frames per second, above 0, at most 1000 (default 30)\n"
           "  --display-out DIR        write every display frame as DIR/display_NNNNN_NAME.png, its camera\n"
           "                           as DIR/display_NAME.trace (time = NNNNN / F: fxcache sim --trace at\n"
           "                           --fps F renders the same cameras) and its figures as\n"
           "                           DIR/display_NAME.csv; DIR is created\n"
           "  --reproject              show the render cache's frames: frames are inserted as they arrive\n"
           "                           (they need depth: --depth defaults to 16), the cache renders each\n"
           "                           display frame and its requests go to the server as sample requests\n"
           "  --no-prediction          no predicted camera (display time + the measured latency) for the\n"
           "                           render cache's predicted requests\n"
           "  --no-prefilter           no 7x7 prefilter in the render cache\n"
           "  --no-eviction            no eviction by age in the render cache\n"
           "  --no-tiling              no tiled z-buffer (one pass over the whole image, one thread)\n"
           "  --rc-threads N           the render cache's threads per viewer, 1..64 (default 1)\n"
           "  --sample-budget N        pixels requested per display frame, 0 (no sample requests) up to the\n"
           "                           image's pixels (default: width * height / 32)\n"
           "  --strategy basic|fan|predictive\n"
           "                           reference frames asked for in the hello (default basic: the camera\n"
           "                           sent; fan: a wider field of view at the same pixel count, "
           "--reproject\n"
           "                           only; predictive: each camera message also carries the camera\n"
           "                           extrapolated by the measured latency)\n"
           "The --no-* switches, --rc-threads and --sample-budget need --reproject.\n"
           "  --time-scale S           run the whole session S times slower, 1..1000 (default 1): trace\n"
           "                           times, --fps, --display-fps and --latency are the session's own "
           "time;\n"
           "                           a server at --fps F/S then stands for one at F on a machine S times\n"
           "                           faster. Latency figures are in session time; fps and seconds on the\n"
           "                           wall clock\n"
           "\n"
           "Latency is, per camera, from the moment it was generated to the moment the first frame rendered\n"
           "for it (or for a newer camera) counts as shown, both --latency delays included. A summary in "
           "words\n"
           "goes to stdout at the end; progress goes to stderr when it is a terminal. SIGINT or SIGTERM: "
           "every\n"
           "viewer says bye and closes, the summary and --stats are written.\n"
           "\n"
           "Exit status: 0 when every viewer ended well; 1 when one failed (refused by the server, could "
           "not\n"
           "connect, timed out, the connection closed early, a message or a frame's picture that does not\n"
           "decode; each gets one line on stderr and the others go on); 2 for a bad option, or a --trace,\n"
           "--out, --display-out or --stats that cannot be used.\n";
}
