// rig/session/reader.c — reading a capture session: its journal's frames and facts,
// and each frame checked against the journal's hash.
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

#include "model/model.h"
#include "model/base/report.h"
#include "rig/rig.h"


void rig_session_free(rig_session_t *s)
{
    if (!s) return;
    free(s->dir);
    free(s->rows);
    free(s->plan_text);
    json_decref(s->facts);
    free(s);
}

bool rig_journal_facts_read(rig_journal_t *j, json_t **facts)
{
    *facts = NULL;
    char *text = NULL;
    if (rig_journal_facts(j, &text)) return false;
    json_t *f = text[0] ? json_loads(text, 0, NULL) : NULL;
    free(text);
    if (f && !model_json_format_check(f, rig_journal_path(j), RIG_SESSION_FACTS_FORMAT, RIG_SESSION_FACTS_VERSION,
                                      NULL)) {
        json_decref(f);
        return false;
    }
    *facts = f;
    return true;
}

rig_session_t *rig_session_open(const char *dir)
{
    rig_session_t *s = calloc(1, sizeof *s);
    rig_journal_t *j = NULL;
    char *psha = NULL, *rsha = NULL;
    if (!s || !(s->dir = strdup(dir))) goto oom;
    bool q = model_error_quiet_thread(true);
    int e = rig_journal_open(&j, dir);
    model_error_quiet_thread(q);
    if (e) {
        // the journal's message names dir already: said once
        char *why = g_strdup(model_last_error());
        const char *w = why;
        size_t n = strlen(dir);
        if (!strncmp(w, dir, n) && w[n] == ':') w += n + 1 + (w[n + 1] == ' ');
        model_error(dir, 0, "not a capture session: %s", w);
        g_free(why);
        goto fail;
    }
    if (rig_journal_check(j)) {
        model_error(dir, 0, "%s", model_last_error());
        goto fail;
    }
    if (rig_journal_source(j, "plan", NULL, &s->plan_text, &psha) ||
        rig_journal_source(j, "rig", NULL, NULL, &rsha) || rig_journal_frames(j, &s->rows, &s->n)) {
        model_error(dir, 0, "cannot read the session's journal: %s", model_last_error());
        goto fail;
    }
    snprintf(s->plan_sha256, sizeof s->plan_sha256, "%s", psha);
    snprintf(s->rig_sha256, sizeof s->rig_sha256, "%s", rsha);
    if (!rig_journal_facts_read(j, &s->facts)) {
        model_error(dir, 0, "cannot read the session's facts: %s", model_last_error());
        goto fail;
    }
    free(psha);
    free(rsha);
    rig_journal_close(j);
    return s;
oom:
    model_error(dir, 0, "out of memory");
fail:
    free(psha);
    free(rsha);
    rig_journal_close(j);
    rig_session_free(s);
    return NULL;
}

int rig_session_cameras(const rig_session_t *s, const char **names, int max)
{
    int n = 0;
    for (int i = 0; s && i < s->n; i++) {
        bool seen = false;
        for (int k = 0; k < n && k < max; k++) seen |= !strcmp(names[k], s->rows[i].camera);
        if (seen) continue;
        if (n < max) names[n] = s->rows[i].camera;
        n++;
    }
    return n;
}

rig_session_t *rig_session_open_camera(const char *dir, const char *camera)
{
    rig_session_t *s = rig_session_open(dir);
    if (!s) return NULL;
    const char *names[64];
    int nc = rig_session_cameras(s, names, 64);
    if (nc == 0) return s;   // no frames yet
    const char *want = camera ? camera : names[0];
    char keep[32];
    snprintf(keep, sizeof keep, "%s", want);
    int k = 0;
    for (int i = 0; i < s->n; i++)
        if (!strcmp(s->rows[i].camera, keep)) s->rows[k++] = s->rows[i];
    if (k == 0) {
        GString *list = g_string_new("");
        for (int i = 0; i < nc && i < 64; i++) g_string_append_printf(list, "%s%s", i ? ", " : "", names[i]);
        model_error(dir, 0, "the session has no frames of camera '%s' (its cameras: %s)", keep, list->str);
        g_string_free(list, TRUE);
        rig_session_free(s);
        return NULL;
    }
    s->n = k;
    return s;
}

float *rig_session_frame(const rig_session_t *s, int i, int *width, int *height)
{
    if (i < 0 || i >= s->n) {
        model_error(s->dir, 0, "frame %d of %d does not exist", i, s->n);
        return NULL;
    }
    const rig_frame_row_t *r = &s->rows[i];
    char *path = g_strdup_printf("%s/%s", s->dir, r->file);
    char sha[65];
    float *out = NULL;
    if (!model_sha256_file(path, sha)) goto done;
    if (strcmp(sha, r->sha256)) {
        model_error(path, 0, "sha256 %s differs from the journal's %s (step %d): the frame was changed or "
                    "damaged; refl session check %s", sha, r->sha256, r->step, s->dir);
        goto done;
    }
    out = model_image_read_float(path, width, height);
    if (out && (*width != r->width || *height != r->height)) {
        model_error(path, 0, "%dx%d pixels, the journal says %dx%d", *width, *height, r->width, r->height);
        free(out);
        out = NULL;
    }
done:
    g_free(path);
    return out;
}
