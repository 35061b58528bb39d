// tests/test_model_config.c — the INI reader, materials, lamps and sensor files.
#include <stdlib.h>

#include "model/internal.h"
#include "tests/test.h"

static model_ini_t *ini_str(const char *text) { return model_ini_parse(text, strlen(text), "t.ini"); }

// Parse must fail with a message containing every needle.
#define INI_FAILS(text, ...)                                                            \
    do {                                                                                \
        model_error_clear();                                                            \
        model_ini_t *bad_ = ini_str(text);                                              \
        CHECK(bad_ == NULL);                                                            \
        model_ini_free(bad_);                                                           \
        const char *needles_[] = { __VA_ARGS__ };                                       \
        for (size_t i_ = 0; i_ < sizeof needles_ / sizeof needles_[0]; i_++)            \
            CHECK_CONTAINS(model_last_error(), needles_[i_]);                           \
    } while (0)

// ---- INI ---------------------------------------------------------------------------

TEST(ini_valid)
{
    const char *text =
        "# comment\n"
        "; another comment\n"
        "\n"
        "[ general ]\n"
        "  name  =  two words  \n"
        "expr = a=b = c\n"
        "empty =\n"
        "hex = x#y\n"
        "note = value # trailing comment\n"
        "[lamp    left]   # comment after a header\n"
        "position_mm = 1 2 3\n"
        "\t[ material  steel ]\n"
        "model=lambert";                       // no final newline
    model_ini_t *ini = ini_str(text);
    CHECK(ini != NULL);
    if (!ini) return;
    CHECK(!strcmp(ini->path, "t.ini"));
    CHECK(ini->nsections == 3);
    CHECK(!strcmp(ini->sections[0], "general"));
    CHECK(!strcmp(ini->sections[1], "lamp left"));
    CHECK(!strcmp(ini->sections[2], "material steel"));
    CHECK(ini->section_lines[0] == 4 && ini->section_lines[1] == 10 && ini->section_lines[2] == 12);
    CHECK(ini->nentries == 7);
    const model_ini_entry_t *e = model_ini_get(ini, "general", "name");
    CHECK(e && !strcmp(e->value, "two words") && e->line == 5);
    e = model_ini_get(ini, "general", "expr");
    CHECK(e && !strcmp(e->value, "a=b = c") && e->line == 6);
    e = model_ini_get(ini, "general", "empty");
    CHECK(e && !strcmp(e->value, "") && e->line == 7);
    e = model_ini_get(ini, "general", "hex");
    CHECK(e && !strcmp(e->value, "x#y"));
    e = model_ini_get(ini, "general", "note");
    CHECK(e && !strcmp(e->value, "value"));
    e = model_ini_get(ini, "lamp left", "position_mm");
    CHECK(e && !strcmp(e->value, "1 2 3") && e->line == 11 && !strcmp(e->section, "lamp left"));
    e = model_ini_get(ini, "material steel", "model");
    CHECK(e && !strcmp(e->value, "lambert") && e->line == 13);
    CHECK(model_ini_get(ini, "general", "position_mm") == NULL);
    CHECK(model_ini_get(ini, "nosuch", "name") == NULL);
    model_ini_free(ini);
    model_ini_free(NULL);
}

TEST(ini_crlf_and_empty)
{
    model_ini_t *ini = ini_str("[a]\r\nk = v\r\n\r\n# c\r\n[b]\r\nx = 1 2\r\n");
    CHECK(ini != NULL);
    if (ini) {
        const model_ini_entry_t *e = model_ini_get(ini, "a", "k");
        CHECK(e && !strcmp(e->value, "v") && e->line == 2);
        e = model_ini_get(ini, "b", "x");
        CHECK(e && !strcmp(e->value, "1 2") && e->line == 6);
        CHECK(ini->nsections == 2 && !strcmp(ini->sections[1], "b"));
    }
    model_ini_free(ini);
    ini = model_ini_parse("", 0, "empty.ini");
    CHECK(ini && ini->nsections == 0 && ini->nentries == 0);
    model_ini_free(ini);
    // The same key in two sections is fine.
    ini = ini_str("[a]\nk=1\n[b]\nk=2\n");
    CHECK(ini && !strcmp(model_ini_get(ini, "b", "k")->value, "2"));
    model_ini_free(ini);
}

TEST(ini_errors)
{
    INI_FAILS("# c\nkey = 1\n", "t.ini:2:", "key 'key' before any section");
    INI_FAILS("[a]\nk = 1\njust words\n", "t.ini:3:", "expected 'key = value'", "just words");
    INI_FAILS("[a]\n = 1\n", "t.ini:2:", "empty key");
    INI_FAILS("[a]\nk = 1\n[lamp x\n", "t.ini:3:", "unterminated '['");
    INI_FAILS("[a]\nk = 1\nj = 2\nk = 3\n", "t.ini:4:", "duplicate key 'k' in [a]", "first at line 2");
    INI_FAILS("[lamp a]\nk = 1\n[b]\n[lamp   a]\n", "t.ini:4:", "duplicate section [lamp a]", "first at line 1");
    INI_FAILS("[a] junk\n", "t.ini:1:", "after the section header");
    INI_FAILS("[a]\n[  ]\n", "t.ini:2:", "empty section name");
    model_error_clear();
    const char nul[] = "[a]\nk = 1\nj = \0x\n";
    CHECK(model_ini_parse(nul, sizeof nul - 1, "bin.ini") == NULL);
    CHECK_CONTAINS(model_last_error(), "bin.ini:3:");
    CHECK_CONTAINS(model_last_error(), "NUL byte");
    model_error_clear();
    CHECK(model_ini_load(test_path("does-not-exist.ini")) == NULL);
    CHECK_CONTAINS(model_last_error(), "does-not-exist.ini");
}

TEST(ini_load)
{
    const char *p = test_write("l.ini", "[s]\nk = v\n");
    model_ini_t *ini = model_ini_load(p);
    CHECK(ini && !strcmp(ini->path, p) && !strcmp(model_ini_get(ini, "s", "k")->value, "v"));
    model_ini_free(ini);
}

// ---- materials ----------------------------------------------------------------------

static const char *materials_text =
    "# materials\n"
    "[material white]\n"                    // 2
    "model = lambert\n"
    "kd = 0.3\n"
    "\n"
    "[material steel]\n"                    // 6
    "model = hall\n"
    "kd = 0.1\n"
    "ks = 2.5\n"
    "ns = 40\n"
    "[material ts]\n"                       // 11
    "model = torrance_sparrow\n"
    "kd = 0.05\nks = 1\nns = 100\nF0 = 0.9\n"
    "[material thesis]\n"                   // 17
    "model = thesis_fit\n"
    "ks = 0.7\nns = 12\n"
    "[material ct]\n"                       // 21
    "kd = 0.5\nks = 0.5\nm = 0.2\nF0 = 0.04\n"
    "model = cook_torrance\n"               // model may come anywhere
    "[material paint]\n"                    // 27
    "model = ggx\n"
    "kd = 0.8\nks = 0.2\nalpha = 0.09\nF0 = 0.04\n";

TEST(materials_valid)
{
    model_materials_t *m = model_materials_parse(materials_text, strlen(materials_text), "mats.ini");
    CHECK(m != NULL);
    if (!m) return;
    CHECK(m->n == 6);
    CHECK(!strcmp(m->path, "mats.ini"));
    char sha[65];
    model_sha256_hex(materials_text, strlen(materials_text), sha);
    CHECK(!strcmp(m->sha256, sha));
    const model_material_t *w = model_materials_find(m, "white");
    CHECK(w && w->model == MODEL_BRDF_LAMBERT && w->p[0] == 0.3 && w->line == 2);
    const model_material_t *s = model_materials_find(m, "steel");
    CHECK(s && s->model == MODEL_BRDF_HALL && s->p[0] == 0.1 && s->p[1] == 2.5 && s->p[2] == 40 && s->line == 6);
    const model_material_t *t = model_materials_find(m, "ts");
    CHECK(t && t->model == MODEL_BRDF_TORRANCE_SPARROW && t->p[3] == 0.9 && t->line == 11);
    const model_material_t *th = model_materials_find(m, "thesis");
    CHECK(th && th->model == MODEL_BRDF_THESIS_FIT && th->p[0] == 0.7 && th->p[1] == 12 && th->p[2] == 0);
    const model_material_t *c = model_materials_find(m, "ct");
    CHECK(c && c->model == MODEL_BRDF_COOK_TORRANCE && c->p[0] == 0.5 && c->p[2] == 0.2 && c->p[3] == 0.04);
    const model_material_t *g = model_materials_find(m, "paint");
    CHECK(g && g->model == MODEL_BRDF_GGX && g->p[2] == 0.09 && g->line == 27);
    CHECK(model_materials_find(m, "nosuch") == NULL);
    CHECK(!strcmp(m->materials[0].name, "white") && !strcmp(m->materials[5].name, "paint"));
    model_materials_free(m);
    model_materials_free(NULL);

    const char *p = test_write("mats.ini", materials_text);
    m = model_materials_load(p);
    CHECK(m && m->n == 6 && !strcmp(m->path, p) && !strcmp(m->sha256, sha));
    CHECK(model_sha256_file(p, sha) && m && !strcmp(m->sha256, sha));
    model_materials_free(m);
}

#define MATERIALS_FAIL(text, ...)                                                       \
    do {                                                                                \
        model_error_clear();                                                            \
        model_materials_t *bad_ = model_materials_parse(text, strlen(text), "mats.ini"); \
        CHECK(bad_ == NULL);                                                            \
        model_materials_free(bad_);                                                     \
        const char *needles_[] = { __VA_ARGS__ };                                       \
        for (size_t i_ = 0; i_ < sizeof needles_ / sizeof needles_[0]; i_++)            \
            CHECK_CONTAINS(model_last_error(), needles_[i_]);                           \
    } while (0)

TEST(materials_errors)
{
    MATERIALS_FAIL("[material a]\nmodel = lambert\nkd = 0.1\n[lamp b]\n", "mats.ini:4:", "[lamp b]",
                   "[material NAME]");
    MATERIALS_FAIL("[material]\nmodel = lambert\n", "mats.ini:1:", "needs a name");
    MATERIALS_FAIL("[material a]\nmodel = hall\nkd = 0.1\nks = 1\nns = 3\nkappa = 2\n", "mats.ini:6:",
                   "unknown key 'kappa'", "material 'a'", "valid keys: model, kd, ks, ns");
    MATERIALS_FAIL("[material a]\nmodel = ggx\nkd = 0.1\nks = 1\nm = 0.3\nF0 = 1\n", "mats.ini:5:",
                   "unknown key 'm'", "valid keys: model, kd, ks, alpha, F0");
    MATERIALS_FAIL("\n[material a]\nkd = 0.1\n", "mats.ini:2:", "material 'a'", "no 'model = ...'", "lambert, hall");
    MATERIALS_FAIL("[material a]\nmodel = phong\n", "mats.ini:2:", "unknown reflection model 'phong'",
                   "torrance_sparrow, thesis_fit, cook_torrance, ggx");
    MATERIALS_FAIL("[material a]\nmodel = lambert\nkd = 0.1\n\n[material bb]\nmodel = hall\nkd = 0.1\nns = 3\n",
                   "mats.ini:5:", "material 'bb'", "lacks parameter 'ks'");
    MATERIALS_FAIL("[material a]\nmodel = lambert\nkd = 0.5\n", "mats.ini:3:", "kd = 0.5 is out of range [0, 0.31831]",
                   "albedo/pi");
    MATERIALS_FAIL("[material a]\nmodel = ggx\nkd = 0.5\nks = 0.5\nalpha = 0\nF0 = 0.5\n", "mats.ini:5:",
                   "alpha = 0 is out of range [0.001, 1]");
    MATERIALS_FAIL("[material a]\nmodel = cook_torrance\nkd = 0.5\nks = 1.5\nm = 0.1\nF0 = 0.5\n", "mats.ini:4:",
                   "ks = 1.5 is out of range [0, 1]");
    MATERIALS_FAIL("[material a]\nmodel = hall\nkd = 0.1\nks = -1\nns = 3\n", "mats.ini:4:",
                   "ks = -1 is out of range [0, inf)");
    MATERIALS_FAIL("[material a]\nmodel = hall\nkd = 0.1\nks = 1\nns = 20000\n", "mats.ini:5:",
                   "ns = 20000 is out of range [0, 10000]");
    MATERIALS_FAIL("[material a]\nmodel = lambert\nkd = 0.1x\n", "mats.ini:3:", "kd = '0.1x' is not a number");
    MATERIALS_FAIL("[material a]\nmodel = lambert\nkd = nan\n", "mats.ini:3:", "not a number");
    MATERIALS_FAIL("[material two words]\nmodel = lambert\nkd = 0.1\n", "mats.ini:1:", "contains blanks");
    MATERIALS_FAIL("", "mats.ini", "no [material NAME] sections");
    MATERIALS_FAIL("[material a]\nmodel = lambert\nkd = 0.1\n[material a]\n", "mats.ini:4:", "duplicate section");

    // Names: 63 characters are fine, 64 are not.
    char text[256], name[80];
    memset(name, 'n', 63);
    name[63] = 0;
    snprintf(text, sizeof text, "[material %s]\nmodel = lambert\nkd = 0.1\n", name);
    model_materials_t *m = model_materials_parse(text, strlen(text), "mats.ini");
    CHECK(m && m->n == 1 && strlen(m->materials[0].name) == 63);
    model_materials_free(m);
    strcat(name, "n");
    snprintf(text, sizeof text, "[material %s]\nmodel = lambert\nkd = 0.1\n", name);
    MATERIALS_FAIL(text, "mats.ini:1:", "64 characters long", "limit is 63");

    model_error_clear();
    CHECK(model_materials_load(test_path("nope.ini")) == NULL);
    CHECK_CONTAINS(model_last_error(), "nope.ini");
}

// ---- lamps --------------------------------------------------------------------------

TEST(lamps_valid)
{
    const char *text = "[lamp left]\nposition_mm = -300 0 500.5\nintensity = 1e6\n\n"
                       "[lamp right]\r\nintensity = 2\r\nposition_mm = 300, 10, 400\r\nradius_mm = 12.5\r\n";
    model_lamps_t *l = model_lamps_parse(text, strlen(text), "lamps.ini");
    CHECK(l && l->n == 2);
    if (!l) return;
    CHECK(!strcmp(l->lamps[0].name, "left") && l->lamps[0].line == 1);
    CHECK(l->lamps[0].position_mm.x == -300 && l->lamps[0].position_mm.y == 0 && l->lamps[0].position_mm.z == 500.5);
    CHECK(l->lamps[0].intensity == 1e6 && l->lamps[0].radius_mm == 0);
    CHECK(!strcmp(l->lamps[1].name, "right") && l->lamps[1].line == 5);
    CHECK(l->lamps[1].position_mm.x == 300 && l->lamps[1].position_mm.y == 10 && l->lamps[1].position_mm.z == 400);
    CHECK(l->lamps[1].intensity == 2 && l->lamps[1].radius_mm == 12.5);
    CHECK(model_lamps_find(l, "right") == 1 && model_lamps_find(l, "left") == 0 && model_lamps_find(l, "x") == -1);
    char sha[65];
    model_sha256_hex(text, strlen(text), sha);
    CHECK(!strcmp(l->sha256, sha) && !strcmp(l->path, "lamps.ini"));
    model_lamps_free(l);
    model_lamps_free(NULL);

    const char *p = test_write("lamps.ini", text);
    l = model_lamps_load(p);
    CHECK(l && l->n == 2 && !strcmp(l->sha256, sha) && !strcmp(l->path, p));
    model_lamps_free(l);
}

#define LAMPS_FAIL(text, ...)                                                           \
    do {                                                                                \
        model_error_clear();                                                            \
        model_lamps_t *bad_ = model_lamps_parse(text, strlen(text), "lamps.ini");        \
        CHECK(bad_ == NULL);                                                            \
        model_lamps_free(bad_);                                                         \
        const char *needles_[] = { __VA_ARGS__ };                                       \
        for (size_t i_ = 0; i_ < sizeof needles_ / sizeof needles_[0]; i_++)            \
            CHECK_CONTAINS(model_last_error(), needles_[i_]);                           \
    } while (0)

TEST(lamps_emission_pattern_keys)
{
    const char *text = "[lamp a]\nposition_mm = 0 0 500\nintensity = 1\n"
                       "[lamp b]\nposition_mm = 100 0 500\nintensity = 1\nemission_cos_power = 13.5\n"
                       "[lamp c]\nposition_mm = 0 0 500\nintensity = 1\nemission_cos_power = 1\n"
                       "emission_axis = 0 3 -4\n";
    model_lamps_t *l = model_lamps_parse(text, strlen(text), "lamps.ini");
    CHECK(l && l->n == 3);
    if (!l) return;
    CHECK(l->lamps[0].emission_cos_power == 0);
    CHECK(l->lamps[1].emission_cos_power == 13.5);
    CHECK(l->lamps[1].emission_axis.x == 0 && l->lamps[1].emission_axis.y == 0 && l->lamps[1].emission_axis.z == 0);
    CHECK(l->lamps[2].emission_cos_power == 1);
    CHECK_NEAR(l->lamps[2].emission_axis.y, 0.6, 1e-15);
    CHECK_NEAR(l->lamps[2].emission_axis.z, -0.8, 1e-15);
    model_lamps_free(l);
}

TEST(lamps_errors)
{
    LAMPS_FAIL("[lamp a]\nposition_mm = 1 2 3\nintensity = 1\nemission_cos_power = -1\n", "lamps.ini:4:",
               "emission_cos_power", "out of range");
    LAMPS_FAIL("[lamp a]\nposition_mm = 1 2 3\nintensity = 1\nemission_axis = 0 0 -1\n", "lamps.ini:4:",
               "needs emission_cos_power");
    LAMPS_FAIL("[lamp a]\nposition_mm = 1 2 3\nintensity = 1\nemission_cos_power = 2\nemission_axis = 0 0 0\n",
               "lamps.ini:5:", "not a direction");
    LAMPS_FAIL("[lamp a]\nposition_mm = 1 2 3\nintensity = 1\nemission_cos_power = 2\nemission_axis = 0 1\n",
               "lamps.ini:5:", "exactly 3 numbers");
    LAMPS_FAIL("[lamp a]\nposition_mm = 0 0 0\nintensity = 1\nemission_cos_power = 2\n", "lamps.ini:1:",
               "at the rig origin", "emission_axis");
    LAMPS_FAIL("[lamp a]\nposition_mm = 1 2\nintensity = 1\n", "lamps.ini:2:", "exactly 3 numbers", "lamp 'a'");
    LAMPS_FAIL("[lamp a]\nposition_mm = 1 2 3 4\nintensity = 1\n", "lamps.ini:2:", "exactly 3 numbers");
    LAMPS_FAIL("[lamp a]\nposition_mm = 1 two 3\nintensity = 1\n", "lamps.ini:2:", "exactly 3 numbers");
    LAMPS_FAIL("[lamp a]\nposition_mm = 1 2 3\nintensity = 0\n", "lamps.ini:3:", "intensity = 0", "must be > 0");
    LAMPS_FAIL("[lamp a]\nposition_mm = 1 2 3\nintensity = -5\n", "lamps.ini:3:", "must be > 0");
    LAMPS_FAIL("[lamp a]\nposition_mm = 1 2 3\nintensity = bright\n", "lamps.ini:3:", "not a number");
    LAMPS_FAIL("[lamp a]\nposition_mm = 1 2 3\nintensity = 1\n[lamp b]\nposition_mm = 1 2 3\n", "lamps.ini:4:",
               "lamp 'b' lacks 'intensity'");
    LAMPS_FAIL("[lamp a]\nintensity = 1\n", "lamps.ini:1:", "lamp 'a' lacks 'position_mm'");
    LAMPS_FAIL("[lamp a]\nposition_mm = 1 2 3\nintensity = 1\nradius_mm = -1\n", "lamps.ini:4:", "must be >= 0");
    LAMPS_FAIL("[lamp a]\nposition_mm = 1 2 3\nintensity = 1\ncolour = red\n", "lamps.ini:4:",
               "unknown key 'colour'", "valid keys: position_mm, intensity, radius_mm");
    LAMPS_FAIL("# nothing\n", "lamps.ini", "no [lamp NAME] sections", "at least one lamp");
    LAMPS_FAIL("[lamp a]\nposition_mm = 1 2 3\nintensity = 1\n[material b]\n", "lamps.ini:4:", "[material b]",
               "[lamp NAME]");
    LAMPS_FAIL("[lamp]\nposition_mm = 1 2 3\nintensity = 1\n", "lamps.ini:1:", "needs a name");
}

// ---- sensor -------------------------------------------------------------------------

TEST(sensor_default_values)
{
    model_sensor_t s = model_sensor_default();
    CHECK(s.bits == 12);
    CHECK(s.system_gain_dn_per_e == 0.25 && s.full_well_e == 16000 && s.read_noise_e == 6);
    CHECK(s.dark_offset_dn == 64 && s.dsnu_dn == 1.5 && s.prnu_pct == 1);
    CHECK(s.dark_current_e_per_s == 0 && s.vignetting == 0.1 && s.nonlinearity_pct == 2);
    CHECK(s.pattern_seed == 1 && s.noise_seed == 1);
}

// Field by field (the struct has padding).
static bool sensor_equal(const model_sensor_t *a, const model_sensor_t *b)
{
    return a->bits == b->bits && a->system_gain_dn_per_e == b->system_gain_dn_per_e &&
           a->full_well_e == b->full_well_e && a->read_noise_e == b->read_noise_e &&
           a->dark_offset_dn == b->dark_offset_dn && a->dsnu_dn == b->dsnu_dn && a->prnu_pct == b->prnu_pct &&
           a->dark_current_e_per_s == b->dark_current_e_per_s && a->exposure_us == b->exposure_us &&
           a->vignetting == b->vignetting && a->nonlinearity_pct == b->nonlinearity_pct &&
           a->pattern_seed == b->pattern_seed && a->noise_seed == b->noise_seed;
}

TEST(sensor_valid)
{
    model_sensor_t s;
    const char *text = "[sensor]\nbits = 16\nsystem_gain_dn_per_e = 1.5\nfull_well_e = 30000\nread_noise_e = 0\n"
                       "dark_offset_dn = 100\ndsnu_dn = 0\nprnu_pct = 50\ndark_current_e_per_s = 20\n"
                       "exposure_us = 10000\nvignetting = 0\nnonlinearity_pct = 0\n"
                       "pattern_seed = 18446744073709551615\nnoise_seed = 0\n";
    CHECK(model_sensor_parse(text, strlen(text), "s.ini", &s));
    CHECK(s.bits == 16 && s.system_gain_dn_per_e == 1.5 && s.full_well_e == 30000 && s.read_noise_e == 0);
    CHECK(s.dark_offset_dn == 100 && s.dsnu_dn == 0 && s.prnu_pct == 50 && s.dark_current_e_per_s == 20);
    CHECK(s.exposure_us == 10000 && s.vignetting == 0 && s.nonlinearity_pct == 0);
    CHECK(s.pattern_seed == UINT64_MAX && s.noise_seed == 0);

    // Unspecified keys keep the defaults.
    const char *part = "# partial\n[ sensor ]\nbits = 8\nnoise_seed = 77\n";
    CHECK(model_sensor_parse(part, strlen(part), "s.ini", &s));
    model_sensor_t d = model_sensor_default();
    d.bits = 8;
    d.noise_seed = 77;
    CHECK(sensor_equal(&s, &d));

    const char *p = test_write("sensor.ini", part);
    memset(&s, 0, sizeof s);
    CHECK(model_sensor_load(p, &s) && sensor_equal(&s, &d));
}

#define SENSOR_FAIL(text, ...)                                                          \
    do {                                                                                \
        model_error_clear();                                                            \
        model_sensor_t s_ = model_sensor_default(), before_ = s_;                       \
        CHECK(!model_sensor_parse(text, strlen(text), "s.ini", &s_));                   \
        CHECK(sensor_equal(&s_, &before_));                                       \
        const char *needles_[] = { __VA_ARGS__ };                                       \
        for (size_t i_ = 0; i_ < sizeof needles_ / sizeof needles_[0]; i_++)            \
            CHECK_CONTAINS(model_last_error(), needles_[i_]);                           \
    } while (0)

TEST(sensor_errors)
{
    SENSOR_FAIL("[sensor]\nbits = 10\n", "s.ini:2:", "bits = '10'", "8, 12 or 16");
    SENSOR_FAIL("[sensor]\nbits = 12.0\n", "s.ini:2:", "8, 12 or 16");
    SENSOR_FAIL("[sensor]\n\nsystem_gain_dn_per_e = 0\n", "s.ini:3:", "system_gain_dn_per_e = 0", "must be > 0");
    SENSOR_FAIL("[sensor]\nfull_well_e = -1\n", "s.ini:2:", "must be > 0");
    SENSOR_FAIL("[sensor]\nread_noise_e = -0.5\n", "s.ini:2:", "read_noise_e = -0.5", "must be >= 0");
    SENSOR_FAIL("[sensor]\ndsnu_dn = -1\n", "s.ini:2:", "must be >= 0");
    SENSOR_FAIL("[sensor]\ndark_current_e_per_s = -1\n", "s.ini:2:", "must be >= 0");
    SENSOR_FAIL("[sensor]\nexposure_us = -1\n", "s.ini:2:", "must be >= 0");
    SENSOR_FAIL("[sensor]\nprnu_pct = 51\n", "s.ini:2:", "must be in [0, 50]");
    SENSOR_FAIL("[sensor]\nvignetting = 1\n", "s.ini:2:", "must be in [0, 1)");
    SENSOR_FAIL("[sensor]\nnonlinearity_pct = -1\n", "s.ini:2:", "must be in [0, 50]");
    SENSOR_FAIL("[sensor]\npattern_seed = -1\n", "s.ini:2:", "pattern_seed = '-1'", "integer >= 0");
    SENSOR_FAIL("[sensor]\nnoise_seed = 1.5\n", "s.ini:2:", "integer >= 0");
    SENSOR_FAIL("[sensor]\nnoise_seed = 18446744073709551616\n", "s.ini:2:", "integer >= 0");
    SENSOR_FAIL("[sensor]\ngain = 2\n", "s.ini:2:", "unknown key 'gain'", "valid keys: bits, system_gain_dn_per_e",
                "noise_seed");
    SENSOR_FAIL("[sensor]\nbits = 8\n[camera]\n", "s.ini:3:", "section [camera]", "one [sensor] section");
    SENSOR_FAIL("", "s.ini", "no [sensor] section");
    SENSOR_FAIL("[sensor]\nbits = 8\n[sensor]\n", "s.ini:3:", "duplicate section [sensor]");
    SENSOR_FAIL("[sensor]\nbits = 8\nbits = 12\n", "s.ini:3:", "duplicate key 'bits'");
    SENSOR_FAIL("[sensor]\nread_noise_e = lots\n", "s.ini:2:", "read_noise_e = 'lots' is not a number");
}

// Large files parse in linear time (duplicate checks are hashed): 100,000 keys
// in one section and 100,000 sections, each well under a second.
TEST_ALONE(ini_large_files_linear_time)
{
    size_t cap = 4 << 20, n = 0;
    char *buf = malloc(cap);
    n += snprintf(buf + n, cap - n, "[s]\n");
    for (int i = 0; i < 100000; i++) n += snprintf(buf + n, cap - n, "k%d = 1\n", i);
    double t0 = model_now_s();
    model_ini_t *ini = model_ini_parse(buf, n, "big_keys.ini");
    double dt = model_now_s() - t0;
    CHECK(ini && ini->nentries == 100000);
    CHECK_MSG(dt < 1.0, "100k keys took %.2f s", dt);
    model_ini_free(ini);
    n = 0;
    for (int i = 0; i < 100000; i++) n += snprintf(buf + n, cap - n, "[s%d]\nk = 1\n", i);
    n += snprintf(buf + n, cap - n, "[s7]\n");
    t0 = model_now_s();
    ini = model_ini_parse(buf, n, "big_sections.ini");
    dt = model_now_s() - t0;
    CHECK(ini == NULL);
    CHECK_CONTAINS(model_last_error(), "big_sections.ini:200001: duplicate section [s7] (first at line 15)");
    CHECK_MSG(dt < 1.0, "100k sections took %.2f s", dt);
    free(buf);
}

// Materials and lamps files with many sections parse in linear time (each
// section reads only its own entries).
TEST_ALONE(materials_lamps_many_sections_linear_time)
{
    size_t cap = 8 << 20, n = 0;
    char *buf = malloc(cap);
    for (int i = 0; i < 50000; i++)
        n += snprintf(buf + n, cap - n, "[material m%d]\nmodel = lambert\nkd = 0.2\n", i);
    double t0 = model_now_s();
    model_materials_t *m = model_materials_parse(buf, n, "many.ini");
    double dt = model_now_s() - t0;
    CHECK(m && m->n == 50000);
    CHECK_MSG(dt < 1.0, "50k materials took %.2f s", dt);
    model_materials_free(m);
    n = 0;
    for (int i = 0; i < 50000; i++)
        n += snprintf(buf + n, cap - n, "[lamp l%d]\nposition_mm = %d 0 500\nintensity = 1e6\n", i, i);
    t0 = model_now_s();
    model_lamps_t *l = model_lamps_parse(buf, n, "many_lamps.ini");
    dt = model_now_s() - t0;
    CHECK(l && l->n == 50000);
    CHECK_MSG(dt < 1.0, "50k lamps took %.2f s", dt);
    model_lamps_free(l);
    free(buf);
}
