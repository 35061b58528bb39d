// rig/rig.h — the hardware layer of refl: turntable, lamps, cameras, the
// virtual rig, rig description files and capture sessions. Each device kind is
// a small ops table with a real driver and a simulated device behind it.
//
// Conventions
// - Functions return 0 or a negative RIG_ERR_* code; rig_strerror() names the
//   code, rig_last_error() gives this thread's last detailed message, which
//   names the device (backend, serial, chip/line) and says what to do.
// - Angles in degrees (the turntable's own frame: 0 at home, positive
//   counter-clockwise seen from above, i.e. about +z of the rig frame), times in
//   seconds unless the name says _ms/_us.
// - Every rig_*_close() accepts NULL. Lamps are switched off on close, on
//   normal exit, on SIGINT/SIGTERM (see rig_safety_install) and on every error
//   path that closes them.
#pragma once

#include <stdbool.h>
#include <stdint.h>

#include <jansson.h>

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
// Record a detailed message (also printed to stderr unless model_error_quiet)
// and return err, so drivers can write `return rig_fail(RIG_ERR_TIMEOUT, "...")`.
int         rig_fail(int err, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
const char *rig_last_error(void);

// ---------------------------------------------------------------------------
// Turntable

typedef struct {
    char   model[32];          // e.g. "K10CR1"
    char   serial[32];
    char   firmware[32];
    double counts_per_deg;     // encoder counts per degree (K10CR1: 136533.33)
} rig_turntable_info_t;

typedef struct {
    double angle_deg;          // measured position
    bool   moving, homing, homed;
    bool   limit_fwd, limit_rev;
    bool   motion_error;
} rig_turntable_status_t;

typedef struct rig_turntable rig_turntable_t;

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
    void (*close)(rig_turntable_t *t);
} rig_turntable_ops_t;

struct rig_turntable {
    const rig_turntable_ops_t *ops;
    char name[96];             // for messages: "apt K10CR1 serial 55000001"
    void *impl;
};

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

// Wrappers over the ops (check arguments, fill rig_last_error with the device name).
int  rig_turntable_info(rig_turntable_t *t, rig_turntable_info_t *out);
int  rig_turntable_status(rig_turntable_t *t, rig_turntable_status_t *out);
int  rig_turntable_home(rig_turntable_t *t, double timeout_s);            // start + wait
int  rig_turntable_move_abs_deg(rig_turntable_t *t, double angle_deg, double timeout_s);
int  rig_turntable_move_rel_deg(rig_turntable_t *t, double delta_deg, double timeout_s);
int  rig_turntable_start_move_abs_deg(rig_turntable_t *t, double angle_deg);
int  rig_turntable_wait(rig_turntable_t *t, double timeout_s);
int  rig_turntable_stop(rig_turntable_t *t, bool immediate);
void rig_turntable_close(rig_turntable_t *t);
// Time a move of delta_deg takes with a trapezoidal profile.
double rig_motion_time_s(double delta_deg, double speed_deg_s, double accel_deg_s2);

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
    void           *impl;
};

// libgpiod v1. Requests every line as output, consumer "refl", initially off
// (lines are requested active-high; active-low lamps are inverted by refl).
// A chip containing '/' is opened as a path, else by name. On any error the
// lines already requested are switched off and released.
int rig_lamps_open_gpiod(rig_lamps_t **out, const rig_lamp_line_t *lamps, int n);
// Both opens: 0..32 lamps with unique non-empty names, warmup_ms/settle_ms in
// [0, 3.6e6]; *out is NULL on error.
// Simulated lamps (state only; the virtual rig reads on_mask).
int rig_lamps_open_sim(rig_lamps_t **out, const rig_lamp_line_t *lamps, int n);
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

// Safety: after this, SIGINT/SIGTERM/SIGHUP and exit() switch every open lamp
// set off (emergency_off) before the process ends; the signals then re-raise
// with the default action (a signal the process ignores stays ignored).
// Idempotent. Lamp sets register themselves on open (at most 32 open at once)
// and deregister on close.
void rig_safety_install(void);

// ---------------------------------------------------------------------------
// Cameras

typedef struct {
    int      width, height;
    int      offset_x, offset_y;     // region origin on the sensor, pixels
    char     pixel_format[16];       // "Mono8", "Mono12", "Mono16"
    int      bits;                   // significant bits of a pixel value (8, 12, 16)
    double   exposure_us;
    double   gain;                   // as the camera states it (dB for GenICam Gain)
    uint64_t frame_id;
    uint64_t timestamp_ns;           // the camera's timestamp
    double   system_time_s;          // host CLOCK_REALTIME when the frame arrived
    double   temperature_c;          // sensor temperature, NAN where the camera has none
    char     vendor[64], model[64], serial[64];
} rig_frame_meta_t;

typedef struct {
    rig_frame_meta_t meta;
    uint16_t        *pix;            // width*height values as delivered (Mono8 0..255, Mono12 0..4095)
} rig_frame_t;

void rig_frame_free(rig_frame_t *f);  // frees pix; accepts NULL

typedef struct rig_camera rig_camera_t;

typedef struct {
    const char *backend;             // "aravis"
    int  (*set_pixel_format)(rig_camera_t *c, const char *format);
    int  (*set_exposure_us)(rig_camera_t *c, double exposure_us);
    int  (*set_gain)(rig_camera_t *c, double gain);
    int  (*set_region)(rig_camera_t *c, int x, int y, int width, int height);
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

// Aravis (GigE Vision, USB3 Vision). id: an IP address (opened directly, no
// discovery), "inprocess:SERIAL" (the in-process virtual camera of this
// process, rig/gv_camera.h: no network), or a serial number / device name
// (which makes Aravis enumerate devices: never used in tests). Fails with
// RIG_ERR_NO_DEVICE naming id.
// Opening sets TriggerMode On / TriggerSource Software. A camera that stops
// answering makes calls fail with RIG_ERR_DISCONNECTED (after Aravis's control
// time-out, 5 x 500 ms) and every later call at once; closing it then takes up
// to ~10 s. Use one camera handle from one thread at a time.
// The virtual GigE Vision camera for tests and the virtual rig: rig/gv_camera.h.
int rig_camera_open_aravis(rig_camera_t **out, const char *id);
int  rig_camera_set_pixel_format(rig_camera_t *c, const char *format);
int  rig_camera_set_exposure_us(rig_camera_t *c, double exposure_us);
int  rig_camera_set_gain(rig_camera_t *c, double gain);
int  rig_camera_set_region(rig_camera_t *c, int x, int y, int width, int height);
int  rig_camera_settings(rig_camera_t *c, rig_frame_meta_t *out);
int  rig_camera_capture(rig_camera_t *c, double timeout_s, int retries, rig_frame_t *out);
void rig_camera_close(rig_camera_t *c);

// ---------------------------------------------------------------------------
// The virtual rig (rig/virtual.c): a simulated turntable, simulated lamps and
// a virtual GigE Vision camera (rig/gv_camera.h) on 127.0.0.1 whose frames are
// rendered by model/ from the turntable angle, the lamps that are on, the
// exposure and the gain, then passed through the sensor stage. Its ground truth
// (camera model, lamps, sensor, kc, materials and the samples that can be put
// on the table) lives in one truth file (see examples/virtual-truth.ini).

typedef struct rig_virtual rig_virtual_t;

// How the virtual rig serves its camera: GigE Vision on a loopback address, or
// in-process (an Aravis fake device inside this process, opened by
// rig_camera_open_aravis as "inprocess:SERIAL": no UDP port, no lock file, so
// several processes may run virtual rigs at once; faster).
typedef enum { RIG_VIRTUAL_SERVE_GIGE = 0, RIG_VIRTUAL_SERVE_INPROCESS = 1 } rig_virtual_serve_t;

typedef struct {
    rig_virtual_serve_t serve;  // default RIG_VIRTUAL_SERVE_GIGE
    const char *address;        // where the camera serves (default "127.0.0.1"; GigE only)
    const char *sample;         // the sample on the table (default: the truth file's `sample`)
    double      time_scale;     // turntable and lamp timing: 1 real time, 0.01 = 100x faster
    uint64_t    noise_seed;     // first frame's noise seed (default 1; +1 per frame)
    double      busy_wait_s;    // wait this long for another camera server on the address to stop (default 0; GigE only)
    const char *serial;         // the camera's serial instead of the truth file's (NULL: the file's); a process
                                // serves one in-process camera per serial
    int         prerender;      // [render] prerender instead of the truth file's (0, 1, 2; -1 = the file's, default)
} rig_virtual_options_t;

rig_virtual_options_t rig_virtual_defaults(void);
// Reads the truth file, starts the camera server, makes the simulated turntable
// and lamps. Errors name the truth file and line.
int  rig_virtual_open(rig_virtual_t **out, const char *truth_path, const rig_virtual_options_t *opt);
void rig_virtual_close(rig_virtual_t *v);
// Only the checks of the truth file rig_virtual_open makes (sections, keys,
// values, the camera model and its sha256, the samples' scenes and materials),
// of the truth file's text: name is its file name in base_dir, the directory
// its relative paths (camera model, scenes) resolve against; messages name
// base_dir/name and the line. Starts nothing. 0 or RIG_ERR_INVALID.
int  rig_virtual_check_truth(const char *text, size_t len, const char *name, const char *base_dir);
// The devices (owned by the virtual rig; do not close them yourself).
rig_turntable_t *rig_virtual_turntable(rig_virtual_t *v);
rig_lamps_t     *rig_virtual_lamps(rig_virtual_t *v);
// The camera's id for rig_camera_open_aravis: the address ("127.0.0.1"), or
// "inprocess:SERIAL" when served in-process.
const char      *rig_virtual_camera_address(const rig_virtual_t *v);
// The camera server (rig/gv_camera.h), for fault injection in tests; NULL
// when the rig serves in-process (serve = inprocess).
struct rig_gv_camera *rig_virtual_gv_camera(rig_virtual_t *v);
// Put another sample on the table (a [sample NAME] of the truth file).
int  rig_virtual_set_sample(rig_virtual_t *v, const char *name);
// The same sample on a wedge: rotated by tilt_deg (|tilt| <= 80) about the
// horizontal hinge axis (cos az, sin az, 0) through the rig origin
// (right-handed), then lifted along z so its lowest point stays at its height;
// the turntable angle applies after this pose. Tilt 0 = rig_virtual_set_sample.
// At most 32 distinct poses per open rig. A uniform_source cannot be tilted.
int  rig_virtual_set_sample_pose(rig_virtual_t *v, const char *name, double tilt_deg, double tilt_azimuth_deg);
// The current sample's pose (truth): x_table = R x_sample_file + t (R
// row-major; identity and 0 at tilt 0). Any pointer may be NULL.
int  rig_virtual_sample_pose(rig_virtual_t *v, double *tilt_deg, double *tilt_azimuth_deg, double R[9], double t[3]);
const char *rig_virtual_sample(const rig_virtual_t *v);
const char *rig_virtual_truth_path(const rig_virtual_t *v);
// The noise-free expected frame (DN of the camera's pixel format, before the
// sensor's noise and quantisation but with its gain patterns, offsets and
// non-linearity) for a state: for tests and for checking calibrations.
// gain_db in dB; width x height: the region at the sensor's top-left corner
// (the full sensor is the camera model's size); the sample is the current one.
// The devices are owned by the rig: rig_virtual_close closes them (never
// rig_lamps_close / rig_turntable_close them yourself).
int  rig_virtual_expected(rig_virtual_t *v, double angle_deg, uint32_t lamp_mask,
                          double exposure_us, double gain_db, const char *pixel_format,
                          int width, int height, float *out);

// The radiance plane of one lamp at an angle for the current sample (kc 1,
// Pa 0: model units, as model_render's bracket; the whole sensor, W*H floats
// into out): what the rig's frames are made of. Lamps add linearly.
int  rig_virtual_radiance(rig_virtual_t *v, double angle_deg, int lamp, float *out);
// The rig's sensor stage on an ideal frame img (whole sensor, DN of the
// sensor's bits, dark offset included: Pa + kc L): its fixed patterns, the
// temporal noise drawn from seed, quantisation, in place.
int  rig_virtual_sensor_apply(rig_virtual_t *v, double exposure_us, double gain_db, uint64_t seed, float *img);
// Truth: kc per us of exposure at 0 dB, the sensor, the camera, the lamps.
double               rig_virtual_kc_per_us(const rig_virtual_t *v);
model_sensor_t       rig_virtual_sensor_params(const rig_virtual_t *v);
model_camera_t      *rig_virtual_camera_model(rig_virtual_t *v);
const model_lamps_t *rig_virtual_lamps_truth(const rig_virtual_t *v);
// Frames the camera handed out that the pre-render thread had computed ahead
// of their triggers (speculation; see rig/virtual.c), since the rig opened.
long                 rig_virtual_frames_ahead(rig_virtual_t *v);
// rig_turntable_sim_destination of the rig's simulated stage.
bool                 rig_virtual_destination(rig_virtual_t *v, double *angle_deg);

// ---------------------------------------------------------------------------
// Rig description files (rig/config.c)
//
//   [camera]     backend = aravis; address = A (IPv4, opened directly) | serial = S | name = N
//                (exactly one); optional camera settings applied at open:
//                pixel_format = Mono8|Mono12|Mono16; exposure_us = ...; gain = ... (the camera's unit)
//   [turntable]  backend = apt: serial (optional: the only stage), stage = K10CR1 (optional:
//                from the controller; one of rig_stage_models)
//                | sim: speed_deg_s, accel_deg_s2, home_time_s, position_noise_deg, time_scale,
//                seed, fault_after_moves, fault = motion|timeout|disconnected (rig_turntable_sim_params_t)
//   [lamp NAME]  backend = gpiod: chip, line (required), active_low (true/false), warmup_ms, settle_ms
//                | sim: position_mm = x y z (nominal position, rig frame; checked, not used),
//                warmup_ms, settle_ms. All lamps use one backend; NAME without ',' and not
//                "all"/"none" (refl rig --lamps NAME,NAME|all|none); at most 32 lamps.
// or, for the whole rig (no other section):
//   [rig]        backend = virtual; truth = FILE (relative to the rig file's directory);
//                serve = gige (default: GigE Vision on the address) | inprocess (an Aravis
//                fake device in refl's own process, no network; address and busy_wait_s
//                are then not allowed);
//                address = 127.0.0.1; sample = NAME; time_scale = 1; noise_seed = 1;
//                busy_wait_s = 0 (wait for another virtual camera on the address);
//                pixel_format, exposure_us, gain (as in [camera])
// Every section but [rig] is optional (a rig without [camera] moves and switches
// lamps but takes no pictures). Unknown sections and keys, missing keys and bad
// values are errors naming file and line and saying what to write instead.

typedef struct {
    char            *path;
    char             sha256[65];
    rig_camera_t    *camera;
    rig_turntable_t *turntable;     // may be NULL when the file has no [turntable]
    rig_lamps_t     *lamps;         // may be NULL when the file has no lamps
    rig_virtual_t   *virt;          // non-NULL for backend = virtual
    char             pixel_format[16];  // camera defaults from the file ("" = the camera's own),
    double           exposure_us;       // applied by rig_open (NAN = not given)
    double           gain;
    // The turntable's motion profile, for time-outs: real seconds (a simulated
    // stage's time_scale applied). Cruise speed, acceleration, longest homing.
    double           speed_deg_s, accel_deg_s2, home_time_s;
} rig_t;

// Parse the rig file and open every device in it (lamps off): the turntable,
// the lamps, then the camera (or, for [rig] backend = virtual, the virtual rig
// and a camera opened at its address); installs rig_safety_install(). Errors
// name the file and line (device errors: the section's line, then the
// driver's message). A file without [camera] is allowed (no snapshots). On
// error nothing stays open. rig_close: lamps off, then camera, lamps,
// turntable (virtual rig) closed; accepts NULL.
int  rig_open(rig_t **out, const char *path);
void rig_close(rig_t *r);
// Only the parsing and checking rig_open does, of a rig file's text (name: the
// file's path, used in messages and to resolve [rig] truth, which is not read):
// 0, or RIG_ERR_INVALID with the file:line message of rig_open. Opens nothing.
int  rig_config_parse(const char *text, size_t len, const char *name);

// `refl rig` (rig/cmd_rig.c).
int rig_cmd(int argc, char **argv);

// ---------------------------------------------------------------------------
// Capture sessions (rig/plan.c, rig/journal.c, rig/capture.c, rig/cmd_capture.c)
//
// A plan file (INI, see examples/plans/) says what to capture:
//   [plan]     name = TEXT; operator = TEXT; notes = TEXT (all optional)
//   [sample]   name = NAME (on a virtual rig: a [sample NAME] of its truth file, put on the
//              table); kind = material_coupon | reference_white | chessboard | mirror_sphere |
//              workpiece | uniform_source; tilt_deg = the wedge the sample stands on (-80..80,
//              default 0), tilt_azimuth_deg = the azimuth of the wedge's hinge axis (default
//              0): a virtual rig poses the sample so (rig_virtual_set_sample_pose); on a real
//              rig the operator sets it up, the journal records it
//   [angles]   list = DEG DEG ... | range = START STOP STEP (STOP included when reached)
//   [lamps]    sets = SET; SET; ...   a SET is NAME+NAME..., "all" or "none"
//   [exposure] mode = fixed: list_us = US US ...
//              mode = auto: list_us = the bracket ladder (captured longest first; the
//              bracket ends with the first frame whose brightest pixel of interest is at
//              or below target_fraction (0 < f <= 1, default 0.9) of full scale; the other
//              exposures of the ladder are journalled as skipped); roi = X Y W H (the pixels
//              of interest, default the whole frame)
//              gain = G (camera unit, default 0); pixel_format = Mono8|Mono12|Mono16 (default Mono12)
//   [capture]  repeats = N (frames per exposure, default 1); dark_every = N (a dark frame,
//              lamps off at the step's exposure, after every N light steps; 0 = none);
//              settle_ms = after each motion (default 0); lamp_settle_ms = extra after each
//              lamp change beyond the lamps' own (default 0); frame_timeout_s = how long to
//              wait for a frame beyond its exposure (default 10); retries = captures tried
//              again after a camera time-out before the session pauses (default 2)
// Order: angle, then lamp set, then repeat, then exposure (a bracket stays
// together). Every problem is reported through model_error naming the plan
// file and line.
//
// A session directory: session.sqlite (tables schema_version, session, steps,
// frames, events; every step is written pending at the start) and
// frames/sNNNNNN.png (step index; 16-bit grey PNG with metadata). A frame is
// written to frames/.sNNNNNN.png.part, fsync'ed, hashed, committed with its row
// (one transaction), then linked to its name (link(2): nothing is overwritten)
// and the temporary name removed; --resume re-links committed frames whose link
// a crash prevented and deletes uncommitted temporary files.

typedef enum { RIG_STEP_LIGHT, RIG_STEP_DARK } rig_step_kind_t;

typedef struct {
    int             index;          // 0-based position in the session
    rig_step_kind_t kind;
    int             angle_index, lamp_set, exposure_index, repeat;
    int             group;          // auto bracketing: steps of one (angle, lamp set, repeat) bracket
    double          angle_deg;
    uint32_t        lamp_mask;      // bits of the rig's lamps (rig_plan_bind)
    char            lamps[256];     // "east+west", "none"
    double          exposure_us, gain;
} rig_step_t;

typedef struct {
    char    *path, *text;           // file name, contents
    char     sha256[65];
    char     name[128], operator_name[128], notes[512];
    char     sample[64], sample_kind[32];
    double   tilt_deg, tilt_azimuth_deg;   // the sample's wedge (see rig_virtual_set_sample_pose)
    int      nangles;
    double  *angles_deg;
    int      nlamp_sets;
    char   (*lamp_sets)[256];       // as written, normalised ("east+west", "none", "all")
    int      lamp_sets_line;
    bool     auto_exposure;
    int      nexposures;
    double  *exposures_us;          // auto: sorted longest first
    int      exposure_line;
    double   target_fraction;
    int      roi[4];                // x y w h; w = 0: whole frame
    double   gain;
    char     pixel_format[16];
    int      repeats, dark_every;
    double   settle_ms, lamp_settle_ms;
    double   frame_timeout_s;
    int      retries;
    int      nsteps;
    rig_step_t *steps;              // built by rig_plan_load (lamp_mask 0 until rig_plan_bind)
} rig_plan_t;

// Parse a plan file (or text, for tests: name is used in messages) and build
// its step list. NULL on error (model_last_error names file and line).
rig_plan_t *rig_plan_load(const char *path);
rig_plan_t *rig_plan_parse(const char *text, size_t len, const char *name);
void        rig_plan_free(rig_plan_t *p);
// Check the plan against an open rig before anything moves: lamp names exist,
// angles within the turntable's range (+-10000 deg; a turntable is needed when
// any angle is not 0), a camera exists and accepts every exposure, the gain and
// the pixel format (set and read back, then restored), the ROI fits the frame,
// the sample exists on a virtual rig. Fills every step's lamp_mask. 0 or a
// RIG_ERR_* (message names the plan file and line).
int rig_plan_bind(rig_plan_t *p, rig_t *r);

// The hardware floor of a step list on a rig: the sum of motions (trapezoidal
// profile from the rig's speed/acceleration), settles (max of motion settle and
// lamp settle when both happen at a step) and exposures; seconds.
double rig_plan_floor_s(const rig_plan_t *p, const rig_t *r, int from_step);

// The journal: DIR/session.sqlite (WAL, one transaction per frame).
typedef struct rig_journal rig_journal_t;

typedef struct {
    int      step;
    char     file[64];              // relative to the session directory
    char     sha256[65];
    double   t_trigger_utc_s, t_written_utc_s;
    double   commanded_deg, measured_deg;
    char     lamps[256];
    double   exposure_us, gain;
    double   mean, max, roi_max, saturated_fraction;
    int      width, height;
    char     pixel_format[16];
    uint64_t frame_id;
} rig_frame_row_t;

// Create DIR/session.sqlite (fails when it exists) with the session and every
// step pending. session_json: a JSON object of session facts (camera serials,
// settings snapshot, calibrations, versions, operator notes).
int  rig_journal_create(rig_journal_t **out, const char *dir, const rig_plan_t *p, const char *rig_path,
                        const char *rig_text, const char *rig_sha256, const char *session_json);
int  rig_journal_open(rig_journal_t **out, const char *dir);
void rig_journal_close(rig_journal_t *j);
// Stored plan/rig: path, text, sha256 (caller frees with free()).
int  rig_journal_source(rig_journal_t *j, const char *which, char **path, char **text, char **sha256);
int  rig_journal_nsteps(rig_journal_t *j);
// The session facts (JSON object text, as given at create). Caller frees.
int  rig_journal_facts(rig_journal_t *j, char **json);
// Steps (as stored) and their status: 'p'ending, 'd'one, 's'kipped. Caller frees both.
int  rig_journal_steps(rig_journal_t *j, rig_step_t **steps, char **status, int *n);
int  rig_journal_frames(rig_journal_t *j, rig_frame_row_t **rows, int *n);
// One transaction: the frame row and its step done.
int  rig_journal_frame_done(rig_journal_t *j, const rig_frame_row_t *f);
int  rig_journal_step_skipped(rig_journal_t *j, int step, const char *why);
// Event log: kind = start, resume, retry, fault, pause, stop, complete, info.
int  rig_journal_event(rig_journal_t *j, int step, const char *kind, const char *fmt, ...)
    __attribute__((format(printf, 4, 5)));
int  rig_journal_set_state(rig_journal_t *j, const char *state);   // running paused stopped fault complete
int  rig_journal_state(rig_journal_t *j, char *out, size_t size);

// Reading a finished (or paused) session for the analyses (rig/session.c).
// A session's frames (in step order) and its facts, for the analyses.
typedef struct {
    char            *dir;
    rig_frame_row_t *rows;
    int              n;
    char             plan_sha256[65], rig_sha256[65];
    char            *plan_text;        // the stored plan
    json_t          *facts;            // session facts (camera, virtual rig, ...); may be NULL
} rig_session_t;

// NULL on error (model_last_error names the directory).
rig_session_t *rig_session_open(const char *dir);
void             rig_session_free(rig_session_t *s);
// Frame i as float DN (its pixel format's values); checks the file's sha256
// against the journal first. NULL on error (names the file). Caller frees.
float           *rig_session_frame(const rig_session_t *s, int i, int *width, int *height);


// Run (or continue) a session. Exit codes of refl capture: 0 complete, 1 error
// or fault (stopped), 3 paused (SIGINT or camera not answering: resume later).
typedef struct {
    const char *plan_path, *rig_path, *dir;
    bool        resume, allow_changed, dry_run;
    const char *operator_name, *notes;
    const char *command_line;
    // A calibration directory (refl calib ... -o DIR, or one holding geometry/,
    // lamps/, gain/, white/): its files are recorded in the session facts by
    // path and sha256 (NULL: none). Frames stay raw.
    const char *calib_dir;
    int         progress;           // -1 auto (bar on a TTY), 0 plain lines, 1 bar
    // Called before each step is carried out (after the rig is open): for
    // tests (fault injection) and instrumentation; may be NULL.
    void      (*before_step)(void *ctx, rig_t *r, int step);
    void       *hook_ctx;
    // Out (may be NULL): the session's wall time, the hardware floor of the
    // steps run, the number of frames written in this run.
    double     *wall_s, *floor_s;
    int        *frames_written;
} rig_capture_opts_t;
int rig_capture_run(const rig_capture_opts_t *o);

// `refl capture`, `refl session` (rig/cmd_capture.c).
int rig_cmd_capture(int argc, char **argv);
int rig_cmd_session(int argc, char **argv);

#ifdef __cplusplus
}
#endif
