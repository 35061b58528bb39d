// fit/eval/lab.h — verification experiments on the virtual rig (in
// process): the truth file's sample rendered at a few turntable angles, one
// radiance plane per lamp (the rig's full physics: interreflections, finite
// lamps, texture), then per case: lamp intensities and camera sensitivity
// drifted, the rig's sensor stage with a fresh noise seed. Its calibrations
// are what a lab would have: the truth's camera model, lamp positions and
// kc*I per lamp, an offset map and flat field from the rig's own dark and
// flat-field frames (noise-free), K and read noise of its sensor.
#pragma once

#include <stdbool.h>
#include <stdint.h>

#include "fit/verify/verify.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef struct eval_lab eval_lab_t;

eval_lab_t *eval_lab_open(const char *truth_path, const char *sample, const double *angles, int nang,
                          double exposure_us, double gain_db, bool verbose);
void eval_lab_free(eval_lab_t *L);

int                      eval_lab_nlamps(const eval_lab_t *L);
int                      eval_lab_width(const eval_lab_t *L);
int                      eval_lab_height(const eval_lab_t *L);
const verify_camera_t   *eval_lab_camera(const eval_lab_t *L);
const model_lamps_t     *eval_lab_lamps(const eval_lab_t *L);   // truth positions
const double            *eval_lab_A(const eval_lab_t *L);       // kc*I per us per lamp (truth)
const model_materials_t *eval_lab_materials(const eval_lab_t *L);

// A frame (W*H DN, 12-bit values) at angles[angle_index] with lamps_on,
// each lamp's intensity times lamp_scale[i] (NULL: 1), the camera's
// sensitivity times kc_scale, sensor noise from seed.
bool eval_lab_image(eval_lab_t *L, int angle_index, uint32_t lamps_on, const double *lamp_scale,
                    double kc_scale, uint64_t seed, float *out);

// The sample placed off by a known amount (rig_virtual_set_sample_offset: turned
// by turn_deg about its centre, shifted by dx, dy mm on the table, after its
// placement error of the truth's [placement]) and rendered at the lab's angles:
// a new placement set for eval_lab_image_placed; its index (1, 2, ...; 0 is
// the sample as opened), or -1 + message.
int  eval_lab_add_placement(eval_lab_t *L, double turn_deg, double dx_mm, double dy_mm, bool verbose);
int  eval_lab_nplacements(const eval_lab_t *L);
// The truth's own placement error of placement set `place` ([placement]: a
// draw for every placement, so a placed-off set has its own on top of the
// offset asked for): turn about the centre (deg) and shift (mm). 0 without
// [placement]; false for a set that does not exist.
bool eval_lab_placement_draw(const eval_lab_t *L, int place, double *turn_deg, double *dx_mm, double *dy_mm);
// eval_lab_image of placement set `place`.
bool eval_lab_image_placed(eval_lab_t *L, int place, int angle_index, uint32_t lamps_on, const double *lamp_scale,
                           double kc_scale, uint64_t seed, float *out);

#ifdef __cplusplus
}
#endif
