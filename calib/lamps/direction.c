// calib/lamps/direction.c — the ray toward a lamp from a model of its highlight in
// direction space (calib_lamps_fit_direction): the mirror's GGX lobe around the
// lamp's direction, the lamp a disk of its angular size, point-sampled at the
// pixel centres, fitted by Levenberg-Marquardt and reweighted twice.
#include <math.h>
#include <string.h>

#include "calib/lamps/internal.h"
#include "model/base/vec.h"

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
        double t = lamps_ray_sphere(C, d[k], c, r);
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
