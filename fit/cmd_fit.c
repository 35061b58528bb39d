// fit/cmd_fit.c — `refl fit brdf FILE [--model M|all] -o PRIORS.json`:
// fit the reflection models to BRDF samples from a file and write the
// priors file (README, "Priors file").
#define _GNU_SOURCE
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "calib/calib.h"
#include "fit/fit.h"
#include "fit/material.h"
#include "model/model.h"
#include "model/report.h"

static void brdf_usage(FILE *f)
{
    fprintf(f, "usage: refl fit brdf FILE [--model all|lambert|hall|torrance_sparrow|thesis_fit|cook_torrance|ggx]\n"
               "                     [--name MATERIAL] [--k-sigma K] [--noise-sigma S] [--systematic REL] -o PRIORS.json\n"
               "\n"
               "Fits reflection models to BRDF samples: a CSV (theta_i,phi_i,theta_o,phi_o,f_r[,weight], degrees,\n"
               "1/sr; optional header; '#' comments) or a MERL binary file (its luminance). With --model all\n"
               "(default) every model is fitted and the one with the lowest BIC is chosen. Errors are the RMS of\n"
               "R = f_r cos(theta_i) (the cosine-weighted metric of Ngan et al. 2005) and of f_r. Bounds are\n"
               "mean +- K std (default 3) clipped to the physical range; std includes REL * mean (default 0) for\n"
               "systematic errors the samples share.\n\nrefl %s\n", REFL_VERSION);
}

static int usage_error(const char *msg, const char *arg)
{
    fprintf(stderr, "refl fit brdf: %s%s%s\n(refl fit brdf --help for the options)\n", msg, arg ? " " : "",
            arg ? arg : "");
    return 2;
}

static int cmd_brdf(int argc, char **argv)
{
    const char *file = NULL, *out = NULL, *model = "all", *name = NULL;
    double k_sigma = 3, noise = 0, sys_rel = 0;
    for (int i = 1; i < argc; i++) {
        const char *a = argv[i];
        if (!strcmp(a, "-h") || !strcmp(a, "--help")) {
            brdf_usage(stdout);
            return 0;
        }
        bool has = i + 1 < argc;
        if (!strcmp(a, "-o") || !strcmp(a, "--model") || !strcmp(a, "--name") || !strcmp(a, "--k-sigma") ||
            !strcmp(a, "--noise-sigma") || !strcmp(a, "--systematic")) {
            if (!has) return usage_error("missing value after", a);
            const char *v = argv[++i];
            char *e;
            if (!strcmp(a, "-o")) out = v;
            else if (!strcmp(a, "--model")) model = v;
            else if (!strcmp(a, "--name")) name = v;
            else if (!strcmp(a, "--k-sigma")) {
                k_sigma = strtod(v, &e);
                if (*e || !(k_sigma > 0) || !isfinite(k_sigma)) return usage_error("--k-sigma needs a number > 0, not", v);
            } else if (!strcmp(a, "--systematic")) {
                sys_rel = strtod(v, &e);
                if (*e || !(sys_rel >= 0) || !isfinite(sys_rel)) return usage_error("--systematic needs a number >= 0, not", v);
            } else {
                noise = strtod(v, &e);
                if (*e || !(noise >= 0) || !isfinite(noise)) return usage_error("--noise-sigma needs a number >= 0, not", v);
            }
        } else if (a[0] == '-') {
            return usage_error("unknown option", a);
        } else if (!file) {
            file = a;
        } else {
            return usage_error("more than one sample file:", a);
        }
    }
    if (!file) return usage_error("give the BRDF sample file", NULL);
    if (!out) return usage_error("give the priors file to write: -o PRIORS.json", NULL);
    int models[MODEL_BRDF_COUNT], nm = 0;
    if (!strcmp(model, "all")) {
        for (int m = 0; m < MODEL_BRDF_COUNT; m++) models[nm++] = m;
    } else {
        int m = model_brdf_from_name(model);
        if (m < 0) return usage_error("--model: unknown model", model);
        models[nm++] = m;
    }
    fit_samples_t *s = fit_samples_read(file);
    if (!s) return 1;
    fprintf(stderr, "refl fit brdf: %d samples from %s\n", s->n, file);
    fit_brdf_result_t res[MODEL_BRDF_COUNT];
    int nres = 0, best = -1;
    fit_brdf_options_t o = fit_brdf_defaults();
    o.noise_sigma = noise;
    for (int k = 0; k < nm; k++) {
        double t0 = model_now_s();
        if (!fit_brdf(s, (model_brdf_t)models[k], &o, &res[nres])) {
            fprintf(stderr, "refl fit brdf: %s: %s\n", model_brdf_name((model_brdf_t)models[k]), model_last_error());
            continue;
        }
        fprintf(stderr, "  %-16s rms %.4g 1/sr  BIC %.6g  (%d iterations, %.2f s)%s\n",
                model_brdf_name(res[nres].model), res[nres].rms, res[nres].bic, res[nres].summary.iterations,
                model_now_s() - t0, res[nres].cov_ok ? "" : "  covariance: not available");
        if (best < 0 || res[nres].bic < res[best].bic) best = nres;
        nres++;
    }
    int rc = 1;
    if (best < 0) {
        fprintf(stderr, "refl fit brdf: no model could be fitted to %s\n", file);
        goto done;
    }
    const char *mat = name;
    char base[256];
    if (!mat) {
        const char *b = strrchr(file, '/');
        snprintf(base, sizeof base, "%s", b ? b + 1 : file);
        char *dot = strrchr(base, '.');
        if (dot) *dot = 0;
        mat = base;
    }
    json_t *top = json_object();
    json_object_set_new(top, "format", json_string("refl priors 1"));
    json_object_set_new(top, "units", json_string("R = f_r cos(theta_i) in 1/sr; parameter units per parameter"));
    json_t *mats = json_array();
    json_t *entry = fit_priors_material(mat, &res[best], res, nres, k_sigma, sys_rel);
    json_t *src = json_object();
    json_object_set_new(src, "path", json_string(file));
    json_object_set_new(src, "sha256", json_string(s->sha256));
    json_object_set_new(entry, "samples", src);
    json_array_append_new(mats, entry);
    json_object_set_new(top, "materials", mats);
    json_t *prov = model_provenance(argc + 1, argv - 1);
    model_provenance_input(prov, "brdf_samples", file);
    json_object_set_new(top, "provenance", prov);
    if (model_write_json(out, top)) {
        printf("%s: %s, model %s (lowest BIC of %d), rms %.4g 1/sr\n", out, mat, model_brdf_name(res[best].model),
               nres, res[best].rms);
        rc = 0;
    }
    json_decref(top);
done:
    fit_samples_free(s);
    return rc;
}

int fit_cmd(int argc, char **argv)
{
    if (argc < 2 || !strcmp(argv[1], "--help") || !strcmp(argv[1], "-h")) {
        FILE *f = argc < 2 ? stderr : stdout;
        fprintf(f, "usage: refl fit brdf FILE ... -o PRIORS.json        (refl fit brdf --help)\n"
                   "       refl fit material SESSION --calib DIR ... -o PRIORS.json   (refl fit material --help)\n"
                   "\nrefl %s\n", REFL_VERSION);
        return argc < 2 ? 2 : 0;
    }
    if (!strcmp(argv[1], "brdf")) return cmd_brdf(argc - 1, argv + 1);
    if (!strcmp(argv[1], "material")) return fit_cmd_material(argc - 1, argv + 1);
    fprintf(stderr, "refl fit: unknown fit '%s' (refl fit --help)\n", argv[1]);
    return 2;
}
