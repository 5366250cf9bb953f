/* What the scene needs: which effects run and which caches exist, decided once from the scene's content
 * and the overrides in its description, each with a reason a person can read ("the scene has no lights").
 *
 * Nothing is allocated or traced for an effect that is left out, so this is where a scene without lights
 * loses its shadow effect, and a scene without a world-space effect loses its world-space cache. The server
 * prints the reasons at start and records them in the statistics.
 *
 * Rules (an override "off" always wins; "on" forces the effect and warns in the reason when it has nothing
 * to work with; "auto" follows the content):
 *   shadow           at least one light with intensity > 0 and a non-black colour;
 *   ao               a sky (the ambient light) with intensity > 0 and a non-black colour;
 *   probes           indirect not switched off, some light, sky or emitting material (emission > 0) with
 *                    energy, and some mesh whose material has a non-zero albedo (a texture counts as
 *                    non-zero); the probes carry the emitters' light to the surfaces around them;
 *   triangle_lookup  iff an on-surface effect (shadow, ao) runs: it serves them;
 *   on_surface cache iff triangle_lookup runs; world_space cache iff probes run. */
#include "scene_internal.h"

#include <stdarg.h>
#include <stdio.h>
#include <string.h>

/* What the content offers the effects, counted once. */
typedef struct needs_content {
    uint32_t lights_with_energy; /* intensity > 0 and a non-black colour */
    bool sky_exists;             /* any sky intensity or colour at all */
    bool sky_with_energy;        /* intensity > 0 and a non-black colour */
    uint32_t meshes_with_albedo; /* meshes whose material has a non-zero diffuse colour or a texture */
    uint32_t emitting_meshes;    /* meshes whose material emits */
} needs_content;

/* Writes a reason (printf-style) into a fixed-size reason slot, cut short if it does not fit. */
__attribute__((format(printf, 3, 4))) static void needs_reason(char *out, size_t cap, const char *fmt, ...)
{
    va_list args;
    va_start(args, fmt);
    vsnprintf(out, cap, fmt, args);
    va_end(args);
}

/* True when an RGB colour has a positive component. */
static bool needs_color_nonblack(const float rgb[3])
{
    return rgb[0] > 0.0f || rgb[1] > 0.0f || rgb[2] > 0.0f;
}

/* Counts the lights, sky and albedo the effects can work with. */
static void needs_survey(const scene *s, needs_content *content)
{
    memset(content, 0, sizeof *content);
    for (uint32_t i = 0; i < s->light_count; i++)
        if (s->lights[i].intensity > 0.0f && needs_color_nonblack(s->lights[i].color))
            content->lights_with_energy++;
    content->sky_exists = s->sky_intensity != 0.0f || needs_color_nonblack(s->sky_color);
    content->sky_with_energy = s->sky_intensity > 0.0f && needs_color_nonblack(s->sky_color);
    for (uint32_t m = 0; m < s->mesh_count; m++) {
        const scene_mesh *mesh = &s->meshes[m];
        if (mesh->triangle_count == 0 || mesh->material >= s->material_count)
            continue;
        const scene_material *material = &s->materials[mesh->material];
        bool textured = material->texture >= 0 && (uint32_t)material->texture < s->texture_count;
        if (textured || needs_color_nonblack(material->diffuse))
            content->meshes_with_albedo++;
        if (scene_material_emits(material))
            content->emitting_meshes++;
    }
}

/* Decides the shadow effect. */
static void needs_shadow(const scene *s, const needs_content *content, scene_needs_result *out)
{
    char *reason = out->effect_reason[SCENE_FX_SHADOW];
    size_t cap = sizeof out->effect_reason[SCENE_FX_SHADOW];
    if (s->fx_shadows == SCENE_OFF) {
        out->effect[SCENE_FX_SHADOW] = false;
        needs_reason(reason, cap, "switched off in the scene description");
    } else if (s->fx_shadows == SCENE_ON) {
        out->effect[SCENE_FX_SHADOW] = true;
        if (content->lights_with_energy > 0)
            needs_reason(reason, cap, "forced on in the scene description (%u of %u lights carry energy)",
                         content->lights_with_energy, s->light_count);
        else
            needs_reason(reason, cap,
                         "forced on in the scene description; warning: no light has intensity > 0 "
                         "and a non-black colour, so there is nothing to shadow");
    } else if (content->lights_with_energy > 0) {
        out->effect[SCENE_FX_SHADOW] = true;
        needs_reason(reason, cap, "%u of %u lights carry energy (intensity > 0, non-black colour)",
                     content->lights_with_energy, s->light_count);
    } else if (s->light_count == 0 && content->emitting_meshes > 0) {
        out->effect[SCENE_FX_SHADOW] = false;
        needs_reason(
            reason, cap,
            "the scene has no lights: its %u emitting mesh%s light it through the probes (emitters cast "
            "no hard shadows)",
            content->emitting_meshes, content->emitting_meshes == 1 ? "" : "es");
    } else if (s->light_count == 0) {
        out->effect[SCENE_FX_SHADOW] = false;
        needs_reason(reason, cap, "the scene has no lights");
    } else {
        out->effect[SCENE_FX_SHADOW] = false;
        needs_reason(reason, cap, "none of the %u lights carries energy (intensity 0 or a black colour)",
                     s->light_count);
    }
}

/* Decides the ambient-occlusion effect. */
static void needs_ao(const scene *s, const needs_content *content, scene_needs_result *out)
{
    char *reason = out->effect_reason[SCENE_FX_AO];
    size_t cap = sizeof out->effect_reason[SCENE_FX_AO];
    if (s->fx_ao == SCENE_OFF) {
        out->effect[SCENE_FX_AO] = false;
        needs_reason(reason, cap, "switched off in the scene description");
    } else if (s->fx_ao == SCENE_ON) {
        out->effect[SCENE_FX_AO] = true;
        if (content->sky_with_energy)
            needs_reason(reason, cap, "forced on in the scene description (the sky gives ambient light)");
        else
            needs_reason(reason, cap,
                         "forced on in the scene description; warning: there is no sky (ambient "
                         "light) with energy, so occlusion darkens nothing");
    } else if (content->sky_with_energy) {
        out->effect[SCENE_FX_AO] = true;
        needs_reason(reason, cap, "the sky gives ambient light (intensity %g)", (double)s->sky_intensity);
    } else if (!content->sky_exists) {
        out->effect[SCENE_FX_AO] = false;
        needs_reason(reason, cap, "the scene has no sky (no ambient light to occlude)");
    } else {
        out->effect[SCENE_FX_AO] = false;
        needs_reason(reason, cap,
                     "the sky is dark (intensity 0 or a black colour): no ambient light to occlude");
    }
}

/* Decides the probes (indirect diffuse) effect. */
static void needs_probes(const scene *s, const needs_content *content, scene_needs_result *out)
{
    char *reason = out->effect_reason[SCENE_FX_PROBES];
    size_t cap = sizeof out->effect_reason[SCENE_FX_PROBES];
    bool has_energy =
        content->lights_with_energy > 0 || content->sky_with_energy || content->emitting_meshes > 0;
    bool has_albedo = content->meshes_with_albedo > 0;
    if (s->fx_indirect == SCENE_OFF) {
        out->effect[SCENE_FX_PROBES] = false;
        needs_reason(reason, cap, "switched off in the scene description");
    } else if (s->fx_indirect == SCENE_ON) {
        out->effect[SCENE_FX_PROBES] = true;
        if (has_energy && has_albedo)
            needs_reason(reason, cap, "forced on in the scene description (light bounces off %u meshes)",
                         content->meshes_with_albedo);
        else
            needs_reason(reason, cap, "forced on in the scene description; warning: nothing to bounce (%s)",
                         !has_energy ? "no light, sky or emitter with energy" : "every material is black");
    } else if (!has_energy) {
        out->effect[SCENE_FX_PROBES] = false;
        needs_reason(reason, cap,
                     "nothing lights the scene (no light, sky or emitter with energy), so no light bounces");
    } else if (!has_albedo) {
        out->effect[SCENE_FX_PROBES] = false;
        needs_reason(reason, cap, "every material is black (zero albedo, no texture), so no light bounces");
    } else {
        out->effect[SCENE_FX_PROBES] = true;
        char sources[64] = "", emitters[48] = "";
        if (content->lights_with_energy > 0 && content->sky_with_energy)
            needs_reason(sources, sizeof sources, "%u light%s and the sky", content->lights_with_energy,
                         content->lights_with_energy == 1 ? "" : "s");
        else if (content->lights_with_energy > 0)
            needs_reason(sources, sizeof sources, "%u light%s", content->lights_with_energy,
                         content->lights_with_energy == 1 ? "" : "s");
        else if (content->sky_with_energy)
            needs_reason(sources, sizeof sources, "the sky");
        if (content->emitting_meshes > 0) /* the emitters' light reaches surfaces through the probes alone */
            needs_reason(emitters, sizeof emitters, "%s%u emitting mesh%s", sources[0] ? " and " : "",
                         content->emitting_meshes, content->emitting_meshes == 1 ? "" : "es");
        needs_reason(reason, cap, "light from %s%s bounces off %u of %u meshes with non-zero albedo", sources,
                     emitters, content->meshes_with_albedo, s->mesh_count);
    }
}

/* Decides which effects and caches run for s (read-only, finished or not) and why; fills every field of out. */
void scene_needs(const scene *s, scene_needs_result *out)
{
    memset(out, 0, sizeof *out);
    needs_content content;
    needs_survey(s, &content);
    needs_shadow(s, &content, out);
    needs_ao(s, &content, out);
    needs_probes(s, &content, out);

    bool shadow = out->effect[SCENE_FX_SHADOW], ao = out->effect[SCENE_FX_AO];
    char *lookup_reason = out->effect_reason[SCENE_FX_TRIANGLE_LOOKUP];
    size_t lookup_cap = sizeof out->effect_reason[SCENE_FX_TRIANGLE_LOOKUP];
    out->effect[SCENE_FX_TRIANGLE_LOOKUP] = shadow || ao;
    if (shadow && ao)
        needs_reason(lookup_reason, lookup_cap, "needed by the on-surface effects shadow and ao");
    else if (shadow || ao)
        needs_reason(lookup_reason, lookup_cap, "needed by the on-surface effect %s",
                     shadow ? "shadow" : "ao");
    else
        needs_reason(lookup_reason, lookup_cap, "no on-surface effect runs (shadow and ao are left out)");

    out->cache[SCENE_CACHE_ON_SURFACE] = out->effect[SCENE_FX_TRIANGLE_LOOKUP];
    if (out->cache[SCENE_CACHE_ON_SURFACE])
        needs_reason(out->cache_reason[SCENE_CACHE_ON_SURFACE],
                     sizeof out->cache_reason[SCENE_CACHE_ON_SURFACE], "holds triangle_lookup%s%s",
                     shadow ? ", shadow" : "", ao ? ", ao" : "");
    else
        needs_reason(out->cache_reason[SCENE_CACHE_ON_SURFACE],
                     sizeof out->cache_reason[SCENE_CACHE_ON_SURFACE],
                     "no on-surface effect runs (shadow and ao are left out)");

    out->cache[SCENE_CACHE_WORLD_SPACE] = out->effect[SCENE_FX_PROBES];
    if (out->cache[SCENE_CACHE_WORLD_SPACE])
        needs_reason(out->cache_reason[SCENE_CACHE_WORLD_SPACE],
                     sizeof out->cache_reason[SCENE_CACHE_WORLD_SPACE], "holds probes");
    else
        needs_reason(out->cache_reason[SCENE_CACHE_WORLD_SPACE],
                     sizeof out->cache_reason[SCENE_CACHE_WORLD_SPACE],
                     "no world-space effect runs (probes are left out)");
}

/* The short name of an effect: "triangle_lookup", "shadow", "ao", "probes" ("?" when out of range). */
const char *scene_effect_name(scene_effect fx)
{
    static const char *const names[SCENE_FX_COUNT] = {"triangle_lookup", "shadow", "ao", "probes"};
    return (unsigned)fx < SCENE_FX_COUNT ? names[fx] : "?";
}

/* The short name of a cache: "on_surface", "world_space" ("?" when out of range). */
const char *scene_cache_name(scene_cache_kind c)
{
    static const char *const names[SCENE_CACHE_COUNT] = {"on_surface", "world_space"};
    return (unsigned)c < SCENE_CACHE_COUNT ? names[c] : "?";
}
