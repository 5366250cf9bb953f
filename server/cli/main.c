/* fxcache: the one command-line program. Each subcommand parses its own options and has its own --help. */
#include "cli.h"

#include <stdio.h>
#include <string.h>

static const char usage[] =
    "usage: fxcache COMMAND [options]\n"
    "\n"
    "fxcache is a multi-viewer effect-cache server: several viewers look at one scene, and ambient\n"
    "occlusion, hard shadows and light probes are computed once into shared caches.\n"
    "\n"
    "commands:\n"
    "  scene-info [SCENE]   what a scene holds: triangles, meshes, lights, islands, texel density,\n"
    "                       build times, and which effects and caches it needs and why\n"
    "  render [SCENE]       a PNG of the scene's albedo with an island checkerboard overlay\n"
    "  sim [options]        several simulated viewers sharing one effect cache, no network:\n"
    "                       statistics per frame, a summary, and the composed frames\n"
    "  serve [options]      the networked server: viewers (fxcache-viewer) connect over WebSockets\n"
    "                       and get composed frames for their cameras\n"
    "  ref [options]        reference images: the same shading per pixel with no cache and converged\n"
    "                       samples, for the frames sim renders, with their noise estimate\n"
    "  report --out DIR     error against run time: sweeps of the settings, each frame's error against\n"
    "                       the reference, CSV, plots, heat maps and an HTML page\n"
    "\n"
    "SCENE is a JSON scene description (*.json), any mesh file Assimp reads (optionally .gz), or\n"
    "'default' (the embedded scene, also used when SCENE is omitted).\n"
    "'fxcache COMMAND --help' tells the options of each command; 'fxcache --version' prints the\n"
    "version.\n";

int main(int argc, char **argv)
{
    if (argc < 2) {
        fputs(usage, stderr);
        return 2;
    }
    const char *cmd = argv[1];
    if (strcmp(cmd, "--help") == 0 || strcmp(cmd, "-h") == 0 || strcmp(cmd, "help") == 0) {
        fputs(usage, stdout);
        return 0;
    }
    if (strcmp(cmd, "--version") == 0) {
        puts("fxcache 0.1.0");
        return 0;
    }
    if (strcmp(cmd, "scene-info") == 0)
        return srv_cmd_scene_info(argc - 1, argv + 1);
    if (strcmp(cmd, "render") == 0)
        return srv_cmd_render(argc - 1, argv + 1);
    if (strcmp(cmd, "sim") == 0)
        return srv_cmd_sim(argc - 1, argv + 1);
    if (strcmp(cmd, "serve") == 0)
        return srv_cmd_serve(argc - 1, argv + 1);
    if (strcmp(cmd, "ref") == 0)
        return srv_cmd_ref(argc - 1, argv + 1);
    if (strcmp(cmd, "report") == 0)
        return srv_cmd_report(argc - 1, argv + 1);
    fprintf(stderr, "fxcache: unknown command '%s' (try 'fxcache --help')\n", cmd);
    return 2;
}
