// tests/test_rig_plan.c — capture plans (rig/session/plan.c): the step list of a valid
// plan (order, dark frames, repeats, auto bracketing longest first), the
// hardware floor against a hand computation, the example plans, and malformed
// plans, each with its message naming the line.
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "model/model.h"
#include "rig/internal.h"   // a stand-in turntable on the stack
#include "rig/rig.h"
#include "tests/test.h"

static rig_plan_t *parse(const char *text)
{
    return rig_plan_parse(text, strlen(text), "plan.ini");
}

#define BASE "[sample]\nname = coupon_matte_paint\nkind = material_coupon\n"

TEST(plan_steps_order_dark_repeats)
{
    rig_plan_t *p = parse(BASE "[angles]\nrange = 0 20 10\n[lamps]\nsets = east; east + west; none\n"
                          "[exposure]\nmode = fixed\nlist_us = 100 200\n[capture]\nrepeats = 2\ndark_every = 5\n");
    CHECK(p != NULL);
    if (!p) return;
    CHECK(p->nangles == 3 && p->angles_deg[2] == 20);
    CHECK(p->nlamp_sets == 3);
    CHECK(!strcmp(p->lamp_sets[1], "east+west"));
    int light = 3 * 3 * 2 * 2;
    CHECK(p->nsteps == 1 + light + light / 5);
    // step 0: the [sample]'s operator step; then angle 0, east, repeat 0: 100, 200; repeat 1: 100, 200; then
    // a dark after the 5th light
    CHECK(p->steps[0].kind == RIG_STEP_OPERATOR && p->steps[0].op == 0 && p->nops == 1);
    CHECK(p->steps[1].exposure_us == 100 && p->steps[2].exposure_us == 200 && p->steps[3].repeat == 1);
    CHECK(p->steps[6].kind == RIG_STEP_DARK && !strcmp(p->steps[6].lamps, "none"));
    CHECK(p->steps[6].exposure_us == p->steps[5].exposure_us);
    for (int i = 0; i < p->nsteps; i++) CHECK(p->steps[i].index == i);
    CHECK(p->steps[p->nsteps - 1].angle_deg == 20);
    rig_plan_free(p);
}

TEST(plan_auto_longest_first)
{
    rig_plan_t *p = parse(BASE "[angles]\nlist = 0\n[lamps]\nsets = all\n[exposure]\nmode = auto\n"
                          "list_us = 100 1600 400\ntarget_fraction = 0.8\nroi = 10 20 30 40\n");
    CHECK(p != NULL);
    if (!p) return;
    CHECK(p->auto_exposure && p->nsteps == 4);   // the operator step, then the bracket
    CHECK(p->steps[1].exposure_us == 1600 && p->steps[2].exposure_us == 400 && p->steps[3].exposure_us == 100);
    CHECK(p->steps[1].group == p->steps[3].group && p->steps[0].group == -1);
    CHECK_NEAR(p->target_fraction, 0.8, 0);
    CHECK(p->roi[0] == 10 && p->roi[3] == 40);
    rig_plan_free(p);
}

TEST(plan_floor_known_answer)
{
    // two angles 10 deg apart, one lamp set with no settle (no lamps: mask 0), exposures 1000 + 3000 us
    rig_plan_t *p = parse(BASE "[angles]\nlist = 0 10\n[lamps]\nsets = none\n[exposure]\nmode = fixed\n"
                          "list_us = 1000 3000\n[capture]\nsettle_ms = 100\n");
    CHECK(p != NULL);
    if (!p) return;
    rig_t r = { 0 };
    rig_turntable_t tt = { 0 };
    r.turntable = &tt;
    r.speed_deg_s = 10;
    r.accel_deg_s2 = 10;
    // motion of 10 deg at 10 deg/s, 10 deg/s^2: 1 s accel (5 deg), 1 s decel (5 deg), no cruise: 2 s
    double want = 2.0 + 2 * 0.1 + 2 * (0.001 + 0.003);
    CHECK_NEAR(rig_plan_floor_s(p, &r, 0), want, 1e-9);
    CHECK_NEAR(rig_motion_time_s(10, 10, 10), 2.0, 1e-9);
    rig_plan_free(p);
}

TEST(plan_examples_parse)
{
    const char *names[] = { "coupon", "reference_white", "chessboard", "workpiece" };
    for (int i = 0; i < 4; i++) {
        char path[1024];
        snprintf(path, sizeof path, "%s/examples/plans/%s.ini", test_srcdir(), names[i]);
        rig_plan_t *p = rig_plan_load(path);
        CHECK_MSG(p != NULL, "%s: %s", path, model_last_error());
        if (p) CHECK(p->nsteps > 0);
        rig_plan_free(p);
    }
}

static void bad(const char *text, const char *needle1, const char *needle2)
{
    model_error_clear();
    rig_plan_t *p = parse(text);
    CHECK_MSG(p == NULL, "plan accepted: %s", text);
    rig_plan_free(p);
    CHECK_CONTAINS(model_last_error(), needle1);
    CHECK_CONTAINS(model_last_error(), needle2);
}

TEST(plan_malformed_messages)
{
    const char *ok_rest = "[angles]\nlist = 0\n[lamps]\nsets = east\n[exposure]\nmode = fixed\nlist_us = 100\n";
    char buf[2048];
    // unknown key, line 4
    snprintf(buf, sizeof buf, BASE "colour = red\n%s", ok_rest);
    bad(buf, "plan.ini:4", "unknown key 'colour'");
    // bad kind
    bad("[sample]\nname = x\nkind = teapot\n[angles]\nlist = 0\n[lamps]\nsets = east\n[exposure]\nmode = fixed\n"
        "list_us = 100\n", "plan.ini:3", "kind = teapot");
    // bad angle number, line 5
    bad(BASE "[angles]\nlist = 0 1O 20\n[lamps]\nsets = east\n[exposure]\nmode = fixed\nlist_us = 100\n",
        "plan.ini:5", "'1O' is not a number");
    // range going the wrong way
    bad(BASE "[angles]\nrange = 0 90 -5\n[lamps]\nsets = east\n[exposure]\nmode = fixed\nlist_us = 100\n",
        "plan.ini:5", "must be non-zero");
    // both list and range
    bad(BASE "[angles]\nlist = 0\nrange = 0 10 5\n[lamps]\nsets = east\n[exposure]\nmode = fixed\nlist_us = 100\n",
        "plan.ini:6", "exactly one of");
    // empty lamp set, line 7
    bad(BASE "[angles]\nlist = 0\n[lamps]\nsets = east;;west\n[exposure]\nmode = fixed\nlist_us = 100\n",
        "plan.ini:7", "empty lamp set");
    // negative exposure, line 10
    bad(BASE "[angles]\nlist = 0\n[lamps]\nsets = east\n[exposure]\nmode = fixed\nlist_us = 100 -5\n",
        "plan.ini:10", "-5 us is out of range");
    // bad mode
    bad(BASE "[angles]\nlist = 0\n[lamps]\nsets = east\n[exposure]\nmode = sometimes\nlist_us = 100\n",
        "plan.ini:9", "mode = sometimes");
    // repeats not whole, line 12
    snprintf(buf, sizeof buf, BASE "%s[capture]\nrepeats = 1.5\n", ok_rest);
    bad(buf, "plan.ini:12", "not a whole number");
    // missing section
    bad(BASE "[angles]\nlist = 0\n[exposure]\nmode = fixed\nlist_us = 100\n", "plan.ini", "missing section [lamps]");
    // unknown section
    snprintf(buf, sizeof buf, BASE "%s[camera]\nx = 1\n", ok_rest);
    bad(buf, "plan.ini:11", "unknown section [camera]");
    // angle beyond the range of the wrappers
    bad(BASE "[angles]\nlist = 0 20000\n[lamps]\nsets = east\n[exposure]\nmode = fixed\nlist_us = 100\n",
        "plan.ini:5", "20000 deg is beyond");
    // syntax error from the INI reader
    bad("[sample\nname = x\n", "plan.ini:1", "");
}
