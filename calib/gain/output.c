// calib/gain/output.c — gain.json: the reference gain's figures, every
// gain's with its curves, the linearisation, the 1-sigmas and the
// definitions of the figures (calib/gain/gain.h).
#include <glib.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "calib/gain/internal.h"
#include "model/model.h"
#include "model/base/report.h"

json_t *gain_json_numbers(const double *v, int n)
{
    json_t *a = json_array();
    for (int i = 0; v && i < n; i++) json_array_append_new(a, model_json_number(v[i]));
    return a;
}

// The exposures of the dark groups the dark level and dark current were
// fitted over (us, one per group); null when unknown.
static json_t *dark_exposures_json(const calib_gain_an_t *a)
{
    if (!(a->ndark > 0) || !a->dark_t_us) return json_null();
    return gain_json_numbers(a->dark_t_us, a->ndark);
}

static json_t *gain_json(const calib_gain_an_t *a)
{
    json_t *o = json_object();
    const calib_gain_ptc_t *p = &a->ptc;
    json_object_set_new(o, "gain_db", json_real(a->gain_db));
    json_object_set_new(o, "system_gain_dn_per_e", model_json_number(p->system_gain_dn_per_e));
    json_object_set_new(o, "system_gain_linear_fit_dn_per_e", model_json_number(p->system_gain_linear_dn_per_e));
    json_object_set_new(o, "read_noise_e", model_json_number(p->read_noise_e));
    json_object_set_new(o, "read_noise_dn", model_json_number(p->read_noise_dn));
    json_object_set_new(o, "dark_temporal_variance_dn2", model_json_number(a->var_dark_dn2));
    json_object_set_new(o, "saturation_dn", model_json_number(p->saturation_dn));
    json_object_set_new(o, "saturation_exposure_us", model_json_number(a->t[p->i_sat]));
    json_object_set_new(o, "saturation_capacity_e", model_json_number(p->saturation_capacity_e));
    json_object_set_new(o, "linearity_error_pct", model_json_number(p->linearity_error_pct));
    json_object_set_new(o, "linearity_error_r3_pct", model_json_number(p->linearity_error_r3_pct));
    json_object_set_new(o, "linearity_error_linearised_pct", model_json_number(a->le_linearised_pct));
    json_object_set_new(o, "linearity_error_linearised_parametric_pct", model_json_number(a->le_linearised_param_pct));
    json_object_set_new(o, "snr_max", model_json_number(p->snr_max));
    json_object_set_new(o, "snr_max_db", model_json_number(20 * log10(p->snr_max)));
    json_object_set_new(o, "dynamic_range", model_json_number(p->dynamic_range));
    json_object_set_new(o, "dynamic_range_db", model_json_number(20 * log10(p->dynamic_range)));
    json_object_set_new(o, "response_dn_per_us", model_json_number(p->response_dn_per_us));
    json_object_set_new(o, "response_offset_dn", model_json_number(p->response_offset_dn));
    json_object_set_new(o, "radiance", model_json_number(a->radiance));
    json_object_set_new(o, "kc_per_us", model_json_number(a->kc_per_us));
    json_object_set_new(o, "response_small_signal_dn_per_us", model_json_number(a->response0_dn_per_us));
    json_object_set_new(o, "kc_small_signal_per_us", model_json_number(a->kc0_per_us));
    json_object_set_new(o, "dark_current_dn_per_s", model_json_number(a->dark_slope_dn_per_us * 1e6));
    json_object_set_new(o, "dark_current_e_per_s",
                        model_json_number(a->dark_slope_dn_per_us * 1e6 / p->system_gain_dn_per_e));
    json_object_set_new(o, "dark_level_dn", model_json_number(a->dark_intercept_dn));
    json_object_set_new(o, "dark_exposures_us", dark_exposures_json(a));
    json_object_set_new(o, "dark_current_from_variance_e_per_s",
                        model_json_number(a->dark_var_slope_dn2_per_us * 1e6 /
                                          (p->system_gain_dn_per_e * p->system_gain_dn_per_e)));
    const calib_gain_emva_t *e = &a->emva;
#define PHOTON(key, v) json_object_set_new(o, key, e->photons ? model_json_number(v) : json_string("not measured"))
    PHOTON("quantum_efficiency", e->qe);
    PHOTON("responsivity_dn_per_photon", e->R);
    PHOTON("absolute_sensitivity_threshold_photons", e->mu_p_min);
    PHOTON("saturation_capacity_photons", e->mu_p_sat);
#undef PHOTON
    json_object_set_new(o, "absolute_sensitivity_threshold_e", model_json_number(e->mu_e_min));
    json_object_set_new(o, "dynamic_range_r4", model_json_number(e->dr));
    json_t *s = json_object();   // this gain's figures by the standard's definitions (the datasheet's rows)
    json_object_set_new(s, "system_gain_dn_per_e", model_json_number(e->K));
    json_object_set_new(s, "temporal_dark_noise_e", model_json_number(e->sigma_d_e));
    json_object_set_new(s, "temporal_dark_noise_dn", model_json_number(e->sigma_y_dark_dn));
    json_object_set_new(s, "saturation_capacity_e", model_json_number(e->mu_e_sat));
    json_object_set_new(s, "absolute_sensitivity_threshold_e", model_json_number(e->mu_e_min));
    json_object_set_new(s, "snr_max", model_json_number(e->snr_max));
    json_object_set_new(s, "dynamic_range", model_json_number(e->dr));
    json_object_set_new(s, "linearity_error_pct", model_json_number(e->le_pct));
    json_object_set_new(s, "linearity_error_min_pct", model_json_number(e->le_min_pct));
    json_object_set_new(s, "linearity_error_max_pct", model_json_number(e->le_max_pct));
    json_object_set_new(s, "dark_current_e_per_s", model_json_number(e->dark_current_e_per_s));
    json_object_set_new(s, "dark_current_from_variance_e_per_s", model_json_number(e->dark_current_var_e_per_s));
    json_object_set_new(s, "saturation_step", json_integer(e->i_sat));
    json_object_set_new(s, "fit_steps", json_integer(e->n_fit));
    json_object_set_new(o, "emva1288", s);
    json_object_set_new(o, "n_steps", json_integer(a->n));
    json_object_set_new(o, "n_ptc_fit", json_integer(p->n_ptc_fit));
    json_object_set_new(o, "n_linearity_fit", json_integer(p->n_lin_fit));
    json_t *c = json_object();
    json_object_set_new(c, "exposure_us", gain_json_numbers(a->t, a->n));
    json_object_set_new(c, "mean_dn", gain_json_numbers(a->mu_y, a->n));
    json_object_set_new(c, "dark_mean_dn", gain_json_numbers(a->mu_d, a->n));
    json_object_set_new(c, "signal_dn", gain_json_numbers(a->mu, a->n));
    json_object_set_new(c, "variance_dn2", gain_json_numbers(a->var_y, a->n));
    json_object_set_new(c, "dark_variance_dn2", gain_json_numbers(a->var_d, a->n));
    json_object_set_new(c, "signal_variance_dn2", gain_json_numbers(a->var, a->n));
    json_object_set_new(c, "snr", gain_json_numbers(a->snr, a->n));
    json_object_set_new(c, "linearity_deviation_pct", gain_json_numbers(a->dev_pct, a->n));
    if (a->mu_p) json_object_set_new(c, "photons", gain_json_numbers(a->mu_p, a->n));
    json_t *kc = json_array();
    for (int i = 0; i < a->n; i++)
        json_array_append_new(kc, model_json_number(isfinite(a->radiance) ? a->mu[i] / a->radiance : NAN));
    json_object_set_new(c, "kc", kc);
    json_object_set_new(o, "curves", c);
    return o;
}

// gain.json: the definitions of its figures.
static json_t *conventions_json(const calib_gain_opts_t *o, const calib_gain_data_t *d)
{
    json_t *cv = json_object();
    json_object_set_new(cv, "grey_values", json_string("DN of the frames' pixel format (unscaled)"));
    json_object_set_new(cv, "signal", json_string("mean grey value minus the mean dark grey value at the same "
                                                  "exposure (EMVA 1288 mu_y - mu_y.dark)"));
    json_object_set_new(cv, "temporal_variance", json_string("var(A - B) / 2 of a frame pair, minus its dark "
                                                             "counterpart"));
    json_object_set_new(cv, "system_gain_dn_per_e", json_string(
        "refl's small-signal K: the slope at zero signal of a quadratic least-squares fit of the variance against "
        "the signal over 0..70 % of saturation (what refl's measurements use; system_gain_linear_fit_dn_per_e: a "
        "straight line with an intercept over the same range). EMVA 1288's K (through the origin, the standard's "
        "range) is emva1288's datasheet row K and gains[].emva1288"));
    json_object_set_new(cv, "read_noise_e", json_string("sqrt(sigma^2_y.dark - q^2/12) / K, sigma^2_y.dark the "
                                                        "dark temporal variance extrapolated to exposure 0"));
    json_object_set_new(cv, "saturation_dn", json_string("signal (above dark) where the temporal variance peaks"));
    json_object_set_new(cv, "linearity_error_pct", json_string(
        "EMVA 1288 Release 4.0, section Linearity: the line a0 + a1 t of signal against exposure through the "
        "steps between 5 % and 95 % of saturation minimising the squared relative deviations "
        "sum((mu_i - a0 - a1 t_i) / mu_i)^2; delta_i = 100 (mu_i - line_i) / line_i; LE = (max delta - min "
        "delta) / 2 in %. linearity_error_r3_pct: the same with Release 3's unweighted least-squares line"));
    json_object_set_new(cv, "linearisation", json_string(
        "measured signal above dark S_m (DN) -> linear signal S (DN) at the reference gain (at gain factor f "
        "relative to it: S = f T(S_m / f)). monotone: a monotone piecewise-cubic Hermite interpolant (Fritsch & "
        "Carlson 1980, knot slopes by Fritsch & Butland 1984) through (measured_dn, linear_dn): every sweep step "
        "up to saturation, made monotone by isotonic regression, from (0, 0); linear_dn = anchor_offset_dn + "
        "anchor_response_dn_per_us t, the small-signal line of a quadratic fit of signal against exposure over "
        "5..70 % of saturation. parametric: S_m = S (1 - a S), a_per_dn from a least-squares fit over the steps "
        "below 90 % of saturation. method: what the consumers apply. linearity_error_linearised_pct: the "
        "Release 4.0 LE of the sweep's signal through the table (its own check; _parametric_pct: through S(1 - aS))"));
    json_object_set_new(cv, "prnu_pct", json_string(
        "std of the flat field (light minus dark averages, each pixel's signal through the linearisation as every "
        "consumer applies it: flat_field.linearised) divided by its quadratic smooth surface (vignetting "
        "and illumination fall-off removed), temporal noise of the averages subtracted (EMVA 1288 variance "
        "correction); prnu_total_pct: the same without removing the smooth part (vignetting included)"));
    json_object_set_new(cv, "dsnu_dn", json_string("std of the averaged dark frame, temporal noise of the average "
                                                   "subtracted"));
    json_object_set_new(cv, "prnu_gain_map", json_string("g(x,y) of the imaging model: flat field minus dark, "
                                                         "mean 1 over the frame, vignetting included"));
    json_object_set_new(cv, "kc_per_us", json_string("response_dn_per_us (slope of the linearity line) / the "
                                                     "source's radiance (--radiance): kc per us at that gain for g "
                                                     "of mean 1"));
    json_object_set_new(cv, "kc_small_signal_per_us", json_string(
        "slope at exposure 0 of a quadratic least-squares fit of the signal against exposure over 0..70 % of "
        "saturation, per unit radiance (free of the non-linearity's compression)"));
    json_object_set_new(cv, "dark_current", json_string("slope of the mean dark level against exposure; "
                                                        "dark_current_from_variance_e_per_s: slope of the dark "
                                                        "temporal variance against exposure / K^2; "
                                                        "dark_exposures_us: the exposures (us) of the dark groups "
                                                        "both were fitted over, one per group"));
    json_object_set_new(cv, "emva1288", json_string("the EMVA 1288 Release 4.0 Linear datasheet: each row by the "
                                                    "standard's definition with its section; refl's own figures in "
                                                    "its refl_rows. The top-level figures (system_gain_dn_per_e, "
                                                    "read_noise_e, saturation_capacity_e, snr_max, dynamic_range, "
                                                    "dsnu_dn, prnu_pct) are refl's; quantum_efficiency and the "
                                                    "gains' photon figures the standard's (\"not measured\" without "
                                                    "a photon axis)"));
    json_object_set_new(cv, "dynamic_range", json_string("refl's: saturation_capacity_e / read_noise_e (both with "
                                                         "the small-signal K; the standard's DR is emva1288's row)"));
    json_object_set_new(cv, "statistics_region", d->roi[2] > 0 ? json_pack("[iiii]", d->roi[0], d->roi[1], d->roi[2],
                                                                           d->roi[3])
                                                               : json_string("whole frame"));
    json_object_set_new(cv, "quantisation_step_dn", json_real(o->quant_dn));
    return cv;
}

// gain.json's "linearisation" (calib_gain_lin_from_json reads it).
static json_t *lin_json(const calib_gain_opts_t *o, const calib_gain_an_t *a)
{
    bool table = a->lin.kind == MODEL_LIN_MONOTONE && a->lin.n >= 2;
    bool mono = o->linearisation != MODEL_LIN_PARAMETRIC && table;
    json_t *l = json_object();
    json_object_set_new(l, "method", json_string(mono ? "monotone" : "parametric"));
    json_object_set_new(l, "a_per_dn", json_real(a->lin_a_per_dn));
    if (table) {
        json_object_set_new(l, "measured_dn", gain_json_numbers(a->lin.m, a->lin.n));
        json_object_set_new(l, "linear_dn", gain_json_numbers(a->lin.s, a->lin.n));
    }
    json_object_set_new(l, "anchor_response_dn_per_us", model_json_number(a->lin_anchor_dn_per_us));
    json_object_set_new(l, "anchor_offset_dn", model_json_number(a->lin_anchor_offset_dn));
    json_object_set_new(l, "linearity_error_linearised_pct", model_json_number(a->le_linearised_pct));
    json_object_set_new(l, "linearity_error_linearised_parametric_pct", model_json_number(a->le_linearised_param_pct));
    return l;
}

json_t *calib_gain_json(const calib_gain_opts_t *o, const calib_gain_data_t *d, const calib_gain_an_t *an, int ngains,
                        const calib_gain_maps_t *maps, json_t *prov)
{
    const calib_gain_an_t *a = &an[0];
    const double K = a->ptc.system_gain_dn_per_e;
    json_t *root = json_object();
    model_json_set_format(root, CALIB_GAIN_FORMAT, CALIB_GAIN_FORMAT_VERSION);
    json_object_set_new(root, "calibration", json_string("gain (EMVA 1288 style)"));
    if (d->camera[0]) json_object_set_new(root, "camera", json_string(d->camera));
    json_object_set_new(root, "gain_db", json_real(a->gain_db));
    json_object_set_new(root, "gain_unit", json_string(d->gain_unit[0] ? d->gain_unit : "dB"));
    json_object_set_new(root, "system_gain_dn_per_e", model_json_number(K));
    json_object_set_new(root, "read_noise_e", model_json_number(a->ptc.read_noise_e));
    json_object_set_new(root, "saturation_dn", model_json_number(a->ptc.saturation_dn));
    json_object_set_new(root, "linearity_error_pct", model_json_number(a->ptc.linearity_error_pct));
    json_object_set_new(root, "linearity_error_r3_pct", model_json_number(a->ptc.linearity_error_r3_pct));
    json_object_set_new(root, "linearisation", lin_json(o, a));
    json_object_set_new(root, "dsnu_dn", model_json_number(maps->dsnu_dn));
    json_object_set_new(root, "dsnu_e", model_json_number(maps->dsnu_dn / K));
    json_object_set_new(root, "prnu_pct", model_json_number(maps->prnu_pct));
    json_object_set_new(root, "prnu_total_pct", model_json_number(maps->prnu_total_pct));
    json_object_set_new(root, "dark_current_e_per_s", model_json_number(a->dark_slope_dn_per_us * 1e6 / K));
    json_object_set_new(root, "dark_current_dn_per_s", model_json_number(a->dark_slope_dn_per_us * 1e6));
    json_object_set_new(root, "dark_level_dn", model_json_number(a->dark_intercept_dn));
    json_object_set_new(root, "dark_exposures_us", dark_exposures_json(a));
    json_object_set_new(root, "saturation_capacity_e", model_json_number(a->ptc.saturation_capacity_e));
    json_object_set_new(root, "snr_max", model_json_number(a->ptc.snr_max));
    json_object_set_new(root, "snr_max_db", model_json_number(20 * log10(a->ptc.snr_max)));
    json_object_set_new(root, "dynamic_range", model_json_number(a->ptc.dynamic_range));
    json_object_set_new(root, "dynamic_range_db", model_json_number(20 * log10(a->ptc.dynamic_range)));
    json_object_set_new(root, "kc_per_us", model_json_number(a->kc_per_us));
    json_object_set_new(root, "kc_small_signal_per_us", model_json_number(a->kc0_per_us));
    json_object_set_new(root, "response_dn_per_us", model_json_number(a->ptc.response_dn_per_us));
    json_t *f = json_object();
    json_object_set_new(f, "exposure_us", json_real(maps->flat_exposure_us));
    json_object_set_new(f, "level_dn", json_real(maps->flat_level_dn));
    json_object_set_new(f, "level_of_saturation", model_json_number(maps->flat_level_dn / a->ptc.saturation_dn));
    json_object_set_new(f, "light_frames", json_integer(maps->flat_frames));
    json_object_set_new(f, "dark_frames", json_integer(maps->dark_frames));
    json_object_set_new(f, "dark_exposure_us", json_real(maps->dark_exposure_us));
    json_object_set_new(f, "width", json_integer(maps->w));
    json_object_set_new(f, "height", json_integer(maps->h));
    json_object_set_new(f, "linearised", json_boolean(maps->flat_linearised));
    json_object_set_new(f, "pixel_std_rel", model_json_number(maps->flat_pixel_std_rel));
    json_object_set_new(root, "flat_field", f);
    json_t *sd = json_object();
    json_object_set_new(sd, "system_gain_dn_per_e", model_json_number(a->ptc.system_gain_std_dn_per_e));
    json_object_set_new(sd, "read_noise_e", model_json_number(a->read_noise_std_e));
    json_object_set_new(sd, "dsnu_dn", model_json_number(maps->dsnu_std_dn));
    json_object_set_new(sd, "prnu_pct", model_json_number(maps->prnu_std_pct));
    json_t *pp = json_object();
    json_object_set_new(pp, "statistical", model_json_number(maps->prnu_std_stat_pct));
    json_object_set_new(pp, "linearisation_slope", model_json_number(maps->prnu_std_lin_pct));
    json_object_set_new(sd, "prnu_pct_parts", pp);
    json_object_set_new(sd, "dark_current_e_per_s", model_json_number(a->dark_current_std_e_per_s));
    json_object_set_new(root, "std", sd);
    json_object_set_new(root, "std_method", json_string(
        "1-sigma of the figures of the same name, from the fits' statistics (units as theirs): "
        "system_gain_dn_per_e: the standard error of the linear coefficient of the photon-transfer quadratic "
        "(heteroscedasticity-consistent sandwich, HC3: each point's own residual, since a variance's scatter grows "
        "with it); read_noise_e: the dark variance's intercept standard error (of its fit against exposure, HC3) "
        "over 2 sigma^2_d and K's relative 1-sigma in quadrature; dark_current_e_per_s: the dark mean's slope "
        "standard error (HC3) and K's in quadrature; dsnu_dn and prnu_pct: the temporal noise tau left in the "
        "averaged frames, a fixed pattern of std s over N pixels giving var(s^2) = (4 s^2 tau + 2 tau^2) / N, "
        "1-sigma = sqrt of that / (2 s) (the pattern itself is the sensor's, not a sample of it); prnu_pct "
        "besides: the linearisation's log-slope d ln S / d ln S_m at the flat's level, the monotone table's "
        "against the parametric S(1 - aS)'s of the same sweep, their relative difference times prnu_pct, in "
        "quadrature (prnu_pct_parts: statistical, linearisation_slope)"));
    json_object_set_new(root, "maps", json_pack("{s:s, s:s, s:s, s:s, s:s}", "offset_dn", "offset_dn.tiff", "dsnu_dn",
                                                "dsnu_dn.tiff", "prnu_gain", "prnu_gain.tiff", "prnu_highpass",
                                                "prnu_highpass.tiff", "defects", "defects.tiff"));
    json_object_set_new(root, "quantum_efficiency",
                        a->emva.photons ? model_json_number(a->emva.qe) : json_string("not measured"));
    json_object_set_new(root, "emva1288", calib_gain_emva_json(o, an, maps));
    json_t *pg = json_array();
    for (int i = 0; i < ngains; i++) json_array_append_new(pg, gain_json(&an[i]));
    json_object_set_new(root, "gains", pg);
    json_object_set_new(root, "conventions", conventions_json(o, d));
    json_object_set_new(root, "provenance", json_incref(prov));
    return root;
}
