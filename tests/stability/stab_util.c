/* The stability suite's shared checker and helpers: see stab_util.h. White-box: the payload walk reaches the
 * caches through the engine's cache kinds (engine_internal.h), and decodes each built-in effect's payload
 * from the layout its header documents (effects.h), byte by byte, independently of the effect's own code. */
#include "stab_util.h"

#include "engine_internal.h"
#include "scene_internal.h"

#include <float.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* ---- payload decoding (effects.h's layouts) ------------------------------------------------------------ */

static uint32_t le_u16(const uint8_t *p)
{
    return (uint32_t)p[0] | (uint32_t)p[1] << 8;
}

static uint32_t le_u32(const uint8_t *p)
{
    return (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24;
}

static float le_f32(const uint8_t *p)
{
    uint32_t bits = le_u32(p);
    float f;
    memcpy(&f, &bits, sizeof f);
    return f;
}

/* A binary16 as a double (subnormals included); NAN for infinities and NaNs, so isfinite() tells. */
static double half_value(uint32_t h)
{
    uint32_t exponent = (h >> 10) & 0x1f, mantissa = h & 0x3ff;
    double sign = (h & 0x8000) ? -1.0 : 1.0;
    if (exponent == 0x1f)
        return NAN;
    if (exponent == 0)
        return sign * ldexp((double)mantissa, -24);
    return sign * ldexp(1.0 + mantissa / 1024.0, (int)exponent - 15);
}

/* The lookup texel of `block` (an on-surface effect's block) for its texel t, or false when the block of the
 * effect it depends on is not resident. */
static bool lookup_texel(srv_loop *loop, uint32_t e, uint32_t block, uint32_t t, uint32_t *texel)
{
    uint32_t dep = loop->dependency[e];
    if (dep == SRV_NO_EFFECT)
        return false;
    const srv_cache_kind *kind = loop->kinds[SCENE_CACHE_ON_SURFACE];
    void *cache = loop->caches[SCENE_CACHE_ON_SURFACE];
    uint32_t dep_block = kind->find(cache, dep, kind->rekey(kind->block_key(cache, e, block), dep));
    if (dep_block == SRV_NONE || !(kind->block_valid(cache, dep, dep_block) >> t & 1))
        return false;
    *texel = le_u32((const uint8_t *)kind->block_payload(cache, dep, dep_block) + 4u * t);
    return true;
}

/* Checks every texel with data of one resident on-surface block. */
static void check_osc_block(srv_loop *loop, uint32_t e, uint32_t block, uint64_t key, uint64_t valid,
                            stab_checked *out)
{
    const scene *s = loop->s;
    const fx_effect *fx = loop->effects[e];
    const srv_cache_kind *kind = loop->kinds[SCENE_CACHE_ON_SURFACE];
    const uint8_t *payload = kind->block_payload(loop->caches[SCENE_CACHE_ON_SURFACE], e, block);
    uint32_t bytes = fx->texel_bytes(s);
    /* The island field names a side too (SCENE_ISLAND_BACK: the twin island of its back). */
    uint32_t island_id = (uint32_t)(key >> 28), level = (uint32_t)(key >> 24) & 0xf;
    uint32_t island = island_id & SCENE_ISLAND_INDEX;
    bool back = (island_id & SCENE_ISLAND_BACK) != 0;
    uint32_t block_y = (uint32_t)(key >> 12) & 0xfff, block_x = (uint32_t)key & 0xfff;
    if (island >= s->island_count)
        fail_msg("effect %s: block %u holds key %016llx of island %u (the scene has %u)", fx->name, block,
                 (unsigned long long)key, island, s->island_count);
    /* The block lies inside the island at its level: a wrapped 12-bit coordinate would not. */
    uint32_t width = (s->islands[island].width + (1u << level) - 1) >> level;
    uint32_t height = (s->islands[island].height + (1u << level) - 1) >> level;
    if (block_x * 8 >= width || block_y * 8 >= height)
        fail_msg("effect %s: block (%u, %u) at level %u lies outside island %u (%u x %u texels)", fx->name,
                 block_x, block_y, level, island, width, height);
    for (uint64_t m = valid; m; m &= m - 1) {
        uint32_t t = (uint32_t)__builtin_ctzll(m);
        const uint8_t *texel = payload + (size_t)t * bytes;
        uint32_t tx = block_x * 8 + (t & 7), ty = block_y * 8 + (t >> 3);
        if (tx >= width || ty >= height)
            fail_msg(
                "effect %s: texel (%u, %u) of island %u level %u holds data outside the island (%u x %u)",
                fx->name, tx, ty, island, level, width, height);
        out->texels[e]++;
        if (strcmp(fx->name, "triangle_lookup") == 0) {
            uint32_t value = le_u32(texel), local = value & 0xff;
            double u = (double)((value >> 8) & 0xfff) / 4095.0, v = (double)(value >> 20) / 4095.0;
            if (local >= s->islands[island].triangle_count || u + v > 1.0 + 2.0 / 4095.0)
                fail_msg("triangle lookup texel %u of island %u (%u triangles): triangle %u, u %g v %g", t,
                         island, s->islands[island].triangle_count, local, u, v);
        } else if (strcmp(fx->name, "ao") == 0) {
            uint32_t count = le_u16(texel + 2);
            if (count < 1 || count > FX_AO_MAX_SAMPLES)
                fail_msg("AO texel %u of key %016llx: %u samples (1..%d)", t, (unsigned long long)key, count,
                         FX_AO_MAX_SAMPLES);
        } else if (strcmp(fx->name, "shadow") == 0) {
            /* A texel facing away from a directional light holds 0 for it (no ray is traced): the side's normal,
             * negated for a back block. */
            uint32_t lookup;
            if (!lookup_texel(loop, e, block, t, &lookup))
                continue;
            const scene_island *is = &s->islands[island];
            if ((lookup & 0xff) >= is->triangle_count)
                fail_msg("shadow texel %u: lookup triangle %u of %u", t, lookup & 0xff, is->triangle_count);
            uint32_t tri = s->island_triangles[is->first + (lookup & 0xff)];
            const float *n = s->tri_normal + 3 * (size_t)tri;
            for (uint32_t l = 0; l < s->light_count; l++) {
                const scene_light *light = &s->lights[l];
                if (light->type != SCENE_LIGHT_DIRECTIONAL)
                    continue;
                double facing =
                    -(n[0] * light->direction[0] + n[1] * light->direction[1] + n[2] * light->direction[2]);
                facing = back ? -facing : facing;
                if (facing < -1e-6 && le_u16(texel + 2 * l) != 0)
                    fail_msg("shadow texel %u of key %016llx faces away from light %u (cos %g) but holds "
                             "mask %04x",
                             t, (unsigned long long)key, l, facing, le_u16(texel + 2 * l));
            }
        }
    }
}

/* Checks one resident probe (world-space, brick size 1) against its documented layout. */
static void check_probe(srv_loop *loop, uint32_t e, uint32_t block, uint64_t key, stab_checked *out)
{
    const srv_cache_kind *kind = loop->kinds[SCENE_CACHE_WORLD_SPACE];
    void *cache = loop->caches[SCENE_CACHE_WORLD_SPACE];
    const uint8_t *p = kind->block_payload(cache, e, block);
    fx_block_job job;
    memset(&job, 0, sizeof job);
    kind->job_location(cache, e, key, &job);
    float position[3] = {le_f32(p), le_f32(p + 4), le_f32(p + 8)}, cell = le_f32(p + 12);
    uint32_t flags = le_u32(p + 16) & 0xffffu; /* the high 16 bits: the blend's drift mean (effects.h) */
    float scale = le_f32(p + 24), backface = le_f32(p + 28);
    fx_probe_info info;
    fx_probe_info_read(p, &info);
    if (!(fabsf(info.drift_mean) <= 1.0f) || !(info.drift_variance >= 0.0f && info.drift_variance <= 1.0f))
        fail_msg("probe %016llx: drift mean %g, variance %g (the change-aware blend's state, in [-1, 1] and "
                 "[0, 1])",
                 (unsigned long long)key, (double)info.drift_mean, (double)info.drift_variance);
    if (!(isfinite(cell) && cell > 0 && fabsf(cell - job.cell) <= 1e-6f * job.cell))
        fail_msg("probe %016llx: cell %g (its level's cell %g)", (unsigned long long)key, (double)cell,
                 (double)job.cell);
    if (!(flags & FX_PROBE_HAS_DATA) ||
        (flags & ~(uint32_t)(FX_PROBE_HAS_DATA | FX_PROBE_OFF | FX_PROBE_MOVED_OUT | FX_PROBE_SEEN_FRONT)))
        fail_msg("probe %016llx: flags %x", (unsigned long long)key, flags);
    if (!(isfinite(scale) && scale >= 0) || !(backface >= 0 && backface <= 1))
        fail_msg("probe %016llx: irradiance scale %g, back-face fraction %g", (unsigned long long)key,
                 (double)scale, (double)backface);
    for (int k = 0; k < 3; k++)
        if (!(fabsf(position[k] - job.origin[k]) <= 0.45f * job.cell * 1.001f + 1e-6f * fabsf(job.origin[k])))
            fail_msg("probe %016llx: position %g is %g cells from its grid point (at most 0.45)",
                     (unsigned long long)key, (double)position[k],
                     (double)((position[k] - job.origin[k]) / job.cell));
    for (uint32_t t = 0; t < FX_PROBE_TEXELS; t++) {
        for (int k = 0; k < 3; k++) {
            double h = half_value(le_u16(p + 32 + 6 * t + 2 * k));
            if (!(h >= 0 && h <= 1.0)) /* stored divided by the scale, the map's largest value */
                fail_msg("probe %016llx texel %u: irradiance / scale %g (0..1)", (unsigned long long)key, t,
                         h);
        }
        for (int k = 0; k < 2; k++) {
            double h = half_value(le_u16(p + 416 + 4 * t + 2 * k));
            if (!(h >= 0 && isfinite(h)))
                fail_msg("probe %016llx texel %u: moment %d %g", (unsigned long long)key, t, k, h);
        }
    }
    out->texels[e]++;
}

/* Walks every block of every pool of every cache kind; checks what has data. */
static void check_payloads(srv_loop *loop, const srv_frame_stats *st, stab_checked *out)
{
    for (uint32_t e = 0; e < loop->effect_count; e++) {
        if (!loop->effect_cached[e])
            continue;
        uint32_t k = loop->effect_kind[e];
        const srv_cache_kind *kind = loop->kinds[k];
        void *cache = loop->caches[k];
        uint32_t capacity = kind->pool_capacity(cache, e), resident = 0;
        for (uint32_t b = 0; b < capacity; b++) {
            uint64_t key = kind->block_key(cache, e, b);
            if (key == UINT64_MAX)
                continue;
            resident++;
            out->blocks++;
            uint64_t valid = kind->block_valid(cache, e, b);
            if (!valid)
                continue;
            if (k == SCENE_CACHE_ON_SURFACE) {
                if ((uint32_t)(key >> 60) != e)
                    fail_msg("block %u of effect %u holds key %016llx of effect %u", b, e,
                             (unsigned long long)key, (unsigned)(key >> 60));
                check_osc_block(loop, e, b, key, valid, out);
            } else if (strcmp(loop->effects[e]->name, "probes") == 0) {
                check_probe(loop, e, b, key, out);
            }
        }
        if (resident != st->blocks_resident[e])
            fail_msg("effect %s: %u blocks hold keys, the statistics say %llu resident",
                     loop->effects[e]->name, resident, (unsigned long long)st->blocks_resident[e]);
    }
}

/* ---- the frame, the statistics and memory ------------------------------------------------------------ */

static void check_viewer(srv_loop *loop, srv_viewer_id id, const srv_viewer_stats *vs, uint32_t viewers,
                         stab_checked *out)
{
    const scene *s = loop->s;
    uint32_t w = 0, h = 0;
    assert_int_equal(srv_viewer_size(loop, id, &w, &h), FXC_OK);
    const float *rad = srv_viewer_radiance(loop, id), *depth = srv_viewer_depth(loop, id);
    const uint8_t *srgb = srv_viewer_image(loop, id);
    assert_non_null(rad);
    assert_non_null(depth);
    assert_non_null(srgb);
    float sky[3];
    stab_sky(s, sky);
    const float *views[SRV_VIEW_COUNT];
    for (int v = 0; v < SRV_VIEW_COUNT; v++)
        views[v] = srv_viewer_view(loop, id, v);
    uint64_t visible = 0;
    for (size_t p = 0; p < (size_t)w * h; p++) {
        bool is_sky = depth[p] == INFINITY;
        if (!is_sky && !(depth[p] >= 0 && isfinite(depth[p])))
            fail_msg("viewer %u pixel (%zu, %zu): depth %g", id.id, p % w, p / w, (double)depth[p]);
        visible += !is_sky;
        for (int k = 0; k < 3; k++) {
            float c = rad[3 * p + k];
            if (!(isfinite(c) && c >= 0))
                fail_msg("viewer %u pixel (%zu, %zu) channel %d: radiance %g", id.id, p % w, p / w, k,
                         (double)c);
            if (is_sky && c != sky[k])
                fail_msg(
                    "viewer %u pixel (%zu, %zu) sees the sky (depth inf) with radiance %g, the sky is %g",
                    id.id, p % w, p / w, (double)c, (double)sky[k]);
            if (srgb[3 * p + k] != srv__tone_map_reference(c))
                fail_msg("viewer %u pixel (%zu, %zu) channel %d: byte %u for radiance %g (tone map: %u)",
                         id.id, p % w, p / w, k, srgb[3 * p + k], (double)c, srv__tone_map_reference(c));
        }
        if (views[SRV_VIEW_AO]) {
            float ao = views[SRV_VIEW_AO][p], lit = views[SRV_VIEW_SHADOW][p],
                  share = views[SRV_VIEW_SHARING][p];
            if (!(ao >= 0 && ao <= 1 && lit >= 0 && lit <= 1 && share >= 0 && share <= (float)viewers &&
                  share == floorf(share)))
                fail_msg("viewer %u pixel (%zu, %zu): views AO %.9g, lit %.9g, sharing %.9g", id.id, p % w,
                         p / w, (double)ao, (double)lit, (double)share);
            if (is_sky && !(ao == 1 && lit == 1 && share == 0))
                fail_msg("viewer %u sky pixel (%zu, %zu): views AO %g, lit %g, sharing %g", id.id, p % w,
                         p / w, (double)ao, (double)lit, (double)share);
            out->view_values += 3;
        }
    }
    out->pixels += (uint64_t)w * h;
    out->sky_pixels += (uint64_t)w * h - visible;
    if (vs->width != w || vs->height != h || vs->pixels_visible != visible || vs->pixels_missing > visible)
        fail_msg("viewer %u: statistics %ux%u, %llu visible, %llu missing; the frame %ux%u, %llu visible",
                 id.id, vs->width, vs->height, (unsigned long long)vs->pixels_visible,
                 (unsigned long long)vs->pixels_missing, w, h, (unsigned long long)visible);
}

static void check_stats(srv_loop *loop, const srv_frame_stats *st)
{
    uint64_t requested = 0, cells = 0, visible = 0, missing = 0, pixels = 0;
    for (uint32_t i = 0; i < st->viewer_count; i++) {
        requested += st->viewers[i].requested_texels;
        cells += st->viewers[i].requested_cells;
        visible += st->viewers[i].pixels_visible;
        missing += st->viewers[i].pixels_missing;
        pixels += (uint64_t)st->viewers[i].width * st->viewers[i].height;
    }
    if (requested != st->requested_texels || cells != st->world.requested_cells ||
        visible != st->pixels_visible || missing != st->pixels_missing || pixels != st->visibility_rays)
        fail_msg(
            "frame %u: the viewers' figures do not add up to the frame's (texels %llu/%llu, cells %llu/%llu, "
            "visible %llu/%llu, missing %llu/%llu, pixels %llu/%llu)",
            st->frame, (unsigned long long)requested, (unsigned long long)st->requested_texels,
            (unsigned long long)cells, (unsigned long long)st->world.requested_cells,
            (unsigned long long)visible, (unsigned long long)st->pixels_visible, (unsigned long long)missing,
            (unsigned long long)st->pixels_missing, (unsigned long long)pixels,
            (unsigned long long)st->visibility_rays);
    if (st->unique_texels > st->requested_texels || st->world.unique_cells > st->world.requested_cells)
        fail_msg("frame %u: more unique texels (%llu) or cells (%llu) than requested (%llu, %llu)", st->frame,
                 (unsigned long long)st->unique_texels, (unsigned long long)st->world.unique_cells,
                 (unsigned long long)st->requested_texels, (unsigned long long)st->world.requested_cells);
    /* At most 75 % of the table's slots hold keys (osc.h's default maximum load). */
    if ((uint64_t)st->table_count * 100 > (uint64_t)st->table_capacity * 75 ||
        st->world.entries * 100 > st->world.table_capacity * 75 ||
        st->world.local_hits > st->world.local_lookups)
        fail_msg("frame %u: table %u of %u slots, world table %llu of %llu, local hits %llu of %llu",
                 st->frame, st->table_count, st->table_capacity, (unsigned long long)st->world.entries,
                 (unsigned long long)st->world.table_capacity, (unsigned long long)st->world.local_hits,
                 (unsigned long long)st->world.local_lookups);
    double stages = 0;
    for (int k = 0; k < SRV_STAGE_COUNT; k++) {
        if (!(isfinite(st->time_ms[k]) && st->time_ms[k] >= 0))
            fail_msg("frame %u: stage %s took %g ms", st->frame, srv_stage_name((srv_stage)k),
                     st->time_ms[k]);
        stages += st->time_ms[k];
    }
    if (!(isfinite(st->frame_ms) && st->frame_ms >= stages - 1e-3 * (1 + stages)))
        fail_msg("frame %u: frame time %g ms, its stages %g ms", st->frame, st->frame_ms, stages);
    for (uint32_t e = 0; e < loop->effect_count; e++)
        if (st->texels_resampled[e] > st->texels_updated[e])
            fail_msg("frame %u: effect %s resampled %llu of %llu texels updated", st->frame,
                     loop->effects[e]->name, (unsigned long long)st->texels_resampled[e],
                     (unsigned long long)st->texels_updated[e]);

    /* Memory: the parts add up to the total, and resident blocks are what the pools say is in use. */
    srv_memory m;
    srv_loop_memory(loop, &m);
    uint64_t sum = m.table + m.viewers + m.queues + m.world_local;
    for (uint32_t e = 0; e < SRV_MAX_EFFECTS; e++) {
        sum += m.pools_reserved[e] + m.block_meta[e];
        if (m.pools_in_use[e] > m.pools_reserved[e])
            fail_msg("effect %u: %llu pool bytes in use of %llu reserved", e,
                     (unsigned long long)m.pools_in_use[e], (unsigned long long)m.pools_reserved[e]);
        if (e < loop->effect_count && loop->effect_cached[e]) {
            const fx_effect *fx = loop->effects[e];
            uint64_t side =
                loop->effect_kind[e] == SCENE_CACHE_WORLD_SPACE ? (fx->brick_size ? fx->brick_size : 1) : 8;
            uint64_t block_bytes =
                (uint64_t)fx->texel_bytes(loop->s) *
                (loop->effect_kind[e] == SCENE_CACHE_WORLD_SPACE ? side * side * side : 64);
            if (m.pools_in_use[e] != st->blocks_resident[e] * block_bytes)
                fail_msg("effect %s: %llu pool bytes in use for %llu resident blocks of %llu bytes", fx->name,
                         (unsigned long long)m.pools_in_use[e], (unsigned long long)st->blocks_resident[e],
                         (unsigned long long)block_bytes);
        }
    }
    if (sum != m.total || st->world.bytes > m.total)
        fail_msg("memory: parts add up to %llu, total %llu (world %llu)", (unsigned long long)sum,
                 (unsigned long long)m.total, (unsigned long long)st->world.bytes);
}

stab_checked stab_check_loop(srv_loop *loop, const srv_frame_stats *st)
{
    stab_checked out;
    memset(&out, 0, sizeof out);
    srv_viewer_id ids[SRV_MAX_VIEWERS];
    uint32_t n = srv_loop_viewers(loop, ids, SRV_MAX_VIEWERS);
    uint32_t rendered = 0;
    for (uint32_t v = 0; v < n; v++) {
        if (!srv_viewer_radiance(loop, ids[v]))
            continue;
        const srv_viewer_stats *vs = NULL;
        for (uint32_t i = 0; i < st->viewer_count; i++)
            if (st->viewers[i].id.id == ids[v].id)
                vs = &st->viewers[i];
        if (!vs)
            continue; /* rendered in an earlier frame, not this one */
        check_viewer(loop, ids[v], vs, st->viewer_count, &out);
        rendered++;
    }
    if (rendered != st->viewer_count)
        fail_msg("frame %u: %u viewers rendered, the statistics name %u", st->frame, rendered,
                 st->viewer_count);
    check_stats(loop, st);
    check_payloads(loop, st, &out);
    return out;
}

stab_checked stab_frames(srv_loop *loop, const srv_viewer_id *ids, uint32_t n, const srv_camera *cameras,
                         bool same, uint32_t frames, srv_frame_stats *st)
{
    stab_checked last;
    memset(&last, 0, sizeof last);
    for (uint32_t f = 0; f < frames; f++) {
        for (uint32_t v = 0; v < n; v++) {
            fxc_result r = srv_viewer_set_camera(loop, ids[v], same ? &cameras[0] : &cameras[v]);
            if (r != FXC_OK)
                fail_msg("srv_viewer_set_camera: %s", fxc_strerror(r));
        }
        fxc_result r = srv_loop_frame(loop, st);
        if (r != FXC_OK)
            fail_msg("srv_loop_frame: %s", fxc_strerror(r));
        last = stab_check_loop(loop, st);
    }
    return last;
}

float *stab_copy_radiance(const srv_loop *loop, srv_viewer_id id)
{
    uint32_t w = 0, h = 0;
    assert_int_equal(srv_viewer_size(loop, id, &w, &h), FXC_OK);
    const float *rad = srv_viewer_radiance(loop, id);
    assert_non_null(rad);
    float *copy = malloc((size_t)w * h * 3 * sizeof *copy);
    assert_non_null(copy);
    memcpy(copy, rad, (size_t)w * h * 3 * sizeof *copy);
    return copy;
}

/* ---- geometry and images --------------------------------------------------------------------------------- */

/* The pixel's primary ray direction, as visibility.c forms it, in double (unnormalised). */
static void pixel_direction(const srv_camera_frame *f, uint32_t x, uint32_t y, double dir[3])
{
    double scale_x = 2.0 * f->tan_half_x / f->width, scale_y = 2.0 * f->tan_half_y / f->height;
    double sx = (x + 0.5) * scale_x - f->tan_half_x, sy = f->tan_half_y - (y + 0.5) * scale_y;
    double len2 = 0;
    for (int k = 0; k < 3; k++) {
        dir[k] = f->forward[k] + sx * f->right[k] + sy * f->up[k];
        len2 += dir[k] * dir[k];
    }
    for (int k = 0; k < 3; k++)
        dir[k] /= sqrt(len2);
}

void stab_pixel_point(const srv_camera_frame *f, uint32_t x, uint32_t y, float depth, double point[3])
{
    double dir[3];
    pixel_direction(f, x, y, dir);
    for (int k = 0; k < 3; k++)
        point[k] = f->origin[k] + (double)depth * dir[k];
}

double stab_plane_depth(const srv_camera_frame *f, uint32_t x, uint32_t y, double plane_y)
{
    double dir[3];
    pixel_direction(f, x, y, dir);
    double t = (plane_y - f->origin[1]) / dir[1];
    return t >= 0 && isfinite(t) ? t : INFINITY;
}

double stab_relative_rmse(const float *a, const float *b, size_t n)
{
    double sum2 = 0, mean = 0;
    for (size_t i = 0; i < n; i++) {
        double d = (double)b[i] - a[i];
        sum2 += d * d;
        mean += fabs((double)a[i]);
    }
    mean /= (double)n;
    return mean > 0 ? sqrt(sum2 / (double)n) / mean : sqrt(sum2 / (double)n);
}

/* ---- scenes ----------------------------------------------------------------------------------------------- */

void stab_add_floor(scene *s, double cx, double height, double cz, double half, uint32_t cells)
{
    /* edge_a along +z, edge_b along +x: normal (z x x) = +y */
    fxt_add_quad(s, "floor", (const double[3]){cx - half, height, cz - half},
                 (const double[3]){0, 0, 2 * half}, (const double[3]){2 * half, 0, 0}, cells);
}

void stab_add_point_light(scene *s, float x, float y, float z, float intensity)
{
    scene_light light = {
        .type = SCENE_LIGHT_POINT, .position = {x, y, z}, .color = {1, 1, 1}, .intensity = intensity};
    scene_error err;
    assert_int_equal(scene__add_light(s, &light, "stability lamp", &err), SCENE_OK);
}

void stab_sky(const scene *s, float sky[3])
{
    for (int k = 0; k < 3; k++)
        sky[k] = s->sky_color[k] * s->sky_intensity;
}

void stab_set_sun(scene *s, const float dir[3], float intensity)
{
    assert_true(s->light_count >= 1 && s->lights[0].type == SCENE_LIGHT_DIRECTIONAL);
    double len = sqrt((double)dir[0] * dir[0] + (double)dir[1] * dir[1] + (double)dir[2] * dir[2]);
    for (int k = 0; k < 3; k++)
        s->lights[0].direction[k] = (float)(dir[k] / len);
    s->lights[0].intensity = intensity;
}

/* ---- the bounce scene ---------------------------------------------------------------------------------- */

scene *stab_bounce_scene(float intensity, scene_rt **rt)
{
    scene *s = fxt_new_scene();
    /* Floor: edge_a along +z, edge_b along +x (normal +y); wall: edge_a along +y, edge_b along +z (+x). */
    fxt_add_quad(s, "floor", (const double[3]){0.1, 0.1, -5}, (const double[3]){0, 0, 10},
                 (const double[3]){4, 0, 0}, 4);
    fxt_add_quad(s, "wall", (const double[3]){0.1, 0.1, -5}, (const double[3]){0, 5, 0},
                 (const double[3]){0, 0, 10}, 4);
    fxt_add_sun(s, 0, -1, 0);
    s->lights[0].intensity = intensity;
    s->sky_intensity = 0;
    *rt = fxt_finish_scene(s, 8.0f, 0.5f);
    assert_true(s->origin[0] == 0 && s->origin[1] == 0 && s->origin[2] == 0);
    return s;
}

srv_camera stab_bounce_camera(void)
{
    return (srv_camera){
        .position = {3.9f, 1.2f, 0.05f}, .target = {0.1f, 0.9f, 0.0f}, .up = {0, 1, 0}, .fov_deg = 60};
}

void stab_bounce_means(const srv_loop *loop, srv_viewer_id id, double *wall, double *floor)
{
    uint32_t w = 0, h = 0;
    assert_int_equal(srv_viewer_size(loop, id, &w, &h), FXC_OK);
    const float *depth = srv_viewer_depth(loop, id), *rad = srv_viewer_radiance(loop, id);
    srv_camera cam = stab_bounce_camera();
    srv_camera_frame f;
    assert_true(srv_camera_setup(&cam, w, h, &f));
    double sum[2] = {0, 0};
    uint32_t count[2] = {0, 0};
    for (uint32_t y = 0; y < h; y++)
        for (uint32_t x = 0; x < w; x++) {
            size_t p = (size_t)y * w + x;
            if (!isfinite(depth[p]))
                continue;
            double q[3];
            stab_pixel_point(&f, x, y, depth[p], q);
            if (fabs(q[0] - 0.1) < 1e-3 && q[1] > 0.5 && q[1] < 1.7 && fabs(q[2]) < 1.4) {
                sum[0] += rad[3 * p];
                count[0]++;
            } else if (fabs(q[1] - 0.1) < 1e-3 && q[0] > 1.5 && q[0] < 3.5 && fabs(q[2]) < 1.4) {
                sum[1] += rad[3 * p];
                count[1]++;
            }
        }
    assert_true(count[0] > 20 && count[1] > 20);
    *wall = sum[0] / count[0];
    *floor = sum[1] / count[1];
}

srv_loop *stab_bounce_loop(scene *s, scene_rt *rt, float h, srv_viewer_id *id)
{
    srv_loop_desc d = {.s = s,
                       .rt = rt,
                       .seed = 21,
                       .threads = 2,
                       .probe_rays = 64,
                       .probe_hysteresis = h,
                       /* plain hysteresis: the closed forms V (1 - h^k) and V h^k the callers check are its
                          (the default change-aware blend's: tests/test_probes_converge.c) */
                       .probe_plain_blend = true,
                       .probe_cell = 0.5f,
                       .keep_views = true};
    fxt_effects_on(&d, (const char *const[]){"shadow", "probes"}, 2);
    return fxt_loop(&d, 1, 48, 32, id);
}

void stab_bounce_frame(srv_loop *loop, srv_viewer_id id, double *wall, double *floor)
{
    srv_camera cam = stab_bounce_camera();
    srv_frame_stats st;
    stab_frames(loop, &id, 1, &cam, true, 1, &st);
    stab_bounce_means(loop, id, wall, floor);
}

void stab_bounce_steady(scene *s, scene_rt *rt, uint32_t frames, double *mean, double *spread)
{
    srv_viewer_id id;
    srv_loop *loop = stab_bounce_loop(s, rt, 0.5f, &id);
    double wall = 0, floor = 0, sum = 0, sum2 = 0;
    for (int f = 0; f < 40; f++)
        stab_bounce_frame(loop, id, &wall, &floor);
    for (uint32_t f = 0; f < frames; f++) {
        stab_bounce_frame(loop, id, &wall, &floor);
        sum += wall;
        sum2 += wall * wall;
    }
    *mean = sum / frames;
    *spread = sqrt(fmax(sum2 / frames - *mean * *mean, 0.0));
    srv_loop_free(loop);
}

void stab_probe_snapshot(srv_loop *loop, stab_probe_counts *out)
{
    out->count = 0;
    const srv_cache_kind *kind = loop->kinds[SCENE_CACHE_WORLD_SPACE];
    void *cache = loop->caches[SCENE_CACHE_WORLD_SPACE];
    assert_non_null(kind);
    for (uint32_t e = 0; e < loop->effect_count; e++) {
        if (!loop->effect_cached[e] || loop->effect_kind[e] != SCENE_CACHE_WORLD_SPACE)
            continue;
        uint32_t capacity = kind->pool_capacity(cache, e);
        for (uint32_t b = 0; b < capacity; b++) {
            uint64_t key = kind->block_key(cache, e, b);
            if (key == UINT64_MAX || !kind->block_valid(cache, e, b) || !kind->block_requested(cache, e, b))
                continue;
            const uint8_t *p = kind->block_payload(cache, e, b);
            if (le_u32(p + 16) & FX_PROBE_OFF)
                continue;
            assert_true(out->count < sizeof out->key / sizeof out->key[0]);
            out->key[out->count] = key;
            out->updates[out->count++] =
                le_u32(p + 20) & 0xffffu; /* the low 16 bits: the count (effects.h) */
        }
    }
}

uint32_t stab_probe_updates_since(srv_loop *loop, const stab_probe_counts *then, uint32_t *least,
                                  uint32_t *most)
{
    stab_probe_counts *now = malloc(sizeof *now);
    assert_non_null(now);
    stab_probe_snapshot(loop, now);
    *least = UINT32_MAX;
    *most = 0;
    uint32_t matched = 0;
    for (uint32_t i = 0; i < now->count; i++)
        for (uint32_t j = 0; j < then->count; j++)
            if (then->key[j] == now->key[i] && now->updates[i] >= then->updates[j]) {
                uint32_t since = now->updates[i] - then->updates[j];
                *least = since < *least ? since : *least;
                *most = since > *most ? since : *most;
                matched++;
                break;
            }
    free(now);
    return matched;
}

/* ---- an open plane ----------------------------------------------------------------------------------- */

scene *stab_open_plane(const float dir[3], float intensity, float sky_intensity, scene_rt **rt)
{
    scene *s = fxt_new_scene();
    stab_add_floor(s, 0.7, 0.3, -0.4, 20.0, 4);
    fxt_add_sun(s, dir[0], dir[1], dir[2]);
    stab_set_sun(s, dir, intensity);
    s->sky_color[0] = 0.2f, s->sky_color[1] = 0.3f, s->sky_color[2] = 0.4f;
    s->sky_intensity = sky_intensity;
    *rt = fxt_finish_scene(s, 4.0f, 1.0f);
    return s;
}

void stab_plane_closed_form(const scene *s, double out[3])
{
    const scene_light *l = &s->lights[0];
    double cosine = -(double)l->direction[1]; /* the normal is +y */
    for (int k = 0; k < 3; k++)
        out[k] = 0.5 * ((cosine > 0 ? (double)l->intensity * l->color[k] * cosine : 0.0) +
                        (double)s->sky_color[k] * s->sky_intensity);
}

stab_plane_result stab_check_open_plane(const srv_loop *loop, srv_viewer_id id, const srv_camera *cam,
                                        double plane_y, double cx, double cz, double half_x, double half_z)
{
    stab_plane_result out;
    memset(&out, 0, sizeof out);
    uint32_t w = 0, h = 0;
    assert_int_equal(srv_viewer_size(loop, id, &w, &h), FXC_OK);
    srv_camera_frame f;
    assert_true(srv_camera_setup(cam, w, h, &f));
    const scene *s = srv_loop_desc_of(loop)->s;
    double expected[3];
    stab_plane_closed_form(s, expected);
    bool lit = -(double)s->lights[0].direction[1] > 0;
    const float *rad = srv_viewer_radiance(loop, id), *depth = srv_viewer_depth(loop, id);
    const float *ao = srv_viewer_view(loop, id, SRV_VIEW_AO),
                *shadow = srv_viewer_view(loop, id, SRV_VIEW_SHADOW);
    for (uint32_t y = 0; y < h; y++)
        for (uint32_t x = 0; x < w; x++) {
            size_t p = (size_t)y * w + x;
            double dir[3];
            pixel_direction(&f, x, y, dir);
            double t = stab_plane_depth(&f, x, y, plane_y);
            double inside = -INFINITY; /* metres inside the floor's border (negative: outside) */
            if (isfinite(t)) {
                double hx = f.origin[0] + t * dir[0], hz = f.origin[2] + t * dir[2];
                inside = fmin(half_x - fabs(hx - cx), half_z - fabs(hz - cz));
            }
            double margin = 1e-4 * (isfinite(t) ? t : 0.0) + 1e-6;
            if (inside > margin) {
                double bound = 0x1p-20 * (1.0 + f.tan_half_x + f.tan_half_y) / fabs(dir[1]);
                double error = fabs((double)depth[p] - t) / t;
                if (!(error <= bound))
                    fail_msg("pixel (%u, %u): depth %.9g, the plane's %.9g (relative error %.3g, bound %.3g)",
                             x, y, (double)depth[p], t, error, bound);
                out.worst_depth = fmax(out.worst_depth, error / bound);
                out.plane_pixels++;
                for (int k = 0; k < 3; k++) {
                    double e = fabs(rad[3 * p + k] - expected[k]) / expected[k];
                    if (!(e <= STAB_FORMULA_TOLERANCE))
                        fail_msg("pixel (%u, %u) channel %d: radiance %.9g, closed form %.9g (relative error "
                                 "%.3g)",
                                 x, y, k, (double)rad[3 * p + k], expected[k], e);
                    out.worst_radiance = fmax(out.worst_radiance, e);
                }
                /* Every texel holds exactly 1 (or 0); a filter's weights sum to 1 within 4 roundings. */
                if (ao && !(fabs(ao[p] - 1.0) <= 0x1p-22 && fabs(shadow[p] - (lit ? 1.0 : 0.0)) <= 0x1p-22))
                    fail_msg("pixel (%u, %u): AO %.9g, lit fraction %.9g (expected 1 and %d)", x, y,
                             (double)ao[p], (double)shadow[p], lit);
            } else if (inside < -margin) {
                if (depth[p] != INFINITY)
                    fail_msg("pixel (%u, %u): depth %.9g, its ray misses the floor by %.3g m", x, y,
                             (double)depth[p], -inside);
                out.sky_pixels++;
            }
        }
    return out;
}

/* ---- a box over a plane ---------------------------------------------------------------------------------- */

bool stab_box_shadows(const double p[3], const float dir[3], const double lo[3], const double hi[3])
{
    double t0 = 0, t1 = INFINITY;
    for (int k = 0; k < 3; k++) {
        double d = -(double)dir[k];
        if (d == 0) {
            if (p[k] < lo[k] || p[k] > hi[k])
                return false;
            continue;
        }
        double a = (lo[k] - p[k]) / d, b = (hi[k] - p[k]) / d;
        t0 = fmax(t0, fmin(a, b));
        t1 = fmin(t1, fmax(a, b));
    }
    return t0 <= t1;
}

static bool box_dark(const double p[3], const float dir[3], const double lo[3], const double hi[3],
                     bool under)
{
    return stab_box_shadows(p, dir, lo, hi) ||
           (under && p[0] >= lo[0] && p[0] <= hi[0] && p[2] >= lo[2] && p[2] <= hi[2]);
}

stab_box_result stab_check_box_on_plane(const srv_loop *loop, srv_viewer_id id, const srv_camera *cam,
                                        double plane_y, const double lo[3], const double hi[3],
                                        bool under_is_dark, float density, float ao_radius,
                                        double depth_tolerance)
{
    stab_box_result out;
    memset(&out, 0, sizeof out);
    uint32_t w = 0, h = 0;
    assert_int_equal(srv_viewer_size(loop, id, &w, &h), FXC_OK);
    srv_camera_frame f;
    assert_true(srv_camera_setup(cam, w, h, &f));
    const scene *s = srv_loop_desc_of(loop)->s;
    const float *sun = s->lights[0].direction;
    const float *depth = srv_viewer_depth(loop, id), *lit = srv_viewer_view(loop, id, SRV_VIEW_SHADOW);
    const float *ao = srv_viewer_view(loop, id, SRV_VIEW_AO);
    assert_non_null(lit);
    for (uint32_t y = 0; y < h; y++)
        for (uint32_t x = 0; x < w; x++) {
            size_t p = (size_t)y * w + x;
            double t = stab_plane_depth(&f, x, y, plane_y), q[3], dir[3];
            if (!(fabs(depth[p] - t) <= depth_tolerance * t))
                continue; /* the box, or the sky */
            pixel_direction(&f, x, y, dir);
            stab_pixel_point(&f, x, y, (float)t, q);
            q[1] = plane_y;
            out.plane_pixels++;
            out.worst_depth = fmax(out.worst_depth, fabs(depth[p] - t) / t);
            double footprint = t * 2.0 * f.tan_half_y / h / fabs(dir[1]);
            double band = 2.0 * fmax(1.42 * footprint, 1.0 / density) + footprint;
            double dx = fmax(fmax(lo[0] - q[0], q[0] - hi[0]), 0.0),
                   dz = fmax(fmax(lo[2] - q[2], q[2] - hi[2]), 0.0);
            if (sqrt(dx * dx + dz * dz) > ao_radius + 2 * band) {
                out.open++;
                if (!(fabs(ao[p] - 1.0) <= 0x1p-22))
                    fail_msg("pixel (%u, %u) at (%.9g, %.9g): AO %.9g, nothing within its radius", x, y, q[0],
                             q[2], (double)ao[p]);
            }
            bool shadowed = box_dark(q, sun, lo, hi, under_is_dark), near_edge = false;
            for (int a = -8; a <= 8 && !near_edge; a++)
                for (int b = -8; b <= 8 && !near_edge; b++) {
                    double r[3] = {q[0] + band * a / 8.0, q[1], q[2] + band * b / 8.0};
                    near_edge = box_dark(r, sun, lo, hi, under_is_dark) != shadowed;
                }
            if (near_edge)
                continue;
            out.lit_checked++;
            out.dark += shadowed;
            if (!(fabs(lit[p] - (shadowed ? 0.0 : 1.0)) <= 0x1p-22))
                fail_msg("pixel (%u, %u) at (%.9g, %.9g): lit fraction %.9g, %s by the box", x, y, q[0], q[2],
                         (double)lit[p], shadowed ? "shadowed" : "not shadowed");
        }
    return out;
}
