/* Stage 7, compose: per pixel,
 *     radiance = albedo x (sum over lights of E x cos x light visibility + sky x sky visibility + indirect)
 *                + the emission of a front face (scene_emission_add; only in scenes with emitters)
 * then a tone map and sRGB 8-bit. Compose knows the formula, not the effects: it starts every pixel
 * unshadowed, unoccluded and with no indirect light, and each effect's shade callback modulates its term for
 * a run of pixels from the taps its cache kind gathers (bilinear reads at the level the pixel requested,
 * texels without data left out and the weights renormalised). A pixel for which some cached effect has no
 * data at all keeps that effect's neutral term and is counted as missing. In no-cache mode each effect's
 * eval callback traces its rays at the pixel with the sample counts the cache converges to. A sparse viewer
 * goes through the same gather and shading, over runs of its pixel list instead of a tile's rows. */
#include "engine_internal.h"
#include "fxc_hot.h"

#include <float.h>
#include <math.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* The effects of one cache kind whose taps one call gathers for a run (kind->pixel_taps). */
enum { TAPS_GROUP = 4 };

/* The largest block compose's blend expands for (srv__coarse_block gives at most desc.indirect_block). */
enum { SRV_BLEND_MAX_BLOCK = 8 };

/* One effect's taps of a run through the kind's call for several. */
FXC_HOT_INLINE void kind_taps(srv_loop *loop, const srv_viewer *view, uint32_t thread_index,
                              const srv_pixel *pixels, uint32_t count, uint32_t e, fx_taps *taps,
                              uint32_t *blocks)
{
    uint32_t k = loop->effect_kind[e];
    loop->kinds[k]->pixel_taps(loop->caches[k], (uint32_t)(view - loop->viewers), thread_index, pixels, NULL,
                               count, 1, &e, loop->bias[e], &taps, &blocks);
}

/* Per-thread scratch for one run of pixels along a row. */
typedef struct compose_scratch {
    srv_pixel pixels[SRV_RUN];
    fx_point points[SRV_RUN];
    fx_taps taps[TAPS_GROUP * SRV_RUN]; /* effect j of a group of one kind's effects: from j * SRV_RUN */
    uint32_t blocks[TAPS_GROUP * SRV_RUN];
    size_t index[SRV_RUN]; /* pixel index of each visible pixel of the run */
    float albedo[SRV_RUN][3];
    uint32_t triangle[SRV_RUN]; /* the albedo's arguments, one array each */
    float bary_u[SRV_RUN], bary_v[SRV_RUN], albedo_footprint[SRV_RUN];
    float shade_normal[3][SRV_RUN]; /* axis k of gathered pixel i at [k][i] */
    /* A tile's run gathered in lanes (gather_tile_run): per gathered pixel its footprint, its triangle's
     * island and the island's size, its island texel position. pixel_lanes is handed to the cache kinds'
     * pixel_taps when the run's pixels are those (have_lanes). */
    srv_pixel_lanes pixel_lanes;
    bool have_lanes;
    float irradiance[SRV_RUN][3]; /* from the lights, summed light by light */
    uint8_t missing[SRV_RUN];
    float sharing[SRV_RUN];
    float sky_visibility[SRV_RUN];
    float indirect[SRV_RUN * 3];
    /* The low-frequency effect per block (loop->coarse_effect): the samples' terms come from the viewer's
     * sample image (sample_patch, sky visibility 1 in: the term is linear in it); the run's pixels no sample
     * stands in for are gathered for one call (own_*). */
    /* coarse_shade's blend (blend_row): the run's block row of samples and the next, expanded per column. */
    float expand[2][SRV_SAMPLE_VALUES][SRV_TILE + SRV_BLEND_MAX_BLOCK];
    int32_t blend_own[SRV_RUN];    /* per lane: no sample stands in, the pixel is evaluated itself */
    uint32_t sample_slot[SRV_RUN]; /* sample pass: the sample image entry of gathered pixel i */
    uint8_t own_index[SRV_RUN];    /* the run's pixels evaluated themselves */
    srv_pixel own_pixels[SRV_RUN];
    fx_point own_points[SRV_RUN];
    float own_sky[SRV_RUN];
    float own_indirect[SRV_RUN * 3];
    float radiance[SRV_RUN][3]; /* the formula's result, before it is stored in the viewer's buffer */
    float light_visibility[];   /* SRV_RUN * max(light_count, 1) */
} compose_scratch;

size_t srv__compose_scratch_bytes(const srv_loop *loop)
{
    size_t lights = loop->s->light_count ? loop->s->light_count : 1;
    size_t bytes = sizeof(compose_scratch) + (size_t)SRV_RUN * lights * sizeof(float);
    return (bytes + 63) & ~(size_t)63;
}

/* Differentials of the hit position towards the next pixel right (dpdx) and down (dpdy) (engine_internal.h). */
void srv__pixel_differentials(const srv_camera_frame *f, const float dir[3], float t, const float n[3],
                              float dpdx[3], float dpdy[3])
{
    float dn = dir[0] * n[0] + dir[1] * n[1] + dir[2] * n[2];
    for (int axis = 0; axis < 2; axis++) {
        const float *offset = axis == 0 ? f->right : f->up;
        float step =
            axis == 0 ? 2.0f * f->tan_half_x / (float)f->width : -2.0f * f->tan_half_y / (float)f->height;
        float d2[3];
        for (int k = 0; k < 3; k++)
            d2[k] = dir[k] + step * offset[k];
        float d2n = d2[0] * n[0] + d2[1] * n[1] + d2[2] * n[2];
        float t2 = fabsf(d2n) > 1e-12f ? t * dn / d2n : t;
        if (!(t2 > 0) || t2 > 64.0f * t)
            t2 = 64.0f * t;
        float *out = axis == 0 ? dpdx : dpdy;
        for (int k = 0; k < 3; k++)
            out[k] = d2[k] * t2 - dir[k] * t;
    }
}

/* min(x, FLT_MAX) without a libm call: infinity saturates, NaN passes on (and is caught after). */
static inline float saturate_max(float x)
{
    return x > FLT_MAX ? FLT_MAX : x;
}

typedef struct compose_task {
    srv_loop *loop;
    srv_viewer *view;
    atomic_uint_fast64_t missing;
    atomic_uint_fast64_t rays[SRV_MAX_EFFECTS];
} compose_task;

/* What neighbouring pixels share when they see the same triangle, looked up once. */
typedef struct gather_memo {
    uint32_t tri, island; /* SRV_MISS: none yet */
    float corner[3][3], normal[3], island_uv[6];
} gather_memo;

/* A memo with no triangle yet. */
FXC_HOT_INLINE gather_memo gather_memo_start(void)
{
    return (gather_memo){.tri = SRV_MISS};
}

/* The shading normal of a visible pixel: its triangle's normal, negated when the pixel sees the back of the
 * triangle (back: the byte visibility stored, its facing test `normal . ray direction on the image plane > 0`,
 * which compose computed again per pixel with the same operations in the same order until 2026-11-29, so the
 * same sign; tests/test_two_side.c checks the byte against that test). The negation flips the sign bit only,
 * exactly as `-n` does, NaN included. */
FXC_HOT_INLINE float shade_axis(float normal, uint32_t back_bit)
{
    uint32_t bits;
    memcpy(&bits, &normal, sizeof bits);
    bits ^= back_bit << 31;
    memcpy(&normal, &bits, sizeof normal);
    return normal;
}

/* Pixel (x, y) of the viewer's frame, held at buffer entry p (y * width + x, or a sparse viewer's list
 * position): a miss gets the sky; a visible pixel is appended to the run (its shading normal, albedo arguments
 * and cache pixel, with position and distance only when `positions`: a cache kind asks for them; its point
 * (fx_point) only when `points`: no-cache mode, a cache kind that needs positions, or a light that is not
 * directional). */
FXC_HOT_INLINE void gather_pixel(srv_loop *loop, srv_viewer *view, uint32_t x, uint32_t y, size_t p,
                                 compose_scratch *cs, uint32_t *count, const float sky[3], float log2_density,
                                 bool positions, bool points, gather_memo *memo)
{
    const scene *s = loop->s;
    const srv_camera_frame *f = &view->frame;
    uint32_t tri = view->tri[p];
    if (tri == SRV_MISS) {
        memcpy(view->radiance + 3 * p, sky, 3 * sizeof(float));
        if (view->views[SRV_VIEW_AO]) {
            view->views[SRV_VIEW_AO][p] = 1.0f;
            view->views[SRV_VIEW_SHADOW][p] = 1.0f;
            view->views[SRV_VIEW_SHARING][p] = 0.0f;
        }
        return;
    }
    uint32_t i = (*count)++;
    cs->index[i] = p;
    float u = view->bary_u[p], v = view->bary_v[p];
    if (tri != memo->tri) {
        memo->tri = tri;
        const uint32_t *idx = s->indices + 3 * (size_t)tri;
        for (int c = 0; c < 3; c++)
            memcpy(memo->corner[c], s->positions + 3 * (size_t)idx[c], sizeof memo->corner[c]);
        memcpy(memo->normal, s->tri_normal + 3 * (size_t)tri, sizeof memo->normal);
        memcpy(memo->island_uv, s->tri_island_uv + 6 * (size_t)tri, sizeof memo->island_uv);
        memo->island = s->tri_island[tri];
    }
    const float *normal = memo->normal;
    float w = 1.0f - u - v;
    uint32_t back = view->back[p]; /* seen from behind: light the side the viewer sees */
    float sn[3] = {shade_axis(normal[0], back), shade_axis(normal[1], back), shade_axis(normal[2], back)};
    cs->shade_normal[0][i] = sn[0];
    cs->shade_normal[1][i] = sn[1];
    cs->shade_normal[2][i] = sn[2];
    /* The pixel's footprint in metres: level-0 texels per pixel over texels per metre. The albedo is
     * sampled after the loop, for the whole run. */
    cs->triangle[i] = tri;
    cs->bary_u[i] = u;
    cs->bary_v[i] = v;
    cs->albedo_footprint[i] = view->footprint[p] - log2_density;
    srv_pixel *px = &cs->pixels[i];
    if (points) {
        fx_point *pt = &cs->points[i];
        for (int k = 0; k < 3; k++) {
            pt->position[k] = w * memo->corner[0][k] + u * memo->corner[1][k] + v * memo->corner[2][k];
            pt->normal[k] = normal[k];
            pt->view_normal[k] = sn[k];
        }
        pt->triangle = tri;
        pt->u = u;
        pt->v = v;
        pt->pixel_id = (uint64_t)y * f->width + x; /* the image position, whatever buffer entry holds it */
        if (loop->desc.no_cache) {
            float dir[3];
            srv_camera_ray(f, (float)x + 0.5f, (float)y + 0.5f, dir);
            srv__pixel_differentials(f, dir, view->depth[p], pt->normal, pt->dpdx, pt->dpdy);
        }
        if (positions)
            memcpy(px->position, pt->position, sizeof px->position);
    }
    px->triangle = tri;
    px->island = memo->island | back << 31; /* the side seen: SCENE_ISLAND_BACK */
    px->footprint = view->footprint[p];
    px->island_u = w * memo->island_uv[0] + u * memo->island_uv[2] + v * memo->island_uv[4];
    px->island_v = w * memo->island_uv[1] + u * memo->island_uv[3] + v * memo->island_uv[5];
    if (positions)
        px->distance = view->depth[p];
}

/* Gathers the visible pixels of one run (rows y0..y1, columns x0..x1, at most SRV_RUN pixels). Returns how
 * many are visible. */
FXC_HOT_INLINE uint32_t gather_run(srv_loop *loop, srv_viewer *view, uint32_t x0, uint32_t x1, uint32_t y0,
                                   uint32_t y1, compose_scratch *cs, const float sky[3], float log2_density,
                                   bool positions, bool points)
{
    gather_memo memo = gather_memo_start();
    uint32_t count = 0;
    cs->have_lanes = false;
    for (uint32_t y = y0; y < y1; y++)
        for (uint32_t x = x0; x < x1; x++)
            gather_pixel(loop, view, x, y, (size_t)y * view->frame.width + x, cs, &count, sky, log2_density,
                         positions, points, &memo);
    scene_albedo_run(loop->s, cs->triangle, cs->bary_u, cs->bary_v, cs->albedo_footprint, count, cs->albedo);
    return count;
}

/* gather_run for a tile's run when no visible points are gathered (points false, so positions false too):
 * the same values (the same operations in the same order as gather_pixel, so the same floats) in two passes
 * instead of one per pixel: the visible pixels into lanes (a miss gets the sky, as in gather_pixel), then the
 * cache pixels, only when some kind reads them (pixels; else cs->pixels stays unset: every pixel_taps call
 * gets the lanes). The lanes past the run get zeros (inputs of loops over every lane; not read). Per pixel
 * only what differs from its neighbour's goes to the lanes: an earlier version also stored its column, row,
 * triangle normal and six island UVs to work out the facing test and the island position in a vectorised
 * pass, 11 more stores a pixel than the scalar arithmetic they saved. */
FXC_HOT_INLINE uint32_t gather_tile_run(srv_loop *loop, srv_viewer *view, uint32_t x0, uint32_t x1,
                                        uint32_t y0, uint32_t y1, compose_scratch *cs, const float sky[3],
                                        float log2_density, bool pixels)
{
    const scene *s = loop->s;
    const size_t width = view->frame.width;
    const uint32_t *tris = view->tri;
    const float *bary_u = view->bary_u, *bary_v = view->bary_v, *footprint = view->footprint;
    const uint8_t *back = view->back;
    float *views_ao = view->views[SRV_VIEW_AO], *views_shadow = view->views[SRV_VIEW_SHADOW],
          *views_sharing = view->views[SRV_VIEW_SHARING], *radiance = view->radiance;
    uint32_t count = 0, last = SRV_MISS, island = 0, width0 = 0, height0 = 0;
    srv_pixel_lanes *pl = &cs->pixel_lanes;
    float n0 = 0, n1 = 0, n2 = 0, uv0 = 0, uv1 = 0, uv2 = 0, uv3 = 0, uv4 = 0, uv5 = 0;
    for (uint32_t y = y0; y < y1; y++) {
        for (uint32_t x = x0; x < x1; x++) {
            size_t p = (size_t)y * width + x;
            uint32_t tri = tris[p];
            if (tri == SRV_MISS) {
                memcpy(radiance + 3 * p, sky, 3 * sizeof(float));
                if (views_ao) {
                    views_ao[p] = 1.0f;
                    views_shadow[p] = 1.0f;
                    views_sharing[p] = 0.0f;
                }
                continue;
            }
            if (tri != last) {
                last = tri;
                const float *normal = s->tri_normal + 3 * (size_t)tri,
                            *uv = s->tri_island_uv + 6 * (size_t)tri;
                n0 = normal[0], n1 = normal[1], n2 = normal[2];
                uv0 = uv[0], uv1 = uv[1], uv2 = uv[2], uv3 = uv[3], uv4 = uv[4], uv5 = uv[5];
                island = s->tri_island[tri];
                width0 = s->islands[island].width;
                height0 = s->islands[island].height;
            }
            uint32_t i = count++;
            cs->index[i] = p;
            cs->triangle[i] = tri;
            float u = bary_u[p], v = bary_v[p], w = 1.0f - u - v, fp = footprint[p];
            cs->bary_u[i] = u;
            cs->bary_v[i] = v;
            pl->footprint[i] = fp;
            cs->albedo_footprint[i] = fp - log2_density;
            pl->island_u[i] = w * uv0 + u * uv2 + v * uv4;
            pl->island_v[i] = w * uv1 + u * uv3 + v * uv5;
            uint32_t back_bit = back[p];
            pl->island[i] = island | back_bit << 31; /* the side seen: SCENE_ISLAND_BACK */
            pl->width0[i] = width0;
            pl->height0[i] = height0;
            cs->shade_normal[0][i] = shade_axis(n0, back_bit);
            cs->shade_normal[1][i] = shade_axis(n1, back_bit);
            cs->shade_normal[2][i] = shade_axis(n2, back_bit);
        }
    }
    for (uint32_t i = count; i < SRV_RUN; i++) { /* defined inputs for the lanes past the run */
        cs->bary_u[i] = cs->bary_v[i] = pl->footprint[i] = pl->island_u[i] = pl->island_v[i] = 0.0f;
        cs->albedo_footprint[i] = 0.0f - log2_density;
        pl->island[i] = pl->width0[i] = pl->height0[i] = 0;
        for (int k = 0; k < 3; k++)
            cs->shade_normal[k][i] = 0.0f;
    }
    for (uint32_t i = 0; pixels && i < count; i++) {
        srv_pixel *px = &cs->pixels[i];
        px->triangle = cs->triangle[i];
        px->island = pl->island[i];
        px->footprint = pl->footprint[i];
        px->island_u = pl->island_u[i];
        px->island_v = pl->island_v[i];
    }
    cs->have_lanes = true;
    scene_albedo_run(s, cs->triangle, cs->bary_u, cs->bary_v, cs->albedo_footprint, count, cs->albedo);
    return count;
}

/* A sparse viewer's run: list entries first..end-1 (at most SRV_RUN). */
static uint32_t gather_list(srv_loop *loop, srv_viewer *view, size_t first, size_t end, compose_scratch *cs,
                            const float sky[3], float log2_density, bool positions, bool points)
{
    gather_memo memo = gather_memo_start();
    uint32_t count = 0;
    cs->have_lanes = false;
    for (size_t p = first; p < end; p++)
        gather_pixel(loop, view, view->list[p] & 0xFFFFu, view->list[p] >> 16, p, cs, &count, sky,
                     log2_density, positions, points, &memo);
    scene_albedo_run(loop->s, cs->triangle, cs->bary_u, cs->bary_v, cs->albedo_footprint, count, cs->albedo);
    return count;
}

enum { CONSTANT_LIGHTS = 8 }; /* directional lights whose direction and irradiance are computed once */

/* What every run of a compose task uses, computed once per task. */
typedef struct compose_setup {
    float sky[3];
    float log2_density;
    bool positions;                     /* some shading cache kind reads the pixels' positions */
    bool points;                        /* the visible points (fx_point) are gathered: someone reads them */
    bool positions_other, points_other; /* the same leaving out loop->coarse_effect: a coarse tile's runs */
    /* Some shading effect's kind reads the pixels (srv_pixel) even when it gets lanes (not lanes_suffice);
     * pixels_other leaves out loop->coarse_effect (coarse_shade gathers its own pixels again in full). */
    bool pixels, pixels_other;
    uint32_t lights, stride;
    float light_dir[CONSTANT_LIGHTS][3], light_rgb[CONSTANT_LIGHTS][3]; /* the same for every pixel */
} compose_setup;

static void compose_setup_init(const srv_loop *loop, compose_setup *cu)
{
    const scene *s = loop->s;
    cu->lights = s->light_count;
    cu->stride = cu->lights ? cu->lights : 1;
    for (int k = 0; k < 3; k++)
        cu->sky[k] = s->sky_color[k] * s->sky_intensity;
    cu->log2_density = log2f(s->texel_density);
    cu->positions = cu->positions_other = cu->pixels = cu->pixels_other = false;
    for (uint32_t e = 0; e < loop->effect_count; e++) {
        if (!loop->effect_shading[e])
            continue;
        const srv_cache_kind *kind = loop->kinds[loop->effect_kind[e]];
        cu->positions |= kind->needs_position;
        cu->positions_other |= kind->needs_position && e != loop->coarse_effect;
        cu->pixels |= !kind->lanes_suffice;
        cu->pixels_other |= !kind->lanes_suffice && e != loop->coarse_effect;
    }
    for (uint32_t l = 0; l < cu->lights && l < CONSTANT_LIGHTS; l++) {
        float dist;
        fx_light_direction(&s->lights[l], (const float[3]){0, 0, 0}, cu->light_dir[l], &dist);
        for (int k = 0; k < 3; k++)
            cu->light_rgb[l][k] = s->lights[l].intensity * s->lights[l].color[k];
    }
    /* The visible points (fx_point) are gathered only for whoever reads them: the no-cache evaluation, a
     * shading cache kind that needs positions (its shade callback reads them), and lights whose direction
     * depends on the position. */
    cu->points_other = loop->desc.no_cache || cu->positions_other;
    for (uint32_t l = 0; l < cu->lights; l++)
        cu->points_other |= !(s->lights[l].type == SCENE_LIGHT_DIRECTIONAL && l < CONSTANT_LIGHTS);
    cu->points = cu->points_other || cu->positions;
}

/* The formula over a run's SRV_RUN lanes (vectorised: FXC_HOT_LANES), each value as one pixel at a time gave
 * it. Saturate, never overflow to infinity (extreme light intensities): DESIGN.md, robustness. */
FXC_HOT_LANES static void radiance_lanes(compose_scratch *cs, const float sky[3])
{
    const float sky0 = sky[0], sky1 = sky[1], sky2 = sky[2];
    for (int i = 0; i < SRV_RUN; i++) {
        float sv = cs->sky_visibility[i];
#pragma GCC unroll 3
        for (int k = 0; k < 3; k++) {
            /* saturate_max() written out: a helper is not inlined into a function of other options */
            float sk = k == 0 ? sky0 : (k == 1 ? sky1 : sky2);
            float a = cs->irradiance[i][k], b = sk * sv, c = cs->indirect[3 * i + k];
            float irr =
                (a > FLT_MAX ? FLT_MAX : a) + (b > FLT_MAX ? FLT_MAX : b) + (c > FLT_MAX ? FLT_MAX : c);
            float value = cs->albedo[i][k] * (irr > FLT_MAX ? FLT_MAX : irr);
            cs->radiance[i][k] = value <= FLT_MAX ? value : (value > 0 ? FLT_MAX : 0.0f);
        }
    }
}

/* A constant directional light's irradiance (direction ldir, colour times intensity rgb, light l of stride) added
 * to every lane of a run (vectorised: FXC_HOT_LANES). A lane that faces away adds +0 where one pixel at a
 * time added nothing: the same sums, since a sum that starts at +0 is never -0 and x + 0 = x for every other
 * x, infinities and NaN included. */
FXC_HOT_LANES static void directional_lanes(compose_scratch *cs, const float ldir[3], const float rgb[3],
                                            uint32_t stride, uint32_t l)
{
    const float l0 = ldir[0], l1 = ldir[1], l2 = ldir[2], c0 = rgb[0], c1 = rgb[1], c2 = rgb[2];
    if (stride == 1) { /* one light: its visibility contiguous (the loop below, vectorised without gathers) */
        for (int i = 0; i < SRV_RUN; i++) {
            float cosine =
                cs->shade_normal[0][i] * l0 + cs->shade_normal[1][i] * l1 + cs->shade_normal[2][i] * l2;
            float visibility = cs->light_visibility[i];
            bool lit = cosine > 0;
            cs->irradiance[i][0] += lit ? cosine * visibility * c0 : 0.0f;
            cs->irradiance[i][1] += lit ? cosine * visibility * c1 : 0.0f;
            cs->irradiance[i][2] += lit ? cosine * visibility * c2 : 0.0f;
        }
        return;
    }
    for (int i = 0; i < SRV_RUN; i++) {
        float cosine =
            cs->shade_normal[0][i] * l0 + cs->shade_normal[1][i] * l1 + cs->shade_normal[2][i] * l2;
        float visibility = cs->light_visibility[(size_t)i * stride + l];
        bool lit = cosine > 0;
        cs->irradiance[i][0] += lit ? cosine * visibility * c0 : 0.0f;
        cs->irradiance[i][1] += lit ? cosine * visibility * c1 : 0.0f;
        cs->irradiance[i][2] += lit ? cosine * visibility * c2 : 0.0f;
    }
}

/* Shades the count gathered pixels of a run into the viewer's radiance (and kept views): the effects' terms
 * from the caches (or per pixel in no-cache mode), then the formula. */
/* The pixels of a run of a whole frame (rows y0..y1, columns x0..x1 of the tile of grid g): compose's
 * coarse evaluation of loop->coarse_effect (engine_internal.h, srv__coarse_mask). */
typedef struct coarse_run {
    const srv_coarse_grid *g;
    uint32_t x0, x1, y0, y1;
    const float *values;  /* the sample image's first value (coarse_shade) */
    size_t value_stride;  /* floats from one value of the image to the next */
    size_t stride, first; /* samples a row; the tile's first sample */
} coarse_run;

/* A row of a tile's samples, expanded per pixel column (out[v][c]: sample c / B of the row, value v; zeros
 * from sample nx on): a pixel in column c of the tile reads its block's samples at c and
 * c + B, with contiguous loads (gathers are slow on the machines we measure on). `values` is sample image
 * value 0 (the others every `value_stride` floats on), `row` the index of the row's first sample. */
FXC_HOT_INLINE void blend_expand_row_of(const float *values, size_t value_stride, size_t row, uint32_t nx,
                                        uint32_t block,
                                        float out[SRV_SAMPLE_VALUES][SRV_TILE + SRV_BLEND_MAX_BLOCK])
{
    const uint32_t columns = SRV_TILE + SRV_BLEND_MAX_BLOCK, samples = columns / block;
    for (uint32_t v = 0; v < SRV_SAMPLE_VALUES; v++) {
        const float *from = values + v * value_stride + row;
        for (uint32_t i = 0; i < samples; i++) { /* block is a constant here: B stores of one value */
            float value = i < nx ? from[i] : 0.0f;
            for (uint32_t f = 0; f < block; f++)
                out[v][i * block + f] = value;
        }
    }
}

/* blend_expand_row_of with the block a constant in each call (2 or 4: srv__coarse_block's choices). */
FXC_HOT_INLINE void blend_expand_row(const float *values, size_t value_stride, size_t row, uint32_t nx,
                                     uint32_t block,
                                     float out[SRV_SAMPLE_VALUES][SRV_TILE + SRV_BLEND_MAX_BLOCK])
{
    if (block == 4)
        blend_expand_row_of(values, value_stride, row, nx, 4, out);
    else if (block == 2)
        blend_expand_row_of(values, value_stride, row, nx, 2, out);
    else
        blend_expand_row_of(values, value_stride, row, nx, 8, out);
}

/* The blend of coarse_shade for one row of a run, every column of the tile as a lane (vectorised:
 * FXC_HOT_LANES, contiguous loads only): column j takes the candidates of its sample choice (mask[j],
 * srv__coarse_mask's order: top[.][j], top[.][j + B], bottom[.][j], bottom[.][j + B]) that have data, with the
 * bilinear weights from wx[j] and wy (srv__coarse_weights' values), into the weighted sums of the 3 indirect
 * values and the sky factor, their weights' total and the largest sharing count taken (out, per column). The
 * candidates left out add exact zeros to the sums (which start at +0, so never -0): the same values in the
 * same order as summing only those taken. */
FXC_HOT_LANES static void blend_row(const int32_t *mask, const float *wx, float wy, int32_t block,
                                    const float (*top)[SRV_TILE + SRV_BLEND_MAX_BLOCK],
                                    const float (*bottom)[SRV_TILE + SRV_BLEND_MAX_BLOCK],
                                    float (*out)[SRV_TILE])
{
    float o[6][SRV_TILE];
    for (int j = 0; j < SRV_TILE; j++) {
        int32_t m = mask[j];
        float x = wx[j];
        float weight[4] = {(1.0f - x) * (1.0f - wy), x * (1.0f - wy), (1.0f - x) * wy, x * wy};
        float sum0 = 0, sum1 = 0, sum2 = 0, sum3 = 0, total = 0, sharing = 0;
#pragma GCC unroll 4
        for (int c = 0; c < 4; c++) {
            const float(*src)[SRV_TILE + SRV_BLEND_MAX_BLOCK] = (c & 2) ? bottom : top;
            int32_t at = j + ((c & 1) ? block : 0);
            float taken = src[SRV_SAMPLE_OK][at] * (float)((m >> c) & 1), w = weight[c] * taken;
            sum0 += w * src[SRV_SAMPLE_R][at];
            sum1 += w * src[SRV_SAMPLE_G][at];
            sum2 += w * src[SRV_SAMPLE_B][at];
            sum3 += w * src[SRV_SAMPLE_SKY][at];
            total += w;
            float s = src[SRV_SAMPLE_SHARING][at] * taken; /* (finite popcounts, at least 0) */
            sharing = s > sharing ? s : sharing;
        }
        o[0][j] = sum0;
        o[1][j] = sum1;
        o[2][j] = sum2;
        o[3][j] = sum3;
        o[4][j] = total;
        o[5][j] = sharing;
    }
    for (int v = 0; v < 6; v++)
        for (int j = 0; j < SRV_TILE; j++)
            out[v][j] = o[v][j];
}

/* coarse_shade's finishing of one row whose 16 columns are all visible, so its pixels are the 16 consecutive
 * gathered lanes from `lane` on (sky, indirect, sharing and own point there), every column a lane
 * (vectorised: FXC_HOT_LANES, contiguous loads only): from the blend's sums o (blend_row) the indirect term
 * added, the sky factor applied and the sharing count kept where any sample was taken, and per lane whether
 * the pixel is evaluated itself. The same operations on the same floats as coarse_shade's scalar loop. */
FXC_HOT_LANES static int32_t blend_finish_lanes(const float (*o)[SRV_TILE], float *restrict sky,
                                                float *restrict indirect, float *restrict sharing,
                                                int32_t *restrict own, int32_t keep_sharing)
{
    /* Results into local arrays first, then stored (a select that may keep the old value, stored in place,
     * becomes a conditional store, and the loop is not vectorised). */
    float e0[SRV_TILE], e1[SRV_TILE], e2[SRV_TILE], sky_out[SRV_TILE];
    int32_t taken[SRV_TILE];
    for (int j = 0; j < SRV_TILE; j++) {
        float total = o[4][j];
        int32_t blended = total > 0;
        float divisor = blended ? total : 1.0f;
        float s = sky[j], open = s / divisor;
        float t0 = o[0][j] * open, t1 = o[1][j] * open, t2 = o[2][j] * open; /* fminf(x, FLT_MAX) */
        t0 = t0 < FLT_MAX ? t0 : FLT_MAX;
        t1 = t1 < FLT_MAX ? t1 : FLT_MAX;
        t2 = t2 < FLT_MAX ? t2 : FLT_MAX;
        e0[j] = blended ? t0 : 0.0f;
        e1[j] = blended ? t1 : 0.0f;
        e2[j] = blended ? t2 : 0.0f;
        float factor = s * (o[3][j] / divisor);
        sky_out[j] = blended ? factor : s;
        taken[j] = blended;
    }
    int32_t owns = 0; /* the lanes evaluated themselves */
    for (int j = 0; j < SRV_TILE; j++) {
        sky[j] = sky_out[j];
        own[j] = !taken[j];
        owns += !taken[j];
    }
    if (keep_sharing) { /* (a loop of its own: the flag inside the loop above kept it from vectorising) */
        float sharing_out[SRV_TILE];
        for (int j = 0; j < SRV_TILE; j++) {
            float was = sharing[j], shared = o[5][j];
            int32_t more = shared > was, keep = taken[j] & more;
            sharing_out[j] = keep ? shared : was;
        }
        for (int j = 0; j < SRV_TILE; j++)
            sharing[j] = sharing_out[j];
    }
    /* Where no sample was taken, + 0 leaves the term as it is: x + (+0) is x for every x but -0, and the
     * term is never -0 (it starts at +0 in shade_run and only has terms added to it, and a sum is -0 only
     * when both are) */
    for (int j = 0; j < SRV_TILE; j++) {
        indirect[3 * j] += e0[j];
        indirect[3 * j + 1] += e1[j];
        indirect[3 * j + 2] += e2[j];
    }
    return owns;
}

/* The coarse effect over a gathered run: each pixel blends the terms of the samples that stand in for it (an
 * indirect term and a sky factor, both linear in the pixel's own sky visibility: blend_row), the others are
 * gathered and go through the kind's taps and the effect's shade as one smaller run. The samples are those of
 * the sample image `values` (value_stride floats from one value to the next, `stride` samples a row, the
 * tile's first at `first`). */
FXC_HOT_INLINE void coarse_shade(srv_loop *loop, srv_viewer *view, compose_scratch *cs, uint32_t e,
                                 const coarse_run *cr, const compose_setup *cu, uint32_t thread_index,
                                 uint32_t count)
{
    const uint64_t *bits = loop->viewer_bits[e];
    const srv_coarse_grid *g = cr->g;
    const size_t width = view->frame.width;
    const uint32_t shift = g->shift, low = g->block - 1, columns = cr->x1 - cr->x0;
    float wx[SRV_TILE];
    for (uint32_t j = 0; j < SRV_TILE; j++) {
        uint32_t ix = j >> shift, fx = j & low;
        wx[j] = fx && ix + 1 < g->nx ? (float)fx * g->inv_block : 0.0f;
    }
    uint32_t expanded = UINT32_MAX; /* the block row in cs->expand */
    uint32_t lane = 0;              /* the lane of the next visible pixel (gather_run's order) */
    uint32_t owns = 0;              /* pixels no sample stands in for (evaluated below) */
    for (uint32_t y = cr->y0; y < cr->y1; y++) {
        uint32_t ly = y - g->y0, iy = ly >> shift, fy = ly & low;
        bool two_y = fy && iy + 1 < g->ny;
        if (iy != expanded) {
            blend_expand_row(cr->values, cr->value_stride, cr->first + (size_t)iy * cr->stride, g->nx,
                             g->block, cs->expand[0]);
            blend_expand_row(cr->values, cr->value_stride,
                             cr->first + (size_t)(iy + 1 < g->ny ? iy + 1 : iy) * cr->stride, g->nx, g->block,
                             cs->expand[1]);
            expanded = iy;
        }
        float wy = two_y ? (float)fy * g->inv_block : 0.0f;
        size_t row = (size_t)y * width + cr->x0;
        uint8_t bytes[SRV_TILE] = {0};
        memcpy(bytes, view->coarse + row, columns); /* requests' sample choice (srv__coarse_mask) */
        int32_t mask[SRV_TILE];
        for (uint32_t j = 0; j < SRV_TILE; j++)
            mask[j] = bytes[j];
        float o[6][SRV_TILE];
        blend_row(mask, wx, wy, (int32_t)g->block,
                  (const float(*)[SRV_TILE + SRV_BLEND_MAX_BLOCK]) cs->expand[0],
                  (const float(*)[SRV_TILE + SRV_BLEND_MAX_BLOCK]) cs->expand[1], o);
        uint32_t visible = 0;
        if (columns == SRV_TILE)
            for (uint32_t j = 0; j < SRV_TILE; j++)
                visible += view->tri[row + j] != SRV_MISS;
        /* the common case, a whole row visible: 16 consecutive lanes */
        if (visible == SRV_TILE && lane + SRV_TILE <= count && !loop->desc.no_lanes) {
            owns += (uint32_t)blend_finish_lanes((const float(*)[SRV_TILE])o, cs->sky_visibility + lane,
                                                 cs->indirect + 3 * lane, cs->sharing + lane,
                                                 cs->blend_own + lane, bits != NULL);
            lane += SRV_TILE;
            continue;
        }
        for (uint32_t j = 0; j < columns; j++) {
            if (view->tri[row + j] == SRV_MISS)
                continue;
            float total = o[4][j];
            bool blended = total > 0;
            float divisor = blended ? total : 1.0f;
            float sky = cs->sky_visibility[lane], open = sky / divisor;
            float e0 = o[0][j] * open, e1 = o[1][j] * open, e2 = o[2][j] * open; /* fminf(x, FLT_MAX) */
            e0 = e0 < FLT_MAX ? e0 : FLT_MAX;
            e1 = e1 < FLT_MAX ? e1 : FLT_MAX;
            e2 = e2 < FLT_MAX ? e2 : FLT_MAX;
            if (blended) {
                cs->indirect[3 * lane] += e0;
                cs->indirect[3 * lane + 1] += e1;
                cs->indirect[3 * lane + 2] += e2;
                cs->sky_visibility[lane] = sky * (o[3][j] / divisor);
                if (bits && o[5][j] > cs->sharing[lane])
                    cs->sharing[lane] = o[5][j];
            }
            cs->blend_own[lane] = !blended;
            owns += !blended;
            lane++;
        }
    }
    if (!owns) /* every pixel blended (the common case): nothing to gather or shade */
        return;
    uint32_t own = 0;
    gather_memo memo = gather_memo_start();
    for (uint32_t i = 0; i < count; i++) {
        if (!cs->blend_own[i])
            continue;
        if (!cu->points) { /* the run was gathered without positions: this pixel's, now */
            size_t p = cs->index[i];
            uint32_t again = i, x = (uint32_t)(p % width), y = (uint32_t)(p / width);
            gather_pixel(loop, view, x, y, p, cs, &again, cu->sky, cu->log2_density, true, true, &memo);
        }
        cs->own_index[own] = (uint8_t)i;
        cs->own_pixels[own] = cs->pixels[i];
        cs->own_points[own] = cs->points[i];
        cs->own_sky[own] = cs->sky_visibility[i];
        memcpy(cs->own_indirect + 3 * own, cs->indirect + 3 * i, 3 * sizeof(float));
        own++;
    }
    if (!own)
        return;
    kind_taps(loop, view, thread_index, cs->own_pixels, own, e, cs->taps, bits ? cs->blocks : NULL);
    fx_shade_run run = {.count = own,
                        .taps = cs->taps,
                        .points = cs->own_points,
                        .sky_visibility = cs->own_sky,
                        .indirect = cs->own_indirect};
    loop->effects[e]->shade(&loop->fx, &run);
    for (uint32_t j = 0; j < own; j++) {
        uint32_t at = cs->own_index[j];
        cs->sky_visibility[at] = cs->own_sky[j];
        memcpy(cs->indirect + 3 * at, cs->own_indirect + 3 * j, 3 * sizeof(float));
        cs->missing[at] |= cs->taps[j].count == 0;
        if (bits && cs->blocks[j] != SRV_NONE)
            cs->sharing[at] = fmaxf(cs->sharing[at], (float)__builtin_popcountll(bits[cs->blocks[j]]));
    }
}

/* The frame-wide pass over the block samples (before compose's tiles): every sample of the frame evaluated
 * once, in patches of SAMPLE_PATCH_TILES x 1 tiles' samples (each patch's samples in runs of at most SRV_RUN, row
 * by row), shaded with sky visibility 1 and kept in the viewer's sample image (srv_viewer.samples). A patch
 * is what one run of the effect's shade sees: its groups (pixels reading the same probes with one normal)
 * form within it. */
enum { SAMPLE_PATCH_TILES = 1 };

typedef struct sample_task {
    srv_loop *loop;
    srv_viewer *view;
    uint32_t block, stride, rows, patches_x;
} sample_task;

FXC_HOT_CLONES static void sample_patch(void *user, uint32_t task_index, uint32_t thread_index)
{
    const sample_task *task = user;
    srv_loop *loop = task->loop;
    srv_viewer *view = task->view;
    compose_scratch *cs = (compose_scratch *)((uint8_t *)loop->compose_scratch +
                                              (size_t)thread_index * loop->compose_scratch_bytes);
    compose_setup cu;
    compose_setup_init(loop, &cu);
    const uint32_t e = loop->coarse_effect, width = view->frame.width, block = task->block;
    const uint32_t per_tile = SRV_TILE / block, patch_w = per_tile * SAMPLE_PATCH_TILES, patch_h = per_tile;
    uint32_t gx0 = (task_index % task->patches_x) * patch_w, gy0 = (task_index / task->patches_x) * patch_h;
    uint32_t gx1 = gx0 + patch_w < task->stride ? gx0 + patch_w : task->stride;
    uint32_t gy1 = gy0 + patch_h < task->rows ? gy0 + patch_h : task->rows;
    float *values = view->samples;
    const size_t value_stride = view->sample_capacity;
    const uint64_t *bits = loop->viewer_bits[e];
    gather_memo memo = gather_memo_start();
    const uint32_t across = gx1 - gx0, n = across * (gy1 - gy0);
    for (uint32_t first = 0; first < n;) {
        uint32_t count = 0;
        for (; first < n && count < SRV_RUN; first++) {
            uint32_t gx = gx0 + first % across, gy = gy0 + first / across;
            size_t sample = (size_t)gy * task->stride + gx;
            for (uint32_t v = 0; v < SRV_SAMPLE_VALUES; v++)
                values[v * value_stride + sample] =
                    0.0f; /* and finite values: blend_row multiplies them by 0 */
            uint32_t x = gx * block, y = gy * block;
            size_t p = (size_t)y * width + x;
            if (view->tri[p] == SRV_MISS)
                continue;
            cs->sample_slot[count] = (uint32_t)sample;
            gather_pixel(loop, view, x, y, p, cs, &count, cu.sky, cu.log2_density, cu.positions, cu.points,
                         &memo);
        }
        if (!count)
            continue;
        kind_taps(loop, view, thread_index, cs->pixels, count, e, cs->taps, bits ? cs->blocks : NULL);
        for (uint32_t i = 0; i < count; i++) {
            cs->sky_visibility[i] = 1.0f;
            cs->indirect[3 * i] = cs->indirect[3 * i + 1] = cs->indirect[3 * i + 2] = 0.0f;
        }
        fx_shade_run run = {.count = count,
                            .taps = cs->taps,
                            .points = cs->points,
                            .sky_visibility = cs->sky_visibility,
                            .indirect = cs->indirect};
        loop->effects[e]->shade(&loop->fx, &run);
        for (uint32_t i = 0; i < count; i++) {
            size_t sample = cs->sample_slot[i];
            values[SRV_SAMPLE_OK * value_stride + sample] = cs->taps[i].count > 0 ? 1.0f : 0.0f;
            for (uint32_t k = 0; k < 3; k++)
                values[(SRV_SAMPLE_R + k) * value_stride + sample] = cs->indirect[3 * i + k];
            values[SRV_SAMPLE_SKY * value_stride + sample] = cs->sky_visibility[i];
            values[SRV_SAMPLE_SHARING * value_stride + sample] =
                bits && cs->blocks[i] != SRV_NONE ? (float)__builtin_popcountll(bits[cs->blocks[i]]) : 0.0f;
        }
    }
}

FXC_HOT_INLINE void shade_run(srv_loop *loop, srv_viewer *view, compose_scratch *cs, uint32_t count,
                              const compose_setup *cu, uint32_t thread_index, uint64_t *missing,
                              uint64_t *rays, const coarse_run *cr)
{
    const scene *s = loop->s;
    const uint32_t lights = cu->lights, stride = cu->stride;
    /* Every lane, also past the run (directional_lanes reads them): loops of a constant length. */
    for (uint32_t i = 0; i < SRV_RUN * stride; i++)
        cs->light_visibility[i] = 1.0f;
    for (uint32_t i = 0; i < SRV_RUN; i++) {
        cs->sky_visibility[i] = 1.0f;
        cs->missing[i] = 0;
        cs->sharing[i] = 0.0f;
    }
    for (uint32_t i = 0; i < 3 * SRV_RUN; i++)
        cs->indirect[i] = 0.0f;
    if (loop->desc.no_cache) {
        for (uint32_t i = 0; i < count; i++) {
            fx_shade_point sp = {.light_visibility = cs->light_visibility + (size_t)i * stride,
                                 .sky_visibility = &cs->sky_visibility[i],
                                 .indirect = &cs->indirect[3 * i]};
            for (uint32_t e = 0; e < loop->effect_count; e++)
                if (loop->effect_on[e] && loop->effects[e]->eval)
                    rays[e] += loop->effects[e]->eval(&loop->fx, &cs->points[i], &sp);
        }
    } else if (count) {
        fx_shade_run run = {.count = count,
                            .light_count = lights,
                            .taps = cs->taps,
                            .points = cu->points ? cs->points : NULL,
                            .light_visibility = cs->light_visibility,
                            .sky_visibility = cs->sky_visibility,
                            .indirect = cs->indirect};
        for (uint32_t e = 0; e < loop->effect_count; e++) {
            if (!loop->effect_shading[e])
                continue;
            if (cr && e == loop->coarse_effect) {
                coarse_shade(loop, view, cs, e, cr, cu, thread_index, count);
                continue;
            }
            /* This effect and the next ones that shade through the same kind at the same bias (up to the
             * coarse effect): their taps in one call, which does their shared per-pixel work once; then each
             * shades in the effects' order, as one at a time. */
            uint32_t k = loop->effect_kind[e], group[TAPS_GROUP], n = 0, last = e;
            fx_taps *group_taps[TAPS_GROUP];
            uint32_t *group_blocks[TAPS_GROUP];
            for (uint32_t f = e; f < loop->effect_count && n < TAPS_GROUP; f++) {
                if (!loop->effect_shading[f])
                    continue;
                if ((cr && f == loop->coarse_effect) || loop->effect_kind[f] != k ||
                    loop->bias[f] != loop->bias[e])
                    break;
                group[n] = f;
                group_taps[n] = cs->taps + (size_t)n * SRV_RUN;
                group_blocks[n] = loop->viewer_bits[f] ? cs->blocks + (size_t)n * SRV_RUN : NULL;
                n++;
                last = f;
            }
            uint32_t empty =
                loop->kinds[k]->pixel_taps(loop->caches[k], (uint32_t)(view - loop->viewers), thread_index,
                                           cs->pixels, cs->have_lanes ? &cs->pixel_lanes : NULL, count, n,
                                           group, loop->bias[e], group_taps, group_blocks);
            for (uint32_t j = 0; j < n; j++) {
                uint32_t g = group[j];
                const uint64_t *bits = loop->viewer_bits[g];
                const fx_taps *taps = group_taps[j];
                const uint32_t *blocks = group_blocks[j];
                run.taps = taps;
                loop->effects[g]->shade(&loop->fx, &run);
                if (bits) {
                    for (uint32_t i = 0; i < count; i++) {
                        cs->missing[i] |= taps[i].count == 0;
                        if (blocks[i] != SRV_NONE)
                            cs->sharing[i] =
                                fmaxf(cs->sharing[i], (float)__builtin_popcountll(bits[blocks[i]]));
                    }
                } else if (empty) { /* else every pixel has taps: nothing is missing */
                    for (uint32_t i = 0; i < count; i++)
                        cs->missing[i] |= taps[i].count == 0;
                }
            }
            e = last;
        }
    }
    /* The lights' irradiance, light by light over the run (each pixel sums its lights in the same order as
     * before): the constant directional ones in a loop of plain arithmetic. */
    for (uint32_t i = 0; i < SRV_RUN; i++)
        cs->irradiance[i][0] = cs->irradiance[i][1] = cs->irradiance[i][2] = 0.0f;
    for (uint32_t l = 0; l < lights; l++) {
        const scene_light *light = &s->lights[l];
        if (light->type == SCENE_LIGHT_DIRECTIONAL && l < CONSTANT_LIGHTS) {
            directional_lanes(cs, cu->light_dir[l], cu->light_rgb[l], stride, l);
            continue;
        }
        for (uint32_t i = 0; i < count; i++) {
            float ldir[3], dist;
            fx_light_direction(light, cs->points[i].position, ldir, &dist); /* cu->points holds them */
            float cosine = cs->shade_normal[0][i] * ldir[0] + cs->shade_normal[1][i] * ldir[1] +
                           cs->shade_normal[2][i] * ldir[2];
            if (!(cosine > 0))
                continue;
            float falloff = light->type == SCENE_LIGHT_POINT ? fx_point_falloff(dist) : 1.0f;
            float scale = fminf(
                light->intensity * cosine * cs->light_visibility[(size_t)i * stride + l] * falloff, FLT_MAX);
            for (int k = 0; k < 3; k++)
                cs->irradiance[i][k] += scale * light->color[k];
        }
    }
    for (uint32_t i = count; i < SRV_RUN; i++) { /* the lanes past the run: defined values */
        cs->sky_visibility[i] = 0.0f;
        for (int k = 0; k < 3; k++)
            cs->irradiance[i][k] = cs->indirect[3 * i + k] = cs->albedo[i][k] = 0.0f;
    }
    radiance_lanes(cs, cu->sky);
    if (s->emissive) /* emitting materials: a front face adds its own radiance (scene_emission_add) */
        for (uint32_t i = 0; i < count; i++)
            scene_emission_add(
                s, cs->triangle[i],
                (const float[3]){cs->shade_normal[0][i], cs->shade_normal[1][i], cs->shade_normal[2][i]},
                cs->radiance[i]);
    float *radiance = view->radiance; /* the stores below cannot change the viewer's pointers: loaded once */
    uint64_t missed = 0;
    for (uint32_t i = 0; i < count; i++) {
        memcpy(radiance + 3 * cs->index[i], cs->radiance[i], sizeof cs->radiance[i]);
        missed += cs->missing[i];
    }
    *missing += missed;
    float *views_ao = view->views[SRV_VIEW_AO], *views_shadow = view->views[SRV_VIEW_SHADOW],
          *views_sharing = view->views[SRV_VIEW_SHARING];
    if (views_ao) {
        for (uint32_t i = 0; i < count; i++) {
            size_t p = cs->index[i];
            views_ao[p] = cs->sky_visibility[i];
            views_shadow[p] = lights ? cs->light_visibility[(size_t)i * stride] : 1.0f;
            views_sharing[p] = cs->sharing[i];
        }
    }
}

static void compose_done(compose_task *task, const srv_loop *loop, uint64_t missing, const uint64_t *rays)
{
    atomic_fetch_add(&task->missing, missing);
    for (uint32_t e = 0; e < loop->effect_count; e++)
        if (rays[e])
            atomic_fetch_add(&task->rays[e], rays[e]);
}

FXC_HOT_CLONES static void compose_tile(void *user, uint32_t task_index, uint32_t thread_index)
{
    compose_task *task = user;
    srv_loop *loop = task->loop;
    srv_viewer *view = task->view;
    const srv_camera_frame *f = &view->frame;
    compose_scratch *cs = (compose_scratch *)((uint8_t *)loop->compose_scratch +
                                              (size_t)thread_index * loop->compose_scratch_bytes);
    uint64_t missing = 0, rays[SRV_MAX_EFFECTS] = {0};
    compose_setup cu;
    compose_setup_init(loop, &cu);
    /* A 16 x 16 tile in runs of 4 rows x 16 columns: neighbouring pixels read the same blocks and texels. */
    uint32_t tiles_x = (f->width + SRV_TILE - 1) / SRV_TILE;
    uint32_t tx0 = (task_index % tiles_x) * SRV_TILE, ty0 = (task_index / tiles_x) * SRV_TILE;
    uint32_t tx1 = tx0 + SRV_TILE < f->width ? tx0 + SRV_TILE : f->width;
    uint32_t ty1 = ty0 + SRV_TILE < f->height ? ty0 + SRV_TILE : f->height;
    srv_coarse_grid grid;
    uint32_t block = srv__coarse_block(loop, view);
    bool coarse = block > 1;
    size_t sample_stride = srv__sample_stride(f->width, block);
    if (coarse)
        srv__coarse_grid(block, tx0, ty0, f->width, f->height, &grid);
    /* A coarse tile's runs gather positions only for the other effects (the pixels evaluated themselves get
     * theirs in coarse_shade). */
    compose_setup run_setup = cu;
    if (coarse) {
        run_setup.positions = cu.positions_other;
        run_setup.points = cu.points_other;
        run_setup.pixels = cu.pixels_other;
    }
    for (uint32_t ry = ty0; ry < ty1; ry += SRV_RUN / SRV_TILE) {
        uint32_t ry1 = ry + SRV_RUN / SRV_TILE < ty1 ? ry + SRV_RUN / SRV_TILE : ty1;
        uint32_t count = run_setup.points ? gather_run(loop, view, tx0, tx1, ry, ry1, cs, cu.sky,
                                                       cu.log2_density, run_setup.positions, run_setup.points)
                                          : gather_tile_run(loop, view, tx0, tx1, ry, ry1, cs, cu.sky,
                                                            cu.log2_density, run_setup.pixels);
        coarse_run cr = {.g = &grid,
                         .x0 = tx0,
                         .x1 = tx1,
                         .y0 = ry,
                         .y1 = ry1,
                         .values = view->samples,
                         .value_stride = view->sample_capacity,
                         .stride = sample_stride,
                         .first = (size_t)(ty0 / block) * sample_stride + tx0 / block};
        shade_run(loop, view, cs, count, &run_setup, thread_index, &missing, rays, coarse ? &cr : NULL);
        for (uint32_t y = ry; y < ry1; y++) {
            size_t p = (size_t)y * f->width + tx0;
            srv__tone_map_row(view->radiance + 3 * p, view->image + 3 * p, 3 * (tx1 - tx0));
        }
    }
    compose_done(task, loop, missing, rays);
}

enum { LIST_RUNS = 4 }; /* runs of SRV_RUN list entries per compose task of a sparse viewer */

/* A sparse viewer: LIST_RUNS runs of its list, the same shading as a tile's runs (and the same clone, so the
 * same arithmetic as a whole frame's). */
FXC_HOT_CLONES static void compose_list_task(void *user, uint32_t task_index, uint32_t thread_index)
{
    compose_task *task = user;
    srv_loop *loop = task->loop;
    srv_viewer *view = task->view;
    compose_scratch *cs = (compose_scratch *)((uint8_t *)loop->compose_scratch +
                                              (size_t)thread_index * loop->compose_scratch_bytes);
    uint64_t missing = 0, rays[SRV_MAX_EFFECTS] = {0};
    compose_setup cu;
    compose_setup_init(loop, &cu);
    size_t first = (size_t)task_index * LIST_RUNS * SRV_RUN, end = first + (size_t)LIST_RUNS * SRV_RUN;
    if (end > view->list_count)
        end = view->list_count;
    uint32_t tiles_x = (view->frame.width + SRV_TILE - 1) / SRV_TILE;
    for (size_t run = first, run_end; run < end; run = run_end) {
        /* The entries of one whole-frame run (srv__run_key's order keeps them together). */
        uint32_t run_index = srv__run_key(view->list[run], tiles_x) >> 6;
        for (run_end = run + 1;
             run_end < end && srv__run_key(view->list[run_end], tiles_x) >> 6 == run_index;)
            run_end++;
        uint32_t count =
            gather_list(loop, view, run, run_end, cs, cu.sky, cu.log2_density, cu.positions, cu.points);
        shade_run(loop, view, cs, count, &cu, thread_index, &missing, rays, NULL);
        srv__tone_map_row(view->radiance + 3 * run, view->image + 3 * run, (uint32_t)(3 * (run_end - run)));
    }
    compose_done(task, loop, missing, rays);
}

void srv__compose(srv_loop *loop, uint32_t slot, srv_frame_stats *st)
{
    srv__tone_map_init();
    srv_viewer *view = &loop->viewers[slot];
    compose_task task = {.loop = loop, .view = view};
    atomic_init(&task.missing, 0);
    for (uint32_t e = 0; e < SRV_MAX_EFFECTS; e++)
        atomic_init(&task.rays[e], 0);
    if (view->sparse) {
        uint32_t per_task = LIST_RUNS * SRV_RUN;
        srv_pool_run(loop->pool, (view->list_count + per_task - 1) / per_task, compose_list_task, &task);
    } else {
        uint32_t tiles = ((view->frame.width + SRV_TILE - 1) / SRV_TILE) *
                         ((view->frame.height + SRV_TILE - 1) / SRV_TILE);
        uint32_t block = srv__coarse_block(loop, view);
        if (block > 1) { /* the block samples, once per frame, before the tiles blend them */
            sample_task samples = {.loop = loop,
                                   .view = view,
                                   .block = block,
                                   .stride = srv__sample_stride(view->frame.width, block),
                                   .rows = srv__sample_stride(view->frame.height, block)};
            uint32_t patch_w = SRV_TILE / block * SAMPLE_PATCH_TILES, patch_h = SRV_TILE / block;
            samples.patches_x = (samples.stride + patch_w - 1) / patch_w;
            srv_pool_run(loop->pool, samples.patches_x * ((samples.rows + patch_h - 1) / patch_h),
                         sample_patch, &samples);
        }
        /* Each thread a contiguous half of the tiles (in order), then the other's last tiles: tiles handed out
         * one by one alternated between the threads, which then wrote neighbouring tiles' rows of the image
         * (48 bytes of a 64-byte line) and of the radiance at the same time, and each read half of the texel
         * blocks its neighbours had just read. */
        srv_pool_run_static(loop->pool, tiles, compose_tile, &task, true);
    }
    view->stats.pixels_missing = atomic_load(&task.missing);
    for (uint32_t e = 0; e < loop->effect_count; e++)
        st->rays[e] += atomic_load(&task.rays[e]);
}
