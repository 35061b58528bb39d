// calib/lamps/highlight.c — a lamp's highlight on the sphere's image
// (calib_lamps_find_highlight): background and noise around the sphere, the
// brightest on-sphere pixel and its blob, the centroid, a 2-D Gaussian fit,
// and the window kept for the direction-space fit.
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "calib/lamps/internal.h"
#include "model/base/vec.h"

// Gaussian fit on the window: params A, x0, y0, sx, sy (Levenberg-Marquardt).
static bool gauss_fit(const double *xs, const double *ys, const double *v, int n, double p[5], double *rms,
                      double *q_std)
{
    double lambda = 1e-3, cost = 0;
    for (int i = 0; i < n; i++) {
        double dx = xs[i] - p[1], dy = ys[i] - p[2];
        double g = p[0] * exp(-0.5 * (dx * dx / (p[3] * p[3]) + dy * dy / (p[4] * p[4])));
        cost += (v[i] - g) * (v[i] - g);
    }
    double JTJ[25];
    for (int it = 0; it < 60; it++) {
        double A[25] = { 0 }, b[5] = { 0 };
        for (int i = 0; i < n; i++) {
            double dx = xs[i] - p[1], dy = ys[i] - p[2];
            double e = exp(-0.5 * (dx * dx / (p[3] * p[3]) + dy * dy / (p[4] * p[4])));
            double g = p[0] * e;
            double J[5] = { e, g * dx / (p[3] * p[3]), g * dy / (p[4] * p[4]), g * dx * dx / (p[3] * p[3] * p[3]),
                            g * dy * dy / (p[4] * p[4] * p[4]) };
            double r = v[i] - g;
            for (int a = 0; a < 5; a++) {
                b[a] += J[a] * r;
                for (int c = 0; c < 5; c++) A[a * 5 + c] += J[a] * J[c];
            }
        }
        memcpy(JTJ, A, sizeof JTJ);
        for (int a = 0; a < 5; a++) A[a * 6] *= 1 + lambda;
        if (!model_solve_linear(A, b, 5)) return false;
        double pn[5];
        for (int a = 0; a < 5; a++) pn[a] = p[a] + b[a];
        double cn = 0;
        bool bad = !(pn[3] > 0.05 && pn[4] > 0.05 && pn[0] > 0);
        for (int i = 0; !bad && i < n; i++) {
            double dx = xs[i] - pn[1], dy = ys[i] - pn[2];
            double g = pn[0] * exp(-0.5 * (dx * dx / (pn[3] * pn[3]) + dy * dy / (pn[4] * pn[4])));
            cn += (v[i] - g) * (v[i] - g);
        }
        if (!bad && cn <= cost) {
            double step = fabs(b[1]) + fabs(b[2]);
            memcpy(p, pn, sizeof pn);
            cost = cn;
            lambda = fmax(lambda * 0.3, 1e-9);
            if (step < 1e-6) break;
        } else {
            lambda *= 10;
            if (lambda > 1e8) break;
        }
    }
    *rms = sqrt(cost / (n > 5 ? n - 5 : 1));
    // standard error of the centre from the residuals: s^2 (J^T J)^-1
    double A[25];
    double s2 = cost / (n > 5 ? n - 5 : 1), var[2];
    for (int k = 1; k <= 2; k++) {
        memcpy(A, JTJ, sizeof A);
        double e[5] = { 0 };
        e[k] = 1;
        if (!model_solve_linear(A, e, 5)) return false;
        var[k - 1] = s2 * e[k];
    }
    *q_std = sqrt(fmax(0, var[0]) + fmax(0, var[1]));
    return true;
}

// The difference img - dark (dark may be NULL) over the sphere's box into D
// (w*h), less the background: the median of the difference off the sphere
// (the box's margin and corners; all of it when fewer than 8 such pixels).
// Returns the noise: the difference's MAD off the sphere, at least 0.5 DN
// (the quantisation floor of integer DN). tmp: room for w*h.
static double subtract_background(const float *img, const float *dark, int W, const calib_lamps_sphere_image_t *sph,
                                  double *D, double *tmp)
{
    const int w = sph->w, h = sph->h, x0 = sph->x0, y0 = sph->y0;
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            size_t k = (size_t)(y0 + y) * W + (x0 + x);
            D[y * w + x] = img[k] - (dark ? dark[k] : 0);
        }
    int nb = 0;
    for (int i = 0; i < w * h; i++)
        if (!sph->on[i]) tmp[nb++] = D[i];
    if (nb < 8)
        for (int i = 0; i < w * h; i++) tmp[nb++] = D[i];
    double bg = model_median(tmp, nb);
    for (int i = 0; i < nb; i++) tmp[i] = fabs(tmp[i] - bg);
    double noise = 1.4826 * model_median(tmp, nb);
    if (!(noise > 0.5)) noise = 0.5;
    for (int i = 0; i < w * h; i++) D[i] -= bg;
    return noise;
}

// The brightest pixel of D on the sphere's image (box index; -1: none).
static int brightest_on_sphere(const calib_lamps_sphere_image_t *sph, const double *D)
{
    int best = -1;
    for (int i = 0; i < sph->w * sph->h; i++)
        if (sph->on[i] && (best < 0 || D[i] > D[best])) best = i;
    return best;
}

// The blob of best: the 8-connected pixels of D (w x h) at or above thr,
// marked in blob (zeroed, w*h). stack: room for w*h. Returns its pixels.
static int grow_blob(const double *D, int w, int h, int best, double thr, int *stack, unsigned char *blob)
{
    int ns = 0, nblob = 0;
    stack[ns++] = best;
    blob[best] = 1;
    while (ns) {
        int i = stack[--ns];
        nblob++;
        int bx = i % w, by = i / w;
        for (int dy = -1; dy <= 1; dy++)
            for (int dx = -1; dx <= 1; dx++) {
                int x = bx + dx, y = by + dy;
                if (x < 0 || y < 0 || x >= w || y >= h) continue;
                int j = y * w + x;
                if (!blob[j] && D[j] >= thr) {
                    blob[j] = 1;
                    stack[ns++] = j;
                }
            }
    }
    return nblob;
}

// The intensity-weighted centroid q (px) of the blob grown by one pixel (the
// dim wings carry position too), within 3 pixels of best.
static void blob_centroid(const calib_lamps_sphere_image_t *sph, const double *D, int best, const unsigned char *blob,
                          double q[2])
{
    const int w = sph->w, h = sph->h, bxp = best % w, byp = best / w;
    double sw = 0, sx = 0, sy = 0;
    for (int y = byp - 3; y <= byp + 3; y++)
        for (int x = bxp - 3; x <= bxp + 3; x++) {
            if (x < 0 || y < 0 || x >= w || y >= h) continue;
            bool near = false;
            for (int dy = -1; dy <= 1 && !near; dy++)
                for (int dx = -1; dx <= 1 && !near; dx++) {
                    int xx = x + dx, yy = y + dy;
                    near = xx >= 0 && yy >= 0 && xx < w && yy < h && blob[yy * w + xx];
                }
            if (!near) continue;
            double v = fmax(0, D[y * w + x]);
            sw += v;
            sx += v * (sph->x0 + x);
            sy += v * (sph->y0 + y);
        }
    q[0] = sx / sw;
    q[1] = sy / sw;
}

// The 2-D Gaussian fit on the 7x7 window around best (pixels of the box; the
// saturated ones left out: their value is clipped), started at the centroid:
// where it converges near the centroid with a plausible width, o->q, sigma_px,
// q_std_px and fit_used.
static void gauss_refine(const float *img, int W, const calib_lamps_sphere_image_t *sph, const double *D, int best,
                         double sat_dn, calib_lamps_highlight_t *o)
{
    const int w = sph->w, h = sph->h, x0 = sph->x0, y0 = sph->y0, bxp = best % w, byp = best / w;
    double xs[49], ys[49], vs[49];
    int n = 0;
    for (int y = byp - 3; y <= byp + 3; y++)
        for (int x = bxp - 3; x <= bxp + 3; x++) {
            if (x < 0 || y < 0 || x >= w || y >= h) continue;
            size_t k = (size_t)(y0 + y) * W + (x0 + x);
            if (img[k] >= sat_dn) continue;
            xs[n] = x0 + x;
            ys[n] = y0 + y;
            vs[n] = D[y * w + x];
            n++;
        }
    double p[5] = { o->peak_dn, o->q_centroid[0], o->q_centroid[1], 0.7, 0.7 }, rms = 0, qs = NAN;
    if (n >= 9 && gauss_fit(xs, ys, vs, n, p, &rms, &qs) &&
        hypot(p[1] - o->q_centroid[0], p[2] - o->q_centroid[1]) < 1.0 && p[3] > 0.15 && p[3] < 4 && p[4] > 0.15 &&
        p[4] < 4) {
        o->q[0] = p[1];
        o->q[1] = p[2];
        o->sigma_px[0] = p[3];
        o->sigma_px[1] = p[4];
        o->q_std_px = qs;
        o->fit_used = true;
    }
}

// o->win: the 9x9 window around best for the direction-space fit (NAN off
// the sphere, off the box and where saturated).
static void direction_window(const float *img, int W, const calib_lamps_sphere_image_t *sph, const double *D,
                             int best, double sat_dn, calib_lamps_highlight_t *o)
{
    const int w = sph->w, h = sph->h, x0 = sph->x0, y0 = sph->y0, bxp = best % w, byp = best / w;
    o->win_x0 = x0 + bxp - 4;
    o->win_y0 = y0 + byp - 4;
    for (int i = 0; i < 81; i++) {
        int x = bxp - 4 + i % 9, y = byp - 4 + i / 9;
        o->win[i] = NAN;
        if (x < 0 || y < 0 || x >= w || y >= h || !sph->on[y * w + x]) continue;
        if (img[(size_t)(y0 + y) * W + (x0 + x)] >= sat_dn) continue;
        o->win[i] = D[y * w + x];
    }
}

bool calib_lamps_find_highlight(const float *img, const float *dark, int W, int H,
                                const calib_lamps_sphere_image_t *sph, double min_snr, double min_peak_dn,
                                int max_blob_px, double sat_dn, calib_lamps_highlight_t *o)
{
    memset(o, 0, sizeof *o);
    const int w = sph->w, h = sph->h;
    double *D = malloc(sizeof *D * (size_t)w * h), *tmp = malloc(sizeof *tmp * (size_t)w * h);
    int *stack = malloc(sizeof *stack * (size_t)w * h);
    unsigned char *blob = calloc((size_t)w * h, 1);
    bool ok = D && tmp && stack && blob;
    if (!ok) {
        snprintf(o->why, sizeof o->why, "out of memory");
        model_error_set(NULL, 0, "out of memory");
        goto done;
    }
    (void)H;
    double noise = o->noise_dn = subtract_background(img, dark, W, sph, D, tmp);
    int best = brightest_on_sphere(sph, D);
    if (best < 0) {
        snprintf(o->why, sizeof o->why, "no pixel of the sphere's predicted image is on the imager");
        goto done;
    }
    o->peak_dn = D[best];
    o->saturated = img[(size_t)(sph->y0 + best / w) * W + (sph->x0 + best % w)] >= sat_dn;
    double need = fmax(min_snr * noise, min_peak_dn);
    if (!(o->peak_dn >= need)) {
        snprintf(o->why, sizeof o->why, "brightest pixel on the sphere's image is %.1f DN above the background "
                 "(noise %.1f DN; a highlight needs %.0f DN)", o->peak_dn, noise, need);
        goto done;
    }
    int nblob = o->blob_px = grow_blob(D, w, h, best, 0.2 * o->peak_dn, stack, blob);
    if (nblob > max_blob_px) {
        snprintf(o->why, sizeof o->why, "the brightest spot on the sphere's image is a broad patch of %d pixels "
                 "(>= 20 %% of its peak %.0f DN), not a lamp's highlight (at most %d pixels)", nblob, o->peak_dn,
                 max_blob_px);
        goto done;
    }
    blob_centroid(sph, D, best, blob, o->q_centroid);
    o->q[0] = o->q_centroid[0];
    o->q[1] = o->q_centroid[1];
    o->q_std_px = NAN;
    gauss_refine(img, W, sph, D, best, sat_dn, o);
    direction_window(img, W, sph, D, best, sat_dn, o);
    o->found = true;
done:
    free(D);
    free(tmp);
    free(stack);
    free(blob);
    return ok;
}
