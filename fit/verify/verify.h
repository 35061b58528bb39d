// fit/verify/verify.h — the verification fitter (thesis ch. 5-6): does a geometric
// scene description match the images?
//
// Model of a reference point k (the mean of a w x w window) in image m, taken
// by camera c with exposure E_m = t_m 10^(G_m/20) (us), lamps L_m on:
//   P_k = Pa_m + E_m kc_c g_k [ sum_{i in L_m} s_i A_i V_ik R(p_mat; l_ik, v_k, n_k) / d_ik^2
//                               + rho sum_{i in L_m} s_i A_i B_ik ]
// A_i = the lamp's kc*I per us at 0 dB (the reference white's calibration,
// DN/us per (1/sr)/mm^2), s_i its relative intensity (prior 1 +- lamp_sigma),
// kc_c the camera's relative sensitivity (prior 1 +- camera_sigma), g_k the
// flat field (gain calibration) and Pa_m the offset left after the offset map
// (prior 0 +- pa_sigma_dn; free without an offset map). B_ik is one diffuse
// bounce of lamp i's light (ir_samples cosine-weighted rays from the point,
// each hit a virtual point source), made once with the priors' means; rho its
// weight (prior 1 +- 0.5; 1 is physical). Material parameters: a Gaussian
// prior (mean, std) and the bounds lo..hi of the priors file; parameters the
// file holds (std 0) are fixed. Without priors (the thesis's fit): physical
// ranges only, lamps fixed at s = 1, kc free.
//
// Residual (P_k - P_meas,k) / sigma_k (reported as z_k = (P_meas,k - P_k) /
// sigma_k, the sign of the difference images) with sigma_k^2 = the window mean's
// sensor noise (from the gain calibration's K and read noise; else from the
// windows' own spread) + (rel * signal)^2 + the interreflection basis's Monte
// Carlo error^2 (E kc sum_i A_i Bsd_i) + for a window near an edge
// (edge_position_sigma_px * its slope across the edge)^2; rel is the
// material's window_rel_std from its priors (the spread of a window's R about
// the model on its coupon, beyond noise), else model_rel. A window near an
// edge (a face's outline, a shadow's) is modelled with the pixels' footprint
// and the optics' blur (fit/verify/footprint.h). Fitted with a robust (Cauchy)
// loss so that a region the description gets wrong does not bend the
// parameters, then judged: points with |z| > z_flag, and windows that show an
// edge the description does not predict, are flags; 8-connected flags on an
// image's grid are regions; the score is the sum over regions of at least
// min_region points of their flags' excess chi^2, sum (z^2 - z_flag^2), with an
// unexpected edge counting as z = z_flag * its std ratio. Verdict: the
// description is incorrect when score > score_threshold.
#pragma once

#include <jansson.h>
#include <stdbool.h>
#include <stdint.h>

#include "calib/calib.h"
#include "fit/priors.h"
#include "model/base/lsq.h"
#include "model/model.h"

#ifdef __cplusplus
extern "C" {
#endif

// ---------------------------------------------------------------------------
// Inputs

typedef struct {
    char            name[64];
    model_camera_t *cam;            // geometry, rt_cam_world = rig frame (not owned)
    const float    *offset_dn;      // gain calibration's dark offset map (W*H) or NULL
    const float    *flat;           // its flat field g (mean 1) or NULL
    double          K_dn_per_e;     // system gain at 0 dB (0: unknown)
    double          read_noise_e;
    double          saturation_dn;  // window maxima at or above are not used
    const model_lin_t *lin;         // the gain calibration's response linearisation of the signal above the
                                    // offset (model_linearise), applied before the fit (NULL: linear)
    double          kc_rel;         // its sensitivity relative to the lamps' scale kc*I (its own white's over
                                    // the one given; 0 or 1: the same camera), a factor on its signal
    double          psf_sigma_px;   // the optics' blur: an isotropic Gaussian PSF's sigma, px, beside the
                                    // pixel's own footprint (calib_set_t.psf_sigma_px; 0: none known)
    double          pixel_fill;     // the pixel's footprint: a square of this side, px (1: the whole pixel,
                                    // a real sensor's; 0: a point, a renderer's one ray a pixel)
} verify_camera_t;

typedef struct {
    char         name[256];
    const float *P;                 // W*H grey values, DN (as the camera delivered them)
    int          W, H;
    int          camera;            // index into the cameras
    double       angle_deg;         // turntable angle (the scene is rotated by it about z)
    uint32_t     lamps_on;          // bit i: lamp i on
    double       exposure_us, gain_db;
    struct verify_windows *windows; // optional (NULL: none): the image's window sums kept for the next fits
                                    //   of the same pixels (verify_windows_new)
} verify_image_t;

// The window sums of an image's reference points (per window and maps), kept
// across the fits of the same pixels: a study verifies each case's images
// against every description and configuration, whose reference grids are the
// same. The caller clears it when the pixels change; one thread at a time.
typedef struct verify_windows verify_windows_t;
verify_windows_t *verify_windows_new(void);   // NULL + message: out of memory
void              verify_windows_clear(verify_windows_t *w);
void              verify_windows_free(verify_windows_t *w);

typedef struct {
    int    spacing_px;          // grid step of reference points (default 8)
    int    window_px;           // window side, odd (default 5)
    double edge_margin_px;      // skip windows this close to predicted edges (default 2)
    double boundary_margin_px;  // and face/shadow changes this far beyond the window (default 4)
    double edge_k;              // window std above sqrt(edge_k^2 var_noise + (edge_rel S)^2) says edge (3)
    double edge_rel;            // (0.05)
    bool   edge_windows;        // model the windows near edges with the pixels' footprint and the blur
                                //   (fit/verify/footprint.h; default true); false: skip them
    int    edge_subsamples;     // sub-cells per px side of a window's mixed cells (odd; default 5)
    double edge_position_sigma_px;   // 1-sigma of where an edge lies in the image (camera model, placement,
                                //   blur), px: a window near an edge gets sigma^2 += (this |dM/dc|)^2 (0.1)
    int    ir_samples;          // interreflection rays per point (default 64; 0: none)
    bool   use_priors;          // bounded by the priors (default true); false: the thesis's fit
    bool   use_flat;            // use the cameras' flat fields and offset maps (default true)
    double model_rel;           // relative model tolerance in sigma (default 0.04) for materials whose priors
                                //   state no window_rel_std
    bool   model_rel_given;     // model_rel for every material, over the priors' window_rel_std
    double lamp_sigma;          // prior std of s_i (default 0.1)
    double camera_sigma;        // prior std of kc_c (default 0.1)
    double pa_sigma_dn;         // prior std of Pa with an offset map (default 5; ambient light)
    double robust_scale;        // Cauchy loss scale in z (default 3; 0: plain least squares)
    double z_flag;              // (default 4)
    int    min_region;          // (default 3)
    double score_threshold;     // (default 400)
    bool   fix_lamps, fix_cameras, fix_pa, fix_rho, fix_materials;   // masks (thesis 5.4)
    int    threads;             // 0: REFL_THREADS or all
    int    max_iterations;      // of the fit (default 100)
    bool   no_covariance;       // skip the parameters' standard deviations (faster; studies)
    bool   reference_eval;      // benchmarks: model_brdf_eval per residual instead of the prepared
                                //   terms (model_brdf_eval_prepared), the robust transform always
                                //   computed (not kept per point); the same results, slower
    bool   verbose;
} verify_options_t;

verify_options_t verify_defaults(void);

// The geometry of one image under a description: the reference-point grid
// with pixel_info, lamp samples, skip reasons and the interreflection basis.
// Made once per (description, camera, angle); images of that view reuse it.
typedef struct verify_view verify_view_t;

// scene: the description at turntable angle 0 (rotated here); mats: the
// materials for the interreflection basis (scene->nmaterials; the priors'
// means); lamps: positions (rig frame). The basis is per unit kc*I.
verify_view_t *verify_view_new(const model_scene_t *scene, const verify_camera_t *cam, double angle_deg,
                               const model_lamps_t *lamps, const model_material_t *const *mats,
                               const verify_options_t *opt);
void verify_view_free(verify_view_t *v);
int  verify_view_npoints(const verify_view_t *v);   // geometrically usable grid points
double verify_view_time_s(const verify_view_t *v);

// One diffuse bounce of each lamp's light at n points (B: n x lamps->n,
// per unit kc*I; the model's interreflection term, see above): samples
// cosine-weighted rays per point, each hit a virtual point source lit by the
// lamps (shadow rays). Points with face < 0 get 0.
void verify_interreflection(const model_tracer_t *t, const model_lamps_t *lamps, const model_material_t *const *mats,
                            const model_pixel_info_t *pi, int n, int samples, int threads, float *B);
// The same and each value's standard error as a Monte Carlo estimate (Bsd:
// n x lamps->n, may be NULL): pi sqrt(var of a ray's term / (samples - 1)).
void verify_interreflection_sd(const model_tracer_t *t, const model_lamps_t *lamps,
                               const model_material_t *const *mats, const model_pixel_info_t *pi, int n, int samples,
                               int threads, float *B, float *Bsd);

// Status of a grid point.
typedef enum {
    VERIFY_PT_USED = 0,
    VERIFY_PT_BACKGROUND,      // the ray misses the description
    VERIFY_PT_NEAR_EDGE,       // within edge_margin_px of a predicted edge (model_edges_predict)
    VERIFY_PT_BOUNDARY,        // the window's corners see another face or another shadow state
    VERIFY_PT_SATURATED,
    VERIFY_PT_EDGE_MEASURED,   // the window's spread says edge where none is predicted (a flag)
    // (a window near an edge that is modelled with its footprint and blur is USED, verify_point_t.footprint)
    VERIFY_PT_NSTATUS
} verify_pt_status_t;

const char *verify_pt_status_name(verify_pt_status_t s);

typedef struct {
    int     image;
    float   q[2];
    int32_t face;          // face of the description (-1 background)
    uint8_t status;        // verify_pt_status_t
    bool    footprint;     // a window near an edge, modelled with the pixels' footprint and the blur
    bool    flag;
    int     region;        // index into regions or -1
    float   meas, model;   // DN (meas after the offset map)
    float   sigma, z;      // z = (meas - model) / sigma
    // region: index into the result's regions (those with counts false too;
    // the JSON's change_regions give each region's index)
} verify_point_t;

typedef struct {
    int    image;
    int    npoints;        // flags in it
    double area_px;        // npoints * spacing^2
    double excess_chi2;    // sum (z^2 - z_flag^2) over its flags
    double max_abs_z;
    double bbox[4];        // x0 y0 x1 y1, px
    int    faces[4], face_points[4];   // the faces it falls on, most points first (-1 background)
    bool   counts;         // npoints >= min_region
} verify_region_t;

typedef struct {
    char   name[96];       // "kc[camera]", "lamp[east]", "Pa[image]", "rho", "plywood.kd"
    double value, std;     // std NAN when the covariance is not available
    double prior_mean, prior_std, lo, hi;   // prior_std 0: none; lo/hi the bounds used
    bool   fixed, pinned;  // pinned: at a bound (within 1e-3 of its range)
} verify_param_t;

typedef struct {
    double max_abs, mean_abs, std_abs, robust_sigma;   // |difference|, DN (robust: 1.4826 MAD of the difference)
    double rms_z, median_abs_z;
    int    npoints;
} verify_stats_t;

typedef struct {
    int              npoints;
    verify_point_t  *points;
    int              nstatus[VERIFY_PT_NSTATUS];
    verify_stats_t   all;
    verify_stats_t  *per_image;     // nimages
    int              nimages;
    int              nregions;
    verify_region_t *regions;
    int              nparams;
    verify_param_t  *params;
    int              npinned;
    double           score;
    bool             correct;
    lsq_summary_t    summary;
    double           time_fit_s;
    // the fitted values, for synthetic images
    double          *kc;            // ncameras
    double          *s;             // nlamps
    double          *Pa;            // nimages
    double           rho;
    model_material_t *mats;         // scene->nmaterials, fitted
    // what the user should look at (verify_param_warning; and the placement's, verify_files_run)
    int              nwarnings;
    char           (*warnings)[256];
} verify_result_t;

// A fitted parameter's warning into buf (true), or false: pinned at a bound,
// or more than 3 sigma from its prior's mean (a prior that does not hold for
// these images: swapped or mislabelled materials, a changed lamp or camera,
// an offset that moved).
bool verify_param_warning(const verify_param_t *p, char *buf, size_t n);

// Fit and judge. views[m] is image m's view; scene: the description (for
// material names; its materials must all have priors: pr). A: kc*I per us.
bool verify_run(const model_scene_t *scene, const verify_priors_t *pr, const verify_camera_t *cams, int ncams,
                const model_lamps_t *lamps, const double *A, const verify_image_t *imgs, int nimgs,
                verify_view_t *const *views, const verify_options_t *opt, verify_result_t *out);
void verify_result_free(verify_result_t *r);

// The part's placement on the turntable as a nuisance (fit/verify/register.c):
// x' = Rz(turn)(x - c) + c + (dx, dy, 0) in the part's frame before the
// turntable angle, c the middle of the description's bounding box in x and y.
typedef struct {
    double dx_mm, dy_mm, turn_deg;   // the registered placement
    double centre_mm[2];             // c
    double tol_mm, tol_deg;          // the search range (the fixture's tolerance): |dx|, |dy| <= tol_mm, ...
    double score_nominal, score;     // edge agreement at (0, 0, 0) and at the placement (1: every edge
                                     //   where and as predicted)
    int    nsamples;                 // edge points used
    bool   at_limit;                 // the placement is at the edge of the range: the part may lie further off
    double time_s;
} verify_placement_t;

// Register the description's predicted edges (at the priors' means mats, the
// lamps' kc*I A, each image's lamps, exposure and gain) to the images over
// the tolerance (0 and 0: nothing to do, out->dx = dy = turn = 0). false +
// message (too few edges in view to register).
bool verify_register(const model_scene_t *scene, const verify_camera_t *cams, const model_lamps_t *lamps,
                     const double *A, const model_material_t *const *mats, const verify_image_t *imgs, int nimgs,
                     double tol_mm, double tol_deg, verify_placement_t *out);
// The description moved to placement p (a new scene; NULL + message).
model_scene_t *verify_placed_scene(const model_scene_t *scene, const verify_placement_t *p);

// The result as JSON (units and conventions named): the body of verify.json,
// which names its format, "format": "refl-verify", "version": 1 (one layout;
// a file without the keys is version 1 to its readers, scripts/verify_report.py
// and refl chain).
#define VERIFY_JSON_FORMAT "refl-verify"
enum { VERIFY_JSON_VERSION = 1 };
json_t *verify_result_json(const verify_result_t *r, const model_scene_t *scene, const verify_image_t *imgs,
                           const model_lamps_t *lamps, const verify_options_t *opt);

// Tests: the fit's residual Jacobian (with the robust transform, every
// reflection model) against central differences.
bool verify_check_jacobian(double *max_abs_err);

// ---------------------------------------------------------------------------
// Verification of files (fit/verify/files.c): `refl verify` without its
// argument parsing and printing.

enum { VERIFY_FILES_MAX = 64 };   // images, cameras, priors files, gain calibrations

typedef struct {
    const char *scene;                             // the description: D3D, OBJ, STL or PLY, rig frame
    double      scene_unit_mm;                     // mm per unit of the scene file (0: mm, not said; --units)
    const char *images[VERIFY_FILES_MAX];          // 16-bit PNG frames of refl capture / refl rig snap (angle,
    int         nimages;                           // lamps, exposure, gain in their text chunks), or float TIFFs
    const char *priors[VERIFY_FILES_MAX];          // priors files (every material of the scene, each once)
    int         npriors;
    const char *cameras[VERIFY_FILES_MAX];         // camera models: none (calib's), one, or one per image
    int         ncameras;
    const char *gain[VERIFY_FILES_MAX];            // gain calibration directories: none, one, or one per camera
    int         ngain;
    const char *calib;                             // calibration directory (calib_set_load) or NULL
    const char *lamps;                             // lamps.json or lamps INI (NULL: calib's)
    const char *white;                             // white.json (kc*I per lamp per us) or NULL
    double      kc_per_us;                         // > 0 without a white: kc*I = kc_per_us * the INI's intensity
    bool        have_angle, have_exposure, have_gain;
    double      angle_deg, exposure_us, gain_db;   // for every image when have_*: over the metadata
    const char *lamps_on;                          // for every image ("east+west", "all"), NULL: metadata
    const char *out;                               // output directory (created)
    double      placement_tol_mm, placement_tol_deg;   // the part's placement registered within these
                                                   //   (verify_register) before the fit; 0 and 0: as described
    double      psf_sigma_px, pixel_fill;          // over every camera's calibration (NAN: the calibration's;
                                                   //   without one: 0 px and 1, the whole pixel)
    verify_options_t opt;
    json_t     *provenance;                        // borrowed: the inputs are added, verify.json carries it
} verify_files_opts_t;

typedef struct {
    verify_result_t fit;
    verify_placement_t placement;                  // the registered placement (zero: none asked)
    int             nimages;
    verify_image_t  images[VERIFY_FILES_MAX];      // as verified (P NULL: the pixels are freed)
} verify_files_result_t;

// Load the inputs, trace the views, fit and judge (verify_run), write
// o->out/verify.json, points.csv, imgN_actual.tiff and imgN_synthetic.tiff.
// Notes and progress through model_note and model_progress. false + message
// (model_error).
bool verify_files_run(const verify_files_opts_t *o, verify_files_result_t *r);
void verify_files_result_free(verify_files_result_t *r);

// A camera model with the gain calibration of gain_dir (gain.json and its maps
// offset_dn.tiff, prnu_gain.tiff; NULL: none) as a calibration set (cam, W, H,
// offset_dn, flat, gain_dn_per_e, read_noise_e, saturation_dn,
// lin). The loader wants a lamps.json: a minimal one from lamps (a
// placeholder lamp when NULL) is written to tmp_dir/.lamps-TAG.json (tmp_dir
// created) and removed. NULL + message. Free with calib_set_free.
calib_set_t *verify_load_camera_gain(const char *camera, const char *gain_dir, const model_lamps_t *lamps,
                                     const char *tmp_dir, int tag);

// `refl verify` (fit/cmd_verify.c).
int verify_cmd(int argc, char **argv);

#ifdef __cplusplus
}
#endif
