// calib/gain/photons.c — the photon axis of EMVA 1288 Release 4.0 Linear:
// photons per pixel from an irradiance (or a photodiode's reading), the
// pixel area and the wavelength, or the frames' own counts (an EMVA 1288
// descriptor's) (calib/gain/gain.h).
#include <math.h>
#include <stdlib.h>
#include <string.h>

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

double calib_gain_opts_irradiance(const calib_gain_opts_t *o)
{
    return isfinite(o->photodiode_na) ? calib_gain_photodiode_irradiance(o->photodiode_na, o->photodiode_a_per_w,
                                                                         o->photodiode_mm2)
                                      : o->irradiance_uw_cm2;
}

bool calib_gain_an_photons(const calib_gain_opts_t *o, calib_gain_an_t *a)
{
    const double E = calib_gain_opts_irradiance(o);
    int counted = 0;
    for (int i = 0; i < a->n; i++) counted += isfinite(a->mu_p[i]);
    a->photon_source = NULL;
    if (counted) {   // the frames' own counts (an EMVA 1288 descriptor)
        if (isfinite(E)) {
            model_error_set(NULL, 0, "the frames carry their photon counts (an EMVA 1288 descriptor): give no "
                            "--irradiance or photodiode reading");
            return false;
        }
        if (counted < a->n) {
            model_error_set(NULL, 0, "%d of the %d sweep steps carry a photon count: all or none", counted, a->n);
            return false;
        }
        a->photon_source = "descriptor";
        return true;
    }
    const bool measured = isfinite(E) && E > 0 && isfinite(o->pixel_area_um2) && o->pixel_area_um2 > 0 &&
                          isfinite(o->wavelength_nm) && o->wavelength_nm > 0;
    for (int i = 0; i < a->n; i++)
        a->mu_p[i] = measured ? calib_gain_photons(E, o->pixel_area_um2, o->wavelength_nm, a->t[i]) : NAN;
    if (measured) a->photon_source = isfinite(o->photodiode_na) ? "photodiode" : "irradiance";
    return true;
}
