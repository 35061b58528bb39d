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
#include <stdio.h>

#include "rig/rig.h"

#ifdef __cplusplus
extern "C" {
#endif

// `refl calib geometry|lamps|gain ...` (calib/cmd_calib.c dispatches).
int calib_cmd(int argc, char **argv);
int calib_cmd_geometry(int argc, char **argv);
int calib_cmd_lamps(int argc, char **argv);
int calib_cmd_gain(int argc, char **argv);

// ---------------------------------------------------------------------------
// Capture sessions of a calibration (calib/capture.c)

// Run a capture plan (its text) on the rig file rig_path into the session
// directory dir/name. The plan is first written to dir/name.plan.ini (kept as
// the record). A complete session of the same plan is reused as it is; a
// paused or stopped one is resumed. progress: as rig_capture_opts_t (-1 auto).
// 0, or -1 with the reason in model_last_error().
int calib_capture(const char *rig_path, const char *dir, const char *name, const char *plan_text, int progress);

#ifdef __cplusplus
}
#endif
