// rig/session/plan_views.h — the [view NAME] sections of a capture plan (rig/session/plan_views.c):
// per turntable angle, the lamp sets and exposures taken there. Used by the
// plan parser (rig/session/plan.c) only; the format is in rig/session/session.h.
#pragma once

#include <stdbool.h>

#include "model/model.h"
#include "rig/session/session.h"

#ifdef __cplusplus
extern "C" {
#endif

// Whether a section header is a view's ("view NAME").
bool rig_plan_view_section(const char *section);
// Parse the plan's [view NAME] sections into p->views (after [angles], [lamps]
// and [exposure] are parsed). false with a model_error naming file and line.
bool rig_plan_views_parse(rig_plan_t *p, const model_ini_t *ini);
// Whether the step (angle a, lamp set l, exposure e) is taken: always without
// views, and for an angle without a view; else when the angle's view names
// the set and the exposure.
bool rig_plan_view_takes(const rig_plan_t *p, int a, int l, int e);
void rig_plan_views_free(rig_plan_t *p);

#ifdef __cplusplus
}
#endif
