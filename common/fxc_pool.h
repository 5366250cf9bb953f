/* A small thread pool for parallel loops: run task 0..count-1 of a function on the workers and the calling
 * thread, and return when every task is done. Tasks are handed out by an atomic counter, so a result must not
 * depend on which thread ran a task (every caller writes per-task outputs). The engine's frame stages
 * (server/engine/pool.h) and the client's render cache (viewer_client/rcache) both run on it; it links
 * nothing but pthreads. */
#ifndef FXC_COMMON_POOL_H
#define FXC_COMMON_POOL_H

#include <stdint.h>

enum { FXC_POOL_MAX_THREADS = 256 };

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

#endif
