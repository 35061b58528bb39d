// fit/cmd_chain.c — `refl chain DIR --truth TRUTH.ini [-o FILE]`: a lab day's
// figures against the virtual rig's truth (fit/eval/chain.h), printed as a table
// and written to chain.json.
#include <glib.h>
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "fit/eval/chain.h"
#include "model/model.h"
#include "model/base/opts.h"
#include "model/base/report.h"

static void print_entry(const json_t *e)
{
    const json_t *v = json_object_get(e, "value"), *t = json_object_get(e, "truth");
    const json_t *s = json_object_get(e, "sigma"), *z = json_object_get(e, "z");
    char vb[32], tb[32], sb[32], zb[32];
    if (json_is_string(v)) snprintf(vb, sizeof vb, "%s", json_string_value(v));
    else snprintf(vb, sizeof vb, "%.6g", json_number_value(v));
    if (json_is_string(t)) snprintf(tb, sizeof tb, "%s", json_string_value(t));
    else if (json_is_number(t)) snprintf(tb, sizeof tb, "%.6g", json_number_value(t));
    else snprintf(tb, sizeof tb, "-");
    snprintf(sb, sizeof sb, json_is_number(s) ? "%.3g" : "-", json_number_value(s));
    snprintf(zb, sizeof zb, json_is_number(z) ? "%+.2f" : "-", json_number_value(z));
    const char *name = json_string_value(json_object_get(e, "name"));
    bool flag = (json_is_number(z) && fabs(json_number_value(z)) > 3) ||
                (json_is_string(v) && json_integer_value(json_object_get(e, "error"))) ||
                (g_str_has_suffix(name, ".ngan_error_ratio") && json_number_value(v) > 1.2);
    printf("%-40s %14s %14s %10s %8s %-10s%s\n", name, vb, tb, sb, zb,
           json_string_value(json_object_get(e, "unit")), flag ? "  <-- |z| > 3, wrong, or over 1.2x the best" : "");
}

int eval_chain_cmd(int argc, char **argv)
{
    const char *truth = NULL, *out = NULL;
    bool quiet = false;
    model_opt_t opts[] = {
        MODEL_OPT_STRING("--truth", "TRUTH.ini", "the virtual rig's truth file the day ran on", &truth, true),
        MODEL_OPT_OUT("FILE", "write chain.json here (default DIR/chain.json)", &out, false),
        MODEL_OPT_FLAG("--quiet", NULL, "print only the summary, not the table", &quiet),
    };
    model_cli_t cli = {
        .cmd = "chain", .synopsis = "DIR", .opts = opts, .nopts = MODEL_NOPTS(opts),
        .min_positional = 1, .max_positional = 1,
        .about = "Compares a lab day's calibrated and fitted figures (DIR of refl demo: calib/geometry,\n"
                 "calib/lamps, calib/gain, calib/white, priors_*.json, */verify.json) with the truth file of\n"
                 "the virtual rig it ran on: each figure's value, truth, the 1-sigma refl states for it\n"
                 "(none where it states none), error = value - truth and z = error / sigma. Writes\n"
                 "chain.json (units and provenance inside) and prints the table, marking |z| > 3 and\n"
                 "wrong verdicts. Camera models are compared over the imager after the best rigid\n"
                 "alignment, as mrcal's projection_diff does.",
    };
    int rc = model_cli_parse(&cli, argc, argv);
    if (rc != MODEL_CLI_OK) return rc;
    const char *dir = cli.positional[0];
    char *path = out ? g_strdup(out) : g_build_filename(dir, "chain.json", NULL);
    json_t *prov = model_provenance(argc, argv);
    bool q = model_error_quiet_thread(true);   // the message is printed once, below
    json_t *doc = eval_chain_compare(dir, truth, prov);
    bool written = doc && model_write_json(path, doc);
    model_error_quiet_thread(q);
    rc = 1;
    if (written) {
        const json_t *e, *s = json_object_get(doc, "summary");
        size_t i;
        if (!quiet) {
            printf("%-40s %14s %14s %10s %8s %s\n", "name", "value", "truth", "sigma", "z", "unit");
            json_array_foreach(json_object_get(doc, "entries"), i, e) print_entry(e);
        }
        printf("%lld figures: %lld with a stated sigma, %lld with a truth but no sigma; |z| > 3: %zu; wrong "
               "verdicts: %lld; materials over 1.2x the best fit's Ngan error: %zu\n",
               json_integer_value(json_object_get(s, "entries")),
               json_integer_value(json_object_get(s, "with_sigma")),
               json_integer_value(json_object_get(s, "without_sigma")),
               json_array_size(json_object_get(s, "z_over_3")),
               json_integer_value(json_object_get(s, "wrong_verdicts")),
               json_array_size(json_object_get(s, "ngan_ratio_over_1_2")));
        json_array_foreach(json_object_get(doc, "missing"), i, e)
            printf("not compared (missing): %s\n", json_string_value(e));
        printf("%s\n", path);
        rc = 0;
    } else
        model_error_report("chain");
    json_decref(doc);
    json_decref(prov);
    g_free(path);
    return rc;
}
