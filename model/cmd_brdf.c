// model/cmd_brdf.c — `refl brdf tabulate`: a reflection model that is none of
// refl's fitted ones (model/brdf/gen.c) written as a MERL binary table
// (model/brdf/table.c), for [material NAME] model = table and refl fit brdf.
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "model/internal.h"
#include "model/base/opts.h"

static int cmd_tabulate(int argc, char **argv)
{
    model_opt_t opts[] = {
        MODEL_OPT_VALUE("--model", "NAME", "oren-nayar, ggx2, retro, ggx-ms, ptfe or ggx", true),
        MODEL_OPT_OUT("FILE.binary", "the MERL binary to write (33 MB)", NULL, true),
    };
    model_cli_t c = { .cmd = "brdf tabulate", .synopsis = "[KEY=VALUE ...]", .opts = opts,
                      .nopts = MODEL_NOPTS(opts), .min_positional = 0, .max_positional = MODEL_BRDF_RECIPE_MAX };
    c.about = "Tabulates a reflection model outside refl's fitted ones in MERL's binary layout (90 x 90 x 180\n"
              "cells over theta_h (square-root mapped), theta_d, phi_d; f_r in all three channels, each divided\n"
              "by its MERL scale). KEY=VALUE set the model's parameters; the others keep their defaults.\n"
              "The same recipe (\"NAME KEY=VALUE ...\") is what [material NAME] generate = takes.";
    c.epilog = "Models and defaults: oren-nayar (albedo=0.5 sigma=0.3 rad), ggx2 (albedo=0.3 ks1=0.3\n"
               "alpha1=0.05 ks2=0.3 alpha2=0.3 F0=0.04), retro (albedo=0.5 kr=0.2 n=10), ggx-ms (alpha=0.5\n"
               "ks=1), ptfe (albedo=0.99 drop=0.03: fall of the reflectance factor at 75 deg), ggx (kd=0 ks=1\n"
               "alpha=0.3 F0=1: refl's own ggx, for checks). The table's directional albedo is printed.";
    int rc = model_cli_parse(&c, argc, argv);
    if (rc != MODEL_CLI_OK) return rc;
    char recipe[1024];
    int n = snprintf(recipe, sizeof recipe, "%s", model_cli_value(&c, "--model"));
    for (int i = 0; i < c.npositional && n < (int)sizeof recipe; i++)
        n += snprintf(recipe + n, sizeof recipe - n, " %s", c.positional[i]);
    model_brdf_recipe_t r;
    bool quiet = model_error_quiet_thread(true);
    bool ok = model_brdf_recipe_parse(recipe, NULL, 0, &r);
    model_error_quiet_thread(quiet);
    if (!ok) return model_cli_error(&c, "%s", model_last_error());
    model_error_quiet_thread(true);
    model_brdf_table_t *t = model_brdf_tabulate(&r);
    const char *out = model_cli_value(&c, "-o");
    ok = t && model_brdf_table_save(t, out);
    if (!ok) {
        model_brdf_table_free(t);
        return model_error_report("brdf tabulate");
    }
    printf("%s: %s", out, r.name);
    for (int i = 0; i < r.np; i++) printf(" %g", r.p[i]);
    printf("; directional albedo at 0/30/60/80 deg: %.4f %.4f %.4f %.4f\n",
           model_brdf_table_albedo(t, 0, 128), model_brdf_table_albedo(t, M_PI / 6, 128),
           model_brdf_table_albedo(t, M_PI / 3, 128), model_brdf_table_albedo(t, 80 * M_PI / 180, 128));
    model_brdf_table_free(t);
    return 0;
}

int model_cmd_brdf(int argc, char **argv)
{
    const char *use = "usage: refl brdf tabulate --model NAME [KEY=VALUE ...] -o FILE.binary\n"
                      "(refl brdf tabulate --help for the options)\n";
    if (argc >= 2 && (!strcmp(argv[1], "--help") || !strcmp(argv[1], "-h"))) {
        fputs(use, stdout);
        fputs("\n", stdout);
        model_cli_exit_status(stdout);
        return 0;
    }
    if (argc >= 2 && !strcmp(argv[1], "tabulate")) return cmd_tabulate(argc - 1, argv + 1);
    if (argc < 2) fprintf(stderr, "refl brdf: missing sub-command (tabulate)\n%s", use);
    else fprintf(stderr, "refl brdf: unknown sub-command '%s' (tabulate)\n%s", argv[1], use);
    return 2;
}
