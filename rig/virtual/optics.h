// rig/virtual/optics.h — the virtual rig's optics outside the fitters' model:
// rays over each pixel's footprint and a point-spread function,
// from the truth file's [optics] section (read by rig/virtual/truth_rig.c).
// Internal to rig/ (rig/virtual/ and the tests).
#ifndef RIG_VIRTUAL_OPTICS_H
#define RIG_VIRTUAL_OPTICS_H

#include <stdbool.h>

#include "model/model.h"

typedef enum { RIG_PSF_NONE = 0, RIG_PSF_GAUSSIAN, RIG_PSF_DISC } rig_psf_t;

typedef struct {
    int       rays_per_pixel;   // N: N x N rays over each pixel's footprint (1: one at its centre)
    rig_psf_t psf;
    double    psf_sigma_px;     // gaussian: standard deviation (px)
    double    psf_radius_px;    // disc: radius (px), a defocus blur
} rig_optics_t;

// The PSF applied in place to a W x H radiance plane (borders: the edge
// pixel repeated; non-finite values count as 0). false on out of memory.
bool rig_optics_psf(const rig_optics_t *o, int W, int H, float *L);

// Average the N x N blocks of a (N W) x (N H) plane into a W x H one.
void rig_optics_average(int N, int W, int H, const float *hi, float *out);

// A camera like cam (its mrcal model at cam_path) with f times the
// resolution: fx, fy times f, pixel centres (c + 0.5) f - 0.5, W x H pixels
// (f > 1: the rays of rays_per_pixel; f < 1: the indirect light's camera).
// RIG_ERR_* (rig_fail) on error, e.g. a lens model without that core.
int rig_optics_scaled_camera(const char *cam_path, const model_camera_t *cam, double f, int W, int H,
                             model_camera_t **out);

#endif
