// fit/cmd_fit.c — `refl fit brdf FILE [--model M|all] -o PRIORS.json` (fit the
// reflection models to BRDF samples from a file and write the priors file,
// README "Priors file") and `refl fit material SESSION --calib DIR ...`
// (fit_material_run, fit/material/material.h): arguments (model/base/opts.h), the library
// call, the printed lines.
#define _GNU_SOURCE
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "calib/calib.h"
#include "fit/brdf/brdf.h"
#include "fit/material/material.h"
#include "fit/priors.h"
#include "model/model.h"
#include "model/base/opts.h"
#include "model/base/report.h"

#define MODEL_NAMES "all|lambert|hall|torrance_sparrow|thesis_fit|cook_torrance|ggx|ashikhmin_shirley|ggx2"

// --cv-folds K and --cv-seed N into *folds, *seed (absent: kept); 0 or MODEL_CLI_USAGE.
static int cv_opts(model_cli_t *cli, int *folds, uint64_t *seed)
{
    const char *v = model_cli_value(cli, "--cv-folds");
    char *e;
    if (v) {
        long k = strtol(v, &e, 10);
        if (e == v || *e || k < 0 || k > 64)
            return model_cli_error(cli, "--cv-folds needs a whole number 0..64 (0: choose by BIC), not '%s'", v);
        *folds = (int)k;
    }
    if ((v = model_cli_value(cli, "--cv-seed"))) {
        unsigned long long x = strtoull(v, &e, 10);
        if (e == v || *e || *v == '-') return model_cli_error(cli, "--cv-seed needs a whole number >= 0, not '%s'", v);
        *seed = x;
    }
    return 0;
}

// A number option of cli converted after parsing: absent keeps *out; a value
// not a finite number >= 0 (> 0 unless zero_ok) is a usage error
// "NAME needs a number >= 0, not 'V'". 0 or MODEL_CLI_USAGE.
static int number_opt(model_cli_t *cli, const char *name, bool zero_ok, double *out)
{
    const char *v = model_cli_value(cli, name);
    double d;
    if (!v) return 0;
    if (!model_parse_double(v, &d) || !isfinite(d) || !(zero_ok ? d >= 0 : d > 0))
        return model_cli_error(cli, "%s needs a number %s 0, not '%s'", name, zero_ok ? ">=" : ">", v);
    *out = d;
    return 0;
}

// The material's name in the priors of a sample file: its base name without extension.
static void base_name(const char *file, char *buf, size_t n)
{
    const char *b = strrchr(file, '/');
    snprintf(buf, n, "%s", b ? b + 1 : file);
    char *dot = strrchr(buf, '.');
    if (dot) *dot = 0;
}

// "  held-out rms X +- SE 1/sr" of a cross-validated fit, else "".
typedef struct {
    char s[64];
} held_out_t;
static held_out_t held_out(const fit_brdf_result_t *r)
{
    held_out_t h = { "" };
    if (isfinite(r->cv_rms)) snprintf(h.s, sizeof h.s, "  held-out rms %.4g +- %.2g 1/sr", r->cv_rms, r->cv_se);
    return h;
}

// ---------------------------------------------------------------------------
// refl fit brdf

// The arguments of refl fit brdf, parsed and converted.
typedef struct {
    const char        *out, *model, *name, *weights, *channel, *loss, *file;
    double             k_sigma, sys_rel;
    model_brdf_t       models[MODEL_BRDF_COUNT];
    int                nmodels;
    fit_read_opts_t    ro;
    model_channel_t    ch;
    fit_brdf_options_t o;
} brdf_args_t;

// Parse refl fit brdf's arguments into *a: MODEL_CLI_OK, or the exit status
// (help, a usage error said).
static int brdf_parse(int argc, char **argv, brdf_args_t *a)
{
    *a = (brdf_args_t){ .model = "all", .weights = "solid-angle", .channel = "luma", .loss = "l2", .k_sigma = 3,
                        .ro = fit_read_defaults(), .o = fit_brdf_defaults() };
    a->o.loss_scale = 2;
    model_opt_t opts[] = {
        MODEL_OPT_OUT("PRIORS.json", "the priors file to write", &a->out, true),
        MODEL_OPT_STRING("--model", "M", MODEL_NAMES " (default all: chosen by cross-validation)", &a->model, false),
        MODEL_OPT_VALUE("--cv-folds", "K", "folds of the model choice's cross-validation (default 5; 0: lowest BIC)",
                        false),
        MODEL_OPT_VALUE("--cv-seed", "N", "seed of the folds' shuffle (default 1)", false),
        MODEL_OPT_STRING("--name", "MATERIAL", "the material's name (default: the file's base name)", &a->name, false),
        MODEL_OPT_VALUE("--k-sigma", "K", "prior bounds mean +- K std (default 3)", false),
        MODEL_OPT_VALUE("--noise-sigma", "S", "known std of R, 1/sr (default 0: from the residuals)", false),
        MODEL_OPT_VALUE("--systematic", "REL", "std adds REL * mean for errors the samples share (default 0)", false),
        MODEL_OPT_STRING("--weights", "solid-angle|uniform|column", "each sample's weight on its squared residual: "
                         "the solid angle it stands for in (omega_i, omega_o) (default), 1, or the CSV's 6th field",
                         &a->weights, false),
        MODEL_OPT_STRING("--channel", "luma|r|g|b", "MERL and RGL colour: Rec. 709 luma (0.2126 R + 0.7152 G + "
                         "0.0722 B; default; spectral RGL: CIE Y) or one channel", &a->channel, false),
        MODEL_OPT_STRING("--loss", "l2|huber|cauchy", "least squares (default) or a robust loss on each sample's "
                         "weighted residual", &a->loss, false),
        MODEL_OPT_DOUBLE("--loss-scale", "S", "where the robust loss starts, in units of the residuals' robust std "
                         "(1.4826 median |r| of a least-squares fit; default 2)", &a->o.loss_scale, 0.01, 1e6),
    };
    model_cli_t cli = {
        .cmd = "fit brdf", .synopsis = "FILE", .opts = opts, .nopts = MODEL_NOPTS(opts),
        .min_positional = 1, .max_positional = 1,
        .about = "Fits reflection models to BRDF samples: a CSV (theta_i,phi_i,theta_o,phi_o,f_r[,weight], degrees,\n"
                 "1/sr; optional header; '#' comments; negative f_r kept, NaN/inf refused), a MERL binary or an RGL\n"
                 ".bsdf file (Dupuy & Jakob 2018; its measured incident directions, 32 x 64 outgoing each), told\n"
                 "apart by content. Each sample's squared residual is multiplied by its weight (scaled to mean 1):\n"
                 "by default the solid angle it stands for in (omega_i, omega_o) (exact for MERL and RGL grids and\n"
                 "CSV theta/phi grids, a ring estimate otherwise), so a grid crowded at the pole does not dominate;\n"
                 "--weights uniform or column (the CSV's 6th field) instead. With --model all\n"
                 "(default) every model is fitted and one chosen by K-fold cross-validation (--cv-folds, default 5):\n"
                 "the samples cut into 10 K contiguous blocks dealt to K folds in an order shuffled by --cv-seed,\n"
                 "each model refitted without each fold and its held-out weighted RMS of R computed; the model with\n"
                 "the fewest parameters within one standard error of the lowest is chosen (BIC and AIC reported\n"
                 "beside it; --cv-folds 0 chooses the lowest BIC). Errors are the RMS of\n"
                 "R = f_r cos(theta_i) (the cosine-weighted metric of Ngan et al. 2005) and of f_r. Bounds are\n"
                 "mean +- K std (default 3) clipped to the physical range; std includes REL * mean (default 0) for\n"
                 "systematic errors the samples share.",
    };
    int rc = model_cli_parse(&cli, argc, argv);
    if (rc != MODEL_CLI_OK) return rc;
    if (number_opt(&cli, "--k-sigma", false, &a->k_sigma) || number_opt(&cli, "--systematic", true, &a->sys_rel) ||
        number_opt(&cli, "--noise-sigma", true, &a->o.noise_sigma))
        return MODEL_CLI_USAGE;
    if (!fit_brdf_model_list(a->model, a->models, &a->nmodels))
        return model_cli_error(&cli, "--model: unknown model %s", a->model);
    if (!fit_weights_parse(a->weights, &a->ro.weights))
        return model_cli_error(&cli, "--weights: solid-angle, uniform or column, not '%s'", a->weights);
    if (!model_channel_parse(a->channel, &a->ch))
        return model_cli_error(&cli, "--channel: luma, r, g or b, not '%s'", a->channel);
    a->ro.channel = (int)a->ch;
    if (!fit_loss_parse(a->loss, &a->o.loss))
        return model_cli_error(&cli, "--loss: l2, huber or cauchy, not '%s'", a->loss);
    if (cv_opts(&cli, &a->o.cv_folds, &a->o.cv_seed)) return MODEL_CLI_USAGE;
    a->file = cli.positional[0];
    return MODEL_CLI_OK;
}

// What was read: the samples, their weights, the negative f_r kept (stderr).
static void brdf_print_samples(const brdf_args_t *a, const fit_samples_t *s)
{
    fprintf(stderr, "refl fit brdf: %d samples from %s (%s, weights %s", s->n, a->file, model_channel_name(a->ch),
            a->weights);
    if (s->omega_sr2 > 0)
        fprintf(stderr, " by %s: %.4g sr^2, %.1f %% of (2 pi)^2", s->omega_how ? s->omega_how : "?", s->omega_sr2,
                100 * s->omega_sr2 / (4 * M_PI * M_PI));
    fprintf(stderr, ")\n");
    if (s->nodes_total)
        fprintf(stderr, "refl fit brdf: sampled where the file measured: %d of its %d nodes (%.1f %%; the others "
                "reflect below the surface or stand for no solid angle); the largest f_r read %.4g 1/sr\n", s->nodes_used,
                s->nodes_total, 100.0 * s->nodes_used / s->nodes_total, s->fr_max);
    if (s->n_negative) {   // measurements (dark-subtracted noise): kept, and how far below 0 they reach
        double lo = 0, hi = 0;
        for (int k = 0; k < s->n; k++) {
            double fr = s->R[k] / s->c[k].nl;
            lo = fmin(lo, fr);
            hi = fmax(hi, fr);
        }
        fprintf(stderr, "refl fit brdf: %d samples with f_r < 0 kept as measurements (down to %.3g 1/sr; the largest "
                "f_r %.3g)\n", s->n_negative, lo, hi);
    }
}

// One line per model tried (stderr).
static void brdf_print_models(const fit_brdf_models_t *fm)
{
    for (int t = 0; t < fm->ntried; t++) {
        const fit_brdf_result_t *r = fm->at[t] >= 0 ? &fm->res[fm->at[t]] : NULL;
        if (!r)
            fprintf(stderr, "refl fit brdf: %s: %s\n", model_brdf_name(fm->tried[t]), fm->error[t]);
        else
            fprintf(stderr, "  %-17s rms %.4g 1/sr%s  BIC %.6g  (%d iterations, %.2f s)%s\n", model_brdf_name(r->model),
                    r->rms, held_out(r).s, r->bic, r->summary.iterations, fm->time_s[t],
                    r->cov_ok ? "" : "  covariance: not available");
    }
}

// The priors document of the chosen model of material mat (fit_priors_document).
static json_t *brdf_priors(const brdf_args_t *a, const char *mat, const fit_samples_t *s, const fit_brdf_models_t *fm,
                           int argc, char **argv)
{
    json_t *top = fit_priors_document();
    json_t *mats = json_array();
    json_t *entry = fit_priors_material(mat, &fm->res[fm->best], fm->res, fm->nres, a->k_sigma, a->sys_rel);
    json_t *src = json_object();
    json_object_set_new(src, "path", json_string(a->file));
    json_object_set_new(src, "sha256", json_string(s->sha256));
    json_object_set_new(src, "channel", json_string(model_channel_name(a->ch)));
    json_object_set_new(src, "weights", json_string(a->weights));
    if (s->omega_sr2 > 0) {
        json_object_set_new(src, "solid_angle_sr2", json_real(s->omega_sr2));
        json_object_set_new(src, "solid_angle_by", json_string(s->omega_how ? s->omega_how : ""));
    }
    if (s->n_negative) json_object_set_new(src, "negative_f_r_kept", json_integer(s->n_negative));
    if (s->nodes_total) {   // a tabulated file sampled at its nodes: how much of it, and its largest f_r
        json_object_set_new(src, "nodes_used", json_integer(s->nodes_used));
        json_object_set_new(src, "nodes_total", json_integer(s->nodes_total));
        json_object_set_new(src, "f_r_max_per_sr", json_real(s->fr_max));
    }
    json_object_set_new(entry, "samples", src);
    json_object_set_new(entry, "model_choice", fit_brdf_choice_json(fm));
    json_array_append_new(mats, entry);
    json_object_set_new(top, "materials", mats);
    json_t *prov = model_provenance(argc + 1, argv - 1);
    model_provenance_input(prov, "brdf_samples", a->file);
    json_object_set_new(top, "provenance", prov);
    return top;
}

// The line of the written priors: the material, the model and how it was chosen.
static void brdf_print_result(const brdf_args_t *a, const char *mat, const fit_brdf_models_t *fm)
{
    const fit_brdf_result_t *best = &fm->res[fm->best];
    char how[160];
    if (fm->nres < 2) snprintf(how, sizeof how, "the only model fitted");
    else snprintf(how, sizeof how, "%s of %d; lowest BIC: %s", fm->by_cv ? "cross-validated" : "lowest BIC",
                  fm->nres, model_brdf_name(fm->res[fm->best_bic].model));
    printf("%s: %s, model %s (%s), rms %.4g 1/sr", a->out, mat, model_brdf_name(best->model), how, best->rms);
    if (fm->by_cv) printf(", held-out rms %.4g 1/sr (%s)\n", best->cv_rms, fm->cv_note);
    else if (fm->nres > 1) printf("\n  model choice: %s\n", fm->cv_note);
    else printf("\n");
}

static int cmd_brdf(int argc, char **argv)
{
    brdf_args_t a;
    int rc = brdf_parse(argc, argv, &a);
    if (rc != MODEL_CLI_OK) return rc;
    bool quiet = model_error_quiet_thread(true);   // reported once, below
    fit_samples_t *s = fit_samples_load(a.file, &a.ro);
    model_error_quiet_thread(quiet);
    if (!s) return model_error_report("fit brdf");
    brdf_print_samples(&a, s);
    fit_brdf_models_t *fm = malloc(sizeof *fm);
    rc = 1;
    if (!fm) {
        fprintf(stderr, "refl fit brdf: out of memory\n");
        goto done;
    }
    fit_brdf_models(s, a.models, a.nmodels, &a.o, fm);
    brdf_print_models(fm);
    if (fm->best < 0) {
        fprintf(stderr, "refl fit brdf: no model could be fitted to %s\n", a.file);
        goto done;
    }
    char base[256];
    base_name(a.file, base, sizeof base);
    const char *mat = a.name ? a.name : base;
    json_t *top = brdf_priors(&a, mat, s, fm, argc, argv);
    if (model_write_json(a.out, top)) {
        brdf_print_result(&a, mat, fm);
        rc = 0;
    }
    json_decref(top);
done:
    free(fm);
    fit_samples_free(s);
    return rc;
}

// ---------------------------------------------------------------------------
// refl fit material

// One line per model tried (a model that could not be fitted on stderr).
static void print_models(const fit_brdf_models_t *m)
{
    for (int t = 0; t < m->ntried; t++) {
        if (m->at[t] < 0) {
            fprintf(stderr, "  %s: %s\n", model_brdf_name(m->tried[t]), m->error[t]);
            continue;
        }
        const fit_brdf_result_t *r = &m->res[m->at[t]];
        printf("  %-17s rms %.4g 1/sr%s  BIC %.6g", model_brdf_name(r->model), r->rms, held_out(r).s, r->bic);
        for (int j = 0; j < r->nparams; j++) printf("  %s %.4g", model_brdf_param_name(r->model, j), r->p[j]);
        printf("\n");
    }
}

// What the fit did, in its order (r: as far as it went).
static void print_material(const fit_material_opts_t *o, const fit_material_result_t *r)
{
    if (!r->observed) return;
    printf("refl fit material: %s: %d BRDF samples from %d frames (%d skipped)\n", r->material, r->nsamples,
           r->frames_used, r->frames_skipped);
    for (int k = 0; r->ncameras > 1 && k < r->ncameras; k++)
        printf("  camera %s: %d observations\n", r->cameras[k], r->nobs_camera[k]);
    calib_sample_pose_print(stdout, &r->pose);
    if (r->have_gain) {
        printf("  expected residual RMS from the sensor's noise alone: %.4g 1/sr\n", r->noise_rms);
        if (r->lin.kind == MODEL_LIN_MONOTONE)
            printf("  response linearised: the gain calibration's monotone table (%d knots up to %.1f DN; its "
                   "S_m = S (1 - a S) fit: a = %.4g per DN)\n", r->lin.n, r->lin.m[r->lin.n - 1], r->lin.a_per_dn);
        else
            printf("  response linearised: S_m = S (1 - a S), a = %.4g per DN at the calibration's gain%s\n",
                   r->lin.a_per_dn, r->lin.kind == MODEL_LIN_PARAMETRIC ? "" : " (none in the gain calibration)");
    }
    print_models(&r->first);
    if (r->cells_done) {
        printf("  albedo cells of %g mm: %d cells hold %d of %d observations; factors' std %.4f (%d iterations "
               "with %s); every model again:\n", o->cell_mm, r->n_cells, r->n_obs_in_cells, r->nobs, r->cells_rel_std,
               r->cell_iterations, model_brdf_name(r->cells_model));
        print_models(&r->models);
    }
    if (r->observed)
        printf("  %s%s\n", r->noise_weighted ? "weighted by each sample's noise (1/sigma^2 from the gain calibration)"
                                              : "weights uniform (no gain calibration, or --weights uniform)",
               o->loss != LSQ_LOSS_NONE ? (o->loss == LSQ_LOSS_HUBER ? "; Huber loss" : "; Cauchy loss") : "");
    if (isfinite(r->rms_over_noise))
        printf("  residual per degree of freedom over the noise: %.3f%s\n", r->rms_over_noise,
               r->noise_weighted ? " (sqrt(chi^2 / dof))" : "");
    if (r->written) {
        const fit_brdf_models_t *m = &r->models;
        const fit_brdf_result_t *b = &m->res[m->best];
        printf("  %s: std = statistical (%s) + each lamp's %g %% + shared %g %%:\n", model_brdf_name(b->model),
               !r->shared_done ? "chi^2/dof-scaled"
               : r->clusters_frame && r->clusters_place ? "clustered by frames and places"
               : r->clusters_frame ? "clustered by frames" : "clustered by places",
               100 * o->lamp_rel, 100 * o->sys_rel);
        for (int j = 0; j < b->nparams; j++) {
            double lamps = b->groups_ok ? sqrt(fmax(b->cov_groups[j * b->nparams + j], 0)) : 0;
            printf("    %-7s %.5g +- %.3g  (statistical %.3g, lamps %.3g)\n", model_brdf_param_name(b->model, j),
                   b->p[j], fit_prior_std(b, o->sys_rel, j), b->std[j], lamps);
        }
        if (m->nres < 2)
            printf("%s: %s, model %s (the only model fitted)\n", o->out, o->name ? o->name : r->material,
                   model_brdf_name(m->res[m->best].model));
        else
            printf("%s: %s, model %s (%s of %d; lowest BIC: %s)\n", o->out, o->name ? o->name : r->material,
                   model_brdf_name(m->res[m->best].model), m->by_cv ? m->cv_note : "lowest BIC", m->nres,
                   model_brdf_name(m->res[m->best_bic].model));
    }
}

int fit_cmd_material(int argc, char **argv)
{
    fit_material_opts_t o = fit_material_defaults();
    const char *pose_mode = "fit";
    const char *weights = "noise", *loss = "l2";
    model_opt_t opts[] = {
        MODEL_OPT_STRING("--calib", "DIR", "the calibrations: camera.cameramodel, lamps.json, white.json, optionally "
                         "gain.json and its maps (DIR or DIR/geometry, DIR/lamps, DIR/white, DIR/gain)", &o.calib, true),
        MODEL_OPT_OUT("PRIORS.json", "the priors file to write", &o.out, true),
        MODEL_OPT_STRING("--camera", "NAME", "only camera NAME's frames of a session of several (default every "
                         "camera's, each with its calibrations: DIR/NAME.cameramodel, DIR/NAME/white.json, "
                         "DIR/NAME/gain.json)", &o.camera, false),
        MODEL_OPT_STRING("--scene", "FILE", "the sample's scene (rig frame; D3D, OBJ, STL or PLY; a session "
                         "records none)", &o.scene, false),
        MODEL_OPT_UNITS,
        MODEL_OPT_STRING("--material", "NAME", "its material in the scene (default: the scene's only material)",
                         &o.material, false),
        MODEL_OPT_STRING("--model", "M", MODEL_NAMES " (default all: chosen by cross-validation over the frames)",
                         &o.model, false),
        MODEL_OPT_VALUE("--cv-folds", "K", "folds of the model choice's cross-validation over the frames (default 5; "
                        "0: lowest BIC)", false),
        MODEL_OPT_VALUE("--cv-seed", "N", "seed of the folds' shuffle (default 1)", false),
        MODEL_OPT_STRING("--name", "NAME", "the material's name in the priors (default: the scene's)", &o.name, false),
        MODEL_OPT_VALUE("--k-sigma", "K", "prior bounds mean +- K std (default 3)", false),
        MODEL_OPT_VALUE("--systematic", "REL", "std adds REL * mean (default 0.03)", false),
        MODEL_OPT_VALUE("--lamp-systematic", "REL", "each lamp's own photometric scale has the relative std REL, "
                        "carried through the fit into the std (default 0.03; 0: none)", false),
        MODEL_OPT_VALUE("--place-mm", "MM", "places on the sample for the cluster-robust std: cubes of MM mm (default "
                        "a sixth of the sample's observed extent)", false),
        MODEL_OPT_VALUE("--albedo-cells", "MM", "albedo cells of MM mm for a textured material (default 0: none)",
                        false),
        MODEL_OPT_VALUE("--window", "N", "windows of N x N pixels (default 5)", false),
        MODEL_OPT_VALUE("--step", "N", "on a grid of N pixels (default 8)", false),
        MODEL_OPT_STRING("--sample-pose", "fit|nominal", "the sample's pose: fitted from its outline in the frames "
                         "with the plan's wedge as prior (default fit), or the plan's nominal wedge", &pose_mode, false),
        MODEL_OPT_VALUE("--pose-sigma-deg", "DEG", "the pose prior's std of the wedge's tilt and azimuth (default 1)",
                        false),
        MODEL_OPT_VALUE("--pose-sigma-mm", "MM", "its std of the offset and height (default 2)", false),
        MODEL_OPT_STRING("--report", "DIR", "write an HTML report there", &o.report, false),
        MODEL_OPT_STRING("--weights", "noise|uniform", "each sample weighted by 1/sigma^2 of its own noise from the "
                         "gain calibration (default; uniform without one) or all alike", &weights, false),
        MODEL_OPT_STRING("--loss", "l2|huber|cauchy", "least squares (default) or a robust loss on each sample's "
                         "residual in units of its sigma", &loss, false),
        MODEL_OPT_DOUBLE("--loss-scale", "S", "where the robust loss starts, in sigma (default 2)", &o.loss_scale,
                         0.01, 1e6),
        MODEL_OPT_FLAG("-v", "--verbose", "print every angle", &o.verbose),
    };
    model_cli_t cli = {
        .cmd = "fit material", .synopsis = "SESSION", .opts = opts, .nopts = MODEL_NOPTS(opts),
        .min_positional = 1, .max_positional = 1,
        .about = "BRDF samples of the session's sample material: every window of the material lit by one lamp, dark\n"
                 "and flat corrected, brackets merged to high dynamic range, scaled by the reference white's kc*I of\n"
                 "its lamp (DIR/white.json) with the geometry (DIR/camera.cameramodel) and lamp positions\n"
                 "(DIR/lamps.json); then every requested model is fitted (refl fit brdf) and the priors file written.\n"
                 "With --model all the model is chosen by K-fold cross-validation over the frames (--cv-folds, default\n"
                 "5; a frame's windows are held out together): the fewest parameters within one standard error of the\n"
                 "lowest held-out RMS; BIC and AIC are reported beside it (--cv-folds 0 chooses the lowest BIC).\n"
                 "The sample's scene is given with --scene (a session records none), its material with --material\n"
                 "when the scene has several. Each parameter's std is the statistical one, cluster-robust over the\n"
                 "frames and the places on the sample (--place-mm), each lamp's own photometric scale of relative std\n"
                 "--lamp-systematic (default 0.03) carried through the fit, and REL * mean (--systematic, default\n"
                 "0.03) for the calibrations' shared errors; the prior bounds are mean +- K std (default 3). --report\n"
                 "DIR writes an HTML\n"
                 "report there: measured vs fitted lobes, residual maps, the parameters and the model comparison.\n"
                 "--albedo-cells MM (textured materials: wood, paint): the sample's surface is cut into cells of MM mm,\n"
                 "each with its own albedo factor on the whole reflectance (mean 1 over the observations), fitted\n"
                 "together with the parameters; the priors then hold the mean material and the factors' spread.\n"
                 "Observations are windows of N x N pixels (--window, default 5) on a grid of N pixels (--step, 8).\n"
                 "A session of several cameras: every camera's frames in one fit, each camera's through its own\n"
                 "calibrations in DIR (refl calib gain / white / geometry of that camera); --camera NAME takes one.\n"
                 "The sample's pose (its wedge's tilt and hinge azimuth, its offset on the wedge's face and height) is\n"
                 "fitted first from its outline in the frames (each angle's lamps summed; --sample-pose fit, the\n"
                 "default), the plan's nominal wedge the prior (std --pose-sigma-deg 1, --pose-sigma-mm 2); printed\n"
                 "with its std and difference from the nominal and written to the priors (sample_pose). Edges too weak\n"
                 "keep the nominal, said so; --sample-pose nominal takes the plan's wedge as it is.\n"
                 "Each sample is weighted by its own noise (--weights noise, the default): sigma of R from the gain\n"
                 "calibration (K, read noise, quantisation at its linearised signal, exposure and gain, carried to R\n"
                 "like the sample), the fit minimising sum ((model - R)/sigma)^2; rms_over_noise is then\n"
                 "sqrt(chi^2 / dof) (about 1 when the model fits to the noise). --loss huber|cauchy down-weights\n"
                 "samples beyond --loss-scale sigma (outliers: a speck, a reflection of the fixture).",
    };
    int rc = model_cli_parse(&cli, argc, argv);
    if (rc != MODEL_CLI_OK) return rc;
    if ((rc = calib_cli_window_step(&cli, &o.window, &o.step)) != MODEL_CLI_OK) return rc;
    if ((rc = model_cli_units(&cli, &o.scene_unit_mm))) return rc;
    if (number_opt(&cli, "--k-sigma", false, &o.k_sigma) || number_opt(&cli, "--systematic", true, &o.sys_rel) ||
        number_opt(&cli, "--lamp-systematic", true, &o.lamp_rel) || number_opt(&cli, "--place-mm", false, &o.place_mm) ||
        number_opt(&cli, "--albedo-cells", true, &o.cell_mm) || cv_opts(&cli, &o.cv_folds, &o.cv_seed) ||
        number_opt(&cli, "--pose-sigma-deg", false, &o.pose_sigma_deg) ||
        number_opt(&cli, "--pose-sigma-mm", false, &o.pose_sigma_mm))
        return MODEL_CLI_USAGE;
    if (strcmp(pose_mode, "fit") && strcmp(pose_mode, "nominal"))
        return model_cli_error(&cli, "--sample-pose: fit or nominal, not '%s'", pose_mode);
    o.pose_nominal = !strcmp(pose_mode, "nominal");
    if (strcmp(weights, "noise") && strcmp(weights, "uniform"))
        return model_cli_error(&cli, "--weights: noise or uniform, not '%s'", weights);
    o.noise_weights = !strcmp(weights, "noise");
    if (!fit_loss_parse(loss, &o.loss)) return model_cli_error(&cli, "--loss: l2, huber or cauchy, not '%s'", loss);
    model_brdf_t models[MODEL_BRDF_COUNT];
    int nm;
    if (!fit_brdf_model_list(o.model, models, &nm)) return model_cli_error(&cli, "--model: unknown model %s", o.model);
    o.session = cli.positional[0];
    o.argc = argc + 1;
    o.argv = argv - 1;
    fit_material_result_t *r = malloc(sizeof *r);
    if (!r) {
        fprintf(stderr, "refl fit material: out of memory\n");
        return 1;
    }
    bool ok = fit_material_run(&o, r);
    print_material(&o, r);
    if (ok && o.report) printf("%s/report.html\n", o.report);
    int rc2 = ok ? 0 : model_error_report("fit material");
    fit_material_result_free(r);
    free(r);
    return rc2;
}

// ---------------------------------------------------------------------------
// refl fit

int fit_cmd(int argc, char **argv)
{
    if (argc < 2 || !strcmp(argv[1], "--help") || !strcmp(argv[1], "-h")) {
        FILE *f = argc < 2 ? stderr : stdout;
        fprintf(f, "usage: refl fit brdf FILE ... -o PRIORS.json        (refl fit brdf --help)\n"
                   "       refl fit material SESSION --calib DIR --scene FILE ... -o PRIORS.json   (refl fit material --help)\n"
                   "\n");
        model_cli_exit_status(f);
        fprintf(f, "\nrefl %s\n", REFL_VERSION);
        return argc < 2 ? 2 : 0;
    }
    if (!strcmp(argv[1], "brdf")) return cmd_brdf(argc - 1, argv + 1);
    if (!strcmp(argv[1], "material")) return fit_cmd_material(argc - 1, argv + 1);
    fprintf(stderr, "refl fit: unknown fit '%s' (refl fit --help)\n", argv[1]);
    return 2;
}
