// model/brdf/brdf.h — reflection models: the analytic BRDFs (one X-macro
// list), MERL tables, RGL .bsdf files and the generators
//
// Part of model/model.h, whose conventions (units, frames, pixel coordinates,
// errors, model_*_free(NULL)) apply here.
#pragma once

#include <stdbool.h>
#include <stddef.h>

#include "model/base/base.h"

#ifdef __cplusplus
extern "C" {
#endif

// ---------------------------------------------------------------------------
// Reflection models (model/brdf/brdf.c)
//
// R = f_r * (n.l), evaluated from the four cosines. One X-macro list is the
// single source of the models, their names and parameters.
// Conventions: in lambert, hall, torrance_sparrow and thesis_fit, kd is the
// thesis's coefficient (albedo/pi absorbed: a Lambertian surface of albedo a
// has kd = a/pi); in cook_torrance, ggx and ggx2, kd is the albedo (they divide by pi).
// alpha is the GGX alpha (not "perceptual roughness", alpha = r^2).
// ashikhmin_shirley (Ashikhmin & Shirley, "An anisotropic Phong BRDF model",
// 2000, isotropic: n_u = n_v = ns): Rd the diffuse reflectance, Rs the
// specular reflectance at normal incidence (its own Schlick Fresnel F0 = Rs,
// and the diffuse term is scaled by 1 - Rs as in the paper), ns the Phong
// exponent of (n.h).
// ggx2: two GGX lobes sharing one Schlick F0: (ks, alpha) the first lobe,
// (ks2, alpha2) the second; a fit orders them so that alpha <= alpha2 (the
// first lobe is the sharper one). The same f_r as the ggx2 generator.
//
//   _(ENUM, name, nparams, param names...)
#define MODEL_BRDF_LIST(_)                                           \
    _(LAMBERT,          lambert,          1, "kd")                   \
    _(HALL,             hall,             3, "kd", "ks", "ns")       \
    _(TORRANCE_SPARROW, torrance_sparrow, 4, "kd", "ks", "ns", "F0") \
    _(THESIS_FIT,       thesis_fit,       3, "ks", "ns", "kd")       \
    _(COOK_TORRANCE,    cook_torrance,    4, "kd", "ks", "m", "F0")  \
    _(GGX,              ggx,              4, "kd", "ks", "alpha", "F0") \
    _(ASHIKHMIN_SHIRLEY, ashikhmin_shirley, 3, "Rd", "Rs", "ns")   \
    _(GGX2,             ggx2,             6, "kd", "ks", "alpha", "ks2", "alpha2", "F0")

typedef enum {
#define MODEL_BRDF_ENUM_(e, name, np, ...) MODEL_BRDF_##e,
    MODEL_BRDF_LIST(MODEL_BRDF_ENUM_)
#undef MODEL_BRDF_ENUM_
    MODEL_BRDF_COUNT
} model_brdf_t;

#define MODEL_BRDF_MAX_PARAMS 6

typedef struct {
    double nl, nv, nh, vh;   // n.l, n.v, n.h, v.h
} model_cosines_t;

const char  *model_brdf_name(model_brdf_t m);
int          model_brdf_from_name(const char *name);       // -1 if unknown
int          model_brdf_nparams(model_brdf_t m);
const char  *model_brdf_param_name(model_brdf_t m, int i);
int          model_brdf_param_index(model_brdf_t m, const char *name); // -1 if none
// Physical range of parameter i: lo <= p <= hi (hi may be INFINITY).
void         model_brdf_param_range(model_brdf_t m, int i, double *lo, double *hi);
// Default value of parameter i when a materials file omits it, or NAN when the
// parameter is required.
double       model_brdf_param_default(model_brdf_t m, int i);
// One-line description of the convention of the model's parameters
// ("kd: thesis coefficient ...; alpha: GGX alpha, not perceptual roughness").
const char  *model_brdf_convention(model_brdf_t m);
// True for the physically based models (energy conserving when kd+ks <= 1).
bool         model_brdf_is_physical(model_brdf_t m);

// Cosines from unit vectors n, l, v (h computed here). n is not flipped.
model_cosines_t model_cosines(model_vec3_t n, model_vec3_t l, model_vec3_t v);

// R = f_r(l,v) * (n.l). Exactly 0 (and dR_dp all 0) when n.l <= 0 or n.v <= 0.
// dR_dp (out, may be NULL): model_brdf_nparams(m) derivatives.
double model_brdf_eval(model_brdf_t m, const double *p, const model_cosines_t *c,
                       double *dR_dp);
// The parameter-free terms of one (point, lamp) geometry, computed once by
// model_brdf_prepare so that fits which evaluate the same geometry many times
// skip them: model_brdf_eval_prepared equals model_brdf_eval bit for bit
// (the same operations in the same order), except Blinn's (n.h)^ns at a
// non-whole ns: exp(ns log(n.h)) from the stored log, within a relative
// 1e-13 of pow() (tests/test_fit_verify_speed.c). The Blinn-based models and GGX
// use the stored terms (the others evaluate c), and keep their last
// distribution and shadowing factors with the shape parameter (ns, alpha)
// they came from: a solver evaluating the same parameters again (the cost
// at a candidate, then its Jacobian) gets them back instead of pow() and
// sqrt(). A prepared geometry is used by one thread at a time.
typedef struct {
    model_cosines_t c;
    double lognh;   // log(n.h) (0 when n.h <= 0)
    double s_ts;    // G_ts / (n.v), the Torrance-Sparrow attenuation over n.v
    double x5;      // (1 - v.h)^5, Schlick's term
    double nh2;     // (n.h)^2
    double t2l, t2v;   // tan^2 of l's and v's angles from n (GGX's Smith term)
    double key;     // the shape parameter of the kept factors (NAN: none)
    double D, G, dD, dG;   // kept: distribution, shadowing, their derivatives (when kept_d)
    bool   kept_d;
    bool   zero;    // n.l <= 0 or n.v <= 0: R = 0
} model_brdf_prep_t;
model_brdf_prep_t model_brdf_prepare(const model_cosines_t *c);
double model_brdf_eval_prepared(model_brdf_t m, const double *p, model_brdf_prep_t *pc, double *dR_dp);
// The same for n cosines (model/brdf/batch.c): R[i], and dR_dp (may be
// NULL) n x nparams row-major. Equal to model_brdf_eval sample by sample to
// rounding (1e-9 relative); GGX, the fitters' inner loop, is vectorised.
void model_brdf_eval_n(model_brdf_t m, const double *p, const model_cosines_t *c, int n, double *R,
                       double *dR_dp);

// ---------------------------------------------------------------------------
// Tabulated isotropic BRDFs (model/brdf/table.c), MERL's binary layout: 3
// int32 dims 90 90 180 (theta_h square-root mapped, theta_d, phi_d), then the
// red, green and blue channels of doubles, each f_r divided by MERL's channel
// scale (1/1500, 1.15/1500, 1.66/1500); negative = missing. refl reads the
// Rec. 709 luminance of the scaled channels and writes f_r in all three.
// Evaluation interpolates trilinearly between cell centres and is reciprocal
// by construction (mean over phi_d and pi - phi_d).
enum { MODEL_MERL_TH = 90, MODEL_MERL_TD = 90, MODEL_MERL_PD = 180 };
typedef struct model_brdf_table model_brdf_table_t;

model_brdf_table_t *model_brdf_table_new(void);                        // every cell 0
// NULL and "FILE: not a MERL BRDF file: ..." (short, wrong dims, wrong size).
model_brdf_table_t *model_brdf_table_load(const char *path);
// The same of one channel: ch 0 the luminance, 1 red, 2 green, 3 blue (model_channel_t).
model_brdf_table_t *model_brdf_table_load_channel(const char *path, int ch);
// Cell (i, j, k)'s measure in (omega_i, omega_o), sr^2: 4 cos(theta_d) d omega_h
// d omega_d over the cell, phi_h over 2 pi and phi_d folded (x 2). Over every
// cell 8 pi^2; over the cells with both directions above the surface ~(2 pi)^2.
double              model_brdf_table_cell_solid_angle(int i, int j, int k);
// True when a file of file_bytes starting with head is a MERL table.
bool                model_brdf_table_sniff(const unsigned char head[12], size_t file_bytes);
bool                model_brdf_table_save(const model_brdf_table_t *t, const char *path);
void                model_brdf_table_free(model_brdf_table_t *t);
// The 90*90*180 values of f_r, index (i*90 + j)*180 + k; NAN = missing.
double             *model_brdf_table_values(model_brdf_table_t *t);
const double       *model_brdf_table_values_const(const model_brdf_table_t *t);
const char         *model_brdf_table_sha256(const model_brdf_table_t *t);   // of the file read, else ""
// The cosines of cell (i, j, k)'s centre (nl or nv may be <= 0: below the horizon).
void                model_brdf_table_cell(int i, int j, int k, model_cosines_t *c);
// f_r, and R = f_r (n.l), interpolated (0 when n.l <= 0 or n.v <= 0).
double              model_brdf_table_f(const model_brdf_table_t *t, const model_cosines_t *c);
double              model_brdf_table_eval(const model_brdf_table_t *t, const model_cosines_t *c);
// Directional albedo int f_r cos(theta_o) d omega_o at incidence theta_i (rad),
// on an n x n cosine-weighted grid; of any f (from cosines) or of a table.
double model_brdf_directional_albedo(double (*f)(const void *ctx, const model_cosines_t *c), const void *ctx,
                                     double theta_i, int n);
double model_brdf_table_albedo(const model_brdf_table_t *t, double theta_i, int n);

// Measured BRDFs in the RGL ".bsdf" tensor format (model/brdf/rgl.c, the one
// owner; Dupuy & Jakob 2018): rgb or spectral, isotropic or not. Detected by
// content (the magic "tensor_file\0"); the file's description and evaluation
// are in the .c file's head. NULL and "FILE: ..." for what is not a valid one.
typedef struct model_brdf_rgl model_brdf_rgl_t;
bool              model_brdf_rgl_sniff(const unsigned char *head, size_t n);
model_brdf_rgl_t *model_brdf_rgl_load(const char *path);
model_brdf_rgl_t *model_brdf_rgl_parse(const void *data, size_t len, const char *name);
void              model_brdf_rgl_free(model_brdf_rgl_t *r);
int               model_brdf_rgl_channels(const model_brdf_rgl_t *r);        // 3 (rgb) or the wavelengths'
const double     *model_brdf_rgl_wavelengths(const model_brdf_rgl_t *r);     // nm; NULL for rgb
int               model_brdf_rgl_ntheta(const model_brdf_rgl_t *r);
int               model_brdf_rgl_nphi(const model_brdf_rgl_t *r);
double            model_brdf_rgl_theta_i(const model_brdf_rgl_t *r, int k);  // radians
double            model_brdf_rgl_phi_i(const model_brdf_rgl_t *r, int k);
bool              model_brdf_rgl_isotropic(const model_brdf_rgl_t *r);       // phi_i has <= 2 values
const char       *model_brdf_rgl_sha256(const model_brdf_rgl_t *r);
const char       *model_brdf_rgl_description(const model_brdf_rgl_t *r);
// The weights of the channels for ch (w[channels]): rgb files Rec. 709 luma
// (0.2126, 0.7152, 0.0722) or one channel; spectral files luma only, the CIE
// 1931 y-bar over the wavelengths normalised to sum 1 (false + message for r/g/b).
bool   model_brdf_rgl_channel_weights(const model_brdf_rgl_t *r, int ch /* model_channel_t */, double *w, const char *name);
// f_r cos(theta_o) of the channels weighted by chw, for unit directions wi, wo
// in the surface frame (z = normal); 0 when either is below the surface.
double model_brdf_rgl_eval(const model_brdf_rgl_t *r, model_vec3_t wi, model_vec3_t wo, const double *chw);
// The directions the file measured: incident slice (iphi, itheta)'s value
// grid, every node of the warped square mapped back through the slice's VNDF
// warp to a microfacet normal m and the outgoing direction w_i reflects into
// about it. model_brdf_rgl_nodes_max is the count per slice (the value grid's
// nodes); model_brdf_rgl_nodes writes those whose w_o is above the surface
// (wi once, wo[k], domega_sr[k]: the outgoing solid angle the node stands
// for: its cell of the warped square, halved at each edge, over the VNDF's
// density there, times the (u_theta, u_phi) -> m Jacobian 2 pi^2 u_theta
// sin(theta_m) and the reflection's 4 (w_i . m); 0 where the density is 0,
// as on the square's u_theta = 0 edge, whose nodes hold the mirror
// direction's value) and returns their count.
int model_brdf_rgl_nodes_max(const model_brdf_rgl_t *r);
int model_brdf_rgl_nodes(const model_brdf_rgl_t *r, int iphi, int itheta, model_vec3_t *wi, model_vec3_t *wo,
                         double *domega_sr);

// Generators (model/brdf/gen.c): "NAME key=value ..." with NAME oren-nayar,
// ggx2, retro, ggx-ms, ptfe or ggx (model_brdf_recipe_models lists the keys
// and defaults); reciprocal and energy conserving within their ranges.
enum { MODEL_BRDF_RECIPE_MAX = 8, MODEL_BRDF_RECIPE_NE = 65 };
typedef struct {
    char   name[32];
    int    model, np;
    double p[MODEL_BRDF_RECIPE_MAX];
    double E[MODEL_BRDF_RECIPE_NE], Eavg;   // ggx-ms: single-scattering albedo over mu = cos theta
} model_brdf_recipe_t;

const char         *model_brdf_recipe_models(void);
// file, line: where the recipe was written (messages); NULL / 0 for the command line.
bool                model_brdf_recipe_parse(const char *text, const char *file, int line, model_brdf_recipe_t *r);
double              model_brdf_recipe_f(const model_brdf_recipe_t *r, const model_cosines_t *c);   // f_r
model_brdf_table_t *model_brdf_tabulate(const model_brdf_recipe_t *r);

#ifdef __cplusplus
}
#endif
