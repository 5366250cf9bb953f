/* The render cache's threads (Reinhard 2001 section 3: tiles processed by several threads). A frame is a
 * fixed sequence of passes; each pass is a count of tasks (chunks of the point store, tiles or bands) handed
 * out by an atomic counter to the workers and the calling thread, and the call returns when all are done.
 * Every task writes only its own outputs, so which thread ran it does not change the result. One mutex and
 * two condition variables; a pass of one task, or a pool of one thread, runs on the caller without touching
 * them. */
#include "rc_internal.h"

#include <pthread.h>
#include <stdatomic.h>
#include <stdlib.h>

struct rc_pool {
    uint32_t thread_count; /* the caller included */
    pthread_t threads[VIEW_RC_MAX_THREADS];
    uint32_t started; /* workers running (thread_count - 1 once created) */
    pthread_mutex_t lock;
    pthread_cond_t work_ready, work_done;
    uint64_t generation; /* bumped for every pass */
    bool stopping;
    rc_pool_task task;
    void *user;
    uint32_t count;
    atomic_uint next;
    uint32_t busy; /* workers inside the current pass */
};

typedef struct rc_worker_start {
    rc_pool *pool;
    uint32_t index;
} rc_worker_start;

/* Claims and runs tasks until none is left. */
static void drain(rc_pool *pool, uint32_t worker)
{
    for (;;) {
        uint32_t i = atomic_fetch_add(&pool->next, 1);
        if (i >= pool->count)
            return;
        pool->task(pool->user, i, worker);
    }
}

static void *worker_main(void *arg)
{
    rc_pool *pool = ((rc_worker_start *)arg)->pool;
    uint32_t index = ((rc_worker_start *)arg)->index;
    free(arg);
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

rc_pool *view_rc__pool_create(uint32_t threads)
{
    if (threads == 0 || threads > VIEW_RC_MAX_THREADS)
        return NULL;
    rc_pool *pool = calloc(1, sizeof *pool);
    if (!pool)
        return NULL;
    pool->thread_count = threads;
    pthread_mutex_init(&pool->lock, NULL);
    pthread_cond_init(&pool->work_ready, NULL);
    pthread_cond_init(&pool->work_done, NULL);
    for (uint32_t i = 1; i < threads; i++) {
        rc_worker_start *start = malloc(sizeof *start);
        if (!start) {
            view_rc__pool_free(pool);
            return NULL;
        }
        start->pool = pool;
        start->index = i;
        if (pthread_create(&pool->threads[i], NULL, worker_main, start) != 0) {
            free(start);
            view_rc__pool_free(pool);
            return NULL;
        }
        pool->started = i;
    }
    return pool;
}

void view_rc__pool_run(rc_pool *pool, uint32_t count, rc_pool_task task, void *user)
{
    if (count == 0)
        return;
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

void view_rc__pool_free(rc_pool *pool)
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
    free(pool);
}
