// model/base/base.h — the model layer's base: refl's version, 3-vectors,
// errors, notices, subprocesses, small utilities and INI files
//
// Part of model/model.h, whose conventions (units, frames, pixel coordinates,
// errors, model_*_free(NULL)) apply here.
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
// A list of numbers separated by any of seps (runs of them count once), each
// model_parse_double's and within [lo, hi], at most max, into v: their count,
// or -1 (none, too many, or one not a number in range).
int  model_parse_doubles(const char *s, const char *seps, double lo, double hi, double *v, int max);
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

#ifdef __cplusplus
}
#endif
