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


// The joint fit (a bundle adjustment) of the lamps and the sphere's path over
// every highlight of every lamp and angle. Each highlight is kept as the
// camera ray of its centre (from the camera centre, world frame: the sphere
// point of the direction fit seen from the camera), which does not depend on
// where the sphere is. The sphere's centre at turntable angle a is
//   s0 + tilt x s0 + (shift_x, shift_y, 0),   s0 = Rz(a) (c0 + offset)
// offset: an error of the sphere's facts (turns with the table); shift and
// tilt (mrad about x and y): where the calibrated camera puts the table's
// circle relative to itself (an extrinsics error; does not turn; the shift's
// z is the offset's z, the tilt about z the offset's turn). On the virtual
// rig with the camera of `refl calib geometry` the three are needed: with
// offset and shift alone, noise-free highlights still leave ~6 mm lamp
// errors. The ray meets that sphere, is reflected
// there, and the residual is the difference of the unit vectors toward the
// lamp and along the reflected ray, mapped back to the camera ray by the
// inverse of d reflected / d camera ray (held per round): an angle of the
// camera's ray (rad; times the focal length: px), over the lamp's sigma, so
// that a highlight near the sphere's rim (whose reflection turns fast with
// the image position) weighs what its image position is worth. Each
// offset, shift and tilt component has a Gaussian prior (mean 0) of the std given.
typedef struct {
    int          lamp;        // 0..nlamps-1
    double       angle_deg;   // turntable angle (measured)
    model_vec3_t ray;         // unit camera ray of the highlight's centre, world frame
} calib_lamps_obs_t;

typedef struct {
    model_vec3_t camera_mm;        // camera centre, world frame
    double       c0_mm[3];         // sphere centre at angle 0 as given
    double       radius_mm;
    double       offset_prior_mm;  // std of each offset component (<= 0: offset held at 0)
    double       shift_prior_mm;   // std of each shift component (<= 0: shift held at 0)
    double       tilt_prior_mrad;  // std of each tilt component (<= 0: tilt held at 0)
    bool         image_weights;    // residuals mapped back to the camera ray (false: the reflected ray's angle)
} calib_lamps_bundle_setup_t;

typedef struct {
    double sphere[7];        // offset x, y, z (mm), shift x, y (mm), tilt x, y (mrad)
    double sphere_cov[49];   // their covariance
    double sigma_rad[64];    // per lamp: the std of its highlights' camera rays (rad, from its residuals)
    double rms_rad[64];      // per lamp: RMS residual (camera-ray angle, rad)
    int    iterations;       // solver iterations (all rounds)
    double cond;             // largest / smallest eigenvalue of the sphere block's information (observability)
} calib_lamps_bundle_t;

// x_mm (nlamps*3): in: start positions; out: the fit. cov_mm2 (nlamps*9):
// each lamp's covariance including the sphere's uncertainty. obs_sigma
// (out, nobs, may be NULL): each residual (camera-ray angle, rad). nlamps <= 64.
// false (message set) when the solver fails or a lamp has fewer than 3
// rays.
bool calib_lamps_bundle(const calib_lamps_obs_t *obs, int nobs, int nlamps, const calib_lamps_bundle_setup_t *setup,
                        double *x_mm, double *cov_mm2, double *obs_angle_rad, calib_lamps_bundle_t *out);

// The residual block of one observation for the joint fit: blocks (lamp
// position[3], sphere[7]); 3 residuals. ctx: a calib_lamps_bundle_ctx_t.
// Exposed for the Jacobian check of the tests.
typedef struct {
    const calib_lamps_bundle_setup_t *setup;
    calib_lamps_obs_t                 obs;
    double                            sigma_rad;
    double                            W[9];   // residual = W (u_lamp - u_reflected) / sigma_rad (3x3)
} calib_lamps_bundle_ctx_t;
// W of an observation at lamp position X and sphere parameters g: the inverse
// of d reflected / d camera ray in their tangent planes (last row 0). false
// when the ray misses the sphere.
bool calib_lamps_bundle_weight(calib_lamps_bundle_ctx_t *ctx, const double X[3], const double g[7]);
bool calib_lamps_bundle_residual(void *ctx, const double *const *params, double *res, double **jac);

#ifdef __cplusplus
}
#endif
