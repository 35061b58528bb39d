// calib/gain/frames.c — the frames of a gain calibration: loading (checked
// against the journal's hash), their groups (exposure, gain, dark/light,
// role, photon count) and each group's mean and temporal variance
// (calib/gain/gain.h).
#include <glib.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "calib/gain/internal.h"
#include "model/model.h"

void calib_gain_data_free(calib_gain_data_t *d)
{
    for (int i = 0; i < d->nf; i++) {
        free(d->f[i].path);
        free(d->f[i].where);
    }
    for (int i = 0; i < d->ng; i++) {
        free(d->g[i].idx);
        free(d->g[i].error);
    }
    free(d->f);
    free(d->g);
}

const char *gain_frame_name(const calib_gain_frame_t *f, char *buf, size_t size)
{
    if (f->line > 0) snprintf(buf, size, "%s:%d (%s)", f->where, f->line, f->path);
    else snprintf(buf, size, "%s (session %s, step %d)", f->path, f->where, f->step);
    return buf;
}

// Load a frame; errors name the manifest line or the session step.
float *gain_frame_load(const calib_gain_frame_t *f, int *w, int *h)
{
    bool q = model_error_quiet_thread(true);
    float *img = NULL;
    char sha[65];
    if (f->sha256[0]) {
        if (!model_sha256_file(f->path, sha)) goto fail;
        if (strcmp(sha, f->sha256)) {
            model_error_set(f->path, 0, "sha256 %s differs from the journal's %s: the frame was changed or damaged",
                            sha, f->sha256);
            goto fail;
        }
    }
    img = model_image_read_float(f->path, w, h);
    if (!img) goto fail;
    model_error_quiet_thread(q);
    return img;
fail:;
    char *why = g_strdup(model_last_error());
    model_error_quiet_thread(q);
    if (f->line > 0) model_error_set(f->where, f->line, "frame %s: %s", f->path, why);
    else model_error_set(f->path, 0, "step %d of the session %s: %s", f->step, f->where, why);
    g_free(why);
    return NULL;
}

void gain_region(int w, int h, const int roi[4], int r[4])
{
    if (roi && roi[2] > 0) memcpy(r, roi, sizeof(int) * 4);
    else {
        r[0] = r[1] = 0;
        r[2] = w;
        r[3] = h;
    }
}

// The group of f's (exposure, gain, dark, role, photon count), made when new; -1 (out of memory).
static int group_find(calib_gain_data_t *d, const calib_gain_frame_t *f, int set)
{
    for (int i = 0; i < d->ng; i++) {
        calib_gain_group_t *g = &d->g[i];
        if (g->exposure_us == f->exposure_us && g->gain_db == f->gain_db && g->dark == f->dark && g->set == set &&
            g->has_photons == f->has_photons && (!f->has_photons || g->photons == f->photons))
            return i;
    }
    calib_gain_group_t *ng = realloc(d->g, sizeof *d->g * (d->ng + 1));
    if (!ng) return -1;
    d->g = ng;
    d->g[d->ng] = (calib_gain_group_t){ .exposure_us = f->exposure_us, .gain_db = f->gain_db,
                                        .has_photons = f->has_photons, .photons = f->has_photons ? f->photons : NAN,
                                        .dark = f->dark, .set = set, .var_dn2 = NAN };
    return d->ng++;
}

bool calib_gain_make_groups(calib_gain_data_t *d)
{
    for (int i = 0; i < d->nf; i++) {
        const calib_gain_frame_t *f = &d->f[i];
        int set = f->set == CALIB_GAIN_SET_ANY ? CALIB_GAIN_SET_SWEEP : f->set;
        int gi = group_find(d, f, set);
        int *idx = gi >= 0 ? realloc(d->g[gi].idx, sizeof(int) * (d->g[gi].n + 1)) : NULL;
        if (!idx) {
            model_error_set(NULL, 0, "out of memory for the exposure groups (%d frames)", d->nf);
            return false;
        }
        calib_gain_group_t *g = &d->g[gi];
        g->idx = idx;
        g->idx[g->n++] = i;
    }
    return true;
}

typedef struct {
    calib_gain_data_t *d;
    int      done;
    int      total;
    double   t0;
} pass1_t;

static void pass1_rows(void *ctx, int begin, int end, int thread)
{
    (void)thread;
    pass1_t *P = ctx;
    calib_gain_data_t *d = P->d;
    for (int gi = begin; gi < end; gi++) {
        calib_gain_group_t *g = &d->g[gi];
        float *prev = NULL;
        double sum_mean = 0, sum_var = 0;
        int npairs = 0;
        for (int k = 0; k < g->n && !g->error; k++) {
            const calib_gain_frame_t *f = &d->f[g->idx[k]];
            int w, h;
            float *img = gain_frame_load(f, &w, &h);
            if (!img) {
                g->error = g_strdup(model_last_error());
                break;
            }
            char nb[1024];
            if (k == 0) {
                g->width = w;
                g->height = h;
            } else if (w != g->width || h != g->height) {
                g->error = g_strdup_printf("%s: %dx%d pixels, the other frames of this exposure are %dx%d",
                                           gain_frame_name(f, nb, sizeof nb), w, h, g->width, g->height);
                free(img);
                break;
            }
            int r[4];
            gain_region(w, h, d->roi, r);
            if (r[0] + r[2] > w || r[1] + r[3] > h) {
                g->error = g_strdup_printf("%s: the region %d,%d,%d,%d does not fit the %dx%d frame",
                                           gain_frame_name(f, nb, sizeof nb), r[0], r[1], r[2], r[3], w, h);
                free(img);
                break;
            }
            double s = 0, sd = 0, sdd = 0;
            long nsat = 0, np = (long)r[2] * r[3];
            for (int y = r[1]; y < r[1] + r[3]; y++) {
                const float *row = img + (size_t)y * w;
                const float *prow = prev ? prev + (size_t)y * w : NULL;
                for (int x = r[0]; x < r[0] + r[2]; x++) {
                    s += row[x];
                    if (row[x] >= f->max_dn) nsat++;
                    if (prow) {
                        double dd = (double)row[x] - prow[x];
                        sd += dd;
                        sdd += dd * dd;
                    }
                }
            }
            sum_mean += s / np;
            if (k == 0) g->sat_frac = (double)nsat / np;
            if (prev) {
                double md = sd / np;
                sum_var += 0.5 * (sdd / np - md * md);
                npairs++;
                free(prev);
                prev = NULL;
                free(img);
            } else
                prev = img;
        }
        free(prev);
        if (!g->error) {
            g->mean_dn = sum_mean / g->n;
            g->var_dn2 = npairs ? sum_var / npairs : NAN;
        }
        int done = __atomic_add_fetch(&P->done, g->n, __ATOMIC_ACQ_REL);
        if (P->total > 100 && (done * 10 / P->total) != ((done - g->n) * 10 / P->total))
            model_progress("read %d/%d frames (%.0f s)", done, P->total, model_now_s() - P->t0);
    }
}

bool calib_gain_frame_stats(calib_gain_data_t *d)
{
    pass1_t P = { d, 0, d->nf, model_now_s() };
    model_parallel_for(d->ng, 1, model_default_threads(), pass1_rows, &P);
    if (P.total > 100) model_progress_end();
    for (int i = 0; i < d->ng; i++)
        if (d->g[i].error) {
            model_error_set(NULL, 0, "%s", d->g[i].error);
            return false;
        }
    // one frame size
    for (int i = 1; i < d->ng; i++)
        if (d->g[i].width != d->g[0].width || d->g[i].height != d->g[0].height) {
            char nb[1024];
            model_error_set(NULL, 0, "%s: %dx%d pixels, but %dx%d elsewhere in the input",
                            gain_frame_name(&d->f[d->g[i].idx[0]], nb, sizeof nb), d->g[i].width, d->g[i].height,
                            d->g[0].width, d->g[0].height);
            return false;
        }
    return true;
}
