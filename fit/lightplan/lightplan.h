// fit/lightplan/lightplan.h — model-based light placement (PREMIO): which
// lamps and exposure make a workpiece's edges detectable and give the
// verification fitter the most usable reference points, without glare or
// saturation?
//
// For one view (scene at a turntable angle, camera, candidate lamps with
// their kc*I, materials, the camera's usable range) the predictor renders each
// candidate lamp's direct light once (P is linear in the lamps), then for every
// lamp set (non-empty subsets of the candidates, at most max_lamps lamps) and
// exposure in the list:
// - dynamic range: per face, the share of its pixels whose signal lies above
//   the noise floor (floor_snr x the temporal noise, at least floor_dn) and
//   below saturation_frac x saturation;
// - specular glare: pixels of non-Lambertian faces where a lit lamp lies within
//   glare_cone_deg of the mirror direction of the view ray;
// - edge contrast: for every visible image segment of a scene edge (the edge
//   query, model_edges_predict), dP across it at points every 2 px along it
//   (the signal 2 px to either side: direct light plus one diffuse bounce,
//   which lights shadowed concave corners) and whether a Sobel detector with
//   threshold sobel_threshold fires: the median along the segment of
//   f |dP| reaches it, f the Sobel response per unit contrast of the step
//   blurred by the optics' Gaussian PSF of psf_sigma_px and integrated over
//   the pixel's 1 px footprint, at the segment's direction and the edge's best
//   sub-pixel phase (model_edge_sobel_step's best: the edge through a pixel
//   centre); sigma 0 gives the sharp step's 4.0 axis-aligned and 4.24
//   diagonal (4.30 at most between them), 0.8 px 3.04 and 2.96;
// and chooses the feasible configuration (saturated and glare pixels at most
// max_bad_frac of the object's pixels) with the longest detectable edge
// length, then the most usable reference points (usable pixels off glare, per
// verification grid cell of spacing_px^2). When none is feasible, the one with
// the fewest bad pixels is chosen and said so.
#pragma once

#include <jansson.h>
#include <stdbool.h>
#include <stdint.h>

#include "model/model.h"

#ifdef __cplusplus
extern "C" {
#endif

enum { MAXL_PLAN = 16 };         // candidate lamps at most (2^16 lamp sets)

typedef struct {
    double glare_cone_deg;      // 15
    double sobel_threshold;     // DN of gradient magnitude (default 250: above the detector's noise
                                // response, about 9 sigma = 140 DN at 1000 DN on a 12-bit camera)
    double floor_snr;           // 10
    double floor_dn;            // 20
    double saturation_frac;     // 0.95
    double max_bad_frac;        // 0.001
    int    max_lamps;           // 0: all candidates
    int    spacing_px;          // 8: verification grid, for the usable reference points
    int    ir_samples;          // 64: rays of one diffuse bounce at the edge points (0: direct light only)
    int    threads;
    double psf_sigma_px;        // the optics' Gaussian PSF (0: a sharp step, the pixel's footprint alone)
} lightplan_options_t;

lightplan_options_t lightplan_defaults(void);

typedef struct {
    double offset_dn;           // dark level (mean; 0 with an offset map subtracted)
    double K_dn_per_e;          // temporal noise: K and read noise (0: floor_dn only)
    double read_noise_e;
    double saturation_dn;
    const float *flat;          // g(x,y) or NULL
} lightplan_sensor_t;

typedef struct {
    int      face;              // scene face (or nfaces + k for sphere k)
    int      npix;              // pixels of the face in view (step-2 grid)
    double   P_min, P_median, P_max;   // DN
    double   usable_frac;       // inside the usable range
    int      glare_pix;         // with glare
    int      saturated_pix;
} lightplan_face_t;

typedef struct {
    uint32_t mask;              // lamp set
    double   exposure_us;
    double   detectable_length_px;
    int      n_detectable, n_segments;
    double   usable_points;     // per spacing_px^2 cell
    int      glare_pix, saturated_pix, object_pix;
    bool     feasible;
} lightplan_config_t;

typedef struct {
    int    edge, segment;       // indices in the edge query's result
    double q0[2], q1[2], length_px;
    double dP;                  // predicted contrast, DN (mean along the segment; chosen configuration)
    double gradient;            // predicted Sobel response, DN (median along the segment)
    double sobel_factor;        // f: the Sobel response per DN of contrast at its direction (see above)
    bool   detectable;
    int    face_side[2];
} lightplan_segment_t;

typedef struct {
    int                  nconfigs;
    lightplan_config_t  *configs;
    int                  best;          // index into configs
    bool                 best_feasible;
    int                  nsegments;
    lightplan_segment_t *segments;      // for the chosen configuration
    int                  nfaces;
    lightplan_face_t    *faces;         // for the chosen configuration
    float               *predicted;     // W*H DN, chosen configuration (direct light)
    float               *L;             // nlamps planes W*H: each lamp's signal per us of exposure (DN/us, with g)
    int32_t             *face_id;       // W*H
    uint32_t            *glare;         // W*H: bit i set where lamp i would glare (nearest point of the step-2 grid)
    int                  npoints;       // sample points along the segments
    int                 *seg_first;     // nsegments + 1: segment s has points seg_first[s] .. seg_first[s+1]-1
    double              *Sside;         // nlamps x npoints x 2: each lamp's signal per us 2 px to each side
    int                  W, H, nlamps;
    double               time_s;
} lightplan_result_t;

// scene: at the view's turntable angle already (model_scene_rotated_z);
// A: kc*I per us of exposure for each candidate (DN/us at 0 dB per radiance
// unit); exposures: the list to try.
bool lightplan_run(const model_scene_t *scene, model_camera_t *cam, const model_lamps_t *cands, const double *A,
                   const model_material_t *const *mats, const lightplan_sensor_t *sensor, const double *exposures,
                   int nexp, const lightplan_options_t *opt, lightplan_result_t *out);
void lightplan_result_free(lightplan_result_t *r);

// Per-segment Sobel check of a camera frame (W*H DN) against the predicted
// detectability of the configuration the frame was taken with: for each
// segment, the median over points every 2 px along it (2 px kept from its ends)
// of the largest Sobel magnitude within 1.5 px across; found when it reaches
// the threshold. Segments shorter than 8 px are not judged. found and
// measured (out, nsegments) may be NULL. *agreement: the rate found ==
// predicted over the judged segments, or NAN when there are none. false +
// message: out of memory.
bool lightplan_sobel_check(const lightplan_segment_t *segs, int nseg, const float *frame, int W, int H,
                           double threshold, bool *found, double *measured, double *agreement);
// The segments' predicted contrast and detectability for any configuration
// (mask, exposure) of the same run (segs: r->nsegments, geometry copied from
// r->segments). false + message: out of memory.
bool lightplan_segments_for(const lightplan_result_t *r, uint32_t mask, double exposure_us,
                            const lightplan_options_t *opt, lightplan_segment_t *segs);

// ---------------------------------------------------------------------------
// The plan of a view from files (`refl plan lamps`, fit/lightplan/files.c)
//
// plan.json (format "refl-lightplan", version 1; read by
// scripts/plan_lamps_report.py): a view's plan ("scene", "turntable_deg",
// "chosen", "configurations", "faces", "segments", "virtual_rig_check", ...),
// or, with several views, their summary in out ("views": each one's choice
// and directory, "capture_plan").

typedef struct {
    const char        *scene;           // D3D, OBJ, STL or PLY description (rig frame)
    double             scene_unit_mm;   // mm per unit of its coordinates (0: mm, not said; --units)
    const char        *camera;          // camera model (mrcal; extrinsics in the rig frame)
    const char        *lamps;           // candidates: a lamps INI (with kc_per_us) or lamps.json (with white)
    const char        *white;           // white.json of refl calib white: kc*I per lamp (NULL: kc_per_us)
    double             kc_per_us;       // with a lamps INI: kc*I = kc_per_us * intensity (DN/us)
    const char *const *materials;       // one materials INI, or priors JSON files (their means)
    int                nmaterials;
    const char        *gain_dir;        // gain.json (K, read noise, saturation), offset_dn.tiff,
                                        // prnu_gain.tiff; NULL: saturation_dn, offset_dn, no SNR floor
    double             saturation_dn;   // without gain_dir (default 4095)
    double             offset_dn;       // without gain_dir (default 0)
    double             angle_deg;       // the view's turntable angle (one view, outputs in out)
    const double      *angles_deg;      // several views (nangles > 0; angle_deg unused): each planned
    int                nangles;         // on its own, outputs in out/view_ANGLE/, a summary in out
    const double      *exposures_us;    // the exposures to try
    int                nexp;
    lightplan_options_t opt;            // opt.psf_sigma_px NAN: the geometry calibration's (calib_psf_read
                                        // beside the camera model), else 0
    const char        *check_truth;     // the virtual rig's truth file: check the plan there (NULL: no check)
    const char        *sample;          // the capture plan's [sample] name and the virtual rig's sample
                                        // for the check (NULL: the scene file's name without extension)
    const char        *pixel_format;    // the capture plan's (default Mono12)
    const char        *out;             // output directory: plan.json, predicted.tiff, glare.tiff
                                        // (check_frame.tiff with a check), capture_plan.ini
    bool               report;          // index.html by scripts/plan_lamps_report.py
    int                argc;            // the command line for the provenance (argv[0] "refl")
    char             **argv;
} lightplan_lamps_opts_t;

lightplan_lamps_opts_t lightplan_lamps_defaults(void);

// One configuration checked on the virtual rig: a Sobel detector on its frame
// against the predicted detectability of each segment.
typedef struct {
    char   lamps[512];                  // "east+west"
    double exposure_us;
    double agreement;                   // found == predicted over the judged segments (NAN: none judged)
    int    judged, agreeing;
} lightplan_check_t;

// One view's plan.
typedef struct {
    double             angle_deg;
    char              *dir;             // its outputs (o->out for the one view)
    bool               planned;         // res holds the plan
    lightplan_result_t res;
    char               chosen[512];     // the chosen configuration's lamp names ("east+west")
    bool               check_started;   // the virtual rig was opened for the check
    int                nchecks;         // the chosen set, then each other single lamp (at the chosen exposure)
    lightplan_check_t  checks[MAXL_PLAN + 1];
    bool               checked;         // the check is done
    double             check_agreement; // over every judged segment (NAN: none)
    long               check_judged;
    double             median_signal_dn;   // the object's median signal in the prediction (offset excluded)
    double             sobel_noise_dn;     // the detector's response to the sensor's noise there (NAN: no gain)
    bool               threshold_near_noise; // opt.sobel_threshold < 1.5 sobel_noise_dn: edges found in noise
    int                exposure_edge;   // the chosen exposure is the longest searched (+1), the shortest (-1),
                                        // or neither, or only one was searched (0): plan.json's "warnings"
    bool               written;         // plan.json, predicted.tiff and glare.tiff are written
} lightplan_view_t;

typedef struct {
    int                ncandidates;     // loaded: > 0
    int                nviews;          // views begun (planned or not)
    lightplan_view_t  *views;
    char              *capture_plan;    // out/capture_plan.ini once written
    bool               plan_bound;      // with check_truth: the capture plan binds to the virtual rig
    double             psf_sigma_px;    // the PSF's sigma the plan used (px) and where it came from
    double             psf_sigma_std_px;   // its 1-sigma (NAN: given, not measured)
    char               psf_source[512];
} lightplan_lamps_result_t;

// Load the inputs, plan each view (lightplan_run at its angle), check it on
// the virtual rig (with check_truth), write its outputs and report; then the
// capture plan of the views (lightplan_capture_plan) and, with several views,
// the summary (plan.json and index.html in out). false + message
// (model_last_error(), not printed: the caller reports it); *r holds what was
// done either way: free with lightplan_lamps_result_free.
bool lightplan_lamps_run(const lightplan_lamps_opts_t *o, lightplan_lamps_result_t *r);
void lightplan_lamps_result_free(lightplan_lamps_result_t *r);

// The capture plan of the planned views (fit/lightplan/capture_plan.c): out/capture_plan.ini
// in refl's plan format (rig_plan_text): [sample] o->sample, kind workpiece; [angles]
// the views; [lamps] and [exposure] (fixed, gain 0, o->pixel_format) every chosen set
// and exposure; one [view N] per angle with its own; [capture] a dark frame after
// the views, settle 50 ms; provenance (command, inputs with sha256) in its comments.
// Read back with rig_plan_parse before it is kept; with check_truth, bound to the
// virtual rig of the truth file (rig_plan_bind). false + message.
bool lightplan_capture_plan(const lightplan_lamps_opts_t *o, const json_t *prov, lightplan_lamps_result_t *r);

// `refl plan lamps` (fit/cmd_plan.c).
int lightplan_cmd(int argc, char **argv);

#ifdef __cplusplus
}
#endif
