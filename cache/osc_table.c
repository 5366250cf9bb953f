/* osc_table.c: the on-surface cache's hash table. One table for all effects (the key carries the effect),
 * open addressing with linear probing over a power-of-two array of keys; values (block indices) live in a
 * separate array that is read only on a hit, so probing streams through keys alone (8 per cache line).
 * Deletion shifts the rest of the probe run back (no tombstones), so lookups never degrade with churn.
 * The arrays are owned by the cache (osc.c), which allocates them once; nothing here allocates. */
#include "osc_internal.h"

#include <string.h>

#if defined(__GNUC__) || defined(__clang__)
#define OSC__PREFETCH(address) __builtin_prefetch(address)
#else
#define OSC__PREFETCH(address) ((void)(address))
#endif

/* Initializes the table over caller-owned arrays and marks every slot empty. */
void osc__table_init(osc__table *table, uint64_t *keys, uint32_t *values, uint32_t capacity,
                     uint32_t max_count)
{
    OSC_ASSERT(capacity >= 16 && (capacity & (capacity - 1)) == 0);
    OSC_ASSERT(max_count < capacity);
    table->keys = keys;
    table->values = values;
    table->capacity = capacity;
    table->mask = capacity - 1;
    table->count = 0;
    table->max_count = max_count;
    /* OSC_KEY_EMPTY is all ones, so a byte fill marks every slot empty. */
    memset(keys, 0xFF, (size_t)capacity * sizeof keys[0]);
    memset(values, 0xFF, (size_t)capacity * sizeof values[0]);
}

/* Batched lookup: hashes a group of keys, prefetches their home slots, then probes; hides memory latency
 * when the table is larger than the caches. */
void osc__table_find_batch(const osc__table *table, const uint64_t *keys, size_t count, uint32_t *values_out)
{
    enum { GROUP = 16 };
    uint32_t slots[GROUP];
    const uint64_t *table_keys = table->keys;
    uint32_t mask = table->mask;
    for (size_t base = 0; base < count; base += GROUP) {
        size_t group = count - base < GROUP ? count - base : GROUP;
        for (size_t i = 0; i < group; i++) {
            slots[i] = (uint32_t)osc__hash(keys[base + i]) & mask;
            OSC__PREFETCH(&table_keys[slots[i]]);
        }
        for (size_t i = 0; i < group; i++) {
            uint64_t key = keys[base + i];
            uint32_t slot = slots[i];
            uint32_t value = OSC_NONE;
            for (uint32_t step = 0; step <= mask; step++) {
                uint64_t stored = table_keys[slot];
                if (stored == key) {
                    value = table->values[slot];
                    break;
                }
                if (stored == OSC_KEY_EMPTY)
                    break;
                slot = (slot + 1) & mask;
            }
            values_out[base + i] = key == OSC_KEY_EMPTY ? OSC_NONE : value;
        }
    }
}

/* Inserts an absent key at the first empty slot of its probe run. */
bool osc__table_insert(osc__table *table, uint64_t key, uint32_t value)
{
    OSC_ASSERT(key != OSC_KEY_EMPTY);
    if (table->count >= table->max_count)
        return false;
    uint32_t mask = table->mask;
    uint32_t slot = (uint32_t)osc__hash(key) & mask;
    for (uint32_t step = 0; step <= mask; step++) {
        uint64_t stored = table->keys[slot];
        OSC_ASSERT(stored != key); /* callers insert absent keys only */
        if (stored == OSC_KEY_EMPTY) {
            table->keys[slot] = key;
            table->values[slot] = value;
            table->count++;
            return true;
        }
        slot = (slot + 1) & mask;
    }
    OSC_ASSERT(!"osc table has no empty slot below max load");
    return false;
}

/* Backward-shift deletion. Walk the run after the hole; an entry may move into the hole when its home
 * slot is not cyclically inside (hole, entry], i.e. when its probe distance reaches back to the hole. */
void osc__table_remove_slot(osc__table *table, uint32_t slot)
{
    uint32_t mask = table->mask;
    uint64_t *keys = table->keys;
    uint32_t hole = slot;
    uint32_t next = (slot + 1) & mask;
    OSC_ASSERT(keys[slot] != OSC_KEY_EMPTY);
    for (uint32_t step = 0; step < mask && keys[next] != OSC_KEY_EMPTY; step++) {
        uint32_t home = (uint32_t)osc__hash(keys[next]) & mask;
        uint32_t distance_from_home = (next - home) & mask;
        uint32_t distance_from_hole = (next - hole) & mask;
        if (distance_from_home >= distance_from_hole) {
            keys[hole] = keys[next];
            table->values[hole] = table->values[next];
            hole = next;
        }
        next = (next + 1) & mask;
    }
    keys[hole] = OSC_KEY_EMPTY;
    table->values[hole] = OSC_NONE;
    table->count--;
}

/* Removes key if present. */
bool osc__table_remove(osc__table *table, uint64_t key)
{
    if (key == OSC_KEY_EMPTY)
        return false;
    uint32_t slot = osc__table_find_slot(table, key);
    if (slot == OSC_NONE)
        return false;
    osc__table_remove_slot(table, slot);
    return true;
}

/* Invariant check for tests: every stored key is found at its own slot by a normal probe (so no empty
 * slot lies between its home and its slot), and the count is right. O(capacity x probe length). */
bool osc__table_check(const osc__table *table)
{
    uint32_t stored = 0;
    for (uint32_t slot = 0; slot < table->capacity; slot++) {
        uint64_t key = table->keys[slot];
        if (key == OSC_KEY_EMPTY)
            continue;
        stored++;
        if (osc__table_find_slot(table, key) != slot)
            return false;
    }
    return stored == table->count && table->count <= table->max_count;
}
