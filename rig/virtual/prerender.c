// rig/virtual/prerender.c — the pre-render thread: planes of the current state
// before their triggers, and frames computed ahead of triggers a plan will make
// (speculation; rig/virtual/virtual.c describes it).
#include <math.h>
#include <pthread.h>
#include <stdlib.h>
#include <string.h>

#include "rig/virtual/internal.h"

bool rig_vspec_is(const spec_t *p, int sample, double angle_deg, uint32_t mask, double exposure_us,
                  double gain_db, uint64_t seed)
{
    return p->valid && p->seed == seed && p->sample == sample && p->angle_deg == angle_deg && p->mask == mask &&
           p->exposure_us == exposure_us && p->gain_db == gain_db;
}

// Compute one missing speculative frame of the state (the next frames'
// exposures predicted from the last state's); cache_lock held. true when one
// was computed.
static bool speculate_one(rig_virtual_t *v, int sample, double angle_deg, uint32_t mask, uint64_t next_seed)
{
    if (v->lamp_fx.timed) return false;   // lamps that drift: a frame is that of its trigger's time
    const shot_t *seq = v->cur;   // a state without frames yet: as the last one
    int nseq = v->ncur, pos = 0;
    if (v->cur_key_set && v->cur_key_sample == sample && v->cur_key_angle == angle_deg && v->cur_key_mask == mask) {
        seq = v->prev;            // frames taken in this state: continue as the previous state
        nseq = v->nprev;
        pos = v->ncur;
    }
    // Once this state has frames, go on only with a short sequence (a
    // bracket): a long one is a stream of frames that may stop at any time.
    if (pos > 0 && nseq > NSPEC) return false;
    for (int j = pos; j < nseq && j < pos + NSPEC; j++) {
        const shot_t *sh = &seq[j];
        uint64_t seed = next_seed + (uint64_t)(j - pos);
        spec_t *free_slot = NULL;
        bool have = false;
        for (int k = 0; k < NSPEC; k++) {
            spec_t *p = &v->spec[k];
            if (rig_vspec_is(p, sample, angle_deg, mask, sh->exposure_us, sh->gain_db, seed)) have = true;
            else if (!free_slot && (!p->valid || p->seed < next_seed || p->sample != sample ||
                                    p->angle_deg != angle_deg || p->mask != mask))
                free_slot = p;
        }
        if (have) continue;
        if (!free_slot) return false;
        if (!free_slot->img) free_slot->img = malloc((size_t)v->W * v->H * sizeof(float));
        if (!free_slot->img) return false;
        free_slot->valid = false;
        bool q = model_error_quiet_thread(true);   // errors show at the trigger
        int r = rig_vnoisy_frame(v, sample, angle_deg, mask, sh->exposure_us, sh->gain_db, seed, 0, free_slot->img);
        model_error_quiet_thread(q);
        if (r) {   // no more speculation until the next frame (which reports the error)
            v->ncur = v->nprev = 0;
            return false;
        }
        *free_slot = (spec_t){ free_slot->img, true, sample, angle_deg, mask, sh->exposure_us, sh->gain_db, seed };
        return true;
    }
    return false;
}

static bool ashot_eq(const ashot_t *a, const ashot_t *b)
{
    return a->mask == b->mask && a->exposure_us == b->exposure_us && a->gain_db == b->gain_db;
}

// The first n frames of a and b alike (na, nb: their lengths; n <= both).
static bool aseq_prefix(const ashot_t *a, int na, const ashot_t *b, int nb, int n)
{
    if (na > NASEQ || nb > NASEQ || n > na || n > nb) return false;
    for (int i = 0; i < n; i++)
        if (!ashot_eq(&a[i], &b[i])) return false;
    return true;
}

// The frames predicted at (sample, angle) from the angle sequences, next
// first: at most NSPEC of them, with the seeds they will draw from next_seed
// on; 0 when there is no prediction (cache_lock held).
static int predict_angle(const rig_virtual_t *v, int sample, double angle_deg, ashot_t *out)
{
    if (!v->akey_set || v->akey_sample != sample || v->nacur > NASEQ) return 0;
    const ashot_t *seq = v->acur;   // a new angle: as the last one, if it repeated the one before
    int n = v->nacur, pos = 0;
    if (v->akey_angle == angle_deg) {   // frames at this angle: go on as the previous angle if they follow it
        if (v->naprev != v->naprev2 || !aseq_prefix(v->aprev, v->naprev, v->aprev2, v->naprev2, v->naprev) ||
            !aseq_prefix(v->acur, v->nacur, v->aprev, v->naprev, v->nacur))
            return 0;
        seq = v->aprev;
        n = v->naprev;
        pos = v->nacur;
    } else if (v->nacur != v->naprev || !aseq_prefix(v->acur, v->nacur, v->aprev, v->naprev, v->nacur)) {
        return 0;
    }
    int k = 0;
    for (int j = pos; j < n && k < NSPEC; j++) out[k++] = seq[j];
    return k;
}

// Compute one missing frame of the angle's prediction (cache_lock held):
// 1 computed, 0 all there (or no room), -1 no prediction.
static int speculate_angle(rig_virtual_t *v, int sample, double angle_deg, uint64_t next_seed)
{
    if (v->lamp_fx.timed) return -1;   // lamps that drift: a frame is that of its trigger's time
    ashot_t pred[NSPEC];
    int np = predict_angle(v, sample, angle_deg, pred);
    if (np == 0) return -1;
    for (int j = 0; j < np; j++) {
        uint64_t seed = next_seed + (uint64_t)j;
        bool have = false;
        spec_t *free_slot = NULL;
        for (int k = 0; k < NSPEC && !have; k++) {
            spec_t *p = &v->spec[k];
            if (rig_vspec_is(p, sample, angle_deg, pred[j].mask, pred[j].exposure_us, pred[j].gain_db, seed)) {
                have = true;
                break;
            }
            // free: invalid, used up, elsewhere, or a frame this prediction does not have
            bool wanted = false;
            if (p->valid && p->seed >= next_seed && p->seed < next_seed + (uint64_t)np && p->sample == sample &&
                p->angle_deg == angle_deg) {
                const ashot_t *q = &pred[p->seed - next_seed];
                wanted = p->mask == q->mask && p->exposure_us == q->exposure_us && p->gain_db == q->gain_db;
            }
            if (!wanted && !free_slot) free_slot = p;
        }
        if (have) continue;
        if (!free_slot) return 0;
        if (!free_slot->img) free_slot->img = malloc((size_t)v->W * v->H * sizeof(float));
        if (!free_slot->img) return 0;
        free_slot->valid = false;
        bool q = model_error_quiet_thread(true);   // errors show at the trigger
        int r = rig_vnoisy_frame(v, sample, angle_deg, pred[j].mask, pred[j].exposure_us, pred[j].gain_db, seed, 0,
                                 free_slot->img);
        model_error_quiet_thread(q);
        if (r) {   // no more speculation until the next frame (which reports the error)
            v->nacur = v->naprev = v->naprev2 = NASEQ + 1;
            return 0;
        }
        *free_slot = (spec_t){ free_slot->img, true, sample, angle_deg, pred[j].mask, pred[j].exposure_us,
                               pred[j].gain_db, seed };
        return 1;
    }
    return 0;
}

void rig_vspec_note(rig_virtual_t *v, int sample, double angle_deg, uint32_t mask, double exposure_us,
                    double gain_db)
{
    // The exposures of this state so far (the prediction of speculate_one).
    if (!(v->cur_key_set && v->cur_key_sample == sample && v->cur_key_angle == angle_deg &&
          v->cur_key_mask == mask)) {
        if (v->ncur > 0) {
            memcpy(v->prev, v->cur, sizeof v->cur);
            v->nprev = v->ncur;
        }
        v->ncur = 0;
        v->cur_key_set = true;
        v->cur_key_sample = sample;
        v->cur_key_angle = angle_deg;
        v->cur_key_mask = mask;
    }
    if (v->ncur < NSEQ) v->cur[v->ncur++] = (shot_t){ exposure_us, gain_db };
    // ... and of this angle
    if (!(v->akey_set && v->akey_sample == sample && v->akey_angle == angle_deg)) {
        memcpy(v->aprev2, v->aprev, sizeof v->aprev);
        v->naprev2 = v->naprev;
        memcpy(v->aprev, v->acur, sizeof v->acur);
        v->naprev = v->nacur;
        v->nacur = 0;
        if (!v->akey_set || v->akey_sample != sample) v->naprev = v->naprev2 = NASEQ + 1;   // another sample
        v->akey_set = true;
        v->akey_sample = sample;
        v->akey_angle = angle_deg;
    }
    if (v->nacur < NASEQ) v->acur[v->nacur++] = (ashot_t){ mask, exposure_us, gain_db };
    else v->nacur = NASEQ + 1;
}

const float *rig_vspec_take(rig_virtual_t *v, int sample, double angle_deg, uint32_t mask, double exposure_us,
                            double gain_db, uint64_t seed)
{
    const float *img = NULL;
    for (int k = 0; k < NSPEC; k++) {
        spec_t *p = &v->spec[k];
        if (rig_vspec_is(p, sample, angle_deg, mask, exposure_us, gain_db, seed)) img = p->img;
        if (p->seed < seed) p->valid = false;   // its seed is used up
    }
    if (img) v->frames_ahead++;
    for (int k = 0; k < NSPEC; k++)
        if (v->spec[k].seed == seed) v->spec[k].valid = false;   // taken (its buffer is read under cache_lock)
    return img;
}

void *rig_vprerender_main(void *arg)
{
    rig_virtual_t *v = arg;
    model_error_quiet_thread(true);   // its errors show at the trigger that needs the frame
    while (!__atomic_load_n(&v->pre_stop, __ATOMIC_ACQUIRE)) {
        rig_turntable_status_t st;
        pthread_mutex_lock(&v->state_lock);
        int r = v->stage_gone ? RIG_ERR_DISCONNECTED : rig_turntable_status(v->tt_sim, &st);
        if (r) v->stage_gone = true;
        double dest = NAN;
        bool to_dest = !r && st.moving && st.homed && rig_turntable_sim_destination(v->tt_sim, &dest);
        int sample = v->cur_sample;
        uint64_t next_seed = v->next_seed;
        pthread_mutex_unlock(&v->state_lock);
        uint32_t mask = __atomic_load_n(&v->lamps_dev->on_mask, __ATOMIC_ACQUIRE);
        int todo = -1;
        bool specd = false;
        if (to_dest && !__atomic_load_n(&v->waiting, __ATOMIC_ACQUIRE)) {
            // the frames of the angle the stage is moving to
            pthread_mutex_lock(&v->cache_lock);
            specd = speculate_angle(v, sample, dest, next_seed) == 1;
            pthread_mutex_unlock(&v->cache_lock);
        }
        if (!r && !st.moving && st.homed) {
            pthread_mutex_lock(&v->cache_lock);
            // lamps that are on first; the others only while no frame waits
            for (int pass = 0; pass < 2 && todo < 0 && !specd; pass++) {
                // between the passes: the next frames of this state
                if (pass == 1 && !__atomic_load_n(&v->waiting, __ATOMIC_ACQUIRE)) {
                    int a = speculate_angle(v, sample, st.angle_deg, next_seed);
                    specd = a == 1 || (a < 0 && speculate_one(v, sample, st.angle_deg, mask, next_seed));
                }
                if (specd) break;
                for (int l = 0; l < v->lamps->n && todo < 0; l++) {
                    bool on = (mask >> l) & 1;
                    if (on != (pass == 0)) continue;
                    if (pass == 1 && (v->prerender < 2 || __atomic_load_n(&v->waiting, __ATOMIC_ACQUIRE) ||
                                      v->lamps->n > NPLANES / 2))
                        continue;
                    if (!rig_vplane_cached(v, sample, st.angle_deg, l)) todo = l;
                }
            }
            if (todo >= 0) rig_vplane_for(v, sample, st.angle_deg, todo);   // errors show at the trigger
            pthread_mutex_unlock(&v->cache_lock);
        }
        if (todo < 0 && !specd) rig_vsleep_s(2e-3);
    }
    return NULL;
}
