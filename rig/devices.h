// rig/devices.h — the public handle API of refl's devices: the turntable, the
// lamps and the cameras. The handles are opaque (their ops tables and structs
// are in rig/internal.h, for the backends); read a device's name, backend and
// lamp lines through the accessors below.
//
// Errors (one convention for every device call)
// - A device call returns 0 (RIG_ERR_OK) or a negative RIG_ERR_* code;
//   rig_strerror() names the code.
// - The detailed message goes to model_error (model/model.h): it is printed
//   to stderr (unless model_error_quiet) and kept as this thread's
//   model_last_error(), the one message store every layer reads. The message
//   names the device (backend, serial, chip/line) and says what to do.
// - Drivers write `return rig_fail(RIG_ERR_TIMEOUT, "...")`: rig_fail records
//   the message and returns the code. rig keeps no error buffer of its own.
//
// Units: angles in degrees (the turntable's own frame: 0 at home, positive
// counter-clockwise seen from above, i.e. about +z of the rig frame), times in
// seconds unless the name says _ms/_us.
//
// Every rig_*_close() accepts NULL. Lamps are switched off on close, on
// normal exit, on SIGINT/SIGTERM (see rig_safety_install) and on every error
// path that closes them.
#pragma once

#include <signal.h>
#include <stdbool.h>
#include <stdint.h>

#include "model/model.h"

#ifdef __cplusplus
extern "C" {
#endif


//   _(NAME, value, description)
#define RIG_ERR_LIST(_)                                                   \
    _(OK,            0,   "success")                                      \
    _(IO,           -1,   "input/output error")                           \
    _(NO_DEVICE,    -2,   "device not found")                             \
    _(ACCESS,       -3,   "permission denied")                            \
    _(BUSY,         -4,   "device busy")                                  \
    _(TIMEOUT,      -5,   "timed out")                                    \
    _(PROTOCOL,     -6,   "unexpected reply from the device")             \
    _(MOTION,       -7,   "motion error")                                 \
    _(LIMIT,        -8,   "limit switch reached")                         \
    _(NOT_HOMED,    -9,   "stage not homed")                              \
    _(INVALID,      -10,  "invalid argument")                             \
    _(NOT_SUPPORTED,-11,  "not supported by this device")                 \
    _(DISCONNECTED, -12,  "device disconnected")                          \
    _(NO_MEM,       -13,  "out of memory")                                \
    _(INTERRUPTED,  -14,  "interrupted")

enum {
#define RIG_ERR_ENUM_(name, value, desc) RIG_ERR_##name = value,
    RIG_ERR_LIST(RIG_ERR_ENUM_)
#undef RIG_ERR_ENUM_
};

const char *rig_strerror(int err);
// Record a detailed message through model_error (printed to stderr unless
// model_error_quiet; kept as model_last_error()) and return err, so drivers can
// write `return rig_fail(RIG_ERR_TIMEOUT, "...")`.
int         rig_fail(int err, const char *fmt, ...) __attribute__((format(printf, 2, 3)));

// ---------------------------------------------------------------------------
// Turntable

typedef struct {
    char   model[32];          // e.g. "K10CR1"
    char   serial[32];
    char   firmware[32];
    double counts_per_deg;     // encoder counts per degree (K10CR1: 136533.33)
    // Motion parameters for time estimates and time-outs: apt reads them from
    // the controller (MOT_GET_VELPARAMS, MOT_GET_HOMEPARAMS; params_from
    // "controller"), or takes rig_stage_models' when it does not answer
    // ("table", with a note: model_note); sim: its own ("sim", real time).
    double speed_deg_s, accel_deg_s2;
    double home_speed_deg_s;
    double home_time_s;        // the longest homing: a full turn to the switch plus the offset
    char   params_from[16];
} rig_turntable_info_t;

typedef struct {
    double angle_deg;          // measured position
    bool   moving, homing, homed;
    bool   limit_fwd, limit_rev;
    bool   motion_error;
} rig_turntable_status_t;

typedef struct rig_turntable rig_turntable_t;

// Stage models known to the APT driver and their counts per degree; NULL name
// ends the table.
typedef struct { const char *model; double counts_per_deg; double max_speed_deg_s; double accel_deg_s2; } rig_stage_model_t;
extern const rig_stage_model_t rig_stage_models[];

// Thorlabs APT over an FTDI chip (libftdi1): serial may be NULL for the only
// stage present; stage_model NULL = take it from HW_GET_INFO.
// Open errors: RIG_ERR_NO_DEVICE (none, or not that serial; the message lists
// what is there), RIG_ERR_INVALID (several stages and no serial), RIG_ERR_ACCESS
// (with a udev rule to add), RIG_ERR_BUSY, RIG_ERR_TIMEOUT (no reply to
// HW_REQ_INFO within 1 s: controller off), RIG_ERR_NOT_SUPPORTED (stage model
// not in rig_stage_models). Moves need a homed stage (RIG_ERR_NOT_HOMED).
// While waiting, status updates are on and acknowledged (keep-alive); the
// motion-error bit gives RIG_ERR_MOTION, an unexpected stop at a limit switch
// RIG_ERR_LIMIT, an unplugged device RIG_ERR_DISCONNECTED (every later call too).
int rig_turntable_open_apt(rig_turntable_t **out, const char *serial, const char *stage_model);

typedef struct {
    double speed_deg_s;         // cruise speed (K10CR1: 10)
    double accel_deg_s2;        // acceleration (K10CR1: 10)
    double home_time_s;         // time a homing takes
    double position_noise_deg;  // std of the measured position after a move
    double time_scale;          // 1 = real time; 0.01 = 100x faster (tests)
    uint64_t seed;
    // Fault injection: after this many completed moves (0 = never) the next
    // move fails with `fault` (RIG_ERR_MOTION, RIG_ERR_TIMEOUT = stall, RIG_ERR_DISCONNECTED)
    // half way through; the fault fires once. Moves need homing first, as on the stage.
    int    fault_after_moves;
    int    fault;
} rig_turntable_sim_params_t;

rig_turntable_sim_params_t rig_turntable_sim_defaults(void);   // K10CR1-like, real time
int rig_turntable_open_sim(rig_turntable_t **out, const rig_turntable_sim_params_t *p);
// A simulated stage in a plain move (no fault armed): true and the angle it
// will stand at when the move ends (its position noise is drawn as the move
// starts), so a simulator can prepare that state while the stage moves.
// false for other backends, when idle, homing, stopping or faulting.
bool rig_turntable_sim_destination(rig_turntable_t *t, double *angle_deg);
// Wrappers over the ops (check arguments; messages name the device).
int  rig_turntable_info(rig_turntable_t *t, rig_turntable_info_t *out);
int  rig_turntable_status(rig_turntable_t *t, rig_turntable_status_t *out);
int  rig_turntable_home(rig_turntable_t *t, double timeout_s);            // start + wait
int  rig_turntable_move_abs_deg(rig_turntable_t *t, double angle_deg, double timeout_s);
int  rig_turntable_move_rel_deg(rig_turntable_t *t, double delta_deg, double timeout_s);
int  rig_turntable_start_move_abs_deg(rig_turntable_t *t, double angle_deg);
int  rig_turntable_wait(rig_turntable_t *t, double timeout_s);
int  rig_turntable_stop(rig_turntable_t *t, bool immediate);
int  rig_turntable_start_home(rig_turntable_t *t);                        // returns at once
// Begins a stop and returns (rig_turntable_wait then waits for it); a
// backend that cannot stops fully here, as rig_turntable_stop.
int  rig_turntable_start_stop(rig_turntable_t *t, bool immediate);
// An interruptible wait for the motion under way (after start_home or
// start_move_abs_deg), in slices of 50 ms. When *interrupt becomes 1 the stage
// starts a profiled stop; when it is 2 or more (also during that stop) an
// immediate one; once it stands: RIG_ERR_INTERRUPTED, "NAME: WHAT interrupted:
// the stage stopped [at once] at X deg" (recorded for model_last_error, not
// printed: the caller words it). progress(ctx, elapsed, angle) every
// period_s while it moves. Other errors as rig_turntable_wait.
typedef struct {
    const volatile sig_atomic_t *interrupt;   // NULL: none
    const char *what;                          // "homing", "the move to 30 deg" (messages)
    double      stop_s;                        // a profiled stop's expected length (NAN: unknown)
    void      (*progress)(void *ctx, double elapsed_s, double angle_deg);
    void       *ctx;
    double      period_s;
} rig_turntable_watch_t;
int  rig_turntable_wait_watched(rig_turntable_t *t, double timeout_s, const rig_turntable_watch_t *w);
void rig_turntable_close(rig_turntable_t *t);
// Time a move of delta_deg takes with a trapezoidal profile.
double rig_motion_time_s(double delta_deg, double speed_deg_s, double accel_deg_s2);

// The turntable's name for messages ("apt K10CR1 serial 55000001", "sim
// turntable ...") and its backend ("apt", "sim"); "" for NULL.
const char *rig_turntable_name(const rig_turntable_t *t);
const char *rig_turntable_backend(const rig_turntable_t *t);

// ---------------------------------------------------------------------------
// Lamps

typedef struct {
    char     name[64];
    char     chip[64];          // gpiod: chip name ("gpiochip0") or path ("/dev/gpiochip0")
    unsigned line;              // gpiod: line offset
    bool     active_low;
    double   warmup_ms;         // after switching on, before light is stable
    double   settle_ms;         // after switching off
} rig_lamp_line_t;

typedef struct rig_lamps rig_lamps_t;
// libgpiod v1. Requests every line as output, consumer "refl", initially off
// (lines are requested active-high; active-low lamps are inverted by refl).
// A chip containing '/' is opened as a path, else by name. On any error the
// lines already requested are switched off and released.
int rig_lamps_open_gpiod(rig_lamps_t **out, const rig_lamp_line_t *lamps, int n);
// Both opens: 0..32 lamps with unique non-empty names, warmup_ms/settle_ms in
// [0, 3.6e6]; *out is NULL on error.
// Simulated lamps (state only; the virtual rig reads on_mask).
int rig_lamps_open_sim(rig_lamps_t **out, const rig_lamp_line_t *lamps, int n);
// The lamp-state file (rig/lamps/state.c): records which lamps are on, flushed
// before one turns on, so that after a death no handler sees (kill -9, the OOM
// killer, a power cut) the next open of the same lamps warns (model_warning)
// "the last session (pid N, started T) died with lamps A, B on; switching them
// off" and does. The open set holds an exclusive flock on it: an open while
// another live process holds it fails with RIG_ERR_BUSY naming that pid. The
// file says format_version = 1; a file of a higher version is refused
// (RIG_ERR_PROTOCOL, the lamps are not opened).
// gpiod: state_file NULL or "" = $XDG_STATE_HOME/refl (~/.local/state/refl)/
// gpiod-CHIP-LINE....state, named after the chips and lines; rig_lamps_open_gpiod
// uses that. sim: a file only when state_file is given (rig_lamps_open_sim: none).
int rig_lamps_open_gpiod_state(rig_lamps_t **out, const rig_lamp_line_t *lamps, int n, const char *state_file);
int rig_lamps_open_sim_state(rig_lamps_t **out, const rig_lamp_line_t *lamps, int n, const char *state_file);
const char *rig_lamps_state_file(const rig_lamps_t *l);   // "" when the set keeps none
// Switch to exactly on_mask and sleep the settle time the change needs (the
// longest warm-up of lamps switched on / settle of lamps switched off).
// RIG_ERR_INVALID for bits beyond the n lamps (nothing switched); when the
// backend fails every lamp is switched off and on_mask becomes 0.
int  rig_lamps_set(rig_lamps_t *l, uint32_t on_mask);
// The settle time a change from `from` to `to` needs, seconds (max of both;
// bits beyond the n lamps are ignored).
double rig_lamps_settle_s(const rig_lamps_t *l, uint32_t from, uint32_t to);
int  rig_lamps_all_off(rig_lamps_t *l);
int  rig_lamps_find(const rig_lamps_t *l, const char *name);   // index or -1
void rig_lamps_close(rig_lamps_t *l);

// Safety: after this, SIGINT/SIGTERM/SIGHUP/SIGQUIT, SIGSEGV/SIGBUS/SIGFPE/
// SIGABRT and exit() switch every open lamp set off (emergency_off; the state
// file then says so) before the process ends; the signals then re-raise with
// the default action, so the process still dies by that signal (with its core)
// (a signal the process ignores stays ignored). Later sigaction calls for
// these signals replace this (rig/session/capture.c's SIGINT handler calls it on).
// Idempotent. Lamp sets register themselves on open (at most 32 open at once)
// and deregister on close.
void rig_safety_install(void);// The lamps of a set: how many (0 for NULL), lamp i's line as opened (NULL
// when i is out of range), lamp i's name ("" when out of range), the lamps
// now on (bit i: lamp i), the backend ("gpiod", "sim"; "" for NULL).
int                    rig_lamps_count(const rig_lamps_t *l);
const rig_lamp_line_t *rig_lamps_line(const rig_lamps_t *l, int i);
const char            *rig_lamps_name(const rig_lamps_t *l, int i);
uint32_t               rig_lamps_on_mask(const rig_lamps_t *l);
const char            *rig_lamps_backend(const rig_lamps_t *l);

// ---------------------------------------------------------------------------
// Cameras

typedef struct {
    int      width, height;
    int      offset_x, offset_y;     // region origin on the sensor, pixels
    char     pixel_format[16];       // "Mono8", "Mono12", "Mono16", "Mono12p", ... (rig/camera/pixfmt.h)
    int      bits;                   // significant bits of a pixel value (8, 10, 12, 16)
    double   exposure_us;
    double   gain;                   // as the camera states it (dB for GenICam Gain)
    uint64_t frame_id;
    uint64_t timestamp_ns;           // the camera's timestamp
    double   system_time_s;          // host CLOCK_REALTIME when the frame arrived
    double   temperature_c;          // sensor temperature, NAN where the camera has none
    char     vendor[64], model[64], serial[64];
    // Radiometric state, read back when the camera was opened or changed (rig/camera/aravis.c):
    char     gain_unit[16];          // the gain feature's GenICam <Unit> ("dB", "x"); "raw" when it states none
    double   black_level;            // BlackLevel as read back, NAN where the camera has none
    double   gamma;                  // the gamma in effect: 1 with gamma off or absent
    char     firmware[64];           // DeviceFirmwareVersion, "" where the camera has none
    char     camera_settings[512];   // what refl found, switched off and read back, e.g. "ExposureAuto=Off
                                     // (was Continuous) GainAuto=Off GammaEnable=0 LUTEnable=0 GevSCPSPacketSize=1500"
} rig_frame_meta_t;

typedef struct {
    rig_frame_meta_t meta;
    uint16_t        *pix;            // width*height values as delivered (Mono8 0..255, Mono12 0..4095)
} rig_frame_t;

void rig_frame_free(rig_frame_t *f);  // frees pix; accepts NULL

typedef struct rig_camera rig_camera_t;
// Aravis (GigE Vision, USB3 Vision). id: an IP address (opened directly, no
// discovery), "inprocess:SERIAL" (the in-process virtual camera of this
// process, rig/virtual/gv_camera.h: no network), or a serial number / device name
// (which makes Aravis enumerate devices: never used in tests). Fails with
// RIG_ERR_NO_DEVICE naming id.
// Opening sets TriggerMode On / TriggerSource Software. A camera that stops
// answering makes calls fail with RIG_ERR_DISCONNECTED (after Aravis's control
// time-out, 5 x 500 ms) and every later call at once; closing it then takes up
// to ~10 s. Use one camera handle from one thread at a time.
// The virtual GigE Vision camera for tests and the virtual rig: rig/virtual/gv_camera.h.
int rig_camera_open_aravis(rig_camera_t **out, const char *id);
int  rig_camera_set_pixel_format(rig_camera_t *c, const char *format);
int  rig_camera_set_exposure_us(rig_camera_t *c, double exposure_us);
int  rig_camera_set_gain(rig_camera_t *c, double gain);
int  rig_camera_set_region(rig_camera_t *c, int x, int y, int width, int height);
// GigE Vision stream packets: GevSCPSPacketSize (bytes, IP and UDP headers
// included) and GevSCPD (the delay between packets, in the camera's timestamp
// ticks); -1 leaves one unchanged. Each is checked against the camera's range
// (RIG_ERR_INVALID), set and read back; RIG_ERR_NOT_SUPPORTED when the camera
// lacks it. A set size also stops Aravis from testing and changing it.
int  rig_camera_set_stream_packets(rig_camera_t *c, long packet_size, long packet_delay);
// The current settings, and what refl found and set at open (rig_frame_meta_t):
// rig_camera_open_aravis switches off the automatics (every *Auto* enumeration
// with an Off entry), GammaEnable (or sets Gamma = 1) and LUTEnable before any
// frame; a feature it cannot switch off fails the open (RIG_ERR_NOT_SUPPORTED
// naming the feature and the camera), except BalanceWhiteAuto on a mono camera
// (a warning in camera_settings).
int  rig_camera_settings(rig_camera_t *c, rig_frame_meta_t *out);
int  rig_camera_capture(rig_camera_t *c, double timeout_s, int retries, rig_frame_t *out);
void rig_camera_close(rig_camera_t *c);
// The camera's name for messages ("aravis Fake camera serial GV01 at
// 127.0.0.1") and its backend ("aravis"); "" for NULL.
const char *rig_camera_name(const rig_camera_t *c);
const char *rig_camera_backend(const rig_camera_t *c);

#ifdef __cplusplus
}
#endif
