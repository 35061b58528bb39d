// model/brdf/table.c — tabulated isotropic BRDFs in MERL's binary layout (the
// one owner of that format: refl fit brdf reads it through here, refl brdf
// tabulate writes it, [material NAME] model = table renders it).
//
// The file: 3 int32 dims 90 90 180 (theta_h, theta_d, phi_d), then three
// channels (red, green, blue) of 90*90*180 doubles each, index
// (i*90 + j)*180 + k. Cell (i, j, k) holds f_r at its centre:
//   theta_h = ((i + 0.5)/90)^2 * pi/2   (square-root mapped: fine near the mirror direction)
//   theta_d = (j + 0.5)/90 * pi/2,  phi_d = (k + 0.5)/180 * pi
// each channel divided by MERL's channel scale (1/1500, 1.15/1500, 1.66/1500);
// a negative value marks a missing sample. refl is monochrome: it reads
// f = 0.2126 r + 0.7152 g + 0.0722 b (Rec. 709 luminance of the scaled
// channels) and writes the same f in every channel (each divided by its own
// scale), so a MERL reader with the standard scales sees f in all three.
//
// Evaluation: (theta_h, theta_d, phi_d) from the four cosines (an isotropic
// BRDF depends on no more), trilinear interpolation between cell centres
// (clamped in theta_h and theta_d, periodic in phi_d with period pi), and the
// mean of the values at phi_d and pi - phi_d: exchanging l and v maps phi_d to
// pi - phi_d, so the result is reciprocal for any table, measured ones too.
#include <errno.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "model/internal.h"

enum { TH = MODEL_MERL_TH, TD = MODEL_MERL_TD, PD = MODEL_MERL_PD };
#define NCELLS ((size_t)TH * TD * PD)
#define FILE_BYTES (12 + 3 * NCELLS * sizeof(double))

static const double merl_scale[3] = { 1.0 / 1500, 1.15 / 1500, 1.66 / 1500 };
static const double luma[3] = { 0.2126, 0.7152, 0.0722 };

struct model_brdf_table {
    double *f;            // NCELLS values of f_r, NAN = missing
    char    sha256[65];   // of the file read (empty for a table made in memory)
};

model_brdf_table_t *model_brdf_table_new(void)
{
    model_brdf_table_t *t = calloc(1, sizeof *t);
    if (t) t->f = calloc(NCELLS, sizeof *t->f);
    if (!t || !t->f) {
        model_brdf_table_free(t);
        model_error(NULL, 0, "out of memory for a BRDF table (%zu MB)", NCELLS * sizeof(double) >> 20);
        return NULL;
    }
    return t;
}

void model_brdf_table_free(model_brdf_table_t *t)
{
    if (!t) return;
    free(t->f);
    free(t);
}

double *model_brdf_table_values(model_brdf_table_t *t) { return t ? t->f : NULL; }
const double *model_brdf_table_values_const(const model_brdf_table_t *t) { return t ? t->f : NULL; }
const char *model_brdf_table_sha256(const model_brdf_table_t *t) { return t ? t->sha256 : ""; }

void model_brdf_table_cell(int i, int j, int k, model_cosines_t *c)
{
    double th = (i + 0.5) / TH;
    th = th * th * (M_PI / 2);
    double td = (j + 0.5) / TD * (M_PI / 2), pd = (k + 0.5) / PD * M_PI;
    // l: the difference vector rotated by theta_h about the binormal; v: its
    // mirror about h. Only the cosines matter.
    double dx = sin(td) * cos(pd), dz = cos(td);
    c->nl = -dx * sin(th) + dz * cos(th);
    c->nv = 2 * cos(td) * cos(th) - c->nl;
    c->nh = cos(th);
    c->vh = cos(td);
}

// The measure of cell (i, j, k) in (omega_i, omega_o): d omega_i d omega_o =
// 4 cos(theta_d) d omega_h d omega_d (for fixed l, d omega_v = 4 (l.h) d omega_h),
// integrated over the cell, phi_h over 2 pi (isotropy) and both phi_d and
// phi_d + pi (the table folds them), in sr^2.
double model_brdf_table_cell_solid_angle(int i, int j, int k)
{
    double h0 = (double)i / TH, h1 = (double)(i + 1) / TH;
    h0 = h0 * h0 * (M_PI / 2);
    h1 = h1 * h1 * (M_PI / 2);
    double d0 = (double)j / TD * (M_PI / 2), d1 = (double)(j + 1) / TD * (M_PI / 2);
    double s0 = sin(d0), s1 = sin(d1);
    (void)k;
    return 2 * M_PI * 2 * (M_PI / PD) * 4 * 0.5 * (s1 * s1 - s0 * s0) * (cos(h0) - cos(h1));
}

bool model_brdf_table_sniff(const unsigned char head[12], size_t file_bytes)
{
    int32_t d[3];
    memcpy(d, head, 12);
    return d[0] == TH && d[1] == TD && d[2] == PD && file_bytes == FILE_BYTES;
}

model_brdf_table_t *model_brdf_table_load(const char *path) { return model_brdf_table_load_channel(path, 0); }

// ch: 0 the luminance, 1..3 red, green or blue alone (model_channel_t).
model_brdf_table_t *model_brdf_table_load_channel(const char *path, int ch)
{
    size_t len = 0;
    unsigned char *b = (unsigned char *)model_read_file(path, &len);
    if (!b) return NULL;
    int32_t d[3] = { 0, 0, 0 };
    if (len >= 12) memcpy(d, b, 12);
    if (len < 12 || d[0] != TH || d[1] != TD || d[2] != PD || len != FILE_BYTES) {
        if (len < 12)
            model_error(path, 0, "not a MERL BRDF file: %zu bytes, shorter than its 12-byte header (3 int32 dims "
                        "90 90 180)", len);
        else if (d[0] != TH || d[1] != TD || d[2] != PD)
            model_error(path, 0, "not a MERL BRDF file: dims %d %d %d (expected 90 90 180: theta_h, theta_d, "
                        "phi_d)", d[0], d[1], d[2]);
        else
            model_error(path, 0, "not a MERL BRDF file: %zu bytes, truncated or padded (dims 90 90 180 need %zu bytes)",
                        len, (size_t)FILE_BYTES);
        free(b);
        return NULL;
    }
    model_brdf_table_t *t = model_brdf_table_new();
    if (!t) {
        free(b);
        return NULL;
    }
    model_sha256_hex(b, len, t->sha256);
    const unsigned char *v = b + 12;
    for (size_t idx = 0; idx < NCELLS; idx++) {
        double f = 0;
        bool missing = false;
        for (int c = 0; c < 3; c++) {
            double x, wc = ch == 0 ? luma[c] : c == ch - 1 ? 1 : 0;
            memcpy(&x, v + (c * NCELLS + idx) * sizeof(double), sizeof x);
            if (!(x >= 0) || !isfinite(x)) missing = true;
            f += wc * x * merl_scale[c];
        }
        t->f[idx] = missing ? NAN : f;
    }
    free(b);
    return t;
}

// Written to PATH.tmp and renamed: an existing file is replaced whole or kept.
bool model_brdf_table_save(const model_brdf_table_t *t, const char *path)
{
    char tmp[4096];
    snprintf(tmp, sizeof tmp, "%s.tmp", path);
    FILE *fp = fopen(tmp, "wb");
    if (!fp) {
        model_error(path, 0, "cannot write: %s", strerror(errno));
        return false;
    }
    const int32_t d[3] = { TH, TD, PD };
    bool ok = fwrite(d, sizeof d, 1, fp) == 1;
    enum { CHUNK = 4096 };
    double buf[CHUNK];
    for (int ch = 0; ch < 3 && ok; ch++)
        for (size_t at = 0; at < NCELLS && ok; at += CHUNK) {
            size_t n = NCELLS - at < CHUNK ? NCELLS - at : CHUNK;
            for (size_t q = 0; q < n; q++) {
                double f = t->f[at + q];
                buf[q] = isnan(f) ? -1.0 : f / merl_scale[ch];
            }
            ok = fwrite(buf, sizeof(double), n, fp) == n;
        }
    if (fclose(fp) != 0) ok = false;
    if (ok && rename(tmp, path) != 0) ok = false;
    if (!ok) {
        model_error(path, 0, "cannot write the BRDF table: %s", strerror(errno));
        remove(tmp);
    }
    return ok;
}

// The Rusinkiewicz angles of a configuration from its cosines; phi_d in [0, pi].
static void half_diff(const model_cosines_t *c, double *th, double *td, double *pd)
{
    double nh = fmin(1, fmax(-1, c->nh)), vh = fmin(1, fmax(-1, c->vh));
    *th = acos(nh);
    *td = acos(vh);
    double den = sqrt(fmax(0, 1 - nh * nh)) * sqrt(fmax(0, 1 - vh * vh));
    double cp = den > 1e-12 ? (nh * vh - c->nl) / den : 0;
    *pd = acos(fmin(1, fmax(-1, cp)));
}

// Trilinear interpolation between cell centres; missing cells are left out.
static double lookup(const double *f, double th, double td, double pd)
{
    double u = sqrt(fmax(0, th) / (M_PI / 2)) * TH - 0.5, w = td / (M_PI / 2) * TD - 0.5, p = pd / M_PI * PD - 0.5;
    u = fmin(TH - 1, fmax(0, u));
    w = fmin(TD - 1, fmax(0, w));
    int i0 = (int)u, j0 = (int)w, k0 = (int)floor(p);
    int i1 = i0 + 1 < TH ? i0 + 1 : i0, j1 = j0 + 1 < TD ? j0 + 1 : j0;
    double a = u - i0, b = w - j0, g = p - k0;
    k0 = ((k0 % PD) + PD) % PD;
    int k1 = (k0 + 1) % PD;
    double sum = 0, wsum = 0;
    for (int q = 0; q < 8; q++) {
        int i = q & 1 ? i1 : i0, j = q & 2 ? j1 : j0, k = q & 4 ? k1 : k0;
        double wt = (q & 1 ? a : 1 - a) * (q & 2 ? b : 1 - b) * (q & 4 ? g : 1 - g);
        double v = f[((size_t)i * TD + j) * PD + k];
        if (isnan(v) || wt <= 0) continue;
        sum += wt * v;
        wsum += wt;
    }
    return wsum > 0 ? sum / wsum : 0;
}

double model_brdf_table_f(const model_brdf_table_t *t, const model_cosines_t *c)
{
    if (!(c->nl > 0) || !(c->nv > 0)) return 0.0;
    double th, td, pd;
    half_diff(c, &th, &td, &pd);
    return 0.5 * (lookup(t->f, th, td, pd) + lookup(t->f, th, td, M_PI - pd));
}

double model_brdf_table_eval(const model_brdf_table_t *t, const model_cosines_t *c)
{
    return c->nl > 0 && c->nv > 0 ? model_brdf_table_f(t, c) * c->nl : 0.0;
}

double model_brdf_directional_albedo(double (*f)(const void *ctx, const model_cosines_t *c), const void *ctx,
                                     double theta_i, int n)
{
    // Cosine-weighted stratified grid: cos(theta) d omega = (1/2) du dphi with
    // u = sin^2(theta); phi over [0, pi] twice (f is symmetric in phi).
    model_vec3_t nn = { 0, 0, 1 }, l = { sin(theta_i), 0, cos(theta_i) };
    double sum = 0;
    for (int a = 0; a < n; a++) {
        double u = (a + 0.5) / n, st = sqrt(u), ct = sqrt(1 - u);
        for (int b = 0; b < n; b++) {
            double ph = (b + 0.5) / n * M_PI;
            model_vec3_t v = { st * cos(ph), st * sin(ph), ct };
            model_cosines_t c = model_cosines(nn, l, v);
            sum += f(ctx, &c);
        }
    }
    return sum * 2 * (0.5 / n) * (M_PI / n);
}

static double table_f_cb(const void *ctx, const model_cosines_t *c)
{
    return model_brdf_table_f((const model_brdf_table_t *)ctx, c);
}

double model_brdf_table_albedo(const model_brdf_table_t *t, double theta_i, int n)
{
    return model_brdf_directional_albedo(table_f_cb, t, theta_i, n);
}
