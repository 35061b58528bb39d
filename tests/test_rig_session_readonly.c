// tests/test_rig_session_readonly.c — archived sessions: every reader reads a session it cannot write
//
// A reference-white session captured on the virtual rig (in-process camera) is
// made read-only (chmod -R a-w) and read through bin/refl by refl session
// check, refl session export, refl calib white and refl fit material: each
// gives what it gives on a writable copy, and nothing in the session changes
// (no file made, none changed: no -wal or -shm, the journal's bytes and times
// as they were). Run as root, chmod does not stop a write; the readers then
// still take the read-only path (the journal's mode has no write bit), the
// unchanged directory shows that they wrote nothing, and the readers run again
// as user nobody (runuser), to whom the session is another user's and cannot
// be written at all, and as root on a read-only bind mount of the writable
// copy (unshare -m; where mounts are not allowed that case says so and is
// left out): the same outputs.
// A journal whose WAL holds commits its writer never checkpointed, in a
// read-only directory, reads with them (as nobody: through the private copy). A damaged journal (a page overwritten,
// or its header) is an error naming the journal, exit 1, for session check
// and session export.
#define _GNU_SOURCE
#include <glib.h>
#include <limits.h>
#include <sqlite3.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "model/model.h"
#include "tests/test.h"

static char *keep(const char *p) { return g_strdup(p); }

static char *srcdir(void)
{
    char *r = realpath(test_srcdir(), NULL);
    return r ? r : g_strdup(".");
}

static int sh(const char *cmd)
{
    const char *argv[] = { "/bin/sh", "-c", cmd, NULL };
    char *err = NULL;
    int rc = test_run(argv, 60, NULL, &err);
    CHECK_MSG(rc == 0, "%s: exit %d: %s", cmd, rc, err ? err : "");
    free(err);
    return rc;
}

// Every file under dir with its size, mode and modification time, one a line.
static char *listing(const char *dir)
{
    char *cmd = g_strdup_printf("cd '%s' && find . -printf '%%p %%s %%m %%T@\\n' | sort", dir);
    const char *argv[] = { "/bin/sh", "-c", cmd, NULL };
    char *out = NULL;
    int rc = test_run(argv, 60, &out, NULL);
    CHECK(rc == 0);
    g_free(cmd);
    return out;
}

// The value of "kc_I_per_us" of each lamp of a white.json, as text.
static char *white_figures(const char *path)
{
    char *text = model_read_file(path, NULL);
    GString *g = g_string_new("");
    for (char *p = text; p && (p = strstr(p, "\"kc_I_per_us\"")); p++) {
        char *e = strpbrk(p, ",}");
        g_string_append_len(g, p, e ? e - p : 20);
        g_string_append_c(g, ' ');
    }
    free(text);
    return g_string_free(g, FALSE);
}

static bool listing_same(const char *dir, const char *before)
{
    char *now = listing(dir);
    bool same = now && before && !strcmp(now, before);
    free(now);
    return same;
}

// A reader on the read-only session and on its writable copy: the same exit
// status and stdout (paths of the session made equal), no word of a write.
static void same_as_copy(const char *ro, const char *rw, const char *what, int want_rc, const char *const *args,
                         int nargs, char **out_ro)
{
    char *out[2] = { NULL, NULL }, *err[2] = { NULL, NULL };
    int rc[2];
    for (int k = 0; k < 2; k++) {
        const char *argv[24];
        int n = 0;
        argv[n++] = test_refl();
        for (int i = 0; i < nargs && n < 22; i++) argv[n++] = strcmp(args[i], "SESSION") ? args[i] : k ? rw : ro;
        argv[n] = NULL;
        rc[k] = test_run(argv, 600, &out[k], &err[k]);
    }
    CHECK_MSG(rc[0] == want_rc, "%s on the read-only session: exit %d: %s", what, rc[0], err[0] ? err[0] : "");
    CHECK_MSG(rc[0] == rc[1], "%s: exit %d read-only, %d writable: %s", what, rc[0], rc[1], err[0] ? err[0] : "");
    CHECK_MSG(!strstr(err[0] ? err[0] : "", "readonly") && !strstr(err[0] ? err[0] : "", "WAL"), "%s: %s", what,
              err[0]);
    if (out[0] && out[1]) {
        GString *a = g_string_new(out[0]);
        g_string_replace(a, ro, rw, 0);
        CHECK_MSG(!strcmp(a->str, out[1]), "%s: stdout differs:\n%s\n--- writable:\n%s", what, a->str, out[1]);
        g_string_free(a, TRUE);
    }
    if (out_ro) *out_ro = out[0];
    else free(out[0]);
    free(out[1]);
    free(err[0]);
    free(err[1]);
}

// bin/refl run as user nobody (refl's state in the shared directory pub);
// exit status as test_run's.
static int as_nobody(const char *pub, char **out, char **err, const char *const *args, int nargs)
{
    char *state = g_strdup_printf("XDG_STATE_HOME=%s/state", pub);
    const char *argv[32] = { "runuser", "-u", "nobody", "--", "env", state, test_refl() };
    int n = 7;
    for (int i = 0; i < nargs && n < 31; i++) argv[n++] = args[i];
    argv[n] = NULL;
    int rc = test_run(argv, 600, out, err);
    g_free(state);
    return rc;
}

// As root, the readers run again as user nobody, to whom the session is
// another user's (nothing can be written there, whatever the modes): the same
// outputs as root's; the journal with a WAL of commits is read through the
// private copy (nobody cannot make its -shm file).
static void readers_as_nobody(const char *ro, const char *walc, const char *cal, const char *scene,
                              const char *check_out, const char *export_out)
{
    if (geteuid() != 0 || access("/usr/sbin/runuser", X_OK) != 0) return;
    printf("the readers run again as user nobody\n");
    char *pub = g_strdup_printf("%s/pub", test_tmpdir()), *cmd = g_strdup_printf("chmod o+rx '%s' && mkdir -m 1777 '%s'",
                                                                                   test_tmpdir(), pub);
    sh(cmd);
    g_free(cmd);
    char *out = NULL, *err = NULL, *wj = g_strdup_printf("%s/white.json", pub), *pj = g_strdup_printf("%s/p.json", pub);
    const char *check[] = { "session", "check", ro }, *export[] = { "session", "export", ro, "--format", "csv" };
    int rc = as_nobody(pub, &out, &err, check, 3);
    CHECK_MSG(rc == 0 && out && !strcmp(out, check_out), "session check as nobody: exit %d: %s%s", rc, out, err);
    g_free(out);
    g_free(err);
    rc = as_nobody(pub, &out, &err, export, 5);
    CHECK_MSG(rc == 0 && out && !strcmp(out, export_out), "session export as nobody: exit %d: %s", rc, err);
    g_free(out);
    g_free(err);
    const char *white[] = { "calib", "white", ro, "--calib", cal, "--scene", scene, "-o", wj };
    rc = as_nobody(pub, &out, &err, white, 9);
    CHECK_MSG(rc == 0, "calib white as nobody: exit %d: %s", rc, err);
    g_free(out);
    g_free(err);
    const char *fit[] = { "fit", "material", ro, "--scene", scene, "--calib", cal, "-o", pj };
    rc = as_nobody(pub, &out, &err, fit, 9);
    CHECK_MSG(rc == 0, "fit material as nobody: exit %d: %s", rc, err);
    g_free(out);
    g_free(err);
    const char *wal[] = { "session", "export", walc, "--format", "csv" };
    rc = as_nobody(pub, &out, &err, wal, 5);
    CHECK_MSG(rc == 0, "session export of a WAL with commits as nobody: exit %d: %s", rc, err);
    CHECK_CONTAINS(out, ",4321.5000,");
    g_free(out);
    g_free(err);
    g_free(wj);
    g_free(pj);
    g_free(pub);
}

// bin/refl run where dir is a read-only bind mount (a private mount
// namespace: unshare -m); -1 when no such mount can be made here.
static int in_ro_bind(const char *dir, char **out, char **err, const char *const *args, int nargs)
{
    static const char script[] = "d=$1; shift; mount --bind \"$d\" \"$d\" && mount -o remount,bind,ro \"$d\" && "
                                 "{ touch \"$d/.w\" 2>/dev/null && exit 99; exec \"$@\"; }";
    const char *argv[32] = { "unshare", "-m", "sh", "-c", script, "sh", dir, test_refl() };
    int n = 8;
    for (int i = 0; i < nargs && n < 31; i++) argv[n++] = args[i];
    argv[n] = NULL;
    if (geteuid() != 0) return -1;
    const char *probe[] = { "unshare", "-m", "sh", "-c", script, "sh", dir, "true", NULL };
    if (test_run(probe, 60, NULL, NULL) != 0) return -1;
    return test_run(argv, 600, out, err);
}

// The readers on a read-only bind mount of the writable copy (where even root
// cannot write): what they give on the copy itself.
static void readers_on_ro_bind(const char *rw, const char *cal, const char *scene)
{
    const char *check[] = { "session", "check", rw }, *export[] = { "session", "export", rw, "--format", "csv" };
    const char *const *args[] = { check, export };
    const int nargs[] = { 3, 5 };
    for (int k = 0; k < 2; k++) {
        char *out = NULL, *err = NULL, *plain = NULL;
        int rc = in_ro_bind(rw, &out, &err, args[k], nargs[k]);
        if (rc == -1) {
            printf("no read-only bind mount here: that case is not tested\n");
            return;
        }
        const char *argv[8] = { test_refl() };
        for (int i = 0; i < nargs[k]; i++) argv[i + 1] = args[k][i];
        argv[nargs[k] + 1] = NULL;
        int rc2 = test_run(argv, 600, &plain, NULL);
        CHECK_MSG(rc == 0 && rc2 == 0 && out && plain && !strcmp(out, plain), "%s on a read-only bind mount: exit %d: "
                  "%s", args[k][1], rc, err);
        free(out);
        free(err);
        free(plain);
    }
    char *wj = g_strdup_printf("%s/white-bind.json", test_tmpdir()), *pj = g_strdup_printf("%s/p-bind.json", test_tmpdir());
    const char *white[] = { "calib", "white", rw, "--calib", cal, "--scene", scene, "-o", wj };
    const char *fit[] = { "fit", "material", rw, "--scene", scene, "--calib", cal, "-o", pj };
    const char *const *more[] = { white, fit };
    for (int k = 0; k < 2; k++) {
        char *out = NULL, *err = NULL;
        int rc = in_ro_bind(rw, &out, &err, more[k], 9);
        CHECK_MSG(rc == 0, "%s %s on a read-only bind mount: exit %d: %s", more[k][0], more[k][1], rc, err);
        free(out);
        free(err);
    }
    printf("the readers ran on a read-only bind mount\n");
    g_free(wj);
    g_free(pj);
}

TEST(session_readonly_archive_readers)
{
    char *sd = srcdir();
    char rig_text[4300];
    snprintf(rig_text, sizeof rig_text, "[rig]\nbackend = virtual\ntruth = %s/examples/virtual-truth.ini\n"
             "serve = inprocess\ntime_scale = 0.005\npixel_format = Mono12\n", sd);
    char *rig = keep(test_write("rig.ini", rig_text));
    char *plan = keep(test_write("white.ini", "[plan]\nname = white\n[sample]\nname = reference_white\n"
                                              "kind = reference_white\n[angles]\nlist = 0 120 240\n[lamps]\n"
                                              "sets = east; south; west; north; rim; none\n[exposure]\nmode = fixed\n"
                                              "list_us = 8000\n"));
    char *cam = g_strdup_printf("%s/examples/camera.cameramodel", sd);
    char *scene = g_strdup_printf("%s/examples/samples/reference_white.d3d", sd);
    char *cal = keep(test_path("cal"));
    g_mkdir_with_parents(cal, 0755);
    char *camtext = model_read_file(cam, NULL);
    test_write("cal/camera.cameramodel", camtext ? camtext : "");
    free(camtext);
    test_write("cal/lamps.json",
               "{\"lamps\": [{\"name\": \"east\", \"position_mm\": [488.6, 177.9, 600], \"radius_mm\": 15},"
               " {\"name\": \"south\", \"position_mm\": [-52.3, -597.7, 480], \"radius_mm\": 15},"
               " {\"name\": \"west\", \"position_mm\": [-526.2, -191.5, 520], \"radius_mm\": 15},"
               " {\"name\": \"north\", \"position_mm\": [98.4, 367.1, 700], \"radius_mm\": 15},"
               " {\"name\": \"rim\", \"position_mm\": [-619.8, 65.1, 219.6], \"radius_mm\": 15}]}\n");
    char *ro = keep(test_path("archive")), *rw = keep(test_path("copy")), *walc = keep(test_path("walcopy"));
    char *out = NULL, *err = NULL;
    int rc = test_refl_run(600, &out, &err, "capture", "--yes", plan, "--rig", rig, "-o", ro, "--calib", cal, NULL);
    CHECK_MSG(rc == 0, "%s", err);
    g_free(out);
    g_free(err);
    char *cmd = g_strdup_printf("cp -a '%s' '%s' && cp -a '%s' '%s' && chmod -R a-w '%s'", ro, rw, ro, walc, ro);
    sh(cmd);
    g_free(cmd);
    char *before = listing(ro);

    const char *check[] = { "session", "check", "SESSION" };
    char *check_out = NULL, *export_out = NULL;
    same_as_copy(ro, rw, "refl session check", 0, check, 3, &check_out);
    CHECK_CONTAINS(check_out, "journal_integrity: ok\n");
    const char *export[] = { "session", "export", "SESSION", "--format", "csv" };
    same_as_copy(ro, rw, "refl session export", 0, export, 5, &export_out);
    CHECK(export_out && strlen(export_out) > 100);
    char *wj_ro = g_strdup_printf("%s/white-ro.json", test_tmpdir()), *wj_rw = g_strdup_printf("%s/white-rw.json", test_tmpdir());
    char *a = NULL;
    for (int k = 0; k < 2; k++) {   // its stdout names its output: the figures are compared
        rc = test_refl_run(600, &out, &err, "calib", "white", k ? rw : ro, "--calib", cal, "--scene", scene, "-o",
                           k ? wj_rw : wj_ro, NULL);
        CHECK_MSG(rc == 0, "refl calib white on the %s session: %s", k ? "writable" : "read-only", err);
        g_free(out);
        g_free(err);
    }
    char *fa = white_figures(wj_ro), *fb = white_figures(wj_rw);
    CHECK_MSG(strlen(fa) > 20 && !strcmp(fa, fb), "white.json from the read-only session: %s; writable: %s", fa, fb);
    g_free(fa);
    g_free(fb);
    // refl fit material reads the session (the white one, as a material: what
    // it makes of it is the same on both)
    char *wj = g_strdup_printf("%s/white.json", cal), *pj = g_strdup_printf("%s/priors.json", test_tmpdir());
    sh(a = g_strdup_printf("cp '%s' '%s'", wj_ro, wj));
    g_free(a);
    const char *fit[] = { "fit", "material", "SESSION", "--scene", scene, "--calib", cal, "-o", pj };
    same_as_copy(ro, rw, "refl fit material", 0, fit, 9, NULL);

    char *after = listing(ro);
    CHECK_MSG(before && after && !strcmp(before, after), "the read-only session changed:\n%s\n--- after:\n%s", before,
              after);
    char *before_all = before;
    g_free(after);
    readers_on_ro_bind(rw, cal, scene);

    // a WAL with commits never checkpointed (its writer died), read-only
    char *db = g_strdup_printf("%s/session.sqlite", rw);
    sqlite3 *h = NULL;
    CHECK(sqlite3_open(db, &h) == SQLITE_OK);
    CHECK(sqlite3_exec(h, "PRAGMA wal_autocheckpoint=0; UPDATE frames SET mean = 4321.5 WHERE step = "
                          "(SELECT min(step) FROM frames);", NULL, NULL, NULL) == SQLITE_OK);
    cmd = g_strdup_printf("cp '%s' '%s-wal' '%s/' && test -s '%s/session.sqlite-wal' && chmod -R a-w '%s'", db, db,
                          walc, walc, walc);
    sh(cmd);
    g_free(cmd);
    sqlite3_close(h);
    rc = test_refl_run(120, &out, &err, "session", "export", walc, "--format", "csv", NULL);
    CHECK_MSG(rc == 0, "%s", err);
    CHECK_CONTAINS(out, ",4321.5000,");
    g_free(out);
    g_free(err);
    readers_as_nobody(ro, walc, cal, scene, check_out ? check_out : "", export_out ? export_out : "");
    free(check_out);
    free(export_out);
    CHECK_MSG(listing_same(ro, before_all), "the read-only session changed (as nobody)");

    // damaged journals: a page overwritten, the header overwritten
    static const char *const damage[] = { "bs=4096 seek=2", "bs=16 seek=0" };
    for (int k = 0; k < 2; k++) {
        char *dd = g_strdup_printf("%s/damaged%d", test_tmpdir(), k);
        cmd = g_strdup_printf("cp -a '%s' '%s' && chmod -R u+w '%s' && head -c 4096 /dev/zero | tr '\\0' x | dd of='%s/session.sqlite' "
                              "%s count=1 conv=notrunc status=none && chmod -R a-w '%s'", ro, dd, dd, dd, damage[k], dd);
        sh(cmd);
        g_free(cmd);
        char *jp = g_strdup_printf("%s/session.sqlite", dd);
        for (int c = 0; c < 2; c++) {
            rc = c ? test_refl_run(120, &out, &err, "session", "export", dd, "--format", "csv", NULL)
                   : test_refl_run(120, &out, &err, "session", "check", dd, NULL);
            CHECK_MSG(rc == 1, "damage %d, session %s: exit %d: %s", k, c ? "export" : "check", rc, err);
            CHECK_CONTAINS(err, jp);
            g_free(out);
            g_free(err);
        }
        g_free(jp);
        g_free(dd);
    }
    g_free(before_all);
    sh(cmd = g_strdup_printf("chmod -R u+w '%s'", test_tmpdir()));
    g_free(cmd);
    g_free(db);
    g_free(wj);
    g_free(pj);
    g_free(wj_ro);
    g_free(wj_rw);
    g_free(cam);
    g_free(scene);
    g_free(sd);
}
