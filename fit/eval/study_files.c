// fit/eval/study_files.c — the detection study's files, the one writer and
// reader of each: study.csv (one row per fit), timing.csv, placement.csv (a
// study that registers) and study.json (units, conditions, design, shard,
// results, timing, provenance); the tables read back for a merge (scores
// written with 17 digits read back to the same doubles).
#define _GNU_SOURCE
#include <glib.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fit/eval/internal.h"
#include "model/model.h"
#include "model/base/report.h"

static const char units[] =
    "score: refl verify's score of the fit (dimensionless, >= 0; higher = more likely wrong; the verdict calls a "
    "description incorrect above score_threshold); rms_z, median_abs_z: over the fit's used reference points, z = "
    "(measured - model) / sigma (for N(0, 1) 1 and 0.674: the stated sigma calibrated); rates: fractions 0..1 of the rows of a configuration and "
    "description; seconds: wall time of one fit on one thread; angles deg, lengths mm";

static const char conditions[] =
    "virtual rig (truth file in design.inputs): T-stiffener, turntable 0/90/180/270 deg, every lamp on, 6000 us, "
    "0 dB, 12-bit sensor with its noise; per case (seeds of the case number only): each lamp's intensity x U(0.9, "
    "1.1), the camera's sensitivity x U(0.95, 1.05), new sensor noise; descriptions: the correct one and 13 "
    "corruptions on the part as placed, and the correct one on the part placed off by 1 mm / 0.5 deg, 2 mm / 1 deg "
    "and 3 mm / 2 deg (shift along 30 deg from x, turn about the part's centre, same drifts, new noise; a truth "
    "with [placement] adds a draw of its own to each placement: design.descriptions[].truth_placement_error; "
    "expected 'placed': a rightly made part, to pass when registration finds it within the tolerance); priors: the chain's (--priors) or the truth's "
    "materials +- 10 %, bounds 3 sigma; no-priors: the thesis's fit (physical bounds only, lamps fixed, kc free); "
    "+maps: the offset map, flat field and linearisation of the gain calibration; calibrations: the chain's "
    "(--calib) or the lab's (the truth's camera, lamps and kc*I, maps measured noise-free)";

// study.csv and timing.csv: the rows run here, configuration by configuration, description by description, case by case.
bool study_write_tables(const char *out, const study_table_t *T)
{
    GString *st = g_string_new("config,description,expected,case,score,verdict_correct,rms_z,median_abs_z\n");
    GString *tm = g_string_new("config,description,case,seconds,iterations\n");
    for (int k = 0; k < T->nconf; k++)
        for (int d = 0; d < T->ncond; d++)
            for (int c = 0; c < T->cases; c++) {
                size_t i = study_row(T, c, k, d);
                if (T->verdict[i] < 0) continue;
                g_string_append_printf(st, "%s,%s,%s,%d,%.17g,%d,%.17g,%.17g\n", T->conf[k], T->cond[d].label,
                                       T->cond[d].expected, c, T->score[i], T->verdict[i], T->rmsz[i], T->medz[i]);
                g_string_append_printf(tm, "%s,%s,%d,%.4f,%d\n", T->conf[k], T->cond[d].label, c, T->secs[i],
                                       T->iters[i]);
            }
    char *sp = g_strdup_printf("%s/study.csv", out), *tp = g_strdup_printf("%s/timing.csv", out);
    bool ok = model_write_file_atomic(sp, st->str) && model_write_file_atomic(tp, tm->str);
    g_free(sp);
    g_free(tp);
    if (ok && T->reg) {
        // each case's registered placement of each description (the same for every configuration)
        GString *pl = g_string_new("description,case,dx_mm,dy_mm,turn_deg,edge_agreement\n");
        for (int d = 0; d < T->ncond; d++)
            for (int c = 0; c < T->cases; c++) {
                const float *q = study_pose(T, c, d);
                if (isfinite(q[3]))
                    g_string_append_printf(pl, "%s,%d,%.9g,%.9g,%.9g,%.9g\n", T->cond[d].label, c, q[0], q[1], q[2],
                                           q[3]);
            }
        char *pp = g_strdup_printf("%s/placement.csv", out);
        ok = model_write_file_atomic(pp, pl->str);
        g_free(pp);
        g_string_free(pl, TRUE);
    }
    g_string_free(st, TRUE);
    g_string_free(tm, TRUE);
    return ok;
}

bool study_table_complete(const study_table_t *T)
{
    size_t n = (size_t)T->cases * T->nconf * T->ncond;
    for (size_t i = 0; i < n; i++)
        if (T->verdict[i] < 0) return false;
    return true;
}

// study.json: units, conditions, design, the shard (when one), the results (when complete), timing, provenance.
bool study_write_json(const char *out, const study_table_t *T, json_t *design, json_t *shard,
                             json_t *provenance)
{
    json_t *doc = json_object();
    model_json_set_format(doc, STUDY_FORMAT, STUDY_FORMAT_VERSION);
    json_object_set_new(doc, "units", json_string(units));
    json_object_set_new(doc, "conditions", json_string(conditions));
    json_object_set(doc, "design", design);
    if (shard) json_object_set(doc, "shard", shard);
    bool complete = study_table_complete(T);
    json_object_set_new(doc, "complete", json_boolean(complete));
    if (complete) {
        json_t *res = study_results(T);
        if (!res) {
            json_decref(doc);
            model_error(NULL, 0, "verify study: out of memory for the summary");
            return false;
        }
        json_object_set_new(doc, "results", res);
    }
    double sum = 0;
    long nf = 0, it = 0;
    for (size_t i = 0; i < (size_t)T->cases * T->nconf * T->ncond; i++)
        if (T->verdict[i] >= 0) sum += T->secs[i], it += T->iters[i], nf++;
    json_object_set_new(doc, "timing", json_pack("{s:I, s:f, s:f}", "fits", (json_int_t)nf, "fit_seconds_sum", sum,
                                                  "mean_iterations", nf ? (double)it / nf : 0.0));
    json_object_set(doc, "provenance", provenance);
    char *jp = g_strdup_printf("%s/study.json", out);
    bool ok = model_write_json(jp, doc);
    g_free(jp);
    json_decref(doc);
    return ok;
}

json_t *study_read_json(const char *path, int *version)
{
    json_error_t je;
    json_t *doc = json_load_file(path, 0, &je);
    if (!doc) {
        model_error(path, je.line, "%s", je.text);
        return NULL;
    }
    if (!model_json_format_check(doc, path, STUDY_FORMAT, STUDY_FORMAT_VERSION, version)) {
        char *msg = g_strdup(model_last_error());
        model_error(NULL, 0, "%s", msg);
        g_free(msg);
        json_decref(doc);
        return NULL;
    }
    return doc;
}

static int find_label(const char *s, const char *base, int n, size_t stride);


// DIR/placement.csv (a study that registers) into the table. false + message naming the file and line.
bool study_read_placement(const char *dir, study_table_t *T)
{
    static const char *h = "description,case,dx_mm,dy_mm,turn_deg,edge_agreement";
    char *path = g_strdup_printf("%s/placement.csv", dir), *text = NULL;
    GError *ge = NULL;
    bool ok = g_file_get_contents(path, &text, NULL, &ge);
    if (!ok) model_error(path, 0, "cannot read: %s (the study registered the placement)", ge->message);
    g_clear_error(&ge);
    char **lines = ok ? g_strsplit(text, "\n", -1) : NULL;
    if (ok && strcmp(lines[0], h)) ok = false, model_error(path, 1, "the header is not '%s'", h);
    for (int ln = 1; ok && lines[ln]; ln++) {
        if (!lines[ln][0] && !lines[ln + 1]) break;
        char **f = g_strsplit(lines[ln], ",", -1);
        int d = g_strv_length(f) == 6 ? find_label(f[0], T->cond[0].label, T->ncond, sizeof T->cond[0]) : -1;
        long c = -1;
        double v[4];
        char *end = NULL;
        bool good = d >= 0 && model_parse_int(f[1], &c) && c >= 0 && c < T->cases;
        for (int k = 0; good && k < 4; k++) good = (v[k] = strtod(f[2 + k], &end), !*end && isfinite(v[k]));
        if (!good) {
            ok = false;
            model_error(path, ln + 1, "a bad row (%s): want description,case,dx_mm,dy_mm,turn_deg,edge_agreement",
                        lines[ln]);
        } else {
            float *q = study_pose(T, (int)c, d);
            for (int k = 0; k < 4; k++) q[k] = (float)v[k];
        }
        g_strfreev(f);
    }
    g_strfreev(lines);
    g_free(text);
    g_free(path);
    return ok;
}

// The index of label s among n strings stored stride bytes apart from base (-1: none).
static int find_label(const char *s, const char *base, int n, size_t stride)
{
    for (int k = 0; k < n; k++)
        if (!strcmp(s, base + (size_t)k * stride)) return k;
    return -1;
}

// A row's configuration, description and case (the first three of f, case at f[ci]). false + message (path:line).
static bool row_key(const study_table_t *T, char **f, int ci, const char *path, int line, int *k, int *d, int *c)
{
    long cv;
    *k = find_label(f[0], T->conf[0], T->nconf, sizeof T->conf[0]);
    *d = find_label(f[1], T->cond[0].label, T->ncond, sizeof T->cond[0]);
    if (*k < 0 || *d < 0) {
        model_error(path, line, "configuration '%s' or description '%s' is not in the study's design", f[0], f[1]);
        return false;
    }
    if (!model_parse_int(f[ci], &cv) || cv < 0 || cv >= T->cases) {
        model_error(path, line, "case '%s' is not a case number 0..%d", f[ci], T->cases - 1);
        return false;
    }
    *c = (int)cv;
    return true;
}

// DIR/study.csv (required) or DIR/timing.csv into the table. false + message naming the file and line.
bool study_read_rows(const char *dir, study_table_t *T, bool timing)
{
    static const char *hs = "config,description,expected,case,score,verdict_correct,rms_z,median_abs_z",
                      *ht = "config,description,case,seconds,iterations";
    char *path = g_strdup_printf("%s/%s", dir, timing ? "timing.csv" : "study.csv"), *text = NULL;
    GError *ge = NULL;
    bool ok = g_file_get_contents(path, &text, NULL, &ge);
    if (!ok) model_error(path, 0, "cannot read: %s", ge->message);
    g_clear_error(&ge);
    char **lines = ok ? g_strsplit(text, "\n", -1) : NULL;
    if (ok && strcmp(lines[0], timing ? ht : hs)) ok = false, model_error(path, 1, "the header is not '%s'", timing ? ht : hs);
    for (int ln = 1; ok && lines[ln]; ln++) {
        if (!lines[ln][0] && !lines[ln + 1]) break;
        char **f = g_strsplit(lines[ln], ",", -1);
        int k, d, c, nf = (int)g_strv_length(f);
        if (nf != (timing ? 5 : 8)) {
            ok = false;
            model_error(path, ln + 1, "%d fields: want %d", nf, timing ? 5 : 8);
        } else if ((ok = row_key(T, f, timing ? 2 : 3, path, ln + 1, &k, &d, &c))) {
            size_t i = study_row(T, c, k, d);
            char *end;
            double v = strtod(f[timing ? 3 : 4], &end);
            if (*end || !isfinite(v) || (!timing && (strcmp(f[2], T->cond[d].expected) ||
                                                     (strcmp(f[5], "0") && strcmp(f[5], "1"))))) {
                ok = false;
                model_error(path, ln + 1, "a bad value (%s: expected, score or verdict_correct 0/1)", lines[ln]);
            } else if (timing) {
                long it = 0;
                model_parse_int(f[4], &it);
                T->secs[i] = v;
                T->iters[i] = (int)it;
            } else if (T->verdict[i] >= 0) {
                ok = false;
                model_error(path, ln + 1, "%s, %s, case %d: already in another shard (the same shard given twice?)",
                            f[0], f[1], c);
            } else {
                double rz = strtod(f[6], &end);
                char *end2;
                double mz = strtod(f[7], &end2);
                if (*end || *end2) {
                    ok = false;
                    model_error(path, ln + 1, "a bad value (%s: rms_z and median_abs_z are numbers)", lines[ln]);
                }
                T->score[i] = v;
                T->verdict[i] = (signed char)(f[5][0] - '0');
                T->rmsz[i] = rz;
                T->medz[i] = mz;
            }
        }
        g_strfreev(f);
    }
    g_strfreev(lines);
    g_free(text);
    g_free(path);
    return ok;
}
