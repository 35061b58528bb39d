// tests/test_fit_verify_footprint.c — the windows near edges with the
// pixels' footprint and the blur (fit/verify/footprint.c): the kernel's
// integrals against their closed forms and a numerical integration, and the
// model of each window near an edge against the virtual rig's own noise-free
// radiance planes (point lamps, no interreflection, no texture: only the
// geometry and the optics differ from the model's) with one ray at each
// pixel's centre, and with 4 x 4 rays over each pixel and a Gaussian blur.
#define _GNU_SOURCE
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fit/verify/verify.h"
#include "fit/verify/footprint.h"
#include "model/model.h"
#include "rig/rig.h"
#include "rig/virtual/truth.h"
#include "tests/fixtures.h"
#include "tests/test.h"

// The kernel k of a 5 px window: its integral over the support is 1; over
// [a, b] it is the integral of its value (midpoint rule, 1e-4 px steps); a
// whole-pixel footprint without blur is the 5 px box; a point footprint
// without blur puts 1/5 at each pixel centre.
TEST(verify_footprint_kernel)
{
    const double fills[] = { 0, 0.5, 1 }, sigmas[] = { 0, 0.3, 0.8, 1.5 };
    for (int f = 0; f < 3; f++)
        for (int s = 0; s < 4; s++) {
            double fill = fills[f], sg = sigmas[s];
            double R = 2 + 0.5 * fill + 6 * sg + 1;
            CHECK_NEAR(verify_kernel_integral(-R, R, 5, fill, sg), 1, 1e-9);
            if (fill == 0 && sg == 0) continue;   // deltas: no value to integrate
            const double a = -1.3, b = 2.6, h = 1e-4;
            double num = 0;
            for (double u = a + h / 2; u < b; u += h) num += verify_kernel_value(u, 5, fill, sg) * h;
            CHECK_MSG(fabs(num - verify_kernel_integral(a, b, 5, fill, sg)) < 1e-6, "fill %g sigma %g: %g vs %g",
                      fill, sg, num, verify_kernel_integral(a, b, 5, fill, sg));
        }
    CHECK_NEAR(verify_kernel_integral(-2.5, -1.5, 5, 1, 0), 0.2, 1e-12);
    CHECK_NEAR(verify_kernel_integral(2.4, 3.0, 5, 1, 0), 0.02, 1e-12);
    CHECK_NEAR(verify_kernel_value(0.3, 5, 1, 0), 0.2, 1e-12);
    CHECK_NEAR(verify_kernel_integral(-0.1, 0.1, 5, 0, 0), 0.2, 1e-12);   // the centre pixel's point
    CHECK_NEAR(verify_kernel_integral(0.2, 0.8, 5, 0, 0), 0, 1e-12);
    CHECK_NEAR(verify_kernel_integral(-3, 3, 5, 0, 0), 1, 1e-12);
}

// A truth file without what the model lacks (Monte Carlo interreflection,
// finite lamps, texture), with extra text appended.
static const char *plain_truth(const char *name, const char *extra)
{
    const char *rep[] = { "interreflection = mc", "interreflection = none", "finite_lamps = 1", "finite_lamps = 0",
                          "amplitude = 0.08", "amplitude = 0", "amplitude = 0.02", "amplitude = 0", NULL };
    return fx_truth_variant("virtual-truth.ini", name, rep, extra);
}

typedef struct {
    int    n[2];          // windows away from edges, near edges
    double rms[2], worst[2];   // relative difference from the rig's window means
} cmp_t;

// The rig's radiance of lamp 0 at 30 deg (noise-free, kc 1) and verification's
// model of its windows with the pixel response (fill, sigma) held at the
// truth's parameters: the relative differences.
static bool compare(const char *truth, double fill, double sigma, cmp_t *out)
{
    memset(out, 0, sizeof *out);
    rig_virtual_options_t o = rig_virtual_defaults();
    o.serve = RIG_VIRTUAL_SERVE_INPROCESS;
    o.time_scale = 0.001;
    o.prerender = 0;
    rig_virtual_t *v = NULL;
    int rc = rig_virtual_open(&v, truth, &o);
    CHECK_MSG(rc == 0, "rig_virtual_open %s: %s", truth, model_last_error());
    if (rc) return false;
    CHECK(rig_virtual_set_sample(v, "t_stiffener") == 0);
    model_camera_t *cam = rig_virtual_camera_model(v);
    int W = model_camera_width(cam), H = model_camera_height(cam);
    float *L = malloc((size_t)W * H * sizeof *L);
    CHECK(rig_virtual_radiance(v, 30, 0, L) == 0);
    // the rig's lamps as points (finite_lamps = 0: hard shadows)
    const model_lamps_t *tl = rig_virtual_lamps_truth(v);
    model_lamp_t pl[32];
    model_lamps_t pls = *tl, *lamps = &pls;
    for (int i = 0; i < tl->n && i < 32; i++) {
        pl[i] = tl->lamps[i];
        pl[i].radius_mm = 0;
    }
    pls.lamps = pl;
    rig_truth_t *t = rig_truth_load(truth);
    model_materials_t *mm = t ? rig_truth_materials(t) : NULL;
    char scene_path[4200];
    snprintf(scene_path, sizeof scene_path, "%s/examples/t_stiffener.d3d", test_srcdir());
    model_scene_t *sc = model_scene_load(scene_path, NULL);
    CHECK(t && mm && sc);
    bool ok = false;
    if (t && mm && sc) {
        verify_priors_t pr = { 0 };
        const model_material_t *mats[8];
        for (int k = 0; k < sc->nmaterials; k++) {
            mats[k] = model_materials_find(mm, sc->material_names[k]);
            CHECK(mats[k] && verify_priors_add(&pr, mats[k], 0.1, 1e-4, 3));
        }
        verify_camera_t vc = { .cam = cam, .pixel_fill = fill, .psf_sigma_px = sigma };
        snprintf(vc.name, sizeof vc.name, "virtual");
        verify_options_t opt = verify_defaults();
        opt.ir_samples = 0;
        opt.fix_lamps = opt.fix_cameras = opt.fix_pa = opt.fix_materials = opt.fix_rho = true;
        opt.robust_scale = 0;
        opt.threads = 2;
        double A[32];
        for (int i = 0; i < lamps->n; i++) A[i] = lamps->lamps[i].intensity;
        verify_image_t im = { .P = L, .W = W, .H = H, .angle_deg = 30, .lamps_on = 1, .exposure_us = 1 };
        snprintf(im.name, sizeof im.name, "lamp0");
        verify_view_t *view = verify_view_new(sc, &vc, 30, lamps, mats, &opt);
        verify_result_t r;
        CHECK(view != NULL);
        if (view && verify_run(sc, &pr, &vc, 1, lamps, A, &im, 1, &view, &opt, &r)) {
            double peak = 0;
            for (int k = 0; k < r.npoints; k++)
                if (r.points[k].status == VERIFY_PT_USED) peak = fmax(peak, r.points[k].meas);
            for (int k = 0; k < r.npoints; k++) {
                const verify_point_t *p = &r.points[k];
                // relative to the window, not below 5 % of the brightest (a shadowed window's light is ~0)
                if (p->status != VERIFY_PT_USED) continue;
                double d = (p->meas - p->model) / fmax(p->meas, 0.05 * peak);
                int f = p->footprint;
                out->n[f]++;
                out->rms[f] += d * d;
                out->worst[f] = fmax(out->worst[f], fabs(d));
            }
            for (int f = 0; f < 2; f++) out->rms[f] = out->n[f] ? sqrt(out->rms[f] / out->n[f]) : NAN;
            ok = true;
            verify_result_free(&r);
        }
        verify_view_free(view);
        verify_priors_free(&pr);
    }
    model_scene_free(sc);
    model_materials_free(mm);
    rig_truth_free(t);
    free(L);
    rig_virtual_close(v);
    return ok;
}

// One ray at each pixel's centre (the example's optics): the windows near
// edges, modelled as points, are the rig's to 0.2 % RMS (the sub-cells' faces
// where an edge passes within a fifth of a pixel of a sample); 4 x 4 rays and a
// 0.8 px Gaussian blur: modelled as whole pixels and that blur, within 1 % RMS,
// and several times worse modelled as points (as before the footprint).
TEST(verify_footprint_matches_rig_optics)
{
    cmp_t a, b, c;
    const char *t1 = plain_truth("plain1.ini", "");
    const char *t2 = plain_truth("plain2.ini", "[optics]\nrays_per_pixel = 4\npsf = gaussian\npsf_sigma_px = 0.8\n");
    CHECK(compare(t1, 0, 0, &a));
    CHECK(compare(t2, 1, 0.8, &b));
    CHECK(compare(t2, 0, 0, &c));
    printf("  one ray a pixel, modelled as points: away from edges %d windows rms %.2e, near edges %d rms %.2e "
           "(worst %.3f)\n", a.n[0], a.rms[0], a.n[1], a.rms[1], a.worst[1]);
    printf("  4x4 rays, blur 0.8 px, modelled so: near edges %d rms %.2e (worst %.3f); modelled as points: rms %.2e\n",
           b.n[1], b.rms[1], b.worst[1], c.rms[1]);
    CHECK(a.n[1] > 500 && b.n[1] > 500);
    CHECK(a.rms[0] < 1e-3);
    CHECK_MSG(a.rms[1] < 2e-3, "points: rms %.3g near edges", a.rms[1]);
    CHECK_MSG(b.rms[1] < 0.01, "footprint and blur: rms %.3g near edges", b.rms[1]);
    CHECK_MSG(c.rms[1] > 3 * b.rms[1], "the same frames modelled as points: rms %.3g, not worse than %.3g",
              c.rms[1], b.rms[1]);
}
