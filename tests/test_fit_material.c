// tests/test_fit_material.c — the offline chain on the virtual rig (fixed
// seeds): a reference-white session gives kc*I per lamp (checked against the
// truth's kc_per_us * I), a glossy coupon on a 40 degree wedge turned through
// the lamps gives BRDF samples, and the fit recovers the truth's GGX
// material (kd within 5 %, alpha within 10 %, F0 within 10 % and 2 std: the
// rim lamp's highlight at v.h = cos 55 deg separates it from ks). The calibrations
// here are the truth's camera model and lamp positions (the calibrations'
// own accuracy is tested in test_calib_*); the sessions record the
// calibrations in use (refl capture --calib); bad calibration directories and
// sessions give errors naming the file.
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include <glib.h>
#include <jansson.h>
#include <sqlite3.h>

#include "model/model.h"
#include "rig/rig.h"
#include "tests/test.h"

// test_path/test_write reuse 8 buffers: keep copies.
static char *keep(const char *p) { return g_strdup(p); }

static char *srcdir(void)
{
    char *r = realpath(test_srcdir(), NULL);
    return r ? r : g_strdup(".");
}

static char *calib_dir(void)
{
    char src[4096];
    char *sd = srcdir();
    snprintf(src, sizeof src, "%s/examples/camera.cameramodel", sd);
    free(sd);
    char *cam = model_read_file(src, NULL);
    char *dir = keep(test_path("cal"));
    g_mkdir_with_parents(dir, 0755);
    test_write("cal/camera.cameramodel", cam);
    free(cam);
    test_write("cal/lamps.json",
               "{\"lamps\": [{\"name\": \"east\", \"position_mm\": [488.6, 177.9, 600], \"radius_mm\": 15},"
               " {\"name\": \"south\", \"position_mm\": [-52.3, -597.7, 480], \"radius_mm\": 15},"
               " {\"name\": \"west\", \"position_mm\": [-526.2, -191.5, 520], \"radius_mm\": 15},"
               " {\"name\": \"north\", \"position_mm\": [98.4, 367.1, 700], \"radius_mm\": 15},"
               " {\"name\": \"rim\", \"position_mm\": [-619.8, 65.1, 219.6], \"radius_mm\": 15}]}\n");
    return dir;
}

// The scene of a sample of the truth file (a session records none: refl
// calib white and refl fit material are told it with --scene).
static char *sample_scene(const char *sample)
{
    char *sd = srcdir(), *p = g_strdup_printf("%s/examples/samples/%s.d3d", sd, sample);
    free(sd);
    return p;
}

static char *rig_file(void)
{
    char text[4200];
    char *sd = srcdir();
    snprintf(text, sizeof text, "[rig]\nbackend = virtual\ntruth = %s/examples/virtual-truth.ini\nserve = inprocess\n"
             "time_scale = 0.005\npixel_format = Mono12\n", sd);
    free(sd);
    return keep(test_write("rig.ini", text));
}


static void check_choice(json_t *m, const char *sample);

TEST_LONG(fit_material_chain_virtual_rig)
{
    char *rig = rig_file(), *cal = calib_dir();
    char *wsc = sample_scene("reference_white"), *gsc = sample_scene("coupon_glossy_plastic");
    char *white = keep(test_write("white.ini", "[plan]\nname = white\n[sample]\nname = reference_white\n"
                                                "kind = reference_white\n[angles]\nlist = 0 120 240\n[lamps]\n"
                                                "sets = east; south; west; north; rim; none\n[exposure]\nmode = fixed\n"
                                                "list_us = 8000\n"));
    char *glossy = keep(test_write("glossy.ini", "[plan]\nname = glossy\n[sample]\nname = coupon_glossy_plastic\n"
                                                  "kind = material_coupon\ntilt_deg = 40\n[angles]\nrange = 0 340 20\n"
                                                  "[lamps]\nsets = east; south; west; north; rim; none\n[exposure]\n"
                                                  "mode = fixed\nlist_us = 8000 500\n"));
    char *out = NULL, *err = NULL;
    char *ws = keep(test_path("w")), *gs = keep(test_path("g"));
    int rc = test_refl_run(300, &out, &err, "capture", "--yes", white, "--rig", rig, "-o", ws, "--progress", "lines",
                           "--calib", cal, NULL);
    CHECK_MSG(rc == 0, "%s", err);
    g_free(out);
    g_free(err);
    // the session records the calibrations in use by path and hash
    rig_journal_t *j = NULL;
    CHECK(rig_journal_open(&j, ws) == 0);
    char *facts = NULL;
    if (j && rig_journal_facts(j, &facts) == 0) {
        char sha[65], lp[4200];
        snprintf(lp, sizeof lp, "%s/lamps.json", cal);
        CHECK(model_sha256_file(lp, sha));
        CHECK_CONTAINS(facts, "lamp positions");
        CHECK_CONTAINS(facts, "camera geometry");
        CHECK_CONTAINS(facts, sha);
    }
    free(facts);
    rig_journal_close(j);
    rc = test_refl_run(60, &out, &err, "capture", "--yes", white, "--rig", rig, "-o", test_path("w2"), "--calib",
                       test_tmpdir(), NULL);
    CHECK(rc == 1);
    CHECK_CONTAINS(err, "no calibration files there");
    g_free(out);
    g_free(err);
    char wj[4200];
    snprintf(wj, sizeof wj, "%s/white.json", cal);
    rc = test_refl_run(300, &out, &err, "calib", "white", ws, "--calib", cal, "--scene", wsc, "-o", wj,
                       NULL);
    CHECK_MSG(rc == 0, "%s", err);
    g_free(out);
    g_free(err);
    // kc*I against the truth: kc_per_us 1e-4 times the lamps' intensities
    // (the flat field is not corrected here: vignetting costs ~1 %)
    json_error_t je;
    json_t *w = json_load_file(wj, 0, &je);
    CHECK(w != NULL);
    const double truth[5] = { 3.2e5, 2.9e5, 3.1e5, 3.6e5, 2.6e5 };
    for (int l = 0; w && l < 5; l++) {
        json_t *e = json_array_get(json_object_get(w, "lamps"), l);
        double v = json_number_value(json_object_get(e, "kc_I_per_us"));
        CHECK_MSG(fabs(v / truth[l] - 1) < 0.02, "lamp %d: kc*I %.6g vs truth %.6g", l, v, truth[l]);
    }
    json_decref(w);

    rc = test_refl_run(300, &out, &err, "capture", "--yes", glossy, "--rig", rig, "-o", gs, "--progress", "lines", NULL);
    CHECK_MSG(rc == 0, "%s", err);
    g_free(out);
    g_free(err);
    char *pj = keep(test_path("priors.json"));
    char *rep = keep(test_path("report"));
    rc = test_refl_run(300, &out, &err, "fit", "material", gs, "--scene", gsc, "--calib", cal, "--model", "all",
                       "-o", pj, "--report", rep, NULL);
    CHECK_MSG(rc == 0, "%s", err);
    CHECK_CONTAINS(out, "model ggx");
    CHECK_CONTAINS(out, "5-fold cross-validation over");
    CHECK_CONTAINS(out, "held-out rms");
    g_free(out);
    g_free(err);
    json_t *pd = json_load_file(pj, 0, NULL);
    check_choice(json_array_get(json_object_get(pd, "materials"), 0), "glossy (chain)");
    json_decref(pd);
    // the report: the page with its tables and the plots it names
    char rp[4300];
    snprintf(rp, sizeof rp, "%s/report.html", rep);
    char *page = model_read_file(rp, NULL);
    CHECK(page != NULL);
    if (page) {
        CHECK_CONTAINS(page, "Model comparison");
        CHECK_CONTAINS(page, "ggx (chosen)");
        CHECK_CONTAINS(page, "held-out RMS of R (1/sr)");
        CHECK_CONTAINS(page, "lowest BIC: ");
        CHECK_CONTAINS(page, "not perceptual roughness");
        // the headline first; a parameter is flagged barely constrained exactly when its 1-sigma exceeds 30 % of
        // its value's magnitude or of its bounds' width (each priors parameter's row)
        CHECK(strstr(page, "id=\"headline\"") && strstr(page, "<h2>Parameters") &&
              strstr(page, "id=\"headline\"") < strstr(page, "<h2>Parameters"));
        json_t *pdoc = json_load_file(pj, 0, NULL), *ps0 = json_object_get(json_array_get(json_object_get(pdoc, "materials"), 0), "parameters");
        int nloose = 0;
        for (size_t k = 0; k < json_array_size(ps0); k++) {
            json_t *q = json_array_get(ps0, k);
            double m = json_number_value(json_object_get(q, "mean")), sd = json_number_value(json_object_get(q, "std"));
            double bw = json_number_value(json_object_get(q, "hi")) - json_number_value(json_object_get(q, "lo"));
            bool loose = sd > 0 && (sd > 0.3 * fabs(m) || (bw > 0 && sd > 0.3 * bw));
            CHECK_MSG(json_is_true(json_object_get(q, "barely_constrained")) == loose, "%s: the priors' flag",
                      json_string_value(json_object_get(q, "name")));
            char want[160];
            snprintf(want, sizeof want, "<li class=\"miss\">%s barely constrained", json_string_value(json_object_get(q, "name")));
            CHECK_MSG(!!strstr(page, want) == loose, "%s: %.4g +- %.2g (bounds width %.4g): flagged %d, rule %d",
                      json_string_value(json_object_get(q, "name")), m, sd, bw, !!strstr(page, want), loose);
            nloose += loose;
        }
        CHECK(!!strstr(page, "no parameter barely constrained") == (nloose == 0));
        json_decref(pdoc);
        free(page);
    }
    static const char *const pngs[] = { "lobes.png", "residual_maps.png", "models.png", "samples.csv" };
    for (int k = 0; k < 4; k++) {
        snprintf(rp, sizeof rp, "%s/%s", rep, pngs[k]);
        CHECK_MSG(access(rp, R_OK) == 0, "%s missing", rp);
    }
    g_free(rep);
    json_t *p = json_load_file(pj, 0, &je);
    CHECK(p != NULL);
    if (p) {
        json_t *m = json_array_get(json_object_get(p, "materials"), 0);
        json_t *ps = json_object_get(m, "parameters");
        double kd = json_number_value(json_object_get(json_array_get(ps, 0), "mean"));
        double alpha = json_number_value(json_object_get(json_array_get(ps, 2), "mean"));
        double prod = json_number_value(json_object_get(m, "ks_times_F0"));
        CHECK_MSG(fabs(kd / 0.35 - 1) < 0.05, "kd %.4g vs truth 0.35", kd);
        CHECK_MSG(fabs(alpha / 0.05 - 1) < 0.10, "alpha %.4g vs truth 0.05", alpha);
        CHECK_MSG(fabs(prod / (0.6 * 0.045) - 1) < 0.10, "ks*F0 %.4g vs truth 0.027", prod);
        // the rim lamp's highlight (v.h = cos 55 deg) measures F0 apart from ks
        double f0 = json_number_value(json_object_get(json_array_get(ps, 3), "mean"));
        double f0sd = json_number_value(json_object_get(json_array_get(ps, 3), "std"));
        CHECK(json_object_get(json_array_get(ps, 3), "held") == NULL);
        CHECK_MSG(fabs(f0 / 0.045 - 1) < 0.10 && fabs(f0 - 0.045) < 2 * f0sd, "F0 %.4g +- %.2g vs truth 0.045", f0,
                  f0sd);
        // the std's parts (README "refl fit material"): the statistical one clustered by frames and places,
        // each of the five lamps' 3 % carried through the fit, the shared 3 %: std^2 their squares' sum
        json_t *sc = json_object_get(m, "statistical_covariance"), *ls = json_object_get(m, "lamp_systematic");
        CHECK(json_integer_value(json_object_get(sc, "frames")) >= 10 &&
              json_integer_value(json_object_get(sc, "places")) >= 10);
        CHECK(json_array_size(json_object_get(ls, "lamps")) == 5);
        for (size_t k = 0; k < json_array_size(ps); k++) {
            json_t *q = json_array_get(ps, k), *pt = json_object_get(q, "std_parts");
            double a = json_number_value(json_object_get(pt, "statistical")), b = json_number_value(json_object_get(pt, "lamps"));
            double c = json_number_value(json_object_get(pt, "shared")), sd = json_number_value(json_object_get(q, "std"));
            CHECK_MSG(fabs(sqrt(a * a + b * b + c * c) - sd) <= 1e-9 * sd, "%s: std %.6g, parts %.3g %.3g %.3g",
                      json_string_value(json_object_get(q, "name")), sd, a, b, c);
        }
        CHECK_CONTAINS(json_string_value(json_object_get(json_object_get(p, "provenance"), "command")),
                       "fit material");
        CHECK(json_array_size(json_object_get(json_object_get(p, "provenance"), "inputs")) >= 4);
        json_decref(p);
    }
    // a calibration without white.json: a clear error naming it
    char *cal2 = keep(test_path("cal2"));
    g_mkdir_with_parents(cal2, 0755);
    test_write("cal2/lamps.json", "{\"lamps\": [{\"name\": \"east\", \"position_mm\": [0, 0, 1]}]}");
    rc = test_refl_run(60, &out, &err, "fit", "material", gs, "--calib", cal2, "-o", pj, NULL);
    CHECK(rc == 1);
    CHECK_CONTAINS(err, "no camera.cameramodel");
    g_free(out);
    g_free(err);
    rc = test_refl_run(60, &out, &err, "fit", "material", test_tmpdir(), "--calib", cal, "-o", pj, NULL);
    CHECK(rc == 1);
    CHECK_CONTAINS(err, "not a capture session");
    g_free(out);
    g_free(err);
    // a session records no scene of its sample: without --scene, an error saying so
    rc = test_refl_run(60, &out, &err, "fit", "material", gs, "--calib", cal, "-o", pj, NULL);
    CHECK(rc == 1);
    CHECK_CONTAINS(err, "give the sample's scene (--scene FILE)");
    g_free(out);
    g_free(err);
    // --systematic 0 is allowed (statistical std only), a negative one is not
    rc = test_refl_run(300, &out, &err, "fit", "material", gs, "--scene", gsc, "--calib", cal, "--model", "ggx",
                       "--systematic", "0", "-o", pj, NULL);
    CHECK_MSG(rc == 0, "%s", err);
    g_free(out);
    g_free(err);
    rc = test_refl_run(60, &out, &err, "fit", "material", gs, "--scene", gsc, "--calib", cal, "--systematic", "-1",
                       "-o", pj, NULL);
    CHECK(rc == 2);
    CHECK_CONTAINS(err, "--systematic needs a number >= 0");
    g_free(out);
    g_free(err);
    rc = test_refl_run(60, &out, &err, "fit", "material", gs, "--scene", gsc, "--calib", cal, "--lamp-systematic",
                       "-0.01", "-o", pj, NULL);
    CHECK(rc == 2);
    CHECK_CONTAINS(err, "--lamp-systematic needs a number >= 0");
    g_free(out);
    g_free(err);
    rc = test_refl_run(60, &out, &err, "fit", "material", gs, "--scene", gsc, "--calib", cal, "--place-mm", "0",
                       "-o", pj, NULL);
    CHECK(rc == 2);
    CHECK_CONTAINS(err, "--place-mm needs a number > 0");
    g_free(out);
    g_free(err);
    // windows of whole pixels 1..64; albedo cells >= 0 and only for fit material
    static const char *const bad[][3] = { { "--window", "0", "--window needs a whole number of pixels 1..64, not '0'" },
                                          { "--step", "2.5", "--step needs a whole number of pixels 1..64, not '2.5'" },
                                          { "--albedo-cells", "-2", "--albedo-cells needs a number >= 0" } };
    for (size_t k = 0; k < sizeof bad / sizeof bad[0]; k++) {
        rc = test_refl_run(60, &out, &err, "fit", "material", gs, "--scene", gsc, "--calib", cal, bad[k][0], bad[k][1],
                           "-o", pj, NULL);
        CHECK(rc == 2);
        CHECK_CONTAINS(err, bad[k][2]);
        g_free(out);
        g_free(err);
    }
    rc = test_refl_run(60, &out, &err, "calib", "white", gs, "--calib", cal, "--albedo-cells", "2", "-o", pj, NULL);
    CHECK(rc == 2);
    CHECK_CONTAINS(err, "unknown option '--albedo-cells'");
    g_free(out);
    g_free(err);
    test_write("cal/lamps.json", "{\"lamps\": [{\"name\": \"east\"}]}");
    rc = test_refl_run(60, &out, &err, "fit", "material", gs, "--scene", gsc, "--calib", cal, "-o", pj, NULL);
    CHECK(rc == 1);
    CHECK_CONTAINS(err, "position_mm");
    g_free(out);
    g_free(err);
    test_write("cal/lamps.json", "{\"lamps\": [{\"name\": \"east\", \"position_mm\": [0, 0, 1], \"radius_mm\": -2}]}");
    rc = test_refl_run(60, &out, &err, "fit", "material", gs, "--scene", gsc, "--calib", cal, "-o", pj, NULL);
    CHECK(rc == 1);
    CHECK_CONTAINS(err, "lamps[0] (east): radius_mm must be a number of mm in [0, 1000)");
    g_free(out);
    g_free(err);
    g_free(rig);
    g_free(cal);
    g_free(white);
    g_free(glossy);
    g_free(ws);
    g_free(gs);
    g_free(pj);
    g_free(cal2);
    g_free(wsc);
    g_free(gsc);
}

// One coupon on the 40 degree wedge: capture (9 angles, each lamp alone,
// bracketed), fit every model (cells: with --albedo-cells 2 on 3x3 windows
// every 4 pixels, for a textured material), and return the priors' material
// entry (caller json_decref's the returned document through *doc).
// The model choice of a priors entry: by 5-fold cross-validation over the
// frames, the chosen model's held-out RMS and BIC recorded, BIC's own pick
// beside it (printed).
static void check_choice(json_t *m, const char *sample)
{
    json_t *ch = json_object_get(m, "model_choice");
    CHECK_MSG(ch != NULL, "%s: no model_choice", sample);
    if (!ch) return;
    CHECK(!strcmp(json_string_value(json_object_get(ch, "criterion")), "cv_rms"));
    CHECK(!strcmp(json_string_value(json_object_get(ch, "unit")), "frame"));
    CHECK(json_integer_value(json_object_get(ch, "folds")) == 5 && json_integer_value(json_object_get(ch, "units")) >= 10);
    CHECK(!strcmp(json_string_value(json_object_get(ch, "chosen")), json_string_value(json_object_get(m, "model"))));
    CHECK(json_is_number(json_object_get(m, "cv_rms")) && json_is_number(json_object_get(m, "bic")));
    double rms = json_number_value(json_object_get(m, "rms")), cv = json_number_value(json_object_get(m, "cv_rms"));
    CHECK_MSG(cv >= 0.9 * rms && cv < 2 * rms, "%s: held-out rms %g vs rms %g", sample, cv, rms);
    fprintf(stderr, "  %s: chosen %s by held-out rms (%.4g 1/sr over %lld frames); lowest BIC %s\n", sample,
            json_string_value(json_object_get(ch, "chosen")), cv, json_integer_value(json_object_get(ch, "units")),
            json_string_value(json_object_get(ch, "lowest_bic")));
}

static json_t *fit_coupon(const char *rig, const char *cal, const char *sample, bool cells, json_t **doc)
{
    char plan[1024];
    snprintf(plan, sizeof plan, "[plan]\nname = %s\n[sample]\nname = %s\nkind = material_coupon\ntilt_deg = 40\n"
             "[angles]\nrange = 0 320 40\n[lamps]\nsets = east; south; west; north; rim; none\n[exposure]\nmode = auto\n"
             "list_us = 8000 1000 125\n", sample, sample);
    char name[256];
    snprintf(name, sizeof name, "%s.ini", sample);
    char *pp = keep(test_write(name, plan));
    snprintf(name, sizeof name, "s_%s", sample);
    char *sd = keep(test_path(name));
    snprintf(name, sizeof name, "p_%s.json", sample);
    char *pj = keep(test_path(name));
    char *out = NULL, *err = NULL;
    int rc = test_refl_run(300, &out, &err, "capture", "--yes", pp, "--rig", rig, "-o", sd, "--progress", "lines", NULL);
    CHECK_MSG(rc == 0, "%s: %s", sample, err);
    g_free(out);
    g_free(err);
    char *sc = sample_scene(sample);
    if (cells)
        rc = test_refl_run(300, &out, &err, "fit", "material", sd, "--scene", sc, "--calib", cal, "-o", pj,
                           "--albedo-cells", "2", "--window", "3", "--step", "4", NULL);
    else
        rc = test_refl_run(300, &out, &err, "fit", "material", sd, "--scene", sc, "--calib", cal, "-o", pj, NULL);
    g_free(sc);
    CHECK_MSG(rc == 0, "%s: %s", sample, err);
    if (cells) CHECK_CONTAINS(out, "albedo cells of 2 mm: ");
    // with a gain calibration: its monotone table applied, and the compression it measured
    // (the parametric fit beside it), against the truth's nonlinearity 2 % of the full well
    // 16000 e- at 0.25 DN/e-: a = 0.02 / 4000 per DN
    CHECK_CONTAINS(out, "response linearised: the gain calibration's monotone table");
    const char *ac = out ? strstr(out, "response linearised") : NULL;
    ac = ac ? strstr(ac, "a = ") : NULL;
    double a = ac ? strtod(ac + strlen("a = "), NULL) : NAN;
    CHECK_MSG(fabs(a / 5e-6 - 1) < 0.10, "%s: response compression a = %g per DN vs truth 5e-6", sample, a);
    g_free(out);
    g_free(err);
    json_error_t je;
    *doc = json_load_file(pj, 0, &je);
    g_free(pp);
    g_free(sd);
    g_free(pj);
    json_t *m = *doc ? json_array_get(json_object_get(*doc, "materials"), 0) : NULL;
    check_choice(m, sample);
    return m;
}

static double param(json_t *m, const char *name, double *sd)
{
    json_t *ps = json_object_get(m, "parameters");
    for (size_t i = 0; i < json_array_size(ps); i++) {
        json_t *p = json_array_get(ps, i);
        if (!strcmp(json_string_value(json_object_get(p, "name")), name)) {
            if (sd) *sd = json_number_value(json_object_get(p, "std"));
            return json_number_value(json_object_get(p, "mean"));
        }
    }
    return NAN;
}

// Within tol (relative) of the truth and (two_std) within 2 std of it.
static void check_param(json_t *m, const char *name, double truth, double tol, bool two_std)
{
    double sd = NAN, v = param(m, name, &sd);
    CHECK_MSG(fabs(v / truth - 1) <= tol, "%s %s = %.5g vs truth %.5g (tolerance %g %%)",
              json_string_value(json_object_get(m, "name")), name, v, truth, 100 * tol);
    CHECK_MSG(!two_std || fabs(v - truth) <= 2 * sd, "%s %s = %.5g +- %.3g: truth %.5g is beyond 2 std",
              json_string_value(json_object_get(m, "name")), name, v, sd, truth);
}

// The fit's residual RMS over what the sensor's noise alone would leave
// (rms_over_noise, from the gain calibration) within [lo, hi].
static void check_noise(json_t *m, double lo, double hi)
{
    double r = json_number_value(json_object_get(m, "rms_over_noise"));
    fprintf(stderr, "  %s: residual %.3f x the noise\n", json_string_value(json_object_get(m, "name")), r);
    CHECK_MSG(r >= lo && r <= hi, "%s: residual RMS %.3g x the noise, expected %g..%g",
              json_string_value(json_object_get(m, "name")), r, lo, hi);
}

// The other coupons of the truth file, with the truth's geometry, a gain
// calibration (refl calib gain on the flat-field source: flat field, dark
// offset, response compression) and a reference white as calibrations: matte
// paint (hall, a weak lobe), the thesis's plywood (thesis_fit, textured), a
// metal (cook_torrance) and the glossy plastic (ggx). Each gets its own model
// by BIC; kd within 5 %, exponents and roughness within 10 %, each within 2
// std of the truth. The glossy plastic's F0 and ks come apart (the rim lamp's
// highlight at v.h = cos 55 deg: F0 within 10 % and 2 std); the metal's F0
// (0.8: F changes < 1 % there) is known only to lie in [ks*F0, 1], whose
// uniform holds the truth within 2 std. The fit averages each sample near a
// lamp's mirror direction over the lamp's disc (lamps.json radius_mm): with
// point lamps the glossy plastic's rim highlight left it at 4.4x the noise.
// The response is linearised with the gain calibration's monotone table, and
// its parametric fit beside it measures the compression (a within 10 % of the
// truth's); uncorrected, the metal's tiny diffuse part came
// out 9 % high. Residuals: the glossy plastic's is at the sensor's noise
// (within 1.5x), and so is the metal's (the truth renders these two coupons
// with 64 and 16 stratified samples of each 15 mm lamp per pixel, as a pixel
// integrates the whole lamp; with one, that Monte Carlo noise left the metal
// at 1.9x), the
// textured paint's (2 % albedo texture) and the plywood's (8 %) with albedo
// cells of 2 mm on 3x3-pixel windows (without them: 1.8x and 5.4x; with cells
// on 5x5 windows the plywood's stays at 2x, a window's footprint turning with
// the table over the texture); the cells' factors spread as the textures'
// amplitudes do (4x).
TEST_LONG(fit_material_coupons_virtual_rig)
{
    char *rig = rig_file(), *cal = calib_dir();
    char *white = keep(test_write("white.ini", "[plan]\nname = white\n[sample]\nname = reference_white\n"
                                                "kind = reference_white\n[angles]\nlist = 0 120 240\n[lamps]\n"
                                                "sets = east; south; west; north; rim; none\n[exposure]\nmode = fixed\n"
                                                "list_us = 8000\n"));
    char *ws = keep(test_path("w")), wj[4200], gd[4200];
    snprintf(wj, sizeof wj, "%s/white.json", cal);
    snprintf(gd, sizeof gd, "%s/gain", cal);
    char *out = NULL, *err = NULL;
    int rc = test_refl_run(300, &out, &err, "calib", "gain", "--yes", "--rig", rig, "-o", gd, "--no-report",
                           "--dark-exposures-us", "100000,1000000", NULL);
    CHECK_MSG(rc == 0, "%s", err);
    g_free(out);
    g_free(err);
    rc = test_refl_run(300, &out, &err, "capture", "--yes", white, "--rig", rig, "-o", ws, "--progress", "lines", NULL);
    CHECK_MSG(rc == 0, "%s", err);
    g_free(out);
    g_free(err);
    char *wsc = sample_scene("reference_white");
    rc = test_refl_run(300, &out, &err, "calib", "white", ws, "--calib", cal, "--scene", wsc, "-o", wj, NULL);
    g_free(wsc);
    CHECK_MSG(rc == 0, "%s", err);
    g_free(out);
    g_free(err);
    json_t *doc = NULL, *m;
    double spread_paint = NAN, spread_plywood = NAN;
    if ((m = fit_coupon(rig, cal, "coupon_matte_paint", true, &doc))) {
        CHECK(!strcmp(json_string_value(json_object_get(m, "model")), "hall"));
        check_param(m, "kd", 0.2, 0.05, true);
        check_param(m, "ks", 0.03, 0.10, true);
        check_param(m, "ns", 5, 0.10, true);
        check_noise(m, 0.9, 1.5);
        json_t *ac = json_object_get(m, "albedo_cells");
        spread_paint = json_number_value(json_object_get(ac, "factor_rel_std"));
        CHECK(json_integer_value(json_object_get(ac, "cells")) > 1000);
        CHECK(json_integer_value(json_object_get(ac, "observations_in_cells")) >
              0.9 * json_integer_value(json_object_get(ac, "observations")));
    }
    json_decref(doc);
    if ((m = fit_coupon(rig, cal, "coupon_plywood", true, &doc))) {
        CHECK(!strcmp(json_string_value(json_object_get(m, "model")), "thesis_fit"));
        check_param(m, "kd", 0.16, 0.05, true);
        check_param(m, "ks", 0.02, 0.10, true);
        check_param(m, "ns", 8, 0.10, true);
        check_noise(m, 0.9, 1.5);
        spread_plywood = json_number_value(json_object_get(json_object_get(m, "albedo_cells"), "factor_rel_std"));
    }
    json_decref(doc);
    fprintf(stderr, "  albedo factors' spread: paint %.4f, plywood %.4f (textures' amplitudes 0.02, 0.08)\n",
            spread_paint, spread_plywood);
    CHECK_MSG(spread_plywood > 0.012 && spread_plywood < 0.04 && spread_plywood / spread_paint > 3.2 &&
              spread_plywood / spread_paint < 4.8, "albedo factors' spread: paint %.4f, plywood %.4f", spread_paint,
              spread_plywood);
    if ((m = fit_coupon(rig, cal, "coupon_metal", false, &doc))) {
        CHECK(!strcmp(json_string_value(json_object_get(m, "model")), "cook_torrance"));
        check_param(m, "kd", 0.03, 0.05, true);
        check_param(m, "m", 0.25, 0.10, true);
        double prod = param(m, "ks", NULL) * param(m, "F0", NULL);
        CHECK_MSG(fabs(prod / (0.9 * 0.8) - 1) < 0.05, "metal ks*F0 %.4g vs truth 0.72", prod);
        // F0 0.8: Schlick's F changes < 1 % even at the rim lamp's v.h, so F0
        // is not measured: only known to lie in [ks*F0, 1] (a uniform's mean
        // and std, ks = ks*F0 / F0), which holds the truth within 2 std
        check_param(m, "F0", 0.8, 0.15, true);
        check_param(m, "ks", 0.9, 0.15, true);
        check_noise(m, 0.9, 1.5);
    }
    json_decref(doc);
    if ((m = fit_coupon(rig, cal, "coupon_glossy_plastic", false, &doc))) {
        CHECK(!strcmp(json_string_value(json_object_get(m, "model")), "ggx"));
        check_param(m, "kd", 0.35, 0.05, true);
        check_param(m, "alpha", 0.05, 0.10, true);
        // F0 measured apart from ks by the rim lamp's highlight at v.h = cos 55 deg
        check_param(m, "ks", 0.6, 0.05, true);
        check_param(m, "F0", 0.045, 0.10, true);
        check_noise(m, 0.9, 1.5);
    }
    json_decref(doc);
    g_free(rig);
    g_free(cal);
    g_free(white);
    g_free(ws);
}

// A gain in a unit without a known scale ("raw"): the white session's frames
// recorded again at gain 100 raw (the journal rewritten); a calibration
// directory whose gain calibration was made at 100 raw gives the same kc*I as
// at 0 dB; one made at 50 raw is an error naming the frame and the unit.
static void raw_gain_white(const char *ws, const char *cal, const char *wsc)
{
    char db[4300], wj[4300];
    snprintf(db, sizeof db, "%s/session.sqlite", ws);
    sqlite3 *d = NULL;
    CHECK(sqlite3_open(db, &d) == SQLITE_OK);
    CHECK(sqlite3_exec(d, "UPDATE frames SET gain = 100, gain_unit = 'raw'", NULL, NULL, NULL) == SQLITE_OK);
    sqlite3_close(d);
    char *rc_dir = keep(test_path("calraw"));
    g_mkdir_with_parents(rc_dir, 0755);
    snprintf(db, sizeof db, "%s/left.cameramodel", cal);
    char *cm = model_read_file(db, NULL);
    test_write("calraw/left.cameramodel", cm ? cm : "");
    free(cm);
    snprintf(db, sizeof db, "%s/lamps.json", cal);
    char *lj = model_read_file(db, NULL);
    test_write("calraw/lamps.json", lj ? lj : "");
    free(lj);
    snprintf(db, sizeof db, "%s/left", rc_dir);
    g_mkdir_with_parents(db, 0755);
    snprintf(wj, sizeof wj, "%s/white_raw.json", rc_dir);
    static const char *const at[2] = { "100", "50" };
    for (int k = 0; k < 2; k++) {
        snprintf(db, sizeof db, "{\"camera\": \"left\", \"gain_db\": %s, \"gain_unit\": \"raw\", "
                 "\"saturation_dn\": 3920}\n", at[k]);
        test_write("calraw/left/gain.json", db);
        char *out = NULL, *err = NULL;
        int rc = test_refl_run(300, &out, &err, "calib", "white", ws, "--calib", rc_dir, "--camera", "left",
                               "--scene", wsc, "-o", wj, NULL);
        if (k == 0) {
            CHECK_MSG(rc == 0, "%s", err);
            snprintf(db, sizeof db, "%s/left/white.json", cal);
            json_t *a = json_load_file(db, 0, NULL), *b = json_load_file(wj, 0, NULL);
            for (int l = 0; a && b && l < 5; l++)
                CHECK_REL(json_number_value(json_object_get(json_array_get(json_object_get(b, "lamps"), l),
                                                            "kc_I_per_us")),
                          json_number_value(json_object_get(json_array_get(json_object_get(a, "lamps"), l),
                                                            "kc_I_per_us")), 1e-9);
            CHECK(a && b);
            json_decref(a);
            json_decref(b);
        } else {
            CHECK(rc == 1);
            CHECK_CONTAINS(err, "in unit 'raw' has no known scale");
            CHECK_CONTAINS(err, "calibration's gain (50 raw)");
            CHECK_CONTAINS(err, "frames/s0000");
        }
        g_free(out);
        g_free(err);
    }
    g_free(rc_dir);
}

// fit_material_two_cameras: the 2-camera virtual rig (examples/virtual-truth-2cam.ini:
// "left" and "right", other poses and sensors, kc_per_us 1e-4 and 1.5e-4). The
// calibration directory holds each camera's model as NAME.cameramodel (the
// truth's), the shared lamps.json and each camera's white (refl calib white
// --camera NAME -o DIR/NAME/white.json: kc*I within 3 % of that camera's
// truth) and gain.json (its saturation). The glossy coupon captured with both
// cameras is fitted with every camera's frames through its own calibrations
// in one fit (more observations than either camera's alone) and recovers the
// truth's GGX material (kd within 5 %, alpha, F0 and ks*F0 within 10 %). A camera without calibration files is an
// error naming the file to make.
TEST_LONG(fit_material_two_cameras)
{
    char *sd = srcdir(), text[4200];
    snprintf(text, sizeof text, "[rig]\nbackend = virtual\ntruth = %s/examples/virtual-truth-2cam.ini\n"
             "serve = inprocess\ntime_scale = 0.005\npixel_format = Mono12\n", sd);
    char *rig = keep(test_write("rig-2cam.ini", text));
    char *cal = keep(test_path("cal2cam"));
    g_mkdir_with_parents(cal, 0755);
    static const char *const names[2] = { "left", "right" }, *const models[2] = { "camera", "camera-right" };
    for (int k = 0; k < 2; k++) {
        snprintf(text, sizeof text, "%s/examples/%s.cameramodel", sd, models[k]);
        char *cm = model_read_file(text, NULL);
        CHECK(cm != NULL);
        snprintf(text, sizeof text, "cal2cam/%s.cameramodel", names[k]);
        test_write(text, cm ? cm : "");
        free(cm);
    }
    free(sd);
    // each camera's gain calibration: its saturation (without it the 12-bit full scale is taken, above which
    // the right camera's well (13000 e- x 0.3 DN/e-) clips: its highlights would be taken clipped); the
    // sensors' full well x K less the 2 % compression, as refl calib gain measures it (calib_gain_two_cameras)
    g_mkdir_with_parents(test_path("cal2cam/left"), 0755);
    g_mkdir_with_parents(test_path("cal2cam/right"), 0755);
    test_write("cal2cam/left/gain.json", "{\"camera\": \"left\", \"gain_db\": 0, \"gain_unit\": \"dB\", "
                                         "\"saturation_dn\": 3920}\n");
    test_write("cal2cam/right/gain.json", "{\"camera\": \"right\", \"gain_db\": 0, \"gain_unit\": \"dB\", "
                                          "\"saturation_dn\": 3822}\n");
    test_write("cal2cam/lamps.json",
               "{\"lamps\": [{\"name\": \"east\", \"position_mm\": [488.6, 177.9, 600], \"radius_mm\": 15},"
               " {\"name\": \"south\", \"position_mm\": [-52.3, -597.7, 480], \"radius_mm\": 15},"
               " {\"name\": \"west\", \"position_mm\": [-526.2, -191.5, 520], \"radius_mm\": 15},"
               " {\"name\": \"north\", \"position_mm\": [98.4, 367.1, 700], \"radius_mm\": 15},"
               " {\"name\": \"rim\", \"position_mm\": [-619.8, 65.1, 219.6], \"radius_mm\": 15}]}\n");
    char *wsc = sample_scene("reference_white"), *gsc = sample_scene("coupon_glossy_plastic");
    char *white = keep(test_write("white2.ini", "[plan]\nname = white\n[sample]\nname = reference_white\n"
                                                 "kind = reference_white\n[angles]\nlist = 0 120 240\n[lamps]\n"
                                                 "sets = east; south; west; north; rim; none\n[exposure]\nmode = fixed\n"
                                                 "list_us = 8000\n"));
    char *glossy = keep(test_write("glossy2.ini", "[plan]\nname = glossy\n[sample]\nname = coupon_glossy_plastic\n"
                                                   "kind = material_coupon\ntilt_deg = 40\n[angles]\nrange = 0 340 20\n"
                                                   "[lamps]\nsets = east; south; west; north; rim; none\n[exposure]\n"
                                                   "mode = fixed\nlist_us = 8000 500\n"));
    char *ws = keep(test_path("w2cam")), *gs = keep(test_path("g2cam")), *pj = keep(test_path("priors2.json"));
    char *out = NULL, *err = NULL;
    double t0 = model_now_s();
    int rc = test_refl_run(300, &out, &err, "capture", "--yes", white, "--rig", rig, "-o", ws, NULL);
    CHECK_MSG(rc == 0, "%s", err);
    g_free(out);
    g_free(err);
    // each camera's white: kc*I = its truth kc_per_us times the lamps' intensities
    const double I[5] = { 3.2e9, 2.9e9, 3.1e9, 3.6e9, 2.6e9 }, kc[2] = { 1e-4, 1.5e-4 };
    for (int k = 0; k < 2 && rc == 0; k++) {
        char wj[4300];
        snprintf(wj, sizeof wj, "%s/%s/white.json", cal, names[k]);
        char *wd = g_path_get_dirname(wj);
        g_mkdir_with_parents(wd, 0755);
        g_free(wd);
        rc = test_refl_run(300, &out, &err, "calib", "white", ws, "--calib", cal, "--camera", names[k], "--scene", wsc,
                           "-o", wj, NULL);
        CHECK_MSG(rc == 0, "calib white --camera %s: %s", names[k], err);
        g_free(out);
        g_free(err);
        json_t *w = json_load_file(wj, 0, NULL);
        CHECK(w && !strcmp(json_string_value(json_object_get(w, "camera")) ?: "", names[k]));
        for (int l = 0; w && l < 5; l++) {
            json_t *e = json_array_get(json_object_get(w, "lamps"), l);
            double v = json_number_value(json_object_get(e, "kc_I_per_us")), t = kc[k] * I[l];
            CHECK_MSG(fabs(v / t - 1) < 0.03, "camera %s lamp %d: kc*I %.6g vs truth %.6g", names[k], l, v, t);
        }
        json_decref(w);
    }
    fprintf(stderr, "  whites: %.1f s\n", model_now_s() - t0);
    raw_gain_white(ws, cal, wsc);
    rc = test_refl_run(300, &out, &err, "capture", "--yes", glossy, "--rig", rig, "-o", gs, NULL);
    CHECK_MSG(rc == 0, "%s", err);
    g_free(out);
    g_free(err);
    rc = test_refl_run(300, &out, &err, "fit", "material", gs, "--scene", gsc, "--calib", cal, "--model", "ggx", "-o",
                       pj, NULL);
    CHECK_MSG(rc == 0, "%s", err);
    fprintf(stderr, "  capture and fit: %.1f s\n%s", model_now_s() - t0, out ? out : "");
    // every camera's observations in the one fit
    int nl = 0, nr = 0, ns = 0;
    const char *p = out ? strstr(out, "camera left: ") : NULL, *q = out ? strstr(out, "camera right: ") : NULL;
    const char *t = out ? strstr(out, "BRDF samples") : NULL;
    CHECK(p && sscanf(p, "camera left: %d", &nl) == 1 && q && sscanf(q, "camera right: %d", &nr) == 1);
    while (t && t > out && t[-1] == ' ') t--;
    while (t && t > out && t[-1] >= '0' && t[-1] <= '9') t--;
    CHECK(t && sscanf(t, "%d", &ns) == 1);
    fprintf(stderr, "  observations: left %d, right %d, samples %d\n", nl, nr, ns);
    CHECK(nl > 100 && nr > 100 && ns == nl + nr);
    g_free(out);
    g_free(err);
    json_t *doc = json_load_file(pj, 0, NULL);
    json_t *m = doc ? json_array_get(json_object_get(doc, "materials"), 0) : NULL;
    CHECK(m != NULL);
    if (m) {
        check_param(m, "kd", 0.35, 0.05, false);
        check_param(m, "alpha", 0.05, 0.10, false);
        double prod = json_number_value(json_object_get(m, "ks_times_F0"));
        CHECK_MSG(fabs(prod / (0.6 * 0.045) - 1) < 0.10, "ks*F0 %.4g vs truth 0.027", prod);
        check_param(m, "F0", 0.045, 0.10, false);
        // the provenance lists both cameras' calibration files
        json_t *in = json_object_get(json_object_get(doc, "provenance"), "inputs");
        int ncam = 0;
        for (size_t i = 0; i < json_array_size(in); i++)
            ncam += !strcmp(json_string_value(json_object_get(json_array_get(in, i), "role")) ?: "", "camera");
        CHECK(ncam == 2);
        int ngain = 0;
        for (size_t i = 0; i < json_array_size(in); i++)
            ngain += !strcmp(json_string_value(json_object_get(json_array_get(in, i), "role")) ?: "", "gain");
        CHECK(ngain == 2);
    }
    json_decref(doc);
    // a camera of the session without its calibrations
    char rm[4400];
    snprintf(rm, sizeof rm, "%s/right.cameramodel", cal);
    CHECK(unlink(rm) == 0);
    rc = test_refl_run(60, &out, &err, "fit", "material", gs, "--scene", gsc, "--calib", cal, "-o", pj, NULL);
    CHECK(rc == 1);
    CHECK_CONTAINS(err, "no right.cameramodel");
    g_free(out);
    g_free(err);
    g_free(rig);
    g_free(cal);
    g_free(wsc);
    g_free(gsc);
    g_free(white);
    g_free(glossy);
    g_free(ws);
    g_free(gs);
    g_free(pj);
}
