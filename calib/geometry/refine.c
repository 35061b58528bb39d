// calib/geometry/refine.c — the turntable axis refined jointly with the board poses
// (calib_geometry_refine_axis), by least squares on the observed corners.
#include <glib.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "calib/geometry/internal.h"
#include "model/base/lsq.h"

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
    model_vec3_t   *x;                   // scratch (n; the grid's points while matching)
    double         *qp;                  // scratch (2 n; the grid's projections while matching)
    double         *res;                 // scratch (6 n: a residual vector and the Jacobian's two)
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
    m3_mul(R, Rot, Rg);
    for (int k = 0; k < 3; k++) d[k] = rt_g[3 + k] - c[k];
    m3_vec(t, Rot, d);
    for (int k = 0; k < 3; k++) t[k] += c[k];
}

static bool axj_eval(const axj_view_t *w, const double *p, const double *rt_g, double *res)
{
    double R[9], t[3];
    axj_pose(w, p, rt_g, R, t);
    for (int i = 0; i < w->n; i++) {
        double b[3] = { w->b[i].x, w->b[i].y, w->b[i].z }, x[3];
        m3_vec(x, R, b);
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
    double *res = w->res, ss = 0;
    if (axj_eval(w, p, rt_g, res))
        for (int k = 0; k < 2 * w->n; k++) ss += res[k] * res[k];
    else
        ss = INFINITY;
    return sqrt(ss / w->n) * sigma_px;
}

static bool axj_residual(void *ctx, const double *const *params, double *res, double **J)
{
    const axj_view_t *w = ctx;
    if (!axj_eval(w, params[0], params[1], res)) return false;
    if (!J) return true;
    int nr = 2 * w->n, sizes[2] = { 4, 6 };
    double *rp = w->res + nr, *rm = rp + nr, pp[2][6];
    bool ok = true;
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
    return ok;
}

// The board point of each corner v observed (nearest projection of the grid
// under v's pose, within a third of the spacing, one to one): w->b[k],
// w->q[2 k] for the k-th corner seen (ncorners of them; the order of v's q,
// those not seen left out; w's scratch holds the grid). 1 when they match, 0
// when not, -1 + message when out of memory.
static int axj_match(const calib_geometry_view_t *v, model_camera_t *cam, const calib_board_t *bd, axj_view_t *w)
{
    int N = bd->width_n * bd->height_n, W = bd->width_n;
    double s = bd->spacing_mm, *q = w->q, *qg = w->qp, R[9], spacing = INFINITY;
    model_vec3_t *b = w->b, *p = w->x;
    int *used = calloc(N, sizeof *used), n = 0;
    if (!used) {
        model_error_set(v->name, 0, "out of memory");
        return -1;
    }
    R_from_r(R, v->rt_cam_board);
    for (int j = 0; j < N; j++) {
        double bb[3] = { (j % W) * s, (j / W) * s, 0 }, x[3];
        m3_vec(x, R, bb);
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
    free(used);
    return ok && n == v->ncorners;
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
        w[i].res = malloc(6 * N * sizeof *w[i].res);
        if (!w[i].b || !w[i].x || !w[i].qp || !w[i].q || !w[i].res) {
            model_error_set(NULL, 0, "out of memory");
            return false;
        }
        w[i].inv_sigma = 1 / sigma_px;
        if (l[i]->q) w[i].n = l[i]->ncorners;
        int match = l[i]->q ? axj_match(l[i], cam, bd, &w[i]) : 0;
        if (match < 0) return false;
        if (!match) {
            model_warning("%s: its corners do not match its pose; left out of the joint "
                          "axis fit", l[i]->name);
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
    if (!rv || !sorted) model_error_set(NULL, 0, "out of memory");
    for (int g = 0; rv && sorted && g < ng; g++)
        for (int i = 0; ws[g] && i < cnt[g]; i++) {
            if (!ws[g][i].n) continue;
            rv[nr] = sorted[nr] = axj_view_rms(&ws[g][i], axp, &rt[6 * g], sigma_px);
            nr++;
        }
    qsort(sorted, nr, sizeof *sorted, model_cmp_double);
    double med = nr ? sorted[nr / 2] : 0, limit = fmax(2.0, 10 * med);
    bool ok = rv && sorted;
    nr = 0;
    *nused = 0;
    for (int g = 0; ok && g < ng; g++)
        for (int i = 0; ok && ws[g] && i < cnt[g]; i++) {
            if (!ws[g][i].n) continue;
            if (rv[nr] > limit) {
                model_warning("%s: its corners are %.1f px RMS from its group's board turned "
                              "to its turntable angle (%.3f deg; the views' median %.3f px): left out of the axis fit",
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

// After the fit: each view's corner RMS (px); *worst: the view of the largest,
// *wrms, *med the views' median. false + message when out of memory.
static bool views_rms(int ng, const int *cnt, axj_view_t **ws, calib_geometry_view_t ***lists, const double *axp,
                      const double *rt, double sigma_px, int nused, calib_geometry_view_t **worst, double *wrms,
                      double *med)
{
    double *rv = calloc(nused + 1, sizeof *rv);
    if (!rv) {
        model_error_set(NULL, 0, "out of memory");
        return false;
    }
    int nr = 0;
    *worst = NULL;
    *wrms = 0;
    for (int g = 0; g < ng; g++)
        for (int i = 0; ws[g] && i < cnt[g]; i++) {
            if (!ws[g][i].n) continue;
            rv[nr] = axj_view_rms(&ws[g][i], axp, &rt[6 * g], sigma_px);
            if (rv[nr] > *wrms) {
                *wrms = rv[nr];
                *worst = lists[g][i];
            }
            nr++;
        }
    qsort(rv, nr, sizeof *rv, model_cmp_double);
    *med = nr ? rv[nr / 2] : 0;
    free(rv);
    return true;
}

static void groups_free(int ng, const int *cnt, axj_view_t **ws, calib_geometry_view_t ***lists)
{
    for (int g = 0; g < ng; g++) {
        for (int i = 0; ws && ws[g] && i < cnt[g]; i++) {
            free(ws[g][i].b);
            free(ws[g][i].q);
            free(ws[g][i].x);
            free(ws[g][i].qp);
            free(ws[g][i].res);
        }
        if (ws) free(ws[g]);
        if (lists) free(lists[g]);
    }
    free(ws);
    free(lists);
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
    bool ok = p && rt && lists && cnt && ws;
    if (p && !ok) model_error_set(NULL, 0, "out of memory");   // (else lsq_problem_new's message)
    ok = ok && lsq_add_parameters(p, axp, 4);
    for (int g = 0; ok && g < ng; g++) {
        cnt[g] = geo_group_views(vs, g, &lists[g]);
        ok = cnt[g] >= 0;
        if (cnt[g] < 1) continue;   // a group of one view: its pose only (the rig frame's sigma from it)
        if (!(ws[g] = calloc(cnt[g], sizeof *ws[g]))) {
            model_error_set(NULL, 0, "out of memory");
            ok = false;
            break;
        }
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
        ok = views_rms(ng, cnt, ws, lists, axp, rt, sigma_px, nused, worst, wrms, med);
    }
    if (ok) {
        for (int g = 0; g < ng; g++)   // the poses as the fit has them: turned about the axis
            for (int i = 0; ws[g] && i < cnt[g]; i++) {
                double R[9], t[3];
                axj_pose(&ws[g][i], axp, &rt[6 * g], R, t);
                r_from_R(lists[g][i]->rt_cam_board, R);
                memcpy(&lists[g][i]->rt_cam_board[3], t, sizeof t);
            }
    }
    groups_free(cnt ? ng : 0, cnt, ws, lists);
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
    if (!rt0) {
        model_error_set(NULL, 0, "out of memory");
        return false;
    }
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
        model_warning("%s: its corners are %.2f px RMS from the joint axis fit (the views' "
                      "median %.3f px): its board is not where the turntable's angle puts it; left out of the axis fit",
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
