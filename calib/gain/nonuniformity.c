// calib/gain/nonuniformity.c — the spatial nonuniformity of EMVA 1288
// Release 4.0 Linear by the standard's definitions (the reference
// implementation's Data1288 / Results1288): a stack of L frames averaged,
// its temporal variance sigma^2_y.stack, the spatial variance of the
// average less the temporal part, its column, row and pixel parts, and
// from the dark and the light stacks DSNU1288 and PRNU1288 with their
// parts (calib/gain/gain.h).
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "calib/gain/internal.h"
#include "model/model.h"

bool calib_gain_stack_average(const calib_gain_data_t *d, const calib_gain_group_t *g, int w, int h, double *avg,
                              double *stack_var)
{
    const size_t n = (size_t)w * h;
    double *sum = calloc(n * 2, sizeof(double)), *sq = sum ? sum + n : NULL;
    if (!sum) {
        model_error_set(NULL, 0, "out of memory for the average of %d frames (%dx%d)", g->n, w, h);
        return false;
    }
    for (int k = 0; k < g->n; k++) {
        int fw, fh;
        float *img = gain_frame_load(&d->f[g->idx[k]], &fw, &fh);
        if (!img) {
            free(sum);
            return false;
        }
        if (fw != w || fh != h) {
            char nb[1024];
            model_error_set(NULL, 0, "%s: %dx%d pixels, the others of its set %dx%d",
                            gain_frame_name(&d->f[g->idx[k]], nb, sizeof nb), fw, fh, w, h);
            free(img);
            free(sum);
            return false;
        }
        for (size_t i = 0; i < n; i++) {
            sum[i] += img[i];
            sq[i] += (double)img[i] * img[i];
        }
        free(img);
    }
    const double L = g->n;
    for (size_t i = 0; i < n; i++) avg[i] = sum[i] / L;
    // each pixel's temporal variance (divisor L - 1) from L sum y^2 - (sum y)^2, exact for whole DN
    int r[4];
    gain_region(w, h, d->roi, r);
    double sv = 0;
    for (int y = r[1]; y < r[1] + r[3]; y++)
        for (int x = r[0]; x < r[0] + r[2]; x++) {
            size_t i = (size_t)y * w + x;
            sv += (L * sq[i] - sum[i] * sum[i]) / (L * (L - 1));
        }
    *stack_var = g->n >= 2 ? sv / ((double)r[2] * r[3]) : NAN;
    free(sum);
    return true;
}

bool calib_gain_stack_variances(const double *avg, int w, int h, const int roi[4], int L, double stack_var,
                                calib_gain_stack_var_t *o)
{
    int r[4];
    gain_region(w, h, roi, r);
    const int M = r[3], N = r[2];   // rows, columns (the standard's M and N)
    memset(o, 0, sizeof *o);
    o->L = L;
    o->M = M;
    o->N = N;
    o->stack_var = stack_var;
    double *colm = calloc((size_t)N + 1, sizeof(double)), s = 0;
    if (!colm) {
        model_error_set(NULL, 0, "out of memory for the spatial variances (%d columns)", N);
        return false;
    }
    for (int y = 0; y < M; y++)
        for (int x = 0; x < N; x++) s += avg[(size_t)(r[1] + y) * w + r[0] + x];
    const double mean = s / ((double)M * N);
    double ss = 0, rs = 0, cs = 0;
    for (int y = 0; y < M; y++) {
        double row = 0;
        for (int x = 0; x < N; x++) {
            double v = avg[(size_t)(r[1] + y) * w + r[0] + x];
            ss += (v - mean) * (v - mean);
            row += v;
            colm[x] += v;
        }
        rs += (row / N - mean) * (row / N - mean);
    }
    for (int x = 0; x < N; x++) cs += (colm[x] / M - mean) * (colm[x] / M - mean);
    free(colm);
    const double MN = (double)M * N, D = MN - M - N;
    o->mean = mean;
    o->s2_measured = ss / (MN - 1);
    o->s2 = o->s2_measured - stack_var / L;
    o->s2_cav = cs / N - stack_var / ((double)L * M);   // the column means (each over M rows)
    o->s2_rav = rs / M - stack_var / ((double)L * N);   // the row means (each over N columns)
    o->s2_col = (MN - M) / D * o->s2_cav - N / D * (o->s2 - o->s2_rav);
    o->s2_row = (MN - N) / D * o->s2_rav - M / D * (o->s2 - o->s2_cav);
    o->s2_pixel = MN / D * (o->s2 - o->s2_cav - o->s2_rav);
    if (!(D > 0) || L < 2) {   // no temporal variance of one frame, no split of a line
        o->s2 = o->s2_cav = o->s2_rav = o->s2_col = o->s2_row = o->s2_pixel = NAN;
        if (L < 2) o->s2_measured = NAN;
    }
    return true;
}

void calib_gain_nonuniformity(calib_gain_nonuni_t *nu)
{
    const calib_gain_stack_var_t *dk = &nu->dark, *lt = &nu->light;
    const double dv[4] = { dk->s2, dk->s2_row, dk->s2_col, dk->s2_pixel };
    const double lv[4] = { lt->s2, lt->s2_row, lt->s2_col, lt->s2_pixel };
    nu->signal_dn = lt->mean - dk->mean;
    for (int k = 0; k < 4; k++) {
        nu->dsnu_var_dn2[k] = dv[k];
        nu->prnu_var_dn2[k] = lv[k] - dv[k];
        nu->dsnu_dn[k] = calib_gain_signed_sqrt(dv[k]);
        nu->prnu_pct[k] = 100 * calib_gain_signed_sqrt(lv[k] - dv[k]) / nu->signal_dn;
    }
}
