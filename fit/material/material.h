// fit/material/material.h — the material fit: from calibrated observations of a
// material (calib_observe, calib/calib.h) to BRDF samples, fitted models and
// priors.
//
//   fit_material_opts_t o = fit_material_defaults();
//   o.session = "sessions/glossy"; o.calib = "calib"; o.scene = "samples/coupon.d3d"; o.out = "priors.json";
//   fit_material_result_t r;
//   bool ok = fit_material_run(&o, &r);   // false: model_last_error(); r holds what was done
//   ...
//   fit_material_result_free(&r);
#pragma once

#include <jansson.h>
#include <stdbool.h>

#include "calib/calib.h"
#include "fit/brdf/brdf.h"
#include "model/model.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef struct {
    const char *session;    // capture session directory of the sample
    const char *calib;      // calibration directory (calib_set_load; white.json required)
    const char *camera;     // one camera of a session of several (NULL: every camera of the session, each
                            // through its own calibrations, calib_set_load_camera; one camera: calib_set_load)
    const char *scene;      // the sample's scene (a session records none; NULL is an error)
    const char *material;   // its material in the scene; NULL: the scene's only one
    double      scene_unit_mm;  // mm per unit of the scene file (0: mm, not said; --units)
    const char *model;      // "all" (default) or one model's name (fit_brdf_model_list)
    const char *name;       // the material's name in the priors; NULL: the observed material's
    const char *out;        // the priors file (JSON) to write; its directory is made
    const char *report;     // a directory for the HTML report; NULL: none
    double      k_sigma;    // prior bounds mean +- k_sigma std (default 3)
    double      sys_rel;    // systematic std relative to the mean (default 0.03)
    double      lamp_rel;   // each lamp's own photometric scale (kc*I, emission pattern, position): relative std
                            // carried through the fit into the parameters' std (default 0.03; 0: none)
    double      place_mm;   // places on the sample for the cluster-robust covariance, cells of place_mm mm of its
                            // surface at angle 0 (0, the default: a sixth of the observed points' largest extent)
    double      cell_mm;    // albedo cells of cell_mm mm (0: none)
    int         cv_folds;   // model choice by cross-validation over the frames, folds (default 5; 0: BIC)
    uint64_t    cv_seed;    // the folds' shuffle (default 1)
    int         window;     // observation windows, pixels (0: calib_observe's default)
    int         step;       // their grid step, pixels (0: the default)
    bool        pose_nominal;   // the plan's nominal wedge pose; false (default): the sample's pose fitted
                                // from its frames (calib_sample_pose_fit), the nominal its prior
    double      pose_sigma_deg, pose_sigma_mm;   // that prior's std (defaults 1 deg, 2 mm)
    bool        noise_weights;  // each sample weighted by 1/sigma^2 of its noise (default true; needs a gain
                                // calibration, else uniform)
    lsq_loss_t  loss;       // robust loss (fit_brdf_options_t; default LSQ_LOSS_NONE)
    double      loss_scale; // its scale in units of each sample's sigma (default 2)
    bool        verbose;    // calib_observe prints each angle on stderr
    int         argc;       // the command line for the provenance (argv[0] "refl"; may be 0)
    char      **argv;
} fit_material_opts_t;

fit_material_opts_t fit_material_defaults(void);

typedef struct {
    // the observations and samples (observed: they were made)
    bool              observed;
    char              sample[64], material[64];
    int               nobs, nsamples, frames_used, frames_skipped;
    int               ncameras;         // the cameras whose frames were observed, and each one's observations
    char              cameras[8][32];
    int               nobs_camera[8];
    // with a gain calibration: the residual RMS its temporal noise alone gives (1/sr; NAN without one)
    // and the response linearisation applied (the gain calibration's)
    bool              have_gain;
    double            noise_rms;
    model_lin_t       lin;
    bool              noise_weighted;   // the samples are weighted by their noise (fit_samples_t)
    // every model fitted to the samples as they are (first.ntried > 0: tried)
    fit_brdf_models_t first;
    // albedo cells (opts cell_mm > 0; cells_done: fitted): the factors' spread, then
    // every model fitted again to the corrected samples (models)
    bool              cells_done;
    int               n_cells, n_obs_in_cells, cell_iterations;
    double            cells_rel_std;
    model_brdf_t      cells_model;      // the model the factors were fitted with
    fit_brdf_models_t models;           // the final fits (a copy of first without cells)
    double            rms_over_noise;   // noise-weighted: sqrt(chi^2 / dof); else the residual per degree of
                                        // freedom over noise_rms (NAN: unknown)
    // the chosen model's covariance from what its samples share (fit_brdf_shared_covariance): clusters of
    // frames and places used (0: that way not used), the place cells' size (mm); false: the chi^2-scaled one kept
    bool              shared_done;
    int               clusters_frame, clusters_place;
    double            place_mm;
    double            window_rel_std;   // a window's R about the final model beyond its temporal noise, relative
                                        // (texture from place to place and what the model lacks; NAN: unknown;
                                        // fit_material_window_spread)
    int               window_rel_n;     // the samples it is from
    bool              written;          // the priors file is written (its material: o->name, else material[])
    calib_sample_pose_t pose;           // the sample's pose used (the first camera's; README "refl fit material")
} fit_material_result_t;

// The parameters' uncertainty (README "refl fit material"): the chosen
// model's statistical covariance is cluster-robust over the frames (a
// camera's turntable step: its exposure, lamp and pose shared) and the places
// on the sample (cells of o->place_mm), and each lamp of each camera adds its
// photometric scale's relative std o->lamp_rel through the fit
// (fit_brdf_shared_covariance); the priors' std adds the shared o->sys_rel.
// The material fit (`refl fit material`): observations of o->session through
// the calibrations of o->calib (calib_observe_session; of several cameras:
// every camera's, each through its own camera model, gain and white, in one
// fit), BRDF samples R = s d^2 / kcI (1/sr, kcI of the observation's
// camera), every model of o->model fitted (and, with albedo cells, again
// with the cells' factors), the model chosen by cross-validation over the
// frames (fit_brdf_models; o->cv_folds 0: the lowest BIC), the priors file
// o->out written with its entry (fit_priors_material, with "model_choice")
// and the provenance, and with o->report
// the report (samples.csv, plots by scripts/fit_material_report.py,
// report.html). false + message (model_last_error(), not printed: the caller
// reports it); *r holds what was done up to the failure either way.
// The spread of the samples' R about the model m(p), relative to it, beyond
// each sample's temporal noise (sigma_R = 1/sqrt(w) when noise-weighted, else
// noise_rms): over the samples whose model R is at least 10 % of the largest,
// e = R / R_model - 1 and u = sigma_R / R_model; rel^2 = (1.4826 MAD(e))^2 -
// median(u^2), at least 0. The samples as observed (no albedo factors): what
// a verification window of the material differs from the model by. NAN when
// fewer than 20 samples qualify; *n: their number (-1 and NAN: out of memory,
// the message in model_last_error()).
double fit_material_window_spread(const fit_samples_t *smp, model_brdf_t m, const double *p, double noise_rms,
                                  int *n);

bool fit_material_run(const fit_material_opts_t *o, fit_material_result_t *r);
void fit_material_result_free(fit_material_result_t *r);

// `refl fit material` (fit/cmd_fit.c).
int fit_cmd_material(int argc, char **argv);

#ifdef __cplusplus
}
#endif
