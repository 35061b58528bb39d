// rig/virtual/materials.c — spatially varying roughness of the virtual rig's
// materials ([texture MATERIAL] roughness_amplitude; simulator only: every
// fitted model has one roughness per material).
//
// A varied material is a per-pixel mixture of two microfacet populations, a
// rougher and a smoother one: f = (1 - w) f_smooth + w f_rough with w in [0, 1]
// a value noise of the surface point (rig/virtual/virtual.c, independent of the albedo
// texture's). A convex mixture of two BRDFs is reciprocal when both are, and
// reflects no more than the more reflective of the two, so the variation adds
// no energy; the mixture is of the radiance at the first hit (the layers are
// rendered once with each population and blended pixel by pixel).
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "rig/virtual/materials.h"

// The index of the material's roughness parameter and whether larger means
// rougher (alpha, m) or smoother (ns); -1 when there is none.
static int roughness_param(const model_material_t *m, bool *larger_is_rougher)
{
    if (m->table) return -1;
    int i = model_brdf_param_index(m->model, "alpha");
    if (i < 0) i = model_brdf_param_index(m->model, "m");
    if (i >= 0) {
        *larger_is_rougher = true;
        return i;
    }
    *larger_is_rougher = false;
    return model_brdf_param_index(m->model, "ns");
}

static void scaled(const model_material_t *b, int i, double factor, model_material_t *out)
{
    *out = *b;
    double lo, hi;
    model_brdf_param_range(b->model, i, &lo, &hi);
    out->p[i] = fmin(hi, fmax(lo, b->p[i] * factor));
}

bool rig_vmat_variants(int n, const model_material_t *const *base, const double *amp, const char *file, int line,
                       model_material_t **store, const model_material_t **rough, const model_material_t **smooth)
{
    *store = calloc(2 * (size_t)(n > 0 ? n : 1), sizeof **store);
    if (!*store) {
        model_error(file, line, "out of memory");
        return false;
    }
    for (int k = 0; k < n; k++) {
        rough[k] = smooth[k] = base[k];
        if (!(amp[k] > 0) || !base[k]) continue;
        bool up = true;
        int i = roughness_param(base[k], &up);
        if (i < 0) {
            model_error(file, line, "[texture %s] roughness_amplitude: material '%s' (%s) has no roughness "
                        "parameter (alpha, m or ns); vary the roughness of a ggx, cook_torrance, hall, "
                        "torrance_sparrow or thesis_fit material", base[k]->name, base[k]->name,
                        base[k]->table ? "a table" : model_brdf_name(base[k]->model));
            free(*store);
            *store = NULL;
            return false;
        }
        double a = amp[k];
        double fr = up ? 1 + a : 1 / ((1 + a) * (1 + a)), fs = up ? 1 - a : 1 / ((1 - a) * (1 - a));
        scaled(base[k], i, fr, &(*store)[2 * k]);
        scaled(base[k], i, fs, &(*store)[2 * k + 1]);
        rough[k] = &(*store)[2 * k];
        smooth[k] = &(*store)[2 * k + 1];
    }
    return true;
}

void rig_vmat_blend(float *L, const float *Lr, const float *w, size_t n)
{
    for (size_t i = 0; i < n; i++) L[i] = (1 - w[i]) * L[i] + w[i] * Lr[i];
}
