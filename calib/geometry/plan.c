// calib/geometry/plan.c — the geometry session's board poses for one's own camera(s): the
// candidates' views through each camera model, the imager's coverage, the greedy choice with
// the orientations spread (calib/geometry/plan.h).
#define _GNU_SOURCE
#include <glib.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "calib/geometry/internal.h"
#include "calib/geometry/plan.h"
#include "model/base/vec.h"

#define NCLASS 5
#define CELLS_X 64
#define HEAD_ON_DEG 15.0
// the board's extent that must land inside the imager: half a square beyond the outer inner corners
// (mrgingham needs the squares around the corner grid)
#define EDGE 0.5
static const char *const class_names[NCLASS] = { "head-on", "left", "right", "up", "down" };

typedef struct {
    double tilt, az, angle;
    bool   usable[CALIB_PLAN_MAX_CAMERAS], chosen;
    double obliq[CALIB_PLAN_MAX_CAMERAS], range[CALIB_PLAN_MAX_CAMERAS];
    int    cls[CALIB_PLAN_MAX_CAMERAS];
    int   *cells[CALIB_PLAN_MAX_CAMERAS];   // the imager cells its corners cover (indices)
    int    ncells[CALIB_PLAN_MAX_CAMERAS];
} cand_t;

typedef struct {
    const calib_geometry_plan_opts_t *o;
    double  centre[3];                  // the corner grid's centre (scene frame)
    int     nx[CALIB_PLAN_MAX_CAMERAS], ny[CALIB_PLAN_MAX_CAMERAS];
    double  R[CALIB_PLAN_MAX_CAMERAS][9], t[CALIB_PLAN_MAX_CAMERAS][3];   // camera <- rig
    model_vec3_t camc[CALIB_PLAN_MAX_CAMERAS];
    cand_t *c;
    int     nc;
    int    *count[CALIB_PLAN_MAX_CAMERAS];   // per cell: chosen views covering it
} plan_t;

calib_geometry_plan_opts_t calib_geometry_plan_defaults(void)
{
    return (calib_geometry_plan_opts_t){ .corners_w = 10, .corners_h = 10, .square_mm = 30,
                                         .wedges_deg = { 20, 35, 50 }, .nwedges = 3,
                                         .azimuths_deg = { 0, 90, 180, 270 }, .nazimuths = 4,
                                         .angle_step_deg = 10, .max_obliquity_deg = 60, .margin_px = 10,
                                         .min_square_px = 12, .max_views = 30, .min_flat_views = 2,
                                         .min_views = 10, .min_shared = 6 };
}

// The board's pose: x_rig = Rz(angle) (Rw x + tw).
static void board_pose(const plan_t *P, double tilt, double az, double angle, double R[9], double t[3])
{
    double Rw[9], tw[3], a = angle * M_PI / 180, c = cos(a), s = sin(a);
    model_scene_wedge_pose(P->o->board, tilt, az, Rw, tw);
    const double Rz[9] = { c, -s, 0, s, c, 0, 0, 0, 1 };
    m3_mul(R, Rz, Rw);
    m3_vec(t, Rz, tw);
}

// Point (i, j) of the corner grid (i, j may lie beyond it: -1 and W are the squares' outer edge).
static model_vec3_t grid_point(const plan_t *P, double i, double j, const double R[9], const double t[3])
{
    const calib_geometry_plan_opts_t *o = P->o;
    double x[3] = { P->centre[0] + (i - (o->corners_w - 1) / 2.0) * o->square_mm,
                    P->centre[1] + (j - (o->corners_h - 1) / 2.0) * o->square_mm, P->centre[2] }, y[3];
    m3_vec(y, R, x);
    return v3(y[0] + t[0], y[1] + t[1], y[2] + t[2]);
}

// The ring of grid points around the grid (lo..hi in both, in steps of one square from lo) in
// order; n points.
static int ring(const plan_t *P, double lo_i, double hi_i, double lo_j, double hi_j, const double R[9],
                const double t[3], model_vec3_t *out)
{
    int n = 0, ni = (int)lround(hi_i - lo_i), nj = (int)lround(hi_j - lo_j);
    for (int i = 0; i < ni; i++) out[n++] = grid_point(P, lo_i + i, lo_j, R, t);
    for (int j = 0; j < nj; j++) out[n++] = grid_point(P, hi_i, lo_j + j, R, t);
    for (int i = 0; i < ni; i++) out[n++] = grid_point(P, hi_i - i, hi_j, R, t);
    for (int j = 0; j < nj; j++) out[n++] = grid_point(P, lo_i, hi_j - j, R, t);
    return n;
}

static bool inside(const double *poly, int n, double x, double y)
{
    bool in = false;
    for (int i = 0, j = n - 1; i < n; j = i++) {
        double xi = poly[2 * i], yi = poly[2 * i + 1], xj = poly[2 * j], yj = poly[2 * j + 1];
        if ((yi > y) != (yj > y) && x < (xj - xi) * (y - yi) / (yj - yi) + xi) in = !in;
    }
    return in;
}

// The cells inside a polygon of projected points.
static int *cells_of(const plan_t *P, int k, const double *poly, int n, int *ncells)
{
    const model_camera_t *cam = P->o->cams[k];
    double W = model_camera_width(cam), H = model_camera_height(cam);
    int *cells = malloc(sizeof(int) * (size_t)(P->nx[k] * P->ny[k]));
    *ncells = 0;
    if (!cells) return NULL;
    for (int cy = 0; cy < P->ny[k]; cy++)
        for (int cx = 0; cx < P->nx[k]; cx++)
            if (inside(poly, n, (cx + 0.5) * W / P->nx[k] - 0.5, (cy + 0.5) * H / P->ny[k] - 0.5))
                cells[(*ncells)++] = cy * P->nx[k] + cx;
    return cells;
}

// Camera k's view of a candidate: usable or not, and its covered cells. false: out of memory
// or a projection that failed.
static bool view(plan_t *P, cand_t *c, int k)
{
    const calib_geometry_plan_opts_t *o = P->o;
    const model_camera_t *cam = o->cams[k];
    const int W = o->corners_w, H = o->corners_h, nmax = 2 * (W + H + 4);
    double R[9], t[3];
    board_pose(P, c->tilt, c->az, c->angle, R, t);
    model_vec3_t edge[nmax], inner[nmax], bc = grid_point(P, (W - 1) / 2.0, (H - 1) / 2.0, R, t);
    int ne = ring(P, -EDGE, W - 1 + EDGE, -EDGE, H - 1 + EDGE, R, t, edge);
    int ni = ring(P, 0, W - 1, 0, H - 1, R, t, inner);
    for (int i = 0; i < ne; i++) {   // in front of the camera
        double p[3] = { edge[i].x, edge[i].y, edge[i].z }, q[3];
        m3_vec(q, P->R[k], p);
        if (q[2] + P->t[k][2] <= 1) return true;
    }
    double n_w[3] = { R[2], R[5], R[8] }, d[3] = { P->camc[k].x - bc.x, P->camc[k].y - bc.y, P->camc[k].z - bc.z };
    double dist = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
    double obl = acos(fmax(-1, fmin(1, (n_w[0] * d[0] + n_w[1] * d[1] + n_w[2] * d[2]) / dist))) * 180 / M_PI;
    c->obliq[k] = obl;
    c->range[k] = dist;
    if (obl > o->max_obliquity_deg) return true;
    double qe[2 * nmax], qi[2 * nmax];
    if (!model_camera_project(cam, edge, ne, qe) || !model_camera_project(cam, inner, ni, qi)) return false;
    double m = o->margin_px, Wpx = model_camera_width(cam), Hpx = model_camera_height(cam);
    for (int i = 0; i < ne; i++)
        if (!(qe[2 * i] >= m - 0.5 && qe[2 * i] <= Wpx - 0.5 - m && qe[2 * i + 1] >= m - 0.5 &&
              qe[2 * i + 1] <= Hpx - 0.5 - m))
            return true;
    for (int i = 0; i < ni; i++) {   // the smallest square along the ring
        int j = (i + 1) % ni;
        if (hypot(qi[2 * j] - qi[2 * i], qi[2 * j + 1] - qi[2 * i + 1]) < o->min_square_px) return true;
    }
    // the orientation: the normal's part across the line of sight, in the camera frame
    double nc[3], dc[3], u[3] = { -d[0] / dist, -d[1] / dist, -d[2] / dist };
    m3_vec(nc, P->R[k], n_w);
    m3_vec(dc, P->R[k], u);
    double nd = nc[0] * dc[0] + nc[1] * dc[1] + nc[2] * dc[2], px = nc[0] - nd * dc[0], py = nc[1] - nd * dc[1];
    c->cls[k] = obl < HEAD_ON_DEG ? 0 : fabs(px) >= fabs(py) ? (px < 0 ? 1 : 2) : (py < 0 ? 3 : 4);
    c->cells[k] = cells_of(P, k, qi, ni, &c->ncells[k]);
    if (!c->cells[k]) return false;
    c->usable[k] = true;
    return true;
}

static bool add_candidate(plan_t *P, double tilt, double az, double angle)
{
    cand_t *c = &P->c[P->nc++];
    memset(c, 0, sizeof *c);
    c->tilt = tilt, c->az = az, c->angle = angle;
    for (int k = 0; k < P->o->ncams; k++)
        if (!view(P, c, k)) {
            model_error_set(NULL, 0, "%s", model_last_error()[0] ? model_last_error() : "out of memory");
            return false;
        }
    return true;
}

static bool setup(plan_t *P, const calib_geometry_plan_opts_t *o)
{
    memset(P, 0, sizeof *P);
    P->o = o;
    if (o->ncams < 1 || o->ncams > CALIB_PLAN_MAX_CAMERAS || !o->board || o->board->nvertices < 3 ||
        o->corners_w < 2 || o->corners_h < 2 || !(o->square_mm > 0) || !(o->angle_step_deg > 0)) {
        model_error_set(NULL, 0, "the geometry plan needs 1..%d camera models, a board scene and its grid",
                        CALIB_PLAN_MAX_CAMERAS);
        return false;
    }
    double lo[2] = { INFINITY, INFINITY }, hi[2] = { -INFINITY, -INFINITY }, top = -INFINITY;
    for (int i = 0; i < o->board->nvertices; i++) {
        model_vec3_t v = o->board->vertices[i];
        lo[0] = fmin(lo[0], v.x), hi[0] = fmax(hi[0], v.x), lo[1] = fmin(lo[1], v.y), hi[1] = fmax(hi[1], v.y);
        top = fmax(top, v.z);
    }
    P->centre[0] = (lo[0] + hi[0]) / 2, P->centre[1] = (lo[1] + hi[1]) / 2, P->centre[2] = top;
    for (int k = 0; k < o->ncams; k++) {
        double rt[6];
        model_camera_rt_cam_world(o->cams[k], rt);
        R_from_r(P->R[k], rt);
        memcpy(P->t[k], rt + 3, sizeof P->t[k]);
        P->camc[k] = model_camera_centre_world(o->cams[k]);
        P->nx[k] = CELLS_X;
        P->ny[k] = (int)fmax(1, round(CELLS_X * (double)model_camera_height(o->cams[k]) /
                                      model_camera_width(o->cams[k])));
        P->count[k] = calloc((size_t)(P->nx[k] * P->ny[k]), sizeof(int));
        if (!P->count[k]) {
            model_error_set(NULL, 0, "out of memory");
            return false;
        }
    }
    return true;
}

static void plan_free(plan_t *P)
{
    for (int i = 0; i < P->nc; i++)
        for (int k = 0; k < P->o->ncams; k++) free(P->c[i].cells[k]);
    free(P->c);
    for (int k = 0; k < CALIB_PLAN_MAX_CAMERAS; k++) free(P->count[k]);
}

static bool candidates(plan_t *P)
{
    const calib_geometry_plan_opts_t *o = P->o;
    int na = (int)ceil(360 / o->angle_step_deg - 1e-9);
    P->c = calloc((size_t)(na * (1 + o->nwedges * o->nazimuths)), sizeof *P->c);
    if (!P->c) return model_error_set(NULL, 0, "out of memory"), false;
    for (int a = 0; a < na; a++)
        if (!add_candidate(P, 0, 0, a * o->angle_step_deg)) return false;
    for (int w = 0; w < o->nwedges; w++)
        for (int z = 0; z < o->nazimuths; z++)
            for (int a = 0; a < na; a++)
                if (!add_candidate(P, o->wedges_deg[w], o->azimuths_deg[z], a * o->angle_step_deg)) return false;
    return true;
}

static double gain(const plan_t *P, const cand_t *c, int only)
{
    double g = 0;
    for (int k = 0; k < P->o->ncams; k++) {
        if (!c->usable[k] || (only >= 0 && k != only)) continue;
        for (int i = 0; i < c->ncells[k]; i++) {
            double n = P->count[k][c->cells[k][i]] + 1;
            g += 1 / (n * n);
        }
    }
    return g;
}

static int first_cam(const plan_t *P, const cand_t *c)
{
    for (int k = 0; k < P->o->ncams; k++)
        if (c->usable[k]) return k;
    return -1;
}

static void choose(plan_t *P, cand_t *c, calib_geometry_plan_t *out)
{
    c->chosen = true;
    out->nviews++;
    for (int k = 0; k < P->o->ncams; k++)
        if (c->usable[k])
            for (int i = 0; i < c->ncells[k]; i++) P->count[k][c->cells[k][i]]++;
}

static void unchoose(plan_t *P, cand_t *c, calib_geometry_plan_t *out)
{
    c->chosen = false;
    out->nviews--;
    for (int k = 0; k < P->o->ncams; k++)
        if (c->usable[k])
            for (int i = 0; i < c->ncells[k]; i++) P->count[k][c->cells[k][i]]--;
}

// The best unchosen candidate passing the filter (cls: orientation class at its first camera, -1 any;
// tilt0: flat only; group: same tilt and azimuth as g; cam: usable by it, -1 any; shared_with0: camera 0
// too). NULL when none adds anything.
typedef struct { int cls; bool flat; const cand_t *group; int cam; bool shared; } filter_t;
static cand_t *best(plan_t *P, filter_t f)
{
    cand_t *b = NULL;
    double bg = 1e-9;
    for (int i = 0; i < P->nc; i++) {
        cand_t *c = &P->c[i];
        int k0 = first_cam(P, c);
        if (c->chosen || k0 < 0 || (f.cls >= 0 && c->cls[k0] != f.cls) || (f.flat && c->tilt != 0) ||
            (f.group && (c->tilt != f.group->tilt || c->az != f.group->az)) || (f.cam >= 0 && !c->usable[f.cam]) ||
            (f.shared && !c->usable[0]))
            continue;
        double g = gain(P, c, f.cam >= 0 && !f.shared ? f.cam : -1) + (f.group || f.cam >= 0 ? 1e-6 : 0);
        if (g > bg) bg = g, b = c;
    }
    return b;
}

static void greedy(plan_t *P, calib_geometry_plan_t *out)
{
    const calib_geometry_plan_opts_t *o = P->o;
    int taken[NCLASS] = { 0 };
    for (int n = 0; n < o->min_flat_views; n++) {
        cand_t *c = best(P, (filter_t){ .cls = -1, .flat = true, .cam = -1 });
        if (!c) break;
        choose(P, c, out);
        taken[c->cls[first_cam(P, c)]]++;
    }
    while (out->nviews < o->max_views * o->ncams) {
        cand_t *pick = NULL;
        int cls = -1;
        for (int k = 0; k < NCLASS; k++) {   // the class with the fewest views that still has a candidate
            if (cls >= 0 && taken[k] >= taken[cls]) continue;
            cand_t *c = best(P, (filter_t){ .cls = k, .cam = -1 });
            if (c) pick = c, cls = k;
        }
        if (!pick) break;
        choose(P, pick, out);
        taken[cls]++;
    }
    for (int i = 0; i < P->nc; i++) {   // every group two angles at least (the axis fit), within max_views
        cand_t *c = &P->c[i];
        if (!c->chosen) continue;
        int n = 0;
        for (int j = 0; j < P->nc; j++) n += P->c[j].chosen && P->c[j].tilt == c->tilt && P->c[j].az == c->az;
        if (n >= 2) continue;
        cand_t *m = out->nviews < o->max_views * o->ncams ? best(P, (filter_t){ .cls = -1, .group = c, .cam = -1 })
                                                          : NULL;
        if (m) choose(P, m, out);
        else unchoose(P, c, out);
    }
    for (int k = 0; k < o->ncams; k++) {   // each camera's views, and those it shares with camera 0
        for (;;) {
            int nk = 0, ns = 0;
            for (int i = 0; i < P->nc; i++) {
                nk += P->c[i].chosen && P->c[i].usable[k];
                ns += P->c[i].chosen && P->c[i].usable[k] && P->c[i].usable[0];
            }
            cand_t *c = nk < o->min_views ? best(P, (filter_t){ .cls = -1, .cam = k })
                        : k > 0 && ns < o->min_shared ? best(P, (filter_t){ .cls = -1, .cam = k, .shared = true })
                                                      : NULL;
            if (!c) break;
            choose(P, c, out);
        }
    }
}

static int cmp_cand(const void *a, const void *b)
{
    const cand_t *x = *(const cand_t *const *)a, *y = *(const cand_t *const *)b;
    if (x->tilt != y->tilt) return x->tilt < y->tilt ? -1 : 1;
    if (x->az != y->az) return x->az < y->az ? -1 : 1;
    return (x->angle > y->angle) - (x->angle < y->angle);
}

// The chosen views as --tilts text, grouped by tilt and azimuth.
static char *tilts_text(const plan_t *P)
{
    const cand_t **v = malloc(sizeof *v * (size_t)(P->nc + 1));
    int n = 0;
    if (!v) return NULL;
    for (int i = 0; i < P->nc; i++)
        if (P->c[i].chosen) v[n++] = &P->c[i];
    qsort(v, (size_t)n, sizeof *v, cmp_cand);
    GString *s = g_string_new("");
    for (int i = 0; i < n; i++) {
        bool head = i == 0 || v[i]->tilt != v[i - 1]->tilt || v[i]->az != v[i - 1]->az;
        if (head && i) g_string_append_c(s, ' ');
        if (head && v[i]->tilt == 0) g_string_append(s, "0:");
        else if (head) g_string_append_printf(s, "%g@%g:", v[i]->tilt, v[i]->az);
        else g_string_append_c(s, ',');
        g_string_append_printf(s, "%g", v[i]->angle);
    }
    free(v);
    return g_string_free(s, FALSE);
}

static void figures(const plan_t *P, calib_geometry_plan_t *out)
{
    for (int k = 0; k < P->o->ncams; k++) {
        int ncell = P->nx[k] * P->ny[k], cov = 0, all = 0;
        char *any = calloc((size_t)ncell, 1);
        out->obliquity_min_deg[k] = out->range_min_mm[k] = INFINITY;
        out->obliquity_max_deg[k] = out->range_max_mm[k] = -INFINITY;
        for (int i = 0; i < P->nc; i++) {
            const cand_t *c = &P->c[i];
            if (!c->usable[k]) continue;
            for (int j = 0; any && j < c->ncells[k]; j++) any[c->cells[k][j]] = 1;
            if (!c->chosen) continue;
            out->views[k]++;
            out->shared[k] += c->usable[0];
            out->classes[k][c->cls[k]]++;
            out->obliquity_min_deg[k] = fmin(out->obliquity_min_deg[k], c->obliq[k]);
            out->obliquity_max_deg[k] = fmax(out->obliquity_max_deg[k], c->obliq[k]);
            out->range_min_mm[k] = fmin(out->range_min_mm[k], c->range[k]);
            out->range_max_mm[k] = fmax(out->range_max_mm[k], c->range[k]);
        }
        for (int j = 0; j < ncell; j++) cov += P->count[k][j] > 0, all += any && any[j];
        out->coverage[k] = (double)cov / ncell;
        out->coverage_all[k] = (double)all / ncell;
        free(any);
    }
}

bool calib_geometry_plan(const calib_geometry_plan_opts_t *o, calib_geometry_plan_t *out)
{
    memset(out, 0, sizeof *out);
    plan_t P;
    bool ok = setup(&P, o) && candidates(&P);
    for (int i = 0; ok && i < P.nc; i++) out->nusable += first_cam(&P, &P.c[i]) >= 0;
    out->ncandidates = P.nc;
    for (int k = 0; ok && k < o->ncams; k++) {
        bool any = false;
        for (int i = 0; i < P.nc && !any; i++) any = P.c[i].usable[k];
        if (!any) {
            model_error_set(NULL, 0, "camera %d sees the whole board in none of the %d candidate poses (wedges, "
                            "azimuths, angles every %g deg): check its model's pose (rt_cam_ref in the rig frame) "
                            "and the board's place, or allow more obliquity", k + 1, P.nc, o->angle_step_deg);
            ok = false;
        }
    }
    if (ok) {
        greedy(&P, out);
        figures(&P, out);
        ok = (out->tilts = tilts_text(&P)) != NULL;
        if (!ok) model_error_set(NULL, 0, "out of memory");
    }
    plan_free(&P);
    return ok;
}

void calib_geometry_plan_free(calib_geometry_plan_t *p)
{
    if (p) g_free(p->tilts);
}

bool calib_geometry_plan_coverage(const calib_geometry_plan_opts_t *o, const char *tilts, double *coverage,
                                  int *views)
{
    plan_t P;
    calib_geometry_plan_t out = { 0 };
    gchar **specs = g_strsplit_set(tilts, " \t", -1);
    int n = 0;
    for (int i = 0; specs[i]; i++) n += (int)strlen(specs[i]) + 1;
    bool ok = setup(&P, o) && (P.c = calloc((size_t)n + 1, sizeof *P.c)) != NULL;
    for (int i = 0; ok && specs[i]; i++) {
        if (!specs[i][0]) continue;
        double tilt = 0, az = 0, a;
        char *colon = strchr(specs[i], ':'), *at = strchr(specs[i], '@');
        if (!colon) ok = false;
        else {
            *colon = 0;
            if (at) *at = 0;
            ok = model_parse_double(specs[i], &tilt) && (!at || model_parse_double(at + 1, &az));
            gchar **as = g_strsplit(colon + 1, ",", -1);
            for (int j = 0; ok && as[j]; j++)
                if ((ok = model_parse_double(as[j], &a))) {
                    ok = add_candidate(&P, tilt, az, a);
                    if (ok) choose(&P, &P.c[P.nc - 1], &out);
                }
            g_strfreev(as);
        }
        if (!ok && !model_last_error()[0]) model_error_set(NULL, 0, "'%s': not TILT[@AZ]:A,A,...", specs[i]);
    }
    if (ok) {
        figures(&P, &out);
        for (int k = 0; k < o->ncams; k++) {
            coverage[k] = out.coverage[k];
            if (views) views[k] = out.views[k];
        }
    }
    g_strfreev(specs);
    if (P.o) plan_free(&P);
    return ok;
}

const char *calib_geometry_plan_class_name(int k) { return k >= 0 && k < NCLASS ? class_names[k] : "?"; }

model_camera_t *calib_geometry_plan_guess_camera(int W, int H, double f_px, const double C[3])
{
    double d = sqrt(C[0] * C[0] + C[1] * C[1] + C[2] * C[2]), hz = hypot(C[0], C[1]);
    if (W < 2 || H < 2 || !(f_px > 0) || !(d > 0) || !(hz > 1e-6 * d)) {
        model_error_set(NULL, 0, "a camera guess needs W, H >= 2 px, a focal length > 0 px and a centre off the "
                        "turntable's axis (it looks at the rig origin, its image x horizontal)");
        return NULL;
    }
    double z[3] = { -C[0] / d, -C[1] / d, -C[2] / d }, x[3] = { z[1], -z[0], 0 }, y[3], R[9], rt[6];
    double nx = hypot(x[0], x[1]);
    x[0] /= nx, x[1] /= nx;
    cross3(y, z, x);
    for (int k = 0; k < 3; k++) R[k] = x[k], R[3 + k] = y[k], R[6 + k] = z[k];
    r_from_R(rt, R);
    double t[3];
    m3_vec(t, R, C);
    rt[3] = -t[0], rt[4] = -t[1], rt[5] = -t[2];
    const double intr[4] = { f_px, f_px, (W - 1) / 2.0, (H - 1) / 2.0 };
    return model_camera_new("LENSMODEL_PINHOLE", intr, W, H, rt);
}
