// calib/gain/linearity.c — the linearity error of a sweep, EMVA 1288
// Release 4.0 (relative deviations from the weighted line) and Release 3
// (the unweighted line) (calib/gain/gain.h).
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "calib/gain/gain.h"
#include "model/model.h"

// Half the range of the relative deviations 100 (mu - line) / line, %, over
// the points with mu in [lo_dn, hi_dn] (and mu > 0 when positive); each
// point's deviation into dev_pct (NAN outside the range) when given.
static double deviation_half_range(double c0, double c1, const double *t, const double *mu, int n, double lo_dn,
                                   double hi_dn, bool positive, double *dev_pct)
{
    double dmin = INFINITY, dmax = -INFINITY;
    for (int i = 0; i < n; i++) {
        double line = c0 + c1 * t[i], d = 100.0 * (mu[i] - line) / line;
        bool in = mu[i] >= lo_dn && mu[i] <= hi_dn && (!positive || mu[i] > 0);
        if (dev_pct) dev_pct[i] = in ? d : NAN;
        if (in) {
            dmin = fmin(dmin, d);
            dmax = fmax(dmax, d);
        }
    }
    return 0.5 * (dmax - dmin);
}

double calib_gain_linearity(const double *t, const double *mu, int n, double sat_dn, double lo, double hi,
                            double *slope, double *offset, int *nfit, double *dev_pct)
{
    double *x = malloc(sizeof(double) * ((size_t)n + 1) * 2), *y = x ? x + n + 1 : NULL;
    int m = 0;
    if (!x) {   // no line, no figure
        model_error_set(NULL, 0, "linearity: out of memory for %d steps", n);
        for (int i = 0; dev_pct && i < n; i++) dev_pct[i] = NAN;
        if (slope) *slope = NAN;
        if (offset) *offset = NAN;
        if (nfit) *nfit = 0;
        return NAN;
    }
    for (int i = 0; i < n; i++)
        if (mu[i] >= lo * sat_dn && mu[i] <= hi * sat_dn) {
            x[m] = t[i];
            y[m] = mu[i];
            m++;
        }
    double c[3] = { NAN, NAN, NAN }, le = NAN;
    if (m >= 3 && calib_gain_polyfit(x, y, m, 1, c)) {
        le = deviation_half_range(c[0], c[1], t, mu, n, lo * sat_dn, hi * sat_dn, false, dev_pct);
    } else if (dev_pct)
        for (int i = 0; i < n; i++) dev_pct[i] = NAN;
    if (slope) *slope = c[1];
    if (offset) *offset = c[0];
    if (nfit) *nfit = m;
    free(x);
    return le;
}

double calib_gain_linearity_r4(const double *t, const double *mu, int n, double sat_dn, double lo, double hi,
                               double *slope, double *offset, int *nfit, double *dev_pct)
{
    // EMVA 1288 Release 4.0, "Linearity": the regression minimises the
    // relative deviations, i.e. weighted least squares with weights 1/mu^2
    double ts = 0;
    for (int i = 0; i < n; i++) ts = fmax(ts, fabs(t[i]));
    double A[4] = { 0 }, b[2] = { 0 };
    int m = 0;
    for (int i = 0; i < n; i++) {
        if (!(mu[i] >= lo * sat_dn && mu[i] <= hi * sat_dn && mu[i] > 0) || !(ts > 0)) continue;
        double w = 1 / (mu[i] * mu[i]), x = t[i] / ts;
        A[0] += w;
        A[1] += w * x;
        A[3] += w * x * x;
        b[0] += w * mu[i];
        b[1] += w * x * mu[i];
        m++;
    }
    A[2] = A[1];
    double le = NAN, c0 = NAN, c1 = NAN;
    if (m >= 3 && model_solve_linear(A, b, 2)) {
        c0 = b[0];
        c1 = b[1] / ts;
        le = deviation_half_range(c0, c1, t, mu, n, lo * sat_dn, hi * sat_dn, true, dev_pct);
    } else if (dev_pct)
        for (int i = 0; i < n; i++) dev_pct[i] = NAN;
    if (slope) *slope = c1;
    if (offset) *offset = c0;
    if (nfit) *nfit = m;
    return le;
}
