// calib/sample_pose.c — the sample's pose (its wedge's tilt and azimuth, its
// offset on the wedge's face and its height) fitted from the outline of the
// sample in its own session's frames, with the plan's nominal wedge as the
// prior (calib/calib.h, "The sample's pose fitted from its own frames").
#define _GNU_SOURCE
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "calib/calib.h"
#include "model/base/lsq.h"
#include "model/base/vec.h"

#define NPOSE 6
#define MAX_SAMPLES_PER_ANGLE 600
#define EDGE_STEP_MM 0.5
#define MIN_CONTRAST_NOISE 10.0   // an edge's step over the image's noise std, at least

static const char *const pose_names[NPOSE] = { "tilt_deg", "tilt_azimuth_deg", "dx_mm", "dy_mm", "dz_mm", "turn_deg" };

calib_sample_pose_options_t calib_sample_pose_defaults(void)
{
    return (calib_sample_pose_options_t){ .sigma_deg = 1, .sigma_mm = 2, .min_samples = 60 };
}

void calib_sample_pose_Rt(const model_scene_t *scene, const double p[6], double R[9], double t[3])
{
    // the turn's centre: the middle of the scene's bounding box in x and y
    double lo[2] = { INFINITY, INFINITY }, hi[2] = { -INFINITY, -INFINITY };
    for (int i = 0; i < scene->nvertices; i++) {
        lo[0] = fmin(lo[0], scene->vertices[i].x), hi[0] = fmax(hi[0], scene->vertices[i].x);
        lo[1] = fmin(lo[1], scene->vertices[i].y), hi[1] = fmax(hi[1], scene->vertices[i].y);
    }
    double cx = isfinite(lo[0]) ? (lo[0] + hi[0]) / 2 : 0, cy = isfinite(lo[1]) ? (lo[1] + hi[1]) / 2 : 0;
    double a = p[5] * M_PI / 180, c = cos(a), s = sin(a);
    // Rz(turn) (x0 - c) + c + d = Rz x0 + u
    const double Rz[9] = { c, -s, 0, s, c, 0, 0, 0, 1 };
    const double u[3] = { cx - (c * cx - s * cy) + p[2], cy - (s * cx + c * cy) + p[3], 0 };
    double Rw[9], tw[3];
    model_scene_wedge_pose(scene, p[0], p[1], Rw, tw);
    m3_mul(R, Rw, Rz);
    for (int r = 0; r < 3; r++) {
        t[r] = tw[r];
        for (int k = 0; k < 3; k++) t[r] += Rw[3 * r + k] * u[k];
    }
    t[2] += p[4];
}

// One edge sample: a point of the sample's outline in its own frame, seen at
// an angle; the image's edge found along dir (unit, from the sample to the
// background) at m.
typedef struct {
    model_vec3_t x0;
    double       dir[2];
    double       m[2];
    int          angle;    // index into the angles' images
    bool         found;
} esample_t;

// An angle's image: the sum of its frames lit by one lamp (each lamp's
// longest exposure) and its noise std (of the sum, DN).
typedef struct {
    double deg;
    float *img;
    double noise;
} eimage_t;

typedef struct {
    const model_scene_t *scene;       // the sample's, unposed
    const model_camera_t *cam;
    const eimage_t *im;
    int nim, W, H;
    esample_t *s;
    int n;
    double sigma_px;                  // the residuals' scale
    int *use;                         // the samples that enter the fit (found)
    int nuse;
    model_vec3_t *pts;                // scratch: nuse points
    double *q;                        // scratch: 2 nuse
} pose_fit_t;

static model_vec3_t posed_point(const double R[9], const double t[3], model_vec3_t x, double deg)
{
    double w[3];
    for (int r = 0; r < 3; r++) w[r] = R[3 * r] * x.x + R[3 * r + 1] * x.y + R[3 * r + 2] * x.z + t[r];
    double a = deg * M_PI / 180, c = cos(a), s = sin(a);
    return (model_vec3_t){ c * w[0] - s * w[1], s * w[0] + c * w[1], w[2] };
}

// The used samples' projections at pose p into F->q. false when a projection fails.
static bool project_used(pose_fit_t *F, const double *p)
{
    double R[9], t[3];
    calib_sample_pose_Rt(F->scene, p, R, t);
    for (int k = 0; k < F->nuse; k++) {
        const esample_t *e = &F->s[F->use[k]];
        F->pts[k] = posed_point(R, t, e->x0, F->im[e->angle].deg);
    }
    if (!model_camera_project(F->cam, F->pts, F->nuse, F->q)) return false;
    for (int k = 0; k < 2 * F->nuse; k++)
        if (!isfinite(F->q[k])) return false;
    return true;
}

static bool residuals_at(pose_fit_t *F, const double *p, double *res)
{
    if (!project_used(F, p)) return false;
    for (int k = 0; k < F->nuse; k++) {
        const esample_t *e = &F->s[F->use[k]];
        res[k] = (e->dir[0] * (F->q[2 * k] - e->m[0]) + e->dir[1] * (F->q[2 * k + 1] - e->m[1])) / F->sigma_px;
    }
    return true;
}

// lsq callback: the distances along each sample's normal; the Jacobian by
// central differences (steps of 1e-4 deg or mm: the projection is smooth).
static bool pose_residuals(void *ctx, const double *const *params, double *res, double **jac)
{
    pose_fit_t *F = ctx;
    if (!residuals_at(F, params[0], res)) return false;
    if (!jac || !jac[0]) return true;
    double *rp = malloc(2 * (size_t)F->nuse * sizeof *rp), *rm = rp ? rp + F->nuse : NULL;
    if (!rp) {
        model_error_set(NULL, 0, "out of memory for the pose's Jacobian");
        return false;
    }
    bool ok = true;
    for (int j = 0; j < NPOSE && ok; j++) {
        double p[NPOSE], h = 1e-4;
        memcpy(p, params[0], sizeof p);
        p[j] += h;
        ok = residuals_at(F, p, rp);
        p[j] -= 2 * h;
        ok = ok && residuals_at(F, p, rm);
        for (int k = 0; ok && k < F->nuse; k++) jac[0][(size_t)k * NPOSE + j] = (rp[k] - rm[k]) / (2 * h);
    }
    free(rp);
    return ok && residuals_at(F, params[0], res);
}

// The image's edge near q along dir (from the sample to the background)
// within +-reach px: the steepest fall of the profile (averaged over 3 px
// along the edge), refined by a parabola; its step (the means 3 px either
// side) must exceed MIN_CONTRAST_NOISE times the noise. *m: the edge point.
static bool find_edge(const eimage_t *im, int W, int H, const double q[2], const double dir[2], double reach,
                      double m[2])
{
    enum { SUB = 4 };
    const double tg[2] = { -dir[1], dir[0] };
    int ns = (int)ceil((reach + 4) * SUB);
    double prof[2 * 16 * SUB * 4 + 8];
    if (2 * ns + 1 > (int)(sizeof prof / sizeof *prof)) return false;
    bool inside = true;
    for (int i = -ns; i <= ns; i++) {
        double s = (double)i / SUB, v = 0;
        for (int k = -1; k <= 1; k++)
            v += model_image_bilinear(im->img, W, H, q[0] + s * dir[0] + k * tg[0], q[1] + s * dir[1] + k * tg[1], &inside);
        prof[i + ns] = v / 3;
    }
    if (!inside) return false;
    // the fall over 2 px; its local maximum nearest the prediction of at
    // least half the step required (another edge may fall further away)
    int best = 0, lim = (int)(reach * SUB);
    double gbest = -INFINITY;
#define FALL(i) (prof[(i) + ns - SUB] - prof[(i) + ns + SUB])
    for (int i = -lim; i <= lim; i++) {
        double g = FALL(i);
        if (!(g > 0.5 * MIN_CONTRAST_NOISE * im->noise) || g < FALL(i - 1) || g < FALL(i + 1)) continue;
        if (gbest == -INFINITY || abs(i) < abs(best)) gbest = g, best = i;
    }
    if (gbest == -INFINITY) return false;
    double gm = FALL(best - 1), gp = FALL(best + 1);
#undef FALL
    double den = gm - 2 * gbest + gp, off = den < 0 ? 0.5 * (gm - gp) / den : 0;
    if (fabs(off) > 1) off = 0;
    double s = (best + off) / SUB;
    int a = best + ns - 3 * SUB, b = best + ns + 3 * SUB;
    if (a < 0 || b > 2 * ns) return false;
    double step = prof[a] - prof[b];
    if (!(step > MIN_CONTRAST_NOISE * im->noise)) return false;
    m[0] = q[0] + s * dir[0];
    m[1] = q[1] + s * dir[1];
    return true;
}

// The noise std of an image (DN): the median absolute difference of
// horizontal neighbours on a sparse grid (mostly background), over sqrt 2;
// at least half a DN. NAN: out of memory.
static double image_noise(const float *P, int W, int H)
{
    int n = 0, cap = (W / 4 + 1) * (H / 4 + 1);
    double *d = malloc((size_t)cap * sizeof *d);
    if (!d) return NAN;
    for (int y = 0; y < H; y += 4)
        for (int x = 0; x + 1 < W; x += 4) d[n++] = fabs((double)P[(size_t)y * W + x + 1] - P[(size_t)y * W + x]);
    qsort(d, (size_t)n, sizeof *d, model_cmp_double);
    double med = n ? d[n / 2] : 0;
    free(d);
    return fmax(1.4826 * med / sqrt(2), 0.5);
}

// The images of the session's angles (*im, *nim): per angle the sum of each
// lamp's longest exposure lit alone. false + message.
static bool angle_images(const rig_session_t *s, const calib_set_t *cal, eimage_t **im, int *nim)
{
    *im = NULL;
    *nim = 0;
    int nl = cal->lamps->n;
    int *pick = malloc((size_t)(nl ? nl : 1) * sizeof *pick);
    bool *done = calloc((size_t)(s->n ? s->n : 1), 1);
    eimage_t *v = calloc((size_t)(s->n ? s->n : 1), sizeof *v);
    bool ok = false;
    if (!pick || !done || !v) goto oom;
    for (int f0 = 0; f0 < s->n; f0++) {
        if (done[f0]) continue;
        const rig_frame_row_t *r0 = &s->rows[f0];
        for (int l = 0; l < nl; l++) pick[l] = -1;
        for (int f = f0; f < s->n; f++) {
            const rig_frame_row_t *r = &s->rows[f];
            if (r->measured_deg != r0->measured_deg || r->commanded_deg != r0->commanded_deg) continue;
            done[f] = true;
            int l = model_lamps_find(cal->lamps, r->lamps);
            if (l >= 0 && (pick[l] < 0 || r->exposure_us > s->rows[pick[l]].exposure_us)) pick[l] = f;
        }
        float *sum = NULL;
        for (int l = 0; l < nl; l++) {
            if (pick[l] < 0) continue;
            int w, h;
            float *img = rig_session_frame(s, pick[l], &w, &h);
            if (!img) {
                free(sum);
                goto fail;
            }
            if (w != cal->W || h != cal->H) {
                model_error_set(s->dir, 0, "step %d: %dx%d frame, the camera model is %dx%d", s->rows[pick[l]].step,
                                w, h, cal->W, cal->H);
                free(img);
                free(sum);
                goto fail;
            }
            if (!sum) sum = img;
            else {
                for (size_t i = 0; i < (size_t)w * h; i++) sum[i] += img[i];
                free(img);
            }
        }
        if (!sum) continue;   // no frame lit by one lamp at this angle
        v[*nim] = (eimage_t){ .deg = r0->measured_deg, .img = sum, .noise = image_noise(sum, cal->W, cal->H) };
        (*nim)++;
        if (isnan(v[*nim - 1].noise)) goto oom;
    }
    ok = true;
    goto fail;
oom:
    model_error_set(s->dir, 0, "out of memory");
fail:
    free(pick);
    free(done);
    *im = v;
    return ok;
}

static bool add_sample(esample_t **s, int *n, int *cap, const esample_t *e)
{
    if (*n == *cap) {
        int c = *cap ? 2 * *cap : 1024;
        esample_t *g = realloc(*s, (size_t)c * sizeof *g);
        if (!g) return false;
        *s = g;
        *cap = c;
    }
    (*s)[(*n)++] = *e;
    return true;
}

static double seg_dist2(const double q[2], const double a[2], const double b[2], double *u)
{
    double dx = b[0] - a[0], dy = b[1] - a[1], l2 = dx * dx + dy * dy;
    *u = l2 > 0 ? ((q[0] - a[0]) * dx + (q[1] - a[1]) * dy) / l2 : 0;
    double t = fmin(fmax(*u, 0), 1), ex = a[0] + t * dx - q[0], ey = a[1] + t * dy - q[1];
    return ex * ex + ey * ey;
}

// The outline samples of angle a at the nominal pose (R, t): the predicted
// edges' visible segments with the background on exactly one side, sampled
// every EDGE_STEP_MM along their 3D edge (away from the segments' ends),
// at most MAX_SAMPLES_PER_ANGLE. false + message.
static bool outline_samples(const model_scene_t *scene, const calib_set_t *cal, const double R[9], const double t[3],
                            double deg, int a, esample_t **s, int *n, int *cap)
{
    model_scene_t *posed = model_scene_transformed(scene, R, t);
    model_scene_t *sc = posed ? model_scene_rotated_z(posed, deg) : NULL;
    model_tracer_t *tr = sc ? model_tracer_new(sc) : NULL;
    const model_material_t **mats = sc ? calloc((size_t)sc->nmaterials + 1, sizeof *mats) : NULL;
    model_shading_t sh = { .kc = 1, .interreflection = MODEL_INTERREFLECTION_NONE, .nthreads = 1 };
    model_edges_t *E = tr && mats ? model_edges_predict(sc, tr, cal->cam, NULL, mats, &sh, 20) : NULL;
    bool ok = false;
    int first = *n;
    model_vec3_t eye = model_camera_centre_world(cal->cam);
    if (tr && !mats) {
        model_error_set(NULL, 0, "out of memory for the sample's predicted edges");
        goto done;
    }
    for (int e = 0; E && e < E->nedges; e++) {
        const model_edge_t *ed = &E->edges[e];
        model_vec3_t v0 = sc->vertices[ed->v0], v1 = sc->vertices[ed->v1];
        double len = sqrt(v3_dot(v3_sub(v1, v0), v3_sub(v1, v0)));
        int ns = (int)ceil(len / EDGE_STEP_MM) + 1;
        for (int g = 0; g < ed->nsegments; g++) {
            const model_edge_segment_t *sg = &ed->segments[g];
            // the top faces' outline against the background: the edge's
            // other face turned away from the camera (a side face in view lies
            // between them, its own edge a few pixels off and maybe dark)
            int fs = sg->face_side[0] < 0 ? sg->face_side[1] : sg->face_side[0];
            int fo = ed->face_a == fs ? ed->face_b : ed->face_a;
            if ((sg->face_side[0] < 0) == (sg->face_side[1] < 0) || sg->length_px < 8 || fs >= scene->nfaces ||
                !(scene->faces[fs].normal.z > 0.9) || (ed->face_a != fs && ed->face_b != fs) ||
                (fo >= 0 && v3_dot(sc->faces[fo].normal, v3_sub(eye, v0)) > 0))
                continue;
            double tx = sg->q1[0] - sg->q0[0], ty = sg->q1[1] - sg->q0[1], tl = hypot(tx, ty);
            // side 0 lies at (-ty, tx) from the segment: the direction to the background
            double sgn = sg->face_side[0] < 0 ? 1 : -1, dir[2] = { -sgn * ty / tl, sgn * tx / tl };
            for (int j = 0; j < ns; j++) {
                double f = (j + 0.5) / ns, q[2], u;
                model_vec3_t w = v3_add(v0, v3_scale(v3_sub(v1, v0), f));
                if (!model_camera_project(cal->cam, &w, 1, q) || seg_dist2(q, sg->q0, sg->q1, &u) > 0.25 ||
                    u < 0.05 || u > 0.95)
                    continue;
                // back to the sample's own frame: un-turn, then x0 = R^T (x - t)
                double b = -deg * M_PI / 180, x = cos(b) * w.x - sin(b) * w.y, y = sin(b) * w.x + cos(b) * w.y;
                double d[3] = { x - t[0], y - t[1], w.z - t[2] };
                esample_t es = { .x0 = { R[0] * d[0] + R[3] * d[1] + R[6] * d[2], R[1] * d[0] + R[4] * d[1] + R[7] * d[2],
                                         R[2] * d[0] + R[5] * d[1] + R[8] * d[2] },
                                 .dir = { dir[0], dir[1] }, .angle = a };
                if (!add_sample(s, n, cap, &es)) {
                    model_error_set(NULL, 0, "out of memory");
                    goto done;
                }
            }
        }
    }
    if (!E) {
        char msg[1600];
        snprintf(msg, sizeof msg, "%s", model_last_error());
        model_error_set(NULL, 0, "the sample's predicted edges at %.3f deg: %s", deg, msg);
        goto done;
    }
    int m = *n - first;   // at most MAX_SAMPLES_PER_ANGLE, evenly
    if (m > MAX_SAMPLES_PER_ANGLE) {
        for (int k = 0; k < MAX_SAMPLES_PER_ANGLE; k++) (*s)[first + k] = (*s)[first + (int)((long)k * m / MAX_SAMPLES_PER_ANGLE)];
        *n = first + MAX_SAMPLES_PER_ANGLE;
    }
    ok = true;
done:
    model_edges_free(E);
    free(mats);
    model_tracer_free(tr);
    model_scene_free(sc);
    model_scene_free(posed);
    return ok;
}

// Every sample's edge searched within reach px of its projection at pose p
// (found or not); the found ones into F->use. false: a projection failed.
static bool measure(pose_fit_t *F, const double *p, double reach)
{
    F->nuse = F->n;
    for (int k = 0; k < F->n; k++) F->use[k] = k;
    if (!project_used(F, p)) return false;
    int nu = 0;
    for (int k = 0; k < F->n; k++) {
        esample_t *e = &F->s[k];
        e->found = find_edge(&F->im[e->angle], F->W, F->H, &F->q[2 * k], e->dir, reach, e->m);
        if (e->found) F->use[nu++] = k;
    }
    F->nuse = nu;
    return true;
}

// The residuals r (of the used samples, in order along the edges) are not
// independent: the edge found wanders with the pixel grid over several
// pixels. The covariance's factor for it, by batch means: blocks of
// CORR_BLOCK consecutive samples of one angle; the mean square of their
// means times the block size over the residuals' mean square ms (at least 1).
#define CORR_BLOCK 8
static double correlation_factor(const pose_fit_t *F, const double *r, double ms)
{
    double sb = 0;
    int nb = 0;
    for (int k = 0; k + CORR_BLOCK <= F->nuse;) {
        int a = F->s[F->use[k]].angle, m = 0;
        double sum = 0;
        while (m < CORR_BLOCK && F->s[F->use[k + m]].angle == a) sum += r[k + m], m++;
        if (m == CORR_BLOCK) {
            sb += sum * sum / CORR_BLOCK;
            nb++;
        }
        k += m;
    }
    return nb > 0 && ms > 0 ? fmax(1, sb / nb / ms) : 1;
}

// One least-squares solve of the pose p over the used samples with the
// prior (nominal, prior_sd); cov (may be NULL) its covariance. *rms_px the
// data residuals' RMS after it. false: no usable solution (or covariance).
static bool solve(pose_fit_t *F, double *p, const double *nominal, const double *prior_sd, double *cov, double *rms_px)
{
    lsq_problem_t *P = lsq_problem_new();
    bool ok = P && lsq_add_parameters(P, p, NPOSE) &&
              lsq_add_residual_folded(P, pose_residuals, F, F->nuse, 1, (double *const[]){ p });
    for (int j = 0; ok && j < NPOSE; j++) ok = lsq_add_prior(P, p, j, nominal[j], prior_sd[j]);
    lsq_options_t lo = lsq_defaults();
    lo.threads = 1;
    lo.max_iterations = 50;
    lsq_summary_t sum;
    ok = ok && lsq_solve(P, &lo, &sum);
    if (ok && cov) ok = lsq_covariance(P, p, cov);
    lsq_problem_free(P);
    double *r = ok ? malloc((size_t)F->nuse * sizeof *r) : NULL, ss = 0;
    if (ok && !r) model_error_set(NULL, 0, "out of memory for the pose's residuals");
    ok = r && residuals_at(F, p, r);
    for (int k = 0; ok && k < F->nuse; k++) ss += r[k] * r[k];
    if (ok) *rms_px = F->sigma_px * sqrt(ss / F->nuse);
    if (ok && cov) {
        double f = correlation_factor(F, r, ss / F->nuse);
        for (int j = 0; j < NPOSE * NPOSE; j++) cov[j] *= f;
    }
    // samples beyond 4 RMS (another edge found) leave the fit
    int nu = 0;
    for (int k = 0; ok && k < F->nuse; k++)
        if (fabs(r[k]) * F->sigma_px <= 4 * *rms_px) F->use[nu++] = F->use[k];
    if (ok) F->nuse = nu;
    free(r);
    return ok;
}

// The searches and fits: reach 8, 3, 2 px, each solve weighted by the
// previous one's RMS; the covariance from the last. The reason it could not
// be done into why ("" when it was).
static void fit_rounds(pose_fit_t *F, calib_sample_pose_t *out, int min_samples, bool verbose, char *why, size_t wn)
{
    static const double reach[3] = { 8, 3, 2 };
    double p[NPOSE], rms = 0.5;
    memcpy(p, out->nominal, sizeof p);
    why[0] = 0;
    for (int r = 0; r < 3; r++) {
        if (!measure(F, p, reach[r])) {
            snprintf(why, wn, "the outline's projection failed");
            return;
        }
        int na = 0;
        for (int a = 0; a < F->nim; a++)
            for (int k = 0; k < F->nuse; k++)
                if (F->s[F->use[k]].angle == a) {
                    na++;
                    break;
                }
        if (F->nuse < min_samples || na < 2) {
            snprintf(why, wn, "the sample's edges are too weak or not in view: %d of %d outline samples found an "
                     "edge (a step over %g x the noise) at %d of %d angles; %d at 2 angles needed", F->nuse, F->n,
                     MIN_CONTRAST_NOISE, na, F->nim, min_samples);
            return;
        }
        F->sigma_px = fmax(rms, 0.02);
        double prev = rms;
        int nused = F->nuse;   // solve drops the outliers after it
        if (!solve(F, p, out->nominal, out->prior_sd, r == 2 ? out->cov : NULL, &rms)) {
            snprintf(why, wn, "the fit failed (%s)", model_last_error());
            return;
        }
        out->nsamples = nused;
        out->nangles = na;
        if (verbose)
            model_note("sample pose: reach %g px: %d edge samples at %d angles, RMS %.3f px (weight %.3f); tilt %.3f "
                       "az %.3f dx %.3f dy %.3f dz %.3f turn %.3f", reach[r], nused, na, rms, prev, p[0], p[1], p[2],
                       p[3], p[4], p[5]);
    }
    memcpy(out->p, p, sizeof p);
    out->rms_px = rms;
}

bool calib_sample_pose_fit(const rig_session_t *s, const rig_plan_t *plan, const calib_set_t *cal,
                           const model_scene_t *scene, const calib_sample_pose_options_t *opt,
                           calib_sample_pose_t *out)
{
    calib_sample_pose_options_t o = opt ? *opt : calib_sample_pose_defaults();
    memset(out, 0, sizeof *out);
    out->tried = true;
    const double nom[NPOSE] = { plan->tilt_deg, plan->tilt_azimuth_deg, 0, 0, 0, 0 };
    memcpy(out->nominal, nom, sizeof nom);
    memcpy(out->p, nom, sizeof nom);
    for (int j = 0; j < NPOSE; j++) out->prior_sd[j] = out->sd[j] = j < 2 || j == 5 ? o.sigma_deg : o.sigma_mm;
    eimage_t *im = NULL;
    int nim = 0;
    pose_fit_t F = { .scene = scene, .cam = cal->cam, .W = cal->W, .H = cal->H };
    bool ok = angle_images(s, cal, &im, &nim);
    double R[9], t[3];
    calib_sample_pose_Rt(scene, nom, R, t);
    int cap = 0;
    for (int a = 0; ok && a < nim; a++) ok = outline_samples(scene, cal, R, t, im[a].deg, a, &F.s, &F.n, &cap);
    F.im = im;
    F.nim = nim;
    char why[sizeof out->note - 100];
    if (ok) {
        F.use = malloc((size_t)(F.n ? F.n : 1) * sizeof *F.use);
        F.pts = malloc((size_t)(F.n ? F.n : 1) * sizeof *F.pts);
        F.q = malloc((size_t)(F.n ? F.n : 1) * 2 * sizeof *F.q);
        if (!F.use || !F.pts || !F.q) {
            model_error_set(s->dir, 0, "out of memory");
            ok = false;
        }
    }
    if (ok) {
        if (nim == 0) snprintf(why, sizeof why, "no frame lit by one lamp");
        else fit_rounds(&F, out, o.min_samples > 0 ? o.min_samples : 60, o.verbose, why, sizeof why);
        if (why[0]) {
            snprintf(out->note, sizeof out->note, "%s: the nominal wedge pose is kept (tilt %g deg, hinge azimuth "
                     "%g deg)", why, nom[0], nom[1]);
            memcpy(out->p, nom, sizeof nom);
        } else {
            out->fitted = true;
            for (int j = 0; j < NPOSE; j++) {
                out->sd[j] = sqrt(fmax(out->cov[j * NPOSE + j], 0));
                if (fabs(out->p[j] - nom[j]) > 2.5 * out->prior_sd[j]) out->at_prior_edge = true;
            }
            if (out->at_prior_edge)
                snprintf(out->note, sizeof out->note, "the fitted pose is at the edge of the fixture's tolerance "
                         "(more than 2.5 std of the prior from the nominal): the sample is placed further off than "
                         "the prior allows, or its edges were mistaken; check the placement");
        }
    }
    double R2[9], t2[3];
    calib_sample_pose_Rt(scene, out->p, R2, t2);
    for (int r = 0; r < 3; r++) out->normal[r] = R2[3 * r + 2];
    for (int a = 0; a < nim; a++) free(im[a].img);
    free(im);
    free(F.s);
    free(F.use);
    free(F.pts);
    free(F.q);
    return ok;
}

void calib_sample_pose_print(FILE *f, const calib_sample_pose_t *ps)
{
    if (!ps->tried) {
        fprintf(f, "  sample pose: the plan's nominal wedge (tilt %g deg, hinge azimuth %g deg; not fitted)\n",
                ps->nominal[0], ps->nominal[1]);
        return;
    }
    if (!ps->fitted) {
        fprintf(f, "  sample pose: NOT FITTED: %s\n", ps->note);
        return;
    }
    fprintf(f, "  sample pose fitted from %d edge samples at %d angles (RMS %.3f px): tilt %.3f +- %.3f deg (%+.3f), "
            "hinge azimuth %.3f +- %.3f deg (%+.3f), offset %+.3f +- %.3f, %+.3f +- %.3f mm, height %+.3f +- %.3f mm, "
            "turn %+.3f +- %.3f deg (differences from the nominal)\n", ps->nsamples, ps->nangles, ps->rms_px,
            ps->p[0], ps->sd[0], ps->p[0] - ps->nominal[0], ps->p[1], ps->sd[1], ps->p[1] - ps->nominal[1], ps->p[2],
            ps->sd[2], ps->p[3], ps->sd[3], ps->p[4], ps->sd[4], ps->p[5], ps->sd[5]);
    if (ps->note[0]) fprintf(f, "  warning: sample pose: %s\n", ps->note);
}

json_t *calib_sample_pose_json(const calib_sample_pose_t *ps)
{
    json_t *j = json_object();
    json_object_set_new(j, "mode", json_string(!ps->tried ? "nominal" : ps->fitted ? "fit" : "nominal (fit failed)"));
    json_t *pa = json_array();
    for (int k = 0; k < NPOSE; k++) {
        json_t *e = json_object();
        json_object_set_new(e, "name", json_string(pose_names[k]));
        json_object_set_new(e, "nominal", json_real(ps->nominal[k]));
        json_object_set_new(e, "value", json_real(ps->p[k]));
        json_object_set_new(e, "std", ps->fitted ? json_real(ps->sd[k]) : json_null());
        json_object_set_new(e, "difference", json_real(ps->p[k] - ps->nominal[k]));
        json_object_set_new(e, "prior_std", ps->tried ? json_real(ps->prior_sd[k]) : json_null());
        json_array_append_new(pa, e);
    }
    json_object_set_new(j, "parameters", pa);
    json_object_set_new(j, "normal_at_0_deg", json_pack("[f, f, f]", ps->normal[0], ps->normal[1], ps->normal[2]));
    if (ps->tried) {
        json_object_set_new(j, "edge_samples", json_integer(ps->nsamples));
        json_object_set_new(j, "angles", json_integer(ps->nangles));
        json_object_set_new(j, "rms_px", ps->fitted ? json_real(ps->rms_px) : json_null());
    }
    json_object_set_new(j, "at_prior_edge", json_boolean(ps->at_prior_edge));
    json_object_set_new(j, "note", json_string(ps->note));
    json_object_set_new(j, "convention",
                        json_string("x = Rw (Rz(turn) (x0 - c) + c + (dx, dy, 0)) + tw + (0, 0, dz): x0 the sample's "
                                    "scene, c the middle of its bounding box in x and y, Rw and tw its wedge's pose "
                                    "of tilt_deg about the hinge at tilt_azimuth_deg; dx, dy in the wedge's face, dz "
                                    "along the rig's z; std from the fit's covariance (residuals scaled by their "
                                    "RMS), the nominal wedge pose the prior (prior_std)"));
    return j;
}
