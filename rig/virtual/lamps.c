// rig/virtual/lamps.c — the virtual rig's lamp warm-up and drift and its stray
// light (see rig/virtual/lamps.h; rig/virtual/virtual.c calls these where a frame sums
// its lamps).
#include <math.h>
#include <stdio.h>
#include <string.h>
#include <time.h>

#include "rig/internal.h"
#include "rig/virtual/lamps.h"

static bool get(const model_ini_t *ini, const char *sec, const char *key, double lo, bool lo_open, double hi,
                const char *range, double *out)
{
    return model_ini_double_in(ini, sec, key, out, false, lo, lo_open, hi, range);
}

bool rig_vlamps_parse(rig_vlamps_t *fx, const model_ini_t *ini, const model_lamps_t *lamps)
{
    memset(fx, 0, sizeof *fx);
    fx->n = lamps->n < 32 ? lamps->n : 32;
    fx->time_scale = 1;
    for (int s = 0; s < ini->nsections; s++) {
        const char *sec = ini->sections[s];
        if (strncmp(sec, "lamp_drift ", 11)) continue;
        int i = model_lamps_find(lamps, sec + 11);
        if (i < 0 || i >= 32) {
            model_error(ini->path, ini->section_lines[s], "[%s] names no [lamp %s] of this truth file", sec, sec + 11);
            return false;
        }
        double a = 0, tau = 0, d = 0;
        if (!get(ini, sec, "warmup_fraction", -0.5, false, 0.5, "-0.5..0.5 (deficit at switch-on; < 0: brighter, as a heating LED)", &a) ||
            !get(ini, sec, "warmup_tau_s", 0, true, 1e5, "> 0 and <= 1e5 s", &tau) ||
            !get(ini, sec, "drift_pct_per_h", -10, false, 10, "-10..10 %/h", &d))
            return false;
        if ((a != 0) != (tau > 0)) {
            const model_ini_entry_t *e = model_ini_get(ini, sec, a != 0 ? "warmup_fraction" : "warmup_tau_s");
            model_error(ini->path, e ? e->line : ini->section_lines[s], "[%s]: a warm-up needs both "
                        "warmup_fraction (not 0) and warmup_tau_s", sec);
            return false;
        }
        fx->warmup_fraction[i] = a;
        fx->warmup_tau_s[i] = tau;
        fx->drift_pct_per_h[i] = d;
        if (a != 0 || d != 0) fx->timed = true;
    }
    return get(ini, "stray", "ambient_radiance", 0, false, 1e12, ">= 0 (radiance units)", &fx->ambient_radiance) &&
           get(ini, "stray", "veiling_glare", 0, false, 0.2, "0..0.2 (a fraction of the mean image radiance)",
               &fx->veiling_glare);
}

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
