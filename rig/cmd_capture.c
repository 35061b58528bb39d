// rig/cmd_capture.c — `refl capture` (run, dry-run or resume a capture
// session) and `refl session` (check, export). Usage errors exit 2, runtime
// errors 1, a paused session 3 (see rig/session/session.h).
#define _GNU_SOURCE
#include <errno.h>
#include <glib.h>
#include <jansson.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include "model/model.h"
#include "model/base/opts.h"
#include "rig/rig.h"

static const char capture_about[] =
    "also:  refl capture PLAN.ini --rig RIG.ini --dry-run\n"
    "       refl capture --resume DIR [--rig RIG.ini] [--allow-changed]\n"
    "\n"
    "Runs the plan (see examples/plans/ and rig/session/session.h) into the session directory DIR: a SQLite\n"
    "journal (session.sqlite) and 16-bit PNG frames (frames/). --dry-run prints the steps, the\n"
    "estimated duration and disk use and checks the plan against the rig; nothing moves.\n"
    "--calib DIR records the calibrations in use (their paths and sha256; with several cameras also\n"
    "each camera's own: NAME.cameramodel, NAME/gain.json, NAME/white.json) in the session.\n"
    "--resume continues a stopped session where it stopped; it refuses when the plan or the rig file\n"
    "changed since, or the camera is another one (its serial differs from the journal's);\n"
    "--allow-changed continues the stored step list anyway.\n"
    "Operator steps (the plan's [sample] first: put the sample on its wedge ...): lamps off, the\n"
    "instruction is printed and the session waits: Enter on a terminal answers done, q pauses;\n"
    "--yes answers every step done; --operator-input FILE one answer a line (empty, done, y, yes:\n"
    "done; q, pause, stop: pause). With stdin not a terminal and neither option the session pauses\n"
    "at the step (exit 3); --resume asks again (an answered step is not asked again).\n"
    "First Ctrl-C: finish the frame, lamps off, pause (exit 3); during homing or a move: stop the\n"
    "stage (profiled stop), pause (exit 3; --resume homes or moves again). Second: stop at once.\n"
    "Exit: 0 complete, 1 error or fault, 2 usage, 3 paused.";

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

// --dry-run: the steps, the estimates, and the plan checked against the rig (nothing moves).
static void print_dry_run(const rig_plan_t *p, const rig_t *r)
{
    rig_frame_meta_t m = { 0 };
    rig_camera_settings(r->camera, &m);
    printf("plan: %s (sha256 %s)\nsample: %s (%s)\nrig: %s\n", p->path, p->sha256, p->sample, p->sample_kind,
           r->path);
    int nframes = 0;
    for (int i = 0; i < p->nsteps; i++) nframes += p->steps[i].kind != RIG_STEP_OPERATOR;
    printf("steps: %d (%d operator step%s; %d frames: %d angles x %d lamp sets x %d exposures x %d repeats%s%s%s)\n",
           p->nsteps, p->nsteps - nframes, p->nsteps - nframes == 1 ? "" : "s", nframes, p->nangles, p->nlamp_sets,
           p->nexposures, p->repeats, p->nviews ? ", as the [view] sections choose" : "",
           p->dark_every ? ", dark frames" : "", p->auto_exposure ? "; auto bracketing: at most" : "");
    if (r->ncameras > 1) {
        printf("cameras: %d, each step triggers every one in this order (%d frames in all):", r->ncameras,
               nframes * r->ncameras);
        for (int k = 0; k < r->ncameras; k++) printf(" %s", r->camera_names[k]);
        printf("\n");
    }
    for (int i = 0; i < p->nsteps; i++) {
        const rig_step_t *s = &p->steps[i];
        if (s->kind == RIG_STEP_OPERATOR) {
            printf("  %6d  operator: %s\n", i, p->ops[s->op].instruction);
            continue;
        }
        printf("  %6d  %-5s angle %10.4f deg  lamps %-20s exposure %10.6g us  gain %g%s\n", i,
               s->kind == RIG_STEP_DARK ? "dark" : "light", s->angle_deg, s->lamps, s->exposure_us, s->gain,
               s->repeat ? " (repeat)" : "");
    }
    double floor_s = rig_plan_floor_s(p, r, 0);
    double bytes = (double)nframes * m.width * m.height * 2.0;
    printf("estimated_duration_s: %.1f (hardware floor: motions, settles, exposures; plus homing)\n", floor_s);
    printf("estimated_disk_bytes: %.0f (at most: %d frames of %d x %d 16-bit; PNG compresses them)\n", bytes,
           nframes, m.width, m.height);
    printf("check: plan matches the rig (lamps exist, angles within range, the camera accepts every exposure)\n");
}

static int dry_run(const rig_capture_opts_t *o)
{
    rig_plan_t *p = rig_plan_load(o->plan_path);
    if (!p) return 1;
    model_note("opening the rig %s", o->rig_path);
    rig_t *r = NULL;
    int rc = rig_open(&r, o->rig_path);
    if (!rc) rc = rig_plan_bind(p, r);
    if (!rc) print_dry_run(p, r);
    char *msg = rc ? g_strdup(model_last_error()) : NULL;
    rig_close(r);
    rig_plan_free(p);
    if (msg) model_error_set(NULL, 0, "%s", msg);
    g_free(msg);
    return rc ? 1 : 0;
}

// The end of a complete run, on stdout.
static void print_summary(const char *dir, const rig_capture_summary_t *s)
{
    if (s->was_complete) {
        printf("refl capture: %s is complete: nothing to resume (refl session check %s)\n", dir, dir);
        return;
    }
    printf("refl capture: session %s complete\n  steps: %d, frames: %d (%d this run)%s\n  wall time: %.1f s, hardware "
           "floor: %.1f s (ratio %.3f); in the camera (trigger to frame in hand): %.1f s; "
           "waiting for the writer: %.1f s\n  check: refl session check %s\n",
           dir, s->steps, s->frames, s->frames_run, s->auto_exposure ? " (auto bracketing skips the rest)" : "",
           s->wall_s, s->floor_s, s->floor_s > 0 ? s->wall_s / s->floor_s : 0, s->camera_s, s->writer_wait_s, dir);
}

int rig_cmd_capture(int argc, char **argv)
{
    rig_capture_opts_t o = { .progress = -1 };
    const char *out_dir = NULL, *resume_dir = NULL, *progress = NULL;
    bool dry = false, allow_changed = false, yes = false;
    const char *operator_input = NULL;
    model_opt_t opts[] = {
        MODEL_OPT_STRING("--rig", "RIG.ini", "the rig description file", &o.rig_path, false),
        MODEL_OPT_OUT("DIR", "the session directory (new or empty)", &out_dir, false),
        MODEL_OPT_STRING("--operator", "NAME", "who runs the session (recorded)", &o.operator_name, false),
        MODEL_OPT_STRING("--notes", "TEXT", "notes recorded with the session", &o.notes, false),
        MODEL_OPT_STRING("--calib", "DIR", "the calibrations in use (recorded by path and sha256)", &o.calib_dir,
                         false),
        MODEL_OPT_STRING("--progress", "bar|lines", "progress display (default: bar on a terminal)", &progress,
                         false),
        MODEL_OPT_FLAG("--dry-run", NULL, "print the steps and check the plan against the rig; nothing moves",
                       &dry),
        MODEL_OPT_STRING("--resume", "DIR", "continue the session in DIR where it stopped", &resume_dir, false),
        MODEL_OPT_FLAG("--allow-changed", NULL, "--resume: continue although the plan, rig file or camera changed",
                       &allow_changed),
        RIG_OPERATOR_OPTS(&yes, &operator_input),
    };
    model_cli_t c = { .cmd = "capture", .synopsis = "PLAN.ini", .about = capture_about, .opts = opts,
                      .nopts = MODEL_NOPTS(opts), .min_positional = 0, .max_positional = 1 };
    int rc = model_cli_parse(&c, argc, argv);
    if (rc != MODEL_CLI_OK) return rc == MODEL_CLI_HELP ? 0 : rc;
    o.plan_path = c.npositional ? c.positional[0] : NULL;
    o.allow_changed = allow_changed;
    o.resume = resume_dir != NULL;
    o.dir = resume_dir ? resume_dir : out_dir;
    if (progress) {
        if (!strcmp(progress, "bar")) o.progress = 1;
        else if (!strcmp(progress, "lines")) o.progress = 0;
        else return model_cli_error(&c, "option --progress: write bar or lines, not %s", progress);
    }
    if (o.resume) {
        if (dry) return model_cli_error(&c, "--dry-run and --resume do not go together");
    } else {
        if (!o.plan_path)
            return model_cli_error(&c, "missing the plan file (refl capture PLAN.ini --rig RIG.ini -o DIR)");
        if (!o.rig_path) return model_cli_error(&c, "missing required option --rig RIG.ini");
        if (!o.dir && !dry) return model_cli_error(&c, "missing -o DIR (the session directory)");
        if (o.allow_changed) return model_cli_error(&c, "--allow-changed is for --resume");
    }
    if (yes && operator_input) return model_cli_error(&c, "give --yes or --operator-input FILE, not both");
    // the library's error is printed once, here; its notes and progress carry the command's name
    bool q = model_error_quiet_thread(true);
    if (dry) {
        rc = dry_run(&o);
    } else if (!(o.op = rig_operator_open(yes, operator_input))) {
        rc = 1;
    } else {
        rig_capture_summary_t sum = { 0 };
        char *cl = join_args(argc, argv);
        o.command_line = cl;
        o.summary = &sum;
        rc = rig_capture_run(&o);
        g_free(cl);
        rig_operator_close(o.op);
        if (rc == 0) print_summary(o.dir, &sum);
    }
    model_error_quiet_thread(q);
    fflush(stdout);
    if (rc == 1) model_error_report("capture");
    return rc;
}

// ---------------------------------------------------------------------------
// refl session

enum { SESSION_CHECK_LIST = 10 };   // missing steps listed one by one (the count covers all)

static const char session_about[] =
    "actions:\n"
    "  check DIR    every frame against its sha256, the steps still missing and SQLite's integrity\n"
    "               check of the journal (refl session check --help)\n"
    "  export DIR   the frame table, one row per frame (refl session export --help)";

static const char session_check_about[] =
    "Checks the session in DIR: every committed frame against the sha256 in the journal, SQLite's\n"
    "PRAGMA integrity_check on the journal (DIR/session.sqlite), and the steps not yet captured (their\n"
    "count, and the first 10 with their angle, lamps and exposure). Operator steps are listed with\n"
    "their instruction and whether they were answered (the answers: the journal's events 'operator').\n"
    "Exit: 0 when every frame is intact, the journal passes and no step is missing (--allow-incomplete:\n"
    "missing steps are fine), 1 otherwise. Reads a session it cannot write (read-only).";

static const char session_export_about[] =
    "Writes the frame table of the session in DIR, one row per frame, as CSV (a header line) or JSON\n"
    "(an array of objects), to stdout or to -o FILE. A journal that fails SQLite's PRAGMA integrity_check\n"
    "is refused (exit 1) before anything is written. Reads a session it cannot write (read-only).";

// The frames against their hashes; prints each bad one. The count of bad frames.
static int check_frames(const char *dir, const rig_frame_row_t *rows, int nrows)
{
    int bad = 0;
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
    return bad;
}

static int session_check(const char *dir, bool allow_incomplete)
{
    rig_journal_t *j = NULL;
    rig_frame_row_t *rows = NULL;
    rig_step_t *steps = NULL;
    char *status = NULL, *integrity = NULL;
    int nrows = 0, nsteps = 0, bad = 0, missing = 0, skipped = 0, rc = 1;
    if (rig_journal_open(&j, dir)) goto done;
    if (rig_journal_integrity(j, &integrity)) goto done;
    bool intact = !strcmp(integrity, "ok");
    if (!intact) {
        printf("journal_integrity: FAILED: %s\n", integrity);
        rig_fail(RIG_ERR_IO, "refl session check: %s fails SQLite's integrity check: %s", rig_journal_path(j),
                 integrity);
        goto done;
    }
    if (rig_journal_frames(j, &rows, &nrows) || rig_journal_steps(j, &steps, &status, &nsteps)) goto done;
    bad = check_frames(dir, rows, nrows);
    for (int i = 0; i < nsteps; i++) {
        if (status[i] == 's') skipped++;
        if (steps[i].kind == RIG_STEP_OPERATOR) {
            char *note = rig_journal_step_note(j, steps[i].index);
            printf("operator step %d: %s: %s\n", steps[i].index, status[i] == 'd' ? "answered" : "not answered yet",
                   note ? note : "(no instruction)");
            free(note);
        }
        if (status[i] != 'p') continue;
        if (missing < SESSION_CHECK_LIST && steps[i].kind == RIG_STEP_OPERATOR)
            printf("missing step %d: operator (see above)\n", steps[i].index);
        else if (missing < SESSION_CHECK_LIST)
            printf("missing step %d: %s angle %g deg lamps %s exposure %g us\n", steps[i].index,
                   steps[i].kind == RIG_STEP_DARK ? "dark" : "light", steps[i].angle_deg, steps[i].lamps,
                   steps[i].exposure_us);
        missing++;
    }
    if (missing > SESSION_CHECK_LIST)
        printf("... and %d more missing step(s) (%d in all)\n", missing - SESSION_CHECK_LIST, missing);
    char state[32] = "";
    rig_journal_state(j, state, sizeof state);
    printf("session: %s\nstate: %s\njournal_integrity: ok\nsteps: %d\nframes: %d\nframes_verified: %d\n"
           "frames_bad: %d\nsteps_skipped: %d\nsteps_missing: %d\n", dir, state, nsteps, nrows, nrows - bad, bad,
           skipped, missing);
    rc = 0;
    if (bad) {
        rig_fail(RIG_ERR_IO, "refl session check: %d frame(s) of %s fail their hash or are missing", bad, dir);
        rc = 1;
    }
    if (missing && !allow_incomplete) {
        rig_fail(RIG_ERR_INVALID, "refl session check: %s is incomplete: %d of %d step(s) missing (continue it "
                 "with refl capture --resume %s, or add --allow-incomplete)", dir, missing, nsteps, dir);
        rc = 1;
    }
done:
    g_free(integrity);
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
    if (rig_journal_open(&j, dir) || rig_journal_check(j) || rig_journal_frames(j, &rows, &n)) goto done;
    f = out ? fopen(out, "w") : stdout;
    if (!f) {
        rig_fail(RIG_ERR_IO, "refl session export: cannot create %s: %s", out, strerror(errno));
        goto done;
    }
    if (!strcmp(format, "csv")) {
        rig_frame_rows_write_csv(f, rows, n);
    } else {
        json_t *doc = rig_frame_rows_json(rows, n);
        if (!doc || json_dumpf(doc, f, JSON_INDENT(1))) {
            json_decref(doc);
            rig_fail(RIG_ERR_NO_MEM, "refl session export: out of memory for %d frames", n);
            goto done;
        }
        fputc('\n', f);
        json_decref(doc);
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

static int cmd_session_check(int argc, char **argv)
{
    bool allow_incomplete = false;
    model_opt_t opts[] = {
        MODEL_OPT_FLAG("--allow-incomplete", NULL, "missing steps are not an error (exit 0 when the rest is fine)",
                       &allow_incomplete),
    };
    model_cli_t c = { .cmd = "session check", .synopsis = "DIR", .about = session_check_about, .opts = opts,
                      .nopts = MODEL_NOPTS(opts), .min_positional = 1, .max_positional = 1 };
    int rc = model_cli_parse(&c, argc, argv);
    if (rc != MODEL_CLI_OK) return rc == MODEL_CLI_HELP ? 0 : rc;
    return session_check(c.positional[0], allow_incomplete);
}

static int cmd_session_export(int argc, char **argv)
{
    const char *format = NULL, *out = NULL;
    model_opt_t opts[] = {
        MODEL_OPT_STRING("--format", "csv|json", "the output format", &format, true),
        MODEL_OPT_OUT("FILE", "write to FILE instead of stdout", &out, false),
    };
    model_cli_t c = { .cmd = "session export", .synopsis = "DIR", .about = session_export_about, .opts = opts,
                      .nopts = MODEL_NOPTS(opts), .min_positional = 1, .max_positional = 1 };
    int rc = model_cli_parse(&c, argc, argv);
    if (rc != MODEL_CLI_OK) return rc == MODEL_CLI_HELP ? 0 : rc;
    if (strcmp(format, "csv") && strcmp(format, "json"))
        return model_cli_error(&c, "option --format: write csv or json, not %s", format);
    return session_export(c.positional[0], format, out);
}

int rig_cmd_session(int argc, char **argv)
{
    // argv[0] is "session"; an action parses its own options (and --help).
    if (argc >= 2 && !strcmp(argv[1], "check")) return cmd_session_check(argc - 1, argv + 1);
    if (argc >= 2 && !strcmp(argv[1], "export")) return cmd_session_export(argc - 1, argv + 1);
    model_cli_t c = { .cmd = "session", .synopsis = "check|export DIR", .about = session_about,
                      .min_positional = 0, .max_positional = 2 };
    int rc = model_cli_parse(&c, argc, argv);
    if (rc != MODEL_CLI_OK) return rc == MODEL_CLI_HELP ? 0 : rc;
    if (c.npositional < 1) return model_cli_error(&c, "needs an action and a directory: check DIR | export DIR");
    return model_cli_error(&c, "unknown action (check or export): %s", c.positional[0]);
}
