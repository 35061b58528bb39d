// fit/verify/files.c — the verification of files (verify.h, "Verification of
// files"): the description, priors, calibrations and images loaded, the views
// traced, the fit (verify_run), and the outputs written: verify.json,
// points.csv, imgN_actual.tiff and imgN_synthetic.tiff. `refl verify`
// (fit/cmd_verify.c) parses its arguments, calls verify_files_run and prints.
#define _GNU_SOURCE
#include <errno.h>
#include <glib.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "fit/verify/verify.h"
#include "model/base/report.h"

// ---------------------------------------------------------------------------
// Shared with other fits of files (refl plan lamps)

calib_set_t *verify_load_camera_gain(const char *camera, const char *gain_dir, const model_lamps_t *lamps,
                                     const char *tmp_dir, int tag)
{
    char *gj = gain_dir ? g_strdup_printf("%s/gain.json", gain_dir) : NULL;
    if (gj && access(gj, R_OK) != 0) {
        model_error(gain_dir, 0, "no gain.json: not a gain calibration (refl calib gain writes one)");
        g_free(gj);
        return NULL;
    }
    // lamps.json is required by the loader: a minimal one from the lamps (or one placeholder)
    char *tmpl = g_strdup_printf("%s/.lamps-%d.json", tmp_dir, tag);
    model_mkdir_p(tmp_dir);
    json_t *lj = json_object(), *arr = json_array();
    for (int i = 0; lamps && i < lamps->n; i++) {
        const model_lamp_t *l = &lamps->lamps[i];
        json_array_append_new(arr, json_pack("{s:s,s:[f,f,f]}", "name", l->name, "position_mm", l->position_mm.x,
                                             l->position_mm.y, l->position_mm.z));
    }
    if (!lamps) json_array_append_new(arr, json_pack("{s:s,s:[f,f,f]}", "name", "x", "position_mm", 0.0, 0.0, 1000.0));
    json_object_set_new(lj, "lamps", arr);
    model_write_json(tmpl, lj);
    json_decref(lj);
    calib_set_t *cal = calib_set_load_files(camera, tmpl, gj, NULL);
    unlink(tmpl);
    g_free(tmpl);
    g_free(gj);
    return cal;
}

// ---------------------------------------------------------------------------
// Inputs

// What verify_files_run loads; freed by vf_free.
typedef struct {
    const verify_files_opts_t *o;
    json_t                    *prov;       // borrowed (o->provenance)
    model_scene_t             *scene;
    verify_priors_t            pr;
    calib_set_t               *base;       // --calib DIR or NULL
    model_lamps_t             *own_lamps;  // --lamps
    const model_lamps_t       *lamps;      // own_lamps or base's
    double                     A[32];      // kc*I per us per lamp
    calib_set_t               *cal[VERIFY_FILES_MAX];   // per camera (base: borrowed)
    verify_camera_t            vcs[VERIFY_FILES_MAX];
    int                        ncams;
    float                     *px[VERIFY_FILES_MAX];    // the images' pixels
    model_meta_t              *meta[VERIFY_FILES_MAX];  // and their metadata (PNG text)
    char                       img_cam[VERIFY_FILES_MAX][32];   // the rig file's camera each names ("": none)
    char                       named[VERIFY_FILES_MAX][32];     // the cameras the images name, in their order
    int                        nnamed;
    bool                       by_name;    // --calib of several cameras: each image's camera by its name
    double                     cal_gain[VERIFY_FILES_MAX];      // each camera's gain calibration's gain and unit
    char                       cal_unit[VERIFY_FILES_MAX][16];
    verify_image_t             imgs[VERIFY_FILES_MAX];
    verify_view_t             *views[VERIFY_FILES_MAX]; // images of one camera and angle share one
    model_material_t          *mean_mats;  // the priors' means
    const model_material_t   **mats;
    verify_placement_t         placement;  // registered (o->placement_tol_*), the scene moved to it
} vf_t;

static void vf_free(vf_t *V)
{
    for (int m = 0; m < V->o->nimages; m++) {
        bool shared = false;
        for (int k = 0; k < m; k++) shared |= V->views[k] == V->views[m];
        if (!shared) verify_view_free(V->views[m]);
        free(V->px[m]);
        model_meta_free(V->meta[m]);
    }
    for (int c = 0; c < V->ncams; c++)
        if (V->cal[c] != V->base) calib_set_free(V->cal[c]);
    calib_set_free(V->base);
    model_lamps_free(V->own_lamps);
    verify_priors_free(&V->pr);
    model_scene_free(V->scene);
    free(V->mean_mats);
    free(V->mats);
}

// The description and the priors of its materials (each prior's material on a face).
static bool vf_scene_priors(vf_t *V)
{
    const verify_files_opts_t *o = V->o;
    model_scene_options_t so = MODEL_SCENE_OPTIONS_DEFAULT;
    so.unit_mm = o->scene_unit_mm;
    if (!(V->scene = model_scene_load(o->scene, &so))) return false;
    model_provenance_input(V->prov, "scene", o->scene);
    for (int k = 0; k < o->npriors; k++) {
        if (!verify_priors_load(&V->pr, o->priors[k])) return false;
        model_provenance_input(V->prov, "priors", o->priors[k]);
    }
    // the materials at the priors' means (the interreflection basis)
    V->mean_mats = calloc((size_t)V->scene->nmaterials + 1, sizeof *V->mean_mats);
    V->mats = calloc((size_t)V->scene->nmaterials + 1, sizeof *V->mats);
    if (!V->mean_mats || !V->mats) {
        model_error(NULL, 0, "out of memory");
        return false;
    }
    if (!verify_priors_means(V->scene, &V->pr, V->mean_mats, V->mats)) return false;
    for (int k = 0; k < V->pr.n; k++)
        if (model_scene_material_index(V->scene, V->pr.m[k].name) < 0) {
            model_error(V->pr.m[k].source, 0, "priors for material '%s', which no face of %s has: check that the "
                        "description and the priors belong together (a material name mistyped in one of them?)",
                        V->pr.m[k].name, o->scene);
            return false;
        }
    return true;
}

// The first camera model's path: --camera-model, else the calibration directory's (NULL: none). g_free.
static char *vf_camera0(const vf_t *V)
{
    if (V->o->ncameras) return g_strdup(V->o->cameras[0]);
    if (!V->base) return NULL;
    return g_strdup(json_string_value(json_object_get(json_array_get(V->base->inputs, 0), "path")));
}

// The lamps: --lamps (lamps.json of refl calib lamps, or a lamps INI), else the calibration directory's.
static bool vf_lamps(vf_t *V)
{
    const verify_files_opts_t *o = V->o;
    if (!o->lamps) {
        V->lamps = V->base->lamps;
        return true;
    }
    if (g_str_has_suffix(o->lamps, ".json")) {
        char *cam0 = vf_camera0(V);
        calib_set_t *lc = cam0 ? calib_set_load_files(cam0, o->lamps, NULL, NULL) : NULL;
        g_free(cam0);
        if (!lc) return false;
        V->own_lamps = lc->lamps;
        lc->lamps = NULL;
        calib_set_free(lc);
    } else if (!(V->own_lamps = model_lamps_load(o->lamps))) {
        return false;
    }
    V->lamps = V->own_lamps;
    model_provenance_input(V->prov, "lamps", o->lamps);
    return true;
}

// The white calibration's kc*I per lamp, read against the lamps.json it was made with.
static bool vf_white(vf_t *V)
{
    const verify_files_opts_t *o = V->o;
    char *cam0 = vf_camera0(V), *lj = NULL;
    if (o->lamps && g_str_has_suffix(o->lamps, ".json")) {
        lj = g_strdup(o->lamps);
    } else if (V->base) {
        for (size_t k = 0; k < json_array_size(V->base->inputs); k++) {
            json_t *e = json_array_get(V->base->inputs, k);
            if (!strcmp(json_string_value(json_object_get(e, "role")), "lamps"))
                lj = g_strdup(json_string_value(json_object_get(e, "path")));
        }
    }
    if (!lj) {
        model_error(o->white, 0, "a white calibration needs the lamps.json it was made with (--lamps or --calib)");
        g_free(cam0);
        return false;
    }
    calib_set_t *wc = cam0 ? calib_set_load_files(cam0, lj, NULL, o->white) : NULL;
    g_free(cam0);
    g_free(lj);
    if (!wc) return false;
    for (int i = 0; i < V->lamps->n && i < 32; i++) {
        int j = model_lamps_find(wc->lamps, V->lamps->lamps[i].name);
        V->A[i] = j >= 0 ? wc->kcI_per_us[j] : 0;
    }
    calib_set_free(wc);
    model_provenance_input(V->prov, "white", o->white);
    return true;
}

// kc*I per lamp: the white calibration, else kc_per_us * intensity, else the directory's white.json.
static bool vf_scale(vf_t *V)
{
    const verify_files_opts_t *o = V->o;
    const model_lamps_t *lamps = V->lamps;
    if (o->white) {
        if (!vf_white(V)) return false;
    } else if (o->kc_per_us > 0) {
        for (int i = 0; i < lamps->n && i < 32; i++) V->A[i] = o->kc_per_us * lamps->lamps[i].intensity;
    } else if (V->base && V->base->have_white && lamps == V->base->lamps) {
        for (int i = 0; i < lamps->n && i < 32; i++) V->A[i] = V->base->kcI_per_us[i];
    } else {
        model_error(NULL, 0, "no absolute scale for the lamps: give --white WHITE.json (refl calib white), a --calib "
                    "directory with white.json, or --kc-per-us with a lamps INI's intensities");
        return false;
    }
    for (int i = 0; i < lamps->n; i++)
        if (!(V->A[i] > 0) || !isfinite(V->A[i])) {
            model_error(NULL, 0, "lamp %s has no positive kc*I (%g): check the white calibration / intensities",
                        lamps->lamps[i].name, V->A[i]);
            return false;
        }
    return true;
}

// The cameras: --camera-model (one, or one per image) with --gain-calib (none, one, or one per camera), else the
// calibration directory's; without --gain-calib the directory's gain calibration applies to a given camera too.
// One camera's calibration into V->vcs[c] (g: its gain calibration's set).
static void vf_camera_fill(vf_t *V, int c, const calib_set_t *cal, const calib_set_t *g)
{
    verify_camera_t *vc = &V->vcs[c];
    vc->cam = cal->cam;
    bool same_size = g->W == cal->W && g->H == cal->H;
    vc->offset_dn = same_size ? g->offset_dn : NULL;
    vc->flat = same_size ? g->flat : NULL;
    vc->K_dn_per_e = g->gain_dn_per_e;
    vc->read_noise_e = g->read_noise_e;
    vc->saturation_dn = g->saturation_dn;
    vc->lin = &g->lin;
    vc->kc_rel = 1;
    // the pixels' footprint and the optics' blur (fit/verify/footprint.h): the options', else the geometry
    // calibration's (calib/geometry/psf.c), else the whole pixel and no blur
    const verify_files_opts_t *o = V->o;
    vc->psf_sigma_px = isfinite(o->psf_sigma_px) ? o->psf_sigma_px : cal->have_psf ? cal->psf_sigma_px : 0;
    vc->pixel_fill = isfinite(o->pixel_fill) ? o->pixel_fill : cal->have_psf ? cal->psf_pixel_fill : 1;
    V->cal_gain[c] = g->cal_gain;
    snprintf(V->cal_unit[c], sizeof V->cal_unit[c], "%s", g->cal_gain_unit);
}

// --calib DIR of several cameras: camera c is the c-th the images name, with
// its own calibrations (calib_set_load_camera); its sensitivity relative to
// the lamps' scale (the first camera's white) is the mean ratio of its own
// white's kc*I to that scale over the lamps.
static bool vf_cameras_by_name(vf_t *V)
{
    const verify_files_opts_t *o = V->o;
    if (o->ngain) {
        model_error(o->calib, 0, "--gain-calib with the calibrations of several cameras: each camera's gain "
                    "calibration is its own there (NAME/gain.json)");
        return false;
    }
    for (int c = 0; c < V->nnamed; c++) {
        V->cal[c] = c == 0 ? V->base : calib_set_load_camera(o->calib, V->named[c], false);
        if (!V->cal[c]) return false;
        V->ncams = c + 1;
        const calib_set_t *cal = V->cal[c];
        g_strlcpy(V->vcs[c].name, V->named[c], sizeof V->vcs[c].name);
        vf_camera_fill(V, c, cal, cal);
        bool own_scale = !o->white && !(o->kc_per_us > 0);
        if (c > 0 && own_scale && cal->have_white) {
            double r = 0;
            int n = 0;
            for (int i = 0; i < V->lamps->n && i < 32; i++) {
                int j = model_lamps_find(cal->lamps, V->lamps->lamps[i].name);
                if (j >= 0 && cal->kcI_per_us[j] > 0 && V->A[i] > 0) r += cal->kcI_per_us[j] / V->A[i], n++;
            }
            if (n) V->vcs[c].kc_rel = r / n;
        } else if (c > 0 && own_scale) {
            model_error(o->calib, 0, "camera %s has no white calibration (%s/white.json): its sensitivity is "
                        "unknown; run refl calib white --camera %s", V->named[c], V->named[c], V->named[c]);
            return false;
        }
        for (size_t k = 0; c > 0 && k < json_array_size(cal->inputs); k++) {
            json_t *e = json_array_get(cal->inputs, k);
            model_provenance_input(V->prov, json_string_value(json_object_get(e, "role")),
                                   json_string_value(json_object_get(e, "path")));
        }
    }
    for (size_t k = 0; k < json_array_size(V->base->inputs); k++) {
        json_t *e = json_array_get(V->base->inputs, k);
        model_provenance_input(V->prov, json_string_value(json_object_get(e, "role")),
                               json_string_value(json_object_get(e, "path")));
    }
    for (int m = 0; m < V->o->nimages; m++) {
        V->imgs[m].camera = -1;
        for (int c = 0; c < V->nnamed; c++)
            if (!strcmp(V->img_cam[m], V->named[c])) V->imgs[m].camera = c;
        if (V->imgs[m].camera < 0) {
            model_error(V->imgs[m].name, 0, "the image names no camera (no camera_name in its text) and the "
                        "calibrations are of several cameras: give --camera-model");
            return false;
        }
    }
    return true;
}

static bool vf_cameras(vf_t *V)
{
    const verify_files_opts_t *o = V->o;
    if (V->by_name) return vf_cameras_by_name(V);
    int want = o->ncameras ? o->ncameras : 1;
    if (o->ngain > 1 && o->ngain != want) {
        model_error(NULL, 0, "%d gain calibrations for %d cameras: give one, or one per camera", o->ngain, want);
        return false;
    }
    for (int c = 0; c < want; c++) {
        const char *gdir = o->ngain ? o->gain[o->ngain == 1 ? 0 : c] : NULL;
        if (o->ncameras || gdir) {
            char *campath = o->ncameras ? g_strdup(o->cameras[c]) : vf_camera0(V);
            V->cal[c] = verify_load_camera_gain(campath, gdir, V->lamps, o->out, c);
            if (V->cal[c]) {
                model_provenance_input(V->prov, "camera", campath);
                if (gdir) {
                    char *gj = g_strdup_printf("%s/gain.json", gdir);
                    model_provenance_input(V->prov, "gain", gj);
                    g_free(gj);
                }
            }
            g_free(campath);
        } else {
            V->cal[c] = V->base;   // borrowed
        }
        if (!V->cal[c]) return false;
        const calib_set_t *cal = V->cal[c], *g = o->ngain ? cal : V->base ? V->base : cal;
        snprintf(V->vcs[c].name, sizeof V->vcs[c].name, "%d", c);
        vf_camera_fill(V, c, cal, g);
        V->ncams++;
    }
    for (int m = 0; m < o->nimages; m++) V->imgs[m].camera = V->ncams == 1 ? 0 : m;
    for (size_t k = 0; V->base && k < json_array_size(V->base->inputs); k++) {
        json_t *e = json_array_get(V->base->inputs, k);
        model_provenance_input(V->prov, json_string_value(json_object_get(e, "role")),
                               json_string_value(json_object_get(e, "path")));
    }
    return true;
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
    if (!dup) {
        model_error(where, 0, "out of memory");
        return false;
    }
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

// An image's pixels: a 16-bit PNG (with its metadata) or a float TIFF. NULL + message.
static float *read_pixels(const char *path, int *W, int *H, model_meta_t *meta)
{
    bool is_png = false;
    FILE *f = fopen(path, "rb");
    unsigned char sig[8] = { 0 };
    if (f) {
        is_png = fread(sig, 1, 8, f) == 8 && sig[0] == 0x89 && sig[1] == 'P';
        fclose(f);
    }
    if (!is_png) return model_image_read_float(path, W, H);
    uint16_t *pix = NULL;
    if (!model_png_read_meta(path, W, H, &pix, meta)) return NULL;
    float *px = malloc((size_t)*W * *H * sizeof(float));
    if (!px) model_error(path, 0, "out of memory for a %dx%d image", *W, *H);
    for (size_t p = 0; px && p < (size_t)*W * *H; p++) px[p] = pix[p];
    free(pix);
    return px;
}

// The gain of the metadata, in dB relative to the gain calibration's gain
// (cal_gain in cal_unit): "gain" ("6", or "6 UNIT") in the unit of
// "gain_unit" (else the one after the number; neither: dB, the unit of
// frames whose metadata names none), converted by model_gain_factor. false +
// message naming the image.
static bool meta_gain_db(const char *path, const char *ga, const char *unit, double cal_gain, const char *cal_unit,
                         double *gain_db)
{
    double g;
    char tmp[64], suffix[32] = "";
    snprintf(tmp, sizeof tmp, "%.63s", ga);
    char *sp = strchr(tmp, ' ');
    if (sp) {   // "6 dB"; a remark in parentheses ("6 (the camera's unit; ...)", refl rig snap) is no unit
        *sp = 0;
        if (sp[1] != '(') snprintf(suffix, sizeof suffix, "%.*s", (int)strcspn(sp + 1, " "), sp + 1);
    }
    if (!model_parse_double(tmp, &g)) {
        model_error(path, 0, "metadata gain '%s' is not a number: give --gain-db", ga);
        return false;
    }
    double f;
    if (!model_gain_factor(g, unit && *unit ? unit : suffix, cal_gain, cal_unit, path, &f)) {
        model_error(NULL, 0, "%s", model_last_error());
        return false;
    }
    *gain_db = 20 * log10(f);
    return true;
}

// Image m's angle, lamps, exposure and gain: the options, else its metadata. false + message.
static bool image_conditions(const vf_t *V, verify_image_t *im, const model_meta_t *meta)
{
    const verify_files_opts_t *o = V->o;
    const char *path = im->name;
    const char *ang = model_meta_get(meta, "turntable_measured_deg");
    if (!ang || !model_parse_double(ang, &im->angle_deg)) {
        ang = model_meta_get(meta, "turntable_commanded_deg");
        if (ang && !model_parse_double(ang, &im->angle_deg)) ang = NULL;
    }
    const char *lo = o->lamps_on ? o->lamps_on : model_meta_get(meta, "lamps_on");
    const char *ex = model_meta_get(meta, "exposure_us"), *ga = model_meta_get(meta, "gain");
    if (o->have_angle) im->angle_deg = o->angle_deg;
    if (!o->have_angle && !ang) {
        model_error(path, 0, "no turntable angle in the image's metadata: give --angle-deg");
        return false;
    }
    if (!lo) {
        model_error(path, 0, "no lamps_on in the image's metadata: give --lamps-on NAMES");
        return false;
    }
    if (!lamp_mask(lo, V->lamps, &im->lamps_on, path)) return false;
    bool ok = true;
    if (o->have_exposure) {
        im->exposure_us = o->exposure_us;
    } else if (!ex || !model_parse_double(ex, &im->exposure_us) || !(im->exposure_us > 0)) {
        model_error(path, 0, "no exposure_us in the image's metadata: give --exposure-us");
        ok = false;
    }
    char given[64];
    snprintf(given, sizeof given, "%.10g dB", o->gain_db);   // --gain-db: the camera's gain in dB
    if (o->have_gain) ga = given;
    if (ga && !meta_gain_db(path, ga, o->have_gain ? "dB" : model_meta_get(meta, "gain_unit"),
                            V->cal_gain[im->camera], V->cal_unit[im->camera], &im->gain_db))
        ok = false;
    return ok;
}

// Image m: its pixels and metadata, and the camera it names (the rig file's, "camera_name").
static bool vf_read_image(vf_t *V, int m)
{
    verify_image_t *im = &V->imgs[m];
    const char *path = V->o->images[m];
    snprintf(im->name, sizeof im->name, "%s", path);
    V->meta[m] = model_meta_new();
    V->px[m] = read_pixels(path, &im->W, &im->H, V->meta[m]);
    im->P = V->px[m];
    if (!V->px[m] || !model_provenance_input(V->prov, "image", path)) return false;
    const char *cn = model_meta_get(V->meta[m], "camera_name");   // "left (the rig file's camera)"
    snprintf(V->img_cam[m], sizeof V->img_cam[m], "%.*s", cn ? (int)strcspn(cn, " ") : 0, cn ? cn : "");
    bool seen = !V->img_cam[m][0];
    for (int c = 0; c < V->nnamed && !seen; c++) seen = !strcmp(V->named[c], V->img_cam[m]);
    if (!seen) snprintf(V->named[V->nnamed++], sizeof V->named[0], "%s", V->img_cam[m]);
    return true;
}

// Image m's conditions (its camera known).
static bool vf_image(vf_t *V, int m)
{
    verify_image_t *im = &V->imgs[m];
    if (!image_conditions(V, im, V->meta[m])) return false;
    if (im->lamps_on == 0) {
        model_error(im->name, 0, "no lamp was on: such an image has nothing to verify with (a dark frame?)");
        return false;
    }
    return true;
}

// --calib DIR: its calibration set; of the first camera the images name when
// they name several, or one that DIR has its own calibrations of (by_name),
// but for "camera", a rig's one plain [camera], whose calibrations are the
// layout of one camera (DIR/camera.cameramodel: also the first camera's of
// several, as refl calib geometry writes them).
static bool vf_base(vf_t *V)
{
    const verify_files_opts_t *o = V->o;
    const char *n0 = V->named[0];
    V->by_name = !o->ncameras && (V->nnamed > 1 || (V->nnamed == 1 && strcmp(n0, "camera") &&
                                                     calib_set_has_camera(o->calib, n0)));
    V->base = V->by_name ? calib_set_load_camera(o->calib, V->named[0], false) : calib_set_load(o->calib, false);
    return V->base != NULL;
}

// The part's placement within the tolerance (verify_register): the scene
// moved to where the images show it. false + message.
static bool vf_register(vf_t *V)
{
    const verify_files_opts_t *o = V->o;
    if (!(o->placement_tol_mm > 0) && !(o->placement_tol_deg > 0)) return true;
    model_note("registering the placement (within %g mm, %g deg)", o->placement_tol_mm, o->placement_tol_deg);
    if (!verify_register(V->scene, V->vcs, V->lamps, V->A, V->mats, V->imgs, o->nimages, o->placement_tol_mm,
                         o->placement_tol_deg, &V->placement))
        return false;
    model_scene_t *placed = verify_placed_scene(V->scene, &V->placement);
    if (!placed) return false;
    model_scene_free(V->scene);
    V->scene = placed;
    return true;
}

// The placement as JSON (units and conventions named).
static json_t *placement_json(const verify_placement_t *p)
{
    json_t *o = json_object();
    json_object_set_new(o, "convention", json_string("x' = Rz(turn)(x - c) + c + (dx, dy, 0): the part's frame before "
                                                     "the turntable angle, c the middle of the description's "
                                                     "bounding box in x and y; mm and deg"));
    json_object_set_new(o, "dx_mm", json_real(p->dx_mm));
    json_object_set_new(o, "dy_mm", json_real(p->dy_mm));
    json_object_set_new(o, "turn_deg", json_real(p->turn_deg));
    json_object_set_new(o, "centre_mm", json_pack("[f,f]", p->centre_mm[0], p->centre_mm[1]));
    json_object_set_new(o, "tolerance_mm", json_real(p->tol_mm));
    json_object_set_new(o, "tolerance_deg", json_real(p->tol_deg));
    json_object_set_new(o, "edge_agreement", json_real(p->score));
    json_object_set_new(o, "edge_agreement_nominal", json_real(p->score_nominal));
    json_object_set_new(o, "edge_agreement_definition",
                        json_string("sum over predicted edge points of |c| clamp(m/c, -1, 2) / sum |c|: c the "
                                    "predicted contrast across the edge (1 px each side), m the image's; 1: every "
                                    "edge where and as predicted"));
    json_object_set_new(o, "edge_points", json_integer(p->nsamples));
    json_object_set_new(o, "at_limit", json_boolean(p->at_limit));
    return o;
}

// The views (verify_view_new): one per camera and angle, images of both share it.
static bool vf_views(vf_t *V)
{
    const int n = V->o->nimages;
    double t0 = model_now_s();
    for (int m = 0; m < n; m++) {
        const verify_image_t *im = &V->imgs[m];
        const model_camera_t *cam = V->vcs[im->camera].cam;
        // reuse the view of an earlier image of the same camera and angle
        for (int k = 0; k < m && !V->views[m]; k++)
            if (V->imgs[k].camera == im->camera && V->imgs[k].angle_deg == im->angle_deg && V->views[k])
                V->views[m] = V->views[k];
        if (V->views[m]) continue;
        if (im->W != model_camera_width(cam) || im->H != model_camera_height(cam)) {
            model_error(im->name, 0, "the image is %dx%d but its camera model is %dx%d: give the camera model "
                        "calibrated for this camera and image size", im->W, im->H, model_camera_width(cam),
                        model_camera_height(cam));
            return false;
        }
        model_progress("view %d/%d (%s, %.4g deg)", m + 1, n, im->name, im->angle_deg);
        if (!(V->views[m] = verify_view_new(V->scene, &V->vcs[im->camera], im->angle_deg, V->lamps, V->mats,
                                            &V->o->opt))) {
            model_progress_end();
            return false;
        }
    }
    model_progress_end();
    model_note("fitting %d images (views %.2f s)", n, model_now_s() - t0);
    return true;
}

// ---------------------------------------------------------------------------
// Outputs

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

// The fit's interreflection term kc g rho sum_i s_i A_i B_i added to the
// synthetic image (the direct term, face: the faces seen) at every pixel of a
// face: B as the fit makes it (verify_interreflection, the priors' means) on
// a grid of IR_STEP px, each pixel taking the nearest grid point on its own
// face (none within one step: the pixel keeps the direct term). L: the
// lamps with their fitted s_i A_i (0: off). false + message.
#define IR_STEP 4
static bool synthetic_interreflection(const vf_t *V, const verify_result_t *res, int m, const model_tracer_t *t,
                                      const model_lamps_t *L, double kc, const float *gmap, const int32_t *face,
                                      float *synth)
{
    const verify_image_t *im = &V->imgs[m];
    const verify_camera_t *vc = &V->vcs[im->camera];
    int gw = (im->W + IR_STEP - 1) / IR_STEP, gh = (im->H + IR_STEP - 1) / IR_STEP, n = gw * gh, nl = L->n;
    double *q = malloc((size_t)n * 2 * sizeof *q);
    model_pixel_info_t *pi = malloc((size_t)n * sizeof *pi);
    float *B = malloc((size_t)n * (nl ? nl : 1) * sizeof *B);
    bool ok = q && pi && B;
    if (!ok) model_error(im->name, 0, "out of memory for the synthetic image's interreflection");
    for (int g = 0; ok && g < n; g++) {
        q[2 * g] = (g % gw) * IR_STEP;
        q[2 * g + 1] = (g / gw) * IR_STEP;
    }
    ok = ok && model_pixel_info(t, vc->cam, L, q, n, pi, NULL, V->o->opt.threads);
    if (ok) verify_interreflection(t, V->lamps, V->mats, pi, n, V->o->opt.ir_samples, V->o->opt.threads, B);
    for (int y = 0; ok && y < im->H; y++)
        for (int x = 0; x < im->W; x++) {
            size_t p = (size_t)y * im->W + x;
            if (face[p] < 0) continue;
            int gx = (x + IR_STEP / 2) / IR_STEP, gy = (y + IR_STEP / 2) / IR_STEP, best = -1;
            double bd = INFINITY;
            for (int j = gy - 1; j <= gy + 1; j++)
                for (int i = gx - 1; i <= gx + 1; i++) {
                    if (i < 0 || j < 0 || i >= gw || j >= gh || pi[j * gw + i].face != face[p]) continue;
                    double d = hypot(i * IR_STEP - x, j * IR_STEP - y);
                    if (d < bd) bd = d, best = j * gw + i;
                }
            if (best < 0) continue;
            double acc = 0;
            for (int i = 0; i < nl; i++) acc += L->lamps[i].intensity * B[(size_t)best * nl + i];
            synth[p] += (float)(kc * (gmap ? gmap[p] : 1) * res->rho * acc);
        }
    free(q);
    free(pi);
    free(B);
    return ok;
}

// The synthetic image of image m: the fitted model's direct term at every
// pixel and its interreflection term (synthetic_interreflection; W*H into
// synth), NaN where the description has no surface.
// A separable Gaussian of sigma px over the finite pixels of img (W x H), in
// place: each pixel the kernel-weighted mean of its finite neighbours (NaN
// stays NaN: no surface is not blurred into). false: out of memory.
static bool blur_surfaces(float *img, int W, int H, double sigma)
{
    int r = (int)ceil(3 * sigma);
    double *k = malloc((size_t)(2 * r + 1) * sizeof *k);
    float *tmp = malloc((size_t)W * H * sizeof *tmp);
    if (!k || !tmp) {
        free(k);
        free(tmp);
        model_error(NULL, 0, "out of memory for the synthetic image's blur");
        return false;
    }
    for (int j = -r; j <= r; j++) k[j + r] = exp(-0.5 * j * j / (sigma * sigma));
    for (int pass = 0; pass < 2; pass++) {
        const float *src = pass ? tmp : img;
        float *dst = pass ? img : tmp;
        for (int y = 0; y < H; y++)
            for (int x = 0; x < W; x++) {
                size_t i = (size_t)y * W + x;
                if (!isfinite(src[i])) {
                    dst[i] = src[i];
                    continue;
                }
                double s = 0, ws = 0;
                for (int j = -r; j <= r; j++) {
                    int xx = pass ? x : x + j, yy = pass ? y + j : y;
                    if (xx < 0 || yy < 0 || xx >= W || yy >= H) continue;
                    float v = src[(size_t)yy * W + xx];
                    if (!isfinite(v)) continue;
                    s += k[j + r] * v;
                    ws += k[j + r];
                }
                dst[i] = (float)(s / ws);
            }
    }
    free(k);
    free(tmp);
    return true;
}

static bool synthetic_image(const vf_t *V, const verify_result_t *res, int m, float *synth)
{
    const verify_image_t *im = &V->imgs[m];
    const verify_camera_t *vc = &V->vcs[im->camera];
    const model_scene_t *scene = V->scene;
    size_t npx = (size_t)im->W * im->H;
    model_lamps_t L = *V->lamps;
    model_lamp_t ll[32];
    for (int i = 0; i < V->lamps->n; i++) {
        ll[i] = V->lamps->lamps[i];
        ll[i].radius_mm = 0;
        ll[i].intensity = ((im->lamps_on >> i) & 1) ? res->s[i] * V->A[i] : 0;
    }
    L.lamps = ll;
    model_shading_t sh = model_shading_default();
    double gf = 1;   // gain_db: dB relative to the calibration (meta_gain_db); checked by the fit
    model_gain_factor(im->gain_db, "dB", 0, "dB", im->name, &gf);
    sh.kc = im->exposure_us * gf * res->kc[im->camera] * (vc->kc_rel > 0 ? vc->kc_rel : 1);
    sh.Pa = res->Pa[m];
    sh.gain_map = V->o->opt.use_flat ? vc->flat : NULL;
    sh.nthreads = V->o->opt.threads;
    const model_material_t **fm = calloc((size_t)scene->nmaterials + 1, sizeof *fm);
    for (int k = 0; fm && k < scene->nmaterials; k++) fm[k] = &res->mats[k];
    model_scene_t *rot = model_scene_rotated_z(scene, im->angle_deg);
    model_tracer_t *t = rot ? model_tracer_new(rot) : NULL;
    int32_t *face = malloc(npx * sizeof *face);
    if (t && (!face || !fm)) model_error(im->name, 0, "out of memory for the synthetic image");
    bool ok = t && face && fm && model_render(t, vc->cam, &L, fm, &sh, synth, face, NULL);
    free(fm);
    if (ok && V->o->opt.ir_samples > 0 && res->rho != 0)
        ok = synthetic_interreflection(V, res, m, t, &L, sh.kc, sh.gain_map, face, synth);
    if (ok)
        for (size_t q = 0; q < npx; q++)
            if (face[q] < 0) synth[q] = NAN;   // no surface of the description: nothing predicted
    // the pixels' footprint and the optics' blur, as the fit models them near edges: a Gaussian of the same
    // second moment (sigma^2 + fill^2 / 12) over the surfaces
    double sb = sqrt(vc->psf_sigma_px * vc->psf_sigma_px + vc->pixel_fill * vc->pixel_fill / 12);
    if (ok && sb > 0.05) ok = blur_surfaces(synth, im->W, im->H, sb);
    free(face);
    model_tracer_free(t);
    model_scene_free(rot);
    return ok;
}

// imgN_actual.tiff and imgN_synthetic.tiff of image m; its entry of verify.json's "images".
static bool write_image_pair(const vf_t *V, const verify_result_t *res, int m, json_t *ja)
{
    const verify_image_t *im = &V->imgs[m];
    const verify_camera_t *vc = &V->vcs[im->camera];
    const char *dir = V->o->out;
    char an[64], sn[64];
    snprintf(an, sizeof an, "img%d_actual.tiff", m);
    snprintf(sn, sizeof sn, "img%d_synthetic.tiff", m);
    size_t npx = (size_t)im->W * im->H;
    float *act = malloc(npx * sizeof(float)), *synth = malloc(npx * sizeof(float));
    bool maps = V->o->opt.use_flat;
    bool ok = act && synth;
    if (!ok) model_error(im->name, 0, "out of memory for the actual and synthetic images");
    for (size_t p = 0; ok && p < npx; p++) act[p] = im->P[p] - (maps && vc->offset_dn ? vc->offset_dn[p] : 0);
    ok = ok && synthetic_image(V, res, m, synth) &&
         write_tiff(dir, an, im->W, im->H, act, "the image minus the offset map (when given)") &&
         write_tiff(dir, sn, im->W, im->H, synth, "the fitted model: offset + kc g sum_i s_i A_i (V R / d^2 + "
                    "rho B_i) (direct light, and the fit's interreflection term from a 4 px grid, each pixel the "
                    "nearest grid point on its face); NaN where the description has no surface");
    free(act);
    free(synth);
    if (!ok) return false;
    char lampnames[512] = "";
    for (int i = 0; i < V->lamps->n; i++)
        if ((im->lamps_on >> i) & 1)
            snprintf(lampnames + strlen(lampnames), sizeof lampnames - strlen(lampnames), "%s%s",
                     lampnames[0] ? "+" : "", V->lamps->lamps[i].name);
    json_array_append_new(ja, json_pack("{s:s,s:s,s:s,s:s,s:f,s:s,s:f,s:f,s:i}", "name", im->name, "file", im->name,
                                        "actual_tiff", an, "synthetic_tiff", sn, "turntable_deg", im->angle_deg,
                                        "lamps_on", lampnames, "exposure_us", im->exposure_us, "gain_db",
                                        im->gain_db, "camera", im->camera));
    return true;
}

// points.csv: every grid point (written to a temporary file, then renamed).
static bool write_points_csv(const vf_t *V, const verify_result_t *res)
{
    const model_scene_t *scene = V->scene;
    char *cp = g_strdup_printf("%s/points.csv.tmp", V->o->out), *final = g_strdup_printf("%s/points.csv", V->o->out);
    bool ok = false;
    FILE *f = fopen(cp, "w");
    if (!f) {
        model_error(cp, 0, "cannot write: %s", strerror(errno));
        goto done;
    }
    fprintf(f, "image,x_px,y_px,face,status,flag,region,measured_dn,model_dn,sigma_dn,z,footprint\n");
    for (int k = 0; k < res->npoints; k++) {
        const verify_point_t *p = &res->points[k];
        int face = p->face >= 0 && p->face < scene->nfaces ? scene->faces[p->face].number : p->face;
        if (p->status == VERIFY_PT_USED || p->status == VERIFY_PT_EDGE_MEASURED)
            fprintf(f, "%d,%.1f,%.1f,%d,%s,%d,%d,%.3f,%.3f,%.4f,%.4f,%d\n", p->image, p->q[0], p->q[1], face,
                    verify_pt_status_name(p->status), p->flag, p->region, p->meas, p->model, p->sigma, p->z,
                    p->footprint);
        else
            fprintf(f, "%d,%.1f,%.1f,%d,%s,0,-1,,,,,0\n", p->image, p->q[0], p->q[1], face,
                    verify_pt_status_name(p->status));
    }
    ok = fclose(f) == 0;
    if (!ok || rename(cp, final) != 0) {
        model_error(final, 0, "cannot write: %s", strerror(errno));
        ok = false;
    }
done:
    g_free(final);
    g_free(cp);
    return ok;
}

// verify.json (with the TIFFs it names) and points.csv in o->out.
static bool vf_outputs(const vf_t *V, const verify_result_t *res)
{
    const verify_files_opts_t *o = V->o;
    if (!model_mkdir_p(o->out)) return false;
    json_t *doc = verify_result_json(res, V->scene, V->imgs, V->lamps, &o->opt);
    if (o->placement_tol_mm > 0 || o->placement_tol_deg > 0)
        json_object_set_new(doc, "placement", placement_json(&V->placement));
    json_object_set_new(doc, "scene", json_string(o->scene));
    json_object_set_new(doc, "units_and_conventions",
                        json_string("grey values in DN of the images' pixel format; pixel coordinates as mrcal "
                                    "((0,0) the centre of the top-left pixel, x right, y down); lengths mm in the rig "
                                    "frame (origin at the turntable top centre, z up); turntable angles deg"));
    json_t *ja = json_array();
    json_object_set_new(doc, "images", ja);
    bool ok = true;
    for (int m = 0; m < o->nimages && ok; m++) ok = write_image_pair(V, res, m, ja);
    if (ok) {
        json_object_set_new(doc, "provenance", json_incref(V->prov));
        char *jp = g_strdup_printf("%s/verify.json", o->out);
        ok = model_write_json(jp, doc);
        g_free(jp);
    }
    json_decref(doc);
    return ok && write_points_csv(V, res);
}

// ---------------------------------------------------------------------------

bool verify_files_run(const verify_files_opts_t *o, verify_files_result_t *r)
{
    memset(r, 0, sizeof *r);
    if (o->nimages < 1 || o->nimages > VERIFY_FILES_MAX || o->ncameras > VERIFY_FILES_MAX) {
        model_error(NULL, 0, "verify: 1 to %d images and at most as many cameras", VERIFY_FILES_MAX);
        return false;
    }
    vf_t *V = calloc(1, sizeof *V);
    if (!V) {
        model_error(NULL, 0, "out of memory");
        return false;
    }
    V->o = o;
    V->prov = o->provenance;
    bool ok = vf_scene_priors(V);
    for (int m = 0; ok && m < o->nimages; m++) ok = vf_read_image(V, m);
    // calibrations: the base directory, then the overrides
    if (ok && o->calib) ok = vf_base(V);
    ok = ok && vf_lamps(V) && vf_scale(V) && vf_cameras(V);
    for (int m = 0; ok && m < o->nimages; m++) ok = vf_image(V, m);
    ok = ok && vf_register(V) && vf_views(V) &&
         verify_run(V->scene, &V->pr, V->vcs, V->ncams, V->lamps, V->A, V->imgs, o->nimages, V->views, &o->opt,
                    &r->fit);
    r->placement = V->placement;
    if (ok && V->placement.at_limit) {
        // the part may lie further off than the fixture allows: say so with the fit's warnings
        char (*w)[256] = realloc(r->fit.warnings, (size_t)(r->fit.nwarnings + 1) * sizeof *w);
        if (!w) {
            model_error(NULL, 0, "out of memory");
            ok = false;
        } else {
            r->fit.warnings = w;
            snprintf(w[r->fit.nwarnings++], sizeof w[0], "the placement (%.2f, %.2f) mm, %.2f deg is at the edge of "
                     "the tolerance (%g mm, %g deg): the part may lie further off, or the description is wrong",
                     V->placement.dx_mm, V->placement.dy_mm, V->placement.turn_deg, o->placement_tol_mm,
                     o->placement_tol_deg);
        }
    }
    r->nimages = o->nimages;
    memcpy(r->images, V->imgs, sizeof r->images);
    for (int m = 0; m < o->nimages; m++) r->images[m].P = NULL;
    ok = ok && vf_outputs(V, &r->fit);
    vf_free(V);
    free(V);
    return ok;
}

void verify_files_result_free(verify_files_result_t *r)
{
    if (!r) return;
    verify_result_free(&r->fit);
    r->nimages = 0;
}
