// rig/virtual/truth.c — the virtual rig's truth file: loaded or parsed, its format
// version, the sections and keys it may have, and its relative paths (the one
// reader of the file with truth_figures.c, truth_rig.c and truth_samples.c;
// rig/virtual/truth.h).
#define _GNU_SOURCE
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "rig/virtual/internal.h"

struct rig_truth {
    char        *path;
    model_ini_t *ini;
    int          format_version;
};

// [virtual] format_version: 1 without it; a newer one than this refl reads is refused.
static bool read_format_version(rig_truth_t *t)
{
    t->format_version = 1;
    const model_ini_entry_t *e = model_ini_get(t->ini, "virtual", "format_version");
    if (!e) return true;
    char *end;
    errno = 0;
    long v = strtol(e->value, &end, 10);
    if (end == e->value || *end || errno || v < 1) {
        model_error(t->path, e->line, "[virtual] format_version = '%s': give the file's format version, a whole "
                    "number from 1", e->value);
        return false;
    }
    if (v > RIG_TRUTH_FORMAT_VERSION) {
        model_error(t->path, e->line, "[virtual] format_version = %ld: a truth file of a newer refl (this refl "
                    "reads truth files up to format version %d)", v, RIG_TRUTH_FORMAT_VERSION);
        return false;
    }
    t->format_version = (int)v;
    return true;
}

// The truth of an INI (taken over, freed on failure).
static rig_truth_t *truth_of(model_ini_t *ini, const char *path)
{
    if (!ini) return NULL;
    rig_truth_t *t = calloc(1, sizeof *t);
    if (!t || !(t->path = strdup(path))) {
        free(t);
        model_ini_free(ini);
        model_error(path, 0, "out of memory");
        return NULL;
    }
    t->ini = ini;
    if (!read_format_version(t)) {
        rig_truth_free(t);
        return NULL;
    }
    return t;
}

rig_truth_t *rig_truth_load(const char *path) { return truth_of(model_ini_load(path), path); }

rig_truth_t *rig_truth_parse(const char *text, size_t len, const char *path)
{
    return truth_of(model_ini_parse(text, len, path), path);
}

void rig_truth_free(rig_truth_t *t)
{
    if (!t) return;
    model_ini_free(t->ini);
    free(t->path);
    free(t);
}

const char *rig_truth_path(const rig_truth_t *t) { return t->path; }
int rig_truth_format_version(const rig_truth_t *t) { return t->format_version; }
const model_ini_t *rig_truth_ini(const rig_truth_t *t) { return t->ini; }

model_lamps_t *rig_truth_lamps(const rig_truth_t *t) { return model_lamps_from_ini(t->ini); }
model_materials_t *rig_truth_materials(const rig_truth_t *t) { return model_materials_from_ini(t->ini); }

char *rig_truth_resolve(const rig_truth_t *t, const char *rel)
{
    char *out = NULL;
    if (rel[0] == '/') return strdup(rel);
    const char *slash = strrchr(t->path, '/');
    int dir = slash ? (int)(slash - t->path) : 0;
    if (asprintf(&out, "%.*s%s%s", dir, t->path, slash ? "/" : "", rel) < 0) return NULL;
    return out;
}

// ---------------------------------------------------------------------------
// Sections and keys

typedef struct {
    const char *section;   // section kind ("lamp" for "[lamp NAME]")
    const char *keys[16];
} allowed_t;

static const allowed_t allowed[] = {
    { "virtual", { "format_version", "sample", "lamp_warmup_ms", "lamp_settle_ms" } },
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
    { "lamp_drift", { "warmup_fraction", "warmup_tau_s", "drift_pct_per_h" } },   // truth_rig.c (rig/virtual/lamps.h)
    { "stray", { "ambient_radiance", "veiling_glare" } },                        // truth_rig.c (rig/virtual/lamps.h)
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

bool rig_truth_check_sections(const rig_truth_t *t)
{
    const model_ini_t *ini = t->ini;
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

// ---------------------------------------------------------------------------
// Typed values (model/base/ini.c reports them with file:line)

int rig_vtruth_line(const model_ini_t *ini, const char *sec, const char *key)
{
    const model_ini_entry_t *e = model_ini_get(ini, sec, key);
    return e ? e->line : model_ini_section_line(ini, sec);
}

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
