// calib/gain.h — the numerics of `refl calib gain` (EMVA 1288 style), public
// within calib/ and to the tests. The command itself is calib_cmd_gain
// (calib/calib.h).
//
// Units: grey values in DN of the frames' pixel format, exposures in us,
// variances in DN^2, electrons e-. "mu" is always the mean grey value minus
// the mean dark grey value at the same exposure (EMVA 1288: mu_y - mu_y.dark),
// "var" the temporal variance from frame pairs, var(A - B) / 2, minus its dark
// counterpart (sigma^2_y - sigma^2_y.dark).
#pragma once

#include <stdbool.h>

#ifdef __cplusplus
extern "C" {
#endif

// Least-squares polynomial y = c[0] + c[1] x (+ c[2] x^2) of degree 1 or 2
// through n points (n > degree). false when the system is singular.
bool calib_gain_polyfit(const double *x, const double *y, int n, int degree, double *c);

// Photon transfer of one gain setting, from n exposure steps sorted by
// exposure. In: exposure_us[n], mu[n], var[n] (dark-subtracted, see above),
// var_dark_dn2 (sigma^2_y.dark at short exposure), quant_dn (the quantisation
// step, 1 for data at the sensor's own bit depth). Out: the figures below.
typedef struct {
    int    i_sat;                  // index of the variance maximum (the saturation point)
    double saturation_dn;          // mu at the variance maximum (above dark)
    double system_gain_dn_per_e;   // K: slope at mu -> 0 of a quadratic fit var(mu) over 0..70 % of saturation
    double system_gain_linear_dn_per_e;   // EMVA 1288's straight-line fit over the same range (biased low
                                          // by a compressive non-linearity)
    int    n_ptc_fit;              // points in the K fit
    double read_noise_dn;          // sqrt(var_dark - quant^2/12)
    double read_noise_e;           // read_noise_dn / K
    double saturation_capacity_e;  // saturation_dn / K
    double dynamic_range;          // saturation_capacity_e / read_noise_e
    double linearity_error_pct;    // see calib_gain_linearity
    double response_dn_per_us;     // slope of the linearity line
    double response_offset_dn;     // its intercept
    int    n_lin_fit;
    double snr_max;                // max of mu / sqrt(var_y) below saturation (var_y incl. dark)
} calib_gain_ptc_t;

// false (message set) when there are fewer than 6 points, the variance has no
// maximum followed by a drop (the sweep does not reach saturation), or a fit
// fails. var_y (not dark-subtracted) is used for the SNR; may be NULL (then var).
bool calib_gain_ptc(const double *exposure_us, const double *mu, const double *var, const double *var_y, int n,
                    double var_dark_dn2, double quant_dn, calib_gain_ptc_t *out);

// Linearity error (EMVA 1288 release 3): a least-squares line mu = a + b t
// through the points with lo*sat <= mu <= hi*sat (lo 0.05, hi 0.95); the
// relative deviations dev_pct[i] = 100 (mu_i - line_i) / line_i; LE = (max dev
// - min dev) / 2 over the fitted points. dev_pct (may be NULL) gets n values
// (NAN outside the range). Returns LE in %, NAN when fewer than 3 points fit.
double calib_gain_linearity(const double *t, const double *mu, int n, double sat_dn, double lo, double hi,
                            double *slope, double *offset, int *nfit, double *dev_pct);

// Pearson correlation of two maps of n values (NAN when one is constant).
double calib_gain_correlation(const float *a, const float *b, long n);

// Divide a map (w x h) by its least-squares smooth surface, a quadratic in x
// and y (removes vignetting and illumination fall-off, keeps the pixel,
// column and row patterns): out = in / surface (mean ~1). in == out allowed.
// false when the fit is singular.
bool calib_gain_highpass(const float *in, int w, int h, float *out);

#ifdef __cplusplus
}
#endif
