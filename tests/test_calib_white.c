// tests/test_calib_white.c — `refl calib white` with the reference white's
// reflectance-factor table (calib/white.c): the table's parser (file:line
// errors), its interpolation, and kc*I recovered on a synthetic white that is
// not Lambertian, with the table and with the Lambertian assumption.
#define _GNU_SOURCE
#include <glib.h>
#include <jansson.h>
#include <stdlib.h>

#include "calib/calib.h"
#include "model/model.h"
#include "model/vec.h"
#include "tests/test.h"

// The synthetic white's reflectance factor (not separable in the two angles,
// falling toward grazing; its own form, not a standard's).
static double white_R(double ti_deg, double tr_deg)
{
    double ci = cos(ti_deg * M_PI / 180), cr = cos(tr_deg * M_PI / 180);
    return 0.985 * (1 - 0.07 * (1 - ci)) * (1 - 0.05 * (1 - cr)) + 0.015 * sin(ti_deg * M_PI / 180) *
                                                                        sin(tr_deg * M_PI / 180);
}

// The table of white_R on a 10-degree grid, 0..80, as a certificate would list it.
static char *white_table_text(void)
{
    GString *s = g_string_new("# synthetic white\ntheta_i_deg,theta_r_deg,factor\n");
    for (int i = 0; i <= 80; i += 10)
        for (int r = 0; r <= 80; r += 10) g_string_append_printf(s, "%d,%d,%.6f\n", i, r, white_R(i, r));
    return g_string_free(s, false);
}

TEST(calib_white_table_parse_and_interpolate)
{
    char *text = white_table_text();
    calib_white_table_t *t = calib_white_table_parse(text, strlen(text), "w.csv");
    CHECK(t != NULL);
    if (t) {
        CHECK(t->ni == 9 && t->nr == 9);
        CHECK_NEAR(calib_white_table_factor(t, 30, 40, NULL), white_R(30, 40), 1e-6);   // a knot
        // between knots: bilinear, close to the smooth function
        CHECK_NEAR(calib_white_table_factor(t, 33, 47, NULL), white_R(33, 47), 1e-3);
        bool out = false;
        CHECK_NEAR(calib_white_table_factor(t, 85, 10, &out), white_R(80, 10), 1e-6);   // clamped
        CHECK(out);
        out = false;
        calib_white_table_factor(t, 79, 0, &out);
        CHECK(!out);
    }
    calib_white_table_free(t);
    g_free(text);
    // a table by incidence only (one theta_r)
    const char *one = "theta_i_deg, theta_r_deg, factor\n0,0,0.99\n60,0,0.95\n";
    t = calib_white_table_parse(one, strlen(one), "one.csv");
    CHECK(t && t->ni == 2 && t->nr == 1);
    if (t) CHECK_NEAR(calib_white_table_factor(t, 30, 50, NULL), 0.97, 1e-12);
    calib_white_table_free(t);
    // bad tables: file:line and what is wrong
    static const struct {
        const char *text, *want;
    } bad[] = {
        { "0,0,0.99\n", "bad.csv:1:" },
        { "theta_i_deg,theta_r_deg,factor\n0,0,0.99\n10,0,abc\n", "bad.csv:3:" },
        { "theta_i_deg,theta_r_deg,factor\n0,0,0.99\n0,95,0.9\n", "[0, 90)" },
        { "theta_i_deg,theta_r_deg,factor\n# c\n0,0,0\n", "bad.csv:3:" },
        { "theta_i_deg,theta_r_deg,factor\n0,0,0.99\n0,0,0.98\n", "again (first on line 2)" },
        { "theta_i_deg,theta_r_deg,factor\n0,0,0.99\n10,20,0.98\n", "full grid" },
        { "theta_i_deg,theta_r_deg,factor\n", "no rows" },
        { "theta_i_deg,theta_r_deg,factor\n0,0,0.99,1\n", "bad.csv:2:" },
    };
    for (size_t k = 0; k < sizeof bad / sizeof bad[0]; k++) {
        t = calib_white_table_parse(bad[k].text, strlen(bad[k].text), "bad.csv");
        CHECK(t == NULL);
        CHECK_CONTAINS(model_last_error(), bad[k].want);
        calib_white_table_free(t);
    }
    CHECK(calib_white_table_load("/nonexistent/w.csv") == NULL);
    CHECK_CONTAINS(model_last_error(), "/nonexistent/w.csv");
    // the example table of a pressed-PTFE standard parses
    char *ex = g_strdup_printf("%s/examples/reference-white-ptfe.csv", test_srcdir());
    t = calib_white_table_load(ex);
    CHECK(t != NULL);
    if (t) CHECK(t->ni >= 3 && t->nr >= 3 && t->sha256[0]);
    calib_white_table_free(t);
    g_free(ex);
}

// kc*I of two lamps from observations of the synthetic white over incidence
// 20..75 deg and viewing 5..65 deg: with its table within 0.5 %; the
// Lambertian assumption (the table's factor at the normal) misses by more.
TEST(calib_white_table_recovers_kc)
{
    const double kcI[2] = { 1234.5, 2345.6 };
    calib_obs_set_t obs = { 0 };
    obs.cap = obs.n = 400;
    obs.o = calloc(400, sizeof *obs.o);
    snprintf(obs.sample, sizeof obs.sample, "reference_white");
    model_rng_t rng = model_rng(7, 1);
    for (int i = 0; i < 400; i++) {
        calib_obs_t *o = &obs.o[i];
        double ti = 20 + 55 * model_rng_uniform(&rng), tr = 5 + 60 * model_rng_uniform(&rng);
        o->lamp = i % 2;
        o->c.nl = cos(ti * M_PI / 180);
        o->c.nv = cos(tr * M_PI / 180);
        o->d_mm = 500 + 200 * model_rng_uniform(&rng);
        o->s_dn_per_us = kcI[o->lamp] * white_R(ti, tr) / M_PI * o->c.nl / (o->d_mm * o->d_mm);
    }
    model_lamp_t lamps[2] = { { .name = "left" }, { .name = "right" } };
    model_lamps_t ls = { .n = 2, .lamps = lamps };
    calib_set_t cal = { .lamps = &ls };
    char *text = white_table_text();
    calib_white_table_t *t = calib_white_table_parse(text, strlen(text), "white.csv");
    char *out = g_strdup_printf("%s/white.json", test_tmpdir()), *outl = g_strdup_printf("%s/lam.json", test_tmpdir());
    CHECK(t && calib_white(&obs, &cal, 0.99, t, NULL, out, NULL));
    CHECK(calib_white(&obs, &cal, white_R(0, 0), NULL, NULL, outl, NULL));
    json_t *j = json_load_file(out, 0, NULL), *jl = json_load_file(outl, 0, NULL);
    CHECK(j && jl);
    for (int l = 0; j && jl && l < 2; l++) {
        json_t *e = json_array_get(json_object_get(j, "lamps"), l), *el = json_array_get(json_object_get(jl, "lamps"), l);
        double k = json_number_value(json_object_get(e, "kc_I_per_us"));
        double kl = json_number_value(json_object_get(el, "kc_I_per_us"));
        fprintf(stderr, "  lamp %d: kc*I with the table %+.3f %%, Lambertian %+.3f %%\n", l, 100 * (k / kcI[l] - 1),
                100 * (kl / kcI[l] - 1));
        CHECK(fabs(k / kcI[l] - 1) < 0.005);
        CHECK(fabs(kl / kcI[l] - 1) > 0.005);
        // white.json states the Lambertian figure beside it
        CHECK_REL(json_number_value(json_object_get(e, "kc_I_lambertian_per_us")), kl, 1e-9);
    }
    json_t *m = j ? json_object_get(j, "white_model") : NULL;
    double dep = json_number_value(json_object_get(m, "departure_from_lambertian_pct"));
    fprintf(stderr, "  departure from Lambertian over the observed geometries: %.2f %%\n", dep);
    CHECK(dep > 2 && dep < 20);
    CHECK(json_integer_value(json_object_get(m, "observations_beyond_table")) == 0);
    CHECK(!strcmp(json_string_value(json_object_get(json_object_get(jl, "white_model"), "kind")), "lambertian"));
    json_decref(j);
    json_decref(jl);
    calib_white_table_free(t);
    g_free(text);
    g_free(out);
    g_free(outl);
    free(obs.o);
}

// The command: --albedo and --reflectance-table together are a usage error;
// a bad table is reported once with its file:line.
TEST(calib_white_cli_table)
{
    char *out = NULL, *err = NULL;
    const char *bad = test_write("bad.csv", "theta_i_deg,theta_r_deg,factor\n0,0,7\n");
    int rc = test_refl_run(60, &out, &err, "calib", "white", "s", "--calib", "c", "-o", "w.json", "--albedo", "0.9",
                           "--reflectance-table", bad, NULL);
    CHECK(rc == 2);
    CHECK_CONTAINS(err, "not both");
    free(out);
    free(err);
    rc = test_refl_run(60, &out, &err, "calib", "white", "s", "--calib", "c", "-o", "w.json", "--reflectance-table",
                       bad, NULL);
    CHECK(rc == 1);
    CHECK_CONTAINS(err, "bad.csv:2:");
    free(out);
    free(err);
}
