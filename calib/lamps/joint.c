// calib/lamps/joint.c — stage 4 of the calibration (calib_lamps_joint_fit): the
// joint fit over every used highlight, the highlights fitted again at the
// fitted sphere path and the fit again; a fit that runs away is tried once more
// with the sphere's offset held within 1 mm of the typed centre.
#include <glib.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "calib/lamps/internal.h"
#include "model/base/vec.h"

// The observations of the joint fit: every used ray as the camera ray of its
// sphere point. ob: room for every ray. Returns their number.
static int joint_obs(const calib_lamps_result_t *r, model_vec3_t Cc, calib_lamps_obs_t *ob)
{
    int k = 0;
    for (int l = 0; l < r->nlamps; l++)
        for (int a = 0; a < r->nangles; a++) {
            const calib_lamps_lamp_t *lp = &r->lamps[l];
            if (!lp->has_ray[a] || !lp->used[a]) continue;
            model_vec3_t ray = v3_sub(lp->p_mm[a], Cc);
            ob[k].lamp = l;
            ob[k].angle_deg = r->angle_deg[a];
            ob[k].ray = v3_scale(ray, 1 / sqrt(v3_dot(ray, ray)));
            k++;
        }
    return k;
}

// Every ray at the fitted sphere path: pass 0 fits the highlights again there
// (the lobe's geometry), pass 1 only reflects the highlight's camera ray.
static void rays_at_path(const calib_lamps_opts_t *o, calib_lamps_result_t *r, const calib_lamps_bundle_setup_t *bs,
                         const double *x_mm, int pass)
{
    const double R = o->sphere_radius_mm;
    for (int a = 0; a < r->nangles; a++) {
        double sc[3];
        lamps_bundle_centre(bs, r->angle_deg[a], r->joint.sphere, sc, NULL);
        model_vec3_t c = v3(sc[0], sc[1], sc[2]);
        for (int l = 0; l < r->nlamps; l++) {
            calib_lamps_lamp_t *lp = &r->lamps[l];
            if (!lp->has_ray[a]) continue;
            r->centre_mm[a] = c;
            if (pass == 0 && o->method == CALIB_LAMPS_MODEL) continue;   // refit_highlights below
            model_vec3_t dd = v3_sub(lp->p_mm[a], bs->camera_mm);
            dd = v3_scale(dd, 1 / sqrt(v3_dot(dd, dd)));
            double t = lamps_ray_sphere(bs->camera_mm, dd, c, R);
            if (!isfinite(t)) continue;
            lp->p_mm[a] = v3_add(bs->camera_mm, v3_scale(dd, t));
            model_vec3_t nn = v3_scale(v3_sub(lp->p_mm[a], c), 1 / R);
            lp->d[a] = v3_sub(dd, v3_scale(nn, 2 * v3_dot(dd, nn)));
        }
    }
    if (pass == 0 && o->method == CALIB_LAMPS_MODEL)
        for (int l = 0; l < r->nlamps; l++) lamps_refit_highlights(o, r, &r->lamps[l], x_mm + 3 * l);
}

bool calib_lamps_joint_fit(const calib_lamps_opts_t *o, calib_lamps_result_t *r)
{
    const int nl = r->nlamps, NA = r->nangles;
    const double *c0 = o->sphere_centre_mm;
    calib_lamps_bundle_setup_t bs = { .camera_mm = model_camera_centre_world(r->cam), .c0_mm = { c0[0], c0[1], c0[2] },
                                      .radius_mm = o->sphere_radius_mm, .offset_prior_mm = o->offset_prior_mm,
                                      .shift_prior_mm = o->shift_prior_mm, .tilt_prior_mrad = o->tilt_prior_mrad,
                                      .image_weights = true };
    for (int k = 0; k < 3 && r->have_typed; k++) bs.offset_prior_mean_mm[k] = r->typed_mm[k] - c0[k];
    calib_lamps_obs_t *ob = calloc((size_t)nl * NA + 1, sizeof *ob);
    double *x = calloc((size_t)nl * 3, sizeof *x), *cv = calloc((size_t)nl * 9, sizeof *cv);
    bool ok = ob && x && cv;
    if (!ok) model_error_set(NULL, 0, "out of memory");
    // the sphere's offset free within its prior; when that fit runs away (a lamp driven off to where its
    // rays turn parallel, or no covariance), once more with the offset held to 1 mm around the typed centre
    for (int attempt = 0; ok && attempt < 2; attempt++) {
        if (attempt) {
            if (!(bs.offset_prior_mm > 1)) break;
            model_note("the joint fit with the sphere's offset free within %g mm failed (%s); fitting again with it "
                       "within 1 mm of the typed centre", bs.offset_prior_mm, model_last_error());
            bs.offset_prior_mm = 1;
        }
        for (int l = 0; l < nl; l++) memcpy(x + 3 * l, r->lamps[l].fit.x_mm, sizeof r->lamps[l].fit.x_mm);
        bool fit = true;
        for (int pass = 0; fit && pass < 2; pass++) {
            r->joint_nobs = joint_obs(r, bs.camera_mm, ob);
            fit = calib_lamps_bundle(ob, r->joint_nobs, nl, &bs, x, cv, NULL, &r->joint);
            for (int l = 0; fit && l < nl; l++)
                if (!(fabs(x[3 * l]) < 1e5 && fabs(x[3 * l + 1]) < 1e5 && fabs(x[3 * l + 2]) < 1e5)) {
                    model_error_set(NULL, 0, "lamp %s ran off to (%.3g, %.3g, %.3g) mm", r->lamps[l].name, x[3 * l],
                                    x[3 * l + 1], x[3 * l + 2]);
                    fit = false;
                }
            if (fit) rays_at_path(o, r, &bs, x, pass);
        }
        if (fit) break;
        if (attempt == 1 || !(bs.offset_prior_mm > 1)) ok = false;
    }
    for (int l = 0; ok && l < nl; l++) {
        calib_lamps_lamp_t *lp = &r->lamps[l];
        calib_lamps_fit_t *f = &lp->fit;
        memcpy(f->x_mm, x + 3 * l, sizeof f->x_mm);
        memcpy(f->cov_mm2, cv + 9 * l, sizeof f->cov_mm2);
        double ss = 0;
        for (int a = 0; a < NA; a++) {
            if (!lp->has_ray[a]) continue;
            lp->dist_mm[a] = lamps_ray_dist(lp->p_mm[a], lp->d[a], f->x_mm);
            if (lp->used[a]) ss += lp->dist_mm[a] * lp->dist_mm[a];
        }
        f->rms_mm = sqrt(ss / f->n_used);
    }
    if (ok) {
        r->have_joint = true;
        const double *gg = r->joint.sphere, *gc = r->joint.sphere_cov;
        model_note("joint fit of %d lamps and the sphere's path over %d highlights: sphere offset %.3f %.3f %.3f mm "
                   "(std %.3f %.3f %.3f), shift %.3f %.3f mm (std %.3f %.3f), tilt %.3f %.3f mrad (std %.3f %.3f); "
                   "condition %.3g", nl, r->joint_nobs, gg[0], gg[1], gg[2], sqrt(gc[0]), sqrt(gc[8]), sqrt(gc[16]),
                   gg[3], gg[4], sqrt(gc[24]), sqrt(gc[32]), gg[5], gg[6], sqrt(gc[40]), sqrt(gc[48]), r->joint.cond);
    }
    free(ob);
    free(x);
    free(cv);
    return ok;
}
