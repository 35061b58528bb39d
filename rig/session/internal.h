// rig/session/internal.h — inside the capture session runner (rig/session/):
// the run's state, the writer's queue, the stages' results and the functions
// the runner's files share (capture.c the stages, motion.c signals and
// motions, writer.c the writer thread, facts.c the session facts, resume.c
// what --resume checks and recovers, steps.c the step loop, progress.c the
// progress line).
#pragma once

#include <pthread.h>
#include <signal.h>
#include <stdbool.h>
#include <stdint.h>

#include <jansson.h>

#include "model/model.h"
#include "rig/rig.h"

// The writer's queue: at least QUEUE_MIN frames, more while their pixels stay
// under QUEUE_BYTES (a burst of frames at one angle is then written during
// the next motion instead of holding up the capture).
#define QUEUE_MIN   4
#define QUEUE_BYTES ((size_t)128 << 20)

// ---------------------------------------------------------------------------
// Signals (motion.c): from capture_sigint_install on, the first SIGINT is
// counted (the session pauses), a second one hands over to the handler
// installed before, rig_safety_install's (lamps off, the process ends);
// capture_sigint_restore puts that handler back.

void capture_sigint_install(void);
void capture_sigint_restore(void);
bool capture_interrupted(void);

// ---------------------------------------------------------------------------
// The writer thread (writer.c)

typedef struct job {
    rig_frame_t  f;
    rig_step_t   step;
    int          cam;           // the rig's camera (r->cameras[cam])
    bool         step_done;     // the step's last camera: its commit marks the step done
    double       t_trigger_s, measured_deg;
    double       mean, max, roi_max, sat;
    size_t       bytes;         // of the pixels (the writer's queue budget)
    bool         stats_done;    // else the writer computes them (the main thread needs them only for auto bracketing)
    struct job  *next;
} job_t;

typedef struct {
    pthread_mutex_t m;
    pthread_cond_t  cv;
    job_t          *head, *tail;
    int             depth;
    size_t          bytes;          // pixel bytes queued
    bool            closing;
    int             err;            // first write error (RIG_ERR_*), the writer stops at it
    char            msg[10000];
    bool            disk_full;
    int             written;
    rig_journal_t  *j;
    const char     *dir;
    const rig_t    *rig;
    const rig_plan_t *plan;
    const char     *cmdline;
} writer_t;

void   capture_frame_stats(const rig_frame_t *f, const int roi[4], double *mean, double *max, double *roi_max,
                           double *sat);
void  *capture_writer_main(void *arg);
// Queue a frame (waits while the queue is full, see QUEUE_BYTES). Takes the frame's pixels.
void   capture_writer_push(writer_t *w, job_t *jb);
int    capture_writer_error(writer_t *w, char *msg, size_t size);

// ---------------------------------------------------------------------------
// Progress (progress.c)

typedef struct {
    bool   bar;
    double t0;
    int    total, done0;
    int    nrun;            // steps carried out in this run
    double t1;              // when the first of them ended
} progress_t;

void capture_progress(progress_t *pg, int done, const rig_step_t *s, int remaining, double remaining_floor_s);
// Whether the progress is a bar (o->progress 1, or -1 on a terminal) or a note a step.
bool capture_progress_bar(const rig_capture_opts_t *o);

// ---------------------------------------------------------------------------
// The run (capture.c)

enum {
    RUN_ON,           // next stage / next step
    RUN_DONE,         // clean up and return exit_code
    RUN_BREAK,        // leave the step loop (pause, writer error), then the end stage
    RUN_FAULT_TT,     // turntable fault (rc): stop the session
    RUN_FAULT_CAM,    // camera fault (rc): stop the session
};

typedef struct {
    const rig_capture_opts_t *o;
    int         rc, exit_code;
    rig_plan_t *p;
    rig_t      *r;
    rig_journal_t *j;
    char       *status, *facts, *rig_text;
    char       *s_plan_path, *s_plan_text, *s_plan_sha;
    char       *s_rig_path, *s_rig_text, *s_rig_sha;
    writer_t    w;
    bool        writer_running, sig_installed;
    pthread_t   wt;
    const char *rig_path;
    int         frames_before;
    bool       *satisfied;       // auto bracketing: the groups already satisfied (a frame at or below target)
    uint32_t   *cam_done;        // per step: bit k set when camera k's frame is journalled (--resume)
    int         step;
    char        msg[10000];
    // The steps' state
    double      full;            // full scale of the camera's pixel format, DN
    progress_t  pg;
    int         first;
    bool        home_pending;    // the stage homes before the first frame (after leading operator steps)
    double      floor_s, angle, t_start;
    uint32_t    mask;
    double      cur_exposure;
    int         paused;          // 1 SIGINT, 2 camera not answering, 3 operator step, 4 operator error,
                                 // 5 SIGINT during homing or a move (msg set)
    rig_operator_t *op_own;      // the terminal's reader when o->op is NULL
    double      t_operator;      // waiting for the operator (not in the wall time)
    double      t_homing;        // homing after the operator's first steps (not in the wall time either)
    double      T_cap, T_push;   // time in the camera (trigger to frame in hand), waiting for the writer
    double      wall_s;          // the run's wall time without the operator's and homing (run_end)
    bool        was_complete;    // --resume of a complete session: nothing to do
} run_t;

int  capture_fault_stop(rig_t *r, rig_journal_t *j, int step, const char *state, const char *kind, const char *msg);
void capture_writer_close(run_t *x);

// Session facts (facts.c)
json_t *capture_calibration_files(const char *dir, const rig_t *r);
char   *capture_session_facts(rig_t *r, const rig_plan_t *p, const char *cmdline, json_t *calibrations);

// --resume (resume.c)
int capture_recover_frames(rig_journal_t *j, const char *dir, int *relinked, int *removed);
int capture_check_camera(run_t *x);
int capture_replay_operator(run_t *x);

// Motions (motion.c)
int capture_motion_paused(run_t *x, const char *during, const char *resume_does);
int capture_home_turntable(run_t *x);
int capture_watched_motion(rig_t *r, bool home, double angle_deg, double timeout_s, double eta_s, bool bar);

// The steps (steps.c)
int capture_run_steps(run_t *x);
