// calib/geometry_diff.c — how far two camera models project apart over the
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
#include <math.h>
#include <mrcal/mrcal.h>
#include <mrcal/poseutils.h>
#include <stdlib.h>
#include <string.h>

#include "calib/geometry.h"
#include "model/lsq.h"
#include "model/model.h"

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
