// model/edges/edges.h — the edge query, a straight step edge as the pixels
// see it, and refl edges' work
//
// Part of model/model.h, whose conventions (units, frames, pixel coordinates,
// errors, model_*_free(NULL)) apply here.
#pragma once

#include <stdbool.h>
#include <stdint.h>
#include <stdio.h>

#include "model/render/render.h"

#ifdef __cplusplus
extern "C" {
#endif

// ---------------------------------------------------------------------------
// Edge query (model/edges/edges.c; thesis 1.6, PREMIO)

typedef struct {
    double q0[2], q1[2];        // image end points, pixels
    double length_px;
    double P_side[2];           // predicted mean grey value on each side (DN)
    double contrast;            // P_side[0] - P_side[1]
    int    face_side[2];        // face seen on each side (-1 background)
    uint32_t lit_side[2];       // bit i: lamp i lights that side (V > 0.5 on at least half its points)
} model_edge_segment_t;

typedef struct {
    int    v0, v1;              // scene vertex indices of the 3D edge
    int    face_a, face_b;      // the faces sharing it (face_b -1 for a boundary edge)
    double dihedral_deg;        // angle between the face normals (0 for a boundary edge)
    int    nsegments;
    model_edge_segment_t *segments;  // visible image segments
} model_edge_t;

typedef struct {
    int           nedges;
    model_edge_t *edges;
} model_edges_t;

// Scene edges (pairs of faces sharing two vertices, and boundary edges), their
// visible image segments, lighting per side and predicted contrast.
// feature_angle_deg: edges between faces closer to coplanar are skipped.
// scene: the scene t was made from. Side 0 of a segment lies to the right of
// q0 -> q1 in the displayed image (y down), 2 px off the segment; P_side is the
// direct term only (Pa + kc * g * model_direct_sum), whatever sh->interreflection.
model_edges_t *model_edges_predict(const model_scene_t *scene,
                                   const model_tracer_t *t, model_camera_t *cam,
                                   const model_lamps_t *lamps,
                                   const model_material_t *const *mats,
                                   const model_shading_t *sh, double feature_angle_deg);
void model_edges_free(model_edges_t *e);

// ---------------------------------------------------------------------------
// A straight step edge as the pixels see it (model/edges/profile.c): the step
// convolved with an isotropic Gaussian point-spread function of sigma_px (the
// optics' blur alone; 0: none) and integrated over each pixel's footprint,
// its own 1 x 1 px square (a separate, known part of the model). theta_rad:
// the edge's normal from the image's +x axis (x right, y down); the
// footprint projected onto the normal is a box of 1 px at 0 and a triangle of
// base sqrt 2 px at 45 deg. Closed forms (no sampling); see the .c file.

// The edge spread function: the grey value, 0 on the dark side and 1 on the
// bright one, of a pixel whose centre lies u_px from the edge (u > 0 toward
// the bright side, along the normal). Derivatives may be NULL: dE_du (the line
// spread function), dE_dsigma (0 at sigma 0, where E depends on sigma^2).
double model_edge_spread(double u_px, double theta_rad, double sigma_px, double *dE_du, double *dE_dsigma);

// The 3 x 3 Sobel gradient magnitude (kernel 1 2 1 across 1 0 -1, in x and y;
// sqrt(gx^2 + gy^2)) per unit contrast of that edge at the pixel whose centre
// lies u_px from it. A sharp step (sigma 0) seen by a pixel whose centre the
// edge passes through: 4 axis-aligned, 3 sqrt 2 = 4.243 diagonal.
double model_edge_sobel(double u_px, double theta_rad, double sigma_px);

// The detector's peak response across the edge (the largest of the pixels
// next to it) per unit contrast, over the edge's sub-pixel phase: the
// distance ph of the nearest pixel centre from the edge, the pixels across it
// at ph + k sp, sp = max(|cos theta|, |sin theta|) (one pixel column or row
// crossing the edge), ph uniform in [0, sp/2]. best: the edge through a pixel
// centre (ph = 0), the phase at which sigma 0 gives the sharp step's 4.0
// (axis-aligned, every phase) and 4.243 (diagonal); mean over the phases;
// worst (ph = sp/2: the edge half-way between pixel centres; 3.89 diagonal at
// sigma 0).
typedef struct {
    double best, mean, worst;
} model_sobel_step_t;
model_sobel_step_t model_edge_sobel_step(double theta_rad, double sigma_px);

// ---------------------------------------------------------------------------
// A scene's predicted edges for a camera and lamps (refl edges's work;
// model/edges/file.c).
typedef struct {
    const char     *scene, *camera, *lamps, *materials;   // inputs (required)
    model_shading_t shading;
    double          planarity_tol_mm, turntable_deg;
    double          scene_unit_mm;       // mm per unit of the scene file (0: mm, not said; --units)
    double          feature_angle_deg;   // edges between faces whose normals differ by less are skipped
    const char     *command_line;        // provenance
} model_edges_file_opts_t;
typedef struct model_edges_file model_edges_file_t;
// Load and hash the inputs, predict the edges. NULL + message.
model_edges_file_t *model_edges_file_predict(const model_edges_file_opts_t *o);
void                model_edges_file_free(model_edges_file_t *f);   // accepts NULL
// The table: one line per visible image segment (3D and image end points,
// faces, lamps lighting each side, predicted grey values and contrast).
void model_edges_file_print(FILE *out, const model_edges_file_t *f, const model_edges_file_opts_t *o);
// The edges, their units and conventions and the provenance as JSON, format
// "refl-edges" version 1 (model_json_set_format). false + message.
bool model_edges_file_write_json(const model_edges_file_t *f, const model_edges_file_opts_t *o, const char *path);

#ifdef __cplusplus
}
#endif
