// rig/session/capture.c — the session runner of `refl capture` (see rig/rig.h,
// "Capture sessions"): the run's stages, from the plan to the summary.
//
// Pipeline: the main thread moves the turntable, switches the lamps (during the
// motion's settle) and captures (steps.c, motion.c); a writer thread
// (writer.c) computes the statistics, encodes the 16-bit PNG, flushes it,
// hashes it and commits the frame row (one SQLite transaction), then links the
// file to its final name (link(2): never overwrites) and removes the temporary
// one. A frame is therefore either committed with its file in place, or
// committed with only its temporary file (crash between commit and link:
// recovered on resume, resume.c), or not committed (its step is pending and is
// captured again; the stale temporary file is removed). Frames are named
// frames/sNNNNNN.png by step index. Signals: motion.c.
#define _GNU_SOURCE
#include <dirent.h>
#include <errno.h>
#include <fcntl.h>
#include <glib.h>
#include <jansson.h>
#include <math.h>
#include <pthread.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#include "model/model.h"
#include "rig/rig.h"
#include "rig/session/internal.h"

// ---------------------------------------------------------------------------

int capture_fault_stop(rig_t *r, rig_journal_t *j, int step, const char *state, const char *kind, const char *msg)
{
    bool q = model_error_quiet_thread(true);
    if (r->lamps) rig_lamps_all_off(r->lamps);
    model_error_quiet_thread(q);
    rig_journal_event(j, step, kind, "%s", msg);
    rig_journal_set_state(j, state);
    return 0;
}

static int mkdir_session(const char *dir)
{
    struct stat st;
    if (stat(dir, &st) == 0) {
        char db[4096];
        snprintf(db, sizeof db, "%s/session.sqlite", dir);
        if (stat(db, &st) == 0)
            return rig_fail(RIG_ERR_INVALID, "%s already holds a session: continue it with refl capture --resume "
                            "%s, or choose another -o DIR", dir, dir);
        DIR *d = opendir(dir);
        int n = 0;
        for (struct dirent *e; d && (e = readdir(d));) n += strcmp(e->d_name, ".") && strcmp(e->d_name, "..");
        if (d) closedir(d);
        if (n) return rig_fail(RIG_ERR_INVALID, "%s is not empty: a session needs a new or empty directory", dir);
    } else if (mkdir(dir, 0777) != 0) {
        return rig_fail(RIG_ERR_IO, "cannot create the session directory %s: %s", dir, strerror(errno));
    }
    char fr[4096];
    snprintf(fr, sizeof fr, "%s/frames", dir);
    if (mkdir(fr, 0777) != 0 && errno != EEXIST)
        return rig_fail(RIG_ERR_IO, "cannot create %s: %s", fr, strerror(errno));
    return 0;
}

static bool file_sha(const char *path, char out[65])
{
    bool q = model_error_quiet_thread(true);
    bool ok = model_sha256_file(path, out);
    model_error_quiet_thread(q);
    return ok;
}

// ---------------------------------------------------------------------------
// The run, in stages: the plan (new or resumed), the session (rig, journal,
// recovery), the writer and signals, the hardware (homing, camera), the steps,
// the end. Each stage returns RUN_ON to go on, or how the run ends.

// The plan: from the plan file, or (--resume) the journal's stored plan once
// the plan and rig files are checked against the journal's sha256.
static int run_plan(run_t *x)
{
    const rig_capture_opts_t *o = x->o;
    if (!o->resume) {
        if (!(x->p = rig_plan_load(o->plan_path))) {
            x->rc = RIG_ERR_INVALID;
            return RUN_DONE;
        }
        return RUN_ON;
    }
    if ((x->rc = rig_journal_resume(&x->j, o->dir))) return RUN_DONE;
    if ((x->rc = rig_journal_source(x->j, "plan", &x->s_plan_path, &x->s_plan_text, &x->s_plan_sha)) ||
        (x->rc = rig_journal_source(x->j, "rig", &x->s_rig_path, &x->s_rig_text, &x->s_rig_sha)))
        return RUN_DONE;
    char state[32] = "";
    rig_journal_state(x->j, state, sizeof state);
    if (!strcmp(state, "complete")) {
        x->was_complete = true;
        x->exit_code = 0;
        return RUN_DONE;
    }
    const char *pp = o->plan_path ? o->plan_path : x->s_plan_path;
    if (!x->rig_path) x->rig_path = x->s_rig_path;
    char sha[65];
    bool plan_same = file_sha(pp, sha) && !strcmp(sha, x->s_plan_sha);
    bool rig_same = file_sha(x->rig_path, sha) && !strcmp(sha, x->s_rig_sha);
    if ((!plan_same || !rig_same) && !o->allow_changed) {
        char *what = g_strdup_printf("%s%s%s%s%s", plan_same ? "" : "the plan file ", plan_same ? "" : pp,
                                     !plan_same && !rig_same ? " and " : "", rig_same ? "" : "the rig file ",
                                     rig_same ? "" : x->rig_path);
        x->rc = rig_fail(RIG_ERR_INVALID, "--resume %s: %s changed since the session started "
                         "(sha256 differs from the journal's, or the file is gone): resume with the original "
                         "files, or add --allow-changed to continue the stored step list anyway", o->dir, what);
        g_free(what);
        return RUN_DONE;
    }
    // The stored plan text defines the steps (identical to the first run).
    if (!(x->p = rig_plan_parse(x->s_plan_text, strlen(x->s_plan_text), x->s_plan_path))) {
        x->rc = RIG_ERR_INVALID;
        return RUN_DONE;
    }
    if (!plan_same || !rig_same)
        rig_journal_event(x->j, -1, "info", "resumed with changed %s%s (--allow-changed)", plan_same ? "" : "plan ",
                          rig_same ? "" : "rig");
    return RUN_ON;
}

// The rig (opened, the plan bound to it), the session
// directory and journal (created, or on --resume its frames recovered), the
// steps' status.
static int run_session(run_t *x)
{
    const rig_capture_opts_t *o = x->o;
    rig_plan_t *p = x->p;
    model_note("opening the rig %s", x->rig_path);
    if ((x->rc = rig_open(&x->r, x->rig_path))) return RUN_DONE;
    if (o->resume && (x->rc = capture_check_camera(x))) return RUN_DONE;
    if ((x->rc = rig_plan_bind(p, x->r))) return RUN_DONE;
    size_t rlen = 0;
    if (!(x->rig_text = model_read_file(x->rig_path, &rlen))) {
        x->rc = RIG_ERR_IO;
        return RUN_DONE;
    }
    if (!o->resume) {
        if ((x->rc = mkdir_session(o->dir))) return RUN_DONE;
        if (o->operator_name) snprintf(p->operator_name, sizeof p->operator_name, "%s", o->operator_name);
        if (o->notes) snprintf(p->notes, sizeof p->notes, "%s", o->notes);
        json_t *cal = NULL;
        if (o->calib_dir && !(cal = capture_calibration_files(o->calib_dir, x->r))) {
            x->rc = RIG_ERR_INVALID;
            return RUN_DONE;
        }
        x->facts = capture_session_facts(x->r, p, o->command_line, cal);
        json_decref(cal);
        if (!x->facts) {
            x->rc = rig_fail(RIG_ERR_NO_MEM, "out of memory for the session facts");
            return RUN_DONE;
        }
        if ((x->rc = rig_journal_create(&x->j, o->dir, p, x->rig_path, x->rig_text, x->r->sha256, x->facts)))
            return RUN_DONE;
        rig_journal_event(x->j, -1, "start", "session started: %d steps, plan %s, rig %s", p->nsteps, p->path,
                          x->rig_path);
    }
    rig_step_t *stored = NULL;
    int nstored = 0;
    if ((x->rc = rig_journal_steps(x->j, &stored, &x->status, &nstored))) return RUN_DONE;
    rig_step_kind_t stored_kind0 = nstored > 0 ? stored[0].kind : RIG_STEP_OPERATOR;
    free(stored);
    if (nstored != p->nsteps) {
        bool before_operator = nstored > 0 && stored_kind0 != RIG_STEP_OPERATOR;
        x->rc = rig_fail(RIG_ERR_INVALID, "journal %s: %d steps stored, the plan makes %d%s", o->dir, nstored,
                         p->nsteps, before_operator ? " (the stored steps begin without the plan's operator step: "
                         "the session cannot continue under this plan; its frames stay readable; capture the rest "
                         "into a new session)" : "");
        return RUN_DONE;
    }
    if (o->resume) {
        int relinked, removed;
        if ((x->rc = capture_recover_frames(x->j, o->dir, &relinked, &removed))) return RUN_DONE;
        int pend = 0;
        for (int i = 0; i < nstored; i++) pend += x->status[i] == 'p';
        rig_journal_event(x->j, -1, "resume", "resumed: %d of %d steps pending (%d frames recovered, %d temporary "
                          "files removed)", pend, nstored, relinked, removed);
        model_note("resuming %s: %d of %d steps to go", o->dir, pend, nstored);
        rig_journal_set_state(x->j, "running");
        if (capture_replay_operator(x) != RUN_ON) return RUN_DONE;
    }
    rig_frame_row_t *rows = NULL;   // the frames journalled before this run (every camera's)
    if (!rig_journal_frames(x->j, &rows, &x->frames_before)) free(rows);
    return RUN_ON;
}

// The writer thread and the SIGINT handler (first Ctrl-C pauses).
static int run_start(run_t *x)
{
    x->w.j = x->j;
    x->w.rig = x->r;
    x->w.plan = x->p;
    x->w.cmdline = x->o->command_line;
    if (pthread_create(&x->wt, NULL, capture_writer_main, &x->w)) {
        x->rc = rig_fail(RIG_ERR_IO, "cannot start the writer thread");
        return RUN_DONE;
    }
    x->writer_running = true;
    capture_sigint_install();
    x->sig_installed = true;
    return RUN_ON;
}

static int run_hardware(run_t *x)
{
    rig_t *r = x->r;
    rig_plan_t *p = x->p;
    rig_frame_meta_t cam;
    for (int k = r->ncameras - 1; k >= 0; k--)   // every camera; cam: the first's settings
        if ((x->rc = rig_camera_set_pixel_format(r->cameras[k], p->pixel_format)) ||
            (x->rc = rig_camera_set_gain(r->cameras[k], p->gain)) ||
            (x->rc = rig_camera_settings(r->cameras[k], &cam)))
            return RUN_DONE;
    x->full = cam.bits >= 16 ? 65535 : (double)((1u << cam.bits) - 1);

    x->pg = (progress_t){ .bar = capture_progress_bar(x->o), .t0 = model_now_s(), .total = p->nsteps, .done0 = 0 };
    x->first = 0;
    while (x->first < p->nsteps && x->status[x->first] != 'p') x->first++;
    x->pg.done0 = x->first;
    // The stage homes now, or after the operator's steps that come first (the
    // operator sets the sample up before anything moves)
    x->home_pending = true;
    if (x->first >= p->nsteps || p->steps[x->first].kind != RIG_STEP_OPERATOR) {
        x->step = x->first;
        int k = capture_home_turntable(x);
        if (k != RUN_ON) return k;
    }
    x->floor_s = 0;
    x->angle = NAN;
    x->t_start = model_now_s();
    x->t_homing = 0;   // homing before this is not in the interval
    x->mask = r->lamps ? rig_lamps_on_mask(r->lamps) : 0;
    x->cur_exposure = cam.exposure_us;
    int ngroups = 0;
    for (int i = 0; i < p->nsteps; i++) ngroups = p->steps[i].group + 1 > ngroups ? p->steps[i].group + 1 : ngroups;
    x->satisfied = calloc((size_t)ngroups + 1, 1);
    x->cam_done = calloc((size_t)p->nsteps + 1, sizeof *x->cam_done);
    uint32_t *low = calloc((size_t)p->nsteps + 1, sizeof *low);
    if (!x->satisfied || !x->cam_done || !low) {
        free(low);
        x->rc = rig_fail(RIG_ERR_NO_MEM, "out of memory for the steps' state (%d steps)", p->nsteps);
        return RUN_DONE;
    }
    rig_frame_row_t *rows = NULL;
    int nr = 0;
    if (!rig_journal_frames(x->j, &rows, &nr)) {
        // a group is satisfied by a step whose every camera's frame is at or below the target
        uint32_t all = r->ncameras >= 32 ? 0xffffffffu : (1u << r->ncameras) - 1;
        for (int i = 0; i < nr; i++) {
            int k = rig_camera_find(r, rows[i].camera);
            if (k < 0 || rows[i].step < 0 || rows[i].step >= p->nsteps) continue;
            x->cam_done[rows[i].step] |= 1u << k;
            if (rows[i].roi_max <= p->target_fraction * x->full) low[rows[i].step] |= 1u << k;
        }
        for (int i = 0; p->auto_exposure && i < p->nsteps; i++)
            if (p->steps[i].group >= 0 && low[i] == all) x->satisfied[p->steps[i].group] = true;
    }
    free(low);
    free(rows);
    return RUN_ON;
}

// The end: the writer drained, then the session stopped (writer error),
// paused or complete, and the summary.
static int run_end(run_t *x)
{
    const rig_capture_opts_t *o = x->o;
    rig_plan_t *p = x->p;
    capture_writer_close(x);
    if (x->pg.bar) model_progress_end();
    // the operator's time is not the rig's, nor homing (before the first frame, as before operator steps)
    x->wall_s = model_now_s() - x->t_start - x->t_operator - x->t_homing;
    if (capture_writer_error(&x->w, x->msg, sizeof x->msg)) {
        capture_fault_stop(x->r, x->j, x->step, "stopped", "fault", x->msg);
        rig_fail(RIG_ERR_IO, "%s", x->msg);
        x->exit_code = 1;
        return RUN_DONE;
    }
    if (x->paused) {
        if (x->paused == 1 || x->paused == 5) {
            if (x->paused == 1)
                snprintf(x->msg, sizeof x->msg, "interrupted (SIGINT): the current frame was finished, lamps off, "
                         "session paused at step %d of %d; continue with refl capture --resume %s", x->step,
                         p->nsteps, o->dir);
            capture_fault_stop(x->r, x->j, x->step, "paused", "pause", x->msg);
        }
        if (x->paused == 4) {
            rig_fail(x->rc ? x->rc : RIG_ERR_INVALID, "%s", x->msg);
            x->exit_code = 1;
            return RUN_DONE;
        }
        // a pause is no error: the note says why and how to go on (camera not answering: also the error text)
        model_note("%s", x->msg);
        if (x->paused == 2) model_error_set(NULL, 0, "%s", x->msg);
        x->exit_code = 3;
        return RUN_DONE;
    }
    if (x->r->lamps) rig_lamps_all_off(x->r->lamps);
    rig_journal_event(x->j, -1, "complete", "session complete: %d frames this run, wall %.3f s, hardware floor %.3f "
                      "s", x->w.written, x->wall_s, x->floor_s);
    rig_journal_set_state(x->j, "complete");
    x->exit_code = 0;
    return RUN_DONE;
}

// A turntable or camera fault: the session stops (lamps off, stage stopped).
static void run_fault(run_t *x, bool turntable)
{
    if (turntable) {
        snprintf(x->msg, sizeof x->msg, "turntable fault at step %d: %s: session stopped, lamps off; after fixing "
                 "the stage, refl capture --resume %s", x->step, model_last_error(), x->o->dir);
        if (x->r && x->r->turntable) {
            bool q = model_error_quiet_thread(true);
            rig_turntable_stop(x->r->turntable, true);
            model_error_quiet_thread(q);
        }
    } else {
        snprintf(x->msg, sizeof x->msg, "camera fault at step %d: %s: session stopped, lamps off; refl capture "
                 "--resume %s", x->step, model_last_error(), x->o->dir);
    }
    if (x->j) capture_fault_stop(x->r, x->j, x->step, "fault", "fault", x->msg);
    rig_fail(x->rc, "%s", x->msg);
}

static void run_cleanup(run_t *x)
{
    if (x->writer_running) capture_writer_close(x);
    if (x->sig_installed) capture_sigint_restore();
    if (x->r && x->r->lamps && rig_lamps_on_mask(x->r->lamps)) {
        bool q = model_error_quiet_thread(true);
        rig_lamps_all_off(x->r->lamps);
        model_error_quiet_thread(q);
    }
    rig_close(x->r);
    rig_journal_close(x->j);
    rig_operator_close(x->op_own);
    rig_plan_free(x->p);
    free(x->status);
    free(x->satisfied);
    free(x->cam_done);
    free(x->facts);
    free(x->rig_text);
    free(x->s_plan_path);
    free(x->s_plan_text);
    free(x->s_plan_sha);
    free(x->s_rig_path);
    free(x->s_rig_text);
    free(x->s_rig_sha);
    pthread_mutex_destroy(&x->w.m);
    pthread_cond_destroy(&x->w.cv);
}

// What the run did, for the command's summary.
static void summarise(const run_t *x, rig_capture_summary_t *s)
{
    *s = (rig_capture_summary_t){
        .complete = x->exit_code == 0, .was_complete = x->was_complete, .steps = x->p ? x->p->nsteps : 0,
        .frames = x->frames_before + x->w.written, .frames_run = x->w.written,
        .auto_exposure = x->p && x->p->auto_exposure, .wall_s = x->wall_s, .floor_s = x->floor_s,
        .camera_s = x->T_cap, .writer_wait_s = x->T_push,
    };
}

int rig_capture_run(const rig_capture_opts_t *o)
{
    // run_t holds the writer's 10 kB message and the run's own: on the heap.
    run_t *x = calloc(1, sizeof *x);
    if (!x) {
        rig_fail(RIG_ERR_NO_MEM, "out of memory");
        return 1;
    }
    x->o = o;
    x->exit_code = 1;
    x->rig_path = o->rig_path;
    x->w.dir = o->dir;
    pthread_mutex_init(&x->w.m, NULL);
    pthread_cond_init(&x->w.cv, NULL);
    if (!o->op && !(x->op_own = rig_operator_open(false, NULL))) {
        free(x);
        return 1;
    }
    int k = run_plan(x);
    if (k == RUN_ON) k = run_session(x);
    if (k == RUN_ON) k = run_start(x);
    if (k == RUN_ON) k = run_hardware(x);
    if (k == RUN_ON) k = capture_run_steps(x);
    if (k == RUN_ON || k == RUN_BREAK) k = run_end(x);   // RUN_BREAK: paused while homing
    if (k == RUN_FAULT_TT || k == RUN_FAULT_CAM) run_fault(x, k == RUN_FAULT_TT);
    if (o->summary) summarise(x, o->summary);
    // the run's message outlives the cleanup (closing the devices may leave messages of its own)
    char *msg = x->exit_code == 1 || x->paused == 2 ? g_strdup(model_last_error()) : NULL;
    run_cleanup(x);
    if (msg) model_error_set(NULL, 0, "%s", msg);
    g_free(msg);
    int exit_code = x->exit_code;
    if (exit_code == 3) rig_operator_set_paused(o->op);
    free(x);
    return exit_code;
}
