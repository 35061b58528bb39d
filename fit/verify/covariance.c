// fit/verify/covariance.c — the fitted parameters' standard deviations: (J^T J +
// priors)^-1 over the free parameters at the solution.
#define _GNU_SOURCE
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fit/verify/internal.h"

// Add residual group g's J^T J to JtJ (nf x nf; col: parameter -> column or -1).
static bool covariance_add_group(const fit_t *F, const res_group_t *g, const int *col, int nf, double *jb,
                                 double *JtJ)
{
    const pdesc_t *pd = F->pd;
    const verify_point_t *p = &F->out->points[F->ptidx[g->k[0]]];
    int mat = F->pt[g->k[0]].mat, mat2 = F->pt[g->k[0]].mat2;
    double *blocks[6], rbuf[64];
    const int nb = verify_fit_blocks(F, p->image, mat, mat2, blocks);
    const int size[6] = { 1, F->nl ? F->nl : 1, 1, F->rcs[mat].np, 1, mat2 >= 0 ? F->rcs[mat2].np : 0 };
    double *jac[6] = { NULL };
    int off = 0, gcol[6][MAX_LAMPS];
    for (int b = 0; b < nb; b++) {
        jac[b] = jb + (size_t)off * 64;
        off += size[b];
        for (int q = 0; q < size[b]; q++) {
            gcol[b][q] = -1;
            for (int k = 0; k < F->npd; k++)
                if (pd[k].x == blocks[b] && pd[k].i == q) gcol[b][q] = col[k];
        }
    }
    if (!verify_group_fn((void *)g, (const double *const *)blocks, rbuf, jac)) return false;
    for (int t = 0; t < g->n; t++) {
        double row[64];
        int rc_[64], nr = 0;
        for (int b = 0; b < nb; b++)
            for (int q = 0; q < size[b]; q++)
                if (gcol[b][q] >= 0 && nr < 64) {
                    row[nr] = jac[b][(size_t)t * size[b] + q];
                    rc_[nr++] = gcol[b][q];
                }
        for (int u = 0; u < nr; u++)
            for (int v2 = 0; v2 < nr; v2++) JtJ[(size_t)rc_[u] * nf + rc_[v2]] += row[u] * row[v2];
    }
    return true;
}

// The parameters' standard deviations: (J^T J + priors)^-1 over the free
// parameters at the solution, J of the loss-scaled residuals (as Ceres's).
// They stay NAN when it cannot be had; false + message: out of memory.
bool verify_fit_covariance(fit_t *F)
{
    const int npd = F->npd, nl = F->nl;
    const pdesc_t *pd = F->pd;
    int nf = 0, *col = malloc((size_t)npd * sizeof *col);
    for (int k = 0; col && k < npd; k++) col[k] = pd[k].fixed ? -1 : nf++;
    double *JtJ = calloc((size_t)nf * nf + 1, sizeof *JtJ), *inv = calloc((size_t)nf * nf + 1, sizeof *inv);
    double *ev = malloc(((size_t)nf + 1) * sizeof *ev);
    double *jb = malloc((size_t)64 * (3 + nl + 2 * MODEL_BRDF_MAX_PARAMS) * sizeof *jb);
    bool mem = col && JtJ && inv && ev && jb, cok = mem && nf > 0;
    for (int gi = 0; gi < F->ngroups && cok; gi++) cok = covariance_add_group(F, &F->groups[gi], col, nf, jb, JtJ);
    for (int k = 0; k < npd && cok; k++)
        if (col[k] >= 0 && pd[k].prior_std > 0 && !pd[k].mv)
            JtJ[(size_t)col[k] * nf + col[k]] += 1 / (pd[k].prior_std * pd[k].prior_std);
    for (int m = 0; m < F->nm && cok; m++) {   // multivariate priors: Sigma_S^-1 = L^-T L^-1
        const verify_mvprior_t *v = &F->mvp[m];
        for (int a = 0; a < v->n; a++)
            for (int b = 0; b < v->n; b++) {
                int ca = col[F->mvp_pd[m] + v->idx[a]], cb = col[F->mvp_pd[m] + v->idx[b]];
                double s = 0;
                for (int r = 0; r < v->n; r++) s += v->Linv[r * v->n + a] * v->Linv[r * v->n + b];
                if (ca >= 0 && cb >= 0) JtJ[(size_t)ca * nf + cb] += s;
            }
    }
    for (int c = 0; c < nf && cok; c++) {
        double *A2 = malloc((size_t)nf * nf * sizeof *A2);
        if (!A2) {
            cok = mem = false;
            break;
        }
        memcpy(A2, JtJ, (size_t)nf * nf * sizeof *A2);
        for (int q = 0; q < nf; q++) ev[q] = q == c;
        cok = model_solve_linear(A2, ev, nf);
        free(A2);
        for (int q = 0; q < nf && cok; q++) inv[(size_t)q * nf + c] = ev[q];
    }
    if (cok)
        for (int k = 0; k < npd; k++)
            if (col[k] >= 0) F->out->params[k].std = sqrt(fmax(inv[(size_t)col[k] * nf + col[k]], 0));
    free(col);
    free(JtJ);
    free(inv);
    free(ev);
    free(jb);
    if (!mem) model_error(NULL, 0, "out of memory for the covariance of %d parameters", nf);
    return mem;
}
