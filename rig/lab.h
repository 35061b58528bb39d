// rig/lab.h — the lab file (refl demo --lab, refl plan day): the lab's own facts in one INI
// file, its one reader (rig/lab.c), the geometry section's writer (refl plan geometry) and the
// lab day's plans written for a rig's own lamps (rig/lab_day.c).
//
// A lab file holds what a lab measured or chose, never what a rig file says (devices) nor what
// a calibration finds: where the chrome ball sits and how big the lamps are, the reference
// white's certificate, the flat-field source's radiance with its unit, the coupons on their
// wedges, the workpiece and the descriptions to verify, the geometry session's board poses.
// examples/lab.ini documents every key (the example real rig's); examples/lab-virtual.ini is a
// second virtual lab's (examples/virtual-rig-lab.ini).
//
//   [lab]          format_version = 1 (required; RIG_LAB_FORMAT_VERSION; a newer one is refused),
//                  name = TEXT (optional)
//   [geometry]     tilts = T[@AZ][:A,A,...] ... (refl calib geometry --tilts; required),
//                  angles_deg = A A ... (turntable angles of a tilt given without its own),
//                  exposure_us, board_sample (default calib_board), board_scene (the board's
//                  scene: its outline and place on the table at angle 0, tilt 0),
//                  board_corners = W H (inner corners, default 10 10), board_square_mm (30),
//                  board_height_mm (the corner plane above the table at tilt 0, default 5)
//   [sphere]       sample (default mirror_sphere), centre_mm = X Y Z (rig frame, angle 0),
//                  radius_mm (both required)
//   [lamps]        radius_mm (the lamps' emitting radius, modelled in the highlights; default 0)
//   [flat_field]   radiance (the source's radiance with the lamps on; absent: no kc),
//                  radiance_unit (required with radiance: the unit, as text)
//   [white]        sample (default reference_white), scene (required), certificate = CSV
//                  (the reflectance-factor table) or albedo (a Lambertian white's; default 0.99),
//                  albedo_std, angles_deg (default 0 120 240), exposure_us (default 8000),
//                  plan = FILE (a capture plan of the lab's own instead of the generated one)
//   [coupon NAME]  sample (required), scene (required), tilt_deg, tilt_azimuth_deg (the wedge),
//                  angles_deg or angle_step_deg (0, step, ... below 360; default 20),
//                  exposures_us (the auto bracket's ladder, default 8000 1000 125),
//                  target_fraction (0.9), albedo_cells_mm, window_px, step_px (refl fit
//                  material's), plan = FILE; at least one coupon
//   [workpiece]    sample (required), scene (required), priors = NAME NAME ... (the coupons
//                  whose priors the verification takes; required), angles_deg (the views,
//                  default 0 90 180 270), exposures_us (the light planner's candidates),
//                  check_lamps = SET; SET ... (the first session's lamp sets, default each lamp
//                  alone), check_exposure_us (20000), plan = FILE (the first session's plan)
//   [description NAME]  scene (required), expect = correct | incorrect (required), what = TEXT
//                  (optional: a label); at least one
//
// Paths are relative to the lab file's directory. Lengths mm, angles deg, exposures us. Unknown
// sections and keys, a missing required key and a bad value are errors naming file:line.
#pragma once

#include <stdbool.h>
#include <stddef.h>

#ifdef __cplusplus
extern "C" {
#endif

#define RIG_LAB_FORMAT_VERSION 1   // the lab file format read (versions 1 to this) and written
#define RIG_LAB_MAX_ANGLES     360
#define RIG_LAB_MAX_EXPOSURES  32
#define RIG_LAB_MAX_ITEMS      16  // coupons, descriptions, a workpiece's priors
#define RIG_LAB_NAME_MAX       64

typedef struct {
    char   name[RIG_LAB_NAME_MAX];        // the section's NAME: files are named after it
    char   sample[RIG_LAB_NAME_MAX];      // the sample's name (a virtual rig's [sample NAME])
    char  *scene;                         // resolved path
    char  *plan;                          // resolved path of the lab's own plan, or NULL
    double tilt_deg, tilt_azimuth_deg;    // the wedge
    int    nangles;
    double angles_deg[RIG_LAB_MAX_ANGLES];
    int    nexposures;
    double exposures_us[RIG_LAB_MAX_EXPOSURES];   // the bracket's ladder, as written
    double target_fraction;
    double albedo_cells_mm;               // 0: none
    int    window_px, step_px;            // 0: refl fit material's defaults
    int    line;                          // the section header's line
} rig_lab_coupon_t;

typedef struct {
    char  name[RIG_LAB_NAME_MAX];         // the section's NAME: the verification's directory verify_NAME
    char *scene;                          // resolved path
    bool  correct;                        // expect = correct
    char  what[160];                      // a label ("" when not given)
    int   line;
} rig_lab_description_t;

typedef struct {
    char  *path;                          // the file as given
    char   sha256[65];
    int    format_version;
    char   name[128];
    struct {
        char  *tilts;                     // --tilts text
        char  *angles;                    // "A A ..." or NULL
        double exposure_us;               // NAN: calib geometry's default
        char   board_sample[RIG_LAB_NAME_MAX];
        char  *board_scene;               // resolved path or NULL
        int    corners_w, corners_h;
        double square_mm, height_mm;
    } geometry;
    struct {
        char   sample[RIG_LAB_NAME_MAX];
        double centre_mm[3], radius_mm;
    } sphere;
    double lamp_radius_mm;
    struct {
        double radiance;                  // NAN: not given (no kc)
        char   unit[64];
    } flat_field;
    struct {
        char  sample[RIG_LAB_NAME_MAX];
        char *scene, *certificate, *plan; // resolved; certificate, plan may be NULL
        double albedo, albedo_std;        // albedo_std NAN: not stated
        int    nangles;
        double angles_deg[RIG_LAB_MAX_ANGLES];
        double exposure_us;
    } white;
    int ncoupons;
    rig_lab_coupon_t coupons[RIG_LAB_MAX_ITEMS];
    struct {
        char   sample[RIG_LAB_NAME_MAX];
        char  *scene, *plan;              // resolved; plan may be NULL
        int    npriors;
        char   priors[RIG_LAB_MAX_ITEMS][RIG_LAB_NAME_MAX];   // coupon names
        int    nangles;
        double angles_deg[RIG_LAB_MAX_ANGLES];
        int    nexposures;
        double exposures_us[RIG_LAB_MAX_EXPOSURES];
        char   check_lamps[512];          // "" = each lamp alone
        int    check_lamps_line;
        double check_exposure_us;
    } workpiece;
    int ndescriptions;
    rig_lab_description_t descriptions[RIG_LAB_MAX_ITEMS];
} rig_lab_t;

// Read and check a lab file completely. NULL + message (model_last_error: file:line, what is
// wrong, what to write). Free with rig_lab_free (accepts NULL).
rig_lab_t *rig_lab_load(const char *path);
// The same of a text (name: the path used in messages and to resolve relative paths).
rig_lab_t *rig_lab_parse(const char *text, size_t len, const char *name);
void       rig_lab_free(rig_lab_t *lab);
// The coupon of that name, or NULL.
const rig_lab_coupon_t *rig_lab_coupon(const rig_lab_t *lab, const char *name);

// The [geometry] section's text as a lab file holds it (refl plan geometry writes it for the
// lab to paste): tilts (required), angles (may be NULL), the board's facts; comment lines
// (may be NULL) first as '# ' lines. g_free.
typedef struct {
    const char *tilts, *angles, *board_sample, *board_scene;
    int         corners_w, corners_h;
    double      square_mm, height_mm, exposure_us;   // exposure_us NAN: not written
} rig_lab_geometry_t;
char *rig_lab_geometry_text(const rig_lab_geometry_t *g, const char *comment);

// The lab day (rig/lab_day.c): every plan the day captures, generated for the rig's own lamps
// (a lab's own plan = FILE is taken as it is), into dir, and dir/day.sh, the day's facts as
// shell assignments for scripts/demo (every value quoted). rig_path: the rig file (its lamps;
// a virtual rig's are its truth file's). Lamps the lab names that the rig lacks are errors
// naming the lab file's line. false + message.
typedef struct {
    int   nplans;
    char *plans[2 + RIG_LAB_MAX_ITEMS];   // written (or taken) plan paths, g_free
    char *script;                         // dir/day.sh, g_free
} rig_lab_day_t;
bool rig_lab_day_write(const rig_lab_t *lab, const char *rig_path, const char *dir, rig_lab_day_t *out);
void rig_lab_day_free(rig_lab_day_t *d);

// `refl plan day --rig RIG --lab LAB -o DIR` (rig/cmd_lab.c).
int rig_cmd_plan_day(int argc, char **argv);

#ifdef __cplusplus
}
#endif
