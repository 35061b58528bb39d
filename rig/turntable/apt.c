// rig/turntable/apt.c — Thorlabs APT rotation stage over an FTDI USB serial
// chip (libftdi1 on libusb-1.0).
//
// The APT protocol (Thorlabs "APT Communications Protocol"): little-endian
// messages with a 6-byte header: message id (2 bytes), then either two
// parameter bytes, destination and source, or, when destination has bit 0x80
// set, the length of a data packet that follows. The host is 0x01, a
// single-channel controller is 0x50. Serial link 115200 8N1 with RTS/CTS.
#define _GNU_SOURCE
#include <errno.h>
#include <ftdi.h>
#include <libusb.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "model/model.h"
#include "rig/internal.h"

enum { APT_HOST = 0x01, APT_DEST = 0x50, APT_CHAN = 1 };
enum { APT_VID = 0x0403, APT_PID = 0xfaf0 };

// Message ids used here.
enum {
    HW_REQ_INFO = 0x0005,
    HW_GET_INFO = 0x0006,
    HW_START_UPDATEMSGS = 0x0011,
    HW_STOP_UPDATEMSGS = 0x0012,
    HW_NO_FLASH_PROGRAMMING = 0x0018,
    HW_RESPONSE = 0x0080,
    HW_RICHRESPONSE = 0x0081,
    MOD_SET_CHANENABLESTATE = 0x0210,
    MOT_REQ_VELPARAMS = 0x0414,
    MOT_GET_VELPARAMS = 0x0415,
    MOT_REQ_HOMEPARAMS = 0x0441,
    MOT_GET_HOMEPARAMS = 0x0442,
    MOT_MOVE_HOME = 0x0443,
    MOT_MOVE_HOMED = 0x0444,
    MOT_MOVE_RELATIVE = 0x0448,
    MOT_MOVE_ABSOLUTE = 0x0453,
    MOT_MOVE_COMPLETED = 0x0464,
    MOT_MOVE_STOP = 0x0465,
    MOT_MOVE_STOPPED = 0x0466,
    MOT_REQ_STATUSUPDATE = 0x0480,
    MOT_GET_STATUSUPDATE = 0x0481,
    MOT_REQ_DCSTATUSUPDATE = 0x0490,
    MOT_GET_DCSTATUSUPDATE = 0x0491,
    MOT_ACK_DCSTATUSUPDATE = 0x0492,
};

// Status bits of GET_STATUSUPDATE / GET_DCSTATUSUPDATE / MOVE_COMPLETED / MOVE_STOPPED.
enum {
    SB_LIMIT_FWD = 0x00000001,
    SB_LIMIT_REV = 0x00000002,
    SB_MOVING = 0x000000f0,      // moving fwd/rev, jogging fwd/rev
    SB_HOMING = 0x00000200,
    SB_HOMED = 0x00000400,
    SB_MOTION_ERROR = 0x00004000,
};

enum { MOTION_IDLE, MOTION_HOME, MOTION_MOVE };

// Times. The controller answers a request within milliseconds; the FTDI chip
// sends a status-only packet every latency period, so reads never block long.
static const double REPLY_TIMEOUT_S = 1.0;     // a request without its reply
static const double PARAMS_TIMEOUT_S = 0.5;    // VELPARAMS/HOMEPARAMS: optional, then the stage table
static const double SILENCE_TIMEOUT_S = 1.0;   // nothing at all while updates are on
static const double ACK_PERIOD_S = 0.5;        // keep-alive while updates are on
static const int ACK_EVERY_UPDATES = 10;
static const int LATENCY_MS = 2;
static const int USB_READ_TIMEOUT_MS = 100;

typedef struct {
    struct ftdi_context *ftdi;
    uint8_t rx[4096];               // received bytes not yet parsed
    int rxlen;
    double counts_per_deg;
    double speed_deg_s, accel_deg_s2;
    double home_speed_deg_s, home_offset_deg;
    bool params_from_controller;    // speeds from VELPARAMS/HOMEPARAMS, else the stage table
    bool stepper;                   // K10CR1 & co: MOT_REQ_STATUSUPDATE, else DCSTATUSUPDATE
    rig_turntable_info_t info;
    int32_t position;               // counts, from the last status seen
    uint32_t bits;
    bool have_status;
    int motion;
    bool stop_requested, stopped_unexpectedly;
    bool disconnected;
    bool updates_on;
    int updates_since_ack;
    double last_ack_s, last_rx_s;
    char response[96];              // last HW_RESPONSE / HW_RICHRESPONSE text
} apt_t;

static apt_t *A(rig_turntable_t *t) { return t->impl; }

static void put_u16(uint8_t *p, unsigned v) { p[0] = v & 0xff; p[1] = (v >> 8) & 0xff; }
static void put_i32(uint8_t *p, int32_t v)
{
    uint32_t u = (uint32_t)v;
    for (int i = 0; i < 4; i++) p[i] = (u >> (8 * i)) & 0xff;
}
static unsigned get_u16(const uint8_t *p) { return p[0] | p[1] << 8; }
static uint32_t get_u32(const uint8_t *p)
{
    return (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24;
}

// ---------------------------------------------------------------------------
// Byte I/O

static int fail_disconnected(rig_turntable_t *t, const char *doing)
{
    A(t)->disconnected = true;
    return rig_fail(RIG_ERR_DISCONNECTED,
                    "%s: the device disconnected while %s: check the USB cable and the controller's "
                    "power, reopen it and home the stage again (its position is lost)",
                    t->name, doing);
}

// An I/O error: find out whether the device is still there.
static int fail_io(rig_turntable_t *t, const char *doing, int code)
{
    apt_t *a = A(t);
    if (code == LIBUSB_ERROR_NO_DEVICE) return fail_disconnected(t, doing);
    if (a->ftdi && a->ftdi->usb_dev) {
        uint8_t ms[2];
        int r = libusb_control_transfer(a->ftdi->usb_dev, 0xC0, 5 /* GET_MODEM_STATUS */, 0, a->ftdi->index,
                                        ms, 2, 200);
        if (r == LIBUSB_ERROR_NO_DEVICE) return fail_disconnected(t, doing);
    }
    return rig_fail(RIG_ERR_IO, "%s: USB error while %s: %s (%s): check the cable; reopen the device",
                    t->name, doing, libusb_error_name(code), ftdi_get_error_string(a->ftdi));
}

static int apt_write(rig_turntable_t *t, const uint8_t *m, int n, const char *what)
{
    apt_t *a = A(t);
    if (a->disconnected) return rig_fail(RIG_ERR_DISCONNECTED, "%s: the device is disconnected: reopen it", t->name);
    int r = ftdi_write_data(a->ftdi, m, n);
    if (r != n) {
        char doing[80];
        snprintf(doing, sizeof doing, "sending %s", what);
        return fail_io(t, doing, r < 0 ? r : LIBUSB_ERROR_IO);
    }
    return 0;
}

static int send_short(rig_turntable_t *t, unsigned id, uint8_t p1, uint8_t p2, const char *what)
{
    uint8_t m[6];
    put_u16(m, id);
    m[2] = p1;
    m[3] = p2;
    m[4] = APT_DEST;
    m[5] = APT_HOST;
    return apt_write(t, m, 6, what);
}

static int send_chan_i32(rig_turntable_t *t, unsigned id, int32_t v, const char *what)
{
    uint8_t m[12];
    put_u16(m, id);
    put_u16(m + 2, 6);
    m[4] = APT_DEST | 0x80;
    m[5] = APT_HOST;
    put_u16(m + 6, APT_CHAN);
    put_i32(m + 8, v);
    return apt_write(t, m, 12, what);
}

// Read what the chip has (at most one latency period or USB_READ_TIMEOUT_MS).
static int read_some(rig_turntable_t *t)
{
    apt_t *a = A(t);
    if (a->disconnected) return rig_fail(RIG_ERR_DISCONNECTED, "%s: the device is disconnected: reopen it", t->name);
    int room = (int)sizeof a->rx - a->rxlen;
    if (room < 512) {   // cannot happen with sane traffic (messages are parsed as they come)
        a->rxlen = 0;
        room = sizeof a->rx;
    }
    int r = ftdi_read_data(a->ftdi, a->rx + a->rxlen, room);
    if (r == LIBUSB_ERROR_TIMEOUT) return 0;
    if (r < 0) return fail_io(t, "reading from the controller", r);
    if (r > 0) a->last_rx_s = model_now_s();
    a->rxlen += r;
    return 0;
}

// Take one whole message out of the byte stream; false if none is complete.
// Bytes that cannot start a message from the controller to us are skipped, so
// the stream resynchronises after garbage.
static bool next_message(apt_t *a, uint8_t *msg, int *len)
{
    while (a->rxlen >= 6) {
        const uint8_t *b = a->rx;
        bool is_long = b[4] & 0x80;
        // from the single-channel controller (0x50) to us (0x01); no checksum in APT
        bool plausible = (b[4] & 0x7f) == APT_HOST && b[5] == APT_DEST;
        int n = is_long ? 6 + (int)get_u16(b + 2) : 6;
        if (!plausible || n > 6 + 255) {
            memmove(a->rx, a->rx + 1, --a->rxlen);
            continue;
        }
        if (a->rxlen < n) return false;
        memcpy(msg, b, n);
        *len = n;
        memmove(a->rx, a->rx + n, a->rxlen - n);
        a->rxlen -= n;
        return true;
    }
    return false;
}

// Update the cached state from a message; send the keep-alive when due.
static int dispatch(rig_turntable_t *t, const uint8_t *m, int n)
{
    apt_t *a = A(t);
    unsigned id = get_u16(m);
    bool update = id == MOT_GET_STATUSUPDATE || id == MOT_GET_DCSTATUSUPDATE;
    if ((update || id == MOT_MOVE_COMPLETED || id == MOT_MOVE_STOPPED) && n >= 20) {
        a->position = (int32_t)get_u32(m + 8);
        a->bits = get_u32(m + 16);
        a->have_status = true;
    } else if (id == MOT_MOVE_HOMED) {
        a->bits = (a->bits | SB_HOMED) & ~(uint32_t)SB_HOMING;
        a->position = 0;
    }
    // The ends of motion
    if (id == MOT_MOVE_HOMED && a->motion == MOTION_HOME) a->motion = MOTION_IDLE;
    if (id == MOT_MOVE_COMPLETED && a->motion == MOTION_MOVE) a->motion = MOTION_IDLE;
    if (id == MOT_MOVE_STOPPED && a->motion != MOTION_IDLE) {
        a->stopped_unexpectedly = !a->stop_requested;
        a->motion = MOTION_IDLE;
    }
    if (id == HW_RESPONSE || id == HW_RICHRESPONSE) {
        // an unsolicited error report from the controller: keep its text for messages
        snprintf(a->response, sizeof a->response, "HW_RESPONSE (event 0x%02x%02x)", m[3], m[2]);
        if (id == HW_RICHRESPONSE && n >= 6 + 68) {
            char notes[65];
            memcpy(notes, m + 10, 64);
            notes[64] = 0;
            snprintf(a->response, sizeof a->response, "code %u: %s", get_u16(m + 8), notes);
        }
    }
    if (update && a->updates_on) a->updates_since_ack++;
    if (a->updates_on &&
        (a->updates_since_ack >= ACK_EVERY_UPDATES || model_now_s() - a->last_ack_s >= ACK_PERIOD_S)) {
        int r = send_short(t, MOT_ACK_DCSTATUSUPDATE, 0, 0, "MOT_ACK_DCSTATUSUPDATE");
        if (r) return r;
        a->updates_since_ack = 0;
        a->last_ack_s = model_now_s();
    }
    return 0;
}

// Wait for a message whose id is want1 or want2 (every message on the way is
// dispatched). RIG_ERR_TIMEOUT without a message after timeout_s (the caller
// words the error).
static int wait_message(rig_turntable_t *t, unsigned want1, unsigned want2, double timeout_s, uint8_t *msg,
                        int *len)
{
    apt_t *a = A(t);
    double end = model_now_s() + timeout_s;
    for (;;) {
        while (next_message(a, msg, len)) {
            int r = dispatch(t, msg, *len);
            if (r) return r;
            unsigned id = get_u16(msg);
            if (id == want1 || id == want2) return 0;
        }
        if (model_now_s() >= end) return RIG_ERR_TIMEOUT;
        int r = read_some(t);
        if (r) return r;
    }
}

static const char *bits_text(uint32_t bits, char *buf, int n)
{
    snprintf(buf, n, "0x%08x%s%s%s%s%s%s", bits, bits & SB_MOVING ? " moving" : "", bits & SB_HOMING ? " homing" : "",
             bits & SB_HOMED ? " homed" : "", bits & SB_LIMIT_FWD ? " fwd-limit" : "",
             bits & SB_LIMIT_REV ? " rev-limit" : "", bits & SB_MOTION_ERROR ? " MOTION-ERROR" : "");
    return buf;
}

// ---------------------------------------------------------------------------
// Ops

static int apt_info(rig_turntable_t *t, rig_turntable_info_t *out)
{
    apt_t *a = A(t);
    *out = a->info;
    out->speed_deg_s = a->speed_deg_s;
    out->accel_deg_s2 = a->accel_deg_s2;
    out->home_speed_deg_s = a->home_speed_deg_s;
    // From anywhere: up to a full turn to the home switch, then the offset,
    // each with its ramps.
    out->home_time_s = a->params_from_controller
                           ? (360 + fabs(a->home_offset_deg)) / a->home_speed_deg_s +
                                 2 * a->home_speed_deg_s / a->accel_deg_s2
                           : 2 * 360 / a->speed_deg_s;    // table: a full turn at cruise speed, twice
    snprintf(out->params_from, sizeof out->params_from, "%s", a->params_from_controller ? "controller" : "table");
    return 0;
}

static int request_status(rig_turntable_t *t)
{
    apt_t *a = A(t);
    uint8_t msg[6 + 256];
    int len;
    unsigned req = a->stepper ? MOT_REQ_STATUSUPDATE : MOT_REQ_DCSTATUSUPDATE;
    unsigned rep = a->stepper ? MOT_GET_STATUSUPDATE : MOT_GET_DCSTATUSUPDATE;
    int r = send_short(t, req, APT_CHAN, 0, a->stepper ? "MOT_REQ_STATUSUPDATE" : "MOT_REQ_DCSTATUSUPDATE");
    if (r) return r;
    r = wait_message(t, rep, rep, REPLY_TIMEOUT_S, msg, &len);
    if (r == RIG_ERR_TIMEOUT)
        return rig_fail(RIG_ERR_TIMEOUT,
                        "%s: no reply to a status request after %.1f s: is the controller powered and "
                        "its USB cable plugged in?",
                        t->name, REPLY_TIMEOUT_S);
    return r;
}

static int apt_status(rig_turntable_t *t, rig_turntable_status_t *out)
{
    apt_t *a = A(t);
    int r = request_status(t);
    if (r) return r;
    *out = (rig_turntable_status_t){
        .angle_deg = a->position / a->counts_per_deg,
        .moving = a->bits & SB_MOVING,
        .homing = a->bits & SB_HOMING,
        .homed = a->bits & SB_HOMED,
        .limit_fwd = a->bits & SB_LIMIT_FWD,
        .limit_rev = a->bits & SB_LIMIT_REV,
        .motion_error = a->bits & SB_MOTION_ERROR,
    };
    return 0;
}

// Read and dispatch what is already on its way (e.g. status updates sent just
// before the last HW_STOP_UPDATEMSGS), so it is not taken for news about the
// next motion.
static int drain(rig_turntable_t *t)
{
    apt_t *a = A(t);
    uint8_t msg[6 + 256];
    int len, r;
    for (int i = 0; i < 8; i++) {
        int before = a->rxlen;
        if ((r = read_some(t))) return r;
        bool got = a->rxlen > before;
        while (next_message(a, msg, &len))
            if ((r = dispatch(t, msg, len))) return r;
        if (!got) break;
    }
    return 0;
}

static int apt_start_home(rig_turntable_t *t)
{
    apt_t *a = A(t);
    int r = drain(t);
    if (r) return r;
    r = send_short(t, MOT_MOVE_HOME, APT_CHAN, 0, "MOT_MOVE_HOME");
    if (r) return r;
    a->motion = MOTION_HOME;
    a->stop_requested = a->stopped_unexpectedly = false;
    a->response[0] = 0;
    a->bits = (a->bits | SB_HOMING) & ~(uint32_t)(SB_HOMED | SB_MOTION_ERROR);
    return 0;
}

static int to_counts(rig_turntable_t *t, double deg, int32_t *out)
{
    double c = round(deg * A(t)->counts_per_deg);
    if (!(fabs(c) < 2147483647.0))
        return rig_fail(RIG_ERR_INVALID, "%s: %g deg is %.0f counts, outside the controller's range", t->name, deg, c);
    *out = (int32_t)c;
    return 0;
}

static int start_move(rig_turntable_t *t, unsigned id, double deg, const char *what)
{
    apt_t *a = A(t);
    int32_t c = 0;
    int r;
    if (!(a->bits & SB_HOMED)) {
        if ((r = request_status(t))) return r;
        if (!(a->bits & SB_HOMED))
            return rig_fail(RIG_ERR_NOT_HOMED, "%s: the stage is not homed, so its angle is unknown: home it "
                            "first (rig_turntable_home)", t->name);
    }
    if ((r = to_counts(t, deg, &c)) || (r = drain(t))) return r;
    if ((r = send_chan_i32(t, id, c, what))) return r;
    a->motion = MOTION_MOVE;
    a->stop_requested = a->stopped_unexpectedly = false;
    a->response[0] = 0;
    a->bits &= ~(uint32_t)SB_MOTION_ERROR;
    return 0;
}

static int apt_start_move_abs(rig_turntable_t *t, double deg)
{
    return start_move(t, MOT_MOVE_ABSOLUTE, deg, "MOT_MOVE_ABSOLUTE");
}

static int apt_start_move_rel(rig_turntable_t *t, double deg)
{
    return start_move(t, MOT_MOVE_RELATIVE, deg, "MOT_MOVE_RELATIVE");
}

static int updates(rig_turntable_t *t, bool on)
{
    apt_t *a = A(t);
    int r = send_short(t, on ? HW_START_UPDATEMSGS : HW_STOP_UPDATEMSGS, 0, 0,
                       on ? "HW_START_UPDATEMSGS" : "HW_STOP_UPDATEMSGS");
    if (r) return r;
    a->updates_on = on;
    a->updates_since_ack = 0;
    a->last_ack_s = a->last_rx_s = model_now_s();
    return 0;
}

// Wait for the motion in progress with status updates on (acknowledged as a
// keep-alive), watching them for a motion error.
static int apt_wait(rig_turntable_t *t, double timeout_s)
{
    apt_t *a = A(t);
    char bt[128];
    if (a->disconnected) return rig_fail(RIG_ERR_DISCONNECTED, "%s: the device is disconnected: reopen it", t->name);
    if (a->motion == MOTION_IDLE) return 0;
    const char *what = a->motion == MOTION_HOME ? "homing" : "the move";
    int r = updates(t, true);
    if (r) return r;
    double end = model_now_s() + timeout_s;
    uint8_t msg[6 + 256];
    int len;
    for (;;) {
        double now = model_now_s();
        if (now >= end) {
            r = rig_fail(RIG_ERR_TIMEOUT,
                         "%s: %s did not finish within %.2f s (at %.3f deg, status %s): give it more time, "
                         "or check that nothing blocks the stage; it may still be moving "
                         "(rig_turntable_stop halts it)",
                         t->name, what, timeout_s, a->position / a->counts_per_deg, bits_text(a->bits, bt, sizeof bt));
            break;
        }
        if (now - a->last_rx_s > SILENCE_TIMEOUT_S) {
            r = rig_fail(RIG_ERR_TIMEOUT,
                         "%s: no reply from the controller for %.1f s during %s: is the controller powered "
                         "and its USB cable plugged in?",
                         t->name, SILENCE_TIMEOUT_S, what);
            break;
        }
        // dispatch what has arrived, stopping at the end of the motion or an error
        bool ended = false;
        while (!ended && next_message(a, msg, &len)) {
            if ((r = dispatch(t, msg, len))) return r;   // disconnected or I/O: nothing more to send
            ended = a->motion == MOTION_IDLE || (a->bits & SB_MOTION_ERROR);
        }
        if (!ended && (r = read_some(t))) return r;
        if (a->bits & SB_MOTION_ERROR) {
            send_short(t, MOT_MOVE_STOP, APT_CHAN, 1, "MOT_MOVE_STOP");
            a->motion = MOTION_IDLE;
            r = rig_fail(RIG_ERR_MOTION,
                         "%s: motion error during %s at %.3f deg (status %s%s%s): the stage stalled or lost "
                         "position; check for obstructions and the load, then home it again",
                         t->name, what, a->position / a->counts_per_deg, bits_text(a->bits, bt, sizeof bt),
                         a->response[0] ? ", controller says " : "", a->response);
            break;
        }
        if (a->motion == MOTION_IDLE) {
            if (a->stopped_unexpectedly && (a->bits & (SB_LIMIT_FWD | SB_LIMIT_REV)))
                r = rig_fail(RIG_ERR_LIMIT, "%s: %s stopped at a limit switch at %.3f deg (status %s): home the "
                             "stage, and keep moves inside its travel", t->name, what,
                             a->position / a->counts_per_deg, bits_text(a->bits, bt, sizeof bt));
            else if (a->stopped_unexpectedly)
                r = rig_fail(RIG_ERR_MOTION, "%s: %s stopped before its end at %.3f deg (status %s%s%s): "
                             "check the stage and its controller, then home it again", t->name, what,
                             a->position / a->counts_per_deg, bits_text(a->bits, bt, sizeof bt),
                             a->response[0] ? ", controller says " : "", a->response);
            break;
        }
    }
    int r2 = a->disconnected ? 0 : updates(t, false);
    return r ? r : r2;
}

static int apt_stop(rig_turntable_t *t, bool immediate)
{
    apt_t *a = A(t);
    int r = send_short(t, MOT_MOVE_STOP, APT_CHAN, immediate ? 1 : 2, "MOT_MOVE_STOP");
    if (r) return r;
    if (a->motion == MOTION_IDLE) return 0;
    a->stop_requested = true;
    uint8_t msg[6 + 256];
    int len;
    double limit_s = REPLY_TIMEOUT_S + (immediate ? 0 : a->speed_deg_s / a->accel_deg_s2);
    r = wait_message(t, MOT_MOVE_STOPPED, MOT_MOVE_COMPLETED, limit_s, msg, &len);
    if (r == RIG_ERR_TIMEOUT)
        return rig_fail(RIG_ERR_TIMEOUT, "%s: no MOVE_STOPPED after MOT_MOVE_STOP within %.1f s: is the "
                        "controller powered? Switch it off if the stage keeps moving", t->name, limit_s);
    if (r) return r;
    a->motion = MOTION_IDLE;
    return 0;
}

// Sends the stop and returns: apt_wait then sees MOVE_STOPPED (asked for).
static int apt_start_stop(rig_turntable_t *t, bool immediate)
{
    apt_t *a = A(t);
    int r = send_short(t, MOT_MOVE_STOP, APT_CHAN, immediate ? 1 : 2, "MOT_MOVE_STOP");
    if (r) return r;
    if (a->motion != MOTION_IDLE) a->stop_requested = true;
    return 0;
}

static void apt_close(rig_turntable_t *t)
{
    apt_t *a = A(t);
    if (a) {
        if (a->ftdi && a->ftdi->usb_dev && !a->disconnected) {
            // best effort on the way out, without touching the last error:
            // a stage must not keep turning after we let go of it
            uint8_t stop[6] = { MOT_MOVE_STOP & 0xff, MOT_MOVE_STOP >> 8, APT_CHAN, 2, APT_DEST, APT_HOST };
            uint8_t quiet[6] = { HW_STOP_UPDATEMSGS & 0xff, HW_STOP_UPDATEMSGS >> 8, 0, 0, APT_DEST, APT_HOST };
            if (a->motion != MOTION_IDLE) ftdi_write_data(a->ftdi, stop, 6);
            if (a->updates_on) ftdi_write_data(a->ftdi, quiet, 6);
        }
        if (a->ftdi) {
            if (a->ftdi->usb_dev) ftdi_usb_close(a->ftdi);
            ftdi_free(a->ftdi);
        }
        free(a);
    }
    free(t);
}

static const rig_turntable_ops_t apt_ops = {
    .backend = "apt",
    .info = apt_info,
    .status = apt_status,
    .start_home = apt_start_home,
    .start_move_abs_deg = apt_start_move_abs,
    .start_move_rel_deg = apt_start_move_rel,
    .wait = apt_wait,
    .stop = apt_stop,
    .start_stop = apt_start_stop,
    .close = apt_close,
};

// ---------------------------------------------------------------------------
// Open

typedef struct {
    libusb_device *dev;
    int bus, addr;
    char serial[32];
    int open_err;                   // libusb code of opening it to read the serial
} apt_candidate_t;

static const char *UDEV_HINT =
    "add a udev rule such as /etc/udev/rules.d/99-thorlabs-apt.rules containing "
    "SUBSYSTEM==\"usb\", ATTRS{idVendor}==\"0403\", ATTRS{idProduct}==\"faf0\", MODE=\"0660\", GROUP=\"plugdev\" "
    "(and be in group plugdev), run `udevadm control --reload && udevadm trigger`, then replug the stage";

// "55000001 (bus 1 device 2), ..." for the error messages.
static void list_candidates(const apt_candidate_t *c, int n, char *buf, size_t len)
{
    size_t o = 0;
    buf[0] = 0;
    for (int i = 0; i < n && o + 1 < len; i++)
        o += snprintf(buf + o, len - o, "%s%s (bus %d device %d)", i ? ", " : "",
                      c[i].serial[0] ? c[i].serial : "serial unreadable", c[i].bus, c[i].addr);
}

// Other USB devices present, for "device not found": "0403:6001, 1d6b:0002".
static void list_others(libusb_device **list, ssize_t n, char *buf, size_t len)
{
    size_t o = 0;
    int shown = 0;
    buf[0] = 0;
    for (ssize_t i = 0; i < n && o + 1 < len; i++) {
        struct libusb_device_descriptor d;
        if (libusb_get_device_descriptor(list[i], &d) != 0) continue;
        if (d.idVendor == APT_VID && d.idProduct == APT_PID) continue;
        if (shown++ == 12) {
            o += snprintf(buf + o, len - o, ", ...");
            break;
        }
        o += snprintf(buf + o, len - o, "%s%04x:%04x", o ? ", " : "", d.idVendor, d.idProduct);
    }
    if (!shown) snprintf(buf, len, "none");
}

static const rig_stage_model_t *find_stage(const char *model)
{
    for (const rig_stage_model_t *m = rig_stage_models; m->model; m++)
        if (strcasecmp(m->model, model) == 0) return m;
    return NULL;
}

static void known_stages(char *buf, size_t len)
{
    size_t o = 0;
    buf[0] = 0;
    for (const rig_stage_model_t *m = rig_stage_models; m->model && o + 1 < len; m++)
        o += snprintf(buf + o, len - o, "%s%s", o ? ", " : "", m->model);
}

// Pick the device: enumerate 0403:faf0, read serials, choose one.
static int find_device(struct ftdi_context *ftdi, const char *serial, libusb_device ***list_out,
                       libusb_device **out)
{
    libusb_device **list = NULL;
    apt_candidate_t cand[16];
    int nc = 0, r = 0;
    char found[512], others[256];
    ssize_t n = libusb_get_device_list(ftdi->usb_ctx, &list);
    *list_out = NULL;
    if (n < 0) return rig_fail(RIG_ERR_IO, "apt: cannot list USB devices: %s", libusb_error_name((int)n));
    for (ssize_t i = 0; i < n && nc < 16; i++) {
        struct libusb_device_descriptor d;
        if (libusb_get_device_descriptor(list[i], &d) != 0) continue;
        if (d.idVendor != APT_VID || d.idProduct != APT_PID) continue;
        apt_candidate_t *c = &cand[nc++];
        memset(c, 0, sizeof *c);
        c->dev = list[i];
        c->bus = libusb_get_bus_number(list[i]);
        c->addr = libusb_get_device_address(list[i]);
        libusb_device_handle *h = NULL;
        c->open_err = libusb_open(list[i], &h);
        if (c->open_err == 0) {
            int k = libusb_get_string_descriptor_ascii(h, d.iSerialNumber, (unsigned char *)c->serial,
                                                       sizeof c->serial);
            if (k < 0) c->serial[0] = 0;
            libusb_close(h);
        }
    }
    list_candidates(cand, nc, found, sizeof found);
    list_others(list, n, others, sizeof others);
    int denied = -1;
    for (int i = 0; i < nc; i++)
        if (cand[i].open_err == LIBUSB_ERROR_ACCESS) denied = i;
    int pick = -1;
    if (serial) {
        for (int i = 0; i < nc; i++)
            if (strcmp(cand[i].serial, serial) == 0) pick = i;
        if (pick < 0 && denied >= 0) {
            r = rig_fail(RIG_ERR_ACCESS,
                         "apt serial %s: permission denied on /dev/bus/usb/%03d/%03d (Thorlabs APT 0403:faf0), "
                         "so its serial cannot be read: %s",
                         serial, cand[denied].bus, cand[denied].addr, UDEV_HINT);
            goto done;
        }
        if (pick < 0) {
            r = rig_fail(RIG_ERR_NO_DEVICE,
                         "apt serial %s: not found; Thorlabs APT controllers (USB 0403:faf0) present: %s; other "
                         "USB devices: %s: check the serial number (on the controller's label), the cable and "
                         "the power",
                         serial, nc ? found : "none", others);
            goto done;
        }
    } else {
        if (nc == 0) {
            r = rig_fail(RIG_ERR_NO_DEVICE,
                         "apt: no Thorlabs APT controller (USB 0403:faf0) found; USB devices present: %s: plug "
                         "the stage in, switch its controller on and check `lsusb`",
                         others);
            goto done;
        }
        if (nc > 1) {
            r = rig_fail(RIG_ERR_INVALID, "apt: %d Thorlabs APT controllers found: %s: give the serial of the one "
                         "to use", nc, found);
            goto done;
        }
        pick = 0;
    }
    if (cand[pick].open_err == LIBUSB_ERROR_ACCESS) {
        r = rig_fail(RIG_ERR_ACCESS, "apt%s%s: permission denied on /dev/bus/usb/%03d/%03d (Thorlabs APT "
                     "0403:faf0): %s", serial ? " serial " : "", serial ? serial : "", cand[pick].bus,
                     cand[pick].addr, UDEV_HINT);
        goto done;
    }
    if (cand[pick].open_err == LIBUSB_ERROR_BUSY) {
        r = rig_fail(RIG_ERR_BUSY, "apt serial %s: the device is busy: close the other program using it",
                     cand[pick].serial);
        goto done;
    }
    if (cand[pick].open_err != 0) {
        r = rig_fail(RIG_ERR_IO, "apt serial %s: cannot open /dev/bus/usb/%03d/%03d: %s: replug the stage",
                     cand[pick].serial, cand[pick].bus, cand[pick].addr, libusb_error_name(cand[pick].open_err));
        goto done;
    }
    *out = cand[pick].dev;
done:
    if (r) libusb_free_device_list(list, 1);
    else *list_out = list;
    return r;
}

// The FTDI set-up of the APT manual: 115200 8N1, purge with 50 ms dwells
// around it, RTS/CTS flow control, RTS on (the chip reset was done by
// ftdi_usb_open_dev); plus a short latency timer so replies come back quickly.
static int setup_ftdi(rig_turntable_t *t)
{
    struct ftdi_context *f = A(t)->ftdi;
    const char *step = NULL;
    if (ftdi_set_baudrate(f, 115200) < 0) step = "set the baud rate";
    else if (ftdi_set_line_property(f, BITS_8, STOP_BIT_1, NONE) < 0) step = "set 8N1";
    if (!step) {
        usleep(50000);
        if (ftdi_tcioflush(f) < 0) step = "purge the buffers";
        usleep(50000);
    }
    if (!step && ftdi_setflowctrl(f, SIO_RTS_CTS_HS) < 0) step = "set RTS/CTS flow control";
    if (!step && ftdi_setrts(f, 1) < 0) step = "raise RTS";
    if (!step && ftdi_set_latency_timer(f, LATENCY_MS) < 0) step = "set the latency timer";
    if (step) return fail_io(t, step, LIBUSB_ERROR_IO);
    f->usb_read_timeout = USB_READ_TIMEOUT_MS;
    f->usb_write_timeout = 1000;
    return 0;
}

static int hw_info(rig_turntable_t *t, const char *stage_model)
{
    apt_t *a = A(t);
    uint8_t msg[6 + 256];
    int len, r;
    // Quiet the controller (no update messages), then ask who it is.
    if ((r = send_short(t, HW_NO_FLASH_PROGRAMMING, 0, 0, "HW_NO_FLASH_PROGRAMMING")) ||
        (r = send_short(t, HW_STOP_UPDATEMSGS, 0, 0, "HW_STOP_UPDATEMSGS")) ||
        (r = send_short(t, HW_REQ_INFO, 0, 0, "HW_REQ_INFO")))
        return r;
    r = wait_message(t, HW_GET_INFO, HW_GET_INFO, REPLY_TIMEOUT_S, msg, &len);
    if (r == RIG_ERR_TIMEOUT)
        return rig_fail(RIG_ERR_TIMEOUT, "%s: no reply to HW_REQ_INFO after %.1f s: is the controller powered "
                        "(its USB chip answers without power)? Switch it on, or replug it",
                        t->name, REPLY_TIMEOUT_S);
    if (r) return r;
    if (len < 6 + 84)
        return rig_fail(RIG_ERR_PROTOCOL, "%s: HW_GET_INFO has %d data bytes, expected 84: is this a Thorlabs "
                        "APT controller?", t->name, len - 6);
    const uint8_t *d = msg + 6;
    char dev_model[9];
    memcpy(dev_model, d + 4, 8);
    dev_model[8] = 0;
    for (int i = 7; i >= 0 && (dev_model[i] == ' ' || dev_model[i] == 0); i--) dev_model[i] = 0;
    snprintf(a->info.serial, sizeof a->info.serial, "%u", get_u32(d));
    snprintf(a->info.firmware, sizeof a->info.firmware, "%u.%u.%u", d[16], d[15], d[14]);
    const char *use = stage_model ? stage_model : dev_model;
    const rig_stage_model_t *sm = find_stage(use);
    snprintf(a->info.model, sizeof a->info.model, "%s", use);
    snprintf(t->name, sizeof t->name, "apt %s serial %s", a->info.model, a->info.serial);
    if (!sm) {
        char known[256];
        known_stages(known, sizeof known);
        return rig_fail(RIG_ERR_NOT_SUPPORTED, "%s: unknown stage model \"%s\" (controller %s): give the stage "
                        "model; known: %s", t->name, use, dev_model, known);
    }
    a->counts_per_deg = sm->counts_per_deg;
    a->speed_deg_s = sm->max_speed_deg_s;
    a->accel_deg_s2 = sm->accel_deg_s2;
    a->info.counts_per_deg = sm->counts_per_deg;
    // Stepper-motor controllers (K10CR1, KST/TST) report MOT_GET_STATUSUPDATE, DC servo ones DCSTATUSUPDATE.
    a->stepper = strncmp(dev_model, "K10CR", 5) == 0 || strncmp(dev_model, "KST", 3) == 0 ||
                 strncmp(dev_model, "TST", 3) == 0;
    return 0;
}

// APT velocity and acceleration units per encoder count (the protocol
// manual's scaling): stepper controllers (K10CR1, KST/TST) count velocity in
// counts/s x 53.68 and acceleration in counts/s^2 / 90.9; DC servo ones (KDC101,
// TDC001) in counts/s x T x 65536 and counts/s^2 x T^2 x 65536, T = 2048 / 6 MHz.
static void apt_units(const apt_t *a, double *vel, double *acc)
{
    const double T = 2048 / 6e6;
    *vel = a->counts_per_deg * (a->stepper ? 53.68 : T * 65536);
    *acc = a->counts_per_deg * (a->stepper ? 1 / 90.9 : T * T * 65536);
}

// One request and its 14-byte reply (RIG_ERR_TIMEOUT quietly when none).
static int ask_params(rig_turntable_t *t, unsigned req, unsigned rep, const char *what, uint8_t *data)
{
    uint8_t msg[6 + 256];
    int len, r;
    if ((r = send_short(t, req, APT_CHAN, 0, what))) return r;
    if ((r = wait_message(t, rep, rep, PARAMS_TIMEOUT_S, msg, &len))) return r;
    if (len < 6 + 14) return RIG_ERR_PROTOCOL;
    memcpy(data, msg + 6, 14);
    return 0;
}

// The controller's cruise speed, acceleration (MOT_GET_VELPARAMS: channel u16,
// min velocity, acceleration, max velocity, i32 each) and homing speed and
// offset (MOT_GET_HOMEPARAMS: channel, direction, limit switch u16; velocity,
// offset distance i32), for time estimates and time-outs. A controller that
// does not answer, or answers nonsense, leaves the stage table's values (a
// note says so).
static int read_motion_params(rig_turntable_t *t)
{
    apt_t *a = A(t);
    uint8_t v[14], h[14];
    double vu, au;
    apt_units(a, &vu, &au);
    a->home_speed_deg_s = a->speed_deg_s;
    a->home_offset_deg = 0;
    int r = ask_params(t, MOT_REQ_VELPARAMS, MOT_GET_VELPARAMS, "MOT_REQ_VELPARAMS", v);
    if (!r) r = ask_params(t, MOT_REQ_HOMEPARAMS, MOT_GET_HOMEPARAMS, "MOT_REQ_HOMEPARAMS", h);
    if (r == RIG_ERR_DISCONNECTED || r == RIG_ERR_IO) return r;
    double accel = 0, speed = 0, home = 0, offset = 0;
    if (!r) {
        accel = (int32_t)get_u32(v + 6) / au;
        speed = (int32_t)get_u32(v + 10) / vu;
        home = (int32_t)get_u32(h + 6) / vu;
        offset = (int32_t)get_u32(h + 10) / a->counts_per_deg;
    }
    // Sane: a rotation stage turns between 0.001 and 10000 deg/s.
    bool ok = !r && speed > 1e-3 && speed < 1e4 && accel > 1e-3 && accel < 1e6 && home > 1e-3 && home < 1e4 &&
              fabs(offset) < 360;
    if (!ok) {
        model_note("%s: %s; time estimates and time-outs use the stage table's %g deg/s, %g deg/s^2", t->name,
                   r == RIG_ERR_TIMEOUT ? "no reply to MOT_REQ_VELPARAMS/MOT_REQ_HOMEPARAMS"
                   : r                  ? "a short VELPARAMS/HOMEPARAMS reply"
                                        : "the controller's VELPARAMS/HOMEPARAMS are out of range",
                   a->speed_deg_s, a->accel_deg_s2);
        return drain(t);
    }
    a->speed_deg_s = speed;
    a->accel_deg_s2 = accel;
    a->home_speed_deg_s = home;
    a->home_offset_deg = offset;
    a->params_from_controller = true;
    return 0;
}

int rig_turntable_open_apt(rig_turntable_t **out, const char *serial, const char *stage_model)
{
    rig_turntable_t *t = NULL;
    libusb_device **list = NULL;
    libusb_device *dev = NULL;
    int r;
    if (!out) return rig_fail(RIG_ERR_INVALID, "apt: NULL output handle");
    *out = NULL;
    if (serial && !*serial) serial = NULL;
    t = calloc(1, sizeof *t);
    apt_t *a = calloc(1, sizeof *a);
    if (!t || !a) {
        free(t);
        free(a);
        return rig_fail(RIG_ERR_NO_MEM, "apt: out of memory");
    }
    t->ops = &apt_ops;
    t->impl = a;
    snprintf(t->name, sizeof t->name, "apt%s%s", serial ? " serial " : "", serial ? serial : "");
    a->ftdi = ftdi_new();
    if (!a->ftdi) {
        // ftdi_new fails when libusb_init does (no usbfs here, e.g. in a container) or out of memory
        r = rig_fail(RIG_ERR_IO, "apt: cannot initialise libftdi/libusb: is USB available here (/dev/bus/usb)?");
        goto fail;
    }
    if ((r = find_device(a->ftdi, serial, &list, &dev))) goto fail;
    int fr = ftdi_usb_open_dev(a->ftdi, dev);
    libusb_free_device_list(list, 1);
    if (fr < 0) {
        if (fr == -8)
            r = rig_fail(RIG_ERR_ACCESS, "%s: permission denied: %s", t->name, UDEV_HINT);
        else if (fr == -5 || fr == -3)
            r = rig_fail(RIG_ERR_BUSY, "%s: cannot claim the USB interface (%s): close other programs using "
                         "the stage", t->name, ftdi_get_error_string(a->ftdi));
        else
            r = rig_fail(RIG_ERR_IO, "%s: cannot open: %s: replug the stage", t->name,
                         ftdi_get_error_string(a->ftdi));
        goto fail;
    }
    char usb_serial[32] = "";
    if (!serial) {
        // name it by the USB serial until HW_GET_INFO arrives
        ftdi_usb_get_strings2(a->ftdi, libusb_get_device(a->ftdi->usb_dev), NULL, 0, NULL, 0, usb_serial,
                              sizeof usb_serial);
        if (usb_serial[0]) snprintf(t->name, sizeof t->name, "apt serial %s", usb_serial);
    }
    if ((r = setup_ftdi(t)) || (r = hw_info(t, stage_model))) goto fail;
    if ((r = send_short(t, MOD_SET_CHANENABLESTATE, APT_CHAN, 1, "MOD_SET_CHANENABLESTATE"))) goto fail;
    if ((r = read_motion_params(t)) || (r = request_status(t))) goto fail;
    *out = t;
    return 0;
fail:
    apt_close(t);
    return r;
}
