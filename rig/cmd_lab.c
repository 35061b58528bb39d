// rig/cmd_lab.c — `refl plan day`: a lab file's day on a rig (rig_lab_day_write, rig/lab.h):
// the options, the library call, the files it wrote.
#include <stdio.h>

#include "model/model.h"
#include "model/base/opts.h"
#include "rig/lab.h"

#define ABOUT                                                                                                  \
    "Reads the lab file (the lab's own facts: examples/lab.ini documents every key) and writes the capture\n" \
    "plans of its lab day for the rig's own lamps (a virtual rig's: those of its truth file), each written\n" \
    "and read back by refl's plan format: DIR/check.ini (the workpiece's first session), DIR/reference_white.ini\n" \
    "(the white under each lamp), DIR/coupon_NAME.ini (each coupon on its wedge under each lamp, bracketed);\n"  \
    "a plan = FILE of the lab file is taken as it is instead. DIR/day.sh holds the day's facts as shell\n"     \
    "assignments (every value quoted) for scripts/demo, which refl demo --lab runs. Nothing is written\n"     \
    "outside DIR."
#define EPILOG "Exit: 0 done, 1 error (the lab file's line, what to write), 2 usage."

int rig_cmd_plan_day(int argc, char **argv)
{
    const char *rig = NULL, *lab_path = NULL, *out = NULL;
    model_opt_t opts[] = {
        MODEL_OPT_STRING("--rig", "RIG.ini", "the rig file: its lamps (a virtual rig's: its truth file's)", &rig, true),
        MODEL_OPT_STRING("--lab", "LAB.ini", "the lab file (examples/lab.ini)", &lab_path, true),
        MODEL_OPT_OUT("DIR", "the output directory (created)", &out, true),
    };
    model_cli_t cli = { .cmd = "plan day", .synopsis = "", .about = ABOUT, .epilog = EPILOG, .opts = opts,
                        .nopts = MODEL_NOPTS(opts) };
    int rc = model_cli_parse(&cli, argc, argv);
    if (rc != MODEL_CLI_OK) return rc;
    bool q = model_error_quiet_thread(true);   // the library's message is printed once, here
    rig_lab_t *lab = rig_lab_load(lab_path);
    rig_lab_day_t day;
    bool ok = lab && rig_lab_day_write(lab, rig, out, &day);
    model_error_quiet_thread(q);
    if (!ok) {
        rig_lab_free(lab);
        return model_error_report("plan day");
    }
    for (int k = 0; k < day.nplans; k++) printf("plan: %s\n", day.plans[k]);
    printf("refl plan day: %d plans for %s and %s; the day's facts: %s\n", day.nplans, rig, lab_path, day.script);
    rig_lab_day_free(&day);
    rig_lab_free(lab);
    return 0;
}
