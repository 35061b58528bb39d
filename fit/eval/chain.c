// fit/eval/chain.c — the lab day's calibrated and fitted figures against the
// virtual rig's truth (fit/eval/chain.h): chain.json's entries, each with the
// uncertainty refl states for it and z = error / sigma.
#include <glib.h>
#include <math.h>
#include <mrcal/mrcal.h>
#include <mrcal/poseutils.h>
#include <stdlib.h>
#include <string.h>

#include "calib/calib.h"
#include "calib/gain/gain.h"
#include "calib/geometry/geometry.h"
#include "calib/lamps/lamps.h"
#include "fit/eval/chain.h"
#include "fit/brdf/brdf.h"
#include "fit/priors.h"
#include "fit/verify/verify.h"
#include "model/cameramodel.h"
#include "model/model.h"
#include "model/base/report.h"
#include "model/base/vec.h"
#include "rig/virtual/truth.h"
#include "rig/virtual/materials.h"

typedef struct {
    const char *dir;
    rig_truth_t *truth;
    model_materials_t *mats;   // the truth's materials (tables generated), or NULL
    json_t *entries, *missing, *prov;
    bool   cams;                            // the first camera's poses (rig -> camera), calibrated and true
    double rt_cam_rig_cal[6], rt_cam_rig_truth[6];
} chain_t;

// One entry; NAN: none (JSON null). error = value - truth, z = error / sigma.
static void add(chain_t *c, const char *group, const char *name, double value, double truth, double sigma,
                const char *unit, const char *note)
{
    json_t *e = json_object();
    double err = value - truth, z = err / sigma;
    json_object_set_new(e, "name", json_string(name));
    json_object_set_new(e, "group", json_string(group));
    json_object_set_new(e, "value", model_json_number(value));
    json_object_set_new(e, "truth", model_json_number(truth));
    json_object_set_new(e, "sigma", sigma > 0 ? model_json_number(sigma) : json_null());
    json_object_set_new(e, "unit", json_string(unit));
    json_object_set_new(e, "error", model_json_number(err));
    json_object_set_new(e, "z", sigma > 0 ? model_json_number(z) : json_null());
    if (note && *note) json_object_set_new(e, "note", json_string(note));
    json_array_append_new(c->entries, e);
}

// A file of the lab day's formats checked as its reader checks it: another
// format or a newer version is a note in "missing" and the file is not used.
static bool format_ok(const char *role, const json_t *j, const char *path)
{
    int v;
    if (!strcmp(role, "geometry")) return calib_geometry_json_check(j, path, &v);
    if (!strcmp(role, "lamps")) return calib_lamps_json_check(j, path, &v);
    if (!strcmp(role, "gain")) return model_json_format_check(j, path, CALIB_GAIN_FORMAT, CALIB_GAIN_FORMAT_VERSION, &v);
    if (!strcmp(role, "white")) return model_json_format_check(j, path, CALIB_WHITE_FORMAT, CALIB_WHITE_FORMAT_VERSION,
                                                               &v);
    if (!strcmp(role, "priors")) return fit_priors_check_format(j, path, &v);
    if (!strcmp(role, "verify")) return model_json_format_check(j, path, VERIFY_JSON_FORMAT, VERIFY_JSON_VERSION, &v);
    return true;
}

static json_t *load(chain_t *c, const char *role, const char *rel)
{
    char *p = g_build_filename(c->dir, rel, NULL);
    json_error_t je;
    json_t *j = g_file_test(p, G_FILE_TEST_EXISTS) ? json_load_file(p, 0, &je) : NULL;
    if (j && !format_ok(role, j, p)) {
        char *why = g_strdup_printf("%s (%s)", rel, model_last_error());
        json_array_append_new(c->missing, json_string(why));
        g_free(why);
        json_decref(j);
        j = NULL;
    } else if (j) {
        model_provenance_input(c->prov, role, p);
    } else {
        json_array_append_new(c->missing, json_string(rel));
    }
    g_free(p);
    return j;
}

static double num(const json_t *o, const char *key)
{
    const json_t *v = json_object_get(o, key);
    return json_is_number(v) ? json_number_value(v) : NAN;
}

// ---------------------------------------------------------------------------
// Camera geometry

// sqrt(mean(stdev^2)) of geometry.json's projection-uncertainty grid: the
// stated 1-sigma of an RMS projection difference over the imager.
static double uncertainty_rms(const json_t *pu)
{
    const json_t *rows = json_object_get(pu, "stdev_px"), *row;
    size_t i, j;
    double s = 0;
    int n = 0;
    json_array_foreach(rows, i, row) {
        const json_t *v;
        json_array_foreach(row, j, v) {
            s += json_number_value(v) * json_number_value(v);
            n++;
        }
    }
    return n ? sqrt(s / n) : NAN;
}

// The intrinsics core's (fx, fy, cx, cy) 1-sigma of mrcal's solve, which
// the geometry step keeps in DIR/calib/geometry/mrcal/solution.json
// (intrinsics_core_stdev, its first camera's) when its intrinsics are the
// camera's (cam's "intrinsics" equal). false: none.
static bool intrinsics_stdev(chain_t *c, const json_t *cam, double sd[4])
{
    char *p = g_build_filename(c->dir, "calib", "geometry", "mrcal", "solution.json", NULL);
    json_error_t je;
    json_t *sol = g_file_test(p, G_FILE_TEST_EXISTS) ? json_load_file(p, 0, &je) : NULL;
    const json_t *s = json_object_get(sol, "intrinsics_core_stdev"), *a = json_object_get(sol, "intrinsics"),
                 *b = json_object_get(cam, "intrinsics");
    bool ok = json_array_size(s) == 4 && json_array_size(a) >= 4 && json_array_size(b) >= 4;
    for (int k = 0; ok && k < 4; k++) {
        sd[k] = json_number_value(json_array_get(s, k));
        double x = json_number_value(json_array_get(a, k)), y = json_number_value(json_array_get(b, k));
        ok = sd[k] > 0 && fabs(x - y) <= 1e-6 * fmax(1, fabs(y));
    }
    if (ok) model_provenance_input(c->prov, "geometry_solution", p);
    json_decref(sol);
    g_free(p);
    return ok;
}

static void chain_camera(chain_t *c, const json_t *cam, const char *model_path, const char *truth_cam,
                         const char *label)
{
    char *tpath = rig_truth_camera_model_path(c->truth, truth_cam);
    mrcal_cameramodel_t *t = tpath ? model_cameramodel_read(tpath) : NULL;
    mrcal_cameramodel_t *b = model_cameramodel_read(model_path);
    char name[160], note[200];
    if (!t || !b) {
        snprintf(note, sizeof note, "%s: %s", label, !b ? model_path : tpath ? tpath : "no [camera] model");
        json_array_append_new(c->missing, json_string(note));
        goto done;
    }
    model_provenance_input(c->prov, "camera_model", model_path);
    static const char *const in[4] = { "fx", "fy", "cx", "cy" };
    double isd[4];
    bool have_sd = intrinsics_stdev(c, cam, isd);
    for (int k = 0; k < 4; k++) {
        snprintf(name, sizeof name, "%s.%s", label, in[k]);
        add(c, "camera geometry", name, b->intrinsics[k], t->intrinsics[k], have_sd ? isd[k] : NAN, "px",
            have_sd ? "sigma: mrcal's solve, the marginal 1-sigma (geometry's mrcal/solution.json "
                      "intrinsics_core_stdev: (J^T J)^-1 scaled by the residuals' RMS^2; the intrinsics are "
                      "correlated, so a single one's z alone says little of the projection)"
                    : "no sigma stated (geometry's mrcal/solution.json has no intrinsics_core_stdev for it)");
    }
    calib_projection_diff_t d;
    const json_t *pu = json_object_get(cam, "projection_uncertainty");
    double dist = num(pu, "distance_mm");
    if (!isfinite(dist)) dist = 900;
    double focus = fmin(t->imagersize[0], t->imagersize[1]) / 6.0;
    if (calib_projection_diff(t, b, dist, 0, focus, &d)) {
        snprintf(note, sizeof note, "over the imager at %g mm, after the rigid alignment that fits best within "
                 "%.0f px of the centre (mrcal's projection_diff default); sigma: RMS of the stated projection "
                 "uncertainty", dist, focus);
        snprintf(name, sizeof name, "%s.projection_error_rms", label);
        add(c, "camera geometry", name, d.rms_px, 0, uncertainty_rms(pu), "px", note);
        snprintf(name, sizeof name, "%s.projection_error_worst", label);
        add(c, "camera geometry", name, d.worst_px, 0, num(pu, "max_px"), "px",
            "the worst grid point; sigma: the worst stated projection uncertainty");
    } else {
        snprintf(note, sizeof note, "%s projection difference: %s", label, model_last_error());
        json_array_append_new(c->missing, json_string(note));
    }
    if (!c->cams) {   // the first camera: where the lamps are compared in its frame
        memcpy(c->rt_cam_rig_cal, b->rt_cam_ref, sizeof c->rt_cam_rig_cal);
        memcpy(c->rt_cam_rig_truth, t->rt_cam_ref, sizeof c->rt_cam_rig_truth);
        c->cams = true;
    }
    // the camera's centre in the rig frame, and the turntable axis
    double rt_ref_cam[6], R[9];
    mrcal_invert_rt(rt_ref_cam, NULL, NULL, t->rt_cam_ref);
    const json_t *cc = json_object_get(cam, "camera_centre_rig_mm");
    double ccs = num(json_object_get(json_object_get(cam, "axis"), "rig_frame_sigma"), "camera_centre_mm");
    for (int k = 0; cc && k < 3; k++) {
        snprintf(name, sizeof name, "%s.centre_rig.%c", label, "xyz"[k]);
        add(c, "camera geometry", name, json_number_value(json_array_get(cc, k)), rt_ref_cam[3 + k], ccs, "mm",
            isfinite(ccs) ? "the camera's centre in the rig frame; sigma: geometry.json axis.rig_frame_sigma."
                            "camera_centre_mm (the rig frame's origin and turn as the axis fit determines them, at "
                            "the camera's distance; one figure for the centre, taken for each coordinate). The "
                            "frame's azimuth rests on the flat board's placement, which no fit of these views sees"
                          : "the camera's centre in the rig frame (the calibration's frame rests on the flat "
                            "board's placement: its azimuth and origin carry that placement's error); no sigma "
                            "stated");
    }
    const json_t *ax = json_object_get(cam, "axis");
    const json_t *dc = json_object_get(ax, "direction_cam");
    double a[3];
    if (json_array_size(dc) == 3 && rig_truth_axis(c->truth, a)) {
        mrcal_R_from_r(R, NULL, t->rt_cam_ref);
        double dot = 0;
        for (int k = 0; k < 3; k++)
            dot += json_number_value(json_array_get(dc, k)) * (R[k * 3] * a[0] + R[k * 3 + 1] * a[1] + R[k * 3 + 2] * a[2]);
        snprintf(name, sizeof name, "%s.axis_direction_angle", label);
        add(c, "camera geometry", name, acos(fmin(1, fabs(dot))) * 180 / M_PI, 0,
            num(ax, "direction_uncertainty_deg"), "deg",
            "angle between the fitted turntable axis and the truth's (rig z, or as [turntable] axis_tilt_deg "
            "leans it), in the camera frame");
    }
done:
    if (t) mrcal_free_cameramodel(&t);
    if (b) mrcal_free_cameramodel(&b);
    g_free(tpath);
}

static void chain_geometry(chain_t *c, const json_t *geo)
{
    const json_t *cams = json_object_get(geo, "cameras"), *cam;
    size_t i;
    if (json_array_size(cams) == 0) {
        char *p = g_build_filename(c->dir, "calib", "geometry", "camera.cameramodel", NULL);
        chain_camera(c, geo, p, NULL, "camera");
        g_free(p);
        return;
    }
    json_array_foreach(cams, i, cam) {
        const char *n = json_string_value(json_object_get(cam, "name"));
        if (!n) continue;
        char *file = g_strdup_printf("%s.cameramodel", n), sec[96], label[96];
        char *p = g_build_filename(c->dir, "calib", "geometry", file, NULL);
        snprintf(sec, sizeof sec, "camera %s", n);
        snprintf(label, sizeof label, "camera_%s", n);
        // a camera's own axis and centre are in geometry.json's top level for the first
        json_t *merged = json_deep_copy(cam);
        if (i == 0) {
            json_object_set(merged, "axis", json_object_get(geo, "axis"));
            if (!json_object_get(merged, "camera_centre_rig_mm"))
                json_object_set(merged, "camera_centre_rig_mm", json_object_get(geo, "camera_centre_rig_mm"));
        }
        chain_camera(c, merged, p, rig_truth_has_camera(c->truth, n) ? n : NULL, label);
        json_decref(merged);
        g_free(p);
        g_free(file);
    }
}

// ---------------------------------------------------------------------------
// Lamps, sensor, white

// A lamp in the first camera's frame (calibrated: through the calibrated
// camera's rig pose; truth: through the truth's): the comparison free of how
// the calibration's rig frame was laid (the flat board's placement sets its
// azimuth and origin). sigma: the covariance turned into the camera frame.
static void chain_lamp_in_camera(chain_t *c, const char *n, const double v[3], const double t[3], const json_t *cov)
{
    double vc[3], tc[3], R[9], C[9], RC[9];
    mrcal_transform_point_rt(vc, NULL, NULL, c->rt_cam_rig_cal, v);
    mrcal_transform_point_rt(tc, NULL, NULL, c->rt_cam_rig_truth, t);
    mrcal_R_from_r(R, NULL, c->rt_cam_rig_cal);
    bool have_cov = json_array_size(cov) == 9;
    for (int k = 0; k < 9; k++) C[k] = have_cov ? json_number_value(json_array_get(cov, k)) : NAN;
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++) RC[i * 3 + j] = R[i * 3] * C[j] + R[i * 3 + 1] * C[3 + j] + R[i * 3 + 2] * C[6 + j];
    for (int k = 0; k < 3; k++) {
        double var = RC[k * 3] * R[k * 3] + RC[k * 3 + 1] * R[k * 3 + 1] + RC[k * 3 + 2] * R[k * 3 + 2];
        char name[160];
        snprintf(name, sizeof name, "lamp_%s.camera_%c", n, "xyz"[k]);
        add(c, "lamps", name, vc[k], tc[k], var > 0 ? sqrt(var) : NAN, "mm",
            "the first camera's frame (x right, y down, z forward): free of the rig frame's placement; sigma: the "
            "covariance turned into that frame (the camera's own uncertainty not included)");
    }
}

static void chain_lamps(chain_t *c, const json_t *lj)
{
    const json_t *l;
    size_t i;
    json_array_foreach(json_object_get(lj, "lamps"), i, l) {
        const char *n = json_string_value(json_object_get(l, "name"));
        char name[160];
        double t[3];
        if (!n || !rig_truth_lamp_position(c->truth, n, t)) continue;
        const json_t *p = json_object_get(l, "position_mm"), *s = json_object_get(l, "std_mm");
        double v[3];
        for (int k = 0; k < 3; k++) {
            v[k] = json_number_value(json_array_get(p, k));
            snprintf(name, sizeof name, "lamp_%s.%c", n, "xyz"[k]);
            add(c, "lamps", name, v[k], t[k],
                json_is_number(json_array_get(s, k)) ? json_number_value(json_array_get(s, k)) : NAN, "mm",
                "rig frame; sigma from the triangulation's covariance");
        }
        if (c->cams) chain_lamp_in_camera(c, n, v, t, json_object_get(l, "covariance_mm2"));
    }
}

static void chain_gain(chain_t *c, const json_t *g)
{
    static const struct { const char *key, *truth, *unit; } k[] = {
        { "system_gain_dn_per_e", "system_gain_dn_per_e", "DN/e-" },
        { "read_noise_e", "read_noise_e", "e-" },
        { "dsnu_dn", "dsnu_dn", "DN" },
        { "prnu_pct", "prnu_pct", "%" },
        { "dark_current_e_per_s", "dark_current_e_per_s", "e-/s" },
    };
    const json_t *sd = json_object_get(g, "std");
    // The read noise and dark current as EMVA 1288 defines them (the temporal
    // dark noise at exposure 0, the mean dark level's slope) are what the
    // truth's sensor delivers: its read noise through the response's low end
    // plus its row noise; its dark current (hot pixels' included) through the
    // same response, over the dark frames' exposures. With a response linear
    // at 0 and neither row noise nor hot pixels, these are its parameters.
    model_sensor_t ts;
    double rn_m = NAN, dc_m = NAN, dt[256];
    int nt = 0;
    const json_t *jt = json_object_get(g, "dark_exposures_us"), *x;
    size_t i;
    json_array_foreach(jt, i, x) if (nt < 256 && json_is_number(x)) dt[nt++] = json_number_value(x);
    if (rig_truth_sensor(c->truth, NULL, &ts)) {
        if (!model_sensor_dark_measurand(&ts, NULL, 0, &rn_m, NULL)) rn_m = NAN;
        if (!model_sensor_dark_measurand(&ts, dt, nt, NULL, &dc_m)) dc_m = NAN;   // (no dark_exposures_us: none)
    }
    for (i = 0; i < sizeof k / sizeof k[0]; i++) {
        char name[96], note[600];
        snprintf(name, sizeof name, "sensor.%s", k[i].key);
        double t = rig_truth_sensor_value(c->truth, k[i].truth), s = num(sd, k[i].key);
        if (!isfinite(t)) continue;
        snprintf(note, sizeof note, isfinite(s) ? "sigma: gain.json std.%s (from the fit's statistics; gain.json "
                 "std_method)" : "no sigma stated (gain.json has no std.%s)", k[i].key);
        bool rn = !strcmp(k[i].key, "read_noise_e"), dc = !strcmp(k[i].key, "dark_current_e_per_s");
        double tm = rn ? rn_m : dc ? dc_m : NAN;
        if (isfinite(tm) && fabs(tm - t) > 1e-4 * fabs(t)) {
            size_t l = strlen(note);
            snprintf(note + l, sizeof note - l, "; truth: as EMVA 1288 defines it, what the truth's sensor "
                     "delivers (%s; model_sensor_dark_measurand): %.4g %s, its [sensor] %s being %.4g",
                     rn ? "the read noise through the response's low end, with the row noise"
                        : "through the response's low end, hot pixels included, over the dark frames' exposures",
                     tm, k[i].unit, k[i].truth, t);
            t = tm;
        }
        add(c, "sensor (EMVA 1288)", name, num(g, k[i].key), t, s, k[i].unit, note);
    }
}

static void chain_white(chain_t *c, const json_t *w, const json_t *g)
{
    double kc = rig_truth_kc_per_us(c->truth, NULL), ks = num(g, "kc_small_signal_per_us");
    double gmean = isfinite(ks) && kc > 0 ? ks / kc : 1;
    const json_t *l;
    size_t i;
    json_array_foreach(json_object_get(w, "lamps"), i, l) {
        const char *n = json_string_value(json_object_get(l, "name"));
        char name[160];
        double I = rig_truth_lamp_intensity(c->truth, n ? n : ""), v = num(l, "kc_I_per_us");
        if (!isfinite(I) || !isfinite(kc)) continue;
        snprintf(name, sizeof name, "white.kc_I_%s", n);
        double sr = num(l, "std_rel");
        bool total = isfinite(sr);
        add(c, "reference white", name, v, kc * I * gmean, v * (total ? sr : num(l, "std_of_median_rel")),
            "DN/us per (1/sr)/mm^2",
            total ? "truth: kc_per_us * I * mean(g), mean(g) the flat field's mean from the gain calibration's "
                    "small-signal kc; sigma: white.json's total (std_rel: statistical, lamp position, emission "
                    "pattern, albedo, flat field in quadrature; sigma_parts_rel)"
                  : "truth: kc_per_us * I * mean(g), mean(g) the flat field's mean from the gain calibration's "
                    "small-signal kc; sigma: the median's standard error (white.json states no total)");
    }
}

// Each lamp's light over the samples' region (calib_region_points: x, y in
// [-60, 60] mm, z 5 and 50 mm): the irradiance of the calibrated lamp, kc*I
// (white.json) times the emission pattern (lamps.json; isotropic without one)
// over its squared distance from the calibrated position, against the truth's
// kc I mean(g) times its pattern over the squared distance from the true
// position: the largest relative error (%), truth 0. sigma: white.json's
// irradiance_samples_region.std_max_pct (the white's kc*I with the lamp's
// position and pattern through the same draws); without it, the pattern's
// irradiance_std_pct and the white's std_rel in quadrature.
static void chain_lamp_irradiance(chain_t *c, const json_t *lj, const json_t *w, const json_t *g)
{
    double kc = rig_truth_kc_per_us(c->truth, NULL), ks = num(g, "kc_small_signal_per_us");
    double gmean = isfinite(ks) && kc > 0 ? ks / kc : 1;
    model_lamps_t *tl = rig_truth_lamps(c->truth);
    const json_t *l, *e;
    size_t i, j;
    json_array_foreach(json_object_get(lj, "lamps"), i, l) {
        const char *n = json_string_value(json_object_get(l, "name"));
        int k = n && tl ? model_lamps_find(tl, n) : -1;
        double v = NAN, sig = NAN;
        json_array_foreach(json_object_get(w, "lamps"), j, e)
            if (n && !g_strcmp0(json_string_value(json_object_get(e, "name")), n)) {
                v = num(e, "kc_I_per_us");
                sig = num(json_object_get(e, "irradiance_samples_region"), "std_max_pct");
                if (!isfinite(sig)) {
                    double ps = num(json_object_get(l, "emission"), "irradiance_std_pct"), ws = num(e, "std_rel");
                    sig = isfinite(ws) && isfinite(ps) ? hypot(ps, 100 * ws) : ps;
                }
            }
        const json_t *p = json_object_get(l, "position_mm"), *ax = json_object_get(l, "emission_axis");
        if (k < 0 || !isfinite(v) || !isfinite(kc) || json_array_size(p) != 3) continue;
        model_lamp_t M = { .position_mm = v3(json_number_value(json_array_get(p, 0)),
                                             json_number_value(json_array_get(p, 1)),
                                             json_number_value(json_array_get(p, 2))) };
        if (json_is_number(json_object_get(l, "emission_cos_power")) && json_array_size(ax) == 3) {
            M.emission_cos_power = json_number_value(json_object_get(l, "emission_cos_power"));
            M.emission_axis = v3_unit(v3(json_number_value(json_array_get(ax, 0)),
                                         json_number_value(json_array_get(ax, 1)),
                                         json_number_value(json_array_get(ax, 2))));
        }
        const model_lamp_t *T = &tl->lamps[k];
        double worst = 0;
        model_vec3_t q[CALIB_REGION_MAX];
        int nq = calib_region_points(q);
        for (int iq = 0; iq < nq; iq++) {
            model_vec3_t dm = v3_sub(q[iq], M.position_mm), dt = v3_sub(q[iq], T->position_mm);
            double m = v * model_lamp_emission(&M, q[iq]) / v3_dot(dm, dm);
            double t = kc * T->intensity * gmean * model_lamp_emission(T, q[iq]) / v3_dot(dt, dt);
            worst = fmax(worst, fabs(m / t - 1));
        }
        char name[160];
        snprintf(name, sizeof name, "lamp_%s.irradiance_max_err", n);
        add(c, "lamps", name, 100 * worst, 0, sig, "%",
            "the calibrated lamp's irradiance, kc*I (white) times the emission pattern (lamps.json; isotropic "
            "without one) over the squared distance from its calibrated position, against the truth's over the "
            "samples' region (x, y within 60 mm, z 5 and 50 mm): the largest relative error; sigma: white.json's "
            "irradiance_samples_region.std_max_pct");
    }
    model_lamps_free(tl);
}

// ---------------------------------------------------------------------------
// Materials and verdicts

// A fitted material against its best fit: where the truth is a table
// (tabulated physics), a material whose roughness varies from place to place
// ([texture NAME] roughness_amplitude a: the virtual rig renders a per-pixel
// mixture (1 - w) f_smooth + w f_rough of rig_vmat_variants' two populations,
// w = 0.5 + 0.5 value noise of mean 0, so the material's mean BRDF is 0.5
// f_smooth + 0.5 f_rough), or a model other than the fitted one, no parameter
// of the fitted model is the truth's: the fair comparison is with the best fit
// of the fitted model to the truth's (mean) BRDF over Ngan et al.'s (2005)
// integral (fit_samples_ngan, every other theta_d and phi_d cell of the MERL
// grid). Entries: each parameter against the best fit's, with its std; the
// Ngan error of the fitted parameters with the best fit's as truth and their
// ratio (null where the best fit reproduces the truth to 1e-3 of its RMS: a
// ratio to ~0 says nothing); the excess sqrt(e^2 - e_best^2) with the RMS
// change of R the priors' covariance implies as sigma. false: none of these
// apply (the caller compares each parameter with the truth's own).
static bool chain_material_best_fit(chain_t *c, const json_t *m, const model_material_t *tm)
{
    const char *n = json_string_value(json_object_get(m, "name"));
    int model = model_brdf_from_name(json_string_value(json_object_get(m, "model")));
    const json_t *ps = json_object_get(m, "parameters"), *pc = json_object_get(m, "prior_covariance");
    char name[200], note[400], what[160];
    double amp = rig_truth_roughness_amplitude(c->truth, n ? n : "");
    bool rough = !tm || tm->table ? false : isfinite(amp) && amp > 0;
    if (!tm || !n || model < 0 || (int)json_array_size(ps) != model_brdf_nparams((model_brdf_t)model)) return false;
    if (!tm->table && !rough && tm->model == (model_brdf_t)model) return false;
    int np = model_brdf_nparams((model_brdf_t)model);
    double p[MODEL_BRDF_MAX_PARAMS], sd[MODEL_BRDF_MAX_PARAMS], C[MODEL_BRDF_MAX_PARAMS * MODEL_BRDF_MAX_PARAMS];
    const json_t *mat = json_object_get(pc, "matrix");
    for (int a = 0; a < np; a++) {
        p[a] = num(json_array_get(ps, (size_t)a), "mean");
        sd[a] = num(json_array_get(ps, (size_t)a), "std");
        for (int b = 0; b < np; b++) {   // the priors' full covariance, else the std alone (independent)
            const json_t *v = json_array_get(json_array_get(mat, (size_t)a), (size_t)b);
            C[a * np + b] = json_array_size(mat) == (size_t)np ? (json_is_number(v) ? json_number_value(v) : NAN)
                          : a == b ? sd[a] * sd[a] : 0;
        }
    }
    model_material_t *store = NULL;
    const model_material_t *mats[2] = { tm, tm }, *rr = NULL, *ss = NULL;
    double wts[2] = { 1, 0 };
    if (rough && rig_vmat_variants(1, &tm, &amp, rig_truth_path(c->truth), rig_truth_texture_line(c->truth, n),
                                   &store, &rr, &ss)) {
        mats[0] = ss, mats[1] = rr, wts[0] = wts[1] = 0.5;
        snprintf(what, sizeof what, "the mean of its two roughness populations (alpha or m scaled by 1 -+ %g, ns "
                 "by 1/(1 -+ %g)^2; half each)", amp, amp);
    } else {
        snprintf(what, sizeof what, "%s", tm->table ? "its table" : "the truth's own model");
    }
    fit_mixture_t mix = { 2, mats, wts };
    fit_samples_t *s = !rough || store ? fit_samples_ngan(fit_mixture_R, &mix, 2) : NULL;
    fit_brdf_result_t *best = malloc(sizeof *best);
    if (!best) model_error_set(NULL, 0, "out of memory");
    fit_brdf_options_t o = fit_brdf_defaults();
    bool ok = s && best && fit_brdf(s, (model_brdf_t)model, &o, best);
    if (ok) {
        double e = fit_samples_rms(s, (model_brdf_t)model, p), eb = best->ngan_error;
        double rms_R = 0, sw = 0;
        for (int i = 0; i < s->n; i++) rms_R += s->w[i] * s->R[i] * s->R[i], sw += s->w[i];
        rms_R = sqrt(rms_R / sw);
        double e_sigma = fit_samples_rms_of_cov(s, (model_brdf_t)model, p, C);
        snprintf(name, sizeof name, "material_%s.ngan_error", n);
        snprintf(note, sizeof note, "the fitted %s against %s, the Ngan et al. (2005) error (RMS of (f_model - f) "
                 "cos theta_i over both hemispheres within %d deg of the normal, MERL cells); truth column: the best "
                 "fit of %s to it", model_brdf_name((model_brdf_t)model), what, FIT_NGAN_THETA_MAX_DEG,
                 model_brdf_name((model_brdf_t)model));
        add(c, "materials", name, e, eb, NAN, "1/sr", note);
        snprintf(name, sizeof name, "material_%s.ngan_error_ratio", n);
        bool within = !(eb > 1e-3 * rms_R);
        add(c, "materials", name, within ? NAN : e / eb, 1, NAN, "1",
            within ? "null: the best fit reproduces the truth (its Ngan error is below 1e-3 of the BRDF's RMS), so no "
                     "fit comes within a ratio of it; see ngan_error_excess and the parameters' z"
                   : "the chain's Ngan error over the best fit's (the chain should come within 1.2)");
        snprintf(name, sizeof name, "material_%s.ngan_error_excess", n);
        add(c, "materials", name, sqrt(fmax(0, e * e - eb * eb)), 0, e_sigma, "1/sr",
            "sqrt(ngan_error^2 - best^2): what the fitted parameters add to the best fit's error; sigma: the RMS "
            "change of R over the same integral that the priors' covariance (prior_covariance, else the std) "
            "implies, sqrt(trace(C H) / sum w) with H = sum w J J^T");
        snprintf(note, sizeof note, "truth: the best fit of %s to %s over Ngan's integral (the truth has no %s "
                 "parameters of its own); sigma: the priors' std", model_brdf_name((model_brdf_t)model), what,
                 model_brdf_name((model_brdf_t)model));
    } else {
        snprintf(note, sizeof note, "material %s: the best fit to the truth (%s) failed: %s", n, what,
                 model_last_error());
        json_array_append_new(c->missing, json_string(note));
        snprintf(note, sizeof note, "no truth: the best fit of the model to the truth failed");
    }
    for (int a = 0; a < np; a++) {
        const json_t *pj = json_array_get(ps, (size_t)a);
        const char *pn = json_string_value(json_object_get(pj, "name"));
        const char *unit = json_string_value(json_object_get(pj, "unit"));
        snprintf(name, sizeof name, "material_%s.%s", n, pn ? pn : "?");
        add(c, "materials", name, p[a], ok ? best->p[a] : NAN, sd[a], unit ? unit : "", note);
    }
    fit_samples_free(s);
    free(best);
    free(store);
    return true;
}

static void chain_priors(chain_t *c, const json_t *pj)
{
    const json_t *m, *p;
    size_t i, j;
    json_array_foreach(json_object_get(pj, "materials"), i, m) {
        const char *n = json_string_value(json_object_get(m, "name"));
        const char *model = json_string_value(json_object_get(m, "model"));
        char name[200], note[200];
        const char *tmodel = rig_truth_material_model(c->truth, n ? n : "");
        bool same = model && tmodel && !strcmp(model, tmodel);
        snprintf(note, sizeof note, same ? "the truth's model (%s); sigma: the fit's"
                 : "fitted model %s, the truth's is %s: no truth per parameter", model ? model : "?",
                 tmodel ? tmodel : "none");
        const model_material_t *tm = c->mats && n ? model_materials_find(c->mats, n) : NULL;
        if (chain_material_best_fit(c, m, tm)) continue;   // a table, varying roughness, another model
        json_array_foreach(json_object_get(m, "parameters"), j, p) {
            const char *pn = json_string_value(json_object_get(p, "name"));
            const char *unit = json_string_value(json_object_get(p, "unit"));
            if (!pn) continue;
            snprintf(name, sizeof name, "material_%s.%s", n, pn);
            add(c, "materials", name, num(p, "mean"), same ? rig_truth_material_param(c->truth, n, pn) : NAN,
                num(p, "std"), unit ? unit : "", note);
        }
    }
}

// A verdict: expected "correct" when the verified description is (byte for
// byte) the scene of one of the truth's samples, else "incorrect".
static void chain_verdict(chain_t *c, const char *sub, const json_t *v)
{
    const char *scene = json_string_value(json_object_get(v, "scene"));
    const char *verdict = json_string_value(json_object_get(v, "verdict"));
    char sha[65] = "", tsha[65];
    if (!scene || !verdict || !model_sha256_file(scene, sha)) return;
    bool expect_correct = false;
    const char *sn;
    for (int s = 0; (sn = rig_truth_sample_name(c->truth, s)) && !expect_correct; s++) {
        char *sp = rig_truth_sample_scene_path(c->truth, sn);
        if (sp && model_sha256_file(sp, tsha)) expect_correct = !strcmp(sha, tsha);
        free(sp);
    }
    model_error_clear();
    const char *want = expect_correct ? "correct" : "incorrect";
    json_t *e = json_object();
    char name[160], note[300];
    snprintf(name, sizeof name, "verify_%s.verdict", sub);
    snprintf(note, sizeof note, "%s: score %g, threshold %g (error 1: not the expected verdict)", scene,
             num(v, "score"), num(v, "score_threshold"));
    json_object_set_new(e, "name", json_string(name));
    json_object_set_new(e, "group", json_string("verification"));
    json_object_set_new(e, "value", json_string(verdict));
    json_object_set_new(e, "truth", json_string(want));
    json_object_set_new(e, "sigma", json_null());
    json_object_set_new(e, "unit", json_string(""));
    json_object_set_new(e, "error", json_integer(strcmp(verdict, want) != 0));
    json_object_set_new(e, "z", json_null());
    json_object_set_new(e, "note", json_string(note));
    json_array_append_new(c->entries, e);
    snprintf(name, sizeof name, "verify_%s.score", sub);
    add(c, "verification", name, num(v, "score"), NAN, NAN, "",
        expect_correct ? "the correct description: should stay below the threshold"
                       : "a wrong description: should exceed the threshold");
}

static void chain_dir_files(chain_t *c)
{
    GDir *d = g_dir_open(c->dir, 0, NULL);
    GPtrArray *names = g_ptr_array_new_with_free_func(g_free);
    const char *n;
    while (d && (n = g_dir_read_name(d))) g_ptr_array_add(names, g_strdup(n));
    if (d) g_dir_close(d);
    // in name order
    for (guint i = 1; i < names->len; i++)
        for (guint j = i; j > 0 && strcmp(names->pdata[j - 1], names->pdata[j]) > 0; j--) {
            gpointer t = names->pdata[j];
            names->pdata[j] = names->pdata[j - 1];
            names->pdata[j - 1] = t;
        }
    for (guint i = 0; i < names->len; i++) {
        const char *f = names->pdata[i];
        if (g_str_has_prefix(f, "priors_") && g_str_has_suffix(f, ".json")) {
            json_t *pj = load(c, "priors", f);
            if (pj) chain_priors(c, pj);
            json_decref(pj);
        }
    }
    for (guint i = 0; i < names->len; i++) {
        const char *f = names->pdata[i];
        char *vp = g_build_filename(c->dir, f, "verify.json", NULL);
        if (g_file_test(vp, G_FILE_TEST_EXISTS)) {
            char *rel = g_build_filename(f, "verify.json", NULL);
            json_t *v = load(c, "verify", rel);
            if (v) chain_verdict(c, g_str_has_prefix(f, "verify_") ? f + 7 : f, v);
            json_decref(v);
            g_free(rel);
        }
        g_free(vp);
    }
    g_ptr_array_free(names, TRUE);
}

// ---------------------------------------------------------------------------

static json_t *summary(const json_t *entries)
{
    json_t *s = json_object(), *over = json_array(), *ngan = json_array();
    const json_t *e;
    size_t i;
    int with = 0, without = 0, wrong = 0;
    json_array_foreach(entries, i, e) {
        const json_t *z = json_object_get(e, "z");
        if (json_is_number(z)) {
            with++;
            if (fabs(json_number_value(z)) > 3) json_array_append(over, json_object_get(e, "name"));
        } else if (json_is_number(json_object_get(e, "truth")))
            without++;
        if (json_is_string(json_object_get(e, "value")) && json_integer_value(json_object_get(e, "error")))
            wrong++;
        if (g_str_has_suffix(json_string_value(json_object_get(e, "name")), ".ngan_error_ratio") &&
            json_number_value(json_object_get(e, "value")) > 1.2)
            json_array_append(ngan, json_object_get(e, "name"));
    }
    json_object_set_new(s, "entries", json_integer((json_int_t)json_array_size(entries)));
    json_object_set_new(s, "with_sigma", json_integer(with));
    json_object_set_new(s, "without_sigma", json_integer(without));
    json_object_set_new(s, "z_over_3", over);
    json_object_set_new(s, "wrong_verdicts", json_integer(wrong));
    json_object_set_new(s, "ngan_ratio_over_1_2", ngan);
    return s;
}

json_t *eval_chain_compare(const char *dir, const char *truth_path, json_t *prov)
{
    chain_t c = { .dir = dir, .prov = prov };
    c.truth = rig_truth_load(truth_path);
    if (!c.truth) return NULL;
    c.mats = rig_truth_materials(c.truth);
    c.entries = json_array();
    c.missing = json_array();
    model_provenance_input(prov, "truth", truth_path);
    json_t *geo = load(&c, "geometry", "calib/geometry/geometry.json"), *doc = NULL;
    if (!geo) {
        char *p = g_build_filename(dir, "calib", "geometry", "geometry.json", NULL);
        model_error(p, 0, "cannot read it: refl chain compares a lab day's directory (refl demo -o DIR), which "
                    "holds calib/geometry/geometry.json");
        g_free(p);
        goto done;
    }
    chain_geometry(&c, geo);
    json_t *lj = load(&c, "lamps", "calib/lamps/lamps.json");
    if (lj) chain_lamps(&c, lj);
    json_t *gj = load(&c, "gain", "calib/gain/gain.json");
    if (gj) chain_gain(&c, gj);
    json_t *wj = load(&c, "white", "calib/white/white.json");
    if (wj) chain_white(&c, wj, gj);
    if (wj && lj) chain_lamp_irradiance(&c, lj, wj, gj);
    chain_dir_files(&c);
    json_decref(lj);
    json_decref(gj);
    json_decref(wj);
    doc = json_object();
    model_json_set_format(doc, "refl-chain", 1);
    json_object_set_new(doc, "chain", json_string("refl chain: the lab day's calibrated and fitted figures against "
                                                  "the truth of the virtual rig it ran on"));
    json_object_set_new(doc, "dir", json_string(dir));
    json_object_set_new(doc, "truth", json_string(truth_path));
    json_object_set_new(doc, "units_and_conventions",
                        json_string("each entry's unit; lengths mm in the rig frame (origin at the turntable top "
                                    "centre, z up); pixels px with (0,0) the centre of the top-left pixel (mrcal); "
                                    "error = value - truth; sigma: the 1-sigma refl states for the value (null: "
                                    "none stated); z = error / sigma; a verdict's error is 1 when it is not the "
                                    "expected one"));
    json_object_set_new(doc, "summary", summary(c.entries));
    json_object_set_new(doc, "entries", c.entries);
    c.entries = NULL;
    json_object_set_new(doc, "missing", c.missing);
    c.missing = NULL;
    json_object_set_new(doc, "provenance", json_incref(prov));
done:
    json_decref(geo);
    json_decref(c.entries);
    json_decref(c.missing);
    model_materials_free(c.mats);
    rig_truth_free(c.truth);
    return doc;
}
