/* fxc_hot.h: FXC_HOT_CLONES marks a hot per-pixel function to be compiled twice, for baseline x86-64 and
 * for x86-64-v3 (AVX2, FMA, POPCNT, SSE4.1 rounding), the copy chosen once at load time from the CPU
 * (function multi-versioning), so the program still runs on any x86-64. Results do not depend on the copy:
 * the build is ISO C11, where the compiler does not contract a * b + c into a fused multiply-add
 * (-ffp-contract=off), and the same IEEE operations run either way. Header-only, no link dependency. */
#ifndef FXC_HOT_H
#define FXC_HOT_H

#if defined(__x86_64__) && defined(__GNUC__) && defined(__linux__) && !defined(FXC_NO_CLONES)
#define FXC_HOT_CLONES __attribute__((target_clones("arch=x86-64-v3", "default")))
#else
#define FXC_HOT_CLONES
#endif

/* FXC_HOT_LANES: a hot loop over lanes (structure of arrays, a fixed trip count) that GCC should vectorise:
 * cloned as above and compiled without -ftrapping-math, since GCC will not turn a float compare-and-select
 * into a vector select while compares may trap. That flag changes no value (only whether FP exception flags
 * may be raised speculatively; nothing here reads them). */
#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__) && defined(__linux__) &&                 \
    !defined(FXC_NO_CLONES)
#define FXC_HOT_LANES                                                                                        \
    __attribute__((noinline, target_clones("arch=x86-64-v3", "default"), optimize("no-trapping-math")))
#elif defined(__GNUC__) && !defined(__clang__)
#define FXC_HOT_LANES __attribute__((noinline, optimize("no-trapping-math")))
#else
#define FXC_HOT_LANES
#endif

/* FXC_HOT_INLINE: a static helper of such a function, always inlined into it, so that it is compiled for
 * each copy (a helper left as a call would run the baseline code from both). */
#if defined(__GNUC__)
#define FXC_HOT_INLINE static inline __attribute__((always_inline))
#else
#define FXC_HOT_INLINE static inline
#endif

#endif
