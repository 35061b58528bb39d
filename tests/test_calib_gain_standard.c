// tests/test_calib_gain_standard.c — EMVA 1288 Release 4.0 Linear by the
// standard's definitions (calib/gain/standard.c, nonuniformity.c): every
// datasheet row of `refl calib gain` against an independent, direct
// implementation of the definitions here (the reference implementation's
// formulas re-derived: photon transfer through the origin over the steps up
// to 70 % of saturation, the saturation walk, sigma^2_y.dark's line, the
// threshold, the weighted linearity line, the stacks' spatial variances and
// their row/column/pixel split) on frames this test makes and keeps in
// memory:
// calib_gain_standard_rows: a sensor with a slightly curved photon transfer
//   (a compression S (1 - a S)): every row within 1e-9 of the definitions,
//   the parts' variances adding up to the totals, and the small-signal
//   quadratic K (refl's) at least 2 % from the standard's.
// calib_gain_standard_known_answers: a linear sensor with a full well: every
//   row against the sensor's own K, eta, read noise, dark current, full
//   well, DSNU and PRNU parts.
// calib_gain_standard_variances: the stacks' split on patterns of known
//   variance, the identity of the parts, a negative estimate reported as a
//   negative value (not 0).
#define _GNU_SOURCE
#include <glib.h>
#include <jansson.h>
#include <stdint.h>
#include <stdlib.h>

#include "calib/gain/gain.h"
#include "model/model.h"
#include "model/base/vec.h"
#include "tests/gain_json.h"
#include "tests/test.h"

// The sensor: eta 0.6, K 0.5 DN/e-, read noise 4 e-, dark current 3e4 e-/s, a compression S_m = S (1 - a S)
// with a 1e-5 per DN (LE about 1 %); offset 100 DN with row and column patterns and pixel DSNU; PRNU 1 % pixel and 0.6 %
// column; 128 x 96 pixels, 12 bits. Light: 100 uW/cm^2 on 25 um^2 at 550 nm.
enum { W = 128, H = 96, P = W * H, NSTEP = 60, LSP = 12 };
static const double S_ETA = 0.6, S_K = 0.5, S_RN = 4, S_DC = 3e4, S_A = 1e-5, S_E = 100, S_AREA = 25, S_L = 550;
static const double SPATIAL_US = 100;

// Photons per pixel during t_us (written out here: A E t lambda / (h c)).
static double photons(double t_us)
{
    return S_AREA * 1e-12 * S_E * 1e-2 * t_us * 1e-6 * S_L * 1e-9 / (6.62607015e-34 * 299792458.0);
}

typedef struct {
    float    dsnu[P], gain[P];
    uint16_t light[NSTEP][2][P], dark[NSTEP][2][P], slight[LSP][P], sdark[LSP][P];
} frames_t;

// The sensor's response: the compression a (per DN) and the full well (e-, the photo-electrons with their shot
// noise clipped to it; 0: none, the 12 bits clip).
typedef struct {
    double a, fw_e;
} response_t;

static void frame(const frames_t *F, response_t rs, double t_us, bool dark, model_rng_t *r, uint16_t *pix)
{
    double mp = photons(t_us);
    for (int i = 0; i < P; i++) {
        double e = (dark ? 0 : S_ETA * mp * F->gain[i]) + S_DC * t_us * 1e-6;
        e += sqrt(e) * model_rng_gauss(r);
        if (rs.fw_e > 0 && e > rs.fw_e) e = rs.fw_e;
        e += S_RN * model_rng_gauss(r);
        double S = S_K * e, v = floor(F->dsnu[i] + S * (1 - rs.a * S) + 0.5);
        pix[i] = (uint16_t)(v < 0 ? 0 : v > 4095 ? 4095 : v);
    }
}

static double step_us(int i)
{
    return 4.0 * (i + 1);   // saturation near 200 us
}

// The frames, written as PNGs with their manifest (the sweep: a light and a dark pair per exposure; the
// spatial set: LSP light and LSP dark frames at SPATIAL_US); returns the manifest's path.
static const char *make_frames(frames_t *F, response_t rs)
{
    const char *dir = test_path("frames");
    g_mkdir_with_parents(dir, 0755);
    model_rng_t r = model_rng(1288, 4);
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++) {
            F->dsnu[y * W + x] = (float)(100 + 1.2 * sin(2 * M_PI * y / 10) + 1.8 * cos(2 * M_PI * 5 * x / W) +
                                         0.7 * model_rng_gauss(&r));
            F->gain[y * W + x] = (float)(1 + 0.01 * model_rng_gauss(&r) + 0.006 * sin(2 * M_PI * x / 7));
        }
    GString *m = g_string_new("file,exposure_us,kind\n");
    int k = 0;
    for (int s = 0; s <= NSTEP; s++)
        for (int dark = 0; dark < 2; dark++)
            for (int rep = 0; rep < (s == NSTEP ? LSP : 2); rep++) {
                uint16_t *pix = s == NSTEP ? (dark ? F->sdark[rep] : F->slight[rep])
                                           : (dark ? F->dark[s][rep] : F->light[s][rep]);
                double t = s == NSTEP ? SPATIAL_US : step_us(s);
                frame(F, rs, t, dark, &r, pix);
                char name[32];
                snprintf(name, sizeof name, "f%04d.png", k++);
                char *path = g_build_filename(dir, name, NULL);
                CHECK(model_png16_write(path, W, H, pix, NULL));
                g_free(path);
                g_string_append_printf(m, "%s,%.6g,%s\n", name, t, s == NSTEP ? (dark ? "flat-dark" : "flat")
                                                                             : (dark ? "dark" : "light"));
            }
    const char *mp = test_write("frames/manifest.csv", m->str);
    g_string_free(m, TRUE);
    return mp;
}

// ---------------------------------------------------------------------------
// The definitions, implemented here directly

// Mean and var(A - B) / 2 of a pair (the temporal variance of EMVA 1288).
static void pair_stats(const uint16_t *a, const uint16_t *b, double *mean, double *var)
{
    double s = 0, d = 0, dd = 0;
    for (int i = 0; i < P; i++) {
        s += (double)a[i] + b[i];
        double v = (double)a[i] - b[i];
        d += v;
        dd += v * v;
    }
    *mean = s / (2.0 * P);
    *var = 0.5 * (dd / P - (d / P) * (d / P));
}

// Least squares y = c0 + c1 x with weights w (NULL: 1) by its 2 x 2 normal equations.
static void wls(const double *x, const double *y, const double *w, int n, double *c0, double *c1)
{
    double s0 = 0, s1 = 0, s2 = 0, t0 = 0, t1 = 0;
    for (int i = 0; i < n; i++) {
        double wi = w ? w[i] : 1;
        s0 += wi;
        s1 += wi * x[i];
        s2 += wi * x[i] * x[i];
        t0 += wi * y[i];
        t1 += wi * x[i] * y[i];
    }
    double det = s0 * s2 - s1 * s1;
    *c0 = (t0 * s2 - s1 * t1) / det;
    *c1 = (s0 * t1 - s1 * t0) / det;
}

typedef struct {
    double mean, s2, s2_row, s2_col, s2_pixel;
} split_t;

// One stack of L frames: its average's spatial variance less its temporal part, and the parts.
static split_t stack_split(uint16_t (*f)[P], int L)
{
    double *avg = calloc(P, sizeof(double)), tv = 0, mean = 0;
    for (int i = 0; i < P; i++) {
        for (int l = 0; l < L; l++) avg[i] += f[l][i];
        avg[i] /= L;
        double v = 0;
        for (int l = 0; l < L; l++) v += (f[l][i] - avg[i]) * (f[l][i] - avg[i]);
        tv += v / (L - 1);
        mean += avg[i];
    }
    tv /= P;
    mean /= P;
    double sm = 0, rav = 0, cav = 0;
    for (int i = 0; i < P; i++) sm += (avg[i] - mean) * (avg[i] - mean);
    sm /= P - 1;
    for (int y = 0; y < H; y++) {   // M = H rows, each mean over N = W columns
        double r = 0;
        for (int x = 0; x < W; x++) r += avg[y * W + x];
        rav += (r / W - mean) * (r / W - mean);
    }
    for (int x = 0; x < W; x++) {
        double c = 0;
        for (int y = 0; y < H; y++) c += avg[y * W + x];
        cav += (c / H - mean) * (c / H - mean);
    }
    free(avg);
    const double M = H, N = W, MN = M * N, D = MN - M - N;
    double s2 = sm - tv / L, s_rav = rav / M - tv / (L * N), s_cav = cav / N - tv / (L * M);
    return (split_t){ mean, s2, (MN - N) / D * s_rav - M / D * (s2 - s_cav), (MN - M) / D * s_cav - N / D * (s2 - s_rav),
                      MN / D * (s2 - s_cav - s_rav) };
}

static double sroot(double v)
{
    return v < 0 ? -sqrt(-v) : sqrt(v);
}

typedef struct {
    const char *symbol, *unit;
    double      value;
} want_t;

// The datasheet's rows, computed here: *n of them into w.
static void definitions(frames_t *F, want_t *w, int *n)
{
    double x[NSTEP], Y[NSTEP], V[NSTEP], vy[NSTEP], t[NSTEP], md[NSTEP], vd[NSTEP];
    for (int i = 0; i < NSTEP; i++) {
        double my, mdk;
        pair_stats(F->light[i][0], F->light[i][1], &my, &vy[i]);
        pair_stats(F->dark[i][0], F->dark[i][1], &mdk, &vd[i]);
        t[i] = step_us(i);
        x[i] = photons(t[i]);
        md[i] = mdk;
        Y[i] = my - mdk;
        V[i] = vy[i] - vd[i];
    }
    // saturation: from the brightest step back while the variance has not fallen on both sides
    int is = NSTEP - 1;
    double best = vy[is];
    for (int i = NSTEP - 2; i >= 0; i--) {
        double before = vy[i > 0 ? i - 1 : 1];
        if (vy[i] < best && before < best) break;
        best = vy[i];
        is = i;
    }
    int top = 0;   // a walk ending below half the largest variance: the largest
    for (int i = 1; i < NSTEP; i++)
        if (vy[i] > vy[top]) top = i;
    if (vy[is] < 0.5 * vy[top]) is = top;
    int last = 0;
    for (int i = 0; i < NSTEP; i++)
        if (Y[i] <= 0.7 * Y[is]) last = i;
    double sxy = 0, sxx = 0, rxy = 0, rxx = 0;
    for (int i = 0; i <= last; i++) {
        sxy += Y[i] * V[i];
        sxx += Y[i] * Y[i];
        rxy += x[i] * Y[i];
        rxx += x[i] * x[i];
    }
    const double K = sxy / sxx, R = rxy / rxx, eta = R / K;
    double c0, c1;
    wls(t, vd, NULL, NSTEP, &c0, &c1);
    const double vdark = fmax(c0, 0.24), sdark = sqrt(vdark), dc_var = c1 * 1e6 / (K * K);
    wls(t, md, NULL, NSTEP, &c0, &c1);
    const double dc = c1 * 1e6 / K;
    const double emin = sdark / K + 0.5, esat = eta * x[is];
    // linearity: the first step >= 5 % .. the last <= 95 % of Y at saturation, weights 1 / Y^2
    int lo = -1, hi = 0;
    for (int i = 0; i < NSTEP; i++) {
        if (lo < 0 && Y[i] >= 0.05 * Y[is]) lo = i;
        if (Y[i] <= 0.95 * Y[is]) hi = i;
    }
    double wt[NSTEP], a0, a1, dmin = INFINITY, dmax = -INFINITY;
    for (int i = lo; i <= hi; i++) wt[i] = 1 / (Y[i] * Y[i]);
    wls(x + lo, Y + lo, wt + lo, hi - lo + 1, &a0, &a1);
    for (int i = lo; i <= hi; i++) {
        double d = 100 * (Y[i] - (a0 + a1 * x[i])) / (a0 + a1 * x[i]);
        dmin = fmin(dmin, d);
        dmax = fmax(dmax, d);
    }
    split_t dk = stack_split(F->sdark, LSP), lt = stack_split(F->slight, LSP);
    const double sig = lt.mean - dk.mean;
    const want_t rows[] = {
        { "K", "DN/e-", K }, { "1/K", "e-/DN", 1 / K }, { "R", "DN/photon", R }, { "eta", "%", 100 * eta },
        { "sigma_d", "e-", sqrt(vdark - 1.0 / 12) / K }, { "sigma_y.dark", "DN", sdark },
        { "mu_e.min", "e-", emin }, { "mu_p.min", "photons", emin / eta }, { "mu_p.sat", "photons", x[is] },
        { "mu_e.sat", "e-", esat }, { "SNR_max", "1", sqrt(esat) }, { "SNR_max", "dB", 20 * log10(sqrt(esat)) },
        { "DR", "1", esat / emin }, { "DR", "dB", 20 * log10(esat / emin) }, { "LE", "%", (dmax - dmin) / 2 },
        { "LE_min", "%", dmin }, { "LE_max", "%", dmax }, { "mu_I.mean", "e-/s", dc }, { "mu_I.var", "e-/s", dc_var },
        { "DSNU1288", "e-", sroot(dk.s2) / K }, { "DSNU1288.row", "e-", sroot(dk.s2_row) / K },
        { "DSNU1288.col", "e-", sroot(dk.s2_col) / K }, { "DSNU1288.pixel", "e-", sroot(dk.s2_pixel) / K },
        { "DSNU1288", "DN", sroot(dk.s2) }, { "PRNU1288", "%", 100 * sroot(lt.s2 - dk.s2) / sig },
        { "PRNU1288.row", "%", 100 * sroot(lt.s2_row - dk.s2_row) / sig },
        { "PRNU1288.col", "%", 100 * sroot(lt.s2_col - dk.s2_col) / sig },
        { "PRNU1288.pixel", "%", 100 * sroot(lt.s2_pixel - dk.s2_pixel) / sig },
    };
    *n = (int)(sizeof rows / sizeof rows[0]);
    memcpy(w, rows, sizeof rows);
    fprintf(stderr, "  definitions: K %.6f DN/e- over %d steps, saturation step %d (%.1f DN), eta %.5f, sigma_d %.4f "
            "e-, mu_e.sat %.1f e-, LE %.4f %%, DSNU %.4f e-, PRNU %.4f %%\n", K, last + 1, is, Y[is], eta,
            sqrt(vdark - 1.0 / 12) / K, esat, (dmax - dmin) / 2, sroot(dk.s2) / K, 100 * sroot(lt.s2 - dk.s2) / sig);
}

TEST(calib_gain_standard_rows)
{
    frames_t *F = calloc(1, sizeof *F);
    const char *m = make_frames(F, (response_t){ S_A, 0 });
    const char *out = test_path("out");
    char *so = NULL, *se = NULL;
    int rc = test_refl_run(180, &so, &se, "calib", "gain", "--frames", m, "-o", out, "--no-report", "--max-dn",
                           "4095", "--min-steps", "20", "--irradiance", "100", "--pixel-pitch-um", "5",
                           "--wavelength-nm", "550", NULL);
    CHECK_MSG(rc == 0, "refl calib gain: %d\n%s", rc, se ? se : "");
    free(so);
    free(se);
    char *jp = g_build_filename(out, "gain.json", NULL);
    json_t *j = json_load_file(jp, 0, NULL);
    g_free(jp);
    CHECK(j != NULL);
    if (!j) {
        free(F);
        return;
    }
    CHECK(json_integer_value(json_object_get(j, "version")) == CALIB_GAIN_FORMAT_VERSION);
    json_t *e = json_object_get(j, "emva1288"), *rows = json_object_get(e, "datasheet");
    want_t w[64];
    int n = 0;
    definitions(F, w, &n);
    double worst = 0;
    for (int i = 0; i < n; i++) {
        json_t *r = gain_row(rows, w[i].symbol, w[i].unit);
        CHECK_MSG(r != NULL, "no datasheet row %s (%s)", w[i].symbol, w[i].unit);
        if (!r) continue;
        double v = json_number_value(json_object_get(r, "value"));
        double rel = fabs(v - w[i].value) / fmax(fabs(w[i].value), 1e-6);
        worst = fmax(worst, rel);
        CHECK_MSG(rel < 1e-9, "%s (%s): refl %.12g, the definition %.12g", w[i].symbol, w[i].unit, v,
                  w[i].value);   // gain.json holds 10 digits
        CHECK_MSG(json_is_string(json_object_get(r, "section")), "%s: no section", w[i].symbol);
        CHECK_MSG((w[i].value < 0) == json_is_true(json_object_get(r, "negative_estimate")) ||
                  !strstr(w[i].symbol, "NU1288"), "%s: negative_estimate flag", w[i].symbol);
    }
    fprintf(stderr, "  %d rows, largest relative difference from the definitions %.2g\n", n, worst);
    // the parts' variances add up to the totals
    json_t *sp = json_object_get(e, "spatial");
    for (int k = 0; k < 2; k++) {
        json_t *v = json_object_get(sp, k ? "prnu_variance_dn2" : "dsnu_variance_dn2");
        double tot = json_number_value(json_object_get(v, "total"));
        double sum = json_number_value(json_object_get(v, "row")) + json_number_value(json_object_get(v, "column")) +
                     json_number_value(json_object_get(v, "pixel"));
        CHECK_MSG(fabs(sum - tot) < 1e-9 * fabs(tot), "%s: parts %.12g, total %.12g", k ? "PRNU" : "DSNU", sum, tot);
    }
    // the curved photon transfer: refl's small-signal quadratic K (top level) at least 2 % above the standard's
    double K0 = json_number_value(json_object_get(j, "system_gain_dn_per_e"));
    double K = json_number_value(json_object_get(gain_row(rows, "K", "DN/e-"), "value"));
    fprintf(stderr, "  standard K %.5f DN/e-, refl's small-signal K %.5f DN/e- (%+.2f %%), the sensor's %.3f\n", K, K0,
            100 * (K0 / K - 1), S_K);
    CHECK(K0 / K - 1 >= 0.02);
    CHECK_REL(K0, S_K, 0.04);
    // refl's own figures: labelled so, never among the standard's rows
    json_t *rr = json_object_get(e, "refl_rows");
    CHECK_REL(json_number_value(json_object_get(gain_row(rr, "K_0", "DN/e-"), "value")), K0, 1e-12);
    CHECK(gain_row(rows, "K_0", "DN/e-") == NULL && gain_row(rows, "PRNU_hp", "%") == NULL);
    CHECK(gain_row(rr, "PRNU_hp", "%") != NULL && gain_row(rr, "LE_lin", "%") != NULL);
    json_decref(j);
    free(F);
}

// Patterns of known variance through calib_gain_stack_variances: a row pattern of variance 2.25 (+-1.5 by
// rows), a column pattern of 4 (+-2 by column pairs), an exact pixel pattern (zero row and column sums) of 1
// (+-1 checkerboard), no temporal noise (two equal frames): each figure by hand from the patterns' variances and
// the definitions' divisors; a pixel pattern alone with a temporal part (sigma^2_stack / L 0.5) gives negative row
// and column estimates, reported as negative values.
TEST(calib_gain_standard_variances)
{
    enum { SW = 40, SH = 30 };
    double *img = malloc(sizeof(double) * SW * SH);
    for (int y = 0; y < SH; y++)
        for (int x = 0; x < SW; x++)
            img[y * SW + x] = 50 + (y % 2 ? 1.5 : -1.5) + ((x / 2) % 2 ? 2 : -2) + ((x + y) % 2 ? 1 : -1);
    calib_gain_stack_var_t v;
    CHECK(calib_gain_stack_variances(img, SW, SH, NULL, 2, 0, &v));
    // s2 (divisor MN - 1) = 7.25 MN / (MN - 1); the row means +-1.5: 2.25; the column means +-2: 4
    const double MN = SW * SH, M = SH, N = SW, D = MN - M - N, s2 = 7.25 * MN / (MN - 1);
    CHECK_NEAR(v.s2, s2, 1e-12);
    CHECK_NEAR(v.s2_rav, 2.25, 1e-12);
    CHECK_NEAR(v.s2_cav, 4, 1e-12);
    CHECK_NEAR(v.s2_pixel, MN / D * (s2 - 6.25), 1e-12);
    CHECK_NEAR(v.s2_row, (MN - N) / D * 2.25 - M / D * (s2 - 4), 1e-12);
    CHECK_NEAR(v.s2_col, (MN - M) / D * 4 - N / D * (s2 - 2.25), 1e-12);
    CHECK_NEAR(v.s2_row + v.s2_col + v.s2_pixel, v.s2, 1e-12);
    // a pixel pattern alone and a temporal variance left in the average: the row and column estimates negative
    for (int y = 0; y < SH; y++)
        for (int x = 0; x < SW; x++) img[y * SW + x] = 50 + ((x + y) % 2 ? 1 : -1);
    CHECK(calib_gain_stack_variances(img, SW, SH, NULL, 4, 2, &v));
    CHECK(v.s2_row < 0 && v.s2_col < 0 && v.s2_pixel > 0);
    CHECK_NEAR(v.s2_row + v.s2_col + v.s2_pixel, v.s2, 1e-12);
    calib_gain_nonuni_t nu = { .dark = v, .light = v };
    nu.light.mean += 100;
    nu.light.s2_row += 0.5 * v.s2_row;   // a light stack whose row part is below the dark's: negative PRNU row
    calib_gain_nonuniformity(&nu);
    CHECK(nu.dsnu_dn[1] < 0);
    CHECK_NEAR(nu.dsnu_dn[1], -sqrt(-v.s2_row), 1e-12);
    CHECK_NEAR(nu.dsnu_var_dn2[1], v.s2_row, 1e-15);
    CHECK_NEAR(nu.prnu_pct[1], 100 * -sqrt(-0.5 * v.s2_row) / 100, 1e-12);
    CHECK(calib_gain_signed_sqrt(-4) == -2 && calib_gain_signed_sqrt(9) == 3 && isnan(calib_gain_signed_sqrt(NAN)));
    free(img);
}

// The variance (divisor n) of n values v[i * stride].
static double var_of(const double *v, int n, int stride)
{
    double m = 0, s = 0;
    for (int i = 0; i < n; i++) m += v[i * stride];
    m /= n;
    for (int i = 0; i < n; i++) s += (v[i * stride] - m) * (v[i * stride] - m);
    return s / n;
}

// The sensor's own figures (the truth of this test's frames): its DSNU's and PRNU's parts from the patterns it
// was made of (row 1.2 sin(2 pi y / 10), column 1.8 cos(2 pi 5 x / W), pixel the rest; gain column 0.006 sin(2 pi
// x / 7), pixel the rest, no row part): the pixel part the variance of the rest; the row and column parts the
// variances of the pattern's own row and column means less the pixel part's share in them (its variance over the
// W or H pixels averaged), as this instance of the patterns holds them (a random pixel pattern's row means
// correlate with the row pattern by chance).
typedef struct {
    double dsnu_dn[4], prnu_pct[4];   // total, row, column, pixel
} truth_nu_t;

static truth_nu_t nonuniformity_truth(const frames_t *F)
{
    double *dp = malloc(sizeof(double) * P * 4), *gp = dp + P, *d = dp + 2 * P, *g = dp + 3 * P, rw[H], cl[W], gc[W];
    for (int y = 0; y < H; y++) rw[y] = 1.2 * sin(2 * M_PI * y / 10);
    for (int x = 0; x < W; x++) {
        cl[x] = 1.8 * cos(2 * M_PI * 5 * x / W);
        gc[x] = 0.006 * sin(2 * M_PI * x / 7);
    }
    double gm = 0, rm[H] = { 0 }, cm[W] = { 0 }, gcm[W] = { 0 };
    for (int i = 0; i < P; i++) gm += F->gain[i] / P;
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++) {
            rm[y] += F->dsnu[y * W + x] / W;
            cm[x] += F->dsnu[y * W + x] / H;
            gcm[x] += F->gain[y * W + x] / gm / H;
        }
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++) {
            int i = y * W + x;
            d[i] = F->dsnu[i];
            g[i] = F->gain[i] / gm;
            dp[i] = F->dsnu[i] - 100 - rw[y] - cl[x];
            gp[i] = F->gain[i] - 1 - gc[x];
        }
    truth_nu_t t;
    t.dsnu_dn[0] = sqrt(var_of(d, P, 1) * P / (P - 1.0));
    const double vp = var_of(dp, P, 1), gvp = var_of(gp, P, 1) / (gm * gm);
    t.dsnu_dn[1] = sqrt(var_of(rm, H, 1) - vp / W);
    t.dsnu_dn[2] = sqrt(var_of(cm, W, 1) - vp / H);
    t.dsnu_dn[3] = sqrt(vp);
    t.prnu_pct[0] = 100 * sqrt(var_of(g, P, 1) * P / (P - 1.0));
    t.prnu_pct[1] = 0;
    t.prnu_pct[2] = 100 * sqrt(var_of(gcm, W, 1) - gvp / H);
    t.prnu_pct[3] = 100 * sqrt(gvp);
    free(dp);
    return t;
}

static double row_value(json_t *rows, const char *symbol, const char *unit)
{
    json_t *r = gain_row(rows, symbol, unit);
    CHECK_MSG(r != NULL, "no datasheet row %s (%s)", symbol, unit);
    return r ? json_number_value(json_object_get(r, "value")) : NAN;
}

// Known answers: a linear sensor (no compression) whose photo-electrons clip at a full well of 7000 e- (3500 DN
// above the offset, below the 12 bits' end): every standard row against the sensor's own K 0.5 DN/e-, eta 0.6,
// read noise 4 e-, dark current 3e4 e-/s, full well, DSNU and PRNU parts. The tolerances are several times each
// figure's statistical scatter on these frames (K: 30 steps of 12,288 pixel pairs, about 0.3 %; the spatial
// totals from 12-frame stacks, about 0.4 %); the saturation capacity is the standard's (the step where the
// variance peaks, below the well by the spread of the pixels' charge there, and by up to one step of 166 e-).
TEST(calib_gain_standard_known_answers)
{
    const double FW = 7000;
    frames_t *F = calloc(1, sizeof *F);
    const char *m = make_frames(F, (response_t){ 0, FW });
    const char *out = test_path("out");
    char *so = NULL, *se = NULL;
    int rc = test_refl_run(180, &so, &se, "calib", "gain", "--frames", m, "-o", out, "--no-report", "--max-dn",
                           "4095", "--min-steps", "20", "--irradiance", "100", "--pixel-pitch-um", "5",
                           "--wavelength-nm", "550", NULL);
    CHECK_MSG(rc == 0, "refl calib gain: %d\n%s", rc, se ? se : "");
    free(so);
    free(se);
    char *jp = g_build_filename(out, "gain.json", NULL);
    json_t *j = json_load_file(jp, 0, NULL);
    g_free(jp);
    CHECK(j != NULL);
    if (!j) {
        free(F);
        return;
    }
    json_t *rows = json_object_get(json_object_get(j, "emva1288"), "datasheet");
    const double K = row_value(rows, "K", "DN/e-"), eta = row_value(rows, "eta", "%") / 100;
    const double sd = row_value(rows, "sigma_d", "e-"), esat = row_value(rows, "mu_e.sat", "e-");
    const double le = row_value(rows, "LE", "%"), dc = row_value(rows, "mu_I.mean", "e-/s");
    const double dcv = row_value(rows, "mu_I.var", "e-/s"), emin = row_value(rows, "mu_e.min", "e-");
    fprintf(stderr, "  K %.5f DN/e- (0.5), eta %.4f (0.6), sigma_d %.4f e- (4), mu_e.sat %.0f e- (full well %.0f), "
            "LE %.3f %%, dark current %.4g / %.4g e-/s (3e4)\n", K, eta, sd, esat, FW, le, dc, dcv);
    CHECK_REL(K, S_K, 0.02);
    CHECK_REL(row_value(rows, "1/K", "e-/DN"), 1 / S_K, 0.02);
    CHECK_REL(eta, S_ETA, 0.02);
    CHECK_REL(row_value(rows, "R", "DN/photon"), S_K * S_ETA, 0.01);
    CHECK_REL(sd, S_RN, 0.02);
    // sigma_y.dark^2 = K^2 sigma_d^2 + q^2 / 12 (the noise dithers the quantisation)
    CHECK_REL(row_value(rows, "sigma_y.dark", "DN"), sqrt(S_K * S_K * S_RN * S_RN + 1.0 / 12), 0.02);
    CHECK_REL(emin, sqrt(S_RN * S_RN + 1.0 / 12 / (S_K * S_K)) + 0.5, 0.02);
    // the standard's saturation, the step where the temporal variance peaks: below the well by one to three
    // times the spread of the pixels' charge there (shot noise 84 e-, PRNU 1.09 % of 7000 e- 76 e-: 113 e-) and
    // by up to one step (166 e-) more, never above it by more than a step
    CHECK(esat > FW - 3 * 113 - 166 && esat < FW + 166);
    // past the full well only the dark noise is left: the walk from the brightest step ends on that plateau
    json_t *fit = json_object_get(json_object_get(j, "emva1288"), "photon_transfer");
    CHECK_MSG(json_is_true(json_object_get(fit, "saturation_past_full_well_plateau")), "no plateau flag in %s",
              json_dumps(fit, JSON_COMPACT) ?: "");
    CHECK_REL(row_value(rows, "SNR_max", "1"), sqrt(esat), 1e-9);
    CHECK_REL(row_value(rows, "DR", "1"), esat / emin, 1e-9);
    CHECK_REL(row_value(rows, "mu_p.sat", "photons"), esat / eta, 1e-9);
    CHECK(le >= 0 && le < 0.25);
    CHECK_REL(dc, S_DC, 0.03);
    CHECK_REL(dcv, S_DC, 0.15);
    truth_nu_t t = nonuniformity_truth(F);
    static const char *part[4] = { "", ".row", ".col", ".pixel" };
    for (int k = 0; k < 4; k++) {
        char sym[32];
        snprintf(sym, sizeof sym, "DSNU1288%s", part[k]);
        double v = row_value(rows, sym, "e-");
        fprintf(stderr, "  %-15s %.4f e- (the pattern's %.4f)\n", sym, v, t.dsnu_dn[k] / S_K);
        CHECK_REL(v, t.dsnu_dn[k] / S_K, 0.03);
    }
    CHECK_REL(row_value(rows, "DSNU1288", "DN"), t.dsnu_dn[0], 0.03);
    for (int k = 0; k < 4; k++) {
        char sym[32];
        snprintf(sym, sizeof sym, "PRNU1288%s", part[k]);
        double v = row_value(rows, sym, "%");
        fprintf(stderr, "  %-15s %.4f %% (the pattern's %.4f)\n", sym, v, t.prnu_pct[k]);
        if (k == 1)   // no row pattern: an estimate near 0, of either sign (pixel variance leaking into 128-pixel
                      // row means, about 0.03 %)
            CHECK(fabs(v) < 0.1);
        else
            CHECK_REL(v, t.prnu_pct[k], 0.03);
    }
    json_decref(j);
    free(F);
}
