// calib/calib.h — calibrations of the rig: camera geometry and turntable axis
// (mrgingham + mrcal), lamp positions (mirror-sphere highlights) and the
// camera's sensitivity (EMVA 1288 style). Each calibration captures through
// capture sessions (rig/rig.h) or reads frames captured elsewhere, writes its
// files (JSON summary with units and provenance, float TIFF maps,
// .cameramodel) and an HTML report with plots into one output directory.
//
// Conventions: lengths in mm, angles in degrees, pixel coordinates with (0, 0)
// at the centre of the top-left pixel, grey values in DN of the frame's pixel
// format (Mono12: 0..4095, unscaled), exposures in microseconds. The rig
// frame: origin at the turntable top centre, z up along the rotation axis.
#pragma once

#include <jansson.h>
#include <stdbool.h>
#include <stdio.h>

#include "rig/rig.h"

#ifdef __cplusplus
extern "C" {
#endif

// `refl calib geometry|lamps|gain ...` (calib/cmd_calib.c dispatches).
int calib_cmd(int argc, char **argv);
int calib_cmd_geometry(int argc, char **argv);
int calib_cmd_lamps(int argc, char **argv);
int calib_cmd_gain(int argc, char **argv);

// ---------------------------------------------------------------------------
// Common parts (calib/common.c)

// Run a capture plan (its text) on the rig file rig_path into the session
// directory dir/name. The plan is first written to dir/name.plan.ini (kept as
// the record). A complete session of the same plan is reused as it is; a
// paused or stopped one is resumed. progress: as rig_capture_opts_t (-1 auto).
// 0, or -1 with the reason in model_last_error().
int calib_capture(const char *rig_path, const char *dir, const char *name, const char *plan_text, int progress);

// A session's frames (in step order) and its facts, for the analyses.
typedef struct {
    char            *dir;
    rig_frame_row_t *rows;
    int              n;
    char             plan_sha256[65], rig_sha256[65];
    char            *plan_text;        // the stored plan
    json_t          *facts;            // session facts (camera, virtual rig, ...); may be NULL
} calib_session_t;

// NULL on error (model_last_error names the directory).
calib_session_t *calib_session_open(const char *dir);
void             calib_session_free(calib_session_t *s);
// Frame i as float DN (its pixel format's values); checks the file's sha256
// against the journal first. NULL on error (names the file). Caller frees.
float           *calib_session_frame(const calib_session_t *s, int i, int *width, int *height);

// Read a 16-bit PNG or a float TIFF (by content) as float. NULL on error.
float *calib_image_read(const char *path, int *width, int *height);

// Provenance object: {"refl_version", "date_utc", "command", "inputs": [{"role",
// "path", "sha256"}...]}; add inputs with calib_provenance_input.
json_t *calib_provenance(int argc, char **argv);
// Adds {role, path, sha256 of the file (a directory: of its session.sqlite)}.
// false when the file cannot be read (message set).
bool    calib_provenance_input(json_t *prov, const char *role, const char *path);
// The same entry appended to an array of inputs.
bool    calib_inputs_add(json_t *inputs, const char *role, const char *path);

// Write JSON to path atomically (temporary name, fsync, rename). false + message.
bool calib_write_json(const char *path, json_t *o);
// Make a directory and its parents (mode 0755); false + message naming it.
bool calib_mkdir_p(const char *path);

// Run scripts/NAME with /usr/bin/python3 and the arguments (NULL-terminated);
// scripts are found in $REFL_SCRIPTS_DIR, else ../scripts of the running
// executable's directory. Its output goes to stderr. 0, or -1 with a message
// (script missing, failed: its exit status).
int calib_python(const char *script, ...) __attribute__((sentinel));

// HTML reports: a page with a title, the provenance table and sections;
// calib_html_end closes it. Text arguments are escaped.
FILE *calib_html_begin(const char *path, const char *title, const json_t *provenance);
void  calib_html_heading(FILE *f, const char *text);
void  calib_html_para(FILE *f, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
// An image (relative path) with a caption.
void  calib_html_figure(FILE *f, const char *src, const char *caption);
// A table: header cells separated by '|', then rows (each a '|'-separated
// string) until NULL.
void  calib_html_table(FILE *f, const char *header, const char *const *rows, int nrows);
// Close the page; false when writing failed (message set).
bool  calib_html_end(FILE *f, const char *path);

#ifdef __cplusplus
}
#endif
