// tests/photo_degrade.cc — a synthetic image made to look photographed
// (tests/photo_degrade.h), by OpenCV: a bend and radial distortion
// (cv::remap), a highlight, a gradient of light and a vignette,
// cv::GaussianBlur, cv::RNG's noise, a round trip through cv::imencode's JPEG.
#include "tests/photo_degrade.h"

#include <cmath>
#include <cstdio>
#include <exception>
#include <vector>

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

extern "C" void test_photo_distort(const test_photo_t *p, int w, int h, double x, double y, double *xd, double *yd)
{
    // the bend: a wave across the image, two periods over its width
    x += p->bend_px * std::sin(2 * M_PI * 2 * y / h) * 0.5;
    y += p->bend_px * std::sin(2 * M_PI * 2 * x / w);
    double cx = (w - 1) / 2.0, cy = (h - 1) / 2.0, dx = x - cx, dy = y - cy;
    double g = p->f_px > 0 ? 1 + p->k1 * (dx * dx + dy * dy) / (p->f_px * p->f_px) : 1;
    *xd = cx + dx * g;
    *yd = cy + dy * g;
}

// The distorted image: each of its pixels from the undistorted point that moves
// there (the distortion inverted by fixed-point iteration), bilinear.
static void distort(cv::Mat &f, const test_photo_t *p)
{
    int w = f.cols, h = f.rows;
    cv::Mat mx(h, w, CV_32F), my(h, w, CV_32F), out;
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            double ux = x, uy = y;
            for (int it = 0; it < 30; it++) {
                double xd, yd;
                test_photo_distort(p, w, h, ux, uy, &xd, &yd);
                ux += x - xd;
                uy += y - yd;
            }
            mx.at<float>(y, x) = (float)ux;
            my.at<float>(y, x) = (float)uy;
        }
    cv::remap(f, out, mx, my, cv::INTER_LINEAR, cv::BORDER_CONSTANT, cv::Scalar(90));
    f = out;
}

extern "C" bool test_photo_degrade(unsigned char *img, int w, int h, const test_photo_t *p)
{
    try {
        cv::Mat m(h, w, CV_8UC1, img), f;
        m.convertTo(f, CV_32F);
        if ((p->k1 != 0 && p->f_px > 0) || p->bend_px != 0) distort(f, p);
        // the light: a linear gradient along light_dir_deg, times a vignette 1 - v (r / r_corner)^2
        double c = std::cos(p->light_dir_deg * M_PI / 180), s = std::sin(p->light_dir_deg * M_PI / 180);
        double ext = std::fabs(c) * (w - 1) / 2.0 + std::fabs(s) * (h - 1) / 2.0;
        double rc2 = ((w - 1) * (w - 1) + (h - 1) * (h - 1)) / 4.0;
        for (int y = 0; y < h; y++)
            for (int x = 0; x < w; x++) {
                double dx = x - (w - 1) / 2.0, dy = y - (h - 1) / 2.0;
                double t = ext > 0 ? ((dx * c + dy * s) / ext + 1) / 2 : 0;   // 0 .. 1 along the fall-off
                double g = 1 - (1 - p->light_lo) * t;
                g *= 1 - p->vignette * (dx * dx + dy * dy) / rc2;
                f.at<float>(y, x) *= (float)g;
            }
        if (p->glare > 0 && p->glare_sigma_px > 0)
            for (int y = 0; y < h; y++)
                for (int x = 0; x < w; x++) {
                    double r2 = (x - p->glare_x) * (x - p->glare_x) + (y - p->glare_y) * (y - p->glare_y);
                    f.at<float>(y, x) += (float)(255 * p->glare * std::exp(-r2 / (2 * p->glare_sigma_px * p->glare_sigma_px)));
                }
        if (p->blur_sigma_px > 0) cv::GaussianBlur(f, f, cv::Size(0, 0), p->blur_sigma_px);
        if (p->noise_dn > 0) {
            cv::Mat n(h, w, CV_32F);
            cv::RNG rng(p->seed ? p->seed : 1);
            rng.fill(n, cv::RNG::NORMAL, 0, p->noise_dn);
            f += n;
        }
        f.convertTo(m, CV_8U);   // rounded and saturated, into img
        if (p->jpeg_quality > 0) {
            std::vector<unsigned char> buf;
            if (!cv::imencode(".jpg", m, buf, { cv::IMWRITE_JPEG_QUALITY, p->jpeg_quality })) return false;
            cv::Mat d = cv::imdecode(buf, cv::IMREAD_GRAYSCALE);
            if (d.rows != h || d.cols != w) return false;
            d.copyTo(m);
        }
        return true;
    } catch (const std::exception &e) {
        fprintf(stderr, "test_photo_degrade: %s\n", e.what());
        return false;
    }
}
