// calib/geometry/psf.c — the lens's blur from the calibration board's edges (see
// calib/geometry/psf.h): each edge between two adjacent corners fitted with the
// footprint-integrated, Gaussian-blurred step of model_edge_spread, the edges
// combined by their median, and the geometry run's stage and report section.
#define _GNU_SOURCE
#include <errno.h>
#include <glib.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "calib/calib.h"
#include "calib/geometry/psf.h"
#include "model/model.h"
#include "model/base/report.h"

#define NP             5        // lo, hi, offset, turn, v = sigma^2
#define DMAX_PX        6.0      // pixels within this of the line (or 0.3 of the edge's length)
#define TMARGIN_PX     6.0      // kept from either corner (or a fifth of the length)
#define MIN_LENGTH_PX  20.0     // shorter edges (small squares) are not fitted
#define MIN_PIXELS     40
#define MIN_V          1e-4     // sigma >= 0.01 px (at 0 E depends on sigma^2 only; a sharp edge sits here)
#define MAX_SIGMA_PX   4.0
#define MAX_OFFSET_PX  1.5
#define MAX_TURN_RAD   0.06
#define MIN_CONTRAST   10.0     // |hi - lo| over the residual RMS
#define BIN_PX         0.125    // the supersampled ESF's bins
#define EDGES_TARGET   600      // the geometry run fits about this many edges (spread over the views)

typedef struct {
    float u, e;      // distance from the fitted line (px), normalised value (0 at lo, 1 at hi)
    int   edge;      // index in a->edges
} psf_sample_t;

struct calib_psf_acc {
    int               nw, nh;    // the board's inner corners along its rows and columns
    GArray           *edges;     // calib_psf_edge_t
    GArray           *samples;   // psf_sample_t of the used edges' pixels
};

calib_psf_acc_t *calib_psf_acc_new(int width_n, int height_n)
{
    calib_psf_acc_t *a = calloc(1, sizeof *a);
    if (!a) return NULL;
    a->nw = width_n;
    a->nh = height_n;
    a->edges = g_array_new(FALSE, TRUE, sizeof(calib_psf_edge_t));
    a->samples = g_array_new(FALSE, FALSE, sizeof(psf_sample_t));
    return a;
}

void calib_psf_acc_free(calib_psf_acc_t *a)
{
    if (!a) return;
    g_array_free(a->edges, TRUE);
    g_array_free(a->samples, TRUE);
    free(a);
}

// ---------------------------------------------------------------------------
// One edge

typedef struct {
    int     n;
    double *x, *y, *P;     // pixel centres and grey values
    bool   *keep;
    double  M[2], u[2], nrm[2], theta;
    bool    point;         // the pixels sample a point at their centre (no footprint): the step blurred only
} edge_pixels_t;

// The model at the pixel k for parameters p: value, and the Jacobian row J (may be NULL).
static double edge_model(const edge_pixels_t *E, int k, const double *p, double *J)
{
    double ca = cos(p[3]), sa = sin(p[3]);
    double rx = E->x[k] - E->M[0], ry = E->y[k] - E->M[1];
    double nx = E->nrm[0] * ca - E->u[0] * sa, ny = E->nrm[1] * ca - E->u[1] * sa;
    double d = nx * rx + ny * ry - p[2];
    double s = sqrt(p[4]), dEdu, dEds, e;
    if (E->point) {   // Phi(d / s)
        double z = d / s, g = exp(-0.5 * z * z) / sqrt(2 * M_PI);
        e = 0.5 * erfc(-z / M_SQRT2);
        dEdu = g / s;
        dEds = -z * g / s;
    } else {
        e = model_edge_spread(d, E->theta, s, &dEdu, &dEds);
    }
    double c = p[1] - p[0];
    if (J) {
        double dd_dturn = (-E->nrm[0] * sa - E->u[0] * ca) * rx + (-E->nrm[1] * sa - E->u[1] * ca) * ry;
        J[0] = 1 - e;
        J[1] = e;
        J[2] = -c * dEdu;
        J[3] = c * dEdu * dd_dturn;
        J[4] = c * dEds / (2 * s);
    }
    return p[0] + c * e;
}

static double edge_cost(const edge_pixels_t *E, const double *p, int *nused)
{
    double c = 0;
    int n = 0;
    for (int k = 0; k < E->n; k++) {
        if (!E->keep[k]) continue;
        double r = E->P[k] - edge_model(E, k, p, NULL);
        c += r * r;
        n++;
    }
    if (nused) *nused = n;
    return c;
}

// Cholesky solve of the n x n system A x = b (A symmetric positive definite). false: not.
static bool chol_solve(int n, const double *A, const double *b, double *x)
{
    double L[NP * NP] = { 0 };
    for (int i = 0; i < n; i++)
        for (int j = 0; j <= i; j++) {
            double s = A[i * n + j];
            for (int k = 0; k < j; k++) s -= L[i * n + k] * L[j * n + k];
            if (i == j) {
                if (!(s > 0)) return false;
                L[i * n + i] = sqrt(s);
            } else {
                L[i * n + j] = s / L[j * n + j];
            }
        }
    double y[NP];
    for (int i = 0; i < n; i++) {
        double s = b[i];
        for (int k = 0; k < i; k++) s -= L[i * n + k] * y[k];
        y[i] = s / L[i * n + i];
    }
    for (int i = n - 1; i >= 0; i--) {
        double s = y[i];
        for (int k = i + 1; k < n; k++) s -= L[k * n + i] * x[k];
        x[i] = s / L[i * n + i];
    }
    return true;
}

// J^T J and J^T r over the kept pixels.
static void normal_equations(const edge_pixels_t *E, const double *p, double *JtJ, double *Jtr)
{
    memset(JtJ, 0, NP * NP * sizeof *JtJ);
    memset(Jtr, 0, NP * sizeof *Jtr);
    for (int k = 0; k < E->n; k++) {
        if (!E->keep[k]) continue;
        double J[NP], r = E->P[k] - edge_model(E, k, p, J);
        for (int i = 0; i < NP; i++) {
            Jtr[i] += J[i] * r;
            for (int j = 0; j <= i; j++) JtJ[i * NP + j] += J[i] * J[j];
        }
    }
    for (int i = 0; i < NP; i++)
        for (int j = i + 1; j < NP; j++) JtJ[i * NP + j] = JtJ[j * NP + i];
}

// Levenberg-Marquardt from p (updated). false: no convergence.
static bool edge_lm(const edge_pixels_t *E, double *p)
{
    double lambda = 1e-3, cost = edge_cost(E, p, NULL);
    for (int it = 0; it < 60; it++) {
        double JtJ[NP * NP], Jtr[NP], A[NP * NP], dp[NP], q[NP];
        normal_equations(E, p, JtJ, Jtr);
        bool better = false;
        for (int tries = 0; tries < 12 && !better; tries++) {
            memcpy(A, JtJ, sizeof A);
            for (int i = 0; i < NP; i++) A[i * NP + i] += lambda * (JtJ[i * NP + i] + 1e-12);
            if (!chol_solve(NP, A, Jtr, dp)) {
                lambda *= 10;
                continue;
            }
            for (int i = 0; i < NP; i++) q[i] = p[i] + dp[i];
            if (q[4] < MIN_V) q[4] = MIN_V;
            if (q[4] > 4 * MAX_SIGMA_PX * MAX_SIGMA_PX) q[4] = 4 * MAX_SIGMA_PX * MAX_SIGMA_PX;
            double c = edge_cost(E, q, NULL);
            if (c <= cost) {
                double rel = (cost - c) / (cost + 1e-300);
                memcpy(p, q, sizeof q);
                cost = c;
                lambda = fmax(lambda / 3, 1e-9);
                better = true;
                if (rel < 1e-10) return true;
            } else {
                lambda *= 4;
            }
        }
        if (!better) return true;   // no step lowers the cost: at the minimum (to rounding)
    }
    return true;
}

// The pixels of the edge from corner A to corner B (none when it reaches past
// the image: *why).
static bool edge_collect(const float *img, int W, int H, const double A[2], const double B[2], edge_pixels_t *E,
                         char *why, size_t whyn)
{
    double dx = B[0] - A[0], dy = B[1] - A[1], L = hypot(dx, dy);
    E->n = 0;
    if (!(L >= MIN_LENGTH_PX)) {
        snprintf(why, whyn, "%.1f px between the corners: shorter than %g px", L, MIN_LENGTH_PX);
        return false;
    }
    E->u[0] = dx / L;
    E->u[1] = dy / L;
    E->nrm[0] = -E->u[1];
    E->nrm[1] = E->u[0];
    E->theta = atan2(E->nrm[1], E->nrm[0]);
    E->M[0] = 0.5 * (A[0] + B[0]);
    E->M[1] = 0.5 * (A[1] + B[1]);
    double dmax = fmin(DMAX_PX, 0.3 * L), th = 0.5 * L - fmax(TMARGIN_PX, 0.2 * L);
    double ex = fabs(E->u[0]) * th + fabs(E->nrm[0]) * dmax, ey = fabs(E->u[1]) * th + fabs(E->nrm[1]) * dmax;
    int x0 = (int)floor(E->M[0] - ex), x1 = (int)ceil(E->M[0] + ex);
    int y0 = (int)floor(E->M[1] - ey), y1 = (int)ceil(E->M[1] + ey);
    if (x0 < 1 || y0 < 1 || x1 > W - 2 || y1 > H - 2) {
        snprintf(why, whyn, "reaches past the image");
        return false;
    }
    size_t cap = (size_t)(x1 - x0 + 1) * (y1 - y0 + 1);
    E->x = malloc(cap * sizeof *E->x);
    E->y = malloc(cap * sizeof *E->y);
    E->P = malloc(cap * sizeof *E->P);
    E->keep = malloc(cap * sizeof *E->keep);
    if (!E->x || !E->y || !E->P || !E->keep) {
        snprintf(why, whyn, "out of memory");
        model_error_set(NULL, 0, "out of memory");
        return false;
    }
    for (int y = y0; y <= y1; y++)
        for (int x = x0; x <= x1; x++) {
            double rx = x - E->M[0], ry = y - E->M[1];
            double t = E->u[0] * rx + E->u[1] * ry, d = E->nrm[0] * rx + E->nrm[1] * ry;
            float v = img[(size_t)y * W + x];
            if (fabs(t) > th || fabs(d) > dmax || !isfinite(v)) continue;
            E->x[E->n] = x;
            E->y[E->n] = y;
            E->P[E->n] = v;
            E->keep[E->n] = true;
            E->n++;
        }
    if (E->n < MIN_PIXELS) {
        snprintf(why, whyn, "%d pixels near the line: under %d", E->n, MIN_PIXELS);
        return false;
    }
    return true;
}

static void edge_pixels_free(edge_pixels_t *E)
{
    free(E->x);
    free(E->y);
    free(E->P);
    free(E->keep);
    memset(E, 0, sizeof *E);
}

// Fit one edge into *r (r->used and r->why say whether it counts); its
// pixels' samples into a->samples when it does.
static bool fit_edge(calib_psf_acc_t *a, const float *img, int W, int H, const double *A, const double *B,
                     calib_psf_edge_t *r)
{
    edge_pixels_t E = { 0 };
    r->used = false;
    r->length_px = hypot(B[0] - A[0], B[1] - A[1]);
    bool collected = edge_collect(img, W, H, A, B, &E, r->why, sizeof r->why);
    if (!collected) {
        bool oom = !strcmp(r->why, "out of memory");
        edge_pixels_free(&E);
        return !oom;
    }
    r->theta_rad = E.theta;
    // the start: the levels beyond 2 px on either side, sigma 0.7 px
    double s0 = 0, s1 = 0;
    int n0 = 0, n1 = 0;
    for (int k = 0; k < E.n; k++) {
        double d = E.nrm[0] * (E.x[k] - E.M[0]) + E.nrm[1] * (E.y[k] - E.M[1]);
        if (d < -2) s0 += E.P[k], n0++;
        if (d > 2) s1 += E.P[k], n1++;
    }
    double p[NP] = { n0 ? s0 / n0 : 0, n1 ? s1 / n1 : 0, 0, 0, 0.49 };
    int nk = 0;
    bool ok = n0 > 0 && n1 > 0 && edge_lm(&E, p);
    if (ok) {   // the pixels beyond 4 RMS out (a hot pixel, a speck), then again
        double rms = sqrt(edge_cost(&E, p, &nk) / nk);
        int out = 0;
        for (int k = 0; k < E.n; k++)
            if (fabs(E.P[k] - edge_model(&E, k, p, NULL)) > 4 * rms) E.keep[k] = false, out++;
        if (out) ok = edge_lm(&E, p);
    }
    double cost = ok ? edge_cost(&E, p, &nk) : NAN, JtJ[NP * NP], Jtr[NP], C[NP], e4[NP] = { 0, 0, 0, 0, 1 };
    r->npix = nk;
    r->level_neg_dn = p[0];
    r->level_pos_dn = p[1];
    r->offset_px = p[2];
    r->turn_rad = p[3];
    // at the bound the edge is as sharp as the footprint alone (or sharper: a pixel seeing less than its square)
    bool at_bound = p[4] <= MIN_V * (1 + 1e-9);
    r->sigma_px = at_bound ? 0 : sqrt(p[4]);
    r->rms_dn = ok && nk > NP ? sqrt(cost / (nk - NP)) : NAN;
    r->sigma_std_px = NAN;
    if (ok) {   // sigma's 1-sigma from v's: sqrt(v + sd_v) - sqrt(v) (sd_v / 2 sigma away from 0)
        normal_equations(&E, p, JtJ, Jtr);
        if (chol_solve(NP, JtJ, e4, C) && C[4] > 0) {   // (J^T J)^-1's v,v element
            double sd_v = sqrt(C[4]) * r->rms_dn, v = at_bound ? 0 : p[4];
            r->sigma_std_px = sd_v / (sqrt(v + sd_v) + sqrt(v));
        }
    }
    double contrast = fabs(p[1] - p[0]);
    if (!ok || !isfinite(r->rms_dn) || !isfinite(r->sigma_std_px))
        snprintf(r->why, sizeof r->why, "the fit did not converge");
    else if (contrast < MIN_CONTRAST * r->rms_dn)
        snprintf(r->why, sizeof r->why, "contrast %.3g under %g x the residual RMS %.3g", contrast, MIN_CONTRAST,
                 r->rms_dn);
    else if (fabs(p[2]) > MAX_OFFSET_PX || fabs(p[3]) > MAX_TURN_RAD)
        snprintf(r->why, sizeof r->why, "the edge lies %.2f px off and turned %.3f rad from the corners' line",
                 p[2], p[3]);
    else if (r->sigma_px > MAX_SIGMA_PX)
        snprintf(r->why, sizeof r->why, "sigma %.2f px above %g px", r->sigma_px, MAX_SIGMA_PX);
    else
        r->used = true;
    // the same pixels as seen by points at the pixels' centres: which footprint the edges show
    r->rss_square = ok ? cost : NAN;
    r->rss_point = NAN;
    r->sigma_point_px = NAN;
    if (r->used) {
        double q[NP];
        memcpy(q, p, sizeof q);
        q[4] = fmax(p[4] + 1.0 / 12, MIN_V);   // the square's variance into the blur's
        E.point = true;
        if (edge_lm(&E, q)) {
            r->rss_point = edge_cost(&E, q, NULL);
            r->sigma_point_px = q[4] <= MIN_V * (1 + 1e-9) ? 0 : sqrt(q[4]);
        }
        E.point = false;
    }
    if (r->used) {
        int idx = (int)a->edges->len;   // r is appended next
        for (int k = 0; k < E.n; k++) {
            if (!E.keep[k]) continue;
            double ca = cos(p[3]), sa = sin(p[3]), rx = E.x[k] - E.M[0], ry = E.y[k] - E.M[1];
            double d = (E.nrm[0] * ca - E.u[0] * sa) * rx + (E.nrm[1] * ca - E.u[1] * sa) * ry - p[2];
            psf_sample_t s = { (float)d, (float)((E.P[k] - p[0]) / (p[1] - p[0])), idx };
            g_array_append_val(a->samples, s);
        }
    }
    edge_pixels_free(&E);
    return true;
}

int calib_psf_add_view(calib_psf_acc_t *a, const float *img, int W, int H, const double *q, int camera, int view,
                       int max_edges)
{
    const int nw = a->nw, nh = a->nh, nrow = nh * (nw - 1), total = nrow + nw * (nh - 1);
    int want = max_edges > 0 && max_edges < total ? max_edges : total, fitted = 0;
    for (int k = 0; k < want; k++) {
        int e = (int)((k + 0.5) * total / want);
        // edges 0 .. nh (nw-1) - 1 along the rows (i, j) - (i+1, j), then along the columns (i, j) - (i, j+1)
        int c0, c1;
        if (e < nrow) {
            int j = e / (nw - 1), i = e % (nw - 1);
            c0 = j * nw + i;
            c1 = c0 + 1;
        } else {
            e -= nrow;
            int i = e / (nh - 1), j = e % (nh - 1);
            c0 = j * nw + i;
            c1 = c0 + nw;
        }
        // a corner not seen (a partial view): no edge
        if (!isfinite(q[2 * c0]) || !isfinite(q[2 * c1]) || !isfinite(q[2 * c0 + 1]) || !isfinite(q[2 * c1 + 1]))
            continue;
        calib_psf_edge_t r = { .camera = camera, .view = view, .c0 = c0, .c1 = c1 };
        if (!fit_edge(a, img, W, H, q + 2 * c0, q + 2 * c1, &r)) return -1;
        g_array_append_val(a->edges, r);
        fitted++;
    }
    return fitted;
}

// ---------------------------------------------------------------------------
// The estimate

// Median and 1.4826 MAD of the used edges of camera (all of view when view >=
// 0): their count, -1 + message when out of memory.
static int edges_median(const calib_psf_acc_t *a, int camera, int view, double *med, double *mad)
{
    int n = 0;
    double *v = malloc((a->edges->len + 1) * sizeof *v);
    if (!v) {
        model_error_set(NULL, 0, "out of memory");
        return -1;
    }
    for (guint k = 0; k < a->edges->len; k++) {
        const calib_psf_edge_t *e = &g_array_index(a->edges, calib_psf_edge_t, k);
        if (e->used && e->camera == camera && (view < 0 || e->view == view)) v[n++] = e->sigma_px;
    }
    *med = model_median(v, n);
    for (int k = 0; k < n; k++) v[k] = fabs(v[k] - *med);
    *mad = 1.4826 * model_median(v, n);
    free(v);
    return n;
}

// An estimate that ran out of memory: not estimated, and why.
static void estimate_oom(calib_psf_t *out)
{
    out->estimated = false;
    snprintf(out->why, sizeof out->why, "out of memory");
    model_error_set(NULL, 0, "out of memory");
}

// The scatter of the views' medians (views of 5 edges or more, at least 3 of
// them): out->sigma_std_views_px, and out->views_used. false when out of memory.
static bool views_scatter(const calib_psf_acc_t *a, int camera, calib_psf_t *out)
{
    int maxview = -1;
    for (guint k = 0; k < a->edges->len; k++) {
        const calib_psf_edge_t *e = &g_array_index(a->edges, calib_psf_edge_t, k);
        if (e->camera == camera && e->view > maxview) maxview = e->view;
    }
    double sv = 0, svv = 0;
    int nv = 0;
    for (int v = 0; v <= maxview; v++) {
        double vm, vd;
        int c = edges_median(a, camera, v, &vm, &vd);
        if (c < 0) return false;
        if (c > 0) out->views_used++;
        if (c < 5) continue;
        sv += vm;
        svv += vm * vm;
        nv++;
    }
    if (nv >= 3) {
        double mean = sv / nv, var = fmax(0, (svv - nv * mean * mean) / (nv - 1));
        out->sigma_std_views_px = sqrt(var / nv);
    }
    return true;
}

void calib_psf_estimate(calib_psf_acc_t *a, int camera, calib_psf_t *out)
{
    memset(out, 0, sizeof *out);
    out->sigma_std_views_px = NAN;
    double med, mad;
    for (guint k = 0; k < a->edges->len; k++) {
        const calib_psf_edge_t *e = &g_array_index(a->edges, calib_psf_edge_t, k);
        if (e->camera != camera) continue;
        out->edges_tried++;
        if (e->npix > 0) out->edges_fitted++;
    }
    // the footprint the edges show: the pixel's square, or a point at its centre (a renderer's one ray a pixel,
    // sharper than a square allows) when that fits the used edges' pixels better by more than 5 %
    double rss_sq = 0, rss_pt = 0;
    int nboth = 0;
    for (guint k = 0; k < a->edges->len; k++) {
        const calib_psf_edge_t *e = &g_array_index(a->edges, calib_psf_edge_t, k);
        if (!e->used || e->camera != camera || !isfinite(e->rss_point) || !isfinite(e->rss_square)) continue;
        rss_sq += e->rss_square;
        rss_pt += e->rss_point;
        nboth++;
    }
    out->pixel_fill = 1;
    out->rss_point_over_square = nboth ? rss_pt / rss_sq : NAN;
    if (nboth && rss_pt < 0.95 * rss_sq) {
        out->pixel_fill = 0;
        for (guint k = 0; k < a->edges->len; k++) {
            calib_psf_edge_t *e = &g_array_index(a->edges, calib_psf_edge_t, k);
            if (e->camera != camera) continue;
            if (isfinite(e->sigma_point_px)) e->sigma_px = e->sigma_point_px;
            else e->used = false;
        }
    }
    int n = edges_median(a, camera, -1, &med, &mad);
    if (n < 0) {
        estimate_oom(out);
        return;
    }
    if (n < 10) {
        snprintf(out->why, sizeof out->why, "%d usable edges of %d (at least 10 are needed: a board of squares of "
                 "20 px or more in view, sharp and unsaturated)", n, out->edges_tried);
        return;
    }
    double lim = fmax(4 * mad, 0.05);
    for (guint k = 0; k < a->edges->len; k++) {
        calib_psf_edge_t *e = &g_array_index(a->edges, calib_psf_edge_t, k);
        if (!e->used || e->camera != camera || fabs(e->sigma_px - med) <= lim) continue;
        e->used = false;
        snprintf(e->why, sizeof e->why, "outlier: sigma %.3f px, %.3f from the edges' median %.3f (limit %.3f)",
                 e->sigma_px, e->sigma_px - med, med, lim);
        out->outliers++;
    }
    n = edges_median(a, camera, -1, &med, &mad);
    double *fs = n < 0 ? NULL : malloc(((size_t)n + 1) * sizeof *fs);
    if (!fs) {
        estimate_oom(out);
        return;
    }
    out->sigma_px = med;
    out->spread_px = mad;
    out->edges_used = n;
    // the median's standard error: from the edges' scatter, or from their own fits' 1-sigma when larger
    // (edges at the bound scatter none)
    int m = 0;
    for (guint k = 0; k < a->edges->len; k++) {
        const calib_psf_edge_t *e = &g_array_index(a->edges, calib_psf_edge_t, k);
        if (e->used && e->camera == camera) fs[m++] = e->sigma_std_px;
    }
    double fit_sd = model_median(fs, m);
    free(fs);
    out->sigma_std_edges_px = 1.2533 * fmax(mad, fit_sd) / sqrt(n);
    double *rr = views_scatter(a, camera, out) ? malloc(((size_t)n + 1) * sizeof *rr) : NULL;
    if (!rr) {
        estimate_oom(out);
        return;
    }
    out->sigma_std_px = fmax(out->sigma_std_edges_px, isfinite(out->sigma_std_views_px) ? out->sigma_std_views_px : 0);
    m = 0;
    for (guint k = 0; k < a->edges->len; k++) {
        const calib_psf_edge_t *e = &g_array_index(a->edges, calib_psf_edge_t, k);
        if (e->used && e->camera == camera) rr[m++] = e->rms_dn / fabs(e->level_pos_dn - e->level_neg_dn);
    }
    out->rms_rel = model_median(rr, m);
    free(rr);
    out->estimated = true;
}

json_t *calib_psf_json(const calib_psf_t *p)
{
    json_t *j = json_object();
    json_object_set_new(j, "model", p->estimated ? json_string("gaussian") : json_null());
    if (!p->estimated) {
        json_object_set_new(j, "why", json_string(p->why));
        json_object_set_new(j, "edges_tried", json_integer(p->edges_tried));
        return j;
    }
    json_object_set_new(j, "sigma_px", json_real(p->sigma_px));
    json_object_set_new(j, "sigma_std_px", json_real(p->sigma_std_px));
    json_object_set_new(j, "sigma_std_edges_px", json_real(p->sigma_std_edges_px));
    json_object_set_new(j, "sigma_std_views_px", model_json_number(p->sigma_std_views_px));
    json_object_set_new(j, "sigma_spread_px", json_real(p->spread_px));
    json_object_set_new(j, "edges_used", json_integer(p->edges_used));
    json_object_set_new(j, "edges_fitted", json_integer(p->edges_fitted));
    json_object_set_new(j, "edges_tried", json_integer(p->edges_tried));
    json_object_set_new(j, "outliers", json_integer(p->outliers));
    json_object_set_new(j, "views_used", json_integer(p->views_used));
    json_object_set_new(j, "residual_rms_over_contrast", json_real(p->rms_rel));
    json_object_set_new(j, "pixel_fill", json_real(p->pixel_fill));
    json_object_set_new(j, "footprint", json_string(p->pixel_fill > 0 ? "the pixel's 1 x 1 px square, integrated "
                                                                         "separately"
                                                                       : "a point at the pixel's centre: the edges "
                                                                         "are sharper than a square footprint allows "
                                                                         "(a renderer's one ray a pixel)"));
    json_object_set_new(j, "rss_point_over_square", model_json_number(p->rss_point_over_square));
    json_object_set_new(j, "method", json_string(
        "slanted edge (ISO 12233's idea) on the board's square edges between adjacent found corners: the pixels of "
        "each edge's middle (a fifth of its length, at least 6 px, from either corner; within 6 px or 0.3 of its "
        "length of the line) fitted by least squares with a step convolved with an isotropic Gaussian of sigma and "
        "integrated over the pixel's 1 x 1 px footprint (closed form, model_edge_spread; and again with a point at "
        "the pixel's centre: pixel_fill 0 when that fits the edges' pixels better by more than 5 %), with the edge's own dark "
        "and light levels and the line's offset and turn; sigma = the median over the edges (outliers beyond 4 "
        "robust std dropped; an edge at the lower bound, 0.01 px, counts as 0); sigma_std_px = the larger of the "
        "median's standard error from the edges' scatter or their fits' own 1-sigma (sigma_std_edges_px) and the "
        "views' medians' scatter over sqrt(views) (sigma_std_views_px): noise and view-to-view differences, not a "
        "footprint other than the full square or a PSF of another shape; sigma_spread_px = the edges' robust std "
        "(1.4826 MAD), how much the blur differs over the field and the views"));
    json_object_set_new(j, "units", json_string("px; sigma is the optics' Gaussian standard deviation alone (the "
                                                "pixel's footprint is not in it)"));
    return j;
}

void calib_psf_esf_csv(const calib_psf_acc_t *a, int camera, const char *name, const calib_psf_t *p, FILE *f)
{
    enum { NB = (int)(2 * DMAX_PX / BIN_PX) };
    double sm[NB] = { 0 }, sd[NB] = { 0 };
    long cnt[NB] = { 0 };
    if (!p->estimated) return;
    for (guint k = 0; k < a->samples->len; k++) {
        const psf_sample_t *s = &g_array_index(a->samples, psf_sample_t, k);
        const calib_psf_edge_t *e = &g_array_index(a->edges, calib_psf_edge_t, s->edge);
        if (e->camera != camera || !e->used) continue;
        int b = (int)floor((s->u + DMAX_PX) / BIN_PX);
        if (b < 0 || b >= NB) continue;
        sm[b] += s->e;
        sd[b] += p->pixel_fill > 0 ? model_edge_spread(s->u, e->theta_rad, p->sigma_px, NULL, NULL)
                 : p->sigma_px > 0 ? 0.5 * erfc(-s->u / (p->sigma_px * M_SQRT2))
                                   : (s->u > 0) + 0.5 * (s->u == 0);   // a point footprint: the blur alone
        cnt[b]++;
    }
    double em[NB], ed[NB];
    for (int b = 0; b < NB; b++) {
        em[b] = cnt[b] ? sm[b] / cnt[b] : NAN;
        ed[b] = cnt[b] ? sd[b] / cnt[b] : NAN;
    }
    for (int b = 0; b < NB; b++) {
        if (!cnt[b]) continue;
        double lm = NAN, ld = NAN;
        if (b > 0 && b + 1 < NB && cnt[b - 1] && cnt[b + 1]) {
            lm = (em[b + 1] - em[b - 1]) / (2 * BIN_PX);
            ld = (ed[b + 1] - ed[b - 1]) / (2 * BIN_PX);
        }
        fprintf(f, "%s,%.4f,%ld,%.6f,%.6f,%.6f,%.6f\n", name, -DMAX_PX + (b + 0.5) * BIN_PX, cnt[b], em[b], ed[b], lm,
                ld);
    }
}

// ---------------------------------------------------------------------------
// The geometry run's stage

// DIR/psf_edges.csv: every edge fitted.
static bool edges_csv(const calib_psf_acc_t *a, const calib_geometry_state_t *s, const char *path)
{
    FILE *f = fopen(path, "w");
    if (!f) {
        model_error_set(path, 0, "cannot create: %s", strerror(errno));
        return false;
    }
    fprintf(f, "camera,view,image,corner0,corner1,theta_deg,length_px,pixels,level_neg_dn,level_pos_dn,offset_px,"
               "turn_mrad,sigma_px,sigma_std_px,rms_dn,used,why\n");
    for (guint k = 0; k < a->edges->len; k++) {
        const calib_psf_edge_t *e = &g_array_index(a->edges, calib_psf_edge_t, k);
        const calib_geometry_view_t *v = g_ptr_array_index(s->views.v, e->view);
        fprintf(f, "%s,%d,%s,%d,%d,%.3f,%.2f,%d,%.3f,%.3f,%.4f,%.3f,%.4f,%.4f,%.4f,%d,\"%s\"\n",
                s->ncams > 1 ? s->camnames[e->camera] : "", e->view, v->name, e->c0, e->c1,
                e->theta_rad * 180 / M_PI, e->length_px, e->npix, e->level_neg_dn, e->level_pos_dn, e->offset_px,
                e->turn_rad * 1000, e->sigma_px, e->sigma_std_px, e->rms_dn, e->used, e->why);
    }
    bool ok = !ferror(f);
    if (fclose(f) != 0) ok = false;
    if (!ok) model_error_set(path, 0, "cannot write: %s", strerror(errno));
    return ok;
}

// DIR/psf_esf.csv: each camera's supersampled ESF and LSF.
static bool esf_csv(const calib_psf_acc_t *a, const calib_geometry_state_t *s, const calib_psf_t *est, int ncams,
                    const char *path)
{
    FILE *f = fopen(path, "w");
    if (!f) {
        model_error_set(path, 0, "cannot create: %s", strerror(errno));
        return false;
    }
    fprintf(f, "camera,u_px,samples,esf_measured,esf_model,lsf_measured_per_px,lsf_model_per_px\n");
    for (int c = 0; c < ncams; c++) calib_psf_esf_csv(a, c, ncams > 1 ? s->camnames[c] : "", &est[c], f);
    bool ok = !ferror(f);
    if (fclose(f) != 0) ok = false;
    if (!ok) model_error_set(path, 0, "cannot write: %s", strerror(errno));
    return ok;
}

// The views' edges into a (a few per view: about EDGES_TARGET in all). false +
// message when out of memory.
static bool fit_views(const calib_geometry_opts_t *o, calib_geometry_state_t *s, calib_psf_acc_t *a)
{
    int nv = 0;
    for (guint k = 0; k < s->views.v->len; k++) {
        const calib_geometry_view_t *v = g_ptr_array_index(s->views.v, k);
        nv += v->found && v->q && v->source;
    }
    const int nw = o->board.width_n, nh = o->board.height_n;
    int total = nh * (nw - 1) + nw * (nh - 1), cap = nv ? EDGES_TARGET / nv : total;
    cap = cap < 6 ? 6 : cap > total ? total : cap;
    model_note("the lens's blur from the board's edges (%d views, up to %d edges each)",
               nv, cap);
    for (guint k = 0; k < s->views.v->len; k++) {
        const calib_geometry_view_t *v = g_ptr_array_index(s->views.v, k);
        if (!v->found || !v->q || !v->source) continue;
        int w = 0, h = 0;
        float *img = model_image_read_float(v->source, &w, &h);
        if (!img) {
            model_warning("the blur leaves out %s: %s", v->source, model_last_error());
            continue;
        }
        int n = calib_psf_add_view(a, img, w, h, v->q, v->camera, (int)k, cap);
        free(img);
        if (n < 0) {
            model_error_set(v->source, 0, "out of memory");
            return false;
        }
    }
    return true;
}

bool calib_psf_geometry(const calib_geometry_opts_t *o, calib_geometry_state_t *s)
{
    int ncams = s->ncams > 1 ? s->ncams : 1;
    calib_psf_t est[RIG_CAMERAS_MAX];
    memset(est, 0, sizeof est);
    calib_psf_acc_t *a = NULL;
    bool ok = true;
    if (o->corners) {
        for (int c = 0; c < ncams; c++)
            snprintf(est[c].why, sizeof est[c].why, "no images: the corners came from --corners (the blur needs "
                     "the frames)");
    } else if (o->board.kind == CALIB_BOARD_CHARUCO) {
        for (int c = 0; c < ncams; c++)
            snprintf(est[c].why, sizeof est[c].why, "a ChArUco board: its markers come within a few pixels of the "
                     "squares' edges (the blur needs a chessboard's clear squares)");
    } else if (!(a = calib_psf_acc_new(o->board.width_n, o->board.height_n))) {
        model_error_set(s->outdir, 0, "out of memory");
        return false;
    } else {
        if (!fit_views(o, s, a)) {
            calib_psf_acc_free(a);
            return false;
        }
        for (int c = 0; c < ncams; c++) calib_psf_estimate(a, c, &est[c]);
        char *ep = g_strdup_printf("%s/psf_edges.csv", s->outdir), *sp = g_strdup_printf("%s/psf_esf.csv", s->outdir);
        ok = edges_csv(a, s, ep) && esf_csv(a, s, est, ncams, sp);
        g_free(ep);
        g_free(sp);
    }
    for (int c = 0; c < ncams; c++) {
        const calib_psf_t *p = &est[c];
        json_t *j = calib_psf_json(p);
        if (a && p->estimated) {
            json_object_set_new(j, "esf_csv", json_string("psf_esf.csv"));
            json_object_set_new(j, "edges_csv", json_string("psf_edges.csv"));
        }
        if (c == 0) json_object_set(s->out, "psf", j);
        if (ncams > 1) json_object_set(json_array_get(json_object_get(s->out, "cameras"), (size_t)c), "psf", j);
        json_decref(j);
        char cam[RIG_CAMERA_NAME_MAX + 16] = "";
        if (ncams > 1) snprintf(cam, sizeof cam, " of %s", s->camnames[c]);
        if (p->estimated)
            model_note("lens blur%s: Gaussian PSF sigma %.3f +- %.3f px (the optics' alone; "
                       "the pixel's footprint apart) from %d edges of %d views", cam, p->sigma_px, p->sigma_std_px,
                       p->edges_used, p->views_used);
        else
            model_note("lens blur%s not estimated: %s", cam, p->why);
    }
    if (ncams > 1)
        json_object_set_new(s->out, "psf_note", json_string("the lens blur per camera in cameras[].psf; the top "
                                                            "level's psf is the first camera's"));
    calib_psf_acc_free(a);
    return ok;
}

void calib_psf_report(FILE *f, const calib_geometry_state_t *s)
{
    json_t *top = json_object_get(s->out, "psf"), *cams = json_object_get(s->out, "cameras");
    if (!top) return;
    model_html_heading(f, "Lens blur (point-spread function)");
    int ncams = s->ncams > 1 && json_array_size(cams) == (size_t)s->ncams ? s->ncams : 1;
    for (int c = 0; c < ncams; c++) {
        json_t *p = ncams > 1 ? json_object_get(json_array_get(cams, (size_t)c), "psf") : top;
        char cam[RIG_CAMERA_NAME_MAX + 16] = "";
        if (ncams > 1) snprintf(cam, sizeof cam, "%s: ", s->camnames[c]);
        if (!json_is_string(json_object_get(p, "model"))) {
            model_html_para(f, "%sNot estimated: %s.", cam, json_string_value(json_object_get(p, "why")));
            continue;
        }
        model_html_para(f, "%sGaussian PSF of sigma %.3f px, 1-sigma %.3f px (the optics' blur alone: the pixel's "
                        "1 x 1 px footprint is integrated separately), the median of %lld edges of %lld views "
                        "(%lld fitted, %lld outliers); the edges' sigmas spread %.3f px (robust std); residual RMS "
                        "%.2f %% of the contrast (median).", cam,
                        json_number_value(json_object_get(p, "sigma_px")),
                        json_number_value(json_object_get(p, "sigma_std_px")),
                        json_integer_value(json_object_get(p, "edges_used")),
                        json_integer_value(json_object_get(p, "views_used")),
                        json_integer_value(json_object_get(p, "edges_fitted")),
                        json_integer_value(json_object_get(p, "outliers")),
                        json_number_value(json_object_get(p, "sigma_spread_px")),
                        100 * json_number_value(json_object_get(p, "residual_rms_over_contrast")));
    }
    model_html_para(f, "Method: %s.", json_string_value(json_object_get(top, "method")) ?: "-");
    char *png = g_strdup_printf("%s/psf.png", s->outdir);
    if (access(png, R_OK) == 0)
        model_html_figure(f, "psf.png", "The board's edges (first camera): the supersampled edge spread function "
                          "(1/8 px bins, normalised 0..1 between each edge's fitted levels) and its line spread "
                          "function against the distance from the fitted edge, measured (dots) and the model "
                          "(line: the step blurred by the Gaussian of the estimated sigma and integrated over the "
                          "pixel's footprint), and the edges' sigmas");
    g_free(png);
}

// ---------------------------------------------------------------------------
// The calibration set's reader (calib/calib.h)

bool calib_psf_read(const char *camera_model, const char *camera, double *sigma_px, double *sigma_std_px,
                    double *pixel_fill, char **geometry_json)
{
    *sigma_px = *sigma_std_px = NAN;
    if (pixel_fill) *pixel_fill = 1;
    if (geometry_json) *geometry_json = NULL;
    char *dir = g_path_get_dirname(camera_model), *path = g_strdup_printf("%s/geometry.json", dir);
    g_free(dir);
    json_t *g = access(path, R_OK) == 0 ? json_load_file(path, 0, NULL) : NULL, *p = NULL;
    if (g && !calib_geometry_json_check(g, path, NULL)) {   // a newer refl's: refused, and said (the callers go on)
        model_warning("%s; its lens blur is not used", model_last_error());
        json_decref(g);
        g = NULL;
    }
    char *base = g_path_get_basename(camera_model);
    if (!camera && g_str_has_suffix(base, ".cameramodel")) {   // DIR/NAME.cameramodel of several cameras
        base[strlen(base) - strlen(".cameramodel")] = 0;
        camera = base;
    }
    if (g && camera && *camera) {   // the camera's own, when the run calibrated several
        size_t k;
        json_t *c;
        json_array_foreach(json_object_get(g, "cameras"), k, c) {
            const char *n = json_string_value(json_object_get(c, "name"));
            if (n && !strcmp(n, camera) && json_object_get(c, "psf")) p = json_object_get(c, "psf");
        }
    }
    if (g && !p) p = json_object_get(g, "psf");
    const char *model = json_string_value(json_object_get(p, "model"));
    json_t *s = json_object_get(p, "sigma_px"), *sd = json_object_get(p, "sigma_std_px");
    bool ok = model && !strcmp(model, "gaussian") && json_is_number(s) && json_is_number(sd) &&
              json_number_value(s) >= 0 && json_number_value(sd) >= 0;
    if (ok) {
        *sigma_px = json_number_value(s);
        *sigma_std_px = json_number_value(sd);
        json_t *f = json_object_get(p, "pixel_fill");
        if (pixel_fill && json_is_number(f) && json_number_value(f) >= 0 && json_number_value(f) <= 1)
            *pixel_fill = json_number_value(f);
        if (geometry_json) *geometry_json = g_strdup(path);
    }
    json_decref(g);
    g_free(path);
    g_free(base);
    return ok;
}
