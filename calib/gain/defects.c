// calib/gain/defects.c — defect pixels of EMVA 1288 Release 4.0 Linear:
// hot, dead and bright pixels beyond a robust threshold, the logarithmic
// histograms, defects.tiff (calib/gain/gain.h).
#include <glib.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "calib/gain/internal.h"
#include "model/model.h"

// Median and robust std (1.4826 MAD) of the roi of m (NaN values left out).
static bool robust(const float *m, int w, const int r[4], double *med, double *sigma)
{
    int n = 0;
    double *v = malloc(sizeof(double) * ((size_t)r[2] * r[3] + 1));
    if (!v) return false;
    for (int y = 0; y < r[3]; y++)
        for (int x = 0; x < r[2]; x++) {
            float f = m[(size_t)(r[1] + y) * w + r[0] + x];
            if (isfinite(f)) v[n++] = f;
        }
    *med = *sigma = NAN;
    if (n) {
        *med = model_median(v, n);
        for (int i = 0; i < n; i++) v[i] = fabs(v[i] - *med);
        *sigma = 1.4826 * model_median(v, n);
    }
    free(v);
    return true;
}

// Histogram of the deviations dev = scale (m - med) over the roi in [lo, hi]
// (*nb bins). q > 0: the values are multiples of q apart (an average of
// quantised frames): the bins are whole multiples of q wide, their edges
// halfway between values, so that no bin holds one level more than its
// neighbour (no comb).
static void histogram(const float *m, int w, const int r[4], double med, double scale, double q, double *lo,
                      double *hi, long *hist, int *nb)
{
    *lo = INFINITY;
    *hi = -INFINITY;
    for (int y = 0; y < r[3]; y++)
        for (int x = 0; x < r[2]; x++) {
            double d = scale * (m[(size_t)(r[1] + y) * w + r[0] + x] - med);
            if (!isfinite(d)) continue;
            *lo = fmin(*lo, d);
            *hi = fmax(*hi, d);
        }
    if (!isfinite(*lo)) *lo = 0;
    *nb = CALIB_GAIN_HIST_BINS;
    if (q > 0 && isfinite(*hi)) {
        double width = q * fmax(1, ceil((*hi - *lo + q) / CALIB_GAIN_HIST_BINS / q));
        *lo -= 0.5 * q;
        *nb = (int)fmin(CALIB_GAIN_HIST_BINS, ceil((*hi + 0.5 * q - *lo) / width));
        *hi = *lo + *nb * width;
    }
    if (!(*hi > *lo)) *hi = *lo + 1;
    memset(hist, 0, sizeof(long) * CALIB_GAIN_HIST_BINS);
    for (int y = 0; y < r[3]; y++)
        for (int x = 0; x < r[2]; x++) {
            double d = scale * (m[(size_t)(r[1] + y) * w + r[0] + x] - med);
            if (!isfinite(d)) continue;
            int b = (int)((d - *lo) / (*hi - *lo) * *nb);
            hist[b < 0 ? 0 : b >= *nb ? *nb - 1 : b]++;
        }
}

static void defect_add(calib_gain_defects_t *o, int kind, int x, int y)
{
    int *count[3] = { &o->hot, &o->dead, &o->bright };
    (*count[kind])++;
    if (o->nlist[kind] < CALIB_GAIN_MAX_DEFECT_LIST) {
        o->list[kind][o->nlist[kind]][0] = x;
        o->list[kind][o->nlist[kind]][1] = y;
        o->nlist[kind]++;
    }
}

bool calib_gain_defects(const float *dark, const float *light, int w, int h, const int roi[4], double nsigma,
                        double dark_tstd, double light_tstd, double dark_quantum, unsigned char *map,
                        calib_gain_defects_t *o)
{
    memset(o, 0, sizeof *o);
    o->nsigma = nsigma;
    int r[4];
    gain_region(w, h, roi, r);
    if (!robust(dark, w, r, &o->dark_median_dn, &o->dark_sigma_dn) ||
        !robust(light, w, r, &o->light_median, &o->light_sigma)) {
        model_error_set(NULL, 0, "out of memory for the defect pixels (%dx%d)", r[2], r[3]);
        return false;
    }
    o->dark_threshold_dn = nsigma * fmax(o->dark_sigma_dn, dark_tstd);
    o->light_threshold = nsigma * fmax(o->light_sigma, light_tstd);
    if (map) memset(map, 0, (size_t)w * h);
    for (int y = r[1]; y < r[1] + r[3]; y++)
        for (int x = r[0]; x < r[0] + r[2]; x++) {
            size_t i = (size_t)y * w + x;
            double dd = dark[i] - o->dark_median_dn, dl = light[i] - o->light_median;
            int kind = dd > o->dark_threshold_dn ? 0 : dl < -o->light_threshold ? 1 : dl > o->light_threshold ? 2 : -1;
            if (kind < 0) continue;
            defect_add(o, kind, x, y);
            if (map) map[i] = (unsigned char)(kind + 1);
            // a hot pixel may also be dead or bright in the light: counted there as well
            if (kind == 0 && (dl < -o->light_threshold || dl > o->light_threshold))
                defect_add(o, dl < 0 ? 1 : 2, x, y);
        }
    histogram(dark, w, r, o->dark_median_dn, 1, dark_quantum, &o->dark_lo, &o->dark_hi, o->dark_hist, &o->dark_nbins);
    histogram(light, w, r, o->light_median, 100 / (o->light_median != 0 ? o->light_median : 1), 0, &o->light_lo,
              &o->light_hi, o->light_hist, &o->light_nbins);
    return true;
}

bool calib_gain_write_defects(const char *dir, const calib_gain_maps_t *m)
{
    size_t n = (size_t)m->w * m->h;
    float *f = malloc(sizeof(float) * (n + 1));
    if (!f) {
        model_error_set(dir, 0, "out of memory for defects.tiff (%dx%d)", m->w, m->h);
        return false;
    }
    for (size_t i = 0; i < n; i++) f[i] = m->sp.defect_map ? m->sp.defect_map[i] : 0;
    char *path = g_build_filename(dir, "defects.tiff", NULL);
    const char *meta[] = { "content", "defect pixels: 0 good, 1 hot (dark), 2 dead (light, low), 3 bright (light, "
                           "high)", "software", "refl calib gain " REFL_VERSION, NULL };
    bool ok = model_tiff_write_float(path, m->w, m->h, f, meta);
    g_free(path);
    free(f);
    return ok;
}
