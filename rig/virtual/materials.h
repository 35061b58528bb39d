// rig/virtual/materials.h — the virtual rig's spatially varying roughness
// (rig/virtual/materials.c): rig/virtual/virtual.c renders with it; fit/eval/chain.c
// compares a fitted material with the mean of its two populations.
#pragma once

#include <stdbool.h>
#include <stddef.h>

#include "model/model.h"

// The rough and smooth variants of n materials: for amp[k] > 0 material k's
// roughness parameter scaled (alpha and m by 1 +- amp, the Blinn exponent ns by
// 1/(1 +- amp)^2, within the parameter's range), else material k itself.
// *store (free it) holds the 2n copies; rough[k] and smooth[k] point into it or
// to base[k]. false + "file:line: ..." when a varied material has no roughness
// parameter (lambert, a table).
bool rig_vmat_variants(int n, const model_material_t *const *base, const double *amp, const char *file, int line,
                       model_material_t **store, const model_material_t **rough, const model_material_t **smooth);
// L = (1 - w) L + w Lr per pixel (L: rendered with the smooth variants, Lr:
// with the rough ones; w in [0, 1]).
void rig_vmat_blend(float *L, const float *Lr, const float *w, size_t n);
