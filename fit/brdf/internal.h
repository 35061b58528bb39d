// fit/brdf/internal.h — what the BRDF fit's files share.
#pragma once

#include "fit/brdf/brdf.h"

// F0 held over its interval (f0_unmeasured): its uniform's variance added to
// out's covariance along ks*F0 = const (fit/brdf/fit.c; the shared covariance
// of fit/brdf/covariance.c restates it).
void fit_brdf_add_f0_uniform(model_brdf_t m, fit_brdf_result_t *out);
