// rig/virtual/virtual.h — the virtual rig (rig/virtual/virtual.c).
#pragma once

#include <stdbool.h>
#include <stdint.h>

#include "model/model.h"
#include "rig/devices.h"

#ifdef __cplusplus
extern "C" {
#endif

// ---------------------------------------------------------------------------
// The virtual rig (rig/virtual/virtual.c): a simulated turntable, simulated lamps and
// a virtual GigE Vision camera (rig/virtual/gv_camera.h) on 127.0.0.1 whose frames are
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
    const char *address;        // where the cameras serve (default "127.0.0.1"; GigE only): one loopback
                                // address per camera, separated by spaces; a camera without one serves on
                                // the address after the previous camera's (127.0.0.1 127.0.0.2 ...)
    const char *sample;         // the sample on the table (default: the truth file's `sample`)
    double      time_scale;     // turntable and lamp timing: 1 real time, 0.01 = 100x faster
    uint64_t    noise_seed;     // first frame's noise seed (default 1; +1 per frame; camera k from
                                // noise_seed + k * 1000003)
    double      busy_wait_s;    // wait this long for another camera server on the address to stop (default 0; GigE only)
    const char *serial;         // the (first) camera's serial instead of the truth file's (NULL: the file's); a process
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
// Cameras: the truth file's [camera] or [camera NAME] sections (one or more,
// with [sensor NAME] keys over [sensor] for camera NAME), in file order. The
// rig is its first camera; camera k (0 <= k < rig_virtual_ncameras) is a view
// (NULL outside the range) with its own camera server (address, serial),
// model, sensor and kc, showing the rig's stage, lamps and sample: the
// per-camera functions below (camera address, gv camera, expected, radiance,
// sensor, kc, camera model) take a view; the devices and samples are shared.
// rig_virtual_close closes the views with the rig (never close a view).
int            rig_virtual_ncameras(const rig_virtual_t *v);
rig_virtual_t *rig_virtual_camera_view(rig_virtual_t *v, int k);
// The view's camera name: NAME of [camera NAME], or "camera".
const char    *rig_virtual_camera_name(const rig_virtual_t *v);
// The devices (owned by the virtual rig; do not close them yourself).
rig_turntable_t *rig_virtual_turntable(rig_virtual_t *v);
rig_lamps_t     *rig_virtual_lamps(rig_virtual_t *v);
// The camera's id for rig_camera_open_aravis: the address ("127.0.0.1"), or
// "inprocess:SERIAL" when served in-process.
const char      *rig_virtual_camera_address(const rig_virtual_t *v);
// The camera server (rig/virtual/gv_camera.h), for fault injection in tests; NULL
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
// The sample on the table placed off where it belongs by a known amount (an
// operator's placement off the fixture; the detection study's placed-off
// cases): after its placement error ([placement]) turned by turn_deg about z
// through its centre (the middle of its bounding box) and shifted by (dx_mm,
// dy_mm) on the table. |turn| <= 45 deg, |shift| <= 100 mm. Not for a uniform source.
int  rig_virtual_set_sample_offset(rig_virtual_t *v, const char *name, double turn_deg, double dx_mm, double dy_mm);
// Whether rig_virtual_set_sample_pose would take that pose (0, or its error
// with the message), without putting the sample anywhere: a placement error
// ([placement]) is drawn when the operator places a sample, not by a check.
int  rig_virtual_check_sample_pose(rig_virtual_t *v, const char *name, double tilt_deg, double tilt_azimuth_deg);
// The placement error of the current sample (truth, [placement]): the turn
// about its centre (deg) and the shift (mm) in the plane it rests on. false
// when it was placed without one (no [placement]; a uniform source).
bool rig_virtual_last_placement(rig_virtual_t *v, double *turn_deg, double *dx_mm, double *dy_mm);
// The current sample's pose (truth): x_table = R x_sample_file + t (R
// row-major; identity and 0 at tilt 0 without a placement error). With a truth
// [placement] section (rig/virtual/place.h) every placement (each call of
// rig_virtual_set_sample*) adds a random rigid error, and R, t are the actual
// pose used (tilt_deg, tilt_azimuth_deg stay the nominal ones). Any pointer may be NULL.
int  rig_virtual_sample_pose(rig_virtual_t *v, double *tilt_deg, double *tilt_azimuth_deg, double R[9], double t[3]);
// The turntable's rotation at angle_deg (truth): x_rig = R x_table (row-major):
// Rz(angle) for an ideal stage; with the truth's [turntable] axis_tilt_deg,
// axis_tilt_azimuth_deg and wobble_deg the tilted, wobbling axis
// (rig/virtual/place.h). The frames render the sample through it.
int  rig_virtual_table_pose(rig_virtual_t *v, double angle_deg, double R[9]);
const char *rig_virtual_sample(const rig_virtual_t *v);
const char *rig_virtual_truth_path(const rig_virtual_t *v);
// The noise-free expected frame (DN of the camera's pixel format, before the
// sensor's noise and quantisation but with its gain patterns, offsets and
// non-linearity) for a state: for tests and for checking calibrations.
// gain_db in dB; width x height: the region at the sensor's top-left corner
// (the full sensor is the camera model's size); the sample is the current one.
// With the truth's [lamp_drift] / [stray] (rig/virtual/lamps.h) it has the lamps'
// factors of the moment of the call (a lamp of the mask that is off: just switched
// on) and the stray light, as a frame triggered then.
// The devices are owned by the rig: rig_virtual_close closes them (never
// rig_lamps_close / rig_turntable_close them yourself).
int  rig_virtual_expected(rig_virtual_t *v, double angle_deg, uint32_t lamp_mask,
                          double exposure_us, double gain_db, const char *pixel_format,
                          int width, int height, float *out);

// The radiance plane of one lamp at an angle for the current sample (kc 1,
// Pa 0: model units, as model_render's bracket; the whole sensor, W*H floats
// into out): what the rig's frames are made of. Lamps add linearly. (Without
// warm-up, drift and stray light: those a frame applies when it sums the lamps.)
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
// Truth: the pixels' footprint and the optics' blur of [optics], as
// verification models them (fit/verify/footprint.h): *fill 1 when each pixel
// integrates rays over its square (rays_per_pixel > 1), 0 for one ray at its
// centre; *sigma_px the Gaussian PSF's sigma (a disc of radius R: R / 2, its
// second moment), 0 without.
void                 rig_virtual_pixel_response(const rig_virtual_t *v, double *fill, double *sigma_px);
// Frames the camera handed out that the pre-render thread had computed ahead
// of their triggers (speculation; see rig/virtual/virtual.c), since the rig opened.
long                 rig_virtual_frames_ahead(rig_virtual_t *v);
// rig_turntable_sim_destination of the rig's simulated stage.
bool                 rig_virtual_destination(rig_virtual_t *v, double *angle_deg);

#ifdef __cplusplus
}
#endif
