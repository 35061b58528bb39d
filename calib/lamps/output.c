// calib/lamps/output.c — stage 5 of the calibration (calib_lamps_write_json):
// lamps.json, each lamp's position, uncertainty and frames, the sphere and
// its joint fit, and the provenance the outputs share.
#include <glib.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "calib/lamps/internal.h"
#include "model/base/report.h"

bool lamps_provenance(const calib_lamps_opts_t *o, calib_lamps_result_t *r)
{
    if (r->provenance) return true;
    r->provenance = model_provenance(o->argc, o->argv);
    if (!model_provenance_input(r->provenance, "camera", o->camera) ||
        !model_provenance_input(r->provenance, "session", r->session_dir))
        return false;
    if (o->rig) model_provenance_input(r->provenance, "rig", o->rig);
    return true;
}

static json_t *vec_json(const double *v, int n)
{
    json_t *a = json_array();
    for (int k = 0; k < n; k++) json_array_append_new(a, model_json_number(v[k]));
    return a;
}

// lamps.json's entry of lamp lp.
static json_t *lamp_json(const calib_lamps_result_t *r, const calib_lamps_lamp_t *lp)
{
    json_t *j = json_object(), *miss = json_array();
    const double *x = lp->fit.x_mm, *cv = lp->fit.cov_mm2;
    json_object_set_new(j, "name", json_string(lp->name));
    json_object_set_new(j, "position_mm", json_pack("[fff]", x[0], x[1], x[2]));
    json_object_set_new(j, "std_mm", json_pack("[fff]", sqrt(cv[0]), sqrt(cv[4]), sqrt(cv[8])));
    json_object_set_new(j, "covariance_mm2", vec_json(cv, 9));
    json_object_set_new(j, "rms_ray_distance_mm", model_json_number(lp->fit.rms_mm));
    json_object_set_new(j, "radius_mm", model_json_number(lp->lamp_radius_mm));
    json_object_set_new(j, "n_frames", json_integer(lp->fit.n_used));
    int nout = 0;
    for (int a = 0; a < r->nangles; a++) {
        nout += lp->has_ray[a] && !lp->used[a];
        if (lp->has_ray[a]) continue;
        int step;
        const char *file = lamps_frame_file(r, lp, a, &step);
        json_array_append_new(miss, json_pack("{s:s,s:i,s:f,s:s}", "file", file, "step", step, "angle_deg",
                                              r->angle_deg[a], "why", lp->hl[a].why));
    }
    json_object_set_new(j, "n_outliers", json_integer(nout));
    json_object_set_new(j, "frames_missing", miss);
    return j;
}

// lamps.json's sphere.joint_fit.
static json_t *joint_json(const calib_lamps_opts_t *o, const calib_lamps_result_t *r)
{
    const calib_lamps_bundle_t *jf = &r->joint;
    const double *gc = jf->sphere_cov;
    json_t *jj = json_object(), *js = json_array();
    for (int l = 0; l < r->nlamps; l++) json_array_append_new(js, model_json_number(jf->sigma_rad[l] * 1e3));
    json_object_set_new(jj, "offset_mm", json_pack("[fff]", jf->sphere[0], jf->sphere[1], jf->sphere[2]));
    json_object_set_new(jj, "shift_mm", json_pack("[ff]", jf->sphere[3], jf->sphere[4]));
    json_object_set_new(jj, "tilt_mrad", json_pack("[ff]", jf->sphere[5], jf->sphere[6]));
    json_object_set_new(jj, "std", json_pack("[fffffff]", sqrt(gc[0]), sqrt(gc[8]), sqrt(gc[16]), sqrt(gc[24]),
                                             sqrt(gc[32]), sqrt(gc[40]), sqrt(gc[48])));
    json_object_set_new(jj, "covariance_mm2", vec_json(gc, 49));
    json_object_set_new(jj, "prior_std", json_pack("{s:f,s:f,s:f}", "offset_mm", o->offset_prior_mm, "shift_mm",
                                                   o->shift_prior_mm, "tilt_mrad", o->tilt_prior_mrad));
    json_object_set_new(jj, "ray_sigma_mrad", js);
    json_object_set_new(jj, "condition", model_json_number(jf->cond));
    json_object_set_new(jj, "model", json_string(
        "sphere centre at angle a = s0 + tilt x s0 + (shift_mm, 0), s0 = Rz(a) (centre_at_angle0_mm + "
        "offset_mm), tilt = (tilt_mrad, 0) 1e-3, fitted jointly with the lamps over every highlight (each a "
        "camera ray reflected off that sphere; residual the angle to the lamp over its lamp's ray sigma); "
        "std and covariance in the order offset x y z, shift x y (mm), tilt x y (mrad); Gaussian priors "
        "of prior_std"));
    return jj;
}

bool calib_lamps_write_json(const calib_lamps_opts_t *o, calib_lamps_result_t *r)
{
    if (!lamps_provenance(o, r)) return false;
    const double *c0 = o->sphere_centre_mm;
    json_t *doc = json_object(), *ja = json_array(), *sj = json_object();
    model_json_set_format(doc, CALIB_LAMPS_JSON_FORMAT, CALIB_LAMPS_JSON_VERSION);
    json_object_set_new(doc, "units", json_string("lengths in mm; angles in degrees; pixels with (0,0) at the "
                                                  "centre of the top-left pixel"));
    json_object_set_new(doc, "conventions", json_string(
        "rig frame: origin at the turntable top centre, z up along the rotation axis; position_mm is the lamp's "
        "centre (the point nearest the rays reflected off the sphere at each highlight; with sphere.joint_fit, "
        "fitted jointly with the sphere's path over every lamp's highlights); std_mm the 1-sigma uncertainty per "
        "axis from the residuals (with sphere.joint_fit including the uncertainty of the sphere's path and its "
        "priors; covariance_mm2 the full 3x3); rms_ray_distance_mm the RMS distance of the used rays from the "
        "position; frames_missing lists frames whose highlight was not found"));
    for (int l = 0; l < r->nlamps; l++) json_array_append_new(ja, lamp_json(r, &r->lamps[l]));
    json_object_set_new(doc, "lamps", ja);
    json_object_set_new(doc, "camera", json_pack("{s:s,s:s}", "path", o->camera, "sha256",
                                                 model_camera_sha256(r->cam)));
    json_object_set_new(sj, "sample", json_string(r->plan->sample));
    json_object_set_new(sj, "centre_at_angle0_mm", json_pack("[fff]", c0[0], c0[1], c0[2]));
    json_object_set_new(sj, "radius_mm", model_json_number(o->sphere_radius_mm));
    json_object_set_new(sj, "motion", json_string("centre at turntable angle a: Rz(a) centre_at_angle0_mm (the "
                                                  "journal's measured angle)"));
    if (r->have_joint) {
        const double *f = r->found_mm, *t = r->typed_mm, *fc = r->found_cov_mm2;
        json_object_set_new(sj, "source", json_string(
            "the highlights across turntable angles: the joint fit's offset, the typed centre its prior (mean, "
            "std joint_fit.prior_std.offset_mm); highlights found again at the moved centre while it moved > 0.2 mm"));
        json_object_set_new(sj, "centre_typed_mm", json_pack("[fff]", t[0], t[1], t[2]));
        json_object_set_new(sj, "centre_found_mm", json_pack("[fff]", f[0], f[1], f[2]));
        json_object_set_new(sj, "centre_found_std_mm", json_pack("[fff]", sqrt(fc[0]), sqrt(fc[4]), sqrt(fc[8])));
        double off = sqrt(pow(f[0] - t[0], 2) + pow(f[1] - t[1], 2) + pow(f[2] - t[2], 2));
        json_object_set_new(sj, "centre_typed_off_mm", model_json_number(off));
        json_object_set_new(sj, "rounds", json_integer(r->rounds));
        json_object_set_new(sj, "joint_fit", joint_json(o, r));
    } else {
        json_object_set_new(sj, "source", json_string("command line"));
    }
    json_object_set_new(doc, "sphere", sj);
    json_object_set_new(doc, "session", json_string(r->session_dir));
    json_object_set_new(doc, "provenance", json_incref(r->provenance));
    char *path = g_strdup_printf("%s/lamps.json", o->out);
    bool ok = model_write_json(path, doc);
    if (ok) model_note("wrote %s", path);
    g_free(path);
    json_decref(doc);
    return ok;
}

bool calib_lamps_json_check(const json_t *root, const char *path, int *version)
{
    return model_json_format_check(root, path, CALIB_LAMPS_JSON_FORMAT, CALIB_LAMPS_JSON_VERSION, version);
}
