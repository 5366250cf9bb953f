/* The render cache's owner struct and its point store: creation with every default resolved in one place, the
 * one allocation everything lives in, and the two ways points come in (a whole frame, or sparse samples).
 *
 * A new point takes a free slot (the stack the last frame's ageing pass rebuilt) after the points it replaces
 * were freed:
 *   - a frame replaces every cached point it saw: one pass projects all points into the frame's camera and
 * frees those that are not behind the frame's depth at their pixel by more than supersede_ratio (the new
 * frame is the truth for everything it shows; an old point of the same surface would otherwise fight the new
 * one in the z-buffer at nearly the same depth, and show stale colour half the time);
 *   - a sample replaces the point the last frame showed at its place (found through the last frame's winners,
 *     so it costs nothing per cached point), and when the colours differ the neighbours' points age faster:
 *     their shading has probably changed too (1999 slide 21, "color change heuristic"; 2002 3.4).
 * Slots freed between two frames return to the stack at the next frame (the last frame's winners still name
 * them). When the stack runs short, it is rebuilt on the spot and, if still short, the oldest points go (the
 * frame's drop plan keeps the cache within capacity anyway; this is the case of more inserts between two
 * frames than insert_reserve, or a whole frame). */
#include "rc_internal.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#if defined(__linux__)
#include <sys/mman.h>
#endif

#define RC_HUGE_PAGE ((size_t)2 << 20) /* bytes of a transparent huge page on x86-64 */

double view_rc__now_ms(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec * 1e3 + (double)ts.tv_nsec * 1e-6;
}

const char *view_rc_stage_name(int stage)
{
    static const char *const names[] = {
#define VIEW_RC_STAGE_NAME(name, text) text,
        VIEW_RC_STAGES(VIEW_RC_STAGE_NAME)
#undef VIEW_RC_STAGE_NAME
    };
    return stage >= 0 && stage < VIEW_RC_STAGE_COUNT ? names[stage] : "unknown";
}

/* ---- creation ---------------------------------------------------------------------------------------- */

/* Fills the defaults into d; false when a field is out of range. */
static bool resolve_desc(view_rc_desc *d)
{
    if (d->width == 0 || d->height == 0 || d->width > VIEW_RC_MAX_SIDE || d->height > VIEW_RC_MAX_SIDE)
        return false;
    uint64_t pixels = (uint64_t)d->width * d->height;
    if (d->sample_budget == 0)
        d->sample_budget = pixels / 32 > 0 ? (uint32_t)(pixels / 32) : 1;
    if (d->sample_budget > pixels)
        return false;
    if (d->capacity == 0)
        d->capacity = (uint32_t)pixels;
    if (d->insert_reserve == 0)
        d->insert_reserve = 4 * d->sample_budget;
    if ((uint64_t)d->capacity + d->insert_reserve > UINT32_MAX - 1)
        return false;
    if (d->tile_size == 0)
        d->tile_size = 64;
    if (d->tile_size > VIEW_RC_MAX_SIDE)
        d->tile_size = VIEW_RC_MAX_SIDE;
    if (d->threads == 0)
        d->threads = 1;
    if (d->threads > VIEW_RC_MAX_THREADS)
        return false;
    if (d->cull_ratio == 0)
        d->cull_ratio = 0.1f;
    if (d->supersede_ratio == 0)
        d->supersede_ratio = 0.02f;
    if (d->hidden_age_factor == 0)
        d->hidden_age_factor = 2.0f;
    if (!(d->cull_ratio > 0 && d->cull_ratio < 1e6f) ||
        !(d->supersede_ratio > 0 && d->supersede_ratio < 1e6f) ||
        !(d->hidden_age_factor >= 1 && d->hidden_age_factor <= 256))
        return false;
    if (d->change_threshold == 0)
        d->change_threshold = 32;
    if (d->change_penalty == 0)
        d->change_penalty = 64;
    return true;
}

/* Lays arrays out in one block: offsets aligned to 64 bytes, overflow checked. */
typedef struct rc_layout {
    size_t bytes;
    bool overflow;
} rc_layout;

static size_t take(rc_layout *l, size_t count, size_t size)
{
    size_t at = (l->bytes + 63) & ~(size_t)63;
    if (at < l->bytes || (size != 0 && count > (SIZE_MAX - at - 64) / size)) {
        l->overflow = true;
        return 0;
    }
    l->bytes = at + count * size;
    return at;
}

fxc_result view_rc_create(const view_rc_desc *desc, view_rc **out)
{
    if (!out)
        return FXC_ERR_INVALID;
    *out = NULL;
    view_rc_desc d = desc ? *desc : (view_rc_desc){0};
    if (!resolve_desc(&d))
        return FXC_ERR_INVALID;
    view_rc *rc = calloc(1, sizeof *rc);
    if (!rc)
        return FXC_ERR_NOMEM;
    rc->width = d.width;
    rc->height = d.height;
    rc->pixels = (size_t)d.width * d.height;
    rc->thread_count = d.threads;

    /* Tiles: a power of two on a side, grown until there are at most VIEW_RC_MAX_TILES. */
    uint32_t shift = 0;
    while ((1u << shift) < d.tile_size)
        shift++;
    for (;;) {
        uint32_t side = 1u << shift;
        uint64_t tx = (d.width + side - 1) / side, ty = (d.height + side - 1) / side;
        if (tx * ty <= VIEW_RC_MAX_TILES) {
            rc->tiles_x = (uint32_t)tx;
            rc->tiles_y = (uint32_t)ty;
            break;
        }
        shift++;
    }
    rc->tile_shift = shift;
    rc->tile = 1u << shift;
    d.tile_size = rc->tile;
    rc->d = d;
    rc->tile_count = rc->tiles_x * rc->tiles_y;
    rc->list_outside = (uint16_t)rc->tile_count;
    rc->list_dead = (uint16_t)(rc->tile_count + 1);
    rc->list_new = (uint16_t)(rc->tile_count + 2);
    uint32_t longest = d.width > d.height ? d.width : d.height;
    uint32_t span = rc->tile < longest ? rc->tile : longest; /* the largest tile's side */
    rc->slots = d.capacity + d.insert_reserve;
    /* Chunks of slots: a power of two, at least 4096, at most 512 of them. */
    uint32_t chunk_shift = 12;
    while ((uint64_t)rc->slots > (uint64_t)512 << chunk_shift)
        chunk_shift++;
    /* An entry's key holds the pixel within the tile and the slot within the chunk: where the two would need
     * more than 32 bits (tiles above 1024 pixels a side, or tens of millions of slots with tiles above 64),
     * chunks get smaller, and more. */
    rc->pix_bits = 2 * shift;
    /* Band lists (band_lists): bands of a power of two of rows, as many as keep a band's depth, winner and
     * colour (12 bytes a pixel) within 384 KiB, so a band stays in L2 (2 MiB here) with room for the entries
     * streaming through: 64 rows at 512 wide, 32 at 1024. Their keys hold the pixel within the band. */
    rc->band_z = !d.no_tiling && d.band_lists;
    rc->zband_shift = 0;
    while (rc->zband_shift < 16 && ((uint64_t)d.width << (rc->zband_shift + 1)) <= 32768 &&
           (1u << rc->zband_shift) < d.height)
        rc->zband_shift++;
    while (((uint64_t)d.height + (1u << rc->zband_shift) - 1) >> rc->zband_shift > VIEW_RC_MAX_TILES)
        rc->zband_shift++; /* at most as many bands as tiles (the counting's scratch) */
    rc->zband_rows = 1u << rc->zband_shift;
    rc->zband_count = (d.height + rc->zband_rows - 1) / rc->zband_rows;
    rc->zband_bits = 1;
    while (((uint64_t)1 << rc->zband_bits) < (uint64_t)rc->zband_rows * d.width)
        rc->zband_bits++;
    uint32_t key_bits = rc->band_z && rc->zband_bits > rc->pix_bits ? rc->zband_bits : rc->pix_bits;
    if (chunk_shift + key_bits > 32)
        chunk_shift = 32 - key_bits;
    rc->list_count = rc->band_z ? rc->zband_count : rc->tile_count;
    rc->count_stride = rc->list_count + 2;
    uint32_t chunk = 1u << chunk_shift;
    rc->chunk_shift = chunk_shift;
    rc->chunk_size = chunk;
    rc->chunk_count = (rc->slots + chunk - 1) / chunk;
    rc->low_w = (d.width + 3) / 4;
    rc->low_h = (d.height + 3) / 4;
    rc->drop_age = RC_AGE_NO_DROP;

    rc_layout l = {0};
    uint32_t lists = rc->count_stride > rc->tile_count + 2 ? rc->count_stride : rc->tile_count + 2;
    size_t o_px = take(&l, rc->slots, sizeof(float));
    size_t o_py = take(&l, rc->slots, sizeof(float));
    size_t o_pz = take(&l, rc->slots, sizeof(float));
    size_t o_rgba = take(&l, rc->slots, sizeof(uint32_t));
    size_t o_tile_of = take(&l, rc->slots, sizeof(uint16_t));
    size_t o_key = take(&l, rc->slots, sizeof(uint32_t));
    size_t o_dep = take(&l, rc->slots, sizeof(float));
    size_t o_dest = take(&l, rc->slots, sizeof(uint16_t));
    rc->mark_stride = ((size_t)rc->slots + 1 + 63) & ~(size_t)63; /* + a sink byte, a line apart */
    size_t o_mark = take(&l, rc->mark_stride * d.threads, 1);
    size_t o_free_slots = take(&l, rc->slots, sizeof(uint32_t));
    size_t o_free_list = take(&l, (size_t)rc->chunk_count * chunk, sizeof(uint32_t));
    size_t o_chunk_free = take(&l, rc->chunk_count, sizeof(uint32_t));
    size_t o_counts = take(&l, (size_t)rc->chunk_count * lists, sizeof(uint32_t));
    size_t o_chunk_hist = take(&l, (size_t)rc->chunk_count * 256, sizeof(uint32_t));
    size_t o_chunk_quota = take(&l, rc->chunk_count, sizeof(uint32_t));
    size_t o_chunk_stat = take(&l, rc->chunk_count, sizeof(rc_chunk_stat));
    /* Entries: one per slot, up to RC_ENTRY_LINE - 1 of padding per list (tile and part), then the sort's
     * sinks (one per thread, a line each). */
    rc->parts = d.threads;
    size_t lists_parts = (size_t)rc->list_count * rc->parts, line = RC_ENTRY_LINE;
    if ((size_t)rc->slots + line * lists_parts + line * (size_t)rc->parts > UINT32_MAX) {
        free(rc);
        return FXC_ERR_INVALID;
    }
    rc->entry_sink = (uint32_t)(((size_t)rc->slots + line * lists_parts + line - 1) & ~(line - 1));
    /* One thread's direct z-buffer (direct_z) uses no entries. */
    rc->direct_z = d.threads == 1 && !d.tiled_one_thread && !d.no_tiling && !rc->band_z;
    rc->band_flush = rc->band_z && d.threads == 1;
    size_t band_px = (size_t)rc->zband_rows * d.width;
    rc->zband_cap = (uint32_t)(band_px > chunk ? band_px : chunk);
    rc->zband_cap = (rc->zband_cap + (uint32_t)line - 1) & ~((uint32_t)line - 1);
    size_t entry_count = (size_t)rc->entry_sink + line * (size_t)rc->parts;
    if (rc->band_flush)
        entry_count = (size_t)rc->zband_count * rc->zband_cap + line;
    if (entry_count > UINT32_MAX) {
        free(rc);
        return FXC_ERR_INVALID;
    }
    size_t o_entries = take(&l, rc->direct_z ? 0 : entry_count, sizeof(rc_entry));
    size_t zbands = rc->band_flush ? rc->zband_count : 0;
    size_t o_zband_fill = take(&l, zbands, sizeof(uint32_t));
    size_t o_zband_nseg = take(&l, zbands, sizeof(uint32_t));
    size_t o_zband_seg = take(&l, zbands * 2 * rc->chunk_count, sizeof(uint32_t));
    size_t o_zband_clear = take(&l, zbands, 1);
    size_t o_list_start = take(&l, lists_parts, sizeof(uint32_t));
    size_t o_list_end = take(&l, lists_parts, sizeof(uint32_t));
    size_t o_zbuf = take(&l, rc->pixels, sizeof(float));
    size_t o_win = take(&l, rc->pixels, sizeof(uint32_t));
    size_t o_pre = take(&l, rc->pixels, sizeof(uint32_t));
    size_t o_pt = take(&l, rc->pixels, sizeof(uint32_t));
    size_t o_rgb = take(&l, rc->pixels, 3);
    size_t o_depth = take(&l, rc->pixels, sizeof(float));
    size_t o_kind = take(&l, rc->pixels, 1);
    size_t o_priority = take(&l, rc->pixels, 1);
    size_t o_chosen = take(&l, rc->pixels, 1);
    size_t o_stretch_x2 = take(&l, d.width, sizeof(float));
    size_t o_stretch_y2 = take(&l, d.height, sizeof(float));
    size_t o_row_need = take(&l, d.height, sizeof(uint32_t));
    size_t o_band_need = take(&l, rc->tiles_y, sizeof(uint32_t));
    size_t o_band_culled = take(&l, rc->tiles_y, sizeof(uint32_t));
    size_t o_band_kind = take(&l, (size_t)rc->tiles_y * VIEW_RC_PIXEL_KINDS, sizeof(uint32_t));
    size_t o_band_weight = take(&l, rc->tiles_y, sizeof(uint64_t));
    size_t o_band_quota = take(&l, rc->tiles_y, sizeof(uint32_t));
    size_t o_band_offset = take(&l, rc->tiles_y, sizeof(uint32_t));
    size_t o_requests = take(&l, d.sample_budget, sizeof(view_rc_pixel));
    size_t o_predicted = take(&l, d.sample_budget / 2 + 1, sizeof(view_rc_pixel));
    size_t o_workers = take(&l, d.threads, sizeof(rc_worker));
    size_t o_occupied[VIEW_RC_MAX_THREADS], o_low[VIEW_RC_MAX_THREADS], o_err[VIEW_RC_MAX_THREADS];
    size_t o_planes[VIEW_RC_MAX_THREADS], o_box[VIEW_RC_MAX_THREADS], o_spare[VIEW_RC_MAX_THREADS];
    size_t o_zt[VIEW_RC_MAX_THREADS], o_wt[VIEW_RC_MAX_THREADS], o_ct[VIEW_RC_MAX_THREADS];
    size_t o_halo[VIEW_RC_MAX_THREADS];
    rc->local_z = rc->tile <= RC_LOCAL_TILE;
    size_t local = rc->local_z ? (size_t)rc->tile * rc->tile : 0;
    for (uint32_t t = 0; t < d.threads; t++) {
        o_occupied[t] = take(&l, (size_t)rc->low_w * rc->low_h + 1, 1); /* + a sink byte */
        o_low[t] = take(&l, chunk, sizeof(uint32_t));
        o_err[t] = take(&l, 2 * RC_DITHER_LANES * ((size_t)d.width + 2), sizeof(float));
        o_spare[t] = take(&l, d.width, 1);
        o_planes[t] = take(&l, view_rc__interp_scratch(d.width), sizeof(uint16_t));
        o_box[t] = take(&l, view_rc__prefilter_scratch(span), sizeof(uint16_t));
        o_halo[t] = take(&l, 7 * (size_t)d.width, sizeof(uint32_t)); /* six rows of points, one of depths */
        o_zt[t] = take(&l, local, sizeof(float));
        o_wt[t] = take(&l, local, sizeof(uint32_t));
        o_ct[t] = take(&l, local, sizeof(uint32_t));
    }
    if (l.overflow) {
        free(rc);
        return FXC_ERR_INVALID;
    }
    /* Blocks of 2 MiB and more: aligned to 2 MiB and, on Linux, offered transparent huge pages (with
     * "madvise", the usual setting, a block gets 4 KiB pages unless asked): the point store, the tile lists
     * and the images are tens of MiB at 1024 x 1024, read and written at random (the sort's 256 lists, the
     * winners' colours, the marks), more than the TLB reaches with 4 KiB pages. Without them (another system,
     * or the kernel refusing) nothing changes but speed. */
    size_t align = 64, bytes = (l.bytes + 63) & ~(size_t)63;
    if (bytes >= RC_HUGE_PAGE) {
        align = RC_HUGE_PAGE;
        bytes = (bytes + RC_HUGE_PAGE - 1) & ~(size_t)(RC_HUGE_PAGE - 1);
    }
    char *block = aligned_alloc(align, bytes);
    if (!block) {
        free(rc);
        return FXC_ERR_NOMEM;
    }
#if defined(__linux__) && defined(MADV_HUGEPAGE)
    if (align == RC_HUGE_PAGE)
        (void)madvise(block, bytes, MADV_HUGEPAGE);
#endif
    rc->block = block;
    rc->memory_bytes = bytes + sizeof *rc;
    rc->px = (float *)(block + o_px);
    rc->py = (float *)(block + o_py);
    rc->pz = (float *)(block + o_pz);
    rc->rgba = (uint32_t *)(block + o_rgba);
    rc->tile_of = (uint16_t *)(block + o_tile_of);
    rc->key = (uint32_t *)(block + o_key);
    rc->dep = (float *)(block + o_dep);
    rc->dest = (uint16_t *)(block + o_dest);
    rc->mark = (uint8_t *)(block + o_mark);
    memset(rc->mark, 0, rc->mark_stride * d.threads);
    rc->free_slots = (uint32_t *)(block + o_free_slots);
    rc->free_list = (uint32_t *)(block + o_free_list);
    rc->chunk_free = (uint32_t *)(block + o_chunk_free);
    rc->counts = (uint32_t *)(block + o_counts);
    rc->chunk_hist = (uint32_t *)(block + o_chunk_hist);
    rc->chunk_quota = (uint32_t *)(block + o_chunk_quota);
    rc->chunk_stat = (rc_chunk_stat *)(block + o_chunk_stat);
    rc->entries = rc->direct_z ? NULL : (rc_entry *)(block + o_entries);
    rc->zband_fill = (uint32_t *)(block + o_zband_fill);
    rc->zband_nseg = (uint32_t *)(block + o_zband_nseg);
    rc->zband_seg = (uint32_t *)(block + o_zband_seg);
    rc->zband_clear = (uint8_t *)(block + o_zband_clear);
    rc->list_start = (uint32_t *)(block + o_list_start);
    rc->list_end = (uint32_t *)(block + o_list_end);
    rc->zbuf = (float *)(block + o_zbuf);
    rc->win = (uint32_t *)(block + o_win);
    rc->pre = (uint32_t *)(block + o_pre);
    rc->pt = (uint32_t *)(block + o_pt);
    rc->rgb = (uint8_t *)(block + o_rgb);
    rc->depth = (float *)(block + o_depth);
    rc->kind = (uint8_t *)(block + o_kind);
    rc->priority = (uint8_t *)(block + o_priority);
    rc->chosen = (uint8_t *)(block + o_chosen);
    rc->stretch_x2 = (float *)(block + o_stretch_x2);
    rc->stretch_y2 = (float *)(block + o_stretch_y2);
    rc->row_need = (uint32_t *)(block + o_row_need);
    rc->band_need = (uint32_t *)(block + o_band_need);
    rc->band_culled = (uint32_t *)(block + o_band_culled);
    rc->band_kind = (uint32_t *)(block + o_band_kind);
    rc->band_weight = (uint64_t *)(block + o_band_weight);
    rc->band_quota = (uint32_t *)(block + o_band_quota);
    rc->band_offset = (uint32_t *)(block + o_band_offset);
    rc->requests = (view_rc_pixel *)(block + o_requests);
    rc->predicted_requests = (view_rc_pixel *)(block + o_predicted);
    rc->workers = (rc_worker *)(block + o_workers);
    for (uint32_t t = 0; t < d.threads; t++) {
        rc->workers[t].occupied = (uint8_t *)(block + o_occupied[t]);
        rc->workers[t].low = (uint32_t *)(block + o_low[t]);
        rc->workers[t].err = (float *)(block + o_err[t]);
        rc->workers[t].spare = (uint8_t *)(block + o_spare[t]);
        rc->workers[t].planes = (uint16_t *)(block + o_planes[t]);
        rc->workers[t].box = (uint16_t *)(block + o_box[t]);
        rc->workers[t].halo = (uint32_t *)(block + o_halo[t]);
        rc->workers[t].zt = (float *)(block + o_zt[t]);
        rc->workers[t].wt = (uint32_t *)(block + o_wt[t]);
        rc->workers[t].ct = (uint32_t *)(block + o_ct[t]);
    }

    /* Every slot free; the stack hands out slot 0 first. */
    for (uint32_t i = 0; i < rc->slots; i++) {
        rc->rgba[i] = RC_AGE_DEAD << 24;
        rc->px[i] = rc->py[i] = rc->pz[i] = 0;
        rc->tile_of[i] = rc->list_dead;
        rc->free_slots[i] = rc->slots - 1 - i;
    }
    rc->free_count = rc->slots;
    memset(rc->chunk_hist, 0, (size_t)rc->chunk_count * 256 * sizeof(uint32_t));
    memset(rc->win, 0xFF, rc->pixels * sizeof(uint32_t));
    for (size_t p = 0; p < rc->pixels; p++)
        rc->pt[p] = RC_EMPTY_PT;

    rc->pool = fxc_pool_create(d.threads, NULL);
    if (!rc->pool) {
        free(block);
        free(rc);
        return FXC_ERR_THREADS;
    }
    *out = rc;
    return FXC_OK;
}

void view_rc_destroy(view_rc *rc)
{
    if (!rc)
        return;
    fxc_pool_free(rc->pool);
    free(rc->block);
    free(rc);
}

view_rc_desc view_rc_resolved_desc(const view_rc *rc)
{
    return rc->d;
}

size_t view_rc_memory_bytes(const view_rc *rc)
{
    return rc->memory_bytes;
}

/* ---- the store --------------------------------------------------------------------------------------- */

void view_rc__recount_ages(view_rc *rc)
{
    memset(rc->chunk_hist, 0, (size_t)rc->chunk_count * 256 * sizeof(uint32_t));
    for (uint32_t i = 0; i < rc->slots; i++) {
        uint32_t age = rc_age(rc->rgba[i]);
        if (age != RC_AGE_DEAD)
            rc->chunk_hist[(size_t)(i >> rc->chunk_shift) * 256 + age]++;
    }
}

/* Changes slot i's age (and its chunk's histogram). */
static void set_age(view_rc *rc, uint32_t i, uint32_t age)
{
    uint32_t old = rc_age(rc->rgba[i]);
    uint32_t *hist = rc->chunk_hist + (size_t)(i >> rc->chunk_shift) * 256;
    if (old != RC_AGE_DEAD)
        hist[old]--;
    if (age != RC_AGE_DEAD)
        hist[age]++;
    rc->rgba[i] = (rc->rgba[i] & 0x00FFFFFFu) | (age << 24);
}

/* The ages of all live points, summed over chunks. Returns the live count. */
static uint64_t total_ages(const view_rc *rc, uint64_t hist[256])
{
    memset(hist, 0, 256 * sizeof(uint64_t));
    uint64_t live = 0;
    for (uint32_t c = 0; c < rc->chunk_count; c++)
        for (uint32_t a = 0; a < 255; a++) {
            hist[a] += rc->chunk_hist[(size_t)c * 256 + a];
            live += rc->chunk_hist[(size_t)c * 256 + a];
        }
    return live;
}

/* Makes `incoming` slots free on the spot: the free stack is rebuilt from every free slot (those freed since
 * the last frame included), then the oldest points go (all older than some age, and the first ones of that
 * age in slot order). The last frame's winners may then name reused slots: the sparse supersede stops until
 * the next frame. */
static void make_room(view_rc *rc, uint32_t incoming)
{
    uint64_t hist[256];
    uint64_t live = total_ages(rc, hist);
    uint64_t drop = live + incoming > rc->slots ? live + incoming - rc->slots : 0;
    uint32_t drop_age = 256;
    uint64_t take = 0;
    if (drop > 0) {
        uint64_t above = 0;
        int age = 254;
        while (age > 0 && above + hist[age] < drop)
            above += hist[age--];
        drop_age = (uint32_t)age;
        take = drop - above;
    }
    rc->free_count = 0;
    for (uint32_t n = rc->slots; n-- > 0;) /* descending: the stack hands out low slots first */
        if (rc_age(rc->rgba[n]) == RC_AGE_DEAD)
            rc->free_slots[rc->free_count++] = n;
    if (drop_age < 256) {
        /* The oldest, in slot order (the first ones of the boundary age). */
        for (uint32_t i = 0; i < rc->slots; i++) {
            uint32_t age = rc_age(rc->rgba[i]);
            if (age == RC_AGE_DEAD || age < drop_age || (age == drop_age && take == 0))
                continue;
            if (age == drop_age)
                take--;
            rc->since_dropped++;
            rc->since_dropped_age_sum += age;
            set_age(rc, i, RC_AGE_DEAD);
            rc->free_slots[rc->free_count++] = i;
        }
    }
    rc->last_valid = false;
}

static bool depth_usable(float depth)
{
    return depth > 0; /* false for NaN and <= 0; +inf is the sky */
}

/* The batch's positions: the unit ray through each image position with srv_camera_ray's arithmetic, operation
 * for operation, then origin + distance x direction in double, stored relative to the cache's origin; and
 * their pixels in `last` (NULL: none). */
FXC_HOT_CLONES static void place_batch(rc_batch *restrict b, const rc_view *v, const rc_view *last,
                                       const double cache_origin[3])
{
    const float w = (float)v->width, h = (float)v->height, thx = v->tan_half_x, thy = v->tan_half_y;
    const float f0 = v->forward[0], f1 = v->forward[1], f2 = v->forward[2];
    const float r0 = v->right[0], r1 = v->right[1], r2 = v->right[2];
    const float u0 = v->up[0], u1 = v->up[1], u2 = v->up[2];
    const double o0 = v->origin[0] - cache_origin[0], o1 = v->origin[1] - cache_origin[1],
                 o2 = v->origin[2] - cache_origin[2];
    for (uint32_t k = 0; k < b->n; k++) {
        float sx = (2.0f * b->px[k] / w - 1.0f) * thx;
        float sy = (1.0f - 2.0f * b->py[k] / h) * thy;
        float d0 = f0 + sx * r0 + sy * u0, d1 = f1 + sx * r1 + sy * u1, d2 = f2 + sx * r2 + sy * u2;
        float inv = 1.0f / sqrtf(d0 * d0 + d1 * d1 + d2 * d2);
        d0 *= inv, d1 *= inv, d2 *= inv;
        double dist = b->dist[k] > 3.0e38f ? VIEW_RC_SKY_DISTANCE : (double)b->dist[k];
        b->x[k] = (float)(o0 + dist * (double)d0);
        b->y[k] = (float)(o1 + dist * (double)d1);
        b->z[k] = (float)(o2 + dist * (double)d2);
    }
    if (!last)
        return;
    const float cx = last->rel[0], cy = last->rel[1], cz = last->rel[2];
    const float lf0 = last->forward[0], lf1 = last->forward[1], lf2 = last->forward[2];
    const float lr0 = last->right[0], lr1 = last->right[1], lr2 = last->right[2];
    const float lu0 = last->up[0], lu1 = last->up[1], lu2 = last->up[2];
    const float lw = (float)last->width, lh = (float)last->height;
    for (uint32_t k = 0; k < b->n; k++) {
        float vx = b->x[k] - cx, vy = b->y[k] - cy, vz = b->z[k] - cz;
        float zc = vx * lf0 + vy * lf1 + vz * lf2;
        float xc = vx * lr0 + vy * lr1 + vz * lr2;
        float yc = vx * lu0 + vy * lu1 + vz * lu2;
        float inv = 1.0f / zc;
        float qx = last->half_w + last->kx * xc * inv, qy = last->half_h - last->ky * yc * inv;
        bool inside = (zc > RC_NEAR) & (qx >= 0.0f) & (qx < lw) & (qy >= 0.0f) & (qy < lh);
        uint32_t ix = (uint32_t)(int32_t)(inside ? qx : 0.0f), iy = (uint32_t)(int32_t)(inside ? qy : 0.0f);
        b->last_pix[k] = inside ? iy * last->width + ix : RC_NO_PIXEL;
        b->last_depth[k] = zc;
    }
}

/* Takes a free slot for the batch's point k. */
static uint32_t add_batch_point(view_rc *rc, const rc_batch *b, uint32_t k)
{
    uint32_t i = rc->free_slots[--rc->free_count];
    const uint8_t *rgb = b->rgb[k];
    rc->px[i] = b->x[k];
    rc->py[i] = b->y[k];
    rc->pz[i] = b->z[k];
    rc->rgba[i] = (uint32_t)rgb[0] | (uint32_t)rgb[1] << 8 | (uint32_t)rgb[2] << 16;
    rc->tile_of[i] = rc->list_new;
    rc->chunk_hist[(size_t)(i >> rc->chunk_shift) * 256]++;
    return i;
}

/* Sets up an insert's camera (and the cache's origin at the first insert). */
static fxc_result insert_view(view_rc *rc, const view_rc_camera *cam, uint32_t width, uint32_t height,
                              rc_view *v)
{
    if (!cam || width == 0 || height == 0 || width > VIEW_RC_MAX_SIDE || height > VIEW_RC_MAX_SIDE)
        return FXC_ERR_INVALID;
    double origin[3] = {cam->position[0], cam->position[1], cam->position[2]};
    if (!view_rc__view_setup(cam, width, height, rc->has_origin ? rc->origin : origin, v))
        return FXC_ERR_CAMERA;
    if (!rc->has_origin) {
        memcpy(rc->origin, origin, sizeof origin);
        rc->has_origin = true;
    }
    return FXC_OK;
}

fxc_result view_rc_insert_frame(view_rc *rc, const view_rc_camera *cam, uint32_t width, uint32_t height,
                                const uint8_t *rgb, const float *depth)
{
    if (!rc || !rgb || !depth)
        return FXC_ERR_INVALID;
    double t0 = view_rc__now_ms();
    rc_view v;
    fxc_result result = insert_view(rc, cam, width, height, &v);
    if (result != FXC_OK)
        return result;
    size_t pixels = (size_t)width * height;
    uint64_t incoming = 0;
    for (size_t p = 0; p < pixels; p++)
        incoming += depth_usable(depth[p]);
    if (incoming > rc->d.capacity)
        return FXC_ERR_RANGE;

    /* Every cached point the frame saw goes: it is not behind the frame's surface at its pixel. */
    float keep = 1.0f + rc->d.supersede_ratio;
    for (uint32_t i = 0; i < rc->slots; i++) {
        if (rc_age(rc->rgba[i]) == RC_AGE_DEAD)
            continue;
        uint32_t x, y;
        float zc;
        if (!rc_project(&v, rc->px[i], rc->py[i], rc->pz[i], &x, &y, &zc))
            continue;
        float d = depth[(size_t)y * width + x];
        if (!depth_usable(d))
            continue;
        float dx = rc->px[i] - v.rel[0], dy = rc->py[i] - v.rel[1], dz = rc->pz[i] - v.rel[2];
        float limit = d * keep;
        if (isinf(d) || dx * dx + dy * dy + dz * dz < limit * limit) {
            set_age(rc, i, RC_AGE_DEAD);
            rc->since_superseded++;
        }
    }
    /* The last frame's winners are gone or replaced: no sparse supersede through them until the next frame.
     */
    rc->last_valid = false;
    if (rc->free_count < incoming)
        make_room(rc, (uint32_t)incoming);

    rc_batch *b = &rc->batch;
    b->n = 0;
    for (uint32_t y = 0; y < height; y++)
        for (uint32_t x = 0; x < width; x++) {
            size_t p = (size_t)y * width + x;
            if (!depth_usable(depth[p]))
                continue;
            b->px[b->n] = (float)x + 0.5f, b->py[b->n] = (float)y + 0.5f, b->dist[b->n] = depth[p];
            b->rgb[b->n++] = rgb + 3 * p;
            if (b->n == RC_BATCH) {
                place_batch(b, &v, NULL, rc->origin);
                for (uint32_t k = 0; k < b->n; k++)
                    add_batch_point(rc, b, k);
                b->n = 0;
            }
        }
    if (b->n > 0) {
        place_batch(b, &v, NULL, rc->origin);
        for (uint32_t k = 0; k < b->n; k++)
            add_batch_point(rc, b, k);
    }
    rc->since_inserted += (uint32_t)incoming;
    rc->since_update_ms += view_rc__now_ms() - t0;
    return FXC_OK;
}

/* Ages the point the last frame showed at pixel q by penalty (evicted at 255, unless eviction is off). */
static void penalise(view_rc *rc, uint32_t q)
{
    uint32_t w = rc->win[q];
    if (rc->pt[q] == RC_EMPTY_PT || w == RC_NO_POINT)
        return;
    uint32_t age = rc_age(rc->rgba[w]);
    if (age == RC_AGE_DEAD)
        return;
    age += rc->d.change_penalty;
    uint32_t top = rc->d.no_eviction ? 254 : 255;
    set_age(rc, w, age > top ? top : age);
}

/* The point the last frame showed at pixel q is replaced by a new sample at view depth `depth` there, unless
 * it lies well behind it; when their colours differ, the pixel's neighbours age. */
static void supersede(view_rc *rc, uint32_t q, float depth, const uint8_t rgb[3])
{
    if (q == RC_NO_PIXEL)
        return;
    uint32_t w = rc->win[q];
    if (rc->pt[q] == RC_EMPTY_PT || w == RC_NO_POINT)
        return;
    uint32_t old = rc->rgba[w];
    if (rc_age(old) == RC_AGE_DEAD || !(rc->zbuf[q] < depth * (1.0f + rc->d.supersede_ratio)))
        return;
    int change = 0;
    for (int k = 0; k < 3; k++) {
        int diff = abs((int)((old >> (8 * k)) & 0xFF) - (int)rgb[k]);
        change = diff > change ? diff : change;
    }
    const rc_view *last = &rc->last_view;
    uint32_t qx = q % last->width, qy = q / last->width;
    if (change > rc->d.change_threshold)
        for (int dy = -1; dy <= 1; dy++)
            for (int dx = -1; dx <= 1; dx++) {
                int64_t nx = (int64_t)qx + dx, ny = (int64_t)qy + dy;
                if ((dx || dy) && nx >= 0 && ny >= 0 && nx < last->width && ny < last->height)
                    penalise(rc, (uint32_t)ny * last->width + (uint32_t)nx);
            }
    set_age(rc, w, RC_AGE_DEAD);
    rc->since_superseded++;
}

fxc_result view_rc_insert_samples(view_rc *rc, const view_rc_camera *cam, uint32_t width, uint32_t height,
                                  const view_rc_sample *samples, uint32_t count)
{
    if (!rc || (!samples && count > 0))
        return FXC_ERR_INVALID;
    double t0 = view_rc__now_ms();
    rc_view v;
    fxc_result result = insert_view(rc, cam, width, height, &v);
    if (result != FXC_OK)
        return result;
    uint32_t incoming = 0;
    for (uint32_t s = 0; s < count; s++)
        incoming += samples[s].x < width && samples[s].y < height && depth_usable(samples[s].depth);
    if (incoming > rc->d.capacity)
        return FXC_ERR_RANGE;
    if (rc->free_count < incoming)
        make_room(rc, incoming);

    rc_batch *b = &rc->batch;
    for (uint32_t s = 0; s < count;) {
        const view_rc_sample *in[RC_BATCH];
        b->n = 0;
        for (; s < count && b->n < RC_BATCH; s++) {
            const view_rc_sample *sample = &samples[s];
            if (!(sample->x < width && sample->y < height && depth_usable(sample->depth)))
                continue;
            in[b->n] = sample;
            b->px[b->n] = (float)sample->x + 0.5f, b->py[b->n] = (float)sample->y + 0.5f;
            b->dist[b->n] = sample->depth;
            b->rgb[b->n++] = sample->rgb;
        }
        place_batch(b, &v, rc->last_valid ? &rc->last_view : NULL, rc->origin);
        for (uint32_t k = 0; k < b->n; k++) {
            add_batch_point(rc, b, k);
            if (rc->last_valid)
                supersede(rc, b->last_pix[k], b->last_depth[k], in[k]->rgb);
        }
    }
    rc->since_inserted += incoming;
    rc->since_update_ms += view_rc__now_ms() - t0;
    return FXC_OK;
}

uint32_t view_rc_point_count(const view_rc *rc)
{
    uint64_t hist[256];
    return (uint32_t)total_ages(rc, hist);
}

uint32_t view_rc_points(const view_rc *rc, uint32_t first, uint32_t count, view_rc_point *out)
{
    uint32_t seen = 0, copied = 0;
    for (uint32_t i = 0; i < rc->slots && copied < count; i++) {
        uint32_t rgba = rc->rgba[i];
        if (rc_age(rgba) == RC_AGE_DEAD)
            continue;
        if (seen++ < first)
            continue;
        view_rc_point *p = &out[copied++];
        p->position[0] = rc->origin[0] + (double)rc->px[i];
        p->position[1] = rc->origin[1] + (double)rc->py[i];
        p->position[2] = rc->origin[2] + (double)rc->pz[i];
        p->rgb[0] = (uint8_t)rgba;
        p->rgb[1] = (uint8_t)(rgba >> 8);
        p->rgb[2] = (uint8_t)(rgba >> 16);
        p->age = (uint8_t)rc_age(rgba);
    }
    return copied;
}
