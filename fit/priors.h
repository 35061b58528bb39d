// fit/priors.h — the priors file: each material's reflection model and the
// prior of its parameters (README "Priors file"); its one reader and writer.
#pragma once

#include <jansson.h>
#include <stdbool.h>

#include "fit/brdf/brdf.h"
#include "model/model.h"

#ifdef __cplusplus
extern "C" {
#endif

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

#ifdef __cplusplus
}
#endif
