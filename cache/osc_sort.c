/* osc_sort.c: in-place MSD radix sort of 64-bit keys (American flag sort), used to make batched requests
 * independent of their order (osc_request_batch) and to order eviction candidates by age. In place so that
 * batches of any size need no scratch memory; 8-bit digits from the top, a digit shared by a whole range
 * is skipped without moving anything (keys share their effect and island bits), insertion sort below a
 * small size. */
#include "osc_internal.h"

enum { OSC__SORT_SMALL = 32 };

static void osc__insertion_sort(uint64_t *keys, uint64_t *payload, size_t count)
{
    for (size_t i = 1; i < count; i++) {
        uint64_t key = keys[i];
        uint64_t value = payload ? payload[i] : 0;
        size_t j = i;
        while (j > 0 && keys[j - 1] > key) {
            keys[j] = keys[j - 1];
            if (payload)
                payload[j] = payload[j - 1];
            j--;
        }
        keys[j] = key;
        if (payload)
            payload[j] = value;
    }
}

static void osc__radix_sort(uint64_t *keys, uint64_t *payload, size_t count, unsigned shift)
{
    if (count <= OSC__SORT_SMALL) {
        osc__insertion_sort(keys, payload, count);
        return;
    }
    size_t bucket_count[256] = {0};
    for (size_t i = 0; i < count; i++)
        bucket_count[(keys[i] >> shift) & 0xFFu]++;
    if (bucket_count[(keys[0] >> shift) & 0xFFu] == count) { /* one digit for all: go to the next */
        if (shift > 0)
            osc__radix_sort(keys, payload, count, shift - 8);
        return;
    }
    size_t next[256], end[256];
    size_t offset = 0;
    for (unsigned bucket = 0; bucket < 256; bucket++) {
        next[bucket] = offset;
        offset += bucket_count[bucket];
        end[bucket] = offset;
    }
    /* Cycle leader permutation: carry an element to the next free place of its bucket until an element
     * of the current bucket comes back. */
    for (unsigned bucket = 0; bucket < 256; bucket++) {
        while (next[bucket] < end[bucket]) {
            uint64_t key = keys[next[bucket]];
            uint64_t value = payload ? payload[next[bucket]] : 0;
            unsigned digit = (unsigned)(key >> shift) & 0xFFu;
            while (digit != bucket) {
                size_t place = next[digit]++;
                uint64_t displaced_key = keys[place];
                keys[place] = key;
                key = displaced_key;
                if (payload) {
                    uint64_t displaced_value = payload[place];
                    payload[place] = value;
                    value = displaced_value;
                }
                digit = (unsigned)(key >> shift) & 0xFFu;
            }
            keys[next[bucket]] = key;
            if (payload)
                payload[next[bucket]] = value;
            next[bucket]++;
        }
    }
    if (shift == 0)
        return;
    size_t start = 0;
    for (unsigned bucket = 0; bucket < 256; bucket++) {
        if (bucket_count[bucket] > 1)
            osc__radix_sort(keys + start, payload ? payload + start : NULL, bucket_count[bucket], shift - 8);
        start += bucket_count[bucket];
    }
}

/* Sorts keys ascending in place, payload moving along (see osc_internal.h). */
void osc__sort_u64(uint64_t *keys, uint64_t *payload, size_t count)
{
    if (count > 1)
        osc__radix_sort(keys, payload, count, 56);
}
