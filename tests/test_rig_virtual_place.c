// tests/test_rig_virtual_place.c — the virtual rig's placement errors and its
// imperfect turntable axis (rig/virtual/place.h): known answers from
// the truth file's magnitudes, reproducibility, and nothing changed when off.
// The rig serves its camera in-process (no socket, no lock on 127.0.0.1).
#define _GNU_SOURCE
#include <glib.h>
#include <limits.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "model/model.h"
#include "rig/rig.h"
#include "rig/virtual/place.h"
#include "tests/fixtures.h"
#include "tests/test.h"

#define W 1280
#define H 1024
#define D2R (M_PI / 180)

// The example truth file with `from` replaced by `to`, its relative paths made
// absolute, written into the test's directory.
static const char *truth_file_with(const char *file, const char *from, const char *to)
{
    return fx_truth_variant(file, "truth.ini", (const char *const[]){ from, to, NULL }, NULL);
}

static const char *truth_with(const char *from, const char *to)
{
    return truth_file_with("virtual-truth.ini", from, to);
}

static rig_virtual_t *open_truth(const char *path)
{
    rig_virtual_options_t o = rig_virtual_defaults();
    o.serve = RIG_VIRTUAL_SERVE_INPROCESS;
    o.time_scale = 0.001;
    o.noise_seed = 5;
    rig_virtual_t *v = NULL;
    int rc = rig_virtual_open(&v, path, &o);
    CHECK_MSG(rc == 0, "rig_virtual_open %s: %d %s", path, rc, model_last_error());
    return v;
}

#define PLACEMENT "[placement]\nposition_sigma_mm = 2\nangle_sigma_deg = 1.5\nseed = %d\n\n[sample calib_board]"

static const char *placement_truth(int seed)
{
    char to[256];
    snprintf(to, sizeof to, PLACEMENT, seed);
    return truth_with("[sample calib_board]", to);
}

// The calibration board (centred at (130, 0) mm, the truth file's comment),
// placed 400 times with position_sigma_mm = 2, angle_sigma_deg = 1.5: the
// actual poses stay flat on the table, turn about z by N(0, 1.5 deg) and move
// the board's centre by N(0, 2 mm) in x and y (the sample standard deviations
// within 12 %, the means within 4 standard errors). The same seed gives the
// same poses in a new rig, another seed others; and the frames show them.
TEST(virtual_place_placement_spread)
{
    rig_virtual_t *v = open_truth(placement_truth(7));
    if (!v) return;
    enum { N = 400 };
    static double yaw[N], dx[N], dy[N];
    double R[9], t[3], first[5][12];
    for (int k = 0; k < N; k++) {
        CHECK(rig_virtual_set_sample(v, "calib_board") == 0);
        CHECK(rig_virtual_sample_pose(v, NULL, NULL, R, t) == 0);
        CHECK_NEAR(R[8], 1, 1e-12);
        CHECK_NEAR(t[2], 0, 1e-12);
        yaw[k] = atan2(R[3], R[0]) / D2R;
        dx[k] = R[0] * 130 + t[0] - 130;
        dy[k] = R[3] * 130 + t[1];
        double turn, ex, ey;   // the error as the rig reports it (and a capture journals it)
        CHECK(rig_virtual_last_placement(v, &turn, &ex, &ey));
        CHECK_NEAR(turn, yaw[k], 1e-9);
        CHECK_NEAR(ex, dx[k], 1e-9);
        CHECK_NEAR(ey, dy[k], 1e-9);
        if (k < 5) memcpy(first[k], R, sizeof R), memcpy(first[k] + 9, t, sizeof t);
    }
    // a check (a capture's of its plan) places nothing
    double R2[9], t2[3];
    CHECK(rig_virtual_check_sample_pose(v, "coupon_metal", 20, 90) == 0);
    CHECK(rig_virtual_check_sample_pose(v, "no_such_sample", 0, 0) == RIG_ERR_INVALID);
    CHECK(rig_virtual_check_sample_pose(v, "flat_field", 10, 0) == RIG_ERR_INVALID);
    CHECK(rig_virtual_sample_pose(v, NULL, NULL, R2, t2) == 0);
    CHECK(!strcmp(rig_virtual_sample(v), "calib_board") && !memcmp(R, R2, sizeof R) && !memcmp(t, t2, sizeof t));
    double m[3] = { 0 }, q[3] = { 0 };
    for (int k = 0; k < N; k++) {
        double x[3] = { yaw[k], dx[k], dy[k] };
        for (int i = 0; i < 3; i++) m[i] += x[i] / N, q[i] += x[i] * x[i] / N;
    }
    double want[3] = { 1.5, 2, 2 };
    for (int i = 0; i < 3; i++) {
        double sd = sqrt(q[i] - m[i] * m[i]);
        printf("  placement %s: mean %.3f sd %.3f (configured %.1f)\n", i ? (i == 1 ? "dx mm" : "dy mm") : "yaw deg",
               m[i], sd, want[i]);
        CHECK_REL(sd, want[i], 0.12);
        CHECK(fabs(m[i]) < 4 * want[i] / sqrt(N));
    }
    // the frame shows the placed board: not the nominal one
    float *A = malloc((size_t)W * H * sizeof(float)), *B = malloc((size_t)W * H * sizeof(float));
    CHECK(A && B);
    rig_virtual_close(v);
    // reproducible: the same seed, the same first placements (the rig opens with
    // t_stiffener placed once, which counts for that sample only)
    v = open_truth(placement_truth(7));
    for (int k = 0; v && k < 5; k++) {
        CHECK(rig_virtual_set_sample(v, "calib_board") == 0);
        CHECK(rig_virtual_sample_pose(v, NULL, NULL, R, t) == 0);
        CHECK(!memcmp(R, first[k], sizeof R) && !memcmp(t, first[k] + 9, sizeof t));
    }
    if (v && A && B) CHECK(rig_virtual_expected(v, 0, 0xf, 10000, 0, "Mono12", W, H, A) == 0);
    rig_virtual_close(v);
    v = open_truth(placement_truth(8));
    if (v) {
        CHECK(rig_virtual_set_sample(v, "calib_board") == 0);
        CHECK(rig_virtual_sample_pose(v, NULL, NULL, R, t) == 0);
        CHECK(memcmp(t, first[0] + 9, sizeof t) != 0);
    }
    rig_virtual_close(v);
    v = open_truth(truth_with("[sample calib_board]", "[sample calib_board]"));
    if (v && A && B) {
        CHECK(rig_virtual_set_sample(v, "calib_board") == 0);
        CHECK(rig_virtual_expected(v, 0, 0xf, 10000, 0, "Mono12", W, H, B) == 0);
        long differ = 0;
        for (size_t i = 0; i < (size_t)W * H; i++) differ += fabsf(A[i] - B[i]) > 20;
        printf("  placed vs nominal board: %ld pixels differ by > 20 DN\n", differ);
        CHECK(differ > 1000);
    }
    rig_virtual_close(v);
    free(A);
    free(B);
}

// Two cameras see one placement: both views' samples take the same actual pose;
// on the wedge the error stays in the wedge's face (the sample's normal is the wedge's).
TEST(virtual_place_two_cameras_one_placement)
{
    rig_virtual_t *v = open_truth(truth_file_with("virtual-truth-2cam.ini", "[sample t_stiffener]",
                                                  "[placement]\nposition_sigma_mm = 1\nangle_sigma_deg = 1\n\n"
                                                  "[sample t_stiffener]"));
    if (!v) return;
    CHECK(rig_virtual_ncameras(v) == 2);
    for (int k = 0; k < 40; k++) {
        double R0[9], t0[3], R1[9], t1[3];
        CHECK(rig_virtual_set_sample_pose(v, "coupon_metal", k % 2 ? 30 : 0, 90) == 0);
        CHECK(rig_virtual_sample_pose(rig_virtual_camera_view(v, 0), NULL, NULL, R0, t0) == 0);
        CHECK(rig_virtual_sample_pose(rig_virtual_camera_view(v, 1), NULL, NULL, R1, t1) == 0);
        CHECK(!memcmp(R0, R1, sizeof R0) && !memcmp(t0, t1, sizeof t0));
        CHECK(t0[0] != 0 || t0[1] != 0);
        // the error lies in the plane it rests on: the sample's normal stays the wedge's (30 deg about y)
        CHECK_NEAR(R0[2], k % 2 ? 0.5 : 0, 1e-12);
        CHECK_NEAR(R0[5], 0, 1e-12);
        CHECK_NEAR(R0[8], k % 2 ? sqrt(0.75) : 1, 1e-12);
    }
    rig_virtual_close(v);
}

// Turntable axis tilted by 0.5 deg towards azimuth 30 deg: a point at radius
// 100 mm runs on a circle whose plane's normal is the leaning axis, its height
// swinging by +-100 sin 0.5 deg; the platter's normal is the axis at every
// angle (no wobble). The ideal stage's pose is Rz(angle) exactly.
TEST(virtual_place_axis_tilt)
{
    rig_virtual_t *v = open_truth(truth_with("position_noise_deg = 0.002\n",
                                             "position_noise_deg = 0.002\naxis_tilt_deg = 0.5\n"
                                             "axis_tilt_azimuth_deg = 30\n"));
    if (!v) return;
    double a[3] = { sin(0.5 * D2R) * cos(30 * D2R), sin(0.5 * D2R) * sin(30 * D2R), cos(0.5 * D2R) };
    double zmin = INFINITY, zmax = -INFINITY, R[9];
    for (int k = 0; k < 360; k++) {
        CHECK(rig_virtual_table_pose(v, k, R) == 0);
        double p[3] = { R[0] * 100, R[3] * 100, R[6] * 100 };   // R (100, 0, 0)
        zmin = fmin(zmin, p[2]), zmax = fmax(zmax, p[2]);
        CHECK_NEAR(p[0] * a[0] + p[1] * a[1] + p[2] * a[2], 0, 1e-9);   // in the plane normal to the axis
        CHECK_NEAR(R[2], a[0], 1e-12);
        CHECK_NEAR(R[5], a[1], 1e-12);
        CHECK_NEAR(R[8], a[2], 1e-12);
    }
    printf("  axis tilt 0.5 deg: height swing %.4f mm (want %.4f)\n", (zmax - zmin) / 2, 100 * sin(0.5 * D2R));
    CHECK_NEAR((zmax - zmin) / 2, 100 * sin(0.5 * D2R), 1e-3);
    // the frames render through it
    float *A = malloc((size_t)W * H * sizeof(float)), *B = malloc((size_t)W * H * sizeof(float));
    CHECK(A && B);
    if (A && B) CHECK(rig_virtual_expected(v, 40, 0xf, 10000, 0, "Mono12", W, H, A) == 0);
    rig_virtual_close(v);
    v = open_truth(truth_with("position_noise_deg = 0.002\n", "position_noise_deg = 0.002\n"));
    if (v) {
        CHECK(rig_virtual_table_pose(v, 40, R) == 0);
        CHECK(R[0] == cos(40 * D2R) && R[3] == sin(40 * D2R) && R[8] == 1 && R[2] == 0 && R[6] == 0);
        if (A && B) {
            CHECK(rig_virtual_expected(v, 40, 0xf, 10000, 0, "Mono12", W, H, B) == 0);
            long differ = 0;
            for (size_t i = 0; i < (size_t)W * H; i++) differ += fabsf(A[i] - B[i]) > 20;
            printf("  tilted vs ideal axis at 40 deg: %ld pixels differ by > 20 DN\n", differ);
            CHECK(differ > 100);
        }
    }
    rig_virtual_close(v);
    free(A);
    free(B);
}

// Wobble 0.2 deg: a point 50 mm above the platter's centre circles the axis
// once per revolution with radius 50 sin 0.2 deg at a constant height, its
// offset pointing along the table's angle; the platter's normal cones about z
// at 0.2 deg.
TEST(virtual_place_wobble)
{
    rig_virtual_t *v = open_truth(truth_with("position_noise_deg = 0.002\n",
                                             "position_noise_deg = 0.002\nwobble_deg = 0.2\n"));
    if (!v) return;
    double R[9];
    for (int k = 0; k < 360; k += 5) {
        CHECK(rig_virtual_table_pose(v, k, R) == 0);
        double p[3] = { R[2] * 50, R[5] * 50, R[8] * 50 };   // R (0, 0, 50)
        CHECK_NEAR(hypot(p[0], p[1]), 50 * sin(0.2 * D2R), 1e-9);
        CHECK_NEAR(p[2], 50 * cos(0.2 * D2R), 1e-9);
        CHECK_NEAR(atan2(p[1], p[0]), atan2(sin(k * D2R), cos(k * D2R)), 1e-9);
        CHECK_NEAR(acos(R[8]) / D2R, 0.2, 1e-9);
    }
    rig_virtual_close(v);
}

// Off: the keys at 0 change no bit of a frame; bad values name their line.
TEST(virtual_place_off_and_errors)
{
    float *A = malloc((size_t)W * H * sizeof(float)), *B = malloc((size_t)W * H * sizeof(float));
    CHECK(A && B);
    rig_virtual_t *v = open_truth(truth_with("[sample calib_board]", "[sample calib_board]"));
    if (v && A) CHECK(rig_virtual_expected(v, 25, 0x5, 10000, 0, "Mono12", W, H, A) == 0);
    if (v) CHECK(rig_virtual_set_sample(v, "calib_board") == 0 && !rig_virtual_last_placement(v, NULL, NULL, NULL));
    rig_virtual_close(v);
    v = open_truth(truth_with("position_noise_deg = 0.002\n", "position_noise_deg = 0.002\naxis_tilt_deg = 0\n"
                              "wobble_deg = 0\n\n[placement]\nposition_sigma_mm = 0\nangle_sigma_deg = 0\n"));
    if (v && A && B) {
        CHECK(rig_virtual_expected(v, 25, 0x5, 10000, 0, "Mono12", W, H, B) == 0);
        CHECK(!memcmp(A, B, (size_t)W * H * sizeof(float)));
    }
    rig_virtual_close(v);
    free(A);
    free(B);
    static const char *bad[][2] = { { "wobble_deg = 9\n", "wobble_deg" },
                                    { "axis_tilt_deg = x\n", "not a number" },
                                    { "\n[placement]\nangle_sigma_deg = -1\n", "angle_sigma_deg" },
                                    { "\n[placement]\nsigma_mm = 1\n", "unknown key 'sigma_mm'" } };
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        char to[256];
        snprintf(to, sizeof to, "position_noise_deg = 0.002\n%s", bad[i][0]);
        const char *path = truth_with("position_noise_deg = 0.002\n", to);
        rig_virtual_options_t o = rig_virtual_defaults();
        o.serve = RIG_VIRTUAL_SERVE_INPROCESS;
        rig_virtual_t *w = NULL;
        CHECK(rig_virtual_open(&w, path, &o) == RIG_ERR_INVALID);
        CHECK(w == NULL);
        CHECK_CONTAINS(model_last_error(), path);
        CHECK_CONTAINS(model_last_error(), bad[i][1]);
    }
}

static model_camera_t *example_camera(const char *name)
{
    char top[PATH_MAX], path[PATH_MAX + 64];
    if (!realpath(test_srcdir(), top)) snprintf(top, sizeof top, "%s", test_srcdir());
    snprintf(path, sizeof path, "%s/examples/%s", top, name);
    model_camera_t *c = model_camera_load(path);
    CHECK_MSG(c != NULL, "%s: %s", path, model_last_error());
    return c;
}

// The adversarial truth lens (examples/camera-adversarial.cameramodel, a
// splined mrcal model made by scripts/make-example-camera --adversarial) and
// its best OPENCV8 fit (camera-adversarial-opencv8.cameramodel): over the
// imager they project the same points 0.052 px RMS apart (0.19 px at most), as
// the script states in both files' notes; and the virtual rig renders through
// the splined lens (its frame differs from the example camera's).
TEST(virtual_place_splined_lens)
{
    model_camera_t *s = example_camera("camera-adversarial.cameramodel");
    model_camera_t *o = example_camera("camera-adversarial-opencv8.cameramodel");
    if (!s || !o) goto done;
    CHECK_CONTAINS(model_camera_lensmodel(s), "LENSMODEL_SPLINED_STEREOGRAPHIC");
    CHECK(!strcmp(model_camera_lensmodel(o), "LENSMODEL_OPENCV8"));
    enum { NX = 65, NY = 52 };
    static double q[NX * NY * 2], q2[NX * NY * 2];
    static model_vec3_t d[NX * NY], p[NX * NY];
    for (int j = 0; j < NY; j++)
        for (int i = 0; i < NX; i++) {
            q[2 * (j * NX + i)] = i * (W - 1) / (NX - 1.0);
            q[2 * (j * NX + i) + 1] = j * (H - 1) / (NY - 1.0);
        }
    CHECK(model_camera_unproject(s, q, NX * NY, d));
    model_vec3_t c = model_camera_centre_world(s);
    for (int k = 0; k < NX * NY; k++)
        p[k] = (model_vec3_t){ c.x + 900 * d[k].x, c.y + 900 * d[k].y, c.z + 900 * d[k].z };
    CHECK(model_camera_project(s, p, NX * NY, q2));
    double back = 0;
    for (int k = 0; k < 2 * NX * NY; k++) back = fmax(back, fabs(q2[k] - q[k]));
    CHECK(back < 1e-3);   // the splined lens unprojects and projects consistently
    CHECK(model_camera_project(o, p, NX * NY, q2));
    double s2 = 0, mx = 0;
    for (int k = 0; k < NX * NY; k++) {
        double e2 = pow(q2[2 * k] - q[2 * k], 2) + pow(q2[2 * k + 1] - q[2 * k + 1], 2);
        s2 += e2;
        mx = fmax(mx, sqrt(e2));
    }
    printf("  splined truth lens vs its OPENCV8 fit: %.4f px RMS, %.4f px max over the imager\n",
           sqrt(s2 / (NX * NY)), mx);
    CHECK_REL(sqrt(s2 / (NX * NY)), 0.0521, 0.05);
    CHECK(mx > 0.15 && mx < 0.21);
    // rendered through: the truth's camera replaced by the splined one
    char sha[65], to[512];
    snprintf(sha, sizeof sha, "%s", model_camera_sha256(s));
    snprintf(to, sizeof to, "model = camera-adversarial.cameramodel\nmodel_sha256 = %s\n", sha);
    float *A = malloc((size_t)W * H * sizeof(float)), *B = malloc((size_t)W * H * sizeof(float));
    CHECK(A && B);
    const char *path = truth_with("model = camera.cameramodel\nmodel_sha256 = "
                                  "6783d8b842ba892ea02876a0c2fd51836075ac69e8bae753d3930a7e5b54ba44\n", to);
    rig_virtual_t *v = open_truth(path);
    if (v && A) {
        CHECK_CONTAINS(model_camera_lensmodel(rig_virtual_camera_model(v)), "SPLINED");
        CHECK(rig_virtual_expected(v, 10, 0xf, 10000, 0, "Mono12", W, H, A) == 0);
    }
    rig_virtual_close(v);
    v = open_truth(truth_with("[sample calib_board]", "[sample calib_board]"));
    if (v && A && B) {
        CHECK(rig_virtual_expected(v, 10, 0xf, 10000, 0, "Mono12", W, H, B) == 0);
        long differ = 0;
        for (size_t i = 0; i < (size_t)W * H; i++) differ += fabsf(A[i] - B[i]) > 20;
        printf("  splined vs example camera's frame: %ld pixels differ by > 20 DN\n", differ);
        CHECK(differ > 1000);
    }
    rig_virtual_close(v);
    free(A);
    free(B);
done:
    model_camera_free(s);
    model_camera_free(o);
}

// Board flex 0.3 mm on the calibration board (390 x 390 mm, centred at (130,
// 0)): every vertex rises by 0.3 rho^2 / rho_max^2, so the corners stand 0.3
// mm above the centre (its sag), each face is split into flat triangles, a
// dome (-0.3) keeps its lowest point; the rig renders the bent board, and a
// flex_mm on a sample that is no chessboard names its line.
TEST(virtual_place_board_flex)
{
    char top[PATH_MAX], path[PATH_MAX + 64];
    if (!realpath(test_srcdir(), top)) snprintf(top, sizeof top, "%s", test_srcdir());
    snprintf(path, sizeof path, "%s/examples/samples/calib_board.d3d", top);
    model_scene_t *b = model_scene_load(path, NULL);
    CHECK_MSG(b != NULL, "%s", model_last_error());
    if (!b) return;
    model_scene_t *f = rig_virtual_place_flexed(b, 0.3), *g = rig_virtual_place_flexed(b, -0.3);
    CHECK(f && g);
    if (f && g) {
        CHECK(f->nvertices == b->nvertices);
        int ntri = 0;
        for (int k = 0; k < b->nfaces; k++) ntri += b->faces[k].nverts - 2;
        CHECK(f->nfaces == ntri);
        double zmin0 = INFINITY, zmin1 = INFINITY, rmax = 0;
        for (int i = 0; i < b->nvertices; i++) {
            model_vec3_t p = b->vertices[i], q = f->vertices[i];
            double r2 = (p.x - 130) * (p.x - 130) + p.y * p.y;
            CHECK(q.x == p.x && q.y == p.y);
            CHECK_NEAR(q.z - p.z, 0.3 * r2 / (2 * 195.0 * 195.0), 1e-12);
            CHECK_NEAR(g->vertices[i].z - p.z, -0.3 * r2 / (2 * 195.0 * 195.0) + 0.3, 1e-12);
            if (sqrt(r2) > rmax - 1e-9) rmax = sqrt(r2);
            zmin0 = fmin(zmin0, p.z), zmin1 = fmin(zmin1, g->vertices[i].z);
        }
        CHECK_NEAR(rmax, 195 * sqrt(2), 1e-9);   // the corners: + 0.3
        CHECK_NEAR(zmin1, zmin0, 1e-12);
    }
    model_scene_free(f);
    model_scene_free(g);
    model_scene_free(b);
    float *A = malloc((size_t)W * H * sizeof(float)), *B = malloc((size_t)W * H * sizeof(float));
    CHECK(A && B);
    rig_virtual_t *v = open_truth(truth_with("corner0_mm = -5 -135 5\n", "corner0_mm = -5 -135 5\nflex_mm = 0.3\n"));
    if (v && A) {
        CHECK(rig_virtual_set_sample(v, "calib_board") == 0);
        CHECK(rig_virtual_expected(v, 0, 0xf, 10000, 0, "Mono12", W, H, A) == 0);
    }
    rig_virtual_close(v);
    v = open_truth(truth_with("corner0_mm = -5 -135 5\n", "corner0_mm = -5 -135 5\n"));
    if (v && A && B) {
        CHECK(rig_virtual_set_sample(v, "calib_board") == 0);
        CHECK(rig_virtual_expected(v, 0, 0xf, 10000, 0, "Mono12", W, H, B) == 0);
        long differ = 0;
        for (size_t i = 0; i < (size_t)W * H; i++) differ += fabsf(A[i] - B[i]) > 20;
        printf("  flexed vs flat board: %ld pixels differ by > 20 DN\n", differ);
        CHECK(differ > 100);
    }
    rig_virtual_close(v);
    free(A);
    free(B);
    const char *bad = truth_with("scene = samples/coupon_metal.d3d\n",
                                 "scene = samples/coupon_metal.d3d\nflex_mm = 1\n");
    rig_virtual_options_t o = rig_virtual_defaults();
    o.serve = RIG_VIRTUAL_SERVE_INPROCESS;
    rig_virtual_t *w = NULL;
    CHECK(rig_virtual_open(&w, bad, &o) == RIG_ERR_INVALID);
    CHECK_CONTAINS(model_last_error(), "flex_mm bends a chessboard");
    CHECK_CONTAINS(model_last_error(), bad);
}

// A capture on a rig with [placement]: the operator step that puts the coupon
// on the wedge reports (and journals) the placement error the truth drew.
TEST(virtual_place_capture_reports_placement)
{
    const char *truth = placement_truth(3);
    char text[2 * PATH_MAX];
    snprintf(text, sizeof text, "[rig]\nbackend = virtual\nserve = inprocess\ntruth = %s\ntime_scale = 0.01\n", truth);
    const char *rig = test_write("rig.ini", text);
    const char *plan = test_write("plan.ini", "[sample]\nname = coupon_matte_paint\nkind = material_coupon\n"
                                  "tilt_deg = 30\n[angles]\nlist = 0\n[lamps]\nsets = east\n[exposure]\nmode = fixed\n"
                                  "list_us = 2000\n");
    char *out = NULL, *err = NULL;
    int rc = test_refl_run(120, &out, &err, "capture", plan, "--rig", rig, "-o", test_path("s"), "--yes", NULL);
    CHECK_MSG(rc == 0, "exit %d: %s", rc, err);
    CHECK_CONTAINS(err, "posed at tilt 30 deg, hinge azimuth 0 deg; truth placement error: turn ");
    const char *line = err ? strstr(err, "operator step 0 done") : NULL;
    if (line) printf("  %.*s\n", (int)strcspn(line, "\n"), line);
    g_free(out);
    g_free(err);
}

// An operator's placement off the fixture by a known amount
// (rig_virtual_set_sample_offset; the detection study's placed-off parts): the
// calibration board (centre (130, 0) mm) turned by 2 deg about its centre and
// shifted by (3, -1) mm: its pose turns by 2 deg and its centre moves to
// (133, -1). With a truth [placement] the offset follows the placement error of
// that placement: the pose is the offset composed with the error the same seed
// gives without an offset. Out-of-range offsets and a uniform source are refused.
TEST(virtual_place_intended_offset)
{
    rig_virtual_t *v = open_truth(truth_with("[sample calib_board]", "[sample calib_board]"));
    if (!v) return;
    double R[9], t[3];
    CHECK(rig_virtual_set_sample_offset(v, "calib_board", 2, 3, -1) == 0);
    CHECK(rig_virtual_sample_pose(v, NULL, NULL, R, t) == 0);
    CHECK_NEAR(atan2(R[3], R[0]) / D2R, 2, 1e-12);
    CHECK_NEAR(R[8], 1, 1e-12);
    CHECK_NEAR(R[0] * 130 + t[0], 133, 1e-9);
    CHECK_NEAR(R[3] * 130 + t[1], -1, 1e-9);
    CHECK(!rig_virtual_last_placement(v, NULL, NULL, NULL));   // no placement error: the truth has none
    CHECK(rig_virtual_set_sample_offset(v, "calib_board", 50, 0, 0) == RIG_ERR_INVALID);
    CHECK(rig_virtual_set_sample_offset(v, "calib_board", 0, NAN, 0) == RIG_ERR_INVALID);
    CHECK(rig_virtual_set_sample_offset(v, "flat_field", 1, 0, 0) == RIG_ERR_INVALID);
    CHECK(rig_virtual_set_sample_offset(v, "no_such_sample", 1, 0, 0) == RIG_ERR_INVALID);
    rig_virtual_close(v);
    // with placement errors: offset after error
    double Re[9], te[3];
    v = open_truth(placement_truth(11));
    if (!v) return;
    CHECK(rig_virtual_set_sample(v, "calib_board") == 0);
    CHECK(rig_virtual_sample_pose(v, NULL, NULL, Re, te) == 0);
    rig_virtual_close(v);
    v = open_truth(placement_truth(11));
    if (!v) return;
    CHECK(rig_virtual_set_sample_offset(v, "calib_board", 2, 3, -1) == 0);
    CHECK(rig_virtual_sample_pose(v, NULL, NULL, R, t) == 0);
    CHECK(rig_virtual_last_placement(v, NULL, NULL, NULL));
    double yaw_e = atan2(Re[3], Re[0]) / D2R;
    CHECK_NEAR(atan2(R[3], R[0]) / D2R, yaw_e + 2, 1e-9);
    // the board's centre: where the error put it, turned 2 deg about the centre, shifted
    double ex = Re[0] * 130 + te[0], ey = Re[3] * 130 + te[1], c = cos(2 * D2R), s = sin(2 * D2R);
    CHECK_NEAR(R[0] * 130 + t[0], c * (ex - 130) - s * ey + 130 + 3, 1e-9);
    CHECK_NEAR(R[3] * 130 + t[1], s * (ex - 130) + c * ey - 1, 1e-9);
    rig_virtual_close(v);
}
