/* The frame's thread pool: common/fxc_pool.h (run task 0..n-1 of a function on all workers and the calling
 * thread, and return when every task is done), with every thread set up for tracing rays (flush-to-zero and
 * denormals-are-zero, scene_tracing_thread_init). Tasks are handed out by an atomic counter, so results must
 * not depend on which thread ran a task (every stage writes per-task or per-pixel outputs). */
#ifndef FXC_SERVER_POOL_H
#define FXC_SERVER_POOL_H

#include "fxc_pool.h"
#include "scene.h"

#include <stdint.h>

typedef fxc_pool srv_pool;

/* task(user, task_index, thread_index): thread_index in [0, srv_pool_threads()) identifies per-thread
 * scratch. */
typedef fxc_pool_task srv_pool_task;

/* Creates a pool of `threads` threads in all (the caller counts as one; 0 = number of cores). NULL when
 * threads cannot be started. */
static inline srv_pool *srv_pool_create(uint32_t threads)
{
    return fxc_pool_create(threads, scene_tracing_thread_init);
}

static inline void srv_pool_free(srv_pool *pool)
{
    fxc_pool_free(pool);
}

static inline uint32_t srv_pool_threads(const srv_pool *pool)
{
    return fxc_pool_threads(pool);
}

/* Runs task for every index in [0, count) and waits for all of them. Not reentrant. */
static inline void srv_pool_run(srv_pool *pool, uint32_t count, srv_pool_task task, void *user)
{
    fxc_pool_run(pool, count, task, user);
}

/* Runs task for every index in [0, count) split statically (fxc_pool_run_static): thread t takes its own
 * contiguous range in order, then, with steal, the others' last tasks. Not reentrant. */
static inline void srv_pool_run_static(srv_pool *pool, uint32_t count, srv_pool_task task, void *user,
                                       bool steal)
{
    fxc_pool_run_static(pool, count, task, user, steal);
}

#endif
