// calib/lamps/triangulate.c — each lamp the least-squares point nearest its rays,
// outliers dropped by deleted residuals (calib_lamps_triangulate), and stage 3
// of the calibration: every lamp triangulated, again with the lamp's disk in
// its highlights (calib_lamps_triangulate_lamps).
#include <glib.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "calib/lamps/internal.h"
#include "model/base/vec.h"

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
    if (m < 3 || !m3_inv(Ai, A)) return false;
    for (int r = 0; r < 3; r++) o->x_mm[r] = Ai[r * 3] * b[0] + Ai[r * 3 + 1] * b[1] + Ai[r * 3 + 2] * b[2];
    memcpy(o->cov_mm2, Ai, sizeof Ai);
    return true;
}

double lamps_ray_dist(model_vec3_t p, model_vec3_t d, const double x[3])
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
    if (!dist || !tmp || !del) {
        model_error_set(NULL, 0, "out of memory");
        goto done;
    }
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
            dist[i] = lamps_ray_dist(p[i], d[i], o->x_mm);
            del[i] = dist[i];
            if (!used[i]) continue;
            used[i] = false;
            if (o->n_used > 3 && fit_once(p, d, n, used, &loo)) del[i] = lamps_ray_dist(p[i], d[i], loo.x_mm);
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

// One lamp: the point nearest its rays, with the lamp's disk once more.
static bool triangulate_lamp(const calib_lamps_opts_t *o, calib_lamps_result_t *r, calib_lamps_lamp_t *lp)
{
    const int NA = r->nangles, nm = lp->nmissing, nr = NA - nm;
    if (nm) {
        char *t = lamps_missing_text(r, lp);
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
            lamps_refit_highlights(o, r, lp, lp->fit.x_mm);
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
