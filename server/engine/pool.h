/* A small thread pool for the frame's parallel loops: run task 0..n-1 of a function on all workers and
 * the calling thread, and return when every task is done. Tasks are handed out by an atomic counter, so
 * results must not depend on which thread ran a task (every stage writes per-task or per-pixel outputs).
 * Every worker sets flush-to-zero and denormals-are-zero once (it traces rays). */
#ifndef FXC_SERVER_POOL_H
#define FXC_SERVER_POOL_H

#include <stdint.h>

typedef struct srv_pool srv_pool;

/* task(user, task_index, thread_index): thread_index in [0, srv_pool_threads()) identifies per-thread
 * scratch. */
typedef void (*srv_pool_task)(void *user, uint32_t task_index, uint32_t thread_index);

/* Creates a pool of `threads` threads in all (the caller counts as one; 0 = number of cores). NULL when
 * threads cannot be started. */
srv_pool *srv_pool_create(uint32_t threads);
void srv_pool_free(srv_pool *pool);
uint32_t srv_pool_threads(const srv_pool *pool);

/* Runs task for every index in [0, count) and waits for all of them. Not reentrant. */
void srv_pool_run(srv_pool *pool, uint32_t count, srv_pool_task task, void *user);

#endif
