// model/sensor.c — the sensor stage: from the ideal grey value P (DN) of the
// imaging model to the integers a camera delivers (EMVA 1288 style model).
//
// Per pixel (x, y), with K = system_gain_dn_per_e and FW = full_well_e:
//   mu    = max(0, P - dark_offset_dn) / K * prnu(x,y) * vig(x,y)
//           + dark_current_e_per_s * exposure_us * 1e-6             (electrons)
//   n     = Poisson(mu): exact (inversion for mu < 12, Hoermann's PTRS
//           transformed rejection for 12 <= mu < 1e7, W. Hoermann, "The
//           transformed rejection method for generating Poisson random
//           variables", Insurance: Mathematics and Economics 12 (1993)),
//           normal above 1e7
//   e     = n + read_noise_e * N(0,1)
//   e     = min(e, FW)                                  (the well saturates)
//   e_nl  = e * (1 - c * e / FW),  c = nonlinearity_pct / 100
//           (a quadratic compression: smooth, monotonic for c < 0.5, exactly
//           c*100 % below linear at e = FW, 0 at e = 0)
//   DN    = round(e_nl * K + dark_offset_dn + dsnu(x,y)), clipped to [0, 2^bits - 1]
// Beyond that model (the virtual rig's adversary; all off by default, and then
// every value is that of the model above):
//   hot pixels  a fixed share hot_pixel_fraction of the pixels (chosen by
//               pattern_seed) add hot_pixel_dark_current_e_per_s * exposure to mu;
//   response    applied to e before the well's clip: first a gamma at the low
//               end, e = low_end_e * (e / low_end_e)^low_end_gamma for
//               0 < e < low_end_e (continuous at low_end_e), then a soft knee,
//               e = k + (FW - k) tanh((e - k) / (FW - k)) above k = knee_e
//               (slope 1 at k, tends to FW; knee_e >= FW: no knee). Neither
//               is the quadratic S(1 - aS) the fitters linearise.
//   row noise   each row of each frame is offset by row_noise_dn * N(0,1)
//               (DN, drawn from model_rng(noise_seed ^ ROW_OFFSET_STREAM, row));
//               the mean (model_sensor_mean) has none.
// Vignetting: vig(x,y) = 1 - vignetting * (r / r_corner)^2, r the distance from
// the image centre ((width-1)/2, (height-1)/2) and r_corner that of pixel (0,0);
// vignetting is the relative fall-off at the corners.
// Non-finite P is treated as dark (P = dark offset); mu is capped at 1e15; a
// negative gain (prnu_pct near its upper limit of 50) gives no signal.
// Temporal noise: per row, counter-based draws of model_rng(noise_seed, row),
// three per pixel at fixed positions, and a second stream for the few pixels
// that need more (see row_draw); normal values by a ziggurat. Reproducible,
// independent of the number of threads and of the instruction set.
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
#include <strings.h>

#include "model/internal.h"

// model_sensor_default() lives with the sensor file parser in model/config.c.

// ---------------------------------------------------------------------------
// Fixed patterns

// Random streams of the patterns (high byte; the low bits index pixel, column or row).
enum { STREAM_PIXEL = 1, STREAM_COLUMN = 2, STREAM_ROW = 3, STREAM_HOT = 4 };
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
// test of PTRS needs it per rejected-fast-path draw, where lgamma_r would
// take a tenth of the sensor stage's time.
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

// Poisson variate with mean mu >= 0 whose first draws were taken by the
// vectorised pass (row_draw) and did not settle it: u0 (the first uniform)
// for the inversion below 12; for PTRS the first pair (U = u0 - 0.5, V) is
// tested in full, then r gives new pairs; above 1e7 the normal approximation
// draws from r.
static double poisson_rest(double mu, double u0, double V, row_rng_t *r)
{
    if (mu <= 0) return 0;
    if (mu < 12) {   // inversion with the first uniform
        if (mu != r->exp_mu) {
            r->exp_mu = mu;
            r->exp_val = exp(-mu);
        }
        double p = r->exp_val, F = p;
        int k = 0;
        while (u0 > F && k < 200) {
            k++;
            p *= mu / k;
            F += p;
        }
        return k;
    }
    if (mu < 1e7) {
        double smu = sqrt(mu);
        double b = 0.931 + 2.53 * smu, a = -0.059 + 0.02483 * b;
        double v_r = 0.9277 - 3.6224 / (b - 2);
        double U = u0 - 0.5;
        for (;;) {
            double us = 0.5 - fabs(U);
            double k = floor((2 * a / us + b) * U + mu + 0.43);
            if (us >= 0.07 && V <= v_r) return k;
            if (!(k < 0 || (us < 0.013 && V > us))) {
                double inv_alpha = 1.1239 + 1.1328 / (b - 3.4);
                if (log(V * inv_alpha / (a / (us * us) + b)) <= -mu + k * log(mu) - log_factorial(k)) return k;
            }
            U = row_uniform(r) - 0.5;
            V = row_uniform(r);
        }
    }
    return fmax(0.0, floor(mu + sqrt(mu) * row_gauss(r) + 0.5));
}

enum { NDARK = 8 };

typedef struct {
    const model_sensor_t *s;
    int          width, height;
    float       *img;
    const float *prnu, *dsnu;   // may be NULL (flat)
    bool         noise;         // false: the noise-free mean (model_sensor_mean)
    // Poisson by inversion at the dark mean (pixels without signal):
    // dark_F[j] = P(n <= j) for j < n_dark, 2 (above any uniform) after;
    // dark_mu < 0 when not used
    double       dark_mu, dark_F[NDARK];
    int          n_dark;
} apply_job_t;

// The sensor stage runs by rows in three passes, the first and last
// vectorised (clones for AVX-512 and AVX2 where the compiler supports them;
// sensor.c is compiled without FMA contraction, so every clone gives the same
// values):
//   row_mu    mu of every pixel (electrons);
//   row_draw  the first try of each pixel's draws: pixel x of row y takes
//             draws 3x+1, 3x+2, 3x+3 of the row's stream (counter-based:
//             draw n = mix64(s_y + n * gamma), s_y = model_rng(noise_seed, y)):
//             u0 and V for the Poisson variate (PTRS's first pair, or u0 for
//             the inversion at the dark mean), the third for the read noise
//             (the ziggurat's fast path); flags what that did not settle;
//   (scalar)  the flagged pixels in order, continuing from their first draws
//             with the row's second stream model_rng(noise_seed ^ OVERFLOW, y)
//             (rejection steps, the inversion at other means below 12, the
//             ziggurat's slow path, means above 1e7);
//   row_dn    electrons to digital numbers.
// Rejection methods need only independent uniforms, so the distributions are
// exact, as in a purely sequential stream.
#define ROW_GAMMA 0x9e3779b97f4a7c15ULL
#define OVERFLOW_STREAM 0x5bd1e9955bd1e995ULL

#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__) && !defined(__SANITIZE_ADDRESS__)
#define SENSOR_CLONES __attribute__((target_clones("arch=x86-64-v4", "arch=x86-64-v3", "default")))
#else
#define SENSOR_CLONES
#endif

// flat: a row of ones (for a NULL prnu)
SENSOR_CLONES
static void row_mu(const apply_job_t *J, int y, const float *restrict flat, double *restrict mu)
{
    const model_sensor_t *s = J->s;
    const int W = J->width;
    const double K = s->system_gain_dn_per_e;
    const double dark_e = s->dark_current_e_per_s * s->exposure_us * 1e-6;
    const double cx = 0.5 * (W - 1), cy = 0.5 * (J->height - 1);
    const double rc2 = cx * cx + cy * cy;
    const double inv_K = 1.0 / K, kvig = rc2 > 0 ? s->vignetting / rc2 : 0;
    const double Pa = s->dark_offset_dn, dy2 = (y - cy) * (y - cy);
    const float *restrict img = J->img + (size_t)y * W;
    const float *restrict prnu = J->prnu ? J->prnu + (size_t)y * W : flat;
    for (int x = 0; x < W; x++) {
        double sig = img[x] - Pa;
        double vig = 1.0 - kvig * ((x - cx) * (x - cx) + dy2);
        double g = prnu[x];
        // a dark pixel (sig 0, also NaN): the dark current only
        double m = sig > 0 ? sig * inv_K * g * vig + dark_e : dark_e;
        m = m > 0 ? m : 0;
        mu[x] = m < 1e15 ? m : 1e15;
    }
}

static inline uint64_t row_draw_u64(uint64_t base, uint64_t n) { return model_mix64(base + n * ROW_GAMMA); }

SENSOR_CLONES
static void row_draw(const apply_job_t *J, uint64_t base, const double *restrict mu, double *restrict kout,
                     double *restrict zout, uint8_t *restrict slow)
{
    const int W = J->width;
    const bool read_noise = J->s->read_noise_e > 0;
    const double dark_mu = J->dark_mu, dark_last = J->dark_F[J->n_dark - 1];
    double F[NDARK];
    memcpy(F, J->dark_F, sizeof F);
    for (int x = 0; x < W; x++) {
        uint64_t n = 3 * (uint64_t)x;
        uint64_t d0 = row_draw_u64(base, n + 1), d1 = row_draw_u64(base, n + 2), d2 = row_draw_u64(base, n + 3);
        double m = mu[x];
        double u0 = (double)(d0 >> 11) * 0x1.0p-53, V = (double)(d1 >> 11) * 0x1.0p-53;
        // PTRS's fast acceptance (see poisson_rest)
        double U = u0 - 0.5, smu = sqrt(m);
        double b = 0.931 + 2.53 * smu, a = -0.059 + 0.02483 * b;
        double v_r = 0.9277 - 3.6224 / (b - 2);
        double us = 0.5 - fabs(U);
        double kp = floor((2 * a / us + b) * U + m + 0.43);
        int ok_p = (m >= 12) & (m < 1e7) & (us >= 0.07) & (V <= v_r);
        // inversion at the dark mean: the number of F_j below u0
        double kd = 0;
#pragma GCC unroll 8
        for (int j = 0; j < NDARK; j++) kd += u0 > F[j] ? 1.0 : 0.0;
        int ok_d = (m == dark_mu) & (u0 <= dark_last);
        // the ziggurat's fast path (see row_gauss)
        int64_t zi = (int64_t)(d2 & (ZIG_N - 1));
        double z = (double)(d2 >> 11) * 0x1.0p-53 * zig_x[zi];
        int ok_z = !read_noise | (z < zig_x[zi + 1]);
        kout[x] = ok_d ? kd : kp;
        zout[x] = (d2 >> 8) & 1 ? -z : z;
        slow[x] = (uint8_t)(((ok_p | ok_d) ^ 1) | ((ok_z ^ 1) << 1));
    }
}

// The flagged pixels of a row (see above), in order.
static void row_slow(const apply_job_t *J, int y, uint64_t base, const double *mu, double *k, double *z,
                     const uint8_t *slow)
{
    row_rng_t r = { model_rng(J->s->noise_seed ^ OVERFLOW_STREAM, (uint64_t)y), -1, 0 };
    for (int x = 0; x < J->width; x++) {
        if (!slow[x]) continue;
        uint64_t n = 3 * (uint64_t)x;
        if (slow[x] & 1) {
            uint64_t d0 = row_draw_u64(base, n + 1), d1 = row_draw_u64(base, n + 2);
            k[x] = poisson_rest(mu[x], (double)(d0 >> 11) * 0x1.0p-53, (double)(d1 >> 11) * 0x1.0p-53, &r);
        }
        if (slow[x] & 2) {
            uint64_t d2 = row_draw_u64(base, n + 3);
            int zi = (int)(d2 & (ZIG_N - 1));
            z[x] = zig_slow(&r, zi, (double)(d2 >> 11) * 0x1.0p-53 * zig_x[zi], (d2 >> 8) & 1);
        }
    }
}

// k, z: the Poisson and normal variates (noise), or mu and zeros (the mean);
// dsnu: the row's offsets (DN)
SENSOR_CLONES
static void row_dn(const apply_job_t *J, int y, const float *restrict dsnu, const double *restrict k,
                   const double *restrict z)
{
    const model_sensor_t *s = J->s;
    const int W = J->width;
    const double K = s->system_gain_dn_per_e, FW = s->full_well_e;
    const double c = s->nonlinearity_pct / 100.0, c_fw = c / FW;
    const double maxv = s->bits >= 1 && s->bits <= 16 ? (double)((1 << s->bits) - 1) : 65535.0;
    const double Pa = s->dark_offset_dn, sigma_r = J->noise && s->read_noise_e > 0 ? s->read_noise_e : 0;
    const bool noise = J->noise;
    float *restrict img = J->img + (size_t)y * W;
#define DN_LOOP(ROUND)                                                                   \
    for (int x = 0; x < W; x++) {                                                        \
        double e = k[x] + sigma_r * z[x];                                                \
        e = e < FW ? e : FW;                                                             \
        e *= 1.0 - c_fw * e;                                                             \
        double dn = e * K + Pa + dsnu[x];                                                \
        dn = dn >= 0 ? dn : 0; /* clamped before rounding (the same integers); NaN -> 0 */ \
        dn = dn < maxv ? dn : maxv;                                                      \
        img[x] = (float)ROUND(dn);                                                       \
    }
#define DN_ROUND(dn) floor((dn) + 0.5)
#define DN_KEEP(dn)  (dn)
    if (noise) {
        DN_LOOP(DN_ROUND)
    } else {
        DN_LOOP(DN_KEEP)
    }
#undef DN_LOOP
#undef DN_ROUND
#undef DN_KEEP
}

// The adversary's effects (see the top of the file), each only when it is on.
static bool hot_on(const model_sensor_t *s)
{
    return s->hot_pixel_fraction > 0 && s->hot_pixel_dark_current_e_per_s > 0 && s->exposure_us > 0;
}

static bool response_on(const model_sensor_t *s)
{
    return (s->knee_e > 0 && s->knee_e < s->full_well_e) || (s->low_end_gamma != 1 && s->low_end_e > 0);
}

#define ROW_OFFSET_STREAM 0x2545f4914f6cdd1dULL

// A pixel is hot when its uniform draw of pattern_seed is below the fraction.
static void row_hot(const apply_job_t *J, int y, double *mu)
{
    const model_sensor_t *s = J->s;
    const double extra = s->hot_pixel_dark_current_e_per_s * s->exposure_us * 1e-6;
    for (int x = 0; x < J->width; x++) {
        model_rng_t r = model_rng(s->pattern_seed, STREAM(STREAM_HOT, (size_t)y * J->width + x));
        if (model_rng_uniform(&r) < s->hot_pixel_fraction) mu[x] = fmin(mu[x] + extra, 1e15);
    }
}

static double response(const model_sensor_t *s, double e)
{
    const double g = s->low_end_gamma, el = s->low_end_e, FW = s->full_well_e, k = s->knee_e;
    if (g != 1 && el > 0 && e > 0 && e < el) e = el * pow(e / el, g);
    if (k > 0 && k < FW && e > k) e = k + (FW - k) * tanh((e - k) / (FW - k));
    return e;
}

// The response applied to the electrons k + read noise (folded into k, z = 0).
static void row_response(const apply_job_t *J, double *k, double *z)
{
    const double sr = J->noise && J->s->read_noise_e > 0 ? J->s->read_noise_e : 0;
    for (int x = 0; x < J->width; x++) {
        k[x] = response(J->s, k[x] + sr * z[x]);
        z[x] = 0;
    }
}

// The row's offsets: dsnu (or zeros) plus this frame's row offset (if any).
static const float *row_offsets(const apply_job_t *J, int y, const float *zeros, float *scratch)
{
    const float *d = J->dsnu ? J->dsnu + (size_t)y * J->width : zeros;
    if (!J->noise || !(J->s->row_noise_dn > 0)) return d;
    model_rng_t r = model_rng(J->s->noise_seed ^ ROW_OFFSET_STREAM, (uint64_t)y);
    double a, b;
    gauss_pair(&r, &a, &b);
    float off = (float)(J->s->row_noise_dn * a);
    for (int x = 0; x < J->width; x++) scratch[x] = d[x] + off;
    return scratch;
}

static void apply_rows(void *ctx, int begin, int end, int thread)
{
    (void)thread;
    const apply_job_t *J = ctx;
    const int W = J->width;
    // row scratch: mu, k, z (doubles), ones, zeros, offsets (floats), flags
    double *buf = malloc((size_t)W * (3 * sizeof(double) + 3 * sizeof(float) + 1));
    if (!buf) {   // no way to report from a worker: leave these rows as they are
        MODEL_FAIL("out of memory for the sensor stage's row buffers (%d pixels)", W);
        return;
    }
    double *mu = buf, *k = buf + W, *z = buf + 2 * (size_t)W;
    float *ones = (float *)(buf + 3 * (size_t)W), *zeros = ones + W, *offs = zeros + W;
    uint8_t *slow = (uint8_t *)(offs + W);
    const bool hot = hot_on(J->s), resp = response_on(J->s);
    for (int x = 0; x < W; x++) {
        ones[x] = 1.0f;
        zeros[x] = 0.0f;
    }
    for (int y = begin; y < end; y++) {
        row_mu(J, y, ones, mu);
        if (hot) row_hot(J, y, mu);
        const float *d = row_offsets(J, y, zeros, offs);
        if (J->noise) {
            uint64_t base = model_rng(J->s->noise_seed, (uint64_t)y).s;
            row_draw(J, base, mu, k, z, slow);
            row_slow(J, y, base, mu, k, z, slow);
            if (resp) row_response(J, k, z);
            row_dn(J, y, d, k, z);
        } else {
            memset(z, 0, (size_t)W * sizeof *z);
            if (resp) row_response(J, mu, z);
            row_dn(J, y, d, mu, z);
        }
    }
    free(buf);
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
    apply_job_t J = { s, width, height, img, prnu_gain, dsnu_dn, noise, -1, { 0 }, 1 };
    // P(n <= j) at the dark mean, as the inversion sums it (poisson_rest), up
    // to 1 - 1e-6 or NDARK terms; the rest of the tail goes the scalar way
    for (int j = 0; j < NDARK; j++) J.dark_F[j] = 2;
    const double dark_e = s->dark_current_e_per_s * s->exposure_us * 1e-6;
    if (noise && dark_e >= 0 && dark_e < 12) {
        double p = exp(-dark_e), F = p;
        J.dark_mu = dark_e;
        J.dark_F[0] = F;
        J.n_dark = 1;
        for (int j = 1; j < NDARK && F < 1 - 1e-6; j++) {
            p *= dark_e / j;
            F += p;
            J.dark_F[J.n_dark++] = F;
        }
    }
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

// ---------------------------------------------------------------------------
// What a measurement to EMVA 1288's definitions reads from the dark frames

// A pixel's DN above the offset (no DSNU, no rounding) for e electrons in the
// well (signal + read noise): the same chain as row_dn's.
static double dark_dn_of(const model_sensor_t *s, double e)
{
    if (response_on(s)) e = response(s, e);
    const double FW = s->full_well_e, c = s->nonlinearity_pct / 100.0;
    e = e < FW ? e : FW;
    e *= 1.0 - c / FW * e;
    return e * s->system_gain_dn_per_e;
}

// E and E[x^2] over the read noise of dark_dn_of(n + sigma z): the trapezoid
// rule on z in [-10, 10] at 1/200 (the response bends at e = 0 and at the
// low end's top; the rule's error there is of order h^2 of the bend).
static void dark_moments(const model_sensor_t *s, double n, double *m1, double *m2)
{
    const double sr = s->read_noise_e > 0 ? s->read_noise_e : 0;
    if (!(sr > 0)) {
        double f = dark_dn_of(s, n);
        *m1 = f;
        *m2 = f * f;
        return;
    }
    const int N = 4000;
    const double h = 20.0 / N;
    double a = 0, b = 0, wsum = 0;
    for (int i = 0; i <= N; i++) {
        double z = -10 + i * h, w = exp(-0.5 * z * z) * (i == 0 || i == N ? 0.5 : 1);
        double f = dark_dn_of(s, n + sr * z);
        a += w * f;
        b += w * f * f;
        wsum += w;
    }
    *m1 = a / wsum;
    *m2 = b / wsum;
}

// The mean DN above the offset of a dark pixel with mu electrons of dark
// signal (Poisson, its terms in logs: mu may be thousands) and the read
// noise; var: its temporal variance.
static void dark_pixel(const model_sensor_t *s, double mu, double *mean, double *var)
{
    double e1 = 0, e2 = 0;
    if (!(mu > 0)) {
        dark_moments(s, 0, &e1, &e2);
    } else {
        int lo = (int)fmax(0, floor(mu - 12 * sqrt(mu) - 12)), hi = (int)ceil(mu + 12 * sqrt(mu) + 12);
        double ps = 0;
        for (int n = lo; n <= hi; n++) {
            double p = exp(n * log(mu) - mu - lgamma(n + 1.0));
            if (!(p > 1e-17)) continue;
            double m1, m2;
            dark_moments(s, n, &m1, &m2);
            e1 += p * m1;
            e2 += p * m2;
            ps += p;
        }
        e1 /= ps;
        e2 /= ps;
    }
    *mean = e1;
    *var = fmax(e2 - e1 * e1, 0);
}

bool model_sensor_dark_measurand(const model_sensor_t *s, const double *t_us, int nt, double *read_noise_e,
                                 double *dark_current_e_per_s)
{
    const double K = s->system_gain_dn_per_e;
    double tmin = INFINITY, tmax = -INFINITY;
    for (int i = 0; t_us && i < nt; i++) {
        if (!(t_us[i] >= 0 && t_us[i] < 1e12)) tmin = NAN;
        tmin = fmin(tmin, t_us[i]);
        tmax = fmax(tmax, t_us[i]);
    }
    if (!(K > 0) || !(s->full_well_e > 0) || (dark_current_e_per_s && !(nt >= 2 && tmax > tmin && tmin >= 0))) {
        model_error_set(NULL, 0, "dark measurand: K %g DN/e- and full well %g e- must be > 0, and the dark current "
                        "needs at least 2 different exposures >= 0 (%d given)", K, s->full_well_e, nt);
        return false;
    }
    double m0, v0;
    dark_pixel(s, 0, &m0, &v0);
    double row = s->row_noise_dn > 0 ? s->row_noise_dn : 0;
    if (read_noise_e) *read_noise_e = sqrt(v0 + row * row) / K;
    if (dark_current_e_per_s) {
        // the mean dark level at each exposure (hot pixels' share added), and
        // its least-squares line against exposure, as the calibration fits it
        const double dc = fmax(s->dark_current_e_per_s, 0);
        const double h = s->hot_pixel_fraction > 0 && s->hot_pixel_dark_current_e_per_s > 0 ? s->hot_pixel_fraction : 0;
        double st = 0, sy = 0, stt = 0, sty = 0;
        for (int i = 0; i < nt; i++) {
            double t = t_us[i] * 1e-6, m, v, mh = 0, vh;
            dark_pixel(s, dc * t, &m, &v);
            if (h > 0) dark_pixel(s, (dc + s->hot_pixel_dark_current_e_per_s) * t, &mh, &vh);
            double y = (1 - h) * m + h * mh;
            st += t;
            sy += y;
            stt += t * t;
            sty += t * y;
        }
        *dark_current_e_per_s = (nt * sty - st * sy) / (nt * stt - st * st) / K;
    }
    return true;
}

// ---------------------------------------------------------------------------
// Gain units

typedef enum { GAIN_DB, GAIN_LINEAR, GAIN_OTHER } gain_unit_t;

static gain_unit_t gain_unit_kind(const char *unit)
{
    if (!unit || !*unit || !strcasecmp(unit, "dB")) return GAIN_DB;   // "": a frame without a unit, GenICam's Gain
    static const char *const linear[] = { "x", "times", "linear", "factor" };
    for (size_t i = 0; i < sizeof linear / sizeof linear[0]; i++)
        if (!strcasecmp(unit, linear[i])) return GAIN_LINEAR;
    return GAIN_OTHER;
}

// The factor of a gain in a known unit (false for a linear gain <= 0 or not finite).
static bool gain_linear(double gain, gain_unit_t k, double *f)
{
    *f = k == GAIN_DB ? pow(10.0, gain / 20.0) : gain;
    return isfinite(gain) && isfinite(*f) && *f > 0;
}

bool model_gain_factor(double gain, const char *unit, double cal_gain, const char *cal_unit, const char *what,
                       double *factor)
{
    const char *w = what && *what ? what : "gain";
    const char *u = unit && *unit ? unit : "dB";
    const char *cu = cal_unit && *cal_unit ? cal_unit : "dB";
    gain_unit_t k = gain_unit_kind(unit), ck = gain_unit_kind(cal_unit);
    if (k == GAIN_OTHER || ck == GAIN_OTHER) {
        if (!strcmp(u, cu) && gain == cal_gain) {
            *factor = 1;
            return true;
        }
        model_error_set(NULL, 0, "%s: gain %.10g in unit '%s' has no known scale (not dB or a factor): only frames "
                        "at the calibration's gain (%.10g %s) are usable; capture at that gain", w, gain, u, cal_gain,
                        cu);
        return false;
    }
    double f, fc;
    if (!gain_linear(gain, k, &f) || !gain_linear(cal_gain, ck, &fc)) {
        model_error_set(NULL, 0, "%s: gain %.10g %s (calibration at %.10g %s) is not a usable gain", w, gain, u,
                        cal_gain, cu);
        return false;
    }
    *factor = f / fc;
    return true;
}

// ---------------------------------------------------------------------------
// Response linearisation (model.h: model_lin_t)

// The monotone table at x (measured DN above dark at the calibration's gain).
static double lin_table(const model_lin_t *L, double x, double *slope)
{
    const int n = L->n;
    if (x <= L->m[0]) {
        *slope = L->d[0];
        return L->s[0] + L->d[0] * (x - L->m[0]);
    }
    if (x >= L->m[n - 1]) {
        *slope = L->d[n - 1];
        return L->s[n - 1] + L->d[n - 1] * (x - L->m[n - 1]);
    }
    return model_pchip_eval(L->m, L->s, L->d, n, x, slope);
}

double model_linearise(const model_lin_t *L, double s_m, double gf, double *slope)
{
    double sl = 1, S = s_m;
    if (!(gf > 0)) gf = 1;
    if (L && L->kind == MODEL_LIN_PARAMETRIC && L->a_per_dn > 0 && s_m > 0) {
        // the root of S_m = S (1 - a' S), a' = a / gf, that goes to S_m as a -> 0
        double a = L->a_per_dn / gf, disc = 1 - 4 * a * s_m;
        if (disc > 0) {
            S = 2 * s_m / (1 + sqrt(disc));
            sl = 1 / sqrt(disc);
        }
    } else if (L && L->kind == MODEL_LIN_MONOTONE && L->n >= 2 && isfinite(s_m)) {
        S = gf * lin_table(L, s_m / gf, &sl);
    }
    if (slope) *slope = sl;
    return S;
}

// Fritsch & Butland's knot derivatives (the weighted harmonic mean of the
// neighbouring secants; 0 at a local extremum) with the one-sided
// three-point ends limited as Fritsch & Carlson's monotone region asks
// (|d| <= 3 secant): the interpolant is monotone on every interval.
static void lin_derivatives(model_lin_t *L)
{
    model_pchip_slopes(L->m, L->s, L->n, L->d);
}

bool model_lin_monotone(const double *m, const double *s, int n, model_lin_t *out)
{
    memset(out, 0, sizeof *out);
    double *bm = malloc((size_t)(n > 0 ? n : 1) * 3 * sizeof(double)), *bs = bm + (n > 0 ? n : 1),
           *bw = bs + (n > 0 ? n : 1);
    if (!bm) {
        model_error_set(NULL, 0, "out of memory for a linearisation table of %d points", n);
        return false;
    }
    // pool adjacent violators: m non-decreasing in the order given; each
    // block keeps its mean m and mean s (weights: the points it pools)
    int nb = 0;
    for (int i = 0; i < n; i++) {
        if (!isfinite(m[i]) || !isfinite(s[i]) || (i > 0 && !(s[i] > s[i - 1]))) {
            free(bm);
            model_error_set(NULL, 0, "linearisation table: point %d (measured %g, linear %g) is not finite or the "
                            "linear signal does not increase", i, m[i], s[i]);
            return false;
        }
        bm[nb] = m[i];
        bs[nb] = s[i];
        bw[nb] = 1;
        nb++;
        while (nb > 1 && bm[nb - 2] >= bm[nb - 1]) {
            double w = bw[nb - 2] + bw[nb - 1];
            bm[nb - 2] = (bw[nb - 2] * bm[nb - 2] + bw[nb - 1] * bm[nb - 1]) / w;
            bs[nb - 2] = (bw[nb - 2] * bs[nb - 2] + bw[nb - 1] * bs[nb - 1]) / w;
            bw[nb - 2] = w;
            nb--;
        }
    }
    int first = 0;
    while (first < nb && !(bm[first] > 0 && bs[first] > 0)) first++;
    // knots much closer than their neighbours (two sweeps' steps side by side)
    // make the knot slopes follow the means' noise: a knot nearer the last
    // kept one than min(20 % of its level, half the median spacing) is pooled
    // with it
    if (nb - first >= 3) {
        double *h = malloc(sizeof(double) * (size_t)(nb - first));
        int nh = 0;
        for (int i = first + 1; h && i < nb; i++) h[nh++] = bm[i] - bm[i - 1];
        if (h) {
            qsort(h, (size_t)nh, sizeof *h, model_cmp_double);
            double med = h[nh / 2];
            free(h);
            int k = first;
            for (int i = first + 1; i < nb; i++) {
                if (bm[i] - bm[k] < fmin(0.2 * bm[k], 0.5 * med)) {
                    double w = bw[k] + bw[i];
                    bm[k] = (bw[k] * bm[k] + bw[i] * bm[i]) / w;
                    bs[k] = (bw[k] * bs[k] + bw[i] * bs[i]) / w;
                    bw[k] = w;
                } else {
                    k++;
                    bm[k] = bm[i];
                    bs[k] = bs[i];
                    bw[k] = bw[i];
                }
            }
            nb = k + 1;
        }
    }
    int avail = nb - first, keep = avail < MODEL_LIN_MAX - 1 ? avail : MODEL_LIN_MAX - 1;
    out->m[0] = out->s[0] = 0;
    out->n = 1;
    for (int j = 0; j < keep; j++) {
        int i = first + (keep > 1 ? (int)((double)j * (avail - 1) / (keep - 1) + 0.5) : 0);
        out->m[out->n] = bm[i];
        out->s[out->n] = bs[i];
        out->n++;
    }
    free(bm);
    if (out->n < 2) {
        model_error_set(NULL, 0, "linearisation table: no point with a positive signal (of %d)", n);
        out->n = 0;
        return false;
    }
    out->kind = MODEL_LIN_MONOTONE;
    lin_derivatives(out);
    return true;
}

bool model_lin_knots(const double *m, const double *s, int n, model_lin_t *out)
{
    memset(out, 0, sizeof *out);
    if (n < 2 || n > MODEL_LIN_MAX) {
        model_error_set(NULL, 0, "linearisation table: %d knots (2 to %d)", n, MODEL_LIN_MAX);
        return false;
    }
    for (int i = 0; i < n; i++) {
        if (!isfinite(m[i]) || !isfinite(s[i]) || (i > 0 && !(m[i] > m[i - 1] && s[i] > s[i - 1]))) {
            model_error_set(NULL, 0, "linearisation table: knot %d (measured %g, linear %g): both must be finite "
                            "and strictly increasing", i, m[i], s[i]);
            return false;
        }
        out->m[i] = m[i];
        out->s[i] = s[i];
    }
    out->n = n;
    out->kind = MODEL_LIN_MONOTONE;
    lin_derivatives(out);
    return true;
}
