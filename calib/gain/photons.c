// calib/gain/photons.c — the photon axis of EMVA 1288 Release 4.0 Linear:
// photons per pixel, quantum efficiency, responsivity, the absolute
// sensitivity threshold and saturation in photons, the SNR model
// (calib/gain/gain.h).
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <stdio.h>

#include "calib/gain/gain.h"
#include "model/model.h"

// Planck's constant (J s) and the speed of light (m/s), SI 2019 exact values.
#define PLANCK_JS 6.62607015e-34
#define LIGHT_MS  299792458.0

double calib_gain_photons(double irradiance_uw_cm2, double pixel_area_um2, double wavelength_nm, double t_us)
{
    // uW/cm^2 = 1e-2 W/m^2; um^2 = 1e-12 m^2; us = 1e-6 s; nm = 1e-9 m
    double energy_j = pixel_area_um2 * 1e-12 * irradiance_uw_cm2 * 1e-2 * t_us * 1e-6;
    return energy_j * wavelength_nm * 1e-9 / (PLANCK_JS * LIGHT_MS);
}

double calib_gain_photodiode_irradiance(double current_na, double responsivity_a_per_w, double area_mm2)
{
    // nA = 1e-9 A; mm^2 = 1e-2 cm^2; W/cm^2 = 1e6 uW/cm^2
    return current_na * 1e-9 / (responsivity_a_per_w * area_mm2 * 1e-2) * 1e6;
}

bool calib_gain_photon_axis(const double *t, const double *mu, int n, double sat_dn, double K, double var_dark_dn2,
                            double E, double A, double lambda, calib_gain_photon_t *o)
{
    memset(o, 0, sizeof *o);
    o->irradiance_uw_cm2 = E;
    o->pixel_area_um2 = A;
    o->wavelength_nm = lambda;
    o->responsivity_dn_per_photon = o->responsivity_offset_dn = o->qe = o->mu_p_min = o->mu_p_sat = NAN;
    // the electron figures: SNR = 1 of the linear model (x = eta mu_p: x^2 = s^2 + x)
    double s2 = var_dark_dn2 / (K * K);
    o->dark_noise_e = sqrt(fmax(s2, 0));
    o->mu_e_min = 0.5 + sqrt(fmax(s2, 0) + 0.25);
    o->mu_e_sat = sat_dn / K;
    o->dynamic_range = o->mu_e_sat / o->mu_e_min;
    o->measured = isfinite(E) && E > 0 && isfinite(A) && A > 0 && isfinite(lambda) && lambda > 0;
    if (!o->measured) return true;
    double *x = malloc(sizeof(double) * (n + 1) * 2), *y = x + n + 1, c[3];
    if (!x) {
        model_error_set(NULL, 0, "out of memory for the photon axis");
        return false;
    }
    int m = 0;
    for (int i = 0; i < n; i++)
        if (mu[i] <= 0.7 * sat_dn) {
            x[m] = calib_gain_photons(E, A, lambda, t[i]);
            y[m] = mu[i];
            m++;
        }
    bool ok = m >= 3 && calib_gain_polyfit(x, y, m, 1, c) && c[1] > 0;
    free(x);
    if (!ok) {
        model_error_set(NULL, 0, "photon axis: %d sweep steps below 70 %% of saturation (%.6g DN); the "
                        "responsivity's line needs at least 3 with a rising signal", m, sat_dn);
        return false;
    }
    o->n_fit = m;
    o->responsivity_dn_per_photon = c[1];
    o->responsivity_offset_dn = c[0];
    o->qe = c[1] / K;
    if (o->qe > 1)
        model_warning("quantum efficiency %.3g %% is above 100 %%: check --irradiance (uW/cm^2 at the sensor), the "
                      "pixel area and the wavelength", 100 * o->qe);
    o->mu_p_min = o->mu_e_min / o->qe;
    o->mu_p_sat = o->mu_e_sat / o->qe;
    return true;
}

double calib_gain_snr_model(const calib_gain_photon_t *p, double mu_p)
{
    double e = p->qe * mu_p;
    return e / sqrt(p->dark_noise_e * p->dark_noise_e + e);
}

bool calib_gain_an_photons(const calib_gain_opts_t *o, calib_gain_an_t *a)
{
    double E = isfinite(o->photodiode_na) ? calib_gain_photodiode_irradiance(o->photodiode_na, o->photodiode_a_per_w,
                                                                             o->photodiode_mm2)
                                          : o->irradiance_uw_cm2;
    if (!calib_gain_photon_axis(a->t, a->mu, a->n, a->ptc.saturation_dn, a->ptc.system_gain_dn_per_e, a->var_dark_dn2,
                                E, o->pixel_area_um2, o->wavelength_nm, &a->ph))
        return false;
    free(a->mu_p);
    a->mu_p = malloc(sizeof(double) * (a->n + 1));
    if (!a->mu_p) {
        model_error_set(NULL, 0, "out of memory for the photon axis");
        return false;
    }
    for (int i = 0; i < a->n; i++)
        a->mu_p[i] = a->ph.measured ? calib_gain_photons(E, o->pixel_area_um2, o->wavelength_nm, a->t[i]) : NAN;
    return true;
}
