// model/model.h — the imaging model of refl (thesis ch. 3-5).
//
// Scenes (D3D, OBJ), cameras (mrcal .cameramodel), lamps, materials and their
// reflection models, ray casting (Embree) into per-pixel pixel_info, the grey
// value function with interreflection, the sensor stage, image files, and the
// edge query.
//
// Conventions
// - Lengths in mm, angles in degrees in files and radians inside. Frames are
//   right-handed. The world frame is the rig frame (origin at the turntable top
//   centre, z up along the rotation axis) and is mrcal's "ref" frame, so a
//   camera model's rt_cam_ref is rt_cam_world.
// - Pixel coordinates are mrcal's: the centre of the top-left pixel is (0,0),
//   x to the right, y down.
// - Errors: functions return bool (or NULL) and report "file:line: message"
//   through model_error(); the message names the input file and line where
//   there is one. model_last_error() returns the last message of this thread.
// - Every model_*_free() accepts NULL.
#pragma once

#include <stdbool.h>
#include <stdio.h>
#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

#define REFL_VERSION "0.1.0"

typedef struct { double x, y, z; } model_vec3_t;

// ---------------------------------------------------------------------------
// Errors and small utilities (model/base/util.c)

// Report an error. where_file may be NULL (then only the message is shown);
// where_line <= 0 omits the line. The text goes to stderr unless quiet mode is
// on, and is kept as this thread's last error either way.
void model_error(const char *where_file, int where_line, const char *fmt, ...)
    __attribute__((format(printf, 3, 4)));
// The same, but only kept (never printed): for code whose caller adds context
// and reports the message itself (the least-squares solver, model/base/lsq.h).
void model_error_set(const char *where_file, int where_line, const char *fmt, ...)
    __attribute__((format(printf, 3, 4)));
const char *model_last_error(void);
void model_error_clear(void);
// For commands, which own what reaches stderr: run the library quietly
// (model_error_quiet_thread(true)) and print its one message once,
// "refl CMD: <message>". Returns 1, the exit status of an error.
int model_error_report(const char *cmd);
// Quiet mode (for tests): errors are kept, not printed. Returns the old value.
// Process-wide: set it once (the test harness does); code that silences its
// own errors for a moment uses model_error_quiet_thread, since toggling the
// process-wide flag from several threads can leave it stuck on.
bool model_error_quiet(bool quiet);
// The same for the calling thread only.
bool model_error_quiet_thread(bool quiet);
// Whether the process-wide quiet mode is on (warnings the library prints
// itself, which a command's quiet thread still shows, follow it).
bool model_error_quiet_global(void);

// ---------------------------------------------------------------------------
// Notices (model/base/notice.c): what library code tells its user while it
// works. Library code never prints a command's name and never writes progress
// to stderr itself: it calls these, and the command decides where they go.
// The default sink writes "PREFIX: text" lines to stderr, PREFIX being what
// the dispatcher set (model_notice_prefix("refl calib geometry")); a warning
// reads "PREFIX: warning: text"; a progress line overwrites itself on a
// terminal and is a line of its own elsewhere. Text after a newline is
// printed as it is (continuation lines). Quiet mode (model_error_quiet, as in
// the tests) drops every notice.
typedef enum {
    MODEL_NOTICE_NOTE,          // what is happening ("solving from 40 views")
    MODEL_NOTICE_WARNING,       // something the user should look at; the work goes on
    MODEL_NOTICE_PROGRESS,      // the state of a long step ("step 12/288, ETA 40 s")
    MODEL_NOTICE_PROGRESS_END,  // the progress line is finished (text "")
} model_notice_kind_t;
void model_note(const char *fmt, ...) __attribute__((format(printf, 1, 2)));
void model_warning(const char *fmt, ...) __attribute__((format(printf, 1, 2)));
void model_progress(const char *fmt, ...) __attribute__((format(printf, 1, 2)));
void model_progress_end(void);
// The prefix of the default sink's lines (at most 127 characters; NULL or "": "refl").
void model_notice_prefix(const char *prefix);
const char *model_notice_prefix_text(void);
// Send every notice to fn(ctx, kind, text) instead (calls are serialised);
// fn NULL restores the default sink.
typedef void (*model_notice_fn)(void *ctx, model_notice_kind_t kind, const char *text);
void model_notice_sink(model_notice_fn fn, void *ctx);

// ---------------------------------------------------------------------------
// Subprocesses (model/base/run.c)

// Run argv (argv[0] looked up in PATH) in cwd (NULL: here) and wait. Its
// stdout and stderr are captured: written to log_path (NULL: not kept) with
// the command line, and stdout returned in *out (NULL: dropped; g_free).
// install_hint names what to install when it cannot start ("Debian: apt
// install mrcal"; may be NULL). Returns its exit status (128 + signal when a
// signal ended it), or -1 + message when it could not run. A non-zero status
// leaves the tail of its stderr in model_last_error().
int model_run_tool(const char *cwd, char *const *argv, const char *log_path, char **out,
                   const char *install_hint);

// Read a whole file into a NUL-terminated buffer (caller frees). *len may be
// NULL. Reports "path: reason" on failure.
char *model_read_file(const char *path, size_t *len);
// Lower-case hex SHA-256 of a buffer / a file's contents.
void model_sha256_hex(const void *data, size_t len, char out[65]);
bool model_sha256_file(const char *path, char out[65]);
// Strict number parsing: the whole string (leading/trailing blanks allowed)
// must be one finite number.
bool model_parse_double(const char *s, double *out);
bool model_parse_int(const char *s, long *out);
// Number of worker threads to use: REFL_THREADS if set, else the online CPUs.
int model_default_threads(void);
// Run fn(ctx, begin, end, thread_index) over [0,n) in chunks of `chunk` on
// nthreads threads (dynamic scheduling). nthreads <= 1 runs inline.
void model_parallel_for(int n, int chunk, int nthreads,
                        void (*fn)(void *ctx, int begin, int end, int thread),
                        void *ctx);
// qsort comparator of doubles, ascending (NaN last).
int model_cmp_double(const void *a, const void *b);
// v[k] of v[0..n) sorted ascending, by selection (v is reordered; no NaN in v).
double model_kth(double *v, int n, int k);
// The median of v[0..n) (NAN when n <= 0; v is reordered), by selection:
// the same value as the middle (or the mean of the two middle values) of v
// sorted with model_cmp_double (a v with NaN is sorted).
double model_median(double *v, int n);
// The eigen-decomposition of the symmetric n x n A (row-major) by cyclic
// Jacobi rotations: A becomes diagonal (the eigenvalues on it), and V (n x n,
// NULL: not wanted) the eigenvectors as columns, so A_in = V diag(A) V^T.
void model_sym_eigen(int n, double *A, double *V);
// The monotone piecewise cubic through (x[k], y[k]), k = 0..n-1 (x strictly
// increasing, n >= 2): model_pchip_slopes gives its knot derivatives d[n]
// (Fritsch & Butland's weighted harmonic mean of the neighbouring secants, 0 at
// a local extremum; the one-sided three-point ends limited to 3 secants; then
// Fritsch & Carlson's alpha^2 + beta^2 <= 9), so that it is monotone wherever
// the data are and never overshoots them; model_pchip_eval its value at
// x[0] <= t <= x[n-1] (the cubic Hermite form; *slope, may be NULL, gets its
// derivative). Beyond the ends, callers choose (a constant, the end slope).
void   model_pchip_slopes(const double *x, const double *y, int n, double *d);
double model_pchip_eval(const double *x, const double *y, const double *d, int n, double t, double *slope);
// Monotonic wall clock in seconds.
double model_now_s(void);
// Host real-time clock (CLOCK_REALTIME), seconds since 1970 UTC.
double model_realtime_s(void);
// t_s as ISO 8601 UTC with milliseconds: "2026-11-21T08:41:02.123Z".
void   model_utc_text(double t_s, char out[40]);
// The command line as one shell-readable string "refl ARG ..." (argv[0] is the
// subcommand; arguments quoted where needed). Free with g_free(). When argv is
// the tail of the whole command line registered by model_set_command_line (a
// command or subcommand handed argc - k, argv + k by its dispatcher), the
// whole line is given, as typed: "refl calib geometry ...", never "refl
// geometry ...", so the recorded command can be run again.
char  *model_command_line(int argc, char **argv);
// The process's whole argv (main's), registered once by the dispatcher.
void   model_set_command_line(int argc, char **argv);
// A command-line usage error: "refl CMD: <message>" and "(refl CMD --help for
// the options)" on stderr; returns 2, the exit status of a usage error. The
// same printer as model_cli_error (model/base/opts.c), for errors found without the
// command's option table at hand.
int    model_usage_error(const char *cmd, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
// Solve A x = b (n x n, row-major; A and b overwritten, x in b) by Gaussian
// elimination with partial pivoting. false when A is singular.
bool   model_solve_linear(double *A, double *b, int n);

// ---------------------------------------------------------------------------
// INI files (model/base/ini.c): "[section]" or "[kind NAME]" headers, "key = value"
// lines, '#' or ';' comments, blank lines. Keys before any section, a
// duplicate key in one section, or a duplicate section header are errors.

typedef struct {
    const char *section;   // the text between the brackets, blanks trimmed
    const char *key;
    const char *value;     // trimmed; may be empty
    int         line;      // 1-based line in the file
} model_ini_entry_t;

typedef struct {
    char               *path;      // the name used in messages
    int                 nentries;
    model_ini_entry_t  *entries;
    int                 nsections;
    const char        **sections;  // in file order
    int                *section_lines;
    int                *section_first;   // entries of section i: entries[section_first[i] ..
    int                *section_count;   //   section_first[i] + section_count[i] - 1] (contiguous)
    char               *storage_;  // private
    void               *index_;    // private: section name -> index + 1 (lookups in constant time)
} model_ini_t;

model_ini_t *model_ini_parse(const char *text, size_t len, const char *name);
model_ini_t *model_ini_load(const char *path);
void         model_ini_free(model_ini_t *ini);
// The entry for (section, key), or NULL (cost: the section's entries).
const model_ini_entry_t *model_ini_get(const model_ini_t *ini, const char *section,
                                       const char *key);
// The line of section's header, 0 when there is none.
int         model_ini_section_line(const model_ini_t *ini, const char *section);
// The value of (section, key) as written, or def when absent.
const char *model_ini_text(const model_ini_t *ini, const char *section, const char *key, const char *def);
// Typed getters: the value of (section, key) converted and checked into *out.
// An absent key keeps *out and returns true, unless required: then
// "[section] lacks 'key'" at the section's line. Every error goes through
// model_error naming file:line, in one form:
//   "[section] key: 'VALUE' is not a number (RANGE)"   (an integer, a truth value, three numbers ...)
//   "[section] key = VALUE is out of range (RANGE)"
// _double_in: within [lo, hi] (lo excluded when lo_open); range_text names the
// range in messages (NULL: "lo..hi"). _int: a whole number in [lo, hi].
// _bool: true/yes/1/on or false/no/0/off. _string: non-empty, at most size-1
// characters. _vec3: three numbers separated by blanks or commas (what: how
// the message names them, NULL: "x y z").
bool model_ini_double(const model_ini_t *ini, const char *section, const char *key, double *out, bool required);
bool model_ini_double_in(const model_ini_t *ini, const char *section, const char *key, double *out, bool required,
                         double lo, bool lo_open, double hi, const char *range_text);
bool model_ini_int(const model_ini_t *ini, const char *section, const char *key, long *out, bool required, long lo,
                   long hi);
bool model_ini_bool(const model_ini_t *ini, const char *section, const char *key, bool *out, bool required);
bool model_ini_string(const model_ini_t *ini, const char *section, const char *key, char *out, size_t size,
                      bool required);
bool model_ini_vec3(const model_ini_t *ini, const char *section, const char *key, double out[3], bool required,
                    const char *what);

// ---------------------------------------------------------------------------
// Scenes (model/scene/scene.c)
//
// D3D (Ammeraal 1988, the thesis's format):
//     # comment
//     1  0 0 0          numbered vertices: number x y z (mm)
//     2  100 0 0
//     ...
//     Faces:
//     @material steel   sets the material of the faces that follow
//     1 2 3 4.          a face: its vertex numbers, ended by '.'
//                       (may span lines; counter-clockwise seen from outside)
//     @sphere cx cy cz r  extension: an exact sphere (centre, radius in mm,
//                       r > 0) of the current material, on a line of its own
//                       after 'Faces:'. A D3D file needs at least one face or
//                       sphere. OBJ has no spheres.
// Wavefront OBJ: v, f (v, v/vt, v/vt/vn, v//vn, negative indices), usemtl;
// vn, vt, o, g, s, mtllib, l are ignored; other statements are errors.
// Faces without a material get the material "default".
// STL (binary or ASCII; model/scene/mesh.c): triangles, their repeated
// corners merged into shared vertices (equal bit for bit), facet normals
// ignored (the corner order gives the normal); every face "default".
// PLY (ascii or binary_little_endian): element vertex (x, y, z; other
// properties skipped), element face (list vertex_indices or vertex_index,
// 0-based; polygons checked for planarity like the others), other elements
// skipped; every face "default". Errors name the line (ASCII) or the byte
// offset (binary); faces of a binary file have line 0.
// Units: the coordinates are in mm unless unit_mm says otherwise
// (model_units_parse: --units mm, m or in); a D3D/OBJ/STL/PLY scene's
// spheres and vertices are scaled alike.

typedef struct {
    int          nverts;
    const int   *verts;      // indices into scene->vertices (0-based)
    int          material;   // index into scene->material_names
    model_vec3_t normal;     // unit normal (Newell), right-hand rule on vertex order
    double       offset_mm;  // plane: normal . x = offset_mm
    int          line;       // line of the face in the source file
    int          number;     // 1-based face number in the file (for messages)
} model_face_t;

typedef struct {
    model_vec3_t centre_mm;  // world frame
    double       radius_mm;  // > 0
    int          material;   // index into scene->material_names
    int          line;       // line of the @sphere in the source file
} model_sphere_t;

typedef struct {
    int            nvertices;
    model_vec3_t  *vertices;     // mm, world frame
    int            nfaces;
    model_face_t  *faces;
    int            nmaterials;
    char         **material_names;
    char          *path;         // as given
    char           sha256[65];   // of the file contents
    int           *vert_storage_; // private
    int            nspheres;     // exact spheres (D3D @sphere); 0 for OBJ
    model_sphere_t *spheres;     // sphere k is "face" nfaces + k in pixel_info
    char           warning[320]; // model_scene_load: a warning it printed ("" none), e.g. the units'
} model_scene_t;

typedef struct {
    double planarity_tol_mm;     // max distance of a vertex from its face's plane (default 0.01)
    double unit_mm;              // mm per unit of the file's coordinates; 0: mm, not said (default)
} model_scene_options_t;

// An OBJ, STL or PLY scene whose bounding box is smaller than this on every
// side, loaded with no unit given, gets a warning (metres read as mm?).
#define MODEL_SCENE_SMALL_MM 5.0
// "mm" -> 1, "m" -> 1000, "in" -> 25.4 (mm per unit); false for anything else.
bool model_units_parse(const char *s, double *unit_mm);

#define MODEL_SCENE_OPTIONS_DEFAULT ((model_scene_options_t){ .planarity_tol_mm = 0.01 })

// Load a scene file: STL and PLY told by their content (a .stl name also
// makes a damaged STL read as one, for its error), D3D and OBJ by the name
// (.d3d, .obj, case-insensitive). opt may be NULL. An OBJ/STL/PLY scene under
// MODEL_SCENE_SMALL_MM with opt->unit_mm 0 gets scene->warning, printed on
// stderr as "PATH: warning: ..." (unless the process-wide quiet mode is on).
model_scene_t *model_scene_load(const char *path, const model_scene_options_t *opt);
model_scene_t *model_scene_parse_d3d(const char *text, size_t len, const char *name,
                                     const model_scene_options_t *opt);
model_scene_t *model_scene_parse_obj(const char *text, size_t len, const char *name,
                                     const model_scene_options_t *opt);
model_scene_t *model_scene_parse_stl(const char *text, size_t len, const char *name,
                                     const model_scene_options_t *opt);
model_scene_t *model_scene_parse_ply(const char *text, size_t len, const char *name,
                                     const model_scene_options_t *opt);
void           model_scene_free(model_scene_t *scene);
// Index of a material name in the scene, or -1.
int            model_scene_material_index(const model_scene_t *scene, const char *name);
// A deep copy rotated by angle_deg about the world z axis (the turntable);
// sphere centres rotate with the vertices.
model_scene_t *model_scene_rotated_z(const model_scene_t *scene, double angle_deg);
// A deep copy moved rigidly: x' = R x + t (R row-major 3x3, a rotation; t in
// mm); face normals and plane offsets, sphere centres move with the vertices.
model_scene_t *model_scene_transformed(const model_scene_t *scene, const double R[9], const double t[3]);
// The pose of a scene standing on a wedge (the sample fixture of capture
// plans, [sample] tilt_deg / tilt_azimuth_deg): R = rotation by tilt_deg about
// the horizontal hinge axis (cos az, sin az, 0) through the origin
// (right-handed), t = (0, 0, lift) with lift = the scene's lowest z minus the
// rotated scene's lowest z (its lowest point stays at its height). Apply with
// model_scene_transformed; the turntable angle applies after.
void model_scene_wedge_pose(const model_scene_t *scene, double tilt_deg, double tilt_azimuth_deg, double R[9],
                            double t[3]);

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
    // adversary, issue 18; all off by default, see model/sensor.c):
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

// ---------------------------------------------------------------------------
// Cameras (model/camera.c): an mrcal camera model plus a cached ray table.

typedef struct model_camera model_camera_t;

// Reads a .cameramodel with libmrcal. NULL and a message naming the file on error.
model_camera_t *model_camera_load(const char *path);
// From explicit parameters (lensmodel name as mrcal spells it, e.g.
// "LENSMODEL_OPENCV8"; intrinsics fx fy cx cy + distortions; rt_cam_world = r(3) t(3), t in mm).
model_camera_t *model_camera_new(const char *lensmodel, const double *intrinsics,
                                 int width, int height, const double rt_cam_world[6]);
bool            model_camera_save(const model_camera_t *cam, const char *path);
void            model_camera_free(model_camera_t *cam);
int             model_camera_width(const model_camera_t *cam);
int             model_camera_height(const model_camera_t *cam);
const char     *model_camera_lensmodel(const model_camera_t *cam);
// The lens model's parameters (fx fy cx cy and the distortions, mrcal's order); *n their count.
const double   *model_camera_intrinsics(const model_camera_t *cam, int *n);
const char     *model_camera_sha256(const model_camera_t *cam);   // of the file, or of the parameters
void            model_camera_rt_cam_world(const model_camera_t *cam, double rt[6]);
model_vec3_t    model_camera_centre_world(const model_camera_t *cam);
// Project world points to pixels. false on error.
bool model_camera_project(const model_camera_t *cam, const model_vec3_t *p_world, int n,
                          double *q_xy /* out: n*2 */);
// Unit ray directions in the world frame through pixels q (exact mrcal_unproject).
bool model_camera_unproject(const model_camera_t *cam, const double *q_xy, int n,
                            model_vec3_t *dir_world /* out: n */);
// The ray table: unit world-frame directions for every integer pixel (row-major,
// width*height), made by unprojecting a coarse grid and interpolating, refined
// until the reprojection error is below max_error_px (default 0.005 px; use
// both cores). Computed once per camera and kept. The achieved bound is
// returned through *err_px (may be NULL).
const model_vec3_t *model_camera_ray_table(model_camera_t *cam, double *err_px);

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
// Sensor stage (model/sensor.c): from the ideal grey value (DN, as the imaging
// model gives it) to what a camera delivers. Separate from the physics.
//   e = (P - dark_offset) / K * prnu(x,y) * vignetting(x,y) + dark current
//   -> Poisson shot noise, Gaussian read noise -> non-linearity near full well
//   -> * K + dark_offset + dsnu(x,y) -> quantised to `bits`, clipped to [0, 2^bits-1].

// Fixed patterns of the sensor (ground truth): prnu gain map (mean 1) and dsnu
// offset map (DN, mean 0). Either may be NULL.
void model_sensor_patterns(const model_sensor_t *s, int width, int height,
                           float *prnu_gain, float *dsnu_dn);
// Apply to an image in place (width*height floats). Output values are integers
// in [0, 2^bits - 1], stored as float.
void model_sensor_apply(const model_sensor_t *s, int width, int height, float *img);
// The same with fixed patterns made once by model_sensor_patterns (for many
// frames of one sensor; NULL = flat), so a frame costs only its noise.
void model_sensor_apply_patterns(const model_sensor_t *s, int width, int height, const float *prnu_gain,
                                 const float *dsnu_dn, float *img);
// The noise-free mean response: the same chain without shot noise, read noise
// and rounding (non-linearity, patterns, offset and clipping to the range of
// `bits` kept). Values stay fractional.
void model_sensor_mean(const model_sensor_t *s, int width, int height, const float *prnu_gain,
                       const float *dsnu_dn, float *img);

// What a measurement to EMVA 1288's definitions reads from this sensor's dark
// frames (model/sensor.c): read_noise_e, the temporal dark noise at exposure 0
// (sigma_y.dark / K without the rounding's q^2/12: the read noise through the
// response's low end, plus the row noise), and dark_current_e_per_s, the
// least-squares slope of the mean dark level against exposure over the nt
// exposures t_us (us), divided by K (e-/s; hot pixels included, through the
// same response). Both the sensor's own read_noise_e and dark_current_e_per_s
// when its response is linear near 0 and it has neither row noise nor hot
// pixels. Either output may be NULL (the exposures are needed only for the
// dark current); false + message when K or the full well is not positive or
// the exposures are fewer than 2 different ones >= 0. Exact sums over the
// Poisson dark electrons and a quadrature over the read noise (no draws).
bool model_sensor_dark_measurand(const model_sensor_t *s, const double *t_us, int nt, double *read_noise_e,
                                 double *dark_current_e_per_s);

// A camera's gain as a signal factor (model/sensor.c), the one conversion of a
// recorded gain. unit is the camera's own (GenICam <Unit> of its Gain feature,
// recorded with every frame): "dB" -> 10^(gain/20); "x", "times", "linear" or
// "factor" -> gain itself; NULL or "" -> dB (frames of sessions recorded before
// refl kept the unit: their gain was GenICam's Gain, in dB). Any other unit
// ("raw", a vendor's) has no known scale: such a frame is usable only at the
// gain its calibration was made at (cal_gain, cal_unit), and its factor is then
// that of the calibration. *factor is relative to the calibration's gain (for
// a calibration at 0 dB, the plain factor). false (model_error_set naming
// `what`, e.g. the frame, its gain and unit) when the gain cannot be converted.
bool model_gain_factor(double gain, const char *unit, double cal_gain, const char *cal_unit, const char *what,
                       double *factor);

// The sensor's response linearisation (model/sensor.c): a measured signal
// above dark S_m (DN) -> the linear signal S (DN), as the gain calibration
// (calib/gain/gain.c, gain.json "linearisation") measured it at its gain. The one
// function every consumer applies (calibrated observations, the white, the
// material fit, verification) is model_linearise.
//   MODEL_LIN_NONE        S = S_m
//   MODEL_LIN_PARAMETRIC  S_m = S (1 - a S) (a per DN; files from before the
//                         table, or refl calib gain --linearisation parametric)
//   MODEL_LIN_MONOTONE    a monotone piecewise-cubic Hermite interpolant
//                         (Fritsch & Carlson, SIAM J. Numer. Anal. 17, 1980;
//                         knot derivatives by Fritsch & Butland's weighted
//                         harmonic mean, SIAM J. Sci. Stat. Comput. 5, 1984)
//                         through knots (m[k], s[k]), m and s strictly
//                         increasing from (0, 0); linear beyond the last knot
//                         (slope d[n-1]) and below 0 (slope d[0]).
#define MODEL_LIN_MAX 256
enum { MODEL_LIN_NONE, MODEL_LIN_PARAMETRIC, MODEL_LIN_MONOTONE };
typedef struct {
    int    kind;                 // MODEL_LIN_*
    double a_per_dn;             // PARAMETRIC: a at the calibration's gain
    int    n;                    // MONOTONE: knots (2..MODEL_LIN_MAX)
    double m[MODEL_LIN_MAX];     // measured DN above dark
    double s[MODEL_LIN_MAX];     // linear DN
    double d[MODEL_LIN_MAX];     // dS/dS_m at the knots
} model_lin_t;

// The linear signal of s_m (DN above dark) at gain factor gf relative to the
// calibration's (the response is the sensor's: S = gf T(s_m / gf)); *slope
// (may be NULL) gets dS/dS_m (for the noise). L NULL: S = s_m.
double model_linearise(const model_lin_t *L, double s_m, double gf, double *slope);
// The monotone table through points (m[i], s[i]), i = 0..n-1, s strictly
// increasing (the order of exposure): m is first made non-decreasing by
// isotonic regression (pool-adjacent-violators), points of equal m pooled,
// points at m <= 0 dropped, a point nearer the one before than min(20 % of
// its level, half the median spacing) pooled with it (close knots would make
// the slopes follow the noise), (0, 0) put first, and more than MODEL_LIN_MAX
// knots thinned evenly. false (message set) when fewer than 2 knots remain or
// a value is not finite.
bool model_lin_monotone(const double *m, const double *s, int n, model_lin_t *out);
// The table through knots as they are (a table written by model_lin_monotone,
// read back): 2..MODEL_LIN_MAX knots, m and s finite and strictly increasing.
// false (message set) otherwise.
bool model_lin_knots(const double *m, const double *s, int n, model_lin_t *out);

// ---------------------------------------------------------------------------
// Image files (model/image/write.c). Text metadata is a NULL-terminated list of
// key, value, key, value, ..., NULL (may be NULL): PNG tEXt chunks, TIFF
// ImageDescription (as "key: value" lines).

bool model_png16_write(const char *path, int width, int height, const uint16_t *pix,
                       const char *const *meta);

typedef struct {
    int  compression_level;   // zlib 0..9; -1: libpng's default
    bool fast_filter;         // the Sub filter only: ~4x faster on sensor frames, a few % larger
    bool fsync;               // flush the file to the disk before it is renamed into place
    bool quiet;               // errors are kept (model_last_error) but not printed
} model_png_options_t;

// model_png16_write with options (opt NULL: the defaults, as model_png16_write).
// On failure errno holds the cause (ENOSPC for a full disk) and nothing is left
// under path or its temporary name.
bool model_png16_write_opts(const char *path, int width, int height, const uint16_t *pix,
                            const char *const *meta, const model_png_options_t *opt);
// An 8-bit greyscale PNG (previews, masks, pictures for reports), written
// atomically like the 16-bit one; zlib level 1.
bool model_png8_write(const char *path, int width, int height, const uint8_t *pix, const char *const *meta);

// A growing list of metadata (key, value) for the writers above.
typedef struct model_meta model_meta_t;
model_meta_t *model_meta_new(void);
void          model_meta_add(model_meta_t *m, const char *key, const char *fmt, ...)
    __attribute__((format(printf, 3, 4)));
// The NULL-terminated key, value, ... list (valid until the next add or free).
const char *const *model_meta_list(model_meta_t *m);
void          model_meta_free(model_meta_t *m);
// The value of the first entry named key, or NULL.
const char   *model_meta_get(const model_meta_t *m, const char *key);
bool model_tiff_write_float(const char *path, int width, int height, const float *pix,
                            const char *const *meta);
// Multi-page TIFF: page 0 P (float32), page 1 face id (int32, -1 = background),
// pages 2.. the lit mask of each lamp (uint8 0/1), each page named.
bool model_tiff_write_info(const char *path, int width, int height, const float *P,
                           const int32_t *face, const uint8_t *lit, int nlamps,
                           const char *const *lamp_names, const char *const *meta);
// Reading (model/image/read.c): one reader for every command that takes
// images. The format is told by the first bytes, never by the name: PNG
// (grey, grey+alpha, RGB(A), palette; 1 to 16 bits), JPEG (libjpeg-turbo;
// grey or YCbCr/RGB; CMYK refused) and TIFF (first page, strips; grey or
// RGB(A), contiguous or planar; integer 8/16/32 bits or float 32/64).
// Values are kept as stored (an 8-bit image gives 0..255, a 16-bit one
// 0..65535; no scaling). Colour gives one value per pixel by the channel:
// MODEL_CHANNEL_LUMA = Rec. 709 luma weights applied to the stored (encoded)
// values, no transfer curve undone; R, G or B: that channel. A grey image is
// the same whatever the channel. Alpha is ignored.
typedef enum { MODEL_CHANNEL_LUMA, MODEL_CHANNEL_R, MODEL_CHANNEL_G, MODEL_CHANNEL_B } model_channel_t;
#define MODEL_LUMA_R 0.2126
#define MODEL_LUMA_G 0.7152
#define MODEL_LUMA_B 0.0722
typedef enum { MODEL_IMAGE_UNKNOWN, MODEL_IMAGE_PNG, MODEL_IMAGE_JPEG, MODEL_IMAGE_TIFF } model_image_format_t;
// "luma", "r", "g" or "b"; false for anything else.
bool            model_channel_parse(const char *s, model_channel_t *out);
const char     *model_channel_name(model_channel_t ch);
// The channel the path-only readers below use for colour images: luma unless
// a command set another from its --channel option (process-wide, set once
// before the work starts).
void            model_image_set_channel(model_channel_t ch);
model_channel_t model_image_channel(void);
// The format of a file from its first bytes (8 are enough).
model_image_format_t model_image_format(const void *data, size_t len);
// Decode an image file's bytes (name: for messages). meta (may be NULL): a
// PNG's text chunks are added. NULL + model_error naming the file and why
// (not an image, truncated, unsupported layout).
float *model_image_decode(const void *data, size_t len, const char *name, model_channel_t ch, int *width,
                          int *height, model_meta_t *meta);
float *model_image_read(const char *path, model_channel_t ch, int *width, int *height, model_meta_t *meta);
// model_image_read with model_image_channel() and no metadata.
float *model_image_read_float(const char *path, int *width, int *height);
// The W x H image P (row-major) at (x, y) in pixels (pixel centres at whole
// numbers), interpolated bilinearly; outside the image: 0 and *inside false
// (*inside is left as it was otherwise).
double model_image_bilinear(const float *P, int W, int H, double x, double y, bool *inside);
// The same as *pix (free it); false on error.
bool model_tiff_read_float(const char *path, int *width, int *height, float **pix);
// The same as 16-bit values (grey values kept; colour mixed, rounded and
// clamped to 0..65535), optionally with the PNG's text chunks (tEXt, zTXt,
// iTXt) added to meta.
bool model_png_read(const char *path, int *width, int *height, uint16_t **pix);
bool model_png_read_meta(const char *path, int *width, int *height, uint16_t **pix, model_meta_t *meta);
// The files of an --images argument: a directory (its regular files, not the
// hidden ones; not recursive) or a glob pattern (or one file name), sorted by
// name. Whether each is an image is for the reader to say (callers skip what
// it refuses, printing why). false + model_error when there is no file at all.
bool model_image_list(const char *spec, char ***paths, int *n);
void model_image_list_free(char **paths, int n);

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
// The reference workpiece (model/scene/workpiece.c; thesis ch. 6): a base plate
// with a welded stiffener, and the wrong descriptions verification is tested
// with. Plate: x -px/2..px/2, y -py/2..py/2, z 0..pz. Stiffener along y,
// centred on the plate, its top at pz + height_mm * height_scale; T: a web of
// web_thickness_mm under a flange flange_width_mm x flange_thickness_mm; I: a
// flat bar of web_thickness_mm; none: the plate alone. The stiffener is then
// rotated by rotate_deg about z through its centre and shifted by shift_mm
// (x, y). The defaults make examples/t_stiffener.d3d.

typedef enum { MODEL_STIFFENER_T, MODEL_STIFFENER_I, MODEL_STIFFENER_NONE } model_stiffener_kind_t;

typedef struct {
    model_stiffener_kind_t kind;
    double plate_mm[3];            // 400 300 10
    double web_thickness_mm;       // 8
    double length_mm;              // 260 (along y)
    double height_mm;              // 88 (above the plate, flange included)
    double flange_width_mm;        // 60
    double flange_thickness_mm;    // 8
    double shift_mm[2];            // 0 0
    double rotate_deg;             // 0
    double height_scale;           // 1
    const char *plate_material;    // "plywood"
    const char *stiffener_material;// "painted_steel"
} model_stiffener_t;

model_stiffener_t model_stiffener_default(void);
const char *model_stiffener_kind_name(model_stiffener_kind_t k);   // "T", "I", "none"
int         model_stiffener_kind_from_name(const char *s);         // -1 if unknown
// The D3D text (caller frees), or NULL with a message for impossible sizes.
char          *model_stiffener_d3d(const model_stiffener_t *p);
model_scene_t *model_stiffener_scene(const model_stiffener_t *p, const char *name);

// ---------------------------------------------------------------------------
// Commands (model/cmd.c): argv[0] is the subcommand name. Return the exit code.
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
// The edges, their units and conventions and the provenance as JSON. false + message.
bool model_edges_file_write_json(const model_edges_file_t *f, const model_edges_file_opts_t *o, const char *path);

int model_cmd_render(int argc, char **argv);
int model_cmd_edges(int argc, char **argv);
int model_cmd_workpiece(int argc, char **argv);
int model_cmd_brdf(int argc, char **argv);   // refl brdf tabulate (model/cmd_brdf.c)

#ifdef __cplusplus
}
#endif
