// rig/virtual/render.c — the virtual rig's frames: each lamp's radiance plane of a
// (sample, angle) rendered and cached, summed into the ideal frame, then the
// sensor (rig/virtual/virtual.c describes the chain).
#include <math.h>
#include <pthread.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "rig/camera/pixfmt.h"
#include "rig/virtual/internal.h"

// ---------------------------------------------------------------------------
// Rendering

void rig_vslot_free(tracer_slot_t *s)
{
    model_tracer_free(s->t);
    model_scene_free(s->rot);
    free(s->tex);
    free(s->rough);
    memset(s, 0, sizeof *s);
}

// The cached tracer of (sample, angle); cache_lock held. NULL on error.
static tracer_slot_t *tracer_for(rig_virtual_t *v, int sample, double angle_deg)
{
    tracer_slot_t *lru = &v->tracers[0];
    for (int i = 0; i < NTRACERS; i++) {
        tracer_slot_t *s = &v->tracers[i];
        if (s->t && s->sample == sample && s->angle_deg == angle_deg) {
            s->used = ++v->tick;
            return s;
        }
        if (!s->t || (lru->t && s->used < lru->used)) lru = s;
    }
    model_scene_t *rot = rig_virtual_place_rotated(&v->place, v->samples[sample].scene, angle_deg);
    if (!rot) return NULL;
    model_tracer_t *t = model_tracer_new(rot);
    if (!t) {
        model_scene_free(rot);
        return NULL;
    }
    rig_vslot_free(lru);
    *lru = (tracer_slot_t){ .t = t, .rot = rot, .tex = NULL, .sample = sample, .angle_deg = angle_deg,
                            .used = ++v->tick };
    return lru;
}

// Add the low-resolution indirect term (A_lr - B_lr) to L, bilinearly from the
// four low-resolution neighbours of the pixel when all four see the pixel's
// face. A pixel where they do not (within about ds pixels of a face's edge,
// where the indirect light changes fastest: it rises toward a concave corner)
// is marked in `full` instead and gets its indirect term at full resolution
// (indirect_full).
typedef struct {
    const rig_virtual_t *v;
    float               *L;
    uint8_t             *full;
} ind_job_t;

static void indirect_rows(void *ctx, int begin, int end, int thread)
{
    const ind_job_t *J = ctx;
    const rig_virtual_t *v = J->v;
    float *L = J->L;
    const int f = v->ds, Wl = v->Wl, Hl = v->Hl;
    for (int y = begin; y < end; y++) {
        double fy = (y + 0.5) / f - 0.5;
        int y0 = (int)floor(fy);
        double wy = fy - y0;
        for (int x = 0; x < v->W; x++) {
            size_t i = (size_t)y * v->W + x;
            J->full[i] = 0;
            int32_t face = v->face[i];
            if (face < 0) continue;
            double fx = (x + 0.5) / f - 0.5;
            int x0 = (int)floor(fx);
            double wx = fx - x0;
            double sum = 0, wsum = 0;
            int same = 0;
            for (int k = 0; k < 4; k++) {
                int xx = x0 + (k & 1), yy = y0 + (k >> 1);
                if (xx < 0 || yy < 0 || xx >= Wl || yy >= Hl) continue;
                size_t j = (size_t)yy * Wl + xx;
                if (v->face_lr[j] != face) continue;
                double w = ((k & 1) ? wx : 1 - wx) * ((k >> 1) ? wy : 1 - wy) + 1e-9;
                sum += w * (v->A_lr[j] - v->B_lr[j]);
                wsum += w;
                same++;
            }
            if (same < 4) J->full[i] = 1;
            else L[i] += (float)(sum / wsum);
        }
    }
}

// The low-resolution indirect term A_lr - B_lr, into A_lr, averaged over each
// pixel's 3 x 3 neighbours that see its face: the indirect light is smooth
// within a face, its Monte Carlo noise is not (mc_samples paths a pixel). false: out of memory.
static bool indirect_smooth(rig_virtual_t *v)
{
    const int Wl = v->Wl, Hl = v->Hl;
    float *D = malloc((size_t)Wl * Hl * sizeof *D);
    if (!D) return false;
    for (size_t j = 0; j < (size_t)Wl * Hl; j++) D[j] = v->A_lr[j] - v->B_lr[j];
    for (int y = 0; y < Hl; y++)
        for (int x = 0; x < Wl; x++) {
            size_t j = (size_t)y * Wl + x;
            int32_t f = v->face_lr[j];
            double sum = 0;
            int n = 0;
            for (int yy = y - 1; yy <= y + 1; yy++)
                for (int xx = x - 1; xx <= x + 1; xx++) {
                    if (xx < 0 || yy < 0 || xx >= Wl || yy >= Hl) continue;
                    size_t k = (size_t)yy * Wl + xx;
                    if (v->face_lr[k] != f) continue;
                    sum += D[k];
                    n++;
                }
            v->A_lr[j] = (float)(sum / n);
            v->B_lr[j] = 0;
        }
    free(D);
    return true;
}

// The indirect term of the pixels marked in full, at full resolution: the
// shadings ind (MC, point lamps) and base (direct only) of those pixels, their
// difference added to L. false + message.
static bool indirect_full(rig_virtual_t *v, model_tracer_t *t, const model_lamps_t *one,
                          const model_material_t *const *mats, const model_shading_t *ind,
                          const model_shading_t *base, const uint8_t *full, float *L)
{
    size_t npx = (size_t)v->W * v->H;
    float *A = malloc(npx * sizeof *A), *B = malloc(npx * sizeof *B);
    model_shading_t si = *ind, sb = *base;
    si.pixel_mask = sb.pixel_mask = full;
    bool ok = A && B && model_render(t, v->cam, one, mats, &si, A, NULL, NULL) &&
              model_render(t, v->cam, one, mats, &sb, B, NULL, NULL);
    if (!A || !B) model_error(v->truth_path, 0, "out of memory for the indirect light near edges");
    for (size_t i = 0; ok && i < npx; i++)
        if (full[i]) L[i] += A[i] - B[i];
    free(A);
    free(B);
    return ok;
}

// Render the radiance image of lamp `lamp` alone into L (cache_lock held).

static bool render_layers(rig_virtual_t *v, model_tracer_t *t, int sample, int lamp,
                          const model_material_t *const *mats, float *L);

static bool render_lamp_rays(rig_virtual_t *v, tracer_slot_t *slot, int sample, int lamp, float *L);

// A lamp's radiance plane with the optics of [optics] (rig/virtual/optics.c).
static bool render_lamp_once(rig_virtual_t *v, tracer_slot_t *slot, int sample, int lamp, float *L);

static bool render_lamp(rig_virtual_t *v, tracer_slot_t *slot, int sample, int lamp, float *L)
{
    bool ok = v->optics.rays_per_pixel > 1 ? render_lamp_rays(v, slot, sample, lamp, L)
                                           : render_lamp_once(v, slot, sample, lamp, L);
    return ok && rig_optics_psf(&v->optics, v->W, v->H, L);
}

// rays_per_pixel N > 1: the same rendering by the camera of N times the
// resolution (a view of v with that camera, its own face ids, texture and
// roughness weights), its N x N blocks averaged.
static bool render_lamp_rays(rig_virtual_t *v, tracer_slot_t *slot, int sample, int lamp, float *L)
{
    const int N = v->optics.rays_per_pixel;
    rig_virtual_t *hv = malloc(sizeof *hv);
    if (!hv) {
        model_error(v->truth_path, 0, "out of memory for a rendering of %d x %d rays per pixel", N, N);
        return false;
    }
    *hv = *v;   // its locks are never used
    hv->cam = v->cam_hr;
    hv->W = v->W * N;
    hv->H = v->H * N;
    hv->face = v->face_hr;
    hv->ds = v->ds > 1 ? v->ds * N : 1;   // the same low-resolution indirect camera
    tracer_slot_t hs = *slot;
    hs.tex = NULL;
    hs.rough = NULL;
    bool ok = render_lamp_once(hv, &hs, sample, lamp, v->L_hr);
    free(hs.tex);
    free(hs.rough);
    free(hv);
    if (ok) rig_optics_average(N, v->W, v->H, v->L_hr, L);
    return ok;
}

static bool render_lamp_once(rig_virtual_t *v, tracer_slot_t *slot, int sample, int lamp, float *L)
{
    const sample_t *sm = &v->samples[sample];
    if (!render_layers(v, slot->t, sample, lamp, sm->rough ? sm->mats_smooth : sm->mats, L)) return false;
    if (!sm->textured) return true;
    if (!slot->tex && !rig_vtexture_make(v, slot, v->face)) return false;
    if (sm->rough) {   // the rough population, blended in by the slot's weights
        float *Lr = malloc((size_t)v->W * v->H * sizeof *Lr);
        bool ok = Lr && render_layers(v, slot->t, sample, lamp, sm->mats_rough, Lr);
        if (ok) rig_vmat_blend(L, Lr, slot->rough, (size_t)v->W * v->H);
        else if (!Lr) model_error(v->truth_path, 0, "out of memory for a roughness layer");
        free(Lr);
        if (!ok) return false;
    }
    for (size_t i = 0; i < (size_t)v->W * v->H; i++) L[i] *= slot->tex[i];
    return true;
}

// The layers of a rendering (direct, indirect), untextured, and the face ids
// into v->face.
static bool render_layers(rig_virtual_t *v, model_tracer_t *t, int sample, int lamp,
                          const model_material_t *const *mats, float *L)
{
    model_lamps_t one = *v->lamps;
    one.n = 1;
    one.lamps = &v->lamps->lamps[lamp];
    model_shading_t sh = v->shading;
    sh.kc = 1;
    sh.Pa = 0;
    sh.gain_map = NULL;
    sh.seed = v->shading.seed + 0x9e3779b97f4a7c15ULL * (uint64_t)(lamp + 1);
    if (sh.interreflection != MODEL_INTERREFLECTION_MC || v->ds <= 1)
        return model_render(t, v->cam, &one, mats, &sh, L, v->face, NULL);
    model_shading_t direct = sh;
    direct.mc_bounces = 0;
    direct.mc_samples = v->samples[sample].direct_samples > 0 ? v->samples[sample].direct_samples : v->direct_samples;
    if (!model_render(t, v->cam, &one, mats, &direct, L, v->face, NULL)) return false;
    if (sh.mc_bounces == 0) return true;
    model_shading_t ind = sh, base = sh;
    ind.finite_lamps = false;   // then MC's direct term at the first hit is the point lamps' (exact)
    base.interreflection = MODEL_INTERREFLECTION_NONE;
    if (!model_render(t, v->cam_lr, &one, mats, &ind, v->A_lr, NULL, NULL) ||
        !model_render(t, v->cam_lr, &one, mats, &base, v->B_lr, v->face_lr, NULL))
        return false;
    uint8_t *full = malloc((size_t)v->W * v->H);
    if (!full || !indirect_smooth(v)) {
        free(full);
        model_error(v->truth_path, 0, "out of memory for the indirect light");
        return false;
    }
    ind_job_t J = { v, L, full };
    model_parallel_for(v->H, 16, model_default_threads(), indirect_rows, &J);
    bool ok = indirect_full(v, t, &one, mats, &ind, &base, full, L);
    free(full);
    return ok;
}

// The radiance image of one lamp; cache_lock held. NULL on error.
const float *rig_vplane_for(rig_virtual_t *v, int sample, double angle_deg, int lamp)
{
    plane_t *lru = &v->planes[0];
    for (int i = 0; i < NPLANES; i++) {
        plane_t *p = &v->planes[i];
        if (p->L && p->sample == sample && p->lamp == lamp && p->angle_deg == angle_deg) {
            p->used = ++v->tick;
            return p->L;
        }
        if (!p->L || (lru->L && p->used < lru->used)) lru = p;
    }
    const sample_t *sm = &v->samples[sample];
    tracer_slot_t *slot = sm->uniform ? NULL : tracer_for(v, sample, angle_deg);
    if (!slot && !sm->uniform) return NULL;
    if (!lru->L) lru->L = malloc((size_t)v->W * v->H * sizeof(float));
    if (!lru->L) {
        model_error(v->truth_path, 0, "out of memory for a %dx%d rendering", v->W, v->H);
        return NULL;
    }
    if (sm->uniform) {
        for (size_t i = 0; i < (size_t)v->W * v->H; i++) lru->L[i] = (float)sm->radiance;
    } else if (!render_lamp(v, slot, sample, lamp, lru->L)) {
        free(lru->L);
        lru->L = NULL;
        return NULL;
    }
    lru->sample = sample;
    lru->lamp = lamp;
    lru->angle_deg = angle_deg;
    lru->used = ++v->tick;
    return lru->L;
}

static int format_bits(const char *pf)
{
    rig_pixfmt_t f;
    return pf && rig_pixfmt_from_name(pf, &f) ? rig_pixfmt_bits(f) : 0;
}

// The ideal grey value P of the whole sensor into v->frame and the sensor of
// that frame; cache_lock held.
static int ideal_frame(rig_virtual_t *v, int sample, double angle_deg, uint32_t mask, double exposure_us,
                       double gain_db, int64_t trigger_ns, model_sensor_t *s_out, float *out)
{
    size_t n = (size_t)v->W * v->H;
    // The virtual sensor's own physics: its camera's Gain is in dB (GenICam
    // <Unit>dB</Unit>, rig/virtual/gv_camera.c), so this is not a recorded gain's
    // conversion (that is model_gain_factor, by the frame's unit).
    double gf = pow(10.0, gain_db / 20.0);
    double kc = v->kc_per_us * exposure_us * gf;
    const double Pa = v->sensor.dark_offset_dn;
    bool first = true;
    double lf[32];   // each lamp's warm-up and drift at the trigger (exactly 1 without them)
    const float *pl[32];
    int np = 0;
    rig_vlamps_factors(&v->lamp_fx, v->state->lamps_dev, trigger_ns, lf);
    for (int l = 0; l < v->lamps->n && l < 32; l++) {
        if (!((mask >> l) & 1)) continue;
        const float *L = rig_vplane_for(v, sample, angle_deg, l);
        if (!L) return rig_fail(RIG_ERR_IO, "virtual rig: rendering %s at %.4f deg with lamp %s failed: %s",
                                v->samples[sample].name, angle_deg, v->lamps->lamps[l].name, model_last_error());
        double kl = kc * lf[l];
        lf[np] = lf[l];
        pl[np++] = L;
        // the same float arithmetic as Pa first, then each lamp added in turn
        if (first)
            for (size_t i = 0; i < n; i++) out[i] = (float)Pa + (float)(kl * L[i]);
        else
            for (size_t i = 0; i < n; i++) out[i] += (float)(kl * L[i]);
        first = false;
    }
    if (first)
        for (size_t i = 0; i < n; i++) out[i] = (float)Pa;
    // room light does not reach a lens covered by a flat-field source (a
    // uniform_source sample): only the lens's own veiling glare is left
    rig_vlamps_t stray = v->lamp_fx;
    if (v->samples[sample].uniform) stray.ambient_radiance = 0;
    rig_vlamps_add_stray(&stray, out, n, kc, pl, lf, np);
    *s_out = v->sensor;
    s_out->system_gain_dn_per_e *= gf;
    s_out->exposure_us = exposure_us;
    return 0;
}

// Value of a `bits`-bit sample in pixel format fb.
static double to_format(double x, int bits, int fb, bool mean)
{
    if (fb >= bits) return ldexp(x, fb - bits);
    int s = bits - fb;
    if (!mean) return floor(ldexp(x, -s));
    return ldexp(x, -s) - ldexp((double)((1 << s) - 1), -(s + 1));
}

// Is the plane cached? (cache_lock held)
bool rig_vplane_cached(const rig_virtual_t *v, int sample, double angle_deg, int lamp)
{
    for (int i = 0; i < NPLANES; i++) {
        const plane_t *p = &v->planes[i];
        if (p->L && p->sample == sample && p->lamp == lamp && p->angle_deg == angle_deg) return true;
    }
    return false;
}

// The noisy sensor values of a frame into out (cache_lock held).
int rig_vnoisy_frame(rig_virtual_t *v, int sample, double angle_deg, uint32_t mask, double exposure_us,
                     double gain_db, uint64_t seed, int64_t trigger_ns, float *out)
{
    model_sensor_t s;
    int r = ideal_frame(v, sample, angle_deg, mask, exposure_us, gain_db, trigger_ns, &s, out);
    if (r) return r;
    s.noise_seed = seed;
    model_sensor_apply_patterns(&s, v->W, v->H, v->prnu, v->dsnu, out);
    return 0;
}

// The state a trigger sees: the stage's angle (a stage that disconnected
// leaves the sample where it was: the camera keeps seeing it at the last known
// angle), the sample on the table and the frame's noise seed (drawn).
static double trigger_state(rig_virtual_t *v, int *sample, uint64_t *seed)
{
    rig_virtual_t *sv = v->state;
    rig_turntable_status_t st;
    pthread_mutex_lock(&sv->state_lock);
    if (!sv->stage_gone) {
        if (rig_turntable_status(sv->tt_sim, &st) == 0) sv->last_angle_deg = st.angle_deg;
        else sv->stage_gone = true;
    }
    double angle_deg = sv->last_angle_deg;
    pthread_mutex_unlock(&sv->state_lock);
    pthread_mutex_lock(&v->state_lock);
    *sample = v->cur_sample;
    *seed = v->next_seed++;
    pthread_mutex_unlock(&v->state_lock);
    return angle_deg;
}

// The sensor's values (integers in [0, 2^bits - 1]) of the frame's region,
// shifted to the pixel format's fb bits.
static void to_pixels(const rig_virtual_t *v, const rig_frame_meta_t *m, int fb, const float *img, uint16_t *pix)
{
    const int bits = v->sensor.bits;
    int up = fb >= bits ? fb - bits : 0, down = fb < bits ? bits - fb : 0;
    for (int y = 0; y < m->height; y++) {
        const float *row = img + (size_t)(y + m->offset_y) * v->W + m->offset_x;
        uint16_t *o = pix + (size_t)y * m->width;
        for (int x = 0; x < m->width; x++) o[x] = (uint16_t)((((uint32_t)row[x]) >> down) << up);
    }
}

int rig_vrender_cb(void *ctx, const rig_frame_meta_t *m, uint16_t *pix)
{
    rig_virtual_t *v = ctx;
    // the exposure starts now: the lamps' warm-up is theirs at this time,
    // however long the frame waits for the renderer
    struct timespec tnow;
    clock_gettime(CLOCK_MONOTONIC, &tnow);
    int64_t trigger_ns = (int64_t)tnow.tv_sec * 1000000000 + tnow.tv_nsec;
    int sample;
    uint64_t seed;
    double angle_deg = trigger_state(v, &sample, &seed);
    uint32_t mask = __atomic_load_n(&v->state->lamps_dev->on_mask, __ATOMIC_ACQUIRE);
    int fb = format_bits(m->pixel_format);
    if (!fb || m->offset_x + m->width > v->W || m->offset_y + m->height > v->H)
        return rig_fail(RIG_ERR_INVALID, "virtual rig: frame %s %dx%d at (%d,%d) does not fit the %dx%d sensor",
                        m->pixel_format, m->width, m->height, m->offset_x, m->offset_y, v->W, v->H);
    __atomic_add_fetch(&v->waiting, 1, __ATOMIC_ACQ_REL);
    pthread_mutex_lock(&v->cache_lock);
    __atomic_sub_fetch(&v->waiting, 1, __ATOMIC_ACQ_REL);
    rig_vspec_note(v, sample, angle_deg, mask, m->exposure_us, m->gain);
    // A frame computed ahead for exactly these inputs, or compute it now.
    const float *img = rig_vspec_take(v, sample, angle_deg, mask, m->exposure_us, m->gain, seed);
    int r = 0;
    if (!img) {
        r = rig_vnoisy_frame(v, sample, angle_deg, mask, m->exposure_us, m->gain, seed, trigger_ns, v->frame);
        img = v->frame;
    }
    if (!r) to_pixels(v, m, fb, img, pix);
    pthread_mutex_unlock(&v->cache_lock);
    return r;
}

int rig_virtual_expected(rig_virtual_t *v, double angle_deg, uint32_t lamp_mask, double exposure_us,
                         double gain_db, const char *pixel_format, int width, int height, float *out)
{
    if (!v || !out) return rig_fail(RIG_ERR_INVALID, "virtual rig: expected frame: NULL argument");
    int fb = format_bits(pixel_format);
    if (!fb)
        return rig_fail(RIG_ERR_INVALID, "virtual rig: pixel format '%s' is not Mono8, Mono12 or Mono16 (nor "
                        "Mono10, Mono10p, Mono12p, Mono10Packed, Mono12Packed)",
                        pixel_format ? pixel_format : "(null)");
    if (width < 1 || height < 1 || width > v->W || height > v->H)
        return rig_fail(RIG_ERR_INVALID, "virtual rig: expected frame %dx%d does not fit the %dx%d sensor "
                        "(the region starts at the top-left pixel)", width, height, v->W, v->H);
    if (!(isfinite(angle_deg) && fabs(angle_deg) <= 1e4))
        return rig_fail(RIG_ERR_INVALID, "virtual rig: angle %g deg is not within +-10000 deg", angle_deg);
    if (!(isfinite(exposure_us) && exposure_us > 0) || !(isfinite(gain_db) && gain_db >= 0))
        return rig_fail(RIG_ERR_INVALID, "virtual rig: exposure %g us must be > 0 and gain %g dB >= 0",
                        exposure_us, gain_db);
    if (v->lamps->n < 32 && (lamp_mask >> v->lamps->n))
        return rig_fail(RIG_ERR_INVALID, "virtual rig: lamp mask 0x%x names lamps beyond the %d of the truth file",
                        lamp_mask, v->lamps->n);
    pthread_mutex_lock(&v->state_lock);
    int sample = v->cur_sample;
    pthread_mutex_unlock(&v->state_lock);
    pthread_mutex_lock(&v->cache_lock);
    model_sensor_t s;
    int r = ideal_frame(v, sample, angle_deg, lamp_mask, exposure_us, gain_db, 0, &s, v->frame);
    if (!r) {
        model_sensor_mean(&s, v->W, v->H, v->prnu, v->dsnu, v->frame);
        for (int y = 0; y < height; y++)
            for (int x = 0; x < width; x++)
                out[(size_t)y * width + x] = (float)to_format(v->frame[(size_t)y * v->W + x], s.bits, fb, true);
    }
    pthread_mutex_unlock(&v->cache_lock);
    return r;
}

int rig_virtual_radiance(rig_virtual_t *v, double angle_deg, int lamp, float *out)
{
    if (!v || !out) return rig_fail(RIG_ERR_INVALID, "virtual rig: radiance: NULL argument");
    if (lamp < 0 || lamp >= v->lamps->n)
        return rig_fail(RIG_ERR_INVALID, "virtual rig: lamp %d is not one of the %d of the truth file", lamp,
                        v->lamps->n);
    if (!(isfinite(angle_deg) && fabs(angle_deg) <= 1e4))
        return rig_fail(RIG_ERR_INVALID, "virtual rig: angle %g deg is not within +-10000 deg", angle_deg);
    pthread_mutex_lock(&v->state_lock);
    int sample = v->cur_sample;
    pthread_mutex_unlock(&v->state_lock);
    pthread_mutex_lock(&v->cache_lock);
    const float *L = rig_vplane_for(v, sample, angle_deg, lamp);
    if (L) memcpy(out, L, (size_t)v->W * v->H * sizeof(float));
    pthread_mutex_unlock(&v->cache_lock);
    if (!L)
        return rig_fail(RIG_ERR_IO, "virtual rig: rendering %s at %.4f deg with lamp %s failed: %s",
                        v->samples[sample].name, angle_deg, v->lamps->lamps[lamp].name, model_last_error());
    return 0;
}

int rig_virtual_sensor_apply(rig_virtual_t *v, double exposure_us, double gain_db, uint64_t seed, float *img)
{
    if (!v || !img) return rig_fail(RIG_ERR_INVALID, "virtual rig: sensor: NULL argument");
    if (!(isfinite(exposure_us) && exposure_us > 0) || !(isfinite(gain_db) && gain_db >= 0))
        return rig_fail(RIG_ERR_INVALID, "virtual rig: exposure %g us must be > 0 and gain %g dB >= 0", exposure_us,
                        gain_db);
    model_sensor_t s = v->sensor;
    s.system_gain_dn_per_e *= pow(10.0, gain_db / 20.0);   // the sensor's physics: its Gain is in dB (see ideal_frame)
    s.exposure_us = exposure_us;
    s.noise_seed = seed;
    model_sensor_apply_patterns(&s, v->W, v->H, v->prnu, v->dsnu, img);
    return 0;
}
