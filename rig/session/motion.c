// rig/session/motion.c — the session's turntable motions: homing and moves,
// watched (progress, ETA) and interruptible (SIGINT), and the SIGINT handler
// of a session.
//
// Signals: the first SIGINT finishes the current frame, switches the lamps
// off and marks the session paused (exit 3); a second one hands over to
// rig_safety_install's handler (lamps off at once, process ends; the journal
// stays consistent and --resume continues). During homing or a move the first
// SIGINT stops the stage (profiled stop) and pauses with no frame taken; a
// second one stops it at once, then hands over (the handler cannot talk to
// the stage itself, so the motion's wait does).
#define _GNU_SOURCE
#include <math.h>
#include <signal.h>
#include <stdio.h>

#include "model/model.h"
#include "rig/rig.h"
#include "rig/session/internal.h"

// ---------------------------------------------------------------------------
// Signals

static volatile sig_atomic_t g_sigint;      // SIGINTs since capture_sigint_install
static volatile sig_atomic_t g_in_motion;   // a watched turntable wait runs (it sees the second SIGINT)
static struct sigaction g_old_int;          // the handler before (rig_safety_install's)

static void sigint_hand_over(int sig)
{
    sigaction(SIGINT, &g_old_int, NULL);
    if (g_old_int.sa_handler != SIG_IGN && g_old_int.sa_handler != SIG_DFL && g_old_int.sa_handler)
        g_old_int.sa_handler(sig);
    else
        raise(sig);
}

static void on_sigint(int sig)
{
    if (++g_sigint >= 2 && !g_in_motion) sigint_hand_over(sig);
}

void capture_sigint_install(void)
{
    g_sigint = 0;
    struct sigaction sa = { .sa_handler = on_sigint };
    sigemptyset(&sa.sa_mask);
    sigaction(SIGINT, &sa, &g_old_int);
}

void capture_sigint_restore(void) { sigaction(SIGINT, &g_old_int, NULL); }

bool capture_interrupted(void) { return g_sigint > 0; }

// Homing progress: "homing... 4 s of ~15 s (ETA 11 s) at 123.4 deg", a
// progress line (bar) or a note.
typedef struct {
    bool        bar;
    const char *what;
    double      eta_s;
    bool        printed;
} motion_progress_t;

static void motion_progress(void *ctx, double elapsed_s, double angle_deg)
{
    motion_progress_t *m = ctx;
    char eta[64] = "";
    if (isfinite(m->eta_s) && m->eta_s > 0)
        snprintf(eta, sizeof eta, " of ~%.0f s (ETA %.0f s)", m->eta_s, fmax(0, m->eta_s - elapsed_s));
    if (m->bar) model_progress("%s... %.0f s%s at %.1f deg", m->what, elapsed_s, eta, angle_deg);
    else model_note("%s... %.0f s%s at %.1f deg", m->what, elapsed_s, eta, angle_deg);
    m->printed = true;
}

// Homing (home) or a move to angle_deg, interruptible: RIG_ERR_INTERRUPTED
// once the stage stands after a SIGINT (the message says where). A second
// SIGINT stops it at once and ends the process (the safety handler: lamps off).
int capture_watched_motion(rig_t *r, bool home, double angle_deg, double timeout_s, double eta_s, bool bar)
{
    char what[64];
    if (home) snprintf(what, sizeof what, "homing");
    else snprintf(what, sizeof what, "the move to %.4g deg", angle_deg);
    motion_progress_t mp = { .bar = bar, .what = what, .eta_s = eta_s };
    rig_turntable_watch_t w = {
        .interrupt = &g_sigint, .what = what, .stop_s = r->speed_deg_s / r->accel_deg_s2,
        // homing always shows progress; a move only once it runs long
        .progress = motion_progress, .ctx = &mp, .period_s = home ? (bar ? 0.5 : 5) : 5,
    };
    g_in_motion = 1;
    int rc = home ? rig_turntable_start_home(r->turntable) : rig_turntable_start_move_abs_deg(r->turntable, angle_deg);
    if (!rc) rc = rig_turntable_wait_watched(r->turntable, timeout_s, &w);
    g_in_motion = 0;
    if (mp.printed && bar) model_progress_end();
    if (rc == RIG_ERR_INTERRUPTED && g_sigint >= 2) {
        model_note("second interrupt: %s; ending now (lamps off; refl capture --resume continues)",
                   model_last_error());
        sigint_hand_over(SIGINT);
    }
    return rc;
}

// The first SIGINT during homing or a move: the stage stands; the session
// pauses (no frame was being taken) and run_end reports it (exit 3).
int capture_motion_paused(run_t *x, const char *during, const char *resume_does)
{
    snprintf(x->msg, sizeof x->msg, "interrupted (SIGINT) during %s: no frame was being taken; %s; lamps off, "
             "session paused before step %d of %d; continue with refl capture --resume %s (it %s again)", during,
             model_last_error(), x->step, x->p->nsteps, x->o->dir, resume_does);
    x->paused = 5;
    return RUN_BREAK;
}

// Homes the turntable unless it is homed (Ctrl-C stops it: the session pauses).
int capture_home_turntable(run_t *x)
{
    rig_t *r = x->r;
    x->home_pending = false;
    if (!r->turntable) return RUN_ON;
    rig_turntable_status_t st;
    if ((x->rc = rig_turntable_status(r->turntable, &st))) return RUN_FAULT_TT;
    if (st.homed) return RUN_ON;
    char up_to[48] = "";
    if (isfinite(r->home_time_s)) snprintf(up_to, sizeof up_to, "up to %.0f s; ", r->home_time_s);
    model_note("homing %s (%sCtrl-C stops it)", rig_turntable_name(r->turntable), up_to);
    double tmo = 1.5 * (isfinite(r->home_time_s) ? r->home_time_s : 120) + 5;
    bool bar = capture_progress_bar(x->o);
    double t0 = model_now_s();
    x->rc = capture_watched_motion(r, true, 0, tmo, r->home_time_s, bar);
    x->t_homing += model_now_s() - t0;
    if (x->rc == RIG_ERR_INTERRUPTED) return capture_motion_paused(x, "homing", "homes the stage");
    return x->rc ? RUN_FAULT_TT : RUN_ON;
}
