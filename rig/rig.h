// rig/rig.h — the hardware layer of refl: the rig file (rig_t, rig_open),
// and through the headers it includes, the devices (rig/devices.h: turntable,
// lamps, cameras, the error convention), the virtual rig (rig/virtual/virtual.h) and
// capture sessions (rig/session/session.h).
#pragma once

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "model/model.h"
#include "rig/devices.h"
#include "rig/session/session.h"
#include "rig/virtual/virtual.h"

#ifdef __cplusplus
extern "C" {
#endif

// ---------------------------------------------------------------------------
// Rig description files (rig/config.c)
//
//   [camera] or [camera NAME] (one or more, at most RIG_CAMERAS_MAX; NAME of letters, digits, '_', '-',
//                not "all"; a plain [camera] is named "camera"; names and camera ids are unique):
//                backend = aravis; address = A (IPv4, opened directly) | serial = S | name = N
//                (exactly one); optional camera settings applied at open:
//                pixel_format = Mono8|Mono12|Mono16 (or Mono10, the packed Mono10p|Mono12p|
//                Mono10Packed|Mono12Packed: rig/camera/pixfmt.h); exposure_us = ...; gain = ... (the camera's unit);
//                packet_size = BYTES (GigE Vision GevSCPSPacketSize, 576..16384 and the
//                camera's range), packet_delay = TICKS (GevSCPD, 0..4294967295 and the camera's
//                range): set and read back at open (rig_camera_set_stream_packets)
//   [turntable]  backend = apt: serial (optional: the only stage), stage = K10CR1 (optional:
//                from the controller; one of rig_stage_models)
//                | sim: speed_deg_s, accel_deg_s2, home_time_s, position_noise_deg, time_scale,
//                seed, fault_after_moves, fault = motion|timeout|disconnected (rig_turntable_sim_params_t)
//   [lamp NAME]  backend = gpiod: chip, line (required), active_low (true/false), warmup_ms, settle_ms
//                | sim: position_mm = x y z (nominal position, rig frame; checked, not used),
//                warmup_ms, settle_ms. All lamps use one backend; NAME without ',' and not
//                "all"/"none" (refl rig snap --lamps NAME,NAME|all|none); at most 32 lamps.
//   [lamps]      state_file = PATH (relative to the rig file's directory): the lamp-state file
//                (rig/lamps/state.c; default: per user, named after the chips and lines; sim
//                lamps keep one only when given this)
// or, for the whole rig (no other section):
//   [rig]        backend = virtual; truth = FILE (relative to the rig file's directory);
//                serve = gige (default: GigE Vision on the address) | inprocess (an Aravis
//                fake device in refl's own process, no network; address and busy_wait_s
//                are then not allowed);
//                address = 127.0.0.1 (one loopback address per camera of the truth file, separated by
//                spaces; a camera without one serves on the address after the previous camera's);
//                sample = NAME; time_scale = 1; noise_seed = 1;
//                busy_wait_s = 0 (wait for another virtual camera on the address);
//                pixel_format, exposure_us, gain, packet_size, packet_delay (as in [camera], for every
//                camera). The cameras are the truth file's [camera] or [camera NAME] sections
//                (rig/virtual/virtual.h), named so here.
// Every section but [rig] is optional (a rig without [camera] moves and switches
// lamps but takes no pictures). Unknown sections and keys, missing keys and bad
// values are errors naming file and line and saying what to write instead.

#define RIG_CAMERAS_MAX 8
#define RIG_CAMERA_NAME_MAX 32

// The kinds of device of a rig file, to open a part of it (rig_open_with).
enum { RIG_DEVICE_TURNTABLE = 1, RIG_DEVICE_LAMPS = 2, RIG_DEVICE_CAMERAS = 4, RIG_DEVICE_ALL = 7 };

// A device that did not open (rig_open_with, keep_going).
typedef struct {
    unsigned kind;                         // RIG_DEVICE_TURNTABLE, _LAMPS or _CAMERAS
    char     name[RIG_CAMERA_NAME_MAX];    // a camera's name in the rig file ("" for the others)
    int      before;                       // a camera: how many open cameras come before it in the file
    char     error[1280];                  // "FILE:LINE: [SECTION]: the driver's message"
} rig_open_failure_t;

typedef struct rig {
    char            *path;
    char             sha256[65];
    rig_camera_t    *camera;        // the first camera (cameras[0]); NULL when the file has none
    int              ncameras;      // the cameras in file order (a virtual rig: one, "camera")
    rig_camera_t    *cameras[RIG_CAMERAS_MAX];
    char             camera_names[RIG_CAMERAS_MAX][RIG_CAMERA_NAME_MAX];
    rig_turntable_t *turntable;     // may be NULL when the file has no [turntable]
    rig_lamps_t     *lamps;         // may be NULL when the file has no lamps
    rig_virtual_t   *virt;          // non-NULL for backend = virtual
    char             pixel_format[16];  // the first camera's defaults from the file ("" = the camera's own),
    double           exposure_us;       // applied by rig_open (NAN = not given)
    double           gain;
    // The turntable's motion profile, for time-outs: real seconds (a simulated
    // stage's time_scale applied). Cruise speed, acceleration, longest homing.
    double           speed_deg_s, accel_deg_s2, home_time_s;
    unsigned         devices;       // the RIG_DEVICE_* kinds asked for (rig_open: all)
    int              nfailed;       // rig_open_with keep_going: the devices that did not open, file order
    rig_open_failure_t failed[RIG_CAMERAS_MAX + 2];
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
// rig_open of a part of the rig, one device at a time: only the kinds in
// devices (RIG_DEVICE_*; the file is still parsed and checked whole; a virtual
// rig's simulation always starts, its cameras are opened only when asked). With
// keep_going a device that fails to open is recorded in r->failed with its
// message (not printed) and the others are still opened: 0 and an open rig_t
// whose r->nfailed says how many failed. Without it, as rig_open.
typedef struct {
    unsigned devices;
    bool     keep_going;
} rig_open_opts_t;
int  rig_open_with(rig_t **out, const char *path, const rig_open_opts_t *o);
// Only the parsing and checking rig_open does, of a rig file's text (name: the
// file's path, used in messages and to resolve [rig] truth, which is not read):
// 0, or RIG_ERR_INVALID with the file:line message of rig_open. Opens nothing.
int  rig_config_parse(const char *text, size_t len, const char *name);
// Questions about a rig file that open no device (rig/config.c).
// The truth file of a rig file: *truth_path is the resolved path (caller
// g_free's) of [rig] truth = FILE when [rig] backend = virtual, else NULL.
// false + message when the rig file cannot be read or a virtual rig names no
// truth file.
bool rig_file_truth_path(const char *rig_path, char **truth_path);
// The lamp names of a rig file in file order: [lamp NAME] sections of the rig
// file, or of its truth file for a virtual rig. *names is a NULL-terminated
// array (g_strfreev). false + message.
bool rig_file_lamp_names(const char *rig_path, char ***names, int *n);
// The camera names of a rig file in file order: [camera] ("camera") and [camera NAME] sections of
// the rig file, or of its truth file for a virtual rig. *names as above. false + message.
bool rig_file_camera_names(const char *rig_path, char ***names, int *n);

// The index in r->cameras of the camera named name, or -1.
int  rig_camera_find(const rig_t *r, const char *name);

// `refl rig` (rig/cmd_rig.c).
int rig_cmd(int argc, char **argv);
// `refl rig status` of an open rig on stdout: every device of the kinds it
// was opened with (r->devices), also after one fails or did not open (its
// DEVICE_error line); 0, or the first failure's RIG_ERR_* code.
int rig_cmd_status(rig_t *r);

#ifdef __cplusplus
}
#endif
