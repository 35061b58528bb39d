// fit/verify/footprint.h — the reference windows near edges, modelled with
// the pixels' footprint and the camera's blur (within fit/; verify.c uses it).
//
// A reference point's measured value is the mean of a w x w window of
// pixels. Pixel j integrates the scene's radiance L over its footprint, a
// square of fill px (1: the whole pixel, as a sensor with microlenses; 0: a
// point at its centre, as a renderer with one ray a pixel), blurred by the
// optics' point spread function, an isotropic Gaussian of sigma_px (0: none).
// Both come from the camera's calibration (verify_camera_t). So the window mean is
//   M = integral L(x) K(x - c) dx,   K(u, v) = k(u) k(v),
//   k(u) = (1/w) sum_j (box_fill * G_sigma)(u - j),  j = -(w-1)/2 .. (w-1)/2
// (fill 1: the w px box convolved with the Gaussian), c the window's centre,
// pixel centres at integer coordinates (mrcal's). Away from edges L is smooth and M
// is L at c, the model of verify.c's other points. Near an edge (a face's
// outline, a shadow's) M mixes the sides. Such a window is cut into "parts",
// one per face it sees: each part's weight W = the integral of K over the
// face's share of the window, its mean point (the K-weighted mean of the hit
// points, on the face's plane), and per lamp the K-weighted visibility over
// distance squared. The model of the window is then the sum over its parts of
// the face's reflection R at its mean point, lamp by lamp:
//   M = sum_parts sum_i s_i A_i E_i(p) R(l_i(p), v(p), n) wl_i + rho s_i A_i W B_i(p)
//   wl_i = integral over the part of K(x - c) V_i(x) / d_i(x)^2 dx
// (R and the lamp's emission E at the part's mean point: over a few pixels of
// one planar face they change by far less than the noise). The integrals are
// sums over samples: a lattice of 1 px cells aligned with the pixels over the
// kernel's support (|u| <= (w-1)/2 + fill/2 + 3 sigma); a cell whose four
// corners see one face in one shadow state counts as that face, any other
// cell is cut into ss x ss sub-cells (ss odd), each the face its centre sees. The cells' weights are
// K's exact integrals over them. The derivatives of wl_i with respect to the
// window's centre (wlx, wly: the model's change when the edge moves by a
// pixel; taken with whole pixels' footprints, as a point footprint's window
// changes by steps) give the point's sensitivity to an error in where the edge is.
#pragma once

#include <stdbool.h>
#include <stdint.h>

#include "model/model.h"

// One face's share of a window.
typedef struct {
    int32_t      face, material;
    float        W;              // K's integral over the share (the window's whole kernel: 1)
    model_vec3_t p_mm, n, v;     // K-weighted mean hit point (world at the view's angle), normal, to the camera
} verify_part_t;

typedef struct {
    int            npoints;      // grid points
    int32_t       *first;        // npoints: the point's first part in parts, -1 when not modelled here
    uint8_t       *nparts;       // npoints
    int            nparts_all, nl;
    verify_part_t *parts;
    float         *wl;           // nparts_all x nl x 3: wl_i, d wl_i / d c_x, d wl_i / d c_y (1/mm^2, 1/(mm^2 px))
    float         *B;            // nparts_all x nl: the interreflection basis at the part's mean point
                                 //   (verify_interreflection), per unit kc*I
    float         *Bsd;          // nparts_all x nl: its Monte Carlo estimate's standard error
    double         background_max;   // a window whose kernel falls on the background by more is not modelled
    int            ss;           // sub-cells per px side (odd)
    double         sigma_px, fill;
    long           samples;      // rays cast (primary), for the record
} verify_footprints_t;

// The 1-D kernel k's integral over [a, b] (px, relative to the window's
// centre) and its value at u (a point footprint without blur: 0).
double verify_kernel_integral(double a, double b, int w, double fill, double sigma_px);
double verify_kernel_value(double u, int w, double fill, double sigma_px);

// The parts of the grid points q (2n coordinates, px) whose want[g] is true:
// tracer t of the view's scene, its camera and lamps, the materials mats (for
// the interreflection basis at the parts, ir_samples rays; 0: none). A point
// is left out (first -1) when more than background_max of its kernel falls
// where the description has no surface, or it sees more than 8 faces. false +
// message (out of memory, tracing failed).
bool verify_footprints_make(const model_tracer_t *t, const model_camera_t *cam, const model_lamps_t *lamps,
                            const model_material_t *const *mats, const double *q, const bool *want, int n,
                            int window_px, double fill, double sigma_px, int ss, int ir_samples, int threads,
                            verify_footprints_t *out);
void verify_footprints_free(verify_footprints_t *f);
