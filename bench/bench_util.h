/* Small helpers every benchmark program shares: a monotonic clock and order statistics of repeated runs. */
#ifndef FXC_BENCH_UTIL_H
#define FXC_BENCH_UTIL_H

#include <stdlib.h>
#include <string.h>
#include <time.h>

enum { BENCH_MAX_SAMPLES = 256 };

/* Monotonic clock, milliseconds. */
static inline double bench_now_ms(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec * 1e3 + (double)ts.tv_nsec * 1e-6;
}

static inline int bench_cmp_double(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

/* The q-quantile (0 = minimum, 0.5 = median, 1 = maximum) of count values (1..BENCH_MAX_SAMPLES; the
 * values are left untouched). The median of an even count is the mean of the middle two. */
static inline double bench_quantile(const double *values, int count, double q)
{
    double sorted[BENCH_MAX_SAMPLES];
    if (count < 1)
        return 0;
    if (count > BENCH_MAX_SAMPLES)
        count = BENCH_MAX_SAMPLES;
    memcpy(sorted, values, sizeof(double) * (size_t)count);
    qsort(sorted, (size_t)count, sizeof *sorted, bench_cmp_double);
    if (q == 0.5 && count % 2 == 0)
        return 0.5 * (sorted[count / 2 - 1] + sorted[count / 2]);
    int index = (int)(q * (count - 1) + 0.5);
    return sorted[index];
}

#endif
