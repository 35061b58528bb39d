// fit/material.c — observations of a material in a capture session (see
// fit/material.h), the reference white's kc*I per lamp (`refl calib white`)
// and the material fit (`refl fit material`).
#define _GNU_SOURCE
#include <errno.h>
#include <glib.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "calib/calib.h"
#include "fit/material.h"
#include "model/report.h"
#include "model/vec.h"
#include "rig/rig.h"

// ---------------------------------------------------------------------------
// Calibration directory

static char *find_in(const char *dir, const char *sub, const char *name)
{
    char *p = g_strdup_printf("%s/%s", dir, name);
    if (access(p, R_OK) == 0) return p;
    g_free(p);
    p = g_strdup_printf("%s/%s/%s", dir, sub, name);
    if (access(p, R_OK) == 0) return p;
    g_free(p);
    return NULL;
}

static bool add_input(fit_calib_t *c, const char *role, const char *path)
{
    return model_inputs_add(c->inputs, role, path);
}

void fit_calib_free(fit_calib_t *c)
{
    if (!c) return;
    model_camera_free(c->cam);
    model_lamps_free(c->lamps);
    free(c->offset_dn);
    free(c->flat);
    json_decref(c->inputs);
    free(c);
}

static float *read_map(fit_calib_t *c, const char *path, const char *role)
{
    int w, h;
    float *m = model_image_read_float(path, &w, &h);
    if (!m) return NULL;
    if (w != c->W || h != c->H) {
        model_error(path, 0, "%dx%d pixels, the camera model's imager is %dx%d", w, h, c->W, c->H);
        free(m);
        return NULL;
    }
    add_input(c, role, path);
    return m;
}

fit_calib_t *fit_calib_load(const char *dir, bool need_white)
{
    char *cam = find_in(dir, "geometry", "camera.cameramodel"), *lamps = find_in(dir, "lamps", "lamps.json");
    char *gain = find_in(dir, "gain", "gain.json"), *white = find_in(dir, "white", "white.json");
    fit_calib_t *c = NULL;
    if (!cam)
        model_error(dir, 0, "no camera.cameramodel (nor geometry/camera.cameramodel): run refl calib geometry first");
    else if (!lamps)
        model_error(dir, 0, "no lamps.json (nor lamps/lamps.json): run refl calib lamps first");
    else if (!white && need_white)
        model_error(dir, 0, "no white.json (nor white/white.json): run refl calib white on a reference-white session");
    else
        c = fit_calib_load_files(cam, lamps, gain, white);
    g_free(cam);
    g_free(lamps);
    g_free(gain);
    g_free(white);
    return c;
}

// The response compression a (per DN at 0 dB) of S_m = S (1 - a S), S the
// linear signal, from a gain calibration's photon-transfer curves (gain.json:
// gains[] at 0 dB, curves.exposure_us and curves.signal_dn): linear least
// squares of S_m = u t + v - a S_m^2 over the steps below 90 % of saturation
// (S_m^2 stands for S^2: the error is second order in a). 0 when the curves
// are absent or say no compression.
static double nonlinearity_of(json_t *gj, double sat)
{
    json_t *gains = json_object_get(gj, "gains"), *g0 = NULL;
    for (size_t k = 0; k < json_array_size(gains); k++) {
        json_t *e = json_array_get(gains, k);
        if (fabs(json_number_value(json_object_get(e, "gain_db"))) < 1e-9) g0 = e;
    }
    json_t *cv = json_object_get(g0 ? g0 : gj, "curves");
    json_t *t = json_object_get(cv, "exposure_us"), *S = json_object_get(cv, "signal_dn");
    if (json_array_size(t) != json_array_size(S) || json_array_size(t) < 5) return 0;
    double A[9] = { 0 }, b[3] = { 0 }, ts = 0, ss = 0;   // column scales
    for (size_t i = 0; i < json_array_size(t); i++) {
        ts = fmax(ts, fabs(json_number_value(json_array_get(t, i))));
        ss = fmax(ss, fabs(json_number_value(json_array_get(S, i))));
    }
    if (!(ts > 0) || !(ss > 0)) return 0;
    int n = 0;
    for (size_t i = 0; i < json_array_size(t); i++) {
        double ti = json_number_value(json_array_get(t, i)), si = json_number_value(json_array_get(S, i));
        if (!(si > 0) || (sat > 0 && si > 0.9 * sat) || !isfinite(ti)) continue;
        double x[3] = { ti / ts, 1, -si * si / (ss * ss) };
        for (int r = 0; r < 3; r++) {
            for (int c = 0; c < 3; c++) A[3 * r + c] += x[r] * x[c];
            b[r] += x[r] * si;
        }
        n++;
    }
    if (n < 5 || !model_solve_linear(A, b, 3)) return 0;
    double a = b[2] / (ss * ss);
    return isfinite(a) && a > 0 && a < 1e-3 ? a : 0;
}

// The linear signal S of a measured S_m = S (1 - a S) (the root that goes to
// S_m as a -> 0); S_m as it is without a compression or where it has no root.
static double linear_signal(double s_m, double a)
{
    if (!(a > 0) || !(s_m > 0)) return s_m;
    double disc = 1 - 4 * a * s_m;
    return disc > 0 ? 2 * s_m / (1 + sqrt(disc)) : s_m;
}

fit_calib_t *fit_calib_load_files(const char *cam, const char *lamps, const char *gain, const char *white)
{
    fit_calib_t *c = calloc(1, sizeof *c);
    char *off = NULL, *flat = NULL;
    json_t *lj = NULL, *gj = NULL, *wj = NULL;
    json_error_t je;
    bool ok = false;
    const char *dir = cam;
    if (!c) return NULL;
    c->inputs = json_array();
    if (!(c->cam = model_camera_load(cam))) goto fail;
    add_input(c, "camera", cam);
    c->W = model_camera_width(c->cam);
    c->H = model_camera_height(c->cam);
    if (!(lj = json_load_file(lamps, 0, &je))) {
        model_error(lamps, je.line, "not valid JSON: %s", je.text);
        goto fail;
    }
    json_t *arr = json_object_get(lj, "lamps");
    size_t nl = json_array_size(arr);
    if (!nl || nl > 32) {
        model_error(lamps, 0, "'lamps' must list 1 to 32 lamps (has %zu)", nl);
        goto fail;
    }
    c->lamps = calloc(1, sizeof *c->lamps);
    if (!c->lamps || !(c->lamps->lamps = calloc(nl, sizeof *c->lamps->lamps))) goto oom;
    c->lamps->path = strdup(lamps);
    for (size_t i = 0; i < nl; i++) {
        json_t *e = json_array_get(arr, i), *p = json_object_get(e, "position_mm");
        const char *name = json_string_value(json_object_get(e, "name"));
        if (!name || json_array_size(p) != 3 || !json_is_number(json_array_get(p, 0)) ||
            !json_is_number(json_array_get(p, 1)) || !json_is_number(json_array_get(p, 2))) {
            model_error(lamps, 0, "lamps[%zu] needs a name and position_mm = [x, y, z]", i);
            goto fail;
        }
        model_lamp_t *l = &c->lamps->lamps[i];
        snprintf(l->name, sizeof l->name, "%s", name);
        l->position_mm = v3(json_number_value(json_array_get(p, 0)), json_number_value(json_array_get(p, 1)),
                            json_number_value(json_array_get(p, 2)));
        l->intensity = 1;
        // the emitting radius (refl calib lamps writes the one its highlight
        // model used): the fit averages R over the lamp's disc
        json_t *rad = json_object_get(e, "radius_mm");
        if (rad && !(json_is_number(rad) && json_number_value(rad) >= 0 && json_number_value(rad) < 1000)) {
            model_error(lamps, 0, "lamps[%zu] (%s): radius_mm must be a number of mm in [0, 1000)", i, name);
            goto fail;
        }
        c->lamp_radius_mm[i] = rad ? json_number_value(rad) : 0;
        c->lamps->n = (int)i + 1;
    }
    add_input(c, "lamps", lamps);
    if (gain) {
        if (!(gj = json_load_file(gain, 0, &je))) {
            model_error(gain, je.line, "not valid JSON: %s", je.text);
            goto fail;
        }
        add_input(c, "gain", gain);
        json_t *sat = json_object_get(gj, "saturation_dn");
        if (json_is_number(sat)) c->saturation_dn = json_number_value(sat);
        json_t *K = json_object_get(gj, "system_gain_dn_per_e"), *rn = json_object_get(gj, "read_noise_e");
        if (json_is_number(K) && json_is_number(rn)) {
            c->gain_dn_per_e = json_number_value(K);
            c->read_noise_e = json_number_value(rn);
        }
        c->nonlin_a_per_dn = nonlinearity_of(gj, c->saturation_dn);
        char *gd = g_path_get_dirname(gain);
        off = g_strdup_printf("%s/offset_dn.tiff", gd);
        flat = g_strdup_printf("%s/flat_field.tiff", gd);
        if (access(flat, R_OK) != 0) {
            g_free(flat);
            flat = g_strdup_printf("%s/prnu_gain.tiff", gd);
        }
        g_free(gd);
        if (access(off, R_OK) == 0 && !(c->offset_dn = read_map(c, off, "offset map"))) goto fail;
        if (access(flat, R_OK) == 0 && !(c->flat = read_map(c, flat, "flat field"))) goto fail;
    }
    if (white) {
        if (!(wj = json_load_file(white, 0, &je))) {
            model_error(white, je.line, "not valid JSON: %s", je.text);
            goto fail;
        }
        json_t *wl = json_object_get(wj, "lamps");
        for (int i = 0; i < c->lamps->n; i++) {
            bool found = false;
            for (size_t k = 0; k < json_array_size(wl); k++) {
                json_t *e = json_array_get(wl, k);
                const char *n = json_string_value(json_object_get(e, "name"));
                json_t *v = json_object_get(e, "kc_I_per_us");
                if (n && !strcmp(n, c->lamps->lamps[i].name) && json_is_number(v)) {
                    c->kcI_per_us[i] = json_number_value(v);
                    found = true;
                }
            }
            if (!found) {
                model_error(white, 0, "no kc_I_per_us for lamp '%s' (of %s): run refl calib white with that lamp",
                            c->lamps->lamps[i].name, lamps);
                goto fail;
            }
        }
        c->have_white = true;
        add_input(c, "white", white);
    }
    ok = true;
    goto done;
oom:
    model_error(dir, 0, "out of memory");
fail:
done:
    g_free(off);
    g_free(flat);
    json_decref(lj);
    json_decref(gj);
    json_decref(wj);
    if (ok) return c;
    fit_calib_free(c);
    return NULL;
}

// ---------------------------------------------------------------------------
// Observations

fit_observe_options_t fit_observe_defaults(void)
{
    return (fit_observe_options_t){ .window = 5, .step = 8, .min_signal_dn = 20 };
}

void fit_obs_free(fit_obs_set_t *s)
{
    if (!s) return;
    free(s->o);
    memset(s, 0, sizeof *s);
}

static bool obs_add(fit_obs_set_t *s, const fit_obs_t *o)
{
    if (s->n == s->cap) {
        int cap = s->cap ? 2 * s->cap : 4096;
        fit_obs_t *n = realloc(s->o, (size_t)cap * sizeof *n);
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

bool fit_observe(const char *session_dir, const fit_calib_t *cal, const fit_observe_options_t *opt,
                 fit_obs_set_t *out)
{
    fit_observe_options_t o = opt ? *opt : fit_observe_defaults();
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
                                fit_lamp_disc_dirs(L->l, L->d_mm, cal->lamp_radius_mm[lamp], dl);
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
                fit_obs_t ob = { .lamp = lamp, .angle_deg = r->measured_deg, .exposure_us = r->exposure_us,
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
    if (!ok) fit_obs_free(out);
    return ok;
}

// ---------------------------------------------------------------------------
// Reference white

bool fit_white(const fit_obs_set_t *obs, const fit_calib_t *cal, double albedo, const char *out_json,
               json_t *prov)
{
    double kd = albedo / M_PI;
    json_t *top = json_object();
    json_object_set_new(top, "calibration", json_string("reference white: kc*I per lamp"));
    json_object_set_new(top, "units", json_string("kc_I_per_us: DN per microsecond of exposure at 0 dB gain per "
                                                  "(R in 1/sr / d^2 in mm^2), so P - Pa = kc_I_per_us * t_us * "
                                                  "10^(gain_dB/20) * g(x,y) * R / d^2"));
    json_object_set_new(top, "albedo", json_real(albedo));
    json_object_set_new(top, "sample", json_string(obs->sample));
    json_t *arr = json_array();
    double *v = malloc((size_t)obs->n * sizeof *v);
    bool ok = v != NULL;
    for (int l = 0; ok && l < cal->lamps->n; l++) {
        int n = 0;
        for (int i = 0; i < obs->n; i++)
            if (obs->o[i].lamp == l) v[n++] = obs->o[i].s_dn_per_us * obs->o[i].d_mm * obs->o[i].d_mm / (kd * obs->o[i].c.nl);
        if (n < 10) {
            model_error(out_json, 0, "lamp %s: %d observations of the reference white (need 10): capture it with "
                        "that lamp alone", cal->lamps->lamps[l].name, n);
            ok = false;
            break;
        }
        qsort(v, (size_t)n, sizeof *v, model_cmp_double);
        double med = v[n / 2];
        for (int i = 0; i < n; i++) v[i] = fabs(v[i] - med);
        qsort(v, (size_t)n, sizeof *v, model_cmp_double);
        double mad = 1.4826 * v[n / 2];
        json_t *e = json_object();
        json_object_set_new(e, "name", json_string(cal->lamps->lamps[l].name));
        json_object_set_new(e, "kc_I_per_us", json_real(med));
        json_object_set_new(e, "spread_rel", json_real(mad / med));
        json_object_set_new(e, "std_of_median_rel", json_real(1.2533 * mad / med / sqrt(n)));
        json_object_set_new(e, "n_observations", json_integer(n));
        json_array_append_new(arr, e);
        printf("  %-12s kc*I = %.6g DN/us per (1/sr)/mm^2  (spread %.2f %%, %d windows)\n", cal->lamps->lamps[l].name,
               med, 100 * mad / med, n);
    }
    free(v);
    json_object_set_new(top, "lamps", arr);
    if (prov) json_object_set_new(top, "provenance", json_incref(prov));
    if (ok) {
        char *d = g_path_get_dirname(out_json);
        ok = model_mkdir_p(d) && model_write_json(out_json, top);
        g_free(d);
    }
    json_decref(top);
    return ok;
}

// ---------------------------------------------------------------------------
// Commands

typedef struct {
    const char *session, *calib, *out, *scene, *material, *model, *name, *report;
    double      albedo, k_sigma, sys_rel, cell_mm;
    int         window, step;   // 0: fit_observe's defaults
    bool        verbose;
} mat_args_t;

static int parse_args(const char *cmd, int argc, char **argv, mat_args_t *a, void (*usage)(FILE *))
{
    for (int i = 1; i < argc; i++) {
        const char *s = argv[i];
        if (!strcmp(s, "-h") || !strcmp(s, "--help")) {
            usage(stdout);
            return 0;
        }
        if (!strcmp(s, "-v") || !strcmp(s, "--verbose")) {
            a->verbose = true;
            continue;
        }
        if (!strcmp(s, "--window") || !strcmp(s, "--step")) {
            char *e = NULL;
            long v = i + 1 < argc ? strtol(argv[i + 1], &e, 10) : 0;
            if (i + 1 >= argc || *e || v < 1 || v > 64) {
                fprintf(stderr, "refl %s: %s needs a whole number of pixels 1..64%s%s%s\n", cmd, s,
                        i + 1 < argc ? ", not '" : "", i + 1 < argc ? argv[i + 1] : "", i + 1 < argc ? "'" : "");
                return 2;
            }
            *(!strcmp(s, "--window") ? &a->window : &a->step) = (int)v;
            i++;
            continue;
        }
        const char **str = !strcmp(s, "-o") ? &a->out : !strcmp(s, "--calib") ? &a->calib
                         : !strcmp(s, "--scene") ? &a->scene : !strcmp(s, "--material") ? &a->material
                         : !strcmp(s, "--model") ? &a->model : !strcmp(s, "--name") ? &a->name
                         : !strcmp(s, "--report") ? &a->report : NULL;
        double *num = !strcmp(s, "--albedo") ? &a->albedo : !strcmp(s, "--k-sigma") ? &a->k_sigma
                    : !strcmp(s, "--systematic") ? &a->sys_rel : !strcmp(s, "--albedo-cells") ? &a->cell_mm : NULL;
        if (str || num) {
            if (i + 1 >= argc) {
                fprintf(stderr, "refl %s: missing value after %s\n", cmd, s);
                return 2;
            }
            const char *v = argv[++i];
            if (str) {
                *str = v;
            } else {
                char *e;
                *num = strtod(v, &e);
                // the systematic floor may be 0 (as refl fit brdf's), and the cells (off);
                // an albedo or K may not
                bool zero_ok = num == &a->sys_rel || num == &a->cell_mm;
                if (*e || !(zero_ok ? *num >= 0 : *num > 0) || !isfinite(*num)) {
                    fprintf(stderr, "refl %s: %s needs a number %s 0, not '%s'\n", cmd, s, zero_ok ? ">=" : ">", v);
                    return 2;
                }
            }
        } else if (s[0] == '-') {
            fprintf(stderr, "refl %s: unknown option %s (refl %s --help)\n", cmd, s, cmd);
            return 2;
        } else if (!a->session) {
            a->session = s;
        } else {
            fprintf(stderr, "refl %s: more than one session: %s\n", cmd, s);
            return 2;
        }
    }
    if (!a->session || !a->calib || !a->out) {
        fprintf(stderr, "refl %s: give SESSION, --calib DIR and -o FILE (refl %s --help)\n", cmd, cmd);
        return 2;
    }
    return -1;
}

// Both commands: the calibrations of --calib and the observations of the
// session. false with the message printed (cmd names the command).
static bool load_and_observe(const char *cmd, const mat_args_t *a, bool need_white, fit_calib_t **cal,
                             fit_obs_set_t *obs)
{
    memset(obs, 0, sizeof *obs);
    if (!(*cal = fit_calib_load(a->calib, need_white))) {
        fprintf(stderr, "refl %s: %s\n", cmd, model_last_error());
        return false;
    }
    fit_observe_options_t o = fit_observe_defaults();
    o.scene_path = a->scene;
    o.material = a->material;
    o.verbose = a->verbose;
    if (a->window > 0) o.window = a->window;
    if (a->step > 0) o.step = a->step;
    if (!fit_observe(a->session, *cal, &o, obs)) {
        fprintf(stderr, "refl %s: %s\n", cmd, model_last_error());
        return false;
    }
    return true;
}

// Provenance of a command's output: the command, the session and every
// calibration file read.
static json_t *provenance(int argc, char **argv, const mat_args_t *a, const fit_calib_t *cal)
{
    json_t *prov = model_provenance(argc + 1, argv - 1);
    model_provenance_input(prov, "session", a->session);
    size_t i;
    json_t *in;
    json_array_foreach(cal->inputs, i, in) json_array_append(json_object_get(prov, "inputs"), in);
    return prov;
}

static void white_usage(FILE *f)
{
    fprintf(f, "usage: refl calib white SESSION --calib DIR [--albedo A] [--scene FILE] [--material NAME]\n"
               "                        [--window N] [--step N] -o WHITE.json\n"
               "\n"
               "The absolute scale kc*I of each lamp from a session of the reference white (a Lambertian standard\n"
               "of albedo A, default 0.99): every lit window of the standard gives (P - Pa) d^2 / (g t kd n.l),\n"
               "kd = A/pi; the median per lamp is written. DIR holds the geometry (camera.cameramodel), the lamp\n"
               "positions (lamps.json) and optionally the gain calibration (gain.json and its maps). Put WHITE.json\n"
               "in DIR (or DIR/white/) for refl fit material. Windows are N x N pixels (--window, default 5) on a\n"
               "grid of N pixels (--step, default 8), each wholly on one face of the material.\n\nrefl %s\n", REFL_VERSION);
}

int fit_cmd_white(int argc, char **argv)
{
    mat_args_t a = { .albedo = 0.99 };
    int rc = parse_args("calib white", argc, argv, &a, white_usage);
    if (rc >= 0) return rc;
    if (a.albedo > 1) {
        fprintf(stderr, "refl calib white: --albedo %g: an albedo is at most 1\n", a.albedo);
        return 2;
    }
    if (a.cell_mm > 0) {
        fprintf(stderr, "refl calib white: --albedo-cells is an option of refl fit material\n");
        return 2;
    }
    fit_calib_t *cal = NULL;
    fit_obs_set_t obs;
    rc = 1;
    if (!load_and_observe("calib white", &a, false, &cal, &obs)) goto done;
    printf("refl calib white: %d observations of %s in %d frames (%d skipped)\n", obs.n, obs.material,
           obs.frames_used, obs.frames_skipped);
    json_t *prov = provenance(argc, argv, &a, cal);
    if (fit_white(&obs, cal, a.albedo, a.out, prov)) {
        printf("%s\n", a.out);
        rc = 0;
    } else {
        fprintf(stderr, "refl calib white: %s\n", model_last_error());
    }
    json_decref(prov);
done:
    fit_obs_free(&obs);
    fit_calib_free(cal);
    return rc;
}

// The report of a material fit: DIR/samples.csv (every sample with its
// geometry, measured and fitted R), plots by scripts/fit_material_report.py,
// and DIR/report.html with the parameter table and the model comparison.
static bool material_report(const char *dir, const fit_obs_set_t *obs, const fit_samples_t *smp,
                            const fit_brdf_result_t *res, int nres, int best, const json_t *entry, const json_t *prov)
{
    if (!model_mkdir_p(dir)) return false;
    char *csv = g_strdup_printf("%s/samples.csv", dir), *html = g_strdup_printf("%s/report.html", dir);
    bool ok = false;
    FILE *f = fopen(csv, "w");
    if (!f) {
        model_error(csv, 0, "cannot write: %s", strerror(errno));
        goto done;
    }
    fprintf(f, "# refl fit material samples: window centre (px), step, lamp, angles (deg: incidence, view, half "
               "vector from the normal), R measured and fitted by %s (1/sr, R = f_r cos theta_i)\n",
            model_brdf_name(res[best].model));
    fprintf(f, "x_px,y_px,step,lamp,theta_i_deg,theta_o_deg,theta_h_deg,R_meas,R_fit\n");
    const double d = 180 / M_PI;
    for (int i = 0; i < smp->n; i++) {
        const model_cosines_t *c = &smp->c[i];
        fprintf(f, "%.1f,%.1f,%d,%d,%.4f,%.4f,%.4f,%.6g,%.6g\n", obs->o[i].q[0], obs->o[i].q[1], obs->o[i].step,
                obs->o[i].lamp, acos(fmin(1, c->nl)) * d, acos(fmin(1, c->nv)) * d, acos(fmin(1, c->nh)) * d,
                smp->R[i], fit_samples_eval(smp, res[best].model, res[best].p, i));
    }
    if (fclose(f) != 0) {
        model_error(csv, 0, "cannot write: %s", strerror(errno));
        goto done;
    }
    char pbuf[256] = "";
    size_t o = 0;
    for (int j = 0; j < res[best].nparams; j++)
        o += (size_t)snprintf(pbuf + o, sizeof pbuf - o, "%s%.6g", j ? "," : "", res[best].p[j]);
    if (model_run_script("fit_material_report.py", dir, model_brdf_name(res[best].model), pbuf, (char *)NULL) != 0)
        goto done;
    FILE *h = model_html_begin(html, "refl fit material", prov);
    if (!h) goto done;
    model_html_para(h, "Material %s of sample %s: %d BRDF samples (windows of %d frames lit by one lamp each). "
                    "Chosen model: %s (lowest BIC). R = f_r cos(theta_i) in 1/sr.",
                    json_string_value(json_object_get(entry, "name")), obs->sample, smp->n, obs->frames_used,
                    model_brdf_name(res[best].model));
    model_html_heading(h, "Parameters");
    json_t *ps = json_object_get(entry, "parameters");
    char **rows = calloc(json_array_size(ps) + 1, sizeof *rows);
    for (size_t j = 0; j < json_array_size(ps); j++) {
        json_t *p = json_array_get(ps, j);
        rows[j] = g_strdup_printf("%s|%s|%.6g|%.3g|%.3g|%.6g .. %.6g|%s|%s", json_string_value(json_object_get(p, "name")),
                                  json_string_value(json_object_get(p, "unit")),
                                  json_number_value(json_object_get(p, "mean")),
                                  json_number_value(json_object_get(p, "std")),
                                  json_number_value(json_object_get(p, "std_statistical")),
                                  json_number_value(json_object_get(p, "lo")),
                                  json_number_value(json_object_get(p, "hi")),
                                  json_string_value(json_object_get(p, "convention")),
                                  json_object_get(p, "held") ? json_string_value(json_object_get(p, "held")) : "");
    }
    model_html_table(h, "parameter|unit|mean|std|std (statistical)|prior bounds|convention|note",
                     (const char *const *)rows, (int)json_array_size(ps));
    for (size_t j = 0; j < json_array_size(ps); j++) g_free(rows[j]);
    free(rows);
    model_html_heading(h, "Measured vs fitted");
    model_html_figure(h, "lobes.png", "R against the half-vector angle, measured (dots, coloured by incidence) "
                      "and fitted (the model at the same geometry), per lamp");
    model_html_figure(h, "residual_maps.png", "residual R_meas - R_fit at each window, for four frames");
    model_html_heading(h, "Model comparison");
    char **mr = calloc((size_t)nres + 1, sizeof *mr);
    for (int k = 0; k < nres; k++) {
        GString *g = g_string_new("");
        g_string_append_printf(g, "%s%s|%.4g|%.4g|%.8g|%.8g|", model_brdf_name(res[k].model), k == best ? " (chosen)" : "",
                               res[k].rms, res[k].rms_fr, res[k].aic, res[k].bic);
        for (int j = 0; j < res[k].nparams; j++)
            g_string_append_printf(g, "%s%s %.4g", j ? ", " : "", model_brdf_param_name(res[k].model, j), res[k].p[j]);
        mr[k] = g_string_free(g, FALSE);
    }
    model_html_table(h, "model|RMS of R (1/sr)|RMS of f_r (1/sr)|AIC|BIC|parameters", (const char *const *)mr, nres);
    for (int k = 0; k < nres; k++) g_free(mr[k]);
    free(mr);
    model_html_figure(h, "models.png", "residuals of the chosen model: histogram, and relative to R against the half-vector angle");
    ok = model_html_end(h, html);
done:
    g_free(csv);
    g_free(html);
    return ok;
}

// ---------------------------------------------------------------------------
// Albedo cells (--albedo-cells MM): a textured material (wood, a painted
// surface) varies its albedo from place to place, which one set of BRDF
// parameters cannot follow. The sample's surface is cut into cells of MM mm
// (by the observations' points at angle 0, which turn with the table, and
// their faces); each cell with at least CELL_MIN_OBS observations gets a
// factor c_j on its whole reflectance (the virtual rig's texture multiplies
// it so), and the fit becomes R_k = c_j(k) R(theta; geometry_k):
//   1. theta from the samples as they are (the model with the lowest BIC);
//   2. c_j = sum R_k f_k / sum f_k^2 over the cell (f = the model's R),
//      then the factors scaled to mean 1 over the observations (so kd & co
//      are the sample's mean);
//   3. theta again from R_k / c_j with weights c_j^2 (the same residuals
//      R_k - c_j f_k); repeat 2-3 until no factor moves by 1e-4 (at most 20).
// Every model is then fitted to the corrected samples. The residual's
// degrees of freedom lose one per cell (rms_over_noise uses N - k - cells).
enum { CELL_MIN_OBS = 4 };

typedef struct {
    int     n_cells, n_obs_in, iterations;
    int    *cell;       // per observation: its cell, -1 when its cell has too few
    double *factor;     // per cell
    double  rel_std;    // std of the factors over the observations (their mean is 1)
} albedo_cells_t;

static void cells_free(albedo_cells_t *ac)
{
    free(ac->cell);
    free(ac->factor);
    memset(ac, 0, sizeof *ac);
}

static bool cells_assign(const fit_obs_set_t *obs, double cell_mm, albedo_cells_t *ac)
{
    memset(ac, 0, sizeof *ac);
    GHashTable *h = g_hash_table_new_full(g_str_hash, g_str_equal, g_free, NULL);
    int *raw = malloc((size_t)(obs->n ? obs->n : 1) * sizeof *raw), nraw = 0;
    ac->cell = malloc((size_t)(obs->n ? obs->n : 1) * sizeof *ac->cell);
    if (!h || !raw || !ac->cell) goto oom;
    for (int i = 0; i < obs->n; i++) {
        const fit_obs_t *o = &obs->o[i];
        char key[96];
        snprintf(key, sizeof key, "%d:%.0f:%.0f:%.0f", o->face, floor(o->p0_mm[0] / cell_mm),
                 floor(o->p0_mm[1] / cell_mm), floor(o->p0_mm[2] / cell_mm));
        gpointer v;
        if (g_hash_table_lookup_extended(h, key, NULL, &v)) {
            raw[i] = GPOINTER_TO_INT(v);
        } else {
            raw[i] = nraw;
            g_hash_table_insert(h, g_strdup(key), GINT_TO_POINTER(nraw));
            nraw++;
        }
    }
    int *count = calloc((size_t)(nraw ? nraw : 1), sizeof *count), *index = malloc((size_t)(nraw ? nraw : 1) * sizeof *index);
    if (!count || !index) {
        free(count);
        free(index);
        goto oom;
    }
    for (int i = 0; i < obs->n; i++) count[raw[i]]++;
    for (int j = 0; j < nraw; j++) index[j] = count[j] >= CELL_MIN_OBS ? ac->n_cells++ : -1;
    for (int i = 0; i < obs->n; i++) {
        ac->cell[i] = index[raw[i]];
        ac->n_obs_in += ac->cell[i] >= 0;
    }
    free(count);
    free(index);
    ac->factor = malloc((size_t)(ac->n_cells ? ac->n_cells : 1) * sizeof *ac->factor);
    if (!ac->factor) goto oom;
    for (int j = 0; j < ac->n_cells; j++) ac->factor[j] = 1;
    free(raw);
    g_hash_table_destroy(h);
    return true;
oom:
    free(raw);
    if (h) g_hash_table_destroy(h);
    cells_free(ac);
    model_error(NULL, 0, "out of memory for the albedo cells");
    return false;
}

// The samples corrected by the cells' factors: R_k / c, weight c^2.
static fit_samples_t *cells_samples(const fit_samples_t *smp, const albedo_cells_t *ac)
{
    fit_samples_t *out = fit_samples_new();
    if (!out) return NULL;
    snprintf(out->source, sizeof out->source, "%s", smp->source);
    for (int i = 0; i < smp->n; i++) {
        double c = ac->cell[i] >= 0 ? ac->factor[ac->cell[i]] : 1;
        const model_cosines_t *disc = smp->disc_at && smp->disc_at[i] >= 0 ? smp->disc + smp->disc_at[i] : NULL;
        if (!fit_samples_add_disc(out, &smp->c[i], disc, smp->R[i] / c, c * c)) {
            fit_samples_free(out);
            model_error(NULL, 0, "sample %d: albedo factor %g gives no usable sample", i, c);
            return NULL;
        }
    }
    return out;
}

// Steps 2-3 above from the fit *r (its model and parameters); *r is updated.
static bool cells_fit(const fit_samples_t *smp, albedo_cells_t *ac, fit_brdf_result_t *r)
{
    double *num = calloc((size_t)(ac->n_cells ? ac->n_cells : 1), sizeof *num);
    double *den = calloc((size_t)(ac->n_cells ? ac->n_cells : 1), sizeof *den);
    bool ok = num && den;
    ac->iterations = 0;
    for (int it = 0; ok && it < 20; it++) {
        ac->iterations = it + 1;   // rounds done (reported)
        memset(num, 0, (size_t)ac->n_cells * sizeof *num);
        memset(den, 0, (size_t)ac->n_cells * sizeof *den);
        for (int i = 0; i < smp->n; i++) {
            int j = ac->cell[i];
            if (j < 0) continue;
            double f = fit_samples_eval(smp, r->model, r->p, i);
            num[j] += smp->R[i] * f;
            den[j] += f * f;
        }
        double sum = 0, moved = 0;
        int n = 0;
        for (int i = 0; i < smp->n; i++) {
            int j = ac->cell[i];
            if (j >= 0 && den[j] > 0) {
                sum += num[j] / den[j];
                n++;
            }
        }
        double mean = n ? sum / n : 1;
        for (int j = 0; j < ac->n_cells; j++) {
            double c = den[j] > 0 && mean > 0 ? num[j] / den[j] / mean : 1;
            if (!(c > 0) || !isfinite(c)) c = 1;
            moved = fmax(moved, fabs(c - ac->factor[j]));
            ac->factor[j] = c;
        }
        fit_samples_t *cs = cells_samples(smp, ac);
        fit_brdf_result_t nr;
        double start[MODEL_BRDF_MAX_PARAMS];
        memcpy(start, r->p, sizeof start);
        ok = cs && fit_brdf_from(cs, r->model, NULL, start, &nr);
        fit_samples_free(cs);
        if (!ok) break;
        // alternating least squares: the residual only falls; stop when it
        // no longer does (or nothing moves)
        double before = r->rss;
        *r = nr;
        if (moved < 1e-4 || (it > 0 && before - nr.rss <= 1e-6 * before)) break;
    }
    if (ok) {
        double s1 = 0, s2 = 0;
        for (int i = 0; i < smp->n; i++)
            if (ac->cell[i] >= 0) {
                double c = ac->factor[ac->cell[i]];
                s1 += c;
                s2 += c * c;
            }
        int n = ac->n_obs_in;
        ac->rel_std = n > 1 ? sqrt(fmax(0.0, (s2 - s1 * s1 / n) / (n - 1))) : 0;
    }
    free(num);
    free(den);
    return ok;
}

// Fit every model of models[] to smp into res (printing a line each); the
// index of the lowest BIC, -1 when none could be fitted.
static int fit_models(const fit_samples_t *smp, const int *models, int nm, fit_brdf_result_t *res, int *nres)
{
    int best = -1;
    *nres = 0;
    for (int k = 0; k < nm; k++) {
        fit_brdf_result_t *r = &res[*nres];
        if (!fit_brdf(smp, (model_brdf_t)models[k], NULL, r)) {
            fprintf(stderr, "  %s: %s\n", model_brdf_name((model_brdf_t)models[k]), model_last_error());
            continue;
        }
        printf("  %-16s rms %.4g 1/sr  BIC %.6g", model_brdf_name(r->model), r->rms, r->bic);
        for (int j = 0; j < r->nparams; j++) printf("  %s %.4g", model_brdf_param_name(r->model, j), r->p[j]);
        printf("\n");
        if (best < 0 || r->bic < res[best].bic) best = *nres;
        (*nres)++;
    }
    return best;
}

static void material_usage(FILE *f)
{
    fprintf(f, "usage: refl fit material SESSION --calib DIR [--model all|lambert|hall|torrance_sparrow|thesis_fit|\n"
               "                         cook_torrance|ggx] [--name NAME] [--scene FILE] [--material NAME]\n"
               "                         [--k-sigma K] [--systematic REL] [--albedo-cells MM] [--window N]\n"
               "                         [--step N] [--report DIR] -o PRIORS.json\n"
               "\n"
               "BRDF samples of the session's sample material: every window of the material lit by one lamp, dark\n"
               "and flat corrected, brackets merged to high dynamic range, scaled by the reference white's kc*I of\n"
               "its lamp (DIR/white.json) with the geometry (DIR/camera.cameramodel) and lamp positions\n"
               "(DIR/lamps.json); then every requested model is fitted (refl fit brdf) and the priors file written.\n"
               "On a virtual rig the sample's scene and material come from the truth file's [sample]; elsewhere\n"
               "give --scene and --material. Each parameter's std adds REL * mean (default 0.03) to the statistical\n"
               "one, for the calibrations' shared errors (on the virtual rig kc*I comes out within ~3 %% and the lamp\n"
               "positions within ~8 mm); the prior bounds are mean +- K std (default 3). --report DIR writes an HTML\n"
               "report there: measured vs fitted lobes, residual maps, the parameters and the model comparison.\n"
               "--albedo-cells MM (textured materials: wood, paint): the sample's surface is cut into cells of MM mm,\n"
               "each with its own albedo factor on the whole reflectance (mean 1 over the observations), fitted\n"
               "together with the parameters; the priors then hold the mean material and the factors' spread.\n"
               "Observations are windows of N x N pixels (--window, default 5) on a grid of N pixels (--step, 8).\n"
               "\nrefl %s\n", REFL_VERSION);
}

int fit_cmd_material(int argc, char **argv)
{
    mat_args_t a = { .k_sigma = 3, .model = "all", .sys_rel = 0.03 };
    int rc = parse_args("fit material", argc, argv, &a, material_usage);
    if (rc >= 0) return rc;
    int models[MODEL_BRDF_COUNT], nm = 0;
    if (!strcmp(a.model, "all")) {
        for (int m = 0; m < MODEL_BRDF_COUNT; m++) models[nm++] = m;
    } else if ((models[0] = model_brdf_from_name(a.model)) >= 0) {
        nm = 1;
    } else {
        fprintf(stderr, "refl fit material: --model: unknown model %s\n", a.model);
        return 2;
    }
    fit_calib_t *cal = NULL;
    fit_obs_set_t obs;
    fit_samples_t *smp = NULL, *csmp = NULL;
    albedo_cells_t ac = { 0 };
    rc = 1;
    if (!load_and_observe("fit material", &a, true, &cal, &obs)) goto done;
    smp = fit_samples_new();
    snprintf(smp->source, sizeof smp->source, "%s", a.session);
    for (int i = 0; i < obs.n; i++) {
        const fit_obs_t *b = &obs.o[i];
        if (!fit_samples_add_disc(smp, &b->c, b->has_disc ? b->disc : NULL,
                                  b->s_dn_per_us * b->d_mm * b->d_mm / cal->kcI_per_us[b->lamp], 1)) {
            fprintf(stderr, "refl fit material: observation %d (step %d) gives no usable sample (kc*I of lamp %s "
                    "is %g)\n", i, b->step, cal->lamps->lamps[b->lamp].name, cal->kcI_per_us[b->lamp]);
            goto done;
        }
    }
    printf("refl fit material: %s: %d BRDF samples from %d frames (%d skipped)\n", obs.material, smp->n,
           obs.frames_used, obs.frames_skipped);
    // the residual RMS the sensor's temporal noise alone would give (with a gain calibration)
    double noise_rms = NAN;
    if (cal->gain_dn_per_e > 0) {
        double v2 = 0;
        for (int i = 0; i < obs.n; i++) {
            double sr = obs.o[i].s_std * obs.o[i].d_mm * obs.o[i].d_mm / cal->kcI_per_us[obs.o[i].lamp];
            v2 += sr * sr;
        }
        noise_rms = sqrt(v2 / obs.n);
        printf("  expected residual RMS from the sensor's noise alone: %.4g 1/sr\n", noise_rms);
        printf("  response compression corrected: S_m = S (1 - a S), a = %.4g per DN at 0 dB%s\n", cal->nonlin_a_per_dn,
               cal->nonlin_a_per_dn > 0 ? "" : " (none in the gain calibration)");
    }
    fit_brdf_result_t res[MODEL_BRDF_COUNT];
    int nres = 0, best = fit_models(smp, models, nm, res, &nres);
    if (best < 0) {
        fprintf(stderr, "refl fit material: no model could be fitted\n");
        goto done;
    }
    if (a.cell_mm > 0) {
        fit_brdf_result_t r = res[best];
        if (!cells_assign(&obs, a.cell_mm, &ac) || !cells_fit(smp, &ac, &r) || !(csmp = cells_samples(smp, &ac))) {
            fprintf(stderr, "refl fit material: albedo cells: %s\n", model_last_error());
            goto done;
        }
        printf("  albedo cells of %g mm: %d cells hold %d of %d observations; factors' std %.4f (%d iterations "
               "with %s); every model again:\n", a.cell_mm, ac.n_cells, ac.n_obs_in, obs.n, ac.rel_std,
               ac.iterations, model_brdf_name(r.model));
        if ((best = fit_models(csmp, models, nm, res, &nres)) < 0) {
            fprintf(stderr, "refl fit material: no model could be fitted to the samples with albedo cells\n");
            goto done;
        }
    }
    json_t *top = json_object();
    json_object_set_new(top, "format", json_string("refl priors 1"));
    json_object_set_new(top, "units", json_string("R = f_r cos(theta_i) in 1/sr; parameter units per parameter"));
    json_t *mats = json_array();
    json_t *e = fit_priors_material(a.name ? a.name : obs.material, &res[best], res, nres, a.k_sigma, a.sys_rel);
    json_object_set_new(e, "session", json_string(a.session));
    json_object_set_new(e, "sample", json_string(obs.sample));
    json_object_set_new(e, "noise_rms_expected", isfinite(noise_rms) ? json_real(noise_rms) : json_null());
    // the residual per degree of freedom (the cells' factors take one each)
    double dof = (double)res[best].n - res[best].nfree - ac.n_cells;
    double rms_dof = dof > 0 ? sqrt(res[best].rss / dof) : NAN;
    if (isfinite(noise_rms) && noise_rms > 0 && isfinite(rms_dof)) {
        json_object_set_new(e, "rms_over_noise", json_real(rms_dof / noise_rms));
        printf("  residual per degree of freedom over the noise: %.3f\n", rms_dof / noise_rms);
    }
    if (a.cell_mm > 0) {
        json_t *jc = json_object();
        json_object_set_new(jc, "cell_mm", json_real(a.cell_mm));
        json_object_set_new(jc, "cells", json_integer(ac.n_cells));
        json_object_set_new(jc, "observations_in_cells", json_integer(ac.n_obs_in));
        json_object_set_new(jc, "observations", json_integer(obs.n));
        json_object_set_new(jc, "factor_rel_std", json_real(ac.rel_std));
        json_object_set_new(jc, "iterations", json_integer(ac.iterations));
        json_object_set_new(jc, "convention", json_string(
            "each cell (MM mm of the sample's surface at angle 0, per face) scales the whole reflectance by its "
            "factor; the factors' mean over the observations is 1, so the parameters describe the mean material; "
            "factor_rel_std is the spread of the albedo from place to place"));
        json_object_set_new(e, "albedo_cells", jc);
    }
    json_array_append_new(mats, e);
    json_object_set_new(top, "materials", mats);
    json_object_set_new(top, "provenance", provenance(argc, argv, &a, cal));
    char *od = g_path_get_dirname(a.out);
    bool made = model_mkdir_p(od);
    g_free(od);
    if (made && model_write_json(a.out, top)) {
        printf("%s: %s, model %s (lowest BIC of %d)\n", a.out, a.name ? a.name : obs.material,
               model_brdf_name(res[best].model), nres);
        rc = 0;
        if (a.report) {
            if (material_report(a.report, &obs, csmp ? csmp : smp, res, nres, best, e,
                                json_object_get(top, "provenance"))) {
                printf("%s/report.html\n", a.report);
            } else {
                fprintf(stderr, "refl fit material: the report: %s\n", model_last_error());
                rc = 1;
            }
        }
    } else {
        fprintf(stderr, "refl fit material: %s\n", model_last_error());
    }
    json_decref(top);
done:
    fit_samples_free(smp);
    fit_samples_free(csmp);
    cells_free(&ac);
    fit_obs_free(&obs);
    fit_calib_free(cal);
    return rc;
}
