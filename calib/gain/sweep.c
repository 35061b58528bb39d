// calib/gain/sweep.c — the exposure sweep of one gain (the second phase of
// calib_gain_analyse): its steps sorted by exposure (then photon count), each
// step's signal and temporal variance above dark (EMVA 1288: mu_y -
// mu_y.dark, sigma^2_y - sigma^2_y.dark), its SNR and its photon count when
// the frames carry one (calib/gain/gain.h).
#include <math.h>
#include <stdlib.h>

#include "calib/gain/internal.h"
#include "model/model.h"

// By exposure, then photon count (a descriptor's steps may share an exposure).
static int cmp_group_t(const void *a, const void *b)
{
    const calib_gain_group_t *const *x = a, *const *y = b;
    if ((*x)->exposure_us != (*y)->exposure_us) return (*x)->exposure_us < (*y)->exposure_us ? -1 : 1;
    return ((*x)->photons > (*y)->photons) - ((*x)->photons < (*y)->photons);
}

// The dark at g's exposure: the dark pair there (of the sweep's or the dark
// set's groups the one of the most frames, else the flat set's: the
// standard keeps its temporal and spatial sets apart), else the dark model
// (the variance's line when fitted; false).
static bool step_dark(const calib_gain_data_t *d, const calib_gain_an_t *a, bool var_fitted,
                      const calib_gain_group_t *g, double *mu_d, double *var_d)
{
    const calib_gain_group_t *best = NULL;
    for (int k = 0; k < d->ng; k++) {
        const calib_gain_group_t *h = &d->g[k];
        if (h->gain_db != a->gain_db || !h->dark || h->exposure_us != g->exposure_us || !isfinite(h->var_dn2))
            continue;
        bool temporal = h->set != CALIB_GAIN_SET_FLAT, best_temporal = best && best->set != CALIB_GAIN_SET_FLAT;
        if (!best || (temporal && !best_temporal) || (temporal == best_temporal && h->n > best->n)) best = h;
    }
    if (best) {
        *mu_d = best->mean_dn;
        *var_d = best->var_dn2;
    } else {
        *mu_d = a->dark_intercept_dn + a->dark_slope_dn_per_us * g->exposure_us;
        *var_d = var_fitted ? a->var_dark_dn2 + a->dark_var_slope_dn2_per_us * g->exposure_us : a->var_dark_dn2;
    }
    return best != NULL;
}

bool gain_sweep_steps(const calib_gain_data_t *d, int min_steps, bool var_fitted, calib_gain_an_t *a)
{
    const calib_gain_group_t **light = malloc(sizeof *light * ((size_t)d->ng + 1));
    int nl = 0;
    if (!light) {
        model_error_set(NULL, 0, "gain %g dB: out of memory for the sweep", a->gain_db);
        return false;
    }
    for (int i = 0; i < d->ng; i++) {
        const calib_gain_group_t *g = &d->g[i];
        if (g->gain_db == a->gain_db && !g->dark && g->set == CALIB_GAIN_SET_SWEEP && g->n >= 2) light[nl++] = g;
    }
    bool ok = false;
    if (nl < min_steps) {
        model_error_set(NULL, 0, "gain %g dB: too few sweep steps: %d exposures with a pair of light frames, EMVA 1288 "
                        "asks for at least %d (capture more exposures, e.g. --steps 50)", a->gain_db, nl, min_steps);
        goto done;
    }
    qsort(light, nl, sizeof *light, cmp_group_t);
    a->n = nl;
    double **arrays[] = { &a->t, &a->mu_y, &a->var_y, &a->mu_d, &a->var_d, &a->mu, &a->var, &a->dev_pct, &a->snr,
                          &a->mu_p };
    for (size_t k = 0; k < sizeof arrays / sizeof arrays[0]; k++)
        if (!(*arrays[k] = calloc((size_t)nl + 1, sizeof(double)))) {
            model_error_set(NULL, 0, "gain %g dB: out of memory for %d sweep steps", a->gain_db, nl);
            goto done;
        }
    for (int i = 0; i < nl; i++) {
        const calib_gain_group_t *g = light[i];
        a->t[i] = g->exposure_us;
        a->mu_y[i] = g->mean_dn;
        a->var_y[i] = g->var_dn2;
        a->n_dark_modelled += !step_dark(d, a, var_fitted, g, &a->mu_d[i], &a->var_d[i]);
        a->mu_p[i] = g->has_photons ? g->photons : NAN;
        a->mu[i] = a->mu_y[i] - a->mu_d[i];
        a->var[i] = a->var_y[i] - a->var_d[i];
        a->snr[i] = a->var_y[i] > 0 ? a->mu[i] / sqrt(a->var_y[i]) : NAN;
    }
    ok = true;
done:
    free(light);
    return ok;
}
