/* A small thread pool for parallel loops: run task 0..count-1 of a function on the workers and the calling
 * thread, and return when every task is done. Tasks are handed out by an atomic counter, so a result must not
 * depend on which thread ran a task (every caller writes per-task outputs). A static run instead gives thread
 * t the same range of tasks every time (fxc_pool_run_static), so passes over the same data in the same ranges
 * find it in the same core's cache. The engine's frame stages
 * (server/engine/pool.h) and the client's render cache (viewer_client/rcache) both run on it; it links
 * nothing but pthreads. */
#ifndef FXC_COMMON_POOL_H
#define FXC_COMMON_POOL_H

#include <stdbool.h>
#include <stdint.h>

enum {
    FXC_POOL_MAX_THREADS = 256,
    FXC_POOL_STATIC_MAX =
        65535 /* the most tasks a static run splits; larger counts are handed out dynamically */
};

typedef struct fxc_pool fxc_pool;

/* task(user, task_index, thread_index): thread_index in [0, fxc_pool_threads()) identifies per-thread
 * scratch; 0 is the calling thread. */
typedef void (*fxc_pool_task)(void *user, uint32_t task_index, uint32_t thread_index);

/* Creates a pool of `threads` threads in all, the caller counted as one (0 = the number of online cores, at
 * most FXC_POOL_MAX_THREADS). thread_init (may be NULL) runs once on every worker when it starts, and on the
 * calling thread at the start of every fxc_pool_run that uses the workers (the engine sets flush-to-zero
 * there). NULL when threads is above FXC_POOL_MAX_THREADS, memory runs out or a thread cannot start. */
fxc_pool *fxc_pool_create(uint32_t threads, void (*thread_init)(void));

/* Stops and joins the workers (NULL is ignored). */
void fxc_pool_free(fxc_pool *pool);

uint32_t fxc_pool_threads(const fxc_pool *pool);

/* Runs task for every index in [0, count) and waits for all of them. A pool of one thread, or a single
 * task, runs on the caller without waking the workers. Not reentrant. */
void fxc_pool_run(fxc_pool *pool, uint32_t count, fxc_pool_task task, void *user);

/* First task of thread t's range in a static run of count tasks on a pool of `threads`: thread t owns
 * [fxc_pool_static_begin(count, threads, t), fxc_pool_static_begin(count, threads, t + 1)). */
static inline uint32_t fxc_pool_static_begin(uint32_t count, uint32_t threads, uint32_t t)
{
    return (uint32_t)((uint64_t)count * t / threads);
}

/* Runs task for every index in [0, count) like fxc_pool_run, but split statically: thread t runs its own range
 * (fxc_pool_static_begin) in ascending order, so with the same count and pool a task runs on the same thread
 * run after run. With steal, a thread that has finished its range then takes tasks from the tails of the
 * others' ranges (descending), so a late or descheduled worker delays the run by at most the task it is in;
 * without, the caller waits for every owner. Either way a task runs exactly once and the result must still
 * not depend on the thread (with steal, a task can move). count above FXC_POOL_STATIC_MAX: fxc_pool_run. */
void fxc_pool_run_static(fxc_pool *pool, uint32_t count, fxc_pool_task task, void *user, bool steal);

#endif
