// fit/lightplan/lightplan.c — model-based light placement (see lightplan.h).
#define _GNU_SOURCE
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fit/lightplan/lightplan.h"
#include "fit/verify/verify.h"
#include "model/base/vec.h"

#define MAXL MAXL_PLAN

static bool no_memory(void)
{
    model_error(NULL, 0, "light planning: out of memory");
    return false;
}

lightplan_options_t lightplan_defaults(void)
{
    return (lightplan_options_t){
        .glare_cone_deg = 15, .sobel_threshold = 250,              // glare cone, Sobel detector
        .floor_snr = 10, .floor_dn = 20, .saturation_frac = 0.95,   // the usable range
        .max_bad_frac = 0.001, .max_lamps = 0,
        .spacing_px = 8, .ir_samples = 64, .psf_sigma_px = 0,
    };
}

void lightplan_result_free(lightplan_result_t *r)
{
    if (!r) return;
    free(r->configs);
    free(r->segments);
    free(r->faces);
    free(r->predicted);
    free(r->L);
    free(r->face_id);
    free(r->glare);
    free(r->seg_first);
    free(r->Sside);
    memset(r, 0, sizeof *r);
}

// The Sobel response per unit contrast of a segment from q0 to q1: its step
// blurred by the PSF and the pixel's footprint, at the best phase.
static double sobel_factor(const double q0[2], const double q1[2], double psf_sigma_px)
{
    double normal = atan2(q1[1] - q0[1], q1[0] - q0[0]) + M_PI / 2;
    return model_edge_sobel_step(normal, psf_sigma_px).best;
}

bool lightplan_segments_for(const lightplan_result_t *r, uint32_t mask, double exposure_us,
                            const lightplan_options_t *opt, lightplan_segment_t *segs)
{
    double *v = malloc((size_t)(r->npoints ? r->npoints : 1) * sizeof *v);
    if (!v) return no_memory();
    for (int s = 0; s < r->nsegments; s++) {
        lightplan_segment_t *g = &segs[s];
        *g = r->segments[s];
        int a = r->seg_first[s], n = r->seg_first[s + 1] - a;
        double f = g->sobel_factor, sum = 0;
        for (int k = 0; k < n; k++) {
            double d = 0;
            for (int i = 0; i < r->nlamps; i++)
                if ((mask >> i) & 1)
                    d += r->Sside[((size_t)i * r->npoints + a + k) * 2] - r->Sside[((size_t)i * r->npoints + a + k) * 2 + 1];
            v[k] = f * fabs(exposure_us * d);
            sum += exposure_us * d;
        }
        g->dP = n ? sum / n : 0;
        g->gradient = n ? model_median(v, n) : 0;
        g->detectable = g->gradient >= opt->sobel_threshold;
    }
    free(v);
    return true;
}

// The smallest signal with the wanted SNR: S^2 = snr^2 (K S + K^2 rn^2).
static double signal_floor(const lightplan_sensor_t *s, const lightplan_options_t *o)
{
    double K = s->K_dn_per_e, rn = s->read_noise_e, q = o->floor_snr * o->floor_snr;
    double S = K > 0 ? 0.5 * (q * K + sqrt(q * q * K * K + 4 * q * K * K * rn * rn)) : 0;
    return fmax(S, o->floor_dn);
}

// One run of the planner: its inputs, the shared tracer and shading, and the
// step-2 grid of dynamic range and glare (pixel info pi, lamp samples ls,
// glare bits per grid point).
typedef struct {
    const model_scene_t             *scene;
    model_camera_t                  *cam;
    const model_lamps_t             *cands;
    const double                    *A;         // kc*I per us per candidate
    const model_material_t *const   *mats;
    const lightplan_sensor_t        *sensor;
    const double                    *exposures;
    int                              nexp;
    const lightplan_options_t       *opt;
    lightplan_result_t              *out;
    int                              threads, W, H, nl;
    size_t                           npx;
    model_tracer_t                  *t;
    model_shading_t                  sh;
    int                              gw, gh;    // the grid
    size_t                           ng;
    model_pixel_info_t              *pi;        // ng
    model_lamp_sample_t             *ls;        // ng x nl
    uint32_t                        *glare;     // ng: bit i where candidate i glares
    double                           sat, floor_s;   // the usable range of the signal
} plan_t;

// Candidate i alone with intensity A[i] (DN per us of exposure); point: as
// a point lamp (radius 0).
static void single_lamp(const plan_t *P, int i, bool point, model_lamp_t *one, model_lamps_t *single)
{
    *one = P->cands->lamps[i];
    one->intensity = P->A[i];
    if (point) one->radius_mm = 0;
    *single = (model_lamps_t){ .n = 1, .lamps = one, .path = P->cands->path };
}

// Each candidate's direct light per us (out->L, with g) and the face of each pixel.
static bool plan_render_lamps(plan_t *P)
{
    lightplan_result_t *out = P->out;
    for (int i = 0; i < P->nl; i++) {
        model_lamp_t one;
        model_lamps_t single;
        single_lamp(P, i, true, &one, &single);
        if (!model_render(P->t, P->cam, &single, P->mats, &P->sh, out->L + (size_t)i * P->npx,
                          i ? NULL : out->face_id, NULL))
            return false;
    }
    return true;
}

// The visible edge segments (the edge query) into out->segments, and the
// points every 2 px along each (2 px kept from its ends; one point for
// segments under 8 px) into out->seg_first, out->npoints.
static bool plan_segments(plan_t *P)
{
    lightplan_result_t *out = P->out;
    model_edges_t *E0 = model_edges_predict(P->scene, P->t, P->cam, P->cands, P->mats, &P->sh, 1.0);
    if (!E0) return false;
    int ns = 0;
    for (int e = 0; e < E0->nedges; e++) ns += E0->edges[e].nsegments;
    out->nsegments = ns;
    out->segments = calloc((size_t)(ns ? ns : 1), sizeof *out->segments);
    out->seg_first = calloc((size_t)ns + 1, sizeof *out->seg_first);
    if (!out->segments || !out->seg_first) {
        model_edges_free(E0);
        return no_memory();
    }
    int np = 0, k = 0;
    for (int e = 0; e < E0->nedges; e++)
        for (int s2 = 0; s2 < E0->edges[e].nsegments; s2++, k++) {
            const model_edge_segment_t *sg = &E0->edges[e].segments[s2];
            lightplan_segment_t *g = &out->segments[k];
            g->edge = e;
            g->segment = s2;
            memcpy(g->q0, sg->q0, sizeof g->q0);
            memcpy(g->q1, sg->q1, sizeof g->q1);
            g->length_px = sg->length_px;
            g->sobel_factor = sobel_factor(sg->q0, sg->q1, P->opt->psf_sigma_px);
            g->face_side[0] = sg->face_side[0];
            g->face_side[1] = sg->face_side[1];
            double L = hypot(sg->q1[0] - sg->q0[0], sg->q1[1] - sg->q0[1]);
            out->seg_first[k] = np;
            np += L >= 8 ? (int)((L - 4) / 2) + 1 : 1;
        }
    out->seg_first[ns] = np;
    out->npoints = np;
    model_edges_free(E0);
    return true;
}

// The two sides (2 px off) of every point along the segments: qs (npoints x 4).
static void side_points(const lightplan_result_t *out, double *qs)
{
    for (int k = 0; k < out->nsegments; k++) {
        const lightplan_segment_t *g = &out->segments[k];
        double dx = g->q1[0] - g->q0[0], dy = g->q1[1] - g->q0[1], L = hypot(dx, dy);
        double ux = L > 0 ? dx / L : 1, uy = L > 0 ? dy / L : 0, nx = -uy, ny = ux;
        int a0 = out->seg_first[k], n = out->seg_first[k + 1] - a0;
        for (int j = 0; j < n; j++) {
            double tt = n == 1 ? L / 2 : 2 + 2.0 * j;
            double x = g->q0[0] + ux * tt, y = g->q0[1] + uy * tt;
            size_t o = (size_t)(a0 + j) * 4;
            qs[o] = x + 2 * nx;
            qs[o + 1] = y + 2 * ny;
            qs[o + 2] = x - 2 * nx;
            qs[o + 3] = y - 2 * ny;
        }
    }
}

// Each lamp's signal per us on both sides of every point (out->Sside): direct
// light plus one diffuse bounce (what lights a shadowed concave corner).
static bool plan_side_signals(plan_t *P)
{
    lightplan_result_t *out = P->out;
    const int np = out->npoints, nl = P->nl, W = P->W, H = P->H;
    const size_t n1 = (size_t)(np ? np : 1);
    double *qs = malloc(n1 * 4 * sizeof *qs);
    model_pixel_info_t *ps = malloc(n1 * 2 * sizeof *ps);
    model_lamp_sample_t *lss = malloc(n1 * 2 * nl * sizeof *lss);
    out->Sside = calloc((size_t)nl * n1 * 2, sizeof *out->Sside);
    bool ok = qs && ps && lss && out->Sside;
    if (ok) side_points(out, qs);
    else no_memory();
    ok = ok && model_pixel_info(P->t, P->cam, P->cands, qs, 2 * np, ps, lss, P->threads);
    float *Bs = ok && P->opt->ir_samples > 0 ? malloc(n1 * 2 * nl * sizeof *Bs) : NULL;
    if (ok && P->opt->ir_samples > 0 && !Bs) ok = no_memory();
    if (Bs) verify_interreflection(P->t, P->cands, P->mats, ps, 2 * np, P->opt->ir_samples, P->threads, Bs);
    for (int j = 0; j < 2 * np && ok; j++) {
        const model_pixel_info_t *p = &ps[j];
        if (p->face < 0 || p->material < 0) continue;
        double gg = 1;
        if (P->sensor->flat) {
            long x = lround(p->q[0]), y = lround(p->q[1]);
            if (x >= 0 && y >= 0 && x < W && y < H) gg = P->sensor->flat[y * (long)W + x];
        }
        for (int i = 0; i < nl; i++) {
            model_lamp_t one;
            model_lamps_t single;
            single_lamp(P, i, false, &one, &single);
            out->Sside[((size_t)i * np + j / 2) * 2 + j % 2] =
                gg * (model_direct_sum(p, &lss[(size_t)j * nl + i], &single, P->mats[p->material], NULL) +
                      (Bs ? P->A[i] * Bs[(size_t)j * nl + i] : 0));
        }
    }
    free(Bs);
    free(qs);
    free(ps);
    free(lss);
    return ok;
}

// Glare on the grid: a lit lamp within the cone around the mirror direction
// of a non-Lambertian face (P->glare); the grid's pixel info (P->pi, P->ls).
static bool plan_glare(plan_t *P)
{
    double *q = malloc(P->ng * 2 * sizeof *q);
    if (!q) return no_memory();
    for (int j = 0; j < P->gh; j++)
        for (int i = 0; i < P->gw; i++) {
            q[2 * ((size_t)j * P->gw + i)] = 2 * i;
            q[2 * ((size_t)j * P->gw + i) + 1] = 2 * j;
        }
    bool ok = model_pixel_info(P->t, P->cam, P->cands, q, (int)P->ng, P->pi, P->ls, P->threads);
    free(q);
    if (!ok) return false;
    double cosg = cos(P->opt->glare_cone_deg * M_PI / 180);
    for (size_t g = 0; g < P->ng; g++) {
        const model_pixel_info_t *p = &P->pi[g];
        if (p->face < 0 || p->material < 0 || P->mats[p->material]->model == MODEL_BRDF_LAMBERT) continue;
        double nv = v3_dot(p->n, p->v);
        model_vec3_t r = v3_sub(v3_scale(p->n, 2 * nv), p->v);
        for (int i = 0; i < P->nl; i++) {
            const model_lamp_sample_t *s = &P->ls[g * P->nl + i];
            if (s->V > 0.5 && v3_dot(r, s->l) >= cosg) P->glare[g] |= 1u << i;
        }
    }
    return true;
}

// Configuration cf (its mask and exposure set): the grid's object, saturated,
// glare and usable pixels, the detectable segments (tmp: scratch of
// nsegments), feasibility. false + message (out of memory).
static bool plan_config(const plan_t *P, lightplan_config_t *cf, lightplan_segment_t *tmp)
{
    const lightplan_result_t *out = P->out;
    const uint32_t m = cf->mask;
    long usable = 0;
    for (size_t g = 0; g < P->ng; g++) {
        if (P->pi[g].face < 0) continue;
        size_t px = (size_t)(2 * (g / P->gw)) * P->W + 2 * (g % P->gw);
        double S = 0;
        for (int i = 0; i < P->nl; i++)
            if ((m >> i) & 1) S += out->L[(size_t)i * P->npx + px];
        S *= cf->exposure_us;
        double Pv = P->sensor->offset_dn + S;
        cf->object_pix++;
        bool bad = false;
        if (Pv >= P->sat) {
            cf->saturated_pix++;
            bad = true;
        }
        if (P->glare[g] & m) {
            cf->glare_pix++;
            bad = true;
        }
        if (!bad && S >= P->floor_s) usable++;
    }
    cf->usable_points = usable * 4.0 / (P->opt->spacing_px * P->opt->spacing_px);
    if (!lightplan_segments_for(out, m, cf->exposure_us, P->opt, tmp)) return false;
    cf->n_segments = out->nsegments;
    for (int s = 0; s < out->nsegments; s++)
        if (tmp[s].detectable) {
            cf->n_detectable++;
            cf->detectable_length_px += tmp[s].length_px;
        }
    double limit = P->opt->max_bad_frac * cf->object_pix;
    cf->feasible = cf->saturated_pix <= limit && cf->glare_pix <= limit;
    return true;
}

// Configuration c better than b: feasible first; among infeasible ones the
// fewest bad pixels; then the longest detectable edge length, then the most
// usable reference points.
static bool config_better(const lightplan_config_t *c, const lightplan_config_t *b)
{
    if (c->feasible != b->feasible) return c->feasible;
    if (!c->feasible) return c->saturated_pix + c->glare_pix < b->saturated_pix + b->glare_pix;
    if (fabs(c->detectable_length_px - b->detectable_length_px) > 1e-9)
        return c->detectable_length_px > b->detectable_length_px;
    return c->usable_points > b->usable_points;
}

// Every configuration (lamp sets of at most max_lamps, every exposure), the
// best one, and the segments' contrast for it (out->segments).
static bool plan_configs(plan_t *P)
{
    lightplan_result_t *out = P->out;
    const int nl = P->nl, maxl = P->opt->max_lamps;
    int nsets = 0;
    for (uint32_t m = 1; m < (1u << nl); m++)
        if (!maxl || __builtin_popcount(m) <= maxl) nsets++;
    out->nconfigs = nsets * P->nexp;
    out->configs = calloc((size_t)out->nconfigs, sizeof *out->configs);
    lightplan_segment_t *tmp = malloc((size_t)(out->nsegments ? out->nsegments : 1) * sizeof *tmp);
    if (!out->configs || !tmp) {
        free(tmp);
        return no_memory();
    }
    int c = 0, best = -1;
    for (uint32_t m = 1; m < (1u << nl); m++) {
        if (maxl && __builtin_popcount(m) > maxl) continue;
        for (int x = 0; x < P->nexp; x++, c++) {
            lightplan_config_t *cf = &out->configs[c];
            cf->mask = m;
            cf->exposure_us = P->exposures[x];
            if (!plan_config(P, cf, tmp)) {
                free(tmp);
                return false;
            }
            if (best < 0 || config_better(cf, &out->configs[best])) best = c;
        }
    }
    out->best = best;
    out->best_feasible = out->configs[best].feasible;
    const lightplan_config_t *b = &out->configs[best];
    bool ok = lightplan_segments_for(out, b->mask, b->exposure_us, P->opt, tmp);
    if (ok) memcpy(out->segments, tmp, (size_t)out->nsegments * sizeof *tmp);
    free(tmp);
    return ok;
}

// The chosen configuration's predicted image (direct light, clipped at saturation).
static void plan_predicted(plan_t *P)
{
    lightplan_result_t *out = P->out;
    const lightplan_config_t *b = &out->configs[out->best];
    for (size_t p = 0; p < P->npx; p++) {
        double S = 0;
        for (int i = 0; i < P->nl; i++)
            if ((b->mask >> i) & 1) S += out->L[(size_t)i * P->npx + p];
        out->predicted[p] = (float)fmin(P->sensor->offset_dn + b->exposure_us * S, P->sensor->saturation_dn);
    }
}

// The chosen configuration's faces (out->faces: grey values, usable share,
// glare and saturated pixels on the grid).
static bool plan_faces(plan_t *P)
{
    lightplan_result_t *out = P->out;
    const lightplan_config_t *b = &out->configs[out->best];
    int nf = P->scene->nfaces + P->scene->nspheres;
    out->faces = calloc((size_t)(nf ? nf : 1), sizeof *out->faces);
    double *vals = malloc(P->ng * sizeof *vals);
    if (!out->faces || !vals) {
        free(vals);
        return no_memory();
    }
    out->nfaces = nf;
    for (int f = 0; f < nf; f++) {
        lightplan_face_t *F = &out->faces[f];
        F->face = f;
        F->P_min = INFINITY;
        F->P_max = -INFINITY;
        int nv = 0, nu = 0;
        for (size_t g = 0; g < P->ng; g++) {
            if (P->pi[g].face != f) continue;
            size_t px = (size_t)(2 * (g / P->gw)) * P->W + 2 * (g % P->gw);
            double Pv = out->predicted[px], S = Pv - P->sensor->offset_dn;
            vals[nv++] = Pv;
            F->P_min = fmin(F->P_min, Pv);
            F->P_max = fmax(F->P_max, Pv);
            if (Pv >= P->sat) F->saturated_pix++;
            if (P->glare[g] & b->mask) F->glare_pix++;
            if (Pv < P->sat && S >= P->floor_s) nu++;
        }
        F->npix = nv;
        if (nv) {
            F->P_median = model_median(vals, nv);
            F->usable_frac = (double)nu / nv;
        } else {
            F->P_min = F->P_max = F->P_median = NAN;
        }
    }
    free(vals);
    return true;
}

// The glare of every candidate at full resolution (nearest grid point).
static bool plan_glare_image(plan_t *P)
{
    lightplan_result_t *out = P->out;
    out->glare = malloc(P->npx * sizeof *out->glare);
    if (!out->glare) return no_memory();
    for (int y = 0; y < P->H; y++)
        for (int x = 0; x < P->W; x++) {
            int gx = (x + 1) / 2 < P->gw ? (x + 1) / 2 : P->gw - 1, gy = (y + 1) / 2 < P->gh ? (y + 1) / 2 : P->gh - 1;
            out->glare[(size_t)y * P->W + x] = P->glare[(size_t)gy * P->gw + gx];
        }
    return true;
}

bool lightplan_run(const model_scene_t *scene, model_camera_t *cam, const model_lamps_t *cands, const double *A,
                   const model_material_t *const *mats, const lightplan_sensor_t *sensor, const double *exposures,
                   int nexp, const lightplan_options_t *opt, lightplan_result_t *out)
{
    memset(out, 0, sizeof *out);
    double t0 = model_now_s();
    const int nl = cands->n;
    if (nl < 1 || nl > MAXL) {
        model_error(cands->path, 0, "%d candidate lamps: give 1 to %d", nl, MAXL);
        return false;
    }
    if (nexp < 1) {
        model_error(NULL, 0, "light planning: no exposure to try");
        return false;
    }
    if (!(opt->psf_sigma_px >= 0 && opt->psf_sigma_px <= 10)) {
        model_error(NULL, 0, "light planning: the PSF's sigma %g px is not in [0, 10] px (0: a sharp step)",
                    opt->psf_sigma_px);
        return false;
    }
    plan_t P = { .scene = scene, .cam = cam, .cands = cands, .A = A, .mats = mats, .sensor = sensor,
                 .exposures = exposures, .nexp = nexp, .opt = opt, .out = out, .nl = nl };
    P.W = model_camera_width(cam);
    P.H = model_camera_height(cam);
    P.npx = (size_t)P.W * P.H;
    out->W = P.W;
    out->H = P.H;
    out->nlamps = nl;
    P.threads = opt->threads > 0 ? opt->threads : model_default_threads();
    P.t = model_tracer_new(scene);
    out->L = malloc(P.npx * nl * sizeof(float));
    out->face_id = malloc(P.npx * sizeof(int32_t));
    out->predicted = malloc(P.npx * sizeof(float));
    P.gw = (P.W + 1) / 2;
    P.gh = (P.H + 1) / 2;
    P.ng = (size_t)P.gw * P.gh;
    P.pi = malloc(P.ng * sizeof *P.pi);
    P.ls = malloc(P.ng * nl * sizeof *P.ls);
    P.glare = calloc(P.ng, sizeof *P.glare);
    P.sat = sensor->saturation_dn * opt->saturation_frac;
    P.floor_s = signal_floor(sensor, opt);
    bool ok = false;
    if (!P.t || !out->L || !out->face_id || !out->predicted || !P.pi || !P.ls || !P.glare) {
        if (P.t) model_error(NULL, 0, "light planning: out of memory for a %dx%d view", P.W, P.H);
        goto done;
    }
    P.sh = model_shading_default();
    P.sh.nthreads = P.threads;
    P.sh.gain_map = sensor->flat;
    if (!plan_render_lamps(&P) || !plan_segments(&P) || !plan_side_signals(&P) || !plan_glare(&P) ||
        !plan_configs(&P))
        goto done;
    plan_predicted(&P);
    ok = plan_faces(&P) && plan_glare_image(&P);
done:
    model_tracer_free(P.t);
    free(P.pi);
    free(P.ls);
    free(P.glare);
    out->time_s = model_now_s() - t0;
    if (!ok) lightplan_result_free(out);
    return ok;
}

static inline double px_at(const float *f, int W, int H, int x, int y)
{
    x = x < 0 ? 0 : x >= W ? W - 1 : x;
    y = y < 0 ? 0 : y >= H ? H - 1 : y;
    return f[(size_t)y * W + x];
}

static double sobel_at(const float *f, int W, int H, int x, int y)
{
    double gx = (px_at(f, W, H, x + 1, y - 1) + 2 * px_at(f, W, H, x + 1, y) + px_at(f, W, H, x + 1, y + 1)) -
                (px_at(f, W, H, x - 1, y - 1) + 2 * px_at(f, W, H, x - 1, y) + px_at(f, W, H, x - 1, y + 1));
    double gy = (px_at(f, W, H, x - 1, y + 1) + 2 * px_at(f, W, H, x, y + 1) + px_at(f, W, H, x + 1, y + 1)) -
                (px_at(f, W, H, x - 1, y - 1) + 2 * px_at(f, W, H, x, y - 1) + px_at(f, W, H, x + 1, y - 1));
    return sqrt(gx * gx + gy * gy);
}


// The points judged along a segment of length L (px): every 2 px, 2 px kept from its ends.
static int judged_points(double L) { return (int)((L - 4) / 2) + 1; }

bool lightplan_sobel_check(const lightplan_segment_t *segs, int nseg, const float *frame, int W, int H,
                           double threshold, bool *found, double *measured, double *agreement)
{
    int agree = 0, n = 0, most = 1;
    for (int s = 0; s < nseg; s++) {
        double dx = segs[s].q1[0] - segs[s].q0[0], dy = segs[s].q1[1] - segs[s].q0[1], L = sqrt(dx * dx + dy * dy);
        if (L >= 8 && judged_points(L) > most) most = judged_points(L);
    }
    double *v = malloc((size_t)most * sizeof *v);
    if (!v) return no_memory();
    for (int s = 0; s < nseg; s++) {
        const lightplan_segment_t *g = &segs[s];
        double dx = g->q1[0] - g->q0[0], dy = g->q1[1] - g->q0[1], L = sqrt(dx * dx + dy * dy);
        double med = 0;
        if (L < 8) {   // too short for a median along it: not judged
            if (found) found[s] = false;
            if (measured) measured[s] = NAN;
            continue;
        }
        {
            double ux = dx / L, uy = dy / L, nx = -uy, ny = ux;
            int m = judged_points(L);
            for (int k = 0; k < m; k++) {
                double t = 2 + 2.0 * k;
                double best = 0;
                for (double o = -1.5; o <= 1.5; o += 0.5) {
                    double x = g->q0[0] + ux * t + nx * o, y = g->q0[1] + uy * t + ny * o;
                    best = fmax(best, sobel_at(frame, W, H, (int)lround(x), (int)lround(y)));
                }
                v[k] = best;
            }
            med = model_median(v, m);
        }
        bool f = med >= threshold;
        if (found) found[s] = f;
        if (measured) measured[s] = med;
        agree += f == g->detectable;
        n++;
    }
    free(v);
    *agreement = n ? (double)agree / n : NAN;
    return true;
}
