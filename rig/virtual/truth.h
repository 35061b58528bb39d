// rig/virtual/truth.h — the virtual rig's truth file (examples/virtual-truth.ini),
// read in one place: rig/virtual/truth.c (the file, its format version, its
// sections and keys), truth_figures.c (the figures below), truth_rig.c and
// truth_samples.c (the file read into a virtual rig, rig/virtual/internal.h).
// The virtual rig renders from it; every other layer reaches it only to
// compare a measurement with the truth (the demo's tables, a test's tolerance,
// a report's "truth" column), never as a default for a measurement: a
// calibration or fit takes its inputs from the user (options, plans,
// calibration files) exactly as on a real rig.
//
// Format version: [virtual] format_version = N (optional; a file without it
// is version 1). This refl reads version 1 (RIG_TRUTH_FORMAT_VERSION) and
// refuses a file of a newer version, naming both.
//
// Sections read here: [camera] / [camera NAME] (model, kc_per_us), [sensor],
// [lamp NAME] (position, intensity, radius), [material NAME], [texture
// MATERIAL] (roughness_amplitude), [sample NAME] (scene, material, kind,
// sphere_centre_mm, sphere_radius_mm, radiance of a uniform source),
// [turntable] (axis). Lengths in mm; relative paths resolve against the truth
// file's directory. Errors: NULL / false with the message (file:line) in
// model_last_error().
#pragma once

#include <stdbool.h>
#include <stddef.h>

#include "model/model.h"

#ifdef __cplusplus
extern "C" {
#endif

#define RIG_TRUTH_FORMAT_VERSION 1

typedef struct rig_truth rig_truth_t;

// Load a truth file. NULL + message. Free with rig_truth_free (accepts NULL).
rig_truth_t *rig_truth_load(const char *path);
// The same from a truth file's text; path: the name its messages give, the
// file its relative paths resolve against. NULL + message.
rig_truth_t *rig_truth_parse(const char *text, size_t len, const char *path);
void         rig_truth_free(rig_truth_t *t);
const char  *rig_truth_path(const rig_truth_t *t);
// The format version the file states (1 when it states none).
int          rig_truth_format_version(const rig_truth_t *t);

// Lamps (positions, intensities, radii) and materials of the truth. NULL + message.
model_lamps_t     *rig_truth_lamps(const rig_truth_t *t);
model_materials_t *rig_truth_materials(const rig_truth_t *t);
// [sample NAME]: its scene (path resolved against the truth file's directory;
// free it) and material (copied into material when not NULL). false + message.
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

// ---------------------------------------------------------------------------
// Figures as the file states them (a comparison's truth column). A figure the
// file does not state is NAN, NULL or false, without a message. A number is
// the value the key's text starts with. A camera is named as in [camera NAME];
// NULL names [camera].

// The samples in file order: the i-th [sample NAME]'s name (NULL past the last).
const char *rig_truth_sample_name(const rig_truth_t *t, int i);
// [sample NAME] scene, resolved (free it); NULL without one (a uniform source).
char       *rig_truth_sample_scene_path(const rig_truth_t *t, const char *sample);
// Whether the file has that camera's section.
bool        rig_truth_has_camera(const rig_truth_t *t, const char *camera);
// The camera's model (its .cameramodel), resolved (free it).
char       *rig_truth_camera_model_path(const rig_truth_t *t, const char *camera);
// The camera's kc_per_us (DN at 0 dB per radiance unit and microsecond).
double      rig_truth_kc_per_us(const rig_truth_t *t, const char *camera);
// [sensor] KEY, a key of model_sensor_t ("read_noise_e", "prnu_pct", ...).
double      rig_truth_sensor_value(const rig_truth_t *t, const char *key);
// The camera's sensor: [sensor] with, for [camera NAME], [sensor NAME]'s keys
// over it (model_sensor_from_ini). false + message.
bool        rig_truth_sensor(const rig_truth_t *t, const char *camera, model_sensor_t *out);
// [lamp NAME] position_mm (three numbers) and intensity.
bool        rig_truth_lamp_position(const rig_truth_t *t, const char *lamp, double position_mm[3]);
double      rig_truth_lamp_intensity(const rig_truth_t *t, const char *lamp);
// [material NAME]: its model's name, and the number it states for a parameter.
const char *rig_truth_material_model(const rig_truth_t *t, const char *material);
double      rig_truth_material_param(const rig_truth_t *t, const char *material, const char *param);
// [texture MATERIAL]: roughness_amplitude, and the section's line (0: none).
double      rig_truth_roughness_amplitude(const rig_truth_t *t, const char *material);
int         rig_truth_texture_line(const rig_truth_t *t, const char *material);

#ifdef __cplusplus
}
#endif
