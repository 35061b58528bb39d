// tests/test_rig_cameras.c — several cameras in one rig: [camera NAME]
// sections (rig/config.c), `refl rig status` and `refl rig snap` of every
// camera (rig/cmd_rig.c). The cameras are pattern servers of tests/fixtures.h
// served in this process (rig_gv_camera_params_t.inprocess, opened as
// "inprocess:SERIAL"): no network.
#define _GNU_SOURCE
#include <fcntl.h>
#include <sys/stat.h>
#include <glib.h>
#include <sqlite3.h>
#include <limits.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "model/model.h"
#include "calib/geometry/geometry.h"
#include "rig/virtual/gv_camera.h"
#include "rig/rig.h"
#include "tests/fixtures.h"
#include "tests/test.h"
#include "tests/virtual_stats.h"

// Parse errors of camera sections: file:line and what to write.
TEST(rigcams_parse_errors)
{
    static const struct {
        const char *text, *want;
    } cases[] = {
        { "[camera left]\nbackend = aravis\nserial = A\n[camera left]\nbackend = aravis\nserial = B\n",
          NULL },   // the INI parser or ours: a repeated section is an error either way
        { "[camera a/b]\nbackend = aravis\nserial = A\n", ":1: [camera a/b]: 'a/b' is not a camera name" },
        { "[camera all]\nbackend = aravis\nserial = A\n", ":1: [camera all]: 'all' is not a camera name" },
        { "[camera left]\nbackend = aravis\nserial = A\n[camera right]\nbackend = aravis\nserial = A\n",
          ":6: [camera right]: 'A' already identifies [camera left] (line 1)" },
        { "[camera]\nbackend = aravis\nserial = A\n[camera camera]\nbackend = aravis\nserial = B\n",
          ":4: [camera camera]: camera 'camera' is already [camera] (line 1)" },
        { "[camera right]\nbackend = aravis\nexposure_us = 5\n", ":1: [camera right] does not say which camera" },
        { "[camera right]\nbackend = aravis\nserial = B\npixel_format = Mono9\n",
          ":4: [camera right] pixel_format: 'Mono9' is not" },
        { "[camera right]\nbackend = aravis\nserial = B\nroi = 1\n", ":4: [camera right]: unknown key 'roi'" },
    };
    bool q = model_error_quiet_thread(true);
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
        int rc = rig_config_parse(cases[i].text, strlen(cases[i].text), "cams.ini");
        CHECK_MSG(rc == RIG_ERR_INVALID, "case %zu accepted", i);
        if (cases[i].want) CHECK_CONTAINS(model_last_error(), cases[i].want);
    }
    const char *ok = "[camera left]\nbackend = aravis\nserial = A\n[camera right-2]\nbackend = aravis\n"
                     "address = 127.0.0.9\n";
    CHECK(rig_config_parse(ok, strlen(ok), "cams.ini") == 0);
    model_error_quiet_thread(q);
}

// Two pattern cameras in this process, serials CAM-L and CAM-R (sensors of
// different sizes).
typedef struct {
    fx_pattern_ctx_t *ctx[2];
    rig_gv_camera_t  *g[2];
} two_t;

static bool two_start(two_t *t)
{
    static const char *const serials[2] = { "CAM-L", "CAM-R" };
    for (int i = 0; i < 2; i++) {
        t->ctx[i] = fx_pattern_ctx_new();
        rig_gv_camera_params_t p = rig_gv_camera_defaults();
        p.inprocess = true;
        p.serial = serials[i];
        p.render = fx_render_pattern;
        p.render_ctx = t->ctx[i];
        p.sensor_width = i ? 96 : 64;
        p.sensor_height = i ? 40 : 48;
        int rc = rig_gv_camera_start(&t->g[i], &p);
        CHECK_MSG(rc == 0, "camera %s: %d %s", serials[i], rc, model_last_error());
        if (rc) return false;
    }
    return true;
}

static void two_stop(two_t *t)
{
    for (int i = 0; i < 2; i++) {
        rig_gv_camera_stop(t->g[i]);
        if (t->ctx[i]) fx_pattern_ctx_free(t->ctx[i]);
    }
}

static const char two_rig[] =
    "[turntable]\nbackend = sim\ntime_scale = 0.001\nposition_noise_deg = 0\n"
    "[lamp key]\nbackend = sim\n"
    "[camera left]\nbackend = aravis\nserial = inprocess:CAM-L\nexposure_us = 1500\npixel_format = Mono16\n"
    "[camera right]\nbackend = aravis\nserial = inprocess:CAM-R\nexposure_us = 2500\npixel_format = Mono8\n";

// rig_open opens both cameras in file order with their own defaults; status
// lists each.
TEST(rigcams_open_status)
{
    two_t t = { 0 };
    if (!two_start(&t)) goto done;
    const char *path = test_write("two.ini", two_rig);
    rig_t *r = NULL;
    int rc = rig_open(&r, path);
    CHECK_MSG(rc == 0, "rig_open: %d %s", rc, model_last_error());
    if (!r) goto done;
    CHECK(r->ncameras == 2 && r->camera == r->cameras[0]);
    CHECK(!strcmp(r->camera_names[0], "left") && !strcmp(r->camera_names[1], "right"));
    CHECK(rig_camera_find(r, "right") == 1 && rig_camera_find(r, "left") == 0 && rig_camera_find(r, "x") < 0);
    CHECK_NEAR(r->exposure_us, 1500, 1e-9);   // the first camera's defaults
    rig_frame_meta_t m[2];
    for (int i = 0; i < 2; i++) CHECK(rig_camera_settings(r->cameras[i], &m[i]) == 0);
    CHECK(!strcmp(m[0].serial, "CAM-L") && !strcmp(m[1].serial, "CAM-R"));
    CHECK_NEAR(m[0].exposure_us, 1500, 1e-6);
    CHECK_NEAR(m[1].exposure_us, 2500, 1e-6);
    CHECK(!strcmp(m[1].pixel_format, "Mono8") && !strcmp(m[0].pixel_format, "Mono16"));
    char *out = fx_stdout_of(rig_cmd_status, r, &rc);
    CHECK(rc == 0);
    CHECK_CONTAINS(out, "cameras: 2\ncamera_name: left\ncamera: ");
    CHECK_CONTAINS(out, "camera_serial: CAM-L\n");
    CHECK_CONTAINS(out, "camera_name: right\ncamera: ");
    CHECK_CONTAINS(out, "camera_serial: CAM-R\n");
    CHECK_CONTAINS(out, "camera_region: 96 x 40 at (0, 0)");
    CHECK(strstr(out, "CAM-L") < strstr(out, "CAM-R"));
    free(out);
    // The second camera stops answering: status still lists both, names it and fails.
    rig_gv_camera_stop(t.g[1]);
    t.g[1] = NULL;
    bool q = model_error_quiet_thread(true);
    out = fx_stdout_of(rig_cmd_status, r, &rc);
    model_error_quiet_thread(q);
    CHECK(rc != 0);
    CHECK_CONTAINS(out, "camera_serial: CAM-L\n");
    CHECK_CONTAINS(out, "camera_name: right\ncamera: aravis");
    CHECK_CONTAINS(model_last_error(), "refl rig status: the camera right did not answer");
    free(out);
    rig_close(r);
done:
    two_stop(&t);
}

static int snap(const char *rig, const char *out, const char *camera)
{
    const char *argv[12] = { "rig", "--rig", rig, "snap", "-o", out, "--lamps", "key", "--angle", "15" };
    int n = 10;
    if (camera) {
        argv[n++] = "--camera";
        argv[n++] = camera;
    }
    fflush(stdout);
    int saved = dup(1), fd = open(test_path("snap.txt"), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    dup2(fd, 1);
    close(fd);
    int rc = rig_cmd(n, (char **)argv);
    fflush(stdout);
    dup2(saved, 1);
    close(saved);
    return rc;
}

static void check_png(const char *path, const char *serial, int w, int h, const char *name)
{
    int W = 0, H = 0;
    uint16_t *pix = NULL;
    model_meta_t *meta = model_meta_new();
    CHECK_MSG(model_png_read_meta(path, &W, &H, &pix, meta), "%s: %s", path, model_last_error());
    CHECK(W == w && H == h);
    const char *s = model_meta_get(meta, "camera_serial"), *n = model_meta_get(meta, "camera_name");
    const char *lamps = model_meta_get(meta, "lamps_on"), *ang = model_meta_get(meta, "turntable_commanded_deg");
    CHECK(s && !strcmp(s, serial));
    CHECK(n && !strncmp(n, name, strlen(name)) && n[strlen(name)] == ' ');
    CHECK(lamps && !strcmp(lamps, "key"));
    CHECK(ang && !strcmp(ang, "15"));
    free(pix);
    model_meta_free(meta);
}

// snap: every camera (OUT_NAME.png each) at one angle and lamp state, or the
// one named by --camera (OUT.png); an unknown name is an error naming the
// cameras.
TEST(rigcams_snap)
{
    two_t t = { 0 };
    if (!two_start(&t)) goto done;
    char *rig = strdup(test_write("two.ini", two_rig));
    int rc = snap(rig, test_path("all.png"), NULL);
    CHECK_MSG(rc == 0, "snap all: %d %s", rc, model_last_error());
    check_png(test_path("all_left.png"), "CAM-L", 64, 48, "left");
    check_png(test_path("all_right.png"), "CAM-R", 96, 40, "right");
    CHECK(access(test_path("all.png"), F_OK) != 0);
    char *txt = model_read_file(test_path("snap.txt"), NULL);
    CHECK(txt && strstr(txt, "wrote ") && strstr(txt, "all_left.png") && strstr(txt, "all_right.png"));
    free(txt);

    rc = snap(rig, test_path("one.png"), "right");
    CHECK_MSG(rc == 0, "snap --camera right: %d %s", rc, model_last_error());
    check_png(test_path("one.png"), "CAM-R", 96, 40, "right");
    CHECK(access(test_path("one_left.png"), F_OK) != 0 && access(test_path("one_right.png"), F_OK) != 0);

    bool q = model_error_quiet_thread(true);
    rc = snap(rig, test_path("none.png"), "middle");
    model_error_quiet_thread(q);
    CHECK(rc == 1);
    CHECK_CONTAINS(model_last_error(), "the rig ");
    CHECK_CONTAINS(model_last_error(), "has no camera 'middle' (its cameras: left, right)");
    CHECK(access(test_path("none.png"), F_OK) != 0);
    free(rig);
done:
    two_stop(&t);
}

// ---------------------------------------------------------------------------
// The virtual rig with two cameras (examples/virtual-truth-2cam.ini)

static char *rig_2cam(const char *serve_lines)
{
    char top[PATH_MAX], text[PATH_MAX + 512];
    if (!realpath(test_srcdir(), top)) snprintf(top, sizeof top, "%s", test_srcdir());
    snprintf(text, sizeof text, "[rig]\nbackend = virtual\ntruth = %s/examples/virtual-truth-2cam.ini\n"
             "time_scale = 0.01\npixel_format = Mono12\nexposure_us = 10000\n%s", top, serve_lines);
    return strdup(test_write("rig-2cam.ini", text));
}

// Each camera's frame of one state against its own expected frame (its
// model, pose and sensor): right; and against the expected frame one degree
// off: wrong. Returns false after a failed CHECK.
static bool check_views(rig_t *r, double angle_deg)
{
    rig_turntable_t *tt = r->turntable;
    CHECK(rig_turntable_home(tt, 10) == 0);
    CHECK(rig_turntable_move_abs_deg(tt, angle_deg, 10) == 0);
    rig_turntable_status_t st;
    CHECK(rig_turntable_status(tt, &st) == 0);
    CHECK(rig_lamps_set(r->lamps, 1u << 0) == 0);   // east
    bool ok = true;
    for (int k = 0; k < 2; k++) {
        rig_virtual_t *view = rig_virtual_camera_view(r->virt, k);
        rig_frame_t f = { 0 };
        int rc = rig_camera_capture(r->cameras[k], 20, 0, &f);
        CHECK_MSG(rc == 0, "capture %s: %d %s", r->camera_names[k], rc, model_last_error());
        if (rc) return false;
        int w = f.meta.width, h = f.meta.height;
        CHECK(w == (k ? 1024 : 1280) && h == (k ? 768 : 1024));
        CHECK(!strcmp(f.meta.serial, k ? "REFL-VIRT02" : "REFL-VIRT01"));
        float *E = malloc((size_t)w * h * sizeof(float));
        CHECK(rig_virtual_expected(view, st.angle_deg, 1u << 0, 10000, 0, "Mono12", w, h, E) == 0);
        model_sensor_t sp = rig_virtual_sensor_params(view);
        vstat_t good = vstat_compare_sensor(f.pix, E, (size_t)w * h, 100, sp.system_gain_dn_per_e, sp.read_noise_e,
                                            sp.dark_offset_dn);
        CHECK(rig_virtual_expected(view, st.angle_deg + 1, 1u << 0, 10000, 0, "Mono12", w, h, E) == 0);
        vstat_t bad = vstat_compare_sensor(f.pix, E, (size_t)w * h, 100, sp.system_gain_dn_per_e, sp.read_noise_e,
                                           sp.dark_offset_dn);
        printf("  camera %s: %ld lit pixels, mean diff %.4f DN (se %.4f), var ratio %.3f; 1 deg off: %.2f\n",
               r->camera_names[k], good.n, good.mean, good.se, good.z2, bad.z2);
        CHECK(good.n > 20000);
        CHECK_MSG(fabs(good.mean) < 4 * good.se + 0.02, "camera %s: mean difference %.4f DN, se %.4f",
                  r->camera_names[k], good.mean, good.se);
        CHECK_NEAR(good.z2, 1.0, 0.1);
        CHECK(bad.z2 > 2);
        ok &= good.n > 20000 && fabs(good.z2 - 1) < 0.1;
        free(E);
        rig_frame_free(&f);
    }
    rig_lamps_all_off(r->lamps);
    return ok;
}

// In-process: two Aravis fake devices, serials REFL-VIRT01 and REFL-VIRT02;
// each camera sees the rig's one stage and lamps through its own model,
// pose and sensor; a sample put on the table reaches both.
TEST(rigcams_virtual_inprocess)
{
    char *path = rig_2cam("serve = inprocess\n");
    rig_t *r = NULL;
    int rc = rig_open(&r, path);
    CHECK_MSG(rc == 0, "rig_open: %d %s", rc, model_last_error());
    free(path);
    if (!r) return;
    CHECK(r->ncameras == 2 && rig_virtual_ncameras(r->virt) == 2);
    CHECK(!strcmp(r->camera_names[0], "left") && !strcmp(r->camera_names[1], "right"));
    CHECK(!strcmp(rig_virtual_camera_address(rig_virtual_camera_view(r->virt, 1)), "inprocess:REFL-VIRT02"));
    CHECK(rig_virtual_camera_view(r->virt, 2) == NULL && rig_virtual_camera_view(r->virt, 0) == r->virt);
    model_sensor_t s0 = rig_virtual_sensor_params(r->virt),
                   s1 = rig_virtual_sensor_params(rig_virtual_camera_view(r->virt, 1));
    CHECK(s0.dark_offset_dn == 64 && s1.dark_offset_dn == 20 && s1.bits == 12);
    CHECK_NEAR(rig_virtual_kc_per_us(rig_virtual_camera_view(r->virt, 1)), 1.5e-4, 1e-12);
    check_views(r, 30);
    CHECK(rig_virtual_set_sample(r->virt, "chessboard") == 0);
    CHECK(!strcmp(rig_virtual_sample(rig_virtual_camera_view(r->virt, 1)), "chessboard"));
    rig_close(r);
}

// Over GigE Vision: each camera on its own loopback address (Aravis serves
// only on an address of a network interface: the second, 127.0.0.x, exists
// where lo has it, e.g. `ip addr add 127.0.0.2/8 dev lo`; a refl camera
// server holds a lock per address, so a busy one is skipped). Without such an
// address, rig_open fails naming the camera and the address, and leaves
// nothing serving: the first camera's address is free again.
TEST(rigcams_virtual_gige)
{
    int session = test_camera_lock();
    rig_t *r = NULL;
    int rc = RIG_ERR_BUSY;
    char second[32] = "", msg[1200] = "";
    for (int x = 2; x < 60 && rc == RIG_ERR_BUSY; x++) {
        char lines[96];
        snprintf(second, sizeof second, "127.0.0.%d", x);
        snprintf(lines, sizeof lines, "address = 127.0.0.1 %s\n", second);
        char *path = rig_2cam(lines);
        bool q = model_error_quiet_thread(true);
        rc = rig_open(&r, path);
        model_error_quiet_thread(q);
        snprintf(msg, sizeof msg, "%s", model_last_error());
        free(path);
    }
    if (rc) {
        printf("  no interface has %s: checking the error\n", second);
        CHECK_CONTAINS(msg, "REFL-VIRT02");
        CHECK_CONTAINS(msg, second);
        CHECK(r == NULL);
        rig_virtual_options_t o = rig_virtual_defaults();
        o.time_scale = 0.01;
        char top[PATH_MAX], truth[PATH_MAX + 64];
        if (!realpath(test_srcdir(), top)) snprintf(top, sizeof top, "%s", test_srcdir());
        snprintf(truth, sizeof truth, "%s/examples/virtual-truth.ini", top);
        rig_virtual_t *v = NULL;
        rc = rig_virtual_open(&v, truth, &o);
        CHECK_MSG(rc == 0, "127.0.0.1 after the failed open: %d %s", rc, model_last_error());
        rig_virtual_close(v);
    } else {
        CHECK(!strcmp(rig_virtual_camera_address(r->virt), "127.0.0.1"));
        CHECK(!strcmp(rig_virtual_camera_address(rig_virtual_camera_view(r->virt, 1)), second));
        CHECK_CONTAINS(rig_camera_name(r->cameras[1]), second);
        check_views(r, -20);
        rig_close(r);
    }
    test_camera_unlock(session);
}

// The truth file's camera sections, checked without starting anything: the
// 2-camera example passes; a [sensor NAME] without its camera, a second
// camera's bad key or model are errors naming the file and line.
TEST(rigcams_truth_errors)
{
    char examples[PATH_MAX + 16];
    snprintf(examples, sizeof examples, "%s/examples", test_srcdir());
    char path[PATH_MAX + 64];
    snprintf(path, sizeof path, "%s/virtual-truth-2cam.ini", examples);
    size_t len = 0;
    char *text = model_read_file(path, &len);
    CHECK(text != NULL);
    if (!text) return;
    CHECK_MSG(rig_virtual_check_truth(text, len, "virtual-truth-2cam.ini", examples) == 0, "%s", model_last_error());
    static const struct {
        const char *from, *to, *want;
    } cases[] = {
        { "[sensor right]", "[sensor middle]", "[sensor middle] has no [camera middle]" },
        { "model = camera-right.cameramodel", "model = camera-rightx.cameramodel", "camera-rightx.cameramodel" },
        { "model_name = virtual rig camera B", "lens = 12 mm", "unknown key 'lens' in [camera right]" },
        { "read_noise_e = 4", "read_noise_e = -4", "read_noise_e" },
    };
    bool q = model_error_quiet_thread(true);
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
        char *at = strstr(text, cases[i].from);
        CHECK_MSG(at != NULL, "case %zu: '%s' not in the example", i, cases[i].from);
        if (!at) continue;
        char *bad = g_strdup_printf("%.*s%s%s", (int)(at - text), text, cases[i].to, at + strlen(cases[i].from));
        int rc = rig_virtual_check_truth(bad, strlen(bad), "virtual-truth-2cam.ini", examples);
        CHECK_MSG(rc == RIG_ERR_INVALID, "case %zu accepted", i);
        CHECK_CONTAINS(model_last_error(), "virtual-truth-2cam.ini:");
        CHECK_CONTAINS(model_last_error(), cases[i].want);
        g_free(bad);
    }
    model_error_quiet_thread(q);
    free(text);
}

// ---------------------------------------------------------------------------
// Capture with two cameras

// Step 3 (the third frame step): the right camera stops answering.
static void drop_right_at_step3(void *ctx, rig_t *r, int step)
{
    (void)ctx;
    if (step == 3) rig_gv_camera_drop_triggers(rig_virtual_gv_camera(rig_virtual_camera_view(r->virt, 1)), 1000);
}

// Every step triggers both cameras: each frame journalled with its camera,
// frames/sNNNNNN_left.png and _right.png; the right camera stops answering at
// step 3: the session pauses with step 3's left frame committed and the step
// pending; --resume takes the right camera's frame of step 3 only, then the
// rest; the session's readers select a camera's frames; session check covers
// every frame.
TEST(rigcams_capture_resume)
{
    char *rig = rig_2cam("serve = inprocess\n");
    const char *plan = test_write("plan.ini", "[sample]\nname = coupon_matte_paint\nkind = material_coupon\n"
                                  "[angles]\nlist = 0 5\n[lamps]\nsets = east\n[exposure]\nmode = fixed\n"
                                  "list_us = 1000 2000\n[capture]\nframe_timeout_s = 0.3\nretries = 1\n");
    char dir[4096];
    snprintf(dir, sizeof dir, "%s/s", test_tmpdir());
    rig_capture_opts_t o = { .plan_path = plan, .rig_path = rig, .dir = dir, .progress = 0,
                             .before_step = drop_right_at_step3, .op = rig_operator_open(true, NULL) };
    bool q = model_error_quiet_thread(true);
    int rc = rig_capture_run(&o);
    model_error_quiet_thread(q);
    CHECK(rc == 3);
    CHECK_CONTAINS(model_last_error(), "serial REFL-VIRT02");
    CHECK_CONTAINS(model_last_error(), "did not answer at step 3");
    rig_session_t *s = rig_session_open(dir);
    CHECK(s != NULL);
    if (!s) goto done;
    CHECK_MSG(s->n == 5, "%d frames after the pause", s->n);   // steps 1, 2 both cameras, step 3 left
    CHECK(s->n == 5 && s->rows[4].step == 3 && !strcmp(s->rows[4].camera, "left"));
    uint64_t left3 = s->n == 5 ? s->rows[4].frame_id : 0;
    rig_session_free(s);

    o.resume = true;
    o.before_step = NULL;
    rc = rig_capture_run(&o);
    CHECK_MSG(rc == 0, "resume: %d %s", rc, model_last_error());
    s = rig_session_open(dir);
    CHECK(s != NULL);
    if (!s) goto done;
    CHECK_MSG(s->n == 8, "%d frames", s->n);
    const char *names[4];
    CHECK(rig_session_cameras(s, names, 4) == 2 && !strcmp(names[0], "left") && !strcmp(names[1], "right"));
    for (int i = 0; i < s->n; i++) {
        const rig_frame_row_t *w = &s->rows[i];
        bool right = !strcmp(w->camera, "right");
        CHECK(right || !strcmp(w->camera, "left"));
        CHECK(w->step == 1 + i / 2);
        CHECK(w->width == (right ? 1024 : 1280) && w->height == (right ? 768 : 1024));
        char want[64];
        snprintf(want, sizeof want, "frames/s%06d_%s.png", w->step, w->camera);
        CHECK_MSG(!strcmp(w->file, want), "row %d: %s", i, w->file);
        if (w->step == 3 && !right) CHECK(w->frame_id == left3);   // not taken again
    }
    int fw = 0, fh = 0;
    float *img = rig_session_frame(s, 7, &fw, &fh);
    CHECK(img && fw == 1024 && fh == 768);
    free(img);
    rig_session_free(s);
    s = rig_session_open_camera(dir, "right");
    CHECK(s && s->n == 4);
    for (int i = 0; s && i < s->n; i++) CHECK(!strcmp(s->rows[i].camera, "right") && s->rows[i].step == i + 1);
    rig_session_free(s);
    s = rig_session_open_camera(dir, NULL);   // the first camera's
    CHECK(s && s->n == 4 && !strcmp(s->rows[0].camera, "left"));
    rig_session_free(s);
    q = model_error_quiet_thread(true);
    s = rig_session_open_camera(dir, "middle");
    model_error_quiet_thread(q);
    CHECK(s == NULL);
    CHECK_CONTAINS(model_last_error(), "no frames of camera 'middle' (its cameras: left, right)");
    // refl session check: every frame of both cameras verified
    const char *argv[] = { "session", "check", dir };
    fflush(stdout);
    int saved = dup(1), fd = open(test_path("check.txt"), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    dup2(fd, 1);
    close(fd);
    rc = rig_cmd_session(3, (char **)argv);
    fflush(stdout);
    dup2(saved, 1);
    close(saved);
    CHECK(rc == 0);
    char *txt = model_read_file(test_path("check.txt"), NULL);
    CHECK(txt && strstr(txt, "frames: 8\nframes_verified: 8\nframes_bad: 0\n") && strstr(txt, "steps_missing: 0"));
    free(txt);
done:
    rig_operator_close(o.op);
    free(rig);
}

// A journal of schema version 1 (one camera: frames keyed by step, no camera
// column) is read as it is (every frame of camera "camera"; a reader writes
// nothing, so it stays version 1), and the writer continuing it
// (rig_journal_resume) migrates it to version 2, which reads the same.
TEST(rigcams_journal_v1_migrated)
{
    char *rig = rig_2cam("serve = inprocess\n");
    const char *plan = test_write("plan.ini", "[sample]\nname = coupon_matte_paint\nkind = material_coupon\n"
                                  "[angles]\nlist = 0\n[lamps]\nsets = east\n[exposure]\nmode = fixed\n"
                                  "list_us = 1000 2000\n");
    char dir[4096], db[4200];
    snprintf(dir, sizeof dir, "%s/s", test_tmpdir());
    snprintf(db, sizeof db, "%s/session.sqlite", dir);
    rig_capture_opts_t o = { .plan_path = plan, .rig_path = rig, .dir = dir, .progress = 0,
                             .op = rig_operator_open(true, NULL) };
    int rc = rig_capture_run(&o);
    CHECK(rc == 0);
    rig_operator_close(o.op);
    free(rig);
    // Make it a version-1 journal of one camera: the left camera's frames, no camera column.
    sqlite3 *h = NULL;
    CHECK(sqlite3_open(db, &h) == SQLITE_OK);
    const char *to_v1 =
        "DELETE FROM frames WHERE camera != 'left';"
        "CREATE TABLE f1 AS SELECT step, file, sha256, t_trigger_utc, t_written_utc, t_trigger_s, t_written_s,"
        " commanded_deg, measured_deg, lamps, exposure_us, gain, mean, max, roi_max, saturated_fraction, width,"
        " height, pixel_format, frame_id FROM frames;"
        "DROP TABLE frames; ALTER TABLE f1 RENAME TO frames; UPDATE schema_version SET version = 1;";
    char *err = NULL;
    CHECK_MSG(sqlite3_exec(h, to_v1, NULL, NULL, &err) == SQLITE_OK, "%s", err ? err : "");
    sqlite3_free(err);
    sqlite3_close(h);
    for (int pass = 0; pass < 2; pass++) {   // as version 1, then migrated by the writer's open
        rig_session_t *s = rig_session_open(dir);
        CHECK_MSG(s != NULL, "%s", model_last_error());
        if (!s) return;
        CHECK(s->n == 2);
        for (int i = 0; i < s->n; i++) CHECK(!strcmp(s->rows[i].camera, "camera") && s->rows[i].step == i + 1);
        int w = 0, hh = 0;
        float *img = rig_session_frame(s, 1, &w, &hh);
        CHECK(img && w == 1280 && hh == 1024);
        free(img);
        rig_session_free(s);
        CHECK(sqlite3_open(db, &h) == SQLITE_OK);
        sqlite3_stmt *st = NULL;
        int v = -1;
        if (sqlite3_prepare_v2(h, "SELECT version FROM schema_version", -1, &st, NULL) == SQLITE_OK &&
            sqlite3_step(st) == SQLITE_ROW)
            v = sqlite3_column_int(st, 0);
        sqlite3_finalize(st);
        sqlite3_close(h);
        CHECK_MSG(v == 1 + pass, "schema version %d after pass %d", v, pass);
        rig_journal_t *j = NULL;
        if (pass == 0) CHECK_MSG(rig_journal_resume(&j, dir) == 0, "%s", model_last_error());
        rig_journal_close(j);
    }
}

// The calibrations read one camera's frames of a session of several: the
// geometry's views of camera right (its imager), of the first camera by
// default, and an error naming the cameras for a name the session lacks.
TEST(rigcams_geometry_selects_camera)
{
    char *rig = rig_2cam("serve = inprocess\n");
    const char *plan = test_write("plan.ini", "[sample]\nname = calib_board\nkind = chessboard\n"
                                  "[angles]\nlist = 0 20\n[lamps]\nsets = all\n[exposure]\nmode = fixed\n"
                                  "list_us = 6000\n");
    char dir[4096], img[4200];
    snprintf(dir, sizeof dir, "%s/s", test_tmpdir());
    snprintf(img, sizeof img, "%s/img", test_tmpdir());
    CHECK(mkdir(img, 0755) == 0);
    rig_capture_opts_t o = { .plan_path = plan, .rig_path = rig, .dir = dir, .progress = 0,
                             .op = rig_operator_open(true, NULL) };
    CHECK(rig_capture_run(&o) == 0);
    rig_operator_close(o.op);
    free(rig);
    static const struct {
        const char *camera;
        int w, h;
    } cases[] = { { "right", 1024, 768 }, { NULL, 1280, 1024 }, { "left", 1280, 1024 } };
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
        calib_geometry_views_t vs;
        calib_geometry_views_init(&vs);
        int w = 0, h = 0;
        CHECK_MSG(calib_geometry_add_session(&vs, dir, cases[i].camera, img, &w, &h), "%s", model_last_error());
        CHECK(w == cases[i].w && h == cases[i].h);
        CHECK(vs.v->len == 2);
        for (guint k = 0; k < vs.v->len; k++) {
            const calib_geometry_view_t *v = g_ptr_array_index(vs.v, k);
            CHECK(strstr(v->name, cases[i].camera ? cases[i].camera : "left") != NULL);
        }
        calib_geometry_views_free(&vs);
    }
    calib_geometry_views_t vs;
    calib_geometry_views_init(&vs);
    int w = 0, h = 0;
    bool q = model_error_quiet_thread(true);
    CHECK(!calib_geometry_add_session(&vs, dir, "middle", img, &w, &h));
    model_error_quiet_thread(q);
    CHECK_CONTAINS(model_last_error(), "no frames of camera 'middle' (its cameras: left, right)");
    calib_geometry_views_free(&vs);
}

// A plan is checked against every camera: a region of interest that fits the
// first camera's frame but not the second's is an error naming the second.
TEST(rigcams_plan_bind_every_camera)
{
    char *path = rig_2cam("serve = inprocess\n");
    rig_t *r = NULL;
    CHECK(rig_open(&r, path) == 0);
    free(path);
    if (!r) return;
    const char *text = "[sample]\nname = coupon_matte_paint\nkind = material_coupon\n[angles]\nlist = 0\n[lamps]\n"
                       "sets = east\n[exposure]\nmode = auto\nlist_us = 4000 1000\nroi = 0 0 1100 100\n";
    rig_plan_t *p = rig_plan_parse(text, strlen(text), "roi.ini");
    CHECK(p != NULL);
    bool q = model_error_quiet_thread(true);
    int rc = p ? rig_plan_bind(p, r) : -1;
    model_error_quiet_thread(q);
    CHECK(rc == RIG_ERR_INVALID);
    CHECK_CONTAINS(model_last_error(), "roi 0 0 1100 100 does not fit the 1024 x 768 frame of the camera");
    CHECK_CONTAINS(model_last_error(), "REFL-VIRT02");
    rig_plan_free(p);
    text = "[sample]\nname = coupon_matte_paint\nkind = material_coupon\n[angles]\nlist = 0\n[lamps]\n"
           "sets = east\n[exposure]\nmode = auto\nlist_us = 4000 1000\nroi = 0 0 1000 100\n";
    p = rig_plan_parse(text, strlen(text), "roi.ini");
    CHECK(p && rig_plan_bind(p, r) == 0);
    rig_plan_free(p);
    rig_close(r);
}

// refl calib geometry on a rig of two cameras calibrates them together, and
// each camera needs the board in enough views: at tilt 0 and angles 20, 40,
// 60 the left camera finds it at 20 and 40, the right only at 60, so with
// --min-views 2 the error names the right camera and its count.
TEST(rigcams_geometry_each_camera_needs_views)
{
    char *rig = rig_2cam("serve = inprocess\nnoise_seed = 7\n");
    char *out = NULL, *err = NULL;
    int rc = test_refl_run(120, &out, &err, "calib", "geometry", "--yes", "--rig", rig, "--tilts", "0:20,40,60",
                           "--min-views", "2", "-o", test_path("geo"), NULL);
    CHECK(rc == 1);
    CHECK_CONTAINS(err, "2 cameras (left 1280x1024, right 1024x768), calibrated together");
    CHECK_CONTAINS(err, "camera left: the board in 2 of 3 images");
    CHECK_CONTAINS(err, "too few views for LENSMODEL_OPENCV8 of camera right: the board was found in 1 of its 3 "
                        "images, the solve needs at least 2");
    free(rig);
    free(out);
    free(err);
}

// refl capture --calib DIR on a rig of several cameras records the shared
// calibration files and each camera's own (calib/calset.c's layout), with
// the camera they belong to; a camera without its own files has none listed.
TEST(rigcams_capture_records_each_cameras_calibration)
{
    char *rig = rig_2cam("serve = inprocess\n");
    char *plan = g_strdup(test_write("plan.ini", "[sample]\nname = coupon_matte_paint\nkind = material_coupon\n"
                                  "[angles]\nlist = 0\n[lamps]\nsets = east\n[exposure]\nmode = fixed\n"
                                  "list_us = 1000\n"));   // test_path's buffers are reused
    CHECK(g_mkdir_with_parents(test_path("cal/geometry"), 0755) == 0 &&
          g_mkdir_with_parents(test_path("cal/gain/right"), 0755) == 0);
    test_write("cal/geometry/camera.cameramodel", "left\n");
    test_write("cal/geometry/left.cameramodel", "left\n");
    test_write("cal/geometry/right.cameramodel", "right\n");
    test_write("cal/gain/gain.json", "{}\n");
    test_write("cal/gain/right/gain.json", "{\"camera\": \"right\"}\n");
    char *cal_dir = g_strdup(test_path("cal")), dir[4096];
    snprintf(dir, sizeof dir, "%s/s", test_tmpdir());
    rig_capture_opts_t o = { .plan_path = plan, .rig_path = rig, .dir = dir, .progress = 0,
                             .calib_dir = cal_dir, .op = rig_operator_open(true, NULL) };
    int rc = rig_capture_run(&o);
    CHECK_MSG(rc == 0, "capture: %d %s", rc, model_last_error());
    rig_session_t *s = rig_session_open(dir);
    CHECK(s != NULL && s->facts != NULL);
    json_t *cal = s ? json_object_get(s->facts, "calibrations") : NULL;
    int shared = 0, left_geo = 0, right_geo = 0, right_gain = 0, left_gain = 0;
    for (size_t i = 0; i < json_array_size(cal); i++) {
        json_t *e = json_array_get(cal, i);
        const char *role = json_string_value(json_object_get(e, "role"));
        const char *cam = json_string_value(json_object_get(e, "camera"));
        const char *path = json_string_value(json_object_get(e, "path"));
        CHECK(role && path && json_string_length(json_object_get(e, "sha256")) == 64);
        if (!role || !path) continue;
        bool geo = !strcmp(role, "camera geometry"), gain = !strcmp(role, "sensitivity");
        if (!cam) shared++;
        else if (geo && !strcmp(cam, "left")) left_geo += g_str_has_suffix(path, "/geometry/left.cameramodel");
        else if (geo && !strcmp(cam, "right")) right_geo += g_str_has_suffix(path, "/geometry/right.cameramodel");
        else if (gain && !strcmp(cam, "right")) right_gain += g_str_has_suffix(path, "/gain/right/gain.json");
        else if (gain && !strcmp(cam, "left")) left_gain++;
    }
    CHECK_MSG(shared == 2 && left_geo == 1 && right_geo == 1 && right_gain == 1 && left_gain == 0,
              "shared %d, left geometry %d, right geometry %d, right gain %d, left gain %d", shared, left_geo,
              right_geo, right_gain, left_gain);
    rig_session_free(s);
    rig_operator_close(o.op);
    g_free(plan);
    g_free(cal_dir);
    free(rig);
}
