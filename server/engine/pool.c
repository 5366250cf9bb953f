/* The frame's thread pool: see pool.h. One mutex and two condition variables; tasks are claimed with an
 * atomic counter so the hot path takes no lock. */
#include "pool.h"
#include "scene.h"

#include <pthread.h>
#include <stdatomic.h>
#include <stdbool.h>
#include <stdlib.h>
#include <unistd.h>

struct srv_pool {
    uint32_t thread_count; /* including the caller */
    pthread_t *threads;
    pthread_mutex_t lock;
    pthread_cond_t work_ready, work_done;
    uint64_t generation; /* bumped for every srv_pool_run */
    bool stopping;
    /* The current job. */
    srv_pool_task task;
    void *user;
    uint32_t count;
    atomic_uint next;
    uint32_t busy_workers;
};

typedef struct worker_arg {
    srv_pool *pool;
    uint32_t index;
} worker_arg;

/* Claims and runs tasks until none is left. */
static void drain(srv_pool *pool, uint32_t thread_index)
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
    worker_arg *wa = arg;
    srv_pool *pool = wa->pool;
    uint32_t index = wa->index;
    free(wa);
    scene_tracing_thread_init();
    uint64_t seen = 0;
    pthread_mutex_lock(&pool->lock);
    for (;;) {
        while (!pool->stopping && pool->generation == seen)
            pthread_cond_wait(&pool->work_ready, &pool->lock);
        if (pool->stopping)
            break;
        seen = pool->generation;
        pool->busy_workers++;
        pthread_mutex_unlock(&pool->lock);
        drain(pool, index);
        pthread_mutex_lock(&pool->lock);
        if (--pool->busy_workers == 0)
            pthread_cond_signal(&pool->work_done);
    }
    pthread_mutex_unlock(&pool->lock);
    return NULL;
}

srv_pool *srv_pool_create(uint32_t threads)
{
    if (threads == 0) {
        long n = sysconf(_SC_NPROCESSORS_ONLN);
        threads = n > 0 && n < 256 ? (uint32_t)n : 1;
    }
    srv_pool *pool = calloc(1, sizeof *pool);
    if (!pool)
        return NULL;
    pool->thread_count = threads;
    pthread_mutex_init(&pool->lock, NULL);
    pthread_cond_init(&pool->work_ready, NULL);
    pthread_cond_init(&pool->work_done, NULL);
    pool->threads = calloc(threads, sizeof *pool->threads);
    if (!pool->threads) {
        free(pool);
        return NULL;
    }
    for (uint32_t i = 1; i < threads; i++) {
        worker_arg *wa = malloc(sizeof *wa);
        if (wa) {
            wa->pool = pool;
            wa->index = i;
        }
        if (!wa || pthread_create(&pool->threads[i], NULL, worker_main, wa) != 0) {
            free(wa);
            pool->thread_count = i; /* run with what started */
            break;
        }
    }
    return pool;
}

uint32_t srv_pool_threads(const srv_pool *pool)
{
    return pool->thread_count;
}

void srv_pool_run(srv_pool *pool, uint32_t count, srv_pool_task task, void *user)
{
    if (count == 0)
        return;
    pthread_mutex_lock(&pool->lock);
    pool->task = task;
    pool->user = user;
    pool->count = count;
    atomic_store(&pool->next, 0);
    pool->generation++;
    pthread_cond_broadcast(&pool->work_ready);
    pthread_mutex_unlock(&pool->lock);
    scene_tracing_thread_init();
    drain(pool, 0);
    pthread_mutex_lock(&pool->lock);
    while (pool->busy_workers > 0 || atomic_load(&pool->next) < count)
        pthread_cond_wait(&pool->work_done, &pool->lock);
    pthread_mutex_unlock(&pool->lock);
}

void srv_pool_free(srv_pool *pool)
{
    if (!pool)
        return;
    pthread_mutex_lock(&pool->lock);
    pool->stopping = true;
    pthread_cond_broadcast(&pool->work_ready);
    pthread_mutex_unlock(&pool->lock);
    for (uint32_t i = 1; i < pool->thread_count; i++)
        pthread_join(pool->threads[i], NULL);
    pthread_cond_destroy(&pool->work_ready);
    pthread_cond_destroy(&pool->work_done);
    pthread_mutex_destroy(&pool->lock);
    free(pool->threads);
    free(pool);
}
