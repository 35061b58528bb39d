// tests/fixtures.c — setup that several tests share (tests/fixtures.h).
#define _GNU_SOURCE
#include <fcntl.h>
#include <glib.h>
#include <limits.h>
#include <mrcal/poseutils.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "model/internal.h"
#include "tests/fixtures.h"
#include "tests/test.h"

// ---------------------------------------------------------------------------
// Scenes, materials, lamps, pinhole cameras

model_scene_t *fx_scene_text(const char *d3d)
{
    model_scene_t *s = model_scene_parse_d3d(d3d, strlen(d3d), "test.d3d", NULL);
    if (!s) fprintf(stderr, "  scene: %s\n", model_last_error());
    return s;
}

model_materials_t *fx_materials_text(const char *ini)
{
    model_materials_t *m = model_materials_parse(ini, strlen(ini), "test_materials.ini");
    if (!m) fprintf(stderr, "  materials: %s\n", model_last_error());
    return m;
}

model_lamps_t *fx_lamps_text(const char *ini)
{
    model_lamps_t *l = model_lamps_parse(ini, strlen(ini), "test_lamps.ini");
    if (!l) fprintf(stderr, "  lamps: %s\n", model_last_error());
    return l;
}

char *fx_plane_d3d(double h, const char *extra_vertices, const char *extra_faces)
{
    char *buf = malloc(8192);
    snprintf(buf, 8192,
             "1 %g %g 0\n2 %g %g 0\n3 %g %g 0\n4 %g %g 0\n%s"
             "Faces:\n@material plane\n1 2 3 4.\n%s",
             -h, -h, h, -h, h, h, -h, h, extra_vertices ? extra_vertices : "",
             extra_faces ? extra_faces : "");
    return buf;
}

const char fx_box_vertices[] =
    "5 -50 -50 0\n6 50 -50 0\n7 50 50 0\n8 -50 50 0\n"
    "9 -50 -50 80\n10 50 -50 80\n11 50 50 80\n12 -50 50 80\n";
const char fx_box_faces[] =
    "@material box\n"
    "9 10 11 12.\n"      // top
    "5 6 10 9.\n"        // y = -50
    "6 7 11 10.\n"       // x = 50
    "7 8 12 11.\n"       // y = 50
    "8 5 9 12.\n";       // x = -50

bool fx_pinhole_look(fx_pinhole_t *p, int W, int H, double f, model_vec3_t C, model_vec3_t target)
{
    model_vec3_t z = v3_unit(v3_sub(target, C));
    model_vec3_t up = fabs(z.z) > 0.99 ? v3(0, 1, 0) : v3(0, 0, 1);
    model_vec3_t x = v3_unit(v3_cross(z, up));
    model_vec3_t y = v3_cross(z, x);
    double R[9] = { x.x, x.y, x.z, y.x, y.y, y.z, z.x, z.y, z.z };
    double rt[6];
    mrcal_r_from_R(rt, NULL, R);
    for (int i = 0; i < 3; i++)
        rt[3 + i] = -(R[3 * i] * C.x + R[3 * i + 1] * C.y + R[3 * i + 2] * C.z);
    memcpy(p->R, R, sizeof R);
    p->C = C;
    p->f = f;
    p->cx = (W - 1) / 2.0;
    p->cy = (H - 1) / 2.0;
    p->W = W;
    p->H = H;
    double intr[4] = { f, f, p->cx, p->cy };
    p->cam = model_camera_new("LENSMODEL_PINHOLE", intr, W, H, rt);
    if (!p->cam) fprintf(stderr, "  camera: %s\n", model_last_error());
    return p->cam != NULL;
}

model_camera_t *fx_pinhole_camera(int W, int H, double f, model_vec3_t C, model_vec3_t target)
{
    fx_pinhole_t p;
    fx_pinhole_look(&p, W, H, f, C, target);
    return p.cam;
}

model_vec3_t fx_pinhole_ray(const fx_pinhole_t *p, double x, double y)
{
    double a = (x - p->cx) / p->f, b = (y - p->cy) / p->f;
    const double *R = p->R;
    model_vec3_t d = v3(R[0] * a + R[3] * b + R[6], R[1] * a + R[4] * b + R[7],
                        R[2] * a + R[5] * b + R[8]);
    return v3_unit(d);
}

bool fx_render_open(fx_render_t *f, char *d3d, const char *materials, const char *lamps, int W, int H,
                    double focal, model_vec3_t C, model_vec3_t target)
{
    memset(f, 0, sizeof *f);
    f->d3d = d3d;
    f->s = fx_scene_text(d3d);
    f->m = materials ? fx_materials_text(materials) : NULL;
    f->l = fx_lamps_text(lamps);
    CHECK(f->s && (f->m || !materials) && f->l && fx_pinhole_look(&f->ph, W, H, focal, C, target));
    if (!f->s || (!f->m && materials) || !f->l || !f->ph.cam) return false;
    f->t = model_tracer_new(f->s);
    CHECK(f->t != NULL);
    if (!f->t) return false;
    if (!materials) return true;
    CHECK(f->s->nmaterials <= FX_MAX_MATERIALS && model_resolve_materials(f->s, f->m, f->mres));
    return f->s->nmaterials <= FX_MAX_MATERIALS;
}

void fx_render_close(fx_render_t *f)
{
    model_tracer_free(f->t);
    free(f->d3d);
    model_camera_free(f->ph.cam);
    model_scene_free(f->s);
    model_materials_free(f->m);
    model_lamps_free(f->l);
    memset(f, 0, sizeof *f);
}

// ---------------------------------------------------------------------------
// Turntables

rig_turntable_sim_params_t fx_fast_sim(void)
{
    rig_turntable_sim_params_t p = rig_turntable_sim_defaults();
    p.time_scale = 0.01;      // 10 s of stage time = 0.1 s
    p.home_time_s = 5;
    p.position_noise_deg = 0.001;
    return p;
}

apt_sim_t *fx_apt_sim_start(const apt_sim_device_t *devs, int n)
{
    char path[1024], msg[256];
    snprintf(path, sizeof path, "%s/tests/data/k10cr1.umockdev", test_srcdir());
    apt_sim_t *s = apt_sim_new(path, devs, n, msg, sizeof msg);
    CHECK_MSG(s != NULL, "apt_sim_new: %s", msg);
    return s;
}

rig_turntable_t *fx_apt_open_homed(void)
{
    rig_turntable_t *t = NULL;
    CHECK(rig_turntable_open_apt(&t, NULL, NULL) == 0);
    if (t) CHECK(rig_turntable_home(t, 2.0) == 0);
    return t;
}

// ---------------------------------------------------------------------------
// A virtual GigE Vision camera serving a test pattern

uint16_t fx_pattern(int sx, int sy, double exposure_us, double gain_db, int bits)
{
    double v = (double)((sx * 3 + sy * 5) % 97 + 1) * (exposure_us / 100.0) * pow(10.0, gain_db / 20.0);
    double maxv = (double)((1 << bits) - 1);
    return (uint16_t)(v >= maxv ? maxv : floor(v));
}

fx_pattern_ctx_t *fx_pattern_ctx_new(void)
{
    fx_pattern_ctx_t *ctx = calloc(1, sizeof *ctx);
    pthread_mutex_init(&ctx->lock, NULL);
    return ctx;
}

void fx_pattern_ctx_free(fx_pattern_ctx_t *ctx)
{
    if (!ctx) return;
    pthread_mutex_destroy(&ctx->lock);
    free(ctx);
}

int fx_render_pattern(void *vctx, const rig_frame_meta_t *m, uint16_t *pix)
{
    fx_pattern_ctx_t *ctx = vctx;
    if (atomic_load(&ctx->fail) > 0) {
        atomic_fetch_sub(&ctx->fail, 1);
        return rig_fail(RIG_ERR_IO, "test renderer: injected failure");
    }
    int ms = atomic_load(&ctx->sleep_ms);
    if (ms > 0) usleep((useconds_t)ms * 1000);
    // Saturate by hand in the 16-bit case too: the server would do the same.
    for (int y = 0; y < m->height; y++)
        for (int x = 0; x < m->width; x++)
            pix[(size_t)y * m->width + x] = fx_pattern(x + m->offset_x, y + m->offset_y, m->exposure_us, m->gain, m->bits);
    pthread_mutex_lock(&ctx->lock);
    ctx->last = *m;
    ctx->n++;
    pthread_mutex_unlock(&ctx->lock);
    return 0;
}

long fx_pattern_mismatches(const rig_frame_t *f)
{
    long bad = 0;
    const rig_frame_meta_t *m = &f->meta;
    for (int y = 0; y < m->height; y++)
        for (int x = 0; x < m->width; x++)
            if (f->pix[(size_t)y * m->width + x] !=
                fx_pattern(x + m->offset_x, y + m->offset_y, m->exposure_us, m->gain, m->bits))
                bad++;
    return bad;
}

bool fx_gv_open(fx_gv_t *f, bool open_camera)
{
    memset(f, 0, sizeof *f);
    f->session = test_camera_lock();
    f->ctx = fx_pattern_ctx_new();
    rig_gv_camera_params_t p = rig_gv_camera_defaults();
    p.serial = "TEST-0042";
    p.vendor = "refl-test";
    p.model = "pattern cam";
    p.render = fx_render_pattern;
    p.render_ctx = f->ctx;
    p.busy_wait_s = 120;   // another tree's tests may hold 127.0.0.1:3956
    int rc = rig_gv_camera_start(&f->g, &p);
    CHECK_MSG(rc == 0, "rig_gv_camera_start: %d %s", rc, model_last_error());
    if (!f->g) return false;
    if (!open_camera) return true;
    rc = rig_camera_open_aravis(&f->c, FX_GV_ADDR);
    CHECK_MSG(rc == 0, "open: %d %s", rc, model_last_error());
    return rc == 0;
}

void fx_gv_close(fx_gv_t *f)
{
    rig_camera_close(f->c);
    rig_gv_camera_stop(f->g);
    fx_pattern_ctx_free(f->ctx);
    test_camera_unlock(f->session);
    memset(f, 0, sizeof *f);
    f->session = -1;
}

char *fx_stdout_of(int (*fn)(rig_t *), rig_t *r, int *rc)
{
    const char *path = test_path("stdout.txt");
    fflush(stdout);
    int saved = dup(1), fd = open(path, O_WRONLY | O_CREAT | O_TRUNC, 0644);
    dup2(fd, 1);
    close(fd);
    *rc = fn(r);
    fflush(stdout);
    dup2(saved, 1);
    close(saved);
    return model_read_file(path, NULL);
}

const char *fx_truth_variant(const char *file, const char *name, const char *const *rep, const char *extra)
{
    char top[PATH_MAX];
    if (!realpath(test_srcdir(), top)) snprintf(top, sizeof top, "%s", test_srcdir());
    char *path = g_strdup_printf("%s/examples/%s", top, file);
    char *text = model_read_file(path, NULL);
    CHECK_MSG(text != NULL, "cannot read %s", path);
    g_free(path);
    if (!text) return "";
    GString *s = g_string_new(text);
    free(text);
    for (int k = 0; rep && rep[k]; k += 2) {
        char *p = strstr(s->str, rep[k]);
        CHECK_MSG(p != NULL, "'%s' not in examples/%s", rep[k], file);
        if (!p) continue;
        size_t at = (size_t)(p - s->str);
        g_string_erase(s, (gssize)at, (gssize)strlen(rep[k]));
        g_string_insert(s, (gssize)at, rep[k + 1]);
    }
    // every relative path of the examples is on a "scene = " or "model = camera" line
    char *sep = g_strdup_printf("scene = %s/examples/", top), *msep = g_strdup_printf("model = %s/examples/camera", top);
    g_string_replace(s, "scene = ", sep, 0);
    g_string_replace(s, "model = camera", msep, 0);
    if (extra) g_string_append_printf(s, "\n%s", extra);
    const char *out = test_write(name, s->str);
    g_free(sep);
    g_free(msep);
    g_string_free(s, TRUE);
    return out;
}
