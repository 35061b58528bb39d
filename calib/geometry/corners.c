// calib/geometry/corners.c — the board's corners of every view: mrgingham's or OpenCV's
// (calib/geometry/board_detect.h) on the 8-bit images, or a corners file; parsed
// into the views (q, ncorners), the views of too few corners left out with the
// reason, and DIR/corners.vnl written for mrcal.
#include <glib.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "calib/calib.h"
#include "calib/geometry/internal.h"
#include "model/model.h"
#include "model/base/report.h"

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
        if (!v && create && !(v = geo_view_add(vs, name, name, NULL, -1, NAN, NAN, NAN))) {
            ok = false;
            break;
        }
        if (v != cur) {
            if (!(ok = corners_block_end(cur, ncur, line0, path, b))) break;
            cur = v;
            ncur = 0;
            line0 = li + 1;
            if (v) {
                free(v->q);
                if (!(v->q = malloc((size_t)N * 2 * sizeof(double)))) {
                    model_error_set(path, li + 1, "out of memory");
                    ok = false;
                    break;
                }
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
        if (v->found) snprintf(v->detector, sizeof v->detector, "corners file");
        else snprintf(v->why, sizeof v->why, "no %dx%d board in the corners file", o->board.width_n,
                      o->board.height_n);
    }
    return true;
}

static bool corners_mrgingham(const calib_geometry_opts_t *o, calib_geometry_state_t *s, char **text)
{
    calib_geometry_views_t *vs = &s->views;
    model_note("finding the %dx%d corners of %u images (mrgingham)", o->board.width_n,
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
    int e = model_run_tool(s->imgdir, (char *const *)args->pdata, log, text, GEO_INSTALL_HINT);
    g_ptr_array_free(args, TRUE);
    g_free(log);
    if (e != 0) {
        if (e > 0) {   // the tail of its messages, then what failed (else it did not run: that message says why)
            model_warning("%s", model_last_error());
            model_error_set(s->imgdir, 0, "mrgingham failed (exit status %d) on the images here; see %s/mrgingham.log",
                            e, s->mdir);
        }
        return false;
    }
    if (!calib_geometry_parse_corners(vs, *text, s->cornpath, &o->board, false)) return false;
    for (guint k = 0; k < vs->v->len; k++) {
        calib_geometry_view_t *v = g_ptr_array_index(vs->v, k);
        if (v->found) snprintf(v->detector, sizeof v->detector, "mrgingham");
        else snprintf(v->why, sizeof v->why, "mrgingham found no %dx%d board", o->board.width_n, o->board.height_n);
    }
    return true;
}

// One view's image (DIR/images/NAME, 8 bits) through the OpenCV detectors
// in turn (calib/geometry/board_detect.h): its lines of corners text into t
// (one "NAME - -" for no board, and then v->why), who found it and each
// attempt's outcome into v->detector, v->attempts. false + message.
static bool detect_view(const calib_geometry_opts_t *o, calib_geometry_state_t *s, calib_geometry_view_t *v,
                        double *q, GString *t)
{
    int w = 0, h = 0, N = o->board.width_n * o->board.height_n;
    char *path = g_strdup_printf("%s/%s", s->imgdir, v->name);
    float *img = model_image_read_float(path, &w, &h);
    unsigned char *u8 = img ? malloc((size_t)w * h) : NULL;
    if (img && !u8) model_error_set(path, 0, "out of memory");
    g_free(path);
    if (!u8) {
        free(img);
        return false;
    }
    for (size_t k = 0; k < (size_t)w * h; k++) u8[k] = img[k] <= 0 ? 0 : img[k] >= 255 ? 255 : (unsigned char)img[k];
    free(img);
    calib_board_how_t how;
    int n = calib_board_detect_how(&o->board, u8, w, h, q, CALIB_BOARD_DET_ALL, &how);
    free(u8);
    if (n < 0) return false;
    snprintf(v->detector, sizeof v->detector, "%s", how.detector);
    snprintf(v->attempts, sizeof v->attempts, "%s", how.attempts);
    if (n == 0) {
        g_string_append_printf(t, "%s - -\n", v->name);
        snprintf(v->why, sizeof v->why, "no detector found the board: %.290s", how.attempts);
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
    model_note("finding the %dx%d corners of the %s in %u images (OpenCV)",
               o->board.width_n, o->board.height_n, calib_board_kind_name(o->board.kind), vs->v->len);
    GString *t = g_string_new("# filename x y level\n");
    double *q = malloc((size_t)2 * o->board.width_n * o->board.height_n * sizeof *q);
    bool ok = q != NULL;
    if (!q) model_error_set(s->imgdir, 0, "out of memory");
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

// A corner line that says "not seen": "- -", a level "-" or a negative
// coordinate or level, as the parser above reads them.
static bool corner_line_unseen(const char *l)
{
    char name[1024], xs[64], ys[64], lev[64] = "";
    if (sscanf(l, "%1023s %63s %63s %63s", name, xs, ys, lev) < 3) return false;
    if (!strcmp(xs, "-") || !strcmp(ys, "-") || !strcmp(lev, "-")) return true;
    return strtod(xs, NULL) < 0 || strtod(ys, NULL) < 0 || (*lev && strtod(lev, NULL) < 0);
}

// The corners text for mrcal: text's lines, but a view not found as one line
// "NAME - -", and a corner a partial view does not show as "NAME nan nan -"
// (written to path). mrcal reads both as "not seen" (weight -1), but its seed
// (one solvePnP per view) keeps a "- -" corner at pixel (-1, -1), where a
// partial view's seed goes wrong and the solve may not recover; it drops NaN.
// false + message.
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
        if (v && corner_line_unseen(l)) g_string_append_printf(out, "%s nan nan -\n", name);
        else g_string_append_printf(out, "%s\n", l);
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
    char part[48] = "";
    if (partial) snprintf(part, sizeof part, " (%d of them in part)", partial);
    model_note("the board was found in %d of %u images%s", s->nfound, vs->v->len, part);
    const char *lens0 = calib_geometry_is_auto(o->lensmodel) ? CALIB_GEOMETRY_LEAN_LENSMODEL : o->lensmodel;
    int min_views = o->min_views ? o->min_views : calib_geometry_default_min_views(lens0);
    if (s->nfound < min_views) {
        model_error_set(o->corners ? o->corners : o->out, 0, "too few views for %s: the board was found in %d of %u "
                        "images, the solve needs at least %d (%d more views; tilt the board and turn the table so the "
                        "corners cover the imager)", lens0, s->nfound, vs->v->len, min_views,
                        min_views - s->nfound);
        GString *l = g_string_new("the images without a board:");
        for (guint k = 0; k < vs->v->len; k++) {
            calib_geometry_view_t *v = g_ptr_array_index(vs->v, k);
            if (!v->found) g_string_append_printf(l, "\n  %s (%s): %s", v->name, v->source, v->why);
        }
        model_note("%s", l->str);
        g_string_free(l, TRUE);
        return false;
    }
    for (int c = 0; c < s->ncams && s->ncams > 1; c++) {
        int nf = 0, nv = 0;
        for (guint k = 0; k < vs->v->len; k++) {
            calib_geometry_view_t *v = g_ptr_array_index(vs->v, k);
            nv += v->camera == c;
            nf += v->camera == c && v->found;
        }
        model_note("camera %s: the board in %d of %d images", s->camnames[c], nf, nv);
        if (nf < min_views) {
            model_error_set(o->out, 0, "too few views for %s of camera %s: the board was found in %d of its %d images, "
                            "the solve needs at least %d (tilt the board towards it, or give --tilts with poses "
                            "it sees)", lens0, s->camnames[c], nf, nv, min_views);
            return false;
        }
    }
    return true;
}
