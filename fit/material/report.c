// fit/material/report.c — the report of a material fit (fit_material_report,
// fit/material/internal.h): DIR/samples.csv (every sample with its geometry,
// lamp, measured and fitted R, noise and albedo cell), DIR/lobes_fit.csv,
// plots by scripts/fit_material_report.py, and DIR/report.html with the
// residual over the noise, the parameter table and the model comparison.
#define _GNU_SOURCE
#include <errno.h>
#include <glib.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fit/material/internal.h"
#include "fit/priors.h"
#include "model/base/report.h"

// DIR/lobes_fit.csv: the chosen model in the plane of incidence, for the report's polar lobes: R at every
// incidence 0..89 deg and view -89..89 deg (negative: the incidence's side), 1 deg apart.
static bool lobes_fit_csv(const char *dir, const fit_brdf_result_t *r)
{
    char *path = g_strdup_printf("%s/lobes_fit.csv", dir);
    FILE *f = fopen(path, "w");
    bool ok = f != NULL;
    if (f) {
        fprintf(f, "theta_i_deg,theta_o_deg,R_fit\n");
        const model_vec3_t n = { 0, 0, 1 };
        for (int ti = 0; ti < 90; ti++)
            for (int to = -89; to <= 89; to++) {
                double a = ti * M_PI / 180, b = to * M_PI / 180;
                model_vec3_t l = { -sin(a), 0, cos(a) }, v = { sin(b), 0, cos(b) };
                model_cosines_t c = model_cosines(n, l, v);
                fprintf(f, "%d,%d,%.6g\n", ti, to, model_brdf_eval(r->model, r->p, &c, NULL));
            }
        ok = fclose(f) == 0;
    }
    if (!ok) model_error_set(path, 0, "cannot write: %s", strerror(errno));
    g_free(path);
    return ok;
}

// DIR/samples.csv: every sample with its geometry, lamp, measured R and R of
// the chosen fit r, noise, albedo factor and point on the sample.
static bool samples_csv(const char *dir, const calib_obs_set_t *obs, const fit_samples_t *smp,
                        const fit_brdf_result_t *r, const calib_set_t *cal, const int *cell, const double *factor)
{
    char *csv = g_strdup_printf("%s/samples.csv", dir);
    FILE *f = fopen(csv, "w");
    if (!f) {
        model_error_set(csv, 0, "cannot write: %s", strerror(errno));
        g_free(csv);
        return false;
    }
    fprintf(f, "# refl fit material samples: window centre (px), step, lamp, angles (deg: incidence, view, half "
               "vector from the normal; phi: azimuth of the view from the incidence's, 180 = the plane of incidence "
               "forward), R measured and fitted by %s (1/sr, R = f_r cos theta_i), sigma_R its expected temporal "
               "noise (0: unknown), the albedo cell's factor (1: none) and the point on the sample at angle 0 "
               "(mm, rig frame)\n",
            model_brdf_name(r->model));
    fprintf(f, "x_px,y_px,step,lamp,theta_i_deg,theta_o_deg,theta_h_deg,R_meas,R_fit,lamp_name,phi_deg,sigma_R,"
               "albedo_factor,x0_mm,y0_mm,z0_mm\n");
    const double d = 180 / M_PI;
    for (int i = 0; i < smp->n; i++) {
        const model_cosines_t *c = &smp->c[i];
        const calib_obs_t *ob = &obs->o[i];
        double ti = acos(fmin(1, c->nl)), to = acos(fmin(1, c->nv)), lv = 2 * c->vh * c->vh - 1;
        double ss = sin(ti) * sin(to), phi = ss > 1e-9 ? acos(fmax(-1, fmin(1, (lv - c->nl * c->nv) / ss))) : 0;
        double sig = ob->s_dn_per_us > 0 ? smp->R[i] * ob->s_std / ob->s_dn_per_us : 0;
        double fac = cell && cell[i] >= 0 ? factor[cell[i]] : 1;
        const char *ln = cal && ob->lamp >= 0 && ob->lamp < cal->lamps->n ? cal->lamps->lamps[ob->lamp].name : "";
        fprintf(f, "%.1f,%.1f,%d,%d,%.4f,%.4f,%.4f,%.6g,%.6g,%s,%.3f,%.4g,%.5g,%.3f,%.3f,%.3f\n", ob->q[0], ob->q[1],
                ob->step, ob->lamp, ti * d, to * d, acos(fmin(1, c->nh)) * d, smp->R[i],
                fit_samples_eval(smp, r->model, r->p, i), ln, phi * d, sig, fac, ob->p0_mm[0],
                ob->p0_mm[1], ob->p0_mm[2]);
    }
    bool ok = fclose(f) == 0;
    if (!ok) model_error_set(csv, 0, "cannot write: %s", strerror(errno));
    g_free(csv);
    return ok;
}

// The plots of scripts/fit_material_report.py from DIR's csv files and the chosen fit r.
static bool report_plots(const char *dir, const fit_brdf_result_t *r)
{
    char pbuf[256] = "";
    size_t o = 0;
    for (int j = 0; j < r->nparams; j++)
        o += (size_t)snprintf(pbuf + o, sizeof pbuf - o, "%s%.6g", j ? "," : "", r->p[j]);
    return model_run_script("fit_material_report.py", dir, model_brdf_name(r->model), pbuf, (char *)NULL) == 0;
}

static void rows_free(char **rows, int n)
{
    for (int j = 0; rows && j < n; j++) g_free(rows[j]);
    free(rows);
}

// The parameter p of a priors entry barely constrained (fit_priors_barely_constrained), and its 1-sigma's shares
// of its value's magnitude and of its bounds' width (NAN where not defined).
static bool param_loose(const json_t *p, double *of_value, double *of_width)
{
    return fit_priors_barely_constrained(json_number_value(json_object_get(p, "mean")),
                                         json_number_value(json_object_get(p, "std")),
                                         json_number_value(json_object_get(p, "lo")),
                                         json_number_value(json_object_get(p, "hi")), of_value, of_width);
}

// x as a percentage ("59 %"), "n/a" where not finite; into buf.
static const char *pct_text(char *buf, size_t n, double x)
{
    if (isfinite(x)) snprintf(buf, n, "%.0f %%", 100 * x);
    else snprintf(buf, n, "n/a");
    return buf;
}

// The parameter table's rows of the priors entry (*n of them). NULL + message (out of memory).
static char **param_rows(const json_t *entry, int *n)
{
    json_t *ps = json_object_get(entry, "parameters");
    *n = (int)json_array_size(ps);
    char **rows = calloc((size_t)*n + 1, sizeof *rows);
    if (!rows) {
        model_error_set(NULL, 0, "out of memory");
        return NULL;
    }
    for (size_t j = 0; j < json_array_size(ps); j++) {
        json_t *p = json_array_get(ps, j);
        double rv, rw;
        bool lz = param_loose(p, &rv, &rw);
        char rel[96], b1[32], b2[32];
        snprintf(rel, sizeof rel, "%s, %s%s", pct_text(b1, sizeof b1, rv), pct_text(b2, sizeof b2, rw),
                 lz ? ": BARELY CONSTRAINED" : "");
        rows[j] = g_strdup_printf("%s|%s|%.6g|%.3g|%s|%.3g|%.6g .. %.6g|%s|%s", json_string_value(json_object_get(p, "name")),
                                  json_string_value(json_object_get(p, "unit")),
                                  json_number_value(json_object_get(p, "mean")),
                                  json_number_value(json_object_get(p, "std")), rel,
                                  json_number_value(json_object_get(p, "std_statistical")),
                                  json_number_value(json_object_get(p, "lo")),
                                  json_number_value(json_object_get(p, "hi")),
                                  json_string_value(json_object_get(p, "convention")),
                                  json_object_get(p, "held") ? json_string_value(json_object_get(p, "held")) : "");
    }
    return rows;
}

// The model comparison's rows: every model fitted (res[nres]), res[best] the chosen. NULL + message.
static char **model_rows(const fit_brdf_result_t *res, int nres, int best)
{
    char **mr = calloc((size_t)nres + 1, sizeof *mr);
    if (!mr) {
        model_error_set(NULL, 0, "out of memory");
        return NULL;
    }
    for (int k = 0; k < nres; k++) {
        GString *g = g_string_new("");
        g_string_append_printf(g, "%s%s|%.4g|%.4g|%.4g|%.4g|%.8g|%.8g|", model_brdf_name(res[k].model),
                               k == best ? " (chosen)" : "", res[k].rms, res[k].cv_rms, res[k].cv_se, res[k].rms_fr,
                               res[k].aic, res[k].bic);
        for (int j = 0; j < res[k].nparams; j++)
            g_string_append_printf(g, "%s%s %.4g", j ? ", " : "", model_brdf_param_name(res[k].model, j), res[k].p[j]);
        mr[k] = g_string_free(g, FALSE);
    }
    return mr;
}

// The page's opening paragraphs: the material and the model chosen, the
// residual against the noise, the albedo cells, weighting and loss.
static void html_summary(FILE *h, const calib_obs_set_t *obs, const fit_samples_t *smp, const fit_brdf_result_t *r,
                         const json_t *entry)
{
    json_t *ch = json_object_get(entry, "model_choice");
    model_html_para(h, "Material %s of sample %s: %d BRDF samples (windows of %d frames lit by one lamp each). "
                    "Chosen model: %s by %s (%s; lowest BIC: %s). R = f_r cos(theta_i) in 1/sr.",
                    json_string_value(json_object_get(entry, "name")), obs->sample, smp->n, obs->frames_used,
                    model_brdf_name(r->model),
                    !strcmp(json_string_value(json_object_get(ch, "criterion")), "cv_rms")
                        ? "the held-out RMS (the fewest parameters within one standard error of the lowest)"
                    : !strcmp(json_string_value(json_object_get(ch, "criterion")), "only_model") ? "--model"
                                                                                                 : "the lowest BIC",
                    json_string_value(json_object_get(ch, "note")),
                    json_string_value(json_object_get(ch, "lowest_bic")));
    json_t *ron = json_object_get(entry, "rms_over_noise"), *cj = json_object_get(entry, "albedo_cells");
    if (ron)
        model_html_para(h, "Residual: RMS of R %.4g 1/sr; over the sensor's temporal noise %.3g (rms_over_noise: "
                        "sqrt(chi^2/dof) with each sample weighted by its noise; near 1: the model explains the data "
                        "down to the noise; the noise alone gives an RMS of %.4g 1/sr).",
                        json_number_value(json_object_get(entry, "rms")), json_number_value(ron),
                        json_number_value(json_object_get(entry, "noise_rms_expected")));
    else
        model_html_para(h, "Residual: RMS of R %.4g 1/sr (no gain calibration: the noise it would be compared with "
                        "is unknown).", json_number_value(json_object_get(entry, "rms")));
    if (cj)
        model_html_para(h, "Albedo cells of %.3g mm: %lld cells hold %lld of %lld observations; the albedo's spread "
                        "from place to place is %.3g %% (std of the cells' factors, mean 1).",
                        json_number_value(json_object_get(cj, "cell_mm")),
                        json_integer_value(json_object_get(cj, "cells")),
                        json_integer_value(json_object_get(cj, "observations_in_cells")),
                        json_integer_value(json_object_get(cj, "observations")),
                        100 * json_number_value(json_object_get(cj, "factor_rel_std")));
    model_html_para(h, "Weighting: %s. Loss: %s.", json_string_value(json_object_get(entry, "weighting")),
                    json_string_value(json_object_get(entry, "loss")));
}

// The page's headline: the material and its model, the residual against the noise, every parameter with its
// 1-sigma, the barely constrained ones as misses.
static void html_headline(FILE *h, const fit_brdf_result_t *r, const json_t *entry)
{
    json_t *ps = json_object_get(entry, "parameters"), *ron = json_object_get(entry, "rms_over_noise");
    size_t np = json_array_size(ps);
    char **it = calloc(np + 3, sizeof *it);
    if (!it) return;   // the page goes on without it (the tables follow)
    int n = 0;
    it[n++] = ron ? g_strdup_printf("%s: model %s, RMS of R %.4g 1/sr = %.3g × the sensor's noise",
                                    json_string_value(json_object_get(entry, "name")), model_brdf_name(r->model),
                                    json_number_value(json_object_get(entry, "rms")), json_number_value(ron))
                  : g_strdup_printf("%s: model %s, RMS of R %.4g 1/sr (the noise is unknown without a gain "
                                    "calibration)", json_string_value(json_object_get(entry, "name")),
                                    model_brdf_name(r->model), json_number_value(json_object_get(entry, "rms")));
    GString *g = g_string_new("parameters (mean ± 1-sigma): ");
    int nloose = 0;
    for (size_t j = 0; j < np; j++) {
        json_t *p = json_array_get(ps, j);
        double rv, rw;
        nloose += param_loose(p, &rv, &rw);
        g_string_append_printf(g, "%s%s = %.4g ± %.2g %s", j ? "; " : "", json_string_value(json_object_get(p, "name")),
                               json_number_value(json_object_get(p, "mean")),
                               json_number_value(json_object_get(p, "std")),
                               json_string_value(json_object_get(p, "unit")));
    }
    it[n++] = g_string_free(g, FALSE);
    for (size_t j = 0; j < np; j++) {
        json_t *p = json_array_get(ps, j);
        double rv, rw;
        char b1[32], b2[32];
        if (param_loose(p, &rv, &rw))
            it[n++] = g_strdup_printf("!%s barely constrained: %.4g ± %.2g, the 1-sigma %s of the value, %s of the "
                                      "bounds' width %.4g .. %.4g", json_string_value(json_object_get(p, "name")),
                                      json_number_value(json_object_get(p, "mean")),
                                      json_number_value(json_object_get(p, "std")), pct_text(b1, sizeof b1, rv),
                                      pct_text(b2, sizeof b2, rw),
                                      json_number_value(json_object_get(p, "lo")),
                                      json_number_value(json_object_get(p, "hi")));
    }
    if (!nloose) it[n++] = g_strdup_printf("no parameter barely constrained (%s)", FIT_PRIORS_LOOSE_RULE);
    model_html_headline(h, "Headline", (const char *const *)it, n);
    for (int k = 0; k < n; k++) g_free(it[k]);
    free(it);
}

// The figures of measured against fitted R (and the albedo cells' with cells).
static void html_fit_figures(FILE *h, bool cells)
{
    model_html_heading(h, "Measured vs fitted");
    model_html_figure(h, "polar.png", "lobes in the plane of incidence (samples within 15 deg of it), one panel per "
                      "band of incidence: R measured (mean ± its spread, and ± the expected noise "
                      "σ) and fitted, against the view angle (negative: the incidence's side)");
    model_html_figure(h, "lobes.png", "R against the half-vector angle, measured (dots, coloured by incidence) "
                      "and fitted (the model at the same geometry), per lamp");
    model_html_figure(h, "residual_maps.png", "residual R_meas - R_fit at each window, for four frames");
    if (cells) {
        model_html_heading(h, "Albedo cells");
        model_html_figure(h, "albedo_cells.png", "each cell's albedo factor on the sample (the point at angle 0, "
                          "mm in the rig frame), and their histogram");
    }
}

bool fit_material_report(const char *dir, const calib_obs_set_t *obs, const fit_samples_t *smp,
                         const fit_brdf_result_t *res, int nres, int best, const json_t *entry, const json_t *prov,
                         const calib_set_t *cal, const int *cell, const double *factor)
{
    if (!model_mkdir_p(dir) || !samples_csv(dir, obs, smp, &res[best], cal, cell, factor) ||
        !lobes_fit_csv(dir, &res[best]) || !report_plots(dir, &res[best]))
        return false;
    int np = 0;
    char **rows = param_rows(entry, &np), **mr = rows ? model_rows(res, nres, best) : NULL;
    char *html = g_strdup_printf("%s/report.html", dir);
    FILE *h = mr ? model_html_begin(html, "refl fit material", prov) : NULL;
    bool ok = false;
    if (h) {
        html_headline(h, &res[best], entry);
        html_summary(h, obs, smp, &res[best], entry);
        model_html_heading(h, "Parameters");
        model_html_table(h, "parameter|unit|mean|std|std / magnitude of mean, std / bounds' width|std "
                            "(statistical)|prior bounds|convention|note", (const char *const *)rows, np);
        model_html_para(h, "std: the 1-sigma the priors carry; %s (flagged BARELY CONSTRAINED).", FIT_PRIORS_LOOSE_RULE);
        html_fit_figures(h, cell != NULL);
        model_html_heading(h, "Model comparison");
        model_html_table(h, "model|RMS of R (1/sr)|held-out RMS of R (1/sr)|its standard error (1/sr)|RMS of f_r "
                            "(1/sr)|AIC|BIC|parameters", (const char *const *)mr, nres);
        model_html_figure(h, "models.png", "residuals of the chosen model: histogram, and relative to R against the "
                          "half-vector angle");
        ok = model_html_end(h, html);
    }
    rows_free(rows, np);
    rows_free(mr, nres);
    g_free(html);
    return ok;
}
