// calib/geometry/views.c — the views of a calibration: 8-bit copies of the frames
// of capture sessions (one tilt group each; several cameras' frames grouped by
// step) or of images captured elsewhere, in DIR/images for the corner finders.
#include <errno.h>
#include <glib.h>
#include <stdlib.h>
#include <string.h>

#include "calib/calib.h"
#include "calib/geometry/internal.h"
#include "model/model.h"
#include "model/base/report.h"

// Scale DN to 8 bits (full_scale -> 255) and write DIR/images/name.
static bool write_8bit(const char *path, const float *img, int w, int h, double full_scale)
{
    unsigned char *b = malloc((size_t)w * h);
    if (!b) {
        model_error_set(path, 0, "out of memory");
        return false;
    }
    for (size_t i = 0; i < (size_t)w * h; i++) {
        double v = img[i] * 255.0 / full_scale + 0.5;
        b[i] = v <= 0 ? 0 : v >= 255 ? 255 : (unsigned char)v;
    }
    bool ok = model_png8_write(path, w, h, b, NULL);
    free(b);
    return ok;
}

calib_geometry_view_t *geo_view_add(calib_geometry_views_t *vs, const char *name, const char *source,
                                    const char *session, int group, double angle, double tilt, double az)
{
    calib_geometry_view_t *v = calloc(1, sizeof *v);
    if (!v) {
        model_error_set(name, 0, "out of memory");
        return NULL;
    }
    v->name = g_strdup(name);
    v->source = g_strdup(source);
    v->session = g_strdup(session);
    v->group = group;
    v->angle_deg = angle;
    v->rms_px = NAN;
    v->tilt_deg = tilt;
    v->tilt_azimuth_deg = az;
    g_ptr_array_add(vs->v, v);
    return v;
}

// A new tilt group of the views (its tilt and hinge azimuth, deg): its index,
// -1 + message when out of memory.
static int group_add(calib_geometry_views_t *vs, double tilt, double az)
{
    double *gt = realloc(vs->group_tilt, (vs->ngroups + 1) * sizeof *gt);
    if (gt) vs->group_tilt = gt;
    double *ga = gt ? realloc(vs->group_az, (vs->ngroups + 1) * sizeof *ga) : NULL;
    if (ga) vs->group_az = ga;
    if (!ga) {
        model_error_set(NULL, 0, "out of memory");
        return -1;
    }
    int g = vs->ngroups++;
    vs->group_tilt[g] = tilt;
    vs->group_az[g] = az;
    return g;
}

static void view_free(gpointer p)
{
    calib_geometry_view_t *v = p;
    g_free(v->name);
    g_free(v->source);
    g_free(v->session);
    free(v->q);
    free(v);
}

void calib_geometry_views_init(calib_geometry_views_t *vs)
{
    memset(vs, 0, sizeof *vs);
    vs->v = g_ptr_array_new_with_free_func(view_free);
}

void calib_geometry_views_free(calib_geometry_views_t *vs)
{
    if (vs->v) g_ptr_array_free(vs->v, TRUE);
    free(vs->group_tilt);
    free(vs->group_az);
    memset(vs, 0, sizeof *vs);
}

calib_geometry_view_t *calib_geometry_view_find(calib_geometry_views_t *vs, const char *name)
{
    const char *b = strrchr(name, '/');
    b = b ? b + 1 : name;
    for (guint i = 0; i < vs->v->len; i++) {
        calib_geometry_view_t *v = g_ptr_array_index(vs->v, i);
        if (!strcmp(v->name, name)) return v;
    }
    for (guint i = 0; i < vs->v->len; i++) {
        calib_geometry_view_t *v = g_ptr_array_index(vs->v, i);
        const char *vb = strrchr(v->name, '/');
        vb = vb ? vb + 1 : v->name;
        if (!strcmp(vb, b)) return v;
    }
    return NULL;
}

// A session's frames of one camera → 8-bit images and views. sub NULL: names
// "SESSION-FRAME" in group g = a new one; else (several cameras) names
// "sub/fGGSSSSSS.png" (g: the group, already made; SSSSSS: the step) of camera cam.
static bool add_session_camera(calib_geometry_views_t *vs, const char *sdir, const char *camera, const char *imgdir,
                               const char *sub, int cam, int g, int *w, int *h)
{
    rig_session_t *s = rig_session_open_camera(sdir, camera);
    if (!s) return false;
    rig_plan_t *p = rig_plan_parse(s->plan_text, strlen(s->plan_text), sdir);
    if (!p) {
        rig_session_free(s);
        return false;
    }
    if (!sub && (g = group_add(vs, p->tilt_deg, p->tilt_azimuth_deg)) < 0) {
        rig_plan_free(p);
        rig_session_free(s);
        return false;
    }
    char *base = g_path_get_basename(sdir);
    bool ok = true;
    if (s->n == 0) model_warning("%s has no frames", sdir);
    for (int i = 0; i < s->n && ok; i++) {
        const rig_frame_row_t *r = &s->rows[i];
        int fw = 0, fh = 0;
        float *img = rig_session_frame(s, i, &fw, &fh);
        if (!img) {
            ok = false;
            break;
        }
        char *fb = g_path_get_basename(r->file);
        char *name = sub ? g_strdup_printf("%s/f%02d%06d.png", sub, g, r->step) : g_strdup_printf("%s-%s", base, fb);
        char *dst = g_strdup_printf("%s/%s", imgdir, name);
        char *src = g_strdup_printf("%s/%s", sdir, r->file);
        double full = !strcmp(r->pixel_format, "Mono8") ? 255 : !strcmp(r->pixel_format, "Mono16") ? 65535 : 4095;
        if (*w && (fw != *w || fh != *h)) {
            model_error_set(src, 0, "%dx%d pixels, the other frames are %dx%d: one camera and one region per "
                            "calibration",
                            fw, fh, *w, *h);
            ok = false;
        } else {
            *w = fw;
            *h = fh;
            ok = write_8bit(dst, img, fw, fh, full);
            calib_geometry_view_t *v =
                ok ? geo_view_add(vs, name, src, sdir, g, r->measured_deg, p->tilt_deg, p->tilt_azimuth_deg) : NULL;
            if (v) v->camera = cam;
            else ok = false;
        }
        free(img);
        g_free(fb);
        g_free(name);
        g_free(dst);
        g_free(src);
    }
    g_free(base);
    rig_plan_free(p);
    rig_session_free(s);
    return ok;
}

bool calib_geometry_add_session(calib_geometry_views_t *vs, const char *sdir, const char *camera, const char *imgdir,
                                int *w, int *h)
{
    return add_session_camera(vs, sdir, camera, imgdir, NULL, 0, -1, w, h);
}

bool calib_geometry_add_images(calib_geometry_views_t *vs, const char *pattern, const char *imgdir, int *w, int *h)
{
    char **paths = NULL;
    int npaths = 0, nread = 0;
    if (!model_image_list(pattern, &paths, &npaths)) return false;
    bool ok = true;
    for (int i = 0; i < npaths && ok; i++) {
        const char *src = paths[i];
        int fw = 0, fh = 0;
        float *img = model_image_read_float(src, &fw, &fh);
        if (!img) {   // not an image, or damaged: skipped, as views without a board are
            model_warning("skipped %s", model_last_error());
            continue;
        }
        nread++;
        if (*w && (fw != *w || fh != *h)) {
            model_error_set(src, 0, "%dx%d pixels, the other images are %dx%d: one camera and one region per "
                            "calibration",
                            fw, fh, *w, *h);
            free(img);
            ok = false;
            break;
        }
        *w = fw;
        *h = fh;
        float mx = 0;
        for (size_t k = 0; k < (size_t)fw * fh; k++) mx = img[k] > mx ? img[k] : mx;
        double full = mx <= 255 ? 255 : mx <= 4095 ? 4095 : 65535;
        char *b = g_path_get_basename(src);
        char *dot = strrchr(b, '.');
        if (dot) *dot = 0;
        char *name = g_strdup_printf("%03d-%s.png", i, b);
        char *dst = g_strdup_printf("%s/%s", imgdir, name);
        ok = write_8bit(dst, img, fw, fh, full);
        if (ok) ok = geo_view_add(vs, name, src, NULL, -1, NAN, NAN, NAN) != NULL;
        free(img);
        g_free(b);
        g_free(name);
        g_free(dst);
    }
    if (ok && nread == 0) {
        model_error_set(pattern, 0, "--images: none of its %d file%s is an image refl reads (PNG, JPEG or TIFF; "
                        "each is listed above with the reason)", npaths, npaths == 1 ? "" : "s");
        ok = false;
    }
    model_image_list_free(paths, npaths);
    return ok;
}

// The cameras of the first session when it has several and no --camera picks
// one: s->ncams, s->camnames (else s->ncams = 1). Names must be safe as
// directory names and globs.
static bool session_cameras(const calib_geometry_opts_t *o, calib_geometry_state_t *s, const char *sdir)
{
    s->ncams = 1;
    if (o->camera || !sdir) return true;
    rig_session_t *rs = rig_session_open(sdir);
    if (!rs) return false;
    const char *names[RIG_CAMERAS_MAX];
    int n = rig_session_cameras(rs, names, RIG_CAMERAS_MAX);
    bool ok = true;
    for (int k = 0; k < n && n > 1 && ok; k++) {
        if (!*names[k] || strspn(names[k], "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789_-") !=
            strlen(names[k])) {
            model_error_set(sdir, 0, "camera name '%s': calibrating several cameras needs names of letters, digits, "
                            "'_' and '-' (or give --camera NAME for one)", names[k]);
            ok = false;
        }
        snprintf(s->camnames[k], sizeof s->camnames[k], "%s", names[k]);
    }
    if (ok && n > 1) s->ncams = n;
    rig_session_free(rs);
    return ok;
}

// One session's frames of every camera (several cameras): one group, the
// views of camera k named camnames[k]/fGGSSSSSS.png.
static bool add_session_cameras(calib_geometry_state_t *s, const char *sd)
{
    calib_geometry_views_t *vs = &s->views;
    int g = vs->ngroups;
    for (int k = 0; k < s->ncams; k++) {
        char *sub = g_strdup_printf("%s/%s", s->imgdir, s->camnames[k]);
        bool ok = model_mkdir_p(sub) && add_session_camera(vs, sd, s->camnames[k], s->imgdir, s->camnames[k], k, g,
                                                           &s->camw[k], &s->camh[k]);
        g_free(sub);
        if (!ok) return false;
    }
    rig_session_t *rs = rig_session_open_camera(sd, s->camnames[0]);
    rig_plan_t *p = rs ? rig_plan_parse(rs->plan_text, strlen(rs->plan_text), sd) : NULL;
    bool ok = p && group_add(vs, p->tilt_deg, p->tilt_azimuth_deg) == g;
    rig_plan_free(p);
    rig_session_free(rs);
    return ok;
}

// Stage 1: the views of the sessions (given or captured) or the images.
bool geo_collect_views(const calib_geometry_opts_t *o, calib_geometry_state_t *s)
{
    s->W = o->imager_w;
    s->H = o->imager_h;
    int n = s->sessions ? (int)g_strv_length(s->sessions) : o->nsessions;
    if (!session_cameras(o, s, n ? (s->sessions ? s->sessions[0] : o->sessions[0]) : NULL)) return false;
    for (int k = 0; k < n; k++) {
        const char *sd = s->sessions ? s->sessions[k] : o->sessions[k];
        model_note("reading the frames of %s", sd);
        if (!(s->ncams > 1 ? add_session_cameras(s, sd)
                           : calib_geometry_add_session(&s->views, sd, o->camera, s->imgdir, &s->W, &s->H)) ||
            !model_provenance_input(s->prov, "session", sd))
            return false;
    }
    if (s->ncams > 1) {
        s->W = s->camw[0];
        s->H = s->camh[0];
        GString *l = g_string_new("");
        for (int k = 0; k < s->ncams; k++)
            g_string_append_printf(l, "%s%s %dx%d", k ? ", " : "", s->camnames[k], s->camw[k], s->camh[k]);
        model_note("%d cameras (%s), calibrated together; the rig frame from %s's views", s->ncams, l->str,
                   s->camnames[0]);
        g_string_free(l, TRUE);
    }
    if (o->images) {
        // said after reading: a failure's message names the path, once
        if (!calib_geometry_add_images(&s->views, o->images, s->imgdir, &s->W, &s->H)) return false;
        model_note("%u images from %s", s->views.v->len, o->images);
        for (guint k = 0; k < s->views.v->len; k++) {
            calib_geometry_view_t *v = g_ptr_array_index(s->views.v, k);
            if (!model_provenance_input(s->prov, "image", v->source)) return false;
        }
    }
    if (o->imager_w && (s->W != o->imager_w || s->H != o->imager_h)) {
        model_error_set(o->out, 0, "the frames are %dx%d, --imagersize says %dx%d", s->W, s->H, o->imager_w,
                        o->imager_h);
        return false;
    }
    return true;
}
