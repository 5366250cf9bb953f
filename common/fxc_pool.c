/* The thread pool (fxc_pool.h). One mutex and two condition variables; tasks are claimed with an atomic
 * counter, so the hot path takes no lock. */
#include "fxc_pool.h"

#include <pthread.h>
#include <stdatomic.h>
#include <stdbool.h>
#include <stdlib.h>
#include <unistd.h>

struct fxc_pool {
    uint32_t thread_count; /* the caller included */
    uint32_t started;      /* workers running (thread_count - 1 once created) */
    pthread_t *threads;    /* [1, thread_count) */
    void (*thread_init)(void);
    pthread_mutex_t lock;
    pthread_cond_t work_ready, work_done;
    uint64_t generation; /* bumped for every run that wakes the workers */
    bool stopping;
    /* The current run. */
    fxc_pool_task task;
    void *user;
    uint32_t count;
    atomic_uint next;
    uint32_t busy; /* workers inside the current run */
};

typedef struct worker_start {
    fxc_pool *pool;
    uint32_t index;
} worker_start;

/* Claims and runs tasks until none is left. */
static void drain(fxc_pool *pool, uint32_t thread_index)
{
    for (;;) {
        uint32_t i = atomic_fetch_add(&pool->next, 1);
        if (i >= pool->count)
            return;
        pool->task(pool->user, i, thread_index);
    }
}

static void *worker_main(void *arg)
{
    fxc_pool *pool = ((worker_start *)arg)->pool;
    uint32_t index = ((worker_start *)arg)->index;
    free(arg);
    if (pool->thread_init)
        pool->thread_init();
    uint64_t seen = 0;
    pthread_mutex_lock(&pool->lock);
    for (;;) {
        while (!pool->stopping && pool->generation == seen)
            pthread_cond_wait(&pool->work_ready, &pool->lock);
        if (pool->stopping)
            break;
        seen = pool->generation;
        pool->busy++;
        pthread_mutex_unlock(&pool->lock);
        drain(pool, index);
        pthread_mutex_lock(&pool->lock);
        if (--pool->busy == 0)
            pthread_cond_signal(&pool->work_done);
    }
    pthread_mutex_unlock(&pool->lock);
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
    pthread_mutex_lock(&pool->lock);
    pool->task = task;
    pool->user = user;
    pool->count = count;
    atomic_store(&pool->next, 0);
    pool->generation++;
    pthread_cond_broadcast(&pool->work_ready);
    pthread_mutex_unlock(&pool->lock);
    drain(pool, 0);
    pthread_mutex_lock(&pool->lock);
    while (pool->busy > 0 || atomic_load(&pool->next) < count)
        pthread_cond_wait(&pool->work_done, &pool->lock);
    pthread_mutex_unlock(&pool->lock);
}

void fxc_pool_free(fxc_pool *pool)
{
    if (!pool)
        return;
    pthread_mutex_lock(&pool->lock);
    pool->stopping = true;
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
