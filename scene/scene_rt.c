/* The Embree side of a scene: one device with an error callback registered once, one triangle geometry
 * holding exactly the scene's triangles (primID = scene triangle index), the floating-point mode every
 * tracing thread sets, and the one helper for robust ray origins that every ray in fxcache uses. */
#include "scene_internal.h"
#include "scene_inline.h"

#include <embree3/rtcore.h>

#include <math.h>
#include <pmmintrin.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <xmmintrin.h>

struct scene_rt {
    RTCDevice device;
    RTCScene scene;
    int error_code;      /* first Embree error seen (RTC_ERROR_NONE when none) */
    char error_msg[256]; /* and its message */
};

/* Embree's error callback: records the first error on the rt, and prints every one (they are rare). */
static void rt_error_callback(void *user, enum RTCError code, const char *str)
{
    scene_rt *rt = user;
    if (rt && rt->error_code == RTC_ERROR_NONE) {
        rt->error_code = (int)code;
        snprintf(rt->error_msg, sizeof rt->error_msg, "%s", str ? str : "(no message)");
    }
    fprintf(stderr, "fxcache: Embree error %d: %s\n", (int)code, str ? str : "(no message)");
}

void scene_tracing_thread_init(void)
{
    _MM_SET_FLUSH_ZERO_MODE(_MM_FLUSH_ZERO_ON);
    _MM_SET_DENORMALS_ZERO_MODE(_MM_DENORMALS_ZERO_ON);
}

scene_rt *scene_rt_create(const scene *s, double *build_ms, scene_error *err)
{
    double t0 = scene__now_ms();
    scene_rt *rt = calloc(1, sizeof *rt);
    if (!rt) {
        scene__fail(err, SCENE_ERR_NOMEM, "out of memory creating the Embree scene");
        return NULL;
    }
    scene_tracing_thread_init();
    rt->device = rtcNewDevice(NULL);
    if (!rt->device) {
        scene__fail(err, SCENE_ERR_EMBREE, "Embree: cannot create a device (error %d)",
                    (int)rtcGetDeviceError(NULL));
        free(rt);
        return NULL;
    }
    rtcSetDeviceErrorFunction(rt->device, rt_error_callback, rt);
    rt->scene = rtcNewScene(rt->device);
    rtcSetSceneFlags(rt->scene, RTC_SCENE_FLAG_ROBUST);
    rtcSetSceneBuildQuality(rt->scene, RTC_BUILD_QUALITY_HIGH);
    RTCGeometry geom = rtcNewGeometry(rt->device, RTC_GEOMETRY_TYPE_TRIANGLE);
    float *vertices = rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3,
                                              3 * sizeof(float), s->vertex_count);
    uint32_t *indices = rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3,
                                                3 * sizeof(uint32_t), s->triangle_count);
    if (vertices && indices) {
        memcpy(vertices, s->positions, sizeof(float) * 3 * (size_t)s->vertex_count);
        memcpy(indices, s->indices, sizeof(uint32_t) * 3 * (size_t)s->triangle_count);
    }
    rtcCommitGeometry(geom);
    rtcAttachGeometryByID(rt->scene, geom, 0);
    rtcReleaseGeometry(geom); /* the scene holds it now */
    rtcCommitScene(rt->scene);
    if (rt->error_code != RTC_ERROR_NONE || !vertices || !indices) {
        scene__fail(err, SCENE_ERR_EMBREE, "Embree: building the scene of %u triangles failed: %s",
                    s->triangle_count, rt->error_msg);
        scene_rt_free(rt);
        return NULL;
    }
    if (build_ms)
        *build_ms = scene__now_ms() - t0;
    return rt;
}

void scene_rt_free(scene_rt *rt)
{
    if (!rt)
        return;
    if (rt->scene)
        rtcReleaseScene(rt->scene);
    if (rt->device)
        rtcReleaseDevice(rt->device);
    free(rt);
}

void *scene_rt_handle(scene_rt *rt)
{
    return rt->scene;
}

void scene_offset_ray_origin(const float p[3], const float n[3], float scale, float out[3])
{
    scene_offset_ray_origin_inline(p, n, scale, out);
}

bool scene_rt_intersect1(scene_rt *rt, const float org[3], const float dir[3], float tfar, uint32_t *tri,
                         float *u, float *v, float *t)
{
    struct RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    struct RTCRayHit rh;
    memset(&rh, 0, sizeof rh);
    rh.ray.org_x = org[0];
    rh.ray.org_y = org[1];
    rh.ray.org_z = org[2];
    rh.ray.dir_x = dir[0];
    rh.ray.dir_y = dir[1];
    rh.ray.dir_z = dir[2];
    rh.ray.tnear = 0.0f;
    rh.ray.tfar = tfar;
    rh.ray.mask = 0xFFFFFFFFu;
    rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
    rtcIntersect1(rt->scene, &ctx, &rh);
    if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID)
        return false;
    *tri = rh.hit.primID;
    *u = rh.hit.u;
    *v = rh.hit.v;
    *t = rh.ray.tfar;
    return true;
}
