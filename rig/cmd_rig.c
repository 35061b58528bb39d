// rig/cmd_rig.c — `refl rig`: drive the rig described by a rig file from the
// command line: status, home, move, identify, snap, serve.
//
// Options are parsed strictly (unknown option, missing value, bad number,
// option of another action, missing --rig: usage error, exit 2) before any
// device is opened; device and file errors exit 1 with the driver's message
// (already printed by rig_fail). Progress goes to stderr, results to stdout.
// Lamps are off again when the command ends, whatever the way out (rig_close,
// and rig_safety_install for signals).
#define _GNU_SOURCE
#include <ctype.h>
#include <errno.h>
#include <glib.h>
#include <limits.h>
#include <math.h>
#include <pthread.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#include "model/model.h"
#include "model/base/opts.h"
#include "rig/camera/pixfmt.h"
#include "rig/rig.h"

#define CAPTURE_TIMEOUT_S 20.0     // beyond the exposure: render time of the virtual camera, transfer
#define CAPTURE_RETRIES   1

// ---------------------------------------------------------------------------
// Options (model/base/opts.h), and the actions each option is for

static const char rig_about[] =
    "actions:\n"
    "  status     every device with its identity and state (the camera: gain and its unit, firmware,\n"
    "             gamma, black level, and the automatics/gamma/LUT refl switched off at open)\n"
    "  home       home the turntable (the only device it opens)\n"
    "  move DEG   move the turntable to DEG (absolute; homes it first when needed; opens only the turntable)\n"
    "  identify   model, serial and firmware of every device\n"
    "  snap       a frame of each camera to a PNG (lamps switched off again afterwards)\n"
    "  serve      virtual rigs: keep the virtual camera up on its address until SIGINT/SIGTERM";

static const char rig_epilog[] =
    "Rig files: [camera] (or [camera NAME], one or more), [turntable], [lamp NAME], [lamps] sections, or\n"
    "[rig] backend = virtual (see rig/rig.h and examples/lab-rig.ini, examples/virtual-rig.ini);\n"
    "[camera] and [rig] also take packet_size (GevSCPSPacketSize, bytes) and packet_delay (GevSCPD,\n"
    "ticks) for GigE Vision. snap captures every camera at one angle and lamp state (--camera NAME: one).\n"
    "Opening a camera switches off its automatics (ExposureAuto, GainAuto, ... every *Auto*), gamma and\n"
    "LUT, or fails naming the feature; frames record what was done and the gain's unit.\n"
    "Angles in degrees (turntable frame: 0 at home, counter-clockwise seen from above).\n"
    "status and identify report every device, also when one does not open or answer (its DEVICE_error\n"
    "line; the exit status is then 1); --only opens and reports one kind (one device at a time at\n"
    "bring-up: --only camera, --only turntable, --only lamps).\n"
    "Ctrl-C during homing or a move stops the stage (a second Ctrl-C: at once), then ends refl.";

#define RIG_OPTS(_)                                                                                               \
    _("--rig", "RIG.ini", "the rig description file", true, NULL)                                                 \
    _("-o", "OUT.png", "snap: output image (16-bit grey PNG with metadata)", false, "snap")                        \
    _("--angle-deg", "DEG", "snap: move the turntable to DEG first (homes it first when needed)", false, "snap",   \
      .old = "--angle")                                                                                           \
    _("--lamps-on", "NAMES", "snap: lamps on during the frame: NAME,NAME,... | all | none (default none)", false,  \
      "snap", .old = "--lamps")                                                                                   \
    _("--exposure-us", "US", "snap: exposure time, us (default: the rig file's, else the camera's)", false, "snap") \
    _("--gain", "G", "snap: gain in the camera's unit (its GenICam <Unit>, recorded) (default: rig file / camera)", false, \
      "snap")                                                                                                     \
    _("--pixel-format", "F", "snap: Mono8 | Mono10 | Mono12 | Mono16 | Mono10p | Mono12p | ... (default: rig file / camera)", false, "snap")          \
    _("--sample", "NAME", "snap, serve (virtual rigs): put this sample of the truth file on the table", false,     \
      "snap serve")                                                                                               \
    _("--camera", "NAME", "snap: only this camera of the rig file, written to OUT.png (default all: one camera "     \
      "writes OUT.png, several OUT_NAME.png each)", false, "snap")                                                \
    _("--only", "KIND", "status, identify: open and report only this kind of device: camera, turntable or lamps "  \
      "(a comma list for more; default every device)", false, "status identify")

static bool word_in(const char *words, const char *w)
{
    size_t n = strlen(w);
    for (const char *p = words; (p = strstr(p, w)); p += n)
        if ((p == words || p[-1] == ' ') && (p[n] == 0 || p[n] == ' ')) return true;
    return false;
}

// The action and its arguments, checked: 0 or MODEL_CLI_USAGE (printed).
static int check_action(model_cli_t *c)
{
#define RIG_OPT_ACTIONS_(name, metavar, help, required, actions, ...) actions,
    static const char *const opt_actions[] = { RIG_OPTS(RIG_OPT_ACTIONS_) };
#undef RIG_OPT_ACTIONS_
    if (c->npositional < 1)
        return model_cli_error(c, "missing action: status, home, move DEG, identify, snap or serve");
    const char *action = c->positional[0];
    static const char *const actions[] = { "status", "home", "move", "identify", "snap", "serve" };
    bool known = false;
    for (size_t i = 0; i < sizeof actions / sizeof actions[0]; i++) known |= !strcmp(action, actions[i]);
    if (!known)
        return model_cli_error(c, "unknown action '%s': use status, home, move DEG, identify, snap or serve", action);
    int nargs = c->npositional - 1, want = !strcmp(action, "move") ? 1 : 0;
    if (nargs < want) return model_cli_error(c, "move needs the angle: refl rig --rig RIG move DEG");
    if (nargs > want) return model_cli_error(c, "unexpected argument '%s' after %s", c->positional[1 + want], action);
    for (int i = 0; i < c->nopts; i++)
        if (c->opts[i].given && opt_actions[i] && !word_in(opt_actions[i], action))
            return model_cli_error(c, "option %s is for %s only, not %s", c->opts[i].name, opt_actions[i], action);
    if (!strcmp(action, "snap") && !model_cli_value(c, "-o")) return model_cli_error(c, "snap needs -o OUT.png");
    return 0;
}

// --only camera|turntable|lamps (a comma list) -> RIG_DEVICE_* (absent: kept).
static int only_devices(model_cli_t *c, unsigned *devices)
{
    const char *v = model_cli_value(c, "--only");
    if (!v) return 0;
    static const struct { const char *word; unsigned kind; } kinds[] = {
        { "camera", RIG_DEVICE_CAMERAS }, { "cameras", RIG_DEVICE_CAMERAS }, { "turntable", RIG_DEVICE_TURNTABLE },
        { "lamps", RIG_DEVICE_LAMPS }, { "lamp", RIG_DEVICE_LAMPS } };
    gchar **words = g_strsplit(v, ",", -1);
    unsigned m = 0;
    int rc = 0;
    for (int i = 0; words[i] && !rc; i++) {
        const char *w = g_strstrip(words[i]);
        size_t k = 0;
        while (k < sizeof kinds / sizeof kinds[0] && strcmp(kinds[k].word, w)) k++;
        if (k == sizeof kinds / sizeof kinds[0])
            rc = model_cli_error(c, "option --only: '%s' is none of camera, turntable, lamps", w);
        else
            m |= kinds[k].kind;
    }
    g_strfreev(words);
    if (!rc) *devices = m;
    return rc;
}

// Angle: finite, within the wrappers' +-10000 deg.
static int parse_angle(model_cli_t *c, const char *what, const char *s, double *out)
{
    if (!model_parse_double(s, out))
        return model_cli_error(c, "%s: '%s' is not an angle in degrees", what, s);
    if (!(fabs(*out) <= 1e4)) return model_cli_error(c, "%s: %s deg is out of range (-10000..10000)", what, s);
    return 0;
}

// ---------------------------------------------------------------------------
// Helpers

// Time-outs from the motion profile, with margin (50 % + 5 s).
static double move_timeout_s(const rig_t *r, double delta_deg)
{
    double t = rig_motion_time_s(delta_deg, r->speed_deg_s, r->accel_deg_s2);
    if (!isfinite(t)) t = 120;   // profile unknown (stage model not in rig_stage_models)
    return 1.5 * t + 5;
}

static double home_timeout_s(const rig_t *r)
{
    double t = isfinite(r->home_time_s) ? r->home_time_s : 120;
    return 1.5 * t + 5;
}

// Ctrl-C during homing or a move: the stage stops first (a profiled stop; a
// second Ctrl-C: at once), then refl ends by SIGINT as anywhere else (the
// safety handler: lamps off). The signal handler cannot talk to the stage, so
// it only counts; the watched wait does the rest.
static volatile sig_atomic_t g_motion_sigint;
static void on_motion_sigint(int sig) { (void)sig; g_motion_sigint++; }

static void motion_progress(void *ctx, double elapsed_s, double angle_deg)
{
    const rig_t *r = ctx;
    char eta[64] = "";
    if (isfinite(r->home_time_s)) snprintf(eta, sizeof eta, " of up to %.0f s", r->home_time_s);
    fprintf(stderr, "refl rig: homing... %.0f s%s, at %.1f deg\n", elapsed_s, eta, angle_deg);
}

static int watched_motion(rig_t *r, bool home, double angle_deg, double timeout_s)
{
    char what[64];
    if (home) snprintf(what, sizeof what, "homing");
    else snprintf(what, sizeof what, "the move to %.4g deg", angle_deg);
    rig_turntable_watch_t w = { .interrupt = &g_motion_sigint, .what = what,
                                .stop_s = r->speed_deg_s / r->accel_deg_s2,
                                .progress = home ? motion_progress : NULL, .ctx = r, .period_s = 5 };
    struct sigaction sa = { .sa_handler = on_motion_sigint }, old;
    sigemptyset(&sa.sa_mask);
    g_motion_sigint = 0;
    sigaction(SIGINT, &sa, &old);
    int rc = home ? rig_turntable_start_home(r->turntable) : rig_turntable_start_move_abs_deg(r->turntable, angle_deg);
    if (!rc) rc = rig_turntable_wait_watched(r->turntable, timeout_s, &w);
    sigaction(SIGINT, &old, NULL);
    if (rc == RIG_ERR_INTERRUPTED) {
        fprintf(stderr, "refl rig: interrupted (SIGINT): %s\n", model_last_error());
        raise(SIGINT);   // ends refl, unless SIGINT is ignored (nohup): then an error
        rc = rig_fail(RIG_ERR_INTERRUPTED, "refl rig: %s", model_last_error());
    }
    return rc;
}

// Lamp names of a mask ("east,west", or "none").
static void lamp_names(const rig_lamps_t *l, uint32_t mask, char *out, size_t size)
{
    size_t n = 0;
    out[0] = 0;
    for (int i = 0; l && i < rig_lamps_count(l) && n < size; i++)
        if (mask & (1u << i)) n += (size_t)snprintf(out + n, size - n, "%s%s", n ? "," : "", rig_lamps_name(l, i));
    if (!out[0]) snprintf(out, size, "none");
}

// --lamps NAMES|all|none -> mask. Runtime error (exit 1) for names the rig does not have.
static int lamps_mask(const rig_t *r, const char *spec, uint32_t *mask)
{
    *mask = 0;
    if (!spec || !strcmp(spec, "none")) return 0;
    const rig_lamps_t *l = r->lamps;
    if (!strcmp(spec, "all")) {
        *mask = !l ? 0 : rig_lamps_count(l) >= 32 ? 0xffffffffu : ((uint32_t)1 << rig_lamps_count(l)) - 1;
        return 0;
    }
    char known[1024];
    int nl = rig_lamps_count(l);
    lamp_names(l, nl >= 32 ? 0xffffffffu : ((uint32_t)1 << nl) - 1, known, sizeof known);
    gchar **names = g_strsplit(spec, ",", -1);
    int rc = 0;
    for (int i = 0; names[i]; i++) {
        char *nm = g_strstrip(names[i]);
        int k = rig_lamps_find(l, nm);
        if (k < 0) {
            rc = rig_fail(RIG_ERR_INVALID, "refl rig: --lamps-on: the rig %s has no lamp '%s' (its lamps: %s)",
                          r->path, nm, known);
            break;
        }
        *mask |= 1u << k;
    }
    g_strfreev(names);
    return rc;
}

// The turntable at angle_deg, homing it first when needed.
static int move_to(rig_t *r, double angle_deg)
{
    rig_turntable_status_t st;
    int rc = rig_turntable_status(r->turntable, &st);
    if (rc) return rc;
    if (!st.homed) {
        fprintf(stderr, "refl rig: %s is not homed: homing first\n", rig_turntable_name(r->turntable));
        if ((rc = watched_motion(r, true, 0, home_timeout_s(r)))) return rc;
        if ((rc = rig_turntable_status(r->turntable, &st))) return rc;
    }
    fprintf(stderr, "refl rig: moving %s from %.3f to %.3f deg\n", rig_turntable_name(r->turntable), st.angle_deg,
            angle_deg);
    return watched_motion(r, false, angle_deg, move_timeout_s(r, angle_deg - st.angle_deg));
}

static int need_turntable(const rig_t *r, const char *action)
{
    if (r->turntable) return 0;
    return rig_fail(RIG_ERR_NO_DEVICE, "refl rig %s: the rig %s has no turntable: add a [turntable] section",
                    action, r->path);
}

static const char *yes_no(bool b) { return b ? "yes" : "no"; }

// ---------------------------------------------------------------------------
// Actions

// The devices that failed, for the closing message: "the turntable, the
// camera left and the lamps did not open (their DEVICE_error lines above)".
typedef struct {
    char what[RIG_CAMERAS_MAX + 2][48];   // "the turntable", "the camera left", ...
    char line[32];                        // the first one's DEVICE_error line
    int  n, unopened;
} failed_t;

// The cameras of the rig file that were asked for: open or not.
static int cameras_asked(const rig_t *r)
{
    int n = r->ncameras;
    for (int i = 0; i < r->nfailed; i++) n += r->failed[i].kind == RIG_DEVICE_CAMERAS;
    return n;
}

static void failed_add(failed_t *f, const rig_t *r, const char *kind, const char *camera, bool unopened)
{
    if (f->n >= (int)(sizeof f->what / sizeof f->what[0])) return;
    if (camera && cameras_asked(r) > 1) snprintf(f->what[f->n], sizeof f->what[0], "the camera %s", camera);
    else snprintf(f->what[f->n], sizeof f->what[0], "the %s", kind);
    if (!f->n) snprintf(f->line, sizeof f->line, "%s_error", kind);
    f->n++;
    f->unopened += unopened;
}

// The closing message of status and identify when a device failed; rc unchanged.
static int failed_report(const failed_t *f, const char *action, int rc)
{
    if (!f->n) return rc;
    char list[600] = "";
    for (int i = 0; i < f->n; i++)
        snprintf(list + strlen(list), sizeof list - strlen(list), "%s%s", !i ? "" : i == f->n - 1 ? " and " : ", ",
                 f->what[i]);
    const char *verb = f->unopened == f->n ? "did not open" : f->unopened ? "did not open or answer" : "did not answer";
    if (f->n == 1) rig_fail(rc, "refl rig %s: %s %s (its %s line above)", action, list, verb, f->line);
    else rig_fail(rc, "refl rig %s: %s %s (their DEVICE_error lines above)", action, list, verb);
    return rc;
}

// The device of this kind that did not open (rig_open_with keep_going), or NULL.
static const rig_open_failure_t *open_failure(const rig_t *r, unsigned kind)
{
    for (int i = 0; i < r->nfailed; i++)
        if (r->failed[i].kind == kind) return &r->failed[i];
    return NULL;
}

// The cameras that did not open and come before open camera i (i = ncameras:
// those after the last), each as "camera_name", "camera: not open",
// "camera_error"; counted in *f. RIG_ERR_NO_DEVICE when there was one, else rc.
static int report_unopened_cameras(const rig_t *r, int i, failed_t *f, int rc)
{
    for (int k = 0; k < r->nfailed; k++) {
        const rig_open_failure_t *x = &r->failed[k];
        if (x->kind != RIG_DEVICE_CAMERAS || x->before != i) continue;
        printf("camera_name: %s\ncamera: not open\ncamera_error: %s\n", x->name, x->error);
        failed_add(f, r, "camera", x->name, true);
        if (!rc) rc = RIG_ERR_NO_DEVICE;
    }
    return rc;
}

// The lines of a kind that did not open ("turntable: not open",
// "turntable_error: ..."): true when it did not.
static bool report_unopened(const rig_t *r, unsigned kind, const char *name, failed_t *f, int *rc)
{
    const rig_open_failure_t *x = open_failure(r, kind);
    if (!x) return false;
    printf("%s: not open\n%s_error: %s\n", name, name, x->error);
    failed_add(f, r, name, NULL, true);
    if (!*rc) *rc = RIG_ERR_NO_DEVICE;
    return true;
}

// One camera's lines of `refl rig status`: 0 or its error code (its camera_error line printed).
static int status_camera(rig_t *r, int i)
{
    rig_camera_t *c = r->cameras[i];
    rig_frame_meta_t m;
    printf("camera_name: %s\n", r->camera_names[i]);
    int e = rig_camera_settings(c, &m);
    if (e) {
        printf("camera: %s\ncamera_error: %s\n", rig_camera_name(c), model_last_error());
        return e;
    }
    printf("camera: %s\ncamera_vendor: %s\ncamera_model: %s\ncamera_serial: %s\n"
           "camera_pixel_format: %s (%d bits)\ncamera_region: %d x %d at (%d, %d)\n"
           "camera_exposure_us: %.6g\ncamera_gain: %.6g %s\n",
           rig_camera_name(c), m.vendor, m.model, m.serial, m.pixel_format, m.bits, m.width, m.height,
           m.offset_x, m.offset_y, m.exposure_us, m.gain, m.gain_unit);
    if (isfinite(m.temperature_c)) printf("camera_temperature_c: %.2f\n", m.temperature_c);
    else printf("camera_temperature_c: none (the camera has no sensor)\n");
    printf("camera_firmware: %s\ncamera_gamma: %.6g\n", m.firmware[0] ? m.firmware : "none (not stated)", m.gamma);
    if (isfinite(m.black_level)) printf("camera_black_level: %.10g\n", m.black_level);
    else printf("camera_black_level: none (the camera has no BlackLevel)\n");
    printf("camera_settings: %s\n", m.camera_settings);
    return 0;
}

static void status_turntable(rig_t *r, failed_t *f, int *rc)
{
    rig_turntable_status_t st;
    int e;
    if (report_unopened(r, RIG_DEVICE_TURNTABLE, "turntable", f, rc)) return;
    if (!r->turntable) {
        printf("turntable: none\n");
    } else if ((e = rig_turntable_status(r->turntable, &st))) {
        printf("turntable: %s\nturntable_error: %s\n", rig_turntable_name(r->turntable), model_last_error());
        failed_add(f, r, "turntable", NULL, false);
        if (!*rc) *rc = e;
    } else {
        printf("turntable: %s\nturntable_angle_deg: %.4f\nturntable_homed: %s\nturntable_moving: %s\n",
               rig_turntable_name(r->turntable), st.angle_deg, yes_no(st.homed), yes_no(st.moving || st.homing));
        if (st.motion_error || st.limit_fwd || st.limit_rev)
            printf("turntable_faults: %s%s%s\n", st.motion_error ? "motion-error " : "",
                   st.limit_fwd ? "limit-forward " : "", st.limit_rev ? "limit-reverse" : "");
    }
}

// Every device of the kinds asked for is reported, also after one fails or
// did not open ("DEVICE_error: ..."); the first failure's code is returned.
// Each camera is a block of lines beginning with its camera_name line.
int rig_cmd_status(rig_t *r)
{
    int rc = 0, e;
    failed_t f = { .n = 0 };
    unsigned dev = r->devices ? r->devices : RIG_DEVICE_ALL;
    printf("rig_file: %s\nrig_sha256: %s\n", r->path, r->sha256);
    if (r->virt)
        printf("rig_backend: virtual (truth %s, sample %s)\n", rig_virtual_truth_path(r->virt),
               rig_virtual_sample(r->virt));
    else
        printf("rig_backend: devices\n");
    if (dev & RIG_DEVICE_TURNTABLE) status_turntable(r, &f, &rc);
    if ((dev & RIG_DEVICE_LAMPS) && !report_unopened(r, RIG_DEVICE_LAMPS, "lamps", &f, &rc)) {
        if (r->lamps && rig_lamps_count(r->lamps) > 0) {
            for (int i = 0; i < rig_lamps_count(r->lamps); i++)
                printf("lamp %s: %s (%s)\n", rig_lamps_name(r->lamps, i),
                       (rig_lamps_on_mask(r->lamps) >> i) & 1 ? "on" : "off", rig_lamps_backend(r->lamps));
        } else {
            printf("lamps: none\n");
        }
    }
    if (!(dev & RIG_DEVICE_CAMERAS)) return failed_report(&f, "status", rc);
    int ncam = cameras_asked(r);
    if (ncam == 0) printf("camera: none\n");
    else if (ncam > 1) printf("cameras: %d\n", ncam);
    for (int i = 0; i <= r->ncameras; i++) {
        rc = report_unopened_cameras(r, i, &f, rc);
        if (i == r->ncameras || !(e = status_camera(r, i))) continue;
        failed_add(&f, r, "camera", r->camera_names[i], false);
        if (!rc) rc = e;
    }
    return failed_report(&f, "status", rc);
}

static void identify_turntable(rig_t *r, failed_t *f, int *rc)
{
    rig_turntable_info_t in;
    int e;
    if (report_unopened(r, RIG_DEVICE_TURNTABLE, "turntable", f, rc)) return;
    if (!r->turntable) {
        printf("turntable: none\n");
    } else if ((e = rig_turntable_info(r->turntable, &in))) {
        printf("turntable: %s\nturntable_error: %s\n", rig_turntable_name(r->turntable), model_last_error());
        failed_add(f, r, "turntable", NULL, false);
        if (!*rc) *rc = e;
    } else {
        printf("turntable: %s\nturntable_backend: %s\nturntable_model: %s\nturntable_serial: %s\n"
               "turntable_firmware: %s\nturntable_counts_per_deg: %.6g\n",
               rig_turntable_name(r->turntable), rig_turntable_backend(r->turntable), in.model, in.serial,
               in.firmware, in.counts_per_deg);
    }
}

static void identify_lamps(rig_t *r, failed_t *f, int *rc)
{
    if (report_unopened(r, RIG_DEVICE_LAMPS, "lamps", f, rc)) return;
    if (!r->lamps || rig_lamps_count(r->lamps) == 0) {
        printf("lamps: none\n");
        return;
    }
    for (int i = 0; i < rig_lamps_count(r->lamps); i++) {
        const rig_lamp_line_t *a = rig_lamps_line(r->lamps, i);
        if (!strcmp(rig_lamps_backend(r->lamps), "gpiod"))
            printf("lamp %s: gpiod %s line %u %s, warm-up %g ms, settle %g ms\n", a->name, a->chip, a->line,
                   a->active_low ? "active-low" : "active-high", a->warmup_ms, a->settle_ms);
        else
            printf("lamp %s: %s%s, warm-up %g ms, settle %g ms\n", a->name, rig_lamps_backend(r->lamps),
                   r->virt ? " (virtual rig)" : "", a->warmup_ms, a->settle_ms);
    }
}

// Model, serial and firmware of every device of the kinds asked for, also
// after one fails or did not open (its DEVICE_error line); the first failure's code.
static int do_identify(rig_t *r)
{
    int rc = 0, e;
    failed_t f = { .n = 0 };
    unsigned dev = r->devices ? r->devices : RIG_DEVICE_ALL;
    printf("rig_file: %s\nrig_sha256: %s\n", r->path, r->sha256);
    if (dev & RIG_DEVICE_TURNTABLE) identify_turntable(r, &f, &rc);
    if (dev & RIG_DEVICE_CAMERAS) {
        if (r->ncameras == 0 && !open_failure(r, RIG_DEVICE_CAMERAS)) printf("camera: none\n");
        for (int i = 0; i <= r->ncameras; i++) {
            rc = report_unopened_cameras(r, i, &f, rc);
            if (i == r->ncameras) continue;
            rig_camera_t *c = r->cameras[i];
            rig_frame_meta_t m;
            printf("camera_name: %s\ncamera: %s\ncamera_backend: %s\n", r->camera_names[i], rig_camera_name(c),
                   rig_camera_backend(c));
            if ((e = rig_camera_settings(c, &m))) {
                printf("camera_error: %s\n", model_last_error());
                failed_add(&f, r, "camera", r->camera_names[i], false);
                if (!rc) rc = e;
                continue;
            }
            printf("camera_vendor: %s\ncamera_model: %s\ncamera_serial: %s\ncamera_firmware: %s\n"
                   "camera_sensor_region: %d x %d\n", m.vendor, m.model, m.serial,
                   m.firmware[0] ? m.firmware : "none (not stated)", m.width, m.height);
        }
    }
    if (dev & RIG_DEVICE_LAMPS) identify_lamps(r, &f, &rc);
    if (r->virt)
        printf("virtual_truth: %s\nvirtual_sample: %s\nvirtual_camera_address: %s\n",
               rig_virtual_truth_path(r->virt), rig_virtual_sample(r->virt), rig_virtual_camera_address(r->virt));
    return failed_report(&f, "identify", rc);
}

typedef struct {
    bool        have_angle;
    double      angle_deg;
    const char *lamps;
    double      exposure_us, gain;     // NAN: keep
    const char *pixel_format;          // NULL: keep
    const char *out;
    const char *camera;                // NULL or "all": every camera
} snap_t;

// The file a snap of camera i writes: -o itself for one camera (--camera
// NAME, or a rig of one), else OUT_NAME.png.
static char *snap_path(const rig_t *r, const snap_t *o, int i)
{
    bool one = r->ncameras == 1 || (o->camera && strcmp(o->camera, "all"));
    if (one) return g_strdup(o->out);
    size_t n = strlen(o->out) - 4;
    return g_strdup_printf("%.*s_%s%s", (int)n, o->out, r->camera_names[i], o->out + n);
}

// One snapped frame of camera i to its PNG with metadata, and its summary on stdout.
static int snap_write(rig_t *r, int i, const snap_t *o, const rig_frame_t *f, const rig_turntable_status_t *st,
                      const char *on_names, const char *cmdline)
{
    const rig_frame_meta_t *m = &f->meta;
    model_meta_t *meta = model_meta_new();
    char date[40], t_frame[40];
    model_utc_text(model_realtime_s(), date);
    model_utc_text(m->system_time_s, t_frame);
    unsigned maxv = m->bits >= 16 ? 65535u : (1u << m->bits) - 1;
    model_meta_add(meta, "Software", "refl %s (refl rig snap)", REFL_VERSION);
    model_meta_add(meta, "units", "DN, the camera's pixel format: %s values 0..%u", m->pixel_format, maxv);
    model_meta_add(meta, "image", "one camera frame as delivered (no processing); 16-bit grey PNG holding the values "
             "unscaled");
    model_meta_add(meta, "pixel_convention", "row-major, (0,0) is the top-left pixel of the region, x to the right, "
             "y down");
    model_meta_add(meta, "camera", "%s", rig_camera_name(r->cameras[i]));
    model_meta_add(meta, "camera_name", "%s (the rig file's camera)", r->camera_names[i]);
    model_meta_add(meta, "camera_vendor", "%s", m->vendor);
    model_meta_add(meta, "camera_model", "%s", m->model);
    model_meta_add(meta, "camera_serial", "%s", m->serial);
    model_meta_add(meta, "frame_id", "%llu", (unsigned long long)m->frame_id);
    model_meta_add(meta, "frame_timestamp_ns", "%llu (the camera's clock)", (unsigned long long)m->timestamp_ns);
    model_meta_add(meta, "frame_time_utc", "%s (host clock when the frame arrived)", t_frame);
    model_meta_add(meta, "exposure_us", "%.10g", m->exposure_us);
    model_meta_add(meta, "gain", "%.10g", m->gain);
    model_meta_add(meta, "gain_unit", "%s", m->gain_unit);   // GenICam <Unit> of the gain; raw: none stated
    model_meta_add(meta, "gamma", "%.6g (in effect)", m->gamma);
    if (isfinite(m->black_level)) model_meta_add(meta, "black_level", "%.10g", m->black_level);
    if (m->firmware[0]) model_meta_add(meta, "camera_firmware", "%s", m->firmware);
    model_meta_add(meta, "camera_settings", "%s", m->camera_settings);
    model_meta_add(meta, "pixel_format", "%s (%d significant bits)", m->pixel_format, m->bits);
    model_meta_add(meta, "region", "%d x %d at (%d, %d) on the sensor", m->width, m->height, m->offset_x, m->offset_y);
    if (isfinite(m->temperature_c)) model_meta_add(meta, "temperature_c", "%.3f", m->temperature_c);
    else model_meta_add(meta, "temperature_c", "none (the camera has no temperature sensor)");
    if (o->have_angle) model_meta_add(meta, "turntable_commanded_deg", "%.10g", o->angle_deg);
    else model_meta_add(meta, "turntable_commanded_deg", "none (not moved by this command)");
    if (r->turntable) model_meta_add(meta, "turntable_measured_deg", "%.6f", st->angle_deg);
    else model_meta_add(meta, "turntable_measured_deg", "none (no turntable)");
    model_meta_add(meta, "turntable_frame", "degrees, 0 at home, positive counter-clockwise seen from above (about +z "
             "of the rig frame)");
    model_meta_add(meta, "lamps_on", "%s", on_names);
    model_meta_add(meta, "rig_file", "%s", r->path);
    model_meta_add(meta, "rig_sha256", "%s", r->sha256);
    if (r->virt) {
        char sha[65] = "";
        const char *truth = rig_virtual_truth_path(r->virt);
        bool q = model_error_quiet_thread(true);
        if (!model_sha256_file(truth, sha)) snprintf(sha, sizeof sha, "unreadable");
        model_error_quiet_thread(q);
        model_meta_add(meta, "virtual_truth", "%s", truth);
        model_meta_add(meta, "virtual_truth_sha256", "%s", sha);
        model_meta_add(meta, "virtual_sample", "%s", rig_virtual_sample(r->virt));
    }
    model_meta_add(meta, "refl_version", "%s", REFL_VERSION);
    model_meta_add(meta, "date_utc", "%s", date);
    model_meta_add(meta, "command_line", "%s", cmdline);

    // model_png16_write writes a temporary file and renames it into place.
    char *path = snap_path(r, o, i);
    bool ok = model_png16_write(path, m->width, m->height, f->pix, model_meta_list(meta));
    model_meta_free(meta);
    if (!ok) {
        g_free(path);
        return RIG_ERR_IO;
    }
    size_t n = (size_t)m->width * (size_t)m->height;
    double sum = 0;
    unsigned lo = 65535, hi = 0;
    for (size_t k = 0; k < n; k++) {
        unsigned v = f->pix[k];
        sum += v;
        if (v < lo) lo = v;
        if (v > hi) hi = v;
    }
    printf("refl rig snap: wrote %s\n", path);
    g_free(path);
    if (r->ncameras > 1) printf("  camera %s\n", r->camera_names[i]);
    printf("  frame %d x %d %s, id %llu, exposure %.6g us, gain %.6g\n", m->width, m->height, m->pixel_format,
           (unsigned long long)m->frame_id, m->exposure_us, m->gain);
    if (r->turntable) printf("  turntable %.4f deg", st->angle_deg);
    else printf("  no turntable");
    if (o->have_angle) printf(" (commanded %.6g)", o->angle_deg);
    printf(", lamps on: %s\n", on_names);
    printf("  pixels (DN): min %u  mean %.1f  max %u\n", lo, n ? sum / (double)n : 0.0, hi);
    return 0;
}

// The snap's settings on camera i, then its frame (the lamps already on).
static int snap_capture(rig_t *r, int i, const snap_t *o, rig_frame_t *f)
{
    rig_camera_t *c = r->cameras[i];
    int rc;
    if (o->pixel_format && (rc = rig_camera_set_pixel_format(c, o->pixel_format))) return rc;
    if (isfinite(o->exposure_us) && (rc = rig_camera_set_exposure_us(c, o->exposure_us))) return rc;
    if (isfinite(o->gain) && (rc = rig_camera_set_gain(c, o->gain))) return rc;
    rig_frame_meta_t set;
    if ((rc = rig_camera_settings(c, &set))) return rc;
    fprintf(stderr, "refl rig: capturing%s%s (%s, exposure %.6g us, gain %.6g)\n", r->ncameras > 1 ? " camera " : "",
            r->ncameras > 1 ? r->camera_names[i] : "", set.pixel_format, set.exposure_us, set.gain);
    return rig_camera_capture(c, CAPTURE_TIMEOUT_S + 2e-6 * set.exposure_us, CAPTURE_RETRIES, f);
}

// Every selected camera captures at one turntable angle and lamp state, one
// after the other (file order), the lamps on throughout; then the files.
static int do_snap(rig_t *r, const snap_t *o, const char *cmdline)
{
    int rc = 0;
    rig_frame_t f[RIG_CAMERAS_MAX] = { 0 };
    uint32_t mask = 0;
    int first = 0, last = r->ncameras - 1;
    if (!r->camera) {
        rc = rig_fail(RIG_ERR_NO_DEVICE, "refl rig snap: the rig %s has no camera: add a [camera] section (or use "
                      "[rig] backend = virtual)", r->path);
        goto done;
    }
    if (o->camera && strcmp(o->camera, "all")) {
        if ((first = last = rig_camera_find(r, o->camera)) < 0) {
            char names[RIG_CAMERAS_MAX * RIG_CAMERA_NAME_MAX + 16] = "";
            for (int i = 0; i < r->ncameras; i++)
                snprintf(names + strlen(names), sizeof names - strlen(names), "%s%s", i ? ", " : "",
                         r->camera_names[i]);
            rc = rig_fail(RIG_ERR_INVALID, "refl rig snap: --camera: the rig %s has no camera '%s' (its cameras: "
                          "%s)", r->path, o->camera, names);
            goto done;
        }
    }
    if ((rc = lamps_mask(r, o->lamps, &mask))) goto done;
    if (mask && !r->lamps) {
        rc = rig_fail(RIG_ERR_NO_DEVICE, "refl rig snap: the rig %s has no lamps", r->path);
        goto done;
    }
    if (o->have_angle) {
        if ((rc = need_turntable(r, "snap --angle-deg")) || (rc = move_to(r, o->angle_deg))) goto done;
    }
    char on_names[1100];
    lamp_names(r->lamps, mask, on_names, sizeof on_names);
    if (r->lamps) {
        fprintf(stderr, "refl rig: lamps on: %s\n", on_names);
        if ((rc = rig_lamps_set(r->lamps, mask))) goto done;
    }
    for (int i = first; i <= last && !rc; i++) rc = snap_capture(r, i, o, &f[i]);
    int off_rc = r->lamps ? rig_lamps_all_off(r->lamps) : 0;
    if (rc) goto done;
    if ((rc = off_rc)) goto done;

    rig_turntable_status_t st = { 0 };
    if (r->turntable && (rc = rig_turntable_status(r->turntable, &st))) goto done;
    for (int i = first; i <= last && !rc; i++) rc = snap_write(r, i, o, &f[i], &st, on_names, cmdline);
done:
    if (r->lamps && rig_lamps_on_mask(r->lamps)) {
        bool q = model_error_quiet_thread(true);
        rig_lamps_all_off(r->lamps);
        model_error_quiet_thread(q);
    }
    for (int i = 0; i < RIG_CAMERAS_MAX; i++) rig_frame_free(&f[i]);
    return rc;
}

// snap -o FILE, before the rig is opened: FILE is not a directory, its
// directory exists and this process may write there.
static int check_out_path(const char *out)
{
    struct stat st;
    if (stat(out, &st) == 0 && S_ISDIR(st.st_mode))
        return rig_fail(RIG_ERR_INVALID, "refl rig snap: -o %s is a directory: name the PNG file to write", out);
    char *dir = g_path_get_dirname(out);
    int rc = 0;
    if (stat(dir, &st) != 0)
        rc = rig_fail(RIG_ERR_IO, "refl rig snap: -o %s: the directory %s does not exist (%s): create it first", out,
                      dir, strerror(errno));
    else if (!S_ISDIR(st.st_mode))
        rc = rig_fail(RIG_ERR_IO, "refl rig snap: -o %s: %s is not a directory", out, dir);
    else if (access(dir, W_OK | X_OK) != 0)
        rc = rig_fail(RIG_ERR_IO, "refl rig snap: -o %s: cannot write in the directory %s (%s)", out, dir,
                      strerror(errno));
    g_free(dir);
    return rc;
}

// True when the rig file is a virtual rig (a [rig] section); errors are left
// to rig_open.
static bool file_is_virtual(const char *path, bool *readable)
{
    bool q = model_error_quiet_thread(true);
    model_ini_t *ini = model_ini_load(path);
    model_error_quiet_thread(q);
    *readable = ini != NULL;
    bool v = false;
    for (int i = 0; ini && i < ini->nsections; i++) v |= !strcmp(ini->sections[i], "rig");
    model_ini_free(ini);
    return v;
}

// ---------------------------------------------------------------------------

// snap's options, checked: 0 or MODEL_CLI_USAGE / 1 (printed).
static int snap_options(model_cli_t *c, snap_t *so)
{
    int rc;
    so->out = model_cli_value(c, "-o");
    so->lamps = model_cli_value(c, "--lamps-on");
    so->pixel_format = model_cli_value(c, "--pixel-format");
    so->camera = model_cli_value(c, "--camera");
    size_t n = strlen(so->out);
    if (n < 4 || strcasecmp(so->out + n - 4, ".png"))
        return model_cli_error(c, "option -o: '%s' must end in .png (16-bit grey PNG)", so->out);
    if ((rc = check_out_path(so->out))) return 1;
    if (model_cli_value(c, "--angle-deg")) {
        so->have_angle = true;
        if ((rc = parse_angle(c, "option --angle-deg", model_cli_value(c, "--angle-deg"), &so->angle_deg))) return rc;
    }
    if ((rc = model_cli_double(c, "--exposure-us", &so->exposure_us, 0, true, 1e8, "0 < US <= 1e8")) ||
        (rc = model_cli_double(c, "--gain", &so->gain, -100, false, 100, "-100..100")))
        return rc;
    rig_pixfmt_t pf;
    if (so->pixel_format && !rig_pixfmt_from_name(so->pixel_format, &pf))
        return model_cli_error(c, "option --pixel-format: '%s' is not Mono8, Mono10, Mono12, Mono16, Mono10p, "
                               "Mono12p, Mono10Packed or Mono12Packed", so->pixel_format);
    if (so->lamps) {
        gchar **names = g_strsplit(so->lamps, ",", -1);
        bool empty = false;
        for (int i = 0; names[i]; i++) empty |= !*g_strstrip(names[i]);
        g_strfreev(names);
        if (empty) return model_cli_error(c, "option --lamps-on: '%s' has an empty lamp name", so->lamps);
    }
    return 0;
}

int rig_cmd(int argc, char **argv)
{
#define RIG_OPT_(name, metavar, help, required, actions, ...)                                                    \
    MODEL_OPT_VALUE(name, metavar, help, required, .alias = !strcmp(name, "-o") ? "--out" : NULL, ##__VA_ARGS__),
    model_opt_t opts[] = { RIG_OPTS(RIG_OPT_) };
#undef RIG_OPT_
    model_cli_t c = { .cmd = "rig", .synopsis = "ACTION [DEG]", .about = rig_about,
                      .epilog = rig_epilog, .opts = opts, .nopts = MODEL_NOPTS(opts), .min_positional = 0,
                      .max_positional = 5, .numbers_positional = true };
    int rc = model_cli_parse(&c, argc, argv);
    if (rc != MODEL_CLI_OK) return rc == MODEL_CLI_HELP ? 0 : rc;
    if ((rc = check_action(&c))) return rc;
    const char *rig_path = model_cli_value(&c, "--rig"), *action = c.positional[0];
    // the devices each action opens: home and move the turntable alone, --only one kind
    rig_open_opts_t open = { .devices = RIG_DEVICE_ALL };
    if (!strcmp(action, "home") || !strcmp(action, "move")) open.devices = RIG_DEVICE_TURNTABLE;
    if (!strcmp(action, "status") || !strcmp(action, "identify")) open.keep_going = true;
    if ((rc = only_devices(&c, &open.devices))) return rc;
    double move_deg = 0;
    snap_t so = { .exposure_us = NAN, .gain = NAN };
    if (!strcmp(action, "move") && (rc = parse_angle(&c, "move", c.positional[1], &move_deg))) return rc;
    if (!strcmp(action, "snap") && (rc = snap_options(&c, &so))) return rc;
    bool serve = !strcmp(action, "serve");
    sigset_t stop_set;
    sigemptyset(&stop_set);
    if (serve) {
        bool readable;
        if (!file_is_virtual(rig_path, &readable) && readable) {
            rig_fail(RIG_ERR_NOT_SUPPORTED, "refl rig serve: %s is not a virtual rig: serve keeps a virtual rig's "
                     "camera up ([rig] backend = virtual, see examples/virtual-rig.ini); a real camera serves "
                     "itself", rig_path);
            return 1;
        }
        // Blocked in every thread (they inherit the mask): sigwait below takes them.
        sigaddset(&stop_set, SIGINT);
        sigaddset(&stop_set, SIGTERM);
        sigaddset(&stop_set, SIGHUP);
        pthread_sigmask(SIG_BLOCK, &stop_set, NULL);
    }

    char *cmdline = model_command_line(argc, argv);
    rig_t *r = NULL;
    fprintf(stderr, "refl rig: opening %s\n", rig_path);
    if ((rc = rig_open_with(&r, rig_path, &open))) goto done;
    const char *sample = model_cli_value(&c, "--sample");
    if (sample) {
        if (!r->virt) {
            rc = rig_fail(RIG_ERR_NOT_SUPPORTED, "refl rig: --sample: %s is not a virtual rig; put the sample on "
                          "the table by hand", rig_path);
            goto done;
        }
        if ((rc = rig_virtual_set_sample(r->virt, sample))) goto done;
    }

    if (!strcmp(action, "status")) {
        rc = rig_cmd_status(r);
    } else if (!strcmp(action, "identify")) {
        rc = do_identify(r);
    } else if (!strcmp(action, "home")) {
        if (!(rc = need_turntable(r, "home"))) {
            fprintf(stderr, "refl rig: homing %s\n", rig_turntable_name(r->turntable));
            rc = watched_motion(r, true, 0, home_timeout_s(r));
        }
        rig_turntable_status_t st;
        if (!rc && !(rc = rig_turntable_status(r->turntable, &st)))
            printf("turntable_angle_deg: %.4f\nturntable_homed: %s\n", st.angle_deg, yes_no(st.homed));
    } else if (!strcmp(action, "move")) {
        rig_turntable_status_t st;
        if (!(rc = need_turntable(r, "move")) && !(rc = move_to(r, move_deg)) &&
            !(rc = rig_turntable_status(r->turntable, &st)))
            printf("turntable_commanded_deg: %.10g\nturntable_angle_deg: %.4f\n", move_deg, st.angle_deg);
    } else if (!strcmp(action, "snap")) {
        rc = do_snap(r, &so, cmdline);
    } else if (!strncmp(rig_virtual_camera_address(r->virt), "inprocess:", 10)) {   // serve
        rc = rig_fail(RIG_ERR_NOT_SUPPORTED, "refl rig serve: %s serves its camera in-process ([rig] serve = "
                      "inprocess), where no other program can reach it; write serve = gige to serve it on 127.0.0.1",
                      rig_path);
    } else {   // serve
        // The client connection rig_open made would hold the camera's control
        // channel: let other clients have it.
        for (int i = 0; i < r->ncameras; i++) rig_camera_close(r->cameras[i]);
        r->camera = NULL;
        r->ncameras = 0;
        printf("address: %s\nsample: %s\n", rig_virtual_camera_address(r->virt), rig_virtual_sample(r->virt));
        fflush(stdout);
        fprintf(stderr, "refl rig: serving the virtual camera at %s; stop with Ctrl-C (SIGINT) or SIGTERM\n",
                rig_virtual_camera_address(r->virt));
        int sig = 0;
        while (sigwait(&stop_set, &sig) != 0) {
        }
        fprintf(stderr, "refl rig: %s: stopping\n", strsignal(sig));
    }
done:
    rig_close(r);
    g_free(cmdline);
    if (rc) return 1;
    fflush(stdout);
    return 0;
}
