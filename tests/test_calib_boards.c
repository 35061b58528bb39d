// tests/test_calib_boards.c — boards other than mrgingham's square
// chessboard: W x H chessboards and ChArUco boards.
//
// - The detector (calib/geometry/board_detect.h, OpenCV) on synthetic images with known
//   corners: a board rendered through a homography (calib_board_render, 8 x 8
//   samples a pixel, a little blur and noise), every corner found checked
//   against its true position (sub-pixel: stated tolerance below); a ChArUco
//   board partly out of the image gives the corners it shows, with their ids;
//   a blank image no board, with the reason; bad board descriptions refused.
// - mrcal with missing corners: synthetic corners of an 8 x 6 board projected
//   through the example camera, some views cut by the imager's edge (their
//   corners beyond it written "nan nan -" as mrcal reads them), solved through
//   --corners: the partial views are used, a view of too few corners is left
//   out with the reason, the projection agrees with the truth's.
// - The virtual rig: an 8 x 6 chessboard (scripts/make-calib-board 8x6) and a
//   ChArUco board (scripts/make-charuco-board), generated into the test's
//   directory with a copy of examples/virtual-truth.ini that names them,
//   rendered, found by OpenCV and calibrated through `refl calib geometry
//   --rig`, against the truth camera as calib_geometry_virtual_rig judges it
//   (the mrcal-style projection difference at 900 mm over the imager).
// - Usage errors of the board options (exit 2, the option named).
#define _GNU_SOURCE
#include <glib.h>
#include <jansson.h>
#include <limits.h>
#include <mrcal/mrcal.h>
#include <mrcal/poseutils.h>
#include <stdlib.h>
#include <unistd.h>

#include "calib/geometry/board_detect.h"
#include "calib/geometry/geometry.h"
#include "model/model.h"
#include "tests/fixtures.h"
#include "tests/test.h"

#define DEG (M_PI / 180.0)

// Deterministic numbers (xorshift; Box-Muller).
static uint64_t rng = 0x9E3779B97F4A7C15ull;
static double urand(void)
{
    rng ^= rng << 13;
    rng ^= rng >> 7;
    rng ^= rng << 17;
    return (double)(rng >> 11) / 9007199254740992.0;
}
static double nrand(void)
{
    double u = urand(), v = urand();
    return sqrt(-2 * log(u > 1e-300 ? u : 1e-300)) * cos(2 * M_PI * v);
}

// H = K [r1 r2 t] of a board at pose rt (r rad, t mm) seen by a pinhole f, (cx, cy).
static void homography(const double rt[6], double f, double cx, double cy, double H[9])
{
    double R[9];
    mrcal_R_from_r(R, NULL, rt);
    const double cols[3][3] = { { R[0], R[3], R[6] }, { R[1], R[4], R[7] }, { rt[3], rt[4], rt[5] } };
    for (int c = 0; c < 3; c++) {
        H[0 * 3 + c] = f * cols[c][0] + cx * cols[c][2];
        H[1 * 3 + c] = f * cols[c][1] + cy * cols[c][2];
        H[2 * 3 + c] = cols[c][2];
    }
}

static void apply_h(const double H[9], double x, double y, double *u, double *v)
{
    double w = H[6] * x + H[7] * y + H[8];
    *u = (H[0] * x + H[1] * y + H[2]) / w;
    *v = (H[3] * x + H[4] * y + H[5]) / w;
}

// A 3 x 3 binomial blur (a lens's) and Gaussian noise of sigma grey levels.
static void blur_noise(unsigned char *img, int w, int h, double sigma)
{
    unsigned char *t = malloc((size_t)w * h);
    memcpy(t, img, (size_t)w * h);
    for (int y = 1; y < h - 1; y++)
        for (int x = 1; x < w - 1; x++) {
            double s = 0;
            for (int dy = -1; dy <= 1; dy++)
                for (int dx = -1; dx <= 1; dx++) s += t[(y + dy) * w + x + dx] * (2 - abs(dx)) * (2 - abs(dy));
            s = s / 16 + sigma * nrand();
            img[y * w + x] = s <= 0 ? 0 : s >= 255 ? 255 : (unsigned char)lround(s);
        }
    free(t);
}

// Every corner found against the truth (H of board point (i, j) spacing); the
// largest error, px; *bad: found corners more than 1 px off (a wrong id).
static double corner_errors(const calib_board_t *b, const double H[9], const double *q, int *nfound, int *bad,
                            double *rms)
{
    double worst = 0, ss = 0;
    *nfound = *bad = 0;
    for (int k = 0; k < b->width_n * b->height_n; k++) {
        if (!isfinite(q[2 * k])) continue;
        double u, v;
        apply_h(H, (k % b->width_n) * b->spacing_mm, (k / b->width_n) * b->spacing_mm, &u, &v);
        double e = hypot(q[2 * k] - u, q[2 * k + 1] - v);
        (*nfound)++;
        if (e > 1) (*bad)++;
        worst = fmax(worst, e);
        ss += e * e;
    }
    *rms = *nfound ? sqrt(ss / *nfound) : NAN;
    return worst;
}

// The chessboard's order is the detector's, up to a half turn (and made
// right-handed in the image): compare with the truth in both orders.
static void reverse(double *q, int n)
{
    for (int a = 0, z = n - 1; a < z; a++, z--)
        for (int c = 0; c < 2; c++) {
            double t = q[2 * a + c];
            q[2 * a + c] = q[2 * z + c];
            q[2 * z + c] = t;
        }
}

TEST(calib_boards_detect_synthetic)
{
    const int W = 800, H = 600;
    unsigned char *img = malloc((size_t)W * H);
    double q[2 * 48], Hm[9];
    char why[256];
    int n, nfound, bad;
    double rms;

    // an 8 x 6 chessboard, 30 mm squares, 700 mm away, tilted 25 deg
    calib_board_t cb = { .kind = CALIB_BOARD_CHESSBOARD, .width_n = 8, .height_n = 6, .spacing_mm = 30 };
    double rt[6] = { 25 * DEG, -10 * DEG, 8 * DEG, -100, -80, 700 };
    homography(rt, 1100, (W - 1) / 2.0, (H - 1) / 2.0, Hm);
    CHECK(calib_board_render(&cb, Hm, W, H, 8, img));
    blur_noise(img, W, H, 1.0);
    double t0 = model_realtime_s();
    n = calib_board_detect(&cb, img, W, H, q, why, sizeof why);
    double t_cb = model_realtime_s() - t0;
    CHECK_MSG(n == 48, "chessboard: %d corners (%s)", n, why);
    if (n == 48) {
        double worst = corner_errors(&cb, Hm, q, &nfound, &bad, &rms);
        if (bad) {   // the other of the two orders a half turn apart
            reverse(q, 48);
            worst = corner_errors(&cb, Hm, q, &nfound, &bad, &rms);
        }
        fprintf(stderr, "  8x6 chessboard (OpenCV findChessboardCornersSB, %.2f s): %d corners, error RMS %.4f px, "
                "worst %.4f px\n", t_cb, nfound, rms, worst);
        CHECK(bad == 0);
        CHECK(rms < 0.05);
        CHECK(worst < 0.12);
    }

    // a ChArUco board of 8 x 6 inner corners (9 x 7 squares), markers 22.5 mm, DICT_4X4_50
    calib_board_t ch = { .kind = CALIB_BOARD_CHARUCO, .width_n = 8, .height_n = 6, .spacing_mm = 30,
                         .marker_mm = 22.5, .dict = "DICT_4X4_50" };
    CHECK(calib_board_render(&ch, Hm, W, H, 8, img));
    blur_noise(img, W, H, 1.0);
    t0 = model_realtime_s();
    n = calib_board_detect(&ch, img, W, H, q, why, sizeof why);
    double t_ch = model_realtime_s() - t0;
    CHECK_MSG(n == 48, "charuco: %d corners (%s)", n, why);
    double worst = corner_errors(&ch, Hm, q, &nfound, &bad, &rms);
    fprintf(stderr, "  8x6 ChArUco (OpenCV aruco, %.2f s): %d corners, error RMS %.4f px, worst %.4f px\n", t_ch,
            nfound, rms, worst);
    CHECK(nfound == 48 && bad == 0);
    CHECK(rms < 0.05);
    CHECK(worst < 0.12);

    // the same board partly out of the image: the corners it shows, by their ids
    double rt2[6] = { 15 * DEG, 20 * DEG, -20 * DEG, 20, -60, 650 };
    homography(rt2, 1100, (W - 1) / 2.0, (H - 1) / 2.0, Hm);
    CHECK(calib_board_render(&ch, Hm, W, H, 8, img));
    blur_noise(img, W, H, 1.0);
    int inside = 0;
    for (int k = 0; k < 48; k++) {
        double u, v;
        apply_h(Hm, (k % 8) * 30.0, (k / 8) * 30.0, &u, &v);
        inside += u > 20 && u < W - 21 && v > 20 && v < H - 21;
    }
    n = calib_board_detect(&ch, img, W, H, q, why, sizeof why);
    worst = corner_errors(&ch, Hm, q, &nfound, &bad, &rms);
    fprintf(stderr, "  ChArUco partly out of the image: %d of 48 corners found (%d well inside), error RMS %.4f px, "
            "worst %.4f px\n", nfound, inside, rms, worst);
    CHECK(inside > 10 && inside < 40);
    CHECK(n == nfound && nfound >= inside - 8 && nfound < 48);
    CHECK(bad == 0);
    CHECK(rms < 0.05);
    CHECK(worst < 0.15);

    // no board: a blank image says so
    memset(img, 200, (size_t)W * H);
    n = calib_board_detect(&ch, img, W, H, q, why, sizeof why);
    CHECK(n == 0);
    CHECK_CONTAINS(why, "no ArUco marker of DICT_4X4_50");
    n = calib_board_detect(&cb, img, W, H, q, why, sizeof why);
    CHECK(n == 0);
    CHECK_CONTAINS(why, "no 8x6 chessboard");
    CHECK(!isfinite(q[0]));

    // bad descriptions: the dictionary too small, the marker larger than its square, an unknown dictionary
    calib_board_t big = ch;
    big.width_n = big.height_n = 10;
    CHECK(calib_board_detect(&big, img, W, H, q, why, sizeof why) == -1);
    CHECK_CONTAINS(model_last_error(), "needs 60");
    CHECK(calib_board_dict_size("DICT_4X4_250") == 250 && calib_board_dict_size("DICT_5X5_1") == 0);
    calib_board_t fat = ch;
    fat.marker_mm = 31;
    CHECK(!calib_board_check(&fat));
    CHECK_CONTAINS(model_last_error(), "--charuco-marker-mm");
    free(img);
}

static const char *example(const char *name)
{
    static char p[PATH_MAX];
    snprintf(p, sizeof p, "%s/examples/%s", test_srcdir(), name);
    return p;
}

static json_t *load_json(const char *dir, const char *name)
{
    char p[PATH_MAX];
    snprintf(p, sizeof p, "%s/%s", dir, name);
    return json_load_file(p, 0, NULL);
}

// The recovered model against the truth camera: the mrcal-style projection
// difference at 900 mm over the whole imager (the rigid transform between the
// two camera frames fitted to every grid point), px RMS; *worst the largest.
static double projection_vs_truth(const char *dir, double *worst)
{
    char mp[PATH_MAX];
    snprintf(mp, sizeof mp, "%s/camera.cameramodel", dir);
    mrcal_cameramodel_t *t = mrcal_read_cameramodel_file(example("camera.cameramodel"));
    mrcal_cameramodel_t *b = mrcal_read_cameramodel_file(mp);
    calib_projection_diff_t d = { 0 };
    bool ok = t && b && calib_projection_diff(t, b, 900, 0, 0, &d);
    CHECK_MSG(ok, "projection difference of %s: %s", mp, model_last_error());
    free(t);
    free(b);
    *worst = ok ? d.worst_px : NAN;
    return ok ? d.rms_px : NAN;
}

// Synthetic corners of a W x H board (30 mm) seen by the truth camera with
// 0.1 px noise: nfull views wholly inside the imager, npart partly outside
// (12..40 of 48 corners inside; those outside "- -"), and one with 6 inside.
static const char *partial_corners(int nfull, int npart, int *nused_partial)
{
    mrcal_cameramodel_t *t = mrcal_read_cameramodel_file(example("camera.cameramodel"));
    CHECK(t != NULL);
    if (!t) return "";
    const int Wn = 8, Hn = 6, N = Wn * Hn;
    const double s = 30;
    int W = (int)t->imagersize[0], H = (int)t->imagersize[1], full = 0, part = 0, few = 0;
    GString *g = g_string_new("# filename x y level\n");
    for (int attempt = 0; (full < nfull || part < npart || few < 1) && attempt < 20000; attempt++) {
        // the board's centre along the ray through a pixel (over the whole imager and beyond), 600..1100 mm away
        mrcal_point2_t qc = { .xy = { -150 + urand() * (W + 300), -150 + urand() * (H + 300) } };
        mrcal_point3_t v;
        mrcal_unproject(&v, &qc, 1, &t->lensmodel, t->intrinsics);
        double vn = sqrt(v.xyz[0] * v.xyz[0] + v.xyz[1] * v.xyz[1] + v.xyz[2] * v.xyz[2]), d = 600 + urand() * 500;
        double rt[6] = { (urand() - 0.5) * 80 * DEG, (urand() - 0.5) * 80 * DEG, urand() * 2 * M_PI, 0, 0, 0 };
        double c[3] = { (Wn - 1) * s / 2, (Hn - 1) * s / 2, 0 }, Rc[3], R[9];
        mrcal_R_from_r(R, NULL, rt);
        for (int i = 0; i < 3; i++) Rc[i] = R[i * 3] * c[0] + R[i * 3 + 1] * c[1];
        for (int k = 0; k < 3; k++) rt[3 + k] = v.xyz[k] / vn * d - Rc[k];
        double cen[3] = { Rc[0] + rt[3], Rc[1] + rt[4], Rc[2] + rt[5] }, nz[3] = { R[2], R[5], R[8] };
        double cn = sqrt(cen[0] * cen[0] + cen[1] * cen[1] + cen[2] * cen[2]);
        if (fabs(nz[0] * cen[0] + nz[1] * cen[1] + nz[2] * cen[2]) / cn < cos(60 * DEG)) continue;
        mrcal_point3_t P[48];
        mrcal_point2_t Q[48];
        for (int k = 0; k < N; k++) {
            double b[3] = { (k % Wn) * s, (k / Wn) * s, 0 };
            for (int i = 0; i < 3; i++) P[k].xyz[i] = R[i * 3] * b[0] + R[i * 3 + 1] * b[1] + rt[3 + i];
        }
        mrcal_project(Q, NULL, NULL, P, N, &t->lensmodel, t->intrinsics);
        int in = 0;
        bool inside[48];
        for (int k = 0; k < N; k++) {
            inside[k] = Q[k].xy[0] > 5 && Q[k].xy[0] < W - 6 && Q[k].xy[1] > 5 && Q[k].xy[1] < H - 6;
            in += inside[k];
        }
        char name[64];
        if (in == N && full < nfull) snprintf(name, sizeof name, "full%02d.png", full++);
        else if (in >= 12 && in <= 40 && part < npart) snprintf(name, sizeof name, "part%02d.png", part++);
        else if (in >= 5 && in <= 7 && !few && (few = 1)) snprintf(name, sizeof name, "few.png");
        else continue;
        for (int k = 0; k < N; k++)
            if (inside[k])
                g_string_append_printf(g, "%s %.4f %.4f 0\n", name, Q[k].xy[0] + 0.1 * nrand(), Q[k].xy[1] + 0.1 * nrand());
            else
                g_string_append_printf(g, "%s - -\n", name);
    }
    g_string_append(g, "blank.png - -\n");
    CHECK(full == nfull && part == npart && few == 1);
    *nused_partial = part;
    const char *path = test_write("partial.vnl", g->str);
    g_string_free(g, TRUE);
    free(t);
    return path;
}

TEST(calib_boards_partial_corners_mrcal)
{
    rng = 0x2545F4914F6CDD1Dull;
    int npart = 0;
    const char *corners = partial_corners(18, 8, &npart);
    const char *dir = test_path("out");
    char *out = NULL, *err = NULL;
    double t0 = model_realtime_s();
    int rc = test_refl_run(180, &out, &err, "calib", "geometry", "--corners", corners, "--imagersize", "1280", "1024",
                           "--object-width-n", "8", "--object-height-n", "6", "--focal-px", "1600", "-o", dir, NULL);
    double dt = model_realtime_s() - t0;
    CHECK_MSG(rc == 0, "refl calib geometry --corners (8x6, partial views): exit %d\n%s", rc, err ? err : "");
    json_t *g = load_json(dir, "geometry.json");
    CHECK(g != NULL);
    if (g && rc == 0) {
        json_t *b = json_object_get(g, "board");
        CHECK(!strcmp(json_string_value(json_object_get(b, "kind")), "chessboard"));
        CHECK(json_integer_value(json_object_get(b, "width_n")) == 8);
        CHECK(json_integer_value(json_object_get(b, "height_n")) == 6);
        CHECK_NEAR(json_number_value(json_object_get(b, "spacing_mm")), 30, 1e-12);
        CHECK(json_integer_value(json_object_get(g, "views_used")) == 18 + npart);
        // the partial views used, with their corner counts; the view of 6 corners left out with the reason
        size_t i;
        json_t *im;
        int partial_used = 0;
        json_array_foreach(json_object_get(g, "images"), i, im) {
            const char *name = json_string_value(json_object_get(im, "image"));
            json_int_t nc = json_integer_value(json_object_get(im, "corners_found"));
            if (g_str_has_prefix(name, "part") && json_is_true(json_object_get(im, "board_found")) && nc < 48 &&
                json_is_number(json_object_get(im, "rms_residual_px")))
                partial_used++;
            if (!strcmp(name, "few.png")) {
                CHECK(json_is_false(json_object_get(im, "board_found")));
                CHECK_CONTAINS(json_string_value(json_object_get(im, "why")), "fewer than 12 (--min-corners)");
            }
        }
        CHECK(partial_used == npart);
        CHECK_CONTAINS(err, "few.png");
        // cross-validated with the partial views in both halves (13 views each)
        json_t *xv = json_array_get(json_object_get(json_object_get(g, "cross_validation"), "runs"), 0);
        CHECK_MSG(json_is_true(json_object_get(xv, "done")), "not cross-validated: %s",
                  json_string_value(json_object_get(xv, "why")));
        fprintf(stderr, "  cross-validation of the halves: ratio %.2f\n", json_number_value(json_object_get(xv, "ratio")));
        double rms = json_number_value(json_object_get(g, "rms_residual_px")), worst;
        double d = projection_vs_truth(dir, &worst);
        fprintf(stderr, "  8x6 board, %d of %d views partial (%.1f s): residual RMS %.4f px, %lld points, %lld "
                "outliers; projection difference from the truth at 900 mm RMS %.4f px (worst %.4f)\n", npart,
                18 + npart, dt, rms, json_integer_value(json_object_get(g, "points_used")),
                json_integer_value(json_object_get(g, "outliers")), d, worst);
        CHECK(rms > 0.11 && rms < 0.16);
        CHECK(d < 0.1);    // of 26 views of 48 corners or fewer (the 10 x 10 board, 24 whole views: 0.05)
        CHECK(json_integer_value(json_object_get(g, "outliers")) < 5);
        // mrcal's corners file keeps a partial view's corners not seen as "nan nan -" (mrcal's seed drops NaN;
        // "- -" it would seed from as pixel (-1, -1)); the view left out is one line "NAME - -"
        char p[PATH_MAX];
        snprintf(p, sizeof p, "%s/corners.vnl", dir);
        char *text = model_read_file(p, NULL);
        CHECK(text && strstr(text, "part00.png nan nan -\n") && !strstr(text, "part00.png - -\n"));
        CHECK(text && strstr(text, "few.png - -\n"));
        CHECK(text && !strstr(text, "few.png - -\nfew.png"));
        free(text);
        snprintf(p, sizeof p, "%s/report.html", dir);
        CHECK(access(p, R_OK) == 0);
    }
    json_decref(g);
    free(out);
    free(err);
}

// A board of the virtual rig: scripts/SCRIPT ARGS... writes it into the test's
// directory, and a copy of examples/virtual-truth.ini names it [sample
// NAME] (kind chessboard, its corners) with the renderer cut to what a board
// needs (direct light only: no interreflection) and, with rays > 1, each
// pixel's footprint sampled by rays x rays rays (a camera integrates its
// pixel's area; the matched rig's one ray at the centre leaves every edge a
// staircase, which a ChArUco corner's small window does not average out).
// The rig file (in-process camera, fixed noise seed); its path.
static const char *board_rig(const char *script, const char *const *args, const char *name, const char *corners,
                             int rays)
{
    char scr[PATH_MAX];
    snprintf(scr, sizeof scr, "%s/scripts/%s", test_srcdir(), script);
    char *d3d = g_strdup(test_path("board.d3d"));
    const char *argv[16] = { "/usr/bin/python3", scr, d3d };
    int n = 3;
    for (int k = 0; args[k] && n < 15; k++) argv[n++] = args[k];
    argv[n] = NULL;
    char *out = NULL, *err = NULL;
    int rc = test_run(argv, 60, &out, &err);
    CHECK_MSG(rc == 0, "%s: exit %d\n%s", script, rc, err ? err : "");
    free(out);
    free(err);
    char *extra = g_strdup_printf("[sample %s]\nkind = chessboard\nscene = %s\nsquare_mm = 30\ncorners = %s\n", name,
                                  d3d, corners);
    char *optics = g_strdup_printf("[optics]\nrays_per_pixel = %d\n\n[sensor]\n", rays);
    const char *rep[] = { "interreflection = mc", "interreflection = none", "[sensor]\n", optics, NULL };
    char *truth = g_strdup(fx_truth_variant("virtual-truth.ini", "truth.ini", rep, extra));
    char *rig = g_strdup_printf("[rig]\nbackend = virtual\ntruth = %s\nserve = inprocess\ntime_scale = 0.01\n"
                                "noise_seed = 7\n", truth);
    const char *path = test_write("rig.ini", rig);
    g_free(d3d);
    g_free(extra);
    g_free(optics);
    g_free(truth);
    g_free(rig);
    return path;
}

// The rig's axis (+z of the rig frame) in the recovered camera frame against
// the truth's carried there by the fitted transform of projection_vs_truth's
// comparison (as calib_geometry_virtual_rig judges it), deg.
static double axis_vs_truth(const char *dir)
{
    char mp[PATH_MAX];
    snprintf(mp, sizeof mp, "%s/camera.cameramodel", dir);
    mrcal_cameramodel_t *t = mrcal_read_cameramodel_file(example("camera.cameramodel"));
    mrcal_cameramodel_t *b = mrcal_read_cameramodel_file(mp);
    calib_projection_diff_t d = { 0 };
    double e = NAN;
    if (t && b && calib_projection_diff(t, b, 900, 0, 0, &d)) {
        double Rt[9], Rb[9], Rf[9], zf[3];
        mrcal_R_from_r(Rt, NULL, t->rt_cam_ref);
        mrcal_R_from_r(Rb, NULL, b->rt_cam_ref);
        mrcal_R_from_r(Rf, NULL, d.rt_a_to_b);
        for (int k = 0; k < 3; k++) zf[k] = Rf[k * 3] * Rt[2] + Rf[k * 3 + 1] * Rt[5] + Rf[k * 3 + 2] * Rt[8];
        double cs = zf[0] * Rb[2] + zf[1] * Rb[5] + zf[2] * Rb[8];
        e = acos(cs > 1 ? 1 : cs) / DEG;
    }
    free(t);
    free(b);
    return e;
}

// A calibration on the virtual rig through `refl calib geometry --rig`; its
// geometry.json (NULL on failure) and the run's time.
static json_t *board_calibrate(const char *rig, const char *const *opts, const char *dir, double *dt)
{
    GPtrArray *a = g_ptr_array_new();
    const char *head[] = { test_refl(), "calib", "geometry", "--yes", "--rig", rig, "-o", dir };
    for (size_t k = 0; k < sizeof head / sizeof head[0]; k++) g_ptr_array_add(a, (gpointer)head[k]);
    for (int k = 0; opts[k]; k++) g_ptr_array_add(a, (gpointer)opts[k]);
    g_ptr_array_add(a, NULL);
    char *out = NULL, *err = NULL;
    double t0 = model_realtime_s();
    int rc = test_run((const char *const *)a->pdata, 400, &out, &err);
    *dt = model_realtime_s() - t0;
    g_ptr_array_free(a, TRUE);
    CHECK_MSG(rc == 0, "refl calib geometry --rig: exit %d\n%s", rc, err ? err : "");
    free(out);
    free(err);
    return rc == 0 ? load_json(dir, "geometry.json") : NULL;
}

// An 8 x 6 chessboard (mrgingham cannot find it: OpenCV's findChessboardCornersSB
// does), 18 views of the default tilts' kinds.
TEST_LONG(calib_boards_virtual_rig_chessboard_8x6)
{
    const char *args[] = { "8x6", NULL };
    const char *rig = board_rig("make-calib-board", args, "board_8x6", "8 6", 1);
    const char *opts[] = { "--sample", "board_8x6", "--object-width-n", "8", "--object-height-n", "6", "--tilts",
                           "0:40,240 20@0:0,40,340 20@90:290,320,350 20@180:210,260 35@0:10,40 35@180:210,240 "
                           "50@0:20,40 50@180:210,240", NULL };
    const char *dir = test_path("geo");
    double dt;
    json_t *g = board_calibrate(rig, opts, dir, &dt);
    if (g) {
        json_t *b = json_object_get(g, "board");
        CHECK(!strcmp(json_string_value(json_object_get(b, "kind")), "chessboard"));
        CHECK(json_integer_value(json_object_get(b, "width_n")) == 8 && json_integer_value(json_object_get(b, "height_n")) == 6);
        CHECK(!strcmp(json_string_value(json_object_get(b, "detector")), "opencv"));
        double worst, d = projection_vs_truth(dir, &worst), ax = axis_vs_truth(dir);
        json_t *axj = json_object_get(g, "axis");
        // the half turns between two detections' corner orders: only 0 or 2 quarter turns
        size_t i;
        json_t *im;
        int turned = 0, odd = 0, named = 0, found = 0;
        json_array_foreach(json_object_get(g, "images"), i, im) {
            json_int_t qt = json_integer_value(json_object_get(im, "quarter_turns"));
            turned += qt == 2;
            odd += qt % 2;
            // who found the board, and each detector's outcome (the first tried: findChessboardCornersSB)
            const char *det = json_string_value(json_object_get(im, "detector"));
            const char *att = json_string_value(json_object_get(im, "detector_attempts"));
            found += json_is_true(json_object_get(im, "board_found"));
            named += json_is_true(json_object_get(im, "board_found")) && det && !strncmp(det, "opencv-", 7) && att &&
                     !strncmp(att, "opencv-sb: ", 11) && strstr(att, det);
        }
        CHECK_MSG(named == found && found > 0, "%d of %d views with the board name their detector", named, found);
        char rp[PATH_MAX];
        snprintf(rp, sizeof rp, "%s/report.html", dir);
        char *html = NULL;
        CHECK(g_file_get_contents(rp, &html, NULL, NULL));
        if (html) CHECK_CONTAINS(html, "Views: who found the board");
        g_free(html);
        fprintf(stderr, "  8x6 chessboard on the virtual rig (%.1f s): %lld of %lld views, residual RMS %.4f px; "
                "projection difference from the truth at 900 mm RMS %.4f px (worst %.4f); axis %.4f deg from the "
                "truth's (stated %.4f); %d views half-turned\n", dt, json_integer_value(json_object_get(g, "views_used")),
                json_integer_value(json_object_get(g, "views_total")),
                json_number_value(json_object_get(g, "rms_residual_px")), d, worst, ax,
                json_number_value(json_object_get(axj, "direction_uncertainty_deg")), turned);
        CHECK(json_integer_value(json_object_get(g, "views_used")) >= 15);
        CHECK(json_number_value(json_object_get(g, "rms_residual_px")) < 0.3);
        CHECK(d < 0.15);
        CHECK(ax < 0.1);
        CHECK(odd == 0);
        CHECK_CONTAINS(json_string_value(json_object_get(axj, "method")), "jointly");
        CHECK(json_is_array(json_object_get(g, "rt_cam_rig")));
    }
    json_decref(g);
}

// A ChArUco board (8 x 6 inner corners, 18 mm markers of DICT_4X4_50) off the
// axis, so that in some views part of it leaves the image: those views give
// the corners they show and are used.
TEST_LONG(calib_boards_virtual_rig_charuco)
{
    const char *args[] = { "--corners", "8x6", "--marker-mm", "18", "--centre-mm", "170,0", NULL };
    const char *rig = board_rig("make-charuco-board", args, "charuco_board", "8 6", 2);
    const char *opts[] = { "--sample", "charuco_board", "--board", "charuco", "--object-width-n", "8",
                           "--object-height-n", "6", "--charuco-marker-mm", "18", "--charuco-dict", "DICT_4X4_50",
                           "--tilts", "0:0,90,150,240,300 20@0:0,40,320 20@180:180,140 35@0:0,40,280,320 "
                           "35@180:180,220 50@0:0,30", NULL };
    const char *dir = test_path("geo");
    double dt;
    json_t *g = board_calibrate(rig, opts, dir, &dt);
    if (g) {
        json_t *b = json_object_get(g, "board");
        CHECK(!strcmp(json_string_value(json_object_get(b, "kind")), "charuco"));
        CHECK(!strcmp(json_string_value(json_object_get(b, "dictionary")), "DICT_4X4_50"));
        CHECK_NEAR(json_number_value(json_object_get(b, "marker_mm")), 18, 1e-12);
        size_t i;
        json_t *im;
        int partial = 0, turned = 0;
        json_array_foreach(json_object_get(g, "images"), i, im) {
            if (json_is_true(json_object_get(im, "board_found")) &&
                json_integer_value(json_object_get(im, "corners_found")) < 48 &&
                json_is_number(json_object_get(im, "rms_residual_px")))
                partial++;
            turned += json_integer_value(json_object_get(im, "quarter_turns")) != 0;
        }
        double worst, d = projection_vs_truth(dir, &worst), ax = axis_vs_truth(dir);
        json_t *axj = json_object_get(g, "axis");
        fprintf(stderr, "  ChArUco on the virtual rig (%.1f s): %lld of %lld views (%d partial), %lld corners, residual "
                "RMS %.4f px, %lld outliers; projection difference from the truth at 900 mm RMS %.4f px (worst %.4f); "
                "axis %.4f deg from the truth's (stated %.4f)\n", dt,
                json_integer_value(json_object_get(g, "views_used")),
                json_integer_value(json_object_get(g, "views_total")), partial,
                json_integer_value(json_object_get(g, "points_used")),
                json_number_value(json_object_get(g, "rms_residual_px")),
                json_integer_value(json_object_get(g, "outliers")), d, worst, ax,
                json_number_value(json_object_get(axj, "direction_uncertainty_deg")));
        CHECK(partial >= 2);   // 3 of 18 views partly out of the image
        CHECK(turned == 0);    // a ChArUco corner carries its id: no turn
        CHECK(json_integer_value(json_object_get(g, "views_used")) >= 12);
        CHECK(json_number_value(json_object_get(g, "rms_residual_px")) < 0.3);
        // a partial view seeded from its corners seen: few outliers (seeded with its corners not seen at pixel
        // (-1, -1), 61 of 858 or a wrong solve)
        CHECK(json_integer_value(json_object_get(g, "outliers")) <
              0.04 * (double)(json_integer_value(json_object_get(g, "points_used")) +
                              json_integer_value(json_object_get(g, "outliers"))));
        CHECK(d < 0.15);
        CHECK(ax < 0.1);
        CHECK_CONTAINS(json_string_value(json_object_get(axj, "method")), "jointly");
    }
    json_decref(g);
}

// The board options' usage errors (exit 2, the option named).
TEST(calib_boards_bad_arguments)
{
    const char *c = test_write("c.vnl", "# filename x y level\na.png 1 2 0\n");
    struct { const char *a[6]; const char *says; } cases[] = {
        { { "--board", "wood" }, "--board wood: give chessboard or charuco" },
        { { "--object-height-n", "1" }, "--object-height-n 1" },
        { { "--object-width-n", "8", "--object-height-n", "6", "--detector", "mrgingham" },
          "--detector mrgingham finds square chessboards only" },
        { { "--detector", "eyes" }, "--detector eyes" },
        { { "--board", "charuco", "--charuco-dict", "DICT_9X9_1" }, "--charuco-dict DICT_9X9_1" },
        { { "--charuco-dict", "DICT_4X4_50" }, "give --board charuco" },
        { { "--board", "charuco", "--gridn", "10" }, "needs 60: give the board's dictionary" },
        { { "--board", "charuco", "--square-mm", "20", "--charuco-marker-mm", "25" }, "--charuco-marker-mm 25" },
        { { "--min-corners", "2" }, "--min-corners 2" },
    };
    for (size_t k = 0; k < sizeof cases / sizeof cases[0]; k++) {
        const char *argv[24] = { test_refl(), "calib", "geometry", "--corners", c, "--imagersize", "640", "480", "-o",
                                 test_path("x") };
        int n = 10;
        for (int i = 0; i < 6 && cases[k].a[i]; i++) argv[n++] = cases[k].a[i];
        char *out = NULL, *err = NULL;
        int rc = test_run(argv, 30, &out, &err);
        CHECK_MSG(rc == 2, "case %zu: exit %d", k, rc);
        CHECK_CONTAINS(err, cases[k].says);
        free(out);
        free(err);
    }
    // --help names the board options
    char *out = NULL, *err = NULL;
    CHECK(test_refl_run(30, &out, &err, "calib", "geometry", "--help", NULL) == 0);
    CHECK_CONTAINS(out, "--object-height-n");
    CHECK_CONTAINS(out, "--charuco-dict");
    free(out);
    free(err);
}
