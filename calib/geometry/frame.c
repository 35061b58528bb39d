// calib/geometry/frame.c — the rig frame from the axis and the tilt-0 board
// (calib_geometry_rig_frame), and the rt algebra that carries poses into it.
//
// The rig frame recovered (see the help text): z along the fitted turntable
// axis (sign: counter-clockwise positive turntable angles, seen from +z);
// origin on the axis, board_height_mm below the board's corner plane at tilt 0
// (the table top); x the one of the board's four grid directions at angle 0,
// tilt 0 that is closest to the camera's +x (image right) once both are
// projected onto the table plane — so the board must lie square to the
// turntable's home orientation.
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "calib/geometry/internal.h"

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
    int n = geo_group_views(vs, g0, &l);
    if (n <= 0) {
        free(l);
        snprintf(why, whyn, "%s", n < 0 ? model_last_error() : "no board found at tilt 0");
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
            m3_vec(u0, Rb, u);
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
void geo_rt_compose(double out[6], const double ab[6], const double bc[6])
{
    double Rab[9], Rbc[9], R[9], t[3];
    R_from_r(Rab, ab);
    R_from_r(Rbc, bc);
    m3_mul(R, Rab, Rbc);
    m3_vec(t, Rab, &bc[3]);
    r_from_R(out, R);
    for (int k = 0; k < 3; k++) out[3 + k] = t[k] + ab[3 + k];
}
void geo_rt_invert(double out[6], const double rt[6])
{
    double R[9], Rt[9], t[3];
    R_from_r(R, rt);
    m3_transpose(Rt, R);
    m3_vec(t, Rt, &rt[3]);
    r_from_R(out, Rt);
    for (int k = 0; k < 3; k++) out[3 + k] = -t[k];
}
