/* A client's sample request as the server takes it: the limits, the camera, the pixel list (net_samples.h).
 * The network thread (net.c, on_sample_request) calls these before it copies the list for the frame thread. */
#include "net_samples.h"

#include "engine.h"
#include "trace.h"

#include <stdio.h>

fxc_result srv_sample_request_check(const scene *s, const srv_sample_limits *limits,
                                    const proto_sample_request *q, srv_camera *camera, char *why,
                                    size_t why_cap)
{
    if (q->count > limits->max_samples) {
        snprintf(why, why_cap, "sample request %u: %u pixels, over the server's limit of %u", q->request,
                 q->count, limits->max_samples);
        return FXC_ERR_LIMIT;
    }
    if (q->width > limits->max_width || q->height > limits->max_height) {
        snprintf(why, why_cap, "sample request %u: image %ux%u is above the server's limit %ux%u", q->request,
                 q->width, q->height, limits->max_width, limits->max_height);
        return FXC_ERR_LIMIT;
    }
    double direction[3] = {q->camera.direction[0], q->camera.direction[1], q->camera.direction[2]};
    *camera = srv_trace_camera_world(s, q->camera.position, direction, q->camera.fov_deg);
    srv_camera_frame check;
    if (!srv_camera_setup(camera, q->width, q->height, &check)) {
        snprintf(why, why_cap, "sample request %u: %s", q->request, fxc_strerror(FXC_ERR_CAMERA));
        return FXC_ERR_CAMERA;
    }
    return FXC_OK;
}

void srv_sample_request_pixels(const proto_sample_request *q, uint32_t *pixels)
{
    for (uint32_t i = 0; i < q->count; i++) {
        uint16_t x, y;
        proto_request_pixel_get(q->pixels, i, &x, &y);
        pixels[i] = SRV_PIXEL_XY(x, y);
    }
}
