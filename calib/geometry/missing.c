// calib/geometry/missing.c — why a view has no board: its pose predicted from the
// axis and its group's first pose, and what that pose shows the camera.
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "calib/geometry/internal.h"

// Why a view in a group with poses has no board: predict the board's pose from
// the group's first pose turned about the axis, and look at it.
bool calib_geometry_explain_missing(calib_geometry_views_t *vs, const calib_board_t *bd,
                                    const calib_geometry_axis_t *ax, model_camera_t *cam, int W, int H)
{
    const double square_mm = bd->spacing_mm;
    // the squares' corners, outer edge included (mrgingham needs every square)
    int nex = bd->width_n + 2, ney = bd->height_n + 2, M = nex * ney;
    model_vec3_t *p = malloc(M * sizeof *p);
    double *q = malloc(2 * M * sizeof *q);
    bool ok = p && q;
    if (!ok) model_error_set(NULL, 0, "out of memory");
    // the sign of normal . (to camera) on the found views
    double sgn = 0;
    for (guint i = 0; i < vs->v->len && sgn == 0; i++) {
        calib_geometry_view_t *v = g_ptr_array_index(vs->v, i);
        if (!v->solved || v->camera != 0) continue;
        double R[9];
        pose_R(R, v);
        double n[3] = { R[2], R[5], R[8] };
        double c[3], tc[3];
        board_centre(bd, c);
        m3_vec(tc, R, c);
        for (int k = 0; k < 3; k++) tc[k] = -(tc[k] + v->rt_cam_board[3 + k]);
        sgn = dot3(n, tc) > 0 ? 1 : -1;
    }
    for (guint i = 0; ok && i < vs->v->len; i++) {
        calib_geometry_view_t *v = g_ptr_array_index(vs->v, i);
        if (v->found) continue;
        if (!v->why[0])
            snprintf(v->why, sizeof v->why, "no %dx%d board found", bd->width_n, bd->height_n);
        if (!ax || !ax->ok || v->group < 0 || v->camera != 0 || !isfinite(v->angle_deg)) continue;
        calib_geometry_view_t **l;
        int n = geo_group_views(vs, v->group, &l);
        ok = n >= 0;
        if (n <= 0) {
            free(l);
            continue;
        }
        calib_geometry_view_t *ref = l[0];
        free(l);
        double d = wrap_deg(v->angle_deg - ref->angle_deg) * DEG;
        double r[3] = { d * ax->a[0], d * ax->a[1], d * ax->a[2] }, Rrot[9], Rref[9], R[9], t[3], tc[3];
        R_from_r(Rrot, r);
        pose_R(Rref, ref);
        m3_mul(R, Rrot, Rref);
        for (int k = 0; k < 3; k++) tc[k] = ref->rt_cam_board[3 + k] - ax->c[k];
        m3_vec(t, Rrot, tc);
        for (int k = 0; k < 3; k++) t[k] += ax->c[k];
        for (int jj = 0; jj < ney; jj++)
            for (int ii = 0; ii < nex; ii++) {
                double b[3] = { (ii - 1) * square_mm, (jj - 1) * square_mm, 0 }, x[3];
                m3_vec(x, R, b);
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
        m3_vec(pc, R, cc);
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
    }
    free(p);
    free(q);
    return ok;
}
