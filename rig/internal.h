// rig/internal.h — inside the device code of rig/: the ops tables every
// backend implements and the device structs behind the opaque handles of
// rig/devices.h. Callers outside the device code (capture, commands, other
// modules) use rig/devices.h only; tests may include this to build a backend.
#pragma once

#include "rig/devices.h"

#ifdef __cplusplus
extern "C" {
#endif

// The ops table every turntable backend implements. An optional operation left
// NULL makes the wrapper return RIG_ERR_NOT_SUPPORTED.
typedef struct {
    const char *backend;       // "apt", "sim"
    int  (*info)(rig_turntable_t *t, rig_turntable_info_t *out);
    int  (*status)(rig_turntable_t *t, rig_turntable_status_t *out);
    int  (*start_home)(rig_turntable_t *t);
    int  (*start_move_abs_deg)(rig_turntable_t *t, double angle_deg);
    // Optional: NULL makes rig_turntable_move_rel_deg read the position and
    // move to position + delta with start_move_abs_deg.
    int  (*start_move_rel_deg)(rig_turntable_t *t, double delta_deg);
    // Wait until the current motion (home or move) completes; RIG_ERR_TIMEOUT
    // after timeout_s, RIG_ERR_MOTION / RIG_ERR_LIMIT / RIG_ERR_DISCONNECTED as found.
    int  (*wait)(rig_turntable_t *t, double timeout_s);
    int  (*stop)(rig_turntable_t *t, bool immediate);
    // Optional: begin a stop and return at once (wait then waits for it to
    // end, successfully); NULL makes rig_turntable_wait_watched use stop.
    int  (*start_stop)(rig_turntable_t *t, bool immediate);
    void (*close)(rig_turntable_t *t);
} rig_turntable_ops_t;

struct rig_turntable {
    const rig_turntable_ops_t *ops;
    char name[96];             // for messages: "apt K10CR1 serial 55000001"
    void *impl;
};

typedef struct {
    const char *backend;        // "gpiod", "sim"
    int  (*set)(rig_lamps_t *l, uint32_t on_mask);   // bit i: lamp i on
    void (*close)(rig_lamps_t *l);                   // all off, release
    // Async-signal-safe: all lines off, nothing else (used by the signal handler).
    void (*emergency_off)(rig_lamps_t *l);
} rig_lamps_ops_t;

struct rig_lamps {
    const rig_lamps_ops_t *ops;
    int             n;
    rig_lamp_line_t lamps[32];
    uint32_t        on_mask;
    int64_t         on_since_ns[32];    // CLOCK_MONOTONIC when lamp i last turned on (the virtual rig's warm-up)
    void           *impl;
    // The lamp-state file (rig/lamps/state.c); state_fd -1: none kept.
    int             state_fd;
    char           *state_path;
    char           *state_off;          // the record "no lamp on", written by the signal handler
    size_t          state_off_len;
    uint32_t        state_mask;         // the lamps the file says are on
    long            state_pid;
    char            state_started[40];
};

// When lamp i last turned on (CLOCK_MONOTONIC ns; 0 never), for the virtual
// rig's lamp warm-up (rig/virtual/lamps.c); safe beside rig_lamps_set.
int64_t rig_lamps_on_since_ns(const rig_lamps_t *l, int i);

// Lamp sets: at most RIG_LAMPS_MAX lamps each, at most RIG_LAMPS_SAFETY_SLOTS
// open at once.
#define RIG_LAMPS_MAX 32
#define RIG_LAMPS_SAFETY_SLOTS 32
// Checks a lamp list (names, times) and allocates the set with ops: *made
// (NULL on error). For the backends' opens (rig/lamps/lamps.c).
int  rig_lamps_new(rig_lamps_t **out, rig_lamps_t **made, const rig_lamps_ops_t *ops,
                   const rig_lamp_line_t *lamps, int n);
// Enter an open set in the safety registry (switched off on signals and
// exit); false when RIG_LAMPS_SAFETY_SLOTS sets are already open.
bool rig_lamps_safety_register(rig_lamps_t *l);
// The lamp-state file (rig/lamps/state.c, its format there). state_open, for
// the backends' opens once the lines are held (all off): path NULL or "" = the
// default per-user file named after the hardware; takes the lock (RIG_ERR_BUSY
// naming the live refl that holds it), reports and switches off what a dead
// process left on, and records "none on". state_write records `on` (durable:
// flushed to disk, for lamps about to turn on). state_signal_off writes the
// "none on" record and nothing else (async-signal-safe). state_close writes it
// when lamps_off, then drops the lock; both do nothing for a set without a file.
int  rig_lamps_state_open(rig_lamps_t *l, const char *path);
int  rig_lamps_state_write(rig_lamps_t *l, uint32_t on, bool durable);
void rig_lamps_state_signal_off(rig_lamps_t *l);
void rig_lamps_state_close(rig_lamps_t *l, bool lamps_off);

typedef struct {
    const char *backend;             // "aravis"
    int  (*set_pixel_format)(rig_camera_t *c, const char *format);
    int  (*set_exposure_us)(rig_camera_t *c, double exposure_us);
    int  (*set_gain)(rig_camera_t *c, double gain);
    int  (*set_region)(rig_camera_t *c, int x, int y, int width, int height);
    int  (*set_stream_packets)(rig_camera_t *c, long packet_size, long packet_delay);   // -1: unchanged
    // Current settings (fills meta except frame_id/timestamps).
    int  (*settings)(rig_camera_t *c, rig_frame_meta_t *out);
    // One frame per software trigger: waits up to timeout_s, retries `retries`
    // times on a lost or incomplete frame, then fails with RIG_ERR_TIMEOUT.
    int  (*capture)(rig_camera_t *c, double timeout_s, int retries, rig_frame_t *out);
    void (*close)(rig_camera_t *c);
} rig_camera_ops_t;

struct rig_camera {
    const rig_camera_ops_t *ops;
    char name[128];                  // for messages: "aravis Fake camera serial GV01 at 127.0.0.1"
    void *impl;
};

#ifdef __cplusplus
}
#endif
