// tests/test_rig_virtual.c — the virtual rig end to end over GigE Vision on
// 127.0.0.1: the simulated turntable and lamps set a state, the real Aravis
// capture path takes the frame, and the frame is compared with the model's
// noise-free rendering of that state (rig_virtual_expected) by its statistics:
// the mean difference over lit pixels is ~0 within a few standard errors and
// the variance of the difference is the sensor's temporal noise
//   var(DN) = K (E - dark_offset) + (read_noise K)^2 + 1/12,
// while a wrong state (another angle, another lamp) is clearly rejected.
#define _GNU_SOURCE
#include <fcntl.h>
#include <glib.h>
#include <limits.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/file.h>
#include <unistd.h>

#include "model/model.h"
#include "rig/rig.h"
#include "rig/virtual/truth.h"
#include "tests/fixtures.h"
#include "tests/test.h"
#include "tests/virtual_stats.h"

#define W 1280
#define H 1024


static const char *truth_path(void)
{
    static char p[1024];
    snprintf(p, sizeof p, "%s/examples/virtual-truth.ini", test_srcdir());
    return p;
}

static rig_virtual_t *open_rig(const char *sample)
{
    rig_virtual_options_t o = rig_virtual_defaults();
    o.time_scale = 0.001;
    o.busy_wait_s = 120;
    o.sample = sample;
    o.noise_seed = 77;
    rig_virtual_t *v = NULL;
    int rc = rig_virtual_open(&v, truth_path(), &o);
    CHECK_MSG(rc == 0, "rig_virtual_open: %d %s", rc, model_last_error());
    return v;
}

typedef vstat_t cmp_t;

// The shared statistic (tests/virtual_stats.h) over the whole frame.
static cmp_t compare(const uint16_t *pix, const float *E, double lit_dn)
{
    return vstat_compare(pix, E, (size_t)W * H, lit_dn);
}

static int capture(rig_camera_t *c, rig_frame_t *f)
{
    int rc = rig_camera_capture(c, 10.0, 2, f);
    CHECK_MSG(rc == 0, "capture: %d %s", rc, model_last_error());
    return rc;
}

TEST(virtual_rig_frame_matches_model)
{
    int session = test_camera_lock();
    CHECK(session >= 0);
    rig_virtual_t *v = open_rig(NULL);
    rig_camera_t *c = NULL;
    float *E = malloc((size_t)W * H * sizeof(float)), *E2 = malloc((size_t)W * H * sizeof(float));
    rig_frame_t f = { 0 };
    if (!v || !E || !E2) goto done;
    CHECK(!strcmp(rig_virtual_sample(v), "t_stiffener"));
    CHECK(!strcmp(rig_virtual_camera_address(v), "127.0.0.1"));
    CHECK_CONTAINS(rig_virtual_truth_path(v), "virtual-truth.ini");
    rig_turntable_t *tt = rig_virtual_turntable(v);
    rig_lamps_t *lamps = rig_virtual_lamps(v);
    CHECK(rig_lamps_count(lamps) == 5);
    int rc = rig_camera_open_aravis(&c, rig_virtual_camera_address(v));
    CHECK_MSG(rc == 0, "open: %d %s", rc, model_last_error());
    if (rc) goto done;
    CHECK_CONTAINS(rig_camera_name(c), "REFL-VIRT01");
    CHECK(rig_camera_set_pixel_format(c, "Mono12") == 0);
    CHECK(rig_camera_set_exposure_us(c, 10000) == 0);
    CHECK(rig_camera_set_gain(c, 0) == 0);

    // Moves need homing, as on the real stage.
    CHECK(rig_turntable_move_abs_deg(tt, 30, 5) == RIG_ERR_NOT_HOMED);
    CHECK(rig_turntable_home(tt, 5) == 0);
    CHECK(rig_turntable_move_abs_deg(tt, 30, 5) == 0);
    rig_turntable_status_t st;
    CHECK(rig_turntable_status(tt, &st) == 0);
    CHECK(st.homed && !st.moving);
    CHECK_NEAR(st.angle_deg, 30, 0.02);   // position noise 0.002 deg
    int east = rig_lamps_find(lamps, "east");
    CHECK(east == 0);
    CHECK(rig_lamps_set(lamps, 1u << east) == 0);

    if (capture(c, &f)) goto done;
    CHECK(f.meta.width == W && f.meta.height == H && f.meta.bits == 12);
    CHECK(!strcmp(f.meta.serial, "REFL-VIRT01"));
    rc = rig_virtual_expected(v, st.angle_deg, 1u << east, 10000, 0, "Mono12", W, H, E);
    CHECK_MSG(rc == 0, "expected: %d %s", rc, model_last_error());
    cmp_t ok = compare(f.pix, E, 100);
    printf("  virtual rig, right state: %ld lit pixels, mean diff %.4f DN (se %.4f), var ratio %.4f\n", ok.n,
           ok.mean, ok.se, ok.z2);
    CHECK(ok.n > 50000);
    CHECK_MSG(fabs(ok.mean) < 4 * ok.se + 0.02, "mean difference %.4f DN, standard error %.4f", ok.mean, ok.se);
    CHECK_NEAR(ok.z2, 1.0, 0.1);

    // Wrong states: the same statistic rejects them.
    CHECK(rig_virtual_expected(v, st.angle_deg + 1, 1u << east, 10000, 0, "Mono12", W, H, E2) == 0);
    cmp_t bad_angle = compare(f.pix, E2, 100);
    printf("  wrong angle (+1 deg): var ratio %.2f\n", bad_angle.z2);
    CHECK(bad_angle.z2 > 3);
    CHECK(rig_virtual_expected(v, st.angle_deg, 1u << 1, 10000, 0, "Mono12", W, H, E2) == 0);
    cmp_t bad_lamp = compare(f.pix, E2, 100);
    printf("  wrong lamp: var ratio %.2f\n", bad_lamp.z2);
    CHECK(bad_lamp.z2 > 3);
    rig_frame_free(&f);

    // Gain: +6.02 dB doubles the signal above the dark level; still matches.
    CHECK(rig_camera_set_gain(c, 20 * log10(2.0)) == 0);
    if (capture(c, &f)) goto done;
    CHECK(rig_virtual_expected(v, st.angle_deg, 1u << east, 10000, 20 * log10(2.0), "Mono12", W, H, E2) == 0);
    double s1 = 0, s2 = 0;
    long nl = 0;
    for (size_t i = 0; i < (size_t)W * H; i++)
        if (E[i] > 200 && E[i] < 1500) {
            s1 += E[i] - 64;
            s2 += E2[i] - 64;
            nl++;
        }
    CHECK(nl > 10000);
    CHECK_REL(s2 / s1, 2.0, 0.01);   // the non-linearity (2 % at full well) bends it slightly
    // With the gain, the noise in DN grows by the gain (K * 2): var = 2K (E - 64) + (6 * 2K)^2 + 1/12.
    {
        double z2 = 0;
        long n = 0;
        for (size_t i = 0; i < (size_t)W * H; i++) {
            if (!(E2[i] - 64 >= 100 && E2[i] < 4000)) continue;
            double var = 0.5 * (E2[i] - 64) + 36 * 0.25 + 1.0 / 12, d = f.pix[i] - E2[i];
            z2 += d * d / var;
            n++;
        }
        CHECK(n > 10000);
        CHECK_NEAR(z2 / n, 1.0, 0.1);
    }
    rig_frame_free(&f);
    CHECK(rig_camera_set_gain(c, 0) == 0);

    // Mono16 carries the 12-bit values << 4.
    CHECK(rig_camera_set_pixel_format(c, "Mono16") == 0);
    if (capture(c, &f)) goto done;
    CHECK(f.meta.bits == 16);
    long not16 = 0;
    double m16 = 0, m12 = 0;
    for (size_t i = 0; i < (size_t)W * H; i++) {
        not16 += f.pix[i] % 16 != 0;
        m16 += f.pix[i];
        m12 += E[i];
    }
    CHECK(not16 == 0);
    CHECK_REL(m16 / 16, m12, 1e-3);
    rig_frame_free(&f);
    CHECK(rig_camera_set_pixel_format(c, "Mono12") == 0);

    // All lamps off: a dark frame at the offset (64 DN, DSNU 1.5 DN, read noise 1.5 DN).
    CHECK(rig_lamps_all_off(lamps) == 0);
    if (capture(c, &f)) goto done;
    double sum = 0, sum2 = 0;
    uint16_t maxv = 0;
    for (size_t i = 0; i < (size_t)W * H; i++) {
        sum += f.pix[i];
        sum2 += (double)f.pix[i] * f.pix[i];
        maxv = f.pix[i] > maxv ? f.pix[i] : maxv;
    }
    double mean = sum / (W * H), sd = sqrt(sum2 / (W * H) - mean * mean);
    printf("  dark frame: mean %.3f DN, std %.3f DN, max %u\n", mean, sd, maxv);
    CHECK_NEAR(mean, 64, 0.3);
    CHECK_NEAR(sd, sqrt(1.5 * 1.5 + 1.5 * 1.5 + 1.0 / 12), 0.3);
    CHECK(maxv < 64 + 20);
    rig_frame_free(&f);

    // Another sample: the reference white, at 0 deg, lamp north.
    CHECK(rig_virtual_set_sample(v, "no_such_sample") == RIG_ERR_INVALID);
    CHECK_CONTAINS(model_last_error(), "reference_white");
    CHECK(rig_virtual_set_sample(v, "reference_white") == 0);
    CHECK(!strcmp(rig_virtual_sample(v), "reference_white"));
    CHECK(rig_turntable_move_abs_deg(tt, 0, 5) == 0);
    CHECK(rig_turntable_status(tt, &st) == 0);
    CHECK(rig_lamps_set(lamps, 1u << 3) == 0);
    if (capture(c, &f)) goto done;
    CHECK(rig_virtual_expected(v, st.angle_deg, 1u << 3, 10000, 0, "Mono12", W, H, E) == 0);
    cmp_t white = compare(f.pix, E, 100);
    printf("  reference white: %ld lit pixels, mean diff %.4f DN (se %.4f), var ratio %.4f\n", white.n,
           white.mean, white.se, white.z2);
    CHECK(white.n > 20000);
    CHECK(fabs(white.mean) < 4 * white.se + 0.02);
    CHECK_NEAR(white.z2, 1.0, 0.1);
    // The tile fills a smaller part of the image than the workpiece's plate.
    CHECK(white.n < ok.n);
    rig_frame_free(&f);

done:
    rig_frame_free(&f);
    rig_camera_close(c);
    rig_virtual_close(v);
    free(E);
    free(E2);
    test_camera_unlock(session);
}

// A truth file with one thing changed: `from` replaced by `to` in the example.
static const char *truth_variant(const char *from, const char *to)
{
    return fx_truth_variant("virtual-truth.ini", "truth.ini", (const char *const[]){ from, to, NULL }, NULL);
}

// Line number of the first line of path containing needle.
static int line_of(const char *path, const char *needle)
{
    char *text = model_read_file(path, NULL);
    if (!text) return -1;
    int line = 1;
    char *p = strstr(text, needle);
    for (char *q = text; p && q < p; q++) line += *q == '\n';
    free(text);
    return p ? line : -1;
}

static void expect_error(const char *from, const char *to, const char *line_needle, const char *msg)
{
    const char *path = truth_variant(from, to);
    rig_virtual_t *v = NULL;
    rig_virtual_options_t o = rig_virtual_defaults();
    o.time_scale = 0.001;
    int rc = rig_virtual_open(&v, path, &o);
    CHECK(rc == RIG_ERR_INVALID);
    CHECK(v == NULL);
    char where[1200];
    snprintf(where, sizeof where, "%s:%d:", path, line_of(path, line_needle));
    CHECK_CONTAINS(model_last_error(), where);
    CHECK_CONTAINS(model_last_error(), msg);
    rig_virtual_close(v);
}

TEST(virtual_truth_errors)
{
    expect_error("home_time_s = 15", "home_time_s = 15\nspeed_mm_s = 3", "speed_mm_s", "unknown key 'speed_mm_s'");
    expect_error("home_time_s = 15", "home_time_s = fifteen", "home_time_s", "not a number");
    expect_error("model_sha256 = 6783", "model_sha256 = 0783", "model_sha256", "sha256");
    expect_error("material = metal", "material = unobtainium", "unobtainium", "no [material unobtainium]");
    expect_error("material = metal", "material = plywood",
                 "material = plywood\ndirect_samples = 16\n\n[sample coupon_plywood]", "uses material 'metal'");
    expect_error("scene = samples/coupon_metal.d3d", "scene = samples/coupon_steel.d3d", "coupon_steel",
                 "coupon_steel.d3d");
    expect_error("kind = workpiece", "kind = gadget", "gadget", "kind = 'gadget' is unknown");
    expect_error("[render]", "[renderer]", "[renderer]", "unknown section [renderer]");
    expect_error("sample = t_stiffener", "sample = t_beam", "t_beam", "samples: t_stiffener, chessboard");
    expect_error("interreflection = mc", "interreflection = photon_map", "photon_map", "use none, thesis or mc");
    expect_error("bits = 12", "bits = 10", "bits = 10", "must be 8, 12 or 16");
    expect_error("radius_mm = 15\n\n[lamp south]", "radius_mm = -15\n\n[lamp south]", "radius_mm = -15",
                 "radius_mm");
    expect_error("corners = 9 7", "corners = 9", "corners = 9", "two integers");
    // A missing truth file names itself.
    rig_virtual_t *v = NULL;
    CHECK(rig_virtual_open(&v, "/nonexistent/truth.ini", NULL) == RIG_ERR_INVALID);
    CHECK_CONTAINS(model_last_error(), "/nonexistent/truth.ini");
    CHECK(v == NULL);
}

// The truth file's format version ([virtual] format_version): a file without
// one is version 1; a newer one is refused by every reader of the file
// (rig_truth_load as rig_virtual_open), naming the versions.
TEST(virtual_truth_format_version)
{
    rig_truth_t *t = rig_truth_load(truth_path());
    CHECK_MSG(t && rig_truth_format_version(t) == 1, "%s", model_last_error());
    rig_truth_free(t);
    char path[1200];
    snprintf(path, sizeof path, "%s", truth_variant("[virtual]", "[virtual]\nformat_version = 1"));
    t = rig_truth_load(path);
    CHECK_MSG(t && rig_truth_format_version(t) == 1, "%s", model_last_error());
    rig_truth_free(t);
    snprintf(path, sizeof path, "%s", truth_variant("[virtual]", "[virtual]\nformat_version = 2"));
    CHECK(rig_truth_load(path) == NULL);
    CHECK_CONTAINS(model_last_error(), "format_version = 2: a truth file of a newer refl");
    CHECK_CONTAINS(model_last_error(), "up to format version 1");
    expect_error("[virtual]", "[virtual]\nformat_version = 2", "format_version", "a truth file of a newer refl");
    expect_error("[virtual]", "[virtual]\nformat_version = two", "format_version", "a whole number from 1");
}

// The albedo texture of the truth file's plywood (amplitude 0.08): the
// expected frame with it, divided (above the dark level) by the one without it,
// varies smoothly about 1 within the amplitude on the plate and is exactly 1 on
// the untextured painted steel; amplitude 0 is no texture at all.
TEST(virtual_texture)
{
    int session = test_camera_lock();
    CHECK(session >= 0);
    float *E1 = malloc((size_t)W * H * sizeof(float)), *E0 = malloc((size_t)W * H * sizeof(float));
    rig_virtual_t *v = open_rig(NULL);
    if (!v || !E1 || !E0) goto done;
    CHECK(rig_virtual_expected(v, 10, 0xf, 10000, 0, "Mono12", W, H, E1) == 0);
    rig_virtual_close(v);
    rig_virtual_options_t o = rig_virtual_defaults();
    o.time_scale = 0.001;
    o.busy_wait_s = 120;
    v = NULL;
    int rc = rig_virtual_open(&v, truth_variant("amplitude = 0.08", "amplitude = 0"), &o);
    CHECK_MSG(rc == 0, "open: %s", model_last_error());
    if (rc) goto done;
    CHECK(rig_virtual_expected(v, 10, 0xf, 10000, 0, "Mono12", W, H, E0) == 0);
    long n = 0, ones = 0, pairs = 0;
    double s = 0, s2 = 0, maxdev = 0, sxy = 0, sxx = 0;
    for (int y = 0; y < H; y++)
        for (int x = 0; x + 1 < W; x++) {
            size_t i = (size_t)y * W + x;
            if (!(E0[i] - 64 > 300 && E0[i] < 3800)) continue;
            double r = (E1[i] - 64) / (E0[i] - 64) - 1;
            n++;
            ones += fabs(r) < 1e-4;
            s += r;
            s2 += r * r;
            maxdev = fmax(maxdev, fabs(r));
            if (E0[i + 1] - 64 > 300 && E0[i + 1] < 3800) {
                double r1 = (E1[i + 1] - 64) / (E0[i + 1] - 64) - 1;
                sxy += r * r1;
                sxx += r * r;
                pairs++;
            }
        }
    double mean = s / n, sd = sqrt(s2 / n - mean * mean);
    printf("  texture: %ld pixels, %ld untextured, ratio - 1: mean %.4f std %.4f max %.4f, neighbour corr %.3f\n",
           n, ones, mean, sd, maxdev, sxy / sxx);
    CHECK(n > 100000);
    CHECK(ones > 1000);                      // the painted steel
    CHECK(n - ones > 100000);                // the plywood plate
    CHECK(fabs(mean) < 0.02);
    CHECK(sd > 0.005 && sd < 0.08);
    CHECK(maxdev <= 0.08 * 1.02 + 1e-3);     // |n| <= 1; the sensor's non-linearity bends it by < 2 %
    CHECK(pairs > 100000 && sxy / sxx > 0.9);   // smooth: neighbours agree
done:
    rig_virtual_close(v);
    free(E1);
    free(E0);
    test_camera_unlock(session);
}

// Fault injection from the truth file: the second move fails half way with a
// motion error (reported by the rig's turntable, whose wait polls the stage);
// after a disconnect the camera still delivers frames of the last angle.
TEST(virtual_turntable_faults)
{
    int session = test_camera_lock();
    CHECK(session >= 0);
    rig_virtual_options_t o = rig_virtual_defaults();
    o.time_scale = 0.01;
    o.busy_wait_s = 120;
    rig_virtual_t *v = NULL;
    rig_camera_t *c = NULL;
    int rc = rig_virtual_open(&v, truth_variant("position_noise_deg = 0.002",
                                                "position_noise_deg = 0.002\nfault_after_moves = 1\nfault = motion"), &o);
    CHECK_MSG(rc == 0, "open: %s", model_last_error());
    if (rc) goto done;
    rig_turntable_t *tt = rig_virtual_turntable(v);
    rig_turntable_status_t st;
    CHECK(rig_turntable_home(tt, 5) == 0);
    CHECK(rig_turntable_move_abs_deg(tt, 10, 5) == 0);
    CHECK(rig_turntable_move_abs_deg(tt, 30, 5) == RIG_ERR_MOTION);
    CHECK_CONTAINS(model_last_error(), "motion error");
    CHECK(rig_turntable_status(tt, &st) == 0);
    CHECK(st.motion_error && !st.moving);
    CHECK_NEAR(st.angle_deg, 20, 0.5);   // stopped half way
    // Stalls time out.
    rig_virtual_close(v);
    v = NULL;
    rc = rig_virtual_open(&v, truth_variant("position_noise_deg = 0.002",
                                            "position_noise_deg = 0.002\nfault_after_moves = 1\nfault = stall"), &o);
    CHECK_MSG(rc == 0, "open: %s", model_last_error());
    if (rc) goto done;
    tt = rig_virtual_turntable(v);
    CHECK(rig_turntable_home(tt, 5) == 0);
    CHECK(rig_turntable_move_abs_deg(tt, 10, 5) == 0);
    CHECK(rig_turntable_move_abs_deg(tt, 30, 0.5) == RIG_ERR_TIMEOUT);
    CHECK_CONTAINS(model_last_error(), "did not finish");
    CHECK(rig_turntable_stop(tt, true) == 0);
    // Disconnect: the stage's calls fail, the camera goes on at the last angle.
    rig_virtual_close(v);
    v = NULL;
    rc = rig_virtual_open(&v, truth_variant("position_noise_deg = 0.002",
                                            "position_noise_deg = 0.002\nfault_after_moves = 1\nfault = disconnect"),
                          &o);
    CHECK_MSG(rc == 0, "open: %s", model_last_error());
    if (rc) goto done;
    tt = rig_virtual_turntable(v);
    CHECK(rig_turntable_home(tt, 5) == 0);
    CHECK(rig_turntable_move_abs_deg(tt, 10, 5) == 0);
    CHECK(rig_turntable_move_abs_deg(tt, 30, 5) == RIG_ERR_DISCONNECTED);
    CHECK(rig_turntable_status(tt, &st) == RIG_ERR_DISCONNECTED);
    rc = rig_camera_open_aravis(&c, rig_virtual_camera_address(v));
    CHECK_MSG(rc == 0, "open camera: %s", model_last_error());
    if (rc) goto done;
    CHECK(rig_lamps_set(rig_virtual_lamps(v), 1) == 0);
    rig_frame_t f;
    rc = rig_camera_capture(c, 10, 2, &f);
    CHECK_MSG(rc == 0, "capture: %s", model_last_error());
    if (!rc) {
        double sum = 0;
        for (size_t i = 0; i < (size_t)W * H; i++) sum += f.pix[i];
        CHECK(sum / (W * H) > 64 / 16.0 + 2);   // Mono8 (the camera's default): lit, not dark
        rig_frame_free(&f);
    }
done:
    rig_camera_close(c);
    rig_virtual_close(v);
    test_camera_unlock(session);
}

// The sensor helpers the virtual rig uses: model_sensor_apply_patterns with
// the patterns of model_sensor_patterns is model_sensor_apply bit for bit, and
// model_sensor_mean is the noise-free response (known answer).
TEST(virtual_sensor_helpers)
{
    enum { SW = 64, SH = 48 };
    model_sensor_t s = model_sensor_default();
    s.dark_current_e_per_s = 20;
    s.exposure_us = 10000;
    float a[SW * SH], b[SW * SH], g[SW * SH], d[SW * SH];
    for (int i = 0; i < SW * SH; i++) a[i] = b[i] = 64 + 10 * (i % 300);
    model_sensor_patterns(&s, SW, SH, g, d);
    model_sensor_apply(&s, SW, SH, a);
    model_sensor_apply_patterns(&s, SW, SH, g, d, b);
    CHECK(memcmp(a, b, sizeof a) == 0);
    // Noise-free: flat patterns, no vignetting: e = (P - 64) / K + dark, DN = e (1 - c e / FW) K + 64.
    s.vignetting = 0;
    for (int i = 0; i < SW * SH; i++) a[i] = 64 + 10 * (i % 300);
    model_sensor_mean(&s, SW, SH, NULL, NULL, a);
    double worst = 0;
    for (int i = 0; i < SW * SH; i++) {
        double e = 10.0 * (i % 300) / 0.25 + 20 * 0.01;
        if (e > 16000) e = 16000;
        double dn = e * (1 - 0.02 * e / 16000) * 0.25 + 64;
        if (dn > 4095) dn = 4095;
        worst = fmax(worst, fabs(a[i] - dn));
    }
    CHECK(worst < 1e-3);
    // With patterns: DN = ((P - 64) / K * g + dark) ... + 64 + d, at a level far from saturation.
    for (int i = 0; i < SW * SH; i++) a[i] = 564;
    model_sensor_mean(&s, SW, SH, g, d, a);
    worst = 0;
    for (int i = 0; i < SW * SH; i++) {
        double e = 500 / 0.25 * g[i] + 0.2;
        double dn = e * (1 - 0.02 * e / 16000) * 0.25 + 64 + d[i];
        worst = fmax(worst, fabs(a[i] - dn));
    }
    CHECK(worst < 1e-3);
}
