// tests/test_rig_lamps.c — lamps (rig/lamps/lamps.c): settle times and checks on the sim
// backend in-process; the gpiod backend through tests/lamp_child.c run under
// LD_PRELOAD of the fake libgpiod (tests/fake_gpiod.c), whose log records the
// physical level of every request/set/release. `make check` passes the two
// paths as REFL_LAMP_CHILD and REFL_FAKE_GPIOD.
#define _GNU_SOURCE
#include <errno.h>
#include <fcntl.h>
#include <limits.h>
#include <poll.h>
#include <signal.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include "model/model.h"
#include "model/base/report.h"
#include "rig/rig.h"
#include "tests/test.h"

static rig_lamp_line_t lamp(const char *name, const char *chip, unsigned line, bool active_low,
                            double warmup_ms, double settle_ms)
{
    rig_lamp_line_t a;
    memset(&a, 0, sizeof a);
    snprintf(a.name, sizeof a.name, "%s", name);
    snprintf(a.chip, sizeof a.chip, "%s", chip);
    a.line = line;
    a.active_low = active_low;
    a.warmup_ms = warmup_ms;
    a.settle_ms = settle_ms;
    return a;
}

// ---------------------------------------------------------------------------
// Sim backend

TEST(lamps_sim_settle_times)
{
    rig_lamp_line_t ls[3] = {
        lamp("key", "", 0, false, 30, 5),
        lamp("fill", "", 1, false, 10, 20),
        lamp("led", "", 2, false, 0, 0),
    };
    rig_lamps_t *l = NULL;
    CHECK(rig_lamps_open_sim(&l, ls, 3) == 0);
    if (!l) return;
    CHECK(rig_lamps_count(l) == 3 && rig_lamps_on_mask(l) == 0);
    CHECK(!strcmp(rig_lamps_backend(l), "sim"));
    CHECK_NEAR(rig_lamps_settle_s(l, 0, 0x3), 0.030, 1e-12);    // warm-ups 30, 10
    CHECK_NEAR(rig_lamps_settle_s(l, 0x3, 0x2), 0.005, 1e-12);  // key off: settle 5
    CHECK_NEAR(rig_lamps_settle_s(l, 0x3, 0x1), 0.020, 1e-12);  // fill off: settle 20
    CHECK_NEAR(rig_lamps_settle_s(l, 0x1, 0x2), 0.010, 1e-12);  // max(fill on 10, key off 5)
    CHECK_NEAR(rig_lamps_settle_s(l, 0x2, 0x1), 0.030, 1e-12);  // max(key on 30, fill off 20)
    CHECK_NEAR(rig_lamps_settle_s(l, 0x3, 0x3), 0.0, 0);        // no change
    CHECK_NEAR(rig_lamps_settle_s(l, 0x0, 0x4), 0.0, 0);        // led: instant
    CHECK_NEAR(rig_lamps_settle_s(l, 0x0, 0x8), 0.0, 0);        // no lamp 3
    CHECK_NEAR(rig_lamps_settle_s(NULL, 0, 1), 0.0, 0);
    rig_lamps_close(l);
}

TEST_ALONE(lamps_sim_set_sleeps_settle_time)
{
    rig_lamp_line_t ls[2] = { lamp("a", "", 0, false, 40, 15), lamp("b", "", 1, false, 0, 0) };
    rig_lamps_t *l = NULL;
    CHECK(rig_lamps_open_sim(&l, ls, 2) == 0);
    if (!l) return;
    double t0 = model_now_s();
    CHECK(rig_lamps_set(l, 0x1) == 0);
    double dt_on = model_now_s() - t0;
    CHECK(rig_lamps_on_mask(l) == 0x1);
    t0 = model_now_s();
    CHECK(rig_lamps_set(l, 0x2) == 0);          // a off (15 ms), b on (0 ms)
    double dt_swap = model_now_s() - t0;
    CHECK(rig_lamps_on_mask(l) == 0x2);
    t0 = model_now_s();
    CHECK(rig_lamps_set(l, 0x2) == 0);          // no change, no wait
    double dt_same = model_now_s() - t0;
    CHECK(rig_lamps_all_off(l) == 0);
    CHECK(rig_lamps_on_mask(l) == 0);
    CHECK_MSG(dt_on >= 0.040 && dt_on < 0.040 + 0.25, "switch-on took %.4f s, want 0.040", dt_on);
    CHECK_MSG(dt_swap >= 0.015 && dt_swap < 0.015 + 0.25, "swap took %.4f s, want 0.015", dt_swap);
    CHECK_MSG(dt_same < 0.010, "no-op set took %.4f s", dt_same);
    rig_lamps_close(l);
}

TEST(lamps_sim_errors)
{
    rig_lamp_line_t ls[3] = { lamp("a", "", 0, false, 0, 0), lamp("b", "", 1, false, 0, 0),
                              lamp("c", "", 2, false, 0, 0) };
    rig_lamps_t *l = NULL;
    CHECK(rig_lamps_open_sim(&l, ls, 3) == 0);
    if (l) {
        CHECK(rig_lamps_set(l, 0x8) == RIG_ERR_INVALID);
        CHECK_CONTAINS(model_last_error(), "on_mask 0x8");
        CHECK_CONTAINS(model_last_error(), "3 configured");
        CHECK(rig_lamps_on_mask(l) == 0);
        CHECK(rig_lamps_find(l, "b") == 1);
        CHECK(rig_lamps_find(l, "d") == -1);
        CHECK(rig_lamps_find(l, NULL) == -1);
        rig_lamps_close(l);
    }
    CHECK(rig_lamps_find(NULL, "a") == -1);
    CHECK(rig_lamps_set(NULL, 0) == RIG_ERR_INVALID);
    CHECK(rig_lamps_all_off(NULL) == RIG_ERR_INVALID);
    rig_lamps_close(NULL);

    rig_lamp_line_t dup[2] = { lamp("a", "", 0, false, 0, 0), lamp("a", "", 1, false, 0, 0) };
    l = (rig_lamps_t *)1;
    CHECK(rig_lamps_open_sim(&l, dup, 2) == RIG_ERR_INVALID);
    CHECK(l == NULL);
    CHECK_CONTAINS(model_last_error(), "both named 'a'");

    rig_lamp_line_t bad = lamp("key", "", 0, false, -1, 0);
    CHECK(rig_lamps_open_sim(&l, &bad, 1) == RIG_ERR_INVALID);
    CHECK_CONTAINS(model_last_error(), "lamp 'key': warmup_ms -1");
    bad = lamp("key", "", 0, false, 0, NAN);
    CHECK(rig_lamps_open_sim(&l, &bad, 1) == RIG_ERR_INVALID);
    CHECK_CONTAINS(model_last_error(), "lamp 'key': settle_ms nan");
    bad = lamp("", "", 0, false, 0, 0);
    CHECK(rig_lamps_open_sim(&l, &bad, 1) == RIG_ERR_INVALID);
    CHECK_CONTAINS(model_last_error(), "lamp 0 has no name");
    CHECK(rig_lamps_open_sim(&l, ls, 33) == RIG_ERR_INVALID);
    CHECK_CONTAINS(model_last_error(), "33 lamps given");
    CHECK(rig_lamps_open_sim(NULL, ls, 1) == RIG_ERR_INVALID);
    CHECK(rig_lamps_open_gpiod(&l, dup, 2) == RIG_ERR_INVALID);   // checked before any chip is opened
    CHECK_CONTAINS(model_last_error(), "both named 'a'");
}

TEST(lamps_sim_registry_full)
{
    // The safety registry holds 32 open sets; the 33rd open fails cleanly.
    rig_lamp_line_t a = lamp("a", "", 0, false, 0, 0);
    rig_lamps_t *sets[40] = { 0 };
    int opened = 0, err = 0;
    while (opened < 40 && !(err = rig_lamps_open_sim(&sets[opened], &a, 1))) opened++;
    CHECK(opened >= 1 && opened <= 32);   // 32 unless another test left a set open
    CHECK(err == RIG_ERR_NO_MEM);
    CHECK_CONTAINS(model_last_error(), "more than 32 lamp sets open");
    for (int i = 0; i < opened; i++) rig_lamps_close(sets[i]);
    rig_lamps_t *l = NULL;
    CHECK(rig_lamps_open_sim(&l, &a, 1) == 0);   // slots freed on close
    rig_lamps_close(l);
}

// ---------------------------------------------------------------------------
// gpiod backend through the child program and the fake library

static bool fake_paths(char lib[PATH_MAX], char child[PATH_MAX])
{
    const char *l = getenv("REFL_FAKE_GPIOD"), *c = getenv("REFL_LAMP_CHILD");
    if (!l || !c || !realpath(l, lib) || !realpath(c, child)) {
        test_fail(__FILE__, __LINE__, "REFL_FAKE_GPIOD (%s) and REFL_LAMP_CHILD (%s) must name the fake "
                  "libgpiod and tests/lamp_child binaries (make check sets them)",
                  l ? l : "unset", c ? c : "unset");
        return false;
    }
    return true;
}

typedef struct {
    char  lib[PATH_MAX], child[PATH_MAX];
    char  env[6][PATH_MAX + 64];
    const char *argv[64];
    const char *log;
} child_cmd_t;

// argv: env LD_PRELOAD=... FAKE_GPIOCHIP=... FAKE_GPIO_LOG=... [extra] child MODE MASK LAMP...
static bool child_cmd(child_cmd_t *c, const char *chips, const char *extra_env, const char *mode,
                      const char *mask, const char *const *lamps)
{
    if (!fake_paths(c->lib, c->child)) return false;
    c->log = test_path("gpio.log");
    unlink(c->log);
    int k = 0, e = 0;
    c->argv[k++] = "env";
    snprintf(c->env[e], sizeof c->env[e], "LD_PRELOAD=%s", c->lib);
    c->argv[k++] = c->env[e++];
    snprintf(c->env[e], sizeof c->env[e], "FAKE_GPIOCHIP=%s", chips);
    c->argv[k++] = c->env[e++];
    snprintf(c->env[e], sizeof c->env[e], "FAKE_GPIO_LOG=%s", c->log);
    c->argv[k++] = c->env[e++];
    // The lamp-state files of the test, not the user's (~/.local/state/refl).
    snprintf(c->env[e], sizeof c->env[e], "XDG_STATE_HOME=%s", test_path("state"));
    c->argv[k++] = c->env[e++];
    // Under make asan the child is an ASan binary and the fake is preloaded first;
    // ASan's own fault handlers would report the child's deliberate faults and
    // end it first: the lamps' handler is what is tested.
    c->argv[k++] = "ASAN_OPTIONS=verify_asan_link_order=0:detect_leaks=0:handle_segv=0:handle_sigbus=0:"
                   "handle_sigfpe=0";
    if (extra_env) c->argv[k++] = extra_env;
    c->argv[k++] = c->child;
    c->argv[k++] = mode;
    c->argv[k++] = mask;
    for (int i = 0; lamps[i] && k < 63; i++) c->argv[k++] = lamps[i];
    c->argv[k] = NULL;
    return true;
}

// The last physical level the log shows for a line, -1 if none.
static int last_level(const char *log, const char *chip, unsigned offset)
{
    int level = -1;
    for (const char *p = log; p && *p;) {
        char op[16], ch[64];
        unsigned off;
        int lv;
        if (sscanf(p, "%15s %63s %u=%d", op, ch, &off, &lv) == 4 && !strcmp(ch, chip) && off == offset)
            level = lv;
        p = strchr(p, '\n');
        if (p) p++;
    }
    return level;
}

static int count_lines(const char *log, const char *prefix)
{
    int n = 0;
    for (const char *p = log; p && *p;) {
        if (!strncmp(p, prefix, strlen(prefix))) n++;
        p = strchr(p, '\n');
        if (p) p++;
    }
    return n;
}

static char *read_log(const char *path)
{
    bool q = model_error_quiet(true);
    char *s = model_read_file(path, NULL);
    model_error_quiet(q);
    return s ? s : calloc(1, 1);
}

static const char *const three_lamps[] = { "key=gpiochip0:3", "fill=gpiochip0:5:low", "back=/dev/gpiochip1:2",
                                           NULL };

TEST(lamps_gpiod_switch_and_close)
{
    child_cmd_t c;
    if (!child_cmd(&c, "gpiochip0:32,gpiochip1:8", NULL, "close", "0x3", three_lamps)) return;
    char *out = NULL, *err = NULL;
    int rc = test_run(c.argv, 20, &out, &err);
    CHECK_MSG(rc == 0, "exit %d, stderr: %s", rc, err);
    CHECK_CONTAINS(out, "closed");
    char *log = read_log(c.log);
    // Requested at the OFF level (active-low 'fill': high), consumer "refl".
    CHECK_CONTAINS(log, "request gpiochip0 3=0 consumer=refl\n");
    CHECK_CONTAINS(log, "request gpiochip0 5=1 consumer=refl\n");
    CHECK_CONTAINS(log, "request gpiochip1 2=0 consumer=refl\n");
    // key and fill on: key high, fill (active-low) low; back stays off.
    CHECK_CONTAINS(log, "set gpiochip0 3=1\nset gpiochip0 5=0\nset gpiochip1 2=0\n");
    // Closed: everything off and released.
    CHECK(last_level(log, "gpiochip0", 3) == 0);
    CHECK(last_level(log, "gpiochip0", 5) == 1);
    CHECK(last_level(log, "gpiochip1", 2) == 0);
    CHECK(count_lines(log, "request ") == 3);
    CHECK(count_lines(log, "release ") == 3);
    CHECK_CONTAINS(log, "release gpiochip0 5=1\n");
    free(log);
    free(out);
    free(err);
}

TEST_ALONE(lamps_gpiod_active_low_only)
{
    static const char *const lamps[] = { "ring=gpiochip0:7:low", NULL };
    child_cmd_t c;
    if (!child_cmd(&c, "gpiochip0:8", NULL, "close", "0x1", lamps)) return;
    int rc = test_run(c.argv, 20, NULL, NULL);
    CHECK(rc == 0);
    char *log = read_log(c.log);
    CHECK_CONTAINS(log, "request gpiochip0 7=1 consumer=refl\nset gpiochip0 7=0\nset gpiochip0 7=1\n");
    CHECK(last_level(log, "gpiochip0", 7) == 1);
    free(log);
}

static const int fatal_signals[] = { SIGINT, SIGTERM, SIGHUP, SIGQUIT, SIGSEGV, SIGBUS, SIGFPE, SIGABRT };

// Forks and execs the child command, its signals at their defaults and no
// core files; waits for "ready" on its stdout. *pid is the child (-1 when
// the fork failed); false when it never got ready (then it is killed).
static bool spawn_ready(const child_cmd_t *c, pid_t *pid)
{
    int p[2];
    *pid = -1;
    if (pipe2(p, O_CLOEXEC)) {
        test_fail(__FILE__, __LINE__, "pipe: %s", strerror(errno));
        return false;
    }
    *pid = fork();
    if (*pid == 0) {
        // The lamp code leaves signals the parent ignores ignored (nohup, or a
        // background job of a non-interactive shell ignores SIGHUP/SIGINT):
        // the child starts from the defaults, as from a terminal.
        for (size_t k = 0; k < sizeof fatal_signals / sizeof fatal_signals[0]; k++)
            signal(fatal_signals[k], SIG_DFL);
        sigset_t none;
        sigemptyset(&none);
        sigprocmask(SIG_SETMASK, &none, NULL);
        struct rlimit no_core = { 0, 0 };
        setrlimit(RLIMIT_CORE, &no_core);
        dup2(p[1], 1);
        execvp(c->argv[0], (char *const *)c->argv);
        _exit(127);
    }
    close(p[1]);
    if (*pid < 0) {
        close(p[0]);
        test_fail(__FILE__, __LINE__, "fork: %s", strerror(errno));
        return false;
    }
    char buf[256] = { 0 };
    size_t len = 0;
    double t0 = model_now_s();
    while (!strstr(buf, "ready") && model_now_s() - t0 < 10 && len + 1 < sizeof buf) {
        struct pollfd pf = { p[0], POLLIN, 0 };
        if (poll(&pf, 1, 100) <= 0) continue;
        ssize_t n = read(p[0], buf + len, sizeof buf - 1 - len);
        if (n <= 0) break;
        len += (size_t)n;
    }
    close(p[0]);
    bool ready = strstr(buf, "ready") != NULL;
    CHECK_MSG(ready, "child never printed ready (got \"%s\")", buf);
    if (!ready) {
        kill(*pid, SIGKILL);
        waitpid(*pid, NULL, 0);
    }
    return ready;
}

// The child's wait status once it ends (killed after 10 s).
static int wait_end(pid_t pid)
{
    int status = 0;
    double t0 = model_now_s();
    while (waitpid(pid, &status, WNOHANG) == 0) {
        if (model_now_s() - t0 > 10) {
            kill(pid, SIGKILL);
            waitpid(pid, &status, 0);
            test_fail(__FILE__, __LINE__, "child did not end");
            break;
        }
        usleep(5000);
    }
    return status;
}

// The default state file of the three lamps (named after chips and lines).
static const char *three_lamps_state(void)
{
    return test_path("state/refl/gpiod-gpiochip0-3-5-gpiochip1-2.state");
}

// Start the child (hold: then send sig; a fault mode: it faults by itself)
// with three lamps on, and check it died of sig with every lamp off: the
// gpiod lines at their OFF level (fake library's log) and the state file
// saying none is on.
static void check_death(int sig, const char *mode, bool sim)
{
    static const char *const sim_lamps[] = { "key=sim", "fill=sim", "back=sim", NULL };
    char state_env[PATH_MAX + 32];
    const char *state = sim ? test_path("sim-lamps.state") : three_lamps_state();
    snprintf(state_env, sizeof state_env, "LAMP_CHILD_STATE_FILE=%s", state);
    child_cmd_t c;
    if (!child_cmd(&c, "gpiochip0:32,gpiochip1:8", sim ? state_env : NULL, mode, "0x7",
                   sim ? sim_lamps : three_lamps))
        return;
    pid_t pid;
    if (!spawn_ready(&c, &pid)) return;

    char *log = read_log(c.log), *st = read_log(state);
    if (!sim) {
        CHECK(last_level(log, "gpiochip0", 3) == 1);   // on before the signal
        CHECK(last_level(log, "gpiochip0", 5) == 0);
        CHECK(last_level(log, "gpiochip1", 2) == 1);
    }
    CHECK_CONTAINS(st, "\non = key, fill, back\n");
    char pidline[32];
    snprintf(pidline, sizeof pidline, "\npid = %ld\n", (long)pid);
    CHECK_CONTAINS(st, pidline);
    free(log);
    free(st);

    if (!strcmp(mode, "hold")) kill(pid, sig);
    int status = wait_end(pid);
    CHECK_MSG(WIFSIGNALED(status) && WTERMSIG(status) == sig, "child status 0x%x, want killed by %d (%s)",
              status, sig, strsignal(sig));
    log = read_log(c.log);
    st = read_log(state);
    if (!sim) {
        CHECK(last_level(log, "gpiochip0", 3) == 0);   // off after the signal
        CHECK(last_level(log, "gpiochip0", 5) == 1);
        CHECK(last_level(log, "gpiochip1", 2) == 0);
    }
    CHECK_CONTAINS(st, "\non =\n");                     // and the state file says so
    free(log);
    free(st);
}

TEST_ALONE(lamps_gpiod_sigint_switches_off) { check_death(SIGINT, "hold", false); }
TEST_ALONE(lamps_gpiod_sigterm_switches_off) { check_death(SIGTERM, "hold", false); }
TEST(lamps_gpiod_sighup_switches_off) { check_death(SIGHUP, "hold", false); }
TEST(lamps_gpiod_sigquit_switches_off) { check_death(SIGQUIT, "hold", false); }
TEST(lamps_gpiod_sigsegv_switches_off) { check_death(SIGSEGV, "hold", false); }
TEST(lamps_gpiod_sigbus_switches_off) { check_death(SIGBUS, "hold", false); }
TEST(lamps_gpiod_sigfpe_switches_off) { check_death(SIGFPE, "hold", false); }
TEST(lamps_gpiod_sigabrt_switches_off) { check_death(SIGABRT, "hold", false); }
// Real faults, not sent signals.
TEST(lamps_gpiod_null_write_switches_off) { check_death(SIGSEGV, "segv", false); }
TEST(lamps_gpiod_bus_error_switches_off) { check_death(SIGBUS, "bus", false); }
TEST(lamps_gpiod_division_by_zero_switches_off) { check_death(SIGFPE, "fpe", false); }
TEST(lamps_gpiod_abort_switches_off) { check_death(SIGABRT, "abort", false); }

// A crash handler that was there before the safety net (a sanitizer's) still
// gets the crash, after the lamps are off.
TEST(lamps_gpiod_crash_reaches_the_previous_handler)
{
    const char *modes[] = { "segv", "abort" };
    for (int k = 0; k < 2; k++) {
        child_cmd_t c;
        if (!child_cmd(&c, "gpiochip0:32,gpiochip1:8", "LAMP_CHILD_CRASH_HANDLER=1", modes[k], "0x7", three_lamps))
            return;
        pid_t pid;
        if (!spawn_ready(&c, &pid)) return;
        int status = wait_end(pid);
        CHECK_MSG(WIFEXITED(status) && WEXITSTATUS(status) == 42, "%s: status 0x%x, want exit 42 from the "
                  "previous handler", modes[k], status);
        char *log = read_log(c.log), *st = read_log(three_lamps_state());
        CHECK(last_level(log, "gpiochip0", 3) == 0);
        CHECK(last_level(log, "gpiochip0", 5) == 1);
        CHECK(last_level(log, "gpiochip1", 2) == 0);
        CHECK_CONTAINS(st, "\non =\n");
        free(log);
        free(st);
    }
}

TEST(lamps_sim_every_signal_switches_off)
{
    for (size_t k = 0; k < sizeof fatal_signals / sizeof fatal_signals[0]; k++)
        check_death(fatal_signals[k], "hold", true);
    check_death(SIGSEGV, "segv", true);
}

TEST(lamps_gpiod_exit_switches_off)
{
    child_cmd_t c;
    if (!child_cmd(&c, "gpiochip0:32,gpiochip1:8", NULL, "exit", "0x7", three_lamps)) return;
    char *out = NULL;
    int rc = test_run(c.argv, 20, &out, NULL);
    CHECK(rc == 0);
    CHECK_CONTAINS(out, "ready");
    char *log = read_log(c.log);
    CHECK_CONTAINS(log, "set gpiochip0 3=1\nset gpiochip0 5=0\nset gpiochip1 2=1\n");
    CHECK(last_level(log, "gpiochip0", 3) == 0);
    CHECK(last_level(log, "gpiochip0", 5) == 1);
    CHECK(last_level(log, "gpiochip1", 2) == 0);
    free(log);
    free(out);
}

TEST(lamps_gpiod_set_failure_switches_all_off)
{
    // gpiochip0's lamps switch on, then gpiochip1 fails (unplugged): every
    // lamp must end off and the error name the lamp and chip.
    child_cmd_t c;
    if (!child_cmd(&c, "gpiochip0:32,gpiochip1:8", "FAKE_GPIO_FAIL_SET=2", "close", "0x7", three_lamps))
        return;
    char *err = NULL;
    int rc = test_run(c.argv, 20, NULL, &err);
    CHECK(rc == 3);
    CHECK_CONTAINS(err, "device disconnected");
    CHECK_CONTAINS(err, "cannot switch lamp 'back' on GPIO chip '/dev/gpiochip1'");
    CHECK_CONTAINS(err, "every lamp is switched off");
    char *log = read_log(c.log);
    CHECK_CONTAINS(log, "set gpiochip0 3=1\nset gpiochip0 5=0\nset gpiochip0 3=0\nset gpiochip0 5=1\n");
    CHECK(last_level(log, "gpiochip0", 3) == 0);
    CHECK(last_level(log, "gpiochip0", 5) == 1);
    CHECK(last_level(log, "gpiochip1", 2) == 0);
    CHECK(count_lines(log, "release ") == 3);
    free(log);
    free(err);
}

// Runs the child in "open" mode; returns its stderr (caller frees) and exit code.
static char *open_error(const char *chips, const char *extra_env, const char *const *lamps, int *rc,
                        char **log)
{
    child_cmd_t c;
    char *err = NULL;
    *rc = -1;
    if (!child_cmd(&c, chips, extra_env, "open", "0", lamps)) return calloc(1, 1);
    *rc = test_run(c.argv, 20, NULL, &err);
    if (log) *log = read_log(c.log);
    return err;
}

TEST(lamps_gpiod_error_missing_chip)
{
    static const char *const lamps[] = { "key=gpiochip3:1", NULL };
    int rc;
    char *err = open_error("gpiochip0:32", NULL, lamps, &rc, NULL);
    CHECK(rc == 3);
    CHECK_CONTAINS(err, "device not found");
    CHECK_CONTAINS(err, "lamp 'key': no GPIO chip 'gpiochip3'; is the board connected? ls /dev/gpiochip*");
    free(err);
}

TEST(lamps_gpiod_error_not_a_chip)
{
    char lamp_arg[PATH_MAX + 32];
    snprintf(lamp_arg, sizeof lamp_arg, "key=%s:1", test_write("notachip", "x\n"));
    const char *const lamps[] = { lamp_arg, NULL };
    int rc;
    char *err = open_error("gpiochip0:32", NULL, lamps, &rc, NULL);
    CHECK(rc == 3);
    CHECK_CONTAINS(err, "notachip' is not a GPIO chip");
    CHECK_CONTAINS(err, "/dev/gpiochipN");
    free(err);
}

TEST(lamps_gpiod_error_out_of_range_releases_others)
{
    // gpiochip0's line is requested first; the bad line on gpiochip1 must
    // leave it off and released.
    static const char *const lamps[] = { "key=gpiochip0:2", "back=gpiochip1:9", NULL };
    int rc;
    char *log = NULL;
    char *err = open_error("gpiochip0:32,gpiochip1:8", NULL, lamps, &rc, &log);
    CHECK(rc == 3);
    CHECK_CONTAINS(err, "invalid argument");
    CHECK_CONTAINS(err, "lamp 'back': line 9 is out of range on GPIO chip 'gpiochip1', which has 8 lines (0..7)");
    CHECK_CONTAINS(log, "request gpiochip0 2=0 consumer=refl\n");
    CHECK_CONTAINS(log, "release gpiochip0 2=0\n");
    CHECK(last_level(log, "gpiochip0", 2) == 0);
    CHECK(count_lines(log, "release ") == 1);
    free(err);
    free(log);
}

TEST(lamps_gpiod_error_busy_line)
{
    static const char *const lamps[] = { "key=gpiochip0:4", "fill=gpiochip0:5", NULL };
    int rc;
    char *log = NULL;
    char *err = open_error("gpiochip0:32", "FAKE_GPIO_BUSY=5", lamps, &rc, &log);
    CHECK(rc == 3);
    CHECK_CONTAINS(err, "device busy");
    CHECK_CONTAINS(err, "lamp 'fill' (GPIO chip 'gpiochip0' line 5) is busy: held by 'other-app'");
    CHECK(count_lines(log, "request ") == 0);   // the bulk request is all or nothing
    free(err);
    free(log);
}

TEST(lamps_gpiod_error_permission)
{
    static const char *const lamps[] = { "key=gpiochip0:4", NULL };
    int rc;
    char *err = open_error("gpiochip0:32", "FAKE_GPIO_EACCES=1", lamps, &rc, NULL);
    CHECK(rc == 3);
    CHECK_CONTAINS(err, "permission denied");
    CHECK_CONTAINS(err, "lamp 'key': permission denied opening GPIO chip 'gpiochip0'");
    CHECK_CONTAINS(err, "usermod -aG gpio");
    CHECK_CONTAINS(err, "udev rule");
    free(err);
}

TEST_ALONE(lamps_gpiod_error_same_line_twice)
{
    static const char *const lamps[] = { "key=gpiochip0:4", "fill=gpiochip0:4", NULL };
    int rc;
    char *log = NULL;
    char *err = open_error("gpiochip0:32", NULL, lamps, &rc, &log);
    CHECK(rc == 3);
    CHECK_CONTAINS(err, "lamps 'key' and 'fill' both use line 4 of GPIO chip 'gpiochip0'");
    CHECK(count_lines(log, "request ") == 0);
    free(err);
    free(log);
}

// ---------------------------------------------------------------------------
// The lamp-state file (rig/lamps/state.c): deaths no handler sees

// kill -9 with lamps on leaves the state file naming them; the next open of
// the same lamps reports the dead session, switches them off and clears it.
static void check_kill9(bool sim)
{
    static const char *const sim_lamps[] = { "key=sim", "fill=sim", "back=sim", NULL };
    const char *const *lamps = sim ? sim_lamps : three_lamps;
    char state_env[PATH_MAX + 32];
    const char *state = sim ? test_path("sim-lamps.state") : three_lamps_state();
    snprintf(state_env, sizeof state_env, "LAMP_CHILD_STATE_FILE=%s", state);
    child_cmd_t c;
    if (!child_cmd(&c, "gpiochip0:32,gpiochip1:8", sim ? state_env : NULL, "hold", "0x5", lamps)) return;
    pid_t pid;
    if (!spawn_ready(&c, &pid)) return;
    kill(pid, SIGKILL);
    int status = wait_end(pid);
    CHECK(WIFSIGNALED(status) && WTERMSIG(status) == SIGKILL);
    char *st = read_log(state);
    CHECK_CONTAINS(st, "\non = key, back\n");            // left behind: no handler ran
    free(st);

    if (!child_cmd(&c, "gpiochip0:32,gpiochip1:8", sim ? state_env : NULL, "open", "0", lamps)) return;
    char *err = NULL;
    int rc = test_run(c.argv, 20, NULL, &err);
    CHECK_MSG(rc == 0, "exit %d, stderr: %s", rc, err);
    char want[160];
    snprintf(want, sizeof want, "refl: warning: the last session (pid %ld, started 20", (long)pid);
    CHECK_CONTAINS(err, want);
    CHECK_CONTAINS(err, "died with lamps key, back on; switching them off\n");
    free(err);
    if (!sim) {
        // Requested off, and switched off explicitly once found.
        char *log = read_log(c.log);
        CHECK_CONTAINS(log, "request gpiochip0 3=0 consumer=refl\n");
        CHECK(count_lines(log, "set gpiochip0 3=0") >= 1);
        CHECK(count_lines(log, "set gpiochip1 2=0") >= 1);
        CHECK(last_level(log, "gpiochip0", 3) == 0);
        CHECK(last_level(log, "gpiochip0", 5) == 1);
        CHECK(last_level(log, "gpiochip1", 2) == 0);
        free(log);
    }
    st = read_log(state);
    CHECK_CONTAINS(st, "\non =\n");                      // cleared
    free(st);

    // Once cleared, the next open has nothing to say.
    rc = test_run(c.argv, 20, NULL, &err);
    CHECK(rc == 0);
    CHECK(err && !strstr(err, "last session"));
    free(err);
}

TEST(lamps_gpiod_kill9_state_file_next_open_switches_off) { check_kill9(false); }
TEST(lamps_sim_kill9_state_file_next_open_switches_off) { check_kill9(true); }

// A state file cut short (a power cut while writing it): every lamp off, said so.
TEST(lamps_gpiod_unreadable_state_file_switches_all_off)
{
    child_cmd_t c;
    if (!child_cmd(&c, "gpiochip0:32,gpiochip1:8", NULL, "open", "0", three_lamps)) return;
    char dir[PATH_MAX + 16];
    snprintf(dir, sizeof dir, "%s/state/refl", test_tmpdir());
    CHECK(model_mkdir_p(dir));
    FILE *f = fopen(three_lamps_state(), "w");
    if (f) {
        fputs("# refl lamp state\npid = 4242\nstarted = 2026-11-24T23:00:00.000Z\nhardw", f);
        fclose(f);
    }
    char *err = NULL;
    int rc = test_run(c.argv, 20, NULL, &err);
    CHECK_MSG(rc == 0, "exit %d, stderr: %s", rc, err);
    CHECK_CONTAINS(err, "is unreadable (the last session, pid 4242, started 2026-11-24T23:00:00.000Z, may have "
                        "died while writing it); switching every lamp off");
    free(err);
    char *st = read_log(three_lamps_state());
    CHECK_CONTAINS(st, "\non =\n");
    free(st);
}

// A live refl holding the lamps is not taken for a dead one: a second open
// fails naming it, switches nothing and leaves its record alone.
TEST_ALONE(lamps_gpiod_live_holder_is_not_dead)
{
    child_cmd_t b, a;
    char log_b[PATH_MAX + 32];
    snprintf(log_b, sizeof log_b, "FAKE_GPIO_LOG=%s", test_path("gpio-b.log"));
    if (!child_cmd(&b, "gpiochip0:32,gpiochip1:8", log_b, "open", "0", three_lamps)) return;
    if (!child_cmd(&a, "gpiochip0:32,gpiochip1:8", NULL, "hold", "0x7", three_lamps)) return;
    pid_t pid;
    if (!spawn_ready(&a, &pid)) return;

    char *err = NULL;
    int rc = test_run(b.argv, 20, NULL, &err);
    CHECK(rc == 3);
    char want[160];
    snprintf(want, sizeof want, "these lamps are in use by another refl (pid %ld, started 20", (long)pid);
    CHECK_CONTAINS(err, want);
    CHECK_CONTAINS(err, "device busy");
    CHECK(err && !strstr(err, "last session") && !strstr(err, "switching"));
    free(err);
    CHECK(kill(pid, 0) == 0);                            // still running, lamps still on
    char *log = read_log(a.log), *st = read_log(three_lamps_state());
    CHECK(last_level(log, "gpiochip0", 3) == 1);
    CHECK(last_level(log, "gpiochip1", 2) == 1);
    CHECK_CONTAINS(st, "\non = key, fill, back\n");
    char pidline[32];
    snprintf(pidline, sizeof pidline, "\npid = %ld\n", (long)pid);
    CHECK_CONTAINS(st, pidline);
    free(log);
    free(st);

    // Once it has ended (SIGTERM: lamps off, record cleared) the lamps open.
    kill(pid, SIGTERM);
    wait_end(pid);
    rc = test_run(b.argv, 20, NULL, &err);
    CHECK_MSG(rc == 0, "exit %d, stderr: %s", rc, err);
    CHECK(err && !strstr(err, "last session"));
    free(err);
}

// The rig file's [lamps] state_file puts the file there (sim lamps too), and
// [lamps] takes no other key.
TEST(lamps_rig_file_state_file_key)
{
    char text[PATH_MAX + 256];
    const char *state = test_path("rig-lamps.state");
    snprintf(text, sizeof text, "[turntable]\nbackend = sim\ntime_scale = 0.001\n"
             "[lamp east]\nbackend = sim\nposition_mm = 0 0 100\n[lamps]\nstate_file = %s\n", state);
    const char *rig = test_write("rig.ini", text);
    const char *argv[] = { test_refl(), "rig", "--rig", rig, "status", NULL };
    char *out = NULL, *err = NULL;
    int rc = test_run(argv, 60, &out, &err);
    CHECK_MSG(rc == 0, "exit %d, stderr: %s", rc, err);
    char *st = read_log(state);
    CHECK_CONTAINS(st, "\nhardware = sim east\non =\n");
    free(st);
    free(out);
    free(err);

    // relative to the rig file's directory
    snprintf(text, sizeof text, "[lamp east]\nbackend = sim\nposition_mm = 0 0 100\n[lamps]\nstate_file = rel.state\n");
    argv[3] = test_write("rel.ini", text);
    rc = test_run(argv, 60, &out, &err);
    CHECK_MSG(rc == 0, "exit %d, stderr: %s", rc, err);
    st = read_log(test_path("rel.state"));
    CHECK_CONTAINS(st, "\nhardware = sim east\non =\n");
    free(st);
    free(out);
    free(err);

    const char *bad = test_write("bad.ini", "[lamp east]\nbackend = sim\nposition_mm = 0 0 100\n"
                                            "[lamps]\nstate_fil = x\n");
    argv[3] = bad;
    rc = test_run(argv, 60, &out, &err);
    CHECK(rc == 1);
    CHECK_CONTAINS(err, "bad.ini:5: [lamps]: unknown key 'state_fil'; known keys: state_file");
    free(out);
    free(err);
}

// The lamp-state file names its format (format_version = 1); a file of a
// higher version is refused (the lamps stay closed, the file as it was); a
// file without the key reads as version 1.
TEST(lamps_state_file_newer_version_refused)
{
    static const rig_lamp_line_t lamps[] = { { .name = "key" }, { .name = "fill" } };
    const char *state = test_path("lamps.state");
    rig_lamps_t *l = NULL;
    CHECK(rig_lamps_open_sim_state(&l, lamps, 2, state) == 0);
    rig_lamps_close(l);
    char *st = model_read_file(state, NULL);
    CHECK_CONTAINS(st, "\nformat_version = 1\npid = ");
    free(st);

    const char *newer = "format_version = 2\npid = 1\nstarted = 2030-01-01T00:00:00.000Z\non = key\n";
    test_write("lamps.state", newer);
    l = NULL;
    CHECK(rig_lamps_open_sim_state(&l, lamps, 2, state) == RIG_ERR_PROTOCOL);
    CHECK(l == NULL);
    CHECK_CONTAINS(model_last_error(), "lamps.state has format_version 2, written by a newer refl (this refl reads "
                                       "version 1)");
    st = model_read_file(state, NULL);
    CHECK(st && !strcmp(st, newer));
    free(st);

    test_write("lamps.state", "pid = 1\nstarted = 2030-01-01T00:00:00.000Z\non =\n");   // version 1, all off
    CHECK(rig_lamps_open_sim_state(&l, lamps, 2, state) == 0);
    rig_lamps_close(l);
}
