// tests/test_calib_sample_pose.c — the sample's pose fitted from its own
// frames (calib_sample_pose_fit, calib/sample_pose.c) before the material fit
// (refl fit material --sample-pose): the glossy coupon on the virtual rig
// placed off (the wedge 1.5 deg steeper than the plan says, the coupon shifted
// ~1.5 mm on it), on the matched rig, and in frames too dark to show its
// edges. The calibrations are the truth's: its camera model, lamp positions
// and kc*I (kc_per_us 1e-4 times the lamps' intensities; the reference
// white's own accuracy is test_calib_white's).
#define _GNU_SOURCE
#include <glib.h>
#include <jansson.h>
#include <math.h>
#include <sqlite3.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "calib/calib.h"
#include "model/model.h"
#include "rig/rig.h"
#include "tests/fixtures.h"
#include "tests/test.h"

static char *keep(const char *p) { return g_strdup(p); }

static char *src_file(const char *rel)
{
    char *r = realpath(test_srcdir(), NULL);
    char *p = g_strdup_printf("%s/%s", r ? r : ".", rel);
    free(r);
    return p;
}

// The calibration directory: the truth's camera model, lamp positions and kc*I.
static char *calib_dir(void)
{
    char *src = src_file("examples/camera.cameramodel");
    char *cam = model_read_file(src, NULL);
    g_free(src);
    char *dir = keep(test_path("cal"));
    g_mkdir_with_parents(dir, 0755);
    test_write("cal/camera.cameramodel", cam ? cam : "");
    free(cam);
    test_write("cal/lamps.json",
               "{\"lamps\": [{\"name\": \"east\", \"position_mm\": [488.6, 177.9, 600], \"radius_mm\": 15},"
               " {\"name\": \"south\", \"position_mm\": [-52.3, -597.7, 480], \"radius_mm\": 15},"
               " {\"name\": \"west\", \"position_mm\": [-526.2, -191.5, 520], \"radius_mm\": 15},"
               " {\"name\": \"north\", \"position_mm\": [98.4, 367.1, 700], \"radius_mm\": 15},"
               " {\"name\": \"rim\", \"position_mm\": [-619.8, 65.1, 219.6], \"radius_mm\": 15}]}\n");
    test_write("cal/white.json", "{\"lamps\": [{\"name\": \"east\", \"kc_I_per_us\": 3.2e5}, {\"name\": \"south\", "
               "\"kc_I_per_us\": 2.9e5}, {\"name\": \"west\", \"kc_I_per_us\": 3.1e5}, {\"name\": \"north\", "
               "\"kc_I_per_us\": 3.6e5}, {\"name\": \"rim\", \"kc_I_per_us\": 2.6e5}]}\n");
    return dir;
}

// A rig file on truth (NULL: the example truth file).
static char *rig_file(const char *truth)
{
    char *t = truth ? g_strdup(truth) : src_file("examples/virtual-truth.ini");
    char *text = g_strdup_printf("[rig]\nbackend = virtual\ntruth = %s\nserve = inprocess\ntime_scale = 0.005\n"
                                 "pixel_format = Mono12\n", t);
    char *p = keep(test_write("rig.ini", text));
    g_free(t);
    g_free(text);
    return p;
}

// The glossy coupon on a tilt_deg wedge at the angles of `angles`, one
// exposure of exposure_us: its session directory; *out the capture's output
// (stdout, then stderr: the operator steps' lines).
static char *capture(const char *rig, const char *name, const char *tilt, const char *angles, const char *exposure_us,
                     char **out)
{
    char *plan = g_strdup_printf("[plan]\nname = %s\n[sample]\nname = coupon_glossy_plastic\nkind = material_coupon\n"
                                 "tilt_deg = %s\n[angles]\n%s\n[lamps]\nsets = east; south; west; north; rim; none\n"
                                 "[exposure]\nmode = fixed\nlist_us = %s\n", name, tilt, angles, exposure_us);
    char fn[256];
    snprintf(fn, sizeof fn, "%s.ini", name);
    char *pp = keep(test_write(fn, plan));
    char *dir = keep(test_path(name)), *err = NULL;
    char *o = NULL;
    int rc = test_refl_run(300, &o, &err, "capture", "--yes", pp, "--rig", rig, "-o", dir, NULL);
    CHECK_MSG(rc == 0, "%s", err);
    *out = g_strdup_printf("%s%s", o ? o : "", err ? err : "");
    g_free(o);
    g_free(err);
    g_free(plan);
    g_free(pp);
    return dir;
}

// refl fit material of the session with the glossy coupon's scene (GGX): its
// exit code, stdout and stderr (*out, *err) and the priors' material entry (*doc holds it).
static int fit(const char *session, const char *cal, const char *pose, const char *name, char **out, char **err,
               json_t **doc)
{
    char *scene = src_file("examples/samples/coupon_glossy_plastic.d3d");
    char *pj = keep(test_path(name));
    int rc = test_refl_run(300, out, err, "fit", "material", session, "--calib", cal, "--scene", scene, "--model",
                           "ggx", "--sample-pose", pose, "-o", pj, NULL);
    *doc = rc == 0 ? json_load_file(pj, 0, NULL) : NULL;
    g_free(scene);
    g_free(pj);
    return rc;
}

static json_t *entry(json_t *doc) { return json_array_get(json_object_get(doc, "materials"), 0); }

// Parameter k of the priors entry's sample_pose (value, std).
static double pose_param(json_t *doc, int k, double *sd)
{
    json_t *p = json_array_get(json_object_get(json_object_get(entry(doc), "sample_pose"), "parameters"), (size_t)k);
    if (sd) *sd = json_number_value(json_object_get(p, "std"));
    return p ? json_number_value(json_object_get(p, "value")) : NAN;
}

static double material_param(json_t *doc, const char *name)
{
    json_t *ps = json_object_get(entry(doc), "parameters");
    for (size_t i = 0; i < json_array_size(ps); i++) {
        json_t *p = json_array_get(ps, i);
        if (!strcmp(json_string_value(json_object_get(p, "name")), name))
            return json_number_value(json_object_get(p, "mean"));
    }
    return NAN;
}

// Each pose parameter within 3 std of truth[k], its std sensible (0 < std <
// 0.3 deg for the angles, 0.5 mm for the offsets and height).
static void check_pose(json_t *doc, const double truth[6])
{
    static const char *const nm[6] = { "tilt", "azimuth", "dx", "dy", "dz", "turn" };
    for (int k = 0; k < 6; k++) {
        double sd, v = pose_param(doc, k, &sd);
        fprintf(stderr, "  pose %s: %.4f +- %.4f (truth %.4f, %.1f std)\n", nm[k], v, sd, truth[k],
                fabs(v - truth[k]) / sd);
        CHECK_MSG(sd > 0 && sd < (k < 2 || k == 5 ? 0.3 : 0.5), "pose %s std %g", nm[k], sd);
        CHECK_MSG(fabs(v - truth[k]) <= 3 * sd, "pose %s %.4f +- %.4f: truth %.4f beyond 3 std", nm[k], v, sd,
                  truth[k]);
    }
}

// The coupon on a wedge of 41.5 deg where the plan says 40 (the session's
// plan rewritten: the wedge's angle is off, not the plan), shifted and turned
// by the truth's placement error ([placement] position_sigma_mm 1.5,
// angle_sigma_deg 1; the drawn turn and shift read from the capture's
// operator step): the fitted pose holds
// the truth within 3 std with std < 0.3 deg / 0.5 mm, and the material fitted
// through it is closer to the truth's GGX (kd 0.35, alpha 0.05, ks 0.6) than
// through the nominal pose. With a prior tighter than the placement (0.3 deg)
// the fit is warned of as at the prior's edge.
TEST_LONG(calib_sample_pose_placed_off)
{
    const char *tf = fx_truth_variant("virtual-truth.ini", "truth.ini", NULL,
                                      "\n[placement]\nposition_sigma_mm = 1.5\nangle_sigma_deg = 1\nseed = 3\n");
    char *truth = keep(tf), *rig = rig_file(truth), *cal = calib_dir(), *out = NULL, *err = NULL;
    char *s = capture(rig, "placed", "41.5", "range = 0 300 60", "8000", &out);
    const char *pe = out ? strstr(out, "truth placement error: turn ") : NULL;
    double turn = NAN, dx = NAN, dy = NAN;
    CHECK_MSG(pe && sscanf(pe, "truth placement error: turn %lf deg, shift %lf %lf mm", &turn, &dx, &dy) == 3, "%s",
              out);
    CHECK(hypot(dx, dy) > 1);
    g_free(out);
    char db[4300];
    snprintf(db, sizeof db, "%s/session.sqlite", s);
    sqlite3 *d = NULL;
    CHECK(sqlite3_open(db, &d) == SQLITE_OK);
    CHECK(sqlite3_exec(d, "UPDATE session SET plan_text = replace(plan_text, 'tilt_deg = 41.5', 'tilt_deg = 40')",
                       NULL, NULL, NULL) == SQLITE_OK);
    CHECK(sqlite3_changes(d) == 1);
    sqlite3_close(d);
    json_t *df = NULL, *dn = NULL;
    int rc = fit(s, cal, "fit", "pf.json", &out, &err, &df);
    CHECK_MSG(rc == 0 && df, "%s", err);
    CHECK_CONTAINS(out, "sample pose fitted from");
    CHECK_CONTAINS(out, "tilt 41.");
    g_free(out);
    g_free(err);
    const double t[6] = { 41.5, 0, dx, dy, 0, turn };
    if (df) {
        check_pose(df, t);
        CHECK(!strcmp(json_string_value(json_object_get(json_object_get(entry(df), "sample_pose"), "mode")), "fit"));
    }
    // a fixture's tolerance tighter than the placement (0.3 deg for 1.5): warned of
    char *scene = src_file("examples/samples/coupon_glossy_plastic.d3d");
    rc = test_refl_run(300, &out, &err, "fit", "material", s, "--calib", cal, "--scene", scene, "--model", "ggx",
                       "--pose-sigma-deg", "0.3", "-o", test_path("pt.json"), NULL);
    CHECK_MSG(rc == 0, "%s", err);
    CHECK_CONTAINS(out, "warning: sample pose: the fitted pose is at the edge of the fixture's tolerance");
    CHECK_CONTAINS(err, "the fitted pose is at the edge of the fixture's tolerance");
    g_free(scene);
    g_free(out);
    g_free(err);
    rc = fit(s, cal, "nominal", "pn.json", &out, &err, &dn);
    CHECK_MSG(rc == 0 && dn, "%s", err);
    CHECK_CONTAINS(out, "the plan's nominal wedge (tilt 40 deg");
    g_free(out);
    g_free(err);
    static const char *const names[3] = { "kd", "alpha", "ks" };
    static const double truth_p[3] = { 0.35, 0.05, 0.6 };
    for (int k = 0; df && dn && k < 3; k++) {
        double ef = fabs(material_param(df, names[k]) / truth_p[k] - 1);
        double en = fabs(material_param(dn, names[k]) / truth_p[k] - 1);
        fprintf(stderr, "  %s: %.2f %% off with the fitted pose, %.2f %% with the nominal\n", names[k], 100 * ef,
                100 * en);
        CHECK_MSG(ef < en, "%s: %.4g off with the fitted pose, %.4g with the nominal", names[k], ef, en);
        CHECK_MSG(ef < 0.05, "%s: %.2f %% off the truth with the fitted pose", names[k], 100 * ef);
    }
    json_decref(df);
    json_decref(dn);
    g_free(truth);
    g_free(rig);
    g_free(cal);
    g_free(s);
}

// The matched rig (the coupon where the plan says): the fitted pose within 3
// std of the nominal; bad pose options are usage errors.
TEST_LONG(calib_sample_pose_matched)
{
    char *rig = rig_file(NULL), *cal = calib_dir(), *out = NULL, *err = NULL;
    char *s = capture(rig, "matched", "40", "range = 0 300 60", "8000", &out);
    g_free(out);
    json_t *df = NULL;
    int rc = fit(s, cal, "fit", "pm.json", &out, &err, &df);
    CHECK_MSG(rc == 0 && df, "%s", err);
    CHECK_CONTAINS(out, "sample pose fitted from");
    g_free(out);
    g_free(err);
    const double t[6] = { 40, 0, 0, 0, 0, 0 };
    if (df) {
        check_pose(df, t);
        CHECK(!json_is_true(json_object_get(json_object_get(entry(df), "sample_pose"), "at_prior_edge")));
    }
    json_decref(df);
    static const char *const bad[3][2] = { { "--sample-pose", "guess" }, { "--pose-sigma-deg", "0" },
                                           { "--pose-sigma-mm", "-1" } };
    for (int k = 0; k < 3; k++) {
        rc = test_refl_run(60, &out, &err, "fit", "material", s, "--calib", cal, "-o", test_path("x.json"),
                           bad[k][0], bad[k][1], NULL);
        CHECK_MSG(rc == 2, "%s %s: exit %d", bad[k][0], bad[k][1], rc);
        CHECK_CONTAINS(err, bad[k][0]);
        g_free(out);
        g_free(err);
    }
    g_free(rig);
    g_free(cal);
    g_free(s);
}

// Frames too dark to show the coupon's outline (20 us): the nominal wedge
// pose is kept, said so (the library's result, and refl fit material's
// warning before the observations find nothing to fit either).
TEST_LONG(calib_sample_pose_dark_keeps_nominal)
{
    char *rig = rig_file(NULL), *cal = calib_dir(), *out = NULL, *err = NULL;
    char *s = capture(rig, "dark", "40", "list = 0 120 240", "20", &out);
    g_free(out);
    calib_set_t *c = calib_set_load(cal, true);
    rig_session_t *ss = rig_session_open(s);
    rig_plan_t *p = ss ? rig_plan_parse(ss->plan_text, strlen(ss->plan_text), s) : NULL;
    char *sp = src_file("examples/samples/coupon_glossy_plastic.d3d");
    model_scene_options_t so = MODEL_SCENE_OPTIONS_DEFAULT;
    model_scene_t *scene = model_scene_load(sp, &so);
    CHECK(c && ss && p && scene);
    if (c && ss && p && scene) {
        calib_sample_pose_t ps;
        CHECK(calib_sample_pose_fit(ss, p, c, scene, NULL, &ps));
        CHECK(ps.tried && !ps.fitted);
        CHECK_CONTAINS(ps.note, "edges are too weak");
        CHECK_CONTAINS(ps.note, "the nominal wedge pose is kept (tilt 40 deg");
        CHECK(ps.p[0] == 40 && ps.p[1] == 0 && ps.p[2] == 0 && ps.p[3] == 0 && ps.p[4] == 0 && ps.p[5] == 0);
        json_t *j = calib_sample_pose_json(&ps);
        CHECK(!strcmp(json_string_value(json_object_get(j, "mode")), "nominal (fit failed)"));
        json_decref(j);
    }
    model_scene_free(scene);
    rig_plan_free(p);
    rig_session_free(ss);
    calib_set_free(c);
    json_t *df = NULL;
    int rc = fit(s, cal, "fit", "pd.json", &out, &err, &df);
    CHECK(rc == 1);
    CHECK_CONTAINS(err, "sample pose: the sample's edges are too weak");
    CHECK_CONTAINS(err, "the nominal wedge pose is kept");
    json_decref(df);
    g_free(out);
    g_free(err);
    g_free(sp);
    g_free(rig);
    g_free(cal);
    g_free(s);
}
