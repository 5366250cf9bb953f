/* `fxcache scene-info`: what a scene holds and what it needs, in words or as JSON. The same figures feed
 * the scene benchmark, so every number here is measured on the loaded scene, not estimated. */
#include "cli.h"
#include "effects.h"

#include <getopt.h>
#include <jansson.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>

enum { HIST_BUCKETS = 9 }; /* islands by triangle count: 1, 2-3, 4-7, ..., 128-255, 256 */

typedef struct island_summary {
    uint32_t count;
    uint32_t min_triangles, max_triangles;
    double mean_triangles;
    uint64_t histogram[HIST_BUCKETS];
    uint64_t texels;   /* level-0 texels over all islands, borders included */
    uint64_t blocks;   /* level-0 8x8 blocks over all islands */
    uint32_t max_side; /* largest island side, texels */
} island_summary;

static const char *const bucket_names[HIST_BUCKETS] = {"1",     "2-3",    "4-7",     "8-15", "16-31",
                                                       "32-63", "64-127", "128-255", "256"};

static int bucket_of(uint32_t triangles)
{
    int b = 0;
    while (b < HIST_BUCKETS - 1 && (1u << (b + 1)) <= triangles)
        b++;
    return b;
}

static void summarize_islands(const scene *s, island_summary *out)
{
    memset(out, 0, sizeof *out);
    out->count = s->island_count;
    out->min_triangles = s->island_count ? UINT32_MAX : 0;
    for (uint32_t i = 0; i < s->island_count; i++) {
        const scene_island *is = &s->islands[i];
        out->min_triangles =
            is->triangle_count < out->min_triangles ? is->triangle_count : out->min_triangles;
        out->max_triangles =
            is->triangle_count > out->max_triangles ? is->triangle_count : out->max_triangles;
        out->histogram[bucket_of(is->triangle_count)]++;
        out->texels += (uint64_t)is->width * is->height;
        out->blocks += (uint64_t)((is->width + 7) / 8) * ((is->height + 7) / 8);
        uint32_t side = is->width > is->height ? is->width : is->height;
        out->max_side = side > out->max_side ? side : out->max_side;
    }
    out->mean_triangles = s->island_count ? (double)s->triangle_count / s->island_count : 0;
}

static json_t *vec3_json(const float v[3])
{
    return json_pack("[fff]", (double)v[0], (double)v[1], (double)v[2]);
}

/* A world-space number that must survive the dump's 6 significant digits: an integer when it is one (scene
 * origins are whole metres), else a real. */
static json_t *exact_number_json(double v)
{
    if (v == nearbyint(v) && fabs(v) < 9007199254740992.0)
        return json_integer((json_int_t)v);
    return json_real(v);
}

/* Whether the scene came from a plain mesh file (not a JSON description, not the embedded scene): such a
 * scene gets the default sun and sky unless its materials emit. */
static bool plain_mesh_file(const scene *s)
{
    size_t n = strlen(s->source);
    return s->source[0] != '(' && !(n >= 5 && strcasecmp(s->source + n - 5, ".json") == 0);
}

/* The emitting materials as one JSON object: count, total power, each one's name and radiance. */
static json_t *emission_json(const scene *s)
{
    uint32_t emitting = 0;
    double power[3];
    scene_emission_power(s, &emitting, power);
    json_t *list = json_array();
    for (uint32_t m = 0; m < s->material_count; m++)
        if (scene_material_emits(&s->materials[m]))
            json_array_append_new(list, json_pack("{s:s,s:o}", "name", s->materials[m].name, "emission",
                                                  vec3_json(s->materials[m].emission)));
    return json_pack("{s:i,s:[fff],s:o,s:b}", "emitting_materials", (int)emitting, "power_w", power[0],
                     power[1], power[2], "materials", list, "default_lighting_replaced",
                     emitting > 0 && plain_mesh_file(s) && !s->default_lighting);
}

/* The whole report as one JSON object. */
static json_t *scene_info_json(const scene *s, const island_summary *is, const scene_needs_result *needs,
                               double bvh_ms)
{
    json_t *root = json_object();
    json_object_set_new(root, "source", json_string(s->source));
    json_object_set_new(root, "triangles", json_integer(s->triangle_count));
    json_object_set_new(root, "vertices", json_integer(s->vertex_count));
    json_object_set_new(root, "meshes", json_integer(s->mesh_count));
    json_object_set_new(root, "materials", json_integer(s->material_count));
    json_object_set_new(root, "textures", json_integer(s->texture_count));
    json_object_set_new(root, "vertex_colors", json_boolean(s->corner_color != NULL));
    json_object_set_new(root, "lights", json_integer(s->light_count));
    json_t *lights = json_array();
    for (uint32_t i = 0; i < s->light_count; i++) {
        const scene_light *l = &s->lights[i];
        bool dir = l->type == SCENE_LIGHT_DIRECTIONAL;
        json_array_append_new(lights, json_pack("{s:s,s:o,s:o,s:f}", "type", dir ? "directional" : "point",
                                                dir ? "direction" : "position",
                                                vec3_json(dir ? l->direction : l->position), "color",
                                                vec3_json(l->color), "intensity", (double)l->intensity));
    }
    json_object_set_new(root, "light_list", lights);
    json_object_set_new(root, "emission", emission_json(s));
    json_object_set_new(
        root, "sky",
        json_pack("{s:o,s:f}", "color", vec3_json(s->sky_color), "intensity", (double)s->sky_intensity));
    json_object_set_new(root, "texel_density", json_real(s->texel_density));
    json_object_set_new(root, "texel_density_auto", json_boolean(s->density_auto));
    json_object_set_new(root, "ao_radius", json_real(s->ao_radius));
    json_object_set_new(root, "surface_area_m2", json_real(scene_surface_area(s)));
    json_object_set_new(
        root, "bounds",
        json_pack("{s:o,s:o}", "min", vec3_json(s->bounds_min), "max", vec3_json(s->bounds_max)));
    json_object_set_new(root, "origin",
                        json_pack("[ooo]", exact_number_json(s->origin[0]), exact_number_json(s->origin[1]),
                                  exact_number_json(s->origin[2])));
    json_object_set_new(root, "position_step_m", json_real(s->position_step));
    json_object_set_new(root, "position_step_texels", json_real(s->position_step * (double)s->texel_density));
    json_object_set_new(root, "precision_warning",
                        s->precision_warning[0] ? json_string(s->precision_warning) : json_null());

    json_t *hist = json_object();
    for (int b = 0; b < HIST_BUCKETS; b++)
        json_object_set_new(hist, bucket_names[b], json_integer((json_int_t)is->histogram[b]));
    json_object_set_new(
        root, "islands",
        json_pack("{s:i,s:i,s:i,s:f,s:o,s:I,s:I,s:i}", "count", (int)is->count, "min_triangles",
                  (int)is->min_triangles, "max_triangles", (int)is->max_triangles, "mean_triangles",
                  is->mean_triangles, "triangles_histogram", hist, "texels_level0", (json_int_t)is->texels,
                  "blocks_level0", (json_int_t)is->blocks, "max_side_texels", (int)is->max_side));

    const scene_repairs *r = &s->repairs;
    json_object_set_new(
        root, "repairs",
        json_pack("{s:I,s:I,s:I,s:I,s:I,s:I,s:I,s:I,s:I}", "degenerate_skipped",
                  (json_int_t)r->degenerate_skipped, "precision_skipped", (json_int_t)r->precision_skipped,
                  "duplicate_skipped", (json_int_t)r->duplicate_skipped, "nonmanifold_split",
                  (json_int_t)r->nonmanifold_split, "vertices_welded", (json_int_t)r->vertices_welded,
                  "non_triangles_dropped", (json_int_t)r->non_triangles_dropped, "textures_missing",
                  (json_int_t)r->textures_missing, "lights_unused", (json_int_t)r->lights_unused,
                  "cameras_unused", (json_int_t)r->cameras_unused));
    json_object_set_new(root, "time_ms",
                        json_pack("{s:f,s:f,s:f,s:f,s:f}", "load", s->timings.load_ms, "weld",
                                  s->timings.weld_ms, "textures", s->timings.textures_ms, "islands",
                                  s->timings.islands_ms, "bvh", bvh_ms));

    json_t *effects = json_object(), *left_out = json_object(), *caches = json_object();
    for (int fx = 0; fx < SCENE_FX_COUNT; fx++) {
        const char *name = scene_effect_name((scene_effect)fx);
        if (needs->effect[fx])
            json_object_set_new(effects, name, json_string(needs->effect_reason[fx]));
        else
            json_object_set_new(left_out, name, json_string(needs->effect_reason[fx]));
    }
    for (int c = 0; c < SCENE_CACHE_COUNT; c++) {
        const char *name = scene_cache_name((scene_cache_kind)c);
        if (needs->cache[c])
            json_object_set_new(caches, name, json_string(needs->cache_reason[c]));
        else
            json_object_set_new(left_out, name, json_string(needs->cache_reason[c]));
    }
    json_object_set_new(root, "effects", effects);
    json_object_set_new(root, "caches", caches);
    json_object_set_new(root, "left_out", left_out);
    return root;
}

static void print_text(const scene *s, const island_summary *is, const scene_needs_result *needs,
                       double bvh_ms)
{
    const scene_repairs *r = &s->repairs;
    printf("scene:          %s\n", s->source);
    printf("triangles:      %u (%u vertices after welding, %llu merged)\n", s->triangle_count,
           s->vertex_count, (unsigned long long)r->vertices_welded);
    char lost[160] = "";
    if (r->precision_skipped)
        snprintf(lost, sizeof lost,
                 " (%llu of them with an area, collapsed at float precision up to %.4g m from "
                 "the local origin)",
                 (unsigned long long)r->precision_skipped, r->precision_reach);
    printf("repairs:        %llu degenerate%s and %llu duplicate triangles skipped, %llu split off at "
           "non-manifold edges, %llu points/lines dropped, %llu textures missing\n",
           (unsigned long long)r->degenerate_skipped, lost, (unsigned long long)r->duplicate_skipped,
           (unsigned long long)r->nonmanifold_split, (unsigned long long)r->non_triangles_dropped,
           (unsigned long long)r->textures_missing);
    if (r->lights_unused || r->cameras_unused)
        printf("file lights:    %llu light(s) and %llu camera(s) of the file not used (docs/SCENE_FORMAT.md: "
               "fxcache reads directional and 1/d^2 point lights from glTF and Collada, cameras also from "
               "FBX)\n",
               (unsigned long long)r->lights_unused, (unsigned long long)r->cameras_unused);
    printf("meshes:         %u (materials %u, textures %u%s)\n", s->mesh_count, s->material_count,
           s->texture_count, s->corner_color ? ", vertex colours" : "");
    uint32_t dirs = 0;
    for (uint32_t i = 0; i < s->light_count; i++)
        dirs += s->lights[i].type == SCENE_LIGHT_DIRECTIONAL;
    printf("lights:         %u (%u directional, %u point)\n", s->light_count, dirs, s->light_count - dirs);
    uint32_t emitting = 0;
    double power[3];
    scene_emission_power(s, &emitting, power);
    if (emitting == 0)
        printf("emission:       none (no material emits)\n");
    else
        printf(
            "emission:       %u emitting material%s, total power (%.4g, %.4g, %.4g) W (pi x Le x area)%s\n",
            emitting, emitting == 1 ? "" : "s", power[0], power[1], power[2],
            !plain_mesh_file(s)   ? ""
            : s->default_lighting ? "; they cover more than a tenth of the surface (a glow, not lamps): the "
                                    "default sun and sky stay"
                                  : "; they light the scene: no default sun and sky");
    for (uint32_t m = 0; m < s->material_count; m++)
        if (scene_material_emits(&s->materials[m]))
            printf("  emits:        '%s' radiance (%.4g, %.4g, %.4g)\n", s->materials[m].name,
                   (double)s->materials[m].emission[0], (double)s->materials[m].emission[1],
                   (double)s->materials[m].emission[2]);
    printf("sky:            colour (%.3g, %.3g, %.3g), intensity %.3g\n", (double)s->sky_color[0],
           (double)s->sky_color[1], (double)s->sky_color[2], (double)s->sky_intensity);
    printf("texel density:  %.4g texels per metre%s\n", (double)s->texel_density,
           s->density_auto ? " (auto)" : "");
    printf("surface area:   %.4g m^2; bounds (%.3g, %.3g, %.3g) to (%.3g, %.3g, %.3g)%s\n",
           scene_surface_area(s), (double)s->bounds_min[0], (double)s->bounds_min[1],
           (double)s->bounds_min[2], (double)s->bounds_max[0], (double)s->bounds_max[1],
           (double)s->bounds_max[2],
           s->origin[0] != 0 || s->origin[1] != 0 || s->origin[2] != 0 ? " in the local frame" : "");
    printf(
        "origin:         (%.17g, %.17g, %.17g): positions are kept relative to it (world = local + origin)\n",
        s->origin[0], s->origin[1], s->origin[2]);
    printf("precision:      positions %.3g m apart = %.3g texels%s%s\n", s->position_step,
           s->position_step * (double)s->texel_density, s->precision_warning[0] ? "; WARNING: " : "",
           s->precision_warning);
    printf("islands:        %u; triangles per island min %u, mean %.1f, max %u\n", is->count,
           is->min_triangles, is->mean_triangles, is->max_triangles);
    printf("  level 0:      %llu texels, %llu blocks of 8x8, largest side %u texels\n",
           (unsigned long long)is->texels, (unsigned long long)is->blocks, is->max_side);
    printf("  histogram:   ");
    for (int b = 0; b < HIST_BUCKETS; b++)
        printf(" [%s] %llu", bucket_names[b], (unsigned long long)is->histogram[b]);
    printf("\n");
    printf("build times:    load %.1f ms, weld %.1f ms, textures %.1f ms, islands %.1f ms, BVH %.1f ms\n",
           s->timings.load_ms, s->timings.weld_ms, s->timings.textures_ms, s->timings.islands_ms, bvh_ms);
    printf("effects:\n");
    for (int fx = 0; fx < SCENE_FX_COUNT; fx++)
        printf("  %-16s %-9s %s\n", scene_effect_name((scene_effect)fx),
               needs->effect[fx] ? "runs" : "left out", needs->effect_reason[fx]);
    printf("caches:\n");
    for (int c = 0; c < SCENE_CACHE_COUNT; c++)
        printf("  %-16s %-9s %s\n", scene_cache_name((scene_cache_kind)c),
               needs->cache[c] ? "exists" : "left out", needs->cache_reason[c]);
}

static const char scene_info_usage[] =
    "usage: fxcache scene-info [SCENE] [--json] [--density TEXELS_PER_METRE]\n"
    "\n"
    "Loads SCENE (a *.json scene description, a mesh file Assimp reads, optionally .gz, or 'default' for\n"
    "the embedded scene; the default) and prints its triangles, meshes, lights, emitting\n"
    "materials (count, total emitted power pi x Le x area), islands (count,\n"
    "triangles-per-island histogram, texels and blocks at level 0), texel density, the origin of its local\n"
    "frame (world = local + origin) and the spacing of its float positions (with a warning when that "
    "exceeds\n"
    "1/16 of a texel), build time per stage (including the Embree BVH), and which effects and caches the\n"
    "scene needs and why.\n"
    "\n"
    "  --json               print the same as one JSON object\n"
    "  --density D          level-0 texels per metre, in [1e-6, 1e6] (default: the scene's, else auto)\n"
    "  -h, --help           this text\n";

/* What the scene's content asks for, narrowed to what fxcache runs: an effect with no registered table
 * (probes until the world-space cache is built) is left out with that said, and a cache exists only when a
 * registered effect that runs lives in it. */
static void what_runs(const scene *s, scene_needs_result *needs)
{
    uint32_t count = 0;
    const fx_effect *const *registry = fx_registry(&count);
    bool needed[FX_MAX_EFFECTS];
    char why[FX_MAX_EFFECTS][200];
    fx_needs(registry, count, s, needed, why);
    bool cache_used[SCENE_CACHE_COUNT] = {false};
    for (uint32_t e = 0; e < count; e++)
        cache_used[registry[e]->cache] |= needed[e];
    for (int fx = 0; fx < SCENE_FX_COUNT; fx++) {
        if (fx_find(registry, count, scene_effect_name((scene_effect)fx)) >= 0 || !needs->effect[fx])
            continue;
        needs->effect[fx] = false;
        size_t used = strlen(needs->effect_reason[fx]);
        snprintf(needs->effect_reason[fx] + used, sizeof needs->effect_reason[fx] - used,
                 "; but it is not implemented yet");
    }
    for (int c = 0; c < SCENE_CACHE_COUNT; c++)
        if (needs->cache[c] && !cache_used[c]) {
            needs->cache[c] = false;
            snprintf(needs->cache_reason[c], sizeof needs->cache_reason[c],
                     "no effect that runs lives in it (its effects are not implemented yet)");
        }
}

int srv_cmd_scene_info(int argc, char **argv)
{
    static const struct option options[] = {
        {"json", no_argument, NULL, 'j'},
        {"density", required_argument, NULL, 'd'},
        {"help", no_argument, NULL, 'h'},
        {NULL, 0, NULL, 0},
    };
    bool as_json = false;
    double density = 0;
    optind = 1;
    opterr = 0;
    for (int c; (c = getopt_long(argc, argv, ":h", options, NULL)) != -1;) {
        switch (c) {
        case 'j': as_json = true; break;
        case 'd':
            if (!srv_cli_double("scene-info", "--density", optarg, 1e-6, 1e6, &density))
                return 2;
            break;
        case 'h': fputs(scene_info_usage, stdout); return 0;
        default: return srv_cli_getopt_error("scene-info", c, argv);
        }
    }
    if (argc - optind > 1) {
        fprintf(stderr, "fxcache scene-info: one SCENE at most, got '%s' and '%s'\n", argv[optind],
                argv[optind + 1]);
        return 2;
    }
    const char *path = optind < argc ? argv[optind] : NULL;
    scene *s = srv_cli_load_scene("scene-info", path, (float)density);
    if (!s)
        return 1;
    scene_error err = {0};
    double bvh_ms = 0;
    scene_rt *rt = scene_rt_create(s, &bvh_ms, &err);
    if (!rt) {
        fprintf(stderr, "fxcache scene-info: %s\n", err.msg);
        scene_free(s);
        return 1;
    }
    scene_rt_free(rt);
    island_summary is;
    summarize_islands(s, &is);
    scene_needs_result needs;
    scene_needs(s, &needs);
    what_runs(s, &needs);
    if (as_json) {
        json_t *root = scene_info_json(s, &is, &needs, bvh_ms);
        json_dumpf(root, stdout, JSON_INDENT(2) | JSON_PRESERVE_ORDER | JSON_REAL_PRECISION(6));
        fputc('\n', stdout);
        json_decref(root);
    } else {
        print_text(s, &is, &needs, bvh_ms);
    }
    scene_free(s);
    return 0;
}
