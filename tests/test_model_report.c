// tests/test_model_report.c — what every command's output shares (model/base/report.c, the dispatcher): the
// provenance's command as typed, no empty output directory left by a failed run, one message naming the file
// once; and the demo's summary page (scripts/demo_index.py) on a small OUTDIR made here.
#include <glib.h>
#include <glib/gstdio.h>
#include <jansson.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include "model/model.h"
#include "model/base/report.h"
#include "model/base/vec.h"
#include "tests/test.h"

static int count(const char *hay, const char *needle)
{
    int n = 0;
    for (const char *p = hay; p && (p = strstr(p, needle)); p += strlen(needle)) n++;
    return n;
}

// A subcommand's tail of argv gives the whole line, as typed; an argv of its own is taken as it is.
TEST(model_provenance_command_whole_line)
{
    char *whole[] = { "refl", "calib", "geometry", "--images", "a b/*.png", "-o", "out", NULL };
    model_set_command_line(7, whole);
    char *c = model_command_line(5, whole + 2);   // what calib geometry's options see
    CHECK(c && !strcmp(c, "refl calib geometry --images 'a b/*.png' -o out"));
    g_free(c);
    c = model_command_line(6, whole + 1);         // the fit/export style: argc + 1, argv - 1
    CHECK(c && !strcmp(c, "refl calib geometry --images 'a b/*.png' -o out"));
    g_free(c);
    char *own[] = { "lamps", "-o", "x", NULL };   // not the tail of the whole line: as given
    c = model_command_line(3, own);
    CHECK(c && !strcmp(c, "refl lamps -o x"));
    g_free(c);
    c = model_command_line(2, whole + 2);         // a head, not the tail: as given
    CHECK(c && !strcmp(c, "refl geometry --images"));
    g_free(c);
    json_t *p = model_provenance(5, whole + 2);
    CHECK_CONTAINS(json_string_value(json_object_get(p, "command")), "refl calib geometry --images");
    json_decref(p);
    model_set_command_line(0, NULL);
}

// bin/refl records a subcommand's whole line: refl fit brdf on a small CSV (a Lambertian surface).
TEST(model_provenance_command_as_typed)
{
    GString *g = g_string_new("theta_i,phi_i,theta_o,phi_o,f_r\n");
    for (int i = 0; i < 8; i++)
        for (int o = 0; o < 8; o++)
            for (int ph = 0; ph < 4; ph++)
                g_string_append_printf(g, "%d,0,%d,%d,%.9f\n", 5 + 10 * i, 5 + 10 * o, 45 * ph, 0.4 / M_PI);
    const char *csv = test_write("lambert.csv", g->str);
    g_string_free(g, TRUE);
    const char *priors = test_path("priors.json");
    char *out = NULL, *err = NULL;
    int rc = test_refl_run(60, &out, &err, "fit", "brdf", csv, "--model", "lambert", "-o", priors, NULL);
    CHECK_MSG(rc == 0, "refl fit brdf: exit %d\n%s", rc, err ? err : "");
    json_t *j = json_load_file(priors, 0, NULL);
    const char *cmd = json_string_value(json_object_get(json_object_get(j, "provenance"), "command"));
    CHECK_MSG(cmd && g_str_has_prefix(cmd, "refl fit brdf ") && strstr(cmd, "--model lambert"), "command: %s",
              cmd ? cmd : "(none)");
    json_decref(j);
    free(out);
    free(err);
}

// A failed run leaves no empty output directory (and keeps one that was there, and whatever has a file).
TEST(model_failed_run_removes_empty_output_dirs)
{
    char *out = NULL, *err = NULL;
    const char *geo = test_path("geo");
    int rc = test_refl_run(60, &out, &err, "calib", "geometry", "--images", test_path("no-such-dir"), "-o", geo,
                           NULL);
    CHECK(rc == 1);
    CHECK_MSG(!g_file_test(geo, G_FILE_TEST_EXISTS), "%s is left after the failed run", geo);
    CHECK_MSG(count(err, "no-such-dir") == 1, "the directory named %d times:\n%s", count(err, "no-such-dir"),
              err ? err : "");
    free(out);
    free(err);
    // an output directory that was there before stays
    const char *pre = test_path("pre");
    CHECK(g_mkdir(pre, 0755) == 0);
    rc = test_refl_run(60, &out, &err, "calib", "geometry", "--images", test_path("no-such-dir"), "-o", pre, NULL);
    CHECK(rc == 1);
    CHECK(g_file_test(pre, G_FILE_TEST_IS_DIR));
    free(out);
    free(err);
    // the library call itself: made, then removed only where empty
    char *a = g_build_filename(test_tmpdir(), "m1", "m2", "m3", NULL), *b = g_build_filename(test_tmpdir(), "m1",
                                                                                              "keep", NULL);
    model_remove_made_empty_dirs();
    CHECK(model_mkdir_p(a) && model_mkdir_p(b));
    char *f = g_build_filename(b, "file", NULL);
    CHECK(g_file_set_contents(f, "x", 1, NULL));
    CHECK(model_remove_made_empty_dirs() == 2);   // m3 and m2; m1 holds keep/file
    CHECK(!g_file_test(a, G_FILE_TEST_EXISTS) && g_file_test(f, G_FILE_TEST_EXISTS));
    g_free(a), g_free(b), g_free(f);
}

// refl fit material on a directory that is no session: one message, the directory named once.
TEST(model_error_names_file_once)
{
    char *out = NULL, *err = NULL;
    const char *nos = test_path("nosession");
    CHECK(g_mkdir(nos, 0755) == 0);
    int rc = test_refl_run(60, &out, &err, "fit", "material", nos, "--scene", test_path("x.d3d"), "--calib",
                           test_path("calib"), "-o", test_path("fm/p.json"), "--report", test_path("fmrep"), NULL);
    CHECK(rc == 1);
    CHECK_CONTAINS(err, "not a capture session");
    CHECK_MSG(count(err, nos) == 1, "the directory named %d times:\n%s", count(err, nos), err ? err : "");
    CHECK(!g_file_test(test_path("fm"), G_FILE_TEST_EXISTS) && !g_file_test(test_path("fmrep"), G_FILE_TEST_EXISTS));
    free(out);
    free(err);
}

// scripts/demo_index.py on a small OUTDIR: a short summary linking chain.html and every material's fit report,
// the log linked, not copied in.
TEST(model_demo_index_summary)
{
    const char *d = test_tmpdir();
    char *p;
    GString *log = g_string_new("");
    for (int i = 0; i < 2000; i++) g_string_append_printf(log, "log line %d of a long run\n", i);
    p = g_build_filename(d, "demo.log", NULL);
    CHECK(g_file_set_contents(p, log->str, -1, NULL));
    g_free(p);
    g_string_free(log, TRUE);
    static const char *const mats[] = { "glossy", "plywood", "steel" };
    for (int k = 0; k < 3; k++) {
        char *name = g_strdup_printf("priors_%s.json", mats[k]);
        // steel's ks barely constrained (1-sigma 59 % of its value), glossy's tight
        char *text = g_strdup_printf("{\"materials\": [{\"name\": \"%s\", \"model\": \"ggx\", \"rms\": 0.001, "
                                     "\"rms_over_noise\": %.2f, \"parameters\": [{\"name\": \"ks\", \"mean\": %s, "
                                     "\"std\": %s, \"lo\": 0, \"hi\": 0.684, \"barely_constrained\": %s}]}]}", mats[k],
                                     1.1 + k, k == 2 ? "0.2474" : "0.5", k == 2 ? "0.1456" : "0.01",
                                     k == 2 ? "true" : "false");
        p = g_build_filename(d, name, NULL);
        CHECK(g_file_set_contents(p, text, -1, NULL));
        g_free(p), g_free(name), g_free(text);
        if (k == 2) continue;   // steel's report is missing: said so
        char *rd = g_strdup_printf("%s/fit_%s", d, mats[k]);
        CHECK(g_mkdir(rd, 0755) == 0);
        p = g_build_filename(rd, "report.html", NULL);
        CHECK(g_file_set_contents(p, "<html></html>", -1, NULL));
        g_free(p), g_free(rd);
    }
    p = g_build_filename(d, "chain.html", NULL);
    CHECK(g_file_set_contents(p, "<!DOCTYPE html><html></html>", -1, NULL));
    g_free(p);
    p = g_build_filename(d, "chain.json", NULL);
    CHECK(g_file_set_contents(p, "{\"summary\": {\"entries\": 7, \"with_sigma\": 5, \"z_over_3\": [\"lamp_x\"], "
                                 "\"wrong_verdicts\": 0}}", -1, NULL));
    g_free(p);
    char *script = g_build_filename(test_srcdir(), "scripts", "demo_index.py", NULL);
    const char *argv[] = { "/usr/bin/python3", script, d, "9.9", NULL };
    char *out = NULL, *err = NULL;
    int rc = test_run(argv, 60, &out, &err);
    CHECK_MSG(rc == 0, "demo_index.py: exit %d\n%s", rc, err ? err : "");
    char *html = NULL;
    p = g_build_filename(d, "index.html", NULL);
    CHECK(g_file_get_contents(p, &html, NULL, NULL));
    g_free(p);
    CHECK(count(html, "\n") < 120);
    CHECK_CONTAINS(html, "href=\"chain.html\"");
    CHECK_CONTAINS(html, "href=\"fit_glossy/report.html\"");
    CHECK_CONTAINS(html, "href=\"fit_plywood/report.html\"");
    CHECK(!strstr(html, "href=\"fit_steel/report.html\""));
    CHECK_CONTAINS(html, "fit report (missing)");
    CHECK_CONTAINS(html, "href=\"demo.log\"");
    CHECK(!strstr(html, "log line 1999"));
    CHECK_CONTAINS(html, "1 off by more than 3 sigma (lamp_x)");
    CHECK_CONTAINS(html, "3.10 &times; the noise");
    // the page opens with its headline: the miss against the truth and the barely constrained parameter in red
    CHECK(strstr(html, "id=\"headline\"") && strstr(html, "<h2>Calibrations") &&
          strstr(html, "id=\"headline\"") < strstr(html, "<h2>Calibrations"));
    CHECK_CONTAINS(html, "font-weight:bold\">against the truth: 7 figures, 5 with a stated 1-sigma; 1 off by more than "
                         "3 sigma (lamp_x)");
    CHECK_CONTAINS(html, "font-weight:bold\">steel: ks = 0.2474 ± 0.15 barely constrained (1-sigma 59 % of the value");
    CHECK(!strstr(html, "glossy: ks = 0.5 ± 0.01 barely"));
    free(html);
    free(out);
    free(err);
    g_free(script);
}

// scripts/fit_material_report.py on a small samples.csv made here (a Lambertian-plus-lobe surface seen in and
// out of the plane of incidence, with albedo cells): the polar lobes, the cells' map and every other plot.
TEST(fit_material_report_plots)
{
    const char *d = test_tmpdir();
    GString *g = g_string_new("# samples\nx_px,y_px,step,lamp,theta_i_deg,theta_o_deg,theta_h_deg,R_meas,R_fit,"
                              "lamp_name,phi_deg,sigma_R,albedo_factor,x0_mm,y0_mm,z0_mm\n");
    model_rng_t rng = model_rng(7, 1);
    for (int i = 0; i < 1200; i++) {
        double ti = 30 + 30 * model_rng_uniform(&rng), to = 70 * model_rng_uniform(&rng);
        double phi = (i % 3 == 0) ? 180 * model_rng_uniform(&rng) : (i % 3 == 1 ? 178 : 3);
        double th = fabs(ti - (phi > 90 ? to : -to)) / 2, fit = 0.1 * cos(ti * M_PI / 180) + 0.05 * exp(-th * th / 50);
        int cell = i % 40;
        double fac = 0.95 + 0.1 * cell / 39.0;
        g_string_append_printf(g, "%d,%d,%d,%d,%.3f,%.3f,%.3f,%.6g,%.6g,%s,%.2f,%.3g,%.4f,%.1f,%.1f,0\n",
                               500 + i % 30, 400 + i / 30, i % 8, i % 2, ti, to, th,
                               fit * (1 + 0.01 * model_rng_gauss(&rng)), fit, i % 2 ? "west" : "east", phi,
                               0.01 * fit, fac, (double)(cell % 8) * 2, (double)(cell / 8) * 2);
    }
    char *p = g_build_filename(d, "samples.csv", NULL);
    CHECK(g_file_set_contents(p, g->str, -1, NULL));
    g_free(p);
    g_string_truncate(g, 0);
    g_string_append(g, "theta_i_deg,theta_o_deg,R_fit\n");   // the model's in-plane lobes, as refl writes them
    for (int ti = 0; ti < 90; ti++)
        for (int to = -89; to <= 89; to++) {
            double th = abs(ti - to) / 2.0;
            g_string_append_printf(g, "%d,%d,%.6g\n", ti, to, 0.1 * cos(ti * M_PI / 180) + 0.05 * exp(-th * th / 50));
        }
    p = g_build_filename(d, "lobes_fit.csv", NULL);
    CHECK(g_file_set_contents(p, g->str, -1, NULL));
    g_free(p);
    g_string_free(g, TRUE);
    char *script = g_build_filename(test_srcdir(), "scripts", "fit_material_report.py", NULL);
    const char *argv[] = { "/usr/bin/python3", script, d, "ggx", "0.1,0.05", NULL };
    char *out = NULL, *err = NULL;
    int rc = test_run(argv, 120, &out, &err);
    CHECK_MSG(rc == 0, "fit_material_report.py: exit %d\n%s", rc, err ? err : "");
    static const char *const pngs[] = { "polar.png", "lobes.png", "residual_maps.png", "albedo_cells.png",
                                        "models.png" };
    for (int k = 0; k < 5; k++) {
        p = g_build_filename(d, pngs[k], NULL);
        struct stat st;
        CHECK_MSG(stat(p, &st) == 0 && st.st_size > 10000, "%s missing or empty", pngs[k]);
        g_free(p);
    }
    free(out);
    free(err);
    g_free(script);
}

// A page's text never shows a negative zero ("-0.00 deg"); other minus signs, dates and names stay.
TEST(model_html_no_negative_zero)
{
    const char *path = test_path("page.html");
    FILE *f = model_html_begin(path, "t", NULL);
    CHECK(f != NULL);
    if (!f) return;
    model_html_para(f, "angle %.2f deg, tilt %.1f deg, offset %g px, %.2f mm, on 2026-00-01, x-0, 1e-00", -0.001,
                    -0.04, -0.0, -0.5);
    const char *rows[] = { "-0.000|-0.25", NULL };
    model_html_table(f, "a|b", rows, 1);
    model_html_figure(f, "x.png", "turned -0.0 deg");
    CHECK(model_html_end(f, path));
    char *html = NULL;
    CHECK(g_file_get_contents(path, &html, NULL, NULL));
    CHECK_CONTAINS(html, "angle 0.00 deg, tilt 0.0 deg, offset 0 px, -0.50 mm, on 2026-00-01, x-0, 1e-00");
    CHECK_CONTAINS(html, "<td>0.000</td><td>-0.25</td>");
    CHECK_CONTAINS(html, "<figcaption>turned 0.0 deg</figcaption>");
    g_free(html);
}

// The headline box: its items in order, a "!" item a miss (red, the "!" dropped), text escaped; the
// provenance's inputs folded under a summary that counts them.
TEST(model_html_headline_and_folded_inputs)
{
    const char *path = test_path("headline.html");
    json_t *prov = json_pack("{s:s,s:s,s:s,s:[{s:s,s:s,s:s},{s:s,s:s,s:s}]}", "refl_version", "9.9", "date_utc",
                             "x", "command", "refl t", "inputs", "role", "a", "path", "/p/a", "sha256", "00",
                             "role", "b", "path", "/p/b", "sha256", "11");
    FILE *f = model_html_begin(path, "t", prov);
    json_decref(prov);
    CHECK(f != NULL);
    if (!f) return;
    const char *items[] = { "K = 0.25 ± 0.001 DN/e-", "!view 90°: 90.0 %, 5.0 points short of 95 %", "a < b" };
    model_html_headline(f, "Headline", items, 3);
    CHECK(model_html_end(f, path));
    char *html = NULL;
    CHECK(g_file_get_contents(path, &html, NULL, NULL));
    CHECK_CONTAINS(html, "<details><summary>2 inputs: paths and sha256</summary>");
    CHECK_CONTAINS(html, "<li>K = 0.25 ± 0.001 DN/e-</li>");
    CHECK_CONTAINS(html, "<li class=\"miss\">view 90°: 90.0 %, 5.0 points short of 95 %</li>");
    CHECK_CONTAINS(html, "<li>a &lt; b</li>");
    CHECK(strstr(html, "</details>") && strstr(html, "id=\"headline\"") &&
          strstr(html, "</details>") < strstr(html, "id=\"headline\""));
    g_free(html);
}
