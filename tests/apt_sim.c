// tests/apt_sim.c — simulated FTDI + Thorlabs APT controller for umockdev
// (see apt_sim.h). Everything below runs in umockdev's ioctl worker thread,
// under one mutex shared with apt_sim_stats().
#define _GNU_SOURCE
#include "tests/apt_sim.h"

#include <errno.h>
#include <linux/capability.h>
#include <linux/usbdevice_fs.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/ioctl.h>
#include <sys/stat.h>
#include <sys/syscall.h>
#include <unistd.h>
#include <umockdev.h>

enum { MAX_DEVS = 4 };
enum { MOTION_IDLE, MOTION_HOME, MOTION_MOVE, MOTION_DECEL };

// APT status bits (MOT_GET_STATUSUPDATE / DCSTATUSUPDATE)
#define SB_FWD      0x00000010u
#define SB_REV      0x00000020u
#define SB_CONN     0x00000100u
#define SB_HOMING   0x00000200u
#define SB_HOMED    0x00000400u
#define SB_ERROR    0x00004000u
#define SB_ENABLED  0x80000000u

typedef struct {
    UMockdevIoctlData *urb, *buf;
    bool discarded;
    double t_s;
} urb_t;

typedef struct apt_sim apt_sim_t;

typedef struct {
    apt_sim_t *sim;
    apt_sim_device_t cfg;
    char serial[32], model[16], node[64];
    UMockdevIoctlBase *handler;
    GQueue pending;
    GByteArray *out;                 // APT bytes waiting to go to the host
    // motion, in counts
    int motion;
    double t0_s, dur_s, p0, dist, dir;   // trapezoid or deceleration from p0
    double v0;                           // deceleration start speed, counts/s
    bool homed, error_bit, gone, enabled;
    uint32_t limit_bits;
    bool fault_motion, fault_unplug, fault_limit;   // armed for the next move
    double fault_at_s;                   // when the armed fault fires (0 = none)
    int fault_kind;                      // 1 motion error, 2 unplug, 3 limit switch
    // update messages
    double next_update_s;
    int unacked;
    bool owe_status_only;            // trickle: a status-only transfer comes next
    apt_sim_stats_t st;
} sim_dev_t;

struct apt_sim {
    UMockdevTestbed *tb;
    GMutex lock;
    int n;
    sim_dev_t dev[MAX_DEVS];
    bool caps_dropped;
    uint32_t saved_caps[2];
};

apt_sim_device_t apt_sim_device_defaults(void)
{
    return (apt_sim_device_t){
        .serial = "55000001", .model = "K10CR1", .counts_per_deg = 136533.33,
        .speed_deg_s = 900, .accel_deg_s2 = 9000, .home_time_s = 0.05, .home_offset_deg = 4,
        .update_period_s = 0.01, .max_unacked = 20,
    };
}

bool apt_sim_available(void)
{
    const char *p = getenv("LD_PRELOAD");
    return p && strstr(p, "libumockdev-preload");
}

static double now_s(void) { return g_get_monotonic_time() * 1e-6; }

// ---------------------------------------------------------------------------
// Motion

static double trap_dist(double D, double v, double a, double t)
{
    // distance covered after t on a trapezoid (or triangle) of length D
    double ta = v / a, da = 0.5 * a * ta * ta;
    if (2 * da > D) {
        ta = sqrt(D / a);
        double T = 2 * ta;
        if (t >= T) return D;
        if (t <= ta) return 0.5 * a * t * t;
        double r = T - t;
        return D - 0.5 * a * r * r;
    }
    double tc = (D - 2 * da) / v, T = 2 * ta + tc;
    if (t >= T) return D;
    if (t <= ta) return 0.5 * a * t * t;
    if (t <= ta + tc) return da + v * (t - ta);
    double r = T - t;
    return D - 0.5 * a * r * r;
}

static double trap_time(double D, double v, double a)
{
    double ta = v / a;
    if (a * ta * ta > D) return 2 * sqrt(D / a);
    return 2 * ta + (D - a * ta * ta) / v;
}

static double trap_speed(double D, double v, double a, double t)
{
    double h = 1e-4;
    return fabs(trap_dist(D, v, a, t + h) - trap_dist(D, v, a, t)) / h;
}

static double cur_pos(sim_dev_t *d, double t)
{
    double e = t - d->t0_s;
    double v = d->cfg.speed_deg_s * d->cfg.counts_per_deg, a = d->cfg.accel_deg_s2 * d->cfg.counts_per_deg;
    switch (d->motion) {
    case MOTION_MOVE: return d->p0 + d->dir * trap_dist(d->dist, v, a, e);
    case MOTION_DECEL: {
        double te = fmin(e, d->v0 / a);
        return d->p0 + d->dir * (d->v0 * te - 0.5 * a * te * te);
    }
    case MOTION_HOME: return d->p0 * fmax(0, 1 - e / d->dur_s);
    default: return d->p0;
    }
}

static uint32_t status_bits(sim_dev_t *d)
{
    uint32_t s = SB_CONN | (d->enabled ? SB_ENABLED : 0);
    if (d->homed) s |= SB_HOMED;
    if (d->error_bit) s |= SB_ERROR;
    s |= d->limit_bits;
    if (d->motion == MOTION_HOME) s |= SB_HOMING | SB_REV;
    if (d->motion == MOTION_MOVE || d->motion == MOTION_DECEL) s |= d->dir > 0 ? SB_FWD : SB_REV;
    return s;
}

// ---------------------------------------------------------------------------
// APT messages to the host

static void put_u16(uint8_t *p, unsigned v) { p[0] = v & 0xff; p[1] = (v >> 8) & 0xff; }
static void put_u32(uint8_t *p, uint32_t v) { for (int i = 0; i < 4; i++) p[i] = (v >> (8 * i)) & 0xff; }

static void send_short(sim_dev_t *d, unsigned id, uint8_t p1, uint8_t p2)
{
    uint8_t m[6];
    put_u16(m, id);
    m[2] = p1; m[3] = p2; m[4] = 0x01; m[5] = 0x50;
    g_byte_array_append(d->out, m, 6);
}

static void send_long(sim_dev_t *d, unsigned id, const uint8_t *data, unsigned len)
{
    uint8_t m[6];
    put_u16(m, id);
    put_u16(m + 2, len);
    m[4] = 0x81; m[5] = 0x50;
    g_byte_array_append(d->out, m, 6);
    g_byte_array_append(d->out, data, len);
}

static void send_status(sim_dev_t *d, unsigned id, double t)
{
    uint8_t s[14] = { 0 };
    int32_t pos = (int32_t)lround(cur_pos(d, t));
    put_u16(s, 1);
    put_u32(s + 2, (uint32_t)pos);
    if (id == 0x0481) put_u32(s + 6, (uint32_t)pos);   // encoder count; DC: velocity + reserved = 0
    put_u32(s + 10, status_bits(d));
    send_long(d, id, s, 14);
}

static unsigned update_id(sim_dev_t *d) { return strcmp(d->model, "K10CR1") == 0 ? 0x0481 : 0x0491; }

static void start_move(sim_dev_t *d, double target, double t)
{
    double p = cur_pos(d, t);
    d->p0 = p;
    d->dist = fabs(target - p);
    d->dir = target >= p ? 1 : -1;
    d->t0_s = t;
    d->motion = MOTION_MOVE;
    d->error_bit = false;
    d->limit_bits = 0;
    d->dur_s = trap_time(d->dist, d->cfg.speed_deg_s * d->cfg.counts_per_deg,
                         d->cfg.accel_deg_s2 * d->cfg.counts_per_deg);
    d->st.last_target = (int32_t)lround(target);
    if (d->fault_motion || d->fault_unplug || d->fault_limit) {
        d->fault_kind = d->fault_motion ? 1 : d->fault_unplug ? 2 : 3;
        d->fault_motion = d->fault_unplug = d->fault_limit = false;
        d->fault_at_s = t + 0.5 * d->dur_s;
    }
}

// Advance the simulated controller to time t: finished motions, faults, updates.
static void tick(sim_dev_t *d, double t)
{
    if (d->gone) return;
    if (d->fault_at_s > 0 && t >= d->fault_at_s) {
        double p = cur_pos(d, d->fault_at_s);
        d->fault_at_s = 0;
        if (d->fault_kind == 2) {
            d->gone = true;
            return;
        }
        d->p0 = p;
        if (d->fault_kind == 3)
            d->limit_bits = d->dir > 0 ? 0x01 : 0x02;
        else
            d->error_bit = true;
        d->motion = MOTION_IDLE;
        send_status(d, 0x0466, t);       // MOVE_STOPPED with the error or limit bit
    }
    if (d->motion == MOTION_MOVE && t >= d->t0_s + d->dur_s) {
        d->p0 = d->p0 + d->dir * d->dist;
        d->motion = MOTION_IDLE;
        send_status(d, 0x0464, t);       // MOVE_COMPLETED
    } else if (d->motion == MOTION_HOME && t >= d->t0_s + d->dur_s) {
        d->p0 = 0;
        d->motion = MOTION_IDLE;
        d->homed = true;
        send_short(d, 0x0444, 1, 0);     // MOVE_HOMED
    } else if (d->motion == MOTION_DECEL) {
        double a = d->cfg.accel_deg_s2 * d->cfg.counts_per_deg;
        if (t >= d->t0_s + d->v0 / a) {
            d->p0 = cur_pos(d, t);
            d->motion = MOTION_IDLE;
            send_status(d, 0x0466, t);   // MOVE_STOPPED
        }
    }
    if (d->st.updates_on && t >= d->next_update_s) {
        d->next_update_s = t + d->cfg.update_period_s;
        if (d->unacked >= d->cfg.max_unacked) {
            d->st.updates_on = false;
            d->st.updates_starved = true;
        } else {
            send_status(d, update_id(d), t);
            d->unacked++;
            d->st.n_updates_sent++;
        }
    }
}

static int32_t sat_i32(double v) { return v >= 2147483647.0 ? INT32_MAX : v <= -2147483648.0 ? INT32_MIN : (int32_t)lround(v); }

static int32_t get_i32(const uint8_t *p) { return (int32_t)((uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24); }

// One APT message from the host (whole messages: the driver writes each in one call).
static void apt_rx(sim_dev_t *d, const uint8_t *b, int n, double t)
{
    while (n >= 6) {
        unsigned id = b[0] | b[1] << 8;
        int len = (b[4] & 0x80) ? 6 + (b[2] | b[3] << 8) : 6;
        if (len > n) return;
        d->st.n_messages++;
        if (!d->cfg.no_reply) {
            switch (id) {
            case 0x0005: {   // HW_REQ_INFO -> HW_GET_INFO
                uint8_t m[84] = { 0 };
                if (d->cfg.garbage_before_info) {
                    static const uint8_t junk[] = { 0x00, 0xff, 0x06, 0x00, 0x54, 0x00, 0x81, 0x13, 0x37 };
                    g_byte_array_append(d->out, junk, sizeof junk);
                }
                put_u32(m, (uint32_t)strtoul(d->serial, NULL, 10));
                memcpy(m + 4, d->model, strnlen(d->model, 8));
                put_u16(m + 12, 45);
                m[14] = 3; m[15] = 0; m[16] = 1;           // firmware 1.0.3
                memcpy(m + 18, "APT simulator", 13);
                put_u16(m + 78, 1);
                put_u16(m + 82, 1);
                send_long(d, 0x0006, m, 84);
                d->st.n_info++;
                break;
            }
            case 0x0011: d->st.updates_on = true; d->unacked = 0; d->next_update_s = t; break;
            case 0x0012: d->st.updates_on = false; break;
            case 0x0210: d->enabled = b[3] == 1; d->st.n_enable++; break;
            case 0x0211: send_short(d, 0x0212, 1, d->enabled ? 1 : 2); break;
            case 0x0443:     // MOVE_HOME
                d->p0 = cur_pos(d, t);
                d->motion = MOTION_HOME;
                d->t0_s = t;
                d->dur_s = d->cfg.home_time_s;
                d->homed = false;
                d->error_bit = false;
                d->st.n_home++;
                break;
            case 0x0448:     // MOVE_RELATIVE (long form)
                if (len >= 12) {
                    d->st.n_move_rel++;
                    double p = d->motion == MOTION_IDLE ? d->p0 : cur_pos(d, t);
                    start_move(d, p + get_i32(b + 8), t);
                }
                break;
            case 0x0453:     // MOVE_ABSOLUTE (long form)
                if (len >= 12) {
                    d->st.n_move_abs++;
                    start_move(d, get_i32(b + 8), t);
                }
                break;
            case 0x0465: {   // MOVE_STOP
                d->st.n_stop++;
                d->st.last_stop_mode = b[3];
                double p = cur_pos(d, t);
                if (d->motion == MOTION_MOVE && b[3] == 2) {
                    double v = d->cfg.speed_deg_s * d->cfg.counts_per_deg, a = d->cfg.accel_deg_s2 * d->cfg.counts_per_deg;
                    d->v0 = trap_speed(d->dist, v, a, t - d->t0_s);
                    d->p0 = p;
                    d->t0_s = t;
                    d->motion = MOTION_DECEL;
                } else {
                    d->p0 = p;
                    d->motion = MOTION_IDLE;
                    send_status(d, 0x0466, t);
                }
                d->fault_at_s = 0;
                break;
            }
            case 0x0411: {   // REQ_POSCOUNTER
                uint8_t m[6];
                put_u16(m, 1);
                put_u32(m + 2, (uint32_t)lround(cur_pos(d, t)));
                send_long(d, 0x0412, m, 6);
                break;
            }
            case 0x0414:     // REQ_VELPARAMS -> GET_VELPARAMS: channel, min vel, accel, max vel
            case 0x0441: {   // REQ_HOMEPARAMS -> GET_HOMEPARAMS: channel, dir, switch, velocity, offset
                bool vel = id == 0x0414;
                if (vel) d->st.n_velparams++;
                else d->st.n_homeparams++;
                if (d->cfg.no_params) break;
                double cpd = d->cfg.counts_per_deg, vu = cpd * 53.68, au = cpd / 90.9;
                double hv = d->cfg.home_speed_deg_s > 0 ? d->cfg.home_speed_deg_s
                            : (360 + fabs(d->cfg.home_offset_deg)) / fmax(d->cfg.home_time_s, 1e-3);
                uint8_t m[14] = { 0 };
                put_u16(m, 1);
                if (vel) {
                    put_u32(m + 2, 0);
                    put_u32(m + 6, (uint32_t)sat_i32(d->cfg.accel_deg_s2 * au));
                    put_u32(m + 10, (uint32_t)sat_i32(d->cfg.speed_deg_s * vu));
                } else {
                    put_u16(m + 2, 2);
                    put_u16(m + 4, 1);
                    put_u32(m + 6, (uint32_t)sat_i32(hv * vu));
                    put_u32(m + 10, (uint32_t)sat_i32(d->cfg.home_offset_deg * cpd));
                }
                send_long(d, vel ? 0x0415 : 0x0442, m, 14);
                break;
            }
            case 0x0480: send_status(d, 0x0481, t); break;
            case 0x0490: send_status(d, 0x0491, t); break;
            case 0x0492: d->st.n_ack++; d->unacked = 0; break;
            default: break;
            }
        }
        b += len;
        n -= len;
    }
}

// Fill a bulk-IN buffer with 64-byte FTDI packets: 2 status bytes + <= 62 data bytes.
static int fill_in(sim_dev_t *d, uint8_t *buf, int cap)
{
    int off = 0;
    int most = d->cfg.trickle_bytes > 0 && d->cfg.trickle_bytes < 62 ? d->cfg.trickle_bytes : 62;
    while (d->out->len > 0 && off + 64 <= cap) {
        int k = (int)d->out->len < most ? (int)d->out->len : most;
        buf[off] = 0x31;
        buf[off + 1] = 0x60;
        memcpy(buf + off + 2, d->out->data, k);
        g_byte_array_remove_range(d->out, 0, k);
        off += 2 + k;
        if (k < 62) break;   // a short packet ends the transfer
    }
    return off;
}

// ---------------------------------------------------------------------------
// usbdevfs

static void control(sim_dev_t *d, struct usbdevfs_urb *u, uint8_t *s)
{
    unsigned type = s[0], req = s[1], val = s[2] | s[3] << 8, idx = s[4] | s[5] << 8, len = s[6] | s[7] << 8;
    (void)idx;
    u->actual_length = 0;
    if (type == 0x80 && req == 6 && s[3] == 3) {      // GET_DESCRIPTOR(string)
        const char *str[] = { NULL, "Thorlabs", "Kinesis K10CR1 Rotary Stage", d->serial };
        uint8_t sd[128];
        int n;
        unsigned i = s[2];
        if (i == 0) {
            sd[0] = 4; sd[1] = 3; sd[2] = 0x09; sd[3] = 0x04;
            n = 4;
        } else if (i < 4) {
            size_t L = strlen(str[i]);
            n = 2 + 2 * (int)L;
            sd[0] = n; sd[1] = 3;
            for (size_t k = 0; k < L; k++) { sd[2 + 2 * k] = str[i][k]; sd[3 + 2 * k] = 0; }
        } else {
            u->status = -EPIPE;
            return;
        }
        if (n > (int)len) n = len;
        memcpy(s + 8, sd, n);
        u->actual_length = n;
    } else if (type == 0x40) {                         // FTDI vendor requests
        switch (req) {
        case 0: if (val == 1 || val == 0) g_byte_array_set_size(d->out, 0); break;   // reset / purge RX
        case 1: if (val & 0x0200) d->st.rts_on = val & 0x02; break;
        case 2: d->st.flow_ctrl = idx >> 8; break;
        case 3: d->st.baud_divisor = val; break;
        case 9: d->st.latency_ms = val & 0xff; break;
        default: break;
        }
    } else if (type == 0xC0 && req == 5 && len >= 2) { // modem status
        s[8] = 0x31; s[9] = 0x60;
        u->actual_length = 2;
    } else if (type == 0xC0 && req == 10 && len >= 1) { // latency timer
        s[8] = d->st.latency_ms;
        u->actual_length = 1;
    }
}

static void urb_free(urb_t *p)
{
    g_object_unref(p->buf);
    g_object_unref(p->urb);
    g_free(p);
}

static gboolean on_ioctl(UMockdevIoctlBase *h, UMockdevIoctlClient *c, gpointer ud)
{
    sim_dev_t *d = ud;
    gulong req = umockdev_ioctl_client_get_request(c);
    UMockdevIoctlData *arg = umockdev_ioctl_client_get_arg(c);
    GError *e = NULL;
    UMockdevIoctlData *data = NULL;
    g_mutex_lock(&d->sim->lock);
    double t = now_s();
    tick(d, t);
    if (d->gone) {
        // unplugged: pending URBs come back with -ESHUTDOWN, then ENODEV
        urb_t *p = (req == USBDEVFS_REAPURB || req == USBDEVFS_REAPURBNDELAY) ? g_queue_pop_head(&d->pending) : NULL;
        if (p) {
            data = umockdev_ioctl_data_resolve(arg, 0, _IOC_SIZE(req), &e);
            ((struct usbdevfs_urb *)p->urb->data)->status = -ESHUTDOWN;
            ((struct usbdevfs_urb *)p->urb->data)->actual_length = 0;
            umockdev_ioctl_data_set_ptr(data, 0, p->urb);
            umockdev_ioctl_client_complete(c, 0, 0);
            urb_free(p);
        } else
            umockdev_ioctl_client_complete(c, -1, ENODEV);
        goto done;
    }
    if (_IOC_SIZE(req) > 0 && arg) data = umockdev_ioctl_data_resolve(arg, 0, _IOC_SIZE(req), &e);
    if (req == USBDEVFS_GET_CAPABILITIES) {
        *(uint32_t *)data->data = USBDEVFS_CAP_BULK_CONTINUATION | USBDEVFS_CAP_NO_PACKET_SIZE_LIM;
        umockdev_ioctl_client_complete(c, 0, 0);
    } else if (req == USBDEVFS_CLAIMINTERFACE || req == USBDEVFS_RELEASEINTERFACE || req == USBDEVFS_RESET ||
               req == USBDEVFS_CLEAR_HALT || req == USBDEVFS_DISCONNECT_CLAIM || req == USBDEVFS_SETCONFIGURATION ||
               req == USBDEVFS_SETINTERFACE) {
        umockdev_ioctl_client_complete(c, 0, 0);
    } else if (req == USBDEVFS_GETDRIVER || req == USBDEVFS_IOCTL) {
        umockdev_ioctl_client_complete(c, -1, ENODATA);   // no kernel driver bound
    } else if (req == USBDEVFS_SUBMITURB) {
        struct usbdevfs_urb *u = (void *)data->data;
        urb_t *p = g_new0(urb_t, 1);
        p->urb = g_object_ref(data);
        p->t_s = t;
        p->buf = umockdev_ioctl_data_resolve(data, G_STRUCT_OFFSET(struct usbdevfs_urb, buffer), u->buffer_length, &e);
        u->status = 0;
        if (u->type == USBDEVFS_URB_TYPE_CONTROL)
            control(d, u, p->buf->data);
        else if (!(u->endpoint & 0x80)) {
            apt_rx(d, p->buf->data, u->buffer_length, t);
            u->actual_length = u->buffer_length;
        }
        g_queue_push_tail(&d->pending, p);
        umockdev_ioctl_client_complete(c, 0, 0);
    } else if (req == USBDEVFS_DISCARDURB) {
        gulong addr = *(gulong *)arg->data;
        bool found = false;
        for (GList *l = d->pending.head; l; l = l->next) {
            urb_t *p = l->data;
            if (p->urb->client_addr == addr) {
                p->discarded = true;
                ((struct usbdevfs_urb *)p->urb->data)->status = -ENOENT;
                found = true;
            }
        }
        umockdev_ioctl_client_complete(c, found ? 0 : -1, found ? 0 : EINVAL);
    } else if (req == USBDEVFS_REAPURB || req == USBDEVFS_REAPURBNDELAY) {
        urb_t *ready = NULL;
        double latency_s = (d->st.latency_ms > 0 ? d->st.latency_ms : 16) * 1e-3;
        for (GList *l = d->pending.head; l; l = l->next) {
            urb_t *p = l->data;
            struct usbdevfs_urb *u = (void *)p->urb->data;
            if (p->discarded || u->type == USBDEVFS_URB_TYPE_CONTROL || !(u->endpoint & 0x80)) { ready = p; break; }
            if (d->cfg.trickle_bytes > 0 && d->owe_status_only) {
                p->buf->data[0] = 0x31;
                p->buf->data[1] = 0x60;
                u->actual_length = 2;
                d->owe_status_only = false;
                ready = p;
                break;
            }
            if (!d->cfg.no_reply && d->out->len) {
                u->actual_length = fill_in(d, p->buf->data, u->buffer_length);
                d->owe_status_only = d->cfg.trickle_bytes > 0;
                ready = p;
                break;
            }
            if (t - p->t_s >= latency_s) {   // FTDI latency timer: status bytes only
                p->buf->data[0] = 0x31;
                p->buf->data[1] = 0x60;
                u->actual_length = 2;
                ready = p;
                break;
            }
        }
        if (ready) {
            g_queue_remove(&d->pending, ready);
            umockdev_ioctl_data_set_ptr(data, 0, ready->urb);
            umockdev_ioctl_client_complete(c, 0, 0);
            urb_free(ready);
        } else
            umockdev_ioctl_client_complete(c, -1, EAGAIN);
    } else {
        umockdev_ioctl_client_complete(c, -1, ENOTTY);
    }
done:
    d->st.position = (int32_t)lround(cur_pos(d, t));
    d->st.status_bits = status_bits(d);
    g_mutex_unlock(&d->sim->lock);
    if (data) g_object_unref(data);
    if (e) g_error_free(e);
    return TRUE;
}

// ---------------------------------------------------------------------------
// Set-up

static void replace(GString *s, const char *from, const char *to) { g_string_replace(s, from, to, 0); }

// Process capabilities: as root, open() ignores file modes unless
// CAP_DAC_OVERRIDE / CAP_DAC_READ_SEARCH are dropped from the effective set.
static bool caps_get(uint32_t eff[2], struct __user_cap_data_struct cd[2])
{
    struct __user_cap_header_struct hd = { _LINUX_CAPABILITY_VERSION_3, 0 };
    if (syscall(SYS_capget, &hd, cd) != 0) return false;
    eff[0] = cd[0].effective;
    eff[1] = cd[1].effective;
    return true;
}

static bool caps_set_effective(const uint32_t eff[2])
{
    struct __user_cap_header_struct hd = { _LINUX_CAPABILITY_VERSION_3, 0 };
    struct __user_cap_data_struct cd[2];
    uint32_t old[2];
    if (!caps_get(old, cd)) return false;
    cd[0].effective = eff[0];
    cd[1].effective = eff[1];
    return syscall(SYS_capset, &hd, cd) == 0;
}

apt_sim_t *apt_sim_new(const char *umockdev_file, const apt_sim_device_t *devs, int n, char *err, int err_len)
{
    GError *e = NULL;
    gchar *text = NULL;
    apt_sim_t *s = NULL;
    if (!apt_sim_available()) {
        snprintf(err, err_len, "not running under umockdev-wrapper");
        return NULL;
    }
    if (n < 0 || n > MAX_DEVS) {
        snprintf(err, err_len, "0 to %d devices", MAX_DEVS);
        return NULL;
    }
    if (!g_file_get_contents(umockdev_file, &text, NULL, &e)) {
        snprintf(err, err_len, "%s", e->message);
        goto fail;
    }
    s = g_new0(apt_sim_t, 1);
    g_mutex_init(&s->lock);
    s->tb = umockdev_testbed_new();
    s->n = n;
    bool deny = false;
    for (int i = 0; i < n; i++) {
        sim_dev_t *d = &s->dev[i];
        d->sim = s;
        d->cfg = devs[i];
        snprintf(d->serial, sizeof d->serial, "%s", devs[i].serial ? devs[i].serial : "55000001");
        snprintf(d->model, sizeof d->model, "%s", devs[i].model ? devs[i].model : "K10CR1");
        d->out = g_byte_array_new();
        g_queue_init(&d->pending);
        d->fault_motion = devs[i].motion_error;
        d->fault_unplug = devs[i].unplug_mid_move;
        d->fault_limit = devs[i].limit_mid_move;
        d->enabled = false;
        snprintf(d->node, sizeof d->node, "/dev/bus/usb/001/%03d", i + 2);
        GString *g = g_string_new(text);
        char a[64], b[64];
        snprintf(a, sizeof a, "usb1/1-%d", i + 1);
        replace(g, "usb1/1-1", a);
        snprintf(a, sizeof a, "bus/usb/001/%03d", i + 2);
        replace(g, "bus/usb/001/002", a);
        snprintf(a, sizeof a, "DEVNUM=%03d", i + 2);
        replace(g, "DEVNUM=002", a);
        snprintf(a, sizeof a, "devnum=%d", i + 2);
        replace(g, "devnum=2", a);
        snprintf(a, sizeof a, "devpath=%d", i + 1);
        replace(g, "devpath=1", a);
        snprintf(a, sizeof a, "dev=189:%d", i + 1);
        replace(g, "dev=189:1", a);
        snprintf(a, sizeof a, "MINOR=%d", i + 1);
        replace(g, "MINOR=1", a);
        snprintf(b, sizeof b, "%s", d->serial);
        replace(g, "55000001", b);
        bool ok = umockdev_testbed_add_from_string(s->tb, g->str, &e);
        g_string_free(g, TRUE);
        if (!ok) {
            snprintf(err, err_len, "umockdev: %s", e->message);
            goto fail;
        }
        d->handler = umockdev_ioctl_base_new();
        g_signal_connect(d->handler, "handle-ioctl", G_CALLBACK(on_ioctl), d);
        if (!umockdev_testbed_attach_ioctl(s->tb, d->node, d->handler, &e)) {
            snprintf(err, err_len, "umockdev attach %s: %s", d->node, e->message);
            goto fail;
        }
        if (devs[i].deny_access) {
            char path[512];
            gchar *root = umockdev_testbed_get_root_dir(s->tb);   // owned by us
            snprintf(path, sizeof path, "%s%s", root, d->node);
            g_free(root);
            if (chmod(path, 0) != 0) {
                snprintf(err, err_len, "chmod %s: %s", path, strerror(errno));
                goto fail;
            }
            deny = true;
        }
    }
    if (deny) {
        struct __user_cap_data_struct cd[2];
        if (caps_get(s->saved_caps, cd)) {
            uint32_t eff[2] = { s->saved_caps[0] & ~((1u << CAP_DAC_OVERRIDE) | (1u << CAP_DAC_READ_SEARCH)),
                                s->saved_caps[1] };
            s->caps_dropped = caps_set_effective(eff);
        }
    }
    g_free(text);
    return s;
fail:
    if (e) g_error_free(e);
    g_free(text);
    apt_sim_free(s);
    return NULL;
}

void apt_sim_stats(apt_sim_t *s, int dev, apt_sim_stats_t *out)
{
    memset(out, 0, sizeof *out);
    if (!s || dev < 0 || dev >= s->n) return;
    g_mutex_lock(&s->lock);
    *out = s->dev[dev].st;
    g_mutex_unlock(&s->lock);
}

void apt_sim_free(apt_sim_t *s)
{
    if (!s) return;
    if (s->caps_dropped) caps_set_effective(s->saved_caps);
    if (s->tb) g_object_unref(s->tb);   // stops the ioctl handlers
    for (int i = 0; i < s->n; i++) {
        sim_dev_t *d = &s->dev[i];
        if (d->handler) g_object_unref(d->handler);
        urb_t *p;
        while ((p = g_queue_pop_head(&d->pending))) urb_free(p);
        if (d->out) g_byte_array_free(d->out, TRUE);
    }
    g_mutex_clear(&s->lock);
    g_free(s);
}
