// tests/test_rig_capture.c — `refl capture` and `refl session` on the virtual rig:
// a session killed with SIGKILL at 10 random steps (fixed seed) and resumed
// each time equals an uninterrupted one (same step rows, every hash valid, no
// duplicate or missing frame; pixel values differ: the virtual camera's noise
// seed counts frames per process); --dry-run; resume refusing a changed plan;
// export; a full disk (a 3 MB tmpfs where mount is allowed, and everywhere an
// ENOSPC injected by tests/enospc_shim.c); a
// camera that stops answering (in-process, triggers dropped through the
// before_step hook); a stalled turntable (truth file with fault keys); the
// session subcommands' help; refl session check of a paused session (missing
// steps, --allow-incomplete, SQLite's integrity check); --resume refusing a
// changed rig file (named) and another camera (both serials); the ETA after
// --resume.
//
// Only one virtual camera serves 127.0.0.1 at a time: these tests hold the
// lock of tests/test_rig_camera_aravis.c throughout.
#define _GNU_SOURCE
#include <errno.h>
#include <fcntl.h>
#include <glib.h>
#include <limits.h>
#include <signal.h>
#include <sqlite3.h>
#include <stdarg.h>
#include <stdlib.h>
#include <sys/file.h>
#include <sys/mount.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include "model/model.h"
#include "rig/virtual/gv_camera.h"
#include "rig/rig.h"
#include "tests/test.h"

#define refl(out, err, ...) test_refl_run(120, out, err, __VA_ARGS__)



static const char *rig_file(const char *name, const char *truth)
{
    char top[PATH_MAX], text[3 * PATH_MAX];
    if (!realpath(test_srcdir(), top)) snprintf(top, sizeof top, "%s", test_srcdir());
    char t[PATH_MAX + 64];
    if (truth) snprintf(t, sizeof t, "%s", truth);
    else snprintf(t, sizeof t, "%s/examples/virtual-truth.ini", top);
    snprintf(text, sizeof text, "[rig]\nbackend = virtual\ntruth = %s\ntime_scale = 0.01\nbusy_wait_s = 60\n", t);
    return test_write(name, text);
}

#define SMALL_PLAN                                                                                     \
    "[sample]\nname = coupon_matte_paint\nkind = material_coupon\n[angles]\nrange = 0 25 5\n"          \
    "[lamps]\nsets = east; west\n[exposure]\nmode = fixed\nlist_us = 1000 4000\n[capture]\nsettle_ms = 5\n"

static int count_frames(const char *dir)
{
    char db[4096];
    snprintf(db, sizeof db, "%s/session.sqlite", dir);
    sqlite3 *d = NULL;
    int n = -1;
    if (sqlite3_open_v2(db, &d, SQLITE_OPEN_READONLY, NULL) == SQLITE_OK) {
        sqlite3_busy_timeout(d, 1000);
        sqlite3_stmt *s = NULL;
        if (sqlite3_prepare_v2(d, "SELECT count(*) FROM frames", -1, &s, NULL) == SQLITE_OK &&
            sqlite3_step(s) == SQLITE_ROW)
            n = sqlite3_column_int(s, 0);
        sqlite3_finalize(s);
    }
    sqlite3_close(d);
    return n;
}

// "idx kind angle lamps exposure status" of every step.
static char *step_rows(const char *dir)
{
    char db[4096];
    snprintf(db, sizeof db, "%s/session.sqlite", dir);
    sqlite3 *d = NULL;
    GString *g = g_string_new("");
    if (sqlite3_open_v2(db, &d, SQLITE_OPEN_READONLY, NULL) == SQLITE_OK) {
        sqlite3_stmt *s = NULL;
        if (sqlite3_prepare_v2(d, "SELECT idx,kind,angle_deg,lamps,exposure_us,status FROM steps ORDER BY idx", -1,
                               &s, NULL) == SQLITE_OK)
            while (sqlite3_step(s) == SQLITE_ROW)
                g_string_append_printf(g, "%d %s %g %s %g %s\n", sqlite3_column_int(s, 0), sqlite3_column_text(s, 1),
                                       sqlite3_column_double(s, 2), sqlite3_column_text(s, 3),
                                       sqlite3_column_double(s, 4), sqlite3_column_text(s, 5));
        sqlite3_finalize(s);
    }
    sqlite3_close(d);
    return g_string_free(g, FALSE);
}

static int count_events(const char *dir, const char *kind)
{
    char db[4096], sql[256];
    snprintf(db, sizeof db, "%s/session.sqlite", dir);
    snprintf(sql, sizeof sql, "SELECT count(*) FROM events WHERE kind='%s'", kind);
    sqlite3 *d = NULL;
    int n = -1;
    if (sqlite3_open_v2(db, &d, SQLITE_OPEN_READONLY, NULL) == SQLITE_OK) {
        sqlite3_stmt *s = NULL;
        if (sqlite3_prepare_v2(d, sql, -1, &s, NULL) == SQLITE_OK && sqlite3_step(s) == SQLITE_ROW)
            n = sqlite3_column_int(s, 0);
        sqlite3_finalize(s);
    }
    sqlite3_close(d);
    return n;
}

static int files_in(const char *dir, int *tmp)
{
    GDir *d = g_dir_open(dir, 0, NULL);
    int n = 0;
    *tmp = 0;
    for (const char *e; d && (e = g_dir_read_name(d));) {
        if (e[0] == '.') (*tmp)++;
        else n++;
    }
    if (d) g_dir_close(d);
    return n;
}

// Start refl capture; kill it with SIGKILL once `at` frames are committed
// (at least one more than now, so every run gets going). Returns true when it
// was killed (false: it finished first).
static bool run_and_kill(const char *const *argv, const char *dir, int at)
{
    int now = count_frames(dir);
    if (at <= now) at = now + 1;
    pid_t pid = fork();
    if (pid == 0) {
        int null = open("/dev/null", O_WRONLY);
        dup2(null, 1);
        dup2(null, 2);
        execv(argv[0], (char *const *)argv);
        _exit(127);
    }
    bool killed = false;
    for (int i = 0; i < 60000; i++) {
        int st;
        if (waitpid(pid, &st, WNOHANG) == pid) return false;
        if (count_frames(dir) >= at) {
            kill(pid, SIGKILL);
            killed = true;
            break;
        }
        usleep(2000);
    }
    if (!killed) kill(pid, SIGKILL);
    int st;
    waitpid(pid, &st, 0);
    return killed;
}

TEST(capture_kill9_resume_equals_uninterrupted)
{
    int lk = test_camera_lock();
    const char *rig = rig_file("rig.ini", NULL);
    const char *plan = test_write("plan.ini", SMALL_PLAN);
    char ref[4096], dir[4096];
    snprintf(ref, sizeof ref, "%s/ref", test_tmpdir());
    snprintf(dir, sizeof dir, "%s/killed", test_tmpdir());
    char *out = NULL, *err = NULL;
    int rc = refl(&out, &err, "capture", "--yes", plan, "--rig", rig, "-o", ref, "--progress", "lines", NULL);
    CHECK_MSG(rc == 0, "rc %d: %s", rc, err);
    CHECK_CONTAINS(out, "frames: 24");
    CHECK_CONTAINS(err, "step 25/25");   // step 1 of 25: the operator step
    g_free(out);
    g_free(err);

    // 10 kill points at random steps (fixed seed), increasing
    GRand *g = g_rand_new_with_seed(12345);
    int at[10], n = 0;
    while (n < 10) {
        int v = g_rand_int_range(g, 1, 23);
        bool dup = false;
        for (int i = 0; i < n; i++) dup |= at[i] == v;
        if (!dup) at[n++] = v;
    }
    g_rand_free(g);
    for (int i = 0; i < 10; i++)
        for (int k = i + 1; k < 10; k++)
            if (at[k] < at[i]) {
                int t = at[i];
                at[i] = at[k];
                at[k] = t;
            }
    const char *first[] = { test_refl(), "capture", "--yes", plan, "--rig", rig, "-o", dir, NULL };
    const char *resume[] = { test_refl(), "capture", "--yes", "--resume", dir, NULL };
    int kills = 0;
    for (int i = 0; i < 10; i++) kills += run_and_kill(i ? resume : first, dir, at[i]);
    CHECK_MSG(kills >= 8, "only %d of 10 runs were killed before finishing", kills);
    rc = refl(&out, &err, "capture", "--yes", "--resume", dir, NULL);
    CHECK_MSG(rc == 0, "final resume rc %d: %s", rc, err);
    g_free(out);
    g_free(err);

    char *a = step_rows(ref), *b = step_rows(dir);
    CHECK(strlen(a) > 100);
    CHECK_MSG(!strcmp(a, b), "step rows differ:\n%s\nvs\n%s", a, b);
    g_free(a);
    g_free(b);
    CHECK(count_frames(dir) == 24);
    CHECK(count_events(dir, "resume") == 10);
    char fr[4200];
    int tmp = 0;
    snprintf(fr, sizeof fr, "%s/frames", dir);
    CHECK(files_in(fr, &tmp) == 24);
    CHECK(tmp == 0);
    rc = refl(&out, &err, "session", "check", dir, NULL);
    CHECK_MSG(rc == 0, "check rc %d: %s %s", rc, out, err);
    CHECK_CONTAINS(out, "frames_verified: 24");
    CHECK_CONTAINS(out, "frames_bad: 0");
    CHECK_CONTAINS(out, "steps_missing: 0");
    g_free(out);
    g_free(err);

    // a damaged frame is found
    snprintf(fr, sizeof fr, "%s/frames/s000003.png", dir);
    FILE *f = fopen(fr, "r+b");
    if (f) {
        fseek(f, 100, SEEK_SET);
        fputc(0x55, f);
        fputc(0xAA, f);
        fclose(f);
    }
    rc = refl(&out, &err, "session", "check", dir, NULL);
    CHECK(rc == 1);
    CHECK_CONTAINS(out, "BAD HASH step 3");
    g_free(out);
    g_free(err);

    // export
    rc = refl(&out, &err, "session", "export", ref, "--format", "csv", NULL);
    CHECK(rc == 0);
    CHECK_CONTAINS(out, "step,file,sha256");
    CHECK_CONTAINS(out, "24,frames/s000024.png,");   // step 0: the operator step, no frame
    g_free(out);
    g_free(err);
    rc = refl(&out, &err, "session", "export", ref, "--format", "json", NULL);
    CHECK(rc == 0);
    CHECK_CONTAINS(out, "\"file\": \"frames/s000024.png\"");
    CHECK_CONTAINS(out, "\"format\": \"refl-session-frames\",\n \"version\": 1,\n \"frames\": [");
    g_free(out);
    g_free(err);

    // resume of a complete session: nothing to do; a changed plan is refused
    rc = refl(&out, &err, "capture", "--yes", "--resume", ref, NULL);
    CHECK(rc == 0);
    CHECK_CONTAINS(out, "complete");
    g_free(out);
    g_free(err);
    test_camera_unlock(lk);
}

TEST_ALONE(capture_dry_run_and_changed_plan)
{
    int lk = test_camera_lock();
    const char *rig = rig_file("rig.ini", NULL);
    const char *plan = test_write("plan.ini", SMALL_PLAN);
    char *out = NULL, *err = NULL;
    int rc = refl(&out, &err, "capture", "--yes", plan, "--rig", rig, "--dry-run", NULL);
    CHECK_MSG(rc == 0, "%s", err);
    CHECK_CONTAINS(out, "steps: 25 (1 operator step; 24 frames: 6 angles x 2 lamp sets x 2 exposures");
    CHECK_CONTAINS(out, "     0  operator: put coupon coupon_matte_paint flat at the turntable centre\n");
    CHECK_CONTAINS(out, "estimated_duration_s:");
    CHECK_CONTAINS(out, "estimated_disk_bytes: 62914560");
    g_free(out);
    g_free(err);
    // a lamp the rig does not have: the line of sets
    const char *bad = test_write("bad.ini", "[sample]\nname = coupon_matte_paint\nkind = material_coupon\n[angles]\n"
                                 "list = 0\n[lamps]\nsets = east; skylight\n[exposure]\nmode = fixed\nlist_us = 100\n");
    rc = refl(&out, &err, "capture", "--yes", bad, "--rig", rig, "--dry-run", NULL);
    CHECK(rc == 1);
    CHECK_CONTAINS(err, "bad.ini:7");
    CHECK_CONTAINS(err, "no lamp 'skylight'");
    g_free(out);
    g_free(err);
    // an exposure the camera refuses (the virtual camera: 10 .. 10e6 us)
    bad = test_write("bad2.ini", "[sample]\nname = coupon_matte_paint\nkind = material_coupon\n[angles]\n"
                     "list = 0\n[lamps]\nsets = east\n[exposure]\nmode = fixed\nlist_us = 100 5e7\n");
    rc = refl(&out, &err, "capture", "--yes", bad, "--rig", rig, "--dry-run", NULL);
    CHECK(rc == 1);
    CHECK_CONTAINS(err, "bad2.ini:10");
    CHECK_CONTAINS(err, "does not accept 5e+07 us");
    g_free(out);
    g_free(err);
    // a paused session (SIGINT) then a changed plan: refused; --allow-changed continues
    char dir[4096];
    snprintf(dir, sizeof dir, "%s/s", test_tmpdir());
    const char *argv[] = { test_refl(), "capture", "--yes", plan, "--rig", rig, "-o", dir, NULL };
    pid_t pid = fork();
    if (pid == 0) {
        int null = open("/dev/null", O_WRONLY);
        dup2(null, 1);
        dup2(null, 2);
        execv(argv[0], (char *const *)argv);
        _exit(127);
    }
    for (int i = 0; i < 20000 && count_frames(dir) < 3; i++) usleep(2000);
    kill(pid, SIGINT);
    int st = 0;
    waitpid(pid, &st, 0);
    CHECK_MSG(WIFEXITED(st) && WEXITSTATUS(st) == 3, "SIGINT: status %d", st);
    CHECK(count_events(dir, "pause") == 1);
    int done = count_frames(dir);
    CHECK(done >= 3 && done < 24);
    test_write("plan.ini", SMALL_PLAN "# changed\n");
    rc = refl(&out, &err, "capture", "--yes", "--resume", dir, NULL);
    CHECK(rc == 1);
    CHECK_CONTAINS(err, "changed since the session started");
    CHECK_CONTAINS(err, "--allow-changed");
    g_free(out);
    g_free(err);
    rc = refl(&out, &err, "capture", "--yes", "--resume", dir, "--allow-changed", NULL);
    CHECK_MSG(rc == 0, "%s", err);
    g_free(out);
    g_free(err);
    CHECK(count_frames(dir) == 24);
    // an existing session directory is not overwritten
    rc = refl(&out, &err, "capture", "--yes", plan, "--rig", rig, "-o", dir, NULL);
    CHECK(rc == 1);
    CHECK_CONTAINS(err, "already holds a session");
    g_free(out);
    g_free(err);
    test_camera_unlock(lk);
}

// A capture into dir that runs out of space (env: NULL-terminated extra
// environment, e.g. the ENOSPC shim's) stops cleanly: no temporary file left,
// every frame written is journalled and valid, the fault is in the event log.
static void disk_full_body(const char *dir, const char *const *env)
{
    int lk = test_camera_lock();
    const char *rig = rig_file("rig.ini", NULL);
    const char *plan = test_write("plan.ini", SMALL_PLAN);
    const char *argv[32];
    int k = 0;
    if (env) {
        argv[k++] = "env";
        while (*env) argv[k++] = *env++;
    }
    const char *rest[] = { test_refl(), "capture", "--yes", plan, "--rig", rig, "-o", dir, NULL };
    for (int i = 0; rest[i]; i++) argv[k++] = rest[i];
    argv[k] = NULL;
    char *out = NULL, *err = NULL;
    int rc = test_run(argv, 120, &out, &err);
    CHECK(rc == 1);
    CHECK_CONTAINS(err, "disk full");
    CHECK_CONTAINS(err, "refl capture --resume");
    g_free(out);
    g_free(err);
    char fr[4300];
    int tmp = 0;
    snprintf(fr, sizeof fr, "%s/frames", dir);
    int n = files_in(fr, &tmp);
    CHECK(tmp == 0);
    CHECK(n >= 1 && n < 24);
    CHECK(n == count_frames(dir));
    CHECK(count_events(dir, "fault") >= 1);
    rc = refl(&out, &err, "session", "check", dir, "--allow-incomplete", NULL);   // stopped part way
    CHECK_MSG(rc == 0, "%s", out);
    CHECK_CONTAINS(out, "frames_bad: 0");
    g_free(out);
    g_free(err);
    test_camera_unlock(lk);
}

// A real full file system: a 3 MB tmpfs where the machine allows the mount.
TEST(capture_disk_full)
{
    char mnt[4096];
    snprintf(mnt, sizeof mnt, "%s/mnt", test_tmpdir());
    mkdir(mnt, 0777);
    if (mount("tmpfs", mnt, "tmpfs", 0, "size=3m") != 0)
        SKIP("no tmpfs here (%s); capture_disk_full_injected covers the disk-full "
             "path with an injected ENOSPC", strerror(errno));
    char dir[4200];
    snprintf(dir, sizeof dir, "%s/s", mnt);
    disk_full_body(dir, NULL);
    umount2(mnt, MNT_DETACH);
}

// Everywhere: ENOSPC injected by the LD_PRELOAD shim (tests/enospc_shim.c)
// once the session directory has taken 3 MB.
TEST(capture_disk_full_injected)
{
    const char *lib = getenv("REFL_ENOSPC_SHIM");
    if (!lib || access(lib, R_OK) != 0) {
        test_fail(__FILE__, __LINE__, "REFL_ENOSPC_SHIM (%s) must name the ENOSPC shim (make check sets it)",
                  lib ? lib : "unset");
        return;
    }
    char dir[4200], pre[4200], edir[4300];
    snprintf(dir, sizeof dir, "%s/s", test_tmpdir());
    snprintf(pre, sizeof pre, "LD_PRELOAD=%s", lib);
    snprintf(edir, sizeof edir, "REFL_ENOSPC_DIR=%s", test_tmpdir());
    const char *env[] = { pre, edir, "REFL_ENOSPC_BYTES=3000000", "ASAN_OPTIONS=verify_asan_link_order=0:detect_leaks=0",
                          NULL };
    disk_full_body(dir, env);
}

// Step 3: the third frame (step 0 is the plan's operator step).
static void drop_at_step3(void *ctx, rig_t *r, int step)
{
    (void)ctx;
    if (step == 3) rig_gv_camera_drop_triggers(rig_virtual_gv_camera(r->virt), 1000);
}

TEST(capture_camera_stops_answering)
{
    int lk = test_camera_lock();
    const char *rig = rig_file("rig.ini", NULL);
    const char *plan = test_write("plan.ini", "[sample]\nname = coupon_matte_paint\nkind = material_coupon\n"
                                  "[angles]\nlist = 0 5\n[lamps]\nsets = east\n[exposure]\nmode = fixed\n"
                                  "list_us = 1000 2000\n[capture]\nframe_timeout_s = 0.5\nretries = 2\n");
    char dir[4096];
    snprintf(dir, sizeof dir, "%s/s", test_tmpdir());
    rig_capture_opts_t o = { .plan_path = plan, .rig_path = rig, .dir = dir, .progress = 0,
                             .before_step = drop_at_step3, .op = rig_operator_open(true, NULL) };
    int rc = rig_capture_run(&o);
    CHECK(rc == 3);
    CHECK_CONTAINS(model_last_error(), "did not answer at step 3 after 2 retries");
    CHECK_CONTAINS(model_last_error(), "refl capture --resume");
    CHECK(count_frames(dir) == 2);
    CHECK(count_events(dir, "retry") == 2);
    CHECK(count_events(dir, "pause") == 1);
    // the camera answers again: the session completes
    o.resume = true;
    o.before_step = NULL;
    rc = rig_capture_run(&o);
    CHECK(rc == 0);
    CHECK(count_frames(dir) == 4);
    rig_operator_close(o.op);
    test_camera_unlock(lk);
}

TEST(capture_turntable_stall)
{
    int lk = test_camera_lock();
    char top[PATH_MAX];
    if (!realpath(test_srcdir(), top)) snprintf(top, sizeof top, "%s", test_srcdir());
    char src[PATH_MAX + 64];
    snprintf(src, sizeof src, "%s/examples/virtual-truth.ini", top);
    char *text = model_read_file(src, NULL);
    CHECK(text != NULL);
    if (!text) return;
    char *t = strstr(text, "[turntable]\n");
    CHECK(t != NULL);
    GString *g = g_string_new_len(text, t ? t - text + 12 : 0);
    g_string_append(g, "fault_after_moves = 2\nfault = stall\n");
    if (t) g_string_append(g, t + 12);
    const char *truth = test_write("truth.ini", g->str);
    g_string_free(g, TRUE);
    free(text);
    const char *links[] = { "camera.cameramodel", "samples", "t_stiffener.d3d" };
    for (int i = 0; i < 3; i++) {
        char a[PATH_MAX + 64], b[4200];
        snprintf(a, sizeof a, "%s/examples/%s", top, links[i]);
        snprintf(b, sizeof b, "%s/%s", test_tmpdir(), links[i]);
        CHECK(symlink(a, b) == 0);
    }
    const char *rig = rig_file("rig.ini", truth);
    const char *plan = test_write("plan.ini", "[sample]\nname = coupon_matte_paint\nkind = material_coupon\n"
                                  "[angles]\nlist = 0 5 10 15\n[lamps]\nsets = east\n[exposure]\nmode = fixed\n"
                                  "list_us = 1000\n");
    char dir[4096];
    snprintf(dir, sizeof dir, "%s/s", test_tmpdir());
    char *out = NULL, *err = NULL;
    int rc = refl(&out, &err, "capture", "--yes", plan, "--rig", rig, "-o", dir, NULL);
    CHECK(rc == 1);
    CHECK_CONTAINS(err, "turntable fault at step");
    CHECK_CONTAINS(err, "lamps off");
    g_free(out);
    g_free(err);
    CHECK(count_events(dir, "fault") == 1);
    int n = count_frames(dir);
    CHECK(n >= 1 && n < 4);
    test_camera_unlock(lk);
}

TEST(capture_auto_bracketing_skips)
{
    int lk = test_camera_lock();
    const char *rig = rig_file("rig.ini", NULL);
    // matte coupon, east lamp: the brightest pixel near full scale (Mono12, 4095) at 64000 us, 16000 us stays below 90 %, so 4000 us is not needed
    const char *plan = test_write("plan.ini", "[sample]\nname = coupon_matte_paint\nkind = material_coupon\n"
                                  "[angles]\nlist = 0 10\n[lamps]\nsets = east\n[exposure]\nmode = auto\n"
                                  "list_us = 4000 64000 16000\ntarget_fraction = 0.9\n");
    char dir[4096];
    snprintf(dir, sizeof dir, "%s/s", test_tmpdir());
    char *out = NULL, *err = NULL;
    int rc = refl(&out, &err, "capture", "--yes", plan, "--rig", rig, "-o", dir, NULL);
    CHECK_MSG(rc == 0, "%s", err);
    g_free(out);
    g_free(err);
    char *rows = step_rows(dir);
    CHECK_CONTAINS(rows, "0 operator 0 none 0 done\n1 light 0 east 64000 done\n2 light 0 east 16000 done\n"
                         "3 light 0 east 4000 skipped\n");
    CHECK_CONTAINS(rows, "4 light 10 east 64000 done\n5 light 10 east 16000 done\n6 light 10 east 4000 skipped\n");
    g_free(rows);
    rc = refl(&out, &err, "session", "export", dir, "--format", "csv", NULL);
    CHECK(rc == 0);
    CHECK_CONTAINS(out, ",east,64000,");   // brightest pixel above 90 % (the statuses above say so)
    g_free(out);
    g_free(err);
    test_camera_unlock(lk);
}

TEST(session_help)
{
    char *out = NULL, *err = NULL;
    int rc = refl(&out, &err, "session", "check", "--help", NULL);
    CHECK_MSG(rc == 0, "%s", err);
    CHECK_CONTAINS(out, "usage: refl session check DIR");
    CHECK_CONTAINS(out, "--allow-incomplete");
    CHECK_CONTAINS(out, "integrity_check");
    g_free(out);
    g_free(err);
    rc = refl(&out, &err, "session", "export", "--help", NULL);
    CHECK_MSG(rc == 0, "%s", err);
    CHECK_CONTAINS(out, "usage: refl session export DIR");
    CHECK_CONTAINS(out, "--format csv|json");
    g_free(out);
    g_free(err);
    rc = refl(&out, &err, "session", "--help", NULL);
    CHECK(rc == 0);
    CHECK_CONTAINS(out, "refl session check --help");
    g_free(out);
    g_free(err);
    rc = refl(&out, &err, "session", "export", test_tmpdir(), NULL);
    CHECK(rc == 2);
    CHECK_CONTAINS(err, "missing required option --format");
    g_free(out);
    g_free(err);
    rc = refl(&out, &err, "session", "check", test_tmpdir(), "--format", "csv", NULL);
    CHECK(rc == 2);
    CHECK_CONTAINS(err, "unknown option '--format'");
    g_free(out);
    g_free(err);
}

// A copy of the example truth file in the test directory (with the files it
// names linked), the camera's serial set to `serial`.
static const char *truth_copy(const char *serial, bool link_files)
{
    char top[PATH_MAX];
    if (!realpath(test_srcdir(), top)) snprintf(top, sizeof top, "%s", test_srcdir());
    char src[PATH_MAX + 64];
    snprintf(src, sizeof src, "%s/examples/virtual-truth.ini", top);
    char *text = model_read_file(src, NULL);
    if (!text) return NULL;
    char *s = strstr(text, "serial = REFL-VIRT01\n");
    GString *g = g_string_new_len(text, s ? s - text : (gssize)strlen(text));
    if (s) g_string_append_printf(g, "serial = %s\n%s", serial, s + strlen("serial = REFL-VIRT01\n"));
    const char *truth = test_write("truth.ini", g->str);
    g_string_free(g, TRUE);
    free(text);
    const char *links[] = { "camera.cameramodel", "samples", "t_stiffener.d3d" };
    for (int i = 0; link_files && i < 3; i++) {
        char a[PATH_MAX + 64], b[4200];
        snprintf(a, sizeof a, "%s/examples/%s", top, links[i]);
        snprintf(b, sizeof b, "%s/%s", test_tmpdir(), links[i]);
        CHECK(symlink(a, b) == 0);
    }
    return truth;
}

static int slow_calls;
static void slow_first_step(void *ctx, rig_t *r, int step)
{
    (void)ctx;
    (void)r;
    (void)step;
    if (slow_calls++ == 0) g_usleep(3000000);   // the first step of the run: a long move, say
}

// A paused session: refl session check lists what is missing and fails
// (unless --allow-incomplete) and reports the journal's integrity check;
// --resume refuses a changed rig file (naming it) and another camera (naming
// both serials); the ETA after --resume counts the steps left at this run's
// pace (not the first step's); a journal that fails SQLite's integrity check
// is an error naming the file.
TEST(session_check_incomplete_and_resume)
{
    int lk = test_camera_lock();
    const char *truth = truth_copy("REFL-VIRT01", true);
    const char *rig = rig_file("rig.ini", truth);
    char *rig_text = model_read_file(rig, NULL);
    const char *plan = test_write("plan.ini", "[sample]\nname = coupon_matte_paint\nkind = material_coupon\n"
                                  "[angles]\nrange = 0 35 5\n[lamps]\nsets = east\n[exposure]\nmode = fixed\n"
                                  "list_us = 1000 2000\n[capture]\nframe_timeout_s = 0.5\nretries = 2\n");
    char dir[4096];
    snprintf(dir, sizeof dir, "%s/s", test_tmpdir());
    rig_capture_opts_t o = { .plan_path = plan, .rig_path = rig, .dir = dir, .progress = 0,
                             .before_step = drop_at_step3, .op = rig_operator_open(true, NULL) };
    int rc = rig_capture_run(&o);
    CHECK(rc == 3);
    CHECK(count_frames(dir) == 2);

    char *out = NULL, *err = NULL;
    rc = refl(&out, &err, "session", "check", dir, NULL);
    CHECK(rc == 1);
    CHECK_CONTAINS(out, "journal_integrity: ok\n");
    CHECK_CONTAINS(out, "steps_missing: 14\n");
    CHECK_CONTAINS(out, "operator step 0: answered: put coupon coupon_matte_paint flat at the turntable centre\n");
    CHECK_CONTAINS(out, "missing step 3: light angle 5 deg lamps east exposure 1000 us\n");
    CHECK_CONTAINS(out, "missing step 12: light angle 25 deg lamps east exposure 2000 us\n");
    CHECK(out && !strstr(out, "missing step 13:"));
    CHECK_CONTAINS(out, "... and 4 more missing step(s) (14 in all)");
    CHECK_CONTAINS(out, "frames_bad: 0\n");
    CHECK_CONTAINS(err, "is incomplete: 14 of 17 step(s) missing");
    CHECK_CONTAINS(err, "--allow-incomplete");
    g_free(out);
    g_free(err);
    rc = refl(&out, &err, "session", "check", dir, "--allow-incomplete", NULL);
    CHECK_MSG(rc == 0, "%s", err);
    CHECK_CONTAINS(out, "steps_missing: 14\n");
    g_free(out);
    g_free(err);

    // the rig file changed: the refusal names it
    char *changed = g_strdup_printf("%s# changed\n", rig_text ? rig_text : "");
    test_write("rig.ini", changed);
    g_free(changed);
    rc = refl(&out, &err, "capture", "--yes", "--resume", dir, NULL);
    CHECK(rc == 1);
    char *want = g_strdup_printf("the rig file %s changed since the session started", rig);
    CHECK_CONTAINS(err, want);
    g_free(want);
    g_free(out);
    g_free(err);
    test_write("rig.ini", rig_text ? rig_text : "");

    // another camera (the same rig file; the virtual camera's serial changed)
    truth_copy("REFL-OTHER7", false);
    rc = refl(&out, &err, "capture", "--yes", "--resume", dir, NULL);
    CHECK(rc == 1);
    CHECK_CONTAINS(err, "the camera changed: serial REFL-OTHER7 now, the session started with serial REFL-VIRT01");
    CHECK_CONTAINS(err, "--allow-changed");
    g_free(out);
    g_free(err);
    CHECK(count_frames(dir) == 2);
    truth_copy("REFL-VIRT01", false);

    // resume (in-process, its progress notes on stderr into a file, named as
    // the dispatcher names them); the first step of the run is slow
    const char *log = test_path("progress.txt");
    fflush(stderr);
    int saved = dup(2), fd = open(log, O_WRONLY | O_CREAT | O_TRUNC, 0644);
    dup2(fd, 2);
    close(fd);
    slow_calls = 0;
    o.resume = true;
    o.before_step = slow_first_step;
    bool quiet = model_error_quiet(false);
    model_notice_prefix("refl capture");
    rc = rig_capture_run(&o);
    model_error_quiet(quiet);
    model_notice_prefix(NULL);
    rig_operator_close(o.op);
    fflush(stderr);
    dup2(saved, 2);
    close(saved);
    CHECK(rc == 0);
    CHECK(count_frames(dir) == 16);
    char *lines = model_read_file(log, NULL);
    double eta[32];
    int neta = 0;
    for (char *l = lines; l && (l = strstr(l, "refl capture: step ")); l++) {
        int done = 0, total = 0;
        char *e = strstr(l, "(ETA ");
        if (sscanf(l, "refl capture: step %d/%d", &done, &total) == 2 && e && neta < 32) eta[neta++] = atof(e + 5);
    }
    CHECK_MSG(neta == 14, "%d progress lines: %s", neta, lines ? lines : "");
    // the second step of the run: 12 steps left at the pace of a step after
    // the first (the old estimate took the first's 3 s in: 12 x 1.5 s)
    if (neta == 14) {
        CHECK_MSG(eta[1] <= 6, "ETA %g s with 12 steps left: %s", eta[1], lines);
        CHECK(eta[13] == 0);
    }
    free(lines);
    rc = refl(&out, &err, "session", "check", dir, NULL);
    CHECK_MSG(rc == 0, "%s %s", out, err);
    CHECK_CONTAINS(out, "steps_missing: 0\n");
    g_free(out);
    g_free(err);

    // a journal that fails SQLite's integrity check: two tables on one b-tree
    char db[4200];
    snprintf(db, sizeof db, "%s/session.sqlite", dir);
    sqlite3 *d = NULL;
    CHECK(sqlite3_open(db, &d) == SQLITE_OK);
    CHECK(sqlite3_exec(d, "PRAGMA writable_schema=ON; UPDATE sqlite_master SET rootpage=(SELECT rootpage FROM "
                       "sqlite_master WHERE name='steps') WHERE name='events';", NULL, NULL, NULL) == SQLITE_OK);
    sqlite3_close(d);
    rc = refl(&out, &err, "session", "check", dir, NULL);
    CHECK(rc == 1);
    CHECK_CONTAINS(out, "journal_integrity: FAILED");
    CHECK_CONTAINS(err, db);
    CHECK_CONTAINS(err, "fails SQLite's integrity check");
    g_free(out);
    g_free(err);
    free(rig_text);
    test_camera_unlock(lk);
}

// A journal of a newer schema version (3; this refl writes 2 and reads 1 and
// 2) is refused by every reader, naming the versions; one without a version
// too.
TEST(session_journal_newer_schema_refused)
{
    const char *dir = test_path("newer");
    CHECK(mkdir(dir, 0777) == 0);
    char db[4200];
    snprintf(db, sizeof db, "%s/session.sqlite", dir);
    sqlite3 *d = NULL;
    CHECK(sqlite3_open(db, &d) == SQLITE_OK);
    CHECK(sqlite3_exec(d, "CREATE TABLE schema_version(version INTEGER NOT NULL); "
                       "INSERT INTO schema_version VALUES(3);", NULL, NULL, NULL) == SQLITE_OK);
    sqlite3_close(d);
    rig_journal_t *j = NULL;
    CHECK(rig_journal_open(&j, dir) == RIG_ERR_PROTOCOL);
    CHECK(j == NULL);
    CHECK_CONTAINS(model_last_error(), "schema version 3, written by a newer refl (this refl reads versions 1 to 2)");
    CHECK(rig_session_open(dir) == NULL);
    CHECK_CONTAINS(model_last_error(), "schema version 3, written by a newer refl");
    char *out = NULL, *err = NULL;
    int rc = refl(&out, &err, "session", "check", dir, NULL);
    CHECK(rc == 1);
    CHECK_CONTAINS(err, "schema version 3, written by a newer refl (this refl reads versions 1 to 2)");
    g_free(out);
    g_free(err);
    rc = refl(&out, &err, "capture", "--yes", "--resume", dir, NULL);
    CHECK(rc == 1);
    CHECK_CONTAINS(err, "refl capture: journal ");
    CHECK_CONTAINS(err, "schema version 3, written by a newer refl");
    g_free(out);
    g_free(err);

    CHECK(sqlite3_open(db, &d) == SQLITE_OK);
    CHECK(sqlite3_exec(d, "DELETE FROM schema_version;", NULL, NULL, NULL) == SQLITE_OK);
    sqlite3_close(d);
    CHECK(rig_journal_open(&j, dir) == RIG_ERR_PROTOCOL);
    CHECK_CONTAINS(model_last_error(), "no schema version (not a refl session journal?)");
}

// The session facts name their format (refl-session-facts); facts without the
// keys read as version 1; a higher version is refused by the session reader.
TEST(session_facts_newer_version_refused)
{
    const char *text = SMALL_PLAN;
    rig_plan_t *p = rig_plan_parse(text, strlen(text), "plan.ini");
    CHECK_MSG(p != NULL, "%s", model_last_error());
    if (!p) return;
    static const char *const facts[] = { "{\"refl_version\": \"x\"}",
                                         "{\"format\": \"refl-session-facts\", \"version\": 1}",
                                         "{\"format\": \"refl-session-facts\", \"version\": 2}" };
    for (int k = 0; k < 3; k++) {
        char name[32];
        snprintf(name, sizeof name, "facts%d", k);
        const char *dir = test_path(name);
        CHECK(mkdir(dir, 0777) == 0);
        rig_journal_t *j = NULL;
        CHECK(rig_journal_create(&j, dir, p, "rig.ini", "[rig]\n", "0", facts[k]) == 0);
        rig_journal_close(j);
        rig_session_t *s = rig_session_open(dir);
        if (k < 2) {
            CHECK_MSG(s != NULL && s->facts != NULL, "%s: %s", facts[k], model_last_error());
        } else {
            CHECK(s == NULL);
            CHECK_CONTAINS(model_last_error(), "refl-session-facts version 2, written by a newer refl");
        }
        rig_session_free(s);
    }
    rig_plan_free(p);
}
