// calib/lamps/pattern.c — each lamp's emission pattern from a session of the
// reference white (or any flat Lambertian target of known albedo) lit by one
// lamp at a time: every window's irradiance, relative to the lamp's on-axis
// intensity, against the direction from the lamp, fitted with the model's
// pattern (model_lamp_emission: max(0, a.u)^n) per lamp; written into
// lamps.json beside the positions (`refl calib pattern`, calib/cmd_lamps.c).
#include <glib.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "calib/lamps/lamps.h"
#include "model/base/report.h"
#include "model/base/vec.h"

// One lamp's windows: unit direction from the lamp, log of the irradiance
// y = s E d^2 / (kd n.l) (E divided back in: the raw signal's), its std.
typedef struct {
    int           n;
    model_vec3_t *u;
    double       *ly, *sig;
    bool         *used;
    model_vec3_t  c, e1, e2;   // the mean direction and a frame across it
} pat_data_t;

static model_vec3_t pat_axis(const pat_data_t *D, const double x[4], double *bn)
{
    model_vec3_t b = v3_add(D->c, v3_add(v3_scale(D->e1, x[2]), v3_scale(D->e2, x[3])));
    *bn = v3_norm(b);
    return v3_scale(b, 1 / *bn);
}

// Residuals (ln y - ln A - n ln(a.u)) / sig of the used windows and their
// Jacobian rows (4 each: ln A, n, t1, t2) into J (may be NULL); the cost.
static double pat_eval(const pat_data_t *D, const double x[4], double *J, double *r)
{
    double bn, cost = 0;
    model_vec3_t a = pat_axis(D, x, &bn);
    model_vec3_t da[2] = { v3_scale(v3_sub(D->e1, v3_scale(a, v3_dot(a, D->e1))), 1 / bn),
                           v3_scale(v3_sub(D->e2, v3_scale(a, v3_dot(a, D->e2))), 1 / bn) };
    int k = 0;
    for (int i = 0; i < D->n; i++) {
        if (!D->used[i]) continue;
        double au = fmax(v3_dot(a, D->u[i]), 1e-9), res = (D->ly[i] - x[0] - x[1] * log(au)) / D->sig[i];
        if (r) r[k] = res;
        cost += res * res;
        if (J) {
            double *j = &J[4 * k];
            j[0] = -1 / D->sig[i];
            j[1] = -log(au) / D->sig[i];
            for (int q = 0; q < 2; q++) j[2 + q] = -x[1] * v3_dot(da[q], D->u[i]) / au / D->sig[i];
        }
        k++;
    }
    return cost;
}

// Normal equations of the used windows plus the axis prior (t ~ N(0, 1):
// 45 deg, only felt where n is near 0 and the axis is not seen).
static void pat_normal(const pat_data_t *D, const double x[4], double *J, double *r, int m, double N[16],
                       double g[4])
{
    pat_eval(D, x, J, r);
    memset(N, 0, 16 * sizeof *N);
    memset(g, 0, 4 * sizeof *g);
    for (int k = 0; k < m; k++)
        for (int p = 0; p < 4; p++) {
            g[p] += J[4 * k + p] * r[k];
            for (int q = 0; q < 4; q++) N[4 * p + q] += J[4 * k + p] * J[4 * k + q];
        }
    for (int q = 2; q < 4; q++) {
        N[5 * q] += 1;
        g[q] += x[q];
    }
}

// Levenberg-Marquardt from x (n held >= 0). Returns the cost.
static double pat_solve(const pat_data_t *D, double x[4], double *J, double *r, int m)
{
    double lambda = 1e-3, cost = pat_eval(D, x, NULL, NULL) + x[2] * x[2] + x[3] * x[3];
    for (int it = 0; it < 100; it++) {
        double N[16], g[4];
        pat_normal(D, x, J, r, m, N, g);
        bool better = false;
        for (int tries = 0; tries < 12 && !better; tries++) {
            double A[16], b[4], xn[4];
            memcpy(A, N, sizeof A);
            for (int p = 0; p < 4; p++) {
                A[5 * p] += lambda * (N[5 * p] + 1e-12);
                b[p] = -g[p];
            }
            if (!model_solve_linear(A, b, 4)) {
                lambda *= 10;
                continue;
            }
            for (int p = 0; p < 4; p++) xn[p] = x[p] + b[p];
            if (xn[1] < 0) xn[1] = 0;
            double c = pat_eval(D, xn, NULL, NULL) + xn[2] * xn[2] + xn[3] * xn[3];
            if (c < cost) {
                double dc = cost - c;
                memcpy(x, xn, sizeof xn);
                cost = c;
                lambda = fmax(lambda / 10, 1e-9);
                better = true;
                if (dc < 1e-10 * (1 + cost)) return cost;
            } else {
                lambda *= 10;
            }
        }
        if (!better) break;
    }
    return cost;
}

// The fit of one lamp's windows: starts at several n, the best kept; then
// windows beyond 5 robust std dropped and fitted again; the covariance and the
// figures of out.
static bool pat_fit(pat_data_t *D, const model_lamp_t *L, calib_lamps_pattern_t *out)
{
    double *J = malloc(sizeof *J * 4 * (size_t)D->n), *r = malloc(sizeof *r * (size_t)D->n);
    double *tmp = malloc(sizeof *tmp * (size_t)D->n), x[4] = { 0 };
    if (!J || !r || !tmp) {
        free(J), free(r), free(tmp);
        model_error_set(NULL, 0, "out of memory");
        return false;
    }
    int m = 0;
    for (int round = 0; round < 2; round++) {
        m = 0;
        double mean = 0;
        for (int i = 0; i < D->n; i++)
            if (D->used[i]) mean += D->ly[i], m++;
        double best = INFINITY, xb[4] = { 0 };
        static const double n0[] = { 0.5, 3, 10, 30 };
        for (size_t s = 0; s < sizeof n0 / sizeof n0[0]; s++) {
            double xs[4] = { mean / m, n0[s], 0, 0 }, c = pat_solve(D, xs, J, r, m);
            if (c < best) best = c, memcpy(xb, xs, sizeof xb);
        }
        memcpy(x, xb, sizeof x);
        pat_eval(D, x, NULL, r);
        for (int k = 0; k < m; k++) tmp[k] = fabs(r[k]);
        double scale = 1.4826 * model_median(tmp, m);
        if (round) break;
        int k = 0, drop = 0;
        for (int i = 0; i < D->n; i++) {
            if (!D->used[i]) continue;
            if (fabs(r[k++]) > 5 * scale && drop < m / 5) D->used[i] = false, drop++;
        }
        out->rejected = drop;
        if (!drop) break;
    }
    double N[16], g[4], C[16] = { 0 };
    pat_normal(D, x, J, r, m, N, g);
    double chi2 = 0;
    for (int k = 0; k < m; k++) chi2 += r[k] * r[k];
    double s2 = chi2 / fmax(m - 4, 1);
    bool ok = true;
    for (int q = 0; q < 4 && ok; q++) {
        double A[16], b[4] = { 0 };
        memcpy(A, N, sizeof A);
        b[q] = 1;
        ok = model_solve_linear(A, b, 4);
        for (int p = 0; p < 4; p++) C[4 * p + q] = b[p] * s2;
    }
    double bn, rms = 0, worst = 0, span = 0;
    model_vec3_t a = pat_axis(D, x, &bn);
    model_vec3_t da[2] = { v3_scale(v3_sub(D->e1, v3_scale(a, v3_dot(a, D->e1))), 1 / bn),
                           v3_scale(v3_sub(D->e2, v3_scale(a, v3_dot(a, D->e2))), 1 / bn) };
    for (int i = 0, k = 0; i < D->n; i++) {
        if (!D->used[i]) continue;
        double au = v3_dot(a, D->u[i]);
        double gr[4] = { 1, log(au), x[1] * v3_dot(da[0], D->u[i]) / au, x[1] * v3_dot(da[1], D->u[i]) / au }, v = 0;
        for (int p = 0; p < 4; p++)
            for (int q = 0; q < 4; q++) v += gr[p] * C[4 * p + q] * gr[q];
        worst = fmax(worst, sqrt(fmax(v, 0)));
        rms += r[k] * D->sig[i] * r[k] * D->sig[i];
        span = fmax(span, acos(fmin(1, v3_dot(D->c, D->u[i]))));
        k++;
    }
    // the axis's std: the larger of the two tilts' (rad per unit t ~ 1 / |b|)
    double at = sqrt(fmax(C[10], C[15])) / bn;
    model_vec3_t o = v3_unit(v3_scale(L->position_mm, -1));
    out->nwindows = m;
    out->n = x[1];
    out->n_std = sqrt(fmax(C[5], 0));
    out->axis = a;
    out->axis_std_deg = at * 180 / M_PI;
    out->tilt_deg = acos(fmax(-1, fmin(1, v3_dot(a, o)))) * 180 / M_PI;
    out->cone_centre = D->c;
    out->cone_half_angle_deg = span * 180 / M_PI;
    out->kcI_axis_per_us = exp(x[0]);
    out->rms_rel = sqrt(rms / m);
    out->irradiance_std_rel = worst;
    for (int p = 0; p < 3; p++)
        for (int q = 0; q < 3; q++) out->cov_n_t[3 * p + q] = C[4 * (p + 1) + q + 1];
    out->axis_per_t[0] = da[0];
    out->axis_per_t[1] = da[1];
    out->fitted = ok;
    free(J), free(r), free(tmp);
    if (!ok) model_error_set(NULL, 0, "lamp %s: the pattern's fit is singular (the windows' directions do not "
                             "constrain it)", L->name);
    return ok;
}

// Observation b as a window of lamp l (L): the unit direction *u from the
// lamp, the irradiance *y = s d^2 / (kd n.l) (s the raw signal: the loaded
// pattern divided back in) and its relative noise *rel (floor 0.1 %: the
// target's and the model's own). false: another lamp's, or no signal.
static bool pat_window(const calib_obs_t *b, int l, const model_lamp_t *L, double kd, model_vec3_t *u, double *y,
                       double *rel)
{
    double s = b->s_dn_per_us * b->emission;
    if (b->lamp != l || !(s > 0) || !(b->c.nl > 0)) return false;
    double ca = cos(b->angle_deg * M_PI / 180), sa = sin(b->angle_deg * M_PI / 180);
    model_vec3_t p = v3(ca * b->p0_mm[0] - sa * b->p0_mm[1], sa * b->p0_mm[0] + ca * b->p0_mm[1], b->p0_mm[2]);
    double d = v3_norm(v3_sub(p, L->position_mm));
    *u = v3_unit(v3_sub(p, L->position_mm));
    *y = s * d * d / (kd * b->c.nl);
    double r = b->s_std > 0 ? b->s_std * b->emission / s : 0;
    *rel = sqrt(r * r + 1e-6);
    return true;
}

bool calib_lamps_pattern_fit(const calib_obs_set_t *obs, const calib_set_t *cal, double albedo,
                             calib_lamps_pattern_t *out)
{
    const double kd = albedo / M_PI;
    bool ok = true;
    for (int l = 0; l < cal->lamps->n && ok; l++) {
        const model_lamp_t *L = &cal->lamps->lamps[l];
        calib_lamps_pattern_t *P = &out[l];
        memset(P, 0, sizeof *P);
        snprintf(P->name, sizeof P->name, "%s", L->name);
        pat_data_t D = { 0 };
        D.u = malloc(sizeof *D.u * (size_t)(obs->n + 1));
        D.ly = malloc(sizeof *D.ly * (size_t)(obs->n + 1));
        D.sig = malloc(sizeof *D.sig * (size_t)(obs->n + 1));
        D.used = malloc(sizeof *D.used * (size_t)(obs->n + 1));
        if (!D.u || !D.ly || !D.sig || !D.used) {
            model_error_set(NULL, 0, "out of memory");
            ok = false;
        }
        model_vec3_t sum = v3(0, 0, 0);
        for (int i = 0; ok && i < obs->n; i++) {
            model_vec3_t u;
            double y, rel;
            if (!pat_window(&obs->o[i], l, L, kd, &u, &y, &rel)) continue;
            D.u[D.n] = u;
            D.ly[D.n] = log(y);
            D.sig[D.n] = rel;
            D.used[D.n] = true;
            sum = v3_add(sum, u);
            D.n++;
        }
        P->nwindows = D.n;
        if (ok && D.n >= 20) {
            D.c = v3_unit(sum);
            model_vec3_t h = fabs(D.c.z) < 0.9 ? v3(0, 0, 1) : v3(1, 0, 0);
            D.e1 = v3_unit(v3_cross(h, D.c));
            D.e2 = v3_cross(D.c, D.e1);
            ok = pat_fit(&D, L, P);
        }   // else too few windows: not fitted, the lamp keeps its entry (the caller names it)
        free(D.u), free(D.ly), free(D.sig), free(D.used);
    }
    return ok;
}

// A fitted lamp is isotropic when its cos power is within PAT_ISO_SIGMAS of its 1-sigma of 0: its axis is then
// not determined, and the report shows no tilt.
#define PAT_ISO_SIGMAS 3
#define PAT_ISO_RULE "isotropic when the fitted cos power n is within 3 of its 1-sigma of 0 (n <= 3 sigma_n): " \
                     "its axis is then not determined and no tilt is shown"

static bool pat_isotropic(const calib_lamps_pattern_t *P)
{
    return P->fitted && P->n <= PAT_ISO_SIGMAS * P->n_std;
}

// The "emission" object of one lamp's fit.
static json_t *pattern_json(const calib_lamps_pattern_t *P)
{
    json_t *e = json_pack("{s:f,s:f,s:f,s:[fff],s:f,s:i,s:i,s:f,s:f,s:f}", "cos_power_std", P->n_std,
                          "axis_std_deg", P->axis_std_deg, "tilt_from_origin_deg", P->tilt_deg,
                          "measured_cone_centre", P->cone_centre.x, P->cone_centre.y, P->cone_centre.z,
                          "measured_cone_half_angle_deg", P->cone_half_angle_deg, "windows", P->nwindows,
                          "windows_rejected", P->rejected, "rms_residual_pct", 100 * P->rms_rel,
                          "irradiance_std_pct", 100 * P->irradiance_std_rel, "kc_I_axis_per_us", P->kcI_axis_per_us);
    json_t *c = json_array();
    for (int k = 0; k < 9; k++) json_array_append_new(c, model_json_number(P->cov_n_t[k]));
    json_object_set_new(e, "covariance_n_t1_t2", c);
    json_object_set_new(e, "isotropic", json_boolean(pat_isotropic(P)));
    for (int k = 0; k < 2; k++)
        json_object_set_new(e, k ? "axis_per_t2" : "axis_per_t1",
                            json_pack("[fff]", P->axis_per_t[k].x, P->axis_per_t[k].y, P->axis_per_t[k].z));
    return e;
}

bool calib_lamps_pattern_write(const calib_set_t *cal, const calib_lamps_pattern_t *pat, const char *session,
                               const char *out_json, json_t *provenance)
{
    json_error_t je;
    const char *in = cal->lamps->path;
    json_t *doc = json_load_file(in, 0, &je);
    if (!doc) {
        model_error_set(in, je.line, "not valid JSON: %s", je.text);
        return false;
    }
    if (!calib_lamps_json_check(doc, in, NULL)) {
        json_decref(doc);
        return false;
    }
    model_json_set_format(doc, CALIB_LAMPS_JSON_FORMAT, CALIB_LAMPS_JSON_VERSION);
    json_t *arr = json_object_get(doc, "lamps");
    for (int l = 0; l < cal->lamps->n; l++) {
        const calib_lamps_pattern_t *P = &pat[l];
        json_t *e = json_array_get(arr, (size_t)l);
        if (!P->fitted || !e) continue;
        json_object_set_new(e, "emission_cos_power", model_json_number(P->n));
        json_object_set_new(e, "emission_axis", json_pack("[fff]", P->axis.x, P->axis.y, P->axis.z));
        json_object_set_new(e, "emission", pattern_json(P));
    }
    json_object_set_new(doc, "emission_conventions", json_string(
        "a lamp's intensity toward the unit direction u from its centre is I max(0, emission_axis . u)^"
        "emission_cos_power (emission_axis a unit vector in the rig frame; emission_cos_power absent or 0: "
        "isotropic); I is the on-axis intensity, the white calibration's kc_I_per_us. Measured by refl calib "
        "pattern from a flat Lambertian target lit by each lamp alone, over the directions of its windows (a cone "
        "about emission.measured_cone_centre of half-angle emission.measured_cone_half_angle_deg; beyond it the "
        "pattern is extrapolated). emission: cos_power_std (1-sigma), axis_std_deg (1-sigma, degrees), "
        "tilt_from_origin_deg (the axis against the direction from the lamp to the rig origin), isotropic (true when "
        "emission_cos_power is within 3 cos_power_std of 0: the axis and its tilt are then not determined), windows and "
        "windows_rejected (beyond 5 robust std), rms_residual_pct (the windows' irradiance about the fitted "
        "pattern), irradiance_std_pct (the largest 1-sigma of the fitted irradiance over the measured cone), "
        "kc_I_axis_per_us (the on-axis kc*I the target's albedo implies; DN/us at 0 dB per (1/sr)/mm^2), "
        "covariance_n_t1_t2 (3 x 3, row-major: the fit's covariance of n and the axis's two tilt parameters t1, "
        "t2, dimensionless) with axis_per_t1 and axis_per_t2 (the axis's change per unit t1, t2, rig frame): "
        "d ln(pattern toward u) = dn ln(a.u) + n (dt1 axis_per_t1 + dt2 axis_per_t2).u / (a.u)"));
    json_object_set_new(doc, "emission_session", json_string(session));
    json_object_set_new(doc, "emission_provenance", json_incref(provenance));
    bool ok = model_write_json(out_json, doc);
    json_decref(doc);
    return ok;
}

// The report's headline: each lamp's cos power with its 1-sigma, isotropic or its axis's tilt; a lamp not
// measured is a miss.
static void pattern_headline(FILE *f, const calib_set_t *cal, const calib_lamps_pattern_t *pat)
{
    char **it = calloc((size_t)cal->lamps->n + 1, sizeof *it);
    if (!it) return;   // the page goes on without it (the table follows)
    int n = 0;
    for (int l = 0; l < cal->lamps->n; l++) {
        const calib_lamps_pattern_t *P = &pat[l];
        if (!P->fitted)
            it[n++] = g_strdup_printf("!%s: not measured (%d windows, 20 needed)", P->name, P->nwindows);
        else if (pat_isotropic(P))
            it[n++] = g_strdup_printf("%s: isotropic, cos power n = %.2f ± %.2f (within 3 sigma of 0: no axis)",
                                      P->name, P->n, P->n_std);
        else
            it[n++] = g_strdup_printf("%s: cos power n = %.2f ± %.2f, its axis %.2f ± %.2f deg from the direction to "
                                      "the rig origin", P->name, P->n, P->n_std, P->tilt_deg, P->axis_std_deg);
    }
    it[n++] = g_strdup(PAT_ISO_RULE);
    model_html_headline(f, "Headline", (const char *const *)it, n);
    for (int k = 0; k < n; k++) g_free(it[k]);
    free(it);
}

bool calib_lamps_pattern_report(const calib_obs_set_t *obs, const calib_set_t *cal, double albedo,
                                const calib_lamps_pattern_t *pat, const char *dir, const json_t *provenance)
{
    if (!model_mkdir_p(dir)) return false;
    char *csv = g_strdup_printf("%s/pattern_windows.csv", dir), *png = g_strdup_printf("%s/pattern.png", dir);
    char *html = g_strdup_printf("%s/report.html", dir);
    GString *t = g_string_new("lamp,angle_from_axis_deg,irradiance_rel,pattern_rel,sigma_rel,cos_power,"
                              "cos_power_std,isotropic\n");
    const double kd = albedo / M_PI;
    for (int l = 0; l < cal->lamps->n; l++) {
        const calib_lamps_pattern_t *P = &pat[l];
        if (!P->fitted) continue;
        for (int i = 0; i < obs->n; i++) {
            model_vec3_t u;
            double y, rel;
            if (!pat_window(&obs->o[i], l, &cal->lamps->lamps[l], kd, &u, &y, &rel)) continue;
            double au = v3_dot(P->axis, u);
            g_string_append_printf(t, "%s,%.4f,%.6g,%.6g,%.4g,%.4g,%.3g,%d\n", P->name,
                                   acos(fmax(-1, fmin(1, au))) * 180 / M_PI, y / P->kcI_axis_per_us,
                                   au > 0 ? pow(au, P->n) : 0, rel, P->n, P->n_std, pat_isotropic(P));
        }
    }
    bool ok = model_write_file_atomic(csv, t->str) && model_run_script("calib_pattern_report.py", csv, png, NULL) == 0;
    g_string_free(t, TRUE);
    FILE *f = ok ? model_html_begin(html, "refl calib pattern: the lamps' emission patterns", provenance) : NULL;
    if (f) {
        pattern_headline(f, cal, pat);
        model_html_heading(f, "Emission patterns");
        model_html_para(f, "Each window of the flat target (albedo %g) lit by one lamp: its irradiance y = s d^2 / (kd "
                        "n.l) relative to the lamp's fitted on-axis value, against the angle between the direction "
                        "from the lamp and the fitted emission axis; the pattern max(0, a.u)^n fitted to the log of "
                        "y, each window weighted by its noise (pattern_windows.csv: the windows and the fitted "
                        "pattern at each).", albedo);
        const char **rows = calloc((size_t)cal->lamps->n + 1, sizeof *rows);
        bool table = rows != NULL;
        int nr = 0;
        for (int l = 0; rows && l < cal->lamps->n; l++) {
            const calib_lamps_pattern_t *P = &pat[l];
            rows[nr++] = pat_isotropic(P)
                             ? g_strdup_printf("%s|%.2f ± %.2f: isotropic|none (isotropic)||%.1f|%.2f|%.2f|%d (%d "
                                               "dropped)", P->name, P->n, P->n_std, P->cone_half_angle_deg,
                                               100 * P->rms_rel, 100 * P->irradiance_std_rel, P->nwindows, P->rejected)
                         : P->fitted ? g_strdup_printf("%s|%.2f ± %.2f|%.2f|%.2f|%.1f|%.2f|%.2f|%d (%d dropped)", P->name,
                                                       P->n, P->n_std, P->tilt_deg, P->axis_std_deg,
                                                       P->cone_half_angle_deg, 100 * P->rms_rel,
                                                       100 * P->irradiance_std_rel, P->nwindows, P->rejected)
                                     : g_strdup_printf("%s|not measured (%d windows, need 20)||||||", P->name,
                                                       P->nwindows);
        }
        if (table)
            model_html_table(f, "lamp|cos power n ± 1σ|axis tilt from the rig origin (deg)|axis 1σ (deg)|measured "
                             "cone half-angle (deg)|residual RMS (%)|irradiance 1σ (%)|windows", rows, nr);
        for (int k = 0; k < nr; k++) g_free((char *)rows[k]);
        free(rows);
        model_html_figure(f, "pattern.png", "Each lamp's windows: irradiance relative to the on-axis value against "
                          "the angle from the fitted emission axis (points), the fitted pattern max(0, cos)^n (line) "
                          "and the windows' relative residuals (%) below; a lamp taken as isotropic would be a flat "
                          "line at 1");
        ok = model_html_end(f, html);
        if (ok && !table) model_error_set(html, 0, "out of memory");
        ok = ok && table;
    } else {
        ok = false;
    }
    g_free(csv);
    g_free(png);
    g_free(html);
    return ok;
}
