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
#include "model/base/report.h"
#include "model/base/vec.h"
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
    calib_white_lamp_t wl[2];
    CHECK(t && calib_white(&obs, &cal, 0.99, t, NULL, out, NULL, wl));
    CHECK(calib_white(&obs, &cal, white_R(0, 0), NULL, NULL, outl, NULL, NULL));
    json_t *j = json_load_file(out, 0, NULL), *jl = json_load_file(outl, 0, NULL);
    CHECK(j && jl);
    // white.json names its format; the figures returned are the file's
    int ver = 0;
    CHECK(j && model_json_format_check(j, out, "refl-white", 1, &ver) && ver == 1);
    for (int l = 0; j && jl && l < 2; l++) {
        json_t *e = json_array_get(json_object_get(j, "lamps"), l), *el = json_array_get(json_object_get(jl, "lamps"), l);
        double k = json_number_value(json_object_get(e, "kc_I_per_us"));
        double kl = json_number_value(json_object_get(el, "kc_I_per_us"));
        fprintf(stderr, "  lamp %d: kc*I with the table %+.3f %%, Lambertian %+.3f %%\n", l, 100 * (k / kcI[l] - 1),
                100 * (kl / kcI[l] - 1));
        CHECK(fabs(k / kcI[l] - 1) < 0.005);
        CHECK(!strcmp(wl[l].name, l ? "right" : "left"));
        CHECK_REL(wl[l].kcI_per_us, k, 1e-9);
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
    rc = test_refl_run(60, &out, &err, "calib", "white", "s", "--calib", "c", "-o", "w.json", "--albedo-std", "x",
                       NULL);
    CHECK(rc == 2);
    CHECK_CONTAINS(err, "--albedo-std");
    free(out);
    free(err);
}

// ---------------------------------------------------------------------------
// The white's uncertainty (calib_white_compute) against the scatter of kc*I
// over repeated lab days whose inputs are drawn from their stated 1-sigmas.

enum { SW_N = 600 };
static const double sw_kcI = 5.0e5, sw_albedo = 0.99;

// A flat white (z = 0, normal +z) of SW_N windows within 70 mm of the
// centre at angle 0, seen at n.v 0.9, lit by a lamp at Lt of pattern
// (n, axis) (n 0: isotropic) with signal noise 0.3 %; the observations'
// geometry (d, n.l) and pattern divided out are the calibrated lamp's Lc
// (n_c, axis_c), as calib_observe makes them.
static void sw_observe(calib_obs_set_t *obs, model_rng_t *noise, model_vec3_t Lt, double nt, model_vec3_t at,
                       model_vec3_t Lc, double nc, model_vec3_t ac)
{
    model_rng_t grid = model_rng(11, 3);   // the same windows every day
    model_lamp_t T = { .position_mm = Lt, .emission_cos_power = nt, .emission_axis = at };
    model_lamp_t C = { .position_mm = Lc, .emission_cos_power = nc, .emission_axis = ac };
    obs->n = SW_N;
    obs->window_px = 5;
    for (int i = 0; i < SW_N; i++) {
        calib_obs_t *o = &obs->o[i];
        double r = 70 * sqrt(model_rng_uniform(&grid)), ph = 2 * M_PI * model_rng_uniform(&grid);
        model_vec3_t p = v3(r * cos(ph), r * sin(ph), 0);
        memset(o, 0, sizeof *o);
        o->p0_mm[0] = p.x, o->p0_mm[1] = p.y;
        o->n0[2] = 1;
        o->q[0] = i % 40, o->q[1] = i / 40;
        model_vec3_t dt = v3_sub(Lt, p), dc = v3_sub(Lc, p);
        double d2t = v3_dot(dt, dt), nlt = dt.z / sqrt(d2t);
        double raw = sw_kcI * model_lamp_emission(&T, p) * sw_albedo / M_PI * nlt / d2t *
                     (1 + 0.003 * model_rng_gauss(noise));
        o->d_mm = sqrt(v3_dot(dc, dc));
        o->c.nl = dc.z / o->d_mm;
        o->c.nv = 0.9;
        o->emission = model_lamp_emission(&C, p);
        o->s_dn_per_us = raw / o->emission;
    }
}

static double sw_std(const double *x, int n)
{
    double m = 0, v = 0;
    for (int i = 0; i < n; i++) m += x[i] / n;
    for (int i = 0; i < n; i++) v += (x[i] - m) * (x[i] - m);
    return sqrt(v / (n - 1));
}

// The lamp position's part: days whose calibrated lamp lies off the true one
// by draws of its stated std (0.8, 0.5, 1.2 mm): the scatter of their kc*I
// (and of the irradiance at the region's worst point) against the stated
// part, within 20 %. The albedo's part is the certificate's relative 1-sigma.
TEST(calib_white_sigma_lamp_position)
{
    const model_vec3_t Lt = v3(420, 150, 560);
    const double sd[3] = { 0.8, 0.5, 1.2 };
    enum { DAYS = 300 };
    calib_obs_set_t obs = { .cap = SW_N, .o = calloc(SW_N, sizeof(calib_obs_t)) };
    model_lamp_t lamp = { .name = "east" };
    model_lamps_t ls = { .n = 1, .lamps = &lamp };
    calib_set_t cal = { .lamps = &ls, .flat_pixel_std_rel = NAN };
    cal.lamp_sigma[0].have_position = true;
    for (int k = 0; k < 3; k++) cal.lamp_sigma[0].position_cov_mm2[4 * k] = sd[k] * sd[k];
    calib_white_options_t o = calib_white_defaults();
    o.albedo_std = 0.005;
    calib_white_lamp_t w;
    model_rng_t noise = model_rng(5, 1), place = model_rng(5, 2);
    // the stated part, on a day whose lamp is where the truth has it
    lamp.position_mm = Lt;
    sw_observe(&obs, &noise, Lt, 0, v3(0, 0, 0), Lt, 0, v3(0, 0, 0));
    CHECK(calib_white_compute(&obs, &cal, sw_albedo, NULL, &o, &w, "white.json"));
    double stated = w.part_rel[CALIB_WHITE_POSITION], stated_irr = w.irr_part_rel[CALIB_WHITE_POSITION];
    model_vec3_t q = w.irr_worst_mm;
    CHECK_REL(w.part_rel[CALIB_WHITE_ALBEDO], 0.005 / sw_albedo, 1e-12);
    CHECK(isnan(w.part_rel[CALIB_WHITE_PATTERN]) && isnan(w.part_rel[CALIB_WHITE_FLAT]));
    CHECK_REL(w.std_rel, sqrt(stated * stated + pow(0.005 / sw_albedo, 2) + pow(w.part_rel[CALIB_WHITE_STAT], 2)),
              1e-9);
    // the days
    double kc[DAYS], irr[DAYS];
    o.draws = 20;
    cal.lamp_sigma[0].have_position = false;
    for (int d = 0; d < DAYS; d++) {
        model_vec3_t Lc = v3_add(Lt, v3(sd[0] * model_rng_gauss(&place), sd[1] * model_rng_gauss(&place),
                                        sd[2] * model_rng_gauss(&place)));
        lamp.position_mm = Lc;
        sw_observe(&obs, &noise, Lt, 0, v3(0, 0, 0), Lc, 0, v3(0, 0, 0));
        CHECK(calib_white_compute(&obs, &cal, sw_albedo, NULL, &o, &w, "white.json"));
        kc[d] = w.kcI_per_us / sw_kcI;
        model_vec3_t dc = v3_sub(q, Lc), dt = v3_sub(q, Lt);
        irr[d] = (w.kcI_per_us / v3_dot(dc, dc)) / (sw_kcI / v3_dot(dt, dt));
    }
    double s = sw_std(kc, DAYS), si = sw_std(irr, DAYS);
    fprintf(stderr, "  lamp position: kc*I scatter %.4f %% over %d days, stated %.4f %%; irradiance at (%g, %g, %g) "
            "mm %.4f %%, stated %.4f %%\n", 100 * s, DAYS, 100 * stated, q.x, q.y, q.z, 100 * si, 100 * stated_irr);
    CHECK(s > 0.0005);   // the part matters here
    CHECK_MSG(fabs(stated / s - 1) < 0.2, "stated %.5f, scatter %.5f", stated, s);
    CHECK_MSG(fabs(stated_irr / si - 1) < 0.2, "irradiance: stated %.5f, scatter %.5f", stated_irr, si);
    free(obs.o);
}

// The emission pattern's part: a lamp of n 3 aimed 12 deg off the white
// (its on-axis kc*I an extrapolation), days whose calibrated pattern is
// drawn from the stated covariance of (n, t1, t2) (n 0.15, tilts 1.5 deg):
// the scatter of kc*I against the stated part, within 20 %; a table's
// factor_std gives the albedo's part.
TEST(calib_white_sigma_pattern)
{
    const model_vec3_t Lt = v3(-380, 200, 600);
    const model_vec3_t o0 = v3_unit(v3_scale(Lt, -1));
    model_vec3_t h = v3_unit(v3_cross(v3(0, 0, 1), o0));
    const double tilt = 12 * M_PI / 180, nt = 3, sn = 0.15, st = 1.5 * M_PI / 180;
    model_vec3_t at = v3_unit(v3_add(v3_scale(o0, cos(tilt)), v3_scale(h, sin(tilt))));
    model_vec3_t u1 = v3_unit(v3_sub(h, v3_scale(at, v3_dot(h, at)))), u2 = v3_unit(v3_cross(at, u1));
    enum { DAYS = 300 };
    calib_obs_set_t obs = { .cap = SW_N, .o = calloc(SW_N, sizeof(calib_obs_t)) };
    model_lamp_t lamp = { .name = "west", .position_mm = Lt, .emission_cos_power = nt, .emission_axis = at };
    model_lamps_t ls = { .n = 1, .lamps = &lamp };
    calib_set_t cal = { .lamps = &ls, .flat_pixel_std_rel = NAN };
    calib_lamp_sigma_t *S = &cal.lamp_sigma[0];
    S->have_pattern = true;
    S->n = nt;
    S->axis = at;
    S->pattern_cov[0] = sn * sn;
    S->pattern_cov[4] = S->pattern_cov[8] = st * st;
    S->axis_per_t[0] = u1;
    S->axis_per_t[1] = u2;
    calib_white_options_t o = calib_white_defaults();
    calib_white_lamp_t w;
    model_rng_t noise = model_rng(6, 1), draw = model_rng(6, 2);
    sw_observe(&obs, &noise, Lt, nt, at, Lt, nt, at);
    CHECK(calib_white_compute(&obs, &cal, sw_albedo, NULL, &o, &w, "white.json"));
    double stated = w.part_rel[CALIB_WHITE_PATTERN];
    CHECK(isnan(w.part_rel[CALIB_WHITE_POSITION]) && isnan(w.part_rel[CALIB_WHITE_ALBEDO]));
    double kc[DAYS];
    o.draws = 20;
    S->have_pattern = false;
    for (int d = 0; d < DAYS; d++) {
        double nc = nt + sn * model_rng_gauss(&draw), t1 = st * model_rng_gauss(&draw), t2 = st * model_rng_gauss(&draw);
        model_vec3_t ac = v3_unit(v3_add(at, v3_add(v3_scale(u1, t1), v3_scale(u2, t2))));
        lamp.emission_cos_power = nc;
        lamp.emission_axis = ac;
        sw_observe(&obs, &noise, Lt, nt, at, Lt, nc, ac);
        CHECK(calib_white_compute(&obs, &cal, sw_albedo, NULL, &o, &w, "white.json"));
        kc[d] = w.kcI_per_us / sw_kcI;
    }
    double s = sw_std(kc, DAYS);
    fprintf(stderr, "  emission pattern: kc*I scatter %.4f %% over %d days, stated %.4f %%\n", 100 * s, DAYS,
            100 * stated);
    CHECK(s > 0.002);
    CHECK_MSG(fabs(stated / s - 1) < 0.2, "stated %.5f, scatter %.5f", stated, s);
    // a certificate with each factor's 1-sigma: the albedo's part is its relative value
    const char *text = "theta_i_deg,theta_r_deg,factor,factor_std\n0,0,0.99,0.004\n80,0,0.96,0.008\n";
    calib_white_table_t *t = calib_white_table_parse(text, strlen(text), "cert.csv");
    CHECK(t && t->fs);
    if (t) {
        CHECK_NEAR(calib_white_table_factor_std(t, 40, 10), 0.006, 1e-12);
        CHECK(calib_white_compute(&obs, &cal, sw_albedo, t, &o, &w, "white.json"));
        double a = w.part_rel[CALIB_WHITE_ALBEDO];
        fprintf(stderr, "  the table's factor_std: albedo part %.3f %%\n", 100 * a);
        CHECK(a > 0.004 / 0.99 && a < 0.008 / 0.96);
    }
    calib_white_table_free(t);
    const char *bad = "theta_i_deg,theta_r_deg,factor,factor_std\n0,0,0.99,-1\n";
    CHECK(calib_white_table_parse(bad, strlen(bad), "bad.csv") == NULL);
    CHECK_CONTAINS(model_last_error(), "bad.csv:2:");
    free(obs.o);
}
