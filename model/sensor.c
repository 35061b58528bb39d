// model/sensor.c — the sensor stage: from the ideal grey value P (DN) of the
// imaging model to the integers a camera delivers (EMVA 1288 style model).
//
// Per pixel (x, y), with K = system_gain_dn_per_e and FW = full_well_e:
//   mu    = max(0, P - dark_offset_dn) / K * prnu(x,y) * vig(x,y)
//           + dark_current_e_per_s * exposure_us * 1e-6             (electrons)
//   n     = Poisson(mu): exact (inversion for mu < 12, Hoermann's PTRS
//           transformed rejection for 12 <= mu < 1e7), normal above 1e7
//   e     = n + read_noise_e * N(0,1)
//   e     = min(e, FW)                                  (the well saturates)
//   e_nl  = e * (1 - c * e / FW),  c = nonlinearity_pct / 100
//           (a quadratic compression: smooth, monotonic for c < 0.5, exactly
//           c*100 % below linear at e = FW, 0 at e = 0)
//   DN    = round(e_nl * K + dark_offset_dn + dsnu(x,y)), clipped to [0, 2^bits - 1]
// Vignetting: vig(x,y) = 1 - vignetting * (r / r_corner)^2, r the distance from
// the image centre ((width-1)/2, (height-1)/2) and r_corner that of pixel (0,0);
// vignetting is the relative fall-off at the corners.
// Non-finite P is treated as dark (P = dark offset); mu is capped at 1e15; a
// negative gain (prnu_pct near its upper limit of 50) gives no signal.
// Temporal noise: one stream per row, model_rng(noise_seed, row), drawn
// along the row (normal values by a ziggurat) — reproducible and
// independent of the number of threads.
//
// Fixed patterns (model_sensor_patterns), from pattern_seed: each map is
// a standardised field z(x,y) (mean exactly 0, std exactly 1 over the image,
// computed in double) made of a column component, a row component and white
// noise, independent standard normal values mixed with these variance shares:
//   PRNU  10 % columns,  5 % rows, 85 % white;  gain = 1 + prnu_pct/100 * z
//   DSNU  30 % columns,  5 % rows, 65 % white;  dsnu = dsnu_dn * z
// (column fixed-pattern noise dominates in CMOS sensors).
#define _GNU_SOURCE
#include <pthread.h>
#include <stdlib.h>
#include <string.h>

#include "model/internal.h"

// model_sensor_default() lives with the sensor file parser in model/config.c.

// ---------------------------------------------------------------------------
// Fixed patterns

// Random streams of the patterns (high byte; the low bits index pixel, column or row).
enum { STREAM_PIXEL = 1, STREAM_COLUMN = 2, STREAM_ROW = 3 };
#define STREAM(kind, i) (((uint64_t)(kind) << 56) | (uint64_t)(i))

// Two independent standard normal values from one Box-Muller transform.
static inline void gauss_pair(model_rng_t *r, double *a, double *b)
{
    double u1 = model_rng_uniform(r), u2 = model_rng_uniform(r);
    if (u1 < 1e-300) u1 = 1e-300;
    double m = sqrt(-2.0 * log(u1));
    *a = m * cos(2.0 * M_PI * u2);
    *b = m * sin(2.0 * M_PI * u2);
}

static const double prnu_col = 0.10, prnu_row = 0.05, prnu_white = 0.85;
static const double dsnu_col = 0.30, dsnu_row = 0.05, dsnu_white = 0.65;

typedef struct {
    const model_sensor_t *s;
    int     width, height;
    const double *col, *row;   // per column / row: (prnu, dsnu) standard normal pairs
    double *zp, *zd;           // raw fields (double), width*height
    double *sums;              // per row: sum zp, sum zp^2, sum zd, sum zd^2
} pattern_job_t;

static void pattern_rows(void *ctx, int begin, int end, int thread)
{
    pattern_job_t *J = ctx;
    const double ac = sqrt(prnu_col), ar = sqrt(prnu_row), aw = sqrt(prnu_white);
    const double bc = sqrt(dsnu_col), br = sqrt(dsnu_row), bw = sqrt(dsnu_white);
    for (int y = begin; y < end; y++) {
        double s[4] = { 0, 0, 0, 0 };
        for (int x = 0; x < J->width; x++) {
            size_t i = (size_t)y * J->width + x;
            model_rng_t r = model_rng(J->s->pattern_seed, STREAM(STREAM_PIXEL, i));
            double gp, gd;
            gauss_pair(&r, &gp, &gd);
            double zp = ac * J->col[2 * x] + ar * J->row[2 * y] + aw * gp;
            double zd = bc * J->col[2 * x + 1] + br * J->row[2 * y + 1] + bw * gd;
            J->zp[i] = zp;
            J->zd[i] = zd;
            s[0] += zp;
            s[1] += zp * zp;
            s[2] += zd;
            s[3] += zd * zd;
        }
        memcpy(J->sums + 4 * (size_t)y, s, sizeof s);
    }
}

void model_sensor_patterns(const model_sensor_t *s, int width, int height,
                           float *prnu_gain, float *dsnu_dn)
{
    if (width <= 0 || height <= 0 || (!prnu_gain && !dsnu_dn)) return;
    size_t n = (size_t)width * height;
    double *col = malloc((size_t)width * 2 * sizeof(double));
    double *row = malloc((size_t)height * 2 * sizeof(double));
    double *zp = malloc(n * sizeof(double)), *zd = malloc(n * sizeof(double));
    double *sums = malloc((size_t)height * 4 * sizeof(double));
    if (!col || !row || !zp || !zd || !sums) {
        // No way to report from here; fall back to the ideal sensor.
        MODEL_FAIL("out of memory for %dx%d sensor patterns; using flat patterns", width, height);
        for (size_t i = 0; i < n; i++) {
            if (prnu_gain) prnu_gain[i] = 1.0f;
            if (dsnu_dn) dsnu_dn[i] = 0.0f;
        }
        goto done;
    }
    for (int x = 0; x < width; x++) {
        model_rng_t r = model_rng(s->pattern_seed, STREAM(STREAM_COLUMN, x));
        gauss_pair(&r, &col[2 * x], &col[2 * x + 1]);
    }
    for (int y = 0; y < height; y++) {
        model_rng_t r = model_rng(s->pattern_seed, STREAM(STREAM_ROW, y));
        gauss_pair(&r, &row[2 * y], &row[2 * y + 1]);
    }
    pattern_job_t J = { s, width, height, col, row, zp, zd, sums };
    model_parallel_for(height, 16, model_default_threads(), pattern_rows, &J);
    double t[4] = { 0, 0, 0, 0 };   // summed in row order: independent of the threads
    for (int y = 0; y < height; y++)
        for (int k = 0; k < 4; k++) t[k] += sums[4 * (size_t)y + k];
    double mp = t[0] / n, md = t[2] / n;
    double vp = t[1] / n - mp * mp, vd = t[3] / n - md * md;
    double kp = vp > 0 ? s->prnu_pct / 100.0 / sqrt(vp) : 0;
    double kd = vd > 0 ? s->dsnu_dn / sqrt(vd) : 0;
    for (size_t i = 0; i < n; i++) {
        if (prnu_gain) prnu_gain[i] = (float)(1.0 + kp * (zp[i] - mp));
        if (dsnu_dn) dsnu_dn[i] = (float)(kd * (zd[i] - md));
    }
done:
    free(col);
    free(row);
    free(zp);
    free(zd);
    free(sums);
}

// ---------------------------------------------------------------------------
// Temporal noise and the response

// A row's random stream: uniforms, and standard normal values from a
// ziggurat (G. Marsaglia and W. W. Tsang, "The ziggurat method for generating
// random variables", J. Statistical Software 5 (2000)): 256 layers of equal
// area under the half density f(x) = exp(-x^2/2); one 64-bit draw gives the
// layer (low 8 bits), the sign (bit 8) and the position (high 53 bits, so
// independent of the layer), and ~99 % of the values need nothing more than a
// multiplication and a comparison. Exact: the rejection steps for the wedges
// and the tail (x > r) make the distribution exactly normal.
typedef struct {
    model_rng_t r;
    double      exp_mu, exp_val;   // exp(-exp_mu): dark pixels share their mean
} row_rng_t;

static inline double row_uniform(row_rng_t *g) { return model_rng_uniform(&g->r); }

enum { ZIG_N = 256 };
static const double zig_r = 3.6541528853610088, zig_v = 0.00492867323399;
static double zig_x[ZIG_N + 1], zig_f[ZIG_N + 1];   // layer i spans heights f(x[i])..f(x[i+1]), width x[i]
static pthread_once_t zig_once = PTHREAD_ONCE_INIT;

static void zig_init(void)
{
    zig_x[0] = zig_v / exp(-0.5 * zig_r * zig_r);
    zig_x[1] = zig_r;
    for (int i = 1; i < ZIG_N - 1; i++) {
        double fi = exp(-0.5 * zig_x[i] * zig_x[i]);
        zig_x[i + 1] = sqrt(-2.0 * log(fi + zig_v / zig_x[i]));
    }
    zig_x[ZIG_N] = 0;
    for (int i = 0; i <= ZIG_N; i++) zig_f[i] = exp(-0.5 * zig_x[i] * zig_x[i]);
}

static double zig_slow(row_rng_t *g, int i, double z, bool neg);

static inline double row_gauss(row_rng_t *g)
{
    uint64_t u = model_rng_u64(&g->r);
    int i = (int)(u & (ZIG_N - 1));
    bool neg = (u >> 8) & 1;
    double z = (u >> 11) * 0x1.0p-53 * zig_x[i];
    if (__builtin_expect(z < zig_x[i + 1], 1)) return neg ? -z : z;
    return zig_slow(g, i, z, neg);
}

static double zig_slow(row_rng_t *g, int i, double z, bool neg)
{
    for (;;) {
        if (i == 0) {   // the tail beyond r (Marsaglia's method)
            double a, b;
            do {
                double u1 = row_uniform(g), u2 = row_uniform(g);
                a = -log(1.0 - u1) / zig_r;
                b = -log(1.0 - u2);
            } while (b + b < a * a);
            z = zig_r + a;
            return neg ? -z : z;
        }
        // the wedge of layer i: accept under the density
        double y = zig_f[i] + row_uniform(g) * (zig_f[i + 1] - zig_f[i]);
        if (y < exp(-0.5 * z * z)) return neg ? -z : z;
        uint64_t u = model_rng_u64(&g->r);
        i = (int)(u & (ZIG_N - 1));
        neg = (u >> 8) & 1;
        z = (u >> 11) * 0x1.0p-53 * zig_x[i];
        if (z < zig_x[i + 1]) return neg ? -z : z;
    }
}

// ln k! for k >= 0: a table below 64 (lgamma once), Stirling's series for
// ln Gamma(n), n = k + 1, above (error below 1e-14 there). The acceptance
// test of PTRS needs it per rejected-fast-path draw; lgamma_r was a tenth of
// the sensor stage.
enum { LOGFACT_N = 64 };
static double logfact_tab[LOGFACT_N];
static pthread_once_t logfact_once = PTHREAD_ONCE_INIT;

static void logfact_init(void)
{
    for (int k = 0; k < LOGFACT_N; k++) {
        int sign;
        logfact_tab[k] = lgamma_r(k + 1.0, &sign);
    }
}

static inline double log_factorial(double k)
{
    if (k < LOGFACT_N) return logfact_tab[(int)k];
    double n = k + 1, r = 1 / n, r2 = r * r;
    return (n - 0.5) * log(n) - n + 0.91893853320467274178 + r * (1.0 / 12 - r2 * (1.0 / 360 - r2 / 1260));
}

// Poisson variate with mean mu >= 0.
static double poisson(double mu, row_rng_t *r)
{
    if (mu <= 0) return 0;
    if (mu < 12) {   // inversion
        if (mu != r->exp_mu) {
            r->exp_mu = mu;
            r->exp_val = exp(-mu);
        }
        double u = row_uniform(r), p = r->exp_val, F = p;
        int k = 0;
        while (u > F && k < 200) {
            k++;
            p *= mu / k;
            F += p;
        }
        return k;
    }
    if (mu < 1e7) {
        // PTRS: W. Hoermann, "The transformed rejection method for generating
        // Poisson random variables", Insurance: Mathematics and Economics 12 (1993).
        // The constants of the slow path (log, inv_alpha) only when it is taken.
        double smu = sqrt(mu);
        double b = 0.931 + 2.53 * smu, a = -0.059 + 0.02483 * b;
        double v_r = 0.9277 - 3.6224 / (b - 2);
        for (;;) {
            double U = row_uniform(r) - 0.5, V = row_uniform(r);
            double us = 0.5 - fabs(U);
            double k = floor((2 * a / us + b) * U + mu + 0.43);
            if (us >= 0.07 && V <= v_r) return k;
            if (k < 0 || (us < 0.013 && V > us)) continue;
            double inv_alpha = 1.1239 + 1.1328 / (b - 3.4);
            if (log(V * inv_alpha / (a / (us * us) + b)) <= -mu + k * log(mu) - log_factorial(k)) return k;
        }
    }
    return fmax(0.0, floor(mu + sqrt(mu) * row_gauss(r) + 0.5));
}

typedef struct {
    const model_sensor_t *s;
    int          width, height;
    float       *img;
    const float *prnu, *dsnu;   // may be NULL (flat)
    bool         noise;         // false: the noise-free mean (model_sensor_mean)
} apply_job_t;

static void apply_rows(void *ctx, int begin, int end, int thread)
{
    const apply_job_t *J = ctx;
    const model_sensor_t *s = J->s;
    const double K = s->system_gain_dn_per_e, FW = s->full_well_e;
    const double c = s->nonlinearity_pct / 100.0, c_fw = c / FW;
    const double dark_e = s->dark_current_e_per_s * s->exposure_us * 1e-6;
    const double maxv = s->bits >= 1 && s->bits <= 16 ? (double)((1 << s->bits) - 1) : 65535.0;
    const double cx = 0.5 * (J->width - 1), cy = 0.5 * (J->height - 1);
    const double rc2 = cx * cx + cy * cy;
    const double inv_K = 1.0 / K, kvig = rc2 > 0 ? s->vignetting / rc2 : 0;
    const double Pa = s->dark_offset_dn, sigma_r = s->read_noise_e;
    const bool noise = J->noise;
    const float *prnu = J->prnu, *dsnu = J->dsnu;
    float *img = J->img;
    for (int y = begin; y < end; y++) {
        const double dy2 = (y - cy) * (y - cy);
        row_rng_t r = { model_rng(s->noise_seed, (uint64_t)y), 0, 1 };
        for (int x = 0; x < J->width; x++) {
            size_t i = (size_t)y * J->width + x;
            double sig = img[i] - Pa;
            double mu = dark_e;   // a dark pixel (sig 0, also NaN): the dark current only
            if (sig > 0) {
                double vig = 1.0 - kvig * ((x - cx) * (x - cx) + dy2);
                mu = sig * inv_K * (prnu ? prnu[i] : 1.0) * vig + dark_e;
            }
            if (!(mu > 0)) mu = 0;
            if (mu > 1e15) mu = 1e15;
            double e = mu;
            if (noise) {
                e = poisson(mu, &r);
                if (sigma_r > 0) e += sigma_r * row_gauss(&r);
            }
            if (e > FW) e = FW;
            e *= 1.0 - c_fw * e;
            double dn = e * K + Pa + (dsnu ? dsnu[i] : 0.0);
            if (!(dn >= 0)) dn = 0;   // clamping before rounding gives the same integers
            if (dn > maxv) dn = maxv;
            if (noise) dn = (double)(int64_t)(dn + 0.5);   // floor(dn + 0.5), dn >= 0
            img[i] = (float)dn;
        }
    }
}

// make: compute the fixed patterns here (prnu_gain/dsnu_dn ignored); else
// use the given ones (NULL = flat).
static void apply(const model_sensor_t *s, int width, int height, const float *prnu_gain,
                  const float *dsnu_dn, float *img, bool noise, bool make)
{
    if (width <= 0 || height <= 0 || !img) return;
    size_t n = (size_t)width * height;
    float *prnu = NULL, *dsnu = NULL;
    if (make) {
        prnu = s->prnu_pct != 0 ? malloc(n * sizeof(float)) : NULL;
        dsnu = s->dsnu_dn != 0 ? malloc(n * sizeof(float)) : NULL;
        if ((s->prnu_pct != 0 && !prnu) || (s->dsnu_dn != 0 && !dsnu))
            MODEL_FAIL("out of memory for %dx%d sensor patterns; applying flat patterns", width, height);
        if (prnu || dsnu) model_sensor_patterns(s, width, height, prnu, dsnu);
        prnu_gain = prnu;
        dsnu_dn = dsnu;
    }
    if (noise) {
        pthread_once(&zig_once, zig_init);
        pthread_once(&logfact_once, logfact_init);
    }
    apply_job_t J = { s, width, height, img, prnu_gain, dsnu_dn, noise };
    model_parallel_for(height, 8, model_default_threads(), apply_rows, &J);
    free(prnu);
    free(dsnu);
}

void model_sensor_apply(const model_sensor_t *s, int width, int height, float *img)
{
    apply(s, width, height, NULL, NULL, img, true, true);
}

void model_sensor_apply_patterns(const model_sensor_t *s, int width, int height, const float *prnu_gain,
                                 const float *dsnu_dn, float *img)
{
    apply(s, width, height, prnu_gain, dsnu_dn, img, true, false);
}

void model_sensor_mean(const model_sensor_t *s, int width, int height, const float *prnu_gain,
                       const float *dsnu_dn, float *img)
{
    apply(s, width, height, prnu_gain, dsnu_dn, img, false, false);
}
