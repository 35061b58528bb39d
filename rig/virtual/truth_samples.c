// rig/virtual/truth_samples.c — the truth file's [texture MATERIAL] and [sample NAME]
// sections read into the virtual rig's textures and samples (scenes loaded,
// materials resolved, facts checked against the scenes).
#include <limits.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "rig/virtual/internal.h"

// A sample's rough and smooth material variants (rig/virtual/materials.c).
static bool sample_roughness(rig_virtual_t *v, const model_ini_t *ini, sample_t *sm)
{
    int n = sm->scene->nmaterials;
    double *amp = calloc(n ? n : 1, sizeof *amp);
    sm->mats_rough = calloc(n ? n : 1, sizeof *sm->mats_rough);
    sm->mats_smooth = calloc(n ? n : 1, sizeof *sm->mats_smooth);
    if (!amp || !sm->mats_rough || !sm->mats_smooth) {
        free(amp);
        return false;
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

bool rig_vtruth_textures(rig_virtual_t *v, const model_ini_t *ini)
{
    int n = 0;
    for (int s = 0; s < ini->nsections; s++)
        if (!strncmp(ini->sections[s], "texture ", 8)) n++;
    if (n == 0) return true;
    v->textures = calloc(n, sizeof *v->textures);
    if (!v->textures) return false;
    for (int s = 0; s < ini->nsections; s++) {
        const char *sec = ini->sections[s];
        if (strncmp(sec, "texture ", 8)) continue;
        texture_t *tx = &v->textures[v->ntextures++];
        const char *mat = sec + 8;
        if (!model_materials_find(v->mats, mat)) {
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
    double r;
    if (!rig_vtruth_double(ini, sec, "sphere_radius_mm", 1e-3, 1e4, true, &r)) return false;
    const char *cs = rig_vtruth_str(ini, sec, "sphere_centre_mm", NULL);
    double c[3];
    char extra;
    if (!cs || sscanf(cs, "%lf %lf %lf %c", &c[0], &c[1], &c[2], &extra) != 3 || !isfinite(c[0]) ||
        !isfinite(c[1]) || !isfinite(c[2])) {
        model_error(ini->path, rig_vtruth_line(ini, sec, "sphere_centre_mm"), "sample '%s': sphere_centre_mm = '%s': give "
                    "the sphere's centre at angle 0 as three numbers x y z (mm, rig frame)", sm->name, cs ? cs : "");
        return false;
    }
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

bool rig_vtruth_samples(rig_virtual_t *v, const model_ini_t *ini)
{
    int n = 0;
    for (int s = 0; s < ini->nsections; s++)
        if (!strncmp(ini->sections[s], "sample ", 7)) n++;
    if (n == 0) {
        model_error(ini->path, 0, "no [sample NAME] sections; add at least one (the workpiece on the table)");
        return false;
    }
    v->samples = calloc((size_t)n + MAX_POSES, sizeof *v->samples);
    if (!v->samples) return false;
    for (int s = 0; s < ini->nsections; s++) {
        const char *sec = ini->sections[s];
        if (strncmp(sec, "sample ", 7)) continue;
        sample_t *sm = &v->samples[v->nsamples++];
        sm->line = ini->section_lines[s];
        if (strlen(sec + 7) >= sizeof sm->name) {
            model_error(ini->path, sm->line, "sample name '%s' is too long (limit %zu)", sec + 7, sizeof sm->name - 1);
            return false;
        }
        strcpy(sm->name, sec + 7);
        const char *kind = rig_vtruth_str(ini, sec, "kind", NULL), *scene = rig_vtruth_str(ini, sec, "scene", NULL);
        sm->R[0] = sm->R[4] = sm->R[8] = 1;
        if (kind && !strcmp(kind, "uniform_source")) {
            // a flat-field source filling the view (an integrating sphere's port
            // in front of the lens), fed by the rig's lamps: no scene
            if (scene) {
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
            if (!sm->mats || !sm->tex) return false;
            continue;
        }
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
        if (!kind || !scene) {
            model_error(ini->path, sm->line, "sample '%s' lacks '%s'; each sample needs kind and scene", sm->name,
                        kind ? "scene" : "kind");
            return false;
        }
        bool known = false;
        for (size_t k = 0; k < sizeof sample_kinds / sizeof sample_kinds[0]; k++)
            if (!strcmp(kind, sample_kinds[k])) known = true;
        if (!known) {
            model_error(ini->path, rig_vtruth_line(ini, sec, "kind"), "sample '%s': kind = '%s' is unknown; use workpiece, "
                        "chessboard, reference_white, material_coupon, mirror_sphere or uniform_source", sm->name, kind);
            return false;
        }
        snprintf(sm->kind, sizeof sm->kind, "%s", kind);
        bool chess = !strcmp(kind, "chessboard"), coupon = !strcmp(kind, "material_coupon") ||
                                                          !strcmp(kind, "reference_white");
        static const char *chess_keys[] = { "square_mm", "corners", "corner0_mm" };
        for (int k = 0; k < 3; k++)
            if (!chess && model_ini_get(ini, sec, chess_keys[k])) {
                model_error(ini->path, rig_vtruth_line(ini, sec, chess_keys[k]), "sample '%s': %s is a key of chessboards, "
                            "not of kind %s", sm->name, chess_keys[k], kind);
                return false;
            }
        if (chess) {
            double sq;
            if (!rig_vtruth_double(ini, sec, "square_mm", 1e-3, 1e4, true, &sq)) return false;
            const char *c = rig_vtruth_str(ini, sec, "corners", NULL);
            int cx, cy;
            char extra;
            if (!c || sscanf(c, "%d %d %c", &cx, &cy, &extra) != 2 || cx < 2 || cy < 2) {
                model_error(ini->path, rig_vtruth_line(ini, sec, "corners"), "sample '%s': corners = '%s': give the inner "
                            "corners along x and y, two integers >= 2 (e.g. corners = 9 7)", sm->name, c ? c : "");
                return false;
            }
        }
        const char *mat = rig_vtruth_str(ini, sec, "material", NULL);
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
        if (mat && !model_materials_find(v->mats, mat)) {
            model_error(ini->path, rig_vtruth_line(ini, sec, "material"), "sample '%s': material '%s' has no "
                        "[material %s] section", sm->name, mat, mat);
            return false;
        }
        sm->scene_path = rig_vtruth_relpath(ini->path, scene);
        if (!sm->scene_path) return false;
        sm->scene = model_scene_load(sm->scene_path, NULL);
        if (!sm->scene) {
            char msg[1024];
            snprintf(msg, sizeof msg, "%s", model_last_error());
            model_error(ini->path, rig_vtruth_line(ini, sec, "scene"), "sample '%s': scene %s: %s", sm->name,
                        sm->scene_path, msg);
            return false;
        }
        if (!rig_virtual_place_flex_sample(ini, sec, sm->name, kind, &sm->scene)) return false;
        sm->mats = calloc(sm->scene->nmaterials ? sm->scene->nmaterials : 1, sizeof *sm->mats);
        if (!sm->mats) return false;
        if (!model_resolve_materials(sm->scene, v->mats, sm->mats)) {
            char msg[1024];
            snprintf(msg, sizeof msg, "%s", model_last_error());
            model_error(ini->path, sm->line, "sample '%s': %s; add the material to the truth file", sm->name, msg);
            return false;
        }
        sm->tex = calloc(sm->scene->nmaterials ? sm->scene->nmaterials : 1, sizeof *sm->tex);
        if (!sm->tex) return false;
        for (int k = 0; k < sm->scene->nmaterials; k++)
            for (int j = 0; j < v->ntextures; j++)
                if (!strcmp(v->textures[j].material, sm->scene->material_names[k]) &&
                    (v->textures[j].amplitude > 0 || v->textures[j].roughness_amplitude > 0)) {
                    sm->tex[k] = &v->textures[j];
                    sm->textured = true;
                    sm->rough |= v->textures[j].roughness_amplitude > 0;
                }
        if (sm->rough && !sample_roughness(v, ini, sm)) return false;
        if (!check_sphere_facts(ini, sec, sm)) return false;
        if (mat)
            for (int k = 0; k < sm->scene->nmaterials; k++)
                if (strcmp(sm->scene->material_names[k], mat)) {
                    model_error(ini->path, rig_vtruth_line(ini, sec, "material"), "sample '%s': material = %s, but its "
                                "scene %s uses material '%s' too", sm->name, mat, sm->scene_path,
                                sm->scene->material_names[k]);
                    return false;
                }
    }
    return true;
}
