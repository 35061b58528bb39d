// fit/cmd_export.c — `refl export material`: a priors file's materials as
// glTF 2.0, Mitsuba 3 or MERL (fit/material/export.c), each conversion's
// error printed and written beside the file.
#include <stdio.h>
#include <string.h>

#include "fit/material/export.h"
#include "model/base/opts.h"
#include "model/base/report.h"

#define ABOUT                                                                                                  \
    "Writes the materials of a priors file (refl fit material, refl fit brdf) for a renderer:\n"               \
    "  gltf     a glTF 2.0 file of materials: pbrMetallicRoughness (metallic 0, roughnessFactor =\n"           \
    "           sqrt(alpha)), KHR_materials_specular (specularFactor = ks, the F0 through\n"                   \
    "           specularColorFactor and, above 0.04, KHR_materials_ior), baseColorFactor fitted\n"             \
    "  mitsuba  a Mitsuba 3 scene of BSDFs: roughplastic or roughconductor (ggx), whichever is closer\n"       \
    "  merl     a MERL binary of the model's f_r at the 90 x 90 x 180 cell centres (one material)\n"           \
    "Models other than ggx go through refl's best ggx fit. Each conversion's error against refl's\n"           \
    "model is printed and written to FILE.conversion.json (and glTF's extras): the Ngan et al. 2005\n"         \
    "metric, RMS of (f_export - f_model) cos theta_i over directions uniform in solid angle, in 1/sr\n"         \
    "and relative to the model's RMS."

int fit_cmd_export(int argc, char **argv)
{
    if (argc < 2 || strcmp(argv[1], "material")) {
        bool help = argc >= 2 && (!strcmp(argv[1], "--help") || !strcmp(argv[1], "-h"));
        fprintf(help ? stdout : stderr, "%susage: refl export material PRIORS.json --format gltf|mitsuba|merl -o FILE "
                "[--material NAME]\n(refl export material --help for the options)\n",
                help || argc < 2 ? "" : "refl export: unknown export (material is the one there is)\n");
        if (help) {
            printf("\n");
            model_cli_exit_status(stdout);
        }
        return help ? 0 : 2;
    }
    argc--, argv++;
    const char *format = NULL, *out = NULL, *material = NULL;
    model_opt_t opts[] = {
        MODEL_OPT_STRING("--format", "gltf|mitsuba|merl", "the renderer's format", &format, true),
        MODEL_OPT_OUT("FILE", "the output (and FILE.conversion.json)", &out, true),
        MODEL_OPT_STRING("--material", "NAME", "this material only (default: every one; merl: the file's only "
                         "material)", &material, false),
    };
    model_cli_t cli = { .cmd = "export material", .synopsis = "PRIORS.json", .about = ABOUT, .opts = opts,
                        .nopts = MODEL_NOPTS(opts), .min_positional = 1, .max_positional = 1 };
    int rc = model_cli_parse(&cli, argc, argv);
    if (rc != MODEL_CLI_OK) return rc;
    fit_export_format_t f;
    if (!fit_export_format_from_name(format, &f))
        return model_cli_error(&cli, "--format %s: give gltf, mitsuba or merl", format);
    json_t *prov = model_provenance(argc + 1, argv - 1);
    fit_export_result_t r;
    bool q = model_error_quiet_thread(true);
    bool ok = model_provenance_input(prov, "priors", cli.positional[0]) &&
              fit_export_materials(cli.positional[0], material, f, out, prov, &r);
    model_error_quiet_thread(q);
    json_decref(prov);
    if (!ok) {
        free(r.m);
        return model_error_report("export material");
    }
    for (int i = 0; i < r.n; i++) {
        const fit_export_material_t *e = &r.m[i];
        printf("refl export material: %s (%s) as %s: Ngan error %.4g 1/sr (%.2f %% of the model's RMS)", e->name,
               model_brdf_name(e->model), e->target, e->error, 100 * e->rel_error);
        if (e->model != MODEL_BRDF_GGX && f != FIT_EXPORT_MERL)
            printf("; via ggx, itself %.4g 1/sr", e->ggx_error);
        if (e->alt_target[0]) printf("; %s: %.4g 1/sr", e->alt_target, e->alt_error);
        printf("\n");
    }
    printf("%s\n%s.conversion.json\n", out, out);
    free(r.m);
    return 0;
}
