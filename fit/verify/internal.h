// fit/verify/internal.h — what the verification fitter's files share: a view's
// layout, the fit's points, residual contexts and working state.
#pragma once

#include "fit/brdf/brdf.h"
#include "fit/verify/footprint.h"
#include "fit/verify/verify.h"
#include "model/base/vec.h"

#define MAX_LAMPS 32

struct verify_view {
    int W, H, gw, gh, sp, x0, y0, nl;
    model_scene_t *rot;
    model_tracer_t *t;
    model_pixel_info_t *pi;     // gw*gh
    model_lamp_sample_t *ls;    // gw*gh*nl
    uint8_t *status;            // geometric status (USED, BACKGROUND, NEAR_EDGE, BOUNDARY)
    float *B;                   // gw*gh*nl: interreflection basis per unit A_i
    float *Bsd;                 // gw*gh*nl: its Monte Carlo estimate's standard error
    verify_footprints_t fp;     // the windows near edges modelled with footprint and blur (USED, fp.first >= 0)
    int nusable;
    double time_s;
};

// The interreflection basis (verify_interreflection_sd) at the points idx[0..n-1]
// of pi (idx NULL: 0..n-1), written at each point's index into B and Bsd.
void verify_interreflection_at(const model_tracer_t *t, const model_lamps_t *lamps, const model_material_t *const *mats,
                               const model_pixel_info_t *pi, const int *idx, int n, int samples, int threads, float *B,
                               float *Bsd);

typedef struct {
    double meas, sigma, Eg;   // measured DN (after the offset map), sigma DN, E * g
    int    mat, mat2;         // scene material; a window near an edge may see a second one (else -1)
    int    nl;                // its terms: (lamp on) for a plain point, (part, lamp on) for a window near an edge
    int    first;             // into the lamp arrays
    double r_last, rr_last;   // the robust transform's last residual and its image (verify_group_fn; NAN: none)
} pt_t;

typedef struct {
    pt_t         *pt;            // (r_last, rr_last change in verify_group_fn)
    model_brdf_prep_t *cs;       // per (point, lamp on): the geometry's terms (kept factors change)
    const double *w;             // A_i V / d^2
    const double *b;             // A_i B_i
    const int    *lamp;          // lamp index
    const uint8_t *sec;          // 1: the term is of the point's second material (mat2)
    model_brdf_t  model;         // of the point's material
    int           np, nl_all;
    bool          reference;     // model_brdf_eval on cs[].c, no kept robust images (reference_eval)
} res_ctx_t;

typedef struct {
    res_ctx_t *rc, *rc2;         // the point's material's and its second's (NULL: none)
    int        k;
} res_item_t;

// A group of points of one image and material: one residual block. The
// robust (Cauchy) loss is applied to each point's residual inside:
// r' = sign(r) sqrt(b ln(1 + r^2/b)), so its Gauss-Newton step is the
// loss's iteratively reweighted one (b = robust_scale^2; 0: plain).
typedef struct {
    res_ctx_t *rc, *rc2;   // the points' material's and their second material's (NULL: none; 6 blocks)
    const int *k;
    int        n;
    double     b;
} res_group_t;

// The residual of one point (ctx a res_item_t) and of a group (ctx a
// res_group_t), model/base/lsq.h's lsq_residual_fn (fit/verify/residuals.c).
bool verify_residual_fn(void *vctx, const double *const *par, double *res, double **jac);
bool verify_group_fn(void *vctx, const double *const *par, double *res, double **jac);

// A parameter of the fit: x[i], its prior and bounds.
typedef struct {
    char   name[96];
    double *x;
    int    i;
    double prior_mean, prior_std, lo, hi;
    bool   fixed;
    bool   mv;      // its prior is in a material's multivariate prior (F->mvp), not alone
} pdesc_t;

// The working state that verify_run's stages share. The inputs are borrowed;
// every array below is owned and freed by fit_free (out's arrays go to the
// caller).
typedef struct {
    // in
    const model_scene_t    *scene;
    const verify_camera_t  *cams;
    int                     ncams;
    const model_lamps_t    *lamps;
    const double           *A;          // kc*I per us, per lamp
    const verify_image_t   *imgs;
    int                     nimgs;
    verify_view_t *const   *views;
    const verify_options_t *opt;
    int                     nl, nm;     // lamps, scene materials
    const verify_prior_t  **prior;      // nm: each material's prior
    int                     npts;       // grid points of every image
    // the fit's points: those used and those with an unexpected edge (predicted, not fitted)
    pt_t            *pt;                // nfit
    int             *ptidx;             // nfit: point -> index in out->points
    int              nfit;
    model_brdf_prep_t *cs;              // per (fit point, lamp on)
    double          *wv, *bv;           // A_i V / d^2 and A_i B_i, per (fit point, lamp on)
    int             *lampv;             // lamp index, per (fit point, lamp on)
    uint8_t         *secv;              // per (fit point, lamp on): the term is of the point's second material
    double          *mp;                // nm x MODEL_BRDF_MAX_PARAMS: the materials' parameters
    res_ctx_t       *rcs;               // nm
    res_group_t     *groups;            // ngroups residual blocks; their indices in gidx
    int             *gidx;
    int              ngroups, nused;
    pdesc_t         *pd;                // npd parameters
    int              npd;
    verify_mvprior_t *mvp;              // nm: the materials' multivariate priors (n 0: none)
    int              *mvp_pd;           // nm: the index in pd of each material's first parameter
    lsq_problem_t   *prob;
    verify_result_t *out;
} fit_t;

// The parameter blocks of a point of image m and material mat: kc, s, Pa, p,
// rho, and with a second material mat2 (>= 0) its p. Returns their number.
int verify_fit_blocks(const fit_t *F, int m, int mat, int mat2, double *blocks[6]);


// A window's sums: of P - offset, its square, the flat field, and the largest raw P.
typedef struct {
    double s1, s2, gs, mx;
} wsum_t;

// The sums of every window of view v's grid on image im (w x w, offset map
// off and flat field flat or NULL): kept in im->windows when given (*owned
// false), else made for this fit (*owned true: the caller frees). NULL: out of memory.
const wsum_t *verify_window_sums(const verify_image_t *im, const verify_view_t *v, int w, const float *off,
                                 const float *flat, bool *owned);

// Every image's reference points and windows (fit/verify/points.c). false: out of memory.
bool verify_fit_measure(fit_t *F);
// The parameters' standard deviations (fit/verify/covariance.c); NAN when
// they cannot be had (no free parameter, a singular system). false + message:
// out of memory.
bool verify_fit_covariance(fit_t *F);
// The residue: the fitted model at every measured point, z and the flags, the
// status counts and the statistics; then the change regions and the score
// (fit/verify/regions.c). false + message: out of memory.
bool verify_fit_residue(fit_t *F);
bool verify_fit_regions(fit_t *F);
