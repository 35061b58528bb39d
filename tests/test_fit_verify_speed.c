// tests/test_fit_verify_speed.c — the verification fit's fast paths give the
// same numbers as the plain ones: the prepared BRDF geometry
// (model_brdf_prepare / model_brdf_eval_prepared) against model_brdf_eval
// (bit for bit but Blinn's power at a non-whole ns, within 1e-12), the
// selection median against a full sort (bit for bit), and the fit itself
// (normal equations, prepared terms) against the reference fit (QR, plain
// evaluation): the same verdicts and points, scores within 1e-9.
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fit/verify/verify.h"
#include "fit/eval/lab.h"
#include "model/model.h"
#include "tests/test.h"

static uint64_t rs = 0x9e3779b97f4a7c15ull;
static double urand(void)
{
    rs ^= rs << 13;
    rs ^= rs >> 7;
    rs ^= rs << 17;
    return (double)(rs >> 11) / 9007199254740992.0;
}

static bool same_bits(double a, double b) { return memcmp(&a, &b, sizeof a) == 0; }

// The models with Blinn's (n.h)^ns (exp of the stored log in the prepared path).
static bool blinn_based(int m)
{
    return m == MODEL_BRDF_THESIS_FIT || m == MODEL_BRDF_HALL || m == MODEL_BRDF_TORRANCE_SPARROW;
}

// Equal bits, or within a relative tol (values below 1e-290 count as equal:
// exp and pow part in the subnormals).
static bool close_rel(double a, double b, double tol)
{
    if (same_bits(a, b) || (fabs(a) < 1e-290 && fabs(b) < 1e-290)) return true;
    return fabs(a - b) <= tol * fmax(fabs(a), fabs(b));
}

// Random cosines, including the degenerate ones (n.l, n.v or n.h <= 0, v.h
// near 0 or negative) and exact zeros.
static model_cosines_t random_cosines(int i)
{
    model_cosines_t c = { 2 * urand() - 0.3, 2 * urand() - 0.3, 2 * urand() - 0.2, 2 * urand() - 0.2 };
    if (c.nl > 1) c.nl = 1;
    if (c.nv > 1) c.nv = 1;
    if (c.nh > 1) c.nh = 1;
    if (c.vh > 1) c.vh = 1;
    if (i % 17 == 0) c.nh = 0;
    if (i % 19 == 0) c.vh = 0;
    if (i % 23 == 0) c.nh = 1;
    return c;
}

TEST(brdf_prepared_equals_eval)
{
    long compared = 0, mismatches = 0;
    for (int m = 0; m < MODEL_BRDF_COUNT; m++) {
        int np = model_brdf_nparams((model_brdf_t)m);
        for (int i = 0; i < 20000; i++) {
            model_cosines_t c = random_cosines(i);
            model_brdf_prep_t pc = model_brdf_prepare(&c);
            double p[MODEL_BRDF_MAX_PARAMS];
            for (int j = 0; j < np; j++) p[j] = 0.01 + urand();
            int ins = model_brdf_param_index((model_brdf_t)m, "ns");
            if (ins >= 0) p[ins] = i % 3 == 0 ? (double)(int)(300 * urand()) : 500 * urand();   // whole and not
            double d0[MODEL_BRDF_MAX_PARAMS], d1[MODEL_BRDF_MAX_PARAMS];
            double r0 = model_brdf_eval((model_brdf_t)m, p, &c, d0);
            double r1 = model_brdf_eval_prepared((model_brdf_t)m, p, &pc, d1);
            double q0 = model_brdf_eval((model_brdf_t)m, p, &c, NULL);
            double q1 = model_brdf_eval_prepared((model_brdf_t)m, p, &pc, NULL);
            // a whole ns up to 256: bit for bit; else within 1e-12 (exp(ns log n.h) for pow)
            double tol = blinn_based(m) && !(ins >= 0 && p[ins] <= 256 && p[ins] == (double)(int)p[ins]) ? 1e-12 : 0;
            bool ok = close_rel(r0, r1, tol) && close_rel(q0, q1, tol) && same_bits(r1, q1);
            for (int j = 0; j < np; j++) ok = ok && close_rel(d0[j], d1[j], tol);
            compared++;
            if (!ok && mismatches++ < 5)
                CHECK_MSG(false, "%s: cosines %.17g %.17g %.17g %.17g: R %.17g vs %.17g", model_brdf_name(m), c.nl,
                          c.nv, c.nh, c.vh, r0, r1);
        }
    }
    CHECK(compared == 20000L * MODEL_BRDF_COUNT);
    CHECK_MSG(mismatches == 0, "%ld of %ld evaluations differ", mismatches, compared);
}

// A prepared geometry keeps its last distribution/shadowing factors: a solver's
// sequence of parameters (repeats, with and without derivatives, the shape
// parameter changing or not) gives model_brdf_eval's values at every step.
TEST(brdf_prepared_kept_factors_follow_the_parameters)
{
    long compared = 0, mismatches = 0;
    for (int m = 0; m < MODEL_BRDF_COUNT; m++) {
        int np = model_brdf_nparams((model_brdf_t)m);
        for (int i = 0; i < 2000; i++) {
            model_cosines_t c = random_cosines(i);
            model_brdf_prep_t pc = model_brdf_prepare(&c);
            double p[MODEL_BRDF_MAX_PARAMS];
            for (int j = 0; j < np; j++) p[j] = 0.01 + urand();
            for (int step = 0; step < 12; step++) {
                int r = (int)(urand() * 4);
                if (r == 1) p[(int)(urand() * np)] = 0.01 + urand();   // any parameter moves (or the shape one)
                if (r == 2) p[(int)(urand() * np)] *= 1 + 1e-9;          // a tiny step, as in a difference
                bool want = urand() < 0.5;
                double d0[MODEL_BRDF_MAX_PARAMS], d1[MODEL_BRDF_MAX_PARAMS];
                double r0 = model_brdf_eval((model_brdf_t)m, p, &c, want ? d0 : NULL);
                double r1 = model_brdf_eval_prepared((model_brdf_t)m, p, &pc, want ? d1 : NULL);
                double tol = blinn_based(m) ? 1e-12 : 0;
                bool ok = close_rel(r0, r1, tol);
                for (int j = 0; want && j < np; j++) ok = ok && close_rel(d0[j], d1[j], tol);
                compared++;
                if (!ok && mismatches++ < 5)
                    CHECK_MSG(false, "%s step %d: R %.17g vs %.17g", model_brdf_name(m), step, r0, r1);
            }
        }
    }
    CHECK_MSG(mismatches == 0, "%ld of %ld evaluations differ", mismatches, compared);
}

static int cmp_sorted(const void *a, const void *b) { return model_cmp_double(a, b); }

TEST(model_median_equals_sorted_middle)
{
    for (int t = 0; t < 3000; t++) {
        int n = 1 + (int)(urand() * (t % 10 == 0 ? 2000 : 40));
        double *v = malloc((size_t)n * sizeof *v), *s = malloc((size_t)n * sizeof *s);
        CHECK(v && s);
        if (!v || !s) return;
        int kind = t % 4;
        for (int i = 0; i < n; i++) {
            double x = urand() * 2 - 1;
            if (kind == 1) x = (double)(int)(x * 4);   // many ties
            if (kind == 2) x = i;                      // sorted already
            if (kind == 3) x = n - i + 0.5 * (i % 3);  // mostly descending
            v[i] = s[i] = x;
        }
        if (t % 50 == 7) v[n / 2] = s[n / 2] = NAN;   // NaN sorts last, as model_cmp_double has it
        qsort(s, (size_t)n, sizeof *s, cmp_sorted);
        double want = n % 2 ? s[n / 2] : 0.5 * (s[n / 2 - 1] + s[n / 2]);
        double got = model_median(v, n);
        CHECK_MSG(same_bits(want, got) || (isnan(want) && isnan(got)), "n %d kind %d: %.17g, sorted %.17g", n, kind,
                  got, want);
        free(v);
        free(s);
    }
    CHECK(isnan(model_median(NULL, 0)));
}

// verify_run with the normal equations, the prepared terms and kept robust
// images against the reference fit (verify_options_t.reference_eval: QR,
// model_brdf_eval) on a virtual-rig view of the T-stiffener, with a correct
// and a wrong description, every configuration the study uses: the same
// verdict, points and iterations; score, parameters and predictions within
// rounding (relative 1e-9; the parameters 1e-6: the unbounded fit's kc and
// albedo share a flat direction). And the window sums kept across the fits
// (verify_windows_t, as the study keeps them): bit for bit.
TEST(verify_run_prepared_equals_reference)
{
    char truth[4096];
    snprintf(truth, sizeof truth, "%s/examples/virtual-truth.ini", test_srcdir());
    const double angle = 30;
    eval_lab_t *L = eval_lab_open(truth, "t_stiffener", &angle, 1, 6000, 0, false);
    CHECK_MSG(L != NULL, "%s", model_last_error());
    if (!L) return;
    int W = eval_lab_width(L), H = eval_lab_height(L);
    float *img = malloc((size_t)W * H * sizeof(float));
    CHECK(img && eval_lab_image(L, 0, 0xf, NULL, 1, 7, img));
    verify_image_t im = { .P = img, .W = W, .H = H, .camera = 0, .angle_deg = angle, .lamps_on = 0xf,
                          .exposure_us = 6000 };
    snprintf(im.name, sizeof im.name, "speed");
    verify_priors_t pr = { 0 };
    const model_materials_t *mm = eval_lab_materials(L);
    const model_material_t *ply = model_materials_find(mm, "plywood"), *st = model_materials_find(mm, "painted_steel");
    CHECK(ply && st && verify_priors_add(&pr, ply, 0.1, 1e-4, 3) && verify_priors_add(&pr, st, 0.1, 1e-4, 3));
    const model_material_t *mats[2] = { ply, st };
    verify_windows_t *win = verify_windows_new();
    CHECK(win != NULL);
    int compared = 0;
    for (int wrong = 0; wrong < 2; wrong++) {
        model_stiffener_t d = model_stiffener_default();
        if (wrong) d.height_scale = 1.04;
        model_scene_t *sc = model_stiffener_scene(&d, "t_stiffener");
        verify_options_t opt = verify_defaults();
        opt.threads = 1;
        verify_view_t *v = sc ? verify_view_new(sc, eval_lab_camera(L), angle, eval_lab_lamps(L), mats, &opt) : NULL;
        CHECK_MSG(v != NULL, "%s", model_last_error());
        for (int k = 0; v && k < 4; k++) {
            opt.use_priors = k < 2;
            opt.use_flat = k % 2 == 0;
            opt.no_covariance = k != 0;
            verify_result_t r[3];
            bool ok[3];
            for (int ref = 0; ref < 3; ref++) {
                // 0: as it is; 1: the reference fit; 2: as it is, the window sums kept across every
                // configuration and description (bit for bit as 0)
                opt.reference_eval = ref == 1;
                im.windows = ref == 2 ? win : NULL;
                ok[ref] = verify_run(sc, &pr, eval_lab_camera(L), 1, eval_lab_lamps(L), eval_lab_A(L), &im, 1, &v,
                                     &opt, &r[ref]);
            }
            CHECK_MSG(ok[0] && ok[1] && ok[2], "%s", model_last_error());
            if (ok[0] && ok[2]) {
                int differ = r[0].npoints != r[2].npoints || !same_bits(r[0].score, r[2].score);
                for (int j = 0; !differ && j < r[0].npoints; j++)
                    differ += memcmp(&r[0].points[j], &r[2].points[j], sizeof r[0].points[j]) != 0;
                CHECK_MSG(differ == 0, "config %d: kept window sums: score %.17g vs %.17g, or points differ", k,
                          r[2].score, r[0].score);
            }
            if (ok[0] && ok[1]) {
                compared++;
                CHECK_MSG(close_rel(r[0].score, r[1].score, 1e-9), "config %d: score %.17g vs reference %.17g", k,
                          r[0].score, r[1].score);
                CHECK(r[0].correct == r[1].correct && r[0].nparams == r[1].nparams && r[0].npoints == r[1].npoints);
                CHECK_MSG(r[0].summary.iterations == r[1].summary.iterations, "config %d: %d iterations vs %d", k,
                          r[0].summary.iterations, r[1].summary.iterations);
                for (int j = 0; j < r[0].nparams && j < r[1].nparams; j++)
                    CHECK_MSG(close_rel(r[0].params[j].value, r[1].params[j].value, 1e-6) &&
                                  (close_rel(r[0].params[j].std, r[1].params[j].std, 1e-6) ||
                                   (isnan(r[0].params[j].std) && isnan(r[1].params[j].std))),
                              "config %d: %s %.17g vs reference %.17g", k, r[0].params[j].name, r[0].params[j].value,
                              r[1].params[j].value);
                int differ = 0;
                for (int j = 0; j < r[0].npoints && j < r[1].npoints; j++) {
                    const verify_point_t *a = &r[0].points[j], *b = &r[1].points[j];
                    differ += a->status != b->status || a->image != b->image || a->meas != b->meas ||
                              !close_rel(a->model, b->model, 1e-6) || fabs(a->z - b->z) > 1e-4 * (1 + fabs(a->z));
                }
                CHECK_MSG(differ == 0, "config %d: %d points differ", k, differ);
            }
            for (int ref = 0; ref < 3; ref++)
                if (ok[ref]) verify_result_free(&r[ref]);
        }
        verify_view_free(v);
        model_scene_free(sc);
    }
    CHECK(compared == 8);
    verify_windows_free(win);
    verify_priors_free(&pr);
    free(img);
    eval_lab_free(L);
}
