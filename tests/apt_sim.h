// tests/apt_sim.h — a simulated Thorlabs APT controller behind an FTDI chip,
// served to the unmodified libusb/libftdi1 code of rig/turntable/apt.c through
// libumockdev (a test fixture, not product code).
//
// The process must run under `umockdev-wrapper` (LD_PRELOAD of
// libumockdev-preload); apt_sim_new() creates a testbed, adds one USB device
// 0403:faf0 per entry of `devs` (described by tests/data/k10cr1.umockdev,
// renumbered and re-serialised for the second and later devices) and answers
// every usbdevfs ioctl on them from umockdev's worker thread:
//   - USB: capabilities, claim/release, string descriptors (manufacturer,
//     product, serial), FTDI vendor requests (reset, purge, baud rate, line,
//     flow control, modem control, latency timer, modem status), bulk IN in
//     64-byte packets with the two FTDI status bytes, the latency-timer
//     status-only packet when there is nothing to send, URB discard (libusb
//     time-outs).
//   - APT: HW_REQ_INFO, HW_NO_FLASH_PROGRAMMING, HW_START/STOP_UPDATEMSGS,
//     MOD_SET/REQ_CHANENABLESTATE, MOT_MOVE_HOME -> MOVE_HOMED,
//     MOT_MOVE_ABSOLUTE / MOVE_RELATIVE -> MOVE_COMPLETED, MOT_MOVE_STOP ->
//     MOVE_STOPPED, MOT_REQ_STATUSUPDATE / REQ_DCSTATUSUPDATE, REQ_POSCOUNTER,
//     MOT_ACK_DCSTATUSUPDATE, MOT_REQ_VELPARAMS (speed_deg_s, accel_deg_s2) and
//     MOT_REQ_HOMEPARAMS (home_speed_deg_s, home_offset_deg), in the APT units
//     of a stepper controller (counts/s x 53.68, counts/s^2 / 90.9; int32, so
//     the defaults' 900 deg/s read as ~293 deg/s). Motion is a trapezoid in encoder counts computed
//     from the clock; while update messages are on, a status update is sent
//     every update_period_ms and the updates stop after `max_unacked` of them
//     without an ACK_DCSTATUSUPDATE (the keep-alive).
//   - Faults (see apt_sim_device_t).
#pragma once

#include <stdbool.h>
#include <stdint.h>

typedef struct {
    const char *serial;          // "55000001"
    const char *model;           // 8-char APT model field, "K10CR1"
    double counts_per_deg;       // 136533.33
    double speed_deg_s;          // simulated cruise speed (fast for tests)
    double accel_deg_s2;
    double home_time_s;
    double home_speed_deg_s;     // MOT_GET_HOMEPARAMS velocity (0: a turn + offset in home_time_s)
    double home_offset_deg;      // MOT_GET_HOMEPARAMS offset distance
    double update_period_s;      // status update period while updates are on
    int    max_unacked;          // updates sent without ACK before they stop
    // Faults
    bool   no_reply;             // the FTDI chip works, the controller never answers
    bool   no_params;            // VELPARAMS/HOMEPARAMS requests go unanswered (older firmware)
    bool   deny_access;          // open() of the device node fails with EACCES
    bool   motion_error;         // the next move stops half way with status bit 0x4000
    bool   unplug_mid_move;      // the device disappears half way through the next move
    bool   limit_mid_move;       // the next move runs into a limit switch half way (bit 0x1/0x2)
    // Byte stream: at most this many APT bytes per bulk-IN transfer, each data
    // transfer followed by a status-only one, so the host gets messages in
    // pieces (0 = whole 62-byte packets, as many as fit)
    int    trickle_bytes;
    bool   garbage_before_info;  // junk bytes on the line before HW_GET_INFO
} apt_sim_device_t;

// Defaults: a K10CR1 with serial 55000001, 900 deg/s, 9000 deg/s^2, homing
// 0.05 s, updates every 10 ms, 20 unacknowledged updates allowed, no faults.
apt_sim_device_t apt_sim_device_defaults(void);

typedef struct {
    int  n_messages;             // APT messages received (any)
    int  n_info, n_enable, n_home, n_move_abs, n_move_rel, n_stop;
    int  last_stop_mode;         // 1 immediate, 2 profiled
    int  n_ack;                  // MOT_ACK_DCSTATUSUPDATE received
    int  n_velparams, n_homeparams;   // MOT_REQ_VELPARAMS / MOT_REQ_HOMEPARAMS received
    int  n_updates_sent;         // status updates sent while updates were on
    bool updates_on;
    bool updates_starved;        // updates stopped for lack of ACK
    int  latency_ms;             // as set by the host
    int  baud_divisor;           // raw SET_BAUDRATE value
    int  flow_ctrl;              // raw SET_FLOW_CTRL index high byte
    bool rts_on;
    int32_t position;            // counts
    uint32_t status_bits;
    int32_t last_target;         // counts of the last absolute/relative move
} apt_sim_stats_t;

typedef struct apt_sim apt_sim_t;

// NULL (with a message in err) when not under umockdev-wrapper or on failure.
// n = 0 makes a testbed with no device at all.
// umockdev_file: path of the device description (tests/data/k10cr1.umockdev).
apt_sim_t *apt_sim_new(const char *umockdev_file, const apt_sim_device_t *devs, int n,
                       char *err, int err_len);
void apt_sim_stats(apt_sim_t *s, int dev, apt_sim_stats_t *out);
void apt_sim_free(apt_sim_t *s);
// True when the process runs with libumockdev-preload (under umockdev-wrapper).
bool apt_sim_available(void);
