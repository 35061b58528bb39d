// tests/test_rig_cli.c — `refl rig` end to end (bin/refl as a child process):
// usage errors, a simulated rig, the virtual rig (status, home, move,
// identify, snap with its PNG metadata and pixel statistics, serve stopped by
// SIGTERM), and lamps switched off and released on error paths (gpiod lamps
// through the fake libgpiod of tests/fake_gpiod.c); status reporting every
// device when one fails (in-process); snap checking -o before it opens the rig.
//
// Only one virtual camera serves 127.0.0.1 at a time: the virtual-rig tests
// hold the lock of tests/test_rig_camera_aravis.c throughout, and run one refl at
// a time.
#define _GNU_SOURCE
#include <errno.h>
#include <fcntl.h>
#include <glib.h>
#include <limits.h>
#include <png.h>
#include <poll.h>
#include <signal.h>
#include <stdarg.h>
#include <stdlib.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include "model/model.h"
#include "rig/rig.h"
#include "tests/fixtures.h"
#include "tests/test.h"

#define refl(out, err, ...) test_refl_run(120, out, err, __VA_ARGS__)



// A virtual rig file in the temporary directory pointing at the example truth
// file, 100x faster than real time.
static const char *virtual_rig(void)
{
    char top[PATH_MAX], text[PATH_MAX + 256];
    if (!realpath(test_srcdir(), top)) snprintf(top, sizeof top, "%s", test_srcdir());
    snprintf(text, sizeof text,
             "# test rig\n[rig]\nbackend = virtual\ntruth = %s/examples/virtual-truth.ini\ntime_scale = 0.01\n"
             "busy_wait_s = 120\n", top);
    return test_write("virtual-rig.ini", text);
}

// Value of a PNG tEXt key (caller frees), NULL when absent.
static char *png_meta(const char *path, const char *key)
{
    FILE *f = fopen(path, "rb");
    if (!f) return NULL;
    png_structp png = png_create_read_struct(PNG_LIBPNG_VER_STRING, NULL, NULL, NULL);
    png_infop info = png ? png_create_info_struct(png) : NULL;
    char *val = NULL;
    if (!png || !info || setjmp(png_jmpbuf(png))) goto done;
    png_init_io(png, f);
    png_read_info(png, info);
    png_textp text;
    int n = 0;
    png_get_text(png, info, &text, &n);
    for (int i = 0; i < n && !val; i++)
        if (!strcmp(text[i].key, key)) val = strdup(text[i].text);
done:
    png_destroy_read_struct(&png, &info, NULL);
    fclose(f);
    return val;
}

#define CHECK_META(png, key, needle)                                             \
    do {                                                                         \
        char *v_ = png_meta(png, key);                                           \
        CHECK_MSG(v_ != NULL, "no metadata key '%s' in %s", key, png);           \
        if (v_) CHECK_CONTAINS(v_, needle);                                      \
        free(v_);                                                                \
    } while (0)

// ---------------------------------------------------------------------------

TEST(rigcli_usage_errors)
{
    const char *rig = test_write("sim.ini", "[turntable]\nbackend = sim\ntime_scale = 0.001\n");
    struct {
        const char *args[8];
        const char *want;
    } cases[] = {
        { { "status" }, "missing required option --rig" },
        { { "--rig", rig }, "missing action" },
        { { "--rig", rig, "dance" }, "unknown action 'dance'" },
        { { "--rig", rig, "move" }, "move needs the angle" },
        { { "--rig", rig, "move", "abc" }, "move: 'abc' is not an angle" },
        { { "--rig", rig, "move", "1e9" }, "out of range" },
        { { "--rig", rig, "move", "30", "40" }, "unexpected argument '40'" },
        { { "--rig", rig, "status", "now" }, "unexpected argument 'now'" },
        { { "--rig", rig, "snap" }, "snap needs -o" },
        { { "--rig", rig, "snap", "-o", "x.tif" }, "must end in .png" },
        { { "--rig", rig, "status", "-o", "x.png" }, "option -o is for snap only" },
        { { "--rig", rig, "move", "5", "--angle-deg", "3" }, "option --angle-deg is for snap only" },
        { { "--rig", rig, "snap", "-o", "x.png", "--angle-deg", "north" }, "'north' is not an angle" },
        { { "--rig", rig, "snap", "-o", "x.png", "--exposure-us", "-5" }, "--exposure-us: -5 is out of range" },
        { { "--rig", rig, "snap", "-o", "x.png", "--gain", "lots" }, "--gain: 'lots' is not a number" },
        { { "--rig", rig, "snap", "-o", "x.png", "--pixel-format", "Mono14" }, "'Mono14' is not Mono8" },
        { { "--rig", rig, "snap", "-o", "x.png", "--lamps-on", "a,,b" }, "has an empty lamp name" },
        { { "--rig", rig, "status", "--frobnicate" }, "unknown option '--frobnicate'" },
        { { "--rig", rig, "--rig", rig, "status" }, "option --rig given twice" },
        { { "--rig" }, "option --rig needs a value" },
    };
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
        const char *argv[16];
        int n = 0;
        argv[n++] = test_refl();
        argv[n++] = "rig";
        for (int k = 0; k < 8 && cases[i].args[k]; k++) argv[n++] = cases[i].args[k];
        argv[n] = NULL;
        char *out = NULL, *err = NULL;
        int rc = test_run(argv, 30, &out, &err);
        CHECK_MSG(rc == 2, "case %zu: exit %d, stderr: %s", i, rc, err);
        CHECK_CONTAINS(err, cases[i].want);
        CHECK_CONTAINS(err, "usage: refl rig");
        CHECK_MSG(out && !out[0], "case %zu: stdout not empty: %s", i, out);
        free(out);
        free(err);
    }
    char *out = NULL;
    CHECK(refl(&out, NULL, "rig", "--help", NULL) == 0);
    CHECK_CONTAINS(out, "snap");
    CHECK_CONTAINS(out, "serve");
    free(out);
    out = NULL;
    CHECK(refl(&out, NULL, "--help", NULL) == 0);
    CHECK_CONTAINS(out, "  rig ");
    free(out);
}

// A rig of simulated devices, no camera: status, home, move (negative angle
// too), identify; snap needs a camera; errors of the file exit 1.
TEST(rigcli_sim_rig)
{
    const char *rig = test_write("sim.ini",
                                 "[turntable]\nbackend = sim\ntime_scale = 0.001\nposition_noise_deg = 0\nseed = 3\n"
                                 "[lamp key]\nbackend = sim\n[lamp fill]\nbackend = sim\n");
    char *out = NULL, *err = NULL;
    int rc = refl(&out, &err, "rig", "--rig", rig, "status", NULL);
    CHECK_MSG(rc == 0, "status: %d %s", rc, err);
    CHECK_CONTAINS(out, "turntable: sim turntable (seed 3)\nturntable_angle_deg: 0.0000\nturntable_homed: no\n");
    CHECK_CONTAINS(out, "lamp key: off (sim)\nlamp fill: off (sim)\n");
    CHECK_CONTAINS(out, "camera: none\n");
    char sha[65];
    CHECK(model_sha256_file(rig, sha));
    CHECK_CONTAINS(out, sha);
    free(out);
    free(err);

    rc = refl(&out, &err, "rig", "--rig", rig, "home", NULL);
    CHECK_MSG(rc == 0, "home: %d %s", rc, err);
    CHECK_CONTAINS(out, "turntable_angle_deg: 0.0000\nturntable_homed: yes\n");
    free(out);
    free(err);

    rc = refl(&out, &err, "rig", "--rig", rig, "move", "-30.5", NULL);
    CHECK_MSG(rc == 0, "move: %d %s", rc, err);
    CHECK_CONTAINS(out, "turntable_commanded_deg: -30.5\nturntable_angle_deg: -30.5000\n");
    CHECK_CONTAINS(err, "not homed: homing first");   // every refl is a new process: the sim stage starts unhomed
    free(out);
    free(err);

    rc = refl(&out, &err, "rig", "--rig", rig, "identify", NULL);
    CHECK_MSG(rc == 0, "identify: %d %s", rc, err);
    CHECK_CONTAINS(out, "turntable_model: K10CR1 (simulated)\nturntable_serial: sim-3\n");
    CHECK_CONTAINS(out, "lamp fill: sim");
    free(out);
    free(err);

    rc = refl(&out, &err, "rig", "--rig", rig, "snap", "-o", test_path("x.png"), NULL);
    CHECK(rc == 1);
    CHECK_CONTAINS(err, "has no camera: add a [camera] section");
    CHECK(access(test_path("x.png"), F_OK) != 0);
    free(out);
    free(err);

    rc = refl(&out, &err, "rig", "--rig", rig, "serve", NULL);
    CHECK(rc == 1);
    CHECK_CONTAINS(err, "is not a virtual rig");
    free(out);
    free(err);

    rc = refl(&out, &err, "rig", "--rig", rig, "snap", "-o", test_path("x.png"), "--sample", "t_stiffener", NULL);
    CHECK(rc == 1);
    CHECK_CONTAINS(err, "--sample: ");
    CHECK_CONTAINS(err, "is not a virtual rig");
    free(out);
    free(err);

    const char *lamps_only = test_write("lamps.ini", "[lamp key]\nbackend = sim\n");
    rc = refl(&out, &err, "rig", "--rig", lamps_only, "move", "5", NULL);
    CHECK(rc == 1);
    CHECK_CONTAINS(err, "has no turntable: add a [turntable] section");
    free(out);
    free(err);
    rc = refl(&out, &err, "rig", "--rig", lamps_only, "status", NULL);
    CHECK(rc == 0);
    CHECK_CONTAINS(out, "turntable: none\nlamp key: off (sim)\ncamera: none\n");
    free(out);
    free(err);

    const char *bad = test_write("bad.ini", "[turntable]\nbackend = sim\nspeed_deg_s = fast\n");
    rc = refl(&out, &err, "rig", "--rig", bad, "status", NULL);
    CHECK(rc == 1);
    CHECK_CONTAINS(err, "bad.ini:3: [turntable] speed_deg_s: 'fast' is not a number");
    CHECK(out && !out[0]);
    free(out);
    free(err);

    rc = refl(&out, &err, "rig", "--rig", test_path("none.ini"), "status", NULL);
    CHECK(rc == 1);
    CHECK_CONTAINS(err, "none.ini: cannot open");
    free(out);
    free(err);
}

// Mean of the pixels of a PNG; *n_above: pixels above `level`.
static bool png_stats(const char *path, double *mean, double level, long *n_above, int *w, int *h)
{
    uint16_t *pix = NULL;
    if (!model_png_read(path, w, h, &pix)) return false;
    double s = 0;
    long above = 0;
    size_t n = (size_t)*w * (size_t)*h;
    for (size_t i = 0; i < n; i++) {
        s += pix[i];
        above += pix[i] > level;
    }
    free(pix);
    *mean = s / (double)n;
    *n_above = above;
    return true;
}

TEST(rigcli_virtual_rig)
{
    int session = test_camera_lock();
    const char *rig = virtual_rig();
    char sha[65];
    CHECK(model_sha256_file(rig, sha));
    char *out = NULL, *err = NULL;

    int rc = refl(&out, &err, "rig", "--rig", rig, "status", NULL);
    CHECK_MSG(rc == 0, "status: %d %s", rc, err);
    CHECK_CONTAINS(out, "rig_backend: virtual (truth ");
    CHECK_CONTAINS(out, "sample t_stiffener");
    CHECK_CONTAINS(out, "turntable_homed: no");
    CHECK_CONTAINS(out, "lamp east: off (sim)");
    CHECK_CONTAINS(out, "camera_serial: REFL-VIRT01");
    CHECK_CONTAINS(out, "camera_temperature_c: 35.00");
    free(out);
    free(err);

    // The example rig file itself: its truth file is found next to it, Mono12 is set at open.
    char example[PATH_MAX + 64];
    snprintf(example, sizeof example, "%s/examples/virtual-rig.ini", test_srcdir());
    rc = refl(&out, &err, "rig", "--rig", example, "status", NULL);
    CHECK_MSG(rc == 0, "status of the example: %d %s", rc, err);
    CHECK_CONTAINS(out, "examples/virtual-truth.ini, sample t_stiffener)");
    CHECK_CONTAINS(out, "camera_pixel_format: Mono12 (12 bits)");
    free(out);
    free(err);

    rc = refl(&out, &err, "rig", "--rig", rig, "home", NULL);
    CHECK_MSG(rc == 0, "home: %d %s", rc, err);
    CHECK_CONTAINS(out, "turntable_homed: yes");
    free(out);
    free(err);

    rc = refl(&out, &err, "rig", "--rig", rig, "move", "30", NULL);
    CHECK_MSG(rc == 0, "move: %d %s", rc, err);
    CHECK_CONTAINS(out, "turntable_commanded_deg: 30\nturntable_angle_deg: ");
    double a = NAN;
    const char *p = out ? strstr(out, "turntable_angle_deg: ") : NULL;
    if (p) a = strtod(p + strlen("turntable_angle_deg: "), NULL);
    CHECK_NEAR(a, 30, 0.02);   // position noise 0.002 deg
    free(out);
    free(err);

    rc = refl(&out, &err, "rig", "--rig", rig, "identify", NULL);
    CHECK_MSG(rc == 0, "identify: %d %s", rc, err);
    CHECK_CONTAINS(out, "turntable_model: K10CR1 (simulated)");
    CHECK_CONTAINS(out, "camera_vendor: refl");
    CHECK_CONTAINS(out, "camera_serial: REFL-VIRT01");
    CHECK_CONTAINS(out, "lamp north: sim (virtual rig)");
    CHECK_CONTAINS(out, "virtual_camera_address: 127.0.0.1");
    free(out);
    free(err);

    // A lit frame at 30 deg and a dark one.
    const char *lit = test_path("lit.png"), *dark = test_path("dark.png");
    rc = refl(&out, &err, "rig", "--rig", rig, "snap", "-o", lit, "--angle-deg", "30", "--lamps-on", "east",
              "--pixel-format", "Mono12", "--exposure-us", "20000", NULL);
    CHECK_MSG(rc == 0, "snap: %d %s", rc, err);
    CHECK_CONTAINS(out, "wrote ");
    CHECK_CONTAINS(out, "lamps on: east");
    free(out);
    free(err);
    // (Not moved: a dark frame does not depend on the angle.)
    rc = refl(&out, &err, "rig", "--rig", rig, "snap", "-o", dark, "--lamps-on", "none",
              "--pixel-format", "Mono12", "--exposure-us", "20000", NULL);
    CHECK_MSG(rc == 0, "snap dark: %d %s", rc, err);
    free(out);
    free(err);

    CHECK_META(lit, "units", "DN, the camera's pixel format: Mono12 values 0..4095");
    CHECK_META(lit, "turntable_commanded_deg", "30");
    {
        char *v = png_meta(lit, "turntable_measured_deg");
        CHECK_NEAR(v ? strtod(v, NULL) : NAN, 30, 0.02);
        free(v);
    }
    CHECK_META(lit, "lamps_on", "east");
    CHECK_META(lit, "rig_sha256", sha);
    CHECK_META(lit, "rig_file", rig);
    CHECK_META(lit, "camera_serial", "REFL-VIRT01");
    CHECK_META(lit, "exposure_us", "20000");
    CHECK_META(lit, "pixel_format", "Mono12 (12 significant bits)");
    CHECK_META(lit, "temperature_c", "35.");
    CHECK_META(lit, "refl_version", REFL_VERSION);
    CHECK_META(lit, "command_line", "--lamps-on east");
    CHECK_META(lit, "virtual_sample", "t_stiffener");
    CHECK_META(lit, "date_utc", "Z");
    CHECK_META(dark, "lamps_on", "none");
    CHECK_META(dark, "turntable_commanded_deg", "none (not moved by this command)");

    // Pixel statistics: the dark frame sits at the sensor's dark offset
    // (64 DN), the lit one has many pixels well above it, all within 12 bits.
    double mean_lit = 0, mean_dark = 0;
    long above_lit = 0, above_dark = 0;
    int w = 0, h = 0, w2 = 0, h2 = 0;
    CHECK(png_stats(lit, &mean_lit, 200, &above_lit, &w, &h));
    CHECK(png_stats(dark, &mean_dark, 200, &above_dark, &w2, &h2));
    CHECK(w == w2 && h == h2 && w > 0 && h > 0);
    CHECK_NEAR(mean_dark, 64, 10);
    CHECK(above_dark == 0);
    CHECK_MSG(above_lit > (long)w * h / 20, "only %ld of %d pixels above 200 DN in the lit frame", above_lit, w * h);
    CHECK_MSG(mean_lit > mean_dark + 50, "lit mean %.1f, dark mean %.1f", mean_lit, mean_dark);
    {
        uint16_t *pix = NULL;
        int ww, hh;
        CHECK(model_png_read(lit, &ww, &hh, &pix));
        long over = 0;
        for (long i = 0; pix && i < (long)ww * hh; i++) over += pix[i] > 4095;
        CHECK(over == 0);
        free(pix);
    }

    // Runtime errors: unknown lamp, unknown sample (exit 1, nothing written).
    const char *nope = test_path("nope.png");
    rc = refl(&out, &err, "rig", "--rig", rig, "snap", "-o", nope, "--lamps-on", "east,nope", NULL);
    CHECK(rc == 1);
    CHECK_CONTAINS(err, "has no lamp 'nope' (its lamps: east,south,west,north,rim)");
    CHECK(access(nope, F_OK) != 0);
    free(out);
    free(err);
    rc = refl(&out, &err, "rig", "--rig", rig, "snap", "-o", nope, "--sample", "unicorn", NULL);
    CHECK(rc == 1);
    CHECK_CONTAINS(err, "unicorn");
    CHECK(access(nope, F_OK) != 0);
    free(out);
    free(err);
    test_camera_unlock(session);
}

// Bit depth of a PNG, 0 when it cannot be read.
static int png_bit_depth(const char *path)
{
    FILE *f = fopen(path, "rb");
    if (!f) return 0;
    png_structp png = png_create_read_struct(PNG_LIBPNG_VER_STRING, NULL, NULL, NULL);
    png_infop info = png ? png_create_info_struct(png) : NULL;
    int depth = 0;
    if (!png || !info || setjmp(png_jmpbuf(png))) goto done;
    png_init_io(png, f);
    png_read_info(png, info);
    depth = png_get_bit_depth(png, info);
done:
    png_destroy_read_struct(&png, &info, NULL);
    fclose(f);
    return depth;
}

// A virtual rig file setting pixel_format at open (test_write's name `name`).
static const char *virtual_rig_format(const char *name, const char *format)
{
    char top[PATH_MAX], text[PATH_MAX + 256];
    if (!realpath(test_srcdir(), top)) snprintf(top, sizeof top, "%s", test_srcdir());
    snprintf(text, sizeof text,
             "[rig]\nbackend = virtual\ntruth = %s/examples/virtual-truth.ini\ntime_scale = 0.01\n"
             "busy_wait_s = 120\npixel_format = %s\n", top, format);
    return test_write(name, text);
}

// pixel_format = Mono12p in the rig file: the camera sends packed pixels, the
// snap is a 16-bit PNG with the values Mono12 gives (the same first frame:
// the same noise seed).
TEST(rigcli_virtual_rig_mono12p)
{
    int session = test_camera_lock();
    const char *fmts[] = { "Mono12", "Mono12p" };
    const char *pngs[] = { test_path("snap-mono12.png"), test_path("snap-mono12p.png") };
    for (int k = 0; k < 2; k++) {
        char name[64];
        snprintf(name, sizeof name, "virtual-rig-%s.ini", fmts[k]);
        const char *rig = virtual_rig_format(name, fmts[k]);
        char *out = NULL, *err = NULL;
        int rc = refl(&out, &err, "rig", "--rig", rig, "snap", "-o", pngs[k], "--lamps", "east", "--exposure-us",
                      "20000", NULL);
        CHECK_MSG(rc == 0, "snap %s: %d %s", fmts[k], rc, err);
        // --lamps, the old spelling of --lamps-on: it works and names the new one once
        int notes = 0;
        for (const char *p = err; p && (p = strstr(p, "the old spelling")); p++) notes++;
        CHECK_MSG(notes == 1 && strstr(err, "--lamps NAMES: the option is --lamps-on (the old spelling still works)"),
                  "%s", err);
        free(out);
        free(err);
        CHECK(png_bit_depth(pngs[k]) == 16);
    }
    CHECK_META(pngs[1], "pixel_format", "Mono12p (12 significant bits)");
    CHECK_META(pngs[0], "pixel_format", "Mono12 (12 significant bits)");
    uint16_t *a = NULL, *b = NULL;
    int wa = 0, ha = 0, wb = 0, hb = 0;
    CHECK(model_png_read(pngs[0], &wa, &ha, &a));
    CHECK(model_png_read(pngs[1], &wb, &hb, &b));
    CHECK(a && b && wa == wb && ha == hb && wa > 0);
    long differ = 0, over = 0, lit = 0;
    for (long i = 0; a && b && wa == wb && ha == hb && i < (long)wa * ha; i++) {
        differ += a[i] != b[i];
        over += b[i] > 4095;
        lit += b[i] > 200;
    }
    CHECK_MSG(differ == 0, "%ld pixels of the Mono12p snap differ from the Mono12 one", differ);
    CHECK(over == 0);
    CHECK_MSG(lit > (long)wa * ha / 20, "only %ld pixels above 200 DN", lit);
    free(a);
    free(b);
    test_camera_unlock(session);
}

// `serve` in a child: prints the address, stops cleanly on SIGTERM.
TEST_ALONE(rigcli_serve_sigterm)
{
    int session = test_camera_lock();
    const char *rig = virtual_rig();
    int po[2];
    if (pipe2(po, O_CLOEXEC)) {
        CHECK(false);
        test_camera_unlock(session);
        return;
    }
    const char *err_path = test_path("serve.err");
    pid_t pid = fork();
    if (pid == 0) {
        dup2(po[1], 1);
        int fe = open(err_path, O_WRONLY | O_CREAT | O_TRUNC, 0644);
        if (fe >= 0) dup2(fe, 2);
        execl(test_refl(), test_refl(), "rig", "--rig", rig, "serve", "--sample", "chessboard", (char *)NULL);
        _exit(127);
    }
    close(po[1]);
    char buf[4096] = "";
    size_t len = 0;
    double t0 = model_now_s();
    while (!strstr(buf, "sample: ") || !strchr(strstr(buf, "sample: "), '\n')) {
        int left_ms = (int)((60 - (model_now_s() - t0)) * 1000);
        if (left_ms <= 0) break;
        struct pollfd pf = { po[0], POLLIN, 0 };
        if (poll(&pf, 1, left_ms) <= 0) continue;
        ssize_t n = read(po[0], buf + len, sizeof buf - 1 - len);
        if (n <= 0) break;
        len += (size_t)n;
        buf[len] = 0;
    }
    CHECK_CONTAINS(buf, "address: 127.0.0.1\n");
    CHECK_CONTAINS(buf, "sample: chessboard\n");
    // The camera is up for another client: a snap through a plain camera rig.
    const char *client = test_write("client.ini", "[camera]\nbackend = aravis\naddress = 127.0.0.1\n");
    char *out = NULL, *err = NULL;
    int rc = refl(&out, &err, "rig", "--rig", client, "snap", "-o", test_path("client.png"), NULL);
    CHECK_MSG(rc == 0, "snap from the served camera: %d %s", rc, err);
    CHECK_META(test_path("client.png"), "camera_serial", "REFL-VIRT01");
    free(out);
    free(err);

    double t_kill = model_now_s();
    kill(pid, SIGTERM);
    int status = 0;
    pid_t w = 0;
    while ((w = waitpid(pid, &status, WNOHANG)) == 0 && model_now_s() - t_kill < 10) usleep(20000);
    double dt = model_now_s() - t_kill;
    if (w == 0) {
        kill(pid, SIGKILL);
        waitpid(pid, &status, 0);
    }
    CHECK_MSG(w == pid, "serve did not stop within 10 s of SIGTERM");
    CHECK_MSG(WIFEXITED(status) && WEXITSTATUS(status) == 0, "serve ended with status 0x%x", status);
    CHECK_MSG(dt < 5, "serve took %.2f s to stop", dt);
    char *e = model_read_file(err_path, NULL);
    CHECK_CONTAINS(e, "stopping");
    free(e);
    close(po[0]);
    test_camera_unlock(session);
}

// gpiod lamps (fake libgpiod): every line requested off, and released at the
// off level on the way out of a failed snap (no camera) and of a failed open
// (the camera after the lamps).
TEST(rigcli_gpiod_lamps_off_on_errors)
{
    char lib[PATH_MAX];
    const char *l = getenv("REFL_FAKE_GPIOD");
    if (!l || !realpath(l, lib)) {
        CHECK_MSG(false, "REFL_FAKE_GPIOD (%s) must name the fake libgpiod (make check sets it)", l ? l : "unset");
        return;
    }
    const char *log = test_path("gpio.log");
    char env_pre[PATH_MAX + 32], env_log[PATH_MAX + 32], env_state[PATH_MAX + 32];
    snprintf(env_pre, sizeof env_pre, "LD_PRELOAD=%s", lib);
    snprintf(env_log, sizeof env_log, "FAKE_GPIO_LOG=%s", log);
    // The lamp-state file of the test, not the user's (~/.local/state/refl).
    snprintf(env_state, sizeof env_state, "XDG_STATE_HOME=%s", test_path("state"));
    const char *lamps = "[turntable]\nbackend = sim\ntime_scale = 0.001\n"
                        "[lamp key]\nbackend = gpiod\nchip = gpiochip0\nline = 3\n"
                        "[lamp fill]\nbackend = gpiod\nchip = gpiochip0\nline = 5\nactive_low = yes\n";
    const char *rig = test_write("gpio.ini", lamps);
    char text[1024];
    snprintf(text, sizeof text, "%s[camera]\nbackend = aravis\naddress = 127.0.0.3\n", lamps);
    const char *rig_cam = test_write("gpio-cam.ini", text);

    const char *argv[] = { "env", env_pre, "FAKE_GPIOCHIP=gpiochip0:32", env_log, env_state,
                           "ASAN_OPTIONS=verify_asan_link_order=0:detect_leaks=0", test_refl(), "rig", "--rig", rig,
                           "snap", "-o", test_path("x.png"), "--lamps-on", "all", NULL };
    char *out = NULL, *err = NULL;
    int rc = test_run(argv, 60, &out, &err);
    CHECK(rc == 1);
    CHECK_CONTAINS(err, "has no camera");
    char *lg = model_read_file(log, NULL);
    CHECK_CONTAINS(lg, "request gpiochip0 3=0 consumer=refl\n");
    CHECK_CONTAINS(lg, "request gpiochip0 5=1 consumer=refl\n");   // active low: off is high
    CHECK_CONTAINS(lg, "release gpiochip0 3=0");
    CHECK_CONTAINS(lg, "release gpiochip0 5=1");
    CHECK(!lg || !strstr(lg, "3=1"));   // never switched on
    free(lg);
    free(out);
    free(err);

    unlink(log);
    argv[9] = rig_cam;
    argv[10] = "status";
    argv[11] = NULL;
    rc = test_run(argv, 60, &out, &err);
    // the camera nobody serves is reported on its camera_error line, the lamps still are (exit 1)
    CHECK(rc == 1);
    CHECK_CONTAINS(out, "lamp key: off (gpiod)\n");
    CHECK_CONTAINS(out, "camera: not open\ncamera_error: ");
    CHECK_CONTAINS(out, "gpio-cam.ini:13: [camera]: aravis: no camera at '127.0.0.3'");
    CHECK_CONTAINS(err, "refl rig status: the camera did not open (its camera_error line above)");
    lg = model_read_file(log, NULL);
    CHECK_CONTAINS(lg, "request gpiochip0 3=0 consumer=refl\n");
    CHECK_CONTAINS(lg, "release gpiochip0 3=0");
    CHECK_CONTAINS(lg, "release gpiochip0 5=1");
    free(lg);
    free(out);
    free(err);

    // status on the lamps: off, gpiod; identify names chip and line.
    argv[9] = rig;
    argv[10] = "identify";
    rc = test_run(argv, 60, &out, &err);
    CHECK_MSG(rc == 0, "identify: %d %s", rc, err);
    CHECK_CONTAINS(out, "lamp key: gpiod gpiochip0 line 3 active-high");
    CHECK_CONTAINS(out, "lamp fill: gpiod gpiochip0 line 5 active-low");
    free(out);
    free(err);
}

// `refl rig status` reports every device when one fails (a simulated stage
// that disconnected): the turntable's error, then the lamps and the camera,
// and a non-zero status.
TEST(rigcli_status_every_device)
{
    const char *path = test_write("sim-fault.ini",
                                  "[turntable]\nbackend = sim\ntime_scale = 0.001\nposition_noise_deg = 0\nseed = 3\n"
                                  "fault_after_moves = 1\nfault = disconnected\n"
                                  "[lamp key]\nbackend = sim\n[lamp fill]\nbackend = sim\n");
    rig_t *r = NULL;
    CHECK(rig_open(&r, path) == 0);
    if (!r) return;
    int rc = -1;
    char *out = fx_stdout_of(rig_cmd_status, r, &rc);
    CHECK(rc == 0);
    CHECK_CONTAINS(out, "turntable_homed: no\n");
    free(out);
    CHECK(rig_turntable_home(r->turntable, 5.0) == 0);
    CHECK(rig_turntable_move_abs_deg(r->turntable, 10, 5.0) == 0);
    CHECK(rig_turntable_move_abs_deg(r->turntable, 20, 5.0) == RIG_ERR_DISCONNECTED);
    out = fx_stdout_of(rig_cmd_status, r, &rc);
    CHECK(rc == RIG_ERR_DISCONNECTED);
    CHECK_CONTAINS(out, "turntable: sim turntable (seed 3)\nturntable_error: ");
    CHECK_CONTAINS(out, "disconnected");
    CHECK_CONTAINS(out, "lamp key: off (sim)\nlamp fill: off (sim)\n");   // reported after the failure
    CHECK_CONTAINS(out, "camera: none\n");
    CHECK_CONTAINS(model_last_error(), "refl rig status: the turntable did not answer");
    free(out);
    rig_close(r);
}

// One device at a time: identify and status report every device though some
// do not open (here both cameras and the lamps: named with the rig file's line,
// the devices after them still reported; exit 1); --only opens one kind; home
// and move open the turntable alone (they work while the cameras are away).
TEST(rigcli_one_device_at_a_time)
{
    const char *rig = test_write("away.ini", "[turntable]\nbackend = sim\ntime_scale = 0.001\nseed = 4\n"
                                 "[lamp key]\nbackend = gpiod\nchip = gpiochip-none\nline = 0\n"
                                 "[camera left]\nbackend = aravis\nserial = inprocess:AWAY-L\n"
                                 "[camera right]\nbackend = aravis\nserial = inprocess:AWAY-R\n");
    char *out = NULL, *err = NULL;
    int rc = refl(&out, &err, "rig", "--rig", rig, "identify", NULL);
    CHECK_MSG(rc == 1, "identify: %d %s", rc, err);
    CHECK_CONTAINS(out, "turntable_serial: sim-4\n");
    CHECK_CONTAINS(out, "camera_name: left\ncamera: not open\ncamera_error: ");
    CHECK_CONTAINS(out, "away.ini:9: [camera left]: ");
    CHECK_CONTAINS(out, "camera_name: right\ncamera: not open\ncamera_error: ");
    CHECK_CONTAINS(out, "lamps: not open\nlamps_error: ");
    CHECK_CONTAINS(out, "away.ini:5: [lamp key]: ");
    CHECK_CONTAINS(err, "refl rig identify: the camera left, the camera right and the lamps did not open");
    free(out);
    free(err);

    rc = refl(&out, &err, "rig", "--rig", rig, "status", NULL);
    CHECK_MSG(rc == 1, "status: %d %s", rc, err);
    CHECK_CONTAINS(out, "turntable_homed: no\nturntable_moving: no\nlamps: not open\n");
    CHECK_CONTAINS(out, "cameras: 2\ncamera_name: left\ncamera: not open\n");
    CHECK_CONTAINS(err, "did not open (their DEVICE_error lines above)");
    free(out);
    free(err);

    rc = refl(&out, &err, "rig", "--rig", rig, "status", "--only", "turntable", NULL);
    CHECK_MSG(rc == 0, "status --only turntable: %d %s", rc, err);
    CHECK_CONTAINS(out, "turntable: sim turntable (seed 4)\n");
    CHECK(out && !strstr(out, "camera") && !strstr(out, "lamp"));
    free(out);
    free(err);
    rc = refl(&out, &err, "rig", "--rig", rig, "status", "--only", "camera", NULL);
    CHECK(rc == 1);
    CHECK_CONTAINS(out, "camera_name: right\ncamera: not open\n");
    CHECK(out && !strstr(out, "turntable") && !strstr(out, "lamp"));
    CHECK_CONTAINS(err, "the camera left and the camera right did not open");
    free(out);
    free(err);
    rc = refl(&out, &err, "rig", "--rig", rig, "identify", "--only", "lamps,turntable", NULL);
    CHECK(rc == 1);
    CHECK_CONTAINS(out, "turntable_model: K10CR1 (simulated)\n");
    CHECK_CONTAINS(out, "lamps_error: ");
    CHECK(out && !strstr(out, "camera"));
    CHECK_CONTAINS(err, "the lamps did not open (its lamps_error line above)");
    free(out);
    free(err);

    rc = refl(&out, &err, "rig", "--rig", rig, "move", "12.5", NULL);
    CHECK_MSG(rc == 0, "move: %d %s", rc, err);
    CHECK_CONTAINS(out, "turntable_commanded_deg: 12.5\nturntable_angle_deg: 12.5");
    free(out);
    free(err);
    // A real rig's bring-up: an APT stage that is not connected, sim lamps, a camera address nobody
    // serves. status reports all three (the lamps fine, the others on their error lines; exit 1);
    // --only lamps opens the lamps alone and succeeds.
    const char *bench = test_write("bench.ini", "[turntable]\nbackend = apt\nserial = 55000001\n"
                                   "[lamp key]\nbackend = sim\n[camera]\nbackend = aravis\naddress = 127.0.0.5\n");
    rc = refl(&out, &err, "rig", "--rig", bench, "status", NULL);
    CHECK_MSG(rc == 1, "status: %d %s", rc, err);
    CHECK_CONTAINS(out, "turntable: not open\nturntable_error: ");
    CHECK_CONTAINS(out, "bench.ini:1: [turntable]: ");
    CHECK_CONTAINS(out, "lamp key: off (sim)\n");
    CHECK_CONTAINS(out, "camera: not open\ncamera_error: ");
    CHECK_CONTAINS(out, "bench.ini:6: [camera]: aravis: no camera at '127.0.0.5'");
    CHECK_CONTAINS(err, "refl rig status: the turntable and the camera did not open (their DEVICE_error lines above)");
    free(out);
    free(err);
    rc = refl(&out, &err, "rig", "--rig", bench, "status", "--only", "lamps", NULL);
    CHECK_MSG(rc == 0, "status --only lamps: %d %s", rc, err);
    CHECK_CONTAINS(out, "lamp key: off (sim)\n");
    CHECK(out && !strstr(out, "turntable") && !strstr(out, "camera"));
    free(out);
    free(err);
    rc = refl(&out, &err, "rig", "--rig", bench, "identify", "--only", "turntable", NULL);
    CHECK_MSG(rc == 1, "identify --only turntable: %d %s", rc, err);
    CHECK_CONTAINS(out, "turntable_error: ");
    CHECK(out && !strstr(out, "camera") && !strstr(out, "lamp"));
    CHECK_CONTAINS(err, "refl rig identify: the turntable did not open (its turntable_error line above)");
    free(out);
    free(err);

    const char *bad[][3] = { { "status", "--only", "stage" }, { "home", "--only", "turntable" } };
    const char *want[] = { "'stage' is none of camera, turntable, lamps", "option --only is for status identify only" };
    for (int k = 0; k < 2; k++) {
        rc = refl(&out, &err, "rig", "--rig", rig, bad[k][0], bad[k][1], bad[k][2], NULL);
        CHECK(rc == 2);
        CHECK_CONTAINS(err, want[k]);
        free(out);
        free(err);
    }
}

// `refl rig snap -o FILE` checks FILE before the rig is opened (nothing is
// captured): its directory exists and is writable, FILE is no directory, it
// ends in .png.
TEST(rigcli_snap_checks_output_first)
{
    const char *rig = test_write("sim.ini",
                                 "[turntable]\nbackend = sim\ntime_scale = 0.001\n[lamp key]\nbackend = sim\n");
    char *out = NULL, *err = NULL;
    int rc = refl(&out, &err, "rig", "--rig", rig, "snap", "-o", test_path("no/such/dir/x.png"), NULL);
    CHECK(rc == 1);
    CHECK_CONTAINS(err, "no/such/dir does not exist");
    CHECK(err && !strstr(err, "opening"));   // before the rig is opened (this rig has no camera)
    free(out);
    free(err);
    const char *d = test_path("d.png");
    CHECK(mkdir(d, 0755) == 0);
    rc = refl(&out, &err, "rig", "--rig", rig, "snap", "-o", d, NULL);
    CHECK(rc == 1);
    CHECK_CONTAINS(err, "is a directory");
    CHECK(err && !strstr(err, "opening"));
    free(out);
    free(err);
    const char *f = test_write("plain", "x");
    char in_file[4200];
    snprintf(in_file, sizeof in_file, "%s/x.png", f);
    rc = refl(&out, &err, "rig", "--rig", rig, "snap", "-o", in_file, NULL);
    CHECK(rc == 1);
    CHECK_CONTAINS(err, "is not a directory");
    free(out);
    free(err);
    if (geteuid() != 0) {   // root writes anywhere
        const char *ro = test_path("ro");
        CHECK(mkdir(ro, 0555) == 0);
        char p[4200];
        snprintf(p, sizeof p, "%s/x.png", ro);
        rc = refl(&out, &err, "rig", "--rig", rig, "snap", "-o", p, NULL);
        CHECK(rc == 1);
        CHECK_CONTAINS(err, "cannot write in the directory");
        CHECK(err && !strstr(err, "opening"));
        free(out);
        free(err);
    }
    rc = refl(&out, &err, "rig", "--rig", rig, "snap", "-o", test_path("x.jpg"), NULL);
    CHECK(rc == 2);
    CHECK_CONTAINS(err, "must end in .png");
    free(out);
    free(err);
    // a good path goes on to the rig (which has no camera here)
    rc = refl(&out, &err, "rig", "--rig", rig, "snap", "-o", test_path("x.png"), NULL);
    CHECK(rc == 1);
    CHECK_CONTAINS(err, "has no camera");
    free(out);
    free(err);
}
