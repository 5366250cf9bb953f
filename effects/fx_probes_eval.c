/* The no-cache baseline's indirect light at a pixel (fx_probe_eval_point, effects.h): one irradiance estimate
 * per pixel per frame with the probes' ray count, cosine-weighted, each front-face hit shaded by its direct
 * light through the shadow-ray queue the probe update uses (fx_probes_shading.h), bouncing once. */
#include "fx_probes_internal.h"
#include "fx_probes_shading.h"
#include "scene_inline.h"

static _Thread_local hit_shading thread_eval_shading; /* within one call */

void fx_probe_eval_point(const fx_context *ctx, const float pos[3], const float normal[3], uint64_t pixel_id,
                         float out_rgb[3], uint64_t *rays)
{
    const scene *s = ctx->s;
    const uint32_t n_rays = probe_ray_count(ctx);
    float sky[3];
    for (int k = 0; k < 3; k++)
        sky[k] = s->sky_color[k] * s->sky_intensity;
    fx__surface_map map;
    float point[3], origin[3], tangent[3], bitangent[3];
    fx__locate_point(ctx, pos, normal, 0.0f, &map, point); /* off a crease's wall */
    scene_offset_ray_origin(point, normal, s->ray_offset_scale, origin);
    fx__onb(normal, tangent, bitangent);
    uint64_t direction_hash = fx__hash(ctx->seed, pixel_id, 0, 0, FX_STREAM_PROBE_EVAL);
    struct RTCIntersectContext context;
    rtcInitIntersectContext(&context);
    RTCScene rtc = (RTCScene)scene_rt_handle(ctx->rt);
    _Alignas(64) struct RTCRayHit hits[PROBE_CHUNK];
    hit_shading *hs = &thread_eval_shading;
    double sum[3] = {0, 0, 0};
    uint64_t traced = 0;
    for (uint32_t first = 0; first < n_rays; first += PROBE_CHUNK) {
        uint32_t n = n_rays - first < PROBE_CHUNK ? n_rays - first : PROBE_CHUNK;
        for (uint32_t r = 0; r < n; r++) {
            float xi[2], dir[3];
            fx__sobol_2d(first + r, direction_hash, xi);
            fx__cosine_direction(normal, tangent, bitangent, xi, dir);
            fx__set_ray(&hits[r].ray, origin, dir, INFINITY, r);
            hits[r].hit.geomID = RTC_INVALID_GEOMETRY_ID;
            hits[r].hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
        }
        if (ctx->observe_hits)
            ctx->observe_hits(ctx->observe_user, hits, n);
        rtcIntersect1M(rtc, &context, hits, n, sizeof(struct RTCRayHit));
        traced += n;
        hs->count = 0;
        float hit_pos[PROBE_CHUNK][3];
        bool front[PROBE_CHUNK];
        for (uint32_t r = 0; r < n; r++) {
            hs->direct[r][0] = hs->direct[r][1] = hs->direct[r][2] = 0;
            front[r] = false;
            if (hits[r].hit.geomID == RTC_INVALID_GEOMETRY_ID || hits[r].hit.primID >= s->triangle_count) {
                for (int k = 0; k < 3; k++)
                    sum[k] += sky[k];
                continue;
            }
            const float *n_hit = s->tri_normal + 3 * (size_t)hits[r].hit.primID;
            float dir[3] = {hits[r].ray.dir_x, hits[r].ray.dir_y, hits[r].ray.dir_z};
            if (!(fx__dot(dir, n_hit) < 0))
                continue; /* back face: no light, as for the probes */
            front[r] = true;
            float p[3];
            for (int k = 0; k < 3; k++)
                p[k] = origin[k] + hits[r].ray.tfar * dir[k];
            scene_offset_ray_origin(p, n_hit, s->ray_offset_scale, hit_pos[r]);
            traced += queue_shadow_rays(ctx, NULL, hs, r, hit_pos[r], n_hit);
        }
        shadow_flush(ctx, hs);
        for (uint32_t r = 0; r < n; r++) {
            if (!front[r])
                continue;
            float albedo[3], emitted[3] = {0, 0, 0};
            uint32_t tri = hits[r].hit.primID;
            scene_albedo_filtered(s, tri, hits[r].hit.u, hits[r].hit.v,
                                  log2f(fmaxf(hits[r].ray.tfar * 0.3f, 1e-30f)), albedo);
            if (s->emissive) /* a front face's own emission */
                scene_emission_add(s, tri, s->tri_normal + 3 * (size_t)tri, emitted);
            for (int k = 0; k < 3; k++)
                sum[k] += (double)albedo[k] * hs->direct[r][k] + (double)emitted[k];
        }
    }
    /* Cosine-weighted sampling: E = pi x the mean radiance. */
    for (int k = 0; k < 3; k++)
        out_rgb[k] = (float)fmin(FX_PROBE_PI * sum[k] / (double)n_rays, FLT_MAX);
    if (rays)
        *rays = traced;
}
