// calib/gain/analyse.c — the analysis of one gain, calib_gain_analyse, in its
// phases: the dark model (dark.c), the sweep's signal and variance
// (sweep.c), photon transfer (ptc.c), the 1-sigmas of read noise and dark
// current, linearity (linearity.c) and the linearisation
// (linearisation.c), the small-signal response (calib/gain/gain.h).
#include <glib.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "calib/gain/internal.h"
#include "model/model.h"

void calib_gain_an_free(calib_gain_an_t *a)
{
    double *arrays[] = { a->t, a->mu_y, a->var_y, a->mu_d, a->var_d, a->mu, a->var, a->dev_pct, a->snr, a->mu_p,
                         a->dark_t_us };
    for (size_t i = 0; i < sizeof arrays / sizeof arrays[0]; i++) free(arrays[i]);
}

// The 1-sigmas of read noise and dark current: K's and the dark fits' in
// quadrature (relative).
static void dark_sigmas(calib_gain_an_t *a)
{
    const calib_gain_ptc_t *p = &a->ptc;
    double kr = p->system_gain_std_dn_per_e / p->system_gain_dn_per_e;
    double rr = p->read_noise_dn > 0 ? a->var_dark_std_dn2 / (2 * p->read_noise_dn * p->read_noise_dn) : NAN;
    a->read_noise_std_e = p->read_noise_e * hypot(rr, kr);
    a->dark_current_std_e_per_s = 1e6 / p->system_gain_dn_per_e *
                                  hypot(a->dark_slope_std_dn_per_us, a->dark_slope_dn_per_us * kr);
}

// The small-signal response: the slope at exposure 0 of a quadratic fit of
// the signal against exposure over the steps up to 70 % of saturation (NAN
// with fewer than 4). false + message (out of memory).
static bool small_signal_response(calib_gain_an_t *a)
{
    double *x = malloc(sizeof(double) * ((size_t)a->n + 1) * 2), *y = x ? x + a->n + 1 : NULL, q[3];
    if (!x) {
        model_error_set(NULL, 0, "gain %g dB: out of memory for the small-signal response", a->gain_db);
        return false;
    }
    int m = 0;
    for (int i = 0; i < a->n; i++)
        if (a->mu[i] <= 0.7 * a->ptc.saturation_dn) {
            x[m] = a->t[i];
            y[m] = a->mu[i];
            m++;
        }
    a->response0_dn_per_us = m >= 4 && calib_gain_polyfit(x, y, m, 2, q) ? q[1] : NAN;
    free(x);
    return true;
}

bool calib_gain_analyse(calib_gain_data_t *d, double gain_db, int min_steps, double quant_dn, calib_gain_an_t *a)
{
    memset(a, 0, sizeof *a);
    a->gain_db = gain_db;
    a->radiance = NAN;
    a->kc_per_us = NAN;
    bool var_fitted;
    if (!gain_dark_model(d, a, &var_fitted) || !gain_sweep_steps(d, min_steps, var_fitted, a)) return false;
    if (!calib_gain_ptc(a->t, a->mu, a->var, a->var_y, a->n, a->var_dark_dn2, quant_dn, &a->ptc)) {
        char *m = g_strdup(model_last_error());
        model_error_set(NULL, 0, "gain %g dB: %s", gain_db, m);
        g_free(m);
        return false;
    }
    dark_sigmas(a);
    calib_gain_linearity_r4(a->t, a->mu, a->n, a->ptc.saturation_dn, 0.05, 0.95, NULL, NULL, NULL, a->dev_pct);
    if (!gain_analyse_linearisation(a)) {   // consumers fall back to the parametric form
        model_warning("%s; the parametric S(1 - aS) applies", model_last_error());
        memset(&a->lin, 0, sizeof a->lin);
    }
    return small_signal_response(a);
}
