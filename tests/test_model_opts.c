// tests/test_model_opts.c — the one option parser (model/base/opts.h): values,
// ranges, flags, lists (repeated and greedy), positionals, required options,
// the usage errors' exit status, and old spellings noted once.
#define _GNU_SOURCE
#include <glib.h>
#include <math.h>
#include <stdio.h>
#include <unistd.h>

#include "model/model.h"
#include "model/base/opts.h"
#include "tests/test.h"

// Parse argv (NULL-terminated) with stderr silenced; returns model_cli_parse's result.
static int parse(model_cli_t *c, const char **argv)
{
    int argc = 0;
    while (argv[argc]) argc++;
    fflush(stderr);
    FILE *keep = stderr;
    stderr = fopen("/dev/null", "w");
    int rc = model_cli_parse(c, argc, (char **)argv);
    fclose(stderr);
    stderr = keep;
    return rc;
}

TEST(opts_values_lists_and_errors)
{
    const char *out = NULL, *mode = NULL;
    double k = 1;
    int n = 3;
    bool verbose = false;
    const char *files_v[3];
    model_opt_list_t files = { files_v, 0, 3 };
    const char *sess_v[4];
    model_opt_list_t sessions = { sess_v, 0, 4 };
    model_opt_t opts[] = {
        MODEL_OPT_STRING("-o", "DIR", "output", &out, true),
        MODEL_OPT_DOUBLE("--kc", "K", "scale", &k, 0, INFINITY),
        MODEL_OPT_INT("--window", "N", "pixels", &n, 1, 64),
        MODEL_OPT_FLAG("-v", "--verbose", "talk", &verbose),
        MODEL_OPT_LIST("--files", "F...", "files", &files, true, false),
        MODEL_OPT_LIST("--session", "DIR", "repeat", &sessions, false, false),
        MODEL_OPT_VALUE("--mode", "M", "a string read after parsing", false),
    };
    model_cli_t c = { .cmd = "test", .synopsis = "SCENE", .opts = opts, .nopts = MODEL_NOPTS(opts),
                      .min_positional = 1, .max_positional = 1 };
    const char *ok[] = { "test", "scene.d3d", "-o", "d", "--kc=2.5", "--window", "7", "--verbose", "--files", "a", "b",
                         "--session", "s1", "--session=s2", "--mode", "fast", NULL };
    CHECK(parse(&c, ok) == MODEL_CLI_OK);
    CHECK(c.npositional == 1 && !strcmp(c.positional[0], "scene.d3d"));
    CHECK(out && !strcmp(out, "d"));
    CHECK_NEAR(k, 2.5, 0);
    CHECK(n == 7 && verbose);
    CHECK(files.n == 2 && !strcmp(files.v[0], "a") && !strcmp(files.v[1], "b"));
    CHECK(sessions.n == 2 && !strcmp(sessions.v[1], "s2"));
    mode = model_cli_value(&c, "--mode");
    CHECK(mode && !strcmp(mode, "fast"));
    CHECK(model_cli_opt(&c, "--verbose") == model_cli_opt(&c, "-v"));
    // a value converted after parsing: "fast" is no integer (a usage error), an absent option keeps the default
    long l = 5;
    fflush(stderr);
    FILE *keep = stderr;
    stderr = fopen("/dev/null", "w");
    CHECK(model_cli_long(&c, "--mode", &l, 0, 9) == MODEL_CLI_USAGE && l == 5);
    fclose(stderr);
    stderr = keep;
    double d = 7;
    CHECK(model_cli_double(&c, "--absent", &d, 0, false, 1, "0..1") == 0 && d == 7);

    // each error is a usage error (exit status 2), the parse leaves the rest
    static const char *const bad[][6] = {
        { "test", "s", "-o", "d", "--window", "0" },      // out of range
        { "test", "s", "-o", "d", "--kc", "x" },          // not a number
        { "test", "s", "-o", "d", "--bogus", NULL },      // unknown option
        { "test", "s", "--window", "3", NULL, NULL },     // -o missing
        { "test", "-o", "d", NULL, NULL, NULL },          // SCENE missing
        { "test", "s", "t", "-o", "d", NULL },            // two positionals
    };
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        const char *argv[8] = { 0 };
        for (int j = 0; j < 6 && bad[i][j]; j++) argv[j] = bad[i][j];
        CHECK_MSG(parse(&c, argv) == MODEL_CLI_USAGE, "case %zu", i);
    }
    const char *twice[] = { "test", "s", "-o", "d", "-o", "e", NULL };
    CHECK(parse(&c, twice) == MODEL_CLI_USAGE);
    const char *full[] = { "test", "s", "-o", "d", "--files", "1", "2", "3", "4", NULL };
    CHECK(parse(&c, full) == MODEL_CLI_USAGE);   // more than the list holds
    // "-30" is a number, not an option, where numbers are positional
    model_cli_t c2 = { .cmd = "move", .synopsis = "ANGLE", .opts = opts, .nopts = MODEL_NOPTS(opts),
                       .min_positional = 1, .max_positional = 1, .numbers_positional = true };
    const char *neg[] = { "move", "-30", "-o", "d", NULL };
    CHECK(parse(&c2, neg) == MODEL_CLI_OK && !strcmp(c2.positional[0], "-30"));
}

// The notes of a parse, one a line (model_note's sink).
static void keep_note(void *ctx, model_notice_kind_t kind, const char *text)
{
    if (kind == MODEL_NOTICE_NOTE) g_string_append_printf(ctx, "%s\n", text);
}

static int parse_noting(model_cli_t *c, const char **argv, GString *notes)
{
    g_string_truncate(notes, 0);
    bool q = model_error_quiet(false);   // notes are what this test reads
    model_notice_sink(keep_note, notes);
    int rc = parse(c, argv);
    model_notice_sink(NULL, NULL);
    model_error_quiet(q);
    return rc;
}

static int count_of(const char *hay, const char *needle)
{
    int n = 0;
    for (const char *p = hay; (p = strstr(p, needle)); p += strlen(needle)) n++;
    return n;
}

// Old spellings: accepted for the option they name now, its value and
// destination the same, noted once a run however often given, never shown by
// --help; an option given by its name and its old spelling is given twice.
TEST(opts_old_spellings)
{
    const char *cam = NULL, *out = NULL;
    double angle = 0;
    const char *lamp_v[4];
    model_opt_list_t lamps = { lamp_v, 0, 4 };
    model_opt_t opts[] = {
        MODEL_OPT_STRING("--camera-model", "FILE", "a camera model", &cam, true, .old = "--camera --cam"),
        MODEL_OPT_DOUBLE("--angle-deg", "A", "an angle", &angle, -360, 360, .old = "--turntable-deg"),
        MODEL_OPT_LIST("--lamps-on", "NAMES", "lamps", &lamps, false, false, .old = "--lamps"),
        MODEL_OPT_OUT("FILE", "the output", &out, true, .old = "--output"),
    };
    model_cli_t c = { .cmd = "test", .synopsis = "", .opts = opts, .nopts = MODEL_NOPTS(opts), .min_positional = 0,
                      .max_positional = 0, .repeat_ok = true };
    GString *notes = g_string_new("");
    const char *old[] = { "test", "--camera", "c.cameramodel", "--turntable-deg=30", "--lamps", "east", "--lamps",
                          "west", "--output", "o.png", NULL };
    CHECK(parse_noting(&c, old, notes) == MODEL_CLI_OK);
    CHECK(cam && !strcmp(cam, "c.cameramodel") && angle == 30 && lamps.n == 2 && out && !strcmp(out, "o.png"));
    CHECK(!strcmp(model_cli_value(&c, "--camera-model"), "c.cameramodel"));
    CHECK_CONTAINS(notes->str, "--camera FILE: the option is --camera-model (the old spelling still works)\n");
    CHECK_CONTAINS(notes->str, "--turntable-deg A: the option is --angle-deg (the old spelling still works)\n");
    CHECK_CONTAINS(notes->str, "--output FILE: the option is --out (the old spelling still works)\n");
    CHECK_MSG(count_of(notes->str, "--lamps NAMES: the option is --lamps-on") == 1, "%s", notes->str);
    CHECK(count_of(notes->str, "\n") == 4);
    // the second old spelling, and the new names: no note
    const char *now[] = { "test", "--cam", "d", "-o", "x", "--angle-deg", "-5", NULL };
    CHECK(parse_noting(&c, now, notes) == MODEL_CLI_OK && !strcmp(cam, "d") && angle == -5);
    CHECK(!strcmp(notes->str, "--cam FILE: the option is --camera-model (the old spelling still works)\n"));
    const char *plain[] = { "test", "--camera-model", "e", "--out", "y", NULL };
    CHECK(parse_noting(&c, plain, notes) == MODEL_CLI_OK && !strcmp(cam, "e") && !strcmp(out, "y"));
    CHECK(notes->len == 0);
    // the new name and an old spelling of one option: given twice (without repeat_ok)
    c.repeat_ok = false;
    const char *twice[] = { "test", "--camera-model", "a", "--camera", "b", "-o", "x", NULL };
    CHECK(parse_noting(&c, twice, notes) == MODEL_CLI_USAGE);
    // --help shows the names, never the old spellings
    char *text = NULL;
    size_t len = 0;
    FILE *f = open_memstream(&text, &len);
    model_cli_help(&c, f);
    fclose(f);
    CHECK_CONTAINS(text, "--camera-model FILE");
    CHECK_CONTAINS(text, "-o, --out FILE");
    CHECK(!strstr(text, "--camera ") && !strstr(text, "--turntable-deg") && !strstr(text, "--output"));
    CHECK_CONTAINS(text, "  4  refl verify --fail-on-incorrect");
    free(text);
    g_string_free(notes, TRUE);
}
