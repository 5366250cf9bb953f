/* Stage 2, visibility: one primary ray per pixel through Embree's 16-wide packets (4 x 4 pixels), in
 * 16 x 16-pixel tiles spread over the thread pool. Per pixel it keeps the triangle, the barycentrics and
 * the footprint: the pixel's size on the surface from ray differentials (the neighbouring pixels' rays
 * intersected with the hit triangle's plane), in level-0 texels, as log2 - the level an unbiased effect
 * reads. */
#include "engine_internal.h"

#include <embree3/rtcore.h>

#include <math.h>
#include <string.h>

void srv__hit_point(const scene *s, uint32_t tri, float u, float v, float pos[3], float normal[3])
{
    const uint32_t *idx = s->indices + 3 * (size_t)tri;
    const float *a = s->positions + 3 * (size_t)idx[0];
    const float *b = s->positions + 3 * (size_t)idx[1];
    const float *c = s->positions + 3 * (size_t)idx[2];
    float w = 1.0f - u - v;
    for (int k = 0; k < 3; k++) {
        pos[k] = w * a[k] + u * b[k] + v * c[k];
        normal[k] = s->tri_normal[3 * (size_t)tri + k];
    }
}

/* log2 of the pixel's footprint in level-0 texels at a hit at distance t along dir with normal n: the rays
 * through the next pixel right and down, cut with the hit's tangent plane. Grazing angles are limited so
 * the footprint stays finite. */
static float pixel_footprint(const srv_camera_frame *f, const float dir[3], float t, const float n[3],
                             float density)
{
    float step_x = 2.0f * f->tan_half_x / (float)f->width, step_y = 2.0f * f->tan_half_y / (float)f->height;
    float dn = dir[0] * n[0] + dir[1] * n[1] + dir[2] * n[2];
    float longest = 0;
    for (int axis = 0; axis < 2; axis++) {
        const float *offset = axis == 0 ? f->right : f->up;
        float step = axis == 0 ? step_x : step_y;
        float d2[3];
        for (int k = 0; k < 3; k++)
            d2[k] = dir[k] + step * offset[k];
        float d2n = d2[0] * n[0] + d2[1] * n[1] + d2[2] * n[2];
        float t2 = fabsf(d2n) > 1e-4f * fabsf(dn) && fabsf(d2n) > 1e-12f ? t * dn / d2n : t * 64.0f;
        if (!(t2 > 0) || t2 > t * 64.0f)
            t2 = t * 64.0f;
        float len2 = 0;
        for (int k = 0; k < 3; k++) {
            float diff = d2[k] * t2 - dir[k] * t;
            len2 += diff * diff;
        }
        longest = fmaxf(longest, len2);
    }
    float texels2 = longest * density * density; /* squared: log2 of the root is half the log2 */
    return texels2 > 1e-30f ? 0.5f * log2f(texels2) : -100.0f;
}

void srv__visibility_tile(const scene *s, scene_rt *rt, const srv_camera_frame *f, uint32_t tile_x,
                          uint32_t tile_y, uint32_t *tri, float *bary_u, float *bary_v, float *depth,
                          float *footprint)
{
    RTCScene rtc = scene_rt_handle(rt);
    _Alignas(64) struct RTCRayHit16 packet;
    _Alignas(64) int valid[16];
    float dirs[16][3];
    struct RTCIntersectContext ctx;
    /* The image plane per pixel: dir = forward + sx * right + sy * up, normalised (srv_camera_ray, inlined). */
    const float scale_x = 2.0f * f->tan_half_x / (float)f->width, scale_y = 2.0f * f->tan_half_y / (float)f->height;
    for (uint32_t py = tile_y; py < tile_y + SRV_TILE && py < f->height; py += 4)
        for (uint32_t px = tile_x; px < tile_x + SRV_TILE && px < f->width; px += 4) {
            for (int i = 0; i < 16; i++) {
                uint32_t x = px + (uint32_t)(i & 3), y = py + (uint32_t)(i >> 2);
                valid[i] = x < f->width && y < f->height ? -1 : 0;
                float sx = ((float)x + 0.5f) * scale_x - f->tan_half_x;
                float sy = f->tan_half_y - ((float)y + 0.5f) * scale_y;
                float d[3], len2 = 0;
                for (int k = 0; k < 3; k++) {
                    d[k] = f->forward[k] + sx * f->right[k] + sy * f->up[k];
                    len2 += d[k] * d[k];
                }
                float inv = 1.0f / sqrtf(len2);
                for (int k = 0; k < 3; k++)
                    dirs[i][k] = d[k] * inv;
                packet.ray.org_x[i] = f->origin[0];
                packet.ray.org_y[i] = f->origin[1];
                packet.ray.org_z[i] = f->origin[2];
                packet.ray.dir_x[i] = dirs[i][0];
                packet.ray.dir_y[i] = dirs[i][1];
                packet.ray.dir_z[i] = dirs[i][2];
                packet.ray.tnear[i] = 0.0f;
                packet.ray.tfar[i] = INFINITY;
                packet.ray.mask[i] = 0xFFFFFFFFu;
                packet.ray.time[i] = 0.0f;
                packet.ray.flags[i] = 0;
                packet.ray.id[i] = 0;
                packet.hit.geomID[i] = RTC_INVALID_GEOMETRY_ID;
                packet.hit.instID[0][i] = RTC_INVALID_GEOMETRY_ID;
            }
            rtcInitIntersectContext(&ctx);
            rtcIntersect16(valid, rtc, &ctx, &packet);
            for (int i = 0; i < 16; i++) {
                if (!valid[i])
                    continue;
                uint32_t x = px + (uint32_t)(i & 3), y = py + (uint32_t)(i >> 2);
                size_t p = (size_t)y * f->width + x;
                if (packet.hit.geomID[i] == RTC_INVALID_GEOMETRY_ID) {
                    tri[p] = SRV_MISS;
                    depth[p] = INFINITY;
                    continue;
                }
                uint32_t hit = packet.hit.primID[i];
                tri[p] = hit;
                bary_u[p] = packet.hit.u[i];
                bary_v[p] = packet.hit.v[i];
                depth[p] = packet.ray.tfar[i];
                footprint[p] = pixel_footprint(f, dirs[i], packet.ray.tfar[i], s->tri_normal + 3 * (size_t)hit,
                                               s->texel_density);
            }
        }
}

typedef struct visibility_task {
    srv_loop *loop;
    srv_viewer *view;
    uint32_t tiles_x;
} visibility_task;

/* One 16 x 16 tile of a viewer. */
static void visibility_tile(void *user, uint32_t task_index, uint32_t thread_index)
{
    (void)thread_index;
    visibility_task *task = user;
    srv_viewer *view = task->view;
    srv__visibility_tile(task->loop->s, task->loop->rt, &view->frame, (task_index % task->tiles_x) * SRV_TILE,
                         (task_index / task->tiles_x) * SRV_TILE, view->tri, view->bary_u, view->bary_v, view->depth,
                         view->footprint);
}

void srv__visibility(srv_loop *loop, srv_viewer *view)
{
    const srv_camera_frame *f = &view->frame;
    visibility_task task = {.loop = loop, .view = view, .tiles_x = (f->width + SRV_TILE - 1) / SRV_TILE};
    uint32_t tiles_y = (f->height + SRV_TILE - 1) / SRV_TILE;
    srv_pool_run(loop->pool, task.tiles_x * tiles_y, visibility_tile, &task);
}
