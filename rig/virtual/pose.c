// rig/virtual/pose.c — the sample on the virtual rig's table: which one, its wedge
// pose, placement errors and intended offsets (posed copies of the samples).
#include <math.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "model/base/vec.h"
#include "rig/virtual/internal.h"

const char *rig_virtual_sample(const rig_virtual_t *v)
{
    if (!v) return NULL;
    rig_virtual_t *w = (rig_virtual_t *)v;
    pthread_mutex_lock(&w->state_lock);
    const char *s = v->samples[v->cur_sample].name;
    pthread_mutex_unlock(&w->state_lock);
    return s;
}

// Posed copy `slot` of the samples is taken again: forget what the caches
// keep of it; cache_lock held.
static void forget_sample(rig_virtual_t *v, int slot)
{
    for (int i = 0; i < NPLANES; i++)
        if (v->planes[i].L && v->planes[i].sample == slot) v->planes[i].sample = -1;
    for (int i = 0; i < NTRACERS; i++)
        if (v->tracers[i].t && v->tracers[i].sample == slot) rig_vslot_free(&v->tracers[i]);
    for (int k = 0; k < NSPEC; k++)
        if (v->spec[k].sample == slot) v->spec[k].valid = false;
    if (v->cur_key_sample == slot) v->cur_key_set = false;
    if (v->akey_sample == slot) v->akey_set = false;
    free(v->samples[slot].scene_path);
    model_scene_free(v->samples[slot].scene);
}

// The rigid move x -> A (B x + tb) + ta as R, t (R may be A or B, t ta or tb).
static void rigid_compose(const double A[9], const double ta[3], const double B[9], const double tb[3], double R[9],
                          double t[3])
{
    double u[3];
    for (int r = 0; r < 3; r++) {
        u[r] = ta[r];
        for (int c = 0; c < 3; c++) u[r] += A[3 * r + c] * tb[c];
    }
    m3_mul(R, A, B);
    memcpy(t, u, sizeof u);
}

// A new posed copy of base sample i (the wedge's pose after the placement
// error dR, dt when dR is not NULL); its index, or a RIG_ERR_* code.
static int new_pose(rig_virtual_t *v, int i, double tilt_deg, double tilt_azimuth_deg, const double *dR,
                    const double *dt)
{
    int slot = v->nsamples;
    if (v->nsamples >= v->nbase_samples + MAX_POSES) {
        if (!dR)
            return rig_fail(RIG_ERR_INVALID, "virtual rig: more than %d sample poses in one rig session; "
                            "close and open the rig", MAX_POSES);
        pthread_mutex_lock(&v->state_lock);
        int cur = v->cur_sample;
        pthread_mutex_unlock(&v->state_lock);
        do slot = v->nbase_samples + v->place_next++ % MAX_POSES;
        while (slot == cur);
    }
    sample_t *b = &v->samples[i], sm = *b;
    sm.variant = true;
    sm.base = i;
    sm.tilt_deg = tilt_deg;
    sm.tilt_azimuth_deg = tilt_azimuth_deg;
    sm.placed = dR != NULL;
    sm.scene_path = strdup(b->scene_path);
    model_scene_wedge_pose(b->scene, tilt_deg, tilt_azimuth_deg, sm.R, sm.t);
    if (dR) rigid_compose(sm.R, sm.t, dR, dt, sm.R, sm.t);   // x = Rw (dR x0 + dt) + tw
    sm.scene = model_scene_transformed(b->scene, sm.R, sm.t);
    if (!sm.scene || !sm.scene_path) {
        model_scene_free(sm.scene);
        free(sm.scene_path);
        return rig_fail(RIG_ERR_NO_MEM, "virtual rig: sample '%s': out of memory for its posed scene", b->name);
    }
    pthread_mutex_lock(&v->cache_lock);
    if (slot < v->nsamples) forget_sample(v, slot);
    v->samples[slot] = sm;
    if (slot == v->nsamples) v->nsamples = slot + 1;
    pthread_mutex_unlock(&v->cache_lock);
    return slot;
}

// Whether sample `name` can take the pose: its index (*i) and the posed copy
// that has it already (*j, -1: none; only without a placement error). 0 or a RIG_ERR_* code.
static int pose_check(rig_virtual_t *v, const char *name, double tilt_deg, double tilt_azimuth_deg, bool placed,
                      int *i, int *j)
{
    *i = rig_vsample_find(v->samples, v->nsamples, name);
    *j = -1;
    if (*i < 0) {
        char list[512];
        rig_vsample_list(v->samples, v->nsamples, list, sizeof list);
        return rig_fail(RIG_ERR_INVALID, "virtual rig: %s has no sample '%s'; samples: %s", v->truth_path, name, list);
    }
    if (!isfinite(tilt_deg) || fabs(tilt_deg) > 80 || !isfinite(tilt_azimuth_deg))
        return rig_fail(RIG_ERR_INVALID, "virtual rig: sample '%s': tilt %g deg at azimuth %g deg; the tilt must be "
                        "within +-80 deg and both finite", name, tilt_deg, tilt_azimuth_deg);
    if (tilt_deg != 0 && v->samples[*i].uniform)
        return rig_fail(RIG_ERR_INVALID, "virtual rig: sample '%s' is a uniform source and cannot be tilted", name);
    for (int k = 0; k < v->nsamples && !placed; k++)
        if (v->samples[k].variant && !v->samples[k].placed && v->samples[k].base == *i &&
            v->samples[k].tilt_deg == tilt_deg && v->samples[k].tilt_azimuth_deg == tilt_azimuth_deg)
            *j = k;
    return 0;
}

static int set_sample_pose_one(rig_virtual_t *v, const char *name, double tilt_deg, double tilt_azimuth_deg,
                               const double *dR, const double *dt)
{
    int i, j, rc = pose_check(v, name, tilt_deg, tilt_azimuth_deg, dR != NULL, &i, &j);
    if (rc) return rc;
    if (tilt_deg != 0 || dR) {
        if (j < 0 && (j = new_pose(v, i, tilt_deg, tilt_azimuth_deg, dR, dt)) < 0) return j;
        i = j;
    }
    pthread_mutex_lock(&v->state_lock);
    v->cur_sample = i;
    pthread_mutex_unlock(&v->state_lock);
    return 0;
}

int rig_virtual_set_sample(rig_virtual_t *v, const char *name)
{
    return rig_virtual_set_sample_pose(v, name, 0, 0);
}

// The sample on the table: its pose, the placement error of this placement
// ([placement]), then the operator's intended offset off (turn deg, dx, dy mm;
// NULL: none): x = off (err x0).
static int set_sample(rig_virtual_t *v, const char *name, double tilt_deg, double tilt_azimuth_deg,
                      const double *off)
{
    if (!v || !name) return rig_fail(RIG_ERR_INVALID, "virtual rig: set sample: NULL argument");
    int rc = 0;
    rig_virtual_t *r = v->state;
    // a placement error (the same for every camera): the count-th placement of this sample
    double dR[9], dt[3], err[3];
    bool placed = false;
    int b = rig_vsample_find(r->samples, r->nsamples, name);
    if (r->place.on && b >= 0 && !r->samples[b].uniform) {
        if (!r->place_count && !(r->place_count = calloc((size_t)r->nbase_samples, sizeof *r->place_count)))
            return rig_fail(RIG_ERR_NO_MEM, "virtual rig: out of memory");
        rig_virtual_place_error(&r->place, name, r->place_count[b]++, r->samples[b].scene, dR, dt, err);
        placed = true;
    }
    if (off && b >= 0) {
        if (r->samples[b].uniform)
            return rig_fail(RIG_ERR_INVALID, "virtual rig: sample '%s' is a uniform source: it is not placed", name);
        double oR[9], ot[3];
        rig_virtual_place_about_centre(r->samples[b].scene, off[0] * M_PI / 180, off[1], off[2], oR, ot);
        if (!placed) {
            memcpy(dR, oR, sizeof oR);
            memcpy(dt, ot, sizeof ot);
        } else {   // off (dR x + dt) = oR dR x + oR dt + ot
            rigid_compose(oR, ot, dR, dt, dR, dt);
        }
    }
    bool moved = placed || (off && b >= 0);
    for (int c = 0; c < r->nviews && !rc; c++)
        rc = set_sample_pose_one(r->views[c], name, tilt_deg, tilt_azimuth_deg, moved ? dR : NULL, moved ? dt : NULL);
    if (!rc) {
        pthread_mutex_lock(&r->state_lock);
        r->place_last_set = placed;
        if (placed) memcpy(r->place_last, err, sizeof err);
        pthread_mutex_unlock(&r->state_lock);
    }
    return rc;
}

int rig_virtual_set_sample_pose(rig_virtual_t *v, const char *name, double tilt_deg, double tilt_azimuth_deg)
{
    return set_sample(v, name, tilt_deg, tilt_azimuth_deg, NULL);
}

int rig_virtual_set_sample_offset(rig_virtual_t *v, const char *name, double turn_deg, double dx_mm, double dy_mm)
{
    if (!isfinite(turn_deg) || !isfinite(dx_mm) || !isfinite(dy_mm) || fabs(turn_deg) > 45 || fabs(dx_mm) > 100 ||
        fabs(dy_mm) > 100)
        return rig_fail(RIG_ERR_INVALID, "virtual rig: sample '%s' placed off by %g deg, (%g, %g) mm: give a turn "
                        "within +-45 deg and shifts within +-100 mm", name ? name : "?", turn_deg, dx_mm, dy_mm);
    const double off[3] = { turn_deg, dx_mm, dy_mm };
    return set_sample(v, name, 0, 0, off);
}

bool rig_virtual_last_placement(rig_virtual_t *v, double *turn_deg, double *dx_mm, double *dy_mm)
{
    if (!v) return false;
    rig_virtual_t *r = v->state;
    pthread_mutex_lock(&r->state_lock);
    bool set = r->place_last_set;
    if (set) {
        if (turn_deg) *turn_deg = r->place_last[0];
        if (dx_mm) *dx_mm = r->place_last[1];
        if (dy_mm) *dy_mm = r->place_last[2];
    }
    pthread_mutex_unlock(&r->state_lock);
    return set;
}

int rig_virtual_check_sample_pose(rig_virtual_t *v, const char *name, double tilt_deg, double tilt_azimuth_deg)
{
    if (!v || !name) return rig_fail(RIG_ERR_INVALID, "virtual rig: check sample: NULL argument");
    rig_virtual_t *r = v->state;
    int i, j, rc = pose_check(r, name, tilt_deg, tilt_azimuth_deg, r->place.on, &i, &j);
    if (!rc && tilt_deg != 0 && j < 0 && !r->place.on && r->nsamples >= r->nbase_samples + MAX_POSES)
        rc = rig_fail(RIG_ERR_INVALID, "virtual rig: more than %d sample poses in one rig session; close and open "
                      "the rig", MAX_POSES);
    return rc;
}

int rig_virtual_table_pose(rig_virtual_t *v, double angle_deg, double R[9])
{
    if (!v || !R || !isfinite(angle_deg)) return rig_fail(RIG_ERR_INVALID, "virtual rig: table pose: bad argument");
    rig_virtual_place_table_R(&v->place, angle_deg, R);
    return 0;
}

int rig_virtual_sample_pose(rig_virtual_t *v, double *tilt_deg, double *tilt_azimuth_deg, double R[9], double t[3])
{
    if (!v) return rig_fail(RIG_ERR_INVALID, "virtual rig: sample pose: NULL rig");
    pthread_mutex_lock(&v->state_lock);
    const sample_t *sm = &v->samples[v->cur_sample];
    if (tilt_deg) *tilt_deg = sm->tilt_deg;
    if (tilt_azimuth_deg) *tilt_azimuth_deg = sm->tilt_azimuth_deg;
    if (R) memcpy(R, sm->R, sizeof sm->R);
    if (t) memcpy(t, sm->t, sizeof sm->t);
    pthread_mutex_unlock(&v->state_lock);
    return 0;
}
