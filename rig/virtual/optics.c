// rig/virtual/optics.c — the virtual rig's optics outside the fitters' model
// (examples/virtual-truth.ini documents [optics]):
//   rays_per_pixel = N   the radiance plane is rendered by a camera of N times
//                        the resolution (rig_optics_scaled_camera) and its N x N
//                        blocks averaged: N x N rays spread evenly over each
//                        pixel's footprint, so a pixel on an edge takes the area
//                        fraction of each side (the fitters' model: one ray at
//                        the pixel's centre)
//   psf = gaussian       the plane convolved with a Gaussian of psf_sigma_px
//                        (separable; weights exp(-k^2 / 2 sigma^2) at whole pixel
//                        offsets |k| <= ceil(4 sigma), normalised)
//   psf = disc           the plane convolved with a uniform disc of
//                        psf_radius_px (defocus): each kernel pixel weighted by
//                        its area inside the disc (16 x 16 sub-samples), normalised
// Both before the sensor (rig/virtual/virtual.c applies them where a lamp's plane is
// rendered, so every frame and rig_virtual_radiance see them).
#define _GNU_SOURCE
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include <mrcal/mrcal.h>

#include "model/cameramodel.h"
#include "rig/devices.h"
#include "rig/virtual/optics.h"

static inline float finite_or_0(float x) { return isfinite(x) ? x : 0.0f; }

static inline int clampi(int v, int lo, int hi) { return v < lo ? lo : v > hi ? hi : v; }

// The separable Gaussian: rows, then columns (through tmp).
static bool psf_gaussian(double sigma, int W, int H, float *L)
{
    int r = (int)ceil(4 * sigma);
    double *w = malloc((size_t)(2 * r + 1) * sizeof *w);
    float *tmp = malloc((size_t)W * H * sizeof *tmp);
    double *col = malloc((size_t)H * sizeof *col);
    if (!w || !tmp || !col) {
        free(w);
        free(tmp);
        free(col);
        return false;
    }
    double sum = 0;
    for (int k = -r; k <= r; k++) sum += w[k + r] = exp(-0.5 * k * k / (sigma * sigma));
    for (int k = 0; k <= 2 * r; k++) w[k] /= sum;
    for (int y = 0; y < H; y++) {
        const float *row = L + (size_t)y * W;
        for (int x = 0; x < W; x++) {
            double a = 0;
            for (int k = -r; k <= r; k++) a += w[k + r] * finite_or_0(row[clampi(x + k, 0, W - 1)]);
            tmp[(size_t)y * W + x] = (float)a;
        }
    }
    for (int x = 0; x < W; x++) {
        for (int y = 0; y < H; y++) col[y] = tmp[(size_t)y * W + x];
        for (int y = 0; y < H; y++) {
            double a = 0;
            for (int k = -r; k <= r; k++) a += w[k + r] * col[clampi(y + k, 0, H - 1)];
            L[(size_t)y * W + x] = (float)a;
        }
    }
    free(w);
    free(tmp);
    free(col);
    return true;
}

// The disc by direct convolution with area weights.
static bool psf_disc(double R, int W, int H, float *L)
{
    int r = (int)ceil(R);
    int n = 2 * r + 1;
    double *w = malloc((size_t)n * n * sizeof *w);
    float *src = malloc((size_t)W * H * sizeof *src);
    if (!w || !src) {
        free(w);
        free(src);
        return false;
    }
    enum { SUB = 16 };
    double sum = 0;
    for (int dy = -r; dy <= r; dy++)
        for (int dx = -r; dx <= r; dx++) {
            int in = 0;
            for (int j = 0; j < SUB; j++)
                for (int i = 0; i < SUB; i++) {
                    double px = dx - 0.5 + (i + 0.5) / SUB, py = dy - 0.5 + (j + 0.5) / SUB;
                    in += px * px + py * py <= R * R;
                }
            sum += w[(dy + r) * n + dx + r] = (double)in / (SUB * SUB);
        }
    for (int k = 0; k < n * n; k++) w[k] /= sum;
    for (size_t i = 0; i < (size_t)W * H; i++) src[i] = finite_or_0(L[i]);
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++) {
            double a = 0;
            for (int dy = -r; dy <= r; dy++) {
                const float *row = src + (size_t)clampi(y + dy, 0, H - 1) * W;
                const double *wr = w + (size_t)(dy + r) * n + r;
                for (int dx = -r; dx <= r; dx++)
                    if (wr[dx] != 0) a += wr[dx] * row[clampi(x + dx, 0, W - 1)];
            }
            L[(size_t)y * W + x] = (float)a;
        }
    free(w);
    free(src);
    return true;
}

bool rig_optics_psf(const rig_optics_t *o, int W, int H, float *L)
{
    if (W <= 0 || H <= 0 || !L) return true;
    bool ok = true;
    if (o->psf == RIG_PSF_GAUSSIAN && o->psf_sigma_px > 0) ok = psf_gaussian(o->psf_sigma_px, W, H, L);
    else if (o->psf == RIG_PSF_DISC && o->psf_radius_px > 0) ok = psf_disc(o->psf_radius_px, W, H, L);
    if (!ok) model_error(NULL, 0, "out of memory for the point-spread function of a %dx%d plane", W, H);
    return ok;
}

void rig_optics_average(int N, int W, int H, const float *hi, float *out)
{
    const size_t WN = (size_t)W * N;
    const double inv = 1.0 / ((double)N * N);
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++) {
            double a = 0;
            for (int j = 0; j < N; j++) {
                const float *row = hi + ((size_t)y * N + j) * WN + (size_t)x * N;
                for (int i = 0; i < N; i++) a += finite_or_0(row[i]);
            }
            out[(size_t)y * W + x] = (float)(a * inv);
        }
}

int rig_optics_scaled_camera(const char *cam_path, const model_camera_t *cam, double f, int W, int H,
                             model_camera_t **out)
{
    *out = NULL;
    mrcal_cameramodel_t *m = model_cameramodel_read(cam_path);
    if (!m) return rig_fail(RIG_ERR_IO, "virtual rig: %s", model_last_error());
    int err = RIG_ERR_OK;
    mrcal_lensmodel_metadata_t meta = mrcal_lensmodel_metadata(&m->lensmodel);
    int np = mrcal_lensmodel_num_params(&m->lensmodel);
    if (!meta.has_core || np < 4) {
        err = rig_fail(RIG_ERR_NOT_SUPPORTED, "virtual rig: %s: lens model %s has no fx fy cx cy core, so it "
                       "cannot be scaled", cam_path, model_camera_lensmodel(cam));
    } else {
        // in place: a splined model's knots stay (they act on the normalised image)
        double *in = m->intrinsics, rt[6];
        in[0] *= f;
        in[1] *= f;
        in[2] = (in[2] + 0.5) * f - 0.5;
        in[3] = (in[3] + 0.5) * f - 0.5;
        model_camera_rt_cam_world(cam, rt);
        *out = model_camera_new(model_camera_lensmodel(cam), in, W, H, rt);
        if (!*out) err = rig_fail(RIG_ERR_IO, "virtual rig: %s", model_last_error());
    }
    mrcal_free_cameramodel(&m);
    return err;
}
