// calib/geometry/axis.c — the turntable axis in closed form from the board poses of
// each tilt group: the corner orders made consistent by quarter turns, the
// direction from the pairs' relative rotations, the point by least squares.
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
#include <glib.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "calib/geometry/internal.h"

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
    m3_vec(Rzc, Rz, c);
    for (int i = 0; i < 3; i++) d[i] = c[i] - Rzc[i];
    m3_vec(Rd, R, d);
    double Rn[9];
    m3_mul(Rn, R, Rz);
    r_from_R(rt, Rn);
    for (int i = 0; i < 3; i++) rt[3 + i] += Rd[i];
}

static int cmp_angle(const void *a, const void *b)
{
    const calib_geometry_view_t *x = *(calib_geometry_view_t *const *)a, *y = *(calib_geometry_view_t *const *)b;
    return (x->angle_deg > y->angle_deg) - (x->angle_deg < y->angle_deg);
}

int geo_group_views(const calib_geometry_views_t *vs, int g, calib_geometry_view_t ***out)
{
    calib_geometry_view_t **l = malloc(vs->v->len * sizeof *l + 1);
    int n = 0;
    *out = l;
    if (!l) {
        model_error_set(NULL, 0, "out of memory");
        return -1;
    }
    for (guint i = 0; i < vs->v->len; i++) {
        calib_geometry_view_t *v = g_ptr_array_index(vs->v, i);
        if (v->group == g && v->camera == 0 && v->solved && isfinite(v->angle_deg)) l[n++] = v;
    }
    qsort(l, n, sizeof *l, cmp_angle);
    return n;
}

// A pair of views of one group whose turntable angles differ by 5..175 deg:
// the step d (rad), the relative rotation Rrel = Rj Ri^T and its rotation vector.
typedef struct {
    const calib_geometry_view_t *vi, *vj;
    double        d, Rrel[9], r[3];
} view_pair_t;

// Every such pair of every group (caller frees *out); *nviews: the views of
// groups with two or more. -1 + message when out of memory.
static int view_pairs(const calib_geometry_views_t *vs, view_pair_t **out, int *nviews)
{
    int np = 0, cap = 0;
    view_pair_t *p = NULL;
    *out = NULL;
    for (int g = 0; g < vs->ngroups; g++) {
        calib_geometry_view_t **l;
        int n = geo_group_views(vs, g, &l);
        if (n < 0) {
            free(p);
            return -1;
        }
        for (int i = 0; i < n; i++)
            for (int j = i + 1; j < n; j++) {
                double d = wrap_deg(l[j]->angle_deg - l[i]->angle_deg) * DEG;
                if (fabs(d) < 5 * DEG || fabs(d) > 175 * DEG) continue;
                if (np == cap) {
                    cap = cap ? 2 * cap : 64;
                    view_pair_t *q = realloc(p, (size_t)cap * sizeof *q);
                    if (!q) {
                        model_error_set(NULL, 0, "out of memory");
                        free(l);
                        free(p);
                        return -1;
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
                m3_mul_bt(e->Rrel, Rj, Ri);
                r_from_R(e->r, e->Rrel);
            }
        if (n >= 2) *nviews += n;
        free(l);
    }
    *out = p;
    return np;
}

// Step 1: group g's poses made consistent with its first by the turn of the
// board's corner order (k quarter turns, k a multiple of step) whose rotation
// relative to the first matches the turntable's angle; a view no turn makes
// consistent (by 2 deg) loses its pose. false + message when out of memory.
static bool align_group_turns(calib_geometry_views_t *vs, int g, const calib_board_t *bd, int step)
{
    calib_geometry_view_t **l;
    int n = geo_group_views(vs, g, &l);
    if (n < 0) return false;
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
            m3_mul_bt(Rrel, R, Rref);
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
            model_warning("%s: its pose turns %.2f deg more or less than the turntable "
                          "(%.3f deg) relative to %s; left out of the axis fit", l[m]->name, best, d, l[0]->name);
            snprintf(l[m]->why, sizeof l[m]->why, "pose inconsistent with the turntable angle by %.2f deg", best);
            l[m]->solved = false;
        }
    }
    free(l);
    return true;
}

// Step 2: the direction (the pairs' rotation vectors weighted by their steps)
// and the point (the pairs' equations and a . c = 0, normal equations A c = b;
// Ai = A^-1) from every pair; *dev2, *wsum: the pairs' squared deviations from
// the direction, weighted, and the weights. false when there is no pair or A
// is singular, false + message when out of memory.
static bool axis_from_pairs(calib_geometry_views_t *vs, calib_geometry_axis_t *ax, double Ai[9], double *dev2,
                            double *wsum)
{
    view_pair_t *pairs = NULL;
    ax->npairs = view_pairs(vs, &pairs, &ax->nviews);
    if (ax->npairs <= 0) {
        ax->npairs = 0;
        free(pairs);
        return false;
    }
    double S[3] = { 0 };
    for (int q = 0; q < ax->npairs; q++)
        for (int k = 0; k < 3; k++) S[k] += pairs[q].d * pairs[q].r[k];
    double sn = norm3(S);
    for (int k = 0; k < 3; k++) ax->a[k] = S[k] / sn;
    double A[9] = { 0 }, b[3] = { 0 };
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++) A[i * 3 + j] = ax->a[i] * ax->a[j];
    for (int q = 0; q < ax->npairs; q++) {
        const double d = pairs[q].d, *Rrel = pairs[q].Rrel, *r = pairs[q].r;
        const calib_geometry_view_t *vi = pairs[q].vi, *vj = pairs[q].vj;
        double ap[3] = { r[0] / d, r[1] / d, r[2] / d }, an = norm3(ap);
        double cs = dot3(ap, ax->a) / an;
        double dv = acos(cs > 1 ? 1 : cs < -1 ? -1 : cs);
        *dev2 += d * d * dv * dv;
        *wsum += d * d;
        double M[9], rhs[3], Rti[3];
        for (int k = 0; k < 9; k++) M[k] = (k % 4 == 0 ? 1.0 : 0.0) - Rrel[k];
        m3_vec(Rti, Rrel, &vi->rt_cam_board[3]);
        for (int k = 0; k < 3; k++) rhs[k] = vj->rt_cam_board[3 + k] - Rti[k];
        for (int p = 0; p < 3; p++) {
            for (int c = 0; c < 3; c++)
                for (int k = 0; k < 3; k++) A[p * 3 + c] += M[k * 3 + p] * M[k * 3 + c];
            for (int k = 0; k < 3; k++) b[p] += M[k * 3 + p] * rhs[k];
        }
    }
    free(pairs);
    if (!m3_inv(Ai, A)) return false;
    m3_vec(ax->c, Ai, b);
    return true;
}

// Step 3, one group: each view's rotation about the axis relative to the
// group's first (into ax->fit when the group has two views or more), the
// rotation off the axis (*off2, *noff) and the point equations' residuals
// (*e2, *ne). false + message when out of memory.
static bool group_residuals(calib_geometry_views_t *vs, int g, calib_geometry_axis_t *ax, double *off2, int *noff,
                            double *e2, int *ne)
{
    calib_geometry_view_t **l;
    int n = geo_group_views(vs, g, &l);
    if (n < 0) return false;
    json_t *ang = json_array(), *rot = json_array();
    double Rref[9];
    if (n) pose_R(Rref, l[0]);
    for (int i = 0; i < n; i++) {
        double Ri[9], Rrel[9], r[3];
        pose_R(Ri, l[i]);
        m3_mul_bt(Rrel, Ri, Rref);
        r_from_R(r, Rrel);
        double along = dot3(r, ax->a);
        double perp[3] = { r[0] - along * ax->a[0], r[1] - along * ax->a[1], r[2] - along * ax->a[2] };
        if (i > 0) {
            *off2 += dot3(perp, perp);
            (*noff)++;
            double M[9], Mc[3], Rti[3];
            for (int k = 0; k < 9; k++) M[k] = (k % 4 == 0 ? 1.0 : 0.0) - Rrel[k];
            m3_vec(Mc, M, ax->c);
            m3_vec(Rti, Rrel, &l[0]->rt_cam_board[3]);
            for (int k = 0; k < 3; k++) {
                double e = Mc[k] - (l[i]->rt_cam_board[3 + k] - Rti[k]);
                *e2 += e * e;
            }
            (*ne)++;
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
    return true;
}

bool calib_geometry_fit_axis(calib_geometry_views_t *vs, const calib_board_t *bd, calib_geometry_axis_t *ax)
{
    int step = board_turn_step(bd);
    memset(ax, 0, sizeof *ax);
    for (int g = 0; g < vs->ngroups; g++)
        if (!align_group_turns(vs, g, bd, step)) return false;
    double Ai[9], wsum = 0, dev2 = 0;
    if (!axis_from_pairs(vs, ax, Ai, &dev2, &wsum)) return false;
    // step 3: residuals of the point equations, and per-view rotation about / off the axis
    double e2 = 0, off2 = 0;
    int ne = 0, noff = 0;
    ax->fit = json_array();
    for (int g = 0; g < vs->ngroups; g++)
        if (!group_residuals(vs, g, ax, &off2, &noff, &e2, &ne)) return false;
    int dof = ax->nviews - vs->ngroups;
    ax->off_axis_rms_deg = noff ? sqrt(off2 / noff) / DEG : 0;
    ax->dir_unc_deg = (wsum > 0 ? sqrt(dev2 / wsum) : 0) / sqrt(dof > 1 ? dof : 1) / DEG;
    ax->point_rms_mm = ne ? sqrt(e2 / (3.0 * ne)) : 0;
    double tr = Ai[0] + Ai[4] + Ai[8], aAa = 0, Aa[3];
    m3_vec(Aa, Ai, ax->a);
    aAa = dot3(ax->a, Aa);
    ax->point_unc_mm = ax->point_rms_mm * sqrt(fmax(tr - aAa, 0) / 2);
    ax->ok = true;
    return true;
}
