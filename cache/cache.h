/* cache.h: the public header of the cache module (stage 3 "requests", stage 4 "update queuing" and
 * stage 9 "housekeeping" of the frame, see DESIGN.md).
 *
 * The module holds the shared effect caches that every viewer's requests land in:
 *   - the on-surface cache (osc_*, cache/osc.h): 8 x 8 texel blocks keyed by
 *     effect | island | level | block_y | block_x, one hash table for all effects, one block pool per effect;
 *   - the world-space cache (wsc_*, cache/wsc.h): bricks of 1 x 1 x 1 or 4 x 4 x 4 grid cells keyed by a
 *     world-grid index, one single-pool osc core (table and pool) per world-space effect, and a per-viewer
 *     local lookup table.
 * It depends on nothing else of fxcache's: pure C11, libm and (for callers that gather requests on
 * several threads) nothing more than per-thread buffers merged with osc_request_batch(). */
#ifndef FXC_CACHE_H
#define FXC_CACHE_H

#include "osc.h"
#include "wsc.h"

#endif
