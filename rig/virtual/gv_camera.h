// rig/virtual/gv_camera.h — a virtual GigE Vision camera, served by this process on a
// loopback address, for the virtual rig and the tests of the Aravis backend.
//
// It is an Aravis ArvGvFakeCamera (GVCP control on UDP 3956, GVSP stream) with
// a GenICam description of our own, derived at start from Aravis's built-in
// fake camera XML:
//   DeviceVendorName, DeviceModelName, DeviceSerialNumber (= DeviceID),
//   DeviceTemperature (float, °C, read-only),
//   SensorWidth/Height, Width, Height, OffsetX, OffsetY,
//   PixelFormat Mono8 | Mono12 (16-bit containers) | Mono16 | Mono10 | Mono10p |
//     Mono12p | Mono10Packed | Mono12Packed (rig/camera/pixfmt.h; packed ones packed
//     with rig_pixfmt_pack),
//   ExposureTime (float, µs, 10 .. 10e6; ExposureTimeAbs is the same value),
//   Gain (float, dB, 0 .. 24; params.gain_unit changes its <Unit>),
//   the automatics and tone curve, on at start as on real cameras: ExposureAuto
//     (Off | Once | Continuous; on: frames exposed 1.5 x ExposureTime), GainAuto
//     (on: 6 dB more than Gain), BalanceWhiteAuto (ignored: mono sensor),
//     GammaEnable (1) + Gamma (0.45: v = max (v/max)^Gamma), LUTEnable (1: the
//     LUT v = sqrt(v max)), BlackLevel (DN added, default 0), and a vendor's own
//     ContrastAuto (on: the same LUT; not a standard name, found in the feature
//     tree): a client that leaves them on gets frames unlike its settings;
//   DeviceFirmwareVersion, GevSCPSPacketSize (bytes, 576 .. 9000, default 8192:
//     the GVSP packets' size), GevSCPD (ticks, 0 .. 1e6; stored and read back,
//     no delay is made),
//   AcquisitionMode/Start/Stop, AcquisitionFrameRate (free running),
//   TriggerSelector, TriggerMode, TriggerSource (Line0 | Software), TriggerSoftware.
// Any GenICam client sees these (e.g. `arv-tool-0.8 -a 127.0.0.1 control ExposureTime`).
//
// Frames come from a render callback. It runs in the server's own render
// thread, never in Aravis's GVCP thread, so the camera keeps answering control
// requests and heartbeats however long a render takes:
//   - software trigger: the TriggerSoftware register the client writes is
//     watched by the render thread; on a trigger it snapshots the settings,
//     renders, packs the pixels to the wire format and sends the frame's GVSP
//     packets at once from the render thread (in-process: hands it to the
//     waiting fill callback). A frame therefore shows the state of the world
//     (turntable, lamps) at the time the trigger arrived, plus the render time.
//   - free running (TriggerMode Off): the render thread renders a new frame as
//     soon as the previous one was sent; Aravis sends the newest finished one.
//     (The first frame after AcquisitionStart may find none ready and is then
//     rendered in Aravis's thread: counted in late_frames.)
//
// Only one server can listen on an address at a time (UDP port 3956); a
// second start on the same address waits (busy_wait_s) or fails with
// RIG_ERR_BUSY. Serve on loopback addresses only (127.0.0.0/8 is enforced), and
// Aravis serves only on an address a network interface has (here: 127.0.0.1).
//
// In-process (params.inprocess): the same camera (XML, registers, render
// thread) as an Aravis ArvFakeDevice inside this process, without any socket
// or lock file: rig_camera_open_aravis("inprocess:SERIAL") opens it through a
// registry of this process, so the real Aravis camera code (GenICam features,
// ArvCamera, ArvStream, buffers) runs without the network stack, and tests
// may run in parallel. Aravis's in-process stream fills any queued buffer
// regardless of triggers and acquisition; here a queued buffer waits in the
// fill callback until the render thread has the frame of the next software
// trigger (or of free running), so a client sees the same behaviour as over
// GigE Vision: one frame per trigger, showing the world at the trigger. A
// buffer still waiting is released (filled with zeros) when the acquisition
// stops. One in-process server per serial in a process.
#pragma once

#include <stddef.h>
#include <stdint.h>

#include "rig/rig.h"

#ifdef __cplusplus
extern "C" {
#endif

// Render one frame. `settings` holds the camera settings the frame is taken
// with (width, height, offsets, pixel_format, bits, exposure_us, gain in dB,
// temperature_c, vendor/model/serial) and, in frame_id and timestamp_ns, the
// server's own count of renders (1, 2, ...) and the trigger time (CLOCK_REALTIME,
// ns). Write width*height values, row-major, into pix, in the range of the
// format (0..255, 0..4095, 0..65535); larger values are saturated to the
// maximum, as a sensor's ADC does. Return 0, or a negative RIG_ERR_* code: then
// no frame is sent for that trigger (the client times out) and the error is
// counted in the statistics. Called from the server's render thread only, one
// call at a time; guard any state shared with other threads yourself.
typedef int (*rig_gv_render_fn)(void *ctx, const rig_frame_meta_t *settings, uint16_t *pix);

typedef struct {
    const char *address;          // interface address to listen on, 127.x.y.z (default "127.0.0.1")
    const char *serial;           // DeviceID / DeviceSerialNumber, < 16 chars (default "REFL-GV01")
    const char *vendor;           // DeviceVendorName, < 32 chars (default "refl")
    const char *model;            // DeviceModelName, < 32 chars (default "virtual camera")
    int         sensor_width;     // pixels (default 1280), 1..4096
    int         sensor_height;    // pixels (default 1024), 1..4096
    double      temperature_c;    // initial DeviceTemperature (default 35)
    double      trigger_poll_hz;  // how often triggers are looked for (default 1000)
    // Servers of refl on one address take turns through a lock file
    // ($TMPDIR/refl-gvcam-ADDRESS.lock, held while serving): wait up to this
    // long for another one to stop (default 0: fail at once with RIG_ERR_BUSY).
    double      busy_wait_s;
    rig_gv_render_fn render;      // required
    void       *render_ctx;
    // Serve in this process instead (see above): address and busy_wait_s are
    // not used; the camera's id is RIG_GV_INPROCESS_PREFIX + serial.
    bool        inprocess;
    const char *firmware;         // DeviceFirmwareVersion, < 32 chars (default "refl-gv 1.0")
    // Variants for tests of the client: the Gain feature's <Unit> (NULL: "dB";
    // "": none, as a camera whose gain is raw), and an auto feature
    // ("ExposureAuto", "GainAuto", "BalanceWhiteAuto") without an Off entry,
    // so it cannot be switched off (NULL: none).
    const char *gain_unit;
    const char *refuse_off;
} rig_gv_camera_params_t;

#define RIG_GV_INPROCESS_PREFIX "inprocess:"

typedef struct {
    uint64_t triggers;            // software triggers seen
    uint64_t frames_rendered;     // successful renders
    uint64_t frames_sent;         // frames sent (GVSP), or handed to Aravis (free running, in-process)
    uint64_t send_errors;         // triggered frames whose GVSP packets could not be sent
    uint64_t render_errors;       // renders that returned an error (no frame sent)
    uint64_t dropped_triggers;    // triggers dropped on purpose (rig_gv_camera_drop_triggers)
    uint64_t late_frames;         // frames rendered inside Aravis's thread (no frame ready in time)
    double   render_s_total;      // wall time spent in the render callback
} rig_gv_camera_stats_t;

typedef struct rig_gv_camera rig_gv_camera_t;

rig_gv_camera_params_t rig_gv_camera_defaults(void);

// Start serving. Fails with RIG_ERR_INVALID (bad parameters, non-loopback
// address), RIG_ERR_BUSY (something already listens on address:3956) or
// RIG_ERR_IO. The server runs in threads of its own until rig_gv_camera_stop.
int  rig_gv_camera_start(rig_gv_camera_t **out, const rig_gv_camera_params_t *p);
// Stop serving and free; accepts NULL. A client still connected then sees the
// camera disappear (its requests time out).
void rig_gv_camera_stop(rig_gv_camera_t *g);

// Set the DeviceTemperature the camera reports (and passes to the renderer).
void rig_gv_camera_set_temperature(rig_gv_camera_t *g, double temperature_c);
// Fault injection: swallow the next n software triggers (no frame is sent), as
// a camera that loses frames does.
void rig_gv_camera_drop_triggers(rig_gv_camera_t *g, int n);
void rig_gv_camera_stats(rig_gv_camera_t *g, rig_gv_camera_stats_t *out);
// The last error message of the render callback ("" when none).
void rig_gv_camera_last_render_error(rig_gv_camera_t *g, char *buf, size_t size);

// For rig/camera/aravis.c: the ArvDevice (as void *) of this process's
// in-process server with that serial, as a new reference (g_object_unref it),
// or NULL when there is none.
void *rig_gv_camera_inprocess_device(const char *serial);
// Is the in-process server of this device still serving? (false after
// rig_gv_camera_stop: a client holding the device gets no more frames.)
bool rig_gv_camera_inprocess_alive(const void *device);

#ifdef __cplusplus
}
#endif
