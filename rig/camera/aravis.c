// rig/camera/aravis.c — cameras through Aravis (GigE Vision, USB3 Vision); the
// rig_camera_* wrappers are in rig/camera/camera.c.
//
// One frame per software trigger: TriggerMode On, TriggerSource Software on the
// FrameStart selector, AcquisitionMode Continuous; the stream (a small pool of
// buffers) is started at the first capture and restarted after a change of
// pixel format or region (the payload size changes). Exposure and gain are
// read back after each change and recorded with every frame. A camera handle is
// used by one thread at a time.
//
// Each capture attempt first recycles frames still queued (they answer earlier
// triggers), then triggers and waits timeout_s. A frame that answers a timed-out
// attempt but arrives during the next one would be taken for that one: choose
// timeout_s well above exposure + transfer time (a lost frame never arrives).
// Frame ids: GVSP 1.x block ids are 16 bits (1..65535, then 1 again); they are
// unwrapped into a 64-bit count that keeps increasing.
//
// "inprocess:SERIAL" opens the in-process virtual camera of rig/virtual/gv_camera.h
// (an ArvFakeDevice; arv_camera_new_with_device, no discovery, no network):
// the same code path, except that Aravis reports a received size of 0 for
// its buffers (the payload we allocated is used) and that a server that
// stopped makes calls fail with RIG_ERR_DISCONNECTED.
#define _GNU_SOURCE
#include <arpa/inet.h>
#include <arv.h>
#include <math.h>
#include <stdarg.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "rig/virtual/gv_camera.h"
#include "rig/internal.h"
#include "rig/camera/pixfmt.h"

#define N_BUFFERS 4

typedef struct {
    ArvCamera  *cam;
    ArvDevice  *dev;                 // owned by cam
    ArvStream  *stream;              // NULL until the first capture
    gulong      lost_handler;
    atomic_bool control_lost;        // set from Aravis's heartbeat thread
    bool        disconnected;        // a request went unanswered: do not wait on it again
    bool        acquiring;
    const void *inprocess_dev;       // in-process: the server's device (identity only; cam holds it)
    guint       payload;             // bytes per buffer of the current stream
    char        id[64];
    char        vendor[64], model[64], serial[64];
    bool        has_temperature;
    bool        has_gain;
    double      exposure_us, gain;   // as read back from the camera
    // Radiometric state (read back at open and after a change; see switch_off_automatics)
    char        gain_unit[16];
    double      black_level, gamma;
    char        firmware[64];
    char        settings[512];
    bool        settings_full;
    bool        have_last_id;
    guint64     last_raw_id;
    uint64_t    frame_id;
    // Triggers whose frames may still come (a time-out leaves its frame on the
    // way), until pending_until (monotonic s), and the last frame id seen
    // (kept or recycled): a frame whose id comes before the latest trigger's
    // is an earlier trigger's, late.
    int         pending;
    double      pending_until;
    bool        have_seen_id;
    guint64     seen_id;
} aravis_cam_t;

static aravis_cam_t *impl_of(rig_camera_t *c) { return c->impl; }

static double now_realtime_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_REALTIME, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

static bool is_ipv4_address(const char *id)
{
    struct in_addr a;
    return inet_pton(AF_INET, id, &a) == 1;
}

// Report a GError (consumed) as a rig error naming the camera and what failed.
static int fail_gerror(rig_camera_t *c, GError **e, const char *what)
{
    aravis_cam_t *a = impl_of(c);
    int code = RIG_ERR_IO;
    const char *hint = "";
    const char *msg = (e && *e) ? (*e)->message : "unknown error";
    if (atomic_load(&a->control_lost)) {
        code = RIG_ERR_DISCONNECTED;
        hint = "; the camera stopped answering heartbeats: check power, cable and network, then reopen it";
    } else if (e && *e && (*e)->domain == ARV_DEVICE_ERROR) {
        switch ((*e)->code) {
        case ARV_DEVICE_ERROR_TIMEOUT:
        case ARV_DEVICE_ERROR_NOT_CONNECTED:
        case ARV_DEVICE_ERROR_TRANSFER_ERROR:
            code = RIG_ERR_DISCONNECTED;
            hint = "; the camera does not answer: check power, cable and network, then reopen it";
            break;
        case ARV_DEVICE_ERROR_NOT_CONTROLLER:
        case ARV_DEVICE_ERROR_PROTOCOL_ERROR_ACCESS_DENIED:
        case ARV_DEVICE_ERROR_PROTOCOL_ERROR_BUSY:
            code = RIG_ERR_BUSY;
            hint = "; another program may control the camera: close it";
            break;
        case ARV_DEVICE_ERROR_FEATURE_NOT_FOUND:
        case ARV_DEVICE_ERROR_WRONG_FEATURE:
            code = RIG_ERR_NOT_SUPPORTED;
            break;
        case ARV_DEVICE_ERROR_NOT_FOUND:
            code = RIG_ERR_NO_DEVICE;
            break;
        case ARV_DEVICE_ERROR_INVALID_PARAMETER:
            code = RIG_ERR_INVALID;
            break;
        default:
            code = RIG_ERR_PROTOCOL;
            break;
        }
    } else if (e && *e && (*e)->domain == ARV_GC_ERROR) {
        code = (*e)->code == ARV_GC_ERROR_NODE_NOT_FOUND ? RIG_ERR_NOT_SUPPORTED : RIG_ERR_INVALID;
    }
    if (code == RIG_ERR_DISCONNECTED) a->disconnected = true;
    int rc = rig_fail(code, "%s: %s failed: %s%s", c->name, what, msg, hint);
    if (e) g_clear_error(e);
    return rc;
}

static void on_control_lost(ArvDevice *dev, gpointer data)
{
    aravis_cam_t *a = data;
    atomic_store(&a->control_lost, true);
}

static int check_connected(rig_camera_t *c)
{
    aravis_cam_t *a = impl_of(c);
    if (atomic_load(&a->control_lost) || a->disconnected)
        return rig_fail(RIG_ERR_DISCONNECTED, "%s: the camera was lost (it stopped answering); check power, cable "
                        "and network, then reopen it", c->name);
    if (a->inprocess_dev && !rig_gv_camera_inprocess_alive(a->inprocess_dev)) {
        a->disconnected = true;
        return rig_fail(RIG_ERR_DISCONNECTED, "%s: the in-process camera stopped serving (its virtual rig was "
                        "closed); close this camera before the virtual rig", c->name);
    }
    return 0;
}

static void stop_stream(aravis_cam_t *a)
{
    if (a->acquiring && !a->disconnected && !atomic_load(&a->control_lost))
        arv_camera_stop_acquisition(a->cam, NULL);
    a->acquiring = false;
    if (a->stream) {
        g_object_unref(a->stream);   // joins the stream thread, frees the buffers
        a->stream = NULL;
    }
}

static int start_stream(rig_camera_t *c)
{
    aravis_cam_t *a = impl_of(c);
    GError *e = NULL;
    if (a->stream && a->acquiring) return 0;
    stop_stream(a);
    guint payload = arv_camera_get_payload(a->cam, &e);
    if (e) return fail_gerror(c, &e, "reading PayloadSize");
    if (!payload) return rig_fail(RIG_ERR_PROTOCOL, "%s: the camera reports a payload of 0 bytes", c->name);
    a->payload = payload;
    a->stream = arv_camera_create_stream(a->cam, NULL, NULL, &e);
    if (!a->stream) return fail_gerror(c, &e, "creating the stream");
    if (ARV_IS_GV_STREAM(a->stream))   // socket buffer sized to the payload (no root needed)
        g_object_set(a->stream, "socket-buffer", ARV_GV_STREAM_SOCKET_BUFFER_AUTO, NULL);
    arv_camera_start_acquisition(a->cam, &e);
    if (e) {
        int rc = fail_gerror(c, &e, "AcquisitionStart");
        stop_stream(a);
        return rc;
    }
    a->acquiring = true;
    // Buffers only once the acquisition runs: Aravis's in-process fake stream
    // fills a buffer as soon as it has one, and one filled before AcquisitionStart
    // would come back as an empty "frame" for a later trigger.
    for (int i = 0; i < N_BUFFERS; i++) {
        ArvBuffer *b = arv_buffer_new_allocate(payload);
        if (!b) {
            stop_stream(a);
            return rig_fail(RIG_ERR_NO_MEM, "%s: out of memory for frame buffers of %u bytes", c->name, payload);
        }
        arv_stream_push_buffer(a->stream, b);
    }
    return 0;
}

// The formats refl records (rig/camera/pixfmt.h), for messages.
static void format_names(char *buf, size_t size)
{
    buf[0] = 0;
    for (int f = 0; f < RIG_PIXFMT_COUNT; f++) {
        size_t len = strlen(buf);
        snprintf(buf + len, size - len, "%s%s", f == 0 ? "" : f == RIG_PIXFMT_COUNT - 1 ? " or " : ", ",
                 rig_pixfmt_name((rig_pixfmt_t)f));
    }
}

static double read_temperature(aravis_cam_t *a)
{
    if (!a->has_temperature || a->disconnected) return NAN;
    GError *e = NULL;
    double t = arv_camera_get_float(a->cam, "DeviceTemperature", &e);
    if (e) {
        g_clear_error(&e);
        return NAN;
    }
    return t;
}

static int read_exposure_gain(rig_camera_t *c)
{
    aravis_cam_t *a = impl_of(c);
    GError *e = NULL;
    a->exposure_us = arv_camera_get_exposure_time(a->cam, &e);
    if (e) return fail_gerror(c, &e, "reading the exposure time");
    a->gain = a->has_gain ? arv_camera_get_gain(a->cam, &e) : NAN;
    if (e) return fail_gerror(c, &e, "reading the gain");
    return 0;
}

// ---------------------------------------------------------------------------
// Radiometric settings. Before any frame refl switches off what makes a pixel
// value anything but the sensor's linear response: the automatics (every
// enumeration named *Auto* that has an Off entry: ExposureAuto, GainAuto,
// BalanceWhiteAuto, BlackLevelAuto and vendors' own), GammaEnable (or Gamma =
// 1 where there is no enable) and LUTEnable; each is read back. A feature the
// camera lacks is fine; one it will not switch off is an error naming it, except
// BalanceWhiteAuto on a mono camera (every pixel format Mono*: it has no colour
// to balance), which is kept as a warning in the settings text. What was found
// and done goes into a->settings ("ExposureAuto=Off (was Continuous) ..."),
// recorded with every frame.

static void settings_add(aravis_cam_t *a, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
static void settings_add(aravis_cam_t *a, const char *fmt, ...)
{
    size_t len = strlen(a->settings);
    if (len + 2 >= sizeof a->settings) return;
    if (len) a->settings[len++] = ' ';
    va_list ap;
    va_start(ap, fmt);
    int n = vsnprintf(a->settings + len, sizeof a->settings - len, fmt, ap);
    va_end(ap);
    if (n < 0 || (size_t)n >= sizeof a->settings - len) {
        a->settings_full = true;
        a->settings[len ? len - 1 : 0] = 0;
    }
}

// The feature's node when the camera has it, implemented and available now; else NULL.
static ArvGcNode *feature(aravis_cam_t *a, const char *name)
{
    ArvGcNode *n = arv_device_get_feature(a->dev, name);
    if (!n || !ARV_IS_GC_FEATURE_NODE(n)) return NULL;
    GError *e = NULL;
    bool ok = arv_gc_feature_node_is_implemented(ARV_GC_FEATURE_NODE(n), &e) &&
              arv_gc_feature_node_is_available(ARV_GC_FEATURE_NODE(n), &e);
    g_clear_error(&e);
    return ok ? n : NULL;
}

static bool is_mono_camera(aravis_cam_t *a)
{
    guint n = 0;
    const char **f = arv_camera_dup_available_pixel_formats_as_strings(a->cam, &n, NULL);
    bool mono = f && n > 0;
    for (guint i = 0; mono && i < n; i++) mono = f[i] && !strncmp(f[i], "Mono", 4);
    g_free(f);
    return mono;
}

// An auto enumeration to Off (absent, or without an Off entry: nothing to do).
static int auto_off(rig_camera_t *c, const char *name, bool mono)
{
    aravis_cam_t *a = impl_of(c);
    ArvGcNode *n = feature(a, name);
    if (!n || !ARV_IS_GC_ENUMERATION(n)) return 0;
    ArvGcEnumeration *en = ARV_GC_ENUMERATION(n);
    GError *e = NULL;
    guint nv = 0;
    const char **vals = arv_gc_enumeration_dup_available_string_values(en, &nv, &e);
    bool has_off = false;
    for (guint i = 0; vals && i < nv; i++) has_off |= vals[i] && !strcmp(vals[i], "Off");
    g_free(vals);
    g_clear_error(&e);
    const char *v = arv_gc_enumeration_get_string_value(en, &e);
    if (e) return fail_gerror(c, &e, name);
    char was[64];
    snprintf(was, sizeof was, "%s", v ? v : "?");
    if (!strcmp(was, "Off")) {
        settings_add(a, "%s=Off", name);
        return 0;
    }
    if (has_off) arv_gc_enumeration_set_string_value(en, "Off", &e);
    char why[200] = "";
    if (e) snprintf(why, sizeof why, ": %s", e->message);
    else if (!has_off) snprintf(why, sizeof why, ": it has no Off entry");
    g_clear_error(&e);
    v = arv_gc_enumeration_get_string_value(en, &e);
    g_clear_error(&e);
    if (v && !strcmp(v, "Off")) {
        settings_add(a, "%s=Off (was %s)", name, was);
        return 0;
    }
    if (mono && !strcmp(name, "BalanceWhiteAuto")) {   // harmless: no colour channels to balance
        settings_add(a, "%s=%s (warning: cannot be switched off%s; harmless on a mono camera)", name, v ? v : was, why);
        return 0;
    }
    return rig_fail(RIG_ERR_NOT_SUPPORTED, "%s: cannot switch %s off (it reads %s%s): refl needs the sensor's own "
                    "linear response; switch it off with the camera's own tool or use another camera", c->name,
                    name, v ? v : was, why);
}

// A boolean feature (GammaEnable, LUTEnable) to false.
static int bool_off(rig_camera_t *c, const char *name)
{
    aravis_cam_t *a = impl_of(c);
    ArvGcNode *n = feature(a, name);
    if (!n || !ARV_IS_GC_BOOLEAN(n)) return 0;
    GError *e = NULL;
    bool was = arv_gc_boolean_get_value(ARV_GC_BOOLEAN(n), &e);
    if (e) return fail_gerror(c, &e, name);
    if (was) arv_gc_boolean_set_value(ARV_GC_BOOLEAN(n), FALSE, &e);
    char why[200] = "";
    if (e) snprintf(why, sizeof why, ": %s", e->message);
    g_clear_error(&e);
    bool now = arv_gc_boolean_get_value(ARV_GC_BOOLEAN(n), &e);
    g_clear_error(&e);
    if (now)
        return rig_fail(RIG_ERR_NOT_SUPPORTED, "%s: cannot switch %s off (it reads true%s): refl needs the sensor's "
                        "own linear response; switch it off with the camera's own tool or use another camera",
                        c->name, name, why);
    settings_add(a, was ? "%s=0 (was 1)" : "%s=0", name);
    return 0;
}

// A float or integer feature's value; NAN when absent or unreadable.
static double number_feature(aravis_cam_t *a, const char *name)
{
    ArvGcNode *n = feature(a, name);
    GError *e = NULL;
    double v = NAN;
    if (n && ARV_IS_GC_FLOAT(n)) v = arv_gc_float_get_value(ARV_GC_FLOAT(n), &e);
    else if (n && ARV_IS_GC_INTEGER(n)) v = (double)arv_gc_integer_get_value(ARV_GC_INTEGER(n), &e);
    if (e) v = NAN;
    g_clear_error(&e);
    return v;
}

// The gamma in effect: 1 with GammaEnable false; where there is no enable,
// Gamma is set to 1 and read back.
static int gamma_off(rig_camera_t *c)
{
    aravis_cam_t *a = impl_of(c);
    int rc = bool_off(c, "GammaEnable");
    if (rc) return rc;
    a->gamma = 1;
    ArvGcNode *n = feature(a, "Gamma");
    if (feature(a, "GammaEnable") || !n || !ARV_IS_GC_FLOAT(n)) {
        if (n) settings_add(a, "Gamma=%.6g (not in effect)", number_feature(a, "Gamma"));
        return 0;
    }
    GError *e = NULL;
    double was = arv_gc_float_get_value(ARV_GC_FLOAT(n), &e);
    if (e) return fail_gerror(c, &e, "Gamma");
    if (was != 1) arv_gc_float_set_value(ARV_GC_FLOAT(n), 1.0, &e);
    g_clear_error(&e);
    a->gamma = arv_gc_float_get_value(ARV_GC_FLOAT(n), &e);
    if (e) return fail_gerror(c, &e, "Gamma");
    if (fabs(a->gamma - 1) > 1e-6)
        return rig_fail(RIG_ERR_NOT_SUPPORTED, "%s: cannot set Gamma to 1 (it reads %.6g) and the camera has no "
                        "GammaEnable: refl needs the sensor's own linear response", c->name, a->gamma);
    settings_add(a, was != 1 ? "Gamma=1 (was %.6g)" : "Gamma=1", was);
    return 0;
}

// The gain feature's unit: GenICam's <Unit> of Gain (or GainAbs), "raw" for
// GainRaw and for a gain that states no unit (never assumed to be dB).
static void read_gain_unit(aravis_cam_t *a)
{
    static const char *const names[] = { "Gain", "GainAbs" };
    snprintf(a->gain_unit, sizeof a->gain_unit, "raw");
    for (size_t i = 0; i < sizeof names / sizeof names[0]; i++) {
        ArvGcNode *n = feature(a, names[i]);
        const char *u = NULL;
        if (n && ARV_IS_GC_FLOAT(n)) u = arv_gc_float_get_unit(ARV_GC_FLOAT(n));
        else if (n && ARV_IS_GC_INTEGER(n)) u = arv_gc_integer_get_unit(ARV_GC_INTEGER(n));
        else continue;
        if (u && *u) snprintf(a->gain_unit, sizeof a->gain_unit, "%s", u);
        return;
    }
}

// The enumerations named *Auto* of the camera's feature tree (from Root),
// beyond the standard ones, appended to names (at most max).
static void find_vendor_autos(ArvGc *gc, const char *cat, int depth, const char **names, int *n, int max)
{
    ArvGcNode *node = arv_gc_get_node(gc, cat);
    if (!node || !ARV_IS_GC_CATEGORY(node) || depth > 8) return;
    for (const GSList *l = arv_gc_category_get_features(ARV_GC_CATEGORY(node)); l; l = l->next) {
        const char *name = l->data;
        ArvGcNode *f = name ? arv_gc_get_node(gc, name) : NULL;
        if (!f) continue;
        if (ARV_IS_GC_CATEGORY(f)) {
            find_vendor_autos(gc, name, depth + 1, names, n, max);
        } else if (ARV_IS_GC_ENUMERATION(f) && strstr(name, "Auto") && *n < max) {
            bool seen = false;
            for (int i = 0; i < *n; i++) seen |= !strcmp(names[i], name);
            if (!seen) names[(*n)++] = name;
        }
    }
}

static int switch_off_automatics(rig_camera_t *c)
{
    aravis_cam_t *a = impl_of(c);
    a->settings[0] = 0;
    bool mono = is_mono_camera(a);
    const char *names[48] = { "ExposureAuto", "GainAuto", "BalanceWhiteAuto", "BlackLevelAuto" };
    int n = 4;
    find_vendor_autos(arv_device_get_genicam(a->dev), "Root", 0, names, &n, 48);
    int rc = 0;
    for (int i = 0; i < n && !rc; i++) rc = auto_off(c, names[i], mono);
    if (!rc) rc = gamma_off(c);
    if (!rc) rc = bool_off(c, "LUTEnable");
    if (rc) return rc;
    read_gain_unit(a);
    a->black_level = number_feature(a, "BlackLevel");
    if (isfinite(a->black_level)) settings_add(a, "BlackLevel=%.10g", a->black_level);
    ArvGcNode *fw = feature(a, "DeviceFirmwareVersion");
    const char *s = fw && ARV_IS_GC_STRING(fw) ? arv_gc_string_get_value(ARV_GC_STRING(fw), NULL) : NULL;
    snprintf(a->firmware, sizeof a->firmware, "%s", s ? s : "");
    static const char *const transport[] = { "GevSCPSPacketSize", "GevSCPD" };
    for (size_t i = 0; i < sizeof transport / sizeof transport[0]; i++) {
        double v = number_feature(a, transport[i]);
        if (isfinite(v)) settings_add(a, "%s=%.0f", transport[i], v);
    }
    if (!a->settings[0]) settings_add(a, "(no automatics, gamma or LUT found)");
    return 0;
}

// The settings text's "name=..." token replaced by name=value (appended when absent).
static void note_set(aravis_cam_t *a, const char *name, long value)
{
    char key[64];
    snprintf(key, sizeof key, "%s=", name);
    char *at = strstr(a->settings, key);
    if (at && (at == a->settings || at[-1] == ' ')) {
        char *end = strchr(at, ' ');
        memmove(at, end ? end + 1 : at + strlen(at), strlen(end ? end + 1 : at + strlen(at)) + 1);
        size_t len = strlen(a->settings);
        if (len && a->settings[len - 1] == ' ') a->settings[len - 1] = 0;
    }
    settings_add(a, "%s=%ld", name, value);
}

// Copy the radiometric state into a frame's metadata.
static void radiometric_meta(const aravis_cam_t *a, rig_frame_meta_t *m)
{
    snprintf(m->gain_unit, sizeof m->gain_unit, "%s", a->gain_unit);
    m->black_level = a->black_level;
    m->gamma = a->gamma;
    snprintf(m->firmware, sizeof m->firmware, "%s", a->firmware);
    snprintf(m->camera_settings, sizeof m->camera_settings, "%s", a->settings);
}

// ---------------------------------------------------------------------------
// ops

static int op_settings(rig_camera_t *c, rig_frame_meta_t *m)
{
    aravis_cam_t *a = impl_of(c);
    GError *e = NULL;
    int rc = check_connected(c);
    if (rc) return rc;
    memset(m, 0, sizeof *m);
    arv_camera_get_region(a->cam, &m->offset_x, &m->offset_y, &m->width, &m->height, &e);
    if (e) return fail_gerror(c, &e, "reading the region");
    ArvPixelFormat pf = arv_camera_get_pixel_format(a->cam, &e);
    if (e) return fail_gerror(c, &e, "reading PixelFormat");
    rig_pixfmt_t fmt;
    if (rig_pixfmt_from_pfnc((uint32_t)pf, &fmt)) {
        m->bits = rig_pixfmt_bits(fmt);
        snprintf(m->pixel_format, sizeof m->pixel_format, "%s", rig_pixfmt_name(fmt));
    } else {
        const char *s = arv_camera_get_pixel_format_as_string(a->cam, NULL);
        snprintf(m->pixel_format, sizeof m->pixel_format, "%s", s ? s : "?");
    }
    if ((rc = read_exposure_gain(c))) return rc;
    m->exposure_us = a->exposure_us;
    m->gain = a->gain;
    m->temperature_c = read_temperature(a);
    m->system_time_s = now_realtime_s();
    snprintf(m->vendor, sizeof m->vendor, "%s", a->vendor);
    snprintf(m->model, sizeof m->model, "%s", a->model);
    snprintf(m->serial, sizeof m->serial, "%s", a->serial);
    radiometric_meta(a, m);
    return 0;
}

static int op_set_pixel_format(rig_camera_t *c, const char *format)
{
    aravis_cam_t *a = impl_of(c);
    GError *e = NULL;
    int rc = check_connected(c);
    if (rc) return rc;
    guint n = 0;
    const char **avail = arv_camera_dup_available_pixel_formats_as_strings(a->cam, &n, &e);
    if (e) {
        g_free(avail);
        return fail_gerror(c, &e, "listing the pixel formats");
    }
    bool found = false;
    char list[512] = "";
    for (guint i = 0; i < n; i++) {
        if (avail[i] && !strcmp(avail[i], format)) found = true;
        size_t len = strlen(list);
        snprintf(list + len, sizeof list - len, "%s%s", i ? ", " : "", avail[i] ? avail[i] : "?");
    }
    g_free(avail);
    rig_pixfmt_t fmt;
    if (!rig_pixfmt_from_name(format, &fmt)) {
        char names[160];
        format_names(names, sizeof names);
        return rig_fail(RIG_ERR_INVALID, "%s: pixel format '%s' is not supported: refl records %s (the camera "
                        "offers: %s)", c->name, format, names, n ? list : "none");
    }
    if (!found)
        return rig_fail(RIG_ERR_NOT_SUPPORTED, "%s: the camera does not offer pixel format %s; it offers: %s",
                        c->name, format, n ? list : "none");
    stop_stream(a);
    arv_camera_set_pixel_format_from_string(a->cam, format, &e);
    if (e) return fail_gerror(c, &e, "setting PixelFormat");
    const char *now = arv_camera_get_pixel_format_as_string(a->cam, &e);
    if (e) return fail_gerror(c, &e, "reading PixelFormat");
    if (!now || strcmp(now, format))
        return rig_fail(RIG_ERR_PROTOCOL, "%s: PixelFormat reads %s after setting %s", c->name, now ? now : "?", format);
    return 0;
}

static int op_set_exposure_us(rig_camera_t *c, double exposure_us)
{
    aravis_cam_t *a = impl_of(c);
    GError *e = NULL;
    int rc = check_connected(c);
    if (rc) return rc;
    double lo = 0, hi = 0;
    arv_camera_get_exposure_time_bounds(a->cam, &lo, &hi, &e);
    if (e) return fail_gerror(c, &e, "reading the exposure time range");
    if (!isfinite(exposure_us) || exposure_us < lo || exposure_us > hi)
        return rig_fail(RIG_ERR_INVALID, "%s: exposure %.10g us is outside the camera's range %.10g..%.10g us", c->name,
                        exposure_us, lo, hi);
    arv_camera_set_exposure_time(a->cam, exposure_us, &e);
    if (e) return fail_gerror(c, &e, "setting the exposure time");
    return read_exposure_gain(c);
}

static int op_set_gain(rig_camera_t *c, double gain)
{
    aravis_cam_t *a = impl_of(c);
    GError *e = NULL;
    int rc = check_connected(c);
    if (rc) return rc;
    if (!a->has_gain) return rig_fail(RIG_ERR_NOT_SUPPORTED, "%s: the camera has no gain control", c->name);
    double lo = 0, hi = 0;
    arv_camera_get_gain_bounds(a->cam, &lo, &hi, &e);
    if (e) return fail_gerror(c, &e, "reading the gain range");
    if (!isfinite(gain) || gain < lo || gain > hi)
        return rig_fail(RIG_ERR_INVALID, "%s: gain %.10g is outside the camera's range %.10g..%.10g", c->name, gain, lo, hi);
    arv_camera_set_gain(a->cam, gain, &e);
    if (e) return fail_gerror(c, &e, "setting the gain");
    return read_exposure_gain(c);
}

static int op_set_region(rig_camera_t *c, int x, int y, int width, int height)
{
    aravis_cam_t *a = impl_of(c);
    GError *e = NULL;
    int rc = check_connected(c);
    if (rc) return rc;
    int sw = 0, sh = 0;
    arv_camera_get_sensor_size(a->cam, &sw, &sh, &e);
    if (e) return fail_gerror(c, &e, "reading the sensor size");
    if (x < 0 || y < 0 || width < 1 || height < 1 || x > sw - width || y > sh - height)
        return rig_fail(RIG_ERR_INVALID, "%s: region %dx%d at (%d,%d) does not fit the %dx%d sensor", c->name,
                        width, height, x, y, sw, sh);
    const struct { const char *what; int value; gint inc; } chk[] = {
        { "width", width, arv_camera_get_width_increment(a->cam, NULL) },
        { "height", height, arv_camera_get_height_increment(a->cam, NULL) },
        { "x offset", x, arv_camera_get_x_offset_increment(a->cam, NULL) },
        { "y offset", y, arv_camera_get_y_offset_increment(a->cam, NULL) },
    };
    for (size_t i = 0; i < sizeof chk / sizeof chk[0]; i++)
        if (chk[i].inc > 1 && chk[i].value % chk[i].inc)
            return rig_fail(RIG_ERR_INVALID, "%s: region %s %d is not a multiple of %d, the camera's step", c->name,
                            chk[i].what, chk[i].value, chk[i].inc);
    stop_stream(a);
    arv_camera_set_region(a->cam, x, y, width, height, &e);
    if (e) return fail_gerror(c, &e, "setting the region");
    int gx, gy, gw, gh;
    arv_camera_get_region(a->cam, &gx, &gy, &gw, &gh, &e);
    if (e) return fail_gerror(c, &e, "reading the region");
    if (gx != x || gy != y || gw != width || gh != height)
        return rig_fail(RIG_ERR_PROTOCOL, "%s: asked for region %dx%d at (%d,%d), the camera took %dx%d at (%d,%d)",
                        c->name, width, height, x, y, gw, gh, gx, gy);
    return 0;
}

// GigE Vision stream packets: an integer feature set within the camera's range, read back.
static int set_transport_feature(rig_camera_t *c, const char *name, long value, const char *unit)
{
    aravis_cam_t *a = impl_of(c);
    ArvGcNode *n = feature(a, name);
    if (!n || !ARV_IS_GC_INTEGER(n))
        return rig_fail(RIG_ERR_NOT_SUPPORTED, "%s: the camera has no %s (a GigE Vision stream setting): remove it "
                        "from the rig file", c->name, name);
    GError *e = NULL;
    gint64 lo = arv_gc_integer_get_min(ARV_GC_INTEGER(n), &e);
    gint64 hi = e ? 0 : arv_gc_integer_get_max(ARV_GC_INTEGER(n), &e);
    if (e) return fail_gerror(c, &e, name);
    if (value < lo || value > hi)
        return rig_fail(RIG_ERR_INVALID, "%s: %s %ld %s is outside the camera's range %lld..%lld", c->name, name, value,
                        unit, (long long)lo, (long long)hi);
    arv_gc_integer_set_value(ARV_GC_INTEGER(n), value, &e);
    if (e) return fail_gerror(c, &e, name);
    gint64 now = arv_gc_integer_get_value(ARV_GC_INTEGER(n), &e);
    if (e) return fail_gerror(c, &e, name);
    if (now != value)
        return rig_fail(RIG_ERR_PROTOCOL, "%s: %s reads %lld after setting %ld %s", c->name, name, (long long)now, value,
                        unit);
    note_set(a, name, value);
    return 0;
}

static int op_set_stream_packets(rig_camera_t *c, long packet_size, long packet_delay)
{
    aravis_cam_t *a = impl_of(c);
    int rc = check_connected(c);
    if (rc) return rc;
    stop_stream(a);   // a new stream takes them
    if (packet_size >= 0) {
        if ((rc = set_transport_feature(c, "GevSCPSPacketSize", packet_size, "bytes"))) return rc;
        if (ARV_IS_GV_DEVICE(a->dev))   // Aravis would otherwise test and change it when the stream starts
            arv_gv_device_set_packet_size_adjustment(ARV_GV_DEVICE(a->dev), ARV_GV_PACKET_SIZE_ADJUSTMENT_NEVER);
    }
    if (packet_delay >= 0 && (rc = set_transport_feature(c, "GevSCPD", packet_delay, "ticks"))) return rc;
    return 0;
}

static const char *status_name(ArvBufferStatus s)
{
    switch (s) {
    case ARV_BUFFER_STATUS_SUCCESS:         return "success";
    case ARV_BUFFER_STATUS_CLEARED:         return "cleared";
    case ARV_BUFFER_STATUS_TIMEOUT:         return "timeout while receiving";
    case ARV_BUFFER_STATUS_MISSING_PACKETS: return "missing packets";
    case ARV_BUFFER_STATUS_WRONG_PACKET_ID: return "wrong packet id";
    case ARV_BUFFER_STATUS_SIZE_MISMATCH:   return "size mismatch";
    case ARV_BUFFER_STATUS_FILLING:         return "still filling";
    case ARV_BUFFER_STATUS_ABORTED:         return "aborted";
    default:                                return "unknown status";
    }
}

// Copy a complete buffer into out (pix allocated here).
static int take_frame(rig_camera_t *c, ArvBuffer *b, rig_frame_t *out)
{
    aravis_cam_t *a = impl_of(c);
    rig_frame_meta_t *m = &out->meta;
    ArvPixelFormat pf = arv_buffer_get_image_pixel_format(b);
    rig_pixfmt_t fmt;
    if (!rig_pixfmt_from_pfnc((uint32_t)pf, &fmt)) {
        char names[160];
        format_names(names, sizeof names);
        return rig_fail(RIG_ERR_PROTOCOL, "%s: the camera sent pixel format 0x%08x, not %s", c->name, (unsigned)pf,
                        names);
    }
    const char *name = rig_pixfmt_name(fmt);
    int x = 0, y = 0, w = 0, h = 0;
    arv_buffer_get_image_region(b, &x, &y, &w, &h);
    size_t size = 0;
    const uint8_t *d = arv_buffer_get_image_data(b, &size);
    size_t n = (size_t)(w > 0 ? w : 0) * (size_t)(h > 0 ? h : 0);
    size_t need = n ? rig_pixfmt_frame_bytes(fmt, w, h) : 0;
    if (a->inprocess_dev && size == 0) size = a->payload;   // Aravis's fake stream leaves it 0
    if (!d || n == 0 || size != need)
        return rig_fail(RIG_ERR_PROTOCOL, "%s: frame of %zu bytes for a %dx%d %s image (%zu bytes expected)",
                        c->name, size, w, h, name, need);
    out->pix = malloc(n * sizeof *out->pix);
    if (!out->pix) return rig_fail(RIG_ERR_NO_MEM, "%s: out of memory for a %dx%d frame", c->name, w, h);
    if (!rig_pixfmt_unpack(fmt, d, size, w, h, out->pix)) {   // little-endian containers or packed bit streams
        char why[256];
        snprintf(why, sizeof why, "%s", model_last_error());
        return rig_fail(RIG_ERR_PROTOCOL, "%s: %s", c->name, why);
    }

    guint64 raw = arv_buffer_get_frame_id(b);
    if (!a->have_last_id) {
        a->frame_id = raw;
        a->have_last_id = true;
    } else {
        uint64_t delta = 1;
        if (raw > a->last_raw_id) delta = raw - a->last_raw_id;
        else if (raw < a->last_raw_id && a->last_raw_id <= 0xffff)   // 16-bit GVSP block id wrapped (0 is skipped)
            delta = raw + 0xffff - a->last_raw_id;
        a->frame_id += delta ? delta : 1;
    }
    a->last_raw_id = raw;

    m->width = w;
    m->height = h;
    m->offset_x = x;
    m->offset_y = y;
    snprintf(m->pixel_format, sizeof m->pixel_format, "%s", name);
    m->bits = rig_pixfmt_bits(fmt);
    m->exposure_us = a->exposure_us;
    m->gain = a->gain;
    m->frame_id = a->frame_id;
    m->timestamp_ns = arv_buffer_get_timestamp(b);
    guint64 sys_ns = arv_buffer_get_system_timestamp(b);
    m->system_time_s = sys_ns ? 1e-9 * (double)sys_ns : now_realtime_s();
    m->temperature_c = read_temperature(a);
    snprintf(m->vendor, sizeof m->vendor, "%s", a->vendor);
    snprintf(m->model, sizeof m->model, "%s", a->model);
    snprintf(m->serial, sizeof m->serial, "%s", a->serial);
    radiometric_meta(a, m);
    return 0;
}

// Frames from `from` to `to` (signed): GVSP's 16-bit block ids wrap after
// 65535 (0 is skipped), the 64-bit ones of GigE Vision 2 do not.
static int64_t id_steps(guint64 from, guint64 to)
{
    if (from <= 0xffff && to <= 0xffff) {
        int64_t d = ((int64_t)to - (int64_t)from) % 0xffff;
        if (d > 0x7fff) d -= 0xffff;
        else if (d < -0x7fff) d += 0xffff;
        return d;
    }
    return (int64_t)(to - from);
}

// A frame came (kept or recycled): one trigger less owed.
static void frame_seen(aravis_cam_t *a, ArvBuffer *b)
{
    a->seen_id = arv_buffer_get_frame_id(b);
    a->have_seen_id = true;
    if (a->pending > 0) a->pending--;
}

// Whether b may answer an earlier trigger than the latest, `owed` triggers
// before it unanswered and `seen` the last frame id seen: its id comes before
// seen + owed + 1, the latest trigger's frame's at the earliest, unless the
// camera let some of those triggers pass (with no id seen yet: any frame).
static bool frame_may_be_late(ArvBuffer *b, bool have_seen, guint64 seen, int owed)
{
    if (owed <= 0) return false;
    return !have_seen || id_steps(seen, arv_buffer_get_frame_id(b)) <= owed;
}

// The frame of a trigger sent with frames of earlier ones owed: a frame that
// may be a late one is held while the time-out lasts; one after it is this
// trigger's (the held one recycled); none after it, the held one is (the
// camera let the earlier triggers pass, or this trigger's frame is late too:
// it stays owed). NULL: no frame in time.
static ArvBuffer *pop_own_frame(aravis_cam_t *a, int owed, double timeout_s)
{
    bool have_seen = a->have_seen_id;
    guint64 seen = a->seen_id;
    double until = model_now_s() + timeout_s;
    ArvBuffer *b, *held = NULL;
    for (;;) {
        double left = until - model_now_s();
        b = left > 0 ? arv_stream_timeout_pop_buffer(a->stream, (guint64)(left * 1e6) + 1) : NULL;
        if (!b || !frame_may_be_late(b, have_seen, seen, owed)) break;
        frame_seen(a, b);
        have_seen = true;
        seen = a->seen_id;
        owed--;
        if (held) arv_stream_push_buffer(a->stream, held);
        held = b;
    }
    if (b) {
        if (held) arv_stream_push_buffer(a->stream, held);
        frame_seen(a, b);
        a->pending = 0;   // frames come in order: none before it is still on the way
    } else if (held) {
        b = held;
        a->pending = 1;
        a->pending_until = model_now_s() + fmax(5 * timeout_s, 2.0);
    } else {
        a->pending_until = model_now_s() + fmax(5 * timeout_s, 2.0);
    }
    return b;
}

static int op_capture(rig_camera_t *c, double timeout_s, int retries, rig_frame_t *out)
{
    aravis_cam_t *a = impl_of(c);
    GError *e = NULL;
    memset(out, 0, sizeof *out);
    if (!(timeout_s > 0 && timeout_s <= 3600))
        return rig_fail(RIG_ERR_INVALID, "%s: capture timeout %g s outside (0, 3600]", c->name, timeout_s);
    if (retries < 0 || retries > 1000)
        return rig_fail(RIG_ERR_INVALID, "%s: capture retries %d outside 0..1000", c->name, retries);
    int rc = check_connected(c);
    if (rc || (rc = start_stream(c))) return rc;

    char problem[160] = "";
    for (int attempt = 0; attempt <= retries; attempt++) {
        // Frames still queued belong to earlier triggers: recycle them.
        ArvBuffer *b;
        while ((b = arv_stream_try_pop_buffer(a->stream))) {
            frame_seen(a, b);
            arv_stream_push_buffer(a->stream, b);
        }
        // An earlier trigger's frame may still come after this trigger (a
        // time-out: a slow render, a late packet); it shows the rig as it was
        // then and must not be taken for this one's.
        if (a->pending > 0 && model_now_s() > a->pending_until) a->pending = 0;
        int owed = a->pending;
        arv_camera_software_trigger(a->cam, &e);
        if (e) return fail_gerror(c, &e, "TriggerSoftware");
        a->pending++;
        b = pop_own_frame(a, owed, timeout_s);
        if (!b) {
            snprintf(problem, sizeof problem, "no frame within %g s", timeout_s);
            if (atomic_load(&a->control_lost)) break;
            continue;
        }
        ArvBufferStatus st = arv_buffer_get_status(b);
        if (st != ARV_BUFFER_STATUS_SUCCESS) {
            snprintf(problem, sizeof problem, "frame %llu incomplete (%s)",
                     (unsigned long long)arv_buffer_get_frame_id(b), status_name(st));
            arv_stream_push_buffer(a->stream, b);
            continue;
        }
        rc = take_frame(c, b, out);
        arv_stream_push_buffer(a->stream, b);
        if (rc) rig_frame_free(out);
        return rc;
    }
    if (atomic_load(&a->control_lost)) {
        a->disconnected = true;
        return rig_fail(RIG_ERR_DISCONNECTED, "%s: camera lost during capture (%s); check power, cable and network, "
                        "then reopen it", c->name, problem);
    }
    return rig_fail(RIG_ERR_TIMEOUT, "%s: no complete frame after %d software trigger%s (last: %s); check the "
                    "exposure time (%g us) against the timeout, the network for packet loss, and the trigger settings",
                    c->name, retries + 1, retries ? "s" : "", problem, a->exposure_us);
}

static void op_close(rig_camera_t *c)
{
    aravis_cam_t *a = impl_of(c);
    if (!a) return;
    stop_stream(a);
    if (a->cam) {
        if (a->dev && a->lost_handler) g_signal_handler_disconnect(a->dev, a->lost_handler);
        g_object_unref(a->cam);   // GigE Vision: releases control of the camera
    }
    free(a);
    c->impl = NULL;
}

static const rig_camera_ops_t aravis_ops = {
    .backend = "aravis",
    .set_pixel_format = op_set_pixel_format,
    .set_exposure_us = op_set_exposure_us,
    .set_gain = op_set_gain,
    .set_region = op_set_region,
    .set_stream_packets = op_set_stream_packets,
    .settings = op_settings,
    .capture = op_capture,
    .close = op_close,
};

static void copy_string(char *dst, size_t size, const char *src)
{
    snprintf(dst, size, "%s", src && *src ? src : "?");
}

int rig_camera_open_aravis(rig_camera_t **out, const char *id)
{
    GError *e = NULL;
    int rc = 0;
    if (!out) return rig_fail(RIG_ERR_INVALID, "aravis: NULL camera pointer");
    *out = NULL;
    if (!id || !*id || strlen(id) >= 64)
        return rig_fail(RIG_ERR_INVALID, "aravis: camera id must be an IP address, serial number or device name "
                        "of 1 to 63 characters");
    const size_t np = strlen(RIG_GV_INPROCESS_PREFIX);
    bool inprocess = !strncmp(id, RIG_GV_INPROCESS_PREFIX, np);
    rig_camera_t *c = calloc(1, sizeof *c);
    aravis_cam_t *a = calloc(1, sizeof *a);
    if (!c || !a) {
        free(c);
        free(a);
        return rig_fail(RIG_ERR_NO_MEM, "aravis: out of memory");
    }
    c->ops = &aravis_ops;
    c->impl = a;
    snprintf(a->id, sizeof a->id, "%s", id);
    snprintf(c->name, sizeof c->name, "aravis camera %s", id);

    // An IPv4 address is opened directly (unicast GVCP), an in-process camera
    // through its device; anything else makes Aravis enumerate devices (GigE
    // Vision discovery is a broadcast).
    if (inprocess) {
        ArvDevice *dev = rig_gv_camera_inprocess_device(id + np);
        if (!dev) {
            rc = rig_fail(RIG_ERR_NO_DEVICE, "aravis: no in-process camera with serial '%s' in this process; it "
                          "exists while a virtual rig with serve = inprocess (or an in-process rig_gv_camera) runs",
                          id + np);
            goto done;
        }
        a->cam = arv_camera_new_with_device(dev, &e);   // takes its own reference
        a->inprocess_dev = dev;
        g_object_unref(dev);
        if (!a->cam) {
            rc = rig_fail(RIG_ERR_IO, "aravis: in-process camera '%s': %s", id + np, e ? e->message : "unknown error");
            g_clear_error(&e);
            goto done;
        }
    } else {
        a->cam = arv_camera_new(id, &e);
    }
    if (!a->cam) {
        rc = rig_fail(RIG_ERR_NO_DEVICE, "aravis: no camera at '%s' (%s); %s", id, e ? e->message : "not found",
                      is_ipv4_address(id) ? "nothing answers GigE Vision control (UDP 3956) there: check the "
                      "address, power and cable"
                      : "check the serial number or name (on the camera's label, or in its "
                      "vendor's tool; rig/README.md: bring-up)");
        g_clear_error(&e);
        goto done;
    }
    a->dev = arv_camera_get_device(a->cam);
    a->lost_handler = g_signal_connect(a->dev, "control-lost", G_CALLBACK(on_control_lost), a);

    const char *s = arv_camera_get_vendor_name(a->cam, &e);
    if (!e) copy_string(a->vendor, sizeof a->vendor, s);
    if (!e) s = arv_camera_get_model_name(a->cam, &e);
    if (!e) copy_string(a->model, sizeof a->model, s);
    if (!e) s = arv_camera_get_device_serial_number(a->cam, &e);
    if (!e) copy_string(a->serial, sizeof a->serial, s);
    if (e) {
        rc = fail_gerror(c, &e, "reading vendor, model and serial number");
        goto done;
    }
    snprintf(c->name, sizeof c->name, "aravis %.24s %.32s serial %.24s at %.24s", a->vendor, a->model, a->serial, id);

    a->has_temperature = arv_camera_is_feature_available(a->cam, "DeviceTemperature", NULL);
    a->has_gain = arv_camera_is_gain_available(a->cam, NULL);
    if (!arv_camera_is_software_trigger_supported(a->cam, &e)) {
        rc = e ? fail_gerror(c, &e, "looking for TriggerSoftware")
               : rig_fail(RIG_ERR_NOT_SUPPORTED, "%s: the camera has no software trigger (TriggerSoftware)", c->name);
        goto done;
    }
    arv_camera_set_acquisition_mode(a->cam, ARV_ACQUISITION_MODE_CONTINUOUS, &e);
    if (e) {
        rc = fail_gerror(c, &e, "setting AcquisitionMode Continuous");
        goto done;
    }
    arv_camera_set_trigger(a->cam, "Software", &e);   // TriggerMode On, TriggerSource Software (FrameStart)
    if (e) {
        rc = fail_gerror(c, &e, "setting TriggerMode On / TriggerSource Software");
        goto done;
    }
    if ((rc = switch_off_automatics(c))) goto done;   // before any frame: the automatics change them
    if ((rc = read_exposure_gain(c))) goto done;
    *out = c;
    return 0;
done:
    op_close(c);
    free(c);
    return rc;
}
