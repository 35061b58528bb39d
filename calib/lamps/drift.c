// calib/lamps/drift.c — lamp drift from a reference revisited during a
// session (calib.h, "Lamp drift"): a plan whose angle list has an angle more
// than once takes every lamp set and exposure there again; each revisit's
// frame of a lamp alone against its first visit, pixel by pixel, gives the
// lamp's intensity relative to then; calib_observe divides every frame of the
// lamp by it, a monotone cubic in time between the visits.
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "calib/calib.h"

// The plan's angle of a frame's step (NAN: none, e.g. an operator step).
static double plan_angle(const rig_plan_t *p, const rig_frame_row_t *r, int *ai)
{
    *ai = -1;
    if (r->step < 0 || r->step >= p->nsteps) return NAN;
    *ai = p->steps[r->step].angle_index;
    return *ai >= 0 && *ai < p->nangles ? p->angles_deg[*ai] : NAN;
}

// The angle is in the plan's list more than once.
static bool revisited(const rig_plan_t *p, double deg)
{
    int n = 0;
    for (int a = 0; a < p->nangles; a++) n += p->angles_deg[a] == deg;
    return n > 1;
}

// The dark level of frame row r: the offset map, else the session's frame of
// lamps none at its gain nearest in exposure (NULL + message: neither).
static float *dark_of(const rig_session_t *s, const calib_set_t *cal, const rig_frame_row_t *r, bool *owned)
{
    *owned = false;
    if (cal->offset_dn) return cal->offset_dn;
    int best = -1, w, h;
    for (int f = 0; f < s->n; f++) {
        const rig_frame_row_t *q = &s->rows[f];
        if (strcmp(q->lamps, "none") || q->gain != r->gain) continue;
        if (best < 0 || fabs(q->exposure_us - r->exposure_us) < fabs(s->rows[best].exposure_us - r->exposure_us))
            best = f;
    }
    if (best < 0) {
        model_error_set(s->dir, 0, "lamp drift: no dark level for step %d: the calibration has no offset map and the "
                        "session no dark frame", r->step);
        return NULL;
    }
    *owned = true;
    return rig_session_frame(s, best, &w, &h);
}

// *ratio: the median over the lit, unsaturated pixels of (img - dark) /
// (base - dark) (lit: base - dark above a fifth of its largest); NAN when too
// few. false (message set) when out of memory.
static bool frame_ratio(const float *base, const float *img, const float *dark, size_t n, double sat, double *ratio)
{
    double top = 0;
    for (size_t i = 0; i < n; i++) top = fmax(top, base[i] - dark[i]);
    double *v = malloc(sizeof *v * (n / 2 + 1));
    *ratio = NAN;
    if (!v) {
        model_error_set(NULL, 0, "out of memory");
        return false;
    }
    size_t m = 0;
    for (size_t i = 0; i < n; i += 2) {
        double b = base[i] - dark[i];
        if (b > 0.2 * top && base[i] < sat && img[i] < sat) v[m++] = (img[i] - dark[i]) / b;
    }
    if (m >= 100) *ratio = model_median(v, (int)m);
    free(v);
    return true;
}

// Lamp l's visits: the frames of it alone at revisited angles, grouped by
// (plan angle, exposure, gain); the group with the most visits is used.
// rows (out): its frames in time order. Their count; -1 (message set) when
// out of memory.
static int lamp_visits(const rig_session_t *s, const rig_plan_t *p, const calib_set_t *cal, int l, int *rows)
{
    int best = 0;
    int *tmp = malloc(sizeof *tmp * (size_t)(s->n + 1));
    if (!tmp) {
        model_error_set(NULL, 0, "out of memory");
        return -1;
    }
    for (int f0 = 0; f0 < s->n; f0++) {
        const rig_frame_row_t *r0 = &s->rows[f0];
        int ai;
        double a0 = plan_angle(p, r0, &ai);
        if (model_lamps_find(cal->lamps, r0->lamps) != l || !isfinite(a0) || !revisited(p, a0)) continue;
        int n = 0;
        for (int f = 0; f < s->n; f++) {
            const rig_frame_row_t *r = &s->rows[f];
            int aj;
            if (!strcmp(r->lamps, r0->lamps) && plan_angle(p, r, &aj) == a0 && r->exposure_us == r0->exposure_us &&
                r->gain == r0->gain)
                tmp[n++] = f;
        }
        if (n > best) {
            best = n;
            memcpy(rows, tmp, sizeof *tmp * (size_t)n);
        }
    }
    free(tmp);
    // time order (frames of one group are journalled in step order already; sorted for safety)
    for (int i = 1; i < best; i++)
        for (int j = i; j > 0 && s->rows[rows[j]].t_trigger_utc_s < s->rows[rows[j - 1]].t_trigger_utc_s; j--) {
            int t = rows[j];
            rows[j] = rows[j - 1];
            rows[j - 1] = t;
        }
    return best;
}

// Lamp l's visits measured into d (its own arrays). false + message.
static bool lamp_drift(const rig_session_t *s, const rig_plan_t *p, const calib_set_t *cal, int l, calib_drift_t *d)
{
    int *rows = malloc(sizeof *rows * (size_t)(s->n + 1)), n = rows ? lamp_visits(s, p, cal, l, rows) : -1;
    bool ok = n >= 0;
    float *base = NULL;
    if (!rows) model_error_set(NULL, 0, "out of memory");
    if (n < 2) goto done;
    d->t_s[l] = malloc(sizeof(double) * (size_t)n);
    d->f[l] = malloc(sizeof(double) * (size_t)n);
    if (!d->t_s[l] || !d->f[l]) {
        model_error_set(NULL, 0, "out of memory");
        ok = false;
        goto done;
    }
    int w, h;
    const rig_frame_row_t *r0 = &s->rows[rows[0]];
    bool own = false;
    float *dark = dark_of(s, cal, r0, &own);
    ok = dark && (base = rig_session_frame(s, rows[0], &w, &h));
    size_t npx = (size_t)cal->W * cal->H;
    ok = ok && (size_t)w * h == npx;
    const char *pf = r0->pixel_format;
    double full = !strcmp(pf, "Mono8") ? 255 : !strcmp(pf, "Mono12") ? 4095 : 65535;
    double sat = 0.95 * (cal->saturation_dn > 0 ? cal->saturation_dn : full);
    snprintf(d->angle_ref[l], sizeof d->angle_ref[l], "%s at %g deg, %g us", r0->lamps,
             p->steps[r0->step].angle_deg, r0->exposure_us);
    for (int k = 0; ok && k < n; k++) {
        float *img = k ? rig_session_frame(s, rows[k], &w, &h) : base;
        double f = NAN;
        bool mem = !(img && (size_t)w * h == npx) || frame_ratio(base, img, dark, npx, sat, &f);
        if (k) free(img);
        if (!mem) {
            ok = false;
            break;
        }
        if (!isfinite(f) || !(f > 0)) {
            model_error_set(s->dir, 0, "lamp drift: lamp %s's reference frame %s (step %d) cannot be compared with "
                            "its first visit %s (too few lit, unsaturated pixels, or unreadable)", r0->lamps,
                            s->rows[rows[k]].file, s->rows[rows[k]].step, r0->file);
            ok = false;
            break;
        }
        d->t_s[l][k] = s->rows[rows[k]].t_trigger_utc_s;
        d->f[l][k] = f;
    }
    if (own) free(dark);
    if (ok) d->nvisits[l] = n;
done:
    free(base);
    free(rows);
    return ok;
}

bool calib_drift_measure(const rig_session_t *s, const rig_plan_t *p, const calib_set_t *cal, calib_drift_t *d)
{
    memset(d, 0, sizeof *d);
    d->nlamps = cal->lamps->n < 32 ? cal->lamps->n : 32;
    for (int l = 0; l < d->nlamps; l++)
        if (!lamp_drift(s, p, cal, l, d)) {
            calib_drift_free(d);
            return false;
        }
    return true;
}

// Between two visits the lamp's intensity follows the monotone cubic through
// every visit (model_pchip_slopes). A warm-up is smooth and monotone; a
// straight line between visits cuts its bend (1 % at 0.7 s between visits of
// an 8 % warm-up), the cubic follows it and never overshoots the visits.
double calib_drift_factor(const calib_drift_t *d, int lamp, double t_s)
{
    if (!d || lamp < 0 || lamp >= d->nlamps || d->nvisits[lamp] < 2) return 1.0;
    const double *t = d->t_s[lamp], *f = d->f[lamp];
    int n = d->nvisits[lamp];
    if (t_s <= t[0]) return f[0];
    if (t_s >= t[n - 1]) return f[n - 1];
    bool ordered = true;   // (visits out of time order or at one time never come from a session)
    for (int j = 1; j < n; j++) ordered = ordered && t[j] > t[j - 1];
    double *sl = ordered ? malloc(sizeof(double) * (size_t)n) : NULL;
    if (!sl) {   // the straight line of the first pair around t_s
        int k = 1;
        while (k < n - 1 && t_s > t[k]) k++;
        return t[k] > t[k - 1] ? f[k - 1] + (f[k] - f[k - 1]) * (t_s - t[k - 1]) / (t[k] - t[k - 1]) : f[k];
    }
    model_pchip_slopes(t, f, n, sl);
    double v = model_pchip_eval(t, f, sl, n, t_s, NULL);
    free(sl);
    return v;
}

void calib_drift_free(calib_drift_t *d)
{
    for (int l = 0; l < 32; l++) {
        free(d->t_s[l]);
        free(d->f[l]);
    }
    memset(d, 0, sizeof *d);
}
