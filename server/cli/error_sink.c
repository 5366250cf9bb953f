/* The error accumulator and the reference cache of `fxcache report` (error_sink.h). */
#include "error_sink.h"

#include "image.h"

#include <errno.h>
#include <jansson.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <time.h>

/* ---- measures ------------------------------------------------------------------------------------------ */

double srv_err_mse(const float *a, const float *b, size_t count)
{
    if (count == 0)
        return 0;
    double sum = 0;
    for (size_t i = 0; i < count; i++) {
        double d = (double)a[i] - (double)b[i];
        sum += d * d;
    }
    return sum / (double)count;
}

double srv_err_rmse(const float *a, const float *b, size_t count)
{
    return sqrt(srv_err_mse(a, b, count));
}

double srv_err_psnr(double rmse)
{
    if (isnan(rmse))
        return NAN; /* no image compared: no error, so no PSNR either (not the infinity of an exact match) */
    return rmse > 0 ? 20.0 * log10(1.0 / rmse) : INFINITY;
}

double srv_err_cpu_ms(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
    return (double)ts.tv_sec * 1e3 + (double)ts.tv_nsec * 1e-6;
}

/* ---- heat maps ----------------------------------------------------------------------------------------- */

int srv_err_heatmap(const char *path, const float *a, const float *b, uint32_t width, uint32_t height,
                    float max, char *msg, size_t msg_cap)
{
    size_t n = (size_t)width * height;
    uint8_t *rgb = malloc(n > 0 ? n * 3 : 1);
    if (!rgb) {
        snprintf(msg, msg_cap, "out of memory for the heat map %s", path);
        return -1;
    }
    float scale = max > 0 ? 1.0f / max : 10.0f;
    for (size_t p = 0; p < n; p++) {
        float e = (fabsf(a[3 * p] - b[3 * p]) + fabsf(a[3 * p + 1] - b[3 * p + 1]) +
                   fabsf(a[3 * p + 2] - b[3 * p + 2])) /
                  3.0f * scale;
        e = e > 1.0f ? 1.0f : (e > 0 ? e : 0.0f); /* NaN reads as 0 */
        /* Black -> red (first third) -> yellow (second) -> white (last). */
        float r = fminf(1.0f, 3.0f * e), g = fminf(1.0f, fmaxf(0.0f, 3.0f * e - 1.0f)),
              bl = fminf(1.0f, fmaxf(0.0f, 3.0f * e - 2.0f));
        rgb[3 * p] = (uint8_t)lrintf(r * 255.0f);
        rgb[3 * p + 1] = (uint8_t)lrintf(g * 255.0f);
        rgb[3 * p + 2] = (uint8_t)lrintf(bl * 255.0f);
    }
    int rc = scene_image_write_u8(path, width, height, 3, rgb, msg, msg_cap);
    free(rgb);
    return rc;
}

/* ---- the reference cache ------------------------------------------------------------------------------- */

struct srv_refcache {
    srv_ref *ref;
    char dir[900];
    char *settings;
    srv_refcache_entry *entries;
    size_t count, capacity;
    uint32_t rendered, read;
    double render_ms;
};

static void entry_free(srv_refcache_entry *e)
{
    free(e->radiance);
    free(e->ao);
    free(e->shadow);
    memset(e, 0, sizeof *e);
}

srv_refcache *srv_refcache_create(srv_ref *ref, const char *dir, const char *settings, char *err,
                                  size_t err_cap)
{
    if (mkdir(dir, 0755) != 0 && errno != EEXIST) {
        snprintf(err, err_cap, "cannot create folder %s: %s", dir, strerror(errno));
        return NULL;
    }
    srv_refcache *cache = calloc(1, sizeof *cache);
    if (!cache || !(cache->settings = strdup(settings ? settings : ""))) {
        free(cache);
        snprintf(err, err_cap, "out of memory");
        return NULL;
    }
    cache->ref = ref;
    snprintf(cache->dir, sizeof cache->dir, "%s", dir);
    return cache;
}

void srv_refcache_free(srv_refcache *cache)
{
    if (!cache)
        return;
    for (size_t i = 0; i < cache->count; i++)
        entry_free(&cache->entries[i]);
    free(cache->entries);
    free(cache->settings);
    free(cache);
}

void srv_refcache_counts(const srv_refcache *cache, uint32_t *rendered, uint32_t *read, double *render_ms)
{
    if (rendered)
        *rendered = cache->rendered;
    if (read)
        *read = cache->read;
    if (render_ms)
        *render_ms = cache->render_ms;
}

uint64_t srv_fnv1a(uint64_t h, const void *data, size_t n)
{
    const unsigned char *p = data;
    for (size_t i = 0; i < n; i++)
        h = (h ^ p[i]) * 0x100000001b3ull;
    return h;
}

uint64_t srv_refcache_key(const srv_refcache *cache, const srv_camera *c, uint32_t width, uint32_t height)
{
    /* %a prints every float exactly, so equal keys mean bit-equal cameras (up to -0). */
    char text[512];
    snprintf(text, sizeof text, "%a %a %a|%a %a %a|%a %a %a|%a|%ux%u|", (double)c->position[0],
             (double)c->position[1], (double)c->position[2], (double)c->target[0], (double)c->target[1],
             (double)c->target[2], (double)c->up[0], (double)c->up[1], (double)c->up[2], (double)c->fov_deg,
             width, height);
    uint64_t h = srv_fnv1a(SRV_FNV1A_START, text, strlen(text));
    return srv_fnv1a(h, cache->settings, strlen(cache->settings));
}

/* Reads one float image of the expected size into a malloc'd array of `channels` per pixel. */
static float *read_image(const char *path, uint32_t width, uint32_t height, uint32_t channels)
{
    uint32_t w = 0, h = 0;
    float *rgb = NULL;
    char msg[512];
    if (scene_image_read_rgb(path, &w, &h, &rgb, msg, sizeof msg) != 0)
        return NULL;
    if (msg[0] || w != width || h != height) { /* a damaged reference is a miss: rendered again */
        free(rgb);
        return NULL;
    }
    if (channels == 3)
        return rgb;
    size_t n = (size_t)w * h;
    float *one = malloc(n * sizeof(float));
    if (one)
        for (size_t i = 0; i < n; i++)
            one[i] = rgb[3 * i];
    free(rgb);
    return one;
}

/* Loads an entry written earlier (its .json present and matching); false if anything is missing. */
static bool entry_load(srv_refcache_entry *e)
{
    char path[1100];
    snprintf(path, sizeof path, "%s.json", e->path);
    json_error_t jerr;
    json_t *record = json_load_file(path, 0, &jerr);
    if (!record)
        return false;
    bool ok = (uint32_t)json_integer_value(json_object_get(record, "width")) == e->width &&
              (uint32_t)json_integer_value(json_object_get(record, "height")) == e->height;
    e->noise_rmse = json_real_value(json_object_get(record, "noise_rmse"));
    json_decref(record);
    if (!ok)
        return false;
    snprintf(path, sizeof path, "%s.exr", e->path);
    e->radiance = read_image(path, e->width, e->height, 3);
    snprintf(path, sizeof path, "%s_ao.exr", e->path);
    e->ao = read_image(path, e->width, e->height, 1);
    snprintf(path, sizeof path, "%s_shadow.exr", e->path);
    e->shadow = read_image(path, e->width, e->height, 1);
    return e->radiance && e->ao && e->shadow;
}

/* Renders an entry and writes it (images first, the record last). */
static bool entry_render(srv_refcache *cache, srv_refcache_entry *e, const srv_camera *camera, char *err,
                         size_t err_cap)
{
    size_t n = (size_t)e->width * e->height;
    e->radiance = malloc(n * 3 * sizeof(float));
    e->ao = malloc(n * sizeof(float));
    e->shadow = malloc(n * sizeof(float));
    uint8_t *srgb = malloc(n * 3);
    if (!e->radiance || !e->ao || !e->shadow || !srgb) {
        free(srgb);
        snprintf(err, err_cap, "out of memory for a %ux%u reference image", e->width, e->height);
        return false;
    }
    srv_ref_image out = {.radiance = e->radiance, .ao = e->ao, .shadow = e->shadow, .srgb = srgb};
    srv_ref_stats st;
    /* The frame number only seeds the noise: a camera's key gives it, so a reference is the same whichever
     * frame asked for it first. */
    fxc_result r = srv_ref_render(cache->ref, camera, e->width, e->height, (uint32_t)(e->key >> 32), &out,
                                  &st, NULL, NULL);
    if (r != FXC_OK) {
        free(srgb);
        snprintf(err, err_cap, "reference image %s: %s", e->path, fxc_strerror(r));
        return false;
    }
    e->noise_rmse = st.noise_rmse;
    e->render_ms = st.render_ms;
    char path[1100], msg[512];
    bool written = true;
    snprintf(path, sizeof path, "%s.exr", e->path);
    written =
        written && scene_image_write_f32(path, e->width, e->height, 3, e->radiance, msg, sizeof msg) == 0;
    snprintf(path, sizeof path, "%s_ao.exr", e->path);
    written = written && scene_image_write_f32(path, e->width, e->height, 1, e->ao, msg, sizeof msg) == 0;
    snprintf(path, sizeof path, "%s_shadow.exr", e->path);
    written = written && scene_image_write_f32(path, e->width, e->height, 1, e->shadow, msg, sizeof msg) == 0;
    snprintf(path, sizeof path, "%s.png", e->path);
    written = written && scene_image_write_u8(path, e->width, e->height, 3, srgb, msg, sizeof msg) == 0;
    free(srgb);
    if (!written) {
        snprintf(err, err_cap, "%s", msg);
        return false;
    }
    json_t *record = json_pack(
        "{s:I,s:I,s:[f,f,f],s:[f,f,f],s:[f,f,f],s:f,s:f,s:f,s:I,s:s}", "width", (json_int_t)e->width,
        "height", (json_int_t)e->height, "position", (double)camera->position[0], (double)camera->position[1],
        (double)camera->position[2], "target", (double)camera->target[0], (double)camera->target[1],
        (double)camera->target[2], "up", (double)camera->up[0], (double)camera->up[1], (double)camera->up[2],
        "fov_deg", (double)camera->fov_deg, "noise_rmse", st.noise_rmse, "render_ms", st.render_ms, "rays",
        (json_int_t)st.rays_total, "settings", cache->settings);
    snprintf(path, sizeof path, "%s.json", e->path);
    char tmp[1120];
    snprintf(tmp, sizeof tmp, "%s.tmp", path);
    bool ok = record && json_dump_file(record, tmp, JSON_INDENT(2) | JSON_PRESERVE_ORDER) == 0 &&
              rename(tmp, path) == 0;
    json_decref(record);
    if (!ok) {
        snprintf(err, err_cap, "cannot write %s: %s", path, strerror(errno));
        return false;
    }
    return true;
}

const srv_refcache_entry *srv_refcache_get(srv_refcache *cache, const srv_camera *camera, uint32_t width,
                                           uint32_t height, bool *rendered, char *err, size_t err_cap)
{
    if (rendered)
        *rendered = false;
    uint64_t key = srv_refcache_key(cache, camera, width, height);
    for (size_t i = 0; i < cache->count; i++)
        if (cache->entries[i].key == key && cache->entries[i].width == width &&
            cache->entries[i].height == height)
            return &cache->entries[i];
    if (cache->count == cache->capacity) {
        size_t cap = cache->capacity ? cache->capacity * 2 : 64;
        srv_refcache_entry *grown =
            cap <= SIZE_MAX / sizeof *grown ? realloc(cache->entries, cap * sizeof *grown) : NULL;
        if (!grown) {
            snprintf(err, err_cap, "out of memory");
            return NULL;
        }
        cache->entries = grown;
        cache->capacity = cap;
    }
    srv_refcache_entry *e = &cache->entries[cache->count];
    memset(e, 0, sizeof *e);
    e->key = key;
    e->width = width;
    e->height = height;
    snprintf(e->path, sizeof e->path, "%s/%016llx", cache->dir, (unsigned long long)key);
    if (entry_load(e)) {
        cache->read++;
    } else {
        entry_free(e);
        e->key = key;
        e->width = width;
        e->height = height;
        snprintf(e->path, sizeof e->path, "%s/%016llx", cache->dir, (unsigned long long)key);
        if (!entry_render(cache, e, camera, err, err_cap)) {
            entry_free(e);
            return NULL;
        }
        cache->rendered++;
        cache->render_ms += e->render_ms;
        if (rendered)
            *rendered = true;
    }
    cache->count++;
    return e;
}

/* ---- the sink ------------------------------------------------------------------------------------------ */

void srv_err_sink_init(srv_err_sink *sink, const srv_err_sink_desc *desc)
{
    memset(sink, 0, sizeof *sink);
    sink->desc = *desc;
    if (!(sink->desc.heatmap_max > 0))
        sink->desc.heatmap_max = 0.1f;
}

static bool frame_compared(const srv_err_sink_desc *d, uint32_t frame)
{
    return frame == d->last_frame || (d->every && frame % d->every == 0);
}

static int err_viewer_frame(void *user, const srv_viewer_frame *vf)
{
    srv_err_sink *sink = user;
    const srv_err_sink_desc *d = &sink->desc;
    uint32_t frame = sink->frame;
    if (!frame_compared(d, frame))
        return 0;
    double cpu_start = srv_err_cpu_ms();
    char err[512];
    const srv_refcache_entry *ref =
        srv_refcache_get(d->refs, &vf->camera, vf->width, vf->height, NULL, err, sizeof err);
    if (!ref) {
        if (!sink->totals.error[0])
            snprintf(sink->totals.error, sizeof sink->totals.error, "%s", err);
        sink->sink_cpu_ms += srv_err_cpu_ms() - cpu_start;
        return -1;
    }
    size_t n = (size_t)vf->width * vf->height;
    srv_err_image image = {.frame = frame,
                           .viewer = vf->name,
                           .steady = frame >= d->warmup,
                           .rmse_shadow = NAN,
                           .rmse_ao = NAN,
                           .ref_noise = ref->noise_rmse};
    double mse = srv_err_mse(vf->radiance, ref->radiance, 3 * n);
    image.rmse = sqrt(mse);
    image.psnr_db = srv_err_psnr(image.rmse);
    double mse_shadow = 0, mse_ao = 0;
    if (d->compare_shadow && vf->views[SRV_VIEW_SHADOW]) {
        mse_shadow = srv_err_mse(vf->views[SRV_VIEW_SHADOW], ref->shadow, n);
        image.rmse_shadow = sqrt(mse_shadow);
    }
    if (d->compare_ao && vf->views[SRV_VIEW_AO]) {
        mse_ao = srv_err_mse(vf->views[SRV_VIEW_AO], ref->ao, n);
        image.rmse_ao = sqrt(mse_ao);
    }
    srv_err_totals *t = &sink->totals;
    t->images_all++;
    if (image.steady) {
        t->images++;
        t->mse_sum += mse;
        t->mse_shadow_sum += mse_shadow;
        t->mse_ao_sum += mse_ao;
        t->noise2_sum += ref->noise_rmse * ref->noise_rmse;
    }
    int rc = 0;
    if (d->heatmap_path && d->heatmap_viewer && frame == d->last_frame &&
        strcmp(vf->name, d->heatmap_viewer) == 0) {
        char msg[512];
        if (srv_err_heatmap(d->heatmap_path, vf->radiance, ref->radiance, vf->width, vf->height,
                            d->heatmap_max, msg, sizeof msg) != 0) {
            if (!t->error[0])
                snprintf(t->error, sizeof t->error, "%s", msg);
            rc = -1;
        }
    }
    if (d->on_image)
        d->on_image(d->user, &image);
    sink->sink_cpu_ms += srv_err_cpu_ms() - cpu_start;
    return rc;
}

static int err_frame_done(void *user, const srv_frame_stats *st)
{
    srv_err_sink *sink = user;
    if (sink->frame < sink->desc.warmup)
        return 0;
    srv_err_totals *t = &sink->totals;
    t->frames++;
    t->ms_sum += st->frame_ms - st->time_ms[SRV_STAGE_SINKS];
    t->viewer_frames += st->viewer_count;
    for (uint32_t e = 0; e < SRV_MAX_EFFECTS; e++)
        t->effect_rays += st->rays[e];
    return 0;
}

srv_sink srv_err_sink_sink(srv_err_sink *sink)
{
    return (srv_sink){.viewer_frame = err_viewer_frame, .frame_done = err_frame_done, .user = sink};
}

void srv_err_sink_add_cpu(srv_err_sink *sink, uint32_t frame, double frame_cpu_ms)
{
    if (frame >= sink->desc.warmup)
        sink->totals.cpu_ms_sum += frame_cpu_ms - sink->sink_cpu_ms;
    sink->sink_cpu_ms = 0;
}
