// tests/test_calib_gain_descriptor.c — the standard's data exchange, the EMVA
// 1288 descriptor file (calib/gain/descriptor.c, exchange.c):
// calib_gain_descriptor_parse_grammar: a file with comments, blank lines, CRLF,
//   decimal commas, Windows and POSIX paths parsed into its sets; malformed
//   ones refused with file:line and what is wrong.
// calib_gain_descriptor_reader: `refl calib gain --emva-descriptor` on a file
//   this test writes (images in two directories, named with '\' and '/'):
//   the photon axis from its counts without an irradiance (eta of the
//   sensor), the per-area rows with --pixel-area-um2; a missing image, an
//   image of another size than the "n" line and an irradiance beside the
//   counts refused.
// calib_gain_descriptor_round_trip: frames of a manifest with an irradiance,
//   written out by --write-emva-descriptor and read back: the same datasheet.
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

// A linear sensor: eta 0.55, K 0.45 DN/e-, read noise 3 e-, offset 80 DN + 0.6 DN pixel DSNU, PRNU 1 %, 12 bits;
// 100 uW/cm^2 on 25 um^2 at 550 nm (69.2 photons per us).
enum { DW = 48, DH = 32, DP = DW * DH, DSTEPS = 24, DLSP = 8 };
static const double D_ETA = 0.55, D_K = 0.45, D_RN = 3;

static void dframe(double t_us, bool dark, model_rng_t *r, const float *pat, uint16_t *pix)
{
    double mp = calib_gain_photons(100, 25, 550, t_us);
    for (int i = 0; i < DP; i++) {
        double e = dark ? 0 : D_ETA * mp * pat[DP + i];
        e += sqrt(e) * model_rng_gauss(r) + D_RN * model_rng_gauss(r);
        double v = floor(pat[i] + D_K * e + 0.5);
        pix[i] = (uint16_t)(v < 0 ? 0 : v > 4095 ? 4095 : v);
    }
}

static double dstep_us(int i)
{
    return 10.0 * (i + 1);   // saturation near 215 us
}

// Writes frame k of the run into dir/sub/fNNNN.png; its name relative to dir into name.
static void dwrite(const char *dir, const char *sub, int k, const uint16_t *pix, char *name, size_t size)
{
    char *d = g_build_filename(dir, sub, NULL);
    g_mkdir_with_parents(d, 0755);
    snprintf(name, size, "%s/f%04d.png", sub, k);
    char *p = g_build_filename(dir, name, NULL);
    CHECK(model_png16_write(p, DW, DH, pix, NULL));
    g_free(p);
    g_free(d);
}

// The run's frames under dir; manifest (may be NULL) gets the manifest's lines, desc (may be NULL) a
// descriptor's (the sweep: pairs, the dark of each exposure first; the spatial set at 100 us), its paths with
// '\' in the even steps, '/' in the odd ones, images in "images" and "more".
static void dframes(const char *dir, GString *manifest, GString *desc)
{
    float *pat = malloc(sizeof(float) * DP * 2);
    model_rng_t r = model_rng(77, 2);
    for (int i = 0; i < DP; i++) {
        pat[i] = (float)(80 + 0.6 * model_rng_gauss(&r));
        pat[DP + i] = (float)(1 + 0.01 * model_rng_gauss(&r));
    }
    uint16_t pix[DP];
    int k = 0;
    if (manifest) g_string_append(manifest, "file,exposure_us,kind\n");
    if (desc) g_string_append(desc, "# written by the test\r\nv 4.0\r\n\r\nn 12 48 32\r\n");
    for (int s = 0; s <= DSTEPS; s++) {
        bool spatial = s == DSTEPS;
        double t = spatial ? 100 : dstep_us(s);
        for (int dark = 1; dark >= 0; dark--) {
            if (desc && dark) g_string_append_printf(desc, "d %.10g\n", t * 1000);
            if (desc && !dark) {   // photons with a decimal comma every third step
                char ph[64];
                snprintf(ph, sizeof ph, "%.10g", calib_gain_photons(100, 25, 550, t));
                if (s % 3 == 0)
                    for (char *c = ph; *c; c++)
                        if (*c == '.') *c = ',';
                g_string_append_printf(desc, "b %.10g %s\n", t * 1000, ph);
            }
            for (int rep = 0; rep < (spatial ? DLSP : 2); rep++) {
                char name[64];
                dframe(t, dark, &r, pat, pix);
                dwrite(dir, s % 2 ? "more" : "images", k++, pix, name, sizeof name);
                if (manifest)
                    g_string_append_printf(manifest, "%s,%.10g,%s\n", name, t,
                                           spatial ? (dark ? "flat-dark" : "flat") : (dark ? "dark" : "light"));
                if (desc) {
                    if (s % 2 == 0) *strchr(name, '/') = '\\';
                    g_string_append_printf(desc, "i %s%s\n", rep == 1 && s % 4 == 0 ? "\\" : "", name);
                }
            }
        }
    }
    free(pat);
}

TEST(calib_gain_descriptor_parse_grammar)
{
    const char *good = "# a comment\r\nv 4.0\r\n\r\n   n 12 64 48\r\n"
                       "d 1000\ni images\\d0.png\ni images/d1.png\n"
                       "b 1000 12,5\n\ti  \\sub\\b0.png\ni /abs/b1.png\n"
                       "x some future line\n"
                       "d 5e6\ni s0.tif\ni s1.tif\ni s2.tif\nb 5000000 7000\ni s3.tif\ni s4.tif\ni s5.tif";
    calib_gain_descriptor_t d;
    CHECK(calib_gain_descriptor_parse(good, strlen(good), "desc.txt", &d));
    CHECK(!strcmp(d.version, "4.0") && d.bits == 12 && d.width == 64 && d.height == 48 && d.n_line == 4);
    CHECK(d.nsets == 4 && d.npaths == 10);
    if (d.nsets == 4 && d.npaths == 10) {
        CHECK(d.sets[0].photons == 0 && d.sets[0].exposure_ns == 1000 && !d.sets[0].spatial && d.sets[0].line == 5);
        CHECK(d.sets[1].photons == 12.5 && d.sets[1].nimages == 2 && d.sets[1].line == 8);
        CHECK(d.sets[2].spatial && d.sets[3].spatial && d.sets[3].photons == 7000 && d.sets[2].exposure_ns == 5e6);
        CHECK(!strcmp(d.paths[0], "images/d0.png") && !strcmp(d.paths[1], "images/d1.png"));
        CHECK(!strcmp(d.paths[2], "sub/b0.png") && !strcmp(d.paths[3], "/abs/b1.png"));
        CHECK(d.path_line[2] == 9 && d.path_line[9] == 19);
    }
    calib_gain_descriptor_free(&d);
    static const struct {
        const char *text, *where, *what;
    } bad[] = {
        { "v 4.0\nn 12 64\n", "desc.txt:2:", "'n' takes three fields" },
        { "n 12 64 48\nn 12 64 48\n", "desc.txt:2:", "a second 'n' line (the first is line 1)" },
        { "n 40 64 48\n", "desc.txt:1:", "BITS '40' is not a whole number in 1..31" },
        { "b 1000 5\ni a.png\nd 1000\ni b.png\ni c.png\n", "desc.txt:1:", "at least two images" },
        { "i a.png\nd 1000\ni b.png\ni c.png\n", "desc.txt:1:", "outside a set" },
        { "d 1000\ni a.png b.png\ni c.png\n", "desc.txt:2:", "'i' takes one path" },
        { "d 1000\ni a\ni b\nb 1000 5\ni c\ni d\nb 1000 5\ni e\ni f\n", "desc.txt:7:",
          "a second temporal set at exposure 1000 ns and 5 photons (the first is at line 4)" },
        { "b -5 3\ni a\ni b\n", "desc.txt:1:", "the exposure (ns) must be a positive number" },
        { "d 1000\ni a\ni b\nb 1000 many\ni c\ni d\n", "desc.txt:4:", "the photons >= 0" },
        { "d 1000 5\ni a\ni b\n", "desc.txt:1:", "'d EXPOSURE_NS' (a dark set), found 2 fields" },
        { "b 1000 5\ni a\ni b\n", "desc.txt:1:", "exposure 1000 ns has no dark set" },
        { "d 1000\ni a\ni b\nb 1000 5\ni c\ni d\nd 2000\ni e\ni f\n", "desc.txt:7:", "has no bright set" },
        { "d 1000\ni a\ni b\nb 1000 5\ni c\ni d\nd 3000\ni e\ni f\ni g\nb 4000 9\ni h\ni j\ni k\n", "desc.txt:11:",
          "one dark and one bright at one exposure" },
        { "d 1000\ni a\ni b\nb 1000 5\ni c\ni d\nd 3000\ni e\ni f\ni g\n", "desc.txt:7:",
          "a spatial dark set without its bright one" },
        { "d 3000\ni e\ni f\ni g\nb 3000 9\ni h\ni j\ni k\n", "desc.txt:", "no bright temporal step" },
        { "v\n", "desc.txt:1:", "a line needs a key and a value" },
        { "d 1000\ni \\\\\ni b\n", "desc.txt:2:", "an empty path" },
    };
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        model_error_clear();
        CHECK_MSG(!calib_gain_descriptor_parse(bad[i].text, strlen(bad[i].text), "desc.txt", &d), "accepted: %s",
                  bad[i].text);
        CHECK_CONTAINS(model_last_error(), bad[i].where);
        CHECK_CONTAINS(model_last_error(), bad[i].what);
        CHECK(d.nsets == 0 && d.npaths == 0 && !d.sets && !d.paths);
    }
    // a NUL byte (the text need not end in one)
    const char nul[] = "d 1000\ni a\0b\ni c\n";
    CHECK(!calib_gain_descriptor_parse(nul, sizeof nul - 1, "desc.txt", &d));
    CHECK_CONTAINS(model_last_error(), "desc.txt:2: a NUL byte");
}

TEST(calib_gain_descriptor_reader)
{
    const char *dir = test_path("exchange");
    GString *desc = g_string_new("");
    dframes(dir, NULL, desc);
    char *dp = g_build_filename(dir, "EMVA1288descriptor.txt", NULL);
    CHECK(g_file_set_contents(dp, desc->str, -1, NULL));
    const char *out = test_path("out");
    char *so = NULL, *se = NULL;
    int rc = test_refl_run(180, &so, &se, "calib", "gain", "--emva-descriptor", dp, "-o", out, "--no-report",
                           "--min-steps", "20", "--pixel-area-um2", "25", NULL);
    CHECK_MSG(rc == 0, "refl calib gain --emva-descriptor: %d\n%s", rc, se ? se : "");
    free(so);
    free(se);
    json_t *j = gain_json_load(out);
    if (j) {
        json_t *e = json_object_get(j, "emva1288");
        CHECK(!strcmp(json_string_value(json_object_get(e, "photon_axis")) ?: "", "measured"));
        CHECK(!strcmp(json_string_value(json_object_get(json_object_get(e, "conditions"), "photon_source")) ?: "",
                      "descriptor"));
        double eta = json_number_value(gain_sheet_value(j, "eta", "%")) / 100, K = json_number_value(gain_sheet_value(j, "K", "DN/e-"));
        fprintf(stderr, "  from the descriptor: eta %.4f (%.2f), K %.4f DN/e- (%.2f)\n", eta, D_ETA, K, D_K);
        CHECK_REL(eta, D_ETA, 0.03);
        CHECK_REL(K, D_K, 0.03);
        // mu_p.sat is one of the descriptor's counts; the per-area rows divide by 25 um^2
        double psat = json_number_value(gain_sheet_value(j, "mu_p.sat", "photons"));
        bool found = false;
        for (int s = 0; s < DSTEPS; s++)   // gain.json's numbers have 10 digits
            found |= fabs(psat / calib_gain_photons(100, 25, 550, dstep_us(s)) - 1) < 1e-9;
        CHECK_MSG(found, "mu_p.sat %.10g is none of the steps' counts", psat);
        CHECK_REL(json_number_value(gain_sheet_value(j, "mu_p.sat.area", "photons/um^2")), psat / 25, 2e-9);
        CHECK_REL(json_number_value(gain_sheet_value(j, "mu_p.min.area", "photons/um^2")),
                  json_number_value(gain_sheet_value(j, "mu_p.min", "photons")) / 25, 2e-9);
        json_t *f = json_object_get(j, "flat_field");
        CHECK(json_integer_value(json_object_get(f, "light_frames")) == DLSP);
        json_decref(j);
    }
    // an irradiance beside the counts: a usage error
    rc = test_refl_run(60, &so, &se, "calib", "gain", "--emva-descriptor", dp, "-o", test_path("o2"), "--irradiance",
                       "5", "--pixel-area-um2", "25", "--wavelength-nm", "550", NULL);
    CHECK(rc == 2);
    CHECK_CONTAINS(se ? se : "", "--emva-descriptor gives each step's photon count");
    free(so);
    free(se);
    // a missing image: the descriptor's line
    GString *bad = g_string_new(desc->str);
    g_string_append(bad, "d 999000\ni images\\missing.png\ni more/f0001.png\nb 999000 1\ni more/f0002.png\n"
                         "i more/f0003.png\n");
    int lines = 0;
    for (const char *c = bad->str; *c; c++) lines += *c == '\n';
    char *bp = g_build_filename(dir, "bad.txt", NULL), where[64];
    CHECK(g_file_set_contents(bp, bad->str, -1, NULL));
    rc = test_refl_run(60, &so, &se, "calib", "gain", "--emva-descriptor", bp, "-o", test_path("o3"), NULL);
    snprintf(where, sizeof where, "bad.txt:%d:", lines - 4);
    CHECK(rc == 1);
    CHECK_CONTAINS(se ? se : "", where);
    CHECK_CONTAINS(se ? se : "", "missing.png");
    free(so);
    free(se);
    // images of another size than the "n" line
    char *nd = g_strdup(desc->str), *np = strstr(nd, "n 12 48 32");
    if (np) memcpy(np, "n 12 48 30", 10);
    CHECK(g_file_set_contents(bp, nd, -1, NULL));
    rc = test_refl_run(60, &so, &se, "calib", "gain", "--emva-descriptor", bp, "-o", test_path("o4"), NULL);
    CHECK(rc == 1);
    CHECK_CONTAINS(se ? se : "", "is 48x32 pixels, line 4 says 'n 12 48 30'");
    free(so);
    free(se);
    g_free(nd);
    g_free(bp);
    g_string_free(bad, TRUE);
    g_string_free(desc, TRUE);
    g_free(dp);
}

TEST(calib_gain_descriptor_round_trip)
{
    const char *dir = test_path("frames");
    GString *man = g_string_new("");
    dframes(dir, man, NULL);
    char *mp = g_build_filename(dir, "manifest.csv", NULL);
    CHECK(g_file_set_contents(mp, man->str, -1, NULL));
    const char *out1 = test_path("out1"), *out2 = test_path("out2");
    char *dp = g_build_filename(out1, "written", "descriptor.txt", NULL), *dd = g_path_get_dirname(dp);
    g_mkdir_with_parents(dd, 0755);
    char *so = NULL, *se = NULL;
    int rc = test_refl_run(180, &so, &se, "calib", "gain", "--frames", mp, "-o", out1, "--no-report", "--max-dn",
                           "4095", "--min-steps", "20", "--irradiance", "100", "--pixel-area-um2", "25",
                           "--wavelength-nm", "550", "--write-emva-descriptor", dp, NULL);
    CHECK_MSG(rc == 0, "refl calib gain --write-emva-descriptor: %d\n%s", rc, se ? se : "");
    free(so);
    free(se);
    size_t n = 0;
    char *text = model_read_file(dp, &n);
    CHECK(text != NULL);
    if (text) {
        calib_gain_descriptor_t d;
        CHECK(calib_gain_descriptor_parse(text, n, dp, &d));
        CHECK(!strcmp(d.version, "4.0") && d.bits == 12 && d.width == DW && d.height == DH);
        int temporal = 0, spatial = 0;
        for (int i = 0; i < d.nsets; i++) {
            temporal += !d.sets[i].spatial && d.sets[i].photons > 0;
            spatial += d.sets[i].spatial;
        }
        CHECK(temporal == DSTEPS && spatial == 2);
        for (int i = 0; i < d.npaths; i++) CHECK_MSG(!strncmp(d.paths[i], "../../frames/", 13), "%s", d.paths[i]);
        calib_gain_descriptor_free(&d);
    }
    free(text);
    // read back, and written again beside the frames (paths below the file's directory)
    char *inside = g_build_filename(dir, "inside.txt", NULL);
    rc = test_refl_run(180, &so, &se, "calib", "gain", "--emva-descriptor", dp, "-o", out2, "--no-report",
                       "--min-steps", "20", "--pixel-area-um2", "25", "--wavelength-nm", "550",
                       "--write-emva-descriptor", inside, NULL);
    CHECK_MSG(rc == 0, "refl calib gain --emva-descriptor (written): %d\n%s", rc, se ? se : "");
    free(so);
    free(se);
    text = model_read_file(inside, &n);
    CHECK(text != NULL);
    if (text) {
        calib_gain_descriptor_t d;
        CHECK(calib_gain_descriptor_parse(text, n, inside, &d));
        CHECK(d.npaths == DSTEPS * 4 + 2 * DLSP);
        for (int i = 0; i < d.npaths; i++)
            CHECK_MSG(!strncmp(d.paths[i], "images/f", 8) || !strncmp(d.paths[i], "more/f", 6), "%s", d.paths[i]);
        calib_gain_descriptor_free(&d);
    }
    free(text);
    g_free(inside);
    json_t *a = gain_json_load(out1), *b = gain_json_load(out2);
    if (a && b) {
        json_t *ra = json_object_get(json_object_get(a, "emva1288"), "datasheet");
        int compared = 0;
        double worst = 0;
        for (size_t i = 0; i < json_array_size(ra); i++) {
            json_t *r = json_array_get(ra, i);
            const char *sym = json_string_value(json_object_get(r, "symbol")),
                       *unit = json_string_value(json_object_get(r, "unit"));
            json_t *va = json_object_get(r, "value"), *vb = gain_sheet_value(b, sym, unit);
            CHECK_MSG(vb != NULL, "%s (%s) missing after the round trip", sym, unit);
            if (!json_is_number(va) || !json_is_number(vb)) {
                CHECK_MSG(json_equal(va, vb), "%s (%s) differs after the round trip", sym, unit);
                continue;
            }
            double x = json_number_value(va), y = json_number_value(vb);
            double rel = fabs(x - y) / fmax(fabs(x), 1e-9);
            worst = fmax(worst, rel);
            CHECK_MSG(rel < 2e-9, "%s (%s): %.12g, after the round trip %.12g", sym, unit, x, y);   // 10 digits each
            compared++;
        }
        fprintf(stderr, "  round trip: %d rows, largest relative difference %.2g\n", compared, worst);
        CHECK(compared >= 30);
    }
    json_decref(a);
    json_decref(b);
    // without a photon axis nothing to write
    rc = test_refl_run(60, &so, &se, "calib", "gain", "--frames", mp, "-o", test_path("o5"),
                       "--write-emva-descriptor", dp, NULL);
    CHECK(rc == 2);
    CHECK_CONTAINS(se ? se : "", "--write-emva-descriptor needs each step's photon count");
    free(so);
    free(se);
    g_free(dd);
    g_free(dp);
    g_free(mp);
    g_string_free(man, TRUE);
}
