// tests/test_model_edge_profile.c — a step edge as the pixels see it
// (model/edges/profile.c): the closed forms against a numerically rendered
// step (each pixel the mean of 48 x 48 points of its footprint, each point the
// Gaussian-blurred step's value there) run through a 3 x 3 Sobel, the sharp
// step's known responses (4.0 axis-aligned, 3 sqrt 2 = 4.24 diagonal), and the
// derivatives by finite differences.
#include <math.h>
#include <stdio.h>

#include "model/model.h"
#include "tests/test.h"

enum { NS = 48 };

// The rendered pixel whose centre lies u from the edge (normal theta), the
// step blurred by sigma > 0: its footprint's mean by the midpoint rule.
static double rendered_pixel(double u, double theta, double sigma)
{
    double c = cos(theta), s = sin(theta), sum = 0;
    for (int j = 0; j < NS; j++)
        for (int i = 0; i < NS; i++) {
            double x = -0.5 + (i + 0.5) / NS, y = -0.5 + (j + 0.5) / NS;
            sum += 0.5 * erfc(-(u + x * c + y * s) / (sigma * M_SQRT2));
        }
    return sum / (NS * NS);
}

// A 3 x 3 Sobel (1 2 1 across 1 0 -1) on the rendered pixels around the one u from the edge.
static double rendered_sobel(double u, double theta, double sigma)
{
    double P[3][3], c = cos(theta), s = sin(theta);
    for (int j = -1; j <= 1; j++)
        for (int i = -1; i <= 1; i++) P[j + 1][i + 1] = rendered_pixel(u + i * c + j * s, theta, sigma);
    double gx = (P[0][2] + 2 * P[1][2] + P[2][2]) - (P[0][0] + 2 * P[1][0] + P[2][0]);
    double gy = (P[2][0] + 2 * P[2][1] + P[2][2]) - (P[0][0] + 2 * P[0][1] + P[0][2]);
    return hypot(gx, gy);
}

TEST(model_edge_sobel_against_rendered_step)
{
    const double thetas_deg[] = { 0, 7, 22.5, 30, 45, 60, 90, 135, 200 }, sigmas[] = { 0.3, 0.5, 0.8, 1.2 };
    const double us[] = { 0, 0.17, 0.4, -0.33, 1.1 };
    double worst = 0;
    for (int a = 0; a < 9; a++)
        for (int b = 0; b < 4; b++)
            for (int k = 0; k < 5; k++) {
                double th = thetas_deg[a] * M_PI / 180, sg = sigmas[b], u = us[k];
                double e = fabs(model_edge_sobel(u, th, sg) - rendered_sobel(u, th, sg));
                double ep = fabs(model_edge_spread(u, th, sg, NULL, NULL) - rendered_pixel(u, th, sg));
                CHECK_MSG(e < 1e-3 && ep < 2e-4, "theta %g deg, sigma %g, u %g: Sobel %.6f rendered %.6f, pixel %.6f "
                          "rendered %.6f", thetas_deg[a], sg, u, model_edge_sobel(u, th, sg),
                          rendered_sobel(u, th, sg), model_edge_spread(u, th, sg, NULL, NULL),
                          rendered_pixel(u, th, sg));
                worst = fmax(worst, e);
            }
    printf("  closed form against the rendered step: Sobel within %.2g per unit contrast\n", worst);
    // the detector's peak over the phases: best is the edge through a pixel centre
    for (int b = 0; b < 4; b++) {
        model_sobel_step_t r = model_edge_sobel_step(0, sigmas[b]);
        CHECK_NEAR(r.best, rendered_sobel(0, 0, sigmas[b]), 1e-3);
        CHECK_NEAR(r.worst, rendered_sobel(0.5, 0, sigmas[b]), 1e-3);
        CHECK(r.worst <= r.mean && r.mean <= r.best);
    }
    model_sobel_step_t r8 = model_edge_sobel_step(0, 0.8), d8 = model_edge_sobel_step(M_PI / 4, 0.8);
    printf("  sigma 0.8 px: axis-aligned best %.3f mean %.3f worst %.3f; diagonal best %.3f mean %.3f worst %.3f\n",
           r8.best, r8.mean, r8.worst, d8.best, d8.mean, d8.worst);
}

// A sharp step (sigma 0, the footprint alone): the known responses.
TEST(model_edge_sobel_sharp_step)
{
    model_sobel_step_t a = model_edge_sobel_step(0, 0), d = model_edge_sobel_step(M_PI / 4, 0);
    CHECK_NEAR(a.best, 4.0, 1e-12);
    CHECK_NEAR(a.worst, 4.0, 1e-12);   // any phase: the pixels beside an axis-aligned step see all of it
    CHECK_NEAR(d.best, 3 * M_SQRT2, 1e-9);
    // the edge half-way between the diagonal's pixel centres (0.354 px from each): gx = gy = 3 - 2 c^2 = 2.75
    CHECK_NEAR(d.worst, 2.75 * M_SQRT2, 1e-9);
    for (int k = 0; k < 8; k++) {   // symmetric under the image's quarter turns and mirrors, continuous in sigma
        double th = k * M_PI / 4;
        CHECK_NEAR(model_edge_sobel_step(th, 0).best, k % 2 ? 3 * M_SQRT2 : 4.0, 1e-9);
        CHECK_NEAR(model_edge_sobel_step(th + 0.3, 0.5).best, model_edge_sobel_step(-th - 0.3, 0.5).best, 1e-9);
    }
    CHECK_NEAR(model_edge_sobel_step(0.3, 1e-4).best, model_edge_sobel_step(0.3, 0).best, 1e-3);
    // the edge spread: 0 .. 1, a half at the edge, odd about it, the footprint's width at sigma 0
    CHECK_NEAR(model_edge_spread(0, 0.4, 0.7, NULL, NULL), 0.5, 1e-12);
    CHECK_NEAR(model_edge_spread(0.3, 0.4, 0.7, NULL, NULL) + model_edge_spread(-0.3, 0.4, 0.7, NULL, NULL), 1, 1e-12);
    CHECK_NEAR(model_edge_spread(9, 0.4, 0.7, NULL, NULL), 1, 1e-12);
    CHECK_NEAR(model_edge_spread(-9, 0.4, 0.7, NULL, NULL), 0, 1e-12);
    CHECK_NEAR(model_edge_spread(0.25, 0, 0, NULL, NULL), 0.75, 1e-12);    // a box of 1 px
    CHECK_NEAR(model_edge_spread(0.5, 0, 0, NULL, NULL), 1, 1e-12);
    CHECK_NEAR(model_edge_spread(-M_SQRT1_2 / 2, M_PI / 4, 0, NULL, NULL), 0.125, 1e-9);   // a triangle
}

// dE/du and dE/dsigma against central differences.
TEST(model_edge_spread_derivatives)
{
    const double thetas[] = { 0, 1e-7, 0.2, M_PI / 4, 1.3 }, sigmas[] = { 0.2, 0.6, 1.5 };
    const double us[] = { -1.3, -0.2, 0, 0.45, 2 };
    for (int a = 0; a < 5; a++)
        for (int b = 0; b < 3; b++)
            for (int k = 0; k < 5; k++) {
                double th = thetas[a], s = sigmas[b], u = us[k], du, ds, h = 1e-5;
                model_edge_spread(u, th, s, &du, &ds);
                double fu = (model_edge_spread(u + h, th, s, NULL, NULL) - model_edge_spread(u - h, th, s, NULL, NULL)) /
                            (2 * h);
                double fs = (model_edge_spread(u, th, s + h, NULL, NULL) - model_edge_spread(u, th, s - h, NULL, NULL)) /
                            (2 * h);
                CHECK_MSG(fabs(du - fu) < 1e-6 && fabs(ds - fs) < 1e-6, "theta %g sigma %g u %g: dE/du %.9f (fd %.9f), "
                          "dE/dsigma %.9f (fd %.9f)", th, s, u, du, fu, ds, fs);
            }
}
