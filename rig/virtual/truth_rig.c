// rig/virtual/truth_rig.c — the virtual rig's truth file read into a rig: its
// sections and keys checked, the camera, render, sensor, lamps, materials,
// turntable and [virtual] sections (rig/virtual/virtual.c lists them).
#define _GNU_SOURCE
#include <limits.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "rig/virtual/internal.h"

typedef struct {
    const char *section;   // section kind ("lamp" for "[lamp NAME]")
    const char *keys[16];
} allowed_t;

static const allowed_t allowed[] = {
    { "virtual", { "sample", "lamp_warmup_ms", "lamp_settle_ms" } },
    { "camera", { "model", "model_sha256", "kc_per_us", "serial", "vendor", "model_name", "temperature_c" } },
    { "render", { "interreflection", "mc_samples", "mc_bounces", "thesis_samples", "thesis_cone_deg", "rho_sr",
                  "finite_lamps", "seed", "direct_samples", "indirect_downsample", "prerender" } },
    { "turntable", { "speed_deg_s", "accel_deg_s2", "home_time_s", "position_noise_deg", "seed",
                     "fault_after_moves", "fault",
                     "axis_tilt_deg", "axis_tilt_azimuth_deg", "wobble_deg" } },
    { "placement", { "position_sigma_mm", "angle_sigma_deg", "seed" } },
    { "sample", { "kind", "scene", "square_mm", "corners", "corner0_mm", "material", "sphere_centre_mm",
                  "sphere_radius_mm", "radiance", "direct_samples",
                  "flex_mm" } },
    { "texture", { "amplitude", "scale_mm", "seed",
                   "roughness_amplitude" } },
    { "optics", { "rays_per_pixel", "psf", "psf_sigma_px", "psf_radius_px" } },
    { "sensor", { NULL } },     // checked by model_sensor_from_ini
    { "lamp", { NULL } },       // model_lamps_from_ini
    { "lamp_drift", { "warmup_fraction", "warmup_tau_s", "drift_pct_per_h" } },   // rig/virtual/lamps.c
    { "stray", { "ambient_radiance", "veiling_glare" } },                        // rig/virtual/lamps.c
    { "material", { NULL } },   // model_materials_from_ini
};

static void section_kind(const char *sec, char kind[32], const char **name)
{
    const char *sp = strchr(sec, ' ');
    size_t n = sp ? (size_t)(sp - sec) : strlen(sec);
    if (n > 31) n = 31;
    memcpy(kind, sec, n);
    kind[n] = 0;
    *name = sp ? sp + 1 : "";
}

static const allowed_t *find_allowed(const char *kind)
{
    for (size_t i = 0; i < sizeof allowed / sizeof allowed[0]; i++)
        if (!strcmp(allowed[i].section, kind)) return &allowed[i];
    return NULL;
}

static bool check_sections(const model_ini_t *ini)
{
    for (int s = 0; s < ini->nsections; s++) {
        char kind[32];
        const char *name;
        section_kind(ini->sections[s], kind, &name);
        const allowed_t *a = find_allowed(kind);
        bool named = !strcmp(kind, "lamp") || !strcmp(kind, "material") || !strcmp(kind, "sample") ||
                     !strcmp(kind, "texture") ||
                     !strcmp(kind, "lamp_drift");
        bool may_name = !strcmp(kind, "camera") || !strcmp(kind, "sensor");
        if (!a) {
            model_error(ini->path, ini->section_lines[s], "unknown section [%s]; a truth file has [virtual], "
                        "[camera] (or [camera NAME], one or more), [render], [sensor] (and [sensor NAME]), "
                        "[turntable], [placement], [lamp NAME], [material NAME], [texture MATERIAL], [sample NAME] "
                        "and [optics] (and [lamp_drift LAMP], [stray])", ini->sections[s]);
            return false;
        }
        if (!strcmp(kind, "sensor") && *name) {
            char cs[80];
            snprintf(cs, sizeof cs, "camera %s", name);
            if (model_ini_section_line(ini, cs) <= 0) {
                model_error(ini->path, ini->section_lines[s], "[%s] has no [camera %s]: a [sensor NAME] is the "
                            "sensor of the camera [camera NAME] (its keys over those of [sensor])", ini->sections[s],
                            name);
                return false;
            }
        }
        if (!may_name && named != (*name != 0)) {
            model_error(ini->path, ini->section_lines[s], named ? "[%s] needs a name: write [%s NAME]"
                        : "[%s] takes no name: write [%s]", ini->sections[s], kind);
            return false;
        }
    }
    for (int k = 0; k < ini->nentries; k++) {
        const model_ini_entry_t *e = &ini->entries[k];
        char kind[32];
        const char *name;
        section_kind(e->section, kind, &name);
        const allowed_t *a = find_allowed(kind);
        if (!a->keys[0]) continue;
        bool ok = false;
        char list[512] = "";
        size_t len = 0;
        for (int i = 0; i < 16 && a->keys[i]; i++) {
            if (!strcmp(a->keys[i], e->key)) ok = true;
            len += snprintf(list + len, sizeof list - len, "%s%s", i ? ", " : "", a->keys[i]);
            if (len >= sizeof list) len = sizeof list - 1;
        }
        if (!ok) {
            model_error(ini->path, e->line, "unknown key '%s' in [%s]; valid keys: %s", e->key, e->section, list);
            return false;
        }
    }
    return true;
}

int rig_vtruth_line(const model_ini_t *ini, const char *sec, const char *key)
{
    const model_ini_entry_t *e = model_ini_get(ini, sec, key);
    return e ? e->line : model_ini_section_line(ini, sec);
}

// Typed values of the truth file (model/base/ini.c reports them with file:line).
bool rig_vtruth_double(const model_ini_t *ini, const char *sec, const char *key, double lo, double hi,
                       bool required, double *out)
{
    return model_ini_double_in(ini, sec, key, out, required, lo, false, hi, NULL);
}

bool rig_vtruth_int(const model_ini_t *ini, const char *sec, const char *key, long lo, long hi, long *out)
{
    return model_ini_int(ini, sec, key, out, false, lo, hi);
}

const char *rig_vtruth_str(const model_ini_t *ini, const char *sec, const char *key, const char *def)
{
    return model_ini_text(ini, sec, key, def);
}

// A path relative to the truth file's directory (malloc'ed).
char *rig_vtruth_relpath(const char *truth, const char *p)
{
    char *out = NULL;
    if (p[0] == '/') return strdup(p);
    const char *slash = strrchr(truth, '/');
    int dir = slash ? (int)(slash - truth) : 0;
    if (asprintf(&out, "%.*s%s%s", dir, truth, slash ? "/" : "", p) < 0) return NULL;
    return out;
}


// The camera sections of a truth file in file order ([camera], [camera NAME]): their count.
int rig_vtruth_camera_sections(const model_ini_t *ini, const char *secs[], int *line_over)
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

// Everything but the devices. false with a message naming file:line.
bool rig_vtruth_parse(rig_virtual_t *v, const model_ini_t *ini, const char **default_sample,
                      rig_turntable_sim_params_t *tp, double *warmup_ms, double *settle_ms,
                      rig_gv_camera_params_t *gp)
{
    if (!check_sections(ini)) return false;
    if (!v->cam_sec[0]) {   // the first camera section
        const char *secs[VIRTUAL_CAMERAS_MAX];
        int over;
        int n = rig_vtruth_camera_sections(ini, secs, &over);
        snprintf(v->cam_sec, sizeof v->cam_sec, "%s", n ? secs[0] : "camera");
    }
    // camera
    const char *cm = rig_vtruth_str(ini, v->cam_sec, "model", NULL);
    if (!cm) {
        model_error(ini->path, rig_vtruth_line(ini, v->cam_sec, "model"), "[%s] lacks 'model': the path of the "
                    "camera's .cameramodel (relative to this file)", v->cam_sec);
        return false;
    }
    char *cpath = rig_vtruth_relpath(ini->path, cm);
    if (!cpath) return false;
    char sha[65];
    bool ok = model_sha256_file(cpath, sha);
    if (ok) {
        const char *want = rig_vtruth_str(ini, v->cam_sec, "model_sha256", NULL);
        if (want && strcmp(want, sha)) {
            model_error(ini->path, rig_vtruth_line(ini, v->cam_sec, "model_sha256"), "camera model %s has sha256 %s, not "
                        "the %s recorded here: the ground truth changed; record the new hash if that is intended",
                        cpath, sha, want);
            ok = false;
        }
    }
    if (ok) v->cam = model_camera_load(cpath);
    v->cam_path = cpath;
    if (ok && !v->cam) {
        char msg[1024];
        snprintf(msg, sizeof msg, "%s", model_last_error());
        model_error(ini->path, rig_vtruth_line(ini, v->cam_sec, "model"), "camera model: %s", msg);
        ok = false;
    } else if (!ok && !strstr(model_last_error(), "sha256")) {
        char msg[1024];
        snprintf(msg, sizeof msg, "%s", model_last_error());
        model_error(ini->path, rig_vtruth_line(ini, v->cam_sec, "model"), "camera model: %s", msg);
    }
    if (!ok) return false;
    v->W = model_camera_width(v->cam);
    v->H = model_camera_height(v->cam);
    if (v->W < 1 || v->H < 1 || v->W > 4096 || v->H > 4096) {
        model_error(ini->path, rig_vtruth_line(ini, v->cam_sec, "model"), "camera model of %dx%d pixels: the virtual "
                    "camera serves 1..4096 x 1..4096", v->W, v->H);
        return false;
    }
    if (!rig_vtruth_double(ini, v->cam_sec, "kc_per_us", 0, 1e6, true, &v->kc_per_us)) return false;
    gp->serial = rig_vtruth_str(ini, v->cam_sec, "serial", gp->serial);
    gp->vendor = rig_vtruth_str(ini, v->cam_sec, "vendor", gp->vendor);
    gp->model = rig_vtruth_str(ini, v->cam_sec, "model_name", gp->model);
    if (!rig_vtruth_double(ini, v->cam_sec, "temperature_c", -100, 200, false, &gp->temperature_c)) return false;
    gp->sensor_width = v->W;
    gp->sensor_height = v->H;
    // render
    v->shading = model_shading_default();
    const char *ir = rig_vtruth_str(ini, "render", "interreflection", "thesis");
    int m = model_interreflection_from_name(ir);
    if (m < 0) {
        model_error(ini->path, rig_vtruth_line(ini, "render", "interreflection"), "interreflection = '%s' is unknown; "
                    "use none, thesis or mc", ir);
        return false;
    }
    v->shading.interreflection = m;
    long li;
    li = v->shading.mc_samples;
    if (!rig_vtruth_int(ini, "render", "mc_samples", 1, 4096, &li)) return false;
    v->shading.mc_samples = (int)li;
    li = v->shading.mc_bounces;
    if (!rig_vtruth_int(ini, "render", "mc_bounces", 0, 16, &li)) return false;
    v->shading.mc_bounces = (int)li;
    li = v->shading.thesis_samples;
    if (!rig_vtruth_int(ini, "render", "thesis_samples", 1, 1024, &li)) return false;
    v->shading.thesis_samples = (int)li;
    li = v->shading.finite_lamps;
    if (!rig_vtruth_int(ini, "render", "finite_lamps", 0, 1, &li)) return false;
    v->shading.finite_lamps = li != 0;
    li = 1;
    if (!rig_vtruth_int(ini, "render", "direct_samples", 1, 4096, &li)) return false;
    v->direct_samples = (int)li;
    li = 1;
    if (!rig_vtruth_int(ini, "render", "indirect_downsample", 1, 16, &li)) return false;
    v->ds = (int)li;
    li = 1;
    if (!rig_vtruth_int(ini, "render", "prerender", 0, 2, &li)) return false;
    v->prerender = (int)li;
    li = 1;
    if (!rig_vtruth_int(ini, "render", "seed", 0, LONG_MAX, &li)) return false;
    v->shading.seed = (uint64_t)li;
    if (!rig_vtruth_double(ini, "render", "thesis_cone_deg", 1e-3, 90, false, &v->shading.thesis_cone_deg) ||
        !rig_vtruth_double(ini, "render", "rho_sr", 0, 4 * M_PI, false, &v->shading.rho))
        return false;
    // sensor, lamps, materials
    if (!model_sensor_from_ini(ini, &v->sensor)) return false;
    if (strcmp(v->cam_sec, "camera")) {   // [sensor NAME] of [camera NAME]
        char ss[80];
        snprintf(ss, sizeof ss, "sensor %s", v->cam_sec + 7);
        if (!model_sensor_update_from_ini(ini, ss, &v->sensor)) return false;
    }
    if (!(v->lamps = model_lamps_from_ini(ini))) return false;
    if (v->lamps->n > 32) {
        model_error(ini->path, v->lamps->lamps[32].line, "more than 32 lamps; the rig switches at most 32");
        return false;
    }
    if (!(v->mats = model_materials_from_ini(ini))) return false;
    // turntable
    const char *tt = "turntable";
    if (!rig_vtruth_double(ini, tt, "speed_deg_s", 1e-6, 1e4, false, &tp->speed_deg_s) ||
        !rig_vtruth_double(ini, tt, "accel_deg_s2", 1e-6, 1e6, false, &tp->accel_deg_s2) ||
        !rig_vtruth_double(ini, tt, "home_time_s", 0, 3600, false, &tp->home_time_s) ||
        !rig_vtruth_double(ini, tt, "position_noise_deg", 0, 10, false, &tp->position_noise_deg))
        return false;
    li = (long)tp->seed;
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
        model_error(ini->path, rig_vtruth_line(ini, tt, f ? "fault" : "fault_after_moves"), "fault injection needs both "
                    "fault_after_moves (> 0) and fault");
        return false;
    }
    // virtual
    *warmup_ms = *settle_ms = 0;
    if (!rig_vtruth_double(ini, "virtual", "lamp_warmup_ms", 0, 3.6e6, false, warmup_ms) ||
        !rig_vtruth_double(ini, "virtual", "lamp_settle_ms", 0, 3.6e6, false, settle_ms))
        return false;
    *default_sample = rig_vtruth_str(ini, "virtual", "sample", NULL);
    // textures, samples
    if (!rig_vtruth_textures(v, ini) || !rig_vtruth_samples(v, ini)) return false;
    if (!rig_vlamps_parse(&v->lamp_fx, ini, v->lamps)) return false;
    if (!rig_optics_parse(ini, &v->optics)) return false;
    v->nbase_samples = v->nsamples;
    if (!rig_virtual_place_parse(ini, &v->place)) return false;
    if (*default_sample && rig_vsample_find(v, *default_sample) < 0) {
        char list[512];
        rig_vsample_list(v, list, sizeof list);
        model_error(ini->path, rig_vtruth_line(ini, "virtual", "sample"), "sample = '%s' has no [sample %s] section; "
                    "samples: %s", *default_sample, *default_sample, list);
        return false;
    }
    return true;
}
