// rig/virtual/virtual.c — the virtual rig: a simulated turntable, simulated lamps and a
// virtual GigE Vision camera (rig/virtual/gv_camera.h) on a loopback address whose
// frames are rendered by model/ from the state of the simulated devices.
//
// Ground truth: one INI file (examples/virtual-truth.ini documents every key):
//   [virtual]    format_version (optional, 1; rig/virtual/truth.h), sample
//                (default sample), lamp_warmup_ms, lamp_settle_ms
//   [camera]     model (mrcal .cameramodel, relative to the truth file),
//                model_sha256 (checked), kc_per_us, serial, vendor, model_name,
//                temperature_c
//   [render]     interreflection = none|thesis|mc, direct_samples, mc_samples,
//                mc_bounces, indirect_downsample, thesis_samples, thesis_cone_deg,
//                rho_sr, finite_lamps, seed, prerender = 0|1|2
//   [sensor]     model_sensor_t's keys (exposure_us and noise_seed are set per frame)
//   [optics]     rays_per_pixel, psf = none|gaussian|disc, psf_sigma_px,
//                psf_radius_px (rig/virtual/optics.c: applied to every lamp's plane)
//   [turntable]  speed_deg_s, accel_deg_s2, home_time_s, position_noise_deg, seed,
//                fault_after_moves, fault = motion|stall|disconnect
//   [lamp NAME]  position_mm, intensity, radius_mm, emission_cos_power, emission_axis
//   [lamp_drift NAME], [stray]  lamp warm-up and drift, stray light (rig/virtual/lamps.h)
//   [material NAME] model and parameters
//   [texture MATERIAL] amplitude (0..0.5), scale_mm (> 0), seed: an albedo
//                texture of that material (see texture_t)
//   [sample NAME] kind = workpiece|chessboard|reference_white|material_coupon|mirror_sphere,
//                scene (relative path); chessboard: square_mm, corners, corner0_mm;
//                reference_white / material_coupon: material; mirror_sphere:
//                sphere_centre_mm (x y z at angle 0) and sphere_radius_mm, the
//                facts of the scene's '@sphere' (checked against it)
//                optional direct_samples: this sample's finite-lamp samples per pixel
//                (overrides [render]; a mirror needs many: its highlights are images
//                of the lamps, which one sample per pixel would dither)
//                | kind = uniform_source, radiance (no scene): a flat-field source
//                filling the view (an integrating sphere's port in front of the
//                lens) fed by the rig's lamps: each lamp that is on adds
//                `radiance` at every pixel (EMVA 1288 sweeps, flat fields)
//   Sample poses (rig_virtual_set_sample_pose): a sample on a wedge, rotated by
//   tilt_deg about the horizontal hinge axis (cos az, sin az, 0) through the
//   rig origin, then lifted along z so its lowest point stays at its height;
//   the turntable angle applies after the pose.
//   [placement] and the [turntable] axis keys (axis_tilt_deg,
//   axis_tilt_azimuth_deg, wobble_deg): placement errors and an imperfect
//   rotation axis, off by default (rig/virtual/place.h).
//
// The camera is served over GigE Vision on a loopback address, or in-process
// (options.serve: an Aravis fake device in this process, rig/virtual/gv_camera.h);
// both use the same server, render path and frames.
//
// A frame (software trigger, in the camera server's render thread):
//   angle   = the turntable's measured angle at the trigger (status)
//   mask    = the lamps that are on at the trigger
//   L_i     = the radiance image of lamp i alone (kc 1, Pa 0) of the sample
//             rotated by angle about z; kept in a cache keyed by (sample,
//             angle, lamp), as the bracket of the grey value is linear in the
//             lamps. With interreflection = mc (the default of the example):
//               direct   full resolution, MC with 0 bounces: each lamp a sphere
//                        of radius_mm sampled direct_samples times per pixel
//                        (soft shadows; the penumbra is dithered, per state)
//               indirect mc_samples paths of mc_bounces bounces (point lamps at
//                        the path vertices) rendered at 1/indirect_downsample
//                        of the resolution with a camera of scaled intrinsics,
//                        minus the direct term there (so only the
//                        interreflection stays), and upsampled bilinearly from
//                        the four low-resolution pixels around a pixel when
//                        all four see its face; the pixels where they do not
//                        (within ~ds pixels of a face's edge, where the
//                        indirect light changes fastest) get theirs at full
//                        resolution (no light leaks across silhouettes, none
//                        is lost toward a concave corner)
//             Interreflection is smooth, so its low resolution costs little
//             accuracy and keeps a new state's rendering near 100 ms on 2 cores.
//             thesis / none: one full-resolution model_render.
//             Textured materials multiply L at the first hit (see texture_t).
//             Spheres (D3D '@sphere', the mirror sphere) are exact model
//             primitives; their face id is nfaces + k (no texture).
//   gf      = 10^(gain_db / 20)
//   P       = dark_offset_dn + kc_per_us * exposure_us * gf * sum_{i in mask} L_i
//   sensor  = the truth's sensor with system gain K * gf (the gain amplifies
//             electrons: the electron count, hence the shot noise in
//             electrons, does not depend on the gain), exposure_us (dark
//             current) and noise_seed = the next frame seed
//   DN      = model_sensor_apply_patterns (fixed patterns made once for the
//             whole sensor), cropped to the region, then mapped to the pixel
//             format from the sensor's `bits` b: Mono8 v >> (b - 8), Mono12
//             v << (12 - b) or >> (b - 12), Mono16 v << (16 - b) (12-bit values
//             << 4 in Mono16, >> 4 in Mono8); Mono10 and the packed formats of
//             rig/camera/pixfmt.h by their bits alike (Mono12p as Mono12).
// The expected frame (rig_virtual_expected) is the same chain with
// model_sensor_mean instead of the noisy sensor (a right shift becomes a
// division by 2^s minus (2^s - 1) / 2^(s+1), the mean of the floor).
// While the stage moves, a frame shows the angle at the trigger (no motion blur).
// Speculation (prerender >= 1): while the stage stands still and no trigger
// waits, the pre-render thread also computes the next frames of the current
// state ahead of their triggers, with the exposures and gains the last state's
// frames had (a plan repeats its exposure list in every state) and the noise
// seeds those triggers will draw. A trigger whose state, exposure, gain and
// seed are exactly those of such a frame takes it: the same values it would
// compute (the frame is a function of these inputs only), but its sensor
// noise then costs no time after the trigger. Others compute as above.
// Ahead of an angle: a plan repeats its lamp sets and exposures at every
// angle, so while the stage moves to a new angle (the simulated stage knows
// where it will stand, noise included, rig_turntable_sim_destination) the
// pre-render thread computes the frames the last angle's sequence predicts
// there (lamps, exposure, gain, and the seeds in order) once the last two
// angles had the same sequence, and at an angle whose frames so far follow
// the last angle's, the rest of that sequence. A trigger that matches one
// takes it, as above; the motion's idle time pays for them.
#define _GNU_SOURCE
#include <glib.h>
#include <math.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "rig/virtual/internal.h"

rig_virtual_options_t rig_virtual_defaults(void)
{
    return (rig_virtual_options_t){
        .serve = RIG_VIRTUAL_SERVE_GIGE,
        .address = "127.0.0.1",
        .sample = NULL,
        .time_scale = 1,
        .noise_seed = 1,
        .busy_wait_s = 0,
        .prerender = -1,
    };
}

// ---------------------------------------------------------------------------
// The turntable seen by users: the simulated stage behind state_lock, so the
// render thread can read its angle at any time. wait polls the status (every
// millisecond) instead of sleeping inside the stage with the lock held.

static rig_virtual_t *TV(rig_turntable_t *t) { return t->impl; }

static int vt_info(rig_turntable_t *t, rig_turntable_info_t *out)
{
    rig_virtual_t *v = TV(t);
    pthread_mutex_lock(&v->state_lock);
    int r = rig_turntable_info(v->tt_sim, out);
    pthread_mutex_unlock(&v->state_lock);
    return r;
}

static int vt_status(rig_turntable_t *t, rig_turntable_status_t *out)
{
    rig_virtual_t *v = TV(t);
    pthread_mutex_lock(&v->state_lock);
    int r = rig_turntable_status(v->tt_sim, out);
    pthread_mutex_unlock(&v->state_lock);
    return r;
}

static int vt_start_home(rig_turntable_t *t)
{
    rig_virtual_t *v = TV(t);
    pthread_mutex_lock(&v->state_lock);
    int r = v->tt_sim->ops->start_home(v->tt_sim);
    pthread_mutex_unlock(&v->state_lock);
    return r;
}

static int vt_start_move_abs(rig_turntable_t *t, double angle_deg)
{
    rig_virtual_t *v = TV(t);
    pthread_mutex_lock(&v->state_lock);
    int r = rig_turntable_start_move_abs_deg(v->tt_sim, angle_deg);
    pthread_mutex_unlock(&v->state_lock);
    return r;
}

void rig_vsleep_s(double s)
{
    struct timespec ts = { (time_t)s, (long)((s - floor(s)) * 1e9) };
    nanosleep(&ts, NULL);
}

static int vt_wait(rig_turntable_t *t, double timeout_s)
{
    rig_virtual_t *v = TV(t);
    double deadline = model_now_s() + timeout_s;
    for (;;) {
        rig_turntable_status_t st;
        int r = vt_status(t, &st);
        if (r) return r;
        if (!st.moving) {
            if (st.motion_error)
                return rig_fail(RIG_ERR_MOTION, "%s: motion error at %.3f deg (simulated fault): the stage "
                                "stalled or lost position; check for obstructions, then home it again",
                                t->name, st.angle_deg);
            return 0;
        }
        double left = deadline - model_now_s();
        if (left <= 0)
            return rig_fail(RIG_ERR_TIMEOUT, "%s: %s did not finish within %.2f s (at %.3f deg): give it more "
                            "time, or check that nothing blocks the stage; it may still be moving "
                            "(rig_turntable_stop halts it)", t->name, st.homing ? "homing" : "the move",
                            timeout_s, st.angle_deg);
        rig_vsleep_s(fmin(left, 1e-3));
    }
    (void)v;
}

static int vt_stop(rig_turntable_t *t, bool immediate)
{
    rig_virtual_t *v = TV(t);
    pthread_mutex_lock(&v->state_lock);
    int r = rig_turntable_stop(v->tt_sim, immediate);
    pthread_mutex_unlock(&v->state_lock);
    return r;
}

static int vt_start_stop(rig_turntable_t *t, bool immediate)
{
    rig_virtual_t *v = TV(t);
    pthread_mutex_lock(&v->state_lock);
    int r = rig_turntable_start_stop(v->tt_sim, immediate);
    pthread_mutex_unlock(&v->state_lock);
    return r;
}

static void vt_close(rig_turntable_t *t) { (void)t; }   // owned by the virtual rig

static const rig_turntable_ops_t virtual_tt_ops = {
    .backend = "sim",
    .info = vt_info,
    .status = vt_status,
    .start_home = vt_start_home,
    .start_move_abs_deg = vt_start_move_abs,
    .start_move_rel_deg = NULL,
    .wait = vt_wait,
    .stop = vt_stop,
    .start_stop = vt_start_stop,
    .close = vt_close,
};

double rig_virtual_kc_per_us(const rig_virtual_t *v) { return v ? v->kc_per_us : NAN; }
model_sensor_t rig_virtual_sensor_params(const rig_virtual_t *v) { return v->sensor; }
model_camera_t *rig_virtual_camera_model(rig_virtual_t *v) { return v ? v->cam : NULL; }
const model_lamps_t *rig_virtual_lamps_truth(const rig_virtual_t *v) { return v ? v->lamps : NULL; }

void rig_virtual_pixel_response(const rig_virtual_t *v, double *fill, double *sigma_px)
{
    *fill = v->optics.rays_per_pixel > 1 ? 1 : 0;
    *sigma_px = v->optics.psf == RIG_PSF_GAUSSIAN ? v->optics.psf_sigma_px
              : v->optics.psf == RIG_PSF_DISC     ? v->optics.psf_radius_px / 2
                                                  : 0;
}

// ---------------------------------------------------------------------------
// Open / close

static int fail_model(int err)
{
    char msg[1024];
    snprintf(msg, sizeof msg, "%s", model_last_error());
    return rig_fail(err, "virtual rig: %s", msg);
}

// Parse-only check of a truth file's text (rig.h): the truth read for each
// camera, as rig_virtual_open reads it, starting nothing (no camera server,
// stage, lamps or render thread).
int rig_virtual_check_truth(const char *text, size_t len, const char *name, const char *base_dir)
{
    if (!text || !name || !base_dir) return rig_fail(RIG_ERR_INVALID, "virtual rig: check truth: NULL argument");
    char *path = NULL;
    if (asprintf(&path, "%s/%s", base_dir, name) < 0) return rig_fail(RIG_ERR_NO_MEM, "virtual rig: out of memory");
    rig_truth_t *t = rig_truth_parse(text, len, path);
    free(path);
    rig_vtruth_t c;
    bool ok = t && rig_vtruth_read(t, 0, &c);
    if (ok) rig_vtruth_free(&c);
    // every further camera: its [camera NAME] and [sensor NAME]
    int ncams = ok ? rig_vtruth_cameras(t) : -1;
    ok = ncams >= 0;
    for (int k = 1; ok && k < ncams; k++)
        if ((ok = rig_vtruth_read(t, k, &c))) rig_vtruth_free(&c);
    rig_truth_free(t);
    return ok ? RIG_ERR_OK : fail_model(RIG_ERR_INVALID);
}

// The camera of the low-resolution indirect term: intrinsics scaled by 1/ds
// about pixel corners (fx/ds, fy/ds, (c + 0.5)/ds - 0.5), same distortion and
// pose; and its scratch buffers.
static int make_lowres(rig_virtual_t *v)
{
    v->Wl = (v->W + v->ds - 1) / v->ds;
    v->Hl = (v->H + v->ds - 1) / v->ds;
    int err = rig_optics_scaled_camera(v->cam_path, v->cam, 1.0 / v->ds, v->Wl, v->Hl, &v->cam_lr);
    if (err == RIG_ERR_NOT_SUPPORTED) {
        char *why = g_strdup(model_last_error());
        err = rig_fail(err, "%s; set indirect_downsample = 1 in [render] of %s", why, v->truth_path);
        g_free(why);
    }
    if (err) return err;
    size_t nl = (size_t)v->Wl * v->Hl;
    v->face_lr = malloc(nl * sizeof *v->face_lr);
    v->A_lr = malloc(nl * sizeof *v->A_lr);
    v->B_lr = malloc(nl * sizeof *v->B_lr);
    if (!v->face_lr || !v->A_lr || !v->B_lr)
        err = rig_fail(RIG_ERR_NO_MEM, "virtual rig: out of memory");
    return err;
}

// rays_per_pixel N > 1: the camera of N times the resolution and its buffers.
static int make_highres(rig_virtual_t *v)
{
    const int N = v->optics.rays_per_pixel;
    int err = rig_optics_scaled_camera(v->cam_path, v->cam, N, v->W * N, v->H * N, &v->cam_hr);
    if (err) return err;
    size_t n = (size_t)v->W * v->H * N * N;
    v->face_hr = malloc(n * sizeof *v->face_hr);
    v->L_hr = malloc(n * sizeof *v->L_hr);
    if (!v->face_hr || !v->L_hr)
        return rig_fail(RIG_ERR_NO_MEM, "virtual rig: out of memory for %d x %d rays per pixel", N, N);
    return 0;
}

// Camera k's loopback address: the k-th of the space-separated list, else
// the address after camera k-1's (last byte + 1). false when none is left.
static bool camera_address(const char *list, int k, char out[64])
{
    gchar **a = g_strsplit_set(list, " \t", -1);
    int n = 0, last = -1;
    for (int i = 0; a[i]; i++)
        if (a[i][0]) {
            if (n <= k) last = i;
            n++;
        }
    bool ok = last >= 0;
    if (ok) snprintf(out, 64, "%s", a[last]);
    int more = k - (n - 1);
    if (ok && more > 0) {
        char *dot = strrchr(out, '.');
        long b = dot ? strtol(dot + 1, NULL, 10) + more : 256;
        ok = dot && b < 255;
        if (ok) snprintf(dot + 1, 64 - (size_t)(dot + 1 - out), "%ld", b);
    }
    g_strfreev(a);
    return ok;
}

// The options of camera k, checked, into *o, and its address.
static int check_options(const rig_virtual_options_t *opt, int k, rig_virtual_options_t *o, char addr[64])
{
    *o = opt ? *opt : rig_virtual_defaults();
    if (!o->address) o->address = "127.0.0.1";
    if (!camera_address(o->address, k, addr))
        return rig_fail(RIG_ERR_INVALID, "virtual rig: address '%s': no loopback address for camera %d", o->address,
                        k + 1);
    if (!(isfinite(o->time_scale) && o->time_scale > 0))
        return rig_fail(RIG_ERR_INVALID, "virtual rig: time_scale %g must be > 0", o->time_scale);
    if (strlen(addr) >= 64 - 1) return rig_fail(RIG_ERR_INVALID, "virtual rig: address '%s' is too long", addr);
    if (o->serve != RIG_VIRTUAL_SERVE_GIGE && o->serve != RIG_VIRTUAL_SERVE_INPROCESS)
        return rig_fail(RIG_ERR_INVALID, "virtual rig: serve = %d is neither RIG_VIRTUAL_SERVE_GIGE nor "
                        "RIG_VIRTUAL_SERVE_INPROCESS", (int)o->serve);
    return 0;
}

// A rig (or a view of parent) that holds nothing yet. NULL: out of memory.
static rig_virtual_t *new_rig(const char *truth_path, const char *addr, uint64_t noise_seed, int k,
                              rig_virtual_t *parent)
{
    rig_virtual_t *v = calloc(1, sizeof *v);
    if (!v) return NULL;
    pthread_mutex_init(&v->state_lock, NULL);
    pthread_mutex_init(&v->cache_lock, NULL);
    v->truth_path = strdup(truth_path);
    snprintf(v->address, sizeof v->address, "%s", addr);
    v->next_seed = noise_seed + (uint64_t)k * 1000003u;   // each camera its own noise
    v->state = parent ? parent : v;
    v->views[v->nviews++] = v;
    if (!v->truth_path) {
        rig_virtual_close(v);
        return NULL;
    }
    return v;
}

// What the truth says for the rig's camera, taken over from c (the rest of c,
// the devices' parameters, stays with the caller).
static void take_truth(rig_virtual_t *v, rig_vtruth_t *c)
{
    snprintf(v->cam_sec, sizeof v->cam_sec, "%s", c->cam_sec);
    snprintf(v->cam_name, sizeof v->cam_name, "%s", c->cam_name);
    v->cam = c->cam;
    v->cam_path = c->cam_path;
    v->W = c->W;
    v->H = c->H;
    v->kc_per_us = c->kc_per_us;
    v->sensor = c->sensor;
    v->shading = c->shading;
    v->direct_samples = c->direct_samples;
    v->ds = c->ds;
    v->prerender = c->prerender;
    v->lamps = c->lamps;
    v->lamp_fx = c->lamp_fx;
    v->mats = c->mats;
    v->textures = c->textures;
    v->ntextures = c->ntextures;
    v->samples = c->samples;
    v->nsamples = v->nbase_samples = c->nsamples;
    v->optics = c->optics;
    v->place = c->place;
    c->cam = NULL;
    c->cam_path = NULL;
    c->lamps = NULL;
    c->mats = NULL;
    c->textures = NULL;
    c->samples = NULL;
    c->nsamples = c->ntextures = 0;
}

// The rig's options over the truth's (time scale, pre-rendering, serial) and
// the sample it opens with.
static int take_options(rig_virtual_t *v, const rig_virtual_options_t *o, rig_vtruth_t *c, bool view, int k)
{
    v->lamp_fx.time_scale = o->time_scale;
    if (o->prerender >= 0) {
        if (o->prerender > 2) return rig_fail(RIG_ERR_INVALID, "virtual rig: prerender %d outside 0..2", o->prerender);
        v->prerender = o->prerender;
    }
    if (o->serial && k == 0) c->gp.serial = o->serial;
    if (view) v->prerender = 0;
    const char *sample = o->sample ? o->sample : c->default_sample ? c->default_sample : v->samples[0].name;
    v->cur_sample = rig_vsample_find(v->samples, v->nsamples, sample);
    if (v->cur_sample < 0) {
        char list[512];
        rig_vsample_list(v->samples, v->nsamples, list, sizeof list);
        return rig_fail(RIG_ERR_INVALID, "virtual rig: %s has no sample '%s'; samples: %s", v->truth_path, sample,
                        list);
    }
    return 0;
}

// The render cameras and buffers: the low- and high-resolution cameras, the
// sensor's fixed patterns, the frame and face buffers, the ray table.
static int make_buffers(rig_virtual_t *v)
{
    int err = 0;
    if (v->shading.interreflection == MODEL_INTERREFLECTION_MC && v->ds > 1 && (err = make_lowres(v))) return err;
    if (v->optics.rays_per_pixel > 1 && (err = make_highres(v))) return err;
    size_t n = (size_t)v->W * v->H;
    v->prnu = malloc(n * sizeof(float));
    v->dsnu = malloc(n * sizeof(float));
    v->frame = malloc(n * sizeof(float));
    v->face = malloc(n * sizeof *v->face);
    if (!v->prnu || !v->dsnu || !v->frame || !v->face)
        return rig_fail(RIG_ERR_NO_MEM, "virtual rig: out of memory for %dx%d images", v->W, v->H);
    model_sensor_patterns(&v->sensor, v->W, v->H, v->prnu, v->dsnu);
    return model_camera_ray_table(v->cam, NULL) ? 0 : fail_model(RIG_ERR_IO);
}

// The rig's devices: the simulated stage (behind state_lock) and lamps.
static int open_devices(rig_virtual_t *v, const rig_vtruth_t *c, double time_scale)
{
    rig_turntable_sim_params_t tp = c->tp;
    tp.time_scale = time_scale;
    int err = rig_turntable_open_sim(&v->tt_sim, &tp);
    if (err) return err;
    v->tt.ops = &virtual_tt_ops;
    v->tt.impl = v;
    snprintf(v->tt.name, sizeof v->tt.name, "virtual turntable (sim, seed %llu)", (unsigned long long)tp.seed);
    rig_lamp_line_t lines[32];
    memset(lines, 0, sizeof lines);
    for (int i = 0; i < v->lamps->n; i++) {
        snprintf(lines[i].name, sizeof lines[i].name, "%s", v->lamps->lamps[i].name);
        snprintf(lines[i].chip, sizeof lines[i].chip, "virtual");
        lines[i].line = (unsigned)i;
        lines[i].warmup_ms = c->warmup_ms * time_scale;
        lines[i].settle_ms = c->settle_ms * time_scale;
    }
    return rig_lamps_open_sim(&v->lamps_dev, lines, v->lamps->n);
}

// The camera server (its serial unique among the rig's cameras) and the
// pre-render thread.
static int start_camera(rig_virtual_t *v, rig_gv_camera_params_t *gp, const rig_virtual_options_t *o,
                        const rig_virtual_t *parent)
{
    snprintf(v->serial, sizeof v->serial, "%s", gp->serial ? gp->serial : "");
    for (int d = 0; parent && d < parent->nviews; d++)
        if (!strcmp(parent->views[d]->serial, v->serial))
            return rig_fail(RIG_ERR_INVALID, "virtual rig: %s: [%s] and [%s] have the same serial '%s': give each "
                            "camera its own 'serial ='", v->truth_path, parent->views[d]->cam_sec, v->cam_sec,
                            v->serial);
    gp->address = v->address;
    gp->busy_wait_s = o->busy_wait_s;
    gp->render = rig_vrender_cb;
    gp->render_ctx = v;
    gp->inprocess = o->serve == RIG_VIRTUAL_SERVE_INPROCESS;
    if (gp->inprocess)   // the id rig_camera_open_aravis takes
        snprintf(v->address, sizeof v->address, "%s%s", RIG_GV_INPROCESS_PREFIX, gp->serial ? gp->serial : "");
    int err = rig_gv_camera_start(&v->gv, gp);
    if (err) return err;
    if (v->prerender) {
        if (pthread_create(&v->pre_thread, NULL, rig_vprerender_main, v))
            return rig_fail(RIG_ERR_IO, "virtual rig: cannot start the pre-render thread");
        v->pre_running = true;
    }
    return 0;
}

static int open_camera(rig_virtual_t **out, const char *truth_path, const rig_virtual_options_t *opt,
                       rig_virtual_t *parent, int k);

int rig_virtual_open(rig_virtual_t **out, const char *truth_path, const rig_virtual_options_t *opt)
{
    return open_camera(out, truth_path, opt, NULL, 0);
}

// The truth file (*truth, for the caller to free) read for camera k into v
// and *c; *ncams: the file's cameras.
static int read_truth(rig_virtual_t *v, const char *truth_path, int k, rig_truth_t **truth, rig_vtruth_t *c,
                      int *ncams)
{
    *truth = rig_truth_load(truth_path);   // the truth file's one reader (rig/virtual/truth.h)
    bool ok = *truth && (*ncams = rig_vtruth_cameras(*truth)) >= 0 && rig_vtruth_read(*truth, k, c);
    if (ok) take_truth(v, c);
    return ok ? 0 : fail_model(RIG_ERR_INVALID);
}

// Camera k of the truth file: the rig itself (k = 0, parent NULL: the stage,
// the lamps, then cameras 1.. as its views), or a view of parent.
static int open_camera(rig_virtual_t **out, const char *truth_path, const rig_virtual_options_t *opt,
                       rig_virtual_t *parent, int k)
{
    if (!out) return rig_fail(RIG_ERR_INVALID, "virtual rig: NULL output handle");
    *out = NULL;
    if (!truth_path) return rig_fail(RIG_ERR_INVALID, "virtual rig: no truth file given");
    rig_virtual_options_t o;
    char addr[64];
    int err = check_options(opt, k, &o, addr);
    if (err) return err;
    rig_virtual_t *v = new_rig(truth_path, addr, o.noise_seed, k, parent);
    if (!v) return rig_fail(RIG_ERR_NO_MEM, "virtual rig: out of memory");
    rig_truth_t *truth = NULL;   // the strings of c.gp are its
    rig_vtruth_t c = { 0 };
    int ncams = 0;
    if (!(err = read_truth(v, truth_path, k, &truth, &c, &ncams)) &&
        !(err = take_options(v, &o, &c, parent != NULL, k)) && !(err = make_buffers(v)) &&
        (parent || !(err = open_devices(v, &c, o.time_scale))))
        err = start_camera(v, &c.gp, &o, parent);
    for (int cam = 1; !err && !parent && cam < ncams; cam++) {
        rig_virtual_t *w = NULL;
        if (!(err = open_camera(&w, truth_path, &o, v, cam))) v->views[v->nviews++] = w;
    }
    if (!err && !parent && v->place.on) err = rig_virtual_set_sample(v, v->samples[v->cur_sample].name);
    rig_truth_free(truth);
    if (err) {
        rig_virtual_close(v);
        return err;
    }
    *out = v;
    return 0;
}

void rig_virtual_close(rig_virtual_t *v)
{
    if (!v) return;
    for (int c = v->nviews - 1; c >= 1; c--) rig_virtual_close(v->views[c]);
    if (v->pre_running) {
        __atomic_store_n(&v->pre_stop, 1, __ATOMIC_RELEASE);
        pthread_join(v->pre_thread, NULL);
    }
    rig_gv_camera_stop(v->gv);   // no render runs after this
    rig_lamps_close(v->lamps_dev);
    rig_turntable_close(v->tt_sim);
    for (int i = 0; i < NPLANES; i++) free(v->planes[i].L);
    for (int i = 0; i < NTRACERS; i++) rig_vslot_free(&v->tracers[i]);
    rig_vsamples_free(v->samples, v->nsamples);
    free(v->place_count);
    model_lamps_free(v->lamps);
    model_materials_free(v->mats);
    free(v->textures);
    model_camera_free(v->cam);
    model_camera_free(v->cam_lr);
    model_camera_free(v->cam_hr);
    free(v->face_hr);
    free(v->L_hr);
    free(v->cam_path);
    free(v->face);
    free(v->face_lr);
    free(v->A_lr);
    free(v->B_lr);
    free(v->prnu);
    free(v->dsnu);
    free(v->frame);
    for (int k = 0; k < NSPEC; k++) free(v->spec[k].img);
    free(v->truth_path);
    pthread_mutex_destroy(&v->state_lock);
    pthread_mutex_destroy(&v->cache_lock);
    free(v);
}

rig_turntable_t *rig_virtual_turntable(rig_virtual_t *v) { return v ? &v->state->tt : NULL; }
int rig_virtual_ncameras(const rig_virtual_t *v) { return v ? v->nviews : 0; }
rig_virtual_t *rig_virtual_camera_view(rig_virtual_t *v, int k)
{
    return v && k >= 0 && k < v->state->nviews ? v->state->views[k] : NULL;
}
const char *rig_virtual_camera_name(const rig_virtual_t *v) { return v ? v->cam_name : NULL; }
rig_lamps_t *rig_virtual_lamps(rig_virtual_t *v) { return v ? v->state->lamps_dev : NULL; }
const char *rig_virtual_camera_address(const rig_virtual_t *v) { return v ? v->address : NULL; }
rig_gv_camera_t *rig_virtual_gv_camera(rig_virtual_t *v) { return v ? v->gv : NULL; }
const char *rig_virtual_truth_path(const rig_virtual_t *v) { return v ? v->truth_path : NULL; }

long rig_virtual_frames_ahead(rig_virtual_t *v)
{
    if (!v) return 0;
    pthread_mutex_lock(&v->cache_lock);
    long n = v->frames_ahead;
    pthread_mutex_unlock(&v->cache_lock);
    return n;
}

bool rig_virtual_destination(rig_virtual_t *v, double *angle_deg)
{
    if (v) v = v->state;
    if (!v) return false;
    pthread_mutex_lock(&v->state_lock);
    bool ok = !v->stage_gone && rig_turntable_sim_destination(v->tt_sim, angle_deg);
    pthread_mutex_unlock(&v->state_lock);
    return ok;
}
