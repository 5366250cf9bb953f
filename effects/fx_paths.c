/* The reference estimate of indirect diffuse light: path tracing, what the probes approximate (effects.h,
 * fx_indirect_reference_point). The reference renderer (server/engine/reference.c) calls it through the probe
 * effect's `reference` callback; nothing in the frame loop does.
 *
 * The quantity is the probes' E at a visible point: the cosine-weighted integral of the radiance arriving
 * there, E = pi x the mean radiance over cosine-weighted directions. The radiance a path brings back follows
 * the probe update's model of a hit, bounce after bounce:
 *   - a miss returns the sky's radiance;
 *   - a back face returns nothing (a probe counts it as the inside of a closed mesh);
 *   - a front face y returns Le(y) + albedo(y) x (direct(y) + E(y) / pi), Le(y) its material's emission,
 *     direct(y) the sum over lights of intensity x
 *     colour x cos (/ d^2 for point lights) where a shadow ray reaches the light (compose's formula at a
 *     point), and E(y) the same integral at y: no ambient occlusion at a hit, as the probes' hits have none.
 * With cosine-weighted directions and a Lambertian surface the weight of a vertex is its albedo, so the
 * throughput is the product of the albedos met; direct light is gathered at every vertex by next-event
 * estimation; the sky by the continuation ray that escapes. A separate sky ray (next-event estimation for
 * the sky) would sample the very same cosine-weighted distribution: it would cost one more ray per vertex
 * for a variance no lower (the escaping ray and the path it would otherwise continue are anticorrelated,
 * which a separate ray loses).
 *
 * Paths end by Russian roulette from the second vertex on (survival probability the throughput's largest
 * component, at most 0.95; a survivor's throughput is divided by it, so the estimate stays unbiased), at
 * ctx->reference_bounces vertices when that is set (a truncated series: tests and one-bounce comparisons),
 * and at FX_PATH_MAX_VERTICES (256) in any case: a path reaches it with probability below 0.95^254.
 *
 * Random numbers: the first direction of path i is point i of a 2D Owen-scrambled Sobol sequence scrambled by
 * hash(seed, stream) (the paths of a pixel are stratified over the hemisphere where it matters most); later
 * directions and the roulette are hashes of (seed, stream, path, vertex), so any thread split gives the same
 * result. Paths are traced as a wavefront of up to PATH_CHUNK: one rtcIntersect1M per vertex for the live
 * paths, their shadow rays in rtcOccluded1M streams of FX_RAY_BATCH. The caller must have called
 * scene_tracing_thread_init() in this thread. */
#include "fx_internal.h"

#include <float.h>
#include <string.h>

enum {
    PATH_CHUNK = 128,                 /* paths traced together (one intersection stream per vertex) */
    FX_STREAM_PATH_FIRST = 0x5046,    /* "PF": the first directions' scramble */
    FX_STREAM_PATH_BOUNCE = 0x5042,   /* "PB": later directions */
    FX_STREAM_PATH_ROULETTE = 0x5055, /* "PU": Russian roulette */
};

#define PATH_SURVIVAL_MAX 0.95f
#define PATH_PI           3.14159265358979323846

/* One live path: where its next ray leaves, which way, and what it carries. */
typedef struct path_state {
    float origin[3], dir[3];
    float throughput[3];
    uint32_t index; /* within the pixel's paths: seeds its random numbers */
} path_state;

/* The working memory of one call: per thread, off the (pool thread) stack, never allocated (as the probes'). */
typedef struct path_work {
    _Alignas(64) struct RTCRayHit hits[PATH_CHUNK];
    _Alignas(64) struct RTCRay shadow[FX_RAY_BATCH];
    float shadow_light[FX_RAY_BATCH][3]; /* what each shadow ray brings if it reaches its light */
    uint32_t shadow_count;
    path_state paths[PATH_CHUNK];
} path_work;

static _Thread_local path_work thread_path_work;

/* Traces the queued shadow rays and adds the light of those that reach their light. */
static void shadow_flush(const fx_context *ctx, path_work *w, double sum[3])
{
    fx__occluded(ctx, w->shadow, w->shadow_count);
    for (uint32_t r = 0; r < w->shadow_count; r++)
        if (w->shadow[r].tfar != -INFINITY)
            for (int k = 0; k < 3; k++)
                sum[k] += w->shadow_light[r][k];
    w->shadow_count = 0;
}

/* Next-event estimation at a front-face vertex (ray origin already offset, unit front normal): one shadow ray
 * per light that faces it, carrying throughput x compose's direct light. Returns the rays queued. */
static uint32_t queue_lights(const fx_context *ctx, path_work *w, double sum[3], const float origin[3],
                             const float normal[3], const float throughput[3])
{
    const scene *s = ctx->s;
    uint32_t queued = 0;
    for (uint32_t l = 0; l < s->light_count; l++) {
        const scene_light *light = &s->lights[l];
        float dir[3], distance, scale;
        if (!fx__light_arriving(light, origin, normal, dir, &distance, &scale))
            continue;
        if (w->shadow_count == FX_RAY_BATCH)
            shadow_flush(ctx, w, sum);
        uint32_t r = w->shadow_count++;
        fx__set_ray(&w->shadow[r], origin, dir, isinf(distance) ? INFINITY : distance * (1.0f - 1e-4f), r);
        for (int k = 0; k < 3; k++)
            w->shadow_light[r][k] = fminf(throughput[k] * fminf(scale * light->color[k], FLT_MAX), FLT_MAX);
        queued++;
    }
    return queued;
}

void fx_indirect_reference_point(const fx_context *ctx, const float pos[3], const float normal[3],
                                 uint32_t paths, uint64_t stream, float out_rgb[3], uint64_t *rays)
{
    const scene *s = ctx->s;
    float sky[3];
    for (int k = 0; k < 3; k++)
        sky[k] = s->sky_color[k] * s->sky_intensity;
    uint32_t max_vertices = ctx->reference_bounces && ctx->reference_bounces < FX_PATH_MAX_VERTICES
                                ? ctx->reference_bounces
                                : FX_PATH_MAX_VERTICES;
    fx__surface_map map;
    float point[3], origin[3], tangent[3], bitangent[3];
    fx__locate_point(ctx, pos, normal, 0.0f, &map, point); /* off a crease's wall, as the baseline */
    scene_offset_ray_origin(point, normal, s->ray_offset_scale, origin);
    fx__onb(normal, tangent, bitangent);
    uint64_t first_hash = fx__hash(ctx->seed, stream, 0, 0, FX_STREAM_PATH_FIRST);
    struct RTCIntersectContext context;
    rtcInitIntersectContext(&context);
    RTCScene rtc = (RTCScene)scene_rt_handle(ctx->rt);
    path_work *w = &thread_path_work;
    w->shadow_count = 0;
    double sum[3] = {0, 0, 0};
    uint64_t traced = 0;

    for (uint32_t first = 0; first < paths; first += PATH_CHUNK) {
        uint32_t live = paths - first < PATH_CHUNK ? paths - first : PATH_CHUNK;
        for (uint32_t i = 0; i < live; i++) {
            path_state *p = &w->paths[i];
            float xi[2];
            fx__sobol_2d(first + i, first_hash, xi);
            fx__cosine_direction(normal, tangent, bitangent, xi, p->dir);
            memcpy(p->origin, origin, sizeof p->origin);
            p->throughput[0] = p->throughput[1] = p->throughput[2] = 1.0f;
            p->index = first + i;
        }
        for (uint32_t vertex = 1; live > 0; vertex++) {
            for (uint32_t i = 0; i < live; i++) {
                struct RTCRayHit *rh = &w->hits[i];
                fx__set_ray(&rh->ray, w->paths[i].origin, w->paths[i].dir, INFINITY, i);
                rh->hit.geomID = RTC_INVALID_GEOMETRY_ID;
                rh->hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
            }
            if (ctx->observe_hits)
                ctx->observe_hits(ctx->observe_user, w->hits, live);
            rtcIntersect1M(rtc, &context, w->hits, live, sizeof(struct RTCRayHit));
            traced += live;
            uint32_t kept = 0; /* live paths are compacted in place, in order */
            for (uint32_t i = 0; i < live; i++) {
                const struct RTCRayHit *rh = &w->hits[i];
                path_state p = w->paths[i];
                if (rh->hit.geomID == RTC_INVALID_GEOMETRY_ID || rh->hit.primID >= s->triangle_count) {
                    for (int k = 0; k < 3; k++)
                        sum[k] += (double)p.throughput[k] * sky[k];
                    continue;
                }
                uint32_t tri = rh->hit.primID;
                const float *hit_normal = s->tri_normal + 3 * (size_t)tri;
                if (!(fx__dot(p.dir, hit_normal) < 0))
                    continue; /* a back face: dark, the path ends */
                float albedo[3], at[3];
                if (s->emissive) { /* the emission the path meets, weighted by what it carries so far */
                    float emitted[3] = {0, 0, 0};
                    scene_emission_add(s, tri, hit_normal, emitted);
                    for (int k = 0; k < 3; k++)
                        sum[k] += (double)p.throughput[k] * emitted[k];
                }
                scene_albedo(s, tri, rh->hit.u, rh->hit.v, albedo);
                for (int k = 0; k < 3; k++) {
                    p.throughput[k] *= albedo[k];
                    at[k] = p.origin[k] + rh->ray.tfar * p.dir[k];
                }
                scene_offset_ray_origin(at, hit_normal, s->ray_offset_scale, p.origin);
                traced += queue_lights(ctx, w, sum, p.origin, hit_normal, p.throughput);
                if (vertex >= max_vertices)
                    continue;
                if (vertex >= 2) {
                    float survive = fminf(fmaxf(p.throughput[0], fmaxf(p.throughput[1], p.throughput[2])),
                                          PATH_SURVIVAL_MAX);
                    uint64_t h = fx__hash(ctx->seed, stream, p.index, vertex, FX_STREAM_PATH_ROULETTE);
                    if (!(fx__unit_float((uint32_t)h) < survive))
                        continue;
                    for (int k = 0; k < 3; k++)
                        p.throughput[k] /= survive;
                }
                uint64_t h = fx__hash(ctx->seed, stream, p.index, vertex, FX_STREAM_PATH_BOUNCE);
                float xi[2] = {fx__unit_float((uint32_t)h), fx__unit_float((uint32_t)(h >> 32))}, t[3], b[3];
                fx__onb(hit_normal, t, b);
                fx__cosine_direction(hit_normal, t, b, xi, p.dir);
                w->paths[kept++] = p;
            }
            shadow_flush(ctx, w, sum);
            live = kept;
        }
    }
    /* Cosine-weighted directions: E = pi x the mean radiance. */
    for (int k = 0; k < 3; k++)
        out_rgb[k] = paths ? (float)fmin((double)PATH_PI * sum[k] / (double)paths, FLT_MAX) : 0.0f;
    if (rays)
        *rays = traced;
}
