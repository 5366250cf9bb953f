/* bench_probes: what the world-space cache and the probe effect cost and share (issue "the world-space cache
 * and probe-based indirect light").
 *
 *   rays:     probe update rays per second against raw Embree over the same rays in the same run: one loop
 *             with probes alone on one thread; per frame after the warm-up, the effects stage (probe updates
 *             and commits) is timed, every ray stream it traced is recorded (fx_context observe hooks), and
 *             the recorded streams are then traced again with rtcIntersect1M / rtcOccluded1M, alternating
 *             update and replay frame by frame. Figure: raw time / update time per frame (1 = as fast as
 *             bare Embree over the same rays); median and spread. The recording (copying every stream,
 *             inside the update) is timed too: the ratio is printed with it, as before, and without it
 *             (the update's own work: the update time less the time spent in the recording hooks).
 *             With --apis, each measured frame's rays are also traced through other Embree calls (the same
 *             streams with the context flag COHERENT; packets of 8 and 16 rays of one stream in the order of
 *             their directions), APIs in a rotating order, Embree's time only, and every result compared
 *             with the streams' (hits: geomID, primID, t, u, v bit for bit; occlusion: occluded or not).
 *   viewers:  1, 4 and 8 viewers (--camera, default group) with everything the scene needs: probes requested
 *             and unique per frame, the world-space cache's bytes and bricks, time per stage (medians); then
 *             two loops, with and without the viewers' local lookup tables, frames alternating: requests and
 *             compose medians of each.
 *   overhead: what indirect light adds to the per-pixel stages, against visibility: two loops on one thread,
 *             with and without probes (everything else the same), frames alternating; per frame
 *             ((requests + compose) with - (requests + compose) without) / visibility (mean of the two
 *             loops' visibility times for that frame); median and spread.
 *   memory:   bytes per probe (payload, and all of the cache per resident probe) beside RTXGI's layout.
 *   image:    (not in all) the radiance of the measured frames with and without probes, to --out FILE, for
 *             comparing the indirect term of two builds (tools: bench/compare_radiance.py).
 *
 * Usage: bench_probes [--scene PATH (default ../shared/scenes/sponza/sponza.3ds)] [--res WxH (640x360)]
 *                     [--warmup N (10)] [--frames N (20)] [--camera GEN (group)]
 *                     [--part rays|viewers|overhead|memory|image|all] [--out FILE (image)] [--apis (rays)]
 *                     [--indirect-block 1|2|4 (the loops with probes in overhead and image; default the
 *                     engine's)]
 */
#include "bench_engine.h"
#include "scene.h"

#include <embree3/rtcore.h>

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

static void print_row(const char *what, const double *values, int n)
{
    printf("| %s | %.3f | %.3f | %.3f |\n", what, bench_quantile(values, n, 0.5),
           bench_quantile(values, n, 0.1), bench_quantile(values, n, 0.9));
}

typedef struct options {
    const char *path;
    uint32_t w, h, warmup, frames;
    srv_camgen_kind gen;
    const char *part;
    const char *out; /* --part image: where the radiance goes */
    uint64_t seed;   /* --part image: the loops' seed (1 unless --seed; another seed measures the noise) */
    uint32_t indirect_block; /* the loops' srv_loop_desc.indirect_block (0: the default) */
    bool apis;               /* --part rays: also replay through the other Embree calls (replay_api) */
} options;

static int32_t effect_index(const char *name)
{
    uint32_t count = 0;
    const fx_effect *const *registry = fx_registry(&count);
    return fx_find(registry, count, name);
}

/* ---- rays: the update against raw Embree over the same rays ------------------------------------------- */

enum { MAX_CAPTURED = 1 << 24 };

/* Ray streams as an update traced them, in order: intersection streams (RTCRayHit) and occlusion streams
 * (RTCRay), each with its size and kind. */
typedef struct captured {
    struct RTCRayHit *hits;
    struct RTCRay *rays;
    uint32_t *sizes;
    uint8_t *is_hit;
    size_t hit_count, ray_count, streams, hit_cap, ray_cap, stream_cap, kind_cap;
    bool truncated;
    double record_ms; /* time spent in capture_stream this frame (inside the timed update) */
} captured;

static bool grow(void **array, size_t *cap, size_t need, size_t size, size_t align)
{
    if (need <= *cap)
        return true;
    size_t n = *cap ? *cap : 4096;
    while (n < need)
        n *= 2;
    void *p = align ? aligned_alloc(align, n * size) : malloc(n * size);
    if (!p)
        return false;
    if (*array)
        memcpy(p, *array, *cap * size);
    free(*array);
    *array = p;
    *cap = n;
    return true;
}

static void capture_stream_untimed(captured *c, const void *rays, uint32_t count, bool hit);

static void capture_stream(captured *c, const void *rays, uint32_t count, bool hit)
{
    double t = bench_now_ms();
    capture_stream_untimed(c, rays, count, hit);
    c->record_ms += bench_now_ms() - t;
}

static void capture_stream_untimed(captured *c, const void *rays, uint32_t count, bool hit)
{
    if (c->truncated || c->hit_count + c->ray_count + count > MAX_CAPTURED ||
        !grow((void **)&c->sizes, &c->stream_cap, c->streams + 1, sizeof *c->sizes, 0) ||
        !grow((void **)&c->is_hit, &c->kind_cap, c->streams + 1, 1, 0)) {
        c->truncated = true;
        return;
    }
    if (hit) {
        if (!grow((void **)&c->hits, &c->hit_cap, c->hit_count + count, sizeof *c->hits, 64)) {
            c->truncated = true;
            return;
        }
        memcpy(c->hits + c->hit_count, rays, count * sizeof *c->hits);
        c->hit_count += count;
    } else {
        if (!grow((void **)&c->rays, &c->ray_cap, c->ray_count + count, sizeof *c->rays, 64)) {
            c->truncated = true;
            return;
        }
        memcpy(c->rays + c->ray_count, rays, count * sizeof *c->rays);
        c->ray_count += count;
    }
    c->sizes[c->streams] = count;
    c->is_hit[c->streams] = hit;
    c->streams++;
}

static void observe_occlusion(void *user, const void *rays, uint32_t count)
{
    capture_stream(user, rays, count, false);
}

static void observe_hits(void *user, const void *rays, uint32_t count)
{
    capture_stream(user, rays, count, true);
}

/* Traces the captured streams again (on copies, so tfar and hits start as they did); returns ms. */
static double replay(scene_rt *rt, const captured *c, struct RTCRayHit *hit_work, struct RTCRay *ray_work)
{
    memcpy(hit_work, c->hits, c->hit_count * sizeof *hit_work);
    memcpy(ray_work, c->rays, c->ray_count * sizeof *ray_work);
    struct RTCIntersectContext context;
    rtcInitIntersectContext(&context);
    double t = bench_now_ms();
    size_t h = 0, r = 0;
    for (size_t k = 0; k < c->streams; k++) {
        if (c->is_hit[k]) {
            rtcIntersect1M(scene_rt_handle(rt), &context, hit_work + h, c->sizes[k], sizeof *hit_work);
            h += c->sizes[k];
        } else {
            rtcOccluded1M(scene_rt_handle(rt), &context, ray_work + r, c->sizes[k], sizeof *ray_work);
            r += c->sizes[k];
        }
    }
    return bench_now_ms() - t;
}

/* ---- rays: the same streams through other Embree calls (the update's choice of API) ------------------- */

/* How a replay hands the captured rays to Embree: streams as the update does (rtcIntersect1M /
 * rtcOccluded1M), the same streams with the context flag COHERENT, or packets of 8 or 16 rays of one stream
 * (an intersection stream is one chunk of one probe's rays: one origin) in the order of their directions
 * (octahedral position, Morton order: rays of one packet point the same way). */
typedef enum replay_api { API_STREAM, API_STREAM_COHERENT, API_PACKET8, API_PACKET16, API_COUNT } replay_api;
static const char *const api_names[API_COUNT] = {"rtcIntersect1M / rtcOccluded1M streams (the update's)",
                                                 "the same streams, RTC_INTERSECT_CONTEXT_FLAG_COHERENT",
                                                 "rtcIntersect8 / rtcOccluded8, rays sorted by direction",
                                                 "rtcIntersect16 / rtcOccluded16, rays sorted by direction"};

/* A direction's place on the octahedral map (8 bits per axis), Morton-interleaved: nearby directions, nearby
 * keys; the octants are the map's triangles. */
static uint32_t direction_key(float x, float y, float z)
{
    float l1 = fabsf(x) + fabsf(y) + fabsf(z);
    float u = l1 > 0 ? x / l1 : 0, v = l1 > 0 ? y / l1 : 0;
    if (z < 0) {
        float fu = (1.0f - fabsf(v)) * (u >= 0 ? 1.0f : -1.0f),
              fv = (1.0f - fabsf(u)) * (v >= 0 ? 1.0f : -1.0f);
        u = fu, v = fv;
    }
    uint32_t qu = (uint32_t)fminf(fmaxf((u + 1.0f) * 128.0f, 0.0f), 255.0f);
    uint32_t qv = (uint32_t)fminf(fmaxf((v + 1.0f) * 128.0f, 0.0f), 255.0f);
    uint32_t key = 0;
    for (int b = 0; b < 8; b++)
        key |= ((qu >> b & 1u) << (2 * b)) | ((qv >> b & 1u) << (2 * b + 1));
    return key;
}

typedef struct keyed {
    uint32_t key, index;
} keyed;

static int keyed_compare(const void *a, const void *b)
{
    const keyed *x = a, *y = b;
    if (x->key != y->key)
        return x->key < y->key ? -1 : 1;
    return x->index < y->index ? -1 : (x->index > y->index);
}

/* The order of a stream's rays for packets: by direction key, ties in stream order. */
static void packet_order(const struct RTCRay *const *ray, uint32_t n, uint32_t *order)
{
    keyed k[4096];
    for (uint32_t i = 0; i < n; i++)
        k[i] = (keyed){direction_key(ray[i]->dir_x, ray[i]->dir_y, ray[i]->dir_z), i};
    qsort(k, n, sizeof *k, keyed_compare);
    for (uint32_t i = 0; i < n; i++)
        order[i] = k[i].index;
}

/* Packet copies of the captured rays: SoA packets of `width` lanes (8 or 16), each stream's rays in its
 * packet order, the last packet of a stream with invalid lanes. Built once per frame, outside the timing. */
static size_t packet_bytes(uint32_t width, bool hit)
{
    return hit ? (width == 16 ? sizeof(struct RTCRayHit16) : sizeof(struct RTCRayHit8))
               : (width == 16 ? sizeof(struct RTCRay16) : sizeof(struct RTCRay8));
}

/* Writes ray r (AoS) into lane l of the SoA packet at p (RTCRayN's field order, each field width floats). */
static void packet_put(uint8_t *p, uint32_t width, uint32_t l, const struct RTCRay *r)
{
    float *f = (float *)p;
    const float v[8] = {r->org_x, r->org_y, r->org_z, r->tnear, r->dir_x, r->dir_y, r->dir_z, r->time};
    for (int k = 0; k < 8; k++)
        f[k * width + l] = v[k];
    f[8 * width + l] = r->tfar;
    uint32_t *u = (uint32_t *)p;
    u[9 * width + l] = r->mask, u[10 * width + l] = r->id, u[11 * width + l] = r->flags;
}

typedef struct packet_set {
    uint8_t *data; /* packets, 64-byte aligned, hit and occlusion packets in stream order */
    size_t bytes, cap;
    uint32_t *lane_ray; /* per packet lane: the captured ray (index into hits or rays), UINT32_MAX: none */
    size_t lanes, lane_cap;
    uint8_t *is_hit; /* per packet */
    size_t packets, packet_cap;
    int *valid; /* per packet lane */
    size_t valid_cap;
} packet_set;

static void packet_set_build(packet_set *ps, const captured *c, uint32_t width)
{
    ps->bytes = ps->lanes = ps->packets = 0;
    size_t h = 0, r = 0;
    const struct RTCRay *ptr[4096];
    uint32_t order[4096];
    for (size_t k = 0; k < c->streams; k++) {
        bool hit = c->is_hit[k];
        uint32_t n = c->sizes[k];
        if (n > 4096) {
            fprintf(stderr, "bench_probes: a stream of %u rays\n", n);
            exit(1);
        }
        for (uint32_t i = 0; i < n; i++)
            ptr[i] = hit ? &c->hits[h + i].ray : &c->rays[r + i];
        packet_order(ptr, n, order);
        size_t pb = packet_bytes(width, hit);
        for (uint32_t first = 0; first < n; first += width) {
            if (!grow((void **)&ps->data, &ps->cap, ps->bytes + pb, 1, 64) ||
                !grow((void **)&ps->lane_ray, &ps->lane_cap, ps->lanes + width, sizeof *ps->lane_ray, 0) ||
                !grow((void **)&ps->valid, &ps->valid_cap, ps->lanes + width, sizeof *ps->valid, 64) ||
                !grow((void **)&ps->is_hit, &ps->packet_cap, ps->packets + 1, 1, 0)) {
                fprintf(stderr, "bench_probes: out of memory\n");
                exit(1);
            }
            uint8_t *p = ps->data + ps->bytes;
            memset(p, 0, pb);
            for (uint32_t l = 0; l < width; l++) {
                bool on = first + l < n;
                ps->valid[ps->lanes + l] = on ? -1 : 0;
                ps->lane_ray[ps->lanes + l] = on ? (uint32_t)((hit ? h : r) + order[first + l]) : UINT32_MAX;
                if (on)
                    packet_put(p, width, l, ptr[order[first + l]]);
                if (hit) { /* geomID and instID[0] invalid, as the update sets them */
                    uint32_t *u =
                        (uint32_t *)(p + (width == 16 ? sizeof(struct RTCRay16) : sizeof(struct RTCRay8)));
                    u[6 * width + l] = RTC_INVALID_GEOMETRY_ID, u[7 * width + l] = RTC_INVALID_GEOMETRY_ID;
                }
            }
            ps->is_hit[ps->packets++] = hit;
            ps->bytes += pb;
            ps->lanes += width;
        }
        if (hit)
            h += n;
        else
            r += n;
    }
}

/* Traces the captured rays through `api`; the results (hits, tfar) land in hit_work / ray_work in captured
 * order (packets: scattered back after the timing). Returns ms of the Embree calls alone; *ms_hit: of the
 * intersections. */
static double replay_api_run(scene_rt *rt, const captured *c, replay_api api, packet_set *ps,
                             uint8_t *packet_work, struct RTCRayHit *hit_work, struct RTCRay *ray_work,
                             double *ms_hit)
{
    struct RTCIntersectContext context;
    rtcInitIntersectContext(&context);
    RTCScene rtc = scene_rt_handle(rt);
    double hit_ms = 0, all_ms = 0;
    if (api == API_STREAM || api == API_STREAM_COHERENT) {
        if (api == API_STREAM_COHERENT)
            context.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
        memcpy(hit_work, c->hits, c->hit_count * sizeof *hit_work);
        memcpy(ray_work, c->rays, c->ray_count * sizeof *ray_work);
        size_t h = 0, r = 0;
        for (size_t k = 0; k < c->streams; k++) {
            double t = bench_now_ms();
            if (c->is_hit[k]) {
                rtcIntersect1M(rtc, &context, hit_work + h, c->sizes[k], sizeof *hit_work);
                h += c->sizes[k];
                hit_ms += bench_now_ms() - t;
            } else {
                rtcOccluded1M(rtc, &context, ray_work + r, c->sizes[k], sizeof *ray_work);
                r += c->sizes[k];
            }
            all_ms += bench_now_ms() - t;
        }
        *ms_hit = hit_ms;
        return all_ms;
    }
    uint32_t width = api == API_PACKET16 ? 16 : 8;
    memcpy(packet_work, ps->data, ps->bytes);
    size_t off = 0, lane = 0;
    for (size_t k = 0; k < ps->packets; k++) {
        bool hit = ps->is_hit[k];
        uint8_t *p = packet_work + off;
        const int *valid = ps->valid + lane;
        double t = bench_now_ms();
        if (hit) {
            if (width == 16)
                rtcIntersect16(valid, rtc, &context, (struct RTCRayHit16 *)p);
            else
                rtcIntersect8(valid, rtc, &context, (struct RTCRayHit8 *)p);
            hit_ms += bench_now_ms() - t;
        } else {
            if (width == 16)
                rtcOccluded16(valid, rtc, &context, (struct RTCRay16 *)p);
            else
                rtcOccluded8(valid, rtc, &context, (struct RTCRay8 *)p);
        }
        all_ms += bench_now_ms() - t;
        /* back into captured order: tfar, and for hits u, v, Ng, primID, geomID */
        const float *f = (const float *)p;
        size_t ray_bytes = width == 16 ? sizeof(struct RTCRay16) : sizeof(struct RTCRay8);
        const float *hf = (const float *)(p + ray_bytes);
        const uint32_t *hu = (const uint32_t *)(p + ray_bytes);
        for (uint32_t l = 0; l < width; l++) {
            uint32_t i = ps->lane_ray[lane + l];
            if (i == UINT32_MAX)
                continue;
            if (hit) {
                struct RTCRayHit *o = &hit_work[i];
                o->ray = c->hits[i].ray;
                o->ray.tfar = f[8 * width + l];
                o->hit.Ng_x = hf[0 * width + l], o->hit.Ng_y = hf[1 * width + l],
                o->hit.Ng_z = hf[2 * width + l];
                o->hit.u = hf[3 * width + l], o->hit.v = hf[4 * width + l];
                o->hit.primID = hu[5 * width + l], o->hit.geomID = hu[6 * width + l];
            } else {
                ray_work[i] = c->rays[i];
                ray_work[i].tfar = f[8 * width + l];
            }
        }
        off += packet_bytes(width, hit);
        lane += width;
    }
    *ms_hit = hit_ms;
    return all_ms;
}

/* Rays whose results differ between two replays (hits: geomID, primID, t, u, v bit for bit; occlusion: the
 * tfar that says occluded or not). */
static size_t replay_differences(const captured *c, const struct RTCRayHit *ha, const struct RTCRay *ra,
                                 const struct RTCRayHit *hb, const struct RTCRay *rb)
{
    size_t d = 0;
    for (size_t i = 0; i < c->hit_count; i++) {
        const struct RTCRayHit *x = &ha[i], *y = &hb[i];
        bool same = x->hit.geomID == y->hit.geomID &&
                    (x->hit.geomID == RTC_INVALID_GEOMETRY_ID ||
                     (x->hit.primID == y->hit.primID && !memcmp(&x->ray.tfar, &y->ray.tfar, 4) &&
                      !memcmp(&x->hit.u, &y->hit.u, 4) && !memcmp(&x->hit.v, &y->hit.v, 4)));
        d += !same;
    }
    for (size_t i = 0; i < c->ray_count; i++)
        d += (ra[i].tfar == -INFINITY) != (rb[i].tfar == -INFINITY);
    return d;
}

/* The API comparison's state over the measured frames. */
typedef struct apis_state {
    packet_set sets[2]; /* 8 and 16 lanes */
    uint8_t *packet_work;
    size_t packet_work_cap;
    struct RTCRayHit *ref_hits, *hits;
    struct RTCRay *ref_rays, *rays;
    size_t ref_hit_cap, ref_ray_cap, hit_cap, ray_cap;
    double all[API_COUNT][BENCH_MAX_SAMPLES], hit[API_COUNT][BENCH_MAX_SAMPLES],
        occ[API_COUNT][BENCH_MAX_SAMPLES];
    double update_over[API_COUNT][BENCH_MAX_SAMPLES];
    double hit_ms[API_COUNT], occ_ms[API_COUNT]; /* this frame's */
    double hit_speedup[API_COUNT][BENCH_MAX_SAMPLES], occ_speedup[API_COUNT][BENCH_MAX_SAMPLES];
    size_t differences[API_COUNT], hit_rays, occ_rays;
} apis_state;

/* One measured frame: every API over the frame's captured rays, in a rotating order (frame f starts with
 * API f mod API_COUNT), each result compared with the streams' (API_STREAM, traced first, untimed). */
static void apis_frame(apis_state *a, scene_rt *rt, const captured *c, int n, uint32_t f, double update_ms,
                       double rays)
{
    if (!grow((void **)&a->ref_hits, &a->ref_hit_cap, c->hit_count + 1, sizeof *a->ref_hits, 64) ||
        !grow((void **)&a->hits, &a->hit_cap, c->hit_count + 1, sizeof *a->hits, 64) ||
        !grow((void **)&a->ref_rays, &a->ref_ray_cap, c->ray_count + 1, sizeof *a->ref_rays, 64) ||
        !grow((void **)&a->rays, &a->ray_cap, c->ray_count + 1, sizeof *a->rays, 64)) {
        fprintf(stderr, "bench_probes: out of memory\n");
        exit(1);
    }
    packet_set_build(&a->sets[0], c, 8);
    packet_set_build(&a->sets[1], c, 16);
    size_t most = a->sets[0].bytes > a->sets[1].bytes ? a->sets[0].bytes : a->sets[1].bytes;
    if (!grow((void **)&a->packet_work, &a->packet_work_cap, most + 1, 1, 64)) {
        fprintf(stderr, "bench_probes: out of memory\n");
        exit(1);
    }
    double hit_ms;
    replay_api_run(rt, c, API_STREAM, NULL, NULL, a->ref_hits, a->ref_rays, &hit_ms);
    for (int k = 0; k < API_COUNT; k++) {
        replay_api api = (replay_api)((f + (uint32_t)k) % API_COUNT);
        packet_set *ps = api == API_PACKET8 ? &a->sets[0] : api == API_PACKET16 ? &a->sets[1] : NULL;
        double all_ms = replay_api_run(rt, c, api, ps, a->packet_work, a->hits, a->rays, &hit_ms);
        a->all[api][n] = rays / all_ms / 1000.0;
        a->hit[api][n] = (double)c->hit_count / hit_ms / 1000.0;
        a->occ[api][n] = (double)c->ray_count / (all_ms - hit_ms) / 1000.0;
        a->update_over[api][n] = all_ms / update_ms;
        a->hit_ms[api] = hit_ms;
        a->occ_ms[api] = all_ms - hit_ms;
        a->differences[api] += replay_differences(c, a->ref_hits, a->ref_rays, a->hits, a->rays);
    }
    for (int k = 0; k < API_COUNT; k++) { /* per frame, the streams' time over this API's (> 1: faster) */
        a->hit_speedup[k][n] = a->hit_ms[API_STREAM] / a->hit_ms[k];
        a->occ_speedup[k][n] = a->occ_ms[API_STREAM] / a->occ_ms[k];
    }
    a->hit_rays += c->hit_count;
    a->occ_rays += c->ray_count;
}

static void apis_print(apis_state *a, int n)
{
    printf(
        "\nthe same rays through other Embree calls (Embree time only; packets: built before the timing, "
        "results scattered back after it), per frame, APIs in a rotating order (%zu intersection and %zu "
        "occlusion rays):\n\n| API | all Mrays/s | intersection Mrays/s | occlusion Mrays/s | speed against "
        "the streams in the same frame: intersection, occlusion (median, p10-p90) | update / raw through "
        "this API "
        "(its time / update time) | rays whose result differs from the streams' "
        "|\n|---|---|---|---|---|---|---|\n",
        a->hit_rays, a->occ_rays);
    for (int k = 0; k < API_COUNT; k++)
        printf("| %s | %.3f | %.3f | %.3f | %.3f (%.3f-%.3f), %.3f (%.3f-%.3f) | %.3f | %zu |\n",
               api_names[k], bench_quantile(a->all[k], n, 0.5), bench_quantile(a->hit[k], n, 0.5),
               bench_quantile(a->occ[k], n, 0.5), bench_quantile(a->hit_speedup[k], n, 0.5),
               bench_quantile(a->hit_speedup[k], n, 0.1), bench_quantile(a->hit_speedup[k], n, 0.9),
               bench_quantile(a->occ_speedup[k], n, 0.5), bench_quantile(a->occ_speedup[k], n, 0.1),
               bench_quantile(a->occ_speedup[k], n, 0.9), bench_quantile(a->update_over[k], n, 0.5),
               a->differences[k]);
    for (int k = 0; k < 2; k++) {
        free(a->sets[k].data), free(a->sets[k].lane_ray), free(a->sets[k].is_hit), free(a->sets[k].valid);
    }
    free(a->packet_work), free(a->ref_hits), free(a->hits), free(a->ref_rays), free(a->rays);
}

static void part_rays(const options *o, scene *s, scene_rt *rt)
{
    int32_t probes = effect_index("probes");
    srv_loop_desc d = {.s = s, .rt = rt, .threads = 1, .seed = 1};
    d.effect_on[probes] = true;
    srv_viewer_id id;
    srv_loop *loop = NULL;
    char err[256];
    if (srv_loop_create(&d, &loop, err, sizeof err) != FXC_OK ||
        srv_viewer_add(loop, &(srv_viewer_desc){.width = o->w, .height = o->h}, &id) != FXC_OK) {
        fprintf(stderr, "bench_probes: %s\n", err);
        exit(1);
    }
    captured c = {0};
    srv_loop_set_observer(loop, observe_occlusion, observe_hits, &c);
    double ratio[BENCH_MAX_SAMPLES], update_mrays[BENCH_MAX_SAMPLES], raw_mrays[BENCH_MAX_SAMPLES];
    double own_ratio[BENCH_MAX_SAMPLES], own_mrays[BENCH_MAX_SAMPLES], record_share[BENCH_MAX_SAMPLES];
    struct RTCRayHit *hit_work = NULL;
    struct RTCRay *ray_work = NULL;
    size_t hit_work_cap = 0, ray_work_cap = 0;
    uint64_t total_rays = 0;
    int n = 0;
    apis_state ac;
    memset(&ac, 0, sizeof ac);
    for (uint32_t f = 0; f < o->warmup + o->frames; f++) {
        c.hit_count = c.ray_count = c.streams = 0;
        c.truncated = false;
        c.record_ms = 0;
        srv_frame_stats st;
        bench_run_frame("bench_probes", loop, s, o->gen, &id, 1, f, &st);
        if (f < o->warmup || st.rays[probes] == 0)
            continue;
        if (c.truncated || c.hit_count + c.ray_count != st.rays[probes]) {
            fprintf(stderr, "bench_probes: frame %u: %zu rays recorded, %llu counted%s\n", f,
                    c.hit_count + c.ray_count, (unsigned long long)st.rays[probes],
                    c.truncated ? " (truncated)" : "");
            exit(1);
        }
        if (!grow((void **)&hit_work, &hit_work_cap, c.hit_count + 1, sizeof *hit_work, 64) ||
            !grow((void **)&ray_work, &ray_work_cap, c.ray_count + 1, sizeof *ray_work, 64)) {
            fprintf(stderr, "bench_probes: out of memory\n");
            exit(1);
        }
        double update_ms = st.time_ms[SRV_STAGE_EFFECTS];
        double raw_ms = replay(rt, &c, hit_work, ray_work);
        if (o->apis)
            apis_frame(&ac, rt, &c, n, f, update_ms, (double)st.rays[probes]);
        double rays = (double)st.rays[probes];
        total_rays += st.rays[probes];
        update_mrays[n] = rays / update_ms / 1000.0;
        raw_mrays[n] = rays / raw_ms / 1000.0;
        ratio[n] = raw_ms / update_ms;
        double own_ms = update_ms - c.record_ms;
        own_mrays[n] = rays / own_ms / 1000.0;
        own_ratio[n] = raw_ms / own_ms;
        record_share[n] = c.record_ms / update_ms;
        n++;
    }
    printf(
        "\nrays: probe updates on 1 thread against raw Embree over the same streams (%d frames, %llu rays, "
        "%.0f per frame)\n\n| figure | median | p10 | p90 |\n|---|---|---|---|\n",
        n, (unsigned long long)total_rays, n ? (double)total_rays / n : 0.0);
    if (n) {
        print_row("update Mrays/s (effects stage: gather, shading, commit)", update_mrays, n);
        print_row("raw rtcIntersect1M + rtcOccluded1M Mrays/s", raw_mrays, n);
        print_row("update / raw (raw time / update time)", ratio, n);
        print_row("recording's share of the update time", record_share, n);
        print_row("update without the recording Mrays/s", own_mrays, n);
        print_row("update without the recording / raw", own_ratio, n);
    }
    if (o->apis)
        apis_print(&ac, n);
    free(hit_work);
    free(ray_work);
    free(c.hits);
    free(c.rays);
    free(c.sizes);
    free(c.is_hit);
    srv_loop_free(loop);
}

/* ---- viewers: sharing, memory, stages; local tables on and off ----------------------------------------- */

static void part_viewers(const options *o, scene *s, scene_rt *rt)
{
    static const uint32_t counts[] = {1, 4, 8};
    printf("\nviewers (%s camera, everything the scene needs, all cores), per frame after the warm-up:\n\n"
           "| viewers | probes requested | unique | sharing | bricks | world-space MiB | visibility ms | "
           "requests ms "
           "| queues ms | effects ms | compose ms | frame ms "
           "|\n|---|---|---|---|---|---|---|---|---|---|---|---|\n",
           srv_camgen_name(o->gen));
    for (size_t c = 0; c < sizeof counts / sizeof counts[0]; c++) {
        uint32_t n = counts[c];
        srv_viewer_id ids[SRV_MAX_VIEWERS];
        srv_loop *loop = bench_make_loop_desc("bench_probes", (srv_loop_desc){.s = s, .rt = rt, .seed = 1},
                                              NULL, n, o->w, o->h, ids);
        double stage[SRV_STAGE_COUNT][BENCH_MAX_SAMPLES], frame[BENCH_MAX_SAMPLES];
        uint64_t requested = 0, unique = 0;
        srv_frame_stats st;
        for (uint32_t f = 0; f < o->warmup + o->frames; f++) {
            bench_run_frame("bench_probes", loop, s, o->gen, ids, n, f, &st);
            if (f < o->warmup)
                continue;
            for (int k = 0; k < SRV_STAGE_COUNT; k++)
                stage[k][f - o->warmup] = st.time_ms[k];
            frame[f - o->warmup] = st.frame_ms;
            requested += st.world.requested_cells;
            unique += st.world.unique_cells;
        }
        int m = (int)o->frames;
        printf("| %u | %.0f | %.0f | %.2f | %llu | %.1f | %.1f | %.1f | %.1f | %.1f | %.1f | %.1f |\n", n,
               (double)requested / m, (double)unique / m, unique ? (double)requested / (double)unique : 0.0,
               (unsigned long long)st.world.bricks_resident, st.world.bytes / 1048576.0,
               bench_quantile(stage[SRV_STAGE_VISIBILITY], m, 0.5),
               bench_quantile(stage[SRV_STAGE_REQUESTS], m, 0.5),
               bench_quantile(stage[SRV_STAGE_QUEUES], m, 0.5),
               bench_quantile(stage[SRV_STAGE_EFFECTS], m, 0.5),
               bench_quantile(stage[SRV_STAGE_COMPOSE], m, 0.5), bench_quantile(frame, m, 0.5));
        srv_loop_free(loop);
    }

    /* Local lookup tables on and off: same cameras, frames alternating between two loops. */
    uint32_t n = 4;
    srv_viewer_id on_ids[SRV_MAX_VIEWERS], off_ids[SRV_MAX_VIEWERS];
    srv_loop *on = bench_make_loop_desc("bench_probes", (srv_loop_desc){.s = s, .rt = rt, .seed = 1}, NULL, n,
                                        o->w, o->h, on_ids);
    srv_loop *off = bench_make_loop_desc("bench_probes",
                                         (srv_loop_desc){.s = s, .rt = rt, .seed = 1, .no_local_table = true},
                                         NULL, n, o->w, o->h, off_ids);
    double req_on[BENCH_MAX_SAMPLES], req_off[BENCH_MAX_SAMPLES], comp_on[BENCH_MAX_SAMPLES],
        comp_off[BENCH_MAX_SAMPLES], ratio[BENCH_MAX_SAMPLES], hit[BENCH_MAX_SAMPLES];
    for (uint32_t f = 0; f < o->warmup + o->frames; f++) {
        srv_frame_stats a, b;
        bench_run_frame("bench_probes", on, s, o->gen, on_ids, n, f, &a);
        bench_run_frame("bench_probes", off, s, o->gen, off_ids, n, f, &b);
        if (f < o->warmup)
            continue;
        int i = (int)(f - o->warmup);
        req_on[i] = a.time_ms[SRV_STAGE_REQUESTS];
        req_off[i] = b.time_ms[SRV_STAGE_REQUESTS];
        comp_on[i] = a.time_ms[SRV_STAGE_COMPOSE];
        comp_off[i] = b.time_ms[SRV_STAGE_COMPOSE];
        ratio[i] = comp_off[i] / comp_on[i];
        hit[i] = a.world.local_lookups ? (double)a.world.local_hits / (double)a.world.local_lookups : 0.0;
    }
    printf(
        "\nlocal lookup tables, %u viewers, frames alternating between a loop with them and one without:\n\n"
        "| figure | median | p10 | p90 |\n|---|---|---|---|\n",
        n);
    int m = (int)o->frames;
    print_row("requests ms, with", req_on, m);
    print_row("requests ms, without", req_off, m);
    print_row("compose ms, with", comp_on, m);
    print_row("compose ms, without", comp_off, m);
    print_row("compose without / with", ratio, m);
    print_row("local table hit rate", hit, m);
    srv_loop_free(on);
    srv_loop_free(off);
}

/* ---- overhead: the per-pixel stages with and without probes ------------------------------------------ */

static void part_overhead(const options *o, scene *s, scene_rt *rt)
{
    srv_viewer_id with_ids[1], without_ids[1];
    srv_loop *with = bench_make_loop_desc(
        "bench_probes",
        (srv_loop_desc){.s = s, .rt = rt, .seed = 1, .threads = 1, .indirect_block = o->indirect_block}, NULL,
        1, o->w, o->h, with_ids);
    srv_loop *without = bench_make_loop_desc(
        "bench_probes",
        (srv_loop_desc){.s = s, .rt = rt, .seed = 1, .threads = 1, .indirect_block = o->indirect_block},
        "probes", 1, o->w, o->h, without_ids);
    double added[BENCH_MAX_SAMPLES], req_added[BENCH_MAX_SAMPLES], comp_added[BENCH_MAX_SAMPLES];
    for (uint32_t f = 0; f < o->warmup + o->frames; f++) {
        srv_frame_stats a, b;
        bench_run_frame("bench_probes", with, s, o->gen, with_ids, 1, f, &a);
        bench_run_frame("bench_probes", without, s, o->gen, without_ids, 1, f, &b);
        if (f < o->warmup)
            continue;
        int i = (int)(f - o->warmup);
        double vis = 0.5 * (a.time_ms[SRV_STAGE_VISIBILITY] + b.time_ms[SRV_STAGE_VISIBILITY]);
        req_added[i] = (a.time_ms[SRV_STAGE_REQUESTS] - b.time_ms[SRV_STAGE_REQUESTS]) / vis;
        comp_added[i] = (a.time_ms[SRV_STAGE_COMPOSE] - b.time_ms[SRV_STAGE_COMPOSE]) / vis;
        added[i] = req_added[i] + comp_added[i];
    }
    printf(
        "\noverhead: 1 viewer (%s camera), 1 thread, frames alternating between a loop with probes and one "
        "without; what probes add, as a fraction of the frame's visibility time:\n\n"
        "| figure | median | p10 | p90 |\n|---|---|---|---|\n",
        srv_camgen_name(o->gen));
    int m = (int)o->frames;
    print_row("requests added / visibility", req_added, m);
    print_row("compose added / visibility", comp_added, m);
    print_row("(requests + compose) added / visibility", added, m);
    srv_loop_free(with);
    srv_loop_free(without);
}

/* ---- image: the radiance of one loop's frames, for comparing two builds ---------------------------------- */

/* One viewer on one thread with probes, and one without, the same frames: after the warm-up, each measured
 * frame's linear radiance of both is appended to o->out (floats, width x height x 3 per frame, with first,
 * then without). Two builds run on the same arguments give files whose difference is the change in the
 * indirect term times the albedo (everything else in the frame is deterministic and the same);
 * with - without says how much light the probes bring (their term minus the sky term they replace). */
static int part_image(const options *o, scene *s, scene_rt *rt)
{
    FILE *f = o->out ? fopen(o->out, "wb") : NULL;
    if (!f) {
        fprintf(stderr, "bench_probes: --part image needs --out FILE (writable)\n");
        return 1;
    }
    srv_viewer_id with_ids[1], without_ids[1];
    srv_loop *with = bench_make_loop_desc(
        "bench_probes",
        (srv_loop_desc){.s = s, .rt = rt, .seed = o->seed, .threads = 1, .indirect_block = o->indirect_block},
        NULL, 1, o->w, o->h, with_ids);
    srv_loop *without = bench_make_loop_desc(
        "bench_probes",
        (srv_loop_desc){.s = s, .rt = rt, .seed = o->seed, .threads = 1, .indirect_block = o->indirect_block},
        "probes", 1, o->w, o->h, without_ids);
    size_t n = (size_t)o->w * o->h * 3;
    for (uint32_t frame = 0; frame < o->warmup + o->frames; frame++) {
        srv_frame_stats a, b;
        bench_run_frame("bench_probes", with, s, o->gen, with_ids, 1, frame, &a);
        bench_run_frame("bench_probes", without, s, o->gen, without_ids, 1, frame, &b);
        if (frame < o->warmup)
            continue;
        const float *ra = srv_viewer_radiance(with, with_ids[0]),
                    *rb = srv_viewer_radiance(without, without_ids[0]);
        if (!ra || !rb || fwrite(ra, sizeof(float), n, f) != n || fwrite(rb, sizeof(float), n, f) != n) {
            fprintf(stderr, "bench_probes: cannot write %s\n", o->out);
            fclose(f);
            return 1;
        }
    }
    srv_loop_free(with);
    srv_loop_free(without);
    printf("\nimage: %u frames of %ux%u radiance (with probes, then without, float RGB) in %s\n", o->frames,
           o->w, o->h, o->out);
    return fclose(f) == 0 ? 0 : 1;
}

/* ---- memory ------------------------------------------------------------------------------------------- */

static void part_memory(const options *o, scene *s, scene_rt *rt)
{
    int32_t probes = effect_index("probes");
    uint32_t count = 0;
    const fx_effect *const *registry = fx_registry(&count);
    uint32_t payload = registry[probes]->texel_bytes(s);
    srv_viewer_id ids[8];
    srv_loop *loop = bench_make_loop_desc("bench_probes", (srv_loop_desc){.s = s, .rt = rt, .seed = 1}, NULL,
                                          8, o->w, o->h, ids);
    srv_frame_stats st;
    for (uint32_t f = 0; f < o->warmup + o->frames; f++)
        bench_run_frame("bench_probes", loop, s, o->gen, ids, 8, f, &st);
    srv_memory m;
    srv_loop_memory(loop, &m);
    /* RTXGI's layout: 8x8 irradiance texels plus a 1-texel border (10x10) in R10G10B10A2 (4 bytes), and 16x16
     * distance texels plus border (18x18) in RG16F (4 bytes); probe data (offsets, states) RGBA16F (8 bytes). */
    double rtxgi_per_probe = 10 * 10 * 4 + 18 * 18 * 4 + 8;
    printf("\nmemory after %u frames of 8 viewers:\n\n| figure | value |\n|---|---|\n",
           o->warmup + o->frames);
    printf("| payload bytes per probe (ours) | %u |\n", payload);
    printf("| world-space cache bytes per resident probe (table, metadata, lists, local tables) | %.0f |\n",
           st.world.bricks_resident ? (double)st.world.bytes / (double)st.world.bricks_resident : 0.0);
    printf("| resident probes | %llu |\n", (unsigned long long)st.world.bricks_resident);
    printf("| world-space cache MiB (pool reserved whole) | %.2f |\n", st.world.bytes / 1048576.0);
    printf("| probe pool reserved MiB / in use MiB | %.2f / %.2f |\n", m.pools_reserved[probes] / 1048576.0,
           m.pools_in_use[probes] / 1048576.0);
    printf("| RTXGI bytes per probe (10x10 x 4 + 18x18 x 4 + 8) | %.0f |\n", rtxgi_per_probe);
    printf("| RTXGI Sponza, 22x22x22 probes, MiB | %.2f |\n", 22.0 * 22 * 22 * rtxgi_per_probe / 1048576.0);
    srv_loop_free(loop);
}

int main(int argc, char **argv)
{
    options o = {.path = "../shared/scenes/sponza/sponza.3ds",
                 .w = 640,
                 .h = 360,
                 .warmup = 10,
                 .frames = 20,
                 .gen = SRV_CAMGEN_GROUP,
                 .part = "all",
                 .seed = 1};
    for (int i = 1; i < argc; i++) {
        const char *a = argv[i], *v = i + 1 < argc ? argv[i + 1] : NULL;
        if (!strcmp(a, "--scene") && v)
            o.path = v, i++;
        else if (!strcmp(a, "--res") && v && sscanf(v, "%ux%u", &o.w, &o.h) == 2)
            i++;
        else if (!strcmp(a, "--warmup") && v)
            o.warmup = (uint32_t)atoi(v), i++;
        else if (!strcmp(a, "--frames") && v)
            o.frames = (uint32_t)atoi(v), i++;
        else if (!strcmp(a, "--camera") && v && srv_camgen_parse(v, &o.gen))
            i++;
        else if (!strcmp(a, "--part") && v)
            o.part = v, i++;
        else if (!strcmp(a, "--out") && v)
            o.out = v, i++;
        else if (!strcmp(a, "--seed") && v)
            o.seed = strtoull(v, NULL, 10), i++;
        else if (!strcmp(a, "--apis"))
            o.apis = true;
        else if (!strcmp(a, "--indirect-block") && v)
            o.indirect_block = (uint32_t)atoi(v), i++;
        else {
            fprintf(stderr,
                    "usage: bench_probes [--scene PATH] [--res WxH] [--warmup N] [--frames N] [--camera GEN] "
                    "[--part rays|viewers|overhead|memory|image|all] [--out FILE (image)] [--seed N (image)] "
                    "[--indirect-block 1|2|4] [--apis (rays)]\n");
            return !strcmp(a, "-h") || !strcmp(a, "--help") ? 0 : 2;
        }
    }
    if (!o.w || !o.h || o.frames < 1 || o.frames > BENCH_MAX_SAMPLES) {
        fprintf(stderr, "bench_probes: bad --res or --frames (1..%d)\n", BENCH_MAX_SAMPLES);
        return 2;
    }
    if (strcmp(o.path, "default") && access(o.path, R_OK) != 0) {
        printf("%s not found: using the embedded default scene\n", o.path);
        o.path = "default";
    }
    scene_error err;
    scene *s = scene_load(o.path, NULL, &err);
    scene_rt *rt = s ? scene_rt_create(s, NULL, &err) : NULL;
    if (!rt) {
        fprintf(stderr, "bench_probes: %s\n", err.msg);
        return 1;
    }
    if (effect_index("probes") < 0) {
        fprintf(stderr, "bench_probes: no effect named probes is registered\n");
        return 1;
    }
    printf("scene %s (%u triangles), %ux%u per viewer, %u warm-up frames then %u measured\n", o.path,
           s->triangle_count, o.w, o.h, o.warmup, o.frames);
    bool all = !strcmp(o.part, "all");
    if (all || !strcmp(o.part, "rays"))
        part_rays(&o, s, rt);
    if (all || !strcmp(o.part, "overhead"))
        part_overhead(&o, s, rt);
    if (all || !strcmp(o.part, "viewers"))
        part_viewers(&o, s, rt);
    if (all || !strcmp(o.part, "memory"))
        part_memory(&o, s, rt);
    int status = !strcmp(o.part, "image") ? part_image(&o, s, rt) : 0;
    scene_rt_free(rt);
    scene_free(s);
    return status;
}
