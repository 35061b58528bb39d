// model/camera.h — cameras: an mrcal camera model and its ray table
//
// Part of model/model.h, whose conventions (units, frames, pixel coordinates,
// errors, model_*_free(NULL)) apply here.
#pragma once

#include <stdbool.h>
#include <stddef.h>

#include "model/base/base.h"

#ifdef __cplusplus
extern "C" {
#endif

// ---------------------------------------------------------------------------
// Cameras (model/camera.c): an mrcal camera model plus a cached ray table.

typedef struct model_camera model_camera_t;

// Reads a .cameramodel with libmrcal, its text checked first
// (model/cameramodel.h: a damaged or cut file is an error naming the file and
// line, never a crash). NULL and a message naming the file on error.
model_camera_t *model_camera_load(const char *path);
// The same from the file's bytes; name: the file, for messages.
model_camera_t *model_camera_parse(const char *text, size_t len, const char *name);
// From explicit parameters (lensmodel name as mrcal spells it, e.g.
// "LENSMODEL_OPENCV8"; intrinsics fx fy cx cy + distortions; rt_cam_world = r(3) t(3), t in mm).
model_camera_t *model_camera_new(const char *lensmodel, const double *intrinsics,
                                 int width, int height, const double rt_cam_world[6]);
bool            model_camera_save(const model_camera_t *cam, const char *path);
void            model_camera_free(model_camera_t *cam);
int             model_camera_width(const model_camera_t *cam);
int             model_camera_height(const model_camera_t *cam);
const char     *model_camera_lensmodel(const model_camera_t *cam);
// The lens model's parameters (fx fy cx cy and the distortions, mrcal's order); *n their count.
const double   *model_camera_intrinsics(const model_camera_t *cam, int *n);
const char     *model_camera_sha256(const model_camera_t *cam);   // of the file, or of the parameters
void            model_camera_rt_cam_world(const model_camera_t *cam, double rt[6]);
model_vec3_t    model_camera_centre_world(const model_camera_t *cam);
// Project world points to pixels. false on error.
bool model_camera_project(const model_camera_t *cam, const model_vec3_t *p_world, int n,
                          double *q_xy /* out: n*2 */);
// Unit ray directions in the world frame through pixels q (exact mrcal_unproject).
bool model_camera_unproject(const model_camera_t *cam, const double *q_xy, int n,
                            model_vec3_t *dir_world /* out: n */);
// The ray table: unit world-frame directions for every integer pixel (row-major,
// width*height), made by unprojecting a coarse grid and interpolating, refined
// until the reprojection error is below max_error_px (default 0.005 px; use
// both cores). Computed once per camera and kept. The achieved bound is
// returned through *err_px (may be NULL).
const model_vec3_t *model_camera_ray_table(model_camera_t *cam, double *err_px);

#ifdef __cplusplus
}
#endif
