// fit/eval/study_results.c — the detection study's results (study.json
// "results"), from its table alone: per configuration and condition the AUC
// (Mann-Whitney) and the ROC against the correct description's rows, the
// rates at the 1 % false-alarm threshold and of the verdicts, and the z
// calibration. The unsharded run and the merge of its shards compute them the
// same way from the same rows.
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "fit/eval/internal.h"
#include "model/model.h"
#include "model/base/report.h"

// Mann-Whitney AUC: P(pos > neg) + P(pos == neg) / 2 (neg sorted).
static double auc_mw(const double *neg, int nn, const double *pos, int np)
{
    double s = 0;
    for (int i = 0; i < np; i++) {
        int lo = 0, hi = nn;   // first neg >= pos[i]
        while (lo < hi) {
            int m = (lo + hi) / 2;
            if (neg[m] < pos[i]) lo = m + 1;
            else hi = m;
        }
        int lt = lo, le = lo;
        while (le < nn && neg[le] == pos[i]) le++;
        s += lt + 0.5 * (le - lt);
    }
    return s / ((double)np * nn);
}

// The ROC of the rule score >= t over every distinct score, from (0, 0) to (1, 1) (both sorted).
static json_t *roc_json(const double *neg, int nn, const double *pos, int np)
{
    json_t *fa = json_array(), *tp = json_array(), *th = json_array();
    json_array_append_new(fa, json_real(0));
    json_array_append_new(tp, json_real(0));
    json_array_append_new(th, json_null());
    int i = nn, j = np;   // scores >= t: neg[i..], pos[j..]
    while (i > 0 || j > 0) {
        double t = fmax(i > 0 ? neg[i - 1] : -INFINITY, j > 0 ? pos[j - 1] : -INFINITY);
        while (i > 0 && neg[i - 1] >= t) i--;
        while (j > 0 && pos[j - 1] >= t) j--;
        json_array_append_new(fa, json_real((double)(nn - i) / nn));
        json_array_append_new(tp, json_real((double)(np - j) / np));
        json_array_append_new(th, json_real(t));
    }
    json_t *o = json_object();
    json_object_set_new(o, "false_alarm", fa);
    json_object_set_new(o, "detection", tp);
    json_object_set_new(o, "threshold", th);
    return o;
}

// The scores and flags of condition d under configuration k (sorted scores; n rows).
static int cond_scores(const study_table_t *T, int k, int d, double *sc, int *flagged)
{
    int n = 0;
    *flagged = 0;
    for (int c = 0; c < T->cases; c++) {
        size_t i = study_row(T, c, k, d);
        if (T->verdict[i] < 0) continue;
        sc[n++] = T->score[i];
        *flagged += T->verdict[i] == 0;
    }
    qsort(sc, (size_t)n, sizeof *sc, model_cmp_double);
    return n;
}

static json_t *config_summary(const study_table_t *T, int k, double *neg, double *pos, json_t *roc)
{
    int nfl, nn = cond_scores(T, k, 0, neg, &nfl);
    double thr = nn ? neg[nn - 1 - nn / 100] : NAN;
    json_t *rows = json_array();
    for (int d = 1; d < T->ncond; d++) {
        int pfl, np = cond_scores(T, k, d, pos, &pfl);
        if (!np) continue;
        int above = 0;
        for (int i = 0; i < np; i++) above += pos[i] > thr;
        json_t *s = json_object();
        bool placed = !strcmp(T->cond[d].expected, "placed");
        json_object_set_new(s, "config", json_string(T->conf[k]));
        json_object_set_new(s, "description", json_string(T->cond[d].label));
        json_object_set_new(s, "expected", json_string(T->cond[d].expected));
        json_object_set_new(s, "n_correct", json_integer(nn));
        json_object_set_new(s, "n", json_integer(np));
        json_object_set_new(s, "auc", nn ? model_json_number(auc_mw(neg, nn, pos, np)) : json_null());
        json_object_set_new(s, "threshold_1pct", model_json_number(thr));
        json_object_set_new(s, placed ? "flagged_at_1pct_fa" : "det_at_1pct_fa",
                            nn ? json_real((double)above / np) : json_null());
        json_object_set_new(s, placed ? "flagged_verdict" : "det_verdict", json_real((double)pfl / np));
        json_object_set_new(s, "fa_verdict", nn ? json_real((double)nfl / nn) : json_null());
        json_array_append_new(rows, s);
        if (nn) {
            json_t *r = roc_json(neg, nn, pos, np);
            json_object_set_new(r, "config", json_string(T->conf[k]));
            json_object_set_new(r, "description", json_string(T->cond[d].label));
            json_array_append_new(roc, r);
        }
    }
    return rows;
}

// The z calibration: per configuration, over the cases of the correct
// description (and of the part placed off when the study registers), the
// mean and range of each fit's RMS z and median |z| (N(0, 1): 1 and 0.674).
static json_t *z_calibration(const study_table_t *T)
{
    json_t *a = json_array();
    for (int k = 0; k < T->nconf; k++)
        for (int d = 0; d < T->ncond; d++) {
            bool placed = !strcmp(T->cond[d].expected, "placed");
            if (strcmp(T->cond[d].expected, "correct") && !(placed && T->reg)) continue;
            double sr = 0, sm = 0, rlo = INFINITY, rhi = -INFINITY, mlo = INFINITY, mhi = -INFINITY;
            int n = 0;
            for (int c = 0; c < T->cases; c++) {
                size_t i = study_row(T, c, k, d);
                if (T->verdict[i] < 0 || !isfinite(T->rmsz[i]) || !isfinite(T->medz[i])) continue;
                sr += T->rmsz[i], sm += T->medz[i], n++;
                rlo = fmin(rlo, T->rmsz[i]), rhi = fmax(rhi, T->rmsz[i]);
                mlo = fmin(mlo, T->medz[i]), mhi = fmax(mhi, T->medz[i]);
            }
            if (!n) continue;
            json_array_append_new(a, json_pack("{s:s, s:s, s:i, s:f, s:[f,f], s:f, s:[f,f]}", "config", T->conf[k],
                                               "description", T->cond[d].label, "n", n, "rms_z_mean", sr / n,
                                               "rms_z_range", rlo, rhi, "median_abs_z_mean", sm / n,
                                               "median_abs_z_range", mlo, mhi));
        }
    return a;
}

// {"summary": [...], "roc": [...]}: per configuration and condition other than
// the correct description (negatives: the correct description's rows of the
// same configuration).
json_t *study_results(const study_table_t *T)
{
    double *neg = malloc((size_t)(T->cases ? T->cases : 1) * sizeof *neg);
    double *pos = malloc((size_t)(T->cases ? T->cases : 1) * sizeof *pos);
    if (!neg || !pos) {
        free(neg);
        free(pos);
        return NULL;
    }
    json_t *summ = json_array(), *roc = json_array();
    for (int k = 0; k < T->nconf; k++) {
        json_t *rows = config_summary(T, k, neg, pos, roc);
        json_array_extend(summ, rows);
        json_decref(rows);
    }
    free(neg);
    free(pos);
    json_t *o = json_object();
    json_object_set_new(o, "summary", summ);
    json_object_set_new(o, "roc", roc);
    json_object_set_new(o, "z_calibration", z_calibration(T));
    return o;
}
