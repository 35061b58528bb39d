// tests/rgl_fixture.h — a small RGL .bsdf tensor file written by the tests
// (the container as model/brdf/rgl.c describes it), with known linear data.
#pragma once

#include <glib.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>

#include "model/base/vec.h"
#include "model/model.h"

// ---------------------------------------------------------------------------
// A tensor file writer (the container as described in model/brdf/rgl.c)

typedef struct {
    const char *name;
    int         type, rank;
    uint64_t    shape[5];
    const void *data;
} rgl_field_t;

static inline size_t rgl_tsize(int type) { return type == 1 ? 1 : type == 10 ? 4 : 8; }

static inline GByteArray *rgl_tensor_file(const rgl_field_t *f, int n)
{
    GByteArray *b = g_byte_array_new();
    g_byte_array_append(b, (const guint8 *)"tensor_file", 12);
    const guint8 ver[2] = { 1, 0 };
    g_byte_array_append(b, ver, 2);
    uint32_t nf = (uint32_t)n;
    g_byte_array_append(b, (const guint8 *)&nf, 4);
    size_t header = b->len;
    for (int k = 0; k < n; k++) header += 2 + strlen(f[k].name) + 2 + 1 + 8 + 8 * (size_t)f[k].rank;
    uint64_t at = (header + 7) & ~(uint64_t)7;
    for (int k = 0; k < n; k++) {
        uint16_t nl = (uint16_t)strlen(f[k].name), rank = (uint16_t)f[k].rank;
        uint8_t type = (uint8_t)f[k].type;
        g_byte_array_append(b, (const guint8 *)&nl, 2);
        g_byte_array_append(b, (const guint8 *)f[k].name, nl);
        g_byte_array_append(b, (const guint8 *)&rank, 2);
        g_byte_array_append(b, &type, 1);
        g_byte_array_append(b, (const guint8 *)&at, 8);
        uint64_t count = 1;
        for (int d = 0; d < f[k].rank; d++) count *= f[k].shape[d];
        g_byte_array_append(b, (const guint8 *)f[k].shape, 8 * (guint)f[k].rank);
        at = (at + count * rgl_tsize(f[k].type) + 7) & ~(uint64_t)7;
    }
    for (int k = 0; k < n; k++) {
        while (b->len % 8) g_byte_array_append(b, (const guint8 *)"", 1);
        uint64_t count = 1;
        for (int d = 0; d < f[k].rank; d++) count *= f[k].shape[d];
        g_byte_array_append(b, f[k].data, (guint)(count * rgl_tsize(f[k].type)));
    }
    return b;
}

// The test BRDF: isotropic, theta_i = {0, 0.6}, on 3 x 3 grids over the unit
// square (x = u_theta, y = u_phi): ndf = 1 + x, sigma = 2 + y; the VNDF of
// theta_i 0 is proportional to 1 + x, of 0.6 to 1 + y; the rgb values on a
// 4 x 4 grid are linear, channel c of slice b: RGL_A[b][c] + RGL_BX[b][c] x + RGL_BY[b][c] y.
static const double RGL_A[2][3] = { { 0.10, 0.20, 0.30 }, { 0.15, 0.05, 0.25 } };
static const double RGL_BX[2][3] = { { 0.50, -0.20, 0.10 }, { 0.30, 0.40, -0.05 } };
static const double RGL_BY[2][3] = { { 0.05, 0.30, -0.10 }, { -0.20, 0.10, 0.60 } };

typedef struct {
    float theta[2], phi[1], ndf[9], sigma[9], vndf[2 * 9], rgb[2 * 3 * 16], lum[2 * 9];
    uint8_t jac;
    char desc[16];
} rgl_data_t;

static inline void rgl_fill(rgl_data_t *d)
{
    d->theta[0] = 0;
    d->theta[1] = 0.6f;
    d->phi[0] = 0;
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++) {
            double x = j / 2.0, y = i / 2.0;
            d->ndf[i * 3 + j] = (float)(1 + x);
            d->sigma[i * 3 + j] = (float)(2 + y);
            d->vndf[i * 3 + j] = (float)(3 * (1 + x));     // any scale: each slice is normalised
            d->vndf[9 + i * 3 + j] = (float)(1 + y);
            d->lum[i * 3 + j] = d->lum[9 + i * 3 + j] = 1;
        }
    for (int b = 0; b < 2; b++)
        for (int c = 0; c < 3; c++)
            for (int i = 0; i < 4; i++)
                for (int j = 0; j < 4; j++)
                    d->rgb[((b * 3 + c) * 4 + i) * 4 + j] = (float)(RGL_A[b][c] + RGL_BX[b][c] * j / 3.0 + RGL_BY[b][c] * i / 3.0);
    d->jac = 1;
    snprintf(d->desc, sizeof d->desc, "test brdf");
}

static inline GByteArray *rgl_test_file(const rgl_data_t *d, const char *drop)
{
    rgl_field_t f[] = {
        { "description", 1, 1, { 9 }, d->desc },
        { "theta_i", 10, 1, { 2 }, d->theta },
        { "phi_i", 10, 1, { 1 }, d->phi },
        { "ndf", 10, 2, { 3, 3 }, d->ndf },
        { "sigma", 10, 2, { 3, 3 }, d->sigma },
        { "vndf", 10, 4, { 1, 2, 3, 3 }, d->vndf },
        { "luminance", 10, 4, { 1, 2, 3, 3 }, d->lum },
        { "rgb", 10, 5, { 1, 2, 3, 4, 4 }, d->rgb },
        { "jacobian", 1, 1, { 1 }, &d->jac },
    };
    rgl_field_t g[9];
    int n = 0;
    for (int k = 0; k < 9; k++)
        if (!drop || strcmp(f[k].name, drop)) g[n++] = f[k];
    return rgl_tensor_file(g, n);
}


// ---------------------------------------------------------------------------
// An isotropic RGL file of refl's GGX model p (kd, ks, alpha, F0), made as the
// format defines: ndf the GGX D over (u_theta, u_phi), sigma the projected
// area cos(theta_i) (1 + Lambda), per theta_i the VNDF D(m) max(0, w_i . m) /
// sigma times the square's Jacobian 2 pi^2 u_theta sin(theta_m), and the rgb
// values (all three f_r cos(theta_o) 4 sigma / D, jacobian 1) at the nodes of
// a 32 x 32 warped square, each node's direction found by inverting the
// VNDF's bilinear CDFs by bisection (written here apart from refl's reader).

enum { RGGX_NT = 7, RGGX_VW = 96, RGGX_VH = 33, RGGX_S = 32, RGGX_DW = 128, RGGX_DH = 3 };

static inline double rggx_d(double a, double th)   // GGX D at theta_m, 1/sr
{
    double c = cos(th), s = sin(th), q = a * a * c * c + s * s;   // alpha^2 / (pi cos^4 (alpha^2 + tan^2)^2)
    return a * a / (M_PI * q * q);
}

static inline double rggx_sigma(double a, double ti)
{
    double t = tan(ti);
    return cos(ti) * (1 + 0.5 * (-1 + sqrt(1 + a * a * t * t)));
}

// The bilinear density v (H x W over the unit square) at (x, y), and its row
// integral at y (trapezoids over x: exact for a function linear in x per cell).
static inline double rggx_bilin(const double *v, int W, int H, double x, double y)
{
    double px = fmin(x, 1) * (W - 1), py = fmin(y, 1) * (H - 1);
    int j = px >= W - 1 ? W - 2 : (int)px, i = py >= H - 1 ? H - 2 : (int)py;
    double fx = px - j, fy = py - i;
    return (1 - fy) * ((1 - fx) * v[i * W + j] + fx * v[i * W + j + 1]) +
           fy * ((1 - fx) * v[(i + 1) * W + j] + fx * v[(i + 1) * W + j + 1]);
}

static inline double rggx_cum_x(const double *v, int W, int H, double x, double y)   // int_0^x v(x', y) dx'
{
    double acc = 0, dx = 1.0 / (W - 1);
    for (int j = 0; j < W - 1 && j * dx < x; j++) {
        double b = fmin(x, (j + 1) * dx);
        acc += (b - j * dx) * 0.5 * (rggx_bilin(v, W, H, j * dx, y) + rggx_bilin(v, W, H, b, y));
    }
    return acc;
}

static inline double rggx_cum_y(const double *v, int W, int H, double y)   // int_0^y int_0^1 v dx dy'
{
    double acc = 0, dy = 1.0 / (H - 1);
    for (int i = 0; i < H - 1 && i * dy < y; i++) {
        double b = fmin(y, (i + 1) * dy);
        acc += (b - i * dy) * 0.5 * (rggx_cum_x(v, W, H, 1, i * dy) + rggx_cum_x(v, W, H, 1, b));
    }
    return acc;
}

static inline GByteArray *rgl_ggx_file(const double p[4])
{
    const double a = p[2];
    static float th[RGGX_NT], ph[1], ndf[RGGX_DH * RGGX_DW], sig[RGGX_DH * RGGX_DW];
    static float vn[RGGX_NT * RGGX_VH * RGGX_VW], lum[RGGX_NT * RGGX_VH * RGGX_VW], rgb[RGGX_NT * 3 * RGGX_S * RGGX_S];
    static double v[RGGX_VH * RGGX_VW];
    ph[0] = 0;
    for (int i = 0; i < RGGX_DH; i++)
        for (int j = 0; j < RGGX_DW; j++) {
            double u = (double)j / (RGGX_DW - 1), t = 0.5 * M_PI * u * u;
            ndf[i * RGGX_DW + j] = (float)rggx_d(a, t);
            sig[i * RGGX_DW + j] = (float)rggx_sigma(a, fmin(t, 1.5));
        }
    for (int b = 0; b < RGGX_NT; b++) {
        th[b] = (float)(0.15 * b);
        double ti = th[b], sg = rggx_sigma(a, ti);
        model_vec3_t wi = v3(sin(ti), 0, cos(ti));
        for (int i = 0; i < RGGX_VH; i++)
            for (int j = 0; j < RGGX_VW; j++) {
                double ux = (double)j / (RGGX_VW - 1), uy = (double)i / (RGGX_VH - 1);
                double tm = 0.5 * M_PI * ux * ux, pm = 2 * M_PI * uy - M_PI;
                double dot = sin(tm) * cos(pm) * wi.x + cos(tm) * wi.z;
                double d = rggx_d(a, tm) * fmax(0, dot) / sg * 2 * M_PI * M_PI * ux * sin(tm);
                v[i * RGGX_VW + j] = d;
                vn[(b * RGGX_VH + i) * RGGX_VW + j] = (float)d;
                lum[(b * RGGX_VH + i) * RGGX_VW + j] = (float)d;
            }
        // the values at the warped square's nodes: s = (F(x | y), F(y)) inverted by bisection
        double tot = rggx_cum_y(v, RGGX_VW, RGGX_VH, 1);
        for (int si = 0; si < RGGX_S; si++) {
            double sy = (double)si / (RGGX_S - 1), lo = 0, hi = 1;
            for (int it = 0; it < 50; it++) {
                double mid = 0.5 * (lo + hi);
                if (rggx_cum_y(v, RGGX_VW, RGGX_VH, mid) / tot < sy) lo = mid; else hi = mid;
            }
            double y = 0.5 * (lo + hi), row = rggx_cum_x(v, RGGX_VW, RGGX_VH, 1, y);
            for (int sj = 0; sj < RGGX_S; sj++) {
                double sx = (double)sj / (RGGX_S - 1), xl = 0, xh = 1;
                for (int it = 0; it < 50; it++) {
                    double mid = 0.5 * (xl + xh);
                    if (rggx_cum_x(v, RGGX_VW, RGGX_VH, mid, y) / row < sx) xl = mid; else xh = mid;
                }
                double x = 0.5 * (xl + xh), tm = 0.5 * M_PI * x * x, pm = 2 * M_PI * y - M_PI;
                model_vec3_t m = v3(sin(tm) * cos(pm), sin(tm) * sin(pm), cos(tm));
                double im = v3_dot(wi, m);
                model_vec3_t wo = v3_sub(v3_scale(m, 2 * im), wi);
                double val = 0;
                if (wo.z > 0 && im > 0) {
                    model_cosines_t c = model_cosines(v3(0, 0, 1), wi, wo);
                    double fr = model_brdf_eval(MODEL_BRDF_GGX, p, &c, NULL) / c.nl;
                    val = fr * wo.z * 4 * sg / rggx_d(a, tm);
                }
                for (int ch = 0; ch < 3; ch++) rgb[((b * 3 + ch) * RGGX_S + si) * RGGX_S + sj] = (float)val;
            }
        }
    }
    static uint8_t jac = 1;
    rgl_field_t f[] = {
        { "description", 1, 1, { 8 }, "ggx test" },
        { "theta_i", 10, 1, { RGGX_NT }, th },
        { "phi_i", 10, 1, { 1 }, ph },
        { "ndf", 10, 2, { RGGX_DH, RGGX_DW }, ndf },
        { "sigma", 10, 2, { RGGX_DH, RGGX_DW }, sig },
        { "vndf", 10, 4, { 1, RGGX_NT, RGGX_VH, RGGX_VW }, vn },
        { "luminance", 10, 4, { 1, RGGX_NT, RGGX_VH, RGGX_VW }, lum },
        { "rgb", 10, 5, { 1, RGGX_NT, 3, RGGX_S, RGGX_S }, rgb },
        { "jacobian", 1, 1, { 1 }, &jac },
    };
    return rgl_tensor_file(f, 9);
}
