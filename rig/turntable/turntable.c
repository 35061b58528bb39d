// rig/turntable/turntable.c — the turntable wrappers over rig_turntable_ops_t, the stage
// models and the trapezoidal motion time.
#include <math.h>
#include <stdio.h>

#include "model/model.h"
#include "rig/internal.h"

// ---------------------------------------------------------------------------
// Stage models. counts_per_deg: Thorlabs APT position units per degree.
//   K10CR1: 200 full steps x 2048 microsteps per motor turn x 120:1 worm gear
//           / 360 = 136533.33 (the APT protocol manual's value).
//   PRM1-Z8 (on a KDC101/TDC001 DC servo controller): 1919.64 (the APT
//           protocol manual's value for this stage).
// DDR25/DDR100 are left out until their scale is verified on a real stage.
// Speeds and accelerations are the controllers' default move parameters
// (K10CR1: 10 deg/s, 10 deg/s^2; PRM1-Z8: 10 deg/s, 10 deg/s^2).
const rig_stage_model_t rig_stage_models[] = {
    { "K10CR1", 136533.33, 10.0, 10.0 },
    { "K10CR1/M", 136533.33, 10.0, 10.0 },
    { "PRM1-Z8", 1919.64, 10.0, 10.0 },
    { "PRM1/MZ8", 1919.64, 10.0, 10.0 },
    { NULL, 0, 0, 0 },
};

// ---------------------------------------------------------------------------
// Turntable wrappers

static int check(rig_turntable_t *t, const char *what)
{
    if (!t || !t->ops) return rig_fail(RIG_ERR_INVALID, "turntable %s: no turntable (NULL handle): open one first", what);
    return RIG_ERR_OK;
}

static int check_timeout(rig_turntable_t *t, const char *what, double timeout_s)
{
    if (!(isfinite(timeout_s) && timeout_s > 0))
        return rig_fail(RIG_ERR_INVALID, "%s: %s: time-out %g s is not a positive number of seconds",
                        t->name, what, timeout_s);
    return RIG_ERR_OK;
}

static int check_angle(rig_turntable_t *t, const char *what, double angle_deg)
{
    // +-10000 deg keeps the position in int32 counts for every stage (K10CR1: 1.37e9).
    if (!(isfinite(angle_deg) && fabs(angle_deg) <= 1e4))
        return rig_fail(RIG_ERR_INVALID, "%s: %s: angle %g deg is not a finite angle within +-10000 deg",
                        t->name, what, angle_deg);
    return RIG_ERR_OK;
}

static int not_supported(rig_turntable_t *t, const char *what)
{
    return rig_fail(RIG_ERR_NOT_SUPPORTED, "%s: %s is not supported by the %s backend", t->name, what,
                    t->ops->backend);
}

int rig_turntable_info(rig_turntable_t *t, rig_turntable_info_t *out)
{
    int r = check(t, "info");
    if (r) return r;
    if (!out) return rig_fail(RIG_ERR_INVALID, "%s: info: NULL output", t->name);
    if (!t->ops->info) return not_supported(t, "info");
    return t->ops->info(t, out);
}

int rig_turntable_status(rig_turntable_t *t, rig_turntable_status_t *out)
{
    int r = check(t, "status");
    if (r) return r;
    if (!out) return rig_fail(RIG_ERR_INVALID, "%s: status: NULL output", t->name);
    if (!t->ops->status) return not_supported(t, "status");
    return t->ops->status(t, out);
}

int rig_turntable_home(rig_turntable_t *t, double timeout_s)
{
    int r = check(t, "home");
    if (r || (r = check_timeout(t, "home", timeout_s))) return r;
    if (!t->ops->start_home || !t->ops->wait) return not_supported(t, "homing");
    if ((r = t->ops->start_home(t))) return r;
    return t->ops->wait(t, timeout_s);
}

int rig_turntable_start_home(rig_turntable_t *t)
{
    int r = check(t, "home");
    if (r) return r;
    if (!t->ops->start_home) return not_supported(t, "homing");
    return t->ops->start_home(t);
}

int rig_turntable_start_move_abs_deg(rig_turntable_t *t, double angle_deg)
{
    int r = check(t, "move");
    if (r || (r = check_angle(t, "move", angle_deg))) return r;
    if (!t->ops->start_move_abs_deg) return not_supported(t, "an absolute move");
    return t->ops->start_move_abs_deg(t, angle_deg);
}

int rig_turntable_move_abs_deg(rig_turntable_t *t, double angle_deg, double timeout_s)
{
    int r = check(t, "move");
    if (r || (r = check_timeout(t, "move", timeout_s))) return r;
    if ((r = rig_turntable_start_move_abs_deg(t, angle_deg))) return r;
    return rig_turntable_wait(t, timeout_s);
}

int rig_turntable_move_rel_deg(rig_turntable_t *t, double delta_deg, double timeout_s)
{
    int r = check(t, "relative move");
    if (r || (r = check_timeout(t, "relative move", timeout_s)) ||
        (r = check_angle(t, "relative move", delta_deg)))
        return r;
    if (t->ops->start_move_rel_deg) {
        if ((r = t->ops->start_move_rel_deg(t, delta_deg))) return r;
    } else {
        rig_turntable_status_t st;
        if ((r = rig_turntable_status(t, &st))) return r;
        if ((r = rig_turntable_start_move_abs_deg(t, st.angle_deg + delta_deg))) return r;
    }
    return rig_turntable_wait(t, timeout_s);
}

int rig_turntable_wait(rig_turntable_t *t, double timeout_s)
{
    int r = check(t, "wait");
    if (r || (r = check_timeout(t, "wait", timeout_s))) return r;
    if (!t->ops->wait) return not_supported(t, "waiting for motion");
    return t->ops->wait(t, timeout_s);
}

// ---------------------------------------------------------------------------
// Watched waits: the motion in slices, an interrupt between them.

#define SLICE_S 0.05

int rig_turntable_start_stop(rig_turntable_t *t, bool immediate)
{
    int r = check(t, "stop");
    if (r) return r;
    if (t->ops->start_stop) return t->ops->start_stop(t, immediate);
    if (!t->ops->stop) return not_supported(t, "stop");
    return t->ops->stop(t, immediate);
}

// Begins a stop, quietly (a failure shows in the wait that follows).
static void begin_stop(rig_turntable_t *t, bool immediate)
{
    bool q = model_error_quiet_thread(true);
    rig_turntable_start_stop(t, immediate);
    model_error_quiet_thread(q);
}

// The angle now (NAN when the status fails); quiet.
static double angle_now(rig_turntable_t *t)
{
    rig_turntable_status_t st = { .angle_deg = NAN };
    bool q = model_error_quiet_thread(true);
    if (t->ops->status && t->ops->status(t, &st)) st.angle_deg = NAN;
    model_error_quiet_thread(q);
    return st.angle_deg;
}

int rig_turntable_wait_watched(rig_turntable_t *t, double timeout_s, const rig_turntable_watch_t *w)
{
    int r = check(t, "wait");
    if (r || (r = check_timeout(t, "wait", timeout_s))) return r;
    if (!t->ops->wait) return not_supported(t, "waiting for motion");
    const char *what = w && w->what ? w->what : "the motion";
    double t0 = model_now_s(), last_report = t0, stop_end = 0;
    int stopping = 0;               // 0 moving, 1 profiled stop under way, 2 immediate stop under way
    for (;;) {
        int level = w && w->interrupt ? *w->interrupt : 0;
        if (level > stopping) {     // the first interrupt: a profiled stop; the second: at once
            stopping = level >= 2 ? 2 : 1;
            begin_stop(t, stopping == 2);
            stop_end = model_now_s() + 5 + (isfinite(w->stop_s) ? w->stop_s : 60);
        }
        bool q = model_error_quiet_thread(true);
        r = t->ops->wait(t, SLICE_S);
        model_error_quiet_thread(q);
        double now = model_now_s();
        if (r == RIG_ERR_OK && !stopping) return RIG_ERR_OK;
        if (r == RIG_ERR_OK || (stopping && r == RIG_ERR_TIMEOUT && now > stop_end)) {
            double at = angle_now(t);
            if (r) return rig_fail(RIG_ERR_TIMEOUT, "%s: %s interrupted, but the stage did not stop within %.1f s "
                                   "(at %.3f deg): switch its controller off", t->name, what,
                                   stop_end - t0, at);
            // Quietly: the caller words the interruption.
            bool quiet = model_error_quiet_thread(true);
            r = rig_fail(RIG_ERR_INTERRUPTED, "%s: %s interrupted: the stage %s at %.3f deg", t->name, what,
                         stopping == 2 ? "stopped at once" : "stopped", at);
            model_error_quiet_thread(quiet);
            return r;
        }
        if (r != RIG_ERR_TIMEOUT) return rig_fail(r, "%s", model_last_error());   // its own message, once
        if (!stopping && now - t0 > timeout_s)
            return rig_fail(RIG_ERR_TIMEOUT, "%s: %s did not finish within %.2f s (at %.3f deg): give it more "
                            "time, or check that nothing blocks the stage; it may still be moving "
                            "(rig_turntable_stop halts it)", t->name, what, timeout_s, angle_now(t));
        if (w && w->progress && now - last_report >= w->period_s) {
            last_report = now;
            w->progress(w->ctx, now - t0, angle_now(t));
        }
    }
}

int rig_turntable_stop(rig_turntable_t *t, bool immediate)
{
    int r = check(t, "stop");
    if (r) return r;
    if (!t->ops->stop) return not_supported(t, "stop");
    return t->ops->stop(t, immediate);
}

void rig_turntable_close(rig_turntable_t *t)
{
    if (t && t->ops && t->ops->close) t->ops->close(t);
}

const char *rig_turntable_name(const rig_turntable_t *t) { return t ? t->name : ""; }
const char *rig_turntable_backend(const rig_turntable_t *t) { return t && t->ops ? t->ops->backend : ""; }

double rig_motion_time_s(double delta_deg, double speed_deg_s, double accel_deg_s2)
{
    double d = fabs(delta_deg);
    if (!(speed_deg_s > 0 && accel_deg_s2 > 0) || !isfinite(d)) return NAN;
    double d_ramps = speed_deg_s * speed_deg_s / accel_deg_s2;   // accelerate + decelerate
    if (d >= d_ramps) return d / speed_deg_s + speed_deg_s / accel_deg_s2;
    return 2 * sqrt(d / accel_deg_s2);                          // triangle: never reaches cruise
}
