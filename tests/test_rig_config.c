// tests/test_rig_config.c — rig description files (rig/config.c): valid files
// on simulated devices and on the virtual rig, every error with its file:line
// message, and that nothing stays open after an error.
#define _GNU_SOURCE
#include <fcntl.h>
#include <glib.h>
#include <limits.h>
#include <math.h>
#include <stdlib.h>
#include <sys/file.h>
#include <unistd.h>

#include "model/model.h"
#include "rig/rig.h"
#include "tests/test.h"



// The example truth file, absolute (rig files in the temporary directory point to it).
static const char *truth_path(void)
{
    static char buf[PATH_MAX + 64];
    char top[PATH_MAX];
    if (!realpath(test_srcdir(), top)) snprintf(top, sizeof top, "%s", test_srcdir());
    snprintf(buf, sizeof buf, "%s/examples/virtual-truth.ini", top);
    return buf;
}

TEST(rigcfg_sim_devices)
{
    const char *path = test_write("sim.ini",
                                  "# a simulated rig\n"
                                  "[turntable]\n"
                                  "backend = sim\n"
                                  "speed_deg_s = 20\n"
                                  "accel_deg_s2 = 40\n"
                                  "home_time_s = 2\n"
                                  "position_noise_deg = 0\n"
                                  "time_scale = 0.001\n"
                                  "seed = 7\n"
                                  "\n"
                                  "[lamp key]\n"
                                  "backend = sim\n"
                                  "position_mm = 100 -50.5 600\n"
                                  "warmup_ms = 1.5\n"
                                  "settle_ms = 0.5\n"
                                  "[lamp fill light]\n"
                                  "backend = sim\n");
    rig_t *r = NULL;
    int rc = rig_open(&r, path);
    CHECK_MSG(rc == 0, "rig_open: %d %s", rc, model_last_error());
    if (rc) return;
    char sha[65];
    CHECK(model_sha256_file(path, sha));
    CHECK(!strcmp(r->sha256, sha));
    CHECK(!strcmp(r->path, path));
    CHECK(r->camera == NULL && r->virt == NULL);
    CHECK(r->turntable && !strcmp(rig_turntable_backend(r->turntable), "sim"));
    CHECK_CONTAINS(rig_turntable_name(r->turntable), "seed 7");
    CHECK(r->lamps && rig_lamps_count(r->lamps) == 2 && rig_lamps_on_mask(r->lamps) == 0);
    if (r->lamps && rig_lamps_count(r->lamps) == 2) {
        CHECK(!strcmp(rig_lamps_name(r->lamps, 0), "key"));
        CHECK(!strcmp(rig_lamps_name(r->lamps, 1), "fill light"));
        CHECK_NEAR(rig_lamps_line(r->lamps, 0)->warmup_ms, 1.5, 0);
        CHECK_NEAR(rig_lamps_line(r->lamps, 0)->settle_ms, 0.5, 0);
        CHECK(!strcmp(rig_lamps_backend(r->lamps), "sim"));
    }
    // Camera defaults absent; the profile in real time (time_scale applied).
    CHECK(r->pixel_format[0] == 0 && isnan(r->exposure_us) && isnan(r->gain));
    CHECK_REL(r->speed_deg_s, 20 / 0.001, 1e-12);
    CHECK_REL(r->accel_deg_s2, 40 / 1e-6, 1e-12);
    CHECK_REL(r->home_time_s, 0.002, 1e-12);
    // The devices work: home, move, lamps.
    CHECK(rig_turntable_home(r->turntable, 5) == 0);
    CHECK(rig_turntable_move_abs_deg(r->turntable, 45, 5) == 0);
    rig_turntable_status_t st;
    CHECK(rig_turntable_status(r->turntable, &st) == 0);
    CHECK_NEAR(st.angle_deg, 45, 1e-9);   // position_noise_deg = 0
    CHECK(st.homed && !st.moving);
    CHECK(rig_lamps_set(r->lamps, 2) == 0);
    CHECK(rig_lamps_on_mask(r->lamps) == 2);
    rig_close(r);
    rig_close(NULL);
}

// The example real rig parses completely: the first device error (no APT
// stage here) comes from opening, and names the [turntable] line.
TEST(rigcfg_lab_example_parses)
{
    char path[1024];
    snprintf(path, sizeof path, "%s/examples/lab-rig.ini", test_srcdir());
    rig_t *r = (rig_t *)1;
    int rc = rig_open(&r, path);
    CHECK(rc == RIG_ERR_NO_DEVICE);
    CHECK(r == NULL);
    char want[1100];
    snprintf(want, sizeof want, "%s:34: [turntable]: apt serial 55000001", path);
    CHECK_CONTAINS(model_last_error(), want);
    CHECK(!strcmp(model_last_error(), model_last_error()));
}

typedef struct {
    const char *text;
    const char *want[3];
} bad_case_t;

static const bad_case_t bad_cases[] = {
    { "[turntable]\nbackend = sim\n[lamps x]\nbackend = sim\n", { ":3: unknown section [lamps x]", "[lamp NAME]" } },
    { "[turntable]\nbackend = sim\nspeed = 3\n", { ":3: [turntable]: unknown key 'speed' for backend sim",
                                                    "speed_deg_s" } },
    { "[turntable]\nspeed_deg_s = 3\n", { ":1: [turntable] has no backend: add 'backend = apt'", "backend = sim" } },
    { "\n[turntable]\nbackend = stepper\n", { ":3: [turntable]: unknown backend 'stepper'", "'backend = apt'" } },
    { "[turntable]\nbackend = sim\nspeed_deg_s = fast\n", { ":3: [turntable] speed_deg_s: 'fast' is not a number" } },
    { "[turntable]\nbackend = sim\naccel_deg_s2 = -1\n", { ":3: [turntable] accel_deg_s2 = -1 is out of range" } },
    { "[turntable]\nbackend = sim\nseed = 1.5\n", { ":3: [turntable] seed: '1.5' is not an integer" } },
    { "[turntable]\nbackend = sim\nfault_after_moves = 2\n", { ":3: [turntable] fault_after_moves needs 'fault" } },
    { "[turntable]\nbackend = sim\nfault_after_moves = 2\nfault = fire\n", { ":4: [turntable] fault: 'fire'" } },
    { "[turntable]\nbackend = apt\nstage = K99\n", { ":3: [turntable] stage: 'K99' is not a stage", "K10CR1" } },
    { "[turntable]\nbackend = apt\nspeed_deg_s = 3\n", { ":3: [turntable]: unknown key 'speed_deg_s' for backend apt" } },
    { "[lamp a]\nbackend = sim\n\n[lamp a]\nbackend = sim\n", { ":4: duplicate section [lamp a] (first at line 1)" } },
    { "[lamp a]\nbackend = sim\n[lamp   a]\nbackend = sim\n", { ":3: duplicate section [lamp a]" } },
    { "[lamp]\nbackend = sim\n", { ":1: [lamp] needs a name" } },
    { "[lamp all]\nbackend = sim\n", { ":1: [lamp all]: lamp names may not contain ','" } },
    { "[lamp a,b]\nbackend = sim\n", { ":1: [lamp a,b]: lamp names may not" } },
    { "[lamp a]\nbackend = sim\nposition_mm = 1 2\n", { ":3: [lamp a] position_mm: '1 2' is not three numbers" } },
    { "[lamp a]\nbackend = sim\nwarmup_ms = 4e6\n", { ":3: [lamp a] warmup_ms = 4e6 is out of range" } },
    { "[lamp a]\nbackend = sim\nchip = gpiochip0\n", { ":3: [lamp a]: unknown key 'chip' for backend sim" } },
    { "[lamp a]\nbackend = gpiod\nchip = gpiochip0\n", { ":1: [lamp a]: backend gpiod needs 'chip = gpiochipN'",
                                                         "'line = OFFSET'" } },
    { "[lamp a]\nbackend = gpiod\nchip = gpiochip0\nline = x\n", { ":4: [lamp a] line: 'x' is not an integer" } },
    { "[lamp a]\nbackend = gpiod\nchip = gpiochip0\nline = 1\nactive_low = maybe\n",
      { ":5: [lamp a] active_low: 'maybe' is not a truth value" } },
    { "[lamp a]\nbackend = gpiod\nchip = gpiochip0\nline = 1\n[lamp b]\nbackend = gpiod\nchip = gpiochip0\nline = 1\n",
      { ":8: [lamp b]: gpiochip0 line 1 is already lamp 'a' (line 1)" } },
    { "[lamp a]\nbackend = sim\n[lamp b]\nbackend = gpiod\nchip = gpiochip0\nline = 1\n",
      { ":4: [lamp b]: backend gpiod, but [lamp a] (line 1) is sim", "one backend" } },
    { "[camera]\nbackend = aravis\nexposure_us = 100\n", { ":1: [camera] does not say which camera",
                                                           "'address = IP'" } },
    { "[camera]\nbackend = aravis\naddress = 127.0.0.3\nserial = X\n",
      { ":4: [camera]: both address (line 3) and serial given" } },
    { "[camera]\nbackend = aravis\naddress = 300.1.2.3\n", { ":3: [camera] address: '300.1.2.3' is not an IPv4" } },
    { "[camera]\nbackend = aravis\naddress = 127.0.0.3\npixel_format = Mono14\n",
      { ":4: [camera] pixel_format: 'Mono14' is not Mono8, Mono12 or Mono16" } },
    { "[camera]\nbackend = aravis\naddress = 127.0.0.3\nexposure_us = 0\n", { ":4: [camera] exposure_us = 0 is out" } },
    { "[camera]\nbackend = aravis\naddress =\n", { ":3: [camera] address is empty" } },
    { "[camera]\nbackend = usb\n", { ":2: [camera]: unknown backend 'usb': use 'backend = aravis'" } },
    { "[rig]\nbackend = virtual\ntruth = t.ini\n\n[turntable]\nbackend = sim\n",
      { ":5: [turntable] together with [rig]", "remove [rig] or the device sections" } },
    { "[lamp a]\nbackend = sim\n[rig]\nbackend = virtual\ntruth = t.ini\n", { ":3: [rig] together with [lamp a]" } },
    { "[rig]\nbackend = virtual\n", { ":1: [rig] backend = virtual needs 'truth = FILE'" } },
    { "[rig]\nbackend = real\n", { ":2: [rig]: unknown backend 'real': use 'backend = virtual'" } },
    { "[rig]\nbackend = virtual\ntruth = t.ini\naddress = 10.0.0.1\n", { ":4: [rig] address: '10.0.0.1' is not a "
                                                                         "loopback" } },
    { "[rig]\nbackend = virtual\ntruth = t.ini\ntime_scale = 0\n", { ":4: [rig] time_scale = 0 is out of range" } },
    { "[rig]\nbackend = virtual\ntruth = t.ini\ncamera = x\n", { ":4: [rig]: unknown key 'camera' for backend "
                                                                 "virtual" } },
    { "# nothing\n", { "no devices: add [camera]" } },
    { "[turntable\nbackend = sim\n", { ":1: unterminated '['" } },
    { "backend = sim\n", { ":1: key 'backend' before any section" } },
};

TEST(rigcfg_errors_name_file_and_line)
{
    for (size_t i = 0; i < sizeof bad_cases / sizeof bad_cases[0]; i++) {
        const bad_case_t *b = &bad_cases[i];
        const char *path = test_write("bad.ini", b->text);
        rig_t *r = (rig_t *)1;
        model_error_clear();
        int rc = rig_open(&r, path);
        CHECK_MSG(rc == RIG_ERR_INVALID, "case %zu: rc %d (%s)", i, rc, model_last_error());
        CHECK_MSG(r == NULL, "case %zu: *out not NULL", i);
        CHECK_MSG(!strncmp(model_last_error(), path, strlen(path)), "case %zu: '%s' does not start with the path", i,
                  model_last_error());
        CHECK_MSG(!strcmp(model_last_error(), model_last_error()), "case %zu: rig '%s' model '%s'", i, model_last_error(),
                  model_last_error());
        for (int k = 0; k < 3 && b->want[k]; k++) CHECK_CONTAINS(model_last_error(), b->want[k]);
        if (r && r != (rig_t *)1) rig_close(r);
    }
    rig_t *r = NULL;
    CHECK(rig_open(&r, test_path("missing.ini")) == RIG_ERR_NO_DEVICE);
    CHECK_CONTAINS(model_last_error(), "missing.ini: cannot open");
    CHECK(rig_open(NULL, "x.ini") == RIG_ERR_INVALID);
    CHECK(rig_open(&r, NULL) == RIG_ERR_INVALID && r == NULL);
}

// A device that fails after others opened: they are closed again. The lamp
// sets' safety registry has 32 slots, so 32 fresh sets open afterwards only if
// none leaked.
TEST(rigcfg_nothing_open_after_error)
{
    // Lamps open, then the camera fails (nothing serves 127.0.0.3).
    const char *path = test_write("cam.ini",
                                  "[turntable]\nbackend = sim\n"
                                  "[lamp a]\nbackend = sim\n[lamp b]\nbackend = sim\n"
                                  "[camera]\nbackend = aravis\naddress = 127.0.0.3\n");
    rig_t *r = NULL;
    int rc = rig_open(&r, path);
    CHECK(rc == RIG_ERR_NO_DEVICE && r == NULL);
    CHECK_CONTAINS(model_last_error(), ":7: [camera]: aravis: no camera at '127.0.0.3'");
    // The turntable opens, then the lamps' GPIO chip is missing.
    path = test_write("gpio.ini",
                      "[turntable]\nbackend = sim\n"
                      "[lamp a]\nbackend = gpiod\nchip = /nonexistent/gpiochip9\nline = 3\n");
    rc = rig_open(&r, path);
    CHECK(rc != 0 && r == NULL);
    CHECK_CONTAINS(model_last_error(), "gpio.ini:3: [lamp a]: ");
    CHECK_CONTAINS(model_last_error(), "/nonexistent/gpiochip9");
    // Every safety slot is free again.
    rig_lamps_t *sets[32] = { 0 };
    rig_lamp_line_t one = { .name = "x" };
    int opened = 0;
    for (int i = 0; i < 32; i++)
        if (rig_lamps_open_sim(&sets[i], &one, 1) == 0) opened++;
    CHECK_MSG(opened == 32, "only %d of 32 lamp sets opened: a failed rig_open kept its lamps (%s)", opened,
              model_last_error());
    for (int i = 0; i < 32; i++) rig_lamps_close(sets[i]);
}

// The virtual rig: a rig file next to nothing but pointing at the example
// truth file, with fast timing.
TEST(rigcfg_virtual_rig)
{
    char text[2048];
    snprintf(text, sizeof text,
             "[rig]\nbackend = virtual\ntruth = %s\ntime_scale = 0.01\n"
             "busy_wait_s = 120\nexposure_us = 5000\n",
             truth_path());
    const char *path = test_write("virtual.ini", text);
    int session = test_camera_lock();
    rig_t *r = NULL;
    int rc = rig_open(&r, path);
    CHECK_MSG(rc == 0, "rig_open: %d %s", rc, model_last_error());
    if (!rc) {
        CHECK(r->virt && r->camera && r->turntable && r->lamps);
        CHECK(r->turntable == rig_virtual_turntable(r->virt));
        CHECK(r->lamps == rig_virtual_lamps(r->virt));
        CHECK(rig_lamps_count(r->lamps) == 5 && rig_lamps_on_mask(r->lamps) == 0);
        CHECK(rig_lamps_find(r->lamps, "east") >= 0 && rig_lamps_find(r->lamps, "north") >= 0);
        CHECK_CONTAINS(rig_camera_name(r->camera), "127.0.0.1");
        rig_frame_meta_t m;
        CHECK(rig_camera_settings(r->camera, &m) == 0);
        CHECK_NEAR(m.exposure_us, 5000, 1e-6);   // the file's camera default applied at open
        CHECK_NEAR(r->exposure_us, 5000, 0);
        // The truth file's stage profile (10 deg/s, 10 deg/s^2, 15 s homing) in real time.
        CHECK_REL(r->speed_deg_s, 10 / 0.01, 1e-12);
        CHECK_REL(r->home_time_s, 15 * 0.01, 1e-12);
        CHECK(rig_turntable_home(r->turntable, 5) == 0);
        CHECK(rig_turntable_move_abs_deg(r->turntable, 30, 5) == 0);
        rig_turntable_status_t st;
        CHECK(rig_turntable_status(r->turntable, &st) == 0);
        CHECK_NEAR(st.angle_deg, 30, 0.05);
    }
    rig_close(r);
    // A missing truth file: the [rig] line and the virtual rig's message.
    path = test_write("virtual-bad.ini", "[rig]\nbackend = virtual\ntruth = no-such-truth.ini\n");
    r = NULL;
    rc = rig_open(&r, path);
    CHECK(rc != 0 && r == NULL);
    CHECK_CONTAINS(model_last_error(), "virtual-bad.ini:1: [rig]: ");
    CHECK_CONTAINS(model_last_error(), "no-such-truth.ini");
    // An unknown sample.
    snprintf(text, sizeof text, "[rig]\nbackend = virtual\ntruth = %s\nsample = unicorn\n",
             truth_path());
    path = test_write("virtual-sample.ini", text);
    rc = rig_open(&r, path);
    CHECK(rc != 0 && r == NULL);
    CHECK_CONTAINS(model_last_error(), "virtual-sample.ini:1: [rig]: ");
    CHECK_CONTAINS(model_last_error(), "unicorn");
    test_camera_unlock(session);
}
