// calib/geometry/internal.h — inside calib/geometry/: the helpers and stages the
// files of `refl calib geometry` share (3-vectors and mrcal's rotation
// vectors, the views of a tilt group, the rig-frame algebra). Included only
// by calib/geometry/*.c; the public interface is calib/geometry/geometry.h.
#pragma once

#include <math.h>
#include <mrcal/poseutils.h>
#include <string.h>

#include "calib/geometry/geometry.h"
#include "model/base/vec.h"

#define DEG (M_PI / 180.0)
// What model_run_tool names when mrgingham or mrcal's programs cannot start.
#define GEO_INSTALL_HINT "is it installed? Debian: apt install mrgingham mrcal"

// Small vector helpers: 3-vectors as double[3] here; 3x3 matrices are
// model/base/vec.h's m3_* (row-major, the output first).

static inline double dot3(const double a[3], const double b[3]) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
static inline double norm3(const double a[3]) { return sqrt(dot3(a, a)); }
static inline void cross3(double o[3], const double a[3], const double b[3])
{
    double t[3] = { a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0] };
    memcpy(o, t, sizeof t);
}
static inline void R_from_r(double R[9], const double r[3]) { mrcal_R_from_r((double *)R, NULL, r); }
static inline void r_from_R(double r[3], const double R[9]) { mrcal_r_from_R(r, NULL, R); }
static inline double wrap_deg(double d) { return d - 360.0 * floor((d + 180.0) / 360.0); }

static inline void pose_R(double R[9], const calib_geometry_view_t *v) { R_from_r(R, v->rt_cam_board); }

// The board's centre in its frame (mm).
static inline void board_centre(const calib_board_t *b, double c[3])
{
    c[0] = (b->width_n - 1) * b->spacing_mm / 2;
    c[1] = (b->height_n - 1) * b->spacing_mm / 2;
    c[2] = 0;
}

// views.c
// A new view (owned by vs); NULL + message when out of memory.
calib_geometry_view_t *geo_view_add(calib_geometry_views_t *vs, const char *name, const char *source,
                                    const char *session, int group, double angle, double tilt, double az);
// Stage 1: the views of the sessions (given or captured) or the images.
bool geo_collect_views(const calib_geometry_opts_t *o, calib_geometry_state_t *s);

// axis.c
// The views of camera 0 in group g with a pose, sorted by angle; returns the
// count (*out: free), -1 + message when out of memory.
int geo_group_views(const calib_geometry_views_t *vs, int g, calib_geometry_view_t ***out);

// frame.c
// rt_a_c = rt_a_b ∘ rt_b_c; the inverse of an rt.
void geo_rt_compose(double out[6], const double ab[6], const double bc[6]);
void geo_rt_invert(double out[6], const double rt[6]);

// output.c
// Several cameras: DIR/NAME.cameramodel each, and geometry.json's "cameras".
bool geo_camera_outputs(const calib_geometry_opts_t *o, calib_geometry_state_t *s);
