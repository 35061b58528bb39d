// tests/test_model_sensor.c — the sensor stage: photon transfer (EMVA 1288), fixed
// patterns, quantisation and clipping, Poisson statistics, non-linearity,
// vignetting, reproducibility.
#define _GNU_SOURCE
#include <stdlib.h>

#include "model/internal.h"
#include "tests/test.h"

#define W 512
#define H 256
#define N ((size_t)W * H)

static float *filled(double P)
{
    float *img = malloc(N * sizeof *img);
    for (size_t i = 0; i < N; i++) img[i] = (float)P;
    return img;
}

static void mean_var(const float *a, double *mean, double *var)
{
    double s = 0, s2 = 0;
    for (size_t i = 0; i < N; i++) s += a[i];
    *mean = s / N;
    for (size_t i = 0; i < N; i++) s2 += (a[i] - *mean) * (a[i] - *mean);
    *var = s2 / (N - 1);
}

// A sensor without fixed patterns, vignetting or non-linearity, huge well:
// K = 1 DN/e- and offset 0 make the output the electron count itself.
static model_sensor_t counting_sensor(void)
{
    model_sensor_t s = model_sensor_default();
    s.bits = 16;
    s.system_gain_dn_per_e = 1;
    s.full_well_e = 1e6;
    s.read_noise_e = 0;
    s.dark_offset_dn = 0;
    s.dsnu_dn = 0;
    s.prnu_pct = 0;
    s.vignetting = 0;
    s.nonlinearity_pct = 0;
    return s;
}

// Photon transfer: two frames with different noise seeds; the temporal variance
// var(A - B)/2 against K (mean - offset) + K^2 read^2 + 1/12 at several levels
// (5 e- up to 12000 e-), and the mean against K mu + offset.
TEST(sensor_photon_transfer)
{
    model_sensor_t s = model_sensor_default();
    s.vignetting = 0;
    s.nonlinearity_pct = 0;
    const double K = s.system_gain_dn_per_e;
    const double levels_e[] = { 5, 40, 300, 2500, 12000 };
    for (size_t l = 0; l < sizeof levels_e / sizeof levels_e[0]; l++) {
        double P = s.dark_offset_dn + levels_e[l] * K;
        float *a = filled(P), *b = filled(P);
        s.noise_seed = 11;
        model_sensor_apply(&s, W, H, a);
        s.noise_seed = 12;
        model_sensor_apply(&s, W, H, b);
        double sum = 0, sd = 0, sd2 = 0;
        for (size_t i = 0; i < N; i++) {
            sum += 0.5 * (a[i] + b[i]);
            double d = a[i] - b[i];
            sd += d;
            sd2 += d * d;
        }
        double mean = sum / N;
        double var = 0.5 * (sd2 / N - (sd / N) * (sd / N));
        double expect_var = K * (mean - s.dark_offset_dn) + K * K * s.read_noise_e * s.read_noise_e + 1.0 / 12;
        CHECK_REL(mean - s.dark_offset_dn, K * levels_e[l], 0.01);
        CHECK_REL(var, expect_var, 0.03);
        free(a);
        free(b);
    }
}

// Exact Poisson statistics (K = 1, no other noise): P(0) = e^-mu for mu = 2;
// mean, variance and P(k = 30) for mu = 30 (the rejection sampler); mean and
// variance for mu = 5000.
TEST(sensor_poisson)
{
    model_sensor_t s = counting_sensor();
    float *a = filled(2.0);
    model_sensor_apply(&s, W, H, a);
    double m, v;
    mean_var(a, &m, &v);
    size_t zeros = 0;
    for (size_t i = 0; i < N; i++) zeros += a[i] == 0;
    CHECK_NEAR(m, 2.0, 4 * sqrt(2.0 / N));
    CHECK_REL(v, 2.0, 0.02);
    double p0 = exp(-2.0);
    CHECK_NEAR((double)zeros / N, p0, 4 * sqrt(p0 * (1 - p0) / N));
    free(a);

    a = filled(30.0);
    model_sensor_apply(&s, W, H, a);
    mean_var(a, &m, &v);
    CHECK_NEAR(m, 30.0, 4 * sqrt(30.0 / N));
    CHECK_REL(v, 30.0, 0.02);
    for (int k = 20; k <= 40; k += 5) {
        size_t c = 0;
        for (size_t i = 0; i < N; i++) c += a[i] == k;
        double pk = exp(-30.0 + k * log(30.0) - lgamma(k + 1.0));
        CHECK_NEAR((double)c / N, pk, 4.5 * sqrt(pk * (1 - pk) / N));
    }
    free(a);

    a = filled(5000.0);
    model_sensor_apply(&s, W, H, a);
    mean_var(a, &m, &v);
    CHECK_NEAR(m, 5000.0, 4 * sqrt(5000.0 / N));
    CHECK_REL(v, 5000.0, 0.02);
    free(a);
}

// Pixels without signal (the dark current only) take the inversion at the
// dark mean of the vectorised pass, their tail beyond its table (8 terms)
// the scalar way: the counts follow Poisson(4) for k = 0..14. Read noise alone (round
// of sigma z, sigma 3): variance sigma^2 + 1/12, and the fraction beyond 3.5
// sigma as the normal's (the ziggurat's tail and wedges are the scalar way).
TEST(sensor_dark_counts_and_read_noise_tails)
{
    model_sensor_t s = counting_sensor();
    s.dark_current_e_per_s = 4e4;
    s.exposure_us = 100;   // 4 e- of dark current
    float *a = filled(0.0);
    model_sensor_apply(&s, W, H, a);
    for (int k = 0; k <= 14; k++) {
        size_t c = 0;
        for (size_t i = 0; i < N; i++) c += a[i] == k;
        double pk = exp(-4.0 + k * log(4.0) - lgamma(k + 1.0));
        double tol = 4.5 * sqrt(pk * (1 - pk) / N) + 1.0 / N;
        CHECK_MSG(fabs((double)c / N - pk) <= tol, "P(%d) = %.6f, Poisson %.6f", k, (double)c / N, pk);
    }
    free(a);

    s = counting_sensor();
    s.read_noise_e = 3;
    s.dark_offset_dn = 100;   // room below for negative values
    a = filled(100.0);
    model_sensor_apply(&s, W, H, a);
    double m, v;
    mean_var(a, &m, &v);
    CHECK_NEAR(m, 100.0, 4 * sqrt(9.0 / N));
    CHECK_REL(v, 9.0 + 1.0 / 12, 0.02);
    size_t far = 0;
    for (size_t i = 0; i < N; i++) far += fabs(a[i] - 100.0) > 10.5;   // |round(3z)| >= 11: |z| > 3.5
    double p_far = erfc(3.5 / sqrt(2.0));
    CHECK_NEAR((double)far / N, p_far, 4.5 * sqrt(p_far / N));
    free(a);
}

TEST(sensor_fixed_patterns)
{
    model_sensor_t s = model_sensor_default();
    s.prnu_pct = 1.7;
    s.dsnu_dn = 2.5;
    float *g = malloc(N * sizeof *g), *d = malloc(N * sizeof *d);
    float *g2 = malloc(N * sizeof *g2), *d2 = malloc(N * sizeof *d2);
    model_sensor_patterns(&s, W, H, g, d);
    double m, v;
    mean_var(g, &m, &v);
    CHECK_NEAR(m, 1.0, 1e-6);
    CHECK_REL(sqrt(v), 0.017, 1e-4);
    mean_var(d, &m, &v);
    CHECK_NEAR(m, 0.0, 1e-6);
    CHECK_REL(sqrt(v), 2.5, 1e-4);
    // documented structure: the column means carry 10 % (PRNU) and 30 % (DSNU)
    // of the variance (plus the white part averaged over H rows)
    for (int which = 0; which < 2; which++) {
        const float *map = which ? d : g;
        double ref = which ? 2.5 : 0.017, share = which ? 0.30 : 0.10, white = which ? 0.65 : 0.85;
        double mm = which ? 0.0 : 1.0, cs2 = 0;
        for (int x = 0; x < W; x++) {
            double c = 0;
            for (int y = 0; y < H; y++) c += map[(size_t)y * W + x];
            c = c / H - mm;
            cs2 += c * c;
        }
        double col_std = sqrt(cs2 / W), expect = ref * sqrt(share + white / H);
        CHECK_REL(col_std, expect, 0.15);
    }
    // deterministic from pattern_seed, and the noise seed plays no part
    s.noise_seed = 77;
    model_sensor_patterns(&s, W, H, g2, d2);
    CHECK(memcmp(g, g2, N * sizeof *g) == 0 && memcmp(d, d2, N * sizeof *d) == 0);
    s.pattern_seed = 2;
    model_sensor_patterns(&s, W, H, g2, NULL);
    CHECK(memcmp(g, g2, N * sizeof *g) != 0);
    // zero configured: flat
    s.prnu_pct = 0;
    s.dsnu_dn = 0;
    model_sensor_patterns(&s, W, H, g2, d2);
    bool flat = true;
    for (size_t i = 0; i < N; i++) flat = flat && g2[i] == 1.0f && d2[i] == 0.0f;
    CHECK(flat);
    free(g);
    free(d);
    free(g2);
    free(d2);
}

// Integers within [0, 2^bits - 1]; dark pixels clip at 0, saturated ones at the
// top code, or at the full well's (compressed) level plus DSNU when below it.
TEST(sensor_quantisation_and_saturation)
{
    const int bits[] = { 8, 12, 16 };
    for (int b = 0; b < 3; b++) {
        model_sensor_t s = model_sensor_default();
        s.bits = bits[b];
        s.dark_offset_dn = 0.5;   // half the dark pixels fall below 0
        double maxv = (1 << bits[b]) - 1;
        const double inputs[] = { 0.0, 500.0, 1e7, NAN, -1e9 };
        for (int k = 0; k < 5; k++) {
            float *a = filled(inputs[k]);
            model_sensor_apply(&s, W, H, a);
            bool ok = true;
            double lo = 1e30, hi = -1e30;
            for (size_t i = 0; i < N; i++) {
                ok = ok && a[i] == floor(a[i]) && a[i] >= 0 && a[i] <= maxv;
                lo = fmin(lo, a[i]);
                hi = fmax(hi, a[i]);
            }
            CHECK_MSG(ok, "%d bits, input %g: values outside the integers of [0, %g]", bits[b],
                      inputs[k], maxv);
            if (k == 0 || k >= 3) CHECK(lo == 0);   // dark: the read noise reaches below 0
            if (k == 2 && bits[b] == 8) CHECK(lo == 255 && hi == 255);
            free(a);
        }
    }
    // 12 bits, default gain: saturated pixels read f(FW) K + offset + dsnu(x,y)
    model_sensor_t s = model_sensor_default();
    float *a = filled(1e6), *d = malloc(N * sizeof *d);
    model_sensor_apply(&s, W, H, a);
    model_sensor_patterns(&s, W, H, NULL, d);
    double e = s.full_well_e, c = s.nonlinearity_pct / 100;
    e *= 1.0 - c * e / s.full_well_e;
    size_t bad = 0;
    for (size_t i = 0; i < N; i++)
        bad += a[i] != floor(e * s.system_gain_dn_per_e + s.dark_offset_dn + d[i] + 0.5);
    CHECK(bad == 0);
    CHECK_NEAR(e * s.system_gain_dn_per_e + s.dark_offset_dn, 3984, 1e-9);
    // K 0.5: the full well is beyond the 12-bit range, all pixels at 4095
    s.system_gain_dn_per_e = 0.5;
    for (size_t i = 0; i < N; i++) a[i] = 1e6f;
    model_sensor_apply(&s, W, H, a);
    bad = 0;
    for (size_t i = 0; i < N; i++) bad += a[i] != 4095;
    CHECK(bad == 0);
    free(a);
    free(d);
}

TEST(sensor_reproducible)
{
    model_sensor_t s = model_sensor_default();
    float *a = filled(900), *b = filled(900), *c = filled(900);
    model_sensor_apply(&s, W, H, a);
    const char *old = getenv("REFL_THREADS");
    char *saved = old ? strdup(old) : NULL;
    setenv("REFL_THREADS", "1", 1);
    model_sensor_apply(&s, W, H, b);   // same seeds, one thread
    if (saved) setenv("REFL_THREADS", saved, 1);
    else unsetenv("REFL_THREADS");
    free(saved);
    CHECK(memcmp(a, b, N * sizeof *a) == 0);
    s.noise_seed = 2;
    model_sensor_apply(&s, W, H, c);
    CHECK(memcmp(a, c, N * sizeof *a) != 0);
    free(a);
    free(b);
    free(c);
}

// A nearly noiseless sensor (1e8 e- signals, K 1e-5 DN/e-: shot noise 0.1 DN)
// to see the deterministic parts.
static model_sensor_t quiet_sensor(double full_well_e)
{
    model_sensor_t s = counting_sensor();
    s.system_gain_dn_per_e = 1e-5;
    s.full_well_e = full_well_e;
    return s;
}

// vig = 1 - v (r / r_corner)^2 about the image centre
TEST(sensor_vignetting)
{
    model_sensor_t s = quiet_sensor(1e12);
    s.vignetting = 0.2;
    float *a = filled(1000);
    model_sensor_apply(&s, W, H, a);
    double cx = 0.5 * (W - 1), cy = 0.5 * (H - 1), worst = 0;
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++) {
            double r2 = ((x - cx) * (x - cx) + (y - cy) * (y - cy)) / (cx * cx + cy * cy);
            worst = fmax(worst, fabs(a[(size_t)y * W + x] - 1000 * (1 - 0.2 * r2)));
        }
    CHECK(worst <= 1.0);   // rounding 0.5 + shot noise (0.1 DN std)
    CHECK_NEAR(a[0], 800, 1.0);
    CHECK_NEAR(a[N - 1], 800, 1.0);
    CHECK_NEAR(a[(size_t)(H / 2) * W + W / 2], 1000, 1.0);
    free(a);
}

// Response f(e) = e (1 - c e / FW): c below linear at full well, smooth and
// monotonic below it.
TEST(sensor_nonlinearity)
{
    model_sensor_t s = quiet_sensor(1e8);   // full well = 1000 DN linear
    s.nonlinearity_pct = 5;
    s.dsnu_dn = 1;   // dithers the rounding (mean 0), so the mean is unbiased
    double prev = -1;
    for (int k = 1; k <= 10; k++) {
        double frac = k < 10 ? 0.1 * k : 0.9995;   // 5 sigma below saturation at k = 10
        float *a = filled(1000 * frac);
        model_sensor_apply(&s, W, H, a);
        double m, v;
        mean_var(a, &m, &v);
        double f = frac * (1 - 0.05 * frac);
        CHECK_NEAR(m, 1000 * f, 0.02);
        CHECK(m > prev);
        prev = m;
        free(a);
    }
    // saturated: exactly 5 % below the linear full-well response (1000 DN)
    s.dsnu_dn = 0;
    float *a = filled(5000);
    model_sensor_apply(&s, W, H, a);
    size_t bad = 0;
    for (size_t i = 0; i < N; i++) bad += a[i] != 950;
    CHECK(bad == 0);
    free(a);
    // realistic sensor, 2 %: 90 % of the well reads 1.8 % below linear
    model_sensor_t r = model_sensor_default();
    r.vignetting = 0;
    r.prnu_pct = 0;
    double mu = 0.9 * r.full_well_e;
    a = filled(r.dark_offset_dn + mu * r.system_gain_dn_per_e);
    model_sensor_apply(&r, W, H, a);
    double m, v;
    mean_var(a, &m, &v);
    CHECK_REL(m - r.dark_offset_dn, mu * r.system_gain_dn_per_e * (1 - 0.02 * 0.9), 5e-4);
    free(a);
}

TEST(sensor_dark_current)
{
    model_sensor_t s = counting_sensor();
    s.dark_current_e_per_s = 400;
    s.exposure_us = 250000;   // 100 e-
    s.dark_offset_dn = 10;
    float *a = filled(10);   // no light
    model_sensor_apply(&s, W, H, a);
    double m, v;
    mean_var(a, &m, &v);
    CHECK_NEAR(m, 110, 4 * sqrt(100.0 / N));
    CHECK_REL(v, 100, 0.02);   // K = 1: integer electrons, no quantisation noise
    free(a);
}

// model_gain_factor: the one conversion of a recorded gain, by its unit.
TEST(sensor_gain_factor_units)
{
    double f = 0;
    CHECK(model_gain_factor(6, "dB", 0, "dB", "frame a", &f));
    CHECK_REL(f, 1.9952623149688795, 1e-12);                 // 10^(6/20)
    CHECK(model_gain_factor(20, "db", 0, "dB", "frame a", &f));
    CHECK_REL(f, 10.0, 1e-12);
    CHECK(model_gain_factor(12, NULL, 0, "dB", "old frame", &f));   // no unit: dB (older sessions)
    CHECK_REL(f, 3.981071705534972, 1e-12);
    CHECK(model_gain_factor(12, "", 6, "dB", "old frame", &f));     // relative to a calibration at 6 dB
    CHECK_REL(f, 1.9952623149688795, 1e-12);
    CHECK(model_gain_factor(2.5, "x", 0, "dB", "frame b", &f));
    CHECK_REL(f, 2.5, 1e-12);
    CHECK(model_gain_factor(4, "times", 2, "linear", "frame b", &f));
    CHECK_REL(f, 2.0, 1e-12);
    CHECK(model_gain_factor(2, "factor", 20, "dB", "frame b", &f));   // 2 against 10
    CHECK_REL(f, 0.2, 1e-12);
    // raw: only at the calibration's gain
    CHECK(model_gain_factor(100, "raw", 100, "raw", "frame c", &f));
    CHECK_NEAR(f, 1.0, 0);
    f = -1;
    CHECK(!model_gain_factor(200, "raw", 100, "raw", "frames/s000007.png", &f));
    CHECK_CONTAINS(model_last_error(), "frames/s000007.png");
    CHECK_CONTAINS(model_last_error(), "unit 'raw'");
    CHECK_NEAR(f, -1, 0);
    CHECK(!model_gain_factor(0, "raw", 0, "dB", "frame d", &f));      // raw against a dB calibration
    CHECK_CONTAINS(model_last_error(), "0 dB");
    CHECK(!model_gain_factor(3, "DN/e", 0, "dB", "frame e", &f));     // any unknown unit
    CHECK_CONTAINS(model_last_error(), "'DN/e'");
    CHECK(!model_gain_factor(0, "x", 0, "dB", "frame f", &f));        // a factor of 0
    CHECK_CONTAINS(model_last_error(), "frame f");
    CHECK(!model_gain_factor(NAN, "dB", 0, "dB", "frame g", &f));
}

// ---------------------------------------------------------------------------
// The adversary's sensor effects: outside the fitters' S(1 - aS).

// The photon transfer curve with a soft knee: mean vs exposure is linear below
// knee_e (0.1 %) and follows k + (FW - k) tanh((e - k)/(FW - k)) above it,
// whereas the quadratic S(1 - aS) fitted to the linear part would not.
TEST(sensor_adversary_knee_photon_transfer)
{
    model_sensor_t s = counting_sensor();
    s.full_well_e = 16000;
    s.knee_e = 12000;
    s.dsnu_dn = 1;   // dithers the rounding
    const double rate_e_per_ms = 1000;   // electrons per ms of exposure
    for (int t_ms = 2; t_ms <= 30; t_ms += 4) {
        double mu = rate_e_per_ms * t_ms;
        float *a = filled(mu);
        model_sensor_apply(&s, W, H, a);
        double m, v;
        mean_var(a, &m, &v);
        double k = s.knee_e, FW = s.full_well_e;
        double want = mu <= k ? mu : k + (FW - k) * tanh((mu - k) / (FW - k));
        // Poisson spread through the knee's curvature is below 1 e- here
        CHECK_NEAR(m, want, 1.5);
        if (mu > 14000) CHECK(mu - m > 0.05 * mu);   // well off the straight line
        if (mu <= 10000) CHECK_REL(m, mu, 1e-3);
        free(a);
    }
    // the noise-free mean follows the same curve, and never reaches full well
    float *a = filled(40000);
    model_sensor_mean(&s, W, H, NULL, NULL, a);
    CHECK_NEAR(a[0], 12000 + 4000 * tanh(7.0), 1e-2);
    CHECK(a[0] < 16000);
    free(a);
}

// A gamma at the low end: low_end_e (e / low_end_e)^gamma below low_end_e.
TEST(sensor_adversary_low_end_gamma)
{
    model_sensor_t s = counting_sensor();
    s.low_end_gamma = 1.1;
    s.low_end_e = 200;
    const double lv[] = { 20, 50, 100, 199, 400 };
    for (size_t i = 0; i < sizeof lv / sizeof lv[0]; i++) {
        float *a = filled(lv[i]);
        model_sensor_mean(&s, W, H, NULL, NULL, a);
        double want = lv[i] < 200 ? 200 * pow(lv[i] / 200, 1.1) : lv[i];
        CHECK_NEAR(a[0], want, 1e-3);
        free(a);
    }
    // with noise: the mean at 50 e- is ~14 % low (200 (1/4)^1.1 = 43.5)
    float *a = filled(50);
    model_sensor_apply(&s, W, H, a);
    double m, v;
    mean_var(a, &m, &v);
    CHECK_NEAR(m, 43.5, 0.5);
    free(a);
}

// Dark current: the dark frame's mean grows linearly with exposure (slope the
// dark current, intercept the offset), hot pixels excluded.
TEST(sensor_adversary_dark_current_linear)
{
    model_sensor_t s = counting_sensor();
    s.dark_current_e_per_s = 50;
    s.dark_offset_dn = 10;
    double sx = 0, sy = 0, sxx = 0, sxy = 0;
    const double t_s[] = { 0.1, 0.5, 1, 2, 4 };
    for (int i = 0; i < 5; i++) {
        s.exposure_us = t_s[i] * 1e6;
        float *a = filled(10);
        model_sensor_apply(&s, W, H, a);
        double m, v;
        mean_var(a, &m, &v);
        CHECK_NEAR(m, 10 + 50 * t_s[i], 4 * sqrt(50 * t_s[i] / N) + 1e-9);
        sx += t_s[i];
        sy += m;
        sxx += t_s[i] * t_s[i];
        sxy += t_s[i] * m;
        free(a);
    }
    double slope = (5 * sxy - sx * sy) / (5 * sxx - sx * sx), icpt = (sy - slope * sx) / 5;
    CHECK_REL(slope, 50, 2e-3);
    CHECK_NEAR(icpt, 10, 0.05);
}

// Hot pixels: the configured fraction, at the configured dark current, fixed
// (the same pixels in every frame, from pattern_seed).
TEST(sensor_adversary_hot_pixels)
{
    model_sensor_t s = counting_sensor();
    s.dark_current_e_per_s = 20;
    s.hot_pixel_fraction = 1e-3;
    s.hot_pixel_dark_current_e_per_s = 2000;
    s.exposure_us = 1e6;
    float *a = filled(0), *b = filled(0);
    model_sensor_apply(&s, W, H, a);
    s.noise_seed = 99;
    model_sensor_apply(&s, W, H, b);
    size_t hot = 0, same = 0;
    double sum = 0;
    for (size_t i = 0; i < N; i++)
        if (a[i] > 1000) {
            hot++;
            same += b[i] > 1000;
            sum += a[i];
        }
    // binomial: 131 expected, sd 11.4
    CHECK_NEAR((double)hot, 1e-3 * N, 4 * sqrt(1e-3 * N));
    CHECK(same == hot);
    CHECK_NEAR(sum / (double)hot, 2020, 4 * sqrt(2020.0 / (double)hot));
    free(a);
    free(b);
    // off by default: no pixel above the dark level's Poisson tail
    s = counting_sensor();
    s.dark_current_e_per_s = 20;
    s.exposure_us = 1e6;
    a = filled(0);
    model_sensor_apply(&s, W, H, a);
    hot = 0;
    for (size_t i = 0; i < N; i++) hot += a[i] > 100;
    CHECK(hot == 0);
    free(a);
}

// Row noise: the std of the row means (over rows) is the configured DN rms,
// new in every frame; the mean has none.
TEST(sensor_adversary_row_noise)
{
    model_sensor_t s = counting_sensor();
    s.dark_offset_dn = 100;
    s.row_noise_dn = 3;
    float *a = filled(100);
    model_sensor_apply(&s, W, H, a);
    double rm[H], m = 0, v = 0;
    for (int y = 0; y < H; y++) {
        double t = 0;
        for (int x = 0; x < W; x++) t += a[(size_t)y * W + x];
        rm[y] = t / W;
        m += rm[y] / H;
    }
    for (int y = 0; y < H; y++) v += (rm[y] - m) * (rm[y] - m) / (H - 1);
    // quantisation of the offset to integers adds ~1/12 DN^2 per pixel, averaged out over a row
    CHECK_NEAR(sqrt(v), 3, 4 * 3 / sqrt(2.0 * H));
    // within a row, nothing: every pixel of a row has the same value
    size_t differ = 0;
    for (int y = 0; y < H; y++)
        for (int x = 1; x < W; x++) differ += a[(size_t)y * W + x] != a[(size_t)y * W];
    CHECK(differ == 0);
    free(a);
    float *b = filled(100);
    model_sensor_mean(&s, W, H, NULL, NULL, b);
    CHECK(b[0] == 100 && b[N - 1] == 100);
    free(b);
}

// What EMVA 1288's dark figures read from a sensor (model_sensor_dark_measurand):
// the sensor's own read noise and dark current when the response is linear at
// 0 and there is no row noise; with row noise, their sum in quadrature; with
// the adversary's low-end gamma and hot pixels, what frames drawn from the
// sensor itself show (pairs of 1024 x 1024 frames: var(A - B) / 2 less
// q^2/12 at exposure 0, and the mean's rise with exposure).
TEST(sensor_dark_measurand_known_answer)
{
    model_sensor_t s = model_sensor_default();
    s.dark_current_e_per_s = 20;
    double rn = 0, dc = 0, t2[2] = { 0, 10000 }, t4[4] = { 100000, 500000, 1000000, 2000000 };
    CHECK(model_sensor_dark_measurand(&s, t2, 2, &rn, &dc));
    CHECK_NEAR(rn, 6, 6e-6);
    CHECK_NEAR(dc, 20, 20e-4);   // (the 2 % compression at full well: 1 - 0.02 e / FW near 0)
    s.row_noise_dn = 0.5;
    CHECK(model_sensor_dark_measurand(&s, NULL, 0, &rn, NULL));
    CHECK_NEAR(rn, sqrt(36 + 4), 1e-5);   // 0.5 DN at 0.25 DN/e- is 2 e-
    CHECK(!model_sensor_dark_measurand(&s, t2, 1, &rn, &dc));   // one exposure: no slope
    CHECK_CONTAINS(model_last_error(), "at least 2 different exposures");
    CHECK(model_sensor_dark_measurand(&s, t4, 4, NULL, &dc));   // 40 e- in 2 s: still linear
    CHECK_NEAR(dc, 20, 20e-4);
    // the adversary's sensor: the low end's gamma compresses the read noise
    s.low_end_gamma = 1.02;
    s.low_end_e = 800;
    s.hot_pixel_fraction = 1e-4;
    s.hot_pixel_dark_current_e_per_s = 2000;
    s.prnu_pct = 0;
    s.dsnu_dn = 0;
    s.vignetting = 0;
    CHECK(model_sensor_dark_measurand(&s, t4, 4, &rn, &dc));
    fprintf(stderr, "  adversarial sensor: read noise %.4f e- (nominal %.4f), dark current %.3f e-/s (nominal 20 + "
            "hot 0.2)\n", rn, sqrt(40.0), dc);
    CHECK(rn < 0.98 * sqrt(40.0));
    CHECK(dc < 0.98 * 20.2);
    const int w = 1024, h = 1024;
    const size_t n = (size_t)w * h;
    float *a = malloc(n * sizeof *a), *b = malloc(n * sizeof *b);
    CHECK(a && b);
    if (!a || !b) goto out;
    // read noise: exposure 0
    s.exposure_us = 0;
    double v = 0;
    for (int rep = 0; rep < 2; rep++) {
        for (size_t i = 0; i < n; i++) a[i] = b[i] = (float)s.dark_offset_dn;
        s.noise_seed = 11 + 2 * rep;
        model_sensor_apply_patterns(&s, w, h, NULL, NULL, a);
        s.noise_seed = 12 + 2 * rep;
        model_sensor_apply_patterns(&s, w, h, NULL, NULL, b);
        for (size_t i = 0; i < n; i++) v += (double)(a[i] - b[i]) * (a[i] - b[i]) / 2;
    }
    double rn_mc = sqrt(v / (2.0 * n) - 1.0 / 12) / s.system_gain_dn_per_e;
    fprintf(stderr, "  frames: read noise %.4f e-\n", rn_mc);
    CHECK_MSG(fabs(rn_mc / rn - 1) < 0.004, "read noise %.4f e- from frames, %.4f computed", rn_mc, rn);
    // dark current: a high one (20 e- in 1 ms, within the low end) and no row noise, so
    // the frames' means are precise to 0.03 %
    s.row_noise_dn = 0;
    s.dark_current_e_per_s = 20000;
    double t1[2] = { 0, 1000 };
    CHECK(model_sensor_dark_measurand(&s, t1, 2, NULL, &dc));
    double m[2];
    for (int k = 0; k < 2; k++) {
        s.exposure_us = k ? 1000 : 0;
        s.noise_seed = 21 + k;
        for (size_t i = 0; i < n; i++) a[i] = (float)s.dark_offset_dn;
        model_sensor_apply_patterns(&s, w, h, NULL, NULL, a);
        double sum = 0;
        for (size_t i = 0; i < n; i++) sum += a[i];
        m[k] = sum / n;
    }
    double dc_mc = (m[1] - m[0]) / 1e-3 / s.system_gain_dn_per_e;
    fprintf(stderr, "  dark current %.1f e-/s computed, %.1f from frames (nominal 20000 + hot 0.2)\n", dc, dc_mc);
    CHECK_MSG(fabs(dc_mc / dc - 1) < 0.002, "dark current %.1f e-/s from frames, %.1f computed", dc_mc, dc);
    CHECK(dc < 0.97 * 20000);
out:
    free(a);
    free(b);
}
