// tests/photo_degrade.h — a synthetic image made to look photographed by a
// low-cost camera (tests/photo_degrade.cc, OpenCV): a bent sheet, a lens's
// barrel distortion, glare, uneven light, lens blur, sensor noise and JPEG compression, in
// that order.
#pragma once

#include <stdbool.h>

#ifdef __cplusplus
extern "C" {
#endif

typedef struct {
    double k1, f_px;        // radial distortion: a point at r px from the centre moves to r (1 + k1 (r / f_px)^2)
                            // (k1 < 0: barrel; 0: none)
    double bend_px;         // paper not flat: a smooth wave of this amplitude moves the pixels (cv::remap); 0: none
    double glare, glare_sigma_px;   // a specular highlight: glare x 255 grey levels added at (glare_x, glare_y)
    double glare_x, glare_y;        // with a Gaussian fall-off of glare_sigma_px (saturating)
    double light_lo;        // the light's gradient: gain 1 on one side of the image, light_lo on the other (0..1]
    double light_dir_deg;   // the direction the light falls off in, image x toward y (deg)
    double vignette;        // the gain lost at the image's corners (cos^4-like, 0: none)
    double blur_sigma_px;   // Gaussian blur (cv::GaussianBlur), px; 0: none
    double noise_dn;        // Gaussian noise, grey levels (cv::RNG seeded with seed)
    int    jpeg_quality;    // cv::imencode's JPEG quality (1..100); 0: no JPEG
    unsigned seed;
} test_photo_t;

// img (w x h, 8-bit grey, rows contiguous) degraded in place by p; false when
// OpenCV failed (the message to stderr).
bool test_photo_degrade(unsigned char *img, int w, int h, const test_photo_t *p);
// Where the bend and the distortion of p move pixel (x, y) of the flat,
// undistorted image.
void test_photo_distort(const test_photo_t *p, int w, int h, double x, double y, double *xd, double *yd);

#ifdef __cplusplus
}
#endif
