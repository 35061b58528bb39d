// rig/virtual/truth.c — the virtual rig's truth file, read in one place (rig/virtual/truth.h).
#include <math.h>
#include <glib.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "model/model.h"
#include "rig/virtual/truth.h"

struct rig_truth {
    char        *path;
    model_ini_t *ini;
};

rig_truth_t *rig_truth_load(const char *path)
{
    model_ini_t *ini = model_ini_load(path);
    if (!ini) return NULL;
    rig_truth_t *t = calloc(1, sizeof *t);
    if (!t || !(t->path = g_strdup(path))) {
        free(t);
        model_ini_free(ini);
        model_error(path, 0, "out of memory");
        return NULL;
    }
    t->ini = ini;
    return t;
}

void rig_truth_free(rig_truth_t *t)
{
    if (!t) return;
    model_ini_free(t->ini);
    g_free(t->path);
    free(t);
}

const char *rig_truth_path(const rig_truth_t *t) { return t->path; }
const model_ini_t *rig_truth_ini(const rig_truth_t *t) { return t->ini; }

model_lamps_t *rig_truth_lamps(const rig_truth_t *t) { return model_lamps_from_ini(t->ini); }
model_materials_t *rig_truth_materials(const rig_truth_t *t) { return model_materials_from_ini(t->ini); }

// The entry key of [sample NAME]; NULL with a message when absent.
static const model_ini_entry_t *sample_key(const rig_truth_t *t, const char *sample, const char *key,
                                           const char *what)
{
    char sec[160];
    snprintf(sec, sizeof sec, "sample %s", sample);
    const model_ini_entry_t *e = model_ini_get(t->ini, sec, key);
    if (!e) model_error(t->path, 0, "no [sample %s] with %s (%s)", sample, key, what);
    return e;
}

bool rig_truth_sample_scene(const rig_truth_t *t, const char *sample, char **scene_path, char *material,
                            size_t material_size)
{
    const model_ini_entry_t *e = sample_key(t, sample, "scene", "the sample's scene");
    if (!e) return false;
    char *d = g_path_get_dirname(t->path);
    *scene_path = g_build_filename(d, e->value, NULL);
    g_free(d);
    char sec[160];
    snprintf(sec, sizeof sec, "sample %s", sample);
    const model_ini_entry_t *m = model_ini_get(t->ini, sec, "material");
    if (material && material_size) snprintf(material, material_size, "%s", m ? m->value : "");
    return true;
}

bool rig_truth_sphere(const rig_truth_t *t, const char *sample, double centre_mm[3], double *radius_mm)
{
    const model_ini_entry_t *ec = sample_key(t, sample, "sphere_centre_mm", "a mirror sphere's centre");
    if (!ec) return false;
    const model_ini_entry_t *er = sample_key(t, sample, "sphere_radius_mm", "a mirror sphere's radius");
    if (!er) return false;
    char extra;
    if (sscanf(ec->value, "%lf %lf %lf %c", &centre_mm[0], &centre_mm[1], &centre_mm[2], &extra) != 3) {
        model_error(t->path, ec->line, "sphere_centre_mm = '%s' is not three numbers", ec->value);
        return false;
    }
    if (!model_parse_double(er->value, radius_mm)) {
        model_error(t->path, er->line, "sphere_radius_mm = '%s' is not a number", er->value);
        return false;
    }
    return true;
}

bool rig_truth_axis(const rig_truth_t *t, double dir[3])
{
    double tilt = 0, az = 0;
    const char *keys[2] = { "axis_tilt_deg", "axis_tilt_azimuth_deg" };
    double *vals[2] = { &tilt, &az };
    for (int k = 0; k < 2; k++) {
        const model_ini_entry_t *e = model_ini_get(t->ini, "turntable", keys[k]);
        if (e && !model_parse_double(e->value, vals[k])) {
            model_error(t->path, e->line, "%s = '%s' is not a number", keys[k], e->value);
            return false;
        }
    }
    double th = tilt * M_PI / 180, ph = az * M_PI / 180;
    dir[0] = sin(th) * cos(ph);
    dir[1] = sin(th) * sin(ph);
    dir[2] = cos(th);
    return true;
}

bool rig_truth_uniform_radiance(const rig_truth_t *t, const char *sample, double *radiance)
{
    char sec[160];
    snprintf(sec, sizeof sec, "sample %s", sample);
    const model_ini_entry_t *k = model_ini_get(t->ini, sec, "kind");
    if (!k || strcmp(k->value, "uniform_source")) {
        model_error(t->path, k ? k->line : 0, "[sample %s] is not a uniform_source", sample);
        return false;
    }
    const model_ini_entry_t *e = sample_key(t, sample, "radiance", "a uniform source's radiance");
    if (!e) return false;
    if (!model_parse_double(e->value, radiance) || !(*radiance > 0)) {
        model_error(t->path, e->line, "radiance = '%s' is not a positive number", e->value);
        return false;
    }
    return true;
}
