// calib/calset.c — the calibration set a measurement uses: a calibration
// directory's camera model, lamps.json, gain calibration (and its maps) and
// the reference white, read into one calib_set_t (calib/calib.h).
#define _GNU_SOURCE
#include <errno.h>
#include <glib.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "calib/calib.h"
#include "calib/gain/gain.h"
#include "model/base/report.h"
#include "model/base/vec.h"
#include "rig/rig.h"


static char *find_in(const char *dir, const char *sub, const char *name)
{
    char *p = g_strdup_printf("%s/%s", dir, name);
    if (access(p, R_OK) == 0) return p;
    g_free(p);
    p = g_strdup_printf("%s/%s/%s", dir, sub, name);
    if (access(p, R_OK) == 0) return p;
    g_free(p);
    return NULL;
}

static bool add_input(calib_set_t *c, const char *role, const char *path)
{
    return model_inputs_add(c->inputs, role, path);
}

void calib_set_free(calib_set_t *c)
{
    if (!c) return;
    model_camera_free(c->cam);
    model_lamps_free(c->lamps);
    free(c->offset_dn);
    free(c->flat);
    json_decref(c->inputs);
    free(c);
}

static float *read_map(calib_set_t *c, const char *path, const char *role)
{
    int w, h;
    float *m = model_image_read_float(path, &w, &h);
    if (!m) return NULL;
    if (w != c->W || h != c->H) {
        model_error(path, 0, "%dx%d pixels, the camera model's imager is %dx%d", w, h, c->W, c->H);
        free(m);
        return NULL;
    }
    add_input(c, role, path);
    return m;
}

// The lens's blur from the geometry.json beside the camera model (of camera
// NAME when given): c->have_psf, psf_sigma_px, psf_sigma_std_px; the file
// among the inputs once.
static void set_psf(calib_set_t *c, const char *cam, const char *camera)
{
    char *gj = NULL;
    c->have_psf = calib_psf_read(cam, camera, &c->psf_sigma_px, &c->psf_sigma_std_px, &c->psf_pixel_fill, &gj);
    if (!c->have_psf) c->psf_sigma_px = c->psf_sigma_std_px = 0, c->psf_pixel_fill = 1;
    bool listed = false;
    size_t i;
    json_t *e;
    json_array_foreach(c->inputs, i, e) listed |= !g_strcmp0(json_string_value(json_object_get(e, "role")), "geometry");
    if (gj && !listed) add_input(c, "geometry", gj);
    g_free(gj);
}

calib_set_t *calib_set_load(const char *dir, bool need_white)
{
    char *cam = find_in(dir, "geometry", "camera.cameramodel"), *lamps = find_in(dir, "lamps", "lamps.json");
    char *gain = find_in(dir, "gain", "gain.json"), *white = find_in(dir, "white", "white.json");
    calib_set_t *c = NULL;
    if (!cam)
        model_error(dir, 0, "no camera.cameramodel (nor geometry/camera.cameramodel): run refl calib geometry first");
    else if (!lamps)
        model_error(dir, 0, "no lamps.json (nor lamps/lamps.json): run refl calib lamps first");
    else if (!white && need_white)
        model_error(dir, 0, "no white.json (nor white/white.json): run refl calib white on a reference-white session");
    else
        c = calib_set_load_files(cam, lamps, gain, white);
    g_free(cam);
    g_free(lamps);
    g_free(gain);
    g_free(white);
    return c;
}

// The first of DIR/A, DIR/B (B may be NULL) readable (g_free), or NULL.
static char *first_of(const char *dir, const char *a, const char *b)
{
    char *p = g_strdup_printf("%s/%s", dir, a);
    if (access(p, R_OK) == 0) return p;
    g_free(p);
    if (!b) return NULL;
    p = g_strdup_printf("%s/%s", dir, b);
    if (access(p, R_OK) == 0) return p;
    g_free(p);
    return NULL;
}

// The camera a gain.json records ("" when none or unreadable: the caller reads and reports it).
static void gain_camera(const char *path, char *out, size_t size)
{
    json_t *j = json_load_file(path, 0, NULL);
    snprintf(out, size, "%s", json_string_value(json_object_get(j, "camera")) ?: "");
    json_decref(j);
}

// Camera NAME's model in DIR (g_free), or NULL.
static char *camera_model_of(const char *dir, const char *camera)
{
    char *a = g_strdup_printf("%s.cameramodel", camera), *b = g_strdup_printf("geometry/%s.cameramodel", camera);
    char *cam = first_of(dir, a, b);
    g_free(a);
    g_free(b);
    if (!cam) {
        a = g_strdup_printf("%s/camera.cameramodel", camera);
        cam = first_of(dir, a, NULL);
        g_free(a);
    }
    return cam;
}

bool calib_set_has_camera(const char *dir, const char *camera)
{
    char *cam = camera && *camera ? camera_model_of(dir, camera) : find_in(dir, "geometry", "camera.cameramodel");
    g_free(cam);
    return cam != NULL;
}

calib_set_t *calib_set_load_camera(const char *dir, const char *camera, bool need_white)
{
    if (!camera) return calib_set_load(dir, need_white);
    char *a, *b, *cam = camera_model_of(dir, camera);
    a = g_strdup_printf("%s/gain.json", camera);
    b = g_strdup_printf("gain/%s/gain.json", camera);
    char *gain = first_of(dir, a, b), rec[32];
    g_free(a);
    g_free(b);
    if (!gain && (gain = find_in(dir, "gain", "gain.json"))) {   // the top level's, when it is this camera's
        gain_camera(gain, rec, sizeof rec);
        if (strcmp(rec, camera)) {
            g_free(gain);
            gain = NULL;
        }
    }
    a = g_strdup_printf("%s/white.json", camera);
    b = g_strdup_printf("white/%s/white.json", camera);
    char *white = first_of(dir, a, b), *lamps = find_in(dir, "lamps", "lamps.json");
    g_free(a);
    g_free(b);
    calib_set_t *c = NULL;
    if (!cam)
        model_error(dir, 0, "no %s.cameramodel (nor geometry/%s.cameramodel, %s/camera.cameramodel): run refl calib "
                    "geometry --camera %s first", camera, camera, camera, camera);
    else if (!lamps)
        model_error(dir, 0, "no lamps.json (nor lamps/lamps.json): run refl calib lamps first");
    else if (!white && need_white)
        model_error(dir, 0, "no %s/white.json (nor white/%s/white.json): run refl calib white --camera %s on a "
                    "reference-white session", camera, camera, camera);
    else if ((c = calib_set_load_files(cam, lamps, gain, white))) {
        snprintf(c->camera, sizeof c->camera, "%s", camera);
        set_psf(c, cam, camera);   // the camera's own when the geometry run stored it per camera
    }
    g_free(cam);
    g_free(lamps);
    g_free(gain);
    g_free(white);
    return c;
}

// The lamp's emission pattern of lamps.json (refl calib pattern writes it):
// emission_cos_power = n (0..1000; 0 or absent: isotropic) and emission_axis =
// [x, y, z] (a direction, rig frame; required with n > 0), into l.
static bool lamp_emission(json_t *e, const char *path, size_t i, model_lamp_t *l)
{
    json_t *n = json_object_get(e, "emission_cos_power"), *a = json_object_get(e, "emission_axis");
    if (!n && !a) return true;
    if (!json_is_number(n) || !(json_number_value(n) >= 0 && json_number_value(n) <= 1000)) {
        model_error(path, 0, "lamps[%zu] (%s): emission_cos_power must be a number in [0, 1000] (0: isotropic)", i,
                    l->name);
        return false;
    }
    l->emission_cos_power = json_number_value(n);
    if (!(l->emission_cos_power > 0)) return true;
    double v[3], len = 0;
    for (int k = 0; k < 3; k++) {
        json_t *x = json_array_get(a, (size_t)k);
        v[k] = json_is_number(x) ? json_number_value(x) : NAN;
        len += v[k] * v[k];
    }
    if (json_array_size(a) != 3 || !(len > 1e-24) || !isfinite(len)) {
        model_error(path, 0, "lamps[%zu] (%s): emission_cos_power %g needs emission_axis = [x, y, z], a direction "
                    "(rig frame)", i, l->name, l->emission_cos_power);
        return false;
    }
    len = sqrt(len);
    l->emission_axis = v3(v[0] / len, v[1] / len, v[2] / len);
    return true;
}

// The numbers of a JSON array of n numbers into v; false when it is not one.
static bool json_numbers(const json_t *a, double *v, size_t n)
{
    if (json_array_size(a) != n) return false;
    for (size_t k = 0; k < n; k++) {
        const json_t *x = json_array_get(a, k);
        if (!json_is_number(x)) return false;
        v[k] = json_number_value(x);
    }
    return true;
}

// A lamp's stated 1-sigmas of lamps.json (calib_lamp_sigma_t): what is absent
// stays unstated.
static void lamp_sigma(const json_t *e, calib_lamp_sigma_t *s)
{
    memset(s, 0, sizeof *s);
    double v[9];
    if (json_numbers(json_object_get(e, "covariance_mm2"), s->position_cov_mm2, 9))
        s->have_position = true;
    else if (json_numbers(json_object_get(e, "std_mm"), v, 3)) {
        for (int k = 0; k < 3; k++) s->position_cov_mm2[4 * k] = v[k] * v[k];
        s->have_position = true;
    }
    const json_t *em = json_object_get(e, "emission"), *n = json_object_get(e, "emission_cos_power");
    double a[3];
    if (!json_is_number(n) || !json_numbers(json_object_get(e, "emission_axis"), a, 3)) return;
    double len = sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2]);
    if (!(len > 0)) return;
    s->n = json_number_value(n);
    s->axis = v3(a[0] / len, a[1] / len, a[2] / len);
    double d1[3], d2[3];
    if (json_numbers(json_object_get(em, "covariance_n_t1_t2"), s->pattern_cov, 9) &&
        json_numbers(json_object_get(em, "axis_per_t1"), d1, 3) && json_numbers(json_object_get(em, "axis_per_t2"), d2, 3)) {
        s->axis_per_t[0] = v3(d1[0], d1[1], d1[2]);
        s->axis_per_t[1] = v3(d2[0], d2[1], d2[2]);
        s->have_pattern = true;
        return;
    }
    const json_t *ns = json_object_get(em, "cos_power_std"), *as = json_object_get(em, "axis_std_deg");
    if (!json_is_number(ns) || !json_is_number(as)) return;
    // independent: n, and two tilts (radians) across the axis
    memset(s->pattern_cov, 0, sizeof s->pattern_cov);
    double sa = json_number_value(as) * M_PI / 180;
    s->pattern_cov[0] = json_number_value(ns) * json_number_value(ns);
    s->pattern_cov[4] = s->pattern_cov[8] = sa * sa;
    model_vec3_t h = fabs(s->axis.z) < 0.9 ? v3(0, 0, 1) : v3(1, 0, 0);
    s->axis_per_t[0] = v3_unit(v3_cross(h, s->axis));
    s->axis_per_t[1] = v3_cross(s->axis, s->axis_per_t[0]);
    s->have_pattern = true;
}

// A JSON file of format (a version up to max_version, into *version);
// NULL + message (model_error) when it is not valid JSON or another format or
// version.
static json_t *load_json(const char *path, const char *format, int max_version, int *version)
{
    json_error_t je;
    json_t *j = json_load_file(path, 0, &je);
    if (!j) {
        model_error(path, je.line, "not valid JSON: %s", je.text);
        return NULL;
    }
    if (!model_json_format_check(j, path, format, max_version, version)) {
        char *e = g_strdup(model_last_error());
        model_error(NULL, 0, "%s", e);
        g_free(e);
        json_decref(j);
        return NULL;
    }
    return j;
}

// lamps.json: every lamp's name, position, radius, emission pattern and
// stated 1-sigmas into c->lamps (intensity 1). false + message.
static bool load_lamps(calib_set_t *c, const char *lamps)
{
    json_t *lj = load_json(lamps, "refl-lamps", 1, &c->lamps_version);
    if (!lj) return false;
    bool ok = false;
    json_t *arr = json_object_get(lj, "lamps");
    size_t nl = json_array_size(arr);
    if (!nl || nl > 32) {
        model_error(lamps, 0, "'lamps' must list 1 to 32 lamps (has %zu)", nl);
        goto done;
    }
    c->lamps = calloc(1, sizeof *c->lamps);
    if (!c->lamps || !(c->lamps->lamps = calloc(nl, sizeof *c->lamps->lamps)) || !(c->lamps->path = strdup(lamps))) {
        model_error(lamps, 0, "out of memory");
        goto done;
    }
    for (size_t i = 0; i < nl; i++) {
        json_t *e = json_array_get(arr, i), *p = json_object_get(e, "position_mm");
        const char *name = json_string_value(json_object_get(e, "name"));
        if (!name || json_array_size(p) != 3 || !json_is_number(json_array_get(p, 0)) ||
            !json_is_number(json_array_get(p, 1)) || !json_is_number(json_array_get(p, 2))) {
            model_error(lamps, 0, "lamps[%zu] needs a name and position_mm = [x, y, z]", i);
            goto done;
        }
        model_lamp_t *l = &c->lamps->lamps[i];
        snprintf(l->name, sizeof l->name, "%s", name);
        l->position_mm = v3(json_number_value(json_array_get(p, 0)), json_number_value(json_array_get(p, 1)),
                            json_number_value(json_array_get(p, 2)));
        l->intensity = 1;
        // the emitting radius (refl calib lamps writes the one its highlight
        // model used): the fit averages R over the lamp's disc
        json_t *rad = json_object_get(e, "radius_mm");
        if (rad && !(json_is_number(rad) && json_number_value(rad) >= 0 && json_number_value(rad) < 1000)) {
            model_error(lamps, 0, "lamps[%zu] (%s): radius_mm must be a number of mm in [0, 1000)", i, name);
            goto done;
        }
        c->lamp_radius_mm[i] = rad ? json_number_value(rad) : 0;
        if (!lamp_emission(e, lamps, i, l)) goto done;
        lamp_sigma(e, &c->lamp_sigma[i]);
        c->lamps->n = (int)i + 1;
    }
    add_input(c, "lamps", lamps);
    ok = true;
done:
    json_decref(lj);
    return ok;
}

// gain.json (CALIB_GAIN_FORMAT, calib/gain/gain.h): saturation, K and read
// noise, the linearisation, the flat map's noise, the gain and its unit
// (version 1 without them: 0 dB), and the maps beside it: offset_dn.tiff,
// flat_field.tiff or else prnu_gain.tiff. false + message.
static bool load_gain(calib_set_t *c, const char *gain)
{
    json_t *gj = load_json(gain, CALIB_GAIN_FORMAT, CALIB_GAIN_FORMAT_VERSION, &c->gain_version);
    if (!gj) return false;
    bool ok = false;
    char *off = NULL, *flat = NULL;
    add_input(c, "gain", gain);
    json_t *sat = json_object_get(gj, "saturation_dn");
    if (json_is_number(sat)) c->saturation_dn = json_number_value(sat);
    json_t *K = json_object_get(gj, "system_gain_dn_per_e"), *rn = json_object_get(gj, "read_noise_e");
    if (json_is_number(K) && json_is_number(rn)) {
        c->gain_dn_per_e = json_number_value(K);
        c->read_noise_e = json_number_value(rn);
    }
    if (!calib_gain_lin_from_json(gj, gain, &c->lin)) goto done;
    json_t *fs = json_object_get(json_object_get(gj, "flat_field"), "pixel_std_rel");
    if (json_is_number(fs)) c->flat_pixel_std_rel = json_number_value(fs);
    json_t *gdb = json_object_get(gj, "gain_db"), *gu = json_object_get(gj, "gain_unit");
    if ((gdb && !json_is_number(gdb)) || (gu && !json_is_string(gu))) {
        model_error(gain, 0, "gain_db must be a number and gain_unit a string (the gain the calibration was "
                    "made at)");
        goto done;
    }
    c->cal_gain = gdb ? json_number_value(gdb) : 0;
    snprintf(c->cal_gain_unit, sizeof c->cal_gain_unit, "%s", gu ? json_string_value(gu) : "dB");
    char *gd = g_path_get_dirname(gain);
    off = g_strdup_printf("%s/offset_dn.tiff", gd);
    flat = g_strdup_printf("%s/flat_field.tiff", gd);
    if (access(flat, R_OK) != 0) {
        g_free(flat);
        flat = g_strdup_printf("%s/prnu_gain.tiff", gd);
    }
    g_free(gd);
    if (access(off, R_OK) == 0 && !(c->offset_dn = read_map(c, off, "offset map"))) goto done;
    if (access(flat, R_OK) == 0 && !(c->flat = read_map(c, flat, "flat field"))) goto done;
    ok = true;
done:
    g_free(off);
    g_free(flat);
    json_decref(gj);
    return ok;
}

// white.json (CALIB_WHITE_FORMAT, calib/calib.h): kc_I_per_us of every lamp
// of c (lamps: lamps.json's path, for the message). false + message.
static bool load_white(calib_set_t *c, const char *white, const char *lamps)
{
    json_t *wj = load_json(white, CALIB_WHITE_FORMAT, CALIB_WHITE_FORMAT_VERSION, &c->white_version);
    if (!wj) return false;
    json_t *wl = json_object_get(wj, "lamps");
    bool ok = true;
    for (int i = 0; ok && i < c->lamps->n; i++) {
        bool found = false;
        for (size_t k = 0; k < json_array_size(wl); k++) {
            json_t *e = json_array_get(wl, k);
            const char *n = json_string_value(json_object_get(e, "name"));
            json_t *v = json_object_get(e, "kc_I_per_us");
            if (n && !strcmp(n, c->lamps->lamps[i].name) && json_is_number(v)) {
                c->kcI_per_us[i] = json_number_value(v);
                found = true;
            }
        }
        if (!found) {
            model_error(white, 0, "no kc_I_per_us for lamp '%s' (of %s): run refl calib white with that lamp",
                        c->lamps->lamps[i].name, lamps);
            ok = false;
        }
    }
    json_decref(wj);
    if (!ok) return false;
    c->have_white = true;
    add_input(c, "white", white);
    return true;
}

calib_set_t *calib_set_load_files(const char *cam, const char *lamps, const char *gain, const char *white)
{
    calib_set_t *c = calloc(1, sizeof *c);
    if (!c) {
        model_error(cam, 0, "out of memory");
        return NULL;
    }
    c->inputs = json_array();
    c->flat_pixel_std_rel = NAN;
    snprintf(c->cal_gain_unit, sizeof c->cal_gain_unit, "dB");
    bool ok = (c->cam = model_camera_load(cam)) != NULL;
    if (ok) {
        add_input(c, "camera", cam);
        set_psf(c, cam, NULL);
        c->W = model_camera_width(c->cam);
        c->H = model_camera_height(c->cam);
    }
    ok = ok && load_lamps(c, lamps) && (!gain || load_gain(c, gain)) && (!white || load_white(c, white, lamps));
    if (ok) return c;
    calib_set_free(c);
    return NULL;
}
