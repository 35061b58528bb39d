// tests/test.h — refl's small test harness.
//
//   TEST(name) { CHECK(x > 0); CHECK_NEAR(a, b, 1e-9); CHECK_REL(a, b, 1e-6);
//                CHECK_CONTAINS(msg, "line 3"); }
//
// Tests register themselves; bin/refl-tests runs them all (or those whose name
// or file contains argv[1]), each in its own child process, $REFL_TEST_JOBS
// (default 2) at a time, and ends with the line "N passed, N failed"
// (", N skipped" appended when tests were skipped). A test that measures time
// (a stop within 1 s, a settle time, linear time on large input) is declared
// with TEST_ALONE instead of TEST: it runs with no other test beside it. A
// test of a minute or more (a lab day, a calibration on the virtual rig) is
// declared with TEST_LONG: the long tests start first, so the short ones fill
// in beside them. Each test's $XDG_STATE_HOME is a directory of its own,
// removed afterwards.
// A test passes when none of its checks failed; a test that crashes, aborts or
// is killed by a signal fails with the signal named, and so does one that runs
// longer than $REFL_TEST_TIMEOUT seconds (default 600). Each failed check
// prints file:line and the values. SKIP("why") ends a test as skipped when
// something it needs is not available here. Tests needing files use
// test_tmpdir(), which is removed afterwards.
#pragma once

#include <math.h>
#include <stdbool.h>
#include <stdio.h>
#include <string.h>

typedef void (*test_fn_t)(void);
void test_register(const char *name, test_fn_t fn, const char *file);
// A test that runs only where only_if() is true (e.g. inside umockdev-wrapper,
// re-run by a host test that checks its result): elsewhere it is neither run
// nor counted, and the summary says how many such tests were left to their host.
void test_register_inner(const char *name, test_fn_t fn, const char *file, bool (*only_if)(void));
void test_fail(const char *file, int line, const char *fmt, ...)
    __attribute__((format(printf, 3, 4)));
// End the running test as skipped, with the reason (printf-style). A test that
// had failed checks before stays failed.
void test_skip(const char *fmt, ...) __attribute__((format(printf, 1, 2), noreturn));
#define SKIP(...) test_skip(__VA_ARGS__)

#define TEST(name)                                                                 \
    static void name(void);                                                        \
    __attribute__((constructor)) static void test_reg_##name(void)                 \
    {                                                                              \
        test_register(#name, name, __FILE__);                                      \
    }                                                                              \
    static void name(void)

#define TEST_INNER(name, only_if)                                                  \
    static void name(void);                                                        \
    __attribute__((constructor)) static void test_reg_##name(void)                 \
    {                                                                              \
        test_register_inner(#name, name, __FILE__, only_if);                       \
    }                                                                              \
    static void name(void)

void test_register_alone(const char *name, test_fn_t fn, const char *file);
void test_register_long(const char *name, test_fn_t fn, const char *file);
#define TEST_LONG(name)                                                            \
    static void name(void);                                                        \
    __attribute__((constructor)) static void test_reg_##name(void)                 \
    {                                                                              \
        test_register_long(#name, name, __FILE__);                                 \
    }                                                                              \
    static void name(void)
// With flags (the runner's own tests register a TEST_INNER that runs alone or long).
enum { TEST_FLAG_ALONE = 1, TEST_FLAG_LONG = 2 };
void test_register_full(const char *name, test_fn_t fn, const char *file, bool (*only_if)(void), int flags);
#define TEST_ALONE(name)                                                           \
    static void name(void);                                                        \
    __attribute__((constructor)) static void test_reg_##name(void)                 \
    {                                                                              \
        test_register_alone(#name, name, __FILE__);                                \
    }                                                                              \
    static void name(void)

#define CHECK(cond)                                                                \
    do {                                                                           \
        if (!(cond)) test_fail(__FILE__, __LINE__, "CHECK(%s)", #cond);            \
    } while (0)

#define CHECK_MSG(cond, ...)                                                       \
    do {                                                                           \
        if (!(cond)) test_fail(__FILE__, __LINE__, __VA_ARGS__);                   \
    } while (0)

#define CHECK_NEAR(a, b, tol)                                                      \
    do {                                                                           \
        double a_ = (a), b_ = (b), t_ = (tol);                                     \
        if (!(fabs(a_ - b_) <= t_))                                                \
            test_fail(__FILE__, __LINE__, "%s = %.12g, %s = %.12g, |diff| %.3g > %.3g", \
                      #a, a_, #b, b_, fabs(a_ - b_), t_);                          \
    } while (0)

#define CHECK_REL(a, b, rel)                                                       \
    do {                                                                           \
        double a_ = (a), b_ = (b), r_ = (rel);                                     \
        double s_ = fmax(fabs(a_), fabs(b_));                                      \
        if (!(fabs(a_ - b_) <= r_ * s_))                                           \
            test_fail(__FILE__, __LINE__, "%s = %.12g, %s = %.12g, rel diff %.3g > %.3g", \
                      #a, a_, #b, b_, s_ > 0 ? fabs(a_ - b_) / s_ : 0.0, r_);      \
    } while (0)

#define CHECK_CONTAINS(hay, needle)                                                \
    do {                                                                           \
        const char *h_ = (hay), *n_ = (needle);                                    \
        if (!h_ || !strstr(h_, n_))                                                \
            test_fail(__FILE__, __LINE__, "expected \"%s\" in \"%s\"", n_, h_ ? h_ : "(null)"); \
    } while (0)

// A fresh temporary directory for this test (removed when the test ends).
const char *test_tmpdir(void);
// Path of a file in the test's temporary directory (static buffer per call slot).
const char *test_path(const char *name);
// Write text to a file in the temporary directory; returns its path.
const char *test_write(const char *name, const char *text);
// The source tree's top directory (for examples/ and tests/ data).
const char *test_srcdir(void);
// The refl binary ($REFL, default bin/refl).
const char *test_refl(void);
// Run a command (argv, NULL-terminated) with a time limit; capture stdout and
// stderr (caller frees, may pass NULL). Returns the exit status, or -1 on
// failure to run, 128+signal when killed, 124 on time-out.
int test_run(const char *const *argv, double timeout_s, char **out, char **err);
// Run bin/refl with the given arguments (NULL-terminated), time limit timeout_s.
int test_refl_run(double timeout_s, char **out, char **err, ...) __attribute__((sentinel));

// The lock every test that serves a virtual camera on 127.0.0.1:3956 holds
// throughout (one server per address): test runs of several build trees take
// turns. Waits up to 300 s; a failed CHECK and -1 if it cannot be had.
int  test_camera_lock(void);
void test_camera_unlock(int fd);

// How the runner runs a test, for the runner's own tests (tests/test_harness.c):
// fn in a child process of its own with a time limit, its temporary directory
// removed afterwards.
typedef struct {
    int  failures;        // failed checks
    bool skipped;
    char reason[512];     // of the skip
    char how[256];        // what alone fails it ("killed by signal ...", "timed out ..."), or ""
    char tmpdir[512];     // the directory test_tmpdir() made, if any (removed by now)
} test_outcome_t;
void test_run_isolated(test_fn_t fn, double limit_s, test_outcome_t *out);
