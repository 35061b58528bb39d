// tests/test_fit_export.c — `refl export material` (fit/material/export.c).
//
// - MERL: written, read back by refl's reader (model/brdf/table.c): every cell
//   equals the model's f_r at the cell's centre; the stated error is the
//   table's interpolation against the model (small, not zero).
// - glTF: the file has the schema's required fields (asset.version "2.0";
//   materials[] with pbrMetallicRoughness factors in range, the extensions in
//   extensionsUsed); roughnessFactor = sqrt(alpha), specularFactor = ks, the
//   F0 through specularColorFactor / KHR_materials_ior; the stated Ngan error
//   equals the one this test computes from the file's numbers with glTF's
//   BRDF written out here (the glTF specification's Appendix B with
//   KHR_materials_specular: D, height-correlated V, F = s (F0 + (1 - F0)
//   (1 - v.h)^5), (1 - F) base/pi), not refl's code; a material of no diffuse
//   part converts exactly.
// - Mitsuba: the XML parsed by python3's xml.etree: one <bsdf> per material
//   with the plugin and parameters expected (lambert: the diffuse plugin,
//   reflectance pi kd, exact); the chosen plugin's error is the smaller.
// - Errors: an unknown format, a missing file, not a priors file, an unknown
//   material, several materials for MERL.
#define _GNU_SOURCE
#include <glib.h>
#include <jansson.h>
#include <stdlib.h>
#include <unistd.h>

#include "fit/material/export.h"
#include "model/model.h"
#include "model/base/report.h"
#include "tests/test.h"

static const char PRIORS[] =
    "{\"format\": \"refl priors 1\", \"materials\": [\n"
    " {\"name\": \"glossy\", \"model\": \"ggx\", \"parameters\": [{\"name\": \"kd\", \"mean\": 0.45, \"std\": 0.01},"
    "  {\"name\": \"ks\", \"mean\": 0.8, \"std\": 0.01}, {\"name\": \"alpha\", \"mean\": 0.15, \"std\": 0.01},"
    "  {\"name\": \"F0\", \"mean\": 0.03, \"std\": 0.01}]},\n"
    " {\"name\": \"steel\", \"model\": \"ggx\", \"parameters\": [{\"name\": \"kd\", \"mean\": 0, \"std\": 0.01},"
    "  {\"name\": \"ks\", \"mean\": 0.9, \"std\": 0.01}, {\"name\": \"alpha\", \"mean\": 0.3, \"std\": 0.01},"
    "  {\"name\": \"F0\", \"mean\": 0.6, \"std\": 0.01}]},\n"
    " {\"name\": \"wood\", \"model\": \"torrance_sparrow\", \"parameters\": [{\"name\": \"kd\", \"mean\": 0.1, "
    "\"std\": 0.01}, {\"name\": \"ks\", \"mean\": 0.05, \"std\": 0.01}, {\"name\": \"ns\", \"mean\": 20, \"std\": 1},"
    "  {\"name\": \"F0\", \"mean\": 0.04, \"std\": 0.01}]},\n"
    " {\"name\": \"matte\", \"model\": \"lambert\", \"parameters\": [{\"name\": \"kd\", \"mean\": 0.2, \"std\": 0.01}]}\n"
    "]}\n";

static json_t *load_json(const char *path)
{
    json_error_t je;
    json_t *j = json_load_file(path, 0, &je);
    CHECK_MSG(j != NULL, "%s: %s", path, je.text);
    return j;
}

static double jget(json_t *o, const char *key)
{
    return json_number_value(json_object_get(o, key));
}

TEST(fit_export_merl_read_back_by_refl)
{
    const char *pr = test_write("priors.json", PRIORS), *out = test_path("glossy.binary");
    char *o = NULL, *e = NULL;
    int rc = test_refl_run(120, &o, &e, "export", "material", pr, "--format", "merl", "--material", "glossy", "-o",
                           out, NULL);
    CHECK_MSG(rc == 0, "exit %d: %s", rc, e ? e : "");
    CHECK_CONTAINS(o, "glossy (ggx) as merl: Ngan error");
    free(o), free(e);
    model_brdf_table_t *t = model_brdf_table_load(out);
    CHECK(t != NULL);
    if (!t) return;
    const double p[4] = { 0.45, 0.8, 0.15, 0.03 };
    const double *v = model_brdf_table_values_const(t);
    double worst = 0;
    long n = 0;
    for (int i = 0; i < MODEL_MERL_TH; i++)
        for (int j = 0; j < MODEL_MERL_TD; j++)
            for (int k = 0; k < MODEL_MERL_PD; k++) {
                model_cosines_t c;
                model_brdf_table_cell(i, j, k, &c);
                double want = c.nl > 0 && c.nv > 0 ? model_brdf_eval(MODEL_BRDF_GGX, p, &c, NULL) / c.nl : 0;
                double got = v[((size_t)i * MODEL_MERL_TD + j) * MODEL_MERL_PD + k];
                worst = fmax(worst, fabs(got - want) / fmax(fabs(want), 1e-300));
                n += want > 0;
            }
    fprintf(stderr, "  MERL read back: %ld cells above the horizon, largest relative difference %.2e\n", n, worst);
    CHECK(n > 1000000);
    CHECK(worst < 1e-12);
    model_brdf_table_free(t);
    char side[4096];
    snprintf(side, sizeof side, "%s.conversion.json", out);
    json_t *j = load_json(side);
    json_t *m = json_array_get(json_object_get(j, "materials"), 0);
    CHECK(!strcmp(json_string_value(json_object_get(m, "target")) ?: "", "merl"));
    double err = jget(m, "ngan_error"), rel = jget(m, "ngan_error_relative");
    fprintf(stderr, "  MERL: stated interpolation error %.3g 1/sr (%.3f %%)\n", err, 100 * rel);
    CHECK(err > 0 && rel < 0.01);
    CHECK(json_is_object(json_object_get(j, "provenance")));
    int version = 0;
    CHECK_MSG(model_json_format_check(j, side, "refl-export", 1, &version) && version == 1, "%s", model_last_error());
    json_decref(j);
}

// glTF's BRDF (metallic 0) from the file's numbers, written from the glTF
// specification (Appendix B) and KHR_materials_specular, with its own D and V.
static double gltf_brdf(double base, double rough, double s, double col, double ior, const model_cosines_t *c)
{
    double a = rough * rough, a2 = a * a, nl = c->nl, nv = c->nv;
    double t = c->nh * c->nh * (a2 - 1) + 1, D = a2 / (M_PI * t * t);
    double V = 0.5 / (nl * sqrt(nv * nv * (1 - a2) + a2) + nv * sqrt(nl * nl * (1 - a2) + a2));
    double f0 = ior == 0 ? 1 : pow((ior - 1) / (ior + 1), 2) * col;
    double F = s * (f0 + (1 - f0) * pow(1 - c->vh, 5));
    return (1 - F) * base / M_PI + F * D * V;
}

// The Ngan error of the file's material against refl's model, over the
// directions fit/material/export.h describes (16 x 32 x 64, below 85 deg).
static double gltf_error(json_t *mat, model_brdf_t model, const double *p)
{
    json_t *pbr = json_object_get(mat, "pbrMetallicRoughness"), *ext = json_object_get(mat, "extensions");
    json_t *sp = json_object_get(ext, "KHR_materials_specular"), *io = json_object_get(ext, "KHR_materials_ior");
    double base = json_number_value(json_array_get(json_object_get(pbr, "baseColorFactor"), 0));
    double rough = jget(pbr, "roughnessFactor"), s = jget(sp, "specularFactor");
    double col = json_number_value(json_array_get(json_object_get(sp, "specularColorFactor"), 0));
    double ior = io ? jget(io, "ior") : 1.5;
    const double cmin = cos(85 * M_PI / 180);
    double ss = 0;
    int n = 0;
    for (int i = 0; i < 16; i++) {
        double ci = 1 - (i + 0.5) / 16 * (1 - cmin), si = sqrt(1 - ci * ci);
        for (int o = 0; o < 32; o++) {
            double co = 1 - (o + 0.5) / 32 * (1 - cmin), so = sqrt(1 - co * co);
            for (int k = 0; k < 64; k++) {
                double ph = 2 * M_PI * (k + 0.5) / 64;
                model_vec3_t l = { si, 0, ci }, v = { so * cos(ph), so * sin(ph), co };
                model_cosines_t c = model_cosines((model_vec3_t){ 0, 0, 1 }, l, v);
                double d = gltf_brdf(base, rough, s, col, ior, &c) * ci - model_brdf_eval(model, p, &c, NULL);
                ss += d * d;
                n++;
            }
        }
    }
    return sqrt(ss / n);
}

TEST(fit_export_gltf_fields_and_stated_error)
{
    const char *pr = test_write("priors.json", PRIORS), *out = test_path("m.gltf");
    char *o = NULL, *e = NULL;
    int rc = test_refl_run(120, &o, &e, "export", "material", pr, "--format", "gltf", "-o", out, NULL);
    CHECK_MSG(rc == 0, "exit %d: %s", rc, e ? e : "");
    CHECK_CONTAINS(o, "wood (torrance_sparrow) as gltf");
    CHECK_CONTAINS(o, "via ggx");
    free(o), free(e);
    json_t *j = load_json(out);
    if (!j) return;
    CHECK(!strcmp(json_string_value(json_object_get(json_object_get(j, "asset"), "version")) ?: "", "2.0"));
    json_t *used = json_object_get(j, "extensionsUsed"), *mats = json_object_get(j, "materials");
    CHECK(json_array_size(mats) == 4);
    static const struct { const char *name; int model; double p[4]; } want[] = {
        { "glossy", MODEL_BRDF_GGX, { 0.45, 0.8, 0.15, 0.03 } }, { "steel", MODEL_BRDF_GGX, { 0, 0.9, 0.3, 0.6 } },
        { "wood", MODEL_BRDF_TORRANCE_SPARROW, { 0.1, 0.05, 20, 0.04 } }, { "matte", MODEL_BRDF_LAMBERT, { 0.2 } },
    };
    for (size_t i = 0; i < json_array_size(mats) && i < 4; i++) {
        json_t *m = json_array_get(mats, i), *pbr = json_object_get(m, "pbrMetallicRoughness");
        json_t *ext = json_object_get(m, "extensions"), *conv = json_object_get(json_object_get(m, "extras"),
                                                                                 "refl_conversion");
        CHECK(!strcmp(json_string_value(json_object_get(m, "name")) ?: "", want[i].name));
        json_t *bc = json_object_get(pbr, "baseColorFactor");
        CHECK(json_array_size(bc) == 4);
        for (int k = 0; k < 4; k++) {
            double x = json_number_value(json_array_get(bc, k));
            CHECK(x >= 0 && x <= 1);
        }
        CHECK(jget(pbr, "metallicFactor") == 0);
        double r = jget(pbr, "roughnessFactor");
        CHECK(r >= 0 && r <= 1);
        // every extension a material uses is in extensionsUsed
        const char *key;
        json_t *val;
        json_object_foreach(ext, key, val) {
            bool listed = false;
            for (size_t u = 0; u < json_array_size(used); u++)
                listed |= !strcmp(json_string_value(json_array_get(used, u)), key);
            CHECK_MSG(listed, "%s not in extensionsUsed", key);
        }
        json_t *sp = json_object_get(ext, "KHR_materials_specular");
        CHECK(sp != NULL);
        double s = jget(sp, "specularFactor"), col = json_number_value(json_array_get(json_object_get(sp,
                                                                              "specularColorFactor"), 0));
        CHECK(s >= 0 && s <= 1 && col >= 0 && col <= 1);
        if (want[i].model == MODEL_BRDF_GGX) {
            CHECK_NEAR(r, sqrt(want[i].p[2]), 1e-9);
            CHECK_NEAR(s, want[i].p[1], 1e-9);
            json_t *io = json_object_get(ext, "KHR_materials_ior");
            double ior = io ? jget(io, "ior") : 1.5;
            CHECK_NEAR(pow((ior - 1) / (ior + 1), 2) * col, want[i].p[3], 1e-8);
        }
        double mine = gltf_error(m, (model_brdf_t)want[i].model, want[i].p), stated = jget(conv, "ngan_error");
        fprintf(stderr, "  glTF %s: stated Ngan error %.4g 1/sr, recomputed from the file %.4g\n", want[i].name,
                stated, mine);
        CHECK_NEAR(stated, mine, 1e-5 * mine + 1e-10);   // the file's numbers have 10 digits
        CHECK(jget(conv, "ngan_error_relative") < (i == 2 ? 0.05 : 0.02));
    }
    json_decref(j);
}

TEST(fit_export_gltf_specular_exact)
{
    // no diffuse part: glTF's specular lobe is refl's ggx exactly
    verify_prior_t m = { .name = "mirrorish", .model = MODEL_BRDF_GGX, .np = 4, .mean = { 0, 0.7, 0.2, 0.3 } };
    fit_export_material_t e;
    CHECK(fit_export_convert(&m, FIT_EXPORT_GLTF, &e));
    CHECK(e.q[0] < 1e-12);
    CHECK(e.rel_error < 1e-12);
    model_cosines_t c = model_cosines((model_vec3_t){ 0, 0, 1 }, (model_vec3_t){ 0.6, 0, 0.8 },
                                      (model_vec3_t){ -0.48, 0.36, 0.8 });
    CHECK_REL(fit_export_eval(&e, &c) * c.nl, model_brdf_eval(MODEL_BRDF_GGX, m.mean, &c, NULL), 1e-12);
}

static const char XML_PY[] =
    "import sys, xml.etree.ElementTree as ET\n"
    "root = ET.parse(sys.argv[1]).getroot()\n"
    "assert root.tag == 'scene' and root.get('version').startswith('3.'), root.tag\n"
    "for b in root.findall('bsdf'):\n"
    "    p = {c.get('name'): (c.tag, c.get('value')) for c in b}\n"
    "    print(b.get('id'), b.get('type'), ' '.join('%s=%s:%s' % (k, t, v.replace(' ', '')) for k, (t, v) in "
    "sorted(p.items())))\n";

TEST(fit_export_mitsuba_xml_parsed)
{
    const char *pr = test_write("priors.json", PRIORS), *out = test_path("m.xml");
    char *o = NULL, *e = NULL;
    int rc = test_refl_run(120, &o, &e, "export", "material", pr, "--format", "mitsuba", "-o", out, NULL);
    CHECK_MSG(rc == 0, "exit %d: %s", rc, e ? e : "");
    free(o), free(e);
    const char *argv[] = { "/usr/bin/python3", test_write("x.py", XML_PY), out, NULL };
    rc = test_run(argv, 60, &o, &e);
    CHECK_MSG(rc == 0, "python3 xml.etree: exit %d: %s", rc, e ? e : "");
    fprintf(stderr, "%s", o ? o : "");
    char **lines = g_strsplit(o ? o : "", "\n", -1);
    CHECK(g_strv_length(lines) == 5);
    for (int i = 0; i < 4 && lines[i]; i++) {
        if (i == 3) {   // lambert: the diffuse plugin, reflectance = pi kd
            char want[200];
            snprintf(want, sizeof want, "matte diffuse reflectance=rgb:%.9g,%.9g,%.9g", M_PI * 0.2, M_PI * 0.2,
                     M_PI * 0.2);
            CHECK_CONTAINS(lines[i], want);
            continue;
        }
        CHECK(g_str_has_prefix(lines[i], (const char *[]){ "glossy rough", "steel rough", "wood rough" }[i]));
        CHECK_CONTAINS(lines[i], "distribution=string:ggx");
        CHECK_CONTAINS(lines[i], "alpha=float:");
        CHECK_CONTAINS(lines[i], "specular_reflectance=rgb:");
        if (strstr(lines[i], "roughplastic"))
            CHECK(strstr(lines[i], "int_ior=float:") && strstr(lines[i], "diffuse_reflectance=rgb:") &&
                  strstr(lines[i], "nonlinear=boolean:false"));
        else CHECK(strstr(lines[i], "roughconductor") && strstr(lines[i], "eta=float:"));
    }
    CHECK(g_str_has_prefix(lines[0], "glossy roughplastic"));   // a diffuse part: the plastic
    g_strfreev(lines);
    free(o), free(e);
    char side[4096];
    snprintf(side, sizeof side, "%s.conversion.json", out);
    json_t *j = load_json(side);
    for (size_t i = 0; j && i < json_array_size(json_object_get(j, "materials")); i++) {
        json_t *m = json_array_get(json_object_get(j, "materials"), i);
        double err = jget(m, "ngan_error"), alt = jget(json_object_get(m, "not_chosen"), "ngan_error");
        CHECK(err <= alt);
        CHECK(jget(m, "ngan_error_relative") < (i == 1 ? 0.2 : 0.08));
    }
    json_decref(j);
}

TEST(fit_export_errors)
{
    const char *pr = test_write("priors.json", PRIORS);
    char *o = NULL, *e = NULL;
    int rc = test_refl_run(30, &o, &e, "export", "material", pr, "--format", "obj", "-o", test_path("x"), NULL);
    CHECK(rc == 2);
    CHECK_CONTAINS(e, "--format obj");
    free(o), free(e);
    rc = test_refl_run(30, &o, &e, "export", "material", pr, "--format", "merl", "-o", test_path("x"), NULL);
    CHECK(rc == 1);
    CHECK_CONTAINS(e, "4 materials: a MERL table holds one; choose it with --material NAME");
    CHECK(access(test_path("x"), F_OK) != 0);
    free(o), free(e);
    rc = test_refl_run(30, &o, &e, "export", "material", pr, "--format", "gltf", "--material", "oak", "-o",
                       test_path("x"), NULL);
    CHECK(rc == 1);
    CHECK_CONTAINS(e, "no material oak here (it has glossy, steel, wood, matte)");
    free(o), free(e);
    const char *bad = test_write("bad.json", "{\"materials\": 3}\n");
    rc = test_refl_run(30, &o, &e, "export", "material", bad, "--format", "gltf", "-o", test_path("x"), NULL);
    CHECK(rc == 1);
    CHECK_CONTAINS(e, "bad.json");
    free(o), free(e);
    rc = test_refl_run(30, &o, &e, "export", "material", test_path("none.json"), "--format", "gltf", "-o",
                       test_path("x"), NULL);
    CHECK(rc == 1);
    CHECK_CONTAINS(e, "none.json");
    free(o), free(e);
    rc = test_refl_run(30, &o, &e, "export", "lamps", NULL);
    CHECK(rc == 2);
    free(o), free(e);
    rc = test_refl_run(30, &o, &e, "export", "material", "--help", NULL);
    CHECK(rc == 0);
    CHECK_CONTAINS(o, "Ngan");
    free(o), free(e);
}
