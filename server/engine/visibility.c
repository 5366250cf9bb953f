/* Stage 2, visibility: one primary ray per pixel through Embree's 16-wide packets (4 x 4 pixels), in
 * 16 x 16-pixel tiles spread over the thread pool (a sparse viewer: packets of 16 consecutive entries of its
 * sorted list, 256 entries per task). Per pixel it keeps the triangle, the barycentrics, the
 * footprint: the pixel's size on the surface from ray differentials (the neighbouring pixels' rays
 * intersected with the hit triangle's plane), in level-0 texels, as log2 - the level an unbiased effect
 * reads - and the side of the triangle the ray meets (back: the ray runs along its geometric normal), which
 * decides which side's cached shadows and AO the pixel reads (requests and compose take it from here). */
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

/* One packet of up to 16 primary rays: lane i is pixel (x[i], y[i]) of frame f when valid_lane[i], its
 * results written at index[i] of the output arrays. The direction formula is srv_camera_ray's, inlined, so a
 * pixel traced in a tile or from a list gets the same ray. */
static void trace_packet(const scene *s, RTCScene rtc, const srv_camera_frame *f, const uint32_t x[16],
                         const uint32_t y[16], const size_t index[16], const int valid_lane[16],
                         uint32_t *tri, float *bary_u, float *bary_v, float *depth, float *footprint,
                         uint8_t *back)
{
    _Alignas(64) struct RTCRayHit16 packet;
    _Alignas(64) int valid[16];
    float dirs[16][3], plane_dirs[16][3]; /* unit, and on the image plane (not normalised) */
    struct RTCIntersectContext ctx;
    /* The image plane per pixel: dir = forward + sx * right + sy * up, normalised (srv_camera_ray, inlined). */
    const float scale_x = 2.0f * f->tan_half_x / (float)f->width,
                scale_y = 2.0f * f->tan_half_y / (float)f->height;
    for (int i = 0; i < 16; i++) {
        valid[i] = valid_lane[i] ? -1 : 0;
        float sx = ((float)x[i] + 0.5f) * scale_x - f->tan_half_x;
        float sy = f->tan_half_y - ((float)y[i] + 0.5f) * scale_y;
        float d[3], len2 = 0;
        for (int k = 0; k < 3; k++) {
            d[k] = f->forward[k] + sx * f->right[k] + sy * f->up[k];
            len2 += d[k] * d[k];
            plane_dirs[i][k] = d[k];
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
        size_t p = index[i];
        if (packet.hit.geomID[i] == RTC_INVALID_GEOMETRY_ID) {
            tri[p] = SRV_MISS;
            depth[p] = INFINITY;
            continue;
        }
        uint32_t hit = packet.hit.primID[i];
        tri[p] = hit;
        if (back) { /* the sign of compose's own facing test (gather_pixel): the same operations, in order */
            const float *n = s->tri_normal + 3 * (size_t)hit, *d = plane_dirs[i];
            float facing = n[0] * d[0] + n[1] * d[1] + n[2] * d[2];
            back[p] = facing > 0;
        }
        bary_u[p] = packet.hit.u[i];
        bary_v[p] = packet.hit.v[i];
        depth[p] = packet.ray.tfar[i];
        footprint[p] = pixel_footprint(f, dirs[i], packet.ray.tfar[i], s->tri_normal + 3 * (size_t)hit,
                                       s->texel_density);
    }
}

void srv__visibility_tile(const scene *s, scene_rt *rt, const srv_camera_frame *f, uint32_t tile_x,
                          uint32_t tile_y, uint32_t *tri, float *bary_u, float *bary_v, float *depth,
                          float *footprint, uint8_t *back)
{
    RTCScene rtc = scene_rt_handle(rt);
    uint32_t xs[16], ys[16];
    size_t index[16];
    int valid[16];
    for (uint32_t py = tile_y; py < tile_y + SRV_TILE && py < f->height; py += 4)
        for (uint32_t px = tile_x; px < tile_x + SRV_TILE && px < f->width; px += 4) {
            for (int i = 0; i < 16; i++) {
                xs[i] = px + (uint32_t)(i & 3);
                ys[i] = py + (uint32_t)(i >> 2);
                valid[i] = xs[i] < f->width && ys[i] < f->height;
                index[i] = valid[i] ? (size_t)ys[i] * f->width + xs[i] : 0;
            }
            trace_packet(s, rtc, f, xs, ys, index, valid, tri, bary_u, bary_v, depth, footprint, back);
        }
}

void srv__visibility_list(const scene *s, scene_rt *rt, const srv_camera_frame *f, const uint32_t *list,
                          uint32_t first, uint32_t count, uint32_t *tri, float *bary_u, float *bary_v,
                          float *depth, float *footprint, uint8_t *back)
{
    uint32_t xs[16] = {0}, ys[16] = {0};
    size_t index[16] = {0};
    int valid[16] = {0};
    for (uint32_t i = 0; i < 16 && i < count; i++) {
        xs[i] = list[first + i] & 0xFFFFu;
        ys[i] = list[first + i] >> 16;
        index[i] = first + i;
        valid[i] = 1;
    }
    trace_packet(s, scene_rt_handle(rt), f, xs, ys, index, valid, tri, bary_u, bary_v, depth, footprint,
                 back);
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
                         (task_index / task->tiles_x) * SRV_TILE, view->tri, view->bary_u, view->bary_v,
                         view->depth, view->footprint, view->back);
}

enum { LIST_TASK = 256 }; /* listed pixels per visibility task: 16 packets */

/* LIST_TASK entries of a sparse viewer's list. */
static void visibility_list_task(void *user, uint32_t task_index, uint32_t thread_index)
{
    (void)thread_index;
    visibility_task *task = user;
    srv_viewer *view = task->view;
    uint32_t first = task_index * LIST_TASK, end = first + LIST_TASK;
    if (end > view->list_count)
        end = view->list_count;
    for (uint32_t at = first; at < end; at += 16)
        srv__visibility_list(task->loop->s, task->loop->rt, &view->frame, view->list, at, end - at, view->tri,
                             view->bary_u, view->bary_v, view->depth, view->footprint, view->back);
}

void srv__visibility(srv_loop *loop, srv_viewer *view)
{
    const srv_camera_frame *f = &view->frame;
    if (view->sparse) {
        visibility_task task = {.loop = loop, .view = view};
        srv_pool_run(loop->pool, (view->list_count + LIST_TASK - 1) / LIST_TASK, visibility_list_task, &task);
        return;
    }
    visibility_task task = {.loop = loop, .view = view, .tiles_x = (f->width + SRV_TILE - 1) / SRV_TILE};
    uint32_t tiles_y = (f->height + SRV_TILE - 1) / SRV_TILE;
    srv_pool_run(loop->pool, task.tiles_x * tiles_y, visibility_tile, &task);
}
