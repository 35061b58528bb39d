// calib/lamps/lamps.c — `refl calib lamps`: lamp positions from the highlights of a
// mirror (chrome) sphere carried round by the turntable.
//
// Flow: a capture plan (the mirror sphere at several turntable angles, each
// lamp alone, a dark frame per angle, auto-bracketed exposures) run with
// calib_capture into DIR/capture (or a session captured elsewhere) -> per
// angle and lamp: the highlight on the sphere's predicted image (dark
// subtracted, brightest compact blob on the sphere's pixels, centroid) -> the
// ray toward the lamp from a model of the highlight in direction space (each
// pixel's camera ray meets the sphere, centre Rz(angle) c0, radius R; the
// mirror's GGX lobe around the lamp's direction, the lamp a disk of its
// angular size, point-sampled at the pixel centres) -> each lamp the
// least-squares point nearest its rays (outliers dropped by deleted
// residuals), covariance from the residuals; then the lamp's disk size from
// that distance and the fit once more; then (--sphere-path fit, the default)
// the joint fit of every lamp and the sphere's path over all highlights
// (calib_lamps_bundle: the path's offset, shift and tilt with priors, the
// highlights fitted again at the fitted path, the joint fit again) ->
// DIR/lamps.json, DIR/report.html (plots by scripts/calib_lamps_report.py).
// calib_lamps_run does it in stages (calib/lamps/lamps.h), each in its file:
// calib_lamps_open (capture.c: the capture or the session, the frames),
// _find_highlights (rays.c, with sphere.c, highlight.c and direction.c),
// _triangulate_lamps (triangulate.c), _joint_fit (joint.c, the fit itself in
// bundle.c), _write_json (output.c), _write_report (report.c); this file
// keeps the run, its rounds and the result's lifetime. `refl calib lamps` is
// calib/cmd_lamps.c.
//
// Measured on the virtual rig (tests/test_calib_lamps.c): the centroid alone
// is biased by the point sampling of a highlight ~2 px wide (0.06 px RMS);
// the direction-space model with the exact lobe and the lamp's disk brings
// the per-ray error to ~1 mrad; the depth along each lamp's line of sight is
// the weak direction (the sphere's circle of 60 mm seen from 0.75 m).
// Why the joint fit: the sphere is 25 mm and 0.87 m from the camera, the
// lamps ~0.8 m from it, so where the camera model puts the sphere relative to
// itself is amplified ~60x at the lamps (0.07 mm -> 5 mm). The demo's
// calibrated camera (centre 1.45 mm off, 0.05 deg) moves the sphere by
// ~0.05-0.1 mm, mostly without turning with the table, and tilts its circle
// by ~0.25 mrad: with the sphere held 7.5 mm RMS, joint 1.9 mm (the true
// camera: 1.37 held, 1.35 joint). The path's tilt and the offset across the
// view are well observed (std ~0.045 mrad, ~0.002-0.009 mm); the shift and
// the offset's z (the path's height relative to the camera) are weak (std
// 0.06-0.08 mm against a 0.1 mm prior: condition ~1e4), and they are the
// main part of each lamp's stated std (~3 mm): on synthetic highlights with
// the virtual rig's ray noise (0.02 px) the joint fit's lamps are 1.5-4.6 mm
// RMS off over seeds, within 4 stated std (tests: calib_lamps_bundle_synthetic).
// The sphere's limb, which would fix the shift, is not seen in these frames
// (the ball mirrors a dark room).
#include <glib.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "calib/lamps/internal.h"

calib_lamps_opts_t calib_lamps_defaults(void)
{
    calib_lamps_opts_t o = { .sample = "mirror_sphere", .nangles = 24, .exposures_us = { 40, 20, 10 },
                             .nexposures = 3, .min_snr = 12, .method = CALIB_LAMPS_MODEL, .joint = true,
                             .offset_prior_mm = 3.0, .shift_prior_mm = 0.1, .tilt_prior_mrad = 1.0,
                             .progress = -1 };
    for (int i = 0; i < o.nangles; i++) o.angles_deg[i] = 15.0 * i;
    return o;
}

// Every lamp's highlights, rays and fit forgotten (another round).
static void reset_rays(calib_lamps_result_t *r)
{
    const size_t NA = (size_t)r->nangles;
    for (int l = 0; l < r->nlamps; l++) {
        calib_lamps_lamp_t *lp = &r->lamps[l];
        memset(lp->hl, 0, NA * sizeof *lp->hl);
        memset(lp->has_ray, 0, NA * sizeof *lp->has_ray);
        memset(lp->used, 0, NA * sizeof *lp->used);
        memset(lp->p_mm, 0, NA * sizeof *lp->p_mm);
        memset(lp->d, 0, NA * sizeof *lp->d);
        memset(lp->dist_mm, 0, NA * sizeof *lp->dist_mm);
        memset(&lp->fit, 0, sizeof lp->fit);
        lp->nmissing = 0;
    }
    r->first_angle = -1;
    r->have_joint = false;
}

// The rounds: highlights, rays and fits at the centre oc->sphere_centre_mm
// (first the typed one); while the joint fit moves it by more than 0.2 mm
// (at most 3 rounds), again at the moved one.
static bool rounds(calib_lamps_opts_t *oc, calib_lamps_result_t *r)
{
    for (r->rounds = 1;; r->rounds++) {
        if (r->rounds > 1) reset_rays(r);
        memcpy(r->base_mm, oc->sphere_centre_mm, sizeof r->base_mm);
        if (!calib_lamps_find_highlights(oc, r) || !calib_lamps_triangulate_lamps(oc, r)) return false;
        if (!oc->joint) break;
        if (!calib_lamps_joint_fit(oc, r)) return false;
        const double *g = r->joint.sphere;
        for (int k = 0; k < 3; k++) {
            r->found_mm[k] = r->base_mm[k] + g[k];
            for (int j = 0; j < 3; j++) r->found_cov_mm2[3 * k + j] = r->joint.sphere_cov[7 * k + j];
        }
        double moved = sqrt(g[0] * g[0] + g[1] * g[1] + g[2] * g[2]);
        if (!(oc->offset_prior_mm > 0) || moved <= 0.2 || r->rounds == 3) break;
        model_note("the sphere's centre from its highlights: %.2f, %.2f, %.2f mm (%.2f mm from where they were "
                   "found, %.2f mm from the typed); finding them again there", r->found_mm[0], r->found_mm[1],
                   r->found_mm[2], moved, sqrt(pow(r->found_mm[0] - r->typed_mm[0], 2) +
                                               pow(r->found_mm[1] - r->typed_mm[1], 2) +
                                               pow(r->found_mm[2] - r->typed_mm[2], 2)));
        memcpy(oc->sphere_centre_mm, r->found_mm, sizeof r->found_mm);
    }
    double off = 0;
    for (int k = 0; k < 3; k++) off += pow(r->found_mm[k] - r->typed_mm[k], 2);
    off = sqrt(off);
    if (oc->joint && oc->offset_prior_mm > 0 && off > 2 * oc->offset_prior_mm)
        model_warning("the typed sphere centre is %.2f mm from the one its highlights give (%.2f, %.2f, %.2f mm), "
                      "more than twice its std (--sphere-offset-prior-mm %g): check the ball's placement and "
                      "--sphere-centre-mm", off, r->found_mm[0], r->found_mm[1], r->found_mm[2], oc->offset_prior_mm);
    return true;
}

bool calib_lamps_run(const calib_lamps_opts_t *o, calib_lamps_result_t *r)
{
    memset(r, 0, sizeof *r);
    r->first_angle = -1;
    if (!calib_lamps_open(o, r)) return false;
    calib_lamps_opts_t oc = *o;   // the centre moves to the images' between rounds
    r->have_typed = true;
    memcpy(r->typed_mm, o->sphere_centre_mm, sizeof r->typed_mm);
    if (!rounds(&oc, r)) return false;
    return calib_lamps_write_json(&oc, r) && calib_lamps_write_report(&oc, r);
}

void calib_lamps_result_free(calib_lamps_result_t *r)
{
    for (int l = 0; r->lamps && l < r->nlamps; l++) {
        calib_lamps_lamp_t *lp = &r->lamps[l];
        free(lp->frame);
        free(lp->hl);
        free(lp->has_ray);
        free(lp->used);
        free(lp->p_mm);
        free(lp->d);
        free(lp->dist_mm);
    }
    free(r->lamps);
    free(r->angle_deg);
    free(r->dark_row);
    free(r->centre_mm);
    json_decref(r->provenance);
    rig_plan_free(r->plan);
    rig_session_free(r->session);
    model_camera_free(r->cam);
    g_free(r->session_dir);
    memset(r, 0, sizeof *r);
    r->first_angle = -1;
}
