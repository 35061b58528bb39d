// calib/gain/emva.c — the EMVA 1288 Release 4.0 Linear summary datasheet of
// `refl calib gain` (calib/gain/gain.h): gain.json's "emva1288" (every row
// with its definition and formula; the photon axis, photons.c; the spatial
// analysis, spatial.c; the defect pixels, defects.c) and datasheet.html.
// Where the standard's own equation numbers are not known here, none are
// cited.
#define _GNU_SOURCE
#include <glib.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <stdio.h>

#include "calib/gain/internal.h"
#include "model/model.h"
#include "model/base/report.h"

// One datasheet row; value NAN with photons false: not computable (null);
// photons true and the photon axis not measured: "not measured".
static void row(json_t *rows, const char *quantity, const char *symbol, double value, const char *unit, bool photons,
                bool measured, const char *definition)
{
    json_t *r = json_object();
    json_object_set_new(r, "quantity", json_string(quantity));
    json_object_set_new(r, "symbol", json_string(symbol));
    json_object_set_new(r, "value", photons && !measured ? json_string("not measured") : model_json_number(value));
    json_object_set_new(r, "unit", json_string(unit));
    json_object_set_new(r, "definition", json_string(definition));
    json_array_append_new(rows, r);
}

static json_t *split_json(const calib_gain_split_t *s)
{
    return json_pack("{s:o, s:o, s:o, s:o}", "total", model_json_number(s->total), "row", model_json_number(s->row),
                     "column", model_json_number(s->col),
                     "pixel", model_json_number(s->pixel));
}

static json_t *datasheet_rows(const calib_gain_an_t *a, const calib_gain_maps_t *m)
{
    const calib_gain_photon_t *p = &a->ph;
    const double K = a->ptc.system_gain_dn_per_e;
    const bool ms = p->measured;
    json_t *r = json_array();
    row(r, "quantum efficiency", "eta", 100 * p->qe, "%", true, ms,
        "eta = R / K, R the slope of the least-squares line of mu_y - mu_y.dark against mu_p over the steps up to "
        "70 % of saturation; mu_p = A E t_exp lambda / (h c)");
    row(r, "responsivity", "R", p->responsivity_dn_per_photon, "DN/photon", true, ms, "R = eta K (the slope above)");
    row(r, "system gain", "K", K, "DN/e-", false, true, "slope at zero signal of the photon transfer "
        "sigma^2_y - sigma^2_y.dark against mu_y - mu_y.dark (quadratic fit over 0..70 % of saturation)");
    row(r, "inverse system gain", "1/K", 1 / K, "e-/DN", false, true, "1 / K");
    row(r, "temporal dark noise", "sigma_d", a->ptc.read_noise_e, "e-", false, true,
        "sqrt(sigma^2_y.dark - q^2/12) / K, sigma^2_y.dark at exposure 0");
    row(r, "temporal dark noise", "sigma_y.dark", sqrt(a->var_dark_dn2), "DN", false, true,
        "sqrt(sigma^2_y.dark), quantisation included");
    row(r, "absolute sensitivity threshold", "mu_e.min", p->mu_e_min, "e-", false, true,
        "SNR = 1 of the linear model: mu_e.min = 1/2 + sqrt(sigma^2_y.dark / K^2 + 1/4)");
    row(r, "absolute sensitivity threshold", "mu_p.min", p->mu_p_min, "photons", true, ms, "mu_e.min / eta");
    row(r, "saturation capacity", "mu_e.sat", p->mu_e_sat, "e-", false, true,
        "mu_y.sat / K, mu_y.sat the signal (above dark) where the temporal variance peaks");
    row(r, "saturation capacity", "mu_p.sat", p->mu_p_sat, "photons", true, ms, "mu_e.sat / eta");
    row(r, "maximum SNR", "SNR_max", sqrt(p->mu_e_sat), "1", false, true, "sqrt(mu_e.sat)");
    row(r, "maximum SNR", "SNR_max", 20 * log10(sqrt(p->mu_e_sat)), "dB", false, true, "20 log10 SNR_max");
    row(r, "dynamic range", "DR", p->dynamic_range, "1", false, true, "mu_p.sat / mu_p.min = mu_e.sat / mu_e.min");
    row(r, "dynamic range", "DR", 20 * log10(p->dynamic_range), "dB", false, true, "20 log10 DR");
    row(r, "linearity error", "LE", a->ptc.linearity_error_pct, "%", false, true,
        "Release 4.0 Linear: the line a0 + a1 t through the steps in 5..95 % of saturation minimising "
        "sum((mu_i - a0 - a1 t_i) / mu_i)^2; delta_i = 100 (mu_i - line_i) / line_i; LE = (max delta - min delta) "
        "/ 2 (exposure stands in for the irradiation: the irradiance is constant over the sweep)");
    row(r, "linearity error (Release 3)", "LE_R3", a->ptc.linearity_error_r3_pct, "%", false, true,
        "the same deviations from the unweighted least-squares line");
    row(r, "dark current (from the mean)", "mu_I", a->dark_slope_dn_per_us * 1e6 / K, "e-/s", false, true,
        "slope of mu_y.dark against exposure / K");
    row(r, "dark current (from the variance)", "mu_I.var", a->dark_var_slope_dn2_per_us * 1e6 / (K * K), "e-/s",
        false, true, "slope of sigma^2_y.dark against exposure / K^2 (shot noise of the dark current)");
    const calib_gain_spatial_t *sp = &m->sp;
    const char *parts[4] = { "total", "row", "column", "pixel" };
    const double dv[4] = { sp->dsnu.total, sp->dsnu.row, sp->dsnu.col, sp->dsnu.pixel },
                 pv[4] = { sp->prnu.total, sp->prnu.row, sp->prnu.col, sp->prnu.pixel };
    for (int k = 0; k < 4; k++) {
        char q[64], sym[32];
        snprintf(q, sizeof q, "DSNU (%s)", parts[k]);
        snprintf(sym, sizeof sym, "DSNU.%s", parts[k]);
        row(r, q, sym, dv[k] / K, "e-", false, true, k ? "std of the averaged dark frame's part (row/column/pixel "
            "split, temporal noise removed) / K" : "std of the averaged dark frame, temporal noise removed, / K");
        snprintf(q, sizeof q, "PRNU (%s)", parts[k]);
        snprintf(sym, sizeof sym, "PRNU.%s", parts[k]);
        row(r, q, sym, pv[k], "%", false, true, "std of the averaged flat minus dark (its part), temporal noise "
            "removed, / its mean");
    }
    const calib_gain_defects_t *df = &sp->defects;
    row(r, "hot pixels", "n_hot", df->hot, "pixels", false, true, "averaged dark above its median by more than "
        "the threshold (nsigma robust stds)");
    row(r, "dead pixels", "n_dead", df->dead, "pixels", false, true, "high-pass flat below its median by more than "
        "the threshold");
    row(r, "bright pixels", "n_bright", df->bright, "pixels", false, true, "high-pass flat above its median by more "
        "than the threshold");
    return r;
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

static json_t *snr_json(const calib_gain_an_t *a)
{
    json_t *o = json_object(), *m = json_array(), *id = json_array();
    for (int i = 0; i < a->n; i++) {
        double mp = a->mu_p ? a->mu_p[i] : NAN;
        json_array_append_new(m, model_json_number(a->ph.measured ? calib_gain_snr_model(&a->ph, mp) : NAN));
        json_array_append_new(id, model_json_number(a->ph.measured ? sqrt(mp) : NAN));
    }
    json_object_set_new(o, "photons", gain_json_numbers(a->mu_p, a->n));
    json_object_set_new(o, "electrons", json_array());
    for (int i = 0; i < a->n; i++)
        json_array_append_new(json_object_get(o, "electrons"),
                              model_json_number(a->mu[i] / a->ptc.system_gain_dn_per_e));
    json_object_set_new(o, "snr_measured", gain_json_numbers(a->snr, a->n));
    json_object_set_new(o, "snr_model", m);
    json_object_set_new(o, "snr_ideal", id);
    // the model and the ideal on a grid from half the threshold to saturation (the plot's lines)
    if (a->ph.measured && a->ph.mu_p_min > 0 && a->ph.mu_p_sat > a->ph.mu_p_min) {
        enum { NG = 64 };
        double g[NG], gm[NG], gi[NG], lo = log(0.5 * a->ph.mu_p_min), hi = log(a->ph.mu_p_sat);
        for (int i = 0; i < NG; i++) {
            g[i] = exp(lo + (hi - lo) * i / (NG - 1));
            gm[i] = calib_gain_snr_model(&a->ph, g[i]);
            gi[i] = sqrt(g[i]);
        }
        json_object_set_new(o, "grid_photons", gain_json_numbers(g, NG));
        json_object_set_new(o, "grid_snr_model", gain_json_numbers(gm, NG));
        json_object_set_new(o, "grid_snr_ideal", gain_json_numbers(gi, NG));
    }
    json_object_set_new(o, "definition", json_string(
        "grid_*: the same on 64 photon counts from mu_p.min / 2 to mu_p.sat; measured: (mu_y - mu_y.dark) / "
        "sigma_y; model: eta mu_p / sqrt(sigma^2_y.dark / K^2 + eta mu_p); ideal: "
        "sqrt(mu_p) (eta = 1, no dark noise); photons null when the photon axis is not measured"));
    return o;
}

json_t *calib_gain_emva_json(const calib_gain_opts_t *o, const calib_gain_an_t *an, const calib_gain_maps_t *m)
{
    const calib_gain_an_t *a = &an[0];
    const calib_gain_spatial_t *sp = &m->sp;
    json_t *e = json_object();
    json_object_set_new(e, "standard", json_string("EMVA 1288 Release 4.0 Linear (definitions as stated per row; "
                                                   "equation numbers of the standard not cited)"));
    json_object_set_new(e, "photon_axis", json_string(a->ph.measured ? "measured" : "not measured (give "
                                                      "--irradiance, --pixel-area-um2 and --wavelength-nm)"));
    json_t *c = json_object();
    json_object_set_new(c, "irradiance_uw_cm2", a->ph.measured ? json_real(a->ph.irradiance_uw_cm2)
                                                                : json_string("not measured"));
    if (isfinite(o->photodiode_na))
        json_object_set_new(c, "photodiode", json_pack("{s:f, s:f, s:f, s:s}", "current_na", o->photodiode_na,
                                                       "responsivity_a_per_w", o->photodiode_a_per_w, "area_mm2",
                                                       o->photodiode_mm2, "irradiance", "E = I / (R S)"));
    json_object_set_new(c, "pixel_area_um2", model_json_number(o->pixel_area_um2));
    json_object_set_new(c, "wavelength_nm", model_json_number(o->wavelength_nm));
    json_object_set_new(c, "gain_db", json_real(a->gain_db));
    json_object_set_new(c, "photons", json_string("mu_p = A E t_exp lambda / (h c), h = 6.62607015e-34 J s, "
                                                  "c = 299792458 m/s"));
    json_object_set_new(e, "conditions", c);
    if (a->ph.measured && a->ph.qe > 1)
        json_object_set_new(e, "warning", json_string("quantum efficiency above 100 %: check the irradiance (uW/cm^2 "
                                                      "at the sensor), the pixel area and the wavelength"));
    json_object_set_new(e, "datasheet", datasheet_rows(a, m));
    json_object_set_new(e, "responsivity_offset_dn", a->ph.measured ? model_json_number(a->ph.responsivity_offset_dn)
                                                                    : json_string("not measured"));
    json_object_set_new(e, "snr_curve", snr_json(a));
    json_t *s = json_object();
    json_object_set_new(s, "dsnu_dn", split_json(&sp->dsnu));
    json_object_set_new(s, "prnu_pct", split_json(&sp->prnu));
    json_object_set_new(s, "prnu_highpass_pct", split_json(&sp->prnu_hp));
    json_object_set_new(s, "signal_mean_dn", model_json_number(sp->signal_mean_dn));
    json_object_set_new(s, "definition", json_string(
        "averaged frame y = mu + r[row] + c[column] + p + e; V, Vr, Vc the variances of all values, of the row means "
        "and of the column means, less the temporal variance of the average (sigma^2/L, /M, /N); s2_pixel = (V - Vr "
        "- Vc) / (1 - 1/M - 1/N), s2_row = Vr - s2_pixel / M, s2_col = Vc - s2_pixel / N (M columns, N rows); "
        "DSNU of the averaged dark (DN), PRNU of the averaged flat minus dark, % of its mean, vignetting included; "
        "prnu_highpass_pct: the same of the flat divided by its quadratic smooth surface (vignetting removed)"));
    json_object_set_new(e, "spatial", s);
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

bool calib_gain_datasheet_html(const char *dir, json_t *emva, json_t *prov)
{
    json_t *rows = json_object_get(emva, "datasheet");
    size_t n = json_array_size(rows);
    char **rs = calloc(n + 1, sizeof *rs);
    if (!rs) {
        model_error_set(dir, 0, "out of memory for the datasheet (%zu rows)", n);
        return false;
    }
    char *hp = g_build_filename(dir, "datasheet.html", NULL);
    FILE *f = model_html_begin(hp, "refl calib gain: EMVA 1288 Release 4.0 Linear summary datasheet", prov);
    if (!f) {
        free(rs);
        g_free(hp);
        return false;
    }
    json_t *c = json_object_get(emva, "conditions");
    json_t *irr = json_object_get(c, "irradiance_uw_cm2");
    char ib[64];
    if (json_is_number(irr)) snprintf(ib, sizeof ib, "%.6g", json_number_value(irr));
    else snprintf(ib, sizeof ib, "not measured");
    model_html_para(f, "Photon axis: %s. Irradiance %s uW/cm^2, pixel area %.6g um^2, wavelength %.6g nm, gain %g.",
                    json_string_value(json_object_get(emva, "photon_axis")), ib,
                    json_number_value(json_object_get(c, "pixel_area_um2")),
                    json_number_value(json_object_get(c, "wavelength_nm")),
                    json_number_value(json_object_get(c, "gain_db")));
    for (size_t i = 0; i < n; i++) {
        json_t *r = json_array_get(rows, i), *v = json_object_get(r, "value");
        char *val = json_is_number(v) ? g_strdup_printf("%.5g", json_number_value(v))
                                      : g_strdup(json_is_string(v) ? json_string_value(v) : "n/a");
        rs[i] = g_strdup_printf("%s|%s|%s|%s|%s", json_string_value(json_object_get(r, "quantity")),
                                json_string_value(json_object_get(r, "symbol")), val,
                                json_string_value(json_object_get(r, "unit")),
                                json_string_value(json_object_get(r, "definition")));
        g_free(val);
    }
    model_html_heading(f, "Datasheet");
    model_html_table(f, "quantity|symbol|value|unit|definition", (const char *const *)rs, (int)n);
    for (size_t i = 0; i < n; i++) g_free(rs[i]);
    free(rs);
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
    bool ok = model_html_end(f, hp);
    g_free(hp);
    return ok;
}
