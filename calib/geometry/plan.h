// calib/geometry/plan.h — the geometry session's board poses for one's own camera(s)
// (refl plan geometry): the board's tilts on its wedges and the turntable's angles that put the
// board's corners over the imager from a spread of orientations, as a lab file's [geometry]
// section (rig/lab.h writes it).
//
// Candidates: the board lying flat (tilt 0) or on a wedge of each given tilt with its hinge at
// each given azimuth, at turntable angles every angle_step_deg; the board's pose is the virtual
// rig's and the sample fit's (model_scene_wedge_pose, then the turntable's turn about z). A
// candidate is usable by a camera when the chessboard's inner corners and half a square beyond them
// project inside the imager with margin_px to spare (mrgingham finds the whole grid, with the squares
// around it, or none; the margin is for the board's placement on its wedge), in front of the camera, its
// smallest square at least min_square_px across, and its obliquity (the angle between the board's
// normal and the direction to the camera) at most max_obliquity_deg.
//
// Choice (greedy): mrcal's guidance for a calibration dance (mrcal.secretsauce.net,
// "How to run a calibration" and "A tour of mrcal: optimal choreography") is many views,
// close-ups, boards tilted both ways about both of their axes, and corners over the whole imager,
// its corners and edges included. The planner keeps the views' orientations spread: each view's
// orientation class is the board normal's direction in the camera frame (head-on within 15 deg,
// else tilted left, right, up or down in the image), and each next view is taken from the class
// with the fewest so far, as the candidate that adds the most to the imager's coverage (each
// cell's weight 1/(k+1)^2 for its k-th observation). First min_flat_views flat views (the rig
// frame needs them), then the classes in turn until max_views or nothing adds; every tilt group
// gets at least two angles (the axis fit turns one pose per group), and with several cameras each
// camera at least min_views views and, where they exist, min_shared views seen by camera 0 too
// (the joint solve ties the cameras by them).
//
// Coverage: the imager cut into cells of about 1/64 of its width; a cell is covered when its
// centre lies inside the polygon of the projected outer corners of a view. Units mm, deg, px.
#pragma once

#include <stdbool.h>

#include "model/model.h"

#ifdef __cplusplus
extern "C" {
#endif

#define CALIB_PLAN_MAX_CAMERAS 8
#define CALIB_PLAN_MAX_WEDGES  8

typedef struct {
    const model_camera_t *cams[CALIB_PLAN_MAX_CAMERAS];   // each camera's model (rig frame extrinsics)
    int                   ncams;
    const model_scene_t  *board;            // the board's scene at angle 0, tilt 0 (rig frame): the corner grid
                                            // is centred on its outline, on its top face
    int                   corners_w, corners_h;   // inner corners
    double                square_mm;
    double                wedges_deg[CALIB_PLAN_MAX_WEDGES];   // the wedges' tilts (tilt 0 is always a candidate)
    int                   nwedges;
    double                azimuths_deg[CALIB_PLAN_MAX_WEDGES]; // the hinge azimuths tried on each wedge
    int                   nazimuths;
    double                angle_step_deg;
    double                max_obliquity_deg, margin_px, min_square_px;
    int                   max_views, min_flat_views, min_views, min_shared;
} calib_geometry_plan_opts_t;

// Defaults: wedges 20 35 50 deg, azimuths 0 90 180 270 deg, angles every 10 deg, obliquity at most
// 60 deg, margin 10 px, squares at least 12 px, 30 views a camera, 2 flat views, 10 views and 6
// shared views a camera; the board 10 x 10 inner corners of 30 mm.
calib_geometry_plan_opts_t calib_geometry_plan_defaults(void);

typedef struct {
    char   *tilts;                  // the --tilts text "T[@AZ]:A,A,... ..." (g_free)
    int     nviews;                 // board poses chosen
    int     ncandidates, nusable;   // candidates tried, usable by at least one camera
    double  coverage[CALIB_PLAN_MAX_CAMERAS];     // fraction of each imager's cells covered (0..1)
    double  coverage_all[CALIB_PLAN_MAX_CAMERAS]; // the same with every usable candidate (the best possible)
    int     views[CALIB_PLAN_MAX_CAMERAS];        // chosen views each camera sees whole
    int     shared[CALIB_PLAN_MAX_CAMERAS];       // ... of which camera 0 sees too
    int     classes[CALIB_PLAN_MAX_CAMERAS][5];   // head-on, left, right, up, down
    double  obliquity_min_deg[CALIB_PLAN_MAX_CAMERAS], obliquity_max_deg[CALIB_PLAN_MAX_CAMERAS];
    double  range_min_mm[CALIB_PLAN_MAX_CAMERAS], range_max_mm[CALIB_PLAN_MAX_CAMERAS];   // board centre
} calib_geometry_plan_t;

// The poses. false + message (model_error_set): no usable candidate for a camera, bad options.
bool calib_geometry_plan(const calib_geometry_plan_opts_t *o, calib_geometry_plan_t *out);
void calib_geometry_plan_free(calib_geometry_plan_t *p);

// Coverage of the given --tilts text (the same cells and polygons; views a camera cannot see whole
// are not counted): per camera into coverage[], views seen whole into views[] (may be NULL).
// false + message on a bad text.
bool calib_geometry_plan_coverage(const calib_geometry_plan_opts_t *o, const char *tilts, double *coverage,
                                  int *views);

// The name of orientation class k (0 head-on, 1 left, 2 right, 3 up, 4 down).
const char *calib_geometry_plan_class_name(int k);

// A guess of a camera for planning before it is calibrated: a pinhole of W x H px and focal length
// f_px (the lens's focal length over the pixel pitch) with its centre at centre_mm (rig frame),
// looking at the rig origin (the turntable's top centre), its image x horizontal. NULL + message.
model_camera_t *calib_geometry_plan_guess_camera(int W, int H, double f_px, const double centre_mm[3]);

// `refl plan geometry` (calib/cmd_plan_geometry.c).
int calib_cmd_plan_geometry(int argc, char **argv);

#ifdef __cplusplus
}
#endif
