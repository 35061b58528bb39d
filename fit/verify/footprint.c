// fit/verify/footprint.c — reference windows near edges with the pixels'
// footprint and the camera's blur (see verify_footprint.h).
#define _GNU_SOURCE
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "fit/verify/verify.h"
#include "fit/verify/footprint.h"
#include "model/base/vec.h"

#define FP_MAX_LAMPS 32
#define FP_MAX_PARTS 8

// The antiderivative of Phi(t / sigma) in t (sigma 0: of the unit step).
static double phi_int(double t, double sigma)
{
    if (!(sigma > 0)) return t > 0 ? t : 0;
    double z = t / sigma;
    return t * 0.5 * erfc(-z / M_SQRT2) + sigma * exp(-0.5 * z * z) / sqrt(2 * M_PI);
}

// One pixel's response across u (px from its centre): its footprint (a box of
// fill px; 0: a point) convolved with the Gaussian blur of sigma. P: its
// integral from -infinity to t; p: its value (a point without blur: 0 but at 0).
static double pixel_cdf(double t, double fill, double sigma)
{
    if (fill > 0) return (phi_int(t + 0.5 * fill, sigma) - phi_int(t - 0.5 * fill, sigma)) / fill;
    if (sigma > 0) return 0.5 * erfc(-t / (sigma * M_SQRT2));
    return t > 0 ? 1 : t < 0 ? 0 : 0.5;
}

static double pixel_pdf(double t, double fill, double sigma)
{
    if (fill > 0) {
        if (!(sigma > 0)) return fabs(t) < 0.5 * fill ? 1 / fill : fabs(t) == 0.5 * fill ? 0.5 / fill : 0;
        return 0.5 * (erfc(-(t + 0.5 * fill) / (sigma * M_SQRT2)) - erfc(-(t - 0.5 * fill) / (sigma * M_SQRT2))) / fill;
    }
    if (sigma > 0) return exp(-0.5 * t * t / (sigma * sigma)) / (sigma * sqrt(2 * M_PI));
    return 0;
}

double verify_kernel_integral(double a, double b, int w, double fill, double sigma_px)
{
    double s = 0;
    for (int j = -(w / 2); j <= w / 2; j++) s += pixel_cdf(b - j, fill, sigma_px) - pixel_cdf(a - j, fill, sigma_px);
    return s / w;
}

double verify_kernel_value(double u, int w, double fill, double sigma_px)
{
    double s = 0;
    for (int j = -(w / 2); j <= w / 2; j++) s += pixel_pdf(u - j, fill, sigma_px);
    return s / w;
}

void verify_footprints_free(verify_footprints_t *f)
{
    if (!f) return;
    free(f->first);
    free(f->nparts);
    free(f->parts);
    free(f->wl);
    free(f->B);
    free(f->Bsd);
    memset(f, 0, sizeof *f);
}

// The share of lamp L's disc (its sphere seen from p) that p on a face of
// normal nrm sees: FP_DISC stratified points of the disc facing p.
#define FP_DISC 8
static double disc_visible(const model_tracer_t *t, const model_lamp_t *L, model_vec3_t p, model_vec3_t nrm)
{
    model_vec3_t d = v3_sub(L->position_mm, p);
    double dd = v3_norm(d);
    if (!(dd > L->radius_mm)) return 1;
    model_vec3_t l = v3_scale(d, 1 / dd), a, b;
    frame_of(l, &a, &b);
    int seen = 0;
    for (int k = 0; k < FP_DISC; k++) {
        double r = L->radius_mm * sqrt((k + 0.5) / FP_DISC), th = 2.399963229728653 * k;   // the golden angle
        model_vec3_t x = v3_add(L->position_mm, v3_add(v3_scale(a, r * cos(th)), v3_scale(b, r * sin(th))));
        if (v3_dot(v3_sub(x, p), nrm) > 0 && model_tracer_visible_from(t, p, nrm, x)) seen++;
    }
    return (double)seen / FP_DISC;
}

// One sample of a window: where it hits, what it sees of each lamp, its
// weights (K's integral over its cell and that integral's derivatives in the
// window's centre).
typedef struct {
    int32_t      face, material;
    const float *V;            // nl: the share of each lamp seen
    model_vec3_t p, n, v;
    double       w, wx, wy;
} fp_sample_t;

// A window's accumulating parts.
typedef struct {
    int            n;
    verify_part_t  part[FP_MAX_PARTS];
    double         W[FP_MAX_PARTS];
    model_vec3_t   P[FP_MAX_PARTS], V[FP_MAX_PARTS], P1[FP_MAX_PARTS], V1[FP_MAX_PARTS];   // weighted, plain sums
    int            ns[FP_MAX_PARTS];
    double         wl[FP_MAX_PARTS][FP_MAX_LAMPS][3];
    double         bg, total;
    bool           overflow;
} fp_acc_t;

static void acc_add(fp_acc_t *A, const fp_sample_t *s, const model_lamps_t *lamps)
{
    if (s->w == 0 && s->wx == 0 && s->wy == 0) return;   // beyond the kernel
    A->total += s->w;
    if (s->face < 0) {
        A->bg += s->w;
        return;
    }
    int k;
    for (k = 0; k < A->n; k++)
        if (A->part[k].face == s->face) break;
    if (k == A->n) {
        if (A->n == FP_MAX_PARTS) {
            A->overflow = true;
            return;
        }
        memset(&A->part[k], 0, sizeof A->part[k]);
        A->part[k].face = s->face;
        A->part[k].material = s->material;
        A->part[k].n = s->n;
        A->W[k] = 0;
        A->P[k] = A->V[k] = A->P1[k] = A->V1[k] = v3(0, 0, 0);
        A->ns[k] = 0;
        memset(A->wl[k], 0, sizeof A->wl[k]);
        A->n++;
    }
    A->W[k] += s->w;
    A->P[k] = v3_add(A->P[k], v3_scale(s->p, s->w));
    A->V[k] = v3_add(A->V[k], v3_scale(s->v, s->w));
    A->P1[k] = v3_add(A->P1[k], s->p);
    A->V1[k] = v3_add(A->V1[k], s->v);
    A->ns[k]++;
    for (int i = 0; i < lamps->n && i < FP_MAX_LAMPS; i++) {
        if (!(s->V[i] > 0)) continue;
        model_vec3_t d = v3_sub(lamps->lamps[i].position_mm, s->p);
        double inv = s->V[i] / v3_dot(d, d);
        A->wl[k][i][0] += s->w * inv;
        A->wl[k][i][1] += s->wx * inv;
        A->wl[k][i][2] += s->wy * inv;
    }
}

typedef struct {
    const model_tracer_t *t;
    const model_camera_t *cam;
    const model_lamps_t  *lamps;
    const double         *q;
    const int            *cand;        // candidate grid points
    int                   w, A, ss, nl;
    const double         *kx, *dkx;    // 2A+1 cells: K's 1-D integral over cell a and its derivative
    const double         *ksub, *dksub;   // (2A+1) x ss: over sub-cell s of cell a
    fp_acc_t             *acc;         // per candidate
    long                  rays;
    int                   failed;      // a worker could not allocate its buffers (set atomically)
} fp_ctx_t;

// pixel_info of n sub-pixel positions q, one thread (the camera's ray table).
static void fp_trace(const fp_ctx_t *c, const double *q, int n, model_pixel_info_t *pi, model_lamp_sample_t *ls)
{
    model_pixel_info_table(c->t, (model_camera_t *)c->cam, c->lamps, q, n, pi, ls, 1);
}

// Each lamp's share seen from n traced samples (pi, ls): the centre ray's
// visibility, or for a finite lamp whose shadow changes among them (soft[i])
// the disc's share (disc_visible). V: n x nl.
static void samples_visibility(const fp_ctx_t *c, const model_pixel_info_t *pi, const model_lamp_sample_t *ls, int n,
                               const bool *soft, float *V)
{
    const int nl = c->nl;
    for (int m = 0; m < n; m++)
        for (int i = 0; i < nl; i++) {
            double v = pi[m].face >= 0 ? ls[(size_t)m * nl + i].V : 0;
            if (soft[i] && pi[m].face >= 0 && v3_dot(v3_sub(c->lamps->lamps[i].position_mm, pi[m].p_mm), pi[m].n) > 0)
                v = disc_visible(c->t, &c->lamps->lamps[i], pi[m].p_mm, pi[m].n);
            V[(size_t)m * nl + i] = (float)v;
        }
}

// The candidates [begin, end): trace the lattice's nodes, refine the cells
// that see two faces (or a point lamp's shadow edge), accumulate the parts. A
// finite lamp's shadow is soft: where it changes within a window every sample
// takes the disc's share it sees, and a cell of one face takes the mean of its
// corners' (the share varies smoothly across the penumbra).
static void fp_rows(void *vctx, int begin, int end, int thread)
{
    (void)thread;
    fp_ctx_t *c = vctx;
    const int A = c->A, nn = 2 * A + 2, nc = 2 * A + 1, ss = c->ss, nl = c->nl, nl1 = nl ? nl : 1;
    const int nnode = nn * nn;
    double *qn = malloc((size_t)nnode * 2 * sizeof *qn);
    model_pixel_info_t *pn = malloc((size_t)nnode * sizeof *pn);
    model_lamp_sample_t *ln = malloc((size_t)nnode * nl1 * sizeof *ln);
    float *vn = malloc((size_t)nnode * nl1 * sizeof *vn);
    double *qs = malloc((size_t)ss * ss * 2 * sizeof *qs);
    model_pixel_info_t *ps = malloc((size_t)ss * ss * sizeof *ps);
    model_lamp_sample_t *lsb = malloc((size_t)ss * ss * nl1 * sizeof *lsb);
    float *vs = malloc((size_t)ss * ss * nl1 * sizeof *vs);
    if (!qn || !pn || !ln || !vn || !qs || !ps || !lsb || !vs) {
        __atomic_store_n(&c->failed, 1, __ATOMIC_RELAXED);
        goto done;
    }
    for (int k = begin; k < end; k++) {
        int g = c->cand[k];
        double cx = c->q[2 * g], cy = c->q[2 * g + 1];
        fp_acc_t *acc = &c->acc[k];
        memset(acc, 0, sizeof *acc);
        for (int j = 0; j < nn; j++)
            for (int i = 0; i < nn; i++) {
                qn[2 * (j * nn + i)] = cx - A - 0.5 + i;
                qn[2 * (j * nn + i) + 1] = cy - A - 0.5 + j;
            }
        fp_trace(c, qn, nnode, pn, ln);
        long rays = nnode;
        // the finite lamps whose shadow changes within the window
        bool soft[FP_MAX_LAMPS] = { false };
        for (int i = 0; i < nl; i++) {
            if (!(c->lamps->lamps[i].radius_mm > 0)) continue;
            int lit = -1;
            for (int m = 0; m < nnode && !soft[i]; m++) {
                if (pn[m].face < 0) continue;
                int l = ln[(size_t)m * nl + i].V > 0.5;
                if (lit < 0) lit = l;
                else if (l != lit) soft[i] = true;
            }
        }
        samples_visibility(c, pn, ln, nnode, soft, vn);
        for (int b = 0; b < nc; b++)
            for (int a = 0; a < nc; a++) {
                int n00 = b * nn + a, n10 = n00 + 1, n01 = n00 + nn, n11 = n01 + 1;
                const int corner[4] = { n00, n10, n01, n11 };
                int f = pn[n00].face;
                bool uniform = pn[n10].face == f && pn[n01].face == f && pn[n11].face == f;
                for (int i = 0; i < nl && uniform && f >= 0; i++)
                    if (!soft[i])   // a point lamp's (or a hard) shadow edge: the cell is cut
                        for (int t = 1; t < 4; t++)
                            if (vn[(size_t)corner[t] * nl + i] != vn[(size_t)n00 * nl + i]) uniform = false;
                if (uniform) {
                    float V[FP_MAX_LAMPS];
                    for (int i = 0; i < nl; i++)
                        V[i] = 0.25f * (vn[(size_t)n00 * nl + i] + vn[(size_t)n10 * nl + i] + vn[(size_t)n01 * nl + i] +
                                        vn[(size_t)n11 * nl + i]);
                    fp_sample_t s = { .face = f, .material = pn[n00].material, .V = V,
                                      .w = c->kx[a] * c->kx[b], .wx = c->dkx[a] * c->kx[b],
                                      .wy = c->kx[a] * c->dkx[b] };
                    if (f >= 0) {
                        s.p = v3_scale(v3_add(v3_add(pn[n00].p_mm, pn[n10].p_mm), v3_add(pn[n01].p_mm, pn[n11].p_mm)),
                                       0.25);
                        s.n = pn[n00].n;
                        s.v = v3_unit(v3_add(v3_add(pn[n00].v, pn[n10].v), v3_add(pn[n01].v, pn[n11].v)));
                    }
                    acc_add(acc, &s, c->lamps);
                    continue;
                }
                // a mixed cell: ss x ss sub-cells, each the face its centre sees
                for (int sj = 0; sj < ss; sj++)
                    for (int si = 0; si < ss; si++) {
                        qs[2 * (sj * ss + si)] = cx + (a - A) - 0.5 + (si + 0.5) / ss;
                        qs[2 * (sj * ss + si) + 1] = cy + (b - A) - 0.5 + (sj + 0.5) / ss;
                    }
                fp_trace(c, qs, ss * ss, ps, lsb);
                rays += ss * ss;
                samples_visibility(c, ps, lsb, ss * ss, soft, vs);
                for (int sj = 0; sj < ss; sj++)
                    for (int si = 0; si < ss; si++) {
                        int m = sj * ss + si;
                        double ux = c->ksub[a * ss + si], uy = c->ksub[b * ss + sj];
                        fp_sample_t s = { .face = ps[m].face, .material = ps[m].material, .V = &vs[(size_t)m * nl],
                                          .p = ps[m].p_mm, .n = ps[m].n, .v = ps[m].v, .w = ux * uy,
                                          .wx = c->dksub[a * ss + si] * uy, .wy = ux * c->dksub[b * ss + sj] };
                        acc_add(acc, &s, c->lamps);
                    }
            }
        __atomic_add_fetch(&c->rays, rays, __ATOMIC_RELAXED);
    }
done:
    free(qn);
    free(pn);
    free(ln);
    free(vn);
    free(qs);
    free(ps);
    free(lsb);
    free(vs);
}

bool verify_footprints_make(const model_tracer_t *t, const model_camera_t *cam, const model_lamps_t *lamps,
                            const model_material_t *const *mats, const double *q, const bool *want, int n,
                            int window_px, double fill, double sigma_px, int ss, int ir_samples, int threads,
                            verify_footprints_t *out)
{
    memset(out, 0, sizeof *out);
    const int nl = lamps->n;
    if (nl > FP_MAX_LAMPS) {
        model_error(lamps->path, 0, "%d lamps: the windows near edges handle at most %d", nl, FP_MAX_LAMPS);
        return false;
    }
    if (ss < 1) ss = 1;
    if (ss % 2 == 0) ss++;   // odd: a pixel's centre is a sub-cell's centre (a point footprint samples it exactly)
    if (!(sigma_px >= 0) || sigma_px > 10 || !(fill >= 0) || fill > 1) {
        model_error(NULL, 0, "verify: a blur sigma of %g px (0..10 px) or a pixel fill of %g (0..1)", sigma_px, fill);
        return false;
    }
    out->npoints = n;
    out->nl = nl;
    out->ss = ss;
    out->sigma_px = sigma_px;
    out->fill = fill;
    out->background_max = 0.01;
    out->first = malloc((size_t)(n ? n : 1) * sizeof *out->first);
    out->nparts = calloc((size_t)(n ? n : 1), 1);
    int ncand = 0;
    for (int g = 0; g < n; g++) ncand += want[g];
    // the kernel's support: the outer pixels' centres, their footprint and 3 sigma of the blur
    const double R = window_px / 2 + 0.5 * fill + 3 * sigma_px;
    const int A = (int)ceil(R - 0.5), nc = 2 * A + 1;
    int *cand = malloc((size_t)(ncand ? ncand : 1) * sizeof *cand);
    fp_acc_t *acc = malloc((size_t)(ncand ? ncand : 1) * sizeof *acc);
    double *kx = malloc((size_t)nc * sizeof *kx), *dkx = malloc((size_t)nc * sizeof *dkx);
    double *ksub = malloc((size_t)nc * ss * sizeof *ksub), *dksub = malloc((size_t)nc * ss * sizeof *dksub);
    bool ok = out->first && out->nparts && cand && acc && kx && dkx && ksub && dksub;
    if (!ok) model_error(NULL, 0, "out of memory for %d windows near edges", ncand);
    for (int a = 0; ok && a < nc; a++) {
        double lo = a - A - 0.5, hi = lo + 1;
        kx[a] = verify_kernel_integral(lo, hi, window_px, fill, sigma_px);
        // d/dc of the integral over [lo - c, hi - c] at c = 0, of the kernel with whole pixels (a point
        // footprint's window changes by steps: its slope is taken over a pixel's width)
        dkx[a] = verify_kernel_value(lo, window_px, 1, sigma_px) - verify_kernel_value(hi, window_px, 1, sigma_px);
        for (int s = 0; s < ss; s++) {
            double sl = lo + (double)s / ss, sh = lo + (double)(s + 1) / ss;
            ksub[a * ss + s] = verify_kernel_integral(sl, sh, window_px, fill, sigma_px);
            dksub[a * ss + s] =
                verify_kernel_value(sl, window_px, 1, sigma_px) - verify_kernel_value(sh, window_px, 1, sigma_px);
        }
    }
    if (ok) {
        ncand = 0;
        for (int g = 0; g < n; g++) {
            out->first[g] = -1;
            if (want[g]) cand[ncand++] = g;
        }
        const model_vec3_t *rays = model_camera_ray_table((model_camera_t *)cam, NULL);   // made once, kept
        if (!rays) {
            ok = false;
            goto out;
        }
        fp_ctx_t fc = { .t = t, .cam = cam, .lamps = lamps, .q = q, .cand = cand, .w = window_px, .A = A,
                        .ss = ss, .nl = nl, .kx = kx, .dkx = dkx, .ksub = ksub,
                        .dksub = dksub, .acc = acc };
        model_parallel_for(ncand, 8, threads > 0 ? threads : model_default_threads(), fp_rows, &fc);
        if (fc.failed) {
            model_error(NULL, 0, "out of memory for the windows near edges");
            ok = false;
            goto out;
        }
        out->samples = fc.rays;
        int np = 0;
        for (int k = 0; k < ncand; k++)
            if (!acc[k].overflow && acc[k].total > 0 && acc[k].bg <= out->background_max * acc[k].total)
                np += acc[k].n;
        out->parts = malloc((size_t)(np ? np : 1) * sizeof *out->parts);
        out->wl = calloc((size_t)(np ? np : 1) * (nl ? nl : 1) * 3, sizeof *out->wl);
        out->B = calloc((size_t)(np ? np : 1) * (nl ? nl : 1), sizeof *out->B);
        out->Bsd = calloc((size_t)(np ? np : 1) * (nl ? nl : 1), sizeof *out->Bsd);
        model_pixel_info_t *pi = malloc((size_t)(np ? np : 1) * sizeof *pi);
        ok = out->parts && out->wl && out->B && out->Bsd && pi;
        if (!ok) model_error(NULL, 0, "out of memory for %d window parts", np);
        int p = 0;
        for (int k = 0; ok && k < ncand; k++) {
            fp_acc_t *a = &acc[k];
            if (a->overflow || !(a->total > 0) || a->bg > out->background_max * a->total) continue;
            int g = cand[k];
            out->first[g] = p;
            out->nparts[g] = (uint8_t)a->n;
            double norm = 1 / (a->total - a->bg);   // the kernel's sum over the surfaces: 1 (its tails are cut)
            for (int j = 0; j < a->n; j++, p++) {
                verify_part_t *P = &out->parts[p];
                *P = a->part[j];
                P->W = (float)(a->W[j] * norm);
                // (a part the kernel gives no weight, only a slope: its samples' plain mean)
                P->p_mm = a->W[j] > 0 ? v3_scale(a->P[j], 1 / a->W[j]) : v3_scale(a->P1[j], 1.0 / a->ns[j]);
                P->v = v3_unit(a->W[j] > 0 ? a->V[j] : a->V1[j]);
                for (int i = 0; i < nl; i++)
                    for (int d = 0; d < 3; d++) out->wl[((size_t)p * nl + i) * 3 + d] = (float)(a->wl[j][i][d] * norm);
                pi[p] = (model_pixel_info_t){ .q = { q[2 * g], q[2 * g + 1] }, .face = P->face,
                                              .material = P->material, .p_mm = P->p_mm, .n = P->n, .v = P->v };
            }
        }
        out->nparts_all = p;
        if (ok && ir_samples > 0 && p && nl)
            verify_interreflection_sd(t, lamps, mats, pi, p, ir_samples, threads, out->B, out->Bsd);
        free(pi);
    }
out:
    free(cand);
    free(acc);
    free(kx);
    free(dkx);
    free(ksub);
    free(dksub);
    if (!ok) verify_footprints_free(out);
    return ok;
}
