// calib/lamps/lamps.h — the lamp calibration (calib/lamps/, run by lamps.c): lamp positions
// from the highlights of a mirror sphere carried round by the turntable. The whole
// calibration is calib_lamps_run (options in, result out), made of the stages
// declared at the end; below them the parts the stages use: the sub-pixel
// highlight finder, the ray toward a lamp, the triangulation and the joint fit
// of lamps and sphere path. `refl calib lamps` (calib/cmd_lamps.c) parses its
// options into a calib_lamps_opts_t, calls calib_lamps_run and prints.
//
// Conventions as calib/calib.h: mm, rig frame, pixel (0, 0) = centre of the
// top-left pixel, grey values in DN, turntable angles in degrees.
#pragma once

#include <stdbool.h>
#include <stdio.h>

#include "calib/calib.h"
#include "model/model.h"
#include "rig/rig.h"

#ifdef __cplusplus
extern "C" {
#endif

// The image of a sphere (centre_mm, radius_mm, rig frame) in a camera: for
// every pixel of the box [x0, x0 + w) x [y0, y0 + h) whether its ray hits the
// sphere, and for those the unit ray direction. Made by
// calib_lamps_sphere_image; free with calib_lamps_sphere_image_free.
typedef struct {
    int           x0, y0, w, h;    // box in pixels (clipped to the imager)
    unsigned char *on;             // w*h: 1 where the pixel's ray hits the sphere
    double        q_centre[2];     // projected sphere centre, px
    double        radius_px;       // largest distance of the silhouette from q_centre, px
} calib_lamps_sphere_image_t;

// NULL when the sphere is behind the camera or outside the imager (message set).
calib_lamps_sphere_image_t *calib_lamps_sphere_image(const model_camera_t *cam, model_vec3_t centre_mm,
                                                     double radius_mm);
void calib_lamps_sphere_image_free(calib_lamps_sphere_image_t *s);

// A highlight found on the sphere's image.
typedef struct {
    bool   found;
    double q[2];            // sub-pixel position, px (Gaussian fit; centroid when the fit failed)
    double q_centroid[2];   // intensity-weighted centroid of the blob, px
    double peak_dn;         // brightest pixel above the background, DN
    double noise_dn;        // robust std of the difference image around the sphere, DN
    double sigma_px[2];     // fitted Gaussian widths (x, y)
    double q_std_px;        // standard error of q from the fit's residuals, px
    int    blob_px;         // pixels of the blob (>= 20 % of the peak, connected to it)
    bool   saturated;       // the brightest pixel is at or above sat_dn
    bool   fit_used;        // q from the Gaussian fit (false: centroid)
    char   why[200];        // when not found: why (levels measured)
    // the 9x9 window around the brightest pixel, background subtracted (for
    // calib_lamps_fit_direction): pixel (win_x0 + i % 9, win_y0 + i / 9);
    // NAN where off the sphere, off the imager or saturated
    int    win_x0, win_y0;
    double win[81];
} calib_lamps_highlight_t;

// Find the lamp's highlight in img - dark (dark may be NULL: then the
// background is the median around the sphere) on the pixels of the sphere's
// image: the brightest on-sphere pixel, its blob (connected pixels >= 20 % of
// the peak; a blob larger than max_blob_px is a broad reflection, not a lamp),
// the intensity-weighted centroid, then a 2-D Gaussian fit (amplitude, centre,
// widths) on the 7x7 window. Found when the peak exceeds min_snr times the
// noise and min_peak_dn. sat_dn: the saturation level of the frame. img and
// dark are width x height. false (message set) only when out of memory; a
// highlight not found is out->found false with out->why.
bool calib_lamps_find_highlight(const float *img, const float *dark, int width, int height,
                                const calib_lamps_sphere_image_t *sph, double min_snr, double min_peak_dn,
                                int max_blob_px, double sat_dn, calib_lamps_highlight_t *out);

// The ray from a highlight toward its lamp: the camera ray through q meets the
// sphere at p_mm, the normal there reflects it into dir (unit). false when the
// ray misses the sphere (message set).
bool calib_lamps_reflect(const model_camera_t *cam, const double q[2], model_vec3_t centre_mm, double radius_mm,
                         model_vec3_t *p_mm, model_vec3_t *dir);

// The highlight's ray toward the lamp from a model of the highlight in
// direction space: every window pixel's camera ray meets the sphere (normal n,
// unit vector to the camera v); a lamp in direction u, a disk of angular
// radius lamp_radius_rad (0: a point; sampled at 37 points w), gives there
// A * mean_w D_ggx(n.h(v, w); alpha) / (n.v) (the mirror's BRDF D G F /
// (4 n.v) with G and F constant over a highlight, D scaled to 1 at its peak),
// point-sampled at the pixel centres as the camera sees it. Fits A, u (2 dof)
// and alpha (Levenberg-Marquardt, numeric Jacobian), starting at the centroid,
// then twice more with weights 1 / (noise^2 + (kappa model)^2) (errors that
// grow with the signal: sampling noise, lobe mismatch; kappa from the residuals);
// the ray starts at the sphere point whose mirror direction is u. *lobe_rad
// (may be NULL): the fitted alpha. false (message set) when the fit fails;
// the caller then keeps calib_lamps_reflect of hl->q.
bool calib_lamps_fit_direction(const model_camera_t *cam, const calib_lamps_highlight_t *hl, model_vec3_t centre_mm,
                               double radius_mm, double lamp_radius_rad, model_vec3_t *p_mm, model_vec3_t *dir,
                               double *lobe_rad);

// The least-squares point nearest n rays (origin p[i], unit direction d[i]),
// with outlier rejection: rays farther than max(reject_sigma * robust scale,
// floor_mm) from the fit are dropped and the fit repeated (at most n/3 rays
// dropped; >= 3 rays always kept).
typedef struct {
    double x_mm[3];
    double cov_mm2[9];       // covariance: s^2 (sum P_i)^-1, s^2 = sum dist^2 / (2 n_used - 3)
    double rms_mm;           // RMS distance of the used rays from x
    int    n_used;
    double min_eig;          // smallest eigen-direction weight of sum P_i (0..n: ray spread)
} calib_lamps_fit_t;
// used (in/out, n): in: rays allowed; out: rays kept. dist_mm (out, n, may be
// NULL): each ray's distance from x. false when fewer than 3 rays or the rays
// are (nearly) parallel (message says which).
bool calib_lamps_triangulate(const model_vec3_t *p, const model_vec3_t *d, int n, double reject_sigma,
                             double floor_mm, bool *used, double *dist_mm, calib_lamps_fit_t *out);


// The joint fit (a bundle adjustment) of the lamps and the sphere's path over
// every highlight of every lamp and angle. Each highlight is kept as the
// camera ray of its centre (from the camera centre, world frame: the sphere
// point of the direction fit seen from the camera), which does not depend on
// where the sphere is. The sphere's centre at turntable angle a is
//   s0 + tilt x s0 + (shift_x, shift_y, 0),   s0 = Rz(a) (c0 + offset)
// offset: an error of the sphere's facts (turns with the table); shift and
// tilt (mrad about x and y): where the calibrated camera puts the table's
// circle relative to itself (an extrinsics error; does not turn; the shift's
// z is the offset's z, the tilt about z the offset's turn). On the virtual
// rig with the camera of `refl calib geometry` the three are needed: with
// offset and shift alone, noise-free highlights still leave ~6 mm lamp
// errors. The ray meets that sphere, is reflected
// there, and the residual is the difference of the unit vectors toward the
// lamp and along the reflected ray, mapped back to the camera ray by the
// inverse of d reflected / d camera ray (held per round): an angle of the
// camera's ray (rad; times the focal length: px), over the lamp's sigma, so
// that a highlight near the sphere's rim (whose reflection turns fast with
// the image position) weighs what its image position is worth. Each
// offset, shift and tilt component has a Gaussian prior (mean 0) of the std given.
typedef struct {
    int          lamp;        // 0..nlamps-1
    double       angle_deg;   // turntable angle (measured)
    model_vec3_t ray;         // unit camera ray of the highlight's centre, world frame
} calib_lamps_obs_t;

typedef struct {
    model_vec3_t camera_mm;        // camera centre, world frame
    double       c0_mm[3];         // sphere centre at angle 0 as given
    double       radius_mm;
    double       offset_prior_mm;  // std of each offset component (<= 0: offset held at 0)
    double       shift_prior_mm;   // std of each shift component (<= 0: shift held at 0)
    double       tilt_prior_mrad;  // std of each tilt component (<= 0: tilt held at 0)
    bool         image_weights;    // residuals mapped back to the camera ray (false: the reflected ray's angle)
    double       offset_prior_mean_mm[3];   // the offset prior's mean (0: c0_mm is the typed centre; a later
                                            // round of calib_lamps_run: the typed centre - c0_mm)
} calib_lamps_bundle_setup_t;

typedef struct {
    double sphere[7];        // offset x, y, z (mm), shift x, y (mm), tilt x, y (mrad)
    double sphere_cov[49];   // their covariance
    double sigma_rad[64];    // per lamp: the std of its highlights' camera rays (rad, from its residuals)
    double rms_rad[64];      // per lamp: RMS residual (camera-ray angle, rad)
    int    iterations;       // solver iterations (all rounds)
    double cond;             // largest / smallest eigenvalue of the sphere block's information (observability)
} calib_lamps_bundle_t;

// x_mm (nlamps*3): in: start positions; out: the fit. cov_mm2 (nlamps*9):
// each lamp's covariance including the sphere's uncertainty. obs_sigma
// (out, nobs, may be NULL): each residual (camera-ray angle, rad). nlamps <= 64.
// false (message set) when the solver fails or a lamp has fewer than 3
// rays.
bool calib_lamps_bundle(const calib_lamps_obs_t *obs, int nobs, int nlamps, const calib_lamps_bundle_setup_t *setup,
                        double *x_mm, double *cov_mm2, double *obs_angle_rad, calib_lamps_bundle_t *out);

// The residual block of one observation for the joint fit: blocks (lamp
// position[3], sphere[7]); 3 residuals. ctx: a calib_lamps_bundle_ctx_t.
// Exposed for the Jacobian check of the tests.
typedef struct {
    const calib_lamps_bundle_setup_t *setup;
    calib_lamps_obs_t                 obs;
    double                            sigma_rad;
    double                            W[9];   // residual = W (u_lamp - u_reflected) / sigma_rad (3x3)
} calib_lamps_bundle_ctx_t;
// W of an observation at lamp position X and sphere parameters g: the inverse
// of d reflected / d camera ray in their tangent planes (last row 0). false
// when the ray misses the sphere.
bool calib_lamps_bundle_weight(calib_lamps_bundle_ctx_t *ctx, const double X[3], const double g[7]);
bool calib_lamps_bundle_residual(void *ctx, const double *const *params, double *res, double **jac);

// ---------------------------------------------------------------------------
// The calibration: calib_lamps_run and its stages
//
// Errors: every stage returns false with one message kept by model_error_set
// (model_last_error()); the functions it calls in model/ and rig/ print theirs
// through model_error unless this thread is quiet (model_error_quiet_thread:
// the command runs the calibration quiet and prints the one message).
// Progress (one line per angle) and notes (capture, frames without a
// highlight, outliers, the joint fit, files written) go through
// model_progress and model_note, the check of the typed sphere centre through
// model_warning.

typedef enum {
    CALIB_LAMPS_CENTROID = 0,   // the highlight's intensity-weighted centroid, reflected
    CALIB_LAMPS_GAUSS = 1,      // the 2-D Gaussian fit in the image, reflected
    CALIB_LAMPS_MODEL = 2,      // calib_lamps_fit_direction (the lamp's disk seen in the mirror)
} calib_lamps_method_t;

enum { CALIB_LAMPS_MAX_ANGLES = 360, CALIB_LAMPS_MAX_EXPOSURES = 16 };

// What to calibrate and how. Strings are borrowed (they must outlive the run).
typedef struct {
    const char  *rig;              // capture on this rig file into out/capture (a complete session there is
                                   // reused); NULL: analyse session
    const char  *session;          // a session captured elsewhere (its plan: the sphere, each lamp alone)
    const char  *camera;           // the camera model (.cameramodel, extrinsics in the rig frame)
    const char  *out;              // output directory: lamps.json, report_data.json, report.html, plots
    const char  *sample;           // the capture plan's sample (default "mirror_sphere")
    char *const *lamps;            // NULL-terminated lamp names; NULL: every lamp of the rig file (capture),
                                   // every lamp set of one lamp alone of the session's plan (session)
    double       angles_deg[CALIB_LAMPS_MAX_ANGLES];        // capture: turntable angles (default 0, 15, ... 345)
    int          nangles;
    double       exposures_us[CALIB_LAMPS_MAX_EXPOSURES];   // capture: auto-bracketing ladder, longest first
    int          nexposures;                                //   (default 40, 20, 10)
    bool         sphere_given;     // the sphere's facts below are set (required: the run fails without them)
    double       sphere_centre_mm[3];   // the sphere's centre at turntable angle 0, rig frame
    double       sphere_radius_mm;
    double       lamp_radius_mm;   // the lamps' emitting radius modelled in the highlights (0: point lamps)
    double       min_snr;          // a highlight's peak / noise at least (default 12)
    calib_lamps_method_t method;   // how a highlight is located (default CALIB_LAMPS_MODEL)
    bool         joint;            // the joint fit of lamps and sphere path after the per-lamp fits (default true)
    double       offset_prior_mm;  // joint fit: priors (std; 0 holds the part at 0), defaults 3 mm (the
                                   //   typed centre's std: the centre is found from the highlights),
    double       shift_prior_mm;   //   0.1 mm and 1 mrad (see calib_lamps_bundle_setup_t)
    double       tilt_prior_mrad;
    int          progress;         // capture progress: -1 auto (a bar on a terminal), 0 lines, 1 bar
    rig_operator_t *op;             // who answers the operator steps (calib_capture)
    int          argc;             // the command line for the provenance (may be 0, NULL)
    char       **argv;
} calib_lamps_opts_t;

// The defaults above; rig/session, camera, out and the sphere's facts unset.
calib_lamps_opts_t calib_lamps_defaults(void);

// One lamp over the session's nangles angles (arrays of nangles, index =
// angle of the plan).
typedef struct {
    char          name[64];
    double        lamp_radius_mm;  // emitting radius modelled in its highlights
    int          *frame;           // session row of the frame used (-1: none in the session)
    calib_lamps_highlight_t *hl;   // the highlight found (hl[a].why says why not)
    bool         *has_ray;         // a ray toward the lamp was found
    model_vec3_t *p_mm;            // ray origin on the sphere, rig frame
    model_vec3_t *d;               // unit ray direction toward the lamp
    bool         *used;            // the ray is in the fit (false: none, or an outlier)
    double       *dist_mm;         // the ray's distance from the fitted position
    int           nmissing;        // angles without a ray
    calib_lamps_fit_t fit;         // the position: per-lamp triangulation, then the joint fit's
} calib_lamps_lamp_t;

typedef struct {
    model_camera_t     *cam;
    char               *session_dir;
    rig_session_t      *session;
    rig_plan_t         *plan;
    int                 nangles;        // the plan's angles
    double             *angle_deg;      // nangles: the journal's measured angle (the plan's where none)
    int                *dark_row;       // nangles: session row of the dark frame (lamp set none; -1: none)
    model_vec3_t       *centre_mm;      // nangles: the sphere's centre the rays were last reflected at
    int                 nlamps;
    calib_lamps_lamp_t *lamps;          // nlamps
    int                 first_angle;    // the first angle with a ray (-1: none): the report's detections
    bool                have_joint;     // the joint fit ran
    int                 joint_nobs;     // highlights in it
    calib_lamps_bundle_t joint;
    // The sphere's centre from the images: calib_lamps_run finds the highlights
    // at the typed centre, and while the joint fit moves it (offset > 0.2 mm,
    // at most 3 rounds) finds them again at the moved one; the typed centre is
    // the offset's prior (mean, std offset_prior_mm), and a check.
    bool                have_typed;     // typed_mm set (by calib_lamps_run)
    double              typed_mm[3];    // the sphere's centre at angle 0 as typed (--sphere-centre-mm)
    double              base_mm[3];     // the centre the last round's highlights were found at (the path's c0)
    int                 rounds;         // rounds of highlights and fits
    double              found_mm[3];    // base + the joint fit's offset: the centre the images give
    double              found_cov_mm2[9];
    json_t             *provenance;
} calib_lamps_result_t;

// The whole calibration: the stages below in order (the joint fit when
// o->joint), lamps.json and the report in o->out. false + message. r is filled as far as the run got;
// free it with calib_lamps_result_free either way.
bool calib_lamps_run(const calib_lamps_opts_t *o, calib_lamps_result_t *r);
void calib_lamps_result_free(calib_lamps_result_t *r);   // accepts a zeroed result

// The capture plan: sample at the angles, each lamp alone and the dark (lamp
// set none) per angle, auto-bracketed exposures (longest first). Caller g_free's.
// centre_mm (may be NULL) and radius_mm: the sphere's facts, for the operator's instruction.
char *calib_lamps_plan_text(const char *sample, const double *centre_mm, double radius_mm, const double *angles_deg,
                            int nangles, char *const *lamps,
                            int nlamps, const double *exposures_us, int nexposures);

// Stage 1: the camera model; with o->rig the capture into o->out/capture;
// the session, its plan and the lamps to calibrate; per angle and lamp the
// frame to use (the longest exposure below 95 % of full scale) and per angle
// the dark frame. r zeroed (or as calib_lamps_run leaves it).
bool calib_lamps_open(const calib_lamps_opts_t *o, calib_lamps_result_t *r);
// Stage 2: per angle the sphere's image, per lamp its highlight and the ray
// toward the lamp (pass 1: a point lamp); fills hl, has_ray, p_mm, d, used,
// nmissing, centre_mm, first_angle.
bool calib_lamps_find_highlights(const calib_lamps_opts_t *o, calib_lamps_result_t *r);
// Stage 3: each lamp the point nearest its rays (outliers dropped); then with
// the lamp's disk (lamp_radius_mm > 0, CALIB_LAMPS_MODEL) its highlights
// fitted again and the point again. Fails when a lamp has fewer than 3 rays
// (every such lamp named in the one message).
bool calib_lamps_triangulate_lamps(const calib_lamps_opts_t *o, calib_lamps_result_t *r);
// Stage 4: calib_lamps_bundle over every used highlight, the highlights
// fitted again at the fitted sphere path, the bundle again; the lamps' fits
// (position, covariance, RMS) replaced by the joint ones.
bool calib_lamps_joint_fit(const calib_lamps_opts_t *o, calib_lamps_result_t *r);
// Stage 5: o->out/lamps.json (units mm, rig frame, provenance).
bool calib_lamps_write_json(const calib_lamps_opts_t *o, calib_lamps_result_t *r);

// lamps.json names its format at its root: "format": "refl-lamps",
// "version": 1. Version 1: "lamps" (per lamp name, position_mm, std_mm,
// covariance_mm2, rms_ray_distance_mm, radius_mm, n_frames, n_outliers,
// frames_missing; `refl calib pattern` adds emission_cos_power,
// emission_axis and emission), "units", "conventions", "camera", "sphere",
// "session", "provenance" (and emission_conventions, emission_session,
// emission_provenance from `refl calib pattern`). A file without "format"
// and "version" reads as version 1.
#define CALIB_LAMPS_JSON_FORMAT "refl-lamps"
enum { CALIB_LAMPS_JSON_VERSION = 1 };
// Every reader of a lamps.json calls this on its parsed root (path for the
// message): false + model_error_set when it is another format or a version
// newer than this refl reads; *version (may be NULL) gets the version read.
bool calib_lamps_json_check(const json_t *root, const char *path, int *version);
// Stage 6: o->out/report_data.json, its plots (scripts/calib_lamps_report.py)
// and o->out/report.html.
bool calib_lamps_write_report(const calib_lamps_opts_t *o, calib_lamps_result_t *r);

// ---------------------------------------------------------------------------
// The lamps' emission patterns (calib/lamps/pattern.c; `refl calib pattern`)
//
// A flat Lambertian target of albedo A (the reference white) lit by each lamp
// alone (at one or more turntable angles): each window's irradiance relative to
// the lamp's on-axis intensity, y = s d^2 / (kd n.l) (kd = A/pi; s the raw
// signal, calib_obs_t's times its emission), is fitted per lamp with the
// model's pattern y = kcI max(0, a.u)^n (u the unit direction from the lamp to
// the window): log residuals weighted by each window's noise (floor 0.1 %),
// Levenberg-Marquardt in ln kcI, n >= 0 and the axis (two tilts across the
// windows' mean direction, prior N(0, 45 deg) that only matters where n ~ 0),
// started at n = 0.5, 3, 10, 30 (the best kept), windows beyond 5 robust std
// dropped (at most a fifth) and fitted again.
typedef struct {
    char         name[64];
    bool         fitted;              // false: fewer than 20 windows (the lamp's entry is left as it was)
    int          nwindows, rejected;  // windows of the lamp (in the fit) and those dropped
    double       n, n_std;            // emission_cos_power and its 1-sigma
    model_vec3_t axis;                // emission_axis (unit, rig frame)
    double       axis_std_deg;        // the axis's 1-sigma (the larger of its two tilts)
    double       tilt_deg;            // the axis against the direction from the lamp to the rig origin
    model_vec3_t cone_centre;         // the windows' mean direction from the lamp
    double       cone_half_angle_deg; // the largest angle of a window's direction from it: the measured cone
    double       kcI_axis_per_us;     // the on-axis kc*I the albedo implies (DN/us at 0 dB per (1/sr)/mm^2)
    double       rms_rel;             // RMS relative residual of the windows
    double       irradiance_std_rel;  // the largest relative 1-sigma of the fitted irradiance over the windows
    double       cov_n_t[9];          // the fit's covariance of (n, t1, t2): the axis is b / |b|, b = the cone
    model_vec3_t axis_per_t[2];       // centre + t1 e1 + t2 e2; axis_per_t[k] = d axis / d t_k (rig frame)
} calib_lamps_pattern_t;

// Each lamp of cal (out: cal->lamps->n) from obs (calib_observe of the target
// through cal). false (model_error_set) on a singular fit or out of memory.
bool calib_lamps_pattern_fit(const calib_obs_set_t *obs, const calib_set_t *cal, double albedo,
                             calib_lamps_pattern_t *out);
// cal's lamps.json (cal->lamps->path) with each fitted lamp's
// emission_cos_power, emission_axis and emission (the figures above), the
// conventions, the session and the provenance, written to out_json (may be
// the same file; atomic). false + message.
bool calib_lamps_pattern_write(const calib_set_t *cal, const calib_lamps_pattern_t *pat, const char *session,
                               const char *out_json, json_t *provenance);
// The report of the fit in dir (made): pattern_windows.csv (per window: lamp,
// angle from the fitted axis in degrees, irradiance relative to the on-axis
// value, the fitted pattern there, relative noise), pattern.png
// (scripts/calib_pattern_report.py) and report.html. false + message.
bool calib_lamps_pattern_report(const calib_obs_set_t *obs, const calib_set_t *cal, double albedo,
                                const calib_lamps_pattern_t *pat, const char *dir, const json_t *provenance);

#ifdef __cplusplus
}
#endif
