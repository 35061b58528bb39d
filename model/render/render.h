// model/render/render.h — ray casting, grey values and rendering, and refl
// render's work (a scene rendered to an image file)
//
// Part of model/model.h, whose conventions (units, frames, pixel coordinates,
// errors, model_*_free(NULL)) apply here.
#pragma once

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "model/base/base.h"
#include "model/camera.h"
#include "model/config.h"
#include "model/scene/scene.h"

#ifdef __cplusplus
extern "C" {
#endif

// ---------------------------------------------------------------------------
// Ray casting (model/render/trace.c): Embree over the scene's faces and spheres.
//
// Spheres are an Embree user geometry with an exact ray-sphere intersection;
// a primary hit is recomputed in double precision from the ray and the
// sphere (like a face's hit from its plane), and its normal is (p - c) / r.
// Face ids (pixel_info.face, model_render's face_out, edges' face_side): 0 ..
// nfaces-1 are scene->faces; nfaces + k is scene->spheres[k]; -1 is a miss.
// Check face < scene->nfaces before indexing scene->faces.

typedef struct model_tracer model_tracer_t;

// Each face is triangulated in its plane (ear clipping: non-convex faces are
// fine; an outline that crosses itself is an error naming the face). The tracer
// keeps no pointer to the scene. All queries are thread-safe (one committed
// Embree scene, cast from many threads). Embree errors are reported with
// Embree's message.
model_tracer_t *model_tracer_new(const model_scene_t *scene);
void            model_tracer_free(model_tracer_t *t);

// The thesis's pixel_info for one pixel (or sub-pixel position).
typedef struct {
    double       q[2];        // pixel coordinates
    int32_t      face;        // index into scene->faces, nfaces + k for sphere k; -1: missed
    int32_t      material;    // scene material index; -1 when missed
    model_vec3_t p_mm;        // hit point, world
    model_vec3_t n;           // unit face normal turned to face the camera
    model_vec3_t v;           // unit vector from the point to the camera centre
    double       range_mm;    // camera centre to hit point
} model_pixel_info_t;

// Per pixel and lamp: direction, distance, visibility.
typedef struct {
    model_vec3_t l;           // unit vector from the point to the lamp centre
    double       d_mm;        // distance to the lamp centre
    double       V;           // visibility: 0 shadowed, 1 lit (fraction for finite lamps)
} model_lamp_sample_t;

// Cast one primary ray: the nearest hit along (origin, unit dir), or face -1.
// Fills face, material, p_mm, n (facing -dir) and range_mm; v = -dir. The hit
// point is recomputed in double precision on the face's plane.
void model_tracer_cast(const model_tracer_t *t, model_vec3_t origin, model_vec3_t dir,
                       model_pixel_info_t *out);
// True when the segment from p to target is unobstructed (shadow ray; any hit
// stops it); the ends are trimmed by model_tracer_epsilon_mm.
bool model_tracer_visible(const model_tracer_t *t, model_vec3_t p, model_vec3_t target);

// pixel_info for n pixel positions q (sparse list, sub-pixel allowed), with the
// per-lamp samples (out lamp_out: n*lamps->n, may be NULL). Rays come from the
// camera (exact unprojection). Uses nthreads (<= 0: model_default_threads()).
// A pixel whose ray misses the scene gets face = material = -1, v = -dir,
// p_mm = n = 0, range_mm = 0 and zero lamp samples. V is that of the lamp
// centre (0 when n.l <= 0: the face itself hides the lamp).
bool model_pixel_info(const model_tracer_t *t, const model_camera_t *cam,
                      const model_lamps_t *lamps, const double *q_xy, int n,
                      model_pixel_info_t *out, model_lamp_sample_t *lamp_out, int nthreads);
// The same with the rays from the camera's ray table (model_camera_ray_table:
// made once per camera and kept; exact to its bound at pixel centres, bilinear
// between them, where a lens changes by far less than that bound): many times
// faster than exact unprojection for many positions.
bool model_pixel_info_table(const model_tracer_t *t, model_camera_t *cam, const model_lamps_t *lamps,
                            const double *q_xy, int n, model_pixel_info_t *out, model_lamp_sample_t *lamp_out,
                            int nthreads);

// Offset (mm) used to keep secondary rays off the surface they start from
// (relative to the scene's size: about 4e-6 x its extent and distance from the origin).
double model_tracer_epsilon_mm(const model_tracer_t *t);
// Packets (Embree ray packets of 16; faster than the one-ray calls for
// coherent rays). n <= MODEL_TRACER_PACKET.
#define MODEL_TRACER_PACKET 16
// True when none of the n rays origin + s dirs[k] (s >= 0, unit dirs) can hit
// the scene: a conservative test of their cone against the scene's bounding box
// (false does not mean a hit).
bool model_tracer_rays_miss(const model_tracer_t *t, model_vec3_t origin,
                            const model_vec3_t *dirs, int n);
// n primary rays from one origin: out[k] as model_tracer_cast(t, origin, dirs[k]).
// Returns the number of rays that hit. A packet whose cone of rays cannot reach
// the scene's bounding box is answered without Embree.
int  model_tracer_cast_packet(const model_tracer_t *t, model_vec3_t origin,
                              const model_vec3_t *dirs, int n, model_pixel_info_t *out);
// A packet of shadow rays on segments, in the layout of Embree's packets:
// lane k tests org + s dir, 0 <= s <= tfar (dir need not be unit; tfar in
// units of |dir|) when active[k] is non-zero.
typedef struct {
    float org_x[MODEL_TRACER_PACKET], org_y[MODEL_TRACER_PACKET], org_z[MODEL_TRACER_PACKET];
    float dir_x[MODEL_TRACER_PACKET], dir_y[MODEL_TRACER_PACKET], dir_z[MODEL_TRACER_PACKET];
    float tfar[MODEL_TRACER_PACKET];
    int   active[MODEL_TRACER_PACKET];
} model_shadow_packet_t;
// vis[k] = 1 when lane k's segment is unobstructed, 0 when blocked or inactive.
void model_tracer_visible_packet(const model_tracer_t *t, const model_shadow_packet_t *sp,
                                 uint8_t vis[MODEL_TRACER_PACKET]);
// One shadow ray from a surface point p with unit normal nrm (on the side of target).
bool model_tracer_visible_from(const model_tracer_t *t, model_vec3_t p, model_vec3_t nrm,
                               model_vec3_t target);

// ---------------------------------------------------------------------------
// Grey values and rendering (model/render/shade.c)
//
//   P(x,y) = Pa + kc * g(x,y) * [ sum_i V_i I_i R_i / d_i^2  + interreflection ]
//
// The bracket is the radiance toward the camera in units of lamp intensity per
// mm^2; kc converts it to grey value (DN).

typedef enum {
    MODEL_INTERREFLECTION_NONE,
    MODEL_INTERREFLECTION_THESIS,   // one bounce, virtual point sources around the mirror direction
    MODEL_INTERREFLECTION_MC,       // Monte Carlo, several bounces, finite lamp radius
} model_interreflection_t;

const char *model_interreflection_name(model_interreflection_t m);
int         model_interreflection_from_name(const char *name);   // -1 if unknown

typedef struct {
    double kc;                  // camera parameter (DN per radiance unit)
    double Pa;                  // offset, DN
    const float *gain_map;      // g(x,y): width*height, mean 1; NULL = 1 everywhere
    model_interreflection_t interreflection;
    double rho;                 // thesis: weight of the virtual sources (sr; see model_render)
    int    thesis_samples;      // thesis: rays in the cone around the mirror direction
    double thesis_cone_deg;     // thesis: half-angle of that cone
    int    mc_samples;          // MC: paths per pixel
    int    mc_bounces;          // MC: indirect bounces
    bool   finite_lamps;        // MC: sample each lamp's sphere (radius_mm) for soft shadows
    uint64_t seed;              // MC: reproducible for a given seed, whatever the thread count
    int    nthreads;            // <= 0: model_default_threads()
    const uint8_t *pixel_mask;  // width*height: render only the pixels where it is non-zero (the others of
                                //   P_out, face_out and lit_out are left as they are); NULL: every pixel
} model_shading_t;

// Defaults: kc 1, Pa 0, no gain map, no interreflection, rho 0.05, 9 thesis
// samples in a 10 deg cone, 16 MC samples, 2 bounces, finite lamps, seed 1.
model_shading_t model_shading_default(void);

// Materials resolved against the scene: mats[k] is the material of scene
// material k. Fails naming the first scene material the file lacks.
bool model_resolve_materials(const model_scene_t *scene, const model_materials_t *mats,
                             const model_material_t **out /* scene->nmaterials */);

// Direct term for one pixel_info: sum_i V_i I_i R_i / d_i^2 (no kc, no Pa).
// dS_dp (out, may be NULL): derivatives with respect to the material's parameters.
double model_direct_sum(const model_pixel_info_t *pi, const model_lamp_sample_t *ls,
                        const model_lamps_t *lamps, const model_material_t *mat,
                        double *dS_dp);

// Render the full image: P per pixel (out, width*height floats, DN; Pa for
// pixels whose ray misses the scene). face_out (may be NULL): face index or -1.
// lit_out (may be NULL): lamps->n planes of width*height, 1 where lamp i lights
// the pixel's point (V > 0.5), else 0.
// Primary rays come from model_camera_ray_table (pixel centres, no
// anti-aliasing); lamps may be NULL (no lamps); mats as model_resolve_materials.
// THESIS: sh->thesis_samples rays in a fixed pattern (centre + rings) within
//   thesis_cone_deg of the mirror direction of v; each nearest hit y is a
//   virtual point source (eq. 18) whose area weight grows with |y - x|^2 (the
//   cone has a fixed solid angle), which adds
//   rho / N * L(y -> x) R_x(toward y, v, n),  L(y -> x) = sum_i V_i I_i R_y / d_i^2.
//   rho is thus a solid angle (sr) and the term stays finite where faces meet.
// MC: mc_samples paths per pixel, direct light at every vertex, mc_bounces
//   indirect bounces sampled from the cosine-weighted hemisphere. With
//   finite_lamps a lamp of radius_mm > 0 is a sphere of uniform radiance
//   I / (pi r^2) sampled by direction (soft shadows; lit_out: mean V > 0.5).
//   Each pixel's random stream is model_rng(seed, pixel index): the image does
//   not depend on the thread count.
bool model_render(const model_tracer_t *t, model_camera_t *cam, const model_lamps_t *lamps,
                  const model_material_t *const *mats, const model_shading_t *sh,
                  float *P_out, int32_t *face_out, uint8_t *lit_out);

// ---------------------------------------------------------------------------
// A scene rendered to an image file (refl render's work; model/render/file.c).
typedef struct {
    const char     *scene, *camera, *lamps, *materials;   // inputs (required)
    const char     *gain_map;        // per-pixel sensitivity g(x,y): float TIFF, camera size, mean 1 (NULL: 1)
    const char     *sensor;          // sensor INI: the sensor stage after the physics (NULL: none)
    const char     *out;             // .png (16-bit, P rounded and clipped) or .tif/.tiff (float32 P)
    const char     *info;            // info TIFF (P, face ids, lit masks), or NULL
    model_shading_t shading;         // its gain_map is set from gain_map
    double          planarity_tol_mm, turntable_deg;
    double          scene_unit_mm;   // mm per unit of the scene file (0: mm, not said; --units)
    const char     *threads_text;    // the threads option as given, for the metadata (NULL: "default")
    const char     *command_line;    // provenance
} model_render_file_opts_t;

typedef struct {
    int    width, height, nfaces, nlamps;
    model_interreflection_t interreflection;
    bool   png;
    double p_min, p_mean, p_max;     // DN, of the written image
    double background_frac;          // pixels whose ray misses the scene
    size_t clipped_low, clipped_high, clipped_nan;   // PNG: pixels clipped below 0, above 65535, not a number
    double time_s, render_s;
} model_render_file_result_t;

// false + message (file and line of the input at fault).
bool model_render_file(const model_render_file_opts_t *o, model_render_file_result_t *r);

#ifdef __cplusplus
}
#endif
