// calib/gain/ptc.c — photon transfer of one gain (EMVA 1288): saturation,
// system gain K, read noise, dynamic range, SNR (calib/gain/gain.h).
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "calib/gain/gain.h"
#include "model/model.h"

bool calib_gain_ptc(const double *t, const double *mu, const double *var, const double *var_y, int n,
                    double var_dark_dn2, double quant_dn, calib_gain_ptc_t *o)
{
    memset(o, 0, sizeof *o);
    if (n < 6) {
        model_error_set(NULL, 0, "photon transfer: %d exposure steps; at least 6 are needed", n);
        return false;
    }
    int imax = 0;
    for (int i = 1; i < n; i++)
        if (var[i] > var[imax]) imax = i;
    // saturation: the variance must drop after its maximum (EMVA 1288)
    bool drop = false;
    for (int i = imax + 1; i < n; i++)
        if (var[i] < 0.9 * var[imax]) drop = true;
    if (!drop) {
        model_error_set(NULL, 0, "photon transfer: the variance does not drop after its maximum %.4g DN^2 at %.6g us "
                        "(mean %.6g DN above dark, the longest exposure of %d is %.6g us): the sweep does not reach "
                        "saturation; extend it to longer exposures", var[imax], t[imax], mu[imax], n, t[n - 1]);
        return false;
    }
    o->i_sat = imax;
    o->saturation_dn = mu[imax];
    double *x = malloc(sizeof(double) * (size_t)n * 2), *y = x ? x + n : NULL;
    if (!x) {
        model_error_set(NULL, 0, "photon transfer: out of memory for %d steps", n);
        return false;
    }
    int m = 0;
    for (int i = 0; i < n; i++)
        if (mu[i] > 0 && mu[i] <= 0.7 * o->saturation_dn) {
            x[m] = mu[i];
            y[m] = var[i];
            m++;
        }
    double c2[3], c1[3], se2[3];
    bool ok = m >= 5 && calib_gain_polyfit(x, y, m, 2, c2) && calib_gain_polyfit(x, y, m, 1, c1);
    o->system_gain_std_dn_per_e = ok && calib_gain_polyfit_se(x, y, m, 2, c2, se2) ? se2[1] : NAN;
    free(x);
    if (!ok || !(c2[1] > 0)) {
        model_error_set(NULL, 0, "photon transfer: %d points below 70 %% of saturation (%.6g DN); the fit of the "
                        "variance against the mean failed (at least 5 are needed, with a rising variance)",
                        m, o->saturation_dn);
        return false;
    }
    o->n_ptc_fit = m;
    o->system_gain_dn_per_e = c2[1];
    o->system_gain_linear_dn_per_e = c1[1];
    double rd2 = var_dark_dn2 - quant_dn * quant_dn / 12.0;
    o->read_noise_dn = rd2 > 0 ? sqrt(rd2) : 0;
    o->read_noise_e = o->read_noise_dn / o->system_gain_dn_per_e;
    o->saturation_capacity_e = o->saturation_dn / o->system_gain_dn_per_e;
    o->dynamic_range = o->read_noise_e > 0 ? o->saturation_capacity_e / o->read_noise_e : NAN;
    o->linearity_error_pct = calib_gain_linearity_r4(t, mu, n, o->saturation_dn, 0.05, 0.95,
                                                     &o->response_dn_per_us, &o->response_offset_dn, &o->n_lin_fit,
                                                     NULL);
    o->linearity_error_r3_pct = calib_gain_linearity(t, mu, n, o->saturation_dn, 0.05, 0.95, NULL, NULL, NULL, NULL);
    o->snr_max = 0;
    for (int i = 0; i <= imax; i++) {
        double vy = var_y ? var_y[i] : var[i];
        if (vy > 0) o->snr_max = fmax(o->snr_max, mu[i] / sqrt(vy));
    }
    return true;
}
