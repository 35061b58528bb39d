// tests/test_rig_virtual_materials.c — materials outside the fitted models in
// the virtual rig: spatially varying roughness ([texture MATERIAL]
// roughness_amplitude, rig/virtual/materials.c) and tabulated materials
// ([material NAME] model = table) in its frames.
#define _GNU_SOURCE
#include <limits.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "model/model.h"
#include "rig/rig.h"
#include "tests/fixtures.h"
#include "tests/test.h"

// The example truth file with the replacements (pairs old, new; NULL ended)
// and `extra` appended, as NAME in the test directory (fx_truth_variant).
// Interreflection off: the frames are the direct light.
static const char *truth_variant(const char *name, const char *const *rep, const char *extra)
{
    const char *all[40] = { "interreflection = mc\n", "interreflection = none\n", "prerender = 1\n", "prerender = 0\n" };
    int n = 4;
    for (int k = 0; rep && rep[k] && n < 38; k += 2) {
        all[n++] = rep[k];
        all[n++] = rep[k + 1];
    }
    all[n] = NULL;
    return fx_truth_variant("virtual-truth.ini", name, all, extra ? extra : "");
}

// The radiance planes (every lamp) of a sample at angle 0 under a truth file.
static float *radiance_of(const char *truth, const char *sample, int *nlamps, int *npix)
{
    rig_virtual_options_t o = rig_virtual_defaults();
    o.serve = RIG_VIRTUAL_SERVE_INPROCESS;
    o.time_scale = 0.001;
    o.sample = sample;
    rig_virtual_t *v = NULL;
    int rc = rig_virtual_open(&v, truth, &o);
    CHECK_MSG(rc == 0, "rig_virtual_open: %d %s", rc, model_last_error());
    if (rc) return NULL;
    model_camera_t *cam = rig_virtual_camera_model(v);
    *npix = model_camera_width(cam) * model_camera_height(cam);
    *nlamps = rig_virtual_lamps_truth(v)->n;
    float *L = malloc(sizeof(float) * (size_t)*npix * *nlamps);
    for (int l = 0; L && l < *nlamps; l++) CHECK(rig_virtual_radiance(v, 0, l, L + (size_t)l * *npix) == 0);
    rig_virtual_close(v);
    return L;
}

static const char *const GLOSSY[] = { "alpha = 0.05\nF0 = 0.045\n", NULL };

// Roughness variation: the frame of a glossy coupon whose GGX alpha varies by
// +-50 % is, pixel by pixel, the mixture (1 - w) L(0.5 alpha) + w L(1.5 alpha)
// of the frames of the two populations, with w in [0, 1] varying over the
// coupon: the lobe width differs from pixel to pixel.
TEST(virtual_roughness_variation_mixes_lobe_widths)
{
    const char *rough[] = { GLOSSY[0], "alpha = 0.225\nF0 = 0.045\n", NULL };
    const char *smooth[] = { GLOSSY[0], "alpha = 0.075\nF0 = 0.045\n", NULL };
    const char *varied[] = { GLOSSY[0], "alpha = 0.15\nF0 = 0.045\n", NULL };
    const char *tex = "[texture glossy_plastic]\namplitude = 0\nscale_mm = 6\nseed = 5\nroughness_amplitude = 0.5\n";
    const char *ta = truth_variant("varied.ini", varied, tex), *tr = truth_variant("rough.ini", rough, NULL),
               *ts = truth_variant("smooth.ini", smooth, NULL);
    if (!ta || !tr || !ts) return;
    int nl = 0, np = 0;
    float *A = radiance_of(ta, "coupon_glossy_plastic", &nl, &np), *R = radiance_of(tr, "coupon_glossy_plastic", &nl, &np),
          *S = radiance_of(ts, "coupon_glossy_plastic", &nl, &np);
    if (!A || !R || !S) goto done;
    // the lamp whose highlight differs most between the populations
    int best = 0;
    double bestd = 0;
    for (int l = 0; l < nl; l++)
        for (int i = 0; i < np; i++) {
            double d = fabs(R[(size_t)l * np + i] - S[(size_t)l * np + i]);
            if (d > bestd) bestd = d, best = l;
        }
    CHECK_MSG(bestd > 0, "the populations' frames do not differ");
    const float *a = A + (size_t)best * np, *r = R + (size_t)best * np, *s = S + (size_t)best * np;
    int n = 0, outside = 0, off = 0;
    double wmin = INFINITY, wmax = -INFINITY, sum = 0, sum2 = 0;
    for (int i = 0; i < np; i++) {
        double d = r[i] - s[i];
        double lo = fmin(r[i], s[i]), hi = fmax(r[i], s[i]), tol = 1e-5 * fmax(1, hi);
        if (a[i] < lo - tol || a[i] > hi + tol) off++;   // never outside the two populations
        if (fabs(d) < 0.1 * bestd) continue;
        double w = (a[i] - s[i]) / d;
        outside += w < -1e-4 || w > 1 + 1e-4;
        wmin = fmin(wmin, w);
        wmax = fmax(wmax, w);
        sum += w;
        sum2 += w * w;
        n++;
    }
    printf("lamp %d: %d pixels, w %.3f..%.3f mean %.3f std %.3f\n", best, n, wmin, wmax, sum / n, sqrt(fmax(0, sum2 / n - sum * sum / n / n)));
    CHECK_MSG(off == 0, "%d pixels outside the range of the two populations", off);
    CHECK_MSG(n > 200, "only %d pixels in the highlight", n);
    double mean = sum / n, sd = sqrt(fmax(0, sum2 / n - mean * mean));
    CHECK_MSG(outside == 0, "%d weights outside [0, 1]", outside);
    CHECK_MSG(wmax - wmin > 0.3 && sd > 0.05, "weights %.3f..%.3f (std %.3f): the roughness does not vary", wmin,
              wmax, sd);
done:
    free(A);
    free(R);
    free(S);
}

// A material without a roughness parameter cannot vary its roughness: the
// error names the truth file's line of the key.
TEST(virtual_roughness_variation_needs_a_roughness)
{
    const char *t = truth_variant("bad.ini", NULL,
                                  "[texture reference_white]\namplitude = 0\nscale_mm = 5\nroughness_amplitude = 0.3\n");
    if (!t) return;
    char *text = model_read_file(t, NULL);
    int rc = text ? rig_virtual_check_truth(text, strlen(text), "bad.ini", test_tmpdir()) : -1;
    free(text);
    CHECK(rc == RIG_ERR_INVALID);
    CHECK_CONTAINS(model_last_error(), "bad.ini:");
    CHECK_CONTAINS(model_last_error(), "has no roughness parameter");
}

// A tabulated material in the virtual rig: a table of the coupon's own GGX
// (generate = ggx ...) renders the coupon as the analytic material does,
// within the table's interpolation tolerance.
TEST(virtual_table_material_renders_like_its_model)
{
    const char *ggx[] = { GLOSSY[0], "alpha = 0.2\nF0 = 0.045\n", NULL };
    const char *table[] = { "model = ggx\nkd = 0.35\nks = 0.6\nalpha = 0.05\nF0 = 0.045\n",
                            "model = table\ngenerate = ggx kd=0.35 ks=0.6 alpha=0.2 F0=0.045\n", NULL };
    const char *ta = truth_variant("analytic.ini", ggx, NULL), *tt = truth_variant("table.ini", table, NULL);
    if (!ta || !tt) return;
    int nl = 0, np = 0;
    float *A = radiance_of(ta, "coupon_glossy_plastic", &nl, &np), *T = radiance_of(tt, "coupon_glossy_plastic", &nl, &np);
    if (A && T) {
        double peak = 0;
        for (size_t i = 0; i < (size_t)np * nl; i++) peak = fmax(peak, A[i]);
        int n = 0, bad = 0;
        double worst = 0;
        for (size_t i = 0; i < (size_t)np * nl; i++) {
            if (A[i] < 0.01 * peak) continue;
            double rel = fabs(T[i] - A[i]) / A[i];
            worst = fmax(worst, rel);
            bad += rel > 0.03;
            n++;
        }
        printf("%d pixels, worst %.4g\n", n, worst);
        CHECK(peak > 0);
        CHECK_MSG(n > 1000 && bad == 0, "%d of %d pixels differ by more than 3 %% (worst %.3g)", bad, n, worst);
    }
    free(A);
    free(T);
}
