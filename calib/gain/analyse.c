// calib/gain/analyse.c — the analysis of one gain: the dark model, the
// sweep's signal and variance, photon transfer, linearity and the
// response (calib/gain/gain.h).
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

static int cmp_group_t(const void *a, const void *b)
{
    const calib_gain_group_t *const *x = a, *const *y = b;
    return ((*x)->exposure_us > (*y)->exposure_us) - ((*x)->exposure_us < (*y)->exposure_us);
}

bool calib_gain_analyse(calib_gain_data_t *d, double gain_db, int min_steps, double quant_dn, calib_gain_an_t *a)
{
    memset(a, 0, sizeof *a);
    a->gain_db = gain_db;
    a->radiance = NAN;
    a->kc_per_us = NAN;
    // dark model: mean and variance against exposure (all dark groups of this gain)
    int nd = 0, nl = 0;
    double *dt = malloc(sizeof(double) * d->ng), *dm = malloc(sizeof(double) * d->ng),
           *dv = malloc(sizeof(double) * d->ng);
    int ndv = 0;
    double *dtv = malloc(sizeof(double) * d->ng);
    calib_gain_group_t **light = malloc(sizeof *light * d->ng);
    for (int i = 0; i < d->ng; i++) {
        calib_gain_group_t *g = &d->g[i];
        if (g->gain_db != gain_db) continue;
        if (g->dark) {
            dt[nd] = g->exposure_us;
            dm[nd] = g->mean_dn;
            nd++;
            if (isfinite(g->var_dn2)) {
                dtv[ndv] = g->exposure_us;
                dv[ndv] = g->var_dn2;
                ndv++;
            }
        } else if (g->set == CALIB_GAIN_SET_SWEEP && g->n >= 2)
            light[nl++] = g;
    }
    bool ok = false;
    if (nd == 0 || ndv == 0) {
        model_error_set(NULL, 0, "gain %g dB: no dark frame pairs (kind dark, at least two frames at an exposure); the "
                        "dark level and temporal dark noise need them", gain_db);
        goto done;
    }
    a->ndark = nd;
    a->dark_t_us = malloc(sizeof(double) * nd);
    if (a->dark_t_us) memcpy(a->dark_t_us, dt, sizeof(double) * nd);
    a->dark_t_min_us = INFINITY;
    a->dark_t_max_us = -INFINITY;
    for (int i = 0; i < nd; i++) {
        a->dark_t_min_us = fmin(a->dark_t_min_us, dt[i]);
        a->dark_t_max_us = fmax(a->dark_t_max_us, dt[i]);
    }
    double c[3], cse[3];
    a->dark_slope_std_dn_per_us = NAN;
    a->var_dark_std_dn2 = NAN;
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
    double dvc[3];
    bool dv_fit = false;
    {
        double tmin = INFINITY, tmax = -INFINITY;
        for (int i = 0; i < ndv; i++) {
            tmin = fmin(tmin, dtv[i]);
            tmax = fmax(tmax, dtv[i]);
        }
        dv_fit = ndv >= 3 && tmax > tmin && calib_gain_polyfit(dtv, dv, ndv, 1, dvc);
        a->dark_var_slope_dn2_per_us = dv_fit ? dvc[1] : NAN;
        double dvse[3];
        if (dv_fit) {
            a->var_dark_dn2 = dvc[0];
            if (calib_gain_polyfit_se(dtv, dv, ndv, 1, dvc, dvse)) a->var_dark_std_dn2 = dvse[0];
        } else {
            double s = 0, ss = 0;
            for (int i = 0; i < ndv; i++) s += dv[i];
            a->var_dark_dn2 = s / ndv;
            for (int i = 0; i < ndv; i++) ss += (dv[i] - a->var_dark_dn2) * (dv[i] - a->var_dark_dn2);
            if (ndv >= 2) a->var_dark_std_dn2 = sqrt(ss / (ndv - 1) / ndv);
        }
    }
    if (nl < min_steps) {
        model_error_set(NULL, 0, "gain %g dB: too few sweep steps: %d exposures with a pair of light frames, EMVA 1288 "
                        "asks for at least %d (capture more exposures, e.g. --steps 50)", gain_db, nl, min_steps);
        goto done;
    }
    qsort(light, nl, sizeof *light, cmp_group_t);
    a->n = nl;
#define ALLOC(p) a->p = calloc(nl, sizeof(double))
    ALLOC(t); ALLOC(mu_y); ALLOC(var_y); ALLOC(mu_d); ALLOC(var_d); ALLOC(mu); ALLOC(var); ALLOC(dev_pct); ALLOC(snr);
#undef ALLOC
    for (int i = 0; i < nl; i++) {
        calib_gain_group_t *g = light[i];
        a->t[i] = g->exposure_us;
        a->mu_y[i] = g->mean_dn;
        a->var_y[i] = g->var_dn2;
        // the dark pair at the same exposure, else the dark model
        calib_gain_group_t *best = NULL;
        for (int k = 0; k < d->ng; k++) {
            calib_gain_group_t *h = &d->g[k];
            if (h->gain_db == gain_db && h->dark && h->exposure_us == g->exposure_us && isfinite(h->var_dn2) &&
                (!best || h->n > best->n))
                best = h;
        }
        if (best) {
            a->mu_d[i] = best->mean_dn;
            a->var_d[i] = best->var_dn2;
        } else {
            a->mu_d[i] = a->dark_intercept_dn + a->dark_slope_dn_per_us * g->exposure_us;
            a->var_d[i] = dv_fit ? dvc[0] + dvc[1] * g->exposure_us : a->var_dark_dn2;
        }
        a->mu[i] = a->mu_y[i] - a->mu_d[i];
        a->var[i] = a->var_y[i] - a->var_d[i];
        a->snr[i] = a->var_y[i] > 0 ? a->mu[i] / sqrt(a->var_y[i]) : NAN;
    }
    if (!calib_gain_ptc(a->t, a->mu, a->var, a->var_y, nl, a->var_dark_dn2, quant_dn, &a->ptc)) {
        char *m = g_strdup(model_last_error());
        model_error_set(NULL, 0, "gain %g dB: %s", gain_db, m);
        g_free(m);
        goto done;
    }
    // the 1-sigmas of read noise and dark current: K's and the dark fits' in quadrature (relative)
    {
        const calib_gain_ptc_t *p = &a->ptc;
        double kr = p->system_gain_std_dn_per_e / p->system_gain_dn_per_e;
        double rr = p->read_noise_dn > 0 ? a->var_dark_std_dn2 / (2 * p->read_noise_dn * p->read_noise_dn) : NAN;
        a->read_noise_std_e = p->read_noise_e * hypot(rr, kr);
        a->dark_current_std_e_per_s = 1e6 / p->system_gain_dn_per_e *
                                      hypot(a->dark_slope_std_dn_per_us, a->dark_slope_dn_per_us * kr);
    }
    calib_gain_linearity_r4(a->t, a->mu, nl, a->ptc.saturation_dn, 0.05, 0.95, NULL, NULL, NULL, a->dev_pct);
    if (!gain_analyse_linearisation(a)) {   // consumers fall back to the parametric form
        fprintf(stderr, "refl calib gain: warning: %s; the parametric S(1 - aS) applies\n", model_last_error());
        memset(&a->lin, 0, sizeof a->lin);
    }
    {
        double *x = malloc(sizeof(double) * nl), *y = malloc(sizeof(double) * nl), q[3];
        int m = 0;
        for (int i = 0; i < nl; i++)
            if (a->mu[i] <= 0.7 * a->ptc.saturation_dn) {
                x[m] = a->t[i];
                y[m] = a->mu[i];
                m++;
            }
        a->response0_dn_per_us = m >= 4 && calib_gain_polyfit(x, y, m, 2, q) ? q[1] : NAN;
        free(x);
        free(y);
    }
    ok = true;
done:
    free(dt);
    free(dm);
    free(dv);
    free(dtv);
    free(light);
    return ok;
}
