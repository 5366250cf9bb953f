/* The thread pool (fxc_pool.h).
 *
 * A run is published by one atomic word, `claim`: the run's generation in the high 32 bits, the next task
 * index in the low 32. Threads claim tasks by compare-and-swap on that word, so a thread that looked at an
 * older run can never take a task of a newer one. The run's function, argument and count live in one of two
 * parameter slots (the generation's parity); a late worker may read a slot the caller is rewriting for a
 * later run, but its claim then fails, so it never calls what it read.
 *
 * Workers that finish a run spin for a short while (FXC_POOL_SPIN_NS) watching `claim` before they sleep on
 * the condition variable: a frame's stages follow each other within microseconds, and a worker woken through
 * the kernel for each one arrived after the caller had done the short stages alone (the render cache's
 * 2-thread speed-up at 512 x 512 was 1.1). `busy` counts workers between seeing a run and leaving it; the
 * caller returns when it has claimed the last task and `busy` is 0. */
#include "fxc_pool.h"

#include <pthread.h>
#include <stdatomic.h>
#include <stdbool.h>
#include <stdlib.h>
#include <time.h>
#include <unistd.h>

#if defined(__x86_64__) || defined(__i386__)
#include <immintrin.h>
#define FXC_POOL_RELAX() _mm_pause()
#else
#define FXC_POOL_RELAX() ((void)0)
#endif

/* How long a worker watches for the next run before it sleeps, and how long the caller watches `busy`. */
enum { FXC_POOL_SPIN_NS = 200000 };

typedef struct run_params {
    _Atomic(fxc_pool_task) task;
    _Atomic(void *) user;
    atomic_uint count;
} run_params;

struct fxc_pool {
    uint32_t thread_count; /* the caller included */
    uint32_t started;      /* workers running (thread_count - 1 once created) */
    pthread_t *threads;    /* [1, thread_count) */
    void (*thread_init)(void);
    pthread_mutex_t lock;
    pthread_cond_t work_ready, work_done;
    atomic_bool stopping;
    atomic_uint sleepers;                 /* workers waiting on work_ready (or about to) */
    atomic_uint busy;                     /* workers inside a run */
    _Atomic(uint64_t) claim;              /* generation << 32 | next task index */
    run_params params[2];                 /* by the generation's parity */
};

typedef struct worker_start {
    fxc_pool *pool;
    uint32_t index;
} worker_start;

static uint64_t now_ns(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (uint64_t)ts.tv_sec * 1000000000u + (uint64_t)ts.tv_nsec;
}

/* Claims and runs tasks of generation g until none is left or another run has started. */
static void drain(fxc_pool *pool, uint32_t g, uint32_t thread_index)
{
    const run_params *p = &pool->params[g & 1u];
    fxc_pool_task task = atomic_load_explicit(&p->task, memory_order_relaxed);
    void *user = atomic_load_explicit(&p->user, memory_order_relaxed);
    uint32_t count = atomic_load_explicit(&p->count, memory_order_relaxed);
    uint64_t v = atomic_load(&pool->claim);
    for (;;) {
        if ((uint32_t)(v >> 32) != g || (uint32_t)v >= count)
            return;
        if (atomic_compare_exchange_weak(&pool->claim, &v, v + 1))
            task(user, (uint32_t)v, thread_index);
        /* on failure v holds the current word */
    }
}

/* Waits (spinning, then sleeping) until the generation differs from seen or the pool stops; returns it. */
static uint32_t next_generation(fxc_pool *pool, uint32_t seen)
{
    uint64_t start = 0;
    for (uint32_t spin = 0;; spin++) {
        uint32_t g = (uint32_t)(atomic_load(&pool->claim) >> 32);
        if (g != seen || atomic_load(&pool->stopping))
            return g;
        FXC_POOL_RELAX();
        if ((spin & 63u) != 63u)
            continue;
        uint64_t t = now_ns();
        if (!start)
            start = t;
        else if (t - start > FXC_POOL_SPIN_NS)
            break;
    }
    pthread_mutex_lock(&pool->lock);
    atomic_fetch_add(&pool->sleepers, 1);
    uint32_t g;
    while ((g = (uint32_t)(atomic_load(&pool->claim) >> 32)) == seen && !atomic_load(&pool->stopping))
        pthread_cond_wait(&pool->work_ready, &pool->lock);
    atomic_fetch_sub(&pool->sleepers, 1);
    pthread_mutex_unlock(&pool->lock);
    return g;
}

static void *worker_main(void *arg)
{
    fxc_pool *pool = ((worker_start *)arg)->pool;
    uint32_t index = ((worker_start *)arg)->index;
    free(arg);
    if (pool->thread_init)
        pool->thread_init();
    uint32_t seen = 0;
    for (;;) {
        uint32_t g = next_generation(pool, seen);
        if (atomic_load(&pool->stopping))
            break;
        seen = g;
        /* Counted before the claim word is read again: the caller cannot finish run g while we may run one of
         * its tasks. */
        atomic_fetch_add(&pool->busy, 1);
        drain(pool, g, index);
        if (atomic_fetch_sub(&pool->busy, 1) == 1) {
            pthread_mutex_lock(&pool->lock);
            pthread_cond_broadcast(&pool->work_done);
            pthread_mutex_unlock(&pool->lock);
        }
    }
    return NULL;
}

fxc_pool *fxc_pool_create(uint32_t threads, void (*thread_init)(void))
{
    if (threads == 0) {
        long n = sysconf(_SC_NPROCESSORS_ONLN);
        threads = n > 0 ? (n < FXC_POOL_MAX_THREADS ? (uint32_t)n : FXC_POOL_MAX_THREADS) : 1;
    }
    if (threads > FXC_POOL_MAX_THREADS)
        return NULL;
    fxc_pool *pool = calloc(1, sizeof *pool);
    if (!pool)
        return NULL;
    pool->threads = calloc(threads, sizeof *pool->threads);
    if (!pool->threads) {
        free(pool);
        return NULL;
    }
    pool->thread_count = threads;
    pool->thread_init = thread_init;
    pthread_mutex_init(&pool->lock, NULL);
    pthread_cond_init(&pool->work_ready, NULL);
    pthread_cond_init(&pool->work_done, NULL);
    atomic_init(&pool->stopping, false);
    atomic_init(&pool->sleepers, 0);
    atomic_init(&pool->busy, 0);
    atomic_init(&pool->claim, 0);
    for (int i = 0; i < 2; i++) {
        atomic_init(&pool->params[i].task, NULL);
        atomic_init(&pool->params[i].user, NULL);
        atomic_init(&pool->params[i].count, 0);
    }
    for (uint32_t i = 1; i < threads; i++) {
        worker_start *start = malloc(sizeof *start);
        if (!start) {
            fxc_pool_free(pool);
            return NULL;
        }
        start->pool = pool;
        start->index = i;
        if (pthread_create(&pool->threads[i], NULL, worker_main, start) != 0) {
            free(start);
            fxc_pool_free(pool);
            return NULL;
        }
        pool->started = i;
    }
    return pool;
}

uint32_t fxc_pool_threads(const fxc_pool *pool)
{
    return pool->thread_count;
}

void fxc_pool_run(fxc_pool *pool, uint32_t count, fxc_pool_task task, void *user)
{
    if (count == 0)
        return;
    if (pool->thread_init)
        pool->thread_init();
    if (pool->thread_count == 1 || count == 1) {
        for (uint32_t i = 0; i < count; i++)
            task(user, i, 0);
        return;
    }
    uint32_t g = (uint32_t)(atomic_load(&pool->claim) >> 32) + 1u;
    if (g == 0) /* 0 is the workers' initial "seen" */
        g = 1;
    run_params *p = &pool->params[g & 1u];
    atomic_store_explicit(&p->task, task, memory_order_relaxed);
    atomic_store_explicit(&p->user, user, memory_order_relaxed);
    atomic_store_explicit(&p->count, count, memory_order_relaxed);
    atomic_store(&pool->claim, (uint64_t)g << 32); /* seq_cst: publishes the parameters, then sleepers is read */
    if (atomic_load(&pool->sleepers) > 0) {
        pthread_mutex_lock(&pool->lock);
        pthread_cond_broadcast(&pool->work_ready);
        pthread_mutex_unlock(&pool->lock);
    }
    drain(pool, g, 0);
    uint64_t start = 0;
    for (uint32_t spin = 0; atomic_load(&pool->busy) > 0; spin++) {
        FXC_POOL_RELAX();
        if ((spin & 63u) != 63u)
            continue;
        uint64_t t = now_ns();
        if (!start) {
            start = t;
        } else if (t - start > FXC_POOL_SPIN_NS) {
            pthread_mutex_lock(&pool->lock);
            while (atomic_load(&pool->busy) > 0)
                pthread_cond_wait(&pool->work_done, &pool->lock);
            pthread_mutex_unlock(&pool->lock);
            break;
        }
    }
}

void fxc_pool_free(fxc_pool *pool)
{
    if (!pool)
        return;
    pthread_mutex_lock(&pool->lock);
    atomic_store(&pool->stopping, true);
    pthread_cond_broadcast(&pool->work_ready);
    pthread_mutex_unlock(&pool->lock);
    for (uint32_t i = 1; i <= pool->started; i++)
        pthread_join(pool->threads[i], NULL);
    pthread_cond_destroy(&pool->work_ready);
    pthread_cond_destroy(&pool->work_done);
    pthread_mutex_destroy(&pool->lock);
    free(pool->threads);
    free(pool);
}
