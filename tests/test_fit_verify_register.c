// tests/test_fit_verify_register.c — the part's placement as a nuisance
// (fit/verify/register.c): on the virtual rig's lab, the correct description
// of a part placed 2 mm / 1 deg off is registered to where the part lies and
// then passes, while it fails at the nominal pose; a stiffener made 2 mm off
// on its plate is still detected (the plate's edges hold the pose).
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fit/verify/verify.h"
#include "fit/eval/lab.h"
#include "model/model.h"
#include "tests/test.h"

#define NANG 4
static const double angles[NANG] = { 0, 90, 180, 270 };

typedef struct {
    float *img[NANG];
    verify_image_t im[NANG];
} images_t;

static void images_make(eval_lab_t *L, int place, uint64_t seed, images_t *I)
{
    int W = eval_lab_width(L), H = eval_lab_height(L);
    for (int a = 0; a < NANG; a++) {
        I->img[a] = malloc((size_t)W * H * sizeof(float));
        CHECK(I->img[a] && eval_lab_image_placed(L, place, a, 0xf, NULL, 1, seed * 16 + a, I->img[a]));
        verify_image_t *m = &I->im[a];
        memset(m, 0, sizeof *m);
        snprintf(m->name, sizeof m->name, "place%d_view%d", place, a);
        m->P = I->img[a];
        m->W = W;
        m->H = H;
        m->angle_deg = angles[a];
        m->lamps_on = 0xf;
        m->exposure_us = 6000;
    }
}

static void images_free(images_t *I)
{
    for (int a = 0; a < NANG; a++) free(I->img[a]);
}

// Verify scene (as placed by p, or as given when p is NULL) on images I: the score (NAN: failed).
static double verify_at(eval_lab_t *L, const model_scene_t *scene, const verify_placement_t *p, const images_t *I,
                        const verify_priors_t *pr, const model_material_t *const *mats)
{
    model_scene_t *sc = p ? verify_placed_scene(scene, p) : NULL;
    const model_scene_t *use = p ? sc : scene;
    verify_options_t opt = verify_defaults();
    opt.no_covariance = true;
    verify_view_t *views[NANG] = { 0 };
    double score = NAN;
    bool ok = use != NULL;
    for (int a = 0; a < NANG && ok; a++)
        ok = (views[a] = verify_view_new(use, eval_lab_camera(L), angles[a], eval_lab_lamps(L), mats, &opt)) != NULL;
    verify_result_t r;
    if (ok && verify_run(use, pr, eval_lab_camera(L), 1, eval_lab_lamps(L), eval_lab_A(L), I->im, NANG, views,
                         &opt, &r)) {
        score = r.score;
        verify_result_free(&r);
    }
    CHECK_MSG(ok && isfinite(score), "%s", model_last_error());
    for (int a = 0; a < NANG; a++) verify_view_free(views[a]);
    model_scene_free(sc);
    return score;
}

TEST_LONG(verify_register_placed_part_passes_wrong_part_fails)
{
    char truth[4096];
    snprintf(truth, sizeof truth, "%s/examples/virtual-truth.ini", test_srcdir());
    eval_lab_t *L = eval_lab_open(truth, "t_stiffener", angles, NANG, 6000, 0, false);
    CHECK_MSG(L != NULL, "%s", model_last_error());
    if (!L) return;
    // placed off: 1 deg about its centre, 2 mm along 30 deg from x
    const double turn = 1, dx = 2 * cos(M_PI / 6), dy = 2 * sin(M_PI / 6);
    int place = eval_lab_add_placement(L, turn, dx, dy, false);
    CHECK_MSG(place == 1, "%s", model_last_error());
    images_t nominal, placed;
    images_make(L, 0, 3, &nominal);
    images_make(L, place, 3, &placed);
    verify_priors_t pr = { 0 };
    const model_materials_t *mm = eval_lab_materials(L);
    const model_material_t *ply = model_materials_find(mm, "plywood"), *st = model_materials_find(mm, "painted_steel");
    CHECK(ply && st && verify_priors_add(&pr, ply, 0.1, 1e-4, 3) && verify_priors_add(&pr, st, 0.1, 1e-4, 3));
    const model_material_t *mats[2] = { ply, st };
    model_stiffener_t d = model_stiffener_default();
    model_scene_t *correct = model_stiffener_scene(&d, "t_stiffener");
    d.shift_mm[0] = 2;
    model_scene_t *shifted = model_stiffener_scene(&d, "t_shifted_2mm");
    CHECK(correct && shifted);
    const double thr = verify_defaults().score_threshold;

    // the placed part: registered where it lies, and then correct (not at the nominal pose)
    verify_placement_t p;
    bool ok = verify_register(correct, eval_lab_camera(L), eval_lab_lamps(L), eval_lab_A(L), mats, placed.im,
                              NANG, 3, 2, &p);
    CHECK_MSG(ok, "%s", model_last_error());
    fprintf(stderr, "  placed 2 mm / 1 deg off: registered (%.3f, %.3f) mm, %.3f deg (truth (%.3f, %.3f), %.3f); "
            "score %.3f (nominal %.3f), %d edge points, %.2f s\n", p.dx_mm, p.dy_mm, p.turn_deg, dx, dy, turn, p.score,
            p.score_nominal, p.nsamples, p.time_s);
    CHECK_NEAR(p.dx_mm, dx, 0.1);
    CHECK_NEAR(p.dy_mm, dy, 0.1);
    CHECK_NEAR(p.turn_deg, turn, 0.05);
    CHECK(p.score > p.score_nominal && !p.at_limit);
    double s_reg = verify_at(L, correct, &p, &placed, &pr, mats), s_nom = verify_at(L, correct, NULL, &placed, &pr, mats);
    fprintf(stderr, "  the correct description on the placed part: score %.1f registered, %.1f at the nominal pose\n",
            s_reg, s_nom);
    CHECK_MSG(s_reg <= thr, "registered: score %.1f > %.0f", s_reg, thr);
    CHECK_MSG(s_nom > thr, "nominal pose: score %.1f <= %.0f (the placement would not matter)", s_nom, thr);

    // the part in place: registered near (0, 0, 0)
    verify_placement_t p0;
    CHECK(verify_register(correct, eval_lab_camera(L), eval_lab_lamps(L), eval_lab_A(L), mats, nominal.im, NANG,
                          3, 2, &p0));
    fprintf(stderr, "  in place: registered (%.3f, %.3f) mm, %.3f deg\n", p0.dx_mm, p0.dy_mm, p0.turn_deg);
    CHECK(fabs(p0.dx_mm) < 0.1 && fabs(p0.dy_mm) < 0.1 && fabs(p0.turn_deg) < 0.05);
    double s_right = verify_at(L, correct, &p0, &nominal, &pr, mats);

    // a stiffener made 2 mm off on its plate: one consistent set of edges holds the pose (here the
    // plate's), not a compromise 1 mm off for every edge that would hide the error; the score is
    // that of the unregistered fit, above the right part's (the default threshold itself does
    // not catch 2 mm: the study's 1 % false-alarm threshold does)
    verify_placement_t ps;
    CHECK(verify_register(shifted, eval_lab_camera(L), eval_lab_lamps(L), eval_lab_A(L), mats, nominal.im, NANG,
                          3, 2, &ps));
    double s_wrong = verify_at(L, shifted, &ps, &nominal, &pr, mats), s_unreg = verify_at(L, shifted, NULL, &nominal,
                                                                                        &pr, mats);
    fprintf(stderr, "  stiffener 2 mm off on its plate: registered (%.3f, %.3f) mm, %.3f deg; score %.1f (unregistered "
            "%.1f; the right part in place %.1f)\n", ps.dx_mm, ps.dy_mm, ps.turn_deg, s_wrong, s_unreg, s_right);
    bool plate = fabs(ps.dx_mm) < 0.2, stiffener = fabs(ps.dx_mm + 2) < 0.2;
    CHECK_MSG((plate || stiffener) && fabs(ps.dy_mm) < 0.2 && fabs(ps.turn_deg) < 0.1, "a compromise: (%.3f, %.3f) mm",
              ps.dx_mm, ps.dy_mm);
    CHECK_MSG(s_wrong >= 0.9 * s_unreg && s_wrong > 1.5 * s_right, "the wrong part: score %.1f (unregistered %.1f, the "
              "right part %.1f)", s_wrong, s_unreg, s_right);

    // no tolerance: nothing registered
    verify_placement_t pz;
    CHECK(verify_register(correct, eval_lab_camera(L), eval_lab_lamps(L), eval_lab_A(L), mats, placed.im, NANG,
                          0, 0, &pz));
    CHECK(pz.dx_mm == 0 && pz.dy_mm == 0 && pz.turn_deg == 0 && pz.nsamples == 0);

    model_scene_free(correct);
    model_scene_free(shifted);
    verify_priors_free(&pr);
    images_free(&nominal);
    images_free(&placed);
    eval_lab_free(L);
}
