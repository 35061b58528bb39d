// tests/test_model_camera.c — cameras: projection round trips, the ray table and its
// error bound, camera centre, .cameramodel save/load, error messages.
#define _GNU_SOURCE
#include <mrcal/mrcal.h>
#include <pthread.h>
#include <stdlib.h>

#include "model/internal.h"
#include "tests/test.h"

#define W 1280
#define H 1024

static const double rt_test[6] = { 0.12, -0.31, 0.05, 25.0, -40.0, 900.0 };

static const double pinhole[4] = { 1100, 1090, 641.3, 509.8 };
static const double opencv4[8] = { 1100, 1090, 641.3, 509.8, -0.12, 0.08, 0.0012, -0.0007 };
static const double opencv8[12] = { 1100, 1090, 641.3, 509.8, -0.12, 0.08, 0.0012, -0.0007,
                                    -0.015, 0.02, 0.003, -0.004 };
#define SPLINED "LENSMODEL_SPLINED_STEREOGRAPHIC_order=3_Nx=30_Ny=20_fov_x_deg=80"

// A plausible splined lens without a fit: stereographic core plus control
// points that follow a smooth barrel distortion (-0.05 u |u|^2 in stereographic
// coordinates) and small ripples (1e-4, about 0.1 px).
static double *splined_intrinsics(void)
{
    mrcal_lensmodel_t lm;
    if (!mrcal_lensmodel_from_name(&lm, SPLINED)) return NULL;
    int np = mrcal_lensmodel_num_params(&lm), Nx = lm.LENSMODEL_SPLINED_STEREOGRAPHIC__config.Nx,
        Ny = lm.LENSMODEL_SPLINED_STEREOGRAPHIC__config.Ny;
    double *p = calloc((size_t)np, sizeof *p), ux[64], uy[64];
    if (!p || Nx > 64 || Ny > 64 || !mrcal_knots_for_splined_models(ux, uy, &lm)) {
        free(p);
        return NULL;
    }
    p[0] = 1000; p[1] = 995; p[2] = 640.7; p[3] = 511.2;
    for (int j = 0; j < Ny; j++)
        for (int i = 0; i < Nx; i++) {
            double r2 = ux[i] * ux[i] + uy[j] * uy[j];
            p[4 + 2 * (j * Nx + i)]     = -0.05 * ux[i] * r2 + 1e-4 * sin(1.3 * i + j);
            p[4 + 2 * (j * Nx + i) + 1] = -0.05 * uy[j] * r2 + 1e-4 * cos(0.7 * i - 2.1 * j);
        }
    return p;
}

typedef struct {
    const char *lensmodel;
    const double *intrinsics;
} lens_t;

static model_camera_t *make(int i, double **spl)
{
    static const lens_t lenses[3] = { { "LENSMODEL_PINHOLE", pinhole },
                                      { "LENSMODEL_OPENCV4", opencv4 },
                                      { "LENSMODEL_OPENCV8", opencv8 } };
    if (i < 3) return model_camera_new(lenses[i].lensmodel, lenses[i].intrinsics, W, H, rt_test);
    *spl = splined_intrinsics();
    return *spl ? model_camera_new(SPLINED, *spl, W, H, rt_test) : NULL;
}

static double uniform(uint64_t *s)
{
    *s = model_mix64(*s);
    return (*s >> 11) * 0x1.0p-53;
}

// pixel -> exact ray -> a point on it at distances 300..3000 mm -> pixel
TEST(camera_project_unproject_round_trip)
{
    for (int lens = 0; lens < 4; lens++) {
        double *spl = NULL;
        model_camera_t *cam = make(lens, &spl);
        CHECK(cam != NULL);
        if (!cam) continue;
        model_vec3_t C = model_camera_centre_world(cam);
        uint64_t s = 42 + lens;
        double worst = 0;
        enum { N = 500 };
        double q[2 * N], q2[2 * N];
        model_vec3_t d[N], p[N];
        for (int i = 0; i < N; i++) {
            q[2 * i] = -0.5 + uniform(&s) * W;
            q[2 * i + 1] = -0.5 + uniform(&s) * H;
        }
        CHECK(model_camera_unproject(cam, q, N, d));
        for (int i = 0; i < N; i++) {
            CHECK_NEAR(v3_norm(d[i]), 1.0, 1e-12);
            p[i] = v3_add(C, v3_scale(d[i], 300 + 2700 * uniform(&s)));
        }
        CHECK(model_camera_project(cam, p, N, q2));
        for (int i = 0; i < N; i++)
            worst = fmax(worst, hypot(q2[2 * i] - q[2 * i], q2[2 * i + 1] - q[2 * i + 1]));
        CHECK_MSG(worst < 1e-6, "%s: round trip error %.3g px", model_camera_lensmodel(cam), worst);
        // and world -> pixel -> ray: the ray points at the world point
        for (int i = 0; i < N; i++) p[i] = v3_add(p[i], v3(0.01 * i, -0.02 * i, 0.003 * i));
        CHECK(model_camera_project(cam, p, N, q2));
        CHECK(model_camera_unproject(cam, q2, N, d));
        double worst_rad = 0;
        for (int i = 0; i < N; i++)
            worst_rad = fmax(worst_rad, v3_norm(v3_sub(d[i], v3_unit(v3_sub(p[i], C)))));
        CHECK_MSG(worst_rad < 1e-9, "%s: ray misses the point by %.3g rad",
                  model_camera_lensmodel(cam), worst_rad);
        model_camera_free(cam);
        free(spl);
    }
}

// The ray table against the exact unprojection at random integer pixels: the
// reprojection error of the table's ray is within the returned bound, and the
// bound within the 0.005 px tolerance.
TEST(camera_ray_table_bound)
{
    for (int lens = 0; lens < 4; lens++) {
        double *spl = NULL;
        model_camera_t *cam = make(lens, &spl);
        CHECK(cam != NULL);
        if (!cam) continue;
        double bound = -1, bound2 = -2;
        double t0 = model_now_s();
        const model_vec3_t *rays = model_camera_ray_table(cam, &bound);
        double dt = model_now_s() - t0;
        CHECK(rays != NULL);
        if (!rays) {
            model_camera_free(cam);
            free(spl);
            continue;
        }
        CHECK(model_camera_ray_table(cam, &bound2) == rays);   // computed once, kept
        CHECK(bound2 == bound);
        CHECK(bound >= 0 && bound <= 0.005);
        model_vec3_t C = model_camera_centre_world(cam);
        enum { N = 3000 };
        static double q[2 * N], q2[2 * N];
        static model_vec3_t exact[N], p[N];
        uint64_t s = 7 + lens;
        for (int i = 0; i < N; i++) {
            int x = (int)(uniform(&s) * W), y = (int)(uniform(&s) * H);
            if (i < 4) {   // the corners too
                x = i & 1 ? W - 1 : 0;
                y = i & 2 ? H - 1 : 0;
            }
            q[2 * i] = x;
            q[2 * i + 1] = y;
            p[i] = v3_add(C, v3_scale(rays[(size_t)y * W + x], 1000.0));
            CHECK_NEAR(v3_norm(rays[(size_t)y * W + x]), 1.0, 1e-12);
        }
        CHECK(model_camera_project(cam, p, N, q2));
        CHECK(model_camera_unproject(cam, q, N, exact));
        double worst = 0, worst_rad = 0;
        for (int i = 0; i < N; i++) {
            int x = (int)q[2 * i], y = (int)q[2 * i + 1];
            worst = fmax(worst, hypot(q2[2 * i] - x, q2[2 * i + 1] - y));
            worst_rad = fmax(worst_rad, v3_norm(v3_sub(exact[i], rays[(size_t)y * W + x])));
        }
        CHECK_MSG(worst <= bound, "%s: table reprojection error %.4g px > bound %.4g px",
                  model_camera_lensmodel(cam), worst, bound);
        // 0.005 px at f ~ 1000 px is 5e-6 rad (x 1.5 for the edge of the field)
        CHECK_MSG(worst_rad < 8e-6, "%s: table ray %.3g rad from the exact ray",
                  model_camera_lensmodel(cam), worst_rad);
        if (getenv("REFL_TEST_VERBOSE"))
            fprintf(stderr, "  %s: ray table %.1f ms, bound %.5f px, worst sampled %.5f px\n",
                    model_camera_lensmodel(cam), 1e3 * dt, bound, worst);
        model_camera_free(cam);
        free(spl);
    }
}

// Same table whatever the number of threads (mrcal_unproject runs in parallel).
TEST(camera_ray_table_thread_independent)
{
    const char *old = getenv("REFL_THREADS");
    char *saved = old ? strdup(old) : NULL;
    const model_vec3_t *r[2];
    model_camera_t *cam[2];
    double err[2];
    for (int k = 0; k < 2; k++) {
        setenv("REFL_THREADS", k ? "3" : "1", 1);
        cam[k] = model_camera_new("LENSMODEL_OPENCV8", opencv8, 640, 480, rt_test);
        CHECK(cam[k] != NULL);
        r[k] = cam[k] ? model_camera_ray_table(cam[k], &err[k]) : NULL;
        CHECK(r[k] != NULL);
    }
    if (saved) setenv("REFL_THREADS", saved, 1);
    else unsetenv("REFL_THREADS");
    free(saved);
    if (r[0] && r[1]) {
        CHECK(memcmp(r[0], r[1], (size_t)640 * 480 * sizeof(model_vec3_t)) == 0);
        CHECK(err[0] == err[1]);
    }
    model_camera_free(cam[0]);
    model_camera_free(cam[1]);
}

// Lazy initialisation from several threads at once: one table for all.
typedef struct {
    model_camera_t *cam;
    const model_vec3_t *rays;
    double err;
} race_t;

static void *race_fn(void *arg)
{
    race_t *r = arg;
    r->rays = model_camera_ray_table(r->cam, &r->err);
    return NULL;
}

TEST(camera_ray_table_concurrent_first_use)
{
    model_camera_t *cam = model_camera_new("LENSMODEL_OPENCV4", opencv4, 320, 240, rt_test);
    CHECK(cam != NULL);
    if (!cam) return;
    race_t r[4];
    pthread_t th[4];
    for (int i = 0; i < 4; i++) {
        r[i] = (race_t){ cam, NULL, -1 };
        CHECK(pthread_create(&th[i], NULL, race_fn, &r[i]) == 0);
    }
    for (int i = 0; i < 4; i++) pthread_join(th[i], NULL);
    for (int i = 0; i < 4; i++) {
        CHECK(r[i].rays != NULL && r[i].rays == r[0].rays);
        CHECK(r[i].err == r[0].err && r[i].err <= 0.005);
    }
    model_camera_free(cam);
}

// Camera centre: r = rotation by 30 deg about z, t given: C = -R^T t.
TEST(camera_centre_and_axis)
{
    double th = 30 * M_PI / 180;
    double rt[6] = { 0, 0, th, 10, -20, 500 };
    model_camera_t *cam = model_camera_new("LENSMODEL_PINHOLE", pinhole, W, H, rt);
    CHECK(cam != NULL);
    if (!cam) return;
    // R_cam_world = Rz(th); R^T t = (c tx + s ty, -s tx + c ty, tz)
    double c = cos(th), s = sin(th);
    model_vec3_t C = model_camera_centre_world(cam);
    CHECK_NEAR(C.x, -(c * 10 + s * -20), 1e-12);
    CHECK_NEAR(C.y, -(-s * 10 + c * -20), 1e-12);
    CHECK_NEAR(C.z, -500, 1e-12);
    // the optical axis (camera z) is world z here: a point straight ahead lands on (cx, cy)
    model_vec3_t p = v3_add(C, v3(0, 0, 250));
    double q[2];
    CHECK(model_camera_project(cam, &p, 1, q));
    CHECK_NEAR(q[0], pinhole[2], 1e-9);
    CHECK_NEAR(q[1], pinhole[3], 1e-9);
    // camera x axis = world direction Rz(th)^T (1,0,0) = (c, -s, 0): moves right by fx*dx/z
    p = v3_add(C, v3(10 * c, -10 * s, 250));
    CHECK(model_camera_project(cam, &p, 1, q));
    CHECK_NEAR(q[0], pinhole[2] + pinhole[0] * 10 / 250, 1e-9);
    CHECK_NEAR(q[1], pinhole[3], 1e-9);
    // behind the camera: NaN for a pinhole-based model
    p = v3_add(C, v3(1, 2, -250));
    CHECK(model_camera_project(cam, &p, 1, q));
    CHECK(isnan(q[0]) && isnan(q[1]));
    double rt2[6];
    model_camera_rt_cam_world(cam, rt2);
    CHECK(memcmp(rt, rt2, sizeof rt) == 0);
    CHECK(strcmp(model_camera_lensmodel(cam), "LENSMODEL_PINHOLE") == 0);
    CHECK(model_camera_width(cam) == W && model_camera_height(cam) == H);
    CHECK(strlen(model_camera_sha256(cam)) == 64);
    model_camera_free(cam);
}

TEST(camera_save_load_round_trip)
{
    for (int lens = 2; lens < 4; lens++) {
        double *spl = NULL;
        model_camera_t *a = make(lens, &spl);
        CHECK(a != NULL);
        if (!a) continue;
        const char *path = test_path(lens == 2 ? "opencv8.cameramodel" : "splined.cameramodel");
        CHECK(model_camera_save(a, path));
        model_camera_t *b = model_camera_load(path);
        CHECK(b != NULL);
        if (b) {
            CHECK(strcmp(model_camera_lensmodel(a), model_camera_lensmodel(b)) == 0);
            CHECK(model_camera_width(b) == W && model_camera_height(b) == H);
            double ra[6], rb[6];
            model_camera_rt_cam_world(a, ra);
            model_camera_rt_cam_world(b, rb);
            CHECK(memcmp(ra, rb, sizeof ra) == 0);
            // the intrinsics are equal: identical projections
            enum { N = 200 };
            model_vec3_t p[N];
            double qa[2 * N], qb[2 * N];
            uint64_t s = 99;
            model_vec3_t C = model_camera_centre_world(a);
            double q0[2 * N];
            model_vec3_t d[N];
            for (int i = 0; i < N; i++) {
                q0[2 * i] = uniform(&s) * (W - 1);
                q0[2 * i + 1] = uniform(&s) * (H - 1);
            }
            CHECK(model_camera_unproject(a, q0, N, d));
            for (int i = 0; i < N; i++) p[i] = v3_add(C, v3_scale(d[i], 800));
            CHECK(model_camera_project(a, p, N, qa));
            CHECK(model_camera_project(b, p, N, qb));
            CHECK(memcmp(qa, qb, sizeof qa) == 0);
            char sha[65];
            CHECK(model_sha256_file(path, sha));
            CHECK(strcmp(sha, model_camera_sha256(b)) == 0);
            CHECK(strcmp(model_camera_sha256(a), model_camera_sha256(b)) != 0);
        }
        model_camera_free(a);
        model_camera_free(b);
        free(spl);
    }
    // the parameters hash changes with any parameter
    double rt2[6];
    memcpy(rt2, rt_test, sizeof rt2);
    model_camera_t *a = model_camera_new("LENSMODEL_OPENCV4", opencv4, W, H, rt_test);
    rt2[5] += 1e-9;
    model_camera_t *b = model_camera_new("LENSMODEL_OPENCV4", opencv4, W, H, rt2);
    model_camera_t *c = model_camera_new("LENSMODEL_OPENCV4", opencv4, W, H, rt_test);
    CHECK(a && b && c);
    if (a && b && c) {
        CHECK(strcmp(model_camera_sha256(a), model_camera_sha256(b)) != 0);
        CHECK(strcmp(model_camera_sha256(a), model_camera_sha256(c)) == 0);
    }
    model_camera_free(a);
    model_camera_free(b);
    model_camera_free(c);
}

TEST(camera_load_errors)
{
    const char *missing = test_path("missing.cameramodel");
    CHECK(model_camera_load(missing) == NULL);
    CHECK_CONTAINS(model_last_error(), missing);
    CHECK_CONTAINS(model_last_error(), "cannot open");

    const char *garbage = test_write("garbage.cameramodel", "this is not a camera model\n");
    CHECK(model_camera_load(garbage) == NULL);
    CHECK_CONTAINS(model_last_error(), garbage);
    CHECK_CONTAINS(model_last_error(), "not a readable .cameramodel");

    const char *empty = test_write("empty.cameramodel", "");
    CHECK(model_camera_load(empty) == NULL);
    CHECK_CONTAINS(model_last_error(), empty);
    CHECK_CONTAINS(model_last_error(), "empty");

    const char *nokey = test_write("nokey.cameramodel",
        "{ 'lensmodel': 'LENSMODEL_PINHOLE', 'intrinsics': [1000, 1000, 320, 240],\n"
        "  'imagersize': [640, 480] }\n");
    CHECK(model_camera_load(nokey) == NULL);
    CHECK_CONTAINS(model_last_error(), nokey);
    CHECK_CONTAINS(model_last_error(), "'extrinsics' is missing");

    const char *zero = test_write("zero.cameramodel",
        "{ 'lensmodel': 'LENSMODEL_PINHOLE', 'intrinsics': [1000, 1000, 320, 240],\n"
        "  'extrinsics': [0, 0, 0, 0, 0, 0], 'imagersize': [0, 0] }\n");
    CHECK(model_camera_load(zero) == NULL);
    CHECK_CONTAINS(model_last_error(), zero);
    CHECK_CONTAINS(model_last_error(), "width and height must be 1..65535 pixels");

    const char *count = test_write("count.cameramodel",
        "{ 'lensmodel': 'LENSMODEL_OPENCV4', 'intrinsics': [1000, 1000, 320, 240],\n"
        "  'extrinsics': [0, 0, 0, 0, 0, 0], 'imagersize': [640, 480] }\n");
    CHECK(model_camera_load(count) == NULL);
    CHECK_CONTAINS(model_last_error(), count);
    CHECK_CONTAINS(model_last_error(), "4 numbers, lens model LENSMODEL_OPENCV4 has 8 parameters");

    const char *cahvore = test_write("cahvore.cameramodel",
        "{ 'lensmodel': 'LENSMODEL_CAHVORE_linearity=0.50',\n"
        "  'intrinsics': [1000, 1000, 320, 240, 0, 0, 0, 0, 0, 0, 0, 0],\n"
        "  'extrinsics': [0, 0, 0, 0, 0, 0], 'imagersize': [640, 480] }\n");
    CHECK(model_camera_load(cahvore) == NULL);
    CHECK_CONTAINS(model_last_error(), cahvore);
    CHECK_CONTAINS(model_last_error(), "LENSMODEL_CAHVORE");
    CHECK_CONTAINS(model_last_error(), "not supported");

    const char *badf = test_write("badf.cameramodel",
        "{ 'lensmodel': 'LENSMODEL_PINHOLE', 'intrinsics': [-1000, 1000, 320, 240],\n"
        "  'extrinsics': [0, 0, 0, 0, 0, 0], 'imagersize': [640, 480] }\n");
    CHECK(model_camera_load(badf) == NULL);
    CHECK_CONTAINS(model_last_error(), badf);
    CHECK_CONTAINS(model_last_error(), "must be > 0");

    // a valid file with a comment loads
    const char *good = test_write("good.cameramodel",
        "# a comment\n{ 'lensmodel': 'LENSMODEL_PINHOLE', 'intrinsics': [1000, 1000, 320, 240],\n"
        "  'extrinsics': [0, 0, 0, 0, 0, 0], 'imagersize': [640, 480] }\n");
    model_camera_t *cam = model_camera_load(good);
    CHECK(cam != NULL);
    if (cam) CHECK(model_camera_width(cam) == 640 && model_camera_height(cam) == 480);
    model_camera_free(cam);

    CHECK(model_camera_new("LENSMODEL_NONSENSE", pinhole, W, H, rt_test) == NULL);
    CHECK_CONTAINS(model_last_error(), "unknown or unconfigured lens model 'LENSMODEL_NONSENSE'");
    CHECK(model_camera_new("LENSMODEL_PINHOLE", pinhole, 0, H, rt_test) == NULL);
    CHECK_CONTAINS(model_last_error(), "imager size 0x1024");
    cam = model_camera_new("LENSMODEL_PINHOLE", pinhole, W, H, rt_test);
    CHECK(cam != NULL);
    if (cam) {
        CHECK(!model_camera_save(cam, "/nonexistent-dir/x.cameramodel"));
        CHECK_CONTAINS(model_last_error(), "/nonexistent-dir/x.cameramodel: cannot create");
    }
    model_camera_free(cam);
}
