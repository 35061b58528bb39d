// fit/verify/views.c — a view: the geometry of one image under a description (the
// reference-point grid with pixel_info, lamp samples, skip reasons, the windows
// near edges and the interreflection basis).
#define _GNU_SOURCE
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fit/verify/internal.h"

int    verify_view_npoints(const verify_view_t *v) { return v ? v->nusable : 0; }
double verify_view_time_s(const verify_view_t *v) { return v ? v->time_s : 0; }

void verify_view_free(verify_view_t *v)
{
    if (!v) return;
    model_tracer_free(v->t);
    model_scene_free(v->rot);
    free(v->pi);
    free(v->ls);
    free(v->status);
    free(v->B);
    free(v->Bsd);
    verify_footprints_free(&v->fp);
    free(v);
}

static uint32_t lit_bits(const model_lamp_sample_t *ls, int nl)
{
    uint32_t b = 0;
    for (int i = 0; i < nl; i++)
        if (ls[i].V > 0.5) b |= 1u << i;
    return b;
}

static double seg_dist(double px, double py, const double a[2], const double b[2])
{
    double dx = b[0] - a[0], dy = b[1] - a[1], L2 = dx * dx + dy * dy;
    double t = L2 > 0 ? ((px - a[0]) * dx + (py - a[1]) * dy) / L2 : 0;
    t = t < 0 ? 0 : t > 1 ? 1 : t;
    double ex = a[0] + t * dx - px, ey = a[1] + t * dy - py;
    return sqrt(ex * ex + ey * ey);
}


// Grid points within reach (px) of a predicted edge (model_edges_predict):
// USED -> NEAR_EDGE. q: the points' pixel coordinates. false + message.
static bool view_near_edges(verify_view_t *v, const verify_camera_t *cam, const model_lamps_t *lamps,
                            const model_material_t *const *mats, const double *q, double reach, int threads)
{
    model_shading_t sh = model_shading_default();
    sh.nthreads = threads;
    model_edges_t *ed = model_edges_predict(v->rot, v->t, cam->cam, lamps, mats, &sh, 1.0);
    if (!ed) return false;
    for (int e = 0; e < ed->nedges; e++)
        for (int s = 0; s < ed->edges[e].nsegments; s++) {
            const model_edge_segment_t *sg = &ed->edges[e].segments[s];
            double xa = fmin(sg->q0[0], sg->q1[0]) - reach, xb = fmax(sg->q0[0], sg->q1[0]) + reach;
            double ya = fmin(sg->q0[1], sg->q1[1]) - reach, yb = fmax(sg->q0[1], sg->q1[1]) + reach;
            int i0 = (int)floor((xa - v->x0) / v->sp), i1 = (int)ceil((xb - v->x0) / v->sp);
            int j0 = (int)floor((ya - v->y0) / v->sp), j1 = (int)ceil((yb - v->y0) / v->sp);
            if (i0 < 0) i0 = 0;
            if (j0 < 0) j0 = 0;
            if (i1 > v->gw - 1) i1 = v->gw - 1;
            if (j1 > v->gh - 1) j1 = v->gh - 1;
            for (int j = j0; j <= j1; j++)
                for (int i = i0; i <= i1; i++) {
                    int g = j * v->gw + i;
                    if (v->status[g] == VERIFY_PT_USED &&
                        seg_dist(q[2 * g], q[2 * g + 1], sg->q0, sg->q1) <= reach)
                        v->status[g] = VERIFY_PT_NEAR_EDGE;
                }
        }
    model_edges_free(ed);
    return true;
}

// Face or shadow changes within the window (+ margin, c px from its centre):
// where a neighbour differs, look at the window's corners and edge midpoints;
// USED -> BOUNDARY. cand: room for the grid's points. false + message.
static bool view_boundaries(verify_view_t *v, const verify_camera_t *cam, const model_lamps_t *lamps,
                            const double *q, int c, int threads, int *cand)
{
    const int nl = v->nl;
    int ncand = 0;
    for (int j = 0; j < v->gh; j++)
        for (int i = 0; i < v->gw; i++) {
            int g = j * v->gw + i;
            if (v->status[g] != VERIFY_PT_USED) continue;
            uint32_t bits = lit_bits(&v->ls[(size_t)g * nl], nl);
            bool diff = false;
            for (int dj = -1; dj <= 1 && !diff; dj++)
                for (int di = -1; di <= 1 && !diff; di++) {
                    int ii = i + di, jj = j + dj;
                    if ((!di && !dj) || ii < 0 || jj < 0 || ii >= v->gw || jj >= v->gh) continue;
                    int g2 = jj * v->gw + ii;
                    diff = v->pi[g2].face != v->pi[g].face || lit_bits(&v->ls[(size_t)g2 * nl], nl) != bits;
                }
            if (diff) cand[ncand++] = g;
        }
    if (!ncand) return true;
    const int NC = 8;
    double *qc = malloc((size_t)ncand * NC * 2 * sizeof *qc);
    model_pixel_info_t *pc = malloc((size_t)ncand * NC * sizeof *pc);
    model_lamp_sample_t *lc = malloc((size_t)ncand * NC * (nl ? nl : 1) * sizeof *lc);
    bool ok = qc && pc && lc;
    if (!ok) model_error(NULL, 0, "out of memory for %d points near face and shadow boundaries", ncand);
    if (ok) {
        static const int off[8][2] = { { -1, -1 }, { 1, -1 }, { -1, 1 }, { 1, 1 },
                                       { 0, -1 }, { 0, 1 }, { -1, 0 }, { 1, 0 } };
        for (int k = 0; k < ncand; k++)
            for (int m = 0; m < NC; m++) {
                qc[2 * (k * NC + m)] = q[2 * cand[k]] + off[m][0] * c;
                qc[2 * (k * NC + m) + 1] = q[2 * cand[k] + 1] + off[m][1] * c;
            }
        ok = model_pixel_info_table(v->t, cam->cam, lamps, qc, ncand * NC, pc, lc, threads);
    }
    if (ok)
        for (int k = 0; k < ncand; k++) {
            int g = cand[k];
            uint32_t bits = lit_bits(&v->ls[(size_t)g * nl], nl);
            for (int m = 0; m < NC; m++) {
                int km = k * NC + m;
                if (pc[km].face != v->pi[g].face || lit_bits(&lc[(size_t)km * nl], nl) != bits) {
                    v->status[g] = VERIFY_PT_BOUNDARY;
                    break;
                }
            }
        }
    free(qc);
    free(pc);
    free(lc);
    return ok;
}

// A view's grid (x0, y0, gw, gh) for the image size and options; false + message when it has no points.
static bool view_grid(verify_view_t *v, const verify_options_t *opt, int *c)
{
    int h = opt->window_px / 2;
    *c = h + (int)ceil(opt->boundary_margin_px);
    v->x0 = v->y0 = *c > v->sp / 2 ? *c : v->sp / 2;
    v->gw = v->W - 1 - *c >= v->x0 ? (v->W - 1 - *c - v->x0) / v->sp + 1 : 0;
    v->gh = v->H - 1 - *c >= v->y0 ? (v->H - 1 - *c - v->y0) / v->sp + 1 : 0;
    if (v->gw * v->gh <= 0) {
        model_error(NULL, 0, "verify: a %dx%d image has no room for reference points", v->W, v->H);
        return false;
    }
    return true;
}

verify_view_t *verify_view_new(const model_scene_t *scene, const verify_camera_t *cam, double angle_deg,
                               const model_lamps_t *lamps, const model_material_t *const *mats,
                               const verify_options_t *opt)
{
    double t0 = model_now_s();
    if (lamps->n > MAX_LAMPS) {
        model_error(lamps->path, 0, "%d lamps: verification handles at most %d", lamps->n, MAX_LAMPS);
        return NULL;
    }
    if (opt->window_px < 1 || opt->window_px % 2 == 0 || opt->spacing_px < 1) {
        model_error(NULL, 0, "verify: the window (%d px) must be odd and >= 1, the spacing (%d px) >= 1",
                    opt->window_px, opt->spacing_px);
        return NULL;
    }
    verify_view_t *v = calloc(1, sizeof *v);
    if (!v) {
        model_error(NULL, 0, "out of memory");
        return NULL;
    }
    v->W = model_camera_width(cam->cam);
    v->H = model_camera_height(cam->cam);
    v->sp = opt->spacing_px;
    v->nl = lamps->n;
    int c;
    if (!view_grid(v, opt, &c)) {
        free(v);
        return NULL;
    }
    int n = v->gw * v->gh, nl = v->nl;
    int threads = opt->threads > 0 ? opt->threads : model_default_threads();
    v->rot = model_scene_rotated_z(scene, angle_deg);
    v->t = v->rot ? model_tracer_new(v->rot) : NULL;
    v->pi = malloc((size_t)n * sizeof *v->pi);
    v->ls = malloc((size_t)n * (nl ? nl : 1) * sizeof *v->ls);
    v->status = calloc((size_t)n, 1);
    v->B = calloc((size_t)n * (nl ? nl : 1), sizeof *v->B);
    v->Bsd = calloc((size_t)n * (nl ? nl : 1), sizeof *v->Bsd);
    double *q = malloc((size_t)n * 2 * sizeof *q);
    int *cand = malloc((size_t)n * sizeof *cand);
    if (!v->t || !v->pi || !v->ls || !v->status || !v->B || !v->Bsd || !q || !cand) {
        if (v->t) model_error(NULL, 0, "out of memory for %d reference points", n);
        goto fail;
    }
    // the grid's pixel_info: face, position, normal, lamp samples (background where the ray misses)
    for (int j = 0; j < v->gh; j++)
        for (int i = 0; i < v->gw; i++) {
            q[2 * (j * v->gw + i)] = v->x0 + i * v->sp;
            q[2 * (j * v->gw + i) + 1] = v->y0 + j * v->sp;
        }
    if (!model_pixel_info_table(v->t, cam->cam, lamps, q, n, v->pi, v->ls, threads)) goto fail;
    for (int g = 0; g < n; g++)
        if (v->pi[g].face < 0) v->status[g] = VERIFY_PT_BACKGROUND;
    // a blurred edge reaches 3 sigma further
    double sigma_px = cam->psf_sigma_px > 0 ? cam->psf_sigma_px : 0;
    double reach = (opt->window_px / 2) * M_SQRT2 + opt->edge_margin_px + 3 * sigma_px;
    if (!view_near_edges(v, cam, lamps, mats, q, reach, threads) ||
        !view_boundaries(v, cam, lamps, q, c + (int)ceil(3 * sigma_px), threads, cand))
        goto fail;
    // the windows near edges: modelled with the pixels' footprint and the blur where they see only the description
    if (opt->edge_windows) {
        bool *want = calloc((size_t)n, sizeof *want);
        if (!want) {
            model_error(NULL, 0, "out of memory for %d reference points", n);
            goto fail;
        }
        for (int g = 0; g < n; g++)
            want[g] = v->status[g] == VERIFY_PT_NEAR_EDGE || v->status[g] == VERIFY_PT_BOUNDARY;
        bool fok = verify_footprints_make(v->t, cam->cam, lamps, mats, q, want, n, opt->window_px,
                                          fmin(fmax(cam->pixel_fill, 0), 1), sigma_px,
                                          opt->edge_subsamples, opt->ir_samples, threads, &v->fp);
        free(want);
        if (!fok) goto fail;
        for (int g = 0; g < n; g++)
            if (v->fp.first[g] >= 0) v->status[g] = VERIFY_PT_USED;
    }
    // the interreflection basis at the usable points
    int ncand = 0;
    v->nusable = 0;
    for (int g = 0; g < n; g++) {
        if (v->status[g] != VERIFY_PT_USED) continue;
        v->nusable++;
        if (!(v->fp.first && v->fp.first[g] >= 0)) cand[ncand++] = g;   // (a window's parts have their own)
    }
    if (opt->ir_samples > 0 && ncand && nl) {
        verify_interreflection_at(v->t, lamps, mats, v->pi, cand, ncand, opt->ir_samples, threads, v->B, v->Bsd);
    }
    free(cand);
    free(q);
    v->time_s = model_now_s() - t0;
    return v;
fail:
    free(cand);
    free(q);
    verify_view_free(v);
    return NULL;
}
