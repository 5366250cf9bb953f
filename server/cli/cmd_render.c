/* `fxcache render`: a picture of a scene's albedo with an island checkerboard overlay, so a person can see
 * the islands and the texel density: each island gets its own tint, and its 8x8-texel level-0 blocks
 * alternate light and dark. One closest-hit ray per pixel through Embree. */
#include "camera.h"
#include "cli.h"
#include "image.h"

#include <getopt.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* Linear [0,1] to an sRGB-encoded byte. */
static uint8_t linear_to_srgb8(float c)
{
    c = c > 0 ? (c < 1 ? c : 1) : 0;
    float e = c <= 0.0031308f ? 12.92f * c : 1.055f * powf(c, 1.0f / 2.4f) - 0.055f;
    return (uint8_t)(e * 255.0f + 0.5f);
}

/* A stable, well-spread tint per island (hashed hue). */
static void island_tint(uint32_t island, float out[3])
{
    uint32_t h = island * 2654435761u;
    h ^= h >> 15;
    float hue = (float)(h % 360u) / 60.0f;
    float x = 1.0f - fabsf(fmodf(hue, 2.0f) - 1.0f);
    float r = 0, g = 0, b = 0;
    switch ((int)hue) {
    case 0: r = 1, g = x; break;
    case 1: r = x, g = 1; break;
    case 2: g = 1, b = x; break;
    case 3: g = x, b = 1; break;
    case 4: r = x, b = 1; break;
    default: r = 1, b = x; break;
    }
    out[0] = r, out[1] = g, out[2] = b;
}

/* The overlay colour of one hit: albedo, tinted per island, checkered per level-0 block, lit by a head
 * light so shapes read. */
static void shade_hit(const scene *s, uint32_t tri, float u, float v, const float dir[3], float out[3])
{
    float albedo[3], tint[3];
    scene_albedo(s, tri, u, v, albedo);
    island_tint(s->tri_island[tri], tint);
    const float *uv = s->tri_island_uv + 6 * (size_t)tri;
    float w = 1 - u - v;
    float tu = w * uv[0] + u * uv[2] + v * uv[4];
    float tv = w * uv[1] + u * uv[3] + v * uv[5];
    long bx = (long)floorf(tu / 8.0f), by = (long)floorf(tv / 8.0f);
    float checker = ((bx + by) & 1) ? 1.0f : 0.55f;
    const float *n = s->tri_normal + 3 * (size_t)tri;
    float facing = fabsf(n[0] * dir[0] + n[1] * dir[1] + n[2] * dir[2]);
    float light = 0.35f + 0.65f * facing;
    for (int k = 0; k < 3; k++)
        out[k] = light * checker * (0.6f * albedo[k] + 0.4f * tint[k]);
}

static const char render_usage[] =
    "usage: fxcache render [SCENE] [-o FILE] [--res WxH] [--camera X,Y,Z] [--target X,Y,Z] [--fov DEG]\n"
    "                      [--density TEXELS_PER_METRE]\n"
    "\n"
    "Renders SCENE (a *.json scene description, a mesh file, or 'default': the embedded scene, the\n"
    "default) to an image showing albedo with an island checkerboard overlay: each island has its own\n"
    "tint and its 8x8-texel blocks at level 0 alternate light and dark.\n"
    "\n"
    "  -o, --out FILE       image to write; the format follows the extension (default fxcache-render.png)\n"
    "  --res WxH            image size, each side in [1, 16384] (default 960x540)\n"
    "  --camera X,Y,Z       camera position, world coordinates (default: the scene's camera, else one\n"
    "                       framing the scene)\n"
    "  --target X,Y,Z       point looked at (default as for --camera)\n"
    "  --fov DEG            vertical field of view in degrees, in [1, 179] (default 60 or the scene's)\n"
    "  --density D          level-0 texels per metre, in [1e-6, 1e6] (default: the scene's, else auto)\n"
    "  -h, --help           this text\n";

int srv_cmd_render(int argc, char **argv)
{
    static const struct option options[] = {
        {"out", required_argument, NULL, 'o'},    {"res", required_argument, NULL, 'r'},
        {"camera", required_argument, NULL, 'c'}, {"target", required_argument, NULL, 't'},
        {"fov", required_argument, NULL, 'f'},    {"density", required_argument, NULL, 'd'},
        {"help", no_argument, NULL, 'h'},         {NULL, 0, NULL, 0},
    };
    const char *out_path = "fxcache-render.png";
    uint32_t width = 960, height = 540;
    double position[3], target[3]; /* world coordinates, converted into the scene's local frame */
    bool has_position = false, has_target = false;
    double fov = 0, density = 0;
    optind = 1;
    opterr = 0;
    for (int c; (c = getopt_long(argc, argv, ":ho:", options, NULL)) != -1;) {
        bool ok = true;
        switch (c) {
        case 'o': out_path = optarg; break;
        case 'r': ok = srv_cli_resolution("render", "--res", optarg, 16384, &width, &height); break;
        case 'c': ok = has_position = srv_cli_vec3("render", "--camera", optarg, position); break;
        case 't': ok = has_target = srv_cli_vec3("render", "--target", optarg, target); break;
        case 'f': ok = srv_cli_double("render", "--fov", optarg, 1, 179, &fov); break;
        case 'd': ok = srv_cli_double("render", "--density", optarg, 1e-6, 1e6, &density); break;
        case 'h': fputs(render_usage, stdout); return 0;
        default: return srv_cli_getopt_error("render", c, argv);
        }
        if (!ok)
            return 2;
    }
    if (argc - optind > 1) {
        fprintf(stderr, "fxcache render: one SCENE at most, got '%s' and '%s'\n", argv[optind],
                argv[optind + 1]);
        return 2;
    }
    scene *s = srv_cli_load_scene("render", optind < argc ? argv[optind] : NULL, (float)density);
    if (!s)
        return 1;
    srv_camera cam = srv_camera_default(s);
    if (has_position)
        scene_world_to_local(s, position, cam.position);
    if (has_target)
        scene_world_to_local(s, target, cam.target);
    if (fov > 0)
        cam.fov_deg = (float)fov;
    srv_camera_frame frame;
    if (!srv_camera_setup(&cam, width, height, &frame)) {
        /* the same two causes, and words, as a trace camera's (srv_cli_cameras_check) */
        double reach = 0;
        for (int k = 0; k < 3; k++)
            reach = fmax(reach, fmax(fabs((double)cam.position[k]), fabs((double)cam.target[k])));
        if (!(reach <= SCENE_MAX_CAMERA_REACH))
            fprintf(stderr,
                    "fxcache render: the camera lies %.3g m from the scene's centre; cameras may be at most "
                    "%.0e m "
                    "from it\n",
                    reach, SCENE_MAX_CAMERA_REACH);
        else
            fprintf(stderr,
                    "fxcache render: the camera is degenerate: its position and target coincide in the "
                    "scene's float coordinates\n");
        scene_free(s);
        return 2;
    }
    scene_error err = {0};
    scene_rt *rt = scene_rt_create(s, NULL, &err);
    uint8_t *pixels = malloc((size_t)width * height * 3);
    if (!rt || !pixels) {
        fprintf(stderr, "fxcache render: %s\n", rt ? "out of memory for the image" : err.msg);
        free(pixels);
        scene_rt_free(rt);
        scene_free(s);
        return 1;
    }
    for (uint32_t y = 0; y < height; y++)
        for (uint32_t x = 0; x < width; x++) {
            float dir[3], rgb[3] = {0.02f, 0.02f, 0.03f};
            srv_camera_ray(&frame, (float)x + 0.5f, (float)y + 0.5f, dir);
            uint32_t tri;
            float u, v, t;
            if (scene_rt_intersect1(rt, frame.origin, dir, INFINITY, &tri, &u, &v, &t))
                shade_hit(s, tri, u, v, dir, rgb);
            uint8_t *p = pixels + 3 * ((size_t)y * width + x);
            for (int k = 0; k < 3; k++)
                p[k] = linear_to_srgb8(rgb[k]);
        }
    char msg[512];
    int rc = scene_image_write_u8(out_path, width, height, 3, pixels, msg, sizeof msg);
    if (rc != 0)
        fprintf(stderr, "fxcache render: %s\n", msg);
    else
        printf("wrote %s (%ux%u, %u islands)\n", out_path, width, height, s->island_count);
    free(pixels);
    scene_rt_free(rt);
    scene_free(s);
    return rc == 0 ? 0 : 1;
}
