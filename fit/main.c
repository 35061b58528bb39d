// fit/main.c — bin/refl: the command dispatcher, above every layer (fit is the
// top floor, so the dispatcher lives in its folder: it includes every layer and
// none includes it).
#include <glib.h>
#include <stdio.h>
#include <errno.h>
#include <string.h>
#include <unistd.h>

#include "model/model.h"
#include "model/base/report.h"
#include "calib/calib.h"
#include "fit/eval/chain.h"
#include "fit/material/export.h"
#include "fit/brdf/brdf.h"
#include "fit/verify/verify.h"
#include "fit/lightplan/lightplan.h"
#include "model/base/opts.h"
#include "rig/rig.h"

typedef struct {
    const char *name;
    int (*run)(int argc, char **argv);
    const char *summary;
} command_t;

static int demo_cmd(int argc, char **argv);

static const command_t commands[] = {
    { "render", model_cmd_render, "render a scene through the imaging model to a PNG/TIFF image" },
    { "edges",  model_cmd_edges,  "list scene edges: visible image segments, lighting per side, contrast" },
    { "workpiece", model_cmd_workpiece, "write the reference workpiece (T/I/no stiffener, shifted, rotated, scaled) as D3D" },
    { "brdf",   model_cmd_brdf,   "tabulate a reflection model outside the fitted ones as a MERL binary (refl brdf tabulate)" },
    { "rig",    rig_cmd,          "drive the rig of a rig file: status, home, move, identify, snap, serve" },
    { "capture", rig_cmd_capture, "run a capture plan on the rig into a session directory (journal + frames)" },
    { "session", rig_cmd_session, "check a session's frames against their hashes, export its frame table" },
    { "calib",   calib_cmd,       "calibrate camera geometry and turntable axis, lamp positions, sensitivity" },
    { "fit",     fit_cmd,         "fit reflection models to BRDF samples and write priors" },
    { "verify",  verify_cmd,      "verify a scene description against images: fit within the priors, residue, changes, verdict" },
    { "demo",    demo_cmd,        "the whole lab day on the virtual rig: calibrations, materials, light planning, verification" },
    { "chain",   eval_chain_cmd,  "compare a lab day's calibrated and fitted figures with the virtual rig's truth: chain.json" },
    { "export",  fit_cmd_export,  "a priors file's materials as glTF 2.0, Mitsuba 3 or MERL, with the conversion error" },
    { "plan",    lightplan_cmd,   "plan lamps: lamps and exposure for detectable edges; plan geometry: the board's poses; plan day: a lab file's plans" },
};

static void usage(FILE *f)
{
    fprintf(f, "usage: refl COMMAND [ARGS...]   (refl COMMAND --help for its options)\n\ncommands:\n");
    for (size_t i = 0; i < sizeof commands / sizeof commands[0]; i++)
        fprintf(f, "  %-10s %s\n", commands[i].name, commands[i].summary);
    fprintf(f, "\n");
    model_cli_exit_status(f);
    fprintf(f, "\nrefl %s\n", REFL_VERSION);
}

// `refl demo [-o DIR] [--rig RIG.ini | --truth TRUTH.ini] [--lab LAB.ini] [--yes | --operator-input FILE] [--until STAGE]
// [--white-table CSV]`: scripts/demo with this binary (found by model_share_path: a build tree's scripts/, or an
// installation's share/refl/scripts/).
static int demo_cmd(int argc, char **argv)
{
    const char *out = "refl-demo", *rig = NULL, *truth = NULL, *operator_input = NULL, *until = NULL,
               *white_table = NULL, *lab = NULL;
    bool yes = false;
    model_opt_t opts[] = {
        MODEL_OPT_OUT("DIR", "output directory (default refl-demo)", &out, false),
        MODEL_OPT_STRING("--rig", "RIG.ini", "run the lab day on this rig (default: the virtual rig, --yes)", &rig,
                         false),
        MODEL_OPT_STRING("--truth", "TRUTH.ini", "the virtual rig of this truth file (default "
                         "examples/virtual-truth.ini; examples/virtual-truth-adversarial.ini: physics outside the "
                         "fitters' models)", &truth, false),
        MODEL_OPT_STRING("--lab", "LAB.ini", "the lab's own facts (examples/lab.ini documents every key): the "
                         "day's plans are generated for the rig's lamps (refl plan day) and checked first",
                         &lab, false),
        MODEL_OPT_STRING("--until", "STAGE", "end the day after this stage: plans (with --lab: written and "
                         "checked), calibrations, or captures (the calibrations and the coupon sessions: the rig's "
                         "work before the offline fits); default all", &until, false),
        MODEL_OPT_STRING("--white-table", "CSV", "the reference white's certificate (refl calib white "
                         "--reflectance-table; default: Lambertian, albedo 0.99; the adversarial rig's: "
                         "examples/virtual-white-certificate.csv)", &white_table, false),
        RIG_OPERATOR_OPTS(&yes, &operator_input),
    };
    model_cli_t cli = {
        .cmd = "demo", .opts = opts, .nopts = MODEL_NOPTS(opts),
        .about = "Runs the whole lab day on the virtual rig (scripts/demo): geometry, lamp and gain\n"
                 "calibrations, the reference white, three material sessions and their fits, light planning\n"
                 "for the workpiece and its verification against the correct and wrong descriptions, each\n"
                 "result next to the rig's truth; prints the path of DIR/index.html.\n"
                 "--rig RIG.ini: the same day on that rig, the operator steps in order (put the board on its\n"
                 "wedge, the chrome ball, the flat-field source, the reference white, each coupon, the\n"
                 "workpiece), answered by --yes, --operator-input FILE (passed to every capture) or on the\n"
                 "terminal. A pause ends it with exit 3: run the same command again to continue (complete\n"
                 "sessions are kept, a partial one resumed). A rig that is not virtual has no truth to\n"
                 "compare with: that part is skipped.\n"
                 "--lab LAB.ini: the lab's own facts instead of the example virtual rig's (the ball, the\n"
                 "lamps' size, the source's radiance, the white and its certificate, the coupons and wedges,\n"
                 "the workpiece, its descriptions, the geometry session's tilts): refl plan day writes the\n"
                 "day's plans for the rig's own lamps into DIR/lab/, each checked against the rig first.\n"
                 "--truth TRUTH.ini: the day on the virtual rig of that truth file. On a virtual rig every\n"
                 "calibrated and fitted figure is compared with the truth in DIR/chain.json (refl chain:\n"
                 "value, truth, the sigma refl states, error and z) and DIR/chain.html.",
    };
    int rc = model_cli_parse(&cli, argc, argv);
    if (rc != MODEL_CLI_OK) return rc;
    if (yes && operator_input) return model_cli_error(&cli, "give --yes or --operator-input FILE, not both");
    if (rig && truth)
        return model_cli_error(&cli, "give --rig RIG.ini or --truth TRUTH.ini, not both (a virtual rig file names "
                               "its truth file)");
    if (until && strcmp(until, "plans") && strcmp(until, "calibrations") && strcmp(until, "captures") &&
        strcmp(until, "all"))
        return model_cli_error(&cli, "--until %s: give plans, calibrations, captures or all", until);
    char exe[4096];
    ssize_t n = readlink("/proc/self/exe", exe, sizeof exe - 1);
    if (n <= 0) {
        fprintf(stderr, "refl demo: cannot find this executable (/proc/self/exe)\n");
        return 1;
    }
    exe[n] = 0;
    char *script = model_share_path("scripts", "demo");
    if (!script) {
        fprintf(stderr, "refl demo: %s\n", model_last_error());
        return 1;
    }
    char *args[24] = { (char *)"/bin/bash", script, exe, (char *)out };
    int na = 4;
    if (rig) {
        args[na++] = (char *)"--rig";
        args[na++] = (char *)rig;
    }
    if (truth) {
        args[na++] = (char *)"--truth";
        args[na++] = (char *)truth;
    }
    if (lab) {
        args[na++] = (char *)"--lab";
        args[na++] = (char *)lab;
    }
    if (yes) args[na++] = (char *)"--yes";
    if (operator_input) {
        args[na++] = (char *)"--operator-input";
        args[na++] = (char *)operator_input;
    }
    if (until) {
        args[na++] = (char *)"--until";
        args[na++] = (char *)until;
    }
    if (white_table) {
        args[na++] = (char *)"--white-table";
        args[na++] = (char *)white_table;
    }
    args[na] = NULL;
    execv("/bin/bash", args);
    fprintf(stderr, "refl demo: cannot run /bin/bash %s: %s\n", script, strerror(errno));
    g_free(script);
    return 1;
}

int main(int argc, char **argv)
{
    model_set_command_line(argc, argv);   // provenance records the command as typed
    if (argc < 2) {
        usage(stderr);
        return 2;
    }
    if (!strcmp(argv[1], "--help") || !strcmp(argv[1], "-h") || !strcmp(argv[1], "help")) {
        usage(stdout);
        return 0;
    }
    if (!strcmp(argv[1], "--version")) {
        printf("refl %s\n", REFL_VERSION);
        return 0;
    }
    for (size_t i = 0; i < sizeof commands / sizeof commands[0]; i++) {
        if (strcmp(argv[1], commands[i].name)) continue;
        // the library's notes and warnings are named by the command as typed:
        // "refl calib geometry: ...", "refl verify: ..."
        static const char *const with_sub[] = { "rig", "calib", "fit", "session", "brdf", "export", "plan" };
        char prefix[128];
        snprintf(prefix, sizeof prefix, "refl %s", argv[1]);
        for (size_t k = 0; k < sizeof with_sub / sizeof with_sub[0]; k++)
            if (!strcmp(argv[1], with_sub[k]) && argc > 2 && argv[2][0] != '-')
                snprintf(prefix, sizeof prefix, "refl %s %s", argv[1], argv[2]);
        model_notice_prefix(prefix);
        int rc = commands[i].run(argc - 1, argv + 1);
        // a failed run leaves no empty output directory (3, a paused session, is resumed later; 4, an
        // incorrect verdict, wrote its outputs)
        if (rc != MODEL_EXIT_OK && rc != MODEL_EXIT_PAUSED && rc != MODEL_EXIT_INCORRECT)
            model_remove_made_empty_dirs();
        return rc;
    }
    fprintf(stderr, "refl: unknown command '%s'\n", argv[1]);
    usage(stderr);
    return 2;
}
