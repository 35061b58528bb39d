// tests/test_corpus.c — replays the fuzz corpus (tests/corpus/) through every
// parser, so `make asan` catches regressions of crashes found by fuzzing.
#define _GNU_SOURCE
#include <dirent.h>
#include <stdlib.h>

#include "tests/fuzz_dispatch.h"
#include "tests/test.h"

TEST(corpus_replays_cleanly)
{
    char dir[1024];
    snprintf(dir, sizeof dir, "%s/tests/corpus", test_srcdir());
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
        bool parsed = refl_fuzz_parse(data, len);
        CHECK_MSG(parsed || model_last_error()[0] != 0,
                  "%s was rejected without an error message", e->d_name);
        if (len > 0) per_parser[data[0] % REFL_FUZZ_NPARSERS]++;
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
