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
//                "all"/"none" (refl rig --lamps NAME,NAME|all|none); at most 32 lamps.
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
// `refl rig status` of an open rig on stdout: every device, also after one
// fails (its DEVICE_error line); 0, or the first failure's RIG_ERR_* code.
int rig_cmd_status(rig_t *r);

#ifdef __cplusplus
}
#endif
