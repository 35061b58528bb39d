// model/config.h — materials, lamps and sensor files: their types and INI readers
//
// Part of model/model.h, whose conventions (units, frames, pixel coordinates,
// errors, model_*_free(NULL)) apply here.
#pragma once

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "model/base/base.h"
#include "model/brdf/brdf.h"

#ifdef __cplusplus
extern "C" {
#endif

// ---------------------------------------------------------------------------
// Materials, lamps and sensor files (model/config.c)

typedef struct {
    char         name[64];
    model_brdf_t model;
    double       p[MODEL_BRDF_MAX_PARAMS];
    int          line;        // of the [material NAME] header
    // model = table: the tabulated BRDF (owned by the materials list) the
    // renderer evaluates (model_material_eval); model and p then hold a
    // Lambertian stand-in of the table's albedo at normal incidence for code
    // that knows only the fitted models.
    model_brdf_table_t *table;
} model_material_t;

// R of a material: its table when it has one, else model_brdf_eval.
double model_material_eval(const model_material_t *mat, const model_cosines_t *c);

typedef struct {
    int               n;
    model_material_t *materials;
    char             *path;
    char              sha256[65];
} model_materials_t;

// [material NAME] with model = lambert|hall|..., and that model's parameters by
// name; or model = table with either table = FILE (a MERL binary, path relative
// to the INI file) or generate = RECIPE (model_brdf_recipe_parse, tabulated
// when the file is read). Unknown keys, missing required parameters and out-of-range values are
// errors naming file and line.
model_materials_t *model_materials_load(const char *path);
model_materials_t *model_materials_parse(const char *text, size_t len, const char *name);
void               model_materials_free(model_materials_t *m);
const model_material_t *model_materials_find(const model_materials_t *m, const char *name);

typedef struct {
    char         name[64];
    model_vec3_t position_mm;   // world (rig) frame
    double       intensity;     // I_i, in the units of the grey value per kc (see model_grey)
    double       radius_mm;     // 0 = ideal point lamp
    // Emission pattern: the intensity toward direction u (unit, from the lamp)
    // is intensity * max(0, axis . u)^emission_cos_power; 0 = isotropic (the
    // fitters' model). emission_axis: unit; (0, 0, 0) = toward the rig origin.
    double       emission_cos_power;
    model_vec3_t emission_axis;
    int          line;
} model_lamp_t;

typedef struct {
    int           n;
    model_lamp_t *lamps;
    char         *path;
    char          sha256[65];
} model_lamps_t;

// [lamp NAME] with position_mm = x y z, intensity = I (> 0), optional radius_mm (>= 0),
// emission_cos_power = n (>= 0, 0 = isotropic) and emission_axis = x y z (needs n > 0).
model_lamps_t *model_lamps_load(const char *path);
model_lamps_t *model_lamps_parse(const char *text, size_t len, const char *name);
void           model_lamps_free(model_lamps_t *l);
int            model_lamps_find(const model_lamps_t *l, const char *name); // -1 if none

// The sensor stage's parameters ([sensor] section; units in the names).
typedef struct {
    int      bits;                   // 8, 12 or 16: output quantisation
    double   system_gain_dn_per_e;   // K
    double   full_well_e;            // saturation of the pixel well
    double   read_noise_e;           // temporal, Gaussian
    double   dark_offset_dn;         // mean dark level
    double   dsnu_dn;                // std of the dark offset over pixels (fixed pattern)
    double   prnu_pct;               // std of the pixel gain over pixels, % (fixed pattern)
    double   dark_current_e_per_s;
    double   exposure_us;            // for the dark current
    double   vignetting;             // relative fall-off at the image corner (0 = none)
    double   nonlinearity_pct;       // compression at full well, % (0 = linear)
    uint64_t pattern_seed;           // fixed patterns (DSNU, PRNU)
    uint64_t noise_seed;             // temporal noise of this frame
    // Outside the fitters' linearised response S(1 - aS) (the virtual rig's
    // adversary; all off by default, see model/sensor.c):
    double   knee_e;                 // soft clip toward full well above this many e- (0 = off)
    double   low_end_gamma;          // e' = low_end_e (e / low_end_e)^gamma below low_end_e (1 = off)
    double   low_end_e;
    double   hot_pixel_fraction;     // fixed share of pixels with a high dark current (0 = none)
    double   hot_pixel_dark_current_e_per_s;
    double   row_noise_dn;           // per-row, per-frame offset, rms DN (0 = none)
} model_sensor_t;

// Defaults: 12 bits, K 0.25 DN/e-, full well 16000 e-, read noise 6 e-,
// dark offset 64 DN, DSNU 1.5 DN, PRNU 1 %, no dark current, vignetting 0.1,
// non-linearity 2 %, seeds 1 and 1.
model_sensor_t model_sensor_default(void);
bool model_sensor_load(const char *path, model_sensor_t *out);
bool model_sensor_parse(const char *text, size_t len, const char *name, model_sensor_t *out);

// From a file that holds other sections too (e.g. the virtual rig's truth
// file): only the sections of the kind are read, the others are ignored; the
// file's own rules (unknown keys, ranges) apply. sha256 is left empty (the
// caller knows the file). NULL / false with "file:line: ..." on error, also
// when there is no such section.
model_materials_t *model_materials_from_ini(const model_ini_t *ini);   // [material NAME]
model_lamps_t     *model_lamps_from_ini(const model_ini_t *ini);       // [lamp NAME]
// The factor of lamp L's emission pattern toward point p: max(0, a . u)^n, u
// the unit direction from the lamp to p, a its emission axis; exactly 1 when
// emission_cos_power is 0 (isotropic), 0 at the lamp itself. (model/render/shade.c)
double             model_lamp_emission(const model_lamp_t *L, model_vec3_t p);
// The 4 quadrature directions of a spherical lamp of radius radius_mm seen at
// distance d_mm in unit direction l: the mean of R over them is R averaged over
// the lamp's disc to its second moments (at r/sqrt(2) from the centre along
// two orthogonal axes; the material fit's finite lamps). false when the lamp
// is a point (radius 0) or the point lies inside it (model/render/shade.c).
bool model_lamp_disc_dirs(model_vec3_t l, double d_mm, double radius_mm, model_vec3_t out[4]);
bool               model_sensor_from_ini(const model_ini_t *ini, model_sensor_t *out);  // [sensor]
// The keys of one more section (as in [sensor]) applied over *s: a sensor that
// differs from [sensor] in a few keys (the virtual rig's [sensor CAMERA]).
bool               model_sensor_update_from_ini(const model_ini_t *ini, const char *section, model_sensor_t *s);

#ifdef __cplusplus
}
#endif
