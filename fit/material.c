// fit/material.c — the material fit (`refl fit material`): calibrated
// observations (calib_observe) to BRDF samples, every model fitted, priors.
#define _GNU_SOURCE
#include <errno.h>
#include <glib.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "calib/calib.h"
#include "fit/material.h"
#include "model/report.h"
#include "model/vec.h"
#include "rig/rig.h"

// ---------------------------------------------------------------------------
// Commands

typedef struct {
    const char *session, *calib, *out, *scene, *material, *model, *name, *report;
    double      albedo, k_sigma, sys_rel, cell_mm;
    int         window, step;   // 0: calib_observe's defaults
    bool        verbose;
} mat_args_t;

static int parse_args(const char *cmd, int argc, char **argv, mat_args_t *a, void (*usage)(FILE *))
{
    for (int i = 1; i < argc; i++) {
        const char *s = argv[i];
        if (!strcmp(s, "-h") || !strcmp(s, "--help")) {
            usage(stdout);
            return 0;
        }
        if (!strcmp(s, "-v") || !strcmp(s, "--verbose")) {
            a->verbose = true;
            continue;
        }
        if (!strcmp(s, "--window") || !strcmp(s, "--step")) {
            char *e = NULL;
            long v = i + 1 < argc ? strtol(argv[i + 1], &e, 10) : 0;
            if (i + 1 >= argc || *e || v < 1 || v > 64) {
                fprintf(stderr, "refl %s: %s needs a whole number of pixels 1..64%s%s%s\n", cmd, s,
                        i + 1 < argc ? ", not '" : "", i + 1 < argc ? argv[i + 1] : "", i + 1 < argc ? "'" : "");
                return 2;
            }
            *(!strcmp(s, "--window") ? &a->window : &a->step) = (int)v;
            i++;
            continue;
        }
        const char **str = !strcmp(s, "-o") ? &a->out : !strcmp(s, "--calib") ? &a->calib
                         : !strcmp(s, "--scene") ? &a->scene : !strcmp(s, "--material") ? &a->material
                         : !strcmp(s, "--model") ? &a->model : !strcmp(s, "--name") ? &a->name
                         : !strcmp(s, "--report") ? &a->report : NULL;
        double *num = !strcmp(s, "--albedo") ? &a->albedo : !strcmp(s, "--k-sigma") ? &a->k_sigma
                    : !strcmp(s, "--systematic") ? &a->sys_rel : !strcmp(s, "--albedo-cells") ? &a->cell_mm : NULL;
        if (str || num) {
            if (i + 1 >= argc) {
                fprintf(stderr, "refl %s: missing value after %s\n", cmd, s);
                return 2;
            }
            const char *v = argv[++i];
            if (str) {
                *str = v;
            } else {
                char *e;
                *num = strtod(v, &e);
                // the systematic floor may be 0 (as refl fit brdf's), and the cells (off);
                // an albedo or K may not
                bool zero_ok = num == &a->sys_rel || num == &a->cell_mm;
                if (*e || !(zero_ok ? *num >= 0 : *num > 0) || !isfinite(*num)) {
                    fprintf(stderr, "refl %s: %s needs a number %s 0, not '%s'\n", cmd, s, zero_ok ? ">=" : ">", v);
                    return 2;
                }
            }
        } else if (s[0] == '-') {
            fprintf(stderr, "refl %s: unknown option %s (refl %s --help)\n", cmd, s, cmd);
            return 2;
        } else if (!a->session) {
            a->session = s;
        } else {
            fprintf(stderr, "refl %s: more than one session: %s\n", cmd, s);
            return 2;
        }
    }
    if (!a->session || !a->calib || !a->out) {
        fprintf(stderr, "refl %s: give SESSION, --calib DIR and -o FILE (refl %s --help)\n", cmd, cmd);
        return 2;
    }
    return -1;
}

// The calibrations of --calib and the observations of the session. false with
// the message printed (cmd names the command).
static bool load_and_observe(const char *cmd, const mat_args_t *a, bool need_white, calib_set_t **cal,
                             calib_obs_set_t *obs)
{
    calib_observe_options_t o = calib_observe_defaults();
    o.scene_path = a->scene;
    o.material = a->material;
    o.verbose = a->verbose;
    if (a->window > 0) o.window = a->window;
    if (a->step > 0) o.step = a->step;
    if (!calib_observe_session(a->session, a->calib, need_white, &o, cal, obs)) {
        fprintf(stderr, "refl %s: %s\n", cmd, model_last_error());
        return false;
    }
    return true;
}

// The report of a material fit: DIR/samples.csv (every sample with its
// geometry, measured and fitted R), plots by scripts/fit_material_report.py,
// and DIR/report.html with the parameter table and the model comparison.
static bool material_report(const char *dir, const calib_obs_set_t *obs, const fit_samples_t *smp,
                            const fit_brdf_result_t *res, int nres, int best, const json_t *entry, const json_t *prov)
{
    if (!model_mkdir_p(dir)) return false;
    char *csv = g_strdup_printf("%s/samples.csv", dir), *html = g_strdup_printf("%s/report.html", dir);
    bool ok = false;
    FILE *f = fopen(csv, "w");
    if (!f) {
        model_error(csv, 0, "cannot write: %s", strerror(errno));
        goto done;
    }
    fprintf(f, "# refl fit material samples: window centre (px), step, lamp, angles (deg: incidence, view, half "
               "vector from the normal), R measured and fitted by %s (1/sr, R = f_r cos theta_i)\n",
            model_brdf_name(res[best].model));
    fprintf(f, "x_px,y_px,step,lamp,theta_i_deg,theta_o_deg,theta_h_deg,R_meas,R_fit\n");
    const double d = 180 / M_PI;
    for (int i = 0; i < smp->n; i++) {
        const model_cosines_t *c = &smp->c[i];
        fprintf(f, "%.1f,%.1f,%d,%d,%.4f,%.4f,%.4f,%.6g,%.6g\n", obs->o[i].q[0], obs->o[i].q[1], obs->o[i].step,
                obs->o[i].lamp, acos(fmin(1, c->nl)) * d, acos(fmin(1, c->nv)) * d, acos(fmin(1, c->nh)) * d,
                smp->R[i], fit_samples_eval(smp, res[best].model, res[best].p, i));
    }
    if (fclose(f) != 0) {
        model_error(csv, 0, "cannot write: %s", strerror(errno));
        goto done;
    }
    char pbuf[256] = "";
    size_t o = 0;
    for (int j = 0; j < res[best].nparams; j++)
        o += (size_t)snprintf(pbuf + o, sizeof pbuf - o, "%s%.6g", j ? "," : "", res[best].p[j]);
    if (model_run_script("fit_material_report.py", dir, model_brdf_name(res[best].model), pbuf, (char *)NULL) != 0)
        goto done;
    FILE *h = model_html_begin(html, "refl fit material", prov);
    if (!h) goto done;
    model_html_para(h, "Material %s of sample %s: %d BRDF samples (windows of %d frames lit by one lamp each). "
                    "Chosen model: %s (lowest BIC). R = f_r cos(theta_i) in 1/sr.",
                    json_string_value(json_object_get(entry, "name")), obs->sample, smp->n, obs->frames_used,
                    model_brdf_name(res[best].model));
    model_html_heading(h, "Parameters");
    json_t *ps = json_object_get(entry, "parameters");
    char **rows = calloc(json_array_size(ps) + 1, sizeof *rows);
    for (size_t j = 0; j < json_array_size(ps); j++) {
        json_t *p = json_array_get(ps, j);
        rows[j] = g_strdup_printf("%s|%s|%.6g|%.3g|%.3g|%.6g .. %.6g|%s|%s", json_string_value(json_object_get(p, "name")),
                                  json_string_value(json_object_get(p, "unit")),
                                  json_number_value(json_object_get(p, "mean")),
                                  json_number_value(json_object_get(p, "std")),
                                  json_number_value(json_object_get(p, "std_statistical")),
                                  json_number_value(json_object_get(p, "lo")),
                                  json_number_value(json_object_get(p, "hi")),
                                  json_string_value(json_object_get(p, "convention")),
                                  json_object_get(p, "held") ? json_string_value(json_object_get(p, "held")) : "");
    }
    model_html_table(h, "parameter|unit|mean|std|std (statistical)|prior bounds|convention|note",
                     (const char *const *)rows, (int)json_array_size(ps));
    for (size_t j = 0; j < json_array_size(ps); j++) g_free(rows[j]);
    free(rows);
    model_html_heading(h, "Measured vs fitted");
    model_html_figure(h, "lobes.png", "R against the half-vector angle, measured (dots, coloured by incidence) "
                      "and fitted (the model at the same geometry), per lamp");
    model_html_figure(h, "residual_maps.png", "residual R_meas - R_fit at each window, for four frames");
    model_html_heading(h, "Model comparison");
    char **mr = calloc((size_t)nres + 1, sizeof *mr);
    for (int k = 0; k < nres; k++) {
        GString *g = g_string_new("");
        g_string_append_printf(g, "%s%s|%.4g|%.4g|%.8g|%.8g|", model_brdf_name(res[k].model), k == best ? " (chosen)" : "",
                               res[k].rms, res[k].rms_fr, res[k].aic, res[k].bic);
        for (int j = 0; j < res[k].nparams; j++)
            g_string_append_printf(g, "%s%s %.4g", j ? ", " : "", model_brdf_param_name(res[k].model, j), res[k].p[j]);
        mr[k] = g_string_free(g, FALSE);
    }
    model_html_table(h, "model|RMS of R (1/sr)|RMS of f_r (1/sr)|AIC|BIC|parameters", (const char *const *)mr, nres);
    for (int k = 0; k < nres; k++) g_free(mr[k]);
    free(mr);
    model_html_figure(h, "models.png", "residuals of the chosen model: histogram, and relative to R against the half-vector angle");
    ok = model_html_end(h, html);
done:
    g_free(csv);
    g_free(html);
    return ok;
}

// ---------------------------------------------------------------------------
// Albedo cells (--albedo-cells MM): a textured material (wood, a painted
// surface) varies its albedo from place to place, which one set of BRDF
// parameters cannot follow. The sample's surface is cut into cells of MM mm
// (by the observations' points at angle 0, which turn with the table, and
// their faces); each cell with at least CELL_MIN_OBS observations gets a
// factor c_j on its whole reflectance (the virtual rig's texture multiplies
// it so), and the fit becomes R_k = c_j(k) R(theta; geometry_k):
//   1. theta from the samples as they are (the model with the lowest BIC);
//   2. c_j = sum R_k f_k / sum f_k^2 over the cell (f = the model's R),
//      then the factors scaled to mean 1 over the observations (so kd & co
//      are the sample's mean);
//   3. theta again from R_k / c_j with weights c_j^2 (the same residuals
//      R_k - c_j f_k); repeat 2-3 until no factor moves by 1e-4 (at most 20).
// Every model is then fitted to the corrected samples. The residual's
// degrees of freedom lose one per cell (rms_over_noise uses N - k - cells).
enum { CELL_MIN_OBS = 4 };

typedef struct {
    int     n_cells, n_obs_in, iterations;
    int    *cell;       // per observation: its cell, -1 when its cell has too few
    double *factor;     // per cell
    double  rel_std;    // std of the factors over the observations (their mean is 1)
} albedo_cells_t;

static void cells_free(albedo_cells_t *ac)
{
    free(ac->cell);
    free(ac->factor);
    memset(ac, 0, sizeof *ac);
}

static bool cells_assign(const calib_obs_set_t *obs, double cell_mm, albedo_cells_t *ac)
{
    memset(ac, 0, sizeof *ac);
    GHashTable *h = g_hash_table_new_full(g_str_hash, g_str_equal, g_free, NULL);
    int *raw = malloc((size_t)(obs->n ? obs->n : 1) * sizeof *raw), nraw = 0;
    ac->cell = malloc((size_t)(obs->n ? obs->n : 1) * sizeof *ac->cell);
    if (!h || !raw || !ac->cell) goto oom;
    for (int i = 0; i < obs->n; i++) {
        const calib_obs_t *o = &obs->o[i];
        char key[96];
        snprintf(key, sizeof key, "%d:%.0f:%.0f:%.0f", o->face, floor(o->p0_mm[0] / cell_mm),
                 floor(o->p0_mm[1] / cell_mm), floor(o->p0_mm[2] / cell_mm));
        gpointer v;
        if (g_hash_table_lookup_extended(h, key, NULL, &v)) {
            raw[i] = GPOINTER_TO_INT(v);
        } else {
            raw[i] = nraw;
            g_hash_table_insert(h, g_strdup(key), GINT_TO_POINTER(nraw));
            nraw++;
        }
    }
    int *count = calloc((size_t)(nraw ? nraw : 1), sizeof *count), *index = malloc((size_t)(nraw ? nraw : 1) * sizeof *index);
    if (!count || !index) {
        free(count);
        free(index);
        goto oom;
    }
    for (int i = 0; i < obs->n; i++) count[raw[i]]++;
    for (int j = 0; j < nraw; j++) index[j] = count[j] >= CELL_MIN_OBS ? ac->n_cells++ : -1;
    for (int i = 0; i < obs->n; i++) {
        ac->cell[i] = index[raw[i]];
        ac->n_obs_in += ac->cell[i] >= 0;
    }
    free(count);
    free(index);
    ac->factor = malloc((size_t)(ac->n_cells ? ac->n_cells : 1) * sizeof *ac->factor);
    if (!ac->factor) goto oom;
    for (int j = 0; j < ac->n_cells; j++) ac->factor[j] = 1;
    free(raw);
    g_hash_table_destroy(h);
    return true;
oom:
    free(raw);
    if (h) g_hash_table_destroy(h);
    cells_free(ac);
    model_error(NULL, 0, "out of memory for the albedo cells");
    return false;
}

// The samples corrected by the cells' factors: R_k / c, weight c^2.
static fit_samples_t *cells_samples(const fit_samples_t *smp, const albedo_cells_t *ac)
{
    fit_samples_t *out = fit_samples_new();
    if (!out) return NULL;
    snprintf(out->source, sizeof out->source, "%s", smp->source);
    for (int i = 0; i < smp->n; i++) {
        double c = ac->cell[i] >= 0 ? ac->factor[ac->cell[i]] : 1;
        const model_cosines_t *disc = smp->disc_at && smp->disc_at[i] >= 0 ? smp->disc + smp->disc_at[i] : NULL;
        if (!fit_samples_add_disc(out, &smp->c[i], disc, smp->R[i] / c, c * c)) {
            fit_samples_free(out);
            model_error(NULL, 0, "sample %d: albedo factor %g gives no usable sample", i, c);
            return NULL;
        }
    }
    return out;
}

// Steps 2-3 above from the fit *r (its model and parameters); *r is updated.
static bool cells_fit(const fit_samples_t *smp, albedo_cells_t *ac, fit_brdf_result_t *r)
{
    double *num = calloc((size_t)(ac->n_cells ? ac->n_cells : 1), sizeof *num);
    double *den = calloc((size_t)(ac->n_cells ? ac->n_cells : 1), sizeof *den);
    bool ok = num && den;
    ac->iterations = 0;
    for (int it = 0; ok && it < 20; it++) {
        ac->iterations = it + 1;   // rounds done (reported)
        memset(num, 0, (size_t)ac->n_cells * sizeof *num);
        memset(den, 0, (size_t)ac->n_cells * sizeof *den);
        for (int i = 0; i < smp->n; i++) {
            int j = ac->cell[i];
            if (j < 0) continue;
            double f = fit_samples_eval(smp, r->model, r->p, i);
            num[j] += smp->R[i] * f;
            den[j] += f * f;
        }
        double sum = 0, moved = 0;
        int n = 0;
        for (int i = 0; i < smp->n; i++) {
            int j = ac->cell[i];
            if (j >= 0 && den[j] > 0) {
                sum += num[j] / den[j];
                n++;
            }
        }
        double mean = n ? sum / n : 1;
        for (int j = 0; j < ac->n_cells; j++) {
            double c = den[j] > 0 && mean > 0 ? num[j] / den[j] / mean : 1;
            if (!(c > 0) || !isfinite(c)) c = 1;
            moved = fmax(moved, fabs(c - ac->factor[j]));
            ac->factor[j] = c;
        }
        fit_samples_t *cs = cells_samples(smp, ac);
        fit_brdf_result_t nr;
        double start[MODEL_BRDF_MAX_PARAMS];
        memcpy(start, r->p, sizeof start);
        ok = cs && fit_brdf_from(cs, r->model, NULL, start, &nr);
        fit_samples_free(cs);
        if (!ok) break;
        // alternating least squares: the residual only falls; stop when it
        // no longer does (or nothing moves)
        double before = r->rss;
        *r = nr;
        if (moved < 1e-4 || (it > 0 && before - nr.rss <= 1e-6 * before)) break;
    }
    if (ok) {
        double s1 = 0, s2 = 0;
        for (int i = 0; i < smp->n; i++)
            if (ac->cell[i] >= 0) {
                double c = ac->factor[ac->cell[i]];
                s1 += c;
                s2 += c * c;
            }
        int n = ac->n_obs_in;
        ac->rel_std = n > 1 ? sqrt(fmax(0.0, (s2 - s1 * s1 / n) / (n - 1))) : 0;
    }
    free(num);
    free(den);
    return ok;
}

// Fit every model of models[] to smp into res (printing a line each); the
// index of the lowest BIC, -1 when none could be fitted.
static int fit_models(const fit_samples_t *smp, const int *models, int nm, fit_brdf_result_t *res, int *nres)
{
    int best = -1;
    *nres = 0;
    for (int k = 0; k < nm; k++) {
        fit_brdf_result_t *r = &res[*nres];
        if (!fit_brdf(smp, (model_brdf_t)models[k], NULL, r)) {
            fprintf(stderr, "  %s: %s\n", model_brdf_name((model_brdf_t)models[k]), model_last_error());
            continue;
        }
        printf("  %-16s rms %.4g 1/sr  BIC %.6g", model_brdf_name(r->model), r->rms, r->bic);
        for (int j = 0; j < r->nparams; j++) printf("  %s %.4g", model_brdf_param_name(r->model, j), r->p[j]);
        printf("\n");
        if (best < 0 || r->bic < res[best].bic) best = *nres;
        (*nres)++;
    }
    return best;
}

static void material_usage(FILE *f)
{
    fprintf(f, "usage: refl fit material SESSION --calib DIR [--model all|lambert|hall|torrance_sparrow|thesis_fit|\n"
               "                         cook_torrance|ggx] [--name NAME] [--scene FILE] [--material NAME]\n"
               "                         [--k-sigma K] [--systematic REL] [--albedo-cells MM] [--window N]\n"
               "                         [--step N] [--report DIR] -o PRIORS.json\n"
               "\n"
               "BRDF samples of the session's sample material: every window of the material lit by one lamp, dark\n"
               "and flat corrected, brackets merged to high dynamic range, scaled by the reference white's kc*I of\n"
               "its lamp (DIR/white.json) with the geometry (DIR/camera.cameramodel) and lamp positions\n"
               "(DIR/lamps.json); then every requested model is fitted (refl fit brdf) and the priors file written.\n"
               "On a virtual rig the sample's scene and material come from the truth file's [sample]; elsewhere\n"
               "give --scene and --material. Each parameter's std adds REL * mean (default 0.03) to the statistical\n"
               "one, for the calibrations' shared errors (on the virtual rig kc*I comes out within ~3 %% and the lamp\n"
               "positions within ~8 mm); the prior bounds are mean +- K std (default 3). --report DIR writes an HTML\n"
               "report there: measured vs fitted lobes, residual maps, the parameters and the model comparison.\n"
               "--albedo-cells MM (textured materials: wood, paint): the sample's surface is cut into cells of MM mm,\n"
               "each with its own albedo factor on the whole reflectance (mean 1 over the observations), fitted\n"
               "together with the parameters; the priors then hold the mean material and the factors' spread.\n"
               "Observations are windows of N x N pixels (--window, default 5) on a grid of N pixels (--step, 8).\n"
               "\nrefl %s\n", REFL_VERSION);
}

int fit_cmd_material(int argc, char **argv)
{
    mat_args_t a = { .k_sigma = 3, .model = "all", .sys_rel = 0.03 };
    int rc = parse_args("fit material", argc, argv, &a, material_usage);
    if (rc >= 0) return rc;
    int models[MODEL_BRDF_COUNT], nm = 0;
    if (!strcmp(a.model, "all")) {
        for (int m = 0; m < MODEL_BRDF_COUNT; m++) models[nm++] = m;
    } else if ((models[0] = model_brdf_from_name(a.model)) >= 0) {
        nm = 1;
    } else {
        fprintf(stderr, "refl fit material: --model: unknown model %s\n", a.model);
        return 2;
    }
    calib_set_t *cal = NULL;
    calib_obs_set_t obs;
    fit_samples_t *smp = NULL, *csmp = NULL;
    albedo_cells_t ac = { 0 };
    rc = 1;
    if (!load_and_observe("fit material", &a, true, &cal, &obs)) goto done;
    smp = fit_samples_new();
    snprintf(smp->source, sizeof smp->source, "%s", a.session);
    for (int i = 0; i < obs.n; i++) {
        const calib_obs_t *b = &obs.o[i];
        if (!fit_samples_add_disc(smp, &b->c, b->has_disc ? b->disc : NULL,
                                  b->s_dn_per_us * b->d_mm * b->d_mm / cal->kcI_per_us[b->lamp], 1)) {
            fprintf(stderr, "refl fit material: observation %d (step %d) gives no usable sample (kc*I of lamp %s "
                    "is %g)\n", i, b->step, cal->lamps->lamps[b->lamp].name, cal->kcI_per_us[b->lamp]);
            goto done;
        }
    }
    printf("refl fit material: %s: %d BRDF samples from %d frames (%d skipped)\n", obs.material, smp->n,
           obs.frames_used, obs.frames_skipped);
    // the residual RMS the sensor's temporal noise alone would give (with a gain calibration)
    double noise_rms = NAN;
    if (cal->gain_dn_per_e > 0) {
        double v2 = 0;
        for (int i = 0; i < obs.n; i++) {
            double sr = obs.o[i].s_std * obs.o[i].d_mm * obs.o[i].d_mm / cal->kcI_per_us[obs.o[i].lamp];
            v2 += sr * sr;
        }
        noise_rms = sqrt(v2 / obs.n);
        printf("  expected residual RMS from the sensor's noise alone: %.4g 1/sr\n", noise_rms);
        printf("  response compression corrected: S_m = S (1 - a S), a = %.4g per DN at 0 dB%s\n", cal->nonlin_a_per_dn,
               cal->nonlin_a_per_dn > 0 ? "" : " (none in the gain calibration)");
    }
    fit_brdf_result_t res[MODEL_BRDF_COUNT];
    int nres = 0, best = fit_models(smp, models, nm, res, &nres);
    if (best < 0) {
        fprintf(stderr, "refl fit material: no model could be fitted\n");
        goto done;
    }
    if (a.cell_mm > 0) {
        fit_brdf_result_t r = res[best];
        if (!cells_assign(&obs, a.cell_mm, &ac) || !cells_fit(smp, &ac, &r) || !(csmp = cells_samples(smp, &ac))) {
            fprintf(stderr, "refl fit material: albedo cells: %s\n", model_last_error());
            goto done;
        }
        printf("  albedo cells of %g mm: %d cells hold %d of %d observations; factors' std %.4f (%d iterations "
               "with %s); every model again:\n", a.cell_mm, ac.n_cells, ac.n_obs_in, obs.n, ac.rel_std,
               ac.iterations, model_brdf_name(r.model));
        if ((best = fit_models(csmp, models, nm, res, &nres)) < 0) {
            fprintf(stderr, "refl fit material: no model could be fitted to the samples with albedo cells\n");
            goto done;
        }
    }
    json_t *top = json_object();
    json_object_set_new(top, "format", json_string("refl priors 1"));
    json_object_set_new(top, "units", json_string("R = f_r cos(theta_i) in 1/sr; parameter units per parameter"));
    json_t *mats = json_array();
    json_t *e = fit_priors_material(a.name ? a.name : obs.material, &res[best], res, nres, a.k_sigma, a.sys_rel);
    json_object_set_new(e, "session", json_string(a.session));
    json_object_set_new(e, "sample", json_string(obs.sample));
    json_object_set_new(e, "noise_rms_expected", isfinite(noise_rms) ? json_real(noise_rms) : json_null());
    // the residual per degree of freedom (the cells' factors take one each)
    double dof = (double)res[best].n - res[best].nfree - ac.n_cells;
    double rms_dof = dof > 0 ? sqrt(res[best].rss / dof) : NAN;
    if (isfinite(noise_rms) && noise_rms > 0 && isfinite(rms_dof)) {
        json_object_set_new(e, "rms_over_noise", json_real(rms_dof / noise_rms));
        printf("  residual per degree of freedom over the noise: %.3f\n", rms_dof / noise_rms);
    }
    if (a.cell_mm > 0) {
        json_t *jc = json_object();
        json_object_set_new(jc, "cell_mm", json_real(a.cell_mm));
        json_object_set_new(jc, "cells", json_integer(ac.n_cells));
        json_object_set_new(jc, "observations_in_cells", json_integer(ac.n_obs_in));
        json_object_set_new(jc, "observations", json_integer(obs.n));
        json_object_set_new(jc, "factor_rel_std", json_real(ac.rel_std));
        json_object_set_new(jc, "iterations", json_integer(ac.iterations));
        json_object_set_new(jc, "convention", json_string(
            "each cell (MM mm of the sample's surface at angle 0, per face) scales the whole reflectance by its "
            "factor; the factors' mean over the observations is 1, so the parameters describe the mean material; "
            "factor_rel_std is the spread of the albedo from place to place"));
        json_object_set_new(e, "albedo_cells", jc);
    }
    json_array_append_new(mats, e);
    json_object_set_new(top, "materials", mats);
    json_object_set_new(top, "provenance", calib_observe_provenance(argc + 1, argv - 1, a.session, cal));
    char *od = g_path_get_dirname(a.out);
    bool made = model_mkdir_p(od);
    g_free(od);
    if (made && model_write_json(a.out, top)) {
        printf("%s: %s, model %s (lowest BIC of %d)\n", a.out, a.name ? a.name : obs.material,
               model_brdf_name(res[best].model), nres);
        rc = 0;
        if (a.report) {
            if (material_report(a.report, &obs, csmp ? csmp : smp, res, nres, best, e,
                                json_object_get(top, "provenance"))) {
                printf("%s/report.html\n", a.report);
            } else {
                fprintf(stderr, "refl fit material: the report: %s\n", model_last_error());
                rc = 1;
            }
        }
    } else {
        fprintf(stderr, "refl fit material: %s\n", model_last_error());
    }
    json_decref(top);
done:
    fit_samples_free(smp);
    fit_samples_free(csmp);
    cells_free(&ac);
    calib_obs_free(&obs);
    calib_set_free(cal);
    return rc;
}
