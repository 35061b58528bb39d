// rig/session/steps.c — the capture's step loop: each pending step's motion,
// exposure and lamps, its frames (a camera that does not answer is retried),
// operator steps, auto bracketing.
#define _GNU_SOURCE
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <glib.h>

#include "model/model.h"
#include "rig/rig.h"
#include "rig/session/internal.h"

// The lamps failed (x->rc): the session stops, the message is the run's error.
static int lamps_fault(run_t *x)
{
    snprintf(x->msg, sizeof x->msg, "lamps: %s", model_last_error());
    capture_fault_stop(x->r, x->j, x->step, "fault", "fault", x->msg);
    rig_fail(x->rc, "%s", x->msg);
    return RUN_DONE;
}

// A step's motion, then its exposure and lamps during the settle; waits out
// the settle.
static int step_setup(run_t *x, const rig_step_t *s)
{
    rig_t *r = x->r;
    rig_plan_t *p = x->p;
    double t_settle = 0;
    if (r->turntable && !(s->angle_deg == x->angle)) {
        rig_turntable_status_t st;
        if ((x->rc = rig_turntable_status(r->turntable, &st))) return RUN_FAULT_TT;
        double tm = rig_motion_time_s(s->angle_deg - st.angle_deg, r->speed_deg_s, r->accel_deg_s2);
        if (isfinite(x->angle)) x->floor_s += tm;
        x->rc = capture_watched_motion(r, false, s->angle_deg, 1.5 * (isfinite(tm) ? tm : 120) + 5, tm, false);
        if (x->rc == RIG_ERR_INTERRUPTED) {
            char during[64];
            snprintf(during, sizeof during, "the move to %.4g deg", s->angle_deg);
            return capture_motion_paused(x, during, "moves there");
        }
        if (x->rc) return RUN_FAULT_TT;
        x->angle = s->angle_deg;
        t_settle = model_now_s() + 1e-3 * p->settle_ms;
    }
    // The exposure register now: its round trip overlaps the settles.
    if (s->exposure_us != x->cur_exposure) {
        for (int k = 0; k < r->ncameras; k++)
            if ((x->rc = rig_camera_set_exposure_us(r->cameras[k], s->exposure_us))) return RUN_FAULT_CAM;
        x->cur_exposure = s->exposure_us;
    }
    double lamp_t = 0;
    if (r->lamps && s->lamp_mask != x->mask) {
        lamp_t = rig_lamps_settle_s(r->lamps, x->mask, s->lamp_mask) + 1e-3 * p->lamp_settle_ms;
        if ((x->rc = rig_lamps_set(r->lamps, s->lamp_mask))) return lamps_fault(x);
        x->mask = s->lamp_mask;
        if (p->lamp_settle_ms > 0) g_usleep((gulong)(1e3 * p->lamp_settle_ms));
    }
    x->floor_s += fmax(t_settle > 0 ? 1e-3 * p->settle_ms : 0, lamp_t) + 1e-6 * s->exposure_us;
    double left = t_settle - model_now_s();
    if (t_settle > 0 && left > 0) g_usleep((gulong)(left * 1e6));
    return RUN_ON;
}

// Camera k's frame of a step into jb->f (a camera that does not answer is
// retried, then the session pauses): RUN_ON, RUN_BREAK or RUN_FAULT_CAM.
static int capture_camera(run_t *x, const rig_step_t *s, int k, job_t *jb)
{
    rig_t *r = x->r;
    rig_plan_t *p = x->p;
    int step = x->step, tries = 0;
    const char *cn = r->ncameras > 1 ? r->camera_names[k] : "";
    for (;;) {
        jb->t_trigger_s = model_realtime_s();
        bool q = model_error_quiet_thread(true);
        x->rc = rig_camera_capture(r->cameras[k], p->frame_timeout_s + 2e-6 * s->exposure_us, 0, &jb->f);
        model_error_quiet_thread(q);
        if (!x->rc) return RUN_ON;
        if (x->rc != RIG_ERR_TIMEOUT || tries >= p->retries || capture_interrupted()) break;
        tries++;
        rig_journal_event(x->j, step, "retry", "camera %stime-out (%s): retry %d of %d", r->ncameras > 1 ? cn : "",
                          model_last_error(), tries, p->retries);
        model_note("camera %s%stime-out at step %d: retry %d of %d", cn, *cn ? " " : "", step, tries, p->retries);
    }
    if (x->rc == RIG_ERR_TIMEOUT || x->rc == RIG_ERR_DISCONNECTED) {
        snprintf(x->msg, sizeof x->msg, "camera %s did not answer at step %d after %d retries (%s): session "
                 "paused; check the camera's cable and power, then refl capture --resume %s",
                 rig_camera_name(r->cameras[k]), step, tries, model_last_error(), x->o->dir);
        capture_fault_stop(r, x->j, step, "paused", "pause", x->msg);
        x->paused = 2;
        return RUN_BREAK;
    }
    return RUN_FAULT_CAM;
}

// A step's frames: every camera whose frame the journal lacks, one after the
// other (the rig file's order), their statistics for auto bracketing, each
// handed to the writer (the last marks the step done).
static int step_capture(run_t *x, const rig_step_t *s)
{
    rig_t *r = x->r;
    rig_plan_t *p = x->p;
    int step = x->step, last = -1;
    for (int k = 0; k < r->ncameras; k++)
        if (!((x->cam_done[step] >> k) & 1)) last = k;
    bool low = true;
    for (int k = 0; k <= last; k++) {
        if ((x->cam_done[step] >> k) & 1) continue;
        double T_cap0 = model_now_s();
        job_t *jb = calloc(1, sizeof *jb);
        if (!jb) {
            x->rc = rig_fail(RIG_ERR_NO_MEM, "out of memory at step %d", step);
            return RUN_FAULT_CAM;
        }
        int c = capture_camera(x, s, k, jb);
        if (c != RUN_ON) {
            free(jb);
            return c;
        }
        x->T_cap += model_now_s() - T_cap0;
        jb->step = *s;
        jb->cam = k;
        jb->step_done = k == last;
        rig_turntable_status_t st = { .angle_deg = NAN };
        if (r->turntable) rig_turntable_status(r->turntable, &st);
        jb->measured_deg = r->turntable ? st.angle_deg : NAN;
        if (p->auto_exposure && s->group >= 0) {
            capture_frame_stats(&jb->f, p->roi, &jb->mean, &jb->max, &jb->roi_max, &jb->sat);
            jb->stats_done = true;
            low &= jb->roi_max <= p->target_fraction * x->full;
        }
        double T_p0 = model_now_s();
        capture_writer_push(&x->w, jb);
        x->T_push += model_now_s() - T_p0;
        x->cam_done[step] |= 1u << k;
    }
    if (p->auto_exposure && s->group >= 0 && low) x->satisfied[s->group] = true;
    int remaining = 0;
    for (int i = step + 1; i < p->nsteps; i++) remaining += x->status[i] == 'p';
    capture_progress(&x->pg, step + 1, s, remaining, x->pg.nrun == 0 ? rig_plan_floor_s(p, r, step + 1) : 0);
    return RUN_ON;
}

// An operator step: lamps off, the instruction, the operator's answer. An
// answered step has its pose applied (the virtual rig plays the operator) and
// is journalled done with how it was answered; otherwise the session pauses
// (x->paused 3), or stops on a bad answer (x->paused 4: an error, exit 1).
static int step_operator(run_t *x, const rig_step_t *s)
{
    rig_t *r = x->r;
    int step = x->step;
    if (r->lamps && x->mask) {
        if ((x->rc = rig_lamps_all_off(r->lamps))) return lamps_fault(x);
        x->mask = 0;
    }
    if (x->pg.bar) model_progress_end();
    char how[1024], what[512];
    const char *dir = x->o->dir;
    double t0 = model_now_s();
    int a = rig_operator_ask(x->o->op ? x->o->op : x->op_own, step, x->p->ops[s->op].instruction, how, sizeof how);
    x->t_operator += model_now_s() - t0;
    if (a == RIG_OPERATOR_PAUSE) {
        snprintf(x->msg, sizeof x->msg, "operator step %d not answered (%s): session paused, lamps off; when it is "
                 "done, continue with refl capture --resume %s (Enter on a terminal answers it, or add --yes or "
                 "--operator-input FILE)", step, how, dir);
        capture_fault_stop(r, x->j, step, "paused", "pause", x->msg);
        x->paused = 3;
        return RUN_BREAK;
    }
    if (a == RIG_OPERATOR_DONE && !(a = rig_plan_operator_pose(x->p, r, step, what, sizeof what))) {
        char *note = g_strdup_printf("%s; %s", how, what);
        a = rig_journal_operator_done(x->j, step, note);
        g_free(note);
    }
    if (a) {
        x->rc = a;
        snprintf(x->msg, sizeof x->msg, "operator step %d: %s: session paused, lamps off; continue with refl "
                 "capture --resume %s", step, model_last_error(), dir);
        capture_fault_stop(r, x->j, step, "paused", "pause", x->msg);
        x->paused = 4;
        return RUN_BREAK;
    }
    x->status[step] = 'd';
    model_note("operator step %d done; %s", step, what);
    return RUN_ON;
}

// Every pending step, until the end, a pause (SIGINT) or a writer error.
int capture_run_steps(run_t *x)
{
    rig_plan_t *p = x->p;
    for (x->step = x->first; x->step < p->nsteps; x->step++) {
        const rig_step_t *s = &p->steps[x->step];
        if (x->status[x->step] != 'p') continue;
        if (capture_interrupted()) {
            x->paused = 1;
            break;
        }
        if (capture_writer_error(&x->w, x->msg, sizeof x->msg)) break;
        if (x->o->before_step) x->o->before_step(x->o->hook_ctx, x->r, x->step);
        if (s->kind == RIG_STEP_OPERATOR) {
            int k = step_operator(x, s);
            if (k == RUN_BREAK) break;
            if (k != RUN_ON) return k;
            continue;
        }
        if (p->auto_exposure && s->group >= 0 && x->satisfied[s->group]) {
            rig_journal_step_skipped(x->j, x->step, "auto bracketing: a shorter exposure is not needed");
            continue;
        }
        int k = x->home_pending ? capture_home_turntable(x) : RUN_ON;
        if (k == RUN_ON) k = step_setup(x, s);
        if (k == RUN_ON) k = step_capture(x, s);
        if (k == RUN_BREAK) break;
        if (k != RUN_ON) return k;
    }
    return RUN_ON;
}
