// rig/virtual/truth.h — the virtual rig's truth file (examples/virtual-truth.ini),
// read in one place. The virtual rig renders from it (rig/virtual/virtual.c); every
// other layer reaches it only to compare a measurement with the truth (the
// demo's tables, a test's tolerance, a report's "truth" column), never as a
// default for a measurement: a calibration or fit takes its inputs from the
// user (options, plans, calibration files) exactly as on a real rig.
//
// Sections read here: [lamp NAME] (position, intensity, radius), [material
// NAME], [sample NAME] (scene, material, kind, sphere_centre_mm,
// sphere_radius_mm, radiance of a uniform source). Lengths in mm.
// Errors: NULL / false with the message (file:line) in model_last_error().
#pragma once

#include <stdbool.h>
#include <stddef.h>

#include "model/model.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef struct rig_truth rig_truth_t;

// Load a truth file. NULL + message. Free with rig_truth_free (accepts NULL).
rig_truth_t *rig_truth_load(const char *path);
void         rig_truth_free(rig_truth_t *t);
const char  *rig_truth_path(const rig_truth_t *t);
// The INI as parsed (for the virtual rig's own sections).
const model_ini_t *rig_truth_ini(const rig_truth_t *t);

// Lamps (positions, intensities, radii) and materials of the truth. NULL + message.
model_lamps_t     *rig_truth_lamps(const rig_truth_t *t);
model_materials_t *rig_truth_materials(const rig_truth_t *t);
// [sample NAME]: its scene (path resolved against the truth file's directory;
// caller g_free's) and material (copied into material when not NULL). false + message.
bool rig_truth_sample_scene(const rig_truth_t *t, const char *sample, char **scene_path, char *material,
                            size_t material_size);
// [sample NAME] of a mirror sphere: its centre (mm, rig frame at angle 0) and radius. false + message.
bool rig_truth_sphere(const rig_truth_t *t, const char *sample, double centre_mm[3], double *radius_mm);
// The turntable's rotation axis, a unit vector in the rig frame: z leaning
// [turntable] axis_tilt_deg towards azimuth axis_tilt_azimuth_deg (both 0
// when absent: z). false + message.
bool rig_truth_axis(const rig_truth_t *t, double dir[3]);
// [sample NAME] of kind uniform_source: its radiance. false + message.
bool rig_truth_uniform_radiance(const rig_truth_t *t, const char *sample, double *radiance);

#ifdef __cplusplus
}
#endif
