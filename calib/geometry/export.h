// calib/geometry/export.h — camera models out (calib/geometry/export.c): a .cameramodel (read by
// model/camera.c, the one reader) written as OpenCV FileStorage YAML or as a
// ROS camera_info YAML.
//
// Distortion coefficients, OpenCV's order, which is mrcal's for these models:
//   LENSMODEL_PINHOLE  -> none (OpenCV: 5 zeros; ROS: plumb_bob, 5 zeros)
//   LENSMODEL_OPENCV4  -> k1 k2 p1 p2          (ROS plumb_bob: k1 k2 p1 p2 0)
//   LENSMODEL_OPENCV5  -> k1 k2 p1 p2 k3       (ROS plumb_bob)
//   LENSMODEL_OPENCV8  -> k1 k2 p1 p2 k3 k4 k5 k6   (ROS rational_polynomial)
//   LENSMODEL_OPENCV12 -> k1 k2 p1 p2 k3 k4 k5 k6 s1 s2 s3 s4 (OpenCV only; ROS has no such model)
// Other models (splined stereographic, stereographic, CAHVOR, lon/lat, ...)
// are refused with a message (they are not OpenCV's projection), unless an
// approximation is asked for (calib_export_camera_approx: a fitted
// LENSMODEL_OPENCV8 and its stated error).
#pragma once

#include <stdbool.h>

#ifdef __cplusplus
extern "C" {
#endif

typedef enum { CALIB_EXPORT_OPENCV, CALIB_EXPORT_ROS } calib_export_format_t;

// "opencv" / "ros"; false for another name (no message).
bool calib_export_format_from_name(const char *name, calib_export_format_t *out);

// The YAML text of the camera model at model_path (NULL + message naming the
// file: unreadable model, or a lens model the format cannot hold). ROS:
// camera_name (NULL: the model file's name without directory and extension).
char *calib_export_camera_text(const char *model_path, calib_export_format_t fmt, const char *camera_name);
// The same written atomically to out. false + message.
bool calib_export_camera(const char *model_path, calib_export_format_t fmt, const char *camera_name,
                         const char *out);

// The same for a model OpenCV cannot hold (splined, ...), approximated:
// LENSMODEL_OPENCV8 fitted to it over the whole imager (48 x 40 pixels
// unprojected with the model, the OpenCV model's intrinsics fitted to project
// those rays onto them; scripts/calib_export_approx.py), written as
// out.approx.cameramodel with its error in out.approx.json, then exported;
// the error (RMS and largest over the grid, px) is returned and stated in the
// YAML's comment. A model OpenCV holds is exported as it is (*rms_px, *max_px 0).
bool calib_export_camera_approx(const char *model_path, calib_export_format_t fmt, const char *camera_name,
                                const char *out, double *rms_px, double *max_px);

// One .cameramodel with mrcal's optimization_inputs and refl's extrinsics
// (refl calib geometry's outputs): model (refl's: rig-frame extrinsics, the
// same intrinsics) is rewritten as mrcal_model (mrcal-calibrate-cameras'
// output, with its optimization_inputs) with model's extrinsics and comment
// lines, by mrcal itself (scripts/calib_cameramodel_merge.py). mrcal allows
// moving a camera without invalidating the optimization_inputs: its tools
// (projection_uncertainty, mrcal-show-projection-uncertainty,
// mrcal-show-residuals-*, mrcal-show-projection-diff) take the solve's poses
// from them, in the solve's reference frame (camera 0). false + message
// (intrinsics that differ: not the same solve). model is left as it was then.
bool calib_export_keep_optimization_inputs(const char *mrcal_model, const char *model);

// `refl calib export` (calib/cmd_calib.c).
int calib_cmd_export(int argc, char **argv);

#ifdef __cplusplus
}
#endif
