// calib/gain/linearisation.c — the response linearisation of a sweep: the
// monotone table measured signal -> linear signal, the parametric
// S_m = S (1 - a S) of the same curve, and its reading from gain.json
// (calib/gain/gain.h).
#include <glib.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "calib/gain/internal.h"
#include "model/model.h"
#include "model/base/report.h"

double calib_gain_parametric_a(const double *t, const double *mu, int n, double sat)
{
    double A[9] = { 0 }, b[3] = { 0 }, ts = 0, ss = 0;   // column scales
    for (int i = 0; i < n; i++) {
        ts = fmax(ts, fabs(t[i]));
        ss = fmax(ss, fabs(mu[i]));
    }
    if (!(ts > 0) || !(ss > 0)) return 0;
    int m = 0;
    for (int i = 0; i < n; i++) {
        double ti = t[i], si = mu[i];
        if (!(si > 0) || (sat > 0 && si > 0.9 * sat) || !isfinite(ti)) continue;
        double x[3] = { ti / ts, 1, -si * si / (ss * ss) };
        for (int r = 0; r < 3; r++) {
            for (int c = 0; c < 3; c++) A[3 * r + c] += x[r] * x[c];
            b[r] += x[r] * si;
        }
        m++;
    }
    if (m < 5 || !model_solve_linear(A, b, 3)) return 0;
    double a = b[2] / (ss * ss);
    return isfinite(a) && a > 0 && a < 1e-3 ? a : 0;
}

bool calib_gain_linearisation(const double *t, const double *mu, int n, double sat, model_lin_t *table,
                              double *a_per_dn, double *anchor_slope, double *anchor_offset)
{
    memset(table, 0, sizeof *table);
    *a_per_dn = calib_gain_parametric_a(t, mu, n, sat);
    double *x = malloc(sizeof(double) * (n + 1) * 2), *y = x + n + 1, c[3];
    if (!x) {
        model_error_set(NULL, 0, "out of memory for the linearisation");
        return false;
    }
    // the anchor: small-signal response from 5..70 % of saturation (above the
    // low end, below the knee of a sensor's top end)
    int m = 0;
    for (int i = 0; i < n; i++)
        if (mu[i] >= 0.05 * sat && mu[i] <= 0.7 * sat) {
            x[m] = t[i];
            y[m] = mu[i];
            m++;
        }
    if (m < 4 || !calib_gain_polyfit(x, y, m, 2, c) || !(c[1] > 0)) {
        free(x);
        model_error_set(NULL, 0, "linearisation: %d sweep steps between 5 %% and 70 %% of saturation (%.6g DN); the "
                        "small-signal response needs at least 4 with a rising signal", m, sat);
        return false;
    }
    *anchor_slope = c[1];
    *anchor_offset = c[0];
    // the table: every step up to saturation, measured -> anchored linear
    m = 0;
    double tlast = -INFINITY;
    for (int i = 0; i < n; i++)
        if (mu[i] <= sat && t[i] > tlast) {
            tlast = t[i];
            x[m] = mu[i];
            y[m] = c[0] + c[1] * t[i];
            m++;
        }
    // the linear signal must rise: steps whose anchored value is not above 0 (exposures shorter than the
    // offset c0 / r allows) carry nothing
    int k0 = 0;
    while (k0 < m && !(y[k0] > 0)) k0++;
    bool ok = model_lin_monotone(x + k0, y + k0, m - k0, table);
    free(x);
    if (!ok) {
        char *e = g_strdup(model_last_error());
        model_error_set(NULL, 0, "linearisation: %s", e);
        g_free(e);
    }
    return ok;
}

// The linearisation of a's sweep and the Release 4.0 LE of the signal through
// it (the table's and the parametric form's; the range 5..95 % of saturation
// mapped through each), for the report.
bool gain_analyse_linearisation(calib_gain_an_t *a)
{
    const double sat = a->ptc.saturation_dn;
    if (!calib_gain_linearisation(a->t, a->mu, a->n, sat, &a->lin, &a->lin_a_per_dn, &a->lin_anchor_dn_per_us,
                                  &a->lin_anchor_offset_dn)) {
        char *m = g_strdup(model_last_error());
        model_error_set(NULL, 0, "gain %g dB: %s", a->gain_db, m);
        g_free(m);
        return false;
    }
    double *v = malloc(sizeof(double) * (a->n + 1));
    if (!v) {
        model_error_set(NULL, 0, "gain %g dB: out of memory for the linearisation's check", a->gain_db);
        return false;
    }
    model_lin_t par = { .kind = MODEL_LIN_PARAMETRIC, .a_per_dn = a->lin_a_per_dn };
    for (int k = 0; k < 2; k++) {
        const model_lin_t *L = k ? &par : &a->lin;
        for (int i = 0; i < a->n; i++) v[i] = model_linearise(L, a->mu[i], 1, NULL);
        double lo = model_linearise(L, 0.05 * sat, 1, NULL), hi = model_linearise(L, 0.95 * sat, 1, NULL);
        *(k ? &a->le_linearised_param_pct : &a->le_linearised_pct) =
            calib_gain_linearity_r4(a->t, v, a->n, 1, lo, hi, NULL, NULL, NULL, NULL);
    }
    free(v);
    return true;
}

bool calib_gain_lin_from_json(json_t *gj, const char *path, model_lin_t *out)
{
    memset(out, 0, sizeof *out);
    int version = 1;
    if (!model_json_format_check(gj, path, CALIB_GAIN_FORMAT, CALIB_GAIN_FORMAT_VERSION, &version)) {
        char *e = g_strdup(model_last_error());
        model_error(NULL, 0, "%s", e);
        g_free(e);
        return false;
    }
    json_t *l = json_object_get(gj, "linearisation");
    if (!l && version >= 2) {
        model_error(path, 0, "refl-gain version %d without its \"linearisation\" (refl calib gain writes it; run it "
                    "again)", version);
        return false;
    }
    if (!l) {   // version 1 without it: the parametric form of its reference gain's curves
        json_t *gains = json_object_get(gj, "gains"), *g0 = NULL;
        for (size_t k = 0; k < json_array_size(gains); k++) {
            json_t *e = json_array_get(gains, k);
            if (fabs(json_number_value(json_object_get(e, "gain_db")) -
                     json_number_value(json_object_get(gj, "gain_db"))) < 1e-9)
                g0 = e;
        }
        json_t *cv = json_object_get(g0 ? g0 : gj, "curves");
        json_t *t = json_object_get(cv, "exposure_us"), *S = json_object_get(cv, "signal_dn");
        size_t n = json_array_size(t);
        if (n != json_array_size(S) || n < 5 || n > 100000) return true;
        double *tv = malloc(sizeof(double) * n * 2), *sv = tv + n;
        if (!tv) {
            model_error(path, 0, "out of memory for the reference gain's curves (%zu steps)", n);
            return false;
        }
        for (size_t i = 0; i < n; i++) {
            tv[i] = json_is_number(json_array_get(t, i)) ? json_number_value(json_array_get(t, i)) : NAN;
            sv[i] = json_is_number(json_array_get(S, i)) ? json_number_value(json_array_get(S, i)) : NAN;
        }
        json_t *sat = json_object_get(gj, "saturation_dn");
        out->a_per_dn = calib_gain_parametric_a(tv, sv, (int)n, json_is_number(sat) ? json_number_value(sat) : 0);
        out->kind = out->a_per_dn > 0 ? MODEL_LIN_PARAMETRIC : MODEL_LIN_NONE;
        free(tv);
        return true;
    }
    const char *method = json_string_value(json_object_get(l, "method"));
    json_t *a = json_object_get(l, "a_per_dn");
    if (!json_is_object(l) || !method || (strcmp(method, "monotone") && strcmp(method, "parametric")) ||
        (a && !json_is_number(a))) {
        model_error(path, 0, "linearisation: needs method \"monotone\" or \"parametric\" and a number a_per_dn "
                    "(refl calib gain writes it; run it again)");
        return false;
    }
    double av = a ? json_number_value(a) : 0;
    if (!strcmp(method, "parametric")) {
        if (!(av >= 0 && av < 1e-3)) {
            model_error(path, 0, "linearisation: a_per_dn %g is outside [0, 1e-3) per DN", av);
            return false;
        }
        *out = (model_lin_t){ .kind = av > 0 ? MODEL_LIN_PARAMETRIC : MODEL_LIN_NONE, .a_per_dn = av };
        return true;
    }
    json_t *jm = json_object_get(l, "measured_dn"), *js = json_object_get(l, "linear_dn");
    size_t n = json_array_size(jm);
    if (n < 2 || n > MODEL_LIN_MAX || json_array_size(js) != n) {
        model_error(path, 0, "linearisation: the monotone table needs measured_dn and linear_dn of equal length, "
                    "2 to %d knots (has %zu and %zu)", MODEL_LIN_MAX, n, json_array_size(js));
        return false;
    }
    double m[MODEL_LIN_MAX], s[MODEL_LIN_MAX];
    for (size_t i = 0; i < n; i++) {
        json_t *x = json_array_get(jm, i), *y = json_array_get(js, i);
        if (!json_is_number(x) || !json_is_number(y) ||
            (i > 0 && !(json_number_value(x) > m[i - 1] && json_number_value(y) > s[i - 1]))) {
            model_error(path, 0, "linearisation: knot %zu: measured_dn and linear_dn must be numbers, both "
                        "strictly increasing", i);
            return false;
        }
        m[i] = json_number_value(x);
        s[i] = json_number_value(y);
    }
    if (!model_lin_knots(m, s, (int)n, out)) {
        char *e = g_strdup(model_last_error());
        model_error(path, 0, "linearisation: %s", e);
        g_free(e);
        return false;
    }
    out->a_per_dn = av;
    return true;
}
