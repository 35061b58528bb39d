// calib/calib.h — calibrations of the rig: camera geometry and turntable axis
// (mrgingham + mrcal), lamp positions (mirror-sphere highlights) and the
// camera's sensitivity (EMVA 1288 style). Each calibration captures through
// capture sessions (rig/rig.h) or reads frames captured elsewhere, writes its
// files (JSON summary with units and provenance, float TIFF maps,
// .cameramodel) and an HTML report with plots into one output directory.
//
// Conventions: lengths in mm, angles in degrees, pixel coordinates with (0, 0)
// at the centre of the top-left pixel, grey values in DN of the frame's pixel
// format (Mono12: 0..4095, unscaled), exposures in microseconds. The rig
// frame: origin at the turntable top centre, z up along the rotation axis.
#pragma once

#include <jansson.h>
#include <stdbool.h>
#include <stdint.h>
#include <stdio.h>

#include "model/base/opts.h"
#include "rig/rig.h"

#ifdef __cplusplus
extern "C" {
#endif

// `refl calib geometry|lamps|gain ...` (calib/cmd_calib.c dispatches).
int calib_cmd(int argc, char **argv);
int calib_cmd_geometry(int argc, char **argv);
int calib_cmd_lamps(int argc, char **argv);
int calib_cmd_pattern(int argc, char **argv);   // the lamps' emission patterns (calib/cmd_lamps.c)
int calib_cmd_gain(int argc, char **argv);

// ---------------------------------------------------------------------------
// Capture sessions of a calibration (calib/capture.c)

// Run a capture plan (its text) on the rig file rig_path into the session
// directory dir/name. The plan is first written to dir/name.plan.ini (kept as
// the record). A complete session of the same plan is reused as it is; a
// paused or stopped one is resumed. progress: as rig_capture_opts_t (-1 auto).
// op: who answers the plan's operator steps (rig_operator_t; NULL: the
// terminal); after a pause rig_operator_paused(op) is true (the command exits 3).
// 0, or -1 with the reason in model_last_error().
int calib_capture(const char *rig_path, const char *dir, const char *name, const char *plan_text, int progress,
                  rig_operator_t *op);
// The full scale (DN) a calibration takes for a session frame's pixel
// format: Mono8 255, Mono12 4095, any other 65535.
int calib_full_scale_dn(const char *pixel_format);

// ---------------------------------------------------------------------------
// The calibration set and calibrated observations (calib/calset.c,
// calib/observe.c, calib/white.c)
//
// The grey value model (model/model.h): P = Pa + kc g(x,y) sum_i V_i I_i R_i / d_i^2.
// An observation is a window (w x w pixels, all on one face of the material,
// lit by the frame's single lamp) in one frame: its mean grey value minus the
// dark level (the gain calibration's offset map, else the session's dark frame
// of that exposure), divided by the flat field g (the gain calibration's map,
// when given), per microsecond of exposure and at 0 dB: s = (P - Pa) / (g t 10^(G/20))
// in DN/us, divided by the lamp's emission pattern toward the window (lamps.json's
// emission_cos_power and emission_axis; 1 for an isotropic lamp). Exposure brackets are merged to high dynamic range by keeping, per
// window, angle and lamp, the longest exposure whose window stays below 95 % of
// saturation.
//   reference white of albedo a (Lambertian, kd = a/pi): kcI_i = s d^2 / (kd n.l)
//   a material: R = s d^2 / kcI_i  (f_r cos theta_i, 1/sr)

// A lamp's stated uncertainties in lamps.json (calib/calset.c reads them; the
// white's uncertainty propagates them, calib_white): the position's
// covariance (covariance_mm2, else std_mm squared on the diagonal) and the
// emission pattern's: the covariance of (n, t1, t2) with axis_per_t the
// axis's change per unit t_k (rig frame; emission.covariance_n_t1_t2 and
// emission.axis_per_t1/_t2 of refl calib pattern, else cos_power_std and
// axis_std_deg as independent, the t_k tilts in radians across the axis).
// d ln E(u) = dn ln(a.u) + n sum_k dt_k (axis_per_t[k] . u) / (a.u).
typedef struct {
    bool         have_position;
    double       position_cov_mm2[9];
    bool         have_pattern;
    double       n;                   // the pattern's n and axis (also where n = 0: isotropic)
    model_vec3_t axis;
    double       pattern_cov[9];      // (n, t1, t2)
    model_vec3_t axis_per_t[2];
} calib_lamp_sigma_t;

// The calibration set a measurement uses (loaded from a calibration directory;
// calib/calset.c).
typedef struct {
    model_camera_t *cam;            // geometry: camera.cameramodel (extrinsics in the rig frame)
    model_lamps_t  *lamps;          // lamps.json positions (intensity 1) and emission patterns (n = 0: isotropic)
    float          *offset_dn;      // gain calibration: dark offset map (NULL: use dark frames)
    float          *flat;           // gain calibration: flat field g(x,y), mean 1 (NULL: 1)
    double          saturation_dn;  // 0: from the frame's bits
    char            camera[32];     // the camera of the set ("": a calibration of one camera, no selector)
    double          cal_gain;       // the gain the gain calibration was made at (gain.json gain_db; 0 without)
    char            cal_gain_unit[16];  // its unit (gain.json gain_unit; "dB" without: a version 1 file may lack it)
    double          gain_dn_per_e;  // gain calibration's K at its gain (0: unknown)
    double          read_noise_e;   // its read noise
    model_lin_t     lin;            // the gain calibration's response linearisation at its gain (model_linearise)
    int             W, H;
    bool            have_white;
    double          kcI_per_us[32]; // white.json: kc I per lamp (DN/us at 0 dB per (1/sr)/mm^2)
    double          lamp_radius_mm[32]; // lamps.json radius_mm per lamp (0 absent: a point lamp)
    calib_lamp_sigma_t lamp_sigma[32];  // lamps.json: each lamp's stated 1-sigmas (position, pattern)
    double          flat_pixel_std_rel; // gain.json flat_field.pixel_std_rel: the flat map's noise per pixel,
                                    // relative (NAN: not stated)
    bool            have_psf;       // the geometry run estimated the lens's blur (geometry.json beside the camera
                                    // model; calib_psf_read): false when it did not or the file is absent
    double          psf_sigma_px;   // the optics' Gaussian PSF sigma (the pixel's 1 px footprint apart), px
    double          psf_sigma_std_px;   // its 1-sigma
    double          psf_pixel_fill; // the footprint the board's edges showed: 1 the pixel's square, 0 a point at its
                                    // centre (a renderer's one ray a pixel); 1 without an estimate
    json_t         *inputs;         // [{role, path, sha256}] of every file read
    int             lamps_version, gain_version, white_version;   // the format versions read (0: no such file)
} calib_set_t;

// Load DIR: camera.cameramodel (or geometry/camera.cameramodel), lamps.json
// (or lamps/lamps.json), optionally gain.json with offset_dn.tiff and
// flat_field.tiff or prnu_gain.tiff (or gain/...), and white.json (or
// white/white.json). need_white: white.json is required. Each JSON file's
// format and version is checked (model_json_format_check): lamps.json
// "refl-lamps" version 1, gain.json CALIB_GAIN_FORMAT up to
// CALIB_GAIN_FORMAT_VERSION (calib/gain/gain.h), white.json
// CALIB_WHITE_FORMAT up to CALIB_WHITE_FORMAT_VERSION; a file of another
// format or a newer version is refused. NULL + message.
calib_set_t *calib_set_load(const char *dir, bool need_white);
// The calibration set of camera NAME of a calibration directory of several
// cameras (camera NULL: calib_set_load). Its camera model: DIR/NAME.cameramodel,
// DIR/geometry/NAME.cameramodel or DIR/NAME/camera.cameramodel; its gain
// calibration: DIR/NAME/gain.json or DIR/gain/NAME/gain.json (refl calib gain
// of several cameras), else DIR/gain.json (or gain/gain.json) when that one
// records camera NAME; its reference white: DIR/NAME/white.json or
// DIR/white/NAME/white.json (a white of another camera does not apply: kc is
// the camera's); the lamps: the directory's lamps.json, shared. NULL + message.
calib_set_t *calib_set_load_camera(const char *dir, const char *camera, bool need_white);
// DIR has a camera model of camera NAME (one of calib_set_load_camera's;
// NULL: the layout of one camera's, calib_set_load's).
bool         calib_set_has_camera(const char *dir, const char *camera);
// The same from explicit files: camera model and lamps.json required, gain.json
// (its maps beside it) and white.json optional (NULL).
calib_set_t *calib_set_load_files(const char *camera, const char *lamps_json, const char *gain_json,
                                  const char *white_json);
void         calib_set_free(calib_set_t *c);
// The lens's blur of the geometry calibration that wrote camera_model: the
// "psf" of geometry.json in the model's directory (calib/geometry/psf.c writes it;
// camera NAME of several: its cameras[].psf, else the top level's, the first
// camera's; camera NULL: the model file's name, NAME.cameramodel). true with
// the optics' Gaussian sigma and its 1-sigma (px; the pixel's footprint is
// not in it), the footprint the edges showed (*pixel_fill: 1 the pixel's
// square, 0 a point at its centre; 1 in files without it; may be NULL) and
// the file's path (g_free; geometry_json may be NULL); false (no message)
// when there is no such file or it has no estimate; false + a warning
// (model_warning; the message kept, model_last_error) when the file is of
// another format or a newer version (calib_geometry_json_check).
bool calib_psf_read(const char *camera_model, const char *camera, double *sigma_px, double *sigma_std_px,
                    double *pixel_fill, char **geometry_json);

typedef struct {
    int             lamp;           // index in calib lamps
    double          angle_deg;      // measured turntable angle
    double          exposure_us, gain_db;   // gain_db: the frame's gain relative to the calibration's, dB
    double          q[2];           // window centre, pixels
    model_cosines_t c;
    bool            has_disc;       // lit by a finite lamp near the mirror direction: disc holds the
    model_cosines_t disc[4];        // cosines of its 4 quadrature directions (fit_samples_t)
    double          d_mm;
    double          s_dn_per_us;    // dark and flat corrected signal per us at 0 dB, divided by the lamp's
                                    // emission pattern toward the window (emission below): the signal of
                                    // the lamp's on-axis intensity
    double          emission;       // that factor, model_lamp_emission (exactly 1 for an isotropic lamp)
    double          drift;          // the lamp's intensity at the frame's time relative to its first visit of
                                    // the reference, also divided out of s (calib_drift_factor; 1 without)
    double          s_std;          // its expected temporal noise (shot, read, quantisation of the
                                    // window mean; dark level noise-free), same unit; 0 without K
    int             step;           // the session step of the frame
    int             face;           // the scene face the window lies on
    double          p0_mm[3];       // the window centre's surface point, rig frame at angle 0 (it
                                    // turns with the table: the same point of the sample at every angle)
    double          n0[3];          // the surface's unit normal there, rig frame at angle 0
} calib_obs_t;

// Lamp drift (calib/lamps/drift.c): a plan whose [angles] list has an angle
// more than once (list = 0 30 60 0 90 120 0 ...) takes every lamp set and
// exposure there again: the reference, revisited. Each lamp alone's frames
// there (grouped by angle, exposure and gain; the group of the most visits)
// against its first visit: the median over the lit (above a fifth of the
// brightest), unsaturated pixels of (P_k - dark) / (P_0 - dark) is the lamp's
// intensity at that time relative to the first visit. Between visits a
// monotone cubic in time through every visit (PCHIP; the frames' trigger
// time), constant before the first and after the last. calib_observe divides every observation of the lamp by it.
typedef struct {
    int    nlamps;
    int    nvisits[32];               // per lamp of the calibration set (< 2: no correction)
    double *t_s[32], *f[32];          // its visits' trigger times (s, UTC) and relative intensities (f[0] = 1)
    char   angle_ref[32][320];        // the reference used: "LAMP at DEG deg, US us"
} calib_drift_t;
// From the session s and its plan; every lamp without revisits gets none.
// false + message (kept) when a revisit cannot be compared.
bool   calib_drift_measure(const rig_session_t *s, const rig_plan_t *p, const calib_set_t *cal, calib_drift_t *d);
double calib_drift_factor(const calib_drift_t *d, int lamp, double t_s);
void   calib_drift_free(calib_drift_t *d);

// ---------------------------------------------------------------------------
// The sample's pose fitted from its own frames (calib/sample_pose.c)
//
// A coupon on its wedge is placed by hand: the wedge's angle, the coupon not
// flush, a millimetre off. Its pose is fitted from the session's frames: at
// each turntable angle the frames lit by one lamp are summed, the coupon's
// outline (model_edges_predict at the nominal pose: the edges with the
// background on one side) is sampled every ~0.5 mm, and at each sample the
// image's edge (the steepest fall from the coupon to the background along the
// edge's normal) is found; least squares (model/base/lsq.h) of those distances over
// the pose, with the nominal wedge pose as a Gaussian prior, search and fit
// repeated three times (8, 3, 2 px). The pose's parameters p[6]:
//   tilt_deg, tilt_azimuth_deg  the wedge (model_scene_wedge_pose: the normal)
//   dx_mm, dy_mm                the in-plane offset, in the sample's own frame
//                               (the wedge's face) before the wedge's rotation
//   dz_mm                       the height, along the rig's z
//   turn_deg                    a turn about the sample's own z through its
//                               centre (the middle of its bounding box in x, y)
// x = Rw (Rz(turn) (x0 - c) + c + (dx, dy, 0)) + tw + (0, 0, dz) with Rw, tw
// the wedge's pose of tilt and azimuth; the nominal: the plan's wedge, 0, 0,
// 0, 0. The covariance is (J^T J)^-1 with the residuals scaled by their RMS (px).
typedef struct {
    double sigma_deg;     // the prior's std of tilt, azimuth and turn (default 1 deg: the fixture's)
    double sigma_mm;      // of the offsets and the height (default 2 mm)
    int    min_samples;   // fewer edge samples found: the nominal is kept (default 60)
    bool   verbose;
} calib_sample_pose_options_t;

typedef struct {
    bool   tried;          // a fit was asked for
    bool   fitted;         // p is the fit's (false: the nominal is kept; note says why)
    bool   at_prior_edge;  // a parameter ended more than 2.5 prior std from the nominal (warning)
    double nominal[6];     // the plan's: tilt, azimuth, 0, 0, 0, 0
    double p[6], sd[6];    // the pose used and its std (prior std when not fitted)
    double cov[36];
    double normal[3];      // the sample's +z in the rig frame at angle 0 (the pose used)
    double prior_sd[6];
    int    nsamples, nangles;   // edge samples (and angles) that entered the fit
    double rms_px;         // their residual RMS
    char   note[600];      // why the nominal was kept, or the warning; "" when none
} calib_sample_pose_t;

calib_sample_pose_options_t calib_sample_pose_defaults(void);
// The pose's rigid move of the sample's scene (its own frame, at angle 0
// before any wedge): x = R x0 + t.
void calib_sample_pose_Rt(const model_scene_t *scene, const double p[6], double R[9], double t[3]);
// Fit the pose of scene (unposed) in session s (its plan p) through cal's
// camera. Weak or missing edges, a failed solve or a singular covariance
// keep the nominal (out->fitted false, out->note why): true. false + message
// (kept) only for a frame that cannot be read.
bool calib_sample_pose_fit(const rig_session_t *s, const rig_plan_t *p, const calib_set_t *cal,
                           const model_scene_t *scene, const calib_sample_pose_options_t *o,
                           calib_sample_pose_t *out);
// One line (and the note on a second), for a command's output.
void    calib_sample_pose_print(FILE *f, const calib_sample_pose_t *ps);
// The pose as JSON: mode, parameters with nominal, value, std and
// difference, the normal, the edge samples, the note.
json_t *calib_sample_pose_json(const calib_sample_pose_t *ps);

typedef struct {
    int        n, cap;
    calib_obs_t *o;
    calib_drift_t drift;         // the session's lamp drift (nvisits 0: none measured)
    int        frames_used, frames_skipped;
    int        window_px;        // the windows' size (N x N pixels)
    char       sample[64], material[64];
    calib_sample_pose_t pose;    // the sample's pose used (pose.tried: fitted from the frames, else the nominal)
} calib_obs_set_t;

typedef struct {
    const char *scene_path;     // the sample's scene (rig frame, mm, at angle 0 before the plan's wedge);
                                // required: a session records no scene (NULL is an error saying so)
    const char *material;       // the material to observe; NULL: the scene's only material
    double      scene_unit_mm;  // mm per unit of the scene file (0: mm, not said; --units)
    int         window;         // window size, pixels (default 5)
    int         step;           // grid step between windows, pixels (default 8)
    double      min_signal_dn;  // windows below this (after dark) are dropped (default 20)
    bool        fit_pose;       // the sample's pose fitted from the frames (calib_sample_pose_fit); false
                                // (default): the plan's nominal wedge
    calib_sample_pose_options_t pose;   // its options (calib_sample_pose_defaults)
    bool        verbose;
} calib_observe_options_t;

calib_observe_options_t calib_observe_defaults(void);
// Observations of the session's sample material (opt->scene_path posed on
// the plan's wedge, turned to each frame's measured angle), in the frames of
// cal->camera (the session's first camera when cal has none). false + message
// (names the session, file or frame), kept in model_last_error() and not
// printed: the caller reports it once.
bool calib_observe(const char *session_dir, const calib_set_t *cal, const calib_observe_options_t *opt,
                   calib_obs_set_t *out);
void calib_obs_free(calib_obs_set_t *s);

// The reference white's reflectance-factor table (its certificate's; the
// format's one owner is calib/white.c, README "Reference white"): a CSV file
// with the header line theta_i_deg,theta_r_deg,factor and one row per
// (incidence, viewing) angle pair, angles from the standard's normal in
// degrees [0, 90), factor the reflectance factor R (the standard's radiance
// over a perfect Lambertian reflector's under the same light and view: the
// BRDF is R/pi; azimuth not resolved), in (0, 2]. The rows form a full grid
// (every theta_i with every theta_r; a single theta_r value: a table by
// incidence only); '#' lines and blank lines are skipped.
// A fourth column factor_std (header theta_i_deg,theta_r_deg,factor,factor_std)
// gives the certificate's 1-sigma of each factor.
typedef struct {
    int     ni, nr;          // grid sizes
    double *ti, *tr;         // the angles, ascending (degrees)
    double *f;               // f[i * nr + r]
    double *fs;              // its 1-sigma (NULL: the table states none)
    char    path[4096];
    char    sha256[65];
} calib_white_table_t;

// NULL + message "file:line: ..." (model_error).
calib_white_table_t *calib_white_table_load(const char *path);
calib_white_table_t *calib_white_table_parse(const char *text, size_t len, const char *name);
void                 calib_white_table_free(calib_white_table_t *t);
// R at (theta_i, theta_r) in degrees: bilinear in the grid, clamped at its
// edges (*outside, may be NULL, set true when an angle lies beyond them).
double calib_white_table_factor(const calib_white_table_t *t, double theta_i_deg, double theta_r_deg,
                                bool *outside);

// The factor's 1-sigma at (theta_i, theta_r) as calib_white_table_factor
// interpolates the factor; NAN when the table states none.
double calib_white_table_factor_std(const calib_white_table_t *t, double theta_i_deg, double theta_r_deg);

// The samples' region (where coupons lie on the table, rig frame at angle 0):
// x, y within +-60 mm, z 5 and 50 mm, on a grid of 20 mm (7 x 7 x 2 points);
// white.json states each lamp's irradiance uncertainty there and refl chain
// compares the lamps' light there.
#define CALIB_REGION_HALF_MM 60.0
#define CALIB_REGION_STEP_MM 20.0
#define CALIB_REGION_Z0_MM   5.0
#define CALIB_REGION_Z1_MM   50.0
// The region's grid points into q (at most CALIB_REGION_MAX); their number.
#define CALIB_REGION_MAX 128
int calib_region_points(model_vec3_t *q);

// The white's uncertainty: every part a relative 1-sigma of kc*I from a stated
// input (NAN: that input states none), the total their quadrature sum.
enum { CALIB_WHITE_STAT, CALIB_WHITE_POSITION, CALIB_WHITE_PATTERN, CALIB_WHITE_ALBEDO, CALIB_WHITE_FLAT,
       CALIB_WHITE_NPARTS };
extern const char *const calib_white_part_names[CALIB_WHITE_NPARTS];

typedef struct {
    double albedo_std;   // the certificate's 1-sigma of the albedo (or of every factor of a table without a
                         // factor_std column); NAN: none stated
    int    draws;        // draws of each sampled input (default 400)
    uint64_t seed;       // of the draws (default 1)
} calib_white_options_t;
calib_white_options_t calib_white_defaults(void);

typedef struct {
    char   name[64];
    int    n;                                  // observations
    double kcI_per_us, kcI_lambertian_per_us;  // the median (and with the Lambertian assumption)
    double spread_rel;                         // scaled MAD / median
    double part_rel[CALIB_WHITE_NPARTS];       // relative 1-sigma of kc*I per part (NAN: not stated)
    double std_rel;                            // their quadrature sum
    // the irradiance kc*I E(q) / |q - L|^2 over the samples' region: the
    // largest total relative 1-sigma, where, and its parts there
    double irr_std_rel, irr_part_rel[CALIB_WHITE_NPARTS];
    model_vec3_t irr_worst_mm;
} calib_white_lamp_t;

// kc*I and its uncertainty per lamp of cal (out: cal->lamps->n) from obs, as
// calib_white writes them. The statistical part is the median's standard
// error (1.2533 MAD / sqrt(n)); the lamp position's and the pattern's are
// sampled through the same computation (o.draws draws of the position from
// its covariance, each observation's d, n.l, table factor and emission
// recomputed; draws of the pattern's (n, t1, t2) from its covariance, ln E
// moved linearly); the albedo's is the certificate's relative 1-sigma (a
// table's factor_std: its mean relative value over the observations, taken
// as fully correlated); the flat field's is its per-pixel noise over
// sqrt(window pixels x distinct windows), x 1.2533 for the median. false +
// message (model_error) for a lamp with fewer than 10 observations.
bool calib_white_compute(const calib_obs_set_t *obs, const calib_set_t *cal, double albedo,
                         const calib_white_table_t *table, const calib_white_options_t *o, calib_white_lamp_t *out,
                         const char *out_json);

// Reference white: kc*I per lamp (median over its observations) and the
// relative spread; writes DIR/white.json (with the camera, cal->camera, when
// it has one). table NULL: a Lambertian standard of albedo (e.g. 0.99), kd =
// albedo/pi; else each observation's BRDF is the table's factor at its
// incidence and viewing angles over pi (albedo unused), and white.json states
// the white's departure from Lambertian over the observed geometries and
// what the Lambertian assumption (the table's factor nearest the normal)
// would have given.
// Each lamp's kc_I_std_per_us, std_rel and sigma_parts_rel (calib_white_compute;
// o NULL: calib_white_defaults) and its irradiance_samples_region. lamps_out
// (may be NULL) gets every lamp's figures (cal->lamps->n), for the command
// to print. false + message (model_error).
// white.json names its format, "refl-white", and version (model_json_set_format):
//   version 1  the layout above; a file that names no format reads as it.
#define CALIB_WHITE_FORMAT         "refl-white"
#define CALIB_WHITE_FORMAT_VERSION 1
bool calib_white(const calib_obs_set_t *obs, const calib_set_t *cal, double albedo,
                 const calib_white_table_t *table, const calib_white_options_t *o, const char *out_json,
                 json_t *provenance, calib_white_lamp_t *lamps_out);

// The calibration set of calib_dir for camera (calib_set_load_camera; NULL:
// calib_set_load) and the observations of the session through it
// (calib_observe: that camera's frames). false + message (kept, not printed,
// as calib_observe's); *cal is set (or NULL) and out emptied either way: the
// caller frees both.
bool calib_observe_session(const char *session_dir, const char *calib_dir, const char *camera, bool need_white,
                           const calib_observe_options_t *opt, calib_set_t **cal, calib_obs_set_t *out);
// Provenance of a result from observations: the command (argv[0] "refl"), the
// session and every calibration file read.
json_t *calib_observe_provenance(int argc, char **argv, const char *session_dir, const calib_set_t *cal);

// `refl calib white` (calib/cmd_calib.c).
// The observation grid's options of a command (--window N, --step N: whole
// pixels 1..64) after model_cli_parse; MODEL_CLI_OK or a usage error (2).
int calib_cli_window_step(model_cli_t *cli, int *window, int *step);
int calib_cmd_white(int argc, char **argv);

#ifdef __cplusplus
}
#endif
