// rig/virtual/lamps.h — the virtual rig's lamps and stray light outside the
// fitters' model: each lamp's warm-up and drift in time, and stray
// light (room light into the lens, the lens's veiling glare). Truth-file
// sections (read by rig/virtual/truth_rig.c; examples/virtual-truth.ini
// documents them; all off by default):
//   [lamp_drift NAME]  (NAME a [lamp NAME]) warmup_fraction = a (-0.5..0.5;
//                      < 0: brighter at switch-on, as an LED whose junction heats),
//                      warmup_tau_s = tau (> 0), drift_pct_per_h = d (-10..10):
//                      lamp NAME's intensity times
//                        f(t) = (1 - a exp(-t / tau)) (1 + d / 100 * t / 3600 s)
//                      t the simulated seconds since it was switched on
//                      (real seconds / time_scale); a lamp that is off counts t = 0
//   [stray]            ambient_radiance = R (>= 0): added at every pixel in
//                      every frame, lamps on or off (radiance units, as a
//                      uniform_source's radiance); veiling_glare = g (0..0.2):
//                      g times the frame's mean lamp radiance added at every pixel
#pragma once

#include <stdbool.h>
#include <stddef.h>

#include "model/model.h"
#include "rig/devices.h"

typedef struct {
    int    n;                                  // lamps of the truth file
    double warmup_fraction[32], warmup_tau_s[32], drift_pct_per_h[32];
    bool   timed;                              // some lamp warms up or drifts: frames depend on the clock
    double ambient_radiance, veiling_glare;    // [stray]
    double time_scale;                         // the rig's (rig_virtual_options_t.time_scale)
} rig_vlamps_t;

// f(t) of lamp i at t_on_s simulated seconds after its switch-on (exactly 1
// without [lamp_drift]).
double rig_vlamps_curve(const rig_vlamps_t *fx, int lamp, double t_on_s);
// Each lamp's factor at at_ns (CLOCK_MONOTONIC ns; <= 0: now), from when dev
// switched it on (all exactly 1 when nothing is timed or dev is NULL). A
// frame's is that of its trigger: the exposure starts then, however long the
// frame then waits to be rendered.
void   rig_vlamps_factors(const rig_vlamps_t *fx, const rig_lamps_t *dev, int64_t at_ns, double f[32]);
// The stray light of a frame added to out (n pixels): kc (ambient_radiance +
// veiling_glare * mean of sum_k f[k] planes[k]) at every pixel; nothing when
// both are 0.
void   rig_vlamps_add_stray(const rig_vlamps_t *fx, float *out, size_t n, double kc, const float *const *planes,
                            const double *f, int nplanes);
