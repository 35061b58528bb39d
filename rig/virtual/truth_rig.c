// rig/virtual/truth_rig.c — the virtual rig's truth file read for one of its cameras
// (rig_vtruth_read, rig/virtual/internal.h): the sections and keys checked, the
// camera, render, sensor, lamps, materials, turntable and [virtual] sections,
// then the textures and samples (truth_samples.c), the lamps' drift and stray
// light, the optics and the placement errors (rig/virtual/virtual.c lists the keys).
#include <limits.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>

#include "rig/virtual/internal.h"

// The camera sections of a truth file in file order ([camera], [camera NAME]):
// their count (at most VIRTUAL_CAMERAS_MAX); *line_over: the line of one more (0: none).
static int camera_sections(const model_ini_t *ini, const char *secs[], int *line_over)
{
    int n = 0;
    *line_over = 0;
    for (int s = 0; s < ini->nsections; s++)
        if (!strcmp(ini->sections[s], "camera") || !strncmp(ini->sections[s], "camera ", 7)) {
            if (n == VIRTUAL_CAMERAS_MAX) *line_over = ini->section_lines[s];
            else secs[n++] = ini->sections[s];
        }
    return n;
}

int rig_vtruth_cameras(const rig_truth_t *t)
{
    const model_ini_t *ini = rig_truth_ini(t);
    const char *secs[VIRTUAL_CAMERAS_MAX];
    int over = 0, n = camera_sections(ini, secs, &over);
    if (over) {
        model_error(ini->path, over, "more than %d cameras: the virtual rig serves at most %d", VIRTUAL_CAMERAS_MAX,
                    VIRTUAL_CAMERAS_MAX);
        return -1;
    }
    return n;
}

// The camera model of c->cam_sec: its path, sha256 (checked against
// model_sha256), the model itself and its size.
static bool read_camera_model(const rig_truth_t *t, rig_vtruth_t *c)
{
    const model_ini_t *ini = rig_truth_ini(t);
    const char *cm = rig_vtruth_str(ini, c->cam_sec, "model", NULL);
    if (!cm) {
        model_error(ini->path, rig_vtruth_line(ini, c->cam_sec, "model"), "[%s] lacks 'model': the path of the "
                    "camera's .cameramodel (relative to this file)", c->cam_sec);
        return false;
    }
    if (!(c->cam_path = rig_truth_resolve(t, cm))) {
        model_error(ini->path, 0, "out of memory");
        return false;
    }
    char sha[65];
    bool ok = model_sha256_file(c->cam_path, sha);
    if (ok) {
        const char *want = rig_vtruth_str(ini, c->cam_sec, "model_sha256", NULL);
        if (want && strcmp(want, sha)) {
            model_error(ini->path, rig_vtruth_line(ini, c->cam_sec, "model_sha256"), "camera model %s has sha256 %s, "
                        "not the %s recorded here: the ground truth changed; record the new hash if that is intended",
                        c->cam_path, sha, want);
            ok = false;
        }
    }
    if (ok) c->cam = model_camera_load(c->cam_path);
    if ((ok && !c->cam) || (!ok && !strstr(model_last_error(), "sha256"))) {
        char msg[1024];
        snprintf(msg, sizeof msg, "%s", model_last_error());
        model_error(ini->path, rig_vtruth_line(ini, c->cam_sec, "model"), "camera model: %s", msg);
        ok = false;
    }
    if (!ok) return false;
    c->W = model_camera_width(c->cam);
    c->H = model_camera_height(c->cam);
    if (c->W < 1 || c->H < 1 || c->W > 4096 || c->H > 4096) {
        model_error(ini->path, rig_vtruth_line(ini, c->cam_sec, "model"), "camera model of %dx%d pixels: the virtual "
                    "camera serves 1..4096 x 1..4096", c->W, c->H);
        return false;
    }
    return true;
}

// [camera] / [camera NAME]: the model, kc and what the camera server reports.
static bool read_camera(const rig_truth_t *t, rig_vtruth_t *c)
{
    const model_ini_t *ini = rig_truth_ini(t);
    rig_gv_camera_params_t *gp = &c->gp;
    if (!read_camera_model(t, c) || !rig_vtruth_double(ini, c->cam_sec, "kc_per_us", 0, 1e6, true, &c->kc_per_us))
        return false;
    gp->serial = rig_vtruth_str(ini, c->cam_sec, "serial", gp->serial);
    gp->vendor = rig_vtruth_str(ini, c->cam_sec, "vendor", gp->vendor);
    gp->model = rig_vtruth_str(ini, c->cam_sec, "model_name", gp->model);
    if (!rig_vtruth_double(ini, c->cam_sec, "temperature_c", -100, 200, false, &gp->temperature_c)) return false;
    gp->sensor_width = c->W;
    gp->sensor_height = c->H;
    return true;
}

// An integer key of [render] into *out (unchanged when absent).
static bool render_int(const model_ini_t *ini, const char *key, long lo, long hi, int *out)
{
    long li = *out;
    if (!rig_vtruth_int(ini, "render", key, lo, hi, &li)) return false;
    *out = (int)li;
    return true;
}

// [render]: the shading of the renders and the simulator's own settings.
static bool read_render(const model_ini_t *ini, rig_vtruth_t *c)
{
    model_shading_t *sh = &c->shading;
    *sh = model_shading_default();
    const char *ir = rig_vtruth_str(ini, "render", "interreflection", "thesis");
    int m = model_interreflection_from_name(ir);
    if (m < 0) {
        model_error(ini->path, rig_vtruth_line(ini, "render", "interreflection"), "interreflection = '%s' is unknown; "
                    "use none, thesis or mc", ir);
        return false;
    }
    sh->interreflection = m;
    int finite = sh->finite_lamps;
    c->direct_samples = c->ds = c->prerender = 1;
    long seed = 1;
    if (!render_int(ini, "mc_samples", 1, 4096, &sh->mc_samples) ||
        !render_int(ini, "mc_bounces", 0, 16, &sh->mc_bounces) ||
        !render_int(ini, "thesis_samples", 1, 1024, &sh->thesis_samples) ||
        !render_int(ini, "finite_lamps", 0, 1, &finite) ||
        !render_int(ini, "direct_samples", 1, 4096, &c->direct_samples) ||
        !render_int(ini, "indirect_downsample", 1, 16, &c->ds) || !render_int(ini, "prerender", 0, 2, &c->prerender) ||
        !rig_vtruth_int(ini, "render", "seed", 0, LONG_MAX, &seed))
        return false;
    sh->finite_lamps = finite != 0;
    sh->seed = (uint64_t)seed;
    return rig_vtruth_double(ini, "render", "thesis_cone_deg", 1e-3, 90, false, &sh->thesis_cone_deg) &&
           rig_vtruth_double(ini, "render", "rho_sr", 0, 4 * M_PI, false, &sh->rho);
}

// The camera's sensor ([sensor], [sensor NAME] of [camera NAME]), the lamps
// and the materials.
static bool read_models(const rig_truth_t *t, rig_vtruth_t *c)
{
    const model_ini_t *ini = rig_truth_ini(t);
    if (!rig_truth_sensor(t, strcmp(c->cam_sec, "camera") ? c->cam_sec + 7 : NULL, &c->sensor)) return false;
    if (!(c->lamps = rig_truth_lamps(t))) return false;
    if (c->lamps->n > 32) {
        model_error(ini->path, c->lamps->lamps[32].line, "more than 32 lamps; the rig switches at most 32");
        return false;
    }
    return (c->mats = rig_truth_materials(t)) != NULL;
}

// [turntable]: the simulated stage's motion and injected faults.
static bool read_turntable(const model_ini_t *ini, rig_turntable_sim_params_t *tp)
{
    const char *tt = "turntable";
    if (!rig_vtruth_double(ini, tt, "speed_deg_s", 1e-6, 1e4, false, &tp->speed_deg_s) ||
        !rig_vtruth_double(ini, tt, "accel_deg_s2", 1e-6, 1e6, false, &tp->accel_deg_s2) ||
        !rig_vtruth_double(ini, tt, "home_time_s", 0, 3600, false, &tp->home_time_s) ||
        !rig_vtruth_double(ini, tt, "position_noise_deg", 0, 10, false, &tp->position_noise_deg))
        return false;
    long li = (long)tp->seed;
    if (!rig_vtruth_int(ini, tt, "seed", 0, LONG_MAX, &li)) return false;
    tp->seed = (uint64_t)li;
    li = 0;
    if (!rig_vtruth_int(ini, tt, "fault_after_moves", 0, INT_MAX, &li)) return false;
    tp->fault_after_moves = (int)li;
    const char *f = rig_vtruth_str(ini, tt, "fault", NULL);
    if (f) {
        if (!strcmp(f, "motion")) tp->fault = RIG_ERR_MOTION;
        else if (!strcmp(f, "stall")) tp->fault = RIG_ERR_TIMEOUT;
        else if (!strcmp(f, "disconnect")) tp->fault = RIG_ERR_DISCONNECTED;
        else {
            model_error(ini->path, rig_vtruth_line(ini, tt, "fault"), "fault = '%s' is unknown; use motion, stall or "
                        "disconnect", f);
            return false;
        }
    }
    if ((tp->fault_after_moves > 0) != (f != NULL)) {
        model_error(ini->path, rig_vtruth_line(ini, tt, f ? "fault" : "fault_after_moves"), "fault injection needs "
                    "both fault_after_moves (> 0) and fault");
        return false;
    }
    return true;
}

// [virtual]: the lamps' timing and the default sample.
static bool read_virtual(const model_ini_t *ini, rig_vtruth_t *c)
{
    c->warmup_ms = c->settle_ms = 0;
    if (!rig_vtruth_double(ini, "virtual", "lamp_warmup_ms", 0, 3.6e6, false, &c->warmup_ms) ||
        !rig_vtruth_double(ini, "virtual", "lamp_settle_ms", 0, 3.6e6, false, &c->settle_ms))
        return false;
    c->default_sample = rig_vtruth_str(ini, "virtual", "sample", NULL);
    return true;
}

// An optional number of the truth in a range, its text for messages.
static bool get(const model_ini_t *ini, const char *sec, const char *key, double lo, bool lo_open, double hi,
                const char *range, double *out)
{
    return model_ini_double_in(ini, sec, key, out, false, lo, lo_open, hi, range);
}

bool rig_vtruth_lamp_effects(const rig_truth_t *t, const model_lamps_t *lamps, rig_vlamps_t *fx)
{
    const model_ini_t *ini = rig_truth_ini(t);
    memset(fx, 0, sizeof *fx);
    fx->n = lamps->n < 32 ? lamps->n : 32;
    fx->time_scale = 1;
    for (int s = 0; s < ini->nsections; s++) {
        const char *sec = ini->sections[s];
        if (strncmp(sec, "lamp_drift ", 11)) continue;
        int i = model_lamps_find(lamps, sec + 11);
        if (i < 0 || i >= 32) {
            model_error(ini->path, ini->section_lines[s], "[%s] names no [lamp %s] of this truth file", sec, sec + 11);
            return false;
        }
        double a = 0, tau = 0, d = 0;
        if (!get(ini, sec, "warmup_fraction", -0.5, false, 0.5,
                 "-0.5..0.5 (deficit at switch-on; < 0: brighter, as a heating LED)", &a) ||
            !get(ini, sec, "warmup_tau_s", 0, true, 1e5, "> 0 and <= 1e5 s", &tau) ||
            !get(ini, sec, "drift_pct_per_h", -10, false, 10, "-10..10 %/h", &d))
            return false;
        if ((a != 0) != (tau > 0)) {
            const model_ini_entry_t *e = model_ini_get(ini, sec, a != 0 ? "warmup_fraction" : "warmup_tau_s");
            model_error(ini->path, e ? e->line : ini->section_lines[s], "[%s]: a warm-up needs both "
                        "warmup_fraction (not 0) and warmup_tau_s", sec);
            return false;
        }
        fx->warmup_fraction[i] = a;
        fx->warmup_tau_s[i] = tau;
        fx->drift_pct_per_h[i] = d;
        if (a != 0 || d != 0) fx->timed = true;
    }
    return get(ini, "stray", "ambient_radiance", 0, false, 1e12, ">= 0 (radiance units)", &fx->ambient_radiance) &&
           get(ini, "stray", "veiling_glare", 0, false, 0.2, "0..0.2 (a fraction of the mean image radiance)",
               &fx->veiling_glare);
}

// [optics]: rays over each pixel and the point-spread function (rig/virtual/optics.h;
// 1 ray, no PSF when the section is absent).
static bool read_optics(const model_ini_t *ini, rig_optics_t *o)
{
    *o = (rig_optics_t){ .rays_per_pixel = 1, .psf = RIG_PSF_NONE };
    const char *sec = "optics";
    long n = 1;
    if (!model_ini_int(ini, sec, "rays_per_pixel", &n, false, 1, 8)) return false;
    o->rays_per_pixel = (int)n;
    const char *psf = model_ini_text(ini, sec, "psf", "none");
    const model_ini_entry_t *e = model_ini_get(ini, sec, "psf");
    int line = e ? e->line : model_ini_section_line(ini, sec);
    if (!strcasecmp(psf, "none")) o->psf = RIG_PSF_NONE;
    else if (!strcasecmp(psf, "gaussian")) o->psf = RIG_PSF_GAUSSIAN;
    else if (!strcasecmp(psf, "disc")) o->psf = RIG_PSF_DISC;
    else {
        model_error(ini->path, line, "[optics] psf = %s: use none, gaussian (with psf_sigma_px) or disc (with "
                    "psf_radius_px)", psf);
        return false;
    }
    bool has_sigma = model_ini_get(ini, sec, "psf_sigma_px") != NULL;
    bool has_radius = model_ini_get(ini, sec, "psf_radius_px") != NULL;
    if (!model_ini_double_in(ini, sec, "psf_sigma_px", &o->psf_sigma_px, o->psf == RIG_PSF_GAUSSIAN, 0, true, 10,
                             "0 < sigma <= 10 px") ||
        !model_ini_double_in(ini, sec, "psf_radius_px", &o->psf_radius_px, o->psf == RIG_PSF_DISC, 0, true, 10,
                             "0 < radius <= 10 px"))
        return false;
    if ((has_sigma && o->psf != RIG_PSF_GAUSSIAN) || (has_radius && o->psf != RIG_PSF_DISC)) {
        const char *k = has_sigma && o->psf != RIG_PSF_GAUSSIAN ? "psf_sigma_px" : "psf_radius_px";
        model_error(ini->path, model_ini_get(ini, sec, k)->line, "[optics] %s is given but psf = %s: write psf = %s "
                    "or remove the key", k, psf, has_sigma && o->psf != RIG_PSF_GAUSSIAN ? "gaussian" : "disc");
        return false;
    }
    return true;
}

// [placement] and the [turntable] axis keys (rig/virtual/place.h).
static bool read_placement(const model_ini_t *ini, rig_virtual_place_t *out)
{
    *out = (rig_virtual_place_t){ 0 };
    long seed = 1;
    if (!model_ini_double_in(ini, "placement", "position_sigma_mm", &out->position_sigma_mm, false, 0, false, 50,
                             NULL) ||
        !model_ini_double_in(ini, "placement", "angle_sigma_deg", &out->angle_sigma_deg, false, 0, false, 20, NULL) ||
        !model_ini_int(ini, "placement", "seed", &seed, false, 0, LONG_MAX) ||
        !model_ini_double_in(ini, "turntable", "axis_tilt_deg", &out->axis_tilt_deg, false, 0, false, 10, NULL) ||
        !model_ini_double_in(ini, "turntable", "axis_tilt_azimuth_deg", &out->axis_tilt_azimuth_deg, false, -360,
                             false, 360, NULL) ||
        !model_ini_double_in(ini, "turntable", "wobble_deg", &out->wobble_deg, false, 0, false, 5, NULL))
        return false;
    out->seed = (uint64_t)seed;
    out->on = out->position_sigma_mm > 0 || out->angle_sigma_deg > 0;
    out->axis_on = out->axis_tilt_deg != 0 || out->wobble_deg != 0;
    return true;
}

// The default sample is one of the samples.
static bool check_default_sample(const model_ini_t *ini, const rig_vtruth_t *c)
{
    if (!c->default_sample || rig_vsample_find(c->samples, c->nsamples, c->default_sample) >= 0) return true;
    char list[512];
    rig_vsample_list(c->samples, c->nsamples, list, sizeof list);
    model_error(ini->path, rig_vtruth_line(ini, "virtual", "sample"), "sample = '%s' has no [sample %s] section; "
                "samples: %s", c->default_sample, c->default_sample, list);
    return false;
}

bool rig_vtruth_read(const rig_truth_t *t, int k, rig_vtruth_t *c)
{
    const model_ini_t *ini = rig_truth_ini(t);
    *c = (rig_vtruth_t){ .gp = rig_gv_camera_defaults(), .tp = rig_turntable_sim_defaults() };
    if (!rig_truth_check_sections(t)) return false;
    const char *secs[VIRTUAL_CAMERAS_MAX];
    int over, n = camera_sections(ini, secs, &over);
    snprintf(c->cam_sec, sizeof c->cam_sec, "%s", k < n ? secs[k] : "camera");
    if (k < n) snprintf(c->cam_name, sizeof c->cam_name, "%s", strcmp(secs[k], "camera") ? secs[k] + 7 : "camera");
    bool ok = read_camera(t, c) && read_render(ini, c) && read_models(t, c) && read_turntable(ini, &c->tp) &&
              read_virtual(ini, c) && rig_vtruth_textures(t, c) && rig_vtruth_samples(t, c) &&
              rig_vtruth_lamp_effects(t, c->lamps, &c->lamp_fx) && read_optics(ini, &c->optics) &&
              read_placement(ini, &c->place) && check_default_sample(ini, c);
    if (!ok) rig_vtruth_free(c);
    return ok;
}

void rig_vtruth_free(rig_vtruth_t *c)
{
    model_camera_free(c->cam);
    free(c->cam_path);
    model_lamps_free(c->lamps);
    rig_vsamples_free(c->samples, c->nsamples);
    model_materials_free(c->mats);
    free(c->textures);
    *c = (rig_vtruth_t){ 0 };
}
