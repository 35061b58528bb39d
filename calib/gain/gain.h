// calib/gain/gain.h — `refl calib gain` (EMVA 1288 style) as a library, public
// within calib/ and to the tests: the numerics, the stages of a run and
// calib_gain_run. The command (argument parsing, calib/cmd_gain.c) is
// calib_cmd_gain (calib/calib.h).
//
// A run, in order (calib/gain/gain.c): frames (calib_gain_capture on a rig,
// capture.c; calib_gain_add_session, calib_gain_read_manifest, input.c) →
// calib_gain_make_groups (one group per exposure, gain, dark/light and role)
// → calib_gain_frame_stats (each group's mean and temporal variance;
// frames.c) → per gain calib_gain_analyse (analyse.c: the dark model,
// dark.c; the sweep, sweep.c; photon transfer, ptc.c; linearity,
// linearity.c; the linearisation, linearisation.c; the response) →
// calib_gain_make_maps (offset, DSNU, PRNU of the flat field at the first
// gain, and the standard's DSNU1288/PRNU1288 of its stacks; maps.c,
// nonuniformity.c) → calib_gain_make_spatial (refl's high-pass split,
// spectrograms, profiles, spatial.c; defects, defects.c) →
// calib_gain_write_maps, calib_gain_write_defects, calib_gain_json
// (gain.json, with "emva1288"; output.c, emva.c, datasheet.c),
// calib_gain_report (plots, report.html; report.c),
// calib_gain_datasheet_html (datasheet.html; emva.c),
// calib_gain_write_descriptor (an EMVA 1288 descriptor; exchange.c). The
// photon axis (calib_gain_an_photons, photons.c) and the standard's figures
// (calib_gain_an_emva, standard.c) follow each gain's calib_gain_analyse.
// Frames also come from an EMVA 1288 descriptor (calib_gain_read_descriptor;
// its grammar descriptor.c).
// The least-squares fits the phases share: fit.c.
// Errors: false / NULL with the message kept by model_error_set
// (model_last_error), not printed: the caller prints it once. What a run is
// doing goes out as notices (model_note, model_progress, model_warning).
//
// Units: grey values in DN of the frames' pixel format, exposures in us,
// variances in DN^2, electrons e-. "mu" is always the mean grey value minus
// the mean dark grey value at the same exposure (EMVA 1288: mu_y - mu_y.dark),
// "var" the temporal variance from frame pairs, var(A - B) / 2, minus its dark
// counterpart (sigma^2_y - sigma^2_y.dark).
#pragma once

#include <jansson.h>
#include <stdbool.h>

#include "model/model.h"
#include "rig/session/session.h"

#ifdef __cplusplus
extern "C" {
#endif

// Least-squares polynomial y = c[0] + c[1] x (+ c[2] x^2) of degree 1 or 2
// through n points (n > degree). false when the system is singular.
bool calib_gain_polyfit(const double *x, const double *y, int n, int degree, double *c);
// The same with the coefficients' standard errors se[degree + 1]: the
// heteroscedasticity-consistent sandwich (HC3: each point's residual over
// 1 - its leverage), for data whose scatter differs from point to point.
// false when the fit fails or n <= degree + 1.
bool calib_gain_polyfit_se(const double *x, const double *y, int n, int degree, double *c, double *se);
// The 1-sigma of a fixed pattern's std s measured over npix pixels of an
// average whose temporal noise variance tau is left in it (and subtracted):
// sqrt((4 s^2 tau + 2 tau^2) / npix) / (2 s); NAN for s <= 0.
double calib_gain_spatial_std(double s, double tau, double npix);

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
    double system_gain_std_dn_per_e;   // K's 1-sigma: the fit's standard error (calib_gain_polyfit_se)
    double read_noise_dn;          // sqrt(var_dark - quant^2/12)
    double read_noise_e;           // read_noise_dn / K
    double saturation_capacity_e;  // saturation_dn / K
    double dynamic_range;          // saturation_capacity_e / read_noise_e
    double linearity_error_pct;    // EMVA 1288 Release 4.0, see calib_gain_linearity_r4
    double linearity_error_r3_pct; // the Release 3 figure (unweighted line), kept for comparison
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

// Linearity error as EMVA 1288 Release 4.0 defines it (section "Linearity"):
// the line mu = a0 + a1 t through the points with lo*sat <= mu <= hi*sat (lo
// 0.05, hi 0.95) that minimises the sum of the squared relative deviations,
// sum ((mu_i - (a0 + a1 t_i)) / mu_i)^2 (Release 4's weighting; Release 3 took
// the plain least-squares line); delta_i = 100 (mu_i - line_i) / line_i; LE =
// (max delta - min delta) / 2 over the fitted points. Arguments and return as
// calib_gain_linearity's.
double calib_gain_linearity_r4(const double *t, const double *mu, int n, double sat_dn, double lo, double hi,
                               double *slope, double *offset, int *nfit, double *dev_pct);

// Linearity error (EMVA 1288 release 3): a least-squares line mu = a + b t
// through the points with lo*sat <= mu <= hi*sat (lo 0.05, hi 0.95); the
// relative deviations dev_pct[i] = 100 (mu_i - line_i) / line_i; LE = (max dev
// - min dev) / 2 over the fitted points. dev_pct (may be NULL) gets n values
// (NAN outside the range). Returns LE in %, NAN when fewer than 3 points fit.
double calib_gain_linearity(const double *t, const double *mu, int n, double sat_dn, double lo, double hi,
                            double *slope, double *offset, int *nfit, double *dev_pct);

// The response linearisation from the sweep (t[n] us ascending, mu[n] DN above
// dark, sat_dn the saturation): the linear signal is anchored to the
// small-signal response, a quadratic least-squares fit mu = c0 + r t + q t^2
// over 5..70 % of saturation, L(t) = c0 + r t (*anchor_slope = r DN/us,
// *anchor_offset = c0 DN); the monotone table maps each step's mu (up to
// saturation) to L (model_lin_monotone); *a_per_dn gets the parametric
// S_m = S (1 - a S) of the same curve (calib_gain_parametric_a). false +
// message when the fit or the table fails.
bool calib_gain_linearisation(const double *t, const double *mu, int n, double sat_dn, model_lin_t *table,
                              double *a_per_dn, double *anchor_slope, double *anchor_offset);
// a (per DN) of S_m = S (1 - a S): linear least squares of S_m = u t + v - a S_m^2
// over the steps below 90 % of saturation; 0 when there are fewer than 5 or
// the curve says no compression.
double calib_gain_parametric_a(const double *t, const double *mu, int n, double sat_dn);
// The linearisation a gain.json (path, for messages) records: its
// "linearisation" (method monotone: the table; parametric: a); a version 1
// file without it: the parametric a of its reference gain's curves, else
// none. false + message (model_error, naming the file) when "linearisation"
// is malformed or missing from a version 2 file, or the file is not a
// refl-gain file this reader knows (model_json_format_check).
bool calib_gain_lin_from_json(json_t *gj, const char *path, model_lin_t *out);

// Pearson correlation of two maps of n values (NAN when one is constant).
double calib_gain_correlation(const float *a, const float *b, long n);

// Divide a map (w x h) by its least-squares smooth surface, a quadratic in x
// and y (removes vignetting and illumination fall-off, keeps the pixel,
// column and row patterns): out = in / surface (mean ~1). in == out allowed.
// false when the fit is singular.
bool calib_gain_highpass(const float *in, int w, int h, float *out);


// ---------------------------------------------------------------------------
// EMVA 1288 Release 4.0 Linear: the photon axis (photons.c), the spatial
// split and spectrograms (spatial.c), defect pixels (defects.c), the
// datasheet (emva.c). Each figure's definition with its formula is in its
// row of gain.json's "emva1288" datasheet (and README).

// Mean photons per pixel during t_us: mu_p = A E t lambda / (h c), A the
// pixel area (um^2), E the irradiance at the sensor (uW/cm^2), lambda (nm).
double calib_gain_photons(double irradiance_uw_cm2, double pixel_area_um2, double wavelength_nm, double t_us);
// The irradiance (uW/cm^2) a photodiode in the sensor's place reads: its
// current I (nA) over its responsivity R (A/W) at the wavelength and its
// area S (mm^2): E = I / (R S) = 0.1 I / (R S) uW/cm^2.
double calib_gain_photodiode_irradiance(double current_na, double responsivity_a_per_w, double area_mm2);

// ---------------------------------------------------------------------------
// EMVA 1288 Release 4.0 Linear by the standard's definitions, with the
// ranges and points of the EMVA 1288 working group's reference
// implementation (github.com/EMVA1288/emva1288): the temporal figures
// (standard.c), the spatial nonuniformity (nonuniformity.c). Sections of the
// standard: gain.json "emva1288" per row, and calib/README.md.

// The square root with the sign of v: -sqrt(-v) for a negative variance
// estimate (reported as such, not clamped); NAN for NAN.
double calib_gain_signed_sqrt(double v);

// The sweep as the standard sees it: n steps sorted by exposure (then photon
// count), each with x (the photon count mu_p per pixel when photons, else
// the exposure in us standing in for it: the irradiance is constant over the
// sweep), mu_y, sigma^2_y (the frame pair's var(A - B) / 2), mu_y.dark,
// sigma^2_y.dark (the dark pair at its exposure); the temporal darks: nd
// exposures (us, each once) with their mean and variance; quant_dn the
// quantisation step q (sigma^2_q = q^2 / 12; 1 for data at its own bit depth).
typedef struct {
    int           n;
    const double *x, *mu_y, *var_y, *mu_d, *var_d;
    bool          photons;
    int           nd;
    const double *dark_t_us, *dark_mu, *dark_var;
    double        quant_dn;
} calib_gain_emva_in_t;

// Each figure as the standard defines it (Y = mu_y - mu_y.dark, V = sigma^2_y -
// sigma^2_y.dark):
typedef struct {
    int    n;
    bool   photons;            // x is the photon count (else the exposure stands in: photon figures NAN)
    int    i_sat;              // saturation: the maximum of sigma^2_y, walking from the brightest step back
                               // until the variance falls on both sides
    bool   sat_plateau;        // the walk ended on a plateau below half the largest sigma^2_y (past a full
                               // well): the largest sigma^2_y taken instead
    double mu_y_sat_dn;        // Y at saturation
    int    i_fit_last, n_fit;  // K and R fitted over the steps 0 .. i_fit_last, the last with Y <= 0.7 Y_sat
    double K, inv_K;           // K: slope of V against Y through the origin, DN/e-
    double R;                  // slope of Y against x through the origin: DN/photon (DN/us as a stand-in)
    double qe;                 // eta = R / K (NAN without photons)
    double var_y_dark_dn2;     // sigma^2_y.dark: the shortest dark exposure's (two exposures or fewer) or the
                               // intercept at exposure 0 of the least-squares line against exposure
    int    n_dark;
    bool   dark_fitted, dark_floored;   // the line was fitted; below 0.24 q^2 it was raised to it
    double sigma_y_dark_dn;    // sqrt(max(sigma^2_y.dark, 0.24 q^2))
    double sigma_d_e;          // sqrt(sigma_y.dark^2 - q^2/12) / K
    double x_sat;              // x at saturation
    double mu_e_sat, mu_p_sat; // eta mu_p.sat = R x_sat / K; mu_p.sat = x_sat (NAN without photons)
    double mu_e_min, mu_p_min; // sigma_y.dark / K + 1/2; mu_e.min / eta
    double snr_max, dr;        // sqrt(mu_e.sat); mu_p.sat / mu_p.min = mu_e.sat / mu_e.min
    int    i_lin_first, i_lin_last;   // linearity: the first step with Y >= 0.05 Y_sat .. the last with <= 0.95
    double lin_slope, lin_offset;     // the line a x + b minimising sum ((Y - a x - b) / Y)^2 over them
    double le_min_pct, le_max_pct, le_pct;   // min, max of 100 (Y - line) / line; LE = (max - min) / 2
    double dark_current_dn_per_s, dark_current_var_dn2_per_s;   // slopes of mu_y.dark, sigma^2_y.dark against
                                                                // exposure (more than two exposures; the
                                                                // variance's NAN when negative)
    double dark_current_e_per_s, dark_current_var_e_per_s;      // / K, / K^2
} calib_gain_emva_t;

// false + message when there are fewer than 2 steps or no dark, or K or R is
// not positive.
bool calib_gain_emva(const calib_gain_emva_in_t *in, calib_gain_emva_t *out);

// The spatial variances of one averaged stack of L frames over the region's
// M rows and N columns (DN^2): mean; s2_measured the variance of the average
// (divisor MN - 1); stack_var sigma^2_y.stack, the mean over pixels of each
// pixel's temporal variance (divisor L - 1); s2 = s2_measured - stack / L;
// s2_cav, s2_rav the variances of the column means (N of them, divisor N)
// and of the row means (M, divisor M) less stack / (L M), stack / (L N);
// s2_col = (MN - M) / D s2_cav - N / D (s2 - s2_rav), s2_row = (MN - N) / D
// s2_rav - M / D (s2 - s2_cav), s2_pixel = MN / D (s2 - s2_cav - s2_rav),
// D = MN - M - N: s2_col + s2_row + s2_pixel = s2 exactly. NAN figures for
// one frame or a region of one row or column; false + message (out of memory).
typedef struct {
    int    L, M, N;
    double mean, s2_measured, stack_var, s2, s2_cav, s2_rav, s2_col, s2_row, s2_pixel;
} calib_gain_stack_var_t;
bool calib_gain_stack_variances(const double *avg, int w, int h, const int roi[4], int L, double stack_var,
                                calib_gain_stack_var_t *out);

// DSNU1288 and PRNU1288 with their parts from the dark and the light stack
// (index 0 total, 1 row, 2 column, 3 pixel): dsnu_var_dn2 the dark's s2
// (total, row, column, pixel); prnu_var_dn2 the light's less the dark's;
// dsnu_dn = signed root of dsnu_var_dn2 (DN; / K: e-), prnu_pct = 100 signed
// root of prnu_var_dn2 / (mu_y - mu_y.dark). The parts' variances add up to
// the total's.
typedef struct {
    calib_gain_stack_var_t dark, light;
    bool   same_exposure;      // the dark stack is at the light stack's exposure (as the standard has it)
    double signal_dn;          // mu_y - mu_y.dark of the stacks
    double dsnu_var_dn2[4], prnu_var_dn2[4], dsnu_dn[4], prnu_pct[4];
} calib_gain_nonuni_t;
void calib_gain_nonuniformity(calib_gain_nonuni_t *nu);

// refl's row/column/pixel split of one map (the high-pass PRNU's: w x h,
// statistics over roi x y w h), temporal_var the temporal variance left in
// it. Model y = mu + r[row] + c[col] + p + e: the variances of the row means
// Vr, column means Vc and of all values V (divisor the count), each less its
// temporal part, give s2_pixel = (V - Vr - Vc) / (1 - 1/M - 1/N) (M columns
// averaged in a row mean, N rows in a column mean), s2_row = Vr - s2_pixel /
// M, s2_col = Vc - s2_pixel / N, so that s2_row + s2_col + s2_pixel = V. The
// figures are the signed roots (calib_gain_signed_sqrt: a negative estimate
// stays negative) in the map's units times scale. false + message (out of
// memory; the figures NAN).
typedef struct {
    double total, row, col, pixel;
} calib_gain_split_t;
bool calib_gain_spatial_split(const float *img, int w, int h, const int roi[4], double temporal_var, double scale,
                              calib_gain_split_t *out);

// Spectrogram: horizontal (vertical false): the DFT Y(k) of every row of the
// roi after removing the roi's mean, s(k) = sqrt(mean over rows |Y(k)|^2 / N),
// k = 0..N/2 (N the row length; frequency k / N cycles per pixel); vertical:
// the same along the columns. White noise of std sigma gives s(k) ~ sigma.
// spec gets N/2 + 1 values times scale; returns their number (0: no memory).
int calib_gain_spectrogram(const float *img, int w, int h, const int roi[4], bool vertical, double scale,
                           double *spec);

// Defect pixels of the averaged dark (DN) and the relative light map (mean ~1,
// the high-pass flat field): deviations from the median beyond nsigma robust
// standard deviations (1.4826 MAD, at least the temporal std of the average):
// hot (dark above), dead (light below), bright (light above). map (w x h, may
// be NULL): 0 good, 1 hot, 2 dead, 3 bright (hot wins). The first
// CALIB_GAIN_MAX_DEFECT_LIST of each kind are listed (x, y). dark_quantum:
// the step between the averaged dark's values (q / frames; 0 unknown), for
// bins of whole steps.
#define CALIB_GAIN_MAX_DEFECT_LIST 64
#define CALIB_GAIN_HIST_BINS 128
typedef struct {
    int    hot, dead, bright;
    double nsigma;                                                 // the threshold in robust stds
    double dark_median_dn, dark_sigma_dn, dark_threshold_dn;      // hot: dark > median + threshold
    double light_sigma, light_threshold;                           // relative; dead/bright: |light - median| > it
    double light_median;
    int    nlist[3], list[3][CALIB_GAIN_MAX_DEFECT_LIST][2];         // hot, dead, bright: x, y
    // logarithmic histograms of the deviations from the median: dark (DN), light (%)
    double dark_lo, dark_hi, light_lo, light_hi;
    long   dark_hist[CALIB_GAIN_HIST_BINS], light_hist[CALIB_GAIN_HIST_BINS];
    int    dark_nbins, light_nbins;                                  // bins used (<= CALIB_GAIN_HIST_BINS)
} calib_gain_defects_t;
bool calib_gain_defects(const float *dark, const float *light, int w, int h, const int roi[4], double nsigma,
                        double dark_temporal_std, double light_temporal_std, double dark_quantum, unsigned char *map,
                        calib_gain_defects_t *out);

// The spatial analysis of the reference gain's flat field (calib_gain_maps_t).
typedef struct {
    calib_gain_split_t dsnu, prnu;          // the standard's (maps' nu): DN; % of mu_y - mu_y.dark (signed)
    calib_gain_split_t prnu_hp;             // refl's: % of the high-pass flat (vignetting removed)
    int     nh, nv;                          // spectrogram lengths (roi w / 2 + 1, h / 2 + 1)
    double *spec_h_dark, *spec_v_dark;       // DN
    double *spec_h_light, *spec_v_light;     // % of the mean signal
    int     pw, ph;                          // profile lengths (roi w, h)
    double *col_dark, *row_dark, *col_light, *row_light;   // means of the roi's columns / rows, DN
    calib_gain_defects_t defects;
    unsigned char *defect_map;               // whole frame, codes as calib_gain_defects
    double  signal_mean_dn;                  // roi mean of the flat minus dark
} calib_gain_spatial_t;

// ---------------------------------------------------------------------------
// A run

// Options of calib_gain_run: exactly one source of frames (rig, frames, sessions, descriptor).
typedef struct {
    const char  *rig;                // capture on this rig file, or NULL
    const char  *frames;             // a manifest "file,exposure_us,kind" (kind dark|light), or NULL
    const char  *descriptor;         // an EMVA 1288 descriptor file (its photon counts: the photon axis), or NULL
    const char  *write_descriptor;   // write an EMVA 1288 descriptor of the run's frames here (NULL: none;
                                     // several cameras: NAME inserted before the extension)
    const char *const *sessions;     // capture sessions made elsewhere (nsessions), or NULL
    int          nsessions;
    const char  *out;                // the output directory (created)
    const char  *camera;             // rig or sessions: calibrate this camera only (NULL: every camera)
    const double *gains_db;          // rig: the gains to sweep, the first the reference; frames: its one label
    int          ngains;
    const double *dark_exposures_us; // rig: the long dark exposures (dark current)
    int          ndark_exposures;
    const char  *sample, *lamps, *pixel_format;   // rig: the plan's sample, lamp set, pixel format
    int          steps;              // rig: exposure steps of each sweep (equally spaced)
    int          low_steps;          // rig: and geometric steps at the low end (calib_gain_sweep_exposures)
    int          flat_frames;        // rig: light and dark frames of the flat field
    int          progress;           // calib_capture's progress mode
    rig_operator_t *op;             // who answers the operator steps (calib_capture)
    double       probe_us;           // rig: first probe exposure
    double       max_us;             // rig: longest sweep exposure; NAN: 1.2 x the probe's full-scale estimate
    int          min_steps;          // fewest sweep steps accepted
    double       radiance;           // the source's radiance with the lamps on; NAN unknown (no kc)
    int          roi[4];             // x y w h of the statistics, px (w 0: the whole frame)
    int          max_dn;             // full scale of manifest frames, DN
    double       quant_dn;           // quantisation step, DN
    int          linearisation;      // what gain.json's consumers apply: MODEL_LIN_MONOTONE (the table,
                                     // default) or MODEL_LIN_PARAMETRIC (S_m = S (1 - a S)); both are written
    double       irradiance_uw_cm2;  // at the sensor, uW/cm^2, constant over the sweep (NAN: not measured)
    double       pixel_area_um2;     // the pixel's area, um^2 (NAN: not given)
    double       wavelength_nm;      // the light's (centre) wavelength, nm (NAN: not given)
    double       photodiode_na, photodiode_a_per_w, photodiode_mm2;   // instead of irradiance_uw_cm2: a
                                     // photodiode's reading (NAN: none), calib_gain_photodiode_irradiance
    double       defect_sigma;       // defect threshold, robust standard deviations (default 6)
    bool         report;             // the plots and report.html
    int          argc;               // the command line, for the provenance (may be 0)
    char       **argv;
} calib_gain_opts_t;

// The irradiance o gives (uW/cm^2): irradiance_uw_cm2, or the photodiode's
// reading (calib_gain_photodiode_irradiance); NAN: none.
double calib_gain_opts_irradiance(const calib_gain_opts_t *o);

// The sweep's exposures up to tmax (us): steps equally spaced (tmax/steps ..
// tmax) and low_steps geometric ones from 0.2 % to 12 % of tmax (the low end,
// where a response departs most from linear in relative terms and the
// linearisation needs its knots close), sorted (duplicates kept) into t
// (steps + low_steps values); returns their number.
int calib_gain_sweep_exposures(double tmax, int steps, int low_steps, double *t);

// Gains {0}, dark exposures 1e5, 5e5, 1e6, 2e6 us, sample flat_field, lamps
// all, Mono12, 50 steps and 16 low steps, 16 flat frames, probe 1000 us, min_steps 50, radiance
// NAN, max_dn 65535, quant_dn 1, report.
calib_gain_opts_t calib_gain_defaults(void);

// The reference gain's figures (the first of the run) of one camera.
typedef struct {
    char   camera[32];               // the camera's name ("" for a manifest's frames)
    char   dir[4096];                // where its gain.json is
    double system_gain_dn_per_e, read_noise_e, saturation_dn, linearity_error_pct, dsnu_dn, prnu_pct;
} calib_gain_result_t;

#define CALIB_GAIN_MAX_CAMERAS 8

// The whole calibration: gain.json, the maps and the report of every camera
// (o->camera NULL) or of o->camera. The sessions' frames of one camera go to
// o->out itself; of several, camera NAME's to o->out/NAME/ (gain.json, maps,
// report.html), and the first camera's gain.json and maps also to o->out (the
// layout of one camera, which a calibration set reads without a camera
// selector). r gets up to max cameras' figures (*n of them). false + message.
bool calib_gain_run(const calib_gain_opts_t *o, calib_gain_result_t *r, int max, int *n);

// ---------------------------------------------------------------------------
// Stages

// The role of a session's frames.
enum { CALIB_GAIN_SET_ANY, CALIB_GAIN_SET_SWEEP, CALIB_GAIN_SET_DARK, CALIB_GAIN_SET_FLAT };

// One frame of the input.
typedef struct {
    char  *path;          // full path
    char   sha256[65];    // expected ("" = not checked: manifest)
    char  *where;         // manifest path, or session directory
    int    line;          // manifest line (0: a session frame)
    int    step;          // session step
    double exposure_us, gain_db;
    bool   has_photons;   // photons known (an EMVA 1288 descriptor's count)
    double photons;       // mean photons per pixel during the frame (0: dark)
    bool   dark;
    int    set;           // CALIB_GAIN_SET_*
    int    max_dn;        // full scale of the frame's pixel format
    int    nlamps;        // lamps on (session frames: from the lamp set; -1 unknown)
} calib_gain_frame_t;

// A session of the run and the role of its frames (calib_gain_capture).
typedef struct {
    char *dir;
    int   set;            // CALIB_GAIN_SET_*
    const char *role;     // its provenance role (static)
} calib_gain_source_t;

// The frames of one exposure, gain, kind, role and photon count.
typedef struct {
    double exposure_us, gain_db;
    bool   has_photons;
    double photons;
    bool   dark;
    int    set;
    int   *idx;           // frames (indices into calib_gain_data_t.f)
    int    n;
    // calib_gain_frame_stats
    double mean_dn;       // spatial mean (ROI) of the frames' average
    double var_dn2;       // temporal variance var(A - B) / 2 averaged over pairs (NAN: a single frame)
    double sat_frac;      // fraction of ROI pixels at full scale (first frame)
    int    width, height;
    char  *error;
} calib_gain_group_t;

typedef struct {
    calib_gain_frame_t *f;
    int                 nf;
    calib_gain_group_t *g;
    int                 ng;
    int                 roi[4];     // x y w h (w 0: whole frame)
    char                camera[32]; // the frames' camera ("": a manifest)
    char                gain_unit[16];   // the unit of the frames' gain (GenICam's; "dB" for a manifest)
} calib_gain_data_t;

void calib_gain_data_free(calib_gain_data_t *d);
// Frames of a manifest (gain 0; max_dn their full scale). false + message (file:line).
bool calib_gain_read_manifest(const char *path, int max_dn, calib_gain_data_t *d);

// An EMVA 1288 descriptor file (descriptor.c has its grammar, the reference
// implementation's): each set of images, a bright one ("b EXPOSURE_NS
// PHOTONS") or a dark one ("d EXPOSURE_NS": photons 0), and its images.
typedef struct {
    double exposure_ns, photons;   // photons 0: dark
    int    line;                   // its b or d line
    int    first, nimages;         // its images: paths[first .. first + nimages - 1]
    bool   spatial;                // more than two images: the spatial set; two: a temporal step
} calib_gain_desc_set_t;
typedef struct {
    char   version[32];            // the "v" line's ("" none)
    int    bits, width, height, n_line;   // the "n" line's (n_line 0: none)
    calib_gain_desc_set_t *sets;
    int    nsets;
    char **paths;                  // as written, '\' turned '/' (relative to the file unless they begin with '/')
    int   *path_line;
    int    npaths;
} calib_gain_descriptor_t;
// Parse a descriptor's text (n bytes, no NUL needed; path for messages):
// false + message naming path:line when it is malformed (*d empty then).
bool calib_gain_descriptor_parse(const char *text, size_t n, const char *path, calib_gain_descriptor_t *d);
void calib_gain_descriptor_free(calib_gain_descriptor_t *d);
// Frames of a descriptor file (exposures ns -> us, gain 0, the photon
// counts; temporal sets the sweep, spatial ones the flat set; full scale 2^bits
// - 1, or max_dn without an "n" line): every image must exist and have the
// "n" line's size. false + message (file:line).
bool calib_gain_read_descriptor(const char *path, int max_dn, calib_gain_data_t *d);
// Frames of camera `camera` (NULL: the session's first) of a session; set:
// their role (CALIB_GAIN_SET_ANY: dark = no lamp on). d->camera and
// d->gain_unit are set from them (frames of another gain unit than d's
// earlier ones: an error). *facts_out (may be NULL) gets the first session's
// facts (a reference).
bool calib_gain_add_session(calib_gain_data_t *d, const char *dir, const char *camera, int set,
                            json_t **facts_out);
// Capture on o->rig: per gain a probe and a sweep, then at the first gain the
// flat field and long darks, into o->out; the sessions into *src (*nsrc; free
// with calib_gain_sources_free) and prov. With several cameras the sweep's
// exposures are the union of each camera's (each reaching 1.2 x its own
// full-scale estimate) and the flat field is near 50 % of full scale for the
// most sensitive. false + message.
bool calib_gain_capture(const calib_gain_opts_t *o, json_t *prov, calib_gain_source_t **src, int *nsrc);
void calib_gain_sources_free(calib_gain_source_t *src, int n);
// Group the frames (exposure, gain, dark, role). false + message (out of memory).
bool calib_gain_make_groups(calib_gain_data_t *d);
// Every group's mean and temporal variance (reads every frame, in threads).
bool calib_gain_frame_stats(calib_gain_data_t *d);

// The analysis of one gain (arrays of n sweep steps, sorted by exposure).
typedef struct {
    double gain_db;
    int    n;
    double *t, *mu_y, *var_y, *mu_d, *var_d, *mu, *var, *dev_pct, *snr;   // us, DN, DN^2, %, 1
    calib_gain_ptc_t ptc;
    double var_dark_dn2;        // sigma^2_y.dark (intercept at exposure 0)
    double dark_slope_dn_per_us, dark_intercept_dn;
    double dark_t_min_us, dark_t_max_us;
    int    ndark;               // dark exposures used for the dark current
    double *dark_t_us;          // their exposures (us; ndark, in the groups' order)
    double radiance;            // total radiance of the light frames, as given (NAN unknown)
    double kc_per_us;           // response / radiance
    double response0_dn_per_us; // small-signal response: slope at 0 of a quadratic in exposure (0..70 % of sat)
    double kc0_per_us;          // response0 / radiance
    // the response linearisation (calib_gain_linearisation)
    model_lin_t lin;            // the monotone table (n 0: none could be made)
    double lin_a_per_dn;        // the parametric a of the same curve
    double lin_anchor_dn_per_us, lin_anchor_offset_dn;
    double le_linearised_pct;   // Release 4.0 LE of the linearised signal (the table's own check)
    double le_linearised_param_pct;   // the same through S(1 - aS)
    double dark_var_slope_dn2_per_us; // slope of sigma^2_y.dark against exposure (NAN: not fitted)
    double var_dark_std_dn2;          // var_dark_dn2's 1-sigma (its fit's standard error)
    double dark_slope_std_dn_per_us;  // dark_slope_dn_per_us's 1-sigma (NAN: not fitted)
    double read_noise_std_e;          // read noise's 1-sigma (var_dark's and K's)
    double dark_current_std_e_per_s;  // dark current's 1-sigma (the slope's and K's)
    int    n_dark_modelled;           // sweep steps without a dark pair at their exposure (the dark model's)
    double *mu_p;                     // photons per pixel of each step (NAN: not measured)
    const char *photon_source;        // of mu_p: "irradiance", "photodiode", "descriptor"; NULL: not measured
    calib_gain_emva_t emva;           // the standard's figures (calib_gain_an_emva)
    double snr_exact_mu_e_min;        // refl's: the exact SNR = 1 root 1/2 + sqrt(sigma^2_y.dark / K^2 + 1/4), e-
} calib_gain_an_t;

void calib_gain_an_free(calib_gain_an_t *a);
// Dark model, photon transfer, linearity and small-signal response of gain_db.
bool calib_gain_analyse(calib_gain_data_t *d, double gain_db, int min_steps, double quant_dn, calib_gain_an_t *a);

// The maps of the reference gain (w x h floats each).
typedef struct {
    int     w, h;
    float  *offset, *dsnu, *prnu, *prnu_hp;   // DN, DN, 1 (mean 1), 1 (mean ~1)
    double  flat_exposure_us, flat_level_dn, flat_sat_frac;
    int     flat_frames, dark_frames;
    double  dark_exposure_us;
    double  dsnu_dn, dsnu_total_raw_dn;
    double  prnu_pct, prnu_total_pct;
    double  flat_var_dn2, dark_var_dn2;
    bool    dark_same_exposure;
    double  prnu_mean_dn;            // the flat minus dark's whole-frame mean (prnu * it: the signal, DN)
    double  signal_temporal_var_dn2; // temporal variance left in the averaged signal
    double  dsnu_std_dn, prnu_std_pct;   // their 1-sigma (PRNU's: the two parts in quadrature)
    double  prnu_std_stat_pct;       // PRNU's statistical part (calib_gain_spatial_std)
    double  prnu_std_lin_pct;        // its linearisation part: prnu_pct x |flat_log_slope /
                                     // flat_log_slope_parametric - 1| (0 without a monotone table)
    double  flat_log_slope, flat_log_slope_parametric;   // d ln S / d ln S_m at the flat's level (0: none)
    double  flat_pixel_std_rel;      // the flat map's temporal noise per pixel, relative to its mean
    bool    flat_linearised;         // the flat's signal went through the response linearisation
    int     flat_group, dark_group;  // the groups of the flat and its dark (indices into d->g)
    calib_gain_nonuni_t nu;          // the standard's DSNU1288 and PRNU1288 of the two stacks (raw, not
                                     // linearised)
    calib_gain_spatial_t sp;         // calib_gain_make_spatial
} calib_gain_maps_t;

void calib_gain_maps_free(calib_gain_maps_t *m);
// The flat field (and its dark) of a's gain → offset, DSNU and PRNU maps.
// false + message when the flat is missing, saturated or too dark.
bool calib_gain_make_maps(calib_gain_data_t *d, const calib_gain_an_t *a, calib_gain_maps_t *m);
// DIR/offset_dn.tiff, dsnu_dn.tiff, prnu_gain.tiff, prnu_highpass.tiff.
bool calib_gain_write_maps(const char *dir, const calib_gain_maps_t *m);
// The EMVA 1288 spatial analysis of m's averaged dark and flat (m->sp): the
// row/column/pixel split, spectrograms, profiles, defects (nsigma) over d's
// roi. false + message (no memory).
bool calib_gain_make_spatial(const calib_gain_data_t *d, calib_gain_maps_t *m, double nsigma, double quant_dn);
// The photon axis of a: a->mu_p from the sweep's photon counts (a
// descriptor's) or o's irradiance, pixel area and wavelength, and
// a->photon_source (NULL: not measured). false + message (out of memory;
// the descriptor's counts with an irradiance too).
bool calib_gain_an_photons(const calib_gain_opts_t *o, calib_gain_an_t *a);
// The standard's figures of a (calib_gain_emva): its sweep, its x the photon
// counts when measured, and the temporal darks of its gain (the dark pairs
// of the sweep and of the dark set, one per exposure, the most frames). false
// + message.
bool calib_gain_an_emva(const calib_gain_data_t *d, double quant_dn, calib_gain_an_t *a);
// A group's frames (all w x h) averaged into avg (w x h doubles) with the
// mean over d's region of each pixel's temporal variance (divisor L - 1;
// NAN for one frame) into *stack_var. false + message.
bool calib_gain_stack_average(const calib_gain_data_t *d, const calib_gain_group_t *g, int w, int h, double *avg,
                              double *stack_var);
// gain.json's "emva1288": the datasheet rows, definitions, the spatial
// analysis and its curves (an[0] the reference gain).
json_t *calib_gain_emva_json(const calib_gain_opts_t *o, const calib_gain_an_t *an, const calib_gain_maps_t *m);
// An EMVA 1288 descriptor of d's frames at a's gain, the standard's data
// exchange: every sweep step with a dark pair at its exposure (its first two
// light and dark frames), then the spatial set (the flat and its dark of m,
// when both have more than two frames at one exposure); paths relative to
// the file's directory; photons from the frames' counts or o's irradiance,
// pixel area and wavelength (an error without). false + message.
bool calib_gain_write_descriptor(const char *path, const calib_gain_opts_t *o, const calib_gain_data_t *d,
                                 const calib_gain_an_t *a, const calib_gain_maps_t *m);
// DIR/defects.tiff (codes 0 good, 1 hot, 2 dead, 3 bright) and DIR/datasheet.html.
bool calib_gain_write_defects(const char *dir, const calib_gain_maps_t *m);
bool calib_gain_datasheet_html(const char *dir, json_t *emva, json_t *prov);
// gain.json names its format, "refl-gain", and version (model_json_set_format):
//   version 1  every gain.json that names no format. Of its keys these may be
//              absent: camera, gain_db and gain_unit (readers take 0 dB),
//              linearisation (readers take the parametric a of the reference
//              gain's curves), flat_field.pixel_std_rel and .linearised, std
//              and std_method (no stated 1-sigmas), dark_exposures_us.
//   version 2  names itself; always has gain_db, gain_unit, linearisation,
//              flat_field.pixel_std_rel and .linearised, std, std_method and
//              dark_exposures_us (null where a figure is unknown).
//   version 3  the same top level; "emva1288" by the standard's definitions:
//              its "datasheet" rows name their "section" of the standard
//              (a negative variance estimate a negative value with
//              "negative_estimate"), refl's own figures in "refl_rows", the
//              spatial block the standard's variances ("variances_dn2") and
//              the temporal block its fit ranges ("photon_transfer"); every
//              gain's "emva1288" figures. Readers of the top level read all
//              three versions alike.
#define CALIB_GAIN_FORMAT         "refl-gain"
#define CALIB_GAIN_FORMAT_VERSION 3
// gain.json's document (new reference): an[0] the reference gain, then every gain.
json_t *calib_gain_json(const calib_gain_opts_t *o, const calib_gain_data_t *d, const calib_gain_an_t *an, int ngains,
                        const calib_gain_maps_t *maps, json_t *prov);
// The plots (scripts/calib_gain_report.py) and DIR/report.html.
bool calib_gain_report(const char *dir, const calib_gain_an_t *an, int ngains, const calib_gain_maps_t *maps,
                       json_t *prov);

#ifdef __cplusplus
}
#endif
