// rig/session/plan_views.c — the [view NAME] sections of a capture plan (see
// rig/session/session.h): per turntable angle, the lamp sets and exposures taken
// there, so a plan can light each view its own way (refl plan lamps).
// Allocations through GLib (g_malloc0_n): freed with free().
#define _GNU_SOURCE
#include <glib.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "rig/session/plan_views.h"

static const char *const view_keys = "angle_deg sets list_us";

bool rig_plan_view_section(const char *section)
{
    return !strncmp(section, "view ", 5) && section[5];
}

static bool check_view_keys(const model_ini_t *ini, int s)
{
    for (int i = 0; i < ini->section_count[s]; i++) {
        const model_ini_entry_t *e = &ini->entries[ini->section_first[s] + i];
        gchar **w = g_strsplit(view_keys, " ", -1);
        bool ok = false;
        for (int j = 0; w[j]; j++) ok |= !strcmp(w[j], e->key);
        g_strfreev(w);
        if (!ok) {
            model_error(ini->path, e->line, "[%s]: unknown key '%s' (keys: %s)", e->section, e->key, view_keys);
            return false;
        }
    }
    return true;
}

// The view's angle: one of [angles], not taken by an earlier view.
static bool view_angle(rig_plan_t *p, const model_ini_t *ini, const char *sec, rig_plan_view_t *v)
{
    double a = NAN;
    if (!model_ini_double_in(ini, sec, "angle_deg", &a, true, -1e4, false, 1e4, NULL)) return false;
    const model_ini_entry_t *e = model_ini_get(ini, sec, "angle_deg");
    v->angle_index = -1;
    for (int i = 0; i < p->nangles && v->angle_index < 0; i++)
        if (p->angles_deg[i] == a) v->angle_index = i;
    if (v->angle_index < 0) {
        model_error(ini->path, e->line, "[%s] angle_deg = %s is not one of [angles]", sec, e->value);
        return false;
    }
    for (int k = 0; &p->views[k] != v; k++)
        if (p->views[k].angle_index == v->angle_index) {
            model_error(ini->path, e->line, "[%s] angle_deg = %s: [%s] (line %d) already has this angle", sec,
                        e->value, p->views[k].name, p->views[k].line);
            return false;
        }
    return true;
}

// sets = SET; SET ...: each one of [lamps] sets (blanks around '+' ignored).
static bool view_sets(rig_plan_t *p, const model_ini_t *ini, const char *sec, rig_plan_view_t *v)
{
    const model_ini_entry_t *e = model_ini_get(ini, sec, "sets");
    for (int i = 0; i < p->nlamp_sets; i++) v->sets[i] = !e;
    if (!e) return true;
    gchar **w = g_strsplit(e->value, ";", -1);
    bool ok = true, any = false;
    for (int i = 0; w[i] && ok; i++) {
        gchar **names = g_strsplit(w[i], "+", -1);
        GString *norm = g_string_new("");
        for (int k = 0; names[k]; k++) g_string_append_printf(norm, "%s%s", k ? "+" : "", g_strstrip(names[k]));
        int found = -1;
        for (int l = 0; l < p->nlamp_sets && found < 0; l++)
            if (!strcmp(p->lamp_sets[l], norm->str)) found = l;
        if (found < 0 && norm->len) {
            model_error(ini->path, e->line, "[%s] sets: '%s' is not one of [lamps] sets (line %d)", sec, norm->str,
                        p->lamp_sets_line);
            ok = false;
        } else if (found >= 0) {
            v->sets[found] = any = true;
        }
        g_string_free(norm, TRUE);
        g_strfreev(names);
    }
    g_strfreev(w);
    if (ok && !any) {
        model_error(ini->path, e->line, "[%s] sets is empty: name at least one of [lamps] sets", sec);
        ok = false;
    }
    return ok;
}

// list_us = US US ...: each one of [exposure] list_us.
static bool view_exposures(rig_plan_t *p, const model_ini_t *ini, const char *sec, rig_plan_view_t *v)
{
    const model_ini_entry_t *e = model_ini_get(ini, sec, "list_us");
    for (int i = 0; i < p->nexposures; i++) v->exposures[i] = !e;
    if (!e) return true;
    gchar **w = g_strsplit_set(e->value, " \t,", -1);
    bool ok = true, any = false;
    for (int i = 0; w[i] && ok; i++) {
        if (!w[i][0]) continue;
        double us;
        int found = -1;
        if (!model_parse_double(w[i], &us)) {
            model_error(ini->path, e->line, "[%s] list_us: '%s' is not a number", sec, w[i]);
            ok = false;
            break;
        }
        for (int k = 0; k < p->nexposures && found < 0; k++)
            if (p->exposures_us[k] == us) found = k;
        if (found < 0) {
            model_error(ini->path, e->line, "[%s] list_us: %s us is not one of [exposure] list_us (line %d)", sec,
                        w[i], p->exposure_line);
            ok = false;
        } else {
            v->exposures[found] = any = true;
        }
    }
    g_strfreev(w);
    if (ok && !any) {
        model_error(ini->path, e->line, "[%s] list_us is empty: name at least one of [exposure] list_us", sec);
        ok = false;
    }
    return ok;
}

bool rig_plan_views_parse(rig_plan_t *p, const model_ini_t *ini)
{
    int n = 0;
    for (int s = 0; s < ini->nsections; s++) n += rig_plan_view_section(ini->sections[s]);
    if (!n) return true;
    p->views = g_malloc0_n((size_t)n, sizeof *p->views);
    for (int s = 0; s < ini->nsections; s++) {
        const char *sec = ini->sections[s];
        if (!rig_plan_view_section(sec)) continue;
        rig_plan_view_t *v = &p->views[p->nviews];
        snprintf(v->name, sizeof v->name, "%s", sec);
        v->line = ini->section_lines[s];
        v->sets = g_malloc0_n((size_t)p->nlamp_sets + 1, sizeof *v->sets);
        v->exposures = g_malloc0_n((size_t)p->nexposures + 1, sizeof *v->exposures);
        p->nviews++;
        if (strlen(sec) >= sizeof v->name) {
            model_error(ini->path, v->line, "[%s]: the view's name is too long (at most %zu characters)", sec,
                        sizeof v->name - 6);
            return false;
        }
        if (!check_view_keys(ini, s) || !view_angle(p, ini, sec, v) || !view_sets(p, ini, sec, v) ||
            !view_exposures(p, ini, sec, v))
            return false;
    }
    return true;
}

bool rig_plan_view_takes(const rig_plan_t *p, int a, int l, int e)
{
    for (int k = 0; k < p->nviews; k++)
        if (p->views[k].angle_index == a) return p->views[k].sets[l] && p->views[k].exposures[e];
    return true;
}

void rig_plan_views_free(rig_plan_t *p)
{
    for (int k = 0; k < p->nviews; k++) {
        free(p->views[k].sets);
        free(p->views[k].exposures);
    }
    free(p->views);
    p->views = NULL;
    p->nviews = 0;
}
