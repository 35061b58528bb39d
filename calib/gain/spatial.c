// calib/gain/spatial.c — the spatial analysis of EMVA 1288 Release 4.0
// Linear around the standard's DSNU and PRNU (nonuniformity.c): refl's
// row/column/pixel split of the high-pass PRNU, horizontal and vertical
// spectrograms, row and column profiles, the defects' inputs
// (calib/gain/gain.h).
#include <complex.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "calib/gain/internal.h"
#include "model/model.h"

bool calib_gain_spatial_split(const float *img, int w, int h, const int roi[4], double tvar, double scale,
                              calib_gain_split_t *o)
{
    int r[4];
    gain_region(w, h, roi, r);
    const int N = r[3], M = r[2];   // N rows, M columns
    double *colsum = calloc(M > 0 ? M : 1, sizeof(double)), s = 0, ss = 0, rs = 0, rss = 0;
    if (!colsum) {
        *o = (calib_gain_split_t){ NAN, NAN, NAN, NAN };
        model_error_set(NULL, 0, "out of memory for the spatial split (%d columns)", M);
        return false;
    }
    for (int y = 0; y < N; y++) {
        const float *row = img + (size_t)(r[1] + y) * w + r[0];
        double t = 0;
        for (int x = 0; x < M; x++) {
            t += row[x];
            ss += (double)row[x] * row[x];
            colsum[x] += row[x];
        }
        s += t;
        rs += t / M;
        rss += (t / M) * (t / M);
    }
    double mean = s / ((double)M * N), cs = 0, css = 0;
    for (int x = 0; x < M; x++) {
        double c = colsum[x] / N;
        cs += c;
        css += c * c;
    }
    free(colsum);
    double V = ss / ((double)M * N) - mean * mean - tvar;
    double Vr = rss / N - (rs / N) * (rs / N) - tvar / M;
    double Vc = css / M - (cs / M) * (cs / M) - tvar / N;
    double den = 1 - 1.0 / M - 1.0 / N;
    double p2 = den > 0 ? (V - Vr - Vc) / den : NAN;
    double r2 = Vr - p2 / M, c2 = Vc - p2 / N;
    o->total = scale * calib_gain_signed_sqrt(V);
    o->row = scale * calib_gain_signed_sqrt(r2);
    o->col = scale * calib_gain_signed_sqrt(c2);
    o->pixel = scale * calib_gain_signed_sqrt(p2);
    return true;
}

// Mixed-radix decimation-in-time DFT of in[j * stride] (j < n) into out[n]:
// out[k] = sum_j in[j] exp(-2 pi i j k / n). tw[q] = exp(-2 pi i q / ntop),
// n dividing ntop; tmp holds n values.
static void dft(const double complex *in, int stride, int n, int ntop, const double complex *tw,
                double complex *out, double complex *tmp)
{
    if (n == 1) {
        out[0] = in[0];
        return;
    }
    int p = n;
    for (int f = 2; f * f <= n; f++)
        if (n % f == 0) {
            p = f;
            break;
        }
    const int m = n / p, step = ntop / n;
    if (p == n || p > 64) {   // a prime length (or a large factor): the plain sum
        for (int k = 0; k < n; k++) {
            double complex acc = 0;
            for (int j = 0; j < n; j++) acc += in[(size_t)j * stride] * tw[((long)j * k % n) * step];
            tmp[k] = acc;
        }
        memcpy(out, tmp, sizeof(double complex) * n);
        return;
    }
    for (int q = 0; q < p; q++) dft(in + (size_t)q * stride, stride * p, m, ntop, tw, out + (size_t)q * m, tmp);
    if (p == 2) {   // the butterfly, in place
        for (int k = 0; k < m; k++) {
            double complex a = out[k], b = out[m + k] * tw[(size_t)k * step];
            out[k] = a + b;
            out[m + k] = a - b;
        }
        return;
    }
    double complex t[64];
    for (int k = 0; k < m; k++) {
        for (int q = 0; q < p; q++) t[q] = out[(size_t)q * m + k] * tw[((long)q * k % n) * step];
        for (int v = 0; v < p; v++) {
            double complex acc = 0;
            for (int q = 0; q < p; q++) acc += t[q] * tw[((long)q * v % p) * (ntop / p)];
            tmp[k + (size_t)v * m] = acc;
        }
    }
    memcpy(out, tmp, sizeof(double complex) * n);
}

int calib_gain_spectrogram(const float *img, int w, int h, const int roi[4], bool vertical, double scale,
                           double *spec)
{
    int r[4];
    gain_region(w, h, roi, r);
    const int n = vertical ? r[3] : r[2], lines = vertical ? r[2] : r[3], nk = n / 2 + 1;
    double complex *buf = malloc(sizeof(double complex) * (size_t)n * 3), *out = buf + n, *tmp = out + n;
    double complex *tw = malloc(sizeof(double complex) * (size_t)n);
    double *pw = calloc(nk, sizeof(double));
    if (!buf || !tw || !pw) {
        free(buf);
        free(tw);
        free(pw);
        return 0;
    }
    for (int q = 0; q < n; q++) tw[q] = cexp(-2 * M_PI * I * q / n);
    double s = 0;
    for (int y = 0; y < r[3]; y++)
        for (int x = 0; x < r[2]; x++) s += img[(size_t)(r[1] + y) * w + r[0] + x];
    const double mean = s / ((double)r[2] * r[3]);
    for (int l = 0; l < lines; l++) {
        for (int j = 0; j < n; j++) {
            int x = vertical ? l : j, y = vertical ? j : l;
            buf[j] = img[(size_t)(r[1] + y) * w + r[0] + x] - mean;
        }
        dft(buf, 1, n, n, tw, out, tmp);
        for (int k = 0; k < nk; k++) pw[k] += creal(out[k] * conj(out[k])) / n;
    }
    for (int k = 0; k < nk; k++) spec[k] = scale * sqrt(pw[k] / lines);
    free(buf);
    free(tw);
    free(pw);
    return nk;
}

static double *profile(const float *m, int w, const int r[4], bool rows, double shift)
{
    int n = rows ? r[3] : r[2], other = rows ? r[2] : r[3];
    double *p = calloc(n + 1, sizeof(double));
    for (int k = 0; p && k < n; k++) {
        double s = 0;
        for (int j = 0; j < other; j++) {
            int x = rows ? j : k, y = rows ? k : j;
            s += m[(size_t)(r[1] + y) * w + r[0] + x];
        }
        p[k] = s / other + shift;
    }
    return p;
}

bool calib_gain_make_spatial(const calib_gain_data_t *d, calib_gain_maps_t *m, double nsigma, double quant_dn)
{
    calib_gain_spatial_t *sp = &m->sp;
    memset(sp, 0, sizeof *sp);
    int r[4];
    gain_region(m->w, m->h, d->roi, r);
    size_t n = (size_t)m->w * m->h;
    float *sig = malloc(sizeof(float) * n);
    sp->defect_map = malloc(n);
    sp->nh = r[2] / 2 + 1;
    sp->nv = r[3] / 2 + 1;
    double *sa = malloc(sizeof(double) * (size_t)(sp->nh + sp->nv) * 4);
    if (!sig || !sp->defect_map || !sa) {
        free(sig);
        free(sa);
        model_error_set(NULL, 0, "out of memory for the spatial analysis (%dx%d)", m->w, m->h);
        return false;
    }
    sp->spec_h_dark = sa;
    sp->spec_h_light = sa + sp->nh;
    sp->spec_v_dark = sa + 2 * sp->nh;
    sp->spec_v_light = sa + 2 * sp->nh + sp->nv;
    for (size_t i = 0; i < n; i++) sig[i] = (float)(m->prnu[i] * m->prnu_mean_dn);
    double smean = 0;
    for (int y = 0; y < r[3]; y++)
        for (int x = 0; x < r[2]; x++) smean += sig[(size_t)(r[1] + y) * m->w + r[0] + x];
    smean /= (double)r[2] * r[3];
    sp->signal_mean_dn = smean;
    const double rel = 100 / smean, dtv = m->dark_var_dn2 / m->dark_frames;
    // DSNU and PRNU: the standard's (maps.c, nonuniformity.c); the high-pass PRNU refl's
    sp->dsnu = (calib_gain_split_t){ m->nu.dsnu_dn[0], m->nu.dsnu_dn[1], m->nu.dsnu_dn[2], m->nu.dsnu_dn[3] };
    sp->prnu = (calib_gain_split_t){ m->nu.prnu_pct[0], m->nu.prnu_pct[1], m->nu.prnu_pct[2], m->nu.prnu_pct[3] };
    bool ok = calib_gain_spatial_split(m->prnu_hp, m->w, m->h, r, m->signal_temporal_var_dn2 / (smean * smean), 100,
                                       &sp->prnu_hp) &&
              calib_gain_spectrogram(m->offset, m->w, m->h, r, false, 1, sp->spec_h_dark) &&
              calib_gain_spectrogram(m->offset, m->w, m->h, r, true, 1, sp->spec_v_dark) &&
              calib_gain_spectrogram(sig, m->w, m->h, r, false, rel, sp->spec_h_light) &&
              calib_gain_spectrogram(sig, m->w, m->h, r, true, rel, sp->spec_v_light);
    sp->pw = r[2];
    sp->ph = r[3];
    sp->col_dark = profile(m->offset, m->w, r, false, 0);
    sp->row_dark = profile(m->offset, m->w, r, true, 0);
    sp->col_light = profile(sig, m->w, r, false, 0);
    sp->row_light = profile(sig, m->w, r, true, 0);
    ok = ok && sp->col_dark && sp->row_dark && sp->col_light && sp->row_light;
    free(sig);
    if (!ok) {
        model_error_set(NULL, 0, "out of memory for the spatial split and spectrograms (%dx%d)", m->w, m->h);
        return false;
    }
    // defects: the dark average and the high-pass flat (vignetting removed)
    return calib_gain_defects(m->offset, m->prnu_hp, m->w, m->h, r, nsigma, sqrt(dtv),
                              sqrt(m->signal_temporal_var_dn2) / smean, quant_dn / m->dark_frames, sp->defect_map,
                              &sp->defects);
}
