// tests/test_model_base.c — the shared base every layer uses: notices and their
// sink, running a tool, 8-bit PNG, JSON numbers, 3x3 matrices.
#include <glib.h>
#include <stdlib.h>
#include <string.h>

#include "model/model.h"
#include "model/base/report.h"
#include "model/base/vec.h"
#include "tests/test.h"

typedef struct {
    int  n[4];
    char last[256];
} seen_t;

static void catch_notice(void *ctx, model_notice_kind_t kind, const char *text)
{
    seen_t *s = ctx;
    s->n[kind]++;
    snprintf(s->last, sizeof s->last, "%s", text);
}

TEST(model_notice_sink_and_quiet)
{
    seen_t s;
    memset(&s, 0, sizeof s);
    bool q = model_error_quiet(false);
    model_notice_sink(catch_notice, &s);
    model_note("solving from %d views", 40);
    CHECK(s.n[MODEL_NOTICE_NOTE] == 1);
    CHECK(!strcmp(s.last, "solving from 40 views"));
    model_warning("lamp %s: %.1f %% drift", "north", 2.5);
    CHECK(s.n[MODEL_NOTICE_WARNING] == 1);
    CHECK(!strcmp(s.last, "lamp north: 2.5 % drift"));
    model_progress("step %d/%d", 3, 12);
    model_progress_end();
    CHECK(s.n[MODEL_NOTICE_PROGRESS] == 1 && s.n[MODEL_NOTICE_PROGRESS_END] == 1);
    model_error_quiet(true);   // quiet mode (the tests' own) drops every notice
    model_note("dropped");
    model_warning("dropped");
    CHECK(s.n[MODEL_NOTICE_NOTE] == 1 && s.n[MODEL_NOTICE_WARNING] == 1);
    model_notice_sink(NULL, NULL);
    model_error_quiet(q);
}

TEST(model_notice_default_sink_prefix)
{
    // the default sink names the command the dispatcher set, never the library
    model_notice_prefix("refl calib geometry");
    CHECK(!strcmp(model_notice_prefix_text(), "refl calib geometry"));
    model_notice_prefix(NULL);
    CHECK(!strcmp(model_notice_prefix_text(), "refl"));
    char long_name[400];
    memset(long_name, 'x', sizeof long_name - 1);
    long_name[sizeof long_name - 1] = 0;
    model_notice_prefix(long_name);   // cut to the buffer, never overrun
    CHECK(strlen(model_notice_prefix_text()) == 127);
    model_notice_prefix(NULL);
}

TEST(model_run_tool_status_and_output)
{
    char *out = NULL;
    const char *log = test_path("tool.log");
    char *ok_argv[] = { "sh", "-c", "echo hello; echo note >&2", NULL };
    CHECK(model_run_tool(NULL, ok_argv, log, &out, NULL) == 0);
    CHECK(out && !strcmp(out, "hello\n"));
    g_free(out);
    char *text = model_read_file(log, NULL);
    CHECK_CONTAINS(text, "# stderr:\nnote");
    free(text);
    char *bad_argv[] = { "sh", "-c", "echo 'the board was not found' >&2; exit 3", NULL };
    CHECK(model_run_tool(NULL, bad_argv, NULL, NULL, NULL) == 3);
    CHECK_CONTAINS(model_last_error(), "exit status 3");
    CHECK_CONTAINS(model_last_error(), "the board was not found");
    char *missing[] = { "refl-no-such-tool-here", NULL };
    CHECK(model_run_tool(NULL, missing, NULL, NULL, "Debian: apt install it") == -1);
    CHECK_CONTAINS(model_last_error(), "refl-no-such-tool-here");
    CHECK_CONTAINS(model_last_error(), "apt install it");
    char *sig[] = { "sh", "-c", "kill -TERM $$", NULL };
    CHECK(model_run_tool(NULL, sig, NULL, NULL, NULL) == 128 + 15);
}

TEST(model_png8_write_reads_back)
{
    uint8_t pix[6 * 4];
    for (int i = 0; i < 24; i++) pix[i] = (uint8_t)(i * 11);
    const char *meta[] = { "what", "a test", NULL };
    const char *p = test_path("g8.png");
    CHECK(model_png8_write(p, 6, 4, pix, meta));
    int w = 0, h = 0;
    uint16_t *back = NULL;
    CHECK(model_png_read(p, &w, &h, &back));
    CHECK(w == 6 && h == 4);
    int bad = 0;
    for (int i = 0; back && i < 24; i++) bad += back[i] != pix[i];
    CHECK(bad == 0);
    free(back);
    bool q = model_error_quiet_thread(true);
    CHECK(!model_png8_write(test_path("no/such/dir/x.png"), 6, 4, pix, NULL));
    model_error_quiet_thread(q);
}

TEST(model_json_number_null_for_not_finite)
{
    json_t *a = model_json_number(1.5), *b = model_json_number(NAN), *c = model_json_number(INFINITY);
    CHECK(json_is_real(a) && json_real_value(a) == 1.5);
    CHECK(json_is_null(b) && json_is_null(c));
    json_decref(a);
    json_decref(b);
    json_decref(c);
}

TEST(model_m3_known_answers)
{
    double a[9] = { 2, 1, 0, 0, 3, 1, 1, 0, 4 }, b[9] = { 1, 2, 3, 4, 5, 6, 7, 8, 9 };
    double ab[9], abt[9], atb[9], ai[9], eye[9], at[9], v[3];
    m3_mul(ab, a, b);
    CHECK(ab[0] == 6 && ab[1] == 9 && ab[2] == 12 && ab[4] == 23 && ab[8] == 39);
    m3_transpose(at, b);
    m3_mul(eye, a, at);
    m3_mul_bt(abt, a, b);
    for (int k = 0; k < 9; k++) CHECK(abt[k] == eye[k]);
    m3_transpose(at, a);
    m3_mul(eye, at, b);
    m3_mul_at(atb, a, b);
    for (int k = 0; k < 9; k++) CHECK(atb[k] == eye[k]);
    CHECK(m3_inv(ai, a));
    m3_mul(eye, a, ai);
    for (int k = 0; k < 9; k++) CHECK_NEAR(eye[k], k % 4 == 0 ? 1.0 : 0.0, 1e-14);
    m3_mul(ab, a, b);   // the output may alias an input
    m3_mul(a, a, b);
    for (int k = 0; k < 9; k++) CHECK(a[k] == ab[k]);
    double x[3] = { 1, -1, 2 };
    m3_vec(v, b, x);
    CHECK(v[0] == 5 && v[1] == 11 && v[2] == 17);
    double sing[9] = { 1, 2, 3, 2, 4, 6, 0, 0, 1 };
    CHECK(!m3_inv(ai, sing));
}

TEST(model_json_format_versions)
{
    json_t *o = json_object();
    model_json_set_format(o, "refl-gain", 2);
    int v = 0;
    CHECK(model_json_format_check(o, "g.json", "refl-gain", 2, &v) && v == 2);
    CHECK(!model_json_format_check(o, "g.json", "refl-gain", 1, &v));   // newer than this reader
    CHECK_CONTAINS(model_last_error(), "g.json: refl-gain version 2, written by a newer refl");
    CHECK(!model_json_format_check(o, "g.json", "refl-lamps", 3, &v));  // another format
    CHECK_CONTAINS(model_last_error(), "a refl-gain file, not refl-lamps");
    json_t *bare = json_pack("{s:f}", "k_dn_per_e", 0.5);               // before formats named themselves
    CHECK(model_json_format_check(bare, "old.json", "refl-gain", 2, &v) && v == 1);
    json_object_set_new(bare, "format", json_string("refl-gain"));      // a format without its version
    CHECK(!model_json_format_check(bare, "old.json", "refl-gain", 2, &v));
    CHECK_CONTAINS(model_last_error(), "\"version\" is missing");
    json_t *arr = json_array();
    CHECK(!model_json_format_check(arr, "a.json", "refl-gain", 2, NULL));
    json_decref(o);
    json_decref(bare);
    json_decref(arr);
}

// A list of numbers: separators folded, each in range, at most max; anything else -1.
TEST(model_parse_doubles_lists)
{
    double v[4];
    CHECK(model_parse_doubles("1, 2,,3", ", ", 0, 10, v, 4) == 3 && v[0] == 1 && v[1] == 2 && v[2] == 3);
    CHECK(model_parse_doubles(" 0.5\t-1 ", " \t,", -1, 1, v, 4) == 2 && v[1] == -1);
    CHECK(model_parse_doubles("1,2,3,4,5", ",", 0, 10, v, 4) == -1);   // too many
    CHECK(model_parse_doubles("1,x", ",", 0, 10, v, 4) == -1);         // not a number
    CHECK(model_parse_doubles("1,11", ",", 0, 10, v, 4) == -1);        // out of range
    CHECK(model_parse_doubles(" , ", ", ", 0, 10, v, 4) == -1);        // none
    CHECK(model_parse_doubles(NULL, ",", 0, 10, v, 4) == -1);
}
