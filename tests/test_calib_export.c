// tests/test_calib_export.c — `refl calib export` (calib/geometry/export.c) and mrcal's
// option names on `refl calib geometry`.
//
// - OpenCV YAML read back by OpenCV (python3 cv2.FileStorage): the same K,
//   distortion and image size; points projected with cv2.projectPoints equal
//   refl's projection (model_camera_project, mrcal) to 1e-6 px, for
//   LENSMODEL_OPENCV8, OPENCV5 and OPENCV4. The ROS YAML (python3 yaml) holds
//   the same numbers, plumb_bob / rational_polynomial, identity rectification
//   and P = [K | 0]; cv2.projectPoints with its coefficients agrees too.
// - Splined models and ROS with OPENCV12 are refused with the reason.
// - Usage errors; mrcal's option names reach refl's options.
#define _GNU_SOURCE
#include <glib.h>
#include <stdlib.h>
#include <sys/stat.h>
#include <unistd.h>

#include "calib/geometry/export.h"
#include "model/model.h"
#include "tests/test.h"

// The camera-frame points of the check: a grid of directions up to the
// imager's corners, at several distances.
static int test_points(model_vec3_t *p, int cap)
{
    int n = 0;
    for (int j = -3; j <= 3; j++)
        for (int i = -4; i <= 4; i++)
            if (n < cap) {
                double z = 400 + 150 * ((i + j + 7) % 5);
                p[n++] = (model_vec3_t){ i * 0.09 * z, j * 0.09 * z, z };
            }
    return n;
}

static const char PY[] =
    "import sys, cv2, numpy as np, yaml\n"
    "fmt, path, pts = sys.argv[1], sys.argv[2], np.loadtxt(sys.argv[3]).reshape(-1, 3)\n"
    "if fmt == 'opencv':\n"
    "    fs = cv2.FileStorage(path, cv2.FILE_STORAGE_READ)\n"
    "    K = fs.getNode('camera_matrix').mat(); D = fs.getNode('distortion_coefficients').mat()\n"
    "    W = int(fs.getNode('image_width').real()); H = int(fs.getNode('image_height').real()); extra = ''\n"
    "else:\n"
    "    y = yaml.safe_load(open(path))\n"
    "    K = np.array(y['camera_matrix']['data'], float).reshape(3, 3)\n"
    "    D = np.array(y['distortion_coefficients']['data'], float).reshape(1, -1)\n"
    "    W, H = y['image_width'], y['image_height']\n"
    "    R = np.array(y['rectification_matrix']['data']).reshape(3, 3)\n"
    "    P = np.array(y['projection_matrix']['data']).reshape(3, 4)\n"
    "    ok = np.allclose(R, np.eye(3), 0, 0) and np.allclose(P[:, :3], K, 0, 0) and not P[:, 3].any()\n"
    "    extra = ' %s %s %d' % (y['distortion_model'], y['camera_name'], ok)\n"
    "q, _ = cv2.projectPoints(pts, np.zeros(3), np.zeros(3), K, D)\n"
    "print(W, H, ' '.join('%.17g' % v for v in K.ravel()), '|', ' '.join('%.17g' % v for v in D.ravel()), '|',\n"
    "      ' '.join('%.17g' % v for v in q.ravel()), '|' + extra)\n";

// Export a camera of this lens model and intrinsics in both formats; read
// each back with OpenCV and compare.
static void roundtrip(const char *lensmodel, const double *in, int nd)
{
    model_camera_t *cam = model_camera_new(lensmodel, in, 1280, 1024, (double[6]){ 0 });
    CHECK(cam != NULL);
    if (!cam) return;
    char name[128];
    snprintf(name, sizeof name, "%s.cameramodel", lensmodel);
    const char *mp = test_path(name);
    CHECK(model_camera_save(cam, mp));
    model_vec3_t p[64];
    int n = test_points(p, 64);
    double q[128];
    CHECK(model_camera_project(cam, p, n, q));
    GString *g = g_string_new("");
    for (int i = 0; i < n; i++) g_string_append_printf(g, "%.17g %.17g %.17g\n", p[i].x, p[i].y, p[i].z);
    const char *pts = test_write("points.txt", g->str);
    g_string_free(g, TRUE);
    const char *script = test_write("check.py", PY);
    for (int f = 0; f < 2; f++) {
        const char *fmt = f ? "ros" : "opencv", *yml = test_path(f ? "ros.yaml" : "opencv.yaml");
        char *out = NULL, *err = NULL;
        int rc = test_refl_run(30, &out, &err, "calib", "export", mp, "--format", fmt, "-o", yml, NULL);
        CHECK_MSG(rc == 0, "%s %s: exit %d: %s", lensmodel, fmt, rc, err ? err : "");
        free(out), free(err);
        const char *argv[] = { "/usr/bin/python3", script, fmt, yml, pts, NULL };
        rc = test_run(argv, 60, &out, &err);
        CHECK_MSG(rc == 0, "python3 cv2 (python3-opencv, python3-yaml): exit %d: %s", rc, err ? err : "");
        char **part = g_strsplit(out ? out : "", "|", -1);
        CHECK(g_strv_length(part) == 4);
        if (g_strv_length(part) == 4) {
            char **a = g_strsplit_set(g_strstrip(part[0]), " ", -1), **d = g_strsplit_set(g_strstrip(part[1]), " ", -1);
            char **qq = g_strsplit_set(g_strstrip(part[2]), " ", -1);
            CHECK(g_strv_length(a) == 11 && atoi(a[0]) == 1280 && atoi(a[1]) == 1024);
            double K[9] = { in[0], 0, in[2], 0, in[1], in[3], 0, 0, 1 };
            for (int k = 0; k < 9 && g_strv_length(a) == 11; k++) CHECK(strtod(a[2 + k], NULL) == K[k]);
            int want = nd <= 5 ? 5 : nd;
            CHECK((int)g_strv_length(d) == want);
            for (int k = 0; k < want && k < (int)g_strv_length(d); k++)
                CHECK(strtod(d[k], NULL) == (k < nd ? in[4 + k] : 0));
            CHECK((int)g_strv_length(qq) == 2 * n);
            double worst = 0;
            for (int k = 0; k < 2 * n && k < (int)g_strv_length(qq); k++)
                worst = fmax(worst, fabs(strtod(qq[k], NULL) - q[k]));
            fprintf(stderr, "  %s %s: cv2.projectPoints against refl: largest difference %.2e px\n", lensmodel, fmt,
                    worst);
            CHECK(worst < 1e-6);
            if (f) {
                CHECK_CONTAINS(part[3], nd == 8 ? "rational_polynomial" : "plumb_bob");
                CHECK_CONTAINS(part[3], lensmodel);   // camera_name: the file's stem
                CHECK_CONTAINS(part[3], " 1");        // identity rectification, P = [K | 0]
            }
            g_strfreev(a), g_strfreev(d), g_strfreev(qq);
        }
        g_strfreev(part);
        free(out), free(err);
    }
    model_camera_free(cam);
}

TEST(calib_export_opencv_ros_read_back_by_opencv)
{
    // strong distortion, so that every coefficient matters at the imager's corners
    const double c8[12] = { 1750, 1745, 642.7, 508.9, -0.12, 0.08, 0.0005, -0.0003, -0.01, 0.002, -0.001, 0.0005 };
    roundtrip("LENSMODEL_OPENCV8", c8, 8);
    const double c5[9] = { 1200, 1210, 630.2, 515.4, -0.21, 0.11, 0.0007, 0.0004, -0.03 };
    roundtrip("LENSMODEL_OPENCV5", c5, 5);
    const double c4[8] = { 900, 905, 640.5, 511.5, 0.05, -0.02, -0.001, 0.0009 };
    roundtrip("LENSMODEL_OPENCV4", c4, 4);
}

TEST(calib_export_refusals_and_usage)
{
    char *out = NULL, *err = NULL, mp[4096];
    snprintf(mp, sizeof mp, "%s/examples/camera-adversarial.cameramodel", test_srcdir());
    int rc = test_refl_run(30, &out, &err, "calib", "export", mp, "--format", "opencv", "-o", test_path("x.yaml"),
                           NULL);
    CHECK(rc == 1);
    CHECK_CONTAINS(err, "camera-adversarial.cameramodel");
    CHECK_CONTAINS(err, "LENSMODEL_SPLINED_STEREOGRAPHIC");
    CHECK_CONTAINS(err, "mrcal-convert-lensmodel");
    CHECK(access(test_path("x.yaml"), F_OK) != 0);
    free(out), free(err);
    // OPENCV12: OpenCV yes, ROS no
    double c12[16] = { 1000, 1000, 640, 512, -0.1, 0.01, 0, 0, 0, 0, 0, 0, 1e-4, 0, 0, 0 };
    model_camera_t *cam = model_camera_new("LENSMODEL_OPENCV12", c12, 1280, 1024, (double[6]){ 0 });
    const char *p12 = test_path("c12.cameramodel");
    CHECK(cam && model_camera_save(cam, p12));
    model_camera_free(cam);
    char *text = calib_export_camera_text(p12, CALIB_EXPORT_OPENCV, NULL);
    CHECK_CONTAINS(text, "cols: 12");
    free(text);
    model_error_quiet_thread(true);
    CHECK(calib_export_camera_text(p12, CALIB_EXPORT_ROS, NULL) == NULL);
    CHECK_CONTAINS(model_last_error(), "rational_polynomial (8) only");
    // a file that is not a camera model: named
    const char *bad = test_write("bad.cameramodel", "{ 'lensmodel': 'LENSMODEL_OPENCV8', \n");
    CHECK(calib_export_camera_text(bad, CALIB_EXPORT_OPENCV, NULL) == NULL);
    CHECK_CONTAINS(model_last_error(), "bad.cameramodel");
    model_error_quiet_thread(false);
    rc = test_refl_run(30, &out, &err, "calib", "export", p12, "--format", "matlab", "-o", test_path("y"), NULL);
    CHECK(rc == 2);
    CHECK_CONTAINS(err, "--format matlab");
    free(out), free(err);
    rc = test_refl_run(30, &out, &err, "calib", "export", p12, "--format", "opencv", NULL);
    CHECK(rc == 2);
    free(out), free(err);
    rc = test_refl_run(30, &out, &err, "calib", "--help", NULL);
    CHECK(rc == 0);
    CHECK_CONTAINS(out, "export");
    free(out), free(err);
}

// mrcal-calibrate-cameras' option names are refl's options (the values reach
// the same checks); --object-spacing is in metres unless it names its unit.
TEST(calib_geometry_mrcal_option_names)
{
    char *out = NULL, *err = NULL;
    const char *x = test_path("x");
    int rc = test_refl_run(30, &out, &err, "calib", "geometry", "--corners-cache", test_path("nope.vnl"),
                           "--imagersize", "640", "480", "-o", x, NULL);
    CHECK(rc == 2);
    CHECK_CONTAINS(err, "nope.vnl: cannot read the corners file");
    free(out), free(err);
    const char *c = test_write("c.vnl", "# filename x y level\na.png 1 2 0\n");
    rc = test_refl_run(30, &out, &err, "calib", "geometry", "--corners", c, "--imagersize", "640", "480",
                       "--object-width-n", "1", "-o", x, NULL);
    CHECK(rc == 2);
    CHECK_CONTAINS(err, "give an integer 2..100");
    free(out), free(err);
    rc = test_refl_run(30, &out, &err, "calib", "geometry", "--corners", c, "--imagersize", "640", "480", "--focal",
                       "-3", "-o", x, NULL);
    CHECK(rc == 2);
    CHECK_CONTAINS(err, "give a focal length in px");
    free(out), free(err);
    rc = test_refl_run(30, &out, &err, "calib", "geometry", "--corners", c, "--imagersize", "640", "480",
                       "--object-spacing", "0.03", "--square-mm", "30", "-o", x, NULL);
    CHECK(rc == 2);
    CHECK_CONTAINS(err, "not both");
    free(out), free(err);
    static const char *const bad[] = { "3furlongs", "20m", "0.5um", "m" };
    for (int k = 0; k < 4; k++) {
        rc = test_refl_run(30, &out, &err, "calib", "geometry", "--corners", c, "--imagersize", "640", "480",
                           "--object-spacing", bad[k], "-o", x, NULL);
        CHECK_MSG(rc == 2, "--object-spacing %s: exit %d", bad[k], rc);
        CHECK_CONTAINS(err, "in metres");
        free(out), free(err);
    }
    // accepted spellings get past the options to the corners file (one corner: too few views)
    static const char *const good[] = { "0.03", "0.03m", "3cm", "30mm" };
    for (int k = 0; k < 4; k++) {
        rc = test_refl_run(30, &out, &err, "calib", "geometry", "--corners-cache", c, "--imagersize", "640", "480",
                           "--object-spacing", good[k], "--object-width-n", "10", "--focal", "800", "-o", x, NULL);
        CHECK_MSG(rc == 1, "--object-spacing %s: exit %d: %s", good[k], rc, err ? err : "");
        free(out), free(err);
    }
    rc = test_refl_run(30, &out, &err, "calib", "geometry", "--help", NULL);
    CHECK_CONTAINS(out, "--object-spacing");
    CHECK_CONTAINS(out, "--corners, --corners-cache");
    free(out), free(err);
}

// ---------------------------------------------------------------------------
// camera.cameramodel with mrcal's optimization_inputs and refl's extrinsics

static double normal(GRand *r)
{
    double u = g_rand_double_range(r, 1e-12, 1), v = g_rand_double(r);
    return sqrt(-2 * log(u)) * cos(2 * M_PI * v);
}

// Corners of a 10 x 10 board (30 mm) in nviews poses seen by the model at
// path, 0.1 px noise (fixed seed), as mrgingham's vnl.
static const char *board_corners(const char *model_path, int nviews)
{
    model_camera_t *src = model_camera_load(model_path), *cam = NULL;
    CHECK(src != NULL);
    if (src) {   // the same lens at the origin: the poses are in its frame
        cam = model_camera_new(model_camera_lensmodel(src), model_camera_intrinsics(src, NULL),
                               model_camera_width(src), model_camera_height(src), (double[6]){ 0 });
        model_camera_free(src);
    }
    if (!cam) return NULL;
    // the board's poses: its centre 700..1000 mm ahead, tilted up to 35 deg, turned
    GString *g = g_string_new("# filename x y level\n");
    GRand *rnd = g_rand_new_with_seed(20261125);
    int made = 0;
    for (int v = 0; v < 400 && made < nviews; v++) {
        double ax = g_rand_double_range(rnd, -0.6, 0.6), ay = g_rand_double_range(rnd, -0.6, 0.6);
        double az = g_rand_double_range(rnd, -M_PI, M_PI), d = g_rand_double_range(rnd, 700, 1000);
        double cx = g_rand_double_range(rnd, -150, 150), cy = g_rand_double_range(rnd, -120, 120);
        model_vec3_t P[100];
        for (int j = 0; j < 10; j++)
            for (int i = 0; i < 10; i++) {
                // board point about its centre, turned by az about z, then tilted about x and y
                double bx = (i - 4.5) * 30, by = (j - 4.5) * 30;
                double x = bx * cos(az) - by * sin(az), y = bx * sin(az) + by * cos(az), z = 0;
                double y2 = y * cos(ax) - z * sin(ax), z2 = y * sin(ax) + z * cos(ax);
                double x3 = x * cos(ay) + z2 * sin(ay), z3 = -x * sin(ay) + z2 * cos(ay);
                P[j * 10 + i] = (model_vec3_t){ x3 + cx, y2 + cy, z3 + d };
            }
        double q[200];
        bool in = model_camera_project(cam, P, 100, q);
        for (int k = 0; in && k < 100; k++)
            in = q[2 * k] > 10 && q[2 * k] < 1270 && q[2 * k + 1] > 10 && q[2 * k + 1] < 1014;
        if (!in) continue;
        for (int k = 0; k < 100; k++)
            g_string_append_printf(g, "v%02d.png %.4f %.4f 0\n", made, q[2 * k] + 0.1 * normal(rnd),
                                   q[2 * k + 1] + 0.1 * normal(rnd));
        made++;
    }
    CHECK(made == nviews);
    g_rand_free(rnd);
    model_camera_free(cam);
    const char *p = test_write("corners.vnl", g->str);
    g_string_free(g, TRUE);
    return p;
}

static const char MRCAL_PY[] =
    "import sys, mrcal, numpy as np\n"
    "merged, solve, rt = sys.argv[1], sys.argv[2], [float(x) for x in sys.argv[3:9]]\n"
    "m, s = mrcal.cameramodel(merged), mrcal.cameramodel(solve)\n"
    "oi = m.optimization_inputs()\n"
    "assert oi is not None, 'no optimization_inputs'\n"
    "print('spacing', oi['calibration_object_spacing'])\n"
    "print('extrinsics', np.abs(m.extrinsics_rt_fromref() - np.array(rt)).max())\n"
    "print('intrinsics', np.abs(m.intrinsics()[1] - s.intrinsics()[1]).max())\n"
    "p = np.array([[0., 0., 900.], [200., -150., 900.], [-300., 250., 1200.]])\n"
    "u, u0 = mrcal.projection_uncertainty(p, m, what='worstdirection-stdev'), \\\n"
    "        mrcal.projection_uncertainty(p, s, what='worstdirection-stdev')\n"
    "print('uncertainty', ' '.join('%.6g' % x for x in u), 'same', np.abs(u - u0).max())\n";

TEST(calib_geometry_cameramodel_for_mrcal_tools)
{
    char mp[4096];
    snprintf(mp, sizeof mp, "%s/examples/camera.cameramodel", test_srcdir());
    const char *corners = board_corners(mp, 14), *dir = test_path("geo");
    if (!corners) return;
    char *out = NULL, *err = NULL;
    // mrcal's option names, the spacing in metres
    int rc = test_refl_run(180, &out, &err, "calib", "geometry", "--corners-cache", corners, "--imagersize", "1280",
                           "1024", "--focal", "1700", "--object-spacing", "0.03", "--object-width-n", "10", "-o", dir,
                           NULL);
    CHECK_MSG(rc == 0, "refl calib geometry: exit %d: %s", rc, err ? err : "");
    free(out), free(err);
    char cam[4200], solve[4200], moved[4200];
    snprintf(cam, sizeof cam, "%s/camera.cameramodel", dir);
    snprintf(solve, sizeof solve, "%s/mrcal/camera-0.cameramodel", dir);
    snprintf(moved, sizeof moved, "%s", test_path("rig.cameramodel"));
    // refl's camera.cameramodel itself (no turntable: extrinsics zero) and a
    // model of the same camera moved into a rig frame, given mrcal's inputs
    model_camera_t *c = model_camera_load(cam);
    CHECK(c != NULL);
    if (!c) return;
    int n = 0;
    const double *in = model_camera_intrinsics(c, &n);
    const double rt[6] = { 0.3, -1.2, 0.4, 120.5, -80.25, 950 };
    model_camera_t *c2 = model_camera_new(model_camera_lensmodel(c), in, 1280, 1024, rt);
    CHECK(c2 && model_camera_save(c2, moved));
    model_camera_free(c2);
    model_camera_free(c);
    model_error_quiet_thread(true);
    CHECK_MSG(calib_export_keep_optimization_inputs(solve, moved), "%s", model_last_error());
    model_error_quiet_thread(false);
    const char *py = test_write("mrcal_check.py", MRCAL_PY);
    const char *models[2] = { cam, moved };
    for (int k = 0; k < 2; k++) {
        char a[6][32];
        const char *argv[12] = { "/usr/bin/python3", py, models[k], solve };
        for (int i = 0; i < 6; i++) {
            snprintf(a[i], sizeof a[i], "%.17g", k ? rt[i] : 0.0);
            argv[4 + i] = a[i];
        }
        rc = test_run(argv, 120, &out, &err);
        CHECK_MSG(rc == 0, "python3 mrcal on %s: exit %d: %s", models[k], rc, err ? err : "");
        fprintf(stderr, "  %s: %s", k ? "moved to a rig frame" : "camera.cameramodel", out ? out : "");
        CHECK_CONTAINS(out, "spacing 30.0");   // --object-spacing 0.03 (m) reached mrcal as 30 mm
        char *e = out ? strstr(out, "extrinsics ") : NULL, *i = out ? strstr(out, "intrinsics ") : NULL;
        char *s = out ? strstr(out, " same ") : NULL;
        CHECK(e && strtod(e + 11, NULL) < 1e-9);
        CHECK(i && strtod(i + 11, NULL) < 1e-9);
        CHECK(s && strtod(s + 6, NULL) < 1e-9);   // the uncertainty is the solve's: moving the camera changes nothing
        free(out), free(err);
    }
    // mrcal's own command-line tools on them, headless
    char png[4200], png2[4200];
    snprintf(png, sizeof png, "%s", test_path("diff.png"));
    snprintf(png2, sizeof png2, "%s", test_path("uncertainty.png"));
    const char *diff[] = { "/usr/bin/mrcal-show-projection-diff", "--unset", "key", "--hardcopy", png, moved, solve,
                           NULL };
    rc = test_run(diff, 180, &out, &err);
    CHECK_MSG(rc == 0, "mrcal-show-projection-diff: exit %d: %s", rc, err ? err : "");
    CHECK(access(png, R_OK) == 0);
    free(out), free(err);
    const char *unc[] = { "/usr/bin/mrcal-show-projection-uncertainty", "--hardcopy", png2, cam, NULL };
    rc = test_run(unc, 180, &out, &err);
    CHECK_MSG(rc == 0, "mrcal-show-projection-uncertainty: exit %d: %s", rc, err ? err : "");
    free(out), free(err);
    for (int k = 0; k < 2; k++) {
        struct stat st;
        CHECK_MSG(stat(k ? png2 : png, &st) == 0 && st.st_size > 1000, "%s: no figure", k ? png2 : png);
    }
    // and refl's own reader and export take the model with its optimization_inputs
    rc = test_refl_run(30, &out, &err, "calib", "export", moved, "--format", "opencv", "-o", test_path("rig.yaml"),
                       NULL);
    CHECK_MSG(rc == 0, "refl calib export: exit %d: %s", rc, err ? err : "");
    free(out), free(err);
}

// --approximate: a splined model as a fitted LENSMODEL_OPENCV8; OpenCV's
// projection of rays the splined model unprojects (a grid other than the
// fit's) lands within the stated error of their pixels.
TEST(calib_export_approximate_splined)
{
    char mp[4096];
    snprintf(mp, sizeof mp, "%s/examples/camera-adversarial.cameramodel", test_srcdir());
    const char *yml = test_path("adv.yaml");
    char *out = NULL, *err = NULL;
    int rc = test_refl_run(120, &out, &err, "calib", "export", mp, "--format", "opencv", "--approximate", "-o", yml,
                           NULL);
    CHECK_MSG(rc == 0, "exit %d: %s", rc, err ? err : "");
    const char *at = out ? strstr(out, "RMS ") : NULL, *mx = out ? strstr(out, "max ") : NULL;
    CHECK(at && mx);
    if (!at || !mx) return;
    double rms = strtod(at + 4, NULL), max = strtod(mx + 4, NULL);
    fprintf(stderr, "  stated: RMS %.4g px, max %.4g px\n", rms, max);
    CHECK(rms > 0 && max >= rms && max < 1);
    free(out), free(err);
    // rays through pixels of a grid off the fit's, 800 mm away, from the splined model (camera frame)
    model_camera_t *src = model_camera_load(mp), *cam = NULL;
    CHECK(src != NULL);
    if (!src) return;
    cam = model_camera_new(model_camera_lensmodel(src), model_camera_intrinsics(src, NULL), 1280, 1024,
                           (double[6]){ 0 });
    model_camera_free(src);
    double q[2 * 13 * 11];
    model_vec3_t d[13 * 11];
    int n = 0;
    for (int j = 0; j < 11; j++)
        for (int i = 0; i < 13; i++, n++) q[2 * n] = 7 + i * 1265.0 / 12, q[2 * n + 1] = 5 + j * 1013.0 / 10;
    CHECK(cam && model_camera_unproject(cam, q, n, d));
    model_camera_free(cam);
    GString *g = g_string_new("");
    for (int k = 0; k < n; k++)
        g_string_append_printf(g, "%.17g %.17g %.17g\n", d[k].x / d[k].z * 800, d[k].y / d[k].z * 800, 800.0);
    const char *pts = test_write("rays.txt", g->str);
    g_string_free(g, TRUE);
    const char *argv[] = { "/usr/bin/python3", test_write("check.py", PY), "opencv", yml, pts, NULL };
    rc = test_run(argv, 60, &out, &err);
    CHECK_MSG(rc == 0, "python3 cv2: exit %d: %s", rc, err ? err : "");
    char **part = g_strsplit(out ? out : "", "|", -1);
    if (g_strv_length(part) == 4) {
        char **qq = g_strsplit_set(g_strstrip(part[2]), " ", -1);
        CHECK((int)g_strv_length(qq) == 2 * n);
        double worst = 0, ss = 0;
        for (int k = 0; k < n && 2 * k + 1 < (int)g_strv_length(qq); k++) {
            double e = hypot(strtod(qq[2 * k], NULL) - q[2 * k], strtod(qq[2 * k + 1], NULL) - q[2 * k + 1]);
            worst = fmax(worst, e);
            ss += e * e;
        }
        fprintf(stderr, "  cv2.projectPoints on another grid: RMS %.4g px, max %.4g px\n", sqrt(ss / n), worst);
        CHECK(worst <= 1.5 * max);
        CHECK(sqrt(ss / n) <= 1.5 * rms);
        g_strfreev(qq);
    } else CHECK(false);
    g_strfreev(part);
    free(out), free(err);
}
