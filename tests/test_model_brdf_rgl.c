// tests/test_model_brdf_rgl.c — the RGL .bsdf reader (model/brdf_rgl.c): a
// small tensor file written here, its evaluation against values computed
// here from the format's description (CDFs of linear densities in closed
// form), and bad files refused with their reason.
#include <glib.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "model/internal.h"
#include "tests/test.h"

// ---------------------------------------------------------------------------
// A tensor file writer (the container as described in model/brdf_rgl.c)

typedef struct {
    const char *name;
    int         type, rank;
    uint64_t    shape[5];
    const void *data;
} tfield_t;

static size_t tsize(int type) { return type == 1 ? 1 : type == 10 ? 4 : 8; }

static GByteArray *tensor_file(const tfield_t *f, int n)
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
        at = (at + count * tsize(f[k].type) + 7) & ~(uint64_t)7;
    }
    for (int k = 0; k < n; k++) {
        while (b->len % 8) g_byte_array_append(b, (const guint8 *)"", 1);
        uint64_t count = 1;
        for (int d = 0; d < f[k].rank; d++) count *= f[k].shape[d];
        g_byte_array_append(b, f[k].data, (guint)(count * tsize(f[k].type)));
    }
    return b;
}

// The test BRDF: isotropic, theta_i = {0, 0.6}, on 3 x 3 grids over the unit
// square (x = u_theta, y = u_phi): ndf = 1 + x, sigma = 2 + y; the VNDF of
// theta_i 0 is proportional to 1 + x, of 0.6 to 1 + y; the rgb values on a
// 4 x 4 grid are linear, channel c of slice b: A[b][c] + Bx[b][c] x + By[b][c] y.
static const double A[2][3] = { { 0.10, 0.20, 0.30 }, { 0.15, 0.05, 0.25 } };
static const double Bx[2][3] = { { 0.50, -0.20, 0.10 }, { 0.30, 0.40, -0.05 } };
static const double By[2][3] = { { 0.05, 0.30, -0.10 }, { -0.20, 0.10, 0.60 } };

typedef struct {
    float theta[2], phi[1], ndf[9], sigma[9], vndf[2 * 9], rgb[2 * 3 * 16], lum[2 * 9];
    uint8_t jac;
    char desc[16];
} tdata_t;

static void fill(tdata_t *d)
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
                    d->rgb[((b * 3 + c) * 4 + i) * 4 + j] = (float)(A[b][c] + Bx[b][c] * j / 3.0 + By[b][c] * i / 3.0);
    d->jac = 1;
    snprintf(d->desc, sizeof d->desc, "test brdf");
}

static GByteArray *test_file(const tdata_t *d, const char *drop)
{
    tfield_t f[] = {
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
    tfield_t g[9];
    int n = 0;
    for (int k = 0; k < 9; k++)
        if (!drop || strcmp(f[k].name, drop)) g[n++] = f[k];
    return tensor_file(g, n);
}

// The expected value, from the description: the CDFs of the linear densities.
static double expected(model_vec3_t wi, model_vec3_t wo, const double *chw)
{
    model_vec3_t m = v3_unit(v3_add(wi, wo));
    double th_i = acos(wi.z), ph_i = atan2(wi.y, wi.x), th_m = acos(m.z), ph_m = atan2(m.y, m.x);
    double x = sqrt(th_m / (M_PI / 2)), y = (ph_m - ph_i + M_PI) / (2 * M_PI);
    y -= floor(y);
    double uiy = (ph_i + M_PI) / (2 * M_PI);
    double t = fmin(1, th_i / 0.6);
    // p = (1 - t) (1 + x) / 1.5 + t (1 + y) / 1.5
    double Fy = (1 - t) * y + t * (y + y * y / 2) / 1.5;
    double num = (1 - t) * (x + x * x / 2) / 1.5 + t * x * (1 + y) / 1.5;
    double den = (1 - t) + t * (1 + y) / 1.5;
    double sx = num / den, sy = Fy, v = 0;
    for (int c = 0; c < 3; c++)
        v += chw[c] * ((1 - t) * (A[0][c] + Bx[0][c] * sx + By[0][c] * sy) + t * (A[1][c] + Bx[1][c] * sx + By[1][c] * sy));
    return v * (1 + x) / (4 * (2 + uiy));
}

static model_vec3_t dir(double th, double ph) { return v3(sin(th) * cos(ph), sin(th) * sin(ph), cos(th)); }

TEST(brdf_rgl_eval_matches_description)
{
    tdata_t d;
    fill(&d);
    GByteArray *b = test_file(&d, NULL);
    const char *path = test_path("test.bsdf");
    CHECK(g_file_set_contents(path, (const char *)b->data, b->len, NULL));
    CHECK(model_brdf_rgl_sniff(b->data, b->len));
    g_byte_array_free(b, TRUE);
    model_brdf_rgl_t *r = model_brdf_rgl_load(path);
    CHECK_MSG(r != NULL, "%s", model_last_error());
    if (!r) return;
    CHECK(model_brdf_rgl_isotropic(r) && model_brdf_rgl_ntheta(r) == 2 && model_brdf_rgl_channels(r) == 3);
    CHECK(!strcmp(model_brdf_rgl_description(r), "test brdf"));
    double w[4][3];
    for (int ch = 0; ch < 4; ch++) CHECK(model_brdf_rgl_channel_weights(r, ch, w[ch], path));
    CHECK_NEAR(w[0][0], 0.2126, 1e-12);
    CHECK_NEAR(w[0][1], 0.7152, 1e-12);
    CHECK(w[2][1] == 1 && w[2][0] == 0 && w[2][2] == 0);
    double worst = 0;
    int n = 0;
    for (double ti = 0.05; ti < 1.2; ti += 0.17)          // beyond 0.6: clamped to the last slice
        for (double pi = -2.9; pi < 3; pi += 1.3)
            for (double to = 0.1; to < 1.5; to += 0.23)
                for (double po = -3; po < 3.1; po += 0.7)
                    for (int ch = 0; ch < 4; ch++) {
                        model_vec3_t wi = dir(ti, pi), wo = dir(to, po);
                        double got = model_brdf_rgl_eval(r, wi, wo, w[ch]), want = expected(wi, wo, w[ch]);
                        worst = fmax(worst, fabs(got - want));
                        n++;
                    }
    printf("  %d evaluations, worst |difference| %.3g\n", n, worst);
    CHECK(worst < 2e-6);   // float32 data
    CHECK(model_brdf_rgl_eval(r, dir(0.3, 0), dir(1.7, 0), w[0]) == 0);   // below the surface
    model_brdf_rgl_free(r);
}

// Bad files: refused with the file's name and the reason; never read past the end.
TEST(brdf_rgl_bad_files)
{
    tdata_t d;
    fill(&d);
    GByteArray *b = test_file(&d, NULL);
    for (size_t cut = 0; cut < b->len; cut += 7) {   // every truncation
        model_brdf_rgl_t *r = model_brdf_rgl_parse(b->data, cut, "cut.bsdf");
        CHECK(r == NULL);
        model_brdf_rgl_free(r);
        if (cut >= 12) CHECK_CONTAINS(model_last_error(), "cut.bsdf");
    }
    CHECK(model_brdf_rgl_parse(b->data, 5, "short.bsdf") == NULL);
    CHECK_CONTAINS(model_last_error(), "not an RGL .bsdf file");
    g_byte_array_free(b, TRUE);
    b = test_file(&d, "vndf");
    CHECK(model_brdf_rgl_parse(b->data, b->len, "novndf.bsdf") == NULL);
    CHECK_CONTAINS(model_last_error(), "without the field 'vndf'");
    g_byte_array_free(b, TRUE);
    d.sigma[4] = 0;
    b = test_file(&d, NULL);
    CHECK(model_brdf_rgl_parse(b->data, b->len, "sigma.bsdf") == NULL);
    CHECK_CONTAINS(model_last_error(), "'sigma'");
    g_byte_array_free(b, TRUE);
    fill(&d);
    d.rgb[7] = NAN;
    b = test_file(&d, NULL);
    CHECK(model_brdf_rgl_parse(b->data, b->len, "nan.bsdf") == NULL);
    CHECK_CONTAINS(model_last_error(), "not finite");
    g_byte_array_free(b, TRUE);
    fill(&d);
    d.vndf[3] = -1;
    b = test_file(&d, NULL);
    CHECK(model_brdf_rgl_parse(b->data, b->len, "neg.bsdf") == NULL);
    CHECK_CONTAINS(model_last_error(), "negative density");
    g_byte_array_free(b, TRUE);
    fill(&d);
    b = test_file(&d, NULL);
    b->data[12] = 2;   // version 2.0
    CHECK(model_brdf_rgl_parse(b->data, b->len, "ver.bsdf") == NULL);
    CHECK_CONTAINS(model_last_error(), "version 2.0");
    g_byte_array_free(b, TRUE);
}
