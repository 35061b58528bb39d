// rig/turntable/sim.c — a simulated rotation stage: trapezoidal moves at the
// given speed and acceleration, homing that takes home_time_s, a measured
// position with noise, everything computed from the clock (time_scale makes
// tests fast), and fault injection.
#define _GNU_SOURCE
#include <errno.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "model/model.h"
#include "rig/internal.h"

enum { MOTION_IDLE, MOTION_HOME, MOTION_MOVE, MOTION_DECEL };

typedef struct {
    rig_turntable_sim_params_t p;
    double t_origin_s;          // real time of sim time 0
    int motion;
    double t0;                  // sim time the motion started
    double p0;                  // position then, deg
    double dist, dir, dur;      // move: length, sign, duration (sim s)
    double v0;                  // deceleration: starting speed
    double target;              // move: end position (before noise)
    double final_pos;           // move: where it will stand (target + noise, drawn at the start)
    double pos;                 // measured position when idle
    bool homed, motion_error, disconnected, stalled;
    int completed_moves;
    bool fault_fired;
    double fault_at;            // sim time the armed fault fires (< 0: none)
    uint64_t rng;
} sim_t;

static sim_t *S(rig_turntable_t *t) { return t->impl; }

static double sim_now(sim_t *s) { return (model_now_s() - s->t_origin_s) / s->p.time_scale; }

static void sleep_real(double sec)
{
    if (!(sec > 0)) return;
    struct timespec ts = { (time_t)sec, (long)((sec - floor(sec)) * 1e9) };
    while (nanosleep(&ts, &ts) != 0 && errno == EINTR) {}
}

static double gauss(sim_t *s)
{
    // splitmix64 -> two uniforms -> Box-Muller
    double u[2];
    for (int i = 0; i < 2; i++) {
        uint64_t z = (s->rng += 0x9E3779B97F4A7C15ull);
        z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
        z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
        z ^= z >> 31;
        u[i] = ((z >> 11) + 0.5) * (1.0 / 9007199254740992.0);
    }
    return sqrt(-2 * log(u[0])) * cos(2 * M_PI * u[1]);
}

// Distance covered t seconds into a trapezoidal (or triangular) move of length D.
static double trap_dist(double D, double v, double a, double t)
{
    double T = rig_motion_time_s(D, v, a);
    if (t >= T) return D;
    if (t <= 0) return 0;
    double ta = fmin(v / a, T / 2);   // end of the acceleration
    double vmax = a * ta;
    if (t <= ta) return 0.5 * a * t * t;
    if (t <= T - ta) return 0.5 * a * ta * ta + vmax * (t - ta);
    double r = T - t;
    return D - 0.5 * a * r * r;
}

static double trap_speed(double D, double v, double a, double t)
{
    double T = rig_motion_time_s(D, v, a);
    if (t <= 0 || t >= T) return 0;
    double ta = fmin(v / a, T / 2);
    if (t <= ta) return a * t;
    if (t <= T - ta) return a * ta;
    return a * (T - t);
}

// Position at sim time t of the motion in progress (deg, no noise).
static double motion_pos(sim_t *s, double t)
{
    double e = t - s->t0;
    switch (s->motion) {
    case MOTION_MOVE: return s->p0 + s->dir * trap_dist(s->dist, s->p.speed_deg_s, s->p.accel_deg_s2, e);
    case MOTION_DECEL: {
        double te = fmin(e, s->v0 / s->p.accel_deg_s2);
        return s->p0 + s->dir * (s->v0 * te - 0.5 * s->p.accel_deg_s2 * te * te);
    }
    case MOTION_HOME: return s->dur > 0 ? s->p0 * fmax(0, 1 - e / s->dur) : 0;
    default: return s->pos;
    }
}

// Bring the state up to sim time t: finish motions, fire faults. Returns the
// fault fired now (0 none).
static int advance(sim_t *s, double t)
{
    if (s->disconnected) return RIG_ERR_DISCONNECTED;
    if (s->motion == MOTION_IDLE) return 0;
    if (s->fault_at >= 0 && t >= s->fault_at) {
        double p = motion_pos(s, s->fault_at);
        int f = s->p.fault;
        s->fault_at = -1;
        s->fault_fired = true;
        if (f == RIG_ERR_DISCONNECTED) {
            s->disconnected = true;
            s->pos = p;
            return f;
        }
        if (f == RIG_ERR_TIMEOUT) {       // stall: the controller keeps "moving" at p
            s->stalled = true;
            s->pos = p;
            return 0;
        }
        s->motion = MOTION_IDLE;          // motion error: stopped where it was
        s->motion_error = true;
        s->pos = p;
        return f;
    }
    if (s->stalled) return 0;
    if (s->motion == MOTION_MOVE && t >= s->t0 + s->dur) {
        s->motion = MOTION_IDLE;
        s->pos = s->final_pos;
        s->completed_moves++;
    } else if (s->motion == MOTION_HOME && t >= s->t0 + s->dur) {
        s->motion = MOTION_IDLE;
        s->pos = 0;
        s->homed = true;
    } else if (s->motion == MOTION_DECEL && t >= s->t0 + s->v0 / s->p.accel_deg_s2) {
        s->pos = motion_pos(s, t);
        s->motion = MOTION_IDLE;
    }
    return 0;
}

static int gone(rig_turntable_t *t)
{
    return rig_fail(RIG_ERR_DISCONNECTED, "%s: the (simulated) stage disconnected: reopen it and home it again",
                    t->name);
}

static int sim_info(rig_turntable_t *t, rig_turntable_info_t *out)
{
    sim_t *s = S(t);
    memset(out, 0, sizeof *out);
    snprintf(out->model, sizeof out->model, "K10CR1 (simulated)");
    snprintf(out->serial, sizeof out->serial, "sim-%llu", (unsigned long long)s->p.seed);
    snprintf(out->firmware, sizeof out->firmware, "sim");
    out->counts_per_deg = 136533.33;
    double ts = s->p.time_scale;
    out->speed_deg_s = s->p.speed_deg_s / ts;
    out->accel_deg_s2 = s->p.accel_deg_s2 / (ts * ts);
    out->home_time_s = s->p.home_time_s * ts;
    out->home_speed_deg_s = out->home_time_s > 0 ? 360 / out->home_time_s : out->speed_deg_s;
    snprintf(out->params_from, sizeof out->params_from, "sim");
    return 0;
}

static int sim_status(rig_turntable_t *t, rig_turntable_status_t *out)
{
    sim_t *s = S(t);
    double now = sim_now(s);
    advance(s, now);
    if (s->disconnected) return gone(t);
    *out = (rig_turntable_status_t){
        .angle_deg = s->motion == MOTION_IDLE || s->stalled ? s->pos : motion_pos(s, now),
        .moving = s->motion != MOTION_IDLE,
        .homing = s->motion == MOTION_HOME,
        .homed = s->homed,
        .motion_error = s->motion_error,
    };
    return 0;
}

static int sim_start_home(rig_turntable_t *t)
{
    sim_t *s = S(t);
    double now = sim_now(s);
    advance(s, now);
    if (s->disconnected) return gone(t);
    s->p0 = s->motion == MOTION_IDLE || s->stalled ? s->pos : motion_pos(s, now);
    s->motion = MOTION_HOME;
    s->t0 = now;
    s->dur = s->p.home_time_s;
    s->homed = s->motion_error = s->stalled = false;
    s->fault_at = -1;
    return 0;
}

static int sim_start_move_abs(rig_turntable_t *t, double angle_deg)
{
    sim_t *s = S(t);
    double now = sim_now(s);
    advance(s, now);
    if (s->disconnected) return gone(t);
    if (!s->homed)
        return rig_fail(RIG_ERR_NOT_HOMED, "%s: the stage is not homed, so its angle is unknown: home it first "
                        "(rig_turntable_home)", t->name);
    double p = s->motion == MOTION_IDLE || s->stalled ? s->pos : motion_pos(s, now);
    s->p0 = p;
    s->target = angle_deg;
    s->final_pos = angle_deg + s->p.position_noise_deg * gauss(s);
    s->dist = fabs(angle_deg - p);
    s->dir = angle_deg >= p ? 1 : -1;
    s->t0 = now;
    s->dur = rig_motion_time_s(s->dist, s->p.speed_deg_s, s->p.accel_deg_s2);
    s->motion = MOTION_MOVE;
    s->motion_error = s->stalled = false;
    s->fault_at = -1;
    if (s->p.fault_after_moves > 0 && !s->fault_fired && s->completed_moves >= s->p.fault_after_moves)
        s->fault_at = now + 0.5 * s->dur;
    return 0;
}

static int sim_wait(rig_turntable_t *t, double timeout_s)
{
    sim_t *s = S(t);
    double deadline = model_now_s() + timeout_s;
    double t_min = 0;   // sim time reached for sure (a motion's end we slept to)
    for (;;) {
        double now = fmax(sim_now(s), t_min);
        int f = advance(s, now);
        if (f == RIG_ERR_DISCONNECTED || s->disconnected) return gone(t);
        if (f == RIG_ERR_MOTION)
            return rig_fail(RIG_ERR_MOTION, "%s: motion error at %.3f deg (simulated fault): the stage stalled or "
                            "lost position; check for obstructions, then home it again", t->name, s->pos);
        if (s->motion == MOTION_IDLE) return 0;
        // when does it end (or fault)?
        double end = s->motion == MOTION_DECEL ? s->t0 + s->v0 / s->p.accel_deg_s2 : s->t0 + s->dur;
        if (s->fault_at >= 0) end = fmin(end, s->fault_at);
        if (s->stalled) end = INFINITY;
        double real_left = (end - now) * s->p.time_scale, remaining = deadline - model_now_s();
        if (real_left > remaining) {
            sleep_real(remaining);
            advance(s, sim_now(s));
            return rig_fail(RIG_ERR_TIMEOUT, "%s: %s did not finish within %.2f s (at %.3f deg): give it more "
                            "time, or check that nothing blocks the stage; it may still be moving "
                            "(rig_turntable_stop halts it)", t->name,
                            s->motion == MOTION_HOME ? "homing" : "the move", timeout_s,
                            s->stalled || s->motion == MOTION_IDLE ? s->pos : motion_pos(s, sim_now(s)));
        }
        sleep_real(real_left);
        t_min = end;
    }
}

// Begins the stop: immediate (or at no speed) it stands at once, else it
// decelerates (MOTION_DECEL) and sim_wait waits for the end.
static int sim_start_stop(rig_turntable_t *t, bool immediate)
{
    sim_t *s = S(t);
    double now = sim_now(s);
    advance(s, now);
    if (s->disconnected) return gone(t);
    if (s->motion == MOTION_IDLE) return 0;
    double p = s->stalled ? s->pos : motion_pos(s, now);
    double v = s->motion == MOTION_MOVE && !s->stalled
                   ? trap_speed(s->dist, s->p.speed_deg_s, s->p.accel_deg_s2, now - s->t0) : 0;
    s->fault_at = -1;
    s->stalled = false;
    if (immediate || v == 0) {
        s->pos = p;
        s->motion = MOTION_IDLE;
        return 0;
    }
    s->motion = MOTION_DECEL;
    s->p0 = p;
    s->v0 = v;
    s->t0 = now;
    return 0;
}

static int sim_stop(rig_turntable_t *t, bool immediate)
{
    sim_t *s = S(t);
    int r = sim_start_stop(t, immediate);
    if (r || s->motion != MOTION_DECEL) return r;
    double now = s->t0;
    sleep_real(s->v0 / s->p.accel_deg_s2 * s->p.time_scale);
    advance(s, fmax(sim_now(s), now + s->v0 / s->p.accel_deg_s2));
    return 0;
}

static void sim_close(rig_turntable_t *t)
{
    if (t) free(t->impl);
    free(t);
}

static const rig_turntable_ops_t sim_ops = {
    .backend = "sim",
    .info = sim_info,
    .status = sim_status,
    .start_home = sim_start_home,
    .start_move_abs_deg = sim_start_move_abs,
    .start_move_rel_deg = NULL,   // the wrapper moves to status + delta
    .wait = sim_wait,
    .stop = sim_stop,
    .start_stop = sim_start_stop,
    .close = sim_close,
};

rig_turntable_sim_params_t rig_turntable_sim_defaults(void)
{
    return (rig_turntable_sim_params_t){
        .speed_deg_s = 10,
        .accel_deg_s2 = 10,
        .home_time_s = 15,          // K10CR1 homes at about 10 deg/s over up to a turn
        .position_noise_deg = 0.002,
        .time_scale = 1,
        .seed = 1,
        .fault_after_moves = 0,
        .fault = 0,
    };
}

int rig_turntable_open_sim(rig_turntable_t **out, const rig_turntable_sim_params_t *p)
{
    if (!out) return rig_fail(RIG_ERR_INVALID, "sim turntable: NULL output handle");
    *out = NULL;
    rig_turntable_sim_params_t d = p ? *p : rig_turntable_sim_defaults();
    const char *bad = NULL;
    if (!(isfinite(d.speed_deg_s) && d.speed_deg_s > 0)) bad = "speed_deg_s must be > 0";
    else if (!(isfinite(d.accel_deg_s2) && d.accel_deg_s2 > 0)) bad = "accel_deg_s2 must be > 0";
    else if (!(isfinite(d.home_time_s) && d.home_time_s >= 0)) bad = "home_time_s must be >= 0";
    else if (!(isfinite(d.position_noise_deg) && d.position_noise_deg >= 0)) bad = "position_noise_deg must be >= 0";
    else if (!(isfinite(d.time_scale) && d.time_scale > 0)) bad = "time_scale must be > 0";
    else if (d.fault_after_moves < 0) bad = "fault_after_moves must be >= 0";
    else if (d.fault_after_moves > 0 && d.fault != RIG_ERR_MOTION && d.fault != RIG_ERR_TIMEOUT &&
             d.fault != RIG_ERR_DISCONNECTED)
        bad = "fault must be RIG_ERR_MOTION, RIG_ERR_TIMEOUT or RIG_ERR_DISCONNECTED";
    if (bad) return rig_fail(RIG_ERR_INVALID, "sim turntable: %s", bad);
    rig_turntable_t *t = calloc(1, sizeof *t);
    sim_t *s = calloc(1, sizeof *s);
    if (!t || !s) {
        free(t);
        free(s);
        return rig_fail(RIG_ERR_NO_MEM, "sim turntable: out of memory");
    }
    s->p = d;
    s->t_origin_s = model_now_s();
    s->fault_at = -1;
    s->rng = d.seed;
    t->ops = &sim_ops;
    t->impl = s;
    snprintf(t->name, sizeof t->name, "sim turntable (seed %llu)", (unsigned long long)d.seed);
    *out = t;
    return 0;
}

bool rig_turntable_sim_destination(rig_turntable_t *t, double *angle_deg)
{
    if (!t || !t->ops || strcmp(t->ops->backend, "sim") || !t->impl) return false;
    sim_t *s = S(t);
    advance(s, sim_now(s));
    if (s->disconnected || s->motion != MOTION_MOVE || s->stalled || s->fault_at >= 0) return false;
    if (angle_deg) *angle_deg = s->final_pos;
    return true;
}
