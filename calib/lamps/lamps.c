// calib/lamps/lamps.c — `refl calib lamps`: lamp positions from the highlights of a
// mirror (chrome) sphere carried round by the turntable.
//
// Flow: a capture plan (the mirror sphere at several turntable angles, each
// lamp alone, a dark frame per angle, auto-bracketed exposures) run with
// calib_capture into DIR/capture (or a session captured elsewhere) -> per
// angle and lamp: the highlight on the sphere's predicted image (dark
// subtracted, brightest compact blob on the sphere's pixels, centroid) -> the
// ray toward the lamp from a model of the highlight in direction space (each
// pixel's camera ray meets the sphere, centre Rz(angle) c0, radius R; the
// mirror's GGX lobe around the lamp's direction, the lamp a disk of its
// angular size, point-sampled at the pixel centres) -> each lamp the
// least-squares point nearest its rays (outliers dropped by deleted
// residuals), covariance from the residuals; then the lamp's disk size from
// that distance and the fit once more; then (--sphere-path fit, the default)
// the joint fit of every lamp and the sphere's path over all highlights
// (calib_lamps_bundle: the path's offset, shift and tilt with priors, the
// highlights fitted again at the fitted path, the joint fit again) ->
// DIR/lamps.json, DIR/report.html (plots by scripts/calib_lamps_report.py).
// calib_lamps_run does it in stages (calib/lamps/lamps.h): calib_lamps_open (the
// capture or the session, the frames), _find_highlights, _triangulate_lamps,
// _joint_fit, _write_json, _write_report; `refl calib lamps` is
// calib/cmd_lamps.c.
//
// Measured on the virtual rig (tests/test_calib_lamps.c): the centroid alone
// is biased by the point sampling of a highlight ~2 px wide (0.06 px RMS);
// the direction-space model with the exact lobe and the lamp's disk brings
// the per-ray error to ~1 mrad; the depth along each lamp's line of sight is
// the weak direction (the sphere's circle of 60 mm seen from 0.75 m).
// Why the joint fit: the sphere is 25 mm and 0.87 m from the camera, the
// lamps ~0.8 m from it, so where the camera model puts the sphere relative to
// itself is amplified ~60x at the lamps (0.07 mm -> 5 mm). The demo's
// calibrated camera (centre 1.45 mm off, 0.05 deg) moves the sphere by
// ~0.05-0.1 mm, mostly without turning with the table, and tilts its circle
// by ~0.25 mrad: with the sphere held 7.5 mm RMS, joint 1.9 mm (the true
// camera: 1.37 held, 1.35 joint). The path's tilt and the offset across the
// view are well observed (std ~0.045 mrad, ~0.002-0.009 mm); the shift and
// the offset's z (the path's height relative to the camera) are weak (std
// 0.06-0.08 mm against a 0.1 mm prior: condition ~1e4), and they are the
// main part of each lamp's stated std (~3 mm): on synthetic highlights with
// the virtual rig's ray noise (0.02 px) the joint fit's lamps are 1.5-4.6 mm
// RMS off over seeds, within 4 stated std (tests: calib_lamps_bundle_synthetic).
// The sphere's limb, which would fix the shift, is not seen in these frames
// (the ball mirrors a dark room).
#define _GNU_SOURCE
#include <errno.h>
#include <glib.h>
#include <limits.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "calib/calib.h"
#include "calib/lamps/lamps.h"
#include "model/base/lsq.h"
#include "model/model.h"
#include "model/base/report.h"
#include "model/base/vec.h"
#include "rig/rig.h"

// ---------------------------------------------------------------------------
// The sphere's image

void calib_lamps_sphere_image_free(calib_lamps_sphere_image_t *s)
{
    if (!s) return;
    free(s->on);
    free(s);
}

// Distance along the unit ray (o, d) to the sphere's near surface; NAN on a miss.
static double ray_sphere(model_vec3_t o, model_vec3_t d, model_vec3_t c, double r)
{
    model_vec3_t oc = v3_sub(o, c);
    double b = v3_dot(d, oc), cc = v3_dot(oc, oc) - r * r, disc = b * b - cc;
    if (disc < 0) return NAN;
    double t = -b - sqrt(disc);
    return t > 0 ? t : NAN;
}

calib_lamps_sphere_image_t *calib_lamps_sphere_image(const model_camera_t *cam, model_vec3_t c, double r)
{
    const int W = model_camera_width(cam), H = model_camera_height(cam);
    model_vec3_t C = model_camera_centre_world(cam);
    model_vec3_t cc = v3_sub(c, C);
    double dist = sqrt(v3_dot(cc, cc));
    if (!(dist > r * 1.01)) {
        model_error_set(NULL, 0, "the sphere (centre %.1f %.1f %.1f mm, radius %g mm) contains the camera centre", c.x,
                        c.y, c.z, r);
        return NULL;
    }
    // silhouette: points of the sphere's tangent cone from the camera centre
    model_vec3_t a = v3_scale(cc, 1 / dist);
    model_vec3_t u = fabs(a.z) < 0.9 ? v3(0, 0, 1) : v3(1, 0, 0);
    model_vec3_t e1 = v3_sub(u, v3_scale(a, v3_dot(u, a)));
    e1 = v3_scale(e1, 1 / sqrt(v3_dot(e1, e1)));
    model_vec3_t e2 = v3_cross(a, e1);
    double sa = r / dist, ca = sqrt(1 - sa * sa);
    enum { NS = 72 };
    model_vec3_t pts[NS + 1];
    for (int k = 0; k < NS; k++) {
        double ph = 2 * M_PI * k / NS;
        // a tangent point: centre - r (sa a - ca (cos e1 + sin e2))
        model_vec3_t rad = v3_add(v3_scale(e1, cos(ph)), v3_scale(e2, sin(ph)));
        pts[k] = v3_add(c, v3_scale(v3_sub(v3_scale(rad, ca), v3_scale(a, sa)), r));
    }
    pts[NS] = c;
    double q[2 * (NS + 1)];
    if (!model_camera_project(cam, pts, NS + 1, q)) return NULL;
    double xmin = INFINITY, xmax = -INFINITY, ymin = INFINITY, ymax = -INFINITY, rad_px = 0;
    for (int k = 0; k < NS; k++) {
        xmin = fmin(xmin, q[2 * k]);
        xmax = fmax(xmax, q[2 * k]);
        ymin = fmin(ymin, q[2 * k + 1]);
        ymax = fmax(ymax, q[2 * k + 1]);
        rad_px = fmax(rad_px, hypot(q[2 * k] - q[2 * NS], q[2 * k + 1] - q[2 * NS + 1]));
    }
    int x0 = (int)floor(xmin) - 3, x1 = (int)ceil(xmax) + 3, y0 = (int)floor(ymin) - 3, y1 = (int)ceil(ymax) + 3;
    if (!isfinite(xmin) || x1 < 0 || y1 < 0 || x0 >= W || y0 >= H) {
        model_error_set(NULL, 0, "the sphere (centre %.1f %.1f %.1f mm) is outside the camera's view", c.x, c.y, c.z);
        return NULL;
    }
    x0 = x0 < 0 ? 0 : x0;
    y0 = y0 < 0 ? 0 : y0;
    x1 = x1 >= W ? W - 1 : x1;
    y1 = y1 >= H ? H - 1 : y1;
    calib_lamps_sphere_image_t *s = calloc(1, sizeof *s);
    int w = x1 - x0 + 1, h = y1 - y0 + 1;
    double *qq = malloc(sizeof *qq * 2 * (size_t)w * h);
    model_vec3_t *dirs = malloc(sizeof *dirs * (size_t)w * h);
    if (!s || !qq || !dirs || !(s->on = calloc((size_t)w * h, 1))) {
        free(qq);
        free(dirs);
        calib_lamps_sphere_image_free(s);
        model_error_set(NULL, 0, "out of memory");
        return NULL;
    }
    s->x0 = x0;
    s->y0 = y0;
    s->w = w;
    s->h = h;
    s->q_centre[0] = q[2 * NS];
    s->q_centre[1] = q[2 * NS + 1];
    s->radius_px = rad_px;
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            qq[2 * (y * w + x)] = x0 + x;
            qq[2 * (y * w + x) + 1] = y0 + y;
        }
    bool ok = model_camera_unproject(cam, qq, w * h, dirs);
    for (int i = 0; ok && i < w * h; i++) s->on[i] = isfinite(ray_sphere(C, dirs[i], c, r));
    free(qq);
    free(dirs);
    if (!ok) {
        calib_lamps_sphere_image_free(s);
        return NULL;
    }
    return s;
}

// ---------------------------------------------------------------------------
// Highlights

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
    double I[25] = { 0 }, A[25];
    double s2 = cost / (n > 5 ? n - 5 : 1), var[2];
    for (int k = 1; k <= 2; k++) {
        memcpy(A, JTJ, sizeof A);
        double e[5] = { 0 };
        e[k] = 1;
        if (!model_solve_linear(A, e, 5)) return false;
        var[k - 1] = s2 * e[k];
    }
    (void)I;
    *q_std = sqrt(fmax(0, var[0]) + fmax(0, var[1]));
    return true;
}

void calib_lamps_find_highlight(const float *img, const float *dark, int W, int H,
                                const calib_lamps_sphere_image_t *sph, double min_snr, double min_peak_dn,
                                int max_blob_px, double sat_dn, calib_lamps_highlight_t *o)
{
    memset(o, 0, sizeof *o);
    const int w = sph->w, h = sph->h, x0 = sph->x0, y0 = sph->y0;
    double *D = malloc(sizeof *D * (size_t)w * h), *tmp = malloc(sizeof *tmp * (size_t)w * h);
    int *stack = malloc(sizeof *stack * (size_t)w * h);
    unsigned char *blob = calloc((size_t)w * h, 1);
    if (!D || !tmp || !stack || !blob) {
        snprintf(o->why, sizeof o->why, "out of memory");
        goto done;
    }
    (void)H;
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            size_t k = (size_t)(y0 + y) * W + (x0 + x);
            D[y * w + x] = img[k] - (dark ? dark[k] : 0);
        }
    // background: median of the difference off the sphere (the box's margin and
    // corners); noise: its MAD
    int nb = 0;
    for (int i = 0; i < w * h; i++)
        if (!sph->on[i]) tmp[nb++] = D[i];
    if (nb < 8)
        for (int i = 0; i < w * h; i++) tmp[nb++] = D[i];
    double bg = model_median(tmp, nb);
    for (int i = 0; i < nb; i++) tmp[i] = fabs(tmp[i] - bg);
    double noise = 1.4826 * model_median(tmp, nb);
    if (!(noise > 0.5)) noise = 0.5;   // quantisation floor (integer DN)
    for (int i = 0; i < w * h; i++) D[i] -= bg;
    o->noise_dn = noise;
    int best = -1;
    for (int i = 0; i < w * h; i++)
        if (sph->on[i] && (best < 0 || D[i] > D[best])) best = i;
    if (best < 0) {
        snprintf(o->why, sizeof o->why, "no pixel of the sphere's predicted image is on the imager");
        goto done;
    }
    o->peak_dn = D[best];
    size_t kbest = (size_t)(y0 + best / w) * W + (x0 + best % w);
    o->saturated = img[kbest] >= sat_dn;
    double need = fmax(min_snr * noise, min_peak_dn);
    if (!(o->peak_dn >= need)) {
        snprintf(o->why, sizeof o->why, "brightest pixel on the sphere's image is %.1f DN above the background "
                 "(noise %.1f DN; a highlight needs %.0f DN)", o->peak_dn, noise, need);
        goto done;
    }
    // the blob: 8-connected pixels >= 20 % of the peak
    double thr = 0.2 * o->peak_dn;
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
    o->blob_px = nblob;
    if (nblob > max_blob_px) {
        snprintf(o->why, sizeof o->why, "the brightest spot on the sphere's image is a broad patch of %d pixels "
                 "(>= 20 %% of its peak %.0f DN), not a lamp's highlight (at most %d pixels)", nblob, o->peak_dn,
                 max_blob_px);
        goto done;
    }
    // centroid of the blob grown by one pixel (the dim wings carry position too)
    double sw = 0, sx = 0, sy = 0;
    int bxp = best % w, byp = best / w;
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
            sx += v * (x0 + x);
            sy += v * (y0 + y);
        }
    o->q_centroid[0] = sx / sw;
    o->q_centroid[1] = sy / sw;
    o->q[0] = o->q_centroid[0];
    o->q[1] = o->q_centroid[1];
    o->q_std_px = NAN;
    // Gaussian fit on the 7x7 window (pixels of the sphere only; saturated
    // pixels left out: their value is clipped)
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
    if (n >= 9 && gauss_fit(xs, ys, vs, n, p, &rms, &qs) && hypot(p[1] - o->q_centroid[0], p[2] - o->q_centroid[1]) < 1.0 &&
        p[3] > 0.15 && p[3] < 4 && p[4] > 0.15 && p[4] < 4) {
        o->q[0] = p[1];
        o->q[1] = p[2];
        o->sigma_px[0] = p[3];
        o->sigma_px[1] = p[4];
        o->q_std_px = qs;
        o->fit_used = true;
    }
    // the window for the direction-space fit
    o->win_x0 = x0 + bxp - 4;
    o->win_y0 = y0 + byp - 4;
    for (int i = 0; i < 81; i++) {
        int x = bxp - 4 + i % 9, y = byp - 4 + i / 9;
        o->win[i] = NAN;
        if (x < 0 || y < 0 || x >= w || y >= h || !sph->on[y * w + x]) continue;
        if (img[(size_t)(y0 + y) * W + (x0 + x)] >= sat_dn) continue;
        o->win[i] = D[y * w + x];
    }
    o->found = true;
done:
    free(D);
    free(tmp);
    free(stack);
    free(blob);
}

bool calib_lamps_reflect(const model_camera_t *cam, const double q[2], model_vec3_t c, double r, model_vec3_t *p,
                         model_vec3_t *dir)
{
    model_vec3_t d;
    if (!model_camera_unproject(cam, q, 1, &d)) return false;
    model_vec3_t C = model_camera_centre_world(cam);
    double t = ray_sphere(C, d, c, r);
    if (!isfinite(t)) {
        model_error_set(NULL, 0, "the camera ray through (%.2f, %.2f) px misses the sphere (centre %.1f %.1f %.1f mm, "
                        "radius %g mm)", q[0], q[1], c.x, c.y, c.z, r);
        return false;
    }
    *p = v3_add(C, v3_scale(d, t));
    model_vec3_t n = v3_scale(v3_sub(*p, c), 1 / r);
    *dir = v3_sub(d, v3_scale(n, 2 * v3_dot(d, n)));
    *dir = v3_scale(*dir, 1 / sqrt(v3_dot(*dir, *dir)));
    return true;
}

// Disk quadrature: points of a unit disk (centre + rings), equal area weights.
enum { NDISK = 1 + 6 + 12 + 18 };
static void disk_points(double pts[NDISK][2])
{
    int k = 0;
    pts[k][0] = pts[k][1] = 0;
    k++;
    for (int ring = 1; ring <= 3; ring++) {
        // ring j: 6 j points at radius (j / 3.5) (equal areas of the annuli)
        double rad = ring / 3.5;
        for (int m = 0; m < 6 * ring; m++) {
            double ph = 2 * M_PI * (m + 0.5 * (ring % 2)) / (6 * ring);
            pts[k][0] = rad * cos(ph);
            pts[k][1] = rad * sin(ph);
            k++;
        }
    }
}

// The mirror point on the sphere for reflection toward direction u (from camera C).
static model_vec3_t mirror_point(model_vec3_t C, model_vec3_t c, double r, model_vec3_t u)
{
    model_vec3_t cc = v3_sub(C, c);
    model_vec3_t p = v3_add(c, v3_scale(cc, r / sqrt(v3_dot(cc, cc))));
    for (int it = 0; it < 100; it++) {
        model_vec3_t v = v3_sub(C, p);
        v = v3_scale(v, 1 / sqrt(v3_dot(v, v)));
        model_vec3_t hh = v3_add(v, u);
        hh = v3_scale(hh, 1 / sqrt(v3_dot(hh, hh)));
        model_vec3_t pn = v3_add(c, v3_scale(hh, r));
        model_vec3_t dp = v3_sub(pn, p);
        p = pn;
        if (v3_dot(dp, dp) < 1e-16) break;
    }
    return p;
}

typedef struct {
    int          n;
    double       val[81];
    model_vec3_t nrm[81], v[81];    // per pixel: the sphere's normal and the unit vector to the camera
    double       inv_nv[81];        // 1 / (n.v)
    double       wt[81];            // weights of the residuals
    model_vec3_t u0, e1, e2;        // start direction and its tangent frame
    double       rho;               // lamp disk radius, rad
    double       disk[NDISK][2];
} dirfit_t;

// The mirror's reflection of the lamp at pixel i for parameters p = (A, a, b,
// alpha): the lamp's centre direction u = u0 + a e1 + b e2 (normalised), its
// disk (angular radius rho) sampled at NDISK points w; the GGX lobe
// D(n.h(v, w)) scaled to 1 at its peak, averaged over the disk, times 1 / (n.v)
// (the BRDF's D G F / (4 n.v) with G and F taken as constant over a highlight).
static double dir_model(const dirfit_t *f, const double *p, int i)
{
    double al2 = p[3] * p[3], sum = 0;
    int nd = f->rho > 0 ? NDISK : 1;
    model_vec3_t u = v3_add(f->u0, v3_add(v3_scale(f->e1, p[1]), v3_scale(f->e2, p[2])));
    u = v3_scale(u, 1 / sqrt(v3_dot(u, u)));
    for (int k = 0; k < nd; k++) {
        model_vec3_t w = u;
        if (nd > 1) {
            w = v3_add(u, v3_add(v3_scale(f->e1, f->rho * f->disk[k][0]), v3_scale(f->e2, f->rho * f->disk[k][1])));
            w = v3_scale(w, 1 / sqrt(v3_dot(w, w)));
        }
        model_vec3_t h = v3_add(w, f->v[i]);
        double c = v3_dot(f->nrm[i], h) / sqrt(v3_dot(h, h));
        double den = c * c * (al2 - 1) + 1;
        sum += al2 * al2 / (den * den);
    }
    return p[0] * sum / nd * f->inv_nv[i];
}

static double dir_cost(const dirfit_t *f, const double *p)
{
    double c = 0;
    for (int i = 0; i < f->n; i++) {
        double r = f->val[i] - dir_model(f, p, i);
        c += f->wt[i] * r * r;
    }
    return c;
}

bool calib_lamps_fit_direction(const model_camera_t *cam, const calib_lamps_highlight_t *hl, model_vec3_t c,
                               double r, double rho, model_vec3_t *p_out, model_vec3_t *dir_out, double *lobe_rad)
{
    model_vec3_t C = model_camera_centre_world(cam);
    model_vec3_t p0, u0;
    if (!calib_lamps_reflect(cam, hl->q_centroid, c, r, &p0, &u0)) return false;
    model_vec3_t e1 = fabs(u0.z) < 0.9 ? v3(0, 0, 1) : v3(1, 0, 0);
    e1 = v3_sub(e1, v3_scale(u0, v3_dot(e1, u0)));
    e1 = v3_scale(e1, 1 / sqrt(v3_dot(e1, e1)));
    model_vec3_t e2 = v3_cross(u0, e1);
    dirfit_t f = { .rho = rho, .u0 = u0, .e1 = e1, .e2 = e2 };
    disk_points(f.disk);
    double q[2 * 81];
    int idx[81], m = 0;
    for (int i = 0; i < 81; i++)
        if (isfinite(hl->win[i])) {
            q[2 * m] = hl->win_x0 + i % 9;
            q[2 * m + 1] = hl->win_y0 + i / 9;
            idx[m++] = i;
        }
    model_vec3_t d[81];
    if (m < 9 || !model_camera_unproject(cam, q, m, d)) {
        model_error_set(NULL, 0, "too few pixels around the highlight for the direction fit (%d)", m);
        return false;
    }
    for (int k = 0; k < m; k++) {
        double t = ray_sphere(C, d[k], c, r);
        if (!isfinite(t)) continue;
        model_vec3_t pp = v3_add(C, v3_scale(d[k], t)), n = v3_scale(v3_sub(pp, c), 1 / r);
        double nv = -v3_dot(n, d[k]);
        if (!(nv > 0.05)) continue;
        f.nrm[f.n] = n;
        f.v[f.n] = v3_scale(d[k], -1);
        f.inv_nv[f.n] = 1 / nv;
        f.val[f.n] = hl->win[idx[k]];
        f.wt[f.n] = 1;
        f.n++;
    }
    if (f.n < 9) {
        model_error_set(NULL, 0, "too few pixels of the highlight on the sphere for the direction fit (%d)", f.n);
        return false;
    }
    // start: the peak, at the centroid's direction, the lobe ~ a pixel's angle
    double p[4] = { hl->peak_dn, 0, 0, 0.01 };
    // three rounds: unweighted, then reweighted twice (on the virtual rig this
    // halves the per-ray error where the renderer's sampling noise dominates)
    for (int round = 0; round < 3; round++) {
        if (round > 0) {
            // the renderer's and the lobe's errors grow with the signal: weights
            // 1 / (noise^2 + (kappa model)^2), kappa from the last residuals
            double num = 0, den = 0;
            for (int i = 0; i < f.n; i++) {
                double m0 = dir_model(&f, p, i), r0 = f.val[i] - m0;
                num += r0 * r0;
                den += m0 * m0;
            }
            double k2 = den > 0 ? num / den : 0, s2 = hl->noise_dn * hl->noise_dn;
            for (int i = 0; i < f.n; i++) {
                double m0 = dir_model(&f, p, i);
                f.wt[i] = 1 / (s2 + k2 * m0 * m0);
            }
        }
        double lambda = 1e-2;
        double cost = dir_cost(&f, p);
        for (int it = 0; it < 80; it++) {
            double J[81][4], res[81];
            for (int i = 0; i < f.n; i++) {
                double m0 = dir_model(&f, p, i);
                res[i] = f.val[i] - m0;
                for (int k = 0; k < 4; k++) {
                    double pk[4] = { p[0], p[1], p[2], p[3] };
                    double h = k == 0 ? 1e-6 * fmax(1, fabs(p[0])) : 1e-7;
                    pk[k] += h;
                    J[i][k] = (dir_model(&f, pk, i) - m0) / h;
                }
            }
            double A[16] = { 0 }, b[4] = { 0 };
            for (int i = 0; i < f.n; i++)
                for (int k = 0; k < 4; k++) {
                    b[k] += f.wt[i] * J[i][k] * res[i];
                    for (int l = 0; l < 4; l++) A[k * 4 + l] += f.wt[i] * J[i][k] * J[i][l];
                }
            for (int k = 0; k < 4; k++) A[k * 5] *= 1 + lambda;
            if (!model_solve_linear(A, b, 4)) break;
            double pn[4] = { p[0] + b[0], p[1] + b[1], p[2] + b[2], p[3] + b[3] };
            if (!(pn[3] > 5e-4 && pn[0] > 0)) {
                lambda *= 10;
                if (lambda > 1e8) break;
                continue;
            }
            double cn = dir_cost(&f, pn);
            if (cn <= cost) {
                double step = fabs(b[1]) + fabs(b[2]);
                memcpy(p, pn, sizeof p);
                cost = cn;
                lambda = fmax(lambda * 0.3, 1e-9);
                if (step < 1e-9) break;
            } else {
                lambda *= 10;
                if (lambda > 1e8) break;
            }
        }
    }
    if (!(hypot(p[1], p[2]) < 0.05)) {
        model_error_set(NULL, 0, "the direction fit moved %.3f rad from the centroid's direction", hypot(p[1], p[2]));
        return false;
    }
    model_vec3_t u = v3_add(u0, v3_add(v3_scale(e1, p[1]), v3_scale(e2, p[2])));
    u = v3_scale(u, 1 / sqrt(v3_dot(u, u)));
    *dir_out = u;
    *p_out = mirror_point(C, c, r, u);
    if (lobe_rad) *lobe_rad = p[3];
    return true;
}

// ---------------------------------------------------------------------------
// Triangulation

// Inverse of a 3x3 matrix; false when singular.
static bool inv3(const double *m, double *out)
{
    double c00 = m[4] * m[8] - m[5] * m[7], c01 = m[5] * m[6] - m[3] * m[8], c02 = m[3] * m[7] - m[4] * m[6];
    double det = m[0] * c00 + m[1] * c01 + m[2] * c02;
    if (!(fabs(det) > 1e-300)) return false;
    double id = 1 / det;
    out[0] = c00 * id;
    out[1] = (m[2] * m[7] - m[1] * m[8]) * id;
    out[2] = (m[1] * m[5] - m[2] * m[4]) * id;
    out[3] = c01 * id;
    out[4] = (m[0] * m[8] - m[2] * m[6]) * id;
    out[5] = (m[2] * m[3] - m[0] * m[5]) * id;
    out[6] = c02 * id;
    out[7] = (m[1] * m[6] - m[0] * m[7]) * id;
    out[8] = (m[0] * m[4] - m[1] * m[3]) * id;
    return true;
}

// The smallest eigenvalue of the symmetric 3x3 a.
static double min_eig(const double a[9])
{
    double e[9];
    memcpy(e, a, sizeof e);
    model_sym_eigen(3, e, NULL);
    return fmin(e[0], fmin(e[4], e[8]));
}

static bool fit_once(const model_vec3_t *p, const model_vec3_t *d, int n, const bool *used, calib_lamps_fit_t *o)
{
    double A[9] = { 0 }, b[3] = { 0 };
    int m = 0;
    for (int i = 0; i < n; i++) {
        if (!used[i]) continue;
        double dd[3] = { d[i].x, d[i].y, d[i].z }, pp[3] = { p[i].x, p[i].y, p[i].z };
        for (int r = 0; r < 3; r++)
            for (int c = 0; c < 3; c++) {
                double P = (r == c) - dd[r] * dd[c];
                A[r * 3 + c] += P;
                b[r] += P * pp[c];
            }
        m++;
    }
    o->n_used = m;
    o->min_eig = min_eig(A);
    double Ai[9];
    if (m < 3 || !inv3(A, Ai)) return false;
    for (int r = 0; r < 3; r++) o->x_mm[r] = Ai[r * 3] * b[0] + Ai[r * 3 + 1] * b[1] + Ai[r * 3 + 2] * b[2];
    memcpy(o->cov_mm2, Ai, sizeof Ai);
    return true;
}

static double ray_dist(model_vec3_t p, model_vec3_t d, const double x[3])
{
    model_vec3_t e = v3_sub(v3(x[0], x[1], x[2]), p);
    model_vec3_t perp = v3_sub(e, v3_scale(d, v3_dot(e, d)));
    return sqrt(v3_dot(perp, perp));
}

bool calib_lamps_triangulate(const model_vec3_t *p, const model_vec3_t *d, int n, double reject_sigma,
                             double floor_mm, bool *used, double *dist_mm, calib_lamps_fit_t *o)
{
    memset(o, 0, sizeof *o);
    int navail = 0;
    for (int i = 0; i < n; i++) navail += used[i];
    if (navail < 3) {
        model_error_set(NULL, 0, "%d ray%s: a position needs at least 3", navail, navail == 1 ? "" : "s");
        return false;
    }
    double *dist = malloc(sizeof *dist * (size_t)n), *tmp = malloc(sizeof *tmp * (size_t)n);
    double *del = malloc(sizeof *del * (size_t)n);
    bool ok = false;
    int max_drop = navail / 3, dropped = 0;
    for (;;) {
        if (!fit_once(p, d, n, used, o) || !(o->min_eig > 1e-4)) {
            model_error_set(NULL, 0, "the %d rays are (nearly) parallel (smallest spread %.2g): they do not fix a "
                            "point; use more turntable angles", o->n_used, o->min_eig);
            goto done;
        }
        // deleted residuals: each used ray's distance from the fit without it
        // (a gross outlier drags the plain fit toward itself; not this one)
        int m = 0;
        calib_lamps_fit_t loo;
        for (int i = 0; i < n; i++) {
            dist[i] = ray_dist(p[i], d[i], o->x_mm);
            del[i] = dist[i];
            if (!used[i]) continue;
            used[i] = false;
            if (o->n_used > 3 && fit_once(p, d, n, used, &loo)) del[i] = ray_dist(p[i], d[i], loo.x_mm);
            used[i] = true;
            tmp[m++] = del[i];
        }
        double scale = 1.4826 * model_median(tmp, m);
        double lim = fmax(reject_sigma * scale, floor_mm);
        int worst = -1;
        for (int i = 0; i < n; i++)
            if (used[i] && del[i] > lim && (worst < 0 || del[i] > del[worst])) worst = i;
        if (worst < 0 || dropped >= max_drop || o->n_used <= 3) break;
        used[worst] = false;   // drop the worst and fit again
        dropped++;
    }
    double ss = 0;
    for (int i = 0; i < n; i++)
        if (used[i]) ss += dist[i] * dist[i];
    o->rms_mm = sqrt(ss / o->n_used);
    int dof = 2 * o->n_used - 3;
    double s2 = ss / (dof > 0 ? dof : 1);
    for (int k = 0; k < 9; k++) o->cov_mm2[k] *= s2;
    if (dist_mm) memcpy(dist_mm, dist, sizeof *dist * (size_t)n);
    ok = true;
done:
    free(dist);
    free(tmp);
    free(del);
    return ok;
}


// ---------------------------------------------------------------------------
// The joint fit of the lamps and the sphere's path (bundle adjustment)

// The sphere centre at the observation's angle for sphere parameters g, and
// d centre / d g (3x7, row-major).
static void bundle_centre(const calib_lamps_bundle_setup_t *S, double angle_deg, const double *g, double s[3],
                          double ds_dg[21])
{
    double th = angle_deg * M_PI / 180, ct = cos(th), st = sin(th);
    double a0 = S->c0_mm[0] + g[0], a1 = S->c0_mm[1] + g[1], a2 = S->c0_mm[2] + g[2];
    double s0[3] = { ct * a0 - st * a1, st * a0 + ct * a1, a2 };
    double wx = 1e-3 * g[5], wy = 1e-3 * g[6];
    // s = s0 + w x s0 + shift, w = (wx, wy, 0)
    s[0] = s0[0] + wy * s0[2] + g[3];
    s[1] = s0[1] - wx * s0[2] + g[4];
    s[2] = s0[2] + wx * s0[1] - wy * s0[0];
    if (ds_dg) {
        // d s0 / d offset = Rz; d s / d s0 = I + [w]x
        const double Rz[9] = { ct, -st, 0, st, ct, 0, 0, 0, 1 };
        const double M[9] = { 1, 0, wy, 0, 1, -wx, -wy, wx, 1 };
        for (int i = 0; i < 3; i++) {
            for (int j = 0; j < 3; j++)
                ds_dg[i * 7 + j] = M[i * 3] * Rz[j] + M[i * 3 + 1] * Rz[3 + j] + M[i * 3 + 2] * Rz[6 + j];
            ds_dg[i * 7 + 3] = i == 0;
            ds_dg[i * 7 + 4] = i == 1;
        }
        ds_dg[0 * 7 + 5] = 0;
        ds_dg[1 * 7 + 5] = -1e-3 * s0[2];
        ds_dg[2 * 7 + 5] = 1e-3 * s0[1];
        ds_dg[0 * 7 + 6] = 1e-3 * s0[2];
        ds_dg[1 * 7 + 6] = 0;
        ds_dg[2 * 7 + 6] = -1e-3 * s0[0];
    }
}

bool calib_lamps_bundle_residual(void *vctx, const double *const *P, double *res, double **jac)
{
    const calib_lamps_bundle_ctx_t *cx = vctx;
    const calib_lamps_bundle_setup_t *S = cx->setup;
    const double *X = P[0], *g = P[1], r = S->radius_mm, isg = 1 / cx->sigma_rad;
    double s[3], dsdg[21];
    bundle_centre(S, cx->obs.angle_deg, g, s, dsdg);
    const double C[3] = { S->camera_mm.x, S->camera_mm.y, S->camera_mm.z };
    const double d[3] = { cx->obs.ray.x, cx->obs.ray.y, cx->obs.ray.z };
    double oc[3], pp[3], n[3], u[3], w[3], ul[3];
    for (int i = 0; i < 3; i++) oc[i] = C[i] - s[i];
    double b = d[0] * oc[0] + d[1] * oc[1] + d[2] * oc[2];
    double cc = oc[0] * oc[0] + oc[1] * oc[1] + oc[2] * oc[2] - r * r, disc = b * b - cc;
    if (!(disc > 0)) return false;   // the ray misses the sphere at these parameters
    double sq = sqrt(disc), t = -b - sq;
    if (!(t > 0)) return false;
    for (int i = 0; i < 3; i++) {
        pp[i] = C[i] + t * d[i];
        n[i] = (pp[i] - s[i]) / r;
    }
    double dn = d[0] * n[0] + d[1] * n[1] + d[2] * n[2];
    for (int i = 0; i < 3; i++) {
        u[i] = d[i] - 2 * dn * n[i];
        w[i] = X[i] - pp[i];
    }
    double wl = sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2]);
    if (!(wl > 1e-9)) return false;
    double r3[3];
    for (int i = 0; i < 3; i++) {
        ul[i] = w[i] / wl;
        r3[i] = ul[i] - u[i];
    }
    const double *Wm = cx->W;
    for (int i = 0; i < 3; i++) res[i] = (Wm[i * 3] * r3[0] + Wm[i * 3 + 1] * r3[1] + Wm[i * 3 + 2] * r3[2]) * isg;
    if (!jac) return true;
    // d t / d s, d p / d s = d (dt/ds)^T, d n / d s = (dp/ds - I) / r,
    // d u / d s = -2 (n (d^T dn/ds) + (d.n) dn/ds)
    double dtds[3], dpds[9], dnds[9], duds[9], Pl[9];
    for (int k = 0; k < 3; k++) dtds[k] = d[k] - (oc[k] - b * d[k]) / sq;
    for (int i = 0; i < 3; i++)
        for (int k = 0; k < 3; k++) {
            dpds[i * 3 + k] = d[i] * dtds[k];
            dnds[i * 3 + k] = (dpds[i * 3 + k] - (i == k)) / r;
            Pl[i * 3 + k] = ((i == k) - ul[i] * ul[k]) / wl;
        }
    for (int k = 0; k < 3; k++) {
        double ddn = d[0] * dnds[k] + d[1] * dnds[3 + k] + d[2] * dnds[6 + k];
        for (int i = 0; i < 3; i++) duds[i * 3 + k] = -2 * (n[i] * ddn + dn * dnds[i * 3 + k]);
    }
    if (jac[0])
        for (int i = 0; i < 3; i++)
            for (int k = 0; k < 3; k++)
                jac[0][i * 3 + k] = (Wm[i * 3] * Pl[k] + Wm[i * 3 + 1] * Pl[3 + k] + Wm[i * 3 + 2] * Pl[6 + k]) * isg;
    if (jac[1]) {
        double drds[9], wd[9];
        for (int i = 0; i < 3; i++)
            for (int k = 0; k < 3; k++) {
                double a = 0;
                for (int m = 0; m < 3; m++) a += Pl[i * 3 + m] * dpds[m * 3 + k];
                drds[i * 3 + k] = -a - duds[i * 3 + k];
            }
        for (int i = 0; i < 3; i++)
            for (int k = 0; k < 3; k++)
                wd[i * 3 + k] = (Wm[i * 3] * drds[k] + Wm[i * 3 + 1] * drds[3 + k] + Wm[i * 3 + 2] * drds[6 + k]) * isg;
        for (int i = 0; i < 3; i++)
            for (int j = 0; j < 7; j++)
                jac[1][i * 7 + j] = wd[i * 3] * dsdg[j] + wd[i * 3 + 1] * dsdg[7 + j] + wd[i * 3 + 2] * dsdg[14 + j];
    }
    return true;
}

// An orthonormal pair perpendicular to the unit vector a.
static void tangent_pair(const double a[3], double e1[3], double e2[3])
{
    double h[3] = { 0, 0, 0 };
    h[fabs(a[2]) < 0.9 ? 2 : 0] = 1;
    double k = h[0] * a[0] + h[1] * a[1] + h[2] * a[2];
    for (int i = 0; i < 3; i++) e1[i] = h[i] - k * a[i];
    double n = sqrt(e1[0] * e1[0] + e1[1] * e1[1] + e1[2] * e1[2]);
    for (int i = 0; i < 3; i++) e1[i] /= n;
    e2[0] = a[1] * e1[2] - a[2] * e1[1];
    e2[1] = a[2] * e1[0] - a[0] * e1[2];
    e2[2] = a[0] * e1[1] - a[1] * e1[0];
}

bool calib_lamps_bundle_weight(calib_lamps_bundle_ctx_t *cx, const double X[3], const double g[7])
{
    (void)X;
    const calib_lamps_bundle_setup_t *S = cx->setup;
    const double r = S->radius_mm;
    double s[3];
    bundle_centre(S, cx->obs.angle_deg, g, s, NULL);
    const double C[3] = { S->camera_mm.x, S->camera_mm.y, S->camera_mm.z };
    const double d[3] = { cx->obs.ray.x, cx->obs.ray.y, cx->obs.ray.z };
    double oc[3], n[3], u[3];
    for (int i = 0; i < 3; i++) oc[i] = C[i] - s[i];
    double b = d[0] * oc[0] + d[1] * oc[1] + d[2] * oc[2];
    double disc = b * b - (oc[0] * oc[0] + oc[1] * oc[1] + oc[2] * oc[2] - r * r);
    if (!(disc > 0)) return false;
    double sq = sqrt(disc), t = -b - sq;
    if (!(t > 0)) return false;
    for (int i = 0; i < 3; i++) n[i] = (C[i] + t * d[i] - s[i]) / r;
    double dn = d[0] * n[0] + d[1] * n[1] + d[2] * n[2];
    for (int i = 0; i < 3; i++) u[i] = d[i] - 2 * dn * n[i];
    // d t / d d = -oc (1 + b / sq); d p / d d = t I + d (dt/dd)^T; d n / d d = (dp/dd) / r;
    // d u / d d = I - 2 (n (n^T + d^T dn/dd) + (d.n) dn/dd)
    double dtdd[3], dndd[9], A[9];
    for (int k = 0; k < 3; k++) dtdd[k] = -oc[k] * (1 + b / sq);
    for (int i = 0; i < 3; i++)
        for (int k = 0; k < 3; k++) dndd[i * 3 + k] = (t * (i == k) + d[i] * dtdd[k]) / r;
    for (int k = 0; k < 3; k++) {
        double ddn = n[k] + d[0] * dndd[k] + d[1] * dndd[3 + k] + d[2] * dndd[6 + k];
        for (int i = 0; i < 3; i++) A[i * 3 + k] = (i == k) - 2 * (n[i] * ddn + dn * dndd[i * 3 + k]);
    }
    // in the tangent planes: A2 = Tu^T A Td (2x2); W = A2^-1 Tu^T
    double td1[3], td2[3], tu1[3], tu2[3];
    tangent_pair(d, td1, td2);
    tangent_pair(u, tu1, tu2);
    const double *Td[2] = { td1, td2 }, *Tu[2] = { tu1, tu2 };
    double A2[4];
    for (int i = 0; i < 2; i++)
        for (int j = 0; j < 2; j++) {
            double a = 0;
            for (int p = 0; p < 3; p++)
                for (int q = 0; q < 3; q++) a += Tu[i][p] * A[p * 3 + q] * Td[j][q];
            A2[i * 2 + j] = a;
        }
    double det = A2[0] * A2[3] - A2[1] * A2[2];
    if (!(fabs(det) > 1e-12)) return false;
    double Ai[4] = { A2[3] / det, -A2[1] / det, -A2[2] / det, A2[0] / det };
    for (int i = 0; i < 2; i++)
        for (int k = 0; k < 3; k++) cx->W[i * 3 + k] = Ai[i * 2] * Tu[0][k] + Ai[i * 2 + 1] * Tu[1][k];
    for (int k = 0; k < 3; k++) cx->W[6 + k] = 0;
    return true;
}

// Largest / smallest eigenvalue of a symmetric positive matrix (n <= 7) by Jacobi rotations.
static double cond_sym(const double *m, int n)
{
    double a[49];
    memcpy(a, m, sizeof *a * (size_t)(n * n));
    model_sym_eigen(n, a, NULL);
    double lo = INFINITY, hi = 0;
    for (int i = 0; i < n; i++) {
        lo = fmin(lo, a[i * n + i]);
        hi = fmax(hi, a[i * n + i]);
    }
    return lo > 0 ? hi / lo : INFINITY;
}

bool calib_lamps_bundle(const calib_lamps_obs_t *obs, int nobs, int nl, const calib_lamps_bundle_setup_t *S,
                        double *x_mm, double *cov_mm2, double *obs_angle, calib_lamps_bundle_t *out)
{
    memset(out, 0, sizeof *out);
    if (nl < 1 || nl > 64) {
        model_error_set(NULL, 0, "the joint fit takes 1 to 64 lamps (%d given)", nl);
        return false;
    }
    int cnt[64] = { 0 };
    for (int i = 0; i < nobs; i++)
        if (obs[i].lamp >= 0 && obs[i].lamp < nl) cnt[obs[i].lamp]++;
    for (int l = 0; l < nl; l++)
        if (cnt[l] < 3) {
            model_error_set(NULL, 0, "lamp %d has %d rays in the joint fit: a position needs at least 3", l, cnt[l]);
            return false;
        }
    calib_lamps_bundle_ctx_t *ctx = calloc((size_t)nobs, sizeof *ctx);
    lsq_problem_t *pr = lsq_problem_new();
    double *g = out->sphere;
    bool ok = false;
    if (!ctx || !pr) {
        model_error_set(NULL, 0, "out of memory");
        goto done;
    }
    for (int l = 0; l < nl; l++)
        if (!lsq_add_parameters(pr, x_mm + 3 * l, 3)) goto fail;
    if (!lsq_add_parameters(pr, g, 7)) goto fail;
    bool fixed[7];
    double prior[7];
    for (int k = 0; k < 7; k++) {
        prior[k] = k < 3 ? S->offset_prior_mm : k < 5 ? S->shift_prior_mm : S->tilt_prior_mrad;
        fixed[k] = !(prior[k] > 0);
    }
    if (!lsq_set_fixed(pr, g, fixed)) goto fail;
    for (int k = 0; k < 7; k++)
        if (!fixed[k] && !lsq_add_prior(pr, g, k, k < 3 ? S->offset_prior_mean_mm[k] : 0, prior[k])) goto fail;
    for (int i = 0; i < nobs; i++) {
        ctx[i].setup = S;
        ctx[i].obs = obs[i];
        ctx[i].sigma_rad = 1e-3;
        for (int k = 0; k < 9; k++) ctx[i].W[k] = k % 4 == 0;
        if (S->image_weights && !calib_lamps_bundle_weight(&ctx[i], x_mm + 3 * obs[i].lamp, g)) {
            model_error_set(NULL, 0, "the joint fit: a highlight's camera ray misses the sphere");
            goto done;
        }
        double *blocks[2] = { x_mm + 3 * obs[i].lamp, g };
        if (!lsq_add_residual(pr, calib_lamps_bundle_residual, &ctx[i], 3, 2, blocks, LSQ_LOSS_NONE, 0)) goto fail;
    }
    // rounds: solve, then each lamp's angular sigma from its residuals (dof
    // 2 per ray less its 3 and its share of the sphere's), solve again
    for (int round = 0; round < 4; round++) {
        lsq_options_t fo = lsq_defaults();
        fo.threads = 1;
        lsq_summary_t sm;
        if (!lsq_solve(pr, &fo, &sm)) {
            model_error_set(NULL, 0, "the joint fit of lamps and sphere failed: %s", sm.message);
            goto done;
        }
        out->iterations += sm.iterations;
        double ss[64] = { 0 };
        for (int i = 0; i < nobs; i++) {
            double rr[3];
            const double *pb[2] = { x_mm + 3 * obs[i].lamp, g };
            if (!calib_lamps_bundle_residual(&ctx[i], pb, rr, NULL)) {
                model_error_set(NULL, 0, "the joint fit: a highlight's ray misses the fitted sphere");
                goto done;
            }
            double a2 = (rr[0] * rr[0] + rr[1] * rr[1] + rr[2] * rr[2]) * ctx[i].sigma_rad * ctx[i].sigma_rad;
            if (!S->image_weights) a2 *= 1;
            ss[obs[i].lamp] += a2;
            if (obs_angle) obs_angle[i] = sqrt(a2);
        }
        int nfree_g = 0;
        for (int k = 0; k < 7; k++) nfree_g += !fixed[k];
        double change = 0;
        for (int l = 0; l < nl; l++) {
            double dof = 2.0 * cnt[l] - 3 - (double)nfree_g * cnt[l] / nobs;
            double sg = sqrt(ss[l] / (dof > 1 ? dof : 1));
            out->rms_rad[l] = sqrt(ss[l] / cnt[l]);
            if (!(sg > 1e-7)) sg = 1e-7;
            change = fmax(change, fabs(log(sg / (out->sigma_rad[l] > 0 ? out->sigma_rad[l] : 1e-3))));
            out->sigma_rad[l] = sg;
        }
        for (int i = 0; i < nobs; i++) {
            ctx[i].sigma_rad = out->sigma_rad[obs[i].lamp];
            if (S->image_weights && !calib_lamps_bundle_weight(&ctx[i], x_mm + 3 * obs[i].lamp, g)) {
                model_error_set(NULL, 0, "the joint fit: a highlight's camera ray misses the fitted sphere");
                goto done;
            }
        }
        if (round > 0 && change < 0.01) break;
    }
    for (int l = 0; l < nl; l++)
        if (!lsq_covariance(pr, x_mm + 3 * l, cov_mm2 + 9 * l)) goto fail;
    if (!lsq_covariance(pr, g, out->sphere_cov)) goto fail;
    {
        // observability of the free sphere parameters: the condition of their covariance
        int idx[7], m = 0;
        for (int k = 0; k < 7; k++)
            if (!fixed[k]) idx[m++] = k;
        double sub[49];
        for (int i = 0; i < m; i++)
            for (int j = 0; j < m; j++) sub[i * m + j] = out->sphere_cov[idx[i] * 7 + idx[j]];
        out->cond = m ? cond_sym(sub, m) : 1;
    }
    ok = true;
    goto done;
fail:
    model_error_set(NULL, 0, "the joint fit of lamps and sphere: %s", model_last_error());
done:
    lsq_problem_free(pr);
    free(ctx);
    return ok;
}

// ---------------------------------------------------------------------------
// The calibration: calib_lamps_run and its stages

calib_lamps_opts_t calib_lamps_defaults(void)
{
    calib_lamps_opts_t o = { .sample = "mirror_sphere", .nangles = 24, .exposures_us = { 40, 20, 10 },
                             .nexposures = 3, .min_snr = 12, .method = CALIB_LAMPS_MODEL, .joint = true,
                             .offset_prior_mm = 3.0, .shift_prior_mm = 0.1, .tilt_prior_mrad = 1.0,
                             .progress = -1 };
    for (int i = 0; i < o.nangles; i++) o.angles_deg[i] = 15.0 * i;
    return o;
}

static double full_scale(const char *pf)
{
    if (!strcmp(pf, "Mono8")) return 255;
    if (!strcmp(pf, "Mono16")) return 65535;
    return 4095;
}

// The sphere's centre at turntable angle angle_deg: Rz(angle) c0.
static model_vec3_t centre_at(const double c0[3], double angle_deg)
{
    double th = angle_deg * M_PI / 180;
    return v3(cos(th) * c0[0] - sin(th) * c0[1], sin(th) * c0[0] + cos(th) * c0[1], c0[2]);
}

char *calib_lamps_plan_text(const char *sample, const double *centre_mm, double radius_mm, const double *angles_deg,
                            int nangles, char *const *lamps,
                            int nlamps, const double *exposures_us, int nexposures)
{
    GString *pt = g_string_new("# refl calib lamps: the mirror sphere at several turntable angles, each lamp "
                               "alone, a dark frame per angle\n[plan]\nname = lamp positions from mirror-sphere "
                               "highlights\n");
    g_string_append_printf(pt, "[sample]\nname = %s\nkind = mirror_sphere\n", sample);
    if (centre_mm)
        g_string_append_printf(pt, "instruction = place the chrome ball %s at the table centre: its centre at "
                               "(%.10g, %.10g, %.10g) mm in the rig frame at turntable angle 0, radius %.10g mm\n",
                               sample, centre_mm[0], centre_mm[1], centre_mm[2], radius_mm);
    g_string_append(pt, "[angles]\nlist =");
    for (int i = 0; i < nangles; i++) g_string_append_printf(pt, " %.10g", angles_deg[i]);
    g_string_append(pt, "\n[lamps]\nsets = ");
    for (int i = 0; i < nlamps; i++) g_string_append_printf(pt, "%s; ", lamps[i]);
    g_string_append(pt, "none\n[exposure]\n# auto bracketing: longest first, down to the first frame whose "
                        "brightest pixel is at or below 70 % of full scale\nmode = auto\nlist_us =");
    for (int i = 0; i < nexposures; i++) g_string_append_printf(pt, " %.10g", exposures_us[i]);
    g_string_append(pt, "\ntarget_fraction = 0.7\npixel_format = Mono12\n[capture]\nsettle_ms = 0\n");
    return g_string_free(pt, FALSE);
}

// "none" and "all" are lamp sets, not lamps.
static bool names_are_lamps(char *const *names)
{
    for (int l = 0; names[l]; l++)
        if (!strcmp(names[l], "none") || !strcmp(names[l], "all")) {
            model_error_set(NULL, 0, "--lamps: '%s' is not a lamp (each lamp is calibrated alone; the dark frames "
                            "are the lamp set none)", names[l]);
            return false;
        }
    return true;
}

// Capture on o->rig into o->out/capture; *names: the lamps (g_strfreev).
static bool capture(const calib_lamps_opts_t *o, calib_lamps_result_t *r, char ***names)
{
    int n = 0;
    if (o->lamps) {
        *names = g_strdupv((char **)o->lamps);
        n = (int)g_strv_length(*names);
    } else if (!rig_file_lamp_names(o->rig, names, &n)) {
        return false;
    }
    if (n == 0) {
        model_error_set(NULL, 0, "%s has no lamps (and no --lamps given)", o->rig);
        return false;
    }
    if (!names_are_lamps(*names)) return false;
    if (!o->sphere_given) {
        model_error_set(NULL, 0, "%s: give --sphere-centre-mm X,Y,Z and --sphere-radius-mm R (the sphere's facts) "
                        "before anything is captured", o->rig);
        return false;
    }
    char *pt = calib_lamps_plan_text(o->sample, o->sphere_centre_mm, o->sphere_radius_mm, o->angles_deg, o->nangles, *names, n, o->exposures_us,
                                     o->nexposures);
    model_note("capturing %d angles x %d lamps + dark into %s/capture", o->nangles, n, o->out);
    int crc = calib_capture(o->rig, o->out, "capture", pt, o->progress, o->op);
    g_free(pt);
    if (crc) return false;
    r->session_dir = g_strdup_printf("%s/capture", o->out);
    return true;
}

// The lamps of a session: o->lamps, else every lamp set of the plan that is
// one lamp alone. g_strfreev.
static char **session_lamps(const calib_lamps_opts_t *o, const rig_plan_t *plan)
{
    if (o->lamps) return g_strdupv((char **)o->lamps);
    GPtrArray *a = g_ptr_array_new();
    for (int i = 0; i < plan->nlamp_sets; i++)
        if (strcmp(plan->lamp_sets[i], "none") && strcmp(plan->lamp_sets[i], "all") &&
            !strchr(plan->lamp_sets[i], '+'))
            g_ptr_array_add(a, g_strdup(plan->lamp_sets[i]));
    g_ptr_array_add(a, NULL);
    return (char **)g_ptr_array_free(a, FALSE);
}

// r->lamps for names, each a lamp set of the plan.
static bool lamps_alloc(const calib_lamps_opts_t *o, calib_lamps_result_t *r, char *const *names)
{
    const int NA = r->nangles;
    r->nlamps = (int)g_strv_length((char **)names);
    r->lamps = calloc((size_t)r->nlamps, sizeof *r->lamps);
    if (!r->lamps) goto oom;
    for (int l = 0; l < r->nlamps; l++) {
        calib_lamps_lamp_t *lp = &r->lamps[l];
        snprintf(lp->name, sizeof lp->name, "%s", names[l]);
        lp->lamp_radius_mm = o->lamp_radius_mm;
        lp->frame = malloc(sizeof(int) * (size_t)NA);
        lp->hl = calloc((size_t)NA, sizeof *lp->hl);
        lp->has_ray = calloc((size_t)NA, sizeof(bool));
        lp->used = calloc((size_t)NA, sizeof(bool));
        lp->p_mm = calloc((size_t)NA, sizeof(model_vec3_t));
        lp->d = calloc((size_t)NA, sizeof(model_vec3_t));
        lp->dist_mm = calloc((size_t)NA, sizeof(double));
        if (!lp->frame || !lp->hl || !lp->has_ray || !lp->used || !lp->p_mm || !lp->d || !lp->dist_mm) goto oom;
        for (int a = 0; a < NA; a++) lp->frame[a] = -1;
        bool in_plan = false;
        for (int i = 0; i < r->plan->nlamp_sets; i++) in_plan |= !strcmp(r->plan->lamp_sets[i], lp->name);
        if (!in_plan) {
            GString *g = g_string_new("");
            for (int i = 0; i < r->plan->nlamp_sets; i++)
                g_string_append_printf(g, "%s%s", i ? "; " : "", r->plan->lamp_sets[i]);
            model_error_set(NULL, 0, "%s: the session's plan has no lamp set '%s' alone (sets: %s)", r->session_dir,
                            lp->name, g->str);
            g_string_free(g, TRUE);
            return false;
        }
    }
    return true;
oom:
    model_error_set(NULL, 0, "out of memory");
    return false;
}

// Per (angle, lamp set) the longest exposure below 95 % of full scale (auto
// bracketing leaves the longest unsaturated one last); per angle the dark
// frame and the measured angle.
static bool choose_frames(calib_lamps_result_t *r)
{
    const int NA = r->nangles;
    const rig_session_t *s = r->session;
    r->angle_deg = malloc(sizeof(double) * (size_t)NA);
    r->dark_row = malloc(sizeof(int) * (size_t)NA);
    r->centre_mm = calloc((size_t)NA, sizeof *r->centre_mm);
    if (!r->angle_deg || !r->dark_row || !r->centre_mm) {
        model_error_set(NULL, 0, "out of memory");
        return false;
    }
    for (int a = 0; a < NA; a++) {
        r->dark_row[a] = -1;
        r->angle_deg[a] = NAN;
    }
    for (int i = 0; i < s->n; i++) {
        const rig_frame_row_t *row = &s->rows[i];
        int a = -1;
        for (int k = 0; k < NA; k++)
            if (fabs(r->plan->angles_deg[k] - row->commanded_deg) < 1e-6) a = k;
        if (a < 0) continue;
        r->angle_deg[a] = row->measured_deg;
        double fs = full_scale(row->pixel_format);
        if (!strcmp(row->lamps, "none")) {
            if (r->dark_row[a] < 0) r->dark_row[a] = i;
            continue;
        }
        for (int l = 0; l < r->nlamps; l++) {
            calib_lamps_lamp_t *lp = &r->lamps[l];
            if (strcmp(row->lamps, lp->name)) continue;
            int cur = lp->frame[a];
            if (cur < 0) {
                lp->frame[a] = i;
                continue;
            }
            const rig_frame_row_t *c = &s->rows[cur];
            bool c_ok = c->max < 0.95 * fs, r_ok = row->max < 0.95 * fs;
            if ((r_ok && !c_ok) || (r_ok == c_ok && (r_ok ? row->exposure_us > c->exposure_us
                                                           : row->exposure_us < c->exposure_us)))
                lp->frame[a] = i;
        }
    }
    for (int a = 0; a < NA; a++)
        if (!isfinite(r->angle_deg[a])) r->angle_deg[a] = r->plan->angles_deg[a];
    return true;
}

bool calib_lamps_open(const calib_lamps_opts_t *o, calib_lamps_result_t *r)
{
    model_error_clear();
    r->first_angle = -1;
    if (access(o->camera, R_OK) != 0) {
        model_error_set(NULL, 0, "%s: cannot read the camera model: %s (make it with refl calib geometry)", o->camera,
                        strerror(errno));
        return false;
    }
    r->cam = model_camera_load(o->camera);
    if (!r->cam || !model_mkdir_p(o->out)) return false;
    char **names = NULL;
    bool ok = false;
    if (o->rig) {
        if (!capture(o, r, &names)) goto done;
    } else {
        r->session_dir = g_strdup(o->session);
    }
    r->session = rig_session_open_camera(r->session_dir, NULL);   // the first camera's frames
    if (!r->session) goto done;
    r->plan = rig_plan_parse(r->session->plan_text, strlen(r->session->plan_text), "session plan");
    if (!r->plan) goto done;
    r->nangles = r->plan->nangles;
    if (!o->sphere_given) {
        model_error_set(NULL, 0, "%s: give --sphere-centre-mm X,Y,Z and --sphere-radius-mm R (the sphere's facts)",
                        r->session_dir);
        goto done;
    }
    if (!names) names = session_lamps(o, r->plan);
    if (!names_are_lamps(names)) goto done;
    if (!names[0]) {
        model_error_set(NULL, 0, "%s: the plan has no lamp set of one lamp alone", r->session_dir);
        goto done;
    }
    ok = lamps_alloc(o, r, names) && choose_frames(r);
done:
    g_strfreev(names);
    return ok;
}

// A frame of the session, checked against the camera model's size. NULL + message.
static float *load_frame(const calib_lamps_opts_t *o, const calib_lamps_result_t *r, int row)
{
    int w = 0, h = 0, W = model_camera_width(r->cam), H = model_camera_height(r->cam);
    float *img = rig_session_frame(r->session, row, &w, &h);
    if (img && (w != W || h != H)) {
        model_error_set(NULL, 0, "%s/%s: %dx%d pixels, the camera model %s has %dx%d", r->session_dir,
                        r->session->rows[row].file, w, h, o->camera, W, H);
        free(img);
        img = NULL;
    }
    return img;
}

// Lamp lp's highlight at angle a in its frame and the ray toward it: the
// direction-space model (pass 1: a point lamp), else the reflection at the
// sub-pixel position. false only when the frame cannot be read.
static bool lamp_ray(const calib_lamps_opts_t *o, calib_lamps_result_t *r, calib_lamps_lamp_t *lp, int a,
                     const calib_lamps_sphere_image_t *sph, const float *dark)
{
    int fr = lp->frame[a];
    calib_lamps_highlight_t *hl = &lp->hl[a];
    float *img = load_frame(o, r, fr);
    if (!img) return false;
    double fs = full_scale(r->session->rows[fr].pixel_format);
    calib_lamps_find_highlight(img, dark, model_camera_width(r->cam), model_camera_height(r->cam), sph, o->min_snr,
                               0.02 * fs, 40, fs, hl);
    free(img);
    if (!hl->found) return true;
    bool ok = false;
    if (o->method == CALIB_LAMPS_MODEL) {
        bool q = model_error_quiet_thread(true);
        ok = calib_lamps_fit_direction(r->cam, hl, r->centre_mm[a], o->sphere_radius_mm, 0, &lp->p_mm[a], &lp->d[a],
                                       NULL);
        model_error_quiet_thread(q);
    }
    if (!ok && o->method == CALIB_LAMPS_CENTROID) {
        hl->q[0] = hl->q_centroid[0];
        hl->q[1] = hl->q_centroid[1];
    }
    if (!ok && !calib_lamps_reflect(r->cam, hl->q, r->centre_mm[a], o->sphere_radius_mm, &lp->p_mm[a], &lp->d[a])) {
        hl->found = false;
        snprintf(hl->why, sizeof hl->why, "%s", model_last_error());
    } else {
        lp->has_ray[a] = lp->used[a] = true;
    }
    return true;
}

// Every lamp's highlight at angle a.
static bool angle_highlights(const calib_lamps_opts_t *o, calib_lamps_result_t *r, int a)
{
    double ang = r->angle_deg[a];
    r->centre_mm[a] = centre_at(o->sphere_centre_mm, ang);
    model_progress("angle %d/%d (%.3f deg): finding highlights", a + 1, r->nangles, ang);
    calib_lamps_sphere_image_t *sph = calib_lamps_sphere_image(r->cam, r->centre_mm[a], o->sphere_radius_mm);
    if (!sph) {
        model_error_set(NULL, 0, "angle %.3f deg: %s", ang, model_last_error());
        return false;
    }
    float *dark = NULL;
    bool ok = false;
    if (r->dark_row[a] >= 0 && !(dark = load_frame(o, r, r->dark_row[a]))) goto done;
    for (int l = 0; l < r->nlamps; l++) {
        calib_lamps_lamp_t *lp = &r->lamps[l];
        if (lp->frame[a] < 0)
            snprintf(lp->hl[a].why, sizeof lp->hl[a].why, "no frame of this lamp at this angle in the session");
        else if (!lamp_ray(o, r, lp, a, sph, dark))
            goto done;
        if (lp->has_ray[a] && r->first_angle < 0) r->first_angle = a;
        lp->nmissing += !lp->has_ray[a];
    }
    ok = true;
done:
    free(dark);
    calib_lamps_sphere_image_free(sph);
    return ok;
}

bool calib_lamps_find_highlights(const calib_lamps_opts_t *o, calib_lamps_result_t *r)
{
    bool ok = true;
    for (int a = 0; ok && a < r->nangles; a++) ok = angle_highlights(o, r, a);
    model_progress_end();
    return ok;
}

// The frame of lamp lp at angle a: its file ("(none)") and step (-1).
static const char *frame_file(const calib_lamps_result_t *r, const calib_lamps_lamp_t *lp, int a, int *step)
{
    int fr = lp->frame[a];
    *step = fr >= 0 ? r->session->rows[fr].step : -1;
    return fr >= 0 ? r->session->rows[fr].file : "(none)";
}

// The frames without a ray, one line each: "    FILE (step N, A deg): why\n". g_free.
static char *missing_text(const calib_lamps_result_t *r, const calib_lamps_lamp_t *lp)
{
    GString *g = g_string_new("");
    for (int a = 0; a < r->nangles; a++) {
        if (lp->has_ray[a]) continue;
        int step;
        const char *file = frame_file(r, lp, a, &step);
        g_string_append_printf(g, "    %s (step %d, %.3f deg): %s\n", file, step, r->angle_deg[a], lp->hl[a].why);
    }
    return g_string_free(g, FALSE);
}

// Each ray again with the lamp's disk (its angular radius seen from the
// sphere point, at the lamp's fitted distance), at the sphere centres
// r->centre_mm; pass 0 of the joint fit and pass 2 of the per-lamp fit.
static void refit_highlights(const calib_lamps_opts_t *o, calib_lamps_result_t *r, calib_lamps_lamp_t *lp,
                             const double x_mm[3])
{
    for (int a = 0; a < r->nangles; a++) {
        if (!lp->has_ray[a]) continue;
        model_vec3_t e = v3_sub(v3(x_mm[0], x_mm[1], x_mm[2]), lp->p_mm[a]);
        double dist = sqrt(v3_dot(e, e));
        double rho = lp->lamp_radius_mm > 0 && dist > lp->lamp_radius_mm ? asin(lp->lamp_radius_mm / dist) : 0;
        bool q = model_error_quiet_thread(true);
        calib_lamps_fit_direction(r->cam, &lp->hl[a], r->centre_mm[a], o->sphere_radius_mm, rho, &lp->p_mm[a],
                                  &lp->d[a], NULL);
        model_error_quiet_thread(q);
    }
}

// One lamp: the point nearest its rays, with the lamp's disk once more.
static bool triangulate_lamp(const calib_lamps_opts_t *o, calib_lamps_result_t *r, calib_lamps_lamp_t *lp)
{
    const int NA = r->nangles, nm = lp->nmissing, nr = NA - nm;
    if (nm) {
        char *t = missing_text(r, lp);
        model_note("lamp %s: no highlight in %d of %d frames:\n%s", lp->name, nm, NA, t);
        g_free(t);
    }
    if (nr < 3) {
        const double *c0 = o->sphere_centre_mm;
        model_error_set(NULL, 0, "lamp %s: its highlight is in only %d frame%s of %s; at least 3 are needed: check "
                        "the lamp switches on, is not hidden from the sphere, and the sphere facts (--sphere-centre-mm "
                        "%g,%g,%g --sphere-radius-mm %g)", lp->name, nr, nr == 1 ? "" : "s", r->session_dir, c0[0],
                        c0[1], c0[2], o->sphere_radius_mm);
        return false;
    }
    if (nm) model_note("lamp %s: fitted from the other %d frames", lp->name, nr);
    for (int pass = 0; pass < 2; pass++) {
        if (pass == 1) {
            // the lamp's finite size (its disk of angular radius asin(r / distance) as seen from
            // the sphere) in the highlight model, then the fit again
            if (!(o->method == CALIB_LAMPS_MODEL && lp->lamp_radius_mm > 0)) break;
            refit_highlights(o, r, lp, lp->fit.x_mm);
            for (int a = 0; a < NA; a++) lp->used[a] = lp->has_ray[a];
        }
        if (!calib_lamps_triangulate(lp->p_mm, lp->d, NA, 4.0, 0.5, lp->used, lp->dist_mm, &lp->fit)) {
            model_error_set(NULL, 0, "lamp %s (%s): %s", lp->name, r->session_dir, model_last_error());
            return false;
        }
    }
    for (int a = 0; a < NA; a++)
        if (lp->has_ray[a] && !lp->used[a])
            model_note("lamp %s: the ray of %s (%.3f deg) is an outlier (%.1f mm from the fit, RMS %.2f mm) and was "
                       "left out", lp->name, r->session->rows[lp->frame[a]].file, r->plan->angles_deg[a],
                       lp->dist_mm[a], lp->fit.rms_mm);
    return true;
}

bool calib_lamps_triangulate_lamps(const calib_lamps_opts_t *o, calib_lamps_result_t *r)
{
    GString *err = g_string_new("");
    int nfail = 0;
    for (int l = 0; l < r->nlamps; l++) {
        if (triangulate_lamp(o, r, &r->lamps[l])) continue;
        g_string_append_printf(err, "\n  %s", model_last_error());
        nfail++;
    }
    if (nfail == 1) model_error_set(NULL, 0, "%s", err->str + 3);
    else if (nfail) model_error_set(NULL, 0, "%d lamps cannot be fitted:%s", nfail, err->str);
    g_string_free(err, TRUE);
    return nfail == 0;
}

// The observations of the joint fit: every used ray as the camera ray of its
// sphere point. ob: room for every ray. Returns their number.
static int joint_obs(const calib_lamps_result_t *r, model_vec3_t Cc, calib_lamps_obs_t *ob)
{
    int k = 0;
    for (int l = 0; l < r->nlamps; l++)
        for (int a = 0; a < r->nangles; a++) {
            const calib_lamps_lamp_t *lp = &r->lamps[l];
            if (!lp->has_ray[a] || !lp->used[a]) continue;
            model_vec3_t ray = v3_sub(lp->p_mm[a], Cc);
            ob[k].lamp = l;
            ob[k].angle_deg = r->angle_deg[a];
            ob[k].ray = v3_scale(ray, 1 / sqrt(v3_dot(ray, ray)));
            k++;
        }
    return k;
}

// Every ray at the fitted sphere path: pass 0 fits the highlights again there
// (the lobe's geometry), pass 1 only reflects the highlight's camera ray.
static void rays_at_path(const calib_lamps_opts_t *o, calib_lamps_result_t *r, const calib_lamps_bundle_setup_t *bs,
                         const double *x_mm, int pass)
{
    const double R = o->sphere_radius_mm;
    for (int a = 0; a < r->nangles; a++) {
        double sc[3];
        bundle_centre(bs, r->angle_deg[a], r->joint.sphere, sc, NULL);
        model_vec3_t c = v3(sc[0], sc[1], sc[2]);
        for (int l = 0; l < r->nlamps; l++) {
            calib_lamps_lamp_t *lp = &r->lamps[l];
            if (!lp->has_ray[a]) continue;
            r->centre_mm[a] = c;
            if (pass == 0 && o->method == CALIB_LAMPS_MODEL) continue;   // refit_highlights below
            model_vec3_t dd = v3_sub(lp->p_mm[a], bs->camera_mm);
            dd = v3_scale(dd, 1 / sqrt(v3_dot(dd, dd)));
            double t = ray_sphere(bs->camera_mm, dd, c, R);
            if (!isfinite(t)) continue;
            lp->p_mm[a] = v3_add(bs->camera_mm, v3_scale(dd, t));
            model_vec3_t nn = v3_scale(v3_sub(lp->p_mm[a], c), 1 / R);
            lp->d[a] = v3_sub(dd, v3_scale(nn, 2 * v3_dot(dd, nn)));
        }
    }
    if (pass == 0 && o->method == CALIB_LAMPS_MODEL)
        for (int l = 0; l < r->nlamps; l++) refit_highlights(o, r, &r->lamps[l], x_mm + 3 * l);
}

bool calib_lamps_joint_fit(const calib_lamps_opts_t *o, calib_lamps_result_t *r)
{
    const int nl = r->nlamps, NA = r->nangles;
    const double *c0 = o->sphere_centre_mm;
    calib_lamps_bundle_setup_t bs = { .camera_mm = model_camera_centre_world(r->cam), .c0_mm = { c0[0], c0[1], c0[2] },
                                      .radius_mm = o->sphere_radius_mm, .offset_prior_mm = o->offset_prior_mm,
                                      .shift_prior_mm = o->shift_prior_mm, .tilt_prior_mrad = o->tilt_prior_mrad,
                                      .image_weights = true };
    for (int k = 0; k < 3 && r->have_typed; k++) bs.offset_prior_mean_mm[k] = r->typed_mm[k] - c0[k];
    calib_lamps_obs_t *ob = calloc((size_t)nl * NA + 1, sizeof *ob);
    double *x = calloc((size_t)nl * 3, sizeof *x), *cv = calloc((size_t)nl * 9, sizeof *cv);
    bool ok = ob && x && cv;
    if (!ok) model_error_set(NULL, 0, "out of memory");
    // the sphere's offset free within its prior; when that fit runs away (a lamp driven off to where its
    // rays turn parallel, or no covariance), once more with the offset held to 1 mm around the typed centre
    for (int attempt = 0; ok && attempt < 2; attempt++) {
        if (attempt) {
            if (!(bs.offset_prior_mm > 1)) break;
            model_note("the joint fit with the sphere's offset free within %g mm failed (%s); fitting again with it "
                       "within 1 mm of the typed centre", bs.offset_prior_mm, model_last_error());
            bs.offset_prior_mm = 1;
        }
        for (int l = 0; l < nl; l++) memcpy(x + 3 * l, r->lamps[l].fit.x_mm, sizeof r->lamps[l].fit.x_mm);
        bool fit = true;
        for (int pass = 0; fit && pass < 2; pass++) {
            r->joint_nobs = joint_obs(r, bs.camera_mm, ob);
            fit = calib_lamps_bundle(ob, r->joint_nobs, nl, &bs, x, cv, NULL, &r->joint);
            for (int l = 0; fit && l < nl; l++)
                if (!(fabs(x[3 * l]) < 1e5 && fabs(x[3 * l + 1]) < 1e5 && fabs(x[3 * l + 2]) < 1e5)) {
                    model_error_set(NULL, 0, "lamp %s ran off to (%.3g, %.3g, %.3g) mm", r->lamps[l].name, x[3 * l],
                                    x[3 * l + 1], x[3 * l + 2]);
                    fit = false;
                }
            if (fit) rays_at_path(o, r, &bs, x, pass);
        }
        if (fit) break;
        if (attempt == 1 || !(bs.offset_prior_mm > 1)) ok = false;
    }
    for (int l = 0; ok && l < nl; l++) {
        calib_lamps_lamp_t *lp = &r->lamps[l];
        calib_lamps_fit_t *f = &lp->fit;
        memcpy(f->x_mm, x + 3 * l, sizeof f->x_mm);
        memcpy(f->cov_mm2, cv + 9 * l, sizeof f->cov_mm2);
        double ss = 0;
        for (int a = 0; a < NA; a++) {
            if (!lp->has_ray[a]) continue;
            lp->dist_mm[a] = ray_dist(lp->p_mm[a], lp->d[a], f->x_mm);
            if (lp->used[a]) ss += lp->dist_mm[a] * lp->dist_mm[a];
        }
        f->rms_mm = sqrt(ss / f->n_used);
    }
    if (ok) {
        r->have_joint = true;
        const double *gg = r->joint.sphere, *gc = r->joint.sphere_cov;
        model_note("joint fit of %d lamps and the sphere's path over %d highlights: sphere offset %.3f %.3f %.3f mm "
                   "(std %.3f %.3f %.3f), shift %.3f %.3f mm (std %.3f %.3f), tilt %.3f %.3f mrad (std %.3f %.3f); "
                   "condition %.3g", nl, r->joint_nobs, gg[0], gg[1], gg[2], sqrt(gc[0]), sqrt(gc[8]), sqrt(gc[16]),
                   gg[3], gg[4], sqrt(gc[24]), sqrt(gc[32]), gg[5], gg[6], sqrt(gc[40]), sqrt(gc[48]), r->joint.cond);
    }
    free(ob);
    free(x);
    free(cv);
    return ok;
}

// The provenance of the outputs (once): the command line, the camera model,
// the session and the rig file.
static bool provenance(const calib_lamps_opts_t *o, calib_lamps_result_t *r)
{
    if (r->provenance) return true;
    r->provenance = model_provenance(o->argc, o->argv);
    if (!model_provenance_input(r->provenance, "camera", o->camera) ||
        !model_provenance_input(r->provenance, "session", r->session_dir))
        return false;
    if (o->rig) model_provenance_input(r->provenance, "rig", o->rig);
    return true;
}

static json_t *vec_json(const double *v, int n)
{
    json_t *a = json_array();
    for (int k = 0; k < n; k++) json_array_append_new(a, model_json_number(v[k]));
    return a;
}

// lamps.json's entry of lamp lp.
static json_t *lamp_json(const calib_lamps_result_t *r, const calib_lamps_lamp_t *lp)
{
    json_t *j = json_object(), *miss = json_array();
    const double *x = lp->fit.x_mm, *cv = lp->fit.cov_mm2;
    json_object_set_new(j, "name", json_string(lp->name));
    json_object_set_new(j, "position_mm", json_pack("[fff]", x[0], x[1], x[2]));
    json_object_set_new(j, "std_mm", json_pack("[fff]", sqrt(cv[0]), sqrt(cv[4]), sqrt(cv[8])));
    json_object_set_new(j, "covariance_mm2", vec_json(cv, 9));
    json_object_set_new(j, "rms_ray_distance_mm", model_json_number(lp->fit.rms_mm));
    json_object_set_new(j, "radius_mm", model_json_number(lp->lamp_radius_mm));
    json_object_set_new(j, "n_frames", json_integer(lp->fit.n_used));
    int nout = 0;
    for (int a = 0; a < r->nangles; a++) {
        nout += lp->has_ray[a] && !lp->used[a];
        if (lp->has_ray[a]) continue;
        int step;
        const char *file = frame_file(r, lp, a, &step);
        json_array_append_new(miss, json_pack("{s:s,s:i,s:f,s:s}", "file", file, "step", step, "angle_deg",
                                              r->angle_deg[a], "why", lp->hl[a].why));
    }
    json_object_set_new(j, "n_outliers", json_integer(nout));
    json_object_set_new(j, "frames_missing", miss);
    return j;
}

// lamps.json's sphere.joint_fit.
static json_t *joint_json(const calib_lamps_opts_t *o, const calib_lamps_result_t *r)
{
    const calib_lamps_bundle_t *jf = &r->joint;
    const double *gc = jf->sphere_cov;
    json_t *jj = json_object(), *js = json_array();
    for (int l = 0; l < r->nlamps; l++) json_array_append_new(js, model_json_number(jf->sigma_rad[l] * 1e3));
    json_object_set_new(jj, "offset_mm", json_pack("[fff]", jf->sphere[0], jf->sphere[1], jf->sphere[2]));
    json_object_set_new(jj, "shift_mm", json_pack("[ff]", jf->sphere[3], jf->sphere[4]));
    json_object_set_new(jj, "tilt_mrad", json_pack("[ff]", jf->sphere[5], jf->sphere[6]));
    json_object_set_new(jj, "std", json_pack("[fffffff]", sqrt(gc[0]), sqrt(gc[8]), sqrt(gc[16]), sqrt(gc[24]),
                                             sqrt(gc[32]), sqrt(gc[40]), sqrt(gc[48])));
    json_object_set_new(jj, "covariance_mm2", vec_json(gc, 49));
    json_object_set_new(jj, "prior_std", json_pack("{s:f,s:f,s:f}", "offset_mm", o->offset_prior_mm, "shift_mm",
                                                   o->shift_prior_mm, "tilt_mrad", o->tilt_prior_mrad));
    json_object_set_new(jj, "ray_sigma_mrad", js);
    json_object_set_new(jj, "condition", model_json_number(jf->cond));
    json_object_set_new(jj, "model", json_string(
        "sphere centre at angle a = s0 + tilt x s0 + (shift_mm, 0), s0 = Rz(a) (centre_at_angle0_mm + "
        "offset_mm), tilt = (tilt_mrad, 0) 1e-3, fitted jointly with the lamps over every highlight (each a "
        "camera ray reflected off that sphere; residual the angle to the lamp over its lamp's ray sigma); "
        "std and covariance in the order offset x y z, shift x y (mm), tilt x y (mrad); Gaussian priors "
        "of prior_std"));
    return jj;
}

bool calib_lamps_write_json(const calib_lamps_opts_t *o, calib_lamps_result_t *r)
{
    if (!provenance(o, r)) return false;
    const double *c0 = o->sphere_centre_mm;
    json_t *doc = json_object(), *ja = json_array(), *sj = json_object();
    json_object_set_new(doc, "units", json_string("lengths in mm; angles in degrees; pixels with (0,0) at the "
                                                  "centre of the top-left pixel"));
    json_object_set_new(doc, "conventions", json_string(
        "rig frame: origin at the turntable top centre, z up along the rotation axis; position_mm is the lamp's "
        "centre (the point nearest the rays reflected off the sphere at each highlight; with sphere.joint_fit, "
        "fitted jointly with the sphere's path over every lamp's highlights); std_mm the 1-sigma uncertainty per "
        "axis from the residuals (with sphere.joint_fit including the uncertainty of the sphere's path and its "
        "priors; covariance_mm2 the full 3x3); rms_ray_distance_mm the RMS distance of the used rays from the "
        "position; frames_missing lists frames whose highlight was not found"));
    for (int l = 0; l < r->nlamps; l++) json_array_append_new(ja, lamp_json(r, &r->lamps[l]));
    json_object_set_new(doc, "lamps", ja);
    json_object_set_new(doc, "camera", json_pack("{s:s,s:s}", "path", o->camera, "sha256",
                                                 model_camera_sha256(r->cam)));
    json_object_set_new(sj, "sample", json_string(r->plan->sample));
    json_object_set_new(sj, "centre_at_angle0_mm", json_pack("[fff]", c0[0], c0[1], c0[2]));
    json_object_set_new(sj, "radius_mm", model_json_number(o->sphere_radius_mm));
    json_object_set_new(sj, "motion", json_string("centre at turntable angle a: Rz(a) centre_at_angle0_mm (the "
                                                  "journal's measured angle)"));
    if (r->have_joint) {
        const double *f = r->found_mm, *t = r->typed_mm, *fc = r->found_cov_mm2;
        json_object_set_new(sj, "source", json_string(
            "the highlights across turntable angles: the joint fit's offset, the typed centre its prior (mean, "
            "std joint_fit.prior_std.offset_mm); highlights found again at the moved centre while it moved > 0.2 mm"));
        json_object_set_new(sj, "centre_typed_mm", json_pack("[fff]", t[0], t[1], t[2]));
        json_object_set_new(sj, "centre_found_mm", json_pack("[fff]", f[0], f[1], f[2]));
        json_object_set_new(sj, "centre_found_std_mm", json_pack("[fff]", sqrt(fc[0]), sqrt(fc[4]), sqrt(fc[8])));
        json_object_set_new(sj, "centre_typed_off_mm", model_json_number(sqrt(pow(f[0] - t[0], 2) + pow(f[1] - t[1], 2) +
                                                                      pow(f[2] - t[2], 2))));
        json_object_set_new(sj, "rounds", json_integer(r->rounds));
        json_object_set_new(sj, "joint_fit", joint_json(o, r));
    } else {
        json_object_set_new(sj, "source", json_string("command line"));
    }
    json_object_set_new(doc, "sphere", sj);
    json_object_set_new(doc, "session", json_string(r->session_dir));
    json_object_set_new(doc, "provenance", json_incref(r->provenance));
    char *path = g_strdup_printf("%s/lamps.json", o->out);
    bool ok = model_write_json(path, doc);
    if (ok) model_note("wrote %s", path);
    g_free(path);
    json_decref(doc);
    return ok;
}

// report_data.json's detections: at the first angle with a ray, the per-pixel
// maximum over the lamp frames (dark subtracted) around the sphere's image and
// the highlights found. NULL when there is nothing to show.
static json_t *detections_json(const calib_lamps_opts_t *o, const calib_lamps_result_t *r)
{
    const int a = r->first_angle, W = model_camera_width(r->cam);
    if (a < 0) return NULL;
    const double ang = r->angle_deg[a];
    calib_lamps_sphere_image_t *sph = calib_lamps_sphere_image(r->cam, centre_at(o->sphere_centre_mm, ang),
                                                               o->sphere_radius_mm);
    if (!sph) return NULL;
    float *acc = calloc((size_t)sph->w * sph->h, sizeof *acc);
    float *dark = r->dark_row[a] >= 0 ? load_frame(o, r, r->dark_row[a]) : NULL;
    json_t *det = json_array(), *crop = json_array();
    for (int l = 0; acc && l < r->nlamps; l++) {
        const calib_lamps_lamp_t *lp = &r->lamps[l];
        int fr = lp->frame[a], w = 0, h = 0;
        if (fr < 0) continue;
        float *img = rig_session_frame(r->session, fr, &w, &h);
        if (!img) continue;
        for (int y = 0; y < sph->h; y++)
            for (int x = 0; x < sph->w; x++) {
                size_t k = (size_t)(sph->y0 + y) * W + sph->x0 + x;
                float v = img[k] - (dark ? dark[k] : 0);
                if (v > acc[y * sph->w + x]) acc[y * sph->w + x] = v;
            }
        free(img);
        const calib_lamps_highlight_t *hl = &lp->hl[a];
        json_array_append_new(det, json_pack("{s:s,s:s,s:b,s:[ff],s:f}", "lamp", lp->name, "file",
                                             r->session->rows[fr].file, "found", hl->found, "q", hl->q[0], hl->q[1],
                                             "peak_dn", hl->peak_dn));
    }
    for (int i = 0; acc && i < sph->w * sph->h; i++) json_array_append_new(crop, model_json_number(acc[i]));
    json_t *out = json_pack("{s:f,s:i,s:i,s:i,s:i,s:o,s:o,s:[ff],s:f}", "angle_deg", ang, "x0", sph->x0, "y0",
                            sph->y0, "w", sph->w, "h", sph->h, "crop", crop, "highlights", det, "sphere_q",
                            sph->q_centre[0], sph->q_centre[1], "sphere_radius_px", sph->radius_px);
    free(acc);
    free(dark);
    calib_lamps_sphere_image_free(sph);
    return out;
}

// report_data.json for the plotting script: rays, fits, one angle's detections.
static json_t *report_json(const calib_lamps_opts_t *o, const calib_lamps_result_t *r)
{
    json_t *rep = json_object(), *rl = json_array();
    for (int l = 0; l < r->nlamps; l++) {
        const calib_lamps_lamp_t *lp = &r->lamps[l];
        const double *x = lp->fit.x_mm, *cv = lp->fit.cov_mm2;
        json_t *j = json_object(), *rays = json_array();
        json_object_set_new(j, "name", json_string(lp->name));
        json_object_set_new(j, "position_mm", json_pack("[fff]", x[0], x[1], x[2]));
        json_object_set_new(j, "std_mm", json_pack("[fff]", sqrt(cv[0]), sqrt(cv[4]), sqrt(cv[8])));
        for (int a = 0; a < r->nangles; a++) {
            if (!lp->has_ray[a]) continue;
            const calib_lamps_highlight_t *hl = &lp->hl[a];
            const model_vec3_t p = lp->p_mm[a], d = lp->d[a];
            json_array_append_new(rays, json_pack("{s:[fff],s:[fff],s:b,s:f,s:f,s:s,s:[ff],s:[ff],s:f,s:b}", "p",
                                                  p.x, p.y, p.z, "d", d.x, d.y, d.z, "used", lp->used[a], "dist_mm",
                                                  lp->dist_mm[a], "angle_deg", r->angle_deg[a], "file",
                                                  r->session->rows[lp->frame[a]].file, "q", hl->q[0], hl->q[1],
                                                  "q_centroid", hl->q_centroid[0], hl->q_centroid[1], "peak_dn",
                                                  hl->peak_dn, "fit_used", hl->fit_used));
        }
        json_object_set_new(j, "rays", rays);
        json_array_append_new(rl, j);
    }
    json_object_set_new(rep, "lamps", rl);
    json_t *det = detections_json(o, r);
    if (det) json_object_set_new(rep, "detections", det);
    model_vec3_t Cw = model_camera_centre_world(r->cam);
    const double *c0 = o->sphere_centre_mm;
    json_object_set_new(rep, "camera_centre_mm", json_pack("[fff]", Cw.x, Cw.y, Cw.z));
    json_object_set_new(rep, "sphere_centre_angle0_mm", json_pack("[fff]", c0[0], c0[1], c0[2]));
    json_object_set_new(rep, "sphere_radius_mm", model_json_number(o->sphere_radius_mm));
    if (r->have_joint) {
        const double *g = r->joint.sphere, *gc = r->joint.sphere_cov;
        json_object_set_new(rep, "sphere_joint_fit", json_pack("{s:[fff],s:[ff],s:[ff],s:[fffffff]}", "offset_mm",
                                                               g[0], g[1], g[2], "shift_mm", g[3], g[4], "tilt_mrad",
                                                               g[5], g[6], "std", sqrt(gc[0]), sqrt(gc[8]),
                                                               sqrt(gc[16]), sqrt(gc[24]), sqrt(gc[32]),
                                                               sqrt(gc[40]), sqrt(gc[48])));
    }
    return rep;
}

// report.html's table: one row per lamp.
static void report_table(FILE *f, const calib_lamps_result_t *r)
{
    const char **rows = calloc((size_t)r->nlamps, sizeof *rows);
    for (int l = 0; rows && l < r->nlamps; l++) {
        const calib_lamps_lamp_t *lp = &r->lamps[l];
        const double *x = lp->fit.x_mm, *cv = lp->fit.cov_mm2;
        rows[l] = g_strdup_printf("%s|%.2f|%.2f|%.2f|%.2f / %.2f / %.2f|%.2f|%d of %d|%d", lp->name, x[0], x[1],
                                  x[2], sqrt(cv[0]), sqrt(cv[4]), sqrt(cv[8]), lp->fit.rms_mm, lp->fit.n_used,
                                  r->nangles, lp->nmissing);
    }
    if (rows)
        model_html_table(f, "lamp|x mm|y mm|z mm|std x / y / z mm|RMS ray distance mm|rays used|frames missing",
                         rows, r->nlamps);
    for (int l = 0; rows && l < r->nlamps; l++) g_free((char *)rows[l]);
    free(rows);
}

static bool report_html(const calib_lamps_opts_t *o, const calib_lamps_result_t *r, const char *path)
{
    const double *c0 = o->sphere_centre_mm, *g = r->joint.sphere, *gc = r->joint.sphere_cov;
    FILE *f = model_html_begin(path, "refl calib lamps: lamp positions", r->provenance);
    if (!f) return false;
    model_html_heading(f, "Lamp positions");
    model_html_para(f, "Mirror sphere '%s': radius %g mm, centre (%g, %g, %g) mm at turntable angle 0 (rig frame); "
                    "%d angles. Each highlight's camera ray is reflected off the sphere into a ray toward the lamp; "
                    "the lamp is the least-squares point nearest its rays (outliers beyond 4 robust sigma dropped); "
                    "std from the ray residuals.", r->plan->sample, o->sphere_radius_mm, c0[0], c0[1], c0[2],
                    r->nangles);
    if (r->have_joint)
        model_html_para(f, "Joint fit of the lamps and the sphere's path over every highlight (the camera model's "
                        "extrinsics error moves the sphere relative to the camera; a tenth of a millimetre there is "
                        "millimetres at the lamps): centre at angle a = s0 + tilt x s0 + shift, s0 = Rz(a) (centre + "
                        "offset). Offset %.3f %.3f %.3f mm (std %.3f %.3f %.3f), shift %.3f %.3f mm (std %.3f %.3f), "
                        "tilt %.3f %.3f mrad (std %.3f %.3f); priors (std) offset %g mm, shift %g mm, tilt %g mrad. "
                        "Residuals are angles of the highlights' camera rays; the std of each lamp includes the "
                        "path's uncertainty.", g[0], g[1], g[2], sqrt(gc[0]), sqrt(gc[8]), sqrt(gc[16]), g[3], g[4],
                        sqrt(gc[24]), sqrt(gc[32]), g[5], g[6], sqrt(gc[40]), sqrt(gc[48]), o->offset_prior_mm,
                        o->shift_prior_mm, o->tilt_prior_mrad);
    if (r->have_joint && r->have_typed) {
        const double *fm = r->found_mm, *t = r->typed_mm, *fc = r->found_cov_mm2;
        model_html_para(f, "The sphere's centre from its highlights across the angles: (%.3f, %.3f, %.3f) mm (std "
                        "%.3f %.3f %.3f), typed (%g, %g, %g) mm, %.2f mm apart; %d round%s of highlights (found again "
                        "at the moved centre while it moved by more than 0.2 mm).", fm[0], fm[1], fm[2], sqrt(fc[0]),
                        sqrt(fc[4]), sqrt(fc[8]), t[0], t[1], t[2],
                        sqrt(pow(fm[0] - t[0], 2) + pow(fm[1] - t[1], 2) + pow(fm[2] - t[2], 2)), r->rounds,
                        r->rounds == 1 ? "" : "s");
    }
    report_table(f, r);
    for (int l = 0; l < r->nlamps; l++) {
        if (!r->lamps[l].nmissing) continue;
        char *t = missing_text(r, &r->lamps[l]);
        model_html_para(f, "Lamp %s: no highlight in:\n%s", r->lamps[l].name, t);
        g_free(t);
    }
    model_html_figure(f, "lamps_triangulation.png", "Triangulation: the rays reflected off the sphere (one per "
                      "turntable angle; grey: left out as outliers) and the fitted lamp positions (x), top (x-y) "
                      "and side (x-z, y-z) views, mm, rig frame; ray residuals");
    model_html_figure(f, "lamps_detections.png", "Highlight detections at the first angle: the per-pixel maximum "
                      "of every lamp's frame minus dark around the sphere's predicted image (circle), the found "
                      "highlights marked");
    return model_html_end(f, path);
}

bool calib_lamps_write_report(const calib_lamps_opts_t *o, calib_lamps_result_t *r)
{
    if (!provenance(o, r)) return false;
    json_t *rep = report_json(o, r);
    char *path = g_strdup_printf("%s/report_data.json", o->out);
    char *png1 = g_strdup_printf("%s/lamps_triangulation.png", o->out);
    char *png2 = g_strdup_printf("%s/lamps_detections.png", o->out);
    char *html = g_strdup_printf("%s/report.html", o->out);
    bool ok = model_write_json(path, rep);
    if (ok) {
        model_note("plotting");
        ok = model_run_script("calib_lamps_report.py", path, png1, png2, NULL) == 0;
    }
    if (ok) ok = report_html(o, r, html);
    if (ok) model_note("wrote %s", html);
    json_decref(rep);
    g_free(path);
    g_free(png1);
    g_free(png2);
    g_free(html);
    return ok;
}

// Every lamp's highlights, rays and fit forgotten (another round).
static void reset_rays(calib_lamps_result_t *r)
{
    const size_t NA = (size_t)r->nangles;
    for (int l = 0; l < r->nlamps; l++) {
        calib_lamps_lamp_t *lp = &r->lamps[l];
        memset(lp->hl, 0, NA * sizeof *lp->hl);
        memset(lp->has_ray, 0, NA * sizeof *lp->has_ray);
        memset(lp->used, 0, NA * sizeof *lp->used);
        memset(lp->p_mm, 0, NA * sizeof *lp->p_mm);
        memset(lp->d, 0, NA * sizeof *lp->d);
        memset(lp->dist_mm, 0, NA * sizeof *lp->dist_mm);
        memset(&lp->fit, 0, sizeof lp->fit);
        lp->nmissing = 0;
    }
    r->first_angle = -1;
    r->have_joint = false;
}

// The rounds: highlights, rays and fits at the centre oc->sphere_centre_mm
// (first the typed one); while the joint fit moves it by more than 0.2 mm
// (at most 3 rounds), again at the moved one.
static bool rounds(calib_lamps_opts_t *oc, calib_lamps_result_t *r)
{
    for (r->rounds = 1;; r->rounds++) {
        if (r->rounds > 1) reset_rays(r);
        memcpy(r->base_mm, oc->sphere_centre_mm, sizeof r->base_mm);
        if (!calib_lamps_find_highlights(oc, r) || !calib_lamps_triangulate_lamps(oc, r)) return false;
        if (!oc->joint) break;
        if (!calib_lamps_joint_fit(oc, r)) return false;
        const double *g = r->joint.sphere;
        for (int k = 0; k < 3; k++) {
            r->found_mm[k] = r->base_mm[k] + g[k];
            for (int j = 0; j < 3; j++) r->found_cov_mm2[3 * k + j] = r->joint.sphere_cov[7 * k + j];
        }
        double moved = sqrt(g[0] * g[0] + g[1] * g[1] + g[2] * g[2]);
        if (!(oc->offset_prior_mm > 0) || moved <= 0.2 || r->rounds == 3) break;
        model_note("the sphere's centre from its highlights: %.2f, %.2f, %.2f mm (%.2f mm from where they were "
                   "found, %.2f mm from the typed); finding them again there", r->found_mm[0], r->found_mm[1],
                   r->found_mm[2], moved, sqrt(pow(r->found_mm[0] - r->typed_mm[0], 2) +
                                               pow(r->found_mm[1] - r->typed_mm[1], 2) +
                                               pow(r->found_mm[2] - r->typed_mm[2], 2)));
        memcpy(oc->sphere_centre_mm, r->found_mm, sizeof r->found_mm);
    }
    double off = 0;
    for (int k = 0; k < 3; k++) off += pow(r->found_mm[k] - r->typed_mm[k], 2);
    off = sqrt(off);
    if (oc->joint && oc->offset_prior_mm > 0 && off > 2 * oc->offset_prior_mm)
        model_warning("the typed sphere centre is %.2f mm from the one its highlights give (%.2f, %.2f, %.2f mm), "
                      "more than twice its std (--sphere-offset-prior-mm %g): check the ball's placement and "
                      "--sphere-centre-mm", off, r->found_mm[0], r->found_mm[1], r->found_mm[2], oc->offset_prior_mm);
    return true;
}

bool calib_lamps_run(const calib_lamps_opts_t *o, calib_lamps_result_t *r)
{
    memset(r, 0, sizeof *r);
    r->first_angle = -1;
    if (!calib_lamps_open(o, r)) return false;
    calib_lamps_opts_t oc = *o;   // the centre moves to the images' between rounds
    r->have_typed = true;
    memcpy(r->typed_mm, o->sphere_centre_mm, sizeof r->typed_mm);
    if (!rounds(&oc, r)) return false;
    return calib_lamps_write_json(&oc, r) && calib_lamps_write_report(&oc, r);
}

void calib_lamps_result_free(calib_lamps_result_t *r)
{
    for (int l = 0; r->lamps && l < r->nlamps; l++) {
        calib_lamps_lamp_t *lp = &r->lamps[l];
        free(lp->frame);
        free(lp->hl);
        free(lp->has_ray);
        free(lp->used);
        free(lp->p_mm);
        free(lp->d);
        free(lp->dist_mm);
    }
    free(r->lamps);
    free(r->angle_deg);
    free(r->dark_row);
    free(r->centre_mm);
    json_decref(r->provenance);
    rig_plan_free(r->plan);
    rig_session_free(r->session);
    model_camera_free(r->cam);
    g_free(r->session_dir);
    memset(r, 0, sizeof *r);
    r->first_angle = -1;
}
