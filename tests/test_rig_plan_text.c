// tests/test_rig_plan_text.c — a plan as text (rig_plan_text, rig/session/plan.c) and
// the plan's [view NAME] sections (rig/session/plan_views.c): every example plan and
// plans with every field read back to the same steps and fields; views select
// each angle's lamp sets and exposures; malformed views name their line.
#include <glib.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "model/model.h"
#include "rig/rig.h"
#include "tests/test.h"

static rig_plan_t *parse(const char *text)
{
    return rig_plan_parse(text, strlen(text), "plan.ini");
}

#define BASE "[sample]\nname = coupon_matte_paint\nkind = material_coupon\n"

static bool same_steps(const rig_plan_t *a, const rig_plan_t *b)
{
    if (a->nsteps != b->nsteps) return false;
    for (int i = 0; i < a->nsteps; i++) {
        const rig_step_t *x = &a->steps[i], *y = &b->steps[i];
        if (x->index != y->index || x->kind != y->kind || x->angle_index != y->angle_index ||
            x->lamp_set != y->lamp_set || x->exposure_index != y->exposure_index || x->repeat != y->repeat ||
            x->group != y->group || x->angle_deg != y->angle_deg || strcmp(x->lamps, y->lamps) ||
            x->exposure_us != y->exposure_us || x->gain != y->gain || x->op != y->op)
            return false;
    }
    return true;
}

// parse(text(p)) has p's steps and fields, and text is a fixed point.
static void round_trip(const rig_plan_t *p, const char *what)
{
    char *t = rig_plan_text(p, "written by a test\n\nsecond line");
    CHECK_MSG(t != NULL, "%s: %s", what, model_last_error());
    if (!t) return;
    rig_plan_t *q = parse(t);
    CHECK_MSG(q != NULL, "%s: %s\n%s", what, model_last_error(), t);
    if (q) {
        CHECK_MSG(same_steps(p, q), "%s: the steps differ after the round trip:\n%s", what, t);
        CHECK(!strcmp(p->name, q->name) && !strcmp(p->notes, q->notes) && !strcmp(p->operator_name, q->operator_name));
        CHECK(!strcmp(p->sample, q->sample) && !strcmp(p->sample_kind, q->sample_kind));
        CHECK(p->tilt_deg == q->tilt_deg && p->tilt_azimuth_deg == q->tilt_azimuth_deg);
        CHECK(p->auto_exposure == q->auto_exposure && p->target_fraction == q->target_fraction);
        CHECK(!memcmp(p->roi, q->roi, sizeof p->roi) && !strcmp(p->pixel_format, q->pixel_format));
        CHECK(p->repeats == q->repeats && p->dark_every == q->dark_every && p->settle_ms == q->settle_ms);
        CHECK(p->lamp_settle_ms == q->lamp_settle_ms && p->frame_timeout_s == q->frame_timeout_s &&
              p->retries == q->retries);
        CHECK(p->nviews == q->nviews);
        CHECK(p->nops == q->nops);
        for (int i = 0; i < p->nops && i < q->nops; i++)
            CHECK_MSG(!strcmp(p->ops[i].instruction, q->ops[i].instruction), "%s: operator step %d: '%s' vs '%s'",
                      what, i, p->ops[i].instruction, q->ops[i].instruction);
        char *t2 = rig_plan_text(q, "written by a test\n\nsecond line");
        CHECK_MSG(t2 && !strcmp(t, t2), "%s: not a fixed point:\n%s\n----\n%s", what, t, t2 ? t2 : "(null)");
        free(t2);
    }
    CHECK_CONTAINS(t, "# written by a test\n#\n# second line\n[plan]");
    rig_plan_free(q);
    free(t);
}

TEST(plan_text_round_trip)
{
    const char *names[] = { "coupon", "reference_white", "chessboard", "workpiece", "workpiece_verify", "demo",
                            "mirror_sphere", "coupon_glossy_wedge", "reference_white_lamps" };
    for (size_t i = 0; i < sizeof names / sizeof names[0]; i++) {
        char path[1024];
        snprintf(path, sizeof path, "%s/examples/plans/%s.ini", test_srcdir(), names[i]);
        rig_plan_t *p = rig_plan_load(path);
        CHECK_MSG(p != NULL, "%s: %s", path, model_last_error());
        if (p) round_trip(p, path);
        rig_plan_free(p);
    }
    // every field away from its default, angles as a range of thirds, auto bracketing, views
    rig_plan_t *p = parse("[plan]\nname = every field\noperator = A. N. Other\nnotes = a; b, c # a comment\n"
                          "[sample]\nname = coupon_x\nkind = material_coupon\ntilt_deg = -12.5\n"
                          "tilt_azimuth_deg = 33.3\ninstruction = put coupon x on the jig, label up\n"
                          "[operator]\nend = take coupon x off the jig\n[angles]\nrange = 0 1 0.3333333333333333\n"
                          "[lamps]\nsets = east + west; none; all\n[exposure]\nmode = auto\nlist_us = 100 1600 400\n"
                          "target_fraction = 0.8\nroi = 1 2 30 40\ngain = 6.02\npixel_format = Mono10p\n"
                          "[capture]\nrepeats = 2\ndark_every = 3\nsettle_ms = 12.5\nlamp_settle_ms = 7\n"
                          "frame_timeout_s = 0.5\nretries = 0\n"
                          "[view first]\nangle_deg = 0.3333333333333333\nsets = none; east+west\nlist_us = 400 100\n");
    CHECK_MSG(p != NULL, "%s", model_last_error());
    if (!p) return;
    CHECK(p->nangles == 4 && p->nviews == 1 && !strcmp(p->notes, "a; b, c") && p->nops == 2);
    round_trip(p, "every field");
    // what a plan file cannot hold is refused, not written wrong
    snprintf(p->notes, sizeof p->notes, "two\nlines");
    model_error_clear();
    bool q = model_error_quiet_thread(true);
    CHECK(rig_plan_text(p, NULL) == NULL);
    model_error_quiet_thread(q);
    CHECK_CONTAINS(model_last_error(), "notes");
    rig_plan_free(p);
}

// Views: each angle takes its own lamp set and exposure; an angle without a
// view takes them all; dark frames count the light steps taken.
TEST(plan_views_steps)
{
    rig_plan_t *p = parse(BASE "[angles]\nlist = 0 90 180\n[lamps]\nsets = east; west+north\n[exposure]\n"
                          "mode = fixed\nlist_us = 100 200\n[capture]\ndark_every = 2\n"
                          "[view a]\nangle_deg = 90\nsets = west + north\nlist_us = 200\n"
                          "[view b]\nangle_deg = 0\nsets = east\n");
    CHECK_MSG(p != NULL, "%s", model_last_error());
    if (!p) return;
    // light steps: angle 0: east 100, east 200; angle 90: west+north 200; angle 180: 4 (2 sets x 2 exposures)
    // step 0: the operator step of [sample]; then the light and dark steps
    int light = 0, dark = 0, op = 0;
    for (int i = 0; i < p->nsteps; i++) {
        if (p->steps[i].kind == RIG_STEP_LIGHT) light++;
        else if (p->steps[i].kind == RIG_STEP_DARK) dark++;
        else op++;
    }
    CHECK(light == 7 && dark == 3 && op == 1 && p->steps[0].kind == RIG_STEP_OPERATOR);
    const rig_step_t *st = p->steps + 1;
    CHECK(st[0].angle_deg == 0 && !strcmp(st[0].lamps, "east") && st[0].exposure_us == 100);
    CHECK(st[1].exposure_us == 200 && !strcmp(st[1].lamps, "east"));
    CHECK(st[2].kind == RIG_STEP_DARK);
    CHECK(st[3].angle_deg == 90 && !strcmp(st[3].lamps, "west+north") && st[3].exposure_us == 200);
    CHECK(st[3].lamp_set == 1 && st[3].exposure_index == 1);
    for (int i = 0; i < p->nsteps; i++) {
        CHECK(p->steps[i].index == i);
        if (p->steps[i].angle_deg == 90 && p->steps[i].kind == RIG_STEP_LIGHT) CHECK(p->steps[i].exposure_us == 200);
    }
    CHECK(p->nviews == 2 && !strcmp(p->views[0].name, "view a") && p->views[0].angle_index == 1);
    round_trip(p, "views");
    rig_plan_free(p);
}

static void bad(const char *text, const char *needle1, const char *needle2)
{
    model_error_clear();
    bool q = model_error_quiet_thread(true);
    rig_plan_t *p = parse(text);
    model_error_quiet_thread(q);
    CHECK_MSG(p == NULL, "plan accepted: %s", text);
    rig_plan_free(p);
    CHECK_CONTAINS(model_last_error(), needle1);
    CHECK_CONTAINS(model_last_error(), needle2);
}

#define REST "[angles]\nlist = 0 90\n[lamps]\nsets = east; west\n[exposure]\nmode = fixed\nlist_us = 100 200\n"

TEST(plan_views_malformed)
{
    // lines: 1-3 sample, 4-5 angles, 6-7 lamps, 8-10 exposure, 11 [view x], 12 ...
    bad(BASE REST "[view x]\nangle_deg = 45\n", "plan.ini:12", "45 is not one of [angles]");
    bad(BASE REST "[view x]\nsets = east\n", "plan.ini", "lacks 'angle_deg'");
    bad(BASE REST "[view x]\nangle_deg = 0\nsets = north\n", "plan.ini:13", "'north' is not one of [lamps] sets");
    bad(BASE REST "[view x]\nangle_deg = 0\nlist_us = 150\n", "plan.ini:13", "150 us is not one of [exposure]");
    bad(BASE REST "[view x]\nangle_deg = 0\nlist_us = 1O0\n", "plan.ini:13", "'1O0' is not a number");
    bad(BASE REST "[view x]\nangle_deg = 0\nsets =\n", "plan.ini:13", "sets is empty");
    bad(BASE REST "[view x]\nangle_deg = 0\ncolour = red\n", "plan.ini:13", "unknown key 'colour'");
    bad(BASE REST "[view x]\nangle_deg = 0\n[view y]\nangle_deg = 0\n", "plan.ini:14", "[view x] (line 11) already");
    bad(BASE REST "[views]\nangle_deg = 0\n", "plan.ini:11", "unknown section [views]");
}

// A plan names its format: rig_plan_text writes [plan] format_version = 1; a
// plan without the key reads as version 1; a higher version is refused,
// naming the line.
TEST(plan_format_version)
{
    const char *body = BASE "[angles]\nlist = 0\n[lamps]\nsets = east\n[exposure]\nmode = fixed\nlist_us = 100\n";
    rig_plan_t *p = parse(body);
    CHECK_MSG(p != NULL, "%s", model_last_error());
    if (!p) return;
    CHECK(p->format_version == 1);
    char *t = rig_plan_text(p, NULL);
    CHECK_CONTAINS(t, "[plan]\nformat_version = 1\n");
    rig_plan_t *q = t ? parse(t) : NULL;
    CHECK(q && q->format_version == 1);
    rig_plan_free(q);
    free(t);
    rig_plan_free(p);
    char *newer = g_strdup_printf("[plan]\nname = n\nformat_version = 2\n%s", body);
    bool quiet = model_error_quiet_thread(true);
    CHECK(parse(newer) == NULL);
    model_error_quiet_thread(quiet);
    CHECK_CONTAINS(model_last_error(), "plan.ini:3: [plan] format_version = 2: a plan of a newer refl (this refl "
                                       "reads format_version up to 1)");
    g_free(newer);
}
