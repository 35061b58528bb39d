// calib/lamps/capture.c — stage 1 of the calibration (calib_lamps_open): the
// capture plan and the capture on a rig, or a session captured elsewhere; the
// lamps to calibrate, and per angle and lamp the frame to use and the dark frame.
#define _GNU_SOURCE
#include <errno.h>
#include <glib.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "calib/lamps/internal.h"
#include "model/base/report.h"

double lamps_full_scale(const char *pf)
{
    if (!strcmp(pf, "Mono8")) return 255;
    if (!strcmp(pf, "Mono16")) return 65535;
    return 4095;
}

char *calib_lamps_plan_text(const char *sample, const double *centre_mm, double radius_mm, const double *angles_deg,
                            int nangles, char *const *lamps,
                            int nlamps, const double *exposures_us, int nexposures)
{
    GString *pt = g_string_new("# refl calib lamps: the mirror sphere at several turntable angles, each lamp "
                               "alone, a dark frame per angle\n[plan]\nname = lamp positions from mirror-sphere "
                               "highlights\n");
    g_string_append_printf(pt, "[sample]\nname = %s\nkind = mirror_sphere\n", sample);
    if (centre_mm)
        g_string_append_printf(pt, "instruction = place the chrome ball %s at the table centre: its centre at "
                               "(%.10g, %.10g, %.10g) mm in the rig frame at turntable angle 0, radius %.10g mm\n",
                               sample, centre_mm[0], centre_mm[1], centre_mm[2], radius_mm);
    g_string_append(pt, "[angles]\nlist =");
    for (int i = 0; i < nangles; i++) g_string_append_printf(pt, " %.10g", angles_deg[i]);
    g_string_append(pt, "\n[lamps]\nsets = ");
    for (int i = 0; i < nlamps; i++) g_string_append_printf(pt, "%s; ", lamps[i]);
    g_string_append(pt, "none\n[exposure]\n# auto bracketing: longest first, down to the first frame whose "
                        "brightest pixel is at or below 70 % of full scale\nmode = auto\nlist_us =");
    for (int i = 0; i < nexposures; i++) g_string_append_printf(pt, " %.10g", exposures_us[i]);
    g_string_append(pt, "\ntarget_fraction = 0.7\npixel_format = Mono12\n[capture]\nsettle_ms = 0\n");
    return g_string_free(pt, FALSE);
}

// "none" and "all" are lamp sets, not lamps.
static bool names_are_lamps(char *const *names)
{
    for (int l = 0; names[l]; l++)
        if (!strcmp(names[l], "none") || !strcmp(names[l], "all")) {
            model_error_set(NULL, 0, "--lamps: '%s' is not a lamp (each lamp is calibrated alone; the dark frames "
                            "are the lamp set none)", names[l]);
            return false;
        }
    return true;
}

// Capture on o->rig into o->out/capture; *names: the lamps (g_strfreev).
static bool capture(const calib_lamps_opts_t *o, calib_lamps_result_t *r, char ***names)
{
    int n = 0;
    if (o->lamps) {
        *names = g_strdupv((char **)o->lamps);
        n = (int)g_strv_length(*names);
    } else if (!rig_file_lamp_names(o->rig, names, &n)) {
        return false;
    }
    if (n == 0) {
        model_error_set(NULL, 0, "%s has no lamps (and no --lamps given)", o->rig);
        return false;
    }
    if (!names_are_lamps(*names)) return false;
    if (!o->sphere_given) {
        model_error_set(NULL, 0, "%s: give --sphere-centre-mm X,Y,Z and --sphere-radius-mm R (the sphere's facts) "
                        "before anything is captured", o->rig);
        return false;
    }
    char *pt = calib_lamps_plan_text(o->sample, o->sphere_centre_mm, o->sphere_radius_mm, o->angles_deg, o->nangles, *names, n, o->exposures_us,
                                     o->nexposures);
    model_note("capturing %d angles x %d lamps + dark into %s/capture", o->nangles, n, o->out);
    int crc = calib_capture(o->rig, o->out, "capture", pt, o->progress, o->op);
    g_free(pt);
    if (crc) return false;
    r->session_dir = g_strdup_printf("%s/capture", o->out);
    return true;
}

// The lamps of a session: o->lamps, else every lamp set of the plan that is
// one lamp alone. g_strfreev.
static char **session_lamps(const calib_lamps_opts_t *o, const rig_plan_t *plan)
{
    if (o->lamps) return g_strdupv((char **)o->lamps);
    GPtrArray *a = g_ptr_array_new();
    for (int i = 0; i < plan->nlamp_sets; i++)
        if (strcmp(plan->lamp_sets[i], "none") && strcmp(plan->lamp_sets[i], "all") &&
            !strchr(plan->lamp_sets[i], '+'))
            g_ptr_array_add(a, g_strdup(plan->lamp_sets[i]));
    g_ptr_array_add(a, NULL);
    return (char **)g_ptr_array_free(a, FALSE);
}

// r->lamps for names, each a lamp set of the plan.
static bool lamps_alloc(const calib_lamps_opts_t *o, calib_lamps_result_t *r, char *const *names)
{
    const int NA = r->nangles;
    r->nlamps = (int)g_strv_length((char **)names);
    r->lamps = calloc((size_t)r->nlamps, sizeof *r->lamps);
    if (!r->lamps) goto oom;
    for (int l = 0; l < r->nlamps; l++) {
        calib_lamps_lamp_t *lp = &r->lamps[l];
        snprintf(lp->name, sizeof lp->name, "%s", names[l]);
        lp->lamp_radius_mm = o->lamp_radius_mm;
        lp->frame = malloc(sizeof(int) * (size_t)NA);
        lp->hl = calloc((size_t)NA, sizeof *lp->hl);
        lp->has_ray = calloc((size_t)NA, sizeof(bool));
        lp->used = calloc((size_t)NA, sizeof(bool));
        lp->p_mm = calloc((size_t)NA, sizeof(model_vec3_t));
        lp->d = calloc((size_t)NA, sizeof(model_vec3_t));
        lp->dist_mm = calloc((size_t)NA, sizeof(double));
        if (!lp->frame || !lp->hl || !lp->has_ray || !lp->used || !lp->p_mm || !lp->d || !lp->dist_mm) goto oom;
        for (int a = 0; a < NA; a++) lp->frame[a] = -1;
        bool in_plan = false;
        for (int i = 0; i < r->plan->nlamp_sets; i++) in_plan |= !strcmp(r->plan->lamp_sets[i], lp->name);
        if (!in_plan) {
            GString *g = g_string_new("");
            for (int i = 0; i < r->plan->nlamp_sets; i++)
                g_string_append_printf(g, "%s%s", i ? "; " : "", r->plan->lamp_sets[i]);
            model_error_set(NULL, 0, "%s: the session's plan has no lamp set '%s' alone (sets: %s)", r->session_dir,
                            lp->name, g->str);
            g_string_free(g, TRUE);
            return false;
        }
    }
    return true;
oom:
    model_error_set(NULL, 0, "out of memory");
    return false;
}

// Per (angle, lamp set) the longest exposure below 95 % of full scale (auto
// bracketing leaves the longest unsaturated one last); per angle the dark
// frame and the measured angle.
static bool choose_frames(calib_lamps_result_t *r)
{
    const int NA = r->nangles;
    const rig_session_t *s = r->session;
    r->angle_deg = malloc(sizeof(double) * (size_t)NA);
    r->dark_row = malloc(sizeof(int) * (size_t)NA);
    r->centre_mm = calloc((size_t)NA, sizeof *r->centre_mm);
    if (!r->angle_deg || !r->dark_row || !r->centre_mm) {
        model_error_set(NULL, 0, "out of memory");
        return false;
    }
    for (int a = 0; a < NA; a++) {
        r->dark_row[a] = -1;
        r->angle_deg[a] = NAN;
    }
    for (int i = 0; i < s->n; i++) {
        const rig_frame_row_t *row = &s->rows[i];
        int a = -1;
        for (int k = 0; k < NA; k++)
            if (fabs(r->plan->angles_deg[k] - row->commanded_deg) < 1e-6) a = k;
        if (a < 0) continue;
        r->angle_deg[a] = row->measured_deg;
        double fs = lamps_full_scale(row->pixel_format);
        if (!strcmp(row->lamps, "none")) {
            if (r->dark_row[a] < 0) r->dark_row[a] = i;
            continue;
        }
        for (int l = 0; l < r->nlamps; l++) {
            calib_lamps_lamp_t *lp = &r->lamps[l];
            if (strcmp(row->lamps, lp->name)) continue;
            int cur = lp->frame[a];
            if (cur < 0) {
                lp->frame[a] = i;
                continue;
            }
            const rig_frame_row_t *c = &s->rows[cur];
            bool c_ok = c->max < 0.95 * fs, r_ok = row->max < 0.95 * fs;
            if ((r_ok && !c_ok) || (r_ok == c_ok && (r_ok ? row->exposure_us > c->exposure_us
                                                           : row->exposure_us < c->exposure_us)))
                lp->frame[a] = i;
        }
    }
    for (int a = 0; a < NA; a++)
        if (!isfinite(r->angle_deg[a])) r->angle_deg[a] = r->plan->angles_deg[a];
    return true;
}

bool calib_lamps_open(const calib_lamps_opts_t *o, calib_lamps_result_t *r)
{
    model_error_clear();
    r->first_angle = -1;
    if (access(o->camera, R_OK) != 0) {
        model_error_set(NULL, 0, "%s: cannot read the camera model: %s (make it with refl calib geometry)", o->camera,
                        strerror(errno));
        return false;
    }
    r->cam = model_camera_load(o->camera);
    if (!r->cam || !model_mkdir_p(o->out)) return false;
    char **names = NULL;
    bool ok = false;
    if (o->rig) {
        if (!capture(o, r, &names)) goto done;
    } else {
        r->session_dir = g_strdup(o->session);
    }
    r->session = rig_session_open_camera(r->session_dir, NULL);   // the first camera's frames
    if (!r->session) goto done;
    r->plan = rig_plan_parse(r->session->plan_text, strlen(r->session->plan_text), "session plan");
    if (!r->plan) goto done;
    r->nangles = r->plan->nangles;
    if (!o->sphere_given) {
        model_error_set(NULL, 0, "%s: give --sphere-centre-mm X,Y,Z and --sphere-radius-mm R (the sphere's facts)",
                        r->session_dir);
        goto done;
    }
    if (!names) names = session_lamps(o, r->plan);
    if (!names_are_lamps(names)) goto done;
    if (!names[0]) {
        model_error_set(NULL, 0, "%s: the plan has no lamp set of one lamp alone", r->session_dir);
        goto done;
    }
    ok = lamps_alloc(o, r, names) && choose_frames(r);
done:
    g_strfreev(names);
    return ok;
}
