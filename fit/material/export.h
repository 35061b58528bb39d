// fit/material/export.h — materials out (fit/material/export.c): the materials of a
// priors file (refl fit material / refl fit brdf; read by fit/verify/verify.c's
// verify_priors_load, the one reader) as a glTF 2.0 material, a Mitsuba 3 BSDF
// or a MERL binary table, each with its conversion error against refl's model.
//
// The error is the Ngan et al. (2005) metric refl's fits minimise: the RMS of
// (f_export - f_model) cos theta_i over pairs of directions uniform in solid
// angle (theta_i, theta_o below 85 deg; 16 x 32 x 64 samples), in 1/sr, and
// relative to the RMS of f_model cos theta_i there.
//
// Conversions (grey: refl's models are of luminance):
// - every model but ggx and lambert is first fitted by refl's ggx on those
//   samples (fit_brdf; the error of that step is stated too); lambert's kd
//   (albedo/pi) is ggx's kd = pi kd with ks = 0;
// - glTF (metallic-roughness, metallic 0): roughnessFactor = sqrt(alpha);
//   KHR_materials_specular specularFactor = ks and the F0: specularColorFactor
//   = F0/0.04 when F0 <= 0.04, else 1 with KHR_materials_ior's ior =
//   (1 + sqrt F0)/(1 - sqrt F0) (ior 0 for F0 = 1): the specular lobe is
//   refl's exactly (glTF's D, height-correlated V and Schlick F); glTF dims the
//   diffuse by (1 - F), so baseColorFactor is the least-squares value;
// - Mitsuba 3: roughplastic (ggx, alpha, int_ior from F0, ext_ior 1,
//   nonlinear false) or roughconductor (ggx, alpha, eta from F0, k 0), their
//   specular_reflectance and diffuse_reflectance by least squares; the one of
//   smaller error is written. Evaluated as Mitsuba 3 documents them: exact
//   dielectric Fresnel, separable Smith G1 G1; roughplastic's diffuse
//   transmittance t(mu) = 1 - the rough interface's reflected albedo and its
//   internal reflectance 1 - (1/eta^2) int t 2 mu dmu (Mitsuba's own tables may
//   differ a little: the stated error is refl's evaluation). principled is not
//   offered (refl does not evaluate it, so could not state its error);
// - MERL: the material's own model at every cell centre (f_r, all three
//   channels; 0 below the horizon), model/brdf/table.c's writer; the error is
//   the table's interpolation against the model.
#pragma once

#include <jansson.h>
#include <stdbool.h>

#include "fit/verify/verify.h"
#include "model/model.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef enum { FIT_EXPORT_GLTF, FIT_EXPORT_MITSUBA, FIT_EXPORT_MERL } fit_export_format_t;

// "gltf", "mitsuba", "merl"; false for another name (no message).
bool fit_export_format_from_name(const char *name, fit_export_format_t *out);

enum { FIT_EXPORT_MAXQ = 8, FIT_EXPORT_NAUX = 66 };
typedef struct {
    char         name[64];
    model_brdf_t model;
    double       p[MODEL_BRDF_MAX_PARAMS];   // the priors' means
    double       ggx[4];                     // kd ks alpha F0 the conversion starts from
    double       ggx_error;                  // Ngan error of that ggx against the model (0: it is the model)
    char         target[64];                 // "gltf", "mitsuba roughplastic", "mitsuba roughconductor", "merl"
    int          nq;
    const char  *qname[FIT_EXPORT_MAXQ];     // the target's parameters
    double       q[FIT_EXPORT_MAXQ];
    double       error, rel_error;           // Ngan error (1/sr) and relative to the model's RMS
    char         alt_target[64];             // mitsuba: the plugin not chosen, its error ("" otherwise)
    double       alt_error;
    double       aux[FIT_EXPORT_NAUX];       // roughplastic: t(mu) at mu = k/64, then the internal reflectance
} fit_export_material_t;

// Convert one material (no file written; MERL: the table's error). false + message.
bool fit_export_convert(const verify_prior_t *m, fit_export_format_t fmt, fit_export_material_t *out);

// The MERL table of a material: f_r of its model at every cell centre (0 below
// the horizon). NULL + message (out of memory).
model_brdf_table_t *fit_export_tabulate(const verify_prior_t *m);

// The target's f_r of a converted material (cosines of one geometry), as the
// target renderer evaluates it (glTF, Mitsuba), the model itself for MERL.
double fit_export_eval(const fit_export_material_t *e, const model_cosines_t *c);

// The materials of the priors file (only: one material's name, NULL every one;
// MERL holds one material, so a file of several needs only) written to out in
// the format, and out.conversion.json (format "refl-export", version 1:
// {"format", "version", "file", "materials": [each conversion, its errors],
// "provenance": prov, left out when NULL}). *res (caller frees res->m) the
// conversions. false + message.
typedef struct {
    int                    n;
    fit_export_material_t *m;
} fit_export_result_t;
bool fit_export_materials(const char *priors, const char *only, fit_export_format_t fmt, const char *out,
                          json_t *prov, fit_export_result_t *res);

// `refl export material` (fit/cmd_export.c).
int fit_cmd_export(int argc, char **argv);

#ifdef __cplusplus
}
#endif
