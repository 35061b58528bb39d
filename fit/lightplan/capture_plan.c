// fit/lightplan/capture_plan.c — the capture plan of `refl plan lamps`
// (lightplan_capture_plan, see lightplan.h): the planned views as a plan file
// refl capture takes as it is, written by the plan format's owner
// (rig_plan_text), read back, and bound to the virtual rig when there is one
// to check against.
#define _GNU_SOURCE
#include <glib.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "fit/lightplan/lightplan.h"
#include "model/base/report.h"
#include "rig/rig.h"

// The comment at the top of the plan: what wrote it, the command, the inputs.
static char *plan_comment(const json_t *prov, const lightplan_lamps_result_t *r, bool several)
{
    GString *c = g_string_new("");
    g_string_append_printf(c, "refl plan lamps: the capture plan of %d view%s, each with the lamp set and exposure "
                           "the planner chose for it", r->nviews, r->nviews == 1 ? "" : "s");
    if (several) g_string_append(c, " (each view's plan and report: view_ANGLE/)");
    g_string_append_printf(c, ".\nrefl %s, %s\ncommand: %s\ninputs (role, path, sha256):",
                           json_string_value(json_object_get(prov, "refl_version")),
                           json_string_value(json_object_get(prov, "date_utc")),
                           json_string_value(json_object_get(prov, "command")));
    json_t *ins = json_object_get(prov, "inputs"), *e;
    size_t i;
    json_array_foreach(ins, i, e)
        g_string_append_printf(c, "\n  %s %s %s", json_string_value(json_object_get(e, "role")),
                               json_string_value(json_object_get(e, "path")),
                               json_string_value(json_object_get(e, "sha256")));
    for (char *s = c->str; *s; s++)
        if (*s == '\r') *s = ' ';
    return g_string_free(c, FALSE);
}

// The plan of the views: every chosen set and exposure once, a view per angle.
static rig_plan_t *views_plan(const lightplan_lamps_opts_t *o, const lightplan_lamps_result_t *r)
{
    const int nv = r->nviews;
    rig_plan_t *p = calloc(1, sizeof *p);
    if (!p) {
        model_error_set(NULL, 0, "out of memory");
        return NULL;
    }
    snprintf(p->name, sizeof p->name, "%s: lamps and exposure per view (refl plan lamps)", o->sample);
    snprintf(p->notes, sizeof p->notes, "each view lit as refl plan lamps chose it; the command and its inputs "
             "with sha256 are in the comments at the top");
    snprintf(p->sample, sizeof p->sample, "%s", o->sample);
    snprintf(p->sample_kind, sizeof p->sample_kind, "workpiece");
    snprintf(p->pixel_format, sizeof p->pixel_format, "%s", o->pixel_format);
    p->angles_deg = calloc((size_t)nv, sizeof *p->angles_deg);
    p->lamp_sets = calloc((size_t)nv, sizeof *p->lamp_sets);
    p->exposures_us = calloc((size_t)nv, sizeof *p->exposures_us);
    p->views = calloc((size_t)nv, sizeof *p->views);
    int *set = calloc((size_t)nv, sizeof *set), *exp = calloc((size_t)nv, sizeof *exp);
    bool ok = p->angles_deg && p->lamp_sets && p->exposures_us && p->views && set && exp;
    if (!ok) model_error_set(NULL, 0, "out of memory");
    for (int k = 0; ok && k < nv; k++) {
        const lightplan_view_t *v = &r->views[k];
        double us = v->res.configs[v->res.best].exposure_us;
        p->angles_deg[p->nangles++] = v->angle_deg;
        for (set[k] = 0; set[k] < p->nlamp_sets && strcmp(p->lamp_sets[set[k]], v->chosen); set[k]++) continue;
        size_t len = strlen(v->chosen);
        if (len >= sizeof p->lamp_sets[0]) {
            model_error_set(NULL, 0, "the lamp set %s is too long for a plan file", v->chosen);
            ok = false;
        } else if (set[k] == p->nlamp_sets) {
            memcpy(p->lamp_sets[p->nlamp_sets++], v->chosen, len + 1);
        }
        for (exp[k] = 0; exp[k] < p->nexposures && p->exposures_us[exp[k]] != us; exp[k]++) continue;
        if (exp[k] == p->nexposures) p->exposures_us[p->nexposures++] = us;
    }
    for (int k = 0; ok && k < nv; k++) {
        rig_plan_view_t *w = &p->views[p->nviews++];
        snprintf(w->name, sizeof w->name, "view %d", k + 1);
        w->angle_index = k;
        w->sets = calloc((size_t)p->nlamp_sets, sizeof *w->sets);
        w->exposures = calloc((size_t)p->nexposures, sizeof *w->exposures);
        ok = w->sets && w->exposures;
        if (ok) w->sets[set[k]] = w->exposures[exp[k]] = true;
        else model_error_set(NULL, 0, "out of memory");
    }
    free(set);
    free(exp);
    p->repeats = 1;
    p->dark_every = nv;   // one dark frame, after the last view
    p->settle_ms = 50;
    p->frame_timeout_s = 10;
    p->retries = 2;
    if (!ok) {
        rig_plan_free(p);
        return NULL;
    }
    return p;
}

// The plan bound to the virtual rig of the truth file (in process, a rig file
// of its own in out, removed after).
static bool bind_virtual(const lightplan_lamps_opts_t *o, rig_plan_t *p)
{
    char *truth = g_canonicalize_filename(o->check_truth, NULL);
    char *rp = g_strdup_printf("%s/.capture_plan_rig.ini", o->out);
    char *rt = g_strdup_printf("# refl plan lamps: the virtual rig the capture plan is checked on\n[rig]\n"
                               "backend = virtual\ntruth = %s\nserve = inprocess\ntime_scale = 0.01\n", truth);
    bool ok = model_write_file_atomic(rp, rt);
    rig_t *rig = NULL;
    if (ok && rig_open(&rig, rp) != 0) {
        model_error_set(o->check_truth, 0, "the virtual rig of this truth file does not open: %s", model_last_error());
        ok = false;
    }
    if (ok && rig_plan_bind(p, rig) != 0) {
        char *msg = g_strdup(model_last_error());
        model_error_set(p->path, 0, "the capture plan does not bind to the virtual rig of %s: %s", o->check_truth,
                        msg);
        g_free(msg);
        ok = false;
    }
    rig_close(rig);
    unlink(rp);
    g_free(rt);
    g_free(rp);
    g_free(truth);
    return ok;
}

bool lightplan_capture_plan(const lightplan_lamps_opts_t *o, const json_t *prov, lightplan_lamps_result_t *r)
{
    rig_plan_t *p = views_plan(o, r), *back = NULL;
    if (!p) return false;
    char *comment = plan_comment(prov, r, o->nangles > 0);
    char *text = rig_plan_text(p, comment), *path = g_strdup_printf("%s/capture_plan.ini", o->out);
    bool ok = text != NULL;
    if (ok && !(back = rig_plan_parse(text, strlen(text), path))) {
        char *msg = g_strdup(model_last_error());
        model_error_set(path, 0, "the capture plan does not read back (%s)", msg);
        g_free(msg);
        ok = false;
    }
    if (ok && back->nsteps != r->nviews + 1 + back->nops) {   // and the operator's steps ([sample])
        model_error_set(path, 0, "the capture plan reads back as %d steps, not the %d views, a dark frame and %d "
                        "operator step(s)", back->nsteps, r->nviews, back->nops);
        ok = false;
    }
    ok = ok && model_write_file_atomic(path, text);
    if (ok) r->capture_plan = g_strdup(path);
    if (ok && o->check_truth) ok = r->plan_bound = bind_virtual(o, back);
    rig_plan_free(back);
    rig_plan_free(p);
    free(text);
    g_free(comment);
    g_free(path);
    return ok;
}
