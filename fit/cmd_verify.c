// fit/cmd_verify.c — `refl verify`: does a scene description match images?
//
//   refl verify SCENE --images IMG... --priors PRIORS.json... -o DIR
//               [--calib DIR] [--cameras CAM...] [--lamps LAMPS] [--gain-calib DIR...]
//               [--white WHITE.json | --kc-per-us X] [options]
//   refl verify --study -o DIR [--truth FILE] [--cases N]      (fit/verify_study.c)
//
// Images: 16-bit PNG frames as refl capture and refl rig snap write them
// (their text chunks give the turntable angle, the lamps that were on, the
// exposure and the gain; --angle-deg, --lamps-on, --exposure-us, --gain-db
// override for every image), or float TIFFs with those options.
#define _GNU_SOURCE
#include <errno.h>
#include <glib.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <unistd.h>

#include "calib/calib.h"
#include "fit/material.h"
#include "fit/verify.h"
#include "model/report.h"
#include "model/vec.h"

#define MAXN 64

typedef struct {
    const char *scene;
    const char *images[MAXN];
    int         nimages;
    const char *cameras[MAXN];
    int         ncameras;
    const char *priors[MAXN];
    int         npriors;
    const char *gain[MAXN];
    int         ngain;
    const char *calib, *lamps, *white, *out;
    double      kc_per_us;
    double      angle_deg, exposure_us, gain_db;
    const char *lamps_on;
    bool        have_angle, have_exposure, have_gain;
    bool        no_report, fail_on_incorrect, study;
    verify_options_t opt;
    int         cases;
    const char *truth;
    const char *fixed;
} va_t;

static void usage(FILE *f)
{
    fprintf(f,
            "usage: refl verify SCENE --images IMG... --priors PRIORS.json... -o DIR\n"
            "                   [--calib DIR] [--cameras CAM.cameramodel...] [--lamps LAMPS.json|LAMPS.ini]\n"
            "                   [--gain-calib DIR...] [--white WHITE.json | --kc-per-us X] [options]\n"
            "       refl verify --study -o DIR [--truth TRUTH.ini] [--cases N] [--threads N]\n"
            "\n"
            "Fits the imaging model of the description SCENE (D3D or OBJ, rig frame, mm) to reference points of\n"
            "the images, within the materials' priors, and judges whether the description is right.\n"
            "\ninputs:\n"
            "  --images IMG...          16-bit PNG frames of refl capture / refl rig snap (angle, lamps, exposure\n"
            "                           and gain from their text chunks), or float TIFFs (give the options below)\n"
            "  --priors FILE...         priors files of refl fit material / refl fit brdf (every material of SCENE)\n"
            "  --calib DIR              a calibration directory: camera.cameramodel, lamps.json, gain.json + maps,\n"
            "                           white.json (or in geometry/ lamps/ gain/ white/); the options below override\n"
            "  --cameras CAM...         camera models (mrcal, extrinsics in the rig frame): one, or one per image\n"
            "  --lamps FILE             lamps.json of refl calib lamps, or a lamps INI ([lamp NAME] position_mm,\n"
            "                           intensity: then kc*I = X * intensity with --kc-per-us X)\n"
            "  --gain-calib DIR...      gain calibrations (gain.json, offset_dn.tiff, prnu_gain.tiff): one per camera\n"
            "  --white FILE             white.json of refl calib white: kc*I per lamp per us at 0 dB\n"
            "  --kc-per-us X            without a white calibration: kc per us of exposure (lamps INI intensities)\n"
            "  --angle-deg A, --lamps-on NAMES, --exposure-us T, --gain-db G   for every image (override metadata)\n"
            "\noptions:\n"
            "  --spacing-px N (8), --window-px N (5), --edge-margin-px D (2), --boundary-margin-px D (4)\n"
            "  --edge-k K (3), --edge-rel R (0.05)      window std > sqrt(K^2 var_noise + (R S)^2): an edge\n"
            "  --interreflection-samples N (16; 0 none), --model-rel R (0.04), --robust-scale Z (3; 0 plain LSQ)\n"
            "  --lamp-sigma S (0.1), --camera-sigma S (0.1), --pa-sigma-dn S (5: ambient light left after the\n"
            "  offset map), --z-flag Z (4), --min-region N (3)\n"
            "  --score-threshold T (400)\n"
            "  --no-priors                the thesis's fit: physical bounds only, lamps fixed, kc free\n"
            "  --no-gain-maps             ignore the offset maps and flat fields\n"
            "  --fix NAMES                hold parameters: comma list of lamps, cameras, offset, rho, materials\n"
            "  --threads N, --verbose, --no-report, --fail-on-incorrect (exit 3 when the verdict is incorrect)\n"
            "\nOutputs in DIR: verify.json (verdict, score, residue, change regions, parameters against their\n"
            "priors, provenance), points.csv, imgN_actual.tiff / imgN_synthetic.tiff (float DN), and index.html\n"
            "with the figures (scripts/verify_report.py). Prints the residue table in the thesis's form.\n"
            "\nrefl %s\n", REFL_VERSION);
}

#define uerr(...) model_usage_error("verify", __VA_ARGS__)

static bool num(const char *s, double lo, double hi, double *out)
{
    double v;
    if (!s || !model_parse_double(s, &v) || v < lo || v > hi) return false;
    *out = v;
    return true;
}

static int parse(int argc, char **argv, va_t *a)
{
    a->opt = verify_defaults();
    a->cases = 200;
    for (int i = 1; i < argc; i++) {
        const char *o = argv[i];
#define LIST(flag, arr, n)                                                                     \
    if (!strcmp(o, flag)) {                                                                    \
        int start = a->n;                                                                      \
        while (i + 1 < argc && !(argv[i + 1][0] == '-' && argv[i + 1][1])) {               \
            if (a->n >= MAXN) return uerr("%s: at most %d values", flag, MAXN);               \
            a->arr[a->n++] = argv[++i];                                                        \
        }                                                                                      \
        if (a->n == start) return uerr("%s needs at least one value", flag);                  \
        continue;                                                                              \
    }
        LIST("--images", images, nimages)
        LIST("--cameras", cameras, ncameras)
        LIST("--priors", priors, npriors)
        LIST("--gain-calib", gain, ngain)
#undef LIST
        if (!strcmp(o, "--help") || !strcmp(o, "-h")) {
            usage(stdout);
            return -1;
        }
        const char *v = i + 1 < argc ? argv[i + 1] : NULL;
        double d;
#define STR(flag, field)                                                    \
    if (!strcmp(o, flag)) {                                                 \
        if (!v) return uerr("%s needs a value", flag);                     \
        a->field = v;                                                       \
        i++;                                                                \
        continue;                                                           \
    }
#define NUM(flag, lo, hi, dst)                                              \
    if (!strcmp(o, flag)) {                                                 \
        if (!num(v, lo, hi, &d)) return uerr("%s: '%s' is not a number in %g..%g", flag, v ? v : "", (double)(lo), (double)(hi)); \
        dst;                                                                \
        i++;                                                                \
        continue;                                                           \
    }
        STR("--calib", calib)
        STR("--lamps", lamps)
        STR("--white", white)
        STR("-o", out)
        STR("--out", out)
        STR("--lamps-on", lamps_on)
        STR("--truth", truth)
        STR("--fix", fixed)
        NUM("--kc-per-us", 1e-300, 1e300, a->kc_per_us = d)
        NUM("--angle-deg", -1e4, 1e4, (a->angle_deg = d, a->have_angle = true))
        NUM("--exposure-us", 1e-3, 1e9, (a->exposure_us = d, a->have_exposure = true))
        NUM("--gain-db", 0, 60, (a->gain_db = d, a->have_gain = true))
        NUM("--spacing-px", 1, 1000, a->opt.spacing_px = (int)d)
        NUM("--window-px", 1, 99, a->opt.window_px = (int)d)
        NUM("--edge-margin-px", 0, 100, a->opt.edge_margin_px = d)
        NUM("--boundary-margin-px", 0, 100, a->opt.boundary_margin_px = d)
        NUM("--edge-k", 0.1, 1e6, a->opt.edge_k = d)
        NUM("--edge-rel", 0, 10, a->opt.edge_rel = d)
        NUM("--interreflection-samples", 0, 1024, a->opt.ir_samples = (int)d)
        NUM("--model-rel", 0, 10, a->opt.model_rel = d)
        NUM("--robust-scale", 0, 1e6, a->opt.robust_scale = d)
        NUM("--lamp-sigma", 1e-6, 10, a->opt.lamp_sigma = d)
        NUM("--camera-sigma", 1e-6, 10, a->opt.camera_sigma = d)
        NUM("--pa-sigma-dn", 1e-6, 1e6, a->opt.pa_sigma_dn = d)
        NUM("--z-flag", 0.1, 1e6, a->opt.z_flag = d)
        NUM("--min-region", 1, 1e6, a->opt.min_region = (int)d)
        NUM("--score-threshold", 0, 1e300, a->opt.score_threshold = d)
        NUM("--threads", 0, 1024, a->opt.threads = (int)d)
        NUM("--cases", 1, 100000, a->cases = (int)d)
#undef STR
#undef NUM
        if (!strcmp(o, "--no-priors")) { a->opt.use_priors = false; continue; }
        if (!strcmp(o, "--no-gain-maps")) { a->opt.use_flat = false; continue; }
        if (!strcmp(o, "--verbose")) { a->opt.verbose = true; continue; }
        if (!strcmp(o, "--no-report")) { a->no_report = true; continue; }
        if (!strcmp(o, "--fail-on-incorrect")) { a->fail_on_incorrect = true; continue; }
        if (!strcmp(o, "--study")) { a->study = true; continue; }
        if (o[0] == '-' && o[1]) return uerr("unknown option '%s'", o);
        if (a->scene) return uerr("unexpected argument '%s' (one SCENE only)", o);
        a->scene = o;
    }
    if (a->opt.window_px % 2 == 0) return uerr("--window-px must be odd");
    if (!a->out) return uerr("missing -o DIR");
    if (a->study) return 0;
    if (!a->scene) return uerr("missing SCENE");
    if (!a->nimages) return uerr("missing --images IMG...");
    if (!a->npriors) return uerr("missing --priors PRIORS.json");
    if (!a->calib && !a->ncameras) return uerr("missing --cameras (or --calib DIR)");
    if (!a->calib && !a->lamps) return uerr("missing --lamps (or --calib DIR)");
    if (a->ncameras > 1 && a->ncameras != a->nimages)
        return uerr("%d cameras for %d images: give one camera, or one per image", a->ncameras, a->nimages);
    if (a->fixed) {
        char *dup = strdup(a->fixed), *save = NULL;
        for (char *t = strtok_r(dup, ",", &save); t; t = strtok_r(NULL, ",", &save)) {
            if (!strcmp(t, "lamps")) a->opt.fix_lamps = true;
            else if (!strcmp(t, "cameras")) a->opt.fix_cameras = true;
            else if (!strcmp(t, "offset")) a->opt.fix_pa = true;
            else if (!strcmp(t, "rho")) a->opt.fix_rho = true;
            else if (!strcmp(t, "materials")) a->opt.fix_materials = true;
            else {
                int r = uerr("--fix: '%s' is not lamps, cameras, offset, rho or materials", t);
                free(dup);
                return r;
            }
        }
        free(dup);
    }
    return 0;
}

// "east+west", "east,west", "all", "none" -> mask
static bool lamp_mask(const char *s, const model_lamps_t *lamps, uint32_t *mask, const char *where)
{
    *mask = 0;
    if (!strcmp(s, "none") || !s[0]) return true;
    if (!strcmp(s, "all")) {
        *mask = lamps->n >= 32 ? 0xffffffffu : (1u << lamps->n) - 1;
        return true;
    }
    char *dup = strdup(s), *save = NULL;
    bool ok = true;
    for (char *t = strtok_r(dup, "+,", &save); t && ok; t = strtok_r(NULL, "+,", &save)) {
        int i = model_lamps_find(lamps, t);
        if (i < 0) {
            model_error(where, 0, "lamp '%s' is not one of the calibrated lamps (%s)", t, lamps->path);
            ok = false;
        } else {
            *mask |= 1u << i;
        }
    }
    free(dup);
    return ok;
}

typedef struct {
    calib_set_t *cal;            // camera, gain maps (per camera)
    verify_camera_t vc;
} cam_t;

static bool write_tiff(const char *dir, const char *name, int W, int H, const float *px, const char *what)
{
    char *path = g_strdup_printf("%s/%s", dir, name);
    model_meta_t *m = model_meta_new();
    model_meta_add(m, "units", "DN (grey value of the image's pixel format)");
    model_meta_add(m, "image", "%s", what);
    model_meta_add(m, "Software", "refl %s (refl verify)", REFL_VERSION);
    bool ok = model_tiff_write_float(path, W, H, px, model_meta_list(m));
    model_meta_free(m);
    g_free(path);
    return ok;
}

int verify_study_cmd(const char *out, const char *truth, int cases, const verify_options_t *opt, int argc,
                     char **argv);

int verify_cmd(int argc, char **argv)
{
    va_t a = { 0 };
    int rc = parse(argc, argv, &a);
    if (rc) return rc < 0 ? 0 : rc;
    if (a.study) return verify_study_cmd(a.out, a.truth, a.cases, &a.opt, argc, argv);
    int exit_code = 1;
    model_scene_t *scene = NULL;
    verify_priors_t pr = { 0 };
    calib_set_t *base = NULL;
    model_lamps_t *ini_lamps = NULL;
    cam_t cams[MAXN];
    int ncams = 0;
    memset(cams, 0, sizeof cams);
    float *imgs_px[MAXN] = { 0 };
    verify_image_t imgs[MAXN];
    verify_view_t *views[MAXN] = { 0 };
    memset(imgs, 0, sizeof imgs);
    verify_result_t res = { 0 };
    json_t *prov = model_provenance(argc, argv);
    double A[32] = { 0 };
    const model_lamps_t *lamps = NULL;
    model_material_t *mean_mats = NULL;
    const model_material_t **mats = NULL;
    const verify_prior_t **pp = NULL;
    float *synth = NULL, *act = NULL;

    if (!(scene = model_scene_load(a.scene, NULL))) goto done;
    model_provenance_input(prov, "scene", a.scene);
    for (int k = 0; k < a.npriors; k++) {
        if (!verify_priors_load(&pr, a.priors[k])) goto done;
        model_provenance_input(prov, "priors", a.priors[k]);
    }
    pp = calloc((size_t)scene->nmaterials + 1, sizeof *pp);
    if (!pp || !verify_match_priors(scene, &pr, pp)) goto done;
    for (int k = 0; k < pr.n; k++)
        if (model_scene_material_index(scene, pr.m[k].name) < 0) {
            model_error(pr.m[k].source, 0, "priors for material '%s', which no face of %s has: check that the "
                        "description and the priors belong together (a material name mistyped in one of them?)",
                        pr.m[k].name, a.scene);
            goto done;
        }
    // calibrations: the base directory, then the overrides
    if (a.calib && !(base = calib_set_load(a.calib, false))) goto done;
    if (a.lamps) {
        if (g_str_has_suffix(a.lamps, ".json")) {
            calib_set_t *lc = NULL;
            char *cam0 = a.ncameras ? g_strdup(a.cameras[0]) : NULL;
            if (!cam0 && base) {
                json_t *in = json_array_get(base->inputs, 0);
                cam0 = g_strdup(json_string_value(json_object_get(in, "path")));
            }
            lc = cam0 ? calib_set_load_files(cam0, a.lamps, NULL, NULL) : NULL;
            g_free(cam0);
            if (!lc) goto done;
            ini_lamps = lc->lamps;
            lc->lamps = NULL;
            calib_set_free(lc);
        } else if (!(ini_lamps = model_lamps_load(a.lamps))) {
            goto done;
        }
        lamps = ini_lamps;
        model_provenance_input(prov, "lamps", a.lamps);
    } else {
        lamps = base->lamps;
    }
    // kc*I per lamp: the white calibration, else kc_per_us * intensity
    if (a.white) {
        calib_set_t *wc = NULL;
        char *cam0 = a.ncameras ? g_strdup(a.cameras[0]) : NULL;
        if (!cam0 && base) cam0 = g_strdup(json_string_value(json_object_get(json_array_get(base->inputs, 0), "path")));
        // the white file names lamps: read it against the lamps in use
        char *lj = NULL;
        if (a.lamps && g_str_has_suffix(a.lamps, ".json")) lj = g_strdup(a.lamps);
        else if (base) {
            for (size_t k = 0; k < json_array_size(base->inputs); k++) {
                json_t *e = json_array_get(base->inputs, k);
                if (!strcmp(json_string_value(json_object_get(e, "role")), "lamps"))
                    lj = g_strdup(json_string_value(json_object_get(e, "path")));
            }
        }
        if (!lj) {
            model_error(a.white, 0, "a white calibration needs the lamps.json it was made with (--lamps or --calib)");
            g_free(cam0);
            goto done;
        }
        wc = cam0 ? calib_set_load_files(cam0, lj, NULL, a.white) : NULL;
        g_free(cam0);
        g_free(lj);
        if (!wc) goto done;
        for (int i = 0; i < lamps->n && i < 32; i++) {
            int j = model_lamps_find(wc->lamps, lamps->lamps[i].name);
            A[i] = j >= 0 ? wc->kcI_per_us[j] : 0;
        }
        calib_set_free(wc);
        model_provenance_input(prov, "white", a.white);
    } else if (a.kc_per_us > 0) {
        for (int i = 0; i < lamps->n && i < 32; i++) A[i] = a.kc_per_us * lamps->lamps[i].intensity;
    } else if (base && base->have_white && lamps == base->lamps) {
        for (int i = 0; i < lamps->n && i < 32; i++) A[i] = base->kcI_per_us[i];
    } else {
        model_error(NULL, 0, "no absolute scale for the lamps: give --white WHITE.json (refl calib white), a --calib "
                    "directory with white.json, or --kc-per-us with a lamps INI's intensities");
        goto done;
    }
    for (int i = 0; i < lamps->n; i++)
        if (!(A[i] > 0) || !isfinite(A[i])) {
            model_error(NULL, 0, "lamp %s has no positive kc*I (%g): check the white calibration / intensities",
                        lamps->lamps[i].name, A[i]);
            goto done;
        }
    // cameras
    int want = a.ncameras ? a.ncameras : 1;
    for (int c = 0; c < want; c++) {
        cam_t *cm = &cams[ncams];
        const char *gdir = a.ngain ? a.gain[a.ngain == 1 ? 0 : c] : NULL;
        if (a.ngain > 1 && a.ngain != want) {
            model_error(NULL, 0, "%d gain calibrations for %d cameras: give one, or one per camera", a.ngain, want);
            goto done;
        }
        char *gj = gdir ? g_strdup_printf("%s/gain.json", gdir) : NULL;
        if (gj && access(gj, R_OK) != 0) {
            model_error(gdir, 0, "no gain.json: not a gain calibration (refl calib gain writes one)");
            g_free(gj);
            goto done;
        }
        if (a.ncameras || gj) {
            char *campath = a.ncameras ? g_strdup(a.cameras[c])
                                       : g_strdup(json_string_value(json_object_get(json_array_get(base->inputs, 0), "path")));
            // lamps.json is required by the loader: a minimal one from the lamps in use
            char *tmpl = g_strdup_printf("%s/.lamps-%d.json", a.out, c);
            model_mkdir_p(a.out);
            json_t *lj = json_object(), *arr = json_array();
            for (int i = 0; i < lamps->n; i++) {
                const model_lamp_t *l = &lamps->lamps[i];
                json_array_append_new(arr, json_pack("{s:s,s:[f,f,f]}", "name", l->name, "position_mm", l->position_mm.x,
                                                     l->position_mm.y, l->position_mm.z));
            }
            json_object_set_new(lj, "lamps", arr);
            model_write_json(tmpl, lj);
            json_decref(lj);
            cm->cal = calib_set_load_files(campath, tmpl, gj, NULL);
            unlink(tmpl);
            g_free(tmpl);
            if (cm->cal) {
                model_provenance_input(prov, "camera", campath);
                if (gj) model_provenance_input(prov, "gain", gj);
            }
            g_free(campath);
        } else {
            cm->cal = base;   // borrowed
        }
        g_free(gj);
        if (!cm->cal) goto done;
        calib_set_t *cal = cm->cal;
        // without --gain-calib, the base directory's gain calibration applies to the given camera too
        const calib_set_t *g = a.ngain ? cal : base ? base : cal;
        snprintf(cm->vc.name, sizeof cm->vc.name, "%d", c);
        cm->vc.cam = cal->cam;
        bool same_size = g->W == cal->W && g->H == cal->H;
        cm->vc.offset_dn = same_size ? g->offset_dn : NULL;
        cm->vc.flat = same_size ? g->flat : NULL;
        cm->vc.K_dn_per_e = g->gain_dn_per_e;
        cm->vc.read_noise_e = g->read_noise_e;
        cm->vc.saturation_dn = g->saturation_dn;
        cm->vc.nonlin_a_per_dn = g->nonlin_a_per_dn;
        ncams++;
    }
    if (base) {
        for (size_t k = 0; k < json_array_size(base->inputs); k++) {
            json_t *e = json_array_get(base->inputs, k);
            model_provenance_input(prov, json_string_value(json_object_get(e, "role")),
                                   json_string_value(json_object_get(e, "path")));
        }
    }
    // images
    for (int m = 0; m < a.nimages; m++) {
        verify_image_t *im = &imgs[m];
        const char *path = a.images[m];
        snprintf(im->name, sizeof im->name, "%s", path);
        im->camera = ncams == 1 ? 0 : m;
        model_meta_t *meta = model_meta_new();
        uint16_t *pix = NULL;
        int W = 0, H = 0;
        bool is_png = false;
        FILE *f = fopen(path, "rb");
        unsigned char sig[8] = { 0 };
        if (f) {
            is_png = fread(sig, 1, 8, f) == 8 && sig[0] == 0x89 && sig[1] == 'P';
            fclose(f);
        }
        if (is_png) {
            if (!model_png_read_meta(path, &W, &H, &pix, meta)) {
                model_meta_free(meta);
                goto done;
            }
            imgs_px[m] = malloc((size_t)W * H * sizeof(float));
            if (!imgs_px[m]) {
                free(pix);
                model_meta_free(meta);
                goto done;
            }
            for (size_t p = 0; p < (size_t)W * H; p++) imgs_px[m][p] = pix[p];
            free(pix);
        } else if (!(imgs_px[m] = model_image_read_float(path, &W, &H))) {
            model_meta_free(meta);
            goto done;
        }
        im->P = imgs_px[m];
        im->W = W;
        im->H = H;
        const char *ang = model_meta_get(meta, "turntable_measured_deg");
        if (!ang || !model_parse_double(ang, &im->angle_deg)) {
            ang = model_meta_get(meta, "turntable_commanded_deg");
            if (ang && !model_parse_double(ang, &im->angle_deg)) ang = NULL;
        }
        const char *lo = a.lamps_on ? a.lamps_on : model_meta_get(meta, "lamps_on");
        const char *ex = model_meta_get(meta, "exposure_us"), *ga = model_meta_get(meta, "gain");
        if (a.have_angle) im->angle_deg = a.angle_deg;
        bool ok = true;
        if (!a.have_angle && !ang) {
            model_error(path, 0, "no turntable angle in the image's metadata: give --angle-deg");
            ok = false;
        } else if (!lo) {
            model_error(path, 0, "no lamps_on in the image's metadata: give --lamps-on NAMES");
            ok = false;
        } else if (!lamp_mask(lo, lamps, &im->lamps_on, path)) {
            ok = false;
        }
        if (ok) {
            if (a.have_exposure) im->exposure_us = a.exposure_us;
            else if (!ex || !model_parse_double(ex, &im->exposure_us) || !(im->exposure_us > 0)) {
                model_error(path, 0, "no exposure_us in the image's metadata: give --exposure-us");
                ok = false;
            }
            if (a.have_gain) im->gain_db = a.gain_db;
            else if (ga) {
                double gd;
                im->gain_db = model_parse_double(ga, &gd) ? gd : 0;
                if (!model_parse_double(ga, &gd)) {
                    char tmp[64];
                    snprintf(tmp, sizeof tmp, "%.63s", ga);
                    char *sp = strchr(tmp, ' ');
                    if (sp) *sp = 0;
                    im->gain_db = model_parse_double(tmp, &gd) ? gd : 0;
                }
            }
        }
        model_meta_free(meta);
        if (!ok) goto done;
        if (!model_provenance_input(prov, "image", path)) goto done;
        if (im->lamps_on == 0) {
            model_error(path, 0, "no lamp was on: such an image has nothing to verify with (a dark frame?)");
            goto done;
        }
    }
    // the materials at the priors' means (the interreflection basis)
    mean_mats = calloc((size_t)scene->nmaterials + 1, sizeof *mean_mats);
    mats = calloc((size_t)scene->nmaterials + 1, sizeof *mats);
    if (!mean_mats || !mats) goto done;
    for (int k = 0; k < scene->nmaterials; k++) {
        snprintf(mean_mats[k].name, sizeof mean_mats[k].name, "%s", pp[k]->name);
        mean_mats[k].model = pp[k]->model;
        memcpy(mean_mats[k].p, pp[k]->mean, sizeof mean_mats[k].p);
        mats[k] = &mean_mats[k];
    }
    verify_camera_t vcs[MAXN];
    for (int c = 0; c < ncams; c++) vcs[c] = cams[c].vc;
    double t0 = model_now_s();
    for (int m = 0; m < a.nimages; m++) {
        // reuse the view of an earlier image of the same camera and angle
        for (int k = 0; k < m && !views[m]; k++)
            if (imgs[k].camera == imgs[m].camera && imgs[k].angle_deg == imgs[m].angle_deg && views[k]) views[m] = views[k];
        if (views[m]) continue;
        if (imgs[m].W != model_camera_width(vcs[imgs[m].camera].cam) ||
            imgs[m].H != model_camera_height(vcs[imgs[m].camera].cam)) {
            model_error(imgs[m].name, 0, "the image is %dx%d but its camera model is %dx%d: give the camera model "
                        "calibrated for this camera and image size", imgs[m].W, imgs[m].H,
                        model_camera_width(vcs[imgs[m].camera].cam), model_camera_height(vcs[imgs[m].camera].cam));
            goto done;
        }
        fprintf(stderr, "refl verify: view %d/%d (%s, %.4g deg)\n", m + 1, a.nimages, imgs[m].name, imgs[m].angle_deg);
        if (!(views[m] = verify_view_new(scene, &vcs[imgs[m].camera], imgs[m].angle_deg, lamps, mats, &a.opt)))
            goto done;
    }
    fprintf(stderr, "refl verify: fitting %d images (views %.2f s)\n", a.nimages, model_now_s() - t0);
    if (!verify_run(scene, &pr, vcs, ncams, lamps, A, imgs, a.nimages, views, &a.opt, &res)) goto done;
    // outputs
    if (!model_mkdir_p(a.out)) goto done;
    json_t *doc = verify_result_json(&res, scene, imgs, lamps, &a.opt);
    json_object_set_new(doc, "scene", json_string(a.scene));
    json_object_set_new(doc, "units_and_conventions",
                        json_string("grey values in DN of the images' pixel format; pixel coordinates as mrcal "
                                    "((0,0) the centre of the top-left pixel, x right, y down); lengths mm in the rig "
                                    "frame (origin at the turntable top centre, z up); turntable angles deg"));
    json_t *ja = json_array();
    int W0 = imgs[0].W, H0 = imgs[0].H;
    synth = malloc((size_t)W0 * H0 * sizeof(float) * 1);
    for (int m = 0; m < a.nimages; m++) {
        verify_image_t *im = &imgs[m];
        const verify_camera_t *vc = &vcs[im->camera];
        char an[64], sn[64];
        snprintf(an, sizeof an, "img%d_actual.tiff", m);
        snprintf(sn, sizeof sn, "img%d_synthetic.tiff", m);
        size_t npx = (size_t)im->W * im->H;
        act = malloc(npx * sizeof(float));
        float *syn = realloc(synth, npx * sizeof(float));
        if (!act || !syn) goto done;
        synth = syn;
        bool maps = a.opt.use_flat;
        for (size_t p = 0; p < npx; p++) act[p] = im->P[p] - (maps && vc->offset_dn ? vc->offset_dn[p] : 0);
        // the synthetic image: the fitted model's direct term at every pixel
        model_lamps_t L = *lamps;
        model_lamp_t ll[32];
        for (int i = 0; i < lamps->n; i++) {
            ll[i] = lamps->lamps[i];
            ll[i].radius_mm = 0;
            ll[i].intensity = ((im->lamps_on >> i) & 1) ? res.s[i] * A[i] : 0;
        }
        L.lamps = ll;
        model_shading_t sh = model_shading_default();
        sh.kc = im->exposure_us * pow(10, im->gain_db / 20) * res.kc[im->camera];
        sh.Pa = res.Pa[m];
        sh.gain_map = maps ? vc->flat : NULL;
        sh.nthreads = a.opt.threads;
        const model_material_t **fm = calloc((size_t)scene->nmaterials + 1, sizeof *fm);
        for (int k = 0; fm && k < scene->nmaterials; k++) fm[k] = &res.mats[k];
        model_scene_t *rot = model_scene_rotated_z(scene, im->angle_deg);
        model_tracer_t *t = rot ? model_tracer_new(rot) : NULL;
        int32_t *face = malloc(npx * sizeof *face);
        bool rok = t && face && fm && model_render(t, vc->cam, &L, fm, &sh, synth, face, NULL);
        free(fm);
        if (rok)
            for (size_t q = 0; q < npx; q++)
                if (face[q] < 0) synth[q] = NAN;   // no surface of the description: nothing predicted
        free(face);
        model_tracer_free(t);
        model_scene_free(rot);
        if (!rok || !write_tiff(a.out, an, im->W, im->H, act, "the image minus the offset map (when given)") ||
            !write_tiff(a.out, sn, im->W, im->H, synth, "the fitted model: offset + kc g sum_i s_i A_i V R / d^2 "
                        "(direct light; the fit's interreflection term is only at reference points); NaN where "
                        "the description has no surface")) {
            free(act);
            act = NULL;
            goto done;
        }
        free(act);
        act = NULL;
        char lampnames[512] = "";
        for (int i = 0; i < lamps->n; i++)
            if ((im->lamps_on >> i) & 1)
                snprintf(lampnames + strlen(lampnames), sizeof lampnames - strlen(lampnames), "%s%s",
                         lampnames[0] ? "+" : "", lamps->lamps[i].name);
        json_array_append_new(ja, json_pack("{s:s,s:s,s:s,s:s,s:f,s:s,s:f,s:f,s:i}", "name", im->name, "file", im->name,
                                            "actual_tiff", an, "synthetic_tiff", sn, "turntable_deg", im->angle_deg,
                                            "lamps_on", lampnames, "exposure_us", im->exposure_us, "gain_db",
                                            im->gain_db, "camera", im->camera));
    }
    json_object_set_new(doc, "images", ja);
    json_object_set_new(doc, "provenance", json_incref(prov));
    char *jp = g_strdup_printf("%s/verify.json", a.out);
    bool wok = model_write_json(jp, doc);
    g_free(jp);
    json_decref(doc);
    if (!wok) goto done;
    char *cp = g_strdup_printf("%s/points.csv.tmp", a.out);
    FILE *f = fopen(cp, "w");
    if (!f) {
        model_error(cp, 0, "cannot write: %s", strerror(errno));
        g_free(cp);
        goto done;
    }
    fprintf(f, "image,x_px,y_px,face,status,flag,region,measured_dn,model_dn,sigma_dn,z\n");
    for (int k = 0; k < res.npoints; k++) {
        const verify_point_t *p = &res.points[k];
        int face = p->face >= 0 && p->face < scene->nfaces ? scene->faces[p->face].number : p->face;
        if (p->status == VERIFY_PT_USED || p->status == VERIFY_PT_EDGE_MEASURED)
            fprintf(f, "%d,%.1f,%.1f,%d,%s,%d,%d,%.3f,%.3f,%.4f,%.4f\n", p->image, p->q[0], p->q[1], face,
                    verify_pt_status_name(p->status), p->flag, p->region, p->meas, p->model, p->sigma, p->z);
        else
            fprintf(f, "%d,%.1f,%.1f,%d,%s,0,-1,,,,\n", p->image, p->q[0], p->q[1], face,
                    verify_pt_status_name(p->status));
    }
    bool cok = fclose(f) == 0;
    char *final = g_strdup_printf("%s/points.csv", a.out);
    if (!cok || rename(cp, final) != 0) {
        model_error(final, 0, "cannot write: %s", strerror(errno));
        cok = false;
    }
    g_free(final);
    g_free(cp);
    if (!cok) goto done;
    // the thesis's table
    printf("refl verify: %s against %d image(s)\n", a.scene, a.nimages);
    printf("%-28s %8s %10s %10s %10s %10s %8s\n", "image", "points", "max|diff|", "mean|diff|", "std|diff|",
           "robust s", "rms z");
    for (int m = 0; m <= a.nimages; m++) {
        const verify_stats_t *s = m < a.nimages ? &res.per_image[m] : &res.all;
        const char *nm = m < a.nimages ? imgs[m].name : "all";
        const char *base_nm = strrchr(nm, '/') ? strrchr(nm, '/') + 1 : nm;
        printf("%-28.28s %8d %10.1f %10.2f %10.2f %10.2f %8.2f\n", base_nm, s->npoints, s->max_abs, s->mean_abs,
               s->std_abs, s->robust_sigma, s->rms_z);
    }
    int nreg = 0;
    for (int k = 0; k < res.nregions; k++) nreg += res.regions[k].counts;
    printf("change regions: %d; pinned parameters: %d\n", nreg, res.npinned);
    for (int k = 0; k < res.nparams; k++)
        if (res.params[k].pinned)
            printf("  warning: %s = %.6g pinned at its bound [%.6g, %.6g]: its prior may be wrong\n", res.params[k].name,
                   res.params[k].value, res.params[k].lo, res.params[k].hi);
    printf("verdict: description %s (score %.1f, threshold %.1f)\n", res.correct ? "CORRECT" : "INCORRECT", res.score,
           a.opt.score_threshold);
    if (!a.no_report) {
        if (model_run_script("verify_report.py", a.out, NULL) != 0) {
            fprintf(stderr, "refl verify: the report failed: %s (the JSON, CSV and TIFF outputs are written)\n",
                    model_last_error());
            goto done;
        }
        printf("report: %s/index.html\n", a.out);
    }
    exit_code = a.fail_on_incorrect && !res.correct ? 3 : 0;
done:
    for (int m = 0; m < a.nimages; m++) {
        bool shared = false;
        for (int k = 0; k < m; k++) shared |= views[k] == views[m];
        if (!shared) verify_view_free(views[m]);
        free(imgs_px[m]);
    }
    for (int c = 0; c < ncams; c++)
        if (cams[c].cal != base) calib_set_free(cams[c].cal);
    calib_set_free(base);
    model_lamps_free(ini_lamps);
    verify_result_free(&res);
    verify_priors_free(&pr);
    model_scene_free(scene);
    free(mean_mats);
    free(mats);
    free(pp);
    free(synth);
    free(act);
    json_decref(prov);
    return exit_code;
}
