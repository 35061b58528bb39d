// fit/priors.h — the priors file: each material's reflection model and the
// prior of its parameters; its one reader and writer (fit/priors.c).
//
// The priors file ("refl-priors", JSON; README "refl fit brdf" has the table)
// is what the offline fits (refl fit brdf, refl fit material) hand the
// verification fitter (refl verify), the lamp planner, the exporter and the
// studies:
//   "format": "refl-priors", "version": 1
//   "units": R = f_r cos(theta_i) in 1/sr; each parameter names its own
//   "materials": [ one entry per material:
//     "name" (under 64 characters; the description's material name),
//     "model" (model_brdf_name: lambert, hall, torrance_sparrow, thesis_fit,
//       cook_torrance, ggx, ashikhmin_shirley, ggx2), "convention" (its formula),
//     "parameters": [ in the model's parameter order:
//       "name" (model_brdf_param_name), "unit" and "convention" (fit_param_unit,
//       fit_param_convention: e.g. kd is albedo/pi in the thesis's models, the
//       albedo in the physical ones; alpha is GGX alpha, not perceptual roughness),
//       "mean" (within the physical range and [lo, hi]),
//       "std" (>= 0; null or absent: unknown, no prior; 0: held),
//       "std_statistical", "std_parts" (how std was made; not read),
//       "lo", "hi" (the prior's bounds, mean +- k std within the physical range;
//         absent or null: the physical range),
//       "held" (a note: the samples could not measure it; a fitter holds it at mean),
//       "barely_constrained" (fit_priors_barely_constrained of mean, std, lo,
//         hi; written for the reports, not read) ],
//     "covariance" (the fit's statistical np x np, null where not available; not read),
//     "prior_covariance" (optional: "parameters" in the model's order and
//       "matrix", np x np symmetric with a diagonal >= 0, units of the parameters;
//       its diagonal is each std^2; without it the parameters are independent),
//     "window_rel_std" (optional, null: not known; a window's relative spread
//       about the model beyond its noise, in [0, 10]),
//     and what the fit reports, not read here: "model_choice", "candidates",
//     "rms", "ngan_error", "aic", "bic", "cv_rms", "samples" or "session" ... ]
//   "provenance": refl's version, the date, the command, the inputs' SHA-256.
// Version 1 is the only layout; a file naming no format, or naming itself
// "refl priors 1" (FIT_PRIORS_FORMAT_V1_NAME), is read as version 1. A file of
// a newer version is refused, naming the version it has and the ones this refl
// reads.
#pragma once

#include <jansson.h>
#include <stdbool.h>

#include "fit/brdf/brdf.h"
#include "model/model.h"

#ifdef __cplusplus
extern "C" {
#endif

#define FIT_PRIORS_FORMAT         "refl-priors"
#define FIT_PRIORS_FORMAT_V1_NAME "refl priors 1"   // the name version 1 files may carry instead
enum { FIT_PRIORS_VERSION = 1 };                   // the version written, the newest read

typedef struct {
    char         name[64];
    model_brdf_t model;
    int          np;
    double       mean[MODEL_BRDF_MAX_PARAMS], std[MODEL_BRDF_MAX_PARAMS];
    double       lo[MODEL_BRDF_MAX_PARAMS], hi[MODEL_BRDF_MAX_PARAMS];
    bool         held[MODEL_BRDF_MAX_PARAMS];   // std 0: fixed
    // The priors' full covariance ("prior_covariance", np x np in parameter
    // order; has_cov false for files without one: independent std).
    bool         has_cov;
    double       cov[MODEL_BRDF_MAX_PARAMS * MODEL_BRDF_MAX_PARAMS];
    double       window_rel;        // "window_rel_std": a window's relative spread about the model beyond its
                                    //   noise (texture, what the model lacks); NAN: not known
    char         source[512];
    char         sha256[65];
    int          version;           // the format version of the file it was read from (0: not from a file)
} verify_prior_t;

// A material's prior as a multivariate Gaussian over its free parameters
// (idx[0..n-1] of its np): residuals r = L^-1 (p_S - mean_S), Sigma_S = L L^T
// (the prior's covariance over them), so |r|^2 is the Mahalanobis distance.
typedef struct {
    int    n, np;
    int    idx[MODEL_BRDF_MAX_PARAMS];
    double mean[MODEL_BRDF_MAX_PARAMS];
    double Linv[MODEL_BRDF_MAX_PARAMS * MODEL_BRDF_MAX_PARAMS];   // n x n, lower triangular
} verify_mvprior_t;

// Build it over the parameters with use[j] (held ones left out by the
// caller). false (no message) when P has no covariance, fewer than 2 are
// used, or their covariance is not positive definite (the caller then keeps
// independent priors).
bool verify_mvprior_make(const verify_prior_t *P, const bool *use, verify_mvprior_t *out);
// The residual block (model/base/lsq.h's lsq_residual_fn; ctx a verify_mvprior_t,
// one parameter block: the material's np parameters; n residuals).
bool verify_mvprior_residual(void *ctx, const double *const *p, double *r, double **J);

typedef struct {
    int             n;
    verify_prior_t *m;
} verify_priors_t;

// Append the materials of a priors file (a material already present is an
// error naming both files). false + "file: message".
bool verify_priors_load(verify_priors_t *pr, const char *path);
// The same from text (len bytes, not NUL-terminated; name for messages).
bool verify_priors_parse(verify_priors_t *pr, const char *text, size_t len, const char *name);
// A prior from known values (tests, studies): std = rel * |mean| (at least
// abs_min), bounds mean +- k std within the physical range.
bool verify_priors_add(verify_priors_t *pr, const model_material_t *mat, double rel, double abs_min, double k);
const verify_prior_t *verify_priors_find(const verify_priors_t *pr, const char *name);
void verify_priors_free(verify_priors_t *pr);

// Scene material k -> its prior (NULL + message naming the material when the
// priors lack one).
bool verify_match_priors(const model_scene_t *scene, const verify_priors_t *pr, const verify_prior_t **out);

// The scene's materials at their priors' means: mm[k] and mats[k] = &mm[k]
// for each of scene->nmaterials. false + message naming a material without priors.
bool verify_priors_means(const model_scene_t *scene, const verify_priors_t *pr, model_material_t *mm,
                         const model_material_t **mats);

// A priors document to write: {"format": "refl-priors", "version": 1,
// "units": ...}; the writer adds "materials" (entries of fit_priors_material
// and what its fit reports) and "provenance". A new reference.
// The format version of a parsed priors file: "format" "refl-priors" with its
// "version", the name "refl priors 1" or no "format" at all: version 1; a newer
// version or another format is refused. false + model_error_set naming path.
bool fit_priors_check_format(const json_t *root, const char *path, int *version);
json_t *fit_priors_document(void);

// Units and convention of parameter i of model m ("1/sr", "albedo", ...).
const char *fit_param_unit(model_brdf_t m, int i);
const char *fit_param_convention(model_brdf_t m, int i);

// The priors' covariance (np x np, row-major, the model's parameter order;
// written as "prior_covariance"): the fit's plus the systematic part, a
// photometric scale of std sys_rel shared by every sample (the parameters R
// is linear in, kd ks ks2 Rd, fully correlated: sys_rel^2 mean_a mean_b),
// (sys_rel mean)^2 on the diagonal of the others, and the photometric groups'
// (each lamp's) cov_groups when groups_ok; held parameters 0, F0 held over its
// interval its uniform's. Its diagonal is the entry's std^2.
void    fit_prior_covariance(const fit_brdf_result_t *best, double sys_rel, double *C);
// Parameter j's std in the priors: sqrt(std^2 + (sys_rel mean)^2 + cov_groups_jj) (the statistical part, the
// shared photometric scale or geometric part, the lamps'), a held parameter's stated one (0, or its interval's
// uniform std). The diagonal of fit_prior_covariance is its square.
double  fit_prior_std(const fit_brdf_result_t *best, double sys_rel, int j);
// The priors entry of one material (see README, "Priors file"): std =
// sqrt(std_statistical^2 + (sys_rel * mean)^2) (the statistical part alone
// shrinks with the sample count; sys_rel covers the calibrations' systematic
// errors, which every sample shares), bounds mean +- k_sigma * std clipped to
// the physical range; candidates (may be NULL) are every model tried.
json_t *fit_priors_material(const char *name, const fit_brdf_result_t *best, const fit_brdf_result_t *candidates,
                            int ncandidates, double k_sigma, double sys_rel);

// A parameter is barely constrained when its 1-sigma exceeds
// FIT_PRIORS_LOOSE_SHARE of its mean's magnitude or of its bounds' width
// (hi - lo); one held (std 0) or of unknown std never is. of_value, of_width
// (may be NULL): std / |mean| and std / (hi - lo), NAN where not defined.
#define FIT_PRIORS_LOOSE_SHARE 0.30
#define FIT_PRIORS_LOOSE_RULE "barely constrained: its 1-sigma exceeds 30 % of its value's magnitude or of its " \
                              "bounds' width"
bool fit_priors_barely_constrained(double mean, double sd, double lo, double hi, double *of_value, double *of_width);

#ifdef __cplusplus
}
#endif

