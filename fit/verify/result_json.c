// fit/verify/result_json.c — a verification's result as JSON: the body of
// verify.json ("refl-verify", VERIFY_JSON_VERSION; fit/verify/verify.h).
#define _GNU_SOURCE
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fit/verify/internal.h"
#include "model/base/report.h"

static json_t *stats_json(const verify_stats_t *s)
{
    json_t *o = json_object();
    json_object_set_new(o, "n_points", json_integer(s->npoints));
    json_object_set_new(o, "max_abs_diff_dn", model_json_number(s->max_abs));
    json_object_set_new(o, "mean_abs_diff_dn", model_json_number(s->mean_abs));
    json_object_set_new(o, "std_abs_diff_dn", model_json_number(s->std_abs));
    json_object_set_new(o, "robust_sigma_dn", model_json_number(s->robust_sigma));
    json_object_set_new(o, "rms_z", model_json_number(s->rms_z));
    json_object_set_new(o, "median_abs_z", model_json_number(s->median_abs_z));
    return o;
}

// Each image's residue statistics.
static json_t *residue_per_image_json(const verify_result_t *r, const verify_image_t *imgs)
{
    json_t *pi = json_array();
    for (int m = 0; m < r->nimages; m++) {
        json_t *s = stats_json(&r->per_image[m]);
        json_object_set_new(s, "image", json_string(imgs[m].name));
        json_object_set_new(s, "turntable_deg", json_real(imgs[m].angle_deg));
        json_array_append_new(pi, s);
    }
    return pi;
}

// A change region's faces, most points first.
static json_t *region_faces_json(const verify_region_t *R, const model_scene_t *scene)
{
    json_t *fa = json_array();
    for (int t = 0; t < 4; t++) {
        if (R->face_points[t] <= 0) continue;
        int f = R->faces[t];
        json_t *fe = json_object();
        if (f < 0) json_object_set_new(fe, "face", json_string("background"));
        else if (f < scene->nfaces) {
            json_object_set_new(fe, "face", json_integer(scene->faces[f].number));
            json_object_set_new(fe, "line", json_integer(scene->faces[f].line));
            json_object_set_new(fe, "material",
                                json_string(scene->material_names[scene->faces[f].material]));
        } else {
            json_object_set_new(fe, "sphere", json_integer(f - scene->nfaces));
        }
        json_object_set_new(fe, "n_points", json_integer(R->face_points[t]));
        json_array_append_new(fa, fe);
    }
    return fa;
}

// The change regions that count (of at least min_region points).
static json_t *regions_json(const verify_result_t *r, const model_scene_t *scene, const verify_image_t *imgs)
{
    json_t *rg = json_array();
    for (int k = 0; k < r->nregions; k++) {
        const verify_region_t *R = &r->regions[k];
        if (!R->counts) continue;
        json_t *e = json_object();
        json_object_set_new(e, "index", json_integer(k));
        json_object_set_new(e, "image", json_string(imgs[R->image].name));
        json_object_set_new(e, "image_index", json_integer(R->image));
        json_object_set_new(e, "n_points", json_integer(R->npoints));
        json_object_set_new(e, "area_px", json_real(R->area_px));
        json_object_set_new(e, "excess_chi2", json_real(R->excess_chi2));
        json_object_set_new(e, "max_abs_z", json_real(R->max_abs_z));
        json_object_set_new(e, "bbox_px", json_pack("[f,f,f,f]", R->bbox[0], R->bbox[1], R->bbox[2], R->bbox[3]));
        json_object_set_new(e, "faces", region_faces_json(R, scene));
        json_array_append_new(rg, e);
    }
    return rg;
}

// The fit's parameters against their priors and bounds.
static json_t *params_json(const verify_result_t *r)
{
    json_t *ps = json_array();
    for (int k = 0; k < r->nparams; k++) {
        const verify_param_t *p = &r->params[k];
        json_t *e = json_object();
        json_object_set_new(e, "name", json_string(p->name));
        json_object_set_new(e, "value", model_json_number(p->value));
        json_object_set_new(e, "std", model_json_number(p->std));
        json_object_set_new(e, "prior_mean", model_json_number(p->prior_mean));
        json_object_set_new(e, "prior_std", p->prior_std > 0 ? json_real(p->prior_std) : json_null());
        json_object_set_new(e, "lo", model_json_number(p->lo));
        json_object_set_new(e, "hi", model_json_number(p->hi));
        json_object_set_new(e, "fixed", json_boolean(p->fixed));
        json_object_set_new(e, "pinned", json_boolean(p->pinned));
        json_array_append_new(ps, e);
    }
    return ps;
}

// The solver's summary.
static json_t *fit_json(const verify_result_t *r)
{
    json_t *fs = json_object();
    json_object_set_new(fs, "iterations", json_integer(r->summary.iterations));
    json_object_set_new(fs, "initial_cost", model_json_number(r->summary.initial_cost));
    json_object_set_new(fs, "final_cost", model_json_number(r->summary.final_cost));
    json_object_set_new(fs, "termination", json_string(r->summary.termination));
    json_object_set_new(fs, "n_residuals", json_integer(r->summary.nresiduals));
    json_object_set_new(fs, "n_free_parameters", json_integer(r->summary.nfree));
    json_object_set_new(fs, "time_s", model_json_number(r->time_fit_s));
    return fs;
}

// The options that shaped the fit.
static json_t *options_json(const verify_options_t *opt)
{
    json_t *op = json_object();
    json_object_set_new(op, "spacing_px", json_integer(opt->spacing_px));
    json_object_set_new(op, "window_px", json_integer(opt->window_px));
    json_object_set_new(op, "edge_margin_px", json_real(opt->edge_margin_px));
    json_object_set_new(op, "boundary_margin_px", json_real(opt->boundary_margin_px));
    json_object_set_new(op, "edge_k", json_real(opt->edge_k));
    json_object_set_new(op, "edge_rel", json_real(opt->edge_rel));
    json_object_set_new(op, "interreflection_samples", json_integer(opt->ir_samples));
    json_object_set_new(op, "priors", json_boolean(opt->use_priors));
    json_object_set_new(op, "gain_maps", json_boolean(opt->use_flat));
    json_object_set_new(op, "model_rel", json_real(opt->model_rel));
    json_object_set_new(op, "model_rel_source",
                        json_string(opt->model_rel_given ? "model_rel for every material (--model-rel)"
                                                         : "each material's priors' window_rel_std; model_rel for "
                                                           "materials whose priors state none"));
    json_object_set_new(op, "edge_windows", json_boolean(opt->edge_windows));
    json_object_set_new(op, "edge_subsamples", json_integer(opt->edge_subsamples));
    json_object_set_new(op, "edge_position_sigma_px", json_real(opt->edge_position_sigma_px));
    json_object_set_new(op, "lamp_sigma", json_real(opt->lamp_sigma));
    json_object_set_new(op, "camera_sigma", json_real(opt->camera_sigma));
    json_object_set_new(op, "robust_scale", json_real(opt->robust_scale));
    json_object_set_new(op, "z_flag", json_real(opt->z_flag));
    json_object_set_new(op, "min_region", json_integer(opt->min_region));
    return op;
}

json_t *verify_result_json(const verify_result_t *r, const model_scene_t *scene, const verify_image_t *imgs,
                           const model_lamps_t *lamps, const verify_options_t *opt)
{
    (void)lamps;
    json_t *o = json_object();
    model_json_set_format(o, VERIFY_JSON_FORMAT, VERIFY_JSON_VERSION);
    json_object_set_new(o, "verdict", json_string(r->correct ? "correct" : "incorrect"));
    json_object_set_new(o, "description_correct", json_boolean(r->correct));
    json_object_set_new(o, "score", model_json_number(r->score));
    json_object_set_new(o, "score_threshold", model_json_number(opt->score_threshold));
    json_object_set_new(o, "score_definition",
                        json_string("sum over change regions of at least min_region flagged grid points of "
                                    "sum(min(z^2, (5 z_flag)^2) - z_flag^2); z = (measured - model)/sigma per "
                                    "reference point; an unexpected edge counts as z_flag x its window-std ratio"));
    json_object_set_new(o, "n_pinned_parameters", json_integer(r->npinned));
    json_t *warn = json_array();
    for (int k = 0; k < r->nwarnings; k++) json_array_append_new(warn, json_string(r->warnings[k]));
    json_object_set_new(o, "warnings", warn);
    json_object_set_new(o, "residue", stats_json(&r->all));
    json_object_set_new(o, "residue_units", json_string("DN of the images' pixel format; difference = measured - "
                                                        "model at each reference point (window mean)"));
    json_object_set_new(o, "residue_per_image", residue_per_image_json(r, imgs));
    json_t *st = json_object();
    for (int s = 0; s < VERIFY_PT_NSTATUS; s++)
        json_object_set_new(st, verify_pt_status_name((verify_pt_status_t)s), json_integer(r->nstatus[s]));
    json_object_set_new(o, "reference_points", st);
    json_object_set_new(o, "change_regions", regions_json(r, scene, imgs));
    json_object_set_new(o, "parameters", params_json(r));
    json_object_set_new(o, "parameter_conventions",
                        json_string("kc[camera]: the camera's sensitivity relative to the white calibration; "
                                    "lamp[name]: the lamp's intensity relative to it; Pa[image]: offset left after "
                                    "the offset map, DN (the dark level itself without one); rho: weight of the "
                                    "one-bounce diffuse interreflection (1 = physical); material.parameter: see "
                                    "the priors' conventions"));
    json_object_set_new(o, "fit", fit_json(r));
    json_object_set_new(o, "options", options_json(opt));
    return o;
}
