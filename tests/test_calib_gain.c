// tests/test_calib_gain.c — `refl calib gain` (EMVA 1288 style sensitivity).
//
// calib_gain_virtual: the whole calibration on the in-process virtual rig
// (examples/virtual-truth.ini, pattern seed 1, noise seeds from 1) at 0 and
// 6 dB on the full 1280x1024 sensor: K within 2 %, read noise within 5 %, dark
// current, DSNU and PRNU figures, the PRNU/DSNU maps correlated > 0.9 with the
// sensor model's own patterns, kc per us against the truth, and the
// linearity error against the noise-free expected frames of the truth (the
// same analysis) and of the same truth made linear (nonlinearity_pct = 0).
// calib_gain_manifest: frames made here by the sensor model (128x96 pixels),
// listed in a manifest (--frames). calib_gain_bad_input: missing and corrupt
// frames, too few steps, saturated and too dark flats. calib_gain_numerics:
// the fits on noise-free data with known answers.
#define _GNU_SOURCE
#include <glib.h>
#include <jansson.h>
#include <limits.h>
#include <stdlib.h>
#include <unistd.h>

#include "calib/calib.h"
#include "calib/gain/gain.h"
#include "model/model.h"
#include "model/base/report.h"
#include "model/base/vec.h"
#include "rig/rig.h"
#include "rig/virtual/truth.h"
#include "tests/test.h"

static const char *truth_path(void)
{
    static char p[PATH_MAX + 64];
    char top[PATH_MAX];
    if (!realpath(test_srcdir(), top)) snprintf(top, sizeof top, "%s", test_srcdir());
    snprintf(p, sizeof p, "%s/examples/virtual-truth.ini", top);
    return p;
}

static bool truth_sensor(model_sensor_t *s)
{
    model_ini_t *ini = model_ini_load(truth_path());
    bool ok = ini && model_sensor_from_ini(ini, s);
    model_ini_free(ini);
    return ok;
}

static double jnum(json_t *o, const char *key)
{
    json_t *v = json_object_get(o, key);
    return json_is_number(v) ? json_number_value(v) : NAN;
}

static double *jvec(json_t *o, const char *key, int *n)
{
    json_t *a = json_object_get(o, key);
    *n = (int)json_array_size(a);
    double *v = malloc(sizeof(double) * (*n + 1));
    for (int i = 0; i < *n; i++) {
        json_t *x = json_array_get(a, i);
        v[i] = json_is_number(x) ? json_number_value(x) : NAN;
    }
    return v;
}

static float *read_tiff(const char *dir, const char *name, int *w, int *h)
{
    char *p = g_build_filename(dir, name, NULL);
    float *m = NULL;
    if (!model_tiff_read_float(p, w, h, &m)) m = NULL;
    g_free(p);
    return m;
}

// Mean of the expected (noise-free) frame: lamps mask, minus the expected dark.
static double expected_signal(rig_virtual_t *v, uint32_t mask, double t_us, double gain_db, float *buf, int w, int h)
{
    double s[2] = { 0, 0 };
    for (int k = 0; k < 2; k++) {
        int rc = rig_virtual_expected(v, 0, k ? 0 : mask, t_us, gain_db, "Mono12", w, h, buf);
        CHECK_MSG(rc == 0, "rig_virtual_expected: %s", model_last_error());
        for (long i = 0; i < (long)w * h; i++) s[k] += buf[i];
    }
    return (s[0] - s[1]) / ((double)w * h);
}

static rig_virtual_t *open_truth(const char *path)
{
    rig_virtual_options_t o = rig_virtual_defaults();
    o.serve = RIG_VIRTUAL_SERVE_INPROCESS;
    o.time_scale = 0.001;
    o.sample = "flat_field";
    rig_virtual_t *v = NULL;
    int rc = rig_virtual_open(&v, path, &o);
    CHECK_MSG(rc == 0, "rig_virtual_open %s: %d %s", path, rc, model_last_error());
    return v;
}

// The truth file with nonlinearity_pct = 0 (and the camera model's path absolute).
static const char *linear_truth(void)
{
    char *text = model_read_file(truth_path(), NULL);
    if (!text) return NULL;
    char *dir = g_path_get_dirname(truth_path());
    char *abs_model = g_strdup_printf("model = %s/camera.cameramodel", dir);
    GString *g = g_string_new("");
    for (char *l = text, *next; l; l = next) {
        next = strchr(l, '\n');
        if (next) *next++ = 0;
        if (!strncmp(l, "model = camera.cameramodel", 26)) g_string_append(g, abs_model);
        else if (!strncmp(l, "scene = ", 8)) g_string_append_printf(g, "scene = %s/%s", dir, l + 8);
        else if (!strncmp(l, "nonlinearity_pct", 16)) g_string_append(g, "nonlinearity_pct = 0");
        else g_string_append(g, l);
        g_string_append_c(g, '\n');
    }
    const char *p = test_write("linear-truth.ini", g->str);
    g_string_free(g, TRUE);
    g_free(abs_model);
    g_free(dir);
    free(text);
    return p;
}

TEST_LONG(calib_gain_virtual)
{
    char top[PATH_MAX], rig[3 * PATH_MAX];
    if (!realpath(test_srcdir(), top)) snprintf(top, sizeof top, "%s", test_srcdir());
    snprintf(rig, sizeof rig, "[rig]\nbackend = virtual\ntruth = %s\nserve = inprocess\ntime_scale = 0.01\n"
             "pixel_format = Mono12\n", truth_path());
    const char *rig_path = test_write("rig.ini", rig);
    const char *out = test_path("gain");
    char *so = NULL, *se = NULL;
    double t0 = model_now_s();
    int rc = test_refl_run(300, &so, &se, "calib", "gain", "--yes", "--rig", rig_path, "-o", out, "--gains", "0,6",
                           "--radiance", "5000", NULL);   // the truth's 5 lamps x radiance 1000
    fprintf(stderr, "  calib gain --rig: %.1f s\n", model_now_s() - t0);
    CHECK_MSG(rc == 0, "refl calib gain: %d\n%s", rc, se ? se : "");
    free(so);
    free(se);
    if (rc) return;
    char *jp = g_build_filename(out, "gain.json", NULL);
    json_t *j = json_load_file(jp, 0, NULL);
    g_free(jp);
    CHECK(j != NULL);
    if (!j) return;
    model_sensor_t s;
    CHECK(truth_sensor(&s));
    fprintf(stderr, "  K %.5f DN/e- (6 dB: %.5f), read noise %.4f e-, dark current %.3f e-/s, DSNU %.4f DN, PRNU %.4f %%, "
            "saturation %.1f DN, LE %.3f %%, kc %.5g per us\n", jnum(j, "system_gain_dn_per_e"),
            jnum(json_array_get(json_object_get(j, "gains"), 1), "system_gain_dn_per_e"), jnum(j, "read_noise_e"),
            jnum(j, "dark_current_e_per_s"), jnum(j, "dsnu_dn"), jnum(j, "prnu_pct"), jnum(j, "saturation_dn"),
            jnum(j, "linearity_error_pct"), jnum(j, "kc_per_us"));
    // photon transfer at 0 dB and 6 dB
    CHECK_REL(jnum(j, "system_gain_dn_per_e"), s.system_gain_dn_per_e, 0.02);
    CHECK_REL(jnum(j, "read_noise_e"), s.read_noise_e, 0.05);
    json_t *g6 = json_array_get(json_object_get(j, "gains"), 1);
    CHECK_NEAR(jnum(g6, "gain_db"), 6, 1e-9);
    CHECK_REL(jnum(g6, "system_gain_dn_per_e"), s.system_gain_dn_per_e * pow(10, 6 / 20.0), 0.02);
    CHECK_REL(jnum(g6, "read_noise_e"), s.read_noise_e, 0.05);
    // saturation: the well (full_well_e, compressed by the non-linearity) at 0 dB, at most
    double sat_truth = s.full_well_e * (1 - s.nonlinearity_pct / 100) * s.system_gain_dn_per_e;
    CHECK(jnum(j, "saturation_dn") > 0.85 * sat_truth && jnum(j, "saturation_dn") <= sat_truth * 1.01);
    // 6 dB: the 12-bit range clips first
    CHECK(jnum(g6, "saturation_dn") > 0.85 * (4095 - s.dark_offset_dn) &&
          jnum(g6, "saturation_dn") <= 4095 - s.dark_offset_dn);
    CHECK_REL(jnum(j, "dark_current_e_per_s"), s.dark_current_e_per_s, 0.10);
    CHECK_REL(jnum(j, "dsnu_dn"), s.dsnu_dn, 0.05);
    CHECK_REL(jnum(j, "prnu_pct"), s.prnu_pct, 0.10);
    CHECK(jnum(j, "prnu_total_pct") > 1.5 * jnum(j, "prnu_pct"));   // vignetting in the total
    // every figure's stated 1-sigma (gain.json std), and each within 4 of them of the truth
    static const char *const fig[] = { "system_gain_dn_per_e", "read_noise_e", "dark_current_e_per_s", "dsnu_dn",
                                       "prnu_pct" };
    const double tru[] = { s.system_gain_dn_per_e, s.read_noise_e, s.dark_current_e_per_s, s.dsnu_dn, s.prnu_pct };
    for (int k = 0; k < 5; k++) {
        double sd = jnum(json_object_get(j, "std"), fig[k]), z = (jnum(j, fig[k]) - tru[k]) / sd;
        fprintf(stderr, "  %s: 1-sigma %.3g, z %+.2f\n", fig[k], sd, z);
        CHECK_MSG(sd > 0 && fabs(z) < 4, "%s: sigma %g, z %g", fig[k], sd, z);
    }
    CHECK_REL(jnum(j, "dark_level_dn"), s.dark_offset_dn, 0.01);
    CHECK(jnum(j, "snr_max") > 100 && jnum(j, "snr_max") < sqrt(s.full_well_e) * 1.05);

    // maps against the sensor model's patterns (same pattern seed)
    int w = 0, h = 0, w2 = 0, h2 = 0, w3 = 0, h3 = 0;
    float *hp = read_tiff(out, "prnu_highpass.tiff", &w, &h);
    float *tot = read_tiff(out, "prnu_gain.tiff", &w2, &h2);
    float *dsnu = read_tiff(out, "dsnu_dn.tiff", &w3, &h3);
    CHECK(hp && tot && dsnu && w == 1280 && h == 1024 && w2 == w && h2 == h && w3 == w && h3 == h);
    if (hp && tot && dsnu && w == 1280 && h == 1024 && w2 == w && h2 == h && w3 == w && h3 == h) {
        size_t n = (size_t)w * h;
        float *tp = malloc(n * sizeof(float)), *td = malloc(n * sizeof(float));
        model_sensor_patterns(&s, w, h, tp, td);
        double r_hp = calib_gain_correlation(hp, tp, (long)n);
        double r_d = calib_gain_correlation(dsnu, td, (long)n);
        // the total map against prnu x vignetting (model/sensor.c)
        double cx = 0.5 * (w - 1), cy = 0.5 * (h - 1), rc2 = cx * cx + cy * cy, mean = 0;
        for (int y = 0; y < h; y++)
            for (int x = 0; x < w; x++) {
                size_t i = (size_t)y * w + x;
                tp[i] *= (float)(1 - s.vignetting * ((x - cx) * (x - cx) + (y - cy) * (y - cy)) / rc2);
            }
        double r_tot = calib_gain_correlation(tot, tp, (long)n);
        for (size_t i = 0; i < n; i++) mean += tot[i];
        fprintf(stderr, "  correlation: PRNU high-pass %.4f, total map %.4f, DSNU %.4f\n", r_hp, r_tot, r_d);
        CHECK(r_hp > 0.9);
        CHECK(r_tot > 0.9);
        CHECK(r_d > 0.9);
        CHECK_NEAR(mean / n, 1.0, 1e-4);
        // small-signal kc per us: kc_per_us of the truth times the mean of prnu x vignetting (g has mean 1)
        double mg = 0;
        for (size_t i = 0; i < n; i++) mg += tp[i];
        mg /= n;
        double kc_truth;
        {
            model_ini_t *ini = model_ini_load(truth_path());
            const model_ini_entry_t *e = ini ? model_ini_get(ini, "camera", "kc_per_us") : NULL;
            kc_truth = e ? atof(e->value) : NAN;
            model_ini_free(ini);
        }
        fprintf(stderr, "  kc small-signal %.6g per us, truth %.6g x mean(g) %.5f = %.6g\n",
                jnum(j, "kc_small_signal_per_us"), kc_truth, mg, kc_truth * mg);
        CHECK_REL(jnum(j, "kc_small_signal_per_us"), kc_truth * mg, 0.01);
        free(tp);
        free(td);
    }
    free(hp);
    free(tot);
    free(dsnu);

    // linearity: the same analysis on the noise-free truth curves (non-linear and linear)
    json_t *g0 = json_array_get(json_object_get(j, "gains"), 0);
    int n = 0, n2 = 0;
    double *t = jvec(json_object_get(g0, "curves"), "exposure_us", &n);
    double *mu = jvec(json_object_get(g0, "curves"), "signal_dn", &n2);
    CHECK(n >= 50 && n2 == n);
    double sat = jnum(j, "saturation_dn"), le = jnum(j, "linearity_error_pct");
    if (n >= 50) {
        float *buf = malloc(sizeof(float) * 1280 * 1024);
        double *mt = malloc(sizeof(double) * n), *ml = malloc(sizeof(double) * n);
        // one in-process camera per process at a time: the truth, then its linear twin
        rig_virtual_t *v = open_truth(truth_path());
        for (int i = 0; v && i < n; i++) mt[i] = expected_signal(v, 0x1F, t[i], 0, buf, 1280, 1024);
        rig_virtual_close(v);
        const char *lt = linear_truth();
        rig_virtual_t *vl = lt ? open_truth(lt) : NULL;
        for (int i = 0; vl && i < n; i++) ml[i] = expected_signal(vl, 0x1F, t[i], 0, buf, 1280, 1024);
        rig_virtual_close(vl);
        if (v && vl) {
            // the measured signal follows the truth curve
            double maxdev = 0;
            for (int i = 0; i < n; i++)
                if (mt[i] < sat) maxdev = fmax(maxdev, fabs(mu[i] - mt[i]) / mt[i]);
            fprintf(stderr, "  measured signal vs the expected frames: max deviation %.3f %%\n", 100 * maxdev);
            CHECK(maxdev < 0.005);
            double kc_slope = 0;
            double le_t = calib_gain_linearity_r4(t, mt, n, sat, 0.05, 0.95, &kc_slope, NULL, NULL, NULL);
            double le_l = calib_gain_linearity_r4(t, ml, n, sat, 0.05, 0.95, NULL, NULL, NULL, NULL);
            double le3 = jnum(j, "linearity_error_r3_pct");
            double le_t3 = calib_gain_linearity(t, mt, n, sat, 0.05, 0.95, NULL, NULL, NULL, NULL);
            fprintf(stderr, "  linearity error: measured %.3f %%, truth curve %.3f %%, linear truth %.3f %%\n", le,
                    le_t, le_l);
            CHECK(le_t > 3 * le_l);
            CHECK(le > 3 * le_l);
            CHECK_NEAR(le, le_t, 0.15 * le_t);
            CHECK_NEAR(le3, le_t3, 0.15 * le_t3);   // Release 3's figure, kept beside it
            // the monotone table recovers the truth's linear twin (its frames without the
            // compression) over 5..95 % of saturation, up to one scale
            model_lin_t L;
            CHECK(calib_gain_lin_from_json(j, "gain.json", &L) && L.kind == MODEL_LIN_MONOTONE);
            double rmin = INFINITY, rmax = -INFINITY;
            for (int i = 0; i < n; i++)
                if (mt[i] >= 0.05 * sat && mt[i] <= 0.95 * sat) {
                    double r = model_linearise(&L, mt[i], 1, NULL) / ml[i];
                    rmin = fmin(rmin, r);
                    rmax = fmax(rmax, r);
                }
            fprintf(stderr, "  linearised / linear truth over 5..95 %%: %.5f .. %.5f\n", rmin, rmax);
            CHECK(rmax / rmin - 1 < 0.002);
            // kc: the response slope per unit radiance (the truth's 5 lamps x radiance 1000)
            CHECK_REL(jnum(j, "kc_per_us"), kc_slope / 5000.0, 0.01);
            CHECK_REL(jnum(j, "response_dn_per_us"), kc_slope, 0.01);
        }
        free(buf);
        free(mt);
        free(ml);
    }
    free(t);
    free(mu);
    // kc at 6 dB is 10^(6/20) times that at 0 dB
    CHECK_REL(jnum(g6, "kc_per_us") / jnum(g0, "kc_per_us"), pow(10, 6 / 20.0), 0.01);
    // the report
    char *rp = g_build_filename(out, "report.html", NULL);
    char *html = model_read_file(rp, NULL);
    CHECK(html != NULL);
    if (html) {
        CHECK_CONTAINS(html, "ptc.png");
        CHECK_CONTAINS(html, "prnu_hist.png");
        // the headline first: the standard's K and refl's K0 with its 1-sigma; no photon axis here, said once
        CHECK(strstr(html, "id=\"headline\"") && strstr(html, "<h2>Summary") &&
              strstr(html, "id=\"headline\"") < strstr(html, "<h2>Summary"));
        CHECK_CONTAINS(html, "<li>EMVA 1288: K ");
        CHECK_CONTAINS(html, "<li>refl's small-signal K (what refl's measurements use) ");
    }
    free(html);
    g_free(rp);
    const char *pngs[] = { "ptc.png", "linearity.png", "snr.png", "prnu_map.png", "prnu_hist.png", "dark.png",
                           "kc.png", "offset_dn.tiff" };
    for (size_t i = 0; i < sizeof pngs / sizeof pngs[0]; i++) {
        char *p = g_build_filename(out, pngs[i], NULL);
        CHECK_MSG(g_file_test(p, G_FILE_TEST_EXISTS), "missing %s", p);
        g_free(p);
    }
    // provenance lists the sessions with their hashes
    json_t *in = json_object_get(json_object_get(j, "provenance"), "inputs");
    CHECK(json_array_size(in) >= 5);
    // --session: the 0 dB sweep session alone, analysed again (same frames: the same photon transfer;
    // its flat field is a frame pair near 50 %, so PRNU is noisier)
    char *sweep = g_build_filename(out, "sweep_g0", NULL);
    const char *out2 = test_path("gain-session");
    rc = test_refl_run(120, &so, &se, "calib", "gain", "--session", sweep, "-o", out2, "--no-report", "--radiance",
                       "5000", NULL);
    CHECK_MSG(rc == 0, "refl calib gain --session: %d\n%s", rc, se ? se : "");
    free(so);
    free(se);
    g_free(sweep);
    jp = g_build_filename(out2, "gain.json", NULL);
    json_t *js = json_load_file(jp, 0, NULL);
    g_free(jp);
    CHECK(js != NULL);
    if (js) {
        CHECK_REL(jnum(js, "system_gain_dn_per_e"), jnum(j, "system_gain_dn_per_e"), 1e-9);
        CHECK_REL(jnum(js, "read_noise_e"), jnum(j, "read_noise_e"), 0.01);
        CHECK_REL(jnum(js, "kc_per_us"), jnum(j, "kc_per_us"), 1e-9);
        CHECK_NEAR(jnum(json_object_get(js, "flat_field"), "light_frames"), 2, 0);
    }
    json_decref(js);
    json_decref(j);
}

// ---------------------------------------------------------------------------
// Frames made here by the sensor model, listed in a manifest.

typedef struct {
    int    nsteps;        // sweep exposures (light pair + dark pair each)
    double max_us;        // longest sweep exposure
    double flat_us;       // flat-field exposure (0: none)
    int    flat_n;
    int    corrupt_line;  // 0 none; else this manifest line's file is garbage
    int    missing_line;  // 0 none; else this line names a missing file
    int    w, h;          // frame size (0: 128 x 96)
} gen_t;

static const double rate_dn_per_us = 0.4;   // at the centre, before PRNU/vignetting

// Write frames and DIR/manifest.csv; returns the manifest path.
static const char *gen_manifest(const char *sub, const gen_t *g)
{
    model_sensor_t s;
    CHECK(truth_sensor(&s));
    const int GW = g->w > 0 ? g->w : 128, GH = g->h > 0 ? g->h : 96;
    char *dir = g_build_filename(test_tmpdir(), sub, NULL);
    g_mkdir_with_parents(dir, 0755);
    float *prnu = malloc(sizeof(float) * GW * GH), *dsnu = malloc(sizeof(float) * GW * GH);
    model_sensor_patterns(&s, GW, GH, prnu, dsnu);
    float *img = malloc(sizeof(float) * GW * GH);
    uint16_t *pix = malloc(sizeof(uint16_t) * GW * GH);
    GString *m = g_string_new("file,exposure_us,kind\n");
    int line = 1, k = 0;
    uint64_t seed = 1000;
    int nflat = g->flat_us > 0 ? g->flat_n : 0;
    for (int i = 0; i < g->nsteps + 1; i++) {
        bool flat = i == g->nsteps;
        if (flat && !nflat) break;
        double t = flat ? g->flat_us : g->max_us * (i + 1) / g->nsteps;
        int reps = flat ? nflat : 2;
        for (int dark = 0; dark < 2; dark++)
            for (int r = 0; r < reps; r++) {
                for (int p = 0; p < GW * GH; p++) img[p] = (float)(s.dark_offset_dn + (dark ? 0 : rate_dn_per_us * t));
                s.exposure_us = t;
                s.noise_seed = seed++;
                model_sensor_apply_patterns(&s, GW, GH, prnu, dsnu, img);
                for (int p = 0; p < GW * GH; p++) pix[p] = (uint16_t)img[p];
                char name[64];
                snprintf(name, sizeof name, "f%05d.png", k++);
                line++;
                char *path = g_build_filename(dir, name, NULL);
                if (line == g->corrupt_line) {
                    FILE *f = fopen(path, "wb");
                    if (f) {
                        fputs("\x89PNG\r\n\x1a\nthis is not a PNG", f);
                        fclose(f);
                    }
                } else if (line != g->missing_line)
                    CHECK(model_png16_write(path, GW, GH, pix, NULL));
                g_free(path);
                g_string_append_printf(m, "%s,%.0f,%s\n", name, t, dark ? "dark" : "light");
            }
    }
    char *mp = g_build_filename(dir, "manifest.csv", NULL);
    FILE *f = fopen(mp, "w");
    if (f) {
        fputs(m->str, f);
        fclose(f);
    }
    static char ret[4][1024];
    static int slot;
    char *r = ret[slot++ % 4];
    snprintf(r, 1024, "%s", mp);
    g_free(mp);
    g_string_free(m, TRUE);
    g_free(dir);
    free(prnu);
    free(dsnu);
    free(img);
    free(pix);
    return r;
}

// calib_gain_two_cameras: the calibration of both cameras of the in-process
// 2-camera virtual rig (examples/virtual-truth-2cam.ini: sensors [sensor] and
// [sensor right]) in one run: each camera's K within 2 % and read noise within
// 5 % of its own truth sensor, each into DIR/NAME/, DIR/gain.json the first
// camera's; gain.json records the gain's value and unit and the camera. Then
// --camera right on the captured sessions gives its figures again, and an
// unknown camera is an error naming the session's cameras.
TEST_LONG(calib_gain_two_cameras)
{
    char top[PATH_MAX], rig[3 * PATH_MAX];
    if (!realpath(test_srcdir(), top)) snprintf(top, sizeof top, "%s", test_srcdir());
    snprintf(rig, sizeof rig, "[rig]\nbackend = virtual\ntruth = %s/examples/virtual-truth-2cam.ini\n"
             "serve = inprocess\ntime_scale = 0.01\npixel_format = Mono12\n", top);
    const char *rig_path = test_write("rig-2cam.ini", rig);
    const char *out = test_path("gain2");
    char *so = NULL, *se = NULL;
    double t0 = model_now_s();
    int rc = test_refl_run(400, &so, &se, "calib", "gain", "--yes", "--rig", rig_path, "-o", out, "--no-report",
                           "--radiance", "5000", "--dark-exposures-us", "100000,1000000", "--low-steps", "0", NULL);
    fprintf(stderr, "  calib gain --rig (2 cameras): %.1f s\n", model_now_s() - t0);
    CHECK_MSG(rc == 0, "refl calib gain: %d\n%s", rc, se ? se : "");
    if (so) {
        CHECK_CONTAINS(so, "camera left ");
        CHECK_CONTAINS(so, "camera right ");
    }
    free(so);
    free(se);
    if (rc) return;
    // the truth sensors of both cameras
    char truth[PATH_MAX + 64];
    snprintf(truth, sizeof truth, "%s/examples/virtual-truth-2cam.ini", top);
    rig_virtual_t *v = open_truth(truth);
    if (!v) return;
    CHECK(rig_virtual_ncameras(v) == 2);
    model_sensor_t s[2] = { rig_virtual_sensor_params(v), rig_virtual_sensor_params(rig_virtual_camera_view(v, 1)) };
    rig_virtual_close(v);
    CHECK(fabs(s[0].system_gain_dn_per_e - s[1].system_gain_dn_per_e) > 0.04);   // the test tells them apart
    const char *names[2] = { "left", "right" };
    double K[2] = { NAN, NAN };
    for (int k = 0; k < 2; k++) {
        char *jp = g_strdup_printf("%s/%s/gain.json", out, names[k]);
        json_t *j = json_load_file(jp, 0, NULL);
        CHECK_MSG(j != NULL, "no %s", jp);
        g_free(jp);
        if (!j) continue;
        K[k] = jnum(j, "system_gain_dn_per_e");
        fprintf(stderr, "  camera %s: K %.5f DN/e- (truth %.5f), read noise %.4f e- (truth %.4f)\n", names[k], K[k],
                s[k].system_gain_dn_per_e, jnum(j, "read_noise_e"), s[k].read_noise_e);
        CHECK_REL(K[k], s[k].system_gain_dn_per_e, 0.02);
        CHECK_REL(jnum(j, "read_noise_e"), s[k].read_noise_e, 0.05);
        CHECK(!strcmp(json_string_value(json_object_get(j, "camera")) ?: "", names[k]));
        CHECK(!strcmp(json_string_value(json_object_get(j, "gain_unit")) ?: "", "dB"));
        CHECK_NEAR(jnum(j, "gain_db"), 0, 1e-12);
        int w = 0, h = 0;
        char *d = g_strdup_printf("%s/%s", out, names[k]);
        float *m = read_tiff(d, "offset_dn.tiff", &w, &h);
        CHECK(m && w == (k ? 1024 : 1280) && h == (k ? 768 : 1024));
        free(m);
        g_free(d);
        json_decref(j);
    }
    // the top level: the first camera's, as with one camera
    char *jp = g_strdup_printf("%s/gain.json", out);
    json_t *j = json_load_file(jp, 0, NULL);
    g_free(jp);
    CHECK(j && !strcmp(json_string_value(json_object_get(j, "camera")) ?: "", "left"));
    if (j) CHECK_NEAR(jnum(j, "system_gain_dn_per_e"), K[0], 1e-12);
    json_decref(j);
    // one camera of the captured sessions
    char *sw = g_strdup_printf("%s/sweep_g0", out), *fl = g_strdup_printf("%s/flat", out),
         *dk = g_strdup_printf("%s/dark", out);
    const char *out2 = test_path("gain2-right");
    rc = test_refl_run(200, &so, &se, "calib", "gain", "--session", sw, "--session", fl, "--session", dk, "--camera",
                       "right", "-o", out2, "--no-report", NULL);
    CHECK_MSG(rc == 0, "refl calib gain --camera right: %d\n%s", rc, se ? se : "");
    free(so);
    free(se);
    jp = g_strdup_printf("%s/gain.json", out2);
    j = json_load_file(jp, 0, NULL);
    g_free(jp);
    CHECK(j && !strcmp(json_string_value(json_object_get(j, "camera")) ?: "", "right"));
    if (j) {   // the same frames (their roles by lamps here: the long darks join the dark model)
        CHECK_REL(jnum(j, "system_gain_dn_per_e"), K[1], 0.005);
        CHECK_REL(jnum(j, "system_gain_dn_per_e"), s[1].system_gain_dn_per_e, 0.02);
    }
    json_decref(j);
    rc = test_refl_run(60, &so, &se, "calib", "gain", "--session", sw, "--camera", "middle", "-o",
                       test_path("gain2-none"), "--no-report", NULL);
    CHECK(rc == 1);
    if (se) {
        CHECK_CONTAINS(se, "no camera 'middle'");
        CHECK_CONTAINS(se, "left, right");
    }
    free(so);
    free(se);
    g_free(sw);
    g_free(fl);
    g_free(dk);
}

TEST(calib_gain_manifest)
{
    model_sensor_t s;
    CHECK(truth_sensor(&s));
    // saturation at ~16000 e- = 4000 DN / 0.4 DN/us = 10000 us; sweep to 12500 us.
    // 256x192 frames: at 128x96, K's spread over noise draws is about 3 %,
    // more than the 2 % checked here.
    gen_t g = { .nsteps = 50, .max_us = 12500, .flat_us = 5100, .flat_n = 16, .w = 256, .h = 192 };
    const char *m = gen_manifest("m1", &g);
    const char *out = test_path("out-manifest");
    char *so = NULL, *se = NULL;
    int rc = test_refl_run(120, &so, &se, "calib", "gain", "--frames", m, "-o", out, "--no-report", "--max-dn",
                           "4095", NULL);
    CHECK_MSG(rc == 0, "refl calib gain --frames: %d\n%s", rc, se ? se : "");
    CHECK_CONTAINS(so, "system_gain_dn_per_e");
    free(so);
    free(se);
    char *jp = g_build_filename(out, "gain.json", NULL);
    json_t *j = json_load_file(jp, 0, NULL);
    g_free(jp);
    CHECK(j != NULL);
    if (!j) return;
    CHECK_REL(jnum(j, "system_gain_dn_per_e"), s.system_gain_dn_per_e, 0.02);
    CHECK_REL(jnum(j, "read_noise_e"), s.read_noise_e, 0.05);
    CHECK_REL(jnum(j, "dsnu_dn"), s.dsnu_dn, 0.15);
    CHECK_REL(jnum(j, "prnu_pct"), s.prnu_pct, 0.25);
    CHECK(jnum(j, "linearity_error_pct") > 0.5);
    CHECK(json_is_null(json_object_get(j, "kc_per_us")));   // radiance unknown
    json_t *ff = json_object_get(j, "flat_field");
    CHECK_NEAR(jnum(ff, "exposure_us"), 5100, 1e-9);
    CHECK_NEAR(jnum(ff, "light_frames"), 16, 0);
    // every frame is an input with its hash
    CHECK(json_array_size(json_object_get(json_object_get(j, "provenance"), "inputs")) == (size_t)(1 + 50 * 4 + 32));
    // PRNU's 1-sigma: its statistical part and the linearisation's, in quadrature; the
    // latter recomputed here from gain.json's own table and a at the flat's level
    json_t *sd = json_object_get(j, "std"), *pp = json_object_get(sd, "prnu_pct_parts");
    double st = jnum(pp, "statistical"), sl = jnum(pp, "linearisation_slope");
    CHECK(st > 0 && sl >= 0);
    CHECK_NEAR(jnum(sd, "prnu_pct"), hypot(st, sl), 1e-12);
    json_t *lj = json_object_get(j, "linearisation"), *jm = json_object_get(lj, "measured_dn"),
           *js = json_object_get(lj, "linear_dn");
    int nk = (int)json_array_size(jm);
    CHECK(nk >= 2 && nk <= MODEL_LIN_MAX && json_array_size(js) == (size_t)nk);
    if (nk >= 2 && nk <= MODEL_LIN_MAX && json_array_size(js) == (size_t)nk) {
        double km[MODEL_LIN_MAX], ks[MODEL_LIN_MAX];
        for (int k = 0; k < nk; k++) {
            km[k] = json_number_value(json_array_get(jm, k));
            ks[k] = json_number_value(json_array_get(js, k));
        }
        model_lin_t tab, par = { .kind = MODEL_LIN_PARAMETRIC, .a_per_dn = jnum(lj, "a_per_dn") };
        CHECK(model_lin_knots(km, ks, nk, &tab));
        double L = jnum(ff, "level_dn"), dm, dp;
        double lm = model_linearise(&tab, L, 1, &dm), lp = model_linearise(&par, L, 1, &dp);
        double want = jnum(j, "prnu_pct") * fabs((dm * L / lm) / (dp * L / lp) - 1);
        fprintf(stderr, "  PRNU's 1-sigma: statistical %.3g %%, linearisation %.3g %% (recomputed %.3g %%)\n", st, sl,
                want);
        CHECK_NEAR(sl, want, 1e-6 * jnum(j, "prnu_pct"));
    }
    // the dark exposures the dark current was fitted over
    CHECK(json_array_size(json_object_get(j, "dark_exposures_us")) >= 2);
    json_decref(j);
    // the same frames with the radiance given: kc per us
    const char *out2 = test_path("out-manifest2");
    rc = test_refl_run(120, &so, &se, "calib", "gain", "--frames", m, "-o", out2, "--no-report", "--radiance", "4000",
                       "--max-dn", "4095", NULL);
    CHECK_MSG(rc == 0, "%s", se ? se : "");
    free(so);
    free(se);
    jp = g_build_filename(out2, "gain.json", NULL);
    j = json_load_file(jp, 0, NULL);
    g_free(jp);
    if (j) CHECK_REL(jnum(j, "kc_per_us") * 4000, jnum(j, "response_dn_per_us"), 1e-9);
    json_decref(j);
}

static int expect_fail(char **err, ...) __attribute__((sentinel));
static int expect_fail(char **err, ...)
{
    const char *argv[32];
    int n = 0;
    argv[n++] = test_refl();
    va_list ap;
    va_start(ap, err);
    for (const char *a; n < 30 && (a = va_arg(ap, const char *));) argv[n++] = a;
    va_end(ap);
    argv[n] = NULL;
    char *so = NULL;
    int rc = test_run(argv, 120, &so, err);
    free(so);
    return rc;
}

TEST(calib_gain_bad_input)
{
    char *err = NULL, line[64];
    // a missing frame: the manifest line
    gen_t g = { .nsteps = 50, .max_us = 12500, .flat_us = 5100, .flat_n = 4, .missing_line = 7, .w = 48, .h = 32 };
    const char *m = gen_manifest("missing", &g);
    CHECK(expect_fail(&err, "calib", "gain", "--frames", m, "-o", test_path("o1"), "--no-report", NULL) == 1);
    snprintf(line, sizeof line, "manifest.csv:7:");
    CHECK_CONTAINS(err, line);
    CHECK_CONTAINS(err, "f00005.png");
    free(err);
    // a corrupt frame: the file and the line
    gen_t g2 = { .nsteps = 50, .max_us = 12500, .flat_us = 5100, .flat_n = 4, .corrupt_line = 12, .w = 48, .h = 32 };
    m = gen_manifest("corrupt", &g2);
    CHECK(expect_fail(&err, "calib", "gain", "--frames", m, "-o", test_path("o2"), "--no-report", NULL) == 1);
    CHECK_CONTAINS(err, "manifest.csv:12:");
    CHECK_CONTAINS(err, "f00010.png");
    free(err);
    // too few sweep steps
    gen_t g3 = { .nsteps = 20, .max_us = 12500, .flat_us = 5100, .flat_n = 4, .w = 48, .h = 32 };
    m = gen_manifest("few", &g3);
    CHECK(expect_fail(&err, "calib", "gain", "--frames", m, "-o", test_path("o3"), "--no-report", NULL) == 1);
    CHECK_CONTAINS(err, "too few sweep steps: 21 exposures");   // 20 + the flat's
    free(err);
    CHECK(expect_fail(&err, "calib", "gain", "--yes", "--rig", test_path("none.ini"), "-o", test_path("o4"), "--steps", "10",
                      NULL) == 1);
    CHECK_CONTAINS(err, "too few sweep steps");
    free(err);
    // saturated flats: the measured levels
    gen_t g4 = { .nsteps = 50, .max_us = 12500, .flat_us = 11000, .flat_n = 8, .w = 48, .h = 32 };
    m = gen_manifest("sat", &g4);
    CHECK(expect_fail(&err, "calib", "gain", "--frames", m, "-o", test_path("o5"), "--no-report", "--max-dn", "4095",
                      NULL) == 1);
    CHECK_CONTAINS(err, "is saturated: mean");
    CHECK_CONTAINS(err, "DN above dark");
    free(err);
    // too dark flats
    gen_t g5 = { .nsteps = 50, .max_us = 12500, .flat_us = 200, .flat_n = 8, .w = 48, .h = 32 };
    m = gen_manifest("dark", &g5);
    CHECK(expect_fail(&err, "calib", "gain", "--frames", m, "-o", test_path("o6"), "--no-report", NULL) == 1);
    CHECK_CONTAINS(err, "is too dark: mean");
    free(err);
    // a sweep that does not reach saturation
    gen_t g6 = { .nsteps = 50, .max_us = 6000, .flat_us = 3000, .flat_n = 4, .w = 48, .h = 32 };
    m = gen_manifest("nosat", &g6);
    CHECK(expect_fail(&err, "calib", "gain", "--frames", m, "-o", test_path("o7"), "--no-report", NULL) == 1);
    CHECK_CONTAINS(err, "does not reach saturation");
    free(err);
    // a bad manifest line
    const char *bad = test_write("bad.csv", "file,exposure_us,kind\na.png,12,bright\n");
    CHECK(expect_fail(&err, "calib", "gain", "--frames", bad, "-o", test_path("o8"), NULL) == 1);
    CHECK_CONTAINS(err, "bad.csv:2:");
    CHECK_CONTAINS(err, "kind 'bright' must be dark, light (the sweep), flat or flat-dark");
    free(err);
    // the photon axis needs all three of its options
    CHECK(expect_fail(&err, "calib", "gain", "--frames", bad, "-o", test_path("o9"), "--irradiance", "5", NULL) == 2);
    CHECK_CONTAINS(err, "needs all of --irradiance");
    free(err);
    CHECK(expect_fail(&err, "calib", "gain", "--frames", bad, "-o", test_path("o9"), "--irradiance", "-5", NULL) == 2);
    CHECK_CONTAINS(err, "--irradiance '-5' must be a positive number");
    free(err);
    CHECK(expect_fail(&err, "calib", "gain", "--frames", bad, "-o", test_path("o9"), "--photodiode-na", "5", NULL) == 2);
    CHECK_CONTAINS(err, "needs all of --photodiode-na");
    free(err);
}

TEST(calib_gain_numerics)
{
    // a linear sensor with K 0.3, read variance 4 DN^2: K, read noise, LE 0
    enum { N = 60 };
    double t[N], mu[N], var[N];
    const double K = 0.3, sat = 3000;
    for (int i = 0; i < N; i++) {
        t[i] = 100.0 * (i + 1);
        double m = 0.6 * t[i];
        mu[i] = fmin(m, sat);
        var[i] = m < sat ? K * m : K * sat * (1 - (m - sat) / 600);   // drops beyond saturation
        if (var[i] < 0) var[i] = 0;
    }
    calib_gain_ptc_t p;
    CHECK(calib_gain_ptc(t, mu, var, NULL, N, 4 + 1.0 / 12, 1, &p));
    CHECK_REL(p.system_gain_dn_per_e, K, 1e-9);
    CHECK_REL(p.system_gain_linear_dn_per_e, K, 1e-9);
    CHECK_REL(p.read_noise_e, 2 / K, 1e-9);
    CHECK_NEAR(p.saturation_dn, sat, 1e-9);
    CHECK_NEAR(p.linearity_error_pct, 0, 1e-9);
    CHECK_REL(p.response_dn_per_us, 0.6, 1e-9);
    // a quadratic compression: the small-signal K survives, the straight line is low
    for (int i = 0; i < N; i++) {
        double e = 0.6 * t[i] / K;   // electrons
        var[i] = mu[i] < sat ? K * K * e * pow(1 - 2 * 0.02 * e / 12000, 2) : var[i];
        mu[i] = mu[i] < sat ? K * e * (1 - 0.02 * e / 12000) : mu[i];
    }
    CHECK(calib_gain_ptc(t, mu, var, NULL, N, 4, 1, &p));
    CHECK_REL(p.system_gain_dn_per_e, K, 0.003);
    CHECK(p.system_gain_linear_dn_per_e < 0.99 * K);
    CHECK(p.linearity_error_pct > 0.3);
    // no saturation in the data: an error
    for (int i = 0; i < N; i++) var[i] = K * mu[i];
    for (int i = 0; i < N; i++) mu[i] = 0.6 * t[i];
    for (int i = 0; i < N; i++) var[i] = K * mu[i];
    CHECK(!calib_gain_ptc(t, mu, var, NULL, N, 4, 1, &p));
    CHECK_CONTAINS(model_last_error(), "does not reach saturation");
    // the high-pass removes a quadratic surface exactly, keeps a pattern
    enum { W = 40, H = 30 };
    float in[W * H], out[W * H], pat[W * H];
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++) {
            pat[y * W + x] = (float)(1 + 0.01 * (((x * 7 + y * 13) % 5) - 2));
            in[y * W + x] = (float)((100 + 0.5 * x - 0.2 * y - 0.01 * x * x + 0.003 * x * y) * 1.0);
        }
    CHECK(calib_gain_highpass(in, W, H, out));
    double md = 0;
    for (int i = 0; i < W * H; i++) md = fmax(md, fabs(out[i] - 1));
    CHECK(md < 1e-5);
    for (int i = 0; i < W * H; i++) in[i] *= pat[i];
    CHECK(calib_gain_highpass(in, W, H, out));
    CHECK(calib_gain_correlation(out, pat, W * H) > 0.99);
}

// calib_gain_radiance_of_truth: the radiance these tests give refl calib gain
// (--radiance 5000) is the truth's: its flat-field source's radiance per lamp
// (1000) times its 5 lamps. The calibration itself never reads the truth.
TEST(calib_gain_radiance_of_truth)
{
    rig_truth_t *t = rig_truth_load(truth_path());
    CHECK(t != NULL);
    if (!t) return;
    double r = 0;
    CHECK(rig_truth_uniform_radiance(t, "flat_field", &r));
    CHECK_NEAR(r, 1000, 1e-9);
    model_lamps_t *lamps = rig_truth_lamps(t);
    CHECK(lamps && lamps->n == 5);
    model_lamps_free(lamps);
    bool q = model_error_quiet_thread(true);
    CHECK(!rig_truth_uniform_radiance(t, "calib_board", &r));   // not a uniform source
    model_error_quiet_thread(q);
    rig_truth_free(t);
}

// calib_set_camera_layouts: the calibration set of one camera of a directory
// of several (calib_set_load_camera): NAME's camera model in any of its
// places, its own gain calibration (or the top level's when that records
// NAME, never another camera's), its white; the gain calibration's gain and
// unit read back; missing and malformed files named.
TEST(calib_set_camera_layouts)
{
    char src[PATH_MAX + 64], top[PATH_MAX];
    if (!realpath(test_srcdir(), top)) snprintf(top, sizeof top, "%s", test_srcdir());
    snprintf(src, sizeof src, "%s/examples/camera.cameramodel", top);
    char *cm = model_read_file(src, NULL);
    CHECK(cm != NULL);
    if (!cm) return;
    const char *lamps = "{\"lamps\": [{\"name\": \"east\", \"position_mm\": [400, 0, 600]}]}\n";
    static const char *const dirs[] = { "one", "two/geometry", "two/right", "two/lamps", "two/gain/right",
                                        "two/white/right", "two/left" };
    for (size_t k = 0; k < sizeof dirs / sizeof dirs[0]; k++) g_mkdir_with_parents(test_path(dirs[k]), 0755);
    // one camera, a version 1 gain.json without camera, gain or unit: 0 dB
    test_write("one/camera.cameramodel", cm);
    test_write("one/lamps.json", lamps);
    test_write("one/gain.json", "{\"camera\": \"camera\", \"system_gain_dn_per_e\": 0.25, \"read_noise_e\": 6}\n");
    bool q = model_error_quiet_thread(true);
    calib_set_t *c = calib_set_load(test_path("one"), false);
    CHECK(c && !c->camera[0] && c->cal_gain == 0 && !strcmp(c->cal_gain_unit, "dB") && c->gain_dn_per_e == 0.25);
    calib_set_free(c);
    // several: left's model in geometry/, its gain the top level's (it records left, at 6 dB); right's
    // model in right/, its gain in gain/right/ (at 100 raw) and its white in white/right/
    test_write("two/geometry/left.cameramodel", cm);
    test_write("two/right/camera.cameramodel", cm);
    test_write("two/lamps/lamps.json", lamps);
    test_write("two/gain.json", "{\"camera\": \"left\", \"gain_db\": 6, \"gain_unit\": \"dB\", "
                                "\"system_gain_dn_per_e\": 0.5, \"read_noise_e\": 6}\n");
    test_write("two/gain/right/gain.json", "{\"camera\": \"right\", \"gain_db\": 100, \"gain_unit\": \"raw\", "
                                           "\"system_gain_dn_per_e\": 0.3, \"read_noise_e\": 4}\n");
    test_write("two/white/right/white.json", "{\"camera\": \"right\", \"lamps\": [{\"name\": \"east\", "
                                             "\"kc_I_per_us\": 480}]}\n");
    char two[PATH_MAX];
    snprintf(two, sizeof two, "%s", test_path("two"));
    CHECK(calib_set_has_camera(two, "left") && calib_set_has_camera(two, "right"));
    CHECK(!calib_set_has_camera(two, "middle"));
    CHECK(calib_set_has_camera(test_path("one"), NULL) && !calib_set_has_camera(two, NULL));
    c = calib_set_load_camera(two, "left", false);
    CHECK_MSG(c != NULL, "%s", model_last_error());
    if (c) {
        CHECK(!strcmp(c->camera, "left") && c->cal_gain == 6 && !strcmp(c->cal_gain_unit, "dB"));
        CHECK(c->gain_dn_per_e == 0.5 && !c->have_white);
    }
    calib_set_free(c);
    c = calib_set_load_camera(two, "right", true);
    CHECK_MSG(c != NULL, "%s", model_last_error());
    if (c) {
        CHECK(!strcmp(c->camera, "right") && c->cal_gain == 100 && !strcmp(c->cal_gain_unit, "raw"));
        CHECK(c->gain_dn_per_e == 0.3 && c->have_white && c->kcI_per_us[0] == 480);
    }
    calib_set_free(c);
    // left has no white; a camera without a model; right without its own gain: not left's
    CHECK(calib_set_load_camera(two, "left", true) == NULL);
    CHECK_CONTAINS(model_last_error(), "no left/white.json");
    CHECK(calib_set_load_camera(two, "middle", false) == NULL);
    CHECK_CONTAINS(model_last_error(), "no middle.cameramodel");
    CHECK(unlink(test_path("two/gain/right/gain.json")) == 0);
    c = calib_set_load_camera(two, "right", false);
    CHECK(c && c->gain_dn_per_e == 0 && c->cal_gain == 0 && !strcmp(c->cal_gain_unit, "dB"));
    calib_set_free(c);
    // a malformed gain unit
    test_write("two/left/gain.json", "{\"camera\": \"left\", \"gain_db\": 0, \"gain_unit\": 5}\n");
    CHECK(calib_set_load_camera(two, "left", false) == NULL);
    CHECK_CONTAINS(model_last_error(), "gain_unit a string");
    CHECK_CONTAINS(model_last_error(), "left/gain.json");
    model_error_quiet_thread(q);
    free(cm);
}

// calib_set_format_versions: the calibration set checks each JSON file's
// format and version: a file that names none reads as version 1, a version
// this refl knows is read and recorded, a newer version or another format is
// refused naming the file.
TEST(calib_set_format_versions)
{
    char src[PATH_MAX + 64], top[PATH_MAX];
    if (!realpath(test_srcdir(), top)) snprintf(top, sizeof top, "%s", test_srcdir());
    snprintf(src, sizeof src, "%s/examples/camera.cameramodel", top);
    char *cm = model_read_file(src, NULL);
    CHECK(cm != NULL);
    if (!cm) return;
    g_mkdir_with_parents(test_path("fv"), 0755);
    char cam[PATH_MAX], lamps[PATH_MAX], gain[PATH_MAX], white[PATH_MAX];
    snprintf(cam, sizeof cam, "%s", test_write("fv/camera.cameramodel", cm));
    snprintf(lamps, sizeof lamps, "%s", test_path("fv/lamps.json"));
    snprintf(gain, sizeof gain, "%s", test_path("fv/gain.json"));
    snprintf(white, sizeof white, "%s", test_path("fv/white.json"));
    const char *lamp = "\"lamps\": [{\"name\": \"east\", \"position_mm\": [400, 0, 600]}]";
    const char *lin = "\"linearisation\": {\"method\": \"parametric\", \"a_per_dn\": 0}";
    char buf[512];
    snprintf(buf, sizeof buf, "{%s}\n", lamp);
    test_write("fv/lamps.json", buf);
    test_write("fv/gain.json", "{\"system_gain_dn_per_e\": 0.25, \"read_noise_e\": 6}\n");
    test_write("fv/white.json", "{\"lamps\": [{\"name\": \"east\", \"kc_I_per_us\": 480}]}\n");
    bool q = model_error_quiet_thread(true);
    calib_set_t *c = calib_set_load_files(cam, lamps, gain, white);
    CHECK_MSG(c != NULL, "%s", model_last_error());
    if (c) CHECK(c->lamps_version == 1 && c->gain_version == 1 && c->white_version == 1);
    calib_set_free(c);
    // the versions refl writes
    snprintf(buf, sizeof buf, "{\"format\": \"refl-lamps\", \"version\": 1, %s}\n", lamp);
    test_write("fv/lamps.json", buf);
    snprintf(buf, sizeof buf, "{\"format\": \"refl-gain\", \"version\": %d, \"gain_db\": 0, \"gain_unit\": \"dB\", %s}\n",
             CALIB_GAIN_FORMAT_VERSION, lin);
    test_write("fv/gain.json", buf);
    test_write("fv/white.json", "{\"format\": \"refl-white\", \"version\": 1, \"lamps\": [{\"name\": \"east\", "
                                "\"kc_I_per_us\": 480}]}\n");
    c = calib_set_load_files(cam, lamps, gain, white);
    CHECK_MSG(c != NULL, "%s", model_last_error());
    if (c) CHECK(c->gain_version == CALIB_GAIN_FORMAT_VERSION && c->have_white && c->kcI_per_us[0] == 480);
    calib_set_free(c);
    // newer versions are refused, naming the file
    snprintf(buf, sizeof buf, "{\"format\": \"refl-gain\", \"version\": %d, %s}\n", CALIB_GAIN_FORMAT_VERSION + 1, lin);
    test_write("fv/gain.json", buf);
    CHECK(calib_set_load_files(cam, lamps, gain, white) == NULL);
    CHECK_CONTAINS(model_last_error(), "fv/gain.json");
    CHECK_CONTAINS(model_last_error(), "written by a newer refl");
    c = calib_set_load_files(cam, lamps, NULL, NULL);   // the camera and lamps alone load
    CHECK(c != NULL);
    calib_set_free(c);
    test_write("fv/white.json", "{\"format\": \"refl-white\", \"version\": 2, \"lamps\": []}\n");
    CHECK(calib_set_load_files(cam, lamps, NULL, white) == NULL);
    CHECK_CONTAINS(model_last_error(), "fv/white.json");
    CHECK_CONTAINS(model_last_error(), "refl-white version 2");
    snprintf(buf, sizeof buf, "{\"format\": \"refl-lamps\", \"version\": 2, %s}\n", lamp);
    test_write("fv/lamps.json", buf);
    CHECK(calib_set_load_files(cam, lamps, NULL, NULL) == NULL);
    CHECK_CONTAINS(model_last_error(), "fv/lamps.json");
    CHECK_CONTAINS(model_last_error(), "written by a newer refl");
    // another format in a file's place
    test_write("fv/lamps.json", "{\"format\": \"refl-gain\", \"version\": 1}\n");
    CHECK(calib_set_load_files(cam, lamps, NULL, NULL) == NULL);
    CHECK_CONTAINS(model_last_error(), "a refl-gain file, not refl-lamps");
    model_error_quiet_thread(q);
    free(cm);
}

// calib_gain_analyse_phases: the dark model, the sweep and photon transfer
// of one gain on groups with known statistics (no frames): dark level 100 DN
// + 0.001 DN/us, dark variance 4 DN^2 + 1e-4 DN^2/us, measured at four
// exposures of their own (every sweep step takes the dark model); signal
// 0.5 DN/us with variance K = 0.25 DN/e- times it up to 2800 DN, then
// saturated. Missing darks and too few steps are errors.
TEST(calib_gain_analyse_phases)
{
    enum { NS = 60, ND = 4 };
    calib_gain_group_t g[NS + ND];
    static const double tdark[ND] = { 150, 2050, 4050, 8050 };
    for (int i = 0; i < ND; i++)
        g[i] = (calib_gain_group_t){ .exposure_us = tdark[i], .dark = true, .set = CALIB_GAIN_SET_DARK, .n = 2,
                                     .mean_dn = 100 + 0.001 * tdark[i], .var_dn2 = 4 + 1e-4 * tdark[i] };
    for (int i = 0; i < NS; i++) {
        double t = 100.0 * (i + 1), mu = 0.5 * t;
        bool sat = mu > 2800;
        g[ND + i] = (calib_gain_group_t){ .exposure_us = t, .set = CALIB_GAIN_SET_SWEEP, .n = 2,
                                          .mean_dn = 100 + 0.001 * t + (sat ? 2800 : mu),
                                          .var_dn2 = 4 + 1e-4 * t + (sat ? 1 : 0.25 * mu) };
    }
    calib_gain_data_t d = { .g = g, .ng = NS + ND };
    calib_gain_an_t a;
    bool q = model_error_quiet_thread(true);
    CHECK_MSG(calib_gain_analyse(&d, 0, 50, 1, &a), "%s", model_last_error());
    CHECK(a.n == NS && a.ndark == ND);
    CHECK_NEAR(a.dark_intercept_dn, 100, 1e-9);
    CHECK_NEAR(a.dark_slope_dn_per_us, 0.001, 1e-12);
    CHECK_NEAR(a.var_dark_dn2, 4, 1e-9);
    CHECK_NEAR(a.dark_var_slope_dn2_per_us, 1e-4, 1e-12);
    CHECK(a.dark_t_min_us == 150 && a.dark_t_max_us == 8050);
    for (int i = 0; i < NS; i++) {
        CHECK_NEAR(a.t[i], 100.0 * (i + 1), 0);
        CHECK_NEAR(a.mu[i], fmin(0.5 * a.t[i], 2800), 1e-9);
        CHECK_NEAR(a.var_d[i], 4 + 1e-4 * a.t[i], 1e-9);
    }
    CHECK_NEAR(a.ptc.saturation_dn, 2800, 1e-9);
    CHECK_REL(a.ptc.system_gain_dn_per_e, 0.25, 1e-9);
    CHECK_REL(a.ptc.read_noise_e, sqrt(4 - 1.0 / 12) / 0.25, 1e-9);
    CHECK_REL(a.response0_dn_per_us, 0.5, 1e-9);
    calib_gain_an_free(&a);
    CHECK(!calib_gain_analyse(&d, 0, NS + 1, 1, &a));
    CHECK_CONTAINS(model_last_error(), "too few sweep steps: 60 exposures");
    calib_gain_an_free(&a);
    d.g = g + ND;
    d.ng = NS;
    CHECK(!calib_gain_analyse(&d, 0, 50, 1, &a));
    CHECK_CONTAINS(model_last_error(), "no dark frame pairs");
    calib_gain_an_free(&a);
    model_error_quiet_thread(q);
}

// ---------------------------------------------------------------------------
// The response linearisation: a known monotone response that is
// not of the form S (1 - a S) (a gamma at the low end, an exponential knee
// toward full well), swept as refl calib gain sweeps (calib_gain_sweep_exposures:
// 50 equal steps up to 1.2 x saturation and 16 geometric ones at the low end).

enum { LIN_N = 66 };
static const double LIN_K = 0.25, LIN_FW = 16000, LIN_RATE = 16.0;   // DN/e-, e-, e-/us

// The test sensor's electrons out for e in: a gamma of 1.03 below 600 e-, a
// knee from 85 % of the well, k + (FW - k)(1 - exp(-(e - k)/(FW - k))).
static double lin_response(double e)
{
    const double el = 600, g = 1.03, k = 0.85 * LIN_FW;
    if (e > 0 && e < el) e = el * pow(e / el, g);
    if (e > k) e = k + (LIN_FW - k) * (1 - exp(-(e - k) / (LIN_FW - k)));
    return e;
}

// The sweep: t[i] us and mu[i] DN above dark (clipped at the well); returns
// the saturation (the last step below the clip).
static double lin_sweep(double *t, double *mu, double noise_rel)
{
    double sat = 0;
    CHECK(calib_gain_sweep_exposures(1.2 * LIN_FW / LIN_RATE, 50, 16, t) == LIN_N);
    for (int i = 0; i < LIN_N; i++) {
        double e = fmin(lin_response(LIN_RATE * t[i]), 0.999 * LIN_FW);
        // a deterministic +-noise_rel pattern (the ROI mean's noise)
        mu[i] = LIN_K * e * (1 + noise_rel * ((i * 7919) % 13 - 6) / 6.0);
        if (e < 0.999 * LIN_FW) sat = mu[i];
    }
    return sat;
}

// The largest relative error of the linearisation over 2..95 % of saturation
// (a fine grid of the true signal), the linear truth K e.
static double lin_max_error(const model_lin_t *L, double sat, double gf)
{
    double worst = 0;
    for (int k = 0; k <= 2000; k++) {
        double S = sat * (0.02 + 0.93 * k / 2000.0);   // the linear truth, DN
        double e = S / LIN_K, m = LIN_K * lin_response(e);
        if (m > 0.95 * sat) break;
        double r = model_linearise(L, gf * m, gf, NULL) / (gf * S) - 1;
        worst = fmax(worst, fabs(r));
    }
    return worst;
}

TEST(calib_gain_linearisation_known_response)
{
    double t[LIN_N], mu[LIN_N];
    double sat = lin_sweep(t, mu, 0);
    model_lin_t L;
    double a, r, c0;
    CHECK(calib_gain_linearisation(t, mu, LIN_N, sat, &L, &a, &r, &c0));
    CHECK(L.kind == MODEL_LIN_MONOTONE && L.n >= 56);
    CHECK_REL(r, LIN_K * LIN_RATE, 1e-3);   // the anchor: the small-signal response
    double err = lin_max_error(&L, sat, 1), err6 = lin_max_error(&L, sat, pow(10, 6 / 20.0));
    model_lin_t P = { .kind = MODEL_LIN_PARAMETRIC, .a_per_dn = a };
    double err_p = lin_max_error(&P, sat, 1);
    fprintf(stderr, "  linear signal recovered over 2..95 %% of saturation: monotone table %.4f %% (at 6 dB %.4f %%), "
            "S(1 - aS) with a = %.3g per DN %.3f %%\n", 100 * err, 100 * err6, a, 100 * err_p);
    CHECK(err < 0.002);
    CHECK(err6 < 0.002);   // the table scales with the gain
    CHECK(err_p > 0.002);
    CHECK(err_p > 3 * err);
    // monotone: a fine grid from below 0 to beyond the last knot rises, its slope positive
    double prev = -INFINITY;
    bool mono = true;
    for (int k = -50; k <= 5000; k++) {
        double x = 1.1 * sat * k / 5000.0, sl, y = model_linearise(&L, x, 1, &sl);
        mono &= y > prev && sl > 0;
        prev = y;
    }
    CHECK(mono);
    // the Release 4.0 LE of the linearised sweep is far below the raw one's
    double le_raw = calib_gain_linearity_r4(t, mu, LIN_N, sat, 0.05, 0.95, NULL, NULL, NULL, NULL), lt[LIN_N];
    for (int i = 0; i < LIN_N; i++) lt[i] = model_linearise(&L, mu[i], 1, NULL);
    double le_lin = calib_gain_linearity_r4(t, lt, LIN_N, 1, model_linearise(&L, 0.05 * sat, 1, NULL),
                                            model_linearise(&L, 0.95 * sat, 1, NULL), NULL, NULL, NULL, NULL);
    fprintf(stderr, "  LE (Release 4.0): raw %.3f %%, linearised %.4f %%\n", le_raw, le_lin);
    CHECK(le_raw > 1);
    CHECK(le_lin < 0.1);

    // noisy means that are not monotone near the top: isotonic regression keeps the table monotone
    // (means with a +-0.05 % pattern: the noise of a small region's mean)
    sat = lin_sweep(t, mu, 0.0005);
    mu[56] = mu[57] + 1;   // a step above its successor
    CHECK(calib_gain_linearisation(t, mu, LIN_N, sat, &L, &a, &r, &c0));
    for (int k = 1; k < L.n; k++) CHECK(L.m[k] > L.m[k - 1] && L.s[k] > L.s[k - 1] && L.d[k] >= 0);
    double err_n = lin_max_error(&L, sat, 1);
    fprintf(stderr, "  with noisy, non-monotone means: %.4f %%\n", 100 * err_n);
    CHECK(err_n < 0.003);
    // too few steps in the anchor's range: an error that says why
    CHECK(!calib_gain_linearisation(t, mu, 3, sat, &L, &a, &r, &c0));
    CHECK_CONTAINS(model_last_error(), "small-signal response");
}

// Fritsch & Carlson's interpolant on knots of a known function: exact on a
// straight line, monotone on steps, and the table's own knots reproduced.
TEST(model_lin_monotone_interpolant)
{
    double m[6] = { 10, 20, 30, 40, 50, 60 }, s[6];
    for (int i = 0; i < 6; i++) s[i] = 2 * m[i];
    model_lin_t L;
    CHECK(model_lin_monotone(m, s, 6, &L));
    CHECK(L.n == 7 && L.m[0] == 0 && L.s[0] == 0);   // (0, 0) first
    double sl;
    for (double x = -5; x < 80; x += 0.37) CHECK_NEAR(model_linearise(&L, x, 1, &sl), 2 * x, 1e-9);
    CHECK_NEAR(sl, 2, 1e-12);
    // a flat run between rising parts: no overshoot, the knots exact
    double m2[5] = { 1, 2, 3, 4, 5 }, s2[5] = { 1, 2, 2.001, 2.002, 6 };
    CHECK(model_lin_monotone(m2, s2, 5, &L));
    for (int i = 0; i < 5; i++) CHECK_NEAR(model_linearise(&L, m2[i], 1, NULL), s2[i], 1e-12);
    double prev = -1;
    for (double x = 0; x <= 5; x += 0.001) {
        double y = model_linearise(&L, x, 1, NULL);
        CHECK(y >= prev - 1e-12);
        prev = y;
    }
    // the linear signal must rise with exposure; nothing positive: errors
    double bad[3] = { 1, 3, 2 };
    CHECK(!model_lin_monotone(m2, bad, 3, &L));
    double neg[3] = { -1, -2, -3 }, up[3] = { 1, 2, 3 };
    CHECK(!model_lin_monotone(neg, up, 3, &L));
    // parametric: the inverse of S_m = S (1 - a S), and a -> a / f at gain factor f
    model_lin_t P = { .kind = MODEL_LIN_PARAMETRIC, .a_per_dn = 1e-5 };
    double S = 3000, Sm = S * (1 - 1e-5 * S);
    CHECK_REL(model_linearise(&P, Sm, 1, NULL), S, 1e-12);
    CHECK_REL(model_linearise(&P, 2 * S * (1 - 1e-5 / 2 * 2 * S), 2, NULL), 2 * S, 1e-12);
    CHECK_NEAR(model_linearise(NULL, 123.5, 1, NULL), 123.5, 0);
}

// EMVA 1288 Release 4.0's linearity error on a response computed by hand:
// t = 1, 2, 3 us, mu = 100, 210, 290 DN (saturation 310: all three within
// 5..95 %). The line minimising sum((mu - a0 - a1 t) / mu)^2 solves the 2x2
// normal equations with weights 1/mu^2; in exact fractions a0 = 2 and
// a1 = 99.10905730129..., deviations 100 (mu - line) / line = -1.09689,
// +4.88561, -3.11605 %, LE = (4.88561 + 3.11605) / 2 = 4.00083 %. Release
// 3's unweighted line (a0 = 10, a1 = 95): deviations -4.76190, +5, -1.69492 %,
// LE 4.88095 %.
TEST(calib_gain_linearity_r4_hand)
{
    double t[3] = { 1, 2, 3 }, mu[3] = { 100, 210, 290 }, dev[3], a1, a0;
    int nfit;
    double le = calib_gain_linearity_r4(t, mu, 3, 310, 0.05, 0.95, &a1, &a0, &nfit, dev);
    CHECK(nfit == 3);
    CHECK_NEAR(a0, 2, 1e-9);
    CHECK_NEAR(a1, 99.1090573013, 1e-8);
    CHECK_NEAR(dev[0], -1.0968921389, 1e-8);
    CHECK_NEAR(dev[1], 4.8856145793, 1e-8);
    CHECK_NEAR(le, 4.0008302123, 1e-8);
    CHECK_NEAR(calib_gain_linearity(t, mu, 3, 310, 0.05, 0.95, NULL, NULL, NULL, NULL), 4.8809523810, 1e-8);
}

// A refl-gain version 1 file without "linearisation" loads and applies
// S(1 - aS) of its curves; a file with the table applies it, and its method
// "parametric" the a; a malformed one is an error naming the file. A version
// 2 file needs its "linearisation"; a newer version or another format is
// refused.
TEST(calib_gain_lin_json_compat)
{
    double t[LIN_N], mu[LIN_N];
    double sat = lin_sweep(t, mu, 0);
    // version 1 without the table: gains[0].curves at gain_db 0
    json_t *cv = json_object(), *et = json_array(), *es = json_array();
    for (int i = 0; i < LIN_N; i++) {
        json_array_append_new(et, json_real(t[i]));
        json_array_append_new(es, json_real(mu[i]));
    }
    json_object_set_new(cv, "exposure_us", et);
    json_object_set_new(cv, "signal_dn", es);
    json_t *old = json_pack("{s:f, s:f, s:[{s:f, s:o}]}", "gain_db", 0.0, "saturation_dn", sat, "gains", "gain_db",
                            0.0, "curves", cv);
    model_lin_t L;
    CHECK(calib_gain_lin_from_json(old, "old/gain.json", &L));
    CHECK(L.kind == MODEL_LIN_PARAMETRIC);
    CHECK_REL(L.a_per_dn, calib_gain_parametric_a(t, mu, LIN_N, sat), 1e-12);
    CHECK(L.a_per_dn > 0);
    // version 2 names itself and always has the table
    json_t *v2 = json_deep_copy(old);
    json_object_set_new(v2, "format", json_string("refl-gain"));
    json_object_set_new(v2, "version", json_integer(2));
    CHECK(!calib_gain_lin_from_json(v2, "v2/gain.json", &L));
    CHECK_CONTAINS(model_last_error(), "v2/gain.json");
    CHECK_CONTAINS(model_last_error(), "without its \"linearisation\"");
    json_object_set_new(v2, "version", json_integer(CALIB_GAIN_FORMAT_VERSION + 1));
    CHECK(!calib_gain_lin_from_json(v2, "v3/gain.json", &L));
    CHECK_CONTAINS(model_last_error(), "written by a newer refl");
    json_object_set_new(v2, "format", json_string("refl-white"));
    CHECK(!calib_gain_lin_from_json(v2, "w/gain.json", &L));
    CHECK_CONTAINS(model_last_error(), "not refl-gain");
    json_decref(v2);
    // with the table
    model_lin_t T;
    double a, r, c0;
    CHECK(calib_gain_linearisation(t, mu, LIN_N, sat, &T, &a, &r, &c0));
    json_t *jm = json_array(), *js = json_array();
    for (int i = 0; i < T.n; i++) {
        json_array_append_new(jm, json_real(T.m[i]));
        json_array_append_new(js, json_real(T.s[i]));
    }
    json_object_set_new(old, "linearisation", json_pack("{s:s, s:f, s:o, s:o}", "method", "monotone", "a_per_dn", a,
                                                        "measured_dn", jm, "linear_dn", js));
    CHECK(calib_gain_lin_from_json(old, "new/gain.json", &L));
    CHECK(L.kind == MODEL_LIN_MONOTONE && L.n == T.n);
    json_object_set_new(old, "format", json_string("refl-gain"));
    json_object_set_new(old, "version", json_integer(2));
    CHECK(calib_gain_lin_from_json(old, "new/gain.json", &L));
    CHECK(L.kind == MODEL_LIN_MONOTONE && L.n == T.n);
    CHECK_REL(model_linearise(&L, 0.9 * sat, 1, NULL), model_linearise(&T, 0.9 * sat, 1, NULL), 1e-12);
    json_object_set_new(json_object_get(old, "linearisation"), "method", json_string("parametric"));
    CHECK(calib_gain_lin_from_json(old, "new/gain.json", &L));
    CHECK(L.kind == MODEL_LIN_PARAMETRIC && L.a_per_dn == a);
    json_object_set_new(json_object_get(old, "linearisation"), "method", json_string("spline"));
    CHECK(!calib_gain_lin_from_json(old, "bad/gain.json", &L));
    CHECK_CONTAINS(model_last_error(), "bad/gain.json");
    json_object_set_new(json_object_get(old, "linearisation"), "method", json_string("monotone"));
    json_array_set_new(js, 3, json_real(-1));
    CHECK(!calib_gain_lin_from_json(old, "bad/gain.json", &L));
    CHECK_CONTAINS(model_last_error(), "knot 3");
    json_decref(old);
}

// The stated 1-sigmas of the EMVA figures against their scatter over
// repeated synthetic frame sets (within 20 %): K from photon transfer
// (calib_gain_ptc's standard error), the dark fits' slope and intercept
// (calib_gain_polyfit_se, whose points scatter unequally), and a fixed
// pattern's std through the temporal noise of an average
// (calib_gain_spatial_std: DSNU and PRNU).
static double gs_std(const double *x, int n, double *mean)
{
    double m = 0, v = 0;
    for (int i = 0; i < n; i++) m += x[i] / n;
    for (int i = 0; i < n; i++) v += (x[i] - m) * (x[i] - m);
    if (mean) *mean = m;
    return sqrt(v / (n - 1));
}

TEST(calib_gain_sigmas_scatter)
{
    enum { SETS = 200, NPIX = 1024, NT = 50, NLOW = 16, NS = NT + NLOW };
    const double K = 0.25, rn_dn = 1.5, fw = 16000, full = 4095;
    model_rng_t r = model_rng(21, 1);
    double t[NS];
    int ns = calib_gain_sweep_exposures(10000, NT, NLOW, t);
    CHECK(ns == NS);
    double k[SETS], ks[SETS];
    for (int set = 0; set < SETS; set++) {
        double mu[NS], var[NS], vd = 0;
        for (int i = 0; i < ns; i++) {
            double me = fw * 1.2 * t[i] / t[ns - 1];   // electrons: the sweep reaches 1.2 x the well
            double sa = 0, sd = 0, sda = 0, sdd = 0;
            for (int p = 0; p < NPIX; p++) {
                double a = fmin(full, K * (me + sqrt(me) * model_rng_gauss(&r)) + rn_dn * model_rng_gauss(&r));
                double b = fmin(full, K * (me + sqrt(me) * model_rng_gauss(&r)) + rn_dn * model_rng_gauss(&r));
                double da = rn_dn * model_rng_gauss(&r), db = rn_dn * model_rng_gauss(&r);
                sa += a + b, sd += (a - b) * (a - b), sda += da + db, sdd += (da - db) * (da - db);
            }
            mu[i] = (sa - sda) / (2 * NPIX);
            var[i] = (sd - sdd) / (2 * NPIX);
            vd += sdd / (2 * NPIX) / ns;
        }
        calib_gain_ptc_t p;
        CHECK(calib_gain_ptc(t, mu, var, NULL, ns, vd, 0, &p));
        k[set] = p.system_gain_dn_per_e;
        ks[set] = p.system_gain_std_dn_per_e;
    }
    double km, ksm, s = gs_std(k, SETS, &km);
    gs_std(ks, SETS, &ksm);
    fprintf(stderr, "  K %.5f (truth %.3f): scatter %.3g over %d frame sets, stated %.3g (mean)\n", km, K, s, SETS,
            ksm);
    CHECK_MSG(fabs(ksm / s - 1) < 0.2, "K: stated %.4g, scatter %.4g", ksm, s);
    CHECK(fabs(km - K) < 3 * s);

    // the dark fits: mean and temporal variance of a dark pair against exposure
    // (dark current 20 e-/s, exposures 0.1 .. 2 s and the sweep's short ones)
    enum { ND = 40, FITS = 400 };
    double dt[ND], slope[FITS], slope_se[FITS], icpt[FITS], icpt_se[FITS];
    for (int i = 0; i < ND; i++) dt[i] = i < 20 ? 100.0 * (i + 1) : 1e5 * (i - 19);
    for (int f = 0; f < FITS; f++) {
        double dm[ND], dv[ND], c[3], se[3];
        for (int i = 0; i < ND; i++) {
            double ve = rn_dn * rn_dn + K * K * 20e-6 * dt[i];   // DN^2
            dm[i] = 64 + K * 20e-6 * dt[i] + sqrt(ve / NPIX) * model_rng_gauss(&r);
            dv[i] = ve * (1 + sqrt(2.0 / NPIX) * model_rng_gauss(&r));
        }
        CHECK(calib_gain_polyfit_se(dt, dm, ND, 1, c, se));
        slope[f] = c[1], slope_se[f] = se[1];
        CHECK(calib_gain_polyfit_se(dt, dv, ND, 1, c, se));
        icpt[f] = c[0], icpt_se[f] = se[0];
    }
    double a, b;
    double ss = gs_std(slope, FITS, NULL), si = gs_std(icpt, FITS, NULL);
    gs_std(slope_se, FITS, &a);
    gs_std(icpt_se, FITS, &b);
    fprintf(stderr, "  dark current slope: scatter %.3g DN/us, stated %.3g; dark variance at 0: scatter %.3g DN^2, "
            "stated %.3g\n", ss, a, si, b);
    CHECK_MSG(fabs(a / ss - 1) < 0.2, "slope: stated %.4g, scatter %.4g", a, ss);
    CHECK_MSG(fabs(b / si - 1) < 0.2, "intercept: stated %.4g, scatter %.4g", b, si);

    // a fixed pattern of std 1.5 DN under the temporal noise of 16 averaged frames of 1.6 DN
    enum { NP = 4096, AVG = 400 };
    static double pat[NP];
    double pm = 0, pv = 0;
    for (int i = 0; i < NP; i++) pat[i] = model_rng_gauss(&r), pm += pat[i] / NP;
    for (int i = 0; i < NP; i++) pv += (pat[i] - pm) * (pat[i] - pm) / NP;
    for (int i = 0; i < NP; i++) pat[i] = 1.5 * (pat[i] - pm) / sqrt(pv);   // exactly 1.5 DN
    const double tau = 1.6 * 1.6 / 16;
    double est[AVG];
    for (int k2 = 0; k2 < AVG; k2++) {
        double m = 0, v = 0, x[NP];
        for (int i = 0; i < NP; i++) x[i] = pat[i] + sqrt(tau) * model_rng_gauss(&r), m += x[i] / NP;
        for (int i = 0; i < NP; i++) v += (x[i] - m) * (x[i] - m) / NP;
        est[k2] = sqrt(v - tau);
    }
    double em, es = gs_std(est, AVG, &em), st = calib_gain_spatial_std(1.5, tau, NP);
    fprintf(stderr, "  fixed pattern 1.5 DN: %.5f, scatter %.3g over %d averages, stated %.3g\n", em, es, AVG, st);
    CHECK_MSG(fabs(st / es - 1) < 0.2, "pattern: stated %.4g, scatter %.4g", st, es);
    CHECK(fabs(em - 1.5) < 3 * es);
    CHECK(isnan(calib_gain_spatial_std(0, tau, NP)));
}
