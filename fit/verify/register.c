// fit/verify/register.c — the part's placement as a nuisance: before the
// photometric fit, the description's predicted edges are registered to the
// images over the fixture's tolerance (a rigid turn about the part's centre
// and a shift on the turntable), so that a rightly made part placed a little
// off is verified where it lies, while a part made wrong (a stiffener off on
// its plate) still shows: its other edges hold the pose. See fit/verify/verify.h.
//
// The edges (model_edges_predict, at the priors' means and the images'
// lamps, exposure and gain: their contrast in DN) are sampled in 3D along
// their visible image segments, once, at the nominal pose. A pose moves the
// samples rigidly; each is projected and the image's contrast across the
// edge (grey value d px to its right minus d px to its left, as predicted) is
// compared with the prediction: score = sum_s w_s clamp(m_s / c_s, -1, 2),
// w_s = |c_s| / sum |c| (1: every edge where and as predicted). A coarse grid
// over the tolerance on images blurred by a Gaussian (sigma 3 px, d 5 px,
// a wide basin) is followed by a pattern search on the images themselves
// (d 2 px) with steps halving to 0.02 mm / 0.01 deg.
#define _GNU_SOURCE
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fit/verify/verify.h"
#include "model/base/vec.h"

#define MAX_SAMPLES_PER_IMAGE 1500

typedef struct {
    model_vec3_t p;     // the part's frame (before the turntable angle), mm
    double t_img[2];    // the edge's unit direction in the image at the nominal pose
    double c;           // predicted contrast, DN (right minus left of t_img)
    int    image;
} esample_t;

typedef struct {
    const verify_image_t *imgs;
    const verify_camera_t *cams;
    int nimgs;
    esample_t *s;
    int n;
    double wsum;
    float **blur;        // per image: Gaussian-blurred copy (the coarse stage)
    double cx, cy;       // the part's centre (its bounding box's middle in x and y)
} reg_t;

static void bbox_centre(const model_scene_t *sc, double *cx, double *cy)
{
    double lo[2] = { INFINITY, INFINITY }, hi[2] = { -INFINITY, -INFINITY };
    for (int i = 0; i < sc->nvertices; i++) {
        lo[0] = fmin(lo[0], sc->vertices[i].x), hi[0] = fmax(hi[0], sc->vertices[i].x);
        lo[1] = fmin(lo[1], sc->vertices[i].y), hi[1] = fmax(hi[1], sc->vertices[i].y);
    }
    *cx = isfinite(lo[0]) ? (lo[0] + hi[0]) / 2 : 0;
    *cy = isfinite(lo[1]) ? (lo[1] + hi[1]) / 2 : 0;
}

model_scene_t *verify_placed_scene(const model_scene_t *scene, const verify_placement_t *p)
{
    double a = p->turn_deg * M_PI / 180, c = cos(a), s = sin(a);
    double R[9] = { c, -s, 0, s, c, 0, 0, 0, 1 };
    double t[3] = { p->centre_mm[0] - (c * p->centre_mm[0] - s * p->centre_mm[1]) + p->dx_mm,
                    p->centre_mm[1] - (s * p->centre_mm[0] + c * p->centre_mm[1]) + p->dy_mm, 0 };
    return model_scene_transformed(scene, R, t);
}

// Point p of the part's frame at pose (dx, dy, turn) and turntable angle ang, world frame.
static model_vec3_t pose_point(const reg_t *R, model_vec3_t p, const double pose[3], double ang_deg)
{
    double a = pose[2] * M_PI / 180, c = cos(a), s = sin(a);
    double x = c * (p.x - R->cx) - s * (p.y - R->cy) + R->cx + pose[0];
    double y = s * (p.x - R->cx) + c * (p.y - R->cy) + R->cy + pose[1];
    double b = ang_deg * M_PI / 180, cb = cos(b), sb = sin(b);
    return (model_vec3_t){ cb * x - sb * y, sb * x + cb * y, p.z };
}

// The score of a pose (coarse: on the blurred images, d 5 px; else d 2 px).
static double pose_score(const reg_t *R, const double pose[3], bool coarse)
{
    const double d = coarse ? 5 : 1;
    double sum = 0;
    for (int k = 0; k < R->n; k++) {
        const esample_t *e = &R->s[k];
        const verify_image_t *im = &R->imgs[e->image];
        model_vec3_t w = pose_point(R, e->p, pose, im->angle_deg);
        double q[2];
        if (!model_camera_project(R->cams[im->camera].cam, &w, 1, q)) continue;
        // the image direction turns with the part (the turn is small: its own rotation in the image
        // is neglected), the right-hand normal in the displayed image (y down)
        double rx = -e->t_img[1], ry = e->t_img[0];
        const float *P = coarse ? R->blur[e->image] : im->P;
        bool in = true;
        double m = model_image_bilinear(P, im->W, im->H, q[0] + d * rx, q[1] + d * ry, &in) -
                   model_image_bilinear(P, im->W, im->H, q[0] - d * rx, q[1] - d * ry, &in);
        if (!in) continue;
        double ratio = fmax(-1, fmin(2, m / e->c));
        sum += fabs(e->c) * ratio;
    }
    return sum / R->wsum;
}

// A separable Gaussian blur (sigma px) of a W x H image. NULL: out of memory.
static float *gauss_blur(const float *P, int W, int H, double sigma)
{
    int r = (int)ceil(3 * sigma);
    double *k = malloc((size_t)(2 * r + 1) * sizeof *k), ks = 0;
    float *tmp = malloc((size_t)W * H * sizeof *tmp), *out = malloc((size_t)W * H * sizeof *out);
    if (!k || !tmp || !out) {
        free(k);
        free(tmp);
        free(out);
        return NULL;
    }
    for (int i = -r; i <= r; i++) ks += k[i + r] = exp(-0.5 * i * i / (sigma * sigma));
    for (int i = 0; i <= 2 * r; i++) k[i] /= ks;
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++) {
            double s = 0;
            for (int i = -r; i <= r; i++) {
                int xx = x + i < 0 ? 0 : x + i >= W ? W - 1 : x + i;
                s += k[i + r] * P[(size_t)y * W + xx];
            }
            tmp[(size_t)y * W + x] = (float)s;
        }
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++) {
            double s = 0;
            for (int i = -r; i <= r; i++) {
                int yy = y + i < 0 ? 0 : y + i >= H ? H - 1 : y + i;
                s += k[i + r] * tmp[(size_t)yy * W + x];
            }
            out[(size_t)y * W + x] = (float)s;
        }
    free(k);
    free(tmp);
    return out;
}

static double seg_dist2(const double q[2], const double a[2], const double b[2], double *u)
{
    double dx = b[0] - a[0], dy = b[1] - a[1], L2 = dx * dx + dy * dy;
    double t = L2 > 0 ? ((q[0] - a[0]) * dx + (q[1] - a[1]) * dy) / L2 : 0;
    t = fmax(0, fmin(1, t));
    if (u) *u = t;
    double ex = a[0] + t * dx - q[0], ey = a[1] + t * dy - q[1];
    return ex * ex + ey * ey;
}

// Image m's edge samples (appended to R->s). false + message.
static bool image_samples(reg_t *R, const model_scene_t *scene, const model_lamps_t *lamps, const double *A,
                          const model_material_t *const *mats, int m, int *cap)
{
    const verify_image_t *im = &R->imgs[m];
    const verify_camera_t *cm = &R->cams[im->camera];
    model_scene_t *sc = model_scene_rotated_z(scene, im->angle_deg);
    model_tracer_t *t = sc ? model_tracer_new(sc) : NULL;
    model_lamps_t L = *lamps;
    L.lamps = malloc((size_t)lamps->n * sizeof *L.lamps);
    bool ok = false;
    model_edges_t *E = NULL;
    if (!t || !L.lamps) {
        model_error(NULL, 0, "verify: registering %s: %s", im->name, sc ? "out of memory" : model_last_error());
        goto done;
    }
    double gf = 1;
    model_gain_factor(im->gain_db, "dB", 0, "dB", im->name, &gf);
    for (int i = 0; i < lamps->n; i++) {
        L.lamps[i] = lamps->lamps[i];
        // intensities in DN per (R in 1/sr / d^2 in mm^2): P_side in DN (the offset aside)
        L.lamps[i].intensity = (im->lamps_on >> i) & 1 ? A[i] * im->exposure_us * gf : 0;
    }
    model_shading_t sh = { .kc = cm->kc_rel > 0 ? cm->kc_rel : 1, .interreflection = MODEL_INTERREFLECTION_NONE,
                           .nthreads = 1 };
    if (!(E = model_edges_predict(sc, t, cm->cam, &L, mats, &sh, 20))) goto done;
    double cmax = 0;
    for (int e = 0; e < E->nedges; e++)
        for (int g = 0; g < E->edges[e].nsegments; g++) cmax = fmax(cmax, fabs(E->edges[e].segments[g].contrast));
    int first = R->n;
    for (int e = 0; e < E->nedges; e++) {
        const model_edge_t *ed = &E->edges[e];
        model_vec3_t v0 = sc->vertices[ed->v0], v1 = sc->vertices[ed->v1];
        double len = sqrt((v1.x - v0.x) * (v1.x - v0.x) + (v1.y - v0.y) * (v1.y - v0.y) + (v1.z - v0.z) * (v1.z - v0.z));
        int ns = (int)ceil(len / 0.5) + 1;
        for (int g = 0; g < ed->nsegments; g++) {
            const model_edge_segment_t *sg = &ed->segments[g];
            if (fabs(sg->contrast) < 0.05 * cmax || sg->length_px < 6) continue;
            double tx = sg->q1[0] - sg->q0[0], ty = sg->q1[1] - sg->q0[1], tl = hypot(tx, ty);
            for (int j = 0; j < ns; j++) {
                double f = (j + 0.5) / ns;
                model_vec3_t w = { v0.x + f * (v1.x - v0.x), v0.y + f * (v1.y - v0.y), v0.z + f * (v1.z - v0.z) };
                double q[2], u;
                if (!model_camera_project(cm->cam, &w, 1, q) || seg_dist2(q, sg->q0, sg->q1, &u) > 0.5 * 0.5 ||
                    u < 0.05 || u > 0.95)
                    continue;   // hidden here, or near the segment's ends (a corner)
                if (R->n == *cap) {
                    esample_t *grown = realloc(R->s, (size_t)(*cap = *cap ? 2 * *cap : 1024) * sizeof *grown);
                    if (!grown) {
                        model_error(NULL, 0, "verify: registering %s: out of memory", im->name);
                        goto done;
                    }
                    R->s = grown;
                }
                double b = -im->angle_deg * M_PI / 180, cb = cos(b), sb = sin(b);
                R->s[R->n++] = (esample_t){ .p = { cb * w.x - sb * w.y, sb * w.x + cb * w.y, w.z },
                                            .t_img = { tx / tl, ty / tl }, .c = sg->contrast, .image = m };
            }
        }
    }
    // at most MAX_SAMPLES_PER_IMAGE, evenly
    int n = R->n - first;
    if (n > MAX_SAMPLES_PER_IMAGE) {
        for (int k = 0; k < MAX_SAMPLES_PER_IMAGE; k++) R->s[first + k] = R->s[first + (int)((long)k * n / MAX_SAMPLES_PER_IMAGE)];
        R->n = first + MAX_SAMPLES_PER_IMAGE;
    }
    ok = true;
done:
    model_edges_free(E);
    free(L.lamps);
    model_tracer_free(t);
    model_scene_free(sc);
    return ok;
}

// The pattern search from pose (on the images themselves, or coarse): steps
// halving from (step_mm, step_deg) down to (min_mm, min_deg), within the tolerance.
static double pattern_search(const reg_t *R, double pose[3], double step_mm, double step_deg, double min_mm,
                             double min_deg, double tol_mm, double tol_deg, bool coarse)
{
    double best = pose_score(R, pose, coarse), st[3] = { step_mm, step_mm, step_deg };
    const double lim[3] = { tol_mm, tol_mm, tol_deg };
    while (st[0] >= min_mm || st[2] >= min_deg) {
        bool moved = false;
        for (int k = 0; k < 3; k++)
            for (int sgn = -1; sgn <= 1; sgn += 2) {
                if (st[k] < (k < 2 ? min_mm : min_deg)) continue;
                double p[3] = { pose[0], pose[1], pose[2] };
                p[k] += sgn * st[k];
                if (fabs(p[k]) > lim[k] + 1e-12) continue;
                double s = pose_score(R, p, coarse);
                if (s > best) {
                    best = s;
                    memcpy(pose, p, sizeof p);
                    moved = true;
                }
            }
        if (!moved) {
            st[0] /= 2;
            st[1] /= 2;
            st[2] /= 2;
        }
    }
    return best;
}

bool verify_register(const model_scene_t *scene, const verify_camera_t *cams, const model_lamps_t *lamps,
                     const double *A, const model_material_t *const *mats, const verify_image_t *imgs, int nimgs,
                     double tol_mm, double tol_deg, verify_placement_t *out)
{
    memset(out, 0, sizeof *out);
    double t0 = model_now_s();
    reg_t R = { .imgs = imgs, .cams = cams, .nimgs = nimgs };
    bbox_centre(scene, &R.cx, &R.cy);
    out->centre_mm[0] = R.cx;
    out->centre_mm[1] = R.cy;
    out->tol_mm = tol_mm;
    out->tol_deg = tol_deg;
    if (!(tol_mm > 0) && !(tol_deg > 0)) return true;   // nothing to register
    int cap = 0;
    bool ok = false;
    R.blur = calloc((size_t)nimgs, sizeof *R.blur);
    if (!R.blur) {
        model_error(NULL, 0, "verify: registering the placement: out of memory");
        goto done;
    }
    for (int m = 0; m < nimgs; m++)
        if (!image_samples(&R, scene, lamps, A, mats, m, &cap)) goto done;
    for (int k = 0; k < R.n; k++) R.wsum += fabs(R.s[k].c);
    out->nsamples = R.n;
    if (R.n < 20 || !(R.wsum > 0)) {
        model_error(NULL, 0, "verify: the description has only %d edge points with contrast in view: its "
                    "placement cannot be registered (give --placement-tolerance-mm 0 --placement-tolerance-deg 0)",
                    R.n);
        goto done;
    }
    for (int m = 0; m < nimgs; m++)
        if (!(R.blur[m] = gauss_blur(imgs[m].P, imgs[m].W, imgs[m].H, 3))) {
            model_error(imgs[m].name, 0, "verify: registering the placement: out of memory");
            goto done;
        }
    // the coarse grid (about 1 mm and 0.5 deg apart), then the pattern search
    const double z[3] = { 0, 0, 0 };
    out->score_nominal = pose_score(&R, z, false);
    int nxy = tol_mm > 0 ? 2 * (int)ceil(tol_mm / 1.0) + 1 : 1, nt = tol_deg > 0 ? 2 * (int)ceil(tol_deg / 0.5) + 1 : 1;
    // starts: the nominal pose (the prior's mean) and the coarse grid's best NSTART
    enum { NSTART = 4 };
    double start[NSTART + 1][3] = { { 0, 0, 0 } }, sc[NSTART + 1];
    for (int k = 1; k <= NSTART; k++) sc[k] = -INFINITY;
    for (int i = 0; i < nxy; i++)
        for (int j = 0; j < nxy; j++)
            for (int a = 0; a < nt; a++) {
                double p[3] = { nxy > 1 ? -tol_mm + 2 * tol_mm * i / (nxy - 1) : 0,
                                nxy > 1 ? -tol_mm + 2 * tol_mm * j / (nxy - 1) : 0,
                                nt > 1 ? -tol_deg + 2 * tol_deg * a / (nt - 1) : 0 };
                double s = pose_score(&R, p, true);
                int k = NSTART;
                if (!(s > sc[k])) continue;
                for (; k > 1 && s > sc[k - 1]; k--) {
                    sc[k] = sc[k - 1];
                    memcpy(start[k], start[k - 1], sizeof start[k]);
                }
                sc[k] = s;
                memcpy(start[k], p, sizeof p);
            }
    // each start refined (coarse, then on the images themselves); the best wins: a description
    // whose edges disagree among themselves (a part made wrong) is held by one consistent set of
    // them, not by a compromise that puts every edge a little off
    double smm = tol_mm > 0 ? 0.5 : 0, sdeg = tol_deg > 0 ? 0.25 : 0, best = -INFINITY, pose[3] = { 0, 0, 0 };
    for (int k = 0; k <= NSTART; k++) {
        if (k > 0 && !isfinite(sc[k])) continue;
        for (int refine = 0; refine < 2; refine++) {   // as it starts, and after a coarse refinement
            double p[3] = { start[k][0], start[k][1], start[k][2] };
            if (refine) pattern_search(&R, p, smm, sdeg, 0.1, 0.05, tol_mm, tol_deg, true);
            double s = pattern_search(&R, p, smm / 2, sdeg / 2, 0.02, 0.01, tol_mm, tol_deg, false);
            if (s > best) {
                best = s;
                memcpy(pose, p, sizeof p);
            }
        }
    }
    out->score = best;
    out->dx_mm = pose[0];
    out->dy_mm = pose[1];
    out->turn_deg = pose[2];
    out->at_limit = (tol_mm > 0 && (fabs(pose[0]) > 0.98 * tol_mm || fabs(pose[1]) > 0.98 * tol_mm)) ||
                    (tol_deg > 0 && fabs(pose[2]) > 0.98 * tol_deg);
    ok = true;
done:
    if (R.blur)
        for (int m = 0; m < nimgs; m++) free(R.blur[m]);
    free(R.blur);
    free(R.s);
    out->time_s = model_now_s() - t0;
    return ok;
}
