// calib/lamps.h — the parts of the lamp calibration (calib/lamps.c) that its
// tests call directly: the sub-pixel highlight finder and the triangulation.
// `refl calib lamps` itself is calib_cmd_lamps (calib/calib.h).
//
// Conventions as calib/calib.h: mm, rig frame, pixel (0, 0) = centre of the
// top-left pixel, grey values in DN.
#pragma once

#include <stdbool.h>

#include "model/model.h"

#ifdef __cplusplus
extern "C" {
#endif

// The image of a sphere (centre_mm, radius_mm, rig frame) in a camera: for
// every pixel of the box [x0, x0 + w) x [y0, y0 + h) whether its ray hits the
// sphere, and for those the unit ray direction. Made by
// calib_lamps_sphere_image; free with calib_lamps_sphere_image_free.
typedef struct {
    int           x0, y0, w, h;    // box in pixels (clipped to the imager)
    unsigned char *on;             // w*h: 1 where the pixel's ray hits the sphere
    double        q_centre[2];     // projected sphere centre, px
    double        radius_px;       // largest distance of the silhouette from q_centre, px
} calib_lamps_sphere_image_t;

// NULL when the sphere is behind the camera or outside the imager (message set).
calib_lamps_sphere_image_t *calib_lamps_sphere_image(const model_camera_t *cam, model_vec3_t centre_mm,
                                                     double radius_mm);
void calib_lamps_sphere_image_free(calib_lamps_sphere_image_t *s);

// A highlight found on the sphere's image.
typedef struct {
    bool   found;
    double q[2];            // sub-pixel position, px (Gaussian fit; centroid when the fit failed)
    double q_centroid[2];   // intensity-weighted centroid of the blob, px
    double peak_dn;         // brightest pixel above the background, DN
    double noise_dn;        // robust std of the difference image around the sphere, DN
    double sigma_px[2];     // fitted Gaussian widths (x, y)
    double q_std_px;        // standard error of q from the fit's residuals, px
    int    blob_px;         // pixels of the blob (>= 20 % of the peak, connected to it)
    bool   saturated;       // the brightest pixel is at or above sat_dn
    bool   fit_used;        // q from the Gaussian fit (false: centroid)
    char   why[200];        // when not found: why (levels measured)
    // the 9x9 window around the brightest pixel, background subtracted (for
    // calib_lamps_fit_direction): pixel (win_x0 + i % 9, win_y0 + i / 9);
    // NAN where off the sphere, off the imager or saturated
    int    win_x0, win_y0;
    double win[81];
} calib_lamps_highlight_t;

// Find the lamp's highlight in img - dark (dark may be NULL: then the
// background is the median around the sphere) on the pixels of the sphere's
// image: the brightest on-sphere pixel, its blob (connected pixels >= 20 % of
// the peak; a blob larger than max_blob_px is a broad reflection, not a lamp),
// the intensity-weighted centroid, then a 2-D Gaussian fit (amplitude, centre,
// widths) on the 7x7 window. Found when the peak exceeds min_snr times the
// noise and min_peak_dn. sat_dn: the saturation level of the frame. img and
// dark are width x height.
void calib_lamps_find_highlight(const float *img, const float *dark, int width, int height,
                                const calib_lamps_sphere_image_t *sph, double min_snr, double min_peak_dn,
                                int max_blob_px, double sat_dn, calib_lamps_highlight_t *out);

// The ray from a highlight toward its lamp: the camera ray through q meets the
// sphere at p_mm, the normal there reflects it into dir (unit). false when the
// ray misses the sphere (message set).
bool calib_lamps_reflect(const model_camera_t *cam, const double q[2], model_vec3_t centre_mm, double radius_mm,
                         model_vec3_t *p_mm, model_vec3_t *dir);

// The highlight's ray toward the lamp from a model of the highlight in
// direction space: every window pixel's camera ray meets the sphere (normal n,
// unit vector to the camera v); a lamp in direction u, a disk of angular
// radius lamp_radius_rad (0: a point; sampled at 37 points w), gives there
// A * mean_w D_ggx(n.h(v, w); alpha) / (n.v) (the mirror's BRDF D G F /
// (4 n.v) with G and F constant over a highlight, D scaled to 1 at its peak),
// point-sampled at the pixel centres as the camera sees it. Fits A, u (2 dof)
// and alpha (Levenberg-Marquardt, numeric Jacobian), starting at the centroid,
// then twice more with weights 1 / (noise^2 + (kappa model)^2) (errors that
// grow with the signal: sampling noise, lobe mismatch; kappa from the residuals);
// the ray starts at the sphere point whose mirror direction is u. *lobe_rad
// (may be NULL): the fitted alpha. false (message set) when the fit fails;
// the caller then keeps calib_lamps_reflect of hl->q.
bool calib_lamps_fit_direction(const model_camera_t *cam, const calib_lamps_highlight_t *hl, model_vec3_t centre_mm,
                               double radius_mm, double lamp_radius_rad, model_vec3_t *p_mm, model_vec3_t *dir,
                               double *lobe_rad);

// The least-squares point nearest n rays (origin p[i], unit direction d[i]),
// with outlier rejection: rays farther than max(reject_sigma * robust scale,
// floor_mm) from the fit are dropped and the fit repeated (at most n/3 rays
// dropped; >= 3 rays always kept).
typedef struct {
    double x_mm[3];
    double cov_mm2[9];       // covariance: s^2 (sum P_i)^-1, s^2 = sum dist^2 / (2 n_used - 3)
    double rms_mm;           // RMS distance of the used rays from x
    int    n_used;
    double min_eig;          // smallest eigen-direction weight of sum P_i (0..n: ray spread)
} calib_lamps_fit_t;
// used (in/out, n): in: rays allowed; out: rays kept. dist_mm (out, n, may be
// NULL): each ray's distance from x. false when fewer than 3 rays or the rays
// are (nearly) parallel (message says which).
bool calib_lamps_triangulate(const model_vec3_t *p, const model_vec3_t *d, int n, double reject_sigma,
                             double floor_mm, bool *used, double *dist_mm, calib_lamps_fit_t *out);

#ifdef __cplusplus
}
#endif
