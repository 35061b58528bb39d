// calib/gain/input.c — where the frames come from: a manifest
// "file,exposure_us,kind" or a capture session's journal (calib/gain/gain.h).
#include <errno.h>
#include <glib.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "calib/calib.h"
#include "calib/gain/internal.h"
#include "model/model.h"

bool gain_add_frame(calib_gain_data_t *d, const calib_gain_frame_t *f)
{
    calib_gain_frame_t *nf = realloc(d->f, sizeof *d->f * (d->nf + 1));
    if (!nf) {
        g_free(f->path);
        g_free(f->where);
        model_error_set(NULL, 0, "out of memory for the frames (%d)", d->nf + 1);
        return false;
    }
    d->f = nf;
    d->f[d->nf++] = *f;
    return true;
}

static char *trim(char *s)
{
    while (*s == ' ' || *s == '\t') s++;
    char *e = s + strlen(s);
    while (e > s && (e[-1] == ' ' || e[-1] == '\t' || e[-1] == '\r' || e[-1] == '\n')) *--e = 0;
    return s;
}

bool calib_gain_read_manifest(const char *path, int max_dn, calib_gain_data_t *d)
{
    char *text = model_read_file(path, NULL);
    if (!text) return false;
    char *dir = g_path_get_dirname(path);
    bool ok = false;
    int line = 0, nframes = 0;
    char *save = NULL;
    for (char *l = text, *next; l; l = next) {
        next = strchr(l, '\n');
        if (next) *next++ = 0;
        line++;
        char *s = trim(l);
        if (!*s || *s == '#') continue;
        char *f[4] = { 0 };
        int nf = 0;
        for (char *p = strtok_r(s, ",", &save); p && nf < 4; p = strtok_r(NULL, ",", &save)) f[nf++] = trim(p);
        if (nf == 3 && nframes == 0 && !strcmp(f[0], "file") && !strcmp(f[1], "exposure_us") && !strcmp(f[2], "kind"))
            continue;   // the header
        if (nf != 3) {
            model_error_set(path, line, "expected 3 fields file,exposure_us,kind, found %d", nf);
            goto done;
        }
        double e;
        if (!model_parse_double(f[1], &e) || !(e > 0)) {
            model_error_set(path, line, "exposure_us '%s' is not a positive number (microseconds)", f[1]);
            goto done;
        }
        // kind: dark | light (the sweep and the dark model), flat | flat-dark (the spatial set: many frames at
        // one level for DSNU, PRNU, spectrograms and defects; aliases spatial-light | spatial-dark)
        bool dark = !strcmp(f[2], "dark") || !strcmp(f[2], "flat-dark") || !strcmp(f[2], "spatial-dark");
        bool flat = !strcmp(f[2], "flat") || !strcmp(f[2], "flat-dark") || !strcmp(f[2], "spatial-light") ||
                    !strcmp(f[2], "spatial-dark");
        if (!dark && !flat && strcmp(f[2], "light")) {
            model_error_set(path, line, "kind '%s' must be dark, light (the sweep), flat or flat-dark (the spatial "
                            "set; also spatial-light, spatial-dark)", f[2]);
            goto done;
        }
        if (!*f[0]) {
            model_error_set(path, line, "empty file name");
            goto done;
        }
        calib_gain_frame_t fr = { .path = f[0][0] == '/' ? g_strdup(f[0]) : g_build_filename(dir, f[0], NULL),
                        .where = g_strdup(path), .line = line, .exposure_us = e, .gain_db = 0, .dark = dark,
                        .set = flat ? CALIB_GAIN_SET_FLAT : CALIB_GAIN_SET_ANY, .max_dn = max_dn, .nlamps = -1 };
        if (access(fr.path, R_OK) != 0) {
            model_error_set(path, line, "frame %s: %s", fr.path, strerror(errno));
            g_free(fr.path);
            g_free(fr.where);
            goto done;
        }
        if (!gain_add_frame(d, &fr)) goto done;
        nframes++;
    }
    if (!nframes) {
        model_error_set(path, 0, "no frames listed (lines file,exposure_us,kind)");
        goto done;
    }
    ok = true;
done:
    g_free(dir);
    free(text);
    return ok;
}

static int lamps_on(const char *lamps, int nlamps_rig)
{
    if (!strcmp(lamps, "none")) return 0;
    if (!strcmp(lamps, "all")) return nlamps_rig;
    int n = 1;
    for (const char *p = lamps; *p; p++) n += *p == '+';
    return n;
}

// Frames of one camera of a session; set: the role of its frames (CALIB_GAIN_SET_ANY: by lamps).
bool calib_gain_add_session(calib_gain_data_t *d, const char *dir, const char *camera, int set,
                            json_t **facts_out)
{
    rig_session_t *s = rig_session_open_camera(dir, camera);   // NULL: the first camera's frames
    if (!s) return false;
    int nlr = -1;
    json_t *lamps = s->facts ? json_object_get(s->facts, "lamps") : NULL;
    if (json_is_array(lamps)) nlr = (int)json_array_size(lamps);
    bool ok = true;
    for (int i = 0; i < s->n && ok; i++) {
        const rig_frame_row_t *r = &s->rows[i];
        const char *unit = r->gain_unit[0] ? r->gain_unit : "dB";   // a session that records no unit: dB
        if (!d->gain_unit[0]) snprintf(d->gain_unit, sizeof d->gain_unit, "%s", unit);
        if (strcmp(d->gain_unit, unit)) {
            model_error_set(dir, 0, "frame %s: gain unit '%s', the run's other frames '%s': one calibration needs "
                            "one unit of gain", r->file, unit, d->gain_unit);
            ok = false;
            break;
        }
        snprintf(d->camera, sizeof d->camera, "%s", r->camera);
        int on = lamps_on(r->lamps, nlr);
        calib_gain_frame_t f = { .path = g_strdup_printf("%s/%s", dir, r->file), .where = g_strdup(dir), .line = 0,
                       .step = r->step, .exposure_us = r->exposure_us, .gain_db = r->gain, .dark = on == 0,
                       .set = set, .max_dn = calib_full_scale_dn(r->pixel_format), .nlamps = on };
        snprintf(f.sha256, sizeof f.sha256, "%s", r->sha256);
        ok = gain_add_frame(d, &f);
    }
    if (ok && facts_out && !*facts_out && s->facts) *facts_out = json_incref(s->facts);
    rig_session_free(s);
    return ok;
}
