/* test_pool.c: the shared thread pool (common/fxc_pool.h). Every task of every run runs exactly once, on a
 * thread index below the pool's thread count, and the run returns only after all of them: checked over many
 * short runs back to back (where workers still spinning from the previous run meet the next one, and late
 * workers meet a run that has already moved on), runs of one task, runs after a pause long enough for the
 * workers to sleep, and pools of 1 to 8 threads on this machine's cores. Static runs (fxc_pool_run_static) the
 * same, and: without stealing, each thread runs one contiguous range, ranges in thread order and of sizes
 * within one of each other, the same thread for the same task run after run; with stealing, each range's owner
 * runs a prefix of it and a stuck owner's tail is taken by another thread.
 *
 * Thread sanitizer (not a CMake option; by hand, from the repository root, with a configured build in $B for
 * test_util.h's include paths):
 *   gcc -std=c11 -O1 -g -fsanitize=thread -D_DEFAULT_SOURCE \
 *       $(grep C_INCLUDES $B/tests/CMakeFiles/test_pool.dir/flags.make | cut -d= -f2-) \
 *       tests/test_pool.c common/fxc_pool.c -lcmocka -lpthread -o /tmp/test_pool_tsan && /tmp/test_pool_tsan */
#include "test_util.h"

#include "fxc_pool.h"

#include <stdatomic.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

enum { MAX_TASKS = 64 };

typedef struct run_state {
    uint32_t threads;
    uint32_t run;                     /* this run's number, written into every slot it ran */
    atomic_uint ran[MAX_TASKS];       /* times each task ran in this run */
    atomic_uint stamp[MAX_TASKS];     /* the run number each task saw */
    atomic_uint bad_thread;           /* tasks that got a thread index out of range */
    atomic_uint by_thread[16];        /* tasks each thread ran, over the test */
    atomic_uint thread_of[MAX_TASKS]; /* the thread that ran each task in this run */
    uint32_t spin;                    /* busy-work per task, to let other threads join */
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
    atomic_store(&st->thread_of[index], thread_index);
    atomic_fetch_add(&st->ran[index], 1);
    atomic_store(&st->stamp[index], st->run);
}

enum { RUN_DYNAMIC, RUN_STATIC_STEAL, RUN_STATIC };

/* Runs `runs` runs of varying sizes on a pool of `threads` and checks each as soon as it returns. */
static void check_static(const run_state *st, uint32_t count, bool steal, uint32_t *first_thread);

static void check_runs_mode(uint32_t threads, uint32_t runs, uint32_t pause_every, uint32_t spin, int mode)
{
    fxc_pool *pool = fxc_pool_create(threads, NULL);
    assert_non_null(pool);
    assert_int_equal(fxc_pool_threads(pool), threads);
    run_state *st = calloc(1, sizeof *st);
    assert_non_null(st);
    st->threads = threads;
    st->spin = spin;
    uint64_t seed = 0x243F6A8885A308D3ull;
    /* Static runs without stealing: the thread of each task in the first run of each count. */
    uint32_t first_thread[MAX_TASKS + 1][MAX_TASKS];
    bool seen_count[MAX_TASKS + 1] = {false};
    for (uint32_t r = 1; r <= runs; r++) {
        seed = seed * 6364136223846793005ull + 1442695040888963407ull;
        uint32_t count = (uint32_t)(seed >> 33) % (MAX_TASKS + 1); /* 0..64, 0 and 1 included */
        st->run = r;
        for (uint32_t i = 0; i < MAX_TASKS; i++)
            atomic_store(&st->ran[i], 0);
        if (mode == RUN_DYNAMIC)
            fxc_pool_run(pool, count, task, st);
        else
            fxc_pool_run_static(pool, count, task, st, mode == RUN_STATIC_STEAL);
        for (uint32_t i = 0; i < MAX_TASKS; i++) {
            uint32_t expected = i < count ? 1u : 0u;
            if (atomic_load(&st->ran[i]) != expected)
                fail_msg("%u threads, run %u of %u tasks: task %u ran %u times", threads, r, count, i,
                         atomic_load(&st->ran[i]));
            if (i < count && atomic_load(&st->stamp[i]) != r)
                fail_msg("%u threads, run %u: task %u carries run %u", threads, r, i,
                         atomic_load(&st->stamp[i]));
        }
        if (mode != RUN_DYNAMIC) {
            check_static(st, count, mode == RUN_STATIC_STEAL, seen_count[count] ? first_thread[count] : NULL);
            if (!seen_count[count])
                for (uint32_t i = 0; i < count; i++)
                    first_thread[count][i] = atomic_load(&st->thread_of[i]);
            seen_count[count] = true;
        }
        if (pause_every && r % pause_every == 0)
            usleep(2000); /* longer than the workers' spin: they go to sleep and must be woken */
    }
    assert_int_equal(atomic_load(&st->bad_thread), 0);
    fxc_pool_free(pool);
    /* Nothing runs after free: a late task would write into freed memory (the sanitizer build sees it). */
    free(st);
}

static void check_runs(uint32_t threads, uint32_t runs, uint32_t pause_every, uint32_t spin)
{
    check_runs_mode(threads, runs, pause_every, spin, RUN_DYNAMIC);
}

/* One static run of count tasks just returned. Without steal: threads run contiguous ranges in thread order
 * (thread 0 first), sizes within one of count / threads, and (first_thread given) each task on the thread it
 * had in the first run of this count. With steal: the tasks each thread ran of the range the header gives it
 * are a prefix of that range. */
static void check_static(const run_state *st, uint32_t count, bool steal, uint32_t *first_thread)
{
    uint32_t threads = st->threads;
    if (!steal) {
        uint32_t size[16] = {0};
        for (uint32_t i = 0; i < count; i++) {
            uint32_t t = atomic_load(&st->thread_of[i]);
            if (i > 0 && t < atomic_load(&st->thread_of[i - 1]))
                fail_msg("%u threads, %u tasks: task %u on thread %u after thread %u", threads, count, i, t,
                         atomic_load(&st->thread_of[i - 1]));
            if (t < 16)
                size[t]++;
            if (first_thread && first_thread[i] != t)
                fail_msg("%u threads, %u tasks: task %u on thread %u, first on %u", threads, count, i, t,
                         first_thread[i]);
        }
        if (count >= 2) /* runs of one task go to the caller */
            for (uint32_t t = 0; t < threads && t < 16; t++)
                if (size[t] != count / threads && size[t] != (count + threads - 1) / threads)
                    fail_msg("%u threads, %u tasks: thread %u ran %u", threads, count, t, size[t]);
        return;
    }
    if (count < 2)
        return;
    for (uint32_t t = 0; t < threads; t++) {
        uint32_t begin = fxc_pool_static_begin(count, threads, t),
                 end = fxc_pool_static_begin(count, threads, t + 1);
        bool others = false;
        for (uint32_t i = begin; i < end; i++) {
            bool own = atomic_load(&st->thread_of[i]) == t;
            if (own && others)
                fail_msg("%u threads, %u tasks: task %u of thread %u's range ran on it after a stolen one",
                         threads, count, i, t);
            others |= !own;
        }
    }
}

static void test_static_back_to_back(void **state)
{
    (void)state;
    for (uint32_t threads = 1; threads <= 8; threads *= 2) {
        /* Without stealing every worker must take part in every run: fewer runs where workers outnumber cores. */
        check_runs_mode(threads, 4000 / threads, 0, 0, RUN_STATIC);
        check_runs_mode(threads, 4000, 0, 0, RUN_STATIC_STEAL);
    }
}

static void test_static_with_sleeps(void **state)
{
    (void)state;
    for (uint32_t threads = 2; threads <= 4; threads++) {
        check_runs_mode(threads, 200, 3, 200, RUN_STATIC);
        check_runs_mode(threads, 200, 3, 200, RUN_STATIC_STEAL);
    }
}

/* Dynamic and static runs alternating on one pool (a late worker of one kind meets a run of the other). */
static void test_mixed_modes(void **state)
{
    (void)state;
    fxc_pool *pool = fxc_pool_create(3, NULL);
    assert_non_null(pool);
    run_state *st = calloc(1, sizeof *st);
    assert_non_null(st);
    st->threads = 3;
    for (uint32_t r = 1; r <= 6000; r++) {
        uint32_t count = 1 + r % MAX_TASKS;
        st->run = r;
        for (uint32_t i = 0; i < MAX_TASKS; i++)
            atomic_store(&st->ran[i], 0);
        if (r % 3 == 0)
            fxc_pool_run(pool, count, task, st);
        else
            fxc_pool_run_static(pool, count, task, st, r % 3 == 1);
        for (uint32_t i = 0; i < count; i++)
            if (atomic_load(&st->ran[i]) != 1 || atomic_load(&st->stamp[i]) != r)
                fail_msg("run %u (kind %u) of %u tasks: task %u ran %u times", r, r % 3, count, i,
                         atomic_load(&st->ran[i]));
    }
    assert_int_equal(atomic_load(&st->bad_thread), 0);
    fxc_pool_free(pool);
    free(st);
}

/* Stealing: thread 1's first task (4 of 8) does not return until task 7, the end of thread 1's range, has run.
 * Thread 1 takes its range from the front, so only a thief (thread 0) can run task 7: without stealing the
 * run would wait for 5 s and fail. */
typedef struct steal_state {
    atomic_uint done7, thread_of7, timed_out;
} steal_state;

static void steal_task(void *user, uint32_t index, uint32_t thread_index)
{
    steal_state *st = user;
    if (index == 7) {
        atomic_store(&st->thread_of7, thread_index);
        atomic_store(&st->done7, 1);
    } else if (index == 4 && thread_index == 1) {
        for (uint32_t ms = 0; !atomic_load(&st->done7); ms++) {
            if (ms == 5000) {
                atomic_store(&st->timed_out, 1);
                break;
            }
            usleep(1000);
        }
    }
}

static void test_static_steal(void **state)
{
    (void)state;
    fxc_pool *pool = fxc_pool_create(2, NULL);
    assert_non_null(pool);
    for (int r = 0; r < 20; r++) {
        steal_state st;
        atomic_init(&st.done7, 0);
        atomic_init(&st.thread_of7, 99);
        atomic_init(&st.timed_out, 0);
        fxc_pool_run_static(pool, 8, steal_task, &st, true);
        assert_int_equal(atomic_load(&st.timed_out), 0);
        assert_int_equal(atomic_load(&st.done7), 1);
        assert_int_equal(atomic_load(&st.thread_of7), 0);
    }
    fxc_pool_free(pool);
}

/* Counts above FXC_POOL_STATIC_MAX are run (dynamically), every task once. */
static atomic_uint g_big_ran;
static void big_task(void *user, uint32_t index, uint32_t thread_index)
{
    (void)thread_index;
    uint8_t *ran = user;
    ran[index]++;
    atomic_fetch_add(&g_big_ran, 1);
}

static void test_static_large_count(void **state)
{
    (void)state;
    fxc_pool *pool = fxc_pool_create(2, NULL);
    assert_non_null(pool);
    uint32_t counts[] = {FXC_POOL_STATIC_MAX, FXC_POOL_STATIC_MAX + 1u, 3u * FXC_POOL_STATIC_MAX};
    for (size_t k = 0; k < sizeof counts / sizeof counts[0]; k++) {
        uint8_t *ran = calloc(counts[k], 1);
        assert_non_null(ran);
        atomic_store(&g_big_ran, 0);
        fxc_pool_run_static(pool, counts[k], big_task, ran, k % 2 == 0);
        assert_int_equal(atomic_load(&g_big_ran), counts[k]);
        for (uint32_t i = 0; i < counts[k]; i++)
            if (ran[i] != 1)
                fail_msg("%u tasks: task %u ran %u times", counts[k], i, ran[i]);
        free(ran);
    }
    fxc_pool_free(pool);
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
        cmocka_unit_test(test_back_to_back),        cmocka_unit_test(test_with_sleeps),
        cmocka_unit_test(test_workers_take_part),   cmocka_unit_test(test_thread_init),
        cmocka_unit_test(test_static_back_to_back), cmocka_unit_test(test_static_with_sleeps),
        cmocka_unit_test(test_mixed_modes),         cmocka_unit_test(test_static_steal),
        cmocka_unit_test(test_static_large_count),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
