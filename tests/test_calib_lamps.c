// tests/test_calib_lamps.c — `refl calib lamps` (calib/lamps.c): the
// triangulation on synthetic rays with a known answer, the highlight finder
// on a synthetic image, the whole calibration on the virtual rig against its
// truth (fixed seeds), and the bad inputs: a lamp whose highlight is missing
// (wrong sphere facts: every frame), bad arguments, a missing camera model.
//
// The virtual rig of the accuracy test is the example truth as it is: its
// mirror sphere renders with direct_samples = 64 (one sample per pixel of the
// lamp's sphere would dither a highlight 2 px wide by ~0.2 px, noise a camera,
// which integrates the lamp's light, does not have).
#define _GNU_SOURCE
#include <glib.h>
#include <jansson.h>
#include <limits.h>
#include <stdlib.h>

#include "calib/lamps.h"
#include "model/model.h"
#include "tests/test.h"

#define CAMERA "/examples/camera.cameramodel"

static char *src(const char *rel)
{
    char top[PATH_MAX];
    if (!realpath(test_srcdir(), top)) snprintf(top, sizeof top, "%s", test_srcdir());
    return g_strdup_printf("%s%s", top, rel);
}

// A truth file: the example's, paths made absolute, every direct_samples set
// (direct_samples <= 0: as they are).
static const char *truth_file(const char *name, int direct_samples)
{
    char *ex = src("/examples/virtual-truth.ini");
    char *text = model_read_file(ex, NULL);
    char *dir = src("/examples");
    GString *g = g_string_new("");
    char **lines = g_strsplit(text ? text : "", "\n", -1);
    for (char **l = lines; *l; l++) {
        if (g_str_has_prefix(*l, "model = ") && strstr(*l, ".cameramodel"))
            g_string_append_printf(g, "model = %s/%s\n", dir, *l + 8);
        else if (g_str_has_prefix(*l, "scene = "))
            g_string_append_printf(g, "scene = %s/%s\n", dir, *l + 8);
        else if (direct_samples > 0 && g_str_has_prefix(*l, "direct_samples = "))
            g_string_append_printf(g, "direct_samples = %d\n", direct_samples);
        else
            g_string_append_printf(g, "%s\n", *l);
    }
    g_strfreev(lines);
    const char *p = test_write(name, g->str);
    g_string_free(g, TRUE);
    free(text);
    g_free(ex);
    g_free(dir);
    return p;
}

static const char *rig_file(const char *name, const char *truth)
{
    char text[PATH_MAX + 200];
    snprintf(text, sizeof text, "[rig]\nbackend = virtual\nserve = inprocess\ntruth = %s\ntime_scale = 0.01\n"
             "pixel_format = Mono12\n", truth);
    return test_write(name, text);
}

// ---------------------------------------------------------------------------
// Triangulation: rays through a known point with known noise

TEST(calib_lamps_triangulate_known_point)
{
    const double X[3] = { 400, -150, 650 };
    model_vec3_t p[24], d[24];
    bool used[24];
    double dist[24];
    GRand *g = g_rand_new_with_seed(7);
    for (int i = 0; i < 24; i++) {
        double a = i * 15 * M_PI / 180;
        p[i] = (model_vec3_t){ 60 * cos(a), 60 * sin(a), 40 + g_rand_double_range(g, -20, 20) };
        // direction to X, perturbed by 1 mrad (Gaussian-ish) per axis
        double e[3] = { X[0] - p[i].x, X[1] - p[i].y, X[2] - p[i].z };
        double n = sqrt(e[0] * e[0] + e[1] * e[1] + e[2] * e[2]);
        for (int k = 0; k < 3; k++) e[k] = e[k] / n + 1e-3 * (g_rand_double(g) + g_rand_double(g) - 1) * 1.7;
        n = sqrt(e[0] * e[0] + e[1] * e[1] + e[2] * e[2]);
        d[i] = (model_vec3_t){ e[0] / n, e[1] / n, e[2] / n };
        used[i] = true;
    }
    // one gross outlier
    d[5] = (model_vec3_t){ 0, 0, 1 };
    calib_lamps_fit_t f;
    CHECK(calib_lamps_triangulate(p, d, 24, 4.0, 0.5, used, dist, &f));
    CHECK(!used[5]);
    CHECK(f.n_used == 23);
    double err = sqrt(pow(f.x_mm[0] - X[0], 2) + pow(f.x_mm[1] - X[1], 2) + pow(f.x_mm[2] - X[2], 2));
    double sd = sqrt(f.cov_mm2[0] + f.cov_mm2[4] + f.cov_mm2[8]);
    // the error is consistent with the stated uncertainty, and both are small
    CHECK_MSG(err < 4 * sd && err < 10, "error %.2f mm, stated std %.2f mm", err, sd);
    CHECK_MSG(sd > 0.05 && sd < 15, "stated std %.3f mm", sd);
    CHECK_MSG(f.rms_mm > 0.1 && f.rms_mm < 2, "rms %.3f mm", f.rms_mm);
    CHECK(dist[5] > 100);

    // exact rays: exact answer
    for (int i = 0; i < 24; i++) {
        double e[3] = { X[0] - p[i].x, X[1] - p[i].y, X[2] - p[i].z };
        double n = sqrt(e[0] * e[0] + e[1] * e[1] + e[2] * e[2]);
        d[i] = (model_vec3_t){ e[0] / n, e[1] / n, e[2] / n };
        used[i] = true;
    }
    CHECK(calib_lamps_triangulate(p, d, 24, 4.0, 0.5, used, dist, &f));
    CHECK_NEAR(f.x_mm[0], X[0], 1e-6);
    CHECK_NEAR(f.x_mm[1], X[1], 1e-6);
    CHECK_NEAR(f.x_mm[2], X[2], 1e-6);
    CHECK(f.n_used == 24);

    // too few rays, parallel rays
    for (int i = 0; i < 24; i++) used[i] = i < 2;
    model_error_clear();
    CHECK(!calib_lamps_triangulate(p, d, 24, 4.0, 0.5, used, dist, &f));
    CHECK_CONTAINS(model_last_error(), "2 rays: a position needs at least 3");
    for (int i = 0; i < 4; i++) {
        used[i] = true;
        d[i] = (model_vec3_t){ 0, 0, 1 };
    }
    CHECK(!calib_lamps_triangulate(p, d, 4, 4.0, 0.5, used, dist, &f));
    CHECK_CONTAINS(model_last_error(), "parallel");
    g_rand_free(g);
}

// ---------------------------------------------------------------------------
// The highlight finder on a synthetic sphere image with a Gaussian spot

TEST(calib_lamps_highlight_synthetic)
{
    char *cp = src(CAMERA);
    model_camera_t *cam = model_camera_load(cp);
    g_free(cp);
    CHECK(cam);
    if (!cam) return;
    const int W = model_camera_width(cam), H = model_camera_height(cam);
    model_vec3_t c = { 60, 0, 40 };
    calib_lamps_sphere_image_t *sph = calib_lamps_sphere_image(cam, c, 25);
    CHECK(sph);
    if (!sph) {
        model_camera_free(cam);
        return;
    }
    CHECK(sph->radius_px > 40 && sph->radius_px < 60);   // 25 mm at ~870 mm, f 1750 px
    float *img = malloc(sizeof *img * (size_t)W * H), *dark = malloc(sizeof *dark * (size_t)W * H);
    GRand *g = g_rand_new_with_seed(3);
    const double qx = sph->q_centre[0] + 7.3, qy = sph->q_centre[1] - 11.6, s = 1.1;
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++) {
            size_t k = (size_t)y * W + x;
            dark[k] = 64 + (float)g_rand_double_range(g, -1, 1);
            double v = 2000 * exp(-((x - qx) * (x - qx) + (y - qy) * (y - qy)) / (2 * s * s));
            img[k] = (float)(64 + v + g_rand_double_range(g, -2, 2));
        }
    calib_lamps_highlight_t h;
    calib_lamps_find_highlight(img, dark, W, H, sph, 12, 80, 40, 4095, &h);
    CHECK_MSG(h.found, "%s", h.why);
    CHECK_NEAR(h.q[0], qx, 0.02);
    CHECK_NEAR(h.q[1], qy, 0.02);
    CHECK(h.fit_used);
    CHECK_NEAR(h.sigma_px[0], s, 0.05);
    CHECK(h.peak_dn > 1500);
    CHECK(!h.saturated);
    // a ray through it: starts on the sphere, leaves it outward
    model_vec3_t p, d;
    CHECK(calib_lamps_reflect(cam, h.q, c, 25, &p, &d));
    double r = sqrt(pow(p.x - c.x, 2) + pow(p.y - c.y, 2) + pow(p.z - c.z, 2));
    CHECK_NEAR(r, 25, 1e-6);
    CHECK((p.x - c.x) * d.x + (p.y - c.y) * d.y + (p.z - c.z) * d.z > 0);

    // a bright spot off the sphere (the post, the plate) is not taken
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++) {
            size_t k = (size_t)y * W + x;
            double ox = sph->q_centre[0], oy = sph->q_centre[1] + sph->radius_px + 2.5;
            img[k] = (float)(dark[k] + 3000 * exp(-((x - ox) * (x - ox) + (y - oy) * (y - oy)) / 2.0));
        }
    calib_lamps_find_highlight(img, dark, W, H, sph, 12, 80, 40, 4095, &h);
    CHECK(!h.found);
    CHECK_CONTAINS(h.why, "brightest pixel on the sphere's image is");
    // a broad bright patch on the sphere is no lamp
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++) {
            size_t k = (size_t)y * W + x;
            double ox = sph->q_centre[0], oy = sph->q_centre[1];
            img[k] = (float)(dark[k] + 1000 * exp(-((x - ox) * (x - ox) + (y - oy) * (y - oy)) / 200.0));
        }
    calib_lamps_find_highlight(img, dark, W, H, sph, 12, 80, 40, 4095, &h);
    CHECK(!h.found);
    CHECK_CONTAINS(h.why, "broad patch");
    g_rand_free(g);
    free(img);
    free(dark);
    calib_lamps_sphere_image_free(sph);
    model_camera_free(cam);
}

// ---------------------------------------------------------------------------
// The whole calibration on the virtual rig against its truth

static double jnum(json_t *a, int i) { return json_number_value(json_array_get(a, (size_t)i)); }

TEST(calib_lamps_virtual_rig_accuracy)
{
    double t0 = model_now_s();
    const char *truth = truth_file("truth.ini", 0);
    const char *rig = rig_file("rig.ini", truth);
    char *cam = src(CAMERA);
    char out[PATH_MAX];
    snprintf(out, sizeof out, "%s/lamps", test_tmpdir());
    char *o = NULL, *e = NULL;
    int rc = test_refl_run(300, &o, &e, "calib", "lamps", "--rig", rig, "--camera", cam, "-o", out,
                           "--progress", "lines", NULL);   // the default: 24 angles, 15 deg apart
    CHECK_MSG(rc == 0, "rc %d\n%s\n%s", rc, o, e);
    fprintf(stderr, "%s", o ? o : "");
    CHECK_CONTAINS(e, "angle 24/24");
    g_free(o);
    g_free(e);
    char *jp = g_strdup_printf("%s/lamps.json", out);
    json_error_t je;
    json_t *doc = json_load_file(jp, 0, &je);
    CHECK_MSG(doc, "%s: %s", jp, je.text);
    model_ini_t *ti = model_ini_load(truth);
    model_lamps_t *tl = ti ? model_lamps_from_ini(ti) : NULL;
    CHECK(tl && tl->n == 4);
    if (doc && tl) {
        CHECK_CONTAINS(json_string_value(json_object_get(doc, "units")), "mm");
        CHECK_CONTAINS(json_string_value(json_object_get(doc, "conventions")), "rig frame");
        json_t *lamps = json_object_get(doc, "lamps");
        CHECK(json_array_size(lamps) == 4);
        double se = 0;
        size_t i;
        json_t *l;
        json_array_foreach(lamps, i, l) {
            const char *name = json_string_value(json_object_get(l, "name"));
            int k = model_lamps_find(tl, name ? name : "");
            CHECK(k >= 0);
            if (k < 0) continue;
            json_t *x = json_object_get(l, "position_mm"), *sd = json_object_get(l, "std_mm");
            model_vec3_t t = tl->lamps[k].position_mm;
            double dx = jnum(x, 0) - t.x, dy = jnum(x, 1) - t.y, dz = jnum(x, 2) - t.z;
            double err = sqrt(dx * dx + dy * dy + dz * dz);
            double s = sqrt(pow(jnum(sd, 0), 2) + pow(jnum(sd, 1), 2) + pow(jnum(sd, 2), 2));
            fprintf(stderr, "  lamp %-6s error %.2f mm (%.2f %.2f %.2f), stated std %.2f mm, rms ray %.2f mm\n", name,
                    err, dx, dy, dz, s, json_number_value(json_object_get(l, "rms_ray_distance_mm")));
            se += err * err;
            CHECK_MSG(err < 5, "lamp %s: %.2f mm from the truth", name, err);
            CHECK_MSG(err < 4 * s + 0.5, "lamp %s: error %.2f mm vs stated std %.2f mm", name, err, s);
            CHECK(json_integer_value(json_object_get(l, "n_frames")) >= 20);
            CHECK(json_array_size(json_object_get(l, "frames_missing")) == 0);
        }
        double rms = sqrt(se / 4);
        fprintf(stderr, "  RMS position error over the 4 lamps: %.2f mm\n", rms);
        CHECK_MSG(rms < 2.0, "RMS position error %.2f mm (limit 2 mm)", rms);
        json_t *camj = json_object_get(doc, "camera");
        CHECK(json_string_length(json_object_get(camj, "sha256")) == 64);
        CHECK(json_array_size(json_object_get(json_object_get(doc, "provenance"), "inputs")) >= 2);
        CHECK_NEAR(json_number_value(json_object_get(json_object_get(doc, "sphere"), "radius_mm")), 25, 1e-9);
    }
    json_decref(doc);
    model_lamps_free(tl);
    model_ini_free(ti);
    // report and plots
    char *html = g_strdup_printf("%s/report.html", out);
    char *text = model_read_file(html, NULL);
    CHECK_CONTAINS(text, "lamps_triangulation.png");
    CHECK_CONTAINS(text, "lamps_detections.png");
    CHECK_CONTAINS(text, "east");
    free(text);
    for (int k = 0; k < 2; k++) {
        char *png = g_strdup_printf("%s/%s", out, k ? "lamps_detections.png" : "lamps_triangulation.png");
        size_t len = 0;
        char *b = model_read_file(png, &len);
        CHECK_MSG(b && len > 10000, "%s: %zu bytes", png, len);
        free(b);
        g_free(png);
    }
    g_free(html);

    // the same session analysed again (--session), with wrong sphere facts:
    // no highlight near the predicted sphere image -> which lamp, which frames
    char out2[PATH_MAX], sess[PATH_MAX + 16];
    snprintf(out2, sizeof out2, "%s/wrong", test_tmpdir());
    snprintf(sess, sizeof sess, "%s/capture", out);
    rc = test_refl_run(120, &o, &e, "calib", "lamps", "--session", sess, "--camera", cam, "-o", out2,
                       "--sphere-centre-mm", "-60,0,40", "--sphere-radius-mm", "25", NULL);
    CHECK(rc == 1);
    CHECK_CONTAINS(e, "lamp east: no highlight in 24 of 24 frames:");
    CHECK_CONTAINS(e, "frames/s000000.png (step 0, ");
    CHECK_CONTAINS(e, "brightest pixel on the sphere's image is");
    CHECK_CONTAINS(e, "lamp north: its highlight is in only 0 frames of");
    CHECK_CONTAINS(e, "--sphere-centre-mm -60,0,40");
    char *jp2 = g_strdup_printf("%s/lamps.json", out2);
    CHECK(access(jp2, F_OK) != 0);   // no result written on an error
    g_free(jp2);
    g_free(o);
    g_free(e);

    // the dark frames (lamp set none) are not a lamp
    rc = test_refl_run(120, &o, &e, "calib", "lamps", "--session", sess, "--camera", cam, "-o", out2, "--lamps",
                       "none", NULL);
    CHECK(rc == 1);
    CHECK_CONTAINS(e, "--lamps: 'none' is not a lamp");
    g_free(o);
    g_free(e);
    fprintf(stderr, "  calib_lamps_virtual_rig_accuracy: %.1f s\n", model_now_s() - t0);
    g_free(jp);
    g_free(cam);
}

// ---------------------------------------------------------------------------
// A lamp hidden at some angles: a screen on the sample (it turns with the
// table) between the sphere and lamp east at a few angles. The lamp is named
// with those frames and fitted from the rest.

TEST(calib_lamps_occluded_frames)
{
    double t0 = model_now_s();
    // the mirror sphere's scene plus a black screen 35..37 mm outward of the
    // ball's centre, 24 mm wide, up to z = 250: it hides lamp east (azimuth ~20
    // deg, 50 deg up) from the ball when the table turns it toward the lamp
    char *ms = src("/examples/samples/mirror_sphere.d3d");
    char *text = model_read_file(ms, NULL);
    g_free(ms);
    CHECK(text);
    if (!text) return;
    // vertices 17..24: the screen; its faces before the '@material chrome' line
    GString *g = g_string_new("");
    char *faces = strstr(text, "\nFaces:");
    g_string_append_len(g, text, faces - text);
    g_string_append(g, "\n17 95 -12 0\n18 97 -12 0\n19 97 12 0\n20 95 12 0\n"
                       "21 95 -12 250\n22 97 -12 250\n23 97 12 250\n24 95 12 250\n");
    char *chrome = strstr(faces, "@material chrome");
    g_string_append_len(g, faces, chrome - faces);
    g_string_append(g, "# screen: bottom, top, -y, +x, +y, -x\n17 20 19 18.\n21 22 23 24.\n17 18 22 21.\n"
                       "18 19 23 22.\n19 20 24 23.\n20 17 21 24.\n");
    g_string_append(g, chrome);
    const char *scene = test_write("screen.d3d", g->str);
    g_string_free(g, TRUE);
    free(text);
    // the truth with that scene for the mirror sphere
    const char *truth0 = truth_file("truth0.ini", 16);
    char *t = model_read_file(truth0, NULL);
    char *ex = src("/examples/samples/mirror_sphere.d3d");
    char **parts = g_strsplit(t, ex, 2);
    char *t2 = g_strjoin(scene, parts[0], parts[1], NULL);
    const char *truth = test_write("truth.ini", t2);
    g_strfreev(parts);
    g_free(t2);
    g_free(ex);
    free(t);
    const char *rig = rig_file("rig.ini", truth);
    char *cam = src(CAMERA);
    char out[PATH_MAX];
    snprintf(out, sizeof out, "%s/lamps", test_tmpdir());
    char *o = NULL, *e = NULL;
    int rc = test_refl_run(300, &o, &e, "calib", "lamps", "--rig", rig, "--camera", cam, "-o", out, "--lamps",
                           "east,south", "--angles", "0,20,40,90,135,180,225,270", "--progress", "lines", NULL);
    CHECK_MSG(rc == 0, "rc %d\n%s\n%s", rc, o, e);
    CHECK_CONTAINS(e, "lamp east: no highlight in");
    CHECK_CONTAINS(e, "lamp east: fitted from the other");
    fprintf(stderr, "%s", e ? strstr(e, "lamp east: no highlight") : "");
    g_free(o);
    g_free(e);
    char *jp = g_strdup_printf("%s/lamps.json", out);
    json_t *doc = json_load_file(jp, 0, NULL);
    CHECK(doc);
    // the hidden frames are those with the screen toward the lamp: east
    // (azimuth ~20 deg) at 0..40 deg, south (azimuth ~265 deg) near 270 deg
    size_t i, k;
    json_t *l, *m;
    json_array_foreach(json_object_get(doc, "lamps"), k, l) {
        const char *name = json_string_value(json_object_get(l, "name"));
        bool east = name && !strcmp(name, "east");
        json_t *miss = json_object_get(l, "frames_missing");
        if (east) CHECK(json_array_size(miss) >= 1 && json_array_size(miss) <= 3);
        json_array_foreach(miss, i, m) {
            double a = json_number_value(json_object_get(m, "angle_deg"));
            CHECK_MSG(east ? a > -5 && a < 45 : a > 240 && a < 300, "lamp %s: frame at %.1f deg reported missing",
                      name, a);
            CHECK_CONTAINS(json_string_value(json_object_get(m, "file")), "frames/s");
            CHECK_CONTAINS(json_string_value(json_object_get(m, "why")), "DN above the background");
        }
        CHECK(json_integer_value(json_object_get(l, "n_frames")) + (json_int_t)json_array_size(miss) <= 8);
        CHECK(json_integer_value(json_object_get(l, "n_frames")) >= 5);
    }
    CHECK(json_array_size(json_object_get(doc, "lamps")) == 2);
    json_decref(doc);
    g_free(jp);
    g_free(cam);
    fprintf(stderr, "  calib_lamps_occluded_frames: %.1f s\n", model_now_s() - t0);
}

// ---------------------------------------------------------------------------
// Bad arguments and a missing camera model

TEST(calib_lamps_bad_arguments)
{
    char *cam = src(CAMERA);
    const char *rig = test_write("rig.ini", "[rig]\nbackend = virtual\nserve = inprocess\ntruth = /nonexistent\n");
    char *o = NULL, *e = NULL;
    struct {
        const char *args[12];
        int rc;
        const char *msg;
    } cases[] = {
        { { "--rig", "r.ini", "-o", "x", NULL }, 2, "--camera CAMERA.cameramodel is required" },
        { { "--rig", "r.ini", "--camera", "c", NULL }, 2, "-o DIR is required" },
        { { "--camera", "c", "-o", "x", NULL }, 2, "give --rig RIG.ini (capture) or --session DIR" },
        { { "--rig", "r", "--session", "s", "--camera", "c", "-o", "x", NULL }, 2, "not both" },
        { { "--rig", "r", "--camera", "c", "-o", "x", "--sphere-centre-mm", "1,2", NULL }, 2, "give X,Y,Z" },
        { { "--rig", "r", "--camera", "c", "-o", "x", "--sphere-centre-mm", "1,2,q", NULL }, 2, "'q' is not a number" },
        { { "--rig", "r", "--camera", "c", "-o", "x", "--sphere-radius-mm", "-3", NULL }, 2, "(> 0)" },
        { { "--rig", "r", "--camera", "c", "-o", "x", "--angles", "0,90", NULL }, 2, "at least 3 angles" },
        { { "--rig", "r", "--camera", "c", "-o", "x", "--frobnicate", NULL }, 2, "unknown option '--frobnicate'" },
        { { "--rig", "r", "--camera", "c", "-o", NULL }, 2, "-o needs a value" },
        { { "--rig", "r", "--camera", "c", "-o", "x", "--highlight", "best", NULL }, 2, "write model, gauss or centroid" },
    };
    for (size_t k = 0; k < sizeof cases / sizeof cases[0]; k++) {
        const char *argv[20] = { test_refl(), "calib", "lamps" };
        int n = 3;
        for (int i = 0; cases[k].args[i]; i++) argv[n++] = cases[k].args[i];
        argv[n] = NULL;
        int rc = test_run(argv, 30, &o, &e);
        CHECK_MSG(rc == cases[k].rc, "case %zu: rc %d: %s", k, rc, e);
        CHECK_CONTAINS(e, cases[k].msg);
        g_free(o);
        g_free(e);
    }
    // a camera model that is missing: named, with what to do
    char out[PATH_MAX];
    snprintf(out, sizeof out, "%s/o", test_tmpdir());
    int rc = test_refl_run(30, &o, &e, "calib", "lamps", "--rig", rig, "--camera", "/nonexistent/cam.cameramodel",
                           "-o", out, NULL);
    CHECK(rc == 1);
    CHECK_CONTAINS(e, "/nonexistent/cam.cameramodel: cannot read the camera model");
    CHECK_CONTAINS(e, "refl calib geometry");
    g_free(o);
    g_free(e);
    // a session directory that is not one
    rc = test_refl_run(30, &o, &e, "calib", "lamps", "--session", test_tmpdir(), "--camera", cam, "-o", out, NULL);
    CHECK(rc == 1);
    CHECK_CONTAINS(e, "not a capture session");
    g_free(o);
    g_free(e);
    // a real rig without sphere facts: asked for
    const char *real = test_write("real.ini", "[lamp a]\nbackend = sim\n");
    rc = test_refl_run(30, &o, &e, "calib", "lamps", "--rig", real, "--camera", cam, "-o", out, NULL);
    CHECK(rc == 1);
    CHECK_CONTAINS(e, "is not a virtual rig: give --sphere-centre-mm X,Y,Z and --sphere-radius-mm R");
    g_free(o);
    g_free(e);
    g_free(cam);
    // --help
    rc = test_refl_run(30, &o, &e, "calib", "lamps", "--help", NULL);
    CHECK(rc == 0);
    CHECK_CONTAINS(o, "--sphere-centre-mm");
    g_free(o);
    g_free(e);
}
