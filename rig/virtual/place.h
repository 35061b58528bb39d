// rig/virtual/place.h — the virtual rig's placement and turntable-axis errors
// (rig/virtual/place.c; physics outside the fitted models). Off by
// default: without [placement] and the [turntable] axis keys nothing changes.
// The truth reader (rig/virtual/truth_rig.c, truth_samples.c) reads these keys:
//
//   [placement]  position_sigma_mm, angle_sigma_deg, seed: every placement of a
//                sample (rig_virtual_set_sample*, the operator's step; also the
//                sample the rig opens with) adds a random rigid error in the
//                plane it rests on (the table or the wedge's face): a shift
//                (dx, dy) ~ N(0, position_sigma_mm) each and a turn about the
//                support's normal through the sample's centre (the middle of
//                its bounding box) ~ N(0, angle_sigma_deg). Drawn from (seed,
//                sample name, placement count of that sample): reproducible.
//                A uniform_source is not placed.
//   [turntable]  axis_tilt_deg, axis_tilt_azimuth_deg: the rotation axis leans
//                by axis_tilt_deg from z towards (cos az, sin az, 0); the
//                platter is square to it (the whole table tilts).
//                wobble_deg: the platter's normal leans by wobble_deg from the
//                axis towards the platter's own +x, so it cones about the
//                axis once per revolution. Pivot: the table top centre.
//                x_rig = A Rz(angle) Wb x_table (A: the tilt, Wb: the wobble).
//   [sample NAME] flex_mm (a chessboard, -5..5): the board bends as a
//                paraboloid, z += flex_mm rho^2 / rho_max^2 (rho from the
//                middle of its bounding box in x, y; rho_max its half
//                diagonal), less min(0, flex_mm): with flex_mm > 0 the centre
//                lies flex_mm below the corners (it sags), < 0 above them;
//                the lowest point keeps its height. Every face is split into
//                flat triangles (a fan).
#pragma once

#include <stdbool.h>
#include <stdint.h>

#include "model/model.h"

typedef struct {
    bool     on;                    // [placement] present with a sigma > 0
    double   position_sigma_mm, angle_sigma_deg;
    uint64_t seed;
    bool     axis_on;               // a tilt or wobble != 0
    double   axis_tilt_deg, axis_tilt_azimuth_deg, wobble_deg;
} rig_virtual_place_t;

// The placement error of sample `name` (its scene in the sample's own frame,
// before any wedge pose) at its count-th placement: x' = dR x + dt; err (may
// be NULL): the turn (deg) and the shift dx, dy (mm) drawn.
void rig_virtual_place_error(const rig_virtual_place_t *p, const char *name, long count,
                             const model_scene_t *scene, double dR[9], double dt[3], double err[3]);
// A rigid move of a sample (its scene in its own frame) in the plane it rests
// on: a turn of turn_rad about z through its centre (the middle of its
// bounding box in x, y), then a shift (dx, dy) mm: x' = dR x + dt.
void rig_virtual_place_about_centre(const model_scene_t *scene, double turn_rad, double dx_mm, double dy_mm,
                                    double dR[9], double dt[3]);
// The table's rotation at angle_deg: x_rig = R x_table (row-major).
void rig_virtual_place_table_R(const rig_virtual_place_t *p, double angle_deg, double R[9]);
// The scene rotated by the table at angle_deg (model_scene_rotated_z when the
// axis is ideal, bit for bit). NULL + message.
model_scene_t *rig_virtual_place_rotated(const rig_virtual_place_t *p, const model_scene_t *scene,
                                         double angle_deg);
// A copy of scene bent by flex_mm (see above). NULL + message.
model_scene_t *rig_virtual_place_flexed(const model_scene_t *scene, double flex_mm);
