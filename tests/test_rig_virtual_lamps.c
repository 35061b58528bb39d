// tests/test_rig_virtual_lamps.c — the virtual rig's lamps outside the
// fitters' model (rig/virtual/lamps.c): warm-up and drift follow
// the configured curve in successive frames, stray light adds its configured
// level with the lamps off and on, and without these sections a frame is
// exactly the documented sum (bit for bit).
//
// The frames are of the flat-field sample (kind = uniform_source: every lamp
// that is on adds its radiance at every pixel) with the sensor's
// non-linearity off, so a frame's mean above the dark frame is proportional to
// the light, and a lamp's factor is that mean over the same mean of a rig
// without the effect (same sensor, same fixed patterns).
#define _GNU_SOURCE
#include <glib.h>
#include <limits.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "model/model.h"
#include "model/base/vec.h"
#include "rig/rig.h"
#include "rig/virtual/internal.h"
#include "tests/fixtures.h"
#include "tests/test.h"

#define W 1280
#define H 1024
#define NPX ((size_t)W * H)

static double mono_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

// The example truth file with the flat field as the sample, a linear sensor,
// `from` replaced by `to` (both may be NULL) and `extra` appended; its
// relative paths made absolute.
static const char *truth_edit(const char *name, const char *extra, const char *from, const char *to)
{
    const char *rep[] = { "sample = t_stiffener", "sample = flat_field", "nonlinearity_pct = 2", "nonlinearity_pct = 0",
                          from, to, NULL };
    return fx_truth_variant("virtual-truth.ini", name, rep, extra);
}

static const char *truth_with(const char *name, const char *extra) { return truth_edit(name, extra, NULL, NULL); }

static rig_virtual_t *open_truth(const char *path, const char *serial)
{
    rig_virtual_options_t o = rig_virtual_defaults();
    o.serve = RIG_VIRTUAL_SERVE_INPROCESS;
    o.serial = serial;
    o.time_scale = 0.001;   // a simulated second is a real millisecond
    o.noise_seed = 5;
    o.prerender = 0;
    rig_virtual_t *v = NULL;
    int rc = rig_virtual_open(&v, path, &o);
    CHECK_MSG(rc == 0, "rig_virtual_open %s: %d %s", path, rc, model_last_error());
    return v;
}

static double mean_f(const float *a)
{
    double s = 0;
    for (size_t i = 0; i < NPX; i++) s += a[i];
    return s / (double)NPX;
}

static double mean_u16(const uint16_t *a)
{
    double s = 0;
    for (size_t i = 0; i < NPX; i++) s += a[i];
    return s / (double)NPX;
}

// The curve itself: f(t) = (1 - a exp(-t/tau)) (1 + d/100 t/3600), exactly 1 without a section.
TEST(virtual_lamps_curve_known_values)
{
    const char *text = "[lamp a]\nposition_mm = 0 0 500\nintensity = 1\n[lamp b]\nposition_mm = 0 0 500\n"
                       "intensity = 1\n[lamp_drift b]\nwarmup_fraction = 0.04\nwarmup_tau_s = 120\n"
                       "drift_pct_per_h = -0.5\n[stray]\nveiling_glare = 0.01\n";
    rig_truth_t *t = rig_truth_parse(text, strlen(text), "t.ini");
    model_lamps_t *l = t ? rig_truth_lamps(t) : NULL;
    CHECK(l && l->n == 2);
    rig_vlamps_t fx;
    if (!l || !rig_vtruth_lamp_effects(t, l, &fx)) {
        CHECK_MSG(false, "parse: %s", model_last_error());
        goto done;
    }
    CHECK(fx.timed);
    CHECK(rig_vlamps_curve(&fx, 0, 1e4) == 1.0);
    CHECK_NEAR(rig_vlamps_curve(&fx, 1, 0), 0.96, 1e-15);
    CHECK_NEAR(rig_vlamps_curve(&fx, 1, 120), (1 - 0.04 / M_E) * (1 - 0.005 / 30), 1e-15);
    CHECK_NEAR(rig_vlamps_curve(&fx, 1, 7200), (1 - 0.04 * exp(-60)) * 0.99, 1e-15);
    // an LED's sag: brighter at switch-on
    fx.warmup_fraction[0] = -0.05;
    fx.warmup_tau_s[0] = 300;
    CHECK_NEAR(rig_vlamps_curve(&fx, 0, 0), 1.05, 1e-15);
    CHECK_NEAR(rig_vlamps_curve(&fx, 0, 600), 1 + 0.05 * exp(-2), 1e-15);
    // glare: g times the mean of the lamps' planes, each by its factor; kc scales it
    float out[4] = { 1, 2, 3, 4 }, p0[4] = { 0, 0, 0, 40 }, p1[4] = { 10, 10, 10, 10 };
    const float *pl[2] = { p0, p1 };
    double f[2] = { 1.0, 0.5 };
    rig_vlamps_add_stray(&fx, out, 4, 2.0, pl, f, 2);
    double add = 2.0 * 0.01 * (10 + 0.5 * 10);
    for (int i = 0; i < 4; i++) CHECK_NEAR(out[i], i + 1 + add, 1e-6);
done:
    model_lamps_free(l);
    rig_truth_free(t);
}

// Errors name the file and line.
TEST(virtual_lamps_truth_errors)
{
    struct { const char *extra, *msg; } bad[] = {
        { "[lamp_drift nowhere]\nwarmup_fraction = 0.1\nwarmup_tau_s = 10\n", "names no [lamp nowhere]" },
        { "[lamp_drift east]\nwarmup_fraction = 0.1\n", "needs both" },
        { "[lamp_drift east]\nwarmup_fraction = 0.7\nwarmup_tau_s = 1\n", "out of range" },
        { "[lamp_drift east]\ncolour = red\n", "unknown key 'colour'" },
        { "[stray]\nveiling_glare = 0.5\n", "out of range" },
        { "[lamp_drift]\ndrift_pct_per_h = 1\n", "needs a name" },
    };
    for (size_t k = 0; k < sizeof bad / sizeof bad[0]; k++) {
        const char *path = truth_with("bad.ini", bad[k].extra);
        rig_virtual_t *v = NULL;
        rig_virtual_options_t o = rig_virtual_defaults();
        o.serve = RIG_VIRTUAL_SERVE_INPROCESS;
        o.serial = "REFL-LAMPS-BAD";
        CHECK(rig_virtual_open(&v, path, &o) == RIG_ERR_INVALID);
        CHECK_CONTAINS(model_last_error(), path);
        CHECK_CONTAINS(model_last_error(), bad[k].msg);
        rig_virtual_close(v);
    }
}

// Without the new sections a frame is exactly Pa + kc L_1 + kc L_2 in float,
// lamp by lamp (the arithmetic of a rig without drift or stray light), through the sensor's mean.
TEST(virtual_lamps_defaults_bit_exact)
{
    rig_virtual_t *v = open_truth(truth_with("plain.ini", ""), "REFL-LAMPS-A");
    float *E = malloc(NPX * sizeof(float)), *P = malloc(NPX * sizeof(float)), *L = malloc(NPX * sizeof(float));
    if (!v || !E || !P || !L) goto done;
    double kc = rig_virtual_kc_per_us(v) * 7000;
    model_sensor_t s = rig_virtual_sensor_params(v);
    for (size_t i = 0; i < NPX; i++) P[i] = (float)s.dark_offset_dn;
    for (int lamp = 0; lamp < 2; lamp++) {
        CHECK(rig_virtual_radiance(v, 0, lamp, L) == 0);
        for (size_t i = 0; i < NPX; i++) P[i] += (float)(kc * L[i]);
    }
    CHECK(rig_virtual_expected(v, 0, 3, 7000, 0, "Mono16", W, H, E) == 0);
    // the expected frame is the sensor's mean of P (Mono16: the 12 bits << 4), with
    // the fixed patterns of the truth's sensor (model_sensor_patterns, seeded)
    float *g = malloc(NPX * sizeof(float)), *d = malloc(NPX * sizeof(float));
    if (!g || !d) {
        free(g);
        free(d);
        goto done;
    }
    model_sensor_patterns(&s, W, H, g, d);
    s.exposure_us = 7000;
    model_sensor_mean(&s, W, H, g, d, P);
    free(g);
    free(d);
    size_t diff = 0;
    for (size_t i = 0; i < NPX; i++) diff += E[i] != (float)ldexp(P[i], 4);
    CHECK_MSG(diff == 0, "%zu pixels differ from the documented sum", diff);
done:
    rig_virtual_close(v);
    free(E);
    free(P);
    free(L);
}

// The known curve of the truth below (time_scale 0.001: a real ms is a simulated s).
static double drift_curve(double t_s) { return (1 - 0.05 * exp(-t_s / 300)) * (1 + 0.06 * t_s / 3600); }

// Warm-up and drift in successive frames of a session through the camera:
// each frame's factor (its mean above the dark frame over that of a rig
// without drift) lies on the configured curve between the earliest and the
// latest time the frame can have (switch-on and trigger bracketed by the
// clock), and the frames climb from the warm-up deficit.
TEST(virtual_lamps_warmup_and_drift_in_frames)
{
    rig_virtual_t *ref = open_truth(truth_with("plain.ini", ""), "REFL-LAMPS-R");
    rig_virtual_t *v = open_truth(truth_with("drift.ini", "[lamp_drift east]\nwarmup_fraction = 0.05\n"
                                             "warmup_tau_s = 300\ndrift_pct_per_h = 6\n"), "REFL-LAMPS-D");
    float *E = malloc(NPX * sizeof(float));
    rig_camera_t *c = NULL;
    rig_frame_t f = { 0 };
    if (!ref || !v || !E) goto done;
    CHECK(rig_virtual_expected(ref, 0, 0, 10000, 0, "Mono12", W, H, E) == 0);
    double dark = mean_f(E);
    CHECK(rig_virtual_expected(ref, 0, 1, 10000, 0, "Mono12", W, H, E) == 0);
    double den = mean_f(E) - dark;
    CHECK(den > 500);
    int rc = rig_camera_open_aravis(&c, rig_virtual_camera_address(v));
    CHECK_MSG(rc == 0, "open: %d %s", rc, model_last_error());
    if (rc) goto done;
    CHECK(rig_camera_set_pixel_format(c, "Mono12") == 0);
    CHECK(rig_camera_set_exposure_us(c, 10000) == 0);
    CHECK(rig_camera_set_gain(c, 0) == 0);
    double tA = mono_s();
    CHECK(rig_lamps_set(rig_virtual_lamps(v), 1) == 0);   // east
    double tB = mono_s();
    double first = NAN, last = NAN;
    for (int k = 0; k < 8; k++) {
        double t1 = mono_s();
        rc = rig_camera_capture(c, 10.0, 0, &f);
        double t2 = mono_s();
        CHECK_MSG(rc == 0, "capture: %d %s", rc, model_last_error());
        if (rc) goto done;
        double got = (mean_u16(f.pix) - dark) / den;
        double lo = drift_curve((t1 - tB) / 0.001), hi = drift_curve((t2 - tA) / 0.001);
        printf("  frame %d: t_on %.0f..%.0f s, factor %.5f (curve %.5f..%.5f)\n", k, (t1 - tB) / 0.001,
               (t2 - tA) / 0.001, got, lo, hi);
        CHECK_MSG(got > lo - 1e-3 && got < hi + 1e-3, "frame %d: factor %.5f outside the curve's %.5f..%.5f", k,
                  got, lo, hi);
        if (k == 0) first = got;
        last = got;
        rig_frame_free(&f);
        g_usleep(120000);
    }
    CHECK_MSG(first < 0.99 && last - first > 0.03, "frames from %.4f to %.4f: no warm-up and drift seen", first, last);
    // the lamp off and on again: the warm-up starts over
    CHECK(rig_lamps_set(rig_virtual_lamps(v), 0) == 0);
    CHECK(rig_lamps_set(rig_virtual_lamps(v), 1) == 0);
    CHECK(rig_camera_capture(c, 10.0, 0, &f) == 0);
    if (f.pix) CHECK((mean_u16(f.pix) - dark) / den < last - 0.01);
done:
    rig_frame_free(&f);
    rig_camera_close(c);
    rig_virtual_close(v);
    rig_virtual_close(ref);
    free(E);
}

// Stray light: the room light's radiance at every pixel with the lamps off
// (none through a flat-field source covering the lens), plus the veiling
// glare (a fraction of the frame's mean lamp radiance) with
// them on; in expected frames and in a frame through the camera.
TEST(virtual_lamps_stray_light_levels)
{
    rig_virtual_t *ref = open_truth(truth_with("plain.ini", ""), "REFL-LAMPS-R2");
    rig_virtual_t *v = open_truth(truth_with("stray.ini", "[stray]\nambient_radiance = 50\nveiling_glare = 0.02\n"),
                                  "REFL-LAMPS-S");
    float *E = malloc(NPX * sizeof(float));
    rig_camera_t *c = NULL;
    rig_frame_t f = { 0 };
    if (!ref || !v || !E) goto done;
    CHECK(rig_virtual_expected(ref, 0, 0, 10000, 0, "Mono12", W, H, E) == 0);
    double dark = mean_f(E);
    CHECK(rig_virtual_expected(ref, 0, 1, 10000, 0, "Mono12", W, H, E) == 0);
    double den = mean_f(E) - dark;   // one lamp's 1000 radiance units
    // the flat-field source covers the lens: no room light, the glare alone:
    // lamps off 0; one lamp (1000 + 0.02 * 1000) / 1000; two (2000 + 40) / 1000
    const uint32_t masks[3] = { 0, 1, 3 };
    const double want[3] = { 0, 1.02, 2.04 };
    for (int k = 0; k < 3; k++) {
        CHECK(rig_virtual_expected(v, 0, masks[k], 10000, 0, "Mono12", W, H, E) == 0);
        CHECK_NEAR((mean_f(E) - dark) / den, want[k], 2e-4);
    }
    // another sample on the table, lamps off: the room light, 50 / 1000 of a lamp here
    CHECK(rig_virtual_set_sample(ref, "reference_white") == 0 && rig_virtual_set_sample(v, "reference_white") == 0);
    CHECK(rig_virtual_expected(ref, 0, 0, 10000, 0, "Mono12", W, H, E) == 0);
    double dark_white = mean_f(E);
    CHECK(rig_virtual_expected(v, 0, 0, 10000, 0, "Mono12", W, H, E) == 0);
    CHECK_NEAR((mean_f(E) - dark_white) / den, 0.05, 2e-4);
    CHECK(rig_virtual_set_sample(v, "flat_field") == 0);
    int rc = rig_camera_open_aravis(&c, rig_virtual_camera_address(v));
    CHECK_MSG(rc == 0, "open: %d %s", rc, model_last_error());
    if (rc) goto done;
    CHECK(rig_camera_set_pixel_format(c, "Mono12") == 0);
    CHECK(rig_camera_set_exposure_us(c, 10000) == 0);
    CHECK(rig_camera_set_gain(c, 0) == 0);
    CHECK(rig_camera_capture(c, 10.0, 0, &f) == 0);   // lamps off
    if (f.pix) CHECK_NEAR((mean_u16(f.pix) - dark) / den, 0, 1e-3);
    rig_frame_free(&f);
    CHECK(rig_lamps_set(rig_virtual_lamps(v), 1) == 0);
    CHECK(rig_camera_capture(c, 10.0, 0, &f) == 0);
    if (f.pix) CHECK_NEAR((mean_u16(f.pix) - dark) / den, 1.02, 1e-3);
done:
    rig_frame_free(&f);
    rig_camera_close(c);
    rig_virtual_close(v);
    rig_virtual_close(ref);
    free(E);
}

// The emission pattern of a truth lamp reaches the virtual rig's frames: the
// reference white under lamp east with emission_cos_power = 4.8 (an LED with a
// 60 deg optic) about a tilted axis, over the same lamp isotropic, is
// (a . u)^n at points of the white's top face (z = 5 mm), u from the lamp to
// the point (the same random draws: the renders differ by that factor only).
TEST(virtual_lamps_emission_pattern_in_frames)
{
    const char *east = "[lamp east]\nposition_mm = 488.6 177.9 600\n";
    rig_virtual_t *ref = open_truth(truth_with("plain.ini", ""), "REFL-LAMPS-R3");
    rig_virtual_t *v = open_truth(truth_edit("pattern.ini", "", east,
                                             "[lamp east]\nposition_mm = 488.6 177.9 600\nemission_cos_power = 4.8\n"
                                             "emission_axis = -488.6 -177.9 -500\n"),
                                  "REFL-LAMPS-P");
    float *A = malloc(NPX * sizeof(float)), *B = malloc(NPX * sizeof(float));
    if (!ref || !v || !A || !B) goto done;
    CHECK(rig_virtual_set_sample(ref, "reference_white") == 0);
    CHECK(rig_virtual_set_sample(v, "reference_white") == 0);
    CHECK(rig_virtual_radiance(ref, 0, 0, A) == 0);
    CHECK(rig_virtual_radiance(v, 0, 0, B) == 0);
    model_vec3_t L = v3(488.6, 177.9, 600), a = v3_unit(v3(-488.6, -177.9, -500));
    model_vec3_t pts[3] = { v3(0, 0, 5), v3(50, 40, 5), v3(-50, -40, 5) };
    double q[6];
    CHECK(model_camera_project(rig_virtual_camera_model(v), pts, 3, q));
    double lo = 2, hi = 0;
    for (int k = 0; k < 3; k++) {
        int x = (int)lround(q[2 * k]), y = (int)lround(q[2 * k + 1]);
        CHECK(x > 2 && x < W - 3 && y > 2 && y < H - 3);
        if (!(x > 2 && x < W - 3 && y > 2 && y < H - 3)) continue;
        double sa = 0, sb = 0;
        for (int dy = -2; dy <= 2; dy++)
            for (int dx = -2; dx <= 2; dx++) {
                sa += A[(size_t)(y + dy) * W + x + dx];
                sb += B[(size_t)(y + dy) * W + x + dx];
            }
        double want = pow(v3_dot(a, v3_unit(v3_sub(pts[k], L))), 4.8);
        printf("  point %d (%.0f, %.0f): ratio %.5f, (a.u)^n %.5f\n", k, pts[k].x, pts[k].y, sb / sa, want);
        CHECK_REL(sb / sa, want, 2e-3);
        lo = fmin(lo, want);
        hi = fmax(hi, want);
    }
    CHECK_MSG(hi - lo > 0.03, "the points' factors %.4f..%.4f do not show the pattern", lo, hi);
done:
    rig_virtual_close(v);
    rig_virtual_close(ref);
    free(A);
    free(B);
}
