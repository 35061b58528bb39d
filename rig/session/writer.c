// rig/session/writer.c — the capture's writer thread: a frame's statistics,
// its 16-bit PNG (flushed, hashed), its journal row (one transaction), then
// its final name (link(2): never overwrites).
// encodes the 16-bit PNG, flushes it, hashes it and commits the frame row
// (one SQLite transaction), then links the file to its final name (link(2):
// never overwrites) and removes the temporary one. A frame is therefore
// either committed with its file in place, or committed with only its
// temporary file (crash between commit and link: recovered on resume), or not
// committed (its step is pending and is captured again; the stale temporary
// file is removed). Frames are named frames/sNNNNNN.png by step index.
#define _GNU_SOURCE
#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "model/model.h"
#include "rig/rig.h"
#include "rig/session/internal.h"

// ---------------------------------------------------------------------------
// Writer thread

void capture_frame_stats(const rig_frame_t *f, const int roi[4], double *mean, double *max, double *roi_max,
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
    row.t_written_utc_s = model_realtime_s();
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

// The thread: its errors are kept in w->msg (the main thread reports them),
// never printed from here.
void *capture_writer_main(void *arg)
{
    writer_t *w = arg;
    model_error_quiet_thread(true);
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
            capture_frame_stats(&jb->f, w->plan->roi, &jb->mean, &jb->max, &jb->roi_max, &jb->sat);
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
void capture_writer_push(writer_t *w, job_t *jb)
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

int capture_writer_error(writer_t *w, char *msg, size_t size)
{
    pthread_mutex_lock(&w->m);
    int e = w->err;
    if (e && msg) snprintf(msg, size, "%s", w->msg);
    pthread_mutex_unlock(&w->m);
    return e;
}

void capture_writer_close(run_t *x)
{
    pthread_mutex_lock(&x->w.m);
    x->w.closing = true;
    pthread_cond_broadcast(&x->w.cv);
    pthread_mutex_unlock(&x->w.m);
    pthread_join(x->wt, NULL);
    x->writer_running = false;
}
