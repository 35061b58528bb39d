// model/base/report.h — the output files every layer writes: directories, atomic
// files and JSON, provenance (the command as typed, refl's version, the date
// and the hashes of every input), the plotting scripts (scripts/*.py under
// /usr/bin/python3) and HTML report pages.
//
// Errors: bool (or NULL / -1) with the message in model_last_error().
#pragma once

#include <jansson.h>
#include <stdbool.h>
#include <stdio.h>

#ifdef __cplusplus
extern "C" {
#endif

// Write text to path atomically (temporary name, fsync, rename). false + message.
bool model_write_file_atomic(const char *path, const char *text);
// Provenance object: {"refl_version", "date_utc", "command", "inputs": [{"role",
// "path", "sha256"}...]}; add inputs with model_provenance_input.
json_t *model_provenance(int argc, char **argv);
// Adds {role, path, sha256 of the file (a directory: of its session.sqlite)}.
// false when the file cannot be read (message set).
bool    model_provenance_input(json_t *prov, const char *role, const char *path);
// The same entry appended to an array of inputs.
bool    model_inputs_add(json_t *inputs, const char *role, const char *path);

// A JSON number, or null where x is not finite (NaN: not measured, not
// defined; JSON has no NaN or infinity). A new reference.
json_t *model_json_number(double x);

// Every JSON file refl writes names its format and the version of its layout
// at its root: {"format": "refl-gain", "version": 2, ...}. A writer calls
// model_json_set_format on the root object; a reader calls
// model_json_format_check on the parsed root: a file of another format is
// refused naming both, a version above max_version is refused as written by
// a newer refl, a file without the keys is read as version 1 (each format's
// first layout); *version (may be NULL) gets the version read.
// false + model_error_set naming path.
void model_json_set_format(json_t *root, const char *format, int version);
bool model_json_format_check(const json_t *root, const char *path, const char *format, int max_version,
                             int *version);

// Write JSON to path atomically (temporary name, fsync, rename). false + message.
bool model_write_json(const char *path, json_t *o);
// Make a directory and its parents (mode 0755); false + message naming it.
// The directories it makes are remembered (process-wide) for
// model_remove_made_empty_dirs.
bool model_mkdir_p(const char *path);
// After a failed command: removes, deepest first, every directory
// model_mkdir_p made in this process that is empty now (a directory with
// anything in it stays, and so do its parents), so a failed run leaves no
// empty output directory behind. Returns how many it removed. The dispatcher
// (fit/main.c) calls it when a command exits with an error.
int  model_remove_made_empty_dirs(void);

// The path of refl's own file DIR/NAME (DIR "scripts" or "examples"; g_free),
// the first that exists of: $REFL_SCRIPTS_DIR/NAME (scripts) or
// $REFL_SCRIPTS_DIR/../DIR/NAME; EXE/../DIR/NAME, EXE/../../DIR/NAME and
// EXE/../../../DIR/NAME (a build tree, EXE the running binary's directory); EXE/../share/refl/DIR/NAME
// (an installation: PREFIX/bin/refl, PREFIX/share/refl/). NULL +
// model_error_set naming where it looked.
char *model_share_path(const char *dir, const char *name);

// Run scripts/NAME with /usr/bin/python3 and the arguments (NULL-terminated);
// scripts are found by model_share_path. Its output goes to stderr. 0, or -1 with a message
// (script missing, failed: its exit status).
int model_run_script(const char *script, ...) __attribute__((sentinel));

// HTML reports: a page with a title, the provenance table and sections;
// model_html_end closes it. Text arguments are escaped.
FILE *model_html_begin(const char *path, const char *title, const json_t *provenance);
void  model_html_heading(FILE *f, const char *text);
void  model_html_para(FILE *f, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
// The page's headline, written first after model_html_begin: a box titled title with one line per item
// (the verdicts, the figures with their sigma, what missed its target and by how much); an item that begins
// with "!" is a miss, drawn in red without the "!".
void  model_html_headline(FILE *f, const char *title, const char *const *items, int nitems);
// An image (relative path) with a caption.
void  model_html_figure(FILE *f, const char *src, const char *caption);
// A table: header cells separated by '|', then rows (each a '|'-separated
// string) until NULL.
void  model_html_table(FILE *f, const char *header, const char *const *rows, int nrows);
// Close the page; false when writing failed (message set).
bool  model_html_end(FILE *f, const char *path);

#ifdef __cplusplus
}
#endif
