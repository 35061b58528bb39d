// fit/material.h — the material fit: from calibrated observations of a
// material (calib_observe, calib/calib.h) to BRDF samples, fitted models and
// priors.
#pragma once

#include <jansson.h>
#include <stdbool.h>

#include "fit/fit.h"
#include "model/model.h"

#ifdef __cplusplus
extern "C" {
#endif

// `refl fit material` (fit/material.c); its observations come from
// calib_observe (calib/calib.h).
int fit_cmd_material(int argc, char **argv);

#ifdef __cplusplus
}
#endif
