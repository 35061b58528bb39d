// tests/test_rig_turntable.c — the turntable: errors, stage table, motion time,
// the simulated stage, and the unmodified APT driver against a simulated
// FTDI + APT controller (tests/apt_sim.c) under umockdev; Ctrl-C (SIGINT)
// during homing and moves, in-process and through refl capture.
//
// The APT tests (apt_umock_*) need libumockdev-preload loaded at process
// start, so turntable_apt_under_umockdev re-runs this test binary as
// `umockdev-wrapper <self> apt_umock_`; run directly, the apt_umock_* tests
// are left to it (TEST_INNER: neither run nor counted outside umockdev).
#define _GNU_SOURCE
#include <fcntl.h>
#include <glib.h>
#include <limits.h>
#include <signal.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include "model/model.h"
#include "rig/internal.h"   // a backend of our own: an ops table without optional operations
#include "rig/rig.h"
#include "tests/apt_sim.h"
#include "tests/fixtures.h"
#include "tests/test.h"

static void sleep_s(double s)
{
    struct timespec ts = { (time_t)s, (long)((s - (time_t)s) * 1e9) };
    nanosleep(&ts, NULL);
}

// ---------------------------------------------------------------------------
// Errors, stage models, motion time

TEST(turntable_strerror_and_fail)
{
    CHECK(strcmp(rig_strerror(RIG_ERR_OK), "success") == 0);
    CHECK(strcmp(rig_strerror(RIG_ERR_TIMEOUT), "timed out") == 0);
    CHECK(strcmp(rig_strerror(RIG_ERR_DISCONNECTED), "device disconnected") == 0);
    CHECK(strcmp(rig_strerror(-999), "unknown error") == 0);
    CHECK(rig_fail(RIG_ERR_LIMIT, "stage %s at %d", "X", 3) == RIG_ERR_LIMIT);
    CHECK(strcmp(model_last_error(), "stage X at 3") == 0);
    CHECK(strcmp(model_last_error(), "stage X at 3") == 0);
}

TEST(turntable_stage_models)
{
    int n = 0;
    bool k10 = false, prm = false;
    for (const rig_stage_model_t *m = rig_stage_models; m->model; m++, n++) {
        CHECK(m->counts_per_deg > 0 && m->max_speed_deg_s > 0 && m->accel_deg_s2 > 0);
        if (strcmp(m->model, "K10CR1") == 0) {
            k10 = true;
            CHECK_NEAR(m->counts_per_deg, 136533.33, 1e-9);
            CHECK_NEAR(m->max_speed_deg_s, 10, 0);
            CHECK_NEAR(m->accel_deg_s2, 10, 0);
        }
        if (strcmp(m->model, "PRM1-Z8") == 0) {
            prm = true;
            CHECK_NEAR(m->counts_per_deg, 1919.64, 1e-9);
        }
    }
    CHECK(k10 && prm && n < 50);
}

TEST(turntable_motion_time)
{
    // trapezoid: 90 deg at 10 deg/s, 10 deg/s^2 -> 1 s up, 8 s cruise, 1 s down
    CHECK_NEAR(rig_motion_time_s(90, 10, 10), 10.0, 1e-12);
    CHECK_NEAR(rig_motion_time_s(-90, 10, 10), 10.0, 1e-12);
    // triangle: 0.5 deg never reaches cruise: 2 sqrt(d/a)
    CHECK_NEAR(rig_motion_time_s(0.5, 10, 10), 2 * sqrt(0.05), 1e-12);
    // the two branches meet at d = v^2/a
    CHECK_NEAR(rig_motion_time_s(10, 10, 10), 2.0, 1e-12);
    CHECK_NEAR(rig_motion_time_s(10 - 1e-9, 10, 10), 2.0, 1e-6);
    CHECK_NEAR(rig_motion_time_s(0, 10, 10), 0.0, 0);
    CHECK(isnan(rig_motion_time_s(1, 0, 10)));
    CHECK(isnan(rig_motion_time_s(1, 10, -1)));
    CHECK(isnan(rig_motion_time_s(NAN, 10, 10)));
}

// ---------------------------------------------------------------------------
// Simulated stage

// fx_fast_sim() (tests/fixtures.h): 10 s of stage time = 0.1 s.

TEST_ALONE(turntable_sim_home_move_timing)
{
    rig_turntable_sim_params_t p = fx_fast_sim();
    rig_turntable_t *t = NULL;
    rig_turntable_status_t st;
    rig_turntable_info_t info;
    CHECK(rig_turntable_open_sim(&t, &p) == 0);
    if (!t) return;
    CHECK(rig_turntable_info(t, &info) == 0);
    CHECK_NEAR(info.counts_per_deg, 136533.33, 1e-9);
    CHECK(rig_turntable_status(t, &st) == 0 && !st.homed && !st.moving);
    double t0 = model_now_s();
    CHECK(rig_turntable_home(t, 1.0) == 0);
    CHECK_NEAR(model_now_s() - t0, 5 * 0.01, 0.02);
    CHECK(rig_turntable_status(t, &st) == 0 && st.homed && !st.moving);
    CHECK_NEAR(st.angle_deg, 0, 0);

    // 90 deg: rig_motion_time_s = 10 s of stage time = 0.1 s real
    t0 = model_now_s();
    CHECK(rig_turntable_move_abs_deg(t, 90, 1.0) == 0);
    double dt = model_now_s() - t0;
    CHECK_NEAR(dt, rig_motion_time_s(90, 10, 10) * 0.01, 0.02);
    CHECK(rig_turntable_status(t, &st) == 0 && !st.moving && !st.motion_error);
    CHECK_NEAR(st.angle_deg, 90, 5 * 0.001);

    // status while moving is computed from the clock: back to 0, half way
    // (5 s stage time) the stage is at 90 - (0.5*10*1^2 + 10*4) = 45 deg
    CHECK(rig_turntable_start_move_abs_deg(t, 0) == 0);
    t0 = model_now_s();
    sleep_s(0.05);
    double el = (model_now_s() - t0) / 0.01;
    CHECK(rig_turntable_status(t, &st) == 0 && st.moving && st.homed);
    double expect = 90 - (el <= 1 ? 5 * el * el : 5 + 10 * (el - 1));
    CHECK_NEAR(st.angle_deg, expect, 2.0);
    CHECK(rig_turntable_wait(t, 1.0) == 0);
    CHECK(rig_turntable_status(t, &st) == 0 && !st.moving);
    CHECK_NEAR(st.angle_deg, 0, 5 * 0.001);
    rig_turntable_close(t);
}

TEST_ALONE(turntable_sim_relative_and_stop)
{
    rig_turntable_sim_params_t p = fx_fast_sim();
    p.position_noise_deg = 0;
    rig_turntable_t *t = NULL;
    rig_turntable_status_t st;
    CHECK(rig_turntable_open_sim(&t, &p) == 0);
    if (!t) return;
    CHECK(rig_turntable_home(t, 1.0) == 0);
    CHECK(rig_turntable_move_abs_deg(t, 90, 1.0) == 0);
    CHECK(rig_turntable_move_rel_deg(t, -30, 1.0) == 0);
    CHECK(rig_turntable_status(t, &st) == 0);
    CHECK_NEAR(st.angle_deg, 60, 1e-9);

    // immediate stop: the stage stays where it was
    CHECK(rig_turntable_start_move_abs_deg(t, 360) == 0);   // 30 s of stage time
    sleep_s(0.05);
    CHECK(rig_turntable_stop(t, true) == 0);
    CHECK(rig_turntable_status(t, &st) == 0 && !st.moving);
    double p1 = st.angle_deg;
    CHECK(p1 > 60 + 20 && p1 < 360);
    sleep_s(0.02);
    CHECK(rig_turntable_status(t, &st) == 0);
    CHECK_NEAR(st.angle_deg, p1, 0);
    CHECK(rig_turntable_wait(t, 0.5) == 0);                  // nothing to wait for

    // profiled stop at cruise (10 deg/s, 10 deg/s^2): v^2/(2a) = 5 deg further
    CHECK(rig_turntable_start_move_abs_deg(t, p1 - 300) == 0);
    sleep_s(0.05);                                           // 5 s: cruising
    CHECK(rig_turntable_status(t, &st) == 0 && st.moving);
    double at_stop = st.angle_deg;
    double t0 = model_now_s();
    CHECK(rig_turntable_stop(t, false) == 0);
    CHECK_NEAR(model_now_s() - t0, 1.0 * 0.01, 0.01);        // v/a = 1 s of stage time
    CHECK(rig_turntable_status(t, &st) == 0 && !st.moving);
    CHECK_NEAR(st.angle_deg, at_stop - 5, 0.5);              // a few ms between status and stop
    rig_turntable_close(t);
}

TEST_ALONE(turntable_sim_faults)
{
    rig_turntable_sim_params_t p = fx_fast_sim();
    rig_turntable_t *t = NULL;
    rig_turntable_status_t st;

    // motion error on the 2nd move, half way
    p.fault_after_moves = 1;
    p.fault = RIG_ERR_MOTION;
    CHECK(rig_turntable_open_sim(&t, &p) == 0);
    if (!t) return;
    CHECK(rig_turntable_home(t, 1.0) == 0);
    CHECK(rig_turntable_move_abs_deg(t, 10, 1.0) == 0);
    CHECK(rig_turntable_move_abs_deg(t, 100, 1.0) == RIG_ERR_MOTION);
    CHECK_CONTAINS(model_last_error(), "motion error");
    CHECK_CONTAINS(model_last_error(), "sim turntable");
    CHECK(rig_turntable_status(t, &st) == 0 && st.motion_error && !st.moving);
    CHECK_NEAR(st.angle_deg, 55, 1.0);                       // stopped half way (symmetric profile)
    CHECK(rig_turntable_move_abs_deg(t, 0, 1.0) == 0);       // the fault fires once
    CHECK(rig_turntable_status(t, &st) == 0 && !st.motion_error);
    rig_turntable_close(t);

    // stall: wait times out, without hanging
    p.fault_after_moves = 1;
    p.fault = RIG_ERR_TIMEOUT;
    CHECK(rig_turntable_open_sim(&t, &p) == 0);
    CHECK(rig_turntable_home(t, 1.0) == 0);
    CHECK(rig_turntable_move_abs_deg(t, 10, 1.0) == 0);
    double t0 = model_now_s();
    CHECK(rig_turntable_move_abs_deg(t, 100, 0.3) == RIG_ERR_TIMEOUT);
    CHECK_NEAR(model_now_s() - t0, 0.3, 0.05);
    CHECK_CONTAINS(model_last_error(), "did not finish within 0.30 s");
    CHECK(rig_turntable_status(t, &st) == 0 && st.moving);
    CHECK(rig_turntable_stop(t, true) == 0);
    CHECK(rig_turntable_status(t, &st) == 0 && !st.moving);
    rig_turntable_close(t);

    // disconnection mid-move
    p.fault_after_moves = 2;
    p.fault = RIG_ERR_DISCONNECTED;
    CHECK(rig_turntable_open_sim(&t, &p) == 0);
    CHECK(rig_turntable_home(t, 1.0) == 0);
    CHECK(rig_turntable_move_abs_deg(t, 10, 1.0) == 0);
    CHECK(rig_turntable_move_abs_deg(t, 20, 1.0) == 0);
    CHECK(rig_turntable_move_abs_deg(t, 30, 1.0) == RIG_ERR_DISCONNECTED);
    CHECK_CONTAINS(model_last_error(), "disconnected");
    CHECK(rig_turntable_status(t, &st) == RIG_ERR_DISCONNECTED);
    CHECK(rig_turntable_home(t, 1.0) == RIG_ERR_DISCONNECTED);
    rig_turntable_close(t);
}

TEST_ALONE(turntable_sim_bad_input)
{
    rig_turntable_sim_params_t p = fx_fast_sim();
    rig_turntable_t *t = NULL;
    rig_turntable_status_t st;
    p.time_scale = 0;
    CHECK(rig_turntable_open_sim(&t, &p) == RIG_ERR_INVALID && t == NULL);
    CHECK_CONTAINS(model_last_error(), "time_scale");
    p = fx_fast_sim();
    p.fault_after_moves = 1;
    p.fault = RIG_ERR_IO;
    CHECK(rig_turntable_open_sim(&t, &p) == RIG_ERR_INVALID);
    CHECK_CONTAINS(model_last_error(), "fault must be");
    p = fx_fast_sim();
    CHECK(rig_turntable_open_sim(&t, &p) == 0);
    if (!t) return;
    CHECK(rig_turntable_move_abs_deg(t, 10, 1.0) == RIG_ERR_NOT_HOMED);
    CHECK_CONTAINS(model_last_error(), "home it first");
    CHECK(rig_turntable_home(t, 1.0) == 0);
    CHECK(rig_turntable_move_abs_deg(t, NAN, 1.0) == RIG_ERR_INVALID);
    CHECK_CONTAINS(model_last_error(), "not a finite angle");
    CHECK(rig_turntable_move_abs_deg(t, 10, 0) == RIG_ERR_INVALID);
    CHECK_CONTAINS(model_last_error(), "time-out 0 s");
    CHECK(rig_turntable_move_rel_deg(t, INFINITY, 1.0) == RIG_ERR_INVALID);
    CHECK(rig_turntable_status(t, &st) == 0 && st.angle_deg == 0 && !st.moving);
    CHECK(rig_turntable_status(NULL, &st) == RIG_ERR_INVALID);
    CHECK(rig_turntable_status(t, NULL) == RIG_ERR_INVALID);
    rig_turntable_close(t);
    rig_turntable_close(NULL);

    // an ops table without optional operations
    static const rig_turntable_ops_t none = { .backend = "none" };
    rig_turntable_t bare = { .ops = &none, .name = "bare stage" };
    CHECK(rig_turntable_home(&bare, 1.0) == RIG_ERR_NOT_SUPPORTED);
    CHECK_CONTAINS(model_last_error(), "bare stage: homing is not supported by the none backend");
    CHECK(rig_turntable_stop(&bare, true) == RIG_ERR_NOT_SUPPORTED);
}

// ---------------------------------------------------------------------------
// Interruptible waits (rig_turntable_wait_watched): the progress callback
// plays the operator, raising the interrupt level at given times.

typedef struct {
    volatile sig_atomic_t flag;
    double at1_s, at2_s;          // elapsed seconds at which flag becomes 1, 2 (<= 0: never)
    double t1_s, t2_s;            // model_now_s() when it did
    int    calls;
    double angle1;                // the angle when flag became 1
} interrupter_t;

static void interrupter(void *ctx, double elapsed_s, double angle_deg)
{
    interrupter_t *it = ctx;
    it->calls++;
    if (it->at1_s > 0 && elapsed_s >= it->at1_s && it->flag < 1) {
        it->flag = 1;
        it->angle1 = angle_deg;
        it->t1_s = model_now_s();
    }
    if (it->at2_s > 0 && elapsed_s >= it->at2_s && it->flag < 2) {
        it->flag = 2;
        it->t2_s = model_now_s();
    }
}

static rig_turntable_watch_t watch_of(interrupter_t *it, const char *what)
{
    return (rig_turntable_watch_t){ .interrupt = &it->flag, .what = what, .stop_s = 5, .progress = interrupter,
                                    .ctx = it, .period_s = 0 };
}

TEST_ALONE(turntable_sim_watched_homing_interrupted)
{
    rig_turntable_sim_params_t p = fx_fast_sim();
    p.time_scale = 0.1;
    p.home_time_s = 30;                       // 3 s real
    rig_turntable_t *t = NULL;
    CHECK(rig_turntable_open_sim(&t, &p) == 0);
    if (!t) return;
    interrupter_t it = { .at1_s = 0.2 };
    rig_turntable_watch_t w = watch_of(&it, "homing");
    double t0 = model_now_s();
    CHECK(rig_turntable_start_home(t) == 0);
    CHECK(rig_turntable_wait_watched(t, 10, &w) == RIG_ERR_INTERRUPTED);
    CHECK_MSG(model_now_s() - it.t1_s < 0.3, "stood %.2f s after the interrupt", model_now_s() - it.t1_s);
    CHECK(model_now_s() - t0 < 1.0);
    CHECK_CONTAINS(model_last_error(), "homing interrupted: the stage stopped at ");
    rig_turntable_status_t st;
    CHECK(rig_turntable_status(t, &st) == 0 && !st.moving && !st.homed);
    // uninterrupted, it homes; the progress callback is called on the way
    interrupter_t quiet = { 0 };
    w = watch_of(&quiet, "homing");
    CHECK(rig_turntable_start_home(t) == 0);
    CHECK(rig_turntable_wait_watched(t, 10, &w) == 0);
    CHECK(quiet.calls > 10);
    CHECK(rig_turntable_status(t, &st) == 0 && st.homed && !st.moving);
    rig_turntable_close(t);
}

TEST_ALONE(turntable_sim_watched_move_interrupted)
{
    rig_turntable_sim_params_t p = fx_fast_sim();
    p.time_scale = 0.1;
    p.speed_deg_s = 10;
    p.accel_deg_s2 = 2;                       // a profiled stop from cruise: 5 s sim = 0.5 s real, 25 deg
    p.position_noise_deg = 0;
    rig_turntable_t *t = NULL;
    CHECK(rig_turntable_open_sim(&t, &p) == 0);
    if (!t) return;
    CHECK(rig_turntable_home(t, 5) == 0);
    rig_turntable_status_t st;

    // One interrupt at cruise: a profiled stop, 25 deg further, 0.5 s.
    interrupter_t it = { .at1_s = 1.2 };      // 12 s sim: cruising since 5 s
    rig_turntable_watch_t w = watch_of(&it, "the move to 300 deg");
    CHECK(rig_turntable_start_move_abs_deg(t, 300) == 0);
    CHECK(rig_turntable_wait_watched(t, 30, &w) == RIG_ERR_INTERRUPTED);
    double took = model_now_s() - it.t1_s;
    CHECK_MSG(took > 0.4 && took < 0.8, "the profiled stop took %.2f s", took);
    CHECK_CONTAINS(model_last_error(), "the move to 300 deg interrupted: the stage stopped at ");
    CHECK(rig_turntable_status(t, &st) == 0 && !st.moving);
    CHECK_NEAR(st.angle_deg, it.angle1 + 25, 3);

    // A second interrupt 0.1 s into that stop: it stands at once.
    double from = st.angle_deg;
    interrupter_t it2 = { .at1_s = 1.2, .at2_s = 1.3 };
    w = watch_of(&it2, "the move back");
    CHECK(rig_turntable_start_move_abs_deg(t, from - 250) == 0);
    CHECK(rig_turntable_wait_watched(t, 30, &w) == RIG_ERR_INTERRUPTED);
    took = model_now_s() - it2.t2_s;
    CHECK_MSG(took < 0.15, "the immediate stop took %.2f s", took);
    CHECK_CONTAINS(model_last_error(), "the move back interrupted: the stage stopped at once at ");
    CHECK(rig_turntable_status(t, &st) == 0 && !st.moving);
    CHECK(st.angle_deg < from - 50 && st.angle_deg > from - 250);

    // Not interrupted, a time-out names the motion
    interrupter_t none = { 0 };
    w = watch_of(&none, "the move to 0 deg");
    CHECK(rig_turntable_start_move_abs_deg(t, 0) == 0);
    CHECK(rig_turntable_wait_watched(t, 0.2, &w) == RIG_ERR_TIMEOUT);
    CHECK_CONTAINS(model_last_error(), "the move to 0 deg did not finish within 0.20 s");
    rig_turntable_stop(t, true);
    rig_turntable_close(t);
}

// ---------------------------------------------------------------------------
// Ctrl-C in refl capture during homing and moves (the virtual rig in real time)

// A rig file for the virtual rig in real time whose truth is the example's
// with the edits (pairs "old line", "new line") and the files it names linked.
static const char *realtime_rig(const char *const *edits)
{
    char top[PATH_MAX];
    if (!realpath(test_srcdir(), top)) snprintf(top, sizeof top, "%s", test_srcdir());
    char src[PATH_MAX + 64];
    snprintf(src, sizeof src, "%s/examples/virtual-truth.ini", top);
    char *text = model_read_file(src, NULL);
    if (!text) return NULL;
    GString *g = g_string_new(text);
    free(text);
    for (int i = 0; edits && edits[i]; i += 2) {
        char *at = strstr(g->str, edits[i]);
        CHECK_MSG(at != NULL, "no \"%s\" in the example truth", edits[i]);
        if (!at) continue;
        gssize pos = at - g->str;
        g_string_erase(g, pos, (gssize)strlen(edits[i]));
        g_string_insert(g, pos, edits[i + 1]);
    }
    const char *truth = test_write("truth.ini", g->str);
    g_string_free(g, TRUE);
    const char *links[] = { "camera.cameramodel", "samples", "t_stiffener.d3d" };
    for (int i = 0; i < 3; i++) {
        char a[PATH_MAX + 64], b[PATH_MAX + 64];
        snprintf(a, sizeof a, "%s/examples/%s", top, links[i]);
        snprintf(b, sizeof b, "%s/%s", test_tmpdir(), links[i]);
        symlink(a, b);
    }
    char rig[PATH_MAX + 128];
    snprintf(rig, sizeof rig, "[rig]\nbackend = virtual\ntruth = %s\ntime_scale = 1\nbusy_wait_s = 60\n", truth);
    return test_write("rig.ini", rig);
}

// refl ARGS with stderr to err_path (stdout dropped); the pid.
static pid_t spawn_refl(const char *const *args, const char *err_path)
{
    const char *argv[32];
    int n = 0;
    argv[n++] = test_refl();
    for (int i = 0; args[i] && n < 31; i++) argv[n++] = args[i];
    argv[n] = NULL;
    pid_t pid = fork();
    if (pid == 0) {
        signal(SIGINT, SIG_DFL);
        int null = open("/dev/null", O_WRONLY), e = open(err_path, O_WRONLY | O_CREAT | O_TRUNC, 0644);
        dup2(null, 1);
        dup2(e, 2);
        execv(argv[0], (char *const *)argv);
        _exit(127);
    }
    return pid;
}

static char *file_text(const char *path)
{
    bool q = model_error_quiet(true);
    char *t = model_read_file(path, NULL);
    model_error_quiet(q);
    return t ? t : calloc(1, 1);
}

// Waits (up to limit_s) until the file holds needle, or exists when needle is NULL.
static bool wait_for(const char *path, const char *needle, double limit_s)
{
    for (double t0 = model_now_s(); model_now_s() - t0 < limit_s; sleep_s(0.02)) {
        struct stat st;
        if (!needle && stat(path, &st) == 0) return true;
        if (needle) {
            char *t = file_text(path);
            bool found = strstr(t, needle) != NULL;
            free(t);
            if (found) return true;
        }
    }
    CHECK_MSG(false, "waited %.0f s for %s%s%s", limit_s, path, needle ? " to say " : " to exist",
              needle ? needle : "");
    return false;
}

// The wait status, or -1 when pid does not end within limit_s (then killed).
static int wait_pid(pid_t pid, double limit_s, double *ended)
{
    int st = 0;
    for (double t0 = model_now_s(); model_now_s() - t0 < limit_s; sleep_s(0.005))
        if (waitpid(pid, &st, WNOHANG) == pid) {
            *ended = model_now_s();
            return st;
        }
    kill(pid, SIGKILL);
    waitpid(pid, &st, 0);
    *ended = model_now_s();
    return -1;
}

// The first Ctrl-C during homing (15 s on this stage) stops it within 1 s and
// pauses the session (exit 3) saying so; no frame was being taken.
TEST_ALONE(capture_ctrl_c_during_homing)
{
    int lk = test_camera_lock();
    const char *rig = realtime_rig(NULL);
    const char *plan = test_write("plan.ini", "[sample]\nname = coupon_matte_paint\nkind = material_coupon\n"
                                  "[angles]\nlist = 0 90\n[lamps]\nsets = east\n[exposure]\nmode = fixed\n"
                                  "list_us = 1000\n");
    char dir[PATH_MAX], frames[PATH_MAX + 16];
    snprintf(dir, sizeof dir, "%s/s", test_tmpdir());
    snprintf(frames, sizeof frames, "%s/frames", dir);
    const char *err_path = test_path("err.txt");
    const char *args[] = { "capture", plan, "--rig", rig, "-o", dir, "--yes", NULL };
    pid_t pid = spawn_refl(args, err_path);
    if (rig && wait_for(err_path, "refl capture: homing", 60)) {
        sleep_s(0.5);
        double t_int = model_now_s(), ended;
        kill(pid, SIGINT);
        int st = wait_pid(pid, 10, &ended);
        CHECK_MSG(ended - t_int < 1.0, "ended %.2f s after Ctrl-C", ended - t_int);
        CHECK_MSG(st >= 0 && WIFEXITED(st) && WEXITSTATUS(st) == 3, "status 0x%x, want exit 3", st);
        char *err = file_text(err_path);
        CHECK_CONTAINS(err, "(up to 15 s; Ctrl-C stops it)");
        CHECK_CONTAINS(err, "refl capture: interrupted (SIGINT) during homing: no frame was being taken; "
                            "virtual turntable (sim, seed 1): homing interrupted: the stage stopped at ");
        // the operator's step first (nothing moves while the sample is set up), then homing
        CHECK_CONTAINS(err, "session paused before step 1 of 3; continue with refl capture --resume");
        const char *op = strstr(err, "operator step 0 done"), *home = strstr(err, "refl capture: homing");
        CHECK_MSG(op && home && op < home, "the operator step is answered before homing:\n%s", err);
        CHECK_CONTAINS(err, "(it homes the stage again)");
        CHECK(!strstr(err, "the current frame was finished"));
        free(err);
        int tmp = 0, n = 0;
        GDir *d = g_dir_open(frames, 0, NULL);
        for (const char *e; d && (e = g_dir_read_name(d));) e[0] == '.' ? tmp++ : n++;
        if (d) g_dir_close(d);
        CHECK(n == 0);
    } else {
        kill(pid, SIGKILL);
        waitpid(pid, NULL, 0);
    }
    test_camera_unlock(lk);
}

// During a long move (1 deg/s^2: a profiled stop from 2.5 deg/s takes 2.5 s):
// one Ctrl-C waits for the profiled stop and pauses (exit 3); after --resume,
// a second Ctrl-C 0.3 s after the first stops the stage at once and ends refl
// by SIGINT at once.
TEST_ALONE(capture_ctrl_c_during_move_once_then_twice)
{
    int lk = test_camera_lock();
    static const char *const edits[] = { "accel_deg_s2 = 10\n", "accel_deg_s2 = 1\n",
                                         "home_time_s = 15\n", "home_time_s = 0.3\n", NULL };
    const char *rig = realtime_rig(edits);
    const char *plan = test_write("plan.ini", "[sample]\nname = coupon_matte_paint\nkind = material_coupon\n"
                                  "[angles]\nlist = 0 170\n[lamps]\nsets = east\n[exposure]\nmode = fixed\n"
                                  "list_us = 1000\n");
    char dir[PATH_MAX], frame0[PATH_MAX + 32];
    snprintf(dir, sizeof dir, "%s/s", test_tmpdir());
    snprintf(frame0, sizeof frame0, "%s/frames/s000001.png", dir);   // step 0: the operator's
    const char *err_path = test_path("err.txt");
    const char *args[] = { "capture", plan, "--rig", rig, "-o", dir, "--yes", NULL };
    pid_t pid = spawn_refl(args, err_path);
    if (!rig || !wait_for(frame0, NULL, 60)) {
        kill(pid, SIGKILL);
        waitpid(pid, NULL, 0);
        test_camera_unlock(lk);
        return;
    }
    sleep_s(2.5);                             // into the move to 170 deg
    double t_int = model_now_s(), ended;
    kill(pid, SIGINT);
    int st = wait_pid(pid, 20, &ended);
    CHECK_MSG(ended - t_int > 1.0 && ended - t_int < 4.5, "ended %.2f s after Ctrl-C", ended - t_int);
    CHECK_MSG(st >= 0 && WIFEXITED(st) && WEXITSTATUS(st) == 3, "status 0x%x, want exit 3", st);
    char *err = file_text(err_path);
    CHECK_CONTAINS(err, "refl capture: interrupted (SIGINT) during the move to 170 deg: no frame was being taken; "
                        "virtual turntable (sim, seed 1): the move to 170 deg interrupted: the stage stopped at ");
    CHECK_CONTAINS(err, "session paused before step 2 of 3");
    CHECK_CONTAINS(err, "(it moves there again)");
    free(err);

    const char *resume[] = { "capture", "--resume", dir, "--yes", NULL };
    pid = spawn_refl(resume, err_path);
    if (wait_for(err_path, "resuming", 60)) {
        sleep_s(3.0);                         // homed (0.3 s), 2.5 s into the move
        kill(pid, SIGINT);
        sleep_s(0.3);
        t_int = model_now_s();
        kill(pid, SIGINT);
        st = wait_pid(pid, 20, &ended);
        CHECK_MSG(ended - t_int < 0.5, "ended %.2f s after the second Ctrl-C", ended - t_int);
        CHECK_MSG(st >= 0 && WIFSIGNALED(st) && WTERMSIG(st) == SIGINT, "status 0x%x, want killed by SIGINT", st);
        err = file_text(err_path);
        CHECK_CONTAINS(err, "refl capture: second interrupt: virtual turntable (sim, seed 1): the move to 170 deg "
                            "interrupted: the stage stopped at once at ");
        free(err);
    } else {
        kill(pid, SIGKILL);
        waitpid(pid, NULL, 0);
    }
    test_camera_unlock(lk);
}

// refl rig home: Ctrl-C stops the homing stage, then refl ends by SIGINT.
TEST_ALONE(rig_home_ctrl_c_stops_the_stage)
{
    const char *rig = test_write("slow.ini", "[turntable]\nbackend = sim\nhome_time_s = 30\ntime_scale = 1\n");
    const char *err_path = test_path("err.txt");
    const char *args[] = { "rig", "--rig", rig, "home", NULL };
    pid_t pid = spawn_refl(args, err_path);
    if (!wait_for(err_path, "refl rig: homing", 30)) {
        kill(pid, SIGKILL);
        waitpid(pid, NULL, 0);
        return;
    }
    sleep_s(0.4);
    double t_int = model_now_s(), ended;
    kill(pid, SIGINT);
    int st = wait_pid(pid, 10, &ended);
    CHECK_MSG(ended - t_int < 1.0, "ended %.2f s after Ctrl-C", ended - t_int);
    CHECK_MSG(st >= 0 && WIFSIGNALED(st) && WTERMSIG(st) == SIGINT, "status 0x%x, want killed by SIGINT", st);
    char *err = file_text(err_path);
    CHECK_CONTAINS(err, "refl rig: interrupted (SIGINT): sim turntable");
    CHECK_CONTAINS(err, "homing interrupted: the stage stopped at ");
    free(err);
}

// ---------------------------------------------------------------------------
// The APT driver under umockdev

// The number of apt_umock_* tests below (the outer test checks they all ran).
enum { N_APT_UMOCK_TESTS = 16 };

TEST_ALONE(turntable_apt_under_umockdev)
{
    if (apt_sim_available()) return;   // we are the inner run
    char self[4096];
    ssize_t n = readlink("/proc/self/exe", self, sizeof self - 1);
    CHECK(n > 0);
    if (n <= 0) return;
    self[n] = 0;
    // ASan must come first in the library list; the preload would come before it.
    char asan[1024];
    const char *ao = getenv("ASAN_OPTIONS");
    snprintf(asan, sizeof asan, "ASAN_OPTIONS=%s%sverify_asan_link_order=0", ao ? ao : "", ao && *ao ? ":" : "");
    // One at a time: the inner tests share the wrapper's one test bed.
    const char *argv[] = { "env", asan, "REFL_TEST_JOBS=1", "REFL_TEST_SET=all", "umockdev-wrapper", self, "apt_umock_", NULL };
    char *out = NULL, *err = NULL;
    int rc = test_run(argv, 60, &out, &err);
    char want[64];
    snprintf(want, sizeof want, "%d passed, 0 failed", N_APT_UMOCK_TESTS);
    CHECK_MSG(rc == 0 && out && strstr(out, want),
              "umockdev-wrapper %s apt_umock_: exit %d, expected \"%s\"\n--- stdout\n%s--- stderr\n%s", self, rc,
              want, out ? out : "", err ? err : "");
    free(out);
    free(err);
}

// The simulated controller and the homed stage: fx_apt_sim_start() and
// fx_apt_open_homed() (tests/fixtures.h).

TEST_INNER(apt_umock_open_info, apt_sim_available)
{
    apt_sim_device_t d = apt_sim_device_defaults();
    apt_sim_t *s = fx_apt_sim_start(&d, 1);
    rig_turntable_t *t = NULL;
    rig_turntable_info_t info;
    apt_sim_stats_t st;
    CHECK(rig_turntable_open_apt(&t, NULL, NULL) == 0);
    if (t) {
        CHECK(rig_turntable_info(t, &info) == 0);
        CHECK(strcmp(info.model, "K10CR1") == 0);
        CHECK(strcmp(info.serial, "55000001") == 0);
        CHECK(strcmp(info.firmware, "1.0.3") == 0);
        CHECK_NEAR(info.counts_per_deg, 136533.33, 1e-9);
        CHECK(strcmp(rig_turntable_name(t), "apt K10CR1 serial 55000001") == 0);
        apt_sim_stats(s, 0, &st);
        CHECK(st.baud_divisor == 0x1a);       // 3 MHz / 115200 = 26 on an FT232R
        CHECK(st.flow_ctrl == 0x01);          // RTS/CTS
        CHECK(st.rts_on);
        CHECK(st.latency_ms == 2);
        CHECK(st.n_info == 1 && st.n_enable == 1);
        CHECK(!st.updates_on);
        rig_turntable_close(t);
    }
    // by serial, with the stage model given
    t = NULL;
    CHECK(rig_turntable_open_apt(&t, "55000001", "K10CR1") == 0);
    rig_turntable_close(t);
    t = NULL;
    CHECK(rig_turntable_open_apt(&t, "55000001", "NO-SUCH-STAGE") == RIG_ERR_NOT_SUPPORTED && !t);
    CHECK_CONTAINS(model_last_error(), "unknown stage model \"NO-SUCH-STAGE\"");
    CHECK_CONTAINS(model_last_error(), "known: K10CR1");
    apt_sim_free(s);
}

TEST_INNER(apt_umock_home_and_moves, apt_sim_available)
{
    apt_sim_device_t d = apt_sim_device_defaults();
    apt_sim_t *s = fx_apt_sim_start(&d, 1);
    rig_turntable_t *t = NULL;
    rig_turntable_status_t st;
    apt_sim_stats_t ss;
    CHECK(rig_turntable_open_apt(&t, NULL, NULL) == 0);
    if (t) {
        CHECK(rig_turntable_status(t, &st) == 0 && !st.homed);
        CHECK(rig_turntable_move_abs_deg(t, 90, 2.0) == RIG_ERR_NOT_HOMED);
        CHECK_CONTAINS(model_last_error(), "apt K10CR1 serial 55000001: the stage is not homed");
        CHECK(rig_turntable_home(t, 2.0) == 0);
        CHECK(rig_turntable_status(t, &st) == 0 && st.homed && !st.homing && !st.moving);
        CHECK_NEAR(st.angle_deg, 0, 0);
        CHECK(rig_turntable_move_abs_deg(t, 90, 2.0) == 0);
        apt_sim_stats(s, 0, &ss);
        CHECK(ss.last_target == 12288000);     // round(90 * 136533.33)
        CHECK(ss.position == 12288000);
        CHECK(rig_turntable_status(t, &st) == 0 && !st.moving && st.homed);
        CHECK_NEAR(st.angle_deg, 90, 1e-5);
        CHECK(rig_turntable_move_rel_deg(t, -30, 2.0) == 0);
        apt_sim_stats(s, 0, &ss);
        CHECK(ss.n_move_rel == 1 && ss.n_move_abs == 1 && ss.n_home == 1);
        CHECK(ss.position == 12288000 - 4096000);  // -round(30 * 136533.33)
        CHECK(rig_turntable_status(t, &st) == 0);
        CHECK_NEAR(st.angle_deg, 60, 1e-5);
        CHECK(rig_turntable_move_abs_deg(t, -45.5, 2.0) == 0);
        apt_sim_stats(s, 0, &ss);
        CHECK(ss.position == -6212267);            // round(-45.5 * 136533.33)
        rig_turntable_close(t);
    }
    apt_sim_free(s);
}

TEST_INNER(apt_umock_status_while_moving_and_keepalive, apt_sim_available)
{
    apt_sim_device_t d = apt_sim_device_defaults();
    d.speed_deg_s = 150;                  // 90 deg in ~0.7 s
    d.accel_deg_s2 = 1500;
    apt_sim_t *s = fx_apt_sim_start(&d, 1);
    rig_turntable_t *t = fx_apt_open_homed();
    rig_turntable_status_t st;
    apt_sim_stats_t ss;
    if (t) {
        CHECK(rig_turntable_start_move_abs_deg(t, 90) == 0);
        sleep_s(0.2);
        CHECK(rig_turntable_status(t, &st) == 0 && st.moving && st.homed && !st.motion_error);
        CHECK(st.angle_deg > 5 && st.angle_deg < 85);
        // waiting turns updates on (every 10 ms); without an ACK every < 20
        // updates the controller would stop sending them
        CHECK(rig_turntable_wait(t, 3.0) == 0);
        apt_sim_stats(s, 0, &ss);
        CHECK_MSG(ss.n_ack >= 3, "acks %d", ss.n_ack);
        CHECK_MSG(ss.n_updates_sent >= 30, "updates %d", ss.n_updates_sent);
        CHECK(!ss.updates_starved);
        CHECK(!ss.updates_on);            // switched off after the wait
        CHECK(rig_turntable_status(t, &st) == 0 && !st.moving);
        CHECK_NEAR(st.angle_deg, 90, 1e-5);
        rig_turntable_close(t);
    }
    apt_sim_free(s);
}

TEST_INNER(apt_umock_stop, apt_sim_available)
{
    apt_sim_device_t d = apt_sim_device_defaults();
    d.speed_deg_s = 100;
    d.accel_deg_s2 = 1000;
    apt_sim_t *s = fx_apt_sim_start(&d, 1);
    rig_turntable_t *t = fx_apt_open_homed();
    rig_turntable_status_t st;
    apt_sim_stats_t ss;
    if (t) {
        CHECK(rig_turntable_start_move_abs_deg(t, 90) == 0);
        sleep_s(0.2);
        CHECK(rig_turntable_stop(t, true) == 0);
        apt_sim_stats(s, 0, &ss);
        CHECK(ss.n_stop == 1 && ss.last_stop_mode == 1);
        CHECK(rig_turntable_status(t, &st) == 0 && !st.moving);
        CHECK(st.angle_deg > 5 && st.angle_deg < 85);
        CHECK(rig_turntable_wait(t, 1.0) == 0);       // nothing left to wait for
        double p1 = st.angle_deg;
        CHECK(rig_turntable_start_move_abs_deg(t, p1 + 80) == 0);
        sleep_s(0.3);                                 // cruising at 100 deg/s
        CHECK(rig_turntable_stop(t, false) == 0);     // profiled: 100^2/(2*1000) = 5 deg more
        apt_sim_stats(s, 0, &ss);
        CHECK(ss.n_stop == 2 && ss.last_stop_mode == 2);
        CHECK(rig_turntable_status(t, &st) == 0 && !st.moving);
        CHECK(st.angle_deg > p1 + 20 && st.angle_deg < p1 + 80);
        rig_turntable_close(t);
    }
    apt_sim_free(s);
}

TEST_INNER(apt_umock_wait_timeout, apt_sim_available)
{
    apt_sim_device_t d = apt_sim_device_defaults();
    d.speed_deg_s = 100;
    d.accel_deg_s2 = 1000;
    apt_sim_t *s = fx_apt_sim_start(&d, 1);
    rig_turntable_t *t = fx_apt_open_homed();
    if (t) {
        double t0 = model_now_s();
        CHECK(rig_turntable_move_abs_deg(t, 90, 0.2) == RIG_ERR_TIMEOUT);
        CHECK_NEAR(model_now_s() - t0, 0.2, 0.1);
        CHECK_CONTAINS(model_last_error(), "apt K10CR1 serial 55000001: the move did not finish within 0.20 s");
        CHECK(rig_turntable_wait(t, 2.0) == 0);       // it was still moving; now done
        rig_turntable_status_t st;
        CHECK(rig_turntable_status(t, &st) == 0);
        CHECK_NEAR(st.angle_deg, 90, 1e-5);
        rig_turntable_close(t);
    }
    apt_sim_free(s);
}

TEST_INNER(apt_umock_no_reply, apt_sim_available)
{
    apt_sim_device_t d = apt_sim_device_defaults();
    d.no_reply = true;
    apt_sim_t *s = fx_apt_sim_start(&d, 1);
    rig_turntable_t *t = NULL;
    double t0 = model_now_s();
    CHECK(rig_turntable_open_apt(&t, NULL, NULL) == RIG_ERR_TIMEOUT && !t);
    double dt = model_now_s() - t0;
    CHECK_MSG(dt > 0.9 && dt < 2.5, "open took %.2f s", dt);
    CHECK_CONTAINS(model_last_error(), "apt serial 55000001: no reply to HW_REQ_INFO after 1.0 s");
    CHECK_CONTAINS(model_last_error(), "powered");
    apt_sim_free(s);
}

TEST_INNER(apt_umock_motion_error, apt_sim_available)
{
    apt_sim_device_t d = apt_sim_device_defaults();
    d.motion_error = true;
    apt_sim_t *s = fx_apt_sim_start(&d, 1);
    rig_turntable_t *t = fx_apt_open_homed();
    rig_turntable_status_t st;
    if (t) {
        CHECK(rig_turntable_move_abs_deg(t, 90, 2.0) == RIG_ERR_MOTION);
        CHECK_CONTAINS(model_last_error(), "apt K10CR1 serial 55000001: motion error during the move");
        CHECK_CONTAINS(model_last_error(), "MOTION-ERROR");
        CHECK(rig_turntable_status(t, &st) == 0 && st.motion_error && !st.moving);
        CHECK(st.angle_deg > 10 && st.angle_deg < 80);
        CHECK(rig_turntable_move_abs_deg(t, 0, 2.0) == 0);   // a new move clears it
        CHECK(rig_turntable_status(t, &st) == 0 && !st.motion_error);
        rig_turntable_close(t);
    }
    apt_sim_free(s);
}

TEST_INNER(apt_umock_unplugged_mid_move, apt_sim_available)
{
    apt_sim_device_t d = apt_sim_device_defaults();
    d.unplug_mid_move = true;
    d.speed_deg_s = 300;
    d.accel_deg_s2 = 3000;
    apt_sim_t *s = fx_apt_sim_start(&d, 1);
    rig_turntable_t *t = fx_apt_open_homed();
    rig_turntable_status_t st;
    if (t) {
        double t0 = model_now_s();
        CHECK(rig_turntable_move_abs_deg(t, 90, 3.0) == RIG_ERR_DISCONNECTED);
        CHECK(model_now_s() - t0 < 1.5);
        CHECK_CONTAINS(model_last_error(), "apt K10CR1 serial 55000001: the device disconnected");
        CHECK(rig_turntable_status(t, &st) == RIG_ERR_DISCONNECTED);
        CHECK(rig_turntable_stop(t, true) == RIG_ERR_DISCONNECTED);
        rig_turntable_close(t);
    }
    apt_sim_free(s);
}

TEST_INNER(apt_umock_permission_denied, apt_sim_available)
{
    apt_sim_device_t d = apt_sim_device_defaults();
    d.deny_access = true;
    apt_sim_t *s = fx_apt_sim_start(&d, 1);
    rig_turntable_t *t = NULL;
    CHECK(rig_turntable_open_apt(&t, NULL, NULL) == RIG_ERR_ACCESS && !t);
    CHECK_CONTAINS(model_last_error(), "permission denied on /dev/bus/usb/001/002");
    CHECK_CONTAINS(model_last_error(), "udev rule");
    CHECK(rig_turntable_open_apt(&t, "55000001", NULL) == RIG_ERR_ACCESS && !t);
    CHECK_CONTAINS(model_last_error(), "apt serial 55000001: permission denied");
    apt_sim_free(s);
}

TEST_INNER(apt_umock_device_missing, apt_sim_available)
{
    apt_sim_device_t d = apt_sim_device_defaults();
    apt_sim_t *s = fx_apt_sim_start(&d, 1);
    rig_turntable_t *t = NULL;
    CHECK(rig_turntable_open_apt(&t, "99999999", NULL) == RIG_ERR_NO_DEVICE && !t);
    CHECK_CONTAINS(model_last_error(), "apt serial 99999999: not found");
    CHECK_CONTAINS(model_last_error(), "present: 55000001 (bus 1 device 2)");
    apt_sim_free(s);
    s = fx_apt_sim_start(NULL, 0);   // no device at all
    CHECK(rig_turntable_open_apt(&t, NULL, NULL) == RIG_ERR_NO_DEVICE && !t);
    CHECK_CONTAINS(model_last_error(), "no Thorlabs APT controller (USB 0403:faf0) found");
    apt_sim_free(s);
}

TEST_INNER(apt_umock_two_devices, apt_sim_available)
{
    apt_sim_device_t d[2] = { apt_sim_device_defaults(), apt_sim_device_defaults() };
    d[1].serial = "55000002";
    apt_sim_t *s = fx_apt_sim_start(d, 2);
    rig_turntable_t *t = NULL;
    rig_turntable_info_t info;
    CHECK(rig_turntable_open_apt(&t, NULL, NULL) == RIG_ERR_INVALID && !t);
    CHECK_CONTAINS(model_last_error(), "2 Thorlabs APT controllers found");
    CHECK_CONTAINS(model_last_error(), "55000001");
    CHECK_CONTAINS(model_last_error(), "55000002");
    CHECK_CONTAINS(model_last_error(), "give the serial");
    CHECK(rig_turntable_open_apt(&t, "55000002", NULL) == 0);
    if (t) {
        CHECK(rig_turntable_info(t, &info) == 0 && strcmp(info.serial, "55000002") == 0);
        CHECK(rig_turntable_home(t, 2.0) == 0);
        CHECK(rig_turntable_move_abs_deg(t, 10, 2.0) == 0);
        apt_sim_stats_t a, b;
        apt_sim_stats(s, 0, &a);
        apt_sim_stats(s, 1, &b);
        CHECK(a.n_move_abs == 0 && b.n_move_abs == 1);
        rig_turntable_close(t);
    }
    apt_sim_free(s);
}

TEST_INNER(apt_umock_partial_messages_and_garbage, apt_sim_available)
{
    apt_sim_device_t d = apt_sim_device_defaults();
    d.trickle_bytes = 5;                  // every message arrives in 5-byte pieces
    d.garbage_before_info = true;         // and junk precedes the first reply
    apt_sim_t *s = fx_apt_sim_start(&d, 1);
    rig_turntable_t *t = NULL;
    rig_turntable_info_t info;
    rig_turntable_status_t st;
    CHECK(rig_turntable_open_apt(&t, NULL, NULL) == 0);
    if (t) {
        CHECK(rig_turntable_info(t, &info) == 0);
        CHECK(strcmp(info.model, "K10CR1") == 0 && strcmp(info.serial, "55000001") == 0);
        CHECK(strcmp(info.firmware, "1.0.3") == 0);
        CHECK(rig_turntable_home(t, 2.0) == 0);
        CHECK(rig_turntable_move_abs_deg(t, 33.3, 2.0) == 0);
        CHECK(rig_turntable_status(t, &st) == 0 && !st.moving && st.homed);
        CHECK_NEAR(st.angle_deg, 33.3, 1e-5);
        rig_turntable_close(t);
    }
    apt_sim_free(s);
}

TEST_INNER(apt_umock_limit_switch, apt_sim_available)
{
    apt_sim_device_t d = apt_sim_device_defaults();
    d.limit_mid_move = true;
    apt_sim_t *s = fx_apt_sim_start(&d, 1);
    rig_turntable_t *t = fx_apt_open_homed();
    rig_turntable_status_t st;
    if (t) {
        CHECK(rig_turntable_move_abs_deg(t, 90, 2.0) == RIG_ERR_LIMIT);
        CHECK_CONTAINS(model_last_error(), "apt K10CR1 serial 55000001: the move stopped at a limit switch");
        CHECK_CONTAINS(model_last_error(), "fwd-limit");
        CHECK(rig_turntable_status(t, &st) == 0 && st.limit_fwd && !st.limit_rev && !st.moving);
        CHECK(!st.motion_error);
        rig_turntable_close(t);
    }
    apt_sim_free(s);
}

// The controller's own speeds (MOT_GET_VELPARAMS / MOT_GET_HOMEPARAMS), unlike
// the stage table's K10CR1 10 deg/s, 10 deg/s^2, give the estimates.
TEST_INNER(apt_umock_motion_params_from_controller, apt_sim_available)
{
    apt_sim_device_t d = apt_sim_device_defaults();
    d.speed_deg_s = 25;
    d.accel_deg_s2 = 40;
    d.home_speed_deg_s = 7.5;
    d.home_offset_deg = 4;
    apt_sim_t *s = fx_apt_sim_start(&d, 1);
    rig_turntable_t *t = NULL;
    CHECK(rig_turntable_open_apt(&t, NULL, NULL) == 0);
    if (t) {
        rig_turntable_info_t info;
        CHECK(rig_turntable_info(t, &info) == 0);
        CHECK(strcmp(info.params_from, "controller") == 0);
        CHECK_NEAR(info.speed_deg_s, 25, 1e-3);
        CHECK_NEAR(info.accel_deg_s2, 40, 1e-2);
        CHECK_NEAR(info.home_speed_deg_s, 7.5, 1e-3);
        // a full turn and the offset at 7.5 deg/s, and the ramps at 40 deg/s^2
        CHECK_NEAR(info.home_time_s, 364 / 7.5 + 2 * 7.5 / 40, 1e-3);
        apt_sim_stats_t st;
        apt_sim_stats(s, 0, &st);
        CHECK(st.n_velparams == 1 && st.n_homeparams == 1);
        // Moves are timed by the controller's speed: 90 deg at 25 deg/s,
        // 40 deg/s^2 takes 4.225 s, so a time-out from the table's (10 deg/s)
        // would be 9.0 + 1.0 s.
        CHECK_NEAR(rig_motion_time_s(90, info.speed_deg_s, info.accel_deg_s2), 90 / 25.0 + 25 / 40.0, 1e-3);
        rig_turntable_close(t);
    }
    // The rig file's turntable takes them as its motion profile.
    char text[256];
    snprintf(text, sizeof text, "[turntable]\nbackend = apt\n");
    const char *path = test_write("apt-rig.ini", text);
    rig_t *r = NULL;
    CHECK(rig_open(&r, path) == 0);
    if (r) {
        CHECK_NEAR(r->speed_deg_s, 25, 1e-3);
        CHECK_NEAR(r->accel_deg_s2, 40, 1e-2);
        CHECK_NEAR(r->home_time_s, 364 / 7.5 + 2 * 7.5 / 40, 1e-3);
        rig_close(r);
    }
    apt_sim_free(s);
}

// A controller that does not answer VELPARAMS/HOMEPARAMS: the stage table's
// values, with a note.
TEST_INNER(apt_umock_motion_params_fallback, apt_sim_available)
{
    apt_sim_device_t d = apt_sim_device_defaults();
    d.no_params = true;
    apt_sim_t *s = fx_apt_sim_start(&d, 1);
    rig_turntable_t *t = NULL;
    fflush(stderr);
    const char *errpath = test_path("stderr.txt");
    int saved = dup(2), fd = open(errpath, O_WRONLY | O_CREAT | O_TRUNC, 0644);
    dup2(fd, 2);
    close(fd);
    bool quiet = model_error_quiet(false);   // the note is what this test reads
    int rc = rig_turntable_open_apt(&t, NULL, NULL);
    model_error_quiet(quiet);
    fflush(stderr);
    dup2(saved, 2);
    close(saved);
    CHECK(rc == 0);
    char *err = model_read_file(errpath, NULL);
    CHECK_CONTAINS(err, "refl: apt K10CR1 serial 55000001: no reply to MOT_REQ_VELPARAMS/MOT_REQ_HOMEPARAMS; "
                        "time estimates and time-outs use the stage table's 10 deg/s, 10 deg/s^2");
    free(err);
    if (t) {
        rig_turntable_info_t info;
        CHECK(rig_turntable_info(t, &info) == 0);
        CHECK(strcmp(info.params_from, "table") == 0);
        CHECK_NEAR(info.speed_deg_s, 10, 1e-9);
        CHECK_NEAR(info.accel_deg_s2, 10, 1e-9);
        CHECK_NEAR(info.home_time_s, 72, 1e-9);
        // and the stage still works
        CHECK(rig_turntable_home(t, 5) == 0);
        CHECK(rig_turntable_move_abs_deg(t, 30, 5) == 0);
        rig_turntable_close(t);
    }
    apt_sim_free(s);
}

// Interrupted homing and moves on the APT stage: MOT_MOVE_STOP profiled (2),
// then at once (1) for a second interrupt.
TEST_INNER(apt_umock_watched_interrupts, apt_sim_available)
{
    apt_sim_device_t d = apt_sim_device_defaults();
    d.home_time_s = 5;
    d.speed_deg_s = 100;
    d.accel_deg_s2 = 50;                      // a profiled stop from cruise: 2 s
    apt_sim_t *s = fx_apt_sim_start(&d, 1);
    rig_turntable_t *t = NULL;
    CHECK(rig_turntable_open_apt(&t, NULL, NULL) == 0);
    if (!t) {
        apt_sim_free(s);
        return;
    }
    interrupter_t it = { .at1_s = 0.3 };
    rig_turntable_watch_t w = watch_of(&it, "homing");
    CHECK(rig_turntable_start_home(t) == 0);
    CHECK(rig_turntable_wait_watched(t, 20, &w) == RIG_ERR_INTERRUPTED);
    CHECK_MSG(model_now_s() - it.t1_s < 0.5, "stood %.2f s after the interrupt", model_now_s() - it.t1_s);
    CHECK_CONTAINS(model_last_error(), "apt K10CR1 serial 55000001: homing interrupted: the stage stopped at ");
    apt_sim_stats_t ss;
    apt_sim_stats(s, 0, &ss);
    CHECK(ss.n_stop == 1 && ss.last_stop_mode == 2);
    rig_turntable_status_t st;
    CHECK(rig_turntable_status(t, &st) == 0 && !st.moving && !st.homed);

    // homed, then a long move interrupted twice: at once
    w = watch_of(&(interrupter_t){ 0 }, "homing");
    CHECK(rig_turntable_start_home(t) == 0);
    CHECK(rig_turntable_wait_watched(t, 20, &w) == 0);
    interrupter_t it2 = { .at1_s = 2.5, .at2_s = 2.8 };
    w = watch_of(&it2, "the move to 1000 deg");
    CHECK(rig_turntable_start_move_abs_deg(t, 1000) == 0);
    CHECK(rig_turntable_wait_watched(t, 30, &w) == RIG_ERR_INTERRUPTED);
    CHECK_MSG(model_now_s() - it2.t2_s < 0.5, "stood %.2f s after the second interrupt", model_now_s() - it2.t2_s);
    CHECK_CONTAINS(model_last_error(), "the move to 1000 deg interrupted: the stage stopped at once at ");
    apt_sim_stats(s, 0, &ss);
    CHECK(ss.n_stop == 3 && ss.last_stop_mode == 1);
    CHECK(rig_turntable_status(t, &st) == 0 && !st.moving && st.angle_deg > 100 && st.angle_deg < 900);
    rig_turntable_close(t);
    apt_sim_free(s);
}
