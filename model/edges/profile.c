// model/edges/profile.c — a straight step edge as the pixels see it: the step
// convolved with an isotropic Gaussian point-spread function (the optics'
// blur, sigma) and integrated over each pixel's footprint (its own 1 x 1 px
// square), and the 3 x 3 Sobel detector's response to it (model/model.h).
//
// The footprint projected onto the edge's normal n = (cos t, sin t) is the
// sum of two uniform variables, of widths a = |cos t| and b = |sin t| (a box
// of 1 px for an axis-aligned edge, a triangle of base sqrt 2 px for a
// diagonal one). With F0(x) = Phi(x / sigma) (the blurred step), F1 its
// antiderivative and F2 that of F1,
//   F1(x) = x Phi(x/s) + s phi(x/s),
//   F2(x) = (x^2 + s^2)/2 Phi(x/s) + x s/2 phi(x/s),
// the pixel at signed distance u from the edge sees
//   E(u) = [F2(u + (a+b)/2) - F2(u + (a-b)/2) - F2(u - (a-b)/2) + F2(u - (a+b)/2)] / (a b)
// (for b -> 0: [F1(u + a/2) - F1(u - a/2)] / a). Its u-derivatives take F1
// and F0 in place of F2, and as any Gaussian blur it obeys the heat equation,
// dE/dsigma = sigma d2E/du2. sigma = 0: the footprint alone (F0 the step,
// F1 = max(x, 0), F2 = max(x, 0)^2 / 2).
#define _GNU_SOURCE
#include <math.h>

#include "model/model.h"

// Below this, the thinner box of the footprint is taken as a line (the
// closed form divides by it; the error is of its order squared).
#define THIN_BOX 1e-5

// F_k(x) for k = 0, 1, 2 (see above), and k = -1: the Gaussian's density
// phi(x/s)/s, F0's derivative (0 for s = 0, where it is a delta that only
// dE/dsigma = 0 meets).
static double Fk(int k, double x, double s)
{
    if (!(s > 0)) {
        double p = x > 0 ? x : 0;
        return k < 0 ? 0.0 : k == 0 ? (x > 0 ? 1.0 : x < 0 ? 0.0 : 0.5) : k == 1 ? p : 0.5 * p * p;
    }
    double z = x / s, phi = exp(-0.5 * z * z) / sqrt(2 * M_PI);
    if (k < 0) return phi / s;
    double Phi = 0.5 * erfc(-z * M_SQRT1_2);
    if (k == 0) return Phi;
    if (k == 1) return x * Phi + s * phi;
    return 0.5 * (x * x + s * s) * Phi + 0.5 * x * s * phi;
}

// The footprint's average of the blurred step (k = 2), of its u-derivative
// (k = 1) and of its second (k = 0), at u; a, b the footprint's box widths
// along the normal.
static double footprint(int k, double u, double a, double b, double s)
{
    if (b > a) {
        double t = a;
        a = b;
        b = t;
    }
    if (b < THIN_BOX) return (Fk(k - 1, u + 0.5 * a, s) - Fk(k - 1, u - 0.5 * a, s)) / a;
    double p = 0.5 * (a + b), m = 0.5 * (a - b);
    return (Fk(k, u + p, s) - Fk(k, u + m, s) - Fk(k, u - m, s) + Fk(k, u - p, s)) / (a * b);
}

double model_edge_spread(double u_px, double theta_rad, double sigma_px, double *dE_du, double *dE_dsigma)
{
    double a = fabs(cos(theta_rad)), b = fabs(sin(theta_rad)), s = sigma_px > 0 ? sigma_px : 0;
    if (dE_du) *dE_du = footprint(1, u_px, a, b, s);
    if (dE_dsigma) *dE_dsigma = s > 0 ? s * footprint(0, u_px, a, b, s) : 0;
    return footprint(2, u_px, a, b, s);
}

double model_edge_sobel(double u_px, double theta_rad, double sigma_px)
{
    double c = cos(theta_rad), sn = sin(theta_rad), a = fabs(c), b = fabs(sn), s = sigma_px > 0 ? sigma_px : 0;
    static const double w[3] = { 1, 2, 1 };
    double gx = 0, gy = 0;
    for (int j = -1; j <= 1; j++) {
        gx += w[j + 1] * (footprint(2, u_px + c + j * sn, a, b, s) - footprint(2, u_px - c + j * sn, a, b, s));
        gy += w[j + 1] * (footprint(2, u_px + j * c + sn, a, b, s) - footprint(2, u_px + j * c - sn, a, b, s));
    }
    return hypot(gx, gy);
}

// The detector's peak across the edge at phase ph: the largest response of
// the pixels at distances ph + k sp.
static double sobel_peak(double ph, double sp, double theta_rad, double s)
{
    double best = 0;
    for (int k = -2; k <= 2; k++) best = fmax(best, model_edge_sobel(ph + k * sp, theta_rad, s));
    return best;
}

model_sobel_step_t model_edge_sobel_step(double theta_rad, double sigma_px)
{
    enum { NPHASE = 32 };
    double sp = fmax(fabs(cos(theta_rad)), fabs(sin(theta_rad)));
    model_sobel_step_t r = { .best = sobel_peak(0, sp, theta_rad, sigma_px),
                             .worst = sobel_peak(0.5 * sp, sp, theta_rad, sigma_px) };
    double sum = 0;
    for (int i = 0; i < NPHASE; i++) {
        double v = sobel_peak((i + 0.5) / NPHASE * 0.5 * sp, sp, theta_rad, sigma_px);
        sum += v;
        r.best = fmax(r.best, v);
        r.worst = fmin(r.worst, v);
    }
    r.mean = sum / NPHASE;
    return r;
}
