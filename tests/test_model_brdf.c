// tests/test_model_brdf.c — reflection models: known values, gradients by finite
// differences, zeros, reciprocity, energy, normalisation, tables.
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "model/internal.h"
#include "tests/test.h"

static model_vec3_t dir_deg(double theta_deg, double phi_deg)
{
    double t = theta_deg * M_PI / 180, p = phi_deg * M_PI / 180;
    return v3(sin(t) * cos(p), sin(t) * sin(p), cos(t));
}

static const model_vec3_t N = { 0, 0, 1 };

// ---- known answers -----------------------------------------------------------

// Values computed independently (mpmath, 30 digits) from the formulas in model/model.h
// at two geometries: n = z, l and v given as (theta, phi) in degrees.
TEST(brdf_known_values)
{
    static const struct {
        double tl, pl, tv, pv;
        double nl, nv, nh, vh;
        double lambert, hall, ts, thesis, cook, ggx;
    } k[] = {
        // G = 0.78338 here (the n.v branch of the min is active)
        { 50, 0, 70, 120, 0.64278760968653933, 0.34202014332566873, 0.75094242269695779,
          0.65571455496903418, 0.12855752193730787, 0.065904694521690283, 0.065408609407145944,
          0.035863508528179981, 0.08219839672655339, 0.10443319524080993 },
        // near the mirror direction, G = 1
        { 40, 0, 35, 180, 0.76604444311897804, 0.81915204428899179, 0.99904822158185776,
          0.79335334029123516, 0.15320888862379561, 0.56717222946385161, 0.25642422012030697,
          0.63717490833444364, 0.41589943747390794, 0.40131161508876116 },
    };
    for (size_t i = 0; i < sizeof k / sizeof k[0]; i++) {
        model_cosines_t c = model_cosines(N, dir_deg(k[i].tl, k[i].pl), dir_deg(k[i].tv, k[i].pv));
        CHECK_NEAR(c.nl, k[i].nl, 1e-14);
        CHECK_NEAR(c.nv, k[i].nv, 1e-14);
        CHECK_NEAR(c.nh, k[i].nh, 1e-14);
        CHECK_NEAR(c.vh, k[i].vh, 1e-14);
        const double lam[] = { 0.2 }, hall[] = { 0.1, 0.5, 20 }, ts[] = { 0.1, 0.5, 20, 0.3 },
                     th[] = { 0.5, 20, 0.05 }, ct[] = { 0.4, 0.6, 0.3, 0.5 }, gg[] = { 0.4, 0.6, 0.3, 0.5 };
        CHECK_REL(model_brdf_eval(MODEL_BRDF_LAMBERT, lam, &c, NULL), k[i].lambert, 1e-12);
        CHECK_REL(model_brdf_eval(MODEL_BRDF_HALL, hall, &c, NULL), k[i].hall, 1e-12);
        CHECK_REL(model_brdf_eval(MODEL_BRDF_TORRANCE_SPARROW, ts, &c, NULL), k[i].ts, 1e-12);
        CHECK_REL(model_brdf_eval(MODEL_BRDF_THESIS_FIT, th, &c, NULL), k[i].thesis, 1e-12);
        CHECK_REL(model_brdf_eval(MODEL_BRDF_COOK_TORRANCE, ct, &c, NULL), k[i].cook, 1e-12);
        CHECK_REL(model_brdf_eval(MODEL_BRDF_GGX, gg, &c, NULL), k[i].ggx, 1e-12);
    }
}

static model_vec3_t random_upper(model_rng_t *r);

// Ashikhmin-Shirley (isotropic) at the same two geometries, Rd 0.4, Rs 0.3,
// ns 20: values from the 2000 paper's formulas (mpmath, 30 digits); ggx2 is
// one ggx plus a second lobe with the same F0 and no diffuse part.
TEST(brdf_known_values_new_models)
{
    static const struct {
        double tl, pl, tv, pv, as;
    } k[] = { { 50, 0, 70, 120, 0.03758812420619286 }, { 40, 0, 35, 180, 0.36041387089421701 } };
    for (size_t i = 0; i < sizeof k / sizeof k[0]; i++) {
        model_cosines_t c = model_cosines(N, dir_deg(k[i].tl, k[i].pl), dir_deg(k[i].tv, k[i].pv));
        const double as[] = { 0.4, 0.3, 20 };
        CHECK_REL(model_brdf_eval(MODEL_BRDF_ASHIKHMIN_SHIRLEY, as, &c, NULL), k[i].as, 1e-12);
        const double g2[] = { 0.2, 0.3, 0.1, 0.25, 0.5, 0.04 }, a[] = { 0.2, 0.3, 0.1, 0.04 },
                     b[] = { 0, 0.25, 0.5, 0.04 };
        double ra = model_brdf_eval(MODEL_BRDF_GGX, a, &c, NULL), rb = model_brdf_eval(MODEL_BRDF_GGX, b, &c, NULL);
        CHECK_REL(model_brdf_eval(MODEL_BRDF_GGX2, g2, &c, NULL), ra + rb, 1e-13);
    }
    // the ggx2 model and the ggx2 generator (model/brdf/gen.c) are the same f_r
    model_brdf_recipe_t r;
    CHECK(model_brdf_recipe_parse("ggx2 albedo=0.2 ks1=0.3 alpha1=0.1 ks2=0.25 alpha2=0.5 F0=0.04", "t", 1, &r));
    const double g2[] = { 0.2, 0.3, 0.1, 0.25, 0.5, 0.04 };
    model_rng_t rng = model_rng(11, 1);
    for (int j = 0; j < 100; j++) {
        model_cosines_t c = model_cosines(N, random_upper(&rng), random_upper(&rng));
        if (!(c.nl > 1e-3 && c.nv > 1e-3)) continue;
        CHECK_REL(model_brdf_eval(MODEL_BRDF_GGX2, g2, &c, NULL) / c.nl, model_brdf_recipe_f(&r, &c), 1e-12);
    }
}

TEST(brdf_cosines_degenerate)
{
    // l = -v: the half vector is undefined; n.h = v.h = 0 by convention.
    model_cosines_t c = model_cosines(N, v3(0, 0, 1), v3(0, 0, -1));
    CHECK(c.nh == 0 && c.vh == 0);
    CHECK(c.nl == 1 && c.nv == -1);
    // l = v = n: everything 1.
    c = model_cosines(N, N, N);
    CHECK_NEAR(c.nh, 1, 1e-15);
    CHECK_NEAR(c.vh, 1, 1e-15);
}

// ---- random valid parameters ---------------------------------------------------

static void random_params(model_brdf_t m, model_rng_t *r, double *p)
{
    for (int i = 0; i < model_brdf_nparams(m); i++) {
        const char *name = model_brdf_param_name(m, i);
        double lo, hi;
        model_brdf_param_range(m, i, &lo, &hi);
        double u = model_rng_uniform(r);
        if (!strcmp(name, "ns"))
            p[i] = 0.5 + 200 * u;                       // the useful part of [0, 10000]
        else if (!strcmp(name, "m") || !strcmp(name, "alpha") || !strcmp(name, "alpha2"))
            p[i] = 0.05 + 0.95 * u;                     // D is extremely peaked below
        else if (isinf(hi))
            p[i] = 0.01 + 5 * u;
        else
            p[i] = lo + (0.01 + 0.98 * u) * (hi - lo);
    }
}

static model_vec3_t random_upper(model_rng_t *r)
{
    double ct = 0.03 + 0.97 * model_rng_uniform(r), ph = 2 * M_PI * model_rng_uniform(r);
    double st = sqrt(1 - ct * ct);
    return v3(st * cos(ph), st * sin(ph), ct);
}

// Distance of the geometry from a switch of the min() in the Torrance-Sparrow G.
static double g_switch_distance(const model_cosines_t *c)
{
    double gv = 2 * c->nh * c->nv / c->vh, gl = 2 * c->nh * c->nl / c->vh;
    return fmin(fmin(fabs(gv - 1), fabs(gl - 1)), fabs(gv - gl));
}

TEST(brdf_gradients_match_finite_differences)
{
    model_rng_t r = model_rng(42, 1);
    for (int m = 0; m < MODEL_BRDF_COUNT; m++) {
        int np = model_brdf_nparams(m), tested = 0, bad = 0;
        double worst = 0;
        while (tested < 250) {
            double p[MODEL_BRDF_MAX_PARAMS], dR[MODEL_BRDF_MAX_PARAMS];
            random_params(m, &r, p);
            model_cosines_t c = model_cosines(N, random_upper(&r), random_upper(&r));
            if (c.nh <= 0 || g_switch_distance(&c) < 1e-6) continue;
            double R = model_brdf_eval(m, p, &c, dR);
            CHECK(isfinite(R) && R >= 0);
            for (int i = 0; i < np; i++) {
                double h = 1e-5 * fmax(fabs(p[i]), 1e-2);
                double pp[MODEL_BRDF_MAX_PARAMS], pm[MODEL_BRDF_MAX_PARAMS];
                memcpy(pp, p, sizeof pp);
                memcpy(pm, p, sizeof pm);
                pp[i] += h;
                pm[i] -= h;
                double fd = (model_brdf_eval(m, pp, &c, NULL) - model_brdf_eval(m, pm, &c, NULL)) / (2 * h);
                // relative 1e-6, with a floor for derivatives that happen to be ~0
                double tol = 1e-6 * fmax(fabs(fd), fabs(dR[i])) + 1e-9 * (fabs(R) + 1e-3) / fmax(fabs(p[i]), 1e-2);
                double err = fabs(fd - dR[i]);
                if (err > tol) {
                    if (bad++ < 5)
                        test_fail(__FILE__, __LINE__, "%s dR/d%s: analytic %.12g, finite difference %.12g",
                                  model_brdf_name(m), model_brdf_param_name(m, i), dR[i], fd);
                }
                double rel = err / fmax(fmax(fabs(fd), fabs(dR[i])), 1e-300);
                // worst relative error among derivatives that matter (p dR/dp > 1e-4 R)
                if (fabs(dR[i]) * fmax(fabs(p[i]), 1e-2) > 1e-4 * fabs(R) && rel > worst) worst = rel;
            }
            tested++;
        }
        CHECK_MSG(bad == 0, "%s: %d gradient mismatches", model_brdf_name(m), bad);
        CHECK_MSG(worst < 1e-6, "%s: worst relative gradient error %.3g", model_brdf_name(m), worst);
    }
}

TEST(brdf_zero_below_horizon)
{
    model_rng_t r = model_rng(7, 2);
    for (int m = 0; m < MODEL_BRDF_COUNT; m++)
        for (int k = 0; k < 50; k++) {
            double p[MODEL_BRDF_MAX_PARAMS], dR[MODEL_BRDF_MAX_PARAMS];
            random_params(m, &r, p);
            model_vec3_t l = random_upper(&r), v = random_upper(&r);
            model_vec3_t lb = v3(l.x, l.y, -l.z), vb = v3(v.x, v.y, -v.z);
            const model_cosines_t cs[] = {
                model_cosines(N, lb, v), model_cosines(N, l, vb), model_cosines(N, lb, vb),
                { 0, 0.5, 0.8, 0.7 }, { 0.5, 0, 0.8, 0.7 }, { -0.0, 0.5, 0.8, 0.7 },
            };
            for (size_t j = 0; j < sizeof cs / sizeof cs[0]; j++) {
                for (int i = 0; i < MODEL_BRDF_MAX_PARAMS; i++) dR[i] = 7;
                double R = model_brdf_eval(m, p, &cs[j], dR);
                CHECK_MSG(R == 0.0 && !signbit(R), "%s: R = %g below the horizon", model_brdf_name(m), R);
                for (int i = 0; i < model_brdf_nparams(m); i++) CHECK(dR[i] == 0.0);
            }
        }
    // Specular lobes vanish when n.h <= 0 (possible only with inconsistent cosines).
    const model_cosines_t c = { 0.5, 0.5, -0.1, 0.7 };
    const double hall[] = { 0, 1, 10 }, ct[] = { 0, 1, 0.3, 1 }, gg[] = { 0, 1, 0.3, 1 };
    CHECK(model_brdf_eval(MODEL_BRDF_HALL, hall, &c, NULL) == 0);
    CHECK(model_brdf_eval(MODEL_BRDF_COOK_TORRANCE, ct, &c, NULL) == 0);
    CHECK(model_brdf_eval(MODEL_BRDF_GGX, gg, &c, NULL) == 0);
}

TEST(brdf_helmholtz_reciprocity)
{
    const model_brdf_t models[] = { MODEL_BRDF_LAMBERT, MODEL_BRDF_COOK_TORRANCE, MODEL_BRDF_GGX,
                                    MODEL_BRDF_ASHIKHMIN_SHIRLEY, MODEL_BRDF_GGX2 };
    model_rng_t r = model_rng(3, 3);
    for (size_t k = 0; k < sizeof models / sizeof models[0]; k++)
        for (int j = 0; j < 200; j++) {
            double p[MODEL_BRDF_MAX_PARAMS];
            random_params(models[k], &r, p);
            model_vec3_t l = random_upper(&r), v = random_upper(&r);
            model_cosines_t a = model_cosines(N, l, v), b = model_cosines(N, v, l);
            double fa = model_brdf_eval(models[k], p, &a, NULL) / a.nl;
            double fb = model_brdf_eval(models[k], p, &b, NULL) / b.nl;
            CHECK_REL(fa, fb, 1e-12);
        }
}

// ---- energy ----------------------------------------------------------------------

// Directional albedo: integral over the outgoing hemisphere of f_r(l,v) (n.v) dw_v,
// f_r = R / (n.l). Midpoint rule in (theta_v, phi_v).
static double albedo(model_brdf_t m, const double *p, double theta_l_deg, int nth, int nph)
{
    model_vec3_t l = dir_deg(theta_l_deg, 0);
    double sum = 0, dth = M_PI / 2 / nth, dph = 2 * M_PI / nph;
    for (int i = 0; i < nth; i++) {
        double th = (i + 0.5) * dth, st = sin(th), ct = cos(th);
        for (int j = 0; j < nph; j++) {
            double ph = (j + 0.5) * dph;
            model_vec3_t v = v3(st * cos(ph), st * sin(ph), ct);
            model_cosines_t c = model_cosines(N, l, v);
            sum += model_brdf_eval(m, p, &c, NULL) / c.nl * c.nv * st;
        }
    }
    return sum * dth * dph;
}

TEST(brdf_albedo_lambertian_part_is_one)
{
    const double p[] = { 1, 0, 0.3, 0.5 };
    for (double th = 0; th <= 80; th += 40) {
        CHECK_NEAR(albedo(MODEL_BRDF_COOK_TORRANCE, p, th, 200, 64), 1.0, 1e-3);
        CHECK_NEAR(albedo(MODEL_BRDF_GGX, p, th, 200, 64), 1.0, 1e-3);
    }
    // lambert's kd is albedo/pi
    const double q[] = { 1 / M_PI };
    CHECK_NEAR(albedo(MODEL_BRDF_LAMBERT, q, 30, 200, 64), 1.0, 1e-3);
}

TEST(brdf_albedo_at_most_one)
{
    const double rough[] = { 0.2, 0.5, 1.0 };
    const double incid[] = { 0, 30, 60, 85 };
    // kd, ks, F0 with kd + ks <= 1
    const double mix[][3] = { { 0, 1, 1 }, { 0.5, 0.5, 0.04 }, { 0.3, 0.7, 1 } };
    const model_brdf_t models[] = { MODEL_BRDF_COOK_TORRANCE, MODEL_BRDF_GGX };
    double max_a = 0;
    for (int k = 0; k < 2; k++)
        for (int a = 0; a < 3; a++)
            for (int t = 0; t < 4; t++)
                for (int x = 0; x < 3; x++) {
                    // the grey mixtures only at one roughness to keep the test fast
                    if (x > 0 && a != 1) continue;
                    const double p[] = { mix[x][0], mix[x][1], rough[a], mix[x][2] };
                    double A = albedo(models[k], p, incid[t], 500, 720);
                    if (A > max_a) max_a = A;
                    CHECK_MSG(A <= 1 + 2e-3, "%s rough %g incidence %g deg kd %g ks %g F0 %g: albedo %.6f > 1",
                              model_brdf_name(models[k]), rough[a], incid[t], p[0], p[1], p[3], A);
                    // A white, smooth mirror-like surface keeps most of the energy
                    // (catches lost factors of pi, 4, ...).
                    if (x == 0 && a == 0 && t == 0)
                        CHECK_MSG(A > 0.93, "%s: albedo %.4f at normal incidence, rough 0.2", model_brdf_name(models[k]), A);
                }
    CHECK(max_a > 0.9);
}

// The new classes in a white furnace: Ashikhmin-Shirley's diffuse term is
// Rd (1 - Rs) at most, its specular one about Rs; ggx2 with kd + ks + ks2 <= 1
// stays below 1 as ggx does. A dense hemisphere integral at each incidence.
TEST(brdf_albedo_new_models_at_most_one)
{
    const double incid[] = { 0, 30, 60, 85 };
    const double as[][3] = { { 1, 0, 1 }, { 1, 0.05, 10 }, { 1, 0.5, 100 }, { 0, 1, 1000 }, { 0.8, 0.2, 3 } };
    const double g2[][6] = { { 0, 0.5, 0.05, 0.5, 0.4, 1 }, { 0.4, 0.3, 0.1, 0.3, 0.8, 1 },
                             { 0.6, 0.2, 0.3, 0.2, 0.3, 0.04 } };
    double amax = 0;
    for (int t = 0; t < 4; t++) {
        for (size_t k = 0; k < sizeof as / sizeof as[0]; k++) {
            double A = albedo(MODEL_BRDF_ASHIKHMIN_SHIRLEY, as[k], incid[t], 500, 720);
            amax = fmax(amax, A);
            CHECK_MSG(A <= 1 + 2e-3, "ashikhmin_shirley Rd %g Rs %g ns %g at %g deg: albedo %.6f > 1", as[k][0],
                      as[k][1], as[k][2], incid[t], A);
        }
        for (size_t k = 0; k < sizeof g2 / sizeof g2[0]; k++) {
            double A = albedo(MODEL_BRDF_GGX2, g2[k], incid[t], 500, 720);
            CHECK_MSG(A <= 1 + 2e-3, "ggx2 case %zu at %g deg: albedo %.6f > 1", k, incid[t], A);
        }
    }
    // the diffuse part alone (Rs = 0, Rd = 1) reflects most light at normal
    // incidence: 28/23 (1 - 1/32)(mean of the view factor) = 0.95 (catches a lost pi)
    const double diff[] = { 1, 0, 1 };
    double Ad = albedo(MODEL_BRDF_ASHIKHMIN_SHIRLEY, diff, 0, 500, 16);
    CHECK_MSG(Ad > 0.9 && Ad < 1, "ashikhmin_shirley diffuse albedo %.4f", Ad);
    CHECK(amax > 0.9);
}

// The microfacet distributions are normalised: integral of D(h) (n.h) dw_h = 1.
// D is read from R at the retro-reflection geometry l = v = h (then n.l = n.v =
// n.h = c, v.h = 1, F = F0 = 1, kd = 0, ks = 1): R = D G / (4 c), with
// G = min(1, 2c^2) (Torrance-Sparrow) or G2 = 1/sqrt(1 + alpha^2 tan^2) (GGX).
TEST(brdf_distributions_normalised)
{
    const double ct[] = { 0, 1, 0.3, 1 }, gg[] = { 0, 1, 0.3, 1 };
    int nth = 20000;
    double sb = 0, sg = 0, dth = M_PI / 2 / nth;
    for (int i = 0; i < nth; i++) {
        double th = (i + 0.5) * dth, c = cos(th), t2 = tan(th) * tan(th);
        model_cosines_t cs = { c, c, c, 1 };
        double Db = 4 * c * model_brdf_eval(MODEL_BRDF_COOK_TORRANCE, ct, &cs, NULL) / fmin(1, 2 * c * c);
        double Dg = 4 * c * model_brdf_eval(MODEL_BRDF_GGX, gg, &cs, NULL) * sqrt(1 + 0.09 * t2);
        sb += Db * c * sin(th);
        sg += Dg * c * sin(th);
    }
    CHECK_NEAR(sb * dth * 2 * M_PI, 1.0, 1e-6);
    CHECK_NEAR(sg * dth * 2 * M_PI, 1.0, 1e-6);
}

// ---- tables ----------------------------------------------------------------------

TEST(brdf_tables)
{
    CHECK(MODEL_BRDF_COUNT == 8);
    for (int m = 0; m < MODEL_BRDF_COUNT; m++) {
        const char *name = model_brdf_name(m);
        CHECK(model_brdf_from_name(name) == m);
        int np = model_brdf_nparams(m);
        CHECK(np >= 1 && np <= MODEL_BRDF_MAX_PARAMS);
        for (int i = 0; i < np; i++) {
            const char *pn = model_brdf_param_name(m, i);
            CHECK(pn != NULL);
            CHECK(model_brdf_param_index(m, pn) == i);
            double lo, hi;
            model_brdf_param_range(m, i, &lo, &hi);
            CHECK(lo < hi && lo >= 0);
        }
        CHECK(model_brdf_param_name(m, np) == NULL);
        CHECK(model_brdf_param_index(m, "nonsense") == -1);
        CHECK(strlen(model_brdf_convention(m)) > 20);
        CHECK_CONTAINS(model_brdf_convention(m), name);
    }
    CHECK(model_brdf_from_name("Lambert") == -1);
    CHECK(model_brdf_from_name("") == -1);
    CHECK(model_brdf_from_name(NULL) == -1);
    CHECK(!strcmp(model_brdf_name(MODEL_BRDF_TORRANCE_SPARROW), "torrance_sparrow"));
    CHECK(!strcmp(model_brdf_name(MODEL_BRDF_THESIS_FIT), "thesis_fit"));
    CHECK(model_brdf_nparams(MODEL_BRDF_LAMBERT) == 1);
    CHECK(model_brdf_nparams(MODEL_BRDF_HALL) == 3);
    CHECK(model_brdf_nparams(MODEL_BRDF_GGX) == 4);
    CHECK(model_brdf_param_index(MODEL_BRDF_THESIS_FIT, "kd") == 2);
    CHECK(model_brdf_param_index(MODEL_BRDF_GGX, "alpha") == 2);
    CHECK(model_brdf_param_index(MODEL_BRDF_COOK_TORRANCE, "m") == 2);
    CHECK(model_brdf_is_physical(MODEL_BRDF_COOK_TORRANCE) && model_brdf_is_physical(MODEL_BRDF_GGX));
    CHECK(!model_brdf_is_physical(MODEL_BRDF_LAMBERT) && !model_brdf_is_physical(MODEL_BRDF_HALL));
    CHECK_CONTAINS(model_brdf_convention(MODEL_BRDF_GGX), "not perceptual roughness");
    CHECK_CONTAINS(model_brdf_convention(MODEL_BRDF_GGX), "alpha = perceptual_roughness^2");
    CHECK_CONTAINS(model_brdf_convention(MODEL_BRDF_LAMBERT), "albedo/pi");
    CHECK_CONTAINS(model_brdf_convention(MODEL_BRDF_COOK_TORRANCE), "Beckmann RMS slope");
    CHECK_CONTAINS(model_brdf_convention(MODEL_BRDF_HALL), "Blinn exponent");
    CHECK(model_brdf_nparams(MODEL_BRDF_GGX2) == 6 && MODEL_BRDF_MAX_PARAMS >= 6);
    CHECK(model_brdf_param_index(MODEL_BRDF_GGX2, "alpha2") == 4);
    CHECK(model_brdf_param_index(MODEL_BRDF_ASHIKHMIN_SHIRLEY, "Rs") == 1);
    CHECK(model_brdf_is_physical(MODEL_BRDF_GGX2) && model_brdf_is_physical(MODEL_BRDF_ASHIKHMIN_SHIRLEY));
    CHECK_CONTAINS(model_brdf_convention(MODEL_BRDF_ASHIKHMIN_SHIRLEY), "Schlick's F0");
    CHECK_CONTAINS(model_brdf_convention(MODEL_BRDF_GGX2), "alpha <= alpha2");
}

TEST(brdf_ranges_and_defaults)
{
    double lo, hi;
    model_brdf_param_range(MODEL_BRDF_LAMBERT, 0, &lo, &hi);
    CHECK(lo == 0 && fabs(hi - 1 / M_PI) < 1e-15);
    model_brdf_param_range(MODEL_BRDF_GGX, 0, &lo, &hi);          // kd albedo
    CHECK(lo == 0 && hi == 1);
    model_brdf_param_range(MODEL_BRDF_HALL, 1, &lo, &hi);         // ks
    CHECK(lo == 0 && isinf(hi));
    model_brdf_param_range(MODEL_BRDF_COOK_TORRANCE, 1, &lo, &hi);
    CHECK(lo == 0 && hi == 1);
    model_brdf_param_range(MODEL_BRDF_TORRANCE_SPARROW, 2, &lo, &hi);  // ns
    CHECK(lo == 0 && hi == 10000);
    model_brdf_param_range(MODEL_BRDF_TORRANCE_SPARROW, 3, &lo, &hi);  // F0
    CHECK(lo == 0 && hi == 1);
    model_brdf_param_range(MODEL_BRDF_COOK_TORRANCE, 2, &lo, &hi);     // m
    CHECK(lo == 0.001 && hi == 1);
    model_brdf_param_range(MODEL_BRDF_GGX, 2, &lo, &hi);               // alpha
    CHECK(lo == 0.001 && hi == 1);
    model_brdf_param_range(MODEL_BRDF_THESIS_FIT, 2, &lo, &hi);        // kd
    CHECK(lo == 0 && fabs(hi - 1 / M_PI) < 1e-15);
    model_brdf_param_range(MODEL_BRDF_LAMBERT, 1, &lo, &hi);           // no such parameter
    CHECK(isnan(lo) && isnan(hi));

    CHECK(model_brdf_param_default(MODEL_BRDF_THESIS_FIT, 2) == 0);
    for (int m = 0; m < MODEL_BRDF_COUNT; m++)
        for (int i = 0; i < model_brdf_nparams(m); i++)
            if (!(m == MODEL_BRDF_THESIS_FIT && i == 2)) CHECK(isnan(model_brdf_param_default(m, i)));
}

// model_brdf_eval_n (the vectorised GGX loop and the others) equals
// model_brdf_eval sample by sample, including the zero cases: light or
// view below the horizon, n.h <= 0 and v.h <= 0 (cosines given directly).
TEST(brdf_eval_n_equals_eval)
{
    enum { NS = 4099 };   // not a multiple of any vector width
    model_cosines_t *c = malloc(NS * sizeof *c);
    double *R = malloc(NS * sizeof *R), *J = malloc(NS * MODEL_BRDF_MAX_PARAMS * sizeof *J);
    model_rng_t rng = model_rng(5, 1);
    for (int i = 0; i < NS; i++) {
        if (i % 7 == 3) {   // raw cosines, some at or below zero
            c[i] = (model_cosines_t){ model_rng_uniform(&rng) * 2 - 0.5, model_rng_uniform(&rng) * 2 - 0.5,
                                      model_rng_uniform(&rng) * 2 - 0.5, model_rng_uniform(&rng) * 2 - 0.5 };
            continue;
        }
        c[i] = model_cosines(N, dir_deg(89.9 * model_rng_uniform(&rng), 360 * model_rng_uniform(&rng)),
                             dir_deg(89.9 * model_rng_uniform(&rng), 360 * model_rng_uniform(&rng)));
    }
    int zeros = 0;
    for (int m = 0; m < MODEL_BRDF_COUNT; m++) {
        int np = model_brdf_nparams(m);
        double p[MODEL_BRDF_MAX_PARAMS];
        for (int j = 0; j < np; j++) {
            const char *n = model_brdf_param_name(m, j);
            p[j] = !strcmp(n, "kd") ? 0.3 : !strcmp(n, "ks") ? 0.5 : !strcmp(n, "ns") ? 40 : !strcmp(n, "F0") ? 0.05 : 0.2;
        }
        for (int pass = 0; pass < 2; pass++) {
            if (pass == 1)   // a rough, strongly Fresnel case too
                for (int j = 0; j < np; j++) {
                    const char *n = model_brdf_param_name(m, j);
                    if (!strcmp(n, "alpha") || !strcmp(n, "m")) p[j] = 0.7;
                    if (!strcmp(n, "F0")) p[j] = 0.9;
                }
            model_brdf_eval_n(m, p, c, NS, R, J);
            double worst = 0;
            for (int i = 0; i < NS; i++) {
                double g[MODEL_BRDF_MAX_PARAMS], r = model_brdf_eval(m, p, &c[i], g);
                worst = fmax(worst, fabs(R[i] - r) / (fabs(r) + 1e-12));
                for (int j = 0; j < np; j++) worst = fmax(worst, fabs(J[i * np + j] - g[j]) / (fabs(g[j]) + 1e-12));
                zeros += r == 0 && R[i] == 0;
            }
            CHECK(worst < 1e-9);
            // without derivatives: the same values
            double *R2 = malloc(NS * sizeof *R2);
            model_brdf_eval_n(m, p, c, NS, R2, NULL);
            for (int i = 0; i < NS; i++) worst = fmax(worst, fabs(R2[i] - R[i]) / (fabs(R[i]) + 1e-12));
            free(R2);
            CHECK(worst < 1e-9);
        }
    }
    CHECK(zeros > 100);   // the zero branches were exercised
    free(c);
    free(R);
    free(J);
}
