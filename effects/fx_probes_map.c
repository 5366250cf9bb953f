/* The probe effect's maps and their readers (see fx_probes.c for the payload, the units and the update):
 * octahedral directions and bilinear reads, spherical Fibonacci directions, a probe's irradiance and moments,
 * the DDGI shading filter (trilinear x wrap x Chebyshev weights), a per-thread memo of irradiance within a
 * frame, and compose's shade over runs of pixels. Everything here only reads payloads. */
#include "fx_probes_internal.h"
#include "fxc_hot.h"

/* ---- directions ------------------------------------------------------------------------------------ */

FXC_HOT_INLINE float sign_nonzero(float x)
{
    return x >= 0 ? 1.0f : -1.0f;
}

/* Inlined into compose's shade copies (FXC_HOT_INLINE); fx_probe_oct_encode is the same code as a function. */
FXC_HOT_INLINE void oct_encode_inline(const float dir[3], float uv[2])
{
    float l1 = fabsf(dir[0]) + fabsf(dir[1]) + fabsf(dir[2]);
    float x = l1 > 0 ? dir[0] / l1 : 0.0f, y = l1 > 0 ? dir[1] / l1 : 0.0f;
    if (dir[2] < 0) {
        float fx = (1.0f - fabsf(y)) * sign_nonzero(x), fy = (1.0f - fabsf(x)) * sign_nonzero(y);
        x = fx, y = fy;
    }
    uv[0] = x;
    uv[1] = y;
}

void fx_probe_oct_encode(const float dir[3], float uv[2])
{
    oct_encode_inline(dir, uv);
}

void fx_probe_oct_decode(const float uv[2], float dir[3])
{
    float x = uv[0], y = uv[1], z = 1.0f - fabsf(x) - fabsf(y);
    if (z < 0) {
        float fx = (1.0f - fabsf(y)) * sign_nonzero(x), fy = (1.0f - fabsf(x)) * sign_nonzero(y);
        x = fx, y = fy;
    }
    float len = sqrtf(x * x + y * y + z * z);
    dir[0] = x / len;
    dir[1] = y / len;
    dir[2] = z / len;
}

void fx_probe_fibonacci(uint32_t i, uint32_t n, float dir[3])
{
    /* DDGI's sphericalFibonacci: phi = 2 pi frac(i (golden ratio - 1)), cos theta = 1 - (2 i + 1) / n. */
    double turns = (double)i * 0.6180339887498949;
    turns -= floor(turns);
    float cos_theta = 1.0f - (2.0f * (float)i + 1.0f) / (float)n;
    float sin_theta = sqrtf(fmaxf(0.0f, 1.0f - cos_theta * cos_theta));
    float s, c;
    fx__sincos_turns((float)turns, &s, &c);
    dir[0] = c * sin_theta;
    dir[1] = s * sin_theta;
    dir[2] = cos_theta;
}

/* The 64 texel-centre directions of the map. */
void fx__probe_texel_dirs(float dirs[FX_PROBE_TEXELS][3])
{
    for (uint32_t t = 0; t < FX_PROBE_TEXELS; t++) {
        float uv[2] = {((float)(t % FX_PROBE_MAP) + 0.5f) * 0.25f - 1.0f,
                       ((float)(t / FX_PROBE_MAP) + 0.5f) * 0.25f - 1.0f};
        fx_probe_oct_decode(uv, dirs[t]);
    }
}

/* The four texels and bilinear weights of direction dir in the 8 x 8 map; neighbours past an edge of the
 * square wrap as the octahedron does (the edge is mirrored about its midpoint; a corner's neighbour is the
 * opposite corner), i.e. DDGI's border texels without storing them. Inlined into compose's shade copies;
 * oct_bilinear below is the same code as a function for the other readers. */
FXC_HOT_INLINE void oct_bilinear_inline(const float dir[3], uint32_t texel[4], float weight[4])
{
    float uv[2];
    oct_encode_inline(dir, uv);
    float fx = (uv[0] + 1.0f) * 4.0f - 0.5f, fy = (uv[1] + 1.0f) * 4.0f - 0.5f;
    float x0 = floorf(fx), y0 = floorf(fy);
    float wx = fx - x0, wy = fy - y0;
    for (int c = 0; c < 4; c++) {
        int x = (int)x0 + (c & 1), y = (int)y0 + (c >> 1);
        if (y < 0 || y > 7) {
            y = y < 0 ? 0 : 7;
            x = 7 - x;
        }
        if (x < 0 || x > 7) {
            x = x < 0 ? 0 : 7;
            y = 7 - y;
        }
        x = x < 0 ? 0 : (x > 7 ? 7 : x); /* only reached for NaN input */
        y = y < 0 ? 0 : (y > 7 ? 7 : y);
        texel[c] = (uint32_t)(y * FX_PROBE_MAP + x);
        weight[c] = ((c & 1) ? wx : 1.0f - wx) * ((c >> 1) ? wy : 1.0f - wy);
    }
}

static void oct_bilinear(const float dir[3], uint32_t texel[4], float weight[4])
{
    oct_bilinear_inline(dir, texel, weight);
}

void fx__probe_oct_bilinear(const float dir[3], uint32_t texel[4], float weight[4])
{
    oct_bilinear(dir, texel, weight);
}

/* ---- reading payloads -------------------------------------------------------------------------------- */

void fx_probe_info_read(const void *payload, fx_probe_info *out)
{
    const uint8_t *p = payload;
    for (int k = 0; k < 3; k++)
        out->position[k] = get_f32(p + 4 * k);
    out->cell = get_f32(p + 12);
    uint32_t flags = get_u32(p + 16);
    out->flags = flags & 0xffffu;
    uint32_t updates_word = get_u32(p + 20);
    out->updates = updates_word & 0xffffu;
    out->drift_mean = half_to_float((uint16_t)(flags >> 16));
    out->drift_variance = half_to_float((uint16_t)(updates_word >> 16));
    out->backface_fraction = get_f32(p + 28);
}

void fx_probe_irradiance(const void *payload, const float dir[3], float out_rgb[3])
{
    const uint8_t *p = payload;
    uint32_t texel[4];
    float weight[4];
    oct_bilinear(dir, texel, weight);
    float scale = get_f32(p + 24);
    out_rgb[0] = out_rgb[1] = out_rgb[2] = 0;
    for (int c = 0; c < 4; c++)
        for (int k = 0; k < 3; k++)
            out_rgb[k] += weight[c] * half_to_float(fx__get_u16(p + PROBE_IRRADIANCE + 6 * texel[c] + 2 * k));
    for (int k = 0; k < 3; k++)
        out_rgb[k] *= scale;
}

/* The moments (mean distance, mean squared distance, metres) of a probe in direction dir, bilinear. */
static void probe_moments(const uint8_t *p, const float dir[3], float cell, float *mean, float *mean2)
{
    uint32_t texel[4];
    float weight[4];
    oct_bilinear(dir, texel, weight);
    float m1 = 0, m2 = 0;
    for (int c = 0; c < 4; c++) {
        m1 += weight[c] * half_to_float(fx__get_u16(p + PROBE_MOMENTS + 4 * texel[c]));
        m2 += weight[c] * half_to_float(fx__get_u16(p + PROBE_MOMENTS + 4 * texel[c] + 2));
    }
    *mean = m1 * cell;
    *mean2 = m2 * cell * cell;
}

/* A probe's weight for a point before the trilinear one: DDGI's wrap term times the Chebyshev visibility
 * bound (when `visibility`), small weights crushed; 0 for a probe without data or switched off. Update hits
 * need the visibility term too: without it the thin-wall test's dark room gets 2.3 % of the lit room's light
 * through the bounce (measured), over its 2 % bound. */
static float probe_weight(const uint8_t *p, const float position[3], const float normal[3], bool visibility)
{
    uint32_t flags = get_u32(p + 16);
    if (!(flags & FX_PROBE_HAS_DATA) || (flags & FX_PROBE_OFF))
        return 0.0f;
    float probe[3], cell = get_f32(p + 12);
    for (int k = 0; k < 3; k++)
        probe[k] = get_f32(p + 4 * k);
    /* DDGI's wrap shading: probes behind the surface count less, never nothing. */
    float to_probe[3], biased_to_probe[3], len2 = 0, biased_len2 = 0;
    for (int k = 0; k < 3; k++) {
        to_probe[k] = probe[k] - position[k];
        biased_to_probe[k] = probe[k] - (position[k] + normal[k] * FX_PROBE_NORMAL_BIAS * cell);
        len2 += to_probe[k] * to_probe[k];
        biased_len2 += biased_to_probe[k] * biased_to_probe[k];
    }
    float len = sqrtf(len2), wrap = len > 0 ? (fx__dot(to_probe, normal) / len + 1.0f) * 0.5f : 1.0f;
    float weight = wrap * wrap + 0.2f;
    /* Chebyshev's bound on the probe seeing the (biased) point, from the moments towards it. */
    float distance = sqrtf(biased_len2);
    if (visibility && distance > 0) {
        float from_probe[3];
        for (int k = 0; k < 3; k++)
            from_probe[k] = -biased_to_probe[k] / distance;
        float mean, mean2;
        probe_moments(p, from_probe, cell, &mean, &mean2);
        float chebyshev = 1.0f;
        if (distance > mean) {
            float variance = fabsf(mean2 - mean * mean), excess = distance - mean;
            chebyshev = variance / (variance + excess * excess);
            chebyshev = chebyshev * chebyshev * chebyshev;
        }
        weight *= fmaxf(0.05f, chebyshev);
    }
    weight = fmaxf(weight, 1e-6f);
    if (weight < 0.2f) /* DDGI: crush small weights, so light leaking through a wall fades quickly */
        weight *= weight * weight / (0.2f * 0.2f);
    return weight;
}

/* Irradiance of a probe towards a normal, kept per thread for the frame (ctx->frame): runs of one frame
 * meet the same probes with the same normals again and again, and within a frame a payload does not change
 * (commits run after every update and before compose). Exact: a hit returns what fx_probe_irradiance would. */
enum { IRRADIANCE_MEMO = 256 };
typedef struct irradiance_memo {
    const void *probe;
    uint64_t
        epoch; /* ctx->epoch: a later loop's payload may sit at a freed one's address, on the same frame */
    uint32_t frame;
    float normal[3];
    float e[3];
} irradiance_memo;
static _Thread_local irradiance_memo irradiance_memo_table[IRRADIANCE_MEMO];

static void probe_irradiance_memo(const fx_context *ctx, bool committed, const void *probe,
                                  const float normal[3], float e[3])
{
    /* Without a loop's epoch (0: test harnesses) the entries could not tell two loops apart (a freed loop's
     * payload address reused, the same frame numbers): no memo then. */
    if (!ctx || ctx->frame == 0 || ctx->epoch == 0) {
        fx_probe_irradiance(probe, normal, e);
        return;
    }
    /* Updates read the payloads before this frame's commits, compose after them: two generations a frame. */
    uint32_t generation = ctx->frame * 2u + (committed ? 1u : 0u);
    uint32_t bits[3];
    memcpy(bits, normal, sizeof bits);
    uint64_t h = (uint64_t)(uintptr_t)probe * 0x9E3779B97F4A7C15ull ^ (bits[0] * 0x85EBCA6Bu) ^
                 (bits[1] * 0xC2B2AE35u) ^ ((uint64_t)bits[2] << 17);
    irradiance_memo *m = &irradiance_memo_table[(h ^ (h >> 29)) & (IRRADIANCE_MEMO - 1)];
    if (m->probe == probe && m->epoch == ctx->epoch && m->frame == generation && m->normal[0] == normal[0] &&
        m->normal[1] == normal[1] && m->normal[2] == normal[2]) {
        memcpy(e, m->e, sizeof m->e);
        return;
    }
    fx_probe_irradiance(probe, normal, e);
    m->probe = probe;
    m->epoch = ctx->epoch;
    m->frame = generation;
    memcpy(m->normal, normal, sizeof m->normal);
    memcpy(m->e, e, sizeof m->e);
}

/* The DDGI filter at a point: each probe with data and not off weighted by its trilinear tap weight x wrap x
 * Chebyshev visibility, renormalised; each probe's irradiance towards the normal from the per-thread memo. */
bool fx__probe_filter_memo(const fx_context *ctx, bool committed, const fx_taps *taps,
                           const float position[3], const float normal[3], float out_rgb[3])
{
    float sum[3] = {0, 0, 0}, total = 0;
    for (uint32_t t = 0; t < taps->count; t++) {
        const uint8_t *p = taps->texel[t];
        if (!(taps->weight[t] > 0))
            continue;
        float weight = probe_weight(p, position, normal, true);
        if (weight == 0.0f)
            continue;
        weight *= taps->weight[t];
        float e[3];
        probe_irradiance_memo(ctx, committed, p, normal, e);
        for (int k = 0; k < 3; k++)
            sum[k] += weight * e[k];
        total += weight;
    }
    if (!(total > 0)) {
        out_rgb[0] = out_rgb[1] = out_rgb[2] = 0;
        return false;
    }
    for (int k = 0; k < 3; k++)
        out_rgb[k] = fminf(sum[k] / total, FLT_MAX);
    return true;
}

/* Adds E / pi of the probes around each pixel. The sky is in E (missed probe rays return it), so the
 * separate sky term goes to 0; what an effect shading before this one left in sky_visibility (ambient
 * occlusion: the fraction of the hemisphere open within its radius) scales E instead, the way engines
 * apply AO to indirect diffuse light. Without AO it is 1 and E goes in whole. Both modes do the same.
 *
 * The back of a single-sided surface (a pixel whose view_normal is against its triangle's normal) reads only
 * the probes on its own side of the surface's plane. The probes there see that surface's back, so they are off
 * (or moved out through it), and DDGI's renormalisation gave the back the whole light of the probes on the
 * other side, however small their weights: the outside of a room of inward faces showed the room's light (the
 * Cornell box's floor seen from below, its ceiling from above; tests/test_probes_sides.c). With no probe on
 * its side the pixel keeps the sky term (what the reference's paths from there see, less what they would meet
 * in the scene). Front faces are as DDGI has them: a probe behind one is usually in a solid.
 *
 * Cost. The filter of one pixel reads 8 probes, each twice (irradiance towards the normal, moments towards
 * the point) and weighs each with a Chebyshev bound: too much to do per pixel (bench_probes). Pixels of a
 * run that read the same 8 probes (the same cell) and face the same way (the same normal: one triangle or
 * coplanar ones) form a group. Per group the probes' irradiance towards the normal is read once (exact: it
 * depends on nothing else) and each probe's wrap and Chebyshev weight is taken once, at the group's mean
 * position; per pixel only the trilinear weights change. A group spans at most 4 x 16 pixels, much less than
 * a cell (cells are about distance/16 wide, 16 pixels about distance/40 at 640 pixels and 60 degrees), so
 * the visibility weights barely move within it. A group of one pixel is exactly the filter of fx__probe_filter_memo
 * (for a front face; the filter knows no sides). */
enum { SHADE_GROUPS = 16 };

typedef struct shade_group {
    const void *texel[FX_MAX_TAPS]; /* its taps' probes, in order: with the normal, what a group shares */
    uint32_t count;
    float normal[3];
    bool back; /* its pixels see their triangles' backs (fx_point.normal against view_normal) */
    float position_sum[3];
    uint32_t pixels;
    /* Per tap: its wrap x Chebyshev weight w at the mean position times its irradiance towards the normal
     * (RGB), and w: a pixel's sum is then one 4-wide multiply-add per tap. */
    _Alignas(16) float weighted[FX_MAX_TAPS][4];
} shade_group;

static bool same_group(const shade_group *g, const fx_taps *taps, const float normal[3], bool back)
{
    /* Normals within 1e-3 per component (0.06 degrees) count as one: coplanar triangles of a wall have
     * normals that differ in their last bits, and the irradiance cannot tell them apart. */
    if (g->count != taps->count || g->texel[0] != taps->texel[0] || g->back != back ||
        fabsf(g->normal[0] - normal[0]) > 1e-3f || fabsf(g->normal[1] - normal[1]) > 1e-3f ||
        fabsf(g->normal[2] - normal[2]) > 1e-3f)
        return false;
    return memcmp(g->texel + 1, taps->texel + 1, (taps->count - 1) * sizeof taps->texel[0]) == 0;
}

/* Pass 2 of compose's shade for one group's taps, PROBE_LANES probes at a time: each probe's weight (probe_weight
 * with visibility at the group's mean position and normal) times its irradiance towards the normal
 * (fx_probe_irradiance, the normal's four texels and weights `texel`, `bilinear` found once for the group), and
 * the weight, into out[0..2][l] (RGB) and out[3][l]. Lane by lane without branches so that the AVX2 copy runs the
 * probes as one vector: the same operations on the same floats as those two functions, so the same results
 * (the stored halves are >= 0, where half_bits_to_float is half_to_float). The payload loads are the only
 * scalar part. Lanes at and beyond n, and probes without data or off, give 0. */
enum { PROBE_LANES = 8 };

FXC_HOT_CLONES static void group_weights_lanes(const void *const *probe, uint32_t n, const float position[3],
                                               const float normal[3], bool back, const uint32_t texel_n[4],
                                               const float bilinear_n[4], float out[4][PROBE_LANES])
{
    const float px = position[0], py = position[1], pz = position[2];
    const float nx = normal[0], ny = normal[1], nz = normal[2];
    float qx[PROBE_LANES], qy[PROBE_LANES], qz[PROBE_LANES], cell[PROBE_LANES], scale[PROBE_LANES];
    int32_t live[PROBE_LANES];
    for (uint32_t l = 0; l < PROBE_LANES; l++) {
        const uint8_t *p = probe[l < n ? l : 0];
        uint32_t flags = get_u32(p + 16);
        live[l] = l < n && (flags & FX_PROBE_HAS_DATA) && !(flags & FX_PROBE_OFF);
        qx[l] = get_f32(p);
        qy[l] = get_f32(p + 4);
        qz[l] = get_f32(p + 8);
        cell[l] = get_f32(p + 12);
        scale[l] = get_f32(p + 24);
    }
    /* Each loop over the lanes is innermost (GCC vectorises only those): per lane the same operations in
     * the same order as probe_weight and fx_probe_irradiance. */
    float weight[PROBE_LANES], distance[PROBE_LANES], wx[PROBE_LANES], wy[PROBE_LANES];
    int32_t ix0[PROBE_LANES], iy0[PROBE_LANES];
    for (uint32_t l = 0; l < PROBE_LANES; l++) {
        float tx = qx[l] - px, ty = qy[l] - py, tz = qz[l] - pz;
        float bx = qx[l] - (px + nx * FX_PROBE_NORMAL_BIAS * cell[l]);
        float by = qy[l] - (py + ny * FX_PROBE_NORMAL_BIAS * cell[l]);
        float bz = qz[l] - (pz + nz * FX_PROBE_NORMAL_BIAS * cell[l]);
        float len2 = tx * tx + ty * ty + tz * tz, biased_len2 = bx * bx + by * by + bz * bz;
        float len = sqrtf(len2), side = tx * nx + ty * ny + tz * nz;
        float wrap = len > 0 ? (side / (len > 0 ? len : 1.0f) + 1.0f) * 0.5f : 1.0f;
        weight[l] = wrap * wrap + 0.2f;
        live[l] = back && !(side > 0) ? 0 : live[l]; /* a back's probes: only those on its viewer's side */
        float d = sqrtf(biased_len2);
        distance[l] = d;
        /* oct_bilinear of the direction from the probe to the biased point */
        float safe = d > 0 ? d : 1.0f;
        float x = -bx / safe, y = -by / safe, z = -bz / safe;
        float l1 = fabsf(x) + fabsf(y) + fabsf(z), l1_safe = l1 > 0 ? l1 : 1.0f;
        float ox = l1 > 0 ? x / l1_safe : 0.0f, oy = l1 > 0 ? y / l1_safe : 0.0f;
        float fold_x = (1.0f - fabsf(oy)) * (ox >= 0 ? 1.0f : -1.0f),
              fold_y = (1.0f - fabsf(ox)) * (oy >= 0 ? 1.0f : -1.0f);
        float u = z < 0 ? fold_x : ox, v = z < 0 ? fold_y : oy;
        float fu = (u + 1.0f) * 4.0f - 0.5f, fv = (v + 1.0f) * 4.0f - 0.5f;
        float x0 = floorf(fu), y0 = floorf(fv);
        wx[l] = fu - x0;
        wy[l] = fv - y0;
        ix0[l] = (int32_t)x0;
        iy0[l] = (int32_t)y0;
    }
    float bilinear[4][PROBE_LANES];
    int32_t texel[4][PROBE_LANES];
    for (int c = 0; c < 4; c++)
        for (uint32_t l = 0; l < PROBE_LANES; l++) {
            int32_t cx = ix0[l] + (c & 1), cy = iy0[l] + (c >> 1);
            int32_t out_y = cy < 0 || cy > 7;
            int32_t wrap_x = out_y ? 7 - cx : cx, wrap_y = out_y ? (cy < 0 ? 0 : 7) : cy;
            int32_t out_x = wrap_x < 0 || wrap_x > 7;
            int32_t tex_x = out_x ? (wrap_x < 0 ? 0 : 7) : wrap_x, tex_y = out_x ? 7 - wrap_y : wrap_y;
            tex_x = tex_x < 0 ? 0 : (tex_x > 7 ? 7 : tex_x); /* only reached for NaN input */
            tex_y = tex_y < 0 ? 0 : (tex_y > 7 ? 7 : tex_y);
            texel[c][l] = tex_y * FX_PROBE_MAP + tex_x;
            bilinear[c][l] = ((c & 1) ? wx[l] : 1.0f - wx[l]) * ((c >> 1) ? wy[l] : 1.0f - wy[l]);
        }
    /* The payload loads (scalar), their offsets found first: per lane the moments' texels, and the normal's
     * texels, the same for every probe */
    int32_t moment_at[4][PROBE_LANES];
    for (int c = 0; c < 4; c++)
        for (uint32_t l = 0; l < PROBE_LANES; l++)
            moment_at[c][l] = PROBE_MOMENTS + 4 * texel[c][l];
    const uint32_t irradiance_at[4] = {PROBE_IRRADIANCE + 6 * texel_n[0], PROBE_IRRADIANCE + 6 * texel_n[1],
                                       PROBE_IRRADIANCE + 6 * texel_n[2], PROBE_IRRADIANCE + 6 * texel_n[3]};
    uint32_t moments[4][PROBE_LANES], irradiance[4][3][PROBE_LANES];
    for (uint32_t l = 0; l < PROBE_LANES; l++) {
        const uint8_t *p = probe[l < n ? l : 0];
#pragma GCC unroll 4
        for (int c = 0; c < 4; c++) {
            moments[c][l] = get_u32(p + moment_at[c][l]);
            const uint8_t *at = p + irradiance_at[c];
            irradiance[c][0][l] = fx__get_u16(at);
            irradiance[c][1][l] = fx__get_u16(at + 2);
            irradiance[c][2][l] = fx__get_u16(at + 4);
        }
    }
    float m1[PROBE_LANES] = {0}, m2[PROBE_LANES] = {0}, e[3][PROBE_LANES] = {{0}};
    for (int c = 0; c < 4; c++) {
        for (uint32_t l = 0; l < PROBE_LANES; l++) {
            m1[l] += bilinear[c][l] * half_bits_to_float(moments[c][l] & 0xffffu);
            m2[l] += bilinear[c][l] * half_bits_to_float(moments[c][l] >> 16);
        }
        for (int k = 0; k < 3; k++)
            for (uint32_t l = 0; l < PROBE_LANES; l++)
                e[k][l] += bilinear_n[c] * half_bits_to_float(irradiance[c][k][l]);
    }
    for (uint32_t l = 0; l < PROBE_LANES; l++) {
        float w = probe_visibility_weight(weight[l], m1[l] * cell[l], m2[l] * cell[l] * cell[l], distance[l]);
        w = live[l] ? w : 0.0f;
        out[0][l] = w * (w > 0 ? e[0][l] * scale[l] : 0.0f);
        out[1][l] = w * (w > 0 ? e[1][l] * scale[l] : 0.0f);
        out[2][l] = w * (w > 0 ? e[2][l] * scale[l] : 0.0f);
        out[3][l] = w;
    }
}

FXC_HOT_CLONES void fx__probes_shade(const fx_context *ctx, const fx_shade_run *run)
{
    (void)
        ctx; /* the probes' irradiance is read directly, without the per-thread memo of fx__probe_filter_memo */
    shade_group groups[SHADE_GROUPS];
    uint8_t group_of[FX_RUN_PIXELS];
    uint32_t group_count = 0;
    uint32_t done = 0; /* pixels before this one are shaded; the rest wait for the next pass */
    while (done < run->count) {
        /* Pass 1: assign pixels to groups until the group table is full. */
        group_count = 0;
        uint32_t end = done, last = 0; /* the group of the pixel before: usually this one's too */
        for (; end < run->count; end++) {
            const fx_taps *taps = &run->taps[end];
            group_of[end] = 0xFF;
            if (taps->count == 0)
                continue;
            const float *n = run->points[end].view_normal, *geometric = run->points[end].normal;
            bool back = n[0] * geometric[0] + n[1] * geometric[1] + n[2] * geometric[2] < 0;
            uint32_t g = last;
            if (!(g < group_count && same_group(&groups[g], taps, n, back)))
                for (g = 0; g < group_count && !same_group(&groups[g], taps, n, back);)
                    g++;
            last = g;
            if (g == group_count) {
                if (group_count == SHADE_GROUPS)
                    break;
                shade_group *ng = &groups[group_count++];
                memcpy(ng->texel, taps->texel, taps->count * sizeof taps->texel[0]);
                ng->count = taps->count;
                memcpy(ng->normal, n, sizeof ng->normal);
                ng->back = back;
                ng->position_sum[0] = ng->position_sum[1] = ng->position_sum[2] = 0;
                ng->pixels = 0;
            }
            group_of[end] = (uint8_t)g;
            for (int k = 0; k < 3; k++)
                groups[g].position_sum[k] += run->points[end].position[k];
            groups[g].pixels++;
        }
        /* Pass 2: per group, each tap's weight at the mean position and irradiance towards the normal. The
         * taps of a group are the same probes in the same order (same cell), whichever pixel is asked. The
         * weights PROBE_LANES probes at a time; the normal's octahedral texels once for all its probes (the
         * sums of fx_probe_irradiance, the same floats). */
        for (uint32_t g = 0; g < group_count; g++) {
            shade_group *sg = &groups[g];
            uint32_t sample = done;
            while (group_of[sample] != g)
                sample++;
            const fx_taps *taps = &run->taps[sample];
            float mean[3];
            for (int k = 0; k < 3; k++)
                mean[k] = sg->pixels == 1 ? run->points[sample].position[k]
                                          : sg->position_sum[k] / (float)sg->pixels;
            uint32_t texel[4];
            float bilinear[4];
            oct_bilinear_inline(sg->normal, texel, bilinear);
            for (uint32_t t = 0; t < taps->count; t += PROBE_LANES) {
                uint32_t lanes = taps->count - t < PROBE_LANES ? taps->count - t : PROBE_LANES;
                float out[4][PROBE_LANES];
                group_weights_lanes(taps->texel + t, lanes, mean, sg->normal, sg->back, texel, bilinear, out);
                for (uint32_t l = 0; l < lanes; l++)
                    for (int k = 0; k < 4; k++)
                        sg->weighted[t + l][k] = out[k][l];
            }
        }
        /* Pass 3: per pixel, the trilinear weights. */
        for (uint32_t i = done; i < end; i++) {
            if (group_of[i] == 0xFF)
                continue;
            const shade_group *sg = &groups[group_of[i]];
            const fx_taps *taps = &run->taps[i];
            float acc[4] = {0, 0, 0, 0}; /* RGB, then the total weight */
            for (uint32_t t = 0; t < taps->count; t++) {
                float w = taps->weight[t];
                for (int k = 0; k < 4; k++)
                    acc[k] += w * sg->weighted[t][k];
            }
            float sum[3] = {acc[0], acc[1], acc[2]}, total = acc[3];
            if (!(total > 0))
                continue;
            float open = run->sky_visibility[i] * (1.0f / FX_PROBE_PI) / total;
            for (int k = 0; k < 3; k++) {
                float term = sum[k] * open;
                run->indirect[3 * i + k] +=
                    term < FLT_MAX ? term : FLT_MAX; /* fminf(term, FLT_MAX), NaN included */
            }
            run->sky_visibility[i] = 0.0f;
        }
        done = end;
    }
}
