// calib/gain/report.c — report.html of a gain calibration: the summary
// table and the plots (scripts/calib_gain_report.py) (calib/gain/gain.h).
#include <glib.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "calib/gain/internal.h"
#include "model/model.h"
#include "model/base/report.h"

// report.html: the summary table's rows (g_free each), returns their count
// (at most max): EMVA 1288's figures (the datasheet's), then refl's own.
static int summary_rows(const calib_gain_an_t *an, int ngains, const calib_gain_maps_t *maps, char **rows, int max)
{
    const calib_gain_an_t *a = &an[0];
    const calib_gain_emva_t *e = &a->emva;
    const double K0 = a->ptc.system_gain_dn_per_e;
    const calib_gain_nonuni_t *nu = &maps->nu;
    int nr = 0;
    rows[nr++] = g_strdup_printf("EMVA 1288 system gain K|%.5g DN/e-|photon transfer through the origin, %d steps "
                                 "up to 70 %% of saturation", e->K, e->n_fit);
    rows[nr++] = g_strdup_printf("EMVA 1288 temporal dark noise|%.4g e- (%.4g DN)|sigma_d; sigma_y.dark",
                                 e->sigma_d_e, e->sigma_y_dark_dn);
    rows[nr++] = g_strdup_printf("EMVA 1288 saturation capacity|%.6g e-|at %.6g us (%.1f DN above dark)",
                                 e->mu_e_sat, a->t[e->i_sat], e->mu_y_sat_dn);
    if (e->photons)
        rows[nr++] = g_strdup_printf("EMVA 1288 quantum efficiency|%.2f %%|responsivity %.5g DN/photon (photons: %s)",
                                     100 * e->qe, e->R, a->photon_source);
    else
        rows[nr++] = g_strdup("EMVA 1288 quantum efficiency|not measured|give --irradiance, --pixel-area-um2 (or "
                              "--pixel-pitch-um) and --wavelength-nm, or --emva-descriptor");
    // measured in electrons; in photons only with the photon axis
    char pmin[96] = "; in photons: not measured (no photon axis)";
    if (e->photons) snprintf(pmin, sizeof pmin, " (%.4g photons)", e->mu_p_min);
    rows[nr++] = g_strdup_printf("EMVA 1288 absolute sensitivity threshold|%.4g e-%s|sigma_y.dark / K + 1/2",
                                 e->mu_e_min, pmin);
    rows[nr++] = g_strdup_printf("EMVA 1288 SNR_max, DR|%.1f (%.1f dB), %.0f (%.1f dB)|sqrt(mu_e.sat); "
                                 "mu_p.sat / mu_p.min", e->snr_max, 20 * log10(e->snr_max), e->dr,
                                 20 * log10(e->dr));
    rows[nr++] = g_strdup_printf("EMVA 1288 linearity error|%.3f %%|LE_min %.3f %%, LE_max %.3f %%", e->le_pct,
                                 e->le_min_pct, e->le_max_pct);
    rows[nr++] = g_strdup_printf("EMVA 1288 dark current|%.3g e-/s|from the variance %.3g e-/s (%d exposures)",
                                 e->dark_current_e_per_s, e->dark_current_var_e_per_s, e->n_dark);
    rows[nr++] = g_strdup_printf("EMVA 1288 DSNU1288 total / row / column / pixel|%.3g / %.3g / %.3g / %.3g e-|%d "
                                 "dark frames averaged", nu->dsnu_dn[0] / e->K, nu->dsnu_dn[1] / e->K,
                                 nu->dsnu_dn[2] / e->K, nu->dsnu_dn[3] / e->K, nu->dark.L);
    rows[nr++] = g_strdup_printf("EMVA 1288 PRNU1288 total / row / column / pixel|%.3g / %.3g / %.3g / %.3g %%|%d "
                                 "light frames averaged, vignetting included", nu->prnu_pct[0], nu->prnu_pct[1],
                                 nu->prnu_pct[2], nu->prnu_pct[3], nu->light.L);
    rows[nr++] = g_strdup_printf("refl's small-signal K|%.5g DN/e-|quadratic fit's slope at zero (what refl's "
                                 "measurements use); straight line with intercept %.5g", K0,
                                 a->ptc.system_gain_linear_dn_per_e);
    rows[nr++] = g_strdup_printf("refl's read noise|%.4g e- (%.4g DN)|with the small-signal K", a->ptc.read_noise_e,
                                 a->ptc.read_noise_dn);
    rows[nr++] = g_strdup_printf("refl's saturation|%.1f DN above dark (%.0f e-)|the variance's largest, small-signal "
                                 "K", a->ptc.saturation_dn, a->ptc.saturation_capacity_e);
    rows[nr++] = g_strdup_printf("defect pixels (refl's thresholds)|hot %d, dead %d, bright %d|beyond %g robust "
                                 "standard deviations", maps->sp.defects.hot, maps->sp.defects.dead,
                                 maps->sp.defects.bright, maps->sp.defects.nsigma);
    rows[nr++] = g_strdup_printf("refl's response linearisation|%s|LE after it %.3g %% (S(1 - aS), a = %.3g per DN: "
                                 "%.3g %%); Release 3's LE before it %.3f %%",
                                 a->lin.kind == MODEL_LIN_MONOTONE ? "monotone table" : "none made",
                                 a->le_linearised_pct, a->lin_a_per_dn, a->le_linearised_param_pct,
                                 a->ptc.linearity_error_r3_pct);
    rows[nr++] = g_strdup_printf("refl's SNR, largest measured|%.1f (%.1f dB)|", a->ptc.snr_max,
                                 20 * log10(a->ptc.snr_max));
    rows[nr++] = g_strdup_printf("refl's dark current|%.3g e-/s (%.3g DN/s)|every dark group, small-signal K; dark "
                                 "frames from %.6g us to %.6g us", a->dark_slope_dn_per_us * 1e6 / K0,
                                 a->dark_slope_dn_per_us * 1e6, a->dark_t_min_us, a->dark_t_max_us);
    rows[nr++] = g_strdup_printf("refl's DSNU|%.3f DN (%.2f e-)|pair variance / L subtracted", maps->dsnu_dn,
                                 maps->dsnu_dn / K0);
    rows[nr++] = g_strdup_printf("refl's PRNU (high-pass)|%.3f %%|linearised, smooth part (vignetting) removed",
                                 maps->prnu_pct);
    rows[nr++] = g_strdup_printf("refl's flat-field non-uniformity (total)|%.3f %%|linearised, vignetting included",
                                 maps->prnu_total_pct);
    for (int i = 0; i < ngains && nr < max; i++)
        rows[nr++] = g_strdup_printf("gain %g dB|EMVA 1288 K %.5g DN/e-, sigma_d %.4g e-, mu_e.sat %.0f e-, LE %.3f "
                                     "%%|refl's K %.5g DN/e-, response %.5g DN/us, kc %.4g per us (small-signal "
                                     "%.4g)", an[i].gain_db, an[i].emva.K, an[i].emva.sigma_d_e, an[i].emva.mu_e_sat,
                                     an[i].emva.le_pct, an[i].ptc.system_gain_dn_per_e, an[i].ptc.response_dn_per_us,
                                     an[i].kc_per_us, an[i].kc0_per_us);
    return nr;
}

// The page's headline (g_free each; returns the count, at most 5): the standard's figures, refl's K0 with its
// 1-sigma, and what was not measured.
static int headline_items(const calib_gain_an_t *a, const calib_gain_maps_t *m, char **it)
{
    const calib_gain_emva_t *e = &a->emva;
    const calib_gain_nonuni_t *nu = &m->nu;
    int n = 0;
    it[n++] = g_strdup_printf("EMVA 1288: K %.5g DN/e-, temporal dark noise %.4g e-, saturation capacity %.6g e-, "
                              "SNR max %.1f dB, linearity error %.3f %%, DSNU1288 %.3g e-, PRNU1288 %.3g %%", e->K,
                              e->sigma_d_e, e->mu_e_sat, 20 * log10(e->snr_max), e->le_pct, nu->dsnu_dn[0] / e->K,
                              nu->prnu_pct[0]);
    it[n++] = g_strdup_printf("refl's small-signal K (what refl's measurements use) %.5g ± %.2g DN/e-, read noise "
                              "%.4g ± %.2g e-", a->ptc.system_gain_dn_per_e, a->ptc.system_gain_std_dn_per_e,
                              a->ptc.read_noise_e, a->read_noise_std_e);
    if (e->photons)
        it[n++] = g_strdup_printf("quantum efficiency %.2f %% (photons: %s)", 100 * e->qe, a->photon_source);
    else
        it[n++] = g_strdup("not measured: the photon axis (quantum efficiency, responsivity, the thresholds in "
                           "photons); give --irradiance, --pixel-area-um2 (or --pixel-pitch-um) and --wavelength-nm, "
                           "or --emva-descriptor. Every figure in e- and DN is measured");
    if (e->photons && e->qe > 1)
        it[n++] = g_strdup("!quantum efficiency above 100 %: check the irradiance, the pixel area and the wavelength");
    return n;
}

bool calib_gain_report(const char *dir, const calib_gain_an_t *an, int ngains, const calib_gain_maps_t *maps,
                       json_t *prov)
{
    char *jp = g_build_filename(dir, "gain.json", NULL);
    model_note("plotting");
    int pr = model_run_script("calib_gain_report.py", jp, dir, NULL);
    g_free(jp);
    if (pr) return false;
    char *hp = g_build_filename(dir, "report.html", NULL);
    FILE *f = model_html_begin(hp, "refl calib gain: camera sensitivity (EMVA 1288 style)", prov);
    if (!f) {
        g_free(hp);
        return false;
    }
    const calib_gain_an_t *a = &an[0];
    char *hl[5];
    int nh = headline_items(a, maps, hl);
    model_html_headline(f, "Headline", (const char *const *)hl, nh);
    for (int i = 0; i < nh; i++) g_free(hl[i]);
    model_html_heading(f, "Summary");
    char *rows[48];
    int nr = summary_rows(an, ngains, maps, rows, 48);
    model_html_table(f, "figure|value|notes", (const char *const *)rows, nr);
    for (int i = 0; i < nr; i++) g_free(rows[i]);
    model_html_para(f, "Flat field: %d light frames at %.6g us (%.0f DN above dark, %.0f %% of saturation) and %d "
                    "dark frames at %.6g us. Definitions: see \"conventions\" in gain.json.", maps->flat_frames,
                    maps->flat_exposure_us, maps->flat_level_dn, 100 * maps->flat_level_dn / a->ptc.saturation_dn,
                    maps->dark_frames, maps->dark_exposure_us);
    fprintf(f, "<p><b><a href=\"datasheet.html\">EMVA 1288 Release 4.0 Linear summary datasheet</a></b> "
            "(gain.json \"emva1288\": every figure with its definition)</p>\n");
    model_html_heading(f, "Photon transfer");
    model_html_figure(f, "ptc.png", "temporal variance against signal (dark subtracted), with EMVA 1288's K (the line through the "
                      "origin, solid) and refl's small-signal K0 (dashed)");
    model_html_heading(f, "Linearity");
    model_html_figure(f, "linearity.png", "signal against exposure with the line of EMVA 1288 Release 4.0 (least "
                      "squared relative deviations), and the relative deviation from it (5..95 % of saturation)");
    model_html_figure(f, "linearisation.png", "the response linearisation: linear over measured signal at the "
                      "monotone table's knots, and the parametric S(1 - aS)'s");
    model_html_heading(f, "SNR");
    model_html_figure(f, "snr.png", "signal-to-noise ratio against signal, with the ideal shot-noise limit");
    model_html_heading(f, "Response (kc) per gain");
    model_html_figure(f, "kc.png", "signal per unit radiance against exposure at each gain");
    model_html_heading(f, "PRNU");
    model_html_figure(f, "prnu_map.png", "relative sensitivity: total (incl. vignetting) and high-pass");
    model_html_figure(f, "prnu_hist.png", "histograms of the high-pass PRNU map and of the DSNU map");
    model_html_heading(f, "Dark signal");
    model_html_figure(f, "dark.png", "mean dark level against exposure (dark current) and dark temporal variance, "
                      "with the dark current from each");
    model_html_heading(f, "EMVA 1288: SNR against photons");
    model_html_figure(f, "snr_photons.png", "SNR against photons per pixel (electrons without --irradiance): "
                      "measured, the linear model and the ideal");
    model_html_heading(f, "EMVA 1288: spatial nonuniformity");
    model_html_para(f, "DSNU1288 total %.3g DN: row %.3g, column %.3g, pixel %.3g DN. PRNU1288 total %.3g %%: row "
                    "%.3g, column %.3g, pixel %.3g %% (the standard's, of the averaged light and dark stacks, "
                    "vignetting included; a negative figure is a negative variance estimate); refl's of the "
                    "high-pass flat (vignetting removed): row %.3g, column %.3g, pixel %.3g %%.", maps->sp.dsnu.total,
                    maps->sp.dsnu.row, maps->sp.dsnu.col, maps->sp.dsnu.pixel, maps->sp.prnu.total, maps->sp.prnu.row,
                    maps->sp.prnu.col, maps->sp.prnu.pixel, maps->sp.prnu_hp.row, maps->sp.prnu_hp.col,
                    maps->sp.prnu_hp.pixel);
    model_html_figure(f, "spectrogram_h.png", "horizontal spectrograms (column patterns)");
    model_html_figure(f, "spectrogram_v.png", "vertical spectrograms (row patterns)");
    model_html_figure(f, "profiles.png", "horizontal and vertical profiles");
    model_html_heading(f, "EMVA 1288: defect pixels");
    model_html_para(f, "hot %d, dead %d, bright %d (beyond %g robust standard deviations; defects.tiff)",
                    maps->sp.defects.hot, maps->sp.defects.dead, maps->sp.defects.bright,
                    maps->sp.defects.nsigma);
    model_html_figure(f, "log_histograms.png", "logarithmic histograms with the defect thresholds");
    model_html_figure(f, "defect_map.png", "the defect map");
    bool ok = model_html_end(f, hp);
    g_free(hp);
    return ok;
}
