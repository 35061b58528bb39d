// calib/geometry/geometry.c — the library of `refl calib geometry` (calib/geometry/geometry.h;
// the command is calib/cmd_geometry.c): the camera model (mrgingham corners,
// mrcal solve), the turntable axis from the board poses, and the camera's
// extrinsics in the rig frame.
//
// Flow: capture (one session per board tilt, all lamps on) or sessions /
// images / a corners file captured elsewhere → 8-bit copies of the frames in
// DIR/images (mrgingham reads 8-bit; frames are Mono12 in 16-bit PNG) →
// mrgingham --gridn N (a square chessboard) or OpenCV (calib/geometry/board_detect.h:
// any chessboard, ChArUco boards whole or in part) → DIR/corners.vnl (a corner
// not seen "- -", as mrcal reads it) → mrcal-calibrate-cameras →
// DIR/mrcal/camera-0.cameramodel → scripts/calib_geometry_report.py solution
// (mrcal's board poses, residuals, projection uncertainty) → the axis fit and
// the rig frame here → DIR/camera.cameramodel, DIR/geometry.json,
// DIR/report.html.
//
// The rig frame recovered (see the help text): z along the fitted turntable
// axis (sign: counter-clockwise positive turntable angles, seen from +z);
// origin on the axis, board_height_mm below the board's corner plane at tilt 0
// (the table top); x the one of the board's four grid directions at angle 0,
// tilt 0 that is closest to the camera's +x (image right) once both are
// projected onto the table plane — so the board must lie square to the
// turntable's home orientation.
//
// Axis: for every pair of board poses at one tilt, R_rel = R_j R_i^T is a
// rotation about the axis by the turntable's angle difference, so its rotation
// vector r_ij ≈ Δθ_ij a; a = normalise(Σ Δθ r). The point c on the axis solves
// (I - R_rel) c = t_j - R_rel t_i for every pair in the least-squares sense
// (plus a·c = 0 to fix it along the axis). mrgingham orders the corners of a
// square grid up to a quarter turn about the board's centre (OpenCV those of
// another chessboard up to a half turn; a ChArUco board's carry their ids);
// each pose is made consistent with its tilt group's first pose by the turn
// whose relative rotation angle matches the turntable's. A partial view's
// corners not seen are NAN in its q and left out of every fit.
#define _GNU_SOURCE
#include <errno.h>
#include <glib.h>
#include <glob.h>
#include <math.h>
#include <mrcal/mrcal.h>
#include <mrcal/poseutils.h>
#include <png.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include "calib/calib.h"
#include "calib/geometry/export.h"
#include "calib/geometry/geometry.h"
#include "calib/geometry/psf.h"
#include "model/base/lsq.h"
#include "model/model.h"
#include "model/base/report.h"

#define DEG (M_PI / 180.0)

// ---------------------------------------------------------------------------
// Small vector helpers (3-vectors, row-major 3x3)

static void mat_mul(double out[9], const double a[9], const double b[9])
{
    double t[9];
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++) t[i * 3 + j] = a[i * 3] * b[j] + a[i * 3 + 1] * b[3 + j] + a[i * 3 + 2] * b[6 + j];
    memcpy(out, t, sizeof t);
}
static void mat_mul_bt(double out[9], const double a[9], const double b[9])   // a b^T
{
    double t[9];
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++)
            t[i * 3 + j] = a[i * 3] * b[j * 3] + a[i * 3 + 1] * b[j * 3 + 1] + a[i * 3 + 2] * b[j * 3 + 2];
    memcpy(out, t, sizeof t);
}
static void mat_vec(double out[3], const double m[9], const double v[3])
{
    double t[3];
    for (int i = 0; i < 3; i++) t[i] = m[i * 3] * v[0] + m[i * 3 + 1] * v[1] + m[i * 3 + 2] * v[2];
    memcpy(out, t, sizeof t);
}
static double dot3(const double a[3], const double b[3]) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
static double norm3(const double a[3]) { return sqrt(dot3(a, a)); }
static void cross3(double o[3], const double a[3], const double b[3])
{
    double t[3] = { a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0] };
    memcpy(o, t, sizeof t);
}
static void R_from_r(double R[9], const double r[3]) { mrcal_R_from_r((double *)R, NULL, r); }
static void r_from_R(double r[3], const double R[9]) { mrcal_r_from_R(r, NULL, R); }
static double wrap_deg(double d) { return d - 360.0 * floor((d + 180.0) / 360.0); }

// Invert a symmetric 3x3 matrix; false when singular.
static bool inv3(double o[9], const double m[9])
{
    double c[9] = { m[4] * m[8] - m[5] * m[7], m[2] * m[7] - m[1] * m[8], m[1] * m[5] - m[2] * m[4],
                    m[5] * m[6] - m[3] * m[8], m[0] * m[8] - m[2] * m[6], m[2] * m[3] - m[0] * m[5],
                    m[3] * m[7] - m[4] * m[6], m[1] * m[6] - m[0] * m[7], m[0] * m[4] - m[1] * m[3] };
    double det = m[0] * c[0] + m[1] * c[3] + m[2] * c[6];
    if (!(fabs(det) > 1e-300)) return false;
    for (int i = 0; i < 9; i++) o[i] = c[i] / det;
    return true;
}

// ---------------------------------------------------------------------------
// Images

static bool png8_write(const char *path, int w, int h, const unsigned char *pix)
{
    FILE *f = fopen(path, "wb");
    if (!f) {
        model_error_set(path, 0, "cannot create: %s", strerror(errno));
        return false;
    }
    png_structp p = png_create_write_struct(PNG_LIBPNG_VER_STRING, NULL, NULL, NULL);
    png_infop info = p ? png_create_info_struct(p) : NULL;
    bool ok = false;
    if (!p || !info) goto done;
    if (setjmp(png_jmpbuf(p))) goto done;
    png_init_io(p, f);
    png_set_compression_level(p, 1);
    png_set_IHDR(p, info, (png_uint_32)w, (png_uint_32)h, 8, PNG_COLOR_TYPE_GRAY, PNG_INTERLACE_NONE,
                 PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
    png_write_info(p, info);
    for (int y = 0; y < h; y++) png_write_row(p, (png_const_bytep)(pix + (size_t)y * w));
    png_write_end(p, NULL);
    ok = true;
done:
    png_destroy_write_struct(&p, &info);
    if (fclose(f) != 0) ok = false;
    if (!ok) model_error_set(path, 0, "cannot write the 8-bit PNG");
    return ok;
}

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
    bool ok = png8_write(path, w, h, b);
    free(b);
    return ok;
}

// ---------------------------------------------------------------------------
// Subprocesses

// Run argv in cwd; stdout and stderr into log_path (may be NULL); stdout also
// to *out (may be NULL). The exit status, -1 when it could not run.
static int run_tool(const char *cwd, char **argv, const char *log_path, char **out)
{
    GError *err = NULL;
    char *so = NULL, *se = NULL;
    gint status = 0;
    fflush(stderr);
    if (!g_spawn_sync(cwd, argv, NULL, G_SPAWN_SEARCH_PATH, NULL, NULL, &so, &se, &status, &err)) {
        model_error_set(argv[0], 0, "cannot run: %s (is it installed? Debian: apt install mrgingham mrcal)",
                        err ? err->message : "?");
        if (err) g_error_free(err);
        return -1;
    }
    if (log_path) {
        FILE *f = fopen(log_path, "w");
        if (f) {
            fprintf(f, "# %s", argv[0]);
            for (int i = 1; argv[i]; i++) fprintf(f, " '%s'", argv[i]);
            fprintf(f, "\n# (in %s)\n# stdout:\n%s\n# stderr:\n%s\n", cwd ? cwd : ".", so ? so : "", se ? se : "");
            fclose(f);
        }
    }
    int rc = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + (WIFSIGNALED(status) ? WTERMSIG(status) : 0);
    if (rc != 0 && se) {
        // the tail of its messages
        size_t n = strlen(se);
        fprintf(stderr, "%s: exit status %d; its last messages:\n%s\n", argv[0], rc, se + (n > 1500 ? n - 1500 : 0));
    }
    if (out) *out = so;
    else g_free(so);
    g_free(se);
    return rc;
}

// ---------------------------------------------------------------------------
// Views

static calib_geometry_view_t *view_add(calib_geometry_views_t *vs, const char *name, const char *source,
                                       const char *session, int group,
                        double angle, double tilt, double az)
{
    calib_geometry_view_t *v = calloc(1, sizeof *v);
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
    if (!sub) {
        g = vs->ngroups++;
        vs->group_tilt = realloc(vs->group_tilt, vs->ngroups * sizeof(double));
        vs->group_az = realloc(vs->group_az, vs->ngroups * sizeof(double));
        vs->group_tilt[g] = p->tilt_deg;
        vs->group_az[g] = p->tilt_azimuth_deg;
    }
    char *base = g_path_get_basename(sdir);
    bool ok = true;
    if (s->n == 0) fprintf(stderr, "refl calib geometry: %s has no frames\n", sdir);
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
            if (ok) view_add(vs, name, src, sdir, g, r->measured_deg, p->tilt_deg, p->tilt_azimuth_deg)->camera = cam;
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
            fprintf(stderr, "refl calib geometry: skipped %s\n", model_last_error());
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
        if (ok) view_add(vs, name, src, NULL, -1, NAN, NAN, NAN);
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

// A view's block of corner lines ends: it is the board when every corner has
// its line and one is seen, no board when it is one "- -" line; any other
// count is an error naming the block's first line.
static bool corners_block_end(calib_geometry_view_t *v, int nlines, int line0, const char *path,
                              const calib_board_t *b)
{
    int N = b->width_n * b->height_n;
    if (!v) return true;
    v->ncorners = 0;
    for (int k = 0; v->q && nlines == N && k < N; k++) v->ncorners += isfinite(v->q[2 * k]);
    v->found = nlines == N && v->ncorners > 0;
    if (nlines == N || (nlines == 1 && v->ncorners == 0)) return true;
    model_error_set(path, line0, "%s: %d corner lines; a %dx%d board has %d, one a corner in the board's order ('- -' "
                    "for one not seen), or one line 'NAME - -' for no board: is the board %dx%d (--object-width-n "
                    "--object-height-n)?", v->name, nlines, b->width_n, b->height_n, N, b->width_n, b->height_n);
    return false;
}

// Parse corners text (name x y [level]; "- -" or level "-" for a corner not
// seen; one line "name - -" when no board).
bool calib_geometry_parse_corners(calib_geometry_views_t *vs, const char *text, const char *path,
                                  const calib_board_t *b, bool create)
{
    int N = b->width_n * b->height_n;
    char **lines = g_strsplit(text, "\n", -1);
    bool ok = true;
    calib_geometry_view_t *cur = NULL;
    int ncur = 0, line0 = 0;
    for (int li = 0; lines[li] && ok; li++) {
        char *l = g_strstrip(lines[li]);
        if (!*l || *l == '#') continue;
        char name[1024], xs[64], ys[64], lev[64] = "";
        if (sscanf(l, "%1023s %63s %63s %63s", name, xs, ys, lev) < 3) {
            model_error_set(path, li + 1, "expected 'FILENAME X Y [LEVEL]' (mrgingham's output), got '%s'", l);
            ok = false;
            break;
        }
        calib_geometry_view_t *v = calib_geometry_view_find(vs, name);
        if (!v && create) v = view_add(vs, name, name, NULL, -1, NAN, NAN, NAN);
        if (v != cur) {
            if (!(ok = corners_block_end(cur, ncur, line0, path, b))) break;
            cur = v;
            ncur = 0;
            line0 = li + 1;
            if (v) {
                free(v->q);
                v->q = malloc((size_t)N * 2 * sizeof(double));
                for (int k = 0; k < 2 * N; k++) v->q[k] = NAN;
            }
        }
        if (!v) continue;     // not one of ours
        if (ncur >= N) {
            model_error_set(path, li + 1, "%s: more than %d corners: is the board %dx%d (--object-width-n %d "
                            "--object-height-n %d)?", name, N, b->width_n, b->height_n, b->width_n, b->height_n);
            ok = false;
            break;
        }
        int k = ncur++;
        if (!strcmp(xs, "-") || !strcmp(ys, "-") || !strcmp(lev, "-")) continue;   // not seen
        char *e1, *e2, *e3;
        double x = strtod(xs, &e1), y = strtod(ys, &e2), lv = *lev ? strtod(lev, &e3) : 0;
        if (*e1 || *e2 || !isfinite(x) || !isfinite(y) || (*lev && *e3)) {
            model_error_set(path, li + 1, "'%s %s%s%s' is not a pixel position (and decimation level)", xs, ys,
                            *lev ? " " : "", lev);
            ok = false;
            break;
        }
        if (x < 0 || y < 0 || lv < 0) continue;   // mrcal's "not seen" too
        v->q[2 * k] = x;
        v->q[2 * k + 1] = y;
    }
    if (ok) ok = corners_block_end(cur, ncur, line0, path, b);
    g_strfreev(lines);
    return ok;
}

// Views a lens model needs (a rule of thumb, stated in the error message).
int calib_geometry_default_min_views(const char *lensmodel)
{
    if (!strncmp(lensmodel, "LENSMODEL_SPLINED", 17)) return 20;
    if (!strcmp(lensmodel, "LENSMODEL_PINHOLE") || !strcmp(lensmodel, "LENSMODEL_STEREOGRAPHIC")) return 4;
    if (!strcmp(lensmodel, "LENSMODEL_OPENCV4")) return 6;
    if (!strcmp(lensmodel, "LENSMODEL_OPENCV5")) return 7;
    return 10;
}

// ---------------------------------------------------------------------------
// Poses, axis, rig frame

static void pose_R(double R[9], const calib_geometry_view_t *v) { R_from_r(R, v->rt_cam_board); }

// The board's centre in its frame (mm).
static void board_centre(const calib_board_t *b, double c[3])
{
    c[0] = (b->width_n - 1) * b->spacing_mm / 2;
    c[1] = (b->height_n - 1) * b->spacing_mm / 2;
    c[2] = 0;
}

// The quarter turns that map the board's corner grid onto itself and so may
// stand between two detections' corner orders: 1 (every quarter turn) for a
// square chessboard, 2 (half turns) for another, 4 (none) for ChArUco.
static int board_turn_step(const calib_board_t *b)
{
    if (b->kind == CALIB_BOARD_CHARUCO) return 4;
    return b->width_n == b->height_n ? 1 : 2;
}

// Turn a pose's board frame a quarter turn k times about the grid centre.
static void quarter_turn(double rt[6], int k, const calib_board_t *b)
{
    double R[9], Rz[9], rz[3] = { 0, 0, k * M_PI / 2 }, c[3];
    board_centre(b, c);
    R_from_r(R, rt);
    R_from_r(Rz, rz);
    double Rzc[3], d[3], Rd[3];
    mat_vec(Rzc, Rz, c);
    for (int i = 0; i < 3; i++) d[i] = c[i] - Rzc[i];
    mat_vec(Rd, R, d);
    double Rn[9];
    mat_mul(Rn, R, Rz);
    r_from_R(rt, Rn);
    for (int i = 0; i < 3; i++) rt[3 + i] += Rd[i];
}

static int cmp_angle(const void *a, const void *b)
{
    const calib_geometry_view_t *x = *(calib_geometry_view_t *const *)a, *y = *(calib_geometry_view_t *const *)b;
    return (x->angle_deg > y->angle_deg) - (x->angle_deg < y->angle_deg);
}

// The views of group g with a pose, sorted by angle; returns the count.
static int group_views(const calib_geometry_views_t *vs, int g, calib_geometry_view_t ***out)
{
    calib_geometry_view_t **l = malloc(vs->v->len * sizeof *l + 1);
    int n = 0;
    for (guint i = 0; i < vs->v->len; i++) {
        calib_geometry_view_t *v = g_ptr_array_index(vs->v, i);
        if (v->group == g && v->camera == 0 && v->solved && isfinite(v->angle_deg)) l[n++] = v;
    }
    qsort(l, n, sizeof *l, cmp_angle);
    *out = l;
    return n;
}

// A pair of views of one group whose turntable angles differ by 5..175 deg:
// the step d (rad), the relative rotation Rrel = Rj Ri^T and its rotation vector.
typedef struct {
    const calib_geometry_view_t *vi, *vj;
    double        d, Rrel[9], r[3];
} view_pair_t;

// Every such pair of every group (caller frees *out); *nviews: the views of
// groups with two or more.
static int view_pairs(const calib_geometry_views_t *vs, view_pair_t **out, int *nviews)
{
    int np = 0, cap = 0;
    view_pair_t *p = NULL;
    for (int g = 0; g < vs->ngroups; g++) {
        calib_geometry_view_t **l;
        int n = group_views(vs, g, &l);
        for (int i = 0; i < n; i++)
            for (int j = i + 1; j < n; j++) {
                double d = wrap_deg(l[j]->angle_deg - l[i]->angle_deg) * DEG;
                if (fabs(d) < 5 * DEG || fabs(d) > 175 * DEG) continue;
                if (np == cap) {
                    cap = cap ? 2 * cap : 64;
                    view_pair_t *q = realloc(p, (size_t)cap * sizeof *q);
                    if (!q) {
                        free(l);
                        *out = p;
                        return np;
                    }
                    p = q;
                }
                double Ri[9], Rj[9];
                pose_R(Ri, l[i]);
                pose_R(Rj, l[j]);
                view_pair_t *e = &p[np++];
                e->vi = l[i];
                e->vj = l[j];
                e->d = d;
                mat_mul_bt(e->Rrel, Rj, Ri);
                r_from_R(e->r, e->Rrel);
            }
        if (n >= 2) *nviews += n;
        free(l);
    }
    *out = p;
    return np;
}

bool calib_geometry_fit_axis(calib_geometry_views_t *vs, const calib_board_t *bd, calib_geometry_axis_t *ax)
{
    int step = board_turn_step(bd);
    memset(ax, 0, sizeof *ax);
    // 1. quarter turns within each group
    for (int g = 0; g < vs->ngroups; g++) {
        calib_geometry_view_t **l;
        int n = group_views(vs, g, &l);
        double Rref[9];
        if (n > 0) pose_R(Rref, l[0]);
        for (int m = 1; m < n; m++) {
            double d = fabs(wrap_deg(l[m]->angle_deg - l[0]->angle_deg)), best = 1e9;
            int bk = 0;
            for (int k = 0; k < 4; k += step) {
                double rt[6];
                memcpy(rt, l[m]->rt_cam_board, sizeof rt);
                quarter_turn(rt, k, bd);
                double R[9], Rrel[9], r[3];
                R_from_r(R, rt);
                mat_mul_bt(Rrel, R, Rref);
                r_from_R(r, Rrel);
                double cost = fabs(norm3(r) / DEG - d);
                if (cost < best) {
                    best = cost;
                    bk = k;
                }
            }
            quarter_turn(l[m]->rt_cam_board, bk, bd);
            l[m]->quarter_turns = bk;
            if (best > 2.0) {
                fprintf(stderr, "refl calib geometry: %s: its pose turns %.2f deg more or less than the turntable "
                        "(%.3f deg) relative to %s; left out of the axis fit\n", l[m]->name, best, d, l[0]->name);
                snprintf(l[m]->why, sizeof l[m]->why, "pose inconsistent with the turntable angle by %.2f deg", best);
                l[m]->solved = false;
            }
        }
        free(l);
    }
    // 2. direction and point from all pairs
    view_pair_t *pairs = NULL;
    ax->npairs = view_pairs(vs, &pairs, &ax->nviews);
    if (ax->npairs == 0) {
        free(pairs);
        return false;
    }
    double S[3] = { 0 };
    for (int q = 0; q < ax->npairs; q++)
        for (int k = 0; k < 3; k++) S[k] += pairs[q].d * pairs[q].r[k];
    double sn = norm3(S);
    for (int k = 0; k < 3; k++) ax->a[k] = S[k] / sn;
    double A[9] = { 0 }, b[3] = { 0 }, wsum = 0, dev2 = 0;
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++) A[i * 3 + j] = ax->a[i] * ax->a[j];
    for (int q = 0; q < ax->npairs; q++) {
        const double d = pairs[q].d, *Rrel = pairs[q].Rrel, *r = pairs[q].r;
        const calib_geometry_view_t *vi = pairs[q].vi, *vj = pairs[q].vj;
        double ap[3] = { r[0] / d, r[1] / d, r[2] / d }, an = norm3(ap);
        double cs = dot3(ap, ax->a) / an;
        double dv = acos(cs > 1 ? 1 : cs < -1 ? -1 : cs);
        dev2 += d * d * dv * dv;
        wsum += d * d;
        double M[9], rhs[3], Rti[3];
        for (int k = 0; k < 9; k++) M[k] = (k % 4 == 0 ? 1.0 : 0.0) - Rrel[k];
        mat_vec(Rti, Rrel, &vi->rt_cam_board[3]);
        for (int k = 0; k < 3; k++) rhs[k] = vj->rt_cam_board[3 + k] - Rti[k];
        for (int p = 0; p < 3; p++) {
            for (int c = 0; c < 3; c++)
                for (int k = 0; k < 3; k++) A[p * 3 + c] += M[k * 3 + p] * M[k * 3 + c];
            for (int k = 0; k < 3; k++) b[p] += M[k * 3 + p] * rhs[k];
        }
    }
    free(pairs);
    double Ai[9];
    if (!inv3(Ai, A)) return false;
    mat_vec(ax->c, Ai, b);
    // residuals of the point equations, and per-view rotation about / off the axis
    double e2 = 0;
    int ne = 0;
    double off2 = 0;
    int noff = 0;
    ax->fit = json_array();
    for (int g = 0; g < vs->ngroups; g++) {
        calib_geometry_view_t **l;
        int n = group_views(vs, g, &l);
        json_t *ang = json_array(), *rot = json_array();
        double Rref[9];
        if (n) pose_R(Rref, l[0]);
        for (int i = 0; i < n; i++) {
            double Ri[9], Rrel[9], r[3];
            pose_R(Ri, l[i]);
            mat_mul_bt(Rrel, Ri, Rref);
            r_from_R(r, Rrel);
            double along = dot3(r, ax->a);
            double perp[3] = { r[0] - along * ax->a[0], r[1] - along * ax->a[1], r[2] - along * ax->a[2] };
            if (i > 0) {
                off2 += dot3(perp, perp);
                noff++;
                double M[9], Mc[3], Rti[3];
                for (int k = 0; k < 9; k++) M[k] = (k % 4 == 0 ? 1.0 : 0.0) - Rrel[k];
                mat_vec(Mc, M, ax->c);
                mat_vec(Rti, Rrel, &l[0]->rt_cam_board[3]);
                for (int k = 0; k < 3; k++) {
                    double e = Mc[k] - (l[i]->rt_cam_board[3 + k] - Rti[k]);
                    e2 += e * e;
                }
                ne++;
            }
            json_array_append_new(ang, json_real(l[i]->angle_deg));
            json_array_append_new(rot, json_real(l[0]->angle_deg + along / DEG));
        }
        if (n >= 2) {
            json_t *gj = json_object();
            json_object_set_new(gj, "tilt_deg", json_real(vs->group_tilt[g]));
            json_object_set_new(gj, "tilt_azimuth_deg", json_real(vs->group_az[g]));
            json_object_set_new(gj, "angle_deg", ang);
            json_object_set_new(gj, "rotation_about_axis_deg", rot);
            json_array_append_new(ax->fit, gj);
        } else {
            json_decref(ang);
            json_decref(rot);
        }
        free(l);
    }
    int dof = ax->nviews - vs->ngroups;
    ax->off_axis_rms_deg = noff ? sqrt(off2 / noff) / DEG : 0;
    ax->dir_unc_deg = (wsum > 0 ? sqrt(dev2 / wsum) : 0) / sqrt(dof > 1 ? dof : 1) / DEG;
    ax->point_rms_mm = ne ? sqrt(e2 / (3.0 * ne)) : 0;
    double tr = Ai[0] + Ai[4] + Ai[8], aAa = 0, Aa[3];
    mat_vec(Aa, Ai, ax->a);
    aAa = dot3(ax->a, Aa);
    ax->point_unc_mm = ax->point_rms_mm * sqrt(fmax(tr - aAa, 0) / 2);
    ax->ok = true;
    return true;
}

// ---------------------------------------------------------------------------
// The axis refined jointly with the board poses (calib_geometry_refine_axis)
//
// Each tilt group's board has one pose P_g (at its first view's angle); view
// v of the group sees it turned about the axis by its turntable angle step:
// X = Rot(a, dtheta_v) (P_g(b) - c) + c. The axis (a: a0 + u e1 + v e2
// normalised; c: c0 + s e1 + t e2, e1, e2 across a0) and every P_g are fitted
// to the corners each view observed (projected with the solved camera, fixed),
// residuals in units of the per-axis corner noise (mrcal's RMS / sqrt 2). The
// Jacobians are central differences (10 parameters a view).

typedef struct {
    model_camera_t *cam;
    const double   *a0, *e1, *e2, *c0;   // the axis frame (closed-form axis)
    double          dtheta;              // rad: the view's angle minus its group's first
    int             n;                   // corners
    model_vec3_t   *b;                   // the board point of each observed corner
    double         *q;                   // observed corners (2 n; owned)
    double          inv_sigma;
    model_vec3_t   *x;                   // scratch (n)
    double         *qp;                  // scratch (2 n)
} axj_view_t;

static void axj_axis(const axj_view_t *w, const double *p, double a[3], double c[3])
{
    for (int k = 0; k < 3; k++) {
        a[k] = w->a0[k] + p[0] * w->e1[k] + p[1] * w->e2[k];
        c[k] = w->c0[k] + p[2] * w->e1[k] + p[3] * w->e2[k];
    }
    double n = norm3(a);
    for (int k = 0; k < 3; k++) a[k] /= n;
}

// The view's board pose: R, t of rt_g turned by dtheta about the axis p.
static void axj_pose(const axj_view_t *w, const double *p, const double *rt_g, double R[9], double t[3])
{
    double a[3], c[3], Rg[9], Rot[9], d[3];
    axj_axis(w, p, a, c);
    double r[3] = { w->dtheta * a[0], w->dtheta * a[1], w->dtheta * a[2] };
    R_from_r(Rot, r);
    R_from_r(Rg, rt_g);
    mat_mul(R, Rot, Rg);
    for (int k = 0; k < 3; k++) d[k] = rt_g[3 + k] - c[k];
    mat_vec(t, Rot, d);
    for (int k = 0; k < 3; k++) t[k] += c[k];
}

static bool axj_eval(const axj_view_t *w, const double *p, const double *rt_g, double *res)
{
    double R[9], t[3];
    axj_pose(w, p, rt_g, R, t);
    for (int i = 0; i < w->n; i++) {
        double b[3] = { w->b[i].x, w->b[i].y, w->b[i].z }, x[3];
        mat_vec(x, R, b);
        w->x[i] = (model_vec3_t){ x[0] + t[0], x[1] + t[1], x[2] + t[2] };
        if (!(w->x[i].z > 0)) return false;
    }
    if (!model_camera_project(w->cam, w->x, w->n, w->qp)) return false;
    for (int i = 0; i < 2 * w->n; i++) {
        res[i] = (w->qp[i] - w->q[i]) * w->inv_sigma;
        if (!isfinite(res[i])) return false;
    }
    return true;
}

// A view's corner RMS (px) at axis p and group pose rt_g (INFINITY: not evaluable).
static double axj_view_rms(const axj_view_t *w, const double *p, const double *rt_g, double sigma_px)
{
    double *res = malloc(2 * w->n * sizeof *res), ss = 0;
    if (res && axj_eval(w, p, rt_g, res))
        for (int k = 0; k < 2 * w->n; k++) ss += res[k] * res[k];
    else
        ss = INFINITY;
    free(res);
    return sqrt(ss / w->n) * sigma_px;
}

static bool axj_residual(void *ctx, const double *const *params, double *res, double **J)
{
    const axj_view_t *w = ctx;
    if (!axj_eval(w, params[0], params[1], res)) return false;
    if (!J) return true;
    int nr = 2 * w->n, sizes[2] = { 4, 6 };
    double *rp = malloc(2 * nr * sizeof *rp), *rm = rp + nr, pp[2][6];
    bool ok = rp != NULL;
    for (int blk = 0; ok && blk < 2; blk++) {
        if (!J[blk]) continue;
        for (int i = 0; ok && i < sizes[blk]; i++) {
            memcpy(pp[0], params[0], 4 * sizeof(double));
            memcpy(pp[1], params[1], 6 * sizeof(double));
            double h = (blk == 0 ? i < 2 : i < 3) ? 1e-7 : 1e-4;   // rad or mm
            pp[blk][i] += h;
            ok = axj_eval(w, pp[0], pp[1], rp);
            pp[blk][i] -= 2 * h;
            ok = ok && axj_eval(w, pp[0], pp[1], rm);
            for (int r = 0; ok && r < nr; r++) J[blk][r * sizes[blk] + i] = (rp[r] - rm[r]) / (2 * h);
        }
    }
    free(rp);
    return ok;
}

// The board point of each corner v observed (nearest projection of the grid
// under v's pose, within a third of the spacing, one to one): b[k], q[2 k] for
// the k-th corner seen (ncorners of them; the order of v's q, those not seen
// left out). false when they do not match.
static bool axj_match(const calib_geometry_view_t *v, model_camera_t *cam, const calib_board_t *bd, model_vec3_t *b,
                      double *q)
{
    int N = bd->width_n * bd->height_n, W = bd->width_n;
    double s = bd->spacing_mm;
    model_vec3_t *p = malloc(N * sizeof *p);
    double *qg = malloc(2 * N * sizeof *qg), R[9], spacing = INFINITY;
    int *used = calloc(N, sizeof *used), n = 0;
    R_from_r(R, v->rt_cam_board);
    for (int j = 0; j < N; j++) {
        double bb[3] = { (j % W) * s, (j / W) * s, 0 }, x[3];
        mat_vec(x, R, bb);
        p[j] = (model_vec3_t){ x[0] + v->rt_cam_board[3], x[1] + v->rt_cam_board[4], x[2] + v->rt_cam_board[5] };
    }
    bool ok = model_camera_project(cam, p, N, qg);
    for (int j = 0; ok && j < N; j++)   // the grid's spacing in the image: its nearest neighbours
        if (j % W) spacing = fmin(spacing, hypot(qg[2 * j] - qg[2 * j - 2], qg[2 * j + 1] - qg[2 * j - 1]));
    for (int j = W; ok && j < N; j++)
        spacing = fmin(spacing, hypot(qg[2 * j] - qg[2 * (j - W)], qg[2 * j + 1] - qg[2 * (j - W) + 1]));
    for (int i = 0; ok && i < N; i++) {
        if (!isfinite(v->q[2 * i])) continue;
        int best = -1;
        double bd2 = INFINITY;
        for (int j = 0; j < N; j++) {
            double d = hypot(qg[2 * j] - v->q[2 * i], qg[2 * j + 1] - v->q[2 * i + 1]);
            if (d < bd2) {
                bd2 = d;
                best = j;
            }
        }
        ok = best >= 0 && bd2 < spacing / 3 && !used[best]++;
        if (ok) {
            b[n] = (model_vec3_t){ (best % W) * s, (best / W) * s, 0 };
            q[2 * n] = v->q[2 * i];
            q[2 * n + 1] = v->q[2 * i + 1];
            n++;
        }
    }
    free(p);
    free(qg);
    free(used);
    return ok && n == v->ncorners;
}


static int cmp_double(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

// Axis-frame vectors across a0.
static void axj_frame(const double a0[3], double e1[3], double e2[3])
{
    double t[3] = { 1, 0, 0 };
    if (fabs(a0[0]) > 0.8) t[0] = 0, t[1] = 1;
    cross3(e1, a0, t);
    double n = norm3(e1);
    for (int k = 0; k < 3; k++) e1[k] /= n;
    cross3(e2, a0, e1);
}

// One group's views into the problem (w: its n views, filled); false + message.
static bool axj_group(lsq_problem_t *p, calib_geometry_view_t **l, int n, const calib_board_t *bd,
                      model_camera_t *cam, double sigma_px, axj_view_t *frame, double *rt_g, axj_view_t *w,
                      int *nused)
{
    int N = bd->width_n * bd->height_n;
    memcpy(rt_g, l[0]->rt_cam_board, 6 * sizeof(double));
    if (!lsq_add_parameters(p, rt_g, 6)) return false;
    for (int i = 0; i < n; i++) {
        w[i] = *frame;
        w[i].cam = cam;
        w[i].dtheta = wrap_deg(l[i]->angle_deg - l[0]->angle_deg) * DEG;
        w[i].n = N;
        w[i].b = malloc(N * sizeof *w[i].b);
        w[i].x = malloc(N * sizeof *w[i].x);
        w[i].qp = malloc(2 * N * sizeof *w[i].qp);
        w[i].q = malloc(2 * N * sizeof *w[i].q);
        w[i].inv_sigma = 1 / sigma_px;
        if (l[i]->q) w[i].n = l[i]->ncorners;
        if (!l[i]->q || !axj_match(l[i], cam, bd, w[i].b, w[i].q)) {
            fprintf(stderr, "refl calib geometry: %s: its corners do not match its pose; left out of the joint "
                    "axis fit\n", l[i]->name);
            w[i].n = 0;
            continue;
        }
        (*nused)++;
    }
    return true;
}

// The prepared views' residuals into the problem, but for those the closed
// form's start does not explain (corner RMS above 10 x the views' median, at
// least 2 px: a frame of another angle than its journal says, which the
// closed form's check of the turn's size alone lets through when the sign is
// wrong); those are marked unsolved and named. false + message.
static bool axj_add(lsq_problem_t *p, int ng, const int *cnt, axj_view_t **ws, calib_geometry_view_t ***lists,
                    double *axp, double *rt, double sigma_px, int *nused)
{
    double *rv = calloc(*nused + 1, sizeof *rv), *sorted = calloc(*nused + 1, sizeof *sorted);
    int nr = 0;
    for (int g = 0; rv && sorted && g < ng; g++)
        for (int i = 0; ws[g] && i < cnt[g]; i++) {
            if (!ws[g][i].n) continue;
            rv[nr] = sorted[nr] = axj_view_rms(&ws[g][i], axp, &rt[6 * g], sigma_px);
            nr++;
        }
    qsort(sorted, nr, sizeof *sorted, cmp_double);
    double med = nr ? sorted[nr / 2] : 0, limit = fmax(2.0, 10 * med);
    bool ok = rv && sorted;
    nr = 0;
    *nused = 0;
    for (int g = 0; ok && g < ng; g++)
        for (int i = 0; ok && ws[g] && i < cnt[g]; i++) {
            if (!ws[g][i].n) continue;
            if (rv[nr] > limit) {
                fprintf(stderr, "refl calib geometry: %s: its corners are %.1f px RMS from its group's board turned "
                        "to its turntable angle (%.3f deg; the views' median %.3f px): left out of the axis fit\n",
                        lists[g][i]->name, rv[nr], lists[g][i]->angle_deg, med);
                snprintf(lists[g][i]->why, sizeof lists[g][i]->why, "left out of the axis fit: its corners %.1f px "
                         "RMS from the board turned to its turntable angle (another angle than its journal says?)",
                         rv[nr]);
                lists[g][i]->solved = false;
                ws[g][i].n = 0;
            } else {
                double *blocks[2] = { axp, &rt[6 * g] };
                ok = lsq_add_residual(p, axj_residual, &ws[g][i], 2 * ws[g][i].n, 2, blocks, LSQ_LOSS_NONE, 0);
                (*nused)++;
            }
            nr++;
        }
    for (int g = 0; ok && g < ng; g++) {   // a group left without views: its pose held (no residual sees it)
        bool any = false;
        for (int i = 0; ws[g] && i < cnt[g]; i++) any = any || ws[g][i].n > 0;
        if (ws[g] && !any) ok = lsq_set_fixed(p, &rt[6 * g], NULL);
    }
    free(rv);
    free(sorted);
    return ok;
}

// One joint fit of the views group_views gives; *worst: the view of the
// largest corner RMS (px) *wrms, *med the views' median RMS.
static bool refine_once(calib_geometry_views_t *vs, const calib_board_t *bd, model_camera_t *cam,
                        double sigma_px, calib_geometry_axis_t *ax, calib_geometry_view_t **worst, double *wrms,
                        double *med)
{
    double a0[3], c0[3], e1[3], e2[3], axp[4] = { 0 };
    memcpy(a0, ax->a, sizeof a0);
    memcpy(c0, ax->c, sizeof c0);
    axj_frame(a0, e1, e2);
    axj_view_t frame = { .a0 = a0, .e1 = e1, .e2 = e2, .c0 = c0 };
    lsq_problem_t *p = lsq_problem_new();
    int ng = vs->ngroups, nused = 0, g0 = -1;
    double *rt = calloc((size_t)6 * (ng ? ng : 1), sizeof *rt);
    calib_geometry_view_t ***lists = calloc(ng ? ng : 1, sizeof *lists);
    int *cnt = calloc(ng ? ng : 1, sizeof *cnt);
    axj_view_t **ws = calloc(ng ? ng : 1, sizeof *ws);
    bool ok = p && rt && lists && cnt && ws && lsq_add_parameters(p, axp, 4);
    for (int g = 0; ok && g < ng; g++) {
        cnt[g] = group_views(vs, g, &lists[g]);
        if (cnt[g] < 1) continue;   // a group of one view: its pose only (the rig frame's sigma from it)
        ws[g] = calloc(cnt[g], sizeof *ws[g]);
        ok = axj_group(p, lists[g], cnt[g], bd, cam, sigma_px, &frame, &rt[6 * g], ws[g], &nused);
        if (g0 < 0 && fabs(vs->group_tilt[g]) < 1e-9) g0 = g;
    }
    if (ok) ok = axj_add(p, ng, cnt, ws, lists, axp, rt, sigma_px, &nused);
    if (ok && nused < 3) {
        model_error_set(NULL, 0, "the joint axis fit needs 3 views with matched corners, %d have them", nused);
        ok = false;
    }
    lsq_summary_t sum = { 0 };
    lsq_options_t lo = lsq_defaults();
    lo.threads = 2;
    if (ok) ok = lsq_solve(p, &lo, &sum);
    double cov[16], cg[36];
    if (ok) ok = lsq_covariance(p, axp, cov);
    if (ok) {
        int dof = sum.nresiduals - sum.nfree;
        double chi2 = dof > 0 ? 2 * sum.final_cost / dof : 1, k2 = fmax(chi2, 1);
        frame.cam = cam;
        axj_axis(&frame, axp, ax->a, ax->c);
        ax->joint = true;
        ax->joint_views = nused;
        ax->joint_rms_px = sqrt(2 * sum.final_cost / sum.nresiduals) * sigma_px;
        ax->joint_chi2 = chi2;
        ax->dir_unc_deg = sqrt(k2 * (cov[0] + cov[5])) / DEG;
        ax->point_unc_mm = sqrt(k2 * (cov[10] + cov[15]));
        ax->rig_x_unc_deg = ax->rig_origin_along_mm = NAN;
        if (g0 >= 0 && lsq_covariance(p, &rt[6 * g0], cg)) {
            double vr = 0, vt = 0;
            for (int i = 0; i < 3; i++)
                for (int j = 0; j < 3; j++) {
                    vr += ax->a[i] * cg[i * 6 + j] * ax->a[j];
                    vt += ax->a[i] * cg[(3 + i) * 6 + 3 + j] * ax->a[j];
                }
            ax->rig_x_unc_deg = sqrt(k2 * fmax(vr, 0)) / DEG;
            ax->rig_origin_along_mm = sqrt(k2 * fmax(vt, 0));
        }
        double *rv = calloc(nused + 1, sizeof *rv);
        int nr = 0;
        *worst = NULL;
        *wrms = 0;
        for (int g = 0; rv && g < ng; g++)   // each view's corner RMS
            for (int i = 0; ws[g] && i < cnt[g]; i++) {
                if (!ws[g][i].n) continue;
                rv[nr] = axj_view_rms(&ws[g][i], axp, &rt[6 * g], sigma_px);
                if (rv[nr] > *wrms) {
                    *wrms = rv[nr];
                    *worst = lists[g][i];
                }
                nr++;
            }
        qsort(rv, nr, sizeof *rv, cmp_double);
        *med = nr ? rv[nr / 2] : 0;
        free(rv);
        for (int g = 0; g < ng; g++)   // the poses as the fit has them: turned about the axis
            for (int i = 0; ws[g] && i < cnt[g]; i++) {
                double R[9], t[3];
                axj_pose(&ws[g][i], axp, &rt[6 * g], R, t);
                r_from_R(lists[g][i]->rt_cam_board, R);
                memcpy(&lists[g][i]->rt_cam_board[3], t, sizeof t);
            }
    }
    for (int g = 0; g < ng; g++) {
        for (int i = 0; ws && ws[g] && i < cnt[g]; i++) {
            free(ws[g][i].b);
            free(ws[g][i].q);
            free(ws[g][i].x);
            free(ws[g][i].qp);
        }
        if (ws) free(ws[g]);
        if (lists) free(lists[g]);
    }
    free(ws);
    free(lists);
    free(cnt);
    free(rt);
    lsq_problem_free(p);
    return ok;
}

bool calib_geometry_refine_axis(calib_geometry_views_t *vs, const calib_board_t *bd, model_camera_t *cam,
                                double sigma_px, calib_geometry_axis_t *ax)
{
    if (!ax->ok || !(sigma_px > 0)) return false;
    // the closed form and mrcal's poses: every attempt starts from them
    calib_geometry_axis_t ax0 = *ax;
    guint n = vs->v->len;
    double *rt0 = malloc((size_t)6 * (n ? n : 1) * sizeof *rt0);
    for (guint k = 0; k < n; k++)
        memcpy(&rt0[6 * k], ((calib_geometry_view_t *)g_ptr_array_index(vs->v, k))->rt_cam_board, 6 * sizeof *rt0);
    bool ok = false, failed = false;
    for (int attempt = 0; attempt < 10; attempt++) {
        *ax = ax0;
        for (guint k = 0; k < n; k++)
            memcpy(((calib_geometry_view_t *)g_ptr_array_index(vs->v, k))->rt_cam_board, &rt0[6 * k],
                   6 * sizeof *rt0);
        calib_geometry_view_t *worst = NULL;
        double wrms = 0, med = 0;
        if (!(ok = refine_once(vs, bd, cam, sigma_px, ax, &worst, &wrms, &med))) {
            failed = true;
            break;
        }
        // a view the turns about the axis do not explain (a frame of another angle than its journal says, a
        // board moved between frames) leaves, and the fit is done again without it
        double limit = fmax(0.5, 5 * med);
        if (!worst || wrms <= limit) break;
        fprintf(stderr, "refl calib geometry: %s: its corners are %.2f px RMS from the joint axis fit (the views' "
                "median %.3f px): its board is not where the turntable's angle puts it; left out of the axis fit\n",
                worst->name, wrms, med);
        snprintf(worst->why, sizeof worst->why, "left out of the joint axis fit: its corners %.2f px RMS from the "
                 "board turned to its turntable angle", wrms);
        worst->solved = false;
        ok = false;
    }
    if (!ok) {
        *ax = ax0;
        for (guint k = 0; k < n; k++)
            memcpy(((calib_geometry_view_t *)g_ptr_array_index(vs->v, k))->rt_cam_board, &rt0[6 * k],
                   6 * sizeof *rt0);
        if (!failed) model_error_set(NULL, 0, "the joint axis fit did not settle (ten views left out one by one)");
    }
    free(rt0);
    return ok;
}

// rt_cam_rig from the axis and the tilt-0 group's first pose; false + why.
bool calib_geometry_rig_frame(calib_geometry_views_t *vs, double board_height_mm, const calib_geometry_axis_t *ax,
                              double rt_cam_rig[6], char *why, size_t whyn)
{
    int g0 = -1;
    for (int g = 0; g < vs->ngroups && g0 < 0; g++)
        if (fabs(vs->group_tilt[g]) < 1e-9) g0 = g;
    if (g0 < 0) {
        snprintf(why, whyn, "no session at tilt 0 (the board flat on the table defines the rig frame's origin "
                 "and x)");
        return false;
    }
    calib_geometry_view_t **l;
    int n = group_views(vs, g0, &l);
    if (n == 0) {
        free(l);
        snprintf(why, whyn, "no board found at tilt 0");
        return false;
    }
    calib_geometry_view_t *v = l[0];
    free(l);
    double R[9];
    pose_R(R, v);
    const double *t = &v->rt_cam_board[3];
    double d[3] = { t[0] - ax->c[0], t[1] - ax->c[1], t[2] - ax->c[2] };
    double s = dot3(ax->a, d) - board_height_mm;
    double O[3] = { ax->c[0] + s * ax->a[0], ax->c[1] + s * ax->a[1], ax->c[2] + s * ax->a[2] };
    // board grid directions at angle 0
    double rb[3] = { -v->angle_deg * DEG * ax->a[0], -v->angle_deg * DEG * ax->a[1], -v->angle_deg * DEG * ax->a[2] };
    double Rb[9];
    R_from_r(Rb, rb);
    double ex[3] = { 1, 0, 0 }, exp_[3], best = -2, xr[3] = { 0 };
    double ea = dot3(ex, ax->a);
    for (int k = 0; k < 3; k++) exp_[k] = ex[k] - ea * ax->a[k];
    double en = norm3(exp_);
    for (int c = 0; c < 2; c++)
        for (int sgn = -1; sgn <= 1; sgn += 2) {
            double u[3] = { sgn * R[c], sgn * R[3 + c], sgn * R[6 + c] }, u0[3];
            mat_vec(u0, Rb, u);
            double ua = dot3(u0, ax->a);
            for (int k = 0; k < 3; k++) u0[k] -= ua * ax->a[k];
            double un = norm3(u0);
            if (un < 1e-6) continue;
            double cs = dot3(u0, exp_) / (un * en);
            if (cs > best) {
                best = cs;
                for (int k = 0; k < 3; k++) xr[k] = u0[k] / un;
            }
        }
    double yr[3];
    cross3(yr, ax->a, xr);
    double Rcr[9] = { xr[0], yr[0], ax->a[0], xr[1], yr[1], ax->a[1], xr[2], yr[2], ax->a[2] };
    r_from_R(rt_cam_rig, Rcr);
    memcpy(&rt_cam_rig[3], O, sizeof O);
    return true;
}

// rt_a_c = rt_a_b ∘ rt_b_c
static void compose(double out[6], const double ab[6], const double bc[6])
{
    double Rab[9], Rbc[9], R[9], t[3];
    R_from_r(Rab, ab);
    R_from_r(Rbc, bc);
    mat_mul(R, Rab, Rbc);
    mat_vec(t, Rab, &bc[3]);
    r_from_R(out, R);
    for (int k = 0; k < 3; k++) out[3 + k] = t[k] + ab[3 + k];
}
static void invert(double out[6], const double rt[6])
{
    double R[9], Rt[9], t[3];
    R_from_r(R, rt);
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++) Rt[i * 3 + j] = R[j * 3 + i];
    mat_vec(t, Rt, &rt[3]);
    r_from_R(out, Rt);
    for (int k = 0; k < 3; k++) out[3 + k] = -t[k];
}

// Why a view in a group with poses has no board: predict the board's pose from
// the group's first pose turned about the axis, and look at it.
void calib_geometry_explain_missing(calib_geometry_views_t *vs, const calib_board_t *bd,
                                    const calib_geometry_axis_t *ax, model_camera_t *cam, int W, int H)
{
    const double square_mm = bd->spacing_mm;
    // the sign of normal . (to camera) on the found views
    double sgn = 0;
    for (guint i = 0; i < vs->v->len && sgn == 0; i++) {
        calib_geometry_view_t *v = g_ptr_array_index(vs->v, i);
        if (!v->solved || v->camera != 0) continue;
        double R[9];
        pose_R(R, v);
        double n[3] = { R[2], R[5], R[8] };
        double c[3], p[3];
        board_centre(bd, c);
        mat_vec(p, R, c);
        for (int k = 0; k < 3; k++) p[k] = -(p[k] + v->rt_cam_board[3 + k]);
        sgn = dot3(n, p) > 0 ? 1 : -1;
    }
    for (guint i = 0; i < vs->v->len; i++) {
        calib_geometry_view_t *v = g_ptr_array_index(vs->v, i);
        if (v->found) continue;
        if (!v->why[0])
            snprintf(v->why, sizeof v->why, "no %dx%d board found", bd->width_n, bd->height_n);
        if (!ax || !ax->ok || v->group < 0 || v->camera != 0 || !isfinite(v->angle_deg)) continue;
        calib_geometry_view_t **l;
        int n = group_views(vs, v->group, &l);
        if (n == 0) {
            free(l);
            continue;
        }
        calib_geometry_view_t *ref = l[0];
        free(l);
        double d = wrap_deg(v->angle_deg - ref->angle_deg) * DEG;
        double r[3] = { d * ax->a[0], d * ax->a[1], d * ax->a[2] }, Rrot[9], Rref[9], R[9], t[3], tc[3];
        R_from_r(Rrot, r);
        pose_R(Rref, ref);
        mat_mul(R, Rrot, Rref);
        for (int k = 0; k < 3; k++) tc[k] = ref->rt_cam_board[3 + k] - ax->c[k];
        mat_vec(t, Rrot, tc);
        for (int k = 0; k < 3; k++) t[k] += ax->c[k];
        // the squares' corners, outer edge included (mrgingham needs every square)
        int nex = bd->width_n + 2, ney = bd->height_n + 2, M = nex * ney;
        model_vec3_t *p = malloc(M * sizeof *p);
        double *q = malloc(2 * M * sizeof *q);
        for (int jj = 0; jj < ney; jj++)
            for (int ii = 0; ii < nex; ii++) {
                double b[3] = { (ii - 1) * square_mm, (jj - 1) * square_mm, 0 }, x[3];
                mat_vec(x, R, b);
                p[jj * nex + ii] = (model_vec3_t){ x[0] + t[0], x[1] + t[1], x[2] + t[2] };
            }
        int outside = 0;
        bool behind = false;
        for (int k = 0; k < M; k++) if (p[k].z <= 0) behind = true;
        if (!behind && model_camera_project(cam, p, M, q))
            for (int k = 0; k < M; k++)
                if (!(q[2 * k] >= 0 && q[2 * k] <= W - 1 && q[2 * k + 1] >= 0 && q[2 * k + 1] <= H - 1)) outside++;
        double nb[3] = { R[2], R[5], R[8] }, cc[3], pc[3];
        board_centre(bd, cc);
        mat_vec(pc, R, cc);
        for (int k = 0; k < 3; k++) pc[k] = -(pc[k] + t[k]);
        double cs = sgn * dot3(nb, pc) / norm3(pc);
        double obl = acos(cs > 1 ? 1 : cs < -1 ? -1 : cs) / DEG;
        char pred[sizeof v->why];
        if (behind || outside)
            snprintf(pred, sizeof pred, "board partly outside the image (predicted from the axis fit: %d of "
                     "its %d square corners outside)", behind ? M : outside, M);
        else if (cs <= 0)
            snprintf(pred, sizeof pred, "board seen from behind (predicted from the axis fit: %.0f deg between "
                     "its normal and the view direction)", obl);
        else if (obl > 65)
            snprintf(pred, sizeof pred, "board too oblique (predicted from the axis fit: %.0f deg between its "
                     "normal and the view direction)", obl);
        else
            snprintf(pred, sizeof pred, "%s found no board although it is predicted fully in view at "
                     "%.0f deg obliquity (dark, blurred, glare or occluded?)", v->ncorners ? "the detector" :
                     strncmp(v->why, "mrgingham", 9) ? "OpenCV" : "mrgingham", obl);
        if (v->ncorners > 0) {   // a partial view left out: its reason, and the prediction
            size_t len = strlen(v->why);
            snprintf(v->why + len, sizeof v->why - len, "; %s", pred);
        } else {
            memcpy(v->why, pred, sizeof pred);
        }
        free(p);
        free(q);
    }
}

// ---------------------------------------------------------------------------
// Output

static json_t *jarr(const double *x, int n)
{
    json_t *a = json_array();
    for (int i = 0; i < n; i++) json_array_append_new(a, json_real(x[i]));
    return a;
}

static bool write_cameramodel_ref(const char *path, const char *lensmodel, json_t *intr, int W, int H,
                                  const double rt[6], const char *ref, double rms);

bool calib_geometry_write_cameramodel(const char *path, const char *lensmodel, json_t *intr, int W, int H,
                              const double rt[6], bool rig, double rms)
{
    return write_cameramodel_ref(path, lensmodel, intr, W, H, rt,
                                 rig ? "the rig frame: origin on the fitted turntable axis at the table top, z up along "
                                       "the axis (counter-clockwise angles positive), x the board's grid direction at "
                                       "angle 0, tilt 0 closest to the image's +x"
                                     : "the camera itself (no turntable angles in the input: no rig frame)", rms);
}

// The model with the extrinsics' reference frame described by ref.
static bool write_cameramodel_ref(const char *path, const char *lensmodel, json_t *intr, int W, int H,
                                  const double rt[6], const char *ref, double rms)
{
    char *tmp = g_strdup_printf("%s.part", path);
    FILE *f = fopen(tmp, "w");
    if (!f) {
        model_error_set(path, 0, "cannot create: %s", strerror(errno));
        g_free(tmp);
        return false;
    }
    fprintf(f, "# refl calib geometry (refl %s): camera model from mrgingham corners and mrcal; RMS reprojection "
            "residual %.4f px.\n", REFL_VERSION, rms);
    fprintf(f, "# Units mm. extrinsics are rt_cam_ref (r in rad, t in mm) with ref = %s\n", ref);
    fprintf(f, "{\n    'lensmodel':  '%s',\n\n    # intrinsics are fx,fy,cx,cy,distortion0,distortion1,....\n"
            "    'intrinsics': [", lensmodel);
    size_t i;
    json_t *x;
    json_array_foreach(intr, i, x) fprintf(f, "%s%.17g,", i % 4 == 0 ? "\n        " : " ", json_real_value(x));
    fprintf(f, "\n    ],\n\n    # extrinsics are rt_fromref\n    'extrinsics': [");
    for (int k = 0; k < 6; k++) fprintf(f, " %.17g,", rt[k]);
    fprintf(f, " ],\n\n    'imagersize': [ %d, %d ],\n}\n", W, H);
    bool ok = !ferror(f);
    if (fclose(f) != 0) ok = false;
    if (ok && rename(tmp, path) != 0) ok = false;
    if (!ok) {
        model_error_set(path, 0, "cannot write: %s", strerror(errno));
        unlink(tmp);
    }
    g_free(tmp);
    return ok;
}

// ---------------------------------------------------------------------------
// The command

static bool parse_num(const char *s, double lo, double hi, double *out)
{
    char *e;
    errno = 0;
    double v = strtod(s, &e);
    if (e == s || *e || errno || !(v >= lo && v <= hi)) return false;
    *out = v;
    return true;
}

// "T[@AZ][:A,A,...]" → plan text; NULL + message.
char *calib_geometry_tilt_plan(const char *spec, const calib_geometry_opts_t *o, char *name, size_t namen)
{
    char *s = g_strdup(spec), *angles = strchr(s, ':'), *at;
    if (angles) *angles++ = 0;
    double tilt = 0, az = 0;
    if ((at = strchr(s, '@'))) *at++ = 0;
    if (!parse_num(s, -80, 80, &tilt) || (at && !parse_num(at, -360, 360, &az))) {
        model_error_set("--tilts", 0, "'%s': write TILT[@AZIMUTH][:ANGLE,ANGLE,...] in degrees, tilt -80..80 "
                        "(e.g. 30@90:0,20,40)", spec);
        g_free(s);
        return NULL;
    }
    GString *al = g_string_new("");
    const char *src = angles ? angles : o->angles;
    char **parts = g_strsplit_set(src, ", ", -1);
    int na = 0;
    for (int i = 0; parts[i]; i++) {
        if (!*parts[i]) continue;
        double a;
        if (!parse_num(parts[i], -10000, 10000, &a)) {
            model_error_set(angles ? "--tilts" : "--angles", 0, "'%s' in '%s' is not an angle in degrees", parts[i],
                            src);
            g_strfreev(parts);
            g_string_free(al, TRUE);
            g_free(s);
            return NULL;
        }
        g_string_append_printf(al, " %g", a);
        na++;
    }
    g_strfreev(parts);
    if (na == 0) {
        model_error_set(angles ? "--tilts" : "--angles", 0, "'%s': no angles", spec);
        g_string_free(al, TRUE);
        g_free(s);
        return NULL;
    }
    snprintf(name, namen, "tilt%g_az%g", tilt, az);
    char what[512];   // the operator's instruction
    if (tilt == 0)
        snprintf(what, sizeof what, "lay the calibration board %s flat at the turntable centre, printed side up "
                 "(no wedge; --tilts '%s')", o->sample, spec);
    else
        snprintf(what, sizeof what, "mount the calibration board %s on the %g deg wedge (hinge at azimuth %g deg; "
                 "--tilts '%s') at the turntable centre, the board facing the camera", o->sample, tilt, az, spec);
    char *plan = g_strdup_printf("# refl calib geometry: the board at tilt %g deg (hinge azimuth %g deg)\n"
                                 "[plan]\nname = calib geometry %s\n"
                                 "[sample]\nname = %s\nkind = chessboard\ntilt_deg = %g\ntilt_azimuth_deg = %g\n"
                                 "instruction = %s\n"
                                 "[angles]\nlist =%s\n[lamps]\nsets = all\n"
                                 "[exposure]\nmode = fixed\nlist_us = %g\npixel_format = Mono12\n"
                                 "[capture]\nsettle_ms = 0\n",
                                 tilt, az, name, o->sample, tilt, az, what, al->str, o->exposure_us);
    g_string_free(al, TRUE);
    g_free(s);
    return plan;
}

calib_detector_t calib_geometry_detector(calib_detector_t d, const calib_board_t *b)
{
    if (d != CALIB_DETECTOR_AUTO) return d;
    return b->kind == CALIB_BOARD_CHESSBOARD && b->width_n == b->height_n ? CALIB_DETECTOR_MRGINGHAM
                                                                          : CALIB_DETECTOR_OPENCV;
}

// The corners: from --corners (*text: the file's), mrgingham's on the 8-bit
// images, or OpenCV's (calib/geometry/board_detect.h) in mrgingham's format; then
// calib_geometry_find_corners leaves out the views of too few corners and
// writes DIR/corners.vnl for mrcal.
static bool corners_from_file(const calib_geometry_opts_t *o, calib_geometry_state_t *s, char **text)
{
    if (!model_provenance_input(s->prov, "corners", o->corners)) return false;
    GError *err = NULL;
    if (!g_file_get_contents(o->corners, text, NULL, &err)) {
        model_error_set(o->corners, 0, "cannot read: %s", err->message);
        g_error_free(err);
        return false;
    }
    if (!calib_geometry_parse_corners(&s->views, *text, o->corners, &o->board, true)) return false;
    for (guint k = 0; k < s->views.v->len; k++) {
        calib_geometry_view_t *v = g_ptr_array_index(s->views.v, k);
        if (!v->found)
            snprintf(v->why, sizeof v->why, "no %dx%d board in the corners file", o->board.width_n,
                     o->board.height_n);
    }
    return true;
}

static bool corners_mrgingham(const calib_geometry_opts_t *o, calib_geometry_state_t *s, char **text)
{
    calib_geometry_views_t *vs = &s->views;
    fprintf(stderr, "refl calib geometry: finding the %dx%d corners of %u images (mrgingham)\n", o->board.width_n,
            o->board.height_n, vs->v->len);
    GPtrArray *args = g_ptr_array_new();
    char gn[16];
    snprintf(gn, sizeof gn, "%d", o->board.width_n);
    g_ptr_array_add(args, "mrgingham");
    g_ptr_array_add(args, "--gridn");
    g_ptr_array_add(args, gn);
    g_ptr_array_add(args, "--jobs");
    g_ptr_array_add(args, "2");
    for (guint k = 0; k < vs->v->len; k++)
        g_ptr_array_add(args, ((calib_geometry_view_t *)g_ptr_array_index(vs->v, k))->name);
    g_ptr_array_add(args, NULL);
    char *log = g_strdup_printf("%s/mrgingham.log", s->mdir);
    int e = run_tool(s->imgdir, (char **)args->pdata, log, text);
    g_ptr_array_free(args, TRUE);
    g_free(log);
    if (e != 0) {
        if (e > 0)    // else it did not run: run_tool's message says why
            model_error_set(s->imgdir, 0, "mrgingham failed (exit status %d) on the images here; see %s/mrgingham.log",
                            e, s->mdir);
        return false;
    }
    if (!calib_geometry_parse_corners(vs, *text, s->cornpath, &o->board, false)) return false;
    for (guint k = 0; k < vs->v->len; k++) {
        calib_geometry_view_t *v = g_ptr_array_index(vs->v, k);
        if (!v->found)
            snprintf(v->why, sizeof v->why, "mrgingham found no %dx%d board", o->board.width_n, o->board.height_n);
    }
    return true;
}

// One view's image (DIR/images/NAME, 8 bits) through the OpenCV detector:
// its lines of corners text into t (one "NAME - -" for no board, and then
// v->why). false + message.
static bool detect_view(const calib_geometry_opts_t *o, calib_geometry_state_t *s, calib_geometry_view_t *v,
                        double *q, GString *t)
{
    int w = 0, h = 0, N = o->board.width_n * o->board.height_n;
    char *path = g_strdup_printf("%s/%s", s->imgdir, v->name);
    float *img = model_image_read_float(path, &w, &h);
    unsigned char *u8 = img ? malloc((size_t)w * h) : NULL;
    g_free(path);
    if (!u8) {
        free(img);
        return false;
    }
    for (size_t k = 0; k < (size_t)w * h; k++) u8[k] = img[k] <= 0 ? 0 : img[k] >= 255 ? 255 : (unsigned char)img[k];
    free(img);
    char why[256] = "";
    int n = calib_board_detect(&o->board, u8, w, h, q, why, sizeof why);
    free(u8);
    if (n < 0) return false;
    if (n == 0) {
        g_string_append_printf(t, "%s - -\n", v->name);
        snprintf(v->why, sizeof v->why, "%s", why);
        return true;
    }
    for (int k = 0; k < N; k++)
        if (isfinite(q[2 * k])) g_string_append_printf(t, "%s %.4f %.4f 0\n", v->name, q[2 * k], q[2 * k + 1]);
        else g_string_append_printf(t, "%s - -\n", v->name);
    return true;
}

static bool corners_opencv(const calib_geometry_opts_t *o, calib_geometry_state_t *s, char **text)
{
    calib_geometry_views_t *vs = &s->views;
    if (!calib_board_check(&o->board)) return false;
    fprintf(stderr, "refl calib geometry: finding the %dx%d corners of the %s in %u images (OpenCV)\n",
            o->board.width_n, o->board.height_n, calib_board_kind_name(o->board.kind), vs->v->len);
    GString *t = g_string_new("# filename x y level\n");
    double *q = malloc((size_t)2 * o->board.width_n * o->board.height_n * sizeof *q);
    bool ok = q != NULL;
    for (guint k = 0; ok && k < vs->v->len; k++) ok = detect_view(o, s, g_ptr_array_index(vs->v, k), q, t);
    free(q);
    *text = g_string_free(t, FALSE);
    return ok && calib_geometry_parse_corners(vs, *text, s->cornpath, &o->board, false);
}

// A view's corners all on one row or one column of the board: no pose.
static bool corners_on_a_line(const calib_geometry_view_t *v, const calib_board_t *b)
{
    int i0 = -1, j0 = -1;
    bool row = true, col = true;
    for (int k = 0; k < b->width_n * b->height_n; k++) {
        if (!isfinite(v->q[2 * k])) continue;
        int i = k % b->width_n, j = k / b->width_n;
        if (i0 < 0) i0 = i, j0 = j;
        row = row && j == j0;
        col = col && i == i0;
    }
    return row || col;
}

// The corners text for mrcal: text's lines, but a view not found as one line
// "NAME - -" (written to path). false + message.
static bool corners_write(const calib_geometry_views_t *vs, const char *text, const char *path)
{
    GString *out = g_string_new("");
    GHashTable *done = g_hash_table_new(g_direct_hash, g_direct_equal);
    char **lines = g_strsplit(text, "\n", -1);
    for (int i = 0; lines[i]; i++) {
        char name[1024];
        const char *l = lines[i];
        if (*l == '#' || sscanf(l, "%1023s", name) != 1) {
            if (*l) g_string_append_printf(out, "%s\n", l);
            continue;
        }
        calib_geometry_view_t *v = calib_geometry_view_find((calib_geometry_views_t *)vs, name);
        if (v && !v->found) {
            if (!g_hash_table_contains(done, v)) g_string_append_printf(out, "%s - -\n", name);
            g_hash_table_add(done, v);
            continue;
        }
        g_string_append_printf(out, "%s\n", l);
    }
    g_strfreev(lines);
    g_hash_table_destroy(done);
    GError *err = NULL;
    bool ok = g_file_set_contents(path, out->str, (gssize)out->len, &err);
    if (!ok) {
        model_error_set(path, 0, "cannot write: %s", err->message);
        g_error_free(err);
    }
    g_string_free(out, TRUE);
    return ok;
}

// The views of too few corners (or all on one line) left out, with the reason.
static void corners_enough(const calib_geometry_opts_t *o, calib_geometry_state_t *s)
{
    int N = o->board.width_n * o->board.height_n;
    int minc = o->min_corners > 0 ? o->min_corners : CALIB_GEOMETRY_MIN_CORNERS;
    minc = minc > N ? N : minc < 4 ? 4 : minc;
    for (guint k = 0; k < s->views.v->len; k++) {
        calib_geometry_view_t *v = g_ptr_array_index(s->views.v, k);
        if (!v->found) continue;
        if (v->ncorners < minc)
            snprintf(v->why, sizeof v->why, "only %d of the board's %d corners found, fewer than %d (--min-corners)",
                     v->ncorners, N, minc);
        else if (corners_on_a_line(v, &o->board))
            snprintf(v->why, sizeof v->why, "its %d corners all lie on one row or column of the board (no pose from "
                     "them)", v->ncorners);
        else
            continue;
        v->found = false;
    }
}

bool calib_geometry_find_corners(const calib_geometry_opts_t *o, calib_geometry_state_t *s)
{
    calib_geometry_views_t *vs = &s->views;
    g_free(s->cornpath);
    s->cornpath = g_strdup_printf("%s/corners.vnl", s->outdir);
    if (!o->corners && vs->v->len == 0) {
        model_error_set(o->out, 0, "no frames or images to calibrate from");
        return false;
    }
    char *text = NULL;
    bool ok = o->corners ? corners_from_file(o, s, &text)
            : calib_geometry_detector(o->detector, &o->board) == CALIB_DETECTOR_MRGINGHAM ? corners_mrgingham(o, s, &text)
                                                                                          : corners_opencv(o, s, &text);
    if (ok) corners_enough(o, s);
    ok = ok && corners_write(vs, text, s->cornpath);
    g_free(text);
    if (!ok) return false;
    s->nfound = 0;
    int partial = 0;
    for (guint k = 0; k < vs->v->len; k++) {
        calib_geometry_view_t *v = g_ptr_array_index(vs->v, k);
        s->nfound += v->found;
        partial += v->found && v->ncorners < o->board.width_n * o->board.height_n;
    }
    fprintf(stderr, "refl calib geometry: the board was found in %d of %u images", s->nfound, vs->v->len);
    if (partial) fprintf(stderr, " (%d of them in part)", partial);
    fprintf(stderr, "\n");
    const char *lens0 = calib_geometry_is_auto(o->lensmodel) ? CALIB_GEOMETRY_LEAN_LENSMODEL : o->lensmodel;
    int min_views = o->min_views ? o->min_views : calib_geometry_default_min_views(lens0);
    if (s->nfound < min_views) {
        model_error_set(o->corners ? o->corners : o->out, 0, "too few views for %s: the board was found in %d of %u "
                        "images, the solve needs at least %d (%d more views; tilt the board and turn the table so the "
                        "corners cover the imager)", lens0, s->nfound, vs->v->len, min_views,
                        min_views - s->nfound);
        for (guint k = 0; k < vs->v->len; k++) {
            calib_geometry_view_t *v = g_ptr_array_index(vs->v, k);
            if (!v->found) fprintf(stderr, "  %s (%s): %s\n", v->name, v->source, v->why);
        }
        return false;
    }
    for (int c = 0; c < s->ncams && s->ncams > 1; c++) {
        int nf = 0, nv = 0;
        for (guint k = 0; k < vs->v->len; k++) {
            calib_geometry_view_t *v = g_ptr_array_index(vs->v, k);
            nv += v->camera == c;
            nf += v->camera == c && v->found;
        }
        fprintf(stderr, "refl calib geometry: camera %s: the board in %d of %d images\n", s->camnames[c], nf, nv);
        if (nf < min_views) {
            model_error_set(o->out, 0, "too few views for %s of camera %s: the board was found in %d of its %d images, "
                            "the solve needs at least %d (tilt the board towards it, or give --tilts with poses "
                            "it sees)", lens0, s->camnames[c], nf, nv, min_views);
            return false;
        }
    }
    return true;
}

// Several cameras: mrgingham's corner order made to agree across the cameras
// of each frame (scripts/calib_geometry_report.py align) into
// DIR/corners-joint.vnl; views left out get their reason. false + message.
static bool align_corners(const calib_geometry_opts_t *o, calib_geometry_state_t *s, char **joint)
{
    char gn[32], sp[32], *spec[RIG_CAMERAS_MAX] = { 0 };
    snprintf(gn, sizeof gn, "%dx%d", o->board.width_n, o->board.height_n);
    snprintf(sp, sizeof sp, "%.9g", o->board.spacing_mm);
    for (int k = 0; k < RIG_CAMERAS_MAX; k++)
        if (k < s->ncams)
            spec[k] = g_strdup_printf("%s:%d:%d:%.6g", s->camnames[k], s->camw[k], s->camh[k],
                                      isfinite(o->focal_px) ? o->focal_px : 1.4 * s->camw[k]);
    *joint = g_strdup_printf("%s/corners-joint.vnl", s->outdir);
    char *ajson = g_strdup_printf("%s/align.json", s->mdir);
    fprintf(stderr, "refl calib geometry: making the corner order agree across the cameras\n");
    int e = model_run_script("calib_geometry_report.py", "align", s->cornpath, *joint, ajson, gn, sp, spec[0],
                             spec[1], spec[2], spec[3], spec[4], spec[5], spec[6], spec[7], NULL);
    for (int k = 0; k < RIG_CAMERAS_MAX; k++) g_free(spec[k]);
    json_error_t je;
    json_t *a = e == 0 ? json_load_file(ajson, 0, &je) : NULL;
    bool ok = a != NULL;
    if (e == 0 && !a) model_error_set(ajson, je.line, "cannot read: %s", je.text);
    else if (e != 0) model_error_set(s->cornpath, 0, "aligning the cameras' corner order failed (exit status %d)", e);
    if (ok && json_object_get(a, "error")) {
        model_error_set(s->cornpath, 0, "%s", json_string_value(json_object_get(a, "error")));
        ok = false;
    }
    const char *name;
    json_t *vj;
    json_object_foreach(ok ? json_object_get(a, "views") : NULL, name, vj) {
        calib_geometry_view_t *v = calib_geometry_view_find(&s->views, name);
        if (!v) continue;
        v->quarter_turns = (int)json_integer_value(json_object_get(vj, "quarter_turns"));
        if (json_is_true(json_object_get(vj, "dropped")))
            snprintf(v->why, sizeof v->why, "left out of the joint solve: no quarter turn of its corners agrees "
                     "with the other cameras' view of this board pose (%.1f deg off)",
                     json_real_value(json_object_get(vj, "mismatch_deg")));
    }
    json_decref(a);
    g_free(ajson);
    return ok;
}

bool calib_geometry_mrcal(const calib_geometry_opts_t *o, calib_geometry_state_t *s, const char *lensmodel,
                          const char *corners, const char *mdir, int nviews, json_t **sol)
{
    char focal[160], spacing[32], wn[16], hn[16], ws[16], hs[16];
    *sol = NULL;
    snprintf(focal, sizeof focal, "%.6g", isfinite(o->focal_px) ? o->focal_px : 1.4 * s->W);
    snprintf(spacing, sizeof spacing, "%.9g", o->board.spacing_mm);
    snprintf(wn, sizeof wn, "%d", o->board.width_n);
    snprintf(hn, sizeof hn, "%d", o->board.height_n);
    snprintf(ws, sizeof ws, "%d", s->W);
    snprintf(hs, sizeof hs, "%d", s->H);
    if (!model_mkdir_p(mdir)) return false;
    char *cwd = o->corners ? g_path_get_dirname(s->cornpath) : g_strdup(s->imgdir);
    char *argv_m[] = { "mrcal-calibrate-cameras", "--corners-cache", (char *)corners, "--lensmodel",
                       (char *)lensmodel, "--focal", focal, "--object-spacing", spacing, "--object-width-n", wn,
                       "--object-height-n", hn, "--imagersize", ws, hs, "--outdir", (char *)mdir, "*", NULL, NULL,
                       NULL, NULL, NULL, NULL, NULL, NULL };
    if (s->ncams > 1) {    // one glob and seed focal length per camera, each its own imager size
        GString *fl = g_string_new("");
        for (int k = 0; k < s->ncams; k++)
            g_string_append_printf(fl, "%s%.6g", k ? "," : "", isfinite(o->focal_px) ? o->focal_px : 1.4 * s->camw[k]);
        snprintf(focal, sizeof focal, "%s", fl->str);
        g_string_free(fl, TRUE);
        argv_m[13] = "--outdir";   // no --imagersize: each camera's own, from its images
        argv_m[14] = (char *)mdir;
        for (int k = 0; k < s->ncams; k++) argv_m[15 + k] = g_strdup_printf("%s/*.png", s->camnames[k]);
        argv_m[15 + s->ncams] = NULL;
    }
    if (s->no_outlier_rejection)   // after the globs: argparse takes options anywhere
        argv_m[s->ncams > 1 ? 15 + s->ncams : 19] = "--skip-outlier-rejection";
    // mrcal-calibrate-cameras runs under Debian's Python (its shebang)
    fprintf(stderr, "refl calib geometry: solving %s from %d views (mrcal-calibrate-cameras)\n", lensmodel, nviews);
    char *log = g_strdup_printf("%s/mrcal-calibrate-cameras.log", mdir);
    char *model0 = g_strdup_printf("%s/camera-0.cameramodel", mdir);
    unlink(model0);
    int e = run_tool(cwd, argv_m, log, NULL);
    g_free(cwd);
    if (s->ncams > 1)
        for (int k = 0; k < s->ncams; k++) g_free(argv_m[15 + k]);
    if (e != 0 || access(model0, R_OK) != 0) {
        if (e >= 0)
            model_error_set(mdir, 0, "mrcal-calibrate-cameras failed (exit status %d) on %s with %s; see %s (a bad "
                            "seed? give --focal-px)", e, corners, lensmodel, log);
        g_free(log);
        g_free(model0);
        return false;
    }
    g_free(log);
    char *solpath = g_strdup_printf("%s/solution.json", mdir), dist[32];
    snprintf(dist, sizeof dist, "%g", o->distance_mm);
    fprintf(stderr, "refl calib geometry: residuals and projection uncertainty (mrcal)\n");
    e = model_run_script("calib_geometry_report.py", "solution", model0, solpath, dist, NULL);
    g_free(model0);
    if (e == 0) {
        json_error_t je;
        *sol = json_load_file(solpath, 0, &je);
        if (!*sol) model_error_set(solpath, je.line, "cannot read: %s", je.text);
    } else {
        model_error_set(solpath, 0, "scripts/calib_geometry_report.py solution failed (exit status %d)", e);
    }
    g_free(solpath);
    return *sol != NULL;
}

// A solve that failed with partial views in it (a ChArUco board seen in part,
// whose corners mrcal's outlier rejection can thin until a view's pose or a
// lens parameter is no longer held: "not positive definite", "factorization
// computation failed") is tried again: first with every corner (mrcal's
// --skip-outlier-rejection; the outliers' residuals then weigh in, and the
// command says so), then without the partial views (their lines
// left out of a copy of the corners file, each such view told why). false +
// the first failure's message when there are none or every solve fails.
static bool solve_again(const calib_geometry_opts_t *o, calib_geometry_state_t *s)
{
    char *first = g_strdup(model_last_error());
    int N0 = o->board.width_n * o->board.height_n, np0 = 0;
    for (guint i = 0; i < s->views.v->len; i++) {
        calib_geometry_view_t *v = g_ptr_array_index(s->views.v, i);
        np0 += v->found && !v->why[0] && v->ncorners < N0;
    }
    if (np0 > 0) {
        fprintf(stderr, "refl calib geometry: the solve failed (%s); solving again with every corner (mrcal's "
                "outlier rejection off)\n", first);
        s->no_outlier_rejection = true;
        json_decref(s->sol);
        s->sol = NULL;
        if (calib_geometry_mrcal(o, s, s->lensmodel, s->solvecorners, s->mdir, s->nfound, &s->sol)) {
            g_free(first);
            return true;
        }
        s->no_outlier_rejection = false;
    }
    int N = o->board.width_n * o->board.height_n, npart = 0;
    GHashTable *drop = g_hash_table_new(g_str_hash, g_str_equal);
    for (guint i = 0; i < s->views.v->len; i++) {
        calib_geometry_view_t *v = g_ptr_array_index(s->views.v, i);
        if (v->found && !v->why[0] && v->ncorners < N) g_hash_table_add(drop, v->name), npart++;
    }
    bool ok = false;
    char *txt = NULL, *path = NULL;
    if (npart > 0 && s->nfound - npart >= 3 && g_file_get_contents(s->solvecorners, &txt, NULL, NULL)) {
        GString *out = g_string_new("");
        char **lines = g_strsplit(txt, "\n", -1);
        for (int k = 0; lines[k]; k++) {
            if (!lines[k][0]) continue;
            char name[512] = "";
            if (lines[k][0] != '#' && sscanf(lines[k], "%511s", name) == 1 && g_hash_table_contains(drop, name))
                continue;
            g_string_append_printf(out, "%s\n", lines[k]);
        }
        g_strfreev(lines);
        path = g_strdup_printf("%s/corners-whole-views.vnl", s->outdir);
        fprintf(stderr, "refl calib geometry: the solve failed (%s); solving again without the %d partial views\n",
                first, npart);
        ok = g_file_set_contents(path, out->str, (gssize)out->len, NULL);
        g_string_free(out, TRUE);
        json_decref(s->sol);
        s->sol = NULL;
        ok = ok && calib_geometry_mrcal(o, s, s->lensmodel, path, s->mdir, s->nfound - npart, &s->sol);
        if (ok) {
            for (guint i = 0; i < s->views.v->len; i++) {
                calib_geometry_view_t *v = g_ptr_array_index(s->views.v, i);
                if (g_hash_table_contains(drop, v->name))
                    snprintf(v->why, sizeof v->why, "left out of the solve: a partial view (%d of %d corners), and "
                             "the solve with the partial views failed", v->ncorners, N);
            }
            g_free(s->solvecorners);
            s->solvecorners = path;
            path = NULL;
        }
    }
    if (!ok) model_error_set(NULL, 0, "%s", first);
    g_free(txt);
    g_free(path);
    g_free(first);
    g_hash_table_destroy(drop);
    return ok;
}

bool calib_geometry_solve(const calib_geometry_opts_t *o, calib_geometry_state_t *s)
{
    g_free(s->solvecorners);
    s->solvecorners = NULL;
    if (s->ncams > 1 && o->board.kind != CALIB_BOARD_CHARUCO) {   // the corner order made to agree across the
        if (!align_corners(o, s, &s->solvecorners)) return false;    // cameras first (ChArUco's corners have ids)
    } else {
        s->solvecorners = g_strdup(s->cornpath);
    }
    if (!s->lensmodel) s->lensmodel = g_strdup(calib_geometry_is_auto(o->lensmodel) ? CALIB_GEOMETRY_LEAN_LENSMODEL
                                                                                  : o->lensmodel);
    g_free(s->soldir);
    s->soldir = g_strdup(s->mdir);
    json_decref(s->sol);
    s->sol = NULL;
    if (calib_geometry_mrcal(o, s, s->lensmodel, s->solvecorners, s->mdir, s->nfound, &s->sol)) return true;
    return solve_again(o, s);
}

bool calib_geometry_apply_solution(const calib_geometry_opts_t *o, calib_geometry_state_t *s)
{
    json_t *jimgs = json_object_get(s->sol, "images"), *intr = json_object_get(s->sol, "intrinsics");
    size_t k;
    json_t *im;
    json_array_foreach(jimgs, k, im) {
        const char *path = json_string_value(json_object_get(im, "path"));
        calib_geometry_view_t *v = s->ncams > 1 ? NULL : calib_geometry_view_find(&s->views, path);
        for (guint i = 0; i < s->views.v->len && s->ncams > 1 && path; i++) {   // names differ by directory only
            calib_geometry_view_t *w = g_ptr_array_index(s->views.v, i);
            size_t ln = strlen(path), lw = strlen(w->name);
            if (ln >= lw && !strcmp(path + ln - lw, w->name) && (ln == lw || path[ln - lw - 1] == '/')) v = w;
        }
        if (!v) continue;
        json_t *rt = json_object_get(im, "rt_cam_board");
        for (int c = 0; c < 6; c++) v->rt_cam_board[c] = json_real_value(json_array_get(rt, c));
        v->solved = true;
        json_t *rms = json_object_get(im, "rms_px");
        v->rms_px = json_is_number(rms) ? json_number_value(rms) : NAN;
        v->outliers = (int)json_integer_value(json_object_get(im, "outliers"));
    }
    double *ip = malloc((json_array_size(intr) + 1) * sizeof *ip);
    for (k = 0; k < json_array_size(intr); k++) ip[k] = json_real_value(json_array_get(intr, k));
    double zero[6] = { 0 };
    model_camera_free(s->cam);
    s->cam = model_camera_new(s->lensmodel, ip, s->W, s->H, zero);
    free(ip);
    if (!s->cam) return false;
    s->rms_px = json_real_value(json_object_get(s->sol, "rms_px"));
    fprintf(stderr, "refl calib geometry: RMS reprojection residual %.4f px, %d outliers\n", s->rms_px,
            (int)json_integer_value(json_object_get(s->sol, "outliers")));
    return true;
}

const char *calib_geometry_tilts_expand(const char *tilts)
{
    return tilts && !strcmp(tilts, "2cam-example") ? CALIB_GEOMETRY_TILTS_2CAM_EXAMPLE : tilts;
}

bool calib_geometry_capture(const calib_geometry_opts_t *o, calib_geometry_state_t *s, bool *usage)
{
    // every plan first: a bad --tilts fails before anything moves
    const char *tilts = calib_geometry_tilts_expand(o->tilts);
    char **specs = g_strsplit(tilts, " ", -1);
    GPtrArray *plans = g_ptr_array_new_with_free_func(g_free), *names = g_ptr_array_new_with_free_func(g_free);
    bool ok = true;
    for (int k = 0; specs[k] && ok; k++) {
        if (!*specs[k]) continue;
        char name[128];
        char *plan = calib_geometry_tilt_plan(specs[k], o, name, sizeof name);
        if (!plan) ok = false;
        else {
            g_ptr_array_add(plans, plan);
            g_ptr_array_add(names, g_strdup(name));
        }
    }
    g_strfreev(specs);
    if (ok && plans->len == 0) {
        model_error_set("--tilts", 0, "'%s': no tilts", tilts);
        ok = false;
    }
    *usage = !ok;
    char *capdir = g_strdup_printf("%s/capture", s->outdir);
    g_strfreev(s->sessions);
    s->sessions = g_new0(char *, plans->len + 1);
    for (guint k = 0; k < plans->len && ok; k++) {
        const char *name = g_ptr_array_index(names, k);
        fprintf(stderr, "refl calib geometry: capturing %s (%u of %u)\n", name, k + 1, plans->len);
        ok = calib_capture(o->rig, capdir, name, g_ptr_array_index(plans, k), o->progress, o->op) == 0;
        if (ok) s->sessions[k] = g_strdup_printf("%s/%s", capdir, name);
    }
    g_ptr_array_free(plans, TRUE);
    g_ptr_array_free(names, TRUE);
    g_free(capdir);
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
    if (p) {
        vs->ngroups++;
        vs->group_tilt = realloc(vs->group_tilt, vs->ngroups * sizeof(double));
        vs->group_az = realloc(vs->group_az, vs->ngroups * sizeof(double));
        vs->group_tilt[g] = p->tilt_deg;
        vs->group_az[g] = p->tilt_azimuth_deg;
    }
    rig_plan_free(p);
    rig_session_free(rs);
    return p != NULL;
}

// Stage 1: the views of the sessions (given or captured) or the images.
static bool collect_views(const calib_geometry_opts_t *o, calib_geometry_state_t *s)
{
    s->W = o->imager_w;
    s->H = o->imager_h;
    int n = s->sessions ? (int)g_strv_length(s->sessions) : o->nsessions;
    if (!session_cameras(o, s, n ? (s->sessions ? s->sessions[0] : o->sessions[0]) : NULL)) return false;
    for (int k = 0; k < n; k++) {
        const char *sd = s->sessions ? s->sessions[k] : o->sessions[k];
        fprintf(stderr, "refl calib geometry: reading the frames of %s\n", sd);
        if (!(s->ncams > 1 ? add_session_cameras(s, sd)
                           : calib_geometry_add_session(&s->views, sd, o->camera, s->imgdir, &s->W, &s->H)) ||
            !model_provenance_input(s->prov, "session", sd))
            return false;
    }
    if (s->ncams > 1) {
        s->W = s->camw[0];
        s->H = s->camh[0];
        fprintf(stderr, "refl calib geometry: %d cameras (", s->ncams);
        for (int k = 0; k < s->ncams; k++) fprintf(stderr, "%s%s %dx%d", k ? ", " : "", s->camnames[k], s->camw[k],
                                                   s->camh[k]);
        fprintf(stderr, "), calibrated together; the rig frame from %s's views\n", s->camnames[0]);
    }
    if (o->images) {
        // said after reading: a failure's message names the path, once
        if (!calib_geometry_add_images(&s->views, o->images, s->imgdir, &s->W, &s->H)) return false;
        fprintf(stderr, "refl calib geometry: %u images from %s\n", s->views.v->len, o->images);
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

// The camera frame itself is as uncertain as the principal point: a shift of
// (dcx, dcy) px turns every direction in it by about (dcy / fy, dcx / fx) rad.
// The axis direction's sigma (in the camera frame) gets that in quadrature
// (mrcal's 1-sigma of cx, cy from the solve; the fit's own kept apart).
static void axis_intrinsics_sigma(calib_geometry_state_t *s)
{
    calib_geometry_axis_t *ax = &s->axis;
    json_t *sd = json_object_get(s->sol, "intrinsics_core_stdev"), *in = json_object_get(s->sol, "intrinsics");
    ax->dir_unc_fit_deg = ax->dir_unc_deg;
    ax->dir_unc_intrinsics_deg = NAN;
    if (json_array_size(sd) != 4 || json_array_size(in) < 4) return;
    double ex = json_number_value(json_array_get(sd, 2)) / json_number_value(json_array_get(in, 0));
    double ey = json_number_value(json_array_get(sd, 3)) / json_number_value(json_array_get(in, 1));
    if (!isfinite(ex) || !isfinite(ey)) return;
    ax->dir_unc_intrinsics_deg = hypot(ex, ey) / DEG;
    ax->dir_unc_deg = hypot(ax->dir_unc_fit_deg, ax->dir_unc_intrinsics_deg);
}

// Stage 4: the axis, the rig frame and why views have no board.
static void axis_and_rig_frame(const calib_geometry_opts_t *o, calib_geometry_state_t *s)
{
    calib_geometry_axis_t *ax = &s->axis;
    snprintf(s->rigwhy, sizeof s->rigwhy, "no turntable angles in the input (--images / --corners)");
    if (s->views.ngroups > 0) {
        fprintf(stderr, "refl calib geometry: fitting the turntable axis\n");
        if (!calib_geometry_fit_axis(&s->views, &o->board, ax)) {
            snprintf(s->rigwhy, sizeof s->rigwhy, "too few board poses at different angles of one tilt for the "
                     "axis (need 2 views 5..175 deg apart)");
            fprintf(stderr, "refl calib geometry: no axis: %s\n", s->rigwhy);
        } else {
            fprintf(stderr, "refl calib geometry: the axis fitted with the board poses as turns about it (from the "
                    "closed form: direction +- %.4f deg)\n", ax->dir_unc_deg);
            if (!calib_geometry_refine_axis(&s->views, &o->board, s->cam, s->rms_px / sqrt(2), ax))
                fprintf(stderr, "refl calib geometry: the joint axis fit failed (%s); the closed-form axis is kept\n",
                        model_last_error());
            else
                fprintf(stderr, "refl calib geometry: joint axis fit: %d views, corner RMS %.4f px (chi^2/dof %.2f)\n",
                        ax->joint_views, ax->joint_rms_px, ax->joint_chi2);
            axis_intrinsics_sigma(s);
            s->have_rig = calib_geometry_rig_frame(&s->views, o->board_height_mm, ax, s->rt_cam_rig, s->rigwhy,
                                                   sizeof s->rigwhy);
            if (!s->have_rig)
                fprintf(stderr, "refl calib geometry: no rig frame: %s; the extrinsics are the camera's own frame\n",
                        s->rigwhy);
            fprintf(stderr, "refl calib geometry: axis direction (camera frame) %.6f %.6f %.6f +- %.4f deg, %d pairs, "
                    "off-axis rotation RMS %.4f deg\n", ax->a[0], ax->a[1], ax->a[2], ax->dir_unc_deg, ax->npairs,
                    ax->off_axis_rms_deg);
        }
    }
    calib_geometry_explain_missing(&s->views, &o->board, ax->ok ? ax : NULL, s->cam, s->W, s->H);
    for (guint k = 0; k < s->views.v->len; k++) {
        calib_geometry_view_t *v = g_ptr_array_index(s->views.v, k);
        bool same = !strcmp(v->name, v->source);   // the source named once
        if (!v->found)
            fprintf(stderr, "refl calib geometry: no board in %s%s%s%s: %s\n", v->name, same ? "" : " (",
                    same ? "" : v->source, same ? "" : ")", v->why);
    }
}

// The rig frame's 1-sigma from the axis fit: z (the axis direction), x (the
// tilt-0 board's turn about the axis), the origin across and along the axis,
// and what they make of the camera centre's position in the rig frame
// (sqrt(origin^2 + (distance x rotation)^2), rotation the two angles combined).
static json_t *rig_sigma_json(const calib_geometry_state_t *s)
{
    const calib_geometry_axis_t *ax = &s->axis;
    double inv[6], xs = ax->joint ? ax->rig_x_unc_deg : NAN, os = ax->joint ? ax->rig_origin_along_mm : NAN;
    invert(inv, s->rt_cam_rig);
    double d = norm3(&inv[3]), rot = hypot(ax->dir_unc_deg, isfinite(xs) ? xs : 0) * DEG;
    double o2 = ax->point_unc_mm * ax->point_unc_mm + (isfinite(os) ? os * os : 0);
    json_t *j = json_object();
    json_object_set_new(j, "z_direction_deg", json_real(ax->dir_unc_deg));
    json_object_set_new(j, "x_direction_deg", isfinite(xs) ? json_real(xs) : json_null());
    json_object_set_new(j, "origin_across_axis_mm", json_real(ax->point_unc_mm));
    json_object_set_new(j, "origin_along_axis_mm", isfinite(os) ? json_real(os) : json_null());
    json_object_set_new(j, "camera_centre_mm", json_real(sqrt(o2 + d * d * rot * rot)));
    json_object_set_new(j, "note", json_string("1-sigma of the rig frame as the axis fit determines it (the "
                        "camera's intrinsics fixed); camera_centre_mm: sqrt(origin^2 + (distance x rotation)^2)"));
    return j;
}

// geometry.json: the axis (null without one).
static json_t *axis_json(const calib_geometry_state_t *s)
{
    const calib_geometry_axis_t *ax = &s->axis;
    if (!ax->ok) return json_null();
    json_t *aj = json_object();
    json_object_set_new(aj, "direction_cam", jarr(ax->a, 3));
    json_object_set_new(aj, "point_cam_mm", jarr(ax->c, 3));
    json_object_set_new(aj, "direction_uncertainty_deg", json_real(ax->dir_unc_deg));
    json_object_set_new(aj, "point_uncertainty_mm", json_real(ax->point_unc_mm));
    if (ax->joint) {
        json_object_set_new(aj, "method", json_string("fitted jointly with the board poses: each tilt group's board "
                            "one pose turned about the axis by the turntable's measured angles, fitted with the axis "
                            "to the observed corners (camera model fixed); the images' rt_cam_board are these poses"));
        json_object_set_new(aj, "uncertainty_note", json_string("1-sigma from the joint fit's covariance (corner "
                            "noise = mrcal's RMS residual / sqrt 2), scaled by chi^2/dof when above 1; the point: "
                            "RMS distance across the axis; the direction (in the camera frame) also carries the "
                            "principal point's 1-sigma from mrcal's solve (hypot(s_cx / fx, s_cy / fy)) in "
                            "quadrature"));
        json_object_set_new(aj, "joint_views", json_integer(ax->joint_views));
        json_object_set_new(aj, "direction_uncertainty_fit_deg", json_real(ax->dir_unc_fit_deg));
        json_object_set_new(aj, "direction_uncertainty_intrinsics_deg", isfinite(ax->dir_unc_intrinsics_deg)
                            ? json_real(ax->dir_unc_intrinsics_deg) : json_null());
        json_object_set_new(aj, "joint_rms_residual_px", json_real(ax->joint_rms_px));
        json_object_set_new(aj, "joint_chi2_per_dof", json_real(ax->joint_chi2));
    } else {
        json_object_set_new(aj, "method", json_string("closed form from the pairs of board poses (the joint fit "
                            "failed or was not run)"));
        json_object_set_new(aj, "uncertainty_note", json_string("approximate 1-sigma, from the scatter of the "
                            "pairwise estimates (direction) and of the point equations (point, across the axis)"));
    }
    json_object_set_new(aj, "off_axis_rms_deg", json_real(ax->off_axis_rms_deg));
    json_object_set_new(aj, "point_equation_rms_mm", json_real(ax->point_rms_mm));
    json_object_set_new(aj, "pairs", json_integer(ax->npairs));
    json_object_set_new(aj, "views", json_integer(ax->nviews));
    if (s->have_rig) {
        // in the rig frame the axis is +z through the origin, by construction
        json_object_set_new(aj, "direction_rig", json_pack("[fff]", 0.0, 0.0, 1.0));
        json_object_set_new(aj, "point_rig_mm", json_pack("[fff]", 0.0, 0.0, 0.0));
        json_object_set_new(aj, "rig_frame_sigma", rig_sigma_json(s));
    }
    json_object_set_new(aj, "fit", json_incref(ax->fit));
    return aj;
}

// geometry.json: the board (kind, corners, spacing; the detector and the least corners a view needs).
static json_t *board_json(const calib_geometry_opts_t *o)
{
    const calib_board_t *b = &o->board;
    int N = b->width_n * b->height_n, minc = o->min_corners > 0 ? o->min_corners : CALIB_GEOMETRY_MIN_CORNERS;
    json_t *j = json_pack("{s:s,s:i,s:i,s:f,s:f,s:f,s:s}", "kind", calib_board_kind_name(b->kind), "width_n",
                          b->width_n, "height_n", b->height_n, "spacing_mm", b->spacing_mm, "square_mm", b->spacing_mm,
                          "height_at_tilt0_mm", o->board_height_mm, "sample", o->sample);
    if (b->width_n == b->height_n) json_object_set_new(j, "gridn", json_integer(b->width_n));
    if (b->kind == CALIB_BOARD_CHARUCO) {
        json_object_set_new(j, "marker_mm", json_real(b->marker_mm));
        json_object_set_new(j, "dictionary", json_string(b->dict));
    }
    json_object_set_new(j, "detector", json_string(o->corners ? "corners file"
                        : calib_geometry_detector(o->detector, b) == CALIB_DETECTOR_MRGINGHAM ? "mrgingham" : "opencv"));
    json_object_set_new(j, "min_corners", json_integer(minc > N ? N : minc < 4 ? 4 : minc));
    json_object_set_new(j, "frame", json_string("corner (i, j), i = 0..width_n-1, j = 0..height_n-1, at (i, j) "
                        "spacing_mm, z = 0 (mrcal's); corners.vnl lists corner (i, j) at j width_n + i"));
    return j;
}

// geometry.json: one view.
static json_t *view_json(const calib_geometry_state_t *s, const calib_geometry_view_t *v)
{
    json_t *im = json_object();
    json_object_set_new(im, "image", json_string(v->name));
    json_object_set_new(im, "source", json_string(v->source));
    if (s->ncams > 1) json_object_set_new(im, "camera", json_string(s->camnames[v->camera]));
    if (v->session) json_object_set_new(im, "session", json_string(v->session));
    if (isfinite(v->angle_deg)) json_object_set_new(im, "angle_deg", json_real(v->angle_deg));
    if (isfinite(v->tilt_deg)) {
        json_object_set_new(im, "tilt_deg", json_real(v->tilt_deg));
        json_object_set_new(im, "tilt_azimuth_deg", json_real(v->tilt_azimuth_deg));
    }
    json_object_set_new(im, "board_found", json_boolean(v->found));
    if (v->q) json_object_set_new(im, "corners_found", json_integer(v->ncorners));
    if (v->why[0]) json_object_set_new(im, "why", json_string(v->why));
    if (isfinite(v->rms_px)) {     // mrcal solved a pose for it
        json_object_set_new(im, "rms_residual_px", json_real(v->rms_px));
        json_object_set_new(im, "outliers", json_integer(v->outliers));
        json_object_set_new(im, "rt_cam_board", jarr(v->rt_cam_board, 6));
        json_object_set_new(im, "quarter_turns", json_integer(v->quarter_turns));
        if (s->have_rig && v->camera == 0) {
            double rt_rig_cam[6], rt_rig_board[6];
            invert(rt_rig_cam, s->rt_cam_rig);
            compose(rt_rig_board, rt_rig_cam, v->rt_cam_board);
            json_object_set_new(im, "rt_rig_board", jarr(rt_rig_board, 6));
        }
    }
    return im;
}

json_t *calib_geometry_json(const calib_geometry_opts_t *o, calib_geometry_state_t *s)
{
    json_t *sol = s->sol, *intr = json_object_get(sol, "intrinsics");
    json_t *out = json_object();
    json_object_set_new(out, "units", json_string("lengths mm, angles deg (rotation vectors r in rad), pixels px with "
                                                  "(0, 0) the centre of the top-left pixel"));
    json_object_set_new(out, "camera_model", json_string(s->campath));
    model_camera_t *final = model_camera_load(s->campath);   // check it reads back
    if (!final) {
        json_decref(out);
        return NULL;
    }
    json_object_set_new(out, "camera_model_sha256", json_string(model_camera_sha256(final)));
    model_camera_free(final);
    json_object_set_new(out, "lensmodel", json_string(s->lensmodel));
    json_object_set_new(out, "intrinsics", json_incref(intr));
    json_object_set_new(out, "intrinsics_meaning", json_string("fx_px, fy_px, cx_px, cy_px, then the lens model's "
                                                               "distortion parameters (mrcal order)"));
    json_object_set_new(out, "imagersize_px", json_pack("[ii]", s->W, s->H));
    json_object_set_new(out, "rms_residual_px", json_real(s->rms_px));
    json_object_set_new(out, "views_used", json_integer(json_array_size(json_object_get(sol, "images"))));
    json_object_set_new(out, "views_total", json_integer(s->views.v->len));
    json_object_set_new(out, "points_used", json_incref(json_object_get(sol, "points")));
    json_object_set_new(out, "outliers", json_incref(json_object_get(sol, "outliers")));
    json_object_set_new(out, "projection_uncertainty", json_deep_copy(json_object_get(sol, "uncertainty")));
    json_object_set_new(out, "cross_validation", s->xv ? json_incref(s->xv) : json_null());
    json_object_set_new(out, "board", board_json(o));
    json_object_set_new(out, "rig_frame", json_string(s->have_rig
        ? "origin on the fitted turntable axis at the table top (board_height_mm below the board's corner plane at "
          "tilt 0); z up along the axis (counter-clockwise turntable angles positive seen from +z); x the board's "
          "grid direction at angle 0, tilt 0 closest to the image's +x, projected onto the table plane"
        : s->rigwhy));
    json_object_set_new(out, "rt_cam_rig", s->have_rig ? jarr(s->rt_cam_rig, 6) : json_null());
    if (s->have_rig) {
        double rt_rig_cam[6];
        invert(rt_rig_cam, s->rt_cam_rig);
        json_object_set_new(out, "camera_centre_rig_mm", jarr(&rt_rig_cam[3], 3));
    }
    json_object_set_new(out, "axis", axis_json(s));
    json_t *ims = json_array(), *missing = json_array();
    for (guint k = 0; k < s->views.v->len; k++) {
        calib_geometry_view_t *v = g_ptr_array_index(s->views.v, k);
        json_array_append_new(ims, view_json(s, v));
        if (!v->found)
            json_array_append_new(missing, json_pack("{s:s,s:s,s:s}", "image", v->name, "source", v->source, "why",
                                                     v->why));
    }
    json_object_set_new(out, "images", ims);
    json_object_set_new(out, "images_without_board", missing);
    model_provenance_input(s->prov, "mrcal solution", s->campath);
    json_object_set_new(out, "provenance", json_incref(s->prov));
    return out;
}

// The report's cross-validation section: each run's figures, the lens choice.
static void report_crossvalidation(FILE *f, const calib_geometry_state_t *s)
{
    json_t *x = s->xv;
    if (!x) return;
    model_html_heading(f, "Cross-validation and the lens model");
    model_html_para(f, "Method: %s. Criterion: %s.", json_string_value(json_object_get(x, "method")),
                    json_string_value(json_object_get(x, "criterion")));
    GPtrArray *rows = g_ptr_array_new_with_free_func(g_free);
    json_t *runs = json_object_get(x, "runs"), *r;
    size_t i;
    json_t *all = json_array();
    json_array_foreach(runs, i, r) json_array_append(all, r);
    if (json_object_get(x, "lean_vs_splined")) json_array_append(all, json_object_get(x, "lean_vs_splined"));
    json_array_foreach(all, i, r) {
        const char *what = json_object_get(r, "lensmodel") ? json_string_value(json_object_get(r, "lensmodel"))
                                                           : "lean against the splined fit of the same views";
        if (!json_is_true(json_object_get(r, "done")) && json_object_get(r, "lensmodel")) {
            g_ptr_array_add(rows, g_strdup_printf("%s|not done: %s||||", what,
                                                  json_string_value(json_object_get(r, "why"))));
            continue;
        }
        json_t *c;
        size_t k;
        json_array_foreach(json_object_get(r, "cameras"), k, c) {
            json_t *o = json_object_get(c, "observed");
            g_ptr_array_add(rows, g_strdup_printf("%s%s%s|%.4f / %.4f|%.4f / %.4f|%.2f|%s", what,
                            json_object_get(c, "camera") ? ", camera " : "",
                            json_object_get(c, "camera") ? json_string_value(json_object_get(c, "camera")) : "",
                            json_number_value(json_object_get(o, "diff_rms_px")),
                            json_number_value(json_object_get(o, "diff_worst_px")),
                            json_number_value(json_object_get(o, "predicted_rms_px")),
                            json_number_value(json_object_get(o, "predicted_worst_px")),
                            json_number_value(json_object_get(o, "ratio_rms")),
                            json_number_value(json_object_get(o, "ratio_rms")) <= CALIB_GEOMETRY_XV_MAX_RATIO
                                ? "passes" : "FAILS"));
        }
    }
    json_decref(all);
    model_html_table(f, "comparison|difference RMS / worst (px)|predicted s0 + s1 RMS / worst (px)|ratio|verdict",
                     (const char *const *)rows->pdata, (int)rows->len);
    char *png = g_strdup_printf("%s/crossvalidation.png", s->outdir);
    if (access(png, R_OK) == 0)
        model_html_figure(f, "crossvalidation.png", "the two halves' calibrations against each other (first camera): "
                          "|difference| / (s0 + s1) over the imager (top) and the projection difference in px "
                          "(bottom)");
    g_free(png);
    g_ptr_array_free(rows, TRUE);
    model_html_para(f, "Lens model: %s.",
                    json_string_value(json_object_get(json_object_get(x, "lens_choice"), "why")));
}

// A figure of the plots script when it wrote it (older scripts or a missing mrcal leave some out).
static void report_figure_if(FILE *f, const char *outdir, const char *png, const char *caption)
{
    char *p = g_strdup_printf("%s/%s", outdir, png);
    if (access(p, R_OK) == 0) model_html_figure(f, png, caption);
    g_free(p);
}

bool calib_geometry_report(const calib_geometry_opts_t *o, const calib_geometry_state_t *s, const char *jpath)
{
    const calib_geometry_axis_t *ax = &s->axis;
    json_t *sol = s->sol, *intr = json_object_get(sol, "intrinsics");
    char *solpath = g_strdup_printf("%s/solution.json", s->soldir);
    char *hpath = g_strdup_printf("%s/report.html", s->outdir);
    fprintf(stderr, "refl calib geometry: plots\n");
    bool ok = model_run_script("calib_geometry_report.py", "plots", jpath, solpath, s->outdir, NULL) == 0;
    FILE *f = ok ? model_html_begin(hpath, "refl calib geometry", s->prov) : NULL;
    if (f) {
        int outliers = (int)json_integer_value(json_object_get(sol, "outliers"));
        model_html_heading(f, "Camera model");
        model_html_para(f, "%s, %dx%d px; %zu of %u views used; RMS reprojection residual %.4f px; %d outliers "
                        "of %d points.", s->lensmodel, s->W, s->H, json_array_size(json_object_get(sol, "images")),
                        s->views.v->len, s->rms_px, outliers,
                        (int)json_integer_value(json_object_get(sol, "points")) + outliers);
        const calib_board_t *bd = &o->board;
        char marker[96] = "";
        if (bd->kind == CALIB_BOARD_CHARUCO)
            snprintf(marker, sizeof marker, ", markers %g mm of %s", bd->marker_mm, bd->dict);
        model_html_para(f, "Board: %s of %d x %d inner corners %g mm apart%s; corners by %s.",
                        calib_board_kind_name(bd->kind), bd->width_n, bd->height_n, bd->spacing_mm, marker,
                        o->corners ? "the corners file" : calib_geometry_detector(o->detector, bd) ==
                        CALIB_DETECTOR_MRGINGHAM ? "mrgingham" : "OpenCV");
        model_html_para(f, "Intrinsics fx, fy, cx, cy: %.3f, %.3f, %.3f, %.3f px.",
                        json_real_value(json_array_get(intr, 0)), json_real_value(json_array_get(intr, 1)),
                        json_real_value(json_array_get(intr, 2)), json_real_value(json_array_get(intr, 3)));
        model_html_figure(f, "residuals_vectors.png", "Reprojection residuals over the imager");
        model_html_figure(f, "residuals_histogram.png", "Distribution of the residuals");
        model_html_figure(f, "residuals_per_image.png", "RMS residual per image");
        report_figure_if(f, s->outdir, "worst_views.png", "The three images with the largest RMS residual: observed "
                         "corners and their residuals over the image");
        report_figure_if(f, s->outdir, "distortion.png", "Lens distortion: how far the model moves each pixel from "
                         "the pinhole of the same fx, fy, cx, cy, with the valid-intrinsics region");
        json_t *u = json_object_get(sol, "uncertainty");
        if (json_object_get(u, "max_px")) {
            model_html_heading(f, "Projection uncertainty");
            model_html_para(f, "mrcal.projection_uncertainty (worst direction, 1 sigma) at %g mm: centre %.4f px, "
                            "median %.4f px, max %.4f px over the imager.", o->distance_mm,
                            json_real_value(json_object_get(u, "centre_px")),
                            json_real_value(json_object_get(u, "median_px")),
                            json_real_value(json_object_get(u, "max_px")));
            model_html_figure(f, "uncertainty.png", "Projection uncertainty (dots: observed corners)");
        }
        report_crossvalidation(f, s);
        calib_psf_report(f, s);
        json_t *cams = json_object_get(s->out, "cameras");
        if (json_array_size(cams) > 1) {
            model_html_heading(f, "Cameras (one joint solve)");
            size_t k;
            json_t *c;
            json_array_foreach(cams, k, c) {
                json_t *ci = json_object_get(c, "intrinsics"), *rel = json_object_get(c, "rt_cam_cam0");
                model_html_para(f, "%s: %s, %lld views, RMS %.4f px; fx, fy, cx, cy %.3f, %.3f, %.3f, %.3f px; pose "
                                "relative to %s rt %.6f %.6f %.6f rad, %.3f %.3f %.3f mm (1-sigma %.4f deg, %.3f mm).",
                                json_string_value(json_object_get(c, "name")),
                                json_string_value(json_object_get(c, "camera_model")),
                                json_integer_value(json_object_get(c, "views_used")),
                                json_number_value(json_object_get(c, "rms_residual_px")),
                                json_real_value(json_array_get(ci, 0)), json_real_value(json_array_get(ci, 1)),
                                json_real_value(json_array_get(ci, 2)), json_real_value(json_array_get(ci, 3)),
                                s->camnames[0], json_real_value(json_array_get(rel, 0)),
                                json_real_value(json_array_get(rel, 1)), json_real_value(json_array_get(rel, 2)),
                                json_real_value(json_array_get(rel, 3)), json_real_value(json_array_get(rel, 4)),
                                json_real_value(json_array_get(rel, 5)),
                                json_real_value(json_object_get(c, "rotation_stdev_deg")),
                                json_real_value(json_object_get(c, "translation_stdev_mm")));
            }
        }
        model_html_heading(f, "Turntable axis and rig frame");
        if (ax->ok) {
            model_html_para(f, "Axis direction (camera frame) %.6f %.6f %.6f, +- %.4f deg; point %.2f %.2f %.2f mm "
                            "+- %.3f mm across the axis (1 sigma, %s); %d pose pairs; off-axis rotation RMS of mrcal's "
                            "free poses %.4f deg.", ax->a[0], ax->a[1], ax->a[2], ax->dir_unc_deg, ax->c[0], ax->c[1],
                            ax->c[2], ax->point_unc_mm, ax->joint ? "fitted jointly with the board poses as turns "
                            "about it" : "closed form, approximate", ax->npairs, ax->off_axis_rms_deg);
            if (ax->joint)
                model_html_para(f, "Joint fit: %d views, corner RMS %.4f px (chi^2/dof %.2f). Rig frame 1 sigma: z "
                                "%.4f deg, x %.4f deg, origin %.3f mm across and %.3f mm along the axis.",
                                ax->joint_views, ax->joint_rms_px, ax->joint_chi2, ax->dir_unc_deg, ax->rig_x_unc_deg,
                                ax->point_unc_mm, ax->rig_origin_along_mm);
            model_html_figure(f, "axis_fit.png", "Board rotation about the fitted axis against the turntable angle");
        } else {
            model_html_para(f, "No axis: %s.", s->rigwhy);
        }
        model_html_para(f, "Rig frame: %s.", json_string_value(json_object_get(s->out, "rig_frame")));
        model_html_heading(f, "Images without a board");
        GPtrArray *rows = g_ptr_array_new_with_free_func(g_free);
        for (guint k = 0; k < s->views.v->len; k++) {
            calib_geometry_view_t *v = g_ptr_array_index(s->views.v, k);
            if (!v->found) g_ptr_array_add(rows, g_strdup_printf("%s|%s|%s", v->name, v->source, v->why));
        }
        if (rows->len)
            model_html_table(f, "image|source|why", (const char *const *)rows->pdata, (int)rows->len);
        else
            model_html_para(f, "none: the board was found in every image.");
        g_ptr_array_free(rows, TRUE);
        ok = model_html_end(f, hpath);
    } else {
        ok = false;
    }
    g_free(solpath);
    g_free(hpath);
    return ok;
}

// Several cameras: camera k's rt_cam_ref (the rig frame's, else camera 0's)
// from the joint solve's rt_camk_cam0.
static void camera_rt(const calib_geometry_state_t *s, json_t *cj, double rt[6])
{
    double rt_k0[6];
    json_t *e = json_object_get(cj, "rt_cam_cam0");
    for (int c = 0; c < 6; c++) rt_k0[c] = json_real_value(json_array_get(e, c));
    if (s->have_rig) compose(rt, rt_k0, s->rt_cam_rig);
    else memcpy(rt, rt_k0, sizeof rt_k0);
}

// Several cameras: DIR/NAME.cameramodel each, and geometry.json's "cameras".
static bool camera_outputs(const calib_geometry_opts_t *o, calib_geometry_state_t *s)
{
    json_t *cams = json_object_get(s->sol, "cameras"), *arr = json_array();
    bool ok = json_array_size(cams) == (size_t)s->ncams;
    if (!ok) model_error_set(s->mdir, 0, "the solution has %zu cameras, not %d", json_array_size(cams), s->ncams);
    for (int k = 0; k < s->ncams && ok; k++) {
        json_t *cj = json_array_get(cams, k), *c = json_object();
        double rt[6], inv[6];
        camera_rt(s, cj, rt);
        char *path = g_strdup_printf("%s/%s.cameramodel", s->outdir, s->camnames[k]);
        json_t *rms = json_object_get(cj, "rms_px");
        char ref[400];
        snprintf(ref, sizeof ref, "camera %s (the first camera; no rig frame: %s)", s->camnames[0], s->rigwhy);
        ok = s->have_rig ? calib_geometry_write_cameramodel(path, s->lensmodel, json_object_get(cj, "intrinsics"),
                                                            s->camw[k], s->camh[k], rt, true, json_number_value(rms))
                         : write_cameramodel_ref(path, s->lensmodel, json_object_get(cj, "intrinsics"), s->camw[k],
                                                 s->camh[k], rt, ref, json_number_value(rms));
        json_object_set_new(c, "name", json_string(s->camnames[k]));
        json_object_set_new(c, "camera_model", json_string(path));
        json_object_set_new(c, "intrinsics", json_incref(json_object_get(cj, "intrinsics")));
        json_object_set_new(c, "imagersize_px", json_pack("[ii]", s->camw[k], s->camh[k]));
        json_object_set_new(c, "rms_residual_px", json_incref(rms));
        json_object_set_new(c, "views_used", json_incref(json_object_get(cj, "observations")));
        json_object_set_new(c, "rt_cam_cam0", json_incref(json_object_get(cj, "rt_cam_cam0")));
        const char *keys[] = { "rt_cam_cam0_stdev", "rotation_stdev_deg", "translation_stdev_mm" };
        for (int i = 0; i < 3; i++)
            if (json_object_get(cj, keys[i])) json_object_set_new(c, keys[i], json_incref(json_object_get(cj, keys[i])));
        json_object_set_new(c, "rt_cam_rig", s->have_rig ? jarr(rt, 6) : json_null());
        if (s->have_rig) {
            invert(inv, rt);
            json_object_set_new(c, "camera_centre_rig_mm", jarr(&inv[3], 3));
        }
        json_object_set_new(c, "projection_uncertainty", json_incref(json_object_get(cj, "uncertainty")));
        json_array_append_new(arr, c);
        g_free(path);
    }
    json_object_set_new(s->out, "cameras_note", json_string("several cameras calibrated in one mrcal solve; "
                        "rt_cam_cam0: each camera's pose relative to the first (rt_camk_cam0, r rad, t mm) with its "
                        "1-sigma from the solve; rt_cam_rig = rt_cam_cam0 composed with the first camera's "
                        "rt_cam_rig (the rig frame from the first camera's views)"));
    json_object_set_new(s->out, "cameras", arr);
    return ok;
}

// Stage 5: camera.cameramodel, geometry.json, the report.
static bool outputs(const calib_geometry_opts_t *o, calib_geometry_state_t *s)
{
    s->campath = g_strdup_printf("%s/camera.cameramodel", s->outdir);
    // each model written here gets mrcal's optimization_inputs (camera k's: the chosen solve's
    // camera-k.cameramodel) while keeping its extrinsics, so that mrcal's tools run on it (calib/geometry/export.c)
    char *m0 = g_strdup_printf("%s/camera-0.cameramodel", s->soldir);
    bool kept = calib_geometry_write_cameramodel(s->campath, s->lensmodel, json_object_get(s->sol, "intrinsics"), s->W,
                                                 s->H, s->rt_cam_rig, s->have_rig, s->rms_px) &&
                calib_export_keep_optimization_inputs(m0, s->campath);
    g_free(m0);
    if (!kept || !(s->out = calib_geometry_json(o, s))) return false;
    if (s->ncams > 1 && !camera_outputs(o, s)) return false;
    if (!calib_psf_geometry(o, s)) return false;   // the lens's blur from the board's edges (calib/geometry/psf.c)
    for (int k = 0; k < s->ncams && s->ncams > 1 && kept; k++) {
        char *mk = g_strdup_printf("%s/camera-%d.cameramodel", s->soldir, k);
        char *pk = g_strdup_printf("%s/%s.cameramodel", s->outdir, s->camnames[k]);
        kept = calib_export_keep_optimization_inputs(mk, pk);
        g_free(mk);
        g_free(pk);
    }
    if (!kept) return false;
    char *jpath = g_strdup_printf("%s/geometry.json", s->outdir);
    bool ok = model_write_json(jpath, s->out) && calib_geometry_report(o, s, jpath);
    g_free(jpath);
    return ok;
}

calib_geometry_opts_t calib_geometry_defaults(void)
{
    return (calib_geometry_opts_t){ .lensmodel = "LENSMODEL_OPENCV8", .tilts = CALIB_GEOMETRY_DEFAULT_TILTS,
                                    .angles = CALIB_GEOMETRY_DEFAULT_ANGLES, .sample = "calib_board",
                                    .board = { .kind = CALIB_BOARD_CHESSBOARD, .width_n = 10, .height_n = 10,
                                               .spacing_mm = 30, .marker_mm = 30 * CALIB_BOARD_DEFAULT_MARKER_RATIO,
                                               .dict = CALIB_BOARD_DEFAULT_DICT },
                                    .board_height_mm = 5, .exposure_us = 6000, .focal_px = NAN,
                                    .distance_mm = 900, .progress = 0 };
}

void calib_geometry_state_free(calib_geometry_state_t *s)
{
    calib_geometry_views_free(&s->views);
    json_decref(s->prov);
    free(s->outdir);
    g_free(s->imgdir);
    g_free(s->mdir);
    g_free(s->soldir);
    g_free(s->solvecorners);
    g_free(s->lensmodel);
    json_decref(s->xv);
    g_free(s->cornpath);
    g_strfreev(s->sessions);
    json_decref(s->sol);
    model_camera_free(s->cam);
    json_decref(s->axis.fit);
    g_free(s->campath);
    json_decref(s->out);
    memset(s, 0, sizeof *s);
}

void calib_geometry_result_free(calib_geometry_result_t *r)
{
    g_free(r->camera_model);
    g_free(r->outdir);
    memset(r, 0, sizeof *r);
}

bool calib_geometry_run(const calib_geometry_opts_t *o, calib_geometry_result_t *r)
{
    memset(r, 0, sizeof *r);
    calib_geometry_state_t s = { 0 };
    calib_geometry_views_init(&s.views);
    bool ok = false;
    s.prov = model_provenance(o->argc, o->argv);
    if (!model_mkdir_p(o->out)) goto done;
    s.outdir = realpath(o->out, NULL);
    s.imgdir = g_strdup_printf("%s/images", s.outdir);
    s.mdir = g_strdup_printf("%s/mrcal", s.outdir);
    if (!model_mkdir_p(s.imgdir) || !model_mkdir_p(s.mdir)) goto done;
    if (o->rig && (!model_provenance_input(s.prov, "rig", o->rig) || !calib_geometry_capture(o, &s, &r->usage)))
        goto done;
    if (!collect_views(o, &s) || !calib_geometry_find_corners(o, &s) || !calib_geometry_solve(o, &s) ||
        !calib_geometry_apply_solution(o, &s) || !calib_geometry_validate_lens(o, &s))
        goto done;
    axis_and_rig_frame(o, &s);
    if (!outputs(o, &s)) goto done;
    r->camera_model = g_strdup(s.campath);
    r->outdir = g_strdup(s.outdir);
    r->rms_px = s.rms_px;
    r->have_rig = s.have_rig;
    ok = true;
done:
    calib_geometry_state_free(&s);
    return ok;
}
