// fit/verify/windows.c — the window sums of an image's reference points, kept
// across the fits of the same pixels (verify_windows_t).
#define _GNU_SOURCE
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fit/verify/internal.h"

#define WINDOWS_KEPT 2   // with and without the maps
struct verify_windows {
    struct {
        const float *P, *off, *flat;
        int          w, sp, x0, y0, gw, gh;
        wsum_t      *s;
    } e[WINDOWS_KEPT];
    int next;
};

verify_windows_t *verify_windows_new(void)
{
    verify_windows_t *W = calloc(1, sizeof *W);
    if (!W) model_error(NULL, 0, "out of memory");
    return W;
}

void verify_windows_clear(verify_windows_t *W)
{
    if (!W) return;
    for (int k = 0; k < WINDOWS_KEPT; k++) free(W->e[k].s);
    memset(W, 0, sizeof *W);
}

void verify_windows_free(verify_windows_t *W)
{
    verify_windows_clear(W);
    free(W);
}

// The sums of every window of view v's grid on image im (w x w, offset map
// off and flat field flat or NULL): kept in im->windows when given (*owned
// false), else made for this fit (*owned true: the caller frees). NULL: out of memory.
const wsum_t *verify_window_sums(const verify_image_t *im, const verify_view_t *v, int w, const float *off,
                                 const float *flat, bool *owned)
{
    verify_windows_t *W = im->windows;
    *owned = W == NULL;
    for (int k = 0; W && k < WINDOWS_KEPT; k++)
        if (W->e[k].s && W->e[k].P == im->P && W->e[k].off == off && W->e[k].flat == flat && W->e[k].w == w &&
            W->e[k].sp == v->sp && W->e[k].x0 == v->x0 && W->e[k].y0 == v->y0 && W->e[k].gw == v->gw &&
            W->e[k].gh == v->gh)
            return W->e[k].s;
    const int h = w / 2, n = v->gw * v->gh;
    wsum_t *S = malloc((size_t)n * sizeof *S);
    if (!S) return NULL;
    for (int g = 0; g < n; g++) {
        int gx = v->x0 + (g % v->gw) * v->sp, gy = v->y0 + (g / v->gw) * v->sp;
        double s1 = 0, s2 = 0, gs = 0, mx = 0;
        for (int y = gy - h; y <= gy + h; y++)
            for (int x = gx - h; x <= gx + h; x++) {
                size_t o = (size_t)y * v->W + x;
                double P = im->P[o];
                if (P > mx) mx = P;
                if (off) P -= off[o];
                s1 += P;
                s2 += P * P;
                gs += flat ? flat[o] : 1;
            }
        S[g] = (wsum_t){ s1, s2, gs, mx };
    }
    if (W) {
        int k = W->next;
        W->next = (k + 1) % WINDOWS_KEPT;
        free(W->e[k].s);
        W->e[k].P = im->P;
        W->e[k].off = off;
        W->e[k].flat = flat;
        W->e[k].w = w;
        W->e[k].sp = v->sp;
        W->e[k].x0 = v->x0;
        W->e[k].y0 = v->y0;
        W->e[k].gw = v->gw;
        W->e[k].gh = v->gh;
        W->e[k].s = S;
    }
    return S;
}
