// tests/test_rig_virtual_inprocess.c — the virtual rig with its camera served
// in-process (rig_virtual_options_t.serve = RIG_VIRTUAL_SERVE_INPROCESS; rig
// files: [rig] serve = inprocess): an Aravis fake device inside this process,
// opened by rig_camera_open_aravis("inprocess:SERIAL") and driven by the same
// Aravis camera code as over GigE Vision, without any socket. These tests take
// no lock on 127.0.0.1 and may run beside the GigE Vision tests.
//
// The frames are checked against the model's noise-free rendering with the
// statistic of tests/test_rig_virtual.c (tests/virtual_stats.h): mean difference
// ~0 within a few standard errors, mean (d^2 / var) ~1; a wrong state is
// rejected. Each frame shows the state at its trigger (a changed state is seen
// by the next capture), and the metadata are the camera's settings.
#define _GNU_SOURCE
#include <dirent.h>
#include <limits.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "model/model.h"
#include "rig/virtual/gv_camera.h"
#include "tests/fixtures.h"
#include "rig/rig.h"
#include "tests/test.h"
#include "tests/virtual_stats.h"

#define W 1280
#define H 1024

static const char *truth_path(void)
{
    static char p[PATH_MAX + 64];
    char top[PATH_MAX];
    if (!realpath(test_srcdir(), top)) snprintf(top, sizeof top, "%s", test_srcdir());
    snprintf(p, sizeof p, "%s/examples/virtual-truth.ini", top);
    return p;
}

static rig_virtual_t *open_inprocess(void)
{
    rig_virtual_options_t o = rig_virtual_defaults();
    o.serve = RIG_VIRTUAL_SERVE_INPROCESS;
    o.time_scale = 0.001;
    o.noise_seed = 91;
    rig_virtual_t *v = NULL;
    int rc = rig_virtual_open(&v, truth_path(), &o);
    CHECK_MSG(rc == 0, "rig_virtual_open: %d %s", rc, model_last_error());
    return v;
}

// Sockets among this process's open files.
static int count_sockets(void)
{
    DIR *d = opendir("/proc/self/fd");
    if (!d) return -1;
    int n = 0;
    struct dirent *e;
    while ((e = readdir(d))) {
        char path[300], target[256];
        snprintf(path, sizeof path, "/proc/self/fd/%s", e->d_name);
        ssize_t len = readlink(path, target, sizeof target - 1);
        if (len <= 0) continue;
        target[len] = 0;
        n += !strncmp(target, "socket:", 7);
    }
    closedir(d);
    return n;
}

static double realtime_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_REALTIME, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

static int capture(rig_camera_t *c, rig_frame_t *f)
{
    int rc = rig_camera_capture(c, 10.0, 0, f);
    CHECK_MSG(rc == 0, "capture: %d %s", rc, model_last_error());
    return rc;
}

TEST(virtual_inprocess_frame_matches_model)
{
    int sockets0 = count_sockets();
    rig_virtual_t *v = open_inprocess();
    rig_camera_t *c = NULL;
    float *E = malloc((size_t)W * H * sizeof(float)), *E2 = malloc((size_t)W * H * sizeof(float));
    rig_frame_t f = { 0 }, f2 = { 0 };
    if (!v || !E || !E2) goto done;
    CHECK(!strcmp(rig_virtual_camera_address(v), "inprocess:REFL-VIRT01"));
    rig_turntable_t *tt = rig_virtual_turntable(v);
    rig_lamps_t *lamps = rig_virtual_lamps(v);
    int rc = rig_camera_open_aravis(&c, rig_virtual_camera_address(v));
    CHECK_MSG(rc == 0, "open: %d %s", rc, model_last_error());
    if (rc) goto done;
    CHECK_CONTAINS(rig_camera_name(c), "serial REFL-VIRT01 at inprocess:REFL-VIRT01");
    CHECK(rig_camera_set_pixel_format(c, "Mono12") == 0);
    CHECK(rig_camera_set_exposure_us(c, 10000) == 0);
    CHECK(rig_camera_set_gain(c, 0) == 0);
    rig_frame_meta_t s;
    CHECK(rig_camera_settings(c, &s) == 0);
    CHECK(s.width == W && s.height == H && s.bits == 12 && !strcmp(s.pixel_format, "Mono12"));

    CHECK(rig_turntable_home(tt, 5) == 0);
    CHECK(rig_turntable_move_abs_deg(tt, 30, 5) == 0);
    rig_turntable_status_t st;
    CHECK(rig_turntable_status(tt, &st) == 0);
    CHECK_NEAR(st.angle_deg, 30, 0.02);
    CHECK(rig_lamps_set(lamps, 1u << 0) == 0);   // east

    double t0 = realtime_s();
    if (capture(c, &f)) goto done;
    double t1 = realtime_s();
    // Metadata: the camera's settings and identity.
    CHECK(f.meta.width == W && f.meta.height == H && f.meta.offset_x == 0 && f.meta.offset_y == 0);
    CHECK(f.meta.bits == 12 && !strcmp(f.meta.pixel_format, "Mono12"));
    CHECK_NEAR(f.meta.exposure_us, 10000, 1e-6);
    CHECK_NEAR(f.meta.gain, 0, 1e-9);
    CHECK_NEAR(f.meta.temperature_c, 35, 1e-9);
    CHECK(!strcmp(f.meta.serial, "REFL-VIRT01"));
    CHECK(!strcmp(f.meta.vendor, "refl"));
    CHECK(!strcmp(f.meta.model, "virtual rig camera"));
    CHECK(f.meta.system_time_s >= t0 - 1 && f.meta.system_time_s <= t1 + 1);
    CHECK_NEAR(1e-9 * (double)f.meta.timestamp_ns, f.meta.system_time_s, 5);

    rc = rig_virtual_expected(v, st.angle_deg, 1u << 0, 10000, 0, "Mono12", W, H, E);
    CHECK_MSG(rc == 0, "expected: %d %s", rc, model_last_error());
    vstat_t ok = vstat_compare(f.pix, E, (size_t)W * H, 100);
    printf("  in-process, right state: %ld lit pixels, mean diff %.4f DN (se %.4f), var ratio %.4f\n", ok.n,
           ok.mean, ok.se, ok.z2);
    CHECK(ok.n > 50000);
    CHECK_MSG(fabs(ok.mean) < 4 * ok.se + 0.02, "mean difference %.4f DN, standard error %.4f", ok.mean, ok.se);
    CHECK_NEAR(ok.z2, 1.0, 0.1);
    CHECK(rig_virtual_expected(v, st.angle_deg + 1, 1u << 0, 10000, 0, "Mono12", W, H, E2) == 0);
    vstat_t bad = vstat_compare(f.pix, E2, (size_t)W * H, 100);
    printf("  in-process, wrong angle (+1 deg): var ratio %.2f\n", bad.z2);
    CHECK(bad.z2 > 3);

    // The next frame: new noise (another seed), the same state, the next frame id.
    if (capture(c, &f2)) goto done;
    CHECK(f2.meta.frame_id == f.meta.frame_id + 1);
    long same = 0;
    for (size_t i = 0; i < (size_t)W * H; i++) same += f.pix[i] == f2.pix[i];
    CHECK(same < (long)W * H * 9 / 10);
    vstat_t ok2 = vstat_compare(f2.pix, E, (size_t)W * H, 100);
    CHECK(fabs(ok2.mean) < 4 * ok2.se + 0.02);
    CHECK_NEAR(ok2.z2, 1.0, 0.1);
    rig_frame_free(&f2);

    // A changed state (another angle, another lamp) shows in the very next
    // frame: no buffer filled before the trigger is handed out.
    CHECK(rig_turntable_move_abs_deg(tt, 50, 5) == 0);
    CHECK(rig_turntable_status(tt, &st) == 0);
    CHECK(rig_lamps_set(lamps, 1u << 3) == 0);   // north
    if (capture(c, &f2)) goto done;
    CHECK(rig_virtual_expected(v, st.angle_deg, 1u << 3, 10000, 0, "Mono12", W, H, E2) == 0);
    vstat_t moved = vstat_compare(f2.pix, E2, (size_t)W * H, 100);
    vstat_t old = vstat_compare(f2.pix, E, (size_t)W * H, 100);
    printf("  in-process, changed state: var ratio %.4f (old state: %.2f)\n", moved.z2, old.z2);
    CHECK(moved.n > 20000);
    CHECK(fabs(moved.mean) < 4 * moved.se + 0.02);
    CHECK_NEAR(moved.z2, 1.0, 0.1);
    CHECK(old.z2 > 3);
    rig_frame_free(&f2);

    // A region (the payload changes, the stream restarts) and Mono16 (12-bit values << 4).
    CHECK(rig_camera_set_region(c, 0, 0, 640, 512) == 0);
    CHECK(rig_camera_set_pixel_format(c, "Mono16") == 0);
    if (capture(c, &f2)) goto done;
    CHECK(f2.meta.width == 640 && f2.meta.height == 512 && f2.meta.bits == 16);
    CHECK(rig_virtual_expected(v, st.angle_deg, 1u << 3, 10000, 0, "Mono12", 640, 512, E2) == 0);
    long not16 = 0;
    double m16 = 0, m12 = 0;
    for (size_t i = 0; i < 640 * 512; i++) {
        not16 += f2.pix[i] % 16 != 0;
        m16 += f2.pix[i];
        m12 += E2[i];
    }
    CHECK(not16 == 0);
    CHECK_REL(m16 / 16, m12, 2e-3);
    rig_frame_free(&f2);

    // No socket was opened for any of this.
    CHECK_MSG(count_sockets() == sockets0, "sockets: %d before, %d now", sockets0, count_sockets());

done:
    rig_frame_free(&f);
    rig_frame_free(&f2);
    rig_camera_close(c);
    rig_virtual_close(v);
    free(E);
    free(E2);
}

// Frames ahead of an angle: once two angles had the same sequence of frames
// (lamps and exposures), the pre-render thread computes the frames it
// predicts at the next angle while the stage moves there. A rig with
// speculation and one without (the same truth, noise seed and sequence over
// three angles) must hand out the very same frames, pixel for pixel, and the
// first must have taken the third angle's frames from speculation (a frame is
// a function of its inputs only).
enum { AHEAD_ANGLES = 3, AHEAD_FRAMES = 4 * AHEAD_ANGLES };

static int ahead_sequence(rig_virtual_t *v, uint16_t *out[AHEAD_FRAMES], long ahead[AHEAD_ANGLES])
{
    rig_camera_t *c = NULL;
    int rc = rig_camera_open_aravis(&c, rig_virtual_camera_address(v));
    CHECK_MSG(rc == 0, "open: %d %s", rc, model_last_error());
    if (rc) return rc;
    rig_turntable_t *tt = rig_virtual_turntable(v);
    rig_lamps_t *lamps = rig_virtual_lamps(v);
    CHECK(rig_camera_set_pixel_format(c, "Mono12") == 0);
    CHECK(rig_turntable_home(tt, 30) == 0);
    int k = 0;
    for (int a = 0; a < AHEAD_ANGLES && !rc; a++) {
        long before = rig_virtual_frames_ahead(v);
        // the simulated stage knows where it will stand while it moves
        CHECK(rig_turntable_start_move_abs_deg(tt, 10 + 15 * a) == 0);
        double dest = NAN;
        CHECK(rig_virtual_destination(v, &dest));
        CHECK_NEAR(dest, 10 + 15 * a, 0.02);
        CHECK(rig_turntable_wait(tt, 30) == 0);
        rig_turntable_status_t st;
        CHECK(rig_turntable_status(tt, &st) == 0);
        CHECK(st.angle_deg == dest);
        CHECK(!rig_virtual_destination(v, NULL));   // idle
        for (int l = 0; l < 2 && !rc; l++) {
            CHECK(rig_lamps_set(lamps, 1u << l) == 0);
            for (int e = 0; e < 2 && !rc; e++) {
                CHECK(rig_camera_set_exposure_us(c, e ? 6000 : 2000) == 0);
                rig_frame_t f = { 0 };
                if ((rc = capture(c, &f))) break;
                out[k++] = f.pix;   // keep the pixels
            }
        }
        ahead[a] = rig_virtual_frames_ahead(v) - before;
    }
    rig_lamps_all_off(lamps);
    rig_camera_close(c);
    return rc;
}

TEST(virtual_inprocess_frames_ahead_of_an_angle)
{
    uint16_t *fa[AHEAD_FRAMES] = { 0 }, *fb[AHEAD_FRAMES] = { 0 };
    rig_virtual_t *va = NULL, *vb = NULL;
    for (int pass = 0; pass < 2; pass++) {
        rig_virtual_options_t o = rig_virtual_defaults();
        o.serve = RIG_VIRTUAL_SERVE_INPROCESS;
        o.time_scale = 0.3;   // a 15 deg move: 0.73 s
        o.noise_seed = 7;
        o.serial = pass ? "REFL-AHEAD-B" : "REFL-AHEAD-A";
        o.prerender = pass ? 0 : 1;
        rig_virtual_t **v = pass ? &vb : &va;
        int rc = rig_virtual_open(v, truth_path(), &o);
        CHECK_MSG(rc == 0, "rig_virtual_open: %d %s", rc, model_last_error());
        if (rc) goto done;
        long ahead[AHEAD_ANGLES] = { 0 };
        if (ahead_sequence(*v, pass ? fb : fa, ahead)) goto done;
        printf("  prerender %d: frames computed ahead of their triggers at each angle: %ld %ld %ld of 4\n",
               o.prerender, ahead[0], ahead[1], ahead[2]);
        if (pass) CHECK(ahead[0] + ahead[1] + ahead[2] == 0);
#ifdef __SANITIZE_ADDRESS__
        else CHECK_MSG(ahead[2] >= 1, "no frame of the third angle came from speculation");   // slower renderer
#else
        else CHECK_MSG(ahead[2] == 4, "only %ld frames of the third angle came from speculation", ahead[2]);
#endif
    }
    for (int k = 0; k < AHEAD_FRAMES; k++) {
        long diff = 0;
        for (size_t i = 0; fa[k] && fb[k] && i < (size_t)W * H; i++) diff += fa[k][i] != fb[k][i];
        CHECK_MSG(fa[k] && fb[k] && diff == 0, "frame %d: %ld pixels differ", k, diff);
    }
    // a bad option is refused
    rig_virtual_options_t o = rig_virtual_defaults();
    o.serve = RIG_VIRTUAL_SERVE_INPROCESS;
    o.prerender = 3;
    rig_virtual_t *vc = NULL;
    CHECK(rig_virtual_open(&vc, truth_path(), &o) == RIG_ERR_INVALID);
    CHECK_CONTAINS(model_last_error(), "prerender 3 outside 0..2");
done:
    for (int k = 0; k < AHEAD_FRAMES; k++) {
        free(fa[k]);
        free(fb[k]);
    }
    rig_virtual_close(va);
    rig_virtual_close(vb);
}

// Opening: unknown serials fail without any discovery; one in-process camera
// per serial; a camera that outlives its virtual rig reports it.
TEST(virtual_inprocess_lifecycle)
{
    rig_camera_t *c = NULL;
    CHECK(rig_camera_open_aravis(&c, "inprocess:NOPE") == RIG_ERR_NO_DEVICE);
    CHECK(c == NULL);
    CHECK_CONTAINS(model_last_error(), "no in-process camera with serial 'NOPE'");
    rig_virtual_t *v = open_inprocess(), *v2 = NULL;
    if (!v) return;
    rig_virtual_options_t o = rig_virtual_defaults();
    o.serve = RIG_VIRTUAL_SERVE_INPROCESS;
    CHECK(rig_virtual_open(&v2, truth_path(), &o) == RIG_ERR_BUSY);
    CHECK(v2 == NULL);
    CHECK_CONTAINS(model_last_error(), "already serves an in-process camera with serial REFL-VIRT01");
    o.serve = (rig_virtual_serve_t)7;
    CHECK(rig_virtual_open(&v2, truth_path(), &o) == RIG_ERR_INVALID);
    CHECK_CONTAINS(model_last_error(), "serve = 7");

    int rc = rig_camera_open_aravis(&c, rig_virtual_camera_address(v));
    CHECK_MSG(rc == 0, "open: %s", model_last_error());
    rig_frame_t f = { 0 };
    if (!rc) {
        // Acquisition started by a capture, then the rig goes away first.
        CHECK(rig_lamps_set(rig_virtual_lamps(v), 1) == 0);
        CHECK(capture(c, &f) == 0);
        rig_frame_free(&f);
    }
    rig_virtual_close(v);
    if (!rc) {
        CHECK(rig_camera_capture(c, 1, 0, &f) == RIG_ERR_DISCONNECTED);
        CHECK_CONTAINS(model_last_error(), "close this camera before the virtual rig");
        CHECK(rig_camera_set_exposure_us(c, 1000) == RIG_ERR_DISCONNECTED);
    }
    rig_camera_close(c);
    // The serial is free again.
    v = open_inprocess();
    CHECK(v != NULL);
    rig_virtual_close(v);
}

// The in-process server on its own (rig/virtual/gv_camera.h) with a known pattern:
// exact pixels through the Aravis path, one render per trigger; a failed
// render or a dropped trigger gives no frame (the capture times out, its
// buffer waits for the next trigger) and the next capture works again.
typedef struct {
    int fail;   // renders left to fail
} pattern_t;

static int pattern_render(void *ctx, const rig_frame_meta_t *m, uint16_t *pix)
{
    pattern_t *p = ctx;
    if (p->fail > 0) {
        p->fail--;
        return rig_fail(RIG_ERR_IO, "pattern: failing on purpose");
    }
    for (int y = 0; y < m->height; y++)
        for (int x = 0; x < m->width; x++)
            pix[(size_t)y * m->width + x] = (uint16_t)((x + 3 * y + 7 * (int)m->frame_id) & 0xfff);
    return 0;
}

static bool pattern_ok(const rig_frame_t *f, uint64_t render)
{
    for (int y = 0; y < f->meta.height; y++)
        for (int x = 0; x < f->meta.width; x++)
            if (f->pix[(size_t)y * f->meta.width + x] != (uint16_t)((x + 3 * y + 7 * (int)render) & 0xfff))
                return false;
    return true;
}

TEST(virtual_inprocess_server_pattern_and_faults)
{
    pattern_t pat = { 0 };
    rig_gv_camera_params_t p = rig_gv_camera_defaults();
    p.inprocess = true;
    p.serial = "REFL-IPT1";
    p.sensor_width = 320;
    p.sensor_height = 200;
    p.render = pattern_render;
    p.render_ctx = &pat;
    rig_gv_camera_t *g = NULL;
    rig_camera_t *c = NULL;
    rig_frame_t f = { 0 };
    int rc = rig_gv_camera_start(&g, &p);
    CHECK_MSG(rc == 0, "start: %s", model_last_error());
    if (rc) return;
    rc = rig_camera_open_aravis(&c, "inprocess:REFL-IPT1");
    CHECK_MSG(rc == 0, "open: %s", model_last_error());
    if (rc) goto done;
    CHECK(rig_camera_set_pixel_format(c, "Mono12") == 0);
    for (int k = 1; k <= 3; k++) {
        if (capture(c, &f)) goto done;
        CHECK(f.meta.width == 320 && f.meta.height == 200 && f.meta.bits == 12);
        CHECK_MSG(pattern_ok(&f, (uint64_t)k), "frame %d is not render %d", k, k);
        rig_frame_free(&f);
    }
    // A failed render: no frame; the waiting buffer takes the next trigger's frame.
    pat.fail = 1;
    CHECK(rig_camera_capture(c, 0.3, 0, &f) == RIG_ERR_TIMEOUT);
    CHECK_CONTAINS(model_last_error(), "no complete frame after 1 software trigger");
    char msg[256];
    rig_gv_camera_last_render_error(g, msg, sizeof msg);
    CHECK_CONTAINS(msg, "failing on purpose");
    if (capture(c, &f)) goto done;
    CHECK(pattern_ok(&f, 5));   // render 4 failed, render 5 answers the second trigger
    rig_frame_free(&f);
    // A dropped trigger, then retries: the second attempt gets its frame.
    rig_gv_camera_drop_triggers(g, 1);
    rc = rig_camera_capture(c, 0.3, 1, &f);
    CHECK_MSG(rc == 0, "capture with a retry: %s", model_last_error());
    if (!rc) CHECK(pattern_ok(&f, 6));
    rig_frame_free(&f);
    rig_gv_camera_stats_t st;
    rig_gv_camera_stats(g, &st);
    CHECK(st.triggers == 7 && st.frames_rendered == 5 && st.frames_sent == 5);
    CHECK(st.render_errors == 1 && st.dropped_triggers == 1 && st.late_frames == 0);
    // A second in-process server with the same serial is refused.
    rig_gv_camera_t *g2 = NULL;
    CHECK(rig_gv_camera_start(&g2, &p) == RIG_ERR_BUSY && g2 == NULL);
done:
    rig_frame_free(&f);
    rig_camera_close(c);
    rig_gv_camera_stop(g);
}

// In-process (Aravis's fake stream, whose buffers report no size: the payload
// is used): packed formats unpack bit-exactly too.
TEST(virtual_inprocess_packed_formats)
{
    fx_pattern_ctx_t *ctx = fx_pattern_ctx_new();
    rig_gv_camera_params_t p = rig_gv_camera_defaults();
    p.inprocess = true;
    p.serial = "REFL-IPT2";
    p.sensor_width = 320;
    p.sensor_height = 200;
    p.render = fx_render_pattern;
    p.render_ctx = ctx;
    rig_gv_camera_t *g = NULL;
    rig_camera_t *c = NULL;
    int rc = rig_gv_camera_start(&g, &p);
    CHECK_MSG(rc == 0, "start: %s", model_last_error());
    if (rc) goto done;
    rc = rig_camera_open_aravis(&c, "inprocess:REFL-IPT2");
    CHECK_MSG(rc == 0, "open: %s", model_last_error());
    if (rc) goto done;
    CHECK(rig_camera_set_exposure_us(c, 4000) == 0);
    const char *fmts[] = { "Mono10p", "Mono12p", "Mono12Packed", "Mono10" };
    const int bits[] = { 10, 12, 12, 10 };
    for (int k = 0; k < 4; k++) {
        rc = rig_camera_set_pixel_format(c, fmts[k]);
        CHECK_MSG(rc == 0, "set %s: %d %s", fmts[k], rc, model_last_error());
        if (rc) continue;
        rig_frame_t f;
        rc = rig_camera_capture(c, 2.0, 1, &f);
        CHECK_MSG(rc == 0, "capture %s: %d %s", fmts[k], rc, model_last_error());
        if (rc) continue;
        CHECK(!strcmp(f.meta.pixel_format, fmts[k]) && f.meta.bits == bits[k]);
        CHECK(f.meta.width == 320 && f.meta.height == 200);
        long bad = fx_pattern_mismatches(&f);
        CHECK_MSG(bad == 0, "%s: %ld pixels differ from the pattern", fmts[k], bad);
        rig_frame_free(&f);
    }
    // 3 pixels of Mono12p take 5 bytes; the camera's PayloadSize (Width *
    // Height * 12 / 8) says 4: a buffer of the wrong size is a protocol error.
    CHECK(rig_camera_set_pixel_format(c, "Mono12p") == 0);
    CHECK(rig_camera_set_region(c, 0, 0, 3, 1) == 0);
    rig_frame_t f;
    rc = rig_camera_capture(c, 1.0, 0, &f);
    CHECK_MSG(rc == RIG_ERR_PROTOCOL, "capture of a short buffer: %d %s", rc, model_last_error());
    CHECK_CONTAINS(model_last_error(), "REFL-IPT2");
    CHECK_CONTAINS(model_last_error(), "frame of 4 bytes for a 3x1 Mono12p image (5 bytes expected)");
    CHECK(f.pix == NULL);
done:
    rig_camera_close(c);
    rig_gv_camera_stop(g);
    fx_pattern_ctx_free(ctx);
}

// Rig files: [rig] serve = inprocess, its errors, and refl rig on it.
TEST(virtual_inprocess_rig_file_and_cli)
{
    char text[PATH_MAX + 512];
    snprintf(text, sizeof text, "[rig]\nbackend = virtual\ntruth = %s\nserve = inprocess\ntime_scale = 0.01\n",
             truth_path());
    const char *rig = test_write("inprocess-rig.ini", text);
    rig_t *r = NULL;
    int rc = rig_open(&r, rig);
    CHECK_MSG(rc == 0, "rig_open: %s", model_last_error());
    if (r) {
        CHECK(r->virt && r->camera);
        CHECK(!strcmp(rig_virtual_camera_address(r->virt), "inprocess:REFL-VIRT01"));
        rig_frame_meta_t m;
        CHECK(rig_camera_settings(r->camera, &m) == 0);
        CHECK(!strcmp(m.serial, "REFL-VIRT01"));
    }
    rig_close(r);

    static const struct { const char *extra, *want; } bad[] = {
        { "serve = udp\n", ":4: [rig] serve: 'udp' is not gige (GigE Vision on the address) or inprocess" },
        { "serve = inprocess\naddress = 127.0.0.1\n", ":5: [rig] address applies to serve = gige only" },
        { "serve = inprocess\nbusy_wait_s = 5\n", ":5: [rig] busy_wait_s applies to serve = gige only" },
    };
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        snprintf(text, sizeof text, "[rig]\nbackend = virtual\ntruth = %s\n%s", truth_path(), bad[i].extra);
        const char *path = test_write("bad-inprocess.ini", text);
        r = (rig_t *)1;
        CHECK(rig_open(&r, path) == RIG_ERR_INVALID);
        CHECK(r == NULL);
        CHECK_CONTAINS(model_last_error(), path);
        CHECK_CONTAINS(model_last_error(), bad[i].want);
    }

    // refl rig on it: identify, snap (a lit Mono12 frame), serve refused.
    char *out = NULL, *err = NULL;
    const char *argv_id[] = { test_refl(), "rig", "--rig", rig, "identify", NULL };
    rc = test_run(argv_id, 60, &out, &err);
    CHECK_MSG(rc == 0, "identify: %d %s", rc, err);
    CHECK_CONTAINS(out, "virtual_camera_address: inprocess:REFL-VIRT01");
    CHECK_CONTAINS(out, "camera_serial: REFL-VIRT01");
    free(out);
    free(err);
    const char *png = test_path("inprocess-snap.png");
    const char *argv_snap[] = { test_refl(), "rig", "--rig", rig, "snap", "-o", png, "--angle", "30", "--lamps",
                                "east", "--pixel-format", "Mono12", "--exposure-us", "20000", NULL };
    rc = test_run(argv_snap, 60, &out, &err);
    CHECK_MSG(rc == 0, "snap: %d %s", rc, err);
    CHECK_CONTAINS(out, "wrote ");
    free(out);
    free(err);
    int w = 0, h = 0;
    uint16_t *pix = NULL;
    CHECK(model_png_read(png, &w, &h, &pix));
    CHECK(w == W && h == H);
    long lit = 0, over = 0, dark = 0;
    for (long i = 0; pix && i < (long)w * h; i++) {
        lit += pix[i] > 200;
        over += pix[i] > 4095;
        dark += pix[i] < 40;
    }
    free(pix);
    CHECK_MSG(lit > (long)W * H / 20, "only %ld lit pixels", lit);
    CHECK(over == 0 && dark == 0);   // Mono12, above the 64 DN offset less noise
    const char *argv_serve[] = { test_refl(), "rig", "--rig", rig, "serve", NULL };
    rc = test_run(argv_serve, 60, &out, &err);
    CHECK(rc == 1);
    CHECK_CONTAINS(err, "serves its camera in-process");
    free(out);
    free(err);
}
