// tests/test_model_corpus.c — replays the fuzz corpus (tests/corpus/) through every
// parser, so `make asan` catches regressions of crashes found by fuzzing.
#define _GNU_SOURCE
#include <dirent.h>
#include <stdlib.h>

#include "tests/fuzz_dispatch.h"
#include "tests/test.h"

TEST(corpus_replays_cleanly)
{
    char dir[1024], examples[1024];
    snprintf(dir, sizeof dir, "%s/tests/corpus", test_srcdir());
    snprintf(examples, sizeof examples, "%s/examples", test_srcdir());
    DIR *d = opendir(dir);
    CHECK_MSG(d != NULL, "cannot open %s", dir);
    if (!d) return;
    int n = 0, ok = 0;
    int per_parser[REFL_FUZZ_NPARSERS] = { 0 };
    struct dirent *e;
    while ((e = readdir(d))) {
        if (e->d_name[0] == '.') continue;
        char path[2048];
        snprintf(path, sizeof path, "%s/%s", dir, e->d_name);
        size_t len;
        char *buf = model_read_file(path, &len);
        CHECK_MSG(buf != NULL, "cannot read %s", path);
        if (!buf) continue;
        // A copy of exactly len bytes, so reads past the end are caught under ASan.
        uint8_t *data = malloc(len ? len : 1);
        memcpy(data, buf, len);
        free(buf);
        model_error_clear();
        bool parsed = refl_fuzz_parse_in(data, len, examples);
        CHECK_MSG(parsed || model_last_error()[0] != 0,
                  "%s was rejected without an error message", e->d_name);
        if (len > 0) per_parser[refl_fuzz_selector(data[0])]++;
        ok += parsed;
        n++;
        free(data);
    }
    closedir(d);
    CHECK_MSG(n >= 20, "only %d corpus inputs in %s (expected >= 20)", n, dir);
    for (int i = 0; i < REFL_FUZZ_NPARSERS; i++)
        CHECK_MSG(per_parser[i] >= 2, "parser %d has only %d corpus inputs", i, per_parser[i]);
    CHECK_MSG(ok >= 1 && ok < n, "%d of %d corpus inputs parsed: expected some valid and some invalid", ok, n);
}

// The parse-only entry points the fuzzer uses for the rig's files: the
// examples pass, and a rejection names the file and line like rig_open /
// rig_virtual_open do.
TEST(rig_parse_only_entry_points)
{
    char path[2048];
    size_t len;
    snprintf(path, sizeof path, "%s/examples/lab-rig.ini", test_srcdir());
    char *text = model_read_file(path, &len);
    CHECK(text != NULL);
    if (text) CHECK(rig_config_parse(text, len, path) == 0);
    free(text);
    const char *bad = "[turntable]\nbackend = sim\nspeed_deg_s = -1\n";
    CHECK(rig_config_parse(bad, strlen(bad), "x/rig.ini") == RIG_ERR_INVALID);
    CHECK_CONTAINS(model_last_error(), "x/rig.ini:3: [turntable] speed_deg_s = -1 is out of range");

    char examples[1024];
    snprintf(examples, sizeof examples, "%s/examples", test_srcdir());
    snprintf(path, sizeof path, "%s/virtual-truth.ini", examples);
    text = model_read_file(path, &len);
    CHECK(text != NULL);
    if (text) CHECK(rig_virtual_check_truth(text, len, "virtual-truth.ini", examples) == 0);
    free(text);
    // Relative paths resolve against the base directory: the scene is not there.
    const char *t = "[camera]\nmodel = camera.cameramodel\n";
    CHECK(rig_virtual_check_truth(t, strlen(t), "t.ini", "/nonexistent") == RIG_ERR_INVALID);
    CHECK_CONTAINS(model_last_error(), "/nonexistent/t.ini:2: camera model");
    CHECK_CONTAINS(model_last_error(), "/nonexistent/camera.cameramodel");
}
