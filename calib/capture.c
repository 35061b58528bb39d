// calib/capture.c — running a calibration's capture plan into a session
// directory (reused when complete, resumed when paused).
#define _GNU_SOURCE
#include <errno.h>
#include <fcntl.h>
#include <glib.h>
#include <stdarg.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#include "calib/calib.h"
#include "model/model.h"
#include "model/base/report.h"

int calib_full_scale_dn(const char *pixel_format)
{
    if (!strcmp(pixel_format, "Mono8")) return 255;
    if (!strcmp(pixel_format, "Mono12")) return 4095;
    return 65535;
}

int calib_capture(const char *rig_path, const char *dir, const char *name, const char *plan_text, int progress,
                  rig_operator_t *op)
{
    if (!model_mkdir_p(dir)) return -1;
    char *plan_path = g_strdup_printf("%s/%s.plan.ini", dir, name);
    char *sdir = g_strdup_printf("%s/%s", dir, name);
    char *db = g_strdup_printf("%s/session.sqlite", sdir);
    int rc = -1;
    char sha[65];
    model_sha256_hex(plan_text, strlen(plan_text), sha);
    bool exists = access(db, F_OK) == 0;
    if (exists) {
        // the same plan? then reuse or resume it
        rig_journal_t *j = NULL;
        char *ptext = NULL, *psha = NULL, state[32] = "";
        if (rig_journal_open(&j, sdir)) {
            model_error(sdir, 0, "an earlier session is here but its journal cannot be read (%s); move it away",
                        model_last_error());
            goto done;
        }
        rig_journal_source(j, "plan", NULL, &ptext, &psha);
        rig_journal_state(j, state, sizeof state);
        rig_journal_close(j);
        bool same = psha && !strcmp(psha, sha);
        free(ptext);
        free(psha);
        if (!same) {
            model_error(sdir, 0, "an earlier session with another plan is here; choose another output directory "
                        "or move it away");
            goto done;
        }
        if (!strcmp(state, "complete")) {
            model_note("%s is complete; using its frames", sdir);
            rc = 0;
            goto done;
        }
        model_note("resuming the %s session %s", state, sdir);
    } else if (!model_write_file_atomic(plan_path, plan_text)) {
        goto done;
    }
    rig_capture_opts_t o = { .plan_path = plan_path, .rig_path = rig_path, .dir = sdir, .resume = exists,
                             .progress = progress, .command_line = "refl calib", .op = op };
    int ec = rig_capture_run(&o);
    if (ec == 0) rc = 0;
    else if (ec == 3)
        model_error(sdir, 0, "the capture paused (an operator step not answered, interrupted, or the camera "
                    "stopped answering: see above); run the same command again to resume it (--yes or "
                    "--operator-input FILE answer the operator steps)");
    else
        model_error(sdir, 0, "the capture failed: %s", model_last_error());
done:
    g_free(plan_path);
    g_free(sdir);
    g_free(db);
    return rc;
}
