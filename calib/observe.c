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
#include "model/report.h"
#include "model/vec.h"
#include "rig/rig.h"

// The linear signal S of a measured S_m = S (1 - a S) (the root that goes to
// S_m as a -> 0); S_m as it is without a compression or where it has no root.
static double linear_signal(double s_m, double a)
{
    if (!(a > 0) || !(s_m > 0)) return s_m;
    double disc = 1 - 4 * a * s_m;
    return disc > 0 ? 2 * s_m / (1 + sqrt(disc)) : s_m;
}


calib_observe_options_t calib_observe_defaults(void)
{
    return (calib_observe_options_t){ .window = 5, .step = 8, .min_signal_dn = 20 };
}

void calib_obs_free(calib_obs_set_t *s)
{
    if (!s) return;
    free(s->o);
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

// The sample's scene and material from the virtual rig's truth file (session facts).
static bool truth_sample(const rig_session_t *s, const char *sample, char **scene, char *mat, size_t matlen)
{
    json_t *vr = s->facts ? json_object_get(s->facts, "virtual_rig") : NULL;
    const char *truth = vr ? json_string_value(json_object_get(vr, "truth")) : NULL;
    if (!truth) {
        model_error(s->dir, 0, "the session was not captured on a virtual rig: give the sample's scene (--scene FILE) "
                    "and its material (--material NAME)");
        return false;
    }
    model_ini_t *ini = model_ini_load(truth);
    if (!ini) return false;
    char sec[128];
    snprintf(sec, sizeof sec, "sample %s", sample);
    const model_ini_entry_t *e = model_ini_get(ini, sec, "scene"), *m = model_ini_get(ini, sec, "material");
    if (!e) {
        model_error(truth, 0, "no [sample %s] with a scene (the session's sample)", sample);
        model_ini_free(ini);
        return false;
    }
    char *d = g_path_get_dirname(truth);
    *scene = g_strdup_printf("%s/%s", d, e->value);
    g_free(d);
    if (m && mat && !mat[0]) snprintf(mat, matlen, "%s", m->value);
    model_ini_free(ini);
    return true;
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

static double bits_full(const char *pf)
{
    if (!strcmp(pf, "Mono8")) return 255;
    if (!strcmp(pf, "Mono12")) return 4095;
    return 65535;
}

bool calib_observe(const char *session_dir, const calib_set_t *cal, const calib_observe_options_t *opt,
                 calib_obs_set_t *out)
{
    calib_observe_options_t o = opt ? *opt : calib_observe_defaults();
    memset(out, 0, sizeof *out);
    bool ok = false;
    rig_session_t *s = rig_session_open(session_dir);
    rig_plan_t *plan = NULL;
    model_scene_t *scene = NULL;
    char *scene_path = NULL;
    int *order = NULL;
    window_t *win = NULL;
    unsigned char *taken = NULL;
    if (!s) return false;
    if (!(plan = rig_plan_parse(s->plan_text, strlen(s->plan_text), session_dir))) goto done;
    snprintf(out->sample, sizeof out->sample, "%s", plan->sample);
    if (o.material) snprintf(out->material, sizeof out->material, "%s", o.material);
    if (o.scene_path) scene_path = g_strdup(o.scene_path);
    else if (!truth_sample(s, plan->sample, &scene_path, out->material, sizeof out->material)) goto done;
    if (!(scene = model_scene_load(scene_path, NULL))) goto done;
    int mat = -1;
    if (out->material[0]) {
        mat = model_scene_material_index(scene, out->material);
        if (mat < 0) {
            model_error(scene_path, 0, "the scene has no material '%s'", out->material);
            goto done;
        }
    } else if (scene->nmaterials == 1) {
        mat = 0;
        snprintf(out->material, sizeof out->material, "%s", scene->material_names[0]);
    } else {
        model_error(scene_path, 0, "the scene has %d materials: say which one to observe (--material NAME)",
                    scene->nmaterials);
        goto done;
    }
    double R[9], t[3];
    model_scene_wedge_pose(scene, plan->tilt_deg, plan->tilt_azimuth_deg, R, t);
    model_scene_t *posed = model_scene_transformed(scene, R, t);
    if (!posed) goto done;
    model_scene_free(scene);
    scene = posed;
    // frames by angle
    if (!(order = malloc((size_t)(s->n ? s->n : 1) * sizeof *order))) goto oom;
    const int half = o.window / 2;
    int nx = (cal->W - o.window) / o.step + 1, ny = (cal->H - o.window) / o.step + 1;
    if (!(win = malloc((size_t)nx * ny * sizeof *win))) goto oom;
    bool *done_row = calloc((size_t)(s->n ? s->n : 1), 1);
    if (!done_row) goto oom;
    for (int f0 = 0; f0 < s->n; f0++) {
        if (done_row[f0]) continue;
        const rig_frame_row_t *r0 = &s->rows[f0];
        // this angle's frames (the same measured position), longest exposure first
        int nf = 0;
        for (int f = f0; f < s->n; f++)
            if (!done_row[f] && s->rows[f].measured_deg == r0->measured_deg &&
                s->rows[f].commanded_deg == r0->commanded_deg) {
                order[nf++] = f;
                done_row[f] = true;
            }
        qsort_r(order, (size_t)nf, sizeof *order, cmp_exposure_desc, s->rows);
        model_scene_t *rot = model_scene_rotated_z(scene, r0->measured_deg);
        model_tracer_t *tr = rot ? model_tracer_new(rot) : NULL;
        if (!tr) {
            model_scene_free(rot);
            free(done_row);
            goto done;
        }
        // windows on the material: the centre and four corners on one face
        int nw = 0;
        {
            int nq = nx * ny * 5;
            double *q = malloc((size_t)nq * 2 * sizeof *q);
            model_pixel_info_t *pi = malloc((size_t)nq * sizeof *pi);
            if (!q || !pi) {
                free(q);
                free(pi);
                model_tracer_free(tr);
                model_scene_free(rot);
                free(done_row);
                goto oom;
            }
            static const int dx[5] = { 0, -1, 1, -1, 1 }, dy[5] = { 0, -1, -1, 1, 1 };
            int k = 0;
            for (int j = 0; j < ny; j++)
                for (int i = 0; i < nx; i++)
                    for (int c = 0; c < 5; c++) {
                        q[2 * k] = i * o.step + half + dx[c] * half;
                        q[2 * k + 1] = j * o.step + half + dy[c] * half;
                        k++;
                    }
            model_pixel_info(tr, cal->cam, NULL, q, nq, pi, NULL, 0);
            for (int w = 0; w < nx * ny; w++) {
                const model_pixel_info_t *p = &pi[5 * w];
                if (p->face < 0 || p->material != mat) continue;
                bool same = true;
                for (int c = 1; c < 5; c++) same = same && pi[5 * w + c].face == p->face;
                if (!same) continue;
                win[nw].q[0] = q[10 * w];
                win[nw].q[1] = q[10 * w + 1];
                win[nw].face = p->face;
                nw++;
            }
            free(q);
            free(pi);
        }
        if (nw == 0) {
            fprintf(stderr, "refl: %s: at %.3f deg no window of %dx%d pixels lies on material %s\n", session_dir,
                    r0->measured_deg, o.window, o.window, out->material);
            out->frames_skipped += nf;
            model_tracer_free(tr);
            model_scene_free(rot);
            continue;
        }
        // geometry per window and lamp
        double *qw = malloc((size_t)nw * 2 * sizeof *qw);
        model_pixel_info_t *pw = malloc((size_t)nw * sizeof *pw);
        model_lamp_sample_t *ls = malloc((size_t)nw * cal->lamps->n * sizeof *ls);
        free(taken);
        taken = calloc((size_t)nw * cal->lamps->n, 1);
        if (!qw || !pw || !ls || !taken) {
            free(qw);
            free(pw);
            free(ls);
            model_tracer_free(tr);
            model_scene_free(rot);
            free(done_row);
            goto oom;
        }
        for (int w = 0; w < nw; w++) {
            qw[2 * w] = win[w].q[0];
            qw[2 * w + 1] = win[w].q[1];
        }
        model_pixel_info(tr, cal->cam, cal->lamps, qw, nw, pw, ls, 0);
        // dark frames of this angle by exposure (when there is no offset map)
        bool fail = false;
        for (int a = 0; a < nf && !fail; a++) {
            const rig_frame_row_t *r = &s->rows[order[a]];
            if (!strcmp(r->lamps, "none")) continue;
            int lamp = model_lamps_find(cal->lamps, r->lamps);
            if (lamp < 0) {
                out->frames_skipped++;   // several lamps at once, or a lamp the calibration lacks
                continue;
            }
            float *dark = NULL;
            if (!cal->offset_dn) {
                // the session's dark frame at the same gain nearest in exposure, then
                // in steps (the dark current is a small part of the dark level: an
                // auto bracket of lamps off stops at its longest exposure)
                int best = -1;
                for (int f = 0; f < s->n; f++) {
                    const rig_frame_row_t *q = &s->rows[f];
                    if (strcmp(q->lamps, "none") || q->gain != r->gain) continue;
                    double de = fabs(q->exposure_us - r->exposure_us);
                    double db = best < 0 ? 0 : fabs(s->rows[best].exposure_us - r->exposure_us);
                    if (best < 0 || de < db || (de == db && abs(q->step - r->step) < abs(s->rows[best].step - r->step)))
                        best = f;
                }
                if (best < 0) {
                    model_error(session_dir, 0, "step %d (%s, %g us): no dark level: the calibration has no offset "
                                "map and the session no dark frame (add the lamp set none or dark_every to the plan, "
                                "or a gain calibration)", r->step, r->lamps, r->exposure_us);
                    fail = true;
                    break;
                }
                int dw, dh;
                if (!(dark = rig_session_frame(s, best, &dw, &dh))) {
                    fail = true;
                    break;
                }
            }
            int fw, fh;
            float *img = rig_session_frame(s, order[a], &fw, &fh);
            if (!img || fw != cal->W || fh != cal->H) {
                if (img) model_error(session_dir, 0, "step %d: %dx%d frame, the camera model is %dx%d", r->step, fw,
                                     fh, cal->W, cal->H);
                free(img);
                free(dark);
                fail = true;
                break;
            }
            double sat = 0.95 * (cal->saturation_dn > 0 ? cal->saturation_dn : bits_full(r->pixel_format));
            double gf = pow(10.0, r->gain / 20);
            // the gain calibration's response compression S_m = S (1 - a S) at this gain
            // (a is per DN at 0 dB; the signal in DN scales with the gain)
            double a_nl = cal->nonlin_a_per_dn > 0 ? cal->nonlin_a_per_dn / gf : 0;
            for (int w = 0; w < nw; w++) {
                if (taken[(size_t)w * cal->lamps->n + lamp]) continue;
                const model_lamp_sample_t *L = &ls[(size_t)w * cal->lamps->n + lamp];
                if (!(L->V > 0.999)) continue;
                model_cosines_t c = model_cosines(pw[w].n, L->l, pw[w].v);
                if (!(c.nl > 0 && c.nv > 0)) continue;
                // a finite lamp near the mirror direction (within 20 deg: where a
                // narrow lobe changes over the lamp's disc) gets its disc's cosines
                model_vec3_t dl[4];
                bool has_disc = c.nh > cos(20 * M_PI / 180) &&
                                model_lamp_disc_dirs(L->l, L->d_mm, cal->lamp_radius_mm[lamp], dl);
                int x0 = (int)win[w].q[0] - half, y0 = (int)win[w].q[1] - half;
                double sum = 0, mx = 0, sg = 0;
                for (int y = y0; y < y0 + o.window; y++)
                    for (int x = x0; x < x0 + o.window; x++) {
                        size_t i = (size_t)y * cal->W + x;
                        sum += linear_signal(img[i] - (cal->offset_dn ? cal->offset_dn[i] : dark[i]), a_nl);
                        mx = fmax(mx, img[i]);
                        sg += cal->flat ? cal->flat[i] : 1;
                    }
                double n = (double)o.window * o.window;
                if (mx >= sat) continue;   // a shorter exposure of the bracket takes it
                double sig = sum / n;
                if (sig < o.min_signal_dn) continue;
                calib_obs_t ob = { .lamp = lamp, .angle_deg = r->measured_deg, .exposure_us = r->exposure_us,
                                 .gain_db = r->gain, .q = { win[w].q[0], win[w].q[1] }, .c = c, .d_mm = L->d_mm,
                                 .s_dn_per_us = sig / (sg / n) / (r->exposure_us * gf), .step = r->step,
                                 .face = pw[w].face, .has_disc = has_disc };
                for (int k = 0; has_disc && k < 4; k++) ob.disc[k] = model_cosines(pw[w].n, dl[k], pw[w].v);
                {   // the point at angle 0: turned back about the table's axis (z)
                    double ca = cos(-r->measured_deg * M_PI / 180), sa = sin(-r->measured_deg * M_PI / 180);
                    model_vec3_t pp = pw[w].p_mm;
                    ob.p0_mm[0] = ca * pp.x - sa * pp.y;
                    ob.p0_mm[1] = sa * pp.x + ca * pp.y;
                    ob.p0_mm[2] = pp.z;
                }
                if (cal->gain_dn_per_e > 0) {
                    // per pixel: shot noise K*signal (K scales with the gain), read noise, quantisation
                    double K = cal->gain_dn_per_e * gf, rd = K * cal->read_noise_e;
                    double var = (K * sig + rd * rd + 1.0 / 12) / n;
                    ob.s_std = sqrt(var) / (sg / n) / (r->exposure_us * gf);
                }
                if (!obs_add(out, &ob)) {
                    free(img);
                    free(dark);
                    fail = true;
                    model_error(session_dir, 0, "out of memory");
                    break;
                }
                taken[(size_t)w * cal->lamps->n + lamp] = 1;
            }
            out->frames_used++;
            free(img);
            free(dark);
        }
        free(qw);
        free(pw);
        free(ls);
        model_tracer_free(tr);
        model_scene_free(rot);
        if (fail) {
            free(done_row);
            goto done;
        }
        if (o.verbose)
            fprintf(stderr, "  %s: angle %.2f deg: %d windows, %d observations so far\n", session_dir,
                    r0->measured_deg, nw, out->n);
    }
    free(done_row);
    if (out->n == 0) {
        model_error(session_dir, 0, "no usable observation of material %s (nothing lit, unsaturated and above %g DN "
                    "on it)", out->material, o.min_signal_dn);
        goto done;
    }
    ok = true;
    goto done;
oom:
    model_error(session_dir, 0, "out of memory");
done:
    free(order);
    free(win);
    free(taken);
    g_free(scene_path);
    model_scene_free(scene);
    rig_plan_free(plan);
    rig_session_free(s);
    if (!ok) calib_obs_free(out);
    return ok;
}

bool calib_observe_session(const char *session_dir, const char *calib_dir, bool need_white,
                           const calib_observe_options_t *opt, calib_set_t **cal, calib_obs_set_t *out)
{
    memset(out, 0, sizeof *out);
    if (!(*cal = calib_set_load(calib_dir, need_white))) return false;
    return calib_observe(session_dir, *cal, opt, out);
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
