// tests/test_calib_plan_geometry.c — refl plan geometry (calib/geometry/plan.h): the board poses
// proposed for the example camera cover its imager at least as well as the example rig's own tilts,
// every pose is seen whole, every tilt group has two angles at least and the orientations are spread;
// the section it writes is a lab file's [geometry] (refl plan day takes it); a guessed camera looks at
// the rig origin (it projects to the image centre); a camera that never sees the board is an error.
#define _GNU_SOURCE
#include <glib.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "calib/geometry/geometry.h"
#include "calib/geometry/plan.h"
#include "model/model.h"
#include "tests/test.h"

// An example file's absolute path (the lab files written by the tests name the examples' scenes).
static char *example(const char *name)
{
    char *top = g_canonicalize_filename(test_srcdir(), NULL), *p = g_strdup_printf("%s/examples/%s", top, name);
    g_free(top);
    return p;
}

TEST(plan_geometry_example_camera)
{
    char *cp = example("camera.cameramodel"), *bp = example("samples/calib_board.d3d");
    model_camera_t *cam = model_camera_load(cp);
    model_scene_t *board = model_scene_load(bp, NULL);
    CHECK(cam && board);
    if (!cam || !board) return;
    calib_geometry_plan_opts_t o = calib_geometry_plan_defaults();
    o.cams[0] = cam;
    o.ncams = 1;
    o.board = board;
    calib_geometry_plan_t p;
    CHECK(calib_geometry_plan(&o, &p));
    double cov_default = 0;
    int views_default = 0;
    CHECK(calib_geometry_plan_coverage(&o, CALIB_GEOMETRY_DEFAULT_TILTS, &cov_default, &views_default));
    double cov_plan = 0;
    int views_plan = 0;
    CHECK(calib_geometry_plan_coverage(&o, p.tilts, &cov_plan, &views_plan));
    printf("plan: %d views, coverage %.3f (every usable pose %.3f); the example rig's tilts: %d views seen whole, "
           "coverage %.3f\n  %s\n", p.nviews, p.coverage[0], p.coverage_all[0], views_default, cov_default, p.tilts);
    CHECK(p.nviews >= 10 && p.nviews <= o.max_views);
    CHECK_MSG(p.views[0] == p.nviews, "%d of %d chosen views seen whole", p.views[0], p.nviews);
    CHECK_NEAR(cov_plan, p.coverage[0], 1e-12);    // the text says what was chosen
    CHECK(views_plan == p.nviews);
    CHECK(p.coverage[0] >= cov_default);
    CHECK(p.coverage[0] <= p.coverage_all[0] + 1e-12);
    int classes = 0;
    for (int k = 0; k < 5; k++) classes += p.classes[0][k] > 0;
    CHECK_MSG(classes >= 3, "%d orientation classes", classes);
    CHECK(p.obliquity_max_deg[0] <= o.max_obliquity_deg);
    // every tilt group: two angles at least (the axis fit turns one pose per group)
    gchar **groups = g_strsplit(p.tilts, " ", -1);
    for (int i = 0; groups[i]; i++) {
        const char *colon = strchr(groups[i], ':');
        CHECK_MSG(colon && strchr(colon, ','), "group '%s' has one angle", groups[i]);
    }
    g_strfreev(groups);
    calib_geometry_plan_free(&p);
    model_camera_free(cam);
    model_scene_free(board);
    g_free(cp);
    g_free(bp);
}

// A guessed camera looks at the rig origin: the origin projects to the image centre, and a point
// above the origin to the centre's column (its image x horizontal).
TEST(plan_geometry_guess_camera)
{
    const double c[3] = { 600, -500, 700 };
    model_camera_t *cam = calib_geometry_plan_guess_camera(1280, 1024, 2000, c);
    CHECK(cam != NULL);
    if (!cam) return;
    model_vec3_t pts[2] = { { 0, 0, 0 }, { 0, 0, 50 } };
    double q[4];
    CHECK(model_camera_project(cam, pts, 2, q));
    CHECK_NEAR(q[0], 639.5, 1e-6);
    CHECK_NEAR(q[1], 511.5, 1e-6);
    CHECK_NEAR(q[2], 639.5, 1e-6);
    CHECK(q[3] < q[1]);   // up in the image
    model_camera_free(cam);
    CHECK(calib_geometry_plan_guess_camera(1280, 1024, 2000, (const double[3]){ 0, 0, 900 }) == NULL);
    CHECK_CONTAINS(model_last_error(), "off the turntable's axis");
}

// The command: the [geometry] section into a file, taken by refl plan day as the lab file's; a camera
// that sees the board whole in no pose is an error saying so.
TEST(plan_geometry_command)
{
    char *rig = example("virtual-rig-lab.ini"), *cam = example("camera.cameramodel"), *lab = example("lab-virtual.ini");
    const char *sec = test_path("geometry.ini");
    char *out = NULL, *err = NULL;
    int rc = test_refl_run(120, &out, &err, "plan", "geometry", "--rig", rig, "--camera-model", cam, "-o", sec, NULL);
    CHECK_MSG(rc == 0, "exit %d: %s", rc, err);
    CHECK_CONTAINS(out, "the [geometry] section in");
    g_free(out);
    g_free(err);
    char *text = NULL, *good = NULL;
    CHECK(g_file_get_contents(sec, &text, NULL, NULL) && g_file_get_contents(lab, &good, NULL, NULL));
    CHECK_CONTAINS(text, "\n[geometry]\ntilts = 0:");
    CHECK_CONTAINS(text, "corners over ");
    if (text && good) {   // the lab file with this [geometry] instead of its own, its paths absolute
        char *a = strstr(good, "[geometry]"), *b = a ? strstr(a, "[sphere]") : NULL;
        CHECK(a && b);
        if (a && b) {
            GString *t = g_string_new_len(good, a - good);
            g_string_append(t, strstr(text, "[geometry]"));
            g_string_append(t, "\n");
            g_string_append(t, b);
            char *exdir = example("");
            GRegex *rel = g_regex_new("^(scene|certificate) = ([^/])", G_REGEX_MULTILINE, 0, NULL);
            char *repl = g_strdup_printf("\\1 = %s\\2", exdir);
            char *fixed = g_regex_replace(rel, t->str, -1, 0, repl, 0, NULL);
            const char *lp = test_write("lab.ini", fixed);
            rc = test_refl_run(60, &out, &err, "plan", "day", "--rig", rig, "--lab", lp, "-o", test_path("d"), NULL);
            CHECK_MSG(rc == 0, "exit %d: %s", rc, err);
            g_free(out);
            g_free(err);
            char *sh = NULL, *shp = g_build_filename(test_path("d"), "day.sh", NULL);
            CHECK(g_file_get_contents(shp, &sh, NULL, NULL));
            const char *tl = strstr(text, "tilts = ");
            char *tilts = tl ? g_strndup(tl + 8, strcspn(tl + 8, "\n")) : NULL;
            char *want = g_strdup_printf("LAB_GEOMETRY_TILTS='%s'", tilts ? tilts : "");
            CHECK_CONTAINS(sh, want);
            g_free(want);
            g_free(tilts);
            g_free(sh);
            g_free(shp);
            g_free(fixed);
            g_free(repl);
            g_regex_unref(rel);
            g_free(exdir);
            g_string_free(t, TRUE);
        }
    }
    g_free(text);
    g_free(good);
    // a long lens: the board never fits the imager
    rc = test_refl_run(60, &out, &err, "plan", "geometry", "--camera-guess", "1280,1024,40000,600,-500,700", NULL);
    CHECK(rc == 1);
    CHECK_CONTAINS(err, "sees the whole board in none");
    g_free(out);
    g_free(err);
    rc = test_refl_run(60, &out, &err, "plan", "geometry", "--camera-guess", "1280,1024", NULL);
    CHECK(rc == 2);
    CHECK_CONTAINS(err, "W,H,F,X,Y,Z");
    g_free(out);
    g_free(err);
    g_free(rig);
    g_free(cam);
    g_free(lab);
}
