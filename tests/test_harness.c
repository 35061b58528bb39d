// tests/test_harness.c — the runner itself (tests/harness.c): a test that
// crashes or hangs fails alone, with the signal or the time-out named; SKIP
// ends a test as skipped with its reason; the temporary directory and any
// process a test leaves behind are gone when it has ended.
#define _GNU_SOURCE
#include <errno.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <sys/mman.h>
#include <unistd.h>

#include "model/model.h"
#include "tests/test.h"

static void aborts(void) { abort(); }

static void hangs(void) { sleep(30); }

static void skips(void) { SKIP("no %s here (%d)", "widget", 7); }

static void writes_a_file(void) { test_write("a.txt", "x"); }

// The pid of the process leaves_a_child leaves running (a shared page).
static pid_t *left_child;

static void leaves_a_child(void)
{
    pid_t pid = fork();
    if (pid == 0) {
        sleep(30);
        _exit(0);
    }
    *left_child = pid;
}

// pid runs (exists and is not a zombie).
static bool running(pid_t pid)
{
    char path[64], buf[256];
    snprintf(path, sizeof path, "/proc/%d/stat", (int)pid);
    FILE *f = fopen(path, "r");
    if (!f) return false;
    size_t n = fread(buf, 1, sizeof buf - 1, f);
    fclose(f);
    buf[n] = 0;
    const char *p = strrchr(buf, ')');   // "pid (comm) S ..."
    return !(p && p[1] == ' ' && (p[2] == 'Z' || p[2] == 'X'));
}

TEST(harness_crash_fails_with_the_signal_named)
{
    test_outcome_t o;
    test_run_isolated(aborts, 60, &o);
    CHECK_CONTAINS(o.how, "killed by signal SIGABRT");
    CHECK(o.failures == 0 && !o.skipped);
}

TEST(harness_hung_test_times_out)
{
    test_outcome_t o;
    double t0 = model_now_s();
    test_run_isolated(hangs, 0.5, &o);
    double dt = model_now_s() - t0;
    CHECK_CONTAINS(o.how, "timed out after 0.5 s");
    CHECK_MSG(dt >= 0.5 && dt < 5, "the time-out took %.2f s", dt);
}

TEST(harness_skip_with_reason)
{
    test_outcome_t o;
    test_run_isolated(skips, 60, &o);
    CHECK(o.skipped && o.failures == 0 && o.how[0] == 0);
    CHECK_CONTAINS(o.reason, "no widget here (7)");
}

TEST(harness_tmpdir_and_left_processes_removed)
{
    test_outcome_t o;
    test_run_isolated(writes_a_file, 60, &o);
    CHECK(o.how[0] == 0 && o.failures == 0 && !o.skipped);
    CHECK_CONTAINS(o.tmpdir, "refl-test-");
    CHECK_MSG(access(o.tmpdir, F_OK) != 0 && errno == ENOENT, "%s is still there", o.tmpdir);

    left_child = mmap(NULL, sizeof *left_child, PROT_READ | PROT_WRITE, MAP_SHARED | MAP_ANONYMOUS, -1, 0);
    CHECK(left_child != MAP_FAILED);
    if (left_child == MAP_FAILED) return;
    *left_child = 0;
    test_run_isolated(leaves_a_child, 60, &o);
    CHECK(o.how[0] == 0 && *left_child > 0);
    // Killed with the test's process group (then a zombie until its new parent reaps it).
    bool gone = false;
    for (int i = 0; i < 200 && !gone; i++) {
        gone = *left_child > 0 && !running(*left_child);
        if (!gone) usleep(10000);
    }
    CHECK_MSG(gone, "process %d the test left is still running", (int)*left_child);
    munmap(left_child, sizeof *left_child);
}
