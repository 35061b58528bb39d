// fit/eval/lab.c — verification experiments on the virtual rig: images of
// the workpiece at several turntable angles with drifted lamps and camera,
// fresh sensor noise per case, and the calibrations a lab would have (the
// truth's camera model, lamp positions and kc*I, an offset map and a flat
// field measured noise-free from the rig's own dark and flat-field frames,
// K and read noise). See fit/eval/lab.h.
#define _GNU_SOURCE
#include <math.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fit/eval/lab.h"
#include "rig/rig.h"
#include "rig/virtual/truth.h"

struct eval_lab {
    rig_virtual_t *v;
    int W, H, nang, nl, nplace;   // nplace: sets of planes (0: as opened; then each eval_lab_add_placement)
    double *angles;
    double exposure_us, gain_db, kc_per_us;
    float **L;                 // nplace * nang * nl radiance planes
    char sample[64];
    float *offset, *flat;
    model_sensor_t sensor;
    verify_camera_t cam;
    model_lin_t lin;           // the truth sensor's S(1 - aS) (the matched rig's response), cam.lin
    model_lamps_t *lamps;      // a copy (truth positions, intensities)
    double *A;                 // kc_per_us * I
    model_materials_t *mats;   // the truth's materials
    char truth[4096];
    double draw[32][3];        // per placement set: the truth's placement error drawn for it (turn deg, dx, dy mm)
};

static int fail_rig(int r, const char *what)
{
    model_error(NULL, 0, "virtual rig: %s: %s", what, rig_strerror(r));
    return r;
}

// The radiance planes of placement set `place` (L->L[place * nang * nl ...]) for the current sample.
static bool render_planes(eval_lab_t *L, int place, bool verbose)
{
    size_t npx = (size_t)L->W * L->H;
    for (int a = 0; a < L->nang; a++)
        for (int i = 0; i < L->nl; i++) {
            if (verbose)
                model_progress("rendering %s on the virtual rig at %g deg, lamp %s (%d/%d)", L->sample, L->angles[a],
                               L->lamps->lamps[i].name, a * L->nl + i + 1, L->nang * L->nl);
            float *P = malloc(npx * sizeof(float));
            if (!P) {
                model_error(NULL, 0, "verify lab: out of memory for the radiance planes");
                return false;
            }
            L->L[(place * L->nang + a) * L->nl + i] = P;
            int r = rig_virtual_radiance(L->v, L->angles[a], i, P);
            if (r) {
                fail_rig(r, "rendering");
                return false;
            }
        }
    if (verbose) model_progress_end();
    return true;
}

void eval_lab_free(eval_lab_t *L)
{
    if (!L) return;
    if (L->L)
        for (int k = 0; k < L->nplace * L->nang * L->nl; k++) free(L->L[k]);
    free(L->L);
    free(L->angles);
    free(L->offset);
    free(L->flat);
    free(L->A);
    model_lamps_free(L->lamps);
    model_materials_free(L->mats);
    rig_virtual_close(L->v);
    free(L);
}

eval_lab_t *eval_lab_open(const char *truth_path, const char *sample, const double *angles, int nang,
                          double exposure_us, double gain_db, bool verbose)
{
    eval_lab_t *L = calloc(1, sizeof *L);
    if (!L) {
        model_error(NULL, 0, "verify lab: out of memory");
        return NULL;
    }
    snprintf(L->truth, sizeof L->truth, "%s", truth_path);
    snprintf(L->sample, sizeof L->sample, "%s", sample);
    // several labs may live in one process: each camera its own serial
    static atomic_int count;
    char serial[32];
    snprintf(serial, sizeof serial, "REFL-LAB%d", atomic_fetch_add(&count, 1) + 1);
    rig_virtual_options_t o = rig_virtual_defaults();
    o.serve = RIG_VIRTUAL_SERVE_INPROCESS;
    o.serial = serial;
    o.time_scale = 0.001;
    int r = rig_virtual_open(&L->v, truth_path, &o);
    if (r) {
        fail_rig(r, truth_path);
        free(L);
        return NULL;
    }
    model_camera_t *cam = rig_virtual_camera_model(L->v);
    L->W = model_camera_width(cam);
    L->H = model_camera_height(cam);
    L->nang = nang;
    L->exposure_us = exposure_us;
    L->gain_db = gain_db;
    L->kc_per_us = rig_virtual_kc_per_us(L->v);
    L->sensor = rig_virtual_sensor_params(L->v);
    const model_lamps_t *tl = rig_virtual_lamps_truth(L->v);
    L->nl = tl->n;
    size_t npx = (size_t)L->W * L->H;
    L->angles = malloc((size_t)nang * sizeof *L->angles);
    L->L = calloc((size_t)nang * L->nl, sizeof *L->L);
    L->offset = malloc(npx * sizeof(float));
    L->flat = malloc(npx * sizeof(float));
    L->A = malloc((size_t)L->nl * sizeof *L->A);
    // the truth's lamps and materials (rig/virtual/truth.h): this lab is the simulation path of the study
    rig_truth_t *truth = rig_truth_load(truth_path);
    double radiance = NAN;
    L->lamps = truth ? rig_truth_lamps(truth) : NULL;
    L->mats = L->lamps ? rig_truth_materials(truth) : NULL;
    // the flat field's source radiance (for the flat field's mean below)
    bool have_radiance = L->mats && rig_truth_uniform_radiance(truth, "flat_field", &radiance);
    rig_truth_free(truth);
    if (!L->angles || !L->L || !L->offset || !L->flat || !L->A) {
        model_error(NULL, 0, "verify lab: out of memory for a %dx%d camera", L->W, L->H);
        goto fail;
    }
    if (!have_radiance) goto fail;
    for (int i = 0; i < L->nl; i++) L->A[i] = L->kc_per_us * L->lamps->lamps[i].intensity;
    memcpy(L->angles, angles, (size_t)nang * sizeof *angles);
    // the flat field and the offset map, as a gain calibration measures them (noise-free here)
    float *tmp = malloc(npx * sizeof(float));
    if (!tmp) {
        model_error(NULL, 0, "verify lab: out of memory for a %dx%d camera", L->W, L->H);
        goto fail;
    }
    const double flat_us = 20000;
    if ((r = rig_virtual_set_sample(L->v, "flat_field")) ||
        (r = rig_virtual_expected(L->v, 0, 1, flat_us, 0, "Mono12", L->W, L->H, tmp)) ||
        (r = rig_virtual_expected(L->v, 0, 0, flat_us, 0, "Mono12", L->W, L->H, L->flat))) {
        fail_rig(r, "flat field");
        free(tmp);
        goto fail;
    }
    double sum = 0;
    for (size_t i = 0; i < npx; i++) {
        L->flat[i] = tmp[i] - L->flat[i];
        sum += L->flat[i];
    }
    for (size_t i = 0; i < npx; i++) L->flat[i] = (float)(L->flat[i] / (sum / npx));
    free(tmp);
    // The flat field has mean 1; the sensor's gain pattern (PRNU x vignetting)
    // does not: its mean goes into kc*I, as a white calibration through this
    // flat field measures it (linearised as verify does).
    L->lin = (model_lin_t){ .kind = MODEL_LIN_PARAMETRIC, .a_per_dn = L->sensor.nonlinearity_pct / 100 /
                                                                   (L->sensor.system_gain_dn_per_e *
                                                                    L->sensor.full_well_e) };
    double S = model_linearise(&L->lin, sum / npx, 1, NULL);
    double gmean = S / (L->kc_per_us * flat_us * radiance);
    for (int i = 0; i < L->nl; i++) L->A[i] *= gmean;
    if ((r = rig_virtual_set_sample(L->v, sample))) {
        fail_rig(r, sample);
        goto fail;
    }
    if ((r = rig_virtual_expected(L->v, angles[0], 0, exposure_us, gain_db, "Mono12", L->W, L->H, L->offset))) {
        fail_rig(r, "dark frame");
        goto fail;
    }
    L->nplace = 1;
    if (!rig_virtual_last_placement(L->v, &L->draw[0][0], &L->draw[0][1], &L->draw[0][2]))
        L->draw[0][0] = L->draw[0][1] = L->draw[0][2] = 0;
    if (!render_planes(L, 0, verbose)) goto fail;
    snprintf(L->cam.name, sizeof L->cam.name, "virtual");
    L->cam.cam = cam;
    L->cam.offset_dn = L->offset;
    L->cam.flat = L->flat;
    L->cam.K_dn_per_e = L->sensor.system_gain_dn_per_e;
    L->cam.read_noise_e = L->sensor.read_noise_e;
    L->cam.saturation_dn = (1 << L->sensor.bits) - 1;
    L->cam.lin = &L->lin;
    rig_virtual_pixel_response(L->v, &L->cam.pixel_fill, &L->cam.psf_sigma_px);   // as a PSF calibration finds them
    return L;
fail:
    eval_lab_free(L);
    return NULL;
}

int                    eval_lab_nlamps(const eval_lab_t *L) { return L->nl; }
const verify_camera_t *eval_lab_camera(const eval_lab_t *L) { return &L->cam; }
const model_lamps_t   *eval_lab_lamps(const eval_lab_t *L) { return L->lamps; }
const double          *eval_lab_A(const eval_lab_t *L) { return L->A; }
const model_materials_t *eval_lab_materials(const eval_lab_t *L) { return L->mats; }
int eval_lab_width(const eval_lab_t *L) { return L->W; }
int eval_lab_height(const eval_lab_t *L) { return L->H; }

int eval_lab_add_placement(eval_lab_t *L, double turn_deg, double dx_mm, double dy_mm, bool verbose)
{
    if (L->nplace >= 32) {
        model_error(NULL, 0, "verify lab: at most 31 placements");
        return -1;
    }
    int r = rig_virtual_set_sample_offset(L->v, L->sample, turn_deg, dx_mm, dy_mm);
    if (r) {
        fail_rig(r, L->sample);
        return -1;
    }
    double *d = L->draw[L->nplace];
    if (!rig_virtual_last_placement(L->v, &d[0], &d[1], &d[2])) d[0] = d[1] = d[2] = 0;
    size_t per = (size_t)L->nang * L->nl;
    float **grown = realloc(L->L, (size_t)(L->nplace + 1) * per * sizeof *grown);
    if (!grown) {
        model_error(NULL, 0, "verify lab: out of memory for the radiance planes");
        return -1;
    }
    L->L = grown;
    memset(&L->L[L->nplace * per], 0, per * sizeof *L->L);
    int place = L->nplace++;
    return render_planes(L, place, verbose) ? place : -1;
}

int eval_lab_nplacements(const eval_lab_t *L) { return L->nplace; }

bool eval_lab_placement_draw(const eval_lab_t *L, int place, double *turn_deg, double *dx_mm, double *dy_mm)
{
    if (place < 0 || place >= L->nplace) return false;
    *turn_deg = L->draw[place][0];
    *dx_mm = L->draw[place][1];
    *dy_mm = L->draw[place][2];
    return true;
}

bool eval_lab_image(eval_lab_t *L, int angle_index, uint32_t lamps_on, const double *lamp_scale,
                    double kc_scale, uint64_t seed, float *out)
{
    return eval_lab_image_placed(L, 0, angle_index, lamps_on, lamp_scale, kc_scale, seed, out);
}

bool eval_lab_image_placed(eval_lab_t *L, int place, int angle_index, uint32_t lamps_on, const double *lamp_scale,
                           double kc_scale, uint64_t seed, float *out)
{
    if (angle_index < 0 || angle_index >= L->nang || place < 0 || place >= L->nplace) {
        model_error(NULL, 0, "verify lab: angle index %d or placement %d out of range", angle_index, place);
        return false;
    }
    size_t npx = (size_t)L->W * L->H;
    double gf = 1;   // the virtual camera's Gain is in dB (its GenICam <Unit>); rig_virtual_expected checked it
    model_gain_factor(L->gain_db, "dB", 0, "dB", "verify lab", &gf);
    double kc = L->kc_per_us * L->exposure_us * gf * kc_scale;
    for (size_t p = 0; p < npx; p++) out[p] = (float)L->sensor.dark_offset_dn;
    for (int i = 0; i < L->nl; i++) {
        if (!((lamps_on >> i) & 1)) continue;
        const float *P = L->L[(place * L->nang + angle_index) * L->nl + i];
        float f = (float)(kc * (lamp_scale ? lamp_scale[i] : 1));
        for (size_t p = 0; p < npx; p++) out[p] += f * P[p];
    }
    int r = rig_virtual_sensor_apply(L->v, L->exposure_us, L->gain_db, seed, out);
    if (r) {
        fail_rig(r, "sensor");
        return false;
    }
    return true;
}
