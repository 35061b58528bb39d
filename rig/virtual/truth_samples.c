// rig/virtual/truth_samples.c — the truth file's [texture MATERIAL] and [sample NAME]
// sections read into the virtual rig's textures and samples (scenes loaded,
// materials resolved, facts checked against the scenes); finding, listing and
// freeing samples.
#include <limits.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "rig/virtual/internal.h"

int rig_vsample_find(const sample_t *samples, int n, const char *name)
{
    for (int i = 0; i < n; i++)
        if (!samples[i].variant && !strcmp(samples[i].name, name)) return i;
    return -1;
}

void rig_vsample_list(const sample_t *samples, int n, char *buf, size_t size)
{
    size_t len = 0;
    buf[0] = 0;
    for (int i = 0; i < n && len < size; i++)
        if (!samples[i].variant) len += snprintf(buf + len, size - len, "%s%s", i ? ", " : "", samples[i].name);
}

void rig_vsamples_free(sample_t *samples, int n)
{
    for (int i = 0; samples && i < n; i++) {
        free(samples[i].scene_path);
        model_scene_free(samples[i].scene);
        if (samples[i].variant) continue;
        free(samples[i].mats);
        free(samples[i].tex);
        free(samples[i].mats_rough);
        free(samples[i].mats_smooth);
        free(samples[i].rough_store);
    }
    free(samples);
}

static bool out_of_memory(const model_ini_t *ini)
{
    model_error(ini->path, 0, "out of memory");
    return false;
}

// A sample's rough and smooth material variants (rig/virtual/materials.c).
static bool sample_roughness(const model_ini_t *ini, sample_t *sm)
{
    int n = sm->scene->nmaterials;
    double *amp = calloc(n ? n : 1, sizeof *amp);
    sm->mats_rough = calloc(n ? n : 1, sizeof *sm->mats_rough);
    sm->mats_smooth = calloc(n ? n : 1, sizeof *sm->mats_smooth);
    if (!amp || !sm->mats_rough || !sm->mats_smooth) {
        free(amp);
        return out_of_memory(ini);
    }
    int line = sm->line;
    for (int k = 0; k < n; k++)
        if (sm->tex[k] && sm->tex[k]->roughness_amplitude > 0) {
            amp[k] = sm->tex[k]->roughness_amplitude;
            char sec[96];
            snprintf(sec, sizeof sec, "texture %s", sm->tex[k]->material);
            line = rig_vtruth_line(ini, sec, "roughness_amplitude");
        }
    bool ok = rig_vmat_variants(n, sm->mats, amp, ini->path, line, &sm->rough_store, sm->mats_rough, sm->mats_smooth);
    free(amp);
    return ok;
}

bool rig_vtruth_textures(const rig_truth_t *t, rig_vtruth_t *c)
{
    const model_ini_t *ini = rig_truth_ini(t);
    int n = 0;
    for (int s = 0; s < ini->nsections; s++)
        if (!strncmp(ini->sections[s], "texture ", 8)) n++;
    if (n == 0) return true;
    if (!(c->textures = calloc(n, sizeof *c->textures))) return out_of_memory(ini);
    for (int s = 0; s < ini->nsections; s++) {
        const char *sec = ini->sections[s];
        if (strncmp(sec, "texture ", 8)) continue;
        texture_t *tx = &c->textures[c->ntextures++];
        const char *mat = sec + 8;
        if (!model_materials_find(c->mats, mat)) {
            model_error(ini->path, ini->section_lines[s], "[texture %s]: there is no [material %s]; a texture "
                        "section is named after the material it textures", mat, mat);
            return false;
        }
        snprintf(tx->material, sizeof tx->material, "%s", mat);
        tx->amplitude = NAN;
        tx->scale_mm = NAN;
        if (!rig_vtruth_double(ini, sec, "amplitude", 0, 0.5, true, &tx->amplitude) ||
            !rig_vtruth_double(ini, sec, "scale_mm", 1e-3, 1e6, true, &tx->scale_mm))
            return false;
        long seed = 1;
        if (!rig_vtruth_int(ini, sec, "seed", 0, LONG_MAX, &seed)) return false;
        tx->seed = (uint64_t)seed;
        if (!rig_vtruth_double(ini, sec, "roughness_amplitude", 0, 0.9, false, &tx->roughness_amplitude)) return false;
    }
    return true;
}

static const char *sample_kinds[] = { "workpiece", "chessboard", "reference_white", "material_coupon",
                                      "mirror_sphere", "uniform_source" };

bool rig_vtruth_sphere_facts(const model_ini_t *ini, const char *sec, const char *name, double centre_mm[3],
                             double *radius_mm)
{
    if (!rig_vtruth_double(ini, sec, "sphere_radius_mm", 1e-3, 1e4, true, radius_mm)) return false;
    const char *cs = rig_vtruth_str(ini, sec, "sphere_centre_mm", NULL);
    double *c = centre_mm;
    char extra;
    if (!cs || sscanf(cs, "%lf %lf %lf %c", &c[0], &c[1], &c[2], &extra) != 3 || !isfinite(c[0]) ||
        !isfinite(c[1]) || !isfinite(c[2])) {
        model_error(ini->path, rig_vtruth_line(ini, sec, "sphere_centre_mm"), "sample '%s': sphere_centre_mm = '%s': "
                    "give the sphere's centre at angle 0 as three numbers x y z (mm, rig frame)", name, cs ? cs : "");
        return false;
    }
    return true;
}

// A mirror sphere's facts (sphere_centre_mm, sphere_radius_mm): required for
// that kind, refused for the others, and one of the scene's spheres must have
// them (to 1e-6 mm).
static bool check_sphere_facts(const model_ini_t *ini, const char *sec, const sample_t *sm)
{
    bool mirror = !strcmp(sm->kind, "mirror_sphere");
    static const char *keys[] = { "sphere_centre_mm", "sphere_radius_mm" };
    for (int k = 0; k < 2; k++)
        if (!mirror && model_ini_get(ini, sec, keys[k])) {
            model_error(ini->path, rig_vtruth_line(ini, sec, keys[k]), "sample '%s': %s is a key of mirror spheres, "
                        "not of kind %s", sm->name, keys[k], sm->kind);
            return false;
        }
    if (!mirror) return true;
    double r, c[3];
    if (!rig_vtruth_sphere_facts(ini, sec, sm->name, c, &r)) return false;
    for (int k = 0; k < sm->scene->nspheres; k++) {
        const model_sphere_t *sp = &sm->scene->spheres[k];
        if (fabs(sp->centre_mm.x - c[0]) <= 1e-6 && fabs(sp->centre_mm.y - c[1]) <= 1e-6 &&
            fabs(sp->centre_mm.z - c[2]) <= 1e-6 && fabs(sp->radius_mm - r) <= 1e-6)
            return true;
    }
    model_error(ini->path, rig_vtruth_line(ini, sec, "sphere_centre_mm"), "sample '%s': its scene %s has no sphere of "
                "centre (%g, %g, %g) mm and radius %g mm (it has %d '@sphere' line%s); make the facts and the "
                "scene agree", sm->name, sm->scene_path, c[0], c[1], c[2], r, sm->scene->nspheres,
                sm->scene->nspheres == 1 ? "" : "s");
    return false;
}

// A uniform_source: a flat-field source filling the view (an integrating
// sphere's port in front of the lens), fed by the rig's lamps: no scene.
static bool read_uniform(const model_ini_t *ini, const char *sec, sample_t *sm, const char *kind, bool has_scene)
{
    if (has_scene) {
        model_error(ini->path, rig_vtruth_line(ini, sec, "scene"), "sample '%s': a uniform_source has no scene; "
                    "remove 'scene' (give 'radiance' only)", sm->name);
        return false;
    }
    static const char *other[] = { "square_mm", "corners", "corner0_mm", "material", "sphere_centre_mm",
                                   "sphere_radius_mm" };
    for (size_t k = 0; k < sizeof other / sizeof other[0]; k++)
        if (model_ini_get(ini, sec, other[k])) {
            model_error(ini->path, rig_vtruth_line(ini, sec, other[k]), "sample '%s': %s is not a key of "
                        "uniform_source samples (only kind and radiance)", sm->name, other[k]);
            return false;
        }
    snprintf(sm->kind, sizeof sm->kind, "%s", kind);
    sm->uniform = true;
    if (!rig_vtruth_double(ini, sec, "radiance", 0, 1e12, true, &sm->radiance)) return false;
    sm->mats = calloc(1, sizeof *sm->mats);
    sm->tex = calloc(1, sizeof *sm->tex);
    return sm->mats && sm->tex ? true : out_of_memory(ini);
}

// The keys of a sample with a scene against its kind: direct_samples, kind
// and scene present, the kind known, a chessboard's keys, a coupon's material.
static bool check_kind_keys(const model_ini_t *ini, const char *sec, sample_t *sm, const char *kind, bool has_scene,
                            const char *mat, const model_materials_t *mats)
{
    if (model_ini_get(ini, sec, "direct_samples")) {
        long ds;
        if (!rig_vtruth_int(ini, sec, "direct_samples", 1, 4096, &ds)) return false;
        sm->direct_samples = (int)ds;
    }
    if (model_ini_get(ini, sec, "radiance")) {
        model_error(ini->path, rig_vtruth_line(ini, sec, "radiance"), "sample '%s': radiance is a key of "
                    "uniform_source samples only", sm->name);
        return false;
    }
    if (!kind || !has_scene) {
        model_error(ini->path, sm->line, "sample '%s' lacks '%s'; each sample needs kind and scene", sm->name,
                    kind ? "scene" : "kind");
        return false;
    }
    bool known = false;
    for (size_t k = 0; k < sizeof sample_kinds / sizeof sample_kinds[0]; k++)
        if (!strcmp(kind, sample_kinds[k])) known = true;
    if (!known) {
        model_error(ini->path, rig_vtruth_line(ini, sec, "kind"), "sample '%s': kind = '%s' is unknown; use "
                    "workpiece, chessboard, reference_white, material_coupon, mirror_sphere or uniform_source",
                    sm->name, kind);
        return false;
    }
    snprintf(sm->kind, sizeof sm->kind, "%s", kind);
    bool chess = !strcmp(kind, "chessboard"), coupon = !strcmp(kind, "material_coupon") ||
                                                      !strcmp(kind, "reference_white");
    static const char *chess_keys[] = { "square_mm", "corners", "corner0_mm" };
    for (int k = 0; k < 3; k++)
        if (!chess && model_ini_get(ini, sec, chess_keys[k])) {
            model_error(ini->path, rig_vtruth_line(ini, sec, chess_keys[k]), "sample '%s': %s is a key of "
                        "chessboards, not of kind %s", sm->name, chess_keys[k], kind);
            return false;
        }
    if (chess) {
        double sq;
        if (!rig_vtruth_double(ini, sec, "square_mm", 1e-3, 1e4, true, &sq)) return false;
        const char *c = rig_vtruth_str(ini, sec, "corners", NULL);
        int cx, cy;
        char extra;
        if (!c || sscanf(c, "%d %d %c", &cx, &cy, &extra) != 2 || cx < 2 || cy < 2) {
            model_error(ini->path, rig_vtruth_line(ini, sec, "corners"), "sample '%s': corners = '%s': give the "
                        "inner corners along x and y, two integers >= 2 (e.g. corners = 9 7)", sm->name, c ? c : "");
            return false;
        }
    }
    if (mat && !coupon) {
        model_error(ini->path, rig_vtruth_line(ini, sec, "material"), "sample '%s': material is a key of material "
                    "coupons and reference whites, not of kind %s", sm->name, kind);
        return false;
    }
    if (coupon && !mat) {
        model_error(ini->path, sm->line, "sample '%s' (kind %s) lacks 'material': name its [material NAME]",
                    sm->name, kind);
        return false;
    }
    if (mat && !model_materials_find(mats, mat)) {
        model_error(ini->path, rig_vtruth_line(ini, sec, "material"), "sample '%s': material '%s' has no "
                    "[material %s] section", sm->name, mat, mat);
        return false;
    }
    return true;
}

// [sample NAME] flex_mm of a sample of kind `kind`: *scene replaced by its
// bent copy (rig/virtual/place.h; unchanged without the key or at 0).
static bool flex_sample(const model_ini_t *ini, const char *sec, const char *name, const char *kind,
                        model_scene_t **scene)
{
    const model_ini_entry_t *e = model_ini_get(ini, sec, "flex_mm");
    if (!e) return true;
    double flex = 0;
    if (!model_ini_double_in(ini, sec, "flex_mm", &flex, true, -5, false, 5, NULL)) return false;
    if (strcmp(kind, "chessboard") != 0) {
        model_error(ini->path, e->line, "sample '%s': flex_mm bends a chessboard (a calibration board), not a "
                    "sample of kind %s", name, kind);
        return false;
    }
    if (flex == 0) return true;
    model_scene_t *f = rig_virtual_place_flexed(*scene, flex);
    if (!f) {
        char msg[1024];
        snprintf(msg, sizeof msg, "%s", model_last_error());
        model_error(ini->path, e->line, "sample '%s': flex_mm: %s", name, msg);
        return false;
    }
    model_scene_free(*scene);
    *scene = f;
    return true;
}

// The sample's scene: loaded (resolved against the truth file), bent by flex_mm.
static bool load_scene(const rig_truth_t *t, const char *sec, sample_t *sm, const char *scene)
{
    const model_ini_t *ini = rig_truth_ini(t);
    if (!(sm->scene_path = rig_truth_resolve(t, scene))) return out_of_memory(ini);
    sm->scene = model_scene_load(sm->scene_path, NULL);
    if (!sm->scene) {
        char msg[1024];
        snprintf(msg, sizeof msg, "%s", model_last_error());
        model_error(ini->path, rig_vtruth_line(ini, sec, "scene"), "sample '%s': scene %s: %s", sm->name,
                    sm->scene_path, msg);
        return false;
    }
    return flex_sample(ini, sec, sm->name, sm->kind, &sm->scene);
}

// The scene's materials (the truth's), their textures and roughness variants.
static bool attach_materials(const model_ini_t *ini, const rig_vtruth_t *c, sample_t *sm)
{
    int nm = sm->scene->nmaterials;
    if (!(sm->mats = calloc(nm ? nm : 1, sizeof *sm->mats))) return out_of_memory(ini);
    if (!model_resolve_materials(sm->scene, c->mats, sm->mats)) {
        char msg[1024];
        snprintf(msg, sizeof msg, "%s", model_last_error());
        model_error(ini->path, sm->line, "sample '%s': %s; add the material to the truth file", sm->name, msg);
        return false;
    }
    if (!(sm->tex = calloc(nm ? nm : 1, sizeof *sm->tex))) return out_of_memory(ini);
    for (int k = 0; k < nm; k++)
        for (int j = 0; j < c->ntextures; j++)
            if (!strcmp(c->textures[j].material, sm->scene->material_names[k]) &&
                (c->textures[j].amplitude > 0 || c->textures[j].roughness_amplitude > 0)) {
                sm->tex[k] = &c->textures[j];
                sm->textured = true;
                sm->rough |= c->textures[j].roughness_amplitude > 0;
            }
    return !sm->rough || sample_roughness(ini, sm);
}

// [sample NAME] of section s into *sm.
static bool read_sample(const rig_truth_t *t, const rig_vtruth_t *c, int s, sample_t *sm)
{
    const model_ini_t *ini = rig_truth_ini(t);
    const char *sec = ini->sections[s];
    sm->line = ini->section_lines[s];
    if (strlen(sec + 7) >= sizeof sm->name) {
        model_error(ini->path, sm->line, "sample name '%s' is too long (limit %zu)", sec + 7, sizeof sm->name - 1);
        return false;
    }
    strcpy(sm->name, sec + 7);
    const char *kind = rig_vtruth_str(ini, sec, "kind", NULL), *scene = rig_vtruth_str(ini, sec, "scene", NULL);
    sm->R[0] = sm->R[4] = sm->R[8] = 1;
    if (kind && !strcmp(kind, "uniform_source")) return read_uniform(ini, sec, sm, kind, scene != NULL);
    const char *mat = rig_vtruth_str(ini, sec, "material", NULL);
    if (!check_kind_keys(ini, sec, sm, kind, scene != NULL, mat, c->mats) || !load_scene(t, sec, sm, scene) ||
        !attach_materials(ini, c, sm) || !check_sphere_facts(ini, sec, sm))
        return false;
    for (int k = 0; mat && k < sm->scene->nmaterials; k++)
        if (strcmp(sm->scene->material_names[k], mat)) {
            model_error(ini->path, rig_vtruth_line(ini, sec, "material"), "sample '%s': material = %s, but its "
                        "scene %s uses material '%s' too", sm->name, mat, sm->scene_path, sm->scene->material_names[k]);
            return false;
        }
    return true;
}

bool rig_vtruth_samples(const rig_truth_t *t, rig_vtruth_t *c)
{
    const model_ini_t *ini = rig_truth_ini(t);
    int n = 0;
    for (int s = 0; s < ini->nsections; s++)
        if (!strncmp(ini->sections[s], "sample ", 7)) n++;
    if (n == 0) {
        model_error(ini->path, 0, "no [sample NAME] sections; add at least one (the workpiece on the table)");
        return false;
    }
    if (!(c->samples = calloc((size_t)n + MAX_POSES, sizeof *c->samples))) return out_of_memory(ini);
    for (int s = 0; s < ini->nsections; s++)
        if (!strncmp(ini->sections[s], "sample ", 7) && !read_sample(t, c, s, &c->samples[c->nsamples++]))
            return false;
    return true;
}
