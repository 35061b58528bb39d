// calib/gain/standard.c — the temporal figures of EMVA 1288 Release 4.0
// Linear by the standard's definitions, with the ranges and points of the
// EMVA 1288 working group's reference implementation (github.com/EMVA1288/
// emva1288, Results1288): saturation, system gain K and responsivity R
// (regressions through the origin over the steps up to 70 % of
// saturation), quantum efficiency, temporal dark noise, absolute
// sensitivity threshold, saturation capacity, SNR_max, dynamic range,
// linearity error and dark current; and their inputs from a gain's analysis
// (calib/gain/gain.h).
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "calib/gain/internal.h"
#include "model/model.h"

double calib_gain_signed_sqrt(double v)
{
    return isfinite(v) ? (v < 0 ? -sqrt(-v) : sqrt(v)) : NAN;
}

// The saturation step: walking from the brightest step back, the variance's
// maximum where it first falls on both sides (a single lower step on the way
// does not end the walk): the reference implementation's index_u_ysat. The
// standard's saturation is the maximum of the variance: where the walk ends
// below half the sweep's largest sigma^2_y it stopped on a noisy plateau
// past saturation (a full well reached before the converter's end leaves
// the dark noise there), and the largest sigma^2_y is the saturation
// (*plateau true).
static int saturation_index(const double *var_y, int n, bool *plateau)
{
    double vmax = 0, top = -INFINITY;
    int imax = 0, itop = 0;
    for (int i = n - 1; i >= 0; i--) {
        double prev = var_y[i > 0 ? i - 1 : 1 < n ? 1 : 0];
        if (var_y[i] >= vmax || prev >= vmax) {
            vmax = var_y[i];
            imax = i;
        } else if (var_y[i] < vmax && prev < vmax)
            break;
    }
    for (int i = 0; i < n; i++)
        if (var_y[i] > top) {
            top = var_y[i];
            itop = i;
        }
    *plateau = var_y[imax] < 0.5 * top;
    return *plateau ? itop : imax;
}

// The slope of y = s x through the origin over i = 0..last: sum x y / sum x^2.
static double slope_origin(const double *x, const double *y, int last)
{
    double sxy = 0, sxx = 0;
    for (int i = 0; i <= last; i++) {
        sxy += x[i] * y[i];
        sxx += x[i] * x[i];
    }
    return sxx > 0 ? sxy / sxx : NAN;
}

// The least-squares line y = c0 + c1 x of n points: false when the x are all equal.
static bool line_fit(const double *x, const double *y, int n, double *c0, double *c1)
{
    double sx = 0, sy = 0, sxx = 0, sxy = 0;
    for (int i = 0; i < n; i++) {
        sx += x[i];
        sy += y[i];
    }
    double mx = sx / n, my = sy / n;
    for (int i = 0; i < n; i++) {
        sxx += (x[i] - mx) * (x[i] - mx);
        sxy += (x[i] - mx) * (y[i] - my);
    }
    if (!(n >= 2 && sxx > 0)) return false;
    *c1 = sxy / sxx;
    *c0 = my - *c1 * mx;
    return true;
}

// Linearity (Release 4.0: the deviations relative to the line of least
// squared relative deviations): over the steps from the first with a signal
// of at least 5 % of saturation's to the last with at most 95 %.
static void linearity(const double *x, const double *Y, int n, calib_gain_emva_t *o)
{
    const double ys = Y[o->i_sat];
    o->i_lin_first = o->i_lin_last = -1;
    for (int i = 0; i < n; i++) {
        if (o->i_lin_first < 0 && Y[i] >= 0.05 * ys) o->i_lin_first = i;
        if (Y[i] <= 0.95 * ys) o->i_lin_last = i;
    }
    o->lin_slope = o->lin_offset = o->le_min_pct = o->le_max_pct = o->le_pct = NAN;
    if (o->i_lin_first < 0 || o->i_lin_last - o->i_lin_first < 1) return;
    // minimise sum ((Y - a x - b) / Y)^2: the normal equations in the sums of x/Y, x/Y^2, (x/Y)^2, 1/Y, 1/Y^2
    double xy = 0, xy2 = 0, x2y2 = 0, iy = 0, iy2 = 0;
    for (int i = o->i_lin_first; i <= o->i_lin_last; i++) {
        xy += x[i] / Y[i];
        xy2 += x[i] / (Y[i] * Y[i]);
        x2y2 += (x[i] / Y[i]) * (x[i] / Y[i]);
        iy += 1 / Y[i];
        iy2 += 1 / (Y[i] * Y[i]);
    }
    double den = xy2 * xy2 - x2y2 * iy2;
    if (!(den != 0) || !(x2y2 != 0)) return;
    double b = (xy * xy2 - x2y2 * iy) / den, a = (xy - b * xy2) / x2y2;
    double dmin = INFINITY, dmax = -INFINITY;
    for (int i = o->i_lin_first; i <= o->i_lin_last; i++) {
        double line = a * x[i] + b, dv = 100 * (Y[i] - line) / line;
        dmin = fmin(dmin, dv);
        dmax = fmax(dmax, dv);
    }
    o->lin_slope = a;
    o->lin_offset = b;
    o->le_min_pct = dmin;
    o->le_max_pct = dmax;
    o->le_pct = 0.5 * (dmax - dmin);
}

// The temporal dark: sigma^2_y.dark (the first exposure's with two exposures
// or fewer, else the intercept of the line against exposure, at least
// 0.24 q^2) and the dark current from the mean and the variance (more than
// two exposures; from the variance NAN when its slope is negative).
static void dark(const calib_gain_emva_in_t *in, calib_gain_emva_t *o)
{
    const double q2 = in->quant_dn * in->quant_dn;
    double c0, c1, tmin = INFINITY, tmax = -INFINITY;
    int first = 0;
    for (int i = 0; i < in->nd; i++) {
        if (in->dark_t_us[i] < in->dark_t_us[first]) first = i;
        tmin = fmin(tmin, in->dark_t_us[i]);
        tmax = fmax(tmax, in->dark_t_us[i]);
    }
    o->n_dark = in->nd;
    o->dark_fitted = in->nd > 2 && tmax > tmin && line_fit(in->dark_t_us, in->dark_var, in->nd, &c0, &c1);
    o->var_y_dark_dn2 = o->dark_fitted ? c0 : in->nd > 0 ? in->dark_var[first] : NAN;
    o->dark_floored = o->var_y_dark_dn2 < 0.24 * q2;
    double v = o->dark_floored ? 0.24 * q2 : o->var_y_dark_dn2;
    o->sigma_y_dark_dn = sqrt(v);
    o->sigma_d_e = sqrt(v - q2 / 12) / o->K;
    o->dark_current_dn_per_s = o->dark_current_var_dn2_per_s = NAN;
    if (o->dark_fitted && line_fit(in->dark_t_us, in->dark_mu, in->nd, &c0, &c1)) {
        o->dark_current_dn_per_s = c1 * 1e6;
        if (line_fit(in->dark_t_us, in->dark_var, in->nd, &c0, &c1) && c1 >= 0) o->dark_current_var_dn2_per_s = c1 * 1e6;
    }
    o->dark_current_e_per_s = o->dark_current_dn_per_s / o->K;
    o->dark_current_var_e_per_s = o->dark_current_var_dn2_per_s / (o->K * o->K);
}

bool calib_gain_emva(const calib_gain_emva_in_t *in, calib_gain_emva_t *o)
{
    memset(o, 0, sizeof *o);
    const int n = in->n;
    o->n = n;
    o->photons = in->photons;
    if (n < 2 || n > 100000 || in->nd < 1 || !(in->quant_dn > 0)) {
        model_error_set(NULL, 0, "EMVA 1288: %d steps and %d dark exposures; at least 2 steps and a dark pair are "
                        "needed", n, in->nd);
        return false;
    }
    double *Y = malloc(sizeof(double) * (size_t)n * 2), *V = Y ? Y + n : NULL;   // signal, variance above dark
    if (!Y) {
        model_error_set(NULL, 0, "EMVA 1288: out of memory for %d steps", n);
        return false;
    }
    for (int i = 0; i < n; i++) {
        Y[i] = in->mu_y[i] - in->mu_d[i];
        V[i] = in->var_y[i] - in->var_d[i];
    }
    o->i_sat = saturation_index(in->var_y, n, &o->sat_plateau);
    o->mu_y_sat_dn = Y[o->i_sat];
    o->i_fit_last = -1;
    for (int i = 0; i < n; i++)
        if (Y[i] <= 0.7 * o->mu_y_sat_dn) o->i_fit_last = i;
    o->n_fit = o->i_fit_last + 1;
    o->K = o->i_fit_last >= 0 ? slope_origin(Y, V, o->i_fit_last) : NAN;
    o->R = o->i_fit_last >= 0 ? slope_origin(in->x, Y, o->i_fit_last) : NAN;
    bool ok = o->K > 0 && o->R > 0;
    if (ok) {
        o->inv_K = 1 / o->K;
        dark(in, o);
        o->x_sat = in->x[o->i_sat];
        o->mu_e_sat = o->R * o->x_sat / o->K;   // eta mu_p.sat: the photon scale cancels
        o->mu_e_min = o->sigma_y_dark_dn / o->K + 0.5;
        o->qe = in->photons ? o->R / o->K : NAN;
        o->mu_p_sat = in->photons ? o->x_sat : NAN;
        o->mu_p_min = in->photons ? o->mu_e_min / o->qe : NAN;
        o->snr_max = sqrt(o->mu_e_sat);
        o->dr = o->mu_e_sat / o->mu_e_min;   // mu_p.sat / mu_p.min
        linearity(in->x, Y, n, o);
    } else
        model_error_set(NULL, 0, "EMVA 1288: the photon transfer through the origin over the %d steps up to 70 %% of "
                        "saturation (%.6g DN) gives K %.6g DN/e- and a responsivity %.6g: the sweep needs steps "
                        "with a rising signal and variance below saturation", o->n_fit, o->mu_y_sat_dn, o->K, o->R);
    free(Y);
    return ok;
}

bool calib_gain_an_emva(const calib_gain_data_t *d, double quant_dn, calib_gain_an_t *a)
{
    const size_t ng = (size_t)d->ng + 1;
    double *buf = malloc(sizeof(double) * ng * 3), *dt = buf, *dm = buf + ng, *dv = buf + 2 * ng;
    int *dn = malloc(sizeof(int) * ng), nd = 0;
    if (!buf || !dn) {
        free(buf);
        free(dn);
        model_error_set(NULL, 0, "gain %g: out of memory for the EMVA 1288 figures", a->gain_db);
        return false;
    }
    // the temporal darks: the sweep's and the dark set's pairs, one per exposure (the most frames)
    for (int i = 0; i < d->ng; i++) {
        const calib_gain_group_t *g = &d->g[i];
        if (g->gain_db != a->gain_db || !g->dark || g->set == CALIB_GAIN_SET_FLAT || !isfinite(g->var_dn2)) continue;
        int k = 0;
        while (k < nd && dt[k] != g->exposure_us) k++;
        if (k == nd) nd++;
        else if (g->n <= dn[k]) continue;
        dt[k] = g->exposure_us;
        dm[k] = g->mean_dn;
        dv[k] = g->var_dn2;
        dn[k] = g->n;
    }
    const bool photons = a->photon_source != NULL;
    const calib_gain_emva_in_t in = { a->n, photons ? a->mu_p : a->t, a->mu_y, a->var_y, a->mu_d, a->var_d, photons,
                                      nd, dt, dm, dv, quant_dn };
    bool ok = calib_gain_emva(&in, &a->emva);
    if (!ok) {
        char *m = strdup(model_last_error());
        model_error_set(NULL, 0, "gain %g: %s", a->gain_db, m ? m : "out of memory");
        free(m);
    }
    const calib_gain_emva_t *e = &a->emva;
    a->snr_exact_mu_e_min = 0.5 + sqrt(e->sigma_y_dark_dn * e->sigma_y_dark_dn / (e->K * e->K) + 0.25);
    free(buf);
    free(dn);
    return ok;
}
