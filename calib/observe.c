// calib/observe.c — calibrated observations of a sample in a capture session:
// for each window of the sample's faces lit by one lamp, the dark- and
// flat-corrected signal per microsecond with its geometry (the cosines, the
// lamp distance) from the camera model and the lamp positions.
#define _GNU_SOURCE
#include <errno.h>
#include <glib.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "calib/calib.h"
#include "model/base/report.h"
#include "model/base/vec.h"
#include "rig/rig.h"

calib_observe_options_t calib_observe_defaults(void)
{
    return (calib_observe_options_t){ .window = 5, .step = 8, .min_signal_dn = 20,
                                      .pose = calib_sample_pose_defaults() };
}

void calib_obs_free(calib_obs_set_t *s)
{
    if (!s) return;
    free(s->o);
    calib_drift_free(&s->drift);
    memset(s, 0, sizeof *s);
}

static bool obs_add(calib_obs_set_t *s, const calib_obs_t *o)
{
    if (s->n == s->cap) {
        int cap = s->cap ? 2 * s->cap : 4096;
        calib_obs_t *n = realloc(s->o, (size_t)cap * sizeof *n);
        if (!n) return false;
        s->o = n;
        s->cap = cap;
    }
    s->o[s->n++] = *o;
    return true;
}

// The sample's scene (opt->scene_path: a capture plan's [sample] names no
// scene, and the virtual rig's truth is no default for a measurement), posed
// on the plan's wedge or (o->fit_pose) at its pose fitted from the session's
// frames (out->pose), and the index of the material to observe (named in
// out->material, or the scene's only one).
static model_scene_t *observe_scene(const rig_session_t *s, const rig_plan_t *plan, const calib_set_t *cal,
                                    const calib_observe_options_t *o, calib_obs_set_t *out, int *mat)
{
    const char *scene_path = o->scene_path;
    double unit_mm = o->scene_unit_mm;
    if (!scene_path) {
        model_error_set(s->dir, 0, "the session records no scene of its sample %s (a capture plan's [sample] names "
                        "none): give the sample's scene (--scene FILE) and its material (--material NAME)",
                        plan->sample);
        return NULL;
    }
    model_scene_options_t so = MODEL_SCENE_OPTIONS_DEFAULT;
    so.unit_mm = unit_mm;
    model_scene_t *scene = model_scene_load(scene_path, &so);
    if (!scene) return NULL;
    *mat = -1;
    if (out->material[0]) {
        *mat = model_scene_material_index(scene, out->material);
        if (*mat < 0) model_error_set(scene_path, 0, "the scene has no material '%s'", out->material);
    } else if (scene->nmaterials == 1) {
        *mat = 0;
        snprintf(out->material, sizeof out->material, "%s", scene->material_names[0]);
    } else {
        model_error_set(scene_path, 0, "the scene has %d materials: say which one to observe (--material NAME)",
                        scene->nmaterials);
    }
    model_scene_t *posed = NULL;
    out->pose = (calib_sample_pose_t){ .nominal = { plan->tilt_deg, plan->tilt_azimuth_deg },
                                       .p = { plan->tilt_deg, plan->tilt_azimuth_deg } };
    bool ok = *mat >= 0 && (!o->fit_pose || calib_sample_pose_fit(s, plan, cal, scene, &o->pose, &out->pose));
    if (ok && out->pose.tried && (!out->pose.fitted || out->pose.at_prior_edge))   // a warning, said at once
        model_warning("%s: sample pose: %s", s->dir, out->pose.note);
    if (ok) {
        double R[9], t[3];
        calib_sample_pose_Rt(scene, out->pose.p, R, t);
        for (int r = 0; r < 3; r++) out->pose.normal[r] = R[3 * r + 2];
        posed = model_scene_transformed(scene, R, t);
    }
    model_scene_free(scene);
    return posed;
}

typedef struct {
    double q[2];
    int    face;
} window_t;

static int cmp_exposure_desc(const void *a, const void *b, void *ctx)
{
    const rig_frame_row_t *r = ctx;
    double x = r[*(const int *)a].exposure_us, y = r[*(const int *)b].exposure_us;
    return (x < y) - (x > y);
}

// One observation run: the session, the calibrations, the posed scene and
// the material's index; win holds the windows of the current angle.
typedef struct {
    const char                    *session_dir;
    const rig_session_t           *s;
    const calib_set_t             *cal;
    const calib_observe_options_t *o;
    const model_scene_t           *scene;   // posed on the wedge, at angle 0
    int                            mat;
    int                            nx, ny;  // the window grid
    window_t                      *win;     // nx * ny
    int                            nw;      // windows on the material at the current angle
    calib_obs_set_t               *out;
} observe_t;

// The frames of row f0's angle (the same measured and commanded position)
// not yet done, longest exposure first, into order; marks them done. Their count.
static int angle_frames(const rig_session_t *s, int f0, bool *done_row, int *order)
{
    const rig_frame_row_t *r0 = &s->rows[f0];
    int nf = 0;
    for (int f = f0; f < s->n; f++)
        if (!done_row[f] && s->rows[f].measured_deg == r0->measured_deg &&
            s->rows[f].commanded_deg == r0->commanded_deg) {
            order[nf++] = f;
            done_row[f] = true;
        }
    qsort_r(order, (size_t)nf, sizeof *order, cmp_exposure_desc, (void *)s->rows);
    return nf;
}

// The windows of the grid that lie wholly on the material (the centre and
// four corners on one face) in the view of tracer tr into ob->win, ob->nw.
static bool material_windows(observe_t *ob, model_tracer_t *tr)
{
    const int half = ob->o->window / 2, nq = ob->nx * ob->ny * 5;
    double *q = malloc((size_t)nq * 2 * sizeof *q);
    model_pixel_info_t *pi = malloc((size_t)nq * sizeof *pi);
    ob->nw = 0;
    if (!q || !pi) {
        free(q);
        free(pi);
        model_error_set(ob->session_dir, 0, "out of memory");
        return false;
    }
    static const int dx[5] = { 0, -1, 1, -1, 1 }, dy[5] = { 0, -1, -1, 1, 1 };
    int k = 0;
    for (int j = 0; j < ob->ny; j++)
        for (int i = 0; i < ob->nx; i++)
            for (int c = 0; c < 5; c++) {
                q[2 * k] = i * ob->o->step + half + dx[c] * half;
                q[2 * k + 1] = j * ob->o->step + half + dy[c] * half;
                k++;
            }
    model_pixel_info(tr, ob->cal->cam, NULL, q, nq, pi, NULL, 0);
    for (int w = 0; w < ob->nx * ob->ny; w++) {
        const model_pixel_info_t *p = &pi[5 * w];
        if (p->face < 0 || p->material != ob->mat) continue;
        bool same = true;
        for (int c = 1; c < 5; c++) same = same && pi[5 * w + c].face == p->face;
        if (!same) continue;
        ob->win[ob->nw].q[0] = q[10 * w];
        ob->win[ob->nw].q[1] = q[10 * w + 1];
        ob->win[ob->nw].face = p->face;
        ob->nw++;
    }
    free(q);
    free(pi);
    return true;
}

// The session's dark frame for row r: lamps none at the same gain, nearest in
// exposure, then in steps (the dark current is a small part of the dark
// level: an auto bracket of lamps off stops at its longest exposure). -1: none.
static int dark_frame(const rig_session_t *s, const rig_frame_row_t *r)
{
    int best = -1;
    for (int f = 0; f < s->n; f++) {
        const rig_frame_row_t *q = &s->rows[f];
        if (strcmp(q->lamps, "none") || q->gain != r->gain) continue;
        double de = fabs(q->exposure_us - r->exposure_us);
        double db = best < 0 ? 0 : fabs(s->rows[best].exposure_us - r->exposure_us);
        if (best < 0 || de < db || (de == db && abs(q->step - r->step) < abs(s->rows[best].step - r->step)))
            best = f;
    }
    return best;
}

// The observation of window w in frame r lit by lamp (pixel info p, lamp
// sample L; img and dark (NULL with an offset map) the frame's grey values;
// sat the saturation limit, gf the gain factor). false when the window gives
// none (unlit, shadowed, saturated or below the signal floor).
static bool window_observation(const observe_t *ob, const rig_frame_row_t *r, int lamp, const window_t *w,
                               const model_pixel_info_t *p, const model_lamp_sample_t *L, const float *img,
                               const float *dark, double sat, double gf, calib_obs_t *obs)
{
    const calib_set_t *cal = ob->cal;
    const int win = ob->o->window, half = win / 2;
    if (!(L->V > 0.999)) return false;
    model_cosines_t c = model_cosines(p->n, L->l, p->v);
    if (!(c.nl > 0 && c.nv > 0)) return false;
    int x0 = (int)w->q[0] - half, y0 = (int)w->q[1] - half;
    double sum = 0, mx = 0, sg = 0;
    for (int y = y0; y < y0 + win; y++)
        for (int x = x0; x < x0 + win; x++) {
            size_t i = (size_t)y * cal->W + x;
            // the gain calibration's linearisation at this gain
            sum += model_linearise(&cal->lin, img[i] - (cal->offset_dn ? cal->offset_dn[i] : dark[i]), gf, NULL);
            mx = fmax(mx, img[i]);
            sg += cal->flat ? cal->flat[i] : 1;
        }
    double n = (double)win * win;
    if (mx >= sat) return false;   // a shorter exposure of the bracket takes it
    double sig = sum / n;
    if (sig < ob->o->min_signal_dn) return false;
    // a finite lamp near the mirror direction (within 20 deg: where a
    // narrow lobe changes over the lamp's disc) gets its disc's cosines
    model_vec3_t dl[4];
    bool has_disc = c.nh > cos(20 * M_PI / 180) && model_lamp_disc_dirs(L->l, L->d_mm, cal->lamp_radius_mm[lamp], dl);
    // the lamp's emission pattern toward the window (1: isotropic) is divided
    // out, as the flat field is: s is the signal of the lamp's on-axis intensity
    double em = model_lamp_emission(&cal->lamps->lamps[lamp], p->p_mm);
    if (!(em > 1e-6)) return false;   // outside the lamp's beam
    // and the lamp's drift since its first visit of the reference (1 without revisits)
    double dr = calib_drift_factor(&ob->out->drift, lamp, r->t_trigger_utc_s);
    em *= dr;
    *obs = (calib_obs_t){ .lamp = lamp, .angle_deg = r->measured_deg, .exposure_us = r->exposure_us,
                          .gain_db = 20 * log10(gf), .q = { w->q[0], w->q[1] }, .c = c, .d_mm = L->d_mm,
                          .s_dn_per_us = sig / (sg / n) / (r->exposure_us * gf * em), .emission = em / dr, .drift = dr,
                          .step = r->step, .face = p->face, .has_disc = has_disc };
    for (int k = 0; has_disc && k < 4; k++) obs->disc[k] = model_cosines(p->n, dl[k], p->v);
    // the point at angle 0: turned back about the table's axis (z)
    double ca = cos(-r->measured_deg * M_PI / 180), sa = sin(-r->measured_deg * M_PI / 180);
    model_vec3_t pp = p->p_mm;
    obs->p0_mm[0] = ca * pp.x - sa * pp.y;
    obs->p0_mm[1] = sa * pp.x + ca * pp.y;
    obs->p0_mm[2] = pp.z;
    obs->n0[0] = ca * p->n.x - sa * p->n.y;
    obs->n0[1] = sa * p->n.x + ca * p->n.y;
    obs->n0[2] = p->n.z;
    if (cal->gain_dn_per_e > 0) {
        // per pixel: shot noise K*signal (K scales with the gain), read noise, quantisation
        double K = cal->gain_dn_per_e * gf, rd = K * cal->read_noise_e;
        double var = (K * sig + rd * rd + 1.0 / 12) / n;
        obs->s_std = sqrt(var) / (sg / n) / (r->exposure_us * gf * em);
    }
    return true;
}

// The observations of frame f (one lamp lit) in the windows ob->win with
// their geometry pw, ls (per window: the lamps' samples); taken marks the
// windows and lamps a longer exposure already gave. false + message.
static bool observe_frame(observe_t *ob, int f, const model_pixel_info_t *pw, const model_lamp_sample_t *ls,
                          unsigned char *taken)
{
    const rig_session_t *s = ob->s;
    const calib_set_t *cal = ob->cal;
    const rig_frame_row_t *r = &s->rows[f];
    const int nl = cal->lamps->n;
    if (!strcmp(r->lamps, "none")) return true;
    int lamp = model_lamps_find(cal->lamps, r->lamps);
    if (lamp < 0) {
        ob->out->frames_skipped++;   // several lamps at once, or a lamp the calibration lacks
        return true;
    }
    float *dark = NULL, *img = NULL;
    bool ok = false;
    int w_, h_;
    if (!cal->offset_dn) {
        int d = dark_frame(s, r);
        if (d < 0) {
            model_error_set(ob->session_dir, 0, "step %d (%s, %g us): no dark level: the calibration has no offset "
                            "map and the session no dark frame (add the lamp set none or dark_every to the plan, "
                            "or a gain calibration)", r->step, r->lamps, r->exposure_us);
            return false;
        }
        if (!(dark = rig_session_frame(s, d, &w_, &h_))) return false;
    }
    if (!(img = rig_session_frame(s, f, &w_, &h_))) goto done;
    if (w_ != cal->W || h_ != cal->H) {
        model_error_set(ob->session_dir, 0, "step %d: %dx%d frame, the camera model is %dx%d", r->step, w_, h_,
                        cal->W, cal->H);
        goto done;
    }
    double sat = 0.95 * (cal->saturation_dn > 0 ? cal->saturation_dn : calib_full_scale_dn(r->pixel_format));
    // the gain as a factor relative to the gain calibration's gain (gain.json
    // gain_db and gain_unit), by the frame's unit (model_gain_factor)
    char what[512];
    snprintf(what, sizeof what, "%s/%s (step %d)", ob->session_dir, r->file, r->step);
    double gf;
    if (!model_gain_factor(r->gain, r->gain_unit, cal->cal_gain, cal->cal_gain_unit, what, &gf)) goto done;
    for (int w = 0; w < ob->nw; w++) {
        if (taken[(size_t)w * nl + lamp]) continue;
        calib_obs_t obs;
        if (!window_observation(ob, r, lamp, &ob->win[w], &pw[w], &ls[(size_t)w * nl + lamp], img, dark, sat, gf,
                                &obs))
            continue;
        if (!obs_add(ob->out, &obs)) {
            model_error_set(ob->session_dir, 0, "out of memory");
            goto done;
        }
        taken[(size_t)w * nl + lamp] = 1;
    }
    ob->out->frames_used++;
    ok = true;
done:
    free(img);
    free(dark);
    return ok;
}

// The observations of one angle's frames (order[0..nf-1], longest exposure
// first) at the measured angle deg. false + message.
static bool observe_angle(observe_t *ob, const int *order, int nf, double deg)
{
    const calib_set_t *cal = ob->cal;
    const int nl = cal->lamps->n;
    bool ok = false;
    double *qw = NULL;
    model_pixel_info_t *pw = NULL;
    model_lamp_sample_t *ls = NULL;
    unsigned char *taken = NULL;
    model_scene_t *rot = model_scene_rotated_z(ob->scene, deg);
    model_tracer_t *tr = rot ? model_tracer_new(rot) : NULL;
    if (!tr || !material_windows(ob, tr)) goto done;
    if (ob->nw == 0) {
        model_warning("%s: at %.3f deg no window of %dx%d pixels lies on material %s", ob->session_dir, deg,
                      ob->o->window, ob->o->window, ob->out->material);
        ob->out->frames_skipped += nf;
        ok = true;
        goto done;
    }
    // geometry per window and lamp
    qw = malloc((size_t)ob->nw * 2 * sizeof *qw);
    pw = malloc((size_t)ob->nw * sizeof *pw);
    ls = malloc((size_t)ob->nw * nl * sizeof *ls);
    taken = calloc((size_t)ob->nw * nl, 1);
    if (!qw || !pw || !ls || !taken) {
        model_error_set(ob->session_dir, 0, "out of memory");
        goto done;
    }
    for (int w = 0; w < ob->nw; w++) {
        qw[2 * w] = ob->win[w].q[0];
        qw[2 * w + 1] = ob->win[w].q[1];
    }
    model_pixel_info(tr, cal->cam, cal->lamps, qw, ob->nw, pw, ls, 0);
    for (int a = 0; a < nf; a++)
        if (!observe_frame(ob, order[a], pw, ls, taken)) goto done;
    if (ob->o->verbose)
        model_note("%s: angle %.2f deg: %d windows, %d observations so far", ob->session_dir, deg, ob->nw,
                   ob->out->n);
    ok = true;
done:
    free(qw);
    free(pw);
    free(ls);
    free(taken);
    model_tracer_free(tr);
    model_scene_free(rot);
    return ok;
}

bool calib_observe(const char *session_dir, const calib_set_t *cal, const calib_observe_options_t *opt,
                   calib_obs_set_t *out)
{
    calib_observe_options_t o = opt ? *opt : calib_observe_defaults();
    memset(out, 0, sizeof *out);
    bool quiet = model_error_quiet_thread(true);   // the caller reports the message
    bool ok = false;
    rig_plan_t *plan = NULL;
    model_scene_t *scene = NULL;
    int *order = NULL;
    bool *done_row = NULL;
    observe_t ob = { .session_dir = session_dir, .cal = cal, .o = &o, .out = out };
    rig_session_t *s = rig_session_open_camera(session_dir, cal->camera[0] ? cal->camera : NULL);   // NULL: the first
    if (!s) goto done;
    ob.s = s;
    if (!(plan = rig_plan_parse(s->plan_text, strlen(s->plan_text), session_dir))) goto done;
    snprintf(out->sample, sizeof out->sample, "%s", plan->sample);
    out->window_px = o.window;
    if (o.material) snprintf(out->material, sizeof out->material, "%s", o.material);
    if (!(scene = observe_scene(s, plan, cal, &o, out, &ob.mat))) goto done;
    if (!calib_drift_measure(s, plan, cal, &out->drift)) goto done;
    for (int l = 0; o.verbose && l < out->drift.nlamps; l++)
        if (out->drift.nvisits[l] > 1) {
            double lo = INFINITY, hi = -INFINITY;
            for (int k = 0; k < out->drift.nvisits[l]; k++)
                lo = fmin(lo, out->drift.f[l][k]), hi = fmax(hi, out->drift.f[l][k]);
            model_note("%s: lamp drift of %s from %d visits of %s: %.4f .. %.4f of the first", session_dir,
                       cal->lamps->lamps[l].name, out->drift.nvisits[l], out->drift.angle_ref[l], lo, hi);
        }
    ob.scene = scene;
    ob.nx = (cal->W - o.window) / o.step + 1;
    ob.ny = (cal->H - o.window) / o.step + 1;
    order = malloc((size_t)(s->n ? s->n : 1) * sizeof *order);
    done_row = calloc((size_t)(s->n ? s->n : 1), 1);
    ob.win = malloc((size_t)ob.nx * ob.ny * sizeof *ob.win);
    if (!order || !done_row || !ob.win) {
        model_error_set(session_dir, 0, "out of memory");
        goto done;
    }
    // frames by angle
    for (int f0 = 0; f0 < s->n; f0++) {
        if (done_row[f0]) continue;
        double deg = s->rows[f0].measured_deg;
        int nf = angle_frames(s, f0, done_row, order);
        if (!observe_angle(&ob, order, nf, deg)) goto done;
    }
    if (out->n == 0) {
        model_error_set(session_dir, 0, "no usable observation of material %s (nothing lit, unsaturated and above "
                        "%g DN on it)", out->material, o.min_signal_dn);
        goto done;
    }
    ok = true;
done:
    free(order);
    free(done_row);
    free(ob.win);
    model_scene_free(scene);
    rig_plan_free(plan);
    rig_session_free(s);
    if (!ok) calib_obs_free(out);
    model_error_quiet_thread(quiet);
    return ok;
}

bool calib_observe_session(const char *session_dir, const char *calib_dir, const char *camera, bool need_white,
                           const calib_observe_options_t *opt, calib_set_t **cal, calib_obs_set_t *out)
{
    memset(out, 0, sizeof *out);
    bool quiet = model_error_quiet_thread(true);   // the caller reports the message
    *cal = calib_set_load_camera(calib_dir, camera, need_white);
    model_error_quiet_thread(quiet);
    return *cal && calib_observe(session_dir, *cal, opt, out);
}

json_t *calib_observe_provenance(int argc, char **argv, const char *session_dir, const calib_set_t *cal)
{
    json_t *prov = model_provenance(argc, argv);
    model_provenance_input(prov, "session", session_dir);
    size_t i;
    json_t *in;
    json_array_foreach(cal->inputs, i, in) json_array_append(json_object_get(prov, "inputs"), in);
    return prov;
}
