// rig/virtual/lamps.c — the virtual rig's lamp warm-up and drift and its stray
// light (see rig/virtual/lamps.h; rig/virtual/virtual.c calls these where a frame sums
// its lamps).
#include <math.h>
#include <time.h>

#include "rig/internal.h"
#include "rig/virtual/lamps.h"

double rig_vlamps_curve(const rig_vlamps_t *fx, int lamp, double t_on_s)
{
    if (!fx || lamp < 0 || lamp >= fx->n) return 1.0;
    double f = 1.0, t = t_on_s > 0 ? t_on_s : 0;
    if (fx->warmup_fraction[lamp] != 0) f *= 1 - fx->warmup_fraction[lamp] * exp(-t / fx->warmup_tau_s[lamp]);
    if (fx->drift_pct_per_h[lamp] != 0) f *= 1 + fx->drift_pct_per_h[lamp] / 100 * t / 3600;
    return f;
}

void rig_vlamps_factors(const rig_vlamps_t *fx, const rig_lamps_t *dev, int64_t at_ns, double f[32])
{
    for (int i = 0; i < 32; i++) f[i] = 1.0;
    if (!fx || !fx->timed || !dev) return;
    int64_t now_ns = at_ns;
    if (now_ns <= 0) {
        struct timespec now;
        clock_gettime(CLOCK_MONOTONIC, &now);
        now_ns = (int64_t)now.tv_sec * 1000000000 + now.tv_nsec;
    }
    uint32_t on = rig_lamps_on_mask(dev);
    for (int i = 0; i < fx->n; i++) {
        int64_t since = rig_lamps_on_since_ns(dev, i);
        double t = (on >> i & 1) && since > 0 ? 1e-9 * (double)(now_ns - since) / fx->time_scale : 0;
        f[i] = rig_vlamps_curve(fx, i, t);
    }
}

void rig_vlamps_add_stray(const rig_vlamps_t *fx, float *out, size_t n, double kc, const float *const *planes,
                          const double *f, int nplanes)
{
    if (!fx || !(fx->ambient_radiance > 0 || fx->veiling_glare > 0) || !n) return;
    double mean = 0;
    if (fx->veiling_glare > 0)
        for (int k = 0; k < nplanes; k++) {
            double s = 0;
            for (size_t i = 0; i < n; i++) s += planes[k][i];
            mean += f[k] * s / (double)n;
        }
    float add = (float)(kc * (fx->ambient_radiance + fx->veiling_glare * mean));
    for (size_t i = 0; i < n; i++) out[i] += add;
}
