// rig/virtual/internal.h — inside the virtual rig (rig/virtual/): its state
// (struct rig_virtual), samples, textures and caches, and the functions its
// files share: virtual.c (open, close, the turntable seen by users), render.c
// (planes and frames), texture.c, prerender.c (pre-rendering and speculation),
// pose.c (the sample on the table), the truth file's reader (truth.c,
// truth_figures.c, truth_rig.c, truth_samples.c; rig/virtual/truth.h) and the
// virtual GigE Vision camera's server (gv_camera.c, gv_render.c, gv_stream.c,
// gv_xml.c).
#pragma once

#include <arv.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "model/model.h"
#include "rig/internal.h"
#include "rig/rig.h"
#include "rig/virtual/gv_camera.h"
#include "rig/virtual/lamps.h"
#include "rig/virtual/materials.h"
#include "rig/virtual/optics.h"
#include "rig/virtual/place.h"
#include "rig/virtual/truth.h"
#include "rig/virtual/virtual.h"

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

// ---------------------------------------------------------------------------
// virtual.c

// Sleep s seconds.
void rig_vsleep_s(double s);

// ---------------------------------------------------------------------------
// render.c (cache_lock held where noted)

void rig_vslot_free(tracer_slot_t *s);
// The radiance image of one lamp; cache_lock held. NULL on error.
const float *rig_vplane_for(rig_virtual_t *v, int sample, double angle_deg, int lamp);
// Is the plane cached? (cache_lock held)
bool rig_vplane_cached(const rig_virtual_t *v, int sample, double angle_deg, int lamp);
// The noisy sensor values of a frame into out (cache_lock held).
int rig_vnoisy_frame(rig_virtual_t *v, int sample, double angle_deg, uint32_t mask, double exposure_us,
                     double gain_db, uint64_t seed, int64_t trigger_ns, float *out);
// The camera server's render callback (rig_gv_render_fn): a triggered frame.
int rig_vrender_cb(void *ctx, const rig_frame_meta_t *m, uint16_t *pix);

// ---------------------------------------------------------------------------
// texture.c

// The texture factors of a slot's view from the full-resolution face ids.
bool rig_vtexture_make(rig_virtual_t *v, tracer_slot_t *slot, const int32_t *face);

// ---------------------------------------------------------------------------
// prerender.c

bool rig_vspec_is(const spec_t *p, int sample, double angle_deg, uint32_t mask, double exposure_us,
                  double gain_db, uint64_t seed);
// The pre-render thread (arg: the rig).
void *rig_vprerender_main(void *arg);
// A triggered frame's state and settings, remembered: they predict the next
// frames (cache_lock held).
void rig_vspec_note(rig_virtual_t *v, int sample, double angle_deg, uint32_t mask, double exposure_us,
                    double gain_db);
// The frame computed ahead for exactly these inputs (NULL: none; its buffer
// stays while cache_lock is held); the speculative frames of seeds up to this
// one are used up (cache_lock held).
const float *rig_vspec_take(rig_virtual_t *v, int sample, double angle_deg, uint32_t mask, double exposure_us,
                            double gain_db, uint64_t seed);

// ---------------------------------------------------------------------------
// The truth file read for the virtual rig (truth.c, truth_rig.c, truth_samples.c)

// What the truth file says for one camera of the virtual rig: the camera
// ([camera] / [camera NAME]: cam_sec, cam_name "camera" / NAME), its render
// settings, sensor, lamps, materials, textures and samples (room for
// MAX_POSES more), and the devices' parameters (gp: the camera server's
// identity and size, tp: the stage, the lamps' timing). Owned (rig_vtruth_free):
// cam, cam_path, lamps, mats, textures, samples; the strings of gp and
// default_sample are the truth file's (valid while it is).
typedef struct {
    char    cam_sec[80], cam_name[32];
    model_camera_t *cam;
    char   *cam_path;
    int     W, H;
    double  kc_per_us;
    model_sensor_t  sensor;
    model_shading_t shading;
    int     direct_samples, ds, prerender;
    model_lamps_t     *lamps;
    rig_vlamps_t       lamp_fx;
    model_materials_t *mats;
    texture_t         *textures;
    int                ntextures;
    sample_t          *samples;
    int                nsamples;
    rig_optics_t        optics;
    rig_virtual_place_t place;
    rig_gv_camera_params_t     gp;
    rig_turntable_sim_params_t tp;
    double      warmup_ms, settle_ms;
    const char *default_sample;   // [virtual] sample; NULL: none
} rig_vtruth_t;

// The file's INI (for the truth reader's files only).
const model_ini_t *rig_truth_ini(const rig_truth_t *t);
// A path of the truth file resolved against its directory (absolute: as it
// is); free it. NULL: out of memory.
char *rig_truth_resolve(const rig_truth_t *t, const char *rel);
// Every section and key is one a truth file has. false + message (file:line).
bool  rig_truth_check_sections(const rig_truth_t *t);
// Typed values of a section (model/base/ini.c reports them with file:line);
// rig_vtruth_line: the line of a key, else of its section.
int         rig_vtruth_line(const model_ini_t *ini, const char *sec, const char *key);
bool        rig_vtruth_double(const model_ini_t *ini, const char *sec, const char *key, double lo, double hi,
                              bool required, double *out);
bool        rig_vtruth_int(const model_ini_t *ini, const char *sec, const char *key, long lo, long hi, long *out);
const char *rig_vtruth_str(const model_ini_t *ini, const char *sec, const char *key, const char *def);

// The file's cameras; -1 + message when it has more than VIRTUAL_CAMERAS_MAX.
int  rig_vtruth_cameras(const rig_truth_t *t);
// The truth for camera k (0: the first camera section; with none, [camera],
// which then lacks its model). false + message (file:line), *out freed.
bool rig_vtruth_read(const rig_truth_t *t, int k, rig_vtruth_t *out);
void rig_vtruth_free(rig_vtruth_t *c);
// [texture MATERIAL] and [sample NAME] into c (its materials read). false + message.
bool rig_vtruth_textures(const rig_truth_t *t, rig_vtruth_t *c);
bool rig_vtruth_samples(const rig_truth_t *t, rig_vtruth_t *c);
// [lamp_drift NAME] and [stray] into fx (rig/virtual/lamps.h). false + message.
bool rig_vtruth_lamp_effects(const rig_truth_t *t, const model_lamps_t *lamps, rig_vlamps_t *fx);
// A mirror sphere's sphere_radius_mm and sphere_centre_mm in section sec of
// sample `name`. false + message.
bool rig_vtruth_sphere_facts(const model_ini_t *ini, const char *sec, const char *name, double centre_mm[3],
                             double *radius_mm);

// The index of base sample `name` among n samples, -1 when none.
int  rig_vsample_find(const sample_t *samples, int n, const char *name);
// The base samples' names, ", "-separated, into buf.
void rig_vsample_list(const sample_t *samples, int n, char *buf, size_t size);
// Free n samples (a posed copy's materials are its base's) and the array.
void rig_vsamples_free(sample_t *samples, int n);

// ---------------------------------------------------------------------------
// The virtual GigE Vision camera (gv_camera.c, gv_render.c, gv_stream.c, gv_xml.c)

// GigE Vision bootstrap registers (GigE Vision 2.0, table 28).
#define GVBS_MANUFACTURER_NAME 0x0048   // 32 bytes
#define GVBS_MODEL_NAME        0x0068   // 32 bytes
#define GVBS_STRING_SIZE       32
#define GVBS_SCPS0             0x0d04   // stream channel 0 packet size (bits 0-15)
#define GVSP_PACKET_SIZE       8192     // loopback has a 64 KiB MTU: jumbo packets
#define GVCP_PORT              3956
#define GV_TICK_HZ             10.0     // Aravis's GV thread's trigger check (see rig/virtual/gv_camera.c)

// Registers our XML adds (inside the fake camera's 64 KiB register memory).
#define REG_TRIGGER            0xa000   // TriggerSoftware as the client sees it
#define REG_EXPOSURE_US        0xa008   // float64 big-endian
#define REG_GAIN_DB            0xa010   // float64 big-endian
#define REG_TEMPERATURE_C      0xa018   // float64 big-endian, read-only to clients
#define REG_EXPOSURE_AUTO      0xa020   // ExposureAuto: 0 Off, 1 Once, 2 Continuous
#define REG_BALANCE_WHITE_AUTO 0xa024   // BalanceWhiteAuto: the same values (a mono sensor ignores it)
#define REG_GAMMA_ENABLE       0xa028   // GammaEnable: 0 / 1
#define REG_LUT_ENABLE         0xa02c   // LUTEnable: 0 / 1
#define REG_GAMMA              0xa030   // float64 big-endian
#define REG_BLACK_LEVEL        0xa038   // float64 big-endian, DN added to every pixel
#define REG_FIRMWARE           0xa040   // DeviceFirmwareVersion, 32 bytes (to 0xa05f)
#define REG_CONTRAST_AUTO      0xa060   // ContrastAuto, a vendor automatic: 0 Off, 1 Once, 2 Continuous
#define REG_GAIN_AUTO          0x0114   // GainAuto of Aravis's fake camera XML: 1 Off, 3 Once, 2 Continuous
#define GAIN_AUTO_OFF          1
#define GVBS_SCPD0             0x0d08   // stream channel 0 packet delay, timestamp ticks

#define EXPOSURE_MIN_US 10.0
#define EXPOSURE_MAX_US 10e6
#define GAIN_MAX_DB     24.0
// What the camera's own automatics do while on (so a client that leaves them on
// gets frames unlike the settings it asked for): ExposureAuto 1.5 x the set
// exposure, GainAuto 6 dB more than the set gain (within the ranges).
#define AUTO_EXPOSURE_FACTOR 1.5
#define AUTO_GAIN_DB         6.0
#define GAMMA_DEFAULT        0.45

struct rig_gv_camera {
    rig_gv_camera_params_t p;
    char address[64], serial[16], vendor[GVBS_STRING_SIZE], model[GVBS_STRING_SIZE];
    char gain_unit[16], firmware[GVBS_STRING_SIZE], refuse_off[32];
    ArvGvFakeCamera *gv;
    ArvDevice       *dev;         // in-process: the ArvFakeDevice (our reference)
    ArvFakeCamera   *fake;
    GThread         *thread;
    atomic_bool      stop;
    int              lock_fd;     // flock on the address's lock file, -1 when none
    int              gvsp_fd;     // our GVSP sender (UDP, bound to address:0); -1 in-process

    GMutex lock;                 // front frame, stats, drop counter, render_error
    GCond  cond;
    uint8_t *front;              // packed wire-format frame ready to send
    size_t   front_cap, front_size;
    int      front_w, front_h;
    guint32  front_pf;
    bool     front_ready;
    rig_gv_camera_stats_t stats;
    guint16  block_id;           // of the last frame sent (GVSP)
    int      drop_triggers;
    char     render_error[512];

    GMutex    render_lock;       // the render callback and the scratch buffers below
    uint16_t *pix;
    size_t    pix_cap;
    uint8_t  *back;
    size_t    back_cap;
    uint64_t  n_renders;
};

// Registers (gv_render.c): 4- and 8-byte copies of the fake camera's memory.
guint32 rig_gv_reg_get(rig_gv_camera_t *g, guint32 addr);
double  rig_gv_reg_get_double(rig_gv_camera_t *g, guint32 addr);
void    rig_gv_reg_set_double(rig_gv_camera_t *g, guint32 addr, double d);
void    rig_gv_reg_set_string(rig_gv_camera_t *g, guint32 addr, const char *s, size_t size);
// Aravis's fill callback (ArvFakeCameraFillPattern; data: the server).
void     rig_gv_fill_cb(ArvBuffer *buffer, void *data, guint32 exposure_us_int, guint32 gain_raw, ArvPixelFormat pf);
// The render thread (data: the server).
gpointer rig_gv_render_thread(gpointer data);
// The next GVSP block id (g->lock held): 1, 2, ... 65535, 1, ...
guint16  rig_gv_next_block_id(rig_gv_camera_t *g);
// Send the published frame (gv_stream.c; render thread): it leaves `front` at once.
void     rig_gv_send_front(rig_gv_camera_t *g, const rig_frame_meta_t *m, guint32 pf);
// Our XML as a new string, or NULL with a message (gv_xml.c).
char      *rig_gv_xml_make(const char *gain_unit, const char *refuse_off);
// The ArvFakeDevice of an in-process server, with our XML.
ArvDevice *rig_gv_xml_fake_device(const char *serial, const char *xml_path, char *err, size_t errsize);
