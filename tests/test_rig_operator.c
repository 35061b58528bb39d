// tests/test_rig_operator.c — operator steps (rig/session/session.h, rig/session/operator.c):
// the plan's operator steps and their instructions; a session pausing (exit 3)
// at its operator step when stdin is not a terminal; --yes; --operator-input
// answers consumed in order across sessions ('q' pauses at the next session's
// step, a bad line is an error naming FILE:LINE); a session killed with
// SIGKILL between the answer and the next frame resumes without asking again
// and with the virtual rig posed; refl calib geometry (its answers shared by
// its sessions), gain and lamps pausing at their operator steps; answers on a
// terminal (a pty); a journal without operator steps refused clearly; refl
// demo passing --rig and the answers to scripts/demo. The virtual rig is
// served in-process (no network).
#define _GNU_SOURCE
#include <glib.h>
#include <limits.h>
#include <poll.h>
#include <pty.h>
#include <math.h>
#include <signal.h>
#include <sqlite3.h>
#include <stdlib.h>
#include <string.h>
#include <sys/wait.h>
#include <unistd.h>

#include "model/model.h"
#include "rig/rig.h"
#include "tests/test.h"

static const char *rig_file(void)
{
    char top[PATH_MAX], text[2 * PATH_MAX];
    if (!realpath(test_srcdir(), top)) snprintf(top, sizeof top, "%s", test_srcdir());
    snprintf(text, sizeof text, "[rig]\nbackend = virtual\nserve = inprocess\ntruth = %s/examples/virtual-truth.ini\n"
             "time_scale = 0.01\n", top);
    return test_write("rig.ini", text);
}

#define WEDGE_PLAN(tilt)                                                                                     \
    "[sample]\nname = coupon_matte_paint\nkind = material_coupon\ntilt_deg = " tilt "\n[angles]\nlist = 0 20\n" \
    "[lamps]\nsets = east\n[exposure]\nmode = fixed\nlist_us = 2000\n"

// One SQL value of DIR/session.sqlite as text ("" when none).
static char *sql1(const char *dir, const char *sql)
{
    char db[4096];
    snprintf(db, sizeof db, "%s/session.sqlite", dir);
    sqlite3 *d = NULL;
    char *v = g_strdup("");
    if (sqlite3_open_v2(db, &d, SQLITE_OPEN_READONLY, NULL) == SQLITE_OK) {
        sqlite3_busy_timeout(d, 1000);
        sqlite3_stmt *s = NULL;
        if (sqlite3_prepare_v2(d, sql, -1, &s, NULL) == SQLITE_OK && sqlite3_step(s) == SQLITE_ROW &&
            sqlite3_column_text(s, 0)) {
            g_free(v);
            v = g_strdup((const char *)sqlite3_column_text(s, 0));
        }
        sqlite3_finalize(s);
    }
    sqlite3_close(d);
    return v;
}

static int sql_int(const char *dir, const char *sql)
{
    char *v = sql1(dir, sql);
    int n = v[0] ? atoi(v) : -1;
    g_free(v);
    return n;
}

TEST(operator_plan_steps_and_instructions)
{
    const char *base = "[angles]\nlist = 0\n[lamps]\nsets = none\n[exposure]\nmode = fixed\nlist_us = 100\n";
    char *t = g_strdup_printf("[sample]\nname = board\nkind = chessboard\ntilt_deg = 20\ntilt_azimuth_deg = 90\n%s",
                              base);
    rig_plan_t *p = rig_plan_parse(t, strlen(t), "a.ini");
    CHECK(p && p->nsteps == 2 && p->nops == 1);
    if (p) {
        CHECK(p->steps[0].kind == RIG_STEP_OPERATOR && p->steps[1].kind == RIG_STEP_LIGHT && p->steps[1].op == -1);
        CHECK_CONTAINS(p->ops[0].instruction, "mount the calibration board board on the 20 deg wedge (hinge at "
                       "azimuth 90 deg)");
        CHECK_CONTAINS(p->ops[0].instruction, "facing the camera");
        CHECK(p->ops[0].pose && p->ops[0].tilt_deg == 20 && p->ops[0].tilt_azimuth_deg == 90);
    }
    rig_plan_free(p);
    g_free(t);
    // [sample] instruction replaces the text; [operator] end adds a last step
    t = g_strdup_printf("[sample]\nname = ball\nkind = mirror_sphere\ninstruction = the ball on its stand\n%s"
                        "[operator]\nend = take the ball away\n", base);
    p = rig_plan_parse(t, strlen(t), "b.ini");
    CHECK(p && p->nsteps == 3 && p->nops == 2);
    if (p) {
        CHECK(!strcmp(p->ops[0].instruction, "the ball on its stand"));
        CHECK(p->steps[2].kind == RIG_STEP_OPERATOR && p->steps[2].op == 1 && !p->ops[1].pose);
        CHECK(!strcmp(p->ops[1].instruction, "take the ball away"));
    }
    rig_plan_free(p);
    g_free(t);
    t = g_strdup_printf("[sample]\nname = ball\nkind = mirror_sphere\n%s", base);
    p = rig_plan_parse(t, strlen(t), "b2.ini");
    CHECK(p && !strcmp(p->ops[0].instruction, "place the chrome ball ball at the turntable centre"));
    rig_plan_free(p);
    g_free(t);
    t = g_strdup_printf("[sample]\nname = s\nkind = uniform_source\n%s", base);
    p = rig_plan_parse(t, strlen(t), "c.ini");
    CHECK(p && strstr(p->ops[0].instruction, "put the flat-field source s in front of the lens"));
    rig_plan_free(p);
    g_free(t);
    // an empty instruction, an unknown key: errors naming file and line
    t = g_strdup_printf("[sample]\nname = s\nkind = workpiece\ninstruction =\n%s", base);
    CHECK(rig_plan_parse(t, strlen(t), "d.ini") == NULL);
    CHECK_CONTAINS(model_last_error(), "d.ini:4");
    CHECK_CONTAINS(model_last_error(), "[sample] instruction is empty");
    g_free(t);
    t = g_strdup_printf("[sample]\nname = s\nkind = workpiece\n%s[operator]\nbegin = x\n", base);
    CHECK(rig_plan_parse(t, strlen(t), "e.ini") == NULL);
    CHECK_CONTAINS(model_last_error(), "unknown key 'begin'");
    g_free(t);
}

TEST(operator_pause_without_terminal_then_yes)
{
    const char *rig = rig_file();
    const char *plan = test_write("plan.ini", WEDGE_PLAN("30"));
    const char *dir = test_path("s");
    char *out = NULL, *err = NULL;
    // stdin is /dev/null (test_run): the session pauses at its operator step
    int rc = test_refl_run(120, &out, &err, "capture", plan, "--rig", rig, "-o", dir, "--progress", "lines", NULL);
    CHECK_MSG(rc == 3, "exit %d: %s", rc, err);
    CHECK_CONTAINS(err, "OPERATOR STEP 0: put coupon coupon_matte_paint on the 30 deg wedge (hinge at azimuth 0 deg)");
    CHECK_CONTAINS(err, "stdin is not a terminal");
    CHECK_CONTAINS(err, "refl capture --resume");
    CHECK_CONTAINS(err, "--yes");
    char *state = sql1(dir, "SELECT state FROM session");
    CHECK(!strcmp(state, "paused"));
    g_free(state);
    char *st0 = sql1(dir, "SELECT kind || ' ' || status FROM steps WHERE idx = 0");
    CHECK(!strcmp(st0, "operator pending"));
    g_free(st0);
    CHECK(sql_int(dir, "SELECT count(*) FROM frames") == 0);
    CHECK(sql_int(dir, "SELECT count(*) FROM events WHERE kind = 'pause' AND step = 0") == 1);
    g_free(out);
    g_free(err);
    rc = test_refl_run(60, &out, &err, "session", "check", dir, "--allow-incomplete", NULL);
    CHECK(rc == 0);
    CHECK_CONTAINS(out, "operator step 0: not answered yet: put coupon coupon_matte_paint on the 30 deg wedge");
    CHECK_CONTAINS(out, "missing step 0: operator");
    g_free(out);
    g_free(err);
    // --yes and --operator-input together: a usage error
    rc = test_refl_run(60, &out, &err, "capture", "--resume", dir, "--yes", "--operator-input", plan, NULL);
    CHECK(rc == 2);
    CHECK_CONTAINS(err, "not both");
    g_free(out);
    g_free(err);
    // --yes answers it: the session completes; the answer is journalled
    rc = test_refl_run(120, &out, &err, "capture", "--resume", dir, "--yes", "--progress", "lines", NULL);
    CHECK_MSG(rc == 0, "exit %d: %s", rc, err);
    CHECK(sql_int(dir, "SELECT count(*) FROM frames") == 2);
    char *ev = sql1(dir, "SELECT message FROM events WHERE kind = 'operator' AND step = 0");
    CHECK_CONTAINS(ev, "done: --yes, 20");   // and the UTC time
    CHECK_CONTAINS(ev, "virtual rig: sample coupon_matte_paint posed at tilt 30 deg");
    g_free(ev);
    st0 = sql1(dir, "SELECT status FROM steps WHERE idx = 0");
    CHECK(!strcmp(st0, "done"));
    g_free(st0);
    g_free(out);
    g_free(err);
    rc = test_refl_run(60, &out, &err, "session", "check", dir, NULL);
    CHECK(rc == 0);
    CHECK_CONTAINS(out, "operator step 0: answered: put coupon");
    g_free(out);
    g_free(err);
}

TEST(operator_input_across_sessions)
{
    const char *rig = rig_file();
    const char *p1 = test_write("p1.ini", WEDGE_PLAN("0"));
    const char *p2 = test_write("p2.ini", WEDGE_PLAN("0") "[operator]\nend = take the coupon off the table\n");
    const char *answers = test_write("answers.txt", "done\n  YES \nq\n");
    rig_operator_t *op = rig_operator_open(false, answers);
    CHECK(op != NULL);
    if (!op) return;
    const char *d1 = test_path("a"), *d2 = test_path("b");
    rig_capture_opts_t o = { .plan_path = p1, .rig_path = rig, .dir = d1, .progress = 0, .op = op };
    CHECK(rig_capture_run(&o) == 0);                      // line 1: done
    CHECK(!rig_operator_paused(op));
    o.plan_path = p2;
    o.dir = d2;
    CHECK(rig_capture_run(&o) == 3);                      // line 2 answers step 0, line 3 'q' pauses the end step
    CHECK(rig_operator_paused(op));
    char *ev = sql1(d1, "SELECT message FROM events WHERE kind = 'operator'");
    CHECK_CONTAINS(ev, "answers.txt:1");
    g_free(ev);
    ev = sql1(d2, "SELECT message FROM events WHERE kind = 'operator' AND step = 0");
    CHECK_CONTAINS(ev, "answers.txt:2");
    g_free(ev);
    CHECK(sql_int(d2, "SELECT count(*) FROM frames") == 2);
    char *st = sql1(d2, "SELECT kind || ' ' || status || ' ' || note FROM steps WHERE idx = 3");
    CHECK(!strcmp(st, "operator pending take the coupon off the table"));
    g_free(st);
    ev = sql1(d2, "SELECT message FROM events WHERE kind = 'pause'");
    CHECK_CONTAINS(ev, "answers.txt:3 answered 'q'");
    g_free(ev);
    // the file is used up: end of file pauses too
    o.resume = true;
    CHECK(rig_capture_run(&o) == 3);
    ev = sql1(d2, "SELECT message FROM events WHERE kind = 'pause' ORDER BY id DESC");
    CHECK_CONTAINS(ev, "no answer left");
    g_free(ev);
    rig_operator_close(op);

    // a bad answer: an error naming FILE:LINE (refl capture: exit 1; the session can be resumed)
    const char *bad2 = test_write("bad2.txt", "maybe later\n");
    char *out = NULL, *err = NULL;
    const char *d3 = test_path("c");
    int rc = test_refl_run(120, &out, &err, "capture", p1, "--rig", rig, "-o", d3, "--operator-input", bad2, NULL);
    CHECK(rc == 1);
    CHECK_CONTAINS(err, "bad2.txt:1: 'maybe later' is not an operator answer");
    g_free(out);
    g_free(err);
    rc = test_refl_run(60, &out, &err, "capture", p1, "--rig", rig, "-o", test_path("d"), "--operator-input",
                       test_path("no-such-file"), NULL);
    CHECK(rc == 1);
    CHECK_CONTAINS(err, "--operator-input");
    CHECK_CONTAINS(err, "no-such-file");
    g_free(out);
    g_free(err);
}

// The hook: SIGKILL before the first frame (after the operator step's answer).
static void kill_at_step1(void *ctx, rig_t *r, int step)
{
    (void)ctx;
    (void)r;
    if (step == 1) kill(getpid(), SIGKILL);
}

// The hook on --resume: the virtual rig's sample tilt at the first frame.
static void pose_at_step1(void *ctx, rig_t *r, int step)
{
    if (step == 1) rig_virtual_sample_pose(r->virt, (double *)ctx, NULL, NULL, NULL);
}

// The fraction of pixels of frame 0 of two sessions that differ by more than
// 20 % + 10 DN (far beyond the sensor noise).
static double frames_differ(const char *a, const char *b)
{
    rig_session_t *sa = rig_session_open(a), *sb = rig_session_open(b);
    int wa = 0, ha = 0, wb = 0, hb = 0;
    float *fa = sa ? rig_session_frame(sa, 0, &wa, &ha) : NULL, *fb = sb ? rig_session_frame(sb, 0, &wb, &hb) : NULL;
    double frac = NAN;
    if (fa && fb && wa == wb && ha == hb) {
        size_t n = (size_t)wa * ha, k = 0;
        for (size_t i = 0; i < n; i++) k += fabsf(fa[i] - fb[i]) > 0.2f * fmaxf(fa[i], fb[i]) + 10;
        frac = (double)k / (double)n;
    }
    free(fa);
    free(fb);
    rig_session_free(sa);
    rig_session_free(sb);
    return frac;
}

TEST(operator_kill9_after_answer_resumes_posed)
{
    const char *rig = rig_file();
    const char *plan = test_write("plan.ini", WEDGE_PLAN("40"));
    const char *flat = test_write("flat.ini", WEDGE_PLAN("0"));
    const char *dir = test_path("s"), *ref = test_path("flat");
    fflush(NULL);
    pid_t pid = fork();
    if (pid == 0) {
        rig_operator_t *op = rig_operator_open(true, NULL);
        rig_capture_opts_t o = { .plan_path = plan, .rig_path = rig, .dir = dir, .progress = 0, .op = op,
                                 .before_step = kill_at_step1 };
        rig_capture_run(&o);
        _exit(0);   // not reached: killed at step 1
    }
    int st = 0;
    waitpid(pid, &st, 0);
    CHECK(WIFSIGNALED(st) && WTERMSIG(st) == SIGKILL);
    char *s0 = sql1(dir, "SELECT status FROM steps WHERE idx = 0");
    CHECK(!strcmp(s0, "done"));
    g_free(s0);
    CHECK(sql_int(dir, "SELECT count(*) FROM frames") == 0);
    // resume with no answers at all (stdin not a terminal, no --yes): the
    // answered step is not asked again, and the virtual rig has its pose
    double tilt = NAN;
    rig_capture_opts_t o = { .rig_path = rig, .dir = dir, .resume = true, .progress = 0, .before_step = pose_at_step1,
                             .hook_ctx = &tilt };
    int rc = rig_capture_run(&o);
    CHECK_MSG(rc == 0, "resume: exit %d: %s", rc, model_last_error());
    CHECK_NEAR(tilt, 40, 0);
    CHECK(sql_int(dir, "SELECT count(*) FROM events WHERE kind = 'operator'") == 1);
    char *ev = sql1(dir, "SELECT message FROM events WHERE kind = 'info' AND step = 0");
    CHECK_CONTAINS(ev, "answered earlier, not asked again");
    CHECK_CONTAINS(ev, "posed at tilt 40 deg");
    g_free(ev);
    // the frames are of the posed sample: they differ from the flat one's
    rig_operator_t *yes = rig_operator_open(true, NULL);
    rig_capture_opts_t f = { .plan_path = flat, .rig_path = rig, .dir = ref, .progress = 0, .op = yes };
    CHECK(rig_capture_run(&f) == 0);
    rig_operator_close(yes);
    double d = frames_differ(dir, ref);
    fprintf(stderr, "  pixels that differ between the 40 deg wedge and the flat coupon: %.2f %%\n", 100 * d);
    CHECK(d > 0.01);
}

TEST(operator_calibrations_pause)
{
    const char *rig = rig_file();
    const char *dir = test_path("geo");
    char *out = NULL, *err = NULL;
    int rc = test_refl_run(120, &out, &err, "calib", "geometry", "--rig", rig, "-o", dir, NULL);
    CHECK_MSG(rc == 3, "exit %d: %s", rc, err);
    CHECK_CONTAINS(err, "OPERATOR STEP 0: lay the calibration board calib_board flat at the turntable centre, "
                        "printed side up (no wedge");
    CHECK(!strstr(err, "refl capture: homing"));   // nothing moved before the operator's answer
    CHECK_CONTAINS(err, "run the same command again");
    g_free(out);
    g_free(err);
    // answers: the first tilt's session done, 'q' at the second tilt's operator step
    const char *answers = test_write("answers.txt", "done\nq\n");
    rc = test_refl_run(300, &out, &err, "calib", "geometry", "--rig", rig, "-o", dir, "--operator-input", answers,
                       NULL);
    CHECK_MSG(rc == 3, "exit %d: %s", rc, err);
    CHECK_CONTAINS(err, "answers.txt:1");
    CHECK_CONTAINS(err, "(2 of 8)");
    char *cap = g_strdup_printf("%s/capture", dir);
    GDir *d = g_dir_open(cap, 0, NULL);
    g_free(cap);
    int complete = 0, paused = 0;
    for (const char *e; d && (e = g_dir_read_name(d));) {
        if (g_str_has_suffix(e, ".ini")) continue;
        char *sd = g_strdup_printf("%s/capture/%s", dir, e);
        char *state = sql1(sd, "SELECT state FROM session");
        complete += !strcmp(state, "complete");
        paused += !strcmp(state, "paused");
        g_free(state);
        g_free(sd);
    }
    if (d) g_dir_close(d);
    CHECK(complete == 1 && paused == 1);
    g_free(out);
    g_free(err);
    // calib gain and calib lamps pause the same way, with their own instructions
    rc = test_refl_run(120, &out, &err, "calib", "gain", "--rig", rig, "-o", test_path("gain"), NULL);
    CHECK_MSG(rc == 3, "calib gain: exit %d: %s", rc, err);
    CHECK_CONTAINS(err, "put the flat-field source flat_field in front of the lens");
    g_free(out);
    g_free(err);
    char cam[PATH_MAX + 64], top[PATH_MAX];
    if (!realpath(test_srcdir(), top)) snprintf(top, sizeof top, "%s", test_srcdir());
    snprintf(cam, sizeof cam, "%s/examples/camera.cameramodel", top);
    rc = test_refl_run(120, &out, &err, "calib", "lamps", "--rig", rig, "--camera", cam, "--sphere-centre-mm",
                       "60,0,40", "--sphere-radius-mm", "25", "-o", test_path("lamps"), NULL);
    CHECK_MSG(rc == 3, "calib lamps: exit %d: %s", rc, err);
    CHECK_CONTAINS(err, "place the chrome ball mirror_sphere at the table centre: its centre at (60, 0, 40) mm");
    g_free(out);
    g_free(err);
}

TEST(operator_demo_arguments)
{
    char *out = NULL, *err = NULL;
    // refl demo passes --rig and the answers to scripts/demo, which checks them before anything runs
    int rc = test_refl_run(60, &out, &err, "demo", "-o", test_path("d"), "--rig", test_path("no-rig.ini"), "--yes",
                           NULL);
    CHECK_MSG(rc == 1, "exit %d: %s", rc, err);
    CHECK_CONTAINS(err, "no-rig.ini: cannot read the rig file");
    g_free(out);
    g_free(err);
    rc = test_refl_run(60, &out, &err, "demo", "-o", test_path("d"), "--operator-input", test_path("none.txt"), NULL);
    CHECK_MSG(rc == 1, "exit %d: %s", rc, err);
    CHECK_CONTAINS(err, "--operator-input");
    CHECK_CONTAINS(err, "none.txt: cannot read it");
    g_free(out);
    g_free(err);
    rc = test_refl_run(60, &out, &err, "demo", "--yes", "--operator-input", "x", NULL);
    CHECK(rc == 2);
    CHECK_CONTAINS(err, "not both");
    g_free(out);
    g_free(err);
}

// Read the pty's output until `want` appears (or EOF / timeout); returns whether it did.
static bool pty_wait(int fd, GString *seen, const char *want, double timeout_s)
{
    double t0 = model_now_s();
    while (!strstr(seen->str, want)) {
        if (model_now_s() - t0 > timeout_s) return false;
        struct pollfd p = { fd, POLLIN, 0 };
        if (poll(&p, 1, 100) <= 0) continue;
        char buf[4096];
        ssize_t n = read(fd, buf, sizeof buf);
        if (n <= 0) return strstr(seen->str, want) != NULL;
        g_string_append_len(seen, buf, n);
    }
    return true;
}

TEST(operator_terminal_answers)
{
    const char *rig = rig_file();
    const char *plan = test_write("plan.ini", WEDGE_PLAN("20"));
    const char *dir = test_path("s");
    int master = -1;
    fflush(NULL);
    pid_t pid = forkpty(&master, NULL, NULL, NULL);
    CHECK(pid >= 0);
    if (pid < 0) return;
    if (pid == 0) {
        execl(test_refl(), test_refl(), "capture", plan, "--rig", rig, "-o", dir, "--progress", "lines", (char *)NULL);
        _exit(127);
    }
    GString *seen = g_string_new("");
    CHECK(pty_wait(master, seen, "press Enter when done, q to pause: ", 60));
    CHECK_CONTAINS(seen->str, "OPERATOR STEP 0: put coupon coupon_matte_paint on the 20 deg wedge");
    CHECK(write(master, "perhaps\n", 8) == 8);   // not an answer: asked again
    CHECK(pty_wait(master, seen, "'perhaps' is not an answer", 30));
    CHECK(write(master, "\n", 1) == 1);           // Enter: done
    CHECK(pty_wait(master, seen, "complete", 60));
    int st = 0;
    waitpid(pid, &st, 0);
    close(master);
    CHECK_MSG(WIFEXITED(st) && WEXITSTATUS(st) == 0, "status %d: %s", st, seen->str);
    char *ev = sql1(dir, "SELECT message FROM events WHERE kind = 'operator'");
    CHECK_CONTAINS(ev, "done: terminal, 20");
    g_free(ev);
    CHECK(sql_int(dir, "SELECT count(*) FROM frames") == 2);
    g_string_free(seen, TRUE);
}

TEST(operator_resume_of_an_older_session_is_refused_clearly)
{
    const char *rig = rig_file();
    const char *plan = test_write("plan.ini", WEDGE_PLAN("0"));
    const char *dir = test_path("s");
    char *out = NULL, *err = NULL;
    int rc = test_refl_run(120, &out, &err, "capture", plan, "--rig", rig, "-o", dir, NULL);
    CHECK(rc == 3);
    g_free(out);
    g_free(err);
    // a journal as a refl without operator steps wrote it: no step 0
    char db[4096];
    snprintf(db, sizeof db, "%s/session.sqlite", dir);
    sqlite3 *d = NULL;
    CHECK(sqlite3_open(db, &d) == SQLITE_OK);
    CHECK(sqlite3_exec(d, "DELETE FROM steps WHERE idx = 0", NULL, NULL, NULL) == SQLITE_OK);
    sqlite3_close(d);
    rc = test_refl_run(120, &out, &err, "capture", "--resume", dir, "--yes", NULL);
    CHECK(rc == 1);
    CHECK_CONTAINS(err, "2 steps stored, the plan makes 3 (the stored steps begin without the plan's operator step");
    g_free(out);
    g_free(err);
}

static int count_of(const char *hay, const char *needle)
{
    int n = 0;
    for (const char *p = hay ? strstr(hay, needle) : NULL; p; p = strstr(p + 1, needle)) n++;
    return n;
}

// The lab day (refl demo, scripts/demo) on the virtual rig with scripted
// answers: one answer pauses it (exit 3) at the next operator step; run again
// with answers enough, it goes on where it stopped (the complete session kept,
// the answered step not asked again), asks every step once, in the day's
// order, up to the last coupon (--until captures: the rig's work before the
// offline fits; the whole day is make demo's), and stops there saying so.
TEST_LONG(operator_lab_day_scripted)
{
    const char *dir = test_path("day");
    const char *one = test_write("answers-1.txt", "done\n");
    GString *many = g_string_new("");
    for (int i = 0; i < 60; i++) g_string_append(many, "done\n");
    char *all = g_strdup(test_write("answers-all.txt", many->str));
    g_string_free(many, TRUE);

    char *out = NULL, *err = NULL, *log1 = NULL, *log2 = NULL;
    int rc = test_refl_run(300, &out, &err, "demo", "-o", dir, "--operator-input", one, NULL);
    CHECK_MSG(rc == 3, "first run (one answer): exit %d\n%s", rc, err ? err : "");
    CHECK_CONTAINS(err, "run the demo again with the same arguments");
    char *logp = g_build_filename(dir, "demo.log", NULL);
    CHECK(g_file_get_contents(logp, &log1, NULL, NULL));
    // the workpiece session's step answered by line 1, the next step paused at the end of the answers
    CHECK(count_of(log1, "OPERATOR STEP") == 2);
    CHECK(count_of(log1, "answered done (--operator-input") == 1);
    CHECK_CONTAINS(log1, "no answer left (end of file after line ");
    const char *first = log1 ? strstr(log1, "OPERATOR STEP 0: ") : NULL;
    char first_instr[300] = "";
    if (first) sscanf(first, "%299[^\n]", first_instr);
    CHECK(first_instr[0] != 0);
    g_free(out);
    g_free(err);

    rc = test_refl_run(900, &out, &err, "demo", "-o", dir, "--operator-input", all, "--until", "captures", NULL);
    CHECK_MSG(rc == 0, "second run: exit %d\n%s", rc, err ? err : "");
    CHECK(g_file_get_contents(logp, &log2, NULL, NULL));
    int asked = count_of(log2, "OPERATOR STEP"), answered = count_of(log2, "answered done (--operator-input");
    fprintf(stderr, "  the day's second run: %d operator steps asked, %d answered\n", asked, answered);
    CHECK(asked >= 16 && answered == asked);
    CHECK_CONTAINS(out, "stopped after the captures (--until captures)");
    CHECK_CONTAINS(out, "complete, kept");           // the workpiece session of the first run
    // not asked again: the run goes on at the board (the workpiece comes back only for the verification)
    const char *first2 = log2 ? strstr(log2, "OPERATOR STEP") : NULL;
    CHECK(first2 && strncmp(first2, first_instr, strlen(first_instr)) != 0);
    CHECK(count_of(log2, first_instr) <= 1);
    CHECK(first2 && strstr(first2, "calibration board") && strstr(first2, "calibration board") < strchr(first2, '\n'));
    // in the day's order: the board first, then the mirror ball, the flat-field source, the white, the coupons
    const char *order[] = { "calibration board", "ball", "flat-field", "white", "glossy", "plywood", "steel" };
    const char *at = log2;
    for (size_t i = 0; at && i < sizeof order / sizeof order[0]; i++) {
        const char *p = strstr(at, order[i]);
        CHECK_MSG(p != NULL, "'%s' not asked after the step before it", order[i]);
        at = p;
    }
    // the coupons captured, nothing fitted yet
    char *steel = g_build_filename(dir, "session_painted_steel", "session.sqlite", NULL);
    char *priors = g_build_filename(dir, "priors_glossy.json", NULL);
    CHECK(g_file_test(steel, G_FILE_TEST_EXISTS));
    CHECK(!g_file_test(priors, G_FILE_TEST_EXISTS));
    g_free(steel);
    g_free(priors);
    g_free(logp);
    g_free(log1);
    g_free(log2);
    g_free(out);
    g_free(err);
    g_free(all);
}
