/* The frame's thread pool: common/fxc_pool.h (run task 0..n-1 of a function on all workers and the calling
 * thread, and return when every task is done), with every thread set up for tracing rays (flush-to-zero and
 * denormals-are-zero, scene_tracing_thread_init). Tasks are handed out by an atomic counter, so results must
 * not depend on which thread ran a task (every stage writes per-task or per-pixel outputs).
 *
 * A pool may watch a stop flag (srv_pool_set_stop): once the flag is non-zero, tasks not yet started are
 * skipped and later runs run nothing, so a frame of seconds ends within one task (a 16 x 16 tile, a chunk
 * of blocks); the frame that watched it is then abandoned (srv_loop_frame), its outputs incomplete. */
#ifndef FXC_SERVER_POOL_H
#define FXC_SERVER_POOL_H

#include "fxc_pool.h"
#include "scene.h"

#include <signal.h>
#include <stdint.h>
#include <stdlib.h>

typedef struct srv_pool {
    fxc_pool *threads;
    const volatile sig_atomic_t *stop; /* NULL, or non-zero when runs must skip what they have not started */
} srv_pool;

/* task(user, task_index, thread_index): thread_index in [0, srv_pool_threads()) identifies per-thread
 * scratch. */
typedef fxc_pool_task srv_pool_task;

/* Creates a pool of `threads` threads in all (the caller counts as one; 0 = number of cores). NULL when
 * threads cannot be started. */
static inline srv_pool *srv_pool_create(uint32_t threads)
{
    srv_pool *pool = calloc(1, sizeof *pool);
    if (pool && !(pool->threads = fxc_pool_create(threads, scene_tracing_thread_init))) {
        free(pool);
        pool = NULL;
    }
    return pool;
}

static inline void srv_pool_free(srv_pool *pool)
{
    if (pool)
        fxc_pool_free(pool->threads);
    free(pool);
}

static inline uint32_t srv_pool_threads(const srv_pool *pool)
{
    return fxc_pool_threads(pool->threads);
}

/* The flag runs watch (NULL: none, every task runs). */
static inline void srv_pool_set_stop(srv_pool *pool, const volatile sig_atomic_t *stop)
{
    pool->stop = stop;
}

/* True once the watched flag is set. */
static inline bool srv_pool_stopped(const srv_pool *pool)
{
    return pool->stop && *pool->stop;
}

/* A task behind the stop flag: runs only while the flag is clear. */
typedef struct srv__pool_call {
    srv_pool_task task;
    void *user;
    const volatile sig_atomic_t *stop;
} srv__pool_call;

static inline void srv__pool_watched(void *user, uint32_t task_index, uint32_t thread_index)
{
    const srv__pool_call *call = user;
    if (!*call->stop)
        call->task(call->user, task_index, thread_index);
}

/* Runs task for every index in [0, count) and waits for all of them (with a stop flag set: none, or those
 * started before it was). Not reentrant. */
static inline void srv_pool_run(srv_pool *pool, uint32_t count, srv_pool_task task, void *user)
{
    if (!pool->stop) {
        fxc_pool_run(pool->threads, count, task, user);
        return;
    }
    if (*pool->stop)
        return;
    srv__pool_call call = {.task = task, .user = user, .stop = pool->stop};
    fxc_pool_run(pool->threads, count, srv__pool_watched, &call);
}

/* Runs task for every index in [0, count) split statically (fxc_pool_run_static): thread t takes its own
 * contiguous range in order, then, with steal, the others' last tasks. Not reentrant. */
static inline void srv_pool_run_static(srv_pool *pool, uint32_t count, srv_pool_task task, void *user,
                                       bool steal)
{
    if (!pool->stop) {
        fxc_pool_run_static(pool->threads, count, task, user, steal);
        return;
    }
    if (*pool->stop)
        return;
    srv__pool_call call = {.task = task, .user = user, .stop = pool->stop};
    fxc_pool_run_static(pool->threads, count, srv__pool_watched, &call, steal);
}

#endif
