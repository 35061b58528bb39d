// tests/test_rig_camera_settings.c — the camera settings refl enforces and
// records (rig/camera/aravis.c): the virtual camera's automatics (ExposureAuto,
// GainAuto, BalanceWhiteAuto), gamma and LUT are on at start, as on real
// cameras; refl switches them off at open, reads them back and records them with
// every frame (metadata, PNG text, journal columns, session export, session
// facts, refl rig status). A frame
// with them on differs from refl's. The gain's unit comes from GenICam (dB, a
// factor, none = raw) and feeds model_gain_factor. A camera that refuses to
// switch ExposureAuto off cannot be opened (the error names the feature and the
// camera); BalanceWhiteAuto on a mono camera is only a warning.
//
// The cameras are in-process (rig/virtual/gv_camera.h: no network, no lock on
// 127.0.0.1), each with a serial of its own, so these tests run beside others.
#define _GNU_SOURCE
#include <arv.h>
#include <glib.h>
#include <jansson.h>
#include <limits.h>
#include <math.h>
#include <sqlite3.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "model/model.h"
#include "rig/virtual/gv_camera.h"
#include "rig/rig.h"
#include "tests/fixtures.h"
#include "tests/test.h"

typedef struct {
    fx_pattern_ctx_t *ctx;
    rig_gv_camera_t  *g;
    ArvDevice        *dev;      // the same camera as Aravis sees it (the test's own client)
    char              id[64];
} cam_t;

// Start an in-process pattern camera (serial, gain unit, feature to refuse).
static bool cam_start(cam_t *k, const char *serial, const char *gain_unit, const char *refuse_off)
{
    memset(k, 0, sizeof *k);
    k->ctx = fx_pattern_ctx_new();
    rig_gv_camera_params_t p = rig_gv_camera_defaults();
    p.serial = serial;
    p.vendor = "refl-test";
    p.model = "settings cam";
    p.sensor_width = 320;
    p.sensor_height = 240;
    p.inprocess = true;
    p.render = fx_render_pattern;
    p.render_ctx = k->ctx;
    p.gain_unit = gain_unit;
    p.refuse_off = refuse_off;
    p.firmware = "fw 2.5.1";
    int rc = rig_gv_camera_start(&k->g, &p);
    CHECK_MSG(rc == 0, "rig_gv_camera_start: %d %s", rc, model_last_error());
    snprintf(k->id, sizeof k->id, "%s%s", RIG_GV_INPROCESS_PREFIX, serial);
    k->dev = k->g ? rig_gv_camera_inprocess_device(serial) : NULL;
    CHECK(k->dev != NULL);
    return k->dev != NULL;
}

static void cam_stop(cam_t *k)
{
    if (k->dev) g_object_unref(k->dev);
    rig_gv_camera_stop(k->g);
    fx_pattern_ctx_free(k->ctx);
    memset(k, 0, sizeof *k);
}

// A feature's value as text, through Aravis directly ("?" on error).
static const char *feature_text(ArvDevice *dev, const char *name, char *buf, size_t size)
{
    GError *e = NULL;
    ArvGcNode *n = arv_device_get_feature(dev, name);
    snprintf(buf, size, "?");
    if (n && ARV_IS_GC_BOOLEAN(n)) {
        gboolean v = arv_gc_boolean_get_value(ARV_GC_BOOLEAN(n), &e);
        if (!e) snprintf(buf, size, "%d", v ? 1 : 0);
    } else if (n && ARV_IS_GC_ENUMERATION(n)) {
        const char *v = arv_gc_enumeration_get_string_value(ARV_GC_ENUMERATION(n), &e);
        if (!e && v) snprintf(buf, size, "%s", v);
    } else if (n) {
        const char *v = arv_device_get_string_feature_value(dev, name, &e);
        if (!e && v) snprintf(buf, size, "%s", v);
    }
    g_clear_error(&e);
    return buf;
}

TEST(camera_settings_automatics_off_recorded)
{
    cam_t k;
    rig_camera_t *c = NULL;
    rig_frame_t f = { 0 };
    char b[64];
    if (!cam_start(&k, "CAMSET-1", NULL, NULL)) goto done;
    // As a real camera starts: automatics, gamma and LUT on.
    CHECK(!strcmp(feature_text(k.dev, "ExposureAuto", b, sizeof b), "Continuous"));
    CHECK(!strcmp(feature_text(k.dev, "GainAuto", b, sizeof b), "Continuous"));
    CHECK(!strcmp(feature_text(k.dev, "BalanceWhiteAuto", b, sizeof b), "Continuous"));
    CHECK(!strcmp(feature_text(k.dev, "GammaEnable", b, sizeof b), "1"));
    CHECK(!strcmp(feature_text(k.dev, "LUTEnable", b, sizeof b), "1"));
    CHECK(!strcmp(feature_text(k.dev, "ContrastAuto", b, sizeof b), "Continuous"));   // a vendor's own

    int rc = rig_camera_open_aravis(&c, k.id);
    CHECK_MSG(rc == 0, "open: %d %s", rc, model_last_error());
    if (rc) goto done;
    // Switched off: the camera itself reads Off.
    CHECK(!strcmp(feature_text(k.dev, "ExposureAuto", b, sizeof b), "Off"));
    CHECK(!strcmp(feature_text(k.dev, "GainAuto", b, sizeof b), "Off"));
    CHECK(!strcmp(feature_text(k.dev, "BalanceWhiteAuto", b, sizeof b), "Off"));
    CHECK(!strcmp(feature_text(k.dev, "GammaEnable", b, sizeof b), "0"));
    CHECK(!strcmp(feature_text(k.dev, "LUTEnable", b, sizeof b), "0"));
    CHECK(!strcmp(feature_text(k.dev, "ContrastAuto", b, sizeof b), "Off"));

    CHECK(rig_camera_set_pixel_format(c, "Mono12") == 0);
    CHECK(rig_camera_set_exposure_us(c, 2000) == 0);
    CHECK(rig_camera_set_gain(c, 6) == 0);
    rig_frame_meta_t s;
    CHECK(rig_camera_settings(c, &s) == 0);
    CHECK(!strcmp(s.gain_unit, "dB"));
    CHECK_NEAR(s.gamma, 1, 0);
    CHECK_NEAR(s.black_level, 0, 0);
    CHECK(!strcmp(s.firmware, "fw 2.5.1"));
    CHECK_CONTAINS(s.camera_settings, "ExposureAuto=Off (was Continuous)");
    CHECK_CONTAINS(s.camera_settings, "GainAuto=Off (was Continuous)");
    CHECK_CONTAINS(s.camera_settings, "BalanceWhiteAuto=Off (was Continuous)");
    CHECK_CONTAINS(s.camera_settings, "GammaEnable=0 (was 1)");
    CHECK_CONTAINS(s.camera_settings, "LUTEnable=0 (was 1)");
    CHECK_CONTAINS(s.camera_settings, "ContrastAuto=Off (was Continuous)");
    CHECK_CONTAINS(s.camera_settings, "BlackLevel=0");
    CHECK_CONTAINS(s.camera_settings, "GevSCPSPacketSize=8192");

    // refl's frame: the sensor's own values (the pattern), the settings with it.
    rc = rig_camera_capture(c, 5, 1, &f);
    CHECK_MSG(rc == 0, "capture: %d %s", rc, model_last_error());
    if (rc) goto done;
    CHECK(fx_pattern_mismatches(&f) == 0);
    CHECK(!strcmp(f.meta.gain_unit, "dB") && f.meta.gamma == 1 && !strcmp(f.meta.firmware, "fw 2.5.1"));
    CHECK_CONTAINS(f.meta.camera_settings, "ExposureAuto=Off");
    rig_frame_free(&f);

    // The same camera with the automatics and tone curve left on (switched on
    // by the test's own Aravis client): its frames are not the sensor's values.
    static const struct { const char *name; bool boolean; } on[] = {
        { "ExposureAuto", false }, { "GammaEnable", true }, { "LUTEnable", true }, { "GainAuto", false },
        { "ContrastAuto", false },
    };
    for (size_t i = 0; i < sizeof on / sizeof on[0]; i++) {
        GError *e = NULL;
        long before = -1;
        if (on[i].boolean) arv_device_set_boolean_feature_value(k.dev, on[i].name, TRUE, &e);
        else arv_device_set_string_feature_value(k.dev, on[i].name, "Continuous", &e);
        CHECK_MSG(!e, "%s: %s", on[i].name, e ? e->message : "");
        g_clear_error(&e);
        rc = rig_camera_capture(c, 5, 1, &f);
        CHECK_MSG(rc == 0, "capture with %s on: %d %s", on[i].name, rc, model_last_error());
        if (rc) break;
        before = fx_pattern_mismatches(&f);
        CHECK_MSG(before > (long)f.meta.width * f.meta.height / 2, "%s on: only %ld pixels differ", on[i].name,
                  before);
        rig_frame_free(&f);
        if (on[i].boolean) arv_device_set_boolean_feature_value(k.dev, on[i].name, FALSE, &e);
        else arv_device_set_string_feature_value(k.dev, on[i].name, "Off", &e);
        g_clear_error(&e);
    }
done:
    rig_frame_free(&f);
    rig_camera_close(c);
    cam_stop(&k);
}

// The gain's unit from GenICam: dB, a factor, none (raw); used by model_gain_factor.
TEST(camera_settings_gain_unit_from_genicam)
{
    static const struct { const char *serial, *xml_unit, *recorded; double gain, factor; bool usable; } cases[] = {
        { "CAMSET-DB", NULL, "dB", 6, 1.9952623149688795, true },
        { "CAMSET-X", "x", "x", 2.5, 2.5, true },
        { "CAMSET-RAW", "", "raw", 6, 0, false },   // no unit stated: not assumed to be dB
        { "CAMSET-RAW0", "", "raw", 0, 1, true },   // raw at the calibration's gain (0) is usable
    };
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
        cam_t k;
        rig_camera_t *c = NULL;
        rig_frame_t f = { 0 };
        if (!cam_start(&k, cases[i].serial, cases[i].xml_unit, NULL)) {
            cam_stop(&k);
            continue;
        }
        int rc = rig_camera_open_aravis(&c, k.id);
        CHECK_MSG(rc == 0, "open %s: %d %s", cases[i].serial, rc, model_last_error());
        if (!rc) rc = rig_camera_set_gain(c, cases[i].gain);
        if (!rc) rc = rig_camera_capture(c, 5, 1, &f);
        CHECK_MSG(rc == 0, "%s: %d %s", cases[i].serial, rc, model_last_error());
        if (!rc) {
            CHECK_MSG(!strcmp(f.meta.gain_unit, cases[i].recorded), "%s: unit '%s'", cases[i].serial,
                      f.meta.gain_unit);
            double gf = -1;
            bool ok = model_gain_factor(f.meta.gain, f.meta.gain_unit, 0, cases[i].recorded[0] == 'r' ? "raw" : "dB",
                                        "frames/s000003.png", &gf);
            CHECK(ok == cases[i].usable);
            if (ok) CHECK_REL(gf, cases[i].factor, 1e-12);
            else CHECK_CONTAINS(model_last_error(), "frames/s000003.png");
        }
        rig_frame_free(&f);
        rig_camera_close(c);
        cam_stop(&k);
    }
}

// A camera that will not switch ExposureAuto off cannot be used; one whose
// BalanceWhiteAuto stays on (a mono sensor: harmless) can, with a warning.
TEST(camera_settings_refused_auto)
{
    cam_t k;
    rig_camera_t *c = NULL;
    if (cam_start(&k, "CAMSET-REF", NULL, "ExposureAuto")) {
        int rc = rig_camera_open_aravis(&c, k.id);
        CHECK(rc == RIG_ERR_NOT_SUPPORTED && c == NULL);
        CHECK_CONTAINS(model_last_error(), "cannot switch ExposureAuto off");
        CHECK_CONTAINS(model_last_error(), "serial CAMSET-REF");
        CHECK_CONTAINS(model_last_error(), "Continuous");
    }
    cam_stop(&k);
    rig_camera_close(c);
    c = NULL;
    if (cam_start(&k, "CAMSET-BW", NULL, "BalanceWhiteAuto")) {
        int rc = rig_camera_open_aravis(&c, k.id);
        CHECK_MSG(rc == 0, "open: %d %s", rc, model_last_error());
        rig_frame_meta_t s;
        if (!rc && rig_camera_settings(c, &s) == 0) {
            CHECK_CONTAINS(s.camera_settings, "BalanceWhiteAuto=Continuous (warning: cannot be switched off");
            CHECK_CONTAINS(s.camera_settings, "harmless on a mono camera");
            CHECK_CONTAINS(s.camera_settings, "ExposureAuto=Off (was Continuous)");
        }
    }
    rig_camera_close(c);
    cam_stop(&k);
    // A bad variant is refused with a message.
    rig_gv_camera_params_t p = rig_gv_camera_defaults();
    p.inprocess = true;
    p.serial = "CAMSET-BAD";
    p.render = fx_render_pattern;
    p.refuse_off = "Gamma";
    rig_gv_camera_t *g = NULL;
    CHECK(rig_gv_camera_start(&g, &p) == RIG_ERR_INVALID && !g);
    CHECK_CONTAINS(model_last_error(), "refuse_off 'Gamma'");
}

// Recorded per frame: a session on the virtual rig (camera in-process) has the
// settings in every frame's PNG text, the journal's columns and the export;
// refl rig status shows them.
TEST(camera_settings_in_session_and_status)
{
    char top[PATH_MAX], text[PATH_MAX + 256];
    if (!realpath(test_srcdir(), top)) snprintf(top, sizeof top, "%s", test_srcdir());
    snprintf(text, sizeof text, "[rig]\nbackend = virtual\ntruth = %s/examples/virtual-truth.ini\nserve = inprocess\n"
             "time_scale = 0.01\n", top);
    const char *rig = test_write("rig.ini", text);
    const char *plan = test_write("plan.ini", "[sample]\nname = coupon_matte_paint\nkind = material_coupon\n"
                                  "[angles]\nlist = 0\n[lamps]\nsets = east; none\n[exposure]\nmode = fixed\n"
                                  "list_us = 2000\ngain = 3\npixel_format = Mono12\n");
    char dir[4096];
    snprintf(dir, sizeof dir, "%s/s", test_tmpdir());
    char *out = NULL, *err = NULL;
    int rc = test_refl_run(120, &out, &err, "capture", plan, "--rig", rig, "-o", dir, "--yes", NULL);
    CHECK_MSG(rc == 0, "capture: %s", err);
    g_free(out);
    g_free(err);

    char png[4200];
    snprintf(png, sizeof png, "%s/frames/s000001.png", dir);   // step 0: the operator's
    model_meta_t *meta = model_meta_new();
    int w = 0, h = 0;
    uint16_t *pix = NULL;
    CHECK(model_png_read_meta(png, &w, &h, &pix, meta));
    free(pix);
    const char *v;
    CHECK((v = model_meta_get(meta, "gain")) && !strcmp(v, "3"));
    CHECK((v = model_meta_get(meta, "gain_unit")) && !strcmp(v, "dB"));
    CHECK((v = model_meta_get(meta, "gamma")) && !strcmp(v, "1"));
    CHECK((v = model_meta_get(meta, "black_level")) && !strcmp(v, "0"));
    CHECK((v = model_meta_get(meta, "camera_firmware")) && !strcmp(v, "refl-gv 1.0"));
    CHECK((v = model_meta_get(meta, "temperature_c")) != NULL);
    v = model_meta_get(meta, "camera_settings");
    CHECK(v != NULL);
    if (v) {
        CHECK_CONTAINS(v, "ExposureAuto=Off (was Continuous)");
        CHECK_CONTAINS(v, "GainAuto=Off (was Continuous)");
        CHECK_CONTAINS(v, "GammaEnable=0 (was 1)");
        CHECK_CONTAINS(v, "LUTEnable=0 (was 1)");
    }
    model_meta_free(meta);

    rc = test_refl_run(60, &out, &err, "session", "export", dir, "--format", "csv", NULL);
    CHECK_MSG(rc == 0, "export: %s", err);
    CHECK_CONTAINS(out, ",gain_unit,black_level,gamma,temperature_c,firmware,camera_settings,camera\n");
    CHECK_CONTAINS(out, ",3,");
    CHECK_CONTAINS(out, ",dB,0,1,");
    CHECK_CONTAINS(out, ",refl-gv 1.0,ExposureAuto=Off (was Continuous) GainAuto=Off");
    g_free(out);
    g_free(err);
    rc = test_refl_run(60, &out, &err, "session", "export", dir, "--format", "json", NULL);
    CHECK_MSG(rc == 0, "export: %s", err);
    CHECK_CONTAINS(out, "\"gain_unit\": \"dB\"");
    CHECK_CONTAINS(out, "LUTEnable=0 (was 1)");
    g_free(out);
    g_free(err);

    // the session facts: the camera's settings at the start
    char db[4200];
    snprintf(db, sizeof db, "%s/session.sqlite", dir);
    sqlite3 *d = NULL;
    char *facts = NULL;
    if (sqlite3_open_v2(db, &d, SQLITE_OPEN_READONLY, NULL) == SQLITE_OK) {
        sqlite3_stmt *st = NULL;
        if (sqlite3_prepare_v2(d, "SELECT facts_json FROM session", -1, &st, NULL) == SQLITE_OK &&
            sqlite3_step(st) == SQLITE_ROW && sqlite3_column_text(st, 0))
            facts = g_strdup((const char *)sqlite3_column_text(st, 0));
        sqlite3_finalize(st);
    }
    sqlite3_close(d);
    CHECK(facts != NULL);
    if (facts) {
        json_t *j = json_loads(facts, 0, NULL);
        json_t *cam = json_object_get(j, "camera");
        CHECK(cam != NULL);
        CHECK(!strcmp(json_string_value(json_object_get(cam, "gain_unit")) ?: "", "dB"));
        CHECK(!strcmp(json_string_value(json_object_get(cam, "firmware")) ?: "", "refl-gv 1.0"));
        CHECK_CONTAINS(json_string_value(json_object_get(cam, "settings")) ?: "", "ExposureAuto=Off (was Continuous)");
        json_decref(j);
    }
    g_free(facts);

    rc = test_refl_run(60, &out, &err, "rig", "--rig", rig, "status", NULL);
    CHECK_MSG(rc == 0, "status: %s", err);
    CHECK_CONTAINS(out, "camera_gain: 0 dB\n");
    CHECK_CONTAINS(out, "camera_firmware: refl-gv 1.0\n");
    CHECK_CONTAINS(out, "camera_gamma: 1\n");
    CHECK_CONTAINS(out, "camera_settings: ExposureAuto=Off (was Continuous)");
    g_free(out);
    g_free(err);

    // A journal of schema version 1 (no gain_unit ... camera_settings columns)
    // still reads: the missing columns are empty (a gain without unit is dB).
    d = NULL;
    CHECK(sqlite3_open(db, &d) == SQLITE_OK);
    static const char *const newer[] = { "gain_unit", "black_level", "gamma", "temperature_c", "firmware",
                                         "camera_settings" };
    for (size_t i = 0; d && i < sizeof newer / sizeof newer[0]; i++) {
        char sql[128];
        snprintf(sql, sizeof sql, "ALTER TABLE frames DROP COLUMN %s", newer[i]);
        CHECK_MSG(sqlite3_exec(d, sql, NULL, NULL, NULL) == SQLITE_OK, "%s: %s", sql, sqlite3_errmsg(d));
    }
    sqlite3_close(d);
    rc = test_refl_run(60, &out, &err, "session", "export", dir, "--format", "csv", NULL);
    CHECK_MSG(rc == 0, "export of an older journal: %s", err);
    CHECK_CONTAINS(out, ",gain_unit,black_level,gamma,temperature_c,firmware,camera_settings,camera\n");
    CHECK_CONTAINS(out, ",,0,0,0.00,,,camera\n");
    g_free(out);
    g_free(err);
    rc = test_refl_run(60, &out, &err, "session", "check", dir, NULL);
    CHECK_MSG(rc == 0, "check of an older journal: %s", err);
    g_free(out);
    g_free(err);

    // ... and resumes: its last step undone, refl capture --resume adds the
    // columns and records the settings with the new frame.
    char f1[4200];
    snprintf(f1, sizeof f1, "%s/frames/s000001.png", dir);
    CHECK(remove(f1) == 0);
    CHECK(sqlite3_open(db, &d) == SQLITE_OK);
    CHECK(sqlite3_exec(d, "DELETE FROM frames WHERE step=1; UPDATE steps SET status='pending' WHERE idx=1; "
                       "UPDATE session SET state='paused'", NULL, NULL, NULL) == SQLITE_OK);
    sqlite3_close(d);
    rc = test_refl_run(120, &out, &err, "capture", "--resume", dir, NULL);
    CHECK_MSG(rc == 0, "resume of an older journal: %s", err);
    g_free(out);
    g_free(err);
    rc = test_refl_run(60, &out, &err, "session", "export", dir, "--format", "csv", NULL);
    CHECK_MSG(rc == 0, "export: %s", err);
    CHECK_CONTAINS(out, ",,0,0,0.00,,,camera\n");                                   // step 2: as schema 1 holds it
    CHECK_CONTAINS(out, ",dB,0,1,");                                          // step 1: this refl's
    CHECK_CONTAINS(out, ",refl-gv 1.0,ExposureAuto=Off (was Continuous)");
    g_free(out);
    g_free(err);
}

// [camera] / [rig] packet_size and packet_delay: parsed, range-checked (the
// file's range, then the camera's), applied at open and read back.
TEST(camera_settings_packet_keys)
{
    char top[PATH_MAX], text[PATH_MAX + 512];
    if (!realpath(test_srcdir(), top)) snprintf(top, sizeof top, "%s", test_srcdir());
    snprintf(text, sizeof text, "[rig]\nbackend = virtual\ntruth = %s/examples/virtual-truth.ini\nserve = inprocess\n"
             "time_scale = 0.01\npacket_size = 1500\npacket_delay = 2000\n", top);
    const char *path = test_write("packets.ini", text);
    rig_t *r = NULL;
    int rc = rig_open(&r, path);
    CHECK_MSG(rc == 0, "rig_open: %s", model_last_error());
    if (r) {
        rig_frame_meta_t m;
        CHECK(rig_camera_settings(r->camera, &m) == 0);
        CHECK_CONTAINS(m.camera_settings, "GevSCPSPacketSize=1500");
        CHECK_CONTAINS(m.camera_settings, "GevSCPD=2000");
        CHECK(!strstr(m.camera_settings, "GevSCPSPacketSize=8192"));
        ArvDevice *dev = rig_gv_camera_inprocess_device("REFL-VIRT01");
        CHECK(dev != NULL);
        if (dev) {
            GError *e = NULL;
            CHECK(arv_device_get_integer_feature_value(dev, "GevSCPSPacketSize", &e) == 1500 && !e);
            g_clear_error(&e);
            CHECK(arv_device_get_integer_feature_value(dev, "GevSCPD", &e) == 2000 && !e);
            g_clear_error(&e);
            g_object_unref(dev);
        }
        rig_frame_t f;
        rc = rig_camera_capture(r->camera, 10, 1, &f);
        CHECK_MSG(rc == 0, "capture: %s", model_last_error());
        if (!rc) CHECK_CONTAINS(f.meta.camera_settings, "GevSCPSPacketSize=1500 GevSCPD=2000");
        rig_frame_free(&f);
    }
    rig_close(r);

    static const struct { const char *keys, *want; } bad[] = {
        { "packet_size = 100\n", ":6: " },
        { "packet_size = 1500.5\n", ":6: " },
        { "packet_delay = -1\n", ":6: " },
        { "packet_delay = 2000000\n", "GevSCPD 2000000 ticks is outside the camera's range 0..1000000" },
        { "packet_size = 16000\n", "GevSCPSPacketSize 16000 bytes is outside the camera's range 576..9000" },
    };
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        snprintf(text, sizeof text, "[rig]\nbackend = virtual\ntruth = %s/examples/virtual-truth.ini\n"
                 "serve = inprocess\ntime_scale = 0.01\n%s", top, bad[i].keys);
        path = test_write("bad-packets.ini", text);
        r = (rig_t *)1;
        rc = rig_open(&r, path);
        CHECK_MSG(rc == RIG_ERR_INVALID && r == NULL, "%s: %d", bad[i].keys, rc);
        CHECK_CONTAINS(model_last_error(), path);
        CHECK_CONTAINS(model_last_error(), bad[i].want);
    }
}

// Over GigE Vision (127.0.0.1, the camera lock of tests/test.h): the stream
// packets set and read back, frames still whole; the automatics switched off.
TEST(camera_settings_gige_packets)
{
    fx_gv_t F;
    rig_frame_t f = { 0 };
    if (!fx_gv_open(&F, true)) goto done;
    int rc = rig_camera_set_stream_packets(F.c, 1500, 100);
    CHECK_MSG(rc == 0, "%d %s", rc, model_last_error());
    CHECK(rig_camera_set_stream_packets(F.c, 9001, -1) == RIG_ERR_INVALID);
    CHECK_CONTAINS(model_last_error(), "GevSCPSPacketSize 9001 bytes is outside the camera's range 576..9000");
    CHECK(rig_camera_set_region(F.c, 0, 0, 320, 240) == 0 && rig_camera_set_pixel_format(F.c, "Mono12") == 0);
    rc = rig_camera_capture(F.c, 5, 2, &f);
    CHECK_MSG(rc == 0, "capture: %d %s", rc, model_last_error());
    if (rc) goto done;
    CHECK(fx_pattern_mismatches(&f) == 0);
    CHECK_CONTAINS(f.meta.camera_settings, "ExposureAuto=Off (was Continuous)");
    CHECK_CONTAINS(f.meta.camera_settings, "GevSCPSPacketSize=1500");
    CHECK_CONTAINS(f.meta.camera_settings, "GevSCPD=100");
    CHECK(!strcmp(f.meta.gain_unit, "dB"));
done:
    rig_frame_free(&f);
    fx_gv_close(&F);
}
