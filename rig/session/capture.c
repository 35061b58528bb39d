// rig/session/capture.c — the session runner of `refl capture` (see rig/rig.h,
// "Capture sessions").
//
// Pipeline: the main thread moves the turntable, switches the lamps (during the
// motion's settle) and captures; a writer thread computes the statistics,
// encodes the 16-bit PNG, flushes it, hashes it and commits the frame row
// (one SQLite transaction), then links the file to its final name (link(2):
// never overwrites) and removes the temporary one. A frame is therefore
// either committed with its file in place, or committed with only its
// temporary file (crash between commit and link: recovered on resume), or not
// committed (its step is pending and is captured again; the stale temporary
// file is removed). Frames are named frames/sNNNNNN.png by step index.
//
// Signals: the first SIGINT finishes the current frame, switches the lamps
// off and marks the session paused (exit 3); a second one hands over to
// rig_safety_install's handler (lamps off at once, process ends; the journal
// stays consistent and --resume continues). During homing or a move the first
// SIGINT stops the stage (profiled stop) and pauses with no frame taken; a
// second one stops it at once, then hands over (the handler cannot talk to
// the stage itself, so the motion's wait does).
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

// The writer's queue: at least QUEUE_MIN frames, more while their pixels stay
// under QUEUE_BYTES (a burst of frames at one angle is then written during
// the next motion instead of holding up the capture).
#define QUEUE_MIN   4
#define QUEUE_BYTES ((size_t)128 << 20)

// ---------------------------------------------------------------------------
// Signals

static volatile sig_atomic_t g_sigint;
static volatile sig_atomic_t g_in_motion;   // a watched turntable wait runs (it sees the second SIGINT)
static struct sigaction g_old_int;

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

// Homing progress: "homing ... 4 s of ~15 s (ETA 11 s) at 123.4 deg".
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
    fprintf(stderr, "%srefl capture: %s... %.0f s%s at %.1f deg%s", m->bar ? "\r" : "", m->what, elapsed_s, eta,
            angle_deg, m->bar ? "   " : "\n");
    m->printed = true;
}

// Homing (home) or a move to angle_deg, interruptible: RIG_ERR_INTERRUPTED
// once the stage stands after a SIGINT (the message says where). A second
// SIGINT stops it at once and ends the process (the safety handler: lamps off).
static int watched_motion(rig_t *r, bool home, double angle_deg, double timeout_s, double eta_s, bool bar)
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
    if (mp.printed && bar) fprintf(stderr, "\n");
    if (rc == RIG_ERR_INTERRUPTED && g_sigint >= 2) {
        fprintf(stderr, "refl capture: second interrupt: %s; ending now (lamps off; refl capture --resume "
                "continues)\n", model_last_error());
        sigint_hand_over(SIGINT);
    }
    return rc;
}

// ---------------------------------------------------------------------------
// Writer thread

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

static double realtime_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_REALTIME, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

static void frame_stats(const rig_frame_t *f, const int roi[4], double *mean, double *max, double *roi_max,
                        double *sat)
{
    const rig_frame_meta_t *m = &f->meta;
    unsigned full = m->bits >= 16 ? 65535u : (1u << m->bits) - 1;
    size_t n = (size_t)m->width * m->height, nsat = 0;
    double sum = 0;
    unsigned hi = 0, rhi = 0;
    for (size_t i = 0; i < n; i++) {
        unsigned v = f->pix[i];
        sum += v;
        if (v > hi) hi = v;
        if (v >= full) nsat++;
    }
    int x0 = roi[2] ? roi[0] : 0, y0 = roi[2] ? roi[1] : 0;
    int w = roi[2] ? roi[2] : m->width, h = roi[2] ? roi[3] : m->height;
    if (x0 + w > m->width) w = m->width - x0;
    if (y0 + h > m->height) h = m->height - y0;
    for (int y = y0; y < y0 + h; y++)
        for (int x = x0; x < x0 + w; x++) {
            unsigned v = f->pix[(size_t)y * m->width + x];
            if (v > rhi) rhi = v;
        }
    *mean = n ? sum / (double)n : 0;
    *max = hi;
    *roi_max = rhi;
    *sat = n ? (double)nsat / (double)n : 0;
}

static bool fsync_path(const char *path, bool dir)
{
    int fd = open(path, (dir ? O_RDONLY | O_DIRECTORY : O_RDONLY) | O_CLOEXEC);
    if (fd < 0) return false;
    bool ok = fsync(fd) == 0;
    close(fd);
    return ok;
}

// frames/sNNNNNN.png (a rig of one camera) or frames/sNNNNNN_NAME.png, its
// temporary frames/.sNNNNNN[_NAME].png.part.
static void frame_names(const char *dir, int step, const rig_t *r, int cam, char *rel, size_t rsize, char *fin,
                        char *part, size_t size)
{
    char suffix[40] = "";
    if (r->ncameras > 1) snprintf(suffix, sizeof suffix, "_%s", r->camera_names[cam]);
    snprintf(rel, rsize, "frames/s%06d%s.png", step, suffix);
    snprintf(fin, size, "%s/%s", dir, rel);
    snprintf(part, size, "%s/frames/.s%06d%s.png.part", dir, step, suffix);
}


// Write one frame; 0 or RIG_ERR_*, message in w->msg.
static int write_frame(writer_t *w, job_t *jb)
{
    char rel[64], fin[4096], part[4096];
    frame_names(w->dir, jb->step.index, w->rig, jb->cam, rel, sizeof rel, fin, part, sizeof fin);
    const rig_frame_meta_t *m = &jb->f.meta;
    model_meta_t *meta = model_meta_new();
    model_meta_add(meta, "Software", "refl %s (refl capture)", REFL_VERSION);
    model_meta_add(meta, "units", "DN, the camera's pixel format %s (%d significant bits), unscaled", m->pixel_format,
             m->bits);
    model_meta_add(meta, "session_step", "%d", jb->step.index);
    model_meta_add(meta, "step_kind", "%s", jb->step.kind == RIG_STEP_DARK ? "dark" : "light");
    model_meta_add(meta, "camera", "%s", rig_camera_name(w->rig->cameras[jb->cam]));
    model_meta_add(meta, "camera_name", "%s (the rig file's camera)", w->rig->camera_names[jb->cam]);
    model_meta_add(meta, "camera_serial", "%s", m->serial);
    model_meta_add(meta, "frame_id", "%llu", (unsigned long long)m->frame_id);
    model_meta_add(meta, "exposure_us", "%.10g", m->exposure_us);
    model_meta_add(meta, "gain", "%.10g", m->gain);
    model_meta_add(meta, "gain_unit", "%s", m->gain_unit);
    if (isfinite(m->black_level)) model_meta_add(meta, "black_level", "%.10g", m->black_level);
    model_meta_add(meta, "gamma", "%.6g", m->gamma);
    if (isfinite(m->temperature_c)) model_meta_add(meta, "temperature_c", "%.2f", m->temperature_c);
    if (m->firmware[0]) model_meta_add(meta, "camera_firmware", "%s", m->firmware);
    model_meta_add(meta, "camera_settings", "%s", m->camera_settings);
    model_meta_add(meta, "turntable_commanded_deg", "%.10g", jb->step.angle_deg);
    model_meta_add(meta, "turntable_measured_deg", "%.6f", jb->measured_deg);
    model_meta_add(meta, "lamps_on", "%s", jb->step.lamps);
    model_meta_add(meta, "sample", "%s (%s)", w->plan->sample, w->plan->sample_kind);
    if (w->plan->tilt_deg != 0)
        model_meta_add(meta, "sample_tilt_deg", "%.10g about the hinge at azimuth %.10g deg", w->plan->tilt_deg,
                       w->plan->tilt_azimuth_deg);
    model_meta_add(meta, "plan_sha256", "%s", w->plan->sha256);
    model_meta_add(meta, "rig_sha256", "%s", w->rig->sha256);
    int rc = 0;
    struct stat st;
    if (stat(fin, &st) == 0) {
        snprintf(w->msg, sizeof w->msg, "%s already exists: refusing to overwrite it (step %d); run refl session "
                 "check %s", fin, jb->step.index, w->dir);
        rc = RIG_ERR_IO;
        goto done;
    }
    // zlib level 1 with the Sub filter: about 4x faster than libpng's default on
    // sensor frames at a few % more bytes (the writer must keep up with the
    // camera); flushed to the disk before the temporary name is renamed to part.
    const model_png_options_t popt = { .compression_level = 1, .fast_filter = true, .fsync = true, .quiet = true };
    if (!model_png16_write_opts(part, m->width, m->height, jb->f.pix, model_meta_list(meta), &popt)) {
        w->disk_full = errno == ENOSPC;
        if (w->disk_full)
            snprintf(w->msg, sizeof w->msg, "disk full writing step %d to %s (No space left on device): nothing "
                     "half-written is kept; free space, then refl capture --resume %s", jb->step.index, fin, w->dir);
        else
            snprintf(w->msg, sizeof w->msg, "%s", model_last_error());
        rc = RIG_ERR_IO;
        goto done;
    }
    rig_frame_row_t row = { .step = jb->step.index };
    snprintf(row.camera, sizeof row.camera, "%s", w->rig->camera_names[jb->cam]);
    snprintf(row.file, sizeof row.file, "%s", rel);
    if (!model_sha256_file(part, row.sha256)) {
        snprintf(w->msg, sizeof w->msg, "cannot read back %s: %s", part, model_last_error());
        rc = RIG_ERR_IO;
        goto done;
    }
    row.t_trigger_utc_s = jb->t_trigger_s;
    row.t_written_utc_s = realtime_s();
    row.commanded_deg = jb->step.angle_deg;
    row.measured_deg = jb->measured_deg;
    snprintf(row.lamps, sizeof row.lamps, "%s", jb->step.lamps);
    row.exposure_us = m->exposure_us;
    row.gain = m->gain;
    row.mean = jb->mean;
    row.max = jb->max;
    row.roi_max = jb->roi_max;
    row.saturated_fraction = jb->sat;
    row.width = m->width;
    row.height = m->height;
    snprintf(row.pixel_format, sizeof row.pixel_format, "%s", m->pixel_format);
    row.frame_id = m->frame_id;
    snprintf(row.gain_unit, sizeof row.gain_unit, "%s", m->gain_unit);
    row.black_level = m->black_level;
    row.gamma = m->gamma;
    row.temperature_c = m->temperature_c;
    snprintf(row.firmware, sizeof row.firmware, "%s", m->firmware);
    snprintf(row.camera_settings, sizeof row.camera_settings, "%s", m->camera_settings);
    rc = rig_journal_frame_done(w->j, &row, jb->step_done);
    if (rc) {
        w->disk_full = strstr(model_last_error(), "full") != NULL;
        snprintf(w->msg, sizeof w->msg, "%s%s", w->disk_full ? "disk full: " : "", model_last_error());
        unlink(part);
        goto done;
    }
    if (link(part, fin) != 0) {
        snprintf(w->msg, sizeof w->msg, "cannot link %s to %s: %s (the frame is committed; refl capture --resume "
                 "recovers it)", part, fin, strerror(errno));
        rc = RIG_ERR_IO;
        goto done;
    }
    unlink(part);
    char fdir[4096];
    snprintf(fdir, sizeof fdir, "%s/frames", w->dir);
    fsync_path(fdir, true);
done:
    model_meta_free(meta);
    return rc;
}

static void *writer_main(void *arg)
{
    writer_t *w = arg;
    for (;;) {
        pthread_mutex_lock(&w->m);
        while (!w->head && !w->closing) pthread_cond_wait(&w->cv, &w->m);
        job_t *jb = w->head;
        if (!jb) {
            pthread_mutex_unlock(&w->m);
            return NULL;
        }
        bool failed = w->err != 0;
        pthread_mutex_unlock(&w->m);
        if (!failed && !jb->stats_done)
            frame_stats(&jb->f, w->plan->roi, &jb->mean, &jb->max, &jb->roi_max, &jb->sat);
        int rc = failed ? 0 : write_frame(w, jb);
        pthread_mutex_lock(&w->m);
        w->head = jb->next;
        if (!w->head) w->tail = NULL;
        w->depth--;
        w->bytes -= jb->bytes;
        if (rc && !w->err) w->err = rc;
        if (!rc && !failed) w->written++;
        pthread_cond_broadcast(&w->cv);
        pthread_mutex_unlock(&w->m);
        rig_frame_free(&jb->f);
        free(jb);
    }
}

// Queue a frame (waits while the queue is full, see QUEUE_BYTES). Takes the frame's pixels.
static void writer_push(writer_t *w, job_t *jb)
{
    pthread_mutex_lock(&w->m);
    jb->bytes = (size_t)jb->f.meta.width * (size_t)jb->f.meta.height * sizeof *jb->f.pix;
    while (w->depth >= QUEUE_MIN && w->bytes + jb->bytes > QUEUE_BYTES && !w->err) pthread_cond_wait(&w->cv, &w->m);
    jb->next = NULL;
    if (w->tail) w->tail->next = jb;
    else w->head = jb;
    w->tail = jb;
    w->depth++;
    w->bytes += jb->bytes;
    pthread_cond_broadcast(&w->cv);
    pthread_mutex_unlock(&w->m);
}

static int writer_error(writer_t *w, char *msg, size_t size)
{
    pthread_mutex_lock(&w->m);
    int e = w->err;
    if (e && msg) snprintf(msg, size, "%s", w->msg);
    pthread_mutex_unlock(&w->m);
    return e;
}

// ---------------------------------------------------------------------------
// Session setup

// One calibration file of a directory (the first of the candidate paths that
// reads), entered by role, path, sha256 and, for a camera's own, the camera.
static void calibration_file(json_t *arr, const char *role, const char *const *cands, int n, const char *camera)
{
    for (int k = 0; k < n; k++) {
        char sha[65];
        if (access(cands[k], R_OK) != 0 || !model_sha256_file(cands[k], sha)) continue;
        json_t *e = json_object();
        json_object_set_new(e, "role", json_string(role));
        if (camera) json_object_set_new(e, "camera", json_string(camera));
        json_object_set_new(e, "path", json_string(cands[k]));
        json_object_set_new(e, "sha256", json_string(sha));
        json_array_append_new(arr, e);
        return;
    }
}

// The calibration files of a directory, by role: path and sha256; with several
// cameras also each camera's own (NAME.cameramodel, NAME/gain.json, NAME/white.json,
// directly or under geometry/, gain/, white/: calib/calset.c's layout). NULL
// with a message when the directory holds none of them.
static json_t *calibration_files(const char *dir, const rig_t *r)
{
    static const char *const files[][3] = {
        { "camera geometry", "geometry", "camera.cameramodel" }, { "geometry summary", "geometry", "geometry.json" },
        { "lamp positions", "lamps", "lamps.json" }, { "sensitivity", "gain", "gain.json" },
        { "reference white", "white", "white.json" },
    };
    json_t *arr = json_array();
    char *abs = realpath(dir, NULL);
    for (size_t i = 0; abs && i < sizeof files / sizeof files[0]; i++) {
        char *c[2] = { g_strdup_printf("%s/%s", abs, files[i][2]),
                       g_strdup_printf("%s/%s/%s", abs, files[i][1], files[i][2]) };
        calibration_file(arr, files[i][0], (const char *const *)c, 2, NULL);
        g_free(c[0]);
        g_free(c[1]);
    }
    for (int k = 0; abs && r && r->ncameras > 1 && k < r->ncameras; k++) {
        const char *nm = r->camera_names[k];
        char *g[3] = { g_strdup_printf("%s/%s.cameramodel", abs, nm), g_strdup_printf("%s/geometry/%s.cameramodel",
                       abs, nm), g_strdup_printf("%s/%s/camera.cameramodel", abs, nm) };
        char *s[2] = { g_strdup_printf("%s/%s/gain.json", abs, nm), g_strdup_printf("%s/gain/%s/gain.json", abs, nm) };
        char *w[2] = { g_strdup_printf("%s/%s/white.json", abs, nm), g_strdup_printf("%s/white/%s/white.json", abs,
                       nm) };
        calibration_file(arr, "camera geometry", (const char *const *)g, 3, nm);
        calibration_file(arr, "sensitivity", (const char *const *)s, 2, nm);
        calibration_file(arr, "reference white", (const char *const *)w, 2, nm);
        for (int i = 0; i < 3; i++) g_free(g[i]);
        for (int i = 0; i < 2; i++) {
            g_free(s[i]);
            g_free(w[i]);
        }
    }
    free(abs);
    if (json_array_size(arr) == 0) {
        json_decref(arr);
        rig_fail(RIG_ERR_INVALID, "--calib %s: no calibration files there (camera.cameramodel, lamps.json, gain.json, "
                 "white.json, or geometry/, lamps/, gain/, white/ holding them)", dir);
        return NULL;
    }
    return arr;
}

static char *session_facts(rig_t *r, const rig_plan_t *p, const char *cmdline, json_t *calibrations)
{
    json_t *o = json_object();
    json_object_set_new(o, "refl_version", json_string(REFL_VERSION));
    json_object_set_new(o, "command_line", json_string(cmdline ? cmdline : ""));
    json_object_set_new(o, "operator", json_string(p->operator_name));
    json_object_set_new(o, "notes", json_string(p->notes));
    // the calibrations in use (by path and hash; frames are stored raw)
    json_object_set_new(o, "calibrations", calibrations ? json_incref(calibrations) : json_array());
    // "camera": the first camera (as before several cameras), "cameras": every one
    json_t *cams = json_array();
    for (int k = 0; k < r->ncameras; k++) {
        rig_frame_meta_t m;
        if (rig_camera_settings(r->cameras[k], &m) != 0) continue;
        json_t *c = json_object();
        json_object_set_new(c, "camera", json_string(r->camera_names[k]));
        json_object_set_new(c, "name", json_string(rig_camera_name(r->cameras[k])));
        json_object_set_new(c, "backend", json_string(rig_camera_backend(r->cameras[k])));
        json_object_set_new(c, "vendor", json_string(m.vendor));
        json_object_set_new(c, "model", json_string(m.model));
        json_object_set_new(c, "serial", json_string(m.serial));
        json_object_set_new(c, "pixel_format", json_string(m.pixel_format));
        json_object_set_new(c, "bits", json_integer(m.bits));
        json_object_set_new(c, "width", json_integer(m.width));
        json_object_set_new(c, "height", json_integer(m.height));
        json_object_set_new(c, "offset_x", json_integer(m.offset_x));
        json_object_set_new(c, "offset_y", json_integer(m.offset_y));
        json_object_set_new(c, "exposure_us", json_real(m.exposure_us));
        json_object_set_new(c, "gain", json_real(m.gain));
        json_object_set_new(c, "gain_unit", json_string(m.gain_unit));
        if (isfinite(m.temperature_c)) json_object_set_new(c, "temperature_c", json_real(m.temperature_c));
        if (isfinite(m.black_level)) json_object_set_new(c, "black_level", json_real(m.black_level));
        json_object_set_new(c, "gamma", json_real(m.gamma));
        json_object_set_new(c, "firmware", json_string(m.firmware));
        json_object_set_new(c, "settings", json_string(m.camera_settings));   // what refl switched off at open
        if (k == 0) json_object_set_new(o, "camera", json_deep_copy(c));
        json_array_append_new(cams, c);
    }
    json_object_set_new(o, "cameras", cams);
    rig_turntable_info_t ti;
    if (r->turntable && rig_turntable_info(r->turntable, &ti) == 0) {
        json_t *t = json_object();
        json_object_set_new(t, "name", json_string(rig_turntable_name(r->turntable)));
        json_object_set_new(t, "model", json_string(ti.model));
        json_object_set_new(t, "serial", json_string(ti.serial));
        json_object_set_new(t, "firmware", json_string(ti.firmware));
        json_object_set_new(t, "speed_deg_s", json_real(r->speed_deg_s));
        json_object_set_new(t, "accel_deg_s2", json_real(r->accel_deg_s2));
        json_object_set_new(o, "turntable", t);
    }
    json_t *l = json_array();
    for (int i = 0; r->lamps && i < rig_lamps_count(r->lamps); i++) {
        json_t *a = json_object();
        json_object_set_new(a, "name", json_string(rig_lamps_name(r->lamps, i)));
        json_object_set_new(a, "backend", json_string(rig_lamps_backend(r->lamps)));
        json_object_set_new(a, "warmup_ms", json_real(rig_lamps_line(r->lamps, i)->warmup_ms));
        json_object_set_new(a, "settle_ms", json_real(rig_lamps_line(r->lamps, i)->settle_ms));
        json_array_append_new(l, a);
    }
    json_object_set_new(o, "lamps", l);
    if (r->virt) {
        json_t *v = json_object();
        char sha[65] = "";
        bool q = model_error_quiet_thread(true);
        if (!model_sha256_file(rig_virtual_truth_path(r->virt), sha)) snprintf(sha, sizeof sha, "unreadable");
        model_error_quiet_thread(q);
        json_object_set_new(v, "truth", json_string(rig_virtual_truth_path(r->virt)));
        json_object_set_new(v, "truth_sha256", json_string(sha));
        // the sample as the plan's operator step poses it (the frames' truth)
        json_object_set_new(v, "sample", json_string(p->sample));
        json_object_set_new(v, "sample_tilt_deg", json_real(p->tilt_deg));
        json_object_set_new(v, "sample_tilt_azimuth_deg", json_real(p->tilt_azimuth_deg));
        json_object_set_new(o, "virtual_rig", v);
    }
    char *s = json_dumps(o, JSON_INDENT(1) | JSON_SORT_KEYS);
    json_decref(o);
    return s;
}

// Put the frames directory in order after a crash: committed frames whose file
// was not yet linked are linked; temporary files of uncommitted frames removed.
static int recover_frames(rig_journal_t *j, const char *dir, int *relinked, int *removed)
{
    *relinked = *removed = 0;
    rig_frame_row_t *rows = NULL;
    int n = 0, rc = rig_journal_frames(j, &rows, &n);
    if (rc) return rc;
    char fd[4096];
    snprintf(fd, sizeof fd, "%s/frames", dir);
    DIR *d = opendir(fd);
    if (!d) {
        free(rows);
        return rig_fail(RIG_ERR_IO, "%s: %s", fd, strerror(errno));
    }
    struct dirent *e;
    while ((e = readdir(d))) {
        if (e->d_name[0] != '.' || !strcmp(e->d_name, ".") || !strcmp(e->d_name, "..")) continue;
        char path[4400];
        snprintf(path, sizeof path, "%s/%s", fd, e->d_name);
        int step = -1;
        size_t len = strlen(e->d_name);
        bool part = sscanf(e->d_name, ".s%d", &step) == 1 && len > 6 && !strcmp(e->d_name + len - 5, ".part") &&
                    !strstr(e->d_name, ".tmp");
        char rel[300] = "";   // its committed name: frames/sNNNNNN[_NAME].png
        if (part) snprintf(rel, sizeof rel, "frames/%.*s", (int)(len - 6), e->d_name + 1);
        const rig_frame_row_t *row = NULL;
        for (int i = 0; part && i < n; i++)
            if (!strcmp(rows[i].file, rel)) row = &rows[i];
        if (row) {
            char fin[4400], sha[65];
            snprintf(fin, sizeof fin, "%s/%s", dir, row->file);
            struct stat st;
            if (stat(fin, &st) != 0 && model_sha256_file(path, sha) && !strcmp(sha, row->sha256) &&
                link(path, fin) == 0) {
                (*relinked)++;
                rig_journal_event(j, step, "info", "recovered %s (committed before the crash, not yet linked)",
                                  row->file);
            } else if (stat(fin, &st) != 0) {
                continue;   // keep it for refl session check to report
            }
        } else {
            (*removed)++;
        }
        unlink(path);
    }
    closedir(d);
    free(rows);
    return 0;
}

// ---------------------------------------------------------------------------
// Progress

typedef struct {
    bool   bar;
    double t0;
    int    total, done0;
    int    nrun;            // steps carried out in this run
    double t1;              // when the first of them ended
} progress_t;

// A step ended (done: its position + 1). The ETA: the steps still pending
// (remaining) at the pace of this run's steps after its first one (the first
// carries the start: a long move from where the stage stood, the camera's
// first frame); after the first step, the hardware floor of the rest
// (remaining_floor_s).
static void progress(progress_t *pg, int done, const rig_step_t *s, int remaining, double remaining_floor_s)
{
    double now = model_now_s();
    double eta = pg->nrun > 0 ? (now - pg->t1) / pg->nrun * remaining : remaining_floor_s;
    if (pg->nrun++ == 0) pg->t1 = now;
    if (pg->bar) {
        int width = 30, fill = pg->total ? (int)((double)done * width / pg->total) : width;
        char bar[64];
        for (int i = 0; i < width; i++) bar[i] = i < fill ? '#' : '.';
        bar[width] = 0;
        fprintf(stderr, "\r[%s] %d/%d ETA %4.0fs  %8.3f deg  %-16.16s %9.6g us ", bar, done, pg->total, eta,
                s->angle_deg, s->lamps, s->exposure_us);
    } else {
        fprintf(stderr, "refl capture: step %d/%d angle %.4g deg lamps %s exposure %.6g us%s (ETA %.0f s)\n", done,
                pg->total, s->angle_deg, s->lamps, s->exposure_us, s->kind == RIG_STEP_DARK ? " dark" : "", eta);
    }
}

// ---------------------------------------------------------------------------
// Dry run

static void print_dry_run(const rig_plan_t *p, const rig_t *r)
{
    rig_frame_meta_t m = { 0 };
    rig_camera_settings(r->camera, &m);
    printf("plan: %s (sha256 %s)\nsample: %s (%s)\nrig: %s\n", p->path, p->sha256, p->sample, p->sample_kind,
           r->path);
    int nframes = 0;
    for (int i = 0; i < p->nsteps; i++) nframes += p->steps[i].kind != RIG_STEP_OPERATOR;
    printf("steps: %d (%d operator step%s; %d frames: %d angles x %d lamp sets x %d exposures x %d repeats%s%s%s)\n",
           p->nsteps, p->nsteps - nframes, p->nsteps - nframes == 1 ? "" : "s", nframes, p->nangles, p->nlamp_sets,
           p->nexposures, p->repeats, p->nviews ? ", as the [view] sections choose" : "",
           p->dark_every ? ", dark frames" : "", p->auto_exposure ? "; auto bracketing: at most" : "");
    if (r->ncameras > 1) {
        printf("cameras: %d, each step triggers every one in this order (%d frames in all):", r->ncameras,
               nframes * r->ncameras);
        for (int k = 0; k < r->ncameras; k++) printf(" %s", r->camera_names[k]);
        printf("\n");
    }
    for (int i = 0; i < p->nsteps; i++) {
        const rig_step_t *s = &p->steps[i];
        if (s->kind == RIG_STEP_OPERATOR) {
            printf("  %6d  operator: %s\n", i, p->ops[s->op].instruction);
            continue;
        }
        printf("  %6d  %-5s angle %10.4f deg  lamps %-20s exposure %10.6g us  gain %g%s\n", i,
               s->kind == RIG_STEP_DARK ? "dark" : "light", s->angle_deg, s->lamps, s->exposure_us, s->gain,
               s->repeat ? " (repeat)" : "");
    }
    double floor_s = rig_plan_floor_s(p, r, 0);
    double bytes = (double)nframes * m.width * m.height * 2.0;
    printf("estimated_duration_s: %.1f (hardware floor: motions, settles, exposures; plus homing)\n", floor_s);
    printf("estimated_disk_bytes: %.0f (at most: %d frames of %d x %d 16-bit; PNG compresses them)\n", bytes,
           nframes, m.width, m.height);
    printf("check: plan matches the rig (lamps exist, angles within range, the camera accepts every exposure)\n");
}

// ---------------------------------------------------------------------------

static int fault_stop(rig_t *r, rig_journal_t *j, int step, const char *state, const char *kind, const char *msg)
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
} run_t;

static int replay_operator(run_t *x);

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
    if ((x->rc = rig_journal_open(&x->j, o->dir))) return RUN_DONE;
    if ((x->rc = rig_journal_source(x->j, "plan", &x->s_plan_path, &x->s_plan_text, &x->s_plan_sha)) ||
        (x->rc = rig_journal_source(x->j, "rig", &x->s_rig_path, &x->s_rig_text, &x->s_rig_sha)))
        return RUN_DONE;
    char state[32] = "";
    rig_journal_state(x->j, state, sizeof state);
    if (!strcmp(state, "complete")) {
        printf("refl capture: %s is complete: nothing to resume (refl session check %s)\n", o->dir, o->dir);
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
        x->rc = rig_fail(RIG_ERR_INVALID, "refl capture --resume %s: %s changed since the session started "
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

// --resume: the camera is the one the session started with (its serial
// against the journal's facts); another camera is refused unless
// --allow-changed (then the event log says so).
static int check_camera(run_t *x)
{
    char *facts = NULL;
    if (!x->r->camera || rig_journal_facts(x->j, &facts)) {
        free(facts);
        return 0;
    }
    json_t *f = facts[0] ? json_loads(facts, 0, NULL) : NULL;
    free(facts);
    json_t *cams = json_object_get(f, "cameras");
    int rc = 0;
    for (int k = 0; k < x->r->ncameras && !rc; k++) {
        // its serial then: by name in "cameras", or the first camera's "camera" (a session of one camera)
        const char *was = k == 0 ? json_string_value(json_object_get(json_object_get(f, "camera"), "serial")) : NULL;
        size_t i;
        json_t *c;
        json_array_foreach(cams, i, c)
            if (!strcmp(json_string_value(json_object_get(c, "camera")) ?: "", x->r->camera_names[k]))
                was = json_string_value(json_object_get(c, "serial"));
        rig_frame_meta_t m;
        if (!was || !was[0] || (rc = rig_camera_settings(x->r->cameras[k], &m)) || !strcmp(was, m.serial)) continue;
        if (!x->o->allow_changed)
            rc = rig_fail(RIG_ERR_INVALID, "refl capture --resume %s: the camera changed: %s%s%sserial %s now, the "
                          "session started with serial %s: connect that camera, or add --allow-changed to continue "
                          "with this one", x->o->dir, x->r->ncameras > 1 ? "camera " : "",
                          x->r->ncameras > 1 ? x->r->camera_names[k] : "", x->r->ncameras > 1 ? ": " : "", m.serial,
                          was);
        else
            rig_journal_event(x->j, -1, "info", "resumed with another camera %s: serial %s, the session started "
                              "with %s (--allow-changed)", x->r->camera_names[k], m.serial, was);
    }
    json_decref(f);
    return rc;
}

// The rig (opened, the plan bound to it; a dry run ends here), the session
// directory and journal (created, or on --resume its frames recovered), the
// steps' status.
static int run_session(run_t *x)
{
    const rig_capture_opts_t *o = x->o;
    rig_plan_t *p = x->p;
    fprintf(stderr, "refl capture: opening the rig %s\n", x->rig_path);
    if ((x->rc = rig_open(&x->r, x->rig_path))) return RUN_DONE;
    if (o->resume && (x->rc = check_camera(x))) return RUN_DONE;
    if ((x->rc = rig_plan_bind(p, x->r))) return RUN_DONE;
    if (o->dry_run) {
        print_dry_run(p, x->r);
        x->exit_code = 0;
        return RUN_DONE;
    }
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
        if (o->calib_dir && !(cal = calibration_files(o->calib_dir, x->r))) {
            x->rc = RIG_ERR_INVALID;
            return RUN_DONE;
        }
        x->facts = session_facts(x->r, p, o->command_line, cal);
        json_decref(cal);
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
                         p->nsteps, before_operator ? " (a session of a refl without operator steps: its frames "
                         "stay readable; capture the rest into a new session)" : "");
        return RUN_DONE;
    }
    if (o->resume) {
        int relinked, removed;
        if ((x->rc = recover_frames(x->j, o->dir, &relinked, &removed))) return RUN_DONE;
        int pend = 0;
        for (int i = 0; i < nstored; i++) pend += x->status[i] == 'p';
        rig_journal_event(x->j, -1, "resume", "resumed: %d of %d steps pending (%d frames recovered, %d temporary "
                          "files removed)", pend, nstored, relinked, removed);
        fprintf(stderr, "refl capture: resuming %s: %d of %d steps to go\n", o->dir, pend, nstored);
        rig_journal_set_state(x->j, "running");
        if (replay_operator(x) != RUN_ON) return RUN_DONE;
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
    if (pthread_create(&x->wt, NULL, writer_main, &x->w)) {
        x->rc = rig_fail(RIG_ERR_IO, "cannot start the writer thread");
        return RUN_DONE;
    }
    x->writer_running = true;
    g_sigint = 0;
    struct sigaction sa = { .sa_handler = on_sigint };
    sigemptyset(&sa.sa_mask);
    sigaction(SIGINT, &sa, &g_old_int);
    x->sig_installed = true;
    return RUN_ON;
}

// The first SIGINT during homing or a move: the stage stands; the session
// pauses (no frame was being taken) and run_end reports it (exit 3).
static int motion_paused(run_t *x, const char *during, const char *resume_does)
{
    snprintf(x->msg, sizeof x->msg, "interrupted (SIGINT) during %s: no frame was being taken; %s; lamps off, "
             "session paused before step %d of %d; continue with refl capture --resume %s (it %s again)", during,
             model_last_error(), x->step, x->p->nsteps, x->o->dir, resume_does);
    x->paused = 5;
    return RUN_BREAK;
}

// Home the turntable when needed, set the camera up, and the steps' state
// (first pending step, progress, groups an earlier run already satisfied).
// Homes the turntable unless it is homed (Ctrl-C stops it: the session pauses).
static int home_turntable(run_t *x)
{
    rig_t *r = x->r;
    x->home_pending = false;
    if (!r->turntable) return RUN_ON;
    rig_turntable_status_t st;
    if ((x->rc = rig_turntable_status(r->turntable, &st))) return RUN_FAULT_TT;
    if (st.homed) return RUN_ON;
    char up_to[48] = "";
    if (isfinite(r->home_time_s)) snprintf(up_to, sizeof up_to, "up to %.0f s; ", r->home_time_s);
    fprintf(stderr, "refl capture: homing %s (%sCtrl-C stops it)\n", rig_turntable_name(r->turntable), up_to);
    double tmo = 1.5 * (isfinite(r->home_time_s) ? r->home_time_s : 120) + 5;
    bool bar = x->o->progress == 1 || (x->o->progress < 0 && isatty(2));
    double t0 = model_now_s();
    x->rc = watched_motion(r, true, 0, tmo, r->home_time_s, bar);
    x->t_homing += model_now_s() - t0;
    if (x->rc == RIG_ERR_INTERRUPTED) return motion_paused(x, "homing", "homes the stage");
    return x->rc ? RUN_FAULT_TT : RUN_ON;
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

    x->pg = (progress_t){ .bar = x->o->progress == 1 || (x->o->progress < 0 && isatty(2)), .t0 = model_now_s(),
                          .total = p->nsteps, .done0 = 0 };
    x->first = 0;
    while (x->first < p->nsteps && x->status[x->first] != 'p') x->first++;
    x->pg.done0 = x->first;
    // The stage homes now, or after the operator's steps that come first (the
    // operator sets the sample up before anything moves)
    x->home_pending = true;
    if (x->first >= p->nsteps || p->steps[x->first].kind != RIG_STEP_OPERATOR) {
        x->step = x->first;
        int k = home_turntable(x);
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
    if (!x->satisfied || !x->cam_done) {
        x->rc = rig_fail(RIG_ERR_NO_MEM, "refl capture: out of memory");
        return RUN_DONE;
    }
    rig_frame_row_t *rows = NULL;
    int nr = 0;
    if (!rig_journal_frames(x->j, &rows, &nr)) {
        // a group is satisfied by a step whose every camera's frame is at or below the target
        uint32_t *low = calloc((size_t)p->nsteps + 1, sizeof *low);
        uint32_t all = r->ncameras >= 32 ? 0xffffffffu : (1u << r->ncameras) - 1;
        for (int i = 0; i < nr; i++) {
            int k = rig_camera_find(r, rows[i].camera);
            if (k < 0 || rows[i].step < 0 || rows[i].step >= p->nsteps) continue;
            x->cam_done[rows[i].step] |= 1u << k;
            if (low && rows[i].roi_max <= p->target_fraction * x->full) low[rows[i].step] |= 1u << k;
        }
        for (int i = 0; low && p->auto_exposure && i < p->nsteps; i++)
            if (p->steps[i].group >= 0 && low[i] == all) x->satisfied[p->steps[i].group] = true;
        free(low);
    }
    free(rows);
    return RUN_ON;
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
        x->rc = watched_motion(r, false, s->angle_deg, 1.5 * (isfinite(tm) ? tm : 120) + 5, tm, false);
        if (x->rc == RIG_ERR_INTERRUPTED) {
            char during[64];
            snprintf(during, sizeof during, "the move to %.4g deg", s->angle_deg);
            return motion_paused(x, during, "moves there");
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
        if ((x->rc = rig_lamps_set(r->lamps, s->lamp_mask))) {
            snprintf(x->msg, sizeof x->msg, "lamps: %s", model_last_error());
            fault_stop(r, x->j, x->step, "fault", "fault", x->msg);
            return RUN_DONE;
        }
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
        jb->t_trigger_s = realtime_s();
        bool q = model_error_quiet_thread(true);
        x->rc = rig_camera_capture(r->cameras[k], p->frame_timeout_s + 2e-6 * s->exposure_us, 0, &jb->f);
        model_error_quiet_thread(q);
        if (!x->rc) return RUN_ON;
        if (x->rc != RIG_ERR_TIMEOUT || tries >= p->retries || g_sigint) break;
        tries++;
        rig_journal_event(x->j, step, "retry", "camera %stime-out (%s): retry %d of %d", r->ncameras > 1 ? cn : "",
                          model_last_error(), tries, p->retries);
        fprintf(stderr, "refl capture: camera %s%stime-out at step %d: retry %d of %d\n", cn, *cn ? " " : "", step,
                tries, p->retries);
    }
    if (x->rc == RIG_ERR_TIMEOUT || x->rc == RIG_ERR_DISCONNECTED) {
        snprintf(x->msg, sizeof x->msg, "camera %s did not answer at step %d after %d retries (%s): session "
                 "paused; check the camera's cable and power, then refl capture --resume %s",
                 rig_camera_name(r->cameras[k]), step, tries, model_last_error(), x->o->dir);
        fault_stop(r, x->j, step, "paused", "pause", x->msg);
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
            x->rc = rig_fail(RIG_ERR_NO_MEM, "refl capture: out of memory");
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
            frame_stats(&jb->f, p->roi, &jb->mean, &jb->max, &jb->roi_max, &jb->sat);
            jb->stats_done = true;
            low &= jb->roi_max <= p->target_fraction * x->full;
        }
        double T_p0 = model_now_s();
        writer_push(&x->w, jb);
        x->T_push += model_now_s() - T_p0;
        x->cam_done[step] |= 1u << k;
    }
    if (p->auto_exposure && s->group >= 0 && low) x->satisfied[s->group] = true;
    int remaining = 0;
    for (int i = step + 1; i < p->nsteps; i++) remaining += x->status[i] == 'p';
    progress(&x->pg, step + 1, s, remaining, x->pg.nrun == 0 ? rig_plan_floor_s(p, r, step + 1) : 0);
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
        if ((x->rc = rig_lamps_all_off(r->lamps))) {
            snprintf(x->msg, sizeof x->msg, "lamps: %s", model_last_error());
            fault_stop(r, x->j, step, "fault", "fault", x->msg);
            return RUN_DONE;
        }
        x->mask = 0;
    }
    if (x->pg.bar) fprintf(stderr, "\n");
    char how[1024], what[512];
    const char *dir = x->o->dir;
    double t0 = model_now_s();
    int a = rig_operator_ask(x->o->op ? x->o->op : x->op_own, step, x->p->ops[s->op].instruction, how, sizeof how);
    x->t_operator += model_now_s() - t0;
    if (a == RIG_OPERATOR_PAUSE) {
        snprintf(x->msg, sizeof x->msg, "operator step %d not answered (%s): session paused, lamps off; when it is "
                 "done, continue with refl capture --resume %s (Enter on a terminal answers it, or add --yes or "
                 "--operator-input FILE)", step, how, dir);
        fault_stop(r, x->j, step, "paused", "pause", x->msg);
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
        fault_stop(r, x->j, step, "paused", "pause", x->msg);
        x->paused = 4;
        return RUN_BREAK;
    }
    x->status[step] = 'd';
    fprintf(stderr, "refl capture: operator step %d done; %s\n", step, what);
    return RUN_ON;
}

// --resume: the operator steps answered earlier are not asked again; their
// poses are applied again (a virtual rig; on a real rig the sample is where
// the operator put it).
static int replay_operator(run_t *x)
{
    for (int i = 0; i < x->p->nsteps; i++) {
        if (x->p->steps[i].kind != RIG_STEP_OPERATOR || x->status[i] != 'd') continue;
        char what[512];
        if ((x->rc = rig_plan_operator_pose(x->p, x->r, i, what, sizeof what))) return RUN_DONE;
        rig_journal_event(x->j, i, "info", "resume: operator step %d was answered earlier, not asked again; %s%s", i,
                          what, x->r->virt ? " again" : " (still in place)");
    }
    return RUN_ON;
}

// Every pending step, until the end, a pause (SIGINT) or a writer error.
static int run_steps(run_t *x)
{
    rig_plan_t *p = x->p;
    for (x->step = x->first; x->step < p->nsteps; x->step++) {
        const rig_step_t *s = &p->steps[x->step];
        if (x->status[x->step] != 'p') continue;
        if (g_sigint) {
            x->paused = 1;
            break;
        }
        if (writer_error(&x->w, x->msg, sizeof x->msg)) break;
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
        int k = x->home_pending ? home_turntable(x) : RUN_ON;
        if (k == RUN_ON) k = step_setup(x, s);
        if (k == RUN_ON) k = step_capture(x, s);
        if (k == RUN_BREAK) break;
        if (k != RUN_ON) return k;
    }
    return RUN_ON;
}

static void writer_close(run_t *x)
{
    pthread_mutex_lock(&x->w.m);
    x->w.closing = true;
    pthread_cond_broadcast(&x->w.cv);
    pthread_mutex_unlock(&x->w.m);
    pthread_join(x->wt, NULL);
    x->writer_running = false;
}

// The end: the writer drained, then the session stopped (writer error),
// paused or complete, and the summary.
static int run_end(run_t *x)
{
    const rig_capture_opts_t *o = x->o;
    rig_plan_t *p = x->p;
    writer_close(x);
    if (x->pg.bar) fprintf(stderr, "\n");
    // the operator's time is not the rig's, nor homing (before the first frame, as before operator steps)
    double wall = model_now_s() - x->t_start - x->t_operator - x->t_homing;
    if (o->wall_s) *o->wall_s = wall;
    if (o->floor_s) *o->floor_s = x->floor_s;
    if (o->frames_written) *o->frames_written = x->w.written;
    if (writer_error(&x->w, x->msg, sizeof x->msg)) {
        fault_stop(x->r, x->j, x->step, "stopped", "fault", x->msg);
        rig_fail(RIG_ERR_IO, "refl capture: %s", x->msg);
        x->exit_code = 1;
        return RUN_DONE;
    }
    if (x->paused) {
        if (x->paused == 1 || x->paused == 5) {
            if (x->paused == 1)
                snprintf(x->msg, sizeof x->msg, "interrupted (SIGINT): the current frame was finished, lamps off, "
                         "session paused at step %d of %d; continue with refl capture --resume %s", x->step,
                         p->nsteps, o->dir);
            fault_stop(x->r, x->j, x->step, "paused", "pause", x->msg);
        }
        if (x->paused == 4) {
            rig_fail(x->rc ? x->rc : RIG_ERR_INVALID, "refl capture: %s", x->msg);
            x->exit_code = 1;
            return RUN_DONE;
        }
        fprintf(stderr, "refl capture: %s\n", x->paused != 2 ? x->msg : "session paused (camera not answering)");
        if (x->paused == 2) rig_fail(RIG_ERR_TIMEOUT, "refl capture: %s", x->msg);
        x->exit_code = 3;
        return RUN_DONE;
    }
    if (x->r->lamps) rig_lamps_all_off(x->r->lamps);
    rig_journal_event(x->j, -1, "complete", "session complete: %d frames this run, wall %.3f s, hardware floor %.3f "
                      "s", x->w.written, wall, x->floor_s);
    rig_journal_set_state(x->j, "complete");
    int total_frames = x->frames_before + x->w.written;
    printf("refl capture: session %s complete\n  steps: %d, frames: %d (%d this run)%s\n  wall time: %.1f s, hardware "
           "floor: %.1f s (ratio %.3f); in the camera (trigger to frame in hand): %.1f s; "
           "waiting for the writer: %.1f s\n  check: refl session check %s\n",
           o->dir, p->nsteps, total_frames, x->w.written, p->auto_exposure ? " (auto bracketing skips the rest)" : "",
           wall, x->floor_s, x->floor_s > 0 ? wall / x->floor_s : 0, x->T_cap, x->T_push, o->dir);
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
    if (x->j) fault_stop(x->r, x->j, x->step, "fault", "fault", x->msg);
    rig_fail(x->rc, "refl capture: %s", x->msg);
}

static void run_cleanup(run_t *x)
{
    if (x->writer_running) writer_close(x);
    if (x->sig_installed) sigaction(SIGINT, &g_old_int, NULL);
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

int rig_capture_run(const rig_capture_opts_t *o)
{
    // run_t holds the writer's 10 kB message and the run's own: on the heap.
    run_t *x = calloc(1, sizeof *x);
    if (!x) {
        rig_fail(RIG_ERR_NO_MEM, "refl capture: out of memory");
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
    if (k == RUN_ON) k = run_steps(x);
    if (k == RUN_ON || k == RUN_BREAK) k = run_end(x);   // RUN_BREAK: paused while homing
    if (k == RUN_FAULT_TT || k == RUN_FAULT_CAM) run_fault(x, k == RUN_FAULT_TT);
    run_cleanup(x);
    int exit_code = x->exit_code;
    if (exit_code == 3) rig_operator_set_paused(o->op);
    free(x);
    return exit_code;
}
