// tests/test_model_brdf_rgl.c — the RGL .bsdf reader (model/brdf/rgl.c): a
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

#include "tests/rgl_fixture.h"

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
        v += chw[c] * ((1 - t) * (RGL_A[0][c] + RGL_BX[0][c] * sx + RGL_BY[0][c] * sy) + t * (RGL_A[1][c] + RGL_BX[1][c] * sx + RGL_BY[1][c] * sy));
    return v * (1 + x) / (4 * (2 + uiy));
}

static model_vec3_t dir(double th, double ph) { return v3(sin(th) * cos(ph), sin(th) * sin(ph), cos(th)); }

TEST(brdf_rgl_eval_matches_description)
{
    rgl_data_t d;
    rgl_fill(&d);
    GByteArray *b = rgl_test_file(&d, NULL);
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
    rgl_data_t d;
    rgl_fill(&d);
    GByteArray *b = rgl_test_file(&d, NULL);
    for (size_t cut = 0; cut < b->len; cut += 7) {   // every truncation
        model_brdf_rgl_t *r = model_brdf_rgl_parse(b->data, cut, "cut.bsdf");
        CHECK(r == NULL);
        model_brdf_rgl_free(r);
        if (cut >= 12) CHECK_CONTAINS(model_last_error(), "cut.bsdf");
    }
    CHECK(model_brdf_rgl_parse(b->data, 5, "short.bsdf") == NULL);
    CHECK_CONTAINS(model_last_error(), "not an RGL .bsdf file");
    g_byte_array_free(b, TRUE);
    b = rgl_test_file(&d, "vndf");
    CHECK(model_brdf_rgl_parse(b->data, b->len, "novndf.bsdf") == NULL);
    CHECK_CONTAINS(model_last_error(), "without the field 'vndf'");
    g_byte_array_free(b, TRUE);
    d.sigma[4] = 0;
    b = rgl_test_file(&d, NULL);
    CHECK(model_brdf_rgl_parse(b->data, b->len, "sigma.bsdf") == NULL);
    CHECK_CONTAINS(model_last_error(), "'sigma'");
    g_byte_array_free(b, TRUE);
    rgl_fill(&d);
    d.rgb[7] = NAN;
    b = rgl_test_file(&d, NULL);
    CHECK(model_brdf_rgl_parse(b->data, b->len, "nan.bsdf") == NULL);
    CHECK_CONTAINS(model_last_error(), "not finite");
    g_byte_array_free(b, TRUE);
    rgl_fill(&d);
    d.vndf[3] = -1;
    b = rgl_test_file(&d, NULL);
    CHECK(model_brdf_rgl_parse(b->data, b->len, "neg.bsdf") == NULL);
    CHECK_CONTAINS(model_last_error(), "negative density");
    g_byte_array_free(b, TRUE);
    rgl_fill(&d);
    b = rgl_test_file(&d, NULL);
    b->data[12] = 2;   // version 2.0
    CHECK(model_brdf_rgl_parse(b->data, b->len, "ver.bsdf") == NULL);
    CHECK_CONTAINS(model_last_error(), "version 2.0");
    g_byte_array_free(b, TRUE);
}

// An anisotropic file measured over half the azimuths (phi_i = -pi, -pi/2, 0):
// w_i on the other side is turned into them by pi (x, y -> -x, -y for both
// directions: a half range assumes that symmetry; a quarter, mirrors);
// the half vector's azimuth is absolute; the values are linear between the
// measured phi_i and theta_i. A uniform VNDF leaves the square unwarped and
// jacobian 0 leaves the values as they are, so the expected value is the
// interpolated linear data at u_m.
TEST(brdf_rgl_anisotropic_half_range)
{
    float theta[2] = { 0, 0.8f }, phi[3] = { (float)-M_PI, (float)(-M_PI / 2), 0 }, ndf[4] = { 1, 1, 1, 1 };
    float sigma[4] = { 1, 1, 1, 1 }, vndf[6 * 4], rgb[6 * 3 * 4];
    uint8_t jac = 0;
    for (int k = 0; k < 6 * 4; k++) vndf[k] = 2;
    // slice (a, b), channel c: 0.1 + 0.2 a + 0.3 b + 0.05 c + (0.4 + 0.1 a) x + (0.2 - 0.1 b) y on a 2 x 2 grid
    for (int a = 0; a < 3; a++)
        for (int b = 0; b < 2; b++)
            for (int c = 0; c < 3; c++)
                for (int i = 0; i < 2; i++)
                    for (int j = 0; j < 2; j++)
                        rgb[(((a * 2 + b) * 3 + c) * 2 + i) * 2 + j] =
                            (float)(0.1 + 0.2 * a + 0.3 * b + 0.05 * c + (0.4 + 0.1 * a) * j + (0.2 - 0.1 * b) * i);
    rgl_field_t f[] = {
        { "theta_i", 10, 1, { 2 }, theta },        { "phi_i", 10, 1, { 3 }, phi },
        { "ndf", 10, 2, { 2, 2 }, ndf },            { "sigma", 10, 2, { 2, 2 }, sigma },
        { "vndf", 10, 4, { 3, 2, 2, 2 }, vndf },    { "rgb", 10, 5, { 3, 2, 3, 2, 2 }, rgb },
        { "jacobian", 1, 1, { 1 }, &jac },
    };
    GByteArray *bytes = rgl_tensor_file(f, 7);
    model_brdf_rgl_t *r = model_brdf_rgl_parse(bytes->data, bytes->len, "aniso.bsdf");
    g_byte_array_free(bytes, TRUE);
    CHECK_MSG(r != NULL, "%s", model_last_error());
    if (!r) return;
    CHECK(!model_brdf_rgl_isotropic(r));
    const double w[3] = { 0, 1, 0 };   // green: c = 1
    double worst = 0;
    for (double ti = 0.1; ti < 1.0; ti += 0.2)
        for (double pi = -3; pi < 3.1; pi += 0.5)
            for (double to = 0.1; to < 1.4; to += 0.3)
                for (double po = -3; po < 3.1; po += 0.9) {
                    model_vec3_t wi = dir(ti, pi), wo = dir(to, po);
                    double got = model_brdf_rgl_eval(r, wi, wo, w);
                    if (wi.y >= 0) {
                        wi.x = -wi.x, wi.y = -wi.y;
                        wo.x = -wo.x, wo.y = -wo.y;
                    }
                    model_vec3_t m = v3_unit(v3_add(wi, wo));
                    double x = sqrt(acos(m.z) / (M_PI / 2)), y = (atan2(m.y, m.x) + M_PI) / (2 * M_PI);
                    y -= floor(y);   // wrapped to [0, 1)
                    double ph = atan2(wi.y, wi.x);   // in [-pi, 0]
                    double ta = fmin(2, fmax(0, (ph + M_PI) / (M_PI / 2))), tb = fmin(1, acos(wi.z) / 0.8);
                    double want = 0.1 + 0.2 * ta + 0.3 * tb + 0.05 + (0.4 + 0.1 * ta) * x + (0.2 - 0.1 * tb) * y;
                    worst = fmax(worst, fabs(got - want));
                }
    printf("  worst |difference| %.3g\n", worst);
    CHECK(worst < 2e-6);
    model_brdf_rgl_free(r);
}
