/* Stage 7, compose: per pixel, albedo x (sum over lights of intensity x cos x filtered shadow + sky x
 * filtered AO), then a tone map and sRGB 8-bit. Cached effects are read with the bilinear filter at the
 * level the pixel requested, through osc_find (read-only, safe from every thread); texels that hold no data
 * yet (ray budget, exhausted pool) are left out of the filter and their weight renormalised; a pixel with
 * no data at all uses the unshadowed, unoccluded value and is counted as missing. In no-cache mode the
 * same terms come from rays traced at the pixel with the sample counts the cache converges to. */
#include "frame_internal.h"

#include <float.h>
#include <math.h>
#include <pthread.h>
#include <stdatomic.h>
#include <string.h>

/* The up to four texels a bilinear lookup reads, with weights, restricted to texels holding data. */
typedef struct bilinear_taps {
    const uint8_t *texel[4];
    float weight[4];
    uint32_t count;
    uint32_t first_block; /* block of the first tap (for the sharing picture), OSC_NONE if none */
} bilinear_taps;

/* Remembers the last block found per effect, since neighbouring pixels mostly read the same block. */
typedef struct block_memo {
    uint64_t key[SCENE_FX_COUNT];
    uint32_t block[SCENE_FX_COUNT];
} block_memo;

static uint32_t find_block(const osc_cache *osc, block_memo *memo, uint32_t fx, uint64_t key)
{
    if (memo->key[fx] != key) {
        memo->key[fx] = key;
        memo->block[fx] = osc_find(osc, key);
    }
    return memo->block[fx];
}

/* Gathers the bilinear taps of effect fx at (tu, tv) (level-0 island texels) at level. */
static void gather_taps(srv_loop *loop, block_memo *memo, uint32_t fx, uint32_t island, uint32_t level, float tu,
                        float tv, bilinear_taps *out)
{
    const scene_island *is = &loop->s->islands[island];
    uint32_t w = osc_level_size(is->width, level), h = osc_level_size(is->height, level);
    float scale = 1.0f / (float)(1u << level);
    float x = tu * scale - 0.5f, y = tv * scale - 0.5f;
    float fx0 = floorf(x), fy0 = floorf(y);
    float ax = x - fx0, ay = y - fy0;
    long x0 = (long)fx0, y0 = (long)fy0;
    uint32_t texel_bytes = osc_pool_texel_bytes(loop->osc, fx);
    float total = 0;
    out->count = 0;
    out->first_block = OSC_NONE;
    /* The four taps mostly share one block: look a block up (and read its valid mask) once. */
    long last_bx = -1, last_by = -1;
    uint32_t block = OSC_NONE;
    uint64_t valid = 0;
    const uint8_t *payload = NULL;
    for (int i = 0; i < 4; i++) {
        long xi = x0 + (i & 1), yi = y0 + (i >> 1);
        xi = xi < 0 ? 0 : (xi >= (long)w ? (long)w - 1 : xi);
        yi = yi < 0 ? 0 : (yi >= (long)h ? (long)h - 1 : yi);
        float weight = ((i & 1) ? ax : 1 - ax) * ((i >> 1) ? ay : 1 - ay);
        if ((xi >> 3) != last_bx || (yi >> 3) != last_by) {
            last_bx = xi >> 3;
            last_by = yi >> 3;
            uint64_t key = osc_key_pack(fx, island, level, (uint32_t)last_bx, (uint32_t)last_by);
            block = find_block(loop->osc, memo, fx, key);
            if (block != OSC_NONE) {
                valid = osc_block_valid(loop->osc, fx, block);
                payload = osc_block_payload(loop->osc, fx, block);
            }
        }
        if (block == OSC_NONE)
            continue;
        if (out->first_block == OSC_NONE)
            out->first_block = block;
        uint32_t t = ((uint32_t)yi & 7) * 8 + ((uint32_t)xi & 7);
        if (!(valid >> t & 1) || weight <= 0)
            continue;
        out->texel[out->count] = payload + (size_t)t * texel_bytes;
        out->weight[out->count] = weight;
        out->count++;
        total += weight;
    }
    for (uint32_t i = 0; i < out->count; i++)
        out->weight[i] /= total;
}

/* Differentials of the hit position towards the next pixel right (dpdx) and down (dpdy). */
static void pixel_differentials(const srv_camera_frame *f, const float dir[3], float t, const float n[3],
                                float dpdx[3], float dpdy[3])
{
    float dn = dir[0] * n[0] + dir[1] * n[1] + dir[2] * n[2];
    for (int axis = 0; axis < 2; axis++) {
        const float *offset = axis == 0 ? f->right : f->up;
        float step = axis == 0 ? 2.0f * f->tan_half_x / (float)f->width : -2.0f * f->tan_half_y / (float)f->height;
        float d2[3];
        for (int k = 0; k < 3; k++)
            d2[k] = dir[k] + step * offset[k];
        float d2n = d2[0] * n[0] + d2[1] * n[1] + d2[2] * n[2];
        float t2 = fabsf(d2n) > 1e-12f ? t * dn / d2n : t;
        if (!(t2 > 0) || t2 > 64.0f * t)
            t2 = 64.0f * t;
        float *out = axis == 0 ? dpdx : dpdy;
        for (int k = 0; k < 3; k++)
            out[k] = d2[k] * t2 - dir[k] * t;
    }
}

enum { TONE_LUT_SIZE = 4096 };

/* The tone map (1 - e^-c) followed by the sRGB encoding, tabulated over the tone-mapped value in [0, 1]:
 * two transcendental calls per channel and pixel were most of compose's time. */
static uint8_t tone_lut[TONE_LUT_SIZE];
static pthread_once_t tone_lut_once = PTHREAD_ONCE_INIT;

static void tone_lut_init(void)
{
    for (int i = 0; i < TONE_LUT_SIZE; i++) {
        float c = (float)i / (TONE_LUT_SIZE - 1);
        float e = c <= 0.0031308f ? 12.92f * c : 1.055f * powf(c, 1.0f / 2.4f) - 0.055f;
        tone_lut[i] = (uint8_t)(e * 255.0f + 0.5f);
    }
}

/* Linear radiance to an sRGB byte through the tone map. */
static uint8_t tone_map_srgb8(float c)
{
    if (!(c > 0))
        return 0;
    float mapped = c < 20.0f ? 1.0f - expf(-c) : 1.0f;
    return tone_lut[(int)(mapped * (TONE_LUT_SIZE - 1) + 0.5f)];
}

typedef struct compose_task {
    srv_loop *loop;
    uint32_t viewer;
    atomic_uint_fast64_t missing, rays_ao, rays_shadow;
} compose_task;

static void compose_rows(void *user, uint32_t task_index, uint32_t thread_index)
{
    (void)thread_index;
    compose_task *task = user;
    srv_loop *loop = task->loop;
    const scene *s = loop->s;
    srv_viewer *view = &loop->viewers[task->viewer];
    const srv_camera_frame *f = &view->frame;
    bool no_cache = loop->desc.no_cache;
    bool use_shadow = loop->desc.effect_on[SCENE_FX_SHADOW], use_ao = loop->desc.effect_on[SCENE_FX_AO];
    block_memo memo;
    memset(memo.key, 0xFF, sizeof memo.key);
    uint64_t missing = 0, rays_ao = 0, rays_shadow = 0;
    float sky[3];
    for (int k = 0; k < 3; k++)
        sky[k] = s->sky_color[k] * s->sky_intensity;
    const float log2_density = log2f(s->texel_density);
    for (uint32_t y = task_index * SRV_TILE; y < (task_index + 1) * SRV_TILE && y < f->height; y++)
        for (uint32_t x = 0; x < f->width; x++) {
            size_t p = (size_t)y * f->width + x;
            float *rad = view->radiance + 3 * p;
            float ao = 1.0f, shadow0 = 1.0f, sharing = 0.0f;
            uint32_t tri = view->tri[p];
            if (tri == SRV_MISS) {
                memcpy(rad, sky, sizeof sky);
            } else {
                float u = view->bary_u[p], v = view->bary_v[p];
                float pos[3], n[3], dir[3], albedo[3];
                srv__hit_point(s, tri, u, v, pos, n);
                srv_camera_ray(f, (float)x + 0.5f, (float)y + 0.5f, dir);
                float facing = n[0] * dir[0] + n[1] * dir[1] + n[2] * dir[2];
                float shade_n[3] = {n[0], n[1], n[2]};
                if (facing > 0) /* seen from behind: light the side the viewer sees */
                    for (int k = 0; k < 3; k++)
                        shade_n[k] = -n[k];
                /* The pixel's footprint in metres: level-0 texels per pixel over texels per metre. */
                scene_albedo_filtered(s, tri, u, v, view->footprint[p] - log2_density, albedo);
                uint32_t island = s->tri_island[tri];
                float tu, tv;
                srv__island_uv(s, tri, u, v, &tu, &tv);
                bilinear_taps shadow_taps = {0}, ao_taps = {0};
                bool pixel_missing = false;
                if (!no_cache && use_shadow) {
                    gather_taps(loop, &memo, FX_SHADOW, island, srv__level(view->footprint[p], loop->bias[FX_SHADOW]),
                                tu, tv, &shadow_taps);
                    pixel_missing |= shadow_taps.count == 0;
                }
                if (!no_cache && use_ao) {
                    gather_taps(loop, &memo, FX_AO, island, srv__level(view->footprint[p], loop->bias[FX_AO]), tu,
                                tv, &ao_taps);
                    pixel_missing |= ao_taps.count == 0;
                    if (view->views[SRV_VIEW_SHARING] && ao_taps.first_block != OSC_NONE && loop->viewer_bits[FX_AO])
                        sharing = (float)__builtin_popcountll(loop->viewer_bits[FX_AO][ao_taps.first_block]);
                }
                missing += pixel_missing;
                float dpdx[3], dpdy[3];
                if (no_cache) {
                    float t = (pos[0] - f->origin[0]) * dir[0] + (pos[1] - f->origin[1]) * dir[1] +
                              (pos[2] - f->origin[2]) * dir[2];
                    pixel_differentials(f, dir, t, n, dpdx, dpdy);
                }
                float irradiance[3] = {0, 0, 0};
                for (uint32_t l = 0; l < s->light_count; l++) {
                    const scene_light *light = &s->lights[l];
                    float ldir[3], dist;
                    fx_light_direction(light, pos, ldir, &dist);
                    float cosine = shade_n[0] * ldir[0] + shade_n[1] * ldir[1] + shade_n[2] * ldir[2];
                    if (!(cosine > 0))
                        continue;
                    float lit = 1.0f;
                    if (use_shadow) {
                        if (no_cache) {
                            uint64_t r = 0;
                            lit = fx_shadow_eval_point(&loop->fx, pos, n, dpdx, dpdy, l, p, &r);
                            rays_shadow += r;
                        } else if (shadow_taps.count) {
                            lit = 0;
                            for (uint32_t i = 0; i < shadow_taps.count; i++)
                                lit += shadow_taps.weight[i] * fx_shadow_sample(shadow_taps.texel[i], 0, s->light_count, l);
                        }
                    }
                    if (l == 0)
                        shadow0 = lit;
                    float falloff = light->type == SCENE_LIGHT_POINT ? 1.0f / fmaxf(dist * dist, 1e-8f) : 1.0f;
                    for (int k = 0; k < 3; k++)
                        irradiance[k] += light->intensity * light->color[k] * cosine * lit * falloff;
                }
                if (use_ao) {
                    if (no_cache) {
                        uint64_t r = 0;
                        ao = fx_ao_eval_point(&loop->fx, pos, n, FX_AO_MAX_SAMPLES, p, &r);
                        rays_ao += r;
                    } else if (ao_taps.count) {
                        ao = 0;
                        for (uint32_t i = 0; i < ao_taps.count; i++)
                            ao += ao_taps.weight[i] * fx_ao_sample(ao_taps.texel[i], 0);
                    }
                }
                /* Saturate, never overflow to infinity (extreme light intensities): DESIGN.md, robustness. */
                for (int k = 0; k < 3; k++) {
                    float irr = fminf(irradiance[k], FLT_MAX) + fminf(sky[k] * ao, FLT_MAX);
                    float value = albedo[k] * fminf(irr, FLT_MAX);
                    rad[k] = value <= FLT_MAX ? value : (value > 0 ? FLT_MAX : 0.0f);
                }
            }
            uint8_t *px = view->image + 3 * p;
            for (int k = 0; k < 3; k++)
                px[k] = tone_map_srgb8(rad[k]);
            if (view->views[SRV_VIEW_AO]) {
                view->views[SRV_VIEW_AO][p] = ao;
                view->views[SRV_VIEW_SHADOW][p] = shadow0;
                view->views[SRV_VIEW_SHARING][p] = sharing;
            }
        }
    atomic_fetch_add(&task->missing, missing);
    atomic_fetch_add(&task->rays_ao, rays_ao);
    atomic_fetch_add(&task->rays_shadow, rays_shadow);
}

void srv__compose(srv_loop *loop, uint32_t viewer)
{
    pthread_once(&tone_lut_once, tone_lut_init);
    compose_task task = {.loop = loop, .viewer = viewer};
    atomic_init(&task.missing, 0);
    atomic_init(&task.rays_ao, 0);
    atomic_init(&task.rays_shadow, 0);
    uint32_t rows = (loop->viewers[viewer].frame.height + SRV_TILE - 1) / SRV_TILE;
    srv_pool_run(loop->pool, rows, compose_rows, &task);
    loop->stats->pixels_missing += atomic_load(&task.missing);
    loop->stats->rays[SCENE_FX_AO] += atomic_load(&task.rays_ao);
    loop->stats->rays[SCENE_FX_SHADOW] += atomic_load(&task.rays_shadow);
}
