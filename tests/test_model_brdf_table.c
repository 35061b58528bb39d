// tests/test_model_brdf_table.c — tabulated BRDFs (model/brdf/table.c) and
// their generators (model/brdf/gen.c): reciprocity and energy of every
// generated model, a tabulated GGX against the analytic one, the MERL round
// trip, bad files, table materials in INI files and in the renderer.
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include "model/internal.h"
#include "tests/fixtures.h"
#include "tests/test.h"

static model_vec3_t dir_deg(double theta_deg, double phi_deg)
{
    double t = theta_deg * M_PI / 180, p = phi_deg * M_PI / 180;
    return v3(sin(t) * cos(p), sin(t) * sin(p), cos(t));
}

static const model_vec3_t N = { 0, 0, 1 };

// A direction of the upper hemisphere with theta in [0, max_deg].
static model_vec3_t random_dir(uint64_t *s, double max_deg)
{
    double u = (double)((*s = *s * 6364136223846793005ULL + 1442695040888963407ULL) >> 11) / 9007199254740992.0;
    double w = (double)((*s = *s * 6364136223846793005ULL + 1442695040888963407ULL) >> 11) / 9007199254740992.0;
    return dir_deg(u * max_deg, w * 360);
}

static model_brdf_table_t *tab(const char *recipe, model_brdf_recipe_t *r)
{
    model_brdf_recipe_t rr;
    if (!r) r = &rr;
    if (!model_brdf_recipe_parse(recipe, NULL, 0, r)) {
        test_fail(__FILE__, __LINE__, "recipe '%s': %s", recipe, model_last_error());
        return NULL;
    }
    return model_brdf_tabulate(r);
}

// Every generator, at its defaults and at the edges of its ranges: the table
// is reciprocal (exactly: the lookup averages phi_d and pi - phi_d) and its
// directional albedo is within [0, 1] (quadrature and interpolation tolerance
// 0.5 %) at 0, 30, 60 and 80 deg; the analytic recipe is reciprocal too.
TEST(brdf_table_generated_reciprocal_and_energy)
{
    static const char *const recipes[] = {
        "oren-nayar", "oren-nayar albedo=1 sigma=1", "ggx2", "ggx2 albedo=0 ks1=0.5 alpha1=0.05 ks2=0.5 F0=1",
        "retro", "retro albedo=0.5 kr=0.5 n=30", "ggx-ms", "ggx-ms alpha=1", "ggx-ms alpha=0.2", "ptfe",
        "ptfe albedo=1 drop=0.1", "ggx",
    };
    for (size_t q = 0; q < sizeof recipes / sizeof recipes[0]; q++) {
        model_brdf_recipe_t r;
        model_brdf_table_t *t = tab(recipes[q], &r);
        if (!t) continue;
        uint64_t seed = 7 + q;
        double worst_table = 0, worst_recipe = 0;
        for (int k = 0; k < 300; k++) {
            model_vec3_t l = random_dir(&seed, 89), v = random_dir(&seed, 89);
            model_cosines_t a = model_cosines(N, l, v), b = model_cosines(N, v, l);
            double fa = model_brdf_table_f(t, &a), fb = model_brdf_table_f(t, &b);
            double ga = model_brdf_recipe_f(&r, &a), gb = model_brdf_recipe_f(&r, &b);
            worst_table = fmax(worst_table, fabs(fa - fb) / fmax(1e-12, fabs(fa)));
            worst_recipe = fmax(worst_recipe, fabs(ga - gb) / fmax(1e-12, fabs(ga)));
        }
        CHECK_MSG(worst_table < 1e-12, "%s: table not reciprocal, worst relative %.3g", recipes[q], worst_table);
        CHECK_MSG(worst_recipe < 1e-9, "%s: model not reciprocal, worst relative %.3g", recipes[q], worst_recipe);
        for (int d = 0; d < 4; d++) {
            double th = (double[]){ 0, 30, 60, 80 }[d], A = model_brdf_table_albedo(t, th * M_PI / 180, 128);
            CHECK_MSG(A >= 0 && A <= 1.005, "%s: directional albedo %.5f at %g deg", recipes[q], A, th);
        }
        model_brdf_table_free(t);
    }
}

// Known answers of the energy: GGX with multiple scattering reflects ks at every
// incidence (a white furnace; single-scattering GGX alone loses up to ~40 % at
// alpha = 1 near grazing), Lambertian oren-nayar at sigma = 0 reflects its
// albedo, and the PTFE white's reflectance factor at 75 deg is 1 - drop of the
// one at normal incidence.
TEST(brdf_table_energy_known_answers)
{
    model_brdf_table_t *t = tab("ggx-ms alpha=0.6 ks=0.9", NULL);
    for (int d = 0; t && d < 5; d++) {
        double th = (double[]){ 0, 20, 45, 65, 80 }[d];
        CHECK_NEAR(model_brdf_table_albedo(t, th * M_PI / 180, 160), 0.9, 0.005);
    }
    model_brdf_table_free(t);
    model_brdf_recipe_t ss;
    CHECK(model_brdf_recipe_parse("ggx kd=0 ks=1 alpha=1 F0=1", NULL, 0, &ss));
    t = model_brdf_tabulate(&ss);
    if (t) CHECK(model_brdf_table_albedo(t, 80 * M_PI / 180, 160) < 0.8);   // what ggx-ms compensates
    model_brdf_table_free(t);
    t = tab("oren-nayar albedo=0.7 sigma=0", NULL);
    for (int d = 0; t && d < 3; d++)
        CHECK_NEAR(model_brdf_table_albedo(t, (double[]){ 0, 40, 80 }[d] * M_PI / 180, 160), 0.7, 0.002);
    model_brdf_table_free(t);
    model_brdf_recipe_t r;
    CHECK(model_brdf_recipe_parse("ptfe albedo=0.99 drop=0.04", NULL, 0, &r));
    model_cosines_t c0 = model_cosines(N, dir_deg(0, 0), dir_deg(0, 0));
    model_cosines_t c75 = model_cosines(N, dir_deg(75, 0), dir_deg(0, 0));
    double rf0 = model_brdf_recipe_f(&r, &c0) * M_PI, rf75 = model_brdf_recipe_f(&r, &c75) * M_PI;
    CHECK_NEAR(rf0, 0.99, 1e-12);
    CHECK_NEAR(rf75 / rf0, 0.96, 1e-12);
}

// A table of refl's analytic GGX, evaluated at random directions (theta up to
// 80 deg), is within the interpolation tolerance of the analytic value.
TEST(brdf_table_ggx_matches_analytic)
{
    const double p[4] = { 0.2, 0.8, 0.3, 0.5 };
    model_brdf_table_t *t = tab("ggx kd=0.2 ks=0.8 alpha=0.3 F0=0.5", NULL);
    if (!t) return;
    uint64_t seed = 11;
    int bad = 0, n = 2000;
    double worst = 0, sum = 0;
    for (int k = 0; k < n; k++) {
        model_cosines_t c = model_cosines(N, random_dir(&seed, 80), random_dir(&seed, 80));
        double a = model_brdf_eval(MODEL_BRDF_GGX, p, &c, NULL), b = model_brdf_table_eval(t, &c);
        double rel = fabs(a - b) / a;
        worst = fmax(worst, rel);
        sum += rel;
        bad += rel > 0.02;
    }
    CHECK_MSG(bad == 0, "%d of %d directions off by more than 2 %% (worst %.3g)", bad, n, worst);
    CHECK_MSG(sum / n < 0.002, "mean relative error %.3g", sum / n);
    model_brdf_table_free(t);
}

// MERL write/read: every cell back to rounding; the reader of refl fit brdf
// reads the same file; a missing cell (negative) stays missing.
TEST(brdf_table_merl_round_trip)
{
    model_brdf_table_t *t = tab("retro albedo=0.4 kr=0.3 n=8", NULL);
    if (!t) return;
    model_brdf_table_values(t)[12345] = NAN;
    char path[1024];
    snprintf(path, sizeof path, "%s/retro.binary", test_tmpdir());
    CHECK(model_brdf_table_save(t, path));
    model_brdf_table_t *u = model_brdf_table_load(path);
    CHECK(u != NULL);
    if (u) {
        const double *a = model_brdf_table_values_const(t), *b = model_brdf_table_values_const(u);
        size_t bad = 0, N_ = (size_t)MODEL_MERL_TH * MODEL_MERL_TD * MODEL_MERL_PD;
        for (size_t i = 0; i < N_; i++)
            if (isnan(a[i]) ? !isnan(b[i]) : !(fabs(a[i] - b[i]) <= 1e-14 * fmax(1, fabs(a[i])))) bad++;
        CHECK_MSG(bad == 0, "%zu cells differ after the round trip", bad);
        CHECK(strlen(model_brdf_table_sha256(u)) == 64);
        FILE *f = fopen(path, "rb");
        unsigned char h[12] = { 0 };
        CHECK(f && fread(h, 1, 12, f) == 12);
        if (f) fclose(f);
        CHECK(model_brdf_table_sniff(h, 12 + 3 * N_ * sizeof(double)));
        CHECK(!model_brdf_table_sniff(h, 12 + 3 * N_ * sizeof(double) - 8));
    }
    model_brdf_table_free(u);
    model_brdf_table_free(t);
}

// Bad files: the message names the file and what is wrong.
TEST(brdf_table_bad_files)
{
    const char *dir = test_tmpdir();
    char p[1024];
    struct { const char *name; int32_t d[3]; size_t doubles; const char *msg; } cases[] = {
        { "truncated.binary", { 90, 90, 180 }, 1000, "truncated or padded" },
        { "dims.binary", { 90, 90, 360 }, 1000, "dims 90 90 360" },
    };
    for (size_t q = 0; q < 2; q++) {
        snprintf(p, sizeof p, "%s/%s", dir, cases[q].name);
        FILE *f = fopen(p, "wb");
        CHECK(f != NULL);
        if (!f) continue;
        fwrite(cases[q].d, 4, 3, f);
        double z = 0.5;
        for (size_t i = 0; i < cases[q].doubles; i++) fwrite(&z, sizeof z, 1, f);
        fclose(f);
        CHECK(model_brdf_table_load(p) == NULL);
        CHECK_CONTAINS(model_last_error(), p);
        CHECK_CONTAINS(model_last_error(), "not a MERL BRDF file");
        CHECK_CONTAINS(model_last_error(), cases[q].msg);
    }
    const char *txt = test_write("notmerl.binary", "theta_i,phi_i,theta_o,phi_o,R\n");
    CHECK(model_brdf_table_load(txt) == NULL);
    CHECK_CONTAINS(model_last_error(), "notmerl.binary");
    CHECK_CONTAINS(model_last_error(), "not a MERL BRDF file");
    const char *tiny = test_write("tiny.binary", "abc");
    CHECK(model_brdf_table_load(tiny) == NULL);
    CHECK_CONTAINS(model_last_error(), "shorter than its 12-byte header");
    snprintf(p, sizeof p, "%s/absent.binary", dir);
    CHECK(model_brdf_table_load(p) == NULL);
    CHECK_CONTAINS(model_last_error(), "absent.binary");
}

// [material NAME] model = table: generate = RECIPE, table = FILE relative to
// the INI; errors name the INI's file and line.
TEST(brdf_table_materials_ini)
{
    const char *dir = test_tmpdir();
    char sub[1024], bin[1200], ini[1200];
    snprintf(sub, sizeof sub, "%s/mats", dir);
    CHECK(mkdir(sub, 0755) == 0);
    model_brdf_table_t *t = tab("oren-nayar albedo=0.6 sigma=0.4", NULL);
    snprintf(bin, sizeof bin, "%s/on.binary", sub);
    CHECK(t && model_brdf_table_save(t, bin));
    const char *text = "[material gen]\nmodel = table\ngenerate = oren-nayar albedo=0.6 sigma=0.4\n"
                       "[material file]\nmodel = table\ntable = on.binary\n[material plain]\nmodel = lambert\nkd = 0.1\n";
    snprintf(ini, sizeof ini, "%s/m.ini", sub);
    FILE *f = fopen(ini, "w");
    CHECK(f && fputs(text, f) >= 0);
    if (f) fclose(f);
    model_materials_t *m = model_materials_load(ini);
    CHECK(m != NULL);
    if (m && t) {
        const model_material_t *g = model_materials_find(m, "gen"), *fl = model_materials_find(m, "file"),
                               *pl = model_materials_find(m, "plain");
        CHECK(g->table && fl->table && !pl->table);
        model_cosines_t c = model_cosines(N, dir_deg(50, 10), dir_deg(30, 200));
        double want = model_brdf_table_eval(t, &c);
        CHECK(want > 0);
        CHECK_NEAR(model_material_eval(g, &c), want, 1e-15);
        CHECK_NEAR(model_material_eval(fl, &c), want, 1e-14);
        CHECK_NEAR(model_material_eval(pl, &c), 0.1 * c.nl, 1e-15);
        // the Lambertian stand-in: the table's albedo at normal incidence
        CHECK(g->model == MODEL_BRDF_LAMBERT);
        CHECK_NEAR(g->p[0] * M_PI, model_brdf_table_albedo(t, 0, 64), 1e-12);
    }
    model_materials_free(m);
    model_brdf_table_free(t);
    static const struct { const char *text, *msg; } bad[] = {
        { "[material a]\nmodel = table\n", "m.ini:1: material 'a' (model table) needs exactly one of" },
        { "[material a]\nmodel = table\ntable = x.binary\ngenerate = ptfe\n", "needs exactly one of" },
        { "[material a]\nmodel = table\nkd = 0.3\n", "m.ini:3: unknown key 'kd'" },
        { "[material a]\nmodel = table\ngenerate = phong n=3\n", "m.ini:3: unknown BRDF generator 'phong'" },
        { "[material a]\nmodel = table\ngenerate = ptfe drop=0.9\n", "m.ini:3: BRDF generator ptfe: drop = '0.9'" },
        { "[material a]\nmodel = table\ngenerate = ggx2 albedo=0.5 ks1=0.5 ks2=0.5\n", "add up to 1.5" },
        { "[material a]\nmodel = table\ntable = missing.binary\n", "m.ini:3: material 'a': " },
    };
    for (size_t q = 0; q < sizeof bad / sizeof bad[0]; q++) {
        f = fopen(ini, "w");
        CHECK(f && fputs(bad[q].text, f) >= 0);
        if (f) fclose(f);
        CHECK(model_materials_load(ini) == NULL);
        CHECK_CONTAINS(model_last_error(), bad[q].msg);
    }
    CHECK_CONTAINS(model_last_error(), "missing.binary");
}

// The renderer on a plane with a table material: every pixel equals the direct
// evaluation of the table (lamp, inverse square, cosines) to 1e-6.
TEST(brdf_table_render_plane_matches_direct)
{
    fx_render_t F;
    if (!fx_render_open(&F, fx_plane_d3d(5000, NULL, NULL),
                        "[material plane]\nmodel = table\ngenerate = ggx2 albedo=0.3 ks1=0.3 alpha1=0.1 ks2=0.3 "
                        "alpha2=0.4\n",
                        "[lamp a]\nposition_mm = 30 -20 400\nintensity = 1e6\n", 96, 72, 90, v3(100, -300, 500),
                        v3(0, 0, 0)))
        goto done;
    int W = F.ph.W, H = F.ph.H;
    float *P = malloc(sizeof(float) * W * H);
    int32_t *face = malloc(sizeof(int32_t) * W * H);
    uint8_t *lit = malloc((size_t)W * H);
    model_shading_t sh = model_shading_default();
    CHECK(model_render(F.t, F.ph.cam, F.l, F.mres, &sh, P, face, lit));
    const model_material_t *mat = F.mres[0];
    CHECK(mat->table != NULL);
    model_vec3_t L = F.l->lamps[0].position_mm;
    int bad = 0;
    double worst = 0, lo = INFINITY, hi = 0;
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++) {
            int i = y * W + x;
            model_vec3_t d = fx_pinhole_ray(&F.ph, x, y);
            model_vec3_t p = v3_add(F.ph.C, v3_scale(d, -F.ph.C.z / d.z));
            model_vec3_t dl = v3_sub(L, p);
            double dist = v3_norm(dl);
            model_cosines_t c = model_cosines(N, v3_scale(dl, 1 / dist), v3_scale(d, -1 / v3_norm(d)));
            double expect = sh.Pa + sh.kc * 1e6 * model_brdf_table_eval(mat->table, &c) / (dist * dist);
            double rel = fabs(P[i] - expect) / expect;
            worst = fmax(worst, rel);
            bad += rel > 1e-5;
            lo = fmin(lo, P[i]);
            hi = fmax(hi, P[i]);
        }
    CHECK_MSG(bad == 0, "%d pixels off by more than 1e-5 relative (worst %.3g)", bad, worst);
    CHECK(hi > 2 * lo);   // the specular lobes are in the view
    free(P);
    free(face);
    free(lit);
done:
    fx_render_close(&F);
}

// refl brdf tabulate: writes a table the loader reads; usage errors exit 2.
TEST(brdf_tabulate_command)
{
    char out[1024];
    snprintf(out, sizeof out, "%s/t.binary", test_tmpdir());
    char *ok[] = { "brdf", "tabulate", "--model", "ptfe", "drop=0.05", "-o", out, NULL };
    CHECK(model_cmd_brdf(7, ok) == 0);
    model_brdf_table_t *t = model_brdf_table_load(out);
    CHECK(t != NULL);
    model_brdf_recipe_t r;
    CHECK(model_brdf_recipe_parse("ptfe drop=0.05", NULL, 0, &r));
    model_cosines_t c = model_cosines(N, dir_deg(60, 0), dir_deg(20, 90));
    if (t) CHECK_NEAR(model_brdf_table_f(t, &c), model_brdf_recipe_f(&r, &c), 1e-3 * model_brdf_recipe_f(&r, &c));
    model_brdf_table_free(t);
    char *bad[] = { "brdf", "tabulate", "--model", "ptfe", "colour=3", "-o", out, NULL };
    CHECK(model_cmd_brdf(7, bad) == 2);
    char *nomodel[] = { "brdf", "tabulate", "-o", out, NULL };
    CHECK(model_cmd_brdf(4, nomodel) == 2);
    char *unknown[] = { "brdf", "frobnicate", NULL };
    CHECK(model_cmd_brdf(2, unknown) == 2);
}
