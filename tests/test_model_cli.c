// tests/test_model_cli.c — `refl render` and `refl edges` end to end (bin/refl on the examples).
#define _GNU_SOURCE
#include <glib.h>
#include <jansson.h>
#include <stdarg.h>
#include <stdlib.h>
#include <unistd.h>

#include "model/model.h"
#include "tests/test.h"

// Path of an example file (static buffer per call slot).
static const char *ex(const char *name)
{
    static char bufs[8][1024];
    static int slot;
    char *b = bufs[slot++ % 8];
    snprintf(b, 1024, "%s/examples/%s", test_srcdir(), name);
    return b;
}

#define refl(out, err, ...) test_refl_run(60, out, err, __VA_ARGS__)

static int count_of(const char *hay, const char *needle)
{
    int n = 0;
    for (const char *p = hay; p && (p = strstr(p, needle)); p += strlen(needle)) n++;
    return n;
}

#define BASE_ARGS ex("t_stiffener.d3d"), "--camera-model", ex("camera.cameramodel"), "--lamps-file", ex("lamps.ini"), \
                  "--materials", ex("materials.ini"), "--threads", "2"

static bool file_contains(const char *path, const char *needle)
{
    size_t len;
    char *buf = model_read_file(path, &len);
    if (!buf) return false;
    bool found = memmem(buf, len, needle, strlen(needle)) != NULL;
    free(buf);
    return found;
}

TEST(cli_render_png_and_provenance)
{
    char *out = NULL, *err = NULL;
    const char *png = test_path("t.png");
    int rc = refl(&out, &err, "render", BASE_ARGS, "-o", png, NULL);
    CHECK_MSG(rc == 0, "exit %d, stderr: %s", rc, err);
    CHECK_CONTAINS(out, "1280 x 1024");
    CHECK_CONTAINS(out, "background");
    CHECK_CONTAINS(out, png);
    int w = 0, h = 0;
    uint16_t *pix = NULL;
    CHECK(model_png_read(png, &w, &h, &pix));
    CHECK(w == 1280 && h == 1024);
    if (pix && w == 1280 && h == 1024) {
        long nbright = 0;
        for (int i = 0; i < w * h; i++) nbright += pix[i] >= 500;
        // the workpiece covers about a fifth of the image, mostly 500..3000 DN
        CHECK(nbright > w * h / 10 && nbright < w * h / 2);
        CHECK(pix[0] == 0);   // corner: background, offset 0
    }
    free(pix);
    // Provenance: each input's sha256, units, the pixel convention and the command line.
    char sha[65];
    CHECK(model_sha256_file(ex("t_stiffener.d3d"), sha));
    CHECK(file_contains(png, sha));
    CHECK(model_sha256_file(ex("materials.ini"), sha));
    CHECK(file_contains(png, sha));
    CHECK(file_contains(png, "P: grey value, DN"));
    CHECK(file_contains(png, "centre of the top-left pixel"));
    CHECK(file_contains(png, "--threads 2"));
    CHECK(file_contains(png, REFL_VERSION));
    free(out);
    free(err);
}

TEST(cli_render_tiff_info_and_offset)
{
    char *out = NULL, *err = NULL;
    const char *tif = test_path("t.tiff"), *info = test_path("info.tif"), *png = test_path("t.png");
    int rc = refl(&out, &err, "render", BASE_ARGS, "--offset", "12.25", "--kc", "0.5", "-o", tif, "--info", info, NULL);
    CHECK_MSG(rc == 0, "exit %d, stderr: %s", rc, err);
    free(out);
    free(err);
    rc = refl(&out, &err, "render", BASE_ARGS, "--offset", "12.25", "--kc", "0.5", "-o", png, NULL);
    CHECK(rc == 0);
    int w = 0, h = 0, wi = 0, hi = 0, wp = 0, hp = 0;
    float *P = NULL, *Pi = NULL;
    uint16_t *pix = NULL;
    CHECK(model_tiff_read_float(tif, &w, &h, &P));
    CHECK(model_tiff_read_float(info, &wi, &hi, &Pi));   // page 0 of the info TIFF: P
    CHECK(model_png_read(png, &wp, &hp, &pix));
    CHECK(w == 1280 && h == 1024 && wi == w && hi == h && wp == w && hp == h);
    if (P && Pi && pix && w == wi && h == hi && w == wp && h == hp) {
        int nbad_info = 0, nbad_png = 0, nbg = 0;
        for (int i = 0; i < w * h; i++) {
            if (P[i] != Pi[i]) nbad_info++;
            if (fabs(pix[i] - P[i]) > 0.5 + 1e-3) nbad_png++;
            if (P[i] == 12.25f) nbg++;
        }
        CHECK(nbad_info == 0);
        CHECK(nbad_png == 0);              // the PNG is the TIFF rounded
        CHECK(nbg > w * h / 2);            // background pixels get exactly Pa
    }
    CHECK(file_contains(tif, "float32 TIFF"));
    CHECK(file_contains(info, "face id"));
    free(P);
    free(Pi);
    free(pix);
    free(out);
    free(err);
}

TEST(cli_render_mc_with_sensor)
{
    char *out = NULL, *err = NULL;
    const char *png = test_path("mc.png");
    int rc = refl(&out, &err, "render", BASE_ARGS, "--interreflection", "mc", "--mc-samples", "1", "--mc-bounces", "1",
                  "--sensor", ex("sensor.ini"), "--seed", "7", "-o", png, NULL);
    CHECK_MSG(rc == 0, "exit %d, stderr: %s", rc, err);
    CHECK_CONTAINS(out, "sensor stage applied");
    int w = 0, h = 0;
    uint16_t *pix = NULL;
    CHECK(model_png_read(png, &w, &h, &pix));
    if (pix) {
        int maxv = 0;
        double bg = 0;
        for (int i = 0; i < w * h; i++) maxv = pix[i] > maxv ? pix[i] : maxv;
        for (int y = 0; y < 10; y++)
            for (int x = 0; x < 10; x++) bg += pix[y * w + x];
        CHECK(maxv <= 4095);               // 12-bit sensor
        CHECK_NEAR(bg / 100, 64, 6);       // background: the sensor's dark level, 64 DN
    }
    CHECK(file_contains(png, "interreflection=mc"));
    char sha[65];
    CHECK(model_sha256_file(ex("sensor.ini"), sha));
    CHECK(file_contains(png, sha));
    free(pix);
    free(out);
    free(err);
}

TEST(cli_edges_json)
{
    char *out = NULL, *err = NULL;
    const char *js = test_path("edges.json");
    // the old spellings --camera, --lamps: they work and each names its new one once (--threads 0: all cores)
    int rc = refl(&out, &err, "edges", ex("t_stiffener.d3d"), "--camera", ex("camera.cameramodel"), "--lamps",
                  ex("lamps.ini"), "--materials", ex("materials.ini"), "--threads", "0", "--json", js, NULL);
    CHECK_MSG(rc == 0, "exit %d, stderr: %s", rc, err);
    CHECK_MSG(count_of(err, "--camera CAM.cameramodel: the option is --camera-model (the old spelling still "
                       "works)") == 1, "%s", err);
    CHECK_MSG(count_of(err, "--lamps LAMPS.ini: the option is --lamps-file") == 1, "%s", err);
    CHECK_MSG(count_of(err, "the old spelling") == 2, "%s", err);
    CHECK_CONTAINS(out, "segments");
    json_error_t jerr;
    json_t *root = json_load_file(js, 0, &jerr);
    CHECK_MSG(root != NULL, "%s: %s", js, jerr.text);
    if (root) {
        CHECK(!strcmp(json_string_value(json_object_get(root, "format")) ?: "", "refl-edges"));
        CHECK(json_integer_value(json_object_get(root, "version")) == 1);
        json_t *edges = json_object_get(root, "edges");
        CHECK(json_is_array(edges));
        // plate 12 edges, web 4 vertical + 4 bottom + 4 top boundary, flange 12
        CHECK(json_array_size(edges) == 36);
        int nseg = 0;
        size_t i;
        json_t *e;
        json_array_foreach(edges, i, e) {
            json_t *segs = json_object_get(e, "segments");
            size_t j;
            json_t *s;
            json_array_foreach(segs, j, s) {
                nseg++;
                CHECK(json_is_number(json_object_get(s, "contrast_dn")));
                CHECK(json_array_size(json_object_get(s, "q0_px")) == 2);
                CHECK(json_array_size(json_object_get(s, "lit_side")) == 2);
            }
        }
        CHECK(nseg >= 15);
        CHECK(json_is_string(json_object_get(json_object_get(root, "units"), "P_side_dn, contrast_dn")));
        json_t *inputs = json_object_get(json_object_get(root, "provenance"), "inputs");
        char sha[65];
        CHECK(model_sha256_file(ex("t_stiffener.d3d"), sha));
        CHECK(json_is_array(inputs) && json_array_size(inputs) == 4);
        if (json_array_size(inputs) >= 1)
            CHECK(!strcmp(json_string_value(json_object_get(json_array_get(inputs, 0), "sha256")) ?: "", sha));
        json_decref(root);
    }
    free(out);
    free(err);
}

// Runs refl with args, expects exit code `want` and `needle` in stderr.
static void expect_error(int want, const char *needle, const char *const *args)
{
    const char *argv[64];
    int n = 0;
    argv[n++] = test_refl();
    for (; *args && n < 63; args++) argv[n++] = *args;
    argv[n] = NULL;
    char *out = NULL, *err = NULL;
    int rc = test_run(argv, 60, &out, &err);
    CHECK_MSG(rc == want, "exit %d (want %d) for '%s ...', stderr: %s", rc, want, needle, err);
    CHECK_CONTAINS(err, needle);
    free(out);
    free(err);
}

TEST(cli_usage_errors)
{
    const char *o = test_path("x.png");
    const char *unknown[] = { "render", BASE_ARGS, "-o", o, "--bogus", "1", NULL };
    expect_error(2, "unknown option '--bogus'", unknown);
    const char *nocam[] = { "render", ex("t_stiffener.d3d"), "--lamps-file", ex("lamps.ini"), "--materials",
                            ex("materials.ini"), "-o", o, NULL };
    expect_error(2, "missing required option --camera-model", nocam);
    const char *badir[] = { "render", BASE_ARGS, "-o", o, "--interreflection", "twice", NULL };
    expect_error(2, "unknown value 'twice'", badir);
    const char *badnum[] = { "render", BASE_ARGS, "-o", o, "--kc", "1.5x", NULL };
    expect_error(2, "--kc: '1.5x' is not a number", badnum);
    const char *noval[] = { "render", BASE_ARGS, "-o", NULL };
    expect_error(2, "option -o needs a value", noval);
    const char *badext[] = { "render", BASE_ARGS, "-o", test_path("x.jpg"), NULL };
    expect_error(2, "must end in .png, .tif or .tiff", badext);
    const char *neg[] = { "render", BASE_ARGS, "-o", o, "--mc-samples", "0", NULL };
    expect_error(2, "--mc-samples: 0 is out of range", neg);
    const char *twice[] = { "edges", BASE_ARGS, "--kc", "1", "--kc", "2", NULL };
    expect_error(2, "--kc given twice", twice);
    const char *edges_unknown[] = { "edges", BASE_ARGS, "-o", o, NULL };
    expect_error(2, "unknown option '-o'", edges_unknown);

    char *out = NULL, *err = NULL;
    const char *help[] = { test_refl(), "render", "--help", NULL };
    CHECK(test_run(help, 10, &out, &err) == 0);
    CHECK_CONTAINS(out, "usage: refl render SCENE");
    CHECK_CONTAINS(out, "--interreflection");
    free(out);
    free(err);
}

// Every command's --help (every page scripts/make-man makes, and refl --help)
// ends with the exit status every refl command shares: 0 done, 1 error,
// 2 usage, 3 paused, 4 an incorrect verdict under --fail-on-incorrect.
TEST(cli_help_lists_exit_status)
{
    char *man = NULL;
    char path[2048];
    snprintf(path, sizeof path, "%s/scripts/make-man", test_srcdir());
    CHECK(g_file_get_contents(path, &man, NULL, NULL));
    GRegex *re = g_regex_new("^\\s+\\(\"([a-z ]+)\",", G_REGEX_MULTILINE, 0, NULL);
    GMatchInfo *mi = NULL;
    int pages = 0;
    for (g_regex_match(re, man, 0, &mi); g_match_info_matches(mi); g_match_info_next(mi, NULL), pages++) {
        char *words = g_match_info_fetch(mi, 1);
        char **w = g_strsplit(words, " ", -1);
        const char *argv[6] = { test_refl() };
        int n = 1;
        for (int k = 0; w[k] && n < 4; k++) argv[n++] = w[k];
        argv[n++] = "--help";
        argv[n] = NULL;
        char *out = NULL, *err = NULL;
        int rc = test_run(argv, 30, &out, &err);
        CHECK_MSG(rc == 0, "refl %s --help: rc %d: %s", words, rc, err);
        CHECK_MSG(strstr(out, "exit status") && strstr(out, "  0  done") && strstr(out, "  2  a usage error") &&
                      strstr(out, "  3  paused") && strstr(out, "  4  refl verify --fail-on-incorrect"),
                  "refl %s --help lists no exit status:\n%s", words, out);
        free(out);
        free(err);
        g_strfreev(w);
        g_free(words);
    }
    g_match_info_free(mi);
    g_regex_unref(re);
    g_free(man);
    CHECK_MSG(pages >= 25, "%d pages in scripts/make-man", pages);
    char *out = NULL, *err = NULL;
    const char *top[] = { test_refl(), "--help", NULL };
    CHECK(test_run(top, 10, &out, &err) == 0);
    CHECK_CONTAINS(out, "  4  refl verify --fail-on-incorrect");
    free(out);
    free(err);
}

// Help texts say what the commands do: every option of verify described, its
// formats; options a command refuses are not in its help.
TEST(cli_help_matches_behaviour)
{
    char *out = NULL, *err = NULL;
    CHECK(refl(&out, &err, "verify", "--help", NULL) == 0);
    CHECK_CONTAINS(out, "D3D, OBJ, STL or PLY");
    static const char *const described[] = { "--z-flag Z", "--min-region N", "--score-threshold T", "--edge-rel R",
                                             "--interreflection-samples N" };
    for (size_t k = 0; k < sizeof described / sizeof described[0]; k++) {
        const char *at = out ? strstr(out, described[k]) : NULL;
        CHECK_MSG(at, "%s not in verify --help", described[k]);
        // the description is more than a default in parentheses
        if (at) {
            at += strlen(described[k]);
            while (*at == ' ' || *at == '\n') at++;
            CHECK_MSG(*at != '(', "%s has no description: %.40s", described[k], at);
        }
    }
    CHECK_CONTAINS(out, "exit 4 when the verdict is incorrect");
    free(out);
    free(err);
    CHECK(refl(&out, &err, "calib", "white", "--help", NULL) == 0);
    CHECK(out && !strstr(out, "--albedo-cells"));
    free(out);
    free(err);
    CHECK(refl(&out, &err, "fit", "material", "--help", NULL) == 0);
    CHECK(out && !strstr(out, "--albedo A") && strstr(out, "--albedo-cells MM"));
    free(out);
    free(err);
    CHECK(refl(&out, &err, "calib", "white", "s", "--albedo-cells", "2", NULL) == 2);
    CHECK_CONTAINS(err, "unknown option '--albedo-cells'");
    free(out);
    free(err);
    CHECK(refl(&out, &err, "fit", "material", "s", "--albedo", "0.9", NULL) == 2);
    CHECK_CONTAINS(err, "unknown option '--albedo'");
    free(out);
    free(err);
    // --no-priors names what --priors still gives
    CHECK(refl(&out, &err, "verify", ex("t_stiffener.d3d"), "--images", ex("t_stiffener.d3d"), "--no-priors",
               "-o", test_path("v"), NULL) == 2);
    CHECK_CONTAINS(err, "with --no-priors too: the materials' models and starting values");
    free(out);
    free(err);
}

// refl workpiece -o OUT.d3d; the old spelling, OUT.d3d as the argument, still
// works and names -o once; both at once is a usage error.
TEST(cli_workpiece_out)
{
    char *out = NULL, *err = NULL;
    const char *a = test_path("a.d3d"), *b = test_path("b.d3d");
    CHECK(refl(&out, &err, "workpiece", "-o", a, "--kind", "I", NULL) == 0);
    CHECK(err && !strstr(err, "old spelling"));
    CHECK(access(a, F_OK) == 0);
    free(out);
    free(err);
    CHECK(refl(&out, &err, "workpiece", b, "--kind", "I", NULL) == 0);
    CHECK_MSG(count_of(err, "OUT.d3d as an argument: the option is -o, --out (the old spelling still works)") == 1,
              "%s", err);
    CHECK(access(b, F_OK) == 0);
    free(out);
    free(err);
    char *ta = NULL, *tb = NULL;
    CHECK(g_file_get_contents(a, &ta, NULL, NULL) && g_file_get_contents(b, &tb, NULL, NULL) && !strcmp(ta, tb));
    g_free(ta);
    g_free(tb);
    CHECK(refl(&out, &err, "workpiece", b, "-o", a, NULL) == 2);
    CHECK_CONTAINS(err, "-o");
    free(out);
    free(err);
    CHECK(refl(&out, &err, "workpiece", "--kind", "I", NULL) == 2);
    CHECK_CONTAINS(err, "missing -o OUT.d3d");
    free(out);
    free(err);
}

TEST(cli_runtime_errors)
{
    const char *o = test_path("x.png");
    const char *missing = test_path("no_such_scene.d3d");
    const char *noscene[] = { "render", missing, "--camera-model", ex("camera.cameramodel"), "--lamps-file", ex("lamps.ini"),
                              "--materials", ex("materials.ini"), "-o", o, NULL };
    expect_error(1, missing, noscene);

    // Malformed materials: the message names file and line.
    const char *bad = test_write("bad_mats.ini", "[material plywood]\nmodel = lambert\nkd = zero\n");
    const char *badmats[] = { "render", ex("t_stiffener.d3d"), "--camera-model", ex("camera.cameramodel"), "--lamps-file",
                              ex("lamps.ini"), "--materials", bad, "-o", o, NULL };
    expect_error(1, "bad_mats.ini:3", badmats);

    // A material the scene needs is missing from the file.
    const char *few = test_write("few_mats.ini", "[material plywood]\nmodel = lambert\nkd = 0.2\n");
    const char *fewmats[] = { "render", ex("t_stiffener.d3d"), "--camera-model", ex("camera.cameramodel"), "--lamps-file",
                              ex("lamps.ini"), "--materials", few, "-o", o, NULL };
    expect_error(1, "painted_steel", fewmats);

    // A non-planar face (vertex 4 lifted by 2 mm).
    const char *warped = test_write("warped.d3d", "1 0 0 0\n2 100 0 0\n3 100 100 0\n4 0 100 2\nFaces:\n1 2 3 4.\n");
    const char *nonplanar[] = { "render", warped, "--camera-model", ex("camera.cameramodel"), "--lamps-file", ex("lamps.ini"),
                                "--materials", ex("materials.ini"), "-o", o, NULL };
    expect_error(1, "not planar", nonplanar);
    // ... accepted with a larger tolerance
    char *out = NULL, *err = NULL;
    const char *tol[] = { test_refl(), "render", warped, "--camera-model", ex("camera.cameramodel"), "--lamps-file", ex("lamps.ini"),
                          "--materials", ex("materials.ini"), "-o", o, "--planarity-tol-mm", "1", "--threads", "2",
                          NULL };
    int rc = test_run(tol, 60, &out, &err);
    CHECK_MSG(rc == 0, "exit %d, stderr %s", rc, err);
    free(out);
    free(err);

    // A gain map of the wrong size.
    float g[12];
    for (int i = 0; i < 12; i++) g[i] = 1;
    const char *gain = test_path("gain_4x3.tiff");
    CHECK(model_tiff_write_float(gain, 4, 3, g, NULL));
    const char *badgain[] = { "render", BASE_ARGS, "-o", o, "--gain-map", gain, NULL };
    expect_error(1, "gain map is 4 x 3 pixels but the camera", badgain);
}

TEST(cli_render_gain_map_and_turntable)
{
    // P = Pa + kc * g * S: with g = 0.5 on the left half and 1.5 on the right,
    // (P_g - Pa) / (P - Pa) is g wherever the workpiece is.
    const int W = 1280, H = 1024;
    float *g = malloc(sizeof(float) * W * H);
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++) g[y * W + x] = x < W / 2 ? 0.5f : 1.5f;
    const char *gain = test_path("gain.tiff"), *ref = test_path("ref.tiff"), *gp = test_path("g.tiff");
    CHECK(model_tiff_write_float(gain, W, H, g, NULL));
    char *out = NULL, *err = NULL;
    int rc = refl(&out, &err, "render", BASE_ARGS, "--offset", "10", "-o", ref, NULL);
    CHECK(rc == 0);
    free(out);
    free(err);
    rc = refl(&out, &err, "render", BASE_ARGS, "--offset", "10", "--gain-map", gain, "-o", gp, NULL);
    CHECK_MSG(rc == 0, "exit %d: %s", rc, err);
    free(out);
    free(err);
    float *P = NULL, *Pg = NULL;
    int w = 0, h = 0, w2 = 0, h2 = 0;
    CHECK(model_tiff_read_float(ref, &w, &h, &P));
    CHECK(model_tiff_read_float(gp, &w2, &h2, &Pg));
    if (P && Pg && w == W && h == H && w2 == W && h2 == H) {
        int n = 0, nbad = 0;
        for (int i = 0; i < W * H; i++)
            if (P[i] > 100) {
                n++;
                double ratio = (Pg[i] - 10) / (P[i] - 10);
                if (fabs(ratio - g[i]) > 1e-4) nbad++;
            }
        CHECK(n > W * H / 10);
        CHECK(nbad == 0);
    }
    CHECK(file_contains(gp, "gain_map="));
    char sha[65];
    CHECK(model_sha256_file(gain, sha));
    CHECK(file_contains(gp, sha));
    free(Pg);
    Pg = NULL;

    // Turntable: the plate with its T-stiffener is symmetric under a half turn
    // about z, so at 180 deg the image is the same; at 90 deg it is not (the
    // lamps and the camera stay where they are).
    const char *t180 = test_path("t180.tiff"), *t90 = test_path("t90.tiff");
    rc = refl(&out, &err, "render", BASE_ARGS, "--offset", "10", "--turntable-deg", "180", "-o", t180, NULL);
    CHECK_MSG(rc == 0, "exit %d: %s", rc, err);
    // the old spelling works and names the new one, once
    CHECK_MSG(count_of(err, "--turntable-deg A: the option is --angle-deg (the old spelling still works)") == 1,
              "%s", err);
    free(out);
    free(err);
    rc = refl(&out, &err, "render", BASE_ARGS, "--offset", "10", "--angle-deg", "90", "-o", t90, NULL);
    CHECK_MSG(rc == 0, "exit %d: %s", rc, err);
    free(out);
    free(err);
    float *P90 = NULL;
    CHECK(model_tiff_read_float(t180, &w2, &h2, &Pg));
    CHECK(model_tiff_read_float(t90, &w2, &h2, &P90));
    if (P && Pg && P90 && w == w2 && h == h2) {
        long nfg = 0, ndiff90 = 0, ndiff = 0;
        for (int i = 0; i < W * H; i++) {
            nfg += P[i] != 10.0f;
            ndiff += fabs(P[i] - Pg[i]) > 1;
            ndiff90 += fabs(P[i] - P90[i]) > 1;
        }
        CHECK_MSG(ndiff < nfg / 1000, "%ld of %ld pixels differ after a half turn", ndiff, nfg);
        CHECK_MSG(ndiff90 > nfg / 5, "%ld of %ld pixels differ after a quarter turn", ndiff90, nfg);
    }
    CHECK(file_contains(t90, "turntable_deg=90"));
    free(P90);
    free(P);
    free(Pg);
    free(g);
}
