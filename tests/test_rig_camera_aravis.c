// tests/test_rig_camera_aravis.c — the Aravis camera backend over the real GigE
// Vision path on 127.0.0.1, against the virtual camera of rig/virtual/gv_camera.c
// served by this process: settings, pixel values, metadata, frame ids, lost
// frames, a camera that disappears, no camera at all, the GenICam features and
// free running seen by an independent client, the server's responsiveness
// during slow renders; and the backend against Aravis's unmodified fake camera.
//
// Never enumerates cameras (no discovery broadcast): every open is by address.
// Servers of refl take turns on 127.0.0.1:3956 through a lock file, so test
// runs of several build trees may run at the same time.
#define _GNU_SOURCE
#include <arv.h>
#include <fcntl.h>
#include <glib.h>
#include <math.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stdlib.h>
#include <sys/file.h>
#include <sys/resource.h>
#include <time.h>
#include <unistd.h>

#include "model/model.h"
#include "rig/virtual/gv_camera.h"
#include "rig/rig.h"
#include "tests/fixtures.h"
#include "tests/test.h"

#define ADDR "127.0.0.1"

// The test pattern, its renderer and the server serving it: tests/fixtures.h.

static double now_s(void) { return model_now_s(); }

static double realtime_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_REALTIME, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

// flock a file in $TMPDIR, waiting up to 300 s; the fd, or -1.
static int lock_file(const char *name)
{
    char path[512];
    snprintf(path, sizeof path, "%s/%s", g_get_tmp_dir(), name);
    int fd = open(path, O_RDONLY | O_CREAT | O_CLOEXEC, 0666);
    if (fd < 0) return -1;
    for (int i = 0; i < 6000; i++) {
        if (flock(fd, LOCK_EX | LOCK_NB) == 0) return fd;
        usleep(50000);
    }
    close(fd);
    return -1;
}



// ---------------------------------------------------------------------------

TEST(aravis_gv_settings_pixels_metadata)
{
    fx_gv_t F;
    if (!fx_gv_open(&F, true)) goto done;
    fx_pattern_ctx_t *ctx = F.ctx;
    rig_gv_camera_t *g = F.g;
    rig_camera_t *c = F.c;
    int rc;
    CHECK(!strcmp(rig_camera_backend(c), "aravis"));
    CHECK_CONTAINS(rig_camera_name(c), "TEST-0042");
    CHECK_CONTAINS(rig_camera_name(c), "pattern cam");
    CHECK_CONTAINS(rig_camera_name(c), ADDR);

    // Defaults of the virtual camera.
    rig_frame_meta_t s;
    CHECK(rig_camera_settings(c, &s) == 0);
    CHECK(s.width == 1280 && s.height == 1024 && s.offset_x == 0 && s.offset_y == 0);
    CHECK(!strcmp(s.pixel_format, "Mono8") && s.bits == 8);
    CHECK_NEAR(s.exposure_us, 10000, 1e-9);
    CHECK_NEAR(s.gain, 0, 1e-12);
    CHECK_NEAR(s.temperature_c, 35, 1e-12);
    CHECK(!strcmp(s.vendor, "refl-test") && !strcmp(s.model, "pattern cam") && !strcmp(s.serial, "TEST-0042"));

    // Mono16, fractional exposure, gain, region.
    CHECK(rig_camera_set_pixel_format(c, "Mono16") == 0);
    CHECK(rig_camera_set_exposure_us(c, 1234.5) == 0);
    CHECK(rig_camera_set_gain(c, 6.5) == 0);
    CHECK(rig_camera_set_region(c, 64, 32, 320, 240) == 0);
    CHECK(rig_camera_settings(c, &s) == 0);
    CHECK(s.width == 320 && s.height == 240 && s.offset_x == 64 && s.offset_y == 32);
    CHECK(!strcmp(s.pixel_format, "Mono16") && s.bits == 16);
    CHECK_NEAR(s.exposure_us, 1234.5, 1e-9);
    CHECK_NEAR(s.gain, 6.5, 1e-12);

    uint64_t prev_id = 0, prev_ts = 0;
    for (int i = 0; i < 3; i++) {
        rig_frame_t f;
        double t0 = realtime_s();
        rc = rig_camera_capture(c, 2.0, 2, &f);
        CHECK_MSG(rc == 0, "capture: %d %s", rc, model_last_error());
        if (rc) break;
        const rig_frame_meta_t *m = &f.meta;
        CHECK(m->width == 320 && m->height == 240 && m->offset_x == 64 && m->offset_y == 32);
        CHECK(!strcmp(m->pixel_format, "Mono16") && m->bits == 16);
        CHECK_NEAR(m->exposure_us, 1234.5, 1e-9);
        CHECK_NEAR(m->gain, 6.5, 1e-12);
        CHECK_NEAR(m->temperature_c, 35, 1e-12);
        CHECK(!strcmp(m->serial, "TEST-0042") && !strcmp(m->model, "pattern cam") && !strcmp(m->vendor, "refl-test"));
        CHECK(m->system_time_s >= t0 && m->system_time_s <= realtime_s());
        CHECK(m->timestamp_ns > 0);
        if (i > 0) {
            CHECK_MSG(m->frame_id == prev_id + 1, "frame id %llu after %llu", (unsigned long long)m->frame_id,
                      (unsigned long long)prev_id);
            CHECK(m->timestamp_ns > prev_ts);
        }
        prev_id = m->frame_id;
        prev_ts = m->timestamp_ns;
        long bad = fx_pattern_mismatches(&f);
        CHECK_MSG(bad == 0, "%ld pixels differ from the pattern", bad);
        // A value in the middle, computed by hand: sensor (64+10, 32+20): (222+260)%97+1 = 95,
        // 95 * 12.345 * 10^(6.5/20) = 2478.6 -> 2478.
        CHECK(f.pix[20 * 320 + 10] == 2478);
        rig_frame_free(&f);
        CHECK(f.pix == NULL);
    }
    // The renderer saw the settings the client set.
    pthread_mutex_lock(&ctx->lock);
    CHECK(ctx->n == 3);
    CHECK(ctx->last.width == 320 && ctx->last.offset_x == 64 && ctx->last.bits == 16);
    CHECK_NEAR(ctx->last.exposure_us, 1234.5, 1e-9);
    pthread_mutex_unlock(&ctx->lock);

    // Mono12 (values cut at 4095) and Mono8 (cut at 255), full sensor, a new temperature.
    rig_gv_camera_set_temperature(g, 41.25);
    CHECK(rig_camera_set_region(c, 0, 0, 1280, 1024) == 0);
    CHECK(rig_camera_set_exposure_us(c, 5000) == 0);
    const char *fmts[] = { "Mono12", "Mono8" };
    const int bits[] = { 12, 8 };
    for (int k = 0; k < 2; k++) {
        CHECK(rig_camera_set_pixel_format(c, fmts[k]) == 0);
        rig_frame_t f;
        rc = rig_camera_capture(c, 2.0, 2, &f);
        CHECK_MSG(rc == 0, "capture %s: %d %s", fmts[k], rc, model_last_error());
        if (rc) continue;
        CHECK(!strcmp(f.meta.pixel_format, fmts[k]) && f.meta.bits == bits[k]);
        CHECK(f.meta.width == 1280 && f.meta.height == 1024);
        CHECK_NEAR(f.meta.temperature_c, 41.25, 1e-12);
        long bad = fx_pattern_mismatches(&f);
        CHECK_MSG(bad == 0, "%s: %ld pixels differ from the pattern", fmts[k], bad);
        uint16_t maxv = 0;
        for (size_t i = 0; i < (size_t)1280 * 1024; i++) maxv = f.pix[i] > maxv ? f.pix[i] : maxv;
        CHECK(maxv == (1 << bits[k]) - 1);   // the pattern saturates at 5 ms
        rig_frame_free(&f);
    }
    rig_gv_camera_stats_t st;
    rig_gv_camera_stats(g, &st);
    CHECK(st.triggers == 5 && st.frames_rendered == 5 && st.frames_sent == 5);
    CHECK(st.late_frames == 0 && st.render_errors == 0);
done:
    fx_gv_close(&F);
}

// Mono10 and the packed formats (rig/camera/pixfmt.h): the server packs, the backend
// unpacks; every pixel is the pattern's value, unscaled (0..1023, 0..4095).
TEST(aravis_gv_mono10_and_packed_formats)
{
    fx_gv_t F;
    if (!fx_gv_open(&F, true)) goto done;
    rig_camera_t *c = F.c;
    CHECK(rig_camera_set_region(c, 64, 32, 640, 480) == 0);
    CHECK(rig_camera_set_exposure_us(c, 4000) == 0);   // up to 97 * 40 = 3880 DN: the high bits are used
    const char *fmts[] = { "Mono10", "Mono10p", "Mono12p", "Mono12Packed", "Mono10Packed" };
    const int bits[] = { 10, 10, 12, 12, 10 };
    for (int k = 0; k < 5; k++) {
        int rc = rig_camera_set_pixel_format(c, fmts[k]);
        CHECK_MSG(rc == 0, "set %s: %d %s", fmts[k], rc, model_last_error());
        if (rc) continue;
        rig_frame_meta_t s;
        CHECK(rig_camera_settings(c, &s) == 0);
        CHECK_MSG(!strcmp(s.pixel_format, fmts[k]) && s.bits == bits[k], "%s: settings say %s, %d bits", fmts[k],
                  s.pixel_format, s.bits);
        rig_frame_t f;
        rc = rig_camera_capture(c, 2.0, 2, &f);
        CHECK_MSG(rc == 0, "capture %s: %d %s", fmts[k], rc, model_last_error());
        if (rc) continue;
        CHECK_MSG(!strcmp(f.meta.pixel_format, fmts[k]) && f.meta.bits == bits[k], "%s: frame says %s, %d bits",
                  fmts[k], f.meta.pixel_format, f.meta.bits);
        CHECK(f.meta.width == 640 && f.meta.height == 480 && f.meta.offset_x == 64 && f.meta.offset_y == 32);
        CHECK_NEAR(f.meta.exposure_us, 4000, 1e-9);
        long bad = 0;
        uint16_t maxv = 0;
        for (int y = 0; y < 480; y++)
            for (int x = 0; x < 640; x++) {
                uint16_t v = f.pix[(size_t)y * 640 + x];
                bad += v != fx_pattern(x + 64, y + 32, 4000, 0, bits[k]);
                maxv = v > maxv ? v : maxv;
            }
        CHECK_MSG(bad == 0, "%s: %ld pixels differ from the pattern", fmts[k], bad);
        CHECK(fx_pattern_mismatches(&f) == 0);
        CHECK_MSG(maxv == (bits[k] == 10 ? 1023 : 3880), "%s: maximum %u", fmts[k], maxv);
        rig_frame_free(&f);
    }
    // Back to Mono12 (unpacked): the same values as Mono12p.
    CHECK(rig_camera_set_pixel_format(c, "Mono12") == 0);
    rig_frame_t f;
    int rc = rig_camera_capture(c, 2.0, 2, &f);
    CHECK_MSG(rc == 0, "capture Mono12: %d %s", rc, model_last_error());
    if (!rc) {
        CHECK(!strcmp(f.meta.pixel_format, "Mono12") && f.meta.bits == 12 && fx_pattern_mismatches(&f) == 0);
        rig_frame_free(&f);
    }
done:
    fx_gv_close(&F);
}

TEST(aravis_gv_invalid_settings)
{
    fx_gv_t F;
    if (!fx_gv_open(&F, true)) goto done;
    rig_camera_t *c = F.c;
    // Not a format refl records: names the camera's formats.
    CHECK(rig_camera_set_pixel_format(c, "RGB8") == RIG_ERR_INVALID);
    CHECK_CONTAINS(model_last_error(), "RGB8");
    CHECK_CONTAINS(model_last_error(), "Mono8, Mono12, Mono16");
    CHECK_CONTAINS(model_last_error(), "TEST-0042");
    CHECK(rig_camera_set_pixel_format(c, "BayerRG8") == RIG_ERR_INVALID);
    CHECK(rig_camera_set_exposure_us(c, 5) == RIG_ERR_INVALID);
    CHECK_CONTAINS(model_last_error(), "outside the camera's range 10..10000000 us");
    CHECK(rig_camera_set_exposure_us(c, NAN) == RIG_ERR_INVALID);
    CHECK(rig_camera_set_gain(c, 30) == RIG_ERR_INVALID);
    CHECK_CONTAINS(model_last_error(), "0..24");
    CHECK(rig_camera_set_region(c, 1000, 0, 300, 100) == RIG_ERR_INVALID);
    CHECK_CONTAINS(model_last_error(), "1280x1024 sensor");
    CHECK(rig_camera_set_region(c, 0, 0, 0, 100) == RIG_ERR_INVALID);
    rig_frame_t f;
    CHECK(rig_camera_capture(c, 0, 1, &f) == RIG_ERR_INVALID && f.pix == NULL);
    CHECK(rig_camera_capture(c, 1, -1, &f) == RIG_ERR_INVALID);
    // Nothing was changed by the rejected calls.
    rig_frame_meta_t s;
    CHECK(rig_camera_settings(c, &s) == 0);
    CHECK(!strcmp(s.pixel_format, "Mono8") && s.width == 1280);
    CHECK_NEAR(s.exposure_us, 10000, 1e-9);
    // Wrappers check their arguments.
    CHECK(rig_camera_capture(NULL, 1, 1, &f) == RIG_ERR_INVALID);
    CHECK(rig_camera_settings(c, NULL) == RIG_ERR_INVALID);
    CHECK(rig_camera_set_pixel_format(c, NULL) == RIG_ERR_INVALID);
    rig_frame_free(NULL);
    rig_camera_close(NULL);
done:
    fx_gv_close(&F);
}

// Frame ids keep increasing across the 16-bit GVSP block id wrap (the Aravis
// fake camera starts at 65400), triggers lost by the camera are retried, and a
// camera that sends nothing times out with a clear message.
TEST_ALONE(aravis_gv_frame_ids_retries)
{
    fx_gv_t F;
    if (!fx_gv_open(&F, true)) goto done;
    fx_pattern_ctx_t *ctx = F.ctx;
    rig_gv_camera_t *g = F.g;
    rig_camera_t *c = F.c;
    int rc;
    CHECK(rig_camera_set_region(c, 0, 0, 64, 48) == 0);
    uint64_t prev = 0;
    int n_ok = 0;
    for (int i = 0; i < 150; i++) {
        rig_frame_t f;
        rc = rig_camera_capture(c, 2.0, 1, &f);
        if (rc) {
            CHECK_MSG(0, "capture %d: %d %s", i, rc, model_last_error());
            break;
        }
        if (i > 0 && f.meta.frame_id != prev + 1)
            CHECK_MSG(0, "frame %d: id %llu after %llu", i, (unsigned long long)f.meta.frame_id, (unsigned long long)prev);
        prev = f.meta.frame_id;
        n_ok += fx_pattern_mismatches(&f) == 0;
        rig_frame_free(&f);
    }
    CHECK(n_ok == 150);
    CHECK_MSG(prev > 65535, "prev %llu", (unsigned long long)prev);   // went past the wrap

    // Two triggers lost: the third attempt delivers.
    rig_gv_camera_drop_triggers(g, 2);
    rig_frame_t f;
    double t0 = now_s();
    rc = rig_camera_capture(c, 0.2, 2, &f);
    CHECK_MSG(rc == 0, "capture with retries: %d %s", rc, model_last_error());
    CHECK(now_s() - t0 >= 0.39 && now_s() - t0 < 2.0);
    if (!rc) CHECK(f.meta.frame_id == prev + 1 && fx_pattern_mismatches(&f) == 0);   // dropped triggers send nothing
    rig_frame_free(&f);

    // More losses than retries: RIG_ERR_TIMEOUT naming the camera and what happened.
    rig_gv_camera_drop_triggers(g, 10);
    t0 = now_s();
    rc = rig_camera_capture(c, 0.1, 1, &f);
    CHECK(rc == RIG_ERR_TIMEOUT && f.pix == NULL);
    CHECK(now_s() - t0 < 1.0);
    CHECK_CONTAINS(model_last_error(), "TEST-0042");
    CHECK_CONTAINS(model_last_error(), "no complete frame after 2 software triggers");
    CHECK_CONTAINS(model_last_error(), "no frame within 0.1 s");
    rig_gv_camera_drop_triggers(g, 0);

    // A render failure sends no frame: the retry gets the next render.
    atomic_store(&ctx->fail, 1);
    rc = rig_camera_capture(c, 0.2, 1, &f);
    CHECK_MSG(rc == 0, "capture after a failed render: %d %s", rc, model_last_error());
    rig_frame_free(&f);
    rig_gv_camera_stats_t st;
    rig_gv_camera_stats(g, &st);
    CHECK(st.dropped_triggers == 4 && st.render_errors == 1 && st.late_frames == 0);
    char msg[256];
    rig_gv_camera_last_render_error(g, msg, sizeof msg);
    CHECK_CONTAINS(msg, "injected failure");
done:
    fx_gv_close(&F);
}

// A frame that comes after its trigger timed out (the renderer slower than
// the time-out) is not taken for a later trigger's: the exposure changed
// after the time-out, the next two frames are the new exposure's pattern.
TEST_ALONE(aravis_gv_late_frame_not_taken_for_the_next)
{
    fx_gv_t F;
    if (!fx_gv_open(&F, true)) goto done;
    rig_camera_t *c = F.c;
    rig_frame_t f = { 0 };
    CHECK(rig_camera_set_region(c, 0, 0, 64, 48) == 0);
    CHECK(rig_camera_set_exposure_us(c, 10000) == 0);
    int rc = rig_camera_capture(c, 2.0, 0, &f);
    CHECK_MSG(rc == 0, "first capture: %d %s", rc, model_last_error());
    rig_frame_free(&f);
    atomic_store(&F.ctx->sleep_ms, 400);
    rc = rig_camera_capture(c, 0.1, 0, &f);
    CHECK_MSG(rc == RIG_ERR_TIMEOUT, "capture with a renderer slower than the time-out: %d %s", rc,
              model_last_error());
    atomic_store(&F.ctx->sleep_ms, 0);
    CHECK(rig_camera_set_exposure_us(c, 20000) == 0);
    for (int k = 0; k < 2; k++) {
        rc = rig_camera_capture(c, 2.0, 0, &f);
        CHECK_MSG(rc == 0, "capture %d after the late frame: %d %s", k, rc, model_last_error());
        if (rc) break;
        long bad = fx_pattern_mismatches(&f);
        CHECK_MSG(bad == 0 && f.meta.exposure_us == 20000, "capture %d after the late frame: %ld pixels not the "
                  "20000 us pattern", k, bad);
        rig_frame_free(&f);
    }
done:
    fx_gv_close(&F);
}

// An independent GenICam client (Aravis through Python GObject introspection,
// by address) reads our features by name from the camera's XML and sees the
// values we set.
static const char genicam_py[] =
    "import sys, gi\n"
    "gi.require_version('Aravis', '0.8')\n"
    "from gi.repository import Aravis\n"
    "dev = Aravis.Camera.new(sys.argv[1]).get_device()\n"   // an IP address: no discovery
    "for name in sys.argv[2:]:\n"
    "    node = dev.get_feature(name)\n"
    "    print(name, '=', node.get_value_as_string() if node is not None else '<missing>')\n"
    "pf = dev.get_feature('PixelFormat')\n"
    "print('PixelFormat entries =', ' '.join(e.get_name() for e in pf.get_entries()))\n"
    "def walk(n, depth):\n"
    "    if depth > 5 or n is None: return\n"
    "    print('feature', n.get_name())\n"
    "    if isinstance(n, Aravis.GcCategory):\n"
    "        for f in n.get_features(): walk(dev.get_feature(f), depth + 1)\n"
    "walk(dev.get_feature('Root'), 0)\n";

TEST(aravis_gv_genicam_features_external_client)
{
    char *out = NULL, *err = NULL;
    fx_gv_t F;
    if (!fx_gv_open(&F, true)) goto done;
    rig_gv_camera_t *g = F.g;
    rig_camera_t *c = F.c;
    CHECK(rig_camera_set_pixel_format(c, "Mono12") == 0);
    CHECK(rig_camera_set_exposure_us(c, 2500.25) == 0);
    CHECK(rig_camera_set_gain(c, 3.5) == 0);
    CHECK(rig_camera_set_region(c, 16, 8, 640, 480) == 0);
    rig_gv_camera_set_temperature(g, 38.5);
    rig_camera_close(c);   // release control (the client could read while we hold it too)
    c = F.c = NULL;

    const char *script = test_write("genicam_read.py", genicam_py);
    const char *argv[] = { "/usr/bin/python3", script, ADDR, "ExposureTime", "ExposureTimeAbs", "Gain",
                           "PixelFormat", "Width", "Height", "OffsetX", "OffsetY", "SensorWidth", "SensorHeight",
                           "DeviceTemperature", "DeviceVendorName", "DeviceModelName", "DeviceSerialNumber",
                           "TriggerMode", "TriggerSource", NULL };
    int st = test_run(argv, 20, &out, &err);
    CHECK_MSG(st == 0, "python GenICam client exited %d: %s", st, err ? err : "");
    CHECK_CONTAINS(out, "ExposureTime = 2500.25\n");
    CHECK_CONTAINS(out, "ExposureTimeAbs = 2500.25\n");
    CHECK_CONTAINS(out, "Gain = 3.5\n");
    CHECK_CONTAINS(out, "PixelFormat = Mono12\n");
    CHECK_CONTAINS(out, "Width = 640\n");
    CHECK_CONTAINS(out, "Height = 480\n");
    CHECK_CONTAINS(out, "OffsetX = 16\n");
    CHECK_CONTAINS(out, "OffsetY = 8\n");
    CHECK_CONTAINS(out, "SensorWidth = 1280\n");
    CHECK_CONTAINS(out, "SensorHeight = 1024\n");
    CHECK_CONTAINS(out, "DeviceTemperature = 38.5\n");
    CHECK_CONTAINS(out, "DeviceVendorName = refl-test\n");
    CHECK_CONTAINS(out, "DeviceModelName = pattern cam\n");
    CHECK_CONTAINS(out, "DeviceSerialNumber = TEST-0042\n");
    CHECK_CONTAINS(out, "TriggerMode = On\n");
    CHECK_CONTAINS(out, "TriggerSource = Software\n");
    const char *entries = out ? strstr(out, "PixelFormat entries =") : NULL;
    CHECK(entries && strstr(entries, " Mono8") && strstr(entries, " Mono12") && strstr(entries, " Mono16") &&
          !strstr(entries, "Bayer") && !strstr(entries, "RGB8"));
    // The feature tree a GenICam browser shows.
    CHECK_CONTAINS(out, "feature ExposureTime\n");
    CHECK_CONTAINS(out, "feature Gain\n");
    CHECK_CONTAINS(out, "feature DeviceTemperature\n");
    CHECK_CONTAINS(out, "feature TriggerSoftware\n");
    CHECK(out && !strstr(out, "feature BinningHorizontal\n") && !strstr(out, "feature GainRaw\n"));
done:
    free(out);
    free(err);
    fx_gv_close(&F);
}

#define ARV_TOOL "arv-tool-0.8"   // only ever run as: arv-tool-0.8 -a 127.0.0.1 ... (no discovery)

// The Aravis command-line client, pointed at the virtual camera by address
// (never by discovery), lists and reads its features, and writes one that our
// own backend then reads back: the camera speaks GenICam as a real one does.
TEST(aravis_gv_arv_tool_by_address)
{
    char *out = NULL, *err = NULL;
    fx_gv_t F;
    if (!fx_gv_open(&F, false)) goto done;
    const char *features[] = { ARV_TOOL, "-a", ADDR, "features", NULL };
    int st = test_run(features, 30, &out, &err);
    CHECK_MSG(st == 0, "arv-tool features exited %d: %s", st, err ? err : "");
    CHECK_CONTAINS(out, "ExposureTime");
    CHECK_CONTAINS(out, "DeviceTemperature");
    CHECK_CONTAINS(out, "TriggerSoftware");
    CHECK_CONTAINS(out, "PixelFormat");
    CHECK(out && !strstr(out, "GainRaw"));
    free(out);
    free(err);
    out = err = NULL;
    const char *write[] = { ARV_TOOL, "-a", ADDR, "control", "ExposureTime=4321.5", "Gain=2.5",
                            "PixelFormat=Mono16", NULL };
    st = test_run(write, 30, &out, &err);
    CHECK_MSG(st == 0, "arv-tool control (write) exited %d: %s", st, err ? err : "");
    free(out);
    free(err);
    out = err = NULL;
    const char *read[] = { ARV_TOOL, "-a", ADDR, "control", "ExposureTime", "Gain", "PixelFormat",
                           "DeviceSerialNumber", "DeviceVendorName", "SensorWidth", NULL };
    st = test_run(read, 30, &out, &err);
    CHECK_MSG(st == 0, "arv-tool control (read) exited %d: %s", st, err ? err : "");
    CHECK_CONTAINS(out, "ExposureTime = 4321.5");
    CHECK_CONTAINS(out, "Gain = 2.5");
    CHECK_CONTAINS(out, "PixelFormat = Mono16");
    CHECK_CONTAINS(out, "DeviceSerialNumber = TEST-0042");
    CHECK_CONTAINS(out, "DeviceVendorName = refl-test");
    CHECK_CONTAINS(out, "SensorWidth = 1280");
    // What arv-tool wrote, our backend reads.
    int rc = rig_camera_open_aravis(&F.c, ADDR);
    CHECK_MSG(rc == 0, "open: %d %s", rc, model_last_error());
    if (rc) goto done;
    rig_frame_meta_t m;
    CHECK(rig_camera_settings(F.c, &m) == 0);
    CHECK_NEAR(m.exposure_us, 4321.5, 1e-6);
    CHECK_NEAR(m.gain, 2.5, 1e-9);
    CHECK(!strcmp(m.pixel_format, "Mono16"));
done:
    free(out);
    free(err);
    fx_gv_close(&F);
}

// Free running (TriggerMode Off, as a viewer would use it), by the same
// independent client: frames keep coming at the frame rate, each rendered
// ahead of the send by the render thread.
static const char freerun_py[] =
    "import sys, gi\n"
    "gi.require_version('Aravis', '0.8')\n"
    "from gi.repository import Aravis\n"
    "cam = Aravis.Camera.new(sys.argv[1])\n"
    "cam.set_region(0, 0, 256, 128)\n"
    "cam.set_pixel_format_from_string('Mono16')\n"
    "cam.set_exposure_time(1000.0)\n"
    "for f in ('ExposureAuto', 'GainAuto', 'ContrastAuto'): cam.set_string(f, 'Off')\n"   // the automatics
    "for f in ('GammaEnable', 'LUTEnable'): cam.set_boolean(f, False)\n"  // and tone curve: on at start
    "cam.set_frame_rate(50.0)\n"   // turns triggering off
    "print('TriggerMode', cam.get_string('TriggerMode'))\n"
    "stream = cam.create_stream(None, None)\n"
    "for i in range(4): stream.push_buffer(Aravis.Buffer.new_allocate(cam.get_payload()))\n"
    "cam.start_acquisition()\n"
    "ok = 0\n"
    "for i in range(10):\n"
    "    b = stream.timeout_pop_buffer(2000000)\n"
    "    if b is None: continue\n"
    "    d = b.get_image_data()\n"
    "    v = d[2 * (5 * 256 + 7)] | (d[2 * (5 * 256 + 7) + 1] << 8)\n"   // pixel (7, 5)
    "    ok += b.get_status() == Aravis.BufferStatus.SUCCESS and v == ((7 * 3 + 5 * 5) % 97 + 1) * 10\n"
    "    stream.push_buffer(b)\n"
    "cam.stop_acquisition()\n"
    "print('good frames', ok)\n";

TEST_ALONE(gv_camera_free_running_external_client)
{
    char *out = NULL, *err = NULL;
    fx_gv_t F;
    if (!fx_gv_open(&F, false)) goto done;
    rig_gv_camera_t *g = F.g;
    const char *script = test_write("freerun.py", freerun_py);
    const char *argv[] = { "/usr/bin/python3", script, ADDR, NULL };
    double t0 = now_s();
    int st = test_run(argv, 20, &out, &err);
    CHECK_MSG(st == 0, "python client exited %d: %s", st, err ? err : "");
    CHECK_CONTAINS(out, "TriggerMode Off\n");
    CHECK_CONTAINS(out, "good frames 10\n");
    CHECK(now_s() - t0 >= 9 * 0.02);   // 50 frames/s
    rig_gv_camera_stats_t s;
    rig_gv_camera_stats(g, &s);
    CHECK(s.triggers == 0 && s.frames_sent >= 10 && s.render_errors == 0);
    // Only the first frame may come before the render thread saw AcquisitionStart.
    CHECK_MSG(s.late_frames <= 1, "%llu frames were rendered in Aravis's thread", (unsigned long long)s.late_frames);
done:
    free(out);
    free(err);
    fx_gv_close(&F);
}

// A slow render (an imaging model) happens in the server's render thread:
// the camera keeps answering control requests meanwhile.
typedef struct {
    rig_camera_t *c;
    int rc;
    rig_frame_t f;
} capture_job_t;

static void *capture_thread(void *arg)
{
    capture_job_t *j = arg;
    j->rc = rig_camera_capture(j->c, 5.0, 0, &j->f);
    return NULL;
}

static double process_cpu_s(void)
{
    struct rusage ru;
    getrusage(RUSAGE_SELF, &ru);
    return ru.ru_utime.tv_sec + ru.ru_stime.tv_sec + 1e-6 * (ru.ru_utime.tv_usec + ru.ru_stime.tv_usec);
}

TEST_ALONE(aravis_gv_responsive_during_slow_render)
{
    fx_gv_t F;
    if (!fx_gv_open(&F, true)) goto done;
    fx_pattern_ctx_t *ctx = F.ctx;
    rig_camera_t *c = F.c;
    int rc;
    CHECK(rig_camera_set_region(c, 0, 0, 256, 256) == 0);
    rig_frame_t f;
    CHECK(rig_camera_capture(c, 2.0, 1, &f) == 0);   // stream started
    rig_frame_free(&f);
    atomic_store(&ctx->sleep_ms, 600);
    capture_job_t job = { .c = c };
    pthread_t th;
    double cpu0 = process_cpu_s();
    double t0 = now_s();
    pthread_create(&th, NULL, capture_thread, &job);
    usleep(150000);   // the render is under way now
    // (Only this test uses one handle from two threads: Aravis's control
    // channel is locked, and the capture thread is waiting on the stream.)
    rig_frame_meta_t s;
    double t1 = now_s();
    rc = rig_camera_settings(c, &s);
    double dt = now_s() - t1;
    CHECK_MSG(rc == 0, "settings during a render: %d %s", rc, model_last_error());
    CHECK_MSG(dt < 0.35, "control request took %.3f s during a 0.6 s render", dt);
    pthread_join(th, NULL);
    double total = now_s() - t0, cpu = process_cpu_s() - cpu0;
    CHECK_MSG(job.rc == 0, "capture: %d %s", job.rc, model_last_error());
    CHECK(total >= 0.6 && total < 3.0);
    // Waiting for a frame costs (almost) no CPU: no thread of the camera or the
    // client spins meanwhile (Aravis's GV thread did, at a 1 kHz trigger check).
    printf("  %.2f s CPU in a %.2f s wait for a slow render\n", cpu, total);
    CHECK_MSG(cpu < 0.25 * total, "%.2f s CPU in a %.2f s wait for a slow render", cpu, total);
    if (!job.rc) CHECK(fx_pattern_mismatches(&job.f) == 0);
    rig_frame_free(&job.f);
    atomic_store(&ctx->sleep_ms, 0);
done:
    fx_gv_close(&F);
}

// The camera disappears in the middle of a session: clear errors naming the
// camera, bounded time, no hang; closing is bounded too.
TEST_ALONE(aravis_gv_camera_disappears)
{
    fx_gv_t F;
    if (!fx_gv_open(&F, true)) goto done;
    rig_gv_camera_t *g = F.g;
    rig_camera_t *c = F.c;
    int rc;
    CHECK(rig_camera_set_region(c, 0, 0, 128, 128) == 0);
    rig_frame_t f;
    CHECK(rig_camera_capture(c, 1.0, 1, &f) == 0);
    rig_frame_free(&f);

    rig_gv_camera_stop(g);   // the camera is gone
    g = F.g = NULL;
    double t0 = now_s();
    rc = rig_camera_capture(c, 0.5, 1, &f);
    double dt = now_s() - t0;
    CHECK_MSG(rc == RIG_ERR_DISCONNECTED || rc == RIG_ERR_TIMEOUT, "capture on a lost camera: %d %s", rc,
              model_last_error());
    CHECK(f.pix == NULL);
    CHECK_MSG(dt < 8.0, "capture on a lost camera took %.1f s", dt);
    CHECK_CONTAINS(model_last_error(), "TEST-0042");
    CHECK_CONTAINS(model_last_error(), ADDR);
    CHECK_CONTAINS(model_last_error(), "check power, cable and network");
    // Later calls fail fast with the same verdict.
    t0 = now_s();
    rc = rig_camera_set_exposure_us(c, 2000);
    CHECK(rc == RIG_ERR_DISCONNECTED || rc == RIG_ERR_TIMEOUT);
    CHECK_CONTAINS(model_last_error(), "TEST-0042");
    CHECK(now_s() - t0 < 4.0);
    t0 = now_s();
    rig_camera_close(c);
    c = F.c = NULL;
    // Aravis 0.8 waits 5 x 500 ms per unanswered request; closing makes up to four.
    CHECK_MSG(now_s() - t0 < 12.0, "close of a lost camera took %.1f s", now_s() - t0);
done:
    fx_gv_close(&F);
}

TEST_ALONE(aravis_open_nothing_there)
{
    int session = test_camera_lock();
    // Also hold the lock of refl's servers on the address (rig/virtual/gv_camera.h):
    // no virtual camera of a demo may appear meanwhile.
    char name[64];
    snprintf(name, sizeof name, "refl-gvcam-%s.lock", ADDR);
    int fd = lock_file(name);
    CHECK(fd >= 0);
    rig_camera_t *c = (rig_camera_t *)&c;
    double t0 = now_s();
    int rc = rig_camera_open_aravis(&c, ADDR);
    double dt = now_s() - t0;
    CHECK(rc == RIG_ERR_NO_DEVICE && c == NULL);
    CHECK_CONTAINS(model_last_error(), "no camera at '127.0.0.1'");
    CHECK_CONTAINS(model_last_error(), "UDP 3956");
    CHECK_MSG(dt < 8.0, "open took %.1f s", dt);
    CHECK(rig_camera_open_aravis(&c, "") == RIG_ERR_INVALID);
    CHECK(rig_camera_open_aravis(NULL, ADDR) == RIG_ERR_INVALID);
    if (fd >= 0) close(fd);
    test_camera_unlock(session);
}

// The backend against Aravis's own fake camera, unmodified: ExposureTimeAbs
// (whole microseconds) instead of ExposureTime, GainRaw instead of Gain, colour
// formats and no Mono12, no DeviceTemperature, no DeviceSerialNumber.
TEST(aravis_plain_aravis_fake_camera)
{
    int session = test_camera_lock();
    char name[64];
    snprintf(name, sizeof name, "refl-gvcam-%s.lock", ADDR);   // the address is ours (rig/virtual/gv_camera.h)
    int fd = lock_file(name);
    CHECK(fd >= 0);
    ArvGvFakeCamera *gv = arv_gv_fake_camera_new(ADDR, "PLAIN-7");
    rig_camera_t *c = NULL;
    CHECK(gv && arv_gv_fake_camera_is_running(gv));
    if (!gv) goto done;
    arv_fake_camera_set_trigger_frequency(arv_gv_fake_camera_get_fake_camera(gv), 1000.0);
    int rc = rig_camera_open_aravis(&c, ADDR);
    CHECK_MSG(rc == 0, "open: %d %s", rc, model_last_error());
    if (rc) goto done;
    CHECK_CONTAINS(rig_camera_name(c), "Aravis Fake serial PLAIN-7 at 127.0.0.1");
    CHECK(rig_camera_set_pixel_format(c, "Mono12") == RIG_ERR_NOT_SUPPORTED);
    CHECK_CONTAINS(model_last_error(), "does not offer pixel format Mono12; it offers: ");
    CHECK_CONTAINS(model_last_error(), "Mono8");
    CHECK_CONTAINS(model_last_error(), "BayerGR8");
    CHECK(rig_camera_set_pixel_format(c, "Mono16") == 0);
    CHECK(rig_camera_set_exposure_us(c, 1234.5) == 0);   // an integer register: 1234 us
    CHECK(rig_camera_set_gain(c, 5) == 0);
    CHECK(rig_camera_set_gain(c, 11) == RIG_ERR_INVALID);
    CHECK(rig_camera_set_region(c, 8, 4, 200, 100) == 0);
    rig_frame_t f;
    for (int i = 0; i < 2; i++) {
        rc = rig_camera_capture(c, 2.0, 2, &f);
        CHECK_MSG(rc == 0, "capture: %d %s", rc, model_last_error());
        if (rc) break;
        CHECK(f.meta.width == 200 && f.meta.height == 100 && f.meta.offset_x == 8 && f.meta.offset_y == 4);
        CHECK(!strcmp(f.meta.pixel_format, "Mono16") && f.meta.bits == 16);
        CHECK_NEAR(f.meta.exposure_us, 1234, 1e-9);
        CHECK_NEAR(f.meta.gain, 5, 1e-12);
        CHECK(isnan(f.meta.temperature_c));
        CHECK(!strcmp(f.meta.serial, "PLAIN-7") && !strcmp(f.meta.vendor, "Aravis") && !strcmp(f.meta.model, "Fake"));
        bool varies = false;
        for (int k = 1; k < 200 * 100; k++) varies |= f.pix[k] != f.pix[0];
        CHECK(varies);   // Aravis's diagonal ramp
        rig_frame_free(&f);
    }
done:
    rig_camera_close(c);
    if (gv) g_object_unref(gv);
    if (fd >= 0) close(fd);
    test_camera_unlock(session);
}

TEST_ALONE(gv_camera_server_params)
{
    int session = test_camera_lock();
    fx_pattern_ctx_t *ctx = fx_pattern_ctx_new();
    rig_gv_camera_params_t p = rig_gv_camera_defaults();
    p.render = fx_render_pattern;
    p.render_ctx = ctx;
    rig_gv_camera_t *g = (rig_gv_camera_t *)&g;
    p.address = "192.168.1.20";
    CHECK(rig_gv_camera_start(&g, &p) == RIG_ERR_INVALID && g == NULL);
    CHECK_CONTAINS(model_last_error(), "not a loopback");
    p.address = ADDR;
    p.render = NULL;
    CHECK(rig_gv_camera_start(&g, &p) == RIG_ERR_INVALID);
    CHECK_CONTAINS(model_last_error(), "render callback");
    p.render = fx_render_pattern;
    p.serial = "A-SERIAL-THAT-IS-TOO-LONG";
    CHECK(rig_gv_camera_start(&g, &p) == RIG_ERR_INVALID);
    p.serial = NULL;
    p.sensor_width = 0;
    CHECK(rig_gv_camera_start(&g, &p) == RIG_ERR_INVALID);
    p.sensor_width = 1280;
    p.busy_wait_s = 120;
    // One server per address: a second one waits, then fails with RIG_ERR_BUSY.
    CHECK(rig_gv_camera_start(&g, &p) == 0);
    rig_gv_camera_params_t q = p;
    q.busy_wait_s = 0.2;
    rig_gv_camera_t *g2 = NULL;
    double t0 = now_s();
    CHECK(rig_gv_camera_start(&g2, &q) == RIG_ERR_BUSY && g2 == NULL);
    CHECK(now_s() - t0 >= 0.2);
    CHECK_CONTAINS(model_last_error(), "127.0.0.1");
    rig_gv_camera_stop(g);
    rig_gv_camera_stop(NULL);
    fx_pattern_ctx_free(ctx);
    test_camera_unlock(session);
}
