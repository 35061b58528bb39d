// rig/cmd_capture.c — `refl capture` (run, dry-run or resume a capture
// session) and `refl session` (check, export). Usage errors exit 2, runtime
// errors 1, a paused session 3 (see rig/rig.h, "Capture sessions").
#define _GNU_SOURCE
#include <errno.h>
#include <glib.h>
#include <jansson.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include "model/model.h"
#include "rig/rig.h"

static void capture_usage(FILE *f)
{
    fprintf(f, "usage: refl capture PLAN.ini --rig RIG.ini -o DIR [--operator NAME] [--notes TEXT] [--calib DIR]\n"
               "                    [--progress bar|lines]\n"
               "       refl capture PLAN.ini --rig RIG.ini --dry-run\n"
               "       refl capture --resume DIR [--rig RIG.ini] [--allow-changed]\n"
               "\n"
               "Runs the plan (see examples/plans/ and rig/rig.h) into the session directory DIR: a SQLite\n"
               "journal (session.sqlite) and 16-bit PNG frames (frames/). --dry-run prints the steps, the\n"
               "estimated duration and disk use and checks the plan against the rig; nothing moves.\n"
               "--calib DIR records the calibrations in use (their paths and sha256) in the session.\n"
               "--resume continues a stopped session where it stopped; it refuses when the plan or the rig file\n"
               "changed since (--allow-changed continues the stored step list anyway).\n"
               "First Ctrl-C: finish the frame, lamps off, pause (exit 3); second: stop at once.\n"
               "Exit: 0 complete, 1 error or fault, 2 usage, 3 paused.\n\nrefl %s\n", REFL_VERSION);
}

static int usage_error(const char *cmd, const char *msg, const char *arg)
{
    fprintf(stderr, "refl %s: %s%s%s\n(refl %s --help for the options)\n", cmd, msg, arg ? " " : "", arg ? arg : "",
            cmd);
    return 2;
}

static char *join_args(int argc, char **argv)
{
    GString *s = g_string_new("refl");
    for (int i = 0; i < argc; i++) {
        gchar *q = g_shell_quote(argv[i]);
        g_string_append_printf(s, " %s", q);
        g_free(q);
    }
    return g_string_free(s, FALSE);
}

int rig_cmd_capture(int argc, char **argv)
{
    rig_capture_opts_t o = { .progress = -1 };
    for (int i = 1; i < argc; i++) {
        const char *a = argv[i];
        const char **val = NULL;
        if (!strcmp(a, "-h") || !strcmp(a, "--help")) {
            capture_usage(stdout);
            return 0;
        } else if (!strcmp(a, "--dry-run")) {
            o.dry_run = true;
        } else if (!strcmp(a, "--allow-changed")) {
            o.allow_changed = true;
        } else if (!strcmp(a, "--rig")) {
            val = &o.rig_path;
        } else if (!strcmp(a, "-o")) {
            val = &o.dir;
        } else if (!strcmp(a, "--resume")) {
            o.resume = true;
            val = &o.dir;
        } else if (!strcmp(a, "--operator")) {
            val = &o.operator_name;
        } else if (!strcmp(a, "--notes")) {
            val = &o.notes;
        } else if (!strcmp(a, "--calib")) {
            val = &o.calib_dir;
        } else if (!strcmp(a, "--progress")) {
            if (i + 1 >= argc) return usage_error("capture", "option --progress needs bar or lines", NULL);
            const char *v = argv[++i];
            if (!strcmp(v, "bar")) o.progress = 1;
            else if (!strcmp(v, "lines")) o.progress = 0;
            else return usage_error("capture", "option --progress: write bar or lines, not", v);
            continue;
        } else if (a[0] == '-') {
            return usage_error("capture", "unknown option", a);
        } else if (!o.plan_path) {
            o.plan_path = a;
        } else {
            return usage_error("capture", "unexpected argument", a);
        }
        if (val) {
            if (i + 1 >= argc || !argv[i + 1][0]) return usage_error("capture", "option needs a value:", a);
            if (*val && strcmp(a, "--resume")) return usage_error("capture", "option given twice:", a);
            *val = argv[++i];
        }
    }
    if (o.resume) {
        if (o.dry_run) return usage_error("capture", "--dry-run and --resume do not go together", NULL);
    } else {
        if (!o.plan_path) return usage_error("capture", "missing the plan file (refl capture PLAN.ini --rig RIG.ini -o "
                                             "DIR)", NULL);
        if (!o.rig_path) return usage_error("capture", "missing required option --rig RIG.ini", NULL);
        if (!o.dir && !o.dry_run) return usage_error("capture", "missing -o DIR (the session directory)", NULL);
        if (o.allow_changed) return usage_error("capture", "--allow-changed is for --resume", NULL);
    }
    char *cl = join_args(argc, argv);
    o.command_line = cl;
    int rc = rig_capture_run(&o);
    g_free(cl);
    fflush(stdout);
    return rc;
}

// ---------------------------------------------------------------------------
// refl session

static void session_usage(FILE *f)
{
    fprintf(f, "usage: refl session check DIR\n"
               "       refl session export DIR --format csv|json [-o FILE]\n"
               "\ncheck: verify every frame of the session against its sha256 and list the steps still missing\n"
               "(exit 0 when every committed frame is intact, 1 otherwise).\n"
               "export: the frame table, one row per frame (stdout unless -o).\n\nrefl %s\n", REFL_VERSION);
}

static int session_check(const char *dir)
{
    rig_journal_t *j = NULL;
    rig_frame_row_t *rows = NULL;
    rig_step_t *steps = NULL;
    char *status = NULL;
    int nrows = 0, nsteps = 0, bad = 0, missing = 0, skipped = 0, rc = 1;
    if (rig_journal_open(&j, dir) || rig_journal_frames(j, &rows, &nrows) ||
        rig_journal_steps(j, &steps, &status, &nsteps))
        goto done;
    for (int i = 0; i < nrows; i++) {
        char path[4200], sha[65];
        snprintf(path, sizeof path, "%s/%s", dir, rows[i].file);
        bool q = model_error_quiet_thread(true);
        bool ok = model_sha256_file(path, sha);
        model_error_quiet_thread(q);
        if (!ok) {
            printf("MISSING FILE step %d: %s (%s)\n", rows[i].step, rows[i].file, strerror(errno));
            bad++;
        } else if (strcmp(sha, rows[i].sha256)) {
            printf("BAD HASH step %d: %s: sha256 %s, journal %s\n", rows[i].step, rows[i].file, sha, rows[i].sha256);
            bad++;
        }
    }
    for (int i = 0; i < nsteps; i++) {
        if (status[i] == 's') skipped++;
        if (status[i] != 'p') continue;
        if (missing < 50)
            printf("missing step %d: %s angle %g deg lamps %s exposure %g us\n", steps[i].index,
                   steps[i].kind == RIG_STEP_DARK ? "dark" : "light", steps[i].angle_deg, steps[i].lamps,
                   steps[i].exposure_us);
        missing++;
    }
    char state[32] = "";
    rig_journal_state(j, state, sizeof state);
    printf("session: %s\nstate: %s\nsteps: %d\nframes: %d\nframes_verified: %d\nframes_bad: %d\nsteps_skipped: %d\n"
           "steps_missing: %d\n", dir, state, nsteps, nrows, nrows - bad, bad, skipped, missing);
    if (bad) rig_fail(RIG_ERR_IO, "refl session check: %d frame(s) of %s fail their hash or are missing", bad, dir);
    rc = bad ? 1 : 0;
done:
    free(rows);
    free(steps);
    free(status);
    rig_journal_close(j);
    return rc;
}

static int session_export(const char *dir, const char *format, const char *out)
{
    rig_journal_t *j = NULL;
    rig_frame_row_t *rows = NULL;
    int n = 0, rc = 1;
    FILE *f = NULL;
    if (rig_journal_open(&j, dir) || rig_journal_frames(j, &rows, &n)) goto done;
    f = out ? fopen(out, "w") : stdout;
    if (!f) {
        rig_fail(RIG_ERR_IO, "refl session export: cannot create %s: %s", out, strerror(errno));
        goto done;
    }
    if (!strcmp(format, "csv")) {
        rig_frame_rows_write_csv(f, rows, n);
    } else {
        json_t *a = rig_frame_rows_json(rows, n);
        json_dumpf(a, f, JSON_INDENT(1));
        fputc('\n', f);
        json_decref(a);
    }
    rc = 0;
    if (out && fclose(f) != 0) {
        rig_fail(RIG_ERR_IO, "refl session export: write error on %s: %s", out, strerror(errno));
        rc = 1;
    }
    f = NULL;
done:
    if (f && f != stdout) fclose(f);
    free(rows);
    rig_journal_close(j);
    return rc;
}

int rig_cmd_session(int argc, char **argv)
{
    if (argc >= 2 && (!strcmp(argv[1], "-h") || !strcmp(argv[1], "--help"))) {
        session_usage(stdout);
        return 0;
    }
    if (argc < 3) return usage_error("session", "needs an action and a directory: check DIR | export DIR", NULL);
    const char *action = argv[1], *dir = argv[2], *format = NULL, *out = NULL;
    for (int i = 3; i < argc; i++) {
        if (!strcmp(argv[i], "--format") && i + 1 < argc) format = argv[++i];
        else if (!strcmp(argv[i], "-o") && i + 1 < argc) out = argv[++i];
        else return usage_error("session", "unexpected argument", argv[i]);
    }
    if (!strcmp(action, "check")) {
        if (format || out) return usage_error("session", "check takes no options", NULL);
        return session_check(dir);
    }
    if (!strcmp(action, "export")) {
        if (!format || (strcmp(format, "csv") && strcmp(format, "json")))
            return usage_error("session", "export needs --format csv or --format json", NULL);
        return session_export(dir, format, out);
    }
    return usage_error("session", "unknown action (check or export):", action);
}
