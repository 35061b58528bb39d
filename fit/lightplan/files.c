// fit/lightplan/files.c — the plan of one or several views from files
// (lightplan_lamps_run, see lightplan.h): inputs loaded, per view lightplan_run,
// the check on the virtual rig, plan.json, the images and the report; then the
// capture plan (fit/lightplan/capture_plan.c) and, for several views, their summary.
#define _GNU_SOURCE
#include <glib.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "calib/calib.h"
#include "fit/lightplan/lightplan.h"
#include "fit/verify/verify.h"
#include "fit/eval/lab.h"
#include "model/base/report.h"

lightplan_lamps_opts_t lightplan_lamps_defaults(void)
{
    lightplan_lamps_opts_t o = { .saturation_dn = 4095, .opt = lightplan_defaults(), .report = true };
    o.opt.psf_sigma_px = NAN;   // the geometry calibration's
    return o;
}

void lightplan_lamps_result_free(lightplan_lamps_result_t *r)
{
    if (!r) return;
    for (int k = 0; k < r->nviews; k++) {
        lightplan_result_free(&r->views[k].res);
        g_free(r->views[k].dir);
    }
    free(r->views);
    g_free(r->capture_plan);
    memset(r, 0, sizeof *r);
}

// ---------------------------------------------------------------------------
// Names in the outputs

static const char *face_name(const model_scene_t *s, int f, char *buf, size_t n)
{
    if (f < 0) snprintf(buf, n, "background");
    else if (f < s->nfaces) snprintf(buf, n, "%d", s->faces[f].number);
    else snprintf(buf, n, "sphere %d", f - s->nfaces);
    return buf;
}

// The names of the lamps of set m, "east+west".
static void mask_names(const model_lamps_t *l, uint32_t m, char *buf, size_t n)
{
    buf[0] = 0;
    for (int i = 0; i < l->n; i++)
        if ((m >> i) & 1) snprintf(buf + strlen(buf), n - strlen(buf), "%s%s", buf[0] ? "+" : "", l->lamps[i].name);
}

static json_t *segments_json(const lightplan_segment_t *sg, int n, const model_scene_t *s, const bool *found,
                             const double *measured)
{
    json_t *arr = json_array();
    char b0[32], b1[32];
    for (int k = 0; k < n; k++) {
        const lightplan_segment_t *g = &sg[k];
        json_t *e = json_pack("{s:i,s:i,s:i,s:[f,f],s:[f,f],s:f,s:f,s:f,s:f,s:b,s:s,s:s}", "index", k, "edge",
                              g->edge, "edge_segment", g->segment, "q0_px", g->q0[0],
                              g->q0[1], "q1_px", g->q1[0], g->q1[1], "length_px", g->length_px, "dP_dn", g->dP,
                              "sobel_factor", g->sobel_factor,
                              "sobel_predicted_dn", g->gradient, "detectable", g->detectable, "face_side0",
                              face_name(s, g->face_side[0], b0, sizeof b0), "face_side1",
                              face_name(s, g->face_side[1], b1, sizeof b1));
        if (found && measured) {
            json_object_set_new(e, "sobel_measured_dn", model_json_number(measured[k]));
            json_object_set_new(e, "found", isfinite(measured[k]) ? json_boolean(found[k]) : json_null());
        }
        json_array_append_new(arr, e);
    }
    return arr;
}

// ---------------------------------------------------------------------------
// Inputs

typedef struct {
    json_t                   *prov;
    model_scene_t            *scene;
    model_camera_t           *cam;
    model_lamps_t            *lamps;    // owned, or wc's
    model_materials_t        *mfile;
    model_material_t         *mm;       // the priors' means
    const model_material_t  **mats;     // per scene material
    calib_set_t              *gc, *wc;  // gain calibration, white calibration
    verify_priors_t           pr;
    double                    A[MAXL_PLAN];
    lightplan_sensor_t        sensor;
    double                    psf_sigma_std_px;   // the PSF's 1-sigma (NAN: given, not measured)
    char                      psf_source[512];    // where its sigma came from
} plan_inputs_t;

static void inputs_free(plan_inputs_t *in)
{
    verify_priors_free(&in->pr);
    free(in->mm);
    free(in->mats);
    model_materials_free(in->mfile);
    if (in->wc) calib_set_free(in->wc);
    else model_lamps_free(in->lamps);
    calib_set_free(in->gc);
    model_scene_free(in->scene);
    model_camera_free(in->cam);
    json_decref(in->prov);
    memset(in, 0, sizeof *in);
}

// The candidates and their kc*I per us: lamps.json with the white's, or a
// lamps INI times kc_per_us.
static bool load_lamps(const lightplan_lamps_opts_t *o, plan_inputs_t *in)
{
    if (g_str_has_suffix(o->lamps, ".json")) {
        if (!o->white) {
            model_error_set(o->lamps, 0, "a lamps.json has positions only: give --white WHITE.json for kc*I");
            return false;
        }
        if (!(in->wc = calib_set_load_files(o->camera, o->lamps, NULL, o->white))) return false;
        in->lamps = in->wc->lamps;
        for (int i = 0; i < in->lamps->n && i < MAXL_PLAN; i++) in->A[i] = in->wc->kcI_per_us[i];
        model_provenance_input(in->prov, "white", o->white);
    } else {
        if (!(in->lamps = model_lamps_load(o->lamps))) return false;
        if (!(o->kc_per_us > 0)) {
            model_error_set(o->lamps, 0, "a lamps INI needs --kc-per-us X (kc*I = X * intensity)");
            return false;
        }
        for (int i = 0; i < in->lamps->n && i < MAXL_PLAN; i++) in->A[i] = o->kc_per_us * in->lamps->lamps[i].intensity;
    }
    model_provenance_input(in->prov, "lamps", o->lamps);
    if (in->lamps->n > MAXL_PLAN) {
        model_error_set(o->lamps, 0, "%d candidate lamps: at most %d", in->lamps->n, MAXL_PLAN);
        return false;
    }
    return true;
}

// The scene's materials: a materials INI, or priors (their means, matched by name).
static bool load_materials(const lightplan_lamps_opts_t *o, plan_inputs_t *in)
{
    const model_scene_t *scene = in->scene;
    in->mats = calloc((size_t)scene->nmaterials + 1, sizeof *in->mats);
    in->mm = calloc((size_t)scene->nmaterials + 1, sizeof *in->mm);
    if (!in->mats || !in->mm) {
        model_error_set(NULL, 0, "out of memory");
        return false;
    }
    if (!g_str_has_suffix(o->materials[0], ".json")) {
        if (o->nmaterials > 1) {
            model_error_set(o->materials[0], 0, "one materials INI (several files: priors JSON)");
            return false;
        }
        if (!(in->mfile = model_materials_load(o->materials[0]))) return false;
        if (!model_resolve_materials(scene, in->mfile, in->mats)) return false;
        model_provenance_input(in->prov, "materials", o->materials[0]);
        return true;
    }
    for (int k = 0; k < o->nmaterials; k++) {
        if (!verify_priors_load(&in->pr, o->materials[k])) return false;
        model_provenance_input(in->prov, "materials", o->materials[k]);
    }
    const verify_prior_t **pm = calloc((size_t)scene->nmaterials + 1, sizeof *pm);
    if (!pm) {
        model_error_set(NULL, 0, "out of memory");
        return false;
    }
    bool ok = verify_match_priors(scene, &in->pr, pm);
    for (int k = 0; ok && k < scene->nmaterials; k++) {
        snprintf(in->mm[k].name, sizeof in->mm[k].name, "%s", pm[k]->name);
        in->mm[k].model = pm[k]->model;
        memcpy(in->mm[k].p, pm[k]->mean, sizeof in->mm[k].p);
        in->mats[k] = &in->mm[k];
    }
    free(pm);
    return ok;
}

// The sensor: the gain calibration of gain_dir (K, read noise, saturation,
// mean dark offset, flat field), else the options' saturation and offset.
static bool load_sensor(const lightplan_lamps_opts_t *o, plan_inputs_t *in)
{
    in->sensor = (lightplan_sensor_t){ .offset_dn = o->offset_dn, .saturation_dn = o->saturation_dn };
    if (!o->gain_dir) return true;
    char *gj = g_strdup_printf("%s/gain.json", o->gain_dir);
    // the loader wants lamps.json: a minimal one
    model_mkdir_p(o->out);
    char *tl = g_strdup_printf("%s/.lamps.json", o->out);
    json_t *lj = json_pack("{s:[{s:s,s:[f,f,f]}]}", "lamps", "name", "x", "position_mm", 0.0, 0.0, 1000.0);
    model_write_json(tl, lj);
    json_decref(lj);
    in->gc = calib_set_load_files(o->camera, tl, gj, NULL);
    unlink(tl);
    g_free(tl);
    if (in->gc) model_provenance_input(in->prov, "gain", gj);
    g_free(gj);
    if (!in->gc) return false;
    const calib_set_t *gc = in->gc;
    in->sensor.K_dn_per_e = gc->gain_dn_per_e;
    in->sensor.read_noise_e = gc->read_noise_e;
    if (gc->saturation_dn > 0) in->sensor.saturation_dn = gc->saturation_dn;
    if (gc->offset_dn) {
        double s = 0;
        for (size_t p = 0; p < (size_t)gc->W * gc->H; p++) s += gc->offset_dn[p];
        in->sensor.offset_dn = s / ((double)gc->W * gc->H);
    }
    in->sensor.flat = gc->flat;
    return true;
}

// The PSF's sigma of the edges' Sobel response: --psf-sigma-px, else the
// geometry calibration's beside the camera model, else 0 (a sharp step):
// into oo->opt and r.
static void resolve_psf(lightplan_lamps_opts_t *oo, plan_inputs_t *in, lightplan_lamps_result_t *r)
{
    double s, sd;
    char *gj = NULL;
    r->psf_sigma_std_px = NAN;
    if (isfinite(oo->opt.psf_sigma_px)) {
        r->psf_sigma_px = oo->opt.psf_sigma_px;
        snprintf(r->psf_source, sizeof r->psf_source, "--psf-sigma-px");
    } else if (calib_psf_read(oo->camera, NULL, &s, &sd, NULL, &gj)) {
        r->psf_sigma_px = s;
        r->psf_sigma_std_px = sd;
        snprintf(r->psf_source, sizeof r->psf_source, "%s (refl calib geometry's psf)", gj);
        model_provenance_input(in->prov, "geometry", gj);
    } else {
        r->psf_sigma_px = 0;
        snprintf(r->psf_source, sizeof r->psf_source, "none: no lens blur beside the camera model (geometry.json's "
                 "psf of refl calib geometry) nor --psf-sigma-px; a sharp step, the pixel's footprint alone");
    }
    g_free(gj);
    oo->opt.psf_sigma_px = r->psf_sigma_px;
    in->psf_sigma_std_px = r->psf_sigma_std_px;
    snprintf(in->psf_source, sizeof in->psf_source, "%s", r->psf_source);
}

static bool load_inputs(const lightplan_lamps_opts_t *o, plan_inputs_t *in)
{
    char *argv0[] = { "refl", NULL };
    in->prov = model_provenance(o->argc > 0 ? o->argc : 1, o->argc > 0 ? o->argv : argv0);
    model_scene_options_t so = MODEL_SCENE_OPTIONS_DEFAULT;
    so.unit_mm = o->scene_unit_mm;
    if (!(in->scene = model_scene_load(o->scene, &so)) || !(in->cam = model_camera_load(o->camera))) return false;
    model_provenance_input(in->prov, "scene", o->scene);
    model_provenance_input(in->prov, "camera", o->camera);
    return load_lamps(o, in) && load_materials(o, in) && load_sensor(o, in);
}

// ---------------------------------------------------------------------------
// The check on the virtual rig

typedef struct {
    eval_lab_t        *lab;
    int                  map[MAXL_PLAN];   // candidate -> the rig's lamp
    float               *frame;
    bool                *found;
    double              *meas;
    lightplan_segment_t *sg;
} plan_check_t;

static void check_free(plan_check_t *c)
{
    eval_lab_free(c->lab);
    free(c->frame);
    free(c->found);
    free(c->meas);
    free(c->sg);
}

// The virtual rig of the truth file at the view's angle and the chosen
// exposure, its lamps matched to the candidates by name, and the buffers.
static bool check_open(const lightplan_lamps_opts_t *o, const plan_inputs_t *in, const lightplan_result_t *res,
                       plan_check_t *c)
{
    const lightplan_config_t *b = &res->configs[res->best];
    double angle = o->angle_deg;
    if (!(c->lab = eval_lab_open(o->check_truth, o->sample, &angle, 1, b->exposure_us, 0, false)))
        return false;
    const model_lamps_t *tl = eval_lab_lamps(c->lab);
    for (int i = 0; i < in->lamps->n; i++) {
        c->map[i] = model_lamps_find(tl, in->lamps->lamps[i].name);
        if (c->map[i] < 0) {
            model_error_set(o->check_truth, 0, "candidate lamp '%s' is not one of the virtual rig's lamps: the check "
                            "renders the rig's own lamps", in->lamps->lamps[i].name);
            return false;
        }
    }
    size_t ns = (size_t)(res->nsegments ? res->nsegments : 1);
    c->frame = malloc((size_t)res->W * res->H * sizeof *c->frame);
    c->found = calloc(ns, sizeof *c->found);
    c->meas = calloc(ns, sizeof *c->meas);
    c->sg = malloc(ns * sizeof *c->sg);
    if (!c->frame || !c->found || !c->meas || !c->sg) {
        model_error_set(NULL, 0, "out of memory");
        return false;
    }
    return true;
}

// The check's frame of the chosen configuration, kept as check_frame.tiff.
static bool check_frame_write(const lightplan_lamps_opts_t *o, const lightplan_result_t *res, const float *frame,
                              const char *names, double exposure_us)
{
    char *fp = g_strdup_printf("%s/check_frame.tiff", o->out);
    model_mkdir_p(o->out);
    model_meta_t *mt = model_meta_new();
    model_meta_add(mt, "units", "DN (12-bit sensor values as float)");
    model_meta_add(mt, "image", "the virtual rig's frame of the chosen configuration (lamps %s, %g us)", names,
                   exposure_us);
    bool ok = model_tiff_write_float(fp, res->W, res->H, frame, model_meta_list(mt));
    model_meta_free(mt);
    g_free(fp);
    return ok;
}

// One configuration (lamp set m of the candidates, the chosen exposure)
// rendered on the virtual rig (seed) and its segments judged by the Sobel
// check: *ck, and its JSON record.
static json_t *check_config(const lightplan_lamps_opts_t *o, const plan_inputs_t *in, const lightplan_result_t *res,
                            plan_check_t *c, uint32_t m, uint64_t seed, lightplan_check_t *ck)
{
    const double exposure = res->configs[res->best].exposure_us;
    const int ns = res->nsegments;
    uint32_t tm = 0;
    for (int i = 0; i < in->lamps->n; i++)
        if ((m >> i) & 1) tm |= 1u << c->map[i];
    if (!eval_lab_image(c->lab, 0, tm, NULL, 1, seed, c->frame)) return NULL;
    if (!lightplan_segments_for(res, m, exposure, &o->opt, c->sg) ||
        !lightplan_sobel_check(c->sg, ns, c->frame, res->W, res->H, o->opt.sobel_threshold, c->found, c->meas,
                               &ck->agreement))
        return NULL;
    ck->exposure_us = exposure;
    ck->judged = ck->agreeing = 0;
    for (int s = 0; s < ns; s++)
        if (isfinite(c->meas[s])) {
            ck->judged++;
            ck->agreeing += c->found[s] == c->sg[s].detectable;
        }
    mask_names(in->lamps, m, ck->lamps, sizeof ck->lamps);
    json_t *e = json_pack("{s:s,s:f,s:o,s:i,s:i}", "lamps", ck->lamps, "exposure_us", exposure, "agreement",
                          model_json_number(ck->agreement), "segments_judged",
                          ck->judged, "segments_agreeing", ck->agreeing);
    json_object_set_new(e, "segments", segments_json(c->sg, ns, in->scene, c->found, c->meas));
    return e;
}

// The chosen set, then each other single lamp, at the chosen exposure, on the
// virtual rig: the record of plan.json's virtual_rig_check (*check), r->checks.
static bool check_virtual(const lightplan_lamps_opts_t *o, plan_inputs_t *in, lightplan_view_t *r,
                          json_t **check)
{
    const lightplan_result_t *res = &r->res;
    const lightplan_config_t *b = &res->configs[res->best];
    plan_check_t c = { 0 };
    bool ok = false;
    r->check_started = true;
    if (!check_open(o, in, res, &c)) goto done;
    json_t *cfgs = json_array();
    *check = json_object();
    json_object_set_new(*check, "configurations", cfgs);
    long agree = 0;
    for (int k = -1; k < in->lamps->n; k++) {
        uint32_t m = k < 0 ? b->mask : 1u << k;
        if (k >= 0 && m == b->mask) continue;
        lightplan_check_t *ck = &r->checks[r->nchecks];
        json_t *e = check_config(o, in, res, &c, m, 4242 + (uint64_t)(k + 1), ck);
        if (!e) goto done;
        json_array_append_new(cfgs, e);
        r->nchecks++;
        agree += ck->agreeing;
        r->check_judged += ck->judged;
        if (k < 0 && !check_frame_write(o, res, c.frame, ck->lamps, b->exposure_us)) goto done;
    }
    r->check_agreement = r->check_judged ? (double)agree / r->check_judged : NAN;
    double overall = r->check_agreement;
    json_object_set_new(*check, "agreement", model_json_number(overall));
    json_object_set_new(*check, "target", json_real(0.95));
    json_object_set_new(*check, "rule",
                        json_string("a segment is found when the median, over points every 2 px along it (2 px "
                                    "kept from its ends), of the largest Sobel magnitude within 1.5 px across "
                                    "reaches the threshold; segments under 8 px are not judged; agreement = "
                                    "found == predicted detectable"));
    json_object_set_new(*check, "truth", json_string(o->check_truth));
    r->checked = ok = true;
done:
    check_free(&c);
    return ok;
}

// ---------------------------------------------------------------------------
// Outputs

// The detector's response to the sensor's noise alone at the object's median
// signal (the check's rule: the largest |Sobel| of 7 positions across,
// median along: about 8.7 sigma) into r and the chosen configuration's record.
// false + message: out of memory.
static bool noise_response(const lightplan_lamps_opts_t *o, const lightplan_sensor_t *sensor,
                           lightplan_view_t *r, json_t *chosen)
{
    const lightplan_result_t *res = &r->res;
    double *sv = malloc((size_t)res->W * res->H * sizeof *sv);
    if (!sv) {
        model_error_set(NULL, 0, "out of memory");
        return false;
    }
    int n = 0;
    for (size_t p = 0; p < (size_t)res->W * res->H; p += 4)
        if (res->face_id[p] >= 0) sv[n++] = res->predicted[p] - sensor->offset_dn;
    double med = 0;
    if (n) med = model_kth(sv, n, n / 2);
    free(sv);
    double sig = sensor->K_dn_per_e > 0
                     ? sqrt(sensor->K_dn_per_e * fmax(med, 0) + pow(sensor->K_dn_per_e * sensor->read_noise_e, 2) +
                            1.0 / 12)
                     : NAN;
    r->median_signal_dn = med;
    r->sobel_noise_dn = 8.7 * sig;
    r->threshold_near_noise = isfinite(r->sobel_noise_dn) && o->opt.sobel_threshold < 1.5 * r->sobel_noise_dn;
    json_object_set_new(chosen, "median_object_signal_dn", json_real(med));
    json_object_set_new(chosen, "sobel_noise_response_dn",
                        model_json_number(r->sobel_noise_dn));
    return true;
}

// The chosen configuration's record. NULL + message: out of memory.
static json_t *chosen_json(const lightplan_lamps_opts_t *o, const plan_inputs_t *in, lightplan_view_t *r)
{
    const lightplan_config_t *b = &r->res.configs[r->res.best];
    json_t *chosen = json_pack("{s:s,s:f,s:b,s:f,s:i,s:i,s:f,s:i,s:i,s:i}", "lamps", r->chosen, "exposure_us",
                               b->exposure_us, "feasible", b->feasible, "detectable_length_px",
                               b->detectable_length_px, "n_detectable", b->n_detectable, "n_segments", b->n_segments,
                               "usable_points", b->usable_points, "glare_pix", b->glare_pix, "saturated_pix",
                               b->saturated_pix, "object_pix", b->object_pix);
    if (!b->feasible)
        json_object_set_new(chosen, "note", json_string("no configuration is free of glare and saturation; this one "
                                                        "has the fewest such pixels"));
    json_object_set_new(chosen, "index", json_integer(r->res.best));
    if (!noise_response(o, &in->sensor, r, chosen)) {
        json_decref(chosen);
        return NULL;
    }
    // at the edge of the searched exposures: the best may lie beyond them
    double lo = INFINITY, hi = -INFINITY;
    for (int k = 0; k < o->nexp; k++) lo = fmin(lo, o->exposures_us[k]), hi = fmax(hi, o->exposures_us[k]);
    r->exposure_edge = !(hi > lo) ? 0 : b->exposure_us >= hi ? 1 : b->exposure_us <= lo ? -1 : 0;
    if (r->exposure_edge)
        json_object_set_new(chosen, "exposure_at_edge", json_string(r->exposure_edge > 0 ? "longest" : "shortest"));
    return chosen;
}

// plan.json's "warnings": sentences a reader must see (the report shows them at the top).
static json_t *warnings_json(const lightplan_lamps_opts_t *o, const lightplan_view_t *r)
{
    json_t *w = json_array();
    const lightplan_config_t *b = &r->res.configs[r->res.best];
    if (r->exposure_edge)
        json_array_append_new(w, json_sprintf("the chosen exposure %g us is the %s of those searched (--exposures-us): "
                                              "a %s one may be better; search beyond it", b->exposure_us,
                                              r->exposure_edge > 0 ? "longest" : "shortest",
                                              r->exposure_edge > 0 ? "longer" : "shorter"));
    if (r->threshold_near_noise)
        json_array_append_new(w, json_sprintf("the Sobel threshold %.0f DN is close to the detector's response to the "
                                              "sensor's noise alone (%.0f DN): edges will be found in noise",
                                              o->opt.sobel_threshold, r->sobel_noise_dn));
    return w;
}

// Every configuration, the glare per candidate and the chosen one's faces.
static void tables_json(const plan_inputs_t *in, const lightplan_result_t *res, json_t *doc)
{
    json_t *cf = json_array();
    for (int c = 0; c < res->nconfigs; c++) {
        const lightplan_config_t *k = &res->configs[c];
        char nm[512];
        mask_names(in->lamps, k->mask, nm, sizeof nm);
        json_array_append_new(cf, json_pack("{s:s,s:f,s:b,s:f,s:i,s:f,s:i,s:i}", "lamps", nm, "exposure_us",
                                            k->exposure_us, "feasible", k->feasible, "detectable_length_px",
                                            k->detectable_length_px, "n_detectable", k->n_detectable, "usable_points",
                                            k->usable_points, "glare_pix", k->glare_pix, "saturated_pix",
                                            k->saturated_pix));
    }
    json_object_set_new(doc, "configurations", cf);
    json_t *gl = json_array();
    for (int i = 0; i < in->lamps->n; i++) {
        long n = 0;
        for (size_t p = 0; p < (size_t)res->W * res->H; p += 1) n += (res->glare[p] >> i) & 1;
        json_array_append_new(gl, json_pack("{s:s,s:I}", "lamp", in->lamps->lamps[i].name, "glare_pixels",
                                            (json_int_t)n));
    }
    json_object_set_new(doc, "glare_per_lamp", gl);
    json_t *fa = json_array();
    char fb[32];
    const model_scene_t *scene = in->scene;
    for (int f = 0; f < res->nfaces; f++) {
        const lightplan_face_t *F = &res->faces[f];
        if (!F->npix) continue;
        json_t *e = json_pack("{s:s,s:i,s:f,s:f,s:f,s:f,s:i,s:i}", "face", face_name(scene, f, fb, sizeof fb),
                              "pixels_step2", F->npix, "P_min_dn", F->P_min, "P_median_dn", F->P_median, "P_max_dn",
                              F->P_max, "usable_frac", F->usable_frac, "glare_pix", F->glare_pix, "saturated_pix",
                              F->saturated_pix);
        if (f < scene->nfaces)
            json_object_set_new(e, "material", json_string(scene->material_names[scene->faces[f].material]));
        json_array_append_new(fa, e);
    }
    json_object_set_new(doc, "faces", fa);
}

// plan.json's "psf": the blur the edges' Sobel response was predicted with.
static json_t *psf_json(const lightplan_lamps_opts_t *o, const plan_inputs_t *in)
{
    const double sig = o->opt.psf_sigma_px, std = in->psf_sigma_std_px;
    json_t *j = json_pack("{s:f,s:o,s:s,s:s,s:s}", "sigma_px", sig, "sigma_std_px",
                          model_json_number(std), "source", in->psf_source,
                          "model", "the step convolved with an isotropic Gaussian of sigma_px (the optics) and "
                          "integrated over the pixel's 1 x 1 px footprint (model_edge_sobel_step)", "phase",
                          "best: the edge through a pixel centre (sigma 0: 4.0 axis-aligned, 4.24 diagonal); the "
                          "factors at the mean and worst phase (the edge half-way between pixel centres) are given "
                          "for comparison");
    const char *names[2] = { "axis_aligned", "diagonal" };
    json_t *f = json_object();
    for (int k = 0; k < 2; k++) {
        model_sobel_step_t s = model_edge_sobel_step(k ? M_PI / 4 : 0, sig);
        json_object_set_new(f, names[k], json_pack("{s:f,s:f,s:f}", "best", s.best, "mean", s.mean, "worst",
                                                   s.worst));
    }
    json_object_set_new(j, "sobel_factor", f);
    return j;
}

// plan.json's document (check: the virtual rig's record or NULL). NULL + message: out of memory.
static json_t *plan_json(const lightplan_lamps_opts_t *o, const plan_inputs_t *in, lightplan_view_t *r,
                         json_t *check)
{
    const lightplan_result_t *res = &r->res;
    json_t *doc = json_object();
    model_json_set_format(doc, "refl-lightplan", 1);
    json_object_set_new(doc, "scene", json_string(o->scene));
    json_object_set_new(doc, "turntable_deg", json_real(o->angle_deg));
    json_object_set_new(doc, "units_and_conventions",
                        json_string("grey values DN; exposure us; pixels as mrcal ((0,0) the centre of the top-left "
                                    "pixel, x right, y down); rig frame mm; predicted.tiff and the faces' P_* are grey "
                                    "values with the dark offset (sensor.offset_dn), direct light only; dP_dn = the "
                                    "signal (offset excluded, direct light plus one diffuse bounce) 2 px to side 0 "
                                    "minus side 1 of a segment, side 0 to the right of q0 -> q1 (y down), mean along "
                                    "it; sobel_predicted_dn = the median along it of f |dP|, f the Sobel response per "
                                    "unit contrast of the step blurred by the PSF and the pixel's footprint at the "
                                    "segment's direction (psf: sigma, phase, f axis-aligned and diagonal)"));
    json_object_set_new(doc, "psf", psf_json(o, in));
    json_t *chosen = chosen_json(o, in, r);
    if (!chosen) {
        json_decref(doc);
        return NULL;
    }
    json_object_set_new(doc, "chosen", chosen);
    json_object_set_new(doc, "warnings", warnings_json(o, r));
    json_object_set_new(doc, "chosen_index", json_integer(res->best));
    tables_json(in, res, doc);
    json_object_set_new(doc, "segments", segments_json(res->segments, res->nsegments, in->scene, NULL, NULL));
    if (check) json_object_set_new(doc, "virtual_rig_check", json_incref(check));
    const lightplan_options_t *op = &o->opt;
    json_object_set_new(doc, "options", json_pack("{s:f,s:f,s:f,s:f,s:f,s:f,s:i,s:i}", "glare_cone_deg",
                                                  op->glare_cone_deg, "sobel_threshold_dn", op->sobel_threshold,
                                                  "floor_snr", op->floor_snr, "floor_dn", op->floor_dn,
                                                  "saturation_frac", op->saturation_frac, "max_bad_frac",
                                                  op->max_bad_frac, "max_lamps", op->max_lamps, "spacing_px",
                                                  op->spacing_px));
    const lightplan_sensor_t *sn = &in->sensor;
    json_object_set_new(doc, "sensor", json_pack("{s:f,s:f,s:f,s:f,s:b}", "offset_dn", sn->offset_dn,
                                                 "saturation_dn", sn->saturation_dn, "K_dn_per_e", sn->K_dn_per_e,
                                                 "read_noise_e", sn->read_noise_e, "flat_field", sn->flat != NULL));
    json_object_set_new(doc, "provenance", json_incref(in->prov));
    return doc;
}

// predicted.tiff and glare.tiff (where each candidate would glare: bit i of
// the value for lamp i, file order).
static bool write_images(const lightplan_lamps_opts_t *o, const plan_inputs_t *in, const lightplan_view_t *r)
{
    const lightplan_result_t *res = &r->res;
    const lightplan_config_t *b = &res->configs[res->best];
    char *tp = g_strdup_printf("%s/predicted.tiff", o->out);
    model_meta_t *mt = model_meta_new();
    model_meta_add(mt, "units", "DN (predicted grey value, direct light, clipped at saturation)");
    model_meta_add(mt, "image", "lamps %s, %g us", r->chosen, b->exposure_us);
    bool ok = model_tiff_write_float(tp, res->W, res->H, res->predicted, model_meta_list(mt));
    model_meta_free(mt);
    g_free(tp);
    float *gm = ok ? malloc((size_t)res->W * res->H * sizeof *gm) : NULL;
    if (ok && !gm) model_error_set(NULL, 0, "out of memory");
    if (!gm) return false;
    for (size_t p = 0; p < (size_t)res->W * res->H; p++) gm[p] = (float)res->glare[p];
    char *gp = g_strdup_printf("%s/glare.tiff", o->out);
    model_meta_t *gmt = model_meta_new();
    char order[512];
    mask_names(in->lamps, in->lamps->n >= 32 ? 0xffffffffu : (1u << in->lamps->n) - 1, order, sizeof order);
    model_meta_add(gmt, "units", "bit mask as a number: bit i set where candidate lamp i (order: %s) lies within "
                   "%g deg of the mirror direction of the view ray on a non-Lambertian face (specular glare)",
                   order, o->opt.glare_cone_deg);
    ok = model_tiff_write_float(gp, res->W, res->H, gm, model_meta_list(gmt));
    model_meta_free(gmt);
    g_free(gp);
    free(gm);
    return ok;
}

// ---------------------------------------------------------------------------
// The run

// One view (v->angle_deg): lightplan_run at its angle, the check on the
// virtual rig, plan.json, the images and the report in v->dir.
static bool plan_view(const lightplan_lamps_opts_t *o, plan_inputs_t *in, lightplan_view_t *v)
{
    lightplan_lamps_opts_t ov = *o;
    ov.angle_deg = v->angle_deg;
    ov.out = v->dir;
    v->check_agreement = v->sobel_noise_dn = NAN;
    bool ok = false;
    json_t *check = NULL, *doc = NULL;
    model_scene_t *rot = model_scene_rotated_z(in->scene, v->angle_deg);
    if (!rot || !lightplan_run(rot, in->cam, in->lamps, in->A, in->mats, &in->sensor, o->exposures_us, o->nexp,
                               &o->opt, &v->res))
        goto done;
    v->planned = true;
    mask_names(in->lamps, v->res.configs[v->res.best].mask, v->chosen, sizeof v->chosen);
    if (o->check_truth && !check_virtual(&ov, in, v, &check)) goto done;
    if (!model_mkdir_p(v->dir)) goto done;
    if (!(doc = plan_json(&ov, in, v, check))) goto done;
    char *jp = g_strdup_printf("%s/plan.json", v->dir);
    bool wok = model_write_json(jp, doc);
    g_free(jp);
    if (!wok || !write_images(&ov, in, v)) goto done;
    v->written = true;
    if (o->report && model_run_script("plan_lamps_report.py", v->dir, NULL) != 0) goto done;
    ok = true;
done:
    json_decref(doc);
    json_decref(check);
    model_scene_free(rot);
    return ok;
}

// Several views: out/plan.json lists them (each one's choice, its directory)
// with the capture plan, and out/index.html links their reports.
static bool write_summary(const lightplan_lamps_opts_t *o, const plan_inputs_t *in, const lightplan_lamps_result_t *r)
{
    json_t *views = json_array();
    for (int k = 0; k < r->nviews; k++) {
        const lightplan_view_t *v = &r->views[k];
        const lightplan_config_t *b = &v->res.configs[v->res.best];
        char *base = g_path_get_basename(v->dir);
        json_t *e = json_pack("{s:f,s:s,s:s,s:f,s:b,s:i,s:i,s:f,s:f,s:i,s:i}", "turntable_deg", v->angle_deg, "dir",
                              base, "lamps", v->chosen, "exposure_us", b->exposure_us, "feasible", b->feasible,
                              "n_detectable", b->n_detectable, "n_segments", b->n_segments, "detectable_length_px",
                              b->detectable_length_px, "usable_points", b->usable_points, "glare_pix", b->glare_pix,
                              "saturated_pix", b->saturated_pix);
        g_free(base);
        json_object_set_new(e, "check_agreement", v->checked ? model_json_number(v->check_agreement) : json_null());
        json_object_set_new(e, "warnings", warnings_json(o, v));
        json_array_append_new(views, e);
    }
    json_t *doc = json_object();
    model_json_set_format(doc, "refl-lightplan", 1);
    json_object_update_new(doc, json_pack("{s:s,s:o,s:s,s:o}", "scene", o->scene, "views", views, "capture_plan",
                                          "capture_plan.ini", "capture_plan_binds_to_virtual_rig",
                                          o->check_truth ? json_boolean(r->plan_bound) : json_null()));
    json_object_set_new(doc, "provenance", json_incref((json_t *)in->prov));
    char *jp = g_strdup_printf("%s/plan.json", o->out);
    bool ok = model_write_json(jp, doc);
    g_free(jp);
    json_decref(doc);
    return ok && (!o->report || model_run_script("plan_lamps_report.py", o->out, NULL) == 0);
}

bool lightplan_lamps_run(const lightplan_lamps_opts_t *o, lightplan_lamps_result_t *r)
{
    memset(r, 0, sizeof *r);
    bool quiet = model_error_quiet_thread(true);   // the caller reports the message
    bool ok = false;
    plan_inputs_t in = { 0 };
    lightplan_lamps_opts_t oo = *o;
    char *sample = NULL;
    if (!oo.sample) {   // the scene file's name without its extension
        sample = g_path_get_basename(o->scene);
        char *dot = strrchr(sample, '.');
        if (dot && dot != sample) *dot = 0;
        oo.sample = sample;
    }
    if (!oo.pixel_format) oo.pixel_format = "Mono12";
    if (o->nmaterials < 1 || o->nexp < 1) {
        model_error_set(NULL, 0, "light planning: give the materials and at least one exposure");
        goto done;
    }
    for (int i = 0; i < o->nangles; i++)
        for (int k = 0; k < i; k++)
            if (o->angles_deg[i] == o->angles_deg[k]) {
                model_error_set(NULL, 0, "light planning: the view at %g deg is given twice", o->angles_deg[i]);
                goto done;
            }
    if (!load_inputs(&oo, &in)) goto done;
    resolve_psf(&oo, &in, r);
    r->ncandidates = in.lamps->n;
    if (o->check_truth && !model_provenance_input(in.prov, "virtual_rig_truth", o->check_truth)) goto done;
    int nv = o->nangles > 0 ? o->nangles : 1;
    r->views = calloc((size_t)nv, sizeof *r->views);
    if (!r->views) {
        model_error_set(NULL, 0, "out of memory");
        goto done;
    }
    for (int k = 0; k < nv; k++) {
        lightplan_view_t *v = &r->views[r->nviews++];
        v->angle_deg = o->nangles > 0 ? o->angles_deg[k] : o->angle_deg;
        v->dir = o->nangles > 0 ? g_strdup_printf("%s/view_%g", o->out, v->angle_deg) : g_strdup(o->out);
        if (!plan_view(&oo, &in, v)) goto done;
    }
    if (!lightplan_capture_plan(&oo, in.prov, r)) goto done;
    if (o->nangles > 0 && !write_summary(&oo, &in, r)) goto done;
    ok = true;
done:
    g_free(sample);
    inputs_free(&in);
    model_error_quiet_thread(quiet);
    return ok;
}
