/* osc_footprint.c: which blocks and texels one filtered cache lookup touches (stage 3, "requests"). For a
 * surface point at level-local texel coordinates (texel (i, j) covers [i, i+1) x [j, j+1), centre at
 * i + 0.5; see osc.h), point filtering touches one texel, bilinear the 2 x 2 stencil around the point,
 * trilinear the bilinear stencils at level l and l+1. Texels are clamped to the island's size at their
 * level, ceil(size0 / 2^l), and grouped into 8 x 8 blocks as (key, texel mask) pairs written to a
 * caller-provided fixed array. No allocation, no state. */
#include "osc_internal.h"

#include <math.h>

/* floor(coord) as an integer, with the coordinate first limited to [-1, size] (NaN -> -1) so the
 * conversion is always defined; the caller clamps the texel index itself. */
static int32_t osc__floor_limited(float coord, uint32_t size)
{
    if (!(coord >= -1.0f)) /* also NaN */
        return -1;
    if (coord > (float)size)
        return (int32_t)size;
    return (int32_t)floorf(coord);
}

static uint32_t osc__clamp_texel(int32_t texel, uint32_t size)
{
    if (texel < 0)
        return 0;
    if ((uint32_t)texel >= size)
        return size - 1;
    return (uint32_t)texel;
}

/* ORs texel (texel_x, texel_y) of `level` into the footprint: into its block's entry when present, else
 * appends a new entry. */
static void osc__footprint_add(osc_footprint *out, const osc_island_extent *island, uint32_t level,
                               uint32_t texel_x, uint32_t texel_y)
{
    uint64_t key = osc_key_pack(island->effect, island->island_id, level, texel_x / OSC_BLOCK_SIZE,
                                texel_y / OSC_BLOCK_SIZE);
    uint64_t bit = osc_texel_bit(texel_x, texel_y);
    for (uint32_t i = 0; i < out->count; i++) {
        if (out->keys[i] == key) {
            out->texel_masks[i] |= bit;
            return;
        }
    }
    OSC_ASSERT(out->count < OSC_FOOTPRINT_MAX);
    out->keys[out->count] = key;
    out->texel_masks[out->count] = bit;
    out->count++;
}

static void osc__check_island(const osc_island_extent *island, uint32_t level)
{
    OSC_ASSERT(island != NULL);
    OSC_ASSERT(island->effect < OSC_MAX_EFFECTS);
    OSC_ASSERT(level <= OSC_MAX_LEVEL);
    OSC_ASSERT(island->width0 >= 1 && island->width0 <= OSC_MAX_ISLAND_SIZE);
    OSC_ASSERT(island->height0 >= 1 && island->height0 <= OSC_MAX_ISLAND_SIZE);
}

/* Appends the bilinear stencil at `level` (no reset of out). */
static void osc__bilinear_append(const osc_island_extent *island, uint32_t level, float x, float y,
                                 osc_footprint *out)
{
    uint32_t width = osc_level_size(island->width0, level);
    uint32_t height = osc_level_size(island->height0, level);
    int32_t x0 = osc__floor_limited(x - 0.5f, width);
    int32_t y0 = osc__floor_limited(y - 0.5f, height);
    uint32_t texel_x0 = osc__clamp_texel(x0, width), texel_x1 = osc__clamp_texel(x0 + 1, width);
    uint32_t texel_y0 = osc__clamp_texel(y0, height), texel_y1 = osc__clamp_texel(y0 + 1, height);
    osc__footprint_add(out, island, level, texel_x0, texel_y0);
    osc__footprint_add(out, island, level, texel_x1, texel_y0);
    osc__footprint_add(out, island, level, texel_x0, texel_y1);
    osc__footprint_add(out, island, level, texel_x1, texel_y1);
}

/* Point filtering: the one texel containing (x, y), clamped to the island. */
void osc_footprint_point(const osc_island_extent *island, uint32_t level, float x, float y,
                         osc_footprint *out)
{
    osc__check_island(island, level);
    uint32_t width = osc_level_size(island->width0, level);
    uint32_t height = osc_level_size(island->height0, level);
    out->count = 0;
    osc__footprint_add(out, island, level, osc__clamp_texel(osc__floor_limited(x, width), width),
                       osc__clamp_texel(osc__floor_limited(y, height), height));
}

/* Bilinear filtering: the 2 x 2 stencil at `level`. */
void osc_footprint_bilinear(const osc_island_extent *island, uint32_t level, float x, float y,
                            osc_footprint *out)
{
    osc__check_island(island, level);
    out->count = 0;
    osc__bilinear_append(island, level, x, y, out);
}

/* Trilinear filtering: bilinear at `level` and at level+1 (coordinates halved). */
void osc_footprint_trilinear(const osc_island_extent *island, uint32_t level, float x, float y,
                             osc_footprint *out)
{
    osc__check_island(island, level);
    OSC_ASSERT(level < OSC_MAX_LEVEL);
    out->count = 0;
    osc__bilinear_append(island, level, x, y, out);
    osc__bilinear_append(island, level + 1, x * 0.5f, y * 0.5f, out);
}
