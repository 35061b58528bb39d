// rig/session/progress.c — the capture's progress: after each step its
// position, angle, lamps and exposure, and the ETA; a bar (model_progress: it
// overwrites itself on a terminal) or a note a step.
#include <stdio.h>
#include <unistd.h>

#include "model/model.h"
#include "rig/rig.h"
#include "rig/session/internal.h"

// A step ended (done: its position + 1). The ETA: the steps still pending
// (remaining) at the pace of this run's steps after its first one (the first
// carries the start: a long move from where the stage stood, the camera's
// first frame); after the first step, the hardware floor of the rest
// (remaining_floor_s).
void capture_progress(progress_t *pg, int done, const rig_step_t *s, int remaining, double remaining_floor_s)
{
    double now = model_now_s();
    double eta = pg->nrun > 0 ? (now - pg->t1) / pg->nrun * remaining : remaining_floor_s;
    if (pg->nrun++ == 0) pg->t1 = now;
    if (pg->bar) {
        int width = 30, fill = pg->total ? (int)((double)done * width / pg->total) : width;
        char bar[64];
        for (int i = 0; i < width; i++) bar[i] = i < fill ? '#' : '.';
        bar[width] = 0;
        model_progress("[%s] %d/%d ETA %4.0fs  %8.3f deg  %-16.16s %9.6g us", bar, done, pg->total, eta,
                       s->angle_deg, s->lamps, s->exposure_us);
    } else {
        model_note("step %d/%d angle %.4g deg lamps %s exposure %.6g us%s (ETA %.0f s)", done, pg->total,
                   s->angle_deg, s->lamps, s->exposure_us, s->kind == RIG_STEP_DARK ? " dark" : "", eta);
    }
}

bool capture_progress_bar(const rig_capture_opts_t *o)
{
    return o->progress == 1 || (o->progress < 0 && isatty(2));
}
