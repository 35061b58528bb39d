// rig/config.c — rig description files: parse the INI (rig.h "Rig description
// files"), check every section, key and value with file:line messages, then
// open the devices (turntable, lamps, camera) or the virtual rig, undoing
// everything on a later error.
//
// Parsing is complete before any device is touched: a typo in the last line
// never leaves a stage half way through a homing.
#define _GNU_SOURCE
#include <arpa/inet.h>
#include <glib.h>
#include <limits.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "model/model.h"
#include "rig/camera/pixfmt.h"
#include "rig/rig.h"

#define MAX_LAMPS 32

// What the file asks for (filled by parse, used by the opener).
typedef struct {
    const char *path;                     // for messages
    const model_ini_t *ini;
    // [rig] backend = virtual
    bool   virt;
    int    rig_line;
    char  *truth;                         // resolved against the rig file's directory (g_free)
    char   address[256], sample[64];
    bool   inprocess;                     // serve = inprocess
    double time_scale, busy_wait_s;
    uint64_t noise_seed;
    bool   have_noise_seed;
    // [camera] / [camera NAME], in file order
    int    ncameras;
    struct {
        int  line;
        char section[80], name[RIG_CAMERA_NAME_MAX], id[64];
        char pixel_format[16];
        double exposure_us, gain;
        long packet_size, packet_delay;
        int  packet_line;
    } cam[RIG_CAMERAS_MAX];
    // camera defaults ([rig] for the virtual camera; the section being parsed)
    char   pixel_format[16];
    double exposure_us, gain;
    long   packet_size, packet_delay;     // GevSCPSPacketSize (bytes), GevSCPD (ticks); -1: the camera's own
    int    packet_line;                   // of the first of them, for messages
    // [turntable]
    bool   have_turntable;
    int    turntable_line;
    bool   turntable_apt;
    char   apt_serial[32], apt_stage[32];
    rig_turntable_sim_params_t sim;
    // [lamp NAME]
    int    nlamps;
    bool   lamps_gpiod;
    rig_lamp_line_t lamps[MAX_LAMPS];
    int    lamp_line[MAX_LAMPS];
    char   lamp_state_file[PATH_MAX];   // [lamps] state_file ("": the default)
} spec_t;

// ---------------------------------------------------------------------------
// Messages

static int cfg_fail(const spec_t *s, int line, const char *fmt, ...) __attribute__((format(printf, 3, 4)));
static int cfg_fail(const spec_t *s, int line, const char *fmt, ...)
{
    char msg[1200];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(msg, sizeof msg, fmt, ap);
    va_end(ap);
    if (line > 0) return rig_fail(RIG_ERR_INVALID, "%s:%d: %s", s->path, line, msg);
    return rig_fail(RIG_ERR_INVALID, "%s: %s", s->path, msg);
}

// A device error: "file:line: [section] driver message", printed once.
static int device_fail(int rc, const spec_t *s, int line, const char *section)
{
    char msg[1200];
    snprintf(msg, sizeof msg, "%s", model_last_error());
    return rig_fail(rc, "%s:%d: [%s]: %s", s->path, line, section, msg);
}

// ---------------------------------------------------------------------------
// Keys and values

typedef struct {
    const char *kind;          // "camera", "turntable", "lamp", "rig"
    const char *backend;
    const char *keys;          // space-separated, "backend" included
    const char *what;          // for the missing/unknown backend messages
} backend_def_t;

static const backend_def_t backends[] = {
    { "camera", "aravis", "backend address serial name pixel_format exposure_us gain packet_size packet_delay",
      "aravis (GigE Vision / USB3 Vision camera)" },
    { "turntable", "apt", "backend serial stage", "apt (Thorlabs APT stage, e.g. K10CR1)" },
    { "turntable", "sim", "backend speed_deg_s accel_deg_s2 home_time_s position_noise_deg time_scale seed "
      "fault_after_moves fault", "sim (simulated stage)" },
    { "lamp", "gpiod", "backend chip line active_low warmup_ms settle_ms", "gpiod (a GPIO line)" },
    { "lamp", "sim", "backend position_mm warmup_ms settle_ms", "sim (simulated lamp)" },
    { "rig", "virtual", "backend truth serve address sample time_scale noise_seed busy_wait_s pixel_format "
      "exposure_us gain packet_size packet_delay",
      "virtual (the whole rig simulated)" },
};
#define NBACKENDS ((int)(sizeof backends / sizeof backends[0]))

static bool key_in(const char *keys, const char *key)
{
    size_t n = strlen(key);
    for (const char *p = keys; *p;) {
        const char *e = strchr(p, ' ');
        size_t m = e ? (size_t)(e - p) : strlen(p);
        if (m == n && !strncmp(p, key, n)) return true;
        if (!e) break;
        p = e + 1;
    }
    return false;
}

static void backend_choices(const char *kind, char *out, size_t size)
{
    size_t n = 0;
    out[0] = 0;
    for (int i = 0; i < NBACKENDS && n < size; i++)
        if (!strcmp(backends[i].kind, kind))
            n += (size_t)snprintf(out + n, size - n, "%s'backend = %s' for %s", n ? " or " : "",
                                  backends[i].backend, backends[i].what);
}

static const char *kind_of(const char *section)
{
    if (!strcmp(section, "turntable") || !strcmp(section, "rig") || !strcmp(section, "lamps")) return section;
    if (!strncmp(section, "camera ", 7) || !strcmp(section, "camera")) return "camera";
    if (!strncmp(section, "lamp ", 5) || !strcmp(section, "lamp")) return "lamp";
    return NULL;
}

// Finds the backend of a section and checks every key of it.
static int check_section(const spec_t *s, const char *section, int line, const backend_def_t **out)
{
    const char *kind = kind_of(section);
    char choices[400];
    backend_choices(kind, choices, sizeof choices);
    const model_ini_entry_t *b = model_ini_get(s->ini, section, "backend");
    if (!b) return cfg_fail(s, line, "[%s] has no backend: add %s", section, choices);
    const backend_def_t *def = NULL;
    for (int i = 0; i < NBACKENDS; i++)
        if (!strcmp(backends[i].kind, kind) && !strcmp(backends[i].backend, b->value)) def = &backends[i];
    if (!def) return cfg_fail(s, b->line, "[%s]: unknown backend '%s': use %s", section, b->value, choices);
    for (int i = 0; i < s->ini->nentries; i++) {
        const model_ini_entry_t *e = &s->ini->entries[i];
        if (strcmp(e->section, section)) continue;
        if (!key_in(def->keys, e->key))
            return cfg_fail(s, e->line, "[%s]: unknown key '%s' for backend %s; known keys: %s", section, e->key,
                            def->backend, def->keys);
    }
    *out = def;
    return 0;
}

static const model_ini_entry_t *get(const spec_t *s, const char *section, const char *key)
{
    return model_ini_get(s->ini, section, key);
}

// Optional typed values (model/base/ini.c reports them with file:line); absent
// keeps *out. 0 or RIG_ERR_INVALID.
static int get_double(const spec_t *s, const char *section, const char *key, double *out, double lo, bool lo_open,
                      double hi, const char *range_text)
{
    return model_ini_double_in(s->ini, section, key, out, false, lo, lo_open, hi, range_text) ? 0 : RIG_ERR_INVALID;
}

static int get_long(const spec_t *s, const char *section, const char *key, long *out, long lo, long hi)
{
    return model_ini_int(s->ini, section, key, out, false, lo, hi) ? 0 : RIG_ERR_INVALID;
}

static int get_bool(const spec_t *s, const char *section, const char *key, bool *out)
{
    return model_ini_bool(s->ini, section, key, out, false) ? 0 : RIG_ERR_INVALID;
}

// Optional string that must fit size-1 characters and be non-empty.
static int get_string(const spec_t *s, const char *section, const char *key, char *out, size_t size)
{
    return model_ini_string(s->ini, section, key, out, size, false) ? 0 : RIG_ERR_INVALID;
}

static int get_pixel_format(spec_t *s, const char *section)
{
    const model_ini_entry_t *e = get(s, section, "pixel_format");
    if (!e) return 0;
    rig_pixfmt_t f;
    if (!rig_pixfmt_from_name(e->value, &f))
        return cfg_fail(s, e->line, "[%s] pixel_format: '%s' is not Mono8, Mono12 or Mono16 (nor Mono10, Mono10p, "
                        "Mono12p, Mono10Packed, Mono12Packed)", section, e->value);
    snprintf(s->pixel_format, sizeof s->pixel_format, "%s", e->value);
    return 0;
}

static int get_camera_defaults(spec_t *s, const char *section)
{
    int rc;
    if ((rc = get_pixel_format(s, section)) ||
        (rc = get_double(s, section, "exposure_us", &s->exposure_us, 0, true, 1e8, "0 < exposure_us <= 1e8 us")) ||
        (rc = get_double(s, section, "gain", &s->gain, -100, false, 100, "-100..100, in the camera's unit (dB)")))
        return rc;
    // GigE Vision stream packets (GenICam GevSCPSPacketSize, GevSCPD); the camera checks its own range at open
    s->packet_size = s->packet_delay = -1;
    if ((rc = get_long(s, section, "packet_size", &s->packet_size, 576, 16384)) ||
        (rc = get_long(s, section, "packet_delay", &s->packet_delay, 0, 4294967295L)))
        return rc;
    const model_ini_entry_t *e = get(s, section, "packet_size");
    if (!e) e = get(s, section, "packet_delay");
    s->packet_line = e ? e->line : 0;
    return 0;
}

static bool is_ipv4(const char *a)
{
    struct in_addr x;
    return inet_pton(AF_INET, a, &x) == 1;
}

// ---------------------------------------------------------------------------
// Sections

static int parse_rig(spec_t *s, const char *sec, int line)
{
    int rc;
    s->virt = true;
    s->rig_line = line;
    const model_ini_entry_t *t = get(s, sec, "truth");
    if (!t || !t->value[0])
        return cfg_fail(s, t ? t->line : line, "[rig] backend = virtual needs 'truth = FILE': the virtual rig's "
                        "ground truth (see examples/virtual-truth.ini), relative to this file's directory");
    if (t->value[0] == '/') {
        s->truth = g_strdup(t->value);
    } else {
        char *dir = g_path_get_dirname(s->path);
        s->truth = g_build_filename(dir, t->value, NULL);
        g_free(dir);
    }
    const model_ini_entry_t *sv = get(s, sec, "serve");
    if (sv) {
        if (!strcmp(sv->value, "inprocess")) s->inprocess = true;
        else if (strcmp(sv->value, "gige"))
            return cfg_fail(s, sv->line, "[rig] serve: '%s' is not gige (GigE Vision on the address) or inprocess "
                            "(an Aravis fake device inside refl, no network)", sv->value);
    }
    if (s->inprocess)
        for (int k = 0; k < 2; k++) {
            const char *key = k ? "busy_wait_s" : "address";
            const model_ini_entry_t *e = get(s, sec, key);
            if (e)
                return cfg_fail(s, e->line, "[rig] %s applies to serve = gige only (serve = inprocess uses no "
                                "network): remove it, or write serve = gige", key);
        }
    snprintf(s->address, sizeof s->address, "127.0.0.1");
    if ((rc = get_string(s, sec, "address", s->address, sizeof s->address))) return rc;
    const model_ini_entry_t *a = get(s, sec, "address");
    gchar **as = g_strsplit_set(s->address, " \t", -1);   // one per camera of the truth file
    for (int i = 0; a && as[i]; i++)
        if (as[i][0] && (!is_ipv4(as[i]) || strncmp(as[i], "127.", 4))) {
            rc = cfg_fail(s, a->line, "[rig] address: '%s' is not a loopback IPv4 address: the virtual cameras "
                          "serve on 127.x.y.z only (one address per camera, separated by spaces)", as[i]);
            break;
        }
    g_strfreev(as);
    if (rc) return rc;
    if ((rc = get_string(s, sec, "sample", s->sample, sizeof s->sample))) return rc;
    s->time_scale = 1;
    if ((rc = get_double(s, sec, "time_scale", &s->time_scale, 0, true, 1e3, "0 < time_scale <= 1000; 1 is real "
                         "time, 0.01 is 100x faster")))
        return rc;
    if ((rc = get_double(s, sec, "busy_wait_s", &s->busy_wait_s, 0, false, 3600, "0 <= busy_wait_s <= 3600: how "
                         "long to wait for another virtual camera on the address to stop")))
        return rc;
    long seed = 1;
    if ((rc = get_long(s, sec, "noise_seed", &seed, 0, LONG_MAX))) return rc;
    s->noise_seed = (uint64_t)seed;
    s->have_noise_seed = get(s, sec, "noise_seed") != NULL;
    return get_camera_defaults(s, sec);
}

// A camera's name: what frame files and --camera use ([A-Za-z0-9_-], not "all").
static bool camera_name_ok(const char *n)
{
    if (!*n || strlen(n) >= RIG_CAMERA_NAME_MAX || !strcmp(n, "all")) return false;
    for (const char *p = n; *p; p++)
        if (!g_ascii_isalnum(*p) && *p != '_' && *p != '-') return false;
    return true;
}

static int parse_camera(spec_t *s, const char *sec, int line)
{
    int rc;
    const char *name = !strcmp(sec, "camera") ? "camera" : sec + 7;
    if (!camera_name_ok(name))
        return cfg_fail(s, line, "[%s]: '%s' is not a camera name: write [camera NAME] with NAME of letters, "
                        "digits, '_' and '-' (at most %d characters, not 'all'), or [camera] for one camera",
                        sec, name, RIG_CAMERA_NAME_MAX - 1);
    for (int j = 0; j < s->ncameras; j++)
        if (!strcmp(s->cam[j].name, name))
            return cfg_fail(s, line, "[%s]: camera '%s' is already [%s] (line %d): give each camera its own name",
                            sec, name, s->cam[j].section, s->cam[j].line);
    if (s->ncameras >= RIG_CAMERAS_MAX)
        return cfg_fail(s, line, "[%s]: more than %d cameras; a rig has at most %d", sec, RIG_CAMERAS_MAX,
                        RIG_CAMERAS_MAX);
    static const char *const ids[] = { "address", "serial", "name" };
    const model_ini_entry_t *id = NULL;
    for (int i = 0; i < 3; i++) {
        const model_ini_entry_t *e = get(s, sec, ids[i]);
        if (!e) continue;
        if (id)
            return cfg_fail(s, e->line, "[%s]: both %s (line %d) and %s given: identify the camera by one of "
                            "address, serial or name", sec, id->key, id->line, e->key);
        id = e;
    }
    if (!id)
        return cfg_fail(s, line, "[%s] does not say which camera: add 'address = IP' (GigE Vision, opened "
                        "directly), 'serial = S' or 'name = N'", sec);
    char cid[64] = "";
    if ((rc = get_string(s, sec, id->key, cid, sizeof cid))) return rc;
    if (!strcmp(id->key, "address") && !is_ipv4(id->value))
        return cfg_fail(s, id->line, "[%s] address: '%s' is not an IPv4 address (a.b.c.d); identify the camera "
                        "by 'serial =' or 'name =' otherwise", sec, id->value);
    for (int j = 0; j < s->ncameras; j++)
        if (!strcmp(s->cam[j].id, cid))
            return cfg_fail(s, id->line, "[%s]: '%s' already identifies [%s] (line %d): one section per camera",
                            sec, cid, s->cam[j].section, s->cam[j].line);
    s->pixel_format[0] = 0;
    s->exposure_us = s->gain = NAN;
    if ((rc = get_camera_defaults(s, sec))) return rc;
    int k = s->ncameras++;
    s->cam[k].line = line;
    snprintf(s->cam[k].section, sizeof s->cam[k].section, "%s", sec);
    snprintf(s->cam[k].name, sizeof s->cam[k].name, "%s", name);
    snprintf(s->cam[k].id, sizeof s->cam[k].id, "%s", cid);
    snprintf(s->cam[k].pixel_format, sizeof s->cam[k].pixel_format, "%s", s->pixel_format);
    s->cam[k].exposure_us = s->exposure_us;
    s->cam[k].gain = s->gain;
    s->cam[k].packet_size = s->packet_size;
    s->cam[k].packet_delay = s->packet_delay;
    s->cam[k].packet_line = s->packet_line;
    return 0;
}

static int parse_turntable(spec_t *s, const char *sec, int line, const backend_def_t *def)
{
    int rc;
    s->have_turntable = true;
    s->turntable_line = line;
    if (!strcmp(def->backend, "apt")) {
        s->turntable_apt = true;
        if ((rc = get_string(s, sec, "serial", s->apt_serial, sizeof s->apt_serial))) return rc;
        const model_ini_entry_t *st = get(s, sec, "stage");
        if (st) {
            bool known = false;
            char list[256] = "";
            size_t n = 0;
            for (int i = 0; rig_stage_models[i].model; i++) {
                if (!strcmp(rig_stage_models[i].model, st->value)) known = true;
                n += (size_t)snprintf(list + n, n < sizeof list ? sizeof list - n : 0, "%s%s", i ? ", " : "",
                                      rig_stage_models[i].model);
            }
            if (!known)
                return cfg_fail(s, st->line, "[turntable] stage: '%s' is not a stage refl knows (%s); leave 'stage' "
                                "out to take it from the controller", st->value, list);
            snprintf(s->apt_stage, sizeof s->apt_stage, "%s", st->value);
        }
        return 0;
    }
    rig_turntable_sim_params_t *p = &s->sim;
    *p = rig_turntable_sim_defaults();
    long seed = (long)p->seed, after = 0;
    if ((rc = get_double(s, sec, "speed_deg_s", &p->speed_deg_s, 0, true, 1e4, "0 < speed_deg_s <= 1e4")) ||
        (rc = get_double(s, sec, "accel_deg_s2", &p->accel_deg_s2, 0, true, 1e6, "0 < accel_deg_s2 <= 1e6")) ||
        (rc = get_double(s, sec, "home_time_s", &p->home_time_s, 0, false, 3600, "0 <= home_time_s <= 3600")) ||
        (rc = get_double(s, sec, "position_noise_deg", &p->position_noise_deg, 0, false, 10,
                         "0 <= position_noise_deg <= 10")) ||
        (rc = get_double(s, sec, "time_scale", &p->time_scale, 0, true, 1e3, "0 < time_scale <= 1000; 1 is real "
                         "time, 0.01 is 100x faster")) ||
        (rc = get_long(s, sec, "seed", &seed, 0, LONG_MAX)) ||
        (rc = get_long(s, sec, "fault_after_moves", &after, 0, 1000000)))
        return rc;
    p->seed = (uint64_t)seed;
    p->fault_after_moves = (int)after;
    const model_ini_entry_t *f = get(s, sec, "fault");
    if (f) {
        if (!strcmp(f->value, "motion")) p->fault = RIG_ERR_MOTION;
        else if (!strcmp(f->value, "timeout")) p->fault = RIG_ERR_TIMEOUT;
        else if (!strcmp(f->value, "disconnected")) p->fault = RIG_ERR_DISCONNECTED;
        else return cfg_fail(s, f->line, "[turntable] fault: '%s' is not motion, timeout or disconnected", f->value);
    }
    if (after > 0 && !f)
        return cfg_fail(s, get(s, sec, "fault_after_moves")->line, "[turntable] fault_after_moves needs "
                        "'fault = motion|timeout|disconnected'");
    return 0;
}

static int parse_lamp(spec_t *s, const char *sec, int line, const backend_def_t *def)
{
    int rc;
    const char *name = sec + 4;
    if (*name == ' ') name++;
    if (!*name) return cfg_fail(s, line, "[lamp] needs a name: write [lamp NAME]");
    if (strlen(name) >= sizeof s->lamps[0].name)
        return cfg_fail(s, line, "[lamp %s]: the name is longer than %zu characters", name,
                        sizeof s->lamps[0].name - 1);
    if (strchr(name, ',') || !strcmp(name, "all") || !strcmp(name, "none"))
        return cfg_fail(s, line, "[lamp %s]: lamp names may not contain ',' or be 'all' or 'none' (they are "
                        "written as refl rig snap --lamps NAME,NAME|all|none); rename it", name);
    if (s->nlamps >= MAX_LAMPS)
        return cfg_fail(s, line, "[lamp %s]: more than %d lamps; a rig switches at most %d", name, MAX_LAMPS,
                        MAX_LAMPS);
    bool gpiod = !strcmp(def->backend, "gpiod");
    if (s->nlamps > 0 && gpiod != s->lamps_gpiod)
        return cfg_fail(s, get(s, sec, "backend")->line, "[lamp %s]: backend %s, but [lamp %s] (line %d) is %s: "
                        "all lamps of a rig use one backend", name, def->backend, s->lamps[0].name, s->lamp_line[0],
                        s->lamps_gpiod ? "gpiod" : "sim");
    s->lamps_gpiod = gpiod;
    rig_lamp_line_t *a = &s->lamps[s->nlamps];
    memset(a, 0, sizeof *a);
    snprintf(a->name, sizeof a->name, "%s", name);
    if ((rc = get_double(s, sec, "warmup_ms", &a->warmup_ms, 0, false, 3.6e6, "0 <= warmup_ms <= 3.6e6")) ||
        (rc = get_double(s, sec, "settle_ms", &a->settle_ms, 0, false, 3.6e6, "0 <= settle_ms <= 3.6e6")))
        return rc;
    if (gpiod) {
        const model_ini_entry_t *c = get(s, sec, "chip"), *l = get(s, sec, "line");
        if (!c || !l)
            return cfg_fail(s, line, "[lamp %s]: backend gpiod needs 'chip = gpiochipN' (or a /dev path) and "
                            "'line = OFFSET'", name);
        if ((rc = get_string(s, sec, "chip", a->chip, sizeof a->chip))) return rc;
        long off = 0;
        if ((rc = get_long(s, sec, "line", &off, 0, 65535))) return rc;
        a->line = (unsigned)off;
        if ((rc = get_bool(s, sec, "active_low", &a->active_low))) return rc;
        for (int j = 0; j < s->nlamps; j++)
            if (!strcmp(s->lamps[j].chip, a->chip) && s->lamps[j].line == a->line)
                return cfg_fail(s, l->line, "[lamp %s]: %s line %u is already lamp '%s' (line %d): one lamp per "
                                "GPIO line", name, a->chip, a->line, s->lamps[j].name, s->lamp_line[j]);
    } else {
        double xyz[3];
        if (!model_ini_vec3(s->ini, sec, "position_mm", xyz, false, "x y z (mm, rig frame)")) return RIG_ERR_INVALID;
    }
    s->lamp_line[s->nlamps++] = line;
    return 0;
}

// [lamps]: settings of the whole lamp set (no backend): state_file.
static int parse_lamps(spec_t *s, const char *sec)
{
    for (int i = 0; i < s->ini->nentries; i++) {
        const model_ini_entry_t *e = &s->ini->entries[i];
        if (!strcmp(e->section, sec) && strcmp(e->key, "state_file"))
            return cfg_fail(s, e->line, "[lamps]: unknown key '%s'; known keys: state_file (where the lamp-state "
                            "file is kept)", e->key);
    }
    int rc = get_string(s, sec, "state_file", s->lamp_state_file, sizeof s->lamp_state_file);
    if (rc || !s->lamp_state_file[0] || s->lamp_state_file[0] == '/') return rc;
    // relative to the rig file's directory, as truth is
    char *dir = g_path_get_dirname(s->path), *full = g_build_filename(dir, s->lamp_state_file, NULL);
    bool fits = strlen(full) < sizeof s->lamp_state_file;
    if (fits) snprintf(s->lamp_state_file, sizeof s->lamp_state_file, "%s", full);
    g_free(dir);
    g_free(full);
    return fits ? 0 : cfg_fail(s, get(s, sec, "state_file")->line, "[lamps] state_file: the path is too long");
}

static int parse(spec_t *s)
{
    const model_ini_t *ini = s->ini;
    int rc;
    s->exposure_us = NAN;
    s->gain = NAN;
    int rig_sec = -1, other_sec = -1;
    for (int i = 0; i < ini->nsections; i++) {
        const char *sec = ini->sections[i];
        if (!kind_of(sec))
            return cfg_fail(s, ini->section_lines[i], "unknown section [%s]: a rig file has [camera] (or "
                            "[camera NAME], one or more), [turntable], [lamp NAME] sections, or one [rig] section "
                            "(backend = virtual)", sec);
        if (!strcmp(sec, "rig")) rig_sec = i;
        else if (other_sec < 0) other_sec = i;
    }
    if (rig_sec >= 0 && other_sec >= 0) {
        int l = ini->section_lines[rig_sec] > ini->section_lines[other_sec] ? rig_sec : other_sec;
        return cfg_fail(s, ini->section_lines[l], "[%s] together with [%s]: [rig] backend = virtual makes its own "
                        "camera, turntable and lamps; remove [rig] or the device sections", ini->sections[l],
                        ini->sections[l == rig_sec ? other_sec : rig_sec]);
    }
    if (ini->nsections == 0)
        return cfg_fail(s, 0, "no devices: add [camera], [turntable] and [lamp NAME] sections, or [rig] "
                        "backend = virtual");
    for (int i = 0; i < ini->nsections; i++) {
        const char *sec = ini->sections[i], *kind = kind_of(sec);
        int line = ini->section_lines[i];
        const backend_def_t *def = NULL;
        if (!strcmp(kind, "lamps")) rc = parse_lamps(s, sec);
        else if ((rc = check_section(s, sec, line, &def))) return rc;
        else if (!strcmp(kind, "rig")) rc = parse_rig(s, sec, line);
        else if (!strcmp(kind, "camera")) rc = parse_camera(s, sec, line);
        else if (!strcmp(kind, "turntable")) rc = parse_turntable(s, sec, line, def);
        else rc = parse_lamp(s, sec, line, def);
        if (rc) return rc;
    }
    if (!s->virt && s->ncameras > 0) {   // the rig's defaults: its first camera's
        snprintf(s->pixel_format, sizeof s->pixel_format, "%s", s->cam[0].pixel_format);
        s->exposure_us = s->cam[0].exposure_us;
        s->gain = s->cam[0].gain;
    }
    return 0;
}

// The INI text, then every section (s->path names it in messages). *ini is
// set whenever the INI parsed (the caller frees it, and s->truth).
static int parse_text(spec_t *s, const char *text, size_t len, model_ini_t **ini)
{
    *ini = model_ini_parse(text, len, s->path);
    if (!*ini) {
        char msg[1200];
        snprintf(msg, sizeof msg, "%s", model_last_error());
        bool q = model_error_quiet_thread(true);
        rig_fail(RIG_ERR_INVALID, "%s", msg);
        model_error_quiet_thread(q);
        return RIG_ERR_INVALID;
    }
    s->ini = *ini;
    return parse(s);
}

int rig_config_parse(const char *text, size_t len, const char *name)
{
    if (!text || !name || !*name) return rig_fail(RIG_ERR_INVALID, "rig_config_parse: NULL text or no name");
    spec_t s = { .path = name };
    model_ini_t *ini = NULL;
    int rc = parse_text(&s, text, len, &ini);
    model_ini_free(ini);
    g_free(s.truth);
    return rc;
}

// ---------------------------------------------------------------------------
// Opening

static void set_profile_from_stage(rig_t *r, const char *model)
{
    for (int i = 0; rig_stage_models[i].model; i++)
        if (model && !strcmp(rig_stage_models[i].model, model)) {
            r->speed_deg_s = rig_stage_models[i].max_speed_deg_s;
            r->accel_deg_s2 = rig_stage_models[i].accel_deg_s2;
            r->home_time_s = 2 * 360 / r->speed_deg_s;   // a full turn at cruise speed, twice
            return;
        }
}

static void set_profile_sim(rig_t *r, const rig_turntable_sim_params_t *p)
{
    double ts = p->time_scale;
    r->speed_deg_s = p->speed_deg_s / ts;
    r->accel_deg_s2 = p->accel_deg_s2 / (ts * ts);
    r->home_time_s = p->home_time_s * ts;
}

// Runs a device call quietly (its message is repeated with the file and line).
#define QUIET(call)                                                                                  \
    do {                                                                                             \
        bool q_ = model_error_quiet_thread(true);                                                           \
        rc = (call);                                                                                 \
        model_error_quiet_thread(q_);                                                                       \
    } while (0)

// A camera's settings from the rig file: pixel format, exposure, gain, then the
// GigE Vision stream packets (-1: the camera's own), each set and read back.
static int apply_camera_defaults(rig_camera_t *c, const char *pixel_format, double exposure_us, double gain,
                                 long packet_size, long packet_delay, int packet_line, const spec_t *s, int line,
                                 const char *section)
{
    int rc = 0;
    if (!c) return 0;
    if (pixel_format[0]) QUIET(rig_camera_set_pixel_format(c, pixel_format));
    if (!rc && isfinite(exposure_us)) QUIET(rig_camera_set_exposure_us(c, exposure_us));
    if (!rc && isfinite(gain)) QUIET(rig_camera_set_gain(c, gain));
    if (rc) return device_fail(rc, s, line, section);
    if (packet_size >= 0 || packet_delay >= 0) QUIET(rig_camera_set_stream_packets(c, packet_size, packet_delay));
    return rc ? device_fail(rc, s, packet_line ? packet_line : line, section) : 0;
}

// Enters an opened camera in r->cameras (r->camera is the first).
static void add_camera(rig_t *r, rig_camera_t *c, const char *name)
{
    snprintf(r->camera_names[r->ncameras], sizeof r->camera_names[0], "%s", name);
    r->cameras[r->ncameras++] = c;
    r->camera = r->cameras[0];
}

// A device that did not open: with keep_going, recorded in r->failed (its
// message, already composed with the file and line) and 0; else rc.
static int open_failed(rig_t *r, int rc, unsigned kind, const char *name, bool keep_going)
{
    if (!keep_going || r->nfailed >= (int)(sizeof r->failed / sizeof r->failed[0])) return rc;
    rig_open_failure_t *f = &r->failed[r->nfailed++];
    f->kind = kind;
    snprintf(f->name, sizeof f->name, "%s", name ? name : "");
    f->before = r->ncameras;
    snprintf(f->error, sizeof f->error, "%s", model_last_error());
    return 0;
}

// One camera of the file (or the virtual rig's camera at address id) opened
// with its settings and entered in r.
static int open_camera(rig_t *r, const spec_t *s, const char *id, const char *name, int k, bool keep_going)
{
    rig_camera_t *c = NULL;
    int rc;
    bool v = s->virt, q = model_error_quiet_thread(true);
    model_error_quiet_thread(q || keep_going);   // a failure recorded with keep_going is not printed
    QUIET(rig_camera_open_aravis(&c, id));
    if (rc) rc = device_fail(rc, s, v ? s->rig_line : s->cam[k].line, v ? "rig" : s->cam[k].section);
    else if (v)
        rc = apply_camera_defaults(c, s->pixel_format, s->exposure_us, s->gain, s->packet_size, s->packet_delay,
                                   s->packet_line, s, s->rig_line, "rig");
    else
        rc = apply_camera_defaults(c, s->cam[k].pixel_format, s->cam[k].exposure_us, s->cam[k].gain,
                                   s->cam[k].packet_size, s->cam[k].packet_delay, s->cam[k].packet_line, s,
                                   s->cam[k].line, s->cam[k].section);
    model_error_quiet_thread(q);
    if (!rc) {
        add_camera(r, c, name);
        return 0;
    }
    if (c) {   // opened, but its settings failed: closed again (keeping the message)
        char keep[1280];
        snprintf(keep, sizeof keep, "%s", model_last_error());
        rig_camera_close(c);
        q = model_error_quiet_thread(true);
        rig_fail(rc, "%s", keep);
        model_error_quiet_thread(q);
    }
    return open_failed(r, rc, RIG_DEVICE_CAMERAS, name, keep_going);
}

// The virtual rig: its simulation, and its cameras when asked.
static int open_virtual(rig_t *r, spec_t *s, unsigned devices, bool keep_going)
{
    int rc = 0;
    rig_virtual_options_t o = rig_virtual_defaults();
    o.serve = s->inprocess ? RIG_VIRTUAL_SERVE_INPROCESS : RIG_VIRTUAL_SERVE_GIGE;
    o.address = s->address;
    if (s->sample[0]) o.sample = s->sample;
    o.time_scale = s->time_scale;
    if (s->have_noise_seed) o.noise_seed = s->noise_seed;
    o.busy_wait_s = s->busy_wait_s;
    QUIET(rig_virtual_open(&r->virt, s->truth, &o));
    if (rc) return device_fail(rc, s, s->rig_line, "rig");
    if (devices & RIG_DEVICE_TURNTABLE) r->turntable = rig_virtual_turntable(r->virt);
    if (devices & RIG_DEVICE_LAMPS) r->lamps = rig_virtual_lamps(r->virt);
    // The stage's profile is the truth file's [turntable] (defaults of the sim stage otherwise).
    rig_turntable_sim_params_t p = rig_turntable_sim_defaults();
    bool q = model_error_quiet_thread(true);
    model_ini_t *truth = model_ini_load(s->truth);
    model_error_quiet_thread(q);
    const model_ini_entry_t *e;
    double v;
    if ((e = model_ini_get(truth, "turntable", "speed_deg_s")) && model_parse_double(e->value, &v) && v > 0)
        p.speed_deg_s = v;
    if ((e = model_ini_get(truth, "turntable", "accel_deg_s2")) && model_parse_double(e->value, &v) && v > 0)
        p.accel_deg_s2 = v;
    if ((e = model_ini_get(truth, "turntable", "home_time_s")) && model_parse_double(e->value, &v) && v >= 0)
        p.home_time_s = v;
    model_ini_free(truth);
    p.time_scale = s->time_scale;
    set_profile_sim(r, &p);
    for (int k = 0; (devices & RIG_DEVICE_CAMERAS) && k < rig_virtual_ncameras(r->virt); k++) {   // the truth file's
        rig_virtual_t *view = rig_virtual_camera_view(r->virt, k);
        if ((rc = open_camera(r, s, rig_virtual_camera_address(view), rig_virtual_camera_name(view), k, keep_going)))
            return rc;
    }
    return 0;
}

// The APT stage, its motion profile from the controller (or the stage table).
static int open_apt(rig_t *r, const spec_t *s)
{
    int rc;
    QUIET(rig_turntable_open_apt(&r->turntable, s->apt_serial[0] ? s->apt_serial : NULL,
                                 s->apt_stage[0] ? s->apt_stage : NULL));
    if (rc) return rc;
    rig_turntable_info_t info;
    QUIET(rig_turntable_info(r->turntable, &info));
    set_profile_from_stage(r, s->apt_stage[0] ? s->apt_stage : rc ? NULL : info.model);
    if (!rc && info.speed_deg_s > 0 && info.accel_deg_s2 > 0 && info.home_time_s > 0) {
        // the controller's own (or the table's) speeds, as the driver found them
        r->speed_deg_s = info.speed_deg_s;
        r->accel_deg_s2 = info.accel_deg_s2;
        r->home_time_s = info.home_time_s;
    }
    return 0;
}

static int open_devices(rig_t *r, spec_t *s, unsigned devices, bool keep_going)
{
    int rc = 0;
    if (s->virt) return open_virtual(r, s, devices, keep_going);
    bool q = model_error_quiet_thread(true);
    model_error_quiet_thread(q || keep_going);   // a failure recorded with keep_going is not printed
    if (s->have_turntable && (devices & RIG_DEVICE_TURNTABLE)) {
        if (s->turntable_apt) {
            rc = open_apt(r, s);
        } else {
            QUIET(rig_turntable_open_sim(&r->turntable, &s->sim));
            set_profile_sim(r, &s->sim);
        }
        if (rc) rc = open_failed(r, device_fail(rc, s, s->turntable_line, "turntable"), RIG_DEVICE_TURNTABLE, NULL,
                                 keep_going);
    }
    if (!rc && s->nlamps > 0 && (devices & RIG_DEVICE_LAMPS)) {
        if (s->lamps_gpiod) QUIET(rig_lamps_open_gpiod_state(&r->lamps, s->lamps, s->nlamps, s->lamp_state_file));
        else QUIET(rig_lamps_open_sim_state(&r->lamps, s->lamps, s->nlamps, s->lamp_state_file));
        if (rc) {
            char sec[80];
            snprintf(sec, sizeof sec, "lamp %s", s->lamps[0].name);
            rc = open_failed(r, device_fail(rc, s, s->lamp_line[0], sec), RIG_DEVICE_LAMPS, NULL, keep_going);
        }
    }
    model_error_quiet_thread(q);
    for (int i = 0; !rc && (devices & RIG_DEVICE_CAMERAS) && i < s->ncameras; i++)
        rc = open_camera(r, s, s->cam[i].id, s->cam[i].name, i, keep_going);
    return rc;
}

int rig_open(rig_t **out, const char *path)
{
    const rig_open_opts_t all = { .devices = RIG_DEVICE_ALL };
    return rig_open_with(out, path, &all);
}

int rig_open_with(rig_t **out, const char *path, const rig_open_opts_t *o)
{
    if (!out) return rig_fail(RIG_ERR_INVALID, "rig_open: NULL output");
    *out = NULL;
    if (!path || !*path) return rig_fail(RIG_ERR_INVALID, "rig_open: no rig file given");
    rig_safety_install();
    int rc = RIG_ERR_INVALID;
    spec_t s = { .path = path };
    rig_t *r = NULL;
    size_t len = 0;
    char *text = model_read_file(path, &len);
    model_ini_t *ini = NULL;
    if (!text) {
        char msg[1200];
        snprintf(msg, sizeof msg, "%s", model_last_error());
        bool q = model_error_quiet_thread(true);
        rig_fail(RIG_ERR_NO_DEVICE, "%s (the rig description file)", msg);
        model_error_quiet_thread(q);
        rc = RIG_ERR_NO_DEVICE;
        goto done;
    }
    if ((rc = parse_text(&s, text, len, &ini))) goto done;

    r = calloc(1, sizeof *r);
    if (!r || !(r->path = strdup(path))) {
        rc = rig_fail(RIG_ERR_NO_MEM, "%s: out of memory", path);
        goto done;
    }
    model_sha256_hex(text, len, r->sha256);
    snprintf(r->pixel_format, sizeof r->pixel_format, "%s", s.pixel_format);
    r->exposure_us = s.exposure_us;
    r->gain = s.gain;
    r->speed_deg_s = r->accel_deg_s2 = r->home_time_s = NAN;
    r->devices = o->devices & RIG_DEVICE_ALL;
    if ((rc = open_devices(r, &s, r->devices, o->keep_going))) goto done;
    *out = r;
    r = NULL;
done:
    rig_close(r);
    model_ini_free(ini);
    free(text);
    g_free(s.truth);
    return rc;
}

int rig_camera_find(const rig_t *r, const char *name)
{
    for (int i = 0; r && name && i < r->ncameras; i++)
        if (!strcmp(r->camera_names[i], name)) return i;
    return -1;
}

void rig_close(rig_t *r)
{
    if (!r) return;
    bool q = model_error_quiet_thread(true);   // closing after an error must not overwrite its message
    char keep[1536];
    snprintf(keep, sizeof keep, "%s", model_last_error());
    if (r->lamps) rig_lamps_all_off(r->lamps);
    if (r->turntable) {
        rig_turntable_status_t st;
        if (rig_turntable_status(r->turntable, &st) == 0 && st.moving) rig_turntable_stop(r->turntable, false);
    }
    for (int i = r->ncameras - 1; i >= 0; i--) rig_camera_close(r->cameras[i]);
    if (r->virt) {
        rig_virtual_close(r->virt);
    } else {
        rig_lamps_close(r->lamps);
        rig_turntable_close(r->turntable);
    }
    rig_fail(RIG_ERR_OK, "%s", keep);
    model_error_quiet_thread(q);
    free(r->path);
    free(r);
}

// ---------------------------------------------------------------------------
// Questions about a rig file that need no device

bool rig_file_truth_path(const char *rig_path, char **truth_path)
{
    *truth_path = NULL;
    model_ini_t *ini = model_ini_load(rig_path);
    if (!ini) return false;
    bool ok = true;
    const model_ini_entry_t *be = model_ini_get(ini, "rig", "backend");
    if (be && !strcmp(be->value, "virtual")) {
        const model_ini_entry_t *t = model_ini_get(ini, "rig", "truth");
        if (!t) {
            model_error(rig_path, be->line, "[rig] backend = virtual without truth = FILE");
            ok = false;
        } else if (t->value[0] == '/') {
            *truth_path = g_strdup(t->value);
        } else {
            char *d = g_path_get_dirname(rig_path);
            *truth_path = g_build_filename(d, t->value, NULL);
            g_free(d);
        }
    }
    model_ini_free(ini);
    return ok;
}

static void lamp_sections(const model_ini_t *ini, GPtrArray *names)
{
    for (int s = 0; s < ini->nsections; s++)
        if (!strncmp(ini->sections[s], "lamp ", 5)) g_ptr_array_add(names, g_strdup(ini->sections[s] + 5));
}

// The INI that names a rig file's devices: a virtual rig's truth file, else the rig file.
static model_ini_t *devices_ini(const char *rig_path)
{
    char *truth = NULL;
    if (!rig_file_truth_path(rig_path, &truth)) return NULL;
    model_ini_t *ini = model_ini_load(truth ? truth : rig_path);
    g_free(truth);
    return ini;
}

bool rig_file_lamp_names(const char *rig_path, char ***names, int *n)
{
    model_ini_t *ini = devices_ini(rig_path);
    if (!ini) return false;
    GPtrArray *a = g_ptr_array_new();
    lamp_sections(ini, a);
    model_ini_free(ini);
    *n = (int)a->len;
    g_ptr_array_add(a, NULL);
    *names = (char **)g_ptr_array_free(a, FALSE);
    return true;
}

bool rig_file_camera_names(const char *rig_path, char ***names, int *n)
{
    model_ini_t *ini = devices_ini(rig_path);
    if (!ini) return false;
    GPtrArray *a = g_ptr_array_new();
    for (int s = 0; s < ini->nsections; s++)
        if (!strcmp(ini->sections[s], "camera")) g_ptr_array_add(a, g_strdup("camera"));
        else if (!strncmp(ini->sections[s], "camera ", 7)) g_ptr_array_add(a, g_strdup(ini->sections[s] + 7));
    model_ini_free(ini);
    *n = (int)a->len;
    g_ptr_array_add(a, NULL);
    *names = (char **)g_ptr_array_free(a, FALSE);
    return true;
}
