// rig/session/facts.c — the session facts of a capture: refl, the command,
// the calibrations in use (by path and sha256), every camera, the turntable,
// the lamps and, on a virtual rig, its truth file (the journal keeps them as
// JSON).
#define _GNU_SOURCE
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <unistd.h>

#include <glib.h>
#include <jansson.h>

#include "model/model.h"
#include "model/base/report.h"
#include "rig/rig.h"
#include "rig/session/internal.h"

// ---------------------------------------------------------------------------
// Session setup

// One calibration file of a directory (the first of the candidate paths that
// reads), entered by role, path, sha256 and, for a camera's own, the camera.
static void calibration_file(json_t *arr, const char *role, const char *const *cands, int n, const char *camera)
{
    for (int k = 0; k < n; k++) {
        char sha[65];
        if (access(cands[k], R_OK) != 0 || !model_sha256_file(cands[k], sha)) continue;
        json_t *e = json_object();
        json_object_set_new(e, "role", json_string(role));
        if (camera) json_object_set_new(e, "camera", json_string(camera));
        json_object_set_new(e, "path", json_string(cands[k]));
        json_object_set_new(e, "sha256", json_string(sha));
        json_array_append_new(arr, e);
        return;
    }
}

// The calibration files of a directory, by role: path and sha256; with several
// cameras also each camera's own (NAME.cameramodel, NAME/gain.json, NAME/white.json,
// directly or under geometry/, gain/, white/: calib/calset.c's layout). NULL
// with a message when the directory holds none of them.
json_t *capture_calibration_files(const char *dir, const rig_t *r)
{
    static const char *const files[][3] = {
        { "camera geometry", "geometry", "camera.cameramodel" }, { "geometry summary", "geometry", "geometry.json" },
        { "lamp positions", "lamps", "lamps.json" }, { "sensitivity", "gain", "gain.json" },
        { "reference white", "white", "white.json" },
    };
    json_t *arr = json_array();
    char *abs = realpath(dir, NULL);
    for (size_t i = 0; abs && i < sizeof files / sizeof files[0]; i++) {
        char *c[2] = { g_strdup_printf("%s/%s", abs, files[i][2]),
                       g_strdup_printf("%s/%s/%s", abs, files[i][1], files[i][2]) };
        calibration_file(arr, files[i][0], (const char *const *)c, 2, NULL);
        g_free(c[0]);
        g_free(c[1]);
    }
    for (int k = 0; abs && r && r->ncameras > 1 && k < r->ncameras; k++) {
        const char *nm = r->camera_names[k];
        char *g[3] = { g_strdup_printf("%s/%s.cameramodel", abs, nm), g_strdup_printf("%s/geometry/%s.cameramodel",
                       abs, nm), g_strdup_printf("%s/%s/camera.cameramodel", abs, nm) };
        char *s[2] = { g_strdup_printf("%s/%s/gain.json", abs, nm), g_strdup_printf("%s/gain/%s/gain.json", abs, nm) };
        char *w[2] = { g_strdup_printf("%s/%s/white.json", abs, nm), g_strdup_printf("%s/white/%s/white.json", abs,
                       nm) };
        calibration_file(arr, "camera geometry", (const char *const *)g, 3, nm);
        calibration_file(arr, "sensitivity", (const char *const *)s, 2, nm);
        calibration_file(arr, "reference white", (const char *const *)w, 2, nm);
        for (int i = 0; i < 3; i++) g_free(g[i]);
        for (int i = 0; i < 2; i++) {
            g_free(s[i]);
            g_free(w[i]);
        }
    }
    free(abs);
    if (json_array_size(arr) == 0) {
        json_decref(arr);
        rig_fail(RIG_ERR_INVALID, "--calib %s: no calibration files there (camera.cameramodel, lamps.json, gain.json, "
                 "white.json, or geometry/, lamps/, gain/, white/ holding them)", dir);
        return NULL;
    }
    return arr;
}

char *capture_session_facts(rig_t *r, const rig_plan_t *p, const char *cmdline, json_t *calibrations)
{
    json_t *o = json_object();
    model_json_set_format(o, RIG_SESSION_FACTS_FORMAT, RIG_SESSION_FACTS_VERSION);
    json_object_set_new(o, "refl_version", json_string(REFL_VERSION));
    json_object_set_new(o, "command_line", json_string(cmdline ? cmdline : ""));
    json_object_set_new(o, "operator", json_string(p->operator_name));
    json_object_set_new(o, "notes", json_string(p->notes));
    // the calibrations in use (by path and hash; frames are stored raw)
    json_object_set_new(o, "calibrations", calibrations ? json_incref(calibrations) : json_array());
    // "camera": the first camera (a session of one camera has only it), "cameras": every one
    json_t *cams = json_array();
    for (int k = 0; k < r->ncameras; k++) {
        rig_frame_meta_t m;
        if (rig_camera_settings(r->cameras[k], &m) != 0) continue;
        json_t *c = json_object();
        json_object_set_new(c, "camera", json_string(r->camera_names[k]));
        json_object_set_new(c, "name", json_string(rig_camera_name(r->cameras[k])));
        json_object_set_new(c, "backend", json_string(rig_camera_backend(r->cameras[k])));
        json_object_set_new(c, "vendor", json_string(m.vendor));
        json_object_set_new(c, "model", json_string(m.model));
        json_object_set_new(c, "serial", json_string(m.serial));
        json_object_set_new(c, "pixel_format", json_string(m.pixel_format));
        json_object_set_new(c, "bits", json_integer(m.bits));
        json_object_set_new(c, "width", json_integer(m.width));
        json_object_set_new(c, "height", json_integer(m.height));
        json_object_set_new(c, "offset_x", json_integer(m.offset_x));
        json_object_set_new(c, "offset_y", json_integer(m.offset_y));
        json_object_set_new(c, "exposure_us", json_real(m.exposure_us));
        json_object_set_new(c, "gain", json_real(m.gain));
        json_object_set_new(c, "gain_unit", json_string(m.gain_unit));
        if (isfinite(m.temperature_c)) json_object_set_new(c, "temperature_c", json_real(m.temperature_c));
        if (isfinite(m.black_level)) json_object_set_new(c, "black_level", json_real(m.black_level));
        json_object_set_new(c, "gamma", json_real(m.gamma));
        json_object_set_new(c, "firmware", json_string(m.firmware));
        json_object_set_new(c, "settings", json_string(m.camera_settings));   // what refl switched off at open
        if (k == 0) json_object_set_new(o, "camera", json_deep_copy(c));
        json_array_append_new(cams, c);
    }
    json_object_set_new(o, "cameras", cams);
    rig_turntable_info_t ti;
    if (r->turntable && rig_turntable_info(r->turntable, &ti) == 0) {
        json_t *t = json_object();
        json_object_set_new(t, "name", json_string(rig_turntable_name(r->turntable)));
        json_object_set_new(t, "model", json_string(ti.model));
        json_object_set_new(t, "serial", json_string(ti.serial));
        json_object_set_new(t, "firmware", json_string(ti.firmware));
        json_object_set_new(t, "speed_deg_s", json_real(r->speed_deg_s));
        json_object_set_new(t, "accel_deg_s2", json_real(r->accel_deg_s2));
        json_object_set_new(o, "turntable", t);
    }
    json_t *l = json_array();
    for (int i = 0; r->lamps && i < rig_lamps_count(r->lamps); i++) {
        json_t *a = json_object();
        json_object_set_new(a, "name", json_string(rig_lamps_name(r->lamps, i)));
        json_object_set_new(a, "backend", json_string(rig_lamps_backend(r->lamps)));
        json_object_set_new(a, "warmup_ms", json_real(rig_lamps_line(r->lamps, i)->warmup_ms));
        json_object_set_new(a, "settle_ms", json_real(rig_lamps_line(r->lamps, i)->settle_ms));
        json_array_append_new(l, a);
    }
    json_object_set_new(o, "lamps", l);
    if (r->virt) {
        json_t *v = json_object();
        char sha[65] = "";
        bool q = model_error_quiet_thread(true);
        if (!model_sha256_file(rig_virtual_truth_path(r->virt), sha)) snprintf(sha, sizeof sha, "unreadable");
        model_error_quiet_thread(q);
        json_object_set_new(v, "truth", json_string(rig_virtual_truth_path(r->virt)));
        json_object_set_new(v, "truth_sha256", json_string(sha));
        // the sample as the plan's operator step poses it (the frames' truth)
        json_object_set_new(v, "sample", json_string(p->sample));
        json_object_set_new(v, "sample_tilt_deg", json_real(p->tilt_deg));
        json_object_set_new(v, "sample_tilt_azimuth_deg", json_real(p->tilt_azimuth_deg));
        json_object_set_new(o, "virtual_rig", v);
    }
    char *s = json_dumps(o, JSON_INDENT(1) | JSON_SORT_KEYS);
    json_decref(o);
    return s;
}
