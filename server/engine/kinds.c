/* The cache kinds, by scene_cache_kind. Adding a kind (the world-space cache) is one file implementing
 * srv_cache_kind and one line here. */
#include "engine_internal.h"

static const srv_cache_kind *const kinds[SCENE_CACHE_COUNT] = {
    [SCENE_CACHE_ON_SURFACE] = &srv__kind_osc,
    [SCENE_CACHE_WORLD_SPACE] = &srv__kind_wsc,
};

const srv_cache_kind *srv__cache_kind(scene_cache_kind kind)
{
    return (unsigned)kind < SCENE_CACHE_COUNT ? kinds[kind] : NULL;
}
