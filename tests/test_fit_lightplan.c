// tests/test_fit_lightplan.c — light planning (fit/lightplan/lightplan.h): the Sobel
// response of known steps, glare and saturation steering the choice, the
// prediction against a Sobel detector on the virtual rig's frames, and the
// capture plan of several views captured on the virtual rig.
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include <glib.h>
#include <jansson.h>

#include "fit/lightplan/lightplan.h"
#include "fit/eval/lab.h"
#include "model/model.h"
#include "model/base/report.h"
#include "rig/rig.h"
#include "tests/test.h"

// An ideal step of 50 DN: the detector's median response is 4.0 x 50 along an
// axis-aligned edge and 4.24 x 50 along a diagonal one (sampled on the pixel
// grid the diagonal step is not ideal: 3 % tolerance).
TEST(lightplan_sobel_known_steps)
{
    const int W = 200, H = 200;
    float *f = malloc(sizeof(float) * W * H);
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++) f[y * W + x] = x < 100 ? 100 : 150;   // step between x = 99 and 100
    lightplan_segment_t s = { .q0 = { 99.5, 20 }, .q1 = { 99.5, 180 }, .length_px = 160, .detectable = true };
    double m, agreement = NAN;
    bool found;
    CHECK(lightplan_sobel_check(&s, 1, f, W, H, 199, &found, &m, &agreement));
    CHECK_NEAR(agreement, 1, 0);
    CHECK_NEAR(m, 200, 1e-9);
    CHECK(found);
    CHECK(lightplan_sobel_check(&s, 1, f, W, H, 201, &found, &m, &agreement));
    CHECK_NEAR(agreement, 0, 0);   // below the threshold: disagrees
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++) f[y * W + x] = x + y < 200 ? 100 : 150;
    lightplan_segment_t d = { .q0 = { 30, 170 }, .q1 = { 170, 30 }, .length_px = 198, .detectable = true };
    CHECK(lightplan_sobel_check(&d, 1, f, W, H, 0, &found, &m, &agreement));
    CHECK_REL(m, 4.24 * 50, 0.03);
    // too short to judge
    lightplan_segment_t t = { .q0 = { 99.5, 20 }, .q1 = { 99.5, 25 }, .length_px = 5 };
    CHECK(lightplan_sobel_check(&t, 1, f, W, H, 0, &found, &m, &agreement) && isnan(agreement));
    free(f);
}

// A glossy plate seen by the camera, one candidate lamp at the camera's
// mirror position (glare on the plate), another off to the side: the plan
// counts the glare and chooses the other lamp; the longest exposure
// saturates and is not chosen.
TEST(lightplan_glare_and_saturation_steer_the_choice)
{
    char path[4096];
    snprintf(path, sizeof path, "%s/examples/camera.cameramodel", test_srcdir());
    model_camera_t *cam = model_camera_load(path);
    model_vec3_t c = model_camera_centre_world(cam);
    const char *scene_txt = "1 -150 -150 0\n2 150 -150 0\n3 150 150 0\n4 -150 150 0\nFaces:\n@material gloss\n1 2 3 4.\n";
    model_scene_t *sc = model_scene_parse_d3d(scene_txt, strlen(scene_txt), "plate.d3d", NULL);
    const char *mt = "[material gloss]\nmodel = ggx\nkd = 0.3\nks = 0.5\nalpha = 0.1\nF0 = 0.04\n";
    model_materials_t *mm = model_materials_parse(mt, strlen(mt), "m.ini");
    char lt[512];
    snprintf(lt, sizeof lt, "[lamp mirror]\nposition_mm = %.3f %.3f %.3f\nintensity = 3e9\n"
             "[lamp side]\nposition_mm = %.3f %.3f %.3f\nintensity = 3e9\n", -c.x, -c.y, c.z, c.y, -c.x, c.z);
    model_lamps_t *l = model_lamps_parse(lt, strlen(lt), "l.ini");
    CHECK(cam && sc && mm && l);
    if (!(cam && sc && mm && l)) return;
    const model_material_t *mats[1];
    CHECK(model_resolve_materials(sc, mm, mats));
    double A[2] = { 1e-4 * 3e9, 1e-4 * 3e9 }, exps[3] = { 1000, 4000, 400000 };
    lightplan_sensor_t s = { .offset_dn = 64, .saturation_dn = 4095, .K_dn_per_e = 0.25, .read_noise_e = 6 };
    lightplan_options_t o = lightplan_defaults();
    lightplan_result_t r;
    CHECK(lightplan_run(sc, cam, l, A, mats, &s, exps, 3, &o, &r));
    if (r.nconfigs) {
        const lightplan_config_t *b = &r.configs[r.best];
        CHECK(b->feasible);
        CHECK(b->mask == 2);            // the side lamp alone
        CHECK(b->exposure_us < 400000);
        CHECK(b->glare_pix == 0 && b->saturated_pix == 0);
        bool mirror_glare = false, long_saturates = false;
        for (int k = 0; k < r.nconfigs; k++) {
            if ((r.configs[k].mask & 1) && r.configs[k].glare_pix > 100) mirror_glare = true;
            if (r.configs[k].exposure_us == 400000 && r.configs[k].saturated_pix > 0) long_saturates = true;
        }
        CHECK(mirror_glare);
        // the glare map: the mirror lamp (bit 0) glares on the plate, the side lamp (bit 1) nowhere
        long g0 = 0, g1 = 0;
        for (size_t p = 0; p < (size_t)r.W * r.H; p++) {
            g0 += r.glare[p] & 1;
            g1 += (r.glare[p] >> 1) & 1;
        }
        CHECK(g0 > 400 && g1 == 0);
        CHECK(long_saturates);
        CHECK(r.nfaces == 1 && r.faces[0].npix > 1000 && r.faces[0].usable_frac > 0.9);
        // the plate's boundary is an edge against the background: detectable when lit
        CHECK(b->n_detectable >= 3);
    }
    lightplan_result_free(&r);
    model_lamps_free(l);
    model_materials_free(mm);
    model_scene_free(sc);
    model_camera_free(cam);
}

// The T-stiffener on the virtual rig: the chosen configuration is free of
// glare and saturation, and a Sobel detector on the rig's frames (the chosen
// set and each single lamp, richer physics than the prediction) agrees with
// the predicted detectability on at least 94 % of the segments (the
// disagreements are printed; REFL_TEST_VERBOSE=1 prints every segment). The
// rig renders the indirect light near face edges at full resolution: at the
// concave junctions of web and plate (faces 2/7, 2/8, 13/7, 13/8, 14/8,
// 14/12) it measures 1.3 to 6 times the planner's one-bounce prediction,
// which puts two weak edges above the threshold the planner predicts below it
// (94.4 %); the planner's light at concave junctions is an open question
// (README: refl plan lamps).
TEST(lightplan_virtual_rig_agreement)
{
    char scene[4096], cam[4096], lamps[4096], mats[4096], truth[4096];
    snprintf(scene, sizeof scene, "%s/examples/t_stiffener.d3d", test_srcdir());
    snprintf(cam, sizeof cam, "%s/examples/camera.cameramodel", test_srcdir());
    snprintf(lamps, sizeof lamps, "%s/examples/lamps.ini", test_srcdir());
    snprintf(mats, sizeof mats, "%s/examples/materials.ini", test_srcdir());
    snprintf(truth, sizeof truth, "%s/examples/virtual-truth.ini", test_srcdir());
    // the gain calibration a lab would have (the rig's own maps, noise-free)
    const double a0 = 0;
    eval_lab_t *L = eval_lab_open(truth, "t_stiffener", &a0, 1, 1000, 0, false);
    CHECK_MSG(L != NULL, "verify lab: %s", model_last_error());
    if (!L) return;
    const verify_camera_t *vc = eval_lab_camera(L);
    int W = eval_lab_width(L), H = eval_lab_height(L);
    char *gdir = g_strdup(test_path("gain"));
    g_mkdir_with_parents(gdir, 0755);
    char buf[256], kc[64];
    snprintf(buf, sizeof buf, "{\"system_gain_dn_per_e\": %.10g, \"read_noise_e\": %.10g, \"saturation_dn\": %.10g}",
             vc->K_dn_per_e, vc->read_noise_e, vc->saturation_dn);
    test_write("gain/gain.json", buf);
    CHECK(model_tiff_write_float(test_path("gain/offset_dn.tiff"), W, H, vc->offset_dn, NULL));
    CHECK(model_tiff_write_float(test_path("gain/prnu_gain.tiff"), W, H, vc->flat, NULL));
    // kc*I as a white calibration through this flat field measures it
    snprintf(kc, sizeof kc, "%.12g", eval_lab_A(L)[0] / eval_lab_lamps(L)->lamps[0].intensity);
    eval_lab_free(L);
    const char *dir = test_path("plan");
    char *out = NULL, *err = NULL;
    int rc = test_refl_run(300, &out, &err, "plan", "lamps", scene, "--camera", cam, "--lamps", lamps, "--kc-per-us",
                           kc, "--materials", mats, "--gain-calib", gdir, "--check-virtual", truth, "--no-report",
                           "-o", dir, NULL);
    g_free(gdir);
    CHECK_MSG(rc == 0, "rc %d: %s", rc, err);
    CHECK_CONTAINS(out, "chosen lamps");
    g_free(out);
    g_free(err);
    char *jp = g_strdup_printf("%s/plan.json", dir);
    json_t *j = json_load_file(jp, 0, NULL);
    g_free(jp);
    CHECK(j != NULL);
    if (!j) return;
    CHECK_MSG(model_json_format_check(j, "plan.json", "refl-lightplan", 1, NULL), "%s", model_last_error());
    json_t *ch = json_object_get(j, "chosen");
    CHECK(json_is_true(json_object_get(ch, "feasible")));
    CHECK(json_integer_value(json_object_get(ch, "n_detectable")) >= 15);
    json_t *chk = json_object_get(j, "virtual_rig_check");
    double ag = json_number_value(json_object_get(chk, "agreement"));
    CHECK_MSG(ag >= 0.94, "agreement %.3f", ag);
    printf("  agreement %.1f %% (target 94 %%)\n", 100 * ag);
    if (ag < 0.94 || getenv("REFL_TEST_VERBOSE")) {
        json_t *cs = json_object_get(chk, "configurations");
        for (size_t c = 0; c < json_array_size(cs); c++) {
            json_t *sgs = json_object_get(json_array_get(cs, c), "segments");
            for (size_t k = 0; k < json_array_size(sgs); k++) {
                json_t *g = json_array_get(sgs, k), *fd = json_object_get(g, "found");
                bool dis = json_is_boolean(fd) && json_is_true(fd) != json_is_true(json_object_get(g, "detectable"));
                if (dis || (getenv("REFL_TEST_VERBOSE") && json_is_boolean(fd)))
                    printf("  %s: lamps %s segment %zu (faces %s/%s, %.0f px): predicted %.1f measured %.1f DN\n",
                           dis ? "disagreement" : "agreement", json_string_value(json_object_get(json_array_get(cs, c), "lamps")), k,
                           json_string_value(json_object_get(g, "face_side0")),
                           json_string_value(json_object_get(g, "face_side1")),
                           json_number_value(json_object_get(g, "length_px")),
                           json_number_value(json_object_get(g, "sobel_predicted_dn")),
                           json_number_value(json_object_get(g, "sobel_measured_dn")));
            }
        }
    }
    CHECK(json_array_size(json_object_get(chk, "configurations")) >= 4);
    CHECK(json_array_size(json_object_get(j, "faces")) >= 6);
    // the warning when the chosen exposure is at an edge of the searched ones (the default list)
    double ex = json_number_value(json_object_get(ch, "exposure_us")), lo = INFINITY, hi = -INFINITY;
    json_t *cfs = json_object_get(j, "configurations");
    for (size_t c = 0; c < json_array_size(cfs); c++) {
        double x = json_number_value(json_object_get(json_array_get(cfs, c), "exposure_us"));
        lo = fmin(lo, x), hi = fmax(hi, x);
    }
    const char *edge = json_string_value(json_object_get(ch, "exposure_at_edge"));
    json_t *warn = json_object_get(j, "warnings");
    CHECK(json_is_array(warn));
    if (ex == hi || ex == lo) {
        CHECK(edge && !strcmp(edge, ex == hi ? "longest" : "shortest"));
        CHECK_CONTAINS(json_string_value(json_array_get(warn, 0)), ex == hi ? "is the longest" : "is the shortest");
    } else {
        CHECK(edge == NULL);
    }
    // the one view's capture plan: angle 0, the chosen lamps and exposure, bound to the virtual rig
    char *pp = g_strdup_printf("%s/capture_plan.ini", dir);
    rig_plan_t *p = rig_plan_load(pp);
    g_free(pp);
    CHECK_MSG(p != NULL, "%s", model_last_error());
    if (p) {
        // step 0: the operator places the workpiece
        CHECK(p->nangles == 1 && p->angles_deg[0] == 0 && p->nsteps == 3 && p->steps[0].kind == RIG_STEP_OPERATOR);
        CHECK(p->steps[1].kind == RIG_STEP_LIGHT);
        CHECK(!strcmp(p->steps[1].lamps, json_string_value(json_object_get(ch, "lamps"))));
        CHECK(p->steps[1].exposure_us == json_number_value(json_object_get(ch, "exposure_us")));
        CHECK(p->steps[2].kind == RIG_STEP_DARK);
    }
    rig_plan_free(p);
    json_decref(j);
    // usage errors
    CHECK(test_refl_run(30, &out, &err, "plan", "lamps", scene, "--camera", cam, "--lamps", lamps, "--materials",
                        mats, "-o", dir, NULL) == 2);
    CHECK_CONTAINS(err, "--kc-per-us");
    g_free(out);
    g_free(err);
    CHECK(test_refl_run(30, &out, &err, "plan", "lamps", scene, "--camera", cam, "--lamps", lamps, "--kc-per-us",
                        "1e-4", "--materials", mats, "--exposures-us", "100,x", "-o", dir, NULL) == 2);
    CHECK_CONTAINS(err, "--exposures-us");
    g_free(out);
    g_free(err);
    // two exposures only: the chosen one is at an edge, said on stderr and in plan.json
    const char *dir2 = test_path("plan2");
    rc = test_refl_run(300, &out, &err, "plan", "lamps", scene, "--camera", cam, "--lamps", lamps, "--kc-per-us", kc,
                       "--materials", mats, "--exposures-us", "4000,8000", "--no-report", "-o", dir2, NULL);
    CHECK_MSG(rc == 0, "rc %d: %s", rc, err);
    CHECK_CONTAINS(err, "warning: the chosen exposure");
    g_free(out);
    g_free(err);
    jp = g_strdup_printf("%s/plan.json", dir2);
    j = json_load_file(jp, 0, NULL);
    g_free(jp);
    CHECK(j && json_string_value(json_object_get(json_object_get(j, "chosen"), "exposure_at_edge")));
    CHECK(j && json_array_size(json_object_get(j, "warnings")) >= 1);
    json_decref(j);
}

// `refl demo` runs scripts/demo (the whole lab day; make demo runs it): its
// usage and its refusal of stray arguments (the run itself is make demo's).
TEST(demo_command_usage)
{
    char *out = NULL, *err = NULL;
    CHECK(test_refl_run(30, &out, &err, "demo", "--help", NULL) == 0);
    CHECK_CONTAINS(out, "refl demo [-o DIR]");
    g_free(out);
    g_free(err);
    CHECK(test_refl_run(30, &out, &err, "demo", "stray", NULL) == 2);
    CHECK_CONTAINS(err, "stray");
    g_free(out);
    g_free(err);
}

// Several views (--angles-deg): each planned on its own (its directory and
// plan.json), the summary lists them, and capture_plan.ini holds those angles
// with each view's chosen lamps and exposure in a [view N] section; refl
// capture takes the plan as it is on the virtual rig and every light frame has
// its view's planned lamps and exposure.
TEST(lightplan_views_capture_plan)
{
    char scene[4096], cam[4096], lamps[4096], mats[4096], truth[4096];
    snprintf(scene, sizeof scene, "%s/examples/t_stiffener.d3d", test_srcdir());
    snprintf(cam, sizeof cam, "%s/examples/camera.cameramodel", test_srcdir());
    snprintf(lamps, sizeof lamps, "%s/examples/lamps.ini", test_srcdir());
    snprintf(mats, sizeof mats, "%s/examples/materials.ini", test_srcdir());
    snprintf(truth, sizeof truth, "%s/examples/virtual-truth.ini", test_srcdir());
    char *dir = g_strdup(test_path("views"));
    char *out = NULL, *err = NULL;
    int rc = test_refl_run(300, &out, &err, "plan", "lamps", scene, "--camera-model", cam, "--lamps-file", lamps, "--kc-per-us",
                           "1e-4", "--materials", mats, "--angles-deg", "0,135", "--exposures-us", "2000,6000",
                           "--max-lamps", "2", "--check-virtual", truth, "--no-report", "-o", dir, NULL);
    CHECK_MSG(rc == 0, "rc %d: %s", rc, err);
    CHECK_CONTAINS(out, "capture plan:");
    CHECK_CONTAINS(out, "(binds to the virtual rig)");
    g_free(out);
    g_free(err);
    // the summary and each view's own plan
    char *jp = g_strdup_printf("%s/plan.json", dir);
    json_t *j = json_load_file(jp, 0, NULL);
    g_free(jp);
    CHECK(j != NULL);
    json_t *views = json_object_get(j, "views");
    CHECK(json_array_size(views) == 2);
    int version = 0;
    CHECK_MSG(model_json_format_check(j, "plan.json", "refl-lightplan", 1, &version) && version == 1, "%s",
              model_last_error());
    CHECK(json_is_true(json_object_get(j, "capture_plan_binds_to_virtual_rig")));
    char want_lamps[2][512] = { "", "" };
    double want_us[2] = { 0, 0 };
    for (size_t k = 0; k < json_array_size(views) && k < 2; k++) {
        json_t *v = json_array_get(views, k);
        CHECK(json_number_value(json_object_get(v, "turntable_deg")) == (k ? 135 : 0));
        snprintf(want_lamps[k], sizeof want_lamps[k], "%s", json_string_value(json_object_get(v, "lamps")));
        want_us[k] = json_number_value(json_object_get(v, "exposure_us"));
        char *vp = g_strdup_printf("%s/%s/plan.json", dir, json_string_value(json_object_get(v, "dir")));
        json_t *vj = json_load_file(vp, 0, NULL);
        CHECK_MSG(vj != NULL, "%s", vp);
        if (vj) {
            json_t *ch = json_object_get(vj, "chosen");
            CHECK(!strcmp(json_string_value(json_object_get(ch, "lamps")), want_lamps[k]));
            CHECK(json_number_value(json_object_get(ch, "exposure_us")) == want_us[k]);
            CHECK(json_number_value(json_object_get(vj, "turntable_deg")) == (k ? 135 : 0));
            CHECK(json_object_get(vj, "virtual_rig_check") != NULL);
        }
        json_decref(vj);
        g_free(vp);
        CHECK(strchr(want_lamps[k], '+') == NULL || strchr(strchr(want_lamps[k], '+') + 1, '+') == NULL);  // max 2
    }
    // the summary page's headline says in words which views miss the virtual-rig check's target and by how much
    int below = 0;
    GString *want = g_string_new("");
    for (size_t k = 0; k < json_array_size(views) && k < 2; k++) {
        json_t *v = json_array_get(views, k);
        char *vp = g_strdup_printf("%s/%s/plan.json", dir, json_string_value(json_object_get(v, "dir")));
        json_t *vj = json_load_file(vp, 0, NULL);
        double ag = json_number_value(json_object_get(v, "check_agreement"));
        double tg = json_number_value(json_object_get(json_object_get(vj, "virtual_rig_check"), "target"));
        if (ag < tg) {
            g_string_append_printf(want, "%s%g°: %.1f %%, %.1f points short", below ? "; " : "",
                                   json_number_value(json_object_get(v, "turntable_deg")), 100 * ag, 100 * (tg - ag));
            below++;
        }
        json_decref(vj);
        g_free(vp);
    }
    CHECK(model_run_script("plan_lamps_report.py", dir, NULL) == 0);
    char *hp = g_strdup_printf("%s/index.html", dir), *html = model_read_file(hp, NULL);
    CHECK(html && strstr(html, "id=\"headline\""));
    if (html && below) CHECK_MSG(strstr(html, want->str) != NULL, "headline lacks '%s'", want->str);
    if (html && !below) CHECK_CONTAINS(html, "virtual-rig check: every view reaches the target");
    free(html);
    g_free(hp);
    g_string_free(want, TRUE);
    json_decref(j);
    // the capture plan: those angles, each view's lamps and exposure
    char *pp = g_strdup_printf("%s/capture_plan.ini", dir);
    rig_plan_t *p = rig_plan_load(pp);
    CHECK_MSG(p != NULL, "%s", model_last_error());
    if (p) {
        CHECK(p->nangles == 2 && p->angles_deg[0] == 0 && p->angles_deg[1] == 135);
        CHECK(!strcmp(p->sample, "t_stiffener") && !strcmp(p->sample_kind, "workpiece"));
        CHECK(!p->auto_exposure && p->gain == 0 && !strcmp(p->pixel_format, "Mono12"));
        CHECK(p->nviews == 2 && p->nsteps == 4 && p->steps[0].kind == RIG_STEP_OPERATOR);
        int light = 0;
        for (int i = 0; i < p->nsteps; i++) {
            const rig_step_t *s = &p->steps[i];
            if (s->kind != RIG_STEP_LIGHT) continue;
            light++;
            CHECK(!strcmp(s->lamps, want_lamps[s->angle_index]) && s->exposure_us == want_us[s->angle_index]);
        }
        CHECK(light == 2 && p->steps[3].kind == RIG_STEP_DARK);
        CHECK_CONTAINS(p->text, "# command: refl plan lamps ");
        CHECK_CONTAINS(p->text, "scene ");
    }
    rig_plan_free(p);
    // refl capture takes it as it is
    char *abs_truth = g_canonicalize_filename(truth, NULL);
    char *rig = g_strdup_printf("[rig]\nbackend = virtual\nserve = inprocess\ntruth = %s\ntime_scale = 0.01\n",
                                abs_truth);
    g_free(abs_truth);
    test_write("views_rig.ini", rig);
    g_free(rig);
    char *sess = g_strdup(test_path("views_session"));
    rc = test_refl_run(300, &out, &err, "capture", pp, "--rig", test_path("views_rig.ini"), "-o", sess, "--progress",
                       "lines", "--yes", NULL);
    CHECK_MSG(rc == 0, "rc %d: %s", rc, err);
    g_free(out);
    g_free(err);
    rig_session_t *s = rig_session_open(sess);
    CHECK_MSG(s != NULL, "%s", model_last_error());
    if (s) {
        CHECK(s->n == 3);
        int seen = 0;
        for (int i = 0; i < s->n; i++) {
            const rig_frame_row_t *f = &s->rows[i];
            if (!strcmp(f->lamps, "none")) continue;
            int k = f->commanded_deg == 135;
            CHECK_MSG(!strcmp(f->lamps, want_lamps[k]) && f->exposure_us == want_us[k],
                      "frame %d at %g deg: lamps %s, %g us; planned %s, %g us", i, f->commanded_deg, f->lamps,
                      f->exposure_us, want_lamps[k], want_us[k]);
            seen |= 1 << k;
        }
        CHECK(seen == 3);
    }
    rig_session_free(s);
    // usage: one view or several, not both; angles as numbers
    CHECK(test_refl_run(30, &out, &err, "plan", "lamps", scene, "--camera-model", cam, "--lamps-file", lamps, "--kc-per-us",
                        "1e-4", "--materials", mats, "--angle-deg", "0", "--angles-deg", "0,90", "-o", dir, NULL) == 2);
    CHECK_CONTAINS(err, "not both");
    g_free(out);
    g_free(err);
    CHECK(test_refl_run(30, &out, &err, "plan", "lamps", scene, "--camera-model", cam, "--lamps-file", lamps, "--kc-per-us",
                        "1e-4", "--materials", mats, "--angles-deg", "0,ninety", "-o", dir, NULL) == 2);
    CHECK_CONTAINS(err, "--angles-deg");
    g_free(out);
    g_free(err);
    // a pixel format the capture plan cannot hold is a usage error
    CHECK(test_refl_run(60, &out, &err, "plan", "lamps", scene, "--camera-model", cam, "--lamps-file", lamps, "--kc-per-us",
                        "1e-4", "--materials", mats, "--pixel-format", "Mono99", "-o", dir, NULL) == 2);
    CHECK_CONTAINS(err, "--pixel-format Mono99");
    g_free(out);
    g_free(err);
    g_free(sess);
    g_free(pp);
    g_free(dir);
}

// The lens's blur in the Sobel prediction: each segment's factor is the
// blurred, footprint-integrated step's (model_edge_sobel_step, best phase),
// so a PSF of 0.8 px scales every predicted response by that factor's ratio
// and leaves the contrast alone; refl plan lamps takes sigma from the
// geometry.json beside --camera (refl calib geometry's psf), --psf-sigma-px
// overrides it, and plan.json and the report say which.
TEST(lightplan_psf_in_the_sobel_prediction)
{
    char path[4096];
    snprintf(path, sizeof path, "%s/examples/camera.cameramodel", test_srcdir());
    model_camera_t *cam = model_camera_load(path);
    const char *scene_txt =
        "1 -150 -150 0\n2 150 -150 0\n3 150 150 0\n4 -150 150 0\nFaces:\n@material matte\n1 2 3 4.\n";
    const char *mt = "[material matte]\nmodel = lambert\nkd = 0.2\n";
    const char *lt = "[lamp side]\nposition_mm = 400 -300 600\nintensity = 3e9\n";
    model_scene_t *sc = model_scene_parse_d3d(scene_txt, strlen(scene_txt), "plate.d3d", NULL);
    model_materials_t *mm = model_materials_parse(mt, strlen(mt), "m.ini");
    model_lamps_t *l = model_lamps_parse(lt, strlen(lt), "l.ini");
    CHECK(cam && sc && mm && l);
    if (!(cam && sc && mm && l)) return;
    const model_material_t *mats[1];
    CHECK(model_resolve_materials(sc, mm, mats));
    double A[1] = { 1e-4 * 3e9 }, exps[1] = { 2000 };
    lightplan_sensor_t s = { .offset_dn = 64, .saturation_dn = 4095 };
    lightplan_options_t o = lightplan_defaults();
    o.ir_samples = 0;
    lightplan_result_t r0, r8;
    CHECK(lightplan_run(sc, cam, l, A, mats, &s, exps, 1, &o, &r0));
    o.psf_sigma_px = 0.8;
    CHECK(lightplan_run(sc, cam, l, A, mats, &s, exps, 1, &o, &r8));
    CHECK(r0.nsegments >= 4 && r0.nsegments == r8.nsegments);
    for (int k = 0; k < r0.nsegments && k < r8.nsegments; k++) {
        const lightplan_segment_t *a = &r0.segments[k], *b = &r8.segments[k];
        double normal = atan2(a->q1[1] - a->q0[1], a->q1[0] - a->q0[0]) + M_PI / 2;
        CHECK_NEAR(a->sobel_factor, model_edge_sobel_step(normal, 0).best, 1e-12);
        CHECK_NEAR(b->sobel_factor, model_edge_sobel_step(normal, 0.8).best, 1e-12);
        CHECK(a->sobel_factor >= 4.0 - 1e-9 && a->sobel_factor <= 4.31);
        CHECK(b->sobel_factor > 2.9 && b->sobel_factor < 3.1);
        CHECK_NEAR(a->dP, b->dP, 1e-9 * fabs(a->dP) + 1e-12);
        CHECK_NEAR(b->gradient / a->gradient, b->sobel_factor / a->sobel_factor, 1e-9);
    }
    lightplan_result_free(&r0);
    lightplan_result_free(&r8);
    o.psf_sigma_px = -1;
    CHECK(!lightplan_run(sc, cam, l, A, mats, &s, exps, 1, &o, &r0));
    CHECK_CONTAINS(model_last_error(), "sigma");
    model_lamps_free(l);
    model_materials_free(mm);
    model_scene_free(sc);
    model_camera_free(cam);

    // refl plan lamps: sigma from the geometry calibration beside --camera, or --psf-sigma-px
    gchar *text = NULL;
    gsize len = 0;
    CHECK(g_file_get_contents(path, &text, &len, NULL));
    g_mkdir_with_parents(test_path("cal/geometry"), 0755);
    char *camp = g_strdup(test_path("cal/geometry/camera.cameramodel"));
    CHECK(g_file_set_contents(camp, text, (gssize)len, NULL));
    g_free(text);
    test_write("cal/geometry/geometry.json", "{\"psf\": {\"model\": \"gaussian\", \"sigma_px\": 0.8, "
               "\"sigma_std_px\": 0.01}}");
    char *scp = g_strdup(test_write("plate.d3d", scene_txt)), *mp = g_strdup(test_write("m.ini", mt));
    char *lp = g_strdup(test_write("l.ini", lt));
    const char *dirs[3] = { "plan_cal", "plan_opt", "plan_none" };
    for (int k = 0; k < 3; k++) {
        char *dir = g_strdup(test_path(dirs[k])), *out = NULL, *err = NULL;
        if (k == 2) unlink(test_path("cal/geometry/geometry.json"));
        // the first with its report, the second with --psf-sigma-px 0.5, the third without geometry.json
        const char *argv[] = { test_refl(), "plan", "lamps", scp, "--camera", camp, "--lamps", lp, "--kc-per-us",
                               "1e-4", "--materials", mp, "--exposures-us", "2000", "-o", dir, NULL, NULL, NULL, NULL };
        const char *tail[3][3] = { { NULL }, { "--psf-sigma-px", "0.5", "--no-report" }, { "--no-report" } };
        memcpy(&argv[16], tail[k], sizeof tail[k]);
        int rc = test_run(argv, 120, &out, &err);
        CHECK_MSG(rc == 0, "%s: rc %d: %s", dirs[k], rc, err);
        CHECK_CONTAINS(err, "edges blurred by a Gaussian PSF of sigma");
        char *jp = g_strdup_printf("%s/plan.json", dir);
        json_t *j = json_load_file(jp, 0, NULL), *psf = json_object_get(j, "psf");
        CHECK(psf != NULL);
        const double want[3] = { 0.8, 0.5, 0 };
        CHECK_NEAR(json_number_value(json_object_get(psf, "sigma_px")), want[k], 1e-12);
        const char *src = json_string_value(json_object_get(psf, "source"));
        CHECK_CONTAINS(src, k == 0 ? "geometry.json" : k == 1 ? "--psf-sigma-px" : "none");
        CHECK(k != 0 || json_number_value(json_object_get(psf, "sigma_std_px")) == 0.01);
        CHECK(k == 0 || json_is_null(json_object_get(psf, "sigma_std_px")));
        json_t *sf = json_object_get(json_object_get(psf, "sobel_factor"), "axis_aligned");
        CHECK_NEAR(json_number_value(json_object_get(sf, "best")), model_edge_sobel_step(0, want[k]).best, 1e-9);
        json_t *sg = json_array_get(json_object_get(j, "segments"), 0);
        CHECK(json_number_value(json_object_get(sg, "sobel_factor")) > 0);
        if (k == 0) {   // the geometry calibration is an input; the report says sigma
            bool listed = false;
            size_t i;
            json_t *e;
            json_array_foreach(json_object_get(json_object_get(j, "provenance"), "inputs"), i, e)
                listed |= !strcmp(json_string_value(json_object_get(e, "role")) ?: "", "geometry");
            CHECK(listed);
            char *hp = g_strdup_printf("%s/index.html", dir), *html = NULL;
            CHECK(g_file_get_contents(hp, &html, NULL, NULL));
            CHECK_CONTAINS(html, "Gaussian PSF of sigma 0.800 px");
            g_free(html);
            g_free(hp);
        }
        json_decref(j);
        g_free(jp);
        g_free(out);
        g_free(err);
        g_free(dir);
    }
    g_free(camp);
    g_free(scp);
    g_free(mp);
    g_free(lp);
}
