// model/internal.h — helpers shared inside model/ (not a public API).
#pragma once

#include <math.h>
#include "model/model.h"

#include "model/base/vec.h"

// Error with the C source location (for internal failures, not input errors).
#define MODEL_FAIL(...) model_error(__FILE__, __LINE__, __VA_ARGS__)

// Texts every file command writes into its outputs' metadata.
#define MODEL_UNITS_P     "P: grey value, DN"
#define MODEL_PIXEL_CONV  "mrcal: (0,0) is the centre of the top-left pixel, x to the right, y down"
#define MODEL_FRAMES_TEXT "world = rig frame (origin at the turntable top centre, z up along the rotation axis, " \
                          "right-handed), mm; the camera model's rt_cam_ref is rt_cam_world; the scene is " \
                          "rotated by the turntable angle about world z before rendering"

// The inputs of refl render and refl edges (model/render/file.c).
// An input file: role, path and its sha256.
typedef struct {
    const char *role;
    const char *path;
    char        sha256[65];
} model_input_t;

typedef struct {
    model_scene_t           *scene;     // the (possibly rotated) scene
    model_camera_t          *cam;
    model_lamps_t           *lamps;
    model_materials_t       *mats;
    const model_material_t **resolved;  // scene->nmaterials
    model_tracer_t          *tracer;
} model_inputs_t;

// Scene (rotated by turntable_deg about z; its file's unit scene_unit_mm, 0:
// mm), camera, lamps, materials resolved for the scene, and its tracer. false
// + message; free with model_inputs_free either way.
bool  model_inputs_load(model_inputs_t *in, const char *scene_path, const char *cam_path, const char *lamps_path,
                        const char *mats_path, double planarity_tol_mm, double scene_unit_mm, double turntable_deg);
void  model_inputs_free(model_inputs_t *in);
// The sha256 of every input with a path. false + message.
bool  model_inputs_hash(model_input_t *in, int n);
// input_ROLE and input_ROLE_sha256 entries for each input with a path.
void  model_meta_add_inputs(model_meta_t *m, const model_input_t *in, int nin);
// "name: model(p=...) [convention]; ..." of the scene's materials (g_free).
char *model_material_conventions(const model_scene_t *scene, const model_material_t *const *mats);
