/* The effect registry: the built-in effects in key order, lookup by name, and what a scene needs.
 *
 * Adding an effect: write its file with one `const fx_effect fx_effect_NAME = {...}` (see effects.h and
 * fx_ao.c for a complete one) and add one line to `builtin` below. The frame loop, the needs decision, the
 * command line and the statistics iterate over this list; nothing else names an effect. */
#include "fx_internal.h"

#include <string.h>

static const fx_effect *const builtin[] = {
    &fx_effect_triangle_lookup, /* 0: every on-surface effect depends on it */
    &fx_effect_shadow,          /* 1 */
    &fx_effect_ao,              /* 2 */
    &fx_effect_probes,          /* 3: world-space (SCENE_FX_PROBES) */
};

const fx_effect *const *fx_registry(uint32_t *count)
{
    *count = (uint32_t)(sizeof builtin / sizeof builtin[0]);
    return builtin;
}

int32_t fx_find(const fx_effect *const *effects, uint32_t count, const char *name)
{
    if (!name)
        return -1;
    for (uint32_t i = 0; i < count; i++)
        if (strcmp(effects[i]->name, name) == 0 ||
            (effects[i]->alias && strcmp(effects[i]->alias, name) == 0))
            return (int32_t)i;
    return -1;
}

void fx_needs(const fx_effect *const *effects, uint32_t count, const scene *s, bool *needed, char (*why)[200])
{
    for (uint32_t i = 0; i < count; i++) {
        needed[i] = false;
        why[i][0] = '\0';
        if (effects[i]->needs)
            needed[i] = effects[i]->needs(s, why[i], sizeof why[i]);
    }
    /* Effects without a decision of their own serve the effects that depend on them. */
    for (uint32_t i = 0; i < count; i++) {
        if (effects[i]->needs)
            continue;
        char users[160] = "";
        for (uint32_t j = 0; j < count; j++)
            if (needed[j] && effects[j]->depends_on &&
                strcmp(effects[j]->depends_on, effects[i]->name) == 0) {
                size_t used = strlen(users);
                snprintf(users + used, sizeof users - used, "%s%s", used ? ", " : "", effects[j]->name);
            }
        needed[i] = users[0] != '\0';
        if (needed[i])
            snprintf(why[i], sizeof why[i], "needed by %s", users);
        else
            snprintf(why[i], sizeof why[i], "no effect that depends on it runs");
    }
}

/* What every on-surface effect's needs callback shares: the scene's own decision for a scene_effect. */
bool fx__scene_needs(const scene *s, scene_effect which, char *why, size_t why_cap)
{
    scene_needs_result r;
    scene_needs(s, &r);
    snprintf(why, why_cap, "%s", r.effect_reason[which]);
    return r.effect[which];
}
