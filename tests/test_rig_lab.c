// tests/test_rig_lab.c — the lab file (rig/lab.h) through bin/refl: the shipped lab files read and
// their day's plans fit their rigs (refl plan day, then refl capture --dry-run of each plan on the
// second virtual lab's four-lamp rig), the facts handed to scripts/demo (day.sh), bad lab files
// refused with file:line, truncated ones never crashing the reader, and refl demo --lab stopping
// after its checked plans (--until plans).
#define _GNU_SOURCE
#include <glib.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "model/model.h"
#include "rig/lab.h"
#include "tests/test.h"

// An example file's absolute path (the lab files written by the tests name the examples' scenes).
static char *example(const char *name)
{
    char *top = g_canonicalize_filename(test_srcdir(), NULL), *p = g_strdup_printf("%s/examples/%s", top, name);
    g_free(top);
    return p;
}

static char *slurp(const char *path)
{
    char *t = NULL;
    return g_file_get_contents(path, &t, NULL, NULL) ? t : NULL;
}

// The second virtual lab (four lamps, no rim): every plan of its day passes refl capture --dry-run
// on its rig, names only the rig's lamps and carries the lab's wedge; a shipped plan naming the
// fifth lamp is refused by the same rig (what the generated plans are for).
TEST(lab_day_plans_fit_the_rig)
{
    char *rig = example("virtual-rig-lab.ini"), *lab = example("lab-virtual.ini");
    const char *dir = test_path("day");
    char *out = NULL, *err = NULL;
    int rc = test_refl_run(60, &out, &err, "plan", "day", "--rig", rig, "--lab", lab, "-o", dir, NULL);
    CHECK_MSG(rc == 0, "exit %d: %s", rc, err);
    CHECK_CONTAINS(out, "5 plans");
    g_free(out);
    g_free(err);
    const char *plans[] = { "check.ini", "reference_white.ini", "coupon_glossy.ini", "coupon_plywood.ini",
                            "coupon_painted_steel.ini" };
    for (size_t k = 0; k < sizeof plans / sizeof plans[0]; k++) {
        char *p = g_build_filename(dir, plans[k], NULL), *text = slurp(p);
        CHECK_MSG(text != NULL, "%s not written", p);
        CHECK(text && !strstr(text, "rim"));
        if (k >= 1) CHECK_CONTAINS(text, "sets = east; south; west; north");
        if (k >= 2) CHECK_CONTAINS(text, "tilt_deg = 35");
        rc = test_refl_run(60, &out, &err, "capture", p, "--rig", rig, "--dry-run", NULL);
        CHECK_MSG(rc == 0, "%s: exit %d: %s", plans[k], rc, err);
        CHECK_CONTAINS(out, "check: plan matches the rig");
        g_free(out);
        g_free(err);
        g_free(text);
        g_free(p);
    }
    char *shipped = example("plans/reference_white_lamps.ini");
    rc = test_refl_run(60, &out, &err, "capture", shipped, "--rig", rig, "--dry-run", NULL);
    CHECK(rc == 1);
    CHECK_CONTAINS(err, "has no lamp 'rim'");
    g_free(out);
    g_free(err);
    // the facts scripts/demo takes: the lab's, not the example virtual rig's
    char *sh = g_build_filename(dir, "day.sh", NULL), *facts = slurp(sh);
    CHECK_CONTAINS(facts, "LAB_SPHERE_CENTRE_MM='-50,30,35'");
    CHECK_CONTAINS(facts, "LAB_SPHERE_RADIUS_MM='20'");
    CHECK_CONTAINS(facts, "LAB_LAMP_RADIUS_MM='12'");
    CHECK_CONTAINS(facts, "LAB_RADIANCE='4000'");
    CHECK_CONTAINS(facts, "virtual-white-certificate.csv'");
    CHECK_CONTAINS(facts, "LAB_COUPON_NAMES=('glossy' 'plywood' 'painted_steel')");
    CHECK_CONTAINS(facts, "LAB_COUPON_TILTS_DEG=('35' '35' '35')");
    CHECK_CONTAINS(facts, "LAB_PRIORS=('plywood' 'painted_steel')");
    CHECK_CONTAINS(facts, "LAB_DESC_EXPECT=('correct' 'incorrect' 'incorrect')");
    g_free(facts);
    g_free(sh);
    g_free(shipped);
    g_free(rig);
    g_free(lab);
}

// The example real lab (examples/lab.ini) on the example real rig's four GPIO lamps: its plans are
// written for those lamps (no device is opened to write them).
TEST(lab_day_example_real_rig)
{
    char *rig = example("lab-rig.ini"), *lab = example("lab.ini");
    const char *dir = test_path("day");
    char *out = NULL, *err = NULL;
    int rc = test_refl_run(60, &out, &err, "plan", "day", "--rig", rig, "--lab", lab, "-o", dir, NULL);
    CHECK_MSG(rc == 0, "exit %d: %s", rc, err);
    g_free(out);
    g_free(err);
    char *p = g_build_filename(dir, "reference_white.ini", NULL), *text = slurp(p);
    CHECK_CONTAINS(text, "sets = east; south; west; north\n");
    g_free(text);
    g_free(p);
    p = g_build_filename(dir, "check.ini", NULL);
    text = slurp(p);
    CHECK_CONTAINS(text, "sets = east; west\n");
    CHECK_CONTAINS(text, "list = 0 90 180 270\n");
    g_free(text);
    g_free(p);
    p = g_build_filename(dir, "day.sh", NULL);
    text = slurp(p);
    CHECK_CONTAINS(text, "LAB_SPHERE_CENTRE_MM='60,0,40'");
    CHECK_CONTAINS(text, "LAB_RADIANCE=''");   // no kc without the lab's radiance
    g_free(text);
    g_free(p);
    g_free(rig);
    g_free(lab);
}

// Bad lab files (one change each to examples/lab-virtual.ini, its paths made absolute): each refused
// with the file, the line of the change and what is wrong.
TEST(lab_file_errors)
{
    char *src = example("lab-virtual.ini"), *good = slurp(src), *rig = example("virtual-rig-lab.ini");
    char *exdir = example("");
    CHECK(good != NULL);
    static const struct {
        const char *from, *to, *want;
        int         dline;   // the error's line from the change's
    } cases[] = {
        { "radius_mm = 20", "radious_mm = 20", "[sphere]: unknown key 'radious_mm'", 0 },
        { "[lamps]", "[lamp]", "unknown section [lamp]", 0 },
        { "format_version = 1", "format_version = 2", "a newer lab file format", 0 },
        { "centre_mm = -50 30 35", "centre_mm = -50 30", "centre_mm", 0 },
        { "radiance_unit = refl radiance units (model/model.h)", "# no unit", "radiance without radiance_unit", -1 },
        { "tilts = 0:40,240", "tilts = 95:40,240", "not TILT[@AZIMUTH]", 0 },
        { "priors = plywood painted_steel", "priors = plywood oak", "'oak' is no [coupon oak]", 0 },
        { "expect = correct", "expect = maybe", "give correct or incorrect", 0 },
        { "scene = samples/reference_white.d3d", "scene = samples/no_white.d3d", "no such file", 0 },
        { "check_lamps = east; west", "check_lamps = east; rim", "has no lamp 'rim'", 0 },
        { "tilt_deg = 35", "tilt_deg = 95", "tilt_deg", 0 },
    };
    GRegex *rel = g_regex_new("^(scene|certificate|board_scene) = ([^/])", G_REGEX_MULTILINE, 0, NULL);
    char *repl = g_strdup_printf("\\1 = %s\\2", exdir);
    for (size_t k = 0; good && k < sizeof cases / sizeof cases[0]; k++) {
        char *at = strstr(good, cases[k].from);
        CHECK_MSG(at != NULL, "case %zu: '%s' not in lab-virtual.ini", k, cases[k].from);
        if (!at) continue;
        int line = 1 + cases[k].dline;
        for (const char *p = good; p < at; p++) line += *p == '\n';
        GString *t = g_string_new_len(good, at - good);
        g_string_append(t, cases[k].to);
        g_string_append(t, at + strlen(cases[k].from));
        char *text = g_regex_replace(rel, t->str, -1, 0, repl, 0, NULL), name[32];
        snprintf(name, sizeof name, "bad%zu.ini", k);
        const char *path = test_write(name, text);
        char *out = NULL, *err = NULL, *want = g_strdup_printf("%s:%d: ", path, line);
        int rc = test_refl_run(60, &out, &err, "plan", "day", "--rig", rig, "--lab", path, "-o", test_path("d"), NULL);
        CHECK_MSG(rc == 1, "case %zu: exit %d", k, rc);
        CHECK_CONTAINS(err, want);
        CHECK_CONTAINS(err, cases[k].want);
        g_free(want);
        g_free(out);
        g_free(err);
        g_free(text);
        g_string_free(t, TRUE);
    }
    g_regex_unref(rel);
    g_free(repl);
    g_free(exdir);
    g_free(rig);
    g_free(good);
    g_free(src);
}

// refl demo --lab: the lab file's day begins with its plans, each checked against the rig, and
// --until plans ends it there; a bad lab file stops the day before anything runs, naming its line.
TEST(lab_demo_until_plans)
{
    char *rig = example("virtual-rig-lab.ini"), *lab = example("lab-virtual.ini");
    const char *dir = test_path("demo");
    char *out = NULL, *err = NULL;
    int rc = test_refl_run(120, &out, &err, "demo", "-o", dir, "--rig", rig, "--lab", lab, "--yes", "--until",
                           "plans", NULL);
    CHECK_MSG(rc == 0, "exit %d: %s %s", rc, out, err);
    int checks = 0;
    for (const char *p = out ? strstr(out, "plan check: ") : NULL; p; p = strstr(p + 1, "plan check: ")) checks++;
    CHECK_MSG(checks == 5, "%d plan checks: %s", checks, out);
    CHECK_CONTAINS(out, "stopped after the plans");
    CHECK(out && !strstr(out, "T-stiffener, direct light"));   // nothing beyond the plans ran
    char *sh = g_build_filename(dir, "lab", "day.sh", NULL);
    CHECK(g_file_test(sh, G_FILE_TEST_EXISTS));
    g_free(sh);
    g_free(out);
    g_free(err);
    const char *bad = test_write("bad.ini", "[lab]\nformat_version = 1\nsphere_mm = 3\n");
    rc = test_refl_run(120, &out, &err, "demo", "-o", test_path("demo2"), "--rig", rig, "--lab", bad, "--yes", NULL);
    CHECK_MSG(rc == 1, "exit %d", rc);
    char want[4200];
    snprintf(want, sizeof want, "%s:3: [lab]: unknown key 'sphere_mm'", bad);
    CHECK_CONTAINS(err, want);
    CHECK(out && !strstr(out, "T-stiffener, direct light"));
    g_free(out);
    g_free(err);
    g_free(rig);
    g_free(lab);
}

// The example lab files cut at every 7th byte: each cut is read or refused with a message naming the
// file, never a crash (the harness fails a test that crashes).
TEST(lab_file_truncated)
{
    const char *names[] = { "lab.ini", "lab-virtual.ini" };
    for (size_t f = 0; f < sizeof names / sizeof names[0]; f++) {
        char *path = example(names[f]), *text = slurp(path);
        CHECK(text != NULL);
        size_t len = text ? strlen(text) : 0;
        int read = 0, refused = 0;
        for (size_t cut = 0; cut < len; cut += 7) {
            rig_lab_t *L = rig_lab_parse(text, cut, path);
            if (L) read++;
            else {
                refused++;
                CHECK_MSG(strstr(model_last_error(), path) != NULL, "cut %zu: '%s'", cut, model_last_error());
            }
            rig_lab_free(L);
        }
        rig_lab_t *L = rig_lab_parse(text, len, path);
        CHECK_MSG(L != NULL, "%s: %s", names[f], model_last_error());
        rig_lab_free(L);
        printf("%s: %d cuts refused, %d read\n", names[f], refused, read);
        g_free(text);
        g_free(path);
    }
}
