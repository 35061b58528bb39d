// fit/verify/regions.c — the residue (the fitted model at every point, z, flags,
// statistics) and the change regions whose excess chi^2 is the score.
#define _GNU_SOURCE
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fit/verify/internal.h"

// The residue statistics of image's used points (image -1: of every image). false: out of memory.
static bool stats_of(const verify_point_t *pts, int n, int image, verify_stats_t *st)
{
    memset(st, 0, sizeof *st);
    double *d = malloc((size_t)(n ? n : 1) * sizeof *d), *z = malloc((size_t)(n ? n : 1) * sizeof *z);
    if (!d || !z) {
        free(d);
        free(z);
        return false;
    }
    double s1 = 0, s2 = 0, zz = 0;
    int m = 0;
    for (int k = 0; k < n; k++) {
        const verify_point_t *p = &pts[k];
        if (p->status != VERIFY_PT_USED || (image >= 0 && p->image != image)) continue;
        double diff = p->meas - p->model, a = fabs(diff);
        d[m] = diff;
        z[m] = fabs(p->z);
        m++;
        s1 += a;
        s2 += a * a;
        zz += (double)p->z * p->z;
        if (a > st->max_abs) st->max_abs = a;
    }
    st->npoints = m;
    if (m) {
        st->mean_abs = s1 / m;
        st->std_abs = sqrt(fmax(s2 / m - st->mean_abs * st->mean_abs, 0));
        st->rms_z = sqrt(zz / m);
        st->median_abs_z = model_median(z, m);
        double med = model_median(d, m);
        for (int k = 0; k < m; k++) d[k] = fabs(d[k] - med);
        st->robust_sigma = 1.4826 * model_median(d, m);
    }
    free(d);
    free(z);
    return true;
}

// The residue: the fitted model at every measured point (used and
// edge-measured), z and the flags; the status counts and the statistics.
bool verify_fit_residue(fit_t *F)
{
    verify_result_t *out = F->out;
    for (int k = 0; k < F->nfit; k++) {
        verify_point_t *p = &out->points[F->ptidx[k]];
        double r, *blocks[6];
        res_item_t it = { &F->rcs[F->pt[k].mat], F->pt[k].mat2 >= 0 ? &F->rcs[F->pt[k].mat2] : NULL, k };
        verify_fit_blocks(F, p->image, F->pt[k].mat, F->pt[k].mat2, blocks);
        verify_residual_fn(&it, (const double *const *)blocks, &r, NULL);
        p->model = (float)(F->pt[k].meas + r * F->pt[k].sigma);
        if (p->status == VERIFY_PT_USED) {
            p->z = (float)-r;   // (measured - model) / sigma, the sign of the difference images
            p->flag = fabs(r) > F->opt->z_flag;
        } else {
            p->flag = true;   // an unexpected edge: z holds z_flag * its std ratio
        }
    }
    for (int k = 0; k < F->npts; k++) out->nstatus[out->points[k].status]++;
    out->npoints = F->npts;
    bool ok = stats_of(out->points, F->npts, -1, &out->all);
    for (int m = 0; ok && m < F->nimgs; m++) ok = stats_of(out->points, F->npts, m, &out->per_image[m]);
    if (!ok) model_error(NULL, 0, "out of memory for the residue of %d reference points", F->npts);
    return ok;
}

// Grow region rid from grid point g0 of image m (points from base on) over
// 8-connected flags; stack: room for the image's points.
static void grow_region(verify_result_t *out, const verify_view_t *v, int m, int base, int g0, int rid, int *stack,
                        const verify_options_t *opt)
{
    verify_region_t *R = &out->regions[rid];
    memset(R, 0, sizeof *R);
    R->image = m;
    R->bbox[0] = R->bbox[1] = INFINITY;
    R->bbox[2] = R->bbox[3] = -INFINITY;
    int fc[64], fn[64], nf = 0;
    int top = 0;
    stack[top++] = g0;
    out->points[base + g0].region = rid;
    const double cap2 = 25 * opt->z_flag * opt->z_flag;
    while (top) {
        int g = stack[--top];
        verify_point_t *p = &out->points[base + g];
        R->npoints++;
        double z2 = fmin((double)p->z * p->z, cap2);
        R->excess_chi2 += fmax(z2 - opt->z_flag * opt->z_flag, 0);
        R->max_abs_z = fmax(R->max_abs_z, fabs(p->z));
        R->bbox[0] = fmin(R->bbox[0], p->q[0] - v->sp / 2.0);
        R->bbox[1] = fmin(R->bbox[1], p->q[1] - v->sp / 2.0);
        R->bbox[2] = fmax(R->bbox[2], p->q[0] + v->sp / 2.0);
        R->bbox[3] = fmax(R->bbox[3], p->q[1] + v->sp / 2.0);
        int f;
        for (f = 0; f < nf; f++)
            if (fc[f] == p->face) break;
        if (f == nf && nf < 64) {
            fc[nf] = p->face;
            fn[nf++] = 0;
        }
        if (f < 64) fn[f]++;
        int gi = g % v->gw, gj = g / v->gw;
        for (int dj = -1; dj <= 1; dj++)
            for (int di = -1; di <= 1; di++) {
                int ii = gi + di, jj = gj + dj;
                if (ii < 0 || jj < 0 || ii >= v->gw || jj >= v->gh) continue;
                verify_point_t *q2 = &out->points[base + jj * v->gw + ii];
                if (q2->flag && q2->region < 0) {
                    q2->region = rid;
                    stack[top++] = jj * v->gw + ii;
                }
            }
    }
    R->area_px = (double)R->npoints * v->sp * v->sp;
    R->counts = R->npoints >= opt->min_region;
    for (int t = 0; t < 4; t++) {
        int best = -1;
        for (int f = 0; f < nf; f++)
            if (fn[f] > 0 && (best < 0 || fn[f] > fn[best])) best = f;
        R->faces[t] = best >= 0 ? fc[best] : -1;
        R->face_points[t] = best >= 0 ? fn[best] : 0;
        if (best >= 0) fn[best] = 0;
    }
}

// Change detection: 8-connected flags on each image's grid are regions; the
// score sums the excess chi^2 of those of at least min_region points.
bool verify_fit_regions(fit_t *F)
{
    verify_result_t *out = F->out;
    int base = 0, cap = 0;
    int *stack = malloc((size_t)(F->npts ? F->npts : 1) * sizeof *stack);
    bool ok = stack != NULL;
    for (int m = 0; m < F->nimgs && ok; m++) {
        const verify_view_t *v = F->views[m];
        int n = v->gw * v->gh;
        for (int g0 = 0; g0 < n; g0++) {
            const verify_point_t *p0 = &out->points[base + g0];
            if (!p0->flag || p0->region >= 0) continue;
            if (out->nregions == cap) {
                cap = cap ? 2 * cap : 64;
                verify_region_t *nr = realloc(out->regions, (size_t)cap * sizeof *nr);
                if (!(ok = nr != NULL)) break;
                out->regions = nr;
            }
            int rid = out->nregions++;
            grow_region(out, v, m, base, g0, rid, stack, F->opt);
            if (out->regions[rid].counts) out->score += out->regions[rid].excess_chi2;
        }
        base += n;
    }
    free(stack);
    if (!ok) model_error(NULL, 0, "out of memory for the change regions");
    return ok;
}
