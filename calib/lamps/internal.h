// calib/lamps/internal.h — inside calib/lamps/: the helpers the files of the lamp
// calibration share (the public API and its documentation: calib/lamps/lamps.h).
#pragma once

#include "calib/lamps/lamps.h"

#ifdef __cplusplus
extern "C" {
#endif

// sphere.c: distance along the unit ray (o, d) to the sphere's (centre c,
// radius r) near surface; NAN on a miss.
double lamps_ray_sphere(model_vec3_t o, model_vec3_t d, model_vec3_t c, double r);

// triangulate.c: the distance of point x from the ray (origin p, unit direction d).
double lamps_ray_dist(model_vec3_t p, model_vec3_t d, const double x[3]);

// bundle.c: the sphere centre s at the angle for sphere parameters g (the
// path of calib_lamps_bundle_setup_t), and d centre / d g (3x7, row-major;
// may be NULL).
void lamps_bundle_centre(const calib_lamps_bundle_setup_t *S, double angle_deg, const double *g, double s[3],
                         double ds_dg[21]);

// capture.c: the full scale of a pixel format in DN (Mono8 255, Mono16
// 65535, else 4095).
double lamps_full_scale(const char *pf);

// rays.c: the sphere's centre at turntable angle angle_deg: Rz(angle) c0.
model_vec3_t lamps_centre_at(const double c0[3], double angle_deg);
// rays.c: a frame of the session, checked against the camera model's size.
// NULL + message.
float *lamps_load_frame(const calib_lamps_opts_t *o, const calib_lamps_result_t *r, int row);
// rays.c: the frame of lamp lp at angle a: its file ("(none)") and step (-1).
const char *lamps_frame_file(const calib_lamps_result_t *r, const calib_lamps_lamp_t *lp, int a, int *step);
// rays.c: the frames without a ray, one line each: "    FILE (step N, A
// deg): why\n". g_free.
char *lamps_missing_text(const calib_lamps_result_t *r, const calib_lamps_lamp_t *lp);
// rays.c: each ray again with the lamp's disk (its angular radius seen from
// the sphere point, at the lamp's fitted distance x_mm), at the sphere centres
// r->centre_mm; pass 0 of the joint fit and pass 2 of the per-lamp fit.
void lamps_refit_highlights(const calib_lamps_opts_t *o, calib_lamps_result_t *r, calib_lamps_lamp_t *lp,
                            const double x_mm[3]);

// output.c: the provenance of the outputs (made once into r->provenance):
// the command line, the camera model, the session and the rig file. false +
// message.
bool lamps_provenance(const calib_lamps_opts_t *o, calib_lamps_result_t *r);

#ifdef __cplusplus
}
#endif
