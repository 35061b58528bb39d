// calib/gain/fit.c — the least-squares fits and statistics the gain analysis
// shares: polynomials of degree 1 or 2 with their standard errors, the
// correlation of two maps, a fixed pattern's 1-sigma (calib/gain/gain.h).
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "calib/gain/gain.h"
#include "model/model.h"

bool calib_gain_polyfit(const double *x, const double *y, int n, int degree, double *c)
{
    if (degree < 1 || degree > 2 || n <= degree) return false;
    int m = degree + 1;
    // scale x for conditioning
    double sx = 0;
    for (int i = 0; i < n; i++) sx = fmax(sx, fabs(x[i]));
    if (!(sx > 0)) return false;
    double A[9] = { 0 }, b[3] = { 0 };
    for (int i = 0; i < n; i++) {
        double p[3] = { 1, x[i] / sx, (x[i] / sx) * (x[i] / sx) };
        for (int r = 0; r < m; r++) {
            b[r] += p[r] * y[i];
            for (int k = 0; k < m; k++) A[r * m + k] += p[r] * p[k];
        }
    }
    if (!model_solve_linear(A, b, m)) return false;
    c[0] = b[0];
    c[1] = b[1] / sx;
    if (degree == 2) c[2] = b[2] / (sx * sx);
    return true;
}

bool calib_gain_polyfit_se(const double *x, const double *y, int n, int degree, double *c, double *se)
{
    if (!calib_gain_polyfit(x, y, n, degree, c)) return false;
    int m = degree + 1;
    if (n <= m) return false;
    double sx = 0;
    for (int i = 0; i < n; i++) sx = fmax(sx, fabs(x[i]));
    // (X^T X)^-1 in the scaled powers (columns solved one at a time)
    double A[9] = { 0 }, Ai[9], h[3];
    for (int i = 0; i < n; i++) {
        double p[3] = { 1, x[i] / sx, (x[i] / sx) * (x[i] / sx) };
        for (int r = 0; r < m; r++)
            for (int k = 0; k < m; k++) A[r * m + k] += p[r] * p[k];
    }
    for (int k = 0; k < m; k++) {
        double B[9], b[3] = { 0 };
        memcpy(B, A, sizeof B);
        b[k] = 1;
        if (!model_solve_linear(B, b, m)) return false;
        for (int r = 0; r < m; r++) Ai[r * m + k] = b[r];
    }
    // the sandwich (X^T X)^-1 X^T diag(e_i^2 / (1 - h_i)^2) X (X^T X)^-1 (HC3)
    double S[9] = { 0 };
    for (int i = 0; i < n; i++) {
        double p[3] = { 1, x[i] / sx, (x[i] / sx) * (x[i] / sx) }, fit = 0, hi = 0;
        for (int r = 0; r < m; r++) fit += c[r] * pow(x[i], r);
        for (int r = 0; r < m; r++) {
            h[r] = 0;
            for (int k = 0; k < m; k++) h[r] += Ai[r * m + k] * p[k];
            hi += p[r] * h[r];
        }
        double e = (y[i] - fit) / fmax(1 - hi, 1e-3);
        for (int r = 0; r < m; r++)
            for (int k = 0; k < m; k++) S[r * m + k] += e * e * h[r] * h[k];
    }
    for (int r = 0; r < m; r++) se[r] = sqrt(fmax(S[r * m + r], 0)) / pow(sx, r);
    return true;
}

double calib_gain_correlation(const float *a, const float *b, long n)
{
    double sa = 0, sb = 0;
    for (long i = 0; i < n; i++) {
        sa += a[i];
        sb += b[i];
    }
    double ma = sa / n, mb = sb / n, saa = 0, sbb = 0, sab = 0;
    for (long i = 0; i < n; i++) {
        double da = a[i] - ma, db = b[i] - mb;
        saa += da * da;
        sbb += db * db;
        sab += da * db;
    }
    if (!(saa > 0 && sbb > 0)) return NAN;
    return sab / sqrt(saa * sbb);
}

double calib_gain_spatial_std(double s, double tau, double npix)
{
    if (!(s > 0) || !(npix > 1) || !(tau >= 0)) return NAN;
    return sqrt((4 * s * s * tau + 2 * tau * tau) / npix) / (2 * s);
}
