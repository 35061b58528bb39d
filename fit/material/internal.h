// fit/material/internal.h — what the material fit's files share
// (fit/material/material.c: the fit; report.c: its report).
#pragma once

#include <jansson.h>
#include <stdbool.h>

#include "calib/calib.h"
#include "fit/brdf/brdf.h"

// The report of a material fit in dir (made): samples.csv, lobes_fit.csv,
// the plots of scripts/fit_material_report.py and report.html. obs and smp
// sample for sample; res[nres] the models fitted, res[best] the chosen;
// entry the material's priors entry, prov the provenance; cal the first
// camera's calibrations (the lamps' names; may be NULL); cell, factor: the
// albedo cells (--albedo-cells) per observation and per cell, NULL without.
// false + message (model_error_set).
bool fit_material_report(const char *dir, const calib_obs_set_t *obs, const fit_samples_t *smp,
                         const fit_brdf_result_t *res, int nres, int best, const json_t *entry, const json_t *prov,
                         const calib_set_t *cal, const int *cell, const double *factor);
