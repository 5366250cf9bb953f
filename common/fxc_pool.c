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
 * caller returns when it has claimed the last task and `busy` is 0.
 *
 * A static run (fxc_pool_run_static) gives thread t the range [count * t / T, count * (t + 1) / T) of the T
 * threads' split. Each range is one word of its own (a cache line apart): the run's generation in the high 32
 * bits, the next index from the front (16 bits) and the end (16 bits) in the low 32, both relative to the
 * range's first task. The owner takes from the front, thieves (with steal) from the end, each by
 * compare-and-swap; the generation tag means a claim can only succeed while its own run is live (a finished
 * run's words are all empty), so a late worker never runs a task with another run's parameters. `claim` still
 * publishes the generation (its task index set past any count, so dynamic claims fail), and `remaining` counts
 * the tasks not yet finished: the caller returns when it is 0 and `busy` is 0. */
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

enum { RUN_DYNAMIC, RUN_STATIC_STEAL, RUN_STATIC };

typedef struct run_params {
    _Atomic(fxc_pool_task) task;
    _Atomic(void *) user;
    atomic_uint count;
    atomic_uint mode; /* RUN_* */
} run_params;

/* One thread's range in a static run: generation << 32 | front << 16 | end (relative to the range's start). */
typedef struct pool_part {
    _Alignas(64) _Atomic(uint64_t) word;
} pool_part;

struct fxc_pool {
    uint32_t thread_count; /* the caller included */
    uint32_t started;      /* workers running (thread_count - 1 once created) */
    pthread_t *threads;    /* [1, thread_count) */
    void (*thread_init)(void);
    pthread_mutex_t lock;
    pthread_cond_t work_ready, work_done;
    atomic_bool stopping;
    atomic_uint sleepers;    /* workers waiting on work_ready (or about to) */
    atomic_uint busy;        /* workers inside a run */
    _Atomic(uint64_t) claim; /* generation << 32 | next task index */
    run_params params[2];    /* by the generation's parity */
    atomic_uint remaining;   /* static runs: tasks not yet finished */
    pool_part *parts;        /* static runs: [thread_count], one cache line each */
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

/* Takes tasks from range `part` of static run g (from the front when own, else from the end) and runs them on
 * thread_index until the range is empty or the run is no longer g. */
static void drain_part(fxc_pool *pool, uint32_t g, uint32_t part, uint32_t thread_index, bool own,
                       fxc_pool_task task, void *user, uint32_t first)
{
    _Atomic(uint64_t) *word = &pool->parts[part].word;
    uint64_t v = atomic_load(word);
    for (;;) {
        uint32_t front = (uint32_t)(v >> 16) & 0xFFFFu, end = (uint32_t)v & 0xFFFFu;
        if ((uint32_t)(v >> 32) != g || front >= end)
            return;
        uint64_t next = own ? v + (1u << 16) : v - 1u;
        if (atomic_compare_exchange_weak(word, &v, next)) {
            task(user, first + (own ? front : end - 1u), thread_index);
            atomic_fetch_sub(&pool->remaining, 1);
            v = atomic_load(word);
        }
        /* on failure v holds the current word */
    }
}

/* Static run g: the thread's own range, then (with steal) the others' tails, nearest thread first. */
static void drain_static(fxc_pool *pool, uint32_t g, uint32_t thread_index)
{
    const run_params *p = &pool->params[g & 1u];
    fxc_pool_task task = atomic_load_explicit(&p->task, memory_order_relaxed);
    void *user = atomic_load_explicit(&p->user, memory_order_relaxed);
    uint32_t count = atomic_load_explicit(&p->count, memory_order_relaxed);
    bool steal = atomic_load_explicit(&p->mode, memory_order_relaxed) == RUN_STATIC_STEAL;
    uint32_t threads = pool->thread_count;
    drain_part(pool, g, thread_index, thread_index, true, task, user,
               fxc_pool_static_begin(count, threads, thread_index));
    if (!steal)
        return;
    for (uint32_t k = 1; k < threads; k++) {
        uint32_t part = (thread_index + k) % threads;
        drain_part(pool, g, part, thread_index, false, task, user,
                   fxc_pool_static_begin(count, threads, part));
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
        /* A stale mode (the slot rewritten for a later run) is harmless: neither kind of claim can succeed for
         * a run that is over. */
        if (atomic_load_explicit(&pool->params[g & 1u].mode, memory_order_relaxed) == RUN_DYNAMIC)
            drain(pool, g, index);
        else
            drain_static(pool, g, index);
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
    pool->parts = aligned_alloc(_Alignof(pool_part), threads * sizeof(pool_part));
    if (!pool->parts) {
        free(pool->threads);
        free(pool);
        return NULL;
    }
    for (uint32_t i = 0; i < threads; i++)
        atomic_init(&pool->parts[i].word, 0);
    atomic_init(&pool->remaining, 0);
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
        atomic_init(&pool->params[i].mode, RUN_DYNAMIC);
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

/* Publishes run g (parameters written by the caller before) and wakes the sleeping workers. */
static void publish(fxc_pool *pool, uint64_t claim)
{
    atomic_store(&pool->claim, claim); /* seq_cst: publishes the parameters, then sleepers is read */
    if (atomic_load(&pool->sleepers) > 0) {
        pthread_mutex_lock(&pool->lock);
        pthread_cond_broadcast(&pool->work_ready);
        pthread_mutex_unlock(&pool->lock);
    }
}

/* The next run's generation, its parameters written into their slot. */
static uint32_t prepare(fxc_pool *pool, uint32_t count, fxc_pool_task task, void *user, uint32_t mode)
{
    uint32_t g = (uint32_t)(atomic_load(&pool->claim) >> 32) + 1u;
    if (g == 0) /* 0 is the workers' initial "seen" */
        g = 1;
    run_params *p = &pool->params[g & 1u];
    atomic_store_explicit(&p->task, task, memory_order_relaxed);
    atomic_store_explicit(&p->user, user, memory_order_relaxed);
    atomic_store_explicit(&p->count, count, memory_order_relaxed);
    atomic_store_explicit(&p->mode, mode, memory_order_relaxed);
    return g;
}

/* Waits until `remaining` (when counted) and `busy` are 0: spinning, then sleeping on work_done (the last worker
 * to leave a run broadcasts it). */
static bool run_finished(fxc_pool *pool, bool counted)
{
    return (!counted || atomic_load(&pool->remaining) == 0) && atomic_load(&pool->busy) == 0;
}

static void wait_finished(fxc_pool *pool, bool counted)
{
    uint64_t start = 0;
    for (uint32_t spin = 0; !run_finished(pool, counted); spin++) {
        FXC_POOL_RELAX();
        if ((spin & 63u) != 63u)
            continue;
        uint64_t t = now_ns();
        if (!start) {
            start = t;
        } else if (t - start > FXC_POOL_SPIN_NS) {
            pthread_mutex_lock(&pool->lock);
            while (!run_finished(pool, counted))
                pthread_cond_wait(&pool->work_done, &pool->lock);
            pthread_mutex_unlock(&pool->lock);
            break;
        }
    }
}

/* The start of every run of count > 0 tasks: the caller's thread_init, then the whole run on the caller when
 * there is one thread or one task (without waking the workers). True when the run is done. */
static bool run_on_caller(fxc_pool *pool, uint32_t count, fxc_pool_task task, void *user)
{
    if (pool->thread_init)
        pool->thread_init();
    if (pool->thread_count > 1 && count > 1)
        return false;
    for (uint32_t i = 0; i < count; i++)
        task(user, i, 0);
    return true;
}

void fxc_pool_run(fxc_pool *pool, uint32_t count, fxc_pool_task task, void *user)
{
    if (count == 0 || run_on_caller(pool, count, task, user))
        return;
    uint32_t g = prepare(pool, count, task, user, RUN_DYNAMIC);
    publish(pool, (uint64_t)g << 32);
    drain(pool, g, 0);
    wait_finished(pool, false);
}

void fxc_pool_run_static(fxc_pool *pool, uint32_t count, fxc_pool_task task, void *user, bool steal)
{
    if (count > FXC_POOL_STATIC_MAX) {
        fxc_pool_run(pool, count, task, user);
        return;
    }
    if (count == 0 || run_on_caller(pool, count, task, user))
        return;
    uint32_t g = prepare(pool, count, task, user, steal ? RUN_STATIC_STEAL : RUN_STATIC);
    uint32_t threads = pool->thread_count;
    atomic_store_explicit(&pool->remaining, count, memory_order_relaxed);
    for (uint32_t t = 0; t < threads; t++) {
        uint64_t n = fxc_pool_static_begin(count, threads, t + 1) - fxc_pool_static_begin(count, threads, t);
        atomic_store_explicit(&pool->parts[t].word, (uint64_t)g << 32 | n, memory_order_relaxed);
    }
    publish(pool, (uint64_t)g << 32 | UINT32_MAX); /* no dynamic claim can succeed */
    drain_static(pool, g, 0);
    wait_finished(pool, true);
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
    free(pool->parts);
    free(pool->threads);
    free(pool);
}
