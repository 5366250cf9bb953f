/* test_pool.c: the shared thread pool (common/fxc_pool.h). Every task of every run runs exactly once, on a
 * thread index below the pool's thread count, and the run returns only after all of them: checked over many
 * short runs back to back (where workers still spinning from the previous run meet the next one, and late
 * workers meet a run that has already moved on), runs of one task, runs after a pause long enough for the
 * workers to sleep, and pools of 1 to 8 threads on this machine's cores. */
#include "test_util.h"

#include "fxc_pool.h"

#include <stdatomic.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

enum { MAX_TASKS = 64 };

typedef struct run_state {
    uint32_t threads;
    uint32_t run;                   /* this run's number, written into every slot it ran */
    atomic_uint ran[MAX_TASKS];     /* times each task ran in this run */
    atomic_uint stamp[MAX_TASKS];   /* the run number each task saw */
    atomic_uint bad_thread;         /* tasks that got a thread index out of range */
    atomic_uint by_thread[16];      /* tasks each thread ran, over the test */
    uint32_t spin;                  /* busy-work per task, to let other threads join */
} run_state;

static void task(void *user, uint32_t index, uint32_t thread_index)
{
    run_state *st = user;
    if (thread_index >= st->threads)
        atomic_fetch_add(&st->bad_thread, 1);
    else if (thread_index < 16)
        atomic_fetch_add(&st->by_thread[thread_index], 1);
    volatile uint32_t sink = 0;
    for (uint32_t i = 0; i < st->spin; i++)
        sink += i;
    atomic_fetch_add(&st->ran[index], 1);
    atomic_store(&st->stamp[index], st->run);
}

/* Runs `runs` runs of varying sizes on a pool of `threads` and checks each as soon as it returns. */
static void check_runs(uint32_t threads, uint32_t runs, uint32_t pause_every, uint32_t spin)
{
    fxc_pool *pool = fxc_pool_create(threads, NULL);
    assert_non_null(pool);
    assert_int_equal(fxc_pool_threads(pool), threads);
    run_state *st = calloc(1, sizeof *st);
    assert_non_null(st);
    st->threads = threads;
    st->spin = spin;
    uint64_t seed = 0x243F6A8885A308D3ull;
    for (uint32_t r = 1; r <= runs; r++) {
        seed = seed * 6364136223846793005ull + 1442695040888963407ull;
        uint32_t count = (uint32_t)(seed >> 33) % (MAX_TASKS + 1); /* 0..64, 0 and 1 included */
        st->run = r;
        for (uint32_t i = 0; i < MAX_TASKS; i++)
            atomic_store(&st->ran[i], 0);
        fxc_pool_run(pool, count, task, st);
        for (uint32_t i = 0; i < MAX_TASKS; i++) {
            uint32_t expected = i < count ? 1u : 0u;
            if (atomic_load(&st->ran[i]) != expected)
                fail_msg("%u threads, run %u of %u tasks: task %u ran %u times", threads, r, count, i,
                         atomic_load(&st->ran[i]));
            if (i < count && atomic_load(&st->stamp[i]) != r)
                fail_msg("%u threads, run %u: task %u carries run %u", threads, r, i, atomic_load(&st->stamp[i]));
        }
        if (pause_every && r % pause_every == 0)
            usleep(2000); /* longer than the workers' spin: they go to sleep and must be woken */
    }
    assert_int_equal(atomic_load(&st->bad_thread), 0);
    fxc_pool_free(pool);
    /* Nothing runs after free: a late task would write into freed memory (the sanitizer build sees it). */
    free(st);
}

static void test_back_to_back(void **state)
{
    (void)state;
    for (uint32_t threads = 1; threads <= 8; threads *= 2)
        check_runs(threads, 20000, 0, 0);
}

static void test_with_sleeps(void **state)
{
    (void)state;
    for (uint32_t threads = 2; threads <= 4; threads++)
        check_runs(threads, 400, 3, 200);
}

/* With tasks long enough, the workers take part: a 2-thread pool on a run of 64 tasks of ~0.2 ms each does not
 * leave every task to the caller (over 50 runs; a worker that never woke would leave thread 1 at 0). */
static void test_workers_take_part(void **state)
{
    (void)state;
    if (sysconf(_SC_NPROCESSORS_ONLN) < 2) {
        print_message("one core: skipped\n");
        skip();
    }
    fxc_pool *pool = fxc_pool_create(2, NULL);
    assert_non_null(pool);
    run_state *st = calloc(1, sizeof *st);
    assert_non_null(st);
    st->threads = 2;
    st->spin = 200000;
    for (uint32_t r = 1; r <= 50; r++) {
        st->run = r;
        fxc_pool_run(pool, MAX_TASKS, task, st);
    }
    fxc_pool_free(pool);
    assert_int_equal(atomic_load(&st->by_thread[0]) + atomic_load(&st->by_thread[1]), 50u * MAX_TASKS);
    assert_true(atomic_load(&st->by_thread[1]) > 0);
    free(st);
}

static int g_inits;
static void count_init(void)
{
    __atomic_add_fetch(&g_inits, 1, __ATOMIC_SEQ_CST);
}

/* thread_init runs once on every worker and on the caller at each run that uses the workers. */
static void test_thread_init(void **state)
{
    (void)state;
    fxc_pool *pool = fxc_pool_create(3, count_init);
    assert_non_null(pool);
    run_state *st = calloc(1, sizeof *st);
    assert_non_null(st);
    st->threads = 3;
    for (uint32_t r = 1; r <= 5; r++) {
        st->run = r;
        fxc_pool_run(pool, 10, task, st);
    }
    fxc_pool_free(pool);
    assert_int_equal(__atomic_load_n(&g_inits, __ATOMIC_SEQ_CST), 2 + 5);
    free(st);
    assert_null(fxc_pool_create(FXC_POOL_MAX_THREADS + 1, NULL));
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_back_to_back),
        cmocka_unit_test(test_with_sleeps),
        cmocka_unit_test(test_workers_take_part),
        cmocka_unit_test(test_thread_init),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
