// calib/geometry/geometry.h — `refl calib geometry` as a library: the camera model
// (mrgingham corners, mrcal solve), the turntable axis from the board poses
// and the camera's extrinsics in the rig frame. Public within calib/ and to
// the tests; the command (argument parsing, calib/cmd_geometry.c) is
// calib_cmd_geometry (calib/calib.h).
//
// calib_geometry_run does it all; its stages, in order, are declared below so
// that a test can run one on data of its own:
//   1. views: calib_geometry_capture (--rig: one session per tilt), then
//      calib_geometry_add_session / calib_geometry_add_images (8-bit copies in
//      DIR/images) or calib_geometry_parse_corners (--corners);
//   2. corners: calib_geometry_find_corners (mrgingham for a square
//      chessboard, else OpenCV through calib/geometry/board_detect.h → DIR/corners.vnl;
//      views with fewer than min_corners corners left out with the reason);
//   3. solve: calib_geometry_solve (mrcal-calibrate-cameras and
//      scripts/calib_geometry_report.py solution) and
//      calib_geometry_apply_solution (poses into the views, the camera);
//   4. axis and rig frame: calib_geometry_fit_axis, calib_geometry_rig_frame,
//      calib_geometry_explain_missing (why a view has no board);
//   5. outputs: calib_geometry_write_cameramodel, calib_geometry_json,
//      calib_geometry_report (DIR/camera.cameramodel, geometry.json, report.html).
//
// Several cameras (sessions of a rig with several and no --camera): every
// camera's frames become views DIR/images/NAME/fGGSSSSSS.png (GG the session,
// SSSSSS the step: one frame number per board pose, the same in every camera),
// scripts/calib_geometry_report.py align makes mrgingham's corner order of
// each frame agree across the cameras (DIR/corners-joint.vnl), and one mrcal
// solve calibrates every camera and its pose relative to camera 0 (the first).
// The axis and the rig frame come from camera 0's views; camera k's rig pose
// is rt_camk_cam0 (the joint solve) composed with camera 0's. Outputs also
// DIR/NAME.cameramodel per camera (DIR/camera.cameramodel stays camera 0's)
// and geometry.json's "cameras".
//
// Units: lengths mm, angles deg (rotation vectors r in rad), pixels px with
// (0, 0) the centre of the top-left pixel. Poses are mrcal's rt (r: rotation
// vector, rad; t: mm); rt_a_b maps coordinates in frame b to frame a.
// Errors: false / NULL with the message kept by model_error_set
// (model_last_error), not printed: the caller prints it once. What the run
// does, the views without a board and why, and the views left out of a fit
// are notes and warnings (model_note, model_warning: the dispatcher names
// the command); a failed tool's last messages are a warning before its error.
#pragma once

#include <glib.h>
#include <jansson.h>
#include <mrcal/mrcal.h>
#include <stdbool.h>
#include <stddef.h>

#include "calib/geometry/board_detect.h"
#include "model/model.h"
#include "rig/rig.h"
#include "rig/session/session.h"

#ifdef __cplusplus
extern "C" {
#endif

// The default tilts (--tilts) and angles (--angles-deg) of the example rig (camera
// ~900 mm away, 35 deg above the table, board 130 mm off the axis): chosen
// greedily for imager coverage among the poses where the whole board is in
// view at < 45 deg obliquity, plus two flat views (tilt 0) for the rig frame.
#define CALIB_GEOMETRY_DEFAULT_TILTS                                                                           \
    "0:40,240 20@0:0,10,40,340 20@90:290,300,320,350 20@180:210,240,260,270 35@0:10,20,40 "                     \
    "35@180:210,230,240 50@0:20,30,40 50@180:210,220,230,240"
#define CALIB_GEOMETRY_DEFAULT_ANGLES "0 40 80 120 160 200 240 280 320"
// Tilts for the two-camera example rig (examples/virtual-rig-2cam.ini: the
// cameras 65 deg apart in azimuth, each seeing the 330 mm board whole only near
// the middle of its view): the poses (of tilt 0 and five tilts at every 10 deg)
// where at least one camera finds the board; 21 of the 111 both cameras do
// (they tie the cameras together).
#define CALIB_GEOMETRY_TILTS_2CAM_EXAMPLE                                                                      \
    "0:20,40,60,160,200,220,240,300,320 "                                                                          \
    "20@0:0,10,20,30,40,50,60,70,110,160,200,210,220,230,290,300,310,320,330 "                                    \
    "20@270:20,30,40,50,60,70,80,90,100,110,120,130,140,160,170,210,220,230,240,250,310,320,330,340 "             \
    "20@90:20,30,130,140,150,160,170,210,220,230,270,280,290,300,310,320,330,340 "                                \
    "35@90:150,160,200,220,230,240,250,260,270,280,290,300,310,320,330,340,350 "                                  \
    "20@180:30,40,50,60,70,80,110,120,140,150,160,180,190,200,210,220,230,240,250,260,290,300,310,320"

// --tilts NAME: "2cam-example" is CALIB_GEOMETRY_TILTS_2CAM_EXAMPLE; any other
// text is itself.
const char *calib_geometry_tilts_expand(const char *tilts);

// Who finds the corners: auto is mrgingham for a square chessboard (it finds
// nothing else), OpenCV for the others (calib/geometry/board_detect.h).
typedef enum { CALIB_DETECTOR_AUTO = 0, CALIB_DETECTOR_MRGINGHAM, CALIB_DETECTOR_OPENCV } calib_detector_t;
// The detector auto (or d) comes to for board b.
calib_detector_t calib_geometry_detector(calib_detector_t d, const calib_board_t *b);
// The corners a view needs by default (--min-corners): 12, at most the board's.
#define CALIB_GEOMETRY_MIN_CORNERS 12

// What to calibrate from (exactly one of rig, sessions, images, corners) and how.
typedef struct {
    const char  *rig;              // capture on this rig file (one session per tilt), or NULL
    const char *const *sessions;   // capture sessions (nsessions), or NULL
    int          nsessions;
    const char  *images;           // a glob of images captured elsewhere, or NULL
    const char  *corners;          // mrgingham's corners file (needs imager_w, imager_h), or NULL
    const char  *out;              // the output directory (created)
    const char  *lensmodel;        // mrcal's name, e.g. "LENSMODEL_OPENCV8"
    const char  *tilts, *angles;   // --rig: "T[@AZ][:A,A,...] ..." and the default angles "A A ..."
    const char  *sample;           // --rig: the board's sample name
    const char  *camera;           // --rig, sessions: the camera (rig file name) whose frames are used;
                                   // NULL: the first camera
    double       exposure_us;      // --rig: the capture's exposure
    calib_board_t board;           // the board: kind, inner corners width_n x height_n, spacing_mm (the
                                   // squares'), charuco marker_mm and dict
    calib_detector_t detector;     // who finds the corners (auto: mrgingham for square chessboards)
    int          min_corners;      // a view with fewer corners is left out (the reason said); 0: the default
    double       board_height_mm;  // corner plane above the table top at tilt 0
    double       focal_px;         // mrcal's seed focal length; NAN: 1.4 x the imager width
    double       distance_mm;      // distance of the projection-uncertainty figure
    int          imager_w, imager_h;   // px; 0: from the images (needed with corners)
    int          min_views;        // views with a board the solve needs; 0: by lens model
    int          progress;         // calib_capture's progress mode
    rig_operator_t *op;             // who answers the operator steps (calib_capture)
    int          argc;             // the command line, for the provenance (may be 0)
    char       **argv;
} calib_geometry_opts_t;

// The defaults above, LENSMODEL_OPENCV8, board calib_board: a chessboard of
// 10x10 corners 30 mm apart 5 mm above the table (ChArUco: marker 0.75 of the
// square, DICT_4X4_50), detector auto, 6000 us, distance 900 mm.
calib_geometry_opts_t calib_geometry_defaults(void);

// Views a lens model needs at least (a rule of thumb: 20 splined, 4 pinhole,
// 6 OPENCV4, 7 OPENCV5, else 10).
int calib_geometry_default_min_views(const char *lensmodel);

// One image of the board.
typedef struct {
    char   *name;            // image name in DIR/images (and in the corners file)
    char   *source;          // the original frame or image path
    char   *session;         // session directory, NULL for images/corners
    int     group;           // tilt group (session index), -1 none
    double  angle_deg;       // turntable angle (measured), NAN unknown
    double  tilt_deg, tilt_azimuth_deg;   // NAN unknown
    bool    found;           // the board was found (at least min_corners of its corners)
    char    why[320];        // why not found / not used
    char    detector[32];    // who found the corners ("opencv-sb" ..., calib_board_how_t; "mrgingham",
                             // "corners file"); "" none
    char    attempts[400];   // the OpenCV detectors tried and each one's outcome; "" none tried
    double *q;               // width_n*height_n*2 corners, px, in the board's order (corner (i, j) at
                             // 2 (j width_n + i)); NAN where not seen (a partial view); NULL: none
    int     ncorners;        // corners seen (not NAN) in q
    bool    solved;          // mrcal has a pose for it
    double  rt_cam_board[6]; // mrcal's pose (corner order as mrgingham's), then quarter-turn corrected
    int     quarter_turns;
    int     camera;          // index into the state's cameras (0: the first, the only one of a single camera)
    double  rms_px;          // mrcal's RMS residual of the view, NAN unknown
    int     outliers;
} calib_geometry_view_t;

// The views and their tilt groups (one group per session).
typedef struct {
    GPtrArray *v;            // calib_geometry_view_t*, owned
    int        ngroups;
    double    *group_tilt, *group_az;   // ngroups each: the session's tilt and hinge azimuth, deg
} calib_geometry_views_t;

void calib_geometry_views_init(calib_geometry_views_t *vs);
void calib_geometry_views_free(calib_geometry_views_t *vs);
// The view of that name (or of that base name); NULL.
calib_geometry_view_t *calib_geometry_view_find(calib_geometry_views_t *vs, const char *name);

// The turntable axis in the camera frame.
typedef struct {
    bool    ok;
    double  a[3], c[3];             // direction (unit) and a point, camera frame, mm
    double  dir_unc_deg, point_unc_mm, off_axis_rms_deg, point_rms_mm;
    int     npairs, nviews;
    json_t *fit;                    // per group: angle_deg[], rotation_about_axis_deg[] (owned)
    // calib_geometry_refine_axis (joint true): a, c, dir_unc_deg, point_unc_mm from the joint fit
    // (point_unc_mm: RMS distance across the axis, both directions; 1 sigma, scaled by the fit's
    // chi^2 per degree of freedom when above 1)
    bool    joint;
    int     joint_views;
    double  joint_rms_px, joint_chi2;
    double  rig_x_unc_deg;          // the rig frame's x: rotation about the axis of the tilt-0 board, 1 sigma
    double  rig_origin_along_mm;    // the rig origin along the axis (the tilt-0 board's height), 1 sigma
    double  dir_unc_fit_deg;        // the joint fit's own direction sigma; dir_unc_deg adds in quadrature
    double  dir_unc_intrinsics_deg; // the camera frame's turn from the principal point's sigma (NAN: unknown)
} calib_geometry_axis_t;

// Everything a run has found so far; the stages fill it in order.
typedef struct {
    calib_geometry_views_t views;
    json_t         *prov;           // provenance (model_provenance), owned
    char           *outdir;         // absolute output directory (free)
    char           *imgdir, *mdir;  // DIR/images, DIR/mrcal (g_free)
    char           *cornpath;       // the corners file used (g_free)
    char          **sessions;       // --rig: the captured sessions (g_strfreev), else NULL
    int             W, H;           // imager size, px
    int             nfound;         // views with a board
    json_t         *sol;            // scripts/calib_geometry_report.py's solution (owned)
    double          rms_px;         // RMS reprojection residual
    model_camera_t *cam;            // intrinsics of the solution, extrinsics 0
    calib_geometry_axis_t axis;
    bool            have_rig;
    double          rt_cam_rig[6];
    int             ncams;          // cameras calibrated together (1: a single camera)
    char            camnames[RIG_CAMERAS_MAX][RIG_CAMERA_NAME_MAX];
    int             camw[RIG_CAMERAS_MAX], camh[RIG_CAMERAS_MAX];   // each camera's imager, px
    char            rigwhy[256];    // why there is no rig frame
    char           *campath;        // DIR/camera.cameramodel (g_free)
    json_t         *out;            // geometry.json's document (owned)
    char           *lensmodel;      // the lens model solved (and, with auto, chosen) (g_free)
    char           *solvecorners;   // the corners file mrcal solves from (cornpath, or the joint one) (g_free)
    char           *soldir;         // the chosen solution's directory (DIR/mrcal or DIR/mrcal/splined) (g_free)
    json_t         *xv;             // cross-validation and lens choice (calib/geometry/diff.c), or NULL (owned)
    bool            no_outlier_rejection;   // mrcal solves with --skip-outlier-rejection (a solve that
                                            // failed with it: calib_geometry_solve)
} calib_geometry_state_t;

void calib_geometry_state_free(calib_geometry_state_t *s);

// The result of a run.
typedef struct {
    bool    usage;          // the failure is the options' (a bad --tilts): exit status 2
    char   *camera_model;   // DIR/camera.cameramodel (g_free)
    char   *outdir;         // the absolute output directory (g_free)
    double  rms_px;         // RMS reprojection residual
    bool    have_rig;       // the extrinsics are in the rig frame (else the camera's own)
} calib_geometry_result_t;

void calib_geometry_result_free(calib_geometry_result_t *r);

// The whole calibration. false + message (r->usage for a bad option).
bool calib_geometry_run(const calib_geometry_opts_t *o, calib_geometry_result_t *r);

// --- stages ----------------------------------------------------------------

// A capture plan (its text) for one --tilts entry "T[@AZ][:A,A,...]" (angles
// default o->angles); name gets "tiltT_azA". NULL + message.
char *calib_geometry_tilt_plan(const char *spec, const calib_geometry_opts_t *o, char *name, size_t namen);
// Every plan of o->tilts first (a bad one fails before anything moves, with
// *usage set), then the captures into DIR/capture/NAME; s->sessions gets them.
bool calib_geometry_capture(const calib_geometry_opts_t *o, calib_geometry_state_t *s, bool *usage);
// A session's frames of one camera (its rig file name; NULL: the first
// camera) → 8-bit images in imgdir and views of a new tilt group; *w, *h: the
// frame size (0: not known yet; all frames must share it).
bool calib_geometry_add_session(calib_geometry_views_t *vs, const char *sdir, const char *camera, const char *imgdir,
                                int *w, int *h);
// Images matching pattern → 8-bit images in imgdir and views without a group.
bool calib_geometry_add_images(calib_geometry_views_t *vs, const char *pattern, const char *imgdir, int *w, int *h);
// Corners text as mrgingham writes it and mrcal reads it ("name x y [level]",
// one line per corner of the board in its order, "name - -" or a level of
// "-" for a corner not seen; one line "name - -": no board) into the views
// (create: add views for unknown names): q, ncorners, found (every corner has
// its line and at least one is seen). path names the text in messages.
bool calib_geometry_parse_corners(calib_geometry_views_t *vs, const char *text, const char *path,
                                  const calib_board_t *b, bool create);
// The corners: from o->corners, or the detector on s->imgdir; views with
// fewer than o->min_corners corners (or all on one line of the board) are
// left out with the reason; DIR/corners.vnl (s->cornpath: the text for mrcal,
// a view left out as one "name - -" line), s->nfound. Fails when fewer than
// o->min_views views have a board (and lists the others).
bool calib_geometry_find_corners(const calib_geometry_opts_t *o, calib_geometry_state_t *s);
// mrcal-calibrate-cameras on the corners (model and log in DIR/mrcal), then
// the solution (board poses, residuals, projection uncertainty) as JSON into
// s->sol. The lens model: o->lensmodel, or with auto the lean one (s->lensmodel).
bool calib_geometry_solve(const calib_geometry_opts_t *o, calib_geometry_state_t *s);
// One mrcal solve: lensmodel on the corners file (views: its count, for the
// progress line) into mdir (created; camera-K.cameramodel, the log, and
// solution.json, read into *sol). false + message.
bool calib_geometry_mrcal(const calib_geometry_opts_t *o, calib_geometry_state_t *s, const char *lensmodel,
                          const char *corners, const char *mdir, int nviews, json_t **sol);
// The solution's poses into the views, s->cam and s->rms_px.
bool calib_geometry_apply_solution(const calib_geometry_opts_t *o, calib_geometry_state_t *s);
// The axis from the poses of each tilt group at different angles (quarter
// turns of mrgingham's corner order made consistent first; inconsistent views
// lose their pose). false when too few pairs (no message), false + message
// when out of memory.
// The turns that make a pose's corner order agree: quarter turns for a square
// chessboard, half turns for another, none for a ChArUco board (its corners
// carry their ids).
bool calib_geometry_fit_axis(calib_geometry_views_t *vs, const calib_board_t *b, calib_geometry_axis_t *ax);
// The axis refined jointly with the board poses (after calib_geometry_fit_axis,
// from its axis): each tilt group's board one pose, turned about the axis by
// the turntable's measured angles in its views, fitted with the axis to the
// corners camera 0 observed (cam fixed, sigma_px the per-axis corner noise).
// Sets ax's joint fields and a, c, dir_unc_deg, point_unc_mm from the fit's
// covariance, and the views' rt_cam_board to the constrained poses. false +
// message (ax and the views unchanged).
bool calib_geometry_refine_axis(calib_geometry_views_t *vs, const calib_board_t *b, model_camera_t *cam,
                                double sigma_px, calib_geometry_axis_t *ax);
// rt_cam_rig from the axis and the tilt-0 group's first pose; false + why.
bool calib_geometry_rig_frame(calib_geometry_views_t *vs, double board_height_mm, const calib_geometry_axis_t *ax,
                              double rt_cam_rig[6], char *why, size_t whyn);
// Why each view without a board has none (predicted from the axis when ax;
// a view left out for too few corners keeps that reason, the prediction added).
// false + message when out of memory.
bool calib_geometry_explain_missing(calib_geometry_views_t *vs, const calib_board_t *b,
                                    const calib_geometry_axis_t *ax, model_camera_t *cam, int W, int H);
// mrcal's .cameramodel (intrinsics intr, imager W x H, extrinsics rt_cam_ref;
// rig: ref is the rig frame, else the camera), written atomically.
bool calib_geometry_write_cameramodel(const char *path, const char *lensmodel, json_t *intr, int W, int H,
                                      const double rt[6], bool rig, double rms);
// geometry.json's document from the state (new reference).
json_t *calib_geometry_json(const calib_geometry_opts_t *o, calib_geometry_state_t *s);
// geometry.json names its format: {"format": "refl-geometry", "version": 1,
// ...}. Version 1 is the layout described here and in calib/geometry/psf.h
// (a file without the two keys reads as version 1). Its readers (the lens
// blur, calib_psf_read; the lab day's comparison) check the parsed root with
// calib_geometry_json_check: true for a geometry.json of a version this refl
// reads (*version, may be NULL, gets it); false + message (model_error_set,
// naming path) for another format or a newer version.
#define CALIB_GEOMETRY_JSON_FORMAT  "refl-geometry"
#define CALIB_GEOMETRY_JSON_VERSION 1
bool calib_geometry_json_check(const json_t *root, const char *path, int *version);
// The plots (scripts/calib_geometry_report.py plots) and DIR/report.html.
bool calib_geometry_report(const calib_geometry_opts_t *o, const calib_geometry_state_t *s, const char *jpath);

// --- cross-validation and the lens model (calib/geometry/diff.c) -----------
//
// Cross-validation as mrcal practises it: the views split into two disjoint
// halves (alternate frames in the order of the corners file, so each half has
// every tilt group's sweep; the views of one frame in every camera stay
// together), each half solved alone, and the two models differenced over the
// imager (scripts/calib_geometry_report.py compare: a 33 x 27 grid unprojected
// with half 0 to o->distance_mm, the rigid transform between the halves'
// camera frames fitted with weights 1 / (s0^2 + s1^2), every point projected
// with half 1) against the predicted difference s0 + s1 (mrcal's projection
// uncertainty of each half, worst direction; two independent estimates with
// per-axis sigma s differ by sqrt(2 (s0^2 + s1^2)) RMS, = s0 + s1 when
// s0 = s1). Judged where the views were: the grid points within one grid step
// of a corner each half observed. A model fails when the RMS over those
// points of diff / (s0 + s1) exceeds CALIB_GEOMETRY_XV_MAX_RATIO.
//
// --lensmodel auto: the lean model (CALIB_GEOMETRY_LEAN_LENSMODEL) is solved
// and cross-validated; as halves of one dance share a lens model's bias (it
// depends on where the corners are, alike in both halves), the lean model is
// also compared with LENSMODEL_SPLINED_STEREOGRAPHIC fitted to the same views,
// by the same measure against the lean and splined uncertainties. The lean
// model is kept when it passes both; else the splined one is cross-validated
// and kept when it passes; when neither passes the one of the smaller
// cross-validation ratio is kept and the output says so.
#define CALIB_GEOMETRY_LEAN_LENSMODEL "LENSMODEL_OPENCV8"
#define CALIB_GEOMETRY_XV_MAX_RATIO   1.5
bool calib_geometry_is_auto(const char *lensmodel);
// LENSMODEL_SPLINED_STEREOGRAPHIC_order=3_Nx=.._Ny=.._fov_x_deg=.. for an imager
// W x H seen through cam (the lean fit): about 70 px per knot interval across
// (Nx 8..30), the knots covering the imager's border rays with a 10 % margin
// (fov_x_deg from cam's unprojection of the border, Ny for the same spacing).
// false + message when cam cannot unproject its border.
bool calib_geometry_splined_name(const model_camera_t *cam, int W, int H, char *name, size_t n);
// Cross-validate lensmodel on s->solvecorners: halves into
// DIR/mrcal/xv-TAG/half0, half1, their comparison; a JSON object (new
// reference) with the figures, "pass" and "why" (or "done": false and why:
// too few views per half). NULL + message when a solve fails.
json_t *calib_geometry_crossvalidate(const calib_geometry_opts_t *o, calib_geometry_state_t *s,
                                     const char *lensmodel, const char *tag);
// Cross-validation of s->lensmodel and, with --lensmodel auto, the choice (may
// replace s->sol, s->lensmodel, s->soldir with the splined solve's): s->xv.
// false + message.
bool calib_geometry_validate_lens(const calib_geometry_opts_t *o, calib_geometry_state_t *s);

// How far model b projects from model a over a's imager (calib/geometry/diff.c),
// as mrcal's projection_diff judges it: a 33 x 27 grid of a's pixels (margin_px
// of the border left out) unprojected with a to distance_mm, the rigid
// transform of a's camera frame onto b's fitted to the points within
// focus_radius_px of the imager's centre (<= 0: all; mrcal's default is
// min(W, H) / 6), every point projected with b. A focal length's error at that
// one distance is absorbed by a shift along the axis (see the .c file).
// false + message (model_last_error).
typedef struct {
    double rms_px, worst_px;                        // after the fitted transform
    double rms_unaligned_px, worst_unaligned_px;    // with the frames taken as they are
    double rt_a_to_b[6];                            // mrcal rt (r rad, t mm)
    double rotation_deg, translation_mm;            // of that transform
    double distance_mm;
    int    npoints;
} calib_projection_diff_t;
bool calib_projection_diff(const mrcal_cameramodel_t *a, const mrcal_cameramodel_t *b, double distance_mm,
                           int margin_px, double focus_radius_px, calib_projection_diff_t *out);

#ifdef __cplusplus
}
#endif

