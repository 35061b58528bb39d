// rig/virtual/truth_figures.c — the figures of the truth file that other layers
// compare measurements with (rig/virtual/truth.h): samples and their scenes,
// cameras, sensor, lamps, materials, textures, the turntable's axis.
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "rig/virtual/internal.h"

// The number a key's text starts with; NAN when the key is absent or starts with none.
static double stated(const rig_truth_t *t, const char *sec, const char *key)
{
    const char *s = model_ini_text(rig_truth_ini(t), sec, key, NULL);
    char *end;
    double v = s ? strtod(s, &end) : NAN;
    return s && end != s ? v : NAN;
}

// "camera" or "camera NAME".
static void camera_section(const char *camera, char sec[96])
{
    if (camera) snprintf(sec, 96, "camera %s", camera);
    else snprintf(sec, 96, "camera");
}

const char *rig_truth_sample_name(const rig_truth_t *t, int i)
{
    const model_ini_t *ini = rig_truth_ini(t);
    for (int s = 0; s < ini->nsections && i >= 0; s++)
        if (!strncmp(ini->sections[s], "sample ", 7) && i-- == 0) return ini->sections[s] + 7;
    return NULL;
}

char *rig_truth_sample_scene_path(const rig_truth_t *t, const char *sample)
{
    char sec[160];
    snprintf(sec, sizeof sec, "sample %s", sample);
    const char *scene = model_ini_text(rig_truth_ini(t), sec, "scene", NULL);
    return scene ? rig_truth_resolve(t, scene) : NULL;
}

bool rig_truth_sample_scene(const rig_truth_t *t, const char *sample, char **scene_path, char *material,
                            size_t material_size)
{
    char sec[160];
    snprintf(sec, sizeof sec, "sample %s", sample);
    if (!model_ini_get(rig_truth_ini(t), sec, "scene")) {
        model_error(rig_truth_path(t), 0, "no [sample %s] with scene (the sample's scene)", sample);
        return false;
    }
    if (!(*scene_path = rig_truth_sample_scene_path(t, sample))) {
        model_error(rig_truth_path(t), 0, "out of memory");
        return false;
    }
    const char *m = model_ini_text(rig_truth_ini(t), sec, "material", "");
    if (material && material_size) snprintf(material, material_size, "%s", m);
    return true;
}

bool rig_truth_sphere(const rig_truth_t *t, const char *sample, double centre_mm[3], double *radius_mm)
{
    char sec[160];
    snprintf(sec, sizeof sec, "sample %s", sample);
    return rig_vtruth_sphere_facts(rig_truth_ini(t), sec, sample, centre_mm, radius_mm);
}

bool rig_truth_axis(const rig_truth_t *t, double dir[3])
{
    double tilt = 0, az = 0;
    const char *keys[2] = { "axis_tilt_deg", "axis_tilt_azimuth_deg" };
    double *vals[2] = { &tilt, &az };
    for (int k = 0; k < 2; k++) {
        const model_ini_entry_t *e = model_ini_get(rig_truth_ini(t), "turntable", keys[k]);
        if (e && !model_parse_double(e->value, vals[k])) {
            model_error(rig_truth_path(t), e->line, "%s = '%s' is not a number", keys[k], e->value);
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
    const model_ini_entry_t *k = model_ini_get(rig_truth_ini(t), sec, "kind");
    if (!k || strcmp(k->value, "uniform_source")) {
        model_error(rig_truth_path(t), k ? k->line : 0, "[sample %s] is not a uniform_source", sample);
        return false;
    }
    const model_ini_entry_t *e = model_ini_get(rig_truth_ini(t), sec, "radiance");
    if (!e) {
        model_error(rig_truth_path(t), 0, "no [sample %s] with radiance (a uniform source's radiance)", sample);
        return false;
    }
    if (!model_parse_double(e->value, radiance) || !(*radiance > 0)) {
        model_error(rig_truth_path(t), e->line, "radiance = '%s' is not a positive number", e->value);
        return false;
    }
    return true;
}

bool rig_truth_has_camera(const rig_truth_t *t, const char *camera)
{
    char sec[96];
    camera_section(camera, sec);
    return model_ini_section_line(rig_truth_ini(t), sec) > 0;
}

char *rig_truth_camera_model_path(const rig_truth_t *t, const char *camera)
{
    char sec[96];
    camera_section(camera, sec);
    const char *m = model_ini_text(rig_truth_ini(t), sec, "model", NULL);
    return m ? rig_truth_resolve(t, m) : NULL;
}

double rig_truth_kc_per_us(const rig_truth_t *t, const char *camera)
{
    char sec[96];
    camera_section(camera, sec);
    return stated(t, sec, "kc_per_us");
}

double rig_truth_sensor_value(const rig_truth_t *t, const char *key) { return stated(t, "sensor", key); }

bool rig_truth_sensor(const rig_truth_t *t, const char *camera, model_sensor_t *out)
{
    if (!model_sensor_from_ini(rig_truth_ini(t), out)) return false;
    if (!camera) return true;
    char sec[96];
    snprintf(sec, sizeof sec, "sensor %s", camera);
    return model_sensor_update_from_ini(rig_truth_ini(t), sec, out);
}

bool rig_truth_lamp_position(const rig_truth_t *t, const char *lamp, double position_mm[3])
{
    char sec[96];
    snprintf(sec, sizeof sec, "lamp %s", lamp);
    const char *s = model_ini_text(rig_truth_ini(t), sec, "position_mm", NULL);
    return s && sscanf(s, "%lf %lf %lf", &position_mm[0], &position_mm[1], &position_mm[2]) == 3;
}

double rig_truth_lamp_intensity(const rig_truth_t *t, const char *lamp)
{
    char sec[96];
    snprintf(sec, sizeof sec, "lamp %s", lamp);
    return stated(t, sec, "intensity");
}

const char *rig_truth_material_model(const rig_truth_t *t, const char *material)
{
    char sec[96];
    snprintf(sec, sizeof sec, "material %s", material);
    return model_ini_text(rig_truth_ini(t), sec, "model", NULL);
}

double rig_truth_material_param(const rig_truth_t *t, const char *material, const char *param)
{
    char sec[96];
    snprintf(sec, sizeof sec, "material %s", material);
    return stated(t, sec, param);
}

double rig_truth_roughness_amplitude(const rig_truth_t *t, const char *material)
{
    char sec[96];
    snprintf(sec, sizeof sec, "texture %s", material);
    return stated(t, sec, "roughness_amplitude");
}

int rig_truth_texture_line(const rig_truth_t *t, const char *material)
{
    char sec[96];
    snprintf(sec, sizeof sec, "texture %s", material);
    int line = model_ini_section_line(rig_truth_ini(t), sec);
    return line > 0 ? line : 0;
}
