// rig/session/resume.c — what `refl capture --resume` checks and recovers:
// the frames directory after a crash, the camera against the journal's, the
// operator steps answered earlier.
#define _GNU_SOURCE
#include <dirent.h>
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include <jansson.h>

#include "model/model.h"
#include "rig/rig.h"
#include "rig/session/internal.h"

// Put the frames directory in order after a crash: committed frames whose file
// was not yet linked are linked; temporary files of uncommitted frames removed.
int capture_recover_frames(rig_journal_t *j, const char *dir, int *relinked, int *removed)
{
    *relinked = *removed = 0;
    rig_frame_row_t *rows = NULL;
    int n = 0, rc = rig_journal_frames(j, &rows, &n);
    if (rc) return rc;
    char fd[4096];
    snprintf(fd, sizeof fd, "%s/frames", dir);
    DIR *d = opendir(fd);
    if (!d) {
        free(rows);
        return rig_fail(RIG_ERR_IO, "%s: %s", fd, strerror(errno));
    }
    struct dirent *e;
    while ((e = readdir(d))) {
        if (e->d_name[0] != '.' || !strcmp(e->d_name, ".") || !strcmp(e->d_name, "..")) continue;
        char path[4400];
        snprintf(path, sizeof path, "%s/%s", fd, e->d_name);
        int step = -1;
        size_t len = strlen(e->d_name);
        bool part = sscanf(e->d_name, ".s%d", &step) == 1 && len > 6 && !strcmp(e->d_name + len - 5, ".part") &&
                    !strstr(e->d_name, ".tmp");
        char rel[300] = "";   // its committed name: frames/sNNNNNN[_NAME].png
        if (part) snprintf(rel, sizeof rel, "frames/%.*s", (int)(len - 6), e->d_name + 1);
        const rig_frame_row_t *row = NULL;
        for (int i = 0; part && i < n; i++)
            if (!strcmp(rows[i].file, rel)) row = &rows[i];
        if (row) {
            char fin[4400], sha[65];
            snprintf(fin, sizeof fin, "%s/%s", dir, row->file);
            struct stat st;
            if (stat(fin, &st) != 0 && model_sha256_file(path, sha) && !strcmp(sha, row->sha256) &&
                link(path, fin) == 0) {
                (*relinked)++;
                rig_journal_event(j, step, "info", "recovered %s (committed before the crash, not yet linked)",
                                  row->file);
            } else if (stat(fin, &st) != 0) {
                continue;   // keep it for refl session check to report
            }
        } else {
            (*removed)++;
        }
        unlink(path);
    }
    closedir(d);
    free(rows);
    return 0;
}

// --resume: the camera is the one the session started with (its serial
// against the journal's facts); another camera is refused unless
// --allow-changed (then the event log says so).
int capture_check_camera(run_t *x)
{
    json_t *f = NULL;
    if (!x->r->camera) return 0;
    if (!rig_journal_facts_read(x->j, &f)) return RIG_ERR_PROTOCOL;   // a newer version (or unreadable)
    json_t *cams = json_object_get(f, "cameras");
    int rc = 0;
    for (int k = 0; k < x->r->ncameras && !rc; k++) {
        // its serial then: by name in "cameras", or the first camera's "camera" (a session of one camera)
        const char *was = k == 0 ? json_string_value(json_object_get(json_object_get(f, "camera"), "serial")) : NULL;
        size_t i;
        json_t *c;
        json_array_foreach(cams, i, c)
            if (!strcmp(json_string_value(json_object_get(c, "camera")) ?: "", x->r->camera_names[k]))
                was = json_string_value(json_object_get(c, "serial"));
        rig_frame_meta_t m;
        if (!was || !was[0] || (rc = rig_camera_settings(x->r->cameras[k], &m)) || !strcmp(was, m.serial)) continue;
        if (!x->o->allow_changed)
            rc = rig_fail(RIG_ERR_INVALID, "--resume %s: the camera changed: %s%s%sserial %s now, the "
                          "session started with serial %s: connect that camera, or add --allow-changed to continue "
                          "with this one", x->o->dir, x->r->ncameras > 1 ? "camera " : "",
                          x->r->ncameras > 1 ? x->r->camera_names[k] : "", x->r->ncameras > 1 ? ": " : "", m.serial,
                          was);
        else
            rig_journal_event(x->j, -1, "info", "resumed with another camera %s: serial %s, the session started "
                              "with %s (--allow-changed)", x->r->camera_names[k], m.serial, was);
    }
    json_decref(f);
    return rc;
}

// --resume: the operator steps answered earlier are not asked again; their
// poses are applied again (a virtual rig; on a real rig the sample is where
// the operator put it).
int capture_replay_operator(run_t *x)
{
    for (int i = 0; i < x->p->nsteps; i++) {
        if (x->p->steps[i].kind != RIG_STEP_OPERATOR || x->status[i] != 'd') continue;
        char what[512];
        if ((x->rc = rig_plan_operator_pose(x->p, x->r, i, what, sizeof what))) return RUN_DONE;
        rig_journal_event(x->j, i, "info", "resume: operator step %d was answered earlier, not asked again; %s%s", i,
                          what, x->r->virt ? " again" : " (still in place)");
    }
    return RUN_ON;
}
