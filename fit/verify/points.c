// fit/verify/points.c — the fit's reference points: each window measured (mean,
// spread, saturation, the offset's start), its sigma and its per-lamp model terms.
#define _GNU_SOURCE
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fit/verify/internal.h"

// An image's gain as a factor: verify_image_t.gain_db is in dB relative to the
// calibration (the readers convert a camera's own unit, model_gain_factor);
// fit_check checked it.
static double image_gain_factor(const verify_image_t *im)
{
    double gf = 1;
    model_gain_factor(im->gain_db, "dB", 0, "dB", im->name, &gf);
    return gf;
}

// Image m's reference points from first_pt on: the windows' means (after the
// offset map, linearised), their spread (in sigma for now) and mean flat
// field (in model for now), saturation. *Pa0: the offset's start (0 with the
// offset map; else the median of the background windows, or the darkest
// usable one); *var_px_fallback: without K, the pixel noise as the median
// window variance of the usable points. false: out of memory.
static bool measure_windows(fit_t *F, int m, int first_pt, double *Pa0, double *var_px_fallback)
{
    const verify_options_t *opt = F->opt;
    const verify_view_t *v = F->views[m];
    const verify_image_t *im = &F->imgs[m];
    const verify_camera_t *cm = &F->cams[im->camera];
    const int w = opt->window_px, n = v->gw * v->gh;
    const float *off = opt->use_flat ? cm->offset_dn : NULL, *flat = opt->use_flat ? cm->flat : NULL;
    double gf = image_gain_factor(im), Kg = cm->K_dn_per_e * gf;
    double sat = cm->saturation_dn > 0 ? cm->saturation_dn : INFINITY;
    bool owned;
    const wsum_t *ws = verify_window_sums(im, v, w, off, flat, &owned);
    double *tmp = malloc((size_t)n * sizeof *tmp);
    int nt = 0;
    if (!tmp || !ws) {
        free(tmp);
        if (owned) free((void *)ws);
        model_error(im->name, 0, "out of memory for %d reference points", n);
        return false;
    }
    for (int g = 0; g < n; g++) {
        verify_point_t *p = &F->out->points[first_pt + g];
        int gx = v->x0 + (g % v->gw) * v->sp, gy = v->y0 + (g / v->gw) * v->sp;
        p->image = m;
        p->q[0] = (float)gx;
        p->q[1] = (float)gy;
        p->face = v->pi[g].face;
        p->status = v->status[g];
        p->region = -1;
        double s1 = ws[g].s1, s2 = ws[g].s2, gs = ws[g].gs, mx = ws[g].mx;
        double N = (double)w * w, mean = s1 / N;
        if (cm->lin && off) {
            // linearise the window (mean and spread) with the gain calibration's linearisation
            double slope, lin = model_linearise(cm->lin, mean, gf, &slope);
            double var = fmax(s2 / N - mean * mean, 0) * slope * slope;
            mean = lin;
            s1 = mean * N;
            s2 = (var + mean * mean) * N;
        }
        p->meas = (float)mean;
        p->sigma = (float)sqrt(fmax(s2 / N - mean * mean, 0) * N / (N > 1 ? N - 1 : 1));   // window std for now
        p->model = (float)(gs / N);   // g for now
        if (p->status == VERIFY_PT_USED && mx >= sat - 0.5) p->status = VERIFY_PT_SATURATED;
        if (!off && p->status == VERIFY_PT_BACKGROUND) tmp[nt++] = mean;
    }
    *Pa0 = 0;
    if (!off) {
        if (nt >= 10) {
            *Pa0 = model_median(tmp, nt);
        } else {
            *Pa0 = INFINITY;
            for (int k = first_pt; k < first_pt + n; k++)
                if (F->out->points[k].status == VERIFY_PT_USED) *Pa0 = fmin(*Pa0, F->out->points[k].meas);
            if (!isfinite(*Pa0)) *Pa0 = 0;
        }
    }
    *var_px_fallback = 0;
    if (!(Kg > 0)) {
        nt = 0;
        for (int k = first_pt; k < first_pt + n; k++)
            if (F->out->points[k].status == VERIFY_PT_USED)
                tmp[nt++] = (double)F->out->points[k].sigma * F->out->points[k].sigma;
        *var_px_fallback = nt ? model_median(tmp, nt) : 1;
        if (!(*var_px_fallback > 0)) *var_px_fallback = 1;
    }
    free(tmp);
    if (owned) free((void *)ws);
    return true;
}

// A point's relative model error: its material's window spread (the priors'
// window_rel_std) unless model_rel is given or the priors state none; of two
// materials the larger.
static double point_model_rel(const fit_t *F, const pt_t *q)
{
    double rel = 0;
    for (int k = 0; k < 2; k++) {
        int mat = k ? q->mat2 : q->mat;
        if (mat < 0) continue;
        double wr = F->prior[mat]->window_rel;
        rel = fmax(rel, F->opt->model_rel_given || !isfinite(wr) ? F->opt->model_rel : wr);
    }
    return rel;
}

// The terms of grid point g of image m's window near an edge (its parts,
// verify_footprint.h) from *e on, into q (mat, mat2, nl); *gx, *gy: the
// model's slope per unit E g across the window's centre (per px) at the
// priors' means (kc = s = 1; the direct light); *bsd += its interreflection
// basis's Monte Carlo error per unit E g. false (nothing written) when the
// window sees more than two materials.
static bool footprint_terms(fit_t *F, int m, int g, pt_t *q, size_t *e, double *gx, double *gy, double *bsd)
{
    const verify_view_t *v = F->views[m];
    const verify_image_t *im = &F->imgs[m];
    const verify_footprints_t *fp = &v->fp;
    const int P0 = fp->first[g], np = fp->nparts[g], nl = fp->nl;
    int mat = fp->parts[P0].material, mat2 = -1;
    for (int j = 1; j < np; j++) {
        int mj = fp->parts[P0 + j].material;
        if (mj == mat || mj == mat2) continue;
        if (mat2 >= 0) return false;
        mat2 = mj;
    }
    q->mat = mat;
    q->mat2 = mat2;
    *gx = *gy = 0;
    for (int j = 0; j < np; j++) {
        const verify_part_t *P = &fp->parts[P0 + j];
        const float *wl = &fp->wl[(size_t)(P0 + j) * nl * 3];
        const float *B = &fp->B[(size_t)(P0 + j) * nl], *Bsd = &fp->Bsd[(size_t)(P0 + j) * nl];
        const int pm = P->material;
        const double *mp = &F->mp[pm * MODEL_BRDF_MAX_PARAMS];
        for (int i = 0; i < F->nl; i++) {
            if (!((im->lamps_on >> i) & 1)) continue;
            if (!(wl[3 * i] > 0) && !(B[i] > 0)) continue;
            model_vec3_t d = v3_sub(F->lamps->lamps[i].position_mm, P->p_mm);
            model_vec3_t l = v3_unit(d);
            model_cosines_t c = model_cosines(P->n, l, P->v);
            double em = model_lamp_emission(&F->lamps->lamps[i], P->p_mm);
            F->cs[*e] = model_brdf_prepare(&c);
            F->wv[*e] = F->A[i] * em * wl[3 * i];
            F->bv[*e] = F->A[i] * P->W * B[i];
            F->lampv[*e] = i;
            F->secv[*e] = mat2 >= 0 && pm == mat2;
            double R = model_brdf_eval(F->prior[pm]->model, mp, &c, NULL);
            *bsd += F->A[i] * P->W * Bsd[i];
            *gx += F->A[i] * em * wl[3 * i + 1] * R;
            *gy += F->A[i] * em * wl[3 * i + 2] * R;
            (*e)++;
            q->nl++;
        }
    }
    return true;
}

// Image m's usable points after measure_windows: the measured-edge test,
// sigma, and the fit's points with their per-lamp terms (from *e on).
static void image_fit_points(fit_t *F, int m, int first_pt, double Pa0, double var_px_fallback, size_t *e)
{
    const verify_options_t *opt = F->opt;
    const verify_view_t *v = F->views[m];
    const verify_image_t *im = &F->imgs[m];
    const verify_camera_t *cm = &F->cams[im->camera];
    const int w = opt->window_px;
    double gf = image_gain_factor(im), Kg = cm->K_dn_per_e * gf;
    double E = im->exposure_us * gf * (cm->kc_rel > 0 ? cm->kc_rel : 1);   // the camera's own sensitivity
    for (int g = 0; g < v->gw * v->gh; g++) {
        int k = first_pt + g;
        verify_point_t *p = &F->out->points[k];
        if (p->status != VERIFY_PT_USED) continue;
        double S = fmax(p->meas - Pa0, 0), wstd = p->sigma, gmean = p->model;
        double var_px = Kg > 0 ? Kg * S + Kg * Kg * cm->read_noise_e * cm->read_noise_e + 1.0 / 12
                               : var_px_fallback;
        bool foot = v->fp.first && v->fp.first[g] >= 0;
        double thr2 = opt->edge_k * opt->edge_k * var_px + (opt->edge_rel * S) * (opt->edge_rel * S);
        if (!foot && wstd * wstd > thr2) {   // (a window near an edge has its spread from the edge)
            p->status = VERIFY_PT_EDGE_MEASURED;
            p->z = (float)(opt->z_flag * wstd / sqrt(thr2));
        }
        double sig2 = var_px / ((double)w * w);
        // the fit's point (edge-measured ones are predicted too, not fitted)
        pt_t *q = &F->pt[F->nfit];
        q->meas = p->meas;
        q->Eg = E * gmean;
        q->mat = v->pi[g].material;
        q->mat2 = -1;
        q->first = (int)*e;
        q->nl = 0;
        q->r_last = q->rr_last = NAN;
        double bsd = 0;   // the interreflection basis's Monte Carlo error, per unit E g
        if (foot) {
            double gx, gy;
            if (!footprint_terms(F, m, g, q, e, &gx, &gy, &bsd)) {   // more than two materials in the window
                p->status = VERIFY_PT_NEAR_EDGE;
                continue;
            }
            p->footprint = true;
            // where the edge lies is known to edge_position_sigma_px: the model's slope across it
            double se = opt->edge_position_sigma_px * q->Eg * hypot(gx, gy);
            sig2 += se * se;
        } else {
            const model_lamp_sample_t *ls = &v->ls[(size_t)g * v->nl];
            for (int i = 0; i < F->nl; i++) {
                if (!((im->lamps_on >> i) & 1)) continue;
                model_cosines_t c = model_cosines(v->pi[g].n, ls[i].l, v->pi[g].v);
                F->cs[*e] = model_brdf_prepare(&c);
                // the lamp's emission pattern toward the point (exactly 1 for an isotropic lamp)
                F->wv[*e] = ls[i].d_mm > 0 ? F->A[i] * ls[i].V / (ls[i].d_mm * ls[i].d_mm) *
                                                 model_lamp_emission(&F->lamps->lamps[i], v->pi[g].p_mm)
                                           : 0;
                F->bv[*e] = F->A[i] * v->B[(size_t)g * v->nl + i];
                F->lampv[*e] = i;
                F->secv[*e] = 0;
                bsd += F->A[i] * v->Bsd[(size_t)g * v->nl + i];
                (*e)++;
                q->nl++;
            }
        }
        // what the model lacks: the material's window spread (its priors' window_rel_std, else model_rel;
        // a window of two materials the larger), and the interreflection basis's Monte Carlo error
        double rel = point_model_rel(F, q);
        double sb = opt->ir_samples > 0 ? q->Eg * bsd : 0;
        sig2 += (rel * S) * (rel * S) + sb * sb;
        q->sigma = sqrt(sig2);
        p->sigma = (float)q->sigma;
        p->model = 0;
        F->ptidx[F->nfit] = k;
        F->nfit++;
    }
}

// Every image's reference points and windows. false + message: out of memory.
bool verify_fit_measure(fit_t *F)
{
    int np = 0;
    size_t e = 0;
    for (int m = 0; m < F->nimgs; m++) {
        double Pa0, var_px_fallback;
        if (!measure_windows(F, m, np, &Pa0, &var_px_fallback)) return false;
        F->out->Pa[m] = Pa0;
        image_fit_points(F, m, np, Pa0, var_px_fallback, &e);
        np += F->views[m]->gw * F->views[m]->gh;
    }
    return true;
}
