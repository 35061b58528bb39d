// calib/gain/emva.c — EMVA 1288 Release 4.0 Linear figures of `refl calib
// gain` (calib/gain/gain.h): the photon axis (quantum efficiency, responsivity,
// absolute sensitivity threshold, saturation in photons, the SNR model), the
// row/column/pixel split of DSNU and PRNU, horizontal and vertical
// spectrograms, row and column profiles, defect pixels from the logarithmic
// histograms, and the summary datasheet (gain.json "emva1288",
// datasheet.html). Each definition is stated with its formula in
// definitions_json below and in README (calib gain); where the standard's own
// equation numbers are not known here, none are cited.
#define _GNU_SOURCE
#include <complex.h>
#include <glib.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "calib/gain/gain.h"
#include "model/model.h"
#include "model/base/report.h"

// Planck's constant (J s) and the speed of light (m/s), SI 2019 exact values.
#define PLANCK_JS 6.62607015e-34
#define LIGHT_MS  299792458.0

double calib_gain_photons(double irradiance_uw_cm2, double pixel_area_um2, double wavelength_nm, double t_us)
{
    // uW/cm^2 = 1e-2 W/m^2; um^2 = 1e-12 m^2; us = 1e-6 s; nm = 1e-9 m
    double energy_j = pixel_area_um2 * 1e-12 * irradiance_uw_cm2 * 1e-2 * t_us * 1e-6;
    return energy_j * wavelength_nm * 1e-9 / (PLANCK_JS * LIGHT_MS);
}

double calib_gain_photodiode_irradiance(double current_na, double responsivity_a_per_w, double area_mm2)
{
    // nA = 1e-9 A; mm^2 = 1e-2 cm^2; W/cm^2 = 1e6 uW/cm^2
    return current_na * 1e-9 / (responsivity_a_per_w * area_mm2 * 1e-2) * 1e6;
}

bool calib_gain_photon_axis(const double *t, const double *mu, int n, double sat_dn, double K, double var_dark_dn2,
                            double E, double A, double lambda, calib_gain_photon_t *o)
{
    memset(o, 0, sizeof *o);
    o->irradiance_uw_cm2 = E;
    o->pixel_area_um2 = A;
    o->wavelength_nm = lambda;
    o->responsivity_dn_per_photon = o->responsivity_offset_dn = o->qe = o->mu_p_min = o->mu_p_sat = NAN;
    // the electron figures: SNR = 1 of the linear model (x = eta mu_p: x^2 = s^2 + x)
    double s2 = var_dark_dn2 / (K * K);
    o->dark_noise_e = sqrt(fmax(s2, 0));
    o->mu_e_min = 0.5 + sqrt(fmax(s2, 0) + 0.25);
    o->mu_e_sat = sat_dn / K;
    o->dynamic_range = o->mu_e_sat / o->mu_e_min;
    o->measured = isfinite(E) && E > 0 && isfinite(A) && A > 0 && isfinite(lambda) && lambda > 0;
    if (!o->measured) return true;
    double *x = malloc(sizeof(double) * (n + 1) * 2), *y = x + n + 1, c[3];
    if (!x) {
        model_error_set(NULL, 0, "out of memory for the photon axis");
        return false;
    }
    int m = 0;
    for (int i = 0; i < n; i++)
        if (mu[i] <= 0.7 * sat_dn) {
            x[m] = calib_gain_photons(E, A, lambda, t[i]);
            y[m] = mu[i];
            m++;
        }
    bool ok = m >= 3 && calib_gain_polyfit(x, y, m, 1, c) && c[1] > 0;
    free(x);
    if (!ok) {
        model_error_set(NULL, 0, "photon axis: %d sweep steps below 70 %% of saturation (%.6g DN); the "
                        "responsivity's line needs at least 3 with a rising signal", m, sat_dn);
        return false;
    }
    o->n_fit = m;
    o->responsivity_dn_per_photon = c[1];
    o->responsivity_offset_dn = c[0];
    o->qe = c[1] / K;
    if (o->qe > 1)
        fprintf(stderr, "refl calib gain: warning: quantum efficiency %.3g %% is above 100 %%: check --irradiance "
                "(uW/cm^2 at the sensor), the pixel area and the wavelength\n", 100 * o->qe);
    o->mu_p_min = o->mu_e_min / o->qe;
    o->mu_p_sat = o->mu_e_sat / o->qe;
    return true;
}

double calib_gain_snr_model(const calib_gain_photon_t *p, double mu_p)
{
    double e = p->qe * mu_p;
    return e / sqrt(p->dark_noise_e * p->dark_noise_e + e);
}

bool calib_gain_an_photons(const calib_gain_opts_t *o, calib_gain_an_t *a)
{
    double E = isfinite(o->photodiode_na) ? calib_gain_photodiode_irradiance(o->photodiode_na, o->photodiode_a_per_w,
                                                                             o->photodiode_mm2)
                                          : o->irradiance_uw_cm2;
    if (!calib_gain_photon_axis(a->t, a->mu, a->n, a->ptc.saturation_dn, a->ptc.system_gain_dn_per_e, a->var_dark_dn2,
                                E, o->pixel_area_um2, o->wavelength_nm, &a->ph))
        return false;
    free(a->mu_p);
    a->mu_p = malloc(sizeof(double) * (a->n + 1));
    if (!a->mu_p) return false;
    for (int i = 0; i < a->n; i++)
        a->mu_p[i] = a->ph.measured ? calib_gain_photons(E, o->pixel_area_um2, o->wavelength_nm, a->t[i]) : NAN;
    return true;
}

// ---------------------------------------------------------------------------
// Spatial split, spectrograms, defects

static void region(int w, int h, const int roi[4], int r[4])
{
    if (roi && roi[2] > 0) memcpy(r, roi, sizeof(int) * 4);
    else {
        r[0] = r[1] = 0;
        r[2] = w;
        r[3] = h;
    }
}

void calib_gain_spatial_split(const float *img, int w, int h, const int roi[4], double tvar, double scale,
                              calib_gain_split_t *o)
{
    int r[4];
    region(w, h, roi, r);
    const int N = r[3], M = r[2];   // N rows, M columns
    double *colsum = calloc(M, sizeof(double)), s = 0, ss = 0, rs = 0, rss = 0;
    for (int y = 0; y < N; y++) {
        const float *row = img + (size_t)(r[1] + y) * w + r[0];
        double t = 0;
        for (int x = 0; x < M; x++) {
            t += row[x];
            ss += (double)row[x] * row[x];
            if (colsum) colsum[x] += row[x];
        }
        s += t;
        rs += t / M;
        rss += (t / M) * (t / M);
    }
    double mean = s / ((double)M * N), cs = 0, css = 0;
    for (int x = 0; colsum && x < M; x++) {
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
    o->total = scale * sqrt(fmax(V, 0));
    o->row = scale * sqrt(fmax(r2, 0));
    o->col = scale * sqrt(fmax(c2, 0));
    o->pixel = scale * sqrt(fmax(p2, 0));
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
    region(w, h, roi, r);
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

// Median and robust std (1.4826 MAD) of the roi of m (NaN values left out).
static bool robust(const float *m, int w, const int r[4], double *med, double *sigma)
{
    int n = 0;
    double *v = malloc(sizeof(double) * ((size_t)r[2] * r[3] + 1));
    if (!v) return false;
    for (int y = 0; y < r[3]; y++)
        for (int x = 0; x < r[2]; x++) {
            float f = m[(size_t)(r[1] + y) * w + r[0] + x];
            if (isfinite(f)) v[n++] = f;
        }
    *med = *sigma = NAN;
    if (n) {
        *med = model_median(v, n);
        for (int i = 0; i < n; i++) v[i] = fabs(v[i] - *med);
        *sigma = 1.4826 * model_median(v, n);
    }
    free(v);
    return true;
}

// Histogram of the deviations dev = scale (m - med) over the roi in [lo, hi]
// (*nb bins). q > 0: the values are multiples of q apart (an average of
// quantised frames): the bins are whole multiples of q wide, their edges
// halfway between values, so that no bin holds one level more than its
// neighbour (no comb).
static void histogram(const float *m, int w, const int r[4], double med, double scale, double q, double *lo,
                      double *hi, long *hist, int *nb)
{
    *lo = INFINITY;
    *hi = -INFINITY;
    for (int y = 0; y < r[3]; y++)
        for (int x = 0; x < r[2]; x++) {
            double d = scale * (m[(size_t)(r[1] + y) * w + r[0] + x] - med);
            if (!isfinite(d)) continue;
            *lo = fmin(*lo, d);
            *hi = fmax(*hi, d);
        }
    if (!isfinite(*lo)) *lo = 0;
    *nb = CALIB_GAIN_HIST_BINS;
    if (q > 0 && isfinite(*hi)) {
        double width = q * fmax(1, ceil((*hi - *lo + q) / CALIB_GAIN_HIST_BINS / q));
        *lo -= 0.5 * q;
        *nb = (int)fmin(CALIB_GAIN_HIST_BINS, ceil((*hi + 0.5 * q - *lo) / width));
        *hi = *lo + *nb * width;
    }
    if (!(*hi > *lo)) *hi = *lo + 1;
    memset(hist, 0, sizeof(long) * CALIB_GAIN_HIST_BINS);
    for (int y = 0; y < r[3]; y++)
        for (int x = 0; x < r[2]; x++) {
            double d = scale * (m[(size_t)(r[1] + y) * w + r[0] + x] - med);
            if (!isfinite(d)) continue;
            int b = (int)((d - *lo) / (*hi - *lo) * *nb);
            hist[b < 0 ? 0 : b >= *nb ? *nb - 1 : b]++;
        }
}

static void defect_add(calib_gain_defects_t *o, int kind, int x, int y)
{
    int *count[3] = { &o->hot, &o->dead, &o->bright };
    (*count[kind])++;
    if (o->nlist[kind] < CALIB_GAIN_MAX_DEFECT_LIST) {
        o->list[kind][o->nlist[kind]][0] = x;
        o->list[kind][o->nlist[kind]][1] = y;
        o->nlist[kind]++;
    }
}

bool calib_gain_defects(const float *dark, const float *light, int w, int h, const int roi[4], double nsigma,
                        double dark_tstd, double light_tstd, double dark_quantum, unsigned char *map,
                        calib_gain_defects_t *o)
{
    memset(o, 0, sizeof *o);
    o->nsigma = nsigma;
    int r[4];
    region(w, h, roi, r);
    if (!robust(dark, w, r, &o->dark_median_dn, &o->dark_sigma_dn) ||
        !robust(light, w, r, &o->light_median, &o->light_sigma)) {
        model_error_set(NULL, 0, "out of memory for the defect pixels (%dx%d)", r[2], r[3]);
        return false;
    }
    o->dark_threshold_dn = nsigma * fmax(o->dark_sigma_dn, dark_tstd);
    o->light_threshold = nsigma * fmax(o->light_sigma, light_tstd);
    if (map) memset(map, 0, (size_t)w * h);
    for (int y = r[1]; y < r[1] + r[3]; y++)
        for (int x = r[0]; x < r[0] + r[2]; x++) {
            size_t i = (size_t)y * w + x;
            double dd = dark[i] - o->dark_median_dn, dl = light[i] - o->light_median;
            int kind = dd > o->dark_threshold_dn ? 0 : dl < -o->light_threshold ? 1 : dl > o->light_threshold ? 2 : -1;
            if (kind < 0) continue;
            defect_add(o, kind, x, y);
            if (map) map[i] = (unsigned char)(kind + 1);
            // a hot pixel may also be dead or bright in the light: counted there as well
            if (kind == 0 && (dl < -o->light_threshold || dl > o->light_threshold))
                defect_add(o, dl < 0 ? 1 : 2, x, y);
        }
    histogram(dark, w, r, o->dark_median_dn, 1, dark_quantum, &o->dark_lo, &o->dark_hi, o->dark_hist, &o->dark_nbins);
    histogram(light, w, r, o->light_median, 100 / (o->light_median != 0 ? o->light_median : 1), 0, &o->light_lo,
              &o->light_hi, o->light_hist, &o->light_nbins);
    return true;
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
    region(m->w, m->h, d->roi, r);
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
    calib_gain_spatial_split(m->offset, m->w, m->h, r, dtv, 1, &sp->dsnu);
    calib_gain_spatial_split(sig, m->w, m->h, r, m->signal_temporal_var_dn2, rel, &sp->prnu);
    calib_gain_spatial_split(m->prnu_hp, m->w, m->h, r, m->signal_temporal_var_dn2 / (smean * smean), 100,
                             &sp->prnu_hp);
    bool ok = calib_gain_spectrogram(m->offset, m->w, m->h, r, false, 1, sp->spec_h_dark) &&
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
        model_error_set(NULL, 0, "out of memory for the spectrograms (%dx%d)", m->w, m->h);
        return false;
    }
    // defects: the dark average and the high-pass flat (vignetting removed)
    return calib_gain_defects(m->offset, m->prnu_hp, m->w, m->h, r, nsigma, sqrt(dtv),
                              sqrt(m->signal_temporal_var_dn2) / smean, quant_dn / m->dark_frames, sp->defect_map,
                              &sp->defects);
}

bool calib_gain_write_defects(const char *dir, const calib_gain_maps_t *m)
{
    size_t n = (size_t)m->w * m->h;
    float *f = malloc(sizeof(float) * (n + 1));
    if (!f) return false;
    for (size_t i = 0; i < n; i++) f[i] = m->sp.defect_map ? m->sp.defect_map[i] : 0;
    char *path = g_build_filename(dir, "defects.tiff", NULL);
    const char *meta[] = { "content", "defect pixels: 0 good, 1 hot (dark), 2 dead (light, low), 3 bright (light, "
                           "high)", "software", "refl calib gain " REFL_VERSION, NULL };
    bool ok = model_tiff_write_float(path, m->w, m->h, f, meta);
    g_free(path);
    free(f);
    return ok;
}

// ---------------------------------------------------------------------------
// The datasheet

static json_t *jnum(double x) { return isfinite(x) ? json_real(x) : json_null(); }

static json_t *jvec(const double *v, int n)
{
    json_t *a = json_array();
    for (int i = 0; v && i < n; i++) json_array_append_new(a, jnum(v[i]));
    return a;
}

// One datasheet row; value NAN with photons false: not computable (null);
// photons true and the photon axis not measured: "not measured".
static void row(json_t *rows, const char *quantity, const char *symbol, double value, const char *unit, bool photons,
                bool measured, const char *definition)
{
    json_t *r = json_object();
    json_object_set_new(r, "quantity", json_string(quantity));
    json_object_set_new(r, "symbol", json_string(symbol));
    json_object_set_new(r, "value", photons && !measured ? json_string("not measured") : jnum(value));
    json_object_set_new(r, "unit", json_string(unit));
    json_object_set_new(r, "definition", json_string(definition));
    json_array_append_new(rows, r);
}

static json_t *split_json(const calib_gain_split_t *s)
{
    return json_pack("{s:o, s:o, s:o, s:o}", "total", jnum(s->total), "row", jnum(s->row), "column", jnum(s->col),
                     "pixel", jnum(s->pixel));
}

static json_t *datasheet_rows(const calib_gain_an_t *a, const calib_gain_maps_t *m)
{
    const calib_gain_photon_t *p = &a->ph;
    const double K = a->ptc.system_gain_dn_per_e;
    const bool ms = p->measured;
    json_t *r = json_array();
    row(r, "quantum efficiency", "eta", 100 * p->qe, "%", true, ms,
        "eta = R / K, R the slope of the least-squares line of mu_y - mu_y.dark against mu_p over the steps up to "
        "70 % of saturation; mu_p = A E t_exp lambda / (h c)");
    row(r, "responsivity", "R", p->responsivity_dn_per_photon, "DN/photon", true, ms, "R = eta K (the slope above)");
    row(r, "system gain", "K", K, "DN/e-", false, true, "slope at zero signal of the photon transfer "
        "sigma^2_y - sigma^2_y.dark against mu_y - mu_y.dark (quadratic fit over 0..70 % of saturation)");
    row(r, "inverse system gain", "1/K", 1 / K, "e-/DN", false, true, "1 / K");
    row(r, "temporal dark noise", "sigma_d", a->ptc.read_noise_e, "e-", false, true,
        "sqrt(sigma^2_y.dark - q^2/12) / K, sigma^2_y.dark at exposure 0");
    row(r, "temporal dark noise", "sigma_y.dark", sqrt(a->var_dark_dn2), "DN", false, true,
        "sqrt(sigma^2_y.dark), quantisation included");
    row(r, "absolute sensitivity threshold", "mu_e.min", p->mu_e_min, "e-", false, true,
        "SNR = 1 of the linear model: mu_e.min = 1/2 + sqrt(sigma^2_y.dark / K^2 + 1/4)");
    row(r, "absolute sensitivity threshold", "mu_p.min", p->mu_p_min, "photons", true, ms, "mu_e.min / eta");
    row(r, "saturation capacity", "mu_e.sat", p->mu_e_sat, "e-", false, true,
        "mu_y.sat / K, mu_y.sat the signal (above dark) where the temporal variance peaks");
    row(r, "saturation capacity", "mu_p.sat", p->mu_p_sat, "photons", true, ms, "mu_e.sat / eta");
    row(r, "maximum SNR", "SNR_max", sqrt(p->mu_e_sat), "1", false, true, "sqrt(mu_e.sat)");
    row(r, "maximum SNR", "SNR_max", 20 * log10(sqrt(p->mu_e_sat)), "dB", false, true, "20 log10 SNR_max");
    row(r, "dynamic range", "DR", p->dynamic_range, "1", false, true, "mu_p.sat / mu_p.min = mu_e.sat / mu_e.min");
    row(r, "dynamic range", "DR", 20 * log10(p->dynamic_range), "dB", false, true, "20 log10 DR");
    row(r, "linearity error", "LE", a->ptc.linearity_error_pct, "%", false, true,
        "Release 4.0 Linear: the line a0 + a1 t through the steps in 5..95 % of saturation minimising "
        "sum((mu_i - a0 - a1 t_i) / mu_i)^2; delta_i = 100 (mu_i - line_i) / line_i; LE = (max delta - min delta) "
        "/ 2 (exposure stands in for the irradiation: the irradiance is constant over the sweep)");
    row(r, "linearity error (Release 3)", "LE_R3", a->ptc.linearity_error_r3_pct, "%", false, true,
        "the same deviations from the unweighted least-squares line");
    row(r, "dark current (from the mean)", "mu_I", a->dark_slope_dn_per_us * 1e6 / K, "e-/s", false, true,
        "slope of mu_y.dark against exposure / K");
    row(r, "dark current (from the variance)", "mu_I.var", a->dark_var_slope_dn2_per_us * 1e6 / (K * K), "e-/s",
        false, true, "slope of sigma^2_y.dark against exposure / K^2 (shot noise of the dark current)");
    const calib_gain_spatial_t *sp = &m->sp;
    const char *parts[4] = { "total", "row", "column", "pixel" };
    const double dv[4] = { sp->dsnu.total, sp->dsnu.row, sp->dsnu.col, sp->dsnu.pixel },
                 pv[4] = { sp->prnu.total, sp->prnu.row, sp->prnu.col, sp->prnu.pixel };
    for (int k = 0; k < 4; k++) {
        char q[64], sym[32];
        snprintf(q, sizeof q, "DSNU (%s)", parts[k]);
        snprintf(sym, sizeof sym, "DSNU.%s", parts[k]);
        row(r, q, sym, dv[k] / K, "e-", false, true, k ? "std of the averaged dark frame's part (row/column/pixel "
            "split, temporal noise removed) / K" : "std of the averaged dark frame, temporal noise removed, / K");
        snprintf(q, sizeof q, "PRNU (%s)", parts[k]);
        snprintf(sym, sizeof sym, "PRNU.%s", parts[k]);
        row(r, q, sym, pv[k], "%", false, true, "std of the averaged flat minus dark (its part), temporal noise "
            "removed, / its mean");
    }
    const calib_gain_defects_t *df = &sp->defects;
    row(r, "hot pixels", "n_hot", df->hot, "pixels", false, true, "averaged dark above its median by more than "
        "the threshold (nsigma robust stds)");
    row(r, "dead pixels", "n_dead", df->dead, "pixels", false, true, "high-pass flat below its median by more than "
        "the threshold");
    row(r, "bright pixels", "n_bright", df->bright, "pixels", false, true, "high-pass flat above its median by more "
        "than the threshold");
    return r;
}

static json_t *hist_json(double lo, double hi, const long *h, int nb, const char *unit)
{
    json_t *c = json_array();
    for (int i = 0; i < nb; i++) json_array_append_new(c, json_integer(h[i]));
    return json_pack("{s:o, s:o, s:s, s:o}", "lo", jnum(lo), "hi", jnum(hi), "unit", unit, "counts", c);
}

static json_t *defects_json(const calib_gain_defects_t *d, double nsigma)
{
    json_t *o = json_object();
    json_object_set_new(o, "map", json_string("defects.tiff"));
    json_object_set_new(o, "codes", json_string("0 good, 1 hot, 2 dead, 3 bright"));
    json_object_set_new(o, "nsigma", json_real(nsigma));
    json_object_set_new(o, "hot", json_integer(d->hot));
    json_object_set_new(o, "dead", json_integer(d->dead));
    json_object_set_new(o, "bright", json_integer(d->bright));
    json_object_set_new(o, "dark_median_dn", jnum(d->dark_median_dn));
    json_object_set_new(o, "dark_sigma_dn", jnum(d->dark_sigma_dn));
    json_object_set_new(o, "hot_threshold_dn", jnum(d->dark_threshold_dn));
    json_object_set_new(o, "light_median", jnum(d->light_median));
    json_object_set_new(o, "light_sigma", jnum(d->light_sigma));
    json_object_set_new(o, "light_threshold", jnum(d->light_threshold));
    const char *names[3] = { "hot_pixels", "dead_pixels", "bright_pixels" };
    for (int k = 0; k < 3; k++) {
        json_t *l = json_array();
        for (int i = 0; i < d->nlist[k]; i++)
            json_array_append_new(l, json_pack("[ii]", d->list[k][i][0], d->list[k][i][1]));
        json_object_set_new(o, names[k], l);
    }
    json_object_set_new(o, "histogram_dark", hist_json(d->dark_lo, d->dark_hi, d->dark_hist, d->dark_nbins,
                                                       "DN from the median"));
    json_object_set_new(o, "histogram_light", hist_json(d->light_lo, d->light_hi, d->light_hist, d->light_nbins,
                                                        "% from the median (high-pass flat)"));
    return o;
}

static json_t *spectro_json(int n, int len, const double *dark, const double *light)
{
    double *f = malloc(sizeof(double) * (n + 1));
    for (int k = 0; f && k < n; k++) f[k] = (double)k / len;
    json_t *o = json_pack("{s:o, s:o, s:o}", "frequency_cycles_per_px", jvec(f, n), "dark_dn", jvec(dark, n),
                          "light_pct", jvec(light, n));
    free(f);
    return o;
}

static json_t *snr_json(const calib_gain_an_t *a)
{
    json_t *o = json_object();
    double *m = malloc(sizeof(double) * (a->n + 1)), *id = malloc(sizeof(double) * (a->n + 1));
    for (int i = 0; m && id && i < a->n; i++) {
        double mp = a->mu_p ? a->mu_p[i] : NAN;
        m[i] = a->ph.measured ? calib_gain_snr_model(&a->ph, mp) : NAN;
        id[i] = a->ph.measured ? sqrt(mp) : NAN;
    }
    json_object_set_new(o, "photons", jvec(a->mu_p, a->n));
    json_object_set_new(o, "electrons", json_array());
    for (int i = 0; i < a->n; i++)
        json_array_append_new(json_object_get(o, "electrons"), jnum(a->mu[i] / a->ptc.system_gain_dn_per_e));
    json_object_set_new(o, "snr_measured", jvec(a->snr, a->n));
    json_object_set_new(o, "snr_model", jvec(m, a->n));
    json_object_set_new(o, "snr_ideal", jvec(id, a->n));
    // the model and the ideal on a grid from half the threshold to saturation (the plot's lines)
    if (a->ph.measured && a->ph.mu_p_min > 0 && a->ph.mu_p_sat > a->ph.mu_p_min) {
        enum { NG = 64 };
        double g[NG], gm[NG], gi[NG], lo = log(0.5 * a->ph.mu_p_min), hi = log(a->ph.mu_p_sat);
        for (int i = 0; i < NG; i++) {
            g[i] = exp(lo + (hi - lo) * i / (NG - 1));
            gm[i] = calib_gain_snr_model(&a->ph, g[i]);
            gi[i] = sqrt(g[i]);
        }
        json_object_set_new(o, "grid_photons", jvec(g, NG));
        json_object_set_new(o, "grid_snr_model", jvec(gm, NG));
        json_object_set_new(o, "grid_snr_ideal", jvec(gi, NG));
    }
    json_object_set_new(o, "definition", json_string(
        "grid_*: the same on 64 photon counts from mu_p.min / 2 to mu_p.sat; measured: (mu_y - mu_y.dark) / sigma_y; model: eta mu_p / sqrt(sigma^2_y.dark / K^2 + eta mu_p); ideal: "
        "sqrt(mu_p) (eta = 1, no dark noise); photons null when the photon axis is not measured"));
    free(m);
    free(id);
    return o;
}

json_t *calib_gain_emva_json(const calib_gain_opts_t *o, const calib_gain_an_t *an, const calib_gain_maps_t *m)
{
    const calib_gain_an_t *a = &an[0];
    const calib_gain_spatial_t *sp = &m->sp;
    json_t *e = json_object();
    json_object_set_new(e, "standard", json_string("EMVA 1288 Release 4.0 Linear (definitions as stated per row; "
                                                   "equation numbers of the standard not cited)"));
    json_object_set_new(e, "photon_axis", json_string(a->ph.measured ? "measured" : "not measured (give "
                                                      "--irradiance, --pixel-area-um2 and --wavelength-nm)"));
    json_t *c = json_object();
    json_object_set_new(c, "irradiance_uw_cm2", a->ph.measured ? json_real(a->ph.irradiance_uw_cm2)
                                                                : json_string("not measured"));
    if (isfinite(o->photodiode_na))
        json_object_set_new(c, "photodiode", json_pack("{s:f, s:f, s:f, s:s}", "current_na", o->photodiode_na,
                                                       "responsivity_a_per_w", o->photodiode_a_per_w, "area_mm2",
                                                       o->photodiode_mm2, "irradiance", "E = I / (R S)"));
    json_object_set_new(c, "pixel_area_um2", jnum(o->pixel_area_um2));
    json_object_set_new(c, "wavelength_nm", jnum(o->wavelength_nm));
    json_object_set_new(c, "gain_db", json_real(a->gain_db));
    json_object_set_new(c, "photons", json_string("mu_p = A E t_exp lambda / (h c), h = 6.62607015e-34 J s, "
                                                  "c = 299792458 m/s"));
    json_object_set_new(e, "conditions", c);
    if (a->ph.measured && a->ph.qe > 1)
        json_object_set_new(e, "warning", json_string("quantum efficiency above 100 %: check the irradiance (uW/cm^2 "
                                                      "at the sensor), the pixel area and the wavelength"));
    json_object_set_new(e, "datasheet", datasheet_rows(a, m));
    json_object_set_new(e, "responsivity_offset_dn", a->ph.measured ? jnum(a->ph.responsivity_offset_dn)
                                                                    : json_string("not measured"));
    json_object_set_new(e, "snr_curve", snr_json(a));
    json_t *s = json_object();
    json_object_set_new(s, "dsnu_dn", split_json(&sp->dsnu));
    json_object_set_new(s, "prnu_pct", split_json(&sp->prnu));
    json_object_set_new(s, "prnu_highpass_pct", split_json(&sp->prnu_hp));
    json_object_set_new(s, "signal_mean_dn", jnum(sp->signal_mean_dn));
    json_object_set_new(s, "definition", json_string(
        "averaged frame y = mu + r[row] + c[column] + p + e; V, Vr, Vc the variances of all values, of the row means "
        "and of the column means, less the temporal variance of the average (sigma^2/L, /M, /N); s2_pixel = (V - Vr "
        "- Vc) / (1 - 1/M - 1/N), s2_row = Vr - s2_pixel / M, s2_col = Vc - s2_pixel / N (M columns, N rows); "
        "DSNU of the averaged dark (DN), PRNU of the averaged flat minus dark, % of its mean, vignetting included; "
        "prnu_highpass_pct: the same of the flat divided by its quadratic smooth surface (vignetting removed)"));
    json_object_set_new(e, "spatial", s);
    json_t *sg = json_object();
    json_object_set_new(sg, "horizontal", spectro_json(sp->nh, sp->pw, sp->spec_h_dark, sp->spec_h_light));
    json_object_set_new(sg, "vertical", spectro_json(sp->nv, sp->ph, sp->spec_v_dark, sp->spec_v_light));
    json_object_set_new(sg, "definition", json_string(
        "horizontal: the DFT Y(k) of every row after removing the frame's mean, s(k) = sqrt(mean over rows of "
        "|Y(k)|^2 / N), N the row length, frequency k / N cycles per pixel (column patterns show here); vertical: "
        "the same along the columns (row patterns). White noise of std sigma gives s ~ sigma; dark in DN, light in % "
        "of the mean signal"));
    json_object_set_new(e, "spectrograms", sg);
    json_t *pr = json_object();
    json_object_set_new(pr, "column_dark_dn", jvec(sp->col_dark, sp->pw));
    json_object_set_new(pr, "column_signal_dn", jvec(sp->col_light, sp->pw));
    json_object_set_new(pr, "row_dark_dn", jvec(sp->row_dark, sp->ph));
    json_object_set_new(pr, "row_signal_dn", jvec(sp->row_light, sp->ph));
    json_object_set_new(pr, "definition", json_string("means of the statistics region's columns (horizontal "
                                                      "profile) and rows (vertical profile) of the averaged dark "
                                                      "and flat minus dark"));
    json_object_set_new(e, "profiles", pr);
    json_object_set_new(e, "defects", defects_json(&sp->defects, o->defect_sigma));
    return e;
}

bool calib_gain_datasheet_html(const char *dir, json_t *emva, json_t *prov)
{
    char *hp = g_build_filename(dir, "datasheet.html", NULL);
    FILE *f = model_html_begin(hp, "refl calib gain: EMVA 1288 Release 4.0 Linear summary datasheet", prov);
    if (!f) {
        g_free(hp);
        return false;
    }
    json_t *c = json_object_get(emva, "conditions");
    json_t *irr = json_object_get(c, "irradiance_uw_cm2");
    char ib[64];
    if (json_is_number(irr)) snprintf(ib, sizeof ib, "%.6g", json_number_value(irr));
    else snprintf(ib, sizeof ib, "not measured");
    model_html_para(f, "Photon axis: %s. Irradiance %s uW/cm^2, pixel area %.6g um^2, wavelength %.6g nm, gain %g.",
                    json_string_value(json_object_get(emva, "photon_axis")), ib,
                    json_number_value(json_object_get(c, "pixel_area_um2")),
                    json_number_value(json_object_get(c, "wavelength_nm")),
                    json_number_value(json_object_get(c, "gain_db")));
    json_t *rows = json_object_get(emva, "datasheet");
    size_t n = json_array_size(rows);
    char **rs = calloc(n + 1, sizeof *rs);
    for (size_t i = 0; rs && i < n; i++) {
        json_t *r = json_array_get(rows, i), *v = json_object_get(r, "value");
        char *val = json_is_number(v) ? g_strdup_printf("%.5g", json_number_value(v))
                                      : g_strdup(json_is_string(v) ? json_string_value(v) : "n/a");
        rs[i] = g_strdup_printf("%s|%s|%s|%s|%s", json_string_value(json_object_get(r, "quantity")),
                                json_string_value(json_object_get(r, "symbol")), val,
                                json_string_value(json_object_get(r, "unit")),
                                json_string_value(json_object_get(r, "definition")));
        g_free(val);
    }
    model_html_heading(f, "Datasheet");
    model_html_table(f, "quantity|symbol|value|unit|definition", (const char *const *)rs, rs ? (int)n : 0);
    for (size_t i = 0; rs && i < n; i++) g_free(rs[i]);
    free(rs);
    static const char *const figs[][3] = {
        { "SNR", "snr_photons.png", "SNR against photons per pixel (or electrons when not measured): measured up to "
                                    "saturation, the linear model and the ideal sqrt(mu_p)" },
        { "Spectrograms", "spectrogram_h.png", "horizontal spectrograms (along the rows: column patterns), dark (DN) "
                                               "and light (%)" },
        { NULL, "spectrogram_v.png", "vertical spectrograms (along the columns: row patterns), dark (DN) and light "
                                     "(%)" },
        { "Profiles", "profiles.png", "horizontal and vertical profiles: column and row means of the averaged dark "
                                      "and flat minus dark" },
        { "Defect pixels", "log_histograms.png", "logarithmic histograms of the deviations from the median: dark "
                                                 "(DN) and high-pass flat (%), with the defect thresholds" },
        { NULL, "defect_map.png", "defect pixels (defects.tiff): hot, dead, bright" },
    };
    for (size_t i = 0; i < sizeof figs / sizeof figs[0]; i++) {
        if (figs[i][0]) model_html_heading(f, figs[i][0]);
        model_html_figure(f, figs[i][1], figs[i][2]);
    }
    fprintf(f, "<p><a href=\"report.html\">the full report</a>; figures and curves: gain.json \"emva1288\"</p>\n");
    bool ok = model_html_end(f, hp);
    g_free(hp);
    return ok;
}
