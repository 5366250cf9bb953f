/* A client's sample request as the server takes it (docs/PROTOCOL.md, "Sample requests"): the checks beyond
 * the wire format's own (proto_decode has checked sizes, pixels inside the image and the pose's numbers) and
 * the conversion into the engine's sparse-viewer list (srv_viewer_set_pixels). No network and no locks: the
 * network thread calls these (net.c), and so does the fuzz harness tests/fuzz/fuzz_sample_request.c. */
#ifndef FXC_SERVER_NET_SAMPLES_H
#define FXC_SERVER_NET_SAMPLES_H

#include "camera.h"
#include "fxc_result.h"
#include "proto.h"
#include "scene.h"

#include <stddef.h>
#include <stdint.h>

/* The server's limits on a request (srv_net_desc's). */
typedef struct srv_sample_limits {
    uint32_t max_samples;           /* pixels in one request, 1..PROTO_MAX_SAMPLES */
    uint32_t max_width, max_height; /* the request's image size */
} srv_sample_limits;

/* Checks the decoded request q against the limits and sets *camera up: q's pose (in the client's frame of
 * reference, moved through the scene's origin) must make a camera the renderer can use at q's image size.
 * FXC_OK; else FXC_ERR_LIMIT (over a limit) or FXC_ERR_CAMERA, with one line in why (no newline). */
fxc_result srv_sample_request_check(const scene *s, const srv_sample_limits *limits,
                                    const proto_sample_request *q, srv_camera *camera, char *why,
                                    size_t why_cap);

/* Writes q's q->count pixels as the engine's list entries (SRV_PIXEL_XY) into pixels (room for q->count),
 * in the request's order. */
void srv_sample_request_pixels(const proto_sample_request *q, uint32_t *pixels);

#endif
