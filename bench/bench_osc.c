/* bench_osc.c: lookup throughput of the on-surface cache's hash table (cache/osc_table.c) on one core,
 * against uthash (HASH_FIND, uint64 keys, its default Jenkins hash) and GLib's GHashTable (g_int64_hash)
 * fed the same key stream in the same run.
 *
 * The keys are shaped like real ones: four effects, island ids from a large sparse set, levels 0..4
 * (mostly fine), small block coordinates. For each table size (2^16 slots: keys fit in L2; 2^20 slots:
 * 8 MiB of keys, beyond L2) and load (50 %, 75 %), the cache is filled through osc_request, then a
 * stream of random resident keys (hits) and of absent keys (misses) is looked up; best of several runs.
 * "ours" is osc_find (one key at a time), "ours batched" is osc_find_batch (prefetching groups of 16).
 *
 * Run:  cmake --build build-osc --target bench_osc && ./build-osc/bench/bench_osc [--quick]
 * Prints a markdown table and the ratio ours / faster of uthash and GHashTable. Targets: 100 M lookups/s
 * per core, and at least 2x the faster of the two. */
#include "cache.h"

#include <glib.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wshadow"
#include <uthash.h>
#pragma GCC diagnostic pop

typedef struct uthash_item {
    uint64_t key;
    uint32_t value;
    UT_hash_handle hh;
} uthash_item;

static uint64_t bench_rng(uint64_t *state)
{
    uint64_t z = (*state += 0x9e3779b97f4a7c15ull);
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
    return z ^ (z >> 31);
}

/* A key like those stage 3 produces. */
static uint64_t realistic_key(uint64_t *state)
{
    uint64_t r = bench_rng(state);
    uint32_t effect = (uint32_t)(r & 3);
    uint32_t island = (uint32_t)((r >> 2) % 400000u) * 7u + 1000u;
    uint32_t level_pick = (uint32_t)(r >> 24) & 15;
    uint32_t level = level_pick < 8 ? 0 : level_pick < 12 ? 1 : level_pick < 14 ? 2 : level_pick < 15 ? 3 : 4;
    uint32_t span = 64u >> level;
    uint32_t block_x = (uint32_t)(r >> 32) % span, block_y = (uint32_t)(r >> 48) % span;
    return osc_key_pack(effect, island, level, block_x, block_y);
}

static double now_seconds(void)
{
    struct timespec time_now;
    clock_gettime(CLOCK_MONOTONIC, &time_now);
    return (double)time_now.tv_sec + (double)time_now.tv_nsec * 1e-9;
}

static volatile uint64_t bench_sink; /* keeps results alive */

typedef enum { IMPL_OURS, IMPL_OURS_BATCH, IMPL_UTHASH, IMPL_GHASH, IMPL_COUNT } bench_impl;

typedef struct bench_tables {
    osc_cache *cache;
    uthash_item *uthash_head;
    GHashTable *ghash;
    uint32_t *batch_out;
} bench_tables;

/* Looks up every key of the stream once with one implementation; returns seconds. */
static double run_stream(const bench_tables *tables, bench_impl impl, const uint64_t *stream, size_t count)
{
    uint64_t checksum = 0;
    double start = now_seconds();
    switch (impl) {
    case IMPL_OURS:
        for (size_t i = 0; i < count; i++)
            checksum += osc_find(tables->cache, stream[i]);
        break;
    case IMPL_OURS_BATCH: {
        enum { CHUNK = 4096 };
        for (size_t base = 0; base < count; base += CHUNK) {
            size_t n = count - base < CHUNK ? count - base : CHUNK;
            osc_find_batch(tables->cache, stream + base, n, tables->batch_out);
            for (size_t i = 0; i < n; i++)
                checksum += tables->batch_out[i];
        }
        break;
    }
    case IMPL_UTHASH:
        for (size_t i = 0; i < count; i++) {
            uthash_item *found = NULL;
            HASH_FIND(hh, tables->uthash_head, &stream[i], sizeof(uint64_t), found);
            checksum += found ? found->value : OSC_NONE;
        }
        break;
    case IMPL_GHASH:
        for (size_t i = 0; i < count; i++) {
            gpointer found = g_hash_table_lookup(tables->ghash, &stream[i]);
            checksum += found ? (uint32_t)(GPOINTER_TO_SIZE(found) - 1) : OSC_NONE;
        }
        break;
    default: break;
    }
    double seconds = now_seconds() - start;
    bench_sink += checksum;
    return seconds;
}

static void check_same_answers(const bench_tables *tables, const uint64_t *stream, size_t count)
{
    for (size_t i = 0; i < count; i += 997) {
        uint32_t ours = osc_find(tables->cache, stream[i]);
        uthash_item *found = NULL;
        HASH_FIND(hh, tables->uthash_head, &stream[i], sizeof(uint64_t), found);
        gpointer g = g_hash_table_lookup(tables->ghash, &stream[i]);
        uint32_t theirs = found ? found->value : OSC_NONE;
        uint32_t glib = g ? (uint32_t)(GPOINTER_TO_SIZE(g) - 1) : OSC_NONE;
        if (ours != theirs || ours != glib) {
            fprintf(stderr, "bench_osc: implementations disagree on key %016llx\n",
                    (unsigned long long)stream[i]);
            exit(1);
        }
    }
}

static void bench_config(uint32_t slots_log2, uint32_t load_percent, size_t stream_count, int repeats)
{
    uint32_t slots = 1u << slots_log2;
    uint32_t keys_wanted = (uint32_t)((uint64_t)slots * load_percent / 100);
    osc_desc desc = {0};
    for (int effect = 0; effect < 4; effect++) {
        desc.effects[effect].texel_bytes = 2;
        desc.effects[effect].max_blocks = keys_wanted / 4 + keys_wanted / 16 + 64; /* keys spread evenly */
    }
    desc.table_capacity = slots;
    desc.max_load_percent = load_percent < 75 ? 75 : load_percent;
    bench_tables tables = {0};
    char message[256];
    if (osc_create(&desc, &tables.cache, message, sizeof message) != OSC_OK) {
        fprintf(stderr, "bench_osc: osc_create: %s\n", message);
        exit(1);
    }
    tables.ghash = g_hash_table_new(g_int64_hash, g_int64_equal);
    tables.batch_out = malloc(4096 * sizeof(uint32_t));
    uint64_t *resident = malloc((size_t)keys_wanted * sizeof(uint64_t));
    uthash_item *items = malloc((size_t)keys_wanted * sizeof(uthash_item));
    uint64_t *stream = malloc(stream_count * sizeof(uint64_t));
    if (!tables.ghash || !tables.batch_out || !resident || !items || !stream) {
        fprintf(stderr, "bench_osc: out of memory\n");
        exit(1);
    }
    /* Fill all three with the same keys and values. */
    uint64_t rng = 12345 + slots_log2 * 100 + load_percent;
    osc_begin_frame(tables.cache, 0);
    uint32_t filled = 0;
    while (filled < keys_wanted) {
        uint64_t key = realistic_key(&rng);
        if (osc_find(tables.cache, key) != OSC_NONE)
            continue;
        uint32_t block;
        if (osc_request(tables.cache, key, 1, &block) != OSC_OK) {
            fprintf(stderr, "bench_osc: fill failed at %u keys\n", filled);
            exit(1);
        }
        resident[filled] = key;
        items[filled].key = key;
        items[filled].value = block;
        HASH_ADD(hh, tables.uthash_head, key, sizeof(uint64_t), &items[filled]);
        g_hash_table_insert(tables.ghash, &items[filled].key, GSIZE_TO_POINTER((gsize)block + 1));
        filled++;
    }
    osc_stats stats;
    osc_stats_get(tables.cache, &stats);

    for (int hits = 1; hits >= 0; hits--) {
        for (size_t i = 0; i < stream_count; i++) {
            if (hits) {
                stream[i] = resident[bench_rng(&rng) % filled];
            } else {
                uint64_t key;
                do
                    key = realistic_key(&rng);
                while (osc_find(tables.cache, key) != OSC_NONE);
                stream[i] = key;
            }
        }
        check_same_answers(&tables, stream, stream_count);
        double best[IMPL_COUNT];
        for (int impl = 0; impl < IMPL_COUNT; impl++) {
            best[impl] = 1e30;
            for (int r = 0; r < repeats; r++) {
                double seconds = run_stream(&tables, (bench_impl)impl, stream, stream_count);
                if (seconds < best[impl])
                    best[impl] = seconds;
            }
        }
        double rate[IMPL_COUNT];
        for (int impl = 0; impl < IMPL_COUNT; impl++)
            rate[impl] = (double)stream_count / best[impl] / 1e6;
        double faster_other = rate[IMPL_UTHASH] > rate[IMPL_GHASH] ? rate[IMPL_UTHASH] : rate[IMPL_GHASH];
        printf("| 2^%u | %u %% (%u keys) | %s | %.1f | %.1f | %.1f | %.1f | %.2fx | %.2fx |\n", slots_log2,
               load_percent, stats.table_count, hits ? "hits" : "misses", rate[IMPL_OURS],
               rate[IMPL_OURS_BATCH], rate[IMPL_UTHASH], rate[IMPL_GHASH], rate[IMPL_OURS] / faster_other,
               rate[IMPL_OURS_BATCH] / faster_other);
        fflush(stdout);
    }
    HASH_CLEAR(hh, tables.uthash_head);
    g_hash_table_destroy(tables.ghash);
    osc_destroy(tables.cache);
    free(tables.batch_out);
    free(resident);
    free(items);
    free(stream);
}

int main(int argc, char **argv)
{
    int quick = argc > 1 && strcmp(argv[1], "--quick") == 0;
    if (argc > 1 && !quick) {
        printf("usage: bench_osc [--quick]\n  table lookups per second (M/s), single core: osc_find, "
               "osc_find_batch, uthash, GHashTable\n");
        return strcmp(argv[1], "--help") == 0 ? 0 : 2;
    }
    size_t stream_count = quick ? (1u << 20) : (1u << 22);
    int repeats = quick ? 2 : 3;
    printf("osc table lookups, single core, %zu lookups per run, best of %d; M lookups/s\n\n", stream_count,
           repeats);
    printf(
        "| slots | load | stream | ours osc_find | ours osc_find_batch | uthash | GHashTable | ours / faster "
        "other | batched / faster other |\n");
    printf("|---|---|---|---|---|---|---|---|---|\n");
    const uint32_t sizes[] = {16, 20};
    const uint32_t loads[] = {50, 75};
    for (size_t s = 0; s < 2; s++)
        for (size_t l = 0; l < 2; l++)
            bench_config(sizes[s], loads[l], stream_count, repeats);
    printf("\n(checksum %llu)\n", (unsigned long long)bench_sink);
    return 0;
}
