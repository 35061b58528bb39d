// tests/test_fit_brdf.c — fitting the reflection models to BRDF samples with
// known answers: samples drawn from each model with known parameters (with
// and without noise) are fitted back; the Jacobians the fit uses are checked
// by central differences; CSV and MERL files round-trip; the priors file has
// the contract's fields; bad files give errors naming file and line.
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <glib.h>
#include <jansson.h>

#include "fit/fit.h"
#include "model/internal.h"
#include "tests/test.h"

// Samples of model m with parameters p on a grid of directions (incidence and
// view every step deg, view azimuth every 2 step), those with v.h >= vh_min,
// with Gaussian noise of std sigma on R (seeded).
static fit_samples_t *synth_grid(model_brdf_t m, const double *p, double sigma, uint64_t seed, int step, double vh_min)
{
    fit_samples_t *s = fit_samples_new();
    model_rng_t rng = model_rng(seed, 3);
    const double d = M_PI / 180;
    for (int ti = 0; ti < 85; ti += step)
        for (int to = 0; to < 85; to += step)
            for (int po = 0; po < 360; po += 2 * step) {
                model_cosines_t c = model_cosines(v3(0, 0, 1), v3(sin(ti * d), 0, cos(ti * d)),
                                                  v3(sin(to * d) * cos(po * d), sin(to * d) * sin(po * d), cos(to * d)));
                if (!(c.nl > 0 && c.nv > 0) || c.vh < vh_min) continue;
                double R = model_brdf_eval(m, p, &c, NULL) + (sigma > 0 ? sigma * model_rng_gauss(&rng) : 0);
                fit_samples_add(s, &c, R, 1);
            }
    return s;
}

static fit_samples_t *synth(model_brdf_t m, const double *p, double sigma, uint64_t seed)
{
    return synth_grid(m, p, sigma, seed, 5, -1);
}

static void check_recovery(model_brdf_t m, const double *truth, double sigma)
{
    fit_samples_t *s = synth(m, truth, sigma, 11);
    fit_brdf_result_t r;
    bool ok = fit_brdf(s, m, NULL, &r);
    CHECK_MSG(ok, "%s: %s", model_brdf_name(m), model_last_error());
    if (!ok) {
        fit_samples_free(s);
        return;
    }
    int np = model_brdf_nparams(m);
    for (int j = 0; j < np; j++) {
        if (sigma == 0) {
            CHECK_MSG(fabs(r.p[j] - truth[j]) <= 1e-4 * fmax(1, fabs(truth[j])), "%s %s: %.8g vs truth %.8g",
                      model_brdf_name(m), model_brdf_param_name(m, j), r.p[j], truth[j]);
        } else if (!r.fixed[j]) {
            // within 3 sigma of the truth, and sigma honest (not huge)
            CHECK_MSG(r.cov_ok && fabs(r.p[j] - truth[j]) <= 3 * r.std[j] + 1e-9, "%s %s: %.6g +- %.3g vs truth %.6g",
                      model_brdf_name(m), model_brdf_param_name(m, j), r.p[j], r.std[j], truth[j]);
            CHECK_MSG(r.std[j] < 0.2 * fmax(fabs(truth[j]), 0.01), "%s %s: std %.3g", model_brdf_name(m),
                      model_brdf_param_name(m, j), r.std[j]);
        }
    }
    if (sigma > 0) CHECK_REL(r.rms, sigma, 0.1);   // residual RMS at the noise level
    else CHECK(r.rms < 1e-6);
    CHECK(r.n == s->n);
    fit_samples_free(s);
}

TEST(fit_brdf_recovers_each_model_exact)
{
    double lam[] = { 0.2 };
    double hall[] = { 0.12, 0.05, 40 };
    double ts[] = { 0.1, 0.3, 60, 0.3 };
    double th[] = { 0.08, 30, 0.05 };
    double ct[] = { 0.4, 0.5, 0.2, 0.6 };
    double ggx[] = { 0.35, 0.6, 0.1, 0.3 };
    check_recovery(MODEL_BRDF_LAMBERT, lam, 0);
    check_recovery(MODEL_BRDF_HALL, hall, 0);
    check_recovery(MODEL_BRDF_TORRANCE_SPARROW, ts, 0);
    check_recovery(MODEL_BRDF_THESIS_FIT, th, 0);
    check_recovery(MODEL_BRDF_COOK_TORRANCE, ct, 0);
    check_recovery(MODEL_BRDF_GGX, ggx, 0);
    double as[] = { 0.5, 0.08, 60 };
    double ggx2[] = { 0.3, 0.2, 0.06, 0.3, 0.35, 0.5 };
    check_recovery(MODEL_BRDF_ASHIKHMIN_SHIRLEY, as, 0);
    check_recovery(MODEL_BRDF_GGX2, ggx2, 0);
}

// A CSV of samples of model m with parameters p (f_r, degrees), one line per
// direction of the 5-degree grid, with white noise sigma on R and, with corr
// > 0, each block of 200 lines scaled by its own 1 + corr N(0,1) (errors a
// block of samples shares, as a frame's lamp or exposure error).
static const char *write_model_csv_corr(const char *name, model_brdf_t m, const double *p, double sigma,
                                        uint64_t seed, double corr)
{
    fit_samples_t *s = synth(m, p, sigma, seed);
    model_rng_t rng = model_rng(seed, 9);
    double fac = 1;
    for (int i = 0; i < s->n; i++) {
        if (i % 200 == 0) fac = 1 + corr * model_rng_gauss(&rng);
        s->R[i] = fmax(0, s->R[i] * fac);   // a file's f_r is >= 0
    }
    GString *g = g_string_new("theta_i,phi_i,theta_o,phi_o,f_r\n");
    const double d = 180 / M_PI;
    for (int i = 0; i < s->n; i++) {
        // the grid's directions back from the cosines: l in the xz plane, v by its azimuth about n
        const model_cosines_t *c = &s->c[i];
        double ti = acos(fmin(1, c->nl)), to = acos(fmin(1, c->nv));
        double lv = 2 * c->vh * c->vh - 1, sl = sin(ti), sv = sin(to);
        double cp = sl * sv > 1e-12 ? fmax(-1, fmin(1, (lv - c->nl * c->nv) / (sl * sv))) : 1;
        g_string_append_printf(g, "%.12g,0,%.12g,%.12g,%.15g\n", ti * d, to * d, acos(cp) * d, s->R[i] / c->nl);
    }
    fit_samples_free(s);
    const char *path = test_write(name, g->str);
    g_string_free(g, TRUE);
    return path;
}

static const char *write_model_csv(const char *name, model_brdf_t m, const double *p, double sigma, uint64_t seed)
{
    return write_model_csv_corr(name, m, p, sigma, seed, 0);
}

// refl fit brdf recovers the parameters of the new classes from noise-free
// samples of each, through its priors file.
TEST(fit_brdf_command_recovers_new_models)
{
    const struct {
        model_brdf_t m;
        double       p[6];
    } k[] = { { MODEL_BRDF_ASHIKHMIN_SHIRLEY, { 0.45, 0.1, 35 } }, { MODEL_BRDF_GGX2, { 0.25, 0.25, 0.08, 0.4, 0.4, 0.6 } } };
    for (size_t i = 0; i < 2; i++) {
        const char *name = model_brdf_name(k[i].m);
        char fn[64];
        snprintf(fn, sizeof fn, "%s.csv", name);
        const char *csv = write_model_csv(fn, k[i].m, k[i].p, 0, 1);
        snprintf(fn, sizeof fn, "%s.json", name);
        const char *priors = test_path(fn);
        char *out = NULL, *err = NULL;
        int rc = test_refl_run(120, &out, &err, "fit", "brdf", csv, "--model", name, "-o", priors, NULL);
        CHECK_MSG(rc == 0, "%s", err);
        g_free(out);
        g_free(err);
        json_t *top = json_load_file(priors, 0, NULL);
        json_t *mat = json_array_get(json_object_get(top, "materials"), 0);
        CHECK(mat && !strcmp(json_string_value(json_object_get(mat, "model")), name));
        json_t *ps = json_object_get(mat, "parameters");
        CHECK((int)json_array_size(ps) == model_brdf_nparams(k[i].m));
        for (size_t j = 0; j < json_array_size(ps); j++) {
            json_t *e = json_array_get(ps, j);
            double mean = json_number_value(json_object_get(e, "mean"));
            CHECK_MSG(fabs(mean - k[i].p[j]) <= 1e-4 * fmax(1, k[i].p[j]), "%s %s: %.8g vs truth %.8g", name,
                      json_string_value(json_object_get(e, "name")), mean, k[i].p[j]);
        }
        json_decref(top);
    }
}

TEST(fit_brdf_noisy_within_uncertainty)
{
    double hall[] = { 0.12, 0.05, 40 };
    double ggx[] = { 0.35, 0.6, 0.1, 0.3 };
    check_recovery(MODEL_BRDF_HALL, hall, 0.002);
    check_recovery(MODEL_BRDF_GGX, ggx, 0.002);
}

// The residual Jacobians the fit uses are the models' analytic derivatives:
// check them through the same callback interface at random parameters.
typedef struct {
    model_brdf_t    m;
    model_cosines_t c[16];
} jac_t;

static bool jac_res(void *ctx, const double *const *p, double *r, double **J)
{
    const jac_t *j = ctx;
    int np = model_brdf_nparams(j->m);
    double d[MODEL_BRDF_MAX_PARAMS];
    for (int k = 0; k < 16; k++) {
        r[k] = model_brdf_eval(j->m, p[0], &j->c[k], J && J[0] ? d : NULL);
        if (J && J[0])
            for (int i = 0; i < np; i++) J[0][k * np + i] = d[i];
    }
    return true;
}

TEST(fit_brdf_jacobians_match_central_differences)
{
    model_rng_t rng = model_rng(5, 1);
    for (int m = 0; m < MODEL_BRDF_COUNT; m++) {
        jac_t J = { .m = (model_brdf_t)m };
        for (int k = 0; k < 16; k++) {
            double ti = 0.1 + 1.2 * model_rng_uniform(&rng), to = 0.1 + 1.2 * model_rng_uniform(&rng);
            double po = 2 * M_PI * model_rng_uniform(&rng);
            J.c[k] = model_cosines(v3(0, 0, 1), v3(sin(ti), 0, cos(ti)),
                                   v3(sin(to) * cos(po), sin(to) * sin(po), cos(to)));
        }
        double p[MODEL_BRDF_MAX_PARAMS];
        int np = model_brdf_nparams((model_brdf_t)m);
        for (int i = 0; i < np; i++) {
            double lo, hi;
            model_brdf_param_range((model_brdf_t)m, i, &lo, &hi);
            if (!isfinite(hi)) hi = lo + 2;
            if (!strcmp(model_brdf_param_name((model_brdf_t)m, i), "ns")) hi = 50;
            p[i] = lo + (0.2 + 0.6 * model_rng_uniform(&rng)) * (hi - lo);
        }
        double *b[] = { p };
        int sizes[] = { np };
        double err;
        bool ok = lsq_check_jacobian(jac_res, &J, 16, 1, sizes, b, 1e-6, 1e-7, 1e-5, &err);
        CHECK_MSG(ok, "%s: %s", model_brdf_name((model_brdf_t)m), model_last_error());
    }
}

// A candidate of a priors entry by model name.
static json_t *candidate(json_t *mat, const char *model)
{
    json_t *c;
    size_t i;
    json_array_foreach(json_object_get(mat, "candidates"), i, c)
        if (!strcmp(json_string_value(json_object_get(c, "model")), model)) return c;
    return NULL;
}

// The model choice of refl fit brdf --model all by 5-fold cross-validation:
// on samples of each model with white noise (sigma 0.002 1/sr) it picks the
// generating model, or one the held-out data cannot tell from it (within one
// standard error); with errors that blocks of samples share (3 % per 200
// lines, on ggx) it keeps ggx, and BIC's pick (which counts every sample as
// independent, and at other seeds prefers the 6-parameter ggx2) is recorded
// and is what --cv-folds 0 chooses. Both criteria are in the priors
// (model_choice, cv_rms and bic per candidate) and printed.
TEST(fit_brdf_model_choice_cross_validated)
{
    const struct {
        model_brdf_t m;
        double       p[6], corr;
    } k[] = {
        { MODEL_BRDF_GGX, { 0.35, 0.6, 0.1, 0.3 }, 0 },
        { MODEL_BRDF_ASHIKHMIN_SHIRLEY, { 0.5, 0.08, 60 }, 0 },
        { MODEL_BRDF_GGX2, { 0.25, 0.25, 0.05, 0.3, 0.4, 0.6 }, 0 },
        { MODEL_BRDF_HALL, { 0.12, 0.05, 40 }, 0 },
        { MODEL_BRDF_GGX, { 0.35, 0.6, 0.1, 0.3 }, 0.03 },
    };
    char bic_pick[32] = "";
    for (size_t i = 0; i < sizeof k / sizeof k[0]; i++) {
        const char *name = model_brdf_name(k[i].m);
        char fn[64];
        snprintf(fn, sizeof fn, "cv%zu.csv", i);
        const char *csv = write_model_csv_corr(fn, k[i].m, k[i].p, 0.002, 21 + i, k[i].corr);
        snprintf(fn, sizeof fn, "cv%zu.json", i);
        const char *priors = test_path(fn);
        char *out = NULL, *err = NULL;
        int rc = test_refl_run(300, &out, &err, "fit", "brdf", csv, "-o", priors, NULL);
        CHECK_MSG(rc == 0, "%s", err);
        CHECK_CONTAINS(out, "cross-validated");
        CHECK_CONTAINS(out, "lowest BIC");
        CHECK_CONTAINS(err, "held-out rms");
        g_free(out);
        g_free(err);
        json_t *top = json_load_file(priors, 0, NULL);
        json_t *mat = json_array_get(json_object_get(top, "materials"), 0), *ch = json_object_get(mat, "model_choice");
        CHECK(ch && !strcmp(json_string_value(json_object_get(ch, "criterion")), "cv_rms"));
        CHECK(json_integer_value(json_object_get(ch, "folds")) == 5 && json_integer_value(json_object_get(ch, "units")) == 50);
        CHECK_CONTAINS(json_string_value(json_object_get(ch, "cv_rms_unit")), "1/sr");
        const char *chosen = json_string_value(json_object_get(ch, "chosen")), *bic = json_string_value(json_object_get(ch, "lowest_bic"));
        CHECK(chosen && bic && !strcmp(chosen, json_string_value(json_object_get(mat, "model"))));
        CHECK(json_is_number(json_object_get(mat, "cv_rms")) && json_is_number(json_object_get(mat, "bic")));
        json_t *c_truth = candidate(mat, name), *c_chosen = candidate(mat, chosen ? chosen : "");
        CHECK(json_array_size(json_object_get(mat, "candidates")) == MODEL_BRDF_COUNT);
        if (c_truth && c_chosen) {
            double ct = json_number_value(json_object_get(c_truth, "cv_rms"));
            double cc = json_number_value(json_object_get(c_chosen, "cv_rms")), se = json_number_value(json_object_get(c_chosen, "cv_rms_se"));
            fprintf(stderr, "  %s%s: chosen %s (held-out rms %.5g +- %.2g), generating %.5g; lowest BIC %s\n", name,
                    k[i].corr > 0 ? " (errors shared by blocks)" : "", chosen, cc, se, ct, bic);
            CHECK_MSG(!strcmp(chosen, name) || ct <= cc + se, "%s: chose %s (held-out %.5g +- %.2g), generating %.5g",
                      name, chosen, cc, se, ct);
            if (k[i].corr == 0) CHECK_MSG(cc < 1.05 * 0.002, "%s: held-out rms %.5g over the noise 0.002", name, cc);
        }
        if (k[i].corr > 0) CHECK(chosen && !strcmp(chosen, "ggx"));
        if (k[i].corr > 0 && bic) snprintf(bic_pick, sizeof bic_pick, "%s", bic);
        json_decref(top);
    }
    // --cv-folds 0 on the correlated samples: the lowest BIC (the one recorded above), said so
    char *out = NULL, *err = NULL, expect[64];
    int rc = test_refl_run(300, &out, &err, "fit", "brdf", test_path("cv4.csv"), "--cv-folds", "0", "-o",
                           test_path("cvb.json"), NULL);
    CHECK_MSG(rc == 0, "%s", err);
    snprintf(expect, sizeof expect, "model %s (lowest BIC", bic_pick);
    CHECK_CONTAINS(out, expect);
    CHECK_CONTAINS(out, "cross-validation off");
    const char *csv = test_path("cv4.csv");
    g_free(out);
    g_free(err);
    rc = test_refl_run(60, &out, &err, "fit", "brdf", csv, "--cv-folds", "x", "-o", test_path("cvc.json"), NULL);
    CHECK(rc == 2);
    CHECK_CONTAINS(err, "--cv-folds needs a whole number");
    g_free(out);
    g_free(err);
}

// The folds are deterministic (the same seed, the same held-out figures bit
// for bit; another seed, other folds), a unit's samples stay together (one
// unit for all: nothing to hold out, the lowest BIC, said so), and the
// number of units is the number of distinct unit ids.
TEST(fit_brdf_cv_folds_seeded_and_by_unit)
{
    double ggx[] = { 0.35, 0.6, 0.1, 0.3 };
    fit_samples_t *s = synth_grid(MODEL_BRDF_GGX, ggx, 0.002, 3, 10, -1);
    const model_brdf_t models[] = { MODEL_BRDF_LAMBERT, MODEL_BRDF_GGX };
    fit_brdf_models_t *a = malloc(sizeof *a), *b = malloc(sizeof *b);
    fit_brdf_options_t o = fit_brdf_defaults();
    CHECK(fit_brdf_models(s, models, 2, &o, a) && fit_brdf_models(s, models, 2, &o, b));
    CHECK(a->by_cv && a->cv_folds == 5 && a->cv_units == 50);
    CHECK(a->res[1].model == MODEL_BRDF_GGX && a->res[1].cv_rms == b->res[1].cv_rms && a->res[1].cv_se == b->res[1].cv_se);
    CHECK(a->res[a->best].model == MODEL_BRDF_GGX);
    o.cv_seed = 2;
    CHECK(fit_brdf_models(s, models, 2, &o, b));
    CHECK(b->by_cv && b->res[1].cv_rms != a->res[1].cv_rms);
    CHECK_REL(b->res[1].cv_rms, a->res[1].cv_rms, 0.05);
    int *unit = malloc((size_t)s->n * sizeof *unit);
    for (int i = 0; i < s->n; i++) unit[i] = 7;
    o.cv_unit = unit;
    o.cv_unit_name = "frame";
    CHECK(fit_brdf_models(s, models, 2, &o, b));
    CHECK(!b->by_cv && b->best == b->best_bic && isnan(b->res[1].cv_rms));
    CHECK_CONTAINS(b->cv_note, "1 frame(s): too few to cross-validate");
    for (int i = 0; i < s->n; i++) unit[i] = 1000 - 3 * (i / 37);   // any ids, in any order
    CHECK(fit_brdf_models(s, models, 2, &o, b));
    CHECK(b->by_cv && b->cv_units == (s->n + 36) / 37 && !strcmp(b->cv_unit_name, "frame"));
    o.cv_folds = 0;
    CHECK(fit_brdf_models(s, models, 2, &o, b));
    CHECK(!b->by_cv && b->cv_folds == 0);
    CHECK_CONTAINS(b->cv_note, "cross-validation off");
    json_t *j = fit_brdf_choice_json(b);
    CHECK(!strcmp(json_string_value(json_object_get(j, "criterion")), "bic"));
    json_decref(j);
    free(unit);
    free(a);
    free(b);
    fit_samples_free(s);
}

TEST(fit_brdf_csv_round_trip_and_errors)
{
    // a GGX material written as a CSV with a header and comments
    double ggx[] = { 0.3, 0.5, 0.15, 0.2 };
    GString *g = g_string_new("# measured somewhere\ntheta_i,phi_i,theta_o,phi_o,f_r,weight\n");
    for (int ti = 0; ti < 80; ti += 10)
        for (int to = 0; to < 80; to += 5)
            for (int po = 0; po < 360; po += 15) {
                const double d = M_PI / 180;
                model_cosines_t c = model_cosines(v3(0, 0, 1), v3(sin(ti * d), 0, cos(ti * d)),
                                                  v3(sin(to * d) * cos(po * d), sin(to * d) * sin(po * d), cos(to * d)));
                double fr = model_brdf_eval(MODEL_BRDF_GGX, ggx, &c, NULL) / c.nl;
                g_string_append_printf(g, "%d,0,%d,%d,%.12g,1\n", ti, to, po, fr);
            }
    const char *csv = test_write("ggx.csv", g->str);
    g_string_free(g, TRUE);
    fit_samples_t *s = fit_samples_read(csv);
    CHECK_MSG(s != NULL, "%s", model_last_error());
    if (!s) return;
    CHECK(s->n == 8 * 16 * 24);
    fit_brdf_result_t r;
    CHECK(fit_brdf(s, MODEL_BRDF_GGX, NULL, &r));
    for (int j = 0; j < 4; j++) CHECK_NEAR(r.p[j], ggx[j], 1e-4);
    fit_samples_free(s);

    // the command: priors file with the contract's fields
    const char *priors = test_path("priors.json");
    char *out = NULL, *err = NULL;
    int rc = test_refl_run(120, &out, &err, "fit", "brdf", csv, "--model", "all", "--name", "paint", "-o", priors,
                           NULL);
    CHECK_MSG(rc == 0, "%s", err);
    CHECK_CONTAINS(out, "model ggx");
    g_free(out);
    g_free(err);
    json_error_t je;
    json_t *top = json_load_file(priors, 0, &je);
    CHECK_MSG(top != NULL, "%s", je.text);
    if (top) {
        json_t *mat = json_array_get(json_object_get(top, "materials"), 0);
        CHECK(!strcmp(json_string_value(json_object_get(mat, "name")), "paint"));
        CHECK(!strcmp(json_string_value(json_object_get(mat, "model")), "ggx"));
        json_t *ps = json_object_get(mat, "parameters");
        CHECK(json_array_size(ps) == 4);
        json_t *alpha = json_array_get(ps, 2);
        CHECK(!strcmp(json_string_value(json_object_get(alpha, "name")), "alpha"));
        CHECK_CONTAINS(json_string_value(json_object_get(alpha, "convention")), "not perceptual roughness");
        double mean = json_number_value(json_object_get(alpha, "mean"));
        double lo = json_number_value(json_object_get(alpha, "lo")), hi = json_number_value(json_object_get(alpha, "hi"));
        CHECK_NEAR(mean, 0.15, 1e-4);
        CHECK(lo <= mean && mean <= hi && lo >= 0.001 && hi <= 1);
        CHECK(json_array_size(json_object_get(mat, "covariance")) == 4);
        CHECK(json_object_get(mat, "rms") && json_object_get(mat, "ngan_error") && json_object_get(mat, "aic") &&
              json_object_get(mat, "bic") && json_object_get(mat, "n_samples"));
        CHECK(json_array_size(json_object_get(mat, "candidates")) == MODEL_BRDF_COUNT);
        json_t *prov = json_object_get(top, "provenance");
        CHECK(json_object_get(prov, "refl_version") && json_array_size(json_object_get(prov, "inputs")) == 1);
        json_decref(top);
    }

    // errors name file and line
    const char *bad = test_write("bad.csv", "theta_i,phi_i,theta_o,phi_o,f_r\n10,0,20,0,0.1\n10,0,abc,0,0.1\n");
    CHECK(fit_samples_read(bad) == NULL);
    CHECK_CONTAINS(model_last_error(), "bad.csv:3");
    bad = test_write("bad2.csv", "10,0,20,0\n");
    CHECK(fit_samples_read(bad) == NULL);
    CHECK_CONTAINS(model_last_error(), "bad2.csv:1");
    CHECK_CONTAINS(model_last_error(), "4 fields");
    bad = test_write("bad3.csv", "10,0,95,0,0.1\n");
    CHECK(fit_samples_read(bad) == NULL);
    CHECK_CONTAINS(model_last_error(), "0..90");
    bad = test_write("bad4.csv", "# nothing\n");
    CHECK(fit_samples_read(bad) == NULL);
    CHECK_CONTAINS(model_last_error(), "no samples");
    rc = test_refl_run(60, &out, &err, "fit", "brdf", csv, "--model", "phong", "-o", priors, NULL);
    CHECK(rc == 2);
    CHECK_CONTAINS(err, "unknown model phong");
    g_free(out);
    g_free(err);
}

// A MERL file of a Cook-Torrance material (written here) fits back.
TEST(fit_brdf_merl_file)
{
    const int N = 90 * 90 * 180;
    double ct[] = { 0.3, 0.4, 0.2, 0.5 };
    double *v = malloc(3 * (size_t)N * sizeof *v);
    const double scale[3] = { 1.0 / 1500, 1.15 / 1500, 1.66 / 1500 };
    for (int i = 0; i < 90; i++) {
        double th = (i + 0.5) / 90;
        th = th * th * (M_PI / 2);
        for (int j = 0; j < 90; j++) {
            double td = (j + 0.5) / 90 * (M_PI / 2);
            for (int k = 0; k < 180; k++) {
                double pd = (k + 0.5) / 180 * M_PI;
                // directions from the half/difference angles (phi_h = 0)
                model_vec3_t h = v3(sin(th), 0, cos(th));
                model_vec3_t dd = v3(sin(td) * cos(pd), sin(td) * sin(pd), cos(td));
                model_vec3_t l = v3(dd.x * cos(th) + dd.z * sin(th), dd.y, -dd.x * sin(th) + dd.z * cos(th));
                double lh = l.x * h.x + l.y * h.y + l.z * h.z;
                model_vec3_t w = v3(2 * lh * h.x - l.x, 2 * lh * h.y - l.y, 2 * lh * h.z - l.z);
                size_t idx = ((size_t)i * 90 + j) * 180 + k;
                double f = -1;
                if (l.z > 0 && w.z > 0) {
                    model_cosines_t c = model_cosines(v3(0, 0, 1), l, w);
                    f = model_brdf_eval(MODEL_BRDF_COOK_TORRANCE, ct, &c, NULL) / c.nl;
                }
                for (int ch = 0; ch < 3; ch++) v[ch * (size_t)N + idx] = f < 0 ? -1 : f / scale[ch];
            }
        }
    }
    const char *path = test_path("ct.binary");
    FILE *f = fopen(path, "wb");
    int32_t dims[3] = { 90, 90, 180 };
    fwrite(dims, 4, 3, f);
    fwrite(v, sizeof *v, 3 * (size_t)N, f);
    fclose(f);
    free(v);
    fit_samples_t *s = fit_samples_read(path);
    CHECK_MSG(s != NULL, "%s", model_last_error());
    if (!s) return;
    CHECK(s->n > N / 3);
    // a subsample keeps the test fast
    fit_samples_t *sub = fit_samples_new();
    for (int i = 0; i < s->n; i += 37) fit_samples_add(sub, &s->c[i], s->R[i], 1);
    fit_brdf_result_t r;
    CHECK(fit_brdf(sub, MODEL_BRDF_COOK_TORRANCE, NULL, &r));
    for (int j = 0; j < 4; j++) CHECK_NEAR(r.p[j], ct[j], 1e-3);
    fit_samples_free(sub);
    fit_samples_free(s);
    // truncated: a clear error
    const char *bad = test_write("short.binary", "\x5a\x00\x00\x00\x5a\x00\x00\x00\xb4\x00\x00\x00");
    fit_samples_t *b = fit_samples_read_merl(bad);
    CHECK(b == NULL);
    CHECK_CONTAINS(model_last_error(), "not a MERL BRDF file");
}

// Noise-free GGX samples seen only at v.h >= vh_min.
static fit_samples_t *synth_vh(const double *p, double vh_min)
{
    return synth_grid(MODEL_BRDF_GGX, p, 0, 1, 3, vh_min);
}

// F0 apart from ks: where the samples never come near grazing only ks*F0 is
// measured, and F0 is known only to lie in [ks*F0 / ks_max, 1]: held at that
// interval's middle with a uniform's std, ks = ks*F0 / F0, and the covariance
// along ks*F0 = const (ks and F0 anticorrelated). A metal-like material (ks*F0
// 0.72: F0 in [0.72, 1]) has its truth within 2 std of both; a dielectric's
// interval is wide (ks = ks*F0 / F0 spans a factor 37 over it), so its
// interval is checked but not its mean. With grazing samples F0 is measured.
TEST(fit_brdf_f0_interval_when_not_measured)
{
    const double metal[4] = { 0.03, 0.9, 0.08, 0.8 }, plastic[4] = { 0.35, 0.6, 0.08, 0.045 };   // kd, ks, alpha, F0
    for (int k = 0; k < 2; k++) {
        const double *truth = k ? plastic : metal;
        fit_samples_t *s = synth_vh(truth, 0.9);
        fit_brdf_result_t r;
        CHECK(fit_brdf(s, MODEL_BRDF_GGX, NULL, &r));
        double prod = truth[1] * truth[3];
        printf("  %s, v.h >= 0.9: F0 %.4f +- %.4f in [%.4f, %.4f], ks %.4f +- %.4f, ks*F0 %.5f\n", k ? "plastic" : "metal",
               r.p[3], r.std[3], r.f0_lo, r.f0_hi, r.p[1], r.std[1], r.p[1] * r.p[3]);
        CHECK(r.fixed[3] && r.f0_unmeasured && r.fresnel_variation < 0.05);
        CHECK_NEAR(r.f0_lo, prod, 1e-4);
        CHECK_NEAR(r.f0_hi, 1, 0);
        CHECK_NEAR(r.p[3], 0.5 * (r.f0_lo + r.f0_hi), 1e-12);
        CHECK_NEAR(r.std[3], (r.f0_hi - r.f0_lo) / sqrt(12), 1e-9);
        CHECK_NEAR(r.p[1] * r.p[3], prod, 1e-4 * prod / 0.027);
        CHECK_NEAR(r.p[0], truth[0], 1e-4);
        CHECK_NEAR(r.p[2], 0.08, 1e-4);
        CHECK(r.cov_ok && r.cov[1 * 4 + 3] < 0);
        if (!k) CHECK(fabs(r.p[3] - truth[3]) < 2 * r.std[3] && fabs(r.p[1] - truth[1]) < 2 * r.std[1]);
        json_t *o = fit_priors_material("m", &r, NULL, 0, 3, 0.03);
        json_t *f0 = json_array_get(json_object_get(o, "parameters"), 3);
        CHECK(json_is_string(json_object_get(f0, "held")));
        CHECK_NEAR(json_number_value(json_object_get(f0, "lo")), r.f0_lo, 1e-12);   // the interval, not mean - 3 std
        CHECK_NEAR(json_number_value(json_object_get(f0, "std")), r.std[3], 1e-12);
        json_decref(o);
        fit_samples_free(s);
    }
    // grazing samples (v.h down to 0.3): F0 measured
    fit_samples_t *s = synth_vh(plastic, 0.3);
    fit_brdf_result_t r;
    CHECK(fit_brdf(s, MODEL_BRDF_GGX, NULL, &r));
    printf("  plastic, v.h >= 0.3: F0 %.5f +- %.2g, ks %.5f\n", r.p[3], r.std[3], r.p[1]);
    CHECK(!r.fixed[3] && !r.f0_unmeasured);
    CHECK_NEAR(r.p[3], 0.045, 1e-4);
    CHECK_NEAR(r.p[1], 0.6, 1e-3);
    fit_samples_free(s);
}

// A finite lamp: the 4-direction quadrature of the lamp's disc against a
// dense average over the disc (a polar grid, equal solid angle per cell) for
// a narrow GGX lobe near the mirror direction at v.h = cos 55 deg (the rim
// lamp's highlight on the glossy coupon): the point lamp is off by several %,
// the quadrature within a tenth of that; the fit's Jacobian is the average's.
TEST(fit_lamp_disc_quadrature)
{
    const double p[4] = { 0.35, 0.6, 0.05, 0.045 };
    const double d_mm = 650, r_mm = 15, d = M_PI / 180;
    model_vec3_t n = v3(0, 0, 1), v = v3(sin(55 * d), 0, cos(55 * d));
    double worst_point = 0, worst_quad = 0;
    for (int off = 0; off <= 4; off++) {   // lamp 0..2 deg off the mirror direction
        double a = (55 + 0.5 * off) * d;
        model_vec3_t l = v3(-sin(a), 0, cos(a));
        model_vec3_t q[4];
        CHECK(model_lamp_disc_dirs(l, d_mm, r_mm, q));
        model_cosines_t c = model_cosines(n, l, v), cq[4];
        for (int k = 0; k < 4; k++) cq[k] = model_cosines(n, q[k], v);
        fit_samples_t *s = fit_samples_new();
        CHECK(fit_samples_add_disc(s, &c, cq, 1, 1));
        double quad = fit_samples_eval(s, MODEL_BRDF_GGX, p, 0), point = model_brdf_eval(MODEL_BRDF_GGX, p, &c, NULL);
        // dense: 200 rings x 200 azimuths over the cone of the lamp
        double tmax = asin(r_mm / d_mm), omc = 1 - cos(tmax), sum = 0;
        model_vec3_t e1 = v3(cos(a), 0, sin(a)), e2 = v3(0, 1, 0);
        for (int i = 0; i < 200; i++)
            for (int j = 0; j < 200; j++) {
                double ct = 1 - (i + 0.5) / 200 * omc, st = sqrt(1 - ct * ct), ph = 2 * M_PI * (j + 0.5) / 200;
                model_vec3_t w = v3(ct * l.x + st * (cos(ph) * e1.x + sin(ph) * e2.x),
                                    ct * l.y + st * (cos(ph) * e1.y + sin(ph) * e2.y),
                                    ct * l.z + st * (cos(ph) * e1.z + sin(ph) * e2.z));
                model_cosines_t cw = model_cosines(n, w, v);
                sum += model_brdf_eval(MODEL_BRDF_GGX, p, &cw, NULL);
            }
        double dense = sum / (200 * 200);
        printf("  %.1f deg off: dense %.5f, point %+.2f %%, quadrature %+.3f %%\n", 0.5 * off, dense,
               100 * (point / dense - 1), 100 * (quad / dense - 1));
        worst_point = fmax(worst_point, fabs(point / dense - 1));
        worst_quad = fmax(worst_quad, fabs(quad / dense - 1));
        // Jacobian: the average of the 4 directions' (central differences of the sample's R)
        double J[4], R0;
        fit_samples_eval_n(s, MODEL_BRDF_GGX, p, 0, 1, &R0, J);
        for (int j = 0; j < 4; j++) {
            double pp[4], pm[4], h = 1e-6 * fmax(1, fabs(p[j]));
            memcpy(pp, p, sizeof pp);
            memcpy(pm, p, sizeof pm);
            pp[j] += h;
            pm[j] -= h;
            double fd = (fit_samples_eval(s, MODEL_BRDF_GGX, pp, 0) - fit_samples_eval(s, MODEL_BRDF_GGX, pm, 0)) / (2 * h);
            CHECK_MSG(fabs(J[j] - fd) <= 1e-5 * fmax(1, fabs(fd)), "dR/dp%d %g vs %g", j, J[j], fd);
        }
        fit_samples_free(s);
    }
    CHECK_MSG(worst_point > 0.03, "point lamp off by only %.2f %%", 100 * worst_point);
    CHECK_MSG(worst_quad < 0.1 * worst_point, "quadrature off by %.3f %% (point %.2f %%)", 100 * worst_quad,
              100 * worst_point);
    model_vec3_t q[4];
    CHECK(!model_lamp_disc_dirs(v3(0, 0, 1), 650, 0, q));   // a point lamp
    CHECK(!model_lamp_disc_dirs(v3(0, 0, 1), 10, 15, q));   // inside the lamp
}
