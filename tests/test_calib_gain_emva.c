// tests/test_calib_gain_emva.c — EMVA 1288 Release 4.0 Linear figures of
// `refl calib gain` (calib/gain/emva.c) on small synthetic frames with known
// answers:
// calib_gain_emva_photon_axis: the photon count of an irradiance and a
//   photodiode; a noise-free sweep of known eta, K, dark noise: the
//   standard's K, R, eta, sigma_d, mu_e.min, mu_p.min, mu_p.sat, SNR_max, DR
//   by hand, with photon counts and with the exposure standing in.
// calib_gain_emva_split: a row pattern, a column pattern and pixel noise of
//   known standard deviations (and temporal noise to remove) recovered.
// calib_gain_emva_spectrogram: the transform against a plain DFT computed here
//   (prime and composite lengths) and the peak of a periodic column pattern at
//   its frequency with its amplitude.
// calib_gain_emva_defects: planted hot, dead and bright pixels found at their
//   coordinates, nothing else.
// calib_gain_emva_le_compression: Release 4.0's LE (and Release 3's) on a 3 %
//   compression against values computed by hand (exact fractions).
// calib_gain_emva_frames: the whole command on synthetic frames (64x48) with a
//   photon input of known eta, a spatial set marked by the manifest's kind,
//   row/column DSNU patterns and planted defects.
// calib_gain_emva_not_measured_report: the same frames without --irradiance:
//   "not measured", the report and the datasheet page.
#define _GNU_SOURCE
#include <complex.h>
#include <glib.h>
#include <jansson.h>
#include <stdlib.h>
#include <unistd.h>

#include "calib/gain/gain.h"
#include "model/model.h"
#include "model/base/vec.h"
#include "tests/gain_json.h"
#include "tests/test.h"

TEST(calib_gain_emva_photon_axis)
{
    // 1 uW/cm^2 on 25 um^2 at 500 nm for 1000 us: 25e-12 m^2 * 1e-2 W/m^2 * 1e-3 s = 2.5e-16 J;
    // a photon h c / lambda = 6.62607015e-34 * 299792458 / 500e-9 = 3.97289e-19 J: 629.26 photons
    double one = calib_gain_photons(1, 25, 500, 1000);
    CHECK_REL(one, 2.5e-16 / (6.62607015e-34 * 299792458.0 / 500e-9), 1e-12);
    CHECK_NEAR(one, 629.2639, 1e-3);
    // a photodiode of 0.3 A/W and 1 mm^2 reading 5 nA: 5e-9 / 0.3 W on 0.01 cm^2 = 1.6667 uW/cm^2
    CHECK_NEAR(calib_gain_photodiode_irradiance(5, 0.3, 1), 5e-9 / 0.3 / 0.01 * 1e6, 1e-12);
    // a noise-free sweep of eta 0.55, K 0.4 DN/e-, sigma^2_y.dark 9 DN^2, saturation at 4000 DN (the variance
    // collapses there): the standard's figures by hand
    const double eta = 0.55, K = 0.4, E = 3, A = 16, L = 620, var_dark = 9;
    double mp[30], mu_y[30], var_y[30], mu_d[30], var_d[30];
    int isat = -1;
    for (int i = 0; i < 30; i++) {
        mp[i] = calib_gain_photons(E, A, L, 100.0 * (i + 1));
        double Y = K * eta * mp[i];
        mu_d[i] = 100;
        var_d[i] = var_dark;
        mu_y[i] = 100 + fmin(Y, 4000);
        var_y[i] = Y < 4000 ? var_dark + K * Y : 2;
        if (Y < 4000) isat = i;
    }
    const double dt[3] = { 100, 1000, 3000 }, dm[3] = { 100, 100, 100 }, dv[3] = { 9, 9, 9 };
    calib_gain_emva_in_t in = { 30, mp, mu_y, var_y, mu_d, var_d, true, 3, dt, dm, dv, 1 };
    calib_gain_emva_t e;
    CHECK(calib_gain_emva(&in, &e));
    CHECK(e.i_sat == isat);
    CHECK_REL(e.K, K, 1e-12);
    CHECK_REL(e.R, K * eta, 1e-12);
    CHECK_REL(e.qe, eta, 1e-12);
    CHECK_NEAR(e.var_y_dark_dn2, 9, 1e-9);
    CHECK_NEAR(e.sigma_d_e, sqrt(9 - 1.0 / 12) / K, 1e-9);
    CHECK_NEAR(e.mu_e_min, 3 / K + 0.5, 1e-9);   // sigma_y.dark / K + 1/2 = 8
    CHECK_NEAR(e.mu_p_min, 8 / eta, 1e-9);
    CHECK_REL(e.mu_p_sat, mp[isat], 1e-12);
    CHECK_REL(e.mu_e_sat, K * eta * mp[isat] / K, 1e-12);
    CHECK_REL(e.snr_max, sqrt(e.mu_e_sat), 1e-12);
    CHECK_REL(e.dr, e.mu_e_sat / 8, 1e-9);
    CHECK_NEAR(e.le_pct, 0, 1e-9);               // a straight line
    CHECK_NEAR(e.dark_current_e_per_s, 0, 1e-9);
    // the same sweep without photon counts (exposure standing in): the photon figures NAN, the electron ones equal
    double t[30];
    for (int i = 0; i < 30; i++) t[i] = 100.0 * (i + 1);
    calib_gain_emva_in_t in2 = in;
    in2.x = t;
    in2.photons = false;
    calib_gain_emva_t e2;
    CHECK(calib_gain_emva(&in2, &e2));
    CHECK(isnan(e2.qe) && isnan(e2.mu_p_min) && isnan(e2.mu_p_sat));
    CHECK_REL(e2.mu_e_sat, e.mu_e_sat, 1e-12);
    CHECK_REL(e2.dr, e.dr, 1e-12);
    CHECK_REL(e2.K, e.K, 1e-12);
}

TEST(calib_gain_emva_split)
{
    const int W = 200, H = 160;
    float *img = malloc(sizeof(float) * W * H);
    model_rng_t r = model_rng(7, 1);
    // rows: 1.5 sin (4 px period... 16 rows a period): std 1.5/sqrt2; columns: +-2 alternating by pairs: std 2;
    // pixels: gaussian 0.8; temporal noise of the average: gaussian 0.5 (variance 0.25, removed)
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++)
            img[y * W + x] = (float)(100 + 1.5 * sin(2 * M_PI * y / 16) + ((x / 2) % 2 ? 2 : -2) +
                                     0.8 * model_rng_gauss(&r) + 0.5 * model_rng_gauss(&r));
    calib_gain_split_t s;
    calib_gain_spatial_split(img, W, H, NULL, 0.25, 1, &s);
    fprintf(stderr, "  split: total %.4f row %.4f col %.4f pixel %.4f\n", s.total, s.row, s.col, s.pixel);
    CHECK_REL(s.row, 1.5 / sqrt(2), 0.03);
    CHECK_REL(s.col, 2, 0.03);
    CHECK_REL(s.pixel, 0.8, 0.03);
    CHECK_REL(s.total, sqrt(1.125 + 4 + 0.64), 0.02);
    // a region: the same parts; scale multiplies
    int roi[4] = { 20, 16, 160, 128 };
    calib_gain_split_t s2;
    calib_gain_spatial_split(img, W, H, roi, 0.25, 10, &s2);
    CHECK_REL(s2.col, 20, 0.04);
    CHECK_REL(s2.pixel, 8, 0.04);
    // no pattern but pixels: no row or column part
    for (int i = 0; i < W * H; i++) img[i] = (float)(50 + model_rng_gauss(&r));
    calib_gain_spatial_split(img, W, H, NULL, 0, 1, &s);
    CHECK(s.row < 0.03 && s.col < 0.03);
    CHECK_REL(s.pixel, 1, 0.03);
    free(img);
}

TEST(calib_gain_emva_spectrogram)
{
    // the transform against a plain DFT computed here, lengths 67 (prime), 60 and 64
    const int lens[3] = { 67, 60, 64 };
    for (int li = 0; li < 3; li++) {
        const int N = lens[li], R = 3;
        float *img = malloc(sizeof(float) * N * R);
        model_rng_t r = model_rng(11, li);
        for (int i = 0; i < N * R; i++) img[i] = (float)model_rng_gauss(&r);
        double mean = 0;
        for (int i = 0; i < N * R; i++) mean += img[i];
        mean /= N * R;
        double spec[40];
        CHECK(calib_gain_spectrogram(img, N, R, NULL, false, 1, spec) == N / 2 + 1);
        double maxerr = 0;
        for (int k = 0; k <= N / 2; k++) {
            double p = 0;
            for (int y = 0; y < R; y++) {
                double complex Y = 0;
                for (int n = 0; n < N; n++) Y += (img[y * N + n] - mean) * cexp(-2 * M_PI * I * n * k / N);
                p += creal(Y * conj(Y)) / N;
            }
            maxerr = fmax(maxerr, fabs(spec[k] - sqrt(p / R)));
        }
        CHECK_MSG(maxerr < 1e-9, "length %d: max difference %g from the plain DFT", N, maxerr);
        free(img);
    }
    // a periodic column pattern 3 cos(2 pi 8 x / 64) over pixel noise: the horizontal peak at k = 8 with
    // 3 sqrt(64) / 2 = 12; the vertical spectrogram has none
    const int W = 64, H = 48;
    float *img = malloc(sizeof(float) * W * H);
    model_rng_t r = model_rng(3, 3);
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++) img[y * W + x] = (float)(20 + 3 * cos(2 * M_PI * 8 * x / W) + model_rng_gauss(&r));
    double sh[33], sv[25];
    CHECK(calib_gain_spectrogram(img, W, H, NULL, false, 1, sh) == 33);
    CHECK(calib_gain_spectrogram(img, W, H, NULL, true, 1, sv) == 25);
    int kmax = 1;
    for (int k = 1; k < 33; k++)
        if (sh[k] > sh[kmax]) kmax = k;
    CHECK(kmax == 8);
    CHECK_REL(sh[8], sqrt(12 * 12 + 1), 0.05);   // the pattern and the noise's own ~1
    double rest = 0;
    for (int k = 1; k < 33; k++) rest += k != 8 ? sh[k] * sh[k] / 31 : 0;
    CHECK_REL(sqrt(rest), 1, 0.15);               // white noise of std 1 elsewhere
    for (int k = 1; k < 25; k++) CHECK(sv[k] < 2);
    free(img);
}

TEST(calib_gain_emva_defects)
{
    const int W = 80, H = 60;
    float *dark = malloc(sizeof(float) * W * H), *light = malloc(sizeof(float) * W * H);
    unsigned char *map = malloc(W * H);
    model_rng_t r = model_rng(5, 0);
    for (int i = 0; i < W * H; i++) {
        dark[i] = (float)(100 + model_rng_gauss(&r));
        light[i] = (float)(1 + 0.01 * model_rng_gauss(&r));
    }
    dark[7 * W + 13] += 40;     // hot at (13, 7)
    light[30 * W + 40] = 0.2f;  // dead at (40, 30)
    light[44 * W + 5] = 1.5f;   // bright at (5, 44)
    calib_gain_defects_t d;
    CHECK(calib_gain_defects(dark, light, W, H, NULL, 6, 0.1, 0.001, 0, map, &d));
    CHECK(d.hot == 1 && d.dead == 1 && d.bright == 1);
    CHECK(d.nlist[0] == 1 && d.list[0][0][0] == 13 && d.list[0][0][1] == 7);
    CHECK(d.nlist[1] == 1 && d.list[1][0][0] == 40 && d.list[1][0][1] == 30);
    CHECK(d.nlist[2] == 1 && d.list[2][0][0] == 5 && d.list[2][0][1] == 44);
    CHECK(map[7 * W + 13] == 1 && map[30 * W + 40] == 2 && map[44 * W + 5] == 3);
    int flagged = 0;
    for (int i = 0; i < W * H; i++) flagged += map[i] != 0;
    CHECK(flagged == 3);
    CHECK_REL(d.dark_sigma_dn, 1, 0.1);
    CHECK_NEAR(d.dark_threshold_dn, 6 * d.dark_sigma_dn, 1e-12);
    long total = 0;
    for (int b = 0; b < CALIB_GAIN_HIST_BINS; b++) total += d.dark_hist[b];
    CHECK(total == W * H);
    CHECK(d.dark_hi > 39 && d.light_lo < -79);   // the histograms reach the defects (DN, %)
    // an averaged dark of 16 frames: values 1/16 DN apart, 160 levels of 30 pixels each; with the step given the
    // bins are 2 levels wide (80 bins of 60 pixels, no comb); without it 128 bins hold 1 or 2 levels
    for (int i = 0; i < W * H; i++) dark[i] = (float)(100 + (i % 160) / 16.0);
    CHECK(calib_gain_defects(dark, light, W, H, NULL, 6, 0.1, 0.001, 1.0 / 16, NULL, &d));
    CHECK(d.dark_nbins == 80);
    int uneven = 0;
    for (int b = 0; b < d.dark_nbins; b++) uneven += d.dark_hist[b] != 60;
    CHECK_MSG(uneven == 0, "%d bins of other than 60 pixels", uneven);
    CHECK_NEAR(d.dark_hi - d.dark_lo, 80 * 2.0 / 16, 1e-9);
    CHECK(calib_gain_defects(dark, light, W, H, NULL, 6, 0.1, 0.001, 0, NULL, &d));
    CHECK(d.dark_nbins == CALIB_GAIN_HIST_BINS);
    free(dark);
    free(light);
    free(map);
}

// mu = S (1 - a S), S = 100 t, t = 1..10 us, a = 0.03 / 1000 per DN (3 % compression at 1000 DN): mu = 99.7,
// 198.8, ..., 970 DN; saturation 1100 DN (all within 5..95 %). With exact fractions (Python's
// fractions.Fraction, the normal equations of each line solved by hand):
// Release 4.0 (weights 1/mu^2): a0 = 2.671188551 DN, a1 = 97.56240378 DN/us, deviations -0.53235 ..
// +0.65737 .. -0.84793 %, LE = 0.752648785 %. Release 3 (unweighted): a0 = 6.6, a1 = 96.7, deviations
// -3.48500 (t = 1) .. +0.48970 (t = 5), LE = 1.987345570 %, 2.6 times Release 4.0's.
TEST(calib_gain_emva_le_compression)
{
    double t[10], mu[10], dev[10], a0, a1;
    for (int i = 0; i < 10; i++) {
        t[i] = i + 1;
        mu[i] = 100 * t[i] * (1 - 0.03 / 1000 * 100 * t[i]);
    }
    int nfit;
    double le = calib_gain_linearity_r4(t, mu, 10, 1100, 0.05, 0.95, &a1, &a0, &nfit, dev);
    CHECK(nfit == 10);
    CHECK_NEAR(a0, 2.6711885510625386, 1e-9);
    CHECK_NEAR(a1, 97.56240377975108, 1e-9);
    CHECK_NEAR(dev[0], -0.5323488048323481, 1e-9);
    CHECK_NEAR(dev[9], -0.8479266917753161, 1e-9);
    CHECK_NEAR(le, 0.7526487854088069, 1e-9);
    double le3 = calib_gain_linearity(t, mu, 10, 1100, 0.05, 0.95, &a1, &a0, NULL, NULL);
    CHECK_NEAR(a0, 6.6, 1e-9);
    CHECK_NEAR(a1, 96.7, 1e-9);
    CHECK_NEAR(le3, 1.987345570070553, 1e-9);
}

// ---------------------------------------------------------------------------
// The whole command on synthetic frames

// The synthetic camera: eta 0.6, K 0.5 DN/e-, dark noise 4 e-, offset 100 DN with a row pattern 1.5 sin(2 pi
// y / 12) and a column pattern 2 cos(2 pi 8 x / 64) (DN), pixel DSNU 0.8 DN, PRNU 1 %; 100 uW/cm^2 on 25 um^2
// at 550 nm; dark current 1e5 e-/s (24 e- at the longest exposure); Mono12 (clipped at 4095). Planted: hot (13, 7) +60 DN dark, dead (40, 30) gain 0.2, bright
// (5, 44) gain 1.5.
enum { FW = 64, FH = 48 };
static const double F_ETA = 0.6, F_K = 0.5, F_RN = 4, F_E = 100, F_A = 25, F_L = 550, F_DARK = 1e5;   // e-/s

static void frame_make(double t_us, bool dark, model_rng_t *r, const float *dsnu, const float *gain, uint16_t *pix)
{
    double mp = calib_gain_photons(F_E, F_A, F_L, t_us);
    for (int i = 0; i < FW * FH; i++) {
        double e = (dark ? 0 : F_ETA * mp * gain[i]) + F_DARK * t_us * 1e-6;
        e += sqrt(e) * model_rng_gauss(r) + F_RN * model_rng_gauss(r);
        double v = floor(dsnu[i] + F_K * e + 0.5);
        pix[i] = (uint16_t)(v < 0 ? 0 : v > 4095 ? 4095 : v);
    }
}

static const char *frames_manifest(void)
{
    const char *dir = test_path("frames");
    g_mkdir_with_parents(dir, 0755);
    float dsnu[FW * FH], gain[FW * FH];
    model_rng_t r = model_rng(2026, 0);
    for (int y = 0; y < FH; y++)
        for (int x = 0; x < FW; x++) {
            dsnu[y * FW + x] = (float)(100 + 1.5 * sin(2 * M_PI * y / 12) + 2 * cos(2 * M_PI * 8 * x / FW) +
                                       0.8 * model_rng_gauss(&r));
            gain[y * FW + x] = (float)(1 + 0.01 * model_rng_gauss(&r));
        }
    dsnu[7 * FW + 13] += 60;
    gain[30 * FW + 40] = 0.2f;
    gain[44 * FW + 5] = 1.5f;
    uint16_t pix[FW * FH];
    GString *m = g_string_new("file,exposure_us,kind\n");
    int k = 0;
    // the sweep: 24 steps to 240 us (saturation near 195 us), a light and a dark pair each; the spatial set:
    // 16 light (flat) and 16 dark (flat-dark) at 95 us
    for (int i = 0; i < 25; i++) {
        bool spatial = i == 24;
        double t = spatial ? 95 : 10.0 * (i + 1);
        for (int dark = 0; dark < 2; dark++)
            for (int rep = 0; rep < (spatial ? 16 : 2); rep++) {
                frame_make(t, dark, &r, dsnu, gain, pix);
                char name[32];
                snprintf(name, sizeof name, "f%04d.png", k++);
                char *path = g_build_filename(dir, name, NULL);
                CHECK(model_png16_write(path, FW, FH, pix, NULL));
                g_free(path);
                g_string_append_printf(m, "%s,%.3f,%s\n", name, t,
                                       spatial ? (dark ? "flat-dark" : "flat") : (dark ? "dark" : "light"));
            }
    }
    const char *mp = test_write("frames/manifest.csv", m->str);
    g_string_free(m, TRUE);
    return mp;
}

TEST(calib_gain_emva_frames)
{
    double t0 = model_now_s();
    const char *m = frames_manifest();
    const char *out = test_path("out");
    char *so = NULL, *se = NULL;
    int rc = test_refl_run(120, &so, &se, "calib", "gain", "--frames", m, "-o", out, "--no-report", "--max-dn",
                           "4095", "--min-steps", "20", "--irradiance", "100", "--pixel-pitch-um", "5",
                           "--wavelength-nm", "550", NULL);
    CHECK_MSG(rc == 0, "refl calib gain: %d\n%s", rc, se ? se : "");
    free(so);
    free(se);
    json_t *j = gain_json_load(out);
    if (!j) return;
    json_t *e = json_object_get(j, "emva1288");
    CHECK(!strcmp(json_string_value(json_object_get(e, "photon_axis")) ?: "", "measured"));
    double K = json_number_value(json_object_get(j, "system_gain_dn_per_e"));
    double qe = json_number_value(json_object_get(j, "quantum_efficiency"));
    fprintf(stderr, "  K %.4f (0.5), eta %.4f (0.6)\n", K, qe);
    CHECK_REL(K, F_K, 0.04);
    CHECK_REL(qe, F_ETA, 0.04);
    CHECK_REL(json_number_value(gain_sheet_value(j, "eta", "%")), 100 * qe, 1e-9);
    CHECK_REL(json_number_value(gain_sheet_value(j, "R", "DN/photon")), F_K * F_ETA, 0.01);
    // saturation: clipped at 4095 DN, 3995 DN above the offset: ~7990 e-, / eta photons
    double sat_e = json_number_value(gain_sheet_value(j, "mu_e.sat", "e-"));
    CHECK(sat_e > 7000 && sat_e < 8400);
    CHECK_REL(json_number_value(gain_sheet_value(j, "mu_p.sat", "photons")), sat_e / qe, 1e-9);
    // threshold: sigma_y.dark / K + 1/2, sigma_y.dark^2 = K^2 4^2 + 1/12 DN^2
    double se_min = 0.5 + sqrt((F_K * F_K * 16 + 1.0 / 12) / (F_K * F_K));
    CHECK_REL(json_number_value(gain_sheet_value(j, "mu_e.min", "e-")), se_min, 0.08);
    // dark current from the mean (K mu_I t) and from the variance (K^2 mu_I t)
    json_t *g0 = json_array_get(json_object_get(j, "gains"), 0);
    fprintf(stderr, "  dark current %.4g e-/s (mean), %.4g e-/s (variance), truth %.4g\n",
            json_number_value(json_object_get(g0, "dark_current_e_per_s")),
            json_number_value(json_object_get(g0, "dark_current_from_variance_e_per_s")), F_DARK);
    CHECK_REL(json_number_value(gain_sheet_value(j, "mu_I.mean", "e-/s")), F_DARK, 0.05);
    CHECK_REL(json_number_value(gain_sheet_value(j, "mu_I.var", "e-/s")), F_DARK, 0.15);
    // the spatial set (kind flat / flat-dark): 16 frames each, the DSNU's row and column parts
    json_t *ff = json_object_get(j, "flat_field");
    CHECK_NEAR(json_number_value(json_object_get(ff, "light_frames")), 16, 0);
    CHECK_NEAR(json_number_value(json_object_get(ff, "exposure_us")), 95, 1e-9);
    json_t *ds = json_object_get(json_object_get(e, "spatial"), "dsnu_dn");
    CHECK_REL(json_number_value(json_object_get(ds, "row")), 1.5 / sqrt(2), 0.1);
    CHECK_REL(json_number_value(json_object_get(ds, "column")), sqrt(2), 0.1);
    // the column pattern's peak in the horizontal dark spectrogram at 8 / 64 cycles per pixel
    json_t *hd = json_object_get(json_object_get(json_object_get(e, "spectrograms"), "horizontal"), "dark_dn");
    size_t kmax = 1;
    for (size_t k = 1; k < json_array_size(hd); k++)
        if (json_number_value(json_array_get(hd, k)) > json_number_value(json_array_get(hd, kmax))) kmax = k;
    CHECK(kmax == 8);
    // the defects at their coordinates
    json_t *df = json_object_get(e, "defects");
    CHECK(json_integer_value(json_object_get(df, "hot")) == 1);
    CHECK(json_integer_value(json_object_get(df, "dead")) == 1);
    CHECK(json_integer_value(json_object_get(df, "bright")) == 1);
    json_t *h = json_array_get(json_object_get(df, "hot_pixels"), 0), *d = json_array_get(json_object_get(df,
                                                                                                           "dead_pixels"), 0);
    CHECK(json_integer_value(json_array_get(h, 0)) == 13 && json_integer_value(json_array_get(h, 1)) == 7);
    CHECK(json_integer_value(json_array_get(d, 0)) == 40 && json_integer_value(json_array_get(d, 1)) == 30);
    int w = 0, hh = 0;
    char *tp = g_build_filename(out, "defects.tiff", NULL);
    float *map = model_image_read_float(tp, &w, &hh);
    g_free(tp);
    CHECK(map && w == FW && hh == FH);
    if (map) CHECK(map[7 * FW + 13] == 1 && map[30 * FW + 40] == 2 && map[44 * FW + 5] == 3);
    free(map);
    json_decref(j);
    // the same irradiance from a photodiode: 1000 nA at 0.5 A/W on 2 mm^2 = 100 uW/cm^2
    const char *out3 = test_path("out3");
    rc = test_refl_run(120, &so, &se, "calib", "gain", "--frames", m, "-o", out3, "--no-report", "--max-dn", "4095",
                       "--min-steps", "20", "--photodiode-na", "1000", "--photodiode-a-per-w", "0.5",
                       "--photodiode-mm2", "2", "--pixel-pitch-um", "5", "--wavelength-nm", "550", NULL);
    CHECK_MSG(rc == 0, "refl calib gain --photodiode-na: %d\n%s", rc, se ? se : "");
    free(so);
    free(se);
    j = gain_json_load(out3);
    if (!j) return;
    CHECK_REL(json_number_value(json_object_get(j, "quantum_efficiency")), qe, 1e-9);
    json_t *cond = json_object_get(json_object_get(j, "emva1288"), "conditions");
    CHECK_REL(json_number_value(json_object_get(cond, "irradiance_uw_cm2")), 100, 1e-12);
    CHECK(json_is_object(json_object_get(cond, "photodiode")));
    json_decref(j);
    fprintf(stderr, "  calib_gain_emva_frames: %.1f s\n", model_now_s() - t0);
}

// Without --irradiance: the photon figures "not measured"; the report and the datasheet page.
TEST(calib_gain_emva_not_measured_report)
{
    double t0 = model_now_s();
    const char *m = frames_manifest();
    char *so = NULL, *se = NULL;
    json_t *j;
    int rc;
    const char *out2 = test_path("out2");
    rc = test_refl_run(120, &so, &se, "calib", "gain", "--frames", m, "-o", out2, "--max-dn", "4095", "--min-steps",
                       "20", NULL);
    CHECK_MSG(rc == 0, "refl calib gain: %d\n%s", rc, se ? se : "");
    free(so);
    free(se);
    j = gain_json_load(out2);
    if (!j) return;
    CHECK(!strcmp(json_string_value(json_object_get(j, "quantum_efficiency")) ?: "", "not measured"));
    CHECK(!strcmp(json_string_value(gain_sheet_value(j, "mu_p.min", "photons")) ?: "", "not measured"));
    CHECK(json_is_number(gain_sheet_value(j, "mu_e.min", "e-")));
    json_decref(j);
    char *hp = g_build_filename(out2, "datasheet.html", NULL);
    char *html = model_read_file(hp, NULL);
    g_free(hp);
    CHECK(html != NULL);
    if (html) {
        CHECK_CONTAINS(html, "not measured");
        CHECK_CONTAINS(html, "quantum efficiency");
        CHECK_CONTAINS(html, "spectrogram_h.png");
    }
    free(html);
    const char *pngs[] = { "snr_photons.png", "spectrogram_h.png", "spectrogram_v.png", "profiles.png",
                           "log_histograms.png", "defect_map.png" };
    for (size_t i = 0; i < sizeof pngs / sizeof pngs[0]; i++) {
        char *p = g_build_filename(out2, pngs[i], NULL);
        CHECK_MSG(access(p, R_OK) == 0, "no %s", pngs[i]);
        g_free(p);
    }
    fprintf(stderr, "  calib_gain_emva_not_measured_report: %.1f s\n", model_now_s() - t0);
}
