// tests/fixtures.h — setup that several tests share, instead of copies in
// each: scenes, materials, lamps and pinhole cameras for the renderer
// (tests/test_model_render.c, tests/test_model_sphere.c); the fast simulated
// stage and the simulated APT controller (tests/test_rig_turntable.c); and a
// virtual GigE Vision camera serving a test pattern on 127.0.0.1 with the
// backend's client opened on it (tests/test_rig_camera_aravis.c).
//
// A fixture that cannot be set up fails a CHECK saying why.
#pragma once

#include <pthread.h>
#include <stdatomic.h>
#include <stdbool.h>

#include "model/model.h"
#include "rig/virtual/gv_camera.h"
#include "rig/rig.h"
#include "tests/apt_sim.h"

// ---------------------------------------------------------------------------
// Scenes, materials, lamps, pinhole cameras

// Parsed from text, as "test.d3d", "test_materials.ini", "test_lamps.ini";
// NULL (and the error on stderr) when the text is wrong.
model_scene_t     *fx_scene_text(const char *d3d);
model_materials_t *fx_materials_text(const char *ini);
model_lamps_t     *fx_lamps_text(const char *ini);

// A square plane z = 0 of half-size h (face 1), material "plane", and extra
// D3D vertices and faces (either may be NULL). The caller frees it.
char *fx_plane_d3d(double h, const char *extra_vertices, const char *extra_faces);
// A box [-50,50]^2 x [0,80] without bottom, vertices 5..12, material "box":
// the extras of fx_plane_d3d.
extern const char fx_box_vertices[], fx_box_faces[];

// A pinhole camera at C looking at target (image y down, world z up), focal
// f px, principal point at the image centre; R (world -> camera rows) out.
typedef struct {
    model_camera_t *cam;
    double R[9];
    model_vec3_t C;
    double f, cx, cy;
    int W, H;
} fx_pinhole_t;

bool fx_pinhole_look(fx_pinhole_t *p, int W, int H, double f, model_vec3_t C, model_vec3_t target);
// The camera alone (NULL on failure).
model_camera_t *fx_pinhole_camera(int W, int H, double f, model_vec3_t C, model_vec3_t target);
// Analytic unit world ray of pixel (x, y).
model_vec3_t fx_pinhole_ray(const fx_pinhole_t *p, double x, double y);

// A scene to render: the scene of d3d (taken: freed by fx_render_close), its
// materials (may be NULL: none resolved) and lamps, a pinhole camera looking
// at target, the tracer and the resolved materials.
#define FX_MAX_MATERIALS 8
typedef struct {
    char *d3d;
    model_scene_t *s;
    model_materials_t *m;
    model_lamps_t *l;
    fx_pinhole_t ph;
    model_tracer_t *t;
    const model_material_t *mres[FX_MAX_MATERIALS];
} fx_render_t;

// false (after a failed CHECK) when any part could not be made; close anyway.
bool fx_render_open(fx_render_t *f, char *d3d, const char *materials, const char *lamps, int W, int H,
                    double focal, model_vec3_t C, model_vec3_t target);
void fx_render_close(fx_render_t *f);

// ---------------------------------------------------------------------------
// Turntables

// The simulated stage 100 times faster than life (10 s of stage time = 0.1 s),
// homing in 5 s of stage time, 0.001 deg of position noise.
rig_turntable_sim_params_t fx_fast_sim(void);

// The simulated APT controller(s) (tests/apt_sim.c) with the USB device of
// tests/data/k10cr1.umockdev: NULL after a failed CHECK.
apt_sim_t *fx_apt_sim_start(const apt_sim_device_t *devs, int n);
// Open the one simulated APT stage and home it (NULL after a failed CHECK).
rig_turntable_t *fx_apt_open_homed(void);

// ---------------------------------------------------------------------------
// A virtual GigE Vision camera on 127.0.0.1 serving a test pattern

#define FX_GV_ADDR "127.0.0.1"

// The pattern's value at a sensor position for the settings.
uint16_t fx_pattern(int sx, int sy, double exposure_us, double gain_db, int bits);
// Pixels of f that differ from the pattern for its settings.
long fx_pattern_mismatches(const rig_frame_t *f);

// The pattern renderer's state.
typedef struct {
    pthread_mutex_t  lock;
    rig_frame_meta_t last;        // settings of the last render
    int              n;           // renders
    atomic_int       fail;        // >0: the next renders fail
    atomic_int       sleep_ms;    // emulate an expensive imaging model
} fx_pattern_ctx_t;

fx_pattern_ctx_t *fx_pattern_ctx_new(void);
void fx_pattern_ctx_free(fx_pattern_ctx_t *ctx);
// The render callback of rig_gv_camera_params_t (render_ctx: an fx_pattern_ctx_t).
int fx_render_pattern(void *ctx, const rig_frame_meta_t *m, uint16_t *pix);

// The camera lock of tests/test.h held, the pattern server "TEST-0042"
// (vendor "refl-test", model "pattern cam") started on FX_GV_ADDR, and, when
// asked, the backend's camera opened on it.
typedef struct {
    int session;                  // test_camera_lock()
    fx_pattern_ctx_t *ctx;
    rig_gv_camera_t *g;           // NULL when stopped
    rig_camera_t *c;              // NULL when not opened or closed
} fx_gv_t;

// false (after a failed CHECK) when the server or the client could not be
// had; close anyway.
bool fx_gv_open(fx_gv_t *f, bool open_camera);

// What fn(r) prints on stdout (caught in a file of the test's directory): its
// text (caller frees) and fn's return value in *rc (e.g. rig_cmd_status).
char *fx_stdout_of(int (*fn)(rig_t *), rig_t *r, int *rc);
void fx_gv_close(fx_gv_t *f);

// A variant of an example truth file (examples/FILE, e.g. "virtual-truth.ini"):
// the replacements rep (pairs from, to; NULL-ended; rep may be NULL) made in
// turn, each of which must be found (a failed CHECK otherwise), the relative
// paths ("scene = ...", "model = camera...") made absolute, then extra (may
// be NULL) appended as it is; written as NAME in the test's directory. Returns
// its path (test_path's buffer: copy it to keep it), "" when FILE is unreadable.
const char *fx_truth_variant(const char *file, const char *name, const char *const *rep, const char *extra);
