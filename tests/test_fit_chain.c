// tests/test_fit_chain.c — the lab day against the truth (fit/eval/chain.h,
// calib_projection_diff in calib/geometry/diff.c): projection differences
// with known answers; chain.json of a made-up day whose every error and z is
// known; refl chain's and refl demo --truth's errors.
#include <glib.h>
#include <jansson.h>
#include <limits.h>
#include <math.h>
#include <mrcal/mrcal.h>
#include <stdlib.h>
#include <string.h>

#include "calib/geometry/geometry.h"
#include "fit/eval/chain.h"
#include "fit/brdf/brdf.h"
#include "model/model.h"
#include "model/base/report.h"
#include "rig/virtual/truth.h"
#include "tests/fixtures.h"
#include "tests/test.h"

static char *example(const char *name)
{
    char top[PATH_MAX];
    if (!realpath(test_srcdir(), top)) snprintf(top, sizeof top, "%s", test_srcdir());
    return g_build_filename(top, "examples", name, NULL);
}

// Identical models project alike; a principal point moved by d px moves every
// pixel by exactly d (it is added after the lens), which a slight turn of the
// camera frame (or a shift across the axis) explains almost wholly.
TEST(chain_projection_diff_known_answers)
{
    char *p = example("camera.cameramodel");
    mrcal_cameramodel_t *a = mrcal_read_cameramodel_file(p), *b = mrcal_read_cameramodel_file(p);
    CHECK(a && b);
    if (!a || !b) return;
    calib_projection_diff_t d;
    CHECK(calib_projection_diff(a, b, 900, 0, 0, &d));
    CHECK(d.rms_px < 1e-6 && d.worst_px < 1e-6 && d.npoints == 33 * 27);
    const double shift = 0.8;
    b->intrinsics[2] += shift;
    CHECK(calib_projection_diff(a, b, 900, 0, 0, &d));
    CHECK_NEAR(d.rms_unaligned_px, shift, 1e-6);
    CHECK_NEAR(d.worst_unaligned_px, shift, 1e-6);
    CHECK_MSG(d.rms_px < 0.1 * shift, "aligned RMS %.4f px", d.rms_px);
    // a focal length 0.5 % longer, at one distance, is the camera 0.5 % of
    // 900 mm nearer: the alignment finds that shift
    b->intrinsics[2] -= shift;
    b->intrinsics[0] *= 1.005;
    b->intrinsics[1] *= 1.005;
    CHECK(calib_projection_diff(a, b, 900, 0, 0, &d));
    CHECK_MSG(d.rms_px < 0.1 && d.rms_unaligned_px > 1, "scaled: %.3f of %.3f px", d.rms_px, d.rms_unaligned_px);
    CHECK_NEAR(d.translation_mm, 900 * (1 - 1 / 1.005), 0.5);
    // against mrcal's own projection_diff (python3-mrcal) on a lens that differs
    // in its distortion: the same RMS with mrcal's focus radius, min(W, H) / 6
    b->intrinsics[0] /= 1.005;
    b->intrinsics[1] /= 1.005;
    b->intrinsics[4] += 0.01;
    b->intrinsics[6] += 0.0005;
    const char *pb = test_path("b.cameramodel");
    CHECK(mrcal_write_cameramodel_file(pb, b));
    CHECK(calib_projection_diff(a, b, 900, 0, fmin(a->imagersize[0], a->imagersize[1]) / 6.0, &d));
    char script[PATH_MAX * 3];
    snprintf(script, sizeof script, "import mrcal, numpy as np\n"
             "m = [mrcal.cameramodel('%s'), mrcal.cameramodel('%s')]\n"
             "d = mrcal.projection_diff(m, gridn_width=33, distance=900, use_uncertainties=False)[0]\n"
             "print('%%.6f' %% np.sqrt(np.mean(d * d)))\n", p, pb);
    const char *argv[] = { "/usr/bin/python3", "-c", script, NULL };
    char *out = NULL, *err = NULL;
    int rc = test_run(argv, 120, &out, &err);
    CHECK_MSG(rc == 0, "python3 mrcal: exit %d: %s", rc, err ? err : "");
    double mr = out ? atof(out) : NAN;
    fprintf(stderr, "  a distorted lens: refl %.4f px RMS (%.4f unaligned), mrcal.projection_diff %.4f px\n", d.rms_px,
            d.rms_unaligned_px, mr);
    CHECK_MSG(fabs(d.rms_px - mr) < 0.25 * mr, "refl %.4f vs mrcal %.4f px", d.rms_px, mr);
    g_free(out);
    g_free(err);
    CHECK(!calib_projection_diff(a, b, -1, 0, 0, &d));
    CHECK_CONTAINS(model_last_error(), "distance > 0");
    mrcal_free_cameramodel(&a);
    mrcal_free_cameramodel(&b);
    g_free(p);
}

static void put(const char *rel, const char *text)
{
    char *p = g_build_filename(test_tmpdir(), "day", rel, NULL), *d = g_path_get_dirname(p);
    CHECK(model_mkdir_p(d));
    CHECK(g_file_set_contents(p, text, -1, NULL));
    g_free(d);
    g_free(p);
}

static const json_t *entry(const json_t *doc, const char *name)
{
    const json_t *e;
    size_t i;
    json_array_foreach(json_object_get(doc, "entries"), i, e)
        if (!strcmp(json_string_value(json_object_get(e, "name")), name)) return e;
    test_fail(__FILE__, __LINE__, "no entry %s", name);
    return NULL;
}

static double field(const json_t *e, const char *k)
{
    const json_t *v = json_object_get(e, k);
    return json_is_number(v) ? json_number_value(v) : NAN;
}

// A made-up day on the matched truth: the truth's camera model as calibrated,
// lamp east 1 mm off in x with a stated 0.5 mm, K 0.01 high, the glossy
// plastic's kd 0.01 high with a stated 0.005, the correct description judged
// incorrect and a wrong one incorrect.
TEST(chain_known_errors_and_z)
{
    char *truth = example("virtual-truth.ini"), *cam = example("camera.cameramodel");
    char *t_scene = example("t_stiffener.d3d"), *i_scene = example("i_stiffener.d3d");
    char *model_text = NULL;
    CHECK(g_file_get_contents(cam, &model_text, NULL, NULL));
    put("calib/geometry/camera.cameramodel", model_text ? model_text : "");
    put("calib/geometry/geometry.json", "{"
        "\"projection_uncertainty\": {\"distance_mm\": 900, \"max_px\": 0.2, \"stdev_px\": [[0.1, 0.1], [0.1, 0.1]]}}");
    put("calib/lamps/lamps.json", "{\"lamps\": [{\"name\": \"east\", \"position_mm\": [489.6, 177.9, 600],"
        "\"std_mm\": [0.5, 0.5, 0.5], \"covariance_mm2\": [0.25, 0, 0, 0, 0.25, 0, 0, 0, 0.25]}]}");
    put("calib/gain/gain.json", "{\"system_gain_dn_per_e\": 0.26, \"read_noise_e\": 6}");
    put("priors_glossy.json", "{\"materials\": [{\"name\": \"glossy_plastic\", \"model\": \"ggx\", \"parameters\": "
        "[{\"name\": \"kd\", \"mean\": 0.36, \"std\": 0.005, \"unit\": \"1\"}]}]}");
    char v[PATH_MAX + 128];
    snprintf(v, sizeof v, "{\"scene\": \"%s\", \"verdict\": \"incorrect\", \"score\": 900, \"score_threshold\": 400}",
             t_scene);
    put("verify_t/verify.json", v);
    snprintf(v, sizeof v, "{\"scene\": \"%s\", \"verdict\": \"incorrect\", \"score\": 9000, \"score_threshold\": 400}",
             i_scene);
    put("verify_i/verify.json", v);
    const char *day = test_path("day");
    json_t *prov = model_provenance(0, NULL);
    json_t *doc = eval_chain_compare(day, truth, prov);
    CHECK_MSG(doc != NULL, "%s", model_last_error());
    if (doc) {
        const json_t *e = entry(doc, "camera.projection_error_rms");
        CHECK(field(e, "value") < 1e-6 && fabs(field(e, "sigma") - 0.1) < 1e-12);
        e = entry(doc, "lamp_east.x");
        CHECK_NEAR(field(e, "error"), 1.0, 1e-9);
        CHECK_NEAR(field(e, "z"), 2.0, 1e-9);
        CHECK_NEAR(field(entry(doc, "lamp_east.y"), "z"), 0.0, 1e-9);
        // in the camera's frame (the same camera, calibrated and true): the same 1 mm, turned; sigma 0.5 each
        double e2 = 0;
        for (int k = 0; k < 3; k++) {
            char n[64];
            snprintf(n, sizeof n, "lamp_east.camera_%c", "xyz"[k]);
            const json_t *ec = entry(doc, n);
            e2 += field(ec, "error") * field(ec, "error");
            CHECK_NEAR(field(ec, "sigma"), 0.5, 1e-9);
        }
        CHECK_NEAR(sqrt(e2), 1.0, 1e-6);
        e = entry(doc, "sensor.system_gain_dn_per_e");
        CHECK_NEAR(field(e, "error"), 0.01, 1e-12);
        CHECK(json_is_null(json_object_get(e, "sigma")) && json_is_null(json_object_get(e, "z")));
        e = entry(doc, "material_glossy_plastic.kd");
        CHECK_NEAR(field(e, "truth"), 0.35, 1e-12);
        CHECK_NEAR(field(e, "z"), 2.0, 1e-9);
        e = entry(doc, "verify_t.verdict");
        CHECK(e && !strcmp(json_string_value(json_object_get(e, "truth")), "correct"));
        CHECK(e && json_integer_value(json_object_get(e, "error")) == 1);
        e = entry(doc, "verify_i.verdict");
        CHECK(e && json_integer_value(json_object_get(e, "error")) == 0);
        const json_t *s = json_object_get(doc, "summary");
        CHECK(json_integer_value(json_object_get(s, "wrong_verdicts")) == 1);
        CHECK(json_array_size(json_object_get(s, "z_over_3")) == 0);
        // missing parts are named, not fatal
        const json_t *m;
        size_t i;
        bool white = false;
        json_array_foreach(json_object_get(doc, "missing"), i, m) white |= strstr(json_string_value(m), "white") != NULL;
        CHECK(white);
    }
    json_decref(doc);
    json_decref(prov);

    // refl chain: the table, |z| > 3 marked, chain.json written
    put("calib/lamps/lamps.json", "{\"lamps\": [{\"name\": \"east\", \"position_mm\": [492.6, 177.9, 600],"
        "\"std_mm\": [0.5, 0.5, 0.5]}]}");
    char *out = NULL, *err = NULL;
    int rc = test_refl_run(60, &out, &err, "chain", day, "--truth", truth, NULL);
    CHECK_MSG(rc == 0, "exit %d: %s", rc, err);
    CHECK_CONTAINS(out, "lamp_east.x");
    CHECK_CONTAINS(out, "+8.00 mm");
    CHECK_CONTAINS(out, "|z| > 3: 1; wrong verdicts: 1");
    char *cj = g_build_filename(day, "chain.json", NULL);
    json_error_t je;
    json_t *j = json_load_file(cj, 0, &je);
    CHECK(j && json_is_object(json_object_get(j, "provenance")));
    int version = 0;
    CHECK_MSG(model_json_format_check(j, cj, "refl-chain", 1, &version) && version == 1, "%s", model_last_error());
    json_decref(j);
    g_free(out);
    g_free(err);
    // a file of a newer version is not used: named among the missing, its figures absent
    put("calib/gain/gain.json", "{\"format\": \"refl-gain\", \"version\": 99, \"system_gain_dn_per_e\": 0.26}");
    rc = test_refl_run(60, &out, &err, "chain", day, "--truth", truth, "--quiet", NULL);
    CHECK_MSG(rc == 0, "exit %d: %s", rc, err);
    j = json_load_file(cj, 0, &je);
    bool named = false;
    const json_t *m;
    size_t i;
    json_array_foreach(json_object_get(j, "missing"), i, m) {
        const char *t = json_string_value(m);
        named |= t && strstr(t, "gain.json") && strstr(t, "refl-gain version 99, written by a newer refl");
    }
    CHECK(named);
    bool gain_figure = false;
    json_array_foreach(json_object_get(j, "entries"), i, m)
        gain_figure |= !strcmp(json_string_value(json_object_get(m, "name")), "sensor.system_gain_dn_per_e");
    CHECK(!gain_figure);
    json_decref(j);
    g_free(cj);
    g_free(out);
    g_free(err);
    g_free(model_text);
    g_free(truth);
    g_free(cam);
    g_free(t_scene);
    g_free(i_scene);
}

// A material whose truth is a table of other physics (two GGX lobes): the
// chain's fitted GGX is judged by its Ngan error against the table, next to
// the best GGX fit to the table itself, which no parameters can beat, and
// each parameter against the best fit's.
TEST(chain_table_material_ngan_ratio)
{
    const char *tp = fx_truth_variant("virtual-truth.ini", "truth-table.ini", (const char *const[]){
        "[material glossy_plastic]\nmodel = ggx\nkd = 0.35\nks = 0.6\nalpha = 0.05\nF0 = 0.045\n",
        "[material glossy_plastic]\nmodel = table\n"
        "generate = ggx2 albedo=0.35 ks1=0.3 alpha1=0.05 ks2=0.3 alpha2=0.2 F0=0.045\n", NULL }, NULL);
    put("calib/geometry/geometry.json", "{}");
    put("priors_glossy.json", "{\"materials\": [{\"name\": \"glossy_plastic\", \"model\": \"ggx\", \"parameters\": "
        "[{\"name\": \"kd\", \"mean\": 0.35, \"std\": 0.01}, {\"name\": \"ks\", \"mean\": 0.6, \"std\": 0.01},"
        "{\"name\": \"alpha\", \"mean\": 0.05, \"std\": 0.001}, {\"name\": \"F0\", \"mean\": 0.045, \"std\": 0.001}]}]}");
    json_t *prov = model_provenance(0, NULL);
    json_t *doc = eval_chain_compare(test_path("day"), tp, prov);
    CHECK_MSG(doc != NULL, "%s", model_last_error());
    if (doc) {
        const json_t *e = entry(doc, "material_glossy_plastic.ngan_error");
        double chain = field(e, "value"), best = field(e, "truth");
        fprintf(stderr, "  one lobe of 0.6 at alpha 0.05 against two lobes: Ngan error %.5f, best GGX %.5f 1/sr\n",
                chain, best);
        CHECK(best > 0 && chain >= best * (1 - 1e-6));
        CHECK_NEAR(field(entry(doc, "material_glossy_plastic.ngan_error_ratio"), "value"), chain / best, 1e-9);
        // each parameter's truth: the best GGX fit to the table (kd 0.362, ks 0.366, alpha 0.0552, F0 0.048 by
        // the MERL cells: the sharp lobe and the broad one's shoulder in one)
        const double want[4] = { 0.362, 0.366, 0.0552, 0.048 };
        const char *pn[4] = { "kd", "ks", "alpha", "F0" };
        for (int j = 0; j < 4; j++) {
            char nm[96];
            snprintf(nm, sizeof nm, "material_glossy_plastic.%s", pn[j]);
            CHECK_MSG(fabs(field(entry(doc, nm), "truth") - want[j]) < 0.02 * want[j], "%s truth %.5g", pn[j],
                      field(entry(doc, nm), "truth"));
        }
        CHECK_CONTAINS(json_string_value(json_object_get(entry(doc, "material_glossy_plastic.ks"), "note")),
                       "best fit of ggx to its table");
    }
    json_decref(doc);
    json_decref(prov);
}

// A table the fitted model can be: a GGX table (the generator's ggx) fitted as
// GGX with its recipe's parameters. The best fit is the recipe (each
// parameter's truth, z 0), no fit comes within a ratio of its error ~0 (the
// ratio is null, said why), and the excess error is ~0.
TEST(chain_table_within_the_model)
{
    const char *tp = fx_truth_variant("virtual-truth.ini", "truth-ggx-table.ini", (const char *const[]){
        "[material glossy_plastic]\nmodel = ggx\nkd = 0.35\nks = 0.6\nalpha = 0.05\nF0 = 0.045\n",
        "[material glossy_plastic]\nmodel = table\ngenerate = ggx kd=0.35 ks=0.6 alpha=0.08 F0=0.045\n", NULL }, NULL);
    put("calib/geometry/geometry.json", "{}");
    put("priors_glossy.json", "{\"materials\": [{\"name\": \"glossy_plastic\", \"model\": \"ggx\", \"parameters\": "
        "[{\"name\": \"kd\", \"mean\": 0.35, \"std\": 0.01}, {\"name\": \"ks\", \"mean\": 0.6, \"std\": 0.01},"
        "{\"name\": \"alpha\", \"mean\": 0.08, \"std\": 0.001}, {\"name\": \"F0\", \"mean\": 0.045, \"std\": 0.001}]}]}");
    json_t *prov = model_provenance(0, NULL);
    json_t *doc = eval_chain_compare(test_path("day"), tp, prov);
    CHECK_MSG(doc != NULL, "%s", model_last_error());
    if (doc) {
        const double want[4] = { 0.35, 0.6, 0.08, 0.045 };
        const char *pn[4] = { "kd", "ks", "alpha", "F0" };
        for (int j = 0; j < 4; j++) {
            char nm[96];
            snprintf(nm, sizeof nm, "material_glossy_plastic.%s", pn[j]);
            CHECK_MSG(fabs(field(entry(doc, nm), "truth") - want[j]) < 1e-4 * want[j], "%s truth %.6g", pn[j],
                      field(entry(doc, nm), "truth"));
        }
        const json_t *r = entry(doc, "material_glossy_plastic.ngan_error_ratio");
        CHECK(json_is_null(json_object_get(r, "value")));
        CHECK_CONTAINS(json_string_value(json_object_get(r, "note")), "reproduces the truth");
        CHECK(field(entry(doc, "material_glossy_plastic.ngan_error"), "value") < 1e-5);
        const json_t *x = entry(doc, "material_glossy_plastic.ngan_error_excess");
        CHECK(field(x, "value") < 1e-5 && field(x, "sigma") > 1e-4);
        CHECK(json_array_size(json_object_get(json_object_get(doc, "summary"), "ngan_ratio_over_1_2")) == 0);
    }
    json_decref(doc);
    json_decref(prov);
}

// A material whose roughness varies from place to place ([texture] roughness_amplitude 0.3 on the painted
// steel, GGX alpha 0.15): its truth is the best GGX fit to the mean of the two populations, half alpha 0.105 and
// half 0.195 (alpha 0.1234 over Ngan's integral), not the nominal GGX. Priors at the nominal parameters are judged
// against it: alpha's z is (0.15 - 0.1234) / 0.002; the truth agrees with a fit to the same mixture made here.
TEST(chain_roughness_mixture_best_fit)
{
    const char *tp = fx_truth_variant("virtual-truth.ini", "truth-rough.ini", NULL,
                                      "\n[texture painted_steel]\namplitude = 0\nscale_mm = 10\nseed = 7\n"
                                      "roughness_amplitude = 0.3\n");
    put("calib/geometry/geometry.json", "{}");
    put("priors_painted_steel.json", "{\"materials\": [{\"name\": \"painted_steel\", \"model\": \"ggx\", "
        "\"parameters\": [{\"name\": \"kd\", \"mean\": 0.5, \"std\": 0.01}, {\"name\": \"ks\", \"mean\": 0.25, "
        "\"std\": 0.01}, {\"name\": \"alpha\", \"mean\": 0.15, \"std\": 0.002}, {\"name\": \"F0\", \"mean\": 0.04, "
        "\"std\": 0.002}]}]}");
    json_t *prov = model_provenance(0, NULL);
    json_t *doc = eval_chain_compare(test_path("day"), tp, prov);
    CHECK_MSG(doc != NULL, "%s", model_last_error());
    if (doc) {
        const double p0[4] = { 0.5, 0.25, 0.15, 0.04 };
        model_material_t a = { .model = MODEL_BRDF_GGX }, b = { .model = MODEL_BRDF_GGX };
        memcpy(a.p, p0, sizeof p0);
        memcpy(b.p, p0, sizeof p0);
        a.p[2] *= 0.7;
        b.p[2] *= 1.3;
        const model_material_t *mats[2] = { &a, &b };
        const double w[2] = { 0.5, 0.5 };
        fit_mixture_t mix = { 2, mats, w };
        fit_samples_t *s = fit_samples_ngan(fit_mixture_R, &mix, 2);
        fit_brdf_result_t r;
        CHECK(s && fit_brdf(s, MODEL_BRDF_GGX, NULL, &r));
        const char *pn[4] = { "kd", "ks", "alpha", "F0" };
        for (int j = 0; j < 4; j++) {
            char nm[96];
            snprintf(nm, sizeof nm, "material_painted_steel.%s", pn[j]);
            CHECK_REL(field(entry(doc, nm), "truth"), r.p[j], 1e-6);
        }
        const json_t *e = entry(doc, "material_painted_steel.alpha");
        CHECK_NEAR(field(e, "truth"), 0.1234, 0.0005);
        CHECK_NEAR(field(e, "z"), (0.15 - field(e, "truth")) / 0.002, 1e-9);
        CHECK_CONTAINS(json_string_value(json_object_get(e, "note")), "roughness populations");
        const json_t *g = entry(doc, "material_painted_steel.ngan_error");
        fprintf(stderr, "  the nominal GGX against the mixture: Ngan error %.5f, best GGX %.5f 1/sr (alpha %.4f)\n",
                field(g, "value"), field(g, "truth"), field(e, "truth"));
        CHECK_REL(field(g, "truth"), r.ngan_error, 1e-6);
        CHECK(field(g, "value") > 1.2 * field(g, "truth"));
        fit_samples_free(s);
    }
    json_decref(doc);
    json_decref(prov);
}

// The truth's rotation axis: z, or z leaning axis_tilt_deg towards its azimuth.
TEST(chain_truth_axis)
{
    char *truth = example("virtual-truth.ini");
    rig_truth_t *t = rig_truth_load(truth);
    double a[3];
    CHECK(t && rig_truth_axis(t, a));
    if (t) CHECK(a[0] == 0 && a[1] == 0 && a[2] == 1);
    rig_truth_free(t);
    t = rig_truth_load(fx_truth_variant("virtual-truth.ini", "tilted.ini", (const char *const[]){
        "[turntable]\n", "[turntable]\naxis_tilt_deg = 0.2\naxis_tilt_azimuth_deg = 30\n", NULL }, NULL));
    CHECK(t && rig_truth_axis(t, a));
    double th = 0.2 * M_PI / 180, ph = 30 * M_PI / 180;
    CHECK_NEAR(a[0], sin(th) * cos(ph), 1e-12);
    CHECK_NEAR(a[1], sin(th) * sin(ph), 1e-12);
    CHECK_NEAR(a[2], cos(th), 1e-12);
    rig_truth_free(t);
    g_free(truth);
}

TEST(chain_and_demo_truth_errors)
{
    char *out = NULL, *err = NULL;
    char *truth = example("virtual-truth.ini");
    int rc = test_refl_run(60, &out, &err, "chain", test_path("nothing"), "--truth", truth, NULL);
    CHECK(rc == 1);
    CHECK_CONTAINS(err, "nothing/calib/geometry/geometry.json: cannot read it");
    g_free(out);
    g_free(err);
    rc = test_refl_run(60, &out, &err, "chain", test_tmpdir(), "--truth", test_path("none.ini"), NULL);
    CHECK(rc == 1);
    CHECK_CONTAINS(err, "none.ini");
    g_free(out);
    g_free(err);
    rc = test_refl_run(60, &out, &err, "chain", test_tmpdir(), NULL);
    CHECK(rc == 2);
    CHECK_CONTAINS(err, "--truth");
    g_free(out);
    g_free(err);
    rc = test_refl_run(60, &out, &err, "demo", "-o", test_path("d"), "--rig", truth, "--truth", truth, NULL);
    CHECK(rc == 2);
    CHECK_CONTAINS(err, "not both");
    g_free(out);
    g_free(err);
    rc = test_refl_run(60, &out, &err, "demo", "-o", test_path("d"), "--truth", test_path("no-truth.ini"), NULL);
    CHECK(rc == 1);
    CHECK_CONTAINS(err, "no-truth.ini: cannot read the truth file");
    g_free(out);
    g_free(err);
    g_free(truth);
}

// Each lamp's light over the samples' region: the white's kc*I times the
// lamps.json pattern against the truth's (the example truth: isotropic lamps,
// kc 1e-4 per us): a pattern n = 2 toward the origin is off by the largest
// 1 - cos^2 over the region; an isotropic lamp with the right kc*I by 0.
TEST(chain_lamp_irradiance)
{
    char *truth = example("virtual-truth.ini"), *cam = example("camera.cameramodel");
    char *model_text = NULL;
    CHECK(g_file_get_contents(cam, &model_text, NULL, NULL));
    put("calib/geometry/camera.cameramodel", model_text ? model_text : "");
    put("calib/geometry/geometry.json", "{}");
    put("calib/lamps/lamps.json", "{\"lamps\": [{\"name\": \"east\", \"position_mm\": [488.6, 177.9, 600], "
        "\"emission_cos_power\": 2, \"emission_axis\": [-488.6, -177.9, -600], \"emission\": "
        "{\"irradiance_std_pct\": 0.5}}, {\"name\": \"south\", \"position_mm\": [-52.3, -597.7, 480]}]}");
    put("calib/white/white.json", "{\"lamps\": [{\"name\": \"east\", \"kc_I_per_us\": 3.2e5}, "
        "{\"name\": \"south\", \"kc_I_per_us\": 2.9e5}]}");
    json_t *prov = model_provenance(0, NULL);
    json_t *doc = eval_chain_compare(test_path("day"), truth, prov);
    CHECK_MSG(doc != NULL, "%s", model_last_error());
    if (doc) {
        double worst = 0, len = sqrt(488.6 * 488.6 + 177.9 * 177.9 + 600 * 600);
        model_lamp_t L = { .position_mm = { 488.6, 177.9, 600 }, .emission_cos_power = 2,
                           .emission_axis = { -488.6 / len, -177.9 / len, -600 / len } };
        for (int x = -60; x <= 60; x += 20)
            for (int y = -60; y <= 60; y += 20)
                for (int z = 5; z <= 50; z += 45)
                    worst = fmax(worst, 1 - model_lamp_emission(&L, (model_vec3_t){ x, y, z }));
        const json_t *e = entry(doc, "lamp_east.irradiance_max_err");
        CHECK(worst > 0.005);
        CHECK_NEAR(field(e, "value"), 100 * worst, 1e-6);
        CHECK_NEAR(field(e, "sigma"), 0.5, 1e-12);
        e = entry(doc, "lamp_south.irradiance_max_err");
        CHECK_NEAR(field(e, "value"), 0, 1e-9);
        CHECK(json_is_null(json_object_get(e, "sigma")));
    }
    json_decref(doc);
    json_decref(prov);
    g_free(model_text);
    g_free(truth);
    g_free(cam);
}

// The stated sigmas the chain reads: the intrinsics' from the geometry's mrcal
// solve (solution.json, when its intrinsics are the camera's), the camera
// centre's from geometry.json's rig_frame_sigma, the EMVA figures' from
// gain.json's std, the white's total std_rel and its irradiance sigma over
// the samples' region; each z = error / sigma.
TEST(chain_stated_sigmas)
{
    char *truth = example("virtual-truth.ini"), *cam = example("camera.cameramodel");
    char *model_text = NULL;
    CHECK(g_file_get_contents(cam, &model_text, NULL, NULL));
    mrcal_cameramodel_t *m = mrcal_read_cameramodel_file(cam);
    CHECK(m != NULL);
    if (!m) return;
    put("calib/geometry/camera.cameramodel", model_text ? model_text : "");
    double rt_ref_cam[6];
    mrcal_invert_rt(rt_ref_cam, NULL, NULL, m->rt_cam_ref);
    char g[2048], s[1024];
    snprintf(g, sizeof g, "{\"intrinsics\": [%.17g, %.17g, %.17g, %.17g], \"camera_centre_rig_mm\": [%.17g, %.17g, "
             "%.17g], \"axis\": {\"rig_frame_sigma\": {\"camera_centre_mm\": 0.5}}}", m->intrinsics[0],
             m->intrinsics[1], m->intrinsics[2], m->intrinsics[3], rt_ref_cam[3] + 1.0, rt_ref_cam[4], rt_ref_cam[5]);
    put("calib/geometry/geometry.json", g);
    snprintf(s, sizeof s, "{\"intrinsics\": [%.17g, %.17g, %.17g, %.17g, 0], \"intrinsics_core_stdev\": [2, 2, 0.5, "
             "0.25]}", m->intrinsics[0], m->intrinsics[1], m->intrinsics[2], m->intrinsics[3]);
    put("calib/geometry/mrcal/solution.json", s);
    put("calib/lamps/lamps.json", "{\"lamps\": [{\"name\": \"east\", \"position_mm\": [488.6, 177.9, 600]}]}");
    put("calib/gain/gain.json", "{\"system_gain_dn_per_e\": 0.251, \"read_noise_e\": 6.02, \"dark_current_e_per_s\": "
        "19, \"std\": {\"system_gain_dn_per_e\": 0.0005, \"read_noise_e\": 0.01, \"dark_current_e_per_s\": 0.25}}");
    // kc 1e-4 per us, east's I 3.2e9: kc*I 3.2e5 (mean(g) 1 without the small-signal kc)
    put("calib/white/white.json", "{\"lamps\": [{\"name\": \"east\", \"kc_I_per_us\": 3.232e5, \"std_rel\": 0.005, "
        "\"std_of_median_rel\": 0.0001, \"irradiance_samples_region\": {\"std_max_pct\": 0.4}}]}");
    json_t *prov = model_provenance(0, NULL);
    json_t *doc = eval_chain_compare(test_path("day"), truth, prov);
    CHECK_MSG(doc != NULL, "%s", model_last_error());
    if (doc) {
        // the same model: every intrinsic error 0 with its stated sigma
        const double sd[4] = { 2, 2, 0.5, 0.25 };
        static const char *const in[4] = { "camera.fx", "camera.fy", "camera.cx", "camera.cy" };
        for (int k = 0; k < 4; k++) {
            const json_t *e = entry(doc, in[k]);
            CHECK_NEAR(field(e, "sigma"), sd[k], 1e-12);
            CHECK_NEAR(field(e, "z"), 0, 1e-9);
        }
        CHECK_NEAR(field(entry(doc, "camera.centre_rig.x"), "z"), 2.0, 1e-6);
        CHECK_NEAR(field(entry(doc, "camera.centre_rig.y"), "sigma"), 0.5, 1e-12);
        CHECK_NEAR(field(entry(doc, "sensor.system_gain_dn_per_e"), "z"), 2.0, 1e-6);
        CHECK_NEAR(field(entry(doc, "sensor.read_noise_e"), "z"), 2.0, 1e-6);
        CHECK_NEAR(field(entry(doc, "sensor.dark_current_e_per_s"), "z"), -4.0, 1e-6);
        CHECK(json_is_null(json_object_get(entry(doc, "sensor.dsnu_dn"), "sigma")));
        const json_t *e = entry(doc, "white.kc_I_east");
        CHECK_NEAR(field(e, "sigma"), 3.232e5 * 0.005, 1e-6);
        CHECK_NEAR(field(e, "z"), 0.01 / 1.01 / 0.005, 1e-6);
        e = entry(doc, "lamp_east.irradiance_max_err");   // isotropic, at its true place: kc*I's 1 %
        CHECK_NEAR(field(e, "value"), 1.0, 1e-9);
        CHECK_NEAR(field(e, "sigma"), 0.4, 1e-12);
        const json_t *over = json_object_get(json_object_get(doc, "summary"), "z_over_3"), *n;
        size_t i;
        int nover = 0;
        json_array_foreach(over, i, n) nover++;
        CHECK(nover == 1);   // the dark current (z -4) alone
    }
    // a solve of other intrinsics (another camera's) gives no sigma
    snprintf(s, sizeof s, "{\"intrinsics\": [%.17g, 1, 1, 1], \"intrinsics_core_stdev\": [2, 2, 0.5, 0.25]}",
             m->intrinsics[0] + 1);
    put("calib/geometry/mrcal/solution.json", s);
    json_decref(doc);
    doc = eval_chain_compare(test_path("day"), truth, prov);
    CHECK(doc && json_is_null(json_object_get(entry(doc, "camera.fx"), "sigma")));
    json_decref(doc);
    // A sensor whose response bends at the low end and has row noise and hot
    // pixels (the adversarial truth's): the read noise and dark current are
    // compared with what EMVA 1288's definitions read from it, over the dark
    // exposures gain.json names, and the note says so
    put("calib/gain/gain.json", "{\"system_gain_dn_per_e\": 0.25, \"read_noise_e\": 6.088, \"dark_current_e_per_s\": "
        "19.12, \"dark_exposures_us\": [100000, 500000, 1000000, 2000000], \"std\": {\"read_noise_e\": 0.0124, "
        "\"dark_current_e_per_s\": 0.124}}");
    char *adv = example("virtual-truth-adversarial.ini");
    model_ini_t *ini = model_ini_load(adv);
    model_sensor_t ts;
    double rn = NAN, dc = NAN, t4[4] = { 100000, 500000, 1000000, 2000000 };
    CHECK(ini && model_sensor_from_ini(ini, &ts) && model_sensor_dark_measurand(&ts, t4, 4, &rn, &dc));
    doc = eval_chain_compare(test_path("day"), adv, prov);
    CHECK_MSG(doc != NULL, "%s", model_last_error());
    if (doc) {
        const json_t *e = entry(doc, "sensor.read_noise_e");
        CHECK_NEAR(field(e, "truth"), rn, 1e-9);
        CHECK(rn < 6.1 && rn > 6.0);   // 6 e- through the low end's gamma (4 % less), with 2 e- of row noise
        CHECK_CONTAINS(json_string_value(json_object_get(e, "note")), "as EMVA 1288 defines it");
        CHECK_NEAR(field(e, "z"), (6.088 - rn) / 0.0124, 1e-6);
        e = entry(doc, "sensor.dark_current_e_per_s");
        CHECK_NEAR(field(e, "truth"), dc, 1e-9);
        CHECK(dc < 19.5 && dc > 18.5);   // 20 e-/s (+ 0.2 of hot pixels) through the same low end
        CHECK_NEAR(field(entry(doc, "sensor.system_gain_dn_per_e"), "truth"), 0.25, 1e-12);
    }
    json_decref(doc);
    model_ini_free(ini);
    g_free(adv);
    json_decref(prov);
    mrcal_free_cameramodel(&m);
    g_free(model_text);
    g_free(truth);
    g_free(cam);
}
