// fit/eval/study_merge.c — `refl verify --study-merge`: the output
// directories of a study's shards (the same design; every case in exactly
// one) joined into one, as the unsharded run writes it.
#define _GNU_SOURCE
#include <glib.h>
#include <stdio.h>
#include <string.h>

#include "fit/eval/internal.h"
#include "fit/eval/study.h"
#include "model/model.h"
#include "model/base/report.h"

// The table's shape from a shard's design. false + message.
static bool table_from_design(study_table_t *T, const json_t *design, const char *path)
{
    json_t *cf = json_object_get(design, "configurations"), *cd = json_object_get(design, "descriptions");
    json_int_t cases = json_integer_value(json_object_get(design, "cases"));
    if (!json_is_array(cf) || !json_is_array(cd) || cases < 1 || cases > 10000000 || json_array_size(cf) < 1 ||
        json_array_size(cf) > NCONF || json_array_size(cd) < 2 || json_array_size(cd) > NCOND) {
        model_error(path, 0, "its design (cases, configurations, descriptions) is not one of refl verify --study's");
        return false;
    }
    T->cases = (int)cases;
    T->nconf = (int)json_array_size(cf);
    T->ncond = (int)json_array_size(cd);
    for (int k = 0; k < T->nconf; k++) {
        const char *s = json_string_value(json_array_get(cf, k));
        if (!s || strlen(s) >= sizeof T->conf[k]) {
            model_error(path, 0, "design: configuration %d is not a short string", k);
            return false;
        }
        snprintf(T->conf[k], sizeof T->conf[k], "%s", s);
    }
    for (int k = 0; k < T->ncond; k++) {
        json_t *e = json_array_get(cd, k);
        const char *l = json_string_value(json_object_get(e, "description")),
                   *x = json_string_value(json_object_get(e, "expected"));
        if (!l || !x || strlen(l) >= sizeof T->cond[k].label || strlen(x) >= sizeof T->cond[k].expected ||
            (k == 0) != !strcmp(x, "correct")) {
            model_error(path, 0, "design: description %d is not {description, expected} (the first, and only "
                        "the first, the correct one)", k);
            return false;
        }
        snprintf(T->cond[k].label, sizeof T->cond[k].label, "%s", l);
        snprintf(T->cond[k].expected, sizeof T->cond[k].expected, "%s", x);
    }
    T->reg = json_object_get(design, "placement_tolerance") != NULL;
    return study_table_alloc(T);
}

// The first case (configuration, description) no shard has: false + message.
static bool check_complete(const study_table_t *T)
{
    for (int c = 0; c < T->cases; c++)
        for (int k = 0; k < T->nconf; k++)
            for (int d = 0; d < T->ncond; d++)
                if (T->verdict[study_row(T, c, k, d)] < 0) {
                    model_error(NULL, 0, "verify study merge: case %d (%s, %s) is in none of the shards given: "
                                "give every shard K/N of the study", c, T->conf[k], T->cond[d].label);
                    return false;
                }
    return true;
}

bool eval_study_merge(const char *const *dirs, int ndirs, const char *out, json_t *provenance,
                      eval_study_result_t *r)
{
    memset(r, 0, sizeof *r);
    study_table_t T = { 0 };
    json_t *design = NULL, *from = json_array();
    bool ok = ndirs > 0;
    if (!ok) model_error(NULL, 0, "verify study merge: no shard directory given");
    for (int s = 0; ok && s < ndirs; s++) {
        char *jp = g_strdup_printf("%s/study.json", dirs[s]);
        int version = 0;
        json_t *doc = study_read_json(jp, &version), *d = json_object_get(doc, "design");
        if (!doc) {
            ok = false;
        } else if (!json_is_object(d)) {
            ok = false;
            model_error(jp, 0, "no design: not a study of refl verify --study");
        } else if (!design) {
            design = json_incref(d);
            ok = table_from_design(&T, d, jp);
        } else if (!json_equal(design, d)) {
            ok = false;
            model_error(jp, 0, "its design (cases, configurations, descriptions, threshold or the inputs' hashes) "
                        "differs from that of %s: shards of different studies", dirs[0]);
        }
        if (ok) {
            model_provenance_input(provenance, "shard", jp);
            json_array_append_new(from, json_pack("{s:s, s:i, s:O?, s:O?}", "dir", dirs[s], "version", version,
                                                  "shard", json_object_get(doc, "shard"), "provenance",
                                                  json_object_get(doc, "provenance")));
            ok = study_read_rows(dirs[s], &T, false);
            char *tp = g_strdup_printf("%s/timing.csv", dirs[s]);
            if (ok && g_file_test(tp, G_FILE_TEST_EXISTS)) ok = study_read_rows(dirs[s], &T, true);
            g_free(tp);
            if (ok && T.reg) ok = study_read_placement(dirs[s], &T);
        }
        json_decref(doc);
        g_free(jp);
    }
    ok = ok && check_complete(&T) && model_mkdir_p(out);
    if (ok) {
        json_object_set_new(provenance, "merged_from", json_incref(from));
        ok = study_write_tables(out, &T) && study_write_json(out, &T, design, NULL, provenance);
    }
    if (ok) {
        r->cases = r->cases_run = T.cases;
        r->ndescriptions = T.ncond;
        r->nconfigurations = T.nconf;
        r->complete = true;
    }
    json_decref(from);
    json_decref(design);
    study_table_free(&T);
    return ok;
}
