// calib/geometry/diff.c — how far two camera models project apart over the
// imager, the way mrcal's projection_diff judges it: pixels on a grid over
// model a's imager are unprojected with a to points at the working distance,
// the rigid transform from a's camera frame to b's that best explains the
// points within a focus radius of the imager's centre is fitted (two
// calibrations of one lens differ by a slight turn of the frame, which no user
// sees; mrcal fits it within min(W, H) / 6 of the centre by default), and all
// the points are projected with b. The RMS and the worst distance between the
// pixels and b's projections over the whole grid are the difference, px. At one distance a focal length's error looks like a shift of the camera
// along its axis, and is absorbed by it: the difference is that of the views
// of points at that distance (where the lab works); where the camera itself
// is, is the extrinsics' to say.
#include <glib.h>
#include <math.h>
#include <mrcal/mrcal.h>
#include <mrcal/poseutils.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "calib/geometry/geometry.h"
#include "model/base/lsq.h"
#include "model/model.h"
#include "model/base/report.h"

typedef struct {
    const mrcal_cameramodel_t *b;
    mrcal_point3_t p;   // a's camera frame
    mrcal_point2_t q;   // the pixel of a
} pd_point_t;

// b's projection of p moved by rt, minus the pixel (2 residuals, d/d rt).
static bool pd_residual(void *ctx, const double *const *params, double *r, double **J)
{
    const pd_point_t *pt = ctx;
    double x[3], dx_drt[18];
    mrcal_transform_point_rt(x, J && J[0] ? dx_drt : NULL, NULL, params[0], pt->p.xyz);
    mrcal_point2_t q;
    mrcal_point3_t dq_dx[2];
    const mrcal_point3_t px = { .xyz = { x[0], x[1], x[2] } };
    if (!mrcal_project(&q, dq_dx, NULL, &px, 1, &pt->b->lensmodel, pt->b->intrinsics)) return false;
    r[0] = q.xy[0] - pt->q.xy[0];
    r[1] = q.xy[1] - pt->q.xy[1];
    if (J && J[0])
        for (int i = 0; i < 2; i++)
            for (int c = 0; c < 6; c++)
                J[0][i * 6 + c] = dq_dx[i].xyz[0] * dx_drt[c] + dq_dx[i].xyz[1] * dx_drt[6 + c] +
                                  dq_dx[i].xyz[2] * dx_drt[12 + c];
    return isfinite(r[0]) && isfinite(r[1]);
}

static double pd_stats(const pd_point_t *pts, int n, const double rt[6], double *worst)
{
    double s = 0, mx = 0;
    const double *blocks[1] = { rt };
    for (int k = 0; k < n; k++) {
        double r[2];
        if (!pd_residual((void *)&pts[k], blocks, r, NULL)) r[0] = r[1] = NAN;
        double d2 = r[0] * r[0] + r[1] * r[1];
        s += d2;
        mx = fmax(mx, sqrt(d2));
    }
    *worst = mx;
    return sqrt(s / n);
}

bool calib_projection_diff(const mrcal_cameramodel_t *a, const mrcal_cameramodel_t *b, double distance_mm,
                           int margin_px, double focus_radius_px, calib_projection_diff_t *out)
{
    memset(out, 0, sizeof *out);
    enum { GX = 33, GY = 27, N = GX * GY };
    double W = a->imagersize[0] - 2.0 * margin_px, H = a->imagersize[1] - 2.0 * margin_px;
    if (!(distance_mm > 0) || W < 2 || H < 2) {
        model_error(NULL, 0, "projection difference: a distance > 0 and an imager larger than twice the margin "
                    "(%d px) are needed", margin_px);
        return false;
    }
    pd_point_t *pts = calloc(N, sizeof *pts);
    mrcal_point2_t *q = calloc(N, sizeof *q);
    mrcal_point3_t *v = calloc(N, sizeof *v);
    lsq_problem_t *p = lsq_problem_new();
    bool ok = pts && q && v && p;
    if (p && !ok) model_error(NULL, 0, "projection difference: out of memory");   // (else lsq_problem_new's)
    for (int j = 0; ok && j < GY; j++)
        for (int i = 0; i < GX; i++)
            q[j * GX + i] = (mrcal_point2_t){ .xy = { margin_px + i * (W - 1) / (GX - 1),
                                                      margin_px + j * (H - 1) / (GY - 1) } };
    if (ok && !mrcal_unproject(v, q, N, &a->lensmodel, a->intrinsics)) {
        ok = false;
        model_error(NULL, 0, "projection difference: mrcal_unproject failed over the first model's imager");
    }
    double rt[6] = { 0 };
    int nfit = 0;
    if (ok) ok = lsq_add_parameters(p, rt, 6);
    for (int k = 0; ok && k < N; k++) {
        double n = sqrt(v[k].xyz[0] * v[k].xyz[0] + v[k].xyz[1] * v[k].xyz[1] + v[k].xyz[2] * v[k].xyz[2]);
        pts[k] = (pd_point_t){ .b = b, .q = q[k] };
        for (int c = 0; c < 3; c++) pts[k].p.xyz[c] = v[k].xyz[c] * distance_mm / n;
        double *blocks[1] = { rt };
        double dx = q[k].xy[0] - (a->imagersize[0] - 1) / 2.0, dy = q[k].xy[1] - (a->imagersize[1] - 1) / 2.0;
        if (focus_radius_px > 0 && dx * dx + dy * dy > focus_radius_px * focus_radius_px) continue;
        nfit++;
        ok = lsq_add_residual(p, pd_residual, &pts[k], 2, 1, blocks, LSQ_LOSS_NONE, 0);
    }
    if (ok && nfit < 3) {
        ok = false;
        model_error(NULL, 0, "projection difference: fewer than 3 grid points within the focus radius (%g px)",
                    focus_radius_px);
    }
    if (ok) {
        out->rms_unaligned_px = pd_stats(pts, N, rt, &out->worst_unaligned_px);
        lsq_options_t lo = lsq_defaults();
        lsq_summary_t sum;
        ok = lsq_solve(p, &lo, &sum);
    }
    if (ok) {
        out->rms_px = pd_stats(pts, N, rt, &out->worst_px);
        memcpy(out->rt_a_to_b, rt, sizeof rt);
        out->rotation_deg = sqrt(rt[0] * rt[0] + rt[1] * rt[1] + rt[2] * rt[2]) * 180 / M_PI;
        out->translation_mm = sqrt(rt[3] * rt[3] + rt[4] * rt[4] + rt[5] * rt[5]);
        out->distance_mm = distance_mm;
        out->npoints = N;
        ok = isfinite(out->rms_px);
        if (!ok) model_error(NULL, 0, "projection difference: the second model cannot project every point");
    }
    lsq_problem_free(p);
    free(pts);
    free(q);
    free(v);
    return ok;
}

// ---------------------------------------------------------------------------
// Cross-validation and the lens model (calib/geometry/geometry.h)

bool calib_geometry_is_auto(const char *lensmodel) { return lensmodel && !strcmp(lensmodel, "auto"); }

bool calib_geometry_splined_name(const model_camera_t *cam, int W, int H, char *name, size_t n)
{
    // the border's rays (every 8th of each side) in the stereographic plane: u = 2 tan(theta / 2) (x, y) / |(x, y)|
    enum { K = 8, NB = 4 * K };
    double q[2 * NB];
    model_vec3_t v[NB];
    for (int k = 0; k < K; k++) {
        double fx = (W - 1.0) * k / K, fy = (H - 1.0) * k / K;
        double pts[4][2] = { { fx, 0 }, { W - 1.0 - fx, H - 1.0 }, { 0, H - 1.0 - fy }, { W - 1.0, fy } };
        for (int s = 0; s < 4; s++) {
            q[2 * (4 * k + s)] = pts[s][0];
            q[2 * (4 * k + s) + 1] = pts[s][1];
        }
    }
    if (!model_camera_unproject(cam, q, NB, v)) return false;
    double ux = 0, uy = 0;
    for (int k = 0; k < NB; k++) {
        double r = hypot(v[k].x, v[k].y), th = atan2(r, v[k].z), u = 2 * tan(th / 2);
        if (!(v[k].z > 0) || !(r > 0)) continue;
        ux = fmax(ux, fabs(u * v[k].x / r));
        uy = fmax(uy, fabs(u * v[k].y / r));
    }
    if (!(ux > 0 && uy > 0)) {
        model_error_set(NULL, 0, "the lean lens model sees no field of view to size the splined model by");
        return false;
    }
    ux *= 1.1;
    uy *= 1.1;
    int nx = (int)lround(W / 70.0);
    nx = nx < 8 ? 8 : nx > 30 ? 30 : nx;
    double du = 2 * ux / (nx - 1);                       // knot spacing, the same along y
    int ny = (int)ceil(2 * uy / du) + 1;
    ny = ny < 6 ? 6 : ny;
    double fov_x_deg = ceil(2 * 2 * atan(ux / 2) * 180 / M_PI);   // u = 2 tan(theta / 2): the knots' half-width
    snprintf(name, n, "LENSMODEL_SPLINED_STEREOGRAPHIC_order=3_Nx=%d_Ny=%d_fov_x_deg=%.0f", nx, ny, fov_x_deg);
    return true;
}

// The corners file in two halves: alternate frames (a view's base name: the
// views of one frame in every camera stay together) in the file's order;
// views[h][k]: the views of camera k in half h. Views without a board are
// left out; a partial view keeps its lines of corners not seen ("nan nan -").
static bool split_corners(const calib_geometry_state_t *s, const char *in, const char *out[2],
                          int views[2][RIG_CAMERAS_MAX])
{
    char *text = NULL;
    GError *err = NULL;
    if (!g_file_get_contents(in, &text, NULL, &err)) {
        model_error_set(in, 0, "cannot read: %s", err->message);
        g_error_free(err);
        return false;
    }
    GHashTable *half = g_hash_table_new_full(g_str_hash, g_str_equal, g_free, NULL);
    GHashTable *seen = g_hash_table_new_full(g_str_hash, g_str_equal, g_free, NULL);
    GString *g[2] = { g_string_new("# filename x y level\n"), g_string_new("# filename x y level\n") };
    memset(views, 0, sizeof(int) * 2 * RIG_CAMERAS_MAX);
    char **lines = g_strsplit(text, "\n", -1);
    GHashTable *board = g_hash_table_new_full(g_str_hash, g_str_equal, g_free, NULL);   // views with a corner seen
    for (int i = 0; lines[i]; i++) {
        char name[1024], xs[64];
        if (lines[i][0] != '#' && sscanf(lines[i], "%1023s %63s", name, xs) == 2 && strcmp(xs, "-") &&
            !g_hash_table_contains(board, name))
            g_hash_table_add(board, g_strdup(name));
    }
    int nkeys = 0;
    for (int i = 0; lines[i]; i++) {
        char name[1024], xs[64];
        if (lines[i][0] == '#' || sscanf(lines[i], "%1023s %63s", name, xs) != 2 || !g_hash_table_contains(board, name))
            continue;
        const char *b = strrchr(name, '/');
        b = b ? b + 1 : name;
        gpointer hv;
        if (!g_hash_table_lookup_extended(half, b, NULL, &hv)) {
            hv = GINT_TO_POINTER(nkeys++ % 2);
            g_hash_table_insert(half, g_strdup(b), hv);
        }
        int h = GPOINTER_TO_INT(hv), cam = 0;
        for (int k = 0; k < s->ncams && s->ncams > 1; k++) {
            size_t l = strlen(s->camnames[k]);
            if (!strncmp(name, s->camnames[k], l) && name[l] == '/') cam = k;
        }
        if (!g_hash_table_contains(seen, name)) {
            g_hash_table_add(seen, g_strdup(name));
            views[h][cam]++;
        }
        g_string_append_printf(g[h], "%s\n", lines[i]);
    }
    bool ok = true;
    for (int h = 0; h < 2 && ok; h++)
        if (!g_file_set_contents(out[h], g[h]->str, (gssize)g[h]->len, &err)) {
            model_error_set(out[h], 0, "cannot write: %s", err->message);
            g_error_free(err);
            ok = false;
        }
    g_strfreev(lines);
    g_string_free(g[0], TRUE);
    g_string_free(g[1], TRUE);
    g_hash_table_destroy(half);
    g_hash_table_destroy(seen);
    g_hash_table_destroy(board);
    g_free(text);
    return ok;
}

// scripts/calib_geometry_report.py compare a b → its figures (new reference; the
// grids stay in out). NULL + message.
static json_t *compare_models(const char *a, const char *b, const char *out, double distance_mm)
{
    char dist[32];
    snprintf(dist, sizeof dist, "%g", distance_mm);
    int e = model_run_script("calib_geometry_report.py", "compare", a, b, out, dist, NULL);
    json_error_t je;
    json_t *c = e == 0 ? json_load_file(out, 0, &je) : NULL;
    if (!c) {
        if (e == 0) model_error_set(out, je.line, "cannot read: %s", je.text);
        else model_error_set(a, 0, "comparing with %s failed (scripts/calib_geometry_report.py compare: exit "
                             "status %d)", b, e);
        return NULL;
    }
    json_t *r = json_pack("{s:O,s:O,s:O,s:O,s:s}", "distance_mm", json_object_get(c, "distance_mm"), "observed",
                          json_object_get(c, "observed"), "imager", json_object_get(c, "imager"), "rt_a_to_b",
                          json_object_get(c, "rt_a_to_b"), "details", out);
    json_decref(c);
    return r;
}

// The comparison of every camera's models in dir_a and dir_b into r's
// "cameras"; r's "ratio": the largest observed ratio. false + message.
static bool compare_cameras(const calib_geometry_state_t *s, const char *dir_a, const char *dir_b, const char *tag,
                            double distance_mm, json_t *r)
{
    json_t *cams = json_array();
    double worst = 0;
    bool ok = true;
    for (int k = 0; k < s->ncams && ok; k++) {
        char *a = g_strdup_printf("%s/camera-%d.cameramodel", dir_a, k);
        char *b = g_strdup_printf("%s/camera-%d.cameramodel", dir_b, k);
        char *out = g_strdup_printf("%s/compare-%s-%d.json", s->mdir, tag, k);
        json_t *c = compare_models(a, b, out, distance_mm);
        ok = c != NULL;
        if (ok) {
            if (s->ncams > 1) json_object_set_new(c, "camera", json_string(s->camnames[k]));
            double ratio = json_number_value(json_object_get(json_object_get(c, "observed"), "ratio_rms"));
            worst = fmax(worst, ratio);
            json_array_append_new(cams, c);
        }
        g_free(a);
        g_free(b);
        g_free(out);
    }
    json_object_set_new(r, "cameras", cams);
    json_object_set_new(r, "ratio", json_real(worst));
    json_object_set_new(r, "pass", json_boolean(worst <= CALIB_GEOMETRY_XV_MAX_RATIO));
    return ok;
}

// One note of figures (and the report's): camera 0's observed region.
static void xv_print(const char *what, const json_t *r)
{
    json_t *c0 = json_array_get(json_object_get(r, "cameras"), 0), *f = json_object_get(c0, "observed");
    model_note("%s: differ by RMS %.4f px (worst %.4f) where the views were, predicted "
               "s0 + s1 RMS %.4f px (worst %.4f); ratio %.2f: %s (criterion: ratio <= %.1f)", what,
               json_number_value(json_object_get(f, "diff_rms_px")),
               json_number_value(json_object_get(f, "diff_worst_px")),
               json_number_value(json_object_get(f, "predicted_rms_px")),
               json_number_value(json_object_get(f, "predicted_worst_px")),
               json_number_value(json_object_get(r, "ratio")),
               json_is_true(json_object_get(r, "pass")) ? "passes" : "FAILS", CALIB_GEOMETRY_XV_MAX_RATIO);
}

json_t *calib_geometry_crossvalidate(const calib_geometry_opts_t *o, calib_geometry_state_t *s,
                                     const char *lensmodel, const char *tag)
{
    char *dir = g_strdup_printf("%s/xv-%s", s->mdir, tag);
    char *hc[2] = { g_strdup_printf("%s/half0.vnl", dir), g_strdup_printf("%s/half1.vnl", dir) };
    char *hd[2] = { g_strdup_printf("%s/half0", dir), g_strdup_printf("%s/half1", dir) };
    int views[2][RIG_CAMERAS_MAX];
    json_t *r = json_object();
    json_object_set_new(r, "lensmodel", json_string(lensmodel));
    bool ok = model_mkdir_p(dir) && split_corners(s, s->solvecorners, (const char *[]){ hc[0], hc[1] }, views);
    int min = o->min_views ? o->min_views : calib_geometry_default_min_views(lensmodel), n[2] = { 0, 0 };
    char why[320] = "";
    for (int k = 0; ok && k < s->ncams; k++)
        for (int h = 0; h < 2; h++) {
            n[h] += views[h][k];
            if (views[h][k] < min && !why[0])
                snprintf(why, sizeof why, "too few views to cross-validate %s: half %d has %d views%s%s, the solve "
                         "needs %d (--min-views)", lensmodel, h, views[h][k], s->ncams > 1 ? " of camera " : "",
                         s->ncams > 1 ? s->camnames[k] : "", min);
        }
    if (ok) json_object_set_new(r, "views_per_half", json_pack("[ii]", n[0], n[1]));
    if (ok && why[0]) {
        json_object_set_new(r, "done", json_false());
        json_object_set_new(r, "why", json_string(why));
        model_warning("no cross-validation: %s", why);
    }
    // a half that cannot be solved or compared is said, not fatal: the calibration of all the views stands
    for (int h = 0; ok && !why[0] && h < 2; h++) {
        json_t *sol = NULL;
        model_note("cross-validation of %s, half %d", lensmodel, h);
        if (!calib_geometry_mrcal(o, s, lensmodel, hc[h], hd[h], n[h], &sol))
            snprintf(why, sizeof why, "half %d could not be solved: %.250s", h, model_last_error());
        json_decref(sol);
    }
    if (ok && !why[0]) {
        json_object_set_new(r, "done", json_true());
        if (!compare_cameras(s, hd[0], hd[1], tag, o->distance_mm, r))
            snprintf(why, sizeof why, "the halves could not be compared: %.250s", model_last_error());
        char what[300];
        snprintf(what, sizeof what, "cross-validation of %s (halves of %d and %d views)", lensmodel, n[0], n[1]);
        if (!why[0]) xv_print(what, r);
    }
    if (ok && why[0] && !json_is_false(json_object_get(r, "done"))) {
        json_object_set_new(r, "done", json_false());
        json_object_set_new(r, "why", json_string(why));
        model_warning("no cross-validation of %s: %s", lensmodel, why);
    }
    for (int h = 0; h < 2; h++) {
        g_free(hc[h]);
        g_free(hd[h]);
    }
    g_free(dir);
    if (!ok) json_decref(r);
    return ok ? r : NULL;
}

// "passes (ratio r)", "FAILS (ratio r)" or "was not done: why".
static void xv_words(const json_t *r, char *out, size_t n)
{
    if (!json_is_true(json_object_get(r, "done")))
        snprintf(out, n, "was not done: %s", json_string_value(json_object_get(r, "why")));
    else
        snprintf(out, n, "%s (ratio %.2f)", json_is_true(json_object_get(r, "pass")) ? "passes" : "FAILS",
                 json_number_value(json_object_get(r, "ratio")));
}

static double xv_ratio(const json_t *r)
{
    return json_is_true(json_object_get(r, "done")) ? json_number_value(json_object_get(r, "ratio")) : NAN;
}

// --lensmodel auto after the lean model's cross-validation lean: the splined
// fit of the same views, the comparison, the choice into x ("lean_vs_splined",
// "lens_choice"; the splined cross-validation appended to runs). false + message.
static bool choose_lens(const calib_geometry_opts_t *o, calib_geometry_state_t *s, json_t *lean, json_t *runs,
                        json_t *x)
{
    char spl[200], why[700];
    const char *leanname = json_string_value(json_object_get(lean, "lensmodel"));
    double rl = xv_ratio(lean);
    bool lean_xv = !(rl > CALIB_GEOMETRY_XV_MAX_RATIO);   // passes, or could not be done
    if (!calib_geometry_splined_name(s->cam, s->W, s->H, spl, sizeof spl)) return false;
    int min = o->min_views ? o->min_views : calib_geometry_default_min_views(spl);
    json_t *choice = json_pack("{s:s,s:s}", "requested", "auto", "splined_candidate", spl);
    json_object_set_new(x, "lens_choice", choice);
    if (s->nfound < min) {
        snprintf(why, sizeof why, "%s kept: %d views are too few for the splined model (%d needed, --min-views)%s",
                 leanname, s->nfound, min, lean_xv ? "" : "; its cross-validation FAILS");
        json_object_set_new(choice, "chosen", json_string(leanname));
        json_object_set_new(choice, "why", json_string(why));
        return true;
    }
    char *sdir = g_strdup_printf("%s/splined", s->mdir);
    json_t *ssol = NULL, *bias = json_pack("{s:s,s:s}", "a", leanname, "b", spl);
    if (!calib_geometry_mrcal(o, s, spl, s->solvecorners, sdir, s->nfound, &ssol) ||
        !compare_cameras(s, s->mdir, sdir, "lean-splined", o->distance_mm, bias)) {
        char *w = g_strdup_printf("%s kept: the splined model could not be fitted or compared (%s)%s", leanname,
                                  model_last_error(), lean_xv ? "" : "; its cross-validation FAILS");
        model_warning("%s", w);
        json_object_set_new(choice, "chosen", json_string(leanname));
        json_object_set_new(choice, "why", json_string(w));
        g_free(w);
        json_decref(bias);
        json_decref(ssol);
        g_free(sdir);
        return true;
    }
    bool ok = true;
    json_object_set_new(x, "lean_vs_splined", bias);
    if (ok) xv_print("the lean model against the splined fit of the same views", bias);
    double rb = json_number_value(json_object_get(bias, "ratio"));
    json_t *sp = NULL;
    if (ok && !(lean_xv && rb <= CALIB_GEOMETRY_XV_MAX_RATIO)) {
        ok = (sp = calib_geometry_crossvalidate(o, s, spl, "splined")) != NULL;
        if (ok) json_array_append_new(runs, sp);
    }
    if (ok) {
        double rs = sp ? xv_ratio(sp) : NAN;
        bool lean_ok = lean_xv && rb <= CALIB_GEOMETRY_XV_MAX_RATIO, spl_ok = !(rs > CALIB_GEOMETRY_XV_MAX_RATIO);
        bool take = !lean_ok && (spl_ok || !(rs >= rl));
        char xl[400], xs[400];
        xv_words(lean, xl, sizeof xl);
        if (sp) xv_words(sp, xs, sizeof xs);
        char *w = lean_ok
            ? g_strdup_printf("%s kept: its cross-validation %s, and it agrees with the splined fit of the same views "
                              "(ratio %.2f <= %.1f)", leanname, xl, rb, CALIB_GEOMETRY_XV_MAX_RATIO)
            : g_strdup_printf("%s %s: the lean %s's cross-validation %s, against the splined fit of the same views "
                              "ratio %.2f (criterion <= %.1f); the splined model's cross-validation %s%s",
                              take ? spl : leanname, take ? "chosen" : "kept", leanname, xl, rb,
                              CALIB_GEOMETRY_XV_MAX_RATIO, sp ? xs : "not run",
                              spl_ok ? "" : take ? "; kept as the smaller ratio" : "; the lean model kept as the "
                                                                                   "smaller ratio");
        json_object_set_new(choice, "chosen", json_string(take ? spl : leanname));
        json_object_set_new(choice, "why", json_string(w));
        g_free(w);
        if (take) {
            json_decref(s->sol);
            s->sol = ssol;
            ssol = NULL;
            g_free(s->lensmodel);
            s->lensmodel = g_strdup(spl);
            g_free(s->soldir);
            s->soldir = g_strdup(sdir);
            ok = calib_geometry_apply_solution(o, s);
        }
    }
    json_decref(ssol);
    g_free(sdir);
    return ok;
}

bool calib_geometry_validate_lens(const calib_geometry_opts_t *o, calib_geometry_state_t *s)
{
    json_t *lean = calib_geometry_crossvalidate(o, s, s->lensmodel, "model");
    if (!lean) return false;
    json_t *x = json_object(), *runs = json_array();
    json_array_append_new(runs, lean);
    json_object_set_new(x, "runs", runs);
    json_object_set_new(x, "criterion", json_sprintf(
        "a lens model fails when, over the grid points within one grid step of a corner each model observed, the "
        "RMS of |difference| / (s0 + s1) exceeds %.1f (s: mrcal's worst-direction projection standard deviation of "
        "each model at distance_mm)", CALIB_GEOMETRY_XV_MAX_RATIO));
    json_object_set_new(x, "method", json_string(
        "halves: alternate frames of the corners file; each solved alone; the difference over a 33 x 27 grid "
        "after the rigid transform between the camera frames fitted with weights 1 / (s0^2 + s1^2)"));
    json_decref(s->xv);
    s->xv = x;
    bool ok = true;
    if (calib_geometry_is_auto(o->lensmodel)) {
        ok = choose_lens(o, s, lean, runs, x);
    } else {
        double r = xv_ratio(lean);
        char why[400];
        snprintf(why, sizeof why, "%s, as --lensmodel says%s", s->lensmodel,
                 r > CALIB_GEOMETRY_XV_MAX_RATIO ? "; its cross-validation FAILS: the lens is not this model "
                                                   "(try --lensmodel auto or a splined model)" : "");
        json_object_set_new(x, "lens_choice", json_pack("{s:s,s:s,s:s}", "requested", o->lensmodel, "chosen",
                                                        s->lensmodel, "why", why));
    }
    if (ok)
        model_note("lens model: %s",
                   json_string_value(json_object_get(json_object_get(x, "lens_choice"), "why")));
    return ok;
}
