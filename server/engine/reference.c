/* The reference renderer: compose's shading per pixel with converged samples and no cache (reference.h).
 *
 * An image is rendered in the engine's 16 x 16 tiles on the engine's thread pool: per tile the engine's own
 * primary rays (srv__visibility_tile: the same packets, so the same triangle and barycentrics at every
 * pixel), then per visible pixel the point compose would build (position, normal, the normal turned to the
 * viewer, the footprint's differentials, the filtered albedo) and, twice with independent random numbers,
 * each running effect's reference term combined with compose's formula. Per-pixel outputs only; the image's
 * sums (noise, mean) are taken afterwards in pixel order, so the thread split cannot change a bit. */
#include "reference.h"

#include "engine_internal.h"

#include <float.h>
#include <math.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

struct srv_ref {
    srv_ref_desc desc;
    const fx_effect *effects[SRV_MAX_EFFECTS];
    bool runs[SRV_MAX_EFFECTS]; /* on and has a reference term */
    fx_context fx;
    srv_pool *pool;
    uint32_t stride;          /* lights per pixel in the per-thread scratch (at least 1) */
    float *thread_visibility; /* per thread: 2 halves x stride light visibilities */
    float *thread_unshadowed; /* per thread: stride x 3, the lights' terms before shadowing */
    /* Per-pixel working buffers of the current image, grown as needed. */
    size_t capacity; /* pixels */
    uint32_t *tri;
    float *bary_u, *bary_v, *depth, *footprint;
    float *noise; /* per pixel: squared half differences of radiance (summed over channels),
                                   AO and shadow */
};

/* One image being rendered. */
typedef struct ref_task {
    srv_ref *ref;
    srv_camera_frame frame;
    uint32_t frame_number;
    uint32_t tiles_x;
    const srv_ref_image *out;
    atomic_uint_fast64_t rays[SRV_MAX_EFFECTS];
    atomic_uint_fast64_t pixels_done;
    uint64_t pixels_total;
    srv_ref_progress progress;
    void *user;
} ref_task;

/* The splitmix64 finaliser: every input bit affects every output bit. */
static uint64_t ref_mix64(uint64_t x)
{
    x ^= x >> 30;
    x *= 0xbf58476d1ce4e5b9ull;
    x ^= x >> 27;
    x *= 0x94d049bb133111ebull;
    x ^= x >> 31;
    return x;
}

/* The id that seeds every random number of one half of one pixel of one frame (with ctx.seed inside the
 * effects' own hashes): independent for every (frame, pixel, half). */
static uint64_t ref_stream(uint32_t frame, size_t pixel, uint32_t half)
{
    uint64_t h = ref_mix64(((uint64_t)frame << 32 | half) ^ 0x7265666572656e63ull); /* "referenc" */
    return ref_mix64(h ^ (uint64_t)pixel);
}

/* min(x, FLT_MAX): infinity saturates (compose's rule: extreme intensities never overflow to infinity). */
static inline float saturate_max(float x)
{
    return x > FLT_MAX ? FLT_MAX : x;
}

fxc_result srv_ref_create(const srv_ref_desc *desc, srv_ref **out, char *err, size_t err_cap)
{
    *out = NULL;
    if (!desc || !desc->s || !desc->rt) {
        snprintf(err, err_cap, "reference: a scene and its Embree scene are required");
        return FXC_ERR_INVALID;
    }
    const fx_effect *const *list = desc->effects;
    uint32_t count = desc->effect_count;
    if (!list)
        list = fx_registry(&count);
    if (count == 0 || count > SRV_MAX_EFFECTS) {
        snprintf(err, err_cap, "reference: %u effects (1..%d)", count, SRV_MAX_EFFECTS);
        return FXC_ERR_EFFECTS;
    }
    srv_ref *ref = calloc(1, sizeof *ref);
    if (!ref) {
        snprintf(err, err_cap, "reference: out of memory");
        return FXC_ERR_NOMEM;
    }
    ref->desc = *desc;
    ref->desc.effects = list;
    ref->desc.effect_count = count;
    for (uint32_t e = 0; e < count; e++) {
        const fx_effect *fx = list[e];
        ref->effects[e] = fx;
        bool shades = fx && (fx->shade || fx->eval);
        if (!desc->effect_on[e] || !shades) {
            ref->desc.samples[e] = 0;
            continue; /* off, or shades nothing itself (the triangle lookup) */
        }
        if (!fx->reference) {
            snprintf(err, err_cap, "reference: effect %s has no reference estimator",
                     fx->name ? fx->name : "?");
            srv_ref_free(ref);
            return FXC_ERR_EFFECTS;
        }
        uint32_t samples = desc->samples[e] ? desc->samples[e] : fx->reference_samples;
        uint32_t granule = fx->reference_granule ? fx->reference_granule : 1;
        if (samples == 0 || samples % (2 * granule) != 0) {
            snprintf(err, err_cap,
                     "reference: effect %s: %u %s per pixel do not split into two halves of whole "
                     "sets of %u",
                     fx->name, samples, fx->reference_unit ? fx->reference_unit : "samples", granule);
            srv_ref_free(ref);
            return FXC_ERR_INVALID;
        }
        ref->desc.samples[e] = samples;
        ref->runs[e] = true;
    }
    const scene *s = desc->s;
    if (!(s->ao_radius > 0)) {
        snprintf(err, err_cap, "reference: the scene's AO radius must be > 0");
        srv_ref_free(ref);
        return FXC_ERR_INVALID;
    }
    ref->fx = (fx_context){.s = s,
                           .rt = desc->rt,
                           .seed = desc->seed,
                           .ao_radius = s->ao_radius,
                           .reference_bounces = desc->max_bounces};
    ref->pool = srv_pool_create(desc->threads);
    if (!ref->pool) {
        snprintf(err, err_cap, "reference: cannot start threads");
        srv_ref_free(ref);
        return FXC_ERR_THREADS;
    }
    ref->stride = s->light_count ? s->light_count : 1;
    size_t threads = srv_pool_threads(ref->pool);
    if (ref->stride > SIZE_MAX / sizeof(float) / 3 / threads ||
        !(ref->thread_visibility = malloc(threads * 2 * ref->stride * sizeof(float))) ||
        !(ref->thread_unshadowed = malloc(threads * 3 * ref->stride * sizeof(float)))) {
        snprintf(err, err_cap, "reference: out of memory");
        srv_ref_free(ref);
        return FXC_ERR_NOMEM;
    }
    *out = ref;
    return FXC_OK;
}

static void free_buffers(srv_ref *ref)
{
    free(ref->tri);
    free(ref->bary_u);
    free(ref->bary_v);
    free(ref->depth);
    free(ref->footprint);
    free(ref->noise);
    ref->tri = NULL;
    ref->bary_u = ref->bary_v = ref->depth = ref->footprint = ref->noise = NULL;
    ref->capacity = 0;
}

void srv_ref_free(srv_ref *ref)
{
    if (!ref)
        return;
    free_buffers(ref);
    free(ref->thread_visibility);
    free(ref->thread_unshadowed);
    srv_pool_free(ref->pool);
    free(ref);
}

const srv_ref_desc *srv_ref_desc_of(const srv_ref *ref)
{
    return &ref->desc;
}

/* Makes room for `pixels` pixels of working buffers. */
static bool reserve(srv_ref *ref, size_t pixels)
{
    if (pixels <= ref->capacity)
        return true;
    free_buffers(ref);
    ref->tri = malloc(pixels * sizeof *ref->tri);
    ref->bary_u = malloc(pixels * sizeof(float));
    ref->bary_v = malloc(pixels * sizeof(float));
    ref->depth = malloc(pixels * sizeof(float));
    ref->footprint = malloc(pixels * sizeof(float));
    ref->noise = malloc(pixels * 3 * sizeof(float));
    if (!ref->tri || !ref->bary_u || !ref->bary_v || !ref->depth || !ref->footprint || !ref->noise) {
        free_buffers(ref);
        return false;
    }
    ref->capacity = pixels;
    return true;
}

/* Compose's bracket for one half: the lights' unshadowed terms times their visibility, the sky times its
 * visibility, the indirect light; each saturating, never infinite. */
static void bracket(const scene *s, const float (*unshadowed)[3], const float *visibility,
                    float sky_visibility, const float indirect[3], float out[3])
{
    float irradiance[3] = {0, 0, 0};
    for (uint32_t l = 0; l < s->light_count; l++)
        for (int k = 0; k < 3; k++)
            irradiance[k] += unshadowed[l][k] * visibility[l];
    for (int k = 0; k < 3; k++) {
        float sky = s->sky_color[k] * s->sky_intensity;
        out[k] = saturate_max(saturate_max(irradiance[k]) + saturate_max(sky * sky_visibility) +
                              saturate_max(indirect[k]));
    }
}

/* One visible pixel: both halves, their mean, the AO and shadow terms. */
static void shade_pixel(ref_task *task, uint32_t thread_index, uint32_t x, uint32_t y,
                        uint64_t rays[SRV_MAX_EFFECTS])
{
    srv_ref *ref = task->ref;
    const scene *s = ref->desc.s;
    const srv_camera_frame *f = &task->frame;
    const srv_ref_image *out = task->out;
    size_t p = (size_t)y * f->width + x;
    uint32_t tri = ref->tri[p];
    float *noise = ref->noise + 3 * p;
    float *rad = out->radiance + 3 * p;
    if (tri == SRV_MISS) { /* compose: the sky's radiance, exactly, in both halves */
        for (int k = 0; k < 3; k++) {
            rad[k] = s->sky_color[k] * s->sky_intensity;
            for (int h = 0; h < 2; h++)
                if (out->half[h])
                    out->half[h][3 * p + k] = rad[k];
        }
        if (out->ao)
            out->ao[p] = 1.0f;
        if (out->shadow)
            out->shadow[p] = 1.0f;
        noise[0] = noise[1] = noise[2] = 0.0f;
        return;
    }
    /* The point as compose builds it (gather_run): position from the barycentrics, the triangle's normal,
     * turned to the side the ray comes from, the footprint's differentials, the albedo over the footprint. */
    fx_point pt;
    memset(&pt, 0, sizeof pt);
    float u = ref->bary_u[p], v = ref->bary_v[p];
    srv__hit_point(s, tri, u, v, pt.position, pt.normal);
    const float scale_x = 2.0f * f->tan_half_x / (float)f->width,
                scale_y = 2.0f * f->tan_half_y / (float)f->height;
    float sx = ((float)x + 0.5f) * scale_x - f->tan_half_x, sy = f->tan_half_y - ((float)y + 0.5f) * scale_y,
          dir[3];
    for (int k = 0; k < 3; k++)
        dir[k] = f->forward[k] + sx * f->right[k] + sy * f->up[k];
    float facing = pt.normal[0] * dir[0] + pt.normal[1] * dir[1] + pt.normal[2] * dir[2];
    for (int k = 0; k < 3; k++)
        pt.view_normal[k] = facing > 0 ? -pt.normal[k] : pt.normal[k];
    srv_camera_ray(f, (float)x + 0.5f, (float)y + 0.5f, dir);
    srv__pixel_differentials(f, dir, ref->depth[p], pt.normal, pt.dpdx, pt.dpdy);
    pt.triangle = tri;
    pt.u = u;
    pt.v = v;
    float albedo[3];
    scene_albedo_filtered(s, tri, u, v, ref->footprint[p] - log2f(s->texel_density), albedo);

    /* The lights' terms without shadow, at the pixel centre (compose's). */
    float(*unshadowed)[3] = (float(*)[3])(ref->thread_unshadowed + (size_t)thread_index * 3 * ref->stride);
    for (uint32_t l = 0; l < s->light_count; l++) {
        const scene_light *light = &s->lights[l];
        float ldir[3], dist;
        fx_light_direction(light, pt.position, ldir, &dist);
        float cosine =
            pt.view_normal[0] * ldir[0] + pt.view_normal[1] * ldir[1] + pt.view_normal[2] * ldir[2];
        float falloff = light->type == SCENE_LIGHT_POINT ? fx_point_falloff(dist) : 1.0f;
        float scale = fminf(light->intensity * cosine * falloff, FLT_MAX); /* x a black channel: 0, not NaN */
        for (int k = 0; k < 3; k++)
            unshadowed[l][k] = cosine > 0 ? fminf(scale * light->color[k], FLT_MAX) : 0.0f;
    }

    float half_rad[2][3], half_ao[2], half_shadow[2];
    for (uint32_t h = 0; h < 2; h++) {
        float *visibility = ref->thread_visibility + ((size_t)thread_index * 2 + h) * ref->stride;
        for (uint32_t l = 0; l < ref->stride; l++)
            visibility[l] = 1.0f;
        float sky_visibility = 1.0f, indirect[3] = {0, 0, 0}, sky_open = -1.0f;
        fx_shade_point sp = {.light_visibility = visibility,
                             .sky_visibility = &sky_visibility,
                             .indirect = indirect,
                             .sky_open = &sky_open};
        pt.pixel_id = ref_stream(task->frame_number, p, h);
        for (uint32_t e = 0; e < ref->desc.effect_count; e++)
            if (ref->runs[e])
                rays[e] += ref->effects[e]->reference(&ref->fx, &pt, ref->desc.samples[e] / 2, &sp);
        float irr[3];
        bracket(s, (const float(*)[3])unshadowed, visibility, sky_visibility, indirect, irr);
        for (int k = 0; k < 3; k++) {
            float value = albedo[k] * irr[k];
            half_rad[h][k] = value <= FLT_MAX ? value : (value > 0 ? FLT_MAX : 0.0f);
        }
        if (s->emissive) /* a front face's own emission, as compose adds it */
            scene_emission_add(s, tri, pt.view_normal, half_rad[h]);
        half_ao[h] = sky_open >= 0 ? sky_open : sky_visibility;
        half_shadow[h] = s->light_count ? visibility[0] : 1.0f;
    }
    double d2 =
        0; /* in double: halves near FLT_MAX square far past a float (noise inf, then unwritable JSON) */
    for (int k = 0; k < 3; k++) {
        rad[k] = 0.5f * half_rad[0][k] + 0.5f * half_rad[1][k];
        double d = (double)half_rad[0][k] - half_rad[1][k];
        d2 += d * d;
        for (int h = 0; h < 2; h++)
            if (out->half[h])
                out->half[h][3 * p + k] = half_rad[h][k];
    }
    noise[0] = d2 <= FLT_MAX ? (float)d2 : FLT_MAX; /* saturated: a lower bound, never infinite */
    noise[1] = (half_ao[0] - half_ao[1]) * (half_ao[0] - half_ao[1]);
    noise[2] = (half_shadow[0] - half_shadow[1]) * (half_shadow[0] - half_shadow[1]);
    if (out->ao)
        out->ao[p] = 0.5f * half_ao[0] + 0.5f * half_ao[1];
    if (out->shadow)
        out->shadow[p] = 0.5f * half_shadow[0] + 0.5f * half_shadow[1];
}

/* One 16 x 16 tile: primary rays, then every pixel. */
static void ref_tile(void *user, uint32_t task_index, uint32_t thread_index)
{
    ref_task *task = user;
    srv_ref *ref = task->ref;
    const srv_camera_frame *f = &task->frame;
    uint32_t tx0 = (task_index % task->tiles_x) * SRV_TILE, ty0 = (task_index / task->tiles_x) * SRV_TILE;
    uint32_t tx1 = tx0 + SRV_TILE < f->width ? tx0 + SRV_TILE : f->width;
    uint32_t ty1 = ty0 + SRV_TILE < f->height ? ty0 + SRV_TILE : f->height;
    srv__visibility_tile(ref->desc.s, ref->desc.rt, f, tx0, ty0, ref->tri, ref->bary_u, ref->bary_v,
                         ref->depth, ref->footprint, NULL);
    uint64_t rays[SRV_MAX_EFFECTS] = {0};
    for (uint32_t y = ty0; y < ty1; y++)
        for (uint32_t x = tx0; x < tx1; x++) {
            shade_pixel(task, thread_index, x, y, rays);
            if (task->out->srgb) {
                size_t p = (size_t)y * f->width + x;
                for (int k = 0; k < 3; k++)
                    task->out->srgb[3 * p + k] = srv__tone_map(task->out->radiance[3 * p + k]);
            }
        }
    for (uint32_t e = 0; e < SRV_MAX_EFFECTS; e++)
        if (rays[e])
            atomic_fetch_add(&task->rays[e], rays[e]);
    uint64_t done = atomic_fetch_add(&task->pixels_done, (uint64_t)(tx1 - tx0) * (ty1 - ty0)) +
                    (uint64_t)(tx1 - tx0) * (ty1 - ty0);
    if (task->progress && thread_index == 0) /* the pool's thread 0 is the caller */
        task->progress(task->user, done, task->pixels_total);
}

fxc_result srv_ref_render(srv_ref *ref, const srv_camera *camera, uint32_t width, uint32_t height,
                          uint32_t frame, const srv_ref_image *out, srv_ref_stats *stats,
                          srv_ref_progress progress, void *user)
{
    if (!out || !out->radiance || width < 1 || height < 1 || width > SRV_MAX_SIDE || height > SRV_MAX_SIDE)
        return FXC_ERR_INVALID;
    double start = srv__now_ms();
    ref_task *task = calloc(1, sizeof *task);
    if (!task)
        return FXC_ERR_NOMEM;
    if (!srv_camera_setup(camera, width, height, &task->frame)) {
        free(task);
        return FXC_ERR_CAMERA;
    }
    size_t pixels = (size_t)width * height;
    if (!reserve(ref, pixels)) {
        free(task);
        return FXC_ERR_NOMEM;
    }
    task->ref = ref;
    task->frame_number = frame;
    task->out = out;
    task->tiles_x = (width + SRV_TILE - 1) / SRV_TILE;
    task->pixels_total = pixels;
    task->progress = progress;
    task->user = user;
    for (uint32_t e = 0; e < SRV_MAX_EFFECTS; e++)
        atomic_init(&task->rays[e], 0);
    atomic_init(&task->pixels_done, 0);
    uint32_t tiles = task->tiles_x * ((height + SRV_TILE - 1) / SRV_TILE);
    srv_pool_run(ref->pool, tiles, ref_tile, task);
    if (progress)
        progress(user, pixels, pixels);

    /* The image's figures, in pixel order (the same sums for any thread split). */
    srv_ref_stats st;
    memset(&st, 0, sizeof st);
    double noise_all = 0, ao = 0, shadow = 0, sum[3] = {0, 0, 0};
    for (size_t p = 0; p < pixels; p++) {
        noise_all += ref->noise[3 * p];
        ao += ref->noise[3 * p + 1];
        shadow += ref->noise[3 * p + 2];
        st.pixels_visible += ref->tri[p] != SRV_MISS;
        for (int k = 0; k < 3; k++)
            sum[k] += out->radiance[3 * p + k];
    }
    st.pixels = pixels;
    st.primary_rays = pixels;
    st.rays_total = pixels;
    for (uint32_t e = 0; e < SRV_MAX_EFFECTS; e++) {
        st.rays[e] = atomic_load(&task->rays[e]);
        st.rays_total += st.rays[e];
    }
    /* Sky pixels add nothing to the sums, so the visible pixels' figure only changes the count. */
    st.noise_rmse = 0.5 * sqrt(noise_all / (3.0 * (double)pixels));
    st.noise_rmse_visible =
        st.pixels_visible ? 0.5 * sqrt(noise_all / (3.0 * (double)st.pixels_visible)) : 0.0;
    st.noise_ao = 0.5 * sqrt(ao / (double)pixels);
    st.noise_shadow = 0.5 * sqrt(shadow / (double)pixels);
    for (int k = 0; k < 3; k++)
        st.mean_radiance[k] = sum[k] / (double)pixels;
    st.render_ms = srv__now_ms() - start;
    if (stats)
        *stats = st;
    free(task);
    return FXC_OK;
}
