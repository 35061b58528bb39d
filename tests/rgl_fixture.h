// tests/rgl_fixture.h — a small RGL .bsdf tensor file written by the tests
// (the container as model/brdf/rgl.c describes it), with known linear data.
#pragma once

#include <glib.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>

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

