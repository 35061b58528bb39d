// calib/gain.h — `refl calib gain` (EMVA 1288 style) as a library, public
// within calib/ and to the tests: the numerics, the stages of a run and
// calib_gain_run. The command (argument parsing, calib/cmd_gain.c) is
// calib_cmd_gain (calib/calib.h).
//
// A run, in order: frames (calib_gain_capture on a rig, calib_gain_add_session,
// calib_gain_read_manifest) → calib_gain_make_groups (one group per exposure,
// gain, dark/light and role) → calib_gain_frame_stats (each group's mean and
// temporal variance) → per gain calib_gain_analyse (dark model, photon
// transfer, linearity, response) → calib_gain_make_maps (offset, DSNU, PRNU
// of the flat field at the first gain) → calib_gain_write_maps,
// calib_gain_json (gain.json), calib_gain_report (plots, report.html).
// Errors: false / NULL with the message kept by model_error_set
// (model_last_error), not printed: the caller prints it once. Progress lines
// go to stderr ("refl calib gain: ...").
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
#include "rig/session.h"

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
// "linearisation" (method monotone: the table; parametric: a), else (files
// from before it) the parametric a of its reference gain's curves, else none.
// false + message (model_error, naming the file) when "linearisation" is malformed.
bool calib_gain_lin_from_json(json_t *gj, const char *path, model_lin_t *out);

// Pearson correlation of two maps of n values (NAN when one is constant).
double calib_gain_correlation(const float *a, const float *b, long n);

// Divide a map (w x h) by its least-squares smooth surface, a quadratic in x
// and y (removes vignetting and illumination fall-off, keeps the pixel,
// column and row patterns): out = in / surface (mean ~1). in == out allowed.
// false when the fit is singular.
bool calib_gain_highpass(const float *in, int w, int h, float *out);


// ---------------------------------------------------------------------------
// A run

// Options of calib_gain_run: exactly one source of frames (rig, frames, sessions).
typedef struct {
    const char  *rig;                // capture on this rig file, or NULL
    const char  *frames;             // a manifest "file,exposure_us,kind" (kind dark|light), or NULL
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
    bool         report;             // the plots and report.html
    int          argc;               // the command line, for the provenance (may be 0)
    char       **argv;
} calib_gain_opts_t;

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

// The frames of one exposure, gain, kind and role.
typedef struct {
    double exposure_us, gain_db;
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
// Group the frames (exposure, gain, dark, role).
void calib_gain_make_groups(calib_gain_data_t *d);
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
    double radiance;            // total radiance of the light frames (NAN unknown)
    double radiance_truth;      // the virtual rig's truth of it, for comparison (NAN unknown)
    double kc_per_us;           // response / radiance
    double response0_dn_per_us; // small-signal response: slope at 0 of a quadratic in exposure (0..70 % of sat)
    double kc0_per_us;          // response0 / radiance
    // the response linearisation (calib_gain_linearisation)
    model_lin_t lin;            // the monotone table (n 0: none could be made)
    double lin_a_per_dn;        // the parametric a of the same curve
    double lin_anchor_dn_per_us, lin_anchor_offset_dn;
    double le_linearised_pct;   // Release 4.0 LE of the linearised signal (the table's own check)
    double le_linearised_param_pct;   // the same through S(1 - aS)
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
} calib_gain_maps_t;

void calib_gain_maps_free(calib_gain_maps_t *m);
// The flat field (and its dark) of a's gain → offset, DSNU and PRNU maps.
// false + message when the flat is missing, saturated or too dark.
bool calib_gain_make_maps(calib_gain_data_t *d, const calib_gain_an_t *a, calib_gain_maps_t *m);
// DIR/offset_dn.tiff, dsnu_dn.tiff, prnu_gain.tiff, prnu_highpass.tiff.
bool calib_gain_write_maps(const char *dir, const calib_gain_maps_t *m);
// The radiance per lamp of the sample of a virtual rig's session facts
// (virtual_rig.truth, .sample), for the comparison with the truth only: false
// when there is none. *truth_path (may be NULL) points into facts.
bool calib_gain_truth_radiance(json_t *facts, const char **truth_path, double *radiance_per_lamp);
// gain.json's document (new reference): an[0] the reference gain, then every gain.
json_t *calib_gain_json(const calib_gain_opts_t *o, const calib_gain_data_t *d, const calib_gain_an_t *an, int ngains,
                        const calib_gain_maps_t *maps, const char *truth, json_t *prov);
// The plots (scripts/calib_gain_report.py) and DIR/report.html.
bool calib_gain_report(const char *dir, const calib_gain_an_t *an, int ngains, const calib_gain_maps_t *maps,
                       json_t *prov);

#ifdef __cplusplus
}
#endif
