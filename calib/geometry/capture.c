// calib/geometry/capture.c — --rig: a capture plan per --tilts entry (the board on
// its wedge, the turntable's angles, all lamps on) and the captures.
#include <errno.h>
#include <glib.h>
#include <stdlib.h>
#include <string.h>

#include "calib/calib.h"
#include "calib/geometry/internal.h"
#include "model/model.h"

static bool parse_num(const char *s, double lo, double hi, double *out)
{
    char *e;
    errno = 0;
    double v = strtod(s, &e);
    if (e == s || *e || errno || !(v >= lo && v <= hi)) return false;
    *out = v;
    return true;
}

// "T[@AZ][:A,A,...]" → plan text; NULL + message.
char *calib_geometry_tilt_plan(const char *spec, const calib_geometry_opts_t *o, char *name, size_t namen)
{
    char *s = g_strdup(spec), *angles = strchr(s, ':'), *at;
    if (angles) *angles++ = 0;
    double tilt = 0, az = 0;
    if ((at = strchr(s, '@'))) *at++ = 0;
    if (!parse_num(s, -80, 80, &tilt) || (at && !parse_num(at, -360, 360, &az))) {
        model_error_set("--tilts", 0, "'%s': write TILT[@AZIMUTH][:ANGLE,ANGLE,...] in degrees, tilt -80..80 "
                        "(e.g. 30@90:0,20,40)", spec);
        g_free(s);
        return NULL;
    }
    GString *al = g_string_new("");
    const char *src = angles ? angles : o->angles;
    char **parts = g_strsplit_set(src, ", ", -1);
    int na = 0;
    for (int i = 0; parts[i]; i++) {
        if (!*parts[i]) continue;
        double a;
        if (!parse_num(parts[i], -10000, 10000, &a)) {
            model_error_set(angles ? "--tilts" : "--angles-deg", 0, "'%s' in '%s' is not an angle in degrees", parts[i],
                            src);
            g_strfreev(parts);
            g_string_free(al, TRUE);
            g_free(s);
            return NULL;
        }
        g_string_append_printf(al, " %g", a);
        na++;
    }
    g_strfreev(parts);
    if (na == 0) {
        model_error_set(angles ? "--tilts" : "--angles-deg", 0, "'%s': no angles", spec);
        g_string_free(al, TRUE);
        g_free(s);
        return NULL;
    }
    snprintf(name, namen, "tilt%g_az%g", tilt, az);
    char what[512];   // the operator's instruction
    if (tilt == 0)
        snprintf(what, sizeof what, "lay the calibration board %s flat at the turntable centre, printed side up "
                 "(no wedge; --tilts '%s')", o->sample, spec);
    else
        snprintf(what, sizeof what, "mount the calibration board %s on the %g deg wedge (hinge at azimuth %g deg; "
                 "--tilts '%s') at the turntable centre, the board facing the camera", o->sample, tilt, az, spec);
    char *plan = g_strdup_printf("# refl calib geometry: the board at tilt %g deg (hinge azimuth %g deg)\n"
                                 "[plan]\nname = calib geometry %s\n"
                                 "[sample]\nname = %s\nkind = chessboard\ntilt_deg = %g\ntilt_azimuth_deg = %g\n"
                                 "instruction = %s\n"
                                 "[angles]\nlist =%s\n[lamps]\nsets = all\n"
                                 "[exposure]\nmode = fixed\nlist_us = %g\npixel_format = Mono12\n"
                                 "[capture]\nsettle_ms = 0\n",
                                 tilt, az, name, o->sample, tilt, az, what, al->str, o->exposure_us);
    g_string_free(al, TRUE);
    g_free(s);
    return plan;
}

const char *calib_geometry_tilts_expand(const char *tilts)
{
    return tilts && !strcmp(tilts, "2cam-example") ? CALIB_GEOMETRY_TILTS_2CAM_EXAMPLE : tilts;
}

bool calib_geometry_capture(const calib_geometry_opts_t *o, calib_geometry_state_t *s, bool *usage)
{
    // every plan first: a bad --tilts fails before anything moves
    const char *tilts = calib_geometry_tilts_expand(o->tilts);
    char **specs = g_strsplit(tilts, " ", -1);
    GPtrArray *plans = g_ptr_array_new_with_free_func(g_free), *names = g_ptr_array_new_with_free_func(g_free);
    bool ok = true;
    for (int k = 0; specs[k] && ok; k++) {
        if (!*specs[k]) continue;
        char name[128];
        char *plan = calib_geometry_tilt_plan(specs[k], o, name, sizeof name);
        if (!plan) ok = false;
        else {
            g_ptr_array_add(plans, plan);
            g_ptr_array_add(names, g_strdup(name));
        }
    }
    g_strfreev(specs);
    if (ok && plans->len == 0) {
        model_error_set("--tilts", 0, "'%s': no tilts", tilts);
        ok = false;
    }
    *usage = !ok;
    char *capdir = g_strdup_printf("%s/capture", s->outdir);
    g_strfreev(s->sessions);
    s->sessions = g_new0(char *, plans->len + 1);
    for (guint k = 0; k < plans->len && ok; k++) {
        const char *name = g_ptr_array_index(names, k);
        model_note("capturing %s (%u of %u)", name, k + 1, plans->len);
        ok = calib_capture(o->rig, capdir, name, g_ptr_array_index(plans, k), o->progress, o->op) == 0;
        if (ok) s->sessions[k] = g_strdup_printf("%s/%s", capdir, name);
    }
    g_ptr_array_free(plans, TRUE);
    g_ptr_array_free(names, TRUE);
    g_free(capdir);
    return ok;
}
