// calib/gain/dark.c — the dark model of one gain (the first phase of
// calib_gain_analyse): the dark level and dark current from the mean dark
// grey value against exposure, the temporal dark noise from the dark
// variance against exposure, with their 1-sigmas (calib/gain/gain.h).
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "calib/gain/internal.h"
#include "model/model.h"

// The dark groups of a->gain_db: every group's exposure and mean (t, m; *n),
// and of those with a temporal variance (a pair or more) the exposure and
// variance (tv, v; *nv). Each array holds d->ng values.
static void dark_groups(const calib_gain_data_t *d, double gain_db, double *t, double *m, int *n, double *tv,
                        double *v, int *nv)
{
    *n = *nv = 0;
    for (int i = 0; i < d->ng; i++) {
        const calib_gain_group_t *g = &d->g[i];
        if (g->gain_db != gain_db || !g->dark) continue;
        t[*n] = g->exposure_us;
        m[*n] = g->mean_dn;
        (*n)++;
        if (isfinite(g->var_dn2)) {
            tv[*nv] = g->exposure_us;
            v[*nv] = g->var_dn2;
            (*nv)++;
        }
    }
}

// The dark level (intercept, DN) and its slope (DN/us) with the slope's
// 1-sigma: a line through the nd groups when their exposures differ, else
// their mean and no slope.
static void dark_level(const double *dt, const double *dm, int nd, calib_gain_an_t *a)
{
    double c[3], cse[3];
    a->dark_slope_std_dn_per_us = NAN;
    if (a->dark_t_max_us > a->dark_t_min_us && calib_gain_polyfit(dt, dm, nd, 1, c)) {
        a->dark_intercept_dn = c[0];
        a->dark_slope_dn_per_us = c[1];
        if (nd >= 3 && calib_gain_polyfit_se(dt, dm, nd, 1, c, cse)) a->dark_slope_std_dn_per_us = cse[1];
    } else {
        double s = 0;
        for (int i = 0; i < nd; i++) s += dm[i];
        a->dark_intercept_dn = s / nd;
        a->dark_slope_dn_per_us = 0;
    }
}

// sigma^2_y.dark at exposure 0 with its 1-sigma: the intercept of a line
// through 3 or more variances at different exposures (its slope:
// dark_var_slope_dn2_per_us, the dark current's shot noise), else their mean
// (its standard error). true when the line was fitted.
static bool dark_variance(const double *dtv, const double *dv, int ndv, calib_gain_an_t *a)
{
    double dvc[3], dvse[3], tmin = INFINITY, tmax = -INFINITY;
    a->var_dark_std_dn2 = NAN;
    for (int i = 0; i < ndv; i++) {
        tmin = fmin(tmin, dtv[i]);
        tmax = fmax(tmax, dtv[i]);
    }
    bool fit = ndv >= 3 && tmax > tmin && calib_gain_polyfit(dtv, dv, ndv, 1, dvc);
    a->dark_var_slope_dn2_per_us = fit ? dvc[1] : NAN;
    if (fit) {
        a->var_dark_dn2 = dvc[0];
        if (calib_gain_polyfit_se(dtv, dv, ndv, 1, dvc, dvse)) a->var_dark_std_dn2 = dvse[0];
    } else {
        double s = 0, ss = 0;
        for (int i = 0; i < ndv; i++) s += dv[i];
        a->var_dark_dn2 = s / ndv;
        for (int i = 0; i < ndv; i++) ss += (dv[i] - a->var_dark_dn2) * (dv[i] - a->var_dark_dn2);
        if (ndv >= 2) a->var_dark_std_dn2 = sqrt(ss / (ndv - 1) / ndv);
    }
    return fit;
}

bool gain_dark_model(const calib_gain_data_t *d, calib_gain_an_t *a, bool *var_fitted)
{
    const size_t ng = (size_t)d->ng + 1;
    double *buf = malloc(sizeof(double) * ng * 4), *dt = buf, *dm = buf + ng, *dtv = buf + 2 * ng, *dv = buf + 3 * ng;
    int nd = 0, ndv = 0;
    *var_fitted = false;
    if (!buf) {
        model_error_set(NULL, 0, "gain %g dB: out of memory for the dark model", a->gain_db);
        return false;
    }
    dark_groups(d, a->gain_db, dt, dm, &nd, dtv, dv, &ndv);
    bool ok = nd > 0 && ndv > 0;
    if (!ok)
        model_error_set(NULL, 0, "gain %g dB: no dark frame pairs (kind dark, at least two frames at an exposure); the "
                        "dark level and temporal dark noise need them", a->gain_db);
    else if (!(a->dark_t_us = malloc(sizeof(double) * nd))) {
        model_error_set(NULL, 0, "gain %g dB: out of memory for the dark model", a->gain_db);
        ok = false;
    }
    if (ok) {
        a->ndark = nd;
        memcpy(a->dark_t_us, dt, sizeof(double) * nd);
        a->dark_t_min_us = INFINITY;
        a->dark_t_max_us = -INFINITY;
        for (int i = 0; i < nd; i++) {
            a->dark_t_min_us = fmin(a->dark_t_min_us, dt[i]);
            a->dark_t_max_us = fmax(a->dark_t_max_us, dt[i]);
        }
        dark_level(dt, dm, nd, a);
        *var_fitted = dark_variance(dtv, dv, ndv, a);
    }
    free(buf);
    return ok;
}
