// rig/virtual/virtual.c — the virtual rig: a simulated turntable, simulated lamps and a
// virtual GigE Vision camera (rig/virtual/gv_camera.h) on a loopback address whose
// frames are rendered by model/ from the state of the simulated devices.
//
// Ground truth: one INI file (examples/virtual-truth.ini documents every key):
//   [virtual]    sample (default sample), lamp_warmup_ms, lamp_settle_ms
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
#include <limits.h>
#include <math.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include <mrcal/mrcal.h>

#include "model/model.h"
#include "rig/virtual/gv_camera.h"
#include "rig/internal.h"
#include "rig/camera/pixfmt.h"
#include "rig/rig.h"
#include "rig/virtual/truth.h"
#include "rig/virtual/lamps.h"
#include "rig/virtual/optics.h"
#include "rig/virtual/materials.h"
#include "rig/virtual/place.h"

#define NPLANES  12   // cached radiance images (5 MB each at 1280x1024)
#define NTRACERS 3    // cached (sample, angle) tracers
#define NSPEC    16   // speculative frames (see spec_t; 5 MB each at 1280x1024, made when first used)
#define NSEQ     16   // exposures remembered per state
#define NASEQ    64   // frames remembered per angle (lamps and exposures)

// An albedo texture of a material (simulator only: the fitter's model has
// none): R at the first hit is multiplied by 1 + amplitude * n(u, v), n a
// smooth value noise in [-1, 1] (three octaves, quintic interpolation) of the
// hit point's coordinates in its face's own frame (origin at the face's first
// vertex, u along its first edge, v = normal x u; scaled by 1/scale_mm), seeded
// by the seed and the face number: it moves with the sample.
typedef struct {
    char     material[64];
    double   amplitude, scale_mm;
    uint64_t seed;
    double   roughness_amplitude;   // 0: none (rig/virtual/materials.c)
} texture_t;

typedef struct {
    char   name[64];
    char   kind[32];
    char  *scene_path;
    int    line;
    model_scene_t *scene;
    const model_material_t **mats;    // scene->nmaterials
    const texture_t **tex;            // scene->nmaterials, NULL = untextured
    bool   textured;
    // roughness variation (rig/virtual/materials.c): the materials' rough and
    // smooth variants, blended per pixel by the slot's rough map
    bool   rough;
    const model_material_t **mats_rough, **mats_smooth;
    model_material_t *rough_store;
    int    direct_samples;            // 0: the [render] value
    // uniform_source: no scene; every lamp that is on adds `radiance` at every pixel
    bool   uniform;
    double radiance;
    // A posed copy of sample `base` (rig_virtual_set_sample_pose): its scene is
    // the base scene moved by x' = R x + t; mats and tex are the base's (not owned).
    bool   variant;
    int    base;
    double tilt_deg, tilt_azimuth_deg;
    double R[9], t[3];
    bool   placed;                    // with a placement error (rig/virtual/place.h): never shared
} sample_t;

#define MAX_POSES 32   // posed copies of samples one rig can hold

typedef struct {
    float   *L;        // W*H radiance (kc 1, Pa 0); NULL = empty slot
    int      sample, lamp;
    double   angle_deg;
    uint64_t used;
} plane_t;

// A frame computed ahead of its trigger by the pre-render thread: the noisy
// sensor values (DN of the sensor's bits, whole sensor) of a state, exposure,
// gain and noise seed. A trigger with exactly these inputs (its state, its
// registers and the seed it draws) takes it instead of computing the same
// values again, so the frame is the one the trigger would have made; any
// other trigger discards the speculative frames of seeds it used up.
typedef struct {
    float   *img;      // W*H; NULL until first used
    bool     valid;
    int      sample;
    double   angle_deg;
    uint32_t mask;
    double   exposure_us, gain_db;
    uint64_t seed;
} spec_t;

// One frame's settings, as the camera asked for them.
typedef struct {
    double exposure_us, gain_db;
} shot_t;

// One frame of an angle's sequence: its lamps and settings.
typedef struct {
    uint32_t mask;
    double   exposure_us, gain_db;
} ashot_t;

typedef struct {
    model_tracer_t *t;
    model_scene_t  *rot;      // the rotated scene
    float          *tex;      // W*H texture factors (textured samples; NULL until made)
    float          *rough;    // W*H roughness mixture weights in [0, 1] (samples with roughness variation)
    int      sample;
    double   angle_deg;
    uint64_t used;
} tracer_slot_t;

#define VIRTUAL_CAMERAS_MAX 8

struct rig_virtual {
    char   *truth_path;
    char    address[64];
    // Cameras: one rig_virtual_t per [camera NAME] of the truth file, in file
    // order. The first is the rig (it owns the stage, the lamps and the
    // others, views[1..]); the others render the first's state (angle, lamps),
    // have a camera server, a model, a sensor and caches of their own, the
    // same samples (rig_virtual_set_sample* reaches every camera) and no
    // pre-render thread.
    char    cam_sec[80], cam_name[32], serial[32];     // "camera" / "camera NAME"; "camera" / NAME
    rig_virtual_t *state;                  // the rig whose stage and lamps a frame shows (itself for the first)
    rig_virtual_t *views[VIRTUAL_CAMERAS_MAX];
    int     nviews;
    model_camera_t    *cam;
    char   *cam_path;
    int     W, H;
    double  kc_per_us;
    model_sensor_t     sensor;
    float  *prnu, *dsnu;              // fixed patterns of the whole sensor
    model_shading_t    shading;
    int     direct_samples;           // mc: finite-lamp samples of the direct light, full resolution
    int     ds;                       // mc: the indirect light is rendered at 1/ds resolution (1: full)
    model_camera_t    *cam_lr;        // that camera (NULL when ds = 1)
    rig_optics_t       optics;        // [optics] (rig/virtual/optics.c)
    model_camera_t    *cam_hr;        // rays_per_pixel N > 1: the camera of N times the resolution
    int32_t           *face_hr;       // its face ids and plane (cache_lock)
    float             *L_hr;
    int     Wl, Hl;
    int32_t *face, *face_lr;          // scratch of the renders (cache_lock)
    float   *A_lr, *B_lr;
    model_lamps_t     *lamps;
    rig_vlamps_t       lamp_fx;       // warm-up, drift, stray light (rig/virtual/lamps.c; off by default)
    model_materials_t *mats;
    texture_t         *textures;
    int                ntextures;
    sample_t *samples;
    int       nsamples, nbase_samples;   // base samples of the truth file, then posed copies
    rig_virtual_place_t place;        // placement and axis errors (rig/virtual/place.h)
    long     *place_count;            // placements of each base sample (the rig's, state)
    int       place_next;             // the next posed copy to reuse when all are taken
    double    place_last[3];          // the current sample's placement error: turn deg, dx, dy mm
    bool      place_last_set;         // (state_lock)

    // state_lock guards: cur_sample, the inner turntable, next_seed.
    pthread_mutex_t state_lock;
    int       cur_sample;
    uint64_t  next_seed;
    double    last_angle_deg;         // the stage's last known angle (a disconnected stage keeps it)
    bool      stage_gone;             // the stage disconnected: the camera and pre-render stop asking it
    rig_turntable_t *tt_sim;          // the simulated stage
    rig_turntable_t  tt;              // what users get: tt_sim behind state_lock
    rig_lamps_t     *lamps_dev;

    // cache_lock guards the caches and the frame buffer (held while rendering).
    pthread_mutex_t cache_lock;
    plane_t       planes[NPLANES];
    tracer_slot_t tracers[NTRACERS];
    uint64_t      tick;
    float        *frame;              // W*H work image
    // Speculation (prerender >= 1): the exposures of the frames taken in the
    // previous state (prev) and so far in the current one (cur, state key
    // cur_*) predict those of the next frames: a plan repeats its exposure
    // list in every state.
    spec_t        spec[NSPEC];
    shot_t        prev[NSEQ], cur[NSEQ];
    int           nprev, ncur;
    int           cur_key_sample;
    double        cur_key_angle;
    uint32_t      cur_key_mask;
    bool          cur_key_set;
    // The frames (lamps, exposure, gain) taken at the angle before the
    // previous one (aprev2), at the previous angle (aprev) and so far at the
    // current one (acur, key akey_*) predict those at the next angle: a plan
    // repeats its lamp sets and exposures at every angle. A sequence is only
    // repeated once it has repeated (two angles alike), so that a client that
    // does something else each time costs no speculation. n > NASEQ: too
    // many to repeat (no prediction).
    ashot_t       aprev2[NASEQ], aprev[NASEQ], acur[NASEQ];
    int           naprev2, naprev, nacur;
    int           akey_sample;
    double        akey_angle;
    bool          akey_set;

    rig_gv_camera_t *gv;

    // Pre-rendering: a thread that renders the planes of the current state
    // as soon as the stage stands still and the lamps are switched (before
    // their warm-up ends), and with prerender = 2 then those of the other
    // lamps (a lamp switch then finds its plane ready, but a trigger that
    // comes at once may wait for a speculative rendering).
    int       prerender;              // 0 off, 1 the lamps that are on, 2 all lamps
    pthread_t pre_thread;
    bool      pre_running;
    int       pre_stop;               // atomic
    int       waiting;                // atomic: frames waiting for cache_lock
    long      frames_ahead;           // frames taken from speculation (cache_lock)
};

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

static void sleep_s(double s)
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
        sleep_s(fmin(left, 1e-3));
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

// ---------------------------------------------------------------------------
// Rendering

static void slot_free(tracer_slot_t *s)
{
    model_tracer_free(s->t);
    model_scene_free(s->rot);
    free(s->tex);
    free(s->rough);
    memset(s, 0, sizeof *s);
}

// The cached tracer of (sample, angle); cache_lock held. NULL on error.
static tracer_slot_t *tracer_for(rig_virtual_t *v, int sample, double angle_deg)
{
    tracer_slot_t *lru = &v->tracers[0];
    for (int i = 0; i < NTRACERS; i++) {
        tracer_slot_t *s = &v->tracers[i];
        if (s->t && s->sample == sample && s->angle_deg == angle_deg) {
            s->used = ++v->tick;
            return s;
        }
        if (!s->t || (lru->t && s->used < lru->used)) lru = s;
    }
    model_scene_t *rot = rig_virtual_place_rotated(&v->place, v->samples[sample].scene, angle_deg);
    if (!rot) return NULL;
    model_tracer_t *t = model_tracer_new(rot);
    if (!t) {
        model_scene_free(rot);
        return NULL;
    }
    slot_free(lru);
    *lru = (tracer_slot_t){ .t = t, .rot = rot, .tex = NULL, .sample = sample, .angle_deg = angle_deg,
                            .used = ++v->tick };
    return lru;
}

// ---------------------------------------------------------------------------
// Texture

static inline uint64_t mix64(uint64_t x)
{
    x += 0x9e3779b97f4a7c15ULL;
    x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ULL;
    x = (x ^ (x >> 27)) * 0x94d049bb133111ebULL;
    return x ^ (x >> 31);
}

// Lattice value in [-1, 1).
static inline double lattice(uint64_t seed, int64_t ix, int64_t iy)
{
    uint64_t h = mix64(seed ^ ((uint64_t)ix * 0x632be59bd9b4e019ULL) ^ ((uint64_t)iy * 0xd1b54a32d192ed03ULL));
    return (double)(h >> 11) * 0x1.0p-52 - 1.0;
}

static inline double quintic(double t) { return t * t * t * (t * (6 * t - 15) + 10); }

// The lattice values of the cell last used at one octave: neighbouring pixels
// mostly fall in the same cell (a cell of the finest octave spans several
// pixels), so they reuse its corners instead of hashing them again.
typedef struct {
    uint64_t seed;
    int64_t  iu, iw;
    double   a, b, c, d;   // (iu, iw), (iu+1, iw), (iu, iw+1), (iu+1, iw+1)
    bool     set;
} cell_cache_t;

static double value_noise(cell_cache_t *cc, uint64_t seed, double u, double w)
{
    double fu = floor(u), fw = floor(w);
    int64_t iu = (int64_t)fu, iw = (int64_t)fw;
    double su = quintic(u - fu), sw = quintic(w - fw);
    if (!cc->set || cc->seed != seed || cc->iu != iu || cc->iw != iw) {
        *cc = (cell_cache_t){ seed, iu, iw, lattice(seed, iu, iw), lattice(seed, iu + 1, iw),
                              lattice(seed, iu, iw + 1), lattice(seed, iu + 1, iw + 1), true };
    }
    double a = cc->a, b = cc->b, c = cc->c, d = cc->d;
    return (a + su * (b - a)) + sw * ((c + su * (d - c)) - (a + su * (b - a)));
}

// The seed of a face's texture.
static uint64_t texture_seed(const texture_t *tx, int face_number)
{
    return mix64(tx->seed ^ mix64((uint64_t)face_number));
}

// The texture's noise n(u, w) in [-1, 1] (u, w in mm in the face's frame;
// seed from texture_seed); cc: the caller's cache of 3 cells (one per octave).
static double texture_noise(cell_cache_t cc[3], const texture_t *tx, uint64_t seed, double u, double w)
{
    double sum = 0, amp = 1, f = 1.0 / tx->scale_mm;
    for (int o = 0; o < 3; o++) {
        sum += amp * value_noise(&cc[o], seed + (uint64_t)o, u * f, w * f);
        amp *= 0.5;
        f *= 2;
    }
    return sum / 1.75;
}

// A textured face's frame: origin v0 (its first vertex), unit u axis e1 along
// its first edge, e2 = normal x e1; NULL tx when untextured.
typedef struct {
    const texture_t *tx;
    uint64_t         seed;
    model_vec3_t     v0, e1, e2;
} face_frame_t;

typedef struct {
    rig_virtual_t       *v;
    const tracer_slot_t *slot;
    const int32_t       *face;
    const model_vec3_t  *rays;
    model_vec3_t         c;
    const face_frame_t  *ff;   // per face of the slot's scene
} tex_job_t;

static void texture_rows(void *ctx, int begin, int end, int thread)
{
    const tex_job_t *J = ctx;
    const rig_virtual_t *v = J->v;
    const model_scene_t *sc = J->slot->rot;
    const model_vec3_t c = J->c;
    cell_cache_t cc[3] = { { 0 } }, cr[3] = { { 0 } };
    for (size_t i = (size_t)begin * v->W; i < (size_t)end * v->W; i++) {
        float *out = &J->slot->tex[i];
        *out = 1.0f;
        if (J->slot->rough) J->slot->rough[i] = 0.5f;
        int f = J->face[i];
        if (f < 0 || f >= sc->nfaces || !J->ff[f].tx) continue;
        const model_face_t *F = &sc->faces[f];
        const face_frame_t *fr = &J->ff[f];
        model_vec3_t nn = F->normal, d = J->rays[i];
        double den = nn.x * d.x + nn.y * d.y + nn.z * d.z;
        if (den == 0) continue;
        double t = (F->offset_mm - (nn.x * c.x + nn.y * c.y + nn.z * c.z)) / den;
        model_vec3_t p = { c.x + t * d.x, c.y + t * d.y, c.z + t * d.z };
        model_vec3_t v0 = fr->v0, e1 = fr->e1, e2 = fr->e2;
        model_vec3_t q = { p.x - v0.x, p.y - v0.y, p.z - v0.z };
        double u = q.x * e1.x + q.y * e1.y + q.z * e1.z, w = q.x * e2.x + q.y * e2.y + q.z * e2.z;
        *out = (float)(1.0 + fr->tx->amplitude * texture_noise(cc, fr->tx, fr->seed, u, w));
        if (J->slot->rough && fr->tx->roughness_amplitude > 0)
            J->slot->rough[i] = (float)(0.5 + 0.5 * texture_noise(cr, fr->tx, mix64(fr->seed ^ 0x70756768ULL), u, w));
    }
}

// The frames of the textured faces of a slot's scene (NULL: out of memory).
static face_frame_t *face_frames(const rig_virtual_t *v, const tracer_slot_t *slot)
{
    const sample_t *sm = &v->samples[slot->sample];
    const model_scene_t *sc = slot->rot;
    face_frame_t *ff = calloc(sc->nfaces > 0 ? (size_t)sc->nfaces : 1, sizeof *ff);
    if (!ff) return NULL;
    for (int f = 0; f < sc->nfaces; f++) {
        const model_face_t *F = &sc->faces[f];
        const texture_t *tx = sm->tex[F->material];
        if (!tx || F->nverts < 2) continue;
        model_vec3_t nn = F->normal;
        model_vec3_t v0 = sc->vertices[F->verts[0]], v1 = sc->vertices[F->verts[1]];
        model_vec3_t e1 = { v1.x - v0.x, v1.y - v0.y, v1.z - v0.z };
        double l1 = sqrt(e1.x * e1.x + e1.y * e1.y + e1.z * e1.z);
        if (!(l1 > 0)) continue;
        e1 = (model_vec3_t){ e1.x / l1, e1.y / l1, e1.z / l1 };
        model_vec3_t e2 = { nn.y * e1.z - nn.z * e1.y, nn.z * e1.x - nn.x * e1.z, nn.x * e1.y - nn.y * e1.x };
        ff[f] = (face_frame_t){ tx, texture_seed(tx, F->number), v0, e1, e2 };
    }
    return ff;
}

// The texture factors of a slot's view from the full-resolution face ids.
static bool make_texture(rig_virtual_t *v, tracer_slot_t *slot, const int32_t *face)
{
    size_t n = (size_t)v->W * v->H;
    slot->tex = malloc(n * sizeof *slot->tex);
    if (v->samples[slot->sample].rough && slot->tex && !(slot->rough = malloc(n * sizeof *slot->rough))) {
        free(slot->tex);
        slot->tex = NULL;
    }
    if (!slot->tex) {
        model_error(v->truth_path, 0, "out of memory for a texture image");
        return false;
    }
    const model_vec3_t *rays = model_camera_ray_table(v->cam, NULL);
    if (!rays) {
        free(slot->tex);
        slot->tex = NULL;
        return false;
    }
    face_frame_t *ff = face_frames(v, slot);
    if (!ff) {
        free(slot->tex);
        slot->tex = NULL;
        model_error(v->truth_path, 0, "out of memory for a texture image");
        return false;
    }
    tex_job_t J = { v, slot, face, rays, model_camera_centre_world(v->cam), ff };
    model_parallel_for(v->H, 16, model_default_threads(), texture_rows, &J);
    free(ff);
    return true;
}

// Add the low-resolution indirect term (A_lr - B_lr) to L, bilinearly from the
// four low-resolution neighbours of the pixel when all four see the pixel's
// face. A pixel where they do not (within about ds pixels of a face's edge,
// where the indirect light changes fastest: it rises toward a concave corner)
// is marked in `full` instead and gets its indirect term at full resolution
// (indirect_full).
typedef struct {
    const rig_virtual_t *v;
    float               *L;
    uint8_t             *full;
} ind_job_t;

static void indirect_rows(void *ctx, int begin, int end, int thread)
{
    const ind_job_t *J = ctx;
    const rig_virtual_t *v = J->v;
    float *L = J->L;
    const int f = v->ds, Wl = v->Wl, Hl = v->Hl;
    for (int y = begin; y < end; y++) {
        double fy = (y + 0.5) / f - 0.5;
        int y0 = (int)floor(fy);
        double wy = fy - y0;
        for (int x = 0; x < v->W; x++) {
            size_t i = (size_t)y * v->W + x;
            J->full[i] = 0;
            int32_t face = v->face[i];
            if (face < 0) continue;
            double fx = (x + 0.5) / f - 0.5;
            int x0 = (int)floor(fx);
            double wx = fx - x0;
            double sum = 0, wsum = 0;
            int same = 0;
            for (int k = 0; k < 4; k++) {
                int xx = x0 + (k & 1), yy = y0 + (k >> 1);
                if (xx < 0 || yy < 0 || xx >= Wl || yy >= Hl) continue;
                size_t j = (size_t)yy * Wl + xx;
                if (v->face_lr[j] != face) continue;
                double w = ((k & 1) ? wx : 1 - wx) * ((k >> 1) ? wy : 1 - wy) + 1e-9;
                sum += w * (v->A_lr[j] - v->B_lr[j]);
                wsum += w;
                same++;
            }
            if (same < 4) J->full[i] = 1;
            else L[i] += (float)(sum / wsum);
        }
    }
}

// The low-resolution indirect term A_lr - B_lr, into A_lr, averaged over each
// pixel's 3 x 3 neighbours that see its face: the indirect light is smooth
// within a face, its Monte Carlo noise is not (mc_samples paths a pixel). false: out of memory.
static bool indirect_smooth(rig_virtual_t *v)
{
    const int Wl = v->Wl, Hl = v->Hl;
    float *D = malloc((size_t)Wl * Hl * sizeof *D);
    if (!D) return false;
    for (size_t j = 0; j < (size_t)Wl * Hl; j++) D[j] = v->A_lr[j] - v->B_lr[j];
    for (int y = 0; y < Hl; y++)
        for (int x = 0; x < Wl; x++) {
            size_t j = (size_t)y * Wl + x;
            int32_t f = v->face_lr[j];
            double sum = 0;
            int n = 0;
            for (int yy = y - 1; yy <= y + 1; yy++)
                for (int xx = x - 1; xx <= x + 1; xx++) {
                    if (xx < 0 || yy < 0 || xx >= Wl || yy >= Hl) continue;
                    size_t k = (size_t)yy * Wl + xx;
                    if (v->face_lr[k] != f) continue;
                    sum += D[k];
                    n++;
                }
            v->A_lr[j] = (float)(sum / n);
            v->B_lr[j] = 0;
        }
    free(D);
    return true;
}

// The indirect term of the pixels marked in full, at full resolution: the
// shadings ind (MC, point lamps) and base (direct only) of those pixels, their
// difference added to L. false + message.
static bool indirect_full(rig_virtual_t *v, model_tracer_t *t, const model_lamps_t *one,
                          const model_material_t *const *mats, const model_shading_t *ind,
                          const model_shading_t *base, const uint8_t *full, float *L)
{
    size_t npx = (size_t)v->W * v->H;
    float *A = malloc(npx * sizeof *A), *B = malloc(npx * sizeof *B);
    model_shading_t si = *ind, sb = *base;
    si.pixel_mask = sb.pixel_mask = full;
    bool ok = A && B && model_render(t, v->cam, one, mats, &si, A, NULL, NULL) &&
              model_render(t, v->cam, one, mats, &sb, B, NULL, NULL);
    if (!A || !B) model_error(v->truth_path, 0, "out of memory for the indirect light near edges");
    for (size_t i = 0; ok && i < npx; i++)
        if (full[i]) L[i] += A[i] - B[i];
    free(A);
    free(B);
    return ok;
}

// Render the radiance image of lamp `lamp` alone into L (cache_lock held).

static bool render_layers(rig_virtual_t *v, model_tracer_t *t, int sample, int lamp,
                          const model_material_t *const *mats, float *L);

static bool render_lamp_rays(rig_virtual_t *v, tracer_slot_t *slot, int sample, int lamp, float *L);

// A lamp's radiance plane with the optics of [optics] (rig/virtual/optics.c).
static bool render_lamp_once(rig_virtual_t *v, tracer_slot_t *slot, int sample, int lamp, float *L);

static bool render_lamp(rig_virtual_t *v, tracer_slot_t *slot, int sample, int lamp, float *L)
{
    bool ok = v->optics.rays_per_pixel > 1 ? render_lamp_rays(v, slot, sample, lamp, L)
                                           : render_lamp_once(v, slot, sample, lamp, L);
    return ok && rig_optics_psf(&v->optics, v->W, v->H, L);
}

// rays_per_pixel N > 1: the same rendering by the camera of N times the
// resolution (a view of v with that camera, its own face ids, texture and
// roughness weights), its N x N blocks averaged.
static bool render_lamp_rays(rig_virtual_t *v, tracer_slot_t *slot, int sample, int lamp, float *L)
{
    const int N = v->optics.rays_per_pixel;
    rig_virtual_t *hv = malloc(sizeof *hv);
    if (!hv) {
        model_error(v->truth_path, 0, "out of memory for a rendering of %d x %d rays per pixel", N, N);
        return false;
    }
    *hv = *v;   // its locks are never used
    hv->cam = v->cam_hr;
    hv->W = v->W * N;
    hv->H = v->H * N;
    hv->face = v->face_hr;
    hv->ds = v->ds > 1 ? v->ds * N : 1;   // the same low-resolution indirect camera
    tracer_slot_t hs = *slot;
    hs.tex = NULL;
    hs.rough = NULL;
    bool ok = render_lamp_once(hv, &hs, sample, lamp, v->L_hr);
    free(hs.tex);
    free(hs.rough);
    free(hv);
    if (ok) rig_optics_average(N, v->W, v->H, v->L_hr, L);
    return ok;
}

static bool render_lamp_once(rig_virtual_t *v, tracer_slot_t *slot, int sample, int lamp, float *L)
{
    const sample_t *sm = &v->samples[sample];
    if (!render_layers(v, slot->t, sample, lamp, sm->rough ? sm->mats_smooth : sm->mats, L)) return false;
    if (!sm->textured) return true;
    if (!slot->tex && !make_texture(v, slot, v->face)) return false;
    if (sm->rough) {   // the rough population, blended in by the slot's weights
        float *Lr = malloc((size_t)v->W * v->H * sizeof *Lr);
        bool ok = Lr && render_layers(v, slot->t, sample, lamp, sm->mats_rough, Lr);
        if (ok) rig_vmat_blend(L, Lr, slot->rough, (size_t)v->W * v->H);
        else if (!Lr) model_error(v->truth_path, 0, "out of memory for a roughness layer");
        free(Lr);
        if (!ok) return false;
    }
    for (size_t i = 0; i < (size_t)v->W * v->H; i++) L[i] *= slot->tex[i];
    return true;
}

// The layers of a rendering (direct, indirect), untextured, and the face ids
// into v->face.
static bool render_layers(rig_virtual_t *v, model_tracer_t *t, int sample, int lamp,
                          const model_material_t *const *mats, float *L)
{
    model_lamps_t one = *v->lamps;
    one.n = 1;
    one.lamps = &v->lamps->lamps[lamp];
    model_shading_t sh = v->shading;
    sh.kc = 1;
    sh.Pa = 0;
    sh.gain_map = NULL;
    sh.seed = v->shading.seed + 0x9e3779b97f4a7c15ULL * (uint64_t)(lamp + 1);
    if (sh.interreflection != MODEL_INTERREFLECTION_MC || v->ds <= 1)
        return model_render(t, v->cam, &one, mats, &sh, L, v->face, NULL);
    model_shading_t direct = sh;
    direct.mc_bounces = 0;
    direct.mc_samples = v->samples[sample].direct_samples > 0 ? v->samples[sample].direct_samples : v->direct_samples;
    if (!model_render(t, v->cam, &one, mats, &direct, L, v->face, NULL)) return false;
    if (sh.mc_bounces == 0) return true;
    model_shading_t ind = sh, base = sh;
    ind.finite_lamps = false;   // then MC's direct term at the first hit is the point lamps' (exact)
    base.interreflection = MODEL_INTERREFLECTION_NONE;
    if (!model_render(t, v->cam_lr, &one, mats, &ind, v->A_lr, NULL, NULL) ||
        !model_render(t, v->cam_lr, &one, mats, &base, v->B_lr, v->face_lr, NULL))
        return false;
    uint8_t *full = malloc((size_t)v->W * v->H);
    if (!full || !indirect_smooth(v)) {
        free(full);
        model_error(v->truth_path, 0, "out of memory for the indirect light");
        return false;
    }
    ind_job_t J = { v, L, full };
    model_parallel_for(v->H, 16, model_default_threads(), indirect_rows, &J);
    bool ok = indirect_full(v, t, &one, mats, &ind, &base, full, L);
    free(full);
    return ok;
}

// The radiance image of one lamp; cache_lock held. NULL on error.
static const float *plane_for(rig_virtual_t *v, int sample, double angle_deg, int lamp)
{
    plane_t *lru = &v->planes[0];
    for (int i = 0; i < NPLANES; i++) {
        plane_t *p = &v->planes[i];
        if (p->L && p->sample == sample && p->lamp == lamp && p->angle_deg == angle_deg) {
            p->used = ++v->tick;
            return p->L;
        }
        if (!p->L || (lru->L && p->used < lru->used)) lru = p;
    }
    const sample_t *sm = &v->samples[sample];
    tracer_slot_t *slot = sm->uniform ? NULL : tracer_for(v, sample, angle_deg);
    if (!slot && !sm->uniform) return NULL;
    if (!lru->L) lru->L = malloc((size_t)v->W * v->H * sizeof(float));
    if (!lru->L) {
        model_error(v->truth_path, 0, "out of memory for a %dx%d rendering", v->W, v->H);
        return NULL;
    }
    if (sm->uniform) {
        for (size_t i = 0; i < (size_t)v->W * v->H; i++) lru->L[i] = (float)sm->radiance;
    } else if (!render_lamp(v, slot, sample, lamp, lru->L)) {
        free(lru->L);
        lru->L = NULL;
        return NULL;
    }
    lru->sample = sample;
    lru->lamp = lamp;
    lru->angle_deg = angle_deg;
    lru->used = ++v->tick;
    return lru->L;
}

static int format_bits(const char *pf)
{
    rig_pixfmt_t f;
    return pf && rig_pixfmt_from_name(pf, &f) ? rig_pixfmt_bits(f) : 0;
}

// The ideal grey value P of the whole sensor into v->frame and the sensor of
// that frame; cache_lock held.
static int ideal_frame(rig_virtual_t *v, int sample, double angle_deg, uint32_t mask, double exposure_us,
                       double gain_db, int64_t trigger_ns, model_sensor_t *s_out, float *out)
{
    size_t n = (size_t)v->W * v->H;
    // The virtual sensor's own physics: its camera's Gain is in dB (GenICam
    // <Unit>dB</Unit>, rig/virtual/gv_camera.c), so this is not a recorded gain's
    // conversion (that is model_gain_factor, by the frame's unit).
    double gf = pow(10.0, gain_db / 20.0);
    double kc = v->kc_per_us * exposure_us * gf;
    const double Pa = v->sensor.dark_offset_dn;
    bool first = true;
    double lf[32];   // each lamp's warm-up and drift at the trigger (exactly 1 without them)
    const float *pl[32];
    int np = 0;
    rig_vlamps_factors(&v->lamp_fx, v->state->lamps_dev, trigger_ns, lf);
    for (int l = 0; l < v->lamps->n && l < 32; l++) {
        if (!((mask >> l) & 1)) continue;
        const float *L = plane_for(v, sample, angle_deg, l);
        if (!L) return rig_fail(RIG_ERR_IO, "virtual rig: rendering %s at %.4f deg with lamp %s failed: %s",
                                v->samples[sample].name, angle_deg, v->lamps->lamps[l].name, model_last_error());
        double kl = kc * lf[l];
        lf[np] = lf[l];
        pl[np++] = L;
        // the same float arithmetic as Pa first, then each lamp added in turn
        if (first)
            for (size_t i = 0; i < n; i++) out[i] = (float)Pa + (float)(kl * L[i]);
        else
            for (size_t i = 0; i < n; i++) out[i] += (float)(kl * L[i]);
        first = false;
    }
    if (first)
        for (size_t i = 0; i < n; i++) out[i] = (float)Pa;
    // room light does not reach a lens covered by a flat-field source (a
    // uniform_source sample): only the lens's own veiling glare is left
    rig_vlamps_t stray = v->lamp_fx;
    if (v->samples[sample].uniform) stray.ambient_radiance = 0;
    rig_vlamps_add_stray(&stray, out, n, kc, pl, lf, np);
    *s_out = v->sensor;
    s_out->system_gain_dn_per_e *= gf;
    s_out->exposure_us = exposure_us;
    return 0;
}

// Value of a `bits`-bit sample in pixel format fb.
static double to_format(double x, int bits, int fb, bool mean)
{
    if (fb >= bits) return ldexp(x, fb - bits);
    int s = bits - fb;
    if (!mean) return floor(ldexp(x, -s));
    return ldexp(x, -s) - ldexp((double)((1 << s) - 1), -(s + 1));
}

// Is the plane cached? (cache_lock held)
static bool plane_cached(const rig_virtual_t *v, int sample, double angle_deg, int lamp)
{
    for (int i = 0; i < NPLANES; i++) {
        const plane_t *p = &v->planes[i];
        if (p->L && p->sample == sample && p->lamp == lamp && p->angle_deg == angle_deg) return true;
    }
    return false;
}

// The noisy sensor values of a frame into out (cache_lock held).
static int noisy_frame(rig_virtual_t *v, int sample, double angle_deg, uint32_t mask, double exposure_us,
                       double gain_db, uint64_t seed, int64_t trigger_ns, float *out)
{
    model_sensor_t s;
    int r = ideal_frame(v, sample, angle_deg, mask, exposure_us, gain_db, trigger_ns, &s, out);
    if (r) return r;
    s.noise_seed = seed;
    model_sensor_apply_patterns(&s, v->W, v->H, v->prnu, v->dsnu, out);
    return 0;
}

static bool spec_is(const spec_t *p, int sample, double angle_deg, uint32_t mask, double exposure_us,
                    double gain_db, uint64_t seed)
{
    return p->valid && p->seed == seed && p->sample == sample && p->angle_deg == angle_deg && p->mask == mask &&
           p->exposure_us == exposure_us && p->gain_db == gain_db;
}

// Compute one missing speculative frame of the state (the next frames'
// exposures predicted from the last state's); cache_lock held. true when one
// was computed.
static bool speculate_one(rig_virtual_t *v, int sample, double angle_deg, uint32_t mask, uint64_t next_seed)
{
    if (v->lamp_fx.timed) return false;   // lamps that drift: a frame is that of its trigger's time
    const shot_t *seq = v->cur;   // a state without frames yet: as the last one
    int nseq = v->ncur, pos = 0;
    if (v->cur_key_set && v->cur_key_sample == sample && v->cur_key_angle == angle_deg && v->cur_key_mask == mask) {
        seq = v->prev;            // frames taken in this state: continue as the previous state
        nseq = v->nprev;
        pos = v->ncur;
    }
    // Once this state has frames, go on only with a short sequence (a
    // bracket): a long one is a stream of frames that may stop at any time.
    if (pos > 0 && nseq > NSPEC) return false;
    for (int j = pos; j < nseq && j < pos + NSPEC; j++) {
        const shot_t *sh = &seq[j];
        uint64_t seed = next_seed + (uint64_t)(j - pos);
        spec_t *free_slot = NULL;
        bool have = false;
        for (int k = 0; k < NSPEC; k++) {
            spec_t *p = &v->spec[k];
            if (spec_is(p, sample, angle_deg, mask, sh->exposure_us, sh->gain_db, seed)) have = true;
            else if (!free_slot && (!p->valid || p->seed < next_seed || p->sample != sample ||
                                    p->angle_deg != angle_deg || p->mask != mask))
                free_slot = p;
        }
        if (have) continue;
        if (!free_slot) return false;
        if (!free_slot->img) free_slot->img = malloc((size_t)v->W * v->H * sizeof(float));
        if (!free_slot->img) return false;
        free_slot->valid = false;
        bool q = model_error_quiet_thread(true);   // errors show at the trigger
        int r = noisy_frame(v, sample, angle_deg, mask, sh->exposure_us, sh->gain_db, seed, 0, free_slot->img);
        model_error_quiet_thread(q);
        if (r) {   // no more speculation until the next frame (which reports the error)
            v->ncur = v->nprev = 0;
            return false;
        }
        *free_slot = (spec_t){ free_slot->img, true, sample, angle_deg, mask, sh->exposure_us, sh->gain_db, seed };
        return true;
    }
    return false;
}

static bool ashot_eq(const ashot_t *a, const ashot_t *b)
{
    return a->mask == b->mask && a->exposure_us == b->exposure_us && a->gain_db == b->gain_db;
}

// The first n frames of a and b alike (na, nb: their lengths; n <= both).
static bool aseq_prefix(const ashot_t *a, int na, const ashot_t *b, int nb, int n)
{
    if (na > NASEQ || nb > NASEQ || n > na || n > nb) return false;
    for (int i = 0; i < n; i++)
        if (!ashot_eq(&a[i], &b[i])) return false;
    return true;
}

// The frames predicted at (sample, angle) from the angle sequences, next
// first: at most NSPEC of them, with the seeds they will draw from next_seed
// on; 0 when there is no prediction (cache_lock held).
static int predict_angle(const rig_virtual_t *v, int sample, double angle_deg, ashot_t *out)
{
    if (!v->akey_set || v->akey_sample != sample || v->nacur > NASEQ) return 0;
    const ashot_t *seq = v->acur;   // a new angle: as the last one, if it repeated the one before
    int n = v->nacur, pos = 0;
    if (v->akey_angle == angle_deg) {   // frames at this angle: go on as the previous angle if they follow it
        if (v->naprev != v->naprev2 || !aseq_prefix(v->aprev, v->naprev, v->aprev2, v->naprev2, v->naprev) ||
            !aseq_prefix(v->acur, v->nacur, v->aprev, v->naprev, v->nacur))
            return 0;
        seq = v->aprev;
        n = v->naprev;
        pos = v->nacur;
    } else if (v->nacur != v->naprev || !aseq_prefix(v->acur, v->nacur, v->aprev, v->naprev, v->nacur)) {
        return 0;
    }
    int k = 0;
    for (int j = pos; j < n && k < NSPEC; j++) out[k++] = seq[j];
    return k;
}

// Compute one missing frame of the angle's prediction (cache_lock held):
// 1 computed, 0 all there (or no room), -1 no prediction.
static int speculate_angle(rig_virtual_t *v, int sample, double angle_deg, uint64_t next_seed)
{
    if (v->lamp_fx.timed) return -1;   // lamps that drift: a frame is that of its trigger's time
    ashot_t pred[NSPEC];
    int np = predict_angle(v, sample, angle_deg, pred);
    if (np == 0) return -1;
    for (int j = 0; j < np; j++) {
        uint64_t seed = next_seed + (uint64_t)j;
        bool have = false;
        spec_t *free_slot = NULL;
        for (int k = 0; k < NSPEC && !have; k++) {
            spec_t *p = &v->spec[k];
            if (spec_is(p, sample, angle_deg, pred[j].mask, pred[j].exposure_us, pred[j].gain_db, seed)) {
                have = true;
                break;
            }
            // free: invalid, used up, elsewhere, or a frame this prediction does not have
            bool wanted = false;
            if (p->valid && p->seed >= next_seed && p->seed < next_seed + (uint64_t)np && p->sample == sample &&
                p->angle_deg == angle_deg) {
                const ashot_t *q = &pred[p->seed - next_seed];
                wanted = p->mask == q->mask && p->exposure_us == q->exposure_us && p->gain_db == q->gain_db;
            }
            if (!wanted && !free_slot) free_slot = p;
        }
        if (have) continue;
        if (!free_slot) return 0;
        if (!free_slot->img) free_slot->img = malloc((size_t)v->W * v->H * sizeof(float));
        if (!free_slot->img) return 0;
        free_slot->valid = false;
        bool q = model_error_quiet_thread(true);   // errors show at the trigger
        int r = noisy_frame(v, sample, angle_deg, pred[j].mask, pred[j].exposure_us, pred[j].gain_db, seed, 0,
                            free_slot->img);
        model_error_quiet_thread(q);
        if (r) {   // no more speculation until the next frame (which reports the error)
            v->nacur = v->naprev = v->naprev2 = NASEQ + 1;
            return 0;
        }
        *free_slot = (spec_t){ free_slot->img, true, sample, angle_deg, pred[j].mask, pred[j].exposure_us,
                               pred[j].gain_db, seed };
        return 1;
    }
    return 0;
}

static void *prerender_main(void *arg)
{
    rig_virtual_t *v = arg;
    while (!__atomic_load_n(&v->pre_stop, __ATOMIC_ACQUIRE)) {
        rig_turntable_status_t st;
        pthread_mutex_lock(&v->state_lock);
        int r = v->stage_gone ? RIG_ERR_DISCONNECTED : rig_turntable_status(v->tt_sim, &st);
        if (r) v->stage_gone = true;
        double dest = NAN;
        bool to_dest = !r && st.moving && st.homed && rig_turntable_sim_destination(v->tt_sim, &dest);
        int sample = v->cur_sample;
        uint64_t next_seed = v->next_seed;
        pthread_mutex_unlock(&v->state_lock);
        uint32_t mask = __atomic_load_n(&v->lamps_dev->on_mask, __ATOMIC_ACQUIRE);
        int todo = -1;
        bool specd = false;
        if (to_dest && !__atomic_load_n(&v->waiting, __ATOMIC_ACQUIRE)) {
            // the frames of the angle the stage is moving to
            pthread_mutex_lock(&v->cache_lock);
            specd = speculate_angle(v, sample, dest, next_seed) == 1;
            pthread_mutex_unlock(&v->cache_lock);
        }
        if (!r && !st.moving && st.homed) {
            pthread_mutex_lock(&v->cache_lock);
            // lamps that are on first; the others only while no frame waits
            for (int pass = 0; pass < 2 && todo < 0 && !specd; pass++) {
                // between the passes: the next frames of this state
                if (pass == 1 && !__atomic_load_n(&v->waiting, __ATOMIC_ACQUIRE)) {
                    int a = speculate_angle(v, sample, st.angle_deg, next_seed);
                    specd = a == 1 || (a < 0 && speculate_one(v, sample, st.angle_deg, mask, next_seed));
                }
                if (specd) break;
                for (int l = 0; l < v->lamps->n && todo < 0; l++) {
                    bool on = (mask >> l) & 1;
                    if (on != (pass == 0)) continue;
                    if (pass == 1 && (v->prerender < 2 || __atomic_load_n(&v->waiting, __ATOMIC_ACQUIRE) ||
                                      v->lamps->n > NPLANES / 2))
                        continue;
                    if (!plane_cached(v, sample, st.angle_deg, l)) todo = l;
                }
            }
            if (todo >= 0) plane_for(v, sample, st.angle_deg, todo);   // errors show at the trigger
            pthread_mutex_unlock(&v->cache_lock);
        }
        if (todo < 0 && !specd) sleep_s(2e-3);
    }
    return NULL;
}

static int render_cb(void *ctx, const rig_frame_meta_t *m, uint16_t *pix)
{
    rig_virtual_t *v = ctx, *sv = v->state;
    // the exposure starts now: the lamps' warm-up is theirs at this time,
    // however long the frame waits for the renderer
    struct timespec tnow;
    clock_gettime(CLOCK_MONOTONIC, &tnow);
    int64_t trigger_ns = (int64_t)tnow.tv_sec * 1000000000 + tnow.tv_nsec;
    rig_turntable_status_t st;
    pthread_mutex_lock(&sv->state_lock);
    // A stage that disconnected leaves the sample where it was: the camera
    // keeps seeing it at the last known angle.
    if (!sv->stage_gone) {
        if (rig_turntable_status(sv->tt_sim, &st) == 0) sv->last_angle_deg = st.angle_deg;
        else sv->stage_gone = true;
    }
    st.angle_deg = sv->last_angle_deg;
    pthread_mutex_unlock(&sv->state_lock);
    pthread_mutex_lock(&v->state_lock);
    int sample = v->cur_sample;
    uint64_t seed = v->next_seed++;
    pthread_mutex_unlock(&v->state_lock);
    uint32_t mask = __atomic_load_n(&sv->lamps_dev->on_mask, __ATOMIC_ACQUIRE);
    int fb = format_bits(m->pixel_format);
    if (!fb || m->offset_x + m->width > v->W || m->offset_y + m->height > v->H)
        return rig_fail(RIG_ERR_INVALID, "virtual rig: frame %s %dx%d at (%d,%d) does not fit the %dx%d sensor",
                        m->pixel_format, m->width, m->height, m->offset_x, m->offset_y, v->W, v->H);
    __atomic_add_fetch(&v->waiting, 1, __ATOMIC_ACQ_REL);
    pthread_mutex_lock(&v->cache_lock);
    __atomic_sub_fetch(&v->waiting, 1, __ATOMIC_ACQ_REL);
    // The exposures of this state so far (the prediction of speculate_one).
    if (!(v->cur_key_set && v->cur_key_sample == sample && v->cur_key_angle == st.angle_deg &&
          v->cur_key_mask == mask)) {
        if (v->ncur > 0) {
            memcpy(v->prev, v->cur, sizeof v->cur);
            v->nprev = v->ncur;
        }
        v->ncur = 0;
        v->cur_key_set = true;
        v->cur_key_sample = sample;
        v->cur_key_angle = st.angle_deg;
        v->cur_key_mask = mask;
    }
    if (v->ncur < NSEQ) v->cur[v->ncur++] = (shot_t){ m->exposure_us, m->gain };
    // ... and of this angle
    if (!(v->akey_set && v->akey_sample == sample && v->akey_angle == st.angle_deg)) {
        memcpy(v->aprev2, v->aprev, sizeof v->aprev);
        v->naprev2 = v->naprev;
        memcpy(v->aprev, v->acur, sizeof v->acur);
        v->naprev = v->nacur;
        v->nacur = 0;
        if (!v->akey_set || v->akey_sample != sample) v->naprev = v->naprev2 = NASEQ + 1;   // another sample
        v->akey_set = true;
        v->akey_sample = sample;
        v->akey_angle = st.angle_deg;
    }
    if (v->nacur < NASEQ) v->acur[v->nacur++] = (ashot_t){ mask, m->exposure_us, m->gain };
    else v->nacur = NASEQ + 1;
    // A frame computed ahead for exactly these inputs, or compute it now.
    const float *img = NULL;
    int r = 0;
    for (int k = 0; k < NSPEC; k++) {
        spec_t *p = &v->spec[k];
        if (spec_is(p, sample, st.angle_deg, mask, m->exposure_us, m->gain, seed)) img = p->img;
        if (p->seed < seed) p->valid = false;   // its seed is used up
    }
    if (img) v->frames_ahead++;
    if (!img) {
        r = noisy_frame(v, sample, st.angle_deg, mask, m->exposure_us, m->gain, seed, trigger_ns, v->frame);
        img = v->frame;
    }
    for (int k = 0; k < NSPEC; k++)
        if (v->spec[k].seed == seed) v->spec[k].valid = false;   // taken (its buffer is read below, under cache_lock)
    if (!r) {
        // The sensor's values are integers in [0, 2^bits - 1]: shift them.
        const int bits = v->sensor.bits;
        int up = fb >= bits ? fb - bits : 0, down = fb < bits ? bits - fb : 0;
        for (int y = 0; y < m->height; y++) {
            const float *row = img + (size_t)(y + m->offset_y) * v->W + m->offset_x;
            uint16_t *o = pix + (size_t)y * m->width;
            for (int x = 0; x < m->width; x++) o[x] = (uint16_t)((((uint32_t)row[x]) >> down) << up);
        }
    }
    pthread_mutex_unlock(&v->cache_lock);
    return r;
}

int rig_virtual_expected(rig_virtual_t *v, double angle_deg, uint32_t lamp_mask, double exposure_us,
                         double gain_db, const char *pixel_format, int width, int height, float *out)
{
    if (!v || !out) return rig_fail(RIG_ERR_INVALID, "virtual rig: expected frame: NULL argument");
    int fb = format_bits(pixel_format);
    if (!fb)
        return rig_fail(RIG_ERR_INVALID, "virtual rig: pixel format '%s' is not Mono8, Mono12 or Mono16 (nor "
                        "Mono10, Mono10p, Mono12p, Mono10Packed, Mono12Packed)",
                        pixel_format ? pixel_format : "(null)");
    if (width < 1 || height < 1 || width > v->W || height > v->H)
        return rig_fail(RIG_ERR_INVALID, "virtual rig: expected frame %dx%d does not fit the %dx%d sensor "
                        "(the region starts at the top-left pixel)", width, height, v->W, v->H);
    if (!(isfinite(angle_deg) && fabs(angle_deg) <= 1e4))
        return rig_fail(RIG_ERR_INVALID, "virtual rig: angle %g deg is not within +-10000 deg", angle_deg);
    if (!(isfinite(exposure_us) && exposure_us > 0) || !(isfinite(gain_db) && gain_db >= 0))
        return rig_fail(RIG_ERR_INVALID, "virtual rig: exposure %g us must be > 0 and gain %g dB >= 0",
                        exposure_us, gain_db);
    if (v->lamps->n < 32 && (lamp_mask >> v->lamps->n))
        return rig_fail(RIG_ERR_INVALID, "virtual rig: lamp mask 0x%x names lamps beyond the %d of the truth file",
                        lamp_mask, v->lamps->n);
    pthread_mutex_lock(&v->state_lock);
    int sample = v->cur_sample;
    pthread_mutex_unlock(&v->state_lock);
    pthread_mutex_lock(&v->cache_lock);
    model_sensor_t s;
    int r = ideal_frame(v, sample, angle_deg, lamp_mask, exposure_us, gain_db, 0, &s, v->frame);
    if (!r) {
        model_sensor_mean(&s, v->W, v->H, v->prnu, v->dsnu, v->frame);
        for (int y = 0; y < height; y++)
            for (int x = 0; x < width; x++)
                out[(size_t)y * width + x] = (float)to_format(v->frame[(size_t)y * v->W + x], s.bits, fb, true);
    }
    pthread_mutex_unlock(&v->cache_lock);
    return r;
}

int rig_virtual_radiance(rig_virtual_t *v, double angle_deg, int lamp, float *out)
{
    if (!v || !out) return rig_fail(RIG_ERR_INVALID, "virtual rig: radiance: NULL argument");
    if (lamp < 0 || lamp >= v->lamps->n)
        return rig_fail(RIG_ERR_INVALID, "virtual rig: lamp %d is not one of the %d of the truth file", lamp,
                        v->lamps->n);
    if (!(isfinite(angle_deg) && fabs(angle_deg) <= 1e4))
        return rig_fail(RIG_ERR_INVALID, "virtual rig: angle %g deg is not within +-10000 deg", angle_deg);
    pthread_mutex_lock(&v->state_lock);
    int sample = v->cur_sample;
    pthread_mutex_unlock(&v->state_lock);
    pthread_mutex_lock(&v->cache_lock);
    const float *L = plane_for(v, sample, angle_deg, lamp);
    if (L) memcpy(out, L, (size_t)v->W * v->H * sizeof(float));
    pthread_mutex_unlock(&v->cache_lock);
    if (!L)
        return rig_fail(RIG_ERR_IO, "virtual rig: rendering %s at %.4f deg with lamp %s failed: %s",
                        v->samples[sample].name, angle_deg, v->lamps->lamps[lamp].name, model_last_error());
    return 0;
}

int rig_virtual_sensor_apply(rig_virtual_t *v, double exposure_us, double gain_db, uint64_t seed, float *img)
{
    if (!v || !img) return rig_fail(RIG_ERR_INVALID, "virtual rig: sensor: NULL argument");
    if (!(isfinite(exposure_us) && exposure_us > 0) || !(isfinite(gain_db) && gain_db >= 0))
        return rig_fail(RIG_ERR_INVALID, "virtual rig: exposure %g us must be > 0 and gain %g dB >= 0", exposure_us,
                        gain_db);
    model_sensor_t s = v->sensor;
    s.system_gain_dn_per_e *= pow(10.0, gain_db / 20.0);   // the sensor's physics: its Gain is in dB (see ideal_frame)
    s.exposure_us = exposure_us;
    s.noise_seed = seed;
    model_sensor_apply_patterns(&s, v->W, v->H, v->prnu, v->dsnu, img);
    return 0;
}

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
// The truth file

typedef struct {
    const char *section;   // section kind ("lamp" for "[lamp NAME]")
    const char *keys[16];
} allowed_t;

static const allowed_t allowed[] = {
    { "virtual", { "sample", "lamp_warmup_ms", "lamp_settle_ms" } },
    { "camera", { "model", "model_sha256", "kc_per_us", "serial", "vendor", "model_name", "temperature_c" } },
    { "render", { "interreflection", "mc_samples", "mc_bounces", "thesis_samples", "thesis_cone_deg", "rho_sr",
                  "finite_lamps", "seed", "direct_samples", "indirect_downsample", "prerender" } },
    { "turntable", { "speed_deg_s", "accel_deg_s2", "home_time_s", "position_noise_deg", "seed",
                     "fault_after_moves", "fault",
                     "axis_tilt_deg", "axis_tilt_azimuth_deg", "wobble_deg" } },
    { "placement", { "position_sigma_mm", "angle_sigma_deg", "seed" } },
    { "sample", { "kind", "scene", "square_mm", "corners", "corner0_mm", "material", "sphere_centre_mm",
                  "sphere_radius_mm", "radiance", "direct_samples",
                  "flex_mm" } },
    { "texture", { "amplitude", "scale_mm", "seed",
                   "roughness_amplitude" } },
    { "optics", { "rays_per_pixel", "psf", "psf_sigma_px", "psf_radius_px" } },
    { "sensor", { NULL } },     // checked by model_sensor_from_ini
    { "lamp", { NULL } },       // model_lamps_from_ini
    { "lamp_drift", { "warmup_fraction", "warmup_tau_s", "drift_pct_per_h" } },   // rig/virtual/lamps.c
    { "stray", { "ambient_radiance", "veiling_glare" } },                        // rig/virtual/lamps.c
    { "material", { NULL } },   // model_materials_from_ini
};

static void section_kind(const char *sec, char kind[32], const char **name)
{
    const char *sp = strchr(sec, ' ');
    size_t n = sp ? (size_t)(sp - sec) : strlen(sec);
    if (n > 31) n = 31;
    memcpy(kind, sec, n);
    kind[n] = 0;
    *name = sp ? sp + 1 : "";
}

static const allowed_t *find_allowed(const char *kind)
{
    for (size_t i = 0; i < sizeof allowed / sizeof allowed[0]; i++)
        if (!strcmp(allowed[i].section, kind)) return &allowed[i];
    return NULL;
}

static bool check_sections(const model_ini_t *ini)
{
    for (int s = 0; s < ini->nsections; s++) {
        char kind[32];
        const char *name;
        section_kind(ini->sections[s], kind, &name);
        const allowed_t *a = find_allowed(kind);
        bool named = !strcmp(kind, "lamp") || !strcmp(kind, "material") || !strcmp(kind, "sample") ||
                     !strcmp(kind, "texture") ||
                     !strcmp(kind, "lamp_drift");
        bool may_name = !strcmp(kind, "camera") || !strcmp(kind, "sensor");
        if (!a) {
            model_error(ini->path, ini->section_lines[s], "unknown section [%s]; a truth file has [virtual], "
                        "[camera] (or [camera NAME], one or more), [render], [sensor] (and [sensor NAME]), "
                        "[turntable], [placement], [lamp NAME], [material NAME], [texture MATERIAL], [sample NAME] "
                        "and [optics] (and [lamp_drift LAMP], [stray])", ini->sections[s]);
            return false;
        }
        if (!strcmp(kind, "sensor") && *name) {
            char cs[80];
            snprintf(cs, sizeof cs, "camera %s", name);
            if (model_ini_section_line(ini, cs) <= 0) {
                model_error(ini->path, ini->section_lines[s], "[%s] has no [camera %s]: a [sensor NAME] is the "
                            "sensor of the camera [camera NAME] (its keys over those of [sensor])", ini->sections[s],
                            name);
                return false;
            }
        }
        if (!may_name && named != (*name != 0)) {
            model_error(ini->path, ini->section_lines[s], named ? "[%s] needs a name: write [%s NAME]"
                        : "[%s] takes no name: write [%s]", ini->sections[s], kind);
            return false;
        }
    }
    for (int k = 0; k < ini->nentries; k++) {
        const model_ini_entry_t *e = &ini->entries[k];
        char kind[32];
        const char *name;
        section_kind(e->section, kind, &name);
        const allowed_t *a = find_allowed(kind);
        if (!a->keys[0]) continue;
        bool ok = false;
        char list[512] = "";
        size_t len = 0;
        for (int i = 0; i < 16 && a->keys[i]; i++) {
            if (!strcmp(a->keys[i], e->key)) ok = true;
            len += snprintf(list + len, sizeof list - len, "%s%s", i ? ", " : "", a->keys[i]);
            if (len >= sizeof list) len = sizeof list - 1;
        }
        if (!ok) {
            model_error(ini->path, e->line, "unknown key '%s' in [%s]; valid keys: %s", e->key, e->section, list);
            return false;
        }
    }
    return true;
}

static int ini_line(const model_ini_t *ini, const char *sec, const char *key)
{
    const model_ini_entry_t *e = model_ini_get(ini, sec, key);
    return e ? e->line : model_ini_section_line(ini, sec);
}

// Typed values of the truth file (model/base/ini.c reports them with file:line).
static bool get_double(const model_ini_t *ini, const char *sec, const char *key, double lo, double hi,
                       bool required, double *out)
{
    return model_ini_double_in(ini, sec, key, out, required, lo, false, hi, NULL);
}

static bool get_int(const model_ini_t *ini, const char *sec, const char *key, long lo, long hi, long *out)
{
    return model_ini_int(ini, sec, key, out, false, lo, hi);
}

static const char *get_str(const model_ini_t *ini, const char *sec, const char *key, const char *def)
{
    return model_ini_text(ini, sec, key, def);
}

// A path relative to the truth file's directory (malloc'ed).
static char *rel_path(const char *truth, const char *p)
{
    char *out = NULL;
    if (p[0] == '/') return strdup(p);
    const char *slash = strrchr(truth, '/');
    int dir = slash ? (int)(slash - truth) : 0;
    if (asprintf(&out, "%.*s%s%s", dir, truth, slash ? "/" : "", p) < 0) return NULL;
    return out;
}

// A sample's rough and smooth material variants (rig/virtual/materials.c).
static bool sample_roughness(rig_virtual_t *v, const model_ini_t *ini, sample_t *sm)
{
    int n = sm->scene->nmaterials;
    double *amp = calloc(n ? n : 1, sizeof *amp);
    sm->mats_rough = calloc(n ? n : 1, sizeof *sm->mats_rough);
    sm->mats_smooth = calloc(n ? n : 1, sizeof *sm->mats_smooth);
    if (!amp || !sm->mats_rough || !sm->mats_smooth) {
        free(amp);
        return false;
    }
    int line = sm->line;
    for (int k = 0; k < n; k++)
        if (sm->tex[k] && sm->tex[k]->roughness_amplitude > 0) {
            amp[k] = sm->tex[k]->roughness_amplitude;
            char sec[96];
            snprintf(sec, sizeof sec, "texture %s", sm->tex[k]->material);
            line = ini_line(ini, sec, "roughness_amplitude");
        }
    bool ok = rig_vmat_variants(n, sm->mats, amp, ini->path, line, &sm->rough_store, sm->mats_rough, sm->mats_smooth);
    free(amp);
    return ok;
}

static bool parse_textures(rig_virtual_t *v, const model_ini_t *ini)
{
    int n = 0;
    for (int s = 0; s < ini->nsections; s++)
        if (!strncmp(ini->sections[s], "texture ", 8)) n++;
    if (n == 0) return true;
    v->textures = calloc(n, sizeof *v->textures);
    if (!v->textures) return false;
    for (int s = 0; s < ini->nsections; s++) {
        const char *sec = ini->sections[s];
        if (strncmp(sec, "texture ", 8)) continue;
        texture_t *tx = &v->textures[v->ntextures++];
        const char *mat = sec + 8;
        if (!model_materials_find(v->mats, mat)) {
            model_error(ini->path, ini->section_lines[s], "[texture %s]: there is no [material %s]; a texture "
                        "section is named after the material it textures", mat, mat);
            return false;
        }
        snprintf(tx->material, sizeof tx->material, "%s", mat);
        tx->amplitude = NAN;
        tx->scale_mm = NAN;
        if (!get_double(ini, sec, "amplitude", 0, 0.5, true, &tx->amplitude) ||
            !get_double(ini, sec, "scale_mm", 1e-3, 1e6, true, &tx->scale_mm))
            return false;
        long seed = 1;
        if (!get_int(ini, sec, "seed", 0, LONG_MAX, &seed)) return false;
        tx->seed = (uint64_t)seed;
        if (!get_double(ini, sec, "roughness_amplitude", 0, 0.9, false, &tx->roughness_amplitude)) return false;
    }
    return true;
}

static const char *sample_kinds[] = { "workpiece", "chessboard", "reference_white", "material_coupon",
                                      "mirror_sphere", "uniform_source" };

// A mirror sphere's facts (sphere_centre_mm, sphere_radius_mm): required for
// that kind, refused for the others, and one of the scene's spheres must have
// them (to 1e-6 mm).
static bool check_sphere_facts(const model_ini_t *ini, const char *sec, const sample_t *sm)
{
    bool mirror = !strcmp(sm->kind, "mirror_sphere");
    static const char *keys[] = { "sphere_centre_mm", "sphere_radius_mm" };
    for (int k = 0; k < 2; k++)
        if (!mirror && model_ini_get(ini, sec, keys[k])) {
            model_error(ini->path, ini_line(ini, sec, keys[k]), "sample '%s': %s is a key of mirror spheres, "
                        "not of kind %s", sm->name, keys[k], sm->kind);
            return false;
        }
    if (!mirror) return true;
    double r;
    if (!get_double(ini, sec, "sphere_radius_mm", 1e-3, 1e4, true, &r)) return false;
    const char *cs = get_str(ini, sec, "sphere_centre_mm", NULL);
    double c[3];
    char extra;
    if (!cs || sscanf(cs, "%lf %lf %lf %c", &c[0], &c[1], &c[2], &extra) != 3 || !isfinite(c[0]) ||
        !isfinite(c[1]) || !isfinite(c[2])) {
        model_error(ini->path, ini_line(ini, sec, "sphere_centre_mm"), "sample '%s': sphere_centre_mm = '%s': give "
                    "the sphere's centre at angle 0 as three numbers x y z (mm, rig frame)", sm->name, cs ? cs : "");
        return false;
    }
    for (int k = 0; k < sm->scene->nspheres; k++) {
        const model_sphere_t *sp = &sm->scene->spheres[k];
        if (fabs(sp->centre_mm.x - c[0]) <= 1e-6 && fabs(sp->centre_mm.y - c[1]) <= 1e-6 &&
            fabs(sp->centre_mm.z - c[2]) <= 1e-6 && fabs(sp->radius_mm - r) <= 1e-6)
            return true;
    }
    model_error(ini->path, ini_line(ini, sec, "sphere_centre_mm"), "sample '%s': its scene %s has no sphere of "
                "centre (%g, %g, %g) mm and radius %g mm (it has %d '@sphere' line%s); make the facts and the "
                "scene agree", sm->name, sm->scene_path, c[0], c[1], c[2], r, sm->scene->nspheres,
                sm->scene->nspheres == 1 ? "" : "s");
    return false;
}

static bool parse_samples(rig_virtual_t *v, const model_ini_t *ini)
{
    int n = 0;
    for (int s = 0; s < ini->nsections; s++)
        if (!strncmp(ini->sections[s], "sample ", 7)) n++;
    if (n == 0) {
        model_error(ini->path, 0, "no [sample NAME] sections; add at least one (the workpiece on the table)");
        return false;
    }
    v->samples = calloc((size_t)n + MAX_POSES, sizeof *v->samples);
    if (!v->samples) return false;
    for (int s = 0; s < ini->nsections; s++) {
        const char *sec = ini->sections[s];
        if (strncmp(sec, "sample ", 7)) continue;
        sample_t *sm = &v->samples[v->nsamples++];
        sm->line = ini->section_lines[s];
        if (strlen(sec + 7) >= sizeof sm->name) {
            model_error(ini->path, sm->line, "sample name '%s' is too long (limit %zu)", sec + 7, sizeof sm->name - 1);
            return false;
        }
        strcpy(sm->name, sec + 7);
        const char *kind = get_str(ini, sec, "kind", NULL), *scene = get_str(ini, sec, "scene", NULL);
        sm->R[0] = sm->R[4] = sm->R[8] = 1;
        if (kind && !strcmp(kind, "uniform_source")) {
            // a flat-field source filling the view (an integrating sphere's port
            // in front of the lens), fed by the rig's lamps: no scene
            if (scene) {
                model_error(ini->path, ini_line(ini, sec, "scene"), "sample '%s': a uniform_source has no scene; "
                            "remove 'scene' (give 'radiance' only)", sm->name);
                return false;
            }
            static const char *other[] = { "square_mm", "corners", "corner0_mm", "material", "sphere_centre_mm",
                                           "sphere_radius_mm" };
            for (size_t k = 0; k < sizeof other / sizeof other[0]; k++)
                if (model_ini_get(ini, sec, other[k])) {
                    model_error(ini->path, ini_line(ini, sec, other[k]), "sample '%s': %s is not a key of "
                                "uniform_source samples (only kind and radiance)", sm->name, other[k]);
                    return false;
                }
            snprintf(sm->kind, sizeof sm->kind, "%s", kind);
            sm->uniform = true;
            if (!get_double(ini, sec, "radiance", 0, 1e12, true, &sm->radiance)) return false;
            sm->mats = calloc(1, sizeof *sm->mats);
            sm->tex = calloc(1, sizeof *sm->tex);
            if (!sm->mats || !sm->tex) return false;
            continue;
        }
        if (model_ini_get(ini, sec, "direct_samples")) {
            long ds;
            if (!get_int(ini, sec, "direct_samples", 1, 4096, &ds)) return false;
            sm->direct_samples = (int)ds;
        }
        if (model_ini_get(ini, sec, "radiance")) {
            model_error(ini->path, ini_line(ini, sec, "radiance"), "sample '%s': radiance is a key of "
                        "uniform_source samples only", sm->name);
            return false;
        }
        if (!kind || !scene) {
            model_error(ini->path, sm->line, "sample '%s' lacks '%s'; each sample needs kind and scene", sm->name,
                        kind ? "scene" : "kind");
            return false;
        }
        bool known = false;
        for (size_t k = 0; k < sizeof sample_kinds / sizeof sample_kinds[0]; k++)
            if (!strcmp(kind, sample_kinds[k])) known = true;
        if (!known) {
            model_error(ini->path, ini_line(ini, sec, "kind"), "sample '%s': kind = '%s' is unknown; use workpiece, "
                        "chessboard, reference_white, material_coupon, mirror_sphere or uniform_source", sm->name, kind);
            return false;
        }
        snprintf(sm->kind, sizeof sm->kind, "%s", kind);
        bool chess = !strcmp(kind, "chessboard"), coupon = !strcmp(kind, "material_coupon") ||
                                                          !strcmp(kind, "reference_white");
        static const char *chess_keys[] = { "square_mm", "corners", "corner0_mm" };
        for (int k = 0; k < 3; k++)
            if (!chess && model_ini_get(ini, sec, chess_keys[k])) {
                model_error(ini->path, ini_line(ini, sec, chess_keys[k]), "sample '%s': %s is a key of chessboards, "
                            "not of kind %s", sm->name, chess_keys[k], kind);
                return false;
            }
        if (chess) {
            double sq;
            if (!get_double(ini, sec, "square_mm", 1e-3, 1e4, true, &sq)) return false;
            const char *c = get_str(ini, sec, "corners", NULL);
            int cx, cy;
            char extra;
            if (!c || sscanf(c, "%d %d %c", &cx, &cy, &extra) != 2 || cx < 2 || cy < 2) {
                model_error(ini->path, ini_line(ini, sec, "corners"), "sample '%s': corners = '%s': give the inner "
                            "corners along x and y, two integers >= 2 (e.g. corners = 9 7)", sm->name, c ? c : "");
                return false;
            }
        }
        const char *mat = get_str(ini, sec, "material", NULL);
        if (mat && !coupon) {
            model_error(ini->path, ini_line(ini, sec, "material"), "sample '%s': material is a key of material "
                        "coupons and reference whites, not of kind %s", sm->name, kind);
            return false;
        }
        if (coupon && !mat) {
            model_error(ini->path, sm->line, "sample '%s' (kind %s) lacks 'material': name its [material NAME]",
                        sm->name, kind);
            return false;
        }
        if (mat && !model_materials_find(v->mats, mat)) {
            model_error(ini->path, ini_line(ini, sec, "material"), "sample '%s': material '%s' has no "
                        "[material %s] section", sm->name, mat, mat);
            return false;
        }
        sm->scene_path = rel_path(ini->path, scene);
        if (!sm->scene_path) return false;
        sm->scene = model_scene_load(sm->scene_path, NULL);
        if (!sm->scene) {
            char msg[1024];
            snprintf(msg, sizeof msg, "%s", model_last_error());
            model_error(ini->path, ini_line(ini, sec, "scene"), "sample '%s': scene %s: %s", sm->name,
                        sm->scene_path, msg);
            return false;
        }
        if (!rig_virtual_place_flex_sample(ini, sec, sm->name, kind, &sm->scene)) return false;
        sm->mats = calloc(sm->scene->nmaterials ? sm->scene->nmaterials : 1, sizeof *sm->mats);
        if (!sm->mats) return false;
        if (!model_resolve_materials(sm->scene, v->mats, sm->mats)) {
            char msg[1024];
            snprintf(msg, sizeof msg, "%s", model_last_error());
            model_error(ini->path, sm->line, "sample '%s': %s; add the material to the truth file", sm->name, msg);
            return false;
        }
        sm->tex = calloc(sm->scene->nmaterials ? sm->scene->nmaterials : 1, sizeof *sm->tex);
        if (!sm->tex) return false;
        for (int k = 0; k < sm->scene->nmaterials; k++)
            for (int j = 0; j < v->ntextures; j++)
                if (!strcmp(v->textures[j].material, sm->scene->material_names[k]) &&
                    (v->textures[j].amplitude > 0 || v->textures[j].roughness_amplitude > 0)) {
                    sm->tex[k] = &v->textures[j];
                    sm->textured = true;
                    sm->rough |= v->textures[j].roughness_amplitude > 0;
                }
        if (sm->rough && !sample_roughness(v, ini, sm)) return false;
        if (!check_sphere_facts(ini, sec, sm)) return false;
        if (mat)
            for (int k = 0; k < sm->scene->nmaterials; k++)
                if (strcmp(sm->scene->material_names[k], mat)) {
                    model_error(ini->path, ini_line(ini, sec, "material"), "sample '%s': material = %s, but its "
                                "scene %s uses material '%s' too", sm->name, mat, sm->scene_path,
                                sm->scene->material_names[k]);
                    return false;
                }
    }
    return true;
}

static int find_sample(const rig_virtual_t *v, const char *name)
{
    for (int i = 0; i < v->nsamples; i++)
        if (!v->samples[i].variant && !strcmp(v->samples[i].name, name)) return i;
    return -1;
}

static void list_samples(const rig_virtual_t *v, char *buf, size_t size)
{
    size_t n = 0;
    buf[0] = 0;
    for (int i = 0; i < v->nsamples && n < size; i++)
        if (!v->samples[i].variant) n += snprintf(buf + n, size - n, "%s%s", i ? ", " : "", v->samples[i].name);
}

// Everything but the devices. false with a message naming file:line.
static int camera_sections(const model_ini_t *ini, const char *secs[], int *line_over);

static bool parse_truth(rig_virtual_t *v, const model_ini_t *ini, const char **default_sample,
                        rig_turntable_sim_params_t *tp, double *warmup_ms, double *settle_ms,
                        rig_gv_camera_params_t *gp)
{
    if (!check_sections(ini)) return false;
    if (!v->cam_sec[0]) {   // the first camera section
        const char *secs[VIRTUAL_CAMERAS_MAX];
        int over;
        int n = camera_sections(ini, secs, &over);
        snprintf(v->cam_sec, sizeof v->cam_sec, "%s", n ? secs[0] : "camera");
    }
    // camera
    const char *cm = get_str(ini, v->cam_sec, "model", NULL);
    if (!cm) {
        model_error(ini->path, ini_line(ini, v->cam_sec, "model"), "[%s] lacks 'model': the path of the "
                    "camera's .cameramodel (relative to this file)", v->cam_sec);
        return false;
    }
    char *cpath = rel_path(ini->path, cm);
    if (!cpath) return false;
    char sha[65];
    bool ok = model_sha256_file(cpath, sha);
    if (ok) {
        const char *want = get_str(ini, v->cam_sec, "model_sha256", NULL);
        if (want && strcmp(want, sha)) {
            model_error(ini->path, ini_line(ini, v->cam_sec, "model_sha256"), "camera model %s has sha256 %s, not "
                        "the %s recorded here: the ground truth changed; record the new hash if that is intended",
                        cpath, sha, want);
            ok = false;
        }
    }
    if (ok) v->cam = model_camera_load(cpath);
    v->cam_path = cpath;
    if (ok && !v->cam) {
        char msg[1024];
        snprintf(msg, sizeof msg, "%s", model_last_error());
        model_error(ini->path, ini_line(ini, v->cam_sec, "model"), "camera model: %s", msg);
        ok = false;
    } else if (!ok && !strstr(model_last_error(), "sha256")) {
        char msg[1024];
        snprintf(msg, sizeof msg, "%s", model_last_error());
        model_error(ini->path, ini_line(ini, v->cam_sec, "model"), "camera model: %s", msg);
    }
    if (!ok) return false;
    v->W = model_camera_width(v->cam);
    v->H = model_camera_height(v->cam);
    if (v->W < 1 || v->H < 1 || v->W > 4096 || v->H > 4096) {
        model_error(ini->path, ini_line(ini, v->cam_sec, "model"), "camera model of %dx%d pixels: the virtual "
                    "camera serves 1..4096 x 1..4096", v->W, v->H);
        return false;
    }
    if (!get_double(ini, v->cam_sec, "kc_per_us", 0, 1e6, true, &v->kc_per_us)) return false;
    gp->serial = get_str(ini, v->cam_sec, "serial", gp->serial);
    gp->vendor = get_str(ini, v->cam_sec, "vendor", gp->vendor);
    gp->model = get_str(ini, v->cam_sec, "model_name", gp->model);
    if (!get_double(ini, v->cam_sec, "temperature_c", -100, 200, false, &gp->temperature_c)) return false;
    gp->sensor_width = v->W;
    gp->sensor_height = v->H;
    // render
    v->shading = model_shading_default();
    const char *ir = get_str(ini, "render", "interreflection", "thesis");
    int m = model_interreflection_from_name(ir);
    if (m < 0) {
        model_error(ini->path, ini_line(ini, "render", "interreflection"), "interreflection = '%s' is unknown; "
                    "use none, thesis or mc", ir);
        return false;
    }
    v->shading.interreflection = m;
    long li;
    li = v->shading.mc_samples;
    if (!get_int(ini, "render", "mc_samples", 1, 4096, &li)) return false;
    v->shading.mc_samples = (int)li;
    li = v->shading.mc_bounces;
    if (!get_int(ini, "render", "mc_bounces", 0, 16, &li)) return false;
    v->shading.mc_bounces = (int)li;
    li = v->shading.thesis_samples;
    if (!get_int(ini, "render", "thesis_samples", 1, 1024, &li)) return false;
    v->shading.thesis_samples = (int)li;
    li = v->shading.finite_lamps;
    if (!get_int(ini, "render", "finite_lamps", 0, 1, &li)) return false;
    v->shading.finite_lamps = li != 0;
    li = 1;
    if (!get_int(ini, "render", "direct_samples", 1, 4096, &li)) return false;
    v->direct_samples = (int)li;
    li = 1;
    if (!get_int(ini, "render", "indirect_downsample", 1, 16, &li)) return false;
    v->ds = (int)li;
    li = 1;
    if (!get_int(ini, "render", "prerender", 0, 2, &li)) return false;
    v->prerender = (int)li;
    li = 1;
    if (!get_int(ini, "render", "seed", 0, LONG_MAX, &li)) return false;
    v->shading.seed = (uint64_t)li;
    if (!get_double(ini, "render", "thesis_cone_deg", 1e-3, 90, false, &v->shading.thesis_cone_deg) ||
        !get_double(ini, "render", "rho_sr", 0, 4 * M_PI, false, &v->shading.rho))
        return false;
    // sensor, lamps, materials
    if (!model_sensor_from_ini(ini, &v->sensor)) return false;
    if (strcmp(v->cam_sec, "camera")) {   // [sensor NAME] of [camera NAME]
        char ss[80];
        snprintf(ss, sizeof ss, "sensor %s", v->cam_sec + 7);
        if (!model_sensor_update_from_ini(ini, ss, &v->sensor)) return false;
    }
    if (!(v->lamps = model_lamps_from_ini(ini))) return false;
    if (v->lamps->n > 32) {
        model_error(ini->path, v->lamps->lamps[32].line, "more than 32 lamps; the rig switches at most 32");
        return false;
    }
    if (!(v->mats = model_materials_from_ini(ini))) return false;
    // turntable
    const char *tt = "turntable";
    if (!get_double(ini, tt, "speed_deg_s", 1e-6, 1e4, false, &tp->speed_deg_s) ||
        !get_double(ini, tt, "accel_deg_s2", 1e-6, 1e6, false, &tp->accel_deg_s2) ||
        !get_double(ini, tt, "home_time_s", 0, 3600, false, &tp->home_time_s) ||
        !get_double(ini, tt, "position_noise_deg", 0, 10, false, &tp->position_noise_deg))
        return false;
    li = (long)tp->seed;
    if (!get_int(ini, tt, "seed", 0, LONG_MAX, &li)) return false;
    tp->seed = (uint64_t)li;
    li = 0;
    if (!get_int(ini, tt, "fault_after_moves", 0, INT_MAX, &li)) return false;
    tp->fault_after_moves = (int)li;
    const char *f = get_str(ini, tt, "fault", NULL);
    if (f) {
        if (!strcmp(f, "motion")) tp->fault = RIG_ERR_MOTION;
        else if (!strcmp(f, "stall")) tp->fault = RIG_ERR_TIMEOUT;
        else if (!strcmp(f, "disconnect")) tp->fault = RIG_ERR_DISCONNECTED;
        else {
            model_error(ini->path, ini_line(ini, tt, "fault"), "fault = '%s' is unknown; use motion, stall or "
                        "disconnect", f);
            return false;
        }
    }
    if ((tp->fault_after_moves > 0) != (f != NULL)) {
        model_error(ini->path, ini_line(ini, tt, f ? "fault" : "fault_after_moves"), "fault injection needs both "
                    "fault_after_moves (> 0) and fault");
        return false;
    }
    // virtual
    *warmup_ms = *settle_ms = 0;
    if (!get_double(ini, "virtual", "lamp_warmup_ms", 0, 3.6e6, false, warmup_ms) ||
        !get_double(ini, "virtual", "lamp_settle_ms", 0, 3.6e6, false, settle_ms))
        return false;
    *default_sample = get_str(ini, "virtual", "sample", NULL);
    // textures, samples
    if (!parse_textures(v, ini) || !parse_samples(v, ini)) return false;
    if (!rig_vlamps_parse(&v->lamp_fx, ini, v->lamps)) return false;
    if (!rig_optics_parse(ini, &v->optics)) return false;
    v->nbase_samples = v->nsamples;
    if (!rig_virtual_place_parse(ini, &v->place)) return false;
    if (*default_sample && find_sample(v, *default_sample) < 0) {
        char list[512];
        list_samples(v, list, sizeof list);
        model_error(ini->path, ini_line(ini, "virtual", "sample"), "sample = '%s' has no [sample %s] section; "
                    "samples: %s", *default_sample, *default_sample, list);
        return false;
    }
    return true;
}

// ---------------------------------------------------------------------------
// Open / close

static int fail_model(int err)
{
    char msg[1024];
    snprintf(msg, sizeof msg, "%s", model_last_error());
    return rig_fail(err, "virtual rig: %s", msg);
}

// Parse-only check of a truth file's text (rig.h): parse_truth on a rig that
// starts nothing (no camera server, stage, lamps or render thread).
int rig_virtual_check_truth(const char *text, size_t len, const char *name, const char *base_dir)
{
    if (!text || !name || !base_dir) return rig_fail(RIG_ERR_INVALID, "virtual rig: check truth: NULL argument");
    int err = RIG_ERR_INVALID;
    char *path = NULL;
    model_ini_t *ini = NULL;
    rig_virtual_t *v = calloc(1, sizeof *v);
    if (!v || asprintf(&path, "%s/%s", base_dir, name) < 0) {
        path = NULL;
        err = rig_fail(RIG_ERR_NO_MEM, "virtual rig: out of memory");
        goto done;
    }
    pthread_mutex_init(&v->state_lock, NULL);
    pthread_mutex_init(&v->cache_lock, NULL);
    const char *def_sample = NULL;
    rig_turntable_sim_params_t tp = rig_turntable_sim_defaults();
    double warmup_ms, settle_ms;
    rig_gv_camera_params_t gp = rig_gv_camera_defaults();
    if (!(ini = model_ini_parse(text, len, path)) ||
        !parse_truth(v, ini, &def_sample, &tp, &warmup_ms, &settle_ms, &gp)) {
        err = fail_model(RIG_ERR_INVALID);
        goto done;
    }
    // every further camera: its [camera NAME] and [sensor NAME]
    const char *secs[VIRTUAL_CAMERAS_MAX];
    int over = 0, ncams = camera_sections(ini, secs, &over);
    if (over) {
        model_error(ini->path, over, "more than %d cameras: the virtual rig serves at most %d", VIRTUAL_CAMERAS_MAX,
                    VIRTUAL_CAMERAS_MAX);
        err = fail_model(RIG_ERR_INVALID);
        goto done;
    }
    for (int k = 1; k < ncams; k++) {
        rig_virtual_t *w = calloc(1, sizeof *w);
        if (!w) {
            err = rig_fail(RIG_ERR_NO_MEM, "virtual rig: out of memory");
            goto done;
        }
        pthread_mutex_init(&w->state_lock, NULL);
        pthread_mutex_init(&w->cache_lock, NULL);
        snprintf(w->cam_sec, sizeof w->cam_sec, "%s", secs[k]);
        rig_gv_camera_params_t gk = rig_gv_camera_defaults();
        bool ok = parse_truth(w, ini, &def_sample, &tp, &warmup_ms, &settle_ms, &gk);
        rig_virtual_close(w);
        if (!ok) {
            err = fail_model(RIG_ERR_INVALID);
            goto done;
        }
    }
    err = RIG_ERR_OK;
done:
    model_ini_free(ini);
    rig_virtual_close(v);
    free(path);
    return err;
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

// The camera sections of a truth file in file order ([camera], [camera NAME]): their count.
static int camera_sections(const model_ini_t *ini, const char *secs[], int *line_over)
{
    int n = 0;
    *line_over = 0;
    for (int s = 0; s < ini->nsections; s++)
        if (!strcmp(ini->sections[s], "camera") || !strncmp(ini->sections[s], "camera ", 7)) {
            if (n == VIRTUAL_CAMERAS_MAX) *line_over = ini->section_lines[s];
            else secs[n++] = ini->sections[s];
        }
    return n;
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

static int open_camera(rig_virtual_t **out, const char *truth_path, const rig_virtual_options_t *opt,
                       rig_virtual_t *parent, int k);

int rig_virtual_open(rig_virtual_t **out, const char *truth_path, const rig_virtual_options_t *opt)
{
    return open_camera(out, truth_path, opt, NULL, 0);
}

// Camera k of the truth file: the rig itself (k = 0, parent NULL: the stage,
// the lamps, then cameras 1.. as its views), or a view of parent.
static int open_camera(rig_virtual_t **out, const char *truth_path, const rig_virtual_options_t *opt,
                       rig_virtual_t *parent, int k)
{
    if (!out) return rig_fail(RIG_ERR_INVALID, "virtual rig: NULL output handle");
    *out = NULL;
    if (!truth_path) return rig_fail(RIG_ERR_INVALID, "virtual rig: no truth file given");
    rig_virtual_options_t o = opt ? *opt : rig_virtual_defaults();
    if (!o.address) o.address = "127.0.0.1";
    char addr[64];
    if (!camera_address(o.address, k, addr))
        return rig_fail(RIG_ERR_INVALID, "virtual rig: address '%s': no loopback address for camera %d", o.address,
                        k + 1);
    if (!(isfinite(o.time_scale) && o.time_scale > 0))
        return rig_fail(RIG_ERR_INVALID, "virtual rig: time_scale %g must be > 0", o.time_scale);
    if (strlen(addr) >= 64 - 1)
        return rig_fail(RIG_ERR_INVALID, "virtual rig: address '%s' is too long", addr);
    if (o.serve != RIG_VIRTUAL_SERVE_GIGE && o.serve != RIG_VIRTUAL_SERVE_INPROCESS)
        return rig_fail(RIG_ERR_INVALID, "virtual rig: serve = %d is neither RIG_VIRTUAL_SERVE_GIGE nor "
                        "RIG_VIRTUAL_SERVE_INPROCESS", (int)o.serve);
    int err = RIG_ERR_OK;
    rig_truth_t *truth = NULL;
    const model_ini_t *ini = NULL;
    rig_virtual_t *v = calloc(1, sizeof *v);
    if (!v) return rig_fail(RIG_ERR_NO_MEM, "virtual rig: out of memory");
    pthread_mutex_init(&v->state_lock, NULL);
    pthread_mutex_init(&v->cache_lock, NULL);
    v->truth_path = strdup(truth_path);
    snprintf(v->address, sizeof v->address, "%s", addr);
    v->next_seed = o.noise_seed + (uint64_t)k * 1000003u;   // each camera its own noise
    v->state = parent ? parent : v;
    v->views[v->nviews++] = v;
    if (!v->truth_path) {
        err = rig_fail(RIG_ERR_NO_MEM, "virtual rig: out of memory");
        goto fail;
    }
    truth = rig_truth_load(truth_path);   // the truth file's one reader (rig/virtual/truth.h)
    if (!truth || !(ini = rig_truth_ini(truth))) {
        err = fail_model(RIG_ERR_INVALID);
        goto fail;
    }
    const char *def_sample = NULL;
    rig_turntable_sim_params_t tp = rig_turntable_sim_defaults();
    double warmup_ms, settle_ms;
    rig_gv_camera_params_t gp = rig_gv_camera_defaults();
    const char *secs[VIRTUAL_CAMERAS_MAX];
    int over = 0, ncams = camera_sections(ini, secs, &over);
    if (over) {
        model_error(ini->path, over, "more than %d cameras: the virtual rig serves at most %d", VIRTUAL_CAMERAS_MAX,
                    VIRTUAL_CAMERAS_MAX);
        err = fail_model(RIG_ERR_INVALID);
        goto fail;
    }
    if (k < ncams) {
        snprintf(v->cam_sec, sizeof v->cam_sec, "%s", secs[k]);
        snprintf(v->cam_name, sizeof v->cam_name, "%s", strcmp(secs[k], "camera") ? secs[k] + 7 : "camera");
    }
    if (!parse_truth(v, ini, &def_sample, &tp, &warmup_ms, &settle_ms, &gp)) {
        err = fail_model(RIG_ERR_INVALID);
        goto fail;
    }
    v->lamp_fx.time_scale = o.time_scale;
    if (o.prerender >= 0) {
        if (o.prerender > 2) {
            err = rig_fail(RIG_ERR_INVALID, "virtual rig: prerender %d outside 0..2", o.prerender);
            goto fail;
        }
        v->prerender = o.prerender;
    }
    if (o.serial && k == 0) gp.serial = o.serial;
    if (parent) v->prerender = 0;
    const char *sample = o.sample ? o.sample : def_sample ? def_sample : v->samples[0].name;
    v->cur_sample = find_sample(v, sample);
    if (v->cur_sample < 0) {
        char list[512];
        list_samples(v, list, sizeof list);
        err = rig_fail(RIG_ERR_INVALID, "virtual rig: %s has no sample '%s'; samples: %s", truth_path, sample, list);
        goto fail;
    }
    if (v->shading.interreflection == MODEL_INTERREFLECTION_MC && v->ds > 1 && (err = make_lowres(v)))
        goto fail;
    if (v->optics.rays_per_pixel > 1 && (err = make_highres(v))) goto fail;
    // fixed patterns and buffers
    size_t n = (size_t)v->W * v->H;
    v->prnu = malloc(n * sizeof(float));
    v->dsnu = malloc(n * sizeof(float));
    v->frame = malloc(n * sizeof(float));
    v->face = malloc(n * sizeof *v->face);
    if (!v->prnu || !v->dsnu || !v->frame || !v->face) {
        err = rig_fail(RIG_ERR_NO_MEM, "virtual rig: out of memory for %dx%d images", v->W, v->H);
        goto fail;
    }
    model_sensor_patterns(&v->sensor, v->W, v->H, v->prnu, v->dsnu);
    if (!model_camera_ray_table(v->cam, NULL)) {
        err = fail_model(RIG_ERR_IO);
        goto fail;
    }
    // devices (the rig's; a view shows its parent's)
    if (parent) goto camera;
    tp.time_scale = o.time_scale;
    if ((err = rig_turntable_open_sim(&v->tt_sim, &tp))) goto fail;
    v->tt.ops = &virtual_tt_ops;
    v->tt.impl = v;
    snprintf(v->tt.name, sizeof v->tt.name, "virtual turntable (sim, seed %llu)", (unsigned long long)tp.seed);
    rig_lamp_line_t lines[32];
    memset(lines, 0, sizeof lines);
    for (int i = 0; i < v->lamps->n; i++) {
        snprintf(lines[i].name, sizeof lines[i].name, "%s", v->lamps->lamps[i].name);
        snprintf(lines[i].chip, sizeof lines[i].chip, "virtual");
        lines[i].line = (unsigned)i;
        lines[i].warmup_ms = warmup_ms * o.time_scale;
        lines[i].settle_ms = settle_ms * o.time_scale;
    }
    if ((err = rig_lamps_open_sim(&v->lamps_dev, lines, v->lamps->n))) goto fail;
camera:
    snprintf(v->serial, sizeof v->serial, "%s", gp.serial ? gp.serial : "");
    for (int d = 0; parent && d < parent->nviews; d++)
        if (!strcmp(parent->views[d]->serial, v->serial)) {
            err = rig_fail(RIG_ERR_INVALID, "virtual rig: %s: [%s] and [%s] have the same serial '%s': give each "
                           "camera its own 'serial ='", truth_path, parent->views[d]->cam_sec, v->cam_sec, v->serial);
            goto fail;
        }
    gp.address = v->address;
    gp.busy_wait_s = o.busy_wait_s;
    gp.render = render_cb;
    gp.render_ctx = v;
    gp.inprocess = o.serve == RIG_VIRTUAL_SERVE_INPROCESS;
    if (gp.inprocess)   // the id rig_camera_open_aravis takes
        snprintf(v->address, sizeof v->address, "%s%s", RIG_GV_INPROCESS_PREFIX, gp.serial ? gp.serial : "");
    if ((err = rig_gv_camera_start(&v->gv, &gp))) goto fail;
    if (v->prerender) {
        if (pthread_create(&v->pre_thread, NULL, prerender_main, v)) {
            err = rig_fail(RIG_ERR_IO, "virtual rig: cannot start the pre-render thread");
            goto fail;
        }
        v->pre_running = true;
    }
    for (int c = 1; !parent && c < ncams; c++) {
        rig_virtual_t *w = NULL;
        if ((err = open_camera(&w, truth_path, &o, v, c))) goto fail;
        v->views[v->nviews++] = w;
    }
    if (!parent && v->place.on && (err = rig_virtual_set_sample(v, v->samples[v->cur_sample].name))) goto fail;
    rig_truth_free(truth);
    *out = v;
    return 0;
fail:
    rig_truth_free(truth);
    rig_virtual_close(v);
    return err ? err : RIG_ERR_IO;
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
    for (int i = 0; i < NTRACERS; i++) slot_free(&v->tracers[i]);
    for (int i = 0; i < v->nsamples; i++) {
        free(v->samples[i].scene_path);
        model_scene_free(v->samples[i].scene);
        if (v->samples[i].variant) continue;
        free(v->samples[i].mats);
        free(v->samples[i].tex);
        free(v->samples[i].mats_rough);
        free(v->samples[i].mats_smooth);
        free(v->samples[i].rough_store);
    }
    free(v->samples);
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

const char *rig_virtual_sample(const rig_virtual_t *v)
{
    if (!v) return NULL;
    rig_virtual_t *w = (rig_virtual_t *)v;
    pthread_mutex_lock(&w->state_lock);
    const char *s = v->samples[v->cur_sample].name;
    pthread_mutex_unlock(&w->state_lock);
    return s;
}

// Posed copy `slot` of the samples is taken again: forget what the caches
// keep of it; cache_lock held.
static void forget_sample(rig_virtual_t *v, int slot)
{
    for (int i = 0; i < NPLANES; i++)
        if (v->planes[i].L && v->planes[i].sample == slot) v->planes[i].sample = -1;
    for (int i = 0; i < NTRACERS; i++)
        if (v->tracers[i].t && v->tracers[i].sample == slot) slot_free(&v->tracers[i]);
    for (int k = 0; k < NSPEC; k++)
        if (v->spec[k].sample == slot) v->spec[k].valid = false;
    if (v->cur_key_sample == slot) v->cur_key_set = false;
    if (v->akey_sample == slot) v->akey_set = false;
    free(v->samples[slot].scene_path);
    model_scene_free(v->samples[slot].scene);
}

// A new posed copy of base sample i (the wedge's pose after the placement
// error dR, dt when dR is not NULL); its index, or a RIG_ERR_* code.
static int new_pose(rig_virtual_t *v, int i, double tilt_deg, double tilt_azimuth_deg, const double *dR,
                    const double *dt)
{
    int slot = v->nsamples;
    if (v->nsamples >= v->nbase_samples + MAX_POSES) {
        if (!dR)
            return rig_fail(RIG_ERR_INVALID, "virtual rig: more than %d sample poses in one rig session; "
                            "close and open the rig", MAX_POSES);
        pthread_mutex_lock(&v->state_lock);
        int cur = v->cur_sample;
        pthread_mutex_unlock(&v->state_lock);
        do slot = v->nbase_samples + v->place_next++ % MAX_POSES;
        while (slot == cur);
    }
    sample_t *b = &v->samples[i], sm = *b;
    sm.variant = true;
    sm.base = i;
    sm.tilt_deg = tilt_deg;
    sm.tilt_azimuth_deg = tilt_azimuth_deg;
    sm.placed = dR != NULL;
    sm.scene_path = strdup(b->scene_path);
    model_scene_wedge_pose(b->scene, tilt_deg, tilt_azimuth_deg, sm.R, sm.t);
    if (dR) {   // x = Rw (dR x0 + dt) + tw
        double R[9], t[3];
        for (int r = 0; r < 3; r++) {
            t[r] = sm.t[r];
            for (int c = 0; c < 3; c++) {
                R[3 * r + c] = sm.R[3 * r] * dR[c] + sm.R[3 * r + 1] * dR[3 + c] + sm.R[3 * r + 2] * dR[6 + c];
                t[r] += sm.R[3 * r + c] * dt[c];
            }
        }
        memcpy(sm.R, R, sizeof R);
        memcpy(sm.t, t, sizeof t);
    }
    sm.scene = model_scene_transformed(b->scene, sm.R, sm.t);
    if (!sm.scene || !sm.scene_path) {
        model_scene_free(sm.scene);
        free(sm.scene_path);
        return rig_fail(RIG_ERR_NO_MEM, "virtual rig: sample '%s': out of memory for its posed scene", b->name);
    }
    pthread_mutex_lock(&v->cache_lock);
    if (slot < v->nsamples) forget_sample(v, slot);
    v->samples[slot] = sm;
    if (slot == v->nsamples) v->nsamples = slot + 1;
    pthread_mutex_unlock(&v->cache_lock);
    return slot;
}

// Whether sample `name` can take the pose: its index (*i) and the posed copy
// that has it already (*j, -1: none; only without a placement error). 0 or a RIG_ERR_* code.
static int pose_check(rig_virtual_t *v, const char *name, double tilt_deg, double tilt_azimuth_deg, bool placed,
                      int *i, int *j)
{
    *i = find_sample(v, name);
    *j = -1;
    if (*i < 0) {
        char list[512];
        list_samples(v, list, sizeof list);
        return rig_fail(RIG_ERR_INVALID, "virtual rig: %s has no sample '%s'; samples: %s", v->truth_path, name, list);
    }
    if (!isfinite(tilt_deg) || fabs(tilt_deg) > 80 || !isfinite(tilt_azimuth_deg))
        return rig_fail(RIG_ERR_INVALID, "virtual rig: sample '%s': tilt %g deg at azimuth %g deg; the tilt must be "
                        "within +-80 deg and both finite", name, tilt_deg, tilt_azimuth_deg);
    if (tilt_deg != 0 && v->samples[*i].uniform)
        return rig_fail(RIG_ERR_INVALID, "virtual rig: sample '%s' is a uniform source and cannot be tilted", name);
    for (int k = 0; k < v->nsamples && !placed; k++)
        if (v->samples[k].variant && !v->samples[k].placed && v->samples[k].base == *i &&
            v->samples[k].tilt_deg == tilt_deg && v->samples[k].tilt_azimuth_deg == tilt_azimuth_deg)
            *j = k;
    return 0;
}

static int set_sample_pose_one(rig_virtual_t *v, const char *name, double tilt_deg, double tilt_azimuth_deg,
                               const double *dR, const double *dt)
{
    int i, j, rc = pose_check(v, name, tilt_deg, tilt_azimuth_deg, dR != NULL, &i, &j);
    if (rc) return rc;
    if (tilt_deg != 0 || dR) {
        if (j < 0 && (j = new_pose(v, i, tilt_deg, tilt_azimuth_deg, dR, dt)) < 0) return j;
        i = j;
    }
    pthread_mutex_lock(&v->state_lock);
    v->cur_sample = i;
    pthread_mutex_unlock(&v->state_lock);
    return 0;
}

int rig_virtual_set_sample(rig_virtual_t *v, const char *name)
{
    return rig_virtual_set_sample_pose(v, name, 0, 0);
}

// The sample on the table: its pose, the placement error of this placement
// ([placement]), then the operator's intended offset off (turn deg, dx, dy mm;
// NULL: none): x = off (err x0).
static int set_sample(rig_virtual_t *v, const char *name, double tilt_deg, double tilt_azimuth_deg,
                      const double *off)
{
    if (!v || !name) return rig_fail(RIG_ERR_INVALID, "virtual rig: set sample: NULL argument");
    int rc = 0;
    rig_virtual_t *r = v->state;
    // a placement error (the same for every camera): the count-th placement of this sample
    double dR[9], dt[3], err[3];
    bool placed = false;
    int b = find_sample(r, name);
    if (r->place.on && b >= 0 && !r->samples[b].uniform) {
        if (!r->place_count && !(r->place_count = calloc((size_t)r->nbase_samples, sizeof *r->place_count)))
            return rig_fail(RIG_ERR_NO_MEM, "virtual rig: out of memory");
        rig_virtual_place_error(&r->place, name, r->place_count[b]++, r->samples[b].scene, dR, dt, err);
        placed = true;
    }
    if (off && b >= 0) {
        if (r->samples[b].uniform)
            return rig_fail(RIG_ERR_INVALID, "virtual rig: sample '%s' is a uniform source: it is not placed", name);
        double oR[9], ot[3], R[9], t[3];
        rig_virtual_place_about_centre(r->samples[b].scene, off[0] * M_PI / 180, off[1], off[2], oR, ot);
        if (!placed) {
            memcpy(dR, oR, sizeof oR);
            memcpy(dt, ot, sizeof ot);
        } else {   // off (dR x + dt) = oR dR x + oR dt + ot
            for (int i = 0; i < 3; i++) {
                t[i] = ot[i];
                for (int j = 0; j < 3; j++) {
                    R[3 * i + j] = oR[3 * i] * dR[j] + oR[3 * i + 1] * dR[3 + j] + oR[3 * i + 2] * dR[6 + j];
                    t[i] += oR[3 * i + j] * dt[j];
                }
            }
            memcpy(dR, R, sizeof R);
            memcpy(dt, t, sizeof t);
        }
    }
    bool moved = placed || (off && b >= 0);
    for (int c = 0; c < r->nviews && !rc; c++)
        rc = set_sample_pose_one(r->views[c], name, tilt_deg, tilt_azimuth_deg, moved ? dR : NULL, moved ? dt : NULL);
    if (!rc) {
        pthread_mutex_lock(&r->state_lock);
        r->place_last_set = placed;
        if (placed) memcpy(r->place_last, err, sizeof err);
        pthread_mutex_unlock(&r->state_lock);
    }
    return rc;
}

int rig_virtual_set_sample_pose(rig_virtual_t *v, const char *name, double tilt_deg, double tilt_azimuth_deg)
{
    return set_sample(v, name, tilt_deg, tilt_azimuth_deg, NULL);
}

int rig_virtual_set_sample_offset(rig_virtual_t *v, const char *name, double turn_deg, double dx_mm, double dy_mm)
{
    if (!isfinite(turn_deg) || !isfinite(dx_mm) || !isfinite(dy_mm) || fabs(turn_deg) > 45 || fabs(dx_mm) > 100 ||
        fabs(dy_mm) > 100)
        return rig_fail(RIG_ERR_INVALID, "virtual rig: sample '%s' placed off by %g deg, (%g, %g) mm: give a turn "
                        "within +-45 deg and shifts within +-100 mm", name ? name : "?", turn_deg, dx_mm, dy_mm);
    const double off[3] = { turn_deg, dx_mm, dy_mm };
    return set_sample(v, name, 0, 0, off);
}

bool rig_virtual_last_placement(rig_virtual_t *v, double *turn_deg, double *dx_mm, double *dy_mm)
{
    if (!v) return false;
    rig_virtual_t *r = v->state;
    pthread_mutex_lock(&r->state_lock);
    bool set = r->place_last_set;
    if (set) {
        if (turn_deg) *turn_deg = r->place_last[0];
        if (dx_mm) *dx_mm = r->place_last[1];
        if (dy_mm) *dy_mm = r->place_last[2];
    }
    pthread_mutex_unlock(&r->state_lock);
    return set;
}

int rig_virtual_check_sample_pose(rig_virtual_t *v, const char *name, double tilt_deg, double tilt_azimuth_deg)
{
    if (!v || !name) return rig_fail(RIG_ERR_INVALID, "virtual rig: check sample: NULL argument");
    rig_virtual_t *r = v->state;
    int i, j, rc = pose_check(r, name, tilt_deg, tilt_azimuth_deg, r->place.on, &i, &j);
    if (!rc && tilt_deg != 0 && j < 0 && !r->place.on && r->nsamples >= r->nbase_samples + MAX_POSES)
        rc = rig_fail(RIG_ERR_INVALID, "virtual rig: more than %d sample poses in one rig session; close and open "
                      "the rig", MAX_POSES);
    return rc;
}

int rig_virtual_table_pose(rig_virtual_t *v, double angle_deg, double R[9])
{
    if (!v || !R || !isfinite(angle_deg)) return rig_fail(RIG_ERR_INVALID, "virtual rig: table pose: bad argument");
    rig_virtual_place_table_R(&v->place, angle_deg, R);
    return 0;
}

int rig_virtual_sample_pose(rig_virtual_t *v, double *tilt_deg, double *tilt_azimuth_deg, double R[9], double t[3])
{
    if (!v) return rig_fail(RIG_ERR_INVALID, "virtual rig: sample pose: NULL rig");
    pthread_mutex_lock(&v->state_lock);
    const sample_t *sm = &v->samples[v->cur_sample];
    if (tilt_deg) *tilt_deg = sm->tilt_deg;
    if (tilt_azimuth_deg) *tilt_azimuth_deg = sm->tilt_azimuth_deg;
    if (R) memcpy(R, sm->R, sizeof sm->R);
    if (t) memcpy(t, sm->t, sizeof sm->t);
    pthread_mutex_unlock(&v->state_lock);
    return 0;
}

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
