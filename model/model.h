// model/model.h — the imaging model of refl (thesis ch. 3-5).
//
// Scenes (D3D, OBJ), cameras (mrcal .cameramodel), lamps, materials and their
// reflection models, ray casting (Embree) into per-pixel pixel_info, the grey
// value function with interreflection, the sensor stage, image files, and the
// edge query.
//
// Conventions
// - Lengths in mm, angles in degrees in files and radians inside. Frames are
//   right-handed. The world frame is the rig frame (origin at the turntable top
//   centre, z up along the rotation axis) and is mrcal's "ref" frame, so a
//   camera model's rt_cam_ref is rt_cam_world.
// - Pixel coordinates are mrcal's: the centre of the top-left pixel is (0,0),
//   x to the right, y down.
// - Errors: functions return bool (or NULL) and report "file:line: message"
//   through model_error(); the message names the input file and line where
//   there is one. model_last_error() returns the last message of this thread.
// - Every model_*_free() accepts NULL.
//
// This header includes one public header per subsystem, each with its
// section of the documentation:
//   model/base/base.h      errors, notices, subprocesses, utilities, INI files
//   model/scene/scene.h    scenes (D3D, OBJ, STL, PLY) and the reference workpiece
//   model/brdf/brdf.h      reflection models, tables, RGL files, generators
//   model/config.h         materials, lamps and sensor files
//   model/camera.h         cameras
//   (model/cameramodel.h   a .cameramodel's text checked, then read by libmrcal:
//                          included on its own, as it includes mrcal's header)
//   model/render/render.h  ray casting, grey values, rendering, refl render's work
//   model/sensor.h         the sensor stage and the response linearisation
//   model/image/image.h    image files
//   model/edges/edges.h    the edge query, step edge profiles, refl edges' work
//   model/cmd.h            the commands
#pragma once

#include "model/base/base.h"
#include "model/scene/scene.h"
#include "model/brdf/brdf.h"
#include "model/config.h"
#include "model/camera.h"
#include "model/render/render.h"
#include "model/sensor.h"
#include "model/image/image.h"
#include "model/edges/edges.h"
#include "model/cmd.h"
