// fit/brdf/compare.c — several models fitted to the same samples and one chosen,
// by k-fold cross-validation (the one-standard-error rule) or the lowest BIC.
#define _GNU_SOURCE
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fit/brdf/brdf.h"
#include "model/base/vec.h"

bool fit_brdf_model_list(const char *name, model_brdf_t models[MODEL_BRDF_COUNT], int *nmodels)
{
    *nmodels = 0;
    if (!strcmp(name, "all")) {
        for (int m = 0; m < MODEL_BRDF_COUNT; m++) models[(*nmodels)++] = (model_brdf_t)m;
        return true;
    }
    int m = model_brdf_from_name(name);
    if (m < 0) return false;
    models[(*nmodels)++] = (model_brdf_t)m;
    return true;
}

static int cmp_int(const void *a, const void *b)
{
    int x = *(const int *)a, y = *(const int *)b;
    return (x > y) - (x < y);
}

// fold[i] of each sample: its unit (o->cv_unit, else one of 10 k contiguous
// blocks) dealt to k folds in an order shuffled by the seed. The number of
// distinct units, 0 when out of memory.
static int cv_folds_of(const fit_samples_t *s, const fit_brdf_options_t *o, int k, int *fold)
{
    int n = s->n, *u = malloc((size_t)n * sizeof *u), *ids = malloc((size_t)n * sizeof *ids);
    if (!u || !ids) {
        free(u);
        free(ids);
        return 0;
    }
    long nb = 10L * k < n ? 10L * k : n;
    for (int i = 0; i < n; i++) u[i] = o->cv_unit ? o->cv_unit[i] : (int)((long)i * nb / n);
    memcpy(ids, u, (size_t)n * sizeof *ids);
    qsort(ids, (size_t)n, sizeof *ids, cmp_int);
    int nu = 0;
    for (int i = 0; i < n; i++)
        if (i == 0 || ids[i] != ids[nu - 1]) ids[nu++] = ids[i];
    // a seeded Fisher-Yates shuffle of the unit ids; unit at position j goes to fold j % k
    int *pos = malloc((size_t)nu * sizeof *pos);
    model_rng_t rng = model_rng(o->cv_seed, 19);
    for (int j = nu - 1; pos && j > 0; j--) {
        int r = (int)(model_rng_uniform(&rng) * (j + 1));
        if (r > j) r = j;
        int t = ids[j];
        ids[j] = ids[r], ids[r] = t;
    }
    // pos[j]: the shuffled place of sorted unit j (search the shuffled ids by a sorted copy)
    int *sorted = pos ? malloc((size_t)nu * sizeof *sorted) : NULL;
    if (!sorted) {
        free(u), free(ids), free(pos);
        return 0;
    }
    for (int j = 0; j < nu; j++) sorted[j] = ids[j];
    qsort(sorted, (size_t)nu, sizeof *sorted, cmp_int);
    for (int j = 0; j < nu; j++) {
        int *at = bsearch(&ids[j], sorted, (size_t)nu, sizeof *sorted, cmp_int);
        pos[at - sorted] = j;
    }
    for (int i = 0; i < n; i++) {
        int *at = bsearch(&u[i], sorted, (size_t)nu, sizeof *sorted, cmp_int);
        fold[i] = pos[at - sorted] % k;
    }
    free(u), free(ids), free(pos), free(sorted);
    return nu;
}

// The samples with (fold[i] == f) == keep, lamp discs kept.
static fit_samples_t *cv_subset(const fit_samples_t *s, const int *fold, int f, bool keep)
{
    fit_samples_t *t = fit_samples_new();
    if (!t) return NULL;
    snprintf(t->source, sizeof t->source, "%s", s->source);
    t->noise_weighted = s->noise_weighted;
    for (int i = 0; i < s->n; i++) {
        if ((fold[i] == f) != keep) continue;
        const model_cosines_t *disc = s->disc_at && s->disc_at[i] >= 0 ? s->disc + s->disc_at[i] : NULL;
        if (!fit_samples_add_disc(t, &s->c[i], disc, s->R[i], s->w[i])) {
            fit_samples_free(t);
            return NULL;
        }
    }
    return t;
}

// r's cross-validation: refitted from its full fit without each fold, the
// held-out weighted squares summed. false when a fold could not be fitted.
static bool cv_model(const fit_samples_t *s, const int *fold, int k, const fit_brdf_options_t *o,
                     fit_brdf_result_t *r)
{
    double sw = 0, swe = 0, mse[64], sum = 0, sum2 = 0;
    fit_brdf_options_t fo = *o;
    fo.cv_unit = NULL;
    bool ok = true;
    for (int f = 0; f < k && ok; f++) {
        fit_samples_t *train = cv_subset(s, fold, f, false), *test = cv_subset(s, fold, f, true);
        fit_brdf_result_t *fr = malloc(sizeof *fr);
        ok = train && test && fr && test->n > 0 && fit_brdf_from(train, r->model, &fo, r->p, fr);
        double fw = 0, fe = 0, Rb[256];
        for (int i0 = 0; ok && i0 < test->n; i0 += 256) {
            int cnt = test->n - i0 < 256 ? test->n - i0 : 256;
            fit_samples_eval_n(test, r->model, fr->p, i0, cnt, Rb, NULL);
            for (int j = 0; j < cnt; j++) {
                double e = Rb[j] - test->R[i0 + j];
                fw += test->w[i0 + j];
                fe += test->w[i0 + j] * e * e;
            }
        }
        if (ok) {
            sw += fw, swe += fe;
            mse[f] = fe / fw;
            sum += mse[f], sum2 += mse[f] * mse[f];
        }
        free(fr);
        fit_samples_free(train);
        fit_samples_free(test);
    }
    r->cv_rms = ok && sw > 0 ? sqrt(swe / sw) : NAN;
    double var = k > 1 ? fmax(0.0, (sum2 - sum * sum / k) / (k - 1)) : 0;
    // the standard error of the mean square over folds, carried to the RMS
    r->cv_se = ok && r->cv_rms > 0 ? sqrt(var / k) / (2 * r->cv_rms) : NAN;
    return ok && isfinite(r->cv_rms);
}

// Cross-validate every fitted model of out and choose by the one-standard-error rule.
static void cv_choose(const fit_samples_t *s, const fit_brdf_options_t *o, fit_brdf_models_t *out)
{
    int k = o->cv_folds > 64 ? 64 : o->cv_folds;
    out->cv_seed = o->cv_seed;
    snprintf(out->cv_unit_name, sizeof out->cv_unit_name, "%s",
             o->cv_unit ? (o->cv_unit_name ? o->cv_unit_name : "unit") : "block of samples");
    if (out->nres < 2) {
        snprintf(out->cv_note, sizeof out->cv_note, "one model fitted: nothing to choose, no cross-validation");
        return;
    }
    if (k < 2) {
        snprintf(out->cv_note, sizeof out->cv_note, "cross-validation off (folds %d): the lowest BIC", o->cv_folds);
        return;
    }
    int *fold = malloc((size_t)s->n * sizeof *fold);
    int nu = fold ? cv_folds_of(s, o, k, fold) : 0;
    if (nu == 0) {   // (there is a unit when there is a sample)
        model_error_set(s->source, 0, "out of memory for the cross-validation");
        snprintf(out->cv_note, sizeof out->cv_note, "out of memory for the cross-validation; the lowest BIC");
        free(fold);
        return;
    }
    if (nu < 2) {
        snprintf(out->cv_note, sizeof out->cv_note, "%d %s(s): too few to cross-validate; the lowest BIC", nu,
                 out->cv_unit_name);
        free(fold);
        return;
    }
    if (nu < k) k = nu;
    out->cv_folds = k;
    out->cv_units = nu;
    for (int i = 0; i < out->nres; i++) {
        bool q = model_error_quiet_thread(true);
        if (cv_model(s, fold, k, o, &out->res[i]) &&
            (out->best_cv < 0 || out->res[i].cv_rms < out->res[out->best_cv].cv_rms))
            out->best_cv = i;
        model_error_quiet_thread(q);
    }
    free(fold);
    if (out->best_cv < 0) {
        snprintf(out->cv_note, sizeof out->cv_note, "no model could be cross-validated; the lowest BIC");
        return;
    }
    // the simplest model within one standard error of the lowest held-out RMS
    // (and within rounding of it, for noise-free samples)
    const fit_brdf_result_t *b = &out->res[out->best_cv];
    double tol = b->cv_rms + fmax(isfinite(b->cv_se) ? b->cv_se : 0, 1e-9 * b->cv_rms + 1e-15);
    int pick = out->best_cv;
    for (int i = 0; i < out->nres; i++) {
        const fit_brdf_result_t *r = &out->res[i];
        if (!(r->cv_rms <= tol)) continue;
        const fit_brdf_result_t *p = &out->res[pick];
        if (r->nparams < p->nparams || (r->nparams == p->nparams && r->cv_rms < p->cv_rms)) pick = i;
    }
    out->best = pick;
    out->by_cv = true;
    snprintf(out->cv_note, sizeof out->cv_note, "%d-fold cross-validation over %d %ss", k, nu, out->cv_unit_name);
}

bool fit_brdf_models(const fit_samples_t *s, const model_brdf_t *models, int nmodels, const fit_brdf_options_t *opt,
                     fit_brdf_models_t *out)
{
    fit_brdf_options_t o = opt ? *opt : fit_brdf_defaults();
    bool quiet = model_error_quiet_thread(true);   // each model's message goes to out->error
    out->ntried = out->nres = 0;
    out->best = out->best_bic = out->best_cv = -1;
    out->by_cv = false;
    out->cv_folds = out->cv_units = 0;
    out->cv_note[0] = 0;
    for (int k = 0; k < nmodels && k < MODEL_BRDF_COUNT; k++) {
        fit_brdf_result_t *r = &out->res[out->nres];
        double t0 = model_now_s();
        int t = out->ntried++;
        out->tried[t] = models[k];
        out->at[t] = -1;
        out->error[t][0] = 0;
        bool ok = fit_brdf(s, models[k], &o, r);
        out->time_s[t] = model_now_s() - t0;
        if (!ok) {
            snprintf(out->error[t], sizeof out->error[t], "%s", model_last_error());
            continue;
        }
        out->at[t] = out->nres;
        if (out->best_bic < 0 || r->bic < out->res[out->best_bic].bic) out->best_bic = out->nres;
        out->nres++;
    }
    out->best = out->best_bic;
    if (out->best >= 0) cv_choose(s, &o, out);
    if (out->best < 0) model_error_set(NULL, 0, "no model could be fitted");
    model_error_quiet_thread(quiet);
    return out->best >= 0;
}

json_t *fit_brdf_choice_json(const fit_brdf_models_t *m)
{
    json_t *o = json_object();
    json_object_set_new(o, "rule", json_string(
        m->by_cv ? "k-fold cross-validation: each model refitted without each fold of independent units and its "
                   "held-out weighted RMS of R (cv_rms, 1/sr) computed; chosen: the model with the fewest parameters "
                   "whose cv_rms is within one standard error (cv_rms_se) of the lowest"
                 : m->nres < 2 ? "one model fitted (see note)"
                               : "the lowest BIC (cross-validation not done: see note)"));
    json_object_set_new(o, "criterion", json_string(m->by_cv ? "cv_rms" : m->nres < 2 ? "only_model" : "bic"));
    json_object_set_new(o, "note", json_string(m->cv_note));
    json_object_set_new(o, "folds", json_integer(m->cv_folds));
    json_object_set_new(o, "units", json_integer(m->cv_units));
    json_object_set_new(o, "unit", json_string(m->cv_unit_name));
    json_object_set_new(o, "seed", json_integer((json_int_t)m->cv_seed));
    json_object_set_new(o, "cv_rms_unit", json_string("1/sr, of R = f_r cos(theta_i), weighted"));
    json_object_set_new(o, "chosen", m->best >= 0 ? json_string(model_brdf_name(m->res[m->best].model)) : json_null());
    json_object_set_new(o, "lowest_bic",
                        m->best_bic >= 0 ? json_string(model_brdf_name(m->res[m->best_bic].model)) : json_null());
    json_object_set_new(o, "lowest_cv_rms",
                        m->best_cv >= 0 ? json_string(model_brdf_name(m->res[m->best_cv].model)) : json_null());
    return o;
}
