// calib/geometry/psf.h — the lens's blur from the calibration board's edges (the
// slanted-edge method, ISO 12233's idea), a stage of `refl calib geometry`.
// Public within calib/ and to the tests (the calibration set reads the result
// through calib_psf_read, calib/calib.h).
//
// Every edge of the board between two adjacent found corners separates a dark
// and a light square. Its pixels (the middle of the segment: a fifth of its
// length, at least 6 px, kept from either corner, where the other squares of
// the corners' junctions do not reach; within 6 px or 0.3 of its length of the
// line) are projected onto the edge's normal, and their grey values fitted
// (Levenberg-Marquardt) with the model of model_edge_spread: the two levels
// (each edge its own dark and light level), the line's offset and turn from
// the corners' segment, and the optics' Gaussian sigma; the pixel's 1 x 1 px
// footprint is integrated separately (known), so sigma is the optics' blur
// alone. Edges under 20 px long are not fitted; edges whose fit fails, whose
// contrast is under 10 times the fit's residual, whose line moves more than
// 1.5 px or turns more than 0.06 rad from the corners', or that reach past the
// image are rejected with the reason. The edges' sigmas are combined by their median; edges more than
// 4 robust standard deviations (1.4826 MAD, at least 0.05 px) from it are
// outliers. An edge whose fit ends at sigma's lower bound (0.01 px: as sharp
// as the footprint alone, or sharper) counts as 0. The 1-sigma of the result:
// the larger of the median's standard error from the edges' scatter
// (1.2533 x 1.4826 MAD / sqrt(N), or from the median of the edges' own fit
// 1-sigma when that is larger) and the scatter of the views' medians over
// sqrt(views) (views with 5 edges or more, at least 3 views): noise and what
// differs from view to view, not a footprint other than the full square or a
// PSF of another shape.
//
// The supersampled edge spread function of the used edges (their pixels'
// normalised values against the distance from the fitted line, in bins of
// 1/8 px) and the line spread function (its central differences), measured
// and modelled, go to a CSV for the report's figure; each edge's fit to
// another.
//
// Units: px (pixel coordinates with (0, 0) the centre of the top-left pixel),
// grey values in the image's own units (DN as stored), angles rad.
#pragma once

#include <jansson.h>
#include <stdbool.h>
#include <stdio.h>

#include "calib/geometry/geometry.h"

#ifdef __cplusplus
extern "C" {
#endif

// One edge's fit.
typedef struct {
    int    camera, view;            // the view's camera (index) and its number
    int    c0, c1;                  // its end corners (index j * width_n + i of the view's corners)
    double theta_rad;               // the edge's normal (a quarter turn from corner c0 toward c1) from +x
    double length_px;               // between the corners
    int    npix;                    // pixels fitted (after the outliers of the fit)
    double level_neg_dn, level_pos_dn;   // the levels on the normal's negative and positive side (either the lighter)
    double offset_px, turn_rad;     // the fitted line against the corners' segment
    double sigma_px, sigma_std_px;  // the optics' Gaussian sigma and its 1-sigma from the fit
    double rms_dn;                  // the fit's residual RMS
    double rss_square, rss_point;   // the fit's sum of squares with the pixel's square footprint, and refitted
                                    // with a point at its centre (a used edge; else NAN)
    double sigma_point_px;          // sigma of that point fit (NAN: none)
    bool   used;                    // in the estimate
    char   why[120];                // why not ("" when used)
} calib_psf_edge_t;

// The estimate of one camera.
typedef struct {
    bool   estimated;
    char   why[256];                // why not (estimated false)
    double sigma_px, sigma_std_px;  // the Gaussian's sigma (the optics' alone) and its 1-sigma
    double sigma_std_edges_px;      // the median's standard error from the edges' scatter (or their fits')
    double sigma_std_views_px;      // the views' medians' scatter / sqrt(views); NAN: under 3 views of 5 edges
    double spread_px;               // the edges' robust std (1.4826 MAD): how much the edges differ
    int    edges_used, edges_fitted, edges_tried, outliers, views_used;
    double rms_rel;                 // median of the edges' residual RMS over their contrast
    double pixel_fill;              // the footprint the edges show: 1 the pixel's square, 0 a point at its centre
                                    // (the point fits the used edges' pixels better by more than 5 %)
    double rss_point_over_square;   // the two footprints' sums of squares over the used edges
} calib_psf_t;

// The edges and their pixels, gathered view by view.
typedef struct calib_psf_acc calib_psf_acc_t;

// width_n x height_n: the board's inner corners along its rows and columns. NULL on out of memory.
calib_psf_acc_t *calib_psf_acc_new(int width_n, int height_n);
void             calib_psf_acc_free(calib_psf_acc_t *a);   // accepts NULL
// Fit the edges of one view: img (W x H grey values), its width_n x height_n
// corners q (x, y pairs, px, row by row; NAN where not seen: no edge there);
// at most max_edges of its height_n (width_n - 1) + width_n (height_n - 1)
// edges, spread evenly over them (0: all). The number
// of edges fitted (used or not), -1 on out of memory.
int calib_psf_add_view(calib_psf_acc_t *a, const float *img, int W, int H, const double *q, int camera, int view,
                       int max_edges);
// The estimate of a camera from its edges so far (marks the outliers).
void calib_psf_estimate(calib_psf_acc_t *a, int camera, calib_psf_t *out);
// The estimate as geometry.json's "psf": model, sigma_px, sigma_std_px,
// edges_used, footprint, method ... (new reference; when not estimated, model
// null and why).
json_t *calib_psf_json(const calib_psf_t *p);
// The supersampled ESF and the LSF of camera's used edges, measured and with
// the estimate's sigma, as CSV rows (header: camera,u_px,samples,esf_measured,
// esf_model,lsf_measured_per_px,lsf_model_per_px) appended to f; name: the
// camera's name for the rows.
void calib_psf_esf_csv(const calib_psf_acc_t *a, int camera, const char *name, const calib_psf_t *p, FILE *f);

// The stage of the geometry run (calib/geometry/psf.c): the views' frames read again
// at full depth (v->source; none with --corners), their edges fitted per
// camera, DIR/psf_esf.csv and DIR/psf_edges.csv, and "psf" in geometry.json's
// document s->out (the first camera's; with several cameras also each one's in
// "cameras"[k]). A camera whose blur cannot be estimated gets "psf" with model
// null and why, not an error. false + message only when a file cannot be
// written.
bool calib_psf_geometry(const calib_geometry_opts_t *o, calib_geometry_state_t *s);
// The report's section (the figure psf.png of scripts/calib_geometry_report.py).
void calib_psf_report(FILE *f, const calib_geometry_state_t *s);

#ifdef __cplusplus
}
#endif
