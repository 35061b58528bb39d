// calib/gain/emva.c — the EMVA 1288 Release 4.0 Linear summary datasheet of
// `refl calib gain` (calib/gain/gain.h): gain.json's "emva1288" (the rows,
// datasheet.c, of the standard's figures, standard.c and nonuniformity.c;
// the photon axis, photons.c; the spatial analysis, spatial.c; the defect
// pixels, defects.c) and datasheet.html.
#define _GNU_SOURCE
#include <glib.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <stdio.h>

#include "calib/gain/internal.h"
#include "model/model.h"
#include "model/base/report.h"

static json_t *split_json(const calib_gain_split_t *s)
{
    return json_pack("{s:o, s:o, s:o, s:o}", "total", model_json_number(s->total), "row", model_json_number(s->row),
                     "column", model_json_number(s->col), "pixel", model_json_number(s->pixel));
}

static json_t *four_json(const double *v, double scale)
{
    return json_pack("{s:o, s:o, s:o, s:o}", "total", model_json_number(v[0] * scale), "row",
                     model_json_number(v[1] * scale), "column", model_json_number(v[2] * scale), "pixel",
                     model_json_number(v[3] * scale));
}

static json_t *stack_json(const calib_gain_stack_var_t *v)
{
    json_t *o = json_object();
    json_object_set_new(o, "frames_L", json_integer(v->L));
    json_object_set_new(o, "rows_M", json_integer(v->M));
    json_object_set_new(o, "columns_N", json_integer(v->N));
    json_object_set_new(o, "mean_dn", model_json_number(v->mean));
    json_object_set_new(o, "s2_measured", model_json_number(v->s2_measured));
    json_object_set_new(o, "sigma2_stack", model_json_number(v->stack_var));
    json_object_set_new(o, "s2", model_json_number(v->s2));
    json_object_set_new(o, "s2_cav", model_json_number(v->s2_cav));
    json_object_set_new(o, "s2_rav", model_json_number(v->s2_rav));
    json_object_set_new(o, "s2_row", model_json_number(v->s2_row));
    json_object_set_new(o, "s2_col", model_json_number(v->s2_col));
    json_object_set_new(o, "s2_pixel", model_json_number(v->s2_pixel));
    return o;
}

static json_t *hist_json(double lo, double hi, const long *h, int nb, const char *unit)
{
    json_t *c = json_array();
    for (int i = 0; i < nb; i++) json_array_append_new(c, json_integer(h[i]));
    return json_pack("{s:o, s:o, s:s, s:o}", "lo", model_json_number(lo), "hi", model_json_number(hi), "unit", unit,
                     "counts", c);
}

static json_t *defects_json(const calib_gain_defects_t *d, double nsigma)
{
    json_t *o = json_object();
    json_object_set_new(o, "map", json_string("defects.tiff"));
    json_object_set_new(o, "codes", json_string("0 good, 1 hot, 2 dead, 3 bright"));
    json_object_set_new(o, "nsigma", json_real(nsigma));
    json_object_set_new(o, "hot", json_integer(d->hot));
    json_object_set_new(o, "dead", json_integer(d->dead));
    json_object_set_new(o, "bright", json_integer(d->bright));
    json_object_set_new(o, "dark_median_dn", model_json_number(d->dark_median_dn));
    json_object_set_new(o, "dark_sigma_dn", model_json_number(d->dark_sigma_dn));
    json_object_set_new(o, "hot_threshold_dn", model_json_number(d->dark_threshold_dn));
    json_object_set_new(o, "light_median", model_json_number(d->light_median));
    json_object_set_new(o, "light_sigma", model_json_number(d->light_sigma));
    json_object_set_new(o, "light_threshold", model_json_number(d->light_threshold));
    const char *names[3] = { "hot_pixels", "dead_pixels", "bright_pixels" };
    for (int k = 0; k < 3; k++) {
        json_t *l = json_array();
        for (int i = 0; i < d->nlist[k]; i++)
            json_array_append_new(l, json_pack("[ii]", d->list[k][i][0], d->list[k][i][1]));
        json_object_set_new(o, names[k], l);
    }
    json_object_set_new(o, "histogram_dark", hist_json(d->dark_lo, d->dark_hi, d->dark_hist, d->dark_nbins,
                                                       "DN from the median"));
    json_object_set_new(o, "histogram_light", hist_json(d->light_lo, d->light_hi, d->light_hist, d->light_nbins,
                                                        "% from the median (high-pass flat)"));
    return o;
}

static json_t *spectro_json(int n, int len, const double *dark, const double *light)
{
    json_t *f = json_array();
    for (int k = 0; k < n; k++) json_array_append_new(f, model_json_number((double)k / len));
    return json_pack("{s:o, s:o, s:o}", "frequency_cycles_per_px", f, "dark_dn", gain_json_numbers(dark, n),
                     "light_pct", gain_json_numbers(light, n));
}

// The linear model's SNR at mu_p photons (the standard's eta, K and sigma_y.dark):
// eta mu_p / sqrt(sigma^2_y.dark / K^2 + eta mu_p).
static double snr_model(const calib_gain_emva_t *e, double mu_p)
{
    const double x = e->qe * mu_p, s = e->sigma_y_dark_dn / e->K;
    return x / sqrt(s * s + x);
}

static json_t *snr_json(const calib_gain_an_t *a)
{
    const calib_gain_emva_t *e = &a->emva;
    const bool ms = e->photons;
    json_t *o = json_object(), *m = json_array(), *id = json_array(), *el = json_array();
    for (int i = 0; i < a->n; i++) {
        double mp = ms ? a->mu_p[i] : NAN;
        json_array_append_new(m, model_json_number(ms ? snr_model(e, mp) : NAN));
        json_array_append_new(id, model_json_number(ms ? sqrt(mp) : NAN));
        json_array_append_new(el, model_json_number(a->mu[i] / e->K));
    }
    json_object_set_new(o, "photons", gain_json_numbers(a->mu_p, a->n));
    json_object_set_new(o, "electrons", el);
    json_object_set_new(o, "snr_measured", gain_json_numbers(a->snr, a->n));
    json_object_set_new(o, "snr_model", m);
    json_object_set_new(o, "snr_ideal", id);
    // the model and the ideal on a grid from half the threshold to saturation (the plot's lines)
    if (ms && e->mu_p_min > 0 && e->mu_p_sat > e->mu_p_min) {
        enum { NG = 64 };
        double g[NG], gm[NG], gi[NG], lo = log(0.5 * e->mu_p_min), hi = log(e->mu_p_sat);
        for (int i = 0; i < NG; i++) {
            g[i] = exp(lo + (hi - lo) * i / (NG - 1));
            gm[i] = snr_model(e, g[i]);
            gi[i] = sqrt(g[i]);
        }
        json_object_set_new(o, "grid_photons", gain_json_numbers(g, NG));
        json_object_set_new(o, "grid_snr_model", gain_json_numbers(gm, NG));
        json_object_set_new(o, "grid_snr_ideal", gain_json_numbers(gi, NG));
    }
    json_object_set_new(o, "definition", json_string(
        "grid_*: the same on 64 photon counts from mu_p.min / 2 to mu_p.sat; measured: (mu_y - mu_y.dark) / "
        "sigma_y; model: eta mu_p / sqrt(sigma^2_y.dark / K^2 + eta mu_p) (the datasheet's eta, K, sigma_y.dark); "
        "ideal: sqrt(mu_p) (eta = 1, no dark noise); electrons (mu_y - mu_y.dark) / K; photons null when the photon "
        "axis is not measured"));
    return o;
}

// The standard's fit ranges and intermediate figures of the photon transfer.
static json_t *ptc_json(const calib_gain_an_t *a)
{
    const calib_gain_emva_t *e = &a->emva;
    json_t *o = json_object();
    json_object_set_new(o, "x", json_string(e->photons ? "mu_p, photons per pixel" : "exposure in us (standing in "
                                                         "for mu_p: constant irradiance)"));
    json_object_set_new(o, "steps", json_integer(e->n));
    json_object_set_new(o, "saturation_step", json_integer(e->i_sat));
    json_object_set_new(o, "saturation_past_full_well_plateau", json_boolean(e->sat_plateau));
    json_object_set_new(o, "saturation_signal_dn", model_json_number(e->mu_y_sat_dn));
    json_object_set_new(o, "saturation_x", model_json_number(e->x_sat));
    json_object_set_new(o, "fit_steps", json_integer(e->n_fit));
    json_object_set_new(o, "fit_last_step", json_integer(e->i_fit_last));
    json_object_set_new(o, "responsivity", model_json_number(e->R));
    json_object_set_new(o, "linearity_steps", json_pack("[ii]", e->i_lin_first, e->i_lin_last));
    json_object_set_new(o, "linearity_slope", model_json_number(e->lin_slope));
    json_object_set_new(o, "linearity_offset_dn", model_json_number(e->lin_offset));
    json_object_set_new(o, "dark_variance_dn2", model_json_number(e->var_y_dark_dn2));
    json_object_set_new(o, "dark_exposures", json_integer(e->n_dark));
    json_object_set_new(o, "dark_variance_fitted", json_boolean(e->dark_fitted));
    json_object_set_new(o, "dark_variance_raised_to_0.24q2", json_boolean(e->dark_floored));
    json_object_set_new(o, "dark_current_dn_per_s", model_json_number(e->dark_current_dn_per_s));
    json_object_set_new(o, "dark_current_var_dn2_per_s", model_json_number(e->dark_current_var_dn2_per_s));
    json_object_set_new(o, "steps_without_their_dark_pair", json_integer(a->n_dark_modelled));
    json_object_set_new(o, "definition", json_string(
        "steps indexed from 0 in gain.json's curves order (exposure, then photons); saturation_step: the maximum "
        "of sigma^2_y walking from the brightest step back (saturation_past_full_well_plateau: the walk ended on a "
        "plateau below half the largest sigma^2_y, past a full well, and the largest is the saturation); fit_steps: 0 .. fit_last_step, the last with mu_y - "
        "mu_y.dark <= 0.7 of its value at saturation_step; linearity_steps: the first with >= 5 % .. the last "
        "with <= 95 %; steps_without_their_dark_pair: steps whose dark is refl's dark model (the standard "
        "takes the dark pair at each exposure)"));
    return o;
}

// The standard's spatial block (and refl's high-pass split beside it).
static json_t *spatial_json(const calib_gain_an_t *a, const calib_gain_maps_t *m)
{
    const calib_gain_nonuni_t *nu = &m->nu;
    json_t *s = json_object();
    json_object_set_new(s, "dsnu_dn", four_json(nu->dsnu_dn, 1));
    json_object_set_new(s, "dsnu_e", four_json(nu->dsnu_dn, 1 / a->emva.K));
    json_object_set_new(s, "prnu_pct", four_json(nu->prnu_pct, 1));
    json_object_set_new(s, "dsnu_variance_dn2", four_json(nu->dsnu_var_dn2, 1));
    json_object_set_new(s, "prnu_variance_dn2", four_json(nu->prnu_var_dn2, 1));
    json_object_set_new(s, "variances_dn2", json_pack("{s:o, s:o}", "dark", stack_json(&nu->dark), "light",
                                                      stack_json(&nu->light)));
    json_object_set_new(s, "signal_dn", model_json_number(nu->signal_dn));
    json_object_set_new(s, "dark_at_light_exposure", json_boolean(nu->same_exposure));
    json_object_set_new(s, "prnu_highpass_pct", split_json(&m->sp.prnu_hp));
    json_object_set_new(s, "signal_mean_dn", model_json_number(m->sp.signal_mean_dn));
    json_object_set_new(s, "definition", json_string(
        "EMVA 1288 Release 4.0 Linear sections 4 and 8, per stack of L frames averaged, over the statistics "
        "region's M rows and N columns: s2_measured the variance of the average (divisor MN - 1), sigma2_stack the "
        "mean of each pixel's temporal variance (divisor L - 1), s2 = s2_measured - sigma2_stack / L, s2_cav and "
        "s2_rav the variances of the N column means and of the M row means less sigma2_stack / (L M) and / (L N), "
        "D = MN - M - N, s2_col = (MN - M) / D s2_cav - N / D (s2 - s2_rav), s2_row = (MN - N) / D s2_rav - M / D "
        "(s2 - s2_cav), s2_pixel = MN / D (s2 - s2_cav - s2_rav): the parts add up to s2. dsnu: the dark stack's "
        "(DN; e- over K), prnu: 100 sqrt(light's - dark's) / (mu_y - mu_y.dark), raw frames (vignetting "
        "included); a negative variance estimate v gives -sqrt(-v) (the *_variance_dn2 keep it). "
        "prnu_highpass_pct: refl's split of the linearised flat divided by its quadratic smooth surface "
        "(signed roots)"));
    return s;
}

// gain.json "emva1288" "conditions".
static json_t *conditions_json(const calib_gain_opts_t *o, const calib_gain_an_t *a)
{
    json_t *c = json_object();
    const double E = calib_gain_opts_irradiance(o);
    const bool from_e = a->photon_source && strcmp(a->photon_source, "descriptor");
    json_object_set_new(c, "photon_source", a->photon_source ? json_string(a->photon_source) : json_null());
    json_object_set_new(c, "irradiance_uw_cm2", from_e ? model_json_number(E) : json_string(
                            a->photon_source ? "not given (the descriptor's photon counts)" : "not measured"));
    if (isfinite(o->photodiode_na))
        json_object_set_new(c, "photodiode", json_pack("{s:f, s:f, s:f, s:s}", "current_na", o->photodiode_na,
                                                       "responsivity_a_per_w", o->photodiode_a_per_w, "area_mm2",
                                                       o->photodiode_mm2, "irradiance", "E = I / (R S)"));
    json_object_set_new(c, "pixel_area_um2", model_json_number(o->pixel_area_um2));
    json_object_set_new(c, "wavelength_nm", model_json_number(o->wavelength_nm));
    json_object_set_new(c, "gain_db", json_real(a->gain_db));
    json_object_set_new(c, "quantisation_step_dn", json_real(o->quant_dn));
    json_object_set_new(c, "photons", json_string(from_e ? "mu_p = A E t_exp lambda / (h c), h = 6.62607015e-34 J "
                                                           "s, c = 299792458 m/s" : a->photon_source ? "each step's "
                                                           "count as the EMVA 1288 descriptor gives it" : "none"));
    return c;
}

json_t *calib_gain_emva_json(const calib_gain_opts_t *o, const calib_gain_an_t *an, const calib_gain_maps_t *m)
{
    const calib_gain_an_t *a = &an[0];
    const calib_gain_spatial_t *sp = &m->sp;
    json_t *e = json_object();
    json_object_set_new(e, "standard", json_string("EMVA 1288 Release 4.0 Linear: every datasheet row as the "
                                                   "standard defines it, with its section, the ranges and points "
                                                   "of the EMVA 1288 reference implementation; refl's own figures "
                                                   "in refl_rows"));
    json_object_set_new(e, "photon_axis", json_string(a->photon_source ? "measured" : "not measured (give "
                                                      "--irradiance, --pixel-area-um2 and --wavelength-nm, or "
                                                      "--emva-descriptor)"));
    json_object_set_new(e, "conditions", conditions_json(o, a));
    if (a->emva.photons && a->emva.qe > 1)
        json_object_set_new(e, "warning", json_string("quantum efficiency above 100 %: check the photon counts (the "
                                                      "irradiance at the sensor, the pixel area, the wavelength)"));
    json_object_set_new(e, "datasheet", gain_datasheet_rows(o, a, m));
    json_object_set_new(e, "refl_rows", gain_refl_rows(a, m));
    json_object_set_new(e, "photon_transfer", ptc_json(a));
    json_object_set_new(e, "snr_curve", snr_json(a));
    json_object_set_new(e, "spatial", spatial_json(a, m));
    json_t *sg = json_object();
    json_object_set_new(sg, "horizontal", spectro_json(sp->nh, sp->pw, sp->spec_h_dark, sp->spec_h_light));
    json_object_set_new(sg, "vertical", spectro_json(sp->nv, sp->ph, sp->spec_v_dark, sp->spec_v_light));
    json_object_set_new(sg, "definition", json_string(
        "horizontal: the DFT Y(k) of every row after removing the frame's mean, s(k) = sqrt(mean over rows of "
        "|Y(k)|^2 / N), N the row length, frequency k / N cycles per pixel (column patterns show here); vertical: "
        "the same along the columns (row patterns). White noise of std sigma gives s ~ sigma; dark in DN, light in % "
        "of the mean signal"));
    json_object_set_new(e, "spectrograms", sg);
    json_t *pr = json_object();
    json_object_set_new(pr, "column_dark_dn", gain_json_numbers(sp->col_dark, sp->pw));
    json_object_set_new(pr, "column_signal_dn", gain_json_numbers(sp->col_light, sp->pw));
    json_object_set_new(pr, "row_dark_dn", gain_json_numbers(sp->row_dark, sp->ph));
    json_object_set_new(pr, "row_signal_dn", gain_json_numbers(sp->row_light, sp->ph));
    json_object_set_new(pr, "definition", json_string("means of the statistics region's columns (horizontal "
                                                      "profile) and rows (vertical profile) of the averaged dark "
                                                      "and flat minus dark"));
    json_object_set_new(e, "profiles", pr);
    json_object_set_new(e, "defects", defects_json(&sp->defects, o->defect_sigma));
    return e;
}

// A table of rows (quantity, symbol, value, unit, [section,] definition). false + message (out of memory).
static bool table(FILE *f, json_t *rows, bool sections)
{
    size_t n = json_array_size(rows);
    char **rs = calloc(n + 1, sizeof *rs);
    if (!rs) {
        model_error_set(NULL, 0, "out of memory for the datasheet (%zu rows)", n);
        return false;
    }
    for (size_t i = 0; i < n; i++) {
        json_t *r = json_array_get(rows, i), *v = json_object_get(r, "value");
        char *val = json_is_number(v) ? g_strdup_printf("%.5g%s", json_number_value(v),
                                                        json_is_true(json_object_get(r, "negative_estimate"))
                                                            ? " (negative variance)" : "")
                                      : g_strdup(json_is_string(v) ? json_string_value(v) : "n/a");
        const char *sec = json_string_value(json_object_get(r, "section"));
        rs[i] = g_strdup_printf("%s|%s|%s|%s|%s%s%s", json_string_value(json_object_get(r, "quantity")),
                                json_string_value(json_object_get(r, "symbol")), val,
                                json_string_value(json_object_get(r, "unit")), sections ? (sec ? sec : "") : "",
                                sections ? "|" : "", json_string_value(json_object_get(r, "definition")));
        g_free(val);
    }
    model_html_table(f, sections ? "quantity|symbol|value|unit|section|definition" : "quantity|symbol|value|unit|"
                     "definition", (const char *const *)rs, (int)n);
    for (size_t i = 0; i < n; i++) g_free(rs[i]);
    free(rs);
    return true;
}

bool calib_gain_datasheet_html(const char *dir, json_t *emva, json_t *prov)
{
    char *hp = g_build_filename(dir, "datasheet.html", NULL);
    FILE *f = model_html_begin(hp, "refl calib gain: EMVA 1288 Release 4.0 Linear summary datasheet", prov);
    if (!f) {
        g_free(hp);
        return false;
    }
    json_t *c = json_object_get(emva, "conditions");
    json_t *irr = json_object_get(c, "irradiance_uw_cm2");
    char ib[96];
    if (json_is_number(irr)) snprintf(ib, sizeof ib, "%.6g uW/cm^2", json_number_value(irr));
    else snprintf(ib, sizeof ib, "%s", json_string_value(irr) ? json_string_value(irr) : "not measured");
    model_html_para(f, "Photon axis: %s (%s). Irradiance %s, pixel area %.6g um^2, wavelength %.6g nm, gain %g.",
                    json_string_value(json_object_get(emva, "photon_axis")),
                    json_is_string(json_object_get(c, "photon_source"))
                        ? json_string_value(json_object_get(c, "photon_source")) : "none", ib,
                    json_number_value(json_object_get(c, "pixel_area_um2")),
                    json_number_value(json_object_get(c, "wavelength_nm")),
                    json_number_value(json_object_get(c, "gain_db")));
    model_html_heading(f, "Datasheet (EMVA 1288 Release 4.0 Linear)");
    model_html_para(f, "Each figure as the standard defines it; the section column names the standard's sections "
                    "(the chapter defining it, the one evaluating it).");
    bool ok = table(f, json_object_get(emva, "datasheet"), true);
    model_html_heading(f, "refl's own figures (not EMVA 1288)");
    ok = ok && table(f, json_object_get(emva, "refl_rows"), false);
    static const char *const figs[][3] = {
        { "SNR", "snr_photons.png", "SNR against photons per pixel (or electrons when not measured): measured up to "
                                    "saturation, the linear model and the ideal sqrt(mu_p)" },
        { "Spectrograms", "spectrogram_h.png", "horizontal spectrograms (along the rows: column patterns), dark (DN) "
                                               "and light (%)" },
        { NULL, "spectrogram_v.png", "vertical spectrograms (along the columns: row patterns), dark (DN) and light "
                                     "(%)" },
        { "Profiles", "profiles.png", "horizontal and vertical profiles: column and row means of the averaged dark "
                                      "and flat minus dark" },
        { "Defect pixels", "log_histograms.png", "logarithmic histograms of the deviations from the median: dark "
                                                 "(DN) and high-pass flat (%), with the defect thresholds" },
        { NULL, "defect_map.png", "defect pixels (defects.tiff): hot, dead, bright" },
    };
    for (size_t i = 0; i < sizeof figs / sizeof figs[0]; i++) {
        if (figs[i][0]) model_html_heading(f, figs[i][0]);
        model_html_figure(f, figs[i][1], figs[i][2]);
    }
    fprintf(f, "<p><a href=\"report.html\">the full report</a>; figures and curves: gain.json \"emva1288\"</p>\n");
    ok = model_html_end(f, hp) && ok;
    g_free(hp);
    return ok;
}
