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

TEST_ALONE(harness_hung_test_times_out)
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

// Several tests at once (REFL_TEST_JOBS): the runner re-runs this binary on
// four inner tests that record when they ran. The TEST_LONG one, registered
// last, starts first, and a plain one beside it; the TEST_ALONE one beside
// none; what each prints comes out whole, before its result line; each
// has its own $XDG_STATE_HOME.
static bool inner_run(void) { return getenv("REFL_TEST_HARNESS_DIR") != NULL; }

static void record_span(const char *name)
{
    double t0 = model_realtime_s();
    printf("%s: begins\n", name);
    usleep(600000);
    printf("%s: ends\n", name);
    char path[1024];
    snprintf(path, sizeof path, "%s/%s", getenv("REFL_TEST_HARNESS_DIR"), name);
    FILE *f = fopen(path, "w");
    if (f) {
        fprintf(f, "%.6f %.6f %s\n", t0, model_realtime_s(), getenv("XDG_STATE_HOME") ? getenv("XDG_STATE_HOME") : "");
        fclose(f);
    }
}

TEST_INNER(harness_inner_span_a, inner_run) { record_span("a"); }
TEST_INNER(harness_inner_span_b, inner_run) { record_span("b"); }
static void harness_inner_span_c(void) { record_span("c"); }
__attribute__((constructor)) static void register_span_c(void)
{
    test_register_full("harness_inner_span_c", harness_inner_span_c, __FILE__, inner_run, TEST_FLAG_ALONE);
}
static void harness_inner_span_d(void) { record_span("d"); }
__attribute__((constructor)) static void register_span_d(void)
{
    test_register_full("harness_inner_span_d", harness_inner_span_d, __FILE__, inner_run, TEST_FLAG_LONG);
}

TEST(harness_jobs_side_by_side_and_alone)
{
    if (inner_run()) return;   // we are the inner run
    char self[4096];
    ssize_t n = readlink("/proc/self/exe", self, sizeof self - 1);
    CHECK(n > 0);
    if (n <= 0) return;
    self[n] = 0;
    char env_dir[1200];
    snprintf(env_dir, sizeof env_dir, "REFL_TEST_HARNESS_DIR=%s", test_tmpdir());
    const char *argv[] = { "env", env_dir, "REFL_TEST_JOBS=2", "REFL_TEST_SET=all", self, "harness_inner_span_", NULL };
    char *out = NULL, *err = NULL;
    int rc = test_run(argv, 60, &out, &err);
    CHECK_MSG(rc == 0 && out && strstr(out, "4 passed, 0 failed"), "exit %d\n%s%s", rc, out ? out : "", err ? err : "");
    CHECK_CONTAINS(out, "4 tests, 2 at a time");
    double t[4][2] = { { 0 } };
    char state[4][1024] = { "" };
    const char *names = "abcd";
    for (int i = 0; i < 4; i++) {
        char p[64];
        snprintf(p, sizeof p, "%c", names[i]);
        FILE *f = fopen(test_path(p), "r");
        CHECK(f && fscanf(f, "%lf %lf %1023s", &t[i][0], &t[i][1], state[i]) == 3);
        if (f) fclose(f);
        // its output whole: "x: begins\nx: ends\n" together, before "ok   harness_inner_span_x"
        char whole[64], ok[64];
        snprintf(whole, sizeof whole, "%c: begins\n%c: ends\n", names[i], names[i]);
        snprintf(ok, sizeof ok, "ok   harness_inner_span_%c", names[i]);
        const char *w = err ? strstr(err, whole) : NULL, *o = out ? strstr(out, ok) : NULL;
        CHECK_MSG(w && o, "'%s' whole in stderr and '%s' in stdout", whole, ok);
    }
    // run side by side: i's span and j's overlap
#define SIDE_BY_SIDE(i, j) (t[i][0] < t[j][1] && t[j][0] < t[i][1])
    // d, registered last, ran beside a: it started with the first pair (in registration order it would have
    // run last, after the TEST_ALONE one, beside nothing)
    CHECK_MSG(SIDE_BY_SIDE(3, 0), "the TEST_LONG d [%.3f, %.3f] did not start first, beside a [%.3f, %.3f]", t[3][0],
              t[3][1], t[0][0], t[0][1]);
    CHECK_MSG(t[3][0] < t[1][0] && t[3][0] < t[2][0], "the TEST_LONG test started after b or c");
    CHECK_MSG(!SIDE_BY_SIDE(2, 0) && !SIDE_BY_SIDE(2, 1) && !SIDE_BY_SIDE(2, 3), "the TEST_ALONE test ran beside another");
#undef SIDE_BY_SIDE
    CHECK(state[0][0] && strcmp(state[0], state[3]) != 0);
    free(out);
    free(err);
}
