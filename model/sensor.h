// model/sensor.h — the sensor stage: from the ideal grey value to what a
// camera delivers; dark measurands, gain factors, the response linearisation
//
// Part of model/model.h, whose conventions (units, frames, pixel coordinates,
// errors, model_*_free(NULL)) apply here.
#pragma once

#include <stdbool.h>

#include "model/config.h"

#ifdef __cplusplus
extern "C" {
#endif

// ---------------------------------------------------------------------------
// Sensor stage (model/sensor.c): from the ideal grey value (DN, as the imaging
// model gives it) to what a camera delivers. Separate from the physics.
//   e = (P - dark_offset) / K * prnu(x,y) * vignetting(x,y) + dark current
//   -> Poisson shot noise, Gaussian read noise -> non-linearity near full well
//   -> * K + dark_offset + dsnu(x,y) -> quantised to `bits`, clipped to [0, 2^bits-1].

// Fixed patterns of the sensor (ground truth): prnu gain map (mean 1) and dsnu
// offset map (DN, mean 0). Either may be NULL.
void model_sensor_patterns(const model_sensor_t *s, int width, int height,
                           float *prnu_gain, float *dsnu_dn);
// Apply to an image in place (width*height floats). Output values are integers
// in [0, 2^bits - 1], stored as float.
void model_sensor_apply(const model_sensor_t *s, int width, int height, float *img);
// The same with fixed patterns made once by model_sensor_patterns (for many
// frames of one sensor; NULL = flat), so a frame costs only its noise.
void model_sensor_apply_patterns(const model_sensor_t *s, int width, int height, const float *prnu_gain,
                                 const float *dsnu_dn, float *img);
// The noise-free mean response: the same chain without shot noise, read noise
// and rounding (non-linearity, patterns, offset and clipping to the range of
// `bits` kept). Values stay fractional.
void model_sensor_mean(const model_sensor_t *s, int width, int height, const float *prnu_gain,
                       const float *dsnu_dn, float *img);

// What a measurement to EMVA 1288's definitions reads from this sensor's dark
// frames (model/sensor.c): read_noise_e, the temporal dark noise at exposure 0
// (sigma_y.dark / K without the rounding's q^2/12: the read noise through the
// response's low end, plus the row noise), and dark_current_e_per_s, the
// least-squares slope of the mean dark level against exposure over the nt
// exposures t_us (us), divided by K (e-/s; hot pixels included, through the
// same response). Both the sensor's own read_noise_e and dark_current_e_per_s
// when its response is linear near 0 and it has neither row noise nor hot
// pixels. Either output may be NULL (the exposures are needed only for the
// dark current); false + message when K or the full well is not positive or
// the exposures are fewer than 2 different ones >= 0. Exact sums over the
// Poisson dark electrons and a quadrature over the read noise (no draws).
bool model_sensor_dark_measurand(const model_sensor_t *s, const double *t_us, int nt, double *read_noise_e,
                                 double *dark_current_e_per_s);

// A camera's gain as a signal factor (model/sensor.c), the one conversion of a
// recorded gain. unit is the camera's own (GenICam <Unit> of its Gain feature,
// recorded with every frame): "dB" -> 10^(gain/20); "x", "times", "linear" or
// "factor" -> gain itself; NULL or "" -> dB (a frame recorded without a unit:
// its gain is GenICam's Gain, in dB). Any other unit
// ("raw", a vendor's) has no known scale: such a frame is usable only at the
// gain its calibration was made at (cal_gain, cal_unit), and its factor is then
// that of the calibration. *factor is relative to the calibration's gain (for
// a calibration at 0 dB, the plain factor). false (model_error_set naming
// `what`, e.g. the frame, its gain and unit) when the gain cannot be converted.
bool model_gain_factor(double gain, const char *unit, double cal_gain, const char *cal_unit, const char *what,
                       double *factor);

// The sensor's response linearisation (model/sensor.c): a measured signal
// above dark S_m (DN) -> the linear signal S (DN), as the gain calibration
// (calib/gain/gain.c, gain.json "linearisation") measured it at its gain. The one
// function every consumer applies (calibrated observations, the white, the
// material fit, verification) is model_linearise.
//   MODEL_LIN_NONE        S = S_m
//   MODEL_LIN_PARAMETRIC  S_m = S (1 - a S) (a per DN; a gain.json without a
//                         "linearisation" table, or refl calib gain
//                         --linearisation parametric)
//   MODEL_LIN_MONOTONE    a monotone piecewise-cubic Hermite interpolant
//                         (Fritsch & Carlson, SIAM J. Numer. Anal. 17, 1980;
//                         knot derivatives by Fritsch & Butland's weighted
//                         harmonic mean, SIAM J. Sci. Stat. Comput. 5, 1984)
//                         through knots (m[k], s[k]), m and s strictly
//                         increasing from (0, 0); linear beyond the last knot
//                         (slope d[n-1]) and below 0 (slope d[0]).
#define MODEL_LIN_MAX 256
enum { MODEL_LIN_NONE, MODEL_LIN_PARAMETRIC, MODEL_LIN_MONOTONE };
typedef struct {
    int    kind;                 // MODEL_LIN_*
    double a_per_dn;             // PARAMETRIC: a at the calibration's gain
    int    n;                    // MONOTONE: knots (2..MODEL_LIN_MAX)
    double m[MODEL_LIN_MAX];     // measured DN above dark
    double s[MODEL_LIN_MAX];     // linear DN
    double d[MODEL_LIN_MAX];     // dS/dS_m at the knots
} model_lin_t;

// The linear signal of s_m (DN above dark) at gain factor gf relative to the
// calibration's (the response is the sensor's: S = gf T(s_m / gf)); *slope
// (may be NULL) gets dS/dS_m (for the noise). L NULL: S = s_m.
double model_linearise(const model_lin_t *L, double s_m, double gf, double *slope);
// The monotone table through points (m[i], s[i]), i = 0..n-1, s strictly
// increasing (the order of exposure): m is first made non-decreasing by
// isotonic regression (pool-adjacent-violators), points of equal m pooled,
// points at m <= 0 dropped, a point nearer the one before than min(20 % of
// its level, half the median spacing) pooled with it (close knots would make
// the slopes follow the noise), (0, 0) put first, and more than MODEL_LIN_MAX
// knots thinned evenly. false (message set) when fewer than 2 knots remain or
// a value is not finite.
bool model_lin_monotone(const double *m, const double *s, int n, model_lin_t *out);
// The table through knots as they are (a table written by model_lin_monotone,
// read back): 2..MODEL_LIN_MAX knots, m and s finite and strictly increasing.
// false (message set) otherwise.
bool model_lin_knots(const double *m, const double *s, int n, model_lin_t *out);

#ifdef __cplusplus
}
#endif
