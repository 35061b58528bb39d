// calib/gain/report.c — report.html of a gain calibration: the summary
// table and the plots (scripts/calib_gain_report.py) (calib/gain/gain.h).
#include <glib.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "calib/gain/internal.h"
#include "model/model.h"
#include "model/base/report.h"

// report.html: the summary table's rows (g_free each), returns their count (at most max).
static int summary_rows(const calib_gain_an_t *an, int ngains, const calib_gain_maps_t *maps, char **rows, int max)
{
    const calib_gain_an_t *a = &an[0];
    const double K = a->ptc.system_gain_dn_per_e;
    int nr = 0;
    rows[nr++] = g_strdup_printf("system gain K|%.5g DN/e-|small-signal; straight-line fit %.5g", K,
                                 a->ptc.system_gain_linear_dn_per_e);
    rows[nr++] = g_strdup_printf("read noise|%.4g e- (%.4g DN)|", a->ptc.read_noise_e, a->ptc.read_noise_dn);
    rows[nr++] = g_strdup_printf("saturation|%.1f DN above dark (%.0f e-)|at %.6g us", a->ptc.saturation_dn,
                                 a->ptc.saturation_capacity_e, a->t[a->ptc.i_sat]);
    const calib_gain_photon_t *ph = &a->ph;
    if (ph->measured)
        rows[nr++] = g_strdup_printf("quantum efficiency|%.2f %%|responsivity R %.5g DN/photon at %.6g nm, %.6g "
                                     "uW/cm^2, pixel %.6g um^2", 100 * ph->qe, ph->responsivity_dn_per_photon,
                                     ph->wavelength_nm, ph->irradiance_uw_cm2, ph->pixel_area_um2);
    else
        rows[nr++] = g_strdup("quantum efficiency|not measured|give --irradiance, --pixel-area-um2 (or "
                              "--pixel-pitch-um) and --wavelength-nm");
    char pmin[64] = "not measured", psat[64] = "not measured";
    if (ph->measured) {
        snprintf(pmin, sizeof pmin, "%.4g photons", ph->mu_p_min);
        snprintf(psat, sizeof psat, "%.6g photons", ph->mu_p_sat);
    }
    rows[nr++] = g_strdup_printf("absolute sensitivity threshold|%.4g e- (%s)|SNR = 1 of the linear model",
                                 ph->mu_e_min, pmin);
    rows[nr++] = g_strdup_printf("saturation capacity|%.6g e- (%s)|EMVA 1288 R4 dynamic range %.0f (%.1f dB)",
                                 ph->mu_e_sat, psat, ph->dynamic_range, 20 * log10(ph->dynamic_range));
    rows[nr++] = g_strdup_printf("DSNU row / column / pixel|%.3g / %.3g / %.3g DN|total %.3g DN (averaged dark)",
                                 maps->sp.dsnu.row, maps->sp.dsnu.col, maps->sp.dsnu.pixel, maps->sp.dsnu.total);
    rows[nr++] = g_strdup_printf("PRNU row / column / pixel|%.3g / %.3g / %.3g %%|total %.3g %% (flat minus dark, "
                                 "vignetting included)", maps->sp.prnu.row, maps->sp.prnu.col, maps->sp.prnu.pixel,
                                 maps->sp.prnu.total);
    rows[nr++] = g_strdup_printf("defect pixels|hot %d, dead %d, bright %d|beyond %g robust standard deviations",
                                 maps->sp.defects.hot, maps->sp.defects.dead, maps->sp.defects.bright,
                                 maps->sp.defects.nsigma);
    rows[nr++] = g_strdup_printf("linearity error|%.3f %%|EMVA 1288 Release 4.0, 5..95 %% of saturation (Release 3's "
                                 "unweighted line: %.3f %%)", a->ptc.linearity_error_pct, a->ptc.linearity_error_r3_pct);
    rows[nr++] = g_strdup_printf("response linearisation|%s|LE after it %.3g %% (S(1 - aS), a = %.3g per DN: %.3g %%)",
                                 a->lin.kind == MODEL_LIN_MONOTONE ? "monotone table" : "none made",
                                 a->le_linearised_pct, a->lin_a_per_dn, a->le_linearised_param_pct);
    rows[nr++] = g_strdup_printf("SNR max|%.1f (%.1f dB)|", a->ptc.snr_max, 20 * log10(a->ptc.snr_max));
    rows[nr++] = g_strdup_printf("dynamic range|%.0f (%.1f dB)|", a->ptc.dynamic_range,
                                 20 * log10(a->ptc.dynamic_range));
    rows[nr++] = g_strdup_printf("dark current|%.3g e-/s (%.3g DN/s)|from the mean; from the variance %.3g e-/s; "
                                 "dark frames from %.6g us to %.6g us", a->dark_slope_dn_per_us * 1e6 / K,
                                 a->dark_slope_dn_per_us * 1e6, a->dark_var_slope_dn2_per_us * 1e6 / (K * K),
                                 a->dark_t_min_us, a->dark_t_max_us);
    rows[nr++] = g_strdup_printf("DSNU|%.3f DN (%.2f e-)|", maps->dsnu_dn, maps->dsnu_dn / K);
    rows[nr++] = g_strdup_printf("PRNU (high-pass)|%.3f %%|smooth part (vignetting) removed", maps->prnu_pct);
    rows[nr++] = g_strdup_printf("flat-field non-uniformity (total)|%.3f %%|vignetting included",
                                 maps->prnu_total_pct);
    for (int i = 0; i < ngains && nr < max; i++)
        rows[nr++] = g_strdup_printf("gain %g dB|K %.5g DN/e-, read noise %.4g e-, sat %.0f DN, LE %.3f %%|"
                                     "response %.5g DN/us, kc %.4g per us (small-signal %.4g)", an[i].gain_db,
                                     an[i].ptc.system_gain_dn_per_e, an[i].ptc.read_noise_e, an[i].ptc.saturation_dn,
                                     an[i].ptc.linearity_error_pct, an[i].ptc.response_dn_per_us, an[i].kc_per_us,
                                     an[i].kc0_per_us);
    return nr;
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
    model_html_heading(f, "Summary");
    char *rows[32];
    int nr = summary_rows(an, ngains, maps, rows, 32);
    model_html_table(f, "figure|value|notes", (const char *const *)rows, nr);
    for (int i = 0; i < nr; i++) g_free(rows[i]);
    model_html_para(f, "Flat field: %d light frames at %.6g us (%.0f DN above dark, %.0f %% of saturation) and %d "
                    "dark frames at %.6g us. Definitions: see \"conventions\" in gain.json.", maps->flat_frames,
                    maps->flat_exposure_us, maps->flat_level_dn, 100 * maps->flat_level_dn / a->ptc.saturation_dn,
                    maps->dark_frames, maps->dark_exposure_us);
    fprintf(f, "<p><b><a href=\"datasheet.html\">EMVA 1288 Release 4.0 Linear summary datasheet</a></b> "
            "(gain.json \"emva1288\": every figure with its definition)</p>\n");
    model_html_heading(f, "Photon transfer");
    model_html_figure(f, "ptc.png", "temporal variance against signal (dark subtracted), with the K fit");
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
    model_html_para(f, "DSNU total %.3g DN: row %.3g, column %.3g, pixel %.3g DN. PRNU total %.3g %%: row %.3g, column "
                    "%.3g, pixel %.3g %% (of the averaged flat minus dark, vignetting included); of the high-pass flat "
                    "(vignetting removed): row %.3g, column %.3g, pixel %.3g %%.", maps->sp.dsnu.total,
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
