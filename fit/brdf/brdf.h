// fit/brdf/brdf.h — fitting reflection models to BRDF samples and choosing among them.
//
// Samples: R = f_r * cos(theta_i) (1/sr; what model_brdf_eval returns) with
// the four cosines (n.l, n.v, n.h, v.h) of their geometry, and a weight.
// The fit minimises sum_k w_k (R_model,k - R_k)^2 (the cosine-weighted
// error of Ngan et al. 2005 in R) with the models' physical bounds; the
// covariance is scaled by the residual variance s^2 = RSS / (N - free).
// Where the samples never come near grazing (the Schlick F changes < 5 %
// over them), or the free fit's std of F0 is no smaller than what follows,
// only ks*F0 is measured: F0 is then only known to lie in [ks*F0 / ks_max, 1],
// and is held (fixed[], f0_unmeasured) at that interval's middle with a
// uniform's std, ks = ks*F0 / F0, the covariance spread along ks*F0 = const.
// Samples lit by finite lamps may carry their lamp's disc (fit_samples_t).
//
// BRDF sample files (refl fit brdf; fit/brdf/samples.c), told apart by content:
//   CSV: theta_i,phi_i,theta_o,phi_o,f_r[,weight] per line, angles in degrees
//        (theta from the normal, phi about it), f_r in 1/sr (negative values
//        are measurements, kept; NaN and inf refused with file:line); an
//        optional header line (not starting with a number); lines starting
//        with '#' and blank lines are comments. Errors name file and line.
//   MERL binary (Matusik et al. 2003): int32 dims 90 90 180 (theta_h, theta_d,
//        phi_d), then 3 x 1458000 little-endian doubles (R, G, B), scaled by
//        1/1500, 1.15/1500, 1.66/1500; negative values are missing samples.
//        refl fits the luminance Y = 0.2126 R + 0.7152 G + 0.0722 B (or one
//        channel) at the centre of each bin (theta_h = ((i + 0.5)/90)^2 * 90 deg).
//   RGL .bsdf (Dupuy & Jakob 2018; model/brdf/rgl.c): the measured incident
//        directions, each with a 32 x 64 grid of outgoing directions of equal
//        solid angle, f_r = the evaluation / cos(theta_o).
//   Any other binary file is refused.
// Weights (fit_read_opts_t.weights) multiply the squared residuals, scaled to
// mean 1: solid-angle (default) the measure each sample stands for in
// (omega_i, omega_o), sr^2 (MERL: its cell's, RGL: its grid's, CSV: the
// rings of equal theta of fit_solid_angles for grids, else the k-nearest-
// neighbour estimate of fit_solid_angles_knn); uniform 1; column the CSV's.
#pragma once

#include <jansson.h>
#include <stdbool.h>
#include <stdint.h>

#include "model/base/lsq.h"
#include "model/model.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef struct {
    int              n, cap;
    model_cosines_t *c;
    double          *R;        // f_r * n.l, 1/sr
    double          *w;        // weights (1 unless given)
    // Finite lamps (optional, NULL when no sample has one): a sample lit by a
    // lamp of angular radius r is modelled as the mean of R over 4 lamp
    // directions at r/sqrt(2) from the centre's (a quadrature of the uniform
    // disc exact to its 2nd and the axes' 4th moments): disc_at[i] >= 0 is the
    // first of sample i's 4 cosines in disc, -1 a point lamp (c[i] alone).
    int             *disc_at;
    model_cosines_t *disc;
    int              ndisc, disc_cap, disc_alloc;   // cosines in disc; disc_at's and disc's capacities
    char             source[512];
    char             sha256[65];
    double           omega_sr2;    // solid-angle weights: their sum before scaling to mean 1, sr^2 (else 0)
    const char      *omega_how;    // and how: "cells" (MERL), "nodes" (RGL), "rings", "k-nearest" (CSV); else NULL
    int              n_negative;   // samples with f_r < 0 (kept: measurements within noise)
    // A tabulated file sampled at its own nodes (RGL): the nodes of the slices
    // read, those used (w_o above the surface, density positive), and the
    // largest f_r read (1/sr); 0 for other sources.
    int              nodes_total, nodes_used;
    double           fr_max;
    // Weighted by each sample's noise: w = 1 / sigma_R^2 (sigma_R its std of R,
    // 1/sr; refl fit material from the gain calibration), so the weighted
    // residuals are in units of sigma and their sum of squares is chi^2
    // (fit_brdf_result_t.chi2_dof); the robust losses' scale is then in sigma.
    bool             noise_weighted;
} fit_samples_t;

fit_samples_t *fit_samples_new(void);
void           fit_samples_free(fit_samples_t *s);
// Add a sample from angles (radians) and f_r (1/sr); false for n.l <= 0 or
// n.v <= 0 (skipped: no reflection there) or non-finite values.
bool fit_samples_add_angles(fit_samples_t *s, double theta_i, double phi_i, double theta_o, double phi_o,
                            double f_r, double weight);
bool fit_samples_add(fit_samples_t *s, const model_cosines_t *c, double R, double weight);
// The same for a sample lit by a finite lamp: disc = the cosines at its 4
// quadrature directions (model_lamp_disc_dirs), NULL = a point lamp.
bool fit_samples_add_disc(fit_samples_t *s, const model_cosines_t *c, const model_cosines_t *disc, double R,
                          double weight);
// The model's R of samples off..off+cnt-1 (lamp discs averaged) and, when
// dR != NULL, dR/dp (cnt x nparams, row-major).
void fit_samples_eval_n(const fit_samples_t *s, model_brdf_t m, const double *p, int off, int cnt, double *R,
                        double *dR);
double fit_samples_eval(const fit_samples_t *s, model_brdf_t m, const double *p, int i);
typedef enum { FIT_WEIGHTS_SOLID_ANGLE, FIT_WEIGHTS_UNIFORM, FIT_WEIGHTS_COLUMN } fit_weights_t;
typedef struct {
    fit_weights_t weights;   // default solid-angle
    int           channel;   // model_channel_t: luma (default), r, g, b (MERL, RGL)
} fit_read_opts_t;
fit_read_opts_t fit_read_defaults(void);
bool            fit_weights_parse(const char *s, fit_weights_t *out);   // solid-angle|uniform|column
// Read a CSV, MERL or RGL file (by content: MERL when the header dims and the
// file size agree, RGL by its magic; another binary is refused), weighted as
// opts says (NULL: defaults). NULL with a message naming file (and line).
fit_samples_t *fit_samples_load(const char *path, const fit_read_opts_t *opts);
fit_samples_t *fit_samples_read(const char *path);        // fit_samples_load with the defaults
fit_samples_t *fit_samples_read_csv(const char *path);    // the file's own weights (1 without)
fit_samples_t *fit_samples_read_merl(const char *path);   // uniform weights
// The solid angle in (omega_i, omega_o) each of n samples stands for, sr^2
// (ang: theta_i, phi_i, theta_o, phi_o per sample, radians): the incident
// direction's area among the distinct incident directions times the outgoing
// one's among those measured with it; each area from rings of equal theta
// (edges at midpoints, the outer ones half a spacing out, clipped to 0 and
// 90 deg) and within a ring the azimuths' midpoints (a ring with a gap over
// twice its widest other is open). Exact cells for theta/phi grids (a full
// grid sums to (2 pi)^2). A CSV uses them when its incident directions are
// few (at most 1 in 8 samples has its own), else fit_solid_angles_knn.
bool fit_solid_angles(int n, const double *ang, double *w);
// A density estimate for scattered samples (fit/brdf/samples.c): the measure
// of the ball reaching each sample's 8th nearest neighbour over 8, in
// (cos theta_i, omega_o turned by -phi_i) where it is 2 pi du d omega_o.
bool fit_solid_angles_knn(int n, const double *ang, double *w);
// Samples of a BRDF for Ngan et al.'s (2005) error, the RMS over both
// hemispheres of (f_model - f) cos theta_i: one sample at the centre of every
// cell of the MERL grid (model_brdf_table_cell: theta_h square-root mapped,
// so a sharp lobe is resolved; theta_d and phi_d every stride-th cell, stride
// >= 1, each standing for its stride x stride block) with both directions
// within FIT_NGAN_THETA_MAX_DEG of the normal, R = R(ctx, cosines) (f_r cos
// theta_i, 1/sr), weighted by the cells' solid angle in (omega_i, omega_o)
// (weights scaled to mean 1; their sum, sr^2, in omega_sr2). A fit's rms on
// them is the Ngan error. NULL + message when R is not finite somewhere.
enum { FIT_NGAN_THETA_MAX_DEG = 85 };
fit_samples_t *fit_samples_ngan(double (*R)(const void *ctx, const model_cosines_t *c), const void *ctx, int stride);
// A mixture of materials for fit_samples_ngan (ctx: a fit_mixture_t): R = sum_k weight[k] R_k
// (model_material_eval: a table or a model). One material of weight 1 is that material.
typedef struct {
    int                            n;
    const model_material_t *const *mat;
    const double                  *weight;
} fit_mixture_t;
double fit_mixture_R(const void *ctx, const model_cosines_t *c);
// Over samples s: sqrt(sum w (R_model(p) - R)^2 / sum w), 1/sr (on fit_samples_ngan's samples: the Ngan error
// of model m with parameters p); and sqrt(trace(C H) / sum w), H = sum w J J^T at p (J = dR/dp): the RMS change
// of R that parameters of covariance C (np x np) make, to first order (NAN when C has a non-finite element).
double fit_samples_rms(const fit_samples_t *s, model_brdf_t m, const double *p);
double fit_samples_rms_of_cov(const fit_samples_t *s, model_brdf_t m, const double *p, const double *C);

typedef struct {
    int     threads;            // 0: all cores
    int     starts;             // multi-start points for the roughness (default 3)
    double  noise_sigma;        // known std of R; 0 = estimate from the residuals
    bool    verbose;
    // Model choice (fit_brdf_models) by k-fold cross-validation: cv_folds
    // folds (default 5; 0 or 1: by the lowest BIC instead) over the samples'
    // independent units, cv_unit[i] the unit of sample i (a frame, a window:
    // any int; NULL: contiguous blocks of samples, 10 per fold), the units
    // dealt to folds in an order shuffled by cv_seed (deterministic).
    int         cv_folds;
    uint64_t    cv_seed;
    const int  *cv_unit;
    const char *cv_unit_name;   // what a unit is, for the outputs ("frame", ...; NULL: "block of samples")
    // A robust loss on each sample's weighted residual r (Ceres's, model/base/lsq.h):
    // LSQ_LOSS_NONE (least squares, default), HUBER or CAUCHY with loss_scale
    // (default 2) in units of sigma: the samples' own (noise_weighted), else the
    // residuals' robust std (1.4826 median |r|) of a least-squares fit first.
    lsq_loss_t  loss;
    double      loss_scale;
} fit_brdf_options_t;

// "l2" (none), "huber" or "cauchy"; false (no message) for another name.
bool        fit_loss_parse(const char *s, lsq_loss_t *out);
const char *fit_loss_name(lsq_loss_t l);

fit_brdf_options_t fit_brdf_defaults(void);

typedef struct {
    model_brdf_t  model;
    int           nparams, nfree;
    double        p[MODEL_BRDF_MAX_PARAMS];
    double        std[MODEL_BRDF_MAX_PARAMS];
    double        cov[MODEL_BRDF_MAX_PARAMS * MODEL_BRDF_MAX_PARAMS];
    bool          fixed[MODEL_BRDF_MAX_PARAMS];   // not identifiable from the samples: held
    bool          cov_ok;
    int           n;                              // samples
    double        rss;                            // sum w (R_model - R)^2
    double        rms;                            // sqrt(rss / sum w), 1/sr
    double        ngan_error;                     // sqrt(sum w ((f_model - f) cos th_i)^2 / sum w) = rms
    double        rms_fr;                         // sqrt(sum w (f_model - f)^2 / sum w), 1/sr
    double        sigma;                          // residual std used for the covariance
    double        chi2_dof;                       // rss / (N - free) of noise-weighted samples (else NAN)
    lsq_loss_t    loss;                           // the loss fitted with, and its scale in the
    double        loss_scale;                     // weighted residuals' units (sigma of R times
                                                  // loss_scale; 0 for least squares)
    int           n_downweighted;                 // robust: samples beyond the loss's scale
    double        aic, bic;                       // N ln(RSS/N) + 2k, N ln(RSS/N) + k ln N
    double        fresnel_variation;              // largest relative change of F over the samples
                                                  // (< 0.05: only ks*F0 is measured; F0 held)
    // held parameters that change R nowhere over the samples (ggx2's alpha2
    // with ks2 0): any value in [free_lo, free_hi] fits alike; held at its
    // middle with a uniform's std (uncorrelated in cov)
    bool          held_free[MODEL_BRDF_MAX_PARAMS];
    double        free_lo[MODEL_BRDF_MAX_PARAMS], free_hi[MODEL_BRDF_MAX_PARAMS];
    bool          f0_unmeasured;                  // F0 held at the middle of [f0_lo, f0_hi], where
    double        f0_lo, f0_hi;                   // ks*F0 and the ranges put it; std[F0] = the
                                                  // uniform's, in cov along ks*F0 = const
    // k-fold cross-validation (fit_brdf_models): the held-out weighted RMS
    // of R over every fold, sqrt(sum w e^2 / sum w) with each fold's samples
    // predicted by the fit to the others (1/sr), and its standard error from
    // the spread of the folds' mean squares; NAN when not done or a fold failed.
    double        cv_rms, cv_se;
    lsq_summary_t summary;
    // What the samples share (fit_brdf_shared_covariance, refl fit material):
    // when shared_done, cov and std above are the cluster-robust statistical
    // covariance and std_chi2 the model-based std it replaced (the covariance
    // scaled by rss / (N - free)); clusters_frame, clusters_place the clusters
    // it used (0: that way not used). groups_ok: cov_groups is the systematic
    // covariance of the photometric groups' (each lamp's) scales.
    bool          shared_done;
    int           clusters_frame, clusters_place;
    double        std_chi2[MODEL_BRDF_MAX_PARAMS];
    bool          groups_ok;
    double        cov_groups[MODEL_BRDF_MAX_PARAMS * MODEL_BRDF_MAX_PARAMS];
} fit_brdf_result_t;

// Fit model m to the samples. false with a message when no usable fit.
bool fit_brdf(const fit_samples_t *s, model_brdf_t m, const fit_brdf_options_t *opt, fit_brdf_result_t *out);
// The same from one given starting point (no multi-start; clamped into the bounds).
bool fit_brdf_from(const fit_samples_t *s, model_brdf_t m, const fit_brdf_options_t *opt, const double *start,
                   fit_brdf_result_t *out);

// What the samples of a fit share, for its covariance (refl fit material;
// README "refl fit material", the parameters' uncertainty). Per sample (NULL:
// none): frame[i] the frame it was measured in (its exposure, lamp state and
// pose shared), place[i] its place on the sample (any int: the samples of a
// place share what the material does there), group[i] in 0..ngroups-1 its
// photometric group (a lamp seen by a camera: the calibration's kc*I of that
// lamp, its emission pattern and position scale every sample of it alike),
// whose scale has the relative std group_rel[group].
typedef struct {
    const int    *frame, *place, *group;
    int           ngroups;
    const double *group_rel;
} fit_shared_t;
enum { FIT_MIN_CLUSTERS = 10 };   // a way of clustering with fewer clusters is not used
// The fit r of samples s (at r->p, with r's held parameters) given what its
// samples share:
//  - the statistical covariance, cluster-robust (the sandwich H^-1 M H^-1,
//    H = sum w J J^T over the free parameters, M = sum over clusters of
//    u u^T, u = sum over the cluster's samples of w (R_model - R) J, times
//    G/(G-1)), two-way by frames and places (Cameron, Gelbach & Miller 2011:
//    V_frame + V_place - V_frame&place, negative eigenvalues set to 0), one-way
//    when only one of them has FIT_MIN_CLUSTERS clusters: residuals that
//    frames or places share (a frame's exposure, a model's misfit over a
//    frame's geometry, the material's variation from place to place) count
//    once per cluster, not once per sample. It replaces r->cov and r->std for
//    the free parameters (F0 held over its interval and the other held
//    parameters keep their stated parts); the former std goes to std_chi2.
//    Without frames and places (or with a robust loss), r is left as it is.
//  - the groups' systematic covariance: each group's scale changed by its
//    group_rel moves the parameters by dp_g = H^-1 sum_g w J R group_rel[g]
//    (the linearised refit); cov_groups = sum_g dp_g dp_g^T, independent
//    groups. dp (ngroups x nparams, row-major; NULL: not wanted) gets each dp_g.
// false + message when H is singular (r unchanged).
bool fit_brdf_shared_covariance(const fit_samples_t *s, const fit_shared_t *sh, fit_brdf_result_t *r, double *dp);

// Several models fitted to the same samples (refl fit brdf, refl fit
// material): the results of those that could be fitted, in the order tried,
// and the message of each that could not.
typedef struct {
    int               ntried;
    model_brdf_t      tried[MODEL_BRDF_COUNT];
    int               at[MODEL_BRDF_COUNT];           // per try: index in res, -1 not fitted (error[k])
    char              error[MODEL_BRDF_COUNT][512];
    double            time_s[MODEL_BRDF_COUNT];       // per try, wall clock
    int               nres;
    int               best;                           // in res: the chosen model, -1 when none was fitted
    int               best_bic;                       // in res: the lowest BIC (reported beside the choice)
    int               best_cv;                        // in res: the lowest cv_rms, -1 without cross-validation
    bool              by_cv;                          // best chosen by cross-validation (else by BIC: why in cv_note)
    int               cv_folds, cv_units;             // folds used, independent units dealt to them
    uint64_t          cv_seed;
    char              cv_unit_name[32];
    char              cv_note[160];
    fit_brdf_result_t res[MODEL_BRDF_COUNT];
} fit_brdf_models_t;

// The models a name selects: "all" (every model, in model order) or one
// model's name. false (no message) for an unknown name.
bool fit_brdf_model_list(const char *name, model_brdf_t models[MODEL_BRDF_COUNT], int *nmodels);
// Fit each of models[0..nmodels-1] (fit_brdf) into *out and choose one: with
// opt->cv_folds >= 2 (and at least 2 units), k-fold cross-validation: each
// model refitted (fit_brdf_from its full fit) without each fold and its
// held-out weighted RMS (cv_rms) computed; the chosen model is the one with
// the fewest parameters whose cv_rms is within one standard error of the
// lowest (the one-standard-error rule: models the held-out data cannot tell
// apart count as equivalent, and the simpler is kept). Else the lowest BIC.
// The messages of the models that could not be fitted are kept in out->error, not printed.
// Returns out->best >= 0; false leaves the message "no model could be fitted"
// (model_last_error, not printed).
bool fit_brdf_models(const fit_samples_t *s, const model_brdf_t *models, int nmodels, const fit_brdf_options_t *opt,
                     fit_brdf_models_t *out);

// The model choice of *m as JSON: the rule, folds, units, seed, the chosen
// model, the lowest BIC's and the lowest cv_rms's (written into a priors entry
// as "model_choice").
json_t *fit_brdf_choice_json(const fit_brdf_models_t *m);

// A material's priors entry from its fit, the priors' std and covariance and
// the parameters' units and conventions: fit/priors.h (fit_priors_material,
// fit_prior_std, fit_prior_covariance, fit_param_unit, fit_param_convention).

// `refl fit brdf|material` (fit/cmd_fit.c).
int fit_cmd(int argc, char **argv);

#ifdef __cplusplus
}
#endif
