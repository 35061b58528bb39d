// tests/test_model_opts.c — the one option parser (model/base/opts.h): values,
// ranges, flags, lists (repeated and greedy), positionals, required options,
// and the usage errors' exit status.
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
