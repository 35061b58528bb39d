// calib/gain/datasheet.c — the rows of the EMVA 1288 Release 4.0 Linear
// summary datasheet (gain.json "emva1288" "datasheet": each figure as the
// standard defines it, with its section) and refl's own figures beside them
// ("refl_rows": never in a row that names the standard) (calib/gain/gain.h).
//
// Sections are the standard's: the chapters 2 (Sensitivity, Linearity, and
// Noise: 2.1 Linear Signal Model, 2.2 Noise Model, 2.3 Signal-to-Noise Ratio,
// 2.4 Signal Saturation and Absolute Sensitivity Threshold), 3 (Dark Current:
// 3.1 Mean and Variance), 4 (Spatial Nonuniformity and Defect Pixels) define
// the figures; 6 (Methods for Sensitivity, Linearity, and Noise), 7 (Methods
// for Dark Current) and 8 (Methods for Spatial Nonuniformity and Defect
// Pixels) evaluate them.
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "calib/gain/internal.h"
#include "model/model.h"
#include "model/base/report.h"

#define S_SIGNAL "2.1, 6"
#define T_SIGNAL "Linear Signal Model; Methods for Sensitivity, Linearity, and Noise (photon transfer)"
#define S_NOISE  "2.2, 6"
#define T_NOISE  "Noise Model; Methods for Sensitivity, Linearity, and Noise (photon transfer)"
#define S_SAT    "2.4, 6"
#define T_SAT    "Signal Saturation and Absolute Sensitivity Threshold; Methods for Sensitivity, Linearity, and Noise"
#define S_SNR    "2.3, 2.4"
#define T_SNR    "Signal-to-Noise Ratio; Signal Saturation and Absolute Sensitivity Threshold"
#define S_LIN    "6"
#define T_LIN    "Methods for Sensitivity, Linearity, and Noise (linearity)"
#define S_DARK   "3.1, 7"
#define T_DARK   "Dark Current: Mean and Variance; Methods for Dark Current"
#define S_NU     "4, 8"
#define T_NU     "Spatial Nonuniformity and Defect Pixels; Methods for Spatial Nonuniformity and Defect Pixels"

// One row; photon: a photon figure ("not measured" without the photon axis);
// variance: the figure is the signed root of a variance (a negative one is
// flagged); value NAN otherwise: null (not computable).
static void row(json_t *rows, const char *quantity, const char *symbol, double value, const char *unit,
                const char *section, const char *title, bool photon, bool measured, bool variance,
                const char *definition)
{
    json_t *r = json_object();
    json_object_set_new(r, "quantity", json_string(quantity));
    json_object_set_new(r, "symbol", json_string(symbol));
    json_object_set_new(r, "value", photon && !measured ? json_string("not measured") : model_json_number(value));
    json_object_set_new(r, "unit", json_string(unit));
    if (section) {
        json_object_set_new(r, "section", json_string(section));
        json_object_set_new(r, "section_title", json_string(title));
    }
    if (variance && value < 0) json_object_set_new(r, "negative_estimate", json_true());
    json_object_set_new(r, "definition", json_string(definition));
    json_array_append_new(rows, r);
}

// The photon-transfer rows (K, eta, R, dark noise, threshold, saturation, SNR_max, DR).
static void ptc_rows(json_t *r, const calib_gain_opts_t *o, const calib_gain_an_t *a)
{
    const calib_gain_emva_t *e = &a->emva;
    const bool ms = e->photons;
    char fit[256];
    snprintf(fit, sizeof fit, "the steps from the first to the last with mu_y - mu_y.dark <= 70 %% of its value at "
             "saturation (%d steps)", e->n_fit);
    char def[768];
    snprintf(def, sizeof def, "slope through the origin of sigma^2_y - sigma^2_y.dark against mu_y - mu_y.dark "
             "(least squares, sum xy / sum x^2) over %s; each step's dark the dark pair at its exposure", fit);
    row(r, "system gain", "K", e->K, "DN/e-", S_NOISE, T_NOISE, false, true, false, def);
    row(r, "inverse system gain", "1/K", e->inv_K, "e-/DN", S_NOISE, T_NOISE, false, true, false, "1 / K");
    snprintf(def, sizeof def, "slope through the origin of mu_y - mu_y.dark against mu_p over %s", fit);
    row(r, "responsivity", "R", e->R, "DN/photon", S_SIGNAL, T_SIGNAL, true, ms, false, def);
    row(r, "quantum efficiency", "eta", 100 * e->qe, "%", S_SIGNAL, T_SIGNAL, true, ms, false, "eta = R / K");
    row(r, "temporal dark noise", "sigma_d", e->sigma_d_e, "e-", S_NOISE, T_NOISE, false, true, false,
        "sqrt(sigma^2_y.dark - q^2/12) / K; sigma^2_y.dark the intercept at exposure 0 of the least-squares line "
        "of the dark variances against exposure (with two exposures or fewer: the shortest one's), at least "
        "0.24 q^2 (q the quantisation step, 1 DN at the data's own bit depth)");
    row(r, "temporal dark noise", "sigma_y.dark", e->sigma_y_dark_dn, "DN", S_NOISE, T_NOISE, false, true, false,
        "sqrt(sigma^2_y.dark), quantisation noise included");
    row(r, "absolute sensitivity threshold", "mu_e.min", e->mu_e_min, "e-", S_SAT, T_SAT, false, true, false,
        "sigma_y.dark / K + 1/2 (the reference implementation's; refl_rows has the exact SNR = 1 root)");
    row(r, "absolute sensitivity threshold", "mu_p.min", e->mu_p_min, "photons", S_SAT, T_SAT, true, ms, false,
        "mu_e.min / eta");
    row(r, "saturation capacity", "mu_p.sat", e->mu_p_sat, "photons", S_SAT, T_SAT, true, ms, false,
        "mu_p at the saturation step: the maximum of sigma^2_y, walking from the brightest step back until the "
        "variance falls on both sides (the largest sigma^2_y where the walk ends on a plateau below half of it)");
    row(r, "saturation capacity", "mu_e.sat", e->mu_e_sat, "e-", S_SAT, T_SAT, false, true, false,
        ms ? "eta mu_p.sat" : "eta mu_p.sat = R' t_sat / K, R' the slope through the origin of mu_y - mu_y.dark "
             "against exposure over the same steps (mu_p proportional to the exposure: constant irradiance)");
    bool area = isfinite(o->pixel_area_um2) && o->pixel_area_um2 > 0;
    if (area) {
        const double A = o->pixel_area_um2;
        row(r, "absolute sensitivity threshold per area", "mu_p.min.area", e->mu_p_min / A, "photons/um^2", S_SAT,
            T_SAT, true, ms, false, "mu_p.min / A (A the pixel area, --pixel-area-um2)");
        row(r, "absolute sensitivity threshold per area", "mu_e.min.area", e->mu_e_min / A, "e-/um^2", S_SAT, T_SAT,
            false, true, false, "mu_e.min / A");
        row(r, "saturation capacity per area", "mu_p.sat.area", e->mu_p_sat / A, "photons/um^2", S_SAT, T_SAT, true,
            ms, false, "mu_p.sat / A");
        row(r, "saturation capacity per area", "mu_e.sat.area", e->mu_e_sat / A, "e-/um^2", S_SAT, T_SAT, false,
            true, false, "mu_e.sat / A");
    }
    row(r, "maximum SNR", "SNR_max", e->snr_max, "1", S_SNR, T_SNR, false, true, false, "sqrt(mu_e.sat)");
    row(r, "maximum SNR", "SNR_max", 20 * log10(e->snr_max), "dB", S_SNR, T_SNR, false, true, false,
        "20 log10 SNR_max");
    row(r, "maximum SNR", "SNR_max", log2(e->snr_max), "bit", S_SNR, T_SNR, false, true, false, "log2 SNR_max");
    row(r, "inverse maximum SNR", "1/SNR_max", 100 / e->snr_max, "%", S_SNR, T_SNR, false, true, false,
        "100 / SNR_max");
    row(r, "dynamic range", "DR", e->dr, "1", S_SAT, T_SAT, false, true, false,
        "mu_p.sat / mu_p.min (= mu_e.sat / mu_e.min)");
    row(r, "dynamic range", "DR", 20 * log10(e->dr), "dB", S_SAT, T_SAT, false, true, false, "20 log10 DR");
}

// Linearity and dark current.
static void lin_dark_rows(json_t *r, const calib_gain_an_t *a)
{
    const calib_gain_emva_t *e = &a->emva;
    static const char lin[] = "the line a mu_p + b (exposure standing in for mu_p: constant irradiance) through the "
                              "steps from the first with mu_y - mu_y.dark >= 5 % of its value at saturation to the "
                              "last with <= 95 %, minimising sum((Y - a mu_p - b) / Y)^2 (Y = mu_y - mu_y.dark); "
                              "delta = 100 (Y - line) / line";
    row(r, "linearity error", "LE", e->le_pct, "%", S_LIN, T_LIN, false, true, false, "(LE_max - LE_min) / 2");
    row(r, "linearity error (minimum)", "LE_min", e->le_min_pct, "%", S_LIN, T_LIN, false, true, false, lin);
    row(r, "linearity error (maximum)", "LE_max", e->le_max_pct, "%", S_LIN, T_LIN, false, true, false, lin);
    char def[512];
    snprintf(def, sizeof def, "slope of the least-squares line of mu_y.dark against exposure / K, over the %d "
             "temporal dark exposures (the sweep's dark pairs and the dark set's); null with two or fewer", e->n_dark);
    row(r, "dark current (from the mean)", "mu_I.mean", e->dark_current_e_per_s, "e-/s", S_DARK, T_DARK, false, true,
        false, def);
    row(r, "dark current (from the variance)", "mu_I.var", e->dark_current_var_e_per_s, "e-/s", S_DARK, T_DARK,
        false, true, false, "slope of the least-squares line of sigma^2_y.dark against exposure / K^2, the same "
        "exposures; null with two or fewer or a negative slope");
}

// DSNU1288 and PRNU1288 with their parts.
static void nonuniformity_rows(json_t *r, const calib_gain_an_t *a, const calib_gain_maps_t *m)
{
    const calib_gain_nonuni_t *nu = &m->nu;
    const double K = a->emva.K;
    static const char *const parts[4] = { "total", "row", "column", "pixel" };
    static const char *const how[4] = {
        "s^2_y = s^2_y.measured - sigma^2_y.stack / L (the averaged stack's spatial variance less its temporal part)",
        "s^2_y.row = (MN - N) / D s^2_y.rav - M / D (s^2_y - s^2_y.cav)",
        "s^2_y.col = (MN - M) / D s^2_y.cav - N / D (s^2_y - s^2_y.rav)",
        "s^2_y.pixel = MN / D (s^2_y - s^2_y.cav - s^2_y.rav)" };
    for (int k = 0; k < 4; k++) {
        char q[64], sym[32], def[768];
        snprintf(q, sizeof q, "DSNU (%s)", parts[k]);
        snprintf(sym, sizeof sym, k ? "DSNU1288.%s" : "DSNU1288", k == 2 ? "col" : parts[k]);
        snprintf(def, sizeof def, "sqrt(s^2_y.dark%s) / K of the averaged dark stack (%d frames); %s; D = MN - M - N "
                 "(M rows, N columns); the parts' variances add up to the total's; a negative variance estimate "
                 "gives -sqrt(-s^2)", k ? (k == 1 ? ".row" : k == 2 ? ".col" : ".pixel") : "", nu->dark.L, how[k]);
        row(r, q, sym, nu->dsnu_dn[k] / K, "e-", S_NU, T_NU, false, true, true, def);
        row(r, q, sym, nu->dsnu_dn[k], "DN", S_NU, T_NU, false, true, true, "the same in DN (times K)");
    }
    for (int k = 0; k < 4; k++) {
        char q[64], sym[32], def[512];
        snprintf(q, sizeof q, "PRNU (%s)", parts[k]);
        snprintf(sym, sizeof sym, k ? "PRNU1288.%s" : "PRNU1288", k == 2 ? "col" : parts[k]);
        snprintf(def, sizeof def, "100 sqrt(s^2_y%s - s^2_y.dark%s) / (mu_y - mu_y.dark) of the averaged light and "
                 "dark stacks (%d, %d frames; raw, vignetting and illumination included), the same variances as "
                 "DSNU's; a negative difference d gives -sqrt(-d)", k ? (k == 1 ? ".row" : k == 2 ? ".col" : ".pixel")
                 : "", k ? (k == 1 ? ".row" : k == 2 ? ".col" : ".pixel") : "", nu->light.L, nu->dark.L);
        row(r, q, sym, nu->prnu_pct[k], "%", S_NU, T_NU, false, true, true, def);
    }
}

json_t *gain_datasheet_rows(const calib_gain_opts_t *o, const calib_gain_an_t *a, const calib_gain_maps_t *m)
{
    json_t *r = json_array();
    ptc_rows(r, o, a);
    lin_dark_rows(r, a);
    nonuniformity_rows(r, a, m);
    return r;
}

json_t *gain_refl_rows(const calib_gain_an_t *a, const calib_gain_maps_t *m)
{
    json_t *r = json_array();
    const calib_gain_ptc_t *p = &a->ptc;
    const double K0 = p->system_gain_dn_per_e;
    row(r, "small-signal system gain", "K_0", K0, "DN/e-", NULL, NULL, false, true, false,
        "refl's: the slope at zero signal of a quadratic least-squares fit of sigma^2_y - sigma^2_y.dark against "
        "mu_y - mu_y.dark over 0..70 % of saturation (free of a compressive non-linearity's bias; gain.json's "
        "top-level system_gain_dn_per_e, what refl's measurements use)");
    row(r, "read noise (small-signal K)", "sigma_d,0", p->read_noise_e, "e-", NULL, NULL, false, true, false,
        "refl's: sqrt(sigma^2_y.dark - q^2/12) / K_0, sigma^2_y.dark of every dark group at exposure 0");
    row(r, "saturation capacity (small-signal K)", "mu_e.sat,0", p->saturation_capacity_e, "e-", NULL, NULL, false,
        true, false, "refl's: the signal where the variance peaks / K_0");
    row(r, "SNR, largest measured", "SNR_meas", p->snr_max, "1", NULL, NULL, false, true, false,
        "refl's: the largest (mu_y - mu_y.dark) / sigma_y of the steps up to saturation");
    row(r, "absolute sensitivity threshold, exact", "mu_e.min,exact", a->snr_exact_mu_e_min, "e-", NULL, NULL, false,
        true, false, "refl's: the root of SNR = 1 of the linear model, 1/2 + sqrt(sigma_y.dark^2 / K^2 + 1/4), "
        "with the standard's K and sigma_y.dark");
    row(r, "linearity error (Release 3)", "LE_R3", p->linearity_error_r3_pct, "%", NULL, NULL, false, true, false,
        "refl's comparison: Release 3's unweighted least-squares line against exposure, 5..95 % of saturation");
    row(r, "linearity error, linearised", "LE_lin", a->le_linearised_pct, "%", NULL, NULL, false, true, false,
        "refl's: the Release 4.0 LE of the sweep's signal through refl's response linearisation (the table)");
    row(r, "PRNU, linearised and high-pass", "PRNU_hp", m->prnu_pct, "%", NULL, NULL, false, true, false,
        "refl's: the flat's linearised signal divided by its quadratic smooth surface (vignetting removed), "
        "temporal noise subtracted (gain.json prnu_pct)");
    const calib_gain_split_t *hp = &m->sp.prnu_hp;
    const double hv[3] = { hp->row, hp->col, hp->pixel };
    static const char *const part[3] = { "row", "column", "pixel" };
    for (int k = 0; k < 3; k++) {
        char q[64], sym[32];
        snprintf(q, sizeof q, "PRNU high-pass (%s)", part[k]);
        snprintf(sym, sizeof sym, "PRNU_hp.%s", part[k]);
        row(r, q, sym, hv[k], "%", NULL, NULL, false, true, true, "refl's: the row/column/pixel split of the "
            "high-pass map (calib_gain_spatial_split; signed roots)");
    }
    row(r, "DSNU (pair variance)", "DSNU_0", m->dsnu_dn, "DN", NULL, NULL, false, true, false,
        "refl's: the averaged dark's spatial std, the pair variance / L subtracted (gain.json dsnu_dn)");
    const calib_gain_defects_t *df = &m->sp.defects;
    row(r, "hot pixels", "n_hot", df->hot, "pixels", NULL, NULL, false, true, false, "refl's threshold: averaged dark "
        "above its median by more than nsigma robust stds");
    row(r, "dead pixels", "n_dead", df->dead, "pixels", NULL, NULL, false, true, false, "refl's threshold: high-pass "
        "flat below its median by more than the threshold");
    row(r, "bright pixels", "n_bright", df->bright, "pixels", NULL, NULL, false, true, false, "refl's threshold: "
        "high-pass flat above its median by more than the threshold");
    return r;
}
