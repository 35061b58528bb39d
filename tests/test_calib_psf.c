// tests/test_calib_psf.c — the lens's blur from the board's edges
// (calib/geometry/psf.h) and the calibration set's reading of it:
// - synthetic chessboards (squares of 40 px turned 4, 19 and 33 deg) blurred
//   by a known Gaussian (0.5, 0.8, 1.2 px), each pixel the mean of 8 x 8
//   samples over its footprint, each at a random place in its cell (on
//   average the whole square, as the estimator's closed form has it; a grid of
//   8 x 8 points would make the footprint 1/768 px^2 narrower), 12 DN of
//   noise on 3000 DN of contrast, rounded to whole DN, corners with 0.05 px of
//   noise: sigma is recovered within 0.005 px and the stated 1-sigma covers
//   the error (|error| <= 3 sigma);
// - geometry.json's psf read back by calib_set_load_files and, per camera,
//   by calib_set_load_camera; without it have_psf is false.
// (The geometry run's stage on the virtual rig: tests/test_calib_geometry.c.)
#define _GNU_SOURCE
#include <glib.h>
#include <jansson.h>
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "calib/calib.h"
#include "calib/geometry/psf.h"
#include "model/model.h"
#include "model/base/report.h"
#include "tests/test.h"

static uint64_t rng = 0x9e3779b97f4a7c15ull;
static double urand(void)
{
    rng ^= rng << 13;
    rng ^= rng >> 7;
    rng ^= rng << 17;
    return (rng >> 11) * (1.0 / 9007199254740992.0);
}
static double nrand(void)
{
    double u = urand(), v = urand();
    return sqrt(-2 * log(u > 1e-300 ? u : 1e-300)) * cos(2 * M_PI * v);
}

// The square wave of period 2 L (+1 on [0, L), -1 on [L, 2 L), ...) blurred
// by a Gaussian of sigma s, at x: the sum over the cells of sign x the
// Gaussian's mass in the cell.
static double square_blurred(double x, double L, double s)
{
    long k0 = (long)floor(x / L), K = (long)ceil(7 * s / L) + 1;
    double sum = 0;
    for (long k = k0 - K; k <= k0 + K; k++) {
        double sign = (k % 2 + 2) % 2 == 0 ? 1 : -1;
        sum += sign * 0.5 * (erfc(-((k + 1) * L - x) / (s * M_SQRT2)) - erfc(-(k * L - x) / (s * M_SQRT2)));
    }
    return sum;
}

typedef struct {
    double x0, h, *v;
    int    n;
} table_t;

static double table_at(const table_t *t, double x)
{
    double f = (x - t->x0) / t->h;
    int i = (int)floor(f);
    if (i < 0) i = 0;
    if (i > t->n - 2) i = t->n - 2;
    f -= i;
    return t->v[i] * (1 - f) + t->v[i + 1] * f;
}

enum { SW = 400, SH = 400, GRIDN = 7, SUB = 8 };
#define SQUARE_PX 40.0

// A chessboard turned psi_deg about (cx, cy), blurred by sigma, each pixel
// its footprint's mean (SUB x SUB samples, jittered in their cells), 300 + 3000 c DN plus noise,
// rounded; its GRIDN x GRIDN inner corners (with 0.05 px of noise) in q.
static float *synthetic_board_as(double sigma, double psi_deg, double cx, double cy, double *q, bool point)
{
    table_t t = { .x0 = -400, .h = 1.0 / 32 };
    t.n = (int)(800 / t.h) + 2;
    t.v = malloc((size_t)t.n * sizeof *t.v);
    for (int i = 0; i < t.n; i++) t.v[i] = square_blurred(t.x0 + i * t.h, SQUARE_PX, sigma);
    float *img = malloc((size_t)SW * SH * sizeof *img);
    double c = cos(psi_deg * M_PI / 180), s = sin(psi_deg * M_PI / 180);
    for (int y = 0; y < SH; y++)
        for (int x = 0; x < SW; x++) {
            double sum = 0;
            const int ns = point ? 1 : SUB;   // a point: the pixel's centre alone
            for (int j = 0; j < ns; j++)
                for (int i = 0; i < ns; i++) {
                    double dx = point ? x - cx : x - 0.5 + (i + urand()) / SUB - cx;
                    double dy = point ? y - cy : y - 0.5 + (j + urand()) / SUB - cy;
                    double u = dx * c + dy * s, v = -dx * s + dy * c;
                    sum += 0.5 + 0.5 * table_at(&t, u) * table_at(&t, v);
                }
            img[(size_t)y * SW + x] = (float)rint(300 + 3000 * sum / (ns * ns) + 12 * nrand());
        }
    for (int j = 0; j < GRIDN; j++)
        for (int i = 0; i < GRIDN; i++) {
            double u = (i - GRIDN / 2) * SQUARE_PX, v = (j - GRIDN / 2) * SQUARE_PX;
            q[2 * (j * GRIDN + i)] = cx + u * c - v * s + 0.05 * nrand();
            q[2 * (j * GRIDN + i) + 1] = cy + u * s + v * c + 0.05 * nrand();
        }
    free(t.v);
    return img;
}

static float *synthetic_board(double sigma, double psi_deg, double cx, double cy, double *q)
{
    return synthetic_board_as(sigma, psi_deg, cx, cy, q, false);
}

TEST(calib_psf_synthetic_edges)
{
    const double sigmas[] = { 0.5, 0.8, 1.2 }, psis[] = { 4, 19, 33 };
    for (int k = 0; k < 3; k++) {
        calib_psf_acc_t *a = calib_psf_acc_new(GRIDN, GRIDN);
        double q[2 * GRIDN * GRIDN];
        for (int v = 0; v < 3; v++) {
            float *img = synthetic_board(sigmas[k], psis[v], 200.3 + 3 * v, 199.6 - 2 * v, q);
            CHECK(calib_psf_add_view(a, img, SW, SH, q, 0, v, 0) == 2 * GRIDN * (GRIDN - 1));
            free(img);
        }
        calib_psf_t p;
        calib_psf_estimate(a, 0, &p);
        double err = p.sigma_px - sigmas[k];
        printf("  sigma %.2f px: estimated %.4f +- %.4f px (error %+.4f, z %+.2f; edges %.4f, views %.4f), %d of %d "
               "edges, spread %.4f px, residual %.2f %% of the contrast\n", sigmas[k], p.sigma_px, p.sigma_std_px,
               err, err / p.sigma_std_px, p.sigma_std_edges_px, p.sigma_std_views_px, p.edges_used, p.edges_tried,
               p.spread_px, 100 * p.rms_rel);
        CHECK_MSG(p.estimated, "%s", p.why);
        CHECK(p.edges_used >= 200);
        CHECK(fabs(err) < 0.005);
        CHECK(fabs(err) <= 3 * p.sigma_std_px);
        CHECK(p.sigma_std_px > 0 && p.sigma_std_px < 0.02);
        json_t *j = calib_psf_json(&p);
        CHECK(!strcmp(json_string_value(json_object_get(j, "model")), "gaussian"));
        CHECK(p.pixel_fill == 1 && json_number_value(json_object_get(j, "pixel_fill")) == 1);
        CHECK_NEAR(json_number_value(json_object_get(j, "sigma_px")), p.sigma_px, 1e-12);
        CHECK(json_integer_value(json_object_get(j, "edges_used")) == p.edges_used);
        json_decref(j);
        calib_psf_acc_free(a);
    }
    // too few edges: not estimated, and said why
    calib_psf_acc_t *a = calib_psf_acc_new(GRIDN, GRIDN);
    calib_psf_t p;
    calib_psf_estimate(a, 0, &p);
    CHECK(!p.estimated);
    CHECK_CONTAINS(p.why, "usable edges");
    json_t *j = calib_psf_json(&p);
    CHECK(json_is_null(json_object_get(j, "model")));
    json_decref(j);
    calib_psf_acc_free(a);
}

// The calibration set reads the blur from the geometry.json beside its camera
// model: the top level's, or camera NAME's of several.
TEST(calib_psf_calibration_set)
{
    char cam[4096];
    snprintf(cam, sizeof cam, "%s/examples/camera.cameramodel", test_srcdir());
    gchar *text = NULL;
    gsize len = 0;
    CHECK(g_file_get_contents(cam, &text, &len, NULL));
    g_mkdir_with_parents(test_path("cal/geometry"), 0755);
    CHECK(g_file_set_contents(test_path("cal/geometry/camera.cameramodel"), text, (gssize)len, NULL));
    CHECK(g_file_set_contents(test_path("cal/geometry/right.cameramodel"), text, (gssize)len, NULL));
    g_free(text);
    test_write("cal/lamps.json", "{\"lamps\": [{\"name\": \"east\", \"position_mm\": [500, 0, 400]}]}");
    // no geometry.json: no blur, no error
    calib_set_t *c = calib_set_load(test_path("cal"), false);
    CHECK(c && !c->have_psf && c->psf_sigma_px == 0);
    calib_set_free(c);
    // one without an estimate
    test_write("cal/geometry/geometry.json", "{\"psf\": {\"model\": null, \"why\": \"no images\"}}");
    c = calib_set_load(test_path("cal"), false);
    CHECK(c && !c->have_psf);
    calib_set_free(c);
    // the top level's, and camera right's own
    test_write("cal/geometry/geometry.json",
               "{\"psf\": {\"model\": \"gaussian\", \"sigma_px\": 0.81, \"sigma_std_px\": 0.012},\n"
               " \"cameras\": [{\"name\": \"left\", \"psf\": {\"model\": \"gaussian\", \"sigma_px\": 0.81, "
               "\"sigma_std_px\": 0.012}},\n"
               "             {\"name\": \"right\", \"psf\": {\"model\": \"gaussian\", \"sigma_px\": 1.1, "
               "\"sigma_std_px\": 0.02}}]}");
    c = calib_set_load(test_path("cal"), false);
    CHECK(c && c->have_psf);
    if (c) {
        CHECK_NEAR(c->psf_sigma_px, 0.81, 1e-12);
        CHECK_NEAR(c->psf_sigma_std_px, 0.012, 1e-12);
        bool listed = false;
        size_t i;
        json_t *e;
        json_array_foreach(c->inputs, i, e) listed |= !strcmp(json_string_value(json_object_get(e, "role")),
                                                              "geometry");
        CHECK(listed);
    }
    calib_set_free(c);
    c = calib_set_load_camera(test_path("cal"), "right", false);
    CHECK_MSG(c != NULL, "%s", model_last_error());
    if (c) {
        CHECK(c->have_psf);
        CHECK_NEAR(c->psf_sigma_px, 1.1, 1e-12);
        CHECK_NEAR(c->psf_sigma_std_px, 0.02, 1e-12);
    }
    calib_set_free(c);
    double s, sd;
    char *gj = NULL;
    CHECK(calib_psf_read(test_path("cal/geometry/right.cameramodel"), NULL, &s, &sd, NULL, &gj));   // by the file's name
    CHECK_NEAR(s, 1.1, 1e-12);
    CHECK(gj && g_str_has_suffix(gj, "cal/geometry/geometry.json"));
    g_free(gj);
    CHECK(!calib_psf_read(test_path("nowhere/camera.cameramodel"), NULL, &s, &sd, NULL, NULL) && isnan(s));
}

// geometry.json names its format and version; the reader takes version 1 (and
// a file without the keys), and refuses a newer version or another format
// with a message naming the file (the calibration set goes on without the blur).
TEST(calib_psf_geometry_json_version)
{
    char cam[4096];
    snprintf(cam, sizeof cam, "%s/examples/camera.cameramodel", test_srcdir());
    gchar *text = NULL;
    gsize len = 0;
    CHECK(g_file_get_contents(cam, &text, &len, NULL));
    g_mkdir_with_parents(test_path("v/geometry"), 0755);
    CHECK(g_file_set_contents(test_path("v/geometry/camera.cameramodel"), text, (gssize)len, NULL));
    g_free(text);
    const char *model = test_path("v/geometry/camera.cameramodel");
    const char *psf = "\"psf\": {\"model\": \"gaussian\", \"sigma_px\": 0.7, \"sigma_std_px\": 0.01}}";
    double s, sd;
    char *doc = g_strdup_printf("{\"format\": \"refl-geometry\", \"version\": 1, %s", psf);
    test_write("v/geometry/geometry.json", doc);
    g_free(doc);
    CHECK(calib_psf_read(model, NULL, &s, &sd, NULL, NULL));
    CHECK_NEAR(s, 0.7, 1e-12);
    doc = g_strdup_printf("{\"format\": \"refl-geometry\", \"version\": 2, %s", psf);
    test_write("v/geometry/geometry.json", doc);
    g_free(doc);
    CHECK(!calib_psf_read(model, NULL, &s, &sd, NULL, NULL) && isnan(s));
    CHECK_CONTAINS(model_last_error(), "geometry.json");
    CHECK_CONTAINS(model_last_error(), "refl-geometry version 2, written by a newer refl");
    doc = g_strdup_printf("{\"format\": \"refl-gain\", \"version\": 1, %s", psf);
    test_write("v/geometry/geometry.json", doc);
    g_free(doc);
    CHECK(!calib_psf_read(model, NULL, &s, &sd, NULL, NULL));
    CHECK_CONTAINS(model_last_error(), "a refl-gain file, not refl-geometry");
    // the check itself
    json_t *root = json_object();
    int v = 0;
    CHECK(calib_geometry_json_check(root, "g.json", &v) && v == 1);   // without the keys: version 1
    model_json_set_format(root, CALIB_GEOMETRY_JSON_FORMAT, CALIB_GEOMETRY_JSON_VERSION);
    CHECK(calib_geometry_json_check(root, "g.json", &v) && v == CALIB_GEOMETRY_JSON_VERSION);
    json_object_set_new(root, "version", json_integer(CALIB_GEOMETRY_JSON_VERSION + 1));
    CHECK(!calib_geometry_json_check(root, "g.json", &v));
    json_decref(root);
}

// Pixels that sample a point at their centre (a renderer's one ray a pixel):
// a sharp board's edges are sharper than a square footprint allows, the
// estimate says so (pixel_fill 0) and its sigma is 0 (within 0.015 px); a
// blurred one (0.6 px) is as well fitted by either footprint (the square
// with sigma sqrt(0.6^2 - 1/12)): the pixel's response, sigma^2 + fill^2/12,
// is 0.6^2 within 3 %.
TEST(calib_psf_point_footprint)
{
    const double sigmas[] = { 0, 0.6 };
    for (int k = 0; k < 2; k++) {
        calib_psf_acc_t *a = calib_psf_acc_new(GRIDN, GRIDN);
        double q[2 * GRIDN * GRIDN];
        for (int v = 0; v < 3; v++) {
            float *img = synthetic_board_as(sigmas[k], 7 + 11 * v, 200.3 + 3 * v, 199.6 - 2 * v, q, true);
            calib_psf_add_view(a, img, SW, SH, q, 0, v, 0);
            free(img);
        }
        calib_psf_t p;
        calib_psf_estimate(a, 0, &p);
        printf("  point footprint, sigma %.1f: fill %.0f (point/square sums of squares %.3f), sigma %.4f +- %.4f from %d "
               "edges\n", sigmas[k], p.pixel_fill, p.rss_point_over_square, p.sigma_px, p.sigma_std_px, p.edges_used);
        CHECK_MSG(p.estimated, "%s", p.why);
        if (sigmas[k] == 0) {
            CHECK(p.pixel_fill == 0);
            CHECK_MSG(fabs(p.sigma_px) < 0.015, "sigma %.4f for a sharp board", p.sigma_px);
        } else {
            double m2 = p.sigma_px * p.sigma_px + p.pixel_fill * p.pixel_fill / 12;
            CHECK_MSG(fabs(m2 / (sigmas[k] * sigmas[k]) - 1) < 0.03, "fill %g sigma %.4f: second moment %.4f for %.4f",
                      p.pixel_fill, p.sigma_px, m2, sigmas[k] * sigmas[k]);
        }
        calib_psf_acc_free(a);
    }
}
