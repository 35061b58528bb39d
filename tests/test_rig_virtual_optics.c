// tests/test_rig_virtual_optics.c — the virtual rig's optics outside the
// fitters' model (rig/virtual/optics.c, [optics] of the truth file): the PSF
// widens an edge by the configured width, N x N rays make an edge pixel its
// area fraction and converge, the rig's planes carry both, and the example
// truth file (no [optics]) renders what an explicit "off" does.
#define _GNU_SOURCE
#include <glib.h>
#include <limits.h>
#include <stdarg.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "model/model.h"
#include "rig/rig.h"
#include "rig/virtual/optics.h"
#include "tests/fixtures.h"
#include "tests/test.h"

// A vertical step edge (0 left of x = 100, 1000 from it on), PSF applied; the
// line-spread function (the ESF's differences, at x + 0.5) has the centre
// 99.5 and the standard deviation *sd.
static void edge_lsf(const rig_optics_t *o, double *centre, double *sd, double *total)
{
    enum { EW = 200, EH = 6 };
    float *L = malloc(EW * EH * sizeof *L);
    for (int y = 0; y < EH; y++)
        for (int x = 0; x < EW; x++) L[y * EW + x] = x >= 100 ? 1000.0f : 0.0f;
    CHECK(rig_optics_psf(o, EW, EH, L));
    double s0 = 0, s1 = 0, s2 = 0;
    const float *row = L + 3 * EW;
    for (int x = 0; x + 1 < EW; x++) {
        double d = row[x + 1] - row[x];
        s0 += d;
        s1 += d * (x + 0.5);
        s2 += d * (x + 0.5) * (x + 0.5);
    }
    *centre = s1 / s0;
    *sd = sqrt(s2 / s0 - *centre * *centre);
    *total = s0;
    free(L);
}

// Gaussian PSF: the edge's width is sigma (1 %: the kernel sampled at whole
// pixels), the edge stays where it was and no light is lost.
TEST(optics_psf_gaussian_widens_edge)
{
    const double sig[] = { 0.7, 1.0, 1.5 };
    for (int i = 0; i < 3; i++) {
        rig_optics_t o = { .rays_per_pixel = 1, .psf = RIG_PSF_GAUSSIAN, .psf_sigma_px = sig[i] };
        double c, sd, tot;
        edge_lsf(&o, &c, &sd, &tot);
        CHECK_REL(sd, sig[i], 0.01);
        CHECK_NEAR(c, 99.5, 1e-6);
        CHECK_REL(tot, 1000, 1e-6);
    }
    // the ESF itself is the normal CDF: at x = 99 and 101 for sigma 1
    enum { EW = 200, EH = 3 };
    float L[EW * EH];
    for (int k = 0; k < EW * EH; k++) L[k] = (k % EW) >= 100 ? 1.0f : 0.0f;
    rig_optics_t o = { .rays_per_pixel = 1, .psf = RIG_PSF_GAUSSIAN, .psf_sigma_px = 1.0 };
    CHECK(rig_optics_psf(&o, EW, EH, L));
    // a sampled unit Gaussian: P(k >= 1) over integers = 0.2420 + 0.0540 + 0.0044 + ... = 0.3007 / 1.0 normalised
    double w[9], s = 0;
    for (int k = -4; k <= 4; k++) s += w[k + 4] = exp(-0.5 * k * k);
    CHECK_NEAR(L[EW + 99], (w[5] + w[6] + w[7] + w[8]) / s, 1e-6);
    CHECK_NEAR(L[EW + 100], (w[4] + w[5] + w[6] + w[7] + w[8]) / s, 1e-6);
}

// Disc PSF (defocus): the edge spread function of a uniform disc of radius R
// is the share of the disc beyond the line, S(t) = (R^2 acos(t/R) - t
// sqrt(R^2 - t^2)) / (pi R^2); with each kernel pixel weighted by its area,
// pixel x of a step at x = 100 takes exactly S(99.5 - x) (to the 16 x 16
// sub-sampling of the weights).
TEST(optics_psf_disc_widens_edge)
{
    const double rad[] = { 1.0, 1.5, 3.0 };
    for (int i = 0; i < 3; i++) {
        const double R = rad[i];
        rig_optics_t o = { .rays_per_pixel = 1, .psf = RIG_PSF_DISC, .psf_radius_px = R };
        double c, sd, tot;
        edge_lsf(&o, &c, &sd, &tot);
        CHECK_NEAR(c, 99.5, 1e-6);
        CHECK_REL(tot, 1000, 1e-6);
        CHECK(sd > 0.45 * R);   // wider than the sharp edge
        enum { EW = 40, EH = 3 };
        float L[EW * EH];
        for (int k = 0; k < EW * EH; k++) L[k] = (k % EW) >= 20 ? 1.0f : 0.0f;
        CHECK(rig_optics_psf(&o, EW, EH, L));
        for (int x = 10; x < 30; x++) {
            double t = 19.5 - x, S;
            if (t <= -R) S = 1;
            else if (t >= R) S = 0;
            else S = (R * R * acos(t / R) - t * sqrt(R * R - t * t)) / (M_PI * R * R);
            CHECK_MSG(fabs(L[EW + x] - S) < 0.01, "R %g x %d: %g vs %g", R, x, L[EW + x], S);
        }
    }
}

// The exact area of the unit pixel [x, x+1] x [y, y+1] where a u + b v < c, by
// 1024 x 1024 midpoints (error < 1e-3).
static double area_fraction(int x, int y, double a, double b, double c)
{
    enum { M = 1024 };
    long in = 0;
    for (int j = 0; j < M; j++) {
        double v = y + (j + 0.5) / M;
        // along u the inside is an interval: count it directly
        for (int i = 0; i < M; i++) in += a * (x + (i + 0.5) / M) + b * v < c;
    }
    return (double)in / ((double)M * M);
}

// N x N rays over each pixel's footprint: a pixel on an edge takes its area
// fraction (to within 1/N), and the error falls as N grows.
TEST(optics_rays_area_fraction)
{
    enum { PW = 12, PH = 12 };
    const double a = 0.83, b = -0.56, c = 0.83 * 6.1 - 0.56 * 5.7;   // a slanted edge through (6.1, 5.7)
    double exact[PW * PH];
    for (int y = 0; y < PH; y++)
        for (int x = 0; x < PW; x++) exact[y * PW + x] = area_fraction(x, y, a, b, c);
    double prev_rms = INFINITY;
    const int Ns[] = { 1, 2, 4, 8 };
    for (int k = 0; k < 4; k++) {
        int N = Ns[k];
        float *hi = malloc((size_t)PW * PH * N * N * sizeof *hi), out[PW * PH];
        // the camera of N times the resolution: its pixel (X, Y) looks at the
        // centre ((X + 0.5) / N, (Y + 0.5) / N) in pixel-corner coordinates
        for (int Y = 0; Y < PH * N; Y++)
            for (int X = 0; X < PW * N; X++)
                hi[(size_t)Y * PW * N + X] = a * (X + 0.5) / N + b * (Y + 0.5) / N < c ? 1.0f : 0.0f;
        rig_optics_average(N, PW, PH, hi, out);
        double worst = 0, ss = 0;
        int edge = 0;
        for (int i = 0; i < PW * PH; i++) {
            double e = fabs(out[i] - exact[i]);
            worst = fmax(worst, e);
            ss += e * e;
            edge += exact[i] > 0.01 && exact[i] < 0.99;
        }
        double rms = sqrt(ss / PW / PH);
        CHECK(edge >= 12);
        if (N > 1) CHECK_MSG(worst <= 1.0 / N + 1e-3, "N %d: worst %g", N, worst);
        CHECK_MSG(rms < prev_rms, "N %d: rms %g not below %g", N, rms, prev_rms);
        prev_rms = rms;
        free(hi);
    }
    CHECK(prev_rms < 0.03);
}

// ---------------------------------------------------------------------------
// The rig: [optics] of a truth file reaches every plane.

// The example truth file with replacements (pairs from, to; NULL-ended) and
// extra text appended, its relative paths made absolute; its path.
static const char *truth_with(const char *extra, ...)
{
    const char *rep[33];
    int n = 0;
    va_list ap;
    va_start(ap, extra);
    for (const char *from; n < 31 && (from = va_arg(ap, const char *));) {
        rep[n++] = from;
        rep[n++] = va_arg(ap, const char *);
    }
    va_end(ap);
    rep[n] = NULL;
    static int count;
    char name[32];
    snprintf(name, sizeof name, "truth%d.ini", count++);
    return fx_truth_variant("virtual-truth.ini", name, rep, extra ? extra : "");
}

// Deterministic planes: no Monte Carlo, point lamps.
#define PLAIN "interreflection = mc", "interreflection = none", "finite_lamps = 1", "finite_lamps = 0"

static rig_virtual_t *open_truth(const char *path)
{
    rig_virtual_options_t o = rig_virtual_defaults();
    o.serve = RIG_VIRTUAL_SERVE_INPROCESS;
    o.time_scale = 0.001;
    o.prerender = 0;
    rig_virtual_t *v = NULL;
    int rc = rig_virtual_open(&v, path, &o);
    CHECK_MSG(rc == 0, "rig_virtual_open %s: %d %s", path, rc, model_last_error());
    return v;
}

// The plane of lamp 0 at 10 deg (malloc'd; its size in *W, *H).
static float *plane(const char *truth, int *W, int *H)
{
    rig_virtual_t *v = open_truth(truth);
    if (!v) return NULL;
    model_camera_t *cam = rig_virtual_camera_model(v);
    *W = model_camera_width(cam);
    *H = model_camera_height(cam);
    float *L = malloc((size_t)*W * *H * sizeof *L);
    CHECK(rig_virtual_radiance(v, 10, 0, L) == 0);
    rig_virtual_close(v);
    return L;
}

// psf = gaussian in [optics]: every plane is the plane without it, convolved.
TEST(optics_rig_psf_in_planes)
{
    int W, H, W2, H2;
    float *L0 = plane(truth_with(NULL, PLAIN, NULL), &W, &H);
    float *L1 = plane(truth_with("[optics]\npsf = gaussian\npsf_sigma_px = 1.2\n", PLAIN, NULL), &W2, &H2);
    CHECK(L0 && L1 && W == W2 && H == H2);
    if (!L0 || !L1) goto done;
    rig_optics_t o = { .rays_per_pixel = 1, .psf = RIG_PSF_GAUSSIAN, .psf_sigma_px = 1.2 };
    CHECK(rig_optics_psf(&o, W, H, L0));
    double worst = 0, peak = 0;
    for (size_t i = 0; i < (size_t)W * H; i++) {
        worst = fmax(worst, fabs(L1[i] - L0[i]));
        peak = fmax(peak, fabs(L0[i]));
    }
    CHECK(peak > 0);
    CHECK_MSG(worst <= 1e-6 * peak, "worst %g of %g", worst, peak);
done:
    free(L0);
    free(L1);
}

// rays_per_pixel: the planes converge as N grows (the change from 2 to 4 rays
// is well below that from 1 to 2), the mean radiance stays (0.5 %), and the
// pixels that change are on edges: values between their neighbours'.
TEST(optics_rig_rays_converge)
{
    int W, H, W2, H2, W4, H4;
    float *L1 = plane(truth_with(NULL, PLAIN, NULL), &W, &H);
    float *L2 = plane(truth_with("[optics]\nrays_per_pixel = 2\n", PLAIN, NULL), &W2, &H2);
    float *L4 = plane(truth_with("[optics]\nrays_per_pixel = 4\n", PLAIN, NULL), &W4, &H4);
    CHECK(L1 && L2 && L4 && W == W2 && W == W4 && H == H2 && H == H4);
    if (!L1 || !L2 || !L4) goto done;
    double d12 = 0, d24 = 0, m1 = 0, m4 = 0;
    size_t n = (size_t)W * H;
    for (size_t i = 0; i < n; i++) {
        d12 += fabs(L2[i] - L1[i]);
        d24 += fabs(L4[i] - L2[i]);
        m1 += L1[i];
        m4 += L4[i];
    }
    CHECK(d12 > 0);
    CHECK_MSG(d24 < 0.7 * d12, "|L4 - L2| %g vs |L2 - L1| %g", d24, d12);
    CHECK_REL(m4, m1, 5e-3);
    // where 4 rays changed a pixel most, it lies between the extremes of its 3 x 3 neighbours at 1 ray
    size_t big = 0, inside = 0;
    for (int y = 1; y + 1 < H; y++)
        for (int x = 1; x + 1 < W; x++) {
            size_t i = (size_t)y * W + x;
            if (fabs(L4[i] - L1[i]) < 0.2 * fmax(fabs(L1[i]), 1e-30) || L1[i] == 0) continue;
            double lo = INFINITY, hi = -INFINITY;
            for (int dy = -1; dy <= 1; dy++)
                for (int dx = -1; dx <= 1; dx++) {
                    lo = fmin(lo, L1[i + dy * W + dx]);
                    hi = fmax(hi, L1[i + dy * W + dx]);
                }
            big++;
            inside += L4[i] >= lo - 1e-3 * hi && L4[i] <= hi * (1 + 1e-3);
        }
    CHECK(big > 100);
    CHECK_MSG(inside >= 0.95 * big, "%zu of %zu changed pixels between their neighbours", inside, big);
done:
    free(L1);
    free(L2);
    free(L4);
}

// Off by default: the example truth file and one that says [optics] and the
// adversarial sensor keys are off give the same expected frames, bit for bit.
TEST(optics_off_is_bit_exact)
{
    const char *off = "[optics]\nrays_per_pixel = 1\npsf = none\n";
    const char *base = truth_with(NULL, NULL);
    const char *expl = truth_with(off, "pattern_seed = 1", "pattern_seed = 1\nknee_e = 0\nlow_end_gamma = 1\n"
                                  "low_end_e = 0\nhot_pixel_fraction = 0\nrow_noise_dn = 0", NULL);
    // one at a time (an in-process camera's serial is served once)
    rig_virtual_t *a = open_truth(base);
    float *Ea = NULL, *Eb = NULL;
    if (!a) goto done;
    model_camera_t *cam = rig_virtual_camera_model(a);
    int W = model_camera_width(cam), H = model_camera_height(cam);
    size_t n = (size_t)W * H;
    Ea = malloc(2 * n * sizeof *Ea);
    Eb = malloc(2 * n * sizeof *Eb);
    CHECK(rig_virtual_expected(a, 10, 0x3, 10000, 0, "Mono12", W, H, Ea) == 0);
    CHECK(rig_virtual_sensor_apply(a, 10000, 0, 5, memcpy(Ea + n, Ea, n * sizeof *Ea)) == 0);
    rig_virtual_close(a);
    rig_virtual_t *b = open_truth(expl);
    if (!b) goto done;
    CHECK(rig_virtual_expected(b, 10, 0x3, 10000, 0, "Mono12", W, H, Eb) == 0);
    CHECK(rig_virtual_sensor_apply(b, 10000, 0, 5, memcpy(Eb + n, Eb, n * sizeof *Eb)) == 0);
    rig_virtual_close(b);
    CHECK(memcmp(Ea, Eb, n * sizeof *Ea) == 0);
    CHECK(memcmp(Ea + n, Eb + n, n * sizeof *Ea) == 0);
done:
    free(Ea);
    free(Eb);
}

// Bad [optics] values: a clear message naming the file's line.
TEST(optics_truth_errors)
{
    struct { const char *text, *want; } cases[] = {
        { "[optics]\npsf = blur\n", "psf = blur: use none, gaussian" },
        { "[optics]\npsf = gaussian\n", "lacks 'psf_sigma_px'" },
        { "[optics]\npsf = disc\npsf_radius_px = 0\n", "psf_radius_px" },
        { "[optics]\npsf_sigma_px = 1\n", "psf_sigma_px is given but psf = none" },
        { "[optics]\nrays_per_pixel = 9\n", "rays_per_pixel" },
        { "[optics]\nrays = 2\n", "unknown key 'rays'" },
    };
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
        const char *path = truth_with(cases[i].text, NULL);
        char *text = model_read_file(path, NULL);
        const char *name = strrchr(path, '/') + 1;
        CHECK(rig_virtual_check_truth(text, strlen(text), name, test_tmpdir()) != 0);
        CHECK_CONTAINS(model_last_error(), cases[i].want);
        CHECK_CONTAINS(model_last_error(), name);
        free(text);
    }
}

// rays_per_pixel with the example's own rendering (Monte Carlo direct light
// of finite lamps, interreflection at 1/4 of the resolution, textures): the
// indirect light and the textures follow the finer camera, and the plane's
// mean stays that of one ray per pixel (1 %: the MC noise of a state).
TEST(optics_rig_rays_with_mc)
{
    int W, H, W2, H2;
    float *L1 = plane(truth_with(NULL, NULL), &W, &H);
    float *L2 = plane(truth_with("[optics]\nrays_per_pixel = 2\n", NULL), &W2, &H2);
    CHECK(L1 && L2 && W == W2 && H == H2);
    if (!L1 || !L2) goto done;
    double m1 = 0, m2 = 0;
    size_t n = (size_t)W * H, lit = 0;
    for (size_t i = 0; i < n; i++) {
        CHECK(isfinite(L2[i]) && L2[i] >= 0);
        m1 += L1[i];
        m2 += L2[i];
        lit += L2[i] > 0;
    }
    CHECK(lit > n / 10);
    CHECK_REL(m2, m1, 0.01);
done:
    free(L1);
    free(L2);
}

// The knee through the rig (flat field, one lamp): the expected frame's photon
// transfer departs from the linear response exactly as configured, pixel by
// pixel: E(t) = E_dark + K knee(e(t)), e(t) the linear rig's electrons scaled
// with the exposure (no dark current, no quadratic compression here).
TEST(optics_rig_sensor_knee_photon_transfer)
{
#define LIN "dark_current_e_per_s = 20", "dark_current_e_per_s = 0", "nonlinearity_pct = 2", "nonlinearity_pct = 0"
    const char *lin = truth_with(NULL, LIN, NULL);
    const char *knee = truth_with(NULL, LIN, "pattern_seed = 1", "pattern_seed = 1\nknee_e = 12000", NULL);
#undef LIN
    rig_virtual_t *v = open_truth(lin);
    float *E0 = NULL, *E1 = NULL, *Ek = NULL;
    if (!v) return;
    model_camera_t *cam = rig_virtual_camera_model(v);
    int W = model_camera_width(cam), H = model_camera_height(cam);
    size_t n = (size_t)W * H;
    const double K = rig_virtual_sensor_params(v).system_gain_dn_per_e, t0 = 10000;
    E0 = malloc(n * sizeof *E0);
    E1 = malloc(n * sizeof *E1);
    Ek = malloc(n * sizeof *Ek);
    CHECK(rig_virtual_set_sample(v, "flat_field") == 0);
    CHECK(rig_virtual_expected(v, 0, 0x0, t0, 0, "Mono12", W, H, E0) == 0);   // dark
    CHECK(rig_virtual_expected(v, 0, 0x1, t0, 0, "Mono12", W, H, E1) == 0);
    rig_virtual_close(v);
    v = open_truth(knee);
    if (!v) goto done;
    CHECK(rig_virtual_set_sample(v, "flat_field") == 0);
    const double ts[] = { 10000, 25000, 35000, 42000 };
    double centre_drop = 0;
    for (int k = 0; k < 4; k++) {
        CHECK(rig_virtual_expected(v, 0, 0x1, ts[k], 0, "Mono12", W, H, Ek) == 0);
        double worst = 0;
        for (size_t i = 0; i < n; i++) {
            double e = (E1[i] - E0[i]) / K * ts[k] / t0;
            double ke = e <= 12000 ? e : 12000 + 4000 * tanh((e - 12000) / 4000);
            worst = fmax(worst, fabs(Ek[i] - (E0[i] + K * ke)));
        }
        CHECK_MSG(worst < 0.02, "exposure %g us: worst %g DN", ts[k], worst);
        size_t c = (size_t)(H / 2) * W + W / 2;
        centre_drop = (E1[c] - E0[c]) * ts[k] / t0 - (Ek[c] - E0[c]);
    }
    CHECK(centre_drop > 100);   // DN below the straight line at the longest exposure
    rig_virtual_close(v);
done:
    free(E0);
    free(E1);
    free(Ek);
}
