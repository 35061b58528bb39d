// fit/brdf/sample_set.c — a set of BRDF samples (fit_samples_t): adding samples
// (with their lamps' discs), the model's R over them and its RMS error.
#define _GNU_SOURCE
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fit/brdf/brdf.h"
#include "model/base/vec.h"

fit_samples_t *fit_samples_new(void)
{
    return calloc(1, sizeof(fit_samples_t));
}

void fit_samples_free(fit_samples_t *s)
{
    if (!s) return;
    free(s->c);
    free(s->R);
    free(s->w);
    free(s->disc_at);
    free(s->disc);
    free(s);
}

bool fit_samples_add(fit_samples_t *s, const model_cosines_t *c, double R, double weight)
{
    if (!(c->nl > 0) || !(c->nv > 0) || !isfinite(R) || !isfinite(weight) || !(weight > 0)) return false;
    if (s->n == s->cap) {
        int cap = s->cap ? 2 * s->cap : 1024;
        model_cosines_t *nc = realloc(s->c, (size_t)cap * sizeof *nc);
        if (nc) s->c = nc;
        double *nR = realloc(s->R, (size_t)cap * sizeof *nR);
        if (nR) s->R = nR;
        double *nw = realloc(s->w, (size_t)cap * sizeof *nw);
        if (nw) s->w = nw;
        if (!nc || !nR || !nw) return false;
        s->cap = cap;
    }
    if (s->disc_at && s->n >= s->disc_cap) {
        int *na = realloc(s->disc_at, (size_t)s->cap * sizeof *na);
        if (!na) return false;
        s->disc_at = na;
        for (int i = s->disc_cap; i < s->cap; i++) s->disc_at[i] = -1;
        s->disc_cap = s->cap;
    }
    s->c[s->n] = *c;
    s->R[s->n] = R;
    s->w[s->n] = weight;
    if (s->disc_at) s->disc_at[s->n] = -1;
    s->n++;
    return true;
}

bool fit_samples_add_disc(fit_samples_t *s, const model_cosines_t *c, const model_cosines_t *disc, double R,
                          double weight)
{
    if (!disc) return fit_samples_add(s, c, R, weight);
    if (!s->disc_at) {   // the first finite lamp: every earlier sample is a point lamp's
        int cap = s->cap > s->n ? s->cap : s->n + 1;
        if (!(s->disc_at = malloc((size_t)cap * sizeof *s->disc_at))) return false;
        for (int i = 0; i < cap; i++) s->disc_at[i] = -1;
        s->disc_cap = cap;
    }
    if (s->ndisc + 4 > s->disc_alloc) {
        int cap = s->disc_alloc ? 2 * s->disc_alloc : 4096;
        model_cosines_t *nd = realloc(s->disc, (size_t)cap * sizeof *nd);
        if (!nd) return false;
        s->disc = nd;
        s->disc_alloc = cap;
    }
    if (!fit_samples_add(s, c, R, weight)) return false;
    memcpy(s->disc + s->ndisc, disc, 4 * sizeof *disc);
    s->disc_at[s->n - 1] = s->ndisc;
    s->ndisc += 4;
    return true;
}

void fit_samples_eval_n(const fit_samples_t *s, model_brdf_t m, const double *p, int off, int cnt, double *R,
                        double *dR)
{
    model_brdf_eval_n(m, p, s->c + off, cnt, R, dR);
    if (!s->disc_at) return;
    int np = model_brdf_nparams(m);
    for (int k = 0; k < cnt; k++) {
        int at = s->disc_at[off + k];
        if (at < 0) continue;
        double r4[4], j4[4 * MODEL_BRDF_MAX_PARAMS];
        model_brdf_eval_n(m, p, s->disc + at, 4, r4, dR ? j4 : NULL);
        R[k] = 0.25 * (r4[0] + r4[1] + r4[2] + r4[3]);
        if (dR)
            for (int j = 0; j < np; j++)
                dR[k * np + j] = 0.25 * (j4[j] + j4[np + j] + j4[2 * np + j] + j4[3 * np + j]);
    }
}

double fit_samples_rms(const fit_samples_t *s, model_brdf_t m, const double *p)
{
    double sw = 0, ss = 0, Rb[256];
    for (int i0 = 0; i0 < s->n; i0 += 256) {
        int cnt = s->n - i0 < 256 ? s->n - i0 : 256;
        fit_samples_eval_n(s, m, p, i0, cnt, Rb, NULL);
        for (int k = 0; k < cnt; k++) {
            double e = Rb[k] - s->R[i0 + k];
            sw += s->w[i0 + k];
            ss += s->w[i0 + k] * e * e;
        }
    }
    return sw > 0 ? sqrt(ss / sw) : NAN;
}

double fit_samples_rms_of_cov(const fit_samples_t *s, model_brdf_t m, const double *p, const double *C)
{
    int np = model_brdf_nparams(m);
    for (int a = 0; a < np * np; a++)
        if (!isfinite(C[a])) return NAN;
    double sw = 0, tr = 0, Rb[256], Jb[256 * MODEL_BRDF_MAX_PARAMS];
    for (int i0 = 0; i0 < s->n; i0 += 256) {
        int cnt = s->n - i0 < 256 ? s->n - i0 : 256;
        fit_samples_eval_n(s, m, p, i0, cnt, Rb, Jb);
        for (int k = 0; k < cnt; k++) {
            const double *J = Jb + k * np;
            double q = 0;   // J^T C J
            for (int a = 0; a < np; a++)
                for (int b = 0; b < np; b++) q += J[a] * C[a * np + b] * J[b];
            sw += s->w[i0 + k];
            tr += s->w[i0 + k] * q;
        }
    }
    return sw > 0 ? sqrt(fmax(tr, 0) / sw) : NAN;
}

double fit_samples_eval(const fit_samples_t *s, model_brdf_t m, const double *p, int i)
{
    double r;
    fit_samples_eval_n(s, m, p, i, 1, &r, NULL);
    return r;
}

static model_vec3_t dir_of(double theta, double phi)
{
    return v3(sin(theta) * cos(phi), sin(theta) * sin(phi), cos(theta));
}

bool fit_samples_add_angles(fit_samples_t *s, double theta_i, double phi_i, double theta_o, double phi_o, double f_r,
                            double weight)
{
    model_cosines_t c = model_cosines(v3(0, 0, 1), dir_of(theta_i, phi_i), dir_of(theta_o, phi_o));
    return fit_samples_add(s, &c, f_r * c.nl, weight);
}
